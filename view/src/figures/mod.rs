//! Figures the commands write, drawn with [`plotters`] as PNG and SVG: a
//! simulated run's disturbance figure and density heatmaps ([`sim_run`]),
//! the tactile benchmark's Pareto plot ([`pareto`]) and a finger's
//! workspace views ([`workspace`]).
//!
//! Each figure is a [`Figure`]: one `draw` for both backends, so the PNG
//! and the SVG show the same thing. Text is set in DejaVu Sans, embedded
//! in the binary (the `dejavu` crate, drawn by plotters' `ab_glyph`
//! feature): figures need no system font, fontconfig or network at run
//! time. This module holds what the figures share: the error type, the
//! renderers and writers, the colours, the legend column and the colour
//! bar.

pub mod pareto;
pub mod sim_run;
pub mod workspace;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use image::RgbImage;
use plotters::chart::MeshStyle;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::Shift;
use plotters::prelude::*;

/// Why a figure could not be drawn or written.
#[derive(Debug, thiserror::Error)]
pub enum FigureError {
    /// The embedded font could not be loaded (a broken build).
    #[error("the embedded font (DejaVu Sans) could not be loaded")]
    Font,
    /// Drawing failed (plotters reported an error).
    #[error("drawing the figure: {0}")]
    Draw(String),
    /// A file could not be written.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A PNG could not be encoded or written.
    #[error("cannot write {path}: {source}")]
    Png {
        /// The file.
        path: PathBuf,
        /// The image error.
        source: image::ImageError,
    },
}

impl<E: std::error::Error + Send + Sync> From<DrawingAreaErrorKind<E>> for FigureError {
    fn from(e: DrawingAreaErrorKind<E>) -> Self {
        FigureError::Draw(e.to_string())
    }
}

/// A figure: its size and one drawing for every backend.
pub trait Figure {
    /// Width and height, px.
    fn size_px(&self) -> (u32, u32);
    /// Draws the figure onto `root` (already filled white).
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), FigureError>;
}

/// The font family the figures' text uses (DejaVu Sans, registered once).
const FAMILY: &str = "sans-serif";

/// Registers the embedded DejaVu Sans as [`FAMILY`] (once per process).
fn font_ready() -> Result<(), FigureError> {
    static READY: OnceLock<bool> = OnceLock::new();
    let ok = *READY.get_or_init(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, dejavu::sans::regular()).is_ok()
            && plotters::style::register_font(FAMILY, FontStyle::Bold, dejavu::sans::bold()).is_ok()
    });
    ok.then_some(()).ok_or(FigureError::Font)
}

/// Renders `figure` to an RGB image.
pub fn render_png(figure: &impl Figure) -> Result<RgbImage, FigureError> {
    font_ready()?;
    let (w, h) = figure.size_px();
    let mut buf = vec![255u8; w as usize * h as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE)?;
        figure.draw(&root)?;
        root.present()?;
    }
    RgbImage::from_raw(w, h, buf)
        .ok_or_else(|| FigureError::Draw("pixel buffer of the wrong size".into()))
}

/// Renders `figure` to an SVG document.
pub fn render_svg(figure: &impl Figure) -> Result<String, FigureError> {
    font_ready()?;
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, figure.size_px()).into_drawing_area();
        root.fill(&WHITE)?;
        figure.draw(&root)?;
        root.present()?;
    }
    Ok(svg)
}

/// Writes `figure` as a PNG file.
pub fn write_png(figure: &impl Figure, path: &Path) -> Result<(), FigureError> {
    render_png(figure)?
        .save(path)
        .map_err(|source| FigureError::Png {
            path: path.to_path_buf(),
            source,
        })
}

/// Writes `figure` as `<stem>.png` and `<stem>.svg` in `dir`.
pub fn write_png_and_svg(figure: &impl Figure, dir: &Path, stem: &str) -> Result<(), FigureError> {
    write_png(figure, &dir.join(format!("{stem}.png")))?;
    let path = dir.join(format!("{stem}.svg"));
    let svg = render_svg(figure)?;
    std::fs::write(&path, svg).map_err(|source| FigureError::Io { path, source })
}

/// The figures' text style, `px` high.
pub fn font(px: u32) -> TextStyle<'static> {
    (FAMILY, px).into_font().into()
}

/// The figures' mesh style: tick labels and axis names in [`font`], a light
/// grid. Callers add the axis names, formatters and label counts.
pub fn house_mesh<'m, 'a, 'b, X, Y, XT, YT, DB>(
    mesh: &'m mut MeshStyle<'a, 'b, X, Y, DB>,
) -> &'m mut MeshStyle<'a, 'b, X, Y, DB>
where
    X: Ranged<ValueType = XT> + ValueFormatter<XT>,
    Y: Ranged<ValueType = YT> + ValueFormatter<YT>,
    DB: DrawingBackend,
{
    mesh.label_style(font(15))
        .axis_desc_style(font(16))
        .light_line_style(RGBColor(242, 242, 242))
        .bold_line_style(RGBColor(215, 215, 215))
}

/// Colour of each finger and its tactile sensor (finger 0 blue, finger 1
/// orange), in every figure.
pub const FINGER_COLOURS: [RGBColor; 2] = [RGBColor(31, 119, 180), RGBColor(230, 120, 10)];

/// How a legend entry is marked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mark {
    /// A solid line.
    Line,
    /// A thin solid line.
    Thin,
    /// A dashed line.
    Dashed,
    /// A filled box.
    Box,
    /// A hollow box.
    Hollow,
}

/// One legend entry: its mark in its colour, then its label.
#[derive(Debug, Clone, PartialEq)]
pub struct LegendEntry {
    /// The text.
    pub label: String,
    /// The colour of the mark.
    pub colour: RGBColor,
    /// The mark.
    pub mark: Mark,
}

impl LegendEntry {
    /// An entry.
    pub fn new(label: impl Into<String>, colour: RGBColor, mark: Mark) -> Self {
        LegendEntry {
            label: label.into(),
            colour,
            mark,
        }
    }
}

/// Height of a legend row, px.
const LEGEND_ROW_PX: i32 = 20;

/// Draws a legend in its own area (a column beside a chart, so it never
/// covers data): one row per entry from the top, marks 24 px wide; the
/// labels are drawn in `text_colour` or, when `None`, in each entry's
/// colour.
pub fn legend<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    entries: &[LegendEntry],
    text_colour: Option<RGBColor>,
) -> Result<(), FigureError> {
    for (k, e) in entries.iter().enumerate() {
        let y = 12 + k as i32 * LEGEND_ROW_PX;
        let c = e.colour;
        match e.mark {
            Mark::Line => area.draw(&PathElement::new(
                vec![(4, y + 7), (28, y + 7)],
                c.stroke_width(3),
            ))?,
            Mark::Thin => area.draw(&PathElement::new(
                vec![(4, y + 7), (28, y + 7)],
                c.stroke_width(1),
            ))?,
            Mark::Dashed => {
                for x in [4, 14, 24] {
                    area.draw(&PathElement::new(
                        vec![(x, y + 7), (x + 5, y + 7)],
                        c.stroke_width(2),
                    ))?;
                }
            }
            Mark::Box => area.draw(&Rectangle::new([(6, y + 1), (26, y + 13)], c.filled()))?,
            Mark::Hollow => area.draw(&Rectangle::new(
                [(6, y + 1), (26, y + 13)],
                c.stroke_width(2),
            ))?,
        }
        let text_colour = text_colour.unwrap_or(c);
        let style = font(14).color(&text_colour);
        area.draw(&Text::new(e.label.clone(), (34, y), style))?;
    }
    Ok(())
}

/// Draws a vertical colour bar filling `area`: `lo..hi` upward, each value
/// in `colour(value)`, with numbered ticks and `label` on its right. (Left
/// labels land on the bar in the bitmap backend: plotters 0.3.7 with
/// `ab_glyph` places right-aligned text of narrow charts too far right.)
pub fn colour_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    (lo, hi): (f64, f64),
    label: &str,
    colour: &dyn Fn(f64) -> RGBColor,
) -> Result<(), FigureError> {
    let (lo, hi) = match (lo.is_finite() && hi.is_finite(), hi > lo) {
        (true, true) => (lo, hi),
        // One value: a unit range around it.
        (true, false) => (lo - 0.5, lo + 0.5),
        (false, _) => (0.0, 1.0),
    };
    let mut chart = ChartBuilder::on(area)
        .margin(10)
        .margin_top(20)
        .margin_left(30)
        .right_y_label_area_size(75)
        .build_cartesian_2d(0.0..1.0, lo..hi)?;
    chart
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_labels(8)
        .y_desc(label)
        .label_style(font(14))
        .axis_desc_style(font(15))
        .draw()?;
    const STEPS: usize = 100;
    let step = (hi - lo) / STEPS as f64;
    chart.draw_series((0..STEPS).map(|k| {
        let v = lo + k as f64 * step;
        Rectangle::new([(0.0, v), (1.0, v + step)], colour(v + 0.5 * step).filled())
    }))?;
    Ok(())
}

#[cfg(test)]
pub(crate) mod test_support {
    //! Checks every figure's tests share.

    use super::*;

    /// Renders `figure` both ways, writes both files into a temporary
    /// folder, and checks that the PNG is non-empty and that the SVG holds
    /// every one of `texts`. Returns the PNG.
    pub fn check_figure(figure: &impl Figure, texts: &[&str]) -> RgbImage {
        let dir = tempfile::tempdir().unwrap();
        write_png_and_svg(figure, dir.path(), "fig").unwrap();
        let png = std::fs::metadata(dir.path().join("fig.png")).unwrap();
        assert!(png.len() > 1000, "png of {} bytes", png.len());
        let svg = std::fs::read_to_string(dir.path().join("fig.svg")).unwrap();
        for t in texts {
            assert!(svg.contains(t), "the svg has no `{t}`");
        }
        render_png(figure).unwrap()
    }
}
