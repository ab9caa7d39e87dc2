//! Accuracy against run time on synthetic scenes (`dexitac bench-pipeline`).
//!
//! For each pipeline [`Setting`] and scene [`Category`], renders seeded
//! frames (one rest frame per category sensor), runs the calibrated pipeline
//! and compares the contact centre with the truth: the error is the distance
//! to the nearest true contact (two-contact scenes accept either), a frame of
//! a contact category without a reported contact is a miss, a reported
//! contact on a no-contact frame is a false positive. Times are the
//! pipeline's single-thread stage times (rendering and calibration excluded).

use std::fmt::Write as _;

use crate::calibrate::{self, CalibrationError};
use crate::params::{CentreMethod, DensityMode, Params, ThresholdMode};
use crate::pipeline::{Pipeline, StageTimes};
use crate::synth::{self, Category};

/// A named pipeline configuration.
#[derive(Debug, Clone)]
pub struct Setting {
    /// Short name for tables.
    pub name: &'static str,
    /// The parameters.
    pub params: Params,
}

/// The settings compared in BENCHMARKS.md: the exact reference (paper rule
/// and relative rule), the fast path at several grid steps, without and with
/// skipping, and the default (fast, step 4, tracking).
pub fn settings() -> Vec<Setting> {
    let make = |mode, step, threshold, centre, skip| {
        let mut p = Params::default();
        p.density.mode = mode;
        p.density.grid_step_px = step;
        p.contact.threshold = threshold;
        p.contact.centre = centre;
        p.contact.skip_unmoved = skip;
        p
    };
    use CentreMethod::{Density as D, Hybrid as H};
    use DensityMode::{Exact as E, Fast as F};
    use ThresholdMode::{Absolute as A, Relative as R};
    vec![
        Setting {
            name: "paper: exact f64, absolute T",
            params: make(E, 1, A, D, false),
        },
        Setting {
            name: "exact f64, relative",
            params: make(E, 1, R, D, false),
        },
        Setting {
            name: "fast s4, absolute, no skip",
            params: make(F, 4, A, D, false),
        },
        Setting {
            name: "fast s4, relative, no skip",
            params: make(F, 4, R, D, false),
        },
        Setting {
            name: "fast s2, relative, skip+ROI",
            params: make(F, 2, R, D, true),
        },
        Setting {
            name: "fast s4, relative, skip+ROI",
            params: make(F, 4, R, D, true),
        },
        Setting {
            name: "fast s8, relative, skip+ROI",
            params: make(F, 8, R, D, true),
        },
        Setting {
            name: "fast s8, relative, skip+ROI, tracking",
            params: make(F, 8, R, H, true),
        },
        Setting {
            name: "default: fast s4, relative, skip+ROI, tracking",
            params: Params::default(),
        },
    ]
}

/// One evaluated frame.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// Scene category.
    pub category: Category,
    /// The frame has a true contact.
    pub has_truth: bool,
    /// Centre error to the nearest true contact, px (`None`: no contact
    /// reported).
    pub error_px: Option<f64>,
    /// The density stages were skipped.
    pub skipped: bool,
    /// Density grid cells computed.
    pub density_cells: usize,
    /// Stage times.
    pub times: StageTimes,
}

/// Runs `setting` on `frames` seeded scenes of each category at `width x
/// height`.
pub fn evaluate(
    setting: &Setting,
    categories: &[Category],
    frames: usize,
    width: usize,
    height: usize,
    seed: u64,
) -> Result<Vec<Sample>, CalibrationError> {
    let mut out = Vec::new();
    for (ci, &cat) in categories.iter().enumerate() {
        let sensor = cat.sensor(width, height, seed.wrapping_add(ci as u64));
        let rest = synth::rest_frame(&sensor, seed ^ 0xA5A5);
        let cal = calibrate::calibrate(&[rest.image], &setting.params)?;
        let pipeline = Pipeline::new(cal, setting.params.clone());
        for k in 0..frames {
            let scene = cat.scene(&sensor, seed.wrapping_mul(1000).wrapping_add(k as u64));
            let frame = synth::render(&scene);
            // Invariant: the frame is rendered at the calibrated size.
            let r = pipeline.run(&frame.image).expect("same size as rest");
            let error_px = r.contact.map(|c| {
                frame
                    .contacts
                    .iter()
                    .map(|t| (t.x - c.centre.x).hypot(t.y - c.centre.y))
                    .fold(f64::INFINITY, f64::min)
            });
            out.push(Sample {
                category: cat,
                has_truth: !frame.contacts.is_empty(),
                error_px,
                skipped: r.skipped,
                density_cells: r.density_cells,
                times: r.times,
            });
        }
    }
    Ok(out)
}

/// Per-category summary of samples.
#[derive(Debug, Clone, Copy)]
pub struct Summary {
    /// Scene category.
    pub category: Category,
    /// Frames.
    pub frames: usize,
    /// Contacts reported on frames with a true contact.
    pub found: usize,
    /// Contacts reported on frames without one.
    pub false_positives: usize,
    /// Median centre error of the reported contacts, px (NaN if none; an
    /// empty error set on a no-contact category).
    pub error_median_px: f64,
    /// 95th percentile centre error, px.
    pub error_p95_px: f64,
    /// Fraction of frames whose density stages were skipped.
    pub skipped: f64,
    /// Median stage times.
    pub median: StageTimes,
}

/// Summarises the samples of one category.
pub fn summarize(category: Category, samples: &[Sample]) -> Summary {
    let s: Vec<&Sample> = samples.iter().filter(|s| s.category == category).collect();
    let errors: Vec<f64> = s
        .iter()
        .filter(|s| s.has_truth)
        .filter_map(|s| s.error_px)
        .collect();
    let med = |f: &dyn Fn(&Sample) -> f64| quantile(s.iter().map(|x| f(x)).collect(), 0.5);
    Summary {
        category,
        frames: s.len(),
        found: s
            .iter()
            .filter(|s| s.has_truth && s.error_px.is_some())
            .count(),
        false_positives: s
            .iter()
            .filter(|s| !s.has_truth && s.error_px.is_some())
            .count(),
        error_median_px: quantile(errors.clone(), 0.5),
        error_p95_px: quantile(errors, 0.95),
        skipped: s.iter().filter(|s| s.skipped).count() as f64 / s.len().max(1) as f64,
        median: StageTimes {
            detect_ms: med(&|x| x.times.detect_ms),
            kde_ms: med(&|x| x.times.kde_ms),
            segment_ms: med(&|x| x.times.segment_ms),
            total_ms: med(&|x| x.times.total_ms),
        },
    }
}

/// Quantile `q` of `v` (nearest rank; NaN for an empty vector).
pub fn quantile(mut v: Vec<f64>, q: f64) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    let k = ((v.len() as f64 * q).ceil() as usize).clamp(1, v.len()) - 1;
    v[k]
}

/// Markdown table of the summaries of one setting.
pub fn markdown(setting: &str, summaries: &[Summary]) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "#### {setting}\n");
    let _ = writeln!(
        s,
        "| scene | frames | found | false + | err median px | err p95 px | skipped | detect ms | kde ms | segment ms | total ms |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|");
    for m in summaries {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {:.2} | {:.2} | {:.0}% | {:.3} | {:.3} | {:.3} | {:.3} |",
            m.category.name(),
            m.frames,
            m.found,
            m.false_positives,
            m.error_median_px,
            m.error_p95_px,
            100.0 * m.skipped,
            m.median.detect_ms,
            m.median.kde_ms,
            m.median.segment_ms,
            m.median.total_ms
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantile_is_nearest_rank() {
        assert!(quantile(vec![], 0.5).is_nan());
        assert_eq!(quantile(vec![3.0, 1.0, 2.0], 0.5), 2.0);
        assert_eq!(quantile((1..=100).map(f64::from).collect(), 0.95), 95.0);
        assert_eq!(quantile(vec![7.0], 0.95), 7.0);
    }
}
