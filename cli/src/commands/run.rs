//! `dexitac run`: the task loop on the real gripper.
//!
//! Frame sources: `--camera DEV`, `--frames DIR` (once per fingertip) or
//! `--render`, see the `cli_sources` module (shared with `dexitac record`
//! and `dexitac view`). `--record FILE.mcap` records the run (see
//! host/RECORDING.md).
//!
//! `GRIPPER.toml`:
//!
//! ```toml
//! baud = 115200
//! grasp_chambers = [0, 1, 4, 5]    # chambers whose inflation closes the fingers
//! tank_positive_kpa = 40.0
//! tank_negative_kpa = -45.0
//! tactile_feedback = true
//! open_loop_close_s = 3.4
//! sensor_config = "sensor.toml"    # optional: pipeline parameters (dexitac analyze --config)
//! [grasp]                          # Algorithm 1 thresholds (optional)
//! stable_shift_mm = 0.5
//! slip_shift_mm = 5.0
//! stable_span_ms = 3000
//! no_contact_timeout_ms = 10000
//! [task]                           # optional: a manipulation primitive once stable
//! kind = "twist"                   # pour | rotate | shake | twist (dexitac_gripper::manipulation)
//! stroke_ms = 4000
//! pause_ms = 2500
//! cycles = 2
//! edge_x_mm = 9.0
//! ```

use anyhow::anyhow;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::mpsc;
use std::sync::Arc;

use serde::Deserialize;

use dexitac_gripper::grasp::GraspParams;
use dexitac_protocol::CHAMBER_COUNT;
use dexitac_rig::event::RuntimeEvent;
use dexitac_rig::link::{Link, LinkConfig};
use dexitac_rig::source::Clock;
use dexitac_rig::task_loop::ControlConfig;

use crate::exit::Outcome;
use crate::shared::live::{calibrated_dashboard, with_live_view, LiveArgs};
use crate::shared::record::{finish_recorder, start_recorder, RecordFlags};
use crate::shared::sources::{self, load_sensor_config, SourceArgs};
use crate::shared::stop_on_ctrl_c;

/// Arguments of `dexitac run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// Serial port of the board (e.g. /dev/ttyUSB0).
    #[arg(long, value_name = "PATH")]
    port: PathBuf,
    /// Gripper configuration (TOML).
    #[arg(long, value_name = "GRIPPER.toml")]
    config: PathBuf,
    #[command(flatten)]
    sources: SourceArgs,
    #[command(flatten)]
    record: RecordFlags,
    /// Live view: window and PNG snapshots.
    #[command(flatten)]
    live: LiveArgs,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct GripperConfig {
    baud: u32,
    grasp_chambers: Vec<usize>,
    tank_positive_kpa: f64,
    tank_negative_kpa: f64,
    tactile_feedback: bool,
    open_loop_close_s: f64,
    sensor_config: Option<PathBuf>,
    grasp: GraspConfig,
    /// A manipulation primitive to run once the grasp is stable (the
    /// `[task]` table of a simulator scenario, `dexitac_gripper::manipulation`).
    task: Option<dexitac_gripper::manipulation::TaskParams>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
struct GraspConfig {
    stable_shift_mm: f64,
    slip_shift_mm: f64,
    stable_span_ms: u64,
    no_contact_timeout_ms: u64,
}

impl Default for GraspConfig {
    fn default() -> Self {
        let g = GraspParams::default();
        GraspConfig {
            stable_shift_mm: g.stable_shift_mm,
            slip_shift_mm: g.slip_shift_mm,
            stable_span_ms: g.stable_span_ms,
            no_contact_timeout_ms: g.no_contact_timeout_ms,
        }
    }
}

impl Default for GripperConfig {
    fn default() -> Self {
        let c = ControlConfig::default();
        GripperConfig {
            baud: LinkConfig::default().baud,
            grasp_chambers: c.grasp_chambers,
            tank_positive_kpa: f64::from(c.tank_targets_pa.0) / 1e3,
            tank_negative_kpa: f64::from(c.tank_targets_pa.1) / 1e3,
            tactile_feedback: c.tactile_feedback,
            open_loop_close_s: c.open_loop_close_ms as f64 / 1e3,
            sensor_config: None,
            grasp: GraspConfig::default(),
            task: None,
        }
    }
}

impl GripperConfig {
    fn load(path: &Path) -> anyhow::Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| anyhow!("cannot read {}: {e}", path.display()))?;
        let config: GripperConfig =
            toml::from_str(&text).map_err(|e| anyhow!("{}: {e}", path.display()))?;
        if let Some(task) = &config.task {
            task.validate().map_err(|(field, value, reason)| {
                anyhow!("{}: {field} = {value}: {reason}", path.display())
            })?;
        }
        let g = &config.grasp;
        let finite_pos = |v: f64| v.is_finite() && v > 0.0;
        if !(finite_pos(g.stable_shift_mm) && finite_pos(g.slip_shift_mm))
            || g.slip_shift_mm <= g.stable_shift_mm
        {
            return Err(anyhow!(
                "{}: grasp thresholds must be positive with slip_shift_mm > stable_shift_mm",
                path.display()
            ));
        }
        if config.grasp_chambers.is_empty()
            || config.grasp_chambers.iter().any(|&c| c >= CHAMBER_COUNT)
        {
            return Err(anyhow!(
                "{}: grasp_chambers must name chambers 0..{CHAMBER_COUNT}",
                path.display()
            ));
        }
        if !config.open_loop_close_s.is_finite() || config.open_loop_close_s < 0.0 {
            return Err(anyhow!(
                "{}: open_loop_close_s must be >= 0",
                path.display()
            ));
        }
        Ok(config)
    }

    fn control(&self) -> anyhow::Result<ControlConfig> {
        let kpa_to_pa = |v: f64| {
            if v.is_finite() && v.abs() < 1e3 {
                Ok((v * 1e3).round() as i32)
            } else {
                Err(anyhow!("tank pressure {v} kPa is not usable"))
            }
        };
        Ok(ControlConfig {
            grasp: GraspParams {
                stable_shift_mm: self.grasp.stable_shift_mm,
                slip_shift_mm: self.grasp.slip_shift_mm,
                stable_span_ms: self.grasp.stable_span_ms,
                no_contact_timeout_ms: self.grasp.no_contact_timeout_ms,
            },
            grasp_chambers: self.grasp_chambers.clone(),
            tank_targets_pa: (
                kpa_to_pa(self.tank_positive_kpa)?,
                kpa_to_pa(self.tank_negative_kpa)?,
            ),
            tactile_feedback: self.tactile_feedback,
            open_loop_close_ms: (self.open_loop_close_s * 1e3) as u64,
            task: self.task.clone(),
            ..ControlConfig::default()
        })
    }
}

fn run_inner(args: &RunArgs) -> anyhow::Result<()> {
    let config = GripperConfig::load(&args.config)?;
    let params = load_sensor_config(config.sensor_config.as_deref())?;
    let control = ControlConfig {
        share_frames: args.record.record_frames || args.live.wanted(),
        ..config.control()?
    };
    let stop = Arc::new(AtomicBool::new(false));
    stop_on_ctrl_c(&stop);
    let mut cameras = Vec::new();
    let setups = sources::open(&args.sources, &params, 2..=2, &stop, &mut cameras)?;
    let (sensors, rests) = sources::calibrated(setups, &params)?;
    let link_config = LinkConfig {
        baud: config.baud,
        ..LinkConfig::default()
    };
    let mut link = Link::open(&args.port, link_config).map_err(|e| anyhow!("{e}"))?;
    let recorder = start_recorder(
        &args.record,
        "run",
        &format!("dexitac run --port {}", args.port.display()),
        &rests,
        config.sensor_config.as_deref(),
        &params,
    )?;
    let dashboard = calibrated_dashboard("RUN", &params, &sensors);
    let tap = recorder.as_ref().map(|r| r.sender());
    let work = |view: Option<mpsc::Sender<RuntimeEvent>>| {
        let (tx, rx) = mpsc::channel::<RuntimeEvent>();
        let printer = std::thread::spawn(move || print_events(&rx, tap.as_ref(), view.as_ref()));
        let result =
            dexitac_rig::task_loop::run(&control, &mut link, sensors, Clock::wall(), &stop, &tx);
        drop(tx);
        if printer.join().is_err() {
            tracing::error!("dexitac run: the event printer failed");
        }
        result
    };
    let (result, linger) = with_live_view(&args.live, "run", dashboard, &stop, work)?;
    if linger.closed_by_user {
        tracing::info!(
            "dexitac run: the live view was closed, the run stopped{}",
            if result.is_ok() {
                ": valves sealed, MCU disarmed"
            } else {
                " (see the error below)"
            }
        );
    }
    sources::print_camera_stats("run", &cameras);
    let recorded = finish_recorder(recorder, &args.record);
    linger.wait();
    result.map_err(|e| anyhow!("{e}"))?;
    recorded
}

/// Prints the loop's commands, task events and end on stderr, and copies
/// every event to the recorder and the live view (either may have closed:
/// the other still gets everything).
fn print_events(
    rx: &mpsc::Receiver<RuntimeEvent>,
    recorder: Option<&mpsc::Sender<RuntimeEvent>>,
    view: Option<&mpsc::Sender<RuntimeEvent>>,
) {
    for event in rx {
        if let Some(tap) = recorder {
            // A failed recorder reports its error when finished.
            let _ = tap.send(event.clone());
        }
        if let Some(view) = view {
            let _ = view.send(event.clone());
        }
        match event {
            RuntimeEvent::CommandSent {
                t_ms, msg, reason, ..
            } => {
                tracing::info!("{:9.3} s  {reason}: {msg:?}", t_ms as f64 / 1e3);
            }
            RuntimeEvent::Task { t_ms, event } => {
                tracing::info!("{:9.3} s  task: {event:?}", t_ms as f64 / 1e3);
            }
            RuntimeEvent::Stopped {
                t_ms,
                outcome,
                max_loop_gap,
            } => {
                tracing::info!(
                    "{:9.3} s  stopped: {outcome:?} (longest loop stall {:.1} ms)",
                    t_ms as f64 / 1e3,
                    max_loop_gap.as_secs_f64() * 1e3
                );
            }
            _ => {}
        }
    }
}

impl RunArgs {
    /// Runs `dexitac run`.
    pub fn run(&self) -> anyhow::Result<Outcome> {
        run_inner(self)?;
        Ok(Outcome::Success)
    }
}
