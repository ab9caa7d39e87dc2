//! Stages 4-5, contact (Sec. III-B, Eq. 2): the contact region R is the
//! largest 4-connected region of low density inside the sensing mask, the
//! contact centre is the argmin over R, refined to sub-pixel by a parabola
//! through the neighbouring samples in x and in y. Under the default
//! relative rule the centre is instead R's centroid, each sample weighted
//! by its depth up to half of R's ([`DENT_WEIGHT_CAP`]): the dent's walls
//! place it, not its lowest sample.
//!
//! "Low density" is either the paper's absolute rule, `d < T` (markers per
//! mm^2), or the default relative rule `d < t d_rest` with the rest density
//! at the same sample; the relative rule also takes the argmin of
//! `d / d_rest`, which removes the bias of the density fall-off at the rim
//! (SPEC section 3; measured in BENCHMARKS.md). Under the relative rule a
//! region grows from its samples below `t` through the connected samples
//! below `relative_extent` (hysteresis): a flat punch dents the density in a
//! shallow ring, which one threshold cuts into arcs. Regions whose samples
//! below `t` cover less than `min_area_mm2` are not contacts.
//!
//! With [`CentreMethod::Hybrid`] the centre comes from the tracked markers
//! around the region ([`crate::tracking::radial_centre_on`], in the chart of
//! a domed skin, [`crate::surface`]; those displaced by at most
//! [`FIT_MAX_MOVE_PITCH`]) when that fit is consistent, and
//! contacts too small to dent the density (width below ~h) are found from
//! the tracked markers alone, and so are wide contacts too shallow to dent
//! it (a flat punch pressed a little: a ring of moved markers around a still
//! centre). Centroids are taken on the skin ([`SurfaceMean`]) with the
//! rim's cells counting less ([`rim_trust`]).
//!
//! ```
//! use dexitac_tactile::contact::{segment, DensityReference, Region};
//! use dexitac_tactile::density::{DensityMap, Grid};
//! use dexitac_tactile::params::{ContactParams, ThresholdMode};
//! // A 5x5 density map (step 1) with a dent at (3, 2); rest density 1.
//! let grid = Grid::new(5, 5, 1);
//! let mut v = vec![1.0f32; 25];
//! v[2 * 5 + 3] = 0.2;
//! v[2 * 5 + 2] = 0.6;
//! let map = DensityMap { grid, roi: grid.full(), values_per_mm2: v };
//! let rest = DensityMap { grid, roi: grid.full(), values_per_mm2: vec![1.0; 25] };
//! let reference = DensityReference::flat(&rest, &[true; 25]);
//! // The relative rule (default): the centroid, the two samples 0.7 and
//! // 0.3 below the extent 0.9, the first weight capped at 0.35.
//! let params = ContactParams { min_area_mm2: 0.0, ..ContactParams::default() };
//! let r: Region = segment(&map, &reference, &params, 1.0).unwrap();
//! assert_eq!(r.cells, 2);
//! assert!((r.centre.x - (3.0 * 0.35 + 2.0 * 0.3) / 0.65).abs() < 1e-3);
//! // The paper's absolute rule: the lowest sample, refined.
//! let params = ContactParams {
//!     threshold: ThresholdMode::Absolute,
//!     absolute_threshold_per_mm2: 0.8,
//!     ..params
//! };
//! let r = segment(&map, &reference, &params, 1.0).unwrap();
//! assert!((r.centre.x - 3.0).abs() < 0.5 && (r.centre.y - 2.0).abs() < 0.5);
//! ```

use crate::density::DensityMap;
use crate::numeric::{collect_bounded, norm, select_f64};
use crate::params::{CentreMethod, ContactParams, ThresholdMode};
use crate::surface::{Surface, SurfaceMean};
use crate::tracking::{self, Field};
use crate::PointPx;

/// The contact region found in a density map.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Region {
    /// The region's centre, working px: under the relative rule its
    /// centroid on the skin with capped depth weights ([`DENT_WEIGHT_CAP`],
    /// unless the mask cuts it); otherwise, and under the paper's absolute
    /// rule, the sub-pixel argmin of the score
    /// over it, or for a region wider than [`CENTROID_RADIUS_H`] kernel
    /// widths, or one that encloses skin, its depth-weighted centroid; for
    /// a ring ([`RING_SHARE`]) the centroid of its disc.
    pub centre: PointPx,
    /// Grid cells in the region, the ones it encloses included.
    pub cells: usize,
    /// Of `cells`, those the region encloses without being low itself: the
    /// skin under a flat press, inside the ring its edge opens (see
    /// [`RING_SHARE`]); 0 for a dent.
    pub enclosed_cells: usize,
    /// Region area, mm^2.
    pub area_mm2: f64,
    /// Lowest score (density / rest, or density per mm^2).
    pub depth: f32,
}

/// What a frame's density map is compared with, all from the calibration.
#[derive(Debug, Clone, Copy)]
pub struct DensityReference<'a> {
    /// The rest density, on the frame map's grid.
    pub rest: &'a DensityMap,
    /// The sensing mask on the same grid (row-major).
    pub mask: &'a [bool],
    /// The skin's shape: a wide region's centroid is taken on it
    /// ([`SurfaceMean`]).
    pub surface: &'a Surface,
    /// Median rest density on the skin over the mask (the density times
    /// the skin's foreshortening, [`Surface::foreshortening`]), markers per
    /// mm^2: a region's cells count less where their rest density on the
    /// skin falls below it ([`rim_trust`]). 0 turns that off.
    pub rest_median_per_mm2: f32,
    /// The densities are per mm^2 of skin already (the kernel on the skin,
    /// [`crate::params::DensityKernel::Skin`]), not per image mm^2 to be
    /// taken onto the skin by the foreshortening.
    pub on_skin: bool,
}

impl<'a> DensityReference<'a> {
    /// A flat skin with no rim weighting: the rest density and mask alone.
    pub fn flat(rest: &'a DensityMap, mask: &'a [bool]) -> Self {
        Self {
            rest,
            mask,
            surface: &Surface::Flat,
            rest_median_per_mm2: 0.0,
            on_skin: false,
        }
    }
}

/// Weight of a cell in a region's centroid by its rest density on the skin
/// `rest` against the median `median`: 1 at or above the median, falling
/// linearly to 0 at half of it. Where the marker lattice ends (the rim, the
/// fall-off of the kernel beyond the last ring) the rest density drops
/// steeply, and its ratio to the frame's density swings with small shifts of
/// the outer markers, which a press near the rim crowds and merges. Measured
/// on the other renderer's rim contacts (BENCHMARKS.md, session 15): without
/// it the centroid on the dome ran outwards, 3.63 px median against 2.94
/// with it.
///
/// The density compared is the one on the skin (the image density times the
/// foreshortening `cos(theta)`): a dome's image packs more markers per pixel
/// towards its rim, and its apex fewer than the median, which is no fall-off.
/// For markers evenly on a dome to 60 degrees, the image density fully
/// trusts only 56 % of the cells within 80 % of its radius, the density on
/// the skin all of them (`calibrate`'s test
/// `a_domes_rest_density_is_trusted_across_its_skin`): a press's cells
/// nearer the rim weighed more, and its centroid moved outwards
/// (BENCHMARKS.md, session 31).
pub fn rim_trust(rest: f32, median: f32) -> f64 {
    if !(median > 0.0 && median.is_finite()) {
        return 1.0;
    }
    let f = (rest / median) as f64;
    if f.is_nan() {
        return 0.0;
    }
    ((f - RIM_TRUST_FLOOR) / (1.0 - RIM_TRUST_FLOOR)).clamp(0.0, 1.0)
}

/// Rest density (fraction of the median) at and below which a cell has no
/// weight in a wide region's centroid ([`rim_trust`]). Measured at 0.3, 0.5
/// and 0.65: rim contacts 3.22 / 2.94 / 2.50 px median, large ones 1.51 /
/// 1.75 / 1.95 (the cut eats into a wide contact's outer side).
pub const RIM_TRUST_FLOOR: f64 = 0.5;

/// Where a contact's centre came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// Argmin of the density over the region.
    Density,
    /// Radial centre of the tracked markers around a density region with
    /// lost markers.
    DensityTracked,
    /// Tracked markers alone (contact too small for the density).
    Tracking,
}

impl Source {
    /// Short name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Source::Density => "density",
            Source::DensityTracked => "density+tracking",
            Source::Tracking => "tracking",
        }
    }
}

/// A contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// Contact centre, working px.
    pub centre: PointPx,
    /// Contact area, mm^2 (for tracking-only contacts: the disc through the
    /// median moved marker).
    pub area_mm2: f64,
    /// How the centre was found.
    pub source: Source,
}

/// One connected region of [`segment`]'s flood fill: its cells below the
/// threshold, its lowest cell and score (its cells are kept beside it).
struct Flood {
    cells: usize,
    low: (usize, usize),
    depth: f32,
}

/// Stage 4 entry: the largest low-density region of `map` (inside its ROI and
/// the mask), or `None` when there is none of at least `min_area_mm2`;
/// without one, under the relative rule, a band below the extent that
/// encloses skin (a flat press's ring, [`RING_SHARE`]).
/// The reference's rest density and mask are on the same grid as `map`.
pub fn segment(
    map: &DensityMap,
    reference: &DensityReference,
    params: &ContactParams,
    mm_per_px: f64,
) -> Option<Region> {
    segment_supported(map, reference, params, mm_per_px, &[])
}

/// [`segment`] among the regions that reach a cell of `support` (row-major
/// on the map's grid, [`support_cells`]; empty: every region counts).
pub fn segment_supported(
    map: &DensityMap,
    reference: &DensityReference,
    params: &ContactParams,
    mm_per_px: f64,
    support: &[bool],
) -> Option<Region> {
    let DensityReference {
        rest,
        mask,
        surface,
        rest_median_per_mm2,
        on_skin,
    } = *reference;
    let g = map.grid;
    let roi = map.roi;
    let n = g.nx * g.ny;
    if rest.values_per_mm2.len() != n || mask.len() != n || roi.area() == 0 {
        return None;
    }
    let score = |i: usize, j: usize| -> f32 {
        let k = j * g.nx + i;
        match params.threshold {
            ThresholdMode::Relative => {
                map.values_per_mm2[k] / rest.values_per_mm2[k].max(f32::MIN_POSITIVE)
            }
            ThresholdMode::Absolute => map.values_per_mm2[k],
        }
    };
    let limit = match params.threshold {
        ThresholdMode::Relative => params.relative_threshold as f32,
        ThresholdMode::Absolute => params.absolute_threshold_per_mm2 as f32,
    };
    // Hysteresis (relative rule): a region is seeded below `limit` and grows
    // through samples below `extent`. The paper's absolute rule has none.
    let extent = match params.threshold {
        ThresholdMode::Relative => (params.relative_extent as f32).max(limit),
        ThresholdMode::Absolute => limit,
    };
    // `is_lt` is false for NaN: a NaN sample is never in a region.
    let below = |i: usize, j: usize, l: f32| score(i, j).partial_cmp(&l).is_some_and(|o| o.is_lt());
    let usable = |i: usize, j: usize| roi.contains(i, j) && mask[j * g.nx + i];
    let mut seen = vec![false; n];
    let mut stack = Vec::new();
    // One connected region through the samples below `extent` from
    // `(i, j)`: its cells, the count below `limit`, whether it reaches a
    // support cell, and its lowest cell and score.
    let mut flood = |i: usize, j: usize, cells: &mut Vec<(usize, usize)>, seen: &mut [bool]| {
        seen[j * g.nx + i] = true;
        stack.push((i, j));
        let mut count = 0;
        let mut supported = support.is_empty();
        let mut low = ((i, j), score(i, j));
        cells.clear();
        while let Some((ci, cj)) = stack.pop() {
            let s = score(ci, cj);
            if s < limit {
                count += 1;
            }
            supported = supported || support.get(cj * g.nx + ci).copied().unwrap_or(false);
            cells.push((ci, cj));
            if s < low.1 {
                low = ((ci, cj), s);
            }
            for (ni, nj) in four_neighbours(ci, cj) {
                if ni < g.nx && nj < g.ny && usable(ni, nj) {
                    let nk = nj * g.nx + ni;
                    if !seen[nk] && below(ni, nj, extent) {
                        seen[nk] = true;
                        stack.push((ni, nj));
                    }
                }
            }
        }
        (count, supported, low)
    };
    let mut best: Option<Flood> = None;
    // The cells of the flood under way and of the best one so far.
    let (mut flood_cells, mut best_cells) = (Vec::new(), Vec::new());
    for j in roi.j0..roi.j1 {
        for i in roi.i0..roi.i1 {
            let k = j * g.nx + i;
            if seen[k] || !usable(i, j) || !below(i, j, limit) {
                continue;
            }
            let (count, supported, low) = flood(i, j, &mut flood_cells, &mut seen);
            if supported && best.as_ref().is_none_or(|b| count > b.cells) {
                best = Some(Flood {
                    cells: count,
                    low: low.0,
                    depth: low.1,
                });
                std::mem::swap(&mut flood_cells, &mut best_cells);
            }
        }
    }
    let step = g.step_px as f64;
    let cell_mm2 = step * step * mm_per_px * mm_per_px;
    // A flat press wider than the kernel leaves the skin under it in place
    // and opens a ring of low density at its edge: a region that encloses
    // skin ([`ring_holes`], counted from a disc one kernel width across) is
    // a ring when that is at least [`RING_SHARE`] of its cells, and then
    // the disc it bounds. A region that encloses skin is one even when
    // none of its cells lies below the threshold, if no other is: a
    // closed band around skin at rest is no noise (on the other renderer's
    // wide punches its cells lay at 0.80-0.90 of rest, BENCHMARKS.md,
    // session 24).
    let min_hole_cells =
        (0.25 * std::f64::consts::PI * params_reach_cells(map).powi(2)).ceil() as usize;
    // (The paper's absolute rule keeps its regions as they are.)
    let relative = params.threshold == ThresholdMode::Relative;
    let enclosure = |flood: &[(usize, usize)]| {
        let holes = if relative {
            ring_holes(flood, &usable, min_hole_cells)
        } else {
            Vec::new()
        };
        let ring = !holes.is_empty() && holes.len() as f64 >= RING_SHARE * flood.len() as f64;
        (holes, ring)
    };
    let (mut holes, mut ring) = (Vec::new(), false);
    if let Some(b) = &mut best {
        (holes, ring) = enclosure(&best_cells);
        // A ring's cells are its disc's; a dent's, those below the
        // threshold and the few it encloses.
        b.cells = if ring { best_cells.len() } else { b.cells } + holes.len();
    }
    if relative
        && best
            .as_ref()
            .is_none_or(|b| (b.cells as f64) * cell_mm2 < params.min_area_mm2)
    {
        for j in roi.j0..roi.j1 {
            for i in roi.i0..roi.i1 {
                let k = j * g.nx + i;
                if seen[k] || !usable(i, j) || !below(i, j, extent) {
                    continue;
                }
                let (_, supported, low) = flood(i, j, &mut flood_cells, &mut seen);
                let (inside, is_ring) = enclosure(&flood_cells);
                // Its cells: the band and what it encloses.
                let disc = flood_cells.len() + inside.len();
                if supported && !inside.is_empty() && best.as_ref().is_none_or(|b| disc > b.cells) {
                    best = Some(Flood {
                        cells: disc,
                        low: low.0,
                        depth: low.1,
                    });
                    std::mem::swap(&mut flood_cells, &mut best_cells);
                    (holes, ring) = (inside, is_ring);
                }
            }
        }
    }
    let Flood {
        cells,
        low: (i, j),
        depth,
    } = best?;
    let area_mm2 = cells as f64 * cell_mm2;
    if area_mm2 < params.min_area_mm2 {
        return None;
    }
    let radius_cells = (cells as f64 / std::f64::consts::PI).sqrt();
    // A dent much wider than the kernel has a flat, noisy bottom: its
    // depth-weighted centroid, not its lowest point; so has a region that
    // encloses skin. A ring: the centroid of its disc, each cell alike (a
    // ring is deepest where the press's edge tilted the pins most, not
    // around its centre).
    let enclosed_cells = holes.len();
    let centroid = |cap: f32| -> Option<PointPx> {
        let mut mean = SurfaceMean::new(*surface);
        let inside = if ring { &holes[..] } else { &[] };
        for &(ci, cj) in best_cells.iter().chain(inside) {
            let rest_k = rest.values_per_mm2[cj * g.nx + ci];
            let weight = if ring {
                1.0
            } else {
                (extent - score(ci, cj)).min(cap) as f64
            };
            // Each cell weighs the skin it covers (1 / cos on a dome) and
            // the trust in its rest density there.
            mean.add_with(g.point(ci as f64, cj as f64), |cos| {
                let rest_on_skin = if on_skin { rest_k } else { rest_k * cos as f32 };
                weight * rim_trust(rest_on_skin, rest_median_per_mm2) / cos
            });
        }
        mean.mean()
    };
    // The relative rule: a region the mask does not cut on its centroid,
    // the weights capped ([`DENT_WEIGHT_CAP`]). Otherwise, and under the
    // paper's absolute rule: a region wider than [`CENTROID_RADIUS_H`]
    // kernel widths, or one that encloses skin, on its depth-weighted
    // centroid; a narrower one on its lowest point.
    let wide = enclosed_cells > 0 || radius_cells > CENTROID_RADIUS_H * params_reach_cells(map);
    let on_mask = |(x, y): (usize, usize)| x < g.nx && y < g.ny && mask[y * g.nx + x];
    let cut = || {
        best_cells
            .iter()
            .any(|&(i, j)| !four_neighbours(i, j).into_iter().all(on_mask))
    };
    let cap = if relative && !cut() {
        Some(DENT_WEIGHT_CAP * (extent - depth))
    } else {
        wide.then_some(f32::INFINITY)
    };
    let centre = if let Some(c) = cap.and_then(centroid) {
        c
    } else {
        let offset = |a: Option<(usize, usize)>, b: Option<(usize, usize)>| -> f64 {
            match (
                a.filter(|&(x, y)| usable(x, y)),
                b.filter(|&(x, y)| usable(x, y)),
            ) {
                (Some(a), Some(b)) => {
                    let (sa, s0, sb) =
                        (score(a.0, a.1) as f64, depth as f64, score(b.0, b.1) as f64);
                    let curv = sa - 2.0 * s0 + sb;
                    if curv > 0.0 {
                        (0.5 * (sa - sb) / curv).clamp(-0.5, 0.5)
                    } else {
                        0.0
                    }
                }
                _ => 0.0,
            }
        };
        let left = i.checked_sub(1).map(|x| (x, j));
        let up = j.checked_sub(1).map(|y| (i, y));
        let dx = offset(left, Some((i + 1, j)).filter(|p| p.0 < g.nx));
        let dy = offset(up, Some((i, j + 1)).filter(|p| p.1 < g.ny));
        // A flat-bottomed dent (contact wider than h) has a noisy argmin: fit a
        // quadratic surface over the cells within half the region's radius.
        let reach = (0.5 * radius_cells)
            .max(2.0)
            .min(2.0 * params_reach_cells(map));
        let (qx, qy) = quadratic_vertex(i, j, reach, &usable, &score)
            .filter(|&(x, y)| x.hypot(y) <= reach)
            .unwrap_or((dx, dy));
        g.point(i as f64 + qx, j as f64 + qy)
    };
    Some(Region {
        centre,
        cells,
        enclosed_cells,
        area_mm2,
        depth,
    })
}

/// The 4-connected neighbours of cell `(i, j)`; one beyond the grid's first
/// row or column wraps to `usize::MAX` (beyond any grid).
fn four_neighbours(i: usize, j: usize) -> [(usize, usize); 4] {
    [
        (i.wrapping_sub(1), j),
        (i + 1, j),
        (i, j.wrapping_sub(1)),
        (i, j + 1),
    ]
}

/// The cells a region of `cells` (4-connected) encloses: inside its
/// bounding box, not its own, and joined by no 8-connected path of such
/// cells to the box's border or to a cell `usable` rejects (outside the
/// mask or the ROI: a region along the rim encloses nothing there). Empty
/// when they are fewer than `min_cells`: noise may leave a cell or two of
/// a dent above the extent.
fn ring_holes(
    cells: &[(usize, usize)],
    usable: &impl Fn(usize, usize) -> bool,
    min_cells: usize,
) -> Vec<(usize, usize)> {
    let Some(&(fi, fj)) = cells.first() else {
        return Vec::new();
    };
    let (mut i0, mut j0, mut i1, mut j1) = (fi, fj, fi, fj);
    for &(i, j) in cells {
        (i0, j0, i1, j1) = (i0.min(i), j0.min(j), i1.max(i), j1.max(j));
    }
    let (w, h) = (i1 - i0 + 1, j1 - j0 + 1);
    const FREE: u8 = 0;
    const OWN: u8 = 1;
    const OUT: u8 = 2;
    let mut state = vec![FREE; w * h];
    for &(i, j) in cells {
        state[(j - j0) * w + (i - i0)] = OWN;
    }
    let mut stack = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let k = y * w + x;
            let border = x == 0 || y == 0 || x + 1 == w || y + 1 == h;
            if state[k] == FREE && (border || !usable(i0 + x, j0 + y)) {
                state[k] = OUT;
                stack.push((x, y));
            }
        }
    }
    while let Some((x, y)) = stack.pop() {
        for (dx, dy) in [
            (-1, -1),
            (0, -1),
            (1, -1),
            (-1, 0),
            (1, 0),
            (-1, 1),
            (0, 1),
            (1, 1),
        ] {
            let (nx, ny) = (x.wrapping_add_signed(dx), y.wrapping_add_signed(dy));
            if nx < w && ny < h && state[ny * w + nx] == FREE {
                state[ny * w + nx] = OUT;
                stack.push((nx, ny));
            }
        }
    }
    let holes: Vec<(usize, usize)> = (0..w * h)
        .filter(|&k| state[k] == FREE)
        .map(|k| (i0 + k % w, j0 + k / w))
        .collect();
    if holes.len() < min_cells {
        return Vec::new();
    }
    holes
}

/// A region that encloses at least this share of its own cells (below the
/// extent) is a ring, a flat press's edge: it is centred on the disc it
/// bounds, each cell alike. Below it, what a region encloses is a few
/// cells of noise inside a wide dent, which keeps its depth weights.
/// Measured (BENCHMARKS.md, session 24): the other renderer's wide punches
/// enclosed 5-48 % of their rings' cells, the real franka taps' dents
/// 0.3-20 %; with every enclosing region a ring, franka's tilt fit fell
/// from LOO R^2 0.90 / 0.95 to 0.83 / 0.87 (the disc's outline follows the
/// tilt worse than the depth does). At 0.15 it stays 0.90 / 0.95, and the
/// renderer's large contacts are 1.17 / 3.68 px off (median / p95); at
/// 0.20 and 0.25 their p95 is 5.05 and 5.89 px.
pub const RING_SHARE: f64 = 0.15;

/// Under the paper's absolute rule, a region whose radius (as a disc of its
/// area) exceeds this many kernel widths h is centred on its centroid, each
/// cell weighted by how far its score lies below the threshold and by its
/// [`rim_trust`], the mean taken on the skin ([`SurfaceMean`]); a narrower
/// one on its lowest point (the paper's method, refined by a quadratic
/// fit). (The relative rule centres every region on its centroid,
/// [`DENT_WEIGHT_CAP`].) Measured under the relative rule (BENCHMARKS.md,
/// session 11): on another renderer's frames, the centre error p95 fell
/// from 19.6 to 4.4 px (nominal) and the large contacts' median from 23.1
/// to 4.1 px; the real cr taps' LOO R^2 rose from 0.95 / 0.91 to
/// 0.97 / 0.95; the generator's sheared contacts, centred on the region,
/// moved from 1.8 to 2.2 px median. At 2 the renderer's nominal p95 was
/// 7.3 px instead of 4.4; 1 measured the same as 1.5.
pub const CENTROID_RADIUS_H: f64 = 1.5;

/// Under the relative rule every region (a ring aside, [`RING_SHARE`]) is
/// centred on its centroid on the skin, each cell weighted by how far its
/// score lies below the extent (`relative_extent`), that weight capped at
/// this fraction of the region's own depth (extent minus its lowest score),
/// and by its [`rim_trust`]. The dent's walls place it, where the score
/// falls steeply, not its single lowest cell nor its flat, noisy bottom:
/// a tilted or sheared press tilts that bottom by a few per cent, and a
/// lowest point or a depth-weighted centroid slides along the tilt.
///
/// A region the sensing mask cuts (a cell of it beside one off the mask or
/// the map) has no wall on that side, and its centroid moves away from the
/// cut: it is centred as under the absolute rule ([`CENTROID_RADIUS_H`]).
///
/// Measured on the other renderer's seeds 1-3 (BENCHMARKS.md, session 31),
/// against the lowest point for regions up to 1.5 kernel widths and the
/// uncapped centroid beyond, median / p95 px: nominal 0.54 / 4.15 -> 0.43 /
/// 3.98, harsh light 0.89 / 3.38 -> 0.75 / 3.31, blur 0.69 / 3.58 -> 0.59 /
/// 3.55, large 0.97 / 3.46 -> 0.69 / 2.75, two colours 0.82 / 3.50 ->
/// 0.68 / 3.50; the flat skin 1.92 -> 2.04 (its error is the pressed pins'
/// parallax, the same on the renderer's true pins). The rim: 2.18 / 5.67
/// px as before (2.29 / 5.32 with cut regions on their capped centroid
/// too); on the project's own generator's edge scene the rule for cut
/// regions keeps the p95 at 2.31 px (2.89 without). At 0.3 the nominal
/// median was 0.58 px, at 0.7 0.44 px.
pub const DENT_WEIGHT_CAP: f32 = 0.5;

/// Upper bound of the quadratic-fit window, grid cells (a kernel width h of
/// 15 px at the map's step).
fn params_reach_cells(map: &DensityMap) -> f64 {
    crate::params::KERNEL_WIDTH_PX / map.grid.step_px as f64
}

/// Least-squares fit of `s = a + b x + c y + d x^2 + e xy + f y^2` to the
/// usable samples within `reach` cells of `(i, j)`; returns the vertex
/// offset when the surface is a bowl.
fn quadratic_vertex(
    i: usize,
    j: usize,
    reach: f64,
    usable: &dyn Fn(usize, usize) -> bool,
    score: &dyn Fn(usize, usize) -> f32,
) -> Option<(f64, f64)> {
    let r = reach.floor() as i64;
    let mut ata = [[0f64; 6]; 6];
    let mut atb = [0f64; 6];
    let mut n = 0;
    for dj in -r..=r {
        for di in -r..=r {
            let (x, y) = (di as f64, dj as f64);
            let (ci, cj) = (i as i64 + di, j as i64 + dj);
            if x.hypot(y) > reach || ci < 0 || cj < 0 || !usable(ci as usize, cj as usize) {
                continue;
            }
            let v = score(ci as usize, cj as usize) as f64;
            if !v.is_finite() {
                continue;
            }
            let row = [1.0, x, y, x * x, x * y, y * y];
            for a in 0..6 {
                for b in 0..6 {
                    ata[a][b] += row[a] * row[b];
                }
                atb[a] += row[a] * v;
            }
            n += 1;
        }
    }
    if n < 9 {
        return None;
    }
    let c = solve6(ata, atb)?;
    let (b, cc, d, e, f) = (c[1], c[2], c[3], c[4], c[5]);
    let det = 4.0 * d * f - e * e;
    if d <= 0.0 || det <= 1e-12 {
        return None;
    }
    let x = (-2.0 * f * b + e * cc) / det;
    let y = (-2.0 * d * cc + e * b) / det;
    (x.is_finite() && y.is_finite()).then_some((x, y))
}

/// Gaussian elimination with partial pivoting; `None` when singular.
fn solve6(mut a: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
    for col in 0..6 {
        let piv = (col..6).max_by(|&p, &q| a[p][col].abs().total_cmp(&a[q][col].abs()))?;
        if a[piv][col].abs() < 1e-12 {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        let (pivot, pb) = (a[col], b[col]);
        for row in col + 1..6 {
            let f = a[row][col] / pivot[col];
            for (x, p) in a[row][col..].iter_mut().zip(&pivot[col..]) {
                *x -= f * p;
            }
            b[row] -= f * pb;
        }
    }
    let mut x = [0f64; 6];
    for row in (0..6).rev() {
        let s: f64 = (row + 1..6).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    Some(x)
}

/// True when `region` (on a grid of `step_px`) is at least as wide, as a
/// disc of its area, as the kernel `h_px` and the marker pitch `pitch_px`: a
/// dent in the density. Smoothing by `h` spreads any dent over at least `h`,
/// and one marker that moves opens a hole about a pitch wide, so a narrower
/// region is a threshold crossing (a lattice ripple where `h` is below the
/// pitch, noise, or a rest that differs from the frame), not a contact.
/// With [`CentreMethod::Hybrid`] the pipeline leaves those to the tracked
/// markers ([`locate`] with no region); the density-only method keeps
/// them (on the generator's frames 2 of 120 contacts are that narrow at
/// the default grid step). Measured on the real
/// TacTip taps with the median image as the rest (BENCHMARKS.md): such one-
/// to four-cell regions lay up to 200 px from the tap's contact.
pub fn is_dent(region: &Region, step_px: usize, h_px: f64, pitch_px: f64) -> bool {
    let area_px = region.cells as f64 * (step_px * step_px) as f64;
    let width_px = 2.0 * (area_px / std::f64::consts::PI).sqrt();
    width_px >= h_px.max(pitch_px)
}

/// The tracked centre replaces the density centre only when the
/// displacement lines meet this tightly (RMS of the inlier lines, px)...
pub const MAX_FIT_RESIDUAL_PX: f64 = 0.6;
/// ... and the inlier lines carry at least this share of the weight. Shear
/// bends the lines away from one point (measured: 3-9 px off on the shear
/// scenes with looser limits), so sheared contacts keep the density centre.
pub const MIN_INLIER_SHARE: f64 = 0.6;

/// Stage 5 entry: the contact from the density region and the tracked
/// markers, by `params.centre`. Under [`CentreMethod::Hybrid`] a dent keeps
/// its density centre unless markers around it are lost; then the point
/// where the displacement lines of the tracked markers meet replaces it
/// when the lines meet tightly ([`MAX_FIT_RESIDUAL_PX`],
/// [`MIN_INLIER_SHARE`]) within the dent. Without a
/// region, a small contact (tracked markers around the most displaced one
/// meet within 1.5 pitches of it) is tried first, then a shallow wide one
/// (a ring of moved markers that meet from all sides,
/// [`SHALLOW_REACH_PITCHES`], [`SHALLOW_MAX_SPREAD_RAD`],
/// [`SHALLOW_MAX_RESULTANT`]). A region that encloses skin keeps its own
/// centre: the lines of a flat press's edge meet where its parallax bends
/// them.
pub fn locate(
    region: Option<Region>,
    rest: &[PointPx],
    field: &Field,
    surface: &Surface,
    pitch_px: f64,
    params: &ContactParams,
    mm_per_px: f64,
) -> Option<Contact> {
    let from_region = |r: Region| Contact {
        centre: r.centre,
        area_mm2: r.area_mm2,
        source: Source::Density,
    };
    match (params.centre, region) {
        (CentreMethod::Density, r) => r.map(from_region),
        // A flat press's ring: the lines of its edge's pins meet where the
        // press's parallax bends them (the other renderer's punch frame 8 of
        // seed 2: 10.9 px off, the ring's centre 3.2 px).
        (CentreMethod::Hybrid, Some(r)) if r.enclosed_cells > 0 => Some(from_region(r)),
        (CentreMethod::Hybrid, Some(r)) => {
            let radius_px = (r.area_mm2 / std::f64::consts::PI).sqrt() / mm_per_px;
            let reach = radius_px + 2.0 * pitch_px;
            let mut near = near_markers(rest, field, r.centre, reach);
            // Every marker around the dent tracked: the density holds them
            // all, and its centre stands. Pins pressed towards the camera
            // also move in the image along the ray from its centre
            // (parallax), so their lines meet off the contact: on the other
            // renderer's dome 1.75 px outwards (median of 24 frames; the
            // density centre 0.44 px off), on its flat skin about 5 px
            // inwards (4 frames; BENCHMARKS.md, session 27). A lost marker
            // is a hole the density reads as part of the dent; the lines do
            // without it.
            if near.iter().all(|&n| field.displacement[n].is_some()) {
                return Some(from_region(r));
            }
            near.retain(|&n| {
                field.displacement[n]
                    .is_none_or(|u| norm(u.x, u.y) <= FIT_MAX_MOVE_PITCH * pitch_px)
            });
            match tracking::radial_centre_on(surface, rest, field, &near, field.moved_px, 0.0) {
                Some(fit)
                    if fit.n_inliers >= params.min_moved_markers
                        && fit.inlier_share >= MIN_INLIER_SHARE
                        && fit.residual_px <= MAX_FIT_RESIDUAL_PX
                        && dist(fit.centre, r.centre) <= radius_px.max(pitch_px) =>
                {
                    Some(Contact {
                        centre: fit.centre,
                        area_mm2: r.area_mm2,
                        source: Source::DensityTracked,
                    })
                }
                _ => Some(from_region(r)),
            }
        }
        (CentreMethod::Hybrid, None) => {
            let t = TrackedMarkers {
                rest,
                field,
                surface,
                pitch_px,
                params,
                mm_per_px,
            };
            let seed = strongest_move(field, pitch_px)?;
            small_contact(&t, seed).or_else(|| shallow_contact(&t, seed))
        }
    }
}

/// The tracked centre of a density region is fitted from the markers
/// displaced by at most this many pitches. Beyond it a marker was paired
/// through its neighbours' displacements ([`crate::markers::NEIGHBOUR_PITCH`]):
/// right more often than not, but on the other renderer's frames, where
/// pressed pins' parallax bends the lines, fitting them too moved the centre
/// (flat skin frame 20: 2.5 -> 10.3 px; BENCHMARKS.md, session 19).
pub const FIT_MAX_MOVE_PITCH: f64 = 0.5;

/// A tracked marker counts as support of a small contact when its
/// displacement exceeds this many sigmas of the frame's jitter (below the
/// "moved" test: the faint ring around a tiny press).
pub const SUPPORT_SIGMAS: f64 = 3.0;
/// A marker displaced by more than this many times the "moved" threshold
/// (24 sigma of the frame's jitter at the default 6 sigma) is *strongly*
/// moved: a press moves at least one marker this far (a tiny press on or
/// next to a marker moves it by ~1 px, a press that dents the density by
/// 1.4 px or more), while noise and the frozen noise of the rest frame
/// stay below it.
pub const STRONG_MOVE_FACTOR: f64 = 4.0;

/// Strongly moved is capped at this fraction of the marker pitch (2.25 px
/// at 15 px): no marker noise moves a marker this far, and a frame where
/// most markers moved (a press over most of the sensor, which inflates the
/// jitter estimate) is still looked at.
pub const STRONG_MOVE_MAX_PITCH: f64 = 0.15;

/// The displacement beyond which a marker is strongly moved, px.
pub fn strong_move_px(field: &Field, pitch_px: f64) -> f64 {
    (STRONG_MOVE_FACTOR * field.moved_px).min(STRONG_MOVE_MAX_PITCH * pitch_px)
}

/// Rest markers (indices) displaced by more than [`strong_move_px`] (lost
/// markers are not: dropout is not a press). Scans every tracked marker, not
/// only `field.moved`: a press over most of the sensor inflates the jitter
/// estimate and with it the moved threshold, while the strong threshold is
/// capped.
pub fn strongly_moved(field: &Field, pitch_px: f64) -> impl Iterator<Item = usize> + '_ {
    strongly_moved_against(field, pitch_px, PointPx::new(0.0, 0.0))
}

/// [`strongly_moved`], with each displacement taken against `common`.
fn strongly_moved_against(
    field: &Field,
    pitch_px: f64,
    common: PointPx,
) -> impl Iterator<Item = usize> + '_ {
    let strong2 = strong_move_px(field, pitch_px).powi(2);
    field
        .displacement
        .iter()
        .enumerate()
        .filter_map(move |(n, u)| {
            let u = (*u)?;
            let d2 = (u.x - common.x).powi(2) + (u.y - common.y).powi(2);
            // A NaN displacement is looked at, not silently dropped (the
            // later stages reject it).
            (d2 > strong2 || d2.is_nan()).then_some(n)
        })
}

/// The cells of `grid` whose samples lie within `reach_px` of the rest
/// place of a marker that moved strongly against the rest of the skin:
/// beyond [`strong_move_px`] from the field's common displacement (per
/// axis, the median), each place taken at its nearest sample. That is the
/// support a density region needs to be a press ([`segment_supported`]).
/// The markers a press moves away from its dent rested in or beside it; a
/// dent that no such marker borders is markers lost or found apart from
/// any press (a rim pin the frame's mask cut off as the skin sheared:
/// franka's real taps, BENCHMARKS.md, session 22). Against the common
/// displacement, not the rest place: with the camera moved 2 px after
/// calibration every marker moved beyond the strong move's cap, and holes
/// the mask cut at the rim passed for presses (the real taps' R² fell from
/// 0.97 / 0.96 to 0.54 / 0.72 on cr, BENCHMARKS.md, session 23).
pub fn support_cells(
    grid: &crate::density::Grid,
    rest: &[PointPx],
    field: &Field,
    pitch_px: f64,
    reach_px: f64,
) -> Vec<bool> {
    let (nx, ny) = (grid.nx as i64, grid.ny as i64);
    let mut support = vec![false; grid.nx * grid.ny];
    let step = grid.step_px as f64;
    let reach_cells = (reach_px / step).max(0.0);
    let r = reach_cells.floor() as i64;
    let disc: Vec<(i64, i64)> = (-r..=r)
        .flat_map(|dj| (-r..=r).map(move |di| (di, dj)))
        .filter(|&(di, dj)| ((di * di + dj * dj) as f64) <= reach_cells * reach_cells)
        .collect();
    let cell = |v: f64| ((v - (step - 1.0) / 2.0) / step).round();
    for n in strongly_moved_against(field, pitch_px, common_displacement(field)) {
        let Some(&p) = rest.get(n).filter(|p| p.is_finite()) else {
            continue;
        };
        let (ci, cj) = (cell(p.x) as i64, cell(p.y) as i64);
        for &(di, dj) in &disc {
            let (i, j) = (ci + di, cj + dj);
            if (0..nx).contains(&i) && (0..ny).contains(&j) {
                support[(j * nx + i) as usize] = true;
            }
        }
    }
    support
}

/// Per axis, the median of the tracked markers' displacements ((0, 0)
/// with none): what the whole skin (or the camera) moved.
fn common_displacement(field: &Field) -> PointPx {
    let tracked = || {
        field
            .displacement
            .iter()
            .filter_map(|u| u.filter(|u| u.is_finite()))
    };
    let axis = |v: Vec<f64>| median(&v).unwrap_or(0.0);
    PointPx::new(
        axis(collect_bounded(tracked().map(|u| u.x))),
        axis(collect_bounded(tracked().map(|u| u.y))),
    )
}

/// True when the field may hold a contact: some marker moved strongly
/// ([`STRONG_MOVE_FACTOR`]). Otherwise the pipeline skips the density
/// stages (weakly moved or lost markers alone are noise or dropout).
pub fn worth_a_look(field: &Field, pitch_px: f64) -> bool {
    strongly_moved(field, pitch_px).next().is_some()
}

/// A contact too small for the density: a cluster of consistently radially
/// displaced markers around the most displaced one. The fit uses every
/// tracked marker within 2.5 pitches of it whose displacement is above
/// [`SUPPORT_SIGMAS`] of the frame's jitter (not only the "moved" ones), with
/// a direction tolerance that grows with the jitter
/// ([`tracking::radial_centre_noisy`]); it needs `min_moved_markers` lines
/// through one point.
fn small_contact(t: &TrackedMarkers, seed: usize) -> Option<Contact> {
    let support_px = if t.field.jitter_px > 0.0 {
        (SUPPORT_SIGMAS * t.field.jitter_px).min(t.field.moved_px)
    } else {
        t.field.moved_px
    };
    let centre = t.rest[seed];
    let reach = 2.5 * t.pitch_px;
    let near: Vec<usize> = t
        .rest
        .iter()
        .enumerate()
        .filter(|&(n, &p)| {
            dist(p, centre) <= reach && magnitude(t.field, n).is_some_and(|m| m > support_px)
        })
        .map(|(n, _)| n)
        .collect();
    let fit = tracking::radial_centre_on(
        t.surface,
        t.rest,
        t.field,
        &near,
        support_px,
        t.field.jitter_px,
    )?;
    let d: Vec<f64> = near
        .iter()
        .filter(|&&n| magnitude(t.field, n).is_some_and(|m| m > t.field.moved_px))
        .map(|&n| dist(t.rest[n], fit.centre))
        .collect();
    let ok = fit.n_inliers >= t.params.min_moved_markers
        && d.len() >= 2
        && fit.inlier_share >= 0.6
        && dist(fit.centre, centre) <= 1.5 * t.pitch_px
        && inside_lattice(t.rest, fit.centre, SMALL_LATTICE_PITCHES * t.pitch_px);
    if !ok {
        return None;
    }
    Some(tracking_contact(fit.centre, median(&d)?, t.mm_per_px))
}

/// A small contact's centre (the tracked-only rule of [`locate`] for tiny
/// presses) must lie inside the marker lattice: the rest markers within
/// this many pitches of it leave no gap of more than a half-turn around it.
/// Lines that meet beyond the lattice's last markers are seen from one
/// side, and there a single marker's move places the centre. Measured
/// (BENCHMARKS.md, session 36): under 5 px of motion blur three outer-ring
/// markers of the other renderer's dome, each pulled 2.6-2.8 px towards its
/// inner neighbour by that neighbour's smear, made three false contacts in
/// 60 contact-free frames, centred where the largest gap around them was
/// 190-231 degrees; the 49 tracked centres of the renderer's contact frames
/// (seed 2, with and without parallax) had at most 75 degrees.
pub const SMALL_LATTICE_PITCHES: f64 = 2.0;

/// True when the points of `rest` within `reach_px` of `c` (other than one
/// on it) leave no angular gap of more than a half-turn around `c`.
fn inside_lattice(rest: &[PointPx], c: PointPx, reach_px: f64) -> bool {
    let mut angles: Vec<f64> = rest
        .iter()
        .filter(|p| {
            let d = dist(**p, c);
            d <= reach_px && d > 1e-6
        })
        .map(|p| (p.y - c.y).atan2(p.x - c.x))
        .collect();
    angles.sort_unstable_by(f64::total_cmp);
    let (Some(&first), Some(&last)) = (angles.first(), angles.last()) else {
        return false;
    };
    let widest = angles
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(first + std::f64::consts::TAU - last, f64::max);
    widest <= std::f64::consts::PI
}

/// The tracked markers the tracking-only rules of [`locate`] look at.
#[derive(Clone, Copy)]
struct TrackedMarkers<'a> {
    rest: &'a [PointPx],
    field: &'a Field,
    surface: &'a Surface,
    pitch_px: f64,
    params: &'a ContactParams,
    mm_per_px: f64,
}

/// A contact found from tracked markers alone, its area the disc through
/// the median moved marker at `radius_px`.
fn tracking_contact(centre: PointPx, radius_px: f64, mm_per_px: f64) -> Contact {
    Contact {
        centre,
        area_mm2: std::f64::consts::PI * (radius_px * mm_per_px).powi(2),
        source: Source::Tracking,
    }
}

/// The median of `v` (`None` when empty; the upper of the middle two).
fn median(v: &[f64]) -> Option<f64> {
    select_f64(v.iter().copied(), v.len() / 2)
}

/// The displacement of rest marker `n`, px (`None` when lost).
fn magnitude(field: &Field, n: usize) -> Option<f64> {
    let u = (*field.displacement.get(n)?)?;
    Some(norm(u.x, u.y))
}

/// The most displaced moved marker, when that is a strong move
/// ([`strong_move_px`]): where the tracking-only rules start.
fn strongest_move(field: &Field, pitch_px: f64) -> Option<usize> {
    let seed = field
        .moved
        .iter()
        .filter_map(|&n| Some((n, magnitude(field, n)?)))
        .max_by(|a, b| a.1.total_cmp(&b.1))?;
    (seed.1 > strong_move_px(field, pitch_px)).then_some(seed.0)
}

/// A shallow contact's moved markers are gathered within this many pitches
/// of its centre (the shallow-contact rule of [`locate`]).
pub const SHALLOW_REACH_PITCHES: f64 = 5.0;
/// A shallow contact's displacement lines may miss its centre by this much
/// RMS, as an angle seen from the centre: the share of the median distance
/// of its markers (at least [`MAX_FIT_RESIDUAL_PX`]).
pub const SHALLOW_MAX_SPREAD_RAD: f64 = 0.05;
/// A shallow contact's markers surround its centre: the mean of the unit
/// vectors from the centre to them is at most this long (1: all on one
/// side, 0: evenly all round).
pub const SHALLOW_MAX_RESULTANT: f64 = 0.5;

/// A contact too shallow to dent the density and too wide for
/// [`small_contact`]: a ring of outward-moved markers around a centre that
/// moved little. A flat punch pressed a little does this: the skin under it
/// moves as one and only the pins at its edge tilt (measured on the other
/// renderer: a punch 3.3 mm in radius, 0.75 mm deep, left the density at
/// 0.81 of rest at least, above the 0.80 threshold; the renderer's true pin
/// positions moved by up to 7.1 px at its edge and 2.5 px within 25 px of
/// its centre). The moved markers within [`SHALLOW_REACH_PITCHES`] of
/// the most displaced one give a first centre; the moved markers around that
/// centre give the next, three fits in all. Accepted when at least twice
/// `min_moved_markers` lines meet there ([`MIN_INLIER_SHARE`] of the
/// weight, within [`SHALLOW_MAX_SPREAD_RAD`]) from all sides
/// ([`SHALLOW_MAX_RESULTANT`]): a shear or a drift moves markers in
/// parallel, and lines that only meet from one side place the centre
/// poorly along them.
fn shallow_contact(t: &TrackedMarkers, seed: usize) -> Option<Contact> {
    let reach = SHALLOW_REACH_PITCHES * t.pitch_px;
    let mut centre = t.rest[seed];
    let mut near = Vec::new();
    let mut fit = None;
    for _ in 0..3 {
        near = near_markers(t.rest, t.field, centre, reach);
        let f = tracking::radial_centre_on(
            t.surface,
            t.rest,
            t.field,
            &near,
            t.field.moved_px,
            t.field.jitter_px,
        )?;
        centre = f.centre;
        fit = Some(f);
    }
    let fit = fit?;
    let c = t.surface.to_chart(fit.centre);
    let (mut sx, mut sy) = (0.0, 0.0);
    let mut d: Vec<f64> = Vec::with_capacity(near.len());
    // The markers that moved (not the lost ones): where they lie around
    // the centre, and how far out.
    for &n in near.iter().filter(|&&n| magnitude(t.field, n).is_some()) {
        let q = t.surface.to_chart(t.rest[n]);
        let l = dist(q, c);
        if l > 0.0 && l.is_finite() {
            sx += (q.x - c.x) / l;
            sy += (q.y - c.y) / l;
            d.push(dist(t.rest[n], fit.centre));
        }
    }
    let r_px = median(&d)?;
    let resultant = sx.hypot(sy) / d.len() as f64;
    let ok = fit.n_inliers >= 2 * t.params.min_moved_markers
        && fit.inlier_share >= MIN_INLIER_SHARE
        && fit.residual_px <= MAX_FIT_RESIDUAL_PX.max(SHALLOW_MAX_SPREAD_RAD * r_px)
        && resultant <= SHALLOW_MAX_RESULTANT
        && dist(fit.centre, t.rest[seed]) <= reach;
    ok.then(|| tracking_contact(fit.centre, r_px, t.mm_per_px))
}

/// Moved rest markers within `reach_px` of `c`.
fn near_markers(rest: &[PointPx], field: &Field, c: PointPx, reach_px: f64) -> Vec<usize> {
    field
        .moved
        .iter()
        .copied()
        .filter(|&n| dist(rest[n], c) <= reach_px)
        .collect()
}

/// The distance from `a` to `b`, px.
fn dist(a: PointPx, b: PointPx) -> f64 {
    norm(a.x - b.x, a.y - b.y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::density::Grid;

    fn maps(values: Vec<f32>, w: usize, h: usize) -> (DensityMap, DensityMap) {
        let grid = Grid::new(w, h, 1);
        (
            DensityMap {
                grid,
                roi: grid.full(),
                values_per_mm2: values,
            },
            DensityMap {
                grid,
                roi: grid.full(),
                values_per_mm2: vec![1.0; w * h],
            },
        )
    }

    fn loose() -> ContactParams {
        ContactParams {
            min_area_mm2: 0.0,
            ..ContactParams::default()
        }
    }

    /// [`segment`] of `map` against `rest` on a flat skin, `loose()`.
    fn segment_flat(map: &DensityMap, rest: &DensityMap, mask: &[bool]) -> Option<Region> {
        segment(map, &DensityReference::flat(rest, mask), &loose(), 1.0)
    }

    /// [`segment_flat`] under the paper's absolute rule, regions below 0.8.
    fn segment_absolute(map: &DensityMap, rest: &DensityMap, mask: &[bool]) -> Option<Region> {
        let params = ContactParams {
            threshold: ThresholdMode::Absolute,
            absolute_threshold_per_mm2: 0.8,
            ..loose()
        };
        segment(map, &DensityReference::flat(rest, mask), &params, 1.0)
    }

    /// A `w x h` map whose cell `(i, j)` is `f(i - cx, j - cy)`, row-major.
    fn values_around(
        w: usize,
        h: usize,
        (cx, cy): (f64, f64),
        f: impl Fn(f64, f64) -> f32,
    ) -> Vec<f32> {
        (0..w * h)
            .map(|k| f((k % w) as f64 - cx, (k / w) as f64 - cy))
            .collect()
    }

    #[test]
    fn largest_region_wins_centred_on_its_centroid_or_the_papers_minimum() {
        let mut v = vec![1.0f32; 100];
        v[11] = 0.1; // one-cell region with the global minimum
        for k in [55, 56, 65, 66, 75] {
            v[k] = 0.5;
        }
        v[66] = 0.3;
        let (map, rest) = maps(v, 10, 10);
        let r = segment_flat(&map, &rest, &[true; 100]).unwrap();
        assert_eq!(r.cells, 5);
        // Its cells lie 0.4-0.6 below the extent 0.9, every weight capped
        // at half the region's depth (0.3): the plain centroid of
        // (5, 5), (6, 5), (5, 6), (6, 6), (5, 7).
        assert!(
            (r.centre.x - 5.4).abs() < 1e-3 && (r.centre.y - 5.8).abs() < 1e-3,
            "{:?}",
            r.centre
        );
        // The paper's rule: its lowest cell.
        let r = segment_absolute(&map, &rest, &[true; 100]).unwrap();
        assert_eq!(r.cells, 5);
        assert!((r.centre.x - 6.0).abs() < 0.5 && (r.centre.y - 6.0).abs() < 0.5);
    }

    /// A flat press's ring: cells at 0.85 of rest (above the 0.80
    /// threshold, below the 0.90 extent) between 10 and 16 cells from
    /// (30, 32), the skin inside at 0.95, and an arc of the ring at 0.70
    /// on its left; `mask_from` cells left of that column are off the mask.
    fn ring_map(mask_from: usize) -> (DensityMap, DensityMap, Vec<bool>) {
        let (w, h) = (64, 64);
        let v = values_around(w, h, (30.0, 32.0), |dx, dy| match dx.hypot(dy) {
            r if r < 10.0 => 0.95,
            r if r <= 16.0 && dx < -10.0 => 0.70,
            r if r <= 16.0 => 0.85,
            _ => 1.0,
        });
        let mask = (0..w * h).map(|k| k % w >= mask_from).collect();
        let (map, rest) = maps(v, w, h);
        (map, rest, mask)
    }

    #[test]
    fn a_flat_press_ring_is_centred_on_the_disc_it_encloses() {
        let (map, rest, mask) = ring_map(0);
        let r = segment_flat(&map, &rest, &mask).unwrap();
        // Its lowest cells, on the deep arc, are 13 cells off the middle.
        assert!(
            (r.centre.x - 30.0).abs() < 0.5 && (r.centre.y - 32.0).abs() < 0.5,
            "{:?}",
            r.centre
        );
        let disc = (0..64 * 64)
            .filter(|k| ((k % 64) as f64 - 30.0).hypot((k / 64) as f64 - 32.0) <= 16.0)
            .count();
        assert_eq!(r.cells, disc);
        assert!(r.enclosed_cells > 250, "{}", r.enclosed_cells);
        // Without the deep arc no cell is below the threshold: the ring
        // alone is the region, with the same centre.
        let v: Vec<f32> = map.values_per_mm2.iter().map(|&x| x.max(0.85)).collect();
        let (map, rest) = maps(v, 64, 64);
        let r = segment_flat(&map, &rest, &mask).unwrap();
        assert!((r.centre.x - 30.0).abs() < 0.5 && (r.centre.y - 32.0).abs() < 0.5);
    }

    #[test]
    fn a_dent_enclosing_a_little_skin_keeps_its_depth_weights() {
        // A dent 30 cells in radius, deeper on its right half, around an
        // island at rest 8 cells in radius (7 % of its cells): no ring, so
        // the centroid leans to the deeper half, as it does without the
        // island. (Its right half lies 0.6 below the extent 0.9, weighed
        // at the cap 0.3; its left half 0.15 below, under the cap.)
        let v = values_around(80, 80, (40.0, 40.0), |dx, dy| match dx.hypot(dy) {
            r if r < 8.0 => 0.95,
            r if r <= 30.0 && dx > 0.0 => 0.3,
            r if r <= 30.0 => 0.75,
            _ => 1.0,
        });
        let (map, rest) = maps(v, 80, 80);
        let r = segment_flat(&map, &rest, &[true; 6400]).unwrap();
        assert!(r.enclosed_cells > 150, "{}", r.enclosed_cells);
        assert!(
            r.centre.x > 41.5 && (r.centre.y - 40.0).abs() < 0.5,
            "{:?}",
            r.centre
        );
        // The same band nowhere below the threshold (0.85 and 0.89 of
        // rest, the extent 0.90): still a region, since it encloses skin.
        let v: Vec<f32> = map
            .values_per_mm2
            .iter()
            .map(|&x| match x {
                x if x < 0.4 => 0.85,
                x if x < 0.9 => 0.89,
                x => x,
            })
            .collect();
        let (map, rest) = maps(v, 80, 80);
        let r = segment_flat(&map, &rest, &[true; 6400]).expect("a closed band is a region");
        assert!(r.enclosed_cells > 150 && r.centre.x > 41.5, "{r:?}");
    }

    /// A dent 30 cells in radius around (40, 40) on a 90 x 90 map: `core`
    /// within 26 cells, `left` on the rest of its left cap (x < 20), `edge`
    /// on the rest of its outer band.
    fn flat_dent_map(core: f32, left: f32, edge: f32) -> (DensityMap, DensityMap) {
        let v = values_around(90, 90, (40.0, 40.0), |dx, dy| match dx.hypot(dy) {
            r if r < 26.0 => core,
            r if r <= 30.0 && dx < -20.0 => left,
            r if r <= 30.0 => edge,
            _ => 1.0,
        });
        maps(v, 90, 90)
    }

    #[test]
    fn a_shallow_flat_dent_is_centred_on_its_whole_bottom() {
        // A shallow punch: its bottom at 0.84 of rest, above the 0.80
        // threshold; only an arc of its edge, on the left, reaches 0.79.
        // At half its depth (0.845) it is 26-30 cells in radius, wider than
        // 1.5 kernel widths (22.5 cells): its centroid, not the arc's
        // lowest cell 27 cells to the left.
        let (map, rest) = flat_dent_map(0.84, 0.79, 0.86);
        let r = segment_flat(&map, &rest, &[true; 8100]).unwrap();
        assert_eq!(r.enclosed_cells, 0);
        assert!(
            (r.centre.x - 40.0).abs() < 4.0 && (r.centre.y - 40.0).abs() < 0.5,
            "{:?}",
            r.centre
        );
        // A deep spot 4 cells in radius 20 cells right of the same shallow
        // dent's middle (a punch pressed deeper there): its cells weigh at
        // most half the region's depth (0.2), the arc's 0.11, the face's
        // 0.06, and the face has some 40 times as many cells. The centre
        // stays on the punch's face, not on the spot.
        let mut v = map.values_per_mm2.clone();
        for j in 0..90 {
            for i in 0..90 {
                let r = (i as f64 - 60.0).hypot(j as f64 - 40.0);
                if r < 4.0 {
                    v[j * 90 + i] = 0.5 + 0.02 * r as f32;
                }
            }
        }
        let (map, rest) = maps(v, 90, 90);
        let r = segment_flat(&map, &rest, &[true; 8100]).unwrap();
        assert!(
            (r.centre.x - 40.0).abs() < 4.0 && (r.centre.y - 40.0).abs() < 0.5,
            "{:?}",
            r.centre
        );
    }

    #[test]
    fn a_ring_the_mask_cuts_open_encloses_nothing() {
        // The mask ends inside the ring: what it held is open to the rim.
        let (map, rest, mask) = ring_map(24);
        let r = segment_flat(&map, &rest, &mask);
        assert!(r.is_none_or(|r| r.enclosed_cells == 0), "{r:?}");
        // Without the deep arc there is no region at all.
        let v: Vec<f32> = map.values_per_mm2.iter().map(|&x| x.max(0.85)).collect();
        let (map, rest) = maps(v, 64, 64);
        assert!(segment_flat(&map, &rest, &mask).is_none());
        // A hole in the mask inside the ring (a config's mask, or a patch
        // of the rest without pins): what the ring holds is joined to cells
        // that are no skin, so it encloses nothing either.
        let (map, rest, mut mask) = ring_map(0);
        for (k, m) in mask.iter_mut().enumerate() {
            let (dx, dy) = ((k % 64) as f64 - 30.0, (k / 64) as f64 - 32.0);
            *m = dx.hypot(dy) > 3.0;
        }
        let r = segment_flat(&map, &rest, &mask);
        assert!(r.is_none_or(|r| r.enclosed_cells == 0), "{r:?}");
    }

    #[test]
    fn a_dent_the_mask_cuts_is_centred_on_its_lowest_point() {
        // A bowl 6 cells in radius around (11, 20), the mask ending at
        // x = 10: the region is the bowl's right part, whose centroid lies
        // right of the bowl's middle; its lowest point does not move.
        let v = values_around(40, 40, (11.0, 20.0), |dx, dy| {
            (0.3 + 0.1 * dx.hypot(dy)).min(1.0) as f32
        });
        let (map, rest) = maps(v, 40, 40);
        let cut: Vec<bool> = (0..1600).map(|k| k % 40 >= 10).collect();
        for mask in [&cut[..], &[true; 1600][..]] {
            let r = segment_flat(&map, &rest, mask).unwrap();
            assert!(
                (r.centre.x - 11.0).abs() < 0.5 && (r.centre.y - 20.0).abs() < 0.5,
                "{:?}",
                r.centre
            );
        }
    }

    #[test]
    fn a_dent_wider_than_the_kernel_is_centred_on_its_centroid() {
        // A flat-bottomed dent of radius 30 cells (2 kernel widths at step
        // 1) whose lowest cell lies 20 cells off its middle: the centre is
        // the middle. Half that radius: the paper's rule takes the lowest
        // point, the relative rule the middle still (the lowest cell and
        // the others weigh alike, capped at half the depth).
        for (radius, want_x, want_absolute_x) in [(30.0, 40.0, 40.0), (15.0, 40.0, 60.0)] {
            let mut v = values_around(80, 80, (40.0, 40.0), |dx, dy| {
                if dx.hypot(dy) <= radius {
                    0.5
                } else {
                    1.0
                }
            });
            v[40 * 80 + 60] = 0.3;
            if radius < 20.0 {
                // Reach the low cell from the narrower dent.
                for i in 40..=60 {
                    v[40 * 80 + i] = v[40 * 80 + i].min(0.5);
                }
            }
            let (map, rest) = maps(v, 80, 80);
            let r = segment_flat(&map, &rest, &[true; 6400]).unwrap();
            let a = segment_absolute(&map, &rest, &[true; 6400]).unwrap();
            for (c, want_x) in [(r.centre, want_x), (a.centre, want_absolute_x)] {
                assert!(
                    (c.x - want_x).abs() < 0.5 && (c.y - 40.0).abs() < 0.5,
                    "radius {radius}: {c:?}, want x {want_x}"
                );
            }
        }
    }

    #[test]
    fn a_shallow_ring_is_one_region_centred_on_its_middle() {
        // A flat punch dents the density in a ring around an interior that
        // keeps most of its markers (another renderer's 5 mm punch: a ring
        // 50 px in radius whose floor reaches 0.73-0.78). Here, on the
        // pipeline's 8 px grid, the ring (radius 6 cells around (20.3,
        // 18.6)) dips to 0.78 in 10 arcs with 0.84 between them: the
        // threshold alone (0.80) sees 10 arcs, the largest centred on the
        // ring, ~6 cells off; grown through the samples below 0.90 the ring
        // is one region, centred on its middle.
        let (cx, cy) = (20.3, 18.6);
        let grid = Grid::new(40 * 8, 40 * 8, 8);
        let v = values_around(40, 40, (cx, cy), |dx, dy| {
            let r = dx.hypot(dy);
            if (r - 6.0).abs() <= 1.5 {
                let arc = (dy.atan2(dx) / std::f64::consts::TAU * 10.0).rem_euclid(1.0);
                if arc < 0.6 {
                    0.78
                } else {
                    0.84
                }
            } else if r < 4.5 {
                0.95
            } else {
                1.0
            }
        });
        let map = DensityMap {
            grid,
            roi: grid.full(),
            values_per_mm2: v,
        };
        let rest = DensityMap {
            values_per_mm2: vec![1.0; 40 * 40],
            ..map.clone()
        };
        let want = grid.point(cx, cy);
        let ring = segment_flat(&map, &rest, &[true; 1600]).unwrap();
        let off = (ring.centre.x - want.x).hypot(ring.centre.y - want.y);
        assert!(off < 2.0, "{:?} vs {want:?}", ring.centre);
        let mut no_extent = loose();
        no_extent.relative_extent = no_extent.relative_threshold;
        let arc = segment(
            &map,
            &DensityReference::flat(&rest, &[true; 1600]),
            &no_extent,
            1.0,
        )
        .unwrap();
        let off = (arc.centre.x - want.x).hypot(arc.centre.y - want.y);
        assert!(
            off > 30.0 && arc.cells < ring.cells / 4,
            "{arc:?} vs {ring:?}"
        );
    }

    #[test]
    fn min_area_and_mask_reject_regions() {
        let mut v = vec![1.0f32; 100];
        v[44] = 0.1;
        let (map, rest) = maps(v, 10, 10);
        let mut p = loose();
        p.min_area_mm2 = 2.0;
        assert!(segment(&map, &DensityReference::flat(&rest, &[true; 100]), &p, 1.0).is_none());
        let mut mask = [true; 100];
        mask[44] = false;
        assert!(segment_flat(&map, &rest, &mask).is_none());
    }

    /// A hex lattice of pitch 30 px on a 300 x 300 frame, its density setup
    /// (h 15 px, step 8 px), its rest density and an all-true mask.
    fn hex_lattice() -> (
        crate::density::DensitySetup,
        f64,
        Vec<PointPx>,
        DensityMap,
        Vec<bool>,
    ) {
        let (w, h, pitch) = (300, 300, 30.0);
        let setup = crate::density::DensitySetup {
            width: w,
            height: h,
            h_px: 15.0,
            mm_per_px: 0.1,
            mode: crate::params::DensityMode::Fast,
            step_px: 8,
            truncate_sigmas: 3.0,
            skin: None,
        };
        let rest = crate::test_fixtures::hex_points(w, h, pitch);
        let rest_map = crate::density::estimate(&rest, &setup, None);
        let mask = vec![true; rest_map.values_per_mm2.len()];
        (setup, pitch, rest, rest_map, mask)
    }

    #[test]
    fn a_lattice_ripple_is_no_dent_a_spread_is() {
        // A kernel half the pitch leaves ripples in the density: one marker
        // moved by 0.4 pitch drops a cell or two below 0.80 x rest. A press
        // that spreads the markers within 3 pitches makes a dent wider than
        // the pitch.
        use crate::density;
        let (setup, pitch, rest, rest_map, mask) = hex_lattice();
        let c = PointPx::new(150.0, 150.0);
        let nearest = (0..rest.len())
            .min_by(|&a, &b| dist(rest[a], c).total_cmp(&dist(rest[b], c)))
            .unwrap();
        let mut one = rest.clone();
        one[nearest].x += 0.4 * pitch;
        let map = density::estimate(&one, &setup, None);
        let ripple = segment(
            &map,
            &DensityReference::flat(&rest_map, &mask),
            &loose(),
            0.1,
        )
        .unwrap();
        assert!(!is_dent(&ripple, 8, 15.0, pitch), "{ripple:?}");
        let spread: Vec<PointPx> = rest
            .iter()
            .map(|&p| {
                let r = dist(p, c);
                let k = if r < 3.0 * pitch {
                    1.0 + 0.5 * (1.0 - r / (3.0 * pitch))
                } else {
                    1.0
                };
                PointPx::new(c.x + k * (p.x - c.x), c.y + k * (p.y - c.y))
            })
            .collect();
        let map = density::estimate(&spread, &setup, None);
        let dent = segment(
            &map,
            &DensityReference::flat(&rest_map, &mask),
            &loose(),
            0.1,
        )
        .unwrap();
        assert!(is_dent(&dent, 8, 15.0, pitch), "{dent:?}");
        assert!(dist(dent.centre, c) < 0.5 * pitch, "{dent:?}");
    }

    #[test]
    fn a_hole_no_moved_marker_borders_is_no_press_when_a_supported_dent_exists() {
        // Real franka taps: a sheared skin leaves a rim pin outside the
        // frame's mask. Its hole in the density was the largest region, far
        // from the press whose markers moved.
        use crate::density;
        let (setup, pitch, rest, rest_map, mask) = hex_lattice();
        let (press, hole) = (PointPx::new(100.0, 100.0), PointPx::new(210.0, 200.0));
        // The press spreads the markers within 2 pitches of it; the two
        // markers nearest the hole are lost.
        let mut nearest_hole: Vec<usize> = (0..rest.len()).collect();
        nearest_hole.sort_by(|&a, &b| dist(rest[a], hole).total_cmp(&dist(rest[b], hole)));
        let lost = &nearest_hole[..2];
        let displacement: Vec<Option<PointPx>> = (0..rest.len())
            .map(|n| {
                if lost.contains(&n) {
                    return None;
                }
                let p = rest[n];
                let r = dist(p, press);
                let k = if r < 2.0 * pitch {
                    0.4 * (1.0 - r / (2.0 * pitch))
                } else {
                    0.0
                };
                Some(PointPx::new(k * (p.x - press.x), k * (p.y - press.y)))
            })
            .collect();
        let now: Vec<PointPx> = rest
            .iter()
            .zip(&displacement)
            .filter_map(|(r, u)| u.map(|u| PointPx::new(r.x + u.x, r.y + u.y)))
            .collect();
        let field = Field {
            moved: (0..rest.len()).collect(),
            displacement,
            lost: 2,
            jitter_px: 0.1,
            moved_px: 0.6,
        };
        let map = density::estimate(&now, &setup, None);
        let reference = DensityReference::flat(&rest_map, &mask);
        let largest = segment(&map, &reference, &loose(), 0.1).unwrap();
        assert!(dist(largest.centre, hole) < pitch, "{largest:?}");
        let support = support_cells(&map.grid, &rest, &field, pitch, 15.0);
        let r = segment_supported(&map, &reference, &loose(), 0.1, &support).unwrap();
        assert!(dist(r.centre, press) < 0.5 * pitch, "{r:?}");
        // The camera moved by 0.2 pitch (beyond the strong move's cap):
        // every marker moved, but only the press moved against the rest
        // of the skin.
        let shift = PointPx::new(0.2 * pitch, 0.0);
        let moved_camera = Field {
            displacement: field
                .displacement
                .iter()
                .map(|u| u.map(|u| PointPx::new(u.x + shift.x, u.y + shift.y)))
                .collect(),
            ..field.clone()
        };
        let now_moved: Vec<PointPx> = now
            .iter()
            .map(|p| PointPx::new(p.x + shift.x, p.y + shift.y))
            .collect();
        let map_moved = density::estimate(&now_moved, &setup, None);
        let support = support_cells(&map_moved.grid, &rest, &moved_camera, pitch, 15.0);
        let r = segment_supported(&map_moved, &reference, &loose(), 0.1, &support).unwrap();
        assert!(dist(r.centre, press) < 0.5 * pitch, "{r:?}");
        // Without the press, the hole alone is no region.
        let still = Field {
            displacement: field
                .displacement
                .iter()
                .map(|u| u.map(|_| PointPx::new(0.0, 0.0)))
                .collect(),
            ..field
        };
        let support = support_cells(&map.grid, &rest, &still, pitch, 15.0);
        assert!(support.iter().all(|&s| !s));
        let kept: Vec<PointPx> = (0..rest.len())
            .filter(|n| !lost.contains(n))
            .map(|n| rest[n])
            .collect();
        let holed = density::estimate(&kept, &setup, None);
        assert!(segment(&holed, &reference, &loose(), 0.1).is_some());
        assert!(segment_supported(&holed, &reference, &loose(), 0.1, &support).is_none());
    }

    #[test]
    fn absolute_rule_compares_density_not_ratio() {
        let (map, mut rest) = maps(vec![0.5f32; 16], 4, 4);
        rest.values_per_mm2 = vec![0.55; 16];
        let mut p = loose();
        assert!(segment(&map, &DensityReference::flat(&rest, &[true; 16]), &p, 1.0).is_none());
        p.threshold = ThresholdMode::Absolute;
        p.absolute_threshold_per_mm2 = 0.6;
        assert_eq!(
            segment(&map, &DensityReference::flat(&rest, &[true; 16]), &p, 1.0)
                .unwrap()
                .cells,
            16
        );
    }

    #[test]
    fn nan_and_mismatched_inputs_give_no_region() {
        let (map, rest) = maps(vec![f32::NAN; 16], 4, 4);
        assert!(segment_flat(&map, &rest, &[true; 16]).is_none());
        assert!(segment_flat(&map, &rest, &[true; 3]).is_none());
    }

    #[test]
    fn a_press_over_most_of_the_sensor_is_still_looked_at() {
        // 90 % of the markers moved 3 px: the jitter estimate is inflated
        // (the lower quartile is a moved marker), the strong threshold is
        // capped at 0.15 pitch, and the frame is not skipped.
        let rest = crate::test_fixtures::hex_points(200, 200, 15.0);
        let cur: Vec<PointPx> = rest
            .iter()
            .enumerate()
            .map(|(n, p)| {
                let d = if n % 10 == 0 { 0.0 } else { 3.0 };
                PointPx::new(p.x + d, p.y)
            })
            .collect();
        let field = tracking::track_adaptive(&rest, &cur, 200, 200, 7.5, 0.1, 6.0);
        assert!(6.0 * field.jitter_px > 2.25, "{}", field.jitter_px);
        assert!((strong_move_px(&field, 15.0) - 2.25).abs() < 1e-12);
        assert!(worth_a_look(&field, 15.0));
        // A NaN displacement is looked at (and then rejected downstream),
        // never silently taken as "not moved".
        let mut nan = tracking::track_adaptive(&rest, &rest, 200, 200, 7.5, 0.1, 6.0);
        assert!(!worth_a_look(&nan, 15.0));
        nan.displacement[3] = Some(PointPx::new(f64::NAN, 0.0));
        nan.moved.push(3);
        assert!(worth_a_look(&nan, 15.0));
        assert!(locate(
            None,
            &rest,
            &nan,
            &Surface::Flat,
            15.0,
            &ContactParams::default(),
            0.1
        )
        .is_none());
    }

    #[test]
    fn a_dent_on_a_dome_is_centred_on_the_skin_it_covers() {
        // A dome of radius 60 px seen along its axis at (40, 40); its skin
        // evenly covered with markers, so the image density is 1 / cos
        // (the skin's median 1). A dent symmetric on the skin, 10 px in
        // chord radius, around the skin point seen at (90, 40), 56 degrees
        // from the apex. The image squeezes its outer half: each cell
        // weighted alike, even on the sphere, its mean lies 0.21 px
        // inwards; each weighted by the skin it covers, 0.006 px off.
        let (w, h, r_px) = (120usize, 80usize, 60.0);
        let dome = crate::surface::Dome {
            centre: PointPx::new(40.0, 40.0),
            radius_px: r_px,
        };
        let surface = Surface::Dome(dome);
        // (Beyond 70 degrees from the apex the map is off the mask.)
        let lift = |x: f64, y: f64| {
            let (a, b) = ((x - 40.0) / r_px, (y - 40.0) / r_px);
            [a, b, (1.0 - a * a - b * b).max(0.1).sqrt()]
        };
        let c = lift(90.0, 40.0);
        let (mut rest_v, mut frame) = (vec![0f32; w * h], vec![0f32; w * h]);
        for k in 0..w * h {
            let q = lift((k % w) as f64, (k / w) as f64);
            let chord = r_px * (0..3).map(|i| (q[i] - c[i]).powi(2)).sum::<f64>().sqrt();
            let dent = 1.0 - 0.5 * (1.0 - (chord / 10.0).powi(2)).max(0.0);
            rest_v[k] = (1.0 / q[2]) as f32;
            frame[k] = (dent / q[2]) as f32;
        }
        let (map, rest) = maps(frame, w, h);
        let rest = DensityMap {
            values_per_mm2: rest_v,
            ..rest
        };
        let mask: Vec<bool> = (0..w * h)
            .map(|k| lift((k % w) as f64, (k / w) as f64)[2] > 0.35)
            .collect();
        let reference = DensityReference {
            rest: &rest,
            mask: &mask,
            surface: &surface,
            rest_median_per_mm2: 1.0,
            on_skin: false,
        };
        let r = segment(&map, &reference, &loose(), 1.0).unwrap();
        assert!(
            (r.centre.x - 90.0).abs() < 0.05 && (r.centre.y - 40.0).abs() < 0.05,
            "{:?}",
            r.centre
        );
    }

    #[test]
    fn rim_trust_ramps_from_half_the_median_to_the_median() {
        assert_eq!(rim_trust(2.0, 1.0), 1.0);
        assert_eq!(rim_trust(1.0, 1.0), 1.0);
        assert!((rim_trust(0.75, 1.0) - 0.5).abs() < 1e-12);
        assert_eq!(rim_trust(0.5, 1.0), 0.0);
        assert_eq!(rim_trust(0.1, 1.0), 0.0);
        assert_eq!(rim_trust(f32::NAN, 1.0), 0.0);
        // No median (0, or not finite): every cell counts fully.
        assert_eq!(rim_trust(0.1, 0.0), 1.0);
        assert_eq!(rim_trust(0.1, f32::NAN), 1.0);
    }

    /// A wide round dent whose hysteresis region runs on into the rim,
    /// where the rest density falls off and a frame's ratio is unreliable:
    /// the rim's cells, weighted by their rest density, move the centroid a
    /// quarter as far as when they count fully.
    #[test]
    fn a_wide_dent_keeps_its_centre_when_its_region_runs_into_the_rim() {
        let grid = Grid::new(320, 160, 8);
        let (nx, ny) = (grid.nx, grid.ny);
        let (ci, cj) = (24.0, 10.0);
        let mut rest = vec![1.0f32; nx * ny];
        let mut frame = vec![1.0f32; nx * ny];
        for j in 0..ny {
            for i in 0..nx {
                let k = j * nx + i;
                let d2 = (i as f64 - ci).powi(2) + (j as f64 - cj).powi(2);
                let dent = 1.0 - 0.5 * (1.0 - d2 / 49.0).max(0.0);
                // The rim: the rest density falls off over the last 9 columns.
                if i > 30 {
                    rest[k] = 1.0 - 0.1 * (i - 30) as f32;
                }
                // A tail of low ratio from the dent's edge into the rim.
                let tail = i > 30 && (8..13).contains(&j);
                let ratio = if tail { dent.min(0.7) } else { dent };
                frame[k] = ratio as f32 * rest[k];
            }
        }
        let map = DensityMap {
            grid,
            roi: grid.full(),
            values_per_mm2: frame,
        };
        let rest = DensityMap {
            grid,
            roi: grid.full(),
            values_per_mm2: rest,
        };
        let mask = vec![true; nx * ny];
        let truth = grid.point(ci, cj);
        let trusted = DensityReference {
            rest_median_per_mm2: 1.0,
            ..DensityReference::flat(&rest, &mask)
        };
        let off = |r: &DensityReference| {
            let region = segment(&map, r, &loose(), 0.1).unwrap();
            region.centre.x - truth.x
        };
        let (with, without) = (off(&trusted), off(&DensityReference::flat(&rest, &mask)));
        // Measured: 4.8 px with, 23.6 px without.
        assert!(without > 15.0, "{without} px off without it");
        assert!(
            with.abs() < 0.25 * without,
            "{with} px off with the rim weighted"
        );
    }

    /// Markers on a lattice; those at distance `r` from `c` moved by
    /// `moved(r, direction from c)`, the rest by a tiny deterministic jitter.
    fn field_around(
        c: PointPx,
        moved: impl Fn(f64, (f64, f64)) -> (f64, f64),
    ) -> (Vec<PointPx>, Field) {
        let rest = crate::test_fixtures::hex_points(320, 320, 15.0);
        let mut rng = crate::synth::Rng::new(7);
        let known: Vec<(usize, PointPx)> = rest
            .iter()
            .enumerate()
            .map(|(n, p)| {
                let (dx, dy) = (p.x - c.x, p.y - c.y);
                let r = dx.hypot(dy).max(1e-9);
                let (ux, uy) = moved(r, (dx / r, dy / r));
                (
                    n,
                    PointPx::new(
                        p.x + ux + 0.02 * rng.normal(),
                        p.y + uy + 0.02 * rng.normal(),
                    ),
                )
            })
            .collect();
        let params = ContactParams::default();
        let field = tracking::track_known_adaptive(
            &rest,
            known,
            params.move_noise_px,
            params.move_noise_sigmas,
        );
        (rest, field)
    }

    /// A tiny press moves the marker beside it and, faintly, the next ones.
    /// Inside the lattice their lines meet at the press. Centred just past
    /// the lattice's last column, the same field is what a motion blur
    /// makes of an outer-ring marker pulled towards its inner neighbour
    /// (BENCHMARKS.md, session 36): the lines meet from one side only, and
    /// it is no contact.
    #[test]
    fn a_small_contact_is_only_found_inside_the_lattice() {
        let press = |r: f64, (ex, ey): (f64, f64)| {
            let m = 2.5 * (-(r / 12.0).powi(2)).exp();
            (m * ex, m * ey)
        };
        let params = ContactParams::default();
        let s = Surface::Flat;
        let inside = PointPx::new(161.3, 158.2);
        let (rest, field) = field_around(inside, press);
        let found = locate(None, &rest, &field, &s, 15.0, &params, 0.1).expect("found");
        assert_eq!(found.source, Source::Tracking);
        assert!(dist(found.centre, inside) < 1.0, "{:?}", found.centre);
        // 4 px left of the first column's marker at (15, 144.9).
        let past = PointPx::new(11.0, 144.9);
        let (rest, field) = field_around(past, press);
        assert!(!inside_lattice(&rest, past, SMALL_LATTICE_PITCHES * 15.0));
        let found = locate(None, &rest, &field, &s, 15.0, &params, 0.1);
        assert!(found.is_none(), "{found:?}");
    }

    /// A shallow flat punch 45 px in radius: only the ring at its edge moves
    /// (outwards, up to 3 px). No marker near the centre moved, so the small
    /// contact's rule (centre within 1.5 pitches of the most moved marker)
    /// cannot take it; the shallow rule finds its centre.
    #[test]
    fn a_shallow_wide_punch_is_found_from_its_ring() {
        let c = PointPx::new(161.3, 158.2);
        let ring = |r: f64, (ex, ey): (f64, f64)| {
            let m = 3.0 * (-((r - 45.0) / 8.0).powi(2)).exp();
            (m * ex, m * ey)
        };
        let (rest, field) = field_around(c, ring);
        let params = ContactParams::default();
        let s = Surface::Flat;
        let tracked = |rest, field| TrackedMarkers {
            rest,
            field,
            surface: &s,
            pitch_px: 15.0,
            params: &params,
            mm_per_px: 0.1,
        };
        let seed = strongest_move(&field, 15.0).expect("a strong move");
        assert!(small_contact(&tracked(&rest, &field), seed).is_none());
        let found = locate(None, &rest, &field, &s, 15.0, &params, 0.1).expect("found");
        assert_eq!(found.source, Source::Tracking);
        assert!(dist(found.centre, c) < 0.5, "{:?}", found.centre);
        // Radius of the median moved marker: the ring, 4.5 mm at 0.1 mm/px.
        let r_mm = (found.area_mm2 / std::f64::consts::PI).sqrt();
        assert!((r_mm - 4.5).abs() < 1.0, "{r_mm} mm");

        // Half a ring (one side moved): the lines meet only from one side.
        let half = |r: f64, e: (f64, f64)| if e.0 > 0.0 { ring(r, e) } else { (0.0, 0.0) };
        let (rest, field) = field_around(c, half);
        let seed = strongest_move(&field, 15.0).expect("a strong move");
        assert!(shallow_contact(&tracked(&rest, &field), seed).is_none());
        // A patch dragged sideways (shear, no press): parallel lines.
        let drag = |r: f64, _| if r < 60.0 { (3.0, 0.0) } else { (0.0, 0.0) };
        let (rest, field) = field_around(c, drag);
        assert!(locate(None, &rest, &field, &s, 15.0, &params, 0.1).is_none());
    }

    /// A dent 2 px from where the displacement lines of its markers meet
    /// (pins pressed towards the camera also move along the ray from the
    /// image's centre): with every marker around it tracked, the dent keeps
    /// its density centre; with two of them lost (a hole the density reads
    /// as dent), the lines' meeting point replaces it.
    #[test]
    fn a_dent_keeps_its_density_centre_unless_markers_around_it_are_lost() {
        let c = PointPx::new(161.3, 158.2);
        let press = |r: f64, (ex, ey): (f64, f64)| {
            let m = 3.0 * (r / 30.0) * (-0.5 * (r / 30.0).powi(2)).exp();
            (m * ex, m * ey)
        };
        let (rest, mut field) = field_around(c, press);
        let dent = Region {
            centre: PointPx::new(c.x + 2.0, c.y),
            cells: 40,
            enclosed_cells: 0,
            area_mm2: std::f64::consts::PI * 9.0,
            depth: 0.5,
        };
        let params = ContactParams::default();
        let found = |field: &Field| {
            locate(Some(dent), &rest, field, &Surface::Flat, 15.0, &params, 0.1).expect("found")
        };
        let kept = found(&field);
        assert_eq!((kept.source, kept.centre), (Source::Density, dent.centre));
        let mut lost = field.moved.clone();
        lost.sort_by(|&a, &b| dist(rest[a], c).total_cmp(&dist(rest[b], c)));
        for &n in &lost[..2] {
            field.displacement[n] = None;
        }
        let fitted = found(&field);
        assert_eq!(fitted.source, Source::DensityTracked);
        assert!(dist(fitted.centre, c) < 0.3, "{:?}", fitted.centre);
    }

    proptest::proptest! {
        #[test]
        fn noise_dropout_and_frozen_rest_noise_are_never_a_contact(
            sigma in 0.0f64..0.1,
            noisy_share in 0.0f64..0.05,
            lost_share in 0.0f64..0.1,
            seed in proptest::prelude::any::<u64>(),
        ) {
            // Every marker jitters (Gaussian, sigma per axis, frame and rest
            // noise; up to twice the 0.05 px of the noisiest synthetic
            // scenes), a few jitter 3x more (rim, low contrast), some are
            // lost: nothing moved strongly, the frame is skipped, and the
            // tracking-only rule finds no contact.
            let mut rng = crate::synth::Rng::new(seed);
            let rest = crate::test_fixtures::hex_points(320, 320, 15.0);
            let mut cur = Vec::new();
            for p in &rest {
                if rng.unit() < lost_share {
                    continue;
                }
                let s = if rng.unit() < noisy_share { 3.0 * sigma } else { sigma };
                cur.push(PointPx::new(p.x + s * rng.normal(), p.y + s * rng.normal()));
            }
            let params = ContactParams::default();
            let field = tracking::track_adaptive(
                &rest, &cur, 320, 320, 7.5, params.move_noise_px, params.move_noise_sigmas,
            );
            proptest::prop_assert!(!worth_a_look(&field, 15.0), "{:?}", field.moved_px);
            proptest::prop_assert!(locate(None, &rest, &field, &Surface::Flat, 15.0, &params, 0.1).is_none());
        }
    }
}
