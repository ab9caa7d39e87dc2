//! Shared test fixtures: point grids, a calibrated nominal sensor, matching.

use crate::calibrate::{self, Calibration};
use crate::frame::GreyFrame;
use crate::markers::{self, Detector};
use crate::params::Params;
use crate::synth::{rest_frame, Category, SynthFrame};
use crate::PointPx;

/// Hex grid of `pitch` covering a `w x h` frame, one pitch from the border.
pub fn hex_points(w: usize, h: usize, pitch: f64) -> Vec<PointPx> {
    let row = pitch * 3f64.sqrt() / 2.0;
    let mut out = Vec::new();
    let mut j = 0;
    loop {
        let y = pitch + j as f64 * row;
        if y > h as f64 - pitch {
            break;
        }
        let shift = if j % 2 == 1 { pitch / 2.0 } else { 0.0 };
        let mut x = pitch + shift;
        while x <= w as f64 - pitch {
            out.push(PointPx::new(x, y));
            x += pitch;
        }
        j += 1;
    }
    out
}

/// The nominal 640x480 rest frame and its automatic detector.
pub fn nominal_rest_and_detector() -> (SynthFrame, Detector) {
    let sensor = Category::Nominal.sensor(640, 480, 11);
    let rest = rest_frame(&sensor, 1);
    let det = markers::auto_detector(&rest.image, &Params::default().markers).unwrap();
    (rest, det)
}

/// A calibrated pipeline for `category` at `w x h` and its rest frame.
pub fn calibrated(category: Category, w: usize, h: usize, params: &Params) -> Calibration {
    let sensor = category.sensor(w, h, 5);
    let rest = rest_frame(&sensor, 99);
    calibrate::calibrate(&[rest.image], params).unwrap()
}

/// Greedy nearest matches `(found index, truth index, distance)` within
/// `radius` px (each truth point used once).
pub fn match_points(found: &[PointPx], truth: &[PointPx], radius: f64) -> Vec<(usize, usize, f64)> {
    let mut used = vec![false; truth.len()];
    let mut out = Vec::new();
    for (i, f) in found.iter().enumerate() {
        let best = truth
            .iter()
            .enumerate()
            .filter(|(k, _)| !used[*k])
            .map(|(k, t)| (k, (t.x - f.x).hypot(t.y - f.y)))
            .filter(|&(_, d)| d <= radius)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((k, d)) = best {
            used[k] = true;
            out.push((i, k, d));
        }
    }
    out
}

/// A `w x h` frame of grey level `background` with Gaussian spots
/// `(centre, sigma px, amplitude grey levels)` added (clipped to 0..=255).
pub fn spots_frame(
    w: usize,
    h: usize,
    background: f64,
    spots: &[(PointPx, f64, f64)],
) -> GreyFrame {
    let mut data = vec![background; w * h];
    for &(c, sigma, amplitude) in spots {
        let reach = (4.0 * sigma).ceil();
        let (x0, x1) = (
            (c.x - reach).max(0.0) as usize,
            ((c.x + reach) as usize).min(w - 1),
        );
        let (y0, y1) = (
            (c.y - reach).max(0.0) as usize,
            ((c.y + reach) as usize).min(h - 1),
        );
        for y in y0..=y1 {
            for x in x0..=x1 {
                let r2 = (x as f64 - c.x).powi(2) + (y as f64 - c.y).powi(2);
                data[y * w + x] += amplitude * (-r2 / (2.0 * sigma * sigma)).exp();
            }
        }
    }
    let bytes = data
        .iter()
        .map(|v| v.round().clamp(0.0, 255.0) as u8)
        .collect();
    GreyFrame::new(w, h, bytes).expect("w * h bytes")
}
