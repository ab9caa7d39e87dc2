//! Frame sources of the commands that run the tactile pipeline live
//! (`dexitac run`, `record`, `view`), chosen by one set of flags:
//!
//! - `--camera DEV` (a V4L2 camera by path or index; `dexitac cameras` lists
//!   them): `--camera-size`, `--fps`, `--camera-format`, `--warmup`; the
//!   first `--rest-frames` frames after warm-up are the rest frames the
//!   pipeline is calibrated on, so nothing may touch the fingertips at
//!   start. A camera that is unplugged is reopened (stderr says "lost" and
//!   "recovered"); the run goes on meanwhile without its frames.
//! - `--frames DIR`: every PNG/JPEG in name order, the first one is the rest
//!   frame, then one frame per `--fps` period, or at the times in the file
//!   names with `--recorded-times` (`dexitac_rig::sources`), or with no pause
//!   with `--max-speed`.
//! - `--recording FILE.mcap`: the frames of a recording made with frames
//!   (`dexitac record`, or `--record --record-frames`), every fingertip in
//!   it, at the recorded pace or with `--max-speed`; the pipeline is
//!   calibrated on the recorded rest frames (or a fingertip's first frame).
//! - `--render`: the simulator's camera showing a steady contact, to
//!   exercise the board, the link or the view without cameras.
//!
//! Give `--camera` or `--frames` once per fingertip (sensor 0, then 1).

use anyhow::anyhow;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64};
use std::sync::mpsc;
use std::sync::Arc;

use dexitac_rig::camera::{CameraConfig, CameraStats, CaptureRequest, DeviceId, PixelFormat};
use dexitac_rig::recording::{RecordedFrame, Recording, ReplaySource};
use dexitac_rig::source::{Clock, FrameSource, SourceError, TimedFrame};
use dexitac_rig::sources::{self, FolderSource, Pace};
use dexitac_rig::task_loop::Sensor;
use dexitac_sim::plant::ContactState;
use dexitac_sim::render::Renderer;
use dexitac_tactile::area::{AreaSpec, MaskImage, WorkToInput};
use dexitac_tactile::calibrate;
use dexitac_tactile::frame::{self, GreyFrame};
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::synth::SensorSpec;

/// Where the fingertip frames come from.
#[derive(Debug, Clone, clap::Args)]
pub struct SourceArgs {
    /// A directory of frames per fingertip (give it once per fingertip; the
    /// first frame in name order is the rest frame).
    #[arg(long, value_name = "DIR", num_args = 1)]
    pub frames: Vec<PathBuf>,
    /// A camera per fingertip, by path or index (give it once per
    /// fingertip). Prefer the stable /dev/v4l/by-id/... names: a replugged
    /// camera may come back as another /dev/videoN.
    #[arg(long, value_name = "DEV", num_args = 1, conflicts_with = "frames")]
    pub camera: Vec<String>,
    /// Use the simulator's cameras (a steady contact) instead.
    #[arg(long, conflicts_with_all = ["frames", "camera"])]
    pub render: bool,
    /// Replay the frames of a recording (MCAP with frames) instead.
    #[arg(long, value_name = "FILE.mcap", conflicts_with_all = ["frames", "camera", "render"])]
    pub recording: Option<PathBuf>,
    /// Frames per second for --frames and --render, and asked of --camera.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// --frames: pace by the `<N>ms` times in the file names (else --fps).
    #[arg(long, conflicts_with = "max_speed")]
    pub recorded_times: bool,
    /// --frames, --recording: no pause between frames.
    #[arg(long)]
    pub max_speed: bool,
    /// Camera frame size asked of the driver.
    #[arg(long, value_name = "WxH", default_value = "640x480")]
    pub camera_size: String,
    /// Camera pixel format (mjpeg, yuyv, grey); default: the first of these
    /// the camera offers.
    #[arg(long, value_name = "FORMAT")]
    pub camera_format: Option<PixelFormat>,
    /// Camera frames dropped after each (re)open.
    #[arg(long, default_value_t = dexitac_rig::camera::DEFAULT_WARMUP_FRAMES)]
    pub warmup: u32,
    /// Camera frames averaged as the rest reference at start.
    #[arg(long, default_value_t = 3)]
    pub rest_frames: usize,
}

/// A frame source and the rest frames its pipeline is calibrated on.
pub struct SourceSetup {
    /// The frames.
    pub source: Box<dyn FrameSource>,
    /// Its rest (no-contact) frames.
    pub rest: Vec<GreyFrame>,
    /// Working -> input pixels (a sensing area in the config is in input
    /// pixels).
    pub map: WorkToInput,
    /// For messages: the directory, camera or simulated sensor.
    pub label: String,
}

/// Each camera's name and counters, for the summary after the run.
pub type CameraStatsList = Vec<(String, Arc<CameraStats>)>;

/// `--fps` as a frame period, ms.
pub fn period_ms(fps: f64) -> anyhow::Result<u64> {
    if fps.is_finite() && fps > 0.1 && fps <= 1_000.0 {
        Ok((1e3 / fps) as u64)
    } else {
        Err(anyhow!("--fps must lie in 0.1..=1000"))
    }
}

/// The parameters of fingertip `finger`: one per fingertip, the last one
/// standing for the fingertips after it.
fn params_for(params: &[Params], finger: usize) -> &Params {
    params
        .get(finger)
        .or_else(|| params.last())
        .unwrap_or_else(|| default_params())
}

fn default_params() -> &'static Params {
    static DEFAULT: std::sync::OnceLock<Params> = std::sync::OnceLock::new();
    DEFAULT.get_or_init(Params::default)
}

/// Opens the sources; `counts` is how many fingertips the command accepts
/// (`run`: exactly 2; `record`, `view`: 1 or 2); `params` holds each
/// fingertip's pipeline parameters (see [`params_for`]). Camera counters
/// are added to `cameras`; `stop` ends a wait on a lost camera.
pub fn open(
    args: &SourceArgs,
    params: &[Params],
    counts: std::ops::RangeInclusive<usize>,
    stop: &Arc<AtomicBool>,
    cameras: &mut CameraStatsList,
) -> anyhow::Result<Vec<SourceSetup>> {
    let period_ms = period_ms(args.fps)?;
    let times = |n: usize| match n {
        1 => "once".to_string(),
        2 => "twice".to_string(),
        n => format!("{n} times"),
    };
    let how_many = if counts.start() == counts.end() {
        times(*counts.start())
    } else {
        format!("{} or {}", times(*counts.start()), times(*counts.end()))
    };
    if args.render {
        return Ok((0..*counts.end())
            .map(|finger| steady_source(finger, params_for(params, finger), period_ms))
            .collect());
    }
    if let Some(path) = &args.recording {
        let setups = recording_sources(path, !args.max_speed)?;
        if !counts.contains(&setups.len()) {
            return Err(anyhow!(
                "{}: {} fingertip(s) with frames recorded, this command takes {how_many}",
                path.display(),
                setups.len()
            ));
        }
        return Ok(setups);
    }
    if !args.camera.is_empty() {
        if !counts.contains(&args.camera.len()) {
            return Err(anyhow!("give --camera {how_many} (one per fingertip)"));
        }
        return camera_sources(args, params, stop, cameras);
    }
    if !counts.contains(&args.frames.len()) {
        return Err(anyhow!(
            "give --frames or --camera {how_many} (one per fingertip), or --render"
        ));
    }
    let pace = if args.max_speed {
        Pace::Max
    } else if args.recorded_times {
        Pace::Recorded { fps: args.fps }
    } else {
        Pace::Fps(args.fps)
    };
    args.frames
        .iter()
        .enumerate()
        .map(|(finger, dir)| {
            let params = params_for(params, finger);
            let files = sources::image_files(dir).map_err(|e| anyhow!("{e}"))?;
            if files.len() < 2 {
                return Err(anyhow!(
                    "{}: needs a rest frame and at least one more frame",
                    dir.display()
                ));
            }
            let rest = sources::load_frame(&files[0], &params.frame).map_err(|e| anyhow!("{e}"))?;
            let source = FolderSource::new(files[1..].to_vec(), pace, &params.frame)
                .map_err(|e| anyhow!("{e}"))?;
            let map = image::image_dimensions(&files[0])
                .map(|(w, h)| frame::map_for(w as usize, h as usize, &params.frame))
                .unwrap_or(WorkToInput::IDENTITY);
            Ok(SourceSetup {
                source: Box::new(source),
                rest: vec![rest],
                map,
                label: dir.display().to_string(),
            })
        })
        .collect()
}

/// Calibrates a pipeline on each source's rest frames: the sensors, and
/// the rest frames (for a recording).
pub fn calibrated(
    setups: Vec<SourceSetup>,
    params: &[Params],
) -> anyhow::Result<(Vec<Sensor>, Vec<Vec<GreyFrame>>)> {
    let mut sensors = Vec::new();
    let mut rests = Vec::new();
    for (finger, s) in setups.into_iter().enumerate() {
        let params = params_for(params, finger);
        let cal = calibrate::calibrate_mapped(&s.rest, params, s.map)
            .map_err(|e| anyhow!("{}: rest frame(s): {e}", s.label))?;
        if let Some(w) = cal.holey_rest_warning() {
            tracing::warn!("{}: {w}", s.label);
        }
        // Only `analyze` (and the Python package) magnify the working frame
        // themselves: a live source says what they would set. The rest's
        // region (its crop, or the whole input) in input px, from the map.
        let region_px = (
            (cal.width as f64 * s.map.scale_x).round() as usize,
            (cal.height as f64 * s.map.scale_y).round() as usize,
        );
        if let Some(finer) = calibrate::upscale_for(&cal, &params.frame, region_px) {
            tracing::warn!(
                "{}: the rest's pins are {:.1} px apart, under the detector's {} px: pins will \
                 be lost; set [frame] upscale = {:.2} and mm_per_px = {:.4} in the sensor config",
                s.label,
                cal.pitch_px,
                calibrate::MIN_WORKING_PITCH_PX,
                finer.upscale.unwrap_or(1.0),
                finer.mm_per_px
            );
        }
        sensors.push(Sensor {
            source: s.source,
            pipeline: Pipeline::new(cal, params.clone()),
        });
        rests.push(s.rest);
    }
    Ok((sensors, rests))
}

/// Prints each camera's counters on stderr.
pub fn print_camera_stats(command: &str, cameras: &CameraStatsList) {
    for (name, stats) in cameras {
        let n = |c: &AtomicU64| CameraStats::get(c);
        tracing::info!(
            "dexitac {command}: camera {name}: {} frames used, {} stale dropped, {} warm-up, \
             {} corrupt, lost {} times",
            n(&stats.delivered),
            n(&stats.dropped_stale),
            n(&stats.dropped_warmup),
            n(&stats.corrupt),
            n(&stats.lost)
        );
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

/// The simulator's camera for `finger` with a steady contact, and the rest
/// frames to calibrate on.
fn steady_source(finger: usize, params: &Params, period_ms: u64) -> SourceSetup {
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
    SourceSetup {
        source: Box::new(source),
        rest,
        map: WorkToInput::IDENTITY,
        label: format!("simulated sensor {finger}"),
    }
}

/// Every fingertip with frames in the recording at `path`.
fn recording_sources(path: &Path, paced: bool) -> anyhow::Result<Vec<SourceSetup>> {
    let rec = Recording::open(path, false).map_err(|e| anyhow!("{e}"))?;
    let mut out = Vec::new();
    for sensor in rec.sensors() {
        let Some(first) = rec.frames_of(sensor).next() else {
            continue;
        };
        let rest_frames: Vec<&RecordedFrame> = match rec.rest.get(&sensor) {
            Some(rest) if !rest.is_empty() => rest.iter().collect(),
            _ => vec![first],
        };
        let rest = rest_frames
            .iter()
            .map(|f| f.decode())
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| anyhow!("{}: sensor {sensor} rest frame: {e}", path.display()))?;
        out.push(SourceSetup {
            source: Box::new(ReplaySource::new(&rec, sensor, paced)),
            rest,
            map: WorkToInput::IDENTITY,
            label: format!("{} sensor {sensor}", path.display()),
        });
    }
    if out.is_empty() {
        return Err(anyhow!(
            "{}: no frames recorded (record with frames to replay them)",
            path.display()
        ));
    }
    Ok(out)
}

/// `640x480` -> (640, 480).
fn parse_size(text: &str) -> anyhow::Result<(u32, u32)> {
    let bad = || anyhow!("--camera-size {text:?}: expected WIDTHxHEIGHT, e.g. 640x480");
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(bad)?;
    Ok((
        w.trim().parse().map_err(|_| bad())?,
        h.trim().parse().map_err(|_| bad())?,
    ))
}

/// Opens the cameras, takes each one's first frames after warm-up as its
/// rest frames, and prints camera events (lost, recovered) on stderr.
fn camera_sources(
    args: &SourceArgs,
    params: &[Params],
    stop: &Arc<AtomicBool>,
    cameras: &mut CameraStatsList,
) -> anyhow::Result<Vec<SourceSetup>> {
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
            tracing::info!("dexitac: {event}");
        }
    });
    let mut out = Vec::new();
    for (finger, dev) in args.camera.iter().enumerate() {
        let params = params_for(params, finger);
        let id: DeviceId = dev.parse().map_err(|e: String| anyhow!(e))?;
        let mut cam =
            dexitac_rig::camera::open_camera(&id, &config, &params.frame, Some(stop.clone()))
                .map_err(|e| anyhow!("{e}"))?;
        cam.report_to(tx.clone());
        cameras.push((id.to_string(), cam.stats()));
        tracing::info!("dexitac: camera {id}: {}", cam.mode());
        let mut rest = Vec::new();
        while rest.len() < args.rest_frames.max(1) {
            match cam.next_prepared().map_err(|e| anyhow!("{id}: {e}"))? {
                Some((_, frame)) => rest.push(frame),
                None => return Err(anyhow!("stopped before the rest frames were captured")),
            }
        }
        let mode = cam.mode();
        out.push(SourceSetup {
            map: frame::map_for(
                mode.width_px as usize,
                mode.height_px as usize,
                &params.frame,
            ),
            source: Box::new(cam),
            rest,
            label: format!("camera {id} (nothing may touch the fingertip at start)"),
        });
    }
    Ok(out)
}

/// The sensor config at `path` (`--config SENSOR.toml`), or the paper's
/// parameters without one.
/// A mask image given as the sensing area (`[area] shape = "mask"`) is
/// read here, relative to the config file.
pub fn load_sensor_config(path: Option<&Path>) -> anyhow::Result<Params> {
    let Some(path) = path else {
        return Ok(Params::default());
    };
    let mut params = Params::load(path)?;
    if let AreaSpec::Mask { path: mask } = &params.area {
        let mask = path.parent().unwrap_or(Path::new(".")).join(mask);
        let img = image::open(&mask)
            .map_err(|e| anyhow::anyhow!("sensing-area mask {}: {e}", mask.display()))?
            .to_luma8();
        params.area_mask = Some(MaskImage {
            width: img.width() as usize,
            height: img.height() as usize,
            inside: img.into_raw().into_iter().map(|v| v > 0).collect(),
        });
    }
    Ok(params)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_or_say_what_is_expected() {
        assert_eq!(parse_size("640x480").unwrap(), (640, 480));
        assert_eq!(parse_size("320X240").unwrap(), (320, 240));
        for bad in ["640", "x480", "640x", "axb", "-1x480", ""] {
            let e = parse_size(bad).unwrap_err();
            assert!(e.to_string().contains("WIDTHxHEIGHT"), "{bad}: {e}");
        }
    }

    #[test]
    fn periods_come_from_usable_rates_only() {
        assert_eq!(period_ms(30.0).unwrap(), 33);
        assert_eq!(period_ms(1000.0).unwrap(), 1);
        for bad in [0.0, -5.0, f64::NAN, f64::INFINITY, 2000.0] {
            assert!(period_ms(bad).is_err(), "{bad}");
        }
    }
}
