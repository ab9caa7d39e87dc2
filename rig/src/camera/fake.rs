//! A fake camera for tests and demos: plays a recorded stream of buffers
//! (MJPEG, YUYV or GREY, e.g. made from synthetic frames with
//! [`super::decode::encode_mjpeg`] / [`super::decode::pack_yuyv`]) at a
//! fixed period, with scripted unplugs and open failures, like a UVC camera
//! would behave.
//!
//! ```
//! use dexitac_rig::camera::fake::FakeDevice;
//! use dexitac_rig::camera::{decode, PixelFormat, RawDevice, CaptureRequest};
//! use dexitac_tactile::frame::GreyFrame;
//! use std::time::Duration;
//!
//! let frame = GreyFrame::new(4, 2, vec![10, 20, 30, 40, 50, 60, 70, 80]).unwrap();
//! let mut cam = FakeDevice::new(PixelFormat::Yuyv, 4, 2, vec![decode::pack_yuyv(&frame)]);
//! let mode = cam.open(&CaptureRequest::default()).unwrap();
//! let mut buf = Vec::new();
//! cam.next_buffer(&mut buf, Duration::from_secs(1)).unwrap().unwrap();
//! assert_eq!(decode::to_grey(&buf, &mode).unwrap(), frame);
//! ```

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use super::{BufferInfo, CameraError, CaptureRequest, Mode, PixelFormat, RawDevice};

/// An open failure the fake can simulate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FakeFailure {
    /// No such device.
    NotFound,
    /// Another program streams from it.
    Busy,
    /// Not a capture device.
    NotCapture,
}

/// What the fake has done (shared, readable while it runs in a thread).
#[derive(Debug, Default)]
pub struct FakeCounters {
    /// Successful opens.
    pub opens: AtomicU64,
    /// Buffers handed out (the sequence number of the next one).
    pub produced: AtomicU64,
}

/// A scripted unplug.
#[derive(Debug, Clone, Copy)]
struct Unplug {
    after_buffers: u64,
    duration: Duration,
}

/// A camera playing recorded buffers (see the [module docs](self)).
#[derive(Debug)]
pub struct FakeDevice {
    name: String,
    format: PixelFormat,
    width_px: u32,
    height_px: u32,
    buffers: Vec<Vec<u8>>,
    period: Duration,
    driver_latency: Option<Duration>,
    fail_open: Option<FakeFailure>,
    unplugs: Vec<Unplug>,
    once: bool,
    counters: Arc<FakeCounters>,
    open: bool,
    next_due: Instant,
    unplugged_until: Option<Instant>,
}

impl FakeDevice {
    /// A camera of `format` and size playing `buffers` in a loop, one per
    /// 1/30 s.
    pub fn new(format: PixelFormat, width_px: u32, height_px: u32, buffers: Vec<Vec<u8>>) -> Self {
        FakeDevice {
            name: "fake0".into(),
            format,
            width_px,
            height_px,
            buffers,
            period: Duration::from_secs_f64(1.0 / 30.0),
            driver_latency: None,
            fail_open: None,
            unplugs: Vec::new(),
            once: false,
            counters: Arc::default(),
            open: false,
            next_due: Instant::now(),
            unplugged_until: None,
        }
    }

    /// Names the device (for messages).
    pub fn named(mut self, name: &str) -> Self {
        self.name = name.into();
        self
    }

    /// One buffer per `period`.
    pub fn period(mut self, period: Duration) -> Self {
        self.period = period;
        self
    }

    /// Gives driver timestamps: each buffer captured `latency` before it
    /// is handed out.
    pub fn driver_timestamps(mut self, latency: Duration) -> Self {
        self.driver_latency = Some(latency);
        self
    }

    /// Plays the buffers once, then stalls (no buffer ever again).
    pub fn once(mut self) -> Self {
        self.once = true;
        self
    }

    /// Every open fails this way.
    pub fn fail_open(mut self, failure: FakeFailure) -> Self {
        self.fail_open = Some(failure);
        self
    }

    /// After `after_buffers` buffers in all, the camera is unplugged for
    /// `duration`: reads fail with `Disconnected`, opens with `NotFound`.
    pub fn unplug_after(mut self, after_buffers: u64, duration: Duration) -> Self {
        self.unplugs.push(Unplug {
            after_buffers,
            duration,
        });
        self
    }

    /// The shared counters.
    pub fn counters(&self) -> Arc<FakeCounters> {
        Arc::clone(&self.counters)
    }

    fn path(&self) -> PathBuf {
        PathBuf::from(&self.name)
    }
}

impl RawDevice for FakeDevice {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn open(&mut self, request: &CaptureRequest) -> Result<Mode, CameraError> {
        self.open = false;
        let device = self.path();
        if let Some(until) = self.unplugged_until {
            if Instant::now() < until {
                return Err(CameraError::NotFound { device });
            }
            self.unplugged_until = None;
        }
        match self.fail_open {
            Some(FakeFailure::NotFound) => return Err(CameraError::NotFound { device }),
            Some(FakeFailure::Busy) => return Err(CameraError::Busy { device }),
            Some(FakeFailure::NotCapture) => {
                return Err(CameraError::NotCapture {
                    device,
                    what: "a fake output device".into(),
                })
            }
            None => {}
        }
        if !request.formats.contains(&self.format) || self.buffers.is_empty() {
            return Err(CameraError::NoFormat {
                device,
                wanted: format_list(&request.formats),
                offered: self.format.to_string(),
            });
        }
        self.open = true;
        self.next_due = Instant::now() + self.period;
        self.counters.opens.fetch_add(1, Ordering::Relaxed);
        let own_fps = 1.0 / self.period.as_secs_f64().max(1e-6);
        Ok(Mode {
            format: self.format,
            width_px: self.width_px,
            height_px: self.height_px,
            stride_bytes: 0,
            fps: Some(request.fps.min(own_fps)),
        })
    }

    fn next_buffer(
        &mut self,
        data: &mut Vec<u8>,
        timeout: Duration,
    ) -> Result<Option<BufferInfo>, CameraError> {
        if !self.open {
            return Err(CameraError::Disconnected {
                device: self.path(),
            });
        }
        let seq = self.counters.produced.load(Ordering::Relaxed);
        if let Some(u) = self.unplugs.iter().find(|u| u.after_buffers == seq) {
            let u = *u;
            self.unplugs.retain(|v| v.after_buffers != seq);
            self.open = false;
            self.unplugged_until = Some(Instant::now() + u.duration);
            return Err(CameraError::Disconnected {
                device: self.path(),
            });
        }
        let now = Instant::now();
        if self.once && seq >= self.buffers.len() as u64 {
            std::thread::sleep(timeout);
            return Ok(None);
        }
        if self.next_due > now + timeout {
            std::thread::sleep(timeout);
            return Ok(None);
        }
        std::thread::sleep(self.next_due.saturating_duration_since(now));
        let handed_out = Instant::now();
        // No catch-up burst after a slow reader: the next buffer is one
        // period after this one at the earliest.
        self.next_due = (self.next_due + self.period).max(handed_out + self.period / 2);
        // `buffers` is non-empty: open refuses an empty stream.
        let buffer = &self.buffers[(seq % self.buffers.len() as u64) as usize];
        data.clear();
        data.extend_from_slice(buffer);
        self.counters.produced.fetch_add(1, Ordering::Relaxed);
        Ok(Some(BufferInfo {
            captured: self
                .driver_latency
                .map(|l| handed_out.checked_sub(l).unwrap_or(handed_out)),
            skipped: 0,
            flagged: false,
        }))
    }

    fn close(&mut self) {
        self.open = false;
    }
}

/// `"MJPEG, YUYV"`.
pub(crate) fn format_list(formats: &[PixelFormat]) -> String {
    formats
        .iter()
        .map(|f| f.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}
