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
use std::sync::atomic::AtomicBool;
use std::sync::mpsc::Sender;
use std::sync::Arc;

use anyhow::anyhow;
use dexitac_rig::event::RuntimeEvent;
use dexitac_rig::sensor_loop;
use dexitac_rig::source::Clock;
use dexitac_view::GraspPhase;
use tracing::{error, info};

use crate::exit::Outcome;
use crate::shared::live::{calibrated_dashboard, parse_period, with_live_view, LiveArgs};
use crate::shared::sources::{self, load_sensor_config, SourceArgs};
use crate::shared::stop_on_ctrl_c;

/// Arguments of `dexitac view`.
#[derive(Debug, clap::Args)]
pub struct ViewArgs {
    #[command(flatten)]
    sources: SourceArgs,
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

fn parse_duration(s: &str) -> anyhow::Result<f64> {
    let v: f64 = s.parse().map_err(|e| anyhow!("{e}"))?;
    if v.is_finite() && (0.1..=3_600.0).contains(&v) {
        Ok(v)
    } else {
        Err(anyhow!("the duration must lie in 0.1..=3600 s"))
    }
}

impl ViewArgs {
    /// Runs `dexitac view`: [`Outcome::Negative`] when a sensor failed.
    pub fn run(&self) -> anyhow::Result<Outcome> {
        let params = load_sensor_config(self.config.as_deref())?;
        let deadline_ms = self.duration_s.map(|s| (s * 1e3) as u64);
        let stop = Arc::new(AtomicBool::new(false));
        stop_on_ctrl_c(&stop);
        let mut cameras = Vec::new();
        let setups = sources::open(
            &self.sources,
            std::slice::from_ref(&params),
            1..=2,
            &stop,
            &mut cameras,
        )?;
        let labels: Vec<String> = setups.iter().map(|s| s.label.clone()).collect();
        let (sensors, _) = sources::calibrated(setups, std::slice::from_ref(&params))?;
        let mut dashboard = calibrated_dashboard("VIEW (NO BOARD)", &params, &sensors);
        // Algorithm 1 starts closing at t = 0 (no board: only its decisions show).
        dashboard.set_phase(0, GraspPhase::Closing);
        info!("dexitac view: {}", labels.join(", "));
        let live = LiveArgs {
            view: !self.headless,
            snapshot: self.snapshot.clone(),
            snapshot_every_s: self.snapshot_every_s,
        };
        let clock = Clock::wall();
        let work = |tx: Option<Sender<RuntimeEvent>>| match tx {
            Some(tx) => sensor_loop::run_with_grasp(sensors, clock, deadline_ms, &stop, tx)
                .map(|e| e.to_string()),
            // `--headless` requires `--snapshot`: the view always runs.
            None => Some("nothing to show: give --snapshot DIR or drop --headless".into()),
        };
        let (failure, linger) = with_live_view(&live, "view", dashboard, &stop, work)?;
        sources::print_camera_stats("view", &cameras);
        if let Some(f) = &failure {
            error!("dexitac view: {f}");
        }
        linger.wait();
        Ok(Outcome::from_ok(failure.is_none()))
    }
}
