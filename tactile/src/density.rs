//! Stage 3, kernel density of the markers (Sec. III-B, Eq. 1), in markers
//! per mm^2:
//!
//! `d(x, y) = sum_m 1/(2 pi h^2) exp(-((x - x_m)^2 + (y - y_m)^2) / 2h^2) / s^2`
//!
//! with `s` mm per px. This is the normalised 2-D Gaussian (SPEC section 3);
//! the paper's `1/(M sqrt(2 pi) h^2)` prefactor is not used.
//!
//! Two implementations behind one entry point, [`estimate`]:
//! - **exact** (reference): f64, every pixel, every marker, no truncation.
//!   The Gaussian factorises, `exp(-(dx^2+dy^2)/2h^2) = gx(x) gy(y)`, so each
//!   pixel costs one multiply-add per marker instead of one `exp` (the same
//!   value up to rounding; checked against the direct formula in the tests).
//! - **fast**: f32 on a grid of `step` px (samples at block centres), kernel
//!   truncated at `truncate_sigmas * h`, and only inside a region of interest
//!   (the cells around moved markers; see [`crate::pipeline`]). Its
//!   difference from the exact reference is measured in the tests and in
//!   BENCHMARKS.md.

use crate::numeric::{ceil_i64, floor_i64};
use crate::params::DensityMode;
use crate::surface::Dome;
use crate::PointPx;

/// A regular sampling grid over the working frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Grid {
    /// Spacing of the samples, px.
    pub step_px: usize,
    /// Samples across.
    pub nx: usize,
    /// Samples down.
    pub ny: usize,
}

impl Grid {
    /// The grid of `step_px` covering a `width x height` frame.
    pub fn new(width: usize, height: usize, step_px: usize) -> Self {
        let step_px = step_px.max(1);
        Self {
            step_px,
            nx: width.div_ceil(step_px),
            ny: height.div_ceil(step_px),
        }
    }

    /// Working-frame coordinate of sample index `i` (block centre).
    pub fn coord(&self, i: f64) -> f64 {
        i * self.step_px as f64 + (self.step_px as f64 - 1.0) / 2.0
    }

    /// Working-frame point of cell `(i, j)` plus a fractional offset.
    pub fn point(&self, i: f64, j: f64) -> PointPx {
        PointPx::new(self.coord(i), self.coord(j))
    }

    /// Working-frame point of the cell at row-major index `k`.
    pub fn point_of(&self, k: usize) -> PointPx {
        self.point((k % self.nx) as f64, (k / self.nx) as f64)
    }

    /// All cells.
    pub fn full(&self) -> CellRect {
        CellRect {
            i0: 0,
            j0: 0,
            i1: self.nx,
            j1: self.ny,
        }
    }

    /// Cells whose sample lies within the working-px box `[x0, x1] x [y0, y1]`.
    pub fn cells_within(&self, x0: f64, y0: f64, x1: f64, y1: f64) -> CellRect {
        let off = (self.step_px as f64 - 1.0) / 2.0;
        let s = self.step_px as f64;
        // Integer rounding: no libm call per marker. (A NaN bound gives no
        // cells.)
        let lo = |v: f64, n: usize| (ceil_i64((v - off) / s).max(0) as usize).min(n);
        let hi = |v: f64, n: usize| match (v - off) / s {
            c if c.is_nan() => 0,
            c => (floor_i64(c).saturating_add(1).max(0) as usize).min(n),
        };
        CellRect {
            i0: lo(x0, self.nx),
            j0: lo(y0, self.ny),
            i1: hi(x1, self.nx),
            j1: hi(y1, self.ny),
        }
    }
}

/// A rectangle of grid cells `[i0, i1) x [j0, j1)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CellRect {
    /// First column.
    pub i0: usize,
    /// First row.
    pub j0: usize,
    /// One past the last column.
    pub i1: usize,
    /// One past the last row.
    pub j1: usize,
}

impl CellRect {
    /// Number of cells (0 when empty).
    pub fn area(&self) -> usize {
        self.i1.saturating_sub(self.i0) * self.j1.saturating_sub(self.j0)
    }

    /// True when `(i, j)` is inside.
    pub fn contains(&self, i: usize, j: usize) -> bool {
        i >= self.i0 && i < self.i1 && j >= self.j0 && j < self.j1
    }
}

/// Density samples on a grid, markers per mm^2. Only cells inside `roi` were
/// computed; the others are 0.
#[derive(Debug, Clone, PartialEq)]
pub struct DensityMap {
    /// The grid.
    pub grid: Grid,
    /// The computed cells.
    pub roi: CellRect,
    /// Row-major `grid.nx * grid.ny` values, markers per mm^2.
    pub values_per_mm2: Vec<f32>,
}

impl DensityMap {
    /// Value at cell `(i, j)`.
    pub fn at(&self, i: usize, j: usize) -> f32 {
        self.values_per_mm2[j * self.grid.nx + i]
    }
}

/// Everything the density stage needs besides the markers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DensitySetup {
    /// Working frame width, px.
    pub width: usize,
    /// Working frame height, px.
    pub height: usize,
    /// Kernel width h, px.
    pub h_px: f64,
    /// mm per working px.
    pub mm_per_px: f64,
    /// Implementation.
    pub mode: DensityMode,
    /// Fast path grid step, px (the exact path always uses 1).
    pub step_px: usize,
    /// Fast path truncation radius, units of h.
    pub truncate_sigmas: f64,
    /// The dome whose skin the fast path's kernel is isotropic on
    /// ([`crate::params::DensityKernel::Skin`]); `None`: in the image. The
    /// exact path (the image kernel's reference) ignores it; a config
    /// cannot ask for both.
    pub skin: Option<Dome>,
}

impl DensitySetup {
    /// The grid this setup samples on.
    pub fn grid(&self) -> Grid {
        match self.mode {
            DensityMode::Exact => Grid::new(self.width, self.height, 1),
            DensityMode::Fast => Grid::new(self.width, self.height, self.step_px),
        }
    }
}

/// Stage 3 entry: the density of `markers` on `setup.grid()`, computed inside
/// `roi` (all cells for `None`). Non-finite marker positions are ignored.
pub fn estimate(markers: &[PointPx], setup: &DensitySetup, roi: Option<CellRect>) -> DensityMap {
    let grid = setup.grid();
    let roi = roi.unwrap_or(grid.full());
    match setup.mode {
        DensityMode::Exact => {
            let exact = exact(
                markers,
                setup.width,
                setup.height,
                setup.h_px,
                setup.mm_per_px,
            );
            DensityMap {
                grid,
                roi: grid.full(),
                values_per_mm2: exact.into_iter().map(|v| v as f32).collect(),
            }
        }
        DensityMode::Fast => fast(markers, grid, roi, setup),
    }
}

/// The reference density at every pixel of a `width x height` frame, f64,
/// row-major, markers per mm^2 (no truncation).
pub fn exact(
    markers: &[PointPx],
    width: usize,
    height: usize,
    h_px: f64,
    mm_per_px: f64,
) -> Vec<f64> {
    let norm = 1.0 / (std::f64::consts::TAU * h_px * h_px * mm_per_px * mm_per_px);
    let inv = 1.0 / (2.0 * h_px * h_px);
    let mut out = vec![0f64; width * height];
    let mut gx = vec![0f64; width];
    let mut gy = vec![0f64; height];
    for m in markers.iter().filter(|m| m.is_finite()) {
        for (x, g) in gx.iter_mut().enumerate() {
            let d = x as f64 - m.x;
            *g = (-d * d * inv).exp();
        }
        for (y, g) in gy.iter_mut().enumerate() {
            let d = y as f64 - m.y;
            *g = norm * (-d * d * inv).exp();
        }
        for (row, &fy) in out.chunks_exact_mut(width).zip(&gy) {
            if fy == 0.0 {
                continue;
            }
            for (v, &fx) in row.iter_mut().zip(&gx) {
                *v += fy * fx;
            }
        }
    }
    out
}

/// The reference density at one point, f64, markers per mm^2: Eq. 1 with the
/// normalised Gaussian, written out literally (every marker, no
/// factorisation, no truncation).
pub fn exact_at(markers: &[PointPx], p: PointPx, h_px: f64, mm_per_px: f64) -> f64 {
    let norm = 1.0 / (std::f64::consts::TAU * h_px * h_px * mm_per_px * mm_per_px);
    markers
        .iter()
        .filter(|m| m.is_finite())
        .map(|m| {
            let r2 = (p.x - m.x).powi(2) + (p.y - m.y).powi(2);
            norm * (-r2 / (2.0 * h_px * h_px)).exp()
        })
        .sum()
}

/// The fast path: f32, grid, truncated kernel, ROI only.
fn fast(markers: &[PointPx], grid: Grid, roi: CellRect, setup: &DensitySetup) -> DensityMap {
    if let Some(dome) = &setup.skin {
        return fast_on_skin(markers, grid, roi, setup, dome);
    }
    let n = grid.nx * grid.ny;
    // `ROW_LANES` spare cells past the end: a window's rows are added
    // `ROW_LANES` cells at a time (see below).
    let mut values = vec![0f32; n + ROW_LANES];
    let h = setup.h_px;
    let norm = 1.0 / (std::f64::consts::TAU * h * h * setup.mm_per_px * setup.mm_per_px);
    let inv = 1.0 / (2.0 * h * h);
    let step = grid.step_px as f64;
    // exp(-2 step^2 inv): the ratio of successive ratios of a sampled
    // Gaussian (see `gaussian_samples`).
    let ratio_step = (-2.0 * step * step * inv).exp();
    let reach = setup.truncate_sigmas * h;
    let mut gx = Vec::new();
    let mut gy = Vec::new();
    // The working-px box whose markers reach the ROI: a marker outside it
    // is skipped by four compares (a small ROI has few of the frame's
    // markers near it).
    let (bx0, by0) = (
        grid.coord(roi.i0 as f64) - reach,
        grid.coord(roi.j0 as f64) - reach,
    );
    let (bx1, by1) = (
        grid.coord(roi.i1 as f64 - 1.0) + reach,
        grid.coord(roi.j1 as f64 - 1.0) + reach,
    );
    for m in markers
        .iter()
        .filter(|m| m.x >= bx0 && m.x <= bx1 && m.y >= by0 && m.y <= by1)
    {
        let win = grid.cells_within(m.x - reach, m.y - reach, m.x + reach, m.y + reach);
        let win = CellRect {
            i0: win.i0.max(roi.i0),
            j0: win.j0.max(roi.j0),
            i1: win.i1.min(roi.i1),
            j1: win.j1.min(roi.j1),
        };
        if win.area() == 0 {
            continue;
        }
        let d0x = grid.coord(win.i0 as f64) - m.x;
        gaussian_samples(&mut gx, d0x, step, win.i1 - win.i0, inv, ratio_step, 1.0);
        let d0y = grid.coord(win.j0 as f64) - m.y;
        gaussian_samples(&mut gy, d0y, step, win.j1 - win.j0, inv, ratio_step, norm);
        if gx.len() <= ROW_LANES {
            // A fixed-width row (the default kernel and step: 12 cells)
            // unrolls and vectorises; the lanes past the window add 0.0 to
            // the cells after it (the next ones of its row, or the next
            // row's first, or the spare cells), which leaves them as they
            // were.
            let mut fx = [0f32; ROW_LANES];
            fx[..gx.len()].copy_from_slice(&gx);
            for (j, &fy) in (win.j0..win.j1).zip(&gy) {
                let at = j * grid.nx + win.i0;
                if let Some(row) = values.get_mut(at..at + ROW_LANES) {
                    for (v, &f) in row.iter_mut().zip(&fx) {
                        *v += fy * f;
                    }
                }
            }
        } else {
            for (j, &fy) in (win.j0..win.j1).zip(&gy) {
                let row = &mut values[j * grid.nx + win.i0..j * grid.nx + win.i1];
                for (v, &fx) in row.iter_mut().zip(&gx) {
                    *v += fy * fx;
                }
            }
        }
    }
    values.truncate(n);
    DensityMap {
        grid,
        roi,
        values_per_mm2: values,
    }
}

/// [`fast`] with the kernel isotropic on `dome`'s skin: the distance between
/// a cell's sample and a marker is the chord between their points on the
/// sphere (the arc to 0.2 % within 3 h of 15 px on a sphere of 260 px),
/// times its radius, so one kernel width covers the same skin at the apex
/// and at the foreshortened rim; the values are markers per mm^2 of skin
/// (mm per px as at the apex). Not separable: one `exp` per cell and marker
/// within reach. Orthographic, the image distance between two points is at
/// most their chord, so the markers within `truncate_sigmas h` on the skin
/// are among those that close in the image.
fn fast_on_skin(
    markers: &[PointPx],
    grid: Grid,
    roi: CellRect,
    setup: &DensitySetup,
    dome: &Dome,
) -> DensityMap {
    let mut values = vec![0f32; grid.nx * grid.ny];
    let h = setup.h_px;
    // In f32, as the fast path's values (libm's expf is about twice as fast
    // as exp; the chords are differences of unit vectors, far above f32's
    // resolution).
    let norm = (1.0 / (std::f64::consts::TAU * h * h * setup.mm_per_px * setup.mm_per_px)) as f32;
    // Squared chords on the unit sphere to the exponent.
    let inv = (dome.radius_px * dome.radius_px / (2.0 * h * h)) as f32;
    let reach = setup.truncate_sigmas * h;
    let cut = (0.5 * setup.truncate_sigmas * setup.truncate_sigmas) as f32;
    let width = roi.i1.saturating_sub(roi.i0);
    let lift = |p: PointPx| dome.lift(p).map(|v| v as f32);
    let lifted: Vec<[f32; 3]> = (roi.j0..roi.j1)
        .flat_map(|j| (roi.i0..roi.i1).map(move |i| (i, j)))
        .map(|(i, j)| lift(grid.point(i as f64, j as f64)))
        .collect();
    for m in markers.iter().filter(|m| m.is_finite()) {
        let win = grid.cells_within(m.x - reach, m.y - reach, m.x + reach, m.y + reach);
        let (i0, i1) = (win.i0.max(roi.i0), win.i1.min(roi.i1));
        let (j0, j1) = (win.j0.max(roi.j0), win.j1.min(roi.j1));
        if i0 >= i1 || j0 >= j1 {
            continue;
        }
        let q = lift(*m);
        for j in j0..j1 {
            let row = &lifted[(j - roi.j0) * width..][..width];
            let out = &mut values[j * grid.nx..][..grid.nx];
            for i in i0..i1 {
                let c = row[i - roi.i0];
                let (dx, dy, dz) = (c[0] - q[0], c[1] - q[1], c[2] - q[2]);
                let e = (dx * dx + dy * dy + dz * dz) * inv;
                if e <= cut {
                    out[i] += norm * (-e).exp();
                }
            }
        }
    }
    DensityMap {
        grid,
        roi,
        values_per_mm2: values,
    }
}

/// Cells of a density window's row added at once by [`fast`].
const ROW_LANES: usize = 16;

/// Fills `out` with `scale exp(-(d0 + k step)^2 inv)` for `k` in `0..n`,
/// with two `exp` calls instead of `n`: successive samples of a Gaussian
/// differ by the ratio `exp(-(2 d step + step^2) inv)`, and successive
/// ratios by `ratio_step` = `exp(-2 step^2 inv)`. In f64 the products drift
/// by about `n` ulps (measured against the direct formula in the tests);
/// the samples are stored as f32. Where a ratio underflows to 0 the
/// samples after it are 0, as the direct formula's would be in f32.
fn gaussian_samples(
    out: &mut Vec<f32>,
    d0: f64,
    step: f64,
    n: usize,
    inv: f64,
    ratio_step: f64,
    scale: f64,
) {
    out.clear();
    let mut g = scale * (-d0 * d0 * inv).exp();
    let mut ratio = (-(2.0 * d0 * step + step * step) * inv).exp();
    for _ in 0..n {
        out.push(g as f32);
        g *= ratio;
        ratio *= ratio_step;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_fixtures;

    #[test]
    fn on_a_dome_the_skins_kernel_sees_markers_even_on_the_skin_as_even() {
        // Markers evenly spread over the sphere (a Fibonacci lattice, about
        // 12 px apart on a sphere of 260 px), out to 60 deg from the apex.
        let dome = Dome {
            centre: PointPx::new(320.0, 240.0),
            radius_px: 260.0,
        };
        let n = 6800;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let markers: Vec<PointPx> = (0..n)
            .filter_map(|i| {
                let z = 1.0 - (2 * i + 1) as f64 / n as f64;
                let (r, phi) = ((1.0 - z * z).sqrt(), i as f64 * golden);
                (z >= 0.5).then(|| {
                    PointPx::new(
                        dome.centre.x + dome.radius_px * r * phi.cos(),
                        dome.centre.y + dome.radius_px * r * phi.sin(),
                    )
                })
            })
            .collect();
        let image = DensitySetup {
            width: 640,
            height: 480,
            h_px: 15.0,
            mm_per_px: 0.1,
            mode: DensityMode::Fast,
            step_px: 4,
            truncate_sigmas: 3.0,
            skin: None,
        };
        let skin = DensitySetup {
            skin: Some(dome),
            ..image
        };
        // The apex and a point 40 deg from it (its kernel's reach ends at
        // 50 deg, inside the markers).
        let rim_x = dome.centre.x + dome.radius_px * 40f64.to_radians().sin();
        let at = |map: &DensityMap, x: f64| {
            let c = map.grid.cells_within(x, 240.0, x, 240.0);
            map.at(c.i0, c.j0) as f64
        };
        let per_mm2 = n as f64 / (4.0 * std::f64::consts::PI * (260.0f64 * 0.1).powi(2));
        let on_skin = estimate(&markers, &skin, None);
        for x in [dome.centre.x, rim_x] {
            let v = at(&on_skin, x);
            assert!(
                (v / per_mm2 - 1.0).abs() < 0.03,
                "at x {x}: {v:.4} / {per_mm2:.4}"
            );
        }
        // The image's kernel counts the foreshortened rim's markers per image
        // area: 1 / cos(40 deg) = 1.31 times the apex's.
        let in_image = estimate(&markers, &image, None);
        let ratio = at(&in_image, rim_x) / at(&in_image, dome.centre.x);
        assert!(
            (ratio - 1.0 / 40f64.to_radians().cos()).abs() < 0.05,
            "{ratio:.3}"
        );
    }

    #[test]
    fn gaussian_samples_match_the_direct_formula() {
        // Kernel widths from a tenth of the step to fifteen steps, windows of
        // 3 h either side, any sub-step offset.
        let mut out = Vec::new();
        for &(h, step) in &[
            (15.0, 8.0),
            (15.0, 1.0),
            (2.0, 8.0),
            (0.8, 8.0),
            (80.0, 8.0),
        ] {
            let inv: f64 = 1.0 / (2.0 * h * h);
            let n = (6.0 * h / step).ceil() as usize + 2;
            for k in 0..7 {
                let d0 = -3.0 * h - step * k as f64 / 7.0;
                gaussian_samples(
                    &mut out,
                    d0,
                    step,
                    n,
                    inv,
                    (-2.0 * step * step * inv).exp(),
                    2.5,
                );
                for (i, &got) in out.iter().enumerate() {
                    let d = d0 + i as f64 * step;
                    let want = (2.5 * (-d * d * inv).exp()) as f32;
                    assert!(
                        (got - want).abs() <= 1e-6 * want.max(1e-30) + 1e-37,
                        "h {h} step {step} d0 {d0} i {i}: {got} vs {want}"
                    );
                }
            }
        }
    }

    fn direct(markers: &[PointPx], x: f64, y: f64, h: f64, s: f64) -> f64 {
        exact_at(markers, PointPx::new(x, y), h, s)
    }

    fn setup(w: usize, h: usize, mode: DensityMode, step: usize) -> DensitySetup {
        DensitySetup {
            width: w,
            height: h,
            h_px: 15.0,
            mm_per_px: 0.1,
            mode,
            step_px: step,
            truncate_sigmas: 3.0,
            skin: None,
        }
    }

    #[test]
    fn separable_exact_equals_the_direct_formula() {
        let markers = test_fixtures::hex_points(80, 60, 15.0);
        let d = exact(&markers, 80, 60, 15.0, 0.1);
        for &(x, y) in &[(0usize, 0usize), (40, 30), (79, 59), (13, 47)] {
            let want = direct(&markers, x as f64, y as f64, 15.0, 0.1);
            let got = d[y * 80 + x];
            assert!(
                (got - want).abs() <= 1e-12 * want.max(1e-300),
                "{got} vs {want}"
            );
        }
    }

    #[test]
    fn one_marker_integrates_to_one_marker() {
        let m = [PointPx::new(50.0, 50.0)];
        let d = exact(&m, 101, 101, 6.0, 0.1);
        let total: f64 = d.iter().sum::<f64>() * 0.1 * 0.1;
        assert!((total - 1.0).abs() < 1e-6, "{total}");
    }

    #[test]
    fn hex_grid_interior_density_is_one_per_cell_area() {
        let markers = test_fixtures::hex_points(200, 200, 15.0);
        let d = exact(&markers, 200, 200, 15.0, 0.1);
        let cell_mm2 = 15.0 * 15.0 * 3f64.sqrt() / 2.0 * 0.01;
        let v = d[100 * 200 + 100];
        assert!((v * cell_mm2 - 1.0).abs() < 0.01, "{}", v * cell_mm2);
    }

    #[test]
    fn fast_path_stays_close_to_exact() {
        let markers = test_fixtures::hex_points(160, 120, 15.0);
        let ex = exact(&markers, 160, 120, 15.0, 0.1);
        let peak = ex.iter().cloned().fold(0.0, f64::max);
        for step in [1usize, 2, 4, 8] {
            let s = setup(160, 120, DensityMode::Fast, step);
            let f = estimate(&markers, &s, None);
            let mut worst: f64 = 0.0;
            for j in 0..f.grid.ny {
                for i in 0..f.grid.nx {
                    let p = f.grid.point(i as f64, j as f64);
                    let want = direct(&markers, p.x, p.y, 15.0, 0.1);
                    worst = worst.max((f.at(i, j) as f64 - want).abs());
                }
            }
            // Truncation at 3 h drops < 1.2 % of a kernel's mass.
            assert!(worst < 0.012 * peak, "step {step}: {worst} vs peak {peak}");
        }
    }

    #[test]
    fn roi_limits_the_work_and_matches_inside() {
        let markers = test_fixtures::hex_points(160, 120, 15.0);
        let s = setup(160, 120, DensityMode::Fast, 4);
        let full = estimate(&markers, &s, None);
        let roi = CellRect {
            i0: 10,
            j0: 5,
            i1: 20,
            j1: 15,
        };
        let part = estimate(&markers, &s, Some(roi));
        // Every cell inside, its border too (markers outside the ROI reach
        // it), is the full map's, to the bit.
        for j in roi.j0..roi.j1 {
            for i in roi.i0..roi.i1 {
                assert_eq!(part.at(i, j), full.at(i, j), "cell ({i}, {j})");
            }
        }
        assert_eq!(part.at(2, 2), 0.0);
    }

    #[test]
    fn row_lanes_past_a_window_change_nothing() {
        // Step 8, h 15: windows of 12 cells, added `ROW_LANES` at a time.
        // Markers at the frame's corners and edges, a ROI that ends inside
        // the rows: every cell is the window-by-window sum to the bit, and
        // the cells outside the ROI stay 0.
        let mut markers = test_fixtures::hex_points(160, 120, 15.0);
        markers.extend([
            PointPx::new(159.5, 119.5),
            PointPx::new(0.0, 119.0),
            PointPx::new(159.0, 0.0),
        ]);
        let s = setup(160, 120, DensityMode::Fast, 8);
        let grid = s.grid();
        let roi = CellRect {
            i0: 3,
            j0: 2,
            i1: 17,
            j1: grid.ny,
        };
        let map = estimate(&markers, &s, Some(roi));
        let inv = 1.0 / (2.0 * s.h_px * s.h_px);
        let norm = 1.0 / (std::f64::consts::TAU * s.h_px * s.h_px * s.mm_per_px * s.mm_per_px);
        let reach = s.truncate_sigmas * s.h_px;
        let ratio_step = (-2.0 * 64.0 * inv).exp();
        let mut want = vec![0f32; grid.nx * grid.ny];
        let (mut gx, mut gy) = (Vec::new(), Vec::new());
        for m in &markers {
            let w = grid.cells_within(m.x - reach, m.y - reach, m.x + reach, m.y + reach);
            let (i0, j0) = (w.i0.max(roi.i0), w.j0.max(roi.j0));
            let (i1, j1) = (w.i1.min(roi.i1), w.j1.min(roi.j1));
            if i0 >= i1 || j0 >= j1 {
                continue;
            }
            let d0x = grid.coord(i0 as f64) - m.x;
            gaussian_samples(&mut gx, d0x, 8.0, i1 - i0, inv, ratio_step, 1.0);
            let d0y = grid.coord(j0 as f64) - m.y;
            gaussian_samples(&mut gy, d0y, 8.0, j1 - j0, inv, ratio_step, norm);
            assert!(gx.len() <= ROW_LANES);
            for j in j0..j1 {
                for i in i0..i1 {
                    want[j * grid.nx + i] += gy[j - j0] * gx[i - i0];
                }
            }
        }
        assert_eq!(map.values_per_mm2, want);
        for j in 0..grid.ny {
            for i in roi.i1..grid.nx {
                assert_eq!(map.at(i, j), 0.0, "cell ({i}, {j})");
            }
        }
    }

    #[test]
    fn grid_cells_within_is_clamped() {
        let g = Grid::new(640, 480, 4);
        assert_eq!((g.nx, g.ny), (160, 120));
        assert_eq!(g.coord(0.0), 1.5);
        let r = g.cells_within(-100.0, -100.0, 1e9, 1e9);
        assert_eq!(r, g.full());
        let e = g.cells_within(1e9, 1e9, 2e9, 2e9);
        assert_eq!(e.area(), 0);
        let n = g.cells_within(f64::NAN, 0.0, 10.0, 10.0);
        assert!(n.area() <= g.full().area());
    }
}
