//! Where a sensor's frames come from: the [`FrameSource`] trait every
//! source implements (cameras, frame folders, recordings, the simulated
//! renderer), the frames it yields ([`TimedFrame`]) and the [`Clock`] their
//! times are read on.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use dexitac_tactile::frame::{FrameError, GreyFrame};

/// The clock every part of a run reads its time from: the task loop, the
/// link's timeouts, the frame sources, the simulated MCU and plant.
///
/// - [`Clock::wall`]: the wall clock (the rig).
/// - [`Clock::scaled`]: a clock `speed` times faster than the wall clock
///   (the simulator in real time, the live view).
/// - [`Clock::virtual_clock`]: virtual time that advances only when a part
///   of the run waits on it ([`Clock::sleep_until`], a simulated port's
///   read that finds no bytes). Nothing runs between two steps, so a run on
///   it is as fast as the CPU allows and repeats exactly.
///
/// Clones share one time line.
#[derive(Debug, Clone)]
pub struct Clock(Kind);

#[derive(Debug, Clone)]
enum Kind {
    Real { epoch: Instant, speed: f64 },
    Virtual(Arc<AtomicU64>),
}

impl Clock {
    /// The wall clock.
    pub fn wall() -> Self {
        Clock::scaled(1.0)
    }

    /// A clock `speed` times faster than the wall clock (non-finite or
    /// non-positive speeds mean 1).
    pub fn scaled(speed: f64) -> Self {
        Clock(Kind::Real {
            epoch: Instant::now(),
            speed: if speed.is_finite() && speed > 0.0 {
                speed
            } else {
                1.0
            },
        })
    }

    /// Virtual time, starting at 0: it moves only when something waits on
    /// it (see the type's docs).
    pub fn virtual_clock() -> Self {
        Clock(Kind::Virtual(Arc::new(AtomicU64::new(0))))
    }

    /// Whether this is virtual time.
    pub fn is_virtual(&self) -> bool {
        matches!(self.0, Kind::Virtual(_))
    }

    /// Clock time, µs.
    pub fn now_us(&self) -> u64 {
        match &self.0 {
            Kind::Real { epoch, speed } => (epoch.elapsed().as_secs_f64() * 1e6 * speed) as u64,
            Kind::Virtual(now) => now.load(Ordering::Acquire),
        }
    }

    /// Clock time, ms.
    pub fn now_ms(&self) -> u64 {
        self.now_us() / 1_000
    }

    /// Clock time per wall-clock time (virtual time: infinite).
    pub fn speed(&self) -> f64 {
        match self.0 {
            Kind::Real { speed, .. } => speed,
            Kind::Virtual(_) => f64::INFINITY,
        }
    }

    /// Waits until clock time `t_us` (returns at once if it has passed). On
    /// virtual time this moves the time to `t_us`: whatever is simulated
    /// catches up when it is next read.
    pub fn sleep_until_us(&self, t_us: u64) {
        match &self.0 {
            Kind::Real { speed, .. } => {
                let now = self.now_us();
                if t_us > now {
                    std::thread::sleep(Duration::from_secs_f64((t_us - now) as f64 / 1e6 / speed));
                }
            }
            Kind::Virtual(now) => {
                now.fetch_max(t_us, Ordering::AcqRel);
            }
        }
    }

    /// Waits until clock time `t_ms` (see [`Clock::sleep_until_us`]).
    pub fn sleep_until(&self, t_ms: u64) {
        self.sleep_until_us(t_ms.saturating_mul(1_000));
    }

    /// Waits for `d` of clock time.
    pub fn sleep(&self, d: Duration) {
        let d_us = u64::try_from(d.as_micros()).unwrap_or(u64::MAX);
        self.sleep_until_us(self.now_us().saturating_add(d_us));
    }
}

/// A frame and when it was captured.
#[derive(Debug, Clone)]
pub struct TimedFrame {
    /// Capture time on the loop's clock, ms.
    pub t_ms: u64,
    /// The working grey frame.
    pub frame: GreyFrame,
}

/// Why a frame source failed.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// A file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// An image could not be decoded.
    #[error("cannot decode {path}: {reason}")]
    Decode {
        /// The file.
        path: std::path::PathBuf,
        /// What the decoder said.
        reason: String,
    },
    /// The frame does not fit the pipeline.
    #[error("bad frame: {0}")]
    Frame(#[from] FrameError),
}

/// Where a sensor's frames come from (simulated renderer, a directory of
/// frames, later a camera).
pub trait FrameSource: Send {
    /// Blocks until the next frame; `None` when the source has ended.
    fn next_frame(&mut self, clock: &Clock) -> Result<Option<TimedFrame>, SourceError>;

    /// A way to end a blocked [`next_frame`](Self::next_frame) from another
    /// thread (it then returns `Ok(None)` soon), for sources that can wait
    /// long (a camera that was unplugged). `None`: the source never blocks
    /// for long.
    fn halt_handle(&self) -> Option<HaltHandle> {
        None
    }

    /// When the next frame is due on the clock, ms, for sources that
    /// produce frames on a schedule (the simulated cameras): the task loop
    /// on a virtual clock asks for a frame only once it is due, so
    /// [`next_frame`](Self::next_frame) never waits there. `u64::MAX`: no
    /// frame is coming (a camera that stopped delivering). `None`: the
    /// source cannot tell (cameras, files), and cannot run on a virtual
    /// clock.
    fn next_due_ms(&self) -> Option<u64> {
        None
    }
}

/// Ends a source's wait for frames (see [`FrameSource::halt_handle`]).
pub type HaltHandle = Box<dyn Fn() + Send + Sync>;
