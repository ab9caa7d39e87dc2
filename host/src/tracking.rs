//! Beyond the paper: marker tracking against the rest frame.
//!
//! Each rest marker is matched to the nearest detected marker within half a
//! marker pitch; the matched pairs give the displacement (shear) field, the
//! unmatched rest markers are "lost". A marker has *moved* when it is lost or
//! displaced by more than the noise level. The pipeline uses this to skip the
//! density stages when nothing moved, to restrict the density to a region
//! around the moved markers, and to find contacts too small to dent the
//! density. [`radial_centre`] finds the point the displacements radiate
//! from: the least-squares intersection of the lines through each rest
//! marker along its displacement, weighted by `|u|^2` and robustly
//! re-weighted by the residual.

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
    /// Indexes `points` inside a `width x height` frame (points outside are
    /// clamped to the border cells; non-finite ones are skipped).
    pub fn new(points: &[PointPx], width: usize, height: usize, cell_px: f64) -> Self {
        let cell_px = cell_px.max(1.0);
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

    /// Index and distance of the point nearest to `q` within `radius_px`
    /// (`radius_px` must not exceed the cell size).
    pub fn nearest(&self, points: &[PointPx], q: PointPx, radius_px: f64) -> Option<(usize, f64)> {
        if !q.is_finite() {
            return None;
        }
        // Truncation toward zero differs from floor only in (-1, 0), where
        // the 3x3 search still covers the right cells.
        let ci = (q.x / self.cell_px) as i64;
        let cj = (q.y / self.cell_px) as i64;
        let r2 = radius_px * radius_px;
        let mut best: Option<(usize, f64)> = None;
        for j in (cj - 1).max(0)..=(cj + 1).min(self.ny as i64 - 1) {
            for i in (ci - 1).max(0)..=(ci + 1).min(self.nx as i64 - 1) {
                let c = j as usize * self.nx + i as usize;
                for &n in &self.items[self.starts[c] as usize..self.starts[c + 1] as usize] {
                    let p = points[n as usize];
                    let d2 = (p.x - q.x).powi(2) + (p.y - q.y).powi(2);
                    if d2 <= r2 && best.is_none_or(|(_, bd)| d2 < bd) {
                        best = Some((n as usize, d2));
                    }
                }
            }
        }
        best.map(|(n, d2)| (n, d2.sqrt()))
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
}

/// Matches `current` markers to the `rest` markers (see the module doc).
pub fn track(
    rest: &[PointPx],
    current: &[PointPx],
    width: usize,
    height: usize,
    search_px: f64,
    noise_px: f64,
) -> Field {
    let index = PointIndex::new(current, width, height, search_px);
    let mut field = Field {
        displacement: Vec::with_capacity(rest.len()),
        moved: Vec::new(),
        lost: 0,
    };
    for (n, &r) in rest.iter().enumerate() {
        match index.nearest(current, r, search_px) {
            Some((k, d)) => {
                let c = current[k];
                field
                    .displacement
                    .push(Some(PointPx::new(c.x - r.x, c.y - r.y)));
                if d > noise_px {
                    field.moved.push(n);
                }
            }
            None => {
                field.displacement.push(None);
                field.lost += 1;
                field.moved.push(n);
            }
        }
    }
    field
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
    /// Lines passing within [`INLIER_PX`] of the centre.
    pub n_inliers: usize,
    /// Share of the `|u|^2` weight carried by the inliers (0..=1).
    pub inlier_share: f64,
}

/// Least-squares radial centre of the displaced markers `selected` (indices
/// into `rest`). `None` with fewer than 2 usable markers or (near-)parallel
/// displacements.
pub fn radial_centre(
    rest: &[PointPx],
    field: &Field,
    selected: &[usize],
    noise_px: f64,
) -> Option<RadialFit> {
    let lines: Vec<(PointPx, PointPx, f64)> = selected
        .iter()
        .filter_map(|&n| {
            let u = (*field.displacement.get(n)?)?;
            let len = u.x.hypot(u.y);
            (len > noise_px && len.is_finite())
                .then(|| (rest[n], PointPx::new(u.x / len, u.y / len), len * len))
        })
        .collect();
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
            *w = w0 / (1.0 + (r / 2.0).powi(2));
        }
        centre = Some(c);
    }
    let c = centre?;
    let (mut sw, mut si, mut sr, mut ni) = (0.0, 0.0, 0.0, 0);
    for (p, n, w) in &lines {
        let r = line_distance(*p, *n, c);
        sw += w;
        if r <= INLIER_PX {
            si += w;
            sr += w * r * r;
            ni += 1;
        }
    }
    let fit = RadialFit {
        centre: c,
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
    fn parallel_or_too_few_displacements_give_no_centre() {
        let rest = test_fixtures::hex_points(100, 100, 15.0);
        let cur: Vec<PointPx> = rest.iter().map(|p| PointPx::new(p.x + 2.0, p.y)).collect();
        let field = track(&rest, &cur, 100, 100, 7.5, 0.3);
        assert!(radial_centre(&rest, &field, &field.moved, 0.3).is_none());
        assert!(radial_centre(&rest, &field, &field.moved[..1], 0.3).is_none());
        assert!(radial_centre(&rest, &field, &[], 0.3).is_none());
    }
}
