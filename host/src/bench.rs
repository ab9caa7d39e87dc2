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
        for k in 0..frames {
            let (sensor, pipeline) = &sensors[k % sensors.len()];
            let scene = cat.scene(sensor, seed.wrapping_mul(1000).wrapping_add(k as u64));
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

    #[test]
    fn pareto_plot_has_labels_in_each_setting_colour() {
        let row = |name, ms, err| Pooled {
            name,
            error_median_px: err,
            error_p95_px: 3.0 * err,
            found: (1, 1),
            small_found: (0, 1),
            false_positives: (0, 1),
            total_median_ms: ms,
            contact_median_ms: ms,
            no_contact_median_ms: ms,
        };
        let rows = [
            row("slow", 40.0, 0.05),
            row("fast", 0.4, f64::NAN),
            row("odd", f64::INFINITY, 1e9),
        ];
        let colours = [[200, 0, 0], [0, 0, 220], [0, 160, 160]];
        let img = pareto_plot(&rows, &colours);
        // The legend (right of the plot area) names every setting in its
        // colour, even one without a finite point.
        for c in colours {
            let legend = img
                .enumerate_pixels()
                .filter(|(x, _, p)| *x > 700 && p.0 == c)
                .count();
            assert!(legend > 50, "{c:?}: {legend} px");
        }
        // Axis and target labels: dark text below the x axis.
        let below_axis = img
            .enumerate_pixels()
            .filter(|(x, y, p)| *x < 690 && *y > 505 && p.0 == [0, 0, 0])
            .count();
        assert!(below_axis > 100, "{below_axis}");
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

/// The Pareto plot: x = median total time per frame (log, 0.1-1000 ms),
/// y = centre error (log, 0.01-1000 px); a filled square per setting at its
/// median error, a hollow one at its p95, numbered as in the legend on the
/// right (setting names in their colours), the number next to the median; grid lines per decade with their
/// values, the targets (0.5 ms, 1 px) as labelled green lines.
pub fn pareto_plot(rows: &[Pooled], colours: &[[u8; 3]]) -> image::RgbImage {
    use crate::sim::output::text;
    use image::Rgb;
    let (w, h) = (1160u32, 560u32);
    let (left, right, top, bottom) = (70.0, 690.0, 40.0, 500.0);
    let mut img = image::RgbImage::from_pixel(w, h, Rgb([255, 255, 255]));
    let x_of = |ms: f64| left + (ms.clamp(0.1, 1000.0).log10() + 1.0) / 4.0 * (right - left);
    let y_of = |px: f64| bottom - (px.clamp(0.01, 1000.0).log10() + 2.0) / 5.0 * (bottom - top);
    let line = |img: &mut image::RgbImage, x0: f64, y0: f64, x1: f64, y1: f64, c: [u8; 3]| {
        let n = ((x1 - x0).abs().max((y1 - y0).abs()) as usize).max(1);
        for k in 0..=n {
            let t = k as f64 / n as f64;
            let (x, y) = (x0 + t * (x1 - x0), y0 + t * (y1 - y0));
            if x >= 0.0 && y >= 0.0 && (x as u32) < w && (y as u32) < h {
                img.put_pixel(x as u32, y as u32, Rgb(c));
            }
        }
    };
    let black = Rgb([0, 0, 0]);
    let grey = Rgb([90, 90, 90]);
    let green = [60, 170, 60];
    // 4 * scale px per character, 5 * scale px high.
    let width_of = |s: &str, scale: i64| s.chars().count() as i64 * 4 * scale;
    for (d, label) in ["0.1", "1", "10", "100", "1000"].iter().enumerate() {
        let x = x_of(10f64.powi(d as i32 - 1));
        line(&mut img, x, top, x, bottom, [210, 210, 210]);
        text(
            &mut img,
            x as i64 - width_of(label, 2) / 2,
            bottom as i64 + 8,
            label,
            2,
            grey,
        );
    }
    for (d, label) in ["0.01", "0.1", "1", "10", "100", "1000"].iter().enumerate() {
        let y = y_of(10f64.powi(d as i32 - 2));
        line(&mut img, left, y, right, y, [210, 210, 210]);
        text(
            &mut img,
            left as i64 - 6 - width_of(label, 2),
            y as i64 - 5,
            label,
            2,
            grey,
        );
    }
    // Targets: 0.5 ms and 1 px.
    line(&mut img, x_of(0.5), top, x_of(0.5), bottom, green);
    line(&mut img, left, y_of(1.0), right, y_of(1.0), green);
    text(
        &mut img,
        x_of(0.5) as i64 + 4,
        top as i64 + 4,
        "target 0.5 ms",
        2,
        Rgb(green),
    );
    let t1 = "target 1 px";
    text(
        &mut img,
        right as i64 - width_of(t1, 2) - 4,
        y_of(1.0) as i64 - 14,
        t1,
        2,
        Rgb(green),
    );
    line(&mut img, left, bottom, right, bottom, [0, 0, 0]);
    line(&mut img, left, top, left, bottom, [0, 0, 0]);
    let x_label = "median total time per frame, ms (log)";
    text(
        &mut img,
        ((left + right) / 2.0) as i64 - width_of(x_label, 2) / 2,
        bottom as i64 + 30,
        x_label,
        2,
        black,
    );
    text(
        &mut img,
        8,
        12,
        "centre error, px (log): nominal + edge + large",
        2,
        black,
    );
    let square = |img: &mut image::RgbImage, x: f64, y: f64, filled: bool, c: [u8; 3]| {
        for dy in -5i32..=5 {
            for dx in -5i32..=5 {
                let edge = dx.abs() == 5 || dy.abs() == 5;
                if filled || edge {
                    let (px, py) = (x as i32 + dx, y as i32 + dy);
                    if px >= 0 && py >= 0 && (px as u32) < w && (py as u32) < h {
                        img.put_pixel(px as u32, py as u32, Rgb(c));
                    }
                }
            }
        }
    };
    for (k, (r, c)) in rows.iter().zip(colours).enumerate() {
        let x = x_of(r.total_median_ms);
        for (err, filled) in [(r.error_median_px, true), (r.error_p95_px, false)] {
            if !err.is_finite() || !x.is_finite() {
                continue;
            }
            let y = y_of(err);
            square(&mut img, x, y, filled, *c);
            if !filled {
                continue;
            }
            // The setting's number next to its median; neighbours alternate
            // sides so that clustered settings stay readable.
            let n = (k + 1).to_string();
            let dx = if k % 2 == 0 { 9 } else { -9 - width_of(&n, 2) };
            let dy = if k % 4 < 2 { -16 } else { 6 };
            text(&mut img, x as i64 + dx, y as i64 + dy, &n, 2, Rgb(*c));
        }
    }
    // Legend.
    let (lx, mut ly) = (right as i64 + 24, top as i64);
    text(&mut img, lx, ly, "settings (filled = median,", 2, black);
    text(&mut img, lx, ly + 14, "hollow = p95):", 2, black);
    ly += 40;
    for (k, (r, c)) in rows.iter().zip(colours).enumerate() {
        square(&mut img, lx as f64 + 5.0, ly as f64 + 4.0, true, *c);
        let label = format!("{} {}", k + 1, r.name);
        text(&mut img, lx + 16, ly, &label, 2, Rgb(*c));
        ly += 22;
    }
    img
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
