//! The runtime's safety paths end to end, on the virtual clock: a fault is
//! injected into a simulated run (a board reset, a sensor reading high, a
//! camera that hangs, a host that stalls) and the run must end the way the
//! task loop's docs say (`dexitac_rig::task_loop`, "Watchdogs"), within the
//! stated time, with the gripper sealed and the MCU disarmed or tripped.
//! Virtual time makes every bound exact: the same run gives the same times.

use dexitac_protocol::{
    ArmState, Fault, ResetCause, ValveState, CHAMBER_COUNT, POSITIVE_TANK_MAX_PA,
};
use dexitac_rig::task_loop::{MCU_SILENCE_MS, SENSOR_TIMEOUT_MS};
use dexitac_sim::rig::{run_scenario, Injection, Outcome, Pace, SimOptions, SimReport};
use dexitac_sim::scenario::Scenario;
use dexitac_sim::status::{seconds, LoopError};

/// When the faults strike: grasp-hold has sealed its grasp by then (closing
/// starts after the tanks charge, the stable span is 3 s) and is lifting.
const AT_MS: u64 = 9_500;
/// The telemetry period the task loop asks for, ms.
const TELEMETRY_MS: u64 = 20;
/// The firmware's host-silence deadline, ms.
const HOST_SILENCE_MS: u64 = dexitac_firmware::control::DEFAULT_HOST_SILENCE_MS as u64;

fn run(injections: Vec<Injection>) -> SimReport {
    let scenario = Scenario::load("grasp-hold").expect("preset");
    let options = SimOptions {
        speed: Pace::Max,
        injections,
        ..SimOptions::default()
    };
    run_scenario(&scenario, &options).expect("simulated rig")
}

/// The run's error text.
fn error(r: &SimReport) -> String {
    match &r.loop_result {
        Ok(reason) => panic!("the run ended normally ({reason:?})"),
        Err(e) => e.to_string(),
    }
}

/// The number after `key` in `text`.
fn number_after(text: &str, key: &str) -> u64 {
    let rest = &text[text
        .find(key)
        .unwrap_or_else(|| panic!("no `{key}` in {text}"))
        + key.len()..];
    rest.chars()
        .take_while(char::is_ascii_digit)
        .collect::<String>()
        .parse()
        .unwrap_or_else(|_| panic!("no number after `{key}` in {text}"))
}

fn assert_sealed(r: &SimReport) {
    assert_eq!(
        r.mcu_at_end.chambers,
        [ValveState::Hold; CHAMBER_COUNT],
        "{:?}",
        r.mcu_at_end
    );
    assert!(!r.mcu_at_end.pumps.positive_on && !r.mcu_at_end.pumps.negative_on);
}

#[test]
fn the_undisturbed_run_holds_and_ends_normally() {
    // The baseline the faults below are injected into.
    let r = run(Vec::new());
    assert!(r.loop_result.is_ok(), "{:?}", r.loop_result);
    assert_eq!(r.outcome, Outcome::Held);
    let sealed_ms = (r.time_to_stable_s.expect("sealed") * 1e3) as u64;
    assert!(sealed_ms < AT_MS, "sealed at {sealed_ms} ms");
}

#[test]
fn a_board_reset_mid_grasp_ends_the_run_within_the_silence_bound() {
    let r = run(vec![Injection::McuResetAt { at_ms: AT_MS }]);
    let Err(LoopError::McuReset {
        cause,
        t_ms: noticed,
    }) = r.loop_result
    else {
        panic!("{:?}", r.loop_result);
    };
    // The firmware restarts with telemetry off: the loop notices the
    // silence after MCU_SILENCE_MS (the last telemetry came at most one
    // period before the reset), says hello (which gets the reset cause) and
    // listens for MCU_SILENCE_MS more.
    assert_eq!(cause, Some(ResetCause::Software));
    assert_eq!(
        r.status().to_string(),
        format!("MCU reset, noticed at {} s", seconds(noticed as f64 / 1e3))
    );
    assert!(
        noticed > AT_MS + 2 * MCU_SILENCE_MS - TELEMETRY_MS
            && noticed <= AT_MS + 2 * MCU_SILENCE_MS + 2 * TELEMETRY_MS,
        "noticed at {noticed} ms"
    );
    // The board restarted disarmed and sealed; the grasp keeps its air.
    assert_eq!(r.mcu_at_end.state, ArmState::Disarmed);
    assert_sealed(&r);
    assert_eq!(r.outcome, Outcome::Held);
}

#[test]
fn a_run_that_ends_before_the_fingers_close_grasped_nothing() {
    // The board resets while the tanks still charge: the run ends before
    // closing began, with the object on the table between open fingers.
    let r = run(vec![Injection::McuResetAt { at_ms: 300 }]);
    assert!(
        matches!(r.loop_result, Err(LoopError::McuReset { .. })),
        "{:?}",
        r.loop_result
    );
    assert_eq!(r.time_to_stable_s, None);
    assert_eq!(r.outcome, Outcome::NotGrasped);
}

#[test]
fn late_telemetry_is_not_taken_for_a_reset() {
    // The MCU stops for 300 ms (longer than MCU_SILENCE_MS, shorter than
    // its own host-silence deadline) and then catches up: the loop's hello
    // is answered late and the telemetry resumes, so the run goes on.
    let r = run(vec![Injection::McuStallAt {
        at_ms: AT_MS,
        for_ms: 300,
    }]);
    assert!(r.loop_result.is_ok(), "{:?}", r.loop_result);
    assert_eq!(r.outcome, Outcome::Held);
    assert!(r.link_stats.retries > 0, "{:?}", r.link_stats);
}

#[test]
fn an_over_limit_reading_trips_the_board_and_the_run_reports_the_fault() {
    // The positive tank's sensor reads 20 kPa high: about 60 kPa against
    // the 50 kPa limit.
    let r = run(vec![Injection::ReadingOffsetAt {
        at_ms: AT_MS,
        offset_pa: (20_000, 0),
    }]);
    let e = error(&r);
    assert!(
        e.contains("tripped: positive tank over its pressure limit"),
        "{e}"
    );
    let tripped = number_after(&e, "at ");
    // MCU time, which started with the run: the trip follows within the
    // firmware's filter, well inside a telemetry period.
    assert!(
        (AT_MS..=AT_MS + TELEMETRY_MS).contains(&tripped),
        "tripped at {tripped} ms"
    );
    assert_eq!(r.mcu_at_end.state, ArmState::Tripped);
    assert!(!r.mcu_at_end.faults.is_empty());
    assert!(!r.mcu_at_end.pumps.positive_on && !r.mcu_at_end.pumps.negative_on);
    assert!(
        r.mcu_at_end
            .chambers
            .iter()
            .all(|v| *v != ValveState::Inflate),
        "{:?}",
        r.mcu_at_end
    );
    // The run ends right after the trip, not at the scenario's end.
    assert!(
        r.sim_s * 1e3 < (AT_MS + 200) as f64,
        "ended at {} s",
        r.sim_s
    );
}

#[test]
fn a_camera_that_stops_while_holding_ends_the_run_sealed() {
    let r = run(vec![Injection::CameraStopsAt {
        finger: 1,
        at_ms: AT_MS,
    }]);
    let e = error(&r);
    assert!(e.contains("sensor 1 delivered no frame"), "{e}");
    let last = number_after(&e, "last at ");
    let silent = number_after(&e, "for ");
    // Its last frame was the one before AT_MS; the watchdog fires at the
    // first pass after SENSOR_TIMEOUT_MS without one.
    assert!(
        last < AT_MS && last + 33 >= AT_MS,
        "last frame at {last} ms"
    );
    assert!(
        silent > SENSOR_TIMEOUT_MS && silent <= SENSOR_TIMEOUT_MS + 3,
        "silent for {silent} ms"
    );
    assert!(
        r.sim_s * 1e3 < (last + silent + 100) as f64,
        "ended at {} s",
        r.sim_s
    );
    // Documented action: sealed (the grasp keeps holding), disarmed.
    assert_eq!(r.mcu_at_end.state, ArmState::Disarmed);
    assert_sealed(&r);
    assert_eq!(r.outcome, Outcome::Held);
}

#[test]
fn a_host_stall_beyond_the_firmware_deadline_trips_it_at_its_real_value() {
    let r = run(vec![Injection::HostStallAt {
        at_ms: AT_MS,
        for_ms: HOST_SILENCE_MS + 100,
    }]);
    let e = error(&r);
    assert!(e.contains("tripped: host silent past the deadline"), "{e}");
    let tripped = number_after(&e, "at ");
    // The host's last frame before the stall came within one heartbeat
    // period (100 ms) of it; the trip follows 500 ms after that frame.
    assert!(
        tripped > AT_MS + HOST_SILENCE_MS - 100 && tripped <= AT_MS + HOST_SILENCE_MS + 1,
        "tripped at {tripped} ms"
    );
    assert_eq!(r.mcu_at_end.state, ArmState::Tripped);
}

#[test]
fn a_host_stall_inside_the_deadline_is_ridden_out() {
    // 300 ms plus at most a heartbeat period stays under 500 ms.
    let r = run(vec![Injection::HostStallAt {
        at_ms: AT_MS,
        for_ms: 300,
    }]);
    assert!(r.loop_result.is_ok(), "{:?}", r.loop_result);
    assert_eq!(r.outcome, Outcome::Held);
    assert!(
        r.max_loop_gap.as_millis() >= 300,
        "the stall shows as the longest loop gap: {:?}",
        r.max_loop_gap
    );
}

#[test]
fn the_same_seed_gives_the_same_run() {
    let scenario = Scenario::load("disturbance").expect("preset");
    let options = SimOptions {
        speed: Pace::Max,
        ..SimOptions::default()
    };
    let a = run_scenario(&scenario, &options).expect("run a");
    let b = run_scenario(&scenario, &options).expect("run b");
    assert_eq!(a.commands, b.commands);
    assert_eq!(a.decisions, b.decisions);
    assert_eq!(a.transitions, b.transitions);
    // Everything but the pipeline's wall-clock time per frame.
    let seen = |r: &SimReport| {
        r.observations
            .iter()
            .map(|o| (o.sensor, o.t_ms, o.centre_mm))
            .collect::<Vec<_>>()
    };
    assert_eq!(seen(&a), seen(&b));
    assert_eq!(a.sim_s, b.sim_s);
}

#[test]
fn a_sensor_reading_low_is_caught_by_the_firmwares_pump_limits() {
    // The positive tank's sensor reads 20 kPa low: the regulation keeps its
    // pump running while the tank really passes its target. The firmware's
    // pump limits (run time, rise, stall) at their real values must stop it.
    let r = run(vec![Injection::ReadingOffsetAt {
        at_ms: AT_MS,
        offset_pa: (-20_000, 0),
    }]);
    let Err(LoopError::McuFault(fault)) = r.loop_result else {
        panic!("{:?}", r.loop_result);
    };
    // The rise check (a 1 s window, twice, plus the filter) sees a tank
    // whose reading lags what its pump should give.
    assert_eq!(fault.fault, Fault::PositivePumpNoRise, "{fault:?}");
    let tripped = u64::from(fault.time_ms);
    assert!(
        (AT_MS..=AT_MS + 2 * 1_000 + 20).contains(&tripped),
        "tripped at {tripped} ms"
    );
    assert_eq!(r.mcu_at_end.state, ArmState::Tripped);
    assert!(!r.mcu_at_end.pumps.positive_on && !r.mcu_at_end.pumps.negative_on);
    // The tank itself never reached its limit.
    assert!(
        r.mcu_at_end.tanks_pa.0 < POSITIVE_TANK_MAX_PA,
        "{:?}",
        r.mcu_at_end
    );
}

#[test]
fn a_stop_request_ends_a_run_on_the_virtual_clock() {
    // Ctrl-C sets the caller's stop flag; here it is set from the start.
    let scenario = Scenario::load("grasp-hold").expect("preset");
    let options = SimOptions {
        speed: Pace::Max,
        ..SimOptions::default()
    };
    options
        .stop
        .store(true, std::sync::atomic::Ordering::Relaxed);
    let r = run_scenario(&scenario, &options).expect("simulated rig");
    assert!(r.loop_result.is_ok(), "{:?}", r.loop_result);
    // It stops at the first tick after the setup, not at the scenario's 18 s.
    assert!(r.sim_s < 0.5, "ran {} s", r.sim_s);
    assert_eq!(r.mcu_at_end.state, ArmState::Disarmed);
    assert_sealed(&r);
}
