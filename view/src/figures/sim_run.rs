//! Figures of a simulated run (`dexitac sim --out DIR`): the disturbance
//! figure `plot.png` and the density heatmaps.

use dexitac_gripper::grasp::Command;
use dexitac_sim::plant::WorldState;
use dexitac_sim::rig::{SimReport, Snapshot};
use dexitac_tactile::density;
use std::io;
use std::path::Path;

use image::{Rgb, RgbImage};

use crate::raster::{line, put, ratio_colour, text};

/// Most heatmap snapshots written per run.
const MAX_HEATMAPS: usize = 16;

/// Writes `plot.png` and the heatmaps (`heatmap_NN_<t>s_<event>.png`) of a
/// simulated run into `dir`.
pub fn write_all(report: &SimReport, dir: &Path) -> io::Result<()> {
    std::fs::create_dir_all(dir)?;
    plot(report)
        .save(dir.join("plot.png"))
        .map_err(io::Error::other)?;
    for (i, snap) in report.snapshots.iter().take(MAX_HEATMAPS).enumerate() {
        let name = format!(
            "heatmap_{i:02}_{:.2}s_{}.png",
            snap.t_ms as f64 / 1e3,
            snap.label
        );
        heatmap(report, snap)
            .save(dir.join(name))
            .map_err(io::Error::other)?;
    }
    Ok(())
}

fn secs(t_ms: u64) -> f64 {
    t_ms as f64 / 1e3
}

const WHITE: Rgb<u8> = Rgb([255, 255, 255]);
const BLACK: Rgb<u8> = Rgb([0, 0, 0]);
const GREY: Rgb<u8> = Rgb([140, 140, 140]);
const LIGHT: Rgb<u8> = Rgb([225, 225, 225]);
const RED: Rgb<u8> = Rgb([210, 30, 30]);
const GREEN_BAND: Rgb<u8> = Rgb([205, 240, 205]);
const BLUE: Rgb<u8> = Rgb([40, 80, 200]);
const PURPLE: Rgb<u8> = Rgb([140, 50, 160]);

/// A plot panel: pixel box and data ranges.
struct Panel {
    x0: i64,
    y0: i64,
    w: i64,
    h: i64,
    t_max_s: f64,
    lo: f64,
    hi: f64,
}

impl Panel {
    fn px(&self, t_s: f64, v: f64) -> (i64, i64) {
        let x = self.x0 + ((t_s / self.t_max_s.max(1e-9)) * self.w as f64) as i64;
        let f = ((v - self.lo) / (self.hi - self.lo).max(1e-9)).clamp(0.0, 1.0);
        (x, self.y0 + self.h - (f * self.h as f64) as i64)
    }

    fn frame(&self, img: &mut RgbImage) {
        for x in self.x0..=self.x0 + self.w {
            put(img, x, self.y0, GREY);
            put(img, x, self.y0 + self.h, GREY);
        }
        for y in self.y0..=self.y0 + self.h {
            put(img, self.x0, y, GREY);
            put(img, self.x0 + self.w, y, GREY);
        }
        // A tick every 5 s.
        let mut t = 0.0;
        while t <= self.t_max_s {
            let (x, _) = self.px(t, self.lo);
            for y in self.y0 + self.h - 6..=self.y0 + self.h {
                put(img, x, y, GREY);
            }
            t += 5.0;
        }
    }

    fn band(&self, img: &mut RgbImage, t0_s: f64, t1_s: f64, color: Rgb<u8>) {
        let (xa, _) = self.px(t0_s, self.lo);
        let (xb, _) = self.px(t1_s, self.lo);
        for x in xa..=xb.max(xa + 1) {
            for y in self.y0 + 1..self.y0 + self.h {
                put(img, x, y, color);
            }
        }
    }

    fn hline(&self, img: &mut RgbImage, v: f64, color: Rgb<u8>, dashed: bool) {
        let (_, y) = self.px(0.0, v);
        for x in self.x0..self.x0 + self.w {
            if !dashed || (x / 6) % 2 == 0 {
                put(img, x, y, color);
            }
        }
    }

    fn series(&self, img: &mut RgbImage, points: &[(f64, Option<f64>)], color: Rgb<u8>) {
        let mut prev: Option<(i64, i64)> = None;
        for &(t, v) in points {
            match v {
                Some(v) if v.is_finite() => {
                    let p = self.px(t, v);
                    if let Some(q) = prev {
                        line(img, q, p, color);
                    }
                    prev = Some(p);
                }
                _ => prev = None,
            }
        }
    }
}

/// The disturbance figure.
pub fn plot(r: &SimReport) -> RgbImage {
    let (w, h) = (1200u32, 900u32);
    let mut img = RgbImage::from_pixel(w, h, WHITE);
    let t_max_s = r.trace.last().map_or(1.0, |s| secs(s.t_ms)).max(1.0);
    let panel = |i: i64, lo: f64, hi: f64| Panel {
        x0: 40,
        y0: 20 + i * 210,
        w: w as i64 - 60,
        h: 185,
        t_max_s,
        lo,
        hi,
    };
    let max_force = r.trace.iter().map(|s| s.external_n).fold(1.0, f64::max);
    let panels = [
        panel(0, 0.0, max_force * 1.1),
        panel(1, 0.0, 6.0),
        // Headroom above the top lane for the label.
        panel(2, 0.0, r.grasp_chambers.len().max(1) as f64 + 0.6),
        panel(3, -60.0, 60.0),
    ];
    for p in &panels {
        for d in &r.disturbances {
            if let Some(open) = d.t_valves_open_s {
                p.band(&mut img, d.t_onset_s, open, GREEN_BAND);
            }
        }
        if let Some(t) = r.dropped_at_ms {
            p.band(&mut img, secs(t), secs(t) + t_max_s / 400.0, RED);
        }
        p.frame(&mut img);
    }
    let labels = [
        format!("POKE FORCE (N) 0-{:.1}", max_force * 1.1),
        "CONTACT CENTRE SHIFT (MM) 0-6, T1 0.5, T2 5".to_string(),
        "GRASP VALVES (CHAMBER LANES, UP +, DOWN -)".to_string(),
        "PRESSURE (KPA) -60-60: TANKS, GRASP CHAMBER".to_string(),
    ];
    for (p, label) in panels.iter().zip(&labels) {
        text(&mut img, p.x0 + 6, p.y0 + 6, label, 2, BLACK);
    }
    let mut tick_s = 0.0;
    while tick_s <= t_max_s {
        let (x, _) = panels[3].px(tick_s, 0.0);
        text(
            &mut img,
            x - 4,
            panels[3].y0 + panels[3].h + 6,
            &format!("{tick_s:.0}"),
            2,
            BLACK,
        );
        tick_s += 5.0;
    }
    text(
        &mut img,
        panels[3].x0 + panels[3].w - 60,
        panels[3].y0 + panels[3].h + 24,
        "T (S)",
        2,
        BLACK,
    );
    let t = |s: &WorldState| secs(s.t_ms);
    // Force.
    let force: Vec<_> = r.trace.iter().map(|s| (t(s), Some(s.external_n))).collect();
    panels[0].series(&mut img, &force, RED);
    // Contact centre shift from the first seal (or first contact).
    let seal_ms = r
        .decisions
        .iter()
        .find(|(_, d)| d.command == Command::Seal)
        .map(|(t, _)| *t);
    panels[1].hline(&mut img, 0.5, GREY, true);
    panels[1].hline(&mut img, 5.0, GREY, true);
    for (sensor, color) in [(0, BLACK), (1, GREY)] {
        let obs: Vec<_> = r
            .observations
            .iter()
            .filter(|o| o.sensor == sensor)
            .collect();
        let reference = obs
            .iter()
            .find(|o| seal_ms.is_none_or(|s| o.t_ms >= s) && o.centre_mm.is_some())
            .or_else(|| obs.iter().find(|o| o.centre_mm.is_some()))
            .and_then(|o| o.centre_mm);
        let points: Vec<_> = obs
            .iter()
            .map(|o| {
                let shift = o.centre_mm.zip(reference).map(|(c, r0)| c.distance_mm(r0));
                (secs(o.t_ms), shift)
            })
            .collect();
        panels[1].series(&mut img, &points, color);
    }
    // Valve lanes: one per grasping chamber, state -1/0/1 inside the lane.
    for (lane, &chamber) in r.grasp_chambers.iter().enumerate() {
        let base = lane as f64 + 0.5;
        panels[2].hline(&mut img, base, LIGHT, false);
        let points: Vec<_> = r
            .trace
            .iter()
            .map(|s| {
                let v = s.valves.get(chamber).map_or(0, |v| v.as_sign());
                (t(s), Some(base + 0.35 * f64::from(v)))
            })
            .collect();
        panels[2].series(&mut img, &points, BLACK);
    }
    // Pressures.
    panels[3].hline(&mut img, 0.0, LIGHT, false);
    let pos: Vec<_> = r
        .trace
        .iter()
        .map(|s| (t(s), Some(s.tanks_kpa.0)))
        .collect();
    let neg: Vec<_> = r
        .trace
        .iter()
        .map(|s| (t(s), Some(s.tanks_kpa.1)))
        .collect();
    let chamber = r.grasp_chambers.first().copied().unwrap_or(0);
    let grasp: Vec<_> = r
        .trace
        .iter()
        .map(|s| (t(s), s.chambers_kpa.get(chamber).copied()))
        .collect();
    panels[3].series(&mut img, &pos, BLUE);
    panels[3].series(&mut img, &neg, BLUE);
    panels[3].series(&mut img, &grasp, PURPLE);
    img
}

/// Both sensors' density relative to rest at a snapshot.
pub fn heatmap(r: &SimReport, snap: &Snapshot) -> RgbImage {
    let scale = 2u32;
    let panels: Vec<RgbImage> = r
        .calibrations
        .iter()
        .zip(&snap.markers)
        .map(|(cal, markers)| {
            let map = density::estimate(markers, &cal.density, None);
            let g = map.grid;
            let mut img = RgbImage::from_pixel(g.nx as u32 * scale, g.ny as u32 * scale, WHITE);
            for j in 0..g.ny {
                for i in 0..g.nx {
                    let k = j * g.nx + i;
                    let inside = cal.mask.get(k).copied().unwrap_or(false);
                    let rest = cal
                        .rest_density
                        .values_per_mm2
                        .get(k)
                        .copied()
                        .unwrap_or(0.0);
                    let v = map.values_per_mm2.get(k).copied().unwrap_or(0.0);
                    let c = if inside && rest > 0.0 {
                        ratio_colour(f64::from(v / rest))
                    } else {
                        Rgb([40, 40, 40])
                    };
                    for dy in 0..scale {
                        for dx in 0..scale {
                            img.put_pixel(i as u32 * scale + dx, j as u32 * scale + dy, c);
                        }
                    }
                }
            }
            img
        })
        .collect();
    let gap = 10;
    let width = panels.iter().map(|p| p.width()).sum::<u32>() + gap;
    let height = panels.iter().map(|p| p.height()).max().unwrap_or(1);
    let mut out = RgbImage::from_pixel(width.max(1), height.max(1), WHITE);
    let mut x0 = 0;
    for (sensor, p) in panels.iter().enumerate() {
        image::imageops::replace(&mut out, p, i64::from(x0), 0);
        // The measured centre closest before the snapshot.
        let centre = r
            .observations
            .iter()
            .rfind(|o| o.sensor == sensor && o.t_ms <= snap.t_ms)
            .and_then(|o| o.centre_mm);
        if let (Some(c), Some(cal)) = (centre, r.calibrations.get(sensor)) {
            let mm = cal.density.mm_per_px;
            let step = cal.density.grid().step_px.max(1) as f64;
            let cx =
                ((c.x_mm / mm + (cal.width as f64 - 1.0) / 2.0) / step * f64::from(scale)) as i64;
            let cy =
                ((c.y_mm / mm + (cal.height as f64 - 1.0) / 2.0) / step * f64::from(scale)) as i64;
            for d in -8..=8 {
                put(&mut out, i64::from(x0) + cx + d, cy, BLACK);
                put(&mut out, i64::from(x0) + cx, cy + d, BLACK);
            }
        }
        x0 += p.width() + gap;
    }
    out
}
