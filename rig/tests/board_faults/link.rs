//! The serial link against a scripted fake board: a lost or corrupted ack is
//! recovered by a retry (same sequence number), a command whose acks are all
//! lost fails after `retries + 1` attempts, and a board with other hard
//! limits, another chamber count or another protocol version is refused at
//! hello with a message naming both sides' numbers.

use crate::fake_board::{answer, matching_hello, FakeBoard};
use dexitac_protocol::{
    HostMsg, McuMsg, CHAMBER_COUNT, NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA, PROTOCOL_VERSION,
};
use dexitac_rig::link::{Link, LinkConfig, LinkError};

/// Short ack timeouts: a lost ack costs 20 ms, not 100.
fn config() -> LinkConfig {
    LinkConfig {
        ack_timeout_ms: 20,
        retries: 3,
        ..LinkConfig::default()
    }
}

/// The sequence numbers of every `msg` frame the host sent.
fn seqs_of(log: &crate::fake_board::HostLog, msg: HostMsg) -> Vec<u16> {
    log.frames()
        .iter()
        .filter(|f| f.msg == msg)
        .map(|f| f.seq)
        .collect()
}

#[test]
fn a_lost_ack_is_recovered_by_one_retry_with_the_same_seq() {
    let mut arms = 0;
    let board = FakeBoard::new(move |frame, out| {
        if frame.msg == HostMsg::Arm {
            arms += 1;
            if arms == 1 {
                return; // the first ack is lost on the line
            }
        }
        answer(matching_hello(), frame, out);
    });
    let log = board.log();
    let mut link = Link::new(board, config());
    link.hello().expect("hello");
    link.command(HostMsg::Arm).expect("the retry is answered");
    assert_eq!(link.stats().retries, 1);
    // Sent twice with one sequence number (commands are idempotent).
    let arms = seqs_of(&log, HostMsg::Arm);
    assert_eq!(arms.len(), 2, "{:?}", log.frames());
    assert_eq!(arms[0], arms[1]);
    // The link goes on normally.
    link.command(HostMsg::SealAll).expect("seal");
    assert_eq!(link.stats().retries, 1);
}

#[test]
fn a_corrupted_ack_is_rejected_and_recovered_by_one_retry() {
    let mut arms = 0;
    let board = FakeBoard::new(move |frame, out| match frame.msg {
        HostMsg::Arm => {
            arms += 1;
            let ack = McuMsg::Ack { seq: frame.seq };
            if arms == 1 {
                out.send_corrupted(ack);
            } else {
                out.send(ack);
            }
        }
        _ => answer(matching_hello(), frame, out),
    });
    let log = board.log();
    let mut link = Link::new(board, config());
    link.hello().expect("hello");
    link.command(HostMsg::Arm).expect("the retry is answered");
    let stats = link.stats();
    assert_eq!(stats.frame_errors, 1, "{stats:?}");
    assert_eq!(stats.retries, 1, "{stats:?}");
    assert_eq!(seqs_of(&log, HostMsg::Arm).len(), 2);
}

#[test]
fn a_command_whose_acks_are_all_lost_times_out_after_every_retry() {
    let board = FakeBoard::new(|frame, out| {
        if frame.msg != HostMsg::Arm {
            answer(matching_hello(), frame, out);
        }
    });
    let log = board.log();
    let config = config();
    let retries = config.retries;
    let mut link = Link::new(board, config);
    link.hello().expect("hello");
    let err = link.command(HostMsg::Arm).unwrap_err();
    let text = err.to_string();
    let LinkError::Timeout { msg, seq, attempts } = err else {
        panic!("expected a timeout, got {err}");
    };
    assert_eq!(msg, HostMsg::Arm);
    assert_eq!(attempts, retries + 1);
    assert_eq!(link.stats().retries, u64::from(retries));
    let arms = seqs_of(&log, HostMsg::Arm);
    assert_eq!(
        arms,
        vec![seq; (retries + 1) as usize],
        "{:?}",
        log.frames()
    );
    assert!(
        text.contains(&format!("after {attempts} attempts")),
        "{text}"
    );
    // The next command gets the next sequence number and its ack.
    link.command(HostMsg::SealAll).expect("seal");
    assert_eq!(seqs_of(&log, HostMsg::SealAll), vec![seq.wrapping_add(1)]);
}

/// Says hello to a board that answers with `hello`.
fn hello_with(hello: dexitac_protocol::HelloReply) -> LinkError {
    let board = FakeBoard::healthy(hello);
    let log = board.log();
    let err = Link::new(board, config()).hello().unwrap_err();
    assert_eq!(
        log.commands(),
        vec![HostMsg::Hello],
        "one hello, nothing else"
    );
    err
}

#[test]
fn other_tank_limits_at_hello_are_refused_naming_both_sides() {
    let cases = [
        (POSITIVE_TANK_MAX_PA + 5_000, NEGATIVE_TANK_MIN_PA),
        (POSITIVE_TANK_MAX_PA, NEGATIVE_TANK_MIN_PA - 7_000),
    ];
    for (max_pa, min_pa) in cases {
        let err = hello_with(dexitac_protocol::HelloReply {
            positive_tank_max_pa: max_pa,
            negative_tank_min_pa: min_pa,
            ..matching_hello()
        });
        let text = err.to_string();
        let LinkError::LimitsMismatch {
            mcu_max_pa,
            mcu_min_pa,
            mcu_chambers,
        } = err
        else {
            panic!("expected a limits mismatch, got {err}");
        };
        assert_eq!(
            (mcu_max_pa, mcu_min_pa, usize::from(mcu_chambers)),
            (max_pa, min_pa, CHAMBER_COUNT)
        );
        assert!(
            text.contains(&format!("tanks {max_pa}/{min_pa} Pa")),
            "the board's limits: {text}"
        );
        assert!(
            text.contains(&format!(
                "expected {POSITIVE_TANK_MAX_PA}/{NEGATIVE_TANK_MIN_PA} Pa"
            )),
            "the host's limits: {text}"
        );
    }
}

#[test]
fn another_chamber_count_at_hello_is_refused_naming_both_counts() {
    let chambers = CHAMBER_COUNT as u8 + 2;
    let err = hello_with(dexitac_protocol::HelloReply {
        chamber_count: chambers,
        ..matching_hello()
    });
    let text = err.to_string();
    assert!(
        matches!(err, LinkError::LimitsMismatch { mcu_chambers, .. } if mcu_chambers == chambers),
        "{text}"
    );
    assert!(
        text.contains(&format!("with {chambers} chambers")),
        "the board's count: {text}"
    );
    assert!(
        text.ends_with(&format!("with {CHAMBER_COUNT}")),
        "the host's count: {text}"
    );
}

#[test]
fn another_protocol_version_at_hello_is_refused_naming_both_versions() {
    let version = PROTOCOL_VERSION + 1;
    let err = hello_with(dexitac_protocol::HelloReply {
        protocol_version: version,
        ..matching_hello()
    });
    let text = err.to_string();
    assert!(
        matches!(
            err,
            LinkError::VersionMismatch { mcu, host } if mcu == version && host == PROTOCOL_VERSION
        ),
        "{text}"
    );
    assert!(
        text.contains(&format!("protocol v{version}"))
            && text.contains(&format!("host v{PROTOCOL_VERSION}")),
        "{text}"
    );
}

#[test]
fn a_matching_hello_is_accepted() {
    // The mismatch tests above differ from this board in one field each.
    let reply = Link::new(FakeBoard::healthy(matching_hello()), config())
        .hello()
        .expect("hello");
    assert_eq!(reply, matching_hello());
}
