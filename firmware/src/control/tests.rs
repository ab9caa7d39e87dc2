//! Tests of the safety loop: behaviour examples, then property tests over
//! arbitrary command sequences, pressure traces and physics.
//!
//! The fake rig ([`Rig`]) is physical where it matters: the sensors give ADC
//! counts (ratiometric to a supply that need not be 5 V, with noise, an
//! offset, an open wire or a frozen value), and the valves release late
//! ([`PhysicalValves`]), so the interlock is checked on what the valves
//! physically do, not on the commanded [`ValveState`].

use std::vec;
use std::vec::Vec;

use dexitac_protocol::{
    ArmState, Calibration, CalibrationRecord, CalibrationSource, Chambers, Decoder, EncodedFrame,
    Fault, FaultFlags, Frame, FrameError, HostMsg, LastStop, McuMsg, Message, NackReason, PumpMode,
    ResetCause, SensorCalibration, TankTargets, ValveState, ZeroSource, CALIBRATION_GAIN_MAX_PPM,
    CALIBRATION_GAIN_MIN_PPM, CALIBRATION_OFFSET_MAX_PA, CHAMBER_COUNT, GAIN_UNITY_PPM,
    NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA,
};
use proptest::prelude::*;

use super::hw::{Clock, PressureSource, Pumps, SensorError, Valves};
use super::valves::{ValveLevels, SAFE_CHAMBERS, VENT_CHAMBERS};
use super::*;
use crate::calibration::{NoStore, RamPage, RECORD_LEN, RECORD_VERSION};
use crate::queue::TxQueues;
use crate::sensor::{SensorSamples, NOMINAL_FRONT_END, OVERSAMPLE};
use crate::tank_model::{TankModel, TankModelParams};

/// Where the fake rig's true pressures come from.
enum Source {
    /// Fixed pressures (or sensor errors), set by the test.
    Fixed(Result<i32, SensorError>, Result<i32, SensorError>),
    /// The simulated tanks, driven by the pumps and the physical valves.
    Model(TankModel),
}

/// Valves that open when commanded and close `release_ms` after the
/// command to close (a solenoid's release time).
#[derive(Debug, Clone, Copy, Default)]
struct PhysicalValves {
    commanded: ValveLevels,
    /// Per valve: open until this time (ms) after its close command.
    inlet_open_until_ms: [u32; CHAMBER_COUNT],
    outlet_open_until_ms: [u32; CHAMBER_COUNT],
    release_ms: u32,
}

impl PhysicalValves {
    fn command(&mut self, to: ValveLevels, now_ms: u32) {
        for i in 0..CHAMBER_COUNT {
            let bit = 1u8 << i;
            if self.commanded.inlets & bit != 0 && to.inlets & bit == 0 {
                self.inlet_open_until_ms[i] = now_ms + self.release_ms;
            }
            if self.commanded.outlets & bit != 0 && to.outlets & bit == 0 {
                self.outlet_open_until_ms[i] = now_ms + self.release_ms;
            }
        }
        self.commanded = to;
    }

    /// The valves physically open at `now_ms`.
    fn open_at(&self, now_ms: u32) -> ValveLevels {
        let mut open = self.commanded;
        for i in 0..CHAMBER_COUNT {
            if now_ms < self.inlet_open_until_ms[i] {
                open.inlets |= 1 << i;
            }
            if now_ms < self.outlet_open_until_ms[i] {
                open.outlets |= 1 << i;
            }
        }
        open
    }
}

/// What is wrong with one sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum SensorFault {
    None,
    /// The signal wire is open: the input floats to 0 counts.
    OpenWire,
    /// The sensor output is frozen at these counts.
    Stuck(u16),
}

/// A fake board.
struct Rig {
    now_ms: u32,
    source: Source,
    pumps: PumpOutputs,
    chambers: Chambers,
    valves: PhysicalValves,
    /// Some chamber's inlet and outlet were physically open at once.
    both_open_ever: bool,
    supply_mv: u32,
    vdda_mv: u32,
    /// Uniform noise of each conversion, ± this many pascal.
    noise_pa: i32,
    /// Each sensor's zero error, in pascal (positive, negative).
    offset_pa: (i32, i32),
    /// Each sensor's gain error, in ppm (positive, negative): it shows
    /// `true * gain + offset`.
    gain_ppm: (u32, u32),
    sensor_faults: (SensorFault, SensorFault),
    /// A dead pump does not move air whatever its output says.
    pump_dead: (bool, bool),
    rng: u64,
}

impl Rig {
    fn fixed(positive_pa: i32, negative_pa: i32) -> Rig {
        Rig::with(Source::Fixed(Ok(positive_pa), Ok(negative_pa)))
    }

    fn model() -> Rig {
        Rig::with(Source::Model(TankModel::new(TankModelParams::default())))
    }

    fn with(source: Source) -> Rig {
        Rig {
            now_ms: 0,
            source,
            pumps: PumpOutputs::OFF,
            chambers: SAFE_CHAMBERS,
            valves: PhysicalValves::default(),
            both_open_ever: false,
            supply_mv: 5_000,
            vdda_mv: 3_300,
            noise_pa: 0,
            offset_pa: (0, 0),
            gain_ppm: (GAIN_UNITY_PPM, GAIN_UNITY_PPM),
            sensor_faults: (SensorFault::None, SensorFault::None),
            pump_dead: (false, false),
            rng: 0x9E37_79B9_7F4A_7C15,
        }
    }

    /// The true tank pressures (no sensor error).
    fn true_pa(&self) -> (Result<i32, SensorError>, Result<i32, SensorError>) {
        match &self.source {
            Source::Fixed(p, n) => (*p, *n),
            Source::Model(m) => {
                let (p, n) = m.tanks_pa();
                (Ok(p), Ok(n))
            }
        }
    }

    fn model_pa(&self) -> (i32, i32) {
        match &self.source {
            Source::Model(m) => m.tanks_pa(),
            Source::Fixed(..) => panic!("not a model rig"),
        }
    }

    fn next_noise_pa(&mut self) -> i32 {
        // xorshift64*
        self.rng ^= self.rng >> 12;
        self.rng ^= self.rng << 25;
        self.rng ^= self.rng >> 27;
        let r = self.rng.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 33;
        if self.noise_pa == 0 {
            return 0;
        }
        let span = 2 * i64::from(self.noise_pa) + 1;
        (r as i64 % span - i64::from(self.noise_pa)) as i32
    }

    fn channel(
        &mut self,
        pa: Result<i32, SensorError>,
        (offset_pa, gain_ppm): (i32, u32),
        fault: SensorFault,
    ) -> Result<[u16; OVERSAMPLE], SensorError> {
        let shown = i64::from(pa?) * i64::from(gain_ppm) / i64::from(GAIN_UNITY_PPM);
        let pa = i32::try_from(shown).unwrap();
        let mut out = [0u16; OVERSAMPLE];
        for c in out.iter_mut() {
            let noisy = pa + offset_pa + self.next_noise_pa();
            *c = match fault {
                SensorFault::None => {
                    NOMINAL_FRONT_END.sensor_counts(noisy, self.supply_mv, self.vdda_mv)
                }
                SensorFault::OpenWire => 0,
                SensorFault::Stuck(counts) => counts,
            };
        }
        Ok(out)
    }

    /// One ms of physics, with the outputs as they were during it.
    fn advance(&mut self) {
        let open = self.valves.open_at(self.now_ms);
        let pumps = PumpOutputs {
            positive_on: self.pumps.positive_on && !self.pump_dead.0,
            negative_on: self.pumps.negative_on && !self.pump_dead.1,
        };
        if let Source::Model(m) = &mut self.source {
            m.advance_levels(1, pumps, open);
        }
        self.now_ms = self.now_ms.wrapping_add(1);
    }
}

impl Clock for Rig {
    fn now_ms(&self) -> u32 {
        self.now_ms
    }
}

impl PressureSource for Rig {
    fn read_samples(&mut self) -> SensorSamples {
        let (p, n) = self.true_pa();
        let positive = self.channel(p, (self.offset_pa.0, self.gain_ppm.0), self.sensor_faults.0);
        let negative = self.channel(n, (self.offset_pa.1, self.gain_ppm.1), self.sensor_faults.1);
        let supply = NOMINAL_FRONT_END.supply_counts(self.supply_mv, self.vdda_mv);
        SensorSamples {
            positive,
            negative,
            supply: Ok([supply; OVERSAMPLE]),
        }
    }
}

impl Valves for Rig {
    fn set_chambers(&mut self, chambers: &Chambers) {
        self.valves
            .command(ValveLevels::from_chambers(chambers), self.now_ms);
        self.both_open_ever |= self.valves.open_at(self.now_ms).shorts_tanks();
        self.chambers = *chambers;
    }
}

impl Pumps for Rig {
    fn set_pumps(&mut self, pumps: PumpOutputs) {
        self.pumps = pumps;
    }
}

/// A controller with its rig and link.
struct Bench {
    ctl: Controller,
    rig: Rig,
    tx: TxQueues<4096, 4096>,
    host_rx: Decoder<McuMsg>,
    seq: u16,
}

impl Bench {
    fn new(rig: Rig) -> Bench {
        Bench::with_config(rig, Config::default())
    }

    fn with_config(rig: Rig, config: Config) -> Bench {
        Bench {
            ctl: Controller::new(config, ResetCause::PowerOn),
            rig,
            tx: TxQueues::new(),
            host_rx: Decoder::new(),
            seq: 0,
        }
    }

    /// Sends `msg` and returns the controller's replies.
    fn send(&mut self, msg: HostMsg) -> Vec<McuMsg> {
        self.seq = self.seq.wrapping_add(1);
        let frame = EncodedFrame::new(self.seq, &msg).unwrap();
        self.ctl.receive(&frame, &self.rig, &mut self.tx);
        self.drain()
    }

    /// Sends `msg`, expects an ack.
    fn ack(&mut self, msg: HostMsg) {
        let r = self.send(msg);
        assert_eq!(r, [McuMsg::Ack { seq: self.seq }], "{msg:?}");
    }

    /// Sends `msg`, expects a nack for `reason`.
    fn nack(&mut self, msg: HostMsg, reason: NackReason) {
        let r = self.send(msg);
        assert_eq!(
            r,
            [McuMsg::Nack {
                seq: self.seq,
                reason
            }],
            "{msg:?}"
        );
    }

    /// Advances time by 1 ms and runs one tick; returns the messages sent.
    fn tick(&mut self) -> Vec<McuMsg> {
        self.rig.advance();
        self.ctl.tick(&mut self.rig, &mut self.tx);
        self.drain()
    }

    fn ticks(&mut self, n: u32) -> Vec<McuMsg> {
        (0..n).flat_map(|_| self.tick()).collect()
    }

    /// Runs `ms` ticks with a heartbeat every 100 ms.
    fn ticks_alive(&mut self, ms: u32) -> Vec<McuMsg> {
        let mut out = Vec::new();
        for i in 0..ms {
            if i % 100 == 0 {
                self.send(HostMsg::Heartbeat);
            }
            out.extend(self.tick());
        }
        out
    }

    fn drain(&mut self) -> Vec<McuMsg> {
        let mut bytes = Vec::new();
        while let Some(b) = self.tx.pop() {
            bytes.push(b);
        }
        self.host_rx
            .feed(&bytes)
            .map(|r| r.map(|Frame { msg, .. }| msg).unwrap())
            .collect()
    }

    /// Past the boot-time zeroing and the valves' start-up dead time.
    fn boot(&mut self) {
        self.ticks(ZERO_AT_TICK + DEFAULT_VALVE_DEAD_TIME_MS);
        assert!(self.ctl.zeroed());
    }

    fn arm(&mut self) {
        self.boot();
        self.ack(HostMsg::Arm);
    }
}

fn regulate_both() -> HostMsg {
    HostMsg::SetPumps {
        positive: PumpMode::Regulate,
        negative: PumpMode::Regulate,
    }
}

fn one_inflating() -> Chambers {
    let mut c = SAFE_CHAMBERS;
    c[0] = ValveState::Inflate;
    c
}

fn faults_of(msgs: &[McuMsg]) -> Vec<Fault> {
    msgs.iter()
        .filter_map(|m| match m {
            McuMsg::Fault(f) => Some(f.fault),
            _ => None,
        })
        .collect()
}

fn clear(faults: &[Fault]) -> HostMsg {
    HostMsg::ClearFaults {
        faults: faults.iter().fold(FaultFlags::NONE, |acc, f| acc.with(*f)),
    }
}

// ------------------------------------------------------------ configuration

#[test]
fn default_targets_are_inside_the_guard_band() {
    let c = Config::default();
    let t = c.default_targets;
    assert_eq!(
        (t.positive_pa(), t.negative_pa()),
        (DEFAULT_TARGETS_PA.0, DEFAULT_TARGETS_PA.1)
    );
    assert!(c.targets_inside_guard_band(t));
}

#[test]
fn fill_time_matches_the_tank_model() {
    // Pump from atmosphere with the pump on throughout: the slower tank
    // reaches its limit at NOMINAL_FILL_TIME_MS (within 1 %).
    let mut m = TankModel::new(TankModelParams::default());
    let on = PumpOutputs {
        positive_on: true,
        negative_on: true,
    };
    let (mut positive_at, mut negative_at) = (None, None);
    for t in 1..=20_000u32 {
        m.advance(1, on, &SAFE_CHAMBERS);
        let (p, n) = m.tanks_pa();
        if p >= POSITIVE_TANK_MAX_PA && positive_at.is_none() {
            positive_at = Some(t);
        }
        if n <= NEGATIVE_TANK_MIN_PA && negative_at.is_none() {
            negative_at = Some(t);
        }
    }
    let slower = positive_at.unwrap().max(negative_at.unwrap());
    assert!(
        slower.abs_diff(NOMINAL_FILL_TIME_MS) * 100 <= NOMINAL_FILL_TIME_MS,
        "model {slower} ms vs {NOMINAL_FILL_TIME_MS}"
    );
}

#[test]
fn fastest_pump_matches_the_tank_model() {
    let model = TankModelParams::default();
    assert_eq!(
        DEFAULT_PUMP_STALL_PA,
        (model.positive_stall_pa, model.negative_stall_pa)
    );
    // A pump 30 % stronger than the model's nominal one.
    assert_eq!(DEFAULT_FASTEST_PUMP_TAU_MS, model.pump_tau_ms * 10 / 13);
    assert_eq!(model.pump_tau_ms, model.negative_pump_tau_ms);
}

#[test]
fn min_telemetry_interval_follows_baud_and_frame_size() {
    // 44-byte frames, 10 bits a byte: 3.82 ms at 115 200 baud, doubled.
    assert_eq!(min_telemetry_interval_ms(115_200), 8);
    assert_eq!(min_telemetry_interval_ms(9_600), 92);
    assert_eq!(min_telemetry_interval_ms(1_000_000), 1);
}

// ------------------------------------------------------------- the protocol

#[test]
fn hello_reports_versions_limits_latches_and_last_stop() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.ctl = Controller::new(Config::default(), ResetCause::IndependentWatchdog)
        .with_last_stop(LastStop::Panic { line: 77 });
    b.ctl.report_fault(Fault::ClockFallback);
    b.tick();
    let replies = b.send(HostMsg::Hello);
    let [McuMsg::HelloReply(h)] = replies[..] else {
        panic!("{replies:?}")
    };
    assert_eq!(h.firmware_version, crate::FIRMWARE_VERSION);
    assert_eq!(h.positive_tank_max_pa, POSITIVE_TANK_MAX_PA);
    assert_eq!(h.negative_tank_min_pa, NEGATIVE_TANK_MIN_PA);
    assert_eq!(h.chamber_count, 8);
    assert_eq!(h.reset_cause, ResetCause::IndependentWatchdog);
    assert_eq!(h.last_stop, LastStop::Panic { line: 77 });
    assert_eq!(
        h.latched_faults,
        FaultFlags::NONE.with(Fault::ClockFallback)
    );
    assert_eq!(h.min_telemetry_interval_ms, 8);
    // No calibration store given: identity, not persisted; zeros pending
    // (one tick after boot).
    let cal = h.calibration;
    assert_eq!(cal.calibration, Calibration::IDENTITY);
    assert_eq!(cal.source, CalibrationSource::Default);
    assert_eq!(cal.record, CalibrationRecord::NotPersisted);
    assert_eq!(cal.positive_zero.source, ZeroSource::Pending);
    assert_eq!(cal.negative_zero.zero_pa, 0);
}

#[test]
fn clock_fallback_latches_until_acknowledged() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.ctl.report_fault(Fault::ClockFallback);
    let sent = b.tick();
    assert_eq!(faults_of(&sent), [Fault::ClockFallback]);
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    b.boot();
    b.nack(HostMsg::Arm, NackReason::Tripped);
    b.ack(clear(&[Fault::ClockFallback]));
    b.ack(HostMsg::Arm);
}

#[test]
fn set_chambers_while_disarmed_is_refused_and_changes_nothing() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.boot();
    b.nack(
        HostMsg::SetChambers {
            chambers: one_inflating(),
        },
        NackReason::NotArmed,
    );
    b.tick();
    assert_eq!(b.rig.chambers, SAFE_CHAMBERS);
}

#[test]
fn arm_waits_for_the_boot_zero() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.tick();
    b.nack(HostMsg::Arm, NackReason::Refused);
    b.boot();
    b.ack(HostMsg::Arm);
}

#[test]
fn armed_set_chambers_drives_the_valves_at_the_next_tick() {
    let mut b = Bench::new(Rig::fixed(30_000, -30_000));
    b.arm();
    b.ack(HostMsg::SetChambers {
        chambers: one_inflating(),
    });
    b.tick();
    assert_eq!(b.rig.chambers, one_inflating());
    assert_eq!(b.rig.valves.commanded.inlets, 1);
}

#[test]
fn targets_outside_the_guard_band_are_refused() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    let band = DEFAULT_GUARD_BAND_PA;
    let ok = TankTargets::new(POSITIVE_TANK_MAX_PA - band, NEGATIVE_TANK_MIN_PA + band).unwrap();
    b.ack(HostMsg::SetTankTargets(ok));
    for (p, n) in [
        (POSITIVE_TANK_MAX_PA - band + 1, -10_000),
        (10_000, NEGATIVE_TANK_MIN_PA + band - 1),
        (POSITIVE_TANK_MAX_PA, NEGATIVE_TANK_MIN_PA),
    ] {
        b.nack(
            HostMsg::SetTankTargets(TankTargets::new(p, n).unwrap()),
            NackReason::GuardBand,
        );
    }
}

// ------------------------------------------------------------------ latches

#[test]
fn host_silence_trips_pumps_and_seals_valves() {
    let mut b = Bench::new(Rig::model());
    b.arm();
    b.ack(regulate_both());
    b.ack(HostMsg::SetChambers {
        chambers: one_inflating(),
    });
    let armed_at = b.rig.now_ms;
    let sent = b.ticks(DEFAULT_HOST_SILENCE_MS - 1);
    assert_eq!(b.ctl.state(), ArmState::Armed);
    assert!(b.rig.pumps.positive_on);
    assert!(faults_of(&sent).is_empty());
    let sent = b.tick();
    assert_eq!(b.rig.now_ms - armed_at, DEFAULT_HOST_SILENCE_MS);
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    assert_eq!(b.rig.pumps, PumpOutputs::OFF);
    assert_eq!(b.rig.chambers, SAFE_CHAMBERS);
    assert_eq!(faults_of(&sent), [Fault::HostSilence]);
}

#[test]
fn heartbeats_keep_an_armed_controller_armed() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    for _ in 0..10 {
        b.ticks(400);
        b.send(HostMsg::Heartbeat);
    }
    assert_eq!(b.ctl.state(), ArmState::Armed);
}

#[test]
fn disarm_does_not_clear_a_trip_only_clear_faults_naming_it_does() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    b.ticks(DEFAULT_HOST_SILENCE_MS);
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    b.nack(HostMsg::Arm, NackReason::Tripped);
    b.nack(regulate_both(), NackReason::Tripped);
    b.ack(HostMsg::Disarm);
    b.tick();
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    assert!(b.ctl.faults().contains(Fault::HostSilence));
    b.nack(HostMsg::Arm, NackReason::Tripped);
    // Naming another fault clears nothing.
    b.ack(clear(&[Fault::PositiveOverLimit]));
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    b.ack(clear(&[Fault::HostSilence]));
    assert_eq!(b.ctl.state(), ArmState::Disarmed);
    assert!(b.ctl.faults().is_empty());
    b.ack(HostMsg::Arm);
}

#[test]
fn over_limit_trips_within_the_stated_time_and_stays_latched_while_present() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    // A step of the true pressure to just past the limit: the filtered
    // value crosses within FILTER_TICKS, then trip_after_ticks.
    b.rig.source = Source::Fixed(Ok(POSITIVE_TANK_MAX_PA + 500), Ok(0));
    let step_at = b.rig.now_ms;
    let mut tripped_at = None;
    for _ in 0..100 {
        if !faults_of(&b.tick()).is_empty() {
            tripped_at = Some(b.rig.now_ms);
            break;
        }
    }
    let after_ms = tripped_at.unwrap() - step_at;
    let stated_ms = filter::FILTER_TICKS as u32 + DEFAULT_TRIP_AFTER_TICKS;
    assert!(after_ms <= stated_ms, "{after_ms} ms > {stated_ms} ms");
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    assert!(b.ctl.faults().contains(Fault::PositiveOverLimit));
    // Still present: neither clear nor arm.
    b.nack(clear(&[Fault::PositiveOverLimit]), NackReason::Refused);
    b.nack(HostMsg::Arm, NackReason::Tripped);
    // Vented below the limit: the fault can be acknowledged.
    b.rig.source = Source::Fixed(Ok(30_000), Ok(0));
    b.ticks(20);
    b.ack(clear(&[Fault::PositiveOverLimit]));
    b.ack(HostMsg::Arm);
}

#[test]
fn over_limit_while_disarmed_latches_too() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.boot();
    b.rig.source = Source::Fixed(Ok(0), Ok(NEGATIVE_TANK_MIN_PA - 1_000));
    let sent = b.ticks(30);
    assert_eq!(faults_of(&sent), [Fault::NegativeOverLimit]);
    assert_eq!(b.ctl.state(), ArmState::Tripped);
}

#[test]
fn sensor_error_trips_after_three_ticks() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    b.rig.source = Source::Fixed(Ok(0), Err(SensorError::OutOfRange));
    b.ticks(2);
    assert_eq!(b.ctl.state(), ArmState::Armed);
    b.tick();
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    assert!(b.ctl.faults().contains(Fault::NegativeSensor));
    assert_eq!(
        b.ctl.telemetry(0).negative_tank_pa,
        dexitac_protocol::NO_READING_PA
    );
}

#[test]
fn open_wire_trips_with_a_sensor_fault() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    b.rig.sensor_faults.0 = SensorFault::OpenWire;
    b.ticks(DEFAULT_TRIP_AFTER_TICKS);
    assert!(b.ctl.faults().contains(Fault::PositiveSensor));
}

#[test]
fn stuck_sensor_while_pumping_trips_despite_noise() {
    // The readings do not follow the pumps (fixed, far below the target),
    // but carry ±2 % FS of noise: the no-rise check still fires.
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.rig.noise_pa = 8_000;
    b.arm();
    b.ack(regulate_both());
    let sent = b.ticks_alive(2 * DEFAULT_RISE_WINDOW_MS + 10);
    let faults = faults_of(&sent);
    assert!(faults.contains(&Fault::PositivePumpNoRise), "{faults:?}");
    assert!(faults.contains(&Fault::NegativePumpNoRise), "{faults:?}");
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    assert_eq!(b.rig.pumps, PumpOutputs::OFF);
    // Latched after the pumps stopped (the condition is gone).
    b.ticks(10);
    b.nack(HostMsg::Arm, NackReason::Tripped);
    b.ack(clear(&[
        Fault::PositivePumpNoRise,
        Fault::NegativePumpNoRise,
    ]));
    b.ack(HostMsg::Arm);
}

#[test]
fn pump_run_time_limit_trips() {
    // A weak pump into a leaky tank: the pressure rises (enough for the
    // no-rise check) but never reaches the target.
    let params = TankModelParams {
        pump_tau_ms: 40_000,
        leak_tau_ms: 40_000,
        ..TankModelParams::default()
    };
    let mut b = Bench::new(Rig::with(Source::Model(TankModel::new(params))));
    b.arm();
    b.ack(HostMsg::SetPumps {
        positive: PumpMode::Regulate,
        negative: PumpMode::Off,
    });
    let started = b.rig.now_ms;
    let mut tripped_at = None;
    for _ in 0..(DEFAULT_PUMP_MAX_RUN_MS / 100 + 10) {
        b.ticks(100);
        if b.ctl.state() == ArmState::Tripped {
            tripped_at = Some(b.rig.now_ms - started);
            break;
        }
        b.send(HostMsg::Heartbeat);
    }
    assert_eq!(
        b.ctl.faults(),
        FaultFlags::NONE.with(Fault::PositivePumpRunTime)
    );
    let t = tripped_at.unwrap();
    assert!(
        t > DEFAULT_PUMP_MAX_RUN_MS && t <= DEFAULT_PUMP_MAX_RUN_MS + 100,
        "{t}"
    );
    b.ticks(10);
    b.nack(HostMsg::Arm, NackReason::Tripped);
}

#[test]
fn vent_all_is_accepted_when_tripped_by_silence() {
    let mut b = Bench::new(Rig::fixed(0, -40_000));
    b.arm();
    b.ticks(DEFAULT_HOST_SILENCE_MS);
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    b.ack(HostMsg::VentAll);
    b.ticks(DEFAULT_VALVE_DEAD_TIME_MS + 1);
    assert_eq!(b.rig.chambers, VENT_CHAMBERS);
    assert_eq!(b.rig.pumps, PumpOutputs::OFF);
    assert_eq!(b.ctl.state(), ArmState::Tripped);
}

#[test]
fn vent_all_onto_a_negative_tank_past_its_limit_is_refused() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    b.rig.source = Source::Fixed(Ok(0), Ok(NEGATIVE_TANK_MIN_PA - 3_000));
    let sent = b.ticks(40);
    assert_eq!(faults_of(&sent), [Fault::NegativeOverLimit]);
    b.nack(HostMsg::VentAll, NackReason::Refused);
    b.ticks(40);
    assert_eq!(b.rig.chambers, SAFE_CHAMBERS);
}

#[test]
fn venting_stops_when_the_negative_tank_goes_bad() {
    let mut b = Bench::new(Rig::fixed(0, -40_000));
    b.boot();
    b.ack(HostMsg::VentAll);
    b.ticks(5);
    assert_eq!(b.rig.chambers, VENT_CHAMBERS);
    b.rig.source = Source::Fixed(Ok(0), Err(SensorError::OutOfRange));
    b.ticks(DEFAULT_TRIP_AFTER_TICKS);
    assert_eq!(b.rig.chambers, SAFE_CHAMBERS);
}

// --------------------------------------------------------- sensor handling

#[test]
fn supply_at_4_75_v_still_regulates_to_the_true_target() {
    let mut b = Bench::new(Rig::model());
    b.rig.supply_mv = 4_750;
    b.arm();
    b.ack(regulate_both());
    b.ticks_alive(10_000);
    assert_eq!(b.ctl.state(), ArmState::Armed, "{:?}", b.ctl.faults());
    let (pos, neg) = b.rig.model_pa();
    let (tp, tn) = DEFAULT_TARGETS_PA;
    assert!((tp - 3_000..=tp + 1_000).contains(&pos), "{pos}");
    assert!((tn - 1_000..=tn + 3_000).contains(&neg), "{neg}");
}

#[test]
fn boot_zero_removes_a_sensor_offset_inside_the_window() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.rig.offset_pa = (3_000, -2_500);
    b.rig.noise_pa = 8_000;
    b.boot();
    let (zp, zn) = b.ctl.zero_offsets_pa().unwrap();
    assert!((zp - 3_000).abs() < 800, "{zp}");
    assert!((zn + 2_500).abs() < 800, "{zn}");
    b.ticks(20);
    let (p, n) = b.ctl.readings();
    assert!(
        p.unwrap().abs() < 800 && n.unwrap().abs() < 800,
        "{p:?} {n:?}"
    );
}

#[test]
fn boot_zero_ignores_a_tank_still_under_pressure() {
    let mut b = Bench::new(Rig::fixed(20_000, 0));
    b.boot();
    assert_eq!(b.ctl.zero_offsets_pa().unwrap().0, 0);
}

#[test]
fn pumps_regulate_the_model_tanks_to_their_targets() {
    let mut b = Bench::new(Rig::model());
    b.rig.noise_pa = 8_000;
    b.arm();
    b.ack(HostMsg::SetTankTargets(
        TankTargets::new(30_000, -30_000).unwrap(),
    ));
    b.ack(regulate_both());
    b.ticks_alive(10_000);
    assert_eq!(b.ctl.state(), ArmState::Armed, "{:?}", b.ctl.faults());
    let (pos, neg) = b.rig.model_pa();
    assert!((27_000..=31_000).contains(&pos), "{pos}");
    assert!((-31_000..=-27_000).contains(&neg), "{neg}");
}

// --------------------------------------------------------------------- link

#[test]
fn telemetry_arrives_at_the_requested_interval() {
    let mut b = Bench::new(Rig::fixed(1_000, -2_000));
    b.ack(HostMsg::SetTelemetryInterval { interval_ms: 10 });
    b.ticks(50);
    let sent = b.ticks(100);
    let times: Vec<u32> = sent
        .iter()
        .filter_map(|m| match m {
            McuMsg::Telemetry(t) => Some(t.time_ms),
            _ => None,
        })
        .collect();
    assert_eq!(times.len(), 10);
    assert!(times.windows(2).all(|w| w[1] - w[0] == 10), "{times:?}");
    let McuMsg::Telemetry(t) = sent[0] else {
        panic!()
    };
    // The boot zero took the 1 kPa / -2 kPa as atmosphere (inside ±4 kPa).
    assert!(t.positive_tank_pa.abs() < 300, "{t:?}");
    b.ack(HostMsg::SetTelemetryInterval { interval_ms: 0 });
    assert!(b.ticks(100).is_empty());
}

#[test]
fn telemetry_faster_than_the_line_is_refused() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    let min = Config::default().min_telemetry_interval_ms();
    b.nack(
        HostMsg::SetTelemetryInterval {
            interval_ms: min - 1,
        },
        NackReason::IntervalTooShort,
    );
    b.ack(HostMsg::SetTelemetryInterval { interval_ms: min });
}

#[test]
fn telemetry_keeps_its_cadence_after_a_late_tick() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.ack(HostMsg::SetTelemetryInterval { interval_ms: 10 });
    let start = b.rig.now_ms;
    // Reports at 1 and 11 ms; the tick due at 21 ms comes at 23 ms.
    b.ticks(20);
    b.rig.now_ms += 2;
    let mut sent = b.tick();
    sent.extend(b.ticks(20));
    let times: Vec<u32> = sent
        .iter()
        .filter_map(|m| match m {
            McuMsg::Telemetry(t) => Some(t.time_ms - start),
            _ => None,
        })
        .collect();
    assert_eq!(times, [23, 31, 41]);
}

#[test]
fn acks_and_faults_are_never_dropped_for_telemetry() {
    // A tiny telemetry queue that is never drained: telemetry is dropped,
    // every ack and the fault event still go out.
    let mut ctl = Controller::new(Config::default(), ResetCause::PowerOn);
    let mut rig = Rig::fixed(0, 0);
    let mut tx = TxQueues::<2048, 64>::new();
    let mut seq = 0u16;
    let mut send = |ctl: &mut Controller, rig: &Rig, tx: &mut TxQueues<2048, 64>, msg| {
        seq += 1;
        ctl.receive(&EncodedFrame::new(seq, &msg).unwrap(), rig, tx);
    };
    send(
        &mut ctl,
        &rig,
        &mut tx,
        HostMsg::SetTelemetryInterval { interval_ms: 8 },
    );
    for _ in 0..100 {
        rig.advance();
        ctl.tick(&mut rig, &mut tx);
    }
    send(&mut ctl, &rig, &mut tx, HostMsg::Arm);
    for _ in 0..DEFAULT_HOST_SILENCE_MS + 50 {
        rig.advance();
        ctl.tick(&mut rig, &mut tx);
    }
    assert!(ctl.link_stats().telemetry_dropped > 10);
    assert_eq!(ctl.link_stats().urgent_dropped, 0);
    let mut bytes = Vec::new();
    while let Some(b) = tx.pop() {
        bytes.push(b);
    }
    let msgs: Vec<McuMsg> = Decoder::<McuMsg>::new()
        .feed(&bytes)
        .map(|r| r.unwrap().msg)
        .collect();
    assert!(msgs.contains(&McuMsg::Ack { seq: 1 }));
    assert!(msgs.contains(&McuMsg::Ack { seq: 2 }));
    assert_eq!(faults_of(&msgs), [Fault::HostSilence]);
}

#[test]
fn late_ticks_count_as_overruns() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.ticks(5);
    assert_eq!(b.ctl.loop_overruns(), 0);
    b.rig.now_ms += 3;
    b.tick();
    assert_eq!(b.ctl.loop_overruns(), 1);
}

#[test]
fn corrupted_frame_is_dropped_and_malformed_frame_is_nacked() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    let mut frame = EncodedFrame::new(
        9,
        &HostMsg::SetChambers {
            chambers: one_inflating(),
        },
    )
    .unwrap()
    .to_vec();
    frame[4] ^= 0x10;
    b.ctl.receive(&frame, &b.rig, &mut b.tx);
    assert!(b.drain().is_empty());
    // Valid CRC, but a valve state tag of 7: malformed.
    let mut raw = std::vec![
        dexitac_protocol::PROTOCOL_VERSION,
        10,
        0,
        2,
        7,
        0,
        0,
        0,
        0,
        0,
        0,
        0
    ];
    let crc = crc32c(&raw);
    raw.extend_from_slice(&crc.to_le_bytes());
    let mut wire = cobs_encode(&raw);
    wire.push(0);
    let decoded: Vec<_> = Decoder::<HostMsg>::new().feed(&wire).collect();
    assert_eq!(decoded, [Err(FrameError::Malformed { seq: 10 })]);
    b.ctl.receive(&wire, &b.rig, &mut b.tx);
    assert_eq!(
        b.drain(),
        [McuMsg::Nack {
            seq: 10,
            reason: NackReason::Malformed
        }]
    );
    b.tick();
    assert_eq!(b.rig.chambers, SAFE_CHAMBERS);
    assert_eq!(b.ctl.link_stats().frame_errors, 2);
}

/// The frame CRC: CRC-32C over the direction byte and the header and body.
fn crc32c(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in [HostMsg::DIRECTION].iter().chain(bytes) {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0x82F6_3B78
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

#[test]
fn test_frame_helpers_match_the_protocol_encoder() {
    let mut raw = std::vec![
        dexitac_protocol::PROTOCOL_VERSION,
        10,
        0,
        2,
        0,
        0,
        0,
        0,
        0,
        0,
        0,
        0
    ];
    let crc = crc32c(&raw);
    raw.extend_from_slice(&crc.to_le_bytes());
    let mut wire = cobs_encode(&raw);
    wire.push(0);
    let reference = EncodedFrame::new(
        10,
        &HostMsg::SetChambers {
            chambers: SAFE_CHAMBERS,
        },
    )
    .unwrap();
    assert_eq!(&wire[..], &reference[..]);
}

fn cobs_encode(raw: &[u8]) -> Vec<u8> {
    let mut out = std::vec![0u8];
    let mut code_at = 0;
    for &b in raw {
        if b == 0 {
            out[code_at] = (out.len() - code_at) as u8;
            code_at = out.len();
            out.push(0);
        } else {
            out.push(b);
            if out.len() - code_at == 0xFF {
                out[code_at] = 0xFF;
                code_at = out.len();
                out.push(0);
            }
        }
    }
    out[code_at] = (out.len() - code_at) as u8;
    out
}

// ---------------------------------------------------------------- properties

fn valve_state() -> impl Strategy<Value = ValveState> {
    prop_oneof![
        Just(ValveState::Hold),
        Just(ValveState::Inflate),
        Just(ValveState::Deflate)
    ]
}

fn pump_mode() -> impl Strategy<Value = PumpMode> {
    prop_oneof![Just(PumpMode::Off), Just(PumpMode::Regulate)]
}

fn fault_flags() -> impl Strategy<Value = FaultFlags> {
    (0u16..(1 << Fault::ALL.len())).prop_map(FaultFlags)
}

fn host_msg() -> impl Strategy<Value = HostMsg> {
    prop_oneof![
        1 => Just(HostMsg::Hello),
        1 => any::<u32>().prop_map(|nonce| HostMsg::Ping { nonce }),
        3 => proptest::array::uniform8(valve_state()).prop_map(|chambers| HostMsg::SetChambers {
            chambers
        }),
        1 => Just(HostMsg::SealAll),
        1 => Just(HostMsg::VentAll),
        3 => (pump_mode(), pump_mode())
            .prop_map(|(positive, negative)| HostMsg::SetPumps { positive, negative }),
        2 => (0..=POSITIVE_TANK_MAX_PA, NEGATIVE_TANK_MIN_PA..=0).prop_map(|(p, n)| {
            HostMsg::SetTankTargets(TankTargets::new(p, n).unwrap())
        }),
        3 => Just(HostMsg::Arm),
        1 => Just(HostMsg::Disarm),
        2 => fault_flags().prop_map(|faults| HostMsg::ClearFaults { faults }),
        1 => (0u16..50).prop_map(|interval_ms| HostMsg::SetTelemetryInterval { interval_ms }),
        3 => Just(HostMsg::Heartbeat),
        1 => calibration_msg(),
    ]
}

/// Calibrations, plausible or not (about half of each).
fn calibration_msg() -> impl Strategy<Value = HostMsg> {
    let sensor = (
        -2 * CALIBRATION_OFFSET_MAX_PA..=2 * CALIBRATION_OFFSET_MAX_PA,
        CALIBRATION_GAIN_MIN_PPM - 50_000..=CALIBRATION_GAIN_MAX_PPM + 50_000,
    )
        .prop_map(|(offset_pa, gain_ppm)| SensorCalibration {
            offset_pa,
            gain_ppm,
        });
    (sensor.clone(), sensor).prop_map(|(positive, negative)| {
        HostMsg::SetCalibration(Calibration { positive, negative })
    })
}

fn sensor_reading() -> impl Strategy<Value = Result<i32, SensorError>> {
    prop_oneof![
        8 => (-120_000..320_000i32).prop_map(Ok),
        4 => (-60_000..55_000i32).prop_map(Ok),
        1 => Just(Err(SensorError::OutOfRange)),
        1 => Just(Err(SensorError::NoSample)),
    ]
}

/// One step of a scenario.
#[derive(Debug, Clone)]
enum Event {
    /// A valid frame from the host.
    Frame(HostMsg),
    /// Random bytes on the line.
    Noise(Vec<u8>),
    /// Time passes, one tick per millisecond.
    Wait(u32),
    /// The sensors read these values from now on (replaces the model).
    Readings(Result<i32, SensorError>, Result<i32, SensorError>),
    /// The sensors follow a fresh tank model again.
    Model,
}

fn event() -> impl Strategy<Value = Event> {
    prop_oneof![
        6 => host_msg().prop_map(Event::Frame),
        1 => proptest::collection::vec(any::<u8>(), 1..40).prop_map(Event::Noise),
        5 => (1u32..300).prop_map(Event::Wait),
        2 => (sensor_reading(), sensor_reading()).prop_map(|(p, n)| Event::Readings(p, n)),
        1 => Just(Event::Model),
    ]
}

/// Checks after every tick: the invariants of the safety loop.
struct Observer {
    /// The state at the previous tick.
    last_state: ArmState,
    /// A `ClearFaults` was accepted since the previous tick.
    clear_seen: bool,
}

impl Observer {
    fn check_tick(&mut self, b: &Bench) -> Result<(), TestCaseError> {
        let state = b.ctl.state();
        let (positive, negative) = b.ctl.readings();
        // Interlock, physically.
        prop_assert!(
            !b.rig.both_open_ever,
            "inlet and outlet physically open together"
        );
        // Pumps run only armed, with a valid filtered reading inside the limit.
        if b.rig.pumps.positive_on {
            prop_assert_eq!(state, ArmState::Armed);
            let pa = positive.unwrap();
            prop_assert!(pa < POSITIVE_TANK_MAX_PA, "positive pump on at {} Pa", pa);
        }
        if b.rig.pumps.negative_on {
            prop_assert_eq!(state, ArmState::Armed);
            let pa = negative.unwrap();
            prop_assert!(pa > NEGATIVE_TANK_MIN_PA, "negative pump on at {} Pa", pa);
        }
        // Latching: once tripped, only an accepted ClearFaults leaves it.
        if self.last_state == ArmState::Tripped && !self.clear_seen {
            prop_assert_eq!(state, ArmState::Tripped);
        }
        // Tripped exactly while faults are latched.
        prop_assert_eq!(state == ArmState::Tripped, !b.ctl.faults().is_empty());
        // Not armed: pumps off, valves sealed or venting.
        if state != ArmState::Armed {
            prop_assert_eq!(b.rig.pumps, PumpOutputs::OFF);
            prop_assert!(b.rig.chambers.iter().all(|c| *c != ValveState::Inflate));
        }
        self.clear_seen = false;
        self.last_state = state;
        Ok(())
    }
}

fn run_scenario(events: &[Event], config: Config) -> Result<Bench, TestCaseError> {
    let mut b = Bench::with_config(Rig::model(), config);
    let mut obs = Observer {
        last_state: ArmState::Disarmed,
        clear_seen: false,
    };
    // The board's flash page, written after each frame as the board does.
    let mut page = RamPage::default();
    for e in events {
        match e {
            Event::Frame(msg) => {
                let state_before = b.ctl.state();
                let calibration_before = b.ctl.calibration_report().calibration;
                let replies = b.send(*msg);
                let acked = replies.iter().any(|r| matches!(r, McuMsg::Ack { .. }));
                if matches!(msg, HostMsg::ClearFaults { .. }) && acked {
                    obs.clear_seen = true;
                }
                // A calibration changes only by an accepted SetCalibration,
                // only while disarmed, and only to a plausible one.
                let calibration = b.ctl.calibration_report().calibration;
                if let HostMsg::SetCalibration(asked) = msg {
                    // (A frame spoiled by noise before it gets no reply.)
                    if !replies.is_empty() {
                        prop_assert_eq!(
                            acked,
                            state_before == ArmState::Disarmed && asked.check().is_ok()
                        );
                    }
                    if acked {
                        prop_assert_eq!(calibration, *asked);
                    }
                }
                if calibration != calibration_before {
                    prop_assert!(matches!(msg, HostMsg::SetCalibration(_)) && acked);
                }
                prop_assert!(calibration.check().is_ok());
                // Flash is written only while not armed with the pumps off.
                let (state, pumps) = (b.ctl.state(), b.rig.pumps);
                let pending = b.ctl.calibration_write_pending();
                let wrote = b.ctl.store_calibration(&mut page);
                prop_assert_eq!(wrote.is_some(), pending);
                if wrote.is_some() {
                    prop_assert!(state != ArmState::Armed && pumps == PumpOutputs::OFF);
                    prop_assert_eq!(
                        crate::calibration::decode(&page.bytes).calibration,
                        Some(calibration)
                    );
                }
            }
            Event::Noise(bytes) => {
                b.ctl.receive(bytes, &b.rig, &mut b.tx);
                b.drain();
            }
            Event::Wait(ms) => {
                for _ in 0..*ms {
                    b.tick();
                    obs.check_tick(&b)?;
                }
            }
            Event::Readings(p, n) => b.rig.source = Source::Fixed(*p, *n),
            Event::Model => {
                b.rig.source = Source::Model(TankModel::new(TankModelParams::default()));
            }
        }
    }
    Ok(b)
}

/// Random chamber commands at random intervals; the valves release
/// `release_ms` late. Returns whether a chamber was ever physically open
/// both ways.
fn valves_ever_open_both_ways(
    commands: &[(Chambers, u32)],
    release_ms: u32,
    dead_time_ms: u32,
) -> bool {
    let config = Config {
        valve_dead_time_ms: dead_time_ms,
        ..Config::default()
    };
    let mut b = Bench::with_config(Rig::fixed(20_000, -20_000), config);
    b.rig.valves.release_ms = release_ms;
    b.arm();
    for (chambers, wait_ms) in commands {
        b.send(HostMsg::SetChambers {
            chambers: *chambers,
        });
        for _ in 0..*wait_ms {
            b.tick();
            // The physical state at every millisecond until the next tick.
            b.rig.both_open_ever |= b.rig.valves.open_at(b.rig.now_ms).shorts_tanks();
        }
        b.send(HostMsg::Heartbeat);
    }
    b.rig.both_open_ever
}

#[test]
fn the_interlock_check_catches_a_dead_time_shorter_than_the_release() {
    // The property below must be able to fail: with valves that release in
    // 25 ms and a dead time of 10 ms, inflate -> deflate overlaps.
    let inflate = [ValveState::Inflate; CHAMBER_COUNT];
    let commands = [(inflate, 100), (VENT_CHAMBERS, 100)];
    assert!(valves_ever_open_both_ways(&commands, 25, 10));
    assert!(!valves_ever_open_both_ways(
        &commands,
        25,
        DEFAULT_VALVE_DEAD_TIME_MS
    ));
}

/// A random physical rig: noise, supply, valves, pumps, leaks.
#[derive(Debug, Clone)]
struct Physics {
    noise_pa: i32,
    supply_mv: u32,
    vdda_mv: u32,
    release_ms: u32,
    /// Pump strengths in percent of nominal (positive, negative).
    pump_strength_pct: (u32, u32),
    leak_tau_ms: u32,
    /// Sensor zero errors, pascal.
    offset_pa: (i32, i32),
    seed: u64,
}

fn physics() -> impl Strategy<Value = Physics> {
    (
        0..=8_000i32,
        4_750u32..=5_250,
        3_240u32..=3_360,
        5u32..=25,
        (70u32..=130, 70u32..=130),
        60_000u32..=600_000,
        (-3_000..=3_000i32, -3_000..=3_000i32),
        any::<u64>(),
    )
        .prop_map(
            |(
                noise_pa,
                supply_mv,
                vdda_mv,
                release_ms,
                pump_strength_pct,
                leak_tau_ms,
                offset_pa,
                seed,
            )| {
                Physics {
                    noise_pa,
                    supply_mv,
                    vdda_mv,
                    release_ms,
                    pump_strength_pct,
                    leak_tau_ms,
                    offset_pa,
                    seed,
                }
            },
        )
}

/// A fault injected into the physical rig.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Injected {
    /// Positive (0) or negative (1) sensor's wire opens.
    OpenWire(usize),
    /// A sensor's output freezes at its present value.
    StuckSensor(usize),
    /// A pump stops moving air.
    DeadPump(usize),
}

/// One step of a physical scenario.
#[derive(Debug, Clone)]
enum PhysEvent {
    Frame(HostMsg),
    Wait(u32),
    Inject(Injected),
}

fn phys_event() -> impl Strategy<Value = PhysEvent> {
    prop_oneof![
        6 => host_msg().prop_map(PhysEvent::Frame),
        6 => (1u32..800).prop_map(PhysEvent::Wait),
        1 => prop_oneof![
            (0usize..2).prop_map(Injected::OpenWire),
            (0usize..2).prop_map(Injected::StuckSensor),
            (0usize..2).prop_map(Injected::DeadPump),
        ]
        .prop_map(PhysEvent::Inject),
    ]
}

/// The stated worst-case time from a sensor's wire opening to the trip.
const OPEN_WIRE_TRIP_MS: u32 = DEFAULT_TRIP_AFTER_TICKS;
/// The stated worst-case continuous pump run after its sensor stuck or the
/// pump died, before the trip: two plausibility windows (the fault may
/// start just after a window began) plus one filter length.
const NO_RISE_TRIP_MS: u32 = 2 * DEFAULT_RISE_WINDOW_MS + filter::FILTER_TICKS as u32;

fn run_physical(phys: &Physics, events: &[PhysEvent]) -> Result<Bench, TestCaseError> {
    let params = TankModelParams {
        pump_tau_ms: 4_000 * 100 / phys.pump_strength_pct.0,
        negative_pump_tau_ms: 4_000 * 100 / phys.pump_strength_pct.1,
        leak_tau_ms: phys.leak_tau_ms,
        ..TankModelParams::default()
    };
    let mut rig = Rig::with(Source::Model(TankModel::new(params)));
    rig.noise_pa = phys.noise_pa;
    rig.supply_mv = phys.supply_mv;
    rig.vdda_mv = phys.vdda_mv;
    rig.valves.release_ms = phys.release_ms;
    rig.offset_pa = phys.offset_pa;
    rig.rng = phys.seed | 1;
    let mut b = Bench::new(rig);
    let mut injected: [Option<(Injected, u32)>; 2] = [None, None];
    // How long each pump has run without pause since a no-rise fault was injected.
    let mut pump_on_since_fault_ms = [0u32; 2];
    let tick = |b: &mut Bench,
                injected: &[Option<(Injected, u32)>; 2],
                pump_on: &mut [u32; 2]|
     -> Result<(), TestCaseError> {
        b.tick();
        let (p, n) = b.rig.model_pa();
        prop_assert!(p <= POSITIVE_TANK_MAX_PA, "positive tank at {} Pa", p);
        prop_assert!(n >= NEGATIVE_TANK_MIN_PA, "negative tank at {} Pa", n);
        prop_assert!(!b.rig.both_open_ever, "a chamber physically open both ways");
        // A pump is never held off by its pressure bound for longer than the
        // stated hold without its reading moving: then it trips.
        let now = b.rig.now_ms;
        for (held, monitor) in [
            (b.ctl.held.positive_on, &b.ctl.positive_monitor),
            (b.ctl.held.negative_on, &b.ctl.negative_monitor),
        ] {
            if let (true, Some(since)) = (held, monitor.held_since_ms()) {
                prop_assert!(
                    now - since <= DEFAULT_PUMP_MAX_HOLD_MS,
                    "a pump held {} ms without a trip",
                    now - since
                );
            }
        }
        let faults = b.ctl.faults();
        for (tank, inj) in injected.iter().enumerate() {
            let Some((what, at_ms)) = inj else { continue };
            let on = if tank == 0 {
                b.rig.pumps.positive_on
            } else {
                b.rig.pumps.negative_on
            };
            pump_on[tank] = if on { pump_on[tank] + 1 } else { 0 };
            let sensor = [Fault::PositiveSensor, Fault::NegativeSensor][tank];
            match what {
                Injected::OpenWire(_) => {
                    if b.rig.now_ms - at_ms >= OPEN_WIRE_TRIP_MS {
                        prop_assert!(
                            faults.contains(sensor),
                            "open wire {} ms ago, {:?}",
                            b.rig.now_ms - at_ms,
                            faults
                        );
                    }
                }
                Injected::StuckSensor(_) | Injected::DeadPump(_) => {
                    prop_assert!(
                        pump_on[tank] <= NO_RISE_TRIP_MS,
                        "pump {} ran {} ms after {:?}",
                        tank,
                        pump_on[tank],
                        what
                    );
                }
            }
        }
        Ok(())
    };
    b.boot();
    for e in events {
        match e {
            PhysEvent::Frame(msg) => {
                b.send(*msg);
            }
            PhysEvent::Wait(ms) => {
                for i in 0..*ms {
                    if i % 100 == 99 {
                        b.send(HostMsg::Heartbeat);
                    }
                    tick(&mut b, &injected, &mut pump_on_since_fault_ms)?;
                }
            }
            PhysEvent::Inject(what) => {
                let (Injected::OpenWire(t) | Injected::StuckSensor(t) | Injected::DeadPump(t)) =
                    *what;
                if injected[t].is_some() {
                    continue;
                }
                let now = b.rig.now_ms;
                match what {
                    Injected::OpenWire(_) => {
                        let f = &mut b.rig.sensor_faults;
                        *(if t == 0 { &mut f.0 } else { &mut f.1 }) = SensorFault::OpenWire;
                    }
                    Injected::StuckSensor(_) => {
                        let (p, n) = b.rig.model_pa();
                        let pa = if t == 0 { p } else { n };
                        let counts =
                            NOMINAL_FRONT_END.sensor_counts(pa, b.rig.supply_mv, b.rig.vdda_mv);
                        let f = &mut b.rig.sensor_faults;
                        *(if t == 0 { &mut f.0 } else { &mut f.1 }) = SensorFault::Stuck(counts);
                    }
                    Injected::DeadPump(_) => {
                        let d = &mut b.rig.pump_dead;
                        *(if t == 0 { &mut d.0 } else { &mut d.1 }) = true;
                    }
                }
                injected[t] = Some((*what, now));
            }
        }
    }
    // Finally the host falls silent: safe by the deadline.
    let silent_from = b.rig.now_ms;
    let was_armed = b.ctl.state() == ArmState::Armed;
    for _ in 0..DEFAULT_HOST_SILENCE_MS {
        tick(&mut b, &injected, &mut pump_on_since_fault_ms)?;
    }
    prop_assert_eq!(b.rig.now_ms - silent_from, DEFAULT_HOST_SILENCE_MS);
    prop_assert_ne!(b.ctl.state(), ArmState::Armed);
    prop_assert_eq!(b.rig.pumps, PumpOutputs::OFF);
    if was_armed {
        prop_assert!(b.ctl.faults().contains(Fault::HostSilence) || !b.ctl.faults().is_empty());
    }
    Ok(b)
}

/// A scenario that charges both tanks first, so that the physics test
/// spends its time near the targets and limits, not at atmosphere.
fn charged_start() -> Vec<PhysEvent> {
    vec![
        PhysEvent::Frame(HostMsg::Arm),
        PhysEvent::Frame(HostMsg::SetPumps {
            positive: PumpMode::Regulate,
            negative: PumpMode::Regulate,
        }),
        PhysEvent::Frame(HostMsg::SetTankTargets(
            TankTargets::new(
                POSITIVE_TANK_MAX_PA - DEFAULT_GUARD_BAND_PA,
                NEGATIVE_TANK_MIN_PA + DEFAULT_GUARD_BAND_PA,
            )
            .unwrap(),
        )),
        PhysEvent::Wait(6_000),
    ]
}

/// `default_cases`, or the number `PROPTEST_CASES` asks for (the explicit
/// `cases` of a config would otherwise override it).
fn cases_or(default_cases: u32) -> u32 {
    std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default_cases)
}

/// The counterexample proptest found to `physical_rig_stays_inside_the_limits`:
/// the positive sensor freezes after the first charge at a value 1.9 kPa
/// below the true pressure (its zero offset), the pump restarts from the
/// frozen reading and a weak pump on a 4.75 V supply pushes the true tank
/// past +50 kPa before the plausibility window ends.
#[test]
fn stuck_sensor_reading_low_near_the_target_stays_inside_the_limits() {
    let phys = Physics {
        noise_pa: 0,
        supply_mv: 4_750,
        vdda_mv: 3_240,
        release_ms: 5,
        pump_strength_pct: (76, 70),
        leak_tau_ms: 426_132,
        offset_pa: (1_913, 0),
        seed: 0,
    };
    let mut events = charged_start();
    events.extend([
        PhysEvent::Inject(Injected::StuckSensor(0)),
        PhysEvent::Wait(505),
        PhysEvent::Frame(HostMsg::ClearFaults {
            faults: FaultFlags::NONE,
        }),
    ]);
    run_physical(&phys, &events).unwrap();
}

/// How long after its pump is first held off a frozen sensor's `*PumpNoRise`
/// is latched: the stated hold, plus the tick of the trip.
const HOLD_TRIP_MS: u32 = DEFAULT_PUMP_MAX_HOLD_MS + 1;

/// A sensor freezing at any moment of the fill (every 151 ms of the first
/// 6 s), with the fastest pump allowed for and a zero error of 0 or 3 kPa
/// (frozen readings 3 kPa below the true pressure): the pump is held off
/// before the true tank pressure passes its limit (checked at every tick by
/// [`run_physical`]), and whenever it was held (the frozen reading lies
/// below the target, so the pump still wants to run) `*PumpNoRise` is
/// latched within [`HOLD_TRIP_MS`] of the hold. Before the bound of
/// [`pumps::PumpMonitor`], 1 s plausibility windows let such a pump run
/// unconfirmed for up to 2 s and most of these cases passed the limit.
#[test]
fn a_sensor_freezing_while_its_pump_runs_is_held_off_below_the_limit_then_trips() {
    let mut held_cases = 0;
    for offset_pa in [0, 3_000] {
        let phys = Physics {
            noise_pa: 0,
            supply_mv: 5_000,
            vdda_mv: 3_300,
            release_ms: 5,
            pump_strength_pct: (130, 130),
            leak_tau_ms: 600_000,
            offset_pa: (offset_pa, -offset_pa),
            seed: 1,
        };
        for frozen_at_ms in (0..6_000u32).step_by(151) {
            for tank in 0..2 {
                let events = [
                    PhysEvent::Frame(HostMsg::Arm),
                    PhysEvent::Frame(regulate_both()),
                    PhysEvent::Frame(HostMsg::SetTankTargets(
                        TankTargets::new(
                            POSITIVE_TANK_MAX_PA - DEFAULT_GUARD_BAND_PA,
                            NEGATIVE_TANK_MIN_PA + DEFAULT_GUARD_BAND_PA,
                        )
                        .unwrap(),
                    )),
                    PhysEvent::Wait(frozen_at_ms.max(1)),
                    PhysEvent::Inject(Injected::StuckSensor(tank)),
                    PhysEvent::Wait(3_000 + HOLD_TRIP_MS),
                ];
                let b = match run_physical(&phys, &events) {
                    Ok(b) => b,
                    Err(e) => panic!(
                        "offset {offset_pa} Pa, tank {tank} frozen at {frozen_at_ms} ms: {e}"
                    ),
                };
                let (monitor, no_rise) = if tank == 0 {
                    (&b.ctl.positive_monitor, Fault::PositivePumpNoRise)
                } else {
                    (&b.ctl.negative_monitor, Fault::NegativePumpNoRise)
                };
                if monitor.held_since_ms().is_some() {
                    held_cases += 1;
                    assert!(
                        b.ctl.faults().contains(no_rise),
                        "offset {offset_pa} Pa, tank {tank} frozen at {frozen_at_ms} ms: held, {:?}",
                        b.ctl.faults()
                    );
                }
            }
        }
    }
    // Many freezes (69 of 160) come before the 1 s window can catch them.
    assert!(held_cases >= 50, "{held_cases}");
}

/// Chambers cycling between the tanks (inflate, hold, deflate) at the
/// default targets, for 30 s with noise of ±2 % FS, zero errors and the
/// weakest, nominal and strongest pumps: chambers drawing air during a
/// top-up keep the reading from rising, the pump is held off at times, but
/// the reading then falls and releases it. No fault. (All 8 chambers
/// cycled every second with 30 % weak pumps trip the 1 s no-rise window,
/// before and after the hold: a known limit of that window, not of the
/// bound.)
#[test]
fn chambers_cycling_at_the_default_targets_hold_but_never_trip() {
    for (strength_pct, chambers_cycled, period_ms, noise_pa) in [
        (70, 2, 500, 8_000),
        (70, 2, 5_000, 8_000),
        (100, 4, 300, 8_000),
        (130, 2, 500, 8_000),
        (70, 2, 500, 0),
        (100, 4, 300, 0),
        (100, 2, 150, 0),
        (130, 2, 500, 0),
    ] {
        let params = TankModelParams {
            pump_tau_ms: 4_000 * 100 / strength_pct,
            negative_pump_tau_ms: 4_000 * 100 / strength_pct,
            leak_tau_ms: 120_000,
            ..TankModelParams::default()
        };
        let mut rig = Rig::with(Source::Model(TankModel::new(params)));
        rig.noise_pa = noise_pa;
        rig.offset_pa = (2_000, -2_000);
        rig.valves.release_ms = 20;
        let mut b = Bench::new(rig);
        b.arm();
        b.ack(regulate_both());
        // Charge first (up to the run-time limit), then cycle.
        b.ticks_alive(DEFAULT_PUMP_MAX_RUN_MS);
        let mut held_ms = 0u32;
        for step in 0..30_000 / period_ms {
            let state =
                [ValveState::Inflate, ValveState::Hold, ValveState::Deflate][step as usize % 3];
            let mut chambers = SAFE_CHAMBERS;
            for c in chambers.iter_mut().take(chambers_cycled) {
                *c = state;
            }
            b.send(HostMsg::SetChambers { chambers });
            for i in 0..period_ms {
                if i % 100 == 0 {
                    b.send(HostMsg::Heartbeat);
                }
                b.tick();
                held_ms += u32::from(b.ctl.held.positive_on || b.ctl.held.negative_on);
            }
        }
        assert_eq!(
            b.ctl.state(),
            ArmState::Armed,
            "{strength_pct} % pumps, {chambers_cycled} chambers every {period_ms} ms, noise {noise_pa}: {:?} at {} ms, held {held_ms} ms, hold since {:?}",
            b.ctl.faults(), b.rig.now_ms, b.ctl.positive_monitor.held_since_ms()
        );
        let (p, n) = b.rig.model_pa();
        assert!(p <= POSITIVE_TANK_MAX_PA && n >= NEGATIVE_TANK_MIN_PA);
        std::println!(
            "{strength_pct} % pumps, {chambers_cycled} chambers every {period_ms} ms, noise {noise_pa}: held {held_ms} ms, tanks {p} / {n} Pa"
        );
    }
}

/// The bound must not trip a healthy rig: the weakest pumps allowed for
/// (30 % weak, the fastest leak), the largest targets, noise of ±2 % FS and
/// zero errors of 3 kPa, topping up for 30 s.
#[test]
fn weakest_pumps_top_up_at_the_largest_targets_without_a_false_trip() {
    let params = TankModelParams {
        pump_tau_ms: 4_000 * 100 / 70,
        negative_pump_tau_ms: 4_000 * 100 / 70,
        leak_tau_ms: 60_000,
        ..TankModelParams::default()
    };
    let mut rig = Rig::with(Source::Model(TankModel::new(params)));
    rig.noise_pa = 8_000;
    rig.offset_pa = (3_000, -3_000);
    let mut b = Bench::new(rig);
    b.arm();
    b.ack(HostMsg::SetTankTargets(
        TankTargets::new(
            POSITIVE_TANK_MAX_PA - DEFAULT_GUARD_BAND_PA,
            NEGATIVE_TANK_MIN_PA + DEFAULT_GUARD_BAND_PA,
        )
        .unwrap(),
    ));
    b.ack(regulate_both());
    b.ticks_alive(30_000);
    assert_eq!(b.ctl.state(), ArmState::Armed, "{:?}", b.ctl.faults());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases_or(256), ..ProptestConfig::default() })]

    /// Interlock, pump limits and latching hold over arbitrary scenarios.
    #[test]
    fn safety_invariants_hold_for_any_commands_and_pressures(
        events in proptest::collection::vec(event(), 1..60)
    ) {
        run_scenario(&events, Config::default())?;
    }

    /// Whatever happened before, a silent host finds the controller out of
    /// the armed state, pumps off and valves safe, by the deadline.
    #[test]
    fn host_silence_always_ends_in_the_safe_state_by_the_deadline(
        events in proptest::collection::vec(event(), 0..40),
        arm_last in any::<bool>(),
        host_silence_ms in 1u32..2_000,
    ) {
        let config = Config { host_silence_ms, ..Config::default() };
        let mut b = run_scenario(&events, config)?;
        if arm_last {
            b.send(HostMsg::Arm);
        }
        let silent_from = b.rig.now_ms;
        let deadline = b.ctl.config().host_silence_ms;
        let mut obs = Observer { last_state: b.ctl.state(), clear_seen: false };
        for _ in 0..deadline {
            b.tick();
            obs.check_tick(&b)?;
        }
        prop_assert_eq!(b.rig.now_ms.wrapping_sub(silent_from), deadline);
        prop_assert_ne!(b.ctl.state(), ArmState::Armed);
        prop_assert_eq!(b.rig.pumps, PumpOutputs::OFF);
        prop_assert!(b.rig.chambers.iter().all(|c| *c != ValveState::Inflate));
    }

    /// Whatever the host commands and however late (5..25 ms) the valves
    /// release, no chamber's inlet and outlet are ever physically open at
    /// the same time.
    #[test]
    fn inlet_and_outlet_never_physically_open_together(
        commands in proptest::collection::vec(
            (proptest::array::uniform8(valve_state()), 0u32..60), 1..40),
        release_ms in 5u32..=25,
    ) {
        prop_assert!(!valves_ever_open_both_ways(&commands, release_ms, DEFAULT_VALVE_DEAD_TIME_MS));
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases_or(48), ..ProptestConfig::default() })]

    /// Random commands on a random physical rig (noise up to ±2 % of full
    /// scale, supply 4.75..5.25 V, valve release 5..25 ms, pump strength
    /// ±30 %, leaks, sensor zero errors) and injected faults: the *true*
    /// tank pressures never pass +50 / -57 kPa, no chamber is physically
    /// open both ways, and each injected fault trips within its stated time.
    #[test]
    fn physical_rig_stays_inside_the_limits(
        phys in physics(),
        events in proptest::collection::vec(phys_event(), 1..30),
        charge_first in any::<bool>(),
    ) {
        let mut all = if charge_first { charged_start() } else { Vec::new() };
        all.extend(events);
        run_physical(&phys, &all)?;
    }
}

// -------------------------------------------------------------- calibration

fn sensor(offset_pa: i32, gain_ppm: u32) -> SensorCalibration {
    SensorCalibration {
        offset_pa,
        gain_ppm,
    }
}

fn a_calibration() -> Calibration {
    Calibration {
        positive: sensor(1_500, 1_050_000),
        negative: sensor(-2_000, 960_000),
    }
}

fn hello(b: &mut Bench) -> dexitac_protocol::HelloReply {
    let replies = b.send(HostMsg::Hello);
    let [McuMsg::HelloReply(h)] = replies[..] else {
        panic!("{replies:?}")
    };
    h
}

#[test]
fn calibration_is_accepted_disarmed_applied_stored_and_reported() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.boot();
    b.ack(HostMsg::SetCalibration(a_calibration()));
    let report = hello(&mut b).calibration;
    assert_eq!(report.calibration, a_calibration());
    assert_eq!(report.source, CalibrationSource::Host);
    assert_eq!(report.record, CalibrationRecord::WritePending);
    // The board stores it after the frame; an unchanged one is not written again.
    let mut page = RamPage::default();
    assert_eq!(
        b.ctl.store_calibration(&mut page),
        Some(CalibrationRecord::Valid {
            version: RECORD_VERSION
        })
    );
    assert_eq!(b.ctl.store_calibration(&mut page), None, "nothing pending");
    b.ack(HostMsg::SetCalibration(a_calibration()));
    b.ctl.store_calibration(&mut page);
    assert_eq!(page.writes, 1);
    let report = hello(&mut b).calibration;
    assert_eq!(
        report.record,
        CalibrationRecord::Valid {
            version: RECORD_VERSION
        }
    );
    // After a reset the board reads the page: the same calibration, from flash.
    let mut after = Bench::new(Rig::fixed(0, 0));
    after.ctl =
        Controller::new(Config::default(), ResetCause::Pin).with_calibration_record(&page.bytes);
    let report = hello(&mut after).calibration;
    assert_eq!(report.calibration, a_calibration());
    assert_eq!(report.source, CalibrationSource::Flash);
}

#[test]
fn calibration_is_refused_while_armed_or_tripped_and_when_implausible() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    b.nack(
        HostMsg::SetCalibration(a_calibration()),
        NackReason::Refused,
    );
    b.ack(HostMsg::Disarm);
    b.ctl.report_fault(Fault::ClockFallback);
    b.tick();
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    b.nack(
        HostMsg::SetCalibration(a_calibration()),
        NackReason::Tripped,
    );
    b.ack(clear(&[Fault::ClockFallback]));
    for implausible in [
        Calibration {
            positive: sensor(CALIBRATION_OFFSET_MAX_PA + 1, GAIN_UNITY_PPM),
            ..a_calibration()
        },
        Calibration {
            negative: sensor(0, CALIBRATION_GAIN_MIN_PPM - 1),
            ..a_calibration()
        },
        Calibration {
            negative: sensor(0, CALIBRATION_GAIN_MAX_PPM + 1),
            ..a_calibration()
        },
        Calibration {
            positive: sensor(i32::MIN, 0),
            negative: sensor(i32::MAX, u32::MAX),
        },
    ] {
        b.nack(
            HostMsg::SetCalibration(implausible),
            NackReason::Implausible,
        );
    }
    // Nothing was applied, nothing waits for the store.
    let report = hello(&mut b).calibration;
    assert_eq!(report.calibration, Calibration::IDENTITY);
    assert_eq!(report.source, CalibrationSource::Default);
    assert!(!b.ctl.calibration_write_pending());
    // The limits themselves are accepted.
    b.ack(HostMsg::SetCalibration(Calibration {
        positive: sensor(CALIBRATION_OFFSET_MAX_PA, CALIBRATION_GAIN_MAX_PPM),
        negative: sensor(-CALIBRATION_OFFSET_MAX_PA, CALIBRATION_GAIN_MIN_PPM),
    }));
}

#[test]
fn arm_waits_until_a_new_calibration_is_stored() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.boot();
    // Calibration and Arm in one chunk of bytes: the store has not run.
    let mut bytes = EncodedFrame::new(1, &HostMsg::SetCalibration(a_calibration()))
        .unwrap()
        .to_vec();
    bytes.extend_from_slice(&EncodedFrame::new(2, &HostMsg::Arm).unwrap());
    b.ctl.receive(&bytes, &b.rig, &mut b.tx);
    assert_eq!(
        b.drain(),
        [
            McuMsg::Ack { seq: 1 },
            McuMsg::Nack {
                seq: 2,
                reason: NackReason::Refused
            }
        ]
    );
    assert_eq!(b.ctl.state(), ArmState::Disarmed);
    // Whatever the store says, the calibration applies; then arming works.
    assert_eq!(
        b.ctl.store_calibration(&mut NoStore),
        Some(CalibrationRecord::NotPersisted)
    );
    b.ack(HostMsg::Arm);
    assert_eq!(
        hello(&mut b).calibration.calibration,
        a_calibration(),
        "applied even if not persisted"
    );
}

#[test]
fn a_failed_write_is_reported_and_the_calibration_still_applies() {
    struct Broken;
    impl crate::calibration::CalibrationStore for Broken {
        fn write_record(
            &mut self,
            _: &[u8; RECORD_LEN],
        ) -> Result<(), crate::calibration::StoreError> {
            Err(crate::calibration::StoreError::Failed)
        }
    }
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.boot();
    b.ack(HostMsg::SetCalibration(a_calibration()));
    assert_eq!(
        b.ctl.store_calibration(&mut Broken),
        Some(CalibrationRecord::WriteFailed)
    );
    let report = hello(&mut b).calibration;
    assert_eq!(report.record, CalibrationRecord::WriteFailed);
    assert_eq!(report.calibration, a_calibration());
}

#[test]
fn a_bad_record_at_boot_is_ignored_and_reported() {
    let good = crate::calibration::encode(&a_calibration());
    let mut bad_crc = good;
    bad_crc[10] ^= 0x01;
    let mut other_version = good;
    other_version[4] = 9;
    let crc = crc::Crc::<u32>::new(&crc::CRC_32_ISCSI).checksum(&other_version[..24]);
    other_version[24..].copy_from_slice(&crc.to_le_bytes());
    for (page, record) in [
        (&bad_crc[..], CalibrationRecord::BadCrc),
        (
            &other_version[..],
            CalibrationRecord::UnknownVersion { version: 9 },
        ),
        (&[0xFF; 1024][..], CalibrationRecord::Empty),
        (&[0x00; 1024][..], CalibrationRecord::NotARecord),
    ] {
        let mut b = Bench::new(Rig::fixed(0, 0));
        b.rig.offset_pa = (1_500, -2_000);
        b.ctl =
            Controller::new(Config::default(), ResetCause::PowerOn).with_calibration_record(page);
        b.boot();
        let report = hello(&mut b).calibration;
        assert_eq!(report.record, record);
        assert_eq!(report.source, CalibrationSource::Default);
        assert_eq!(report.calibration, Calibration::IDENTITY);
        // Defaults: the boot zero alone.
        assert_eq!(report.positive_zero.source, ZeroSource::Boot);
        assert!((report.positive_zero.zero_pa - 1_500).abs() < 300);
    }
}

/// The true pressure at which `tank` trips over its limit when it ramps
/// toward it by `step_pa` a millisecond from `start_pa`, on a sensor with
/// `gain_ppm` gain error, with `calibration` set before the ramp (and the
/// tanks at atmosphere for the boot zero).
fn true_trip_pa(
    positive: bool,
    sensor_gain_ppm: u32,
    calibration: Option<Calibration>,
    start_pa: i32,
    step_pa: i32,
) -> i32 {
    let mut b = Bench::new(Rig::fixed(0, 0));
    if positive {
        b.rig.gain_ppm.0 = sensor_gain_ppm;
    } else {
        b.rig.gain_ppm.1 = sensor_gain_ppm;
    }
    b.boot();
    if let Some(c) = calibration {
        b.ack(HostMsg::SetCalibration(c));
    }
    let mut pa = start_pa;
    for _ in 0..20_000 {
        b.rig.source = if positive {
            Source::Fixed(Ok(pa), Ok(0))
        } else {
            Source::Fixed(Ok(0), Ok(pa))
        };
        if !faults_of(&b.tick()).is_empty() {
            let want = if positive {
                Fault::PositiveOverLimit
            } else {
                Fault::NegativeOverLimit
            };
            assert_eq!(b.ctl.faults(), FaultFlags::NONE.with(want));
            return pa;
        }
        pa += step_pa;
    }
    panic!("no trip up to {pa} Pa");
}

#[test]
fn a_calibrated_gain_moves_the_trip_to_the_true_limit() {
    // A positive sensor that reads 1/1.05 of the true pressure: without
    // calibration the tank trips only at 52.5 kPa (true); with gain 1.05 at
    // the limit, 50 kPa. Tolerances: the ramp's filter lag (5 Pa/ms, about
    // 10 ms) and the ADC's resolution (one count is about 120 Pa, in the
    // reading and in the boot zero).
    let low = 952_381;
    let gain = Calibration {
        positive: sensor(0, 1_050_000),
        negative: SensorCalibration::IDENTITY,
    };
    let uncalibrated = true_trip_pa(true, low, None, 45_000, 5);
    let calibrated = true_trip_pa(true, low, Some(gain), 45_000, 5);
    assert!(
        (52_400..=52_900).contains(&uncalibrated),
        "uncalibrated: {uncalibrated}"
    );
    assert!(
        (POSITIVE_TANK_MAX_PA - 250..=POSITIVE_TANK_MAX_PA + 400).contains(&calibrated),
        "calibrated: {calibrated}"
    );
    // The same on the negative side: a sensor reading 4 % high trips early
    // (-54.8 kPa) until gain 0.96 puts the trip back at -57 kPa.
    let high = 1_040_000;
    let gain = Calibration {
        positive: SensorCalibration::IDENTITY,
        negative: sensor(0, 961_538),
    };
    let uncalibrated = true_trip_pa(false, high, None, -50_000, -5);
    let calibrated = true_trip_pa(false, high, Some(gain), -50_000, -5);
    assert!(
        (-55_100..=-54_700).contains(&uncalibrated),
        "uncalibrated: {uncalibrated}"
    );
    assert!(
        (NEGATIVE_TANK_MIN_PA - 400..=NEGATIVE_TANK_MIN_PA + 250).contains(&calibrated),
        "calibrated: {calibrated}"
    );
}

#[test]
fn the_stored_offset_stands_in_when_a_tank_is_under_pressure_at_boot() {
    // A sensor with a +5 kPa zero error on a tank still at 20 kPa after a
    // reset: the boot zero cannot be atmosphere. Without a calibration the
    // reading is 5 kPa high; with the stored offset it is right.
    let stored = Calibration {
        positive: sensor(5_000, GAIN_UNITY_PPM),
        negative: SensorCalibration::IDENTITY,
    };
    let page = crate::calibration::encode(&stored);
    for (record, want_pa, want_source) in [
        (None, 25_000, ZeroSource::Offset),
        (Some(&page[..]), 20_000, ZeroSource::Offset),
    ] {
        let mut b = Bench::new(Rig::fixed(20_000, 0));
        b.rig.offset_pa = (5_000, 0);
        if let Some(page) = record {
            b.ctl = Controller::new(Config::default(), ResetCause::IndependentWatchdog)
                .with_calibration_record(page);
        }
        b.boot();
        let reading = b.ctl.readings().0.unwrap();
        assert!((reading - want_pa).abs() < 300, "{reading} vs {want_pa}");
        assert_eq!(hello(&mut b).calibration.positive_zero.source, want_source);
    }
}

#[test]
fn the_stored_offset_centres_the_boot_zero_window() {
    // A sensor with a 7 kPa zero error at atmosphere: outside the ±4 kPa
    // window around 0, so uncalibrated it reads 7 kPa high; a stored
    // offset of 6 kPa brings the boot zero (7 kPa, measured) into the
    // window, and the boot zero, not the offset, applies.
    let stored = Calibration {
        positive: sensor(6_000, GAIN_UNITY_PPM),
        negative: SensorCalibration::IDENTITY,
    };
    let page = crate::calibration::encode(&stored);
    for (record, want_pa, want_source) in [
        (None, 7_000, ZeroSource::Offset),
        (Some(&page[..]), 0, ZeroSource::Boot),
    ] {
        let mut b = Bench::new(Rig::fixed(0, 0));
        b.rig.offset_pa = (7_000, 0);
        if let Some(page) = record {
            b.ctl = Controller::new(Config::default(), ResetCause::PowerOn)
                .with_calibration_record(page);
        }
        b.boot();
        let reading = b.ctl.readings().0.unwrap();
        assert!((reading - want_pa).abs() < 300, "{reading} vs {want_pa}");
        let zero = hello(&mut b).calibration.positive_zero;
        assert_eq!(zero.source, want_source);
    }
}

#[test]
fn a_calibration_set_while_running_is_judged_against_the_boot_reading() {
    // Booted at atmosphere with a 7 kPa sensor error: the boot zero is
    // outside the window, so 0 Pa applies and the reading is 7 kPa high.
    // Setting the offset to 6 kPa brings the measured 7 kPa into the
    // window at once.
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.rig.offset_pa = (7_000, 0);
    b.boot();
    assert!((b.ctl.readings().0.unwrap() - 7_000).abs() < 300);
    b.ack(HostMsg::SetCalibration(Calibration {
        positive: sensor(6_000, GAIN_UNITY_PPM),
        negative: SensorCalibration::IDENTITY,
    }));
    assert!(b.ctl.readings().0.unwrap().abs() < 300);
    b.ticks(5);
    assert!(b.ctl.readings().0.unwrap().abs() < 300);
    assert_eq!(
        hello(&mut b).calibration.positive_zero.source,
        ZeroSource::Boot
    );
}

proptest! {
    #![proptest_config(ProptestConfig { cases: cases_or(24), ..ProptestConfig::default() })]

    /// For any plausible gain error of the positive sensor, the matching
    /// calibration puts the trip at the true limit (within the ramp's lag
    /// and two ADC counts), whatever offset the calibration carries within
    /// the boot zero's window (the boot zero applies).
    #[test]
    fn the_matching_gain_trips_at_the_true_limit(
        gain_ppm in CALIBRATION_GAIN_MIN_PPM..=CALIBRATION_GAIN_MAX_PPM,
        offset_pa in -3_000i32..=3_000,
    ) {
        let sensor_gain = u32::try_from(
            u64::from(GAIN_UNITY_PPM) * u64::from(GAIN_UNITY_PPM) / u64::from(gain_ppm),
        )
        .unwrap();
        let calibration = Calibration {
            positive: sensor(offset_pa, gain_ppm),
            negative: SensorCalibration::IDENTITY,
        };
        let trip = true_trip_pa(true, sensor_gain, Some(calibration), 47_000, 5);
        prop_assert!(
            (POSITIVE_TANK_MAX_PA - 250..=POSITIVE_TANK_MAX_PA + 400).contains(&trip),
            "gain {} ppm: trip at {} Pa", gain_ppm, trip
        );
    }
}
