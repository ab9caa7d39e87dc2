//! Proptest strategies for every wire type, shared by the protocol tests.
#![allow(dead_code)] // each test binary uses a different subset

use dexitac_protocol::*;
use proptest::prelude::*;

pub fn valve_state() -> impl Strategy<Value = ValveState> {
    prop_oneof![
        Just(ValveState::Hold),
        Just(ValveState::Inflate),
        Just(ValveState::Deflate)
    ]
}

pub fn chambers() -> impl Strategy<Value = Chambers> {
    proptest::array::uniform8(valve_state())
}

pub fn pump_mode() -> impl Strategy<Value = PumpMode> {
    prop_oneof![Just(PumpMode::Off), Just(PumpMode::Regulate)]
}

pub fn tank_targets() -> impl Strategy<Value = TankTargets> {
    (0..=POSITIVE_TANK_MAX_PA, NEGATIVE_TANK_MIN_PA..=0)
        .prop_filter_map("inside limits", |(p, n)| TankTargets::new(p, n).ok())
}

pub fn host_msg() -> impl Strategy<Value = HostMsg> {
    prop_oneof![
        Just(HostMsg::Hello),
        any::<u32>().prop_map(|nonce| HostMsg::Ping { nonce }),
        chambers().prop_map(|chambers| HostMsg::SetChambers { chambers }),
        Just(HostMsg::SealAll),
        Just(HostMsg::VentAll),
        (pump_mode(), pump_mode())
            .prop_map(|(positive, negative)| HostMsg::SetPumps { positive, negative }),
        tank_targets().prop_map(HostMsg::SetTankTargets),
        Just(HostMsg::Arm),
        Just(HostMsg::Disarm),
        any::<u16>().prop_map(|interval_ms| HostMsg::SetTelemetryInterval { interval_ms }),
        Just(HostMsg::Heartbeat),
        fault_flags().prop_map(|faults| HostMsg::ClearFaults { faults }),
        calibration().prop_map(HostMsg::SetCalibration),
    ]
}

/// Any values, plausible or not: every calibration must travel intact.
pub fn sensor_calibration() -> impl Strategy<Value = SensorCalibration> {
    (any::<i32>(), any::<u32>()).prop_map(|(offset_pa, gain_ppm)| SensorCalibration {
        offset_pa,
        gain_ppm,
    })
}

pub fn calibration() -> impl Strategy<Value = Calibration> {
    (sensor_calibration(), sensor_calibration())
        .prop_map(|(positive, negative)| Calibration { positive, negative })
}

pub fn calibration_record() -> impl Strategy<Value = CalibrationRecord> {
    prop_oneof![
        Just(CalibrationRecord::NotPersisted),
        Just(CalibrationRecord::Empty),
        any::<u16>().prop_map(|version| CalibrationRecord::Valid { version }),
        Just(CalibrationRecord::BadCrc),
        any::<u16>().prop_map(|version| CalibrationRecord::UnknownVersion { version }),
        Just(CalibrationRecord::NotARecord),
        any::<u16>().prop_map(|version| CalibrationRecord::Implausible { version }),
        Just(CalibrationRecord::WritePending),
        Just(CalibrationRecord::WriteFailed),
    ]
}

pub fn active_zero() -> impl Strategy<Value = ActiveZero> {
    (
        any::<i32>(),
        prop_oneof![
            Just(ZeroSource::Pending),
            Just(ZeroSource::Boot),
            Just(ZeroSource::Offset)
        ],
    )
        .prop_map(|(zero_pa, source)| ActiveZero { zero_pa, source })
}

pub fn calibration_report() -> impl Strategy<Value = CalibrationReport> {
    (
        calibration(),
        prop_oneof![
            Just(CalibrationSource::Default),
            Just(CalibrationSource::Flash),
            Just(CalibrationSource::Host)
        ],
        calibration_record(),
        active_zero(),
        active_zero(),
    )
        .prop_map(
            |(calibration, source, record, positive_zero, negative_zero)| CalibrationReport {
                calibration,
                source,
                record,
                positive_zero,
                negative_zero,
            },
        )
}

pub fn fault_flags() -> impl Strategy<Value = FaultFlags> {
    (0u16..(1 << Fault::ALL.len())).prop_map(FaultFlags)
}

pub fn last_stop() -> impl Strategy<Value = LastStop> {
    prop_oneof![
        Just(LastStop::None),
        fault().prop_map(|fault| LastStop::Trip { fault }),
        any::<u32>().prop_map(|line| LastStop::Panic { line }),
        any::<u32>().prop_map(|pc| LastStop::HardFault { pc }),
        any::<i16>().prop_map(|irqn| LastStop::UnexpectedInterrupt { irqn }),
    ]
}

pub fn reset_cause() -> impl Strategy<Value = ResetCause> {
    prop_oneof![
        Just(ResetCause::PowerOn),
        Just(ResetCause::Pin),
        Just(ResetCause::Software),
        Just(ResetCause::IndependentWatchdog),
        Just(ResetCause::WindowWatchdog),
        Just(ResetCause::LowPower),
        Just(ResetCause::Unknown),
    ]
}

pub fn nack_reason() -> impl Strategy<Value = NackReason> {
    prop_oneof![
        Just(NackReason::Malformed),
        Just(NackReason::UnknownMessage),
        Just(NackReason::NotArmed),
        Just(NackReason::Tripped),
        Just(NackReason::Refused),
        Just(NackReason::GuardBand),
        Just(NackReason::IntervalTooShort),
        Just(NackReason::Implausible),
    ]
}

pub fn arm_state() -> impl Strategy<Value = ArmState> {
    prop_oneof![
        Just(ArmState::Disarmed),
        Just(ArmState::Armed),
        Just(ArmState::Tripped)
    ]
}

pub fn fault() -> impl Strategy<Value = Fault> {
    proptest::sample::select(Fault::ALL.to_vec())
}

pub fn telemetry() -> impl Strategy<Value = Telemetry> {
    (
        (any::<u32>(), any::<i32>(), any::<i32>(), chambers()),
        (any::<bool>(), any::<bool>(), arm_state()),
        (0u16..(1 << Fault::ALL.len()), any::<u32>()),
    )
        .prop_map(
            |(
                (time_ms, positive_tank_pa, negative_tank_pa, chambers),
                (positive_pump_on, negative_pump_on, state),
                (faults, loop_overruns),
            )| Telemetry {
                time_ms,
                positive_tank_pa,
                negative_tank_pa,
                chambers,
                positive_pump_on,
                negative_pump_on,
                state,
                faults: FaultFlags(faults),
                loop_overruns,
            },
        )
}

pub fn mcu_msg() -> impl Strategy<Value = McuMsg> {
    prop_oneof![
        (
            any::<u8>(),
            any::<[u8; 3]>(),
            any::<i32>(),
            any::<i32>(),
            any::<u8>(),
            reset_cause(),
            (
                fault_flags(),
                last_stop(),
                any::<u16>(),
                calibration_report(),
            ),
        )
            .prop_map(
                |(
                    protocol_version,
                    [major, minor, patch],
                    p,
                    n,
                    c,
                    reset_cause,
                    (latched_faults, last_stop, min_telemetry_interval_ms, calibration),
                )| {
                    McuMsg::HelloReply(HelloReply {
                        protocol_version,
                        firmware_version: FirmwareVersion {
                            major,
                            minor,
                            patch,
                        },
                        positive_tank_max_pa: p,
                        negative_tank_min_pa: n,
                        chamber_count: c,
                        reset_cause,
                        latched_faults,
                        last_stop,
                        min_telemetry_interval_ms,
                        calibration,
                    })
                }
            ),
        any::<u16>().prop_map(|seq| McuMsg::Ack { seq }),
        (any::<u16>(), nack_reason()).prop_map(|(seq, reason)| McuMsg::Nack { seq, reason }),
        telemetry().prop_map(McuMsg::Telemetry),
        (any::<u32>(), fault(), any::<i32>(), any::<i32>()).prop_map(|(time_ms, fault, p, n)| {
            McuMsg::Fault(FaultEvent {
                time_ms,
                fault,
                positive_tank_pa: p,
                negative_tank_pa: n,
            })
        }),
    ]
}

/// Decodes every frame in `bytes` with a fresh decoder.
pub fn decode_all<M: Message>(bytes: &[u8]) -> Vec<Result<Frame<M>, FrameError>> {
    Decoder::<M>::new().feed(bytes).collect()
}

fn example_targets() -> TankTargets {
    TankTargets::new(35_000, -40_000).expect("inside limits")
}

fn example_telemetry() -> Telemetry {
    let mut chambers = [ValveState::Hold; CHAMBER_COUNT];
    chambers[1] = ValveState::Inflate;
    chambers[6] = ValveState::Deflate;
    Telemetry {
        time_ms: 123_456,
        positive_tank_pa: 35_012,
        negative_tank_pa: -39_950,
        chambers,
        positive_pump_on: true,
        negative_pump_on: false,
        state: ArmState::Armed,
        faults: FaultFlags::NONE.with(Fault::HostSilence),
        loop_overruns: 3,
    }
}

/// A plausible calibration: +1.2 kPa / x1.05 and -0.8 kPa / x0.98.
pub fn example_calibration() -> Calibration {
    Calibration {
        positive: SensorCalibration {
            offset_pa: 1_200,
            gain_ppm: 1_050_000,
        },
        negative: SensorCalibration {
            offset_pa: -800,
            gain_ppm: 980_000,
        },
    }
}

/// One instance of every HostMsg variant, in wire order (the wire
/// snapshots and the fuzz seeds).
pub fn host_examples() -> Vec<HostMsg> {
    let mut chambers = [ValveState::Hold; CHAMBER_COUNT];
    chambers[0] = ValveState::Inflate;
    chambers[7] = ValveState::Deflate;
    vec![
        HostMsg::Hello,
        HostMsg::Ping { nonce: 0xdead_beef },
        HostMsg::SetChambers { chambers },
        HostMsg::SealAll,
        HostMsg::VentAll,
        HostMsg::SetPumps {
            positive: PumpMode::Regulate,
            negative: PumpMode::Off,
        },
        HostMsg::SetTankTargets(example_targets()),
        HostMsg::Arm,
        HostMsg::Disarm,
        HostMsg::SetTelemetryInterval { interval_ms: 20 },
        HostMsg::Heartbeat,
        HostMsg::ClearFaults {
            faults: FaultFlags::NONE.with(Fault::HostSilence),
        },
        HostMsg::SetCalibration(example_calibration()),
    ]
}

/// One instance of every McuMsg variant, in wire order.
pub fn mcu_examples() -> Vec<McuMsg> {
    vec![
        McuMsg::HelloReply(HelloReply {
            protocol_version: PROTOCOL_VERSION,
            firmware_version: FirmwareVersion {
                major: 0,
                minor: 1,
                patch: 2,
            },
            positive_tank_max_pa: POSITIVE_TANK_MAX_PA,
            negative_tank_min_pa: NEGATIVE_TANK_MIN_PA,
            chamber_count: CHAMBER_COUNT as u8,
            reset_cause: ResetCause::IndependentWatchdog,
            latched_faults: FaultFlags::NONE.with(Fault::PositiveOverLimit),
            last_stop: LastStop::Panic { line: 300 },
            min_telemetry_interval_ms: 8,
            calibration: CalibrationReport {
                calibration: example_calibration(),
                source: CalibrationSource::Flash,
                record: CalibrationRecord::Valid { version: 1 },
                positive_zero: ActiveZero {
                    zero_pa: 1_450,
                    source: ZeroSource::Boot,
                },
                negative_zero: ActiveZero {
                    zero_pa: -800,
                    source: ZeroSource::Offset,
                },
            },
        }),
        McuMsg::Ack { seq: 513 },
        McuMsg::Nack {
            seq: 7,
            reason: NackReason::Tripped,
        },
        McuMsg::Telemetry(example_telemetry()),
        McuMsg::Fault(FaultEvent {
            time_ms: 42,
            fault: Fault::PositiveOverLimit,
            positive_tank_pa: 50_100,
            negative_tank_pa: -1_000,
        }),
    ]
}
