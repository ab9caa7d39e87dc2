//! The dashboard's state, fed one [`RuntimeEvent`] at a time.
//!
//! [`Dashboard::apply`] only stores: the latest frame, markers and contact
//! of each fingertip, the contact centre's trail (working px, the last
//! [`DashboardConfig::trail_s`]), the centre's shift from its anchor (mm),
//! the telemetry (tank pressures, valves, pumps) and the grasp phase over
//! the last [`DashboardConfig::history_s`]. Time is the events' own clock
//! (ms); the dashboard's "now" is the latest time seen, so a replay or an
//! accelerated simulation draws the same charts as a live run.
//! [`Dashboard::render`](crate::draw) draws it.
//!
//! The density heatmap is the density relative to a rest reference: the
//! sensor's [`Calibration`] when the caller has it
//! ([`Dashboard::set_calibration`]), otherwise the first observation's
//! markers (in the simulator the fingers start open: that frame is at rest).

use std::collections::VecDeque;
use std::sync::Arc;

use dexitac_protocol::{ArmState, Chambers, HostMsg, Telemetry, NO_READING_PA};

use dexitac_gripper::grasp::{Cause, CentreMm, Command, Decision, GraspParams, SENSOR_COUNT};
use dexitac_gripper::manipulation::{GuardTrip, TaskEvent};
use dexitac_rig::event::{RuntimeEvent, StopReason};
use dexitac_tactile::calibrate::{sensing_mask, Calibration};
use dexitac_tactile::contact::Contact;
use dexitac_tactile::density::{self, DensityMap, DensitySetup};
use dexitac_tactile::frame::GreyFrame;
use dexitac_tactile::params::{DensityMode, Params};
use dexitac_tactile::PointPx;

/// Default strip-chart window, s.
pub const DEFAULT_HISTORY_S: f64 = 20.0;
/// Default length of the contact centre's trail, s.
pub const DEFAULT_TRAIL_S: f64 = 3.0;

/// What the dashboard shows and how.
#[derive(Debug, Clone)]
pub struct DashboardConfig {
    /// Time span of the strip charts, s.
    pub history_s: f64,
    /// Time span of the contact centre's trail, s.
    pub trail_s: f64,
    /// Pipeline parameters (frame size, mm per px, density kernel).
    pub params: Params,
    /// Algorithm 1 thresholds (T1, T2 on the shift chart).
    pub grasp: GraspParams,
    /// Shown at the top left.
    pub title: String,
}

impl Default for DashboardConfig {
    fn default() -> Self {
        DashboardConfig {
            history_s: DEFAULT_HISTORY_S,
            trail_s: DEFAULT_TRAIL_S,
            params: Params::default(),
            grasp: GraspParams::default(),
            title: "DEXITAC".into(),
        }
    }
}

/// Where the grasp is, as the events tell it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GraspPhase {
    /// Nothing happened yet.
    Idle,
    /// Tanks charging (after setup).
    Charging,
    /// Fingers closing, waiting for a stable contact.
    Closing,
    /// Valves sealed on a stable grasp.
    Holding,
    /// Inflation reopened after a disturbance.
    Reinforcing,
    /// Fingers opened (slip, lost contact or no contact).
    Released,
    /// A manipulation primitive is running.
    Manipulating,
    /// The manipulation primitive completed.
    TaskDone,
    /// A manipulation guard stopped the task.
    GuardStop,
    /// The loop stopped (sealed and disarmed).
    Stopped,
    /// The loop stopped on an error.
    Failed,
}

impl GraspPhase {
    /// Upper-case name (the dashboard's font).
    pub fn name(self) -> &'static str {
        match self {
            GraspPhase::Idle => "IDLE",
            GraspPhase::Charging => "CHARGING",
            GraspPhase::Closing => "CLOSING",
            GraspPhase::Holding => "HOLDING",
            GraspPhase::Reinforcing => "REINFORCING",
            GraspPhase::Released => "RELEASED",
            GraspPhase::Manipulating => "MANIPULATING",
            GraspPhase::TaskDone => "TASK DONE",
            GraspPhase::GuardStop => "GUARD STOP",
            GraspPhase::Stopped => "STOPPED",
            GraspPhase::Failed => "FAILED",
        }
    }
}

/// One telemetry report, in display units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TelemetrySample {
    /// When it arrived, ms.
    pub t_ms: u64,
    /// Positive tank, kPa (`None`: no reading).
    pub positive_kpa: Option<f64>,
    /// Negative tank, kPa (`None`: no reading).
    pub negative_kpa: Option<f64>,
    /// Valve state of every chamber.
    pub valves: Chambers,
    /// Positive and negative pump running.
    pub pumps_on: [bool; 2],
    /// The MCU's safety state.
    pub arm: ArmState,
}

impl TelemetrySample {
    /// Converts a report (gauge Pa to kPa; [`NO_READING_PA`] to `None`).
    pub fn new(t_ms: u64, t: &Telemetry) -> Self {
        let kpa = |pa: i32| (pa != NO_READING_PA).then(|| f64::from(pa) / 1e3);
        TelemetrySample {
            t_ms,
            positive_kpa: kpa(t.positive_tank_pa),
            negative_kpa: kpa(t.negative_tank_pa),
            valves: t.chambers,
            pumps_on: [t.positive_pump_on, t.negative_pump_on],
            arm: t.state,
        }
    }
}

/// The rest reference of the density heatmap.
#[derive(Debug, Clone)]
pub(crate) struct RestRef {
    /// The fast density setup the view uses.
    pub setup: DensitySetup,
    /// Rest density on `setup.grid()`.
    pub density: DensityMap,
    /// Sensing area ([`sensing_mask`], the calibration's rule).
    pub mask: Vec<bool>,
}

impl RestRef {
    /// A reference from rest markers on a `width x height` working frame.
    fn from_markers(markers: &[PointPx], width: usize, height: usize, params: &Params) -> Self {
        let setup = view_setup(width, height, params);
        let density = density::estimate(markers, &setup, None);
        let mask = sensing_mask(&density.values_per_mm2);
        RestRef {
            setup,
            density,
            mask,
        }
    }
}

/// The fast density path on the view's grid (the exact path is a
/// reference, far too slow to redraw 30 times a second).
fn view_setup(width: usize, height: usize, params: &Params) -> DensitySetup {
    DensitySetup {
        width,
        height,
        h_px: params.density.kernel_width_px,
        mm_per_px: params.frame.mm_per_px,
        mode: DensityMode::Fast,
        step_px: params.density.grid_step_px.max(1) as usize,
        truncate_sigmas: params.density.truncate_sigmas,
        skin: None,
    }
}

/// One fingertip's latest state and history.
#[derive(Debug, Clone, Default)]
pub(crate) struct SensorView {
    /// Observations received.
    pub frames: u64,
    /// The latest working frame (when the events carry frames).
    pub frame: Option<Arc<GreyFrame>>,
    /// The latest markers, working px.
    pub markers: Arc<Vec<PointPx>>,
    /// The latest contact.
    pub contact: Option<Contact>,
    /// The latest contact centre, mm.
    pub centre_mm: Option<CentreMm>,
    /// Contact centres, working px (`None`: no contact then), oldest first.
    pub trail: VecDeque<(u64, Option<PointPx>)>,
    /// Centre shift from the anchor, mm (`None`: no contact), oldest first.
    pub shift: VecDeque<(u64, Option<f64>)>,
    /// The shift chart's anchor: the centre at the last seal, else the
    /// first centre of the current contact.
    pub anchor: Option<CentreMm>,
    /// Capture time of the latest frame, ms.
    pub last_t_ms: Option<u64>,
    /// Frames per second of event time (smoothed).
    pub fps: Option<f64>,
    /// The latest pipeline time, ms.
    pub pipeline_ms: Option<f64>,
    /// Working frame size, px (from the frames or the calibration).
    pub size_px: Option<(usize, usize)>,
    /// The heatmap's rest reference.
    pub rest: Option<RestRef>,
}

/// The live view's state (see the [module docs](self)).
#[derive(Debug, Clone)]
pub struct Dashboard {
    pub(crate) config: DashboardConfig,
    pub(crate) now_ms: Option<u64>,
    pub(crate) sensors: [SensorView; SENSOR_COUNT],
    pub(crate) telemetry: VecDeque<TelemetrySample>,
    pub(crate) phases: VecDeque<(u64, GraspPhase)>,
    pub(crate) last_decision: Option<(u64, String)>,
    pub(crate) task: Option<(u64, String)>,
    pub(crate) tank_targets_kpa: Option<(f64, f64)>,
    pub(crate) stopped: Option<String>,
    pub(crate) events: u64,
}

impl Dashboard {
    /// An empty dashboard.
    pub fn new(config: DashboardConfig) -> Self {
        Dashboard {
            config,
            now_ms: None,
            sensors: Default::default(),
            telemetry: VecDeque::new(),
            phases: VecDeque::new(),
            last_decision: None,
            task: None,
            tank_targets_kpa: None,
            stopped: None,
            events: 0,
        }
    }

    /// The settings.
    pub fn config(&self) -> &DashboardConfig {
        &self.config
    }

    /// Uses `cal` (a sensor's rest calibration) as that sensor's heatmap
    /// reference; unknown sensors are ignored.
    pub fn set_calibration(&mut self, sensor: usize, cal: &Calibration) {
        let Some(s) = self.sensors.get_mut(sensor) else {
            return;
        };
        let rest = if cal.density.mode == DensityMode::Fast {
            RestRef {
                setup: cal.density,
                density: cal.rest_density.clone(),
                mask: cal.mask.clone(),
            }
        } else {
            RestRef::from_markers(
                &cal.rest_markers,
                cal.width,
                cal.height,
                &self.config.params,
            )
        };
        s.size_px.get_or_insert((cal.width, cal.height));
        s.rest = Some(rest);
    }

    /// The latest event time, ms (`None` before the first event).
    pub fn now_ms(&self) -> Option<u64> {
        self.now_ms
    }

    /// Events applied so far.
    pub fn events(&self) -> u64 {
        self.events
    }

    /// The current grasp phase.
    pub fn phase(&self) -> GraspPhase {
        self.phases.back().map_or(GraspPhase::Idle, |p| p.1)
    }

    /// The latest telemetry.
    pub fn telemetry(&self) -> Option<&TelemetrySample> {
        self.telemetry.back()
    }

    /// Sensor `sensor`'s latest contact.
    pub fn contact(&self, sensor: usize) -> Option<Contact> {
        self.sensors.get(sensor).and_then(|s| s.contact)
    }

    /// Records one event.
    pub fn apply(&mut self, event: &RuntimeEvent) {
        self.events += 1;
        match event {
            RuntimeEvent::Observation(r) => {
                self.advance(r.t_ms);
                self.observe(
                    r.sensor,
                    r.t_ms,
                    r.centre_mm,
                    &r.markers,
                    r.pipeline_ms,
                    r.contact,
                    r.frame.as_ref(),
                );
            }
            RuntimeEvent::Decision { t_ms, decision } => {
                self.advance(*t_ms);
                self.decide(*t_ms, decision);
            }
            RuntimeEvent::CommandSent {
                t_ms, msg, reason, ..
            } => {
                self.advance(*t_ms);
                if let HostMsg::SetTankTargets(targets) = msg {
                    self.tank_targets_kpa = Some((
                        f64::from(targets.positive_pa()) / 1e3,
                        f64::from(targets.negative_pa()) / 1e3,
                    ));
                }
                // Transitions no decision reports (the rest follow the
                // typed Decision and Task events).
                match *reason {
                    "setup" if self.phase() == GraspPhase::Idle => {
                        self.set_phase(*t_ms, GraspPhase::Charging)
                    }
                    "close fingers" => self.set_phase(*t_ms, GraspPhase::Closing),
                    "open-loop seal" => self.set_phase(*t_ms, GraspPhase::Holding),
                    _ => {}
                }
            }
            RuntimeEvent::Telemetry { t_ms, telemetry } => {
                self.advance(*t_ms);
                self.telemetry
                    .push_back(TelemetrySample::new(*t_ms, telemetry));
            }
            RuntimeEvent::Task { t_ms, event } => {
                self.advance(*t_ms);
                let (phase, text) = match event {
                    TaskEvent::Stroke { n, drive } => {
                        (GraspPhase::Manipulating, format!("STROKE {n} {drive:?}"))
                    }
                    TaskEvent::Guard {
                        trip,
                        stopped: true,
                    } => (
                        GraspPhase::GuardStop,
                        format!("GUARD STOP: {}", guard_text(trip)),
                    ),
                    TaskEvent::Guard {
                        trip,
                        stopped: false,
                    } => (
                        GraspPhase::Manipulating,
                        format!("GUARD RETURN: {}", guard_text(trip)),
                    ),
                    TaskEvent::Completed => (GraspPhase::TaskDone, "COMPLETED".to_string()),
                };
                self.set_phase(*t_ms, phase);
                self.task = Some((*t_ms, text.to_ascii_uppercase()));
            }
            RuntimeEvent::Stopped { t_ms, outcome, .. } => {
                self.advance(*t_ms);
                let (phase, text) = match outcome {
                    Ok(StopReason::Requested) => (GraspPhase::Stopped, "STOP REQUESTED".into()),
                    Ok(StopReason::FramesEnded) => (GraspPhase::Stopped, "FRAMES ENDED".into()),
                    Err(e) => (GraspPhase::Failed, e.clone()),
                };
                self.set_phase(*t_ms, phase);
                self.stopped = Some(text.to_ascii_uppercase());
            }
        }
        self.prune();
    }

    fn advance(&mut self, t_ms: u64) {
        self.now_ms = Some(self.now_ms.map_or(t_ms, |n| n.max(t_ms)));
    }

    /// Sets the grasp phase from `t_ms` on (for callers that know it
    /// without an event, e.g. `dexitac view` runs Algorithm 1 from t = 0).
    pub fn set_phase(&mut self, t_ms: u64, phase: GraspPhase) {
        if self.phase() != phase {
            self.phases.push_back((t_ms, phase));
        }
    }

    fn decide(&mut self, t_ms: u64, d: &Decision) {
        let (phase, text) = match (d.command, d.cause) {
            (Command::Seal, _) => (GraspPhase::Holding, "SEAL (STABLE)".to_string()),
            (Command::ReopenInflation, Cause::Disturbance { sensor, .. }) => (
                GraspPhase::Reinforcing,
                format!("DISTURBANCE ON {sensor}: REOPEN"),
            ),
            (Command::ReopenInflation, _) => (GraspPhase::Reinforcing, "REOPEN".to_string()),
            (Command::Release, Cause::Slip { sensor, .. }) => {
                (GraspPhase::Released, format!("SLIP ON {sensor}: RELEASE"))
            }
            (Command::Release, Cause::ContactLost { sensor }) => (
                GraspPhase::Released,
                format!("CONTACT LOST ON {sensor}: RELEASE"),
            ),
            (Command::Release, Cause::NoContact { sensor }) => (
                GraspPhase::Released,
                format!("NO CONTACT ON {sensor}: RELEASE"),
            ),
            (Command::Release, _) => (GraspPhase::Released, "RELEASE".to_string()),
        };
        if d.command == Command::Seal {
            // Algorithm 1: the centres at the seal become the anchors.
            for s in &mut self.sensors {
                s.anchor = s.centre_mm;
            }
        }
        self.set_phase(t_ms, phase);
        self.last_decision = Some((t_ms, text));
    }

    #[allow(clippy::too_many_arguments)]
    fn observe(
        &mut self,
        sensor: usize,
        t_ms: u64,
        centre_mm: Option<CentreMm>,
        markers: &Arc<Vec<PointPx>>,
        pipeline_ms: f64,
        contact: Option<Contact>,
        frame: Option<&Arc<GreyFrame>>,
    ) {
        let params = &self.config.params;
        let Some(s) = self.sensors.get_mut(sensor) else {
            return;
        };
        s.frames += 1;
        if let Some(last) = s.last_t_ms {
            let dt_ms = t_ms.saturating_sub(last) as f64;
            if dt_ms > 0.0 {
                let fps = 1e3 / dt_ms;
                s.fps = Some(s.fps.map_or(fps, |f| 0.8 * f + 0.2 * fps));
            }
        }
        s.last_t_ms = Some(t_ms);
        s.pipeline_ms = pipeline_ms.is_finite().then_some(pipeline_ms);
        if let Some(f) = frame {
            s.size_px = Some((f.width(), f.height()));
            s.frame = Some(Arc::clone(f));
        }
        s.markers = Arc::clone(markers);
        if s.rest.is_none() && !markers.is_empty() {
            let (w, h) = s.size_px.unwrap_or((
                params.frame.work_width_px as usize,
                params.frame.work_height_px as usize,
            ));
            s.rest = Some(RestRef::from_markers(markers, w, h, params));
        }
        let contact = contact.filter(|c| c.centre.is_finite() && c.area_mm2.is_finite());
        let centre_mm = centre_mm.filter(|c| c.x_mm.is_finite() && c.y_mm.is_finite());
        s.contact = contact;
        s.trail.push_back((t_ms, contact.map(|c| c.centre)));
        s.centre_mm = centre_mm;
        let shift = match centre_mm {
            Some(c) => {
                let anchor = *s.anchor.get_or_insert(c);
                Some(c.distance_mm(anchor))
            }
            None => {
                s.anchor = None;
                None
            }
        };
        s.shift.push_back((t_ms, shift));
    }

    /// Drops history older than the charts and trails show.
    fn prune(&mut self) {
        let Some(now) = self.now_ms else { return };
        let history_ms = secs_to_ms(self.config.history_s);
        let trail_ms = secs_to_ms(self.config.trail_s);
        let keep_from = now.saturating_sub(history_ms);
        // Keep one sample before the window: it gives the state at its start.
        prune_before(&mut self.telemetry, keep_from, |s| s.t_ms);
        prune_before(&mut self.phases, keep_from, |p| p.0);
        for s in &mut self.sensors {
            prune_before(&mut s.shift, keep_from, |p| p.0);
            prune_before(&mut s.trail, now.saturating_sub(trail_ms), |p| p.0);
        }
    }
}

fn guard_text(trip: &GuardTrip) -> String {
    match *trip {
        GuardTrip::Unstable {
            sensor,
            shift_mm: Some(mm),
        } => format!("{sensor} MOVED {mm:.1} MM"),
        GuardTrip::Unstable {
            sensor,
            shift_mm: None,
        } => format!("{sensor} LOST CONTACT"),
        GuardTrip::XShift { sensor, shift_mm } => format!("{sensor} X SHIFT {shift_mm:.1} MM"),
        GuardTrip::NearEdge { sensor, x_mm } => format!("{sensor} NEAR EDGE X {x_mm:+.1} MM"),
    }
}

/// Seconds to ms for a chart span (non-finite or negative: 0; capped at a day).
pub(crate) fn secs_to_ms(s: f64) -> u64 {
    if s.is_finite() && s > 0.0 {
        (s.min(86_400.0) * 1e3) as u64
    } else {
        0
    }
}

/// Removes entries while the next one is still at or before `t_ms` (the
/// last entry before the window stays: it is the state at the window's start).
fn prune_before<T>(q: &mut VecDeque<T>, t_ms: u64, time: impl Fn(&T) -> u64) {
    while q.len() >= 2 && q.get(1).is_some_and(|next| time(next) <= t_ms) {
        q.pop_front();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dexitac_protocol::ValveState;
    use dexitac_tactile::contact::Source;

    fn telemetry(pos_pa: i32) -> Telemetry {
        Telemetry {
            time_ms: 0,
            positive_tank_pa: pos_pa,
            negative_tank_pa: -40_000,
            chambers: [ValveState::Hold; 8],
            positive_pump_on: true,
            negative_pump_on: false,
            state: ArmState::Armed,
            faults: Default::default(),
            loop_overruns: 0,
        }
    }

    pub(crate) fn observation(sensor: usize, t_ms: u64, centre: Option<PointPx>) -> RuntimeEvent {
        RuntimeEvent::Observation(dexitac_rig::event::SensorReport {
            sensor,
            t_ms,
            centre_mm: centre.map(|c| CentreMm {
                x_mm: c.x * 0.1,
                y_mm: c.y * 0.1,
            }),
            markers: Arc::new(vec![PointPx::new(100.0, 100.0)]),
            pipeline_ms: 2.0,
            contact: centre.map(|c| Contact {
                centre: c,
                area_mm2: 10.0,
                source: Source::Density,
            }),
            frame: None,
        })
    }

    #[test]
    fn no_reading_is_a_gap_not_a_number() {
        let mut d = Dashboard::new(DashboardConfig::default());
        d.apply(&RuntimeEvent::Telemetry {
            t_ms: 5,
            telemetry: telemetry(NO_READING_PA),
        });
        let t = d.telemetry().copied().expect("sample");
        assert_eq!(t.positive_kpa, None);
        assert_eq!(t.negative_kpa, Some(-40.0));
    }

    #[test]
    fn history_is_pruned_to_the_window_keeping_the_state_at_its_start() {
        let mut d = Dashboard::new(DashboardConfig {
            history_s: 1.0,
            ..DashboardConfig::default()
        });
        for t in (0..5_000).step_by(20) {
            d.apply(&RuntimeEvent::Telemetry {
                t_ms: t,
                telemetry: telemetry(30_000),
            });
        }
        let first = d.telemetry.front().map(|s| s.t_ms).expect("kept");
        assert!(
            first <= 4_980 - 1_000 && first + 20 > 4_980 - 1_000,
            "{first}"
        );
        assert!(d.telemetry.len() <= 52);
    }

    #[test]
    fn decisions_and_commands_set_the_phase() {
        let mut d = Dashboard::new(DashboardConfig::default());
        assert_eq!(d.phase(), GraspPhase::Idle);
        let cmd = |t_ms, reason| RuntimeEvent::CommandSent {
            t_ms,
            msg: HostMsg::SealAll,
            reason,
            from_frame: None,
        };
        d.apply(&cmd(0, "setup"));
        assert_eq!(d.phase(), GraspPhase::Charging);
        d.apply(&cmd(100, "close fingers"));
        assert_eq!(d.phase(), GraspPhase::Closing);
        d.apply(&observation(0, 200, Some(PointPx::new(320.0, 240.0))));
        d.apply(&RuntimeEvent::Decision {
            t_ms: 300,
            decision: Decision {
                t_ms: 300,
                command: Command::Seal,
                cause: Cause::BothStable,
            },
        });
        assert_eq!(d.phase(), GraspPhase::Holding);
        assert!(d.sensors[0].anchor.is_some());
        d.apply(&RuntimeEvent::Decision {
            t_ms: 400,
            decision: Decision {
                t_ms: 400,
                command: Command::Release,
                cause: Cause::ContactLost { sensor: 1 },
            },
        });
        assert_eq!(d.phase(), GraspPhase::Released);
        assert_eq!(
            d.last_decision.as_ref().map(|x| x.1.as_str()),
            Some("CONTACT LOST ON 1: RELEASE")
        );
    }

    #[test]
    fn shift_is_measured_from_the_anchor_and_breaks_without_contact() {
        let mut d = Dashboard::new(DashboardConfig::default());
        d.apply(&observation(1, 0, Some(PointPx::new(0.0, 0.0))));
        d.apply(&observation(1, 33, Some(PointPx::new(30.0, 40.0))));
        d.apply(&observation(1, 66, None));
        let shifts: Vec<_> = d.sensors[1].shift.iter().map(|s| s.1).collect();
        assert_eq!(shifts.len(), 3);
        assert_eq!(shifts[0], Some(0.0));
        assert!((shifts[1].expect("contact") - 5.0).abs() < 1e-9);
        assert_eq!(shifts[2], None);
    }

    #[test]
    fn bad_input_is_ignored_not_stored() {
        let mut d = Dashboard::new(DashboardConfig::default());
        d.apply(&observation(7, 0, Some(PointPx::new(1.0, 1.0))));
        d.apply(&observation(0, 10, Some(PointPx::new(f64::NAN, 1.0))));
        d.apply(&RuntimeEvent::Observation(
            dexitac_rig::event::SensorReport {
                sensor: 0,
                t_ms: 20,
                centre_mm: Some(CentreMm {
                    x_mm: f64::INFINITY,
                    y_mm: 0.0,
                }),
                markers: Arc::new(vec![]),
                pipeline_ms: f64::NAN,
                contact: None,
                frame: None,
            },
        ));
        assert_eq!(d.contact(0), None);
        assert_eq!(d.sensors[0].centre_mm, None);
        assert_eq!(d.sensors[0].pipeline_ms, None);
        assert_eq!(d.events(), 3);
    }

    /// A sensor with no calibration gets its heatmap reference from its
    /// first markers, with the calibration's mask rule: a lattice that fills
    /// a few per cent of the frame is a sensing area, not nothing (the
    /// view's own rule took the 90th percentile over every cell, empty ones
    /// too, and found none where the lattice covered under a tenth).
    #[test]
    fn an_uncalibrated_sensor_gets_the_calibrations_mask() {
        let params = Params::default();
        let markers: Vec<PointPx> = (0..6)
            .flat_map(|j| {
                (0..6).map(move |i| {
                    let x = 300.0 + 15.0 * i as f64 + if j % 2 == 1 { 7.5 } else { 0.0 };
                    PointPx::new(x, 200.0 + 13.0 * j as f64)
                })
            })
            .collect();
        let rest = RestRef::from_markers(&markers, 640, 480, &params);
        let inside = rest.mask.iter().filter(|&&m| m).count();
        let cells = rest.mask.len();
        assert!(inside > 0, "no cell of the lattice is in the mask");
        assert!(
            10 * inside < cells,
            "{inside} of {cells} cells: the mask runs beyond the lattice"
        );
        assert_eq!(rest.mask, sensing_mask(&rest.density.values_per_mm2));
        // Every cell of it lies on the lattice (x 300-383 px, y 200-265 px).
        let grid = rest.setup.grid();
        for (k, _) in rest.mask.iter().enumerate().filter(|(_, &m)| m) {
            let p = grid.point_of(k);
            assert!(
                (285.0..400.0).contains(&p.x) && (185.0..280.0).contains(&p.y),
                "a mask cell at {p:?}, off the lattice"
            );
        }
    }
}
