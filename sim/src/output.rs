//! Text files a simulated run writes (`dexitac sim --out DIR`); the figures
//! (`plot.png`, heatmaps) are drawn by the view crate.
//!
//! - `events.log`: for people. One line per event, time-ordered: time in s,
//!   then what happened in words, with units (N, s, kPa, mm): pokes,
//!   Algorithm 1's decisions and their causes, commands sent to the board,
//!   valve output changes, a drop, the end. No Rust debug output. The last
//!   line is the end: `end: ok, outcome held, ...`, or for a failed run
//!   `end: FAILED: <status>; object held at the end; task loop failed:
//!   <message>; MCU tripped (faults: ...)`. No line is timed after the end:
//!   scheduled pokes the run did not reach are one line at the end's time
//!   (`not reached, the run ended first: ...`), not poke onsets.
//! - `timeseries.csv`: the columns below ([`write_timeseries`]), up to the
//!   end of the run.
//! - `summary.json`: the run in numbers ([`Summary`]; the fields' docs give
//!   each key's meaning and unit). Times in s, rounded to 1 ms; numbers
//!   that are not finite are `null`.
//!
//! # Failed runs
//!
//! A run *fails* when its task loop did not end normally
//! ([`SimReport::loop_result`] is an error: the MCU tripped or reset, the
//! link or a sensor failed). Every output says so ([`crate::status`]):
//!
//! - `summary.json`: `status` is `ok` for a run that did not fail, else the
//!   failure in words with its simulated time (a trip's from the MCU's fault
//!   event, else the end of the run): `tripped: HostSilence at 11.3 s`,
//!   `MCU reset, noticed at 4.2 s`, `error: <message>`; `outcome` is `failed` (never `held`), and
//!   `object_at_end` keeps what became of the object (`held`, `dropped`,
//!   `released`, `not_grasped`: the same as `outcome` when the run did not
//!   fail);
//! - `events.log`: the end line starts with `FAILED: <status>`;
//! - `dexitac sim`'s last stdout line starts with `FAILED: <status>` and its
//!   exit code is 1; the figure's title says `FAILED: <status>`.
//!
//! **Nothing after the end.** A run ends at [`SimReport::sim_s`] (the
//! scenario's duration, shortly after a drop or release, or earlier on a
//! failure). A scheduled poke whose onset is not before the end was never
//! applied: it is not in `disturbances` (nor in the figure, nor among the
//! poke onsets of `events.log`) but in `pokes_not_reached`, whose length
//! counts them. `timeseries.csv` has no row after the end.
//!
//! # `timeseries.csv`
//!
//! One row per 10 ms of simulated time (the plant's trace). An empty cell
//! means no value: no contact, no anchor held, or a number that is not
//! finite. Sensor `k` is the fingertip of finger `k`; its measured columns
//! hold its latest frame at or before `t_s`.
//!
//! | column | unit | meaning |
//! | --- | --- | --- |
//! | `t_s` | s | simulated time |
//! | `c0_x_mm`, `c0_y_mm` | mm | sensor 0's measured contact centre from the image centre; empty without contact |
//! | `c1_x_mm`, `c1_y_mm` | mm | sensor 1's, as for sensor 0 |
//! | `d0_mm`, `d1_mm` | mm | D(t) of sensor 0 and 1: Algorithm 1's frame-to-frame shift, the distance of the frame's centre from the same sensor's previous centre ([`dexitac_gripper::grasp::shifts_mm`]); 0 on the first frame of a contact; empty without contact |
//! | `a0_mm`, `a1_mm` | mm | shift of sensor 0 and 1 from the anchor, the sensor's centre when the grasp was sealed (Algorithm 1's anchored shift); empty without contact and while no anchor is held (before the first seal, after a release) |
//! | `true_c0_x_mm`, `true_c0_y_mm`, `true_c1_x_mm`, `true_c1_y_mm` | mm | the plant's true contact centre per fingertip, from the sensor centre; empty without contact |
//! | `valve0` ... `valve7` | -1, 0, 1 | each chamber's valve output: -1 deflate, 0 hold, 1 inflate |
//! | `tank_pos_kpa`, `tank_neg_kpa` | kPa | positive and negative tank pressure (gauge) |
//! | `external_n` | N | total poke force |
//! | `grasp0_kpa`, `grasp1_kpa` | kPa | mean pressure of each finger's grasping chambers; empty if the finger has none |
//! | `normal0_n`, `normal1_n` | N | normal force of each fingertip's contact; empty without contact |
//! | `capacity_n` | N | friction capacity of the grasp |
//! | `load_n` | N | tangential load on the grasp |
//! | `slide_mm` | mm | slide of the object in the grasp |
//! | `lift_mm`, `move_mm` | mm | gripper height and horizontal position |
//! | `object` | word | `absent` (no object in the scenario), `in_grasp` (between the fingers, on the table or lifted), `dropped` |
//!
//! **The anchor.** [`dexitac_gripper::grasp::Grasp`] sets each sensor's
//! anchor to its latest centre when it seals. Here the anchors are set the
//! same way from the recorded seal decisions, in the order the task loop
//! saw the frames and the decisions ([`frame_shifts`]), and dropped at a
//! release. Without tactile feedback there are no decisions, so no anchor.
//! D is computed on every frame, also where the task loop does not feed the
//! grasp (charging, a manipulation task) and across the start of closing,
//! where the grasp forgets the previous frame (its D is 0 there).

use std::fs::File;
use std::io::{self, BufWriter, Write as _};
use std::path::Path;

use serde::Serialize;

use crate::plant::{ObjectState, PokeTarget, WorldState, FINGER_COUNT};
use crate::rig::{Pace, SimReport};
use crate::status::{seconds, LoopError};
use dexitac_gripper::grasp::{shifts_mm, Cause, CentreMm, Command};
use dexitac_protocol::{ArmState, Chambers, HostMsg, PumpMode, CHAMBER_COUNT};
use dexitac_rig::event::StopReason;

/// Writes the text files (`events.log`, `timeseries.csv`, `summary.json`)
/// into `dir` (created if needed). An error names the file.
pub fn write_all(report: &SimReport, dir: &Path) -> io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let file = |name: &str, write: &dyn Fn(&mut BufWriter<File>) -> io::Result<()>| {
        let path = dir.join(name);
        let named = |e: io::Error| io::Error::new(e.kind(), format!("{}: {e}", path.display()));
        let mut w = BufWriter::new(File::create(&path).map_err(named)?);
        write(&mut w).and_then(|()| w.flush()).map_err(named)
    };
    file("events.log", &|w| w.write_all(event_log(report).as_bytes()))?;
    file("timeseries.csv", &|w| write_timeseries(report, w))?;
    file("summary.json", &|w| {
        w.write_all(summary_json(report)?.as_bytes())
    })?;
    Ok(())
}

fn secs(t_ms: u64) -> f64 {
    t_ms as f64 / 1e3
}

/// `v` rounded to `decimals` places, or `None` if it is not finite.
fn rounded(v: f64, decimals: i32) -> Option<f64> {
    let scale = 10f64.powi(decimals);
    let r = (v * scale).round() / scale;
    r.is_finite().then_some(r)
}

/// A chamber map as one character per chamber: `+` inflate, `-` deflate,
/// `.` hold.
fn valves_string(chambers: &Chambers) -> String {
    chambers
        .iter()
        .map(|v| match v.as_sign() {
            1 => '+',
            -1 => '-',
            _ => '.',
        })
        .collect()
}

fn poke_target(t: PokeTarget) -> &'static str {
    match t {
        PokeTarget::Object => "object",
        PokeTarget::Actuator => "actuator",
        PokeTarget::FingertipBack => "back of the fingertip",
    }
}

fn command_words(c: Command) -> &'static str {
    match c {
        Command::Seal => "seal",
        Command::ReopenInflation => "reopen inflation",
        Command::Release => "release",
    }
}

fn cause_words(cause: &Cause) -> String {
    match *cause {
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
    }
}

fn pump_words(mode: PumpMode) -> &'static str {
    match mode {
        PumpMode::Off => "off",
        PumpMode::Regulate => "regulating",
    }
}

fn kpa(pa: i32) -> f64 {
    f64::from(pa) / 1e3
}

/// A command to the board in words.
fn host_msg_words(msg: &HostMsg) -> String {
    match msg {
        HostMsg::Hello => "hello (versions and limits)".to_string(),
        HostMsg::Ping { .. } => "ping".to_string(),
        HostMsg::SetChambers { chambers } => format!("set valves {}", valves_string(chambers)),
        HostMsg::SealAll => "seal all chambers".to_string(),
        HostMsg::VentAll => "vent all chambers, pumps off".to_string(),
        HostMsg::SetPumps { positive, negative } => format!(
            "pumps: positive {}, negative {}",
            pump_words(*positive),
            pump_words(*negative)
        ),
        HostMsg::SetTankTargets(t) => format!(
            "tank targets {:+.1} kPa and {:+.1} kPa",
            kpa(t.positive_pa()),
            kpa(t.negative_pa())
        ),
        HostMsg::Arm => "arm".to_string(),
        HostMsg::Disarm => "disarm".to_string(),
        HostMsg::SetTelemetryInterval { interval_ms: 0 } => "telemetry off".to_string(),
        HostMsg::SetTelemetryInterval { interval_ms } => {
            format!("telemetry every {interval_ms} ms")
        }
        HostMsg::Heartbeat => "heartbeat".to_string(),
        HostMsg::ClearFaults { faults } => {
            let names: Vec<String> = faults.iter().map(|f| f.to_string()).collect();
            format!("clear faults: {}", names.join("; "))
        }
        HostMsg::SetCalibration(c) => format!(
            "sensor calibration: positive {:+.1} kPa x{:.4}, negative {:+.1} kPa x{:.4}",
            kpa(c.positive.offset_pa),
            f64::from(c.positive.gain_ppm) / 1e6,
            kpa(c.negative.offset_pa),
            f64::from(c.negative.gain_ppm) / 1e6
        ),
    }
}

fn arm_state_words(s: ArmState) -> &'static str {
    match s {
        ArmState::Disarmed => "disarmed",
        ArmState::Armed => "armed",
        ArmState::Tripped => "tripped",
    }
}

fn loop_words(r: &Result<StopReason, LoopError>) -> String {
    match r {
        Ok(StopReason::Requested) => "task loop stopped on request".to_string(),
        Ok(StopReason::FramesEnded) => "task loop stopped: the frames ended".to_string(),
        Err(e) => format!("task loop failed: {e}"),
    }
}

/// The event log, time-ordered, for people (see the module docs).
pub fn event_log(r: &SimReport) -> String {
    let mut lines: Vec<(u64, String)> = Vec::new();
    for d in r.pokes_reached() {
        lines.push((
            (d.t_onset_s * 1e3) as u64,
            format!(
                "poke onset: {} (finger {}), {:.1} N peak over {:.2} s",
                poke_target(d.poke.target),
                d.poke.finger,
                d.poke.peak_n,
                d.poke.duration_s
            ),
        ));
    }
    for (t, d) in &r.decisions {
        lines.push((
            *t,
            format!(
                "decision: {} ({}; frame captured at {:.3} s)",
                command_words(d.command),
                cause_words(&d.cause),
                secs(d.t_ms)
            ),
        ));
    }
    for (t, msg, reason) in &r.commands {
        lines.push((
            *t,
            format!("command sent: {} ({reason})", host_msg_words(msg)),
        ));
    }
    for (t, chambers) in &r.transitions {
        lines.push((*t, format!("valve outputs: {}", valves_string(chambers))));
    }
    if let Some(t) = r.dropped_at_ms {
        lines.push((t, "object dropped".to_string()));
    }
    let mcu = &r.mcu_at_end;
    let faults: Vec<_> = mcu.faults.iter().map(|f| f.to_string()).collect();
    let faults = if faults.is_empty() {
        String::new()
    } else {
        format!(" (faults: {})", faults.join(", "))
    };
    let end_ms = r.end_ms().unwrap_or(0);
    let late: Vec<String> = r
        .pokes_not_reached()
        .map(|d| format!("{} s", seconds(d.t_onset_s)))
        .collect();
    if !late.is_empty() {
        lines.push((
            end_ms,
            format!(
                "not reached, the run ended first: {} scheduled poke(s), onsets {}",
                late.len(),
                late.join(", ")
            ),
        ));
    }
    let status = r.status();
    let outcome = r.outcome.name().replace('_', " ");
    let loop_words = loop_words(&r.loop_result);
    let mcu_words = arm_state_words(mcu.state);
    // Last among the events of its millisecond (the sort is stable).
    lines.push((
        end_ms,
        if status.is_ok() {
            format!("end: ok, outcome {outcome}, {loop_words}, MCU {mcu_words}{faults}")
        } else {
            format!(
                "end: FAILED: {status}; object {outcome} at the end; {loop_words}; MCU {mcu_words}{faults}"
            )
        },
    ));
    lines.sort_by_key(|(t, _)| *t);
    let mut out = format!(
        "# dexitac sim: scenario {}, tactile feedback {}\n# valves: chamber 0..{}, + inflate, - deflate, . hold\n",
        r.scenario,
        if r.tactile_feedback { "on" } else { "off" },
        CHAMBER_COUNT - 1
    );
    for (t, line) in lines {
        out.push_str(&format!("{:9.3} s  {line}\n", secs(t)));
    }
    out
}

/// One frame of one sensor with Algorithm 1's shifts, as the time series
/// holds it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrameShifts {
    /// Capture time, ms.
    pub t_ms: u64,
    /// The measured contact centre, mm; `None` without contact.
    pub centre_mm: Option<CentreMm>,
    /// D: the shift from the sensor's previous centre, mm (0 on the first
    /// frame of a contact); `None` without contact.
    pub frame_shift_mm: Option<f64>,
    /// A: the shift from the anchor, mm; `None` without contact or anchor.
    pub anchored_shift_mm: Option<f64>,
}

/// Every frame of each sensor, in the order the task loop reported them,
/// with D and A as [`dexitac_gripper::grasp::Grasp`] computes them: D from
/// the sensor's previous frame, A from the anchor. The anchors follow the
/// recorded decisions, placed among the frames by
/// [`SimReport::observations_before_decision`]: a seal makes each sensor's
/// latest centre its anchor, a release drops them. Frames the grasp ignores
/// (a centre that is not finite, or older than the sensor's previous frame)
/// have no shifts.
pub fn frame_shifts(r: &SimReport) -> [Vec<FrameShifts>; FINGER_COUNT] {
    // Anchor changes: (observations before, set (true) or drop).
    let mut anchor_events: Vec<(usize, bool)> = r
        .decisions
        .iter()
        .zip(&r.observations_before_decision)
        .filter_map(|((_, d), &before)| match d.command {
            Command::Seal => Some((before, true)),
            Command::Release => Some((before, false)),
            Command::ReopenInflation => None,
        })
        .collect();
    anchor_events.sort_by_key(|&(before, _)| before);
    let mut events = anchor_events.into_iter().peekable();
    let mut out: [Vec<FrameShifts>; FINGER_COUNT] = Default::default();
    let mut last_t_ms: [Option<u64>; FINGER_COUNT] = [None; FINGER_COUNT];
    let mut last: [Option<CentreMm>; FINGER_COUNT] = [None; FINGER_COUNT];
    let mut anchor: [Option<CentreMm>; FINGER_COUNT] = [None; FINGER_COUNT];
    for (k, o) in r.observations.iter().enumerate() {
        while let Some((_, set)) = events.next_if(|&(before, _)| before <= k) {
            anchor = if set { last } else { [None; FINGER_COUNT] };
        }
        let Some(frames) = out.get_mut(o.sensor) else {
            continue;
        };
        let s = o.sensor;
        let ignored = last_t_ms[s].is_some_and(|t| o.t_ms < t)
            || o.centre_mm
                .is_some_and(|c| !(c.x_mm.is_finite() && c.y_mm.is_finite()));
        let shifts = match o.centre_mm {
            Some(c) if !ignored => {
                let (d, a) = shifts_mm(c, last[s], anchor[s]);
                Some((d, anchor[s].map(|_| a)))
            }
            _ => None,
        };
        if !ignored {
            last[s] = o.centre_mm;
            last_t_ms[s] = Some(o.t_ms);
        }
        frames.push(FrameShifts {
            t_ms: o.t_ms,
            centre_mm: o.centre_mm,
            frame_shift_mm: shifts.map(|(d, _)| d),
            anchored_shift_mm: shifts.and_then(|(_, a)| a),
        });
    }
    out
}

/// For each trace row, the index of the latest frame at or before it.
fn latest_at(trace: &[WorldState], frames: &[FrameShifts]) -> Vec<Option<usize>> {
    let mut k = 0;
    trace
        .iter()
        .map(|w| {
            while frames.get(k).is_some_and(|f| f.t_ms <= w.t_ms) {
                k += 1;
            }
            k.checked_sub(1)
        })
        .collect()
}

/// The columns of `timeseries.csv`, in order (units in the module docs).
pub fn timeseries_header() -> Vec<String> {
    let per_sensor = |f: &dyn Fn(usize) -> Vec<String>| (0..FINGER_COUNT).flat_map(f).collect();
    let mut h = vec!["t_s".to_string()];
    let groups: [Vec<String>; 5] = [
        per_sensor(&|k| vec![format!("c{k}_x_mm"), format!("c{k}_y_mm")]),
        per_sensor(&|k| vec![format!("d{k}_mm")]),
        per_sensor(&|k| vec![format!("a{k}_mm")]),
        per_sensor(&|k| vec![format!("true_c{k}_x_mm"), format!("true_c{k}_y_mm")]),
        (0..CHAMBER_COUNT).map(|i| format!("valve{i}")).collect(),
    ];
    h.extend(groups.into_iter().flatten());
    h.extend(["tank_pos_kpa", "tank_neg_kpa", "external_n"].map(String::from));
    h.extend(per_sensor(&|k| vec![format!("grasp{k}_kpa")]));
    h.extend(per_sensor(&|k| vec![format!("normal{k}_n")]));
    h.extend(
        [
            "capacity_n",
            "load_n",
            "slide_mm",
            "lift_mm",
            "move_mm",
            "object",
        ]
        .map(String::from),
    );
    h
}

fn object_word(o: ObjectState) -> &'static str {
    match o {
        ObjectState::Absent => "absent",
        ObjectState::InGrasp => "in_grasp",
        ObjectState::Dropped => "dropped",
    }
}

/// A CSV cell: `v` with `decimals` places, empty if absent or not finite.
fn cell(v: Option<f64>, decimals: usize) -> String {
    match v {
        Some(v) if v.is_finite() => format!("{v:.decimals$}"),
        _ => String::new(),
    }
}

/// Writes `timeseries.csv` (columns in the module docs) with the `csv`
/// crate: one row per trace sample up to the end of the run.
pub fn write_timeseries(r: &SimReport, w: impl io::Write) -> io::Result<()> {
    let mut csv = csv::Writer::from_writer(w);
    csv.write_record(timeseries_header())?;
    let shifts = frame_shifts(r);
    let trace = match r.end_ms() {
        Some(end) => &r.trace[..r.trace.partition_point(|w| w.t_ms <= end)],
        None => &r.trace[..],
    };
    let rows: Vec<Vec<Option<usize>>> = shifts.iter().map(|s| latest_at(trace, s)).collect();
    let mut record: Vec<String> = Vec::new();
    for (i, w) in trace.iter().enumerate() {
        record.clear();
        record.push(cell(Some(secs(w.t_ms)), 3));
        let frame =
            |sensor: usize| -> Option<&FrameShifts> { shifts[sensor].get(rows[sensor][i]?) };
        for sensor in 0..FINGER_COUNT {
            let c = frame(sensor).and_then(|f| f.centre_mm);
            record.push(cell(c.map(|c| c.x_mm), 3));
            record.push(cell(c.map(|c| c.y_mm), 3));
        }
        for sensor in 0..FINGER_COUNT {
            record.push(cell(frame(sensor).and_then(|f| f.frame_shift_mm), 3));
        }
        for sensor in 0..FINGER_COUNT {
            record.push(cell(frame(sensor).and_then(|f| f.anchored_shift_mm), 3));
        }
        for c in &w.contacts {
            record.push(cell(c.map(|c| c.centre_mm[0]), 3));
            record.push(cell(c.map(|c| c.centre_mm[1]), 3));
        }
        record.extend(w.valves.iter().map(|v| v.as_sign().to_string()));
        record.push(cell(Some(w.tanks_kpa.0), 2));
        record.push(cell(Some(w.tanks_kpa.1), 2));
        record.push(cell(Some(w.external_n), 3));
        for finger in 0..FINGER_COUNT {
            let mine: Vec<f64> = r
                .grasp_chambers
                .iter()
                .filter(|&&c| c * FINGER_COUNT / CHAMBER_COUNT == finger)
                .filter_map(|&c| w.chambers_kpa.get(c).copied())
                .collect();
            let mean = (!mine.is_empty()).then(|| mine.iter().sum::<f64>() / mine.len() as f64);
            record.push(cell(mean, 2));
        }
        for c in &w.contacts {
            record.push(cell(c.map(|c| c.normal_n), 3));
        }
        record.push(cell(Some(w.capacity_n), 3));
        record.push(cell(Some(w.load_n), 3));
        record.push(cell(Some(w.slide_mm), 3));
        record.push(cell(Some(w.gripper_mm.0), 1));
        record.push(cell(Some(w.gripper_mm.1), 1));
        record.push(object_word(w.object).to_string());
        csv.write_record(&record)?;
    }
    csv.flush()
}

fn percentile_ms(sorted_ms: &[f64], p: f64) -> Option<f64> {
    if sorted_ms.is_empty() {
        return None;
    }
    let i = ((sorted_ms.len() - 1) as f64 * p).round() as usize;
    sorted_ms.get(i).copied()
}

/// `summary.json`: the run in numbers.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// The scenario's name.
    pub scenario: String,
    /// `ok`, or how the run failed and when (simulated time):
    /// `tripped: HostSilence at 11.3 s`, `MCU reset, noticed at 4.2 s`,
    /// `error: <message>` ([module docs](self#failed-runs)).
    pub status: String,
    /// The manipulation task, if the scenario has one and it started (its
    /// keys sit at the top level).
    #[serde(flatten)]
    pub task: Option<TaskSummary>,
    /// Whether the loop was closed on the tactile frames.
    pub tactile_feedback: bool,
    /// `failed` when `status` is not `ok`; else `held`, `dropped`,
    /// `released` or `not_grasped`, as `object_at_end`.
    pub outcome: &'static str,
    /// What became of the object, failed run or not: `held` (both
    /// fingertips still on it at the end), `dropped`, `released` or
    /// `not_grasped` (none in the scenario, or the fingers never closed on
    /// it).
    pub object_at_end: &'static str,
    /// Closing began -> seal decision, s.
    pub time_to_stable_s: Option<f64>,
    /// One entry per poke whose onset came before the end of the run.
    pub disturbances: Vec<DisturbanceSummary>,
    /// The scheduled pokes the run ended before (never applied); their
    /// number is the length.
    pub pokes_not_reached: Vec<PokeNotReached>,
    /// When the object fell, s.
    pub dropped_at_s: Option<f64>,
    /// Frame arrival -> command bytes written, for commands a frame decided.
    pub frame_to_command_ms: LatencySummary,
    /// Observations (frames through the pipeline, both sensors).
    pub frames: usize,
    /// The longest wall-clock stall of the host's link thread, ms.
    pub host_max_loop_gap_ms: Option<f64>,
    /// How the task loop ended: `Requested`, `FramesEnded` or `error: ...`.
    pub loop_result: String,
    /// The simulated MCU's safety state at the end: `Disarmed`, `Armed` or
    /// `Tripped`.
    pub mcu_state_at_end: &'static str,
    /// Simulated run time, s.
    pub sim_s: Option<f64>,
    /// Wall-clock run time, s; `null` on the virtual clock (`--speed max`),
    /// where everything else repeats exactly from run to run.
    pub wall_s: Option<f64>,
}

/// One poke's timeline in `summary.json`, s of simulated time.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DisturbanceSummary {
    /// `object`, `actuator` or `fingertip_back`.
    pub target: &'static str,
    /// Which finger (actuator and fingertip pokes).
    pub finger: usize,
    /// Peak force, N.
    pub peak_n: Option<f64>,
    /// Onset of the force.
    pub t_onset_s: Option<f64>,
    /// The host decided "disturbance".
    pub t_detected_s: Option<f64>,
    /// The reopen command's bytes were written.
    pub t_reopen_sent_s: Option<f64>,
    /// The MCU opened the grasping inlets.
    pub t_valves_open_s: Option<f64>,
    /// Onset to valves open.
    pub response_s: Option<f64>,
}

/// A scheduled poke the run did not reach, in `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PokeNotReached {
    /// `object`, `actuator` or `fingertip_back`.
    pub target: &'static str,
    /// Which finger (actuator and fingertip pokes).
    pub finger: usize,
    /// Its scheduled onset, s (not before the end of the run).
    pub t_onset_s: Option<f64>,
}

/// Latency statistics in `summary.json`, ms.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LatencySummary {
    /// Number of latencies.
    pub count: usize,
    /// Median, ms.
    pub median: Option<f64>,
    /// 99th percentile, ms.
    pub p99: Option<f64>,
}

/// A manipulation task's keys in `summary.json`. The simulated angles come
/// from invented plant coefficients ([`crate::task_report`]); the paper's
/// are ArUco measurements.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TaskSummary {
    /// The task's name (`pour`, `rotate`, `shake`, `twist`).
    pub task: &'static str,
    /// The gripper configuration.
    pub gripper: String,
    /// The achieved angle, deg.
    pub achieved_deg: Option<f64>,
    /// The paper's angle, deg.
    pub paper_deg: Option<f64>,
    /// The achieved stroke, mm.
    pub achieved_mm: Option<f64>,
    /// The paper's stroke, mm.
    pub paper_mm: Option<f64>,
    /// Per turn (rotate) or per twist (twist), deg.
    pub per_cycle_deg: Vec<Option<f64>>,
    /// Every stroke ran.
    pub task_completed: bool,
    /// A guard ended the task early.
    pub stopped_by_guard: bool,
    /// Guard trips.
    pub guard_trips: usize,
    /// Where the angles come from: always `simulated plant with invented
    /// coefficients`.
    pub task_angles_from: &'static str,
}

impl Summary {
    /// The summary of a run.
    pub fn of(r: &SimReport) -> Summary {
        let target = |t: PokeTarget| match t {
            PokeTarget::Object => "object",
            PokeTarget::Actuator => "actuator",
            PokeTarget::FingertipBack => "fingertip_back",
        };
        let s3 = |v: Option<f64>| v.and_then(|v| rounded(v, 3));
        let disturbances = r
            .pokes_reached()
            .map(|d| DisturbanceSummary {
                target: target(d.poke.target),
                finger: d.poke.finger,
                peak_n: rounded(d.poke.peak_n, 2),
                t_onset_s: rounded(d.t_onset_s, 3),
                t_detected_s: s3(d.t_detected_s),
                t_reopen_sent_s: s3(d.t_reopen_sent_s),
                t_valves_open_s: s3(d.t_valves_open_s),
                response_s: s3(d.response_s()),
            })
            .collect();
        let mut lat: Vec<f64> = r
            .frame_to_command
            .iter()
            .map(|d| d.as_secs_f64() * 1e3)
            .collect();
        let pokes_not_reached = r
            .pokes_not_reached()
            .map(|d| PokeNotReached {
                target: target(d.poke.target),
                finger: d.poke.finger,
                t_onset_s: rounded(d.t_onset_s, 3),
            })
            .collect();
        lat.sort_by(f64::total_cmp);
        let loop_result = match &r.loop_result {
            Ok(StopReason::Requested) => "Requested".to_string(),
            Ok(StopReason::FramesEnded) => "FramesEnded".to_string(),
            Err(e) => format!("error: {e}"),
        };
        let mcu_state_at_end = match r.mcu_at_end.state {
            ArmState::Disarmed => "Disarmed",
            ArmState::Armed => "Armed",
            ArmState::Tripped => "Tripped",
        };
        let task = r.task.as_ref().map(|t| TaskSummary {
            task: t.kind.name(),
            gripper: t.gripper.clone(),
            achieved_deg: s3(t.achieved_deg),
            paper_deg: rounded(t.kind.paper_deg(), 3),
            achieved_mm: s3(t.achieved_mm),
            paper_mm: s3(t.kind.paper_mm()),
            per_cycle_deg: t.per_cycle_deg.iter().map(|&d| rounded(d, 2)).collect(),
            task_completed: t.completed,
            stopped_by_guard: t.stopped_by_guard,
            guard_trips: t.guard_trips,
            task_angles_from: "simulated plant with invented coefficients",
        });
        Summary {
            scenario: r.scenario.clone(),
            status: r.status().to_string(),
            task,
            tactile_feedback: r.tactile_feedback,
            outcome: r.outcome_word(),
            object_at_end: r.outcome.name(),
            time_to_stable_s: s3(r.time_to_stable_s),
            disturbances,
            pokes_not_reached,
            dropped_at_s: s3(r.dropped_at_ms.map(secs)),
            frame_to_command_ms: LatencySummary {
                count: lat.len(),
                median: s3(percentile_ms(&lat, 0.5)),
                p99: s3(percentile_ms(&lat, 0.99)),
            },
            frames: r.observations.len(),
            host_max_loop_gap_ms: rounded(r.max_loop_gap.as_secs_f64() * 1e3, 1),
            loop_result,
            mcu_state_at_end,
            sim_s: rounded(r.sim_s, 3),
            // Virtual time: the wall time would make two runs' files differ.
            wall_s: if r.pace == Pace::Max {
                None
            } else {
                rounded(r.wall_s, 3)
            },
        }
    }
}

/// `summary.json` as text (pretty-printed, ending in a newline).
pub fn summary_json(r: &SimReport) -> serde_json::Result<String> {
    serde_json::to_string_pretty(&Summary::of(r)).map(|s| s + "\n")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mcu::McuSnapshot;
    use crate::plant::{ContactState, Plant, PlantParams, Poke, PokeShape, Trajectory};
    use crate::rig::{DisturbanceTiming, ObservationRecord, Outcome};
    use crate::status::LoopError;
    use crate::task_report::TaskReport;
    use dexitac_gripper::grasp::Decision;
    use dexitac_gripper::manipulation::TaskKind;
    use dexitac_protocol::{Fault, FaultFlags, TankTargets, ValveState};
    use std::time::Duration;

    const HEADER: &str = "t_s,c0_x_mm,c0_y_mm,c1_x_mm,c1_y_mm,d0_mm,d1_mm,a0_mm,a1_mm,\
        true_c0_x_mm,true_c0_y_mm,true_c1_x_mm,true_c1_y_mm,\
        valve0,valve1,valve2,valve3,valve4,valve5,valve6,valve7,\
        tank_pos_kpa,tank_neg_kpa,external_n,grasp0_kpa,grasp1_kpa,normal0_n,normal1_n,\
        capacity_n,load_n,slide_mm,lift_mm,move_mm,object";

    /// The plant at rest, then the fixture's values.
    fn world(t_ms: u64) -> WorldState {
        let plant = Plant::new(
            PlantParams::default(),
            None,
            &[],
            Trajectory::default(),
            Vec::new(),
        );
        let touching = t_ms >= 200;
        let contact = ContactState {
            centre_mm: [0.5, -0.25],
            shear_mm: [0.0; 2],
            normal_n: 2.0,
            width_mm: 4.0,
        };
        WorldState {
            t_ms,
            chambers_kpa: [10.0; CHAMBER_COUNT],
            // One row with a broken reading: an empty cell, not "NaN".
            tanks_kpa: (if t_ms == 450 { f64::NAN } else { 40.0 }, -45.0),
            contacts: [touching.then_some(contact), None],
            object: ObjectState::InGrasp,
            capacity_n: 3.0,
            load_n: 1.0,
            ..plant.state().clone()
        }
    }

    fn centre(x_mm: f64, y_mm: f64) -> Option<CentreMm> {
        Some(CentreMm { x_mm, y_mm })
    }

    /// Sensor 0: no contact until 200 ms, still at (1, 0) mm, sealed at
    /// 500 ms, a 0.5 mm jump at 700 ms, released at 900 ms. Sensor 1 never
    /// touches. Trace rows every 100 ms at 50, 150, ... ms.
    fn report() -> SimReport {
        let mut observations = Vec::new();
        for t_ms in (0..=1_000).step_by(100) {
            let c0 = match t_ms {
                0..200 => None,
                200..700 => centre(1.0, 0.0),
                _ => centre(1.3, 0.4),
            };
            for (sensor, centre_mm) in [(0, c0), (1, None)] {
                observations.push(ObservationRecord {
                    sensor,
                    t_ms,
                    centre_mm,
                    pipeline_ms: 5.0,
                });
            }
        }
        let decision = |t_ms, command, cause| {
            (
                t_ms + 3,
                Decision {
                    t_ms,
                    command,
                    cause,
                },
            )
        };
        let mut chambers = [ValveState::Hold; CHAMBER_COUNT];
        chambers[0] = ValveState::Inflate;
        chambers[4] = ValveState::Deflate;
        SimReport {
            pace: crate::rig::Pace::Times(1.0),
            scenario: "unit \"test\"".to_string(),
            tactile_feedback: true,
            outcome: Outcome::Released,
            time_to_stable_s: Some(0.3),
            disturbances: vec![DisturbanceTiming {
                poke: Poke {
                    target: PokeTarget::FingertipBack,
                    finger: 1,
                    at_s: 0.65,
                    duration_s: 0.2,
                    peak_n: 4.5,
                    shape: PokeShape::HalfSine,
                },
                t_onset_s: 0.65,
                t_detected_s: None,
                t_reopen_sent_s: None,
                t_valves_open_s: None,
            }],
            decisions: vec![
                decision(500, Command::Seal, Cause::BothStable),
                decision(
                    700,
                    Command::ReopenInflation,
                    Cause::Disturbance {
                        sensor: 0,
                        frame_shift_mm: 0.5,
                        anchored_shift_mm: 0.5,
                    },
                ),
                decision(900, Command::Release, Cause::ContactLost { sensor: 1 }),
            ],
            commands: vec![
                (
                    10,
                    HostMsg::SetTankTargets(TankTargets::new(40_000, -45_000).unwrap()),
                    "setup",
                ),
                (
                    11,
                    HostMsg::SetPumps {
                        positive: PumpMode::Regulate,
                        negative: PumpMode::Off,
                    },
                    "setup",
                ),
                (100, HostMsg::SetChambers { chambers }, "close fingers"),
                (503, HostMsg::SealAll, "stable: seal"),
                (903, HostMsg::VentAll, "release"),
            ],
            // After both 500 ms frames, after sensor 0's 700 ms frame, after
            // sensor 1's 900 ms frame.
            observations_before_decision: vec![12, 15, 20],
            frame_to_command: vec![Duration::from_micros(600), Duration::from_micros(1_400)],
            observations,
            trace: (0..10).map(|i| world(50 + 100 * i)).collect(),
            transitions: vec![(101, chambers)],
            dropped_at_ms: None,
            snapshots: Vec::new(),
            calibrations: Vec::new(),
            loop_result: Ok(StopReason::Requested),
            mcu_at_end: McuSnapshot {
                time_ms: 1_000,
                chambers: [ValveState::Hold; CHAMBER_COUNT],
                pumps: Default::default(),
                tanks_pa: (0, 0),
                chambers_pa: [0; CHAMBER_COUNT],
                state: ArmState::Tripped,
                faults: FaultFlags::default().with(Fault::HostSilence),
                frames_ok: 10,
                frame_errors: 0,
            },
            link_stats: Default::default(),
            max_loop_gap: Duration::from_millis(7),
            grasp_chambers: vec![0, 1, 4, 5],
            task: None,
            sim_s: 1.0,
            wall_s: f64::NAN,
        }
    }

    fn csv_of(r: &SimReport) -> String {
        let mut bytes = Vec::new();
        write_timeseries(r, &mut bytes).unwrap();
        String::from_utf8(bytes).unwrap()
    }

    fn keys(v: &serde_json::Value) -> Vec<&str> {
        let mut k: Vec<&str> = v.as_object().unwrap().keys().map(String::as_str).collect();
        k.sort_unstable();
        k
    }

    #[test]
    fn summary_json_parses_and_has_every_key() {
        let r = report();
        let v: serde_json::Value = serde_json::from_str(&summary_json(&r).unwrap()).unwrap();
        assert_eq!(
            keys(&v),
            [
                "disturbances",
                "dropped_at_s",
                "frame_to_command_ms",
                "frames",
                "host_max_loop_gap_ms",
                "loop_result",
                "mcu_state_at_end",
                "object_at_end",
                "outcome",
                "pokes_not_reached",
                "scenario",
                "sim_s",
                "status",
                "tactile_feedback",
                "time_to_stable_s",
                "wall_s",
            ]
        );
        assert_eq!(v["scenario"], "unit \"test\"");
        assert_eq!(v["status"], "ok");
        assert_eq!(v["outcome"], "released");
        assert_eq!(v["object_at_end"], "released");
        assert_eq!(v["pokes_not_reached"], serde_json::json!([]));
        assert_eq!(v["time_to_stable_s"], 0.3);
        assert_eq!(v["frames"], 22);
        assert_eq!(v["host_max_loop_gap_ms"], 7.0);
        assert_eq!(v["loop_result"], "Requested");
        assert_eq!(v["mcu_state_at_end"], "Tripped");
        // Not finite: null.
        assert!(v["wall_s"].is_null() && v["dropped_at_s"].is_null());
        let lat = &v["frame_to_command_ms"];
        assert_eq!(keys(lat), ["count", "median", "p99"]);
        assert_eq!(
            (lat["count"].as_u64(), lat["p99"].as_f64()),
            (Some(2), Some(1.4))
        );
        let d = &v["disturbances"][0];
        assert_eq!(
            keys(d),
            [
                "finger",
                "peak_n",
                "response_s",
                "t_detected_s",
                "t_onset_s",
                "t_reopen_sent_s",
                "t_valves_open_s",
                "target",
            ]
        );
        assert_eq!(d["target"], "fingertip_back");
        assert_eq!(d["peak_n"], 4.5);
        assert!(d["response_s"].is_null());
    }

    #[test]
    fn summary_json_has_the_task_keys_when_there_is_a_task() {
        let mut r = report();
        r.task = Some(TaskReport {
            kind: TaskKind::Rotate,
            gripper: "ClosureGrip".to_string(),
            events: Vec::new(),
            completed: true,
            stopped_by_guard: false,
            guard_trips: 0,
            per_cycle_deg: vec![12.345, f64::NAN],
            achieved_deg: Some(12.3456),
            achieved_mm: None,
        });
        let v: serde_json::Value = serde_json::from_str(&summary_json(&r).unwrap()).unwrap();
        for key in [
            "task",
            "gripper",
            "achieved_deg",
            "paper_deg",
            "achieved_mm",
            "paper_mm",
            "per_cycle_deg",
            "task_completed",
            "stopped_by_guard",
            "guard_trips",
            "task_angles_from",
        ] {
            assert!(v.get(key).is_some(), "{key} missing: {v}");
        }
        assert_eq!(v["task"], "rotate");
        assert_eq!(v["achieved_deg"], 12.346);
        assert_eq!(v["per_cycle_deg"], serde_json::json!([12.35, null]));
        assert!(v["achieved_mm"].is_null());
    }

    #[test]
    fn timeseries_has_the_documented_header_and_parses() {
        assert_eq!(timeseries_header().join(","), HEADER);
        // Every column is in the module docs' table.
        let docs: String = include_str!("output.rs")
            .lines()
            .filter(|l| l.starts_with("//! | `"))
            .map(|l| l.split('|').nth(1).unwrap_or_default())
            .collect();
        for column in timeseries_header() {
            let documented = match column.strip_prefix("valve") {
                // One table row for the range `valve0` ... `valve7`.
                Some(i) => i.parse::<usize>().is_ok_and(|i| i < CHAMBER_COUNT),
                None => docs.contains(&format!("`{column}`")),
            };
            assert!(documented, "{column} is not documented");
        }
        assert!(docs.contains(&format!("`valve{}`", CHAMBER_COUNT - 1)));

        let r = report();
        let text = csv_of(&r);
        let mut reader = csv::Reader::from_reader(text.as_bytes());
        let header: Vec<String> = reader.headers().unwrap().iter().map(String::from).collect();
        assert_eq!(header, timeseries_header());
        let rows: Vec<csv::StringRecord> = reader.records().map(Result::unwrap).collect();
        assert_eq!(rows.len(), r.trace.len());
        let col = |name: &str| header.iter().position(|h| h == name).unwrap();
        let num = |row: &csv::StringRecord, name: &str| -> Option<f64> {
            let v = &row[col(name)];
            (!v.is_empty()).then(|| v.parse().unwrap())
        };
        // 750 ms: the latest frame (700 ms) jumped 0.5 mm from the anchor.
        let row = &rows[7];
        assert_eq!(&row[col("t_s")], "0.750");
        assert_eq!(num(row, "c0_x_mm"), Some(1.3));
        assert_eq!(num(row, "d0_mm"), Some(0.5));
        assert_eq!(num(row, "a0_mm"), Some(0.5));
        assert_eq!(&row[col("valve0")], "0");
        assert_eq!(num(row, "grasp0_kpa"), Some(10.0));
        assert_eq!(&row[col("object")], "in_grasp");
    }

    #[test]
    fn shifts_follow_algorithm_1_and_the_anchor_is_held_from_seal_to_release() {
        let [s0, s1] = frame_shifts(&report());
        let at = |t_ms: u64| *s0.iter().find(|f| f.t_ms == t_ms).unwrap();
        // No contact: nothing; first contact frame: D = 0, no anchor yet.
        assert_eq!(at(100).frame_shift_mm, None);
        assert_eq!(at(200).frame_shift_mm, Some(0.0));
        assert_eq!(at(200).anchored_shift_mm, None);
        // The sealing frame is measured against the old (no) anchor.
        assert_eq!(at(500).anchored_shift_mm, None);
        assert_eq!(at(600).anchored_shift_mm, Some(0.0));
        // The jump: D and A as the grasp's cause reports them.
        let jump = at(700);
        assert!((jump.frame_shift_mm.unwrap() - 0.5).abs() < 1e-12);
        assert!((jump.anchored_shift_mm.unwrap() - 0.5).abs() < 1e-12);
        assert_eq!(at(800).frame_shift_mm, Some(0.0));
        assert!((at(900).anchored_shift_mm.unwrap() - 0.5).abs() < 1e-12);
        // Released at 900 ms: no anchor after it.
        assert_eq!(at(1_000).anchored_shift_mm, None);
        assert!(s1.iter().all(|f| f.frame_shift_mm.is_none()));
    }

    #[test]
    fn missing_and_non_finite_values_are_empty_cells() {
        let mut r = report();
        // A non-finite centre (ignored by the grasp) and no contact anywhere.
        r.observations[4].centre_mm = centre(f64::NAN, 1.0);
        r.observations.retain(|o| o.t_ms < 300);
        for w in &mut r.trace {
            w.contacts = [None, None];
        }
        r.grasp_chambers.clear();
        let text = csv_of(&r);
        assert!(!text.to_ascii_lowercase().contains("nan"), "{text}");
        assert!(!text.contains("inf"), "{text}");
        let mut reader = csv::Reader::from_reader(text.as_bytes());
        let header = reader.headers().unwrap().clone();
        let col = |name: &str| header.iter().position(|h| h == name).unwrap();
        let rows: Vec<csv::StringRecord> = reader.records().map(Result::unwrap).collect();
        // 450 ms: NaN tank reading, the NaN centre (200 ms frame) held, no contact.
        let row = &rows[4];
        assert_eq!(&row[col("t_s")], "0.450");
        for name in [
            "tank_pos_kpa",
            "c0_x_mm",
            "d0_mm",
            "a0_mm",
            "true_c0_x_mm",
            "normal0_n",
            "grasp0_kpa",
            "c1_x_mm",
            "d1_mm",
        ] {
            assert_eq!(&row[col(name)], "", "{name}");
        }
        assert_eq!(&row[col("tank_neg_kpa")], "-45.00");
    }

    #[test]
    fn event_log_is_for_people() {
        let mut r = report();
        let mut late = r.disturbances[0];
        late.t_onset_s = 1.5;
        r.disturbances.push(late);
        let log = event_log(&r);
        for debug in ["{", "}", "Some(", "None", "::", "Ok(", "Err(", "["] {
            assert!(!log.contains(debug), "{debug:?} in:\n{log}");
        }
        for line in [
            "    0.010 s  command sent: tank targets +40.0 kPa and -45.0 kPa (setup)",
            "    0.011 s  command sent: pumps: positive regulating, negative off (setup)",
            "    0.100 s  command sent: set valves +...-... (close fingers)",
            "    0.101 s  valve outputs: +...-...",
            "    0.503 s  decision: seal (both sensors stable; frame captured at 0.500 s)",
            "    0.650 s  poke onset: back of the fingertip (finger 1), 4.5 N peak over 0.20 s",
            "    0.703 s  decision: reopen inflation (disturbance on sensor 0: frame shift 0.50 mm, anchored 0.50 mm; frame captured at 0.700 s)",
            "    0.903 s  command sent: vent all chambers, pumps off (release)",
            "    1.000 s  not reached, the run ended first: 1 scheduled poke(s), onsets 1.5 s",
        ] {
            assert!(log.lines().any(|l| l == line), "{line:?} not in:\n{log}");
        }
        // Time-ordered, the end last; the poke after it is not an onset.
        assert!(log.trim_end().ends_with(
            "    1.000 s  end: ok, outcome released, task loop stopped on request, \
             MCU tripped (faults: host silent past the deadline)"
        ));
        assert_eq!(log.matches("poke onset").count(), 1, "{log}");
    }

    /// The run: tripped on host silence at 11.23 s (the MCU's time),
    /// ended at 11.3 s, the object still
    /// in the grasp, pokes scheduled at 5 (reached), 12, 18 and 24 s, a
    /// trace row after the end.
    fn tripped_report() -> SimReport {
        let mut r = report();
        let poke = r.disturbances[0];
        r.disturbances = [5.0, 12.0, 18.0, 24.0]
            .into_iter()
            .map(|at_s| DisturbanceTiming {
                poke: Poke { at_s, ..poke.poke },
                t_onset_s: at_s,
                ..poke
            })
            .collect();
        r.outcome = Outcome::Held;
        r.loop_result = Err(LoopError::McuFault(dexitac_protocol::FaultEvent {
            time_ms: 11_230,
            fault: Fault::HostSilence,
            positive_tank_pa: 40_000,
            negative_tank_pa: -45_000,
        }));
        r.trace = (0..=114).map(|i| world(100 * i)).collect();
        r.sim_s = 11.3;
        r
    }

    /// The time of an events.log line, s.
    fn line_time(line: &str) -> f64 {
        line.split(" s  ").next().unwrap().trim().parse().unwrap()
    }

    #[test]
    fn a_tripped_run_says_so_in_its_summary() {
        let r = tripped_report();
        assert_eq!(r.status().to_string(), "tripped: HostSilence at 11.23 s");
        let v: serde_json::Value = serde_json::from_str(&summary_json(&r).unwrap()).unwrap();
        assert_eq!(v["status"], "tripped: HostSilence at 11.23 s");
        // Never `held` for a failed run; the object's fate is kept apart.
        assert_eq!(v["outcome"], "failed");
        assert_eq!(v["object_at_end"], "held");
        assert!(v["loop_result"]
            .as_str()
            .unwrap()
            .starts_with("error: the MCU tripped: host silent past the deadline at 11230 ms"));
        // Only the poke before the end happened; the others are counted apart.
        let onsets = |key: &str| -> Vec<f64> {
            v[key]
                .as_array()
                .unwrap()
                .iter()
                .map(|d| d["t_onset_s"].as_f64().unwrap())
                .collect()
        };
        assert_eq!(onsets("disturbances"), [5.0]);
        assert_eq!(onsets("pokes_not_reached"), [12.0, 18.0, 24.0]);
        assert_eq!(v["pokes_not_reached"][0]["target"], "fingertip_back");
    }

    #[test]
    fn a_tripped_run_lists_nothing_after_its_end() {
        let r = tripped_report();
        let log = event_log(&r);
        let lines: Vec<&str> = log.lines().filter(|l| !l.starts_with('#')).collect();
        for line in &lines {
            assert!(
                line_time(line) <= 11.3,
                "after the end: {line:?} in:\n{log}"
            );
        }
        let onsets: Vec<&&str> = lines.iter().filter(|l| l.contains("poke onset")).collect();
        assert_eq!(onsets.len(), 1, "{log}");
        assert!(onsets[0].starts_with("    5.000 s  "), "{log}");
        assert!(
            lines.contains(
                &"   11.300 s  not reached, the run ended first: 3 scheduled poke(s), \
                  onsets 12.0 s, 18.0 s, 24.0 s"
            ),
            "{log}"
        );
        let end = lines.last().unwrap();
        assert!(
            end.starts_with(
                "   11.300 s  end: FAILED: tripped: HostSilence at 11.23 s; object held at the end; \
                 task loop failed: the MCU tripped: host silent past the deadline at 11230 ms"
            ),
            "{end}"
        );
        assert!(!log.contains("outcome held"), "{log}");
        // The time series ends with the run.
        let text = csv_of(&r);
        let last = text.lines().last().unwrap();
        assert!(last.starts_with("11.300,"), "{last}");
    }

    #[test]
    fn failures_without_a_fault_event_are_stated_too() {
        let mut r = tripped_report();
        // A refused command, the MCU tripped at the end: the trip, and why.
        r.loop_result = Err(LoopError::Other("link: refused: tripped".into()));
        assert_eq!(
            r.status().to_string(),
            "tripped: HostSilence at 11.3 s (link: refused: tripped)"
        );
        r.mcu_at_end.state = ArmState::Disarmed;
        r.mcu_at_end.faults = FaultFlags::default();
        assert_eq!(r.status().to_string(), "error: link: refused: tripped");
        r.loop_result = Err(LoopError::McuReset {
            cause: None,
            t_ms: 11_250,
        });
        assert_eq!(r.status().to_string(), "MCU reset, noticed at 11.25 s");
        for r in [&r, &tripped_report()] {
            let v: serde_json::Value = serde_json::from_str(&summary_json(r).unwrap()).unwrap();
            assert_eq!(v["outcome"], "failed");
            assert_eq!(v["status"], r.status().to_string());
            assert!(event_log(r).contains(&format!("end: FAILED: {}; ", r.status())));
        }
        // A run that ended normally is ok, whatever the MCU says.
        r.loop_result = Ok(StopReason::FramesEnded);
        assert_eq!(r.status().to_string(), "ok");
        assert_eq!(r.outcome_word(), "held");
    }

    #[test]
    fn write_all_writes_the_three_files() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("new");
        write_all(&report(), &out).unwrap();
        for name in ["events.log", "timeseries.csv", "summary.json"] {
            assert!(out.join(name).metadata().unwrap().len() > 0, "{name}");
        }
        // A file in the way of the directory: an error naming the path.
        let blocked = dir.path().join("file");
        std::fs::write(&blocked, "x").unwrap();
        assert!(write_all(&report(), &blocked.join("sub")).is_err());
    }
}
