//! Where a sensor's frames come from: the [`FrameSource`] trait every
//! source implements (cameras, frame folders, recordings, the simulated
//! renderer), the frames it yields ([`TimedFrame`]) and the [`Clock`] their
//! times are read on.

use std::time::{Duration, Instant};

use dexitac_tactile::frame::{FrameError, GreyFrame};

/// A clock in milliseconds since its creation, running `speed` times faster
/// than the wall clock (1 on the rig).
#[derive(Debug, Clone, Copy)]
pub struct Clock {
    epoch: Instant,
    speed: f64,
}

impl Clock {
    /// The wall clock.
    pub fn wall() -> Self {
        Clock::scaled(1.0)
    }

    /// A clock `speed` times faster than the wall clock (non-finite or
    /// non-positive speeds mean 1).
    pub fn scaled(speed: f64) -> Self {
        Clock {
            epoch: Instant::now(),
            speed: if speed.is_finite() && speed > 0.0 {
                speed
            } else {
                1.0
            },
        }
    }

    /// Clock time, ms.
    pub fn now_ms(&self) -> u64 {
        (self.epoch.elapsed().as_secs_f64() * 1e3 * self.speed) as u64
    }

    /// Simulated time per wall-clock time.
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// The wall-clock duration of `ms` of clock time.
    pub fn wall_duration(&self, ms: u64) -> Duration {
        Duration::from_secs_f64(ms as f64 / 1e3 / self.speed)
    }

    /// Sleeps until clock time `t_ms` (returns at once if it has passed).
    pub fn sleep_until(&self, t_ms: u64) {
        let now = self.now_ms();
        if t_ms > now {
            std::thread::sleep(self.wall_duration(t_ms - now));
        }
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
}

/// Ends a source's wait for frames (see [`FrameSource::halt_handle`]).
pub type HaltHandle = Box<dyn Fn() + Send + Sync>;
