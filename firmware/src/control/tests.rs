//! Tests of the safety loop: behaviour examples, then property tests over
//! arbitrary command sequences and pressure traces.

use std::vec;
use std::vec::Vec;

use dexitac_protocol::{
    ArmState, Chambers, Decoder, EncodedFrame, Fault, Frame, FrameError, HostMsg, McuMsg, Message,
    NackReason, PumpMode, ResetCause, TankTargets, ValveState, NEGATIVE_TANK_MIN_PA,
    POSITIVE_TANK_MAX_PA,
};
use proptest::prelude::*;

use super::hw::{Clock, PressureSource, Pumps, SensorError, TankReadings, Valves};
use super::valves::{ValveLevels, SAFE_CHAMBERS, VENT_CHAMBERS};
use super::*;
use crate::queue::ByteQueue;
use crate::tank_model::{TankModel, TankModelParams};

/// Where the fake rig's pressures come from.
enum Source {
    /// Fixed readings, set by the test.
    Fixed(TankReadings),
    /// The simulated tanks, driven by the pump and valve outputs.
    Model(TankModel),
}

/// A fake board: records every output level it is asked to drive.
struct Rig {
    now_ms: u32,
    source: Source,
    pumps: PumpOutputs,
    chambers: Chambers,
    levels: ValveLevels,
    /// Every valve level written, break-before-make steps included.
    shorted_ever: bool,
}

impl Rig {
    fn fixed(positive_pa: i32, negative_pa: i32) -> Rig {
        Rig::with(Source::Fixed(TankReadings {
            positive_pa: Ok(positive_pa),
            negative_pa: Ok(negative_pa),
        }))
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
            levels: ValveLevels::CLOSED,
            shorted_ever: false,
        }
    }

    fn set_readings(&mut self, readings: TankReadings) {
        self.source = Source::Fixed(readings);
    }
}

impl Clock for Rig {
    fn now_ms(&self) -> u32 {
        self.now_ms
    }
}

impl PressureSource for Rig {
    fn read_tanks(&mut self) -> TankReadings {
        self.readings()
    }
}

impl Rig {
    /// What the sensors read now.
    fn readings(&self) -> TankReadings {
        match &self.source {
            Source::Fixed(r) => *r,
            Source::Model(m) => {
                let (positive_pa, negative_pa) = m.tanks_pa();
                TankReadings {
                    positive_pa: Ok(positive_pa),
                    negative_pa: Ok(negative_pa),
                }
            }
        }
    }
}

impl Valves for Rig {
    fn set_chambers(&mut self, chambers: &Chambers) {
        let to = ValveLevels::from_chambers(chambers);
        for step in self.levels.transition(to) {
            self.shorted_ever |= step.shorts_tanks();
        }
        self.levels = to;
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
    tx: ByteQueue<4096>,
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
            tx: ByteQueue::new(),
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

    /// Advances time by 1 ms and runs one tick; returns the messages sent.
    fn tick(&mut self) -> Vec<McuMsg> {
        self.rig.now_ms = self.rig.now_ms.wrapping_add(1);
        if let Source::Model(m) = &mut self.rig.source {
            m.advance(1, self.rig.pumps, &self.rig.chambers);
        }
        self.ctl.tick(&mut self.rig, &mut self.tx);
        self.drain()
    }

    fn ticks(&mut self, n: u32) -> Vec<McuMsg> {
        (0..n).flat_map(|_| self.tick()).collect()
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

    fn arm(&mut self) {
        self.tick();
        assert_eq!(self.send(HostMsg::Arm), [McuMsg::Ack { seq: self.seq }]);
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

#[test]
fn default_targets_are_inside_the_limits() {
    let t = Config::default().default_targets;
    assert_eq!(
        (t.positive_pa(), t.negative_pa()),
        (DEFAULT_TARGETS_PA.0, DEFAULT_TARGETS_PA.1)
    );
}

#[test]
fn hello_reports_versions_limits_and_reset_cause() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    let replies = b.send(HostMsg::Hello);
    let [McuMsg::HelloReply(h)] = replies[..] else {
        panic!("{replies:?}")
    };
    assert_eq!(h.firmware_version, crate::FIRMWARE_VERSION);
    assert_eq!(h.positive_tank_max_pa, POSITIVE_TANK_MAX_PA);
    assert_eq!(h.negative_tank_min_pa, NEGATIVE_TANK_MIN_PA);
    assert_eq!(h.chamber_count, 8);
    assert_eq!(h.reset_cause, ResetCause::PowerOn);
}

#[test]
fn set_chambers_while_disarmed_is_refused_and_changes_nothing() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    let replies = b.send(HostMsg::SetChambers {
        chambers: one_inflating(),
    });
    assert_eq!(
        replies,
        [McuMsg::Nack {
            seq: b.seq,
            reason: NackReason::NotArmed
        }]
    );
    b.tick();
    assert_eq!(b.rig.chambers, SAFE_CHAMBERS);
}

#[test]
fn armed_set_chambers_drives_the_valves_at_the_next_tick() {
    let mut b = Bench::new(Rig::fixed(30_000, -30_000));
    b.arm();
    b.send(HostMsg::SetChambers {
        chambers: one_inflating(),
    });
    b.tick();
    assert_eq!(b.rig.chambers, one_inflating());
    assert_eq!(b.rig.levels.inlets, 1);
}

#[test]
fn host_silence_trips_pumps_and_seals_valves() {
    let mut b = Bench::new(Rig::model());
    b.arm();
    b.send(regulate_both());
    b.send(HostMsg::SetChambers {
        chambers: one_inflating(),
    });
    let armed_at = b.rig.now_ms;
    let sent = b.ticks(DEFAULT_HOST_SILENCE_MS - 1);
    assert_eq!(b.ctl.state(), ArmState::Armed);
    assert!(b.rig.pumps.positive_on);
    assert!(!sent.iter().any(|m| matches!(m, McuMsg::Fault(_))));
    let sent = b.tick();
    assert_eq!(b.rig.now_ms - armed_at, DEFAULT_HOST_SILENCE_MS);
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    assert_eq!(b.rig.pumps, PumpOutputs::OFF);
    assert_eq!(b.rig.chambers, SAFE_CHAMBERS);
    assert!(matches!(
        sent[..],
        [McuMsg::Fault(FaultEvent {
            fault: Fault::HostSilence,
            ..
        })]
    ));
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
fn trip_latches_until_disarm_then_arm_works_again() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    b.ticks(DEFAULT_HOST_SILENCE_MS);
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    for msg in [HostMsg::Arm, regulate_both()] {
        let r = b.send(msg);
        assert_eq!(
            r,
            [McuMsg::Nack {
                seq: b.seq,
                reason: NackReason::Tripped
            }]
        );
    }
    b.tick();
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    assert!(b.ctl.faults().contains(Fault::HostSilence));
    b.send(HostMsg::Disarm);
    assert_eq!(b.ctl.state(), ArmState::Disarmed);
    assert!(b.ctl.faults().is_empty());
    b.arm();
    assert_eq!(b.ctl.state(), ArmState::Armed);
}

#[test]
fn over_limit_trips_and_arm_is_refused_while_it_persists() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    b.rig.set_readings(TankReadings {
        positive_pa: Ok(POSITIVE_TANK_MAX_PA),
        negative_pa: Ok(0),
    });
    let sent = b.tick();
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    assert!(matches!(
        sent[..],
        [McuMsg::Fault(FaultEvent {
            fault: Fault::PositiveOverLimit,
            positive_tank_pa: POSITIVE_TANK_MAX_PA,
            ..
        })]
    ));
    b.send(HostMsg::Disarm);
    b.tick();
    let r = b.send(HostMsg::Arm);
    assert_eq!(
        r,
        [McuMsg::Nack {
            seq: b.seq,
            reason: NackReason::Refused
        }]
    );
}

#[test]
fn sensor_error_trips_with_sensor_fault() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    b.rig.set_readings(TankReadings {
        positive_pa: Ok(0),
        negative_pa: Err(SensorError::OutOfRange),
    });
    b.tick();
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    assert!(b.ctl.faults().contains(Fault::NegativeSensor));
    assert_eq!(
        b.ctl.telemetry(0).negative_tank_pa,
        dexitac_protocol::NO_READING_PA
    );
}

#[test]
fn stuck_sensor_while_pumping_trips() {
    // Fixed readings far below the target: the pump runs, nothing moves.
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    b.send(regulate_both());
    for _ in 0..(DEFAULT_STUCK_WINDOW_MS / 200) {
        b.ticks(200);
        b.send(HostMsg::Heartbeat);
    }
    b.tick();
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    assert!(b.ctl.faults().contains(Fault::PositiveSensor));
    assert!(b.ctl.faults().contains(Fault::NegativeSensor));
    assert_eq!(b.rig.pumps, PumpOutputs::OFF);
}

#[test]
fn pump_run_time_limit_trips() {
    // A weak pump (or a leaky tank): the pressure rises steadily (about
    // 400 Pa/s, enough for the stuck check) but never reaches the target.
    let params = TankModelParams {
        pump_tau_ms: 200_000,
        ..TankModelParams::default()
    };
    let mut b = Bench::new(Rig::with(Source::Model(TankModel::new(params))));
    b.arm();
    b.send(HostMsg::SetPumps {
        positive: PumpMode::Regulate,
        negative: PumpMode::Off,
    });
    let mut tripped_at = None;
    for _ in 0..(DEFAULT_PUMP_MAX_RUN_MS / 100 + 10) {
        b.ticks(100);
        if b.ctl.state() == ArmState::Tripped {
            tripped_at = Some(b.rig.now_ms);
            break;
        }
        b.send(HostMsg::Heartbeat);
    }
    assert!(b.ctl.faults().contains(Fault::PositivePumpRunTime));
    assert!(!b.ctl.faults().contains(Fault::PositiveSensor));
    let t = tripped_at.unwrap();
    assert!(
        t > DEFAULT_PUMP_MAX_RUN_MS && t < DEFAULT_PUMP_MAX_RUN_MS + 200,
        "{t}"
    );
}

#[test]
fn pumps_regulate_the_model_tanks_to_their_targets() {
    let mut b = Bench::new(Rig::model());
    b.arm();
    b.send(HostMsg::SetTankTargets(
        TankTargets::new(30_000, -30_000).unwrap(),
    ));
    b.send(regulate_both());
    for _ in 0..40 {
        b.ticks(250);
        b.send(HostMsg::Heartbeat);
    }
    assert_eq!(b.ctl.state(), ArmState::Armed, "{:?}", b.ctl.faults());
    let (pos, neg) = match &b.rig.source {
        Source::Model(m) => m.tanks_pa(),
        Source::Fixed(_) => unreachable!(),
    };
    assert!((27_000..=31_000).contains(&pos), "{pos}");
    assert!((-31_000..=-27_000).contains(&neg), "{neg}");
}

#[test]
fn vent_all_opens_outlets_and_stops_pumps_even_when_tripped() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.arm();
    b.ticks(DEFAULT_HOST_SILENCE_MS);
    assert_eq!(b.ctl.state(), ArmState::Tripped);
    assert_eq!(b.send(HostMsg::VentAll), [McuMsg::Ack { seq: b.seq }]);
    b.tick();
    assert_eq!(b.rig.chambers, VENT_CHAMBERS);
    assert_eq!(b.rig.pumps, PumpOutputs::OFF);
    assert_eq!(b.ctl.state(), ArmState::Tripped);
}

#[test]
fn telemetry_arrives_at_the_requested_interval() {
    let mut b = Bench::new(Rig::fixed(1_000, -2_000));
    b.send(HostMsg::SetTelemetryInterval { interval_ms: 10 });
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
    assert_eq!((t.positive_tank_pa, t.negative_tank_pa), (1_000, -2_000));
    b.send(HostMsg::SetTelemetryInterval { interval_ms: 0 });
    assert!(b.ticks(100).is_empty());
}

#[test]
fn telemetry_keeps_its_cadence_after_a_late_tick() {
    let mut b = Bench::new(Rig::fixed(0, 0));
    b.send(HostMsg::SetTelemetryInterval { interval_ms: 10 });
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
    let mut raw = std::vec![1u8, 10, 0, 2, 7, 0, 0, 0, 0, 0, 0, 0];
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
    let mut raw = std::vec![1u8, 10, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0];
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
        1 => (0u16..50).prop_map(|interval_ms| HostMsg::SetTelemetryInterval { interval_ms }),
        3 => Just(HostMsg::Heartbeat),
    ]
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
    /// The sensors follow the tank model again.
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
    /// A disarm frame was processed since the previous tick.
    disarm_seen: bool,
}

impl Observer {
    fn check_tick(&mut self, b: &Bench) -> Result<(), TestCaseError> {
        let readings = b.rig.readings();
        let state = b.ctl.state();
        // Interlock: no write ever opened an inlet and its outlet together.
        prop_assert!(!b.rig.shorted_ever, "inlet and outlet open together");
        // Pumps run only armed, with a valid reading strictly inside the limit.
        if b.rig.pumps.positive_on {
            prop_assert_eq!(state, ArmState::Armed);
            let pa = readings.positive_pa.unwrap();
            prop_assert!(pa < POSITIVE_TANK_MAX_PA, "positive pump on at {} Pa", pa);
        }
        if b.rig.pumps.negative_on {
            prop_assert_eq!(state, ArmState::Armed);
            let pa = readings.negative_pa.unwrap();
            prop_assert!(pa > NEGATIVE_TANK_MIN_PA, "negative pump on at {} Pa", pa);
        }
        // Latching: once tripped, only a disarm leaves the tripped state.
        if self.last_state == ArmState::Tripped && !self.disarm_seen {
            prop_assert_eq!(state, ArmState::Tripped);
        }
        // Not armed: pumps off, valves sealed or venting.
        if state != ArmState::Armed {
            prop_assert_eq!(b.rig.pumps, PumpOutputs::OFF);
            prop_assert!(b.rig.chambers == SAFE_CHAMBERS || b.rig.chambers == VENT_CHAMBERS);
        }
        self.disarm_seen = false;
        self.last_state = state;
        Ok(())
    }
}

fn run_scenario(events: &[Event], config: Config) -> Result<Bench, TestCaseError> {
    let mut b = Bench::with_config(Rig::model(), config);
    let mut obs = Observer {
        last_state: ArmState::Disarmed,
        disarm_seen: false,
    };
    for e in events {
        match e {
            Event::Frame(msg) => {
                b.send(*msg);
                if *msg == HostMsg::Disarm {
                    obs.disarm_seen = true;
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
            Event::Readings(p, n) => b.rig.set_readings(TankReadings {
                positive_pa: *p,
                negative_pa: *n,
            }),
            Event::Model => {
                let (p, n) = match b.rig.readings() {
                    TankReadings {
                        positive_pa: Ok(p),
                        negative_pa: Ok(n),
                    } => (p, n),
                    _ => (0, 0),
                };
                let mut m = TankModel::new(TankModelParams::default());
                // Start the model near the last fixed readings' range.
                let on = PumpOutputs {
                    positive_on: p > 0,
                    negative_on: n < 0,
                };
                m.advance(500, on, &SAFE_CHAMBERS);
                b.rig.source = Source::Model(m);
            }
        }
    }
    Ok(b)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

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
        let mut obs = Observer { last_state: b.ctl.state(), disarm_seen: false };
        for _ in 0..deadline {
            b.tick();
            obs.check_tick(&b)?;
        }
        prop_assert_eq!(b.rig.now_ms.wrapping_sub(silent_from), deadline);
        prop_assert_ne!(b.ctl.state(), ArmState::Armed);
        prop_assert_eq!(b.rig.pumps, PumpOutputs::OFF);
        prop_assert!(b.rig.chambers == SAFE_CHAMBERS || b.rig.chambers == VENT_CHAMBERS);
    }

    /// Every valve level derived from any two chamber states, including the
    /// break-before-make step between them, keeps inlets and outlets apart.
    #[test]
    fn inlet_and_outlet_never_open_together(
        from in proptest::array::uniform8(valve_state()),
        to in proptest::array::uniform8(valve_state()),
    ) {
        let a = ValveLevels::from_chambers(&from);
        let z = ValveLevels::from_chambers(&to);
        for step in a.transition(z) {
            prop_assert!(!step.shorts_tanks());
        }
        // Break-before-make: the first step opens nothing new.
        let [first, _] = a.transition(z);
        prop_assert_eq!(first.inlets & !a.inlets, 0);
        prop_assert_eq!(first.outlets & !a.outlets, 0);
    }
}
