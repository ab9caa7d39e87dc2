//! Where everything sits on the dashboard image (1280 x 720 px, fits a
//! laptop screen at 1:1, so the window shows the snapshot's pixels unscaled).
//!
//! ```text
//! +--------------------------------------------------------------------------+
//! | status: time, grasp phase, last decision, task, MCU state, fps, pipeline |
//! | finger 0 frame | finger 0 density | finger 1 frame | finger 1 density    |  320 x 240 each
//! | contact, area  | pipeline, fps    | ...                                  |
//! | tank pressures, kPa (strip chart, last `history_s`)                      |
//! | grasp phase lane, chamber valves C0..C7, pumps P+ P- (lanes)             |
//! | contact centre shift from its anchor, mm (T1, T2 dashed)                 |
//! +--------------------------------------------------------------------------+
//! ```

use dexitac_tactile::PointPx;

/// Dashboard width, px.
pub const VIEW_WIDTH_PX: u32 = 1280;
/// Dashboard height, px.
pub const VIEW_HEIGHT_PX: u32 = 720;
/// Width of a frame or density panel, px.
pub const PANEL_WIDTH_PX: i64 = 320;
/// Height of a frame or density panel, px.
pub const PANEL_HEIGHT_PX: i64 = 240;
/// Top of the panels, px.
const PANEL_TOP_PX: i64 = 36;
/// Left edge of the charts' plotting area, px (room for the axis labels).
const CHART_LEFT_PX: i64 = 70;
/// Right edge of the charts' plotting area, px.
const CHART_RIGHT_PX: i64 = 1262;
/// Height of one valve lane, px (lanes are 1 px apart).
pub const LANE_HEIGHT_PX: i64 = 12;
/// Lanes of the valve chart: grasp phase, 8 chambers, 2 pumps.
pub const LANES: usize = 11;

/// An axis-aligned rectangle, px: `[x, x + w) x [y, y + h)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rect {
    /// Left, px.
    pub x: i64,
    /// Top, px.
    pub y: i64,
    /// Width, px.
    pub w: i64,
    /// Height, px.
    pub h: i64,
}

impl Rect {
    /// True when (x, y) is inside.
    pub fn contains(&self, x: i64, y: i64) -> bool {
        x >= self.x && x < self.x + self.w && y >= self.y && y < self.y + self.h
    }
}

/// The dashboard's geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Layout;

impl Layout {
    /// Image size, px.
    pub fn size(&self) -> (u32, u32) {
        (VIEW_WIDTH_PX, VIEW_HEIGHT_PX)
    }

    /// The camera frame panel of `sensor` (0 or 1).
    pub fn frame_panel(&self, sensor: usize) -> Rect {
        Rect {
            x: sensor as i64 * 2 * PANEL_WIDTH_PX,
            y: PANEL_TOP_PX,
            w: PANEL_WIDTH_PX,
            h: PANEL_HEIGHT_PX,
        }
    }

    /// The density heatmap panel of `sensor`.
    pub fn density_panel(&self, sensor: usize) -> Rect {
        Rect {
            x: self.frame_panel(sensor).x + PANEL_WIDTH_PX,
            ..self.frame_panel(sensor)
        }
    }

    /// Where a `width x height` working frame is drawn inside `panel`
    /// (aspect kept, centred) and its scale, panel px per frame px.
    pub fn fit(&self, panel: Rect, width: usize, height: usize) -> (Rect, f64) {
        let (w, h) = (width.max(1) as f64, height.max(1) as f64);
        let scale = (panel.w as f64 / w).min(panel.h as f64 / h);
        let (fw, fh) = ((w * scale) as i64, (h * scale) as i64);
        let inner = Rect {
            x: panel.x + (panel.w - fw) / 2,
            y: panel.y + (panel.h - fh) / 2,
            w: fw,
            h: fh,
        };
        (inner, scale)
    }

    /// The image pixel showing working-frame point `p` of a `width x
    /// height` frame in `panel` (`None` for non-finite points).
    pub fn to_panel(&self, panel: Rect, size_px: (usize, usize), p: PointPx) -> Option<(i64, i64)> {
        if !p.is_finite() {
            return None;
        }
        let (inner, scale) = self.fit(panel, size_px.0, size_px.1);
        let clamp = |v: f64| v.clamp(-1e6, 1e6);
        Some((
            inner.x + clamp(p.x * scale).floor() as i64,
            inner.y + clamp(p.y * scale).floor() as i64,
        ))
    }

    /// Line under the panels with each sensor's numbers, y px.
    pub fn panel_footer_y(&self) -> i64 {
        PANEL_TOP_PX + PANEL_HEIGHT_PX + 6
    }

    /// Tank pressure chart (plotting area).
    pub fn pressure_chart(&self) -> Rect {
        Rect {
            x: CHART_LEFT_PX,
            y: 308,
            w: CHART_RIGHT_PX - CHART_LEFT_PX,
            h: 120,
        }
    }

    /// The valve chart (plotting area holding all lanes).
    pub fn valve_chart(&self) -> Rect {
        Rect {
            x: CHART_LEFT_PX,
            y: 446,
            w: CHART_RIGHT_PX - CHART_LEFT_PX,
            h: LANES as i64 * (LANE_HEIGHT_PX + 1),
        }
    }

    /// Lane `index` of the valve chart: 0 grasp phase, 1..=8 chambers
    /// 0..=7, 9 positive pump, 10 negative pump.
    pub fn lane(&self, index: usize) -> Rect {
        let chart = self.valve_chart();
        Rect {
            x: chart.x,
            y: chart.y + index as i64 * (LANE_HEIGHT_PX + 1),
            w: chart.w,
            h: LANE_HEIGHT_PX,
        }
    }

    /// Contact centre shift chart (plotting area).
    pub fn shift_chart(&self) -> Rect {
        Rect {
            x: CHART_LEFT_PX,
            y: 612,
            w: CHART_RIGHT_PX - CHART_LEFT_PX,
            h: 80,
        }
    }

    /// The x of time `t_ms` on the charts, whose right edge is `now_ms`
    /// and which span `history_ms` (may lie outside the charts).
    pub fn time_x(&self, now_ms: u64, history_ms: u64, t_ms: u64) -> i64 {
        let chart = self.pressure_chart();
        let span = history_ms.max(1) as f64;
        let age = now_ms as f64 - t_ms as f64;
        chart.x + chart.w - (age / span * chart.w as f64).round() as i64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn everything_fits_the_image_without_overlap() {
        let l = Layout;
        let (w, h) = l.size();
        let mut rects = vec![l.pressure_chart(), l.valve_chart(), l.shift_chart()];
        for s in 0..2 {
            rects.push(l.frame_panel(s));
            rects.push(l.density_panel(s));
        }
        for r in &rects {
            assert!(r.x >= 0 && r.y >= 0 && r.x + r.w <= i64::from(w) && r.y + r.h <= i64::from(h));
        }
        for (i, a) in rects.iter().enumerate() {
            for b in &rects[i + 1..] {
                let apart =
                    a.x + a.w <= b.x || b.x + b.w <= a.x || a.y + a.h <= b.y || b.y + b.h <= a.y;
                assert!(apart, "{a:?} overlaps {b:?}");
            }
        }
        assert_eq!(l.lane(LANES - 1).y + LANE_HEIGHT_PX + 1, {
            let v = l.valve_chart();
            v.y + v.h
        });
    }

    #[test]
    fn a_640x480_frame_maps_at_half_scale() {
        let l = Layout;
        let p = l.frame_panel(1);
        assert_eq!(
            l.to_panel(p, (640, 480), PointPx::new(200.0, 100.0)),
            Some((p.x + 100, p.y + 50))
        );
        assert_eq!(l.to_panel(p, (640, 480), PointPx::new(f64::NAN, 1.0)), None);
    }
}
