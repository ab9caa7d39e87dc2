//! Control-core step cost on the host: how long one `Controller::tick`
//! takes (plus, in a second scenario, receiving one command frame).
//!
//! `cargo bench -p dexitac-firmware` (release profile: opt-level "s", fat
//! LTO, the firmware's own settings). Scenario: armed, both pumps
//! regulating a simulated tank pair, one chamber inflating, telemetry every
//! 10 ms, a heartbeat frame every 100 ms. The simulated tanks that feed the
//! sensor readings run in the same loop; a second run with the model alone
//! (`model only`) gives their share, and the difference is the control core.
//!
//! Pass an iteration count as the first argument to run that many ticks
//! without timing (for `valgrind --tool=callgrind`, see firmware/README.md).

use std::hint::black_box;
use std::time::Instant;

use dexitac_firmware::control::ZERO_AT_TICK;
use dexitac_firmware::cost_scenario;
use dexitac_firmware::sensor::{SensorSamples, NOMINAL_FRONT_END, OVERSAMPLE};
use dexitac_firmware::tank_model::{TankModel, TankModelParams};
use dexitac_firmware::{
    Clock, Config, Controller, PressureSource, PumpOutputs, Pumps, TxQueues, Valves,
};
use dexitac_protocol::{Chambers, EncodedFrame, HostMsg, ResetCause, ValveState, CHAMBER_COUNT};

struct Rig {
    now_ms: u32,
    /// True tank pressures, pascal.
    tanks_pa: (i32, i32),
    pumps: PumpOutputs,
    chambers: Chambers,
}

impl Clock for Rig {
    fn now_ms(&self) -> u32 {
        self.now_ms
    }
}

impl PressureSource for Rig {
    fn read_samples(&mut self) -> SensorSamples {
        let fe = NOMINAL_FRONT_END;
        let counts = |pa| Ok([fe.sensor_counts(pa, 5_000, 3_300); OVERSAMPLE]);
        SensorSamples {
            positive: counts(self.tanks_pa.0),
            negative: counts(self.tanks_pa.1),
            supply: Ok([fe.supply_counts(5_000, 3_300); OVERSAMPLE]),
        }
    }
}

impl Valves for Rig {
    fn set_chambers(&mut self, chambers: &Chambers) {
        self.chambers = *chambers;
    }
}

impl Pumps for Rig {
    fn set_pumps(&mut self, pumps: PumpOutputs) {
        self.pumps = pumps;
    }
}

fn frame(seq: u16, msg: HostMsg) -> EncodedFrame {
    match EncodedFrame::new(seq, &msg) {
        Ok(f) => f,
        Err(e) => panic!("encoding a host message: {e}"),
    }
}

/// An armed controller regulating both pumps, one chamber inflating.
fn setup() -> (Controller, Rig, TxQueues<4096, 4096>, TankModel) {
    let mut ctl = Controller::new(Config::default(), ResetCause::PowerOn);
    let mut rig = Rig {
        now_ms: 0,
        tanks_pa: (0, 0),
        pumps: PumpOutputs::OFF,
        chambers: [ValveState::Hold; CHAMBER_COUNT],
    };
    let mut tx = TxQueues::new();
    // The boot-time zero comes first; arming waits for it.
    for _ in 0..=ZERO_AT_TICK {
        rig.now_ms += 1;
        ctl.tick(&mut rig, &mut tx);
    }
    for (seq, msg) in (1..).zip(cost_scenario::setup_commands()) {
        ctl.receive(&frame(seq, msg), &rig, &mut tx);
    }
    (ctl, rig, tx, TankModel::new(TankModelParams::default()))
}

/// Runs `n` 1-ms periods; returns the final state so nothing is optimised out.
fn run(n: u32, with_controller: bool) -> (u32, u32) {
    let (mut ctl, mut rig, mut tx, mut model) = setup();
    let heartbeat = frame(100, HostMsg::Heartbeat);
    for _ in 0..n {
        rig.now_ms += 1;
        model.advance(1, rig.pumps, &rig.chambers);
        let (p, q) = model.tanks_pa();
        rig.tanks_pa = (p, q);
        if with_controller {
            if rig.now_ms % 100 == 0 {
                ctl.receive(black_box(&heartbeat), &rig, &mut tx);
            }
            ctl.tick(black_box(&mut rig), &mut tx);
        } else {
            rig.pumps = PumpOutputs {
                positive_on: p < 40_000,
                negative_on: q > -45_000,
            };
        }
        while tx.pop().is_some() {}
    }
    (ctl.loop_overruns(), ctl.link_stats().frames_ok)
}

fn time_per_tick_ns(n: u32, with_controller: bool) -> f64 {
    let start = Instant::now();
    black_box(run(n, with_controller));
    start.elapsed().as_nanos() as f64 / f64::from(n)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if let Some(n) = args.first().and_then(|a| a.parse::<u32>().ok()) {
        // Untimed run for instruction counting.
        let with_controller = args.get(1).map(String::as_str) != Some("model-only");
        black_box(run(n, with_controller));
        return;
    }
    // `cargo bench` passes `--bench`; anything else is ignored.
    const TICKS: u32 = 2_000_000;
    const ROUNDS: usize = 5;
    // Warm-up.
    black_box(run(TICKS / 10, true));
    let mut full: Vec<f64> = (0..ROUNDS).map(|_| time_per_tick_ns(TICKS, true)).collect();
    let mut model: Vec<f64> = (0..ROUNDS)
        .map(|_| time_per_tick_ns(TICKS, false))
        .collect();
    full.sort_by(f64::total_cmp);
    model.sort_by(f64::total_cmp);
    let median = |v: &[f64]| v[v.len() / 2];
    println!(
        "control tick + model: median {:.1} ns/tick (min {:.1}, max {:.1}) over {ROUNDS} x {TICKS} ticks",
        median(&full),
        full[0],
        full[ROUNDS - 1]
    );
    println!(
        "model only:           median {:.1} ns/tick (min {:.1}, max {:.1})",
        median(&model),
        model[0],
        model[ROUNDS - 1]
    );
    println!(
        "control core:         {:.1} ns/tick (difference of the medians)",
        median(&full) - median(&model)
    );
}
