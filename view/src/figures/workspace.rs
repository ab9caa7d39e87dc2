//! Workspace views of one finger (`dexitac workspace` writes
//! `<finger>-xy`, `-xz` and `-3d`, each as PNG and SVG): scatter views of
//! its reachable points, in mm of the finger frame (origin at the finger
//! base, z along the finger at rest).
//!
//! - [`View::Xy`]: looking down the z axis, x right, y up; [`View::Xz`]:
//!   from the side, x right, z up. Both with numbered axes in mm at equal
//!   scale, a grid, the axes through the finger base as thin dark lines and
//!   the base marked.
//! - [`View::ThreeD`]: an oblique 3-D view (plotters' 3-D chart) with
//!   three numbered axes in mm, z up.
//!
//! Points are coloured by the coordinate the view hides (z in the x-y
//! view, y in the x-z view, z in the 3-D view), blue (low) to red (high),
//! with a colour bar giving its values, and drawn far to near. The title
//! (given by the caller: finger type, configuration) names the view.

use std::path::Path;

use dexitac_gripper::workspace::extents;
use plotters::coord::Shift;
use plotters::prelude::*;

use super::{colour_bar, font, write_png_and_svg, Figure, FigureError};

/// A view of the point cloud.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum View {
    /// Looking down the finger's z axis: x right, y up.
    Xy,
    /// From the side: x right, z up.
    Xz,
    /// Oblique 3-D view, z up.
    ThreeD,
}

impl View {
    /// The view's name in titles and file names: `xy`, `xz`, `3d`.
    pub const fn name(self) -> &'static str {
        match self {
            View::Xy => "xy",
            View::Xz => "xz",
            View::ThreeD => "3d",
        }
    }

    /// Index of the coordinate the points are coloured by, and its name.
    const fn colour_axis(self) -> (usize, &'static str) {
        match self {
            View::Xy | View::ThreeD => (2, "z (mm)"),
            View::Xz => (1, "y (mm)"),
        }
    }
}

/// A workspace view (module docs).
#[derive(Debug, Clone, Copy)]
pub struct WorkspaceFigure<'a> {
    /// Reachable points, mm (x, y, z).
    pub points: &'a [[f64; 3]],
    /// Which view.
    pub view: View,
    /// The title's first part: finger type and configuration.
    pub title: &'a str,
    /// Width and height, px.
    pub size_px: u32,
}

/// Writes the view as `<stem>.png` and `<stem>.svg` in `dir`.
pub fn write(figure: &WorkspaceFigure<'_>, dir: &Path, stem: &str) -> Result<(), FigureError> {
    write_png_and_svg(figure, dir, stem)
}

const AXES: RGBColor = RGBColor(70, 70, 70);

/// Blue (t = 0) through purple to red (t = 1).
fn depth_colour(t: f64) -> RGBColor {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.5
    };
    RGBColor(
        (230.0 * t) as u8,
        (60.0 + 60.0 * (1.0 - (2.0 * t - 1.0).abs())) as u8,
        (230.0 * (1.0 - t)) as u8,
    )
}

/// The finite points and their extents with the origin included, mm.
struct Cloud {
    points: Vec<[f64; 3]>,
    lo: [f64; 3],
    hi: [f64; 3],
}

impl WorkspaceFigure<'_> {
    /// The finite points, and their extents with the origin included.
    fn finite(&self) -> Cloud {
        let mut pts: Vec<[f64; 3]> = self
            .points
            .iter()
            .copied()
            .filter(|p| p.iter().all(|v| v.is_finite()))
            .collect();
        pts.push([0.0; 3]);
        let e = extents(pts.iter());
        pts.pop();
        Cloud {
            points: pts,
            lo: e.min_mm,
            hi: e.max_mm,
        }
    }

    /// The colour scale: the range of the coloured coordinate over the
    /// points (the origin not included), or `fallback` without points.
    fn colour_range(&self, pts: &[[f64; 3]], fallback: (f64, f64)) -> (f64, f64) {
        let (c, _) = self.view.colour_axis();
        if pts.is_empty() {
            return fallback;
        }
        let e = extents(pts.iter());
        (e.min_mm[c], e.max_mm[c])
    }

    /// Pixel scale of the figure's text and margins (1 at 800 px).
    fn scale(&self) -> f64 {
        (f64::from(self.size_px) / 800.0).clamp(0.25, 3.0)
    }

    fn px(&self, base: f64) -> u32 {
        (base * self.scale()).round().max(1.0) as u32
    }

    fn planar<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        cloud: &Cloud,
    ) -> Result<(), FigureError> {
        let (pts, lo, hi) = (&cloud.points[..], cloud.lo, cloud.hi);
        let (a, b, names) = match self.view {
            View::Xz => (0, 2, ("x (mm)", "z (mm)")),
            _ => (0, 1, ("x (mm)", "y (mm)")),
        };
        let builder = |area| {
            let mut b = ChartBuilder::on(area);
            b.margin(self.px(12.0))
                .x_label_area_size(self.px(50.0))
                .y_label_area_size(self.px(65.0));
            b
        };
        // Equal scale: the plotting area's size decides the ranges, so the
        // chart is built once to measure it (nothing is drawn) and again to
        // draw.
        let (w, h) = builder(area)
            .build_cartesian_2d(0.0..1.0, 0.0..1.0)?
            .plotting_area()
            .dim_in_pixel();
        let (w, h) = (f64::from(w.max(1)), f64::from(h.max(1)));
        let span = |k: usize| (hi[k] - lo[k]).max(1.0) * 1.08;
        let mm_per_px = (span(a) / w).max(span(b) / h);
        let centre = |k: usize| 0.5 * (lo[k] + hi[k]);
        let half = |px: f64| 0.5 * mm_per_px * px;
        let x = (centre(a) - half(w))..(centre(a) + half(w));
        let y = (centre(b) - half(h))..(centre(b) + half(h));
        let mut chart = builder(area).build_cartesian_2d(x.clone(), y.clone())?;
        chart
            .configure_mesh()
            .x_desc(names.0)
            .y_desc(names.1)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.0}"))
            .label_style(font(self.px(15.0)))
            .axis_desc_style(font(self.px(16.0)))
            .max_light_lines(4)
            .light_line_style(RGBColor(245, 245, 245))
            .bold_line_style(RGBColor(220, 220, 220))
            .draw()?;
        let thin = AXES.stroke_width(1);
        chart.draw_series(LineSeries::new([(x.start, 0.0), (x.end, 0.0)], thin))?;
        chart.draw_series(LineSeries::new([(0.0, y.start), (0.0, y.end)], thin))?;
        let (c, _) = self.view.colour_axis();
        let (c_lo, c_hi) = self.colour_range(pts, (lo[c], hi[c]));
        let colour = |p: &[f64; 3]| depth_colour((p[c] - c_lo) / (c_hi - c_lo).max(1e-9));
        // Far to near: looking down z, the highest points are nearest;
        // from the side (looking along +y), the smallest y.
        let mut order: Vec<&[f64; 3]> = pts.iter().collect();
        match self.view {
            View::Xz => order.sort_by(|p, q| q[1].total_cmp(&p[1])),
            _ => order.sort_by(|p, q| p[2].total_cmp(&q[2])),
        }
        let r = self.px(2.0);
        chart.draw_series(
            order
                .into_iter()
                .map(|p| Circle::new((p[a], p[b]), r, colour(p).filled())),
        )?;
        chart.draw_series([EmptyElement::at((0.0, 0.0))
            + Cross::new((0, 0), self.px(7.0), BLACK.stroke_width(2))
            + Text::new("finger base", (8, 4), font(self.px(14.0)))])?;
        Ok(())
    }

    fn three_d<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        cloud: &Cloud,
    ) -> Result<(), FigureError> {
        let (pts, lo, hi) = (&cloud.points[..], cloud.lo, cloud.hi);
        let pad = |k: usize| 0.05 * (hi[k] - lo[k]).max(1.0);
        let range = |k: usize| (lo[k] - pad(k))..(hi[k] + pad(k));
        // plotters' 3-D axes are (x, y up, z): our (x, z, y).
        let mut chart = ChartBuilder::on(area)
            .margin(self.px(16.0))
            .build_cartesian_3d(range(0), range(2), range(1))?;
        chart.with_projection(|mut p| {
            p.yaw = 0.6;
            p.pitch = 0.35;
            p.scale = 0.72;
            p.into_matrix()
        });
        chart
            .configure_axes()
            .label_style(font(self.px(14.0)))
            .x_formatter(&|v| format!("{v:.0}"))
            .y_formatter(&|v| format!("{v:.0}"))
            .z_formatter(&|v| format!("{v:.0}"))
            .light_grid_style(RGBColor(235, 235, 235))
            .max_light_lines(3)
            .draw()?;
        let (xr, zr, yr) = (range(0), range(2), range(1));
        let name = font(self.px(17.0)).color(&BLACK);
        // Each axis named beyond its end, clear of the tick labels (a
        // pixel offset from the axis end).
        let d = self.px(10.0) as i32;
        chart.draw_series([
            EmptyElement::at((xr.end, zr.start, yr.start))
                + Text::new("x (mm)", (d, 0), name.clone()),
            EmptyElement::at((xr.start, zr.start, yr.end))
                + Text::new("y (mm)", (-7 * d, -d), name.clone()),
            EmptyElement::at((xr.start, zr.end, yr.start)) + Text::new("z (mm)", (0, -3 * d), name),
        ])?;
        let mut order: Vec<&[f64; 3]> = pts.iter().collect();
        // Far to near along the view direction (yaw about the vertical).
        let (s, c) = 0.6f64.sin_cos();
        order.sort_by(|p, q| (c * q[1] - s * q[0]).total_cmp(&(c * p[1] - s * p[0])));
        let (c_lo, c_hi) = self.colour_range(pts, (lo[2], hi[2]));
        let colour = |p: &[f64; 3]| depth_colour((p[2] - c_lo) / (c_hi - c_lo).max(1e-9));
        let r = self.px(2.0);
        chart.draw_series(
            order
                .into_iter()
                .map(|p| Circle::new((p[0], p[2], p[1]), r, colour(p).filled())),
        )?;
        chart.draw_series([EmptyElement::at((0.0, 0.0, 0.0))
            + Cross::new((0, 0), self.px(7.0), BLACK.stroke_width(2))
            + Text::new("finger base", (8, 4), font(self.px(14.0)))])?;
        Ok(())
    }
}

impl Figure for WorkspaceFigure<'_> {
    fn size_px(&self) -> (u32, u32) {
        (self.size_px, self.size_px)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), FigureError> {
        let view = match self.view {
            View::Xy => "x-y view (from above)",
            View::Xz => "x-z view (from the side)",
            View::ThreeD => "3-D view",
        };
        let title = format!("{}: {view}", self.title);
        let body = root.titled(&title, font(self.px(20.0)))?;
        let (plot, bar) = body.split_horizontally(self.size_px.saturating_sub(self.px(150.0)));
        let cloud = self.finite();
        match self.view {
            View::Xy | View::Xz => self.planar(&plot, &cloud)?,
            View::ThreeD => self.three_d(&plot, &cloud)?,
        }
        let (pts, lo, hi) = (&cloud.points, cloud.lo, cloud.hi);
        let (c, name) = self.view.colour_axis();
        let (c_lo, c_hi) = self.colour_range(pts, (lo[c], hi[c]));
        colour_bar(&bar, (c_lo, c_hi), name, &|v| {
            depth_colour((v - c_lo) / (c_hi - c_lo).max(1e-9))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_support::check_figure;

    #[test]
    fn every_view_draws_points_with_named_axes() {
        let pts = [[0.0, 0.0, 50.0], [10.0, -5.0, 40.0], [-20.0, 3.0, 60.0]];
        for view in [View::Xy, View::Xz, View::ThreeD] {
            let figure = WorkspaceFigure {
                points: &pts,
                view,
                title: "dex-rot finger workspace",
                size_px: 400,
            };
            let img = check_figure(&figure, &["dex-rot finger workspace", "x (mm)", "z (mm)"]);
            assert_eq!(img.dimensions(), (400, 400));
            let coloured = img
                .pixels()
                .filter(|p| p.0[0].abs_diff(p.0[2]) > 60)
                .count();
            assert!(coloured >= 3, "{view:?}: {coloured}");
        }
    }

    #[test]
    fn views_of_no_point_one_point_and_nan_do_not_fail() {
        let cases: [&[[f64; 3]]; 3] = [
            &[],
            &[[5.0, 5.0, 5.0]],
            &[[f64::NAN, 1.0, 2.0], [1.0, 2.0, 3.0]],
        ];
        for pts in cases {
            for view in [View::Xy, View::Xz, View::ThreeD] {
                for size_px in [64, 300] {
                    let figure = WorkspaceFigure {
                        points: pts,
                        view,
                        title: "empty",
                        size_px,
                    };
                    check_figure(&figure, &["empty"]);
                }
            }
        }
    }
}
