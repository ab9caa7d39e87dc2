//! Grasp logic: the paper's Algorithm 1 as a pure state machine.
//!
//! Input: per-sensor observations (time in ms from an injected clock, the
//! contact centre in mm or "no contact"). Output: at most one [`Decision`]
//! per call — seal the valves, reopen inflation, or release. No I/O, no
//! sleeps: the runtime feeds it frames and sends the commands.
//!
//! # The rules (Algorithm 1, SPEC section 4)
//!
//! | phase | condition | decision |
//! | --- | --- | --- |
//! | closing | both sensors stable: in contact for the stable span (3 s) with every centre of that span inside a box of diagonal T1 = 0.5 mm | seal |
//! | closing | a sensor still without contact 10 s after closing began | release (no contact) |
//! | holding | frame-to-frame shift D or anchored shift A above T1 and both at most T2 = 5 mm | reopen inflation |
//! | holding, reinforcing | D or A above T2 | release (slip) |
//! | holding, reinforcing | contact lost | release (contact lost) |
//! | reinforcing | both sensors stable again | seal (new anchors) |
//!
//! **Frame-to-frame against anchored shift.** The paper's D compares
//! consecutive frames; it answers a poke within one frame, but a slow slip
//! moves the centre little per frame and never trips it. So each sensor
//! also holds an *anchor*, its centre when the grasp was sealed, and the
//! anchored shift A = |c(t) - anchor| raises the same events: a slow creep
//! past T1 is a disturbance and past T2 a slip. Both are reported in the
//! [`Cause`] so logs show which one fired.
//!
//! Two sensors are fused as the paper does: the grasp is stable only when
//! both are; either one can raise a disturbance or a slip.

use std::collections::VecDeque;

/// Stable grasp: contact centre moves less than T1 (Algorithm 1).
pub const STABLE_SHIFT_MM: f64 = 0.5;
/// Slip: contact centre moves more than T2 (Algorithm 1).
pub const SLIP_SHIFT_MM: f64 = 5.0;
/// Time span over which the centre must stay within T1 (Algorithm 1).
pub const STABLE_SPAN_MS: u64 = 3_000;
/// No contact within this time of finger closure means a failed grasp
/// (Algorithm 1).
pub const NO_CONTACT_TIMEOUT_MS: u64 = 10_000;

/// Number of tactile sensors (one per fingertip).
pub const SENSOR_COUNT: usize = crate::configuration::FINGER_COUNT;

/// Thresholds of Algorithm 1; [`Default`] uses the paper's values. The
/// `[grasp]` table of a rig config (any subset of the fields).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GraspParams {
    /// T1: a centre moving less than this over the stable span is stable,
    /// more is a disturbance, mm.
    pub stable_shift_mm: f64,
    /// T2: a shift above this is a slip, mm.
    pub slip_shift_mm: f64,
    /// The span over which a stable centre must stay within T1, ms.
    pub stable_span_ms: u64,
    /// Release when a sensor has no contact this long after closing began, ms.
    pub no_contact_timeout_ms: u64,
}

impl GraspParams {
    /// Checks the thresholds: positive and finite, T2 above T1, a span.
    pub fn validate(&self) -> Result<(), &'static str> {
        let positive = |v: f64| v.is_finite() && v > 0.0;
        if !positive(self.stable_shift_mm) || !positive(self.slip_shift_mm) {
            return Err("stable_shift_mm and slip_shift_mm must be positive");
        }
        if self.slip_shift_mm <= self.stable_shift_mm {
            return Err("slip_shift_mm (T2) must be above stable_shift_mm (T1)");
        }
        if self.stable_span_ms == 0 {
            return Err("stable_span_ms must be positive");
        }
        Ok(())
    }
}

impl Default for GraspParams {
    fn default() -> Self {
        GraspParams {
            stable_shift_mm: STABLE_SHIFT_MM,
            slip_shift_mm: SLIP_SHIFT_MM,
            stable_span_ms: STABLE_SPAN_MS,
            no_contact_timeout_ms: NO_CONTACT_TIMEOUT_MS,
        }
    }
}

/// A contact centre on the sensor surface, mm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CentreMm {
    /// x, mm.
    pub x_mm: f64,
    /// y, mm.
    pub y_mm: f64,
}

impl CentreMm {
    /// Euclidean distance to `other`, mm.
    pub fn distance_mm(self, other: CentreMm) -> f64 {
        (self.x_mm - other.x_mm).hypot(self.y_mm - other.y_mm)
    }

    fn is_finite(self) -> bool {
        self.x_mm.is_finite() && self.y_mm.is_finite()
    }
}

/// Algorithm 1's two shifts of one frame's contact centre, mm: the
/// frame-to-frame shift D from the previous frame's centre and the anchored
/// shift A from the anchor (the centre when the grasp was sealed). Each is 0
/// when there is no previous centre (first frame of a contact) or no anchor.
/// [`Grasp`] compares both with T1 and T2; `dexitac sim` writes them to its
/// time series.
///
/// ```
/// use dexitac_gripper::grasp::{shifts_mm, CentreMm};
/// let c = |x_mm| CentreMm { x_mm, y_mm: 0.0 };
/// assert_eq!(shifts_mm(c(1.0), Some(c(0.5)), Some(c(-1.0))), (0.5, 2.0));
/// assert_eq!(shifts_mm(c(1.0), None, None), (0.0, 0.0));
/// ```
pub fn shifts_mm(
    centre: CentreMm,
    previous: Option<CentreMm>,
    anchor: Option<CentreMm>,
) -> (f64, f64) {
    let from = |other: Option<CentreMm>| other.map_or(0.0, |o| centre.distance_mm(o));
    (from(previous), from(anchor))
}

/// What a sensor's pipeline reported for one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observation {
    /// Frame time from the injected clock, ms.
    pub t_ms: u64,
    /// The contact centre, or `None` when the frame shows no contact.
    pub centre_mm: Option<CentreMm>,
}

/// The command a decision asks the runtime to send.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Close every valve: hold the air in the actuators (stable grasp).
    Seal,
    /// Reopen the grasping inlet valves: more grip force (disturbance).
    ReopenInflation,
    /// Open the fingers (slip, lost contact or no contact).
    Release,
}

/// Why a decision was taken.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Cause {
    /// Both sensors stable over the stable span.
    BothStable,
    /// A shift above T1 and at most T2.
    Disturbance {
        /// The sensor that saw it.
        sensor: usize,
        /// Frame-to-frame shift D, mm.
        frame_shift_mm: f64,
        /// Shift from the anchor A, mm.
        anchored_shift_mm: f64,
    },
    /// A shift above T2.
    Slip {
        /// The sensor that saw it.
        sensor: usize,
        /// Frame-to-frame shift D, mm.
        frame_shift_mm: f64,
        /// Shift from the anchor A, mm.
        anchored_shift_mm: f64,
    },
    /// A sensor lost contact while the grasp was held.
    ContactLost {
        /// The sensor that lost contact.
        sensor: usize,
    },
    /// No contact on a sensor within the no-contact timeout of closing.
    NoContact {
        /// The first sensor without contact.
        sensor: usize,
    },
}

/// A decision of the state machine.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Decision {
    /// When it was taken (the time of the observation or tick), ms.
    pub t_ms: u64,
    /// What to send.
    pub command: Command,
    /// Why.
    pub cause: Cause,
}

/// Where the grasp is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Not grasping; waiting for [`Grasp::start`].
    Open,
    /// Fingers closing (inlets open) since `since_ms`, waiting for a stable contact.
    Closing {
        /// When closing began, ms.
        since_ms: u64,
    },
    /// Valves sealed on a stable grasp.
    Holding,
    /// Inflation reopened after a disturbance, waiting for a stable contact again.
    Reinforcing,
    /// Released; [`Grasp::start`] begins a regrasp.
    Released,
}

/// One sensor's contact history (Algorithm 1, process 1 or 2).
#[derive(Debug, Clone, Default)]
struct SensorTrack {
    /// Contact centres within the stable span, oldest first.
    window: VecDeque<(u64, CentreMm)>,
    /// When the current uninterrupted contact began.
    contact_since_ms: Option<u64>,
    /// The previous frame's centre.
    last: Option<CentreMm>,
    /// The centre when the grasp was last sealed.
    anchor: Option<CentreMm>,
    /// The latest frame time seen.
    last_t_ms: Option<u64>,
}

impl SensorTrack {
    /// Records a frame; returns (frame-to-frame shift, anchored shift) when in contact.
    fn record(&mut self, obs: Observation, span_ms: u64) -> Option<(f64, f64)> {
        self.last_t_ms = Some(obs.t_ms);
        let Some(centre) = obs.centre_mm else {
            self.window.clear();
            self.contact_since_ms = None;
            self.last = None;
            return None;
        };
        self.contact_since_ms.get_or_insert(obs.t_ms);
        let shifts = shifts_mm(centre, self.last, self.anchor);
        self.last = Some(centre);
        self.window.push_back((obs.t_ms, centre));
        while let Some(&(t, _)) = self.window.front() {
            if obs.t_ms.saturating_sub(t) > span_ms {
                self.window.pop_front();
            } else {
                break;
            }
        }
        Some(shifts)
    }

    /// In contact for at least the span, and the span's centres fit in a box
    /// of diagonal `max_shift_mm` (a box's diagonal bounds every distance
    /// between its points, so no two centres are further apart).
    fn is_stable(&self, now_ms: u64, span_ms: u64, max_shift_mm: f64) -> bool {
        let Some(since) = self.contact_since_ms else {
            return false;
        };
        if now_ms.saturating_sub(since) < span_ms {
            return false;
        }
        let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
        for (_, c) in &self.window {
            x0 = x0.min(c.x_mm);
            y0 = y0.min(c.y_mm);
            x1 = x1.max(c.x_mm);
            y1 = y1.max(c.y_mm);
        }
        (x1 - x0).hypot(y1 - y0) < max_shift_mm
    }

    fn has_had_contact_since(&self, since_ms: u64) -> bool {
        self.contact_since_ms.is_some_and(|t| t >= since_ms)
    }
}

/// Algorithm 1 for two fused sensors.
///
/// ```
/// use dexitac_gripper::grasp::{CentreMm, Command, Grasp, GraspParams, Observation};
/// let mut grasp = Grasp::new(GraspParams::default());
/// grasp.start(0);
/// let at = |t_ms| Observation { t_ms, centre_mm: Some(CentreMm { x_mm: 1.0, y_mm: 2.0 }) };
/// let mut sealed = None;
/// for t_ms in (0..=4_000).step_by(100) {
///     for sensor in 0..2 {
///         if let Some(d) = grasp.observe(sensor, at(t_ms)) {
///             sealed.get_or_insert(d);
///         }
///     }
/// }
/// let sealed = sealed.unwrap();
/// assert_eq!(sealed.command, Command::Seal);
/// assert_eq!(sealed.t_ms, 3_000);
/// ```
#[derive(Debug, Clone)]
pub struct Grasp {
    params: GraspParams,
    phase: Phase,
    sensors: [SensorTrack; SENSOR_COUNT],
}

impl Grasp {
    /// A grasp in [`Phase::Open`].
    pub fn new(params: GraspParams) -> Self {
        Grasp {
            params,
            phase: Phase::Open,
            sensors: Default::default(),
        }
    }

    /// The current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The thresholds in use.
    pub fn params(&self) -> &GraspParams {
        &self.params
    }

    /// The fingers began closing at `now_ms` (grasp or regrasp): forget the
    /// previous contact history.
    pub fn start(&mut self, now_ms: u64) {
        self.sensors = Default::default();
        self.phase = Phase::Closing { since_ms: now_ms };
    }

    /// Feeds one frame's result from `sensor` (0 or 1). Observations for an
    /// unknown sensor, with a non-finite centre, or older than that sensor's
    /// previous frame are ignored.
    pub fn observe(&mut self, sensor: usize, obs: Observation) -> Option<Decision> {
        let span_ms = self.params.stable_span_ms;
        let track = self.sensors.get_mut(sensor)?;
        if obs.centre_mm.is_some_and(|c| !c.is_finite())
            || track.last_t_ms.is_some_and(|t| obs.t_ms < t)
        {
            return None;
        }
        let shifts = track.record(obs, span_ms);
        let now = obs.t_ms;
        match self.phase {
            Phase::Open | Phase::Released => None,
            Phase::Closing { since_ms } => {
                self.settle(now).or_else(|| self.no_contact(now, since_ms))
            }
            Phase::Holding | Phase::Reinforcing => match shifts {
                None => Some(self.decide(now, Command::Release, Cause::ContactLost { sensor })),
                Some((frame_shift_mm, anchored_shift_mm)) => {
                    let worst = frame_shift_mm.max(anchored_shift_mm);
                    if worst > self.params.slip_shift_mm {
                        let cause = Cause::Slip {
                            sensor,
                            frame_shift_mm,
                            anchored_shift_mm,
                        };
                        Some(self.decide(now, Command::Release, cause))
                    } else if self.phase == Phase::Holding && worst > self.params.stable_shift_mm {
                        let cause = Cause::Disturbance {
                            sensor,
                            frame_shift_mm,
                            anchored_shift_mm,
                        };
                        Some(self.decide(now, Command::ReopenInflation, cause))
                    } else if self.phase == Phase::Reinforcing {
                        self.settle(now)
                    } else {
                        None
                    }
                }
            },
        }
    }

    /// Advances time without a frame: the no-contact timeout fires even if
    /// a camera stops delivering frames.
    pub fn tick(&mut self, now_ms: u64) -> Option<Decision> {
        match self.phase {
            Phase::Closing { since_ms } => self.no_contact(now_ms, since_ms),
            _ => None,
        }
    }

    /// Seals when both sensors are stable; the current centres become the anchors.
    fn settle(&mut self, now_ms: u64) -> Option<Decision> {
        let GraspParams {
            stable_span_ms,
            stable_shift_mm,
            ..
        } = self.params;
        let stable = self
            .sensors
            .iter()
            .all(|s| s.is_stable(now_ms, stable_span_ms, stable_shift_mm));
        if !stable {
            return None;
        }
        for s in &mut self.sensors {
            s.anchor = s.last;
        }
        Some(self.decide(now_ms, Command::Seal, Cause::BothStable))
    }

    fn no_contact(&mut self, now_ms: u64, since_ms: u64) -> Option<Decision> {
        if now_ms.saturating_sub(since_ms) < self.params.no_contact_timeout_ms {
            return None;
        }
        let sensor = self
            .sensors
            .iter()
            .position(|s| !s.has_had_contact_since(since_ms))?;
        Some(self.decide(now_ms, Command::Release, Cause::NoContact { sensor }))
    }

    fn decide(&mut self, t_ms: u64, command: Command, cause: Cause) -> Decision {
        if command == Command::ReopenInflation {
            // Stable again means stable for a whole span after the
            // disturbance: a small anchored creep can leave the old window
            // inside T1, which would reseal at once.
            for s in &mut self.sensors {
                s.window.retain(|&(t, _)| t >= t_ms);
                if s.contact_since_ms.is_some() {
                    s.contact_since_ms = Some(t_ms);
                }
            }
        }
        self.phase = match command {
            Command::Seal => Phase::Holding,
            Command::ReopenInflation => Phase::Reinforcing,
            Command::Release => Phase::Released,
        };
        Decision {
            t_ms,
            command,
            cause,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const FRAME_MS: u64 = 33;

    fn at(t_ms: u64, x_mm: f64, y_mm: f64) -> Observation {
        Observation {
            t_ms,
            centre_mm: Some(CentreMm { x_mm, y_mm }),
        }
    }

    /// Feeds both sensors the same centre track from `from_ms` to `to_ms`;
    /// returns every decision.
    fn run(
        grasp: &mut Grasp,
        from_ms: u64,
        to_ms: u64,
        centre: impl Fn(u64) -> Option<(f64, f64)>,
    ) -> Vec<Decision> {
        let mut out = Vec::new();
        let mut t = from_ms;
        while t <= to_ms {
            let obs = Observation {
                t_ms: t,
                centre_mm: centre(t).map(|(x_mm, y_mm)| CentreMm { x_mm, y_mm }),
            };
            for sensor in 0..SENSOR_COUNT {
                out.extend(grasp.observe(sensor, obs));
            }
            out.extend(grasp.tick(t));
            t += FRAME_MS;
        }
        out
    }

    fn sealed_grasp() -> (Grasp, u64) {
        let mut grasp = Grasp::new(GraspParams::default());
        grasp.start(0);
        let decisions = run(&mut grasp, 0, 3_500, |_| Some((0.0, 0.0)));
        assert_eq!(decisions.len(), 1, "{decisions:?}");
        assert_eq!(decisions[0].command, Command::Seal);
        (grasp, 3_500)
    }

    #[test]
    fn still_contact_on_both_sensors_seals_after_the_stable_span() {
        let (grasp, _) = sealed_grasp();
        assert_eq!(grasp.phase(), Phase::Holding);
    }

    #[test]
    fn one_stable_sensor_is_not_a_stable_grasp() {
        let mut grasp = Grasp::new(GraspParams::default());
        grasp.start(0);
        let mut decisions = Vec::new();
        for t in (0..6_000).step_by(FRAME_MS as usize) {
            decisions.extend(grasp.observe(0, at(t, 0.0, 0.0)));
            // Sensor 1 wobbles by 1 mm: never stable.
            decisions.extend(grasp.observe(1, at(t, (t / FRAME_MS % 2) as f64, 0.0)));
        }
        assert!(decisions.is_empty(), "{decisions:?}");
        assert!(matches!(grasp.phase(), Phase::Closing { .. }));
    }

    #[test]
    fn a_poke_between_t1_and_t2_reopens_inflation_then_reseals() {
        let (mut grasp, t0) = sealed_grasp();
        // A 2 mm jump, then still again at the new place.
        let decisions = run(&mut grasp, t0, t0 + 4_000, |_| Some((2.0, 0.0)));
        assert_eq!(decisions.len(), 2, "{decisions:?}");
        assert_eq!(decisions[0].command, Command::ReopenInflation);
        assert!(matches!(
            decisions[0].cause,
            Cause::Disturbance { frame_shift_mm, .. } if (frame_shift_mm - 2.0).abs() < 1e-9
        ));
        assert_eq!(decisions[1].command, Command::Seal);
        assert_eq!(grasp.phase(), Phase::Holding);
    }

    #[test]
    fn reinforcing_needs_a_fresh_stable_span_before_resealing() {
        let (mut grasp, t0) = sealed_grasp();
        // A slow creep of 0.6 mm over 4 s: the anchored shift passes T1 while
        // the last 3 s span only 0.45 mm (inside T1).
        let decisions = run(&mut grasp, t0, t0 + 9_000, |t| {
            Some(((t.saturating_sub(t0) as f64 / 4_000.0).min(1.0) * 0.6, 0.0))
        });
        assert_eq!(
            decisions[0].command,
            Command::ReopenInflation,
            "{decisions:?}"
        );
        let reseal = decisions.get(1).expect("resealed");
        assert_eq!(reseal.command, Command::Seal);
        assert!(
            reseal.t_ms >= decisions[0].t_ms + grasp.params().stable_span_ms,
            "{decisions:?}"
        );
    }

    #[test]
    fn a_shift_beyond_t2_releases() {
        let (mut grasp, t0) = sealed_grasp();
        let decisions = run(&mut grasp, t0, t0 + 100, |_| Some((6.0, 0.0)));
        assert_eq!(decisions.len(), 1);
        assert_eq!(decisions[0].command, Command::Release);
        assert!(matches!(decisions[0].cause, Cause::Slip { .. }));
    }

    #[test]
    fn a_slow_slip_is_caught_by_the_anchored_shift() {
        let (mut grasp, t0) = sealed_grasp();
        // 0.05 mm per frame: far below T1 frame to frame.
        let decisions = run(&mut grasp, t0, t0 + 10_000, |t| {
            Some(((t - t0) as f64 / FRAME_MS as f64 * 0.05, 0.0))
        });
        let first = decisions.first().expect("a decision");
        assert_eq!(first.command, Command::ReopenInflation);
        let Cause::Disturbance {
            frame_shift_mm,
            anchored_shift_mm,
            ..
        } = first.cause
        else {
            panic!("{first:?}");
        };
        assert!(frame_shift_mm < 0.5 && anchored_shift_mm > 0.5);
        let last = decisions.last().expect("a decision");
        assert_eq!(
            last.command,
            Command::Release,
            "creeping past T2 is a slip: {decisions:?}"
        );
    }

    #[test]
    fn losing_contact_while_holding_releases() {
        let (mut grasp, t0) = sealed_grasp();
        let decisions = run(&mut grasp, t0, t0 + 100, |_| None);
        assert_eq!(decisions[0].command, Command::Release);
        assert_eq!(decisions[0].cause, Cause::ContactLost { sensor: 0 });
    }

    #[test]
    fn no_contact_within_ten_seconds_releases() {
        let mut grasp = Grasp::new(GraspParams::default());
        grasp.start(1_000);
        let decisions = run(&mut grasp, 1_000, 12_000, |_| None);
        assert_eq!(decisions.len(), 1);
        assert_eq!(decisions[0].command, Command::Release);
        assert_eq!(decisions[0].cause, Cause::NoContact { sensor: 0 });
        assert!(decisions[0].t_ms >= 11_000 && decisions[0].t_ms < 11_000 + FRAME_MS);
    }

    #[test]
    fn the_timeout_fires_on_ticks_without_frames() {
        let mut grasp = Grasp::new(GraspParams::default());
        grasp.start(0);
        assert_eq!(grasp.tick(9_999), None);
        let d = grasp.tick(10_000).expect("timeout");
        assert_eq!(d.command, Command::Release);
    }

    #[test]
    fn stale_and_invalid_observations_are_ignored() {
        let (mut grasp, t0) = sealed_grasp();
        assert_eq!(grasp.observe(0, at(t0 - 1_000, 9.0, 9.0)), None);
        assert_eq!(grasp.observe(0, at(t0 + 1, f64::NAN, 0.0)), None);
        assert_eq!(grasp.observe(7, at(t0 + 1, 9.0, 9.0)), None);
        assert_eq!(grasp.phase(), Phase::Holding);
    }

    #[test]
    fn thresholds_come_from_params() {
        let params = GraspParams {
            stable_shift_mm: 3.0,
            ..GraspParams::default()
        };
        let mut grasp = Grasp::new(params);
        grasp.start(0);
        run(&mut grasp, 0, 3_500, |_| Some((0.0, 0.0)));
        // 2 mm is below this T1: no disturbance.
        let decisions = run(&mut grasp, 3_500, 4_000, |_| Some((2.0, 0.0)));
        assert!(decisions.is_empty(), "{decisions:?}");
    }

    /// A centre track built from segments — still, slow creep, a jump (a
    /// poke or a slip), lost contact — at a random frame period, so that
    /// runs reach every phase.
    fn track() -> impl Strategy<Value = Vec<(u64, Option<(f64, f64)>)>> {
        #[derive(Debug, Clone)]
        enum Segment {
            Still,
            Creep(f64),
            Jump(f64, f64),
            Lost,
        }
        let segment = prop_oneof![
            5 => Just(Segment::Still),
            2 => (-0.05..0.05f64).prop_map(Segment::Creep),
            2 => (-8.0..8.0f64, -8.0..8.0f64).prop_map(|(x, y)| Segment::Jump(x, y)),
            1 => Just(Segment::Lost),
        ];
        (
            20u64..80,
            proptest::collection::vec((segment, 1usize..150), 1..12),
        )
            .prop_map(|(dt, segments)| {
                let (mut x, mut y) = (0.0, 0.0);
                let mut out = Vec::new();
                for (segment, frames) in segments {
                    for i in 0..frames {
                        let centre = match segment {
                            Segment::Still => Some((x, y)),
                            Segment::Creep(v) => {
                                x += v;
                                Some((x, y))
                            }
                            Segment::Jump(dx, dy) => {
                                if i == 0 {
                                    x += dx;
                                    y += dy;
                                }
                                Some((x, y))
                            }
                            Segment::Lost => None,
                        };
                        out.push((dt, centre));
                    }
                }
                out
            })
    }

    proptest! {
        /// Whatever the two sensors report: a seal needs both sensors in
        /// contact for the stable span and is never followed by another seal
        /// without a reopen between; a reopen comes only from holding; a
        /// release is final until a new start; a shift beyond T2 while
        /// holding always releases.
        #[test]
        fn decisions_follow_algorithm_1(steps in track(), offset in proptest::option::of(-3.0..3.0f64)) {
            let params = GraspParams::default();
            let mut grasp = Grasp::new(params);
            grasp.start(0);
            let (mut t, mut last_command) = (0u64, None);
            let mut contact_since: [Option<u64>; 2] = [None, None];
            let mut previous: [Option<(f64, f64)>; 2] = [None, None];
            for (dt, c) in &steps {
                t += dt;
                // Sensor 1 sees the same object, shifted (or never in contact).
                let c1 = offset.and_then(|o| c.map(|(x, y)| (x + o, y - o)));
                for (sensor, c) in [(0usize, *c), (1, c1)] {
                    contact_since[sensor] = c.map(|_| contact_since[sensor].unwrap_or(t));
                    let jump = match (previous[sensor], c) {
                        (Some(a), Some(b)) => (a.0 - b.0).hypot(a.1 - b.1),
                        _ => 0.0,
                    };
                    previous[sensor] = c;
                    let obs = Observation { t_ms: t, centre_mm: c.map(|(x_mm, y_mm)| CentreMm { x_mm, y_mm }) };
                    let before = grasp.phase();
                    let decision = grasp.observe(sensor, obs);
                    if before == Phase::Holding && jump > params.slip_shift_mm {
                        prop_assert_eq!(decision.map(|d| d.command), Some(Command::Release));
                    }
                    let Some(d) = decision else { continue };
                    prop_assert!(before != Phase::Released && before != Phase::Open);
                    match d.command {
                        Command::Seal => {
                            prop_assert!(contact_since.iter().all(|s| s.is_some_and(|s| t - s >= params.stable_span_ms)));
                            prop_assert_ne!(last_command, Some(Command::Seal));
                        }
                        Command::ReopenInflation => prop_assert_eq!(before, Phase::Holding),
                        Command::Release => {}
                    }
                    last_command = Some(d.command);
                }
            }
        }
    }
}
