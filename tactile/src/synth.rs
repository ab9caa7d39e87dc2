//! Seeded synthetic marker-type tactile frames with ground truth.
//!
//! A DigiTac-like skin: a hex grid of bright markers (~6-8 px, ~15 px pitch)
//! on dark skin inside a round or rounded-rectangle sensing area. A pressing
//! contact at `c` with width `w` and strength `k` moves each marker at `p` by
//! the radial field `k (p - c) exp(-|p - c|^2 / 2w^2)` (largest move
//! `0.61 k w` at `|p - c| = w`; the density at `c` falls to `1/(1+k)^2` of
//! rest), plus an optional shear `s exp(-|p - c|^2 / 2(1.5w)^2)`. The true
//! contact centre is where the skin point under the indenter's centre ends up:
//! `c + s`. Rendering adds blur, vignetting and uneven light, gain
//! (saturation), Gaussian noise and marker dropout.
//!
//! Conditions the flat skin above never shows, each off by default (so the
//! frames of the original categories are byte-identical to what they were)
//! and each seeded:
//! - [`FrameConditions`]: light and focus of a frame that differ from its
//!   rest frame (gain, vignetting, a linear light gradient, extra noise, a
//!   wider Gaussian PSF); [`rest_frame`] always renders under the sensor's
//!   own, nominal conditions;
//! - [`SensorSpec::psf_sigma_px`]: a Gaussian point-spread function over the
//!   whole image ([`gaussian_blur`], separable);
//! - [`Texture`]: low-contrast value-noise texture of the skin, moving with
//!   the skin on a flat sensor (static on a dome);
//! - [`Dome`]: a TacTip-like hemisphere seen from inside (orthographic):
//!   markers foreshortened into ellipses, pitch shrinking towards the rim,
//!   contacts acting along the dome's surface;
//! - [`Housing`]: a bright housing outside the sensing area with a dark bezel,
//!   saturated LEDs, dust specks and a reflection;
//! - [`PinColours`]: a fraction of dimmer (bluish) pins;
//! - [`SensorSpec::rim_clamp_px`]: skin glued at the rim (the displacement
//!   tapers to zero at the outline).
//!
//! Everything is reproducible from a `u64` seed (SplitMix64; no external RNG).
//! [`Category`] gives the scene families used by tests and benchmarks:
//! [`Category::ALL`] the original ones, [`Category::CONDITIONS`] the ones
//! with the conditions above.

use crate::frame::{gaussian_blur, GreyFrame};
use crate::PointPx;

/// Small, fast, seeded PRNG (SplitMix64). Not for cryptography.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// A generator from a seed; equal seeds give equal streams.
    pub fn new(seed: u64) -> Self {
        Self(seed ^ 0x9E37_79B9_7F4A_7C15)
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.unit()
    }

    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.unit().max(1e-300);
        let u2 = self.unit();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// Outline of the sensing area (markers exist only inside).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// Disc of the given radius around the sensor centre.
    Round {
        /// Radius, px.
        radius_px: f64,
    },
    /// Rounded rectangle around the sensor centre.
    RoundedRect {
        /// Half width, px.
        half_width_px: f64,
        /// Half height, px.
        half_height_px: f64,
        /// Corner radius, px.
        corner_px: f64,
    },
}

impl Shape {
    /// Signed distance from the outline (negative inside), px, for a point
    /// relative to the sensor centre.
    pub fn signed_distance_px(&self, dx: f64, dy: f64) -> f64 {
        match *self {
            Shape::Round { radius_px } => dx.hypot(dy) - radius_px,
            Shape::RoundedRect {
                half_width_px,
                half_height_px,
                corner_px,
            } => {
                let qx = dx.abs() - (half_width_px - corner_px);
                let qy = dy.abs() - (half_height_px - corner_px);
                qx.max(0.0).hypot(qy.max(0.0)) + qx.max(qy).min(0.0) - corner_px
            }
        }
    }

    /// Inscribed radius: distance from the centre to the nearest outline point.
    pub fn inner_radius_px(&self) -> f64 {
        match *self {
            Shape::Round { radius_px } => radius_px,
            Shape::RoundedRect {
                half_width_px,
                half_height_px,
                ..
            } => half_width_px.min(half_height_px),
        }
    }
}

/// The sensing area of a sensor in the image: its outline around its centre
/// (part of the truth of every frame: detections outside it are not
/// markers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensingArea {
    /// Outline.
    pub shape: Shape,
    /// Centre, px.
    pub centre: PointPx,
}

impl SensingArea {
    /// Signed distance of an image point from the outline (negative inside),
    /// px.
    pub fn signed_distance_px(&self, p: PointPx) -> f64 {
        self.shape
            .signed_distance_px(p.x - self.centre.x, p.y - self.centre.y)
    }

    /// True for points inside the outline.
    pub fn contains(&self, p: PointPx) -> bool {
        self.signed_distance_px(p) < 0.0
    }
}

/// How a frame's light and focus differ from its rest frame's (a lamp that
/// dims or brightens, a camera refocusing, more sensor noise). Applied by
/// [`render`] on top of the sensor's own optics; [`rest_frame`] ignores it.
/// [`FrameConditions::NONE`] changes nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameConditions {
    /// Overall light gain against rest (1/3: markers a third as bright;
    /// 3: saturated markers with wide flat tops).
    pub gain: f64,
    /// Vignetting: light at the image corners relative to the image centre,
    /// falling quadratically with the distance from the centre (1: none).
    pub corner_light: f64,
    /// Linear light gradient: light changes by this fraction from one side
    /// of the image to the other (0.3: +-15 % about the middle).
    pub gradient: f64,
    /// Direction in which the light grows, rad (0: left to right).
    pub gradient_angle_rad: f64,
    /// Extra Gaussian noise, grey levels (added in quadrature to the
    /// sensor's).
    pub extra_noise_sigma: f64,
    /// Gaussian PSF sigma of the frame, px, replacing the sensor's
    /// [`SensorSpec::psf_sigma_px`] (`None`: the sensor's).
    pub psf_sigma_px: Option<f64>,
}

impl FrameConditions {
    /// The rest frame's conditions: no change.
    pub const NONE: FrameConditions = FrameConditions {
        gain: 1.0,
        corner_light: 1.0,
        gradient: 0.0,
        gradient_angle_rad: 0.0,
        extra_noise_sigma: 0.0,
        psf_sigma_px: None,
    };

    /// The light factor of these conditions at pixel `(x, y)` of a `w x h`
    /// image.
    pub fn light_at(&self, x: f64, y: f64, w: usize, h: usize) -> f64 {
        let (cx, cy) = (w as f64 / 2.0 - 0.5, h as f64 / 2.0 - 0.5);
        let (dx, dy) = (x - cx, y - cy);
        let corner2 = (cx * cx + cy * cy).max(1.0);
        let vignette = 1.0 - (1.0 - self.corner_light) * (dx * dx + dy * dy) / corner2;
        let (c, s) = (self.gradient_angle_rad.cos(), self.gradient_angle_rad.sin());
        let extent = (w as f64 * c).abs() + (h as f64 * s).abs();
        let t = (dx * c + dy * s) / extent.max(1.0);
        self.gain * vignette * (1.0 + self.gradient * t)
    }
}

impl Default for FrameConditions {
    fn default() -> Self {
        Self::NONE
    }
}

/// A TacTip-like dome seen from inside by an orthographic camera on its
/// axis: a skin point at polar angle `theta` (from the apex, the image's
/// sensing-area centre) and azimuth `phi` appears at radius
/// `radius_px sin(theta)`. The markers lie on a hex lattice laid out along
/// the dome (azimuthal equidistant: arc length from the apex = lattice
/// distance), so in the image the radial pitch shrinks by `cos(theta)`, the
/// tangential one by `sin(theta) / theta`, and every marker is an ellipse
/// foreshortened by `cos(theta)` along the radius. Contacts act along the
/// dome's surface (widths and displacements are arc lengths).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dome {
    /// Sphere radius, image px.
    pub radius_px: f64,
    /// Polar angle of the dome's rim (the edge of the sensing area), rad.
    pub rim_polar_rad: f64,
}

pub(crate) type Vec3 = [f64; 3];

pub(crate) fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Rotation of `v` about the unit axis `k` by `angle` (Rodrigues).
pub(crate) fn rotate(v: Vec3, k: Vec3, angle: f64) -> Vec3 {
    let (s, c) = angle.sin_cos();
    let kv = cross(k, v);
    let kd = dot(k, v) * (1.0 - c);
    [
        v[0] * c + kv[0] * s + k[0] * kd,
        v[1] * c + kv[1] * s + k[1] * kd,
        v[2] * c + kv[2] * s + k[2] * kd,
    ]
}

pub(crate) fn normalized(v: Vec3) -> Option<Vec3> {
    let n = dot(v, v).sqrt();
    (n > 1e-12).then(|| [v[0] / n, v[1] / n, v[2] / n])
}

impl Dome {
    /// Image radius of the rim (the sensing area's radius), px.
    pub fn rim_radius_px(&self) -> f64 {
        self.radius_px * self.rim_polar_rad.sin()
    }

    /// The unit vector of the dome point seen at image point `p` (points
    /// beyond the equator map onto it).
    pub fn lift(&self, centre: PointPx, p: PointPx) -> DomePoint {
        let (x, y) = (
            (p.x - centre.x) / self.radius_px,
            (p.y - centre.y) / self.radius_px,
        );
        let r = x.hypot(y);
        let (x, y) = if r > 1.0 { (x / r, y / r) } else { (x, y) };
        DomePoint([x, y, (1.0 - x * x - y * y).max(0.0).sqrt()])
    }

    /// The image point of the dome point with unit vector `v`.
    pub fn project(&self, centre: PointPx, v: DomePoint) -> PointPx {
        PointPx::new(
            centre.x + self.radius_px * v.0[0],
            centre.y + self.radius_px * v.0[1],
        )
    }

    /// Foreshortening `cos(theta)` of the dome at image point `p` (1 at the
    /// apex, `cos(rim_polar_rad)` at the rim).
    pub fn foreshortening(&self, centre: PointPx, p: PointPx) -> f64 {
        self.lift(centre, p).0[2]
    }

    /// Arc length along the dome from the point seen at `p` to the rim, px
    /// (negative beyond the rim).
    pub fn arc_to_rim_px(&self, centre: PointPx, p: PointPx) -> f64 {
        let polar = self.lift(centre, p).0[2].clamp(-1.0, 1.0).acos();
        self.radius_px * (self.rim_polar_rad - polar)
    }
}

/// A unit vector on a [`Dome`] (x right, y down, z towards the camera).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DomePoint(pub [f64; 3]);

/// Low-contrast skin texture: smooth value noise (two octaves, quintic
/// interpolation of hashed lattice values) of a few grey levels, inside the
/// sensing area only. On a flat sensor with `follows_skin` it is printed on
/// the skin and moves with it (each pixel samples the texture at the rest
/// point that the contacts moved there); otherwise (and always on a dome) it
/// is static, fixed to the image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Texture {
    /// Largest deviation from the skin level, grey levels (before light).
    pub amplitude: f64,
    /// Lattice cell of the coarse octave (feature size), px.
    pub cell_px: f64,
    /// Texture seed.
    pub seed: u64,
    /// The texture moves with the skin (flat sensors only).
    pub follows_skin: bool,
}

impl Texture {
    /// Texture value at skin point `(x, y)`, grey levels, in
    /// `[-amplitude, amplitude]`.
    pub fn value(&self, x: f64, y: f64) -> f64 {
        let coarse = value_noise(x / self.cell_px, y / self.cell_px, self.seed);
        let fine = value_noise(
            2.0 * x / self.cell_px,
            2.0 * y / self.cell_px,
            self.seed ^ 0xF1E,
        );
        self.amplitude * (0.65 * coarse + 0.35 * fine)
    }
}

/// SplitMix64 finaliser of a lattice point and seed.
fn hash3(a: i64, b: i64, seed: u64) -> u64 {
    let mut z = seed
        .wrapping_add((a as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15))
        .wrapping_add((b as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

fn hash_unit(a: i64, b: i64, seed: u64) -> f64 {
    (hash3(a, b, seed) >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Value noise in `[-1, 1]` with unit lattice cells.
fn value_noise(x: f64, y: f64, seed: u64) -> f64 {
    let (fx, fy) = (x.floor(), y.floor());
    let (i, j) = (fx as i64, fy as i64);
    let quintic = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (u, v) = (quintic(x - fx), quintic(y - fy));
    let at = |a, b| 2.0 * hash_unit(a, b, seed) - 1.0;
    let top = at(i, j) + (at(i + 1, j) - at(i, j)) * u;
    let bottom = at(i, j + 1) + (at(i + 1, j + 1) - at(i, j + 1)) * u;
    top + (bottom - top) * v
}

/// Pins of two colours: real TacTips mix white and bluish pins, and the
/// bluish ones are dimmer in grey. Which rest marker is dim is fixed by the
/// seed and the marker's index (the same pins in the rest frame and every
/// frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PinColours {
    /// Fraction of dim pins.
    pub dim_fraction: f64,
    /// Brightness of a dim pin relative to a white one (its contrast above
    /// the skin).
    pub dim_level: f64,
    /// Seed of the choice.
    pub seed: u64,
}

impl PinColours {
    /// Relative brightness of rest marker `index`.
    pub fn level(&self, index: usize) -> f64 {
        if hash_unit(index as i64, 0x9195, self.seed) < self.dim_fraction {
            self.dim_level
        } else {
            1.0
        }
    }
}

/// A Gaussian spot, added to the image before light and noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spot {
    /// Centre, px.
    pub at: PointPx,
    /// Gaussian sigma, px.
    pub sigma_px: f64,
    /// Peak, grey levels (negative: dark).
    pub amplitude: f64,
}

/// An elongated Gaussian streak (a reflection), added before light and noise.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Streak {
    /// Centre, px.
    pub at: PointPx,
    /// Direction of the long axis, rad.
    pub angle_rad: f64,
    /// Half length of the flat part along the long axis, px.
    pub half_length_px: f64,
    /// Gaussian sigma across (and at the ends), px.
    pub sigma_px: f64,
    /// Peak, grey levels.
    pub amplitude: f64,
}

impl Streak {
    fn value(&self, x: f64, y: f64) -> f64 {
        let (dx, dy) = (x - self.at.x, y - self.at.y);
        let (c, s) = (self.angle_rad.cos(), self.angle_rad.sin());
        let along = ((dx * c + dy * s).abs() - self.half_length_px).max(0.0);
        let across = -dx * s + dy * c;
        let r2 = (along * along + across * across) / (self.sigma_px * self.sigma_px);
        self.amplitude * (-0.5 * r2).exp()
    }
}

/// What the housing around the sensing area shows: a dark bezel ring just
/// outside the outline, then the bright housing, with very bright LEDs
/// (saturated spots) on the bezel, dust specks (bright on the bezel, dark on
/// the housing) and a reflection streak along the bezel: the things that
/// give false detections outside the pin disc. The features are listed
/// explicitly (see [`Housing::random`]) and are the same in the rest frame
/// and every frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Housing {
    /// Housing grey level (before light; above 255 clips).
    pub level: f64,
    /// Width of the dark bezel ring outside the outline, px.
    pub bezel_px: f64,
    /// Bezel grey level.
    pub bezel_level: f64,
    /// LEDs (centres outside the sensing area, on the bezel).
    pub leds: Vec<Spot>,
    /// Dust specks.
    pub specks: Vec<Spot>,
    /// Reflections.
    pub reflections: Vec<Streak>,
}

impl Housing {
    /// A random housing around `sensor`'s sensing area: level 250-320 (white,
    /// clipping where the light is full), bezel
    /// 8-14 px (scaled to the image), 4-8 LEDs evenly round the bezel with
    /// jitter, 12-24 dust specks and one reflection on the bezel.
    pub fn random(sensor: &SensorSpec, seed: u64) -> Self {
        let mut rng = Rng::new(seed ^ 0x4005_1E60);
        let s = scale_of(sensor.width_px, sensor.height_px);
        let area = sensor.sensing_area();
        let bezel_px = rng.range(8.0, 14.0) * s;
        // A point at distance `d` outside the outline in direction `a` (found
        // by bisection on the signed distance, so any outline works).
        let outside = |a: f64, d: f64| {
            let (c, sn) = (a.cos(), a.sin());
            let at = |t: f64| PointPx::new(area.centre.x + t * c, area.centre.y + t * sn);
            let (mut lo, mut hi) = (0.0, (sensor.width_px + sensor.height_px) as f64);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if area.signed_distance_px(at(mid)) < d {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            at(0.5 * (lo + hi))
        };
        let n_leds = 4 + (rng.unit() * 5.0) as usize;
        let a0 = rng.range(0.0, std::f64::consts::TAU);
        let leds = (0..n_leds)
            .map(|i| {
                let a =
                    a0 + std::f64::consts::TAU * (i as f64 + rng.range(-0.2, 0.2)) / n_leds as f64;
                Spot {
                    at: outside(a, bezel_px * rng.range(0.35, 0.65)),
                    sigma_px: rng.range(1.5, 2.5) * s,
                    amplitude: rng.range(1200.0, 2000.0),
                }
            })
            .collect();
        let n_specks = 12 + (rng.unit() * 13.0) as usize;
        let (w, h) = (sensor.width_px as f64, sensor.height_px as f64);
        let mut specks = Vec::with_capacity(n_specks);
        let mut tries = 0;
        while specks.len() < n_specks && tries < 10_000 {
            tries += 1;
            // Half the specks on the bezel, half anywhere outside.
            let at = if specks.len() % 2 == 0 {
                outside(
                    rng.range(0.0, std::f64::consts::TAU),
                    bezel_px * rng.range(0.2, 0.8),
                )
            } else {
                PointPx::new(rng.range(0.0, w), rng.range(0.0, h))
            };
            let d = area.signed_distance_px(at);
            if d < 2.0 * s {
                continue;
            }
            let on_bezel = d < bezel_px;
            specks.push(Spot {
                at,
                sigma_px: rng.range(0.7, 1.6) * s,
                amplitude: if on_bezel {
                    rng.range(60.0, 140.0)
                } else {
                    -rng.range(70.0, 150.0)
                },
            });
        }
        let a = rng.range(0.0, std::f64::consts::TAU);
        let at = outside(a, 0.5 * bezel_px);
        let reflections = vec![Streak {
            at,
            angle_rad: a + std::f64::consts::FRAC_PI_2,
            half_length_px: rng.range(10.0, 25.0) * s,
            sigma_px: rng.range(1.5, 2.5) * s,
            amplitude: rng.range(90.0, 160.0),
        }];
        Self {
            level: rng.range(250.0, 320.0),
            bezel_px,
            bezel_level: 12.0,
            leds,
            specks,
            reflections,
        }
    }

    /// Grey level outside the outline at signed distance `d` (positive
    /// outside), before the spots: bezel, then housing.
    fn outside_level(&self, d: f64, soft: f64) -> f64 {
        self.bezel_level + (self.level - self.bezel_level) * soft_step(d - self.bezel_px, soft)
    }
}

/// One sensor: geometry, skin and optics. Fixed for a rest frame and all
/// frames compared with it, except [`SensorSpec::frame_conditions`], which
/// only frames (not the rest frame) are rendered under.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorSpec {
    /// Image width, px.
    pub width_px: usize,
    /// Image height, px.
    pub height_px: usize,
    /// Sensing area outline (with a [`Dome`], the dome's rim:
    /// [`SensorSpec::sensing_area`]).
    pub shape: Shape,
    /// Sensing area centre.
    pub centre: PointPx,
    /// Hex grid pitch, px (on a dome: arc length along the dome).
    pub pitch_px: f64,
    /// Lattice origin offset, px (moves the grid against the outline).
    pub lattice_offset: PointPx,
    /// Marker diameter, px (on a dome: before foreshortening).
    pub marker_diameter_px: f64,
    /// Optical blur (edge softness) sigma, px.
    pub blur_sigma_px: f64,
    /// Gaussian noise sigma, grey levels.
    pub noise_sigma: f64,
    /// Vignetting: light falls by this fraction at the sensor rim.
    pub vignette: f64,
    /// Uneven light: left-to-right gain change over the image width.
    pub light_gradient: f64,
    /// Overall gain; > 1 saturates the markers.
    pub gain: f64,
    /// Skin (background) grey level inside the sensing area.
    pub skin_level: f64,
    /// Marker grey level above the skin.
    pub marker_contrast: f64,
    /// Gaussian point-spread function over the whole image (separable
    /// [`gaussian_blur`] before light and noise), px; 0: none.
    pub psf_sigma_px: f64,
    /// Domed skin (`None`: flat).
    pub dome: Option<Dome>,
    /// Housing around the sensing area (`None`: uniformly dark outside).
    pub housing: Option<Housing>,
    /// Skin texture (`None`: uniform skin).
    pub texture: Option<Texture>,
    /// Pins of two colours (`None`: all alike).
    pub pin_colours: Option<PinColours>,
    /// Skin glued at the rim: every contact's displacement of a skin point
    /// at distance `d` inside the outline (on a dome: arc length to the rim)
    /// is scaled by `1 - exp(-d / rim_clamp_px)`, zero at the rim. `None`:
    /// free skin.
    pub rim_clamp_px: Option<f64>,
    /// Light and focus of the frames against the rest frame.
    pub frame_conditions: FrameConditions,
}

impl SensorSpec {
    /// A nominal DigiTac-like sensor: round, 15 px pitch, 7 px markers, scaled
    /// to the image size (reference 640x480).
    pub fn nominal(width_px: usize, height_px: usize) -> Self {
        let s = scale_of(width_px, height_px);
        Self {
            width_px,
            height_px,
            shape: Shape::Round {
                radius_px: 220.0 * s,
            },
            centre: PointPx::new(width_px as f64 / 2.0 - 0.5, height_px as f64 / 2.0 - 0.5),
            pitch_px: 15.0 * s,
            lattice_offset: PointPx::new(0.0, 0.0),
            marker_diameter_px: 7.0 * s,
            blur_sigma_px: 0.7 * s,
            noise_sigma: 2.0,
            vignette: 0.2,
            light_gradient: 0.0,
            gain: 1.0,
            skin_level: 25.0,
            marker_contrast: 170.0,
            psf_sigma_px: 0.0,
            dome: None,
            housing: None,
            texture: None,
            pin_colours: None,
            rim_clamp_px: None,
            frame_conditions: FrameConditions::NONE,
        }
    }

    /// A TacTip-like domed sensor: a dome whose rim (polar angle 65 deg) is
    /// seen at the nominal sensor's radius (220 px at 640x480), 7 px markers
    /// at a 16.5 px arc pitch: about 950 markers at 640x480.
    pub fn domed(width_px: usize, height_px: usize) -> Self {
        let s = scale_of(width_px, height_px);
        let mut sensor = Self::nominal(width_px, height_px);
        let rim_polar_rad = 65f64.to_radians();
        let dome = Dome {
            radius_px: 220.0 * s / rim_polar_rad.sin(),
            rim_polar_rad,
        };
        sensor.shape = Shape::Round {
            radius_px: dome.rim_radius_px(),
        };
        sensor.dome = Some(dome);
        sensor.pitch_px = 16.5 * s;
        sensor
    }

    /// The sensing area (with a dome: the disc inside its rim).
    pub fn sensing_area(&self) -> SensingArea {
        let shape = match self.dome {
            Some(d) => Shape::Round {
                radius_px: d.rim_radius_px(),
            },
            None => self.shape,
        };
        SensingArea {
            shape,
            centre: self.centre,
        }
    }

    /// This sensor as its rest frame is rendered: under
    /// [`FrameConditions::NONE`].
    pub fn at_rest(&self) -> SensorSpec {
        let mut s = self.clone();
        s.frame_conditions = FrameConditions::NONE;
        s
    }

    /// Rest marker positions (hex grid inside the outline, one marker radius
    /// from the rim; on a dome, laid out along the dome and projected).
    pub fn rest_markers(&self) -> Vec<PointPx> {
        if let Some(dome) = self.dome {
            return self.dome_rest_markers(&dome);
        }
        let pitch = self.pitch_px;
        let row_h = pitch * 3f64.sqrt() / 2.0;
        let r = self.marker_diameter_px / 2.0;
        let mut out = Vec::new();
        let rows = (self.height_px as f64 / row_h) as i64 + 2;
        let cols = (self.width_px as f64 / pitch) as i64 + 2;
        for j in -rows..=rows {
            for i in -cols..=cols {
                let shift = if j.rem_euclid(2) == 1 {
                    pitch / 2.0
                } else {
                    0.0
                };
                let x = self.centre.x + self.lattice_offset.x + i as f64 * pitch + shift;
                let y = self.centre.y + self.lattice_offset.y + j as f64 * row_h;
                let d = self
                    .shape
                    .signed_distance_px(x - self.centre.x, y - self.centre.y);
                if d <= -r {
                    out.push(PointPx::new(x, y));
                }
            }
        }
        out
    }

    fn dome_rest_markers(&self, dome: &Dome) -> Vec<PointPx> {
        let pitch = self.pitch_px;
        let row_h = pitch * 3f64.sqrt() / 2.0;
        let r = self.marker_diameter_px / 2.0;
        // Largest arc from the apex of a marker centre.
        let max_arc = dome.radius_px * dome.rim_polar_rad - r;
        let reach = max_arc + pitch + self.lattice_offset.x.abs() + self.lattice_offset.y.abs();
        let rows = (reach / row_h) as i64 + 2;
        let cols = (reach / pitch) as i64 + 2;
        let mut out = Vec::new();
        for j in -rows..=rows {
            for i in -cols..=cols {
                let shift = if j.rem_euclid(2) == 1 {
                    pitch / 2.0
                } else {
                    0.0
                };
                let qx = self.lattice_offset.x + i as f64 * pitch + shift;
                let qy = self.lattice_offset.y + j as f64 * row_h;
                let arc = qx.hypot(qy);
                if arc > max_arc {
                    continue;
                }
                let polar = arc / dome.radius_px;
                let k = if arc > 0.0 {
                    dome.radius_px * polar.sin() / arc
                } else {
                    1.0
                };
                out.push(PointPx::new(self.centre.x + k * qx, self.centre.y + k * qy));
            }
        }
        out
    }

    /// Rim-clamp factor of the displacement at rest point `p` (1 for free
    /// skin, 0 at and beyond the rim).
    pub fn rim_factor(&self, p: PointPx) -> f64 {
        let Some(l) = self.rim_clamp_px else {
            return 1.0;
        };
        let d = match self.dome {
            Some(dome) => dome.arc_to_rim_px(self.centre, p),
            None => -self.sensing_area().signed_distance_px(p),
        };
        if d <= 0.0 {
            0.0
        } else {
            1.0 - (-d / l.max(1e-9)).exp()
        }
    }

    /// Where the skin point seen at rest at `p` is seen under `presses`.
    pub fn displaced(&self, p: PointPx, presses: &[Press]) -> PointPx {
        if let Some(dome) = self.dome {
            return self.dome_displaced(&dome, p, presses);
        }
        let mut q = p;
        if self.rim_clamp_px.is_none() {
            for press in presses {
                let u = press.displacement(p);
                q.x += u.x;
                q.y += u.y;
            }
        } else {
            let f = self.rim_factor(p);
            for press in presses {
                let u = press.displacement(p);
                q.x += f * u.x;
                q.y += f * u.y;
            }
        }
        q
    }

    /// Displacement of the skin point seen at rest at `p`, image px.
    pub fn displacement_at(&self, p: PointPx, presses: &[Press]) -> PointPx {
        let q = self.displaced(p, presses);
        PointPx::new(q.x - p.x, q.y - p.y)
    }

    fn dome_displaced(&self, dome: &Dome, p: PointPx, presses: &[Press]) -> PointPx {
        let m0 = dome.lift(self.centre, p).0;
        let f = self.rim_factor(p);
        let mut m = m0;
        for press in presses {
            let c = dome.lift(self.centre, press.centre).0;
            let g = dome.radius_px * dot(m0, c).clamp(-1.0, 1.0).acos();
            let w2 = press.width_px * press.width_px;
            // Radial: away from the press centre along the great circle.
            let arc = if press.flat_radius_px > 0.0 {
                f * press.radial_px(g)
            } else {
                f * press.strength * g * (-g * g / (2.0 * w2)).exp()
            };
            if let Some(axis) = normalized(cross(c, m0)) {
                m = rotate(m, axis, arc / dome.radius_px);
            }
            // Shear: along the shear's direction in the tangent plane at c.
            if let Some(axis) = shear_axis(c, press.shear_px) {
                let s = press.shear_px.x.hypot(press.shear_px.y);
                let arc = f * s * (-g * g / (2.0 * 2.25 * w2)).exp();
                m = rotate(m, axis, arc / dome.radius_px);
            }
        }
        dome.project(self.centre, DomePoint(m))
    }

    /// Where the indenter's centre of `press` appears in the image (the
    /// truth): the press centre moved by its shear (scaled by the rim clamp,
    /// along the dome on a dome).
    pub fn visible_centre(&self, press: &Press) -> PointPx {
        match self.dome {
            None if self.rim_clamp_px.is_none() => press.visible_centre(),
            None => {
                let f = self.rim_factor(press.centre);
                PointPx::new(
                    press.centre.x + f * press.shear_px.x,
                    press.centre.y + f * press.shear_px.y,
                )
            }
            Some(dome) => {
                let c = dome.lift(self.centre, press.centre).0;
                let m = match shear_axis(c, press.shear_px) {
                    Some(axis) => {
                        let s = press.shear_px.x.hypot(press.shear_px.y);
                        let arc = self.rim_factor(press.centre) * s;
                        rotate(c, axis, arc / dome.radius_px)
                    }
                    None => c,
                };
                dome.project(self.centre, DomePoint(m))
            }
        }
    }

    /// Relative brightness of rest marker `index` (1 unless
    /// [`SensorSpec::pin_colours`] makes it dim).
    pub fn marker_level(&self, index: usize) -> f64 {
        self.pin_colours.map_or(1.0, |p| p.level(index))
    }

    /// The rest point that `presses` move to image point `x` (inverse of
    /// [`SensorSpec::displaced`] by Newton's method; flat sensors).
    fn rest_point_of(&self, x: PointPx, presses: &[Press]) -> PointPx {
        let u = |p: PointPx| self.displacement_at(p, presses);
        let u0 = u(x);
        if u0.x.hypot(u0.y) < 1e-3 {
            return x;
        }
        let mut p = PointPx::new(x.x - u0.x, x.y - u0.y);
        for _ in 0..8 {
            let up = u(p);
            let (rx, ry) = (p.x + up.x - x.x, p.y + up.y - x.y);
            if rx.hypot(ry) < 1e-4 {
                break;
            }
            let e = 0.25;
            let (ax, ay) = (u(PointPx::new(p.x + e, p.y)), u(PointPx::new(p.x - e, p.y)));
            let (bx, by) = (u(PointPx::new(p.x, p.y + e)), u(PointPx::new(p.x, p.y - e)));
            let j11 = 1.0 + (ax.x - ay.x) / (2.0 * e);
            let j21 = (ax.y - ay.y) / (2.0 * e);
            let j12 = (bx.x - by.x) / (2.0 * e);
            let j22 = 1.0 + (bx.y - by.y) / (2.0 * e);
            let det = j11 * j22 - j12 * j21;
            if det.abs() < 1e-9 {
                break;
            }
            p.x -= (j22 * rx - j12 * ry) / det;
            p.y -= (-j21 * rx + j11 * ry) / det;
        }
        p
    }
}

/// Rotation axis that moves the dome point `c` along the image direction of
/// `shear` (`None` for no shear).
fn shear_axis(c: Vec3, shear: PointPx) -> Option<Vec3> {
    let s3 = [shear.x, shear.y, 0.0];
    let k = dot(s3, c);
    let t = normalized([s3[0] - k * c[0], s3[1] - k * c[1], s3[2] - k * c[2]])?;
    normalized(cross(c, t))
}

fn scale_of(width_px: usize, height_px: usize) -> f64 {
    (width_px as f64 / 640.0).min(height_px as f64 / 480.0)
}

/// A pressing contact.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Press {
    /// Press point on the rest skin.
    pub centre: PointPx,
    /// Contact width w, px.
    pub width_px: f64,
    /// Radial strength k (dimensionless, 0..~1.5).
    pub strength: f64,
    /// Shear displacement at the centre, px.
    pub shear_px: PointPx,
    /// Radius of a flat punch's face, px (0: a rounded indenter). The skin
    /// under the face moves as one (along the view: not at all in the
    /// image); the radial push starts at its edge, so the pins there part
    /// from the ones under it and the density dips in a ring around skin at
    /// rest (the other renderer's Boussinesq punches).
    pub flat_radius_px: f64,
}

impl Press {
    /// Displacement of a rest point by this press, px (flat free skin; see
    /// [`SensorSpec::displacement_at`] for domes and clamped skins).
    pub fn displacement(&self, p: PointPx) -> PointPx {
        let dx = p.x - self.centre.x;
        let dy = p.y - self.centre.y;
        let r2 = dx * dx + dy * dy;
        let w2 = self.width_px * self.width_px;
        let radial = if self.flat_radius_px > 0.0 {
            let r = r2.sqrt();
            self.radial_px(r) / r.max(f64::MIN_POSITIVE)
        } else {
            self.strength * (-r2 / (2.0 * w2)).exp()
        };
        let shear = (-r2 / (2.0 * 2.25 * w2)).exp();
        PointPx::new(
            radial * dx + shear * self.shear_px.x,
            radial * dy + shear * self.shear_px.y,
        )
    }

    /// How far this press pushes a skin point `r` px from its centre
    /// outwards, px: `k r exp(-r^2 / 2 w^2)`; for a flat punch 0 under the
    /// face and `k w exp(-d^2 / 2 w^2)` at `d = r - a` beyond its edge (the
    /// elastic slope is unbounded at a punch's edge: the pins there tilt
    /// most, and part from the ones under the face).
    pub fn radial_px(&self, r: f64) -> f64 {
        let w2 = self.width_px * self.width_px;
        if self.flat_radius_px <= 0.0 {
            return self.strength * r * (-r * r / (2.0 * w2)).exp();
        }
        let d = r - self.flat_radius_px;
        if d <= 0.0 {
            return 0.0;
        }
        self.strength * self.width_px * (-d * d / (2.0 * w2)).exp()
    }

    /// Where the indenter's centre appears in the image (the truth; flat free
    /// skin, see [`SensorSpec::visible_centre`]).
    pub fn visible_centre(&self) -> PointPx {
        PointPx::new(
            self.centre.x + self.shear_px.x,
            self.centre.y + self.shear_px.y,
        )
    }
}

/// A scene: a sensor, its contacts, dropout and the noise seed.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The sensor (its [`SensorSpec::frame_conditions`] are this frame's).
    pub sensor: SensorSpec,
    /// Contacts (empty: no contact).
    pub presses: Vec<Press>,
    /// Probability that a marker is not visible.
    pub dropout: f64,
    /// Seed of the noise and dropout.
    pub seed: u64,
}

/// What a housing feature is (see [`Housing`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DistractorKind {
    /// A saturated LED spot.
    Led,
    /// A dust speck.
    Speck,
    /// A reflection streak (its centre).
    Reflection,
}

/// A bright or dark feature outside the sensing area that is not a marker.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Distractor {
    /// Kind.
    pub kind: DistractorKind,
    /// Centre, px.
    pub at: PointPx,
}

/// A rendered frame with its ground truth.
#[derive(Debug, Clone)]
pub struct SynthFrame {
    /// The grey image.
    pub image: GreyFrame,
    /// True contact centres (largest press first); empty for no contact.
    pub contacts: Vec<PointPx>,
    /// Rest marker positions.
    pub rest_markers: Vec<PointPx>,
    /// Displaced positions of the visible markers (all inside the sensing
    /// area: their count is the true marker count).
    pub markers: Vec<PointPx>,
    /// Relative brightness of each of `markers` (1, or the dim pins' level).
    pub marker_levels: Vec<f64>,
    /// The sensing area.
    pub area: SensingArea,
    /// Housing features outside the sensing area (empty without a housing).
    pub distractors: Vec<Distractor>,
}

/// Renders a scene.
pub fn render(scene: &Scene) -> SynthFrame {
    let s = &scene.sensor;
    let mut rng = Rng::new(scene.seed);
    let rest = s.rest_markers();
    let area = s.sensing_area();
    let mut markers = Vec::with_capacity(rest.len());
    let mut marker_levels = Vec::with_capacity(rest.len());
    for (i, &p) in rest.iter().enumerate() {
        let visible = rng.unit() >= scene.dropout;
        let q = s.displaced(p, &scene.presses);
        if visible {
            markers.push(q);
            marker_levels.push(s.marker_level(i));
        }
    }
    let (w, h) = (s.width_px, s.height_px);
    let mut canvas = vec![0f32; w * h];
    // Skin inside the outline (soft edge), dark outside (or the housing).
    let edge = s.blur_sigma_px.max(0.5);
    for y in 0..h {
        for x in 0..w {
            let d = area
                .shape
                .signed_distance_px(x as f64 - s.centre.x, y as f64 - s.centre.y);
            let inside = soft_step(-d, edge);
            canvas[y * w + x] = match &s.housing {
                None => (5.0 + (s.skin_level - 5.0) * inside) as f32,
                Some(hs) => {
                    let out = hs.outside_level(d, edge);
                    (out + (s.skin_level - out) * inside) as f32
                }
            };
        }
    }
    if let Some(t) = &s.texture {
        add_texture(&mut canvas, s, t, &area, &scene.presses);
    }
    let r = s.marker_diameter_px / 2.0;
    let soft = s.blur_sigma_px.max(0.3);
    let reach = (r + 4.0 * soft).ceil() as i64;
    for (m, &level) in markers.iter().zip(&marker_levels) {
        let contrast = s.marker_contrast * level;
        let (cx, cy) = (m.x.round() as i64, m.y.round() as i64);
        // On a dome: an ellipse with semi-axes r cos(theta) (radial) and r.
        let ellipse = s.dome.map(|dome| {
            let (dx, dy) = (m.x - s.centre.x, m.y - s.centre.y);
            let rho = dx.hypot(dy).max(1e-9);
            (
                dx / rho,
                dy / rho,
                r * dome.foreshortening(s.centre, *m).max(0.05),
            )
        });
        for y in (cy - reach).max(0)..=(cy + reach).min(h as i64 - 1) {
            for x in (cx - reach).max(0)..=(cx + reach).min(w as i64 - 1) {
                let (px, py) = (x as f64 - m.x, y as f64 - m.y);
                let d = px.hypot(py);
                let inside = match ellipse {
                    None => r - d,
                    Some((ux, uy, a)) if d > 0.0 => {
                        let along = (px * ux + py * uy) / d;
                        let across = (py * ux - px * uy) / d;
                        1.0 / (along / a).hypot(across / r) - d
                    }
                    Some((_, _, a)) => a,
                };
                let v = contrast * soft_step(inside, soft);
                canvas[y as usize * w + x as usize] += v as f32;
            }
        }
    }
    let mut distractors = Vec::new();
    if let Some(hs) = &s.housing {
        add_housing(&mut canvas, w, h, hs, &mut distractors);
    }
    let psf = s.frame_conditions.psf_sigma_px.unwrap_or(s.psf_sigma_px);
    if psf > 0.0 {
        gaussian_blur(&mut canvas, w, h, psf);
    }
    let fc = &s.frame_conditions;
    let plain_light = fc.gain == 1.0 && fc.corner_light == 1.0 && fc.gradient == 0.0;
    let noise_sigma = if fc.extra_noise_sigma == 0.0 {
        s.noise_sigma
    } else {
        s.noise_sigma.hypot(fc.extra_noise_sigma)
    };
    let rim = area.shape.inner_radius_px().max(1.0);
    let mut data = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let dx = x as f64 - s.centre.x;
            let dy = y as f64 - s.centre.y;
            let rr = (dx * dx + dy * dy) / (rim * rim);
            let mut light = (1.0 - s.vignette * rr.min(1.5))
                * (1.0 + s.light_gradient * (x as f64 / w.max(1) as f64 - 0.5));
            if !plain_light {
                light *= fc.light_at(x as f64, y as f64, w, h);
            }
            let v = canvas[y * w + x] as f64 * light * s.gain + noise_sigma * rng.normal();
            data[y * w + x] = v.round().clamp(0.0, 255.0) as u8;
        }
    }
    let mut presses = scene.presses.clone();
    presses.sort_by(|a, b| b.width_px.total_cmp(&a.width_px));
    SynthFrame {
        // Invariant: `data` has exactly w * h bytes.
        image: GreyFrame::new(w, h, data).expect("synth frame size matches"),
        contacts: presses.iter().map(|p| s.visible_centre(p)).collect(),
        rest_markers: rest,
        markers,
        marker_levels,
        area,
        distractors,
    }
}

/// Adds the skin texture inside the sensing area.
fn add_texture(
    canvas: &mut [f32],
    s: &SensorSpec,
    t: &Texture,
    area: &SensingArea,
    presses: &[Press],
) {
    let (w, h) = (s.width_px, s.height_px);
    let moving = t.follows_skin && s.dome.is_none() && !presses.is_empty();
    let edge = s.blur_sigma_px.max(0.5);
    for y in 0..h {
        for x in 0..w {
            let p = PointPx::new(x as f64, y as f64);
            let d = area.signed_distance_px(p);
            if d > 4.0 * edge {
                continue;
            }
            let src = if moving {
                s.rest_point_of(p, presses)
            } else {
                p
            };
            let v = t.value(src.x, src.y) * soft_step(-d, edge);
            canvas[y * w + x] += v as f32;
        }
    }
}

/// Adds the housing's LEDs, specks and reflections, and lists them.
fn add_housing(canvas: &mut [f32], w: usize, h: usize, hs: &Housing, out: &mut Vec<Distractor>) {
    let mut spot = |sp: &Spot, kind| {
        out.push(Distractor { kind, at: sp.at });
        let reach = (4.0 * sp.sigma_px).ceil() as i64 + 1;
        let (cx, cy) = (sp.at.x.round() as i64, sp.at.y.round() as i64);
        for y in (cy - reach).max(0)..=(cy + reach).min(h as i64 - 1) {
            for x in (cx - reach).max(0)..=(cx + reach).min(w as i64 - 1) {
                let r2 = (x as f64 - sp.at.x).powi(2) + (y as f64 - sp.at.y).powi(2);
                let v = sp.amplitude * (-0.5 * r2 / (sp.sigma_px * sp.sigma_px)).exp();
                canvas[y as usize * w + x as usize] += v as f32;
            }
        }
    };
    for sp in &hs.leds {
        spot(sp, DistractorKind::Led);
    }
    for sp in &hs.specks {
        spot(sp, DistractorKind::Speck);
    }
    for st in &hs.reflections {
        out.push(Distractor {
            kind: DistractorKind::Reflection,
            at: st.at,
        });
        let reach = (st.half_length_px + 4.0 * st.sigma_px).ceil() as i64 + 1;
        let (cx, cy) = (st.at.x.round() as i64, st.at.y.round() as i64);
        for y in (cy - reach).max(0)..=(cy + reach).min(h as i64 - 1) {
            for x in (cx - reach).max(0)..=(cx + reach).min(w as i64 - 1) {
                canvas[y as usize * w + x as usize] += st.value(x as f64, y as f64) as f32;
            }
        }
    }
}

/// Smooth 0..1 step of a signed distance `d` (positive inside) with edge
/// softness `sigma` (logistic approximation of a blurred edge).
fn soft_step(d: f64, sigma: f64) -> f64 {
    1.0 / (1.0 + (-d / (0.6 * sigma)).exp())
}

/// Scene families for tests and benchmarks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Category {
    /// One contact, width 15-30 px, within half the radius of the centre.
    Nominal,
    /// One contact at 70-85 % of the sensor radius.
    Edge,
    /// One contact, width 40-60 px.
    Large,
    /// One tiny contact, width 4-8 px (below the kernel width).
    Small,
    /// Two contacts (one larger); truth is either.
    Two,
    /// Nominal contact with 1-4 px shear.
    Shear,
    /// Nominal contact, strong blur, vignetting, uneven light and noise.
    Degraded,
    /// Nominal contact, gain 2 (saturated markers).
    Saturated,
    /// Nominal contact, 3 % of markers missing.
    Dropout,
    /// Nominal contact on a rounded-rectangle sensor with bigger markers.
    RoundedRect,
    /// No contact; blur, vignetting, uneven light and strong noise.
    NoContact,
    // The condition categories ([`Category::CONDITIONS`]): one scene in four
    // has no contact; the others one nominal-like contact (width 15-30 px,
    // strength 0.5-0.9) unless said otherwise.
    /// The light changed since rest: frame gain 0.30-0.37 (markers a third
    /// as bright), vignetting to 0.45-0.65 at the corners, a 25-35 % linear
    /// light gradient in a random direction, noise sigma 2 -> 3.6-5.4; the
    /// rest frame under nominal light.
    Dim,
    /// The light grew since rest: frame gain 2.5-3.5, markers clipped at 255
    /// with wide flat tops, extra noise sigma 1; rest under nominal light.
    Overexposed,
    /// Out of focus: Gaussian PSF sigma 1.8-2.8 px on the frame, 1 px at
    /// rest.
    Blurred,
    /// Skin texture (value noise, amplitude 4-8 grey levels, 10-20 px
    /// features) that moves with the skin.
    Textured,
    /// A TacTip-like dome ([`SensorSpec::domed`], ~950 markers at 640x480),
    /// contact anywhere within 70 % of the rim radius.
    Dome,
    /// A bright housing round the nominal sensor ([`Housing::random`]).
    Housing,
    /// Pins of two colours: 8-12 % of the markers at 55-65 % brightness.
    TwoColour,
    /// Skin clamped at the rim (clamp length 12-20 px); the contact's centre
    /// 25-70 px inside the rim, width 15-25 px.
    RimClamped,
    /// All of a real TacTip frame at once: dome, housing, two-colour pins,
    /// static texture, PSF sigma 1 px.
    TacTip,
}

impl Category {
    /// All original categories, in table order (the frames and the
    /// BENCHMARKS tables of these do not change).
    pub const ALL: [Category; 11] = [
        Category::Nominal,
        Category::Edge,
        Category::Large,
        Category::Small,
        Category::Two,
        Category::Shear,
        Category::Degraded,
        Category::Saturated,
        Category::Dropout,
        Category::RoundedRect,
        Category::NoContact,
    ];

    /// The condition categories (light change, blur, texture, dome,
    /// housing, two-colour pins, rim clamp), in table order.
    pub const CONDITIONS: [Category; 9] = [
        Category::Dim,
        Category::Overexposed,
        Category::Blurred,
        Category::Textured,
        Category::Dome,
        Category::Housing,
        Category::TwoColour,
        Category::RimClamped,
        Category::TacTip,
    ];

    /// Short name.
    pub fn name(self) -> &'static str {
        match self {
            Category::Nominal => "nominal",
            Category::Edge => "edge",
            Category::Large => "large",
            Category::Small => "small",
            Category::Two => "two",
            Category::Shear => "shear",
            Category::Degraded => "degraded",
            Category::Saturated => "saturated",
            Category::Dropout => "dropout",
            Category::RoundedRect => "rounded_rect",
            Category::NoContact => "no_contact",
            Category::Dim => "dim",
            Category::Overexposed => "overexposed",
            Category::Blurred => "blurred",
            Category::Textured => "textured",
            Category::Dome => "dome",
            Category::Housing => "housing",
            Category::TwoColour => "two_colour",
            Category::RimClamped => "rim_clamped",
            Category::TacTip => "tactip",
        }
    }

    /// The category of a [`Category::name`] (original or condition).
    pub fn from_name(name: &str) -> Option<Category> {
        Self::ALL
            .into_iter()
            .chain(Self::CONDITIONS)
            .find(|c| c.name() == name)
    }

    /// True for the [`Category::CONDITIONS`].
    pub fn is_condition(self) -> bool {
        Self::CONDITIONS.contains(&self)
    }

    /// The sensor of this category (fixed per seed: one rest frame serves all
    /// frames of the category).
    pub fn sensor(self, width_px: usize, height_px: usize, seed: u64) -> SensorSpec {
        let mut rng = Rng::new(seed ^ 0x5E45_0000);
        let s = scale_of(width_px, height_px);
        let mut sensor = match self {
            Category::Dome | Category::TacTip => SensorSpec::domed(width_px, height_px),
            _ => SensorSpec::nominal(width_px, height_px),
        };
        sensor.marker_diameter_px = rng.range(6.0, 8.0) * s;
        sensor.lattice_offset = PointPx::new(rng.range(0.0, 15.0) * s, rng.range(0.0, 13.0) * s);
        match self {
            Category::Degraded => {
                sensor.blur_sigma_px = 1.5 * s;
                sensor.vignette = 0.5;
                sensor.light_gradient = 0.3;
                sensor.noise_sigma = 6.0;
            }
            Category::NoContact => {
                sensor.blur_sigma_px = 1.2 * s;
                sensor.vignette = 0.4;
                sensor.light_gradient = 0.2;
                sensor.noise_sigma = 5.0;
            }
            Category::Saturated => {
                sensor.gain = 2.0;
                sensor.noise_sigma = 3.0;
            }
            Category::RoundedRect => {
                sensor.shape = Shape::RoundedRect {
                    half_width_px: 290.0 * s,
                    half_height_px: 215.0 * s,
                    corner_px: 60.0 * s,
                };
                sensor.marker_diameter_px = 8.0 * s;
            }
            Category::Blurred => sensor.psf_sigma_px = 1.0 * s,
            Category::Textured => {
                sensor.texture = Some(Texture {
                    amplitude: rng.range(4.0, 8.0),
                    cell_px: rng.range(10.0, 20.0) * s,
                    seed: rng.next_u64(),
                    follows_skin: true,
                });
            }
            Category::Housing => sensor.housing = Some(Housing::random(&sensor, rng.next_u64())),
            Category::TwoColour => {
                sensor.pin_colours = Some(PinColours {
                    dim_fraction: rng.range(0.08, 0.12),
                    dim_level: rng.range(0.55, 0.65),
                    seed: rng.next_u64(),
                });
            }
            Category::RimClamped => sensor.rim_clamp_px = Some(rng.range(12.0, 20.0) * s),
            Category::TacTip => {
                sensor.housing = Some(Housing::random(&sensor, rng.next_u64()));
                sensor.pin_colours = Some(PinColours {
                    dim_fraction: rng.range(0.08, 0.12),
                    dim_level: rng.range(0.55, 0.65),
                    seed: rng.next_u64(),
                });
                sensor.texture = Some(Texture {
                    amplitude: rng.range(3.0, 6.0),
                    cell_px: rng.range(10.0, 20.0) * s,
                    seed: rng.next_u64(),
                    follows_skin: false,
                });
                sensor.psf_sigma_px = 1.0 * s;
            }
            _ => {}
        }
        sensor
    }

    /// A random scene of this category on `sensor`.
    pub fn scene(self, sensor: &SensorSpec, seed: u64) -> Scene {
        if self.is_condition() {
            return self.condition_scene(sensor, seed);
        }
        let mut rng = Rng::new(seed);
        let s = scale_of(sensor.width_px, sensor.height_px);
        let inner = sensor.shape.inner_radius_px();
        let at = |rng: &mut Rng, r_lo: f64, r_hi: f64| {
            let r = inner * rng.range(r_lo, r_hi).sqrt();
            let a = rng.range(0.0, std::f64::consts::TAU);
            PointPx::new(sensor.centre.x + r * a.cos(), sensor.centre.y + r * a.sin())
        };
        let press = |centre, width_px, strength| Press {
            centre,
            width_px,
            strength,
            shear_px: PointPx::new(0.0, 0.0),
            flat_radius_px: 0.0,
        };
        let mut dropout = 0.0;
        let presses = match self {
            Category::NoContact => vec![],
            Category::Edge => {
                let c = at(&mut rng, 0.49, 0.72);
                vec![press(c, rng.range(15.0, 25.0) * s, rng.range(0.5, 0.9))]
            }
            Category::Large => {
                let c = at(&mut rng, 0.0, 0.16);
                vec![press(c, rng.range(40.0, 60.0) * s, rng.range(0.4, 0.7))]
            }
            Category::Small => {
                let c = at(&mut rng, 0.0, 0.5);
                vec![press(c, rng.range(4.0, 8.0) * s, rng.range(0.6, 1.0))]
            }
            Category::Two => {
                let a = at(&mut rng, 0.0, 0.3);
                let mut b = at(&mut rng, 0.0, 0.4);
                for _ in 0..50 {
                    if (a.x - b.x).hypot(a.y - b.y) > 110.0 * s {
                        break;
                    }
                    b = at(&mut rng, 0.0, 0.4);
                }
                vec![
                    press(a, rng.range(20.0, 30.0) * s, rng.range(0.6, 0.9)),
                    press(b, rng.range(10.0, 15.0) * s, rng.range(0.5, 0.7)),
                ]
            }
            _ => {
                let c = at(&mut rng, 0.0, 0.25);
                let mut p = press(c, rng.range(15.0, 30.0) * s, rng.range(0.5, 0.9));
                if self == Category::Shear {
                    let m = rng.range(1.0, 4.0) * s;
                    let a = rng.range(0.0, std::f64::consts::TAU);
                    p.shear_px = PointPx::new(m * a.cos(), m * a.sin());
                }
                if self == Category::Dropout {
                    dropout = 0.03;
                }
                vec![p]
            }
        };
        Scene {
            sensor: sensor.clone(),
            presses,
            dropout,
            seed: rng.next_u64(),
        }
    }

    /// A scene of a condition category: the contact (none in one scene in
    /// four) and the frame's conditions.
    fn condition_scene(self, sensor: &SensorSpec, seed: u64) -> Scene {
        let mut rng = Rng::new(seed ^ 0xC0_4D17);
        let s = scale_of(sensor.width_px, sensor.height_px);
        let area = sensor.sensing_area();
        let inner = area.shape.inner_radius_px();
        let c = area.centre;
        let angle = rng.range(0.0, std::f64::consts::TAU);
        let at = |r: f64| PointPx::new(c.x + r * angle.cos(), c.y + r * angle.sin());
        let contact = rng.unit() >= 0.25;
        let presses = match self {
            _ if !contact => vec![],
            Category::RimClamped => {
                let from_rim = rng.range(25.0, 70.0) * s;
                vec![Press {
                    centre: at(inner - from_rim),
                    width_px: rng.range(15.0, 25.0) * s,
                    strength: rng.range(0.5, 0.9),
                    shear_px: PointPx::new(0.0, 0.0),
                    flat_radius_px: 0.0,
                }]
            }
            Category::Dome | Category::TacTip => vec![Press {
                centre: at(inner * rng.range(0.0, 0.5).sqrt()),
                width_px: rng.range(15.0, 30.0) * s,
                strength: rng.range(0.5, 0.9),
                shear_px: PointPx::new(0.0, 0.0),
                flat_radius_px: 0.0,
            }],
            _ => vec![Press {
                centre: at(inner * rng.range(0.0, 0.25).sqrt()),
                width_px: rng.range(15.0, 30.0) * s,
                strength: rng.range(0.5, 0.9),
                shear_px: PointPx::new(0.0, 0.0),
                flat_radius_px: 0.0,
            }],
        };
        let mut sensor = sensor.clone();
        match self {
            Category::Dim => {
                sensor.frame_conditions = FrameConditions {
                    gain: rng.range(0.30, 0.37),
                    corner_light: rng.range(0.45, 0.65),
                    gradient: rng.range(0.25, 0.35),
                    gradient_angle_rad: rng.range(0.0, std::f64::consts::TAU),
                    extra_noise_sigma: rng.range(3.0, 5.0),
                    psf_sigma_px: None,
                }
            }
            Category::Overexposed => {
                sensor.frame_conditions = FrameConditions {
                    gain: rng.range(2.5, 3.5),
                    extra_noise_sigma: 1.0,
                    ..FrameConditions::NONE
                }
            }
            Category::Blurred => {
                sensor.frame_conditions = FrameConditions {
                    psf_sigma_px: Some(rng.range(1.8, 2.8) * s),
                    ..FrameConditions::NONE
                }
            }
            _ => {}
        }
        Scene {
            sensor,
            presses,
            dropout: 0.0,
            seed: rng.next_u64(),
        }
    }
}

/// The rest (no-contact) frame of a sensor, with its own noise seed, under
/// the sensor's nominal light and focus (its frame conditions ignored).
pub fn rest_frame(sensor: &SensorSpec, seed: u64) -> SynthFrame {
    render(&Scene {
        sensor: sensor.at_rest(),
        presses: vec![],
        dropout: 0.0,
        seed,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_frame_other_seed_other_noise() {
        let sensor = Category::Nominal.sensor(160, 120, 1);
        let scene = Category::Nominal.scene(&sensor, 7);
        let a = render(&scene);
        let b = render(&scene);
        assert_eq!(a.image.data(), b.image.data());
        let c = render(&Category::Nominal.scene(&sensor, 8));
        assert_ne!(a.image.data(), c.image.data());
    }

    #[test]
    fn rest_grid_has_pitch_spacing_and_stays_inside() {
        let sensor = SensorSpec::nominal(640, 480);
        let m = sensor.rest_markers();
        assert!(m.len() > 600 && m.len() < 900, "{}", m.len());
        for p in &m {
            assert!(p.x.hypot(0.0) >= 0.0);
            let d = sensor
                .shape
                .signed_distance_px(p.x - sensor.centre.x, p.y - sensor.centre.y);
            assert!(d <= -3.5);
        }
        let a = m[0];
        let nearest = m[1..]
            .iter()
            .map(|q| (q.x - a.x).hypot(q.y - a.y))
            .fold(f64::INFINITY, f64::min);
        assert!((nearest - 15.0).abs() < 1e-9);
    }

    #[test]
    fn a_flat_punch_leaves_its_face_and_pushes_its_edge_out() {
        let punch = Press {
            centre: PointPx::new(100.0, 100.0),
            width_px: 9.0,
            strength: 1.2,
            shear_px: PointPx::new(0.0, 0.0),
            flat_radius_px: 50.0,
        };
        let at = |x: f64| punch.displacement(PointPx::new(x, 100.0));
        for x in [100.0, 120.0, 149.9] {
            assert_eq!(at(x), PointPx::new(0.0, 0.0), "under the face at {x}");
        }
        // Just beyond the edge: k w outwards; a width further, exp(-1/2) of it.
        assert!((at(150.001).x - 1.2 * 9.0).abs() < 1e-3 && at(150.001).y == 0.0);
        assert!((at(159.0).x - 1.2 * 9.0 * (-0.5f64).exp()).abs() < 1e-9);
        assert!(at(41.0).x < 0.0);
        // On a dome too: the face's skin stays where it was.
        let sensor = SensorSpec::domed(640, 480);
        let c = sensor.centre;
        let press = Press { centre: c, ..punch };
        let under = PointPx::new(c.x + 20.0, c.y);
        let u = sensor.displacement_at(under, &[press]);
        assert!(u.x.hypot(u.y) < 1e-9, "{u:?}");
        let beyond = PointPx::new(c.x + 60.0, c.y);
        assert!(sensor.displacement_at(beyond, &[press]).x > 1.0);
    }

    #[test]
    fn press_pushes_markers_outward_and_truth_includes_shear() {
        let p = Press {
            centre: PointPx::new(100.0, 100.0),
            width_px: 20.0,
            strength: 0.8,
            shear_px: PointPx::new(2.0, -1.0),
            flat_radius_px: 0.0,
        };
        let u = p.displacement(PointPx::new(120.0, 100.0));
        assert!(u.x > 9.0 && u.x < 12.0, "{u:?}");
        assert_eq!(p.visible_centre(), PointPx::new(102.0, 99.0));
        let far = p.displacement(PointPx::new(300.0, 300.0));
        assert!(far.x.abs() < 1e-6 && far.y.abs() < 1e-6);
    }

    #[test]
    fn rounded_rect_distance_is_signed() {
        let s = Shape::RoundedRect {
            half_width_px: 100.0,
            half_height_px: 50.0,
            corner_px: 10.0,
        };
        assert!((s.signed_distance_px(0.0, 0.0) + 50.0).abs() < 1e-9);
        assert!((s.signed_distance_px(110.0, 0.0) - 10.0).abs() < 1e-9);
        assert!(s.signed_distance_px(99.0, 49.0) > 0.0);
    }
}
