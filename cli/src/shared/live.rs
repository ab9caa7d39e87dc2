//! The live view's flags (`--view`, `--snapshot DIR`) and running a command
//! with it: the window on this thread, the command's work on another
//! (`dexitac_view`). Shared by `sim`, `run` and `view`.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Sender};
use std::sync::Arc;

use anyhow::anyhow;
use dexitac_protocol::{ArmState, ValveState};
use dexitac_rig::event::RuntimeEvent;
use dexitac_rig::sensor_loop::tee;
use dexitac_rig::task_loop::Sensor;
use dexitac_sim::rig::{run_scenario, SimOptions, SimReport};
use dexitac_sim::scenario::Scenario;
use dexitac_tactile::params::Params;
use dexitac_view::{
    live, Dashboard, DashboardConfig, LiveOptions, Snapshots, ViewError, ViewWindow,
};

/// Redraws per second of the window.
const WINDOW_FPS: f64 = 30.0;

/// The live-view options of `dexitac sim`.
#[derive(Debug, Clone, clap::Args)]
pub struct LiveArgs {
    /// Show the live view in a window (X11); closing it stops the run.
    #[arg(long)]
    pub view: bool,
    /// Write PNG snapshots of the live view into DIR (no window needed).
    #[arg(long, value_name = "DIR")]
    pub snapshot: Option<PathBuf>,
    /// Snapshot period, s of simulated time (at least 0.01).
    #[arg(long, default_value_t = 2.0, value_name = "S", value_parser = parse_period)]
    pub snapshot_every_s: f64,
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
) -> anyhow::Result<(T, Linger)> {
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
        Some(ViewWindow::open(&title, w, h).map_err(|e| anyhow!(no_window(&e, alternative)))?)
    } else {
        None
    };
    let snapshots = match &args.snapshot {
        Some(dir) => Some(Snapshots::new(dir, args.snapshot_every_s).map_err(|e| anyhow!("{e}"))?),
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
            .map_err(|_| anyhow!("dexitac {command}: the task thread panicked"))?;
        let end = end.map_err(|e| anyhow!("live view: {e}"))?;
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

pub fn parse_period(s: &str) -> anyhow::Result<f64> {
    let v: f64 = s.parse().map_err(|e| anyhow!("{e}"))?;
    if v.is_finite() && (0.01..=3_600.0).contains(&v) {
        Ok(v)
    } else {
        Err(anyhow!("the snapshot period must lie in 0.01..=3600 s"))
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
        tracing::info!(
            "dexitac {command}: live view drew {} frame(s) from {} event(s), render {:.2} ms mean, {:.2} ms max",
            s.renders, s.events, s.render_ms_mean, s.render_ms_max
        );
    }
    if let (Some(first), Some(dir)) = (
        s.snapshots.first(),
        s.snapshots.first().and_then(|p| p.parent()),
    ) {
        tracing::info!(
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
            tracing::info!("dexitac: the live view shows the end of the run; Esc or q closes it");
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
) -> anyhow::Result<(SimReport, Linger)> {
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
    let report = report.map_err(|e| anyhow!("{e}"))?;
    if linger.closed_by_user {
        let mcu = &report.mcu_at_end;
        let safe =
            mcu.state == ArmState::Disarmed && mcu.chambers.iter().all(|v| *v == ValveState::Hold);
        tracing::info!(
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
