//! The `--record` flags of `dexitac sim` and `dexitac run`: open the MCAP
//! recorder, write the rest frames, finish and describe the file. Format
//! and topics: `rig/RECORDING.md`, `dexitac_rig::recording`.

use anyhow::anyhow;
use std::path::{Path, PathBuf};

use dexitac_rig::recording::{RecordOptions, RecordStats, Recorder, RecorderThread};
use dexitac_tactile::frame::GreyFrame;
use dexitac_tactile::params::Params;

/// The recording flags of `dexitac sim` and `dexitac run`.
#[derive(Debug, clap::Args)]
pub struct RecordFlags {
    /// Record the run to this MCAP file (topics: rig/RECORDING.md).
    #[arg(long, value_name = "FILE.mcap")]
    pub record: Option<PathBuf>,
    /// Also record the fingertip frames (PNG; `dexitac replay` needs them).
    #[arg(long, requires = "record")]
    pub record_frames: bool,
    /// Record one frame in N per fingertip (contacts: every frame).
    #[arg(long, default_value_t = 1, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..))]
    pub record_frame_every: u32,
}

/// Opens the recording (if asked), writes the rest frames, starts its thread.
pub fn start_recorder(
    flags: &RecordFlags,
    source: &str,
    description: &str,
    rests: &[Vec<GreyFrame>],
    sensor_config: Option<&Path>,
    params: &Params,
) -> anyhow::Result<Option<RecorderThread>> {
    let Some(path) = &flags.record else {
        return Ok(None);
    };
    let recorder = open_recorder(
        path,
        source,
        description,
        rests,
        sensor_config,
        params,
        flags.record_frames,
        flags.record_frame_every,
    )?;
    Ok(Some(recorder.spawn()))
}

#[allow(clippy::too_many_arguments)]
pub fn open_recorder(
    path: &Path,
    source: &str,
    description: &str,
    rests: &[Vec<GreyFrame>],
    sensor_config: Option<&Path>,
    params: &Params,
    frames: bool,
    frame_every: u32,
) -> anyhow::Result<Recorder<std::io::BufWriter<std::fs::File>>> {
    let sensor_config_toml = sensor_config
        .map(|p| {
            std::fs::read_to_string(p).map_err(|e| anyhow!("cannot read {}: {e}", p.display()))
        })
        .transpose()?;
    let options = RecordOptions {
        source: source.into(),
        description: description.into(),
        frames,
        frame_every,
        mm_per_px: params.frame.mm_per_px,
        sensor_config_toml,
    };
    let mut recorder = Recorder::create(path, options).map_err(|e| anyhow!("recording: {e}"))?;
    for (sensor, rest) in rests.iter().enumerate() {
        recorder
            .write_rest(sensor, rest)
            .map_err(|e| anyhow!("recording: {e}"))?;
    }
    Ok(recorder)
}

/// Finishes the recording (if any) and prints what it holds.
pub fn finish_recorder(
    recorder: Option<RecorderThread>,
    flags: &RecordFlags,
) -> anyhow::Result<()> {
    let (Some(recorder), Some(path)) = (recorder, &flags.record) else {
        return Ok(());
    };
    let stats = recorder.finish().map_err(|e| anyhow!("recording: {e}"))?;
    tracing::info!("{}", describe(&stats, path));
    Ok(())
}

/// One line: counts, size, rate and write cost.
pub fn describe(stats: &RecordStats, path: &Path) -> String {
    let mb = stats.bytes as f64 / 1e6;
    let minutes = stats.span_ms as f64 / 60e3;
    let rate = if minutes > 0.0 {
        format!(", {:.1} MB/min", mb / minutes)
    } else {
        String::new()
    };
    let per = |total: std::time::Duration, n: u64| {
        if n == 0 {
            "-".to_string()
        } else {
            format!("{:.2} ms", total.as_secs_f64() * 1e3 / n as f64)
        }
    };
    let plain = stats.observations - stats.frames;
    format!(
        "recorded {} observation(s), {} frame(s), {} message(s) over {:.1} s: {mb:.2} MB{rate} \
         (write cost {} per frame, {} per observation without frame) to {}",
        stats.observations,
        stats.frames,
        stats.messages.values().sum::<u64>(),
        stats.span_ms as f64 / 1e3,
        per(stats.frame_write, stats.frames),
        per(stats.observation_write, plain),
        path.display()
    )
}
