//! `dexitac record` (sensors only: frames -> pipeline -> MCAP), `dexitac
//! replay` (the pipeline again over a recording, compared), and the
//! `--record` flags of `sim` and `run`. Format and topics:
//! `rig/RECORDING.md`, `dexitac_rig::recording`.

use crate::exit::Outcome;
use crate::shared::record::{describe, open_recorder};
use anyhow::anyhow;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use dexitac_rig::source::Clock;

/// Arguments of `dexitac record`.
#[derive(Debug, clap::Args)]
pub struct RecordArgs {
    /// The MCAP file to write.
    #[arg(long, value_name = "FILE.mcap")]
    out: PathBuf,
    #[command(flatten)]
    sources: crate::shared::sources::SourceArgs,
    /// Stop after this many seconds (default: when the frames end, or Ctrl-C).
    #[arg(long, value_name = "S")]
    duration_s: Option<f64>,
    /// Sensor config (TOML); defaults to the paper's parameters.
    #[arg(long, value_name = "SENSOR.toml")]
    config: Option<PathBuf>,
    /// Record contacts and markers only, no frames (cannot be replayed).
    #[arg(long)]
    no_frames: bool,
    /// Record one frame in N per fingertip (contacts: every frame).
    #[arg(long, default_value_t = 1, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..))]
    frame_every: u32,
}

fn record_inner(args: &RecordArgs) -> anyhow::Result<()> {
    let params = crate::shared::sources::load_sensor_config(args.config.as_deref())?;
    let deadline_ms = match args.duration_s {
        Some(s) if s.is_finite() && s > 0.0 => Some((s * 1e3) as u64),
        Some(_) => return Err(anyhow!("--duration-s must be positive")),
        None => None,
    };
    let stop = Arc::new(AtomicBool::new(false));
    crate::shared::stop_on_ctrl_c(&stop);
    let mut cameras = Vec::new();
    let setups = crate::shared::sources::open(
        &args.sources,
        std::slice::from_ref(&params),
        1..=2,
        &stop,
        &mut cameras,
    )?;
    let labels: Vec<String> = setups.iter().map(|s| s.label.clone()).collect();
    let (sensors, rests) =
        crate::shared::sources::calibrated(setups, std::slice::from_ref(&params))?;
    let recorder = open_recorder(
        &args.out,
        "record",
        &format!("dexitac record: {}", labels.join(", ")),
        &rests,
        args.config.as_deref(),
        &params,
        !args.no_frames,
        args.frame_every,
    )?
    .spawn();
    let clock = Clock::wall();
    let spinner = crate::shared::progress::spinner("recording (Ctrl-C stops)");
    let results = dexitac_rig::sensor_loop::sensor_threads(
        sensors,
        clock,
        deadline_ms,
        &stop,
        &recorder.sender(),
    );
    spinner.finish_and_clear();
    let stats = recorder.finish().map_err(|e| anyhow!("recording: {e}"))?;
    crate::shared::sources::print_camera_stats("record", &cameras);
    for r in &results {
        if let Err(e) = r {
            tracing::info!("dexitac record: {e}");
        }
    }
    println!("{}", describe(&stats, &args.out));
    if results.iter().any(Result::is_err) {
        return Err(anyhow!(
            "a sensor failed (the frames before it are recorded)"
        ));
    }
    Ok(())
}

impl RecordArgs {
    /// Runs `dexitac record`.
    pub fn run(&self) -> anyhow::Result<Outcome> {
        record_inner(self)?;
        Ok(Outcome::Success)
    }
}
