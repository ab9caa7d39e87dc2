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

use crate::plant::{PokeTarget, FINGER_COUNT};
use crate::rig::SimReport;
use dexitac_gripper::grasp::{Cause, CentreMm};

/// Writes the text files (`events.log`, `timeseries.csv`, `summary.json`)
/// into `dir` (created if needed). The figures are drawn by the view crate.
pub fn write_all(report: &SimReport, dir: &Path) -> io::Result<()> {
    std::fs::create_dir_all(dir)?;
    std::fs::write(dir.join("events.log"), event_log(report))?;
    std::fs::write(dir.join("timeseries.csv"), timeseries_csv(report))?;
    std::fs::write(dir.join("summary.json"), summary_json(report))?;
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
/// ([`crate::task_report`]); the paper's are ArUco measurements.
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
