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
//! Everything is reproducible from a `u64` seed (SplitMix64; no external RNG).
//! [`Category`] gives the scene families used by tests and benchmarks.

use crate::frame::GreyFrame;
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

/// One sensor: geometry, skin and optics. Fixed for a rest frame and all
/// frames compared with it.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorSpec {
    /// Image width, px.
    pub width_px: usize,
    /// Image height, px.
    pub height_px: usize,
    /// Sensing area outline.
    pub shape: Shape,
    /// Sensing area centre.
    pub centre: PointPx,
    /// Hex grid pitch, px.
    pub pitch_px: f64,
    /// Lattice origin offset, px (moves the grid against the outline).
    pub lattice_offset: PointPx,
    /// Marker diameter, px.
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
        }
    }

    /// Rest marker positions (hex grid inside the outline, one marker radius
    /// from the rim).
    pub fn rest_markers(&self) -> Vec<PointPx> {
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
}

impl Press {
    /// Displacement of a rest point by this press, px.
    pub fn displacement(&self, p: PointPx) -> PointPx {
        let dx = p.x - self.centre.x;
        let dy = p.y - self.centre.y;
        let r2 = dx * dx + dy * dy;
        let w2 = self.width_px * self.width_px;
        let radial = self.strength * (-r2 / (2.0 * w2)).exp();
        let shear = (-r2 / (2.0 * 2.25 * w2)).exp();
        PointPx::new(
            radial * dx + shear * self.shear_px.x,
            radial * dy + shear * self.shear_px.y,
        )
    }

    /// Where the indenter's centre appears in the image (the truth).
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
    /// The sensor.
    pub sensor: SensorSpec,
    /// Contacts (empty: no contact).
    pub presses: Vec<Press>,
    /// Probability that a marker is not visible.
    pub dropout: f64,
    /// Seed of the noise and dropout.
    pub seed: u64,
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
    /// Displaced positions of the visible markers.
    pub markers: Vec<PointPx>,
}

/// Renders a scene.
pub fn render(scene: &Scene) -> SynthFrame {
    let s = &scene.sensor;
    let mut rng = Rng::new(scene.seed);
    let rest = s.rest_markers();
    let mut markers = Vec::with_capacity(rest.len());
    for &p in &rest {
        let visible = rng.unit() >= scene.dropout;
        let mut q = p;
        for press in &scene.presses {
            let u = press.displacement(p);
            q.x += u.x;
            q.y += u.y;
        }
        if visible {
            markers.push(q);
        }
    }
    let (w, h) = (s.width_px, s.height_px);
    let mut canvas = vec![0f32; w * h];
    // Skin inside the outline (soft edge), dark outside.
    for y in 0..h {
        for x in 0..w {
            let d = s
                .shape
                .signed_distance_px(x as f64 - s.centre.x, y as f64 - s.centre.y);
            let inside = soft_step(-d, s.blur_sigma_px.max(0.5));
            canvas[y * w + x] = (5.0 + (s.skin_level - 5.0) * inside) as f32;
        }
    }
    let r = s.marker_diameter_px / 2.0;
    let soft = s.blur_sigma_px.max(0.3);
    let reach = (r + 4.0 * soft).ceil() as i64;
    for m in &markers {
        let (cx, cy) = (m.x.round() as i64, m.y.round() as i64);
        for y in (cy - reach).max(0)..=(cy + reach).min(h as i64 - 1) {
            for x in (cx - reach).max(0)..=(cx + reach).min(w as i64 - 1) {
                let d = (x as f64 - m.x).hypot(y as f64 - m.y);
                let v = s.marker_contrast * soft_step(r - d, soft);
                canvas[y as usize * w + x as usize] += v as f32;
            }
        }
    }
    let rim = s.shape.inner_radius_px().max(1.0);
    let mut data = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let dx = x as f64 - s.centre.x;
            let dy = y as f64 - s.centre.y;
            let rr = (dx * dx + dy * dy) / (rim * rim);
            let light = (1.0 - s.vignette * rr.min(1.5))
                * (1.0 + s.light_gradient * (x as f64 / w.max(1) as f64 - 0.5));
            let v = canvas[y * w + x] as f64 * light * s.gain + s.noise_sigma * rng.normal();
            data[y * w + x] = v.round().clamp(0.0, 255.0) as u8;
        }
    }
    let mut presses = scene.presses.clone();
    presses.sort_by(|a, b| b.width_px.total_cmp(&a.width_px));
    SynthFrame {
        // Invariant: `data` has exactly w * h bytes.
        image: GreyFrame::new(w, h, data).expect("synth frame size matches"),
        contacts: presses.iter().map(Press::visible_centre).collect(),
        rest_markers: rest,
        markers,
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
}

impl Category {
    /// All categories, in table order.
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
        }
    }

    /// The sensor of this category (fixed per seed: one rest frame serves all
    /// frames of the category).
    pub fn sensor(self, width_px: usize, height_px: usize, seed: u64) -> SensorSpec {
        let mut rng = Rng::new(seed ^ 0x5E45_0000);
        let s = scale_of(width_px, height_px);
        let mut sensor = SensorSpec::nominal(width_px, height_px);
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
            _ => {}
        }
        sensor
    }

    /// A random scene of this category on `sensor`.
    pub fn scene(self, sensor: &SensorSpec, seed: u64) -> Scene {
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
}

/// The rest (no-contact) frame of a sensor, with its own noise seed.
pub fn rest_frame(sensor: &SensorSpec, seed: u64) -> SynthFrame {
    render(&Scene {
        sensor: sensor.clone(),
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
    fn press_pushes_markers_outward_and_truth_includes_shear() {
        let p = Press {
            centre: PointPx::new(100.0, 100.0),
            width_px: 20.0,
            strength: 0.8,
            shear_px: PointPx::new(2.0, -1.0),
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
