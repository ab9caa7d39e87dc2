//! `dexitac record` (sensors only: frames -> pipeline -> MCAP), `dexitac
//! replay` (the pipeline again over a recording, compared), and the
//! `--record` flags of `sim` and `run`. Format and topics:
//! `host/RECORDING.md`, `dexitac_rig::recording`.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use dexitac_rig::event::{RuntimeEvent, SensorReport};
use dexitac_rig::recording::replay::{self, Replay};
use dexitac_rig::recording::{
    ReadError, RecordOptions, RecordStats, Recorder, RecorderThread, Recording,
};
use dexitac_rig::source::{Clock, FrameSource};
use dexitac_rig::task_loop::Sensor;
use dexitac_tactile::frame::GreyFrame;
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;

/// The recording flags of `dexitac sim` and `dexitac run`.
#[derive(Debug, clap::Args)]
pub struct RecordFlags {
    /// Record the run to this MCAP file (topics: host/RECORDING.md).
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
) -> Result<Option<RecorderThread>, String> {
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
fn open_recorder(
    path: &Path,
    source: &str,
    description: &str,
    rests: &[Vec<GreyFrame>],
    sensor_config: Option<&Path>,
    params: &Params,
    frames: bool,
    frame_every: u32,
) -> Result<Recorder<std::io::BufWriter<std::fs::File>>, String> {
    let sensor_config_toml = sensor_config
        .map(|p| {
            std::fs::read_to_string(p).map_err(|e| format!("cannot read {}: {e}", p.display()))
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
    let mut recorder = Recorder::create(path, options).map_err(|e| format!("recording: {e}"))?;
    for (sensor, rest) in rests.iter().enumerate() {
        recorder
            .write_rest(sensor, rest)
            .map_err(|e| format!("recording: {e}"))?;
    }
    Ok(recorder)
}

/// Finishes the recording (if any) and prints what it holds.
pub fn finish_recorder(
    recorder: Option<RecorderThread>,
    flags: &RecordFlags,
) -> Result<(), String> {
    let (Some(recorder), Some(path)) = (recorder, &flags.record) else {
        return Ok(());
    };
    let stats = recorder.finish().map_err(|e| format!("recording: {e}"))?;
    eprintln!("{}", describe(&stats, path));
    Ok(())
}

/// One line: counts, size, rate and write cost.
fn describe(stats: &RecordStats, path: &Path) -> String {
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

/// Arguments of `dexitac record`.
#[derive(Debug, clap::Args)]
pub struct RecordArgs {
    /// The MCAP file to write.
    #[arg(long, value_name = "FILE.mcap")]
    out: PathBuf,
    #[command(flatten)]
    sources: crate::commands::sources::SourceArgs,
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

/// One sensor: frames through the pipeline to the recorder until the
/// source ends, the deadline passes or `stop` is set.
pub(crate) fn sensor_loop(
    sensor: usize,
    mut source: Box<dyn FrameSource>,
    pipeline: &Pipeline,
    clock: Clock,
    deadline_ms: Option<u64>,
    stop: &AtomicBool,
    tx: &std::sync::mpsc::Sender<RuntimeEvent>,
) -> Result<u64, String> {
    let mut n = 0;
    while !stop.load(Ordering::Relaxed) {
        let Some(frame) = source
            .next_frame(&clock)
            .map_err(|e| format!("sensor {sensor}: {e}"))?
        else {
            break;
        };
        if deadline_ms.is_some_and(|d| frame.t_ms > d) {
            break;
        }
        let result = pipeline
            .run(&frame.frame)
            .map_err(|e| format!("sensor {sensor}: frame at {} ms: {e}", frame.t_ms))?;
        let event = RuntimeEvent::Observation(SensorReport::new(
            sensor,
            frame.t_ms,
            pipeline,
            &result,
            Some(frame.frame),
        ));
        if tx.send(event).is_err() {
            return Err("the recorder stopped".into());
        }
        n += 1;
    }
    Ok(n)
}

/// Runs [`sensor_loop`] for each sensor on a thread of its own, all
/// sending to `tx`; a failing sensor sets `stop`, which ends the others.
/// Returns each sensor's frame count or failure, in sensor order.
pub(crate) fn sensor_threads(
    sensors: Vec<Sensor>,
    clock: Clock,
    deadline_ms: Option<u64>,
    stop: &AtomicBool,
    tx: &std::sync::mpsc::Sender<RuntimeEvent>,
) -> Vec<Result<u64, String>> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = sensors
            .into_iter()
            .enumerate()
            .map(|(sensor, s)| {
                let tx = tx.clone();
                scope.spawn(move || {
                    let r =
                        sensor_loop(sensor, s.source, &s.pipeline, clock, deadline_ms, stop, &tx);
                    if r.is_err() {
                        stop.store(true, Ordering::Relaxed);
                    }
                    r
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err("a sensor thread panicked".into()))
            })
            .collect()
    })
}

fn record_inner(args: &RecordArgs) -> Result<(), String> {
    let params = match &args.config {
        Some(path) => Params::load(path).map_err(|e| e.to_string())?,
        None => Params::default(),
    };
    let deadline_ms = match args.duration_s {
        Some(s) if s.is_finite() && s > 0.0 => Some((s * 1e3) as u64),
        Some(_) => return Err("--duration-s must be positive".into()),
        None => None,
    };
    let stop = Arc::new(AtomicBool::new(false));
    crate::commands::sim::stop_on_ctrl_c(&stop);
    let mut cameras = Vec::new();
    let setups =
        crate::commands::sources::open(&args.sources, &params, 1..=2, &stop, &mut cameras)?;
    let labels: Vec<String> = setups.iter().map(|s| s.label.clone()).collect();
    let (sensors, rests) = crate::commands::sources::calibrated(setups, &params)?;
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
    let results = sensor_threads(sensors, clock, deadline_ms, &stop, &recorder.sender());
    let stats = recorder.finish().map_err(|e| format!("recording: {e}"))?;
    crate::commands::sources::print_camera_stats("record", &cameras);
    for r in &results {
        if let Err(e) = r {
            eprintln!("dexitac record: {e}");
        }
    }
    println!("{}", describe(&stats, &args.out));
    if results.iter().any(Result::is_err) {
        return Err("a sensor failed (the frames before it are recorded)".into());
    }
    Ok(())
}

/// Runs `dexitac record`.
pub fn run_record(args: &RecordArgs) -> ExitCode {
    match record_inner(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(msg) => {
            eprintln!("dexitac record: {msg}");
            ExitCode::from(2)
        }
    }
}

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

fn write_csv(path: &Path, replay: &Replay) -> Result<(), String> {
    let err = |e: std::io::Error| format!("{}: {e}", path.display());
    let mut w = std::io::BufWriter::new(std::fs::File::create(path).map_err(err)?);
    writeln!(
        w,
        "sensor,t_ms,recorded_x_px,recorded_y_px,replayed_x_px,replayed_y_px,diff_px,agreement"
    )
    .map_err(err)?;
    let f = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
    for c in &replay.comparisons {
        let agreement = if !c.recorded_present {
            "unmatched"
        } else if c.disagrees() {
            "disagree"
        } else {
            "agree"
        };
        writeln!(
            w,
            "{},{},{},{},{},{},{},{agreement}",
            c.sensor,
            c.t_ms,
            f(c.recorded.map(|p| p.x)),
            f(c.recorded.map(|p| p.y)),
            f(c.replayed.map(|p| p.x)),
            f(c.replayed.map(|p| p.y)),
            f(c.diff_px()),
        )
        .map_err(err)?;
    }
    w.flush().map_err(err)
}

fn replay_inner(args: &ReplayArgs) -> Result<bool, String> {
    if !(args.tolerance_px.is_finite() && args.tolerance_px >= 0.0) {
        return Err("--tolerance-px must be >= 0".into());
    }
    let recording = Recording::open(&args.file, args.recover).map_err(|e| match e {
        ReadError::Damaged { .. } => format!("{e} (replay them with --recover)"),
        e => e.to_string(),
    })?;
    if let Some(damage) = &recording.damage {
        eprintln!("dexitac replay: warning: {damage}");
    }
    let stored = recording
        .session
        .as_ref()
        .and_then(|s| s.sensor_config_toml.as_deref());
    let (params, from) = match (&args.config, stored) {
        (Some(path), _) => (
            Params::load(path).map_err(|e| e.to_string())?,
            path.display().to_string(),
        ),
        (None, Some(text)) => (
            Params::from_toml_str(text).map_err(|e| format!("stored sensor config: {e}"))?,
            "the recording's sensor config".to_string(),
        ),
        (None, None) => (Params::default(), "default parameters".to_string()),
    };
    let out = replay::replay(&recording, &params, args.rest_frames as usize)
        .map_err(|e| e.to_string())?;
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

/// Runs `dexitac replay`: 0 same, 1 different, 2 error.
pub fn run_replay(args: &ReplayArgs) -> ExitCode {
    match replay_inner(args) {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(msg) => {
            eprintln!("dexitac replay: {msg}");
            ExitCode::from(2)
        }
    }
}
