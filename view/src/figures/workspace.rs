//! Workspace views of one finger: scatter projections of its reachable
//! points (`dexitac workspace`).

use dexitac_gripper::workspace::extents;
use image::{Rgb, RgbImage};

/// A view of the point cloud for [`render`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum View {
    /// Looking down the finger's z axis: x right, y up.
    Xy,
    /// From the side: x right, z up.
    Xz,
    /// Oblique 3-D view (azimuth 35 deg, elevation 25 deg), z up.
    ThreeD,
}

/// Projects a point to view coordinates `(right, up, depth)` (depth grows
/// away from the viewer).
fn project(view: View, p: [f64; 3]) -> [f64; 3] {
    match view {
        View::Xy => [p[0], p[1], -p[2]],
        View::Xz => [p[0], p[2], p[1]],
        View::ThreeD => {
            let (sa, ca) = 35f64.to_radians().sin_cos();
            let (se, ce) = 25f64.to_radians().sin_cos();
            // Rotate about z by the azimuth, then tilt by the elevation.
            let right = ca * p[0] - sa * p[1];
            let fwd = sa * p[0] + ca * p[1];
            [right, ce * p[2] - se * fwd, ce * fwd + se * p[2]]
        }
    }
}

/// Grid line spacing of the plots, mm.
pub const GRID_MM: f64 = 10.0;
const MARGIN_PX: f64 = 20.0;

/// Renders a scatter view of the points: a square `size_px` image, equal
/// scale on both axes, light grid lines every [`GRID_MM`] (planar views
/// only), the view's axes
/// through the finger base (origin) in dark grey (in the 3-D view: x red,
/// y green, z blue, 20 mm long), points coloured by depth from blue (near)
/// to red (far) and drawn far to near. No text: the axes are named in the
/// file names and in [`View`].
pub fn render(points: &[[f64; 3]], view: View, size_px: u32) -> RgbImage {
    let size = f64::from(size_px.max(2 * MARGIN_PX as u32 + 2));
    let mut img = RgbImage::from_pixel(size as u32, size as u32, Rgb([255, 255, 255]));
    let mut projected: Vec<[f64; 3]> = points.iter().map(|&p| project(view, p)).collect();
    projected.push([0.0; 3]); // keep the origin in view
    let ext = extents(projected.iter());
    let span = ext.size_mm[0].max(ext.size_mm[1]).max(1.0);
    let scale = (size - 2.0 * MARGIN_PX) / span;
    let cx = 0.5 * (ext.min_mm[0] + ext.max_mm[0]);
    let cy = 0.5 * (ext.min_mm[1] + ext.max_mm[1]);
    let to_px = |r: f64, u: f64| (0.5 * size + (r - cx) * scale, 0.5 * size - (u - cy) * scale);
    // Axes through the origin, and a grid in the planar views.
    let o = to_px(0.0, 0.0);
    match view {
        View::Xy | View::Xz => {
            let grey = Rgb([225, 225, 225]);
            let half = 0.5 * span + MARGIN_PX / scale;
            let first = |c: f64| ((c - half) / GRID_MM).floor() as i64;
            let last = |c: f64| ((c + half) / GRID_MM).ceil() as i64;
            for k in first(cx)..=last(cx) {
                let (x, _) = to_px(k as f64 * GRID_MM, 0.0);
                line(&mut img, (x, 0.0), (x, size), grey);
            }
            for k in first(cy)..=last(cy) {
                let (_, y) = to_px(0.0, k as f64 * GRID_MM);
                line(&mut img, (0.0, y), (size, y), grey);
            }
            let dark = Rgb([90, 90, 90]);
            line(&mut img, (0.0, o.1), (size, o.1), dark);
            line(&mut img, (o.0, 0.0), (o.0, size), dark);
        }
        View::ThreeD => {
            let colours = [Rgb([220, 0, 0]), Rgb([0, 160, 0]), Rgb([0, 0, 220])];
            for (k, colour) in colours.into_iter().enumerate() {
                let mut tip = [0.0; 3];
                tip[k] = 20.0;
                let t = project(view, tip);
                line(&mut img, o, to_px(t[0], t[1]), colour);
            }
        }
    }
    // Points, far to near.
    projected.pop();
    projected.sort_by(|a, b| b[2].total_cmp(&a[2]));
    let (dmin, dmax) = (ext.min_mm[2], ext.max_mm[2]);
    for q in &projected {
        let t = if dmax > dmin {
            (dmax - q[2]) / (dmax - dmin)
        } else {
            0.5
        };
        // t = 1 nearest: blue; t = 0 farthest: red.
        let colour = Rgb([
            (230.0 * (1.0 - t)) as u8,
            (60.0 + 60.0 * (1.0 - (2.0 * t - 1.0).abs())) as u8,
            (230.0 * t) as u8,
        ]);
        let (x, y) = to_px(q[0], q[1]);
        dot(&mut img, x, y, colour);
    }
    img
}

fn put(img: &mut RgbImage, x: f64, y: f64, colour: Rgb<u8>) {
    if x >= 0.0 && y >= 0.0 && x < f64::from(img.width()) && y < f64::from(img.height()) {
        img.put_pixel(x as u32, y as u32, colour);
    }
}

fn dot(img: &mut RgbImage, x: f64, y: f64, colour: Rgb<u8>) {
    for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
        put(img, x + dx - 0.5, y + dy - 0.5, colour);
    }
}

fn line(img: &mut RgbImage, a: (f64, f64), b: (f64, f64), colour: Rgb<u8>) {
    let steps = (b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil().max(1.0);
    // At most a few thousand steps: the ends are inside or near the image.
    let steps = steps.min(1e5) as u32;
    for i in 0..=steps {
        let t = f64::from(i) / f64::from(steps);
        put(img, a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1), colour);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_draws_points_inside_the_image() {
        let pts = [[0.0, 0.0, 50.0], [10.0, -5.0, 40.0], [-20.0, 3.0, 60.0]];
        for view in [View::Xy, View::Xz, View::ThreeD] {
            let img = render(&pts, view, 200);
            assert_eq!(img.dimensions(), (200, 200));
            let coloured = img
                .pixels()
                .filter(|p| p.0[0] != p.0[1] || p.0[1] != p.0[2])
                .count();
            assert!(coloured >= 3, "{view:?}: {coloured}");
        }
    }
}
