//! The tactile benchmark's Pareto plot (`dexitac bench-pipeline` writes
//! `pareto.png` and `pareto.svg`): accuracy against run time per pipeline
//! setting.
//!
//! x = median total time per frame (ms, log, 0.1-1000), y = centre error on
//! the nominal, edge and large scenes (px, log, 0.01-1000), grid lines per
//! decade with their values. Each setting has its colour: a filled square
//! at its median error, a hollow one at its p95, its number next to the
//! median; the legend on the right names the numbered settings in their
//! colours. The targets ([`TARGET_MS`], [`TARGET_PX`]) are labelled green
//! lines. Points outside the axes are clamped to their edge; a setting
//! without a finite time or error has no point but keeps its legend row.

use std::path::Path;

use dexitac_tactile::bench::Pooled;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{font, house_mesh, legend, write_png_and_svg, Figure, FigureError, LegendEntry, Mark};

/// Target median time per frame, ms.
pub const TARGET_MS: f64 = 0.5;
/// Target centre error, px.
pub const TARGET_PX: f64 = 1.0;

// A little beyond the decades, so that plotters labels the first one too.
const TIME_MS: (f64, f64) = (0.09, 1100.0);
const ERROR_PX: (f64, f64) = (0.009, 1100.0);
const KEY: RGBColor = RGBColor(100, 100, 100);
const TARGET: RGBColor = RGBColor(40, 150, 40);
const LEGEND_PX: u32 = 340;

/// The Pareto plot of the pooled benchmark rows, one colour per row.
#[derive(Debug, Clone, Copy)]
pub struct ParetoFigure<'a> {
    /// One row per setting.
    pub rows: &'a [Pooled],
    /// The settings' colours (RGB), in row order; rows without one are grey.
    pub colours: &'a [[u8; 3]],
}

/// Writes `pareto.png` and `pareto.svg` into `dir`.
pub fn write(rows: &[Pooled], colours: &[[u8; 3]], dir: &Path) -> Result<(), FigureError> {
    write_png_and_svg(&ParetoFigure { rows, colours }, dir, "pareto")
}

impl ParetoFigure<'_> {
    fn colour(&self, k: usize) -> RGBColor {
        let [r, g, b] = self.colours.get(k).copied().unwrap_or([128, 128, 128]);
        RGBColor(r, g, b)
    }
}

/// A decade's label: 0.01, 0.1, 1, 10, ...
fn decade(v: &f64) -> String {
    if *v >= 1.0 {
        format!("{v:.0}")
    } else {
        let digits = (-v.log10()).ceil().max(0.0) as usize;
        format!("{v:.digits$}")
    }
}

impl Figure for ParetoFigure<'_> {
    fn size_px(&self) -> (u32, u32) {
        let rows = 3 + self.rows.len() as u32;
        (1180, (rows * 20 + 120).max(620))
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), FigureError> {
        let (w, _) = self.size_px();
        let body = root.titled(
            "Tactile pipeline settings: time against centre error (640x480)",
            font(22),
        )?;
        let (plot, side) = body.split_horizontally(w - LEGEND_PX);
        let mut chart = ChartBuilder::on(&plot)
            .margin(12)
            .margin_right(24)
            .x_label_area_size(55)
            .y_label_area_size(80)
            .build_cartesian_2d(
                (TIME_MS.0..TIME_MS.1).log_scale(),
                (ERROR_PX.0..ERROR_PX.1).log_scale(),
            )?;
        house_mesh(&mut chart.configure_mesh())
            .x_desc("median total time per frame (ms, log)")
            .y_desc("centre error (px, log): nominal + edge + large")
            .x_label_formatter(&decade)
            .y_label_formatter(&decade)
            .draw()?;
        let target = TARGET.stroke_width(2);
        chart.draw_series(LineSeries::new(
            [(TARGET_MS, ERROR_PX.0), (TARGET_MS, ERROR_PX.1)],
            target,
        ))?;
        chart.draw_series(LineSeries::new(
            [(TIME_MS.0, TARGET_PX), (TIME_MS.1, TARGET_PX)],
            target,
        ))?;
        let label = font(15).color(&TARGET);
        chart.draw_series([
            Text::new(
                format!("target {TARGET_MS} ms"),
                (TARGET_MS * 1.08, ERROR_PX.1 / 1.6),
                label.clone(),
            ),
            Text::new(
                format!("target {TARGET_PX} px"),
                (TIME_MS.1 / 9.0, TARGET_PX * 1.6),
                label,
            ),
        ])?;
        let clamp = |v: f64, (lo, hi): (f64, f64)| v.is_finite().then(|| v.clamp(lo, hi));
        for (k, r) in self.rows.iter().enumerate() {
            let c = self.colour(k);
            let Some(x) = clamp(r.total_median_ms, TIME_MS) else {
                continue;
            };
            if let Some(p95) = clamp(r.error_p95_px, ERROR_PX) {
                chart.draw_series(std::iter::once(
                    EmptyElement::at((x, p95))
                        + Rectangle::new([(-6, -6), (6, 6)], c.stroke_width(2)),
                ))?;
            }
            if let Some(median) = clamp(r.error_median_px, ERROR_PX) {
                // Neighbours put their numbers on alternate sides, so that
                // clustered settings stay readable.
                let dx = if k % 2 == 0 { 10 } else { -22 };
                let dy = if k % 4 < 2 { -22 } else { 8 };
                let number = font(15).color(&c);
                chart.draw_series(std::iter::once(
                    EmptyElement::at((x, median))
                        + Rectangle::new([(-6, -6), (6, 6)], c.filled())
                        + Text::new((k + 1).to_string(), (dx, dy), number),
                ))?;
            }
        }
        let mut entries = vec![
            LegendEntry::new("settings: filled = median,", KEY, Mark::Box),
            LegendEntry::new("hollow = p95 error", KEY, Mark::Hollow),
            LegendEntry::new("targets", TARGET, Mark::Line),
        ];
        entries.extend(self.rows.iter().enumerate().map(|(k, r)| {
            LegendEntry::new(format!("{} {}", k + 1, r.name), self.colour(k), Mark::Box)
        }));
        legend(&side.margin(30, 0, 0, 0), &entries, None)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_support::check_figure;

    fn row(name: &'static str, ms: f64, err: f64) -> Pooled {
        Pooled {
            name,
            error_median_px: err,
            error_p95_px: 3.0 * err,
            found: (1, 1),
            small_found: (0, 1),
            false_positives: (0, 1),
            total_median_ms: ms,
            contact_median_ms: ms,
            no_contact_median_ms: ms,
        }
    }

    #[test]
    fn pareto_plot_has_a_legend_row_in_each_setting_colour_and_labels() {
        let rows = [
            row("slow", 40.0, 0.05),
            row("fast", 0.4, f64::NAN),
            row("odd", f64::INFINITY, 1e9),
        ];
        let colours = [[200, 0, 0], [0, 0, 220], [0, 160, 160]];
        let figure = ParetoFigure {
            rows: &rows,
            colours: &colours,
        };
        let img = check_figure(
            &figure,
            &[
                "1 slow",
                "2 fast",
                "3 odd",
                "target 0.5 ms",
                "target 1 px",
                "median total time per frame (ms, log)",
                "centre error (px, log)",
            ],
        );
        // The legend (right of the plot area) marks every setting in its
        // colour, even one without a finite point.
        let (w, _) = figure.size_px();
        for c in colours {
            let legend = img
                .enumerate_pixels()
                .filter(|(x, _, p)| *x > w - LEGEND_PX && p.0 == c)
                .count();
            assert!(legend > 150, "{c:?}: {legend} px");
        }
        // The only point (setting 1, 40 ms) is drawn: its filled square.
        let red_in_plot = img
            .enumerate_pixels()
            .filter(|(x, _, p)| *x < w - LEGEND_PX && p.0 == colours[0])
            .count();
        assert!(red_in_plot > 100, "{red_in_plot}");
    }

    #[test]
    fn pareto_plot_of_no_settings_still_has_axes_and_targets() {
        check_figure(
            &ParetoFigure {
                rows: &[],
                colours: &[],
            },
            &["target 0.5 ms", "Tactile pipeline settings"],
        );
    }
}
