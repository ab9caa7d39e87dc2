//! The task loop's safety paths against a scripted fake board: a board that
//! fails the hello check is never armed; an MCU fault event and a command
//! refused because the MCU tripped each end the run with the fault, report
//! it on the events channel, and leave the gripper sealed and disarmed (the
//! shutdown of the task loop's module docs: `SealAll`, then `Disarm`).
//!
//! The sensors are idle sources (no frame until halted): every step here is
//! driven by the board's answers, none by a frame's timing.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, OnceLock};
use std::time::Duration;

use crate::fake_board::{answer, matching_hello, FakeBoard, HostLog, Outbox};
use dexitac_protocol::{
    Fault, FaultEvent, HelloReply, HostMsg, McuMsg, NackReason, CHAMBER_COUNT,
    POSITIVE_TANK_MAX_PA, PROTOCOL_VERSION,
};
use dexitac_rig::event::{RuntimeEvent, StopReason};
use dexitac_rig::link::{Link, LinkConfig, LinkError};
use dexitac_rig::source::{Clock, FrameSource, HaltHandle, SourceError, TimedFrame};
use dexitac_rig::task_loop::{self, ControlConfig, RuntimeError, Sensor};
use dexitac_tactile::calibrate::{self, Calibration};
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::synth::{rest_frame, Category};

/// A sensor that delivers no frame and ends when halted.
struct Idle(Arc<AtomicBool>);

impl FrameSource for Idle {
    fn next_frame(&mut self, _clock: &Clock) -> Result<Option<TimedFrame>, SourceError> {
        while !self.0.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(1));
        }
        Ok(None)
    }

    fn halt_handle(&self) -> Option<HaltHandle> {
        let halted = self.0.clone();
        Some(Box::new(move || halted.store(true, Ordering::Relaxed)))
    }
}

/// A calibration of the synthetic nominal sensor (made once per binary).
fn calibration() -> Calibration {
    static CAL: OnceLock<Calibration> = OnceLock::new();
    CAL.get_or_init(|| {
        let rest = rest_frame(&Category::Nominal.sensor(640, 480, 5), 99).image;
        calibrate::calibrate(&[rest], &Params::default()).expect("calibration")
    })
    .clone()
}

fn sensors() -> Vec<Sensor> {
    (0..dexitac_gripper::grasp::SENSOR_COUNT)
        .map(|_| Sensor {
            source: Box::new(Idle(Arc::default())),
            pipeline: Pipeline::new(calibration(), Params::default()),
        })
        .collect()
}

/// What a run against `board` gave.
struct Run {
    result: Result<StopReason, RuntimeError>,
    events: Vec<RuntimeEvent>,
    log: HostLog,
}

/// Runs the task loop against `board`. A run that would go on forever (the
/// failure under test did not happen) is stopped after a generous bound, so
/// the test fails instead of hanging; no test here waits for it otherwise.
fn run(config: &ControlConfig, board: FakeBoard) -> Run {
    let log = board.log();
    let mut link = Link::new(board, LinkConfig::default());
    let stop = AtomicBool::new(false);
    let (tx, rx) = mpsc::channel();
    let (done_tx, done_rx) = mpsc::channel::<()>();
    let result = std::thread::scope(|scope| {
        let stop = &stop;
        scope.spawn(move || {
            if let Err(mpsc::RecvTimeoutError::Timeout) =
                done_rx.recv_timeout(Duration::from_secs(30))
            {
                stop.store(true, Ordering::Relaxed);
            }
        });
        let result = task_loop::run(config, &mut link, sensors(), Clock::wall(), stop, &tx);
        drop(done_tx);
        result
    });
    drop(tx);
    Run {
        result,
        events: rx.iter().collect(),
        log,
    }
}

impl Run {
    /// The error the run ended with; also checks that the events channel's
    /// last event is `Stopped` with that error's text.
    fn error(self) -> (RuntimeError, HostLog) {
        let err = match self.result {
            Ok(reason) => panic!("the run ended without an error: {reason:?}"),
            Err(e) => e,
        };
        match self.events.last() {
            Some(RuntimeEvent::Stopped {
                outcome: Err(text), ..
            }) => assert_eq!(*text, err.to_string()),
            other => panic!("the last event is not Stopped with the error: {other:?}"),
        }
        (err, self.log)
    }
}

/// The setup commands of the task loop, in order, up to telemetry on.
fn is_setup(msg: &HostMsg) -> bool {
    matches!(
        msg,
        HostMsg::Hello
            | HostMsg::Arm
            | HostMsg::SetTankTargets(_)
            | HostMsg::SetPumps { .. }
            | HostMsg::SetTelemetryInterval { .. }
    )
}

/// The documented shutdown: seal, then disarm, and nothing after.
fn assert_sealed_then_disarmed(after: &[HostMsg]) {
    assert_eq!(
        after,
        [HostMsg::SealAll, HostMsg::Disarm],
        "after the failure the host sent {after:?}"
    );
}

/// A board that refuses the hello check is never armed.
fn assert_never_armed(hello: HelloReply, expected: impl Fn(&LinkError) -> bool) {
    let (err, log) = run(&ControlConfig::default(), FakeBoard::healthy(hello)).error();
    match &err {
        RuntimeError::Link(e) if expected(e) => {}
        other => panic!("unexpected error: {other}"),
    }
    let commands = log.commands();
    assert!(!commands.contains(&HostMsg::Arm), "armed: {commands:?}");
    assert_eq!(commands.first(), Some(&HostMsg::Hello));
    assert_sealed_then_disarmed(&commands[1..]);
}

#[test]
fn a_board_with_other_tank_limits_is_never_armed() {
    let limit = POSITIVE_TANK_MAX_PA + 5_000;
    assert_never_armed(
        HelloReply {
            positive_tank_max_pa: limit,
            ..matching_hello()
        },
        |e| matches!(e, LinkError::LimitsMismatch { mcu_max_pa, .. } if *mcu_max_pa == limit),
    );
}

#[test]
fn a_board_with_another_chamber_count_is_never_armed() {
    let chambers = CHAMBER_COUNT as u8 - 2;
    assert_never_armed(
        HelloReply {
            chamber_count: chambers,
            ..matching_hello()
        },
        |e| matches!(e, LinkError::LimitsMismatch { mcu_chambers, .. } if *mcu_chambers == chambers),
    );
}

#[test]
fn a_board_with_another_protocol_version_is_never_armed() {
    let version = PROTOCOL_VERSION + 1;
    assert_never_armed(
        HelloReply {
            protocol_version: version,
            ..matching_hello()
        },
        |e| matches!(e, LinkError::VersionMismatch { mcu, .. } if *mcu == version),
    );
}

/// The positive tank over its limit, as the firmware reports it.
fn over_limit() -> FaultEvent {
    FaultEvent {
        time_ms: 4_321,
        fault: Fault::PositiveOverLimit,
        positive_tank_pa: POSITIVE_TANK_MAX_PA + 1_234,
        negative_tank_pa: -20_000,
    }
}

/// A board that answers as the firmware does (its dispatch table): once
/// tripped, `Arm`, `SetChambers` and `SetPumps` are nacked `Tripped`;
/// `SealAll`, `Disarm`, heartbeats and the rest are acked. `trip` decides,
/// for each frame, whether the board trips just before answering it; the
/// trip sends `fault` (if any) first.
fn tripping_board(
    fault: Option<FaultEvent>,
    mut trip: impl FnMut(&HostMsg) -> bool + Send + 'static,
) -> FakeBoard {
    let mut tripped = false;
    FakeBoard::new(move |frame, out: &mut Outbox| {
        if !tripped && trip(&frame.msg) {
            tripped = true;
            if let Some(f) = fault {
                out.send(McuMsg::Fault(f));
            }
        }
        match frame.msg {
            HostMsg::Arm | HostMsg::SetChambers { .. } | HostMsg::SetPumps { .. } if tripped => {
                out.nack(frame, NackReason::Tripped)
            }
            _ => answer(matching_hello(), frame, out),
        }
    })
}

/// The commands after setup (the last setup command is telemetry on).
fn after_setup(log: &HostLog) -> Vec<HostMsg> {
    let commands = log.commands();
    let setup = commands.iter().take_while(|m| is_setup(m)).count();
    assert!(
        matches!(
            commands.get(setup.wrapping_sub(1)),
            Some(HostMsg::SetTelemetryInterval { .. })
        ),
        "setup did not finish: {commands:?}"
    );
    commands[setup..].to_vec()
}

#[test]
fn an_mcu_fault_event_ends_the_run_sealed_and_disarmed() {
    let fault = over_limit();
    // The board acks setup, then trips while the loop runs (at its first
    // heartbeat, the only frame the host sends while charging: charging
    // lasts up to 8 s).
    let board = tripping_board(Some(fault), |msg| *msg == HostMsg::Heartbeat);
    let (err, log) = run(&ControlConfig::default(), board).error();
    match err {
        RuntimeError::McuFault(f) => assert_eq!(f, fault),
        other => panic!("expected the MCU fault, got {other}"),
    }
    assert_sealed_then_disarmed(&after_setup(&log));
}

#[test]
fn a_tripped_nack_ends_the_run_with_the_fault_sealed_and_disarmed() {
    let fault = over_limit();
    // Closing starts at once (no charging wait); the board trips as the
    // fingers' command arrives: fault event, then the command's nack.
    let config = ControlConfig {
        charge_timeout_ms: 0,
        ..ControlConfig::default()
    };
    let board = tripping_board(Some(fault), |msg| {
        matches!(msg, HostMsg::SetChambers { .. })
    });
    let (err, log) = run(&config, board).error();
    match err {
        RuntimeError::McuFault(f) => assert_eq!(f, fault),
        other => panic!("expected the MCU fault, got {other}"),
    }
    let after = after_setup(&log);
    assert!(
        matches!(after.first(), Some(HostMsg::SetChambers { .. })),
        "{after:?}"
    );
    assert_sealed_then_disarmed(&after[1..]);
}

#[test]
fn a_tripped_nack_without_its_fault_event_still_ends_the_run_safely() {
    // The fault event was lost on the line: the nack alone stops the run.
    let config = ControlConfig {
        charge_timeout_ms: 0,
        ..ControlConfig::default()
    };
    let board = tripping_board(None, |msg| matches!(msg, HostMsg::SetChambers { .. }));
    let (err, log) = run(&config, board).error();
    match err {
        RuntimeError::Link(LinkError::Nack {
            msg: HostMsg::SetChambers { .. },
            reason: NackReason::Tripped,
            ..
        }) => {}
        other => panic!("expected the tripped nack, got {other}"),
    }
    let after = after_setup(&log);
    assert_sealed_then_disarmed(&after[1..]);
}
