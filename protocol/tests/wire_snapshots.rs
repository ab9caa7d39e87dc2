//! Wire snapshots: the exact bytes of one frame per message variant.
//!
//! Firmware and host must agree byte for byte. If one of these fails, the
//! wire format changed: renumbered or reordered variants, a changed field
//! type, CRC or framing. That is a protocol break: bump
//! `PROTOCOL_VERSION`, then update the snapshots deliberately.

use dexitac_protocol::*;

fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

fn targets() -> TankTargets {
    TankTargets::new(35_000, -40_000).expect("inside limits")
}

fn telemetry() -> Telemetry {
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

/// One instance of every HostMsg variant, in wire order, with its frame bytes (seq 0x0102).
fn host_snapshots() -> Vec<(HostMsg, &'static str)> {
    let mut chambers = [ValveState::Hold; CHAMBER_COUNT];
    chambers[0] = ValveState::Inflate;
    chambers[7] = ValveState::Deflate;
    vec![
        (HostMsg::Hello, "04 02 02 01 05 f1 fe ee 54 00"),
        (
            HostMsg::Ping { nonce: 0xdead_beef },
            "0e 02 02 01 01 ef fd b6 f5 0d 76 91 16 b5 00",
        ),
        (
            HostMsg::SetChambers { chambers },
            "06 02 02 01 02 01 01 01 01 01 01 06 02 36 f8 56 f4 00",
        ),
        (HostMsg::SealAll, "09 02 02 01 03 05 0d be 47 00"),
        (HostMsg::VentAll, "09 02 02 01 04 ee 69 74 93 00"),
        (
            HostMsg::SetPumps {
                positive: PumpMode::Regulate,
                negative: PumpMode::Off,
            },
            "06 02 02 01 05 01 05 74 eb 72 d1 00",
        ),
        (
            HostMsg::SetTankTargets(targets()),
            "0f 02 02 01 06 f0 a2 04 ff f0 04 3a 3c b1 0c 00",
        ),
        (HostMsg::Arm, "09 02 02 01 07 1a 9a 24 80 00"),
        (HostMsg::Disarm, "09 02 02 01 08 3e a6 37 de 00"),
        (
            HostMsg::SetTelemetryInterval { interval_ms: 20 },
            "0a 02 02 01 09 14 66 5a 5e 0a 00",
        ),
        (HostMsg::Heartbeat, "09 02 02 01 0a c9 d6 0c 3f 00"),
        (
            HostMsg::ClearFaults {
                faults: FaultFlags::NONE.with(Fault::HostSilence),
            },
            "0a 02 02 01 0b 40 44 27 a4 bb 00",
        ),
    ]
}

/// One instance of every McuMsg variant, in wire order, with its frame bytes (seq 0x0102).
fn mcu_snapshots() -> Vec<(McuMsg, &'static str)> {
    vec![
        (
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
            }),
            "04 02 02 01 02 02 14 01 02 a0 8d 06 cf fa 06 08 03 01 02 ac 02 08 ad 77 7a 37 00",
        ),
        (McuMsg::Ack { seq: 513 }, "0b 02 02 01 01 81 04 91 cb 16 be 00"),
        (
            McuMsg::Nack {
                seq: 7,
                reason: NackReason::Tripped,
            },
            "0b 02 02 01 02 07 03 c2 c4 fe 12 00",
        ),
        (
            McuMsg::Telemetry(telemetry()),
            "0e 02 02 01 03 c0 c4 07 88 a3 04 9b f0 04 02 01 01 01 01 02 02 02 01 08 01 40 03 24 69 30 ef 00",
        ),
        (
            McuMsg::Fault(FaultEvent {
                time_ms: 42,
                fault: Fault::PositiveOverLimit,
                positive_tank_pa: 50_100,
                negative_tank_pa: -1_000,
            }),
            "06 02 02 01 04 2a 0a e8 8e 06 cf 0f af a8 9d 70 00",
        ),
    ]
}

fn check<M: Message + std::fmt::Debug>(snapshots: Vec<(M, &'static str)>) {
    let mut failures = Vec::new();
    for (msg, want) in &snapshots {
        let got = hex(&EncodedFrame::new(0x0102, msg).expect("fits"));
        if got != *want {
            failures.push(format!("{msg:?}\n    want: {want}\n    got:  {got}"));
        }
    }
    assert!(
        failures.is_empty(),
        "wire format changed:\n{}",
        failures.join("\n")
    );
}

/// The snapshot lists hold exactly one message per variant, in tag order,
/// so a new variant without a snapshot fails here.
fn check_covers_every_variant<M: Message>(snapshots: &[(M, &'static str)]) {
    let tags: Vec<u8> = snapshots
        .iter()
        .map(|(msg, _)| postcard::to_allocvec(msg).expect("encodes")[0])
        .collect();
    let all: Vec<u8> = (0..M::VARIANT_COUNT).collect();
    assert_eq!(tags, all);
}

#[test]
fn host_messages_match_their_wire_snapshots() {
    check(host_snapshots());
}

#[test]
fn mcu_messages_match_their_wire_snapshots() {
    check(mcu_snapshots());
}

#[test]
fn snapshots_cover_every_variant_in_tag_order() {
    check_covers_every_variant(&host_snapshots());
    check_covers_every_variant(&mcu_snapshots());
}

#[test]
fn set_chambers_frame_is_18_bytes() {
    let msg = HostMsg::SetChambers {
        chambers: [ValveState::Inflate; CHAMBER_COUNT],
    };
    let body = postcard::to_allocvec(&msg).expect("encodes").len();
    let wire = EncodedFrame::new(1, &msg).expect("fits").len();
    assert_eq!(body, 9, "postcard body");
    assert_eq!(wire, 18, "bytes on the wire");
    assert_eq!(wire - body, 9, "overhead stated in the crate docs");
}
