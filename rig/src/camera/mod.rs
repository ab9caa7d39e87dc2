//! Tactile cameras: a DigiTac fingertip is a UVC USB camera (MJPEG or YUYV,
//! 640x480 typical). [`CameraSource`] turns any [`RawDevice`] into a
//! [`FrameSource`] for the task loop:
//!
//! ```text
//! RawDevice (V4L2 or fake) -> capture thread -> one-slot mailbox -> next_frame: decode -> frame::prepare
//!                              warm-up drop      (latest buffer        (luma only)       (working grey)
//!                              lost -> reopen     only; older ones
//!                              with backoff       are counted dropped)
//! ```
//!
//! - **Freshest frame**: the capture thread dequeues every buffer as it
//!   arrives and keeps only the newest in the mailbox; a buffer the
//!   consumer did not take in time is replaced and counted in
//!   [`CameraStats::dropped_stale`]. Decoding happens in the consumer, only
//!   for frames that are used.
//! - **Warm-up**: the first [`CameraConfig::warmup_frames`] buffers after
//!   each (re)open are dropped (auto exposure settles).
//! - **Timestamps**: the driver's capture time when the device gives one,
//!   else the time the capture thread received the buffer, converted to the
//!   loop's [`Clock`] when the frame is handed out.
//! - **Unplug**: an error or no buffer for [`CameraConfig::frame_timeout_ms`]
//!   makes the capture thread close the device and reopen it with
//!   exponential backoff ([`CameraConfig::reconnect_min_ms`] ..
//!   [`CameraConfig::reconnect_max_ms`]), reporting
//!   [`CameraEvent::Lost`] and [`CameraEvent::Recovered`]. The source does not
//!   end the run on its own: `next_frame` waits, and returns `None` only
//!   once the stop flag given to [`CameraSource::open`] (the Ctrl-C flag in
//!   `dexitac run`) is set, [`CameraSource::halt`] is called, or its
//!   [`FrameSource::halt_handle`] is called: the task loop does that when it
//!   ends (after sealing and disarming the gripper), so a run that ends on
//!   an error while a camera is lost does not wait for the camera.
//! - **Errors**: opening reports a typed [`CameraError`] (missing, busy,
//!   no permission, not a capture device, no usable format).
//!
//! The V4L2 device ([`v4l2`], Linux) uses the `linuxvideo` crate (plain
//! ioctls, no C library or bindgen at build time). [`fake::FakeDevice`]
//! plays a recorded stream with scripted unplugs, so every part above is
//! tested without hardware.

pub mod decode;
pub mod fake;
#[cfg(target_os = "linux")]
pub mod v4l2;

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::source::{Clock, FrameSource, HaltHandle, SourceError, TimedFrame};
use dexitac_tactile::frame::{self, RawFrame};
use dexitac_tactile::params::FrameParams;

/// Default number of buffers dropped after each (re)open.
pub const DEFAULT_WARMUP_FRAMES: u32 = 5;
/// Default time without a buffer after which the camera counts as lost, ms.
pub const DEFAULT_FRAME_TIMEOUT_MS: u64 = 2_000;
/// Default first reopen delay, ms (doubles per failed attempt).
pub const DEFAULT_RECONNECT_MIN_MS: u64 = 100;
/// Default longest reopen delay, ms.
pub const DEFAULT_RECONNECT_MAX_MS: u64 = 2_000;
/// Default number of corrupt frames in a row after which `next_frame` fails.
pub const DEFAULT_MAX_CORRUPT_IN_ROW: u32 = 30;
/// How often waiting threads look at their stop flag, ms.
const POLL_SLICE_MS: u64 = 50;

/// A camera pixel format this module decodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PixelFormat {
    /// Motion JPEG: one JPEG per buffer (FourCC `MJPG`).
    Mjpeg,
    /// YUV 4:2:2 packed `Y0 U Y1 V` (FourCC `YUYV`).
    Yuyv,
    /// 8-bit grey (FourCC `GREY`).
    Grey,
}

impl PixelFormat {
    /// Every format, in the default order of preference.
    pub const ALL: [PixelFormat; 3] = [PixelFormat::Mjpeg, PixelFormat::Yuyv, PixelFormat::Grey];

    /// The V4L2 FourCC.
    pub const fn fourcc(self) -> [u8; 4] {
        match self {
            PixelFormat::Mjpeg => *b"MJPG",
            PixelFormat::Yuyv => *b"YUYV",
            PixelFormat::Grey => *b"GREY",
        }
    }

    /// The format of a FourCC (`JPEG` counts as MJPEG), if decodable.
    pub fn from_fourcc(fourcc: [u8; 4]) -> Option<Self> {
        match &fourcc {
            b"MJPG" | b"JPEG" => Some(PixelFormat::Mjpeg),
            b"YUYV" => Some(PixelFormat::Yuyv),
            b"GREY" => Some(PixelFormat::Grey),
            _ => None,
        }
    }
}

impl fmt::Display for PixelFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            PixelFormat::Mjpeg => "MJPEG",
            PixelFormat::Yuyv => "YUYV",
            PixelFormat::Grey => "GREY",
        })
    }
}

impl FromStr for PixelFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "mjpeg" | "mjpg" | "jpeg" => Ok(PixelFormat::Mjpeg),
            "yuyv" | "yuy2" => Ok(PixelFormat::Yuyv),
            "grey" | "gray" => Ok(PixelFormat::Grey),
            _ => Err(format!("unknown pixel format {s:?} (mjpeg, yuyv or grey)")),
        }
    }
}

/// A camera by device path (`/dev/video2`) or index (`2` = `/dev/video2`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DeviceId {
    /// A device node.
    Path(PathBuf),
    /// `/dev/video<N>`.
    Index(u32),
}

impl DeviceId {
    /// The device node.
    pub fn path(&self) -> PathBuf {
        match self {
            DeviceId::Path(p) => p.clone(),
            DeviceId::Index(i) => PathBuf::from(format!("/dev/video{i}")),
        }
    }
}

impl FromStr for DeviceId {
    type Err = String;
    /// All digits: an index; anything else: a path.
    fn from_str(s: &str) -> Result<Self, String> {
        if s.is_empty() {
            return Err("empty camera device".into());
        }
        if s.bytes().all(|b| b.is_ascii_digit()) {
            s.parse()
                .map(DeviceId::Index)
                .map_err(|_| format!("camera index {s} is too large"))
        } else {
            Ok(DeviceId::Path(PathBuf::from(s)))
        }
    }
}

impl fmt::Display for DeviceId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.path().display())
    }
}

/// What to ask the driver for.
#[derive(Debug, Clone, PartialEq)]
pub struct CaptureRequest {
    /// Frame width, px.
    pub width_px: u32,
    /// Frame height, px.
    pub height_px: u32,
    /// Frames per second.
    pub fps: f64,
    /// Acceptable formats, most preferred first.
    pub formats: Vec<PixelFormat>,
}

impl Default for CaptureRequest {
    /// 640x480 at 30 fps, MJPEG (least USB bandwidth: two cameras on one
    /// bus), else YUYV, else GREY.
    fn default() -> Self {
        CaptureRequest {
            width_px: dexitac_tactile::params::WORK_WIDTH_PX,
            height_px: dexitac_tactile::params::WORK_HEIGHT_PX,
            fps: 30.0,
            formats: PixelFormat::ALL.to_vec(),
        }
    }
}

/// What the driver granted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    /// Pixel format.
    pub format: PixelFormat,
    /// Frame width, px.
    pub width_px: u32,
    /// Frame height, px.
    pub height_px: u32,
    /// Bytes per line (YUYV, GREY; 0: packed).
    pub stride_bytes: usize,
    /// Frames per second, when the driver reports it.
    pub fps: Option<f64>,
}

impl fmt::Display for Mode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} {}x{}", self.format, self.width_px, self.height_px)?;
        match self.fps {
            Some(fps) => write!(f, " at {fps:.1} fps"),
            None => write!(f, " (fps not reported)"),
        }
    }
}

/// One dequeued buffer's metadata (its bytes went into the caller's `Vec`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BufferInfo {
    /// Capture time from the driver, if it gives one.
    pub captured: Option<Instant>,
    /// Older buffers the device layer discarded to return this newest one.
    pub skipped: u32,
    /// The driver flagged the buffer as possibly corrupt.
    pub flagged: bool,
}

/// Why a camera could not be opened or read.
#[derive(Debug, thiserror::Error)]
pub enum CameraError {
    /// No such device node.
    #[error("{device}: no such camera (is it plugged in? `dexitac cameras` lists them)")]
    NotFound {
        /// The device node.
        device: PathBuf,
    },
    /// Another program is using the camera.
    #[error("{device}: camera is busy (another program is streaming from it; close it or pick another device)")]
    Busy {
        /// The device node.
        device: PathBuf,
    },
    /// No permission to open the device.
    #[error("{device}: permission denied (add your user to the `video` group)")]
    PermissionDenied {
        /// The device node.
        device: PathBuf,
    },
    /// The node is not a V4L2 video capture device.
    #[error("{device}: not a video capture device ({what})")]
    NotCapture {
        /// The device node.
        device: PathBuf,
        /// What it is instead.
        what: String,
    },
    /// The device offers none of the requested formats.
    #[error("{device}: no usable pixel format (asked for {wanted}; the device offers {offered})")]
    NoFormat {
        /// The device node.
        device: PathBuf,
        /// The requested formats.
        wanted: String,
        /// What the device offers.
        offered: String,
    },
    /// The device disappeared while streaming (unplugged).
    #[error("{device}: camera disconnected")]
    Disconnected {
        /// The device node.
        device: PathBuf,
    },
    /// No buffer arrived in time.
    #[error("{device}: no frame for {waited_ms} ms")]
    Timeout {
        /// The device node.
        device: PathBuf,
        /// How long it waited, ms.
        waited_ms: u64,
    },
    /// Any other system error.
    #[error("{device}: {op}: {source}")]
    Io {
        /// The device node.
        device: PathBuf,
        /// What was being done.
        op: &'static str,
        /// The error.
        source: std::io::Error,
    },
    /// Cameras are not supported on this platform.
    #[error("camera capture is only supported on Linux (V4L2)")]
    Unsupported,
    /// The capture settings are not usable.
    #[error("camera settings: {0}")]
    Config(String),
}

impl CameraError {
    /// Maps a system error of `op` on `device` to the typed error.
    pub fn from_io(device: &Path, op: &'static str, e: std::io::Error) -> Self {
        let device = device.to_path_buf();
        match e.raw_os_error() {
            Some(libc::ENOENT) => CameraError::NotFound { device },
            Some(libc::EBUSY) => CameraError::Busy { device },
            Some(libc::EACCES) | Some(libc::EPERM) => CameraError::PermissionDenied { device },
            Some(libc::ENODEV) | Some(libc::ENXIO) => CameraError::Disconnected { device },
            Some(libc::ENOTTY) => CameraError::NotCapture {
                device,
                what: "not a V4L2 device".into(),
            },
            _ => CameraError::Io {
                device,
                op,
                source: e,
            },
        }
    }
}

/// The raw camera: opened and streaming, it hands out buffers.
///
/// Implemented by the V4L2 device and by [`fake::FakeDevice`].
pub trait RawDevice: Send {
    /// The device's name for messages (its path).
    fn name(&self) -> String;
    /// Opens the device and starts streaming in the best mode for
    /// `request`; returns what the driver granted. Opening an open device
    /// closes it first.
    fn open(&mut self, request: &CaptureRequest) -> Result<Mode, CameraError>;
    /// Waits at most `timeout` for the next buffer and copies it into
    /// `data` (cleared first). `Ok(None)`: nothing within `timeout`.
    fn next_buffer(
        &mut self,
        data: &mut Vec<u8>,
        timeout: Duration,
    ) -> Result<Option<BufferInfo>, CameraError>;
    /// Stops streaming and releases the device.
    fn close(&mut self);
}

/// Settings of a [`CameraSource`].
#[derive(Debug, Clone, PartialEq)]
pub struct CameraConfig {
    /// Mode asked of the driver.
    pub request: CaptureRequest,
    /// Buffers dropped after each (re)open.
    pub warmup_frames: u32,
    /// No buffer for this long: the camera is lost, ms.
    pub frame_timeout_ms: u64,
    /// First reopen delay, ms.
    pub reconnect_min_ms: u64,
    /// Longest reopen delay, ms.
    pub reconnect_max_ms: u64,
    /// `next_frame` fails after this many undecodable frames in a row.
    pub max_corrupt_in_row: u32,
}

impl Default for CameraConfig {
    fn default() -> Self {
        CameraConfig {
            request: CaptureRequest::default(),
            warmup_frames: DEFAULT_WARMUP_FRAMES,
            frame_timeout_ms: DEFAULT_FRAME_TIMEOUT_MS,
            reconnect_min_ms: DEFAULT_RECONNECT_MIN_MS,
            reconnect_max_ms: DEFAULT_RECONNECT_MAX_MS,
            max_corrupt_in_row: DEFAULT_MAX_CORRUPT_IN_ROW,
        }
    }
}

impl CameraConfig {
    /// Checks the settings.
    pub fn validate(&self) -> Result<(), CameraError> {
        let r = &self.request;
        let bad = |s: String| Err(CameraError::Config(s));
        if !(1..=frame::MAX_SIDE_PX as u32).contains(&r.width_px)
            || !(1..=frame::MAX_SIDE_PX as u32).contains(&r.height_px)
        {
            return bad(format!("size {}x{} px", r.width_px, r.height_px));
        }
        if !(r.fps.is_finite() && r.fps > 0.0 && r.fps <= 1_000.0) {
            return bad(format!("fps {} must lie in (0, 1000]", r.fps));
        }
        if r.formats.is_empty() {
            return bad("no pixel format requested".into());
        }
        if self.frame_timeout_ms == 0 || self.reconnect_min_ms == 0 {
            return bad("frame_timeout_ms and reconnect_min_ms must be > 0".into());
        }
        if self.reconnect_max_ms < self.reconnect_min_ms {
            return bad("reconnect_max_ms must be >= reconnect_min_ms".into());
        }
        Ok(())
    }
}

/// What the camera reports as it runs.
#[derive(Debug, Clone, PartialEq)]
pub enum CameraEvent {
    /// The camera was lost (unplugged, stalled, failing); reopening.
    Lost {
        /// The device.
        device: String,
        /// Why.
        reason: String,
    },
    /// The camera streams again.
    Recovered {
        /// The device.
        device: String,
        /// The granted mode.
        mode: Mode,
        /// Reopen attempts it took.
        attempts: u32,
    },
}

impl fmt::Display for CameraEvent {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CameraEvent::Lost { device, reason } => {
                write!(f, "camera {device} lost ({reason}); reconnecting")
            }
            CameraEvent::Recovered {
                device,
                mode,
                attempts,
            } => write!(
                f,
                "camera {device} recovered after {attempts} attempt(s): {mode}"
            ),
        }
    }
}

/// Counters of a [`CameraSource`] (shared with its capture thread).
#[derive(Debug, Default)]
pub struct CameraStats {
    /// Buffers received from the device.
    pub received: AtomicU64,
    /// Frames handed to the consumer.
    pub delivered: AtomicU64,
    /// Buffers dropped because a newer one arrived before the consumer
    /// asked (including those the device layer skipped).
    pub dropped_stale: AtomicU64,
    /// Buffers dropped as warm-up.
    pub dropped_warmup: AtomicU64,
    /// Buffers that could not be decoded.
    pub corrupt: AtomicU64,
    /// Times the camera was lost.
    pub lost: AtomicU64,
    /// Times it was reopened.
    pub recovered: AtomicU64,
}

impl CameraStats {
    fn add(counter: &AtomicU64, n: u64) {
        counter.fetch_add(n, Ordering::Relaxed);
    }

    /// A counter's value.
    pub fn get(counter: &AtomicU64) -> u64 {
        counter.load(Ordering::Relaxed)
    }
}

/// A buffer waiting in the mailbox.
struct Captured {
    data: Vec<u8>,
    mode: Mode,
    captured: Instant,
}

#[derive(Default)]
struct Slot {
    latest: Option<Captured>,
    /// A consumed buffer's allocation, for the capture thread to reuse.
    spare: Option<Vec<u8>>,
}

struct Shared {
    slot: Mutex<Slot>,
    ready: Condvar,
    /// Set by [`CameraSource::halt`] and on drop.
    halt: AtomicBool,
    /// The caller's stop flag (Ctrl-C).
    stop: Option<Arc<AtomicBool>>,
    stats: Arc<CameraStats>,
    events: Mutex<Option<Sender<CameraEvent>>>,
}

impl Shared {
    fn stopped(&self) -> bool {
        self.halt.load(Ordering::Relaxed)
            || self
                .stop
                .as_ref()
                .is_some_and(|s| s.load(Ordering::Relaxed))
    }

    fn slot(&self) -> MutexGuard<'_, Slot> {
        // A poisoned lock means the other thread panicked while holding
        // it; the slot is still a valid Option, so go on with it.
        self.slot.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn report(&self, event: CameraEvent) {
        let events = self.events.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(tx) = events.as_ref() {
            // A gone receiver only means nobody listens any more.
            let _ = tx.send(event);
        }
    }
}

/// A camera as the task loop's [`FrameSource`] (see the [module docs](self)).
pub struct CameraSource {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    mode: Mode,
    name: String,
    frame_params: FrameParams,
    max_corrupt_in_row: u32,
    corrupt_in_row: u32,
}

impl CameraSource {
    /// Opens `device` (errors here are the device's: missing, busy, no
    /// format...), then starts the capture thread. Frames are prepared with
    /// `frame_params` (grey, crop, working size). Once `stop` (e.g. the
    /// Ctrl-C flag) is set, `next_frame` returns `None` within ~50 ms and
    /// the capture thread ends, even while the camera is lost.
    pub fn open(
        mut device: Box<dyn RawDevice>,
        config: &CameraConfig,
        frame_params: &FrameParams,
        stop: Option<Arc<AtomicBool>>,
    ) -> Result<Self, CameraError> {
        config.validate()?;
        let mode = device.open(&config.request)?;
        let name = device.name();
        let shared = Arc::new(Shared {
            slot: Mutex::new(Slot::default()),
            ready: Condvar::new(),
            halt: AtomicBool::new(false),
            stop,
            stats: Arc::new(CameraStats::default()),
            events: Mutex::new(None),
        });
        let capture = Capture {
            device,
            config: config.clone(),
            shared: Arc::clone(&shared),
            mode,
        };
        let thread = std::thread::Builder::new()
            .name(format!("camera {name}"))
            .spawn(move || capture.run())
            .map_err(|e| CameraError::Io {
                device: PathBuf::from(&name),
                op: "start the capture thread",
                source: e,
            })?;
        Ok(CameraSource {
            shared,
            thread: Some(thread),
            mode,
            name,
            frame_params: frame_params.clone(),
            max_corrupt_in_row: config.max_corrupt_in_row,
            corrupt_in_row: 0,
        })
    }

    /// The mode the driver granted at the first open.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// The device's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The counters (stay readable after the source moved into the loop).
    pub fn stats(&self) -> Arc<CameraStats> {
        Arc::clone(&self.shared.stats)
    }

    /// Stops the capture thread; a waiting `next_frame` returns `None`
    /// within ~50 ms (as when the `stop` flag given to
    /// [`CameraSource::open`] is set).
    pub fn halt(&self) {
        self.shared.halt.store(true, Ordering::Relaxed);
    }

    /// Sends [`CameraEvent`]s (lost, recovered) to `tx`.
    pub fn report_to(&self, tx: Sender<CameraEvent>) {
        *self.shared.events.lock().unwrap_or_else(|p| p.into_inner()) = Some(tx);
    }

    /// The newest buffer, waiting for one; `None` once stopped.
    fn take_latest(&self) -> Option<Captured> {
        let mut slot = self.shared.slot();
        loop {
            if self.shared.stopped() {
                return None;
            }
            if let Some(c) = slot.latest.take() {
                return Some(c);
            }
            slot = self
                .shared
                .ready
                .wait_timeout(slot, Duration::from_millis(POLL_SLICE_MS))
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
    }

    /// Decodes and prepares the freshest frame; `Ok(None)` once stopped.
    /// Corrupt frames are skipped (and counted) up to
    /// [`CameraConfig::max_corrupt_in_row`] in a row.
    pub fn next_prepared(&mut self) -> Result<Option<(Instant, frame::GreyFrame)>, SourceError> {
        loop {
            let Some(c) = self.take_latest() else {
                return Ok(None);
            };
            let decoded = decode::to_grey(&c.data, &c.mode);
            self.shared.slot().spare = Some(c.data);
            match decoded {
                Ok(grey) => {
                    self.corrupt_in_row = 0;
                    let raw = RawFrame {
                        width: grey.width(),
                        height: grey.height(),
                        channels: 1,
                        data: grey.data(),
                    };
                    let prepared = frame::prepare(&raw, &self.frame_params)?;
                    CameraStats::add(&self.shared.stats.delivered, 1);
                    return Ok(Some((c.captured, prepared.grey)));
                }
                Err(e) => {
                    CameraStats::add(&self.shared.stats.corrupt, 1);
                    self.corrupt_in_row += 1;
                    if self.corrupt_in_row >= self.max_corrupt_in_row.max(1) {
                        return Err(SourceError::Decode {
                            path: PathBuf::from(&self.name),
                            reason: format!(
                                "{} corrupt frames in a row, last: {e}",
                                self.corrupt_in_row
                            ),
                        });
                    }
                }
            }
        }
    }
}

/// Opens a V4L2 camera as a [`CameraSource`] (see [`CameraSource::open`]).
pub fn open_camera(
    id: &DeviceId,
    config: &CameraConfig,
    frame_params: &FrameParams,
    stop: Option<Arc<AtomicBool>>,
) -> Result<CameraSource, CameraError> {
    #[cfg(target_os = "linux")]
    {
        let device = v4l2::V4l2Device::new(&id.path());
        CameraSource::open(Box::new(device), config, frame_params, stop)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (id, config, frame_params, stop);
        Err(CameraError::Unsupported)
    }
}

/// `instant` on `clock` (ms), `now` being the same moment as `clock.now_ms()`
/// (on virtual time, which wall-clock instants do not map to: now).
pub fn clock_ms_at(clock: &Clock, instant: Instant, now: Instant) -> u64 {
    let speed = if clock.is_virtual() {
        0.0
    } else {
        clock.speed()
    };
    let age_ms = now.saturating_duration_since(instant).as_secs_f64() * 1e3 * speed;
    (clock.now_ms() as f64 - age_ms).max(0.0) as u64
}

impl FrameSource for CameraSource {
    fn next_frame(&mut self, clock: &Clock) -> Result<Option<TimedFrame>, SourceError> {
        let Some((captured, frame)) = self.next_prepared()? else {
            return Ok(None);
        };
        let t_ms = clock_ms_at(clock, captured, Instant::now());
        Ok(Some(TimedFrame { t_ms, frame }))
    }

    fn halt_handle(&self) -> Option<HaltHandle> {
        let shared = Arc::clone(&self.shared);
        Some(Box::new(move || shared.halt.store(true, Ordering::Relaxed)))
    }
}

impl Drop for CameraSource {
    fn drop(&mut self) {
        self.halt();
        if let Some(t) = self.thread.take() {
            // A panicked capture thread has nothing left to clean up.
            let _ = t.join();
        }
    }
}

/// The capture thread's state.
struct Capture {
    device: Box<dyn RawDevice>,
    config: CameraConfig,
    shared: Arc<Shared>,
    mode: Mode,
}

impl Capture {
    fn stopped(&self) -> bool {
        self.shared.stopped()
    }

    fn run(mut self) {
        let stats = Arc::clone(&self.shared.stats);
        let slice = Duration::from_millis(POLL_SLICE_MS.min(self.config.frame_timeout_ms));
        let mut warmup = self.config.warmup_frames;
        let mut idle = Duration::ZERO;
        let mut buf = Vec::new();
        while !self.stopped() {
            match self.device.next_buffer(&mut buf, slice) {
                Ok(Some(info)) => {
                    let received = Instant::now();
                    idle = Duration::ZERO;
                    CameraStats::add(&stats.received, 1 + info.skipped as u64);
                    CameraStats::add(&stats.dropped_stale, info.skipped as u64);
                    if warmup > 0 {
                        warmup -= 1;
                        CameraStats::add(&stats.dropped_warmup, 1);
                        continue;
                    }
                    if info.flagged {
                        CameraStats::add(&stats.corrupt, 1);
                        continue;
                    }
                    let mut slot = self.shared.slot();
                    let next = slot.spare.take().unwrap_or_default();
                    let old = slot.latest.replace(Captured {
                        data: std::mem::replace(&mut buf, next),
                        mode: self.mode,
                        captured: info.captured.unwrap_or(received),
                    });
                    if let Some(old) = old {
                        CameraStats::add(&stats.dropped_stale, 1);
                        slot.spare = Some(old.data);
                    }
                    drop(slot);
                    self.shared.ready.notify_all();
                }
                Ok(None) => {
                    idle += slice;
                    if idle.as_millis() as u64 >= self.config.frame_timeout_ms {
                        let e = CameraError::Timeout {
                            device: PathBuf::from(self.device.name()),
                            waited_ms: idle.as_millis() as u64,
                        };
                        self.reconnect(&e);
                        idle = Duration::ZERO;
                        warmup = self.config.warmup_frames;
                    }
                }
                Err(e) => {
                    self.reconnect(&e);
                    idle = Duration::ZERO;
                    warmup = self.config.warmup_frames;
                }
            }
        }
        self.device.close();
    }

    /// Closes the device and reopens it with backoff until it streams again
    /// or the source is stopped.
    fn reconnect(&mut self, why: &CameraError) {
        let stats = Arc::clone(&self.shared.stats);
        CameraStats::add(&stats.lost, 1);
        self.device.close();
        self.shared.report(CameraEvent::Lost {
            device: self.device.name(),
            reason: why.to_string(),
        });
        let mut delay_ms = self.config.reconnect_min_ms;
        let mut attempts = 0;
        loop {
            if !self.sleep_unless_stopped(Duration::from_millis(delay_ms)) {
                return;
            }
            attempts += 1;
            match self.device.open(&self.config.request) {
                Ok(mode) => {
                    self.mode = mode;
                    CameraStats::add(&stats.recovered, 1);
                    self.shared.report(CameraEvent::Recovered {
                        device: self.device.name(),
                        mode,
                        attempts,
                    });
                    return;
                }
                Err(_) => {
                    delay_ms = (delay_ms * 2).min(self.config.reconnect_max_ms);
                }
            }
        }
    }

    /// Sleeps `d` in slices; false when stopped meanwhile.
    fn sleep_unless_stopped(&self, d: Duration) -> bool {
        let end = Instant::now() + d;
        loop {
            if self.stopped() {
                return false;
            }
            let now = Instant::now();
            if now >= end {
                return true;
            }
            std::thread::sleep((end - now).min(Duration::from_millis(POLL_SLICE_MS)));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::fake::{FakeDevice, FakeFailure};
    use super::*;
    use dexitac_tactile::frame::GreyFrame;
    use std::sync::mpsc;

    const W: u32 = 16;
    const H: u32 = 8;

    /// A frame whose first four pixels hold `seq` (little endian).
    fn stamped(seq: u32) -> GreyFrame {
        let mut data = vec![40u8; (W * H) as usize];
        data[..4].copy_from_slice(&seq.to_le_bytes());
        GreyFrame::new(W as usize, H as usize, data).unwrap()
    }

    fn stamp_of(frame: &GreyFrame) -> u32 {
        u32::from_le_bytes(frame.data()[..4].try_into().unwrap())
    }

    /// YUYV buffers stamped 0..n.
    fn yuyv_stream(n: u32) -> Vec<Vec<u8>> {
        (0..n).map(|i| decode::pack_yuyv(&stamped(i))).collect()
    }

    fn params() -> FrameParams {
        FrameParams {
            work_width_px: W,
            work_height_px: H,
            ..FrameParams::default()
        }
    }

    fn config(warmup: u32) -> CameraConfig {
        CameraConfig {
            warmup_frames: warmup,
            reconnect_min_ms: 10,
            reconnect_max_ms: 40,
            ..CameraConfig::default()
        }
    }

    fn next_stamp(cam: &mut CameraSource) -> u32 {
        stamp_of(&cam.next_frame(&Clock::wall()).unwrap().unwrap().frame)
    }

    #[test]
    fn only_the_newest_of_many_waiting_buffers_is_handed_out() {
        const N: u32 = 200;
        let fake = FakeDevice::new(PixelFormat::Yuyv, W, H, yuyv_stream(N))
            .period(Duration::from_micros(200))
            .once();
        let mut cam = CameraSource::open(Box::new(fake), &config(0), &params(), None).unwrap();
        let stats = cam.stats();
        let t0 = Instant::now();
        while CameraStats::get(&stats.received) < N as u64 {
            assert!(
                t0.elapsed() < Duration::from_secs(20),
                "the fake stopped early"
            );
            std::thread::sleep(Duration::from_millis(5));
        }
        // Every buffer has arrived and none was taken: only the last counts.
        assert_eq!(next_stamp(&mut cam), N - 1);
        assert_eq!(CameraStats::get(&stats.dropped_stale), N as u64 - 1);
        assert_eq!(CameraStats::get(&stats.delivered), 1);
    }

    #[test]
    fn freshest_frame_with_a_fast_producer_and_a_slow_consumer() {
        let fake = FakeDevice::new(PixelFormat::Yuyv, W, H, yuyv_stream(100_000))
            .period(Duration::from_millis(1));
        let produced = fake.counters();
        let mut cam = CameraSource::open(Box::new(fake), &config(0), &params(), None).unwrap();
        let mut last = None;
        for _ in 0..6 {
            std::thread::sleep(Duration::from_millis(30));
            let before = CameraStats::get(&produced.produced);
            let seq = next_stamp(&mut cam) as u64;
            // The newest buffer when we asked is at `before - 1` (the
            // capture thread may still be publishing it: allow a few). A
            // queue would hand out frames ~30 behind.
            assert!(seq + 5 >= before, "got frame {seq}, {before} produced");
            if let Some(l) = last {
                assert!(seq > l, "frame {seq} after {l}");
            }
            last = Some(seq);
        }
        let stats = cam.stats();
        assert_eq!(CameraStats::get(&stats.delivered), 6);
        assert!(CameraStats::get(&stats.dropped_stale) > 0);
    }

    #[test]
    fn warmup_frames_are_dropped() {
        let fake = FakeDevice::new(PixelFormat::Yuyv, W, H, yuyv_stream(1000))
            .period(Duration::from_millis(2));
        let mut cam = CameraSource::open(Box::new(fake), &config(7), &params(), None).unwrap();
        assert!(next_stamp(&mut cam) >= 7);
        assert_eq!(CameraStats::get(&cam.stats().dropped_warmup), 7);
    }

    #[test]
    fn unplug_is_reported_and_the_camera_reopened() {
        let fake = FakeDevice::new(PixelFormat::Yuyv, W, H, yuyv_stream(1000))
            .period(Duration::from_millis(2))
            .unplug_after(10, Duration::from_millis(150));
        let counters = fake.counters();
        let mut cam = CameraSource::open(Box::new(fake), &config(3), &params(), None).unwrap();
        let (tx, rx) = mpsc::channel();
        cam.report_to(tx);
        let mut stamps = Vec::new();
        while stamps.last().is_none_or(|&s| s < 20) {
            stamps.push(next_stamp(&mut cam));
        }
        // Warm-up again after the reopen: frames 10, 11, 12 are dropped.
        assert!(
            stamps.iter().all(|&s| (3..10).contains(&s) || s >= 13),
            "{stamps:?}"
        );
        assert!(stamps.iter().any(|&s| s >= 13));
        let events: Vec<CameraEvent> = rx.try_iter().collect();
        assert!(
            matches!(&events[..], [CameraEvent::Lost { reason, .. }, CameraEvent::Recovered { attempts, .. }]
                if reason.contains("disconnected") && *attempts >= 1),
            "{events:?}"
        );
        assert_eq!(CameraStats::get(&counters.opens), 2);
        let stats = cam.stats();
        assert_eq!(
            (
                CameraStats::get(&stats.lost),
                CameraStats::get(&stats.recovered)
            ),
            (1, 1)
        );
    }

    #[test]
    fn a_stalled_camera_times_out_and_is_reopened() {
        let fake = FakeDevice::new(PixelFormat::Yuyv, W, H, yuyv_stream(1))
            .period(Duration::from_secs(3600));
        let counters = fake.counters();
        let cfg = CameraConfig {
            frame_timeout_ms: 60,
            ..config(0)
        };
        let cam = CameraSource::open(Box::new(fake), &cfg, &params(), None).unwrap();
        let (tx, rx) = mpsc::channel();
        cam.report_to(tx);
        let lost = rx.recv_timeout(Duration::from_secs(5)).unwrap();
        assert!(
            matches!(&lost, CameraEvent::Lost { reason, .. } if reason.contains("no frame for")),
            "{lost:?}"
        );
        let back = rx.recv_timeout(Duration::from_secs(5)).unwrap();
        assert!(matches!(back, CameraEvent::Recovered { .. }), "{back:?}");
        assert!(CameraStats::get(&counters.opens) >= 2);
    }

    /// Opens a camera unplugged for an hour (with the caller's `stop`
    /// flag), has another thread call what `end` returns after 100 ms, and
    /// checks that the waiting `next_frame` returns `None` soon.
    fn a_lost_camera_wait_ends(
        stop: Option<Arc<AtomicBool>>,
        end: impl FnOnce(&CameraSource) -> HaltHandle,
    ) {
        let fake = FakeDevice::new(PixelFormat::Yuyv, W, H, yuyv_stream(10))
            .unplug_after(0, Duration::from_secs(3600));
        let mut cam = CameraSource::open(Box::new(fake), &config(0), &params(), stop).unwrap();
        let trigger = end(&cam);
        let setter = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(100));
            trigger();
        });
        let t0 = Instant::now();
        assert!(cam.next_frame(&Clock::wall()).unwrap().is_none());
        assert!(t0.elapsed() < Duration::from_secs(5));
        setter.join().unwrap();
        // Dropping joins the capture thread: it must have seen the signal too.
        drop(cam);
    }

    #[test]
    fn the_halt_handle_ends_a_wait_for_a_lost_camera() {
        a_lost_camera_wait_ends(None, |cam| {
            cam.halt_handle().expect("a camera can be halted")
        });
    }

    #[test]
    fn the_stop_flag_ends_a_wait_for_a_lost_camera() {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = Arc::clone(&stop);
        a_lost_camera_wait_ends(Some(stop), move |_| {
            Box::new(move || flag.store(true, Ordering::Relaxed))
        });
    }

    #[test]
    fn open_errors_are_typed_and_say_what_to_do() {
        let open = |fake: FakeDevice, formats: Vec<PixelFormat>| {
            let mut cfg = config(0);
            cfg.request.formats = formats;
            CameraSource::open(Box::new(fake.named("/dev/video7")), &cfg, &params(), None)
        };
        let busy = open(
            FakeDevice::new(PixelFormat::Yuyv, W, H, yuyv_stream(1)).fail_open(FakeFailure::Busy),
            PixelFormat::ALL.to_vec(),
        )
        .err()
        .unwrap();
        assert!(matches!(busy, CameraError::Busy { .. }));
        assert!(
            busy.to_string().contains("/dev/video7: camera is busy"),
            "{busy}"
        );
        let missing = open(
            FakeDevice::new(PixelFormat::Yuyv, W, H, yuyv_stream(1))
                .fail_open(FakeFailure::NotFound),
            PixelFormat::ALL.to_vec(),
        )
        .err()
        .unwrap();
        assert!(missing.to_string().contains("no such camera"), "{missing}");
        let no_format = open(
            FakeDevice::new(PixelFormat::Yuyv, W, H, yuyv_stream(1)),
            vec![PixelFormat::Mjpeg],
        )
        .err()
        .unwrap();
        assert_eq!(
            no_format.to_string(),
            "/dev/video7: no usable pixel format (asked for MJPEG; the device offers YUYV)"
        );
        let bad_fps = {
            let mut cfg = config(0);
            cfg.request.fps = 0.0;
            CameraSource::open(
                Box::new(FakeDevice::new(PixelFormat::Yuyv, W, H, yuyv_stream(1))),
                &cfg,
                &params(),
                None,
            )
            .err()
            .unwrap()
        };
        assert!(matches!(bad_fps, CameraError::Config(_)), "{bad_fps}");
    }

    #[test]
    fn system_errors_map_to_typed_errors() {
        let dev = Path::new("/dev/video3");
        let of =
            |errno| CameraError::from_io(dev, "open", std::io::Error::from_raw_os_error(errno));
        assert!(matches!(of(libc::EBUSY), CameraError::Busy { .. }));
        assert!(matches!(of(libc::ENOENT), CameraError::NotFound { .. }));
        assert!(matches!(
            of(libc::EACCES),
            CameraError::PermissionDenied { .. }
        ));
        assert!(matches!(of(libc::ENODEV), CameraError::Disconnected { .. }));
        assert!(matches!(of(libc::ENOTTY), CameraError::NotCapture { .. }));
        assert!(matches!(of(libc::EINVAL), CameraError::Io { .. }));
        assert!(of(libc::EBUSY)
            .to_string()
            .starts_with("/dev/video3: camera is busy"));
    }

    #[test]
    fn corrupt_frames_are_skipped_and_counted_then_fail_the_source() {
        let good = decode::encode_mjpeg(&stamped(1), 90).unwrap();
        let bad = good[..good.len() / 3].to_vec();
        let fake = FakeDevice::new(PixelFormat::Mjpeg, W, H, vec![bad.clone(), good])
            .period(Duration::from_millis(20));
        let mut cam = CameraSource::open(Box::new(fake), &config(0), &params(), None).unwrap();
        for _ in 0..3 {
            assert!(cam.next_frame(&Clock::wall()).unwrap().is_some());
        }
        assert!(CameraStats::get(&cam.stats().corrupt) >= 2);
        let fake =
            FakeDevice::new(PixelFormat::Mjpeg, W, H, vec![bad]).period(Duration::from_millis(1));
        let cfg = CameraConfig {
            max_corrupt_in_row: 5,
            ..config(0)
        };
        let mut cam = CameraSource::open(Box::new(fake), &cfg, &params(), None).unwrap();
        let e = cam.next_frame(&Clock::wall()).unwrap_err();
        assert!(e.to_string().contains("5 corrupt frames in a row"), "{e}");
    }

    #[test]
    fn driver_timestamps_date_the_frame_on_the_loop_clock() {
        let clock = Clock::wall();
        std::thread::sleep(Duration::from_millis(400));
        let fake = FakeDevice::new(PixelFormat::Yuyv, W, H, yuyv_stream(10))
            .period(Duration::from_millis(5))
            .driver_timestamps(Duration::from_millis(300));
        let mut cam = CameraSource::open(Box::new(fake), &config(0), &params(), None).unwrap();
        let f = cam.next_frame(&clock).unwrap().unwrap();
        assert!(
            f.t_ms + 300 <= clock.now_ms(),
            "{} vs {}",
            f.t_ms,
            clock.now_ms()
        );
        // Without driver times: the receive time, just before now.
        let fake = FakeDevice::new(PixelFormat::Yuyv, W, H, yuyv_stream(10))
            .period(Duration::from_millis(5));
        let mut cam = CameraSource::open(Box::new(fake), &config(0), &params(), None).unwrap();
        let f = cam.next_frame(&clock).unwrap().unwrap();
        assert!(f.t_ms <= clock.now_ms() && f.t_ms + 1_000 > clock.now_ms());
    }

    #[test]
    fn clock_conversion_scales_the_age() {
        let clock = Clock::scaled(10.0);
        std::thread::sleep(Duration::from_millis(50));
        let now = Instant::now();
        let then = now - Duration::from_millis(20);
        let at = clock_ms_at(&clock, then, now);
        let t_now = clock.now_ms();
        // 20 wall ms = 200 clock ms before now.
        // (Loose upper bound: this thread may be descheduled in between.)
        assert!(at + 195 <= t_now && at + 2_000 >= t_now, "{at} vs {t_now}");
        assert_eq!(clock_ms_at(&Clock::wall(), then, now), 0);
    }

    #[test]
    fn a_recorded_mjpeg_stream_calibrates_like_its_source_frames() {
        use dexitac_tactile::synth::{rest_frame, SensorSpec};
        let sensor = SensorSpec::nominal(640, 480);
        let frames: Vec<GreyFrame> = (0..3).map(|s| rest_frame(&sensor, s).image).collect();
        let stream: Vec<Vec<u8>> = frames
            .iter()
            .map(|f| decode::encode_mjpeg(f, 90).unwrap())
            .collect();
        let fake =
            FakeDevice::new(PixelFormat::Mjpeg, 640, 480, stream).period(Duration::from_millis(5));
        let params = dexitac_tactile::params::Params::default();
        let mut cam = CameraSource::open(Box::new(fake), &config(0), &params.frame, None).unwrap();
        let got: Vec<GreyFrame> = (0..3)
            .map(|_| cam.next_frame(&Clock::wall()).unwrap().unwrap().frame)
            .collect();
        let from_camera = dexitac_tactile::calibrate::calibrate(&got, &params).unwrap();
        let from_files = dexitac_tactile::calibrate::calibrate(&frames, &params).unwrap();
        let (a, b) = (
            from_camera.rest_markers.len(),
            from_files.rest_markers.len(),
        );
        assert!(
            a.abs_diff(b) <= b / 50,
            "{a} markers through MJPEG, {b} from the frames"
        );
    }

    #[test]
    fn device_ids_parse_as_index_or_path() {
        assert_eq!(
            "2".parse::<DeviceId>().unwrap().path(),
            Path::new("/dev/video2")
        );
        assert_eq!(
            "/dev/v4l/by-id/usb-DIGIT".parse::<DeviceId>().unwrap(),
            DeviceId::Path(PathBuf::from("/dev/v4l/by-id/usb-DIGIT"))
        );
        assert!("".parse::<DeviceId>().is_err());
        assert!("99999999999999999999".parse::<DeviceId>().is_err());
        assert_eq!("YUY2".parse::<PixelFormat>().unwrap(), PixelFormat::Yuyv);
        assert!("h264".parse::<PixelFormat>().is_err());
        for f in PixelFormat::ALL {
            assert_eq!(PixelFormat::from_fourcc(f.fourcc()), Some(f));
        }
    }
}
