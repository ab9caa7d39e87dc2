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
    ]
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
            (fault_flags(), last_stop(), any::<u16>()),
        )
            .prop_map(
                |(
                    protocol_version,
                    [major, minor, patch],
                    p,
                    n,
                    c,
                    reset_cause,
                    (latched_faults, last_stop, min_telemetry_interval_ms),
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
