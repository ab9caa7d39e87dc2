//! `dexitac run`: the task loop on the real gripper.
//!
//! Frame sources until the camera driver lands: `--frames DIR` (twice, one
//! per fingertip; every PNG/JPEG in name order, the first one is the rest
//! frame the pipeline is calibrated on, then one frame per `--fps` period),
//! or `--render` (the simulator's camera showing a steady contact, to
//! exercise the board and the link without cameras).
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
//! kind = "twist"                   # pour | rotate | shake | twist (dexitac::manipulation)
//! stroke_ms = 4000
//! pause_ms = 2500
//! cycles = 2
//! edge_x_mm = 9.0
//! ```

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::AtomicBool;
use std::sync::mpsc;
use std::sync::Arc;

use serde::Deserialize;

use dexitac::calibrate;
use dexitac::frame::{self, GreyFrame, RawFrame};
use dexitac::grasp::GraspParams;
use dexitac::link::{Link, LinkConfig};
use dexitac::params::Params;
use dexitac::pipeline::Pipeline;
use dexitac::runtime::{
    self, Clock, ControlConfig, FrameSource, RuntimeEvent, Sensor, SourceError, TimedFrame,
};
use dexitac::sim::plant::ContactState;
use dexitac::sim::render::Renderer;
use dexitac::synth::SensorSpec;
use dexitac_protocol::CHAMBER_COUNT;

/// Arguments of `dexitac run`.
#[derive(Debug, clap::Args)]
pub struct RunArgs {
    /// Serial port of the board (e.g. /dev/ttyUSB0).
    #[arg(long, value_name = "PATH")]
    port: PathBuf,
    /// Gripper configuration (TOML).
    #[arg(long, value_name = "GRIPPER.toml")]
    config: PathBuf,
    /// A directory of frames per fingertip (give it twice: sensor 0, sensor 1).
    #[arg(long, value_name = "DIR", num_args = 1)]
    frames: Vec<PathBuf>,
    /// Frames per second for --frames.
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    /// Use the simulator's camera (a steady contact) instead of --frames.
    #[arg(long, conflicts_with = "frames")]
    render: bool,
    #[command(flatten)]
    record: crate::cli_record::RecordFlags,
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
    /// `[task]` table of a simulator scenario, `dexitac::manipulation`).
    task: Option<dexitac::manipulation::TaskParams>,
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
    fn load(path: &Path) -> Result<Self, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        let config: GripperConfig =
            toml::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        if let Some(task) = &config.task {
            task.validate().map_err(|(field, value, reason)| {
                format!("{}: {field} = {value}: {reason}", path.display())
            })?;
        }
        let g = &config.grasp;
        let finite_pos = |v: f64| v.is_finite() && v > 0.0;
        if !(finite_pos(g.stable_shift_mm) && finite_pos(g.slip_shift_mm))
            || g.slip_shift_mm <= g.stable_shift_mm
        {
            return Err(format!(
                "{}: grasp thresholds must be positive with slip_shift_mm > stable_shift_mm",
                path.display()
            ));
        }
        if config.grasp_chambers.is_empty()
            || config.grasp_chambers.iter().any(|&c| c >= CHAMBER_COUNT)
        {
            return Err(format!(
                "{}: grasp_chambers must name chambers 0..{CHAMBER_COUNT}",
                path.display()
            ));
        }
        if !config.open_loop_close_s.is_finite() || config.open_loop_close_s < 0.0 {
            return Err(format!(
                "{}: open_loop_close_s must be >= 0",
                path.display()
            ));
        }
        Ok(config)
    }

    fn control(&self) -> Result<ControlConfig, String> {
        let kpa_to_pa = |v: f64| {
            if v.is_finite() && v.abs() < 1e3 {
                Ok((v * 1e3).round() as i32)
            } else {
                Err(format!("tank pressure {v} kPa is not usable"))
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

/// Frames from a directory, one per period.
struct DirSource {
    files: Vec<PathBuf>,
    next: usize,
    period_ms: u64,
    next_ms: u64,
    params: Params,
}

fn image_files(dir: &Path) -> Result<Vec<PathBuf>, String> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| format!("cannot list {}: {e}", dir.display()))?
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.extension()
                .and_then(|e| e.to_str())
                .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"))
        })
        .collect();
    files.sort();
    if files.len() < 2 {
        return Err(format!(
            "{}: needs a rest frame and at least one more frame",
            dir.display()
        ));
    }
    Ok(files)
}

fn load_frame(path: &Path, params: &Params) -> Result<GreyFrame, SourceError> {
    let img = image::open(path)
        .map_err(|e| SourceError::Decode {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?
        .into_luma8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let data = img.into_raw();
    let raw = RawFrame {
        width: w,
        height: h,
        channels: 1,
        data: &data,
    };
    Ok(frame::prepare(&raw, &params.frame)?.grey)
}

impl FrameSource for DirSource {
    fn next_frame(&mut self, clock: &Clock) -> Result<Option<TimedFrame>, SourceError> {
        let Some(path) = self.files.get(self.next).cloned() else {
            return Ok(None);
        };
        self.next += 1;
        clock.sleep_until(self.next_ms);
        let t_ms = clock.now_ms();
        self.next_ms = t_ms.max(self.next_ms) + self.period_ms;
        let frame = load_frame(&path, &self.params)?;
        Ok(Some(TimedFrame { t_ms, frame }))
    }
}

/// The simulator's camera with a steady contact.
struct SteadySource {
    renderer: Renderer,
    contact: ContactState,
    period_ms: u64,
    next_ms: u64,
}

impl FrameSource for SteadySource {
    fn next_frame(&mut self, clock: &Clock) -> Result<Option<TimedFrame>, SourceError> {
        clock.sleep_until(self.next_ms);
        let t_ms = clock.now_ms();
        self.next_ms = t_ms.max(self.next_ms) + self.period_ms;
        Ok(Some(TimedFrame {
            t_ms,
            frame: self.renderer.render(Some(&self.contact)),
        }))
    }
}

/// `--fps` as a frame period, ms.
pub(crate) fn period_ms(fps: f64) -> Result<u64, String> {
    if fps.is_finite() && fps > 0.1 && fps <= 1_000.0 {
        Ok((1e3 / fps) as u64)
    } else {
        Err("--fps must lie in 0.1..=1000".into())
    }
}

/// The simulator's camera for `finger` with a steady contact, and the rest
/// frames to calibrate on.
pub(crate) fn steady_source(
    finger: usize,
    params: &Params,
    period_ms: u64,
) -> (Box<dyn FrameSource>, Vec<GreyFrame>) {
    let mut renderer = Renderer::new(
        SensorSpec::nominal(640, 480),
        params.frame.mm_per_px,
        finger as u64 + 1,
    );
    let rest = vec![renderer.render(None), renderer.render(None)];
    let source = SteadySource {
        renderer,
        contact: ContactState {
            centre_mm: [0.0, 0.0],
            shear_mm: [0.0, 0.0],
            normal_n: 1.5,
            width_mm: 2.5,
        },
        period_ms,
        next_ms: 0,
    };
    (Box::new(source), rest)
}

/// The frames of `dir` (the first is the rest frame, returned apart).
pub(crate) fn dir_source(
    dir: &Path,
    params: &Params,
    period_ms: u64,
) -> Result<(Box<dyn FrameSource>, GreyFrame), String> {
    let files = image_files(dir)?;
    let rest = load_frame(&files[0], params).map_err(|e| e.to_string())?;
    let source = DirSource {
        files: files[1..].to_vec(),
        next: 0,
        period_ms,
        next_ms: 0,
        params: params.clone(),
    };
    Ok((Box::new(source), rest))
}

/// The sensors and the rest frames each was calibrated on.
fn sensors(args: &RunArgs, params: &Params) -> Result<(Vec<Sensor>, Vec<Vec<GreyFrame>>), String> {
    let period_ms = period_ms(args.fps)?;
    let mut sources = Vec::new();
    if args.render {
        for finger in 0..2 {
            let (source, rest) = steady_source(finger, params, period_ms);
            sources.push((source, rest, format!("simulated sensor {finger}")));
        }
    } else if args.frames.len() != 2 {
        return Err("give --frames twice (one directory per fingertip) or --render".into());
    } else {
        for dir in &args.frames {
            let (source, rest) = dir_source(dir, params, period_ms)?;
            sources.push((source, vec![rest], format!("{}", dir.display())));
        }
    }
    let mut out = Vec::new();
    let mut rests = Vec::new();
    for (source, rest, label) in sources {
        let cal =
            calibrate::calibrate(&rest, params).map_err(|e| format!("{label}: rest frame: {e}"))?;
        out.push(Sensor {
            source,
            pipeline: Pipeline::new(cal, params.clone()),
        });
        rests.push(rest);
    }
    Ok((out, rests))
}

fn run_inner(args: &RunArgs) -> Result<(), String> {
    let config = GripperConfig::load(&args.config)?;
    let params = match &config.sensor_config {
        Some(path) => Params::load(path).map_err(|e| e.to_string())?,
        None => Params::default(),
    };
    let control = ControlConfig {
        share_frames: args.record.record_frames,
        ..config.control()?
    };
    let (sensors, rests) = sensors(args, &params)?;
    let link_config = LinkConfig {
        baud: config.baud,
        ..LinkConfig::default()
    };
    let mut link = Link::open(&args.port, link_config).map_err(|e| e.to_string())?;
    let stop = Arc::new(AtomicBool::new(false));
    crate::cli_sim::stop_on_ctrl_c(&stop);
    let recorder = crate::cli_record::start_recorder(
        &args.record,
        "run",
        &format!("dexitac run --port {}", args.port.display()),
        &rests,
        config.sensor_config.as_deref(),
        &params,
    )?;
    let tap = recorder.as_ref().map(|r| r.sender());
    let (tx, rx) = mpsc::channel::<RuntimeEvent>();
    let printer = std::thread::spawn(move || {
        for event in rx {
            if let Some(tap) = &tap {
                // A failed recorder reports its error when finished.
                let _ = tap.send(event.clone());
            }
            match event {
                RuntimeEvent::CommandSent {
                    t_ms, msg, reason, ..
                } => {
                    eprintln!("{:9.3} s  {reason}: {msg:?}", t_ms as f64 / 1e3);
                }
                RuntimeEvent::Task { t_ms, event } => {
                    eprintln!("{:9.3} s  task: {event:?}", t_ms as f64 / 1e3);
                }
                RuntimeEvent::Stopped {
                    t_ms,
                    outcome,
                    max_loop_gap,
                } => {
                    eprintln!(
                        "{:9.3} s  stopped: {outcome:?} (longest loop stall {:.1} ms)",
                        t_ms as f64 / 1e3,
                        max_loop_gap.as_secs_f64() * 1e3
                    );
                }
                _ => {}
            }
        }
    });
    let result = runtime::run(&control, &mut link, sensors, Clock::wall(), &stop, &tx);
    drop(tx);
    if printer.join().is_err() {
        eprintln!("dexitac run: the event printer failed");
    }
    let recorded = crate::cli_record::finish_recorder(recorder, &args.record);
    result.map_err(|e| e.to_string())?;
    recorded
}

/// Runs the subcommand.
pub fn run(args: &RunArgs) -> ExitCode {
    match run_inner(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(msg) => {
            eprintln!("dexitac run: {msg}");
            ExitCode::from(2)
        }
    }
}
