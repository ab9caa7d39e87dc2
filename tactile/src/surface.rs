//! The shape of the skin the camera looks at: flat, or a dome (TacTip).
//!
//! On a dome seen from inside along its axis, a marker at polar angle
//! `theta` from the apex appears at image radius `R sin(theta)`: towards the
//! rim the skin is foreshortened by `cos(theta)` along the radius. A press
//! pushes the markers along the dome, away from the contact along great
//! circles; in the image those paths are arcs of ellipses whose tangents at
//! the markers miss the contact's image, towards the rim by pixels. The
//! tracked contact centre ([`crate::tracking::radial_centre_on`]) meets the
//! displacement lines in a plane where they are straight again: the
//! **gnomonic chart** of the dome (central projection from the sphere's
//! centre onto the plane touching the apex), which maps every great circle
//! to a straight line. It is scaled so that at the apex one chart px is one
//! image px; the centre is found there and mapped back to the image.
//!
//! The dome is estimated from the rest markers ([`estimate`]): the skin's
//! pins sit at a regular pitch along its surface, so the right sphere makes
//! the distances between radial neighbours *along the surface* most
//! uniform, while in the image they shrink towards the rim by
//! `cos(theta)`. A flat skin gives no improvement over the image and stays
//! [`Surface::Flat`]. The camera is taken as orthographic (the dome's axis
//! through the sensing area's centre); a strong perspective would need the
//! lens.

use serde::Deserialize;

use crate::area::WorkToInput;
use crate::PointPx;

/// The skin's shape as given in a sensor config (`[surface]`), in input px.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Default)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum SurfaceSpec {
    /// Estimated from the rest markers ([`estimate`], the default).
    #[default]
    Auto,
    /// Flat: the image is the chart.
    Flat,
    /// A dome seen from inside along its axis.
    Dome {
        /// The apex's image `[x, y]`, input px.
        centre_px: [f64; 2],
        /// Sphere radius, input px (the rim's image radius over the sine
        /// of the rim's polar angle).
        radius_px: f64,
    },
}

impl SurfaceSpec {
    /// The surface in working px: a given dome mapped through `map` (its
    /// radius by the mean scale), or estimated from `rest` (working px).
    pub fn resolve(&self, rest: &[PointPx], map: WorkToInput) -> Surface {
        match *self {
            SurfaceSpec::Auto => estimate(rest),
            SurfaceSpec::Flat => Surface::Flat,
            SurfaceSpec::Dome {
                centre_px,
                radius_px,
            } => Surface::Dome(Dome {
                centre: map.to_work(PointPx::new(centre_px[0], centre_px[1])),
                radius_px: 2.0 * radius_px / (map.scale_x + map.scale_y),
            }),
        }
    }

    /// Why the spec is unusable, if it is (non-finite or non-positive).
    pub fn problem(&self) -> Option<&'static str> {
        match *self {
            SurfaceSpec::Dome {
                centre_px,
                radius_px,
            } if !(centre_px.iter().all(|v| v.is_finite())
                && radius_px.is_finite()
                && radius_px > 0.0) =>
            {
                Some("a dome needs a finite centre_px and a finite radius_px > 0")
            }
            _ => None,
        }
    }
}

/// The skin's shape, in working px.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Surface {
    /// A flat skin: the image is the chart.
    #[default]
    Flat,
    /// A dome seen from inside along its axis.
    Dome(Dome),
}

/// A spherical dome seen orthographically along its axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dome {
    /// The apex's image (the sphere's axis), working px.
    pub centre: PointPx,
    /// Sphere radius, working px.
    pub radius_px: f64,
}

/// Farthest polar angle mapped to the chart, rad (the gnomonic scale grows
/// as `1 / cos^2`: 11x at 72.5 deg). Points beyond are clamped to it.
pub const MAX_POLAR_RAD: f64 = 1.265;

impl Surface {
    /// The chart point of image point `p` (itself on a flat skin).
    pub fn to_chart(&self, p: PointPx) -> PointPx {
        match self {
            Surface::Flat => p,
            Surface::Dome(d) => d.to_chart(p),
        }
    }

    /// The image point of chart point `q` (itself on a flat skin).
    pub fn from_chart(&self, q: PointPx) -> PointPx {
        match self {
            Surface::Flat => q,
            Surface::Dome(d) => d.from_chart(q),
        }
    }

    /// Foreshortening `cos(theta)` at image point `p`: 1 on a flat skin, and
    /// at least `cos(MAX_POLAR_RAD)` on a dome.
    pub fn foreshortening(&self, p: PointPx) -> f64 {
        match self {
            Surface::Flat => 1.0,
            Surface::Dome(d) => d.lift(p)[2],
        }
    }

    /// Short description for reports: `flat`, or the dome's radius and the
    /// polar angle of the farthest of the `rest` markers.
    pub fn describe(&self, rest: &[PointPx]) -> String {
        match self {
            Surface::Flat => "flat".into(),
            Surface::Dome(d) => {
                let rim_px = rest
                    .iter()
                    .map(|p| (p.x - d.centre.x).hypot(p.y - d.centre.y))
                    .filter(|r| r.is_finite())
                    .fold(0.0, f64::max);
                format!(
                    "dome (radius {:.0} px, markers out to {:.0} deg from the apex)",
                    d.radius_px,
                    (rim_px / d.radius_px).clamp(0.0, 1.0).asin().to_degrees()
                )
            }
        }
    }
}

/// Weighted mean of image points taken on the skin: on a dome the mean of
/// the points' unit vectors on the sphere, renormalised and seen again in
/// the image; on a flat skin the plain weighted mean. Weights are the
/// caller's: [`SurfaceMean::add`] takes one per image point as given, and
/// [`SurfaceMean::add_with`] lets it depend on the foreshortening there (a
/// contact region weighs each cell by the skin it covers, `1 / cos(theta)`,
/// times the trust in its rest density on the skin; BENCHMARKS.md, session
/// 31. In session 15 the area weight alone had moved the other renderer's
/// centres further than the sphere alone).
///
/// On a dome the image mean of a patch is pulled towards the apex: the image
/// radius `R sin(theta)` bends over as theta grows, so the outer half of a
/// patch symmetric on the skin is squeezed into fewer pixels. The mean on
/// the sphere has no such pull.
#[derive(Debug, Clone, Copy)]
pub struct SurfaceMean {
    surface: Surface,
    /// Weighted sums of x, y, z (unit sphere; z unused on a flat skin) and
    /// of the weights.
    sum: [f64; 4],
}

impl SurfaceMean {
    /// An empty mean on `surface`.
    pub fn new(surface: Surface) -> Self {
        Self {
            surface,
            sum: [0.0; 4],
        }
    }

    /// Adds image point `p` with weight `w` (ignored unless finite and
    /// positive).
    pub fn add(&mut self, p: PointPx, w: f64) {
        if w > 0.0 && w.is_finite() {
            self.add_with(p, |_| w);
        }
    }

    /// Adds image point `p` with the weight `weight(cos)` gives for the
    /// skin's foreshortening `cos` there ([`Surface::foreshortening`]; 1 on
    /// a flat skin), the point lifted once (a weight ignored unless finite
    /// and positive).
    pub fn add_with(&mut self, p: PointPx, weight: impl FnOnce(f64) -> f64) {
        if !p.is_finite() {
            return;
        }
        let ([x, y, z], cos) = match &self.surface {
            Surface::Flat => ([p.x, p.y, 0.0], 1.0),
            Surface::Dome(d) => {
                let q = d.lift(p);
                (q, q[2])
            }
        };
        let w = weight(cos);
        if !(w > 0.0 && w.is_finite()) {
            return;
        }
        for (s, v) in self.sum.iter_mut().zip([x, y, z, 1.0]) {
            *s += w * v;
        }
    }

    /// The mean's image point; `None` without any weight.
    pub fn mean(&self) -> Option<PointPx> {
        let [x, y, z, w] = self.sum;
        if w <= 0.0 || w.is_nan() {
            return None;
        }
        let c = match &self.surface {
            Surface::Flat => PointPx::new(x / w, y / w),
            Surface::Dome(d) => {
                let n = (x * x + y * y + z * z).sqrt();
                if n <= 0.0 || n.is_nan() {
                    return None;
                }
                PointPx::new(
                    d.centre.x + d.radius_px * x / n,
                    d.centre.y + d.radius_px * y / n,
                )
            }
        };
        c.is_finite().then_some(c)
    }
}

impl Dome {
    /// Unit-sphere coordinates `(x, y, z)` of the dome point seen at `p`,
    /// with the polar angle clamped to [`MAX_POLAR_RAD`].
    pub(crate) fn lift(&self, p: PointPx) -> [f64; 3] {
        let (x, y) = (
            (p.x - self.centre.x) / self.radius_px,
            (p.y - self.centre.y) / self.radius_px,
        );
        let r = crate::numeric::norm(x, y);
        let r_max = MAX_POLAR_RAD.sin();
        let (x, y) = if r > r_max {
            (x * r_max / r, y * r_max / r)
        } else {
            (x, y)
        };
        [x, y, (1.0 - x * x - y * y).max(0.0).sqrt()]
    }

    /// Gnomonic chart point of image point `p`, px (scale 1 at the apex).
    pub fn to_chart(&self, p: PointPx) -> PointPx {
        let [x, y, z] = self.lift(p);
        PointPx::new(
            self.centre.x + self.radius_px * x / z,
            self.centre.y + self.radius_px * y / z,
        )
    }

    /// Image point of gnomonic chart point `q`.
    pub fn from_chart(&self, q: PointPx) -> PointPx {
        let (a, b) = (
            (q.x - self.centre.x) / self.radius_px,
            (q.y - self.centre.y) / self.radius_px,
        );
        let n = (1.0 + a * a + b * b).sqrt();
        PointPx::new(
            self.centre.x + self.radius_px * a / n,
            self.centre.y + self.radius_px * b / n,
        )
    }

    /// Distance along the dome between the points seen at `p` and `q`, px.
    pub fn arc_px(&self, p: PointPx, q: PointPx) -> f64 {
        let (a, b) = (self.lift(p), self.lift(q));
        let c = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        // acos loses precision for close points: use the chord's angle.
        let chord = ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt();
        let angle = if c > 0.9 {
            2.0 * (0.5 * chord).asin()
        } else {
            c.clamp(-1.0, 1.0).acos()
        };
        self.radius_px * angle
    }
}

/// Rim polar angles tried by [`estimate`], deg (0: flat).
const RIM_ANGLES_DEG: std::ops::RangeInclusive<u32> = 1..=16;
/// Step of [`RIM_ANGLES_DEG`], deg.
const RIM_STEP_DEG: f64 = 5.0;
/// A dome is taken only when it makes the nearest-neighbour distances along
/// the skin this much more uniform than in the image (robust spread ratio).
pub const MIN_UNIFORMITY_GAIN: f64 = 0.8;
/// ... and its rim lies at least this far from the apex, deg (below, the
/// foreshortening is under 6 % and a flat chart is as good).
pub const MIN_RIM_DEG: f64 = 20.0;
/// Neighbours looked at per marker for its nearest along the surface.
const NEIGHBOURS: usize = 8;

/// The skin's shape from its rest markers (see the [module docs](self)):
/// a dome centred on the markers' centroid whose radius makes the
/// distances between radial neighbours along it most uniform, or
/// [`Surface::Flat`] when that is no better than the image. Needs at least
/// 30 markers (fewer: flat).
pub fn estimate(rest: &[PointPx]) -> Surface {
    let pts: Vec<PointPx> = rest.iter().copied().filter(|p| p.is_finite()).collect();
    if pts.len() < 30 {
        return Surface::Flat;
    }
    let n = pts.len() as f64;
    let centre = PointPx::new(
        pts.iter().map(|p| p.x).sum::<f64>() / n,
        pts.iter().map(|p| p.y).sum::<f64>() / n,
    );
    let rim_px = pts
        .iter()
        .map(|p| (p.x - centre.x).hypot(p.y - centre.y))
        .fold(0.0, f64::max);
    if rim_px <= 0.0 {
        return Surface::Flat;
    }
    let radial = radial_neighbours(&pts, &nearest_neighbours(&pts, NEIGHBOURS), centre);
    let spread_for = |rim_deg: f64| -> f64 {
        let dome = Dome {
            centre,
            radius_px: rim_px / rim_deg.to_radians().sin(),
        };
        spread(&pts, &radial, |a, b| dome.arc_px(a, b))
    };
    let flat = spread(&pts, &radial, |a, b| (a.x - b.x).hypot(a.y - b.y));
    let (mut best_deg, mut best) = (0.0, f64::INFINITY);
    for k in RIM_ANGLES_DEG {
        let deg = k as f64 * RIM_STEP_DEG;
        let s = spread_for(deg);
        if s < best {
            (best_deg, best) = (deg, s);
        }
    }
    // Refine within one step either side (golden section).
    let (mut lo, mut hi) = (
        (best_deg - RIM_STEP_DEG).max(1.0),
        (best_deg + RIM_STEP_DEG).min(MAX_POLAR_RAD.to_degrees()),
    );
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..12 {
        let (a, b) = (hi - g * (hi - lo), lo + g * (hi - lo));
        if spread_for(a) < spread_for(b) {
            hi = b;
        } else {
            lo = a;
        }
    }
    let deg = 0.5 * (lo + hi);
    let s = spread_for(deg);
    if s.is_finite() && s < MIN_UNIFORMITY_GAIN * flat && deg >= MIN_RIM_DEG {
        Surface::Dome(Dome {
            centre,
            radius_px: rim_px / deg.to_radians().sin(),
        })
    } else {
        Surface::Flat
    }
}

/// Per point, the indices of its `k` nearest others in the image.
fn nearest_neighbours(pts: &[PointPx], k: usize) -> Vec<Vec<usize>> {
    pts.iter()
        .enumerate()
        .map(|(i, p)| {
            let mut d: Vec<(f64, usize)> = pts
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(j, q)| ((p.x - q.x).powi(2) + (p.y - q.y).powi(2), j))
                .collect();
            let k = k.min(d.len());
            if k == 0 {
                return Vec::new();
            }
            d.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
            d[..k].iter().map(|x| x.1).collect()
        })
        .collect()
}

/// Of each point's `neighbours`, those in the radial direction: within
/// [`RADIAL_CONE_DEG`] of the line from `centre`. The radial spacing is
/// what the dome foreshortens; the tangential one also depends on how the
/// pins are laid out, and would bias the estimate.
fn radial_neighbours(
    pts: &[PointPx],
    neighbours: &[Vec<usize>],
    centre: PointPx,
) -> Vec<Vec<usize>> {
    let cone = RADIAL_CONE_DEG.to_radians().cos();
    pts.iter()
        .zip(neighbours)
        .map(|(p, ns)| {
            let (rx, ry) = (p.x - centre.x, p.y - centre.y);
            let r = rx.hypot(ry);
            ns.iter()
                .copied()
                .filter(|&j| {
                    let (qx, qy) = (pts[j].x - p.x, pts[j].y - p.y);
                    let q = qx.hypot(qy);
                    // Near the centre every direction is radial enough.
                    r < 1e-9 || q < 1e-9 || (rx * qx + ry * qy).abs() >= cone * r * q
                })
                .collect()
        })
        .collect()
}

/// Robust relative spread (interquartile range over median) of each point's
/// distance, by `dist`, to its nearest `radial` neighbour
/// ([`radial_neighbours`]; worked out once, not per dome tried).
fn spread(pts: &[PointPx], radial: &[Vec<usize>], dist: impl Fn(PointPx, PointPx) -> f64) -> f64 {
    let mut d: Vec<f64> = pts
        .iter()
        .zip(radial)
        .filter_map(|(p, ns)| {
            ns.iter()
                .map(|&j| dist(*p, pts[j]))
                .filter(|v| v.is_finite())
                .min_by(f64::total_cmp)
        })
        .collect();
    if d.len() < 4 {
        return f64::INFINITY;
    }
    d.sort_by(f64::total_cmp);
    let q = |f: f64| d[((d.len() - 1) as f64 * f).round() as usize];
    let median = q(0.5);
    if median <= 0.0 {
        return f64::INFINITY;
    }
    (q(0.75) - q(0.25)) / median
}

/// Half-angle of the cone around the radial direction that [`spread`] looks
/// in, deg (a hex lattice always has a neighbour within 30 deg).
const RADIAL_CONE_DEG: f64 = 30.0;

#[cfg(test)]
mod tests {
    use super::*;

    /// The generator's domed skin with its rim at `rim_deg` (seen at 220 px
    /// in a 640x480 frame): rest markers, sphere radius, apex.
    fn dome_lattice(rim_deg: f64) -> (Vec<PointPx>, f64, PointPx) {
        let mut sensor = crate::synth::SensorSpec::domed(640, 480);
        let rim = rim_deg.to_radians();
        let dome = crate::synth::Dome {
            radius_px: 220.0 / rim.sin(),
            rim_polar_rad: rim,
        };
        sensor.dome = Some(dome);
        (sensor.rest_markers(), dome.radius_px, sensor.centre)
    }

    /// A ring of points at equal arc distance around a skin point at 50 deg
    /// from the apex: on the sphere their mean is that point; in the image
    /// the plain mean falls short of it, towards the apex.
    #[test]
    fn surface_mean_of_a_ring_on_the_dome_is_its_centre() {
        let d = Dome {
            centre: PointPx::new(320.0, 240.0),
            radius_px: 260.0,
        };
        let dome = Surface::Dome(d);
        let (theta, phi) = (50f64.to_radians(), 0.6f64);
        let axis = [
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        ];
        // Two unit vectors perpendicular to the axis.
        let e1 = [
            theta.cos() * phi.cos(),
            theta.cos() * phi.sin(),
            -theta.sin(),
        ];
        let e2 = [-phi.sin(), phi.cos(), 0.0];
        let image = |v: [f64; 3]| PointPx::new(320.0 + 260.0 * v[0], 240.0 + 260.0 * v[1]);
        let truth = image(axis);
        let ring = 0.15f64; // rad: 39 px of arc
        let (mut on_skin, mut flat) = (SurfaceMean::new(dome), SurfaceMean::new(Surface::Flat));
        for k in 0..24 {
            let a = k as f64 * std::f64::consts::TAU / 24.0;
            let v: Vec<f64> = (0..3)
                .map(|i| ring.cos() * axis[i] + ring.sin() * (a.cos() * e1[i] + a.sin() * e2[i]))
                .collect();
            let p = image([v[0], v[1], v[2]]);
            on_skin.add(p, 1.0);
            flat.add(p, 1.0);
        }
        let m = on_skin.mean().unwrap();
        assert!(
            (m.x - truth.x).hypot(m.y - truth.y) < 1e-9,
            "{m:?} vs {truth:?}"
        );
        let f = flat.mean().unwrap();
        let towards_apex =
            (truth.x - 320.0).hypot(truth.y - 240.0) - (f.x - 320.0).hypot(f.y - 240.0);
        assert!(
            towards_apex > 1.0,
            "the image mean is {towards_apex} px short"
        );
        // Nothing added, or only weights that are not positive: no mean.
        let mut empty = SurfaceMean::new(dome);
        empty.add(truth, 0.0);
        empty.add(truth, f64::NAN);
        assert!(empty.mean().is_none());
    }

    #[test]
    fn chart_round_trips_and_is_the_image_near_the_apex() {
        let d = Dome {
            centre: PointPx::new(320.0, 240.0),
            radius_px: 230.0,
        };
        for p in [
            PointPx::new(320.0, 240.0),
            PointPx::new(400.0, 200.0),
            PointPx::new(320.0 + 200.0, 240.0),
            PointPx::new(170.0, 360.0),
        ] {
            let back = d.from_chart(d.to_chart(p));
            assert!(
                (back.x - p.x).abs() < 1e-9 && (back.y - p.y).abs() < 1e-9,
                "{p:?} {back:?}"
            );
        }
        let near = d.to_chart(PointPx::new(321.0, 240.0));
        assert!((near.x - 321.0).abs() < 1e-4);
        // Beyond the chart's reach: clamped, finite.
        assert!(d.to_chart(PointPx::new(1e6, -1e6)).is_finite());
    }

    #[test]
    fn great_circles_are_straight_in_the_chart() {
        // Points along one great circle (rotating a rim point towards another
        // through the sphere), seen in the image, lie on one chart line.
        let d = Dome {
            centre: PointPx::new(0.0, 0.0),
            radius_px: 100.0,
        };
        let (a, b) = ([0.8f64, 0.1, 0.0], [-0.2f64, 0.7, 0.0]);
        let za = (1.0 - a[0] * a[0] - a[1] * a[1]).sqrt();
        let zb = (1.0 - b[0] * b[0] - b[1] * b[1]).sqrt();
        let (a, b) = ([a[0], a[1], za], [b[0], b[1], zb]);
        let pts: Vec<PointPx> = (0..=10)
            .map(|k| {
                let t = k as f64 / 10.0;
                let v: Vec<f64> = (0..3).map(|i| (1.0 - t) * a[i] + t * b[i]).collect();
                let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                d.to_chart(PointPx::new(100.0 * v[0] / n, 100.0 * v[1] / n))
            })
            .collect();
        let (p0, p1) = (pts[0], pts[10]);
        let len = (p1.x - p0.x).hypot(p1.y - p0.y);
        for p in &pts {
            let off = ((p1.x - p0.x) * (p.y - p0.y) - (p1.y - p0.y) * (p.x - p0.x)) / len;
            assert!(off.abs() < 1e-9, "{off}");
        }
    }

    #[test]
    fn a_configured_dome_is_mapped_to_working_px() {
        let map = WorkToInput {
            scale_x: 2.0,
            scale_y: 2.0,
            origin_px: PointPx::new(100.0, 50.0),
        };
        let spec = SurfaceSpec::Dome {
            centre_px: [739.5, 529.5],
            radius_px: 500.0,
        };
        let Surface::Dome(d) = spec.resolve(&[], map) else {
            panic!("not a dome");
        };
        let back = map.apply(d.centre);
        assert!((back.x - 739.5).abs() < 1e-9 && (back.y - 529.5).abs() < 1e-9);
        assert_eq!(d.radius_px, 250.0);
        assert_eq!(SurfaceSpec::Flat.resolve(&[], map), Surface::Flat);
        assert!(spec.problem().is_none());
        let bad = SurfaceSpec::Dome {
            centre_px: [f64::NAN, 1.0],
            radius_px: 5.0,
        };
        assert!(bad.problem().is_some());
    }

    #[test]
    fn a_dome_is_found_with_its_radius_and_a_flat_skin_stays_flat() {
        // Rims at 40 and 65 deg (foreshortening 0.77 and 0.42).
        for rim_deg in [40.0, 65.0] {
            let (pts, radius_px, apex) = dome_lattice(rim_deg);
            let Surface::Dome(d) = estimate(&pts) else {
                panic!("rim {rim_deg} deg: taken for flat");
            };
            let rel = (d.radius_px - radius_px).abs() / radius_px;
            assert!(
                rel < 0.03,
                "rim {rim_deg}: radius {} vs {radius_px}",
                d.radius_px
            );
            assert!((d.centre.x - apex.x).abs() < 2.0 && (d.centre.y - apex.y).abs() < 2.0);
        }
        let flat = crate::synth::SensorSpec::nominal(640, 480).rest_markers();
        assert_eq!(estimate(&flat), Surface::Flat);
        assert_eq!(estimate(&[]), Surface::Flat);
        let nan = vec![PointPx::new(f64::NAN, 1.0); 50];
        assert_eq!(estimate(&nan), Surface::Flat);
    }
}
