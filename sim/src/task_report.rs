//! What a manipulation task achieved in a simulated run, measured on the
//! plant's trace (the simulator's stand-in for the paper's ArUco marker):
//!
//! - pour: the largest object angle;
//! - rotate: per turn, the largest angle before the next turn minus the
//!   angle at the turn's start; reported: their mean;
//! - shake: half the peak-to-peak object angle after the first stroke (+-),
//!   and the fingertip's sideways sway for that angle by the
//!   constant-curvature forward kinematics of a Dex joint plus fingertip
//!   ([`dexitac_gripper::kinematics::arc`]);
//! - twist: per twist, the largest angle of its forward stroke; reported:
//!   the largest.
//!
//! The angles come from the plant's invented manipulation coefficients
//! ([`crate::plant::PlantParams::manip_deg_per_kpa`] and the scenario's
//! stroke times), not from a model fitted to the real gripper: they show
//! that the primitives and guards work end to end, not the paper's numbers.

use crate::plant::WorldState;
use dexitac_gripper::configuration::{ACTUATOR_LENGTH_MM, FINGERTIP_LENGTH_MM};
use dexitac_gripper::manipulation::{Drive, TaskEvent, TaskKind, TaskParams};

/// A manipulation task's outcome next to the paper's.
#[derive(Debug, Clone, PartialEq)]
pub struct TaskReport {
    /// Which task.
    pub kind: TaskKind,
    /// The gripper configuration.
    pub gripper: String,
    /// The primitive's events with their times, ms.
    pub events: Vec<(u64, TaskEvent)>,
    /// Every stroke ran.
    pub completed: bool,
    /// A guard ended the task early.
    pub stopped_by_guard: bool,
    /// Guard trips (twist: one per return).
    pub guard_trips: usize,
    /// Per turn (rotate), per twist (twist), deg.
    pub per_cycle_deg: Vec<f64>,
    /// The achieved angle (see the module docs), deg.
    pub achieved_deg: Option<f64>,
    /// The achieved stroke (shake: sway, +-), mm.
    pub achieved_mm: Option<f64>,
}

/// Fingertip sideways displacement for a Dex joint bent by `deg`: a
/// constant-curvature arc of the actuator's length, then the fingertip
/// along the bent axis, mm.
pub fn fingertip_sway_mm(deg: f64) -> f64 {
    use dexitac_gripper::kinematics::{arc, translation};
    let bend = arc(ACTUATOR_LENGTH_MM, deg.to_radians(), 0.0);
    (bend * translation(0.0, 0.0, FINGERTIP_LENGTH_MM))
        .translation
        .vector
        .x
}

fn max_deg(trace: &[WorldState], from_ms: u64, to_ms: u64) -> Option<f64> {
    trace
        .iter()
        .filter(|s| (from_ms..to_ms).contains(&s.t_ms))
        .map(|s| s.object_deg)
        .reduce(f64::max)
}

fn min_deg(trace: &[WorldState], from_ms: u64, to_ms: u64) -> Option<f64> {
    trace
        .iter()
        .filter(|s| (from_ms..to_ms).contains(&s.t_ms))
        .map(|s| s.object_deg)
        .reduce(f64::min)
}

fn deg_at(trace: &[WorldState], t_ms: u64) -> Option<f64> {
    trace.iter().find(|s| s.t_ms >= t_ms).map(|s| s.object_deg)
}

/// Measures the task on the trace; `None` without a started task.
pub fn task_report(
    params: &TaskParams,
    events: Vec<(u64, TaskEvent)>,
    trace: &[WorldState],
) -> Option<TaskReport> {
    let first_ms = events.first()?.0;
    let end_ms = trace.last().map_or(first_ms, |s| s.t_ms + 1);
    let stopped_by_guard = events
        .iter()
        .any(|(_, e)| matches!(e, TaskEvent::Guard { stopped: true, .. }));
    let guard_trips = events
        .iter()
        .filter(|(_, e)| matches!(e, TaskEvent::Guard { .. }))
        .count();
    let completed = events.iter().any(|(_, e)| *e == TaskEvent::Completed);
    // Stroke starts: (time, drive), including the return a guard commands.
    let starts: Vec<(u64, Drive)> = events
        .iter()
        .filter(|(_, e)| {
            !matches!(
                e,
                TaskEvent::Completed | TaskEvent::Guard { stopped: true, .. }
            )
        })
        .map(|(t, e)| (*t, e.drive()))
        .collect();
    let forward: Vec<u64> = starts
        .iter()
        .filter(|(_, d)| *d == Drive::Forward)
        .map(|(t, _)| *t)
        .collect();
    let next_forward = |i: usize| forward.get(i + 1).copied().unwrap_or(end_ms);
    let next_start = |t: u64| {
        starts
            .iter()
            .map(|(s, _)| *s)
            .find(|s| *s > t)
            .unwrap_or(end_ms)
    };
    let mut per_cycle_deg = Vec::new();
    let (achieved_deg, achieved_mm) = match params.kind {
        TaskKind::Pour => (max_deg(trace, first_ms, end_ms), None),
        TaskKind::Rotate => {
            for (i, &t) in forward.iter().enumerate() {
                if let (Some(peak), Some(at)) =
                    (max_deg(trace, t, next_forward(i)), deg_at(trace, t))
                {
                    per_cycle_deg.push(peak - at);
                }
            }
            let mean = (!per_cycle_deg.is_empty())
                .then(|| per_cycle_deg.iter().sum::<f64>() / per_cycle_deg.len() as f64);
            (mean, None)
        }
        TaskKind::Shake => {
            let from = starts.get(1).map_or(end_ms, |(t, _)| *t);
            let amplitude = max_deg(trace, from, end_ms)
                .zip(min_deg(trace, from, end_ms))
                .map(|(hi, lo)| (hi - lo) / 2.0);
            (amplitude, amplitude.map(|a| fingertip_sway_mm(a).abs()))
        }
        TaskKind::Twist => {
            for &t in &forward {
                if let Some(peak) = max_deg(trace, t, next_start(t).saturating_add(500)) {
                    per_cycle_deg.push(peak);
                }
            }
            (per_cycle_deg.iter().copied().reduce(f64::max), None)
        }
    };
    Some(TaskReport {
        kind: params.kind,
        gripper: params.gripper_name().to_string(),
        events,
        completed,
        stopped_by_guard,
        guard_trips,
        per_cycle_deg,
        achieved_deg,
        achieved_mm,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sway_is_zero_straight_and_grows_with_the_bend() {
        assert!(fingertip_sway_mm(0.0).abs() < 1e-12);
        let a = fingertip_sway_mm(10.0);
        let b = fingertip_sway_mm(20.0);
        assert!(a > 0.0 && b > a, "{a} {b}");
        // Small angles: arc sag L*theta/2 plus the fingertip's L*theta.
        let t = 1f64.to_radians();
        let expected = ACTUATOR_LENGTH_MM * t / 2.0 + FINGERTIP_LENGTH_MM * t;
        assert!((fingertip_sway_mm(1.0) - expected).abs() < 1e-2);
    }
}
