//! The sensing area: the part of the working frame covered by the skin's
//! marker lattice. Detections outside it (the bright housing, LEDs, dust,
//! reflections) are dropped before density and tracking.
//!
//! The area is either found from the rest frame ([`from_lattice`]: the
//! convex hull of the markers that sit in a regular lattice, grown by
//! [`HULL_GROWTH_PITCH`], with a band [`RIM_TRAVEL_PITCH`] wide around it
//! where the outer markers a contact pushes out are kept, see
//! [`crate::markers::RimBand`]) or given in the sensor config as a circle, a
//! rounded rectangle, a polygon or a mask image ([`AreaSpec`], in
//! input-image pixels). Either way
//! it is stored as row spans of the working frame, so the test of a point
//! is a lookup of its row and a scan of that row's (usually one) spans.

use serde::Deserialize;

use crate::PointPx;

/// The sensing area as given in a sensor config (`[area]`), in input-image
/// pixels (before crop and rescale).
#[derive(Debug, Clone, PartialEq, Deserialize, Default)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum AreaSpec {
    /// Found from the rest frame's marker lattice (the default).
    #[default]
    Auto,
    /// The whole frame: no detection is dropped.
    Whole,
    /// A circle.
    Circle {
        /// Centre `[x, y]`, input px.
        centre_px: [f64; 2],
        /// Radius, input px.
        radius_px: f64,
    },
    /// A rectangle with rounded corners.
    RoundedRect {
        /// `[x, y, width, height]`, input px.
        rect_px: [f64; 4],
        /// Corner radius, input px (0: square corners).
        #[serde(default)]
        corner_radius_px: f64,
    },
    /// A polygon (at least 3 vertices, any winding; even-odd fill).
    Polygon {
        /// Vertices `[[x, y], ...]`, input px.
        points_px: Vec<[f64; 2]>,
    },
    /// A mask image, as large as the input frame: non-zero pixels are the
    /// sensing area. The path is relative to the config file; the caller
    /// that reads the config decodes it into [`MaskImage`] (this crate reads
    /// no files).
    Mask {
        /// Path of a PNG (grey or colour) mask.
        path: std::path::PathBuf,
    },
}

/// A decoded mask image in input pixels: `true` = sensing area.
#[derive(Debug, Clone, PartialEq)]
pub struct MaskImage {
    /// Width, input px.
    pub width: usize,
    /// Height, input px.
    pub height: usize,
    /// Row-major, `width * height` values.
    pub inside: Vec<bool>,
}

/// Map from working-frame pixels to input-image pixels (see
/// [`crate::frame::Prepared::to_input`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorkToInput {
    /// Input px per working px, x.
    pub scale_x: f64,
    /// Input px per working px, y.
    pub scale_y: f64,
    /// Crop origin in input px.
    pub origin_px: PointPx,
}

impl WorkToInput {
    /// The identity (working frame = input frame).
    pub const IDENTITY: Self = Self {
        scale_x: 1.0,
        scale_y: 1.0,
        origin_px: PointPx::new(0.0, 0.0),
    };

    /// Working point -> input point (pixel centres at integers).
    pub fn apply(&self, p: PointPx) -> PointPx {
        PointPx::new(
            self.origin_px.x + (p.x + 0.5) * self.scale_x - 0.5,
            self.origin_px.y + (p.y + 0.5) * self.scale_y - 0.5,
        )
    }

    /// Input point -> working point (the inverse of [`WorkToInput::apply`]).
    pub fn to_work(&self, q: PointPx) -> PointPx {
        PointPx::new(
            (q.x - self.origin_px.x + 0.5) / self.scale_x - 0.5,
            (q.y - self.origin_px.y + 0.5) / self.scale_y - 0.5,
        )
    }
}

/// Errors of an area given in the config.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AreaError {
    /// A shape with a non-finite or non-positive size, or a polygon with
    /// fewer than 3 vertices.
    #[error("sensing area: {0}")]
    Invalid(&'static str),
    /// A mask spec reached the pipeline without its decoded image.
    #[error("sensing area: the mask image {0} was not loaded")]
    MaskNotLoaded(std::path::PathBuf),
    /// The mask image's size differs from the input frame's.
    #[error("sensing area: mask is {mask_w}x{mask_h} but frames are {frame_w}x{frame_h}")]
    MaskSize {
        /// Mask width, px.
        mask_w: usize,
        /// Mask height, px.
        mask_h: usize,
        /// Input frame width, px.
        frame_w: usize,
        /// Input frame height, px.
        frame_h: usize,
    },
    /// The area covers no working pixel.
    #[error("sensing area covers no pixel of the working frame")]
    Empty,
}

/// The sensing area on the working frame, as row spans `[x0, x1)`.
#[derive(Debug, Clone, PartialEq)]
pub struct SensingArea {
    width: usize,
    height: usize,
    /// Per row, the half-open x ranges inside the area, ascending.
    rows: Vec<Vec<(u16, u16)>>,
}

impl SensingArea {
    /// The whole `width x height` frame.
    pub fn whole(width: usize, height: usize) -> Self {
        let w = width.min(u16::MAX as usize) as u16;
        Self {
            width,
            height,
            rows: vec![vec![(0, w)]; height],
        }
    }

    /// The area from a per-pixel predicate on working-pixel centres.
    pub fn from_fn(width: usize, height: usize, inside: impl Fn(f64, f64) -> bool) -> Self {
        let rows = (0..height)
            .map(|y| spans(width, |x| inside(x as f64, y as f64)))
            .collect();
        Self {
            width,
            height,
            rows,
        }
    }

    /// The pixels inside `poly` by [`in_polygon`]'s even-odd rule, a row
    /// at a time: each edge's crossing of a row is worked out once, not
    /// once per pixel (with the same arithmetic, so the same pixels).
    fn from_polygon(width: usize, height: usize, poly: &[PointPx]) -> Self {
        let mut crossings: Vec<f64> = Vec::with_capacity(poly.len());
        let rows = (0..height)
            .map(|y| {
                let y = y as f64;
                crossings.clear();
                let mut j = poly.len().saturating_sub(1);
                for i in 0..poly.len() {
                    let (a, b) = (poly[i], poly[j]);
                    if (a.y > y) != (b.y > y) {
                        let c = (b.x - a.x) * (y - a.y) / (b.y - a.y) + a.x;
                        // A NaN crossing never toggles `in_polygon`.
                        if !c.is_nan() {
                            crossings.push(c);
                        }
                    }
                    j = i;
                }
                crossings.sort_by(f64::total_cmp);
                // Pixel x is inside when an odd number of crossings lie
                // beyond it (x < c); `passed` counts those that do not
                // (none is NaN).
                let mut passed = 0;
                spans(width, |x| {
                    let x = x as f64;
                    while passed < crossings.len() && x >= crossings[passed] {
                        passed += 1;
                    }
                    (crossings.len() - passed) % 2 == 1
                })
            })
            .collect();
        Self {
            width,
            height,
            rows,
        }
    }

    /// The area of a config spec on a `width x height` working frame whose
    /// pixels map to input pixels by `map`. `Auto` is not a shape: it gives
    /// `Ok(None)` (the caller finds the area from the rest markers).
    pub fn from_spec(
        spec: &AreaSpec,
        mask: Option<&MaskImage>,
        width: usize,
        height: usize,
        map: WorkToInput,
    ) -> Result<Option<Self>, AreaError> {
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        let area = match spec {
            AreaSpec::Auto => return Ok(None),
            AreaSpec::Whole => Self::whole(width, height),
            AreaSpec::Circle {
                centre_px,
                radius_px,
            } => {
                if !finite(centre_px) || !radius_px.is_finite() || *radius_px <= 0.0 {
                    return Err(AreaError::Invalid(
                        "circle needs a finite centre and radius > 0",
                    ));
                }
                let [cx, cy] = *centre_px;
                let r2 = radius_px * radius_px;
                Self::from_fn(width, height, |x, y| {
                    let p = map.apply(PointPx::new(x, y));
                    (p.x - cx).powi(2) + (p.y - cy).powi(2) <= r2
                })
            }
            AreaSpec::RoundedRect {
                rect_px,
                corner_radius_px,
            } => {
                let [rx, ry, rw, rh] = *rect_px;
                let r = *corner_radius_px;
                if !finite(rect_px) || rw <= 0.0 || rh <= 0.0 || !r.is_finite() || r < 0.0 {
                    return Err(AreaError::Invalid(
                        "rounded_rect needs finite [x, y, w, h] with w, h > 0 and a corner radius >= 0",
                    ));
                }
                let r = r.min(rw / 2.0).min(rh / 2.0);
                Self::from_fn(width, height, |x, y| {
                    let p = map.apply(PointPx::new(x, y));
                    // Distance outside the rectangle shrunk by r, <= r inside.
                    let dx = ((rx + r) - p.x).max(p.x - (rx + rw - r)).max(0.0);
                    let dy = ((ry + r) - p.y).max(p.y - (ry + rh - r)).max(0.0);
                    p.x >= rx
                        && p.x <= rx + rw
                        && p.y >= ry
                        && p.y <= ry + rh
                        && dx * dx + dy * dy <= r * r
                })
            }
            AreaSpec::Polygon { points_px } => {
                if points_px.len() < 3 || !points_px.iter().all(|p| finite(p)) {
                    return Err(AreaError::Invalid(
                        "polygon needs at least 3 finite vertices",
                    ));
                }
                let poly: Vec<PointPx> =
                    points_px.iter().map(|p| PointPx::new(p[0], p[1])).collect();
                Self::from_fn(width, height, |x, y| {
                    in_polygon(&poly, map.apply(PointPx::new(x, y)))
                })
            }
            AreaSpec::Mask { path } => {
                let m = mask.ok_or_else(|| AreaError::MaskNotLoaded(path.clone()))?;
                if m.inside.len() != m.width * m.height {
                    return Err(AreaError::Invalid("mask buffer does not match its size"));
                }
                Self::from_fn(width, height, |x, y| {
                    let p = map.apply(PointPx::new(x, y));
                    let (ix, iy) = (p.x.round(), p.y.round());
                    ix >= 0.0
                        && iy >= 0.0
                        && (ix as usize) < m.width
                        && (iy as usize) < m.height
                        && m.inside[iy as usize * m.width + ix as usize]
                })
            }
        };
        if area.pixel_count() == 0 {
            return Err(AreaError::Empty);
        }
        Ok(Some(area))
    }

    /// Checks a decoded mask against the input frame size.
    pub fn check_mask(mask: &MaskImage, frame_w: usize, frame_h: usize) -> Result<(), AreaError> {
        if (mask.width, mask.height) == (frame_w, frame_h) {
            Ok(())
        } else {
            Err(AreaError::MaskSize {
                mask_w: mask.width,
                mask_h: mask.height,
                frame_w,
                frame_h,
            })
        }
    }

    /// Working frame width, px.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Working frame height, px.
    pub fn height(&self) -> usize {
        self.height
    }

    /// True when the point (working px, pixel centres at integers) is inside.
    pub fn contains(&self, p: PointPx) -> bool {
        if !p.is_finite() {
            return false;
        }
        // Rounded to the nearest pixel; below -0.5 is outside. `+ 0.5` and
        // truncation round without a libm call (the per-marker hot path).
        if p.x <= -0.5 || p.y <= -0.5 {
            return false;
        }
        // (Through i64: a float's `as usize` takes a longer sequence on
        // x86-64; both are above -0.5 here, so non-negative.)
        let (x, y) = ((p.x + 0.5) as i64 as usize, (p.y + 0.5) as i64 as usize);
        if y >= self.height {
            return false;
        }
        self.rows[y]
            .iter()
            .any(|&(a, b)| (a as usize) <= x && x < b as usize)
    }

    /// Number of working pixels inside.
    pub fn pixel_count(&self) -> usize {
        self.rows
            .iter()
            .flatten()
            .map(|&(a, b)| (b - a) as usize)
            .sum()
    }

    /// Bounding box `[x0, y0, x1, y1)` of the area (working px), or `None`
    /// when it is empty.
    pub fn bounds(&self) -> Option<[usize; 4]> {
        let ys: Vec<usize> = (0..self.height)
            .filter(|&y| !self.rows[y].is_empty())
            .collect();
        let (y0, y1) = (*ys.first()?, *ys.last()? + 1);
        let x0 = self
            .rows
            .iter()
            .filter_map(|r| r.first())
            .map(|s| s.0)
            .min()? as usize;
        let x1 = self
            .rows
            .iter()
            .filter_map(|r| r.last())
            .map(|s| s.1)
            .max()? as usize;
        Some([x0, y0, x1, y1])
    }
}

/// The half-open runs of `x` in `0..width` where `inside(x)` holds, in
/// ascending order (`inside` is asked once per x, left to right).
fn spans(width: usize, mut inside: impl FnMut(usize) -> bool) -> Vec<(u16, u16)> {
    let mut out = Vec::new();
    let mut start = None;
    for x in 0..=width {
        let inn = x < width && inside(x);
        match (inn, start) {
            (true, None) => start = Some(x),
            (false, Some(s)) => {
                out.push((s as u16, x as u16));
                start = None;
            }
            _ => {}
        }
    }
    out
}

/// Even-odd point-in-polygon test.
fn in_polygon(poly: &[PointPx], p: PointPx) -> bool {
    let mut inside = false;
    let mut j = poly.len() - 1;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[j]);
        if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
            inside = !inside;
        }
        j = i;
    }
    inside
}

/// Markers that sit in a regular lattice: a marker is kept when its
/// nearest-neighbour distance is at most [`LATTICE_MAX_GAP`] times the
/// median one and at least [`LATTICE_MIN_NEIGHBOURS`] others lie within
/// [`LATTICE_REACH`] times that distance, or it completes a cell of kept
/// markers (a square lattice's corner, `completes_a_cell`). A skin's
/// markers (the rim's included: two along the rim and two inwards) pass;
/// LEDs, dust and reflections on the housing are isolated or irregular and
/// fail. Returns the indices kept.
pub fn lattice_members(points: &[PointPx]) -> Vec<usize> {
    let n = points.len();
    if n < LATTICE_MIN_NEIGHBOURS + 1 {
        return (0..n).collect();
    }
    let dists = nearest_distances(points, LATTICE_MIN_NEIGHBOURS + 4, true);
    let mut nn: Vec<f64> = dists.iter().filter_map(|d| d.first().copied()).collect();
    if nn.is_empty() {
        return Vec::new();
    }
    let k = nn.len() / 2;
    let median = *nn.select_nth_unstable_by(k, f64::total_cmp).1;
    let gap_ok = |d: &[f64]| d.first().is_some_and(|&d1| d1 <= LATTICE_MAX_GAP * median);
    let member: Vec<bool> = dists
        .iter()
        .map(|d| {
            gap_ok(d)
                && d.iter().filter(|&&x| x <= LATTICE_REACH * d[0]).count()
                    >= LATTICE_MIN_NEIGHBOURS
        })
        .collect();
    (0..n)
        .filter(|&i| {
            member[i] || (gap_ok(&dists[i]) && completes_a_cell(points, &member, i, median))
        })
        .collect()
}

/// Per point of `points`, its `k` smallest distances to the others,
/// ascending: with `skip_zero` every distance of 0 is left out (a point
/// on top of it as well as itself), otherwise only its own. A sweep over
/// the points in order of x, each stopped once the x gap alone exceeds the
/// k-th distance so far: about O(n k) on a marker lattice, where sorting
/// every pair's distance took half of a calibration (0.23 of 0.48 s for
/// 1223 markers, BENCHMARKS.md, session 23). Points with a non-finite
/// coordinate are measured against every other point instead.
pub(crate) fn nearest_distances(points: &[PointPx], k: usize, skip_zero: bool) -> Vec<Vec<f64>> {
    // Offers `points[j]` to point `i`'s `best`; false once the x gap alone
    // exceeds the k-th distance (the sweep's stop).
    let offer = |best: &mut Vec<f64>, i: usize, j: usize, sweep: bool| {
        let (p, q) = (points[i], points[j]);
        if sweep && best.len() == k && (q.x - p.x).abs() > best[k - 1] {
            return false;
        }
        let (dx, dy) = (q.x - p.x, q.y - p.y);
        // Surely beyond the k-th (hypot is within an ulp of the root):
        // spared the hypot.
        if best.len() == k && dx * dx + dy * dy > (best[k - 1] * (1.0 + 1e-9)).powi(2) {
            return true;
        }
        let d = dx.hypot(dy);
        let kept = if skip_zero {
            d > 0.0
        } else {
            i != j && !d.is_nan()
        };
        let at = best.partition_point(|&b| b <= d);
        if kept && at < k {
            best.insert(at, d);
            best.truncate(k);
        }
        true
    };
    if k == 0 {
        return vec![Vec::new(); points.len()];
    }
    if !points.iter().all(|p| p.is_finite()) {
        return (0..points.len())
            .map(|i| {
                let mut best = Vec::with_capacity(k + 1);
                for j in 0..points.len() {
                    offer(&mut best, i, j, false);
                }
                best
            })
            .collect();
    }
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| points[a].x.total_cmp(&points[b].x));
    let mut rank = vec![0; points.len()];
    for (r, &i) in order.iter().enumerate() {
        rank[i] = r;
    }
    (0..points.len())
        .map(|i| {
            let mut best = Vec::with_capacity(k + 1);
            let r = rank[i];
            for &j in &order[r + 1..] {
                if !offer(&mut best, i, j, true) {
                    break;
                }
            }
            for &j in order[..r].iter().rev() {
                if !offer(&mut best, i, j, true) {
                    break;
                }
            }
            best
        })
        .collect()
}

/// Whether `points[i]` is the fourth corner of a square lattice cell whose
/// other three corners are members: two members `a`, `b` within
/// [`LATTICE_REACH`] median spacings of it, at right angles seen from it
/// ([`CELL_CORNER_SKEW_DEG`]), and a member within
/// [`CELL_CORNER_TOLERANCE`] median spacings of `a + b - p`.
/// A square lattice's corner marker has only its two side neighbours
/// within the reach (the diagonal one lies 1.41 spacings away, and 1.5-1.6
/// times its own nearest distance where the frame's edge cuts it or the lens
/// distorts the corner), and so fails the neighbour count; a speck on the
/// housing lies on no such cell.
fn completes_a_cell(points: &[PointPx], member: &[bool], i: usize, median: f64) -> bool {
    let p = points[i];
    let reach = LATTICE_REACH * median;
    let near: Vec<PointPx> = points
        .iter()
        .zip(member)
        .filter(|&(&q, &m)| m && within(p, q, reach))
        .map(|(q, _)| *q)
        .collect();
    let tolerance = CELL_CORNER_TOLERANCE * median;
    near.iter().enumerate().any(|(k, a)| {
        near[k + 1..].iter().any(|b| {
            let (ax, ay, bx, by) = (a.x - p.x, a.y - p.y, b.x - p.x, b.y - p.y);
            // Sides at right angles, within CELL_CORNER_SKEW_DEG.
            let cos = (ax * bx + ay * by) / (ax.hypot(ay) * bx.hypot(by));
            let apart = cos.abs() <= CELL_CORNER_SKEW_DEG.to_radians().sin();
            let c = PointPx::new(a.x + bx, a.y + by);
            apart
                && points
                    .iter()
                    .zip(member)
                    .any(|(&q, &m)| m && within(c, q, tolerance))
        })
    })
}

/// Whether `a` and `b` lie within `r` of each other (by `hypot`, which only
/// the pairs whose squared distance comes near `r^2` need).
fn within(a: PointPx, b: PointPx, r: f64) -> bool {
    let (dx, dy) = (a.x - b.x, a.y - b.y);
    dx * dx + dy * dy <= (r * (1.0 + 1e-9)).powi(2) && dx.hypot(dy) <= r
}

/// Neighbours a lattice marker needs within [`LATTICE_REACH`] x its
/// nearest-neighbour distance (a hex lattice's rim marker has 4).
pub const LATTICE_MIN_NEIGHBOURS: usize = 3;
/// Reach of the neighbour count, in units of the marker's own
/// nearest-neighbour distance (a hex lattice's second ring is at 1.73).
pub const LATTICE_REACH: f64 = 1.5;
/// A marker whose nearest neighbour is farther than this many median
/// spacings is isolated. The LEDs and specks around a real TacTip's pin
/// disc sit about 1.95 median spacings from the outer ring; a dome's
/// central markers (the widest spaced) are within about 1.3.
pub const LATTICE_MAX_GAP: f64 = 1.5;
/// How far from the fourth corner of a cell a member may lie for a marker
/// to complete it ([`lattice_members`]), in median spacings.
pub const CELL_CORNER_TOLERANCE: f64 = 0.25;
/// A completed cell's sides meet at right angles within this many degrees:
/// a square lattice's cell (the lens and a cut edge skew it by a few
/// degrees), not a hex lattice's rhombus (60 and 120 degrees), which an LED
/// right outside the outer ring would complete.
pub const CELL_CORNER_SKEW_DEG: f64 = 20.0;
/// The automatic area is the lattice's convex hull grown by this many
/// pitches (the outer markers' own extent plus a margin for their motion).
pub const HULL_GROWTH_PITCH: f64 = 0.6;

/// How far beyond the automatic area the outer markers may be pushed by a
/// contact, in pitches: a deep tap on a real TacTip moves the outer ring
/// up to 1.5 pitches beyond the rest lattice's hull (the public
/// `tactile_data_shear` taps of 4-5 mm), 0.9 beyond the area. See
/// [`crate::markers::RimBand`].
pub const RIM_TRAVEL_PITCH: f64 = 1.0;

/// The sensing area from the rest markers: the convex hull of the lattice
/// markers ([`lattice_members`]), grown outwards by `growth_pitch` times
/// `pitch_px` ([`HULL_GROWTH_PITCH`] for the area itself). `None` with
/// fewer than 3 lattice markers.
pub fn from_lattice(
    points: &[PointPx],
    pitch_px: f64,
    growth_pitch: f64,
    width: usize,
    height: usize,
) -> Option<SensingArea> {
    let kept: Vec<PointPx> = lattice_members(points)
        .into_iter()
        .map(|i| points[i])
        .collect();
    let hull = convex_hull(&kept);
    if hull.len() < 3 {
        return None;
    }
    let (sx, sy) = hull.iter().fold((0.0, 0.0), |(a, b), p| (a + p.x, b + p.y));
    let c = PointPx::new(sx / hull.len() as f64, sy / hull.len() as f64);
    let grow = growth_pitch * pitch_px;
    let grown: Vec<PointPx> = hull
        .iter()
        .map(|p| {
            let (dx, dy) = (p.x - c.x, p.y - c.y);
            let r = dx.hypot(dy).max(1e-9);
            PointPx::new(p.x + grow * dx / r, p.y + grow * dy / r)
        })
        .collect();
    let area = SensingArea::from_polygon(width, height, &grown);
    (area.pixel_count() > 0).then_some(area)
}

/// Convex hull (Andrew's monotone chain), counter-clockwise in image
/// coordinates, without collinear points.
pub fn convex_hull(points: &[PointPx]) -> Vec<PointPx> {
    let mut p: Vec<PointPx> = points.iter().copied().filter(|p| p.is_finite()).collect();
    p.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross =
        |o: PointPx, a: PointPx, b: PointPx| (a.x - o.x) * (b.y - o.y) - (a.y - o.y) * (b.x - o.x);
    let mut hull: Vec<PointPx> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &PointPx>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(cx: f64, cy: f64, radius: f64, pitch: f64) -> Vec<PointPx> {
        let mut v = Vec::new();
        let rows = (radius / (pitch * 0.866)) as i64 + 1;
        for j in -rows..=rows {
            let y = cy + j as f64 * pitch * 0.866;
            let off = if j % 2 == 0 { 0.0 } else { pitch / 2.0 };
            for i in -rows - 1..=rows + 1 {
                let x = cx + i as f64 * pitch + off;
                if (x - cx).hypot(y - cy) <= radius {
                    v.push(PointPx::new(x, y));
                }
            }
        }
        v
    }

    #[test]
    fn a_point_belongs_to_its_nearest_pixel() {
        // Pixels x, y in 0..=2 of a 5x4 frame.
        let area = SensingArea::from_fn(5, 4, |x, y| x <= 2.0 && y <= 2.0);
        let inside = [(-0.49, 0.0), (0.0, -0.49), (2.49, 2.49), (1.0, 1.0)];
        let outside = [
            (-0.5, 0.0),
            (0.0, -0.5),
            (2.5, 0.0),
            (0.0, 2.5),
            (4.0, 9.0),
            (f64::NAN, 0.0),
        ];
        assert!(inside
            .iter()
            .all(|&(x, y)| area.contains(PointPx::new(x, y))));
        assert!(outside
            .iter()
            .all(|&(x, y)| !area.contains(PointPx::new(x, y))));
    }

    #[test]
    fn housing_blobs_are_not_lattice_and_fall_outside_the_area() {
        let mut pts = hex(320.0, 240.0, 180.0, 15.0);
        let n = pts.len();
        // LEDs just outside the disc, and dust specks on the housing.
        let outside = [
            PointPx::new(320.0, 240.0 - 215.0),
            PointPx::new(320.0 + 212.0, 240.0),
            PointPx::new(40.0, 30.0),
            PointPx::new(600.0, 450.0),
            PointPx::new(610.0, 455.0),
        ];
        pts.extend(outside);
        let kept = lattice_members(&pts);
        assert_eq!(kept.len(), n, "every lattice marker and no housing blob");
        assert!(kept.iter().all(|&i| i < n));
        let area = from_lattice(&pts, 15.0, HULL_GROWTH_PITCH, 640, 480).unwrap();
        assert!(pts[..n].iter().all(|&p| area.contains(p)));
        assert!(outside.iter().all(|&p| !area.contains(p)));
    }

    #[test]
    fn config_shapes_map_from_input_pixels() {
        // Working 320x240 from a 640x480 input: 2 input px per working px.
        let map = WorkToInput {
            scale_x: 2.0,
            scale_y: 2.0,
            origin_px: PointPx::new(0.0, 0.0),
        };
        let circle = AreaSpec::Circle {
            centre_px: [320.0, 240.0],
            radius_px: 100.0,
        };
        let a = SensingArea::from_spec(&circle, None, 320, 240, map)
            .unwrap()
            .unwrap();
        assert!(a.contains(PointPx::new(160.0, 120.0)));
        assert!(a.contains(PointPx::new(160.0 + 48.0, 120.0)));
        assert!(!a.contains(PointPx::new(160.0 + 52.0, 120.0)));
        let area_px = a.pixel_count() as f64;
        let want = std::f64::consts::PI * 50.0 * 50.0;
        assert!((area_px - want).abs() < 0.02 * want, "{area_px} vs {want}");

        let rr = AreaSpec::RoundedRect {
            rect_px: [100.0, 100.0, 200.0, 100.0],
            corner_radius_px: 40.0,
        };
        let a = SensingArea::from_spec(&rr, None, 640, 480, WorkToInput::IDENTITY)
            .unwrap()
            .unwrap();
        assert!(a.contains(PointPx::new(200.0, 150.0)));
        assert!(!a.contains(PointPx::new(101.0, 101.0)), "the corner is cut");
        assert!(a.contains(PointPx::new(101.0, 150.0)));
        assert_eq!(a.bounds(), Some([100, 100, 301, 201]));

        let tri = AreaSpec::Polygon {
            points_px: vec![[0.0, 0.0], [100.0, 0.0], [0.0, 100.0]],
        };
        let a = SensingArea::from_spec(&tri, None, 640, 480, WorkToInput::IDENTITY)
            .unwrap()
            .unwrap();
        assert!(a.contains(PointPx::new(10.0, 10.0)));
        assert!(!a.contains(PointPx::new(60.0, 60.0)));

        let mut inside = vec![false; 64 * 48];
        inside[10 * 64 + 20] = true;
        let mask = MaskImage {
            width: 64,
            height: 48,
            inside,
        };
        let spec = AreaSpec::Mask {
            path: "m.png".into(),
        };
        let a = SensingArea::from_spec(&spec, Some(&mask), 64, 48, WorkToInput::IDENTITY)
            .unwrap()
            .unwrap();
        assert_eq!(a.pixel_count(), 1);
        assert!(a.contains(PointPx::new(20.2, 9.8)));
    }

    #[test]
    fn bad_shapes_are_typed_errors() {
        let id = WorkToInput::IDENTITY;
        let bad = [
            AreaSpec::Circle {
                centre_px: [f64::NAN, 0.0],
                radius_px: 3.0,
            },
            AreaSpec::Circle {
                centre_px: [0.0, 0.0],
                radius_px: -3.0,
            },
            AreaSpec::Polygon {
                points_px: vec![[0.0, 0.0], [1.0, 1.0]],
            },
            AreaSpec::RoundedRect {
                rect_px: [0.0, 0.0, 0.0, 10.0],
                corner_radius_px: 0.0,
            },
        ];
        for spec in &bad {
            assert!(matches!(
                SensingArea::from_spec(spec, None, 64, 48, id),
                Err(AreaError::Invalid(_))
            ));
        }
        let off = AreaSpec::Circle {
            centre_px: [-500.0, -500.0],
            radius_px: 3.0,
        };
        assert_eq!(
            SensingArea::from_spec(&off, None, 64, 48, id),
            Err(AreaError::Empty)
        );
        let mask = AreaSpec::Mask {
            path: "m.png".into(),
        };
        assert!(matches!(
            SensingArea::from_spec(&mask, None, 64, 48, id),
            Err(AreaError::MaskNotLoaded(_))
        ));
        assert!(!SensingArea::whole(4, 4).contains(PointPx::new(f64::NAN, 1.0)));
    }

    proptest::proptest! {
        /// The sweep's nearest distances are every pair's distance sorted
        /// and cut to `k`, on scattered points with duplicates, as on a
        /// lattice; with a NaN coordinate too.
        #[test]
        fn nearest_distances_are_the_sorted_pair_distances(
            xy in proptest::collection::vec((0u8..40, 0u8..40), 0..60),
            k in 0usize..9,
            skip_zero: bool,
            nan: bool,
        ) {
            let mut points: Vec<PointPx> = xy
                .iter()
                .map(|&(x, y)| PointPx::new(x as f64 * 1.7, y as f64 * 0.9))
                .collect();
            if nan && !points.is_empty() {
                points[0].y = f64::NAN;
            }
            let plain: Vec<Vec<f64>> = points
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let mut d: Vec<f64> = points
                        .iter()
                        .enumerate()
                        .filter(|&(j, _)| j != i)
                        .map(|(_, q)| (q.x - p.x).hypot(q.y - p.y))
                        .filter(|&d| !d.is_nan() && (!skip_zero || d > 0.0))
                        .collect();
                    d.sort_by(f64::total_cmp);
                    d.truncate(k);
                    d
                })
                .collect();
            proptest::prop_assert_eq!(nearest_distances(&points, k, skip_zero), plain);
        }

        /// The row-wise polygon fill holds the pixels the per-pixel even-odd
        /// test does, for any (also self-crossing) polygon.
        #[test]
        fn the_polygon_fill_is_the_even_odd_test(
            poly in proptest::collection::vec((-10.0f64..50.0, -10.0f64..40.0), 3..9),
        ) {
            let poly: Vec<PointPx> = poly.iter().map(|&(x, y)| PointPx::new(x, y)).collect();
            proptest::prop_assert_eq!(
                SensingArea::from_polygon(40, 30, &poly),
                SensingArea::from_fn(40, 30, |x, y| in_polygon(&poly, PointPx::new(x, y)))
            );
        }

        /// Every marker of a rectangular lattice, turned any way, is a
        /// lattice member, its four corners included (up to an aspect of
        /// 1.118 the plain neighbour count passes them; beyond, only a
        /// completed cell does). A point by the straight edge of a hex
        /// lattice, where its next row would be, has two members 60 degrees
        /// apart: it completes no cell and stays out.
        #[test]
        fn rectangular_lattices_keep_their_corners_and_hex_edges_keep_out(
            pitch in 8.0f64..40.0,
            aspect in 1.0f64..1.3,
            angle in 0.0f64..std::f64::consts::PI,
            (cols, rows) in (3usize..9, 3usize..9),
        ) {
            let (c, s) = (angle.cos(), angle.sin());
            let at = |i: f64, j: f64| {
                let (x, y) = (i * pitch * aspect, j * pitch);
                PointPx::new(400.0 + c * x - s * y, 400.0 + s * x + c * y)
            };
            let lattice: Vec<PointPx> = (0..rows)
                .flat_map(|j| (0..cols).map(move |i| (i, j)))
                .map(|(i, j)| at(i as f64, j as f64))
                .collect();
            proptest::prop_assert_eq!(lattice_members(&lattice).len(), lattice.len());

            let side = (12.0 * pitch) as usize;
            let mut skin = crate::test_fixtures::hex_points(side, side, pitch);
            // A site of the row above the top row, half a pitch along from
            // a top-row marker: its two members lie 60 degrees apart.
            let top = skin[skin.len().min(7) / 2];
            let beyond = PointPx::new(top.x + 0.5 * pitch, top.y - 0.866 * pitch);
            let neighbours = skin
                .iter()
                .filter(|p| (p.x - beyond.x).hypot(p.y - beyond.y) <= 1.5 * pitch)
                .count();
            proptest::prop_assert_eq!(neighbours, 2);
            skin.push(beyond);
            let kept = lattice_members(&skin);
            proptest::prop_assert!(!kept.contains(&(skin.len() - 1)), "{:?} kept", beyond);
        }
    }
}
