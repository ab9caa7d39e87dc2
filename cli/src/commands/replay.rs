//! `dexitac replay`: the pipeline again over a recording's frames, the
//! contact centres compared with the recorded ones.

use crate::exit::Outcome;
use anyhow::anyhow;
use std::path::{Path, PathBuf};

use dexitac_rig::recording::replay::{self, Replay};
use dexitac_rig::recording::{ReadError, Recording};
use dexitac_tactile::params::Params;

/// Arguments of `dexitac replay`.
#[derive(Debug, clap::Args)]
pub struct ReplayArgs {
    /// The recording (MCAP, from `record`, or `sim`/`run` with --record-frames).
    #[arg(value_name = "FILE.mcap")]
    file: PathBuf,
    /// Sensor config (TOML); default: the one stored in the recording, else
    /// the paper's parameters.
    #[arg(long, value_name = "SENSOR.toml")]
    config: Option<PathBuf>,
    /// Per-frame comparison CSV.
    #[arg(long, value_name = "CMP.csv")]
    out: Option<PathBuf>,
    /// Largest accepted centre difference, px (exit status 1 beyond it or on
    /// any found/lost disagreement).
    #[arg(long, default_value_t = 0.0)]
    tolerance_px: f64,
    /// Read a damaged or unfinished file up to the damage.
    #[arg(long)]
    recover: bool,
    /// Without recorded rest frames: calibrate on this many first frames.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=100))]
    rest_frames: u64,
}

fn write_csv(path: &Path, replay: &Replay) -> anyhow::Result<()> {
    let err = |e: std::io::Error| anyhow!("{}: {e}", path.display());
    let csv_err = |e: csv::Error| anyhow!("cannot write {}: {e}", path.display());
    let mut w = csv::Writer::from_path(path).map_err(csv_err)?;
    for c in &replay.comparisons {
        let agreement = if !c.recorded_present {
            "unmatched"
        } else if c.disagrees() {
            "disagree"
        } else {
            "agree"
        };
        w.serialize(ComparisonRow {
            sensor: c.sensor,
            t_ms: c.t_ms,
            recorded_x_px: c.recorded.map(|p| p.x),
            recorded_y_px: c.recorded.map(|p| p.y),
            replayed_x_px: c.replayed.map(|p| p.x),
            replayed_y_px: c.replayed.map(|p| p.y),
            diff_px: c.diff_px(),
            agreement,
        })
        .map_err(csv_err)?;
    }
    w.flush().map_err(err)
}

/// One row of `--out`: a recorded and a replayed centre of one frame
/// (empty cells without a contact).
#[derive(serde::Serialize)]
struct ComparisonRow {
    sensor: usize,
    t_ms: u64,
    recorded_x_px: Option<f64>,
    recorded_y_px: Option<f64>,
    replayed_x_px: Option<f64>,
    replayed_y_px: Option<f64>,
    diff_px: Option<f64>,
    agreement: &'static str,
}

fn replay_inner(args: &ReplayArgs) -> anyhow::Result<bool> {
    if !(args.tolerance_px.is_finite() && args.tolerance_px >= 0.0) {
        return Err(anyhow!("--tolerance-px must be >= 0"));
    }
    let recording = Recording::open(&args.file, args.recover).map_err(|e| match e {
        ReadError::Damaged { .. } => anyhow!("{e} (replay them with --recover)"),
        e => anyhow!(e),
    })?;
    if let Some(damage) = &recording.damage {
        tracing::warn!("dexitac replay: {damage}");
    }
    let stored = recording
        .session
        .as_ref()
        .and_then(|s| s.sensor_config_toml.as_deref());
    let (params, from) = match (&args.config, stored) {
        (Some(path), _) => (
            Params::load(path).map_err(|e| anyhow!("{e}"))?,
            path.display().to_string(),
        ),
        (None, Some(text)) => (
            Params::from_toml_str(text).map_err(|e| anyhow!("stored sensor config: {e}"))?,
            "the recording's sensor config".to_string(),
        ),
        (None, None) => (Params::default(), "default parameters".to_string()),
    };
    let spinner = crate::shared::progress::spinner("replaying the recording's frames");
    let out = replay::replay(&recording, &params, args.rest_frames as usize)
        .map_err(|e| anyhow!("{e}"))?;
    spinner.finish_and_clear();
    if let Some(path) = &args.out {
        write_csv(path, &out)?;
    }
    let s = &out.summary;
    println!("replay of {} with {from}:", args.file.display());
    for (sensor, on) in &s.calibrated_on {
        println!("  sensor {sensor}: calibrated on {on}");
    }
    println!(
        "  {} frame(s): {} with a contact in both, {} in neither, {} found/lost disagreement(s), {} without a recorded contact",
        s.frames, s.both_found, s.neither_found, s.disagreements, s.unmatched
    );
    println!(
        "  centre difference: max {:.6} px, median {:.6} px, p95 {:.6} px (tolerance {} px)",
        s.max_px, s.median_px, s.p95_px, args.tolerance_px
    );
    let same = s.within(args.tolerance_px);
    println!(
        "  {}",
        if same {
            "the replay reproduces the recording"
        } else {
            "the replay DIFFERS from the recording"
        }
    );
    Ok(same)
}

impl ReplayArgs {
    /// Runs `dexitac replay`: [`Outcome::Negative`] when the centres differ.
    pub fn run(&self) -> anyhow::Result<Outcome> {
        Ok(Outcome::from_ok(replay_inner(self)?))
    }
}
