//! `dexitac run`: the task loop on the real gripper.
//!
//! `--config RIG.toml` is the rig config (`dexitac_rig::config`; commented
//! example: `config/rig.example.toml`): serial link, grasping chambers per
//! finger, tank targets, Algorithm 1 thresholds, a sensor config per
//! fingertip, the gripper configuration and an optional manipulation task.
//! `--check` loads and checks it (and the files it names) and opens nothing.
//!
//! Frame sources: `--camera DEV`, `--frames DIR` (once per fingertip),
//! `--recording FILE.mcap` or `--render` (`crate::shared::sources`, shared
//! with `dexitac record` and `dexitac view`). `--record FILE.mcap` records
//! the run (see rig/RECORDING.md).

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::mpsc;
use std::sync::Arc;

use anyhow::{anyhow, Context};
use dexitac_gripper::configuration::FINGER_COUNT;
use dexitac_rig::config::RigConfig;
use dexitac_rig::event::RuntimeEvent;
use dexitac_rig::link::Link;
use dexitac_rig::source::Clock;

use crate::exit::Outcome;
use crate::shared::live::{calibrated_dashboard, with_live_view, LiveArgs};
use crate::shared::record::{finish_recorder, start_recorder, RecordFlags};
use crate::shared::sources::{self, SourceArgs};
use crate::shared::stop_on_ctrl_c;

/// Arguments of `dexitac run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// Serial port of the board (e.g. /dev/ttyUSB0); default: the rig
    /// config's `[link] port`.
    #[arg(long, value_name = "PATH")]
    port: Option<PathBuf>,
    /// Rig config (TOML; see config/rig.example.toml).
    #[arg(long, value_name = "RIG.toml")]
    config: PathBuf,
    /// Load and check the rig config and the files it names, print what it
    /// sets, and exit: no port or camera is opened.
    #[arg(long)]
    check: bool,
    #[command(flatten)]
    sources: SourceArgs,
    #[command(flatten)]
    record: RecordFlags,
    /// Live view: window and PNG snapshots.
    #[command(flatten)]
    live: LiveArgs,
}

/// Prints what a checked rig config sets (`--check`).
fn print_check(args: &RunArgs, rig: &RigConfig) -> anyhow::Result<()> {
    let control = rig.control();
    let params = rig.sensor_params(FINGER_COUNT)?;
    println!("rig config {}: OK", args.config.display());
    println!(
        "  link: {} at {} baud",
        rig.link
            .port
            .as_ref()
            .map_or("(port from --port)".to_string(), |p| p
                .display()
                .to_string()),
        rig.link.baud
    );
    println!(
        "  grasping chambers per finger: {:?}",
        rig.chambers.grasp_per_finger
    );
    println!(
        "  tank targets: {:+.1} kPa, {:+.1} kPa",
        rig.tanks.positive_kpa, rig.tanks.negative_kpa
    );
    let g = control.grasp;
    println!(
        "  Algorithm 1: T1 {} mm, T2 {} mm, stable span {} ms, no-contact timeout {} ms, tactile feedback {}",
        g.stable_shift_mm,
        g.slip_shift_mm,
        g.stable_span_ms,
        g.no_contact_timeout_ms,
        if control.tactile_feedback { "on" } else { "off" }
    );
    for (finger, p) in params.iter().enumerate() {
        let from = rig
            .fingertip
            .get(finger)
            .and_then(|f| f.sensor_config.as_ref())
            .map_or("the paper's parameters".to_string(), |p| {
                p.display().to_string()
            });
        println!(
            "  fingertip {finger}: {from} ({:.3} mm/px, kernel {} px)",
            p.frame.mm_per_px, p.density.kernel_width_px
        );
    }
    match rig.gripper_config() {
        Some(c) => println!(
            "  gripper: {} ({} fingers, {} assembly)",
            c.name,
            c.finger.name(),
            c.assembly.name()
        ),
        None => println!("  gripper: not given"),
    }
    match &control.task {
        Some(t) => println!("  task: {}, stroke {} ms", t.kind.name(), t.stroke_ms),
        None => println!("  task: none (grasp and hold)"),
    }
    Ok(())
}

impl RunArgs {
    /// Runs `dexitac run` (or only checks its config with `--check`).
    pub fn run(&self) -> anyhow::Result<Outcome> {
        let rig = RigConfig::load(&self.config)?;
        if self.check {
            print_check(self, &rig)?;
        } else {
            run_inner(self, &rig)?;
        }
        Ok(Outcome::Success)
    }
}

fn run_inner(args: &RunArgs, rig: &RigConfig) -> anyhow::Result<()> {
    let port = args
        .port
        .clone()
        .or_else(|| rig.link.port.clone())
        .ok_or_else(|| anyhow!("give --port, or `port` in the rig config's [link] table"))?;
    let params = rig.sensor_params(FINGER_COUNT)?;
    let mut control = rig.control();
    control.share_frames = args.record.record_frames || args.live.wanted();
    let stop = Arc::new(AtomicBool::new(false));
    stop_on_ctrl_c(&stop);
    let mut cameras = Vec::new();
    let setups = sources::open(&args.sources, &params, 2..=2, &stop, &mut cameras)?;
    let (sensors, rests) = sources::calibrated(setups, &params)?;
    let mut link =
        Link::open(&port, rig.link()).with_context(|| format!("opening {}", port.display()))?;
    // The recording holds one sensor config: the first fingertip's.
    let first_config = rig
        .fingertip
        .first()
        .and_then(|f| f.sensor_config.as_deref());
    let recorder = start_recorder(
        &args.record,
        "run",
        &format!("dexitac run --port {}", port.display()),
        &rests,
        first_config,
        &params[0],
    )?;
    let dashboard = calibrated_dashboard("RUN", &params[0], &sensors);
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
    if let Err(dexitac_rig::task_loop::RuntimeError::McuFaultsLatched { faults, .. }) = &result {
        let names: Vec<String> = faults
            .iter()
            .map(crate::commands::faults::fault_name)
            .collect();
        return Err(anyhow!(
            "the board has latched faults: {}. Find and remove their cause, then acknowledge \
             them: dexitac faults --port {} --clear {}",
            names.join(", "),
            port.display(),
            names.join(",")
        ));
    }
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
