//! [`Dashboard::render`]: the dashboard as an RGB image, a pure function of
//! the dashboard's state (the window and the PNG snapshots show its pixels).
//!
//! - Frame panels: the working frame (grey), detected markers (green), the
//!   contact centre's trail (orange, the last `trail_s`) and the contact
//!   (red cross at the centre, red circle of the contact's area).
//! - Density panels: the fast kernel density of the latest markers
//!   ([`dexitac_tactile::density::estimate`]) relative to the rest reference, in the
//!   simulator heatmaps' colours (dark red: markers pushed away, white:
//!   rest, blue: denser); grey outside the sensing area; the same trail and
//!   contact on top.
//! - Charts over the last `history_s`, time in s on the x axis: tank
//!   pressures (kPa; dashed: the targets commanded), a lane per chamber
//!   (green inflate, blue deflate, light grey hold) and per pump (purple:
//!   running) under a lane of the grasp phase, and each sensor's contact
//!   centre shift from its anchor (mm; dashed: T1 and T2 of Algorithm 1).
//!
//! The text uses the 3x5 pixel font of [`crate::raster`], upper case.

use dexitac_protocol::{ArmState, ValveState};
use image::{Rgb, RgbImage};

use crate::dashboard::{secs_to_ms, Dashboard, GraspPhase, SensorView};
use crate::layout::{Layout, Rect, LANES};
use crate::raster::{line, put, ratio_colour, text};
use dexitac_tactile::density;

/// Dashboard background.
pub const BACKGROUND: Rgb<u8> = Rgb([246, 246, 246]);
/// Chart background.
pub const CHART_BACKGROUND: Rgb<u8> = Rgb([255, 255, 255]);
/// Panel background where there is no frame.
pub const NO_FRAME: Rgb<u8> = Rgb([28, 28, 34]);
/// Detected markers.
pub const MARKER_COLOUR: Rgb<u8> = Rgb([40, 220, 60]);
/// The contact centre and outline.
pub const CONTACT_COLOUR: Rgb<u8> = Rgb([235, 20, 20]);
/// The contact centre's trail.
pub const TRAIL_COLOUR: Rgb<u8> = Rgb([255, 165, 0]);
/// Valve lane: inflate (inlet open).
pub const INFLATE_COLOUR: Rgb<u8> = Rgb([60, 170, 70]);
/// Valve lane: deflate (outlet open).
pub const DEFLATE_COLOUR: Rgb<u8> = Rgb([60, 110, 220]);
/// Valve lane: hold (sealed).
pub const HOLD_COLOUR: Rgb<u8> = Rgb([214, 214, 214]);
/// Pump lane: running.
pub const PUMP_ON_COLOUR: Rgb<u8> = Rgb([140, 60, 170]);
/// Pump lane: off.
pub const PUMP_OFF_COLOUR: Rgb<u8> = Rgb([236, 236, 236]);
/// Positive tank series.
pub const POSITIVE_TANK_COLOUR: Rgb<u8> = Rgb([200, 40, 40]);
/// Negative tank series.
pub const NEGATIVE_TANK_COLOUR: Rgb<u8> = Rgb([40, 80, 200]);
/// Each sensor's series on the shift chart.
pub const SENSOR_COLOURS: [Rgb<u8>; 2] = [Rgb([20, 20, 20]), Rgb([220, 120, 0])];
/// Outside the sensing area on the density panels.
const OUTSIDE: Rgb<u8> = Rgb([60, 60, 60]);
const TEXT: Rgb<u8> = Rgb([0, 0, 0]);
const MUTED: Rgb<u8> = Rgb([120, 120, 120]);
const GRID: Rgb<u8> = Rgb([228, 228, 228]);
const AXIS: Rgb<u8> = Rgb([150, 150, 150]);
const WARN: Rgb<u8> = Rgb([200, 0, 0]);

/// Pressure chart range, kPa (the tank limits are +50 / -57 kPa).
const PRESSURE_RANGE_KPA: (f64, f64) = (-60.0, 60.0);
/// Shift chart range, mm (T2 is 5 mm).
const SHIFT_RANGE_MM: f64 = 6.0;

/// Colour of a grasp phase in its lane.
pub fn phase_colour(p: GraspPhase) -> Rgb<u8> {
    match p {
        GraspPhase::Idle => Rgb([236, 236, 236]),
        GraspPhase::Charging => Rgb([180, 200, 225]),
        GraspPhase::Closing => Rgb([245, 215, 90]),
        GraspPhase::Holding => Rgb([120, 200, 120]),
        GraspPhase::Reinforcing => Rgb([250, 150, 60]),
        GraspPhase::Released => Rgb([230, 90, 90]),
        GraspPhase::Manipulating => Rgb([190, 150, 220]),
        GraspPhase::TaskDone => Rgb([90, 160, 110]),
        GraspPhase::GuardStop => Rgb([170, 50, 50]),
        GraspPhase::Stopped => Rgb([150, 150, 150]),
        GraspPhase::Failed => Rgb([120, 0, 0]),
    }
}

/// Colour of a valve state in its lane.
pub fn valve_colour(v: ValveState) -> Rgb<u8> {
    match v {
        ValveState::Inflate => INFLATE_COLOUR,
        ValveState::Deflate => DEFLATE_COLOUR,
        ValveState::Hold => HOLD_COLOUR,
    }
}

impl Dashboard {
    /// Draws the dashboard (see the [module docs](self)).
    pub fn render(&self) -> RgbImage {
        let layout = Layout;
        let (w, h) = layout.size();
        let mut img = RgbImage::from_pixel(w, h, BACKGROUND);
        self.draw_status(&mut img);
        for (sensor, s) in self.sensors.iter().enumerate() {
            self.draw_frame_panel(&mut img, &layout, sensor, s);
            self.draw_density_panel(&mut img, &layout, sensor, s);
            self.draw_footer(&mut img, &layout, sensor, s);
        }
        let now_ms = self.now_ms.unwrap_or(0);
        let history_ms = secs_to_ms(self.config.history_s).max(1);
        let chart = Chart {
            layout,
            now_ms,
            history_ms,
        };
        self.draw_pressures(&mut img, &chart);
        self.draw_lanes(&mut img, &chart);
        self.draw_shifts(&mut img, &chart);
        img
    }

    fn draw_status(&self, img: &mut RgbImage) {
        let t = self
            .now_ms
            .map_or("-".to_string(), |t| format!("{:.2} S", t as f64 / 1e3));
        let phase = self.phase();
        let mut status = format!("{}  T {t}  GRASP ", self.config.title);
        text(img, 6, 4, &status, 2, TEXT);
        let x = 6 + 8 * status.chars().count() as i64;
        let name = phase.name();
        fill(
            img,
            Rect {
                x: x - 3,
                y: 1,
                w: 8 * name.len() as i64 + 4,
                h: 16,
            },
            phase_colour(phase),
        );
        text(img, x, 4, name, 2, TEXT);
        status = String::new();
        if let Some((t, d)) = &self.last_decision {
            status.push_str(&format!("  LAST {d} AT {:.2} S", *t as f64 / 1e3));
        }
        if let Some((_, task)) = &self.task {
            status.push_str(&format!("  TASK {task}"));
        }
        if let Some(s) = &self.stopped {
            status.push_str(&format!("  END {s}"));
        }
        let x = x + 8 * name.len() as i64 + 4;
        text(img, x, 4, &status, 2, TEXT);
        if let Some(t) = self.telemetry.back() {
            let (label, colour) = match t.arm {
                ArmState::Armed => ("MCU ARMED", TEXT),
                ArmState::Disarmed => ("MCU DISARMED", MUTED),
                ArmState::Tripped => ("MCU TRIPPED", WARN),
            };
            text(img, 1280 - 8 * label.len() as i64 - 6, 4, label, 2, colour);
        }
        for sensor in 0..2 {
            let layout = Layout;
            let f = layout.frame_panel(sensor);
            let d = layout.density_panel(sensor);
            text(
                img,
                f.x + 4,
                22,
                &format!("FINGER {sensor}: FRAME"),
                2,
                TEXT,
            );
            text(
                img,
                d.x + 4,
                22,
                &format!("FINGER {sensor}: DENSITY / REST"),
                2,
                TEXT,
            );
        }
    }

    fn draw_frame_panel(&self, img: &mut RgbImage, layout: &Layout, sensor: usize, s: &SensorView) {
        let panel = layout.frame_panel(sensor);
        fill(img, panel, NO_FRAME);
        let size = self.size_of(s);
        match &s.frame {
            Some(frame) => {
                let (inner, scale) = layout.fit(panel, frame.width(), frame.height());
                blit_grey(img, inner, scale, frame);
            }
            None => {
                let msg = if s.frames == 0 {
                    "NO DATA"
                } else {
                    "NO FRAMES (MARKERS ONLY)"
                };
                text(img, panel.x + 8, panel.y + panel.h - 14, msg, 2, MUTED);
            }
        }
        // One pixel per marker: the blob around it stays visible.
        for m in s.markers.iter() {
            if let Some((x, y)) = layout.to_panel(panel, size, *m) {
                put_in(img, panel, x, y, MARKER_COLOUR);
            }
        }
        self.draw_contact(img, layout, panel, s);
    }

    /// The trail and the contact, clipped to `panel`.
    fn draw_contact(&self, img: &mut RgbImage, layout: &Layout, panel: Rect, s: &SensorView) {
        let size = self.size_of(s);
        let mut prev: Option<(i64, i64)> = None;
        for (_, p) in &s.trail {
            let q = p.and_then(|p| layout.to_panel(panel, size, p));
            if let (Some(a), Some(b)) = (prev, q) {
                line_in(img, panel, a, b, TRAIL_COLOUR);
            }
            prev = q;
        }
        let Some(c) = s.contact else { return };
        let Some((cx, cy)) = layout.to_panel(panel, size, c.centre) else {
            return;
        };
        let (_, scale) = layout.fit(panel, size.0, size.1);
        let mm_per_px = self.config.params.frame.mm_per_px;
        if c.area_mm2 > 0.0 && mm_per_px > 0.0 {
            let r = ((c.area_mm2 / std::f64::consts::PI).sqrt() / mm_per_px * scale).min(1e4);
            let steps = (r * 6.0).clamp(16.0, 720.0) as usize;
            for k in 0..steps {
                let a = k as f64 / steps as f64 * std::f64::consts::TAU;
                let x = cx + (r * a.cos()).round() as i64;
                let y = cy + (r * a.sin()).round() as i64;
                put_in(img, panel, x, y, CONTACT_COLOUR);
            }
        }
        for d in -7..=7 {
            for t in 0..2 {
                put_in(img, panel, cx + d, cy + t, CONTACT_COLOUR);
                put_in(img, panel, cx + t, cy + d, CONTACT_COLOUR);
            }
        }
    }

    /// The working frame size of a sensor: its frames, its calibration, or
    /// the configured working size.
    fn size_of(&self, s: &SensorView) -> (usize, usize) {
        s.size_px.unwrap_or((
            self.config.params.frame.work_width_px as usize,
            self.config.params.frame.work_height_px as usize,
        ))
    }

    fn draw_density_panel(
        &self,
        img: &mut RgbImage,
        layout: &Layout,
        sensor: usize,
        s: &SensorView,
    ) {
        let panel = layout.density_panel(sensor);
        fill(img, panel, NO_FRAME);
        let Some(rest) = &s.rest else {
            text(
                img,
                panel.x + 8,
                panel.y + panel.h - 14,
                "NO MARKERS YET",
                2,
                MUTED,
            );
            return;
        };
        let map = density::estimate(&s.markers, &rest.setup, None);
        let grid = map.grid;
        let (inner, scale) = layout.fit(panel, rest.setup.width, rest.setup.height);
        let step = grid.step_px.max(1) as f64;
        // Cell of each column and row of the panel, then one colour per cell.
        let col_cell: Vec<usize> = (0..inner.w)
            .map(|i| (((i as f64 + 0.5) / scale / step) as usize).min(grid.nx.saturating_sub(1)))
            .collect();
        let colours: Vec<Rgb<u8>> = (0..grid.nx * grid.ny)
            .map(|k| {
                let inside = rest.mask.get(k).copied().unwrap_or(false);
                let r = rest.density.values_per_mm2.get(k).copied().unwrap_or(0.0);
                let v = map.values_per_mm2.get(k).copied().unwrap_or(0.0);
                if inside && r > 0.0 {
                    ratio_colour(f64::from(v / r))
                } else {
                    OUTSIDE
                }
            })
            .collect();
        let width = img.width() as usize;
        let buf: &mut [u8] = img;
        for j in 0..inner.h {
            let row_cell =
                (((j as f64 + 0.5) / scale / step) as usize).min(grid.ny.saturating_sub(1));
            let y = inner.y + j;
            for (i, &col) in col_cell.iter().enumerate() {
                let x = inner.x + i as i64;
                if let Some(c) = colours.get(row_cell * grid.nx + col) {
                    let k = (y as usize * width + x as usize) * 3;
                    if let Some(px) = buf.get_mut(k..k + 3) {
                        px.copy_from_slice(&c.0);
                    }
                }
            }
        }
        self.draw_contact(img, layout, panel, s);
    }

    fn draw_footer(&self, img: &mut RgbImage, layout: &Layout, sensor: usize, s: &SensorView) {
        let y = layout.panel_footer_y();
        let f = layout.frame_panel(sensor);
        let d = layout.density_panel(sensor);
        let contact = match (s.centre_mm, s.contact) {
            (Some(c), Some(k)) => format!(
                "C ({:+.2},{:+.2}) MM  A {:.0} MM2",
                c.x_mm, c.y_mm, k.area_mm2
            ),
            _ if s.frames > 0 => "NO CONTACT".to_string(),
            _ => String::new(),
        };
        text(img, f.x + 4, y, &contact, 2, TEXT);
        let mut numbers = format!("{} MARKERS", s.markers.len());
        if let Some(ms) = s.pipeline_ms {
            numbers.push_str(&format!("  {ms:.1} MS"));
        }
        if let Some(fps) = s.fps {
            numbers.push_str(&format!("  {fps:.0} FPS"));
        }
        if s.frames > 0 {
            text(img, d.x + 4, y, &numbers, 2, TEXT);
        }
    }

    fn draw_pressures(&self, img: &mut RgbImage, chart: &Chart) {
        let r = chart.layout.pressure_chart();
        let (lo, hi) = PRESSURE_RANGE_KPA;
        fill(img, r, CHART_BACKGROUND);
        for v in [-50.0, -25.0, 0.0, 25.0, 50.0] {
            let y = value_y(r, v, lo, hi);
            hline(img, r, y, if v == 0.0 { AXIS } else { GRID }, false);
            text(img, r.x - 30, y - 2, &format!("{v:+.0}"), 1, MUTED);
        }
        chart.time_grid(img, r);
        if let Some((pos, neg)) = self.tank_targets_kpa {
            hline(img, r, value_y(r, pos, lo, hi), POSITIVE_TANK_COLOUR, true);
            hline(img, r, value_y(r, neg, lo, hi), NEGATIVE_TANK_COLOUR, true);
        }
        let series = |f: fn(&crate::dashboard::TelemetrySample) -> Option<f64>| {
            self.telemetry
                .iter()
                .map(move |s| (s.t_ms, f(s)))
                .collect::<Vec<_>>()
        };
        chart.series(
            img,
            r,
            &series(|s| s.positive_kpa),
            lo,
            hi,
            POSITIVE_TANK_COLOUR,
        );
        chart.series(
            img,
            r,
            &series(|s| s.negative_kpa),
            lo,
            hi,
            NEGATIVE_TANK_COLOUR,
        );
        frame_rect(img, r, AXIS);
        let mut title = "TANK PRESSURE (KPA)".to_string();
        text(img, r.x + 6, r.y + 4, &title, 2, TEXT);
        if let Some(t) = self.telemetry.back() {
            let fmt = |v: Option<f64>| v.map_or("NO READING".to_string(), |v| format!("{v:+.1}"));
            title = format!("+ TANK {}", fmt(t.positive_kpa));
            text(img, r.x + 200, r.y + 4, &title, 2, POSITIVE_TANK_COLOUR);
            title = format!("- TANK {}", fmt(t.negative_kpa));
            text(img, r.x + 360, r.y + 4, &title, 2, NEGATIVE_TANK_COLOUR);
        } else {
            text(img, r.x + 200, r.y + 4, "NO TELEMETRY", 2, MUTED);
        }
    }

    fn draw_lanes(&self, img: &mut RgbImage, chart: &Chart) {
        let layout = chart.layout;
        let all = layout.valve_chart();
        fill(img, all, CHART_BACKGROUND);
        text(
            img,
            all.x,
            all.y - 12,
            "GRASP PHASE, VALVES, PUMPS",
            2,
            TEXT,
        );
        let mut x = all.x + 250;
        for (label, c) in [
            ("INFLATE", INFLATE_COLOUR),
            ("DEFLATE", DEFLATE_COLOUR),
            ("HOLD", HOLD_COLOUR),
            ("PUMP ON", PUMP_ON_COLOUR),
        ] {
            fill(
                img,
                Rect {
                    x,
                    y: all.y - 12,
                    w: 10,
                    h: 10,
                },
                c,
            );
            text(img, x + 14, all.y - 12, label, 2, TEXT);
            x += 14 + 8 * label.len() as i64 + 20;
        }
        for lane in 0..LANES {
            let r = layout.lane(lane);
            let label = match lane {
                0 => "GRASP".to_string(),
                1..=8 => format!("C{}", lane - 1),
                9 => "P+".to_string(),
                _ => "P-".to_string(),
            };
            text(
                img,
                r.x - 8 * label.len() as i64 - 6,
                r.y + 1,
                &label,
                2,
                TEXT,
            );
        }
        // Phase lane, with each phase's name where it fits.
        let lane = layout.lane(0);
        let phases: Vec<_> = self.phases.iter().map(|&(t, p)| (t, p)).collect();
        for (t0, t1, p) in spans(&phases, chart.now_ms) {
            if let Some((x0, x1)) = chart.span_x(lane, t0, t1) {
                fill(
                    img,
                    Rect {
                        x: x0,
                        w: x1 - x0,
                        ..lane
                    },
                    phase_colour(p),
                );
                let name = p.name();
                if x1 - x0 > 4 * name.len() as i64 + 4 {
                    text(img, x0 + 2, lane.y + 4, name, 1, TEXT);
                }
            }
        }
        let samples: Vec<_> = self.telemetry.iter().map(|s| (s.t_ms, *s)).collect();
        for (t0, t1, s) in spans(&samples, chart.now_ms) {
            for chamber in 0..8 {
                let lane = layout.lane(1 + chamber);
                if let (Some((x0, x1)), Some(v)) =
                    (chart.span_x(lane, t0, t1), s.valves.get(chamber))
                {
                    fill(
                        img,
                        Rect {
                            x: x0,
                            w: x1 - x0,
                            ..lane
                        },
                        valve_colour(*v),
                    );
                }
            }
            for (pump, on) in s.pumps_on.iter().enumerate() {
                let lane = layout.lane(9 + pump);
                if let Some((x0, x1)) = chart.span_x(lane, t0, t1) {
                    let c = if *on { PUMP_ON_COLOUR } else { PUMP_OFF_COLOUR };
                    fill(
                        img,
                        Rect {
                            x: x0,
                            w: x1 - x0,
                            ..lane
                        },
                        c,
                    );
                }
            }
        }
        if self.telemetry.is_empty() {
            let lane = layout.lane(3);
            text(img, lane.x + 8, lane.y, "NO TELEMETRY", 2, MUTED);
        }
        chart.time_ticks(img, all);
        frame_rect(img, all, AXIS);
    }

    fn draw_shifts(&self, img: &mut RgbImage, chart: &Chart) {
        let r = chart.layout.shift_chart();
        fill(img, r, CHART_BACKGROUND);
        chart.time_grid(img, r);
        let g = &self.config.grasp;
        for (v, label) in [(g.stable_shift_mm, "T1"), (g.slip_shift_mm, "T2")] {
            if v.is_finite() && v > 0.0 && v < SHIFT_RANGE_MM {
                let y = value_y(r, v, 0.0, SHIFT_RANGE_MM);
                hline(img, r, y, AXIS, true);
                text(img, r.x + r.w - 18, y - 7, label, 1, MUTED);
            }
        }
        for v in [0.0, 2.0, 4.0, 6.0] {
            let y = value_y(r, v, 0.0, SHIFT_RANGE_MM);
            text(img, r.x - 18, y - 2, &format!("{v:.0}"), 1, MUTED);
        }
        for (s, colour) in self.sensors.iter().zip(SENSOR_COLOURS) {
            let points: Vec<_> = s.shift.iter().copied().collect();
            chart.series(img, r, &points, 0.0, SHIFT_RANGE_MM, colour);
        }
        frame_rect(img, r, AXIS);
        text(
            img,
            r.x,
            r.y - 12,
            "CONTACT CENTRE SHIFT FROM ITS ANCHOR (MM)",
            2,
            TEXT,
        );
        text(img, r.x + 360, r.y - 12, "FINGER 0", 2, SENSOR_COLOURS[0]);
        text(img, r.x + 440, r.y - 12, "FINGER 1", 2, SENSOR_COLOURS[1]);
        // Time labels under the last chart.
        for t in chart.ticks() {
            let x = chart.x(t);
            if x >= r.x && x <= r.x + r.w {
                let label = format!("{}", t / 1000);
                text(
                    img,
                    x - 4 * label.len() as i64,
                    r.y + r.h + 5,
                    &label,
                    2,
                    MUTED,
                );
            }
        }
        text(img, r.x - 62, r.y + r.h + 5, "T (S)", 2, MUTED);
    }
}

/// `(t0, t1, value)` spans: each entry lasts until the next one (the last
/// until `now_ms`).
fn spans<T: Copy>(entries: &[(u64, T)], now_ms: u64) -> Vec<(u64, u64, T)> {
    entries
        .iter()
        .enumerate()
        .map(|(i, &(t, v))| {
            let end = entries.get(i + 1).map_or(now_ms, |n| n.0);
            (t, end.max(t), v)
        })
        .collect()
}

/// A time tick every 1, 2, 5, 10, ... s: about 5 to 10 per chart.
fn tick_step_ms(history_ms: u64) -> u64 {
    [
        1_000, 2_000, 5_000, 10_000, 30_000, 60_000, 300_000, 600_000,
    ]
    .into_iter()
    .find(|&s| history_ms / s <= 10)
    .unwrap_or(3_600_000)
}

/// The time axis of the charts.
struct Chart {
    layout: Layout,
    now_ms: u64,
    history_ms: u64,
}

impl Chart {
    fn x(&self, t_ms: u64) -> i64 {
        self.layout.time_x(self.now_ms, self.history_ms, t_ms)
    }

    /// `[x0, x1)` of the time span `t0..t1` clipped to `r` (`None` when
    /// outside).
    fn span_x(&self, r: Rect, t0: u64, t1: u64) -> Option<(i64, i64)> {
        let x0 = self.x(t0).max(r.x);
        let x1 = (self.x(t1) + 1).min(r.x + r.w);
        (x1 > x0).then_some((x0, x1))
    }

    /// Tick times within the window, oldest first.
    fn ticks(&self) -> impl Iterator<Item = u64> {
        let step_ms = tick_step_ms(self.history_ms);
        let first = self.now_ms.saturating_sub(self.history_ms) / step_ms * step_ms;
        let now = self.now_ms;
        std::iter::successors(Some(first), move |t| t.checked_add(step_ms))
            .take_while(move |&t| t <= now)
    }

    fn time_grid(&self, img: &mut RgbImage, r: Rect) {
        for t in self.ticks() {
            let x = self.x(t);
            if x > r.x && x < r.x + r.w {
                for y in r.y..r.y + r.h {
                    put(img, x, y, GRID);
                }
            }
        }
    }

    fn time_ticks(&self, img: &mut RgbImage, r: Rect) {
        for t in self.ticks() {
            let x = self.x(t);
            if x > r.x && x < r.x + r.w {
                for y in r.y + r.h - 4..r.y + r.h {
                    put(img, x, y, AXIS);
                }
            }
        }
    }

    /// A polyline of `(t, value)`; `None` or non-finite values break it.
    fn series(
        &self,
        img: &mut RgbImage,
        r: Rect,
        points: &[(u64, Option<f64>)],
        lo: f64,
        hi: f64,
        colour: Rgb<u8>,
    ) {
        let mut prev: Option<(i64, i64)> = None;
        for &(t, v) in points {
            let q = v
                .filter(|v| v.is_finite())
                .map(|v| (self.x(t), value_y(r, v, lo, hi)));
            match (prev, q) {
                (Some(a), Some(b)) => line_in(img, r, a, b, colour),
                (None, Some(b)) => put_in(img, r, b.0, b.1, colour),
                _ => {}
            }
            prev = q;
        }
    }
}

/// The y of value `v` in chart `r` spanning `lo..hi` (clamped to the chart).
fn value_y(r: Rect, v: f64, lo: f64, hi: f64) -> i64 {
    let f = ((v - lo) / (hi - lo)).clamp(0.0, 1.0);
    r.y + r.h - 1 - (f * (r.h - 1) as f64).round() as i64
}

/// Fills `r` (clipped to the image).
pub(crate) fn fill(img: &mut RgbImage, r: Rect, c: Rgb<u8>) {
    let (w, h) = (i64::from(img.width()), i64::from(img.height()));
    let (x0, x1) = (r.x.clamp(0, w), (r.x + r.w).clamp(0, w));
    let (y0, y1) = (r.y.clamp(0, h), (r.y + r.h).clamp(0, h));
    if x0 >= x1 {
        return;
    }
    let stride = w as usize * 3;
    let buf: &mut [u8] = img;
    for y in y0..y1 {
        let row = y as usize * stride;
        if let Some(span) = buf.get_mut(row + x0 as usize * 3..row + x1 as usize * 3) {
            for px in span.chunks_exact_mut(3) {
                px.copy_from_slice(&c.0);
            }
        }
    }
}

fn frame_rect(img: &mut RgbImage, r: Rect, c: Rgb<u8>) {
    for x in r.x - 1..=r.x + r.w {
        put(img, x, r.y - 1, c);
        put(img, x, r.y + r.h, c);
    }
    for y in r.y - 1..=r.y + r.h {
        put(img, r.x - 1, y, c);
        put(img, r.x + r.w, y, c);
    }
}

fn hline(img: &mut RgbImage, r: Rect, y: i64, c: Rgb<u8>, dashed: bool) {
    for x in r.x..r.x + r.w {
        if !dashed || (x / 6) % 2 == 0 {
            put(img, x, y, c);
        }
    }
}

fn put_in(img: &mut RgbImage, r: Rect, x: i64, y: i64, c: Rgb<u8>) {
    if r.contains(x, y) {
        put(img, x, y, c);
    }
}

/// A line clipped to `r` (segments far outside are skipped whole).
fn line_in(img: &mut RgbImage, r: Rect, a: (i64, i64), b: (i64, i64), c: Rgb<u8>) {
    let outside = |p: (i64, i64)| !r.contains(p.0, p.1);
    if outside(a) && outside(b) {
        return;
    }
    let clamp = |p: (i64, i64)| (p.0.clamp(r.x, r.x + r.w - 1), p.1.clamp(r.y, r.y + r.h - 1));
    // The bottom row of the 2 px line must stay inside too.
    let (a, b) = (clamp(a), clamp(b));
    let lift = |p: (i64, i64)| (p.0, p.1.min(r.y + r.h - 2));
    line(img, lift(a), lift(b), c);
}

/// Draws a grey frame into `inner` at `scale`: each panel pixel is the
/// mean of the 2 x 2 frame pixels at its top-left corner (a box filter at
/// the usual half scale; no aliasing of the 3 px markers).
fn blit_grey(
    img: &mut RgbImage,
    inner: Rect,
    scale: f64,
    frame: &dexitac_tactile::frame::GreyFrame,
) {
    let (fw, fh) = (frame.width(), frame.height());
    if fw == 0 || fh == 0 || scale <= 0.0 {
        return;
    }
    let cols: Vec<(usize, usize)> = (0..inner.w)
        .map(|i| {
            let x = ((i as f64 / scale) as usize).min(fw - 1);
            (x, (x + 1).min(fw - 1))
        })
        .collect();
    let width = img.width() as usize;
    let height = img.height() as i64;
    let data = frame.data();
    let buf: &mut [u8] = img;
    for j in 0..inner.h {
        let y = inner.y + j;
        if y < 0 || y >= height || inner.x < 0 {
            continue;
        }
        let sy = ((j as f64 / scale) as usize).min(fh - 1);
        let (row0, row1) = (sy * fw, (sy + 1).min(fh - 1) * fw);
        let start = (y as usize * width + inner.x as usize) * 3;
        let Some(dst) = buf.get_mut(start..start + cols.len() * 3) else {
            continue;
        };
        let at = |k: usize| u16::from(data.get(k).copied().unwrap_or(0));
        for (px, &(x0, x1)) in dst.chunks_exact_mut(3).zip(&cols) {
            let sum = at(row0 + x0) + at(row0 + x1) + at(row1 + x0) + at(row1 + x1);
            let g = ((sum + 2) / 4) as u8;
            px.copy_from_slice(&[g, g, g]);
        }
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use dexitac_protocol::{HostMsg, Telemetry};

    use super::*;
    use crate::dashboard::DashboardConfig;
    use dexitac_gripper::grasp::CentreMm;
    use dexitac_rig::event::RuntimeEvent;
    use dexitac_tactile::contact::{Contact, Source};
    use dexitac_tactile::frame::GreyFrame;
    use dexitac_tactile::PointPx;

    fn pixel(img: &RgbImage, (x, y): (i64, i64)) -> Rgb<u8> {
        *img.get_pixel(x as u32, y as u32)
    }

    fn grid_markers() -> Vec<PointPx> {
        let mut m = Vec::new();
        for j in 0..30 {
            for i in 0..40 {
                m.push(PointPx::new(10.0 + i as f64 * 15.5, 10.0 + j as f64 * 15.5));
            }
        }
        m
    }

    fn observation(sensor: usize, t_ms: u64, centre: PointPx, frame: bool) -> RuntimeEvent {
        RuntimeEvent::Observation(dexitac_rig::event::SensorReport {
            sensor,
            t_ms,
            centre_mm: Some(CentreMm {
                x_mm: 0.0,
                y_mm: 0.0,
            }),
            markers: Arc::new(grid_markers()),
            pipeline_ms: 3.0,
            contact: Some(Contact {
                centre,
                area_mm2: 20.0,
                source: Source::Density,
            }),
            frame: frame
                .then(|| Arc::new(GreyFrame::new(640, 480, vec![90; 640 * 480]).expect("frame"))),
        })
    }

    fn telemetry(t_ms: u64, valves: [ValveState; 8], pumps: bool) -> RuntimeEvent {
        RuntimeEvent::Telemetry {
            t_ms,
            telemetry: Telemetry {
                time_ms: t_ms as u32,
                positive_tank_pa: 40_000,
                negative_tank_pa: -45_000,
                chambers: valves,
                positive_pump_on: pumps,
                negative_pump_on: false,
                state: ArmState::Armed,
                faults: Default::default(),
                loop_overruns: 0,
            },
        }
    }

    #[test]
    fn contact_centre_is_drawn_where_the_event_puts_it() {
        let layout = Layout;
        for (sensor, centre) in [
            (0, PointPx::new(200.0, 150.0)),
            (1, PointPx::new(517.0, 401.0)),
        ] {
            let mut d = Dashboard::new(DashboardConfig::default());
            d.apply(&observation(sensor, 0, centre, true));
            let img = d.render();
            for panel in [layout.frame_panel(sensor), layout.density_panel(sensor)] {
                let at = layout.to_panel(panel, (640, 480), centre).expect("finite");
                assert_eq!(pixel(&img, at), CONTACT_COLOUR, "sensor {sensor} at {at:?}");
                // Not drawn on the other sensor's panel.
                let other = layout.frame_panel(1 - sensor);
                let there = layout.to_panel(other, (640, 480), centre).expect("finite");
                assert_ne!(pixel(&img, there), CONTACT_COLOUR);
            }
            // The frame itself (grey 90) is under the panel away from the overlays.
            let corner = layout.frame_panel(sensor);
            assert_eq!(pixel(&img, (corner.x + 2, corner.y + 2)), Rgb([90, 90, 90]));
        }
    }

    #[test]
    fn valve_and_pump_states_colour_their_lanes() {
        let layout = Layout;
        let mut d = Dashboard::new(DashboardConfig::default());
        let mut valves = [ValveState::Hold; 8];
        valves[0] = ValveState::Inflate;
        valves[5] = ValveState::Deflate;
        d.apply(&telemetry(0, valves, true));
        d.apply(&telemetry(10_000, [ValveState::Hold; 8], false));
        d.apply(&telemetry(15_000, [ValveState::Hold; 8], false));
        let img = d.render();
        let history_ms = 20_000;
        // 5 s: the first report's states; 12 s: the second's.
        let at = |lane: usize, t_ms: u64| {
            let r = layout.lane(lane);
            (layout.time_x(15_000, history_ms, t_ms), r.y + r.h / 2)
        };
        assert_eq!(pixel(&img, at(1, 5_000)), INFLATE_COLOUR);
        assert_eq!(pixel(&img, at(6, 5_000)), DEFLATE_COLOUR);
        assert_eq!(pixel(&img, at(2, 5_000)), HOLD_COLOUR);
        assert_eq!(pixel(&img, at(9, 5_000)), PUMP_ON_COLOUR);
        assert_eq!(pixel(&img, at(1, 12_000)), HOLD_COLOUR);
        assert_eq!(pixel(&img, at(9, 12_000)), PUMP_OFF_COLOUR);
        // Before the first report: nothing known, chart background.
        let (x0, y) = at(1, 0);
        assert_eq!(pixel(&img, (x0 - 10, y)), CHART_BACKGROUND);
    }

    #[test]
    fn grasp_phase_lane_follows_the_decisions() {
        let layout = Layout;
        let mut d = Dashboard::new(DashboardConfig::default());
        d.apply(&RuntimeEvent::CommandSent {
            t_ms: 1_000,
            msg: HostMsg::SealAll,
            reason: "close fingers",
            from_frame: None,
        });
        d.apply(&telemetry(9_000, [ValveState::Hold; 8], false));
        let img = d.render();
        let lane = layout.lane(0);
        let x = layout.time_x(9_000, 20_000, 5_000);
        assert_eq!(
            pixel(&img, (x, lane.y + lane.h - 1)),
            phase_colour(GraspPhase::Closing)
        );
    }

    #[test]
    fn empty_nan_and_frameless_states_render_without_panic() {
        let empty = Dashboard::new(DashboardConfig::default()).render();
        assert_eq!(empty.dimensions(), Layout.size());
        let mut d = Dashboard::new(DashboardConfig {
            history_s: f64::NAN,
            trail_s: -1.0,
            ..DashboardConfig::default()
        });
        d.apply(&observation(0, 0, PointPx::new(f64::NAN, 3.0), false));
        d.apply(&observation(1, 5, PointPx::new(1e300, -1e300), false));
        d.apply(&RuntimeEvent::Observation(
            dexitac_rig::event::SensorReport {
                sensor: 0,
                t_ms: u64::MAX,
                centre_mm: None,
                markers: Arc::new(vec![PointPx::new(f64::NAN, f64::INFINITY)]),
                pipeline_ms: f64::INFINITY,
                contact: None,
                frame: Some(Arc::new(
                    GreyFrame::new(3, 2000, vec![0; 6000]).expect("frame"),
                )),
            },
        ));
        d.apply(&telemetry(7, [ValveState::Inflate; 8], true));
        d.apply(&RuntimeEvent::Stopped {
            t_ms: 9,
            max_loop_gap: std::time::Duration::ZERO,
            outcome: Err("link: gone".into()),
        });
        let img = d.render();
        assert_eq!(img.dimensions(), Layout.size());
        assert_eq!(d.phase(), GraspPhase::Failed);
    }
}
