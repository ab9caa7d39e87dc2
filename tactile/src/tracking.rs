//! Beyond the paper: marker tracking against the rest frame.
//!
//! Each rest marker is matched to the nearest detected marker within half a
//! marker pitch; the matched pairs give the displacement (shear) field, the
//! unmatched rest markers are "lost". A marker has *moved* when it is lost or
//! displaced by more than the noise level. The noise level is measured on
//! each frame ([`track_adaptive`]): the marker jitter sigma (per axis) is
//! estimated from the lower quartile of the displacements of all matched
//! markers (a contact moves fewer than three quarters of them; for isotropic
//! Gaussian jitter `|u|` is Rayleigh distributed), and a marker moved when
//! `|u|` exceeds `max(floor, z sigma)`. At z = 6 a Gaussian marker exceeds
//! it with probability `exp(-18) = 1.5e-8`, so the threshold sits just above
//! the noise of the frame: a quiet sensor sees the sub-pixel ring around a
//! tiny contact, a noisy one does not report its noise. Real jitter has
//! heavier tails (the rest frame's own noise is frozen into the reference,
//! rim markers are dimmer), so the pipeline only looks at a frame when some
//! marker moved *strongly* ([`crate::contact::worth_a_look`]).
//!
//! The pipeline uses the field to skip the density stages when nothing moved
//! strongly, to restrict the density to a region around the strongly moved
//! markers, and to find contacts too small to dent the density.
//! [`radial_centre`] finds the point the displacements radiate from: the
//! least-squares intersection of the lines through each rest marker along its
//! displacement, weighted by `|u|^2` and robustly re-weighted by the
//! residual; [`radial_centre_noisy`] lets weak displacements take part with
//! a tolerance that follows their direction uncertainty.

use crate::numeric::{collect_bounded, norm, select_f64};
use crate::surface::Surface;
use crate::PointPx;

/// A displacement line passing within this distance of the fitted centre is
/// an inlier, px.
pub const INLIER_PX: f64 = 2.0;

/// Uniform-grid spatial index of points (cell = search radius).
#[derive(Debug, Clone)]
pub struct PointIndex {
    cell_px: f64,
    nx: usize,
    ny: usize,
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl PointIndex {
    /// Most grid cells per indexed point.
    pub const CELLS_PER_POINT: usize = 4;

    /// Indexes `points` inside a `width x height` frame (points outside are
    /// clamped to the border cells; non-finite ones are skipped). The cells
    /// are `cell_px` wide, or wider where that would make more than
    /// [`PointIndex::CELLS_PER_POINT`] cells per point: a small search
    /// radius then costs no frame-sized grid to clear (measured: building
    /// the index was 9 % of a domed frame's work with 4 px cells).
    pub fn new(points: &[PointPx], width: usize, height: usize, cell_px: f64) -> Self {
        let fewest_px =
            ((width * height) as f64 / (Self::CELLS_PER_POINT * points.len().max(1)) as f64).sqrt();
        let cell_px = cell_px.max(fewest_px).max(1.0);
        let nx = ((width as f64 / cell_px).ceil() as usize).max(1);
        let ny = ((height as f64 / cell_px).ceil() as usize).max(1);
        let mut counts = vec![0u32; nx * ny + 1];
        let cell_of = |p: &PointPx| -> Option<usize> {
            if !p.is_finite() {
                return None;
            }
            // `as usize` saturates negatives to 0 and truncates (= floor for >= 0).
            let i = ((p.x / cell_px) as usize).min(nx - 1);
            let j = ((p.y / cell_px) as usize).min(ny - 1);
            Some(j * nx + i)
        };
        for c in points.iter().filter_map(cell_of) {
            counts[c + 1] += 1;
        }
        for k in 1..counts.len() {
            counts[k] += counts[k - 1];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; counts[nx * ny] as usize];
        for (n, p) in points.iter().enumerate() {
            if let Some(c) = cell_of(p) {
                items[fill[c] as usize] = n as u32;
                fill[c] += 1;
            }
        }
        Self {
            cell_px,
            nx,
            ny,
            starts: counts,
            items,
        }
    }

    /// [`PointIndex::new`] over the box from the origin to the farthest of
    /// `points` (a point set with no frame of its own, such as the rest
    /// markers).
    pub fn spanning(points: &[PointPx], cell_px: f64) -> Self {
        let (mut w, mut h) = (1.0f64, 1.0f64);
        for p in points.iter().filter(|p| p.is_finite()) {
            w = w.max(p.x + 1.0);
            h = h.max(p.y + 1.0);
        }
        Self::new(points, w as usize, h as usize, cell_px)
    }

    /// Index and distance of the point nearest to `q` within `radius_px`
    /// (`radius_px` must not exceed the cell size).
    pub fn nearest(&self, points: &[PointPx], q: PointPx, radius_px: f64) -> Option<(usize, f64)> {
        self.nearest_but(points, q, radius_px, usize::MAX)
    }

    /// [`PointIndex::nearest`] to point `n` among the others.
    pub fn nearest_other(
        &self,
        points: &[PointPx],
        n: usize,
        radius_px: f64,
    ) -> Option<(usize, f64)> {
        self.nearest_but(points, *points.get(n)?, radius_px, n)
    }

    /// Every point within `radius_px` of `q` (`radius_px` must not exceed
    /// the cell size): index and squared distance, in no order.
    pub fn within<'a>(
        &'a self,
        points: &'a [PointPx],
        q: PointPx,
        radius_px: f64,
    ) -> impl Iterator<Item = (usize, f64)> + 'a {
        let (cols, rows) = self.cells_around(q);
        Within {
            index: self,
            points,
            q,
            r2: radius_px * radius_px,
            i: cols.start,
            cols,
            rows,
            at: 0,
            end: 0,
        }
    }

    /// The cells of the 3x3 around `q`'s cell that lie in the grid: the
    /// column and row ranges (empty for a non-finite `q`). Truncation toward
    /// zero differs from floor only in (-1, 0), where the 3x3 still covers
    /// the right cells.
    fn cells_around(&self, q: PointPx) -> (std::ops::Range<usize>, std::ops::Range<usize>) {
        if !q.is_finite() {
            return (0..0, 0..0);
        }
        let span = |c: i64, n: usize| {
            let end = c.saturating_add(2).clamp(0, n as i64) as usize;
            (c.saturating_sub(1).max(0) as usize)..end
        };
        (
            span((q.x / self.cell_px) as i64, self.nx),
            span((q.y / self.cell_px) as i64, self.ny),
        )
    }

    fn nearest_but(
        &self,
        points: &[PointPx],
        q: PointPx,
        radius_px: f64,
        skip: usize,
    ) -> Option<(usize, f64)> {
        // `within`, written out as loops: the iterator chain cost 5x the
        // instructions on this hot path (search and tracking).
        let (cols, rows) = self.cells_around(q);
        let mut best: Option<(usize, f64)> = None;
        for j in rows {
            for i in cols.clone() {
                let c = j * self.nx + i;
                let (a, b) = (self.starts[c] as usize, self.starts[c + 1] as usize);
                for &n in &self.items[a..b] {
                    let n = n as usize;
                    let p = points[n];
                    let d2 = (p.x - q.x).powi(2) + (p.y - q.y).powi(2);
                    if n != skip
                        && d2 <= radius_px * radius_px
                        && best.is_none_or(|(_, b2)| d2 < b2)
                    {
                        best = Some((n, d2));
                    }
                }
            }
        }
        best.map(|(n, d2)| (n, d2.sqrt()))
    }
}

/// [`PointIndex::within`]'s points: the cells of the 3x3 row by row, each
/// cell's points in turn. Written out: the chain of `flat_map`s it replaced
/// cost about 740 instructions a call in the local search (4.5 % of its
/// instructions on the other renderer's nominal frames).
struct Within<'a> {
    index: &'a PointIndex,
    points: &'a [PointPx],
    q: PointPx,
    r2: f64,
    cols: std::ops::Range<usize>,
    rows: std::ops::Range<usize>,
    /// The next column of the current row (`rows.start`).
    i: usize,
    /// The current cell's items still to look at.
    at: usize,
    end: usize,
}

impl Iterator for Within<'_> {
    type Item = (usize, f64);

    fn next(&mut self) -> Option<(usize, f64)> {
        loop {
            while self.at < self.end {
                let n = self.index.items[self.at] as usize;
                self.at += 1;
                let p = self.points[n];
                let d2 = (p.x - self.q.x).powi(2) + (p.y - self.q.y).powi(2);
                if d2 <= self.r2 {
                    return Some((n, d2));
                }
            }
            if self.i >= self.cols.end {
                self.rows.next()?;
                self.i = self.cols.start;
                continue;
            }
            if self.rows.is_empty() {
                return None;
            }
            let c = self.rows.start * self.index.nx + self.i;
            self.i += 1;
            (self.at, self.end) = (
                self.index.starts[c] as usize,
                self.index.starts[c + 1] as usize,
            );
        }
    }
}

/// The displacement field of one frame against the rest markers.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Field {
    /// Per rest marker: its displacement, px, or `None` when lost.
    pub displacement: Vec<Option<PointPx>>,
    /// Indices of rest markers that moved beyond noise or were lost.
    pub moved: Vec<usize>,
    /// Number of lost rest markers.
    pub lost: usize,
    /// Estimated marker jitter of this frame, px (per-axis sigma; 0 with
    /// a fixed threshold, see [`track`]).
    pub jitter_px: f64,
    /// The displacement beyond which a marker counted as moved, px.
    pub moved_px: f64,
}

/// Quantile of the displacement magnitudes used by [`jitter_sigma_px`]: a
/// press may move most markers of a sensor (a large contact moves about
/// half), the quietest quarter is noise.
pub const JITTER_QUANTILE: f64 = 0.25;

/// Per-axis sigma of isotropic Gaussian marker jitter estimated from the
/// matched markers' displacements: `|u|` is Rayleigh distributed, whose
/// [`JITTER_QUANTILE`] quantile is `sigma sqrt(-2 ln(1 - q))`. 0 with no
/// matched marker.
pub fn jitter_sigma_px(displacement: &[Option<PointPx>]) -> f64 {
    let sq = collect_bounded(displacement.iter().filter_map(|u| {
        let u = (*u)?;
        Some(u.x * u.x + u.y * u.y).filter(|v| v.is_finite())
    }));
    let k = ((sq.len() as f64 * JITTER_QUANTILE) as usize).min(sq.len().saturating_sub(1));
    select_f64(sq, k).map_or(0.0, |q| rayleigh_sigma_px(q, JITTER_QUANTILE))
}

/// The per-axis sigma of isotropic Gaussian jitter whose magnitude's `q`
/// quantile, squared, is `quantile_sq_px2`: the Rayleigh quantile is
/// `sigma sqrt(-2 ln(1 - q))`.
pub fn rayleigh_sigma_px(quantile_sq_px2: f64, q: f64) -> f64 {
    (quantile_sq_px2 / (-2.0 * (1.0 - q).ln())).sqrt()
}

/// Matches `current` markers to the `rest` markers (see the module doc)
/// with a fixed noise threshold `noise_px`.
pub fn track(
    rest: &[PointPx],
    current: &[PointPx],
    width: usize,
    height: usize,
    search_px: f64,
    noise_px: f64,
) -> Field {
    let mut field = match_rest(rest, current, width, height, search_px);
    mark_moved(&mut field, noise_px);
    field
}

/// Matches `current` markers to the `rest` markers; a marker moved when it
/// is lost or displaced by more than `max(floor_px, sigmas * jitter)`, with
/// the jitter estimated on this frame ([`jitter_sigma_px`]).
pub fn track_adaptive(
    rest: &[PointPx],
    current: &[PointPx],
    width: usize,
    height: usize,
    search_px: f64,
    floor_px: f64,
    sigmas: f64,
) -> Field {
    let field = match_rest(rest, current, width, height, search_px);
    mark_moved_adaptive(field, floor_px, sigmas)
}

/// [`track_adaptive`] for markers whose rest marker is known, `(rest index,
/// position)` (followed markers, [`crate::markers::follow`]): no matching
/// is needed; a rest marker without one is lost.
pub fn track_known_adaptive(
    rest: &[PointPx],
    known: impl IntoIterator<Item = (usize, PointPx)>,
    floor_px: f64,
    sigmas: f64,
) -> Field {
    let mut field = Field {
        displacement: vec![None; rest.len()],
        ..Field::default()
    };
    for (n, p) in known {
        if let Some(r) = rest.get(n) {
            field.displacement[n] = Some(PointPx::new(p.x - r.x, p.y - r.y));
        }
    }
    field.lost = field.displacement.iter().filter(|u| u.is_none()).count();
    mark_moved_adaptive(field, floor_px, sigmas)
}

/// `field` with its jitter raised to `jitter_px` when that is more, and its
/// moved markers marked again as [`track_known_adaptive`] marks them.
pub fn with_jitter_at_least(field: Field, jitter_px: f64, floor_px: f64, sigmas: f64) -> Field {
    if jitter_px > field.jitter_px {
        with_jitter(field, jitter_px, floor_px, sigmas)
    } else {
        field
    }
}

fn mark_moved_adaptive(field: Field, floor_px: f64, sigmas: f64) -> Field {
    let jitter_px = jitter_sigma_px(&field.displacement);
    with_jitter(field, jitter_px, floor_px, sigmas)
}

/// `field` with jitter `jitter_px`, its markers moved beyond
/// `max(floor_px, sigmas x jitter_px)`.
fn with_jitter(mut field: Field, jitter_px: f64, floor_px: f64, sigmas: f64) -> Field {
    field.jitter_px = jitter_px;
    // `max` ignores a NaN product (sigmas is validated finite anyway).
    mark_moved(&mut field, floor_px.max(sigmas * jitter_px));
    field
}

fn match_rest(
    rest: &[PointPx],
    current: &[PointPx],
    width: usize,
    height: usize,
    search_px: f64,
) -> Field {
    let index = PointIndex::new(current, width, height, search_px);
    let mut field = Field {
        displacement: Vec::with_capacity(rest.len()),
        ..Field::default()
    };
    for &r in rest {
        let u = index
            .nearest(current, r, search_px)
            .map(|(k, _)| PointPx::new(current[k].x - r.x, current[k].y - r.y));
        field.lost += usize::from(u.is_none());
        field.displacement.push(u);
    }
    field
}

fn mark_moved(field: &mut Field, threshold_px: f64) {
    field.moved_px = threshold_px;
    let t2 = threshold_px * threshold_px;
    field.moved = field
        .displacement
        .iter()
        .enumerate()
        // A lost marker moved; so did a NaN one.
        .filter(|(_, u)| {
            u.is_none_or(|u| {
                let d2 = u.x * u.x + u.y * u.y;
                d2 > t2 || d2.is_nan()
            })
        })
        .map(|(n, _)| n)
        .collect();
}

/// A centre found from the displacement field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadialFit {
    /// The point the displacements radiate from, working px.
    pub centre: PointPx,
    /// RMS distance of the inlier lines from the centre, px.
    pub residual_px: f64,
    /// Markers that took part.
    pub n_markers: usize,
    /// Lines passing within their tolerance of the centre ([`INLIER_PX`],
    /// more for weak displacements with [`radial_centre_noisy`]).
    pub n_inliers: usize,
    /// Share of the `|u|^2` weight carried by the inliers (0..=1).
    pub inlier_share: f64,
}

/// Least-squares radial centre of the displaced markers `selected` (indices
/// into `rest`). `None` with fewer than 2 usable markers or (near-)parallel
/// displacements. Same as [`radial_centre_noisy`] with no jitter (a line is
/// an inlier within [`INLIER_PX`]).
pub fn radial_centre(
    rest: &[PointPx],
    field: &Field,
    selected: &[usize],
    noise_px: f64,
) -> Option<RadialFit> {
    radial_centre_noisy(rest, field, selected, noise_px, 0.0)
}

/// A line counts as an inlier when it passes within `max(INLIER_PX,
/// INLIER_SIGMAS * jitter * r / |u|)` of the centre: the direction of a
/// displacement `u` measured with per-axis jitter sigma is uncertain by
/// about `sigma / |u|` rad, which moves the line by that times the distance
/// `r` from the marker to the centre.
pub const INLIER_SIGMAS: f64 = 3.0;

/// [`radial_centre`] for markers whose positions have per-axis jitter
/// `jitter_px`: weak displacements (a few sigma) take part with a tolerance
/// that grows with their direction uncertainty ([`INLIER_SIGMAS`]).
pub fn radial_centre_noisy(
    rest: &[PointPx],
    field: &Field,
    selected: &[usize],
    noise_px: f64,
    jitter_px: f64,
) -> Option<RadialFit> {
    radial_centre_on(&Surface::Flat, rest, field, selected, noise_px, jitter_px)
}

/// [`radial_centre_noisy`] on a skin of shape `surface`: each displacement
/// line runs from the rest marker's chart point towards its displaced
/// position's chart point ([`Surface::to_chart`], where a dome's great
/// circles are straight), with its weight and noise test on the image
/// displacement; the centre is met in the chart and mapped back to the
/// image. The residual is in chart px.
pub fn radial_centre_on(
    surface: &Surface,
    rest: &[PointPx],
    field: &Field,
    selected: &[usize],
    noise_px: f64,
    jitter_px: f64,
) -> Option<RadialFit> {
    let lines: Vec<(PointPx, PointPx, f64)> = selected
        .iter()
        .filter_map(|&n| {
            let u = (*field.displacement.get(n)?)?;
            let len = norm(u.x, u.y);
            if !(len > noise_px && len.is_finite()) {
                return None;
            }
            let p = *rest.get(n)?;
            let (a, (dx, dy)) = match surface {
                Surface::Flat => (p, (u.x, u.y)),
                Surface::Dome(_) => {
                    let a = surface.to_chart(p);
                    let b = surface.to_chart(PointPx::new(p.x + u.x, p.y + u.y));
                    (a, (b.x - a.x, b.y - a.y))
                }
            };
            let d = norm(dx, dy);
            (d > 0.0 && d.is_finite()).then(|| (a, PointPx::new(dx / d, dy / d), len * len))
        })
        .collect();
    let jitter_px = if jitter_px.is_finite() {
        jitter_px.max(0.0)
    } else {
        0.0
    };
    // Inlier tolerance of a line through `p` with weight |u|^2 at centre `c`.
    let tolerance = |p: PointPx, w: f64, c: PointPx| -> f64 {
        let r = norm(c.x - p.x, c.y - p.y);
        INLIER_PX.max(INLIER_SIGMAS * jitter_px * r / w.sqrt())
    };
    if lines.len() < 2 {
        return None;
    }
    let mut weights: Vec<f64> = lines.iter().map(|l| l.2).collect();
    let mut centre = None;
    for _ in 0..4 {
        let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for ((p, n, _), &w) in lines.iter().zip(&weights) {
            // Projector onto the line normal: I - n n^T.
            let (m11, m12, m22) = (1.0 - n.x * n.x, -n.x * n.y, 1.0 - n.y * n.y);
            a11 += w * m11;
            a12 += w * m12;
            a22 += w * m22;
            b1 += w * (m11 * p.x + m12 * p.y);
            b2 += w * (m12 * p.x + m22 * p.y);
        }
        let det = a11 * a22 - a12 * a12;
        let trace = a11 + a22;
        // Also rejects NaN: the comparison is false.
        let well_posed = det > 1e-6 * trace * trace;
        if !well_posed {
            return None;
        }
        let c = PointPx::new((a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det);
        for ((p, n, w0), w) in lines.iter().zip(weights.iter_mut()) {
            let r = line_distance(*p, *n, c);
            *w = w0 / (1.0 + (r / tolerance(*p, *w0, c)).powi(2));
        }
        centre = Some(c);
    }
    let c = centre?;
    let (mut sw, mut si, mut sr, mut ni) = (0.0, 0.0, 0.0, 0);
    for (p, n, w) in &lines {
        let r = line_distance(*p, *n, c);
        sw += w;
        // A press pushes markers away from its centre.
        let outward = (p.x - c.x) * n.x + (p.y - c.y) * n.y > 0.0;
        if outward && r <= tolerance(*p, *w, c) {
            si += w;
            sr += w * r * r;
            ni += 1;
        }
    }
    let fit = RadialFit {
        centre: surface.from_chart(c),
        residual_px: if si > 0.0 {
            (sr / si).sqrt()
        } else {
            f64::INFINITY
        },
        n_markers: lines.len(),
        n_inliers: ni,
        inlier_share: si / sw,
    };
    fit.centre.is_finite().then_some(fit)
}

/// Distance of `c` from the line through `p` with unit direction `n`.
fn line_distance(p: PointPx, n: PointPx, c: PointPx) -> f64 {
    ((c.x - p.x) * n.y - (c.y - p.y) * n.x).abs()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::Press;
    use crate::test_fixtures;

    #[test]
    fn a_jitter_floor_marks_the_moved_markers_again() {
        let rest = vec![
            PointPx::new(10.0, 10.0),
            PointPx::new(40.0, 10.0),
            PointPx::new(70.0, 10.0),
        ];
        let known = [
            (0, PointPx::new(10.1, 10.0)),
            (1, PointPx::new(40.0, 10.9)),
            (2, PointPx::new(70.0, 12.0)),
        ];
        let field = track_known_adaptive(&rest, known, 0.5, 6.0);
        assert_eq!(field.moved, vec![1, 2]);
        // A floor below the frame's own jitter changes nothing.
        let same = with_jitter_at_least(field.clone(), 0.0, 0.5, 6.0);
        assert_eq!(same, field);
        // 0.2 px: moved beyond 1.2 px.
        let raised = with_jitter_at_least(field, 0.2, 0.5, 6.0);
        assert_eq!((raised.jitter_px, raised.moved_px), (0.2, 6.0 * 0.2));
        assert_eq!(raised.moved, vec![2]);
    }

    #[test]
    fn nearest_finds_the_closest_within_radius() {
        let pts = [
            PointPx::new(10.0, 10.0),
            PointPx::new(14.0, 10.0),
            PointPx::new(30.0, 30.0),
        ];
        let idx = PointIndex::new(&pts, 40, 40, 7.0);
        assert_eq!(
            idx.nearest(&pts, PointPx::new(13.0, 10.0), 7.0).unwrap().0,
            1
        );
        assert!(idx.nearest(&pts, PointPx::new(22.0, 22.0), 7.0).is_none());
        assert!(idx
            .nearest(&pts, PointPx::new(f64::NAN, 1.0), 7.0)
            .is_none());
    }

    #[test]
    fn radial_field_points_back_to_the_press() {
        let rest = test_fixtures::hex_points(200, 200, 15.0);
        let press = Press {
            centre: PointPx::new(97.3, 104.6),
            width_px: 6.0,
            strength: 0.8,
            shear_px: PointPx::new(0.0, 0.0),
            flat_radius_px: 0.0,
        };
        let cur: Vec<PointPx> = rest
            .iter()
            .map(|&p| {
                let u = press.displacement(p);
                PointPx::new(p.x + u.x, p.y + u.y)
            })
            .collect();
        let field = track(&rest, &cur, 200, 200, 7.5, 0.3);
        assert!(!field.moved.is_empty());
        let fit = radial_centre(&rest, &field, &field.moved, 0.3).unwrap();
        let err = (fit.centre.x - 97.3).hypot(fit.centre.y - 104.6);
        assert!(err < 0.05, "{fit:?}");
    }

    #[test]
    fn on_a_dome_the_chart_removes_the_foreshortening_bias() {
        use crate::surface::{Dome, Surface};
        let centre = PointPx::new(320.0, 240.0);
        let dome = crate::synth::Dome {
            radius_px: 230.0,
            rim_polar_rad: 65f64.to_radians(),
        };
        let surface = Surface::Dome(Dome {
            centre,
            radius_px: 230.0,
        });
        // A press at polar angle 50 deg: markers within 40 px of arc move
        // away from it along great circles, by up to 3 px of arc.
        let c = [
            50f64.to_radians().sin() * 0.6,
            50f64.to_radians().sin() * 0.8,
            50f64.to_radians().cos(),
        ];
        let truth = dome.project(centre, crate::synth::DomePoint(c));
        let rest: Vec<PointPx> = test_fixtures::hex_points(640, 480, 12.0)
            .into_iter()
            .filter(|p| (p.x - centre.x).hypot(p.y - centre.y) < dome.rim_radius_px())
            .collect();
        let cur: Vec<PointPx> = rest
            .iter()
            .map(|&p| {
                use crate::synth::{cross, dot, normalized, rotate};
                let m = dome.lift(centre, p).0;
                let g = 230.0 * dot(m, c).clamp(-1.0, 1.0).acos();
                // About the axis from c towards m: away from the press.
                match normalized(cross(c, m)) {
                    Some(k) if g <= 40.0 => {
                        let angle = 3.0 * (-(g * g) / (2.0 * 15.0 * 15.0)).exp() / 230.0;
                        dome.project(centre, crate::synth::DomePoint(rotate(m, k, angle)))
                    }
                    _ => p,
                }
            })
            .collect();
        let field = track(&rest, &cur, 640, 480, 6.0, 0.05);
        assert!(field.moved.len() > 10, "{}", field.moved.len());
        let err = |s: &Surface| {
            let fit = radial_centre_on(s, &rest, &field, &field.moved, 0.05, 0.0).unwrap();
            (fit.centre.x - truth.x).hypot(fit.centre.y - truth.y)
        };
        let (flat, charted) = (err(&Surface::Flat), err(&surface));
        assert!(charted < 0.05, "dome chart: {charted} px off");
        assert!(flat > 10.0 * charted, "flat {flat} px, chart {charted} px");
    }

    #[test]
    fn parallel_or_too_few_displacements_give_no_centre() {
        let rest = test_fixtures::hex_points(100, 100, 15.0);
        let cur: Vec<PointPx> = rest.iter().map(|p| PointPx::new(p.x + 2.0, p.y)).collect();
        let field = track(&rest, &cur, 100, 100, 7.5, 0.3);
        assert!(radial_centre(&rest, &field, &field.moved, 0.3).is_none());
        assert!(radial_centre(&rest, &field, &field.moved[..1], 0.3).is_none());
        assert!(radial_centre(&rest, &field, &[], 0.3).is_none());
    }

    /// `n` displacements of Gaussian jitter `sigma` per axis.
    fn jitter_field(n: usize, sigma: f64, seed: u64) -> Vec<Option<PointPx>> {
        let mut rng = crate::synth::Rng::new(seed);
        (0..n)
            .map(|_| Some(PointPx::new(sigma * rng.normal(), sigma * rng.normal())))
            .collect()
    }

    #[test]
    fn jitter_of_nothing_is_zero_and_non_finite_is_ignored() {
        assert_eq!(jitter_sigma_px(&[]), 0.0);
        assert_eq!(jitter_sigma_px(&[None, None]), 0.0);
        let mut d = jitter_field(400, 0.05, 3);
        d.push(Some(PointPx::new(f64::NAN, 0.0)));
        d.push(Some(PointPx::new(f64::INFINITY, 1.0)));
        d.push(None);
        let s = jitter_sigma_px(&d);
        assert!((s - 0.05).abs() < 0.01, "{s}");
    }

    proptest::proptest! {
        /// `within` lists exactly the points a scan of all of them finds
        /// within the radius (points off the frame and at its corners too),
        /// and `nearest` finds the nearest of them.
        #[test]
        fn within_and_nearest_find_what_a_full_scan_finds(
            pts in proptest::collection::vec((-5.0f64..45.0, -5.0f64..45.0), 0..60),
            q in (-5.0f64..45.0, -5.0f64..45.0),
            radius in 0.5f64..7.0,
        ) {
            let pts: Vec<PointPx> = pts.into_iter().map(|(x, y)| PointPx::new(x, y)).collect();
            let q = PointPx::new(q.0, q.1);
            let idx = PointIndex::new(&pts, 40, 40, 7.0);
            let mut got: Vec<usize> = idx.within(&pts, q, radius).map(|(n, _)| n).collect();
            got.sort_unstable();
            let want: Vec<usize> = (0..pts.len())
                .filter(|&n| (pts[n].x - q.x).powi(2) + (pts[n].y - q.y).powi(2) <= radius * radius)
                .collect();
            proptest::prop_assert_eq!(&got, &want);
            // `nearest` is the nearest of them (the first of equals).
            let d2 = |n: usize| (pts[n].x - q.x).powi(2) + (pts[n].y - q.y).powi(2);
            let nearest = idx.nearest(&pts, q, radius).map(|(n, _)| d2(n));
            let scanned = want.iter().map(|&n| d2(n)).min_by(f64::total_cmp);
            proptest::prop_assert_eq!(nearest, scanned);
        }

        #[test]
        fn jitter_estimate_recovers_sigma_despite_a_press(
            sigma in 0.002f64..0.5,
            pressed in 0usize..60,
            seed in proptest::prelude::any::<u64>(),
        ) {
            // 600 markers with Gaussian jitter, up to 10 % of them moved by
            // a press (1-5 px) or lost: the estimate stays within 25 %.
            let mut d = jitter_field(600, sigma, seed);
            for (k, u) in d.iter_mut().take(pressed).enumerate() {
                *u = if k % 5 == 0 { None } else { Some(PointPx::new(1.0 + k as f64 * 0.07, -2.0)) };
            }
            let s = jitter_sigma_px(&d);
            proptest::prop_assert!((s / sigma - 1.0).abs() < 0.25, "sigma {} estimate {}", sigma, s);
        }

        #[test]
        fn adaptive_threshold_follows_the_noise_and_keeps_the_floor(
            sigma in 0.0f64..0.2,
            seed in proptest::prelude::any::<u64>(),
        ) {
            let rest = test_fixtures::hex_points(300, 300, 15.0);
            let noise = jitter_field(rest.len(), sigma, seed);
            let cur: Vec<PointPx> = rest
                .iter()
                .zip(&noise)
                .map(|(p, u)| {
                    let u = u.unwrap_or_default();
                    PointPx::new(p.x + u.x, p.y + u.y)
                })
                .collect();
            let f = track_adaptive(&rest, &cur, 300, 300, 7.5, 0.1, 6.0);
            proptest::prop_assert!(f.moved_px >= 0.1);
            proptest::prop_assert!((f.moved_px - (6.0 * f.jitter_px).max(0.1)).abs() < 1e-12);
            proptest::prop_assert_eq!(f.lost, 0);
            // Gaussian jitter beyond ~4.5 sigma (the threshold is 6 sigma of
            // the estimate, which is within 25 % of sigma) is rarer than
            // 1e-4 per marker: at most a few of ~350 markers.
            proptest::prop_assert!(f.moved.len() <= 3, "{} moved, {:?}", f.moved.len(), f.moved_px);
        }

        /// Markers that know their rest marker give the field matching
        /// would give (each within a third of the pitch of its rest place),
        /// and a rest marker without one is lost.
        #[test]
        fn known_rest_markers_give_the_matched_field(
            sigma in 0.0f64..1.5,
            gone in 0usize..300,
            seed in proptest::prelude::any::<u64>(),
        ) {
            let rest = test_fixtures::hex_points(300, 300, 15.0);
            let noise = jitter_field(rest.len(), sigma, seed);
            let cur: Vec<(usize, PointPx)> = rest
                .iter()
                .zip(&noise)
                .enumerate()
                .filter(|&(k, _)| k != gone)
                .map(|(k, (p, u))| {
                    let u = u.unwrap_or_default();
                    (k, PointPx::new(p.x + u.x.clamp(-4.0, 4.0), p.y + u.y.clamp(-4.0, 4.0)))
                })
                .collect();
            let positions: Vec<PointPx> = cur.iter().map(|&(_, p)| p).collect();
            let matched = track_adaptive(&rest, &positions, 300, 300, 7.5, 0.1, 6.0);
            let known = track_known_adaptive(&rest, cur.iter().copied(), 0.1, 6.0);
            proptest::prop_assert_eq!(known.lost, usize::from(gone < rest.len()));
            if gone >= rest.len() {
                proptest::prop_assert_eq!(&known.displacement, &matched.displacement);
                proptest::prop_assert_eq!(&known.moved, &matched.moved);
            } else {
                proptest::prop_assert!(known.displacement[gone].is_none());
                proptest::prop_assert!(known.moved.contains(&gone));
            }
        }
    }
}
