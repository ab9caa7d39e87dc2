//! The manipulation primitives end to end on the simulated rig, on the virtual clock:
//! grasp, seal, then the primitive drives the manipulation joints through the
//! host's task loop, the link and the firmware; its tactile guards read the
//! rendered cameras through the pipeline. Assertions are functional (what
//! happened, in which order); the angles come from invented plant
//! coefficients and are only checked for being there and plausible.

use dexitac_gripper::manipulation::{Drive, GuardTrip, TaskEvent, MANIPULATION_CHAMBERS};
use dexitac_protocol::{ArmState, HostMsg, ValveState, CHAMBER_COUNT};
use dexitac_rig::task_loop::DEFAULT_GRASP_CHAMBERS;
use dexitac_sim::rig::{run_scenario, Outcome, Pace, SimOptions, SimReport};
use dexitac_sim::scenario::Scenario;
use dexitac_sim::task_report::TaskReport;

/// On the virtual clock, at the firmware's real deadlines (see sim_scenarios.rs).
fn run(scenario: &Scenario) -> (SimReport, TaskReport) {
    let options = SimOptions {
        speed: Pace::Max,
        ..SimOptions::default()
    };
    let report = run_scenario(scenario, &options).expect("simulated rig");
    assert!(report.loop_result.is_ok(), "{:?}", report.loop_result);
    assert_eq!(report.mcu_at_end.state, ArmState::Disarmed);
    assert_eq!(
        report.mcu_at_end.chambers,
        [ValveState::Hold; CHAMBER_COUNT]
    );
    let task = report.task.clone().expect("the task started");
    eprintln!(
        "{}: achieved {:?} deg {:?} mm (paper {} deg), per cycle {:?}, guard trips {}, {:.1} s wall",
        scenario.name,
        task.achieved_deg,
        task.achieved_mm,
        task.kind.paper_deg(),
        task.per_cycle_deg,
        task.guard_trips,
        report.wall_s
    );
    (report, task)
}

/// Every task command keeps the grasping chambers sealed.
fn assert_grasp_sealed_during_task(r: &SimReport) {
    let task_commands: Vec<_> = r
        .commands
        .iter()
        .filter(|(_, _, reason)| reason.starts_with("task:"))
        .collect();
    assert!(!task_commands.is_empty());
    for (_, msg, reason) in task_commands {
        let HostMsg::SetChambers { chambers } = msg else {
            panic!("{reason}: {msg:?}");
        };
        for c in DEFAULT_GRASP_CHAMBERS {
            assert_eq!(chambers[c], ValveState::Hold, "{reason}: {chambers:?}");
        }
    }
}

fn strokes(t: &TaskReport) -> Vec<Drive> {
    t.events
        .iter()
        .filter_map(|(_, e)| match e {
            TaskEvent::Stroke { drive, .. } => Some(*drive),
            _ => None,
        })
        .collect()
}

fn preset(name: &str) -> Scenario {
    Scenario::load(name).expect("preset")
}

#[test]
fn pour_tilts_while_the_grasp_holds() {
    let (r, t) = run(&preset("pour"));
    assert_eq!(r.outcome, Outcome::Held);
    assert!(t.completed && !t.stopped_by_guard, "{:?}", t.events);
    assert_grasp_sealed_during_task(&r);
    let tilt = t.achieved_deg.expect("a tilt");
    assert!((20.0..90.0).contains(&tilt), "tilt {tilt} deg");
    // Both fingers touch the cup through the whole tilt.
    let start = t.events[0].0;
    assert!(r
        .trace
        .iter()
        .filter(|s| s.t_ms >= start)
        .all(|s| s.contacts.iter().all(Option::is_some)));
}

#[test]
fn rotate_turns_twice() {
    let (r, t) = run(&preset("rotate"));
    assert_eq!(r.outcome, Outcome::Held);
    assert!(t.completed && !t.stopped_by_guard, "{:?}", t.events);
    assert_grasp_sealed_during_task(&r);
    assert_eq!(
        strokes(&t),
        vec![Drive::Forward, Drive::Hold, Drive::Forward]
    );
    assert_eq!(t.per_cycle_deg.len(), 2);
    assert!(
        t.per_cycle_deg.iter().all(|d| *d > 3.0),
        "{:?}",
        t.per_cycle_deg
    );
}

#[test]
fn shake_completes_its_cycles_when_the_bowl_stays_put() {
    let (r, t) = run(&preset("shake"));
    assert_eq!(r.outcome, Outcome::Held);
    assert!(t.completed && !t.stopped_by_guard, "{:?}", t.events);
    assert_grasp_sealed_during_task(&r);
    let cycles = preset("shake").task.expect("task").cycles as usize;
    assert_eq!(strokes(&t).len(), 2 * cycles);
    assert!(t.achieved_deg.is_some_and(|a| a > 5.0), "{t:?}");
    assert!(t.achieved_mm.is_some_and(|a| a > 2.0), "{t:?}");
}

#[test]
fn shake_stops_when_the_contact_x_shift_grows() {
    let mut s = preset("shake");
    s.name = "shake-loose".into();
    // The bowl works loose: its contacts creep in x with every stroke.
    s.object.manip_creep_x_mm_per_deg = 0.04;
    let (r, t) = run(&s);
    assert!(t.stopped_by_guard && !t.completed, "{:?}", t.events);
    let Some((stop_ms, TaskEvent::Guard { trip, .. })) = t.events.last() else {
        panic!("{:?}", t.events);
    };
    assert!(matches!(trip, GuardTrip::XShift { shift_mm, .. } if *shift_mm > 3.0));
    let cycles = s.task.expect("task").cycles as usize;
    assert!(strokes(&t).len() < 2 * cycles);
    // After the stop the manipulation chambers stay sealed: the angle only
    // leaks slowly (sealed leak time constant 40 s), no more strokes.
    let after: Vec<f64> = r
        .trace
        .iter()
        .filter(|w| (stop_ms + 300..stop_ms + 2_300).contains(&w.t_ms))
        .map(|w| w.object_deg)
        .collect();
    let [a, b] = MANIPULATION_CHAMBERS[0];
    let sealed_after = r
        .trace
        .iter()
        .filter(|w| w.t_ms > stop_ms + 300)
        .all(|w| w.valves[a] == ValveState::Hold && w.valves[b] == ValveState::Hold);
    assert!(sealed_after);
    if let (Some(lo), Some(hi)) = (
        after.iter().copied().reduce(f64::min),
        after.iter().copied().reduce(f64::max),
    ) {
        assert!(hi - lo < 3.0, "moved {lo}..{hi} deg after the stop");
    }
}

#[test]
fn twist_returns_at_the_sensor_edge_and_repeats() {
    let s = preset("twist");
    let (r, t) = run(&s);
    assert_eq!(r.outcome, Outcome::Held);
    assert!(t.completed, "{:?}", t.events);
    assert_grasp_sealed_during_task(&r);
    let task = s.task.expect("task");
    // Every twist ended at the edge guard, none on the stroke time limit.
    assert_eq!(t.guard_trips, task.cycles as usize, "{:?}", t.events);
    for (_, e) in &t.events {
        if let TaskEvent::Guard { trip, stopped } = e {
            assert!(!stopped);
            assert!(
                matches!(trip, GuardTrip::NearEdge { x_mm, .. } if x_mm.abs() >= task.edge_x_mm)
            );
        }
    }
    assert_eq!(t.per_cycle_deg.len(), task.cycles as usize);
    // It returned close to the start before twisting again.
    let second = t
        .events
        .iter()
        .filter(|(_, e)| {
            matches!(
                e,
                TaskEvent::Stroke {
                    drive: Drive::Forward,
                    ..
                }
            )
        })
        .nth(1)
        .map(|(ms, _)| *ms)
        .expect("a second twist");
    let at_second = r
        .trace
        .iter()
        .find(|w| w.t_ms >= second)
        .map(|w| w.object_deg)
        .expect("trace");
    let peak = t.per_cycle_deg[0];
    assert!(at_second.abs() < 0.25 * peak, "{at_second} deg of {peak}");
}
