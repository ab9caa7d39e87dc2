//! The tactile benchmark's Pareto plot (`dexitac bench-pipeline`):
//! accuracy against run time per pipeline setting.

use dexitac_tactile::bench::Pooled;
use image::Rgb;

use crate::raster::text;

/// The Pareto plot: x = median total time per frame (log, 0.1-1000 ms),
/// y = centre error (log, 0.01-1000 px); a filled square per setting at its
/// median error, a hollow one at its p95, numbered as in the legend on the
/// right (setting names in their colours), the number next to the median; grid lines per decade with their
/// values, the targets (0.5 ms, 1 px) as labelled green lines.
pub fn pareto_plot(rows: &[Pooled], colours: &[[u8; 3]]) -> image::RgbImage {
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

#[cfg(test)]
mod tests {
    use super::*;

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
