//! The whole simulated rig around the host's real task loop: a scenario in,
//! a [`SimReport`] out.
//!
//! [`run_scenario`] gives each fingertip a rendered frame source
//! ([`crate::render`]) and a pipeline calibrated on its rest frames, connects
//! the normal [`dexitac_rig::link::Link`] to a simulated MCU that steps the
//! plant, and runs [`dexitac_rig::task_loop::run`]. The run ends at the
//! scenario's duration, 1.5 s after the object fell or the host
//! released it, or when the caller's stop flag is set (Ctrl-C).
//!
//! # Pace
//!
//! - [`Pace::Max`] (the tests, `dexitac sim --speed max`): one virtual clock
//!   ([`Clock::virtual_clock`]) for the task loop, the link, the MCU, the
//!   plant and the cameras. The MCU is a [`VirtualMcu`]: no thread, no pty;
//!   it catches up with the clock whenever the link reads or writes, and
//!   checks the end of the run after every tick. The firmware's own
//!   deadlines (host silence, pump run time) apply at their real values,
//!   and the same scenario and seed give the same run, event for event.
//!   Faults can be injected ([`SimOptions::injections`]).
//! - [`Pace::Times`] (the live view, soak tests): real time, `speed` times
//!   faster; the MCU runs on its own thread, on an in-process serial line
//!   ([`SimMcu::spawn_with_plant_in_process`]: a pty's bytes pass through a
//!   kernel worker that a busy machine can starve for over a second), and a
//!   monitor thread ends the run. Above
//!   real time the firmware's host-silence deadline is scaled by the speed:
//!   the host keeps the 500 ms of *wall-clock* time it has on the rig
//!   ([`SimOptions::stall_tolerance_ms`]), so the scheduling jitter of a busy
//!   PC does not trip the simulated board any more than it would trip the
//!   real one. The task loop's watchdogs (a silent sensor, a silent MCU) are
//!   scaled the same way, and by the stall tolerance over the firmware's
//!   500 ms.
//!
//! # Outcome
//!
//! - `held`: the object was still in the grasp at the end;
//! - `dropped`: it fell out while the host had not released it;
//! - `released`: the host released (slip, lost contact, no contact);
//! - `not_grasped`: no release, and no object in the grasp at the end:
//!   none in the scenario (only without tactile feedback), or one the
//!   fingertips are not both on (the run ended before they closed).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use dexitac_protocol::{HostMsg, ValveState};

use crate::line::NoisyPort;
use crate::mcu::{
    lock_plant, McuInjection, McuSnapshot, SharedPlant, SimMcu, SimMcuConfig, VirtualMcu,
};
use crate::plant::{ObjectState, Plant, Poke, WorldState, FINGER_COUNT};
use crate::render::Renderer;
use crate::scenario::Scenario;
use crate::task_report::{task_report, TaskReport};
use dexitac_gripper::grasp::{Cause, CentreMm, Command};
use dexitac_rig::event::{RuntimeEvent, StopReason};
use dexitac_rig::link::{Link, LinkConfig, LinkError, LinkStats, Port};
use dexitac_rig::source::{Clock, FrameSource, SourceError, TimedFrame};
use dexitac_rig::task_loop::{ControlConfig, Sensor};
use dexitac_tactile::calibrate::{self, Calibration, CalibrationError};
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::synth::SensorSpec;
use dexitac_tactile::PointPx;

/// Working frame size of the simulated cameras (the paper's 640x480).
const FRAME_SIZE_PX: (usize, usize) = (640, 480);
/// How far the simulated MCU's tick stamps may trail the shared clock, ms.
const MCU_LAG_MS: u64 = 50;
/// The plant's trace period, ms of simulated time.
const TRACE_PERIOD_MS: u64 = 10;
/// Keep running this long after the object fell or was released, ms.
const AFTER_END_MS: u64 = 1_500;
/// The simulated tube and valves are slower than the firmware's QEMU tank
/// model assumes; the plant models the actuator side itself.
const STATUS_PERIOD: Duration = Duration::from_millis(200);

/// How simulated time relates to the wall clock.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// Virtual time, as fast as the CPU allows: the task loop, the
    /// simulated MCU, the plant and the cameras run in lock step on one
    /// virtual clock ([`Clock::virtual_clock`]), and a run with the same
    /// scenario and seed repeats exactly. The firmware's deadlines apply at
    /// their real values.
    Max,
    /// Real time, this many times faster than the wall clock (the live
    /// view, soak tests): threads, a pty and the scheduler's jitter, as on
    /// the rig.
    Times(f64),
}

impl Pace {
    /// `max`, or a speed factor in 0.1..=20.
    pub fn parse(s: &str) -> Result<Pace, String> {
        if s.eq_ignore_ascii_case("max") {
            return Ok(Pace::Max);
        }
        let v: f64 = s
            .parse()
            .map_err(|_| format!("`{s}` is neither `max` nor a number"))?;
        if (0.1..=20.0).contains(&v) {
            Ok(Pace::Times(v))
        } else {
            Err(format!("speed must be `max` or lie in 0.1..=20, not {s}"))
        }
    }
}

impl std::fmt::Display for Pace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Pace::Max => write!(f, "max"),
            Pace::Times(v) => write!(f, "{v}"),
        }
    }
}

/// Something that goes wrong during a run, on purpose (tests of the
/// runtime's safety paths).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Injection {
    /// The MCU resets (see [`McuInjection::ResetAt`]).
    McuResetAt {
        /// When, ms of simulated time.
        at_ms: u64,
    },
    /// The MCU stops for a while, then catches up (see
    /// [`McuInjection::StallAt`]).
    McuStallAt {
        /// When, ms.
        at_ms: u64,
        /// For how long, ms.
        for_ms: u64,
    },
    /// A pressure sensor starts reading high or low (see
    /// [`McuInjection::ReadingOffsetAt`]).
    ReadingOffsetAt {
        /// When, ms.
        at_ms: u64,
        /// Positive and negative tank reading offsets, Pa.
        offset_pa: (i32, i32),
    },
    /// The host hangs: fingertip 0's frame at this time takes this long
    /// to arrive and the task loop waits for it, sending nothing (a
    /// stalled process). The board's host-silence trip is what answers.
    HostStallAt {
        /// When, ms.
        at_ms: u64,
        /// For how long, ms.
        for_ms: u64,
    },
    /// A fingertip's camera stops delivering frames (it hangs, without
    /// an error).
    CameraStopsAt {
        /// The finger.
        finger: usize,
        /// When, ms.
        at_ms: u64,
    },
}

/// How to run a scenario.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// Close the loop on the tactile frames (false: the paper's ablation).
    pub tactile_feedback: bool,
    /// Simulated time per wall-clock time.
    pub speed: Pace,
    /// Faults to inject (only on the virtual clock, [`Pace::Max`]).
    pub injections: Vec<Injection>,
    /// Print a one-line status on stderr while running.
    pub status: bool,
    /// Seed of the cameras' noise.
    pub seed: u64,
    /// Set to end the run early (Ctrl-C).
    pub stop: Arc<AtomicBool>,
    /// Probability that a byte on the serial line is corrupted, each way.
    pub line_error_rate: f64,
    /// In real time ([`Pace::Times`]): the wall-clock time the host may
    /// stall before the simulated board trips on host silence (and the
    /// link's ack timeout, a quarter of it), ms. The rig's value is the
    /// firmware's 500 ms. On the virtual clock the firmware's own deadline
    /// applies unchanged.
    pub stall_tolerance_ms: u32,
    /// Every event of the task loop is also sent here (recorder, live
    /// view); a closed receiver is ignored.
    pub event_tap: Option<mpsc::Sender<RuntimeEvent>>,
    /// Attach the working frames to the observations (for the tap).
    pub share_frames: bool,
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            tactile_feedback: true,
            speed: Pace::Max,
            injections: Vec::new(),
            status: false,
            seed: 1,
            stop: Arc::new(AtomicBool::new(false)),
            line_error_rate: 0.0,
            stall_tolerance_ms: dexitac_firmware::control::DEFAULT_HOST_SILENCE_MS,
            event_tap: None,
            share_frames: false,
        }
    }
}

/// Why the simulated rig could not run.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// The simulated MCU (pty) could not start.
    #[error("simulated MCU: {0}")]
    Mcu(#[from] std::io::Error),
    /// Its port could not be opened.
    #[error("link: {0}")]
    Link(#[from] LinkError),
    /// A simulated sensor could not be calibrated.
    #[error("calibration of sensor {sensor}: {source}")]
    Calibration {
        /// The sensor.
        sensor: usize,
        /// Why.
        source: CalibrationError,
    },
}

/// How the scenario ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// The object was still held at the end.
    Held,
    /// The object fell while the host had not released it.
    Dropped,
    /// The host released.
    Released,
    /// No release, and no object in the grasp at the end (none in the
    /// scenario, or the fingertips are not both on it).
    NotGrasped,
}

impl Outcome {
    /// The name used in `summary.json`.
    pub fn name(self) -> &'static str {
        match self {
            Outcome::Held => "held",
            Outcome::Dropped => "dropped",
            Outcome::Released => "released",
            Outcome::NotGrasped => "not_grasped",
        }
    }
}

/// The timeline of one poke, s of simulated time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisturbanceTiming {
    /// The poke.
    pub poke: Poke,
    /// Onset of the force.
    pub t_onset_s: f64,
    /// The host decided "disturbance".
    pub t_detected_s: Option<f64>,
    /// The reopen command's bytes were written.
    pub t_reopen_sent_s: Option<f64>,
    /// The MCU opened the grasping inlets.
    pub t_valves_open_s: Option<f64>,
}

impl DisturbanceTiming {
    /// Onset to valves open, s.
    pub fn response_s(&self) -> Option<f64> {
        self.t_valves_open_s.map(|t| t - self.t_onset_s)
    }
}

/// A density snapshot taken at an event.
#[derive(Debug, Clone)]
pub struct Snapshot {
    /// When, ms.
    pub t_ms: u64,
    /// What happened.
    pub label: String,
    /// Each sensor's latest markers, working px.
    pub markers: [Arc<Vec<PointPx>>; FINGER_COUNT],
}

/// One sensor observation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObservationRecord {
    /// The sensor.
    pub sensor: usize,
    /// Capture time, ms.
    pub t_ms: u64,
    /// The measured contact centre.
    pub centre_mm: Option<CentreMm>,
    /// Pipeline time, ms.
    pub pipeline_ms: f64,
}

/// Everything a run produced.
#[derive(Debug, Clone)]
pub struct SimReport {
    /// The scenario's name.
    pub scenario: String,
    /// Whether the loop was closed on the tactile frames.
    pub tactile_feedback: bool,
    /// How it ended for the object. The outputs say `failed` instead for a
    /// run whose task loop failed ([`SimReport::outcome_word`]).
    pub outcome: Outcome,
    /// Closing began -> seal decision, s.
    pub time_to_stable_s: Option<f64>,
    /// Per poke.
    pub disturbances: Vec<DisturbanceTiming>,
    /// Decisions of the grasp state machine: (handled at ms, decision).
    pub decisions: Vec<(u64, dexitac_gripper::grasp::Decision)>,
    /// For each of `decisions`, how many of `observations` the task loop
    /// had reported before it: a decision on a frame follows that frame's
    /// observation, so this places it in the order the grasp saw the frames
    /// ([`crate::output::frame_shifts`] sets the anchors with it).
    pub observations_before_decision: Vec<usize>,
    /// Commands sent: (bytes written at ms, command, reason).
    pub commands: Vec<(u64, HostMsg, &'static str)>,
    /// Frame arrival -> command bytes written, for commands a frame decided.
    pub frame_to_command: Vec<Duration>,
    /// Every observation.
    pub observations: Vec<ObservationRecord>,
    /// The plant's trace.
    pub trace: Vec<WorldState>,
    /// Valve output changes: (ms, chambers).
    pub transitions: Vec<(u64, dexitac_protocol::Chambers)>,
    /// When the object fell, ms.
    pub dropped_at_ms: Option<u64>,
    /// Density snapshots at decisions.
    pub snapshots: Vec<Snapshot>,
    /// The calibrations (for heatmaps).
    pub calibrations: Vec<Calibration>,
    /// How the task loop ended; [`SimReport::status`] states it in words.
    pub loop_result: Result<StopReason, crate::status::LoopError>,
    /// The MCU's state at the end.
    pub mcu_at_end: McuSnapshot,
    /// The host link's traffic counters.
    pub link_stats: LinkStats,
    /// The longest wall-clock stall of the host's link thread.
    pub max_loop_gap: Duration,
    /// The grasping chambers.
    pub grasp_chambers: Vec<usize>,
    /// The manipulation task's outcome, if the scenario has one and it started.
    pub task: Option<TaskReport>,
    /// Simulated run time, s.
    pub sim_s: f64,
    /// Wall-clock run time, s.
    pub wall_s: f64,
    /// How simulated time ran.
    pub pace: Pace,
}

/// A fingertip camera rendering the plant's contact.
struct RenderSource {
    renderer: Renderer,
    plant: SharedPlant,
    finger: usize,
    period_ms: u64,
    next_ms: u64,
    /// On the virtual clock: the MCU that steps the plant, caught up before
    /// each frame.
    world: Option<VirtualMcu>,
    /// The camera hangs from this time on (an injected fault), ms.
    stops_at_ms: Option<u64>,
    /// The frame due at or after this time takes this long (an injected
    /// host stall): (at, for), ms.
    stall: Option<(u64, u64)>,
}

impl FrameSource for RenderSource {
    fn next_due_ms(&self) -> Option<u64> {
        match self.stops_at_ms {
            Some(stop) if self.next_ms >= stop => Some(u64::MAX),
            _ => Some(self.next_ms),
        }
    }

    fn next_frame(&mut self, clock: &Clock) -> Result<Option<TimedFrame>, SourceError> {
        clock.sleep_until(self.next_ms);
        if let Some((at_ms, for_ms)) = self.stall {
            if self.next_ms >= at_ms {
                self.stall = None;
                clock.sleep(Duration::from_millis(for_ms));
            }
        }
        // On the virtual clock the frame shows the plant at its due time,
        // whatever else moved the clock meanwhile (the other sensor's
        // injected stall, on its own thread).
        let t_ms = match &self.world {
            Some(world) => {
                world.catch_up_to(self.next_ms * 1_000);
                self.next_ms
            }
            None => clock.now_ms(),
        };
        let contact = lock_plant(&self.plant)
            .state()
            .contacts
            .get(self.finger)
            .copied()
            .flatten();
        let frame = self.renderer.render(contact.as_ref());
        self.next_ms += self.period_ms;
        if self.next_ms <= t_ms {
            // Rendering fell behind: drop frames rather than queue them.
            self.next_ms = t_ms + self.period_ms;
        }
        Ok(Some(TimedFrame { t_ms, frame }))
    }
}

fn sensor_spec(finger: usize) -> SensorSpec {
    let mut spec = SensorSpec::nominal(FRAME_SIZE_PX.0, FRAME_SIZE_PX.1);
    // Two skins are never cut alike.
    spec.lattice_offset = PointPx::new(4.0 * finger as f64, 3.0 * finger as f64);
    spec
}

/// Rest frames a simulated fingertip is calibrated on.
const REST_FRAMES: usize = 2;

fn renderer(finger: usize, params: &Params, seed: u64) -> Renderer {
    Renderer::new(
        sensor_spec(finger),
        params.frame.mm_per_px,
        seed.wrapping_mul(31).wrapping_add(finger as u64),
    )
}

/// The rest frames simulated fingertip `finger` is calibrated on in a run
/// with camera seed `seed` (the same frames every time: for recordings,
/// whose replay recalibrates on them).
pub fn rest_frames(
    finger: usize,
    params: &Params,
    seed: u64,
) -> Vec<dexitac_tactile::frame::GreyFrame> {
    renderer_after_rest(finger, params, seed).1
}

/// Fingertip `finger`'s camera, after it rendered the rest frames (also
/// returned) that its pipeline is calibrated on.
fn renderer_after_rest(
    finger: usize,
    params: &Params,
    seed: u64,
) -> (Renderer, Vec<dexitac_tactile::frame::GreyFrame>) {
    let mut renderer = renderer(finger, params, seed);
    let rest = (0..REST_FRAMES).map(|_| renderer.render(None)).collect();
    (renderer, rest)
}

/// A simulated fingertip: its camera and its calibrated pipeline.
struct SimSensor {
    source: RenderSource,
    pipeline: Pipeline,
}

impl SimSensor {
    fn into_sensor(self) -> Sensor {
        Sensor {
            source: Box::new(self.source),
            pipeline: self.pipeline,
        }
    }
}

fn make_sensor(
    finger: usize,
    params: &Params,
    plant: &SharedPlant,
    period_ms: u64,
    seed: u64,
) -> Result<(SimSensor, Calibration), SimError> {
    let (renderer, rest) = renderer_after_rest(finger, params, seed);
    let calibration =
        calibrate::calibrate(&rest, params).map_err(|source| SimError::Calibration {
            sensor: finger,
            source,
        })?;
    let pipeline = Pipeline::new(calibration.clone(), params.clone());
    let source = RenderSource {
        renderer,
        plant: Arc::clone(plant),
        finger,
        period_ms,
        next_ms: 0,
        world: None,
        stops_at_ms: None,
        stall: None,
    };
    Ok((SimSensor { source, pipeline }, calibration))
}

/// What the monitor and the collector share.
#[derive(Default)]
struct Live {
    released_ms: Option<u64>,
    phase: String,
    centres: [Option<CentreMm>; FINGER_COUNT],
    markers: [Arc<Vec<PointPx>>; FINGER_COUNT],
}

/// Runs `scenario` on the simulated rig.
pub fn run_scenario(scenario: &Scenario, options: &SimOptions) -> Result<SimReport, SimError> {
    let wall_start = Instant::now();
    // The scenario file's rig tables, as `dexitac run --config` reads them;
    // `--no-tactile` (options.tactile_feedback = false) turns feedback off.
    let base = scenario.rig.control();
    // In real time the watchdogs get the wall-clock time they have on the
    // rig, and the stall tolerance asked for, like the firmware's
    // host-silence deadline (module docs).
    let scale = match options.speed {
        Pace::Times(speed) => {
            let tolerance = f64::from(options.stall_tolerance_ms)
                / f64::from(dexitac_firmware::control::DEFAULT_HOST_SILENCE_MS);
            speed.max(1.0) * tolerance.max(1.0)
        }
        Pace::Max => 1.0,
    };
    let control = ControlConfig {
        tactile_feedback: options.tactile_feedback && base.tactile_feedback,
        task: scenario.task.clone(),
        share_frames: options.share_frames,
        sensor_timeout_ms: (base.sensor_timeout_ms as f64 * scale) as u64,
        mcu_silence_ms: (base.mcu_silence_ms as f64 * scale) as u64,
        ..base
    };
    let params = Params::default();
    let plant = Plant::new(
        scenario.plant.clone(),
        scenario.object().cloned(),
        &control.grasp_chambers,
        scenario.trajectory.clone(),
        scenario.pokes.clone(),
    )
    .with_trace(TRACE_PERIOD_MS);
    let plant: SharedPlant = Arc::new(Mutex::new(plant));
    let mut sensors = Vec::new();
    let mut calibrations = Vec::new();
    for finger in 0..FINGER_COUNT {
        let (s, c) = make_sensor(
            finger,
            &params,
            &plant,
            scenario.frame_period_ms,
            options.seed,
        )?;
        sensors.push(s);
        calibrations.push(c);
    }
    // Calibration done: the simulated time starts now.
    let duration_ms = (scenario.duration_s * 1e3) as u64;
    let (tx, rx) = mpsc::channel();
    let live = Arc::new(Mutex::new(Live::default()));
    let stop = Arc::new(AtomicBool::new(false));
    let run = |clock: &Clock, link: &mut Link<Box<dyn Port>>, sensors: Vec<Sensor>| {
        let finished = AtomicBool::new(false);
        std::thread::scope(|scope| {
            if !clock.is_virtual() {
                scope.spawn(|| {
                    monitor(clock, duration_ms, &plant, &live, options, &stop, &finished)
                });
            }
            let tap = options.event_tap.clone();
            let collector = scope.spawn(|| collect(rx, &live, tap));
            let result =
                dexitac_rig::task_loop::run(&control, link, sensors, clock.clone(), &stop, &tx);
            finished.store(true, Ordering::Relaxed);
            drop(tx);
            let collected = collector.join().unwrap_or_default();
            (result, collected)
        })
    };
    let (clock, (loop_result, collected), mcu_at_end, link_stats) = match options.speed {
        Pace::Max => {
            let clock = Clock::virtual_clock();
            let mcu = VirtualMcu::new(
                SimMcuConfig::default(),
                Some(Arc::clone(&plant)),
                clock.clone(),
            );
            for injection in &options.injections {
                match *injection {
                    Injection::McuResetAt { at_ms } => mcu.inject(McuInjection::ResetAt { at_ms }),
                    Injection::McuStallAt { at_ms, for_ms } => {
                        mcu.inject(McuInjection::StallAt { at_ms, for_ms })
                    }
                    Injection::ReadingOffsetAt { at_ms, offset_pa } => {
                        mcu.inject(McuInjection::ReadingOffsetAt { at_ms, offset_pa })
                    }
                    Injection::HostStallAt { at_ms, for_ms } => {
                        if let Some(s) = sensors.first_mut() {
                            s.source.stall = Some((at_ms, for_ms));
                        }
                    }
                    Injection::CameraStopsAt { finger, at_ms } => {
                        if let Some(s) = sensors.get_mut(finger) {
                            s.source.stops_at_ms = Some(at_ms);
                        }
                    }
                }
            }
            mcu.observe(end_watch(
                duration_ms,
                &control.grasp_chambers,
                Arc::clone(&stop),
                Arc::clone(&options.stop),
                Arc::clone(&live),
                options.status,
            ));
            let link_config = LinkConfig::default();
            let port = mcu.port(link_config.read_timeout_ms);
            let port: Box<dyn Port> = if options.line_error_rate > 0.0 {
                Box::new(NoisyPort::new(port, options.line_error_rate, options.seed))
            } else {
                Box::new(port)
            };
            let mut link = Link::with_clock(port, link_config, clock.clone());
            let sensors = sensors
                .into_iter()
                .map(|mut s| {
                    s.source.world = Some(mcu.clone());
                    s.into_sensor()
                })
                .collect();
            let result = run(&clock, &mut link, sensors);
            // The MCU applies the shutdown commands within a tick or two.
            clock.sleep(Duration::from_millis(20));
            (clock, result, mcu.snapshot(), link.stats())
        }
        Pace::Times(speed) => {
            let clock = Clock::scaled(speed);
            let speed = clock.speed();
            let firmware = dexitac_firmware::Config {
                // The host gets the same wall-clock time to send a frame as on the rig.
                host_silence_ms: (f64::from(options.stall_tolerance_ms) * speed.max(1.0)) as u32,
                ..dexitac_firmware::Config::default()
            };
            let link_config = LinkConfig {
                // Link timeouts run on the simulated clock.
                ack_timeout_ms: ((f64::from(options.stall_tolerance_ms / 4) * speed) as u64)
                    .max(20),
                ..LinkConfig::default()
            };
            // An in-process line, not a pty: see SimMcu::spawn_with_plant_in_process.
            let (mcu, port) = SimMcu::spawn_with_plant_in_process(
                SimMcuConfig {
                    firmware,
                    clock: Some(clock.clone()),
                    speed,
                    ..SimMcuConfig::default()
                },
                Arc::clone(&plant),
                Duration::from_millis(link_config.read_timeout_ms.max(1)),
            )?;
            let port: Box<dyn Port> = if options.line_error_rate > 0.0 {
                Box::new(NoisyPort::new(port, options.line_error_rate, options.seed))
            } else {
                Box::new(port)
            };
            let mut link = Link::with_clock(port, link_config, clock.clone());
            let sensors = sensors.into_iter().map(SimSensor::into_sensor).collect();
            let result = run(&clock, &mut link, sensors);
            // Let the MCU apply the shutdown commands before reading its state.
            std::thread::sleep(Duration::from_millis(20));
            let snapshot = mcu.snapshot();
            drop(mcu);
            (clock, result, snapshot, link.stats())
        }
    };
    let sim_s = clock.now_ms() as f64 / 1e3;
    let plant = lock_plant(&plant);
    let report = build_report(
        scenario,
        options,
        &control,
        &plant,
        collected,
        calibrations,
        loop_result,
        mcu_at_end,
    );
    Ok(SimReport {
        sim_s,
        wall_s: wall_start.elapsed().as_secs_f64(),
        link_stats,
        ..report
    })
}

/// On the virtual clock, the monitor's job, run by the MCU after every
/// tick: ends the run at the scenario's duration, [`AFTER_END_MS`] after
/// the object fell or the grasping chambers were all set to deflate (the
/// host released), or on the caller's stop request, and prints the status
/// line.
fn end_watch(
    duration_ms: u64,
    grasp_chambers: &[usize],
    stop: Arc<AtomicBool>,
    requested: Arc<AtomicBool>,
    live: Arc<Mutex<Live>>,
    status: bool,
) -> crate::mcu::TickObserver {
    let grasp_chambers = grasp_chambers.to_vec();
    let mut released_ms = None;
    let mut last_status = Instant::now();
    Box::new(move |t_ms, chambers, plant| {
        let all_deflate = !grasp_chambers.is_empty()
            && grasp_chambers
                .iter()
                .all(|&i| chambers.get(i) == Some(&ValveState::Deflate));
        if all_deflate {
            released_ms.get_or_insert(t_ms);
        }
        let requested = requested.load(Ordering::Relaxed);
        if run_is_over(
            t_ms,
            duration_ms,
            plant.dropped_at_ms(),
            released_ms,
            requested,
        ) {
            stop.store(true, Ordering::Relaxed);
        }
        if status && last_status.elapsed() >= STATUS_PERIOD {
            last_status = Instant::now();
            let (phase, centres) = {
                let l = live.lock().unwrap_or_else(|e| e.into_inner());
                (l.phase.clone(), l.centres)
            };
            eprint!("\r{}", status_line(plant.state(), &phase, &centres));
        }
    })
}

/// Whether a run is over at `now_ms`: the scenario's duration reached,
/// [`AFTER_END_MS`] past a drop or a release, or a stop requested (Ctrl-C).
fn run_is_over(
    now_ms: u64,
    duration_ms: u64,
    dropped_ms: Option<u64>,
    released_ms: Option<u64>,
    requested: bool,
) -> bool {
    let settled = dropped_ms
        .or(released_ms)
        .is_some_and(|t| now_ms > t + AFTER_END_MS);
    now_ms >= duration_ms || settled || requested
}

/// Ends the run and prints the status line.
fn monitor(
    clock: &Clock,
    duration_ms: u64,
    plant: &SharedPlant,
    live: &Mutex<Live>,
    options: &SimOptions,
    stop: &AtomicBool,
    finished: &AtomicBool,
) {
    let mut last_status = Instant::now();
    while !finished.load(Ordering::Relaxed) {
        let now = clock.now_ms();
        let (state, dropped) = {
            let p = lock_plant(plant);
            (p.state().clone(), p.dropped_at_ms())
        };
        let (released, phase, centres) = {
            let l = live.lock().unwrap_or_else(|e| e.into_inner());
            (l.released_ms, l.phase.clone(), l.centres)
        };
        let requested = options.stop.load(Ordering::Relaxed);
        if run_is_over(now, duration_ms, dropped, released, requested) {
            stop.store(true, Ordering::Relaxed);
        }
        if options.status && last_status.elapsed() >= STATUS_PERIOD {
            last_status = Instant::now();
            eprint!("\r{}", status_line(&state, &phase, &centres));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    if options.status {
        eprintln!();
    }
}

fn status_line(s: &WorldState, phase: &str, centres: &[Option<CentreMm>; FINGER_COUNT]) -> String {
    let valves: String = s
        .valves
        .iter()
        .map(|v| match v {
            ValveState::Hold => '.',
            ValveState::Inflate => '+',
            ValveState::Deflate => '-',
        })
        .collect();
    let centre = |c: &Option<CentreMm>| match c {
        Some(c) => format!("({:+5.2},{:+5.2})", c.x_mm, c.y_mm),
        None => "(  none     )".to_string(),
    };
    let object = match s.object {
        ObjectState::Absent => "none",
        ObjectState::InGrasp if s.gripper_mm.0 > 1.0 => "lifted",
        ObjectState::InGrasp => "on table",
        ObjectState::Dropped => "DROPPED",
    };
    format!(
        "t {:6.2} s | {:<12} | valves {valves} | tanks {:+5.1}/{:+5.1} kPa | c0 {} c1 {} mm | poke {:4.1} N | object {object:<8}",
        s.t_ms as f64 / 1e3,
        phase,
        s.tanks_kpa.0,
        s.tanks_kpa.1,
        centre(&centres[0]),
        centre(&centres[1]),
        s.external_n,
    )
}

#[derive(Default)]
struct Collected {
    decisions: Vec<(u64, dexitac_gripper::grasp::Decision)>,
    observations_before_decision: Vec<usize>,
    commands: Vec<(u64, HostMsg, &'static str)>,
    frame_to_command: Vec<Duration>,
    observations: Vec<ObservationRecord>,
    snapshots: Vec<Snapshot>,
    max_loop_gap: Duration,
    task_events: Vec<(u64, dexitac_gripper::manipulation::TaskEvent)>,
}

/// Gathers the loop's events; keeps the live view for the monitor.
fn collect(
    rx: mpsc::Receiver<RuntimeEvent>,
    live: &Mutex<Live>,
    tap: Option<mpsc::Sender<RuntimeEvent>>,
) -> Collected {
    let mut c = Collected::default();
    for event in rx {
        if let Some(tap) = &tap {
            let _ = tap.send(event.clone());
        }
        let mut l = live.lock().unwrap_or_else(|e| e.into_inner());
        match event {
            RuntimeEvent::Observation(r) => {
                if let Some(slot) = l.centres.get_mut(r.sensor) {
                    *slot = r.centre_mm;
                }
                if let Some(slot) = l.markers.get_mut(r.sensor) {
                    *slot = r.markers;
                }
                c.observations.push(ObservationRecord {
                    sensor: r.sensor,
                    t_ms: r.t_ms,
                    centre_mm: r.centre_mm,
                    pipeline_ms: r.pipeline_ms,
                });
            }
            RuntimeEvent::Decision { t_ms, decision } => {
                c.snapshots.push(Snapshot {
                    t_ms,
                    label: decision_label(&decision),
                    markers: l.markers.clone(),
                });
                c.decisions.push((t_ms, decision));
                c.observations_before_decision.push(c.observations.len());
            }
            RuntimeEvent::CommandSent {
                t_ms,
                msg,
                reason,
                from_frame,
            } => {
                l.phase = match reason {
                    "stable: seal" | "open-loop seal" => "sealed",
                    "disturbance: reopen inflation" => "reinforcing",
                    "release" => "released",
                    "close fingers" => "closing",
                    "task: stroke" | "task: guard return" => "manipulating",
                    "task: guard stop" => "guard stop",
                    "task: completed" => "task done",
                    _ => "charging",
                }
                .to_string();
                if reason == "release" {
                    l.released_ms.get_or_insert(t_ms);
                }
                if let Some(d) = from_frame {
                    c.frame_to_command.push(d);
                }
                c.commands.push((t_ms, msg, reason));
            }
            RuntimeEvent::Stopped { max_loop_gap, .. } => c.max_loop_gap = max_loop_gap,
            RuntimeEvent::Telemetry { .. } => {}
            RuntimeEvent::Task { t_ms, event } => c.task_events.push((t_ms, event)),
        }
    }
    c
}

fn decision_label(d: &dexitac_gripper::grasp::Decision) -> String {
    match (d.command, d.cause) {
        (Command::Seal, _) => "seal".into(),
        (Command::ReopenInflation, Cause::Disturbance { sensor, .. }) => {
            format!("disturbance-s{sensor}")
        }
        (Command::ReopenInflation, _) => "reopen".into(),
        (Command::Release, Cause::Slip { sensor, .. }) => format!("slip-s{sensor}"),
        (Command::Release, Cause::ContactLost { sensor }) => format!("contact-lost-s{sensor}"),
        (Command::Release, Cause::NoContact { .. }) => "no-contact".into(),
        (Command::Release, _) => "release".into(),
    }
}

#[allow(clippy::too_many_arguments)]
fn build_report(
    scenario: &Scenario,
    options: &SimOptions,
    control: &ControlConfig,
    plant: &Plant,
    c: Collected,
    calibrations: Vec<Calibration>,
    loop_result: Result<StopReason, impl Into<crate::status::LoopError>>,
    mcu_at_end: McuSnapshot,
) -> SimReport {
    let loop_result = loop_result.map_err(Into::into);
    let released_ms = c
        .commands
        .iter()
        .find(|(_, _, r)| *r == "release")
        .map(|(t, _, _)| *t);
    let dropped_ms = plant.dropped_at_ms();
    // Held: both fingertips still on the object at the end (an object the
    // fingers never closed on stays on the table, in no grasp).
    let gripped = plant.state().contacts.iter().all(Option::is_some);
    let outcome = match (scenario.object().is_some(), released_ms, dropped_ms) {
        (false, Some(_), _) => Outcome::Released,
        (false, None, _) => Outcome::NotGrasped,
        (true, Some(r), d) if d.is_none_or(|d| r <= d) => Outcome::Released,
        (true, _, Some(_)) => Outcome::Dropped,
        (true, _, None) if gripped => Outcome::Held,
        (true, _, None) => Outcome::NotGrasped,
    };
    let closing_ms = c
        .commands
        .iter()
        .find(|(_, _, r)| *r == "close fingers")
        .map(|(t, _, _)| *t);
    let stable_ms = c
        .decisions
        .iter()
        .find(|(_, d)| d.command == Command::Seal)
        .map(|(t, _)| *t);
    let time_to_stable_s = closing_ms
        .zip(stable_ms)
        .map(|(a, b)| b.saturating_sub(a) as f64 / 1e3);
    let disturbances = disturbance_timings(scenario, control, plant, &c);
    let task = scenario
        .task
        .as_ref()
        .and_then(|t| task_report(t, c.task_events, plant.trace()));
    SimReport {
        pace: options.speed,
        scenario: scenario.name.clone(),
        tactile_feedback: options.tactile_feedback,
        outcome,
        time_to_stable_s,
        disturbances,
        decisions: c.decisions,
        observations_before_decision: c.observations_before_decision,
        commands: c.commands,
        frame_to_command: c.frame_to_command,
        observations: c.observations,
        trace: plant.trace().to_vec(),
        transitions: plant.transitions().to_vec(),
        dropped_at_ms: dropped_ms,
        snapshots: c.snapshots,
        calibrations,
        loop_result,
        mcu_at_end,
        link_stats: LinkStats::default(),
        max_loop_gap: c.max_loop_gap,
        grasp_chambers: control.grasp_chambers.clone(),
        task,
        sim_s: 0.0,
        wall_s: 0.0,
    }
}

fn disturbance_timings(
    scenario: &Scenario,
    control: &ControlConfig,
    plant: &Plant,
    c: &Collected,
) -> Vec<DisturbanceTiming> {
    let mut pokes = scenario.pokes.clone();
    pokes.sort_by(|a, b| a.at_s.total_cmp(&b.at_s));
    let inflating = |chambers: &dexitac_protocol::Chambers| {
        control
            .grasp_chambers
            .iter()
            .all(|&i| chambers.get(i) == Some(&ValveState::Inflate))
    };
    (0..pokes.len())
        .map(|i| {
            let poke = pokes[i];
            let onset_ms = (poke.at_s * 1e3) as u64;
            let end_ms = pokes.get(i + 1).map_or(u64::MAX, |p| (p.at_s * 1e3) as u64);
            let within = |t: u64| t >= onset_ms && t < end_ms;
            let detected = c
                .decisions
                .iter()
                .find(|(t, d)| within(*t) && d.command == Command::ReopenInflation)
                .map(|(t, _)| *t);
            let sent = detected.and_then(|d| {
                c.commands
                    .iter()
                    .find(|(t, _, r)| *t >= d && *r == "disturbance: reopen inflation")
                    .map(|(t, _, _)| *t)
            });
            // The first opening after the decision. The simulated MCU stamps
            // a tick with the time it simulates; when its thread lags the
            // clock by a few ms, the tick that applies the command carries a
            // time slightly before the write: look back by that lag and
            // clamp to the write.
            let open = sent.zip(detected).and_then(|(s, d)| {
                plant
                    .transitions()
                    .iter()
                    .find(|(t, ch)| *t + MCU_LAG_MS >= d && inflating(ch))
                    .map(|(t, _)| (*t).max(s))
            });
            let s = |t: Option<u64>| t.map(|t| t as f64 / 1e3);
            DisturbanceTiming {
                poke,
                t_onset_s: poke.at_s,
                t_detected_s: s(detected),
                t_reopen_sent_s: s(sent),
                t_valves_open_s: s(open),
            }
        })
        .collect()
}
