//! `dexitac sim`: the whole system on the simulated rig (see
//! `dexitac_sim::rig`), results to a directory (see `dexitac_sim::output`).
//!
//! The last line on stdout is the run in one line: `scenario NAME: ok,
//! outcome held, ...`, or for a run whose task loop failed (the MCU tripped
//! or reset, the link or a sensor failed) `FAILED: <status>; scenario NAME
//! ended at 11.4 s, object held at the end, 0 of 3 poke(s) before the end,
//! wrote DIR`, and
//! the exit code is 1 ([`crate::exit`]). `<status>` is `summary.json`'s
//! (`tripped: HostSilence at 11.3 s`; `dexitac_sim::status`).

use anyhow::anyhow;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use anyhow::Context;
use dexitac_sim::output;
use tracing::{error, info};

use crate::exit::Outcome;
use crate::shared::live::{run_sim, LiveArgs};
use crate::shared::out_dir::{self, Owned};
use crate::shared::record::{finish_recorder, start_recorder, RecordFlags};
use crate::shared::stop_on_ctrl_c;
use dexitac_sim::plant::FINGER_COUNT;
use dexitac_sim::rig::{self, Pace, SimOptions, SimReport};
use dexitac_sim::scenario::{Scenario, DEFAULT_SCENARIO, PRESETS};
use dexitac_tactile::params::Params;

/// Arguments of `dexitac sim`.
#[derive(Debug, clap::Args)]
pub struct SimArgs {
    /// A preset (disturbance, grasp-hold, slip, no-object) or a scenario TOML file.
    #[arg(long, default_value = DEFAULT_SCENARIO, value_name = "NAME|FILE")]
    scenario: String,
    /// Run without tactile feedback (the paper's ablation: open-loop seal).
    #[arg(long)]
    no_tactile: bool,
    /// Directory for events.log, timeseries.csv, plot.png, heatmaps, summary.json.
    #[arg(long, default_value = "sim-out", value_name = "DIR")]
    out: PathBuf,
    /// `max`: virtual time, as fast as the CPU allows; the same scenario
    /// and seed then give the same files, byte for byte. Or a factor of
    /// real time in 0.1..=20 (the live view, soak tests).
    #[arg(long, default_value = "1", value_parser = parse_speed, value_name = "max|FACTOR")]
    speed: Pace,
    /// Seed of the simulated cameras' noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// In real time: the simulated board's host-silence deadline,
    /// wall-clock ms (the firmware's is 500). Raise it only to run on a
    /// machine so busy that the host process stalls for longer. With
    /// `--speed max` the firmware's own deadline applies.
    #[arg(long, default_value_t = dexitac_firmware::control::DEFAULT_HOST_SILENCE_MS,
          value_parser = clap::value_parser!(u32).range(50..=60_000))]
    host_silence_ms: u32,
    /// List the preset scenarios and exit.
    #[arg(long)]
    list: bool,
    #[command(flatten)]
    record: RecordFlags,
    /// Live view: window and PNG snapshots.
    #[command(flatten)]
    live: LiveArgs,
}

fn parse_speed(s: &str) -> anyhow::Result<Pace> {
    Pace::parse(s).map_err(|e| anyhow!(e))
}

/// The files `dexitac sim` writes into --out.
pub const OWNED: [Owned; 7] = [
    Owned::File("events.log"),
    Owned::File("timeseries.csv"),
    Owned::File("summary.json"),
    Owned::File("plot.png"),
    Owned::File("plot.svg"),
    Owned::Pattern {
        prefix: "heatmap_",
        suffix: ".png",
    },
    Owned::Pattern {
        prefix: "heatmap_",
        suffix: ".svg",
    },
];

impl SimArgs {
    /// Runs `dexitac sim`: [`Outcome::Negative`] when the task loop failed
    /// (a trip, an MCU reset, the link, a sensor); the results are written
    /// either way, and the last stdout line starts with `FAILED:`.
    pub fn run(&self) -> anyhow::Result<Outcome> {
        run(self)
    }
}

fn run(args: &SimArgs) -> anyhow::Result<Outcome> {
    if args.list {
        for (name, text) in PRESETS {
            let description = Scenario::from_toml_str(text, name)
                .map(|s| s.description)
                .unwrap_or_default();
            println!("{name:<12} {description}");
        }
        return Ok(Outcome::Success);
    }
    if args.speed == Pace::Max && args.live.view {
        return Err(anyhow!(
            "the live view window runs in real time: give --speed a factor (0.1..=20), not max"
        ));
    }
    let scenario = Scenario::load(&args.scenario)?;
    out_dir::prepare("sim", &args.out, &OWNED)?;
    let stop = Arc::new(AtomicBool::new(false));
    stop_on_ctrl_c(&stop);
    info!(
        "dexitac sim: scenario {} ({:.0} s simulated, speed {}), tactile feedback {}",
        scenario.name,
        scenario.duration_s,
        args.speed,
        if args.no_tactile { "off" } else { "on" }
    );
    let rests: Vec<_> = (0..FINGER_COUNT)
        .map(|finger| rig::rest_frames(finger, &Params::default(), args.seed))
        .collect();
    let recorder = start_recorder(
        &args.record,
        "sim",
        &format!(
            "dexitac sim --scenario {} --seed {}",
            scenario.name, args.seed
        ),
        &rests,
        None,
        &Params::default(),
    )?;
    let options = SimOptions {
        event_tap: recorder.as_ref().map(|r| r.sender()),
        share_frames: args.record.record_frames,
        tactile_feedback: !args.no_tactile,
        speed: args.speed,
        status: true,
        seed: args.seed,
        stop,
        stall_tolerance_ms: args.host_silence_ms,
        ..SimOptions::default()
    };
    // run_sim drops the options: they hold the last sender of the event tap.
    let report = run_sim(&scenario, options, &args.live);
    let recorded = finish_recorder(recorder, &args.record);
    let (report, view) = report?;
    recorded?;
    output::write_all(&report, &args.out)
        .and_then(|()| {
            dexitac_view::figures::sim_run::write_all(&report, &args.out)
                .map_err(std::io::Error::other)
        })
        .with_context(|| format!("writing {}", args.out.display()))?;
    if let Some(t) = &report.task {
        let fmt =
            |v: Option<f64>, unit: &str| v.map_or("-".to_string(), |v| format!("{v:.1} {unit}"));
        println!(
            "  task {} ({}): achieved {} / {} (paper {} / {}), {}{} guard trip(s); simulated with invented plant coefficients",
            t.kind.name(),
            t.gripper,
            fmt(t.achieved_deg, "deg"),
            fmt(t.achieved_mm, "mm"),
            fmt(Some(t.kind.paper_deg()), "deg"),
            fmt(t.kind.paper_mm(), "mm"),
            if t.stopped_by_guard {
                "stopped by its guard, "
            } else if t.completed {
                "completed, "
            } else {
                "not finished, "
            },
            t.guard_trips
        );
    }
    for d in &report.disturbances {
        if !report.poke_reached(d) {
            println!(
                "  poke {:?} at {:.2} s: not reached, the run ended at {:.2} s",
                d.poke.target, d.t_onset_s, report.sim_s
            );
            continue;
        }
        println!(
            "  poke {:?} at {:.2} s: detected {}, valves open {}",
            d.poke.target,
            d.t_onset_s,
            d.t_detected_s.map_or("never".to_string(), |t| format!(
                "+{:.3} s",
                t - d.t_onset_s
            )),
            d.response_s()
                .map_or("never".to_string(), |t| format!("+{t:.3} s")),
        );
    }
    view.wait();
    info!(
        "dexitac sim: {:.1} s simulated in {:.2} s of wall-clock time (speed {})",
        report.sim_s, report.wall_s, args.speed
    );
    println!("{}", final_line(&report, &args.out));
    match &report.loop_result {
        Ok(_) => Ok(Outcome::Success),
        Err(e) => {
            error!("dexitac sim: the task loop failed: {e}");
            let stalled_ms = report.max_loop_gap.as_secs_f64() * 1e3;
            if args.speed != Pace::Max && stalled_ms >= f64::from(args.host_silence_ms) {
                error!(
                    "dexitac sim: the host's control loop stalled for {stalled_ms:.0} ms, longer than \
                     the board's {} ms host-silence deadline, so the firmware tripped as it would on \
                     the real rig. The machine was too busy: re-run when it is idle, or give the \
                     simulated board more time with --host-silence-ms.",
                    args.host_silence_ms
                );
            }
            Ok(Outcome::Negative)
        }
    }
}

/// The last stdout line (module docs): the status first when the run failed.
fn final_line(report: &SimReport, out: &std::path::Path) -> String {
    let scheduled = report.disturbances.len();
    let reached = report.pokes_reached().count();
    let pokes = if reached == scheduled {
        format!("{scheduled} poke(s)")
    } else {
        format!("{reached} of {scheduled} poke(s) before the end")
    };
    let status = report.status();
    if status.is_ok() {
        format!(
            "scenario {}: ok, outcome {}, time to stable {}, {pokes}, wrote {}",
            report.scenario,
            report.outcome.name(),
            report
                .time_to_stable_s
                .map_or("-".to_string(), |t| format!("{t:.2} s")),
            out.display()
        )
    } else {
        format!(
            "FAILED: {status}; scenario {} ended at {} s, object {} at the end, {pokes}, wrote {}",
            report.scenario,
            dexitac_sim::status::seconds(report.sim_s),
            report.outcome.name().replace('_', " "),
            out.display()
        )
    }
}
