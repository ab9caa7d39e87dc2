//! The simulated fingertip camera: a [`ContactState`] -> a marker frame.
//!
//! Uses the synthetic skin of [`dexitac_tactile::synth`] (its sensor, its press
//! displacement field, its marker drawing), but caches what does not change
//! between frames of one sensor: the skin background, the light field
//! (vignetting, gradient, gain) and a small bank of noise fields. A frame
//! is then the background plus the displaced markers plus one noise field:
//! about 4x cheaper than [`dexitac_tactile::synth::render`] at 640x480, with the same
//! image formula (the test `matches_synth_without_noise` pins that).
//!
//! Contact -> press: the press sits where the object touches the skin
//! (`centre_mm - shear_mm`, converted with the sensor's mm per px), the
//! skin's elastic shear is the press's shear, and the press strength grows
//! with the normal force, `k = K_MAX * F / (F + F_HALF)`: a light touch
//! (below about 0.3 N) stays under the pipeline's detection limit, as on the
//! real skin.

use crate::plant::ContactState;
use dexitac_tactile::frame::GreyFrame;
use dexitac_tactile::synth::{Press, Rng, SensorSpec};
use dexitac_tactile::PointPx;

/// Press strength at infinite force.
const K_MAX: f64 = 0.8;
/// Force at half of [`K_MAX`], N.
const F_HALF_N: f64 = 0.5;
/// Noise fields kept per sensor (frames cycle through them).
const NOISE_BANK: usize = 8;

/// A cached renderer for one sensor.
#[derive(Debug, Clone)]
pub struct Renderer {
    sensor: SensorSpec,
    mm_per_px: f64,
    rest: Vec<PointPx>,
    /// Skin level per pixel before light, grey levels.
    background: Vec<f32>,
    /// Light factor per pixel (vignetting, gradient, gain).
    light: Vec<f32>,
    noise: Vec<Vec<f32>>,
    frame_index: u64,
    /// A marker's grey-level profile against its squared distance from
    /// the marker's centre, sampled every [`PROFILE_STEP_PX2`] px².
    profile: Vec<f32>,
    /// The frames without contact, one per noise field, made when first
    /// needed: nothing touches, so nothing changes but the noise.
    untouched: Vec<Option<Vec<u8>>>,
}

/// Sampling step of a marker's profile, px² (the profile is interpolated
/// linearly between samples: under 0.01 grey levels off).
const PROFILE_STEP_PX2: f64 = 1.0 / 64.0;

impl Renderer {
    /// A renderer for `sensor` at `mm_per_px`, noise seeded by `seed`.
    pub fn new(sensor: SensorSpec, mm_per_px: f64, seed: u64) -> Self {
        let (w, h) = (sensor.width_px, sensor.height_px);
        let mut background = vec![0f32; w * h];
        let mut light = vec![0f32; w * h];
        let rim = sensor.shape.inner_radius_px().max(1.0);
        for y in 0..h {
            for x in 0..w {
                let dx = x as f64 - sensor.centre.x;
                let dy = y as f64 - sensor.centre.y;
                let d = sensor.shape.signed_distance_px(dx, dy);
                let inside = soft_step(-d, sensor.blur_sigma_px.max(0.5));
                background[y * w + x] = (5.0 + (sensor.skin_level - 5.0) * inside) as f32;
                let rr = (dx * dx + dy * dy) / (rim * rim);
                let l = (1.0 - sensor.vignette * rr.min(1.5))
                    * (1.0 + sensor.light_gradient * (x as f64 / w.max(1) as f64 - 0.5));
                light[y * w + x] = (l * sensor.gain) as f32;
            }
        }
        let mut rng = Rng::new(seed);
        let noise = (0..NOISE_BANK)
            .map(|_| {
                (0..w * h)
                    .map(|_| (sensor.noise_sigma * rng.normal()) as f32)
                    .collect()
            })
            .collect();
        let (r, soft, reach) = marker_extent(&sensor);
        let samples = ((reach * reach) as f64 / PROFILE_STEP_PX2).ceil() as usize + 2;
        let profile = (0..samples)
            .map(|i| {
                let d = (i as f64 * PROFILE_STEP_PX2).sqrt();
                (sensor.marker_contrast * soft_step(r - d, soft)) as f32
            })
            .collect();
        Renderer {
            rest: sensor.rest_markers(),
            sensor,
            mm_per_px: mm_per_px.max(1e-6),
            background,
            light,
            noise,
            frame_index: 0,
            profile,
            untouched: vec![None; NOISE_BANK],
        }
    }

    /// The sensor.
    pub fn sensor(&self) -> &SensorSpec {
        &self.sensor
    }

    /// The press that shows `contact` on this sensor.
    pub fn press(&self, contact: &ContactState) -> Press {
        let c = self.sensor.centre;
        let f = contact.normal_n.max(0.0);
        Press {
            centre: PointPx::new(
                c.x + (contact.centre_mm[0] - contact.shear_mm[0]) / self.mm_per_px,
                c.y + (contact.centre_mm[1] - contact.shear_mm[1]) / self.mm_per_px,
            ),
            width_px: contact.width_mm / self.mm_per_px,
            strength: K_MAX * f / (f + F_HALF_N),
            shear_px: PointPx::new(
                contact.shear_mm[0] / self.mm_per_px,
                contact.shear_mm[1] / self.mm_per_px,
            ),
            flat_radius_px: 0.0,
        }
    }

    /// Renders the next frame with `contact` (None: nothing touches).
    ///
    /// Only what the contact changes is drawn: the frame without contact
    /// for this frame's noise field is made once, and a contact redraws the
    /// box around the markers it moves by more than 0.001 px.
    pub fn render(&mut self, contact: Option<&ContactState>) -> GreyFrame {
        let press = contact.map(|c| self.press(c));
        let noise_index = (self.frame_index % NOISE_BANK as u64) as usize;
        self.frame_index += 1;
        let (w, h) = (self.sensor.width_px, self.sensor.height_px);
        let mut data = self.untouched(noise_index);
        if let Some(press) = press {
            let mut moved: Option<[f64; 4]> = None;
            let markers: Vec<PointPx> = self
                .rest
                .iter()
                .map(|&p| {
                    let u = press.displacement(p);
                    let q = PointPx::new(p.x + u.x, p.y + u.y);
                    if u.x.hypot(u.y) > MOVED_PX {
                        let b = moved.get_or_insert([p.x, p.y, p.x, p.y]);
                        *b = [
                            b[0].min(p.x).min(q.x),
                            b[1].min(p.y).min(q.y),
                            b[2].max(p.x).max(q.x),
                            b[3].max(p.y).max(q.y),
                        ];
                    }
                    q
                })
                .collect();
            if let Some([x0, y0, x1, y1]) = moved {
                let (_, _, reach) = marker_extent(&self.sensor);
                let pad = reach as f64 + 1.0;
                let region = Region {
                    x0: (x0 - pad).floor().clamp(0.0, w as f64) as usize,
                    y0: (y0 - pad).floor().clamp(0.0, h as f64) as usize,
                    x1: (x1 + pad).ceil().clamp(0.0, w as f64) as usize,
                    y1: (y1 + pad).ceil().clamp(0.0, h as f64) as usize,
                };
                self.compose(&markers, noise_index, region, &mut data);
            }
        }
        // Invariant: the data has exactly w * h pixels, and the sensor's
        // size was accepted by the synthetic renderer's checks.
        GreyFrame::new(w, h, data).unwrap_or_else(|_| blank(w, h))
    }

    /// The pixels of the frame without contact for noise field `index`
    /// (made when first needed).
    fn untouched(&mut self, index: usize) -> Vec<u8> {
        if let Some(Some(data)) = self.untouched.get(index) {
            return data.clone();
        }
        let (w, h) = (self.sensor.width_px, self.sensor.height_px);
        let mut data = vec![0; w * h];
        let whole = Region {
            x0: 0,
            y0: 0,
            x1: w,
            y1: h,
        };
        let rest = self.rest.clone();
        self.compose(&rest, index, whole, &mut data);
        if let Some(slot) = self.untouched.get_mut(index) {
            *slot = Some(data.clone());
        }
        data
    }

    /// Draws `region` of the frame with `markers` and noise field
    /// `noise_index` into `data` (w * h pixels).
    fn compose(&self, markers: &[PointPx], noise_index: usize, region: Region, data: &mut [u8]) {
        let s = &self.sensor;
        let w = s.width_px;
        let Region { x0, y0, x1, y1 } = region;
        if x1 <= x0 || y1 <= y0 {
            return;
        }
        let rw = x1 - x0;
        let mut canvas: Vec<f32> = (y0..y1)
            .flat_map(|y| self.background[y * w + x0..y * w + x1].iter().copied())
            .collect();
        let (_, _, reach) = marker_extent(s);
        let reach2 = (reach * reach) as f64;
        let last = self.profile.len().saturating_sub(2);
        let (rx0, ry0, rx1, ry1) = (x0 as i64, y0 as i64, x1 as i64 - 1, y1 as i64 - 1);
        for m in markers {
            let (cx, cy) = (m.x.round() as i64, m.y.round() as i64);
            for y in (cy - reach).max(ry0)..=(cy + reach).min(ry1) {
                let dy = y as f64 - m.y;
                let row = (y - ry0) as usize * rw;
                for x in (cx - reach).max(rx0)..=(cx + reach).min(rx1) {
                    let dx = x as f64 - m.x;
                    let d2 = dx * dx + dy * dy;
                    if d2 > reach2 {
                        continue;
                    }
                    // Linear interpolation in the sampled profile.
                    let f = d2 / PROFILE_STEP_PX2;
                    let i = (f as usize).min(last);
                    let t = (f - i as f64) as f32;
                    let (a, b) = (self.profile[i], self.profile[i + 1]);
                    canvas[row + (x - rx0) as usize] += a + (b - a) * t;
                }
            }
        }
        let quantise = |v: f32| (v.clamp(0.0, 255.0) + 0.5) as u8;
        let noise = self
            .noise
            .get(noise_index)
            .filter(|n| n.len() == self.light.len());
        for (ry, y) in (y0..y1).enumerate() {
            let span = y * w + x0..y * w + x1;
            let out = &mut data[span.clone()];
            let values = &canvas[ry * rw..(ry + 1) * rw];
            let light = &self.light[span.clone()];
            match noise {
                Some(noise) => {
                    for ((o, (&v, &l)), &n) in out
                        .iter_mut()
                        .zip(values.iter().zip(light))
                        .zip(&noise[span])
                    {
                        *o = quantise(v * l + n);
                    }
                }
                None => {
                    for (o, (&v, &l)) in out.iter_mut().zip(values.iter().zip(light)) {
                        *o = quantise(v * l);
                    }
                }
            }
        }
    }
}

/// A marker moved less than this by a contact is left as drawn without
/// contact, px (at most about 0.05 grey levels off).
const MOVED_PX: f64 = 1e-3;

/// A box of pixels, `x0..x1` by `y0..y1`.
#[derive(Debug, Clone, Copy)]
struct Region {
    x0: usize,
    y0: usize,
    x1: usize,
    y1: usize,
}

/// A black frame (only reached for a sensor size the frame type refuses).
fn blank(w: usize, h: usize) -> GreyFrame {
    GreyFrame::new(w.max(1), h.max(1), vec![0; w.max(1) * h.max(1)])
        .unwrap_or_else(|_| blank(640, 480))
}

/// A marker's radius and edge softness, px, and how far from its centre it
/// is drawn, whole px.
fn marker_extent(s: &SensorSpec) -> (f64, f64, i64) {
    let r = s.marker_diameter_px / 2.0;
    let soft = s.blur_sigma_px.max(0.3);
    (r, soft, (r + 4.0 * soft).ceil() as i64)
}

/// Same edge as [`dexitac_tactile::synth`]'s renderer.
fn soft_step(d: f64, sigma: f64) -> f64 {
    1.0 / (1.0 + (-d / (0.6 * sigma)).exp())
}

#[cfg(test)]
mod tests {
    use super::*;
    use dexitac_tactile::synth::{self, Scene};

    fn contact() -> ContactState {
        ContactState {
            centre_mm: [1.0, -2.0],
            shear_mm: [0.0, 0.3],
            normal_n: 1.5,
            width_mm: 2.5,
        }
    }

    #[test]
    fn matches_synth_without_noise() {
        let mut sensor = SensorSpec::nominal(160, 120);
        sensor.noise_sigma = 0.0;
        let mut r = Renderer::new(sensor.clone(), 0.4, 1);
        let ours = r.render(Some(&contact()));
        let theirs = synth::render(&Scene {
            sensor,
            presses: vec![r.press(&contact())],
            dropout: 0.0,
            seed: 1,
        });
        let worst = ours
            .data()
            .iter()
            .zip(theirs.image.data())
            .map(|(a, b)| a.abs_diff(*b))
            .max();
        assert!(worst.is_some_and(|d| d <= 1), "{worst:?}");
    }

    #[test]
    fn drawing_only_the_moved_box_matches_a_whole_redraw() {
        let mut r = Renderer::new(SensorSpec::nominal(320, 240), 0.2, 3);
        let c = contact();
        // Frame 0 without contact, frame 1 with: noise fields 0 and 1.
        let untouched = r.render(None);
        let pressed = r.render(Some(&c));
        let press = r.press(&c);
        let moved: Vec<PointPx> = r
            .rest
            .iter()
            .map(|&p| {
                let u = press.displacement(p);
                PointPx::new(p.x + u.x, p.y + u.y)
            })
            .collect();
        let whole = Region {
            x0: 0,
            y0: 0,
            x1: 320,
            y1: 240,
        };
        let (mut full, mut rest) = (vec![0; 320 * 240], vec![0; 320 * 240]);
        r.compose(&moved, 1, whole, &mut full);
        r.compose(&r.rest.clone(), 0, whole, &mut rest);
        assert_eq!(untouched.data(), &rest[..]);
        let worst = pressed
            .data()
            .iter()
            .zip(&full)
            .map(|(a, b)| a.abs_diff(*b))
            .max();
        assert!(worst.is_some_and(|d| d <= 1), "{worst:?}");
        // The contact did change the frame (against the same noise field).
        let mut rest1 = vec![0; 320 * 240];
        r.compose(&r.rest.clone(), 1, whole, &mut rest1);
        assert!(pressed.data() != &rest1[..]);
    }

    #[test]
    fn stronger_force_presses_harder() {
        let r = Renderer::new(SensorSpec::nominal(160, 120), 0.4, 1);
        let light = r.press(&ContactState {
            normal_n: 0.2,
            ..contact()
        });
        let firm = r.press(&contact());
        assert!(firm.strength > light.strength);
        assert!(firm.strength < K_MAX);
    }
}
