//! Wire snapshots: the exact bytes of one frame per message variant.
//!
//! Firmware and host must agree byte for byte. If one of these fails, the
//! wire format changed: renumbered or reordered variants, a changed field
//! type, CRC or framing. That is a protocol break: bump
//! `PROTOCOL_VERSION`, then update the snapshots deliberately.

mod common;

use common::{host_examples, mcu_examples};
use dexitac_protocol::*;

fn hex(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// One instance of every HostMsg variant ([`host_examples`]), in wire order,
/// with its frame bytes (seq 0x0102).
fn host_snapshots() -> Vec<(HostMsg, &'static str)> {
    let hex = [
        // Hello
        "04 03 02 01 05 49 54 ab 89 00",
        // Ping
        "0e 03 02 01 01 ef fd b6 f5 0d 3e 47 28 41 00",
        // SetChambers
        "06 03 02 01 02 01 01 01 01 01 01 06 02 06 2c 27 c5 00",
        // SealAll
        "09 03 02 01 03 bd a7 fb 9a 00",
        // VentAll
        "09 03 02 01 04 56 c3 31 4e 00",
        // SetPumps
        "06 03 02 01 05 01 05 6d 80 42 3e 00",
        // SetTankTargets
        "0f 03 02 01 06 f0 a2 04 ff f0 04 9f 47 e7 c7 00",
        // Arm
        "09 03 02 01 07 a2 30 61 5d 00",
        // Disarm
        "09 03 02 01 08 86 0c 72 03 00",
        // SetTelemetryInterval
        "0a 03 02 01 09 14 ca 35 4f 32 00",
        // Heartbeat
        "09 03 02 01 0a 71 7c 49 e2 00",
        // ClearFaults
        "0a 03 02 01 0b 40 e8 48 b5 83 00",
        // SetCalibration
        "13 03 02 01 0c e0 12 90 8b 40 bf 0c a0 e8 3b bf 6e 62 e3 00",
    ];
    host_examples().into_iter().zip(hex).collect()
}

/// One instance of every McuMsg variant ([`mcu_examples`]), in wire order,
/// with its frame bytes (seq 0x0102).
fn mcu_snapshots() -> Vec<(McuMsg, &'static str)> {
    let hex = [
        // HelloReply
        "04 03 02 01 02 03 27 01 02 a0 8d 06 cf fa 06 08 03 01 02 ac 02 08 e0 12 90 8b 40 bf 0c a0 e8 3b 01 02 01 d4 16 01 bf 0c 02 66 84 42 09 00",
        // Ack
        "0b 03 02 01 01 81 04 88 a0 26 51 00",
        // Nack
        "0b 03 02 01 02 07 03 db af ce fd 00",
        // Telemetry
        "0e 03 02 01 03 c0 c4 07 88 a3 04 9b f0 04 02 01 01 01 01 02 02 02 01 08 01 40 03 2b ed 9e c2 00",
        // Fault
        "06 03 02 01 04 2a 0a e8 8e 06 cf 0f 6e 5f ec e7 00",
    ];
    mcu_examples().into_iter().zip(hex).collect()
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
    // `zip` stops at the shorter list: both must be complete.
    assert_eq!(snapshots.len(), usize::from(M::VARIANT_COUNT));
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
