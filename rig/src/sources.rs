//! Replay sources: a folder of frame images (PNG or JPEG) as a
//! [`FrameSource`], at recorded speed or as fast as the pipeline goes.
//!
//! Files are read in name order. A file name that carries its capture time
//! as `<digits>ms` (e.g. `frame-0042-1400ms.png`, `t1400ms.jpg`; the last
//! such group counts) gives [`Pace::Recorded`] its timing: frame `k` is
//! handed out `t_k - t_0` ms after the first one (and the files are taken
//! in time order). When any file lacks a time, `Recorded` falls back to its
//! fps. [`Pace::Max`] never sleeps: each frame is stamped with the clock's
//! time when it is handed out.

use std::path::{Path, PathBuf};

use crate::source::{Clock, FrameSource, SourceError, TimedFrame};
use dexitac_tactile::frame::{self, GreyFrame, RawFrame};
use dexitac_tactile::params::FrameParams;

/// How fast a folder is replayed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pace {
    /// One frame per `1 / fps` s.
    Fps(f64),
    /// The times in the file names; `fps` when a file has none.
    Recorded {
        /// Fallback frame rate.
        fps: f64,
    },
    /// No sleeping.
    Max,
}

/// The image files (`.png`, `.jpg`, `.jpeg`, any case) of `dir`, in name
/// order.
pub fn image_files(dir: &Path) -> Result<Vec<PathBuf>, SourceError> {
    let io = |source| SourceError::Io {
        path: dir.to_path_buf(),
        source,
    };
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let path = entry.map_err(io)?.path();
        let is_image = path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "png" | "jpg" | "jpeg"));
        if is_image && path.is_file() {
            files.push(path);
        }
    }
    files.sort();
    Ok(files)
}

/// Reads an image file and prepares it as a working grey frame. Colour
/// images go through the pipeline's own grey conversion
/// ([`frame::to_grey`]), so a frame gives the same grey here as in
/// `dexitac analyze`.
pub fn load_frame(path: &Path, params: &FrameParams) -> Result<GreyFrame, SourceError> {
    let img = image::open(path).map_err(|e| SourceError::Decode {
        path: path.to_path_buf(),
        reason: e.to_string(),
    })?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let (channels, data) = match img {
        image::DynamicImage::ImageLuma8(b) => (1, b.into_raw()),
        image::DynamicImage::ImageRgba8(b) => (4, b.into_raw()),
        other => (3, other.into_rgb8().into_raw()),
    };
    let raw = RawFrame {
        width: w,
        height: h,
        channels,
        data: &data,
    };
    Ok(frame::prepare(&raw, params)?.grey)
}

/// The capture time a file name carries (`...<digits>ms...`), ms.
pub fn time_from_name(path: &Path) -> Option<u64> {
    let stem = path.file_stem()?.to_str()?;
    let bytes = stem.as_bytes();
    let mut found = None;
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i].is_ascii_digit() {
            let start = i;
            while i < bytes.len() && bytes[i].is_ascii_digit() {
                i += 1;
            }
            let unit_ms = stem[i..].starts_with("ms")
                && !stem[i + 2..].starts_with(|c: char| c.is_ascii_alphabetic());
            if unit_ms {
                found = stem[start..i].parse().ok().or(found);
            }
        } else {
            i += 1;
        }
    }
    found
}

/// Frames from image files (see the [module docs](self)).
#[derive(Debug)]
pub struct FolderSource {
    files: Vec<PathBuf>,
    /// Offsets from the first frame, ms (recorded pace with times).
    offsets_ms: Option<Vec<u64>>,
    period_ms: f64,
    max_speed: bool,
    next: usize,
    start_ms: Option<u64>,
    params: FrameParams,
}

impl FolderSource {
    /// Replays `files` (in the given order, unless recorded times reorder
    /// them), preparing each with `params`.
    pub fn new(files: Vec<PathBuf>, pace: Pace, params: &FrameParams) -> Result<Self, SourceError> {
        let fps = match pace {
            Pace::Fps(f) | Pace::Recorded { fps: f } => f,
            Pace::Max => 1.0,
        };
        if !(fps.is_finite() && fps > 0.0) {
            return Err(SourceError::Decode {
                path: PathBuf::from("<folder source>"),
                reason: format!("frame rate {fps} must be positive"),
            });
        }
        let mut files = files;
        let times: Option<Vec<u64>> = match pace {
            Pace::Recorded { .. } => files.iter().map(|f| time_from_name(f)).collect(),
            _ => None,
        };
        let offsets_ms = times.map(|times| {
            let mut pairs: Vec<(u64, PathBuf)> = times.into_iter().zip(files.drain(..)).collect();
            pairs.sort();
            let t0 = pairs.first().map_or(0, |p| p.0);
            let offsets = pairs.iter().map(|p| p.0 - t0).collect();
            files = pairs.into_iter().map(|p| p.1).collect();
            offsets
        });
        Ok(FolderSource {
            files,
            offsets_ms,
            period_ms: 1e3 / fps,
            max_speed: matches!(pace, Pace::Max),
            next: 0,
            start_ms: None,
            params: params.clone(),
        })
    }

    /// Replays the image files of `dir` (see [`image_files`]).
    pub fn from_dir(dir: &Path, pace: Pace, params: &FrameParams) -> Result<Self, SourceError> {
        Self::new(image_files(dir)?, pace, params)
    }

    /// True when the file names' times pace the replay.
    pub fn uses_recorded_times(&self) -> bool {
        self.offsets_ms.is_some()
    }

    /// Frames left.
    pub fn remaining(&self) -> usize {
        self.files.len() - self.next
    }

    /// When frame `k` is due, ms after the first.
    fn offset_ms(&self, k: usize) -> u64 {
        match &self.offsets_ms {
            Some(o) => o[k],
            None => (k as f64 * self.period_ms).round() as u64,
        }
    }
}

impl FrameSource for FolderSource {
    fn next_frame(&mut self, clock: &Clock) -> Result<Option<TimedFrame>, SourceError> {
        let Some(path) = self.files.get(self.next).cloned() else {
            return Ok(None);
        };
        let k = self.next;
        self.next += 1;
        let t_ms = if self.max_speed {
            clock.now_ms()
        } else {
            let start = *self.start_ms.get_or_insert_with(|| clock.now_ms());
            let due = start + self.offset_ms(k);
            clock.sleep_until(due);
            due
        };
        let frame = load_frame(&path, &self.params)?;
        Ok(Some(TimedFrame { t_ms, frame }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_frames(dir: &Path, names: &[&str]) {
        for (i, n) in names.iter().enumerate() {
            let img = image::GrayImage::from_fn(32, 24, |x, y| {
                image::Luma([((x + y) as usize * 5 + i * 40) as u8])
            });
            img.save(dir.join(n)).unwrap();
        }
    }

    fn params() -> FrameParams {
        FrameParams {
            work_width_px: 32,
            work_height_px: 24,
            ..FrameParams::default()
        }
    }

    #[test]
    fn times_come_from_ms_groups_in_names() {
        assert_eq!(
            time_from_name(Path::new("frame-0042-1400ms.png")),
            Some(1400)
        );
        assert_eq!(time_from_name(Path::new("t0ms.jpg")), Some(0));
        assert_eq!(time_from_name(Path::new("12ms_34ms.png")), Some(34));
        assert_eq!(time_from_name(Path::new("frame_0001.png")), None);
        assert_eq!(time_from_name(Path::new("5msec.png")), None);
        assert_eq!(
            time_from_name(Path::new("99999999999999999999999ms.png")),
            None
        );
    }

    #[test]
    fn recorded_pace_follows_the_file_times() {
        let dir = tempfile::tempdir().unwrap();
        write_frames(dir.path(), &["b-200ms.png", "a-0ms.png", "c-260ms.png"]);
        let mut src =
            FolderSource::from_dir(dir.path(), Pace::Recorded { fps: 1.0 }, &params()).unwrap();
        assert!(src.uses_recorded_times());
        // 20x fast clock: 260 recorded ms take 13 wall ms.
        let clock = Clock::scaled(20.0);
        let mut times = Vec::new();
        while let Some(f) = src.next_frame(&clock).unwrap() {
            times.push(f.t_ms);
        }
        assert_eq!(times.len(), 3);
        let rel: Vec<u64> = times.iter().map(|t| t - times[0]).collect();
        assert_eq!(rel, vec![0, 200, 260]);
        assert!(
            clock.now_ms() >= times[2],
            "a frame was handed out before it was due"
        );
    }

    #[test]
    fn recorded_pace_without_times_uses_the_fps() {
        let dir = tempfile::tempdir().unwrap();
        write_frames(dir.path(), &["f0.png", "f1.png", "f2-10ms.png"]);
        let mut src =
            FolderSource::from_dir(dir.path(), Pace::Recorded { fps: 10.0 }, &params()).unwrap();
        assert!(!src.uses_recorded_times());
        let clock = Clock::scaled(50.0);
        let t: Vec<u64> = std::iter::from_fn(|| src.next_frame(&clock).unwrap())
            .map(|f| f.t_ms)
            .collect();
        assert_eq!(
            t.iter().map(|x| x - t[0]).collect::<Vec<_>>(),
            vec![0, 100, 200]
        );
    }

    #[test]
    fn max_speed_does_not_sleep() {
        let dir = tempfile::tempdir().unwrap();
        write_frames(dir.path(), &["a.png", "b.png", "c.png", "d.png"]);
        let mut src = FolderSource::from_dir(dir.path(), Pace::Max, &params()).unwrap();
        // At 0.01 fps a paced replay would take 300 s of clock time.
        let clock = Clock::wall();
        let t0 = std::time::Instant::now();
        let n = std::iter::from_fn(|| src.next_frame(&clock).unwrap()).count();
        assert_eq!(n, 4);
        assert!(t0.elapsed().as_secs_f64() < 5.0);
    }

    #[test]
    fn unreadable_files_and_folders_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("bad.png"), b"not a png").unwrap();
        let mut src = FolderSource::from_dir(dir.path(), Pace::Max, &params()).unwrap();
        let e = src.next_frame(&Clock::wall()).unwrap_err();
        assert!(matches!(e, SourceError::Decode { .. }), "{e}");
        assert!(e.to_string().contains("bad.png"), "{e}");
        let e = image_files(&dir.path().join("missing")).unwrap_err();
        assert!(matches!(e, SourceError::Io { .. }), "{e}");
        assert!(FolderSource::new(Vec::new(), Pace::Fps(0.0), &params()).is_err());
        assert!(FolderSource::new(Vec::new(), Pace::Fps(f64::NAN), &params()).is_err());
    }
}
