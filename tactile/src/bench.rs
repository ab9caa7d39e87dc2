//! Accuracy against run time on synthetic scenes (`dexitac bench-pipeline`).
//!
//! For each pipeline [`Setting`] and scene [`Category`], renders seeded
//! frames on [`SENSORS_PER_CATEGORY`] sensors per category (each with its
//! own rest frame and calibration), runs the calibrated pipeline
//! and compares the contact centre with the truth: the error is the distance
//! to the nearest true contact (two-contact scenes accept either), a frame of
//! a contact category without a reported contact is a miss, a reported
//! contact on a no-contact frame is a false positive. Times are the
//! pipeline's single-thread stage times (rendering and calibration excluded).
//!
//! Each frame also counts markers against the generator's truth: the true
//! (visible) markers, the detected ones, the true markers with a detection
//! within a quarter pitch, and the detections outside the sensing area (a
//! housing's LEDs, specks, reflections); and the signed radial error of the
//! centre (towards the rim positive), for the rim bias. The condition
//! categories ([`Category::CONDITIONS`]: light change, blur, texture, dome,
//! housing, two-colour pins, rim clamp) are evaluated the same way
//! ([`evaluate_each`], [`conditions_markdown`], [`conditions_report`]).

use std::fmt::Write as _;

use crate::calibrate::{self, CalibrationError};
use crate::params::{CentreMethod, DensityMode, Params, ThresholdMode};
use crate::pipeline::{Pipeline, StageTimes};
use crate::synth::{self, Category, SynthFrame};
use crate::PointPx;

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
/// skipping, and with tracking (the default: fast, step 8, tracking).
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
            name: "fast s4, relative, skip+ROI, tracking",
            params: make(F, 4, R, H, true),
        },
        Setting {
            name: "default, whole-frame search of lost markers",
            params: {
                let mut p = Params::default();
                p.markers.local_search = false;
                p
            },
        },
        Setting {
            name: "default: fast s8, relative, skip+ROI, tracking",
            params: Params::default(),
        },
    ]
}

/// Sensors (rest frames, calibrations) per scene category in [`evaluate`].
pub const SENSORS_PER_CATEGORY: usize = 4;

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
    /// Markers counted against the truth.
    pub markers: MarkerCounts,
    /// Signed radial centre error against the nearest true contact, px:
    /// the reported centre's offset along the direction from the sensing
    /// area's centre to the true centre (positive: towards the rim; `None`:
    /// no contact reported or no true contact).
    pub radial_error_px: Option<f64>,
}

/// Detected markers of one frame against the generator's truth.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MarkerCounts {
    /// True visible markers (all inside the sensing area).
    pub truth: usize,
    /// Detected markers.
    pub detected: usize,
    /// True markers with a detection within a quarter pitch.
    pub matched: usize,
    /// Detections outside the sensing area.
    pub outside: usize,
}

impl MarkerCounts {
    /// Counts `detected` against the truth of `frame` (`pitch_px`: the
    /// sensor's pitch).
    pub fn of(frame: &SynthFrame, detected: &[PointPx], pitch_px: f64) -> Self {
        let radius = 0.25 * pitch_px;
        let cell = radius.max(1.0);
        let mut grid: std::collections::HashMap<(i64, i64), Vec<PointPx>> =
            std::collections::HashMap::new();
        let key = |p: &PointPx| ((p.x / cell).floor() as i64, (p.y / cell).floor() as i64);
        for p in detected {
            grid.entry(key(p)).or_default().push(*p);
        }
        let matched = frame
            .markers
            .iter()
            .filter(|t| {
                let (i, j) = key(t);
                (i - 1..=i + 1).any(|a| {
                    (j - 1..=j + 1).any(|b| {
                        grid.get(&(a, b)).is_some_and(|v| {
                            v.iter().any(|p| (p.x - t.x).hypot(p.y - t.y) <= radius)
                        })
                    })
                })
            })
            .count();
        Self {
            truth: frame.markers.len(),
            detected: detected.len(),
            matched,
            outside: detected
                .iter()
                .filter(|p| !frame.area.contains(**p))
                .count(),
        }
    }
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
        out.extend(evaluate_category(
            setting, cat, ci, frames, width, height, seed,
        )?);
    }
    Ok(out)
}

/// As [`evaluate`], but a category whose rest frame does not calibrate
/// gives its error and the others still run (the same sensors and scenes as
/// [`evaluate`] on the same list).
pub fn evaluate_each(
    setting: &Setting,
    categories: &[Category],
    frames: usize,
    width: usize,
    height: usize,
    seed: u64,
) -> Vec<(Category, Result<Vec<Sample>, CalibrationError>)> {
    categories
        .iter()
        .enumerate()
        .map(|(ci, &cat)| {
            (
                cat,
                evaluate_category(setting, cat, ci, frames, width, height, seed),
            )
        })
        .collect()
}

/// The samples of category `cat` at index `ci` of the evaluated list (the
/// index picks the sensor seeds).
fn evaluate_category(
    setting: &Setting,
    cat: Category,
    ci: usize,
    frames: usize,
    width: usize,
    height: usize,
    seed: u64,
) -> Result<Vec<Sample>, CalibrationError> {
    // Several sensors per category (marker size and lattice offset vary
    // with the sensor seed), each with its own rest frame; frame k uses
    // sensor k mod SENSORS_PER_CATEGORY.
    let mut sensors = Vec::new();
    for j in 0..SENSORS_PER_CATEGORY.min(frames.max(1)) {
        let sensor_seed = seed.wrapping_add((ci * SENSORS_PER_CATEGORY + j) as u64);
        let sensor = cat.sensor(width, height, sensor_seed);
        let rest = synth::rest_frame(&sensor, sensor_seed ^ 0xA5A5);
        let cal = calibrate::calibrate(&[rest.image], &setting.params)?;
        sensors.push((sensor, Pipeline::new(cal, setting.params.clone())));
    }
    let mut out = Vec::with_capacity(frames);
    for k in 0..frames {
        let (sensor, pipeline) = &sensors[k % sensors.len()];
        let scene = cat.scene(sensor, seed.wrapping_mul(1000).wrapping_add(k as u64));
        let frame = synth::render(&scene);
        // Invariant: the frame is rendered at the calibrated size.
        let r = pipeline.run(&frame.image).expect("same size as rest");
        let nearest = r.contact.as_ref().and_then(|c| {
            frame
                .contacts
                .iter()
                .map(|t| (*t, (t.x - c.centre.x).hypot(t.y - c.centre.y)))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(t, e)| (t, e, c.centre))
        });
        let error_px = r
            .contact
            .as_ref()
            .map(|_| nearest.map_or(f64::INFINITY, |n| n.1));
        let radial_error_px = nearest.map(|(t, _, c)| {
            let o = frame.area.centre;
            let (nx, ny) = (t.x - o.x, t.y - o.y);
            let n = nx.hypot(ny);
            if n < 1e-9 {
                0.0
            } else {
                ((c.x - t.x) * nx + (c.y - t.y) * ny) / n
            }
        });
        out.push(Sample {
            category: cat,
            has_truth: !frame.contacts.is_empty(),
            error_px,
            skipped: r.skipped,
            density_cells: r.density_cells,
            times: r.times,
            markers: MarkerCounts::of(&frame, &r.markers.positions(), sensor.pitch_px),
            radial_error_px,
        });
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
    /// Frames with a true contact.
    pub contact_frames: usize,
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
    /// Median true marker count per frame.
    pub markers_truth_median: f64,
    /// Median detected marker count per frame.
    pub markers_detected_median: f64,
    /// Median count of true markers with a detection within a quarter
    /// pitch.
    pub markers_matched_median: f64,
    /// Median count of detections outside the sensing area.
    pub markers_outside_median: f64,
    /// Largest count of detections outside the sensing area in a frame.
    pub markers_outside_max: usize,
    /// Median signed radial centre error, px (positive: towards the rim;
    /// NaN if no contact was reported).
    pub radial_error_median_px: f64,
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
        contact_frames: s.iter().filter(|s| s.has_truth).count(),
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
        markers_truth_median: med(&|x| x.markers.truth as f64),
        markers_detected_median: med(&|x| x.markers.detected as f64),
        markers_matched_median: med(&|x| x.markers.matched as f64),
        markers_outside_median: med(&|x| x.markers.outside as f64),
        markers_outside_max: s.iter().map(|x| x.markers.outside).max().unwrap_or(0),
        radial_error_median_px: quantile(
            s.iter()
                .filter(|s| s.has_truth)
                .filter_map(|s| s.radial_error_px)
                .collect(),
            0.5,
        ),
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

/// Markdown table of the summaries of one setting on the condition
/// categories: marker counts against the truth, contacts found on contact
/// frames and reported on no-contact frames, centre error (and its signed
/// radial part), total time. `failed` lists categories whose rest frame did
/// not calibrate.
pub fn conditions_markdown(
    setting: &str,
    summaries: &[Summary],
    failed: &[(Category, String)],
) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "#### {setting}\n");
    let _ = writeln!(
        s,
        "| scene | frames | markers true | detected | matched | outside area (max) | found | false + | err median px | err p95 px | radial err median px | total ms |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|---|");
    for m in summaries {
        let _ = writeln!(
            s,
            "| {} | {} | {:.0} | {:.0} | {:.0} | {:.0} ({}) | {}/{} | {}/{} | {:.2} | {:.2} | {:+.2} | {:.3} |",
            m.category.name(),
            m.frames,
            m.markers_truth_median,
            m.markers_detected_median,
            m.markers_matched_median,
            m.markers_outside_median,
            m.markers_outside_max,
            m.found,
            m.contact_frames,
            m.false_positives,
            m.frames - m.contact_frames,
            m.error_median_px,
            m.error_p95_px,
            m.radial_error_median_px,
            m.median.total_ms
        );
    }
    for (c, e) in failed {
        let _ = writeln!(
            s,
            "| {} | calibration failed: {e} | | | | | | | | | | |",
            c.name()
        );
    }
    s
}

/// The condition categories' table ([`conditions_markdown`]) for each
/// setting of [`settings`] whose name is in `names` (all when empty), at
/// 640x480 with `frames` frames per category of `categories`.
pub fn conditions_report(
    names: &[&str],
    categories: &[Category],
    frames: usize,
    seed: u64,
) -> String {
    let mut out = String::new();
    let _ = writeln!(
        out,
        "### Condition categories (640x480, seed {seed}, {frames} frames per scene, {SENSORS_PER_CATEGORY} sensors each)\n"
    );
    for setting in settings() {
        if !names.is_empty() && !names.contains(&setting.name) {
            continue;
        }
        let mut sums = Vec::new();
        let mut failed = Vec::new();
        for (cat, r) in evaluate_each(&setting, categories, frames, 640, 480, seed) {
            match r {
                Ok(samples) => sums.push(summarize(cat, &samples)),
                Err(e) => failed.push((cat, e.to_string())),
            }
        }
        let _ = writeln!(out, "{}", conditions_markdown(setting.name, &sums, &failed));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Prints the condition categories' table for the default setting
    /// (`cargo test --release -p dexitac-tactile --features synth --lib
    /// conditions_report -- --ignored --nocapture`; env `DEXITAC_FRAMES`,
    /// `DEXITAC_SEED`, `DEXITAC_SETTINGS=all` or `local` (the default and the
    /// whole-frame search of lost markers), `DEXITAC_CATEGORIES=dome,tactip`).
    #[test]
    #[ignore = "a benchmark run, minutes in debug"]
    fn conditions_report_of_the_default_setting() {
        let env = |k: &str| std::env::var(k).ok();
        let frames = env("DEXITAC_FRAMES")
            .and_then(|v| v.parse().ok())
            .unwrap_or(40);
        let seed = env("DEXITAC_SEED")
            .and_then(|v| v.parse().ok())
            .unwrap_or(1);
        let names: Vec<&str> = match env("DEXITAC_SETTINGS").as_deref() {
            Some("all") => vec![],
            // The default setting and the whole-frame search of lost
            // markers, one after the other in one run.
            Some("local") => vec![
                "default, whole-frame search of lost markers",
                "default: fast s8, relative, skip+ROI, tracking",
            ],
            _ => vec!["default: fast s8, relative, skip+ROI, tracking"],
        };
        let categories: Vec<Category> = match env("DEXITAC_CATEGORIES") {
            Some(list) => list
                .split(',')
                .map(|n| Category::from_name(n.trim()).unwrap_or_else(|| panic!("no category {n}")))
                .collect(),
            None => Category::CONDITIONS.to_vec(),
        };
        println!("{}", conditions_report(&names, &categories, frames, seed));
    }

    #[test]
    fn marker_counts_match_within_a_quarter_pitch_and_flag_outside() {
        let sensor = Category::Housing.sensor(320, 240, 1);
        let f = synth::rest_frame(&sensor, 2);
        let mut detected: Vec<PointPx> = f.markers.iter().skip(3).copied().collect();
        detected[0].x += 0.3 * sensor.pitch_px;
        detected.extend(f.distractors.iter().map(|d| d.at));
        let c = MarkerCounts::of(&f, &detected, sensor.pitch_px);
        assert_eq!(c.truth, f.markers.len());
        assert_eq!(c.detected, detected.len());
        assert_eq!(c.matched, f.markers.len() - 4);
        assert_eq!(c.outside, f.distractors.len());
    }

    #[test]
    fn quantile_is_nearest_rank() {
        assert!(quantile(vec![], 0.5).is_nan());
        assert_eq!(quantile(vec![3.0, 1.0, 2.0], 0.5), 2.0);
        assert_eq!(quantile((1..=100).map(f64::from).collect(), 0.95), 95.0);
        assert_eq!(quantile(vec![7.0], 0.95), 7.0);
    }
}

/// Accuracy and time of one setting pooled over scene groups (one point of
/// the Pareto plot).
#[derive(Debug, Clone)]
pub struct Pooled {
    /// Setting name.
    pub name: &'static str,
    /// Median centre error over nominal, edge and large scenes, px.
    pub error_median_px: f64,
    /// 95th percentile centre error over nominal, edge and large, px.
    pub error_p95_px: f64,
    /// Contacts found / frames over nominal, edge and large.
    pub found: (usize, usize),
    /// Small contacts found / frames.
    pub small_found: (usize, usize),
    /// False contacts / no-contact frames.
    pub false_positives: (usize, usize),
    /// Median total time over all frames, ms.
    pub total_median_ms: f64,
    /// Median total time over contact frames, ms.
    pub contact_median_ms: f64,
    /// Median total time over no-contact frames, ms.
    pub no_contact_median_ms: f64,
}

/// Pools the samples of one setting (see [`Pooled`]).
pub fn pool(name: &'static str, samples: &[Sample]) -> Pooled {
    let target = |s: &&Sample| {
        matches!(
            s.category,
            Category::Nominal | Category::Edge | Category::Large
        )
    };
    let t: Vec<&Sample> = samples.iter().filter(target).collect();
    let errors: Vec<f64> = t.iter().filter_map(|s| s.error_px).collect();
    let count = |c: Category| {
        let v: Vec<&Sample> = samples.iter().filter(|s| s.category == c).collect();
        (v.iter().filter(|s| s.error_px.is_some()).count(), v.len())
    };
    let times = |f: &dyn Fn(&Sample) -> bool| {
        quantile(
            samples
                .iter()
                .filter(|s| f(s))
                .map(|s| s.times.total_ms)
                .collect(),
            0.5,
        )
    };
    Pooled {
        name,
        error_median_px: quantile(errors.clone(), 0.5),
        error_p95_px: quantile(errors, 0.95),
        found: (t.iter().filter(|s| s.error_px.is_some()).count(), t.len()),
        small_found: count(Category::Small),
        false_positives: count(Category::NoContact),
        total_median_ms: times(&|_| true),
        contact_median_ms: times(&|s| s.has_truth),
        no_contact_median_ms: times(&|s| !s.has_truth),
    }
}

/// Markdown Pareto table of pooled settings.
pub fn pareto_markdown(rows: &[Pooled]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "| setting | err median px | err p95 px | found (nom+edge+large) | small found | false + | total ms median | contact frames ms | no-contact frames ms |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {:.2} | {:.2} | {}/{} | {}/{} | {}/{} | {:.3} | {:.3} | {:.3} |",
            r.name,
            r.error_median_px,
            r.error_p95_px,
            r.found.0,
            r.found.1,
            r.small_found.0,
            r.small_found.1,
            r.false_positives.0,
            r.false_positives.1,
            r.total_median_ms,
            r.contact_median_ms,
            r.no_contact_median_ms
        );
    }
    s
}

/// Median stage times of the default pipeline at `width x height` (the
/// sensor, h and mm/px scaled with the image so the scene is the same), on
/// nominal-contact and no-contact frames.
pub fn time_at_size(
    width: usize,
    height: usize,
    frames: usize,
    seed: u64,
) -> Result<(StageTimes, StageTimes), CalibrationError> {
    let scale = width as f64 / 640.0;
    let mut params = Params::default();
    params.frame.work_width_px = width as u32;
    params.frame.work_height_px = height as u32;
    params.density.kernel_width_px *= scale;
    params.frame.mm_per_px /= scale;
    params.contact.move_noise_px *= scale.max(0.5);
    let setting = Setting {
        name: "default",
        params,
    };
    let contact = evaluate(&setting, &[Category::Nominal], frames, width, height, seed)?;
    let idle = evaluate(
        &setting,
        &[Category::NoContact],
        frames,
        width,
        height,
        seed,
    )?;
    let med = |v: &[Sample]| {
        let q = |f: &dyn Fn(&Sample) -> f64| quantile(v.iter().map(f).collect(), 0.5);
        StageTimes {
            detect_ms: q(&|s| s.times.detect_ms),
            kde_ms: q(&|s| s.times.kde_ms),
            segment_ms: q(&|s| s.times.segment_ms),
            total_ms: q(&|s| s.times.total_ms),
        }
    };
    Ok((med(&contact), med(&idle)))
}

/// Difference of the fast density path from the exact f64 reference on the
/// markers of `frames` nominal frames: for each grid step, the largest and
/// the mean absolute difference at the fast path's samples, as a fraction of
/// the interior rest density (90th percentile of the reference values).
pub fn density_difference(steps: &[u32], frames: usize, seed: u64) -> Vec<(u32, f64, f64)> {
    let sensor = Category::Nominal.sensor(640, 480, seed);
    let params = Params::default();
    let (h, mm) = (params.density.kernel_width_px, params.frame.mm_per_px);
    let scenes: Vec<Vec<crate::PointPx>> = (0..frames)
        .map(|k| synth::render(&Category::Nominal.scene(&sensor, seed + k as u64)).markers)
        .collect();
    let mut out = Vec::new();
    for &step in steps {
        let setup = crate::density::DensitySetup {
            width: 640,
            height: 480,
            h_px: h,
            mm_per_px: mm,
            mode: DensityMode::Fast,
            step_px: step as usize,
            truncate_sigmas: params.density.truncate_sigmas,
            skin: None,
        };
        let (mut worst, mut sum, mut n) = (0f64, 0f64, 0usize);
        for m in &scenes {
            let fast = crate::density::estimate(m, &setup, None);
            let g = fast.grid;
            let mut pairs = Vec::with_capacity(g.nx * g.ny);
            for j in 0..g.ny {
                for i in 0..g.nx {
                    let want = crate::density::exact_at(m, g.point(i as f64, j as f64), h, mm);
                    pairs.push((fast.at(i, j) as f64, want));
                }
            }
            let typical = quantile(pairs.iter().map(|p| p.1).collect(), 0.9);
            for (got, want) in pairs {
                let d = (got - want).abs() / typical;
                worst = worst.max(d);
                sum += d;
                n += 1;
            }
        }
        out.push((step, worst, sum / n.max(1) as f64));
    }
    out
}
