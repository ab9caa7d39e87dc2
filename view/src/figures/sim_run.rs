//! Figures of a simulated run (`dexitac sim --out DIR`).
//!
//! **`plot.png` and `plot.svg`** ([`RunFigure`]) follow the paper's
//! disturbance figure (its panel (e)): stacked panels sharing the time axis
//! (s), each with its legend in a column on the right:
//!
//! 1. poke force (N), red, each poke's target written above it (runs
//!    without pokes, such as the manipulation tasks, leave this panel out);
//! 2. contact-centre shift per sensor (mm, sensor 0 blue, sensor 1
//!    orange): the frame-to-frame shift D(t) as a thin line and the shift
//!    from the anchor (the centre when the grasp was last sealed) A(t) as a
//!    thick line, with Algorithm 1's T1 and T2
//!    ([`dexitac_gripper::grasp::STABLE_SHIFT_MM`],
//!    [`dexitac_gripper::grasp::SLIP_SHIFT_MM`]) as labelled dashed lines;
//! 3. valve lanes: one lane per grasping chamber and per chamber that
//!    changed state during the run (the manipulation chambers of a task),
//!    named by finger and joint, coloured by state (inflate, hold,
//!    deflate);
//! 4. pressures (kPa): the + tank and the - tank, and each grasping
//!    chamber in its finger's colour (Rot joint solid, Dex palm bellows
//!    dashed);
//! 5. manipulation scenarios only: each finger's manipulation joint angle
//!    and the object's tilt (deg).
//!
//! A light green band runs in every panel from each poke's onset to the
//! valves opening in response (the paper's green response area; a thin
//! band at the onset when the valves never opened), and a red vertical line
//! marks where the object fell. The title names the
//! scenario, the tactile feedback and the outcome; for a run that failed
//! (the MCU tripped or reset, the link or a sensor failed:
//! [`dexitac_sim::status`]) it says `FAILED: <status>` in red instead, with
//! what became of the object (`FAILED: tripped: HostSilence at 11.3 s;
//! object held at the end`). Scheduled pokes the run ended before are not
//! drawn: they never happened.
//!
//! **Heatmaps** `heatmap_NN_<t>s_<event>.png` ([`HeatmapFigure`], at most
//! [`MAX_HEATMAPS`]): both sensors' marker density relative to rest at a
//! decision, on the sensor surface (mm from the image centre, y down), dark
//! red where markers were pushed away, white at rest, blue where denser,
//! with a colour bar, each sensor's name and its measured centre as a
//! black cross.
//!
//! Everything is derived from the [`SimReport`]; nothing here simulates.

use std::path::Path;

use dexitac_gripper::grasp::{SLIP_SHIFT_MM, STABLE_SHIFT_MM};
use dexitac_gripper::manipulation::MANIPULATION_CHAMBERS;
use dexitac_protocol::ValveState;
use dexitac_sim::plant::{PokeTarget, CHAMBERS_PER_FINGER, FINGER_COUNT};
use dexitac_sim::rig::{SimReport, Snapshot};
use dexitac_tactile::density;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::{
    colour_bar, font, house_mesh, legend, write_png, write_png_and_svg, Figure, FigureError,
    LegendEntry, Mark, FINGER_COLOURS,
};
use crate::raster::ratio_colour;

/// Most heatmap snapshots written per run.
pub const MAX_HEATMAPS: usize = 16;

/// Writes `plot.png`, `plot.svg` and the heatmaps
/// (`heatmap_NN_<t>s_<event>.png`) of a simulated run into `dir`.
pub fn write_all(report: &SimReport, dir: &Path) -> Result<(), FigureError> {
    std::fs::create_dir_all(dir).map_err(|source| FigureError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    write_png_and_svg(&RunFigure { report }, dir, "plot")?;
    for (i, snapshot) in report.snapshots.iter().take(MAX_HEATMAPS).enumerate() {
        let name = format!(
            "heatmap_{i:02}_{:.2}s_{}.png",
            secs(snapshot.t_ms),
            snapshot.label
        );
        write_png(&HeatmapFigure { report, snapshot }, &dir.join(name))?;
    }
    Ok(())
}

fn secs(t_ms: u64) -> f64 {
    t_ms as f64 / 1e3
}

const POKE: RGBColor = RGBColor(210, 30, 30);
/// The title of a failed run.
const FAILED: RGBColor = RGBColor(200, 0, 0);
/// Longest status in the title, characters (a long error message is cut).
const TITLE_STATUS_CHARS: usize = 90;
const BAND: RGBColor = RGBColor(205, 240, 205);
const DROP: RGBColor = RGBColor(210, 30, 30);
const POSITIVE_TANK: RGBColor = RGBColor(150, 40, 150);
const NEGATIVE_TANK: RGBColor = RGBColor(20, 150, 150);
const OBJECT: RGBColor = RGBColor(40, 40, 40);
const GUIDE: RGBColor = RGBColor(90, 90, 90);
const INFLATE: RGBColor = RGBColor(220, 90, 70);
const HOLD: RGBColor = RGBColor(222, 222, 222);
const DEFLATE: RGBColor = RGBColor(70, 110, 210);

/// Width of the figure, px.
const WIDTH_PX: u32 = 1500;
/// Width of the legend column right of each panel, px.
const LEGEND_PX: u32 = 330;
/// Height of the title, px.
const TITLE_PX: u32 = 44;
/// Extra height of the bottom panel for the time axis, px.
const TIME_AXIS_PX: u32 = 50;
/// Height of one valve lane, px.
const LANE_PX: u32 = 30;
/// Width of the panels' y label area (lane names), px.
const Y_LABELS_PX: u32 = 140;

/// `plot.png`: the disturbance figure of a simulated run (module docs).
#[derive(Debug, Clone, Copy)]
pub struct RunFigure<'a> {
    /// The run.
    pub report: &'a SimReport,
}

/// The panels of a run's figure, top to bottom.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Panel {
    Force,
    Shift,
    Valves,
    Pressure,
    Angles,
}

impl RunFigure<'_> {
    fn panels(&self) -> Vec<Panel> {
        // A run without pokes (the manipulation tasks) has no force panel.
        let poked = self.report.pokes_reached().next().is_some()
            || self.report.trace.iter().any(|s| s.external_n > 0.0);
        let mut p = vec![Panel::Shift, Panel::Valves, Panel::Pressure];
        if poked {
            p.insert(0, Panel::Force);
        }
        if self.report.task.is_some() {
            p.push(Panel::Angles);
        }
        p
    }

    fn height_of(&self, panel: Panel) -> u32 {
        match panel {
            Panel::Force => 170,
            Panel::Shift => 240,
            Panel::Valves => {
                (LANE_PX * lanes(self.report).len().max(1) as u32 + 30).max(LEGEND_ROW_MIN_PX)
            }
            Panel::Pressure => 240,
            Panel::Angles => 210,
        }
    }

    fn t_max_s(&self) -> f64 {
        let t = self.report.trace.last().map_or(1.0, |s| secs(s.t_ms));
        if t.is_finite() && t > 0.0 {
            t
        } else {
            1.0
        }
    }

    fn title(&self) -> String {
        let r = self.report;
        let feedback = if r.tactile_feedback { "on" } else { "off" };
        let task = r
            .task
            .as_ref()
            .map(|t| format!(", task {} with {}", t.kind.name(), t.gripper))
            .unwrap_or_default();
        let status = r.status();
        if status.is_ok() {
            return format!(
                "Simulated run: {} (tactile feedback {feedback}{task}), outcome {}",
                r.scenario,
                r.outcome.name()
            );
        }
        let mut status = status.to_string();
        if let Some((cut, _)) = status.char_indices().nth(TITLE_STATUS_CHARS) {
            status.truncate(cut);
            status.push_str("...");
        }
        format!(
            "Simulated run: {} (tactile feedback {feedback}{task}), FAILED: {status}; object {} at the end",
            r.scenario,
            r.outcome.name().replace('_', " ")
        )
    }

    fn title_style(&self) -> TextStyle<'static> {
        if self.report.status().is_ok() {
            font(24)
        } else {
            font(24).color(&FAILED)
        }
    }
}

/// Smallest height of the valve panel: room for its three legend rows.
const LEGEND_ROW_MIN_PX: u32 = 110;

impl Figure for RunFigure<'_> {
    fn size_px(&self) -> (u32, u32) {
        let h: u32 = self.panels().iter().map(|&p| self.height_of(p)).sum();
        (WIDTH_PX, TITLE_PX + h + TIME_AXIS_PX)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), FigureError> {
        let r = self.report;
        let (_, h) = self.size_px();
        let body = root.titled(&self.title(), self.title_style())?;
        let panels = self.panels();
        let mut breaks = Vec::new();
        let mut y = 0;
        for (k, &p) in panels.iter().enumerate() {
            y += self.height_of(p);
            if k + 1 < panels.len() {
                breaks.push(y);
            }
        }
        debug_assert!(y + TIME_AXIS_PX + TITLE_PX <= h);
        let rows = body.split_by_breakpoints::<u32, u32, _, _>([], breaks);
        let marks = TimeMarks::of(r);
        for (k, (row, &panel)) in rows.iter().zip(&panels).enumerate() {
            let (plot, side) = row.split_horizontally(WIDTH_PX - LEGEND_PX);
            let p = PanelContext {
                r,
                marks: &marks,
                t_max: self.t_max_s(),
                bottom: k + 1 == panels.len(),
            };
            let mut entries = match panel {
                Panel::Force => force_panel(&plot, &p)?,
                Panel::Shift => shift_panel(&plot, &p)?,
                Panel::Valves => valve_panel(&plot, &p)?,
                Panel::Pressure => pressure_panel(&plot, &p)?,
                Panel::Angles => angle_panel(&plot, &p)?,
            };
            // The time marks are explained once, in the first panel.
            if k == 0 {
                entries.extend(marks.entries());
            }
            legend(&side, &entries, Some(BLACK))?;
        }
        Ok(())
    }
}

/// What every panel is drawn from.
struct PanelContext<'a> {
    r: &'a SimReport,
    marks: &'a TimeMarks,
    /// End of the time axis, s.
    t_max: f64,
    /// The bottom panel carries the time axis' labels.
    bottom: bool,
}

/// The time marks every panel shows: response bands and the drop.
struct TimeMarks {
    /// (poke onset, valves open or `None`), s.
    responses: Vec<(f64, Option<f64>)>,
    /// When the object fell, s.
    drop_s: Option<f64>,
}

impl TimeMarks {
    fn of(r: &SimReport) -> Self {
        TimeMarks {
            responses: r
                .pokes_reached()
                .map(|d| (d.t_onset_s, d.t_valves_open_s))
                .collect(),
            drop_s: r.dropped_at_ms.map(secs),
        }
    }

    /// Legend entries for the marks (the force panel carries them).
    fn entries(&self) -> Vec<LegendEntry> {
        let mut e = Vec::new();
        if !self.responses.is_empty() {
            e.push(LegendEntry::new(
                "response: poke onset to valves open",
                BAND,
                Mark::Box,
            ));
        }
        if self.drop_s.is_some() {
            e.push(LegendEntry::new("object dropped", DROP, Mark::Line));
        }
        e
    }
}

type TimeChart<'a, DB, Y> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, Y>>;

/// A panel's chart: time 0..`t_max` s, the y range `y`, the same label
/// areas in every panel (so the time axes line up), time labels only on
/// the bottom panel; the response bands and the drop line drawn first.
fn time_chart<'a, DB, Y>(
    area: &'a DrawingArea<DB, Shift>,
    p: &PanelContext<'_>,
    y: Y,
) -> Result<TimeChart<'a, DB, Y::CoordDescType>, FigureError>
where
    DB: DrawingBackend,
    Y: AsRangedCoord<Value = f64>,
    Y::CoordDescType: Ranged<ValueType = f64>,
{
    let (t_max, marks) = (p.t_max, p.marks);
    let mut chart = ChartBuilder::on(area)
        .margin_top(10)
        .margin_right(16)
        .margin_left(6)
        .y_label_area_size(Y_LABELS_PX)
        .x_label_area_size(if p.bottom { TIME_AXIS_PX } else { 0 })
        .build_cartesian_2d(0.0..t_max, y)?;
    let y = chart.y_range();
    let (lo, hi) = (y.start, y.end);
    for &(onset, open) in &marks.responses {
        let end = open.unwrap_or(onset + t_max / 500.0);
        chart.draw_series(std::iter::once(Rectangle::new(
            [(onset, lo), (end, hi)],
            BAND.filled(),
        )))?;
    }
    if let Some(t) = marks.drop_s {
        chart.draw_series(LineSeries::new([(t, lo), (t, hi)], DROP.stroke_width(2)))?;
    }
    Ok(chart)
}

/// A time axis label, s: to the ms, without trailing zeros (`12`, `0.05`):
/// a run shorter than a second still gets distinct labels.
fn seconds_label(t: &f64) -> String {
    let ms = (t * 1e3).round() / 1e3;
    format!("{}", ms + 0.0)
}

/// Draws the mesh with numbered axes: time in s (bottom panel), `y_desc`.
fn mesh<DB, Y>(
    chart: &mut TimeChart<'_, DB, Y>,
    y_desc: &str,
    y_format: &dyn Fn(&f64) -> String,
) -> Result<(), FigureError>
where
    DB: DrawingBackend,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    house_mesh(&mut chart.configure_mesh())
        .x_desc("time (s)")
        .y_desc(y_desc)
        .x_labels(16)
        .y_labels(6)
        .y_label_formatter(y_format)
        .x_label_formatter(&seconds_label)
        .max_light_lines(2)
        .draw()?;
    Ok(())
}

fn plain(v: &f64) -> String {
    // Ticks are round numbers: at most one decimal is needed.
    if (v - v.round()).abs() < 1e-9 {
        format!("{v:.0}")
    } else {
        format!("{v:.1}")
    }
}

/// `lo..hi` around the finite values, with `pad` of the span on each side
/// and at least `min_span`.
fn range_of(values: impl Iterator<Item = f64>, pad: f64, min_span: f64) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
            (lo.min(v), hi.max(v))
        });
    if !lo.is_finite() {
        return (0.0, min_span);
    }
    let (lo, hi) = if hi - lo < min_span {
        let mid = 0.5 * (lo + hi);
        (mid - 0.5 * min_span, mid + 0.5 * min_span)
    } else {
        (lo, hi)
    };
    let span = hi - lo;
    (lo - pad * span, hi + pad * span)
}

/// Splits a series at its missing or non-finite values into drawable runs.
fn runs(points: impl Iterator<Item = (f64, Option<f64>)>) -> Vec<Vec<(f64, f64)>> {
    let mut out: Vec<Vec<(f64, f64)>> = vec![Vec::new()];
    for (t, v) in points {
        match v {
            Some(v) if v.is_finite() && t.is_finite() => {
                if let Some(run) = out.last_mut() {
                    run.push((t, v));
                }
            }
            _ => {
                if out.last().is_some_and(|run| !run.is_empty()) {
                    out.push(Vec::new());
                }
            }
        }
    }
    out.retain(|run| !run.is_empty());
    out
}

fn draw_runs<DB, Y>(
    chart: &mut TimeChart<'_, DB, Y>,
    runs: Vec<Vec<(f64, f64)>>,
    style: ShapeStyle,
    dashed: bool,
) -> Result<(), FigureError>
where
    DB: DrawingBackend,
    Y: Ranged<ValueType = f64>,
{
    for run in runs {
        if dashed {
            chart.draw_series(DashedLineSeries::new(run, 8, 5, style))?;
        } else {
            chart.draw_series(LineSeries::new(run, style))?;
        }
    }
    Ok(())
}

fn force_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &PanelContext<'_>,
) -> Result<Vec<LegendEntry>, FigureError> {
    let r = p.r;
    let (_, hi) = range_of(r.trace.iter().map(|s| s.external_n), 0.0, 1.0);
    let mut chart = time_chart(area, p, 0.0..hi.max(1.0) * 1.1)?;
    mesh(&mut chart, "poke force (N)", &plain)?;
    let force = runs(r.trace.iter().map(|s| (secs(s.t_ms), Some(s.external_n))));
    draw_runs(&mut chart, force, POKE.stroke_width(2), false)?;
    // Each poke's target above its peak, as the paper's panels (b)-(d).
    let label = font(14).pos(Pos::new(HPos::Center, VPos::Bottom));
    chart.draw_series(r.pokes_reached().map(|d| {
        let target = match d.poke.target {
            PokeTarget::Object => "on the object",
            PokeTarget::Actuator => "on a soft actuator",
            PokeTarget::FingertipBack => "on a fingertip's back",
        };
        let at = (d.poke.at_s + 0.5 * d.poke.duration_s, d.poke.peak_n);
        EmptyElement::at(at) + Text::new(target, (0, -4), label.clone())
    }))?;
    Ok(vec![LegendEntry::new("poke force", POKE, Mark::Line)])
}

/// A time series: (time s, value or `None` where there is none).
pub type Series = Vec<(f64, Option<f64>)>;

/// Contact-centre shifts of one sensor: (D(t) frame to frame, A(t) from
/// the anchor), mm, as the grasp computes them
/// ([`dexitac_sim::output::frame_shifts`], the columns of `timeseries.csv`).
pub fn shifts(r: &SimReport, sensor: usize) -> (Series, Series) {
    let frames = dexitac_sim::output::frame_shifts(r);
    let Some(frames) = frames.get(sensor) else {
        return (Vec::new(), Vec::new());
    };
    frames
        .iter()
        .map(|f| {
            let t = secs(f.t_ms);
            ((t, f.frame_shift_mm), (t, f.anchored_shift_mm))
        })
        .unzip()
}

fn shift_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &PanelContext<'_>,
) -> Result<Vec<LegendEntry>, FigureError> {
    let (r, t_max) = (p.r, p.t_max);
    let series: Vec<_> = (0..FINGER_COUNT).map(|s| shifts(r, s)).collect();
    let largest = series
        .iter()
        .flat_map(|(d, a)| d.iter().chain(a))
        .filter_map(|(_, v)| *v)
        .filter(|v| v.is_finite())
        .fold(0.0, f64::max);
    let hi = (largest * 1.05).max(SLIP_SHIFT_MM * 1.25);
    let mut chart = time_chart(area, p, 0.0..hi)?;
    mesh(&mut chart, "centre shift (mm)", &plain)?;
    let mut entries = Vec::new();
    for (sensor, (frame, anchored)) in series.into_iter().enumerate() {
        let c = FINGER_COLOURS[sensor % FINGER_COLOURS.len()];
        draw_runs(
            &mut chart,
            runs(frame.into_iter()),
            c.stroke_width(1),
            false,
        )?;
        draw_runs(
            &mut chart,
            runs(anchored.into_iter()),
            c.stroke_width(3),
            false,
        )?;
        entries.push(LegendEntry::new(
            format!("sensor {sensor}: D(t), frame to frame"),
            c,
            Mark::Thin,
        ));
        entries.push(LegendEntry::new(
            format!("sensor {sensor}: A(t), from the anchor"),
            c,
            Mark::Line,
        ));
    }
    for (name, v) in [("T1", STABLE_SHIFT_MM), ("T2", SLIP_SHIFT_MM)] {
        chart.draw_series(DashedLineSeries::new(
            [(0.0, v), (t_max, v)],
            10,
            6,
            GUIDE.stroke_width(2),
        ))?;
        // At the left end: before the first contact there is no data.
        let style = font(15)
            .color(&GUIDE)
            .pos(Pos::new(HPos::Left, VPos::Bottom));
        chart.draw_series(std::iter::once(Text::new(
            format!("{name} = {v} mm"),
            (t_max * 0.005, v),
            style,
        )))?;
    }
    entries.push(LegendEntry::new(
        "T1 (disturbance), T2 (slip)",
        GUIDE,
        Mark::Dashed,
    ));
    Ok(entries)
}

/// The chambers with a valve lane: the grasping chambers and every chamber
/// whose valves changed during the run, in chamber order.
pub fn lanes(r: &SimReport) -> Vec<usize> {
    let mut lanes: Vec<usize> = r.grasp_chambers.clone();
    if let Some(first) = r.trace.first() {
        for c in 0..first.valves.len() {
            if r.trace
                .iter()
                .any(|s| s.valves.get(c) != first.valves.get(c))
            {
                lanes.push(c);
            }
        }
    }
    lanes.sort_unstable();
    lanes.dedup();
    lanes
}

/// A chamber's name: finger and joint.
pub fn chamber_name(chamber: usize) -> String {
    let finger = chamber / CHAMBERS_PER_FINGER;
    let joint = match (
        chamber % CHAMBERS_PER_FINGER,
        MANIPULATION_CHAMBERS.get(finger),
    ) {
        (0, _) => "rot",
        (_, Some(&[forward, _])) if forward == chamber => "dex side +",
        (_, Some(&[_, backward])) if backward == chamber => "dex side -",
        (1, _) => "dex palm",
        _ => "dex",
    };
    format!("f{finger} {joint} ({chamber})")
}

/// A chamber's valve states as runs: (from s, to s, state).
pub fn valve_runs(r: &SimReport, chamber: usize) -> Vec<(f64, f64, ValveState)> {
    let mut out: Vec<(f64, f64, ValveState)> = Vec::new();
    for s in &r.trace {
        let Some(&state) = s.valves.get(chamber) else {
            continue;
        };
        let t = secs(s.t_ms);
        match out.last_mut() {
            Some(last) if last.2 == state => last.1 = t,
            Some(last) => {
                last.1 = t;
                out.push((t, t, state));
            }
            None => out.push((t, t, state)),
        }
    }
    out
}

fn valve_colour(state: ValveState) -> RGBColor {
    match state {
        ValveState::Inflate => INFLATE,
        ValveState::Hold => HOLD,
        ValveState::Deflate => DEFLATE,
    }
}

fn valve_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &PanelContext<'_>,
) -> Result<Vec<LegendEntry>, FigureError> {
    let r = p.r;
    let lanes = lanes(r);
    let n = lanes.len().max(1);
    // Lane k (top to bottom) is centred on y = n - 1 - k; with at most n
    // labels, plotters puts them on the integers, one per lane.
    let mut chart = time_chart(area, p, -0.5..n as f64 - 0.5)?;
    let names: Vec<String> = lanes.iter().map(|&c| chamber_name(c)).collect();
    let lane_name = |y: &f64| {
        let k = n as f64 - 1.0 - y;
        let on_lane = k > -0.5 && (k - k.round()).abs() < 1e-6;
        let name = on_lane.then(|| names.get(k.round() as usize)).flatten();
        name.cloned().unwrap_or_default()
    };
    house_mesh(&mut chart.configure_mesh())
        .disable_y_mesh()
        .max_light_lines(2)
        .x_desc("time (s)")
        .y_desc("valves")
        .x_labels(16)
        .y_labels(n)
        .x_label_formatter(&seconds_label)
        .y_label_formatter(&lane_name)
        .draw()?;
    for (k, &chamber) in lanes.iter().enumerate() {
        let centre = (n - 1 - k) as f64;
        chart.draw_series(valve_runs(r, chamber).into_iter().map(|(t0, t1, s)| {
            Rectangle::new(
                [(t0, centre - 0.36), (t1, centre + 0.36)],
                valve_colour(s).filled(),
            )
        }))?;
    }
    Ok([
        ("inflate (inlet open)", ValveState::Inflate),
        ("hold (sealed)", ValveState::Hold),
        ("deflate (outlet open)", ValveState::Deflate),
    ]
    .into_iter()
    .map(|(label, s)| LegendEntry::new(label, valve_colour(s), Mark::Box))
    .collect())
}

fn pressure_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &PanelContext<'_>,
) -> Result<Vec<LegendEntry>, FigureError> {
    let r = p.r;
    let values = r.trace.iter().flat_map(|s| {
        let chambers = r
            .grasp_chambers
            .iter()
            .filter_map(|&c| s.chambers_kpa.get(c).copied());
        [s.tanks_kpa.0, s.tanks_kpa.1].into_iter().chain(chambers)
    });
    let (lo, hi) = range_of(values, 0.05, 10.0);
    let mut chart = time_chart(area, p, lo..hi)?;
    mesh(&mut chart, "pressure (kPa)", &plain)?;
    let t = |s: &dexitac_sim::plant::WorldState| secs(s.t_ms);
    let positive = runs(r.trace.iter().map(|s| (t(s), Some(s.tanks_kpa.0))));
    let negative = runs(r.trace.iter().map(|s| (t(s), Some(s.tanks_kpa.1))));
    draw_runs(&mut chart, positive, POSITIVE_TANK.stroke_width(2), false)?;
    draw_runs(&mut chart, negative, NEGATIVE_TANK.stroke_width(2), false)?;
    let mut entries = vec![
        LegendEntry::new("+ tank", POSITIVE_TANK, Mark::Line),
        LegendEntry::new("- tank", NEGATIVE_TANK, Mark::Line),
    ];
    for &c in &r.grasp_chambers {
        let colour = FINGER_COLOURS[(c / CHAMBERS_PER_FINGER) % FINGER_COLOURS.len()];
        let dashed = c % CHAMBERS_PER_FINGER != 0;
        let p = runs(
            r.trace
                .iter()
                .map(|s| (t(s), s.chambers_kpa.get(c).copied())),
        );
        draw_runs(&mut chart, p, colour.stroke_width(2), dashed)?;
        let mark = if dashed { Mark::Dashed } else { Mark::Line };
        entries.push(LegendEntry::new(
            format!("chamber {}", chamber_name(c)),
            colour,
            mark,
        ));
    }
    Ok(entries)
}

/// Line width of a finger's series: finger 0 wider, so that where both
/// fingers have the same value (a symmetric grasp) both colours show.
fn finger_width(finger: usize) -> u32 {
    if finger == 0 {
        5
    } else {
        2
    }
}

fn angle_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    p: &PanelContext<'_>,
) -> Result<Vec<LegendEntry>, FigureError> {
    let r = p.r;
    let values = r
        .trace
        .iter()
        .flat_map(|s| s.manip_deg.iter().copied().chain([s.object_deg]));
    let (lo, hi) = range_of(values, 0.08, 10.0);
    let mut chart = time_chart(area, p, lo..hi)?;
    mesh(&mut chart, "angle (deg)", &plain)?;
    let t = |s: &dexitac_sim::plant::WorldState| secs(s.t_ms);
    let mut entries = Vec::new();
    for f in 0..FINGER_COUNT {
        let colour = FINGER_COLOURS[f % FINGER_COLOURS.len()];
        let a = runs(r.trace.iter().map(|s| (t(s), s.manip_deg.get(f).copied())));
        draw_runs(&mut chart, a, colour.stroke_width(finger_width(f)), false)?;
        entries.push(LegendEntry::new(
            format!("finger {f}: manipulation joint"),
            colour,
            Mark::Line,
        ));
    }
    let tilt = runs(r.trace.iter().map(|s| (t(s), Some(s.object_deg))));
    draw_runs(&mut chart, tilt, OBJECT.stroke_width(2), true)?;
    entries.push(LegendEntry::new("object tilt", OBJECT, Mark::Dashed));
    Ok(entries)
}

/// A density heatmap of both sensors at a snapshot (module docs).
#[derive(Debug, Clone, Copy)]
pub struct HeatmapFigure<'a> {
    /// The run.
    pub report: &'a SimReport,
    /// The snapshot (time, event, markers of both sensors).
    pub snapshot: &'a Snapshot,
}

/// Density ratio at the top of the colour bar (everything denser is blue).
const RATIO_MAX: f64 = 1.3;
/// Size of one sensor's panel, px.
const SENSOR_PANEL_PX: (u32, u32) = (520, 440);
/// Width of the colour bar, px.
const BAR_PX: u32 = 150;

impl Figure for HeatmapFigure<'_> {
    fn size_px(&self) -> (u32, u32) {
        let n = self.report.calibrations.len().max(1) as u32;
        (n * SENSOR_PANEL_PX.0 + BAR_PX, SENSOR_PANEL_PX.1 + TITLE_PX)
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), FigureError> {
        let (w, _) = self.size_px();
        let title = format!(
            "{}: marker density relative to rest at t = {:.2} s ({})",
            self.report.scenario,
            secs(self.snapshot.t_ms),
            self.snapshot.label
        );
        let body = root.titled(&title, font(22))?;
        let (sensors, bar) = body.split_horizontally(w - BAR_PX);
        let n = self.report.calibrations.len().max(1);
        for (sensor, area) in sensors.split_evenly((1, n)).iter().enumerate() {
            self.sensor_panel(area, sensor)?;
        }
        colour_bar(&bar, (0.0, RATIO_MAX), "density / rest", &|v| {
            let c = ratio_colour(v);
            RGBColor(c.0[0], c.0[1], c.0[2])
        })
    }
}

impl HeatmapFigure<'_> {
    fn sensor_panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        sensor: usize,
    ) -> Result<(), FigureError> {
        let r = self.report;
        let Some(cal) = r.calibrations.get(sensor) else {
            return Ok(());
        };
        let mm = cal.density.mm_per_px;
        let half_w = 0.5 * (cal.width as f64 - 1.0);
        let half_h = 0.5 * (cal.height as f64 - 1.0);
        // Plotted y is -y_mm so that the image's y runs down, as on the
        // sensor image; the labels show y_mm.
        let (x_lim, y_lim) = (half_w * mm, half_h * mm);
        let mut chart = ChartBuilder::on(area)
            .caption(format!("sensor {sensor} (finger {sensor})"), font(18))
            .margin(8)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(-x_lim..x_lim, -y_lim..y_lim)?;
        house_mesh(&mut chart.configure_mesh())
            .disable_mesh()
            .x_desc("x (mm)")
            .y_desc("y (mm, down)")
            // + 0.0: no "-0" at the origin.
            .y_label_formatter(&|v| format!("{:.0}", -v + 0.0))
            .x_label_formatter(&|v| format!("{v:.0}"))
            .draw()?;
        let Some(markers) = self.snapshot.markers.get(sensor) else {
            return Ok(());
        };
        let map = density::estimate(markers, &cal.density, None);
        let g = map.grid;
        let step = g.step_px.max(1) as f64;
        let cells = (0..g.ny).flat_map(|j| (0..g.nx).map(move |i| (i, j)));
        chart.draw_series(cells.map(|(i, j)| {
            let k = j * g.nx + i;
            let inside = cal.mask.get(k).copied().unwrap_or(false);
            let rest = cal
                .rest_density
                .values_per_mm2
                .get(k)
                .copied()
                .unwrap_or(0.0);
            let v = map.values_per_mm2.get(k).copied().unwrap_or(0.0);
            let c = if inside && rest > 0.0 {
                let c = ratio_colour(f64::from(v / rest));
                RGBColor(c.0[0], c.0[1], c.0[2])
            } else {
                RGBColor(40, 40, 40)
            };
            let x0 = (i as f64 * step - half_w) * mm;
            let y0 = (j as f64 * step - half_h) * mm;
            let x1 = ((i + 1) as f64 * step - half_w) * mm;
            let y1 = ((j + 1) as f64 * step - half_h) * mm;
            Rectangle::new([(x0, -y0), (x1.min(x_lim), -y1.max(-y_lim))], c.filled())
        }))?;
        // The measured centre closest before the snapshot.
        let centre = r
            .observations
            .iter()
            .rfind(|o| o.sensor == sensor && o.t_ms <= self.snapshot.t_ms)
            .and_then(|o| o.centre_mm)
            .filter(|c| c.x_mm.is_finite() && c.y_mm.is_finite());
        if let Some(c) = centre {
            let label = format!("centre ({:.1}, {:.1}) mm", c.x_mm, c.y_mm);
            chart.draw_series(std::iter::once(
                EmptyElement::at((c.x_mm, -c.y_mm))
                    + Cross::new((0, 0), 9, BLACK.stroke_width(3))
                    + Text::new(label, (-40, 16), font(14)),
            ))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::figures::test_support::check_figure;
    use dexitac_gripper::grasp::{Cause, CentreMm, Command, Decision};
    use dexitac_protocol::{ArmState, FaultFlags, CHAMBER_COUNT};
    use dexitac_protocol::{Fault, FaultEvent};
    use dexitac_rig::event::StopReason;
    use dexitac_sim::mcu::McuSnapshot;
    use dexitac_sim::plant::{Plant, PlantParams, Trajectory, WorldState};
    use dexitac_sim::plant::{Poke, PokeShape};
    use dexitac_sim::rig::{DisturbanceTiming, ObservationRecord, Outcome};
    use dexitac_sim::status::LoopError;
    use std::sync::Arc;
    use std::time::Duration;

    fn world(t_ms: u64) -> WorldState {
        let plant = Plant::new(
            PlantParams::default(),
            None,
            &[0, 1, 4, 5],
            Trajectory::default(),
            Vec::new(),
        );
        WorldState {
            t_ms,
            ..plant.state().clone()
        }
    }

    fn report(trace: Vec<WorldState>, observations: Vec<ObservationRecord>) -> SimReport {
        SimReport {
            pace: dexitac_sim::rig::Pace::Times(1.0),
            scenario: "probe".into(),
            tactile_feedback: true,
            outcome: Outcome::Held,
            time_to_stable_s: None,
            disturbances: Vec::new(),
            decisions: Vec::new(),
            commands: Vec::new(),
            frame_to_command: Vec::new(),
            observations,
            observations_before_decision: Vec::new(),
            trace,
            transitions: Vec::new(),
            dropped_at_ms: None,
            snapshots: Vec::new(),
            calibrations: Vec::new(),
            loop_result: Ok(StopReason::Requested),
            mcu_at_end: McuSnapshot {
                time_ms: 0,
                chambers: [ValveState::Hold; CHAMBER_COUNT],
                pumps: Default::default(),
                tanks_pa: (0, 0),
                chambers_pa: [0; CHAMBER_COUNT],
                state: ArmState::default(),
                faults: FaultFlags::default(),
                frames_ok: 0,
                frame_errors: 0,
            },
            link_stats: Default::default(),
            max_loop_gap: Duration::ZERO,
            grasp_chambers: vec![0, 1, 4, 5],
            task: None,
            sim_s: 0.0,
            wall_s: 0.0,
        }
    }

    fn observation(sensor: usize, t_ms: u64, x_mm: f64) -> ObservationRecord {
        ObservationRecord {
            sensor,
            t_ms,
            centre_mm: Some(CentreMm { x_mm, y_mm: 0.0 }),
            pipeline_ms: 1.0,
        }
    }

    const TEXTS: [&str; 8] = [
        "Simulated run: probe",
        "time (s)",
        "centre shift (mm)",
        "pressure (kPa)",
        "T1 = 0.5 mm",
        "T2 = 5 mm",
        "+ tank",
        "- tank",
    ];

    #[test]
    fn the_run_figure_of_an_empty_report_has_its_axes_and_legends() {
        let r = report(Vec::new(), Vec::new());
        check_figure(&RunFigure { report: &r }, &TEXTS);
    }

    #[test]
    fn the_run_figure_survives_one_sample_and_nan() {
        let mut state = world(0);
        state.tanks_kpa = (f64::NAN, f64::INFINITY);
        state.chambers_kpa[0] = f64::NAN;
        state.external_n = f64::NAN;
        let obs = vec![observation(0, 0, f64::NAN)];
        let r = report(vec![state], obs);
        check_figure(&RunFigure { report: &r }, &TEXTS);
    }

    #[test]
    fn the_run_figure_shows_pokes_lanes_and_both_tanks() {
        let mut trace: Vec<WorldState> = (0..=100).map(|k| world(k * 100)).collect();
        for s in &mut trace {
            let t = secs(s.t_ms);
            s.tanks_kpa = (40.0 * (t / 10.0), -45.0 * (t / 10.0));
            s.external_n = if (4.0..5.0).contains(&t) { 3.0 } else { 0.0 };
            if t > 2.0 {
                s.valves[0] = ValveState::Inflate;
            }
        }
        let obs = (0..100)
            .flat_map(|k| {
                [
                    observation(0, k * 100, 0.01 * k as f64),
                    observation(1, k * 100, 0.0),
                ]
            })
            .collect();
        let mut r = report(trace, obs);
        r.decisions.push((
            3_000,
            Decision {
                t_ms: 3_000,
                command: Command::Seal,
                cause: Cause::BothStable,
            },
        ));
        // The seal came after the frames up to 3 s (both sensors).
        r.observations_before_decision.push(62);
        r.dropped_at_ms = Some(9_000);
        let figure = RunFigure { report: &r };
        let img = check_figure(
            &figure,
            &[
                "poke force (N)",
                "f0 rot (0)",
                "inflate (inlet open)",
                "object dropped",
            ],
        );
        // The two tanks are drawn in their own colours.
        for c in [POSITIVE_TANK, NEGATIVE_TANK, INFLATE] {
            let n = img.pixels().filter(|p| p.0 == [c.0, c.1, c.2]).count();
            assert!(n > 100, "{c:?}: {n} px");
        }
        // Sensor 0 moves 0.01 mm per frame: A(t) from the seal at 3 s.
        let (d, a) = shifts(&r, 0);
        assert!(d
            .iter()
            .skip(1)
            .all(|(_, v)| v.is_some_and(|v| (v - 0.01).abs() < 1e-9)));
        assert!(a
            .iter()
            .take_while(|(t, _)| *t < 3.0)
            .all(|(_, v)| v.is_none()));
        assert!(a
            .last()
            .and_then(|(_, v)| *v)
            .is_some_and(|v| (v - 0.69).abs() < 1e-9));
    }

    #[test]
    fn a_failed_run_says_so_in_red_in_the_title_and_draws_no_poke_after_its_end() {
        let trace: Vec<WorldState> = (0..=113).map(|k| world(k * 100)).collect();
        let mut r = report(trace, Vec::new());
        let ok_title = RunFigure { report: &r }.title();
        assert!(ok_title.ends_with("outcome held"), "{ok_title}");
        assert!(!ok_title.contains("FAILED"), "{ok_title}");
        r.sim_s = 11.3;
        r.loop_result = Err(LoopError::McuFault(FaultEvent {
            time_ms: 11_300,
            fault: Fault::HostSilence,
            positive_tank_pa: 0,
            negative_tank_pa: 0,
        }));
        let poke = |target, at_s| DisturbanceTiming {
            poke: Poke {
                target,
                finger: 0,
                at_s,
                duration_s: 1.0,
                peak_n: 3.0,
                shape: PokeShape::HalfSine,
            },
            t_onset_s: at_s,
            t_detected_s: None,
            t_reopen_sent_s: None,
            t_valves_open_s: None,
        };
        r.disturbances = vec![
            poke(PokeTarget::Object, 5.0),
            poke(PokeTarget::Actuator, 12.0),
            poke(PokeTarget::FingertipBack, 18.0),
        ];
        let figure = RunFigure { report: &r };
        let img = check_figure(
            &figure,
            &[
                "FAILED: tripped: HostSilence at 11.3 s; object held at the end",
                "on the object",
            ],
        );
        let svg_dir = tempfile::tempdir().unwrap();
        write_png_and_svg(&figure, svg_dir.path(), "fig").unwrap();
        let svg = std::fs::read_to_string(svg_dir.path().join("fig.svg")).unwrap();
        for late in ["on a soft actuator", "on a fingertip's back"] {
            assert!(!svg.contains(late), "a poke after the end is drawn: {late}");
        }
        assert!(!svg.contains("outcome held"));
        // The title is red.
        let red = (0..img.width())
            .flat_map(|x| (0..TITLE_PX).map(move |y| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0 == [FAILED.0, FAILED.1, FAILED.2])
            .count();
        assert!(red > 50, "{red} red px in the title");
    }

    #[test]
    fn a_heatmap_without_calibrations_or_markers_still_draws() {
        let r = report(Vec::new(), Vec::new());
        let snapshot = Snapshot {
            t_ms: 1_500,
            label: "seal".into(),
            markers: [Arc::new(Vec::new()), Arc::new(Vec::new())],
        };
        let figure = HeatmapFigure {
            report: &r,
            snapshot: &snapshot,
        };
        check_figure(&figure, &["t = 1.50 s (seal)", "density / rest"]);
    }

    #[test]
    fn valve_runs_cover_the_trace_and_lanes_include_changed_chambers() {
        let mut trace: Vec<WorldState> = (0..10).map(|k| world(k * 1000)).collect();
        for s in trace.iter_mut().skip(5) {
            s.valves[2] = ValveState::Deflate;
        }
        let r = report(trace, Vec::new());
        assert_eq!(lanes(&r), vec![0, 1, 2, 4, 5]);
        assert_eq!(
            valve_runs(&r, 2),
            vec![
                (0.0, 5.0, ValveState::Hold),
                (5.0, 9.0, ValveState::Deflate)
            ]
        );
        assert_eq!(chamber_name(2), "f0 dex side + (2)");
        assert_eq!(chamber_name(7), "f1 dex side - (7)");
    }
}
