//! Replay: the recorded frames through the pipeline again, each contact
//! centre compared with the recorded one.
//!
//! Each sensor's pipeline is calibrated on its recorded rest frames
//! (`/sensor{i}/rest`); a recording without them is calibrated on the
//! sensor's first `fallback_rest_frames` frames, and then cannot be expected
//! to reproduce the centres exactly. Frames are paired with the recorded
//! contact of the same sensor and capture time.
//!
//! Same binary, same parameters, same rest frames: every centre is
//! reproduced bit for bit (the pipeline is deterministic), so the default
//! tolerance is 0 px.

use std::collections::{HashMap, VecDeque};

use super::reader::{Recording, ReplaySource};
use super::Point2;
use crate::source::{Clock, FrameSource};
use dexitac_tactile::calibrate::{self, CalibrationError};
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::PointPx;

/// Why a replay could not run.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The recording has no frames (recorded without `--record-frames`?).
    #[error("the recording has no frames to replay (was it recorded with frames?)")]
    NoFrames,
    /// A sensor could not be calibrated.
    #[error("sensor {sensor}: calibration on {on}: {source}")]
    Calibration {
        /// The sensor.
        sensor: usize,
        /// What it was calibrated on.
        on: String,
        /// Why.
        source: CalibrationError,
    },
    /// A recorded frame could not be decoded or processed.
    #[error("sensor {sensor}: {reason}")]
    Frame {
        /// The sensor.
        sensor: usize,
        /// What failed.
        reason: String,
    },
}

/// One frame: the recorded and the replayed contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Comparison {
    /// The sensor.
    pub sensor: usize,
    /// Capture time, ms.
    pub t_ms: u64,
    /// Whether a contact record was found for this frame.
    pub recorded_present: bool,
    /// The recorded centre, working px.
    pub recorded: Option<Point2>,
    /// The replayed centre, working px.
    pub replayed: Option<PointPx>,
}

impl Comparison {
    /// Distance between the centres when both found one, px.
    pub fn diff_px(&self) -> Option<f64> {
        let (a, b) = (self.recorded?, self.replayed?);
        Some((a.x - b.x).hypot(a.y - b.y))
    }

    /// One found a contact and the other did not.
    pub fn disagrees(&self) -> bool {
        self.recorded_present && self.recorded.is_some() != self.replayed.is_some()
    }
}

/// Summary of a replay.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReplaySummary {
    /// Frames replayed.
    pub frames: usize,
    /// Frames without a recorded contact to compare with.
    pub unmatched: usize,
    /// Frames where both found a contact.
    pub both_found: usize,
    /// Frames where neither found one.
    pub neither_found: usize,
    /// Found/lost disagreements.
    pub disagreements: usize,
    /// Largest centre difference, px (0 when none compared).
    pub max_px: f64,
    /// Median centre difference, px.
    pub median_px: f64,
    /// 95th percentile centre difference, px.
    pub p95_px: f64,
    /// Per sensor: what its pipeline was calibrated on.
    pub calibrated_on: Vec<(usize, String)>,
}

impl ReplaySummary {
    /// Whether the replay reproduces the recording within `tolerance_px`.
    pub fn within(&self, tolerance_px: f64) -> bool {
        self.disagreements == 0 && self.max_px <= tolerance_px
    }
}

/// A replay's per-frame comparisons and their summary.
#[derive(Debug, Clone, Default)]
pub struct Replay {
    /// Per frame, in the order replayed (sensor by sensor).
    pub comparisons: Vec<Comparison>,
    /// The summary.
    pub summary: ReplaySummary,
}

/// The pipeline of `sensor`, calibrated on its rest frames or first frames.
fn sensor_pipeline(
    recording: &Recording,
    sensor: usize,
    params: &Params,
    fallback_rest_frames: usize,
) -> Result<(Pipeline, String), ReplayError> {
    let (frames, on): (Vec<_>, String) = match recording.rest.get(&sensor) {
        Some(rest) if !rest.is_empty() => (
            rest.iter().collect(),
            format!("{} recorded rest frame(s)", rest.len()),
        ),
        _ => (
            recording
                .frames_of(sensor)
                .take(fallback_rest_frames.max(1))
                .collect(),
            format!(
                "its first {} frame(s) (no rest frames recorded)",
                fallback_rest_frames.max(1)
            ),
        ),
    };
    let decoded = frames
        .iter()
        .map(|f| f.decode())
        .collect::<Result<Vec<_>, _>>()
        .map_err(|reason| ReplayError::Frame {
            sensor,
            reason: format!("rest frame: {reason}"),
        })?;
    let cal =
        calibrate::calibrate(&decoded, params).map_err(|source| ReplayError::Calibration {
            sensor,
            on: on.clone(),
            source,
        })?;
    Ok((Pipeline::new(cal, params.clone()), on))
}

/// Runs the pipeline on every recorded frame and compares.
pub fn replay(
    recording: &Recording,
    params: &Params,
    fallback_rest_frames: usize,
) -> Result<Replay, ReplayError> {
    if recording.frames.is_empty() {
        return Err(ReplayError::NoFrames);
    }
    let mut recorded: HashMap<(usize, u64), VecDeque<Option<Point2>>> = HashMap::new();
    for c in &recording.contacts {
        recorded
            .entry((c.sensor, c.t_ms))
            .or_default()
            .push_back(c.centre_px.filter(|_| c.found));
    }
    let clock = Clock::wall();
    let mut out = Replay::default();
    for sensor in recording.sensors() {
        if recording.frames_of(sensor).next().is_none() {
            continue;
        }
        let (pipeline, on) = sensor_pipeline(recording, sensor, params, fallback_rest_frames)?;
        out.summary.calibrated_on.push((sensor, on));
        let mut source = ReplaySource::new(recording, sensor, false);
        while let Some(frame) = source.next_frame(&clock).map_err(|e| ReplayError::Frame {
            sensor,
            reason: e.to_string(),
        })? {
            let result = pipeline.run(&frame.frame).map_err(|e| ReplayError::Frame {
                sensor,
                reason: format!("frame at {} ms: {e}", frame.t_ms),
            })?;
            let rec = recorded
                .get_mut(&(sensor, frame.t_ms))
                .and_then(VecDeque::pop_front);
            out.comparisons.push(Comparison {
                sensor,
                t_ms: frame.t_ms,
                recorded_present: rec.is_some(),
                recorded: rec.flatten(),
                replayed: result.contact.map(|c| c.centre),
            });
        }
    }
    out.summary = summarise(&out.comparisons, out.summary.calibrated_on);
    Ok(out)
}

/// Value at quantile `q` of sorted `v` (nearest rank; 0 when empty).
fn quantile(v: &[f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

fn summarise(c: &[Comparison], calibrated_on: Vec<(usize, String)>) -> ReplaySummary {
    let mut diffs: Vec<f64> = c.iter().filter_map(Comparison::diff_px).collect();
    diffs.sort_by(f64::total_cmp);
    ReplaySummary {
        frames: c.len(),
        unmatched: c.iter().filter(|c| !c.recorded_present).count(),
        both_found: diffs.len(),
        neither_found: c
            .iter()
            .filter(|c| c.recorded_present && c.recorded.is_none() && c.replayed.is_none())
            .count(),
        disagreements: c.iter().filter(|c| c.disagrees()).count(),
        max_px: diffs.last().copied().unwrap_or(0.0),
        median_px: quantile(&diffs, 0.5),
        p95_px: quantile(&diffs, 0.95),
        calibrated_on,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cmp(recorded: Option<(f64, f64)>, replayed: Option<(f64, f64)>) -> Comparison {
        Comparison {
            sensor: 0,
            t_ms: 0,
            recorded_present: true,
            recorded: recorded.map(|(x, y)| Point2 { x, y }),
            replayed: replayed.map(|(x, y)| PointPx::new(x, y)),
        }
    }

    #[test]
    fn summary_counts_differences_and_disagreements() {
        let c = [
            cmp(Some((0.0, 0.0)), Some((3.0, 4.0))),
            cmp(Some((1.0, 1.0)), Some((1.0, 1.0))),
            cmp(Some((1.0, 1.0)), None),
            cmp(None, None),
        ];
        let s = summarise(&c, Vec::new());
        assert_eq!(s.frames, 4);
        assert_eq!(s.both_found, 2);
        assert_eq!(s.disagreements, 1);
        assert_eq!(s.neither_found, 1);
        assert_eq!(s.max_px, 5.0);
        assert_eq!(s.median_px, 0.0);
        assert!(!s.within(10.0), "a disagreement fails any tolerance");
    }

    #[test]
    fn identical_centres_are_within_zero_tolerance() {
        let s = summarise(&[cmp(Some((2.5, 7.25)), Some((2.5, 7.25)))], Vec::new());
        assert!(s.within(0.0));
    }
}
