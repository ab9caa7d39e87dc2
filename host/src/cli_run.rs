//! `dexitac run`: the task loop on the real gripper.
//!
//! Frame sources (give one per fingertip, twice):
//! - `--camera DEV` (a V4L2 camera by path or index, `dexitac cameras`
//!   lists them): `--camera-size`, `--fps`, `--camera-format`, `--warmup`;
//!   the first `--rest-frames` frames after warm-up are the rest frames the
//!   pipeline is calibrated on, so nothing may touch the fingertips at
//!   start. A camera that is unplugged is reopened (stderr says "lost" and
//!   "recovered"); the run goes on meanwhile without its frames.
//! - `--frames DIR`: every PNG/JPEG in name order, the first one is the rest
//!   frame, then one frame per `--fps` period, or at the times in the file
//!   names with `--recorded-times` (`dexitac::sources`), or with no pause
//!   with `--max-speed`.
//! - `--render`: the simulator's camera showing a steady contact, to
//!   exercise the board and the link without cameras.
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
use dexitac::camera::{CameraConfig, CameraStats, CaptureRequest, DeviceId, PixelFormat};
use dexitac::grasp::GraspParams;
use dexitac::link::{Link, LinkConfig};
use dexitac::params::Params;
use dexitac::pipeline::Pipeline;
use dexitac::runtime::{
    self, Clock, ControlConfig, FrameSource, RuntimeEvent, Sensor, SourceError, TimedFrame,
};
use dexitac::sim::plant::ContactState;
use dexitac::sim::render::Renderer;
use dexitac::sources::{self, FolderSource, Pace};
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
    /// Frames per second for --frames, and asked of --camera.
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    /// --frames: pace by the `<N>ms` times in the file names (else --fps).
    #[arg(long, conflicts_with = "max_speed")]
    recorded_times: bool,
    /// --frames: no pause between frames.
    #[arg(long)]
    max_speed: bool,
    /// Use the simulator's camera (a steady contact) instead of --frames.
    #[arg(long, conflicts_with_all = ["frames", "camera"])]
    render: bool,
    /// A camera per fingertip, by path or index (give it twice: sensor 0,
    /// sensor 1). Prefer the stable /dev/v4l/by-id/... names: a replugged
    /// camera may come back as another /dev/videoN.
    #[arg(long, value_name = "DEV", num_args = 1, conflicts_with = "frames")]
    camera: Vec<String>,
    /// Camera frame size asked of the driver.
    #[arg(long, value_name = "WxH", default_value = "640x480")]
    camera_size: String,
    /// Camera pixel format (mjpeg, yuyv, grey); default: the first of these
    /// the camera offers.
    #[arg(long, value_name = "FORMAT")]
    camera_format: Option<PixelFormat>,
    /// Camera frames dropped after each (re)open.
    #[arg(long, default_value_t = dexitac::camera::DEFAULT_WARMUP_FRAMES)]
    warmup: u32,
    /// Camera frames averaged as the rest reference at start.
    #[arg(long, default_value_t = 3)]
    rest_frames: usize,
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

/// Each camera's name and counters, for the summary after the run.
type CameraStatsList = Vec<(String, Arc<CameraStats>)>;

fn sensors(
    args: &RunArgs,
    params: &Params,
    stop: &Arc<AtomicBool>,
    camera_stats: &mut CameraStatsList,
) -> Result<Vec<Sensor>, String> {
    let period_ms = if args.fps.is_finite() && args.fps > 0.1 && args.fps <= 1_000.0 {
        (1e3 / args.fps) as u64
    } else {
        return Err("--fps must lie in 0.1..=1000".into());
    };
    let mut out = Vec::new();
    if args.render {
        for finger in 0..2 {
            let mut renderer = Renderer::new(
                SensorSpec::nominal(640, 480),
                params.frame.mm_per_px,
                finger as u64 + 1,
            );
            let rest = [renderer.render(None), renderer.render(None)];
            let cal = calibrate::calibrate(&rest, params).map_err(|e| e.to_string())?;
            out.push(Sensor {
                source: Box::new(SteadySource {
                    renderer,
                    contact: ContactState {
                        centre_mm: [0.0, 0.0],
                        shear_mm: [0.0, 0.0],
                        normal_n: 1.5,
                        width_mm: 2.5,
                    },
                    period_ms,
                    next_ms: 0,
                }),
                pipeline: Pipeline::new(cal, params.clone()),
            });
        }
        return Ok(out);
    }
    if !args.camera.is_empty() {
        return camera_sensors(args, params, stop, camera_stats);
    }
    if args.frames.len() != 2 {
        return Err(
            "give --frames twice or --camera twice (one per fingertip), or --render".into(),
        );
    }
    let pace = if args.max_speed {
        Pace::Max
    } else if args.recorded_times {
        Pace::Recorded { fps: args.fps }
    } else {
        Pace::Fps(args.fps)
    };
    for dir in &args.frames {
        let files = sources::image_files(dir).map_err(|e| e.to_string())?;
        if files.len() < 2 {
            return Err(format!(
                "{}: needs a rest frame and at least one more frame",
                dir.display()
            ));
        }
        let rest = sources::load_frame(&files[0], &params.frame).map_err(|e| e.to_string())?;
        let cal = calibrate::calibrate(&[rest], params)
            .map_err(|e| format!("{}: {e}", files[0].display()))?;
        let source = FolderSource::new(files[1..].to_vec(), pace, &params.frame)
            .map_err(|e| e.to_string())?;
        out.push(Sensor {
            source: Box::new(source),
            pipeline: Pipeline::new(cal, params.clone()),
        });
    }
    Ok(out)
}

/// `640x480` -> (640, 480).
fn parse_size(text: &str) -> Result<(u32, u32), String> {
    let bad = || format!("--camera-size {text:?}: expected WIDTHxHEIGHT, e.g. 640x480");
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(bad)?;
    Ok((
        w.trim().parse().map_err(|_| bad())?,
        h.trim().parse().map_err(|_| bad())?,
    ))
}

/// Opens both cameras, calibrates each on its first frames after warm-up,
/// and prints camera events (lost, recovered) on stderr.
fn camera_sensors(
    args: &RunArgs,
    params: &Params,
    stop: &Arc<AtomicBool>,
    camera_stats: &mut CameraStatsList,
) -> Result<Vec<Sensor>, String> {
    if args.camera.len() != 2 {
        return Err("give --camera twice (one per fingertip)".into());
    }
    let (width_px, height_px) = parse_size(&args.camera_size)?;
    let config = CameraConfig {
        request: CaptureRequest {
            width_px,
            height_px,
            fps: args.fps,
            formats: args
                .camera_format
                .map_or_else(|| PixelFormat::ALL.to_vec(), |f| vec![f]),
        },
        warmup_frames: args.warmup,
        ..CameraConfig::default()
    };
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for event in rx {
            eprintln!("dexitac run: {event}");
        }
    });
    let mut out = Vec::new();
    for dev in &args.camera {
        let id: DeviceId = dev.parse()?;
        let mut cam = dexitac::camera::open_camera(&id, &config, &params.frame, Some(stop.clone()))
            .map_err(|e| e.to_string())?;
        cam.report_to(tx.clone());
        camera_stats.push((id.to_string(), cam.stats()));
        eprintln!("dexitac run: camera {id}: {}", cam.mode());
        let mut rest = Vec::new();
        while rest.len() < args.rest_frames.max(1) {
            match cam.next_prepared().map_err(|e| format!("{id}: {e}"))? {
                Some((_, frame)) => rest.push(frame),
                None => return Err("stopped before the rest frames were captured".into()),
            }
        }
        let cal = calibrate::calibrate(&rest, params).map_err(|e| {
            format!("{id}: rest frames (nothing may touch the fingertip at start): {e}")
        })?;
        out.push(Sensor {
            source: Box::new(cam),
            pipeline: Pipeline::new(cal, params.clone()),
        });
    }
    Ok(out)
}

fn run_inner(args: &RunArgs) -> Result<(), String> {
    let config = GripperConfig::load(&args.config)?;
    let params = match &config.sensor_config {
        Some(path) => Params::load(path).map_err(|e| e.to_string())?,
        None => Params::default(),
    };
    let control = config.control()?;
    let stop = Arc::new(AtomicBool::new(false));
    crate::cli_sim::stop_on_ctrl_c(&stop);
    let mut camera_stats = Vec::new();
    let sensors = sensors(args, &params, &stop, &mut camera_stats)?;
    let link_config = LinkConfig {
        baud: config.baud,
        ..LinkConfig::default()
    };
    let mut link = Link::open(&args.port, link_config).map_err(|e| e.to_string())?;
    let (tx, rx) = mpsc::channel();
    let printer = std::thread::spawn(move || {
        for event in rx {
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
    for (name, stats) in &camera_stats {
        let n = |c: &std::sync::atomic::AtomicU64| CameraStats::get(c);
        eprintln!(
            "dexitac run: camera {name}: {} frames used, {} stale dropped, {} warm-up, \
             {} corrupt, lost {} times",
            n(&stats.delivered),
            n(&stats.dropped_stale),
            n(&stats.dropped_warmup),
            n(&stats.corrupt),
            n(&stats.lost)
        );
    }
    result.map(|_| ()).map_err(|e| e.to_string())
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
