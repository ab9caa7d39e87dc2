//! Files a simulated run writes (`dexitac sim --out DIR`):
//!
//! - `events.log`: pokes, decisions, commands, valve changes, drop, end;
//! - `timeseries.csv`: every 10 ms of simulated time: both measured contact
//!   centres (mm from the image centre; empty without contact), both true
//!   centres, each chamber's valve state (-1 deflate, 0 hold, 1 inflate),
//!   tank pressures, external force, grip and object state;
//! - `plot.png`: the paper's disturbance figure layout, top to bottom: poke
//!   force (red), contact centre shift from its value at the first seal
//!   (black: sensor 0, grey: sensor 1, dashed: T1 and T2), grasping chamber
//!   valve states (one lane per chamber, up = inflate, down = deflate),
//!   tank (blue) and grasping chamber (purple) pressures; a green band from
//!   each poke's onset to the valves opening, a red line where the object
//!   fell;
//! - `heatmap_NN_<t>s_<event>.png`: both sensors' marker density relative to
//!   rest at each decision (dark red: compressed away, white: rest, blue:
//!   denser), with the measured centre as a cross;
//! - `summary.json`.

use std::fmt::Write as _;
use std::io;
use std::path::Path;

use image::{Rgb, RgbImage};

use crate::density;
use crate::grasp::{Cause, CentreMm, Command};
use crate::sim::plant::{PokeTarget, WorldState, FINGER_COUNT};
use crate::sim::rig::{SimReport, Snapshot};

/// Most heatmap snapshots written per run.
const MAX_HEATMAPS: usize = 16;

/// Writes every file into `dir` (created if needed).
pub fn write_all(report: &SimReport, dir: &Path) -> io::Result<()> {
    std::fs::create_dir_all(dir)?;
    std::fs::write(dir.join("events.log"), event_log(report))?;
    std::fs::write(dir.join("timeseries.csv"), timeseries_csv(report))?;
    std::fs::write(dir.join("summary.json"), summary_json(report))?;
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

fn valves_string(chambers: &dexitac_protocol::Chambers) -> String {
    chambers
        .iter()
        .map(|v| match v.as_sign() {
            1 => '+',
            -1 => '-',
            _ => '.',
        })
        .collect()
}

/// The event log, time-ordered.
pub fn event_log(r: &SimReport) -> String {
    let mut lines: Vec<(u64, String)> = Vec::new();
    for d in &r.disturbances {
        lines.push((
            (d.t_onset_s * 1e3) as u64,
            format!(
                "poke onset: {:?} (finger {}), {:.1} N peak over {:.2} s",
                d.poke.target, d.poke.finger, d.poke.peak_n, d.poke.duration_s
            ),
        ));
    }
    for (t, d) in &r.decisions {
        let cause = match d.cause {
            Cause::BothStable => "both sensors stable".to_string(),
            Cause::Disturbance {
                sensor,
                frame_shift_mm,
                anchored_shift_mm,
            } => format!("disturbance on sensor {sensor}: frame shift {frame_shift_mm:.2} mm, anchored {anchored_shift_mm:.2} mm"),
            Cause::Slip {
                sensor,
                frame_shift_mm,
                anchored_shift_mm,
            } => format!("slip on sensor {sensor}: frame shift {frame_shift_mm:.2} mm, anchored {anchored_shift_mm:.2} mm"),
            Cause::ContactLost { sensor } => format!("contact lost on sensor {sensor}"),
            Cause::NoContact { sensor } => format!("no contact on sensor {sensor} within the timeout"),
        };
        lines.push((
            *t,
            format!(
                "decision: {:?} ({cause}; frame captured at {:.3} s)",
                d.command,
                secs(d.t_ms)
            ),
        ));
    }
    for (t, msg, reason) in &r.commands {
        lines.push((*t, format!("command sent: {msg:?} ({reason})")));
    }
    for (t, chambers) in &r.transitions {
        lines.push((*t, format!("valve outputs: {}", valves_string(chambers))));
    }
    if let Some(t) = r.dropped_at_ms {
        lines.push((t, "object dropped".to_string()));
    }
    lines.sort_by_key(|(t, _)| *t);
    let mut out = format!(
        "# dexitac sim: scenario {}, tactile feedback {}\n# valves: chamber 0..7, + inflate, - deflate, . hold\n",
        r.scenario,
        if r.tactile_feedback { "on" } else { "off" }
    );
    for (t, line) in lines {
        let _ = writeln!(out, "{:9.3} s  {line}", secs(t));
    }
    let _ = writeln!(
        out,
        "{:9.3} s  end: outcome {}, loop {:?}, MCU {:?}",
        r.sim_s,
        r.outcome.name(),
        r.loop_result,
        r.mcu_at_end.state
    );
    out
}

/// The latest measured centre of `sensor` at or before each trace row.
fn measured_at(r: &SimReport, sensor: usize) -> Vec<Option<CentreMm>> {
    let obs: Vec<_> = r
        .observations
        .iter()
        .filter(|o| o.sensor == sensor)
        .collect();
    let mut k = 0;
    let mut last = None;
    r.trace
        .iter()
        .map(|w| {
            while let Some(o) = obs.get(k) {
                if o.t_ms > w.t_ms {
                    break;
                }
                last = o.centre_mm;
                k += 1;
            }
            last
        })
        .collect()
}

/// The time series as CSV.
pub fn timeseries_csv(r: &SimReport) -> String {
    let mut out = String::from(
        "t_s,c0_x_mm,c0_y_mm,c1_x_mm,c1_y_mm,true_c0_x_mm,true_c0_y_mm,true_c1_x_mm,true_c1_y_mm",
    );
    for i in 0..dexitac_protocol::CHAMBER_COUNT {
        let _ = write!(out, ",valve{i}");
    }
    out.push_str(",tank_pos_kpa,tank_neg_kpa,external_n,grasp0_kpa,grasp1_kpa,normal0_n,normal1_n,capacity_n,load_n,slide_mm,lift_mm,move_mm,object\n");
    let measured: Vec<_> = (0..FINGER_COUNT).map(|s| measured_at(r, s)).collect();
    let opt = |v: Option<f64>| v.map_or(String::new(), |v| format!("{v:.3}"));
    for (i, w) in r.trace.iter().enumerate() {
        let _ = write!(out, "{:.3}", secs(w.t_ms));
        for m in &measured {
            let c = m.get(i).copied().flatten();
            let _ = write!(
                out,
                ",{},{}",
                opt(c.map(|c| c.x_mm)),
                opt(c.map(|c| c.y_mm))
            );
        }
        for c in &w.contacts {
            let _ = write!(
                out,
                ",{},{}",
                opt(c.map(|c| c.centre_mm[0])),
                opt(c.map(|c| c.centre_mm[1]))
            );
        }
        for v in &w.valves {
            let _ = write!(out, ",{}", v.as_sign());
        }
        let grasp = |f: usize| {
            let mine: Vec<f64> = r
                .grasp_chambers
                .iter()
                .filter(|&&c| c / 4 == f)
                .filter_map(|&c| w.chambers_kpa.get(c).copied())
                .collect();
            mine.iter().sum::<f64>() / mine.len().max(1) as f64
        };
        let normal = |f: usize| w.contacts.get(f).copied().flatten().map(|c| c.normal_n);
        let _ = writeln!(
            out,
            ",{:.2},{:.2},{:.3},{:.2},{:.2},{},{},{:.3},{:.3},{:.3},{:.1},{:.1},{:?}",
            w.tanks_kpa.0,
            w.tanks_kpa.1,
            w.external_n,
            grasp(0),
            grasp(1),
            opt(normal(0)),
            opt(normal(1)),
            w.capacity_n,
            w.load_n,
            w.slide_mm,
            w.gripper_mm.0,
            w.gripper_mm.1,
            w.object
        );
    }
    out
}

fn json_opt(v: Option<f64>) -> String {
    v.map_or("null".to_string(), |v| format!("{v:.3}"))
}

fn json_str(s: &str) -> String {
    let mut out = String::from("\"");
    for ch in s.chars() {
        match ch {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn percentile_ms(sorted_ms: &[f64], p: f64) -> Option<f64> {
    if sorted_ms.is_empty() {
        return None;
    }
    let i = ((sorted_ms.len() - 1) as f64 * p).round() as usize;
    sorted_ms.get(i).copied()
}

/// `summary.json`.
pub fn summary_json(r: &SimReport) -> String {
    let target = |t: PokeTarget| match t {
        PokeTarget::Object => "object",
        PokeTarget::Actuator => "actuator",
        PokeTarget::FingertipBack => "fingertip_back",
    };
    let disturbances: Vec<String> = r
        .disturbances
        .iter()
        .map(|d| {
            format!(
                "    {{\"target\": {}, \"finger\": {}, \"peak_n\": {:.2}, \"t_onset_s\": {:.3}, \"t_detected_s\": {}, \"t_reopen_sent_s\": {}, \"t_valves_open_s\": {}, \"response_s\": {}}}",
                json_str(target(d.poke.target)),
                d.poke.finger,
                d.poke.peak_n,
                d.t_onset_s,
                json_opt(d.t_detected_s),
                json_opt(d.t_reopen_sent_s),
                json_opt(d.t_valves_open_s),
                json_opt(d.response_s())
            )
        })
        .collect();
    let mut lat: Vec<f64> = r
        .frame_to_command
        .iter()
        .map(|d| d.as_secs_f64() * 1e3)
        .collect();
    lat.sort_by(f64::total_cmp);
    let loop_result = match &r.loop_result {
        Ok(reason) => format!("{reason:?}"),
        Err(e) => format!("error: {e}"),
    };
    format!(
        "{{\n  \"scenario\": {},\n{}  \"tactile_feedback\": {},\n  \"outcome\": {},\n  \"time_to_stable_s\": {},\n  \"disturbances\": [\n{}\n  ],\n  \"dropped_at_s\": {},\n  \"frame_to_command_ms\": {{\"count\": {}, \"median\": {}, \"p99\": {}}},\n  \"frames\": {},\n  \"host_max_loop_gap_ms\": {:.1},\n  \"loop_result\": {},\n  \"mcu_state_at_end\": {},\n  \"sim_s\": {:.3},\n  \"wall_s\": {:.3}\n}}\n",
        json_str(&r.scenario),
        task_json(r),
        r.tactile_feedback,
        json_str(r.outcome.name()),
        json_opt(r.time_to_stable_s),
        disturbances.join(",\n"),
        json_opt(r.dropped_at_ms.map(secs)),
        lat.len(),
        json_opt(percentile_ms(&lat, 0.5)),
        json_opt(percentile_ms(&lat, 0.99)),
        r.observations.len(),
        r.max_loop_gap.as_secs_f64() * 1e3,
        json_str(&loop_result),
        json_str(&format!("{:?}", r.mcu_at_end.state)),
        r.sim_s,
        r.wall_s
    )
}

/// The manipulation task's lines of `summary.json` (empty without a task).
/// The simulated angles come from invented plant coefficients
/// ([`crate::sim::task_report`]); the paper's are ArUco measurements.
fn task_json(r: &SimReport) -> String {
    let Some(t) = &r.task else {
        return String::new();
    };
    let per_cycle: Vec<String> = t.per_cycle_deg.iter().map(|d| format!("{d:.2}")).collect();
    format!(
        "  \"task\": {},\n  \"gripper\": {},\n  \"achieved_deg\": {},\n  \"paper_deg\": {},\n  \"achieved_mm\": {},\n  \"paper_mm\": {},\n  \"per_cycle_deg\": [{}],\n  \"task_completed\": {},\n  \"stopped_by_guard\": {},\n  \"guard_trips\": {},\n  \"task_angles_from\": \"simulated plant with invented coefficients\",\n",
        json_str(t.kind.name()),
        json_str(&t.gripper),
        json_opt(t.achieved_deg),
        t.kind.paper_deg(),
        json_opt(t.achieved_mm),
        json_opt(t.kind.paper_mm()),
        per_cycle.join(", "),
        t.completed,
        t.stopped_by_guard,
        t.guard_trips
    )
}

// ---- drawing ----

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

/// A 3x5 pixel font for the plot's labels: digits, capitals and a few signs
/// (also used by the live view, [`crate::view`]).
fn glyph(c: char) -> [u8; 5] {
    // Each row: 3 bits, the leftmost pixel in bit 2.
    match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '.' => [0, 0, 0, 0, 2],
        '-' => [0, 0, 7, 0, 0],
        '+' => [0, 2, 7, 2, 0],
        '/' => [1, 1, 2, 4, 4],
        '(' => [2, 4, 4, 4, 2],
        ')' => [2, 1, 1, 1, 2],
        ',' => [0, 0, 0, 2, 4],
        ':' => [0, 2, 0, 2, 0],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [7, 4, 4, 4, 7],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [7, 4, 5, 5, 7],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [7, 5, 5, 5, 7],
        'P' => [7, 5, 7, 4, 4],
        'R' => [6, 5, 6, 5, 5],
        'S' => [7, 4, 7, 1, 7],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        'J' => [1, 1, 1, 5, 7],
        'Q' => [7, 5, 5, 7, 1],
        '=' => [0, 7, 0, 7, 0],
        '%' => [5, 1, 2, 4, 5],
        '>' => [4, 2, 1, 2, 4],
        '<' => [1, 2, 4, 2, 1],
        '_' => [0, 0, 0, 0, 7],
        '|' => [2, 2, 2, 2, 2],
        _ => [0; 5],
    }
}

/// Draws `text` (upper case) with its top-left at (x, y), `scale` px per
/// font pixel (4 * scale px per character). Also used by the tactile
/// benchmark's Pareto plot (`crate::bench::pareto_plot`) and the live view.
pub(crate) fn text(img: &mut RgbImage, x: i64, y: i64, text: &str, scale: i64, c: Rgb<u8>) {
    for (i, ch) in text.chars().enumerate() {
        let rows = glyph(ch.to_ascii_uppercase());
        for (r, bits) in rows.iter().enumerate() {
            for col in 0..3 {
                if bits & (4 >> col) != 0 {
                    for dy in 0..scale {
                        for dx in 0..scale {
                            put(
                                img,
                                x + (i as i64 * 4 + col) * scale + dx,
                                y + r as i64 * scale + dy,
                                c,
                            );
                        }
                    }
                }
            }
        }
    }
}

/// Sets one pixel; points outside the image are ignored.
pub(crate) fn put(img: &mut RgbImage, x: i64, y: i64, c: Rgb<u8>) {
    if x >= 0 && y >= 0 && (x as u32) < img.width() && (y as u32) < img.height() {
        img.put_pixel(x as u32, y as u32, c);
    }
}

/// A 2 px thick line from `a` to `b` (Bresenham); clipped to the image.
pub(crate) fn line(img: &mut RgbImage, a: (i64, i64), b: (i64, i64), c: Rgb<u8>) {
    let (mut x, mut y) = a;
    let dx = (b.0 - a.0).abs();
    let dy = -(b.1 - a.1).abs();
    let sx = if a.0 < b.0 { 1 } else { -1 };
    let sy = if a.1 < b.1 { 1 } else { -1 };
    let mut err = dx + dy;
    loop {
        put(img, x, y, c);
        put(img, x, y + 1, c);
        if (x, y) == b {
            break;
        }
        let e2 = 2 * err;
        if e2 >= dy {
            err += dy;
            x += sx;
        }
        if e2 <= dx {
            err += dx;
            y += sy;
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

/// Colour of a density ratio (density / rest): dark red (0) -> white (1) -> blue (>1.3).
pub(crate) fn ratio_colour(ratio: f64) -> Rgb<u8> {
    if !ratio.is_finite() {
        return Rgb([60, 60, 60]);
    }
    if ratio < 1.0 {
        let f = ratio.clamp(0.0, 1.0);
        Rgb([
            (120.0 + 135.0 * f) as u8,
            (255.0 * f) as u8,
            (255.0 * f) as u8,
        ])
    } else {
        let f = ((ratio - 1.0) / 0.3).clamp(0.0, 1.0);
        Rgb([
            (255.0 * (1.0 - f)) as u8,
            (255.0 * (1.0 - f * 0.6)) as u8,
            255,
        ])
    }
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
