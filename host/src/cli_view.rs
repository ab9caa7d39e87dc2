//! The live view on the command line (see `dexitac::view`):
//!
//! - `dexitac sim --view [--snapshot DIR [--snapshot-every-s S]]`: the
//!   simulated rig's every event goes through the sim's event tap into the
//!   dashboard; closing the window (Esc, q, close button) stops the run
//!   safely (the sim's stop flag: valves sealed, MCU disarmed), the results
//!   are written as usual, and the window then stays up with the last
//!   picture until closed;
//! - `dexitac view (--frames DIR [--frames DIR] | --render)`: sensors
//!   only, no board: frames -> pipeline -> dashboard, with Algorithm 1 run
//!   on the observations from t = 0 (its decisions are shown; nothing is
//!   sent anywhere). `--frames`: every PNG/JPEG in name order, the first is
//!   the rest frame (as `dexitac run --frames`). `--render`: the simulator's
//!   camera with a scripted press (press, hold, slide, lift).
//!
//! Without a display the window cannot open: the command says so and
//! suggests `--snapshot DIR` (and `--headless` for `view`), which writes the
//! same pictures as PNGs with no window.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Sender};
use std::sync::Arc;
use std::time::Duration;

use dexitac::calibrate;
use dexitac::frame::GreyFrame;
use dexitac::grasp::{Grasp, Observation};
use dexitac::params::Params;
use dexitac::pipeline::Pipeline;
use dexitac::protocol::{ArmState, ValveState};
use dexitac::runtime::{self, Clock, RuntimeEvent, StopReason};
use dexitac::sim::plant::ContactState;
use dexitac::sim::render::Renderer;
use dexitac::sim::rig::{run_scenario, SimOptions, SimReport};
use dexitac::sim::scenario::Scenario;
use dexitac::synth::SensorSpec;
use dexitac::view::{self, live, Dashboard, DashboardConfig, GraspPhase, LiveOptions, Snapshots};
use dexitac::view::{ViewError, ViewWindow};

/// Redraws per second of the window.
const WINDOW_FPS: f64 = 30.0;

/// The live-view options of `dexitac sim`.
#[derive(Debug, Clone, clap::Args)]
pub struct LiveArgs {
    /// Show the live view in a window (X11); closing it stops the run.
    #[arg(long)]
    view: bool,
    /// Write PNG snapshots of the live view into DIR (no window needed).
    #[arg(long, value_name = "DIR")]
    snapshot: Option<PathBuf>,
    /// Snapshot period, s of simulated time (at least 0.01).
    #[arg(long, default_value_t = 2.0, value_name = "S", value_parser = parse_period)]
    snapshot_every_s: f64,
}

/// Arguments of `dexitac view`.
#[derive(Debug, clap::Args)]
pub struct ViewArgs {
    /// A directory of frames per fingertip (once or twice); the first frame
    /// in name order is the rest frame.
    #[arg(
        long,
        value_name = "DIR",
        num_args = 1,
        required_unless_present = "render"
    )]
    frames: Vec<PathBuf>,
    /// The simulator's camera with a scripted press instead of --frames.
    #[arg(long, conflicts_with = "frames")]
    render: bool,
    /// Frames per second (the frames' time step; the window plays at it).
    #[arg(long, default_value_t = 30.0, value_parser = parse_fps)]
    fps: f64,
    /// Length of the --render script, s.
    #[arg(long, default_value_t = 13.0, value_parser = parse_duration)]
    duration_s: f64,
    /// Sensor config (TOML, as `dexitac analyze --config`).
    #[arg(long, value_name = "SENSOR.toml")]
    config: Option<PathBuf>,
    /// Write PNG snapshots of the view into DIR.
    #[arg(long, value_name = "DIR")]
    snapshot: Option<PathBuf>,
    /// Snapshot period, s of frame time (at least 0.01).
    #[arg(long, default_value_t = 2.0, value_name = "S", value_parser = parse_period)]
    snapshot_every_s: f64,
    /// No window: only the snapshots (needs --snapshot); runs as fast as
    /// the pipeline goes.
    #[arg(long, requires = "snapshot")]
    headless: bool,
}

fn parse_period(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && (0.01..=3_600.0).contains(&v) {
        Ok(v)
    } else {
        Err("the snapshot period must lie in 0.01..=3600 s".into())
    }
}

fn parse_fps(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && (0.1..=1_000.0).contains(&v) {
        Ok(v)
    } else {
        Err("fps must lie in 0.1..=1000".into())
    }
}

fn parse_duration(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && (0.1..=3_600.0).contains(&v) {
        Ok(v)
    } else {
        Err("the duration must lie in 0.1..=3600 s".into())
    }
}

/// The message when the window cannot open.
fn no_window(e: &ViewError, alternative: &str) -> String {
    match e {
        ViewError::NoDisplay(why) => format!(
            "cannot open the live view window ({why}). It needs an X11 display (a desktop \
             session, XWayland, or ssh -X). Without a display, {alternative} writes the same \
             pictures as PNG files."
        ),
        other => format!("live view: {other}"),
    }
}

fn print_summary(command: &str, s: &view::LiveSummary) {
    if s.renders > 0 {
        eprintln!(
            "dexitac {command}: live view drew {} frame(s) from {} event(s), render {:.2} ms mean, {:.2} ms max",
            s.renders, s.events, s.render_ms_mean, s.render_ms_max
        );
    }
    if let (Some(first), Some(dir)) = (
        s.snapshots.first(),
        s.snapshots.first().and_then(|p| p.parent()),
    ) {
        eprintln!(
            "dexitac {command}: wrote {} snapshot(s) to {} (first {})",
            s.snapshots.len(),
            dir.display(),
            first
                .file_name()
                .map_or("?".into(), |n| n.to_string_lossy())
        );
    }
}

/// A window kept open after the run, until the user closes it.
pub struct Linger {
    window: Option<ViewWindow>,
    title: String,
    stop: Arc<AtomicBool>,
}

impl Linger {
    /// Waits for the user to close the window (returns at once without one).
    pub fn wait(self) {
        if let Some(w) = self.window {
            eprintln!("dexitac: the live view shows the end of the run; Esc or q closes it");
            live::linger(w, &self.title, &self.stop);
        }
    }
}

/// Runs `scenario` on the simulated rig, with the live view and snapshots
/// when asked for.
pub fn run_sim(
    scenario: &Scenario,
    mut options: SimOptions,
    args: &LiveArgs,
) -> Result<(SimReport, Linger), String> {
    let stop = Arc::clone(&options.stop);
    let title = format!("dexitac sim: {}", scenario.name);
    if !args.view && args.snapshot.is_none() {
        let report = run_scenario(scenario, &options).map_err(|e| e.to_string())?;
        let linger = Linger {
            window: None,
            title,
            stop,
        };
        return Ok((report, linger));
    }
    // Open the window before the run starts, so a missing display costs nothing.
    let window = if args.view {
        let (w, h) = view::Layout.size();
        Some(ViewWindow::open(&title, w, h).map_err(|e| no_window(&e, "--snapshot DIR"))?)
    } else {
        None
    };
    let snapshots = match &args.snapshot {
        Some(dir) => Some(Snapshots::new(dir, args.snapshot_every_s).map_err(|e| e.to_string())?),
        None => None,
    };
    let (tx, rx) = mpsc::channel();
    options.event_tap = Some(tx);
    options.share_frames = true;
    let mut dashboard = Dashboard::new(DashboardConfig {
        title: format!("SIM {}", scenario.name.to_ascii_uppercase()),
        ..DashboardConfig::default()
    });
    std::thread::scope(|scope| {
        let sim = scope.spawn(move || {
            let report = run_scenario(scenario, &options);
            // The tap's sender goes with the options: the view sees the end.
            drop(options);
            report
        });
        let end = {
            let rx = rx;
            live::run(
                &rx,
                &mut dashboard,
                LiveOptions {
                    window,
                    snapshots,
                    fps: WINDOW_FPS,
                    stop: Arc::clone(&stop),
                    lower_priority: true,
                },
            )
        };
        if end.is_err() {
            // The view failed: end the run safely rather than run blind.
            stop.store(true, Ordering::Relaxed);
        }
        let report = sim
            .join()
            .map_err(|_| "the simulated rig's thread panicked".to_string())?
            .map_err(|e| e.to_string())?;
        let end = end.map_err(|e| format!("live view: {e}"))?;
        print_summary("sim", &end.summary);
        if end.summary.closed_by_user {
            let mcu = &report.mcu_at_end;
            let safe = mcu.state == ArmState::Disarmed
                && mcu.chambers.iter().all(|v| *v == ValveState::Hold);
            eprintln!(
                "dexitac sim: the live view was closed, the run stopped: {}",
                if safe {
                    "valves sealed, MCU disarmed"
                } else {
                    "WARNING: the simulated MCU did not end sealed and disarmed"
                }
            );
        }
        Ok((
            report,
            Linger {
                window: end.window,
                title,
                stop,
            },
        ))
    })
}

/// Where a sensor's frames come from in `dexitac view`.
enum Feed {
    /// Files, the rest frame already taken off.
    Files { files: Vec<PathBuf>, next: usize },
    /// The simulator's camera with the scripted press.
    Render {
        renderer: Box<Renderer>,
        finger: usize,
    },
}

struct ViewSensor {
    feed: Feed,
    pipeline: Pipeline,
}

/// The scripted press of `--render` at `t_s`: touch at 1 s, hold (stable:
/// seal at about 4 s), slide 1.5 mm at 6 s (a disturbance), hold again,
/// lift at 11 s (contact lost: release), press again from 12 s.
fn scripted_contact(finger: usize, t_s: f64) -> Option<ContactState> {
    let cycle = t_s % 14.0;
    let pressed = (1.0..11.0).contains(&cycle) || cycle >= 12.0;
    if !pressed {
        return None;
    }
    let slide_mm = if cycle < 12.0 {
        ((cycle - 6.0) / 0.5).clamp(0.0, 1.0) * 1.5
    } else {
        0.0
    };
    let side = if finger == 0 { 1.0 } else { -1.0 };
    Some(ContactState {
        centre_mm: [side * (0.5 + slide_mm), 0.3 * side],
        shear_mm: [0.0, 0.0],
        normal_n: 1.5,
        width_mm: 2.5,
    })
}

impl ViewSensor {
    fn next_frame(&mut self, t_ms: u64, params: &Params) -> Result<Option<GreyFrame>, String> {
        match &mut self.feed {
            Feed::Files { files, next } => {
                let Some(path) = files.get(*next) else {
                    return Ok(None);
                };
                *next += 1;
                crate::cli_run::load_frame(path, params)
                    .map(Some)
                    .map_err(|e| e.to_string())
            }
            Feed::Render { renderer, finger } => {
                let contact = scripted_contact(*finger, t_ms as f64 / 1e3);
                Ok(Some(renderer.render(contact.as_ref())))
            }
        }
    }
}

fn view_sensors(args: &ViewArgs, params: &Params) -> Result<Vec<ViewSensor>, String> {
    let mut out = Vec::new();
    if args.render {
        for finger in 0..2 {
            let mut renderer = Renderer::new(
                SensorSpec::nominal(
                    params.frame.work_width_px as usize,
                    params.frame.work_height_px as usize,
                ),
                params.frame.mm_per_px,
                finger as u64 + 1,
            );
            let rest = [renderer.render(None), renderer.render(None)];
            let cal = calibrate::calibrate(&rest, params).map_err(|e| e.to_string())?;
            out.push(ViewSensor {
                feed: Feed::Render {
                    renderer: Box::new(renderer),
                    finger,
                },
                pipeline: Pipeline::new(cal, params.clone()),
            });
        }
        return Ok(out);
    }
    if args.frames.is_empty() || args.frames.len() > 2 {
        return Err("give --frames once or twice (one directory per fingertip) or --render".into());
    }
    for dir in &args.frames {
        let files = crate::cli_run::image_files(dir)?;
        let rest = crate::cli_run::load_frame(&files[0], params).map_err(|e| e.to_string())?;
        let cal = calibrate::calibrate(&[rest], params)
            .map_err(|e| format!("{}: {e}", files[0].display()))?;
        out.push(ViewSensor {
            feed: Feed::Files {
                files: files[1..].to_vec(),
                next: 0,
            },
            pipeline: Pipeline::new(cal, params.clone()),
        });
    }
    Ok(out)
}

/// Frames -> pipeline -> events, Algorithm 1 on the observations. Frame
/// `k` is at `k / fps` s; `paced`: at that wall-clock time too. Returns why
/// the frames failed, if they did.
#[allow(clippy::too_many_arguments)]
fn produce(
    mut sensors: Vec<ViewSensor>,
    params: &Params,
    period_ms: u64,
    end_ms: Option<u64>,
    paced: bool,
    stop: &AtomicBool,
    tx: &Sender<RuntimeEvent>,
) -> Option<String> {
    let clock = Clock::wall();
    let mut grasp = Grasp::new(Default::default());
    grasp.start(0);
    let mut t_ms = 0u64;
    let outcome = 'frames: loop {
        if stop.load(Ordering::Relaxed) {
            break Ok(StopReason::Requested);
        }
        if end_ms.is_some_and(|end| t_ms > end) {
            break Ok(StopReason::FramesEnded);
        }
        if paced {
            clock.sleep_until(t_ms);
        }
        let mut any = false;
        for (sensor, s) in sensors.iter_mut().enumerate() {
            let frame = match s.next_frame(t_ms, params) {
                Ok(Some(f)) => f,
                Ok(None) => continue,
                Err(e) => break 'frames Err(format!("sensor {sensor}: {e}")),
            };
            any = true;
            let result = match s.pipeline.run(&frame) {
                Ok(r) => r,
                Err(e) => break 'frames Err(format!("sensor {sensor}: {e}")),
            };
            let centre_mm = result
                .contact
                .map(|c| runtime::centre_mm(&s.pipeline, c.centre));
            let event = RuntimeEvent::Observation {
                sensor,
                t_ms,
                centre_mm,
                markers: Arc::new(result.markers.positions()),
                pipeline_ms: result.times.total_ms,
                contact: result.contact,
                frame: Some(Arc::new(frame)),
            };
            if tx.send(event).is_err() {
                return None;
            }
            if let Some(decision) = grasp.observe(sensor, Observation { t_ms, centre_mm }) {
                if tx.send(RuntimeEvent::Decision { t_ms, decision }).is_err() {
                    return None;
                }
            }
        }
        if !any {
            break Ok(StopReason::FramesEnded);
        }
        if let Some(decision) = grasp.tick(t_ms) {
            if tx.send(RuntimeEvent::Decision { t_ms, decision }).is_err() {
                return None;
            }
        }
        t_ms += period_ms;
    };
    let failure = outcome.as_ref().err().cloned();
    // The view may have closed already.
    let _ = tx.send(RuntimeEvent::Stopped {
        t_ms,
        max_loop_gap: Duration::ZERO,
        outcome,
    });
    failure
}

/// Runs the view; `Ok(false)` when a frame could not be read or processed
/// (reported on stderr).
fn run_view(args: &ViewArgs) -> Result<bool, String> {
    let params = match &args.config {
        Some(path) => Params::load(path).map_err(|e| e.to_string())?,
        None => Params::default(),
    };
    let title = "dexitac view".to_string();
    let window = if args.headless {
        None
    } else {
        let (w, h) = view::Layout.size();
        Some(
            ViewWindow::open(&title, w, h)
                .map_err(|e| no_window(&e, "--headless --snapshot DIR"))?,
        )
    };
    let snapshots = match &args.snapshot {
        Some(dir) => Some(Snapshots::new(dir, args.snapshot_every_s).map_err(|e| e.to_string())?),
        None => None,
    };
    let sensors = view_sensors(args, &params)?;
    let mut dashboard = Dashboard::new(DashboardConfig {
        title: if args.render {
            "VIEW RENDER (NO BOARD)".into()
        } else {
            "VIEW FRAMES (NO BOARD)".into()
        },
        params: params.clone(),
        ..DashboardConfig::default()
    });
    for (sensor, s) in sensors.iter().enumerate() {
        dashboard.set_calibration(sensor, &s.pipeline.calibration);
    }
    // Algorithm 1 starts closing at t = 0 (no board: only its decisions show).
    dashboard.set_phase(0, GraspPhase::Closing);
    let period_ms = ((1e3 / args.fps).round() as u64).max(1);
    let end_ms = args.render.then_some((args.duration_s * 1e3) as u64);
    let stop = Arc::new(AtomicBool::new(false));
    crate::cli_sim::stop_on_ctrl_c(&stop);
    let paced = window.is_some();
    let (tx, rx) = mpsc::channel();
    let (end, failure) = std::thread::scope(|scope| {
        let producer_stop = Arc::clone(&stop);
        let params = &params;
        let producer = scope.spawn(move || {
            produce(
                sensors,
                params,
                period_ms,
                end_ms,
                paced,
                &producer_stop,
                &tx,
            )
        });
        let end = live::run(
            &rx,
            &mut dashboard,
            LiveOptions {
                window,
                snapshots,
                fps: WINDOW_FPS,
                stop: Arc::clone(&stop),
                lower_priority: false,
            },
        );
        if end.is_err() {
            stop.store(true, Ordering::Relaxed);
        }
        drop(rx);
        let failure = producer
            .join()
            .unwrap_or_else(|_| Some("the frame thread panicked".into()));
        (end, failure)
    });
    let end = end.map_err(|e| format!("live view: {e}"))?;
    print_summary("view", &end.summary);
    if let Some(f) = &failure {
        eprintln!("dexitac view: {f}");
    }
    if let Some(w) = end.window {
        eprintln!("dexitac view: the frames ended; Esc or q closes the window");
        live::linger(w, &title, &stop);
    }
    Ok(failure.is_none())
}

/// Runs `dexitac view`.
pub fn run(args: &ViewArgs) -> ExitCode {
    match run_view(args) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(msg) => {
            eprintln!("dexitac view: {msg}");
            ExitCode::from(2)
        }
    }
}
