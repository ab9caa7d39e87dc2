//! Tactile-guarded manipulation primitives (paper Sec. V-D, Fig. 11):
//! pour (HookGrip), rotate (SupportGrip), shake (ClosureGrip) and twist
//! (PinchGrip).
//!
//! Each primitive is a small state machine ([`Primitive`]) that starts once
//! the grasp is stable and sealed, then drives the *manipulation joint* of
//! both fingers: the two side bellows of each Dex joint
//! ([`MANIPULATION_CHAMBERS`]), one inflated and the other deflated
//! ([`Drive::Forward`]), the reverse ([`Drive::Backward`]), or both sealed
//! ([`Drive::Hold`]). It is fed the contact centres of both sensors and the
//! clock, and decides from time (stroke lengths) and from its tactile guard:
//!
//! | task | motion | guard (pure function) | on trip |
//! | --- | --- | --- | --- |
//! | pour | one forward tilt of `stroke_ms` | [`grasp_unstable`]: a centre moved more than `shift_limit_mm` from where it was at the start, or lost its contact | stop (hold) |
//! | rotate | `cycles` forward turns of `stroke_ms`, `pause_ms` apart | [`grasp_unstable`] | stop (hold) |
//! | shake | `cycles` forward + backward strokes of `stroke_ms` | [`x_shift_exceeded`]: a centre's x moved more than `shift_limit_mm` | stop (hold) |
//! | twist | forward until [`near_edge`] (or `stroke_ms`), return for `pause_ms`, `cycles` times | [`near_edge`]: a centre's \|x\| reached `edge_x_mm` | return, then repeat |
//!
//! The twist returns by venting both chambers of the joint
//! ([`Drive::Relax`]): the pressure difference, and with it the joint
//! angle, decays toward zero, the original grasping position, however far
//! the twist went (there is no angle sensor; a timed backward stroke would
//! overshoot).
//!
//! The primitive is part of the host's task loop (`dexitac_rig::task_loop`), so
//! the same code runs on the simulated and on the real rig. While it runs it
//! owns the grasp: the grasp state machine is no longer fed (the moving
//! object shifts the contact centres by design); the guards above take its
//! place.

use serde::Deserialize;

use crate::grasp::{CentreMm, SENSOR_COUNT};

/// The manipulation joint's chamber pair of each finger: (forward, backward).
/// The Dex joint's side bellows (chambers 2/3 and 6/7), which a two-finger
/// grasp leaves sealed (`dexitac_rig::task_loop::DEFAULT_GRASP_CHAMBERS`).
pub const MANIPULATION_CHAMBERS: [[usize; 2]; SENSOR_COUNT] = [[2, 3], [6, 7]];

/// The four tasks of the paper.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TaskKind {
    /// Ball pouring with HookGrip.
    Pour,
    /// Rubik's cube rotating with SupportGrip.
    Rotate,
    /// Dye mixing (shaking) with ClosureGrip.
    Shake,
    /// Cap twisting with PinchGrip.
    Twist,
}

impl TaskKind {
    /// Lower-case name.
    pub const fn name(self) -> &'static str {
        match self {
            TaskKind::Pour => "pour",
            TaskKind::Rotate => "rotate",
            TaskKind::Shake => "shake",
            TaskKind::Twist => "twist",
        }
    }

    /// The gripper configuration the paper uses for it.
    pub const fn paper_gripper(self) -> crate::configuration::Preset {
        use crate::configuration::Preset;
        match self {
            TaskKind::Pour => Preset::HookGrip,
            TaskKind::Rotate => Preset::SupportGrip,
            TaskKind::Shake => Preset::ClosureGrip,
            TaskKind::Twist => Preset::PinchGrip,
        }
    }

    /// The paper's measured angle (ArUco marker), deg: pour angle, mean per
    /// rotation, shake amplitude (+-), maximum twist.
    pub const fn paper_deg(self) -> f64 {
        match self {
            TaskKind::Pour => 47.5,
            TaskKind::Rotate => 14.5,
            TaskKind::Shake => 22.6,
            TaskKind::Twist => 25.2,
        }
    }

    /// The paper's measured stroke, mm (shake: horizontal sway, +-).
    pub const fn paper_mm(self) -> Option<f64> {
        match self {
            TaskKind::Shake => Some(13.0),
            _ => None,
        }
    }
}

/// A primitive's settings (the `[task]` table of a scenario).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskParams {
    /// Which task.
    pub kind: TaskKind,
    /// The gripper configuration (a preset name of [`crate::configuration`]);
    /// default: the paper's for this task.
    #[serde(default)]
    pub gripper: Option<String>,
    /// Length of one stroke (twist: the longest forward stroke), ms.
    pub stroke_ms: u64,
    /// Pause between turns (rotate); return time (twist), ms.
    #[serde(default)]
    pub pause_ms: u64,
    /// Turns (rotate), back-and-forth cycles (shake), twists (twist);
    /// ignored by pour.
    #[serde(default = "one")]
    pub cycles: u32,
    /// Guard of pour, rotate (centre shift) and shake (x shift), mm.
    #[serde(default = "default_shift_limit_mm")]
    pub shift_limit_mm: f64,
    /// Guard of twist: |x| of a centre at which it is near the edge, mm.
    #[serde(default = "default_edge_x_mm")]
    pub edge_x_mm: f64,
}

fn one() -> u32 {
    1
}
fn default_shift_limit_mm() -> f64 {
    3.0
}
fn default_edge_x_mm() -> f64 {
    9.0
}

impl TaskParams {
    /// Checks the ranges; `Err` names the field and what is allowed.
    pub fn validate(&self) -> Result<(), (&'static str, String, &'static str)> {
        if !(1..=600_000).contains(&self.stroke_ms) {
            return Err(("task.stroke_ms", self.stroke_ms.to_string(), "1..=600000"));
        }
        if self.pause_ms > 600_000 {
            return Err(("task.pause_ms", self.pause_ms.to_string(), "0..=600000"));
        }
        if !(1..=1_000).contains(&self.cycles) {
            return Err(("task.cycles", self.cycles.to_string(), "1..=1000"));
        }
        for (name, v) in [
            ("task.shift_limit_mm", self.shift_limit_mm),
            ("task.edge_x_mm", self.edge_x_mm),
        ] {
            if !(v.is_finite() && v > 0.0 && v < 1e3) {
                return Err((name, v.to_string(), "positive, finite, < 1000"));
            }
        }
        if let Some(g) = &self.gripper {
            if crate::configuration::Preset::from_name(g).is_none() {
                return Err((
                    "task.gripper",
                    g.clone(),
                    "hookgrip | supportgrip | closuregrip | pinchgrip",
                ));
            }
        }
        Ok(())
    }

    /// The gripper configuration's name.
    pub fn gripper_name(&self) -> &str {
        self.gripper
            .as_deref()
            .unwrap_or(self.kind.paper_gripper().name())
    }
}

/// What the manipulation joints do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Drive {
    /// Forward chamber inflated, backward chamber deflated.
    Forward,
    /// The reverse.
    Backward,
    /// Both sealed.
    Hold,
    /// Both vented to the negative tank: the joint relaxes to straight.
    Relax,
}

impl Drive {
    /// The valve states of the manipulation chambers of both fingers:
    /// (chamber, state) pairs.
    pub fn valves(self) -> [(usize, dexitac_protocol::ValveState); 2 * SENSOR_COUNT] {
        use dexitac_protocol::ValveState::{Deflate, Hold, Inflate};
        let (fwd, back) = match self {
            Drive::Forward => (Inflate, Deflate),
            Drive::Backward => (Deflate, Inflate),
            Drive::Hold => (Hold, Hold),
            Drive::Relax => (Deflate, Deflate),
        };
        let [[a0, b0], [a1, b1]] = MANIPULATION_CHAMBERS;
        [(a0, fwd), (b0, back), (a1, fwd), (b1, back)]
    }
}

/// Which guard tripped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GuardTrip {
    /// A centre moved `shift_mm` from its reference (or lost contact: `None`).
    Unstable {
        /// The sensor.
        sensor: usize,
        /// The shift, mm; `None`: contact lost.
        shift_mm: Option<f64>,
    },
    /// A centre's x moved `shift_mm` from its reference.
    XShift {
        /// The sensor.
        sensor: usize,
        /// |x - x_ref|, mm.
        shift_mm: f64,
    },
    /// A centre's |x| reached the edge threshold.
    NearEdge {
        /// The sensor.
        sensor: usize,
        /// x, mm.
        x_mm: f64,
    },
}

/// What a primitive reports, with the drive it commands from then on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TaskEvent {
    /// A stroke began (`n` from 0): forward, backward or a pause.
    Stroke {
        /// Stroke number.
        n: u32,
        /// Its drive.
        drive: Drive,
    },
    /// A guard tripped; `stopped`: the task ends here (pour, rotate, shake),
    /// otherwise it returns (twist).
    Guard {
        /// What tripped.
        trip: GuardTrip,
        /// The task ended.
        stopped: bool,
    },
    /// Every stroke done.
    Completed,
}

impl TaskEvent {
    /// The drive commanded from this event on.
    pub fn drive(&self) -> Drive {
        match self {
            TaskEvent::Stroke { drive, .. } => *drive,
            TaskEvent::Guard { stopped: false, .. } => Drive::Relax,
            TaskEvent::Guard { stopped: true, .. } | TaskEvent::Completed => Drive::Hold,
        }
    }
}

/// Pour/rotate guard: true when a sensor lost its contact or its centre
/// moved more than `limit_mm` (Euclidean) from its reference.
pub fn grasp_unstable(
    reference: [Option<CentreMm>; SENSOR_COUNT],
    now: [Option<CentreMm>; SENSOR_COUNT],
    limit_mm: f64,
) -> Option<GuardTrip> {
    for sensor in 0..SENSOR_COUNT {
        let Some(r) = reference[sensor] else { continue };
        match now[sensor] {
            None => {
                return Some(GuardTrip::Unstable {
                    sensor,
                    shift_mm: None,
                })
            }
            Some(c) => {
                let d = (c.x_mm - r.x_mm).hypot(c.y_mm - r.y_mm);
                if d.is_nan() || d > limit_mm {
                    return Some(GuardTrip::Unstable {
                        sensor,
                        shift_mm: Some(d),
                    });
                }
            }
        }
    }
    None
}

/// Shake guard: true when a sensor's centre x moved more than `limit_mm`
/// from its reference (the motion moves the centres along y; a growing x
/// shift means the object is working loose). A lost contact also trips.
pub fn x_shift_exceeded(
    reference: [Option<CentreMm>; SENSOR_COUNT],
    now: [Option<CentreMm>; SENSOR_COUNT],
    limit_mm: f64,
) -> Option<GuardTrip> {
    for sensor in 0..SENSOR_COUNT {
        let Some(r) = reference[sensor] else { continue };
        let shift_mm = now[sensor].map_or(f64::INFINITY, |c| (c.x_mm - r.x_mm).abs());
        if shift_mm.is_nan() || shift_mm > limit_mm {
            return Some(GuardTrip::XShift { sensor, shift_mm });
        }
    }
    None
}

/// Twist guard: true when a sensor's centre is within reach of the sensor
/// edge, `|x| >= edge_x_mm`.
pub fn near_edge(now: [Option<CentreMm>; SENSOR_COUNT], edge_x_mm: f64) -> Option<GuardTrip> {
    (0..SENSOR_COUNT).find_map(|sensor| {
        now[sensor]
            .filter(|c| c.x_mm.is_nan() || c.x_mm.abs() >= edge_x_mm)
            .map(|c| GuardTrip::NearEdge {
                sensor,
                x_mm: c.x_mm,
            })
    })
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// Not started.
    Idle,
    /// Stroke `n` since `since_ms`.
    Moving { n: u32, drive: Drive, since_ms: u64 },
    /// Finished (completed or stopped by a guard).
    Done,
}

/// A manipulation primitive's state machine (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct Primitive {
    params: TaskParams,
    phase: Phase,
    latest: [Option<CentreMm>; SENSOR_COUNT],
    reference: [Option<CentreMm>; SENSOR_COUNT],
}

impl Primitive {
    /// A primitive, not started.
    pub fn new(params: TaskParams) -> Self {
        Primitive {
            params,
            phase: Phase::Idle,
            latest: [None; SENSOR_COUNT],
            reference: [None; SENSOR_COUNT],
        }
    }

    /// Its settings.
    pub fn params(&self) -> &TaskParams {
        &self.params
    }

    /// Started and not finished.
    pub fn running(&self) -> bool {
        matches!(self.phase, Phase::Moving { .. })
    }

    /// Finished.
    pub fn done(&self) -> bool {
        self.phase == Phase::Done
    }

    /// Starts at `t_ms` (the grasp is stable): the latest centres become
    /// the guards' reference; the first stroke begins.
    pub fn start(&mut self, t_ms: u64) -> Option<TaskEvent> {
        if self.phase != Phase::Idle {
            return None;
        }
        self.reference = self.latest;
        Some(self.stroke(0, Drive::Forward, t_ms))
    }

    fn stroke(&mut self, n: u32, drive: Drive, t_ms: u64) -> TaskEvent {
        self.phase = Phase::Moving {
            n,
            drive,
            since_ms: t_ms,
        };
        TaskEvent::Stroke { n, drive }
    }

    fn finish(&mut self, event: TaskEvent) -> Option<TaskEvent> {
        self.phase = Phase::Done;
        Some(event)
    }

    /// A sensor's contact centre at `t_ms`; guards are checked while moving.
    pub fn observe(
        &mut self,
        sensor: usize,
        t_ms: u64,
        centre: Option<CentreMm>,
    ) -> Option<TaskEvent> {
        let slot = self.latest.get_mut(sensor)?;
        *slot = centre;
        let Phase::Moving { n, drive, .. } = self.phase else {
            return None;
        };
        // A sensor with no centre at the start takes its first one.
        if let Some(r) = self.reference.get_mut(sensor) {
            if r.is_none() {
                *r = centre;
            }
        }
        let p = &self.params;
        match p.kind {
            TaskKind::Pour | TaskKind::Rotate => {
                let trip = grasp_unstable(self.reference, self.latest, p.shift_limit_mm)?;
                self.finish(TaskEvent::Guard {
                    trip,
                    stopped: true,
                })
            }
            TaskKind::Shake => {
                let trip = x_shift_exceeded(self.reference, self.latest, p.shift_limit_mm)?;
                self.finish(TaskEvent::Guard {
                    trip,
                    stopped: true,
                })
            }
            TaskKind::Twist if drive == Drive::Forward => {
                let trip = near_edge(self.latest, p.edge_x_mm)?;
                self.stroke(n + 1, Drive::Relax, t_ms);
                Some(TaskEvent::Guard {
                    trip,
                    stopped: false,
                })
            }
            TaskKind::Twist => None,
        }
    }

    /// Time-driven steps: the end of a stroke or pause.
    pub fn tick(&mut self, t_ms: u64) -> Option<TaskEvent> {
        let Phase::Moving { n, drive, since_ms } = self.phase else {
            return None;
        };
        let elapsed = t_ms.saturating_sub(since_ms);
        let p = &self.params;
        let (stroke, pause, cycles) = (p.stroke_ms, p.pause_ms, p.cycles);
        match p.kind {
            TaskKind::Pour => (elapsed >= stroke).then(|| self.finish(TaskEvent::Completed))?,
            TaskKind::Rotate => {
                // Strokes: turn, pause, turn, ... (2 * cycles - 1 of them).
                let limit = if drive == Drive::Hold { pause } else { stroke };
                if elapsed < limit {
                    return None;
                }
                let turns_done = n / 2 + 1;
                if drive == Drive::Forward && turns_done >= cycles {
                    return self.finish(TaskEvent::Completed);
                }
                let next = if drive == Drive::Forward {
                    Drive::Hold
                } else {
                    Drive::Forward
                };
                Some(self.stroke(n + 1, next, t_ms))
            }
            TaskKind::Shake => {
                if elapsed < stroke {
                    return None;
                }
                if n + 1 >= 2 * cycles {
                    return self.finish(TaskEvent::Completed);
                }
                let next = if drive == Drive::Forward {
                    Drive::Backward
                } else {
                    Drive::Forward
                };
                Some(self.stroke(n + 1, next, t_ms))
            }
            TaskKind::Twist => match drive {
                // No edge within the longest stroke: return anyway.
                Drive::Forward if elapsed >= stroke => Some(self.stroke(n + 1, Drive::Relax, t_ms)),
                Drive::Forward => None,
                _ if elapsed >= pause => {
                    let twists_done = n / 2 + 1;
                    if twists_done >= cycles {
                        return self.finish(TaskEvent::Completed);
                    }
                    Some(self.stroke(n + 1, Drive::Forward, t_ms))
                }
                _ => None,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn c(x_mm: f64, y_mm: f64) -> Option<CentreMm> {
        Some(CentreMm { x_mm, y_mm })
    }

    fn params(kind: TaskKind) -> TaskParams {
        TaskParams {
            kind,
            gripper: None,
            stroke_ms: 1_000,
            pause_ms: 500,
            cycles: 2,
            shift_limit_mm: 2.0,
            edge_x_mm: 8.0,
        }
    }

    /// Ticks every 10 ms from `from` to `to`, feeding `centre` to both
    /// sensors; returns the events with their times.
    fn run(
        p: &mut Primitive,
        from: u64,
        to: u64,
        centre: impl Fn(u64) -> Option<CentreMm>,
    ) -> Vec<(u64, TaskEvent)> {
        let mut out = Vec::new();
        for t in (from..=to).step_by(10) {
            for s in 0..SENSOR_COUNT {
                if let Some(e) = p.observe(s, t, centre(t)) {
                    out.push((t, e));
                }
            }
            if let Some(e) = p.tick(t) {
                out.push((t, e));
            }
        }
        out
    }

    #[test]
    fn guards_are_pure_threshold_tests() {
        let r = [c(0.0, 0.0), c(1.0, 1.0)];
        assert_eq!(grasp_unstable(r, [c(1.0, 1.0), c(1.0, 2.0)], 2.0), None);
        assert!(matches!(
            grasp_unstable(r, [c(0.0, 0.0), c(1.0, 3.5)], 2.0),
            Some(GuardTrip::Unstable { sensor: 1, .. })
        ));
        assert!(matches!(
            grasp_unstable(r, [None, c(1.0, 1.0)], 2.0),
            Some(GuardTrip::Unstable {
                sensor: 0,
                shift_mm: None
            })
        ));
        // A large y motion is fine for shake; an x shift is not.
        assert_eq!(x_shift_exceeded(r, [c(0.5, 9.0), c(1.0, -9.0)], 1.0), None);
        assert!(x_shift_exceeded(r, [c(0.0, 0.0), c(2.5, 1.0)], 1.0).is_some());
        assert!(x_shift_exceeded(r, [c(0.0, 0.0), c(f64::NAN, 1.0)], 1.0).is_some());
        assert_eq!(near_edge([c(7.9, 20.0), c(-7.9, 0.0)], 8.0), None);
        assert!(matches!(
            near_edge([c(0.0, 0.0), c(-8.0, 0.0)], 8.0),
            Some(GuardTrip::NearEdge { sensor: 1, .. })
        ));
    }

    #[test]
    fn pour_tilts_once_and_completes_with_a_steady_grasp() {
        let mut p = Primitive::new(params(TaskKind::Pour));
        p.observe(0, 0, c(1.0, 1.0));
        p.observe(1, 0, c(1.0, 1.0));
        assert_eq!(
            p.start(0),
            Some(TaskEvent::Stroke {
                n: 0,
                drive: Drive::Forward
            })
        );
        let ev = run(&mut p, 10, 2_000, |t| c(1.0, 1.0 + t as f64 * 1e-3));
        assert_eq!(ev, vec![(1_000, TaskEvent::Completed)]);
        assert!(p.done());
    }

    #[test]
    fn pour_stops_when_the_grasp_moves() {
        let mut p = Primitive::new(params(TaskKind::Pour));
        p.observe(0, 0, c(0.0, 0.0));
        p.observe(1, 0, c(0.0, 0.0));
        p.start(0);
        let ev = run(&mut p, 10, 2_000, |t| c(0.0, t as f64 * 5e-3));
        assert_eq!(ev.len(), 1);
        assert!(matches!(
            ev[0],
            (410, TaskEvent::Guard { stopped: true, .. })
        ));
        assert_eq!(ev[0].1.drive(), Drive::Hold);
    }

    #[test]
    fn rotate_turns_pauses_and_turns_again() {
        let mut p = Primitive::new(params(TaskKind::Rotate));
        p.start(0);
        let ev = run(&mut p, 10, 5_000, |_| c(0.0, 0.0));
        let drives: Vec<(u64, Drive)> = ev
            .iter()
            .filter_map(|(t, e)| match e {
                TaskEvent::Stroke { drive, .. } => Some((*t, *drive)),
                _ => None,
            })
            .collect();
        assert_eq!(drives, vec![(1_000, Drive::Hold), (1_500, Drive::Forward)]);
        assert_eq!(ev.last(), Some(&(2_500, TaskEvent::Completed)));
    }

    #[test]
    fn shake_alternates_then_completes_or_stops_on_x_shift() {
        let mut p = Primitive::new(params(TaskKind::Shake));
        p.start(0);
        // Centres swing along y only: all cycles.
        let ev = run(&mut p, 10, 6_000, |t| {
            c(0.0, ((t as f64) / 300.0).sin() * 5.0)
        });
        assert_eq!(ev.len(), 4);
        assert_eq!(ev.last(), Some(&(4_000, TaskEvent::Completed)));

        let mut p = Primitive::new(params(TaskKind::Shake));
        p.observe(0, 0, c(0.0, 0.0));
        p.observe(1, 0, c(0.0, 0.0));
        p.start(0);
        // x creeps 1 mm per second: the guard trips past 2 mm.
        let ev = run(&mut p, 10, 6_000, |t| c(t as f64 * 1e-3, 0.0));
        assert!(matches!(
            ev.last(),
            Some((
                2_010,
                TaskEvent::Guard {
                    trip: GuardTrip::XShift { .. },
                    stopped: true
                }
            ))
        ));
        assert!(p.done());
    }

    #[test]
    fn twist_returns_at_the_edge_and_repeats() {
        let mut p = Primitive::new(TaskParams {
            pause_ms: 1_500,
            ..params(TaskKind::Twist)
        });
        p.start(0);
        // x follows the twist: +10 mm/s forward, decays while relaxing.
        let x = std::cell::Cell::new(0.0);
        let mut events = Vec::new();
        for t in (10..=10_000).step_by(10) {
            match p.phase {
                Phase::Moving {
                    drive: Drive::Forward,
                    ..
                } => x.set(x.get() + 0.1),
                Phase::Moving {
                    drive: Drive::Relax,
                    ..
                } => x.set(x.get() * 0.97),
                _ => {}
            }
            for s in 0..SENSOR_COUNT {
                if let Some(e) = p.observe(s, t, c(x.get(), 0.0)) {
                    events.push(e);
                }
            }
            if let Some(e) = p.tick(t) {
                if matches!(e, TaskEvent::Stroke { n: 2, .. }) {
                    // Returned before twisting again.
                    assert!(x.get().abs() < 0.25, "x = {}", x.get());
                }
                events.push(e);
            }
        }
        let edges = events
            .iter()
            .filter(|e| matches!(e, TaskEvent::Guard { stopped: false, .. }))
            .count();
        assert_eq!(edges, 2, "{events:?}");
        assert_eq!(events.last(), Some(&TaskEvent::Completed));
        // Returned to where it started.
        assert!(x.get().abs() < 0.25, "x = {}", x.get());
    }

    #[test]
    fn bad_task_settings_are_named() {
        let bad = |f: fn(&mut TaskParams)| {
            let mut p = params(TaskKind::Shake);
            f(&mut p);
            p.validate().map(|_| ()).map_err(|(field, _, _)| field)
        };
        assert_eq!(bad(|_| {}), Ok(()));
        assert_eq!(bad(|p| p.stroke_ms = 0), Err("task.stroke_ms"));
        assert_eq!(bad(|p| p.cycles = 0), Err("task.cycles"));
        assert_eq!(
            bad(|p| p.shift_limit_mm = f64::NAN),
            Err("task.shift_limit_mm")
        );
        assert_eq!(bad(|p| p.edge_x_mm = -1.0), Err("task.edge_x_mm"));
        assert_eq!(
            bad(|p| p.gripper = Some("claw".into())),
            Err("task.gripper")
        );
        let text = "kind = \"stir\"\nstroke_ms = 10\n";
        assert!(toml::from_str::<TaskParams>(text).is_err());
        let text = "kind = \"twist\"\nstroke_ms = 10\nedge_mm = 3.0\n";
        assert!(toml::from_str::<TaskParams>(text).is_err());
    }

    fn centre() -> impl Strategy<Value = Option<CentreMm>> {
        proptest::option::of(
            (-30.0f64..30.0, -30.0f64..30.0).prop_map(|(x_mm, y_mm)| CentreMm { x_mm, y_mm }),
        )
    }

    proptest! {
        /// The guards trip exactly at their thresholds.
        #[test]
        fn guards_trip_exactly_past_their_limits(
            r0 in centre(), r1 in centre(), n0 in centre(), n1 in centre(),
            limit_mm in 0.1f64..10.0,
        ) {
            let (r, n) = ([r0, r1], [n0, n1]);
            let lost = (0..2).any(|s| r[s].is_some() && n[s].is_none());
            let shift = |s: usize, f: &dyn Fn(CentreMm, CentreMm) -> f64| {
                r[s].zip(n[s]).map_or(0.0, |(a, b)| f(a, b))
            };
            let dist = |a: CentreMm, b: CentreMm| (a.x_mm - b.x_mm).hypot(a.y_mm - b.y_mm);
            let dx = |a: CentreMm, b: CentreMm| (a.x_mm - b.x_mm).abs();
            let moved = (0..2).any(|s| shift(s, &dist) > limit_mm);
            let moved_x = (0..2).any(|s| shift(s, &dx) > limit_mm);
            prop_assert_eq!(grasp_unstable(r, n, limit_mm).is_some(), lost || moved);
            prop_assert_eq!(x_shift_exceeded(r, n, limit_mm).is_some(), lost || moved_x);
            let edge = n.iter().flatten().any(|c| c.x_mm.abs() >= limit_mm);
            prop_assert_eq!(near_edge(n, limit_mm).is_some(), edge);
            // A motion along y alone never trips the shake guard.
            let along_y = n.map(|c| c.map(|c| CentreMm { x_mm: 0.0, ..c }));
            let r_x0 = r.map(|c| c.map(|c| CentreMm { x_mm: 0.0, ..c }));
            prop_assert_eq!(
                x_shift_exceeded(r_x0, along_y, limit_mm).is_some(),
                (0..2).any(|s| r_x0[s].is_some() && along_y[s].is_none())
            );
        }

        /// Whatever the centres do, a primitive ends within its stroke
        /// budget and never commands a drive after it is done.
        #[test]
        fn every_primitive_ends_and_then_stays_quiet(
            kind in prop_oneof![
                Just(TaskKind::Pour), Just(TaskKind::Rotate),
                Just(TaskKind::Shake), Just(TaskKind::Twist)
            ],
            xs in proptest::collection::vec(-20.0f64..20.0, 1..50),
        ) {
            let mut p = Primitive::new(params(kind));
            p.start(0);
            let end = run(&mut p, 10, 20_000, |t| {
                c(xs[(t / 10) as usize % xs.len()], 0.0)
            });
            prop_assert!(p.done(), "{end:?}");
            let after = run(&mut p, 20_010, 21_000, |_| c(0.0, 0.0));
            prop_assert!(after.is_empty());
        }
    }
}
