//! The live view on the command line (see `dexitac_view`):
//!
//! - `dexitac sim --view [--snapshot DIR [--snapshot-every-s S]]`: the
//!   simulated rig's every event goes through the sim's event tap into the
//!   dashboard; closing the window (Esc, q, close button) stops the run
//!   safely (the sim's stop flag: valves sealed, MCU disarmed), the results
//!   are written as usual, and the window then stays up with the last
//!   picture until closed;
//! - `dexitac view (--frames DIR | --camera DEV | --render)` (the sources of
//!   `dexitac run` and `record`, once or twice): sensors only, no board:
//!   frames -> pipeline -> dashboard, with Algorithm 1 run on the
//!   observations from t = 0 (its decisions are shown; nothing is sent
//!   anywhere).
//!
//! Without a display the window cannot open: the command says so and
//! suggests `--snapshot DIR` (and `--headless` for `view`), which writes the
//! same pictures as PNGs with no window.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::Arc;
use std::time::Duration;

use dexitac_gripper::grasp::{Grasp, Observation};
use dexitac_protocol::{ArmState, ValveState};
use dexitac_rig::event::{RuntimeEvent, StopReason};
use dexitac_rig::source::Clock;
use dexitac_rig::task_loop::Sensor;
use dexitac_sim::rig::{run_scenario, SimOptions, SimReport};
use dexitac_sim::scenario::Scenario;
use dexitac_tactile::params::Params;
use dexitac_view::{self, live, Dashboard, DashboardConfig, GraspPhase, LiveOptions, Snapshots};
use dexitac_view::{ViewError, ViewWindow};

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
    #[command(flatten)]
    sources: crate::commands::sources::SourceArgs,
    /// Stop after this many seconds of frame time (default: when the frames
    /// end, the window is closed, or Ctrl-C).
    #[arg(long, value_name = "S", value_parser = parse_duration)]
    duration_s: Option<f64>,
    /// Sensor config (TOML, as `dexitac analyze --config`).
    #[arg(long, value_name = "SENSOR.toml")]
    config: Option<PathBuf>,
    /// Write PNG snapshots of the view into DIR.
    #[arg(long, value_name = "DIR")]
    snapshot: Option<PathBuf>,
    /// Snapshot period, s of frame time (at least 0.01).
    #[arg(long, default_value_t = 2.0, value_name = "S", value_parser = parse_period)]
    snapshot_every_s: f64,
    /// No window: only the snapshots (needs --snapshot).
    #[arg(long, requires = "snapshot")]
    headless: bool,
}

impl LiveArgs {
    /// True when the view is asked for (window or snapshots): the task loop
    /// must then share its frames.
    pub fn wanted(&self) -> bool {
        self.view || self.snapshot.is_some()
    }
}

/// Runs `work` on a thread of its own while the live view (window and/or
/// snapshots, as `args` asks) shows, on this thread, the events `work`
/// sends to the sender it is given; closing the window sets `stop`, as
/// does a failing view (better to end the run safely than to run blind).
/// Without `--view` and `--snapshot`, `work` runs here with `None`.
pub fn with_live_view<T: Send>(
    args: &LiveArgs,
    command: &str,
    mut dashboard: Dashboard,
    stop: &Arc<AtomicBool>,
    work: impl FnOnce(Option<Sender<RuntimeEvent>>) -> T + Send,
) -> Result<(T, Linger), String> {
    let title = format!("dexitac {command}");
    if !args.wanted() {
        let out = work(None);
        let linger = Linger {
            window: None,
            title,
            stop: Arc::clone(stop),
            closed_by_user: false,
        };
        return Ok((out, linger));
    }
    // Open the window before the run starts, so a missing display costs nothing.
    let window = if args.view {
        let (w, h) = dexitac_view::Layout.size();
        let alternative = if command == "view" {
            "--headless --snapshot DIR"
        } else {
            "--snapshot DIR"
        };
        Some(ViewWindow::open(&title, w, h).map_err(|e| no_window(&e, alternative))?)
    } else {
        None
    };
    let snapshots = match &args.snapshot {
        Some(dir) => Some(Snapshots::new(dir, args.snapshot_every_s).map_err(|e| e.to_string())?),
        None => None,
    };
    let (tx, rx) = mpsc::channel();
    std::thread::scope(|scope| {
        let worker = scope.spawn(move || work(Some(tx)));
        let end = live::run(
            &rx,
            &mut dashboard,
            LiveOptions {
                window,
                snapshots,
                fps: WINDOW_FPS,
                stop: Arc::clone(stop),
                lower_priority: true,
            },
        );
        // Later events go nowhere.
        drop(rx);
        if end.is_err() {
            stop.store(true, Ordering::Relaxed);
        }
        let out = worker
            .join()
            .map_err(|_| format!("dexitac {command}: the task thread panicked"))?;
        let end = end.map_err(|e| format!("live view: {e}"))?;
        print_summary(command, &end.summary);
        Ok((
            out,
            Linger {
                window: end.window,
                title,
                stop: Arc::clone(stop),
                closed_by_user: end.summary.closed_by_user,
            },
        ))
    })
}

fn parse_period(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|e| format!("{e}"))?;
    if v.is_finite() && (0.01..=3_600.0).contains(&v) {
        Ok(v)
    } else {
        Err("the snapshot period must lie in 0.01..=3600 s".into())
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

fn print_summary(command: &str, s: &dexitac_view::LiveSummary) {
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
    /// The user closed the window during the run (which stopped it).
    pub closed_by_user: bool,
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

/// A dashboard titled `title` whose heatmaps are relative to each sensor's
/// own rest calibration.
pub fn calibrated_dashboard(title: &str, params: &Params, sensors: &[Sensor]) -> Dashboard {
    let mut dashboard = Dashboard::new(DashboardConfig {
        title: title.into(),
        params: params.clone(),
        ..DashboardConfig::default()
    });
    for (sensor, s) in sensors.iter().enumerate() {
        dashboard.set_calibration(sensor, &s.pipeline.calibration);
    }
    dashboard
}

/// Runs `scenario` on the simulated rig, with the live view and snapshots
/// when asked for.
pub fn run_sim(
    scenario: &Scenario,
    mut options: SimOptions,
    args: &LiveArgs,
) -> Result<(SimReport, Linger), String> {
    let stop = Arc::clone(&options.stop);
    options.share_frames |= args.wanted();
    let dashboard = Dashboard::new(DashboardConfig {
        title: format!("SIM {}", scenario.name.to_ascii_uppercase()),
        ..DashboardConfig::default()
    });
    let work = move |view: Option<Sender<RuntimeEvent>>| {
        if let Some(view) = view {
            // A recorder already on the tap gets every event too.
            options.event_tap = Some(match options.event_tap.take() {
                Some(recorder) => tee(recorder, view),
                None => view,
            });
        }
        let report = run_scenario(scenario, &options);
        // The options hold the last sender of the event tap: the view and
        // the recorder see the end.
        drop(options);
        report
    };
    let (report, linger) = with_live_view(args, "sim", dashboard, &stop, work)?;
    let report = report.map_err(|e| e.to_string())?;
    if linger.closed_by_user {
        let mcu = &report.mcu_at_end;
        let safe =
            mcu.state == ArmState::Disarmed && mcu.chambers.iter().all(|v| *v == ValveState::Hold);
        eprintln!(
            "dexitac sim: the live view was closed, the run stopped: {}",
            if safe {
                "valves sealed, MCU disarmed"
            } else {
                "WARNING: the simulated MCU did not end sealed and disarmed"
            }
        );
    }
    Ok((report, linger))
}

/// A sender whose events are copied to `recorder` and `view` by a thread of
/// its own: the recording does not wait for the view, and goes on when the
/// view's window is closed. The thread ends when the sender is dropped.
fn tee(recorder: Sender<RuntimeEvent>, view: Sender<RuntimeEvent>) -> Sender<RuntimeEvent> {
    let (tx, rx) = mpsc::channel::<RuntimeEvent>();
    std::thread::spawn(move || {
        for event in rx {
            // Either side may have closed: the other still gets everything.
            let _ = recorder.send(event.clone());
            let _ = view.send(event);
        }
    });
    tx
}

/// How often Algorithm 1's clock ticks without frames (no-contact timeout).
const TICK: Duration = Duration::from_millis(20);

/// Algorithm 1 on the observations: forwards each observation to the view,
/// followed by the decision it caused, until every sensor thread ended.
fn relay(observations: Receiver<RuntimeEvent>, clock: Clock, tx: &Sender<RuntimeEvent>) {
    let mut grasp = Grasp::new(Default::default());
    grasp.start(0);
    loop {
        let (event, decision) = match observations.recv_timeout(TICK) {
            Ok(event) => {
                let decision = match &event {
                    RuntimeEvent::Observation(r) => grasp.observe(
                        r.sensor,
                        Observation {
                            t_ms: r.t_ms,
                            centre_mm: r.centre_mm,
                        },
                    ),
                    _ => None,
                };
                (Some(event), decision)
            }
            Err(RecvTimeoutError::Timeout) => (None, grasp.tick(clock.now_ms())),
            Err(RecvTimeoutError::Disconnected) => return,
        };
        // The view may have closed: the sensors end on the stop flag.
        if let Some(e) = event {
            let _ = tx.send(e);
        }
        if let Some(decision) = decision {
            let _ = tx.send(RuntimeEvent::Decision {
                t_ms: decision.t_ms,
                decision,
            });
        }
    }
}

/// Sensors -> pipeline -> Algorithm 1 -> `tx`, one thread per sensor
/// (`cli_record`'s loop) and one for Algorithm 1; ends with a `Stopped`
/// event. Returns the first sensor failure.
fn run_sensors(
    sensors: Vec<Sensor>,
    clock: Clock,
    deadline_ms: Option<u64>,
    stop: &AtomicBool,
    tx: Sender<RuntimeEvent>,
) -> Option<String> {
    std::thread::scope(|scope| {
        let (obs_tx, obs_rx) = mpsc::channel();
        let relay_tx = tx.clone();
        let relay = scope.spawn(move || relay(obs_rx, clock, &relay_tx));
        let failure =
            crate::commands::record::sensor_threads(sensors, clock, deadline_ms, stop, &obs_tx)
                .into_iter()
                .find_map(Result::err);
        // The relay ends when the last sender of observations is gone.
        drop(obs_tx);
        if relay.join().is_err() {
            eprintln!("dexitac view: the Algorithm 1 thread panicked");
        }
        let outcome = match &failure {
            Some(e) => Err(e.clone()),
            None if stop.load(Ordering::Relaxed) => Ok(StopReason::Requested),
            None => Ok(StopReason::FramesEnded),
        };
        // The view may have closed already.
        let _ = tx.send(RuntimeEvent::Stopped {
            t_ms: clock.now_ms(),
            max_loop_gap: Duration::ZERO,
            outcome,
        });
        failure
    })
}

/// Runs the view; `Ok(false)` when a sensor failed (reported on stderr).
fn run_view(args: &ViewArgs) -> Result<bool, String> {
    let params = match &args.config {
        Some(path) => Params::load(path).map_err(|e| e.to_string())?,
        None => Params::default(),
    };
    let deadline_ms = args.duration_s.map(|s| (s * 1e3) as u64);
    let stop = Arc::new(AtomicBool::new(false));
    crate::commands::sim::stop_on_ctrl_c(&stop);
    let mut cameras = Vec::new();
    let setups =
        crate::commands::sources::open(&args.sources, &params, 1..=2, &stop, &mut cameras)?;
    let labels: Vec<String> = setups.iter().map(|s| s.label.clone()).collect();
    let (sensors, _) = crate::commands::sources::calibrated(setups, &params)?;
    let mut dashboard = calibrated_dashboard("VIEW (NO BOARD)", &params, &sensors);
    // Algorithm 1 starts closing at t = 0 (no board: only its decisions show).
    dashboard.set_phase(0, GraspPhase::Closing);
    eprintln!("dexitac view: {}", labels.join(", "));
    let live = LiveArgs {
        view: !args.headless,
        snapshot: args.snapshot.clone(),
        snapshot_every_s: args.snapshot_every_s,
    };
    let clock = Clock::wall();
    let work = |tx: Option<Sender<RuntimeEvent>>| match tx {
        Some(tx) => run_sensors(sensors, clock, deadline_ms, &stop, tx),
        // `--headless` requires `--snapshot`: the view always runs.
        None => Some("nothing to show: give --snapshot DIR or drop --headless".into()),
    };
    let (failure, linger) = with_live_view(&live, "view", dashboard, &stop, work)?;
    crate::commands::sources::print_camera_stats("view", &cameras);
    if let Some(f) = &failure {
        eprintln!("dexitac view: {f}");
    }
    linger.wait();
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
