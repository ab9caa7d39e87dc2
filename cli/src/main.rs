//! `dexitac`: the DexiTac command-line tool. Parses the command line and
//! dispatches to one module per command ([`commands`]); the exit codes are
//! in one table ([`exit`]), logs go through `tracing` ([`logging`]).

mod commands;
mod exit;
mod logging;
mod shared;

use std::process::ExitCode;

use clap::{CommandFactory, Parser, Subcommand};

use commands::{
    analyze, bench_pipeline, calibrate, cameras, completions, faults, fit_actuator, record, replay,
    run, sensor, sim, synth_frames, view, workspace,
};
use exit::Outcome;

/// DexiTac: soft dexterous tactile gripping — host tools for the pneumatic
/// two-finger gripper with camera-based tactile fingertips.
#[derive(Debug, Parser)]
#[command(name = "dexitac", version, about, long_about = None, after_help = exit::EXIT_CODES_HELP)]
struct Cli {
    /// More log output (-v debug, -vv trace); RUST_LOG overrides.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    /// Less log output (-q warnings and errors only, -qq errors only).
    #[arg(short, long, global = true, action = clap::ArgAction::Count, conflicts_with = "verbose")]
    quiet: u8,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The whole system on the simulated rig (firmware core behind a pty,
    /// pneumatics, object, rendered fingertip cameras); results to --out.
    Sim(sim::SimArgs),
    /// The task loop on the real gripper: serial port, rig config, frame sources.
    Run(run::RunArgs),
    /// What the board has latched (faults, the last stop before its boot),
    /// and a person's acknowledgement: `--clear FAULT,...` once the cause is
    /// removed. Exit 1 while faults stay latched.
    Faults(faults::FaultsArgs),
    /// The tank pressure sensors' calibration on the board (zero offset and
    /// gain per sensor): `--show` it, set it (`--offset-kpa POS,NEG`,
    /// `--gain POS,NEG`, or `--zero` from the readings with the tanks open
    /// to atmosphere), stored in the board's flash and read back. Only
    /// while the board is disarmed; offsets within ±10 kPa, gains within
    /// 0.9..1.1. Exit 1 when it was applied but not stored, or `--show`
    /// finds the stored record ignored (bad CRC, unknown version).
    Calibrate(calibrate::CalibrateArgs),
    /// Tactile pipeline on image files: contact centre per frame to a CSV.
    ///
    /// Writes `frame,cx,cy,n_markers,t_detect_ms,t_kde_ms,t_segment_ms,t_total_ms`
    /// then `area_mm2,source,skipped,shift_mm,shift_from_anchor_mm`; cx, cy in
    /// input-image pixels (NaN when no contact); shifts are the contact
    /// centre's move from the previous frame and from the first contact, mm.
    /// Frames that cannot be read are reported on stderr and left out; the
    /// exit status is then 1.
    Analyze(analyze::AnalyzeArgs),
    /// Accuracy against run time on synthetic scenes, per setting and scene
    /// category (Markdown to stdout, plot and tables to --out-dir).
    BenchPipeline(bench_pipeline::BenchArgs),
    /// Seeded synthetic tactile frames with truth (rest.png, frames/,
    /// truth.csv) to try `analyze` without a sensor.
    SynthFrames(synth_frames::SynthArgs),
    /// Workspace of one finger: points CSV, X-Y / X-Z / 3-D views (PNG),
    /// extents and volume (JSON) in --out.
    Workspace(workspace::WorkspaceArgs),
    /// Fit the linear pressure -> angle actuator model to measured
    /// `pressure_kpa,angle_deg` rows by least squares.
    FitActuator(fit_actuator::FitArgs),
    /// Live view of the tactile sensors without a board: frames ->
    /// pipeline -> dashboard (window, or PNG snapshots with --headless).
    View(view::ViewArgs),
    /// Record the fingertips without a board: frames -> pipeline -> MCAP
    /// (frames, markers, contact centres; see rig/RECORDING.md).
    Record(record::RecordArgs),
    /// Run the pipeline again over a recording's frames and compare the
    /// contact centres with the recorded ones (exit 1 when they differ).
    Replay(replay::ReplayArgs),
    /// List the tactile cameras (V4L2 capture devices) with their formats
    /// and sizes. Exit 1 when there is none.
    Cameras,
    /// Sensor setup: tune the marker detector to the pin count, check a
    /// skin's health.
    #[command(subcommand)]
    Sensor(sensor::SensorCommand),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell)
    /// to stdout, e.g. `dexitac completions bash > ~/.local/share/bash-completion/completions/dexitac`.
    Completions(completions::CompletionsArgs),
}

impl Command {
    /// The command's name, as typed (for messages).
    fn name(&self) -> &'static str {
        match self {
            Command::Sim(_) => "sim",
            Command::Run(_) => "run",
            Command::Faults(_) => "faults",
            Command::Calibrate(_) => "calibrate",
            Command::Analyze(_) => "analyze",
            Command::BenchPipeline(_) => "bench-pipeline",
            Command::SynthFrames(_) => "synth-frames",
            Command::Workspace(_) => "workspace",
            Command::FitActuator(_) => "fit-actuator",
            Command::View(_) => "view",
            Command::Record(_) => "record",
            Command::Replay(_) => "replay",
            Command::Cameras => "cameras",
            Command::Sensor(sensor::SensorCommand::Tune(_)) => "sensor tune",
            Command::Sensor(sensor::SensorCommand::Health(_)) => "sensor health",
            Command::Completions(_) => "completions",
        }
    }

    fn run(&self) -> anyhow::Result<Outcome> {
        match self {
            Command::Sim(args) => args.run(),
            Command::Run(args) => args.run(),
            Command::Faults(args) => args.run(),
            Command::Calibrate(args) => args.run(),
            Command::Analyze(args) => args.run(),
            Command::BenchPipeline(args) => args.run(),
            Command::SynthFrames(args) => args.run(),
            Command::Workspace(args) => args.run(),
            Command::FitActuator(args) => args.run(),
            Command::View(args) => args.run(),
            Command::Record(args) => args.run(),
            Command::Replay(args) => args.run(),
            Command::Cameras => cameras::run(),
            Command::Sensor(command) => command.run(),
            Command::Completions(args) => args.run(&mut Cli::command()),
        }
    }

    /// The exit code of an error.
    fn error_code(&self) -> u8 {
        match self {
            Command::Sensor(sensor::SensorCommand::Health(_)) => exit::HEALTH_ERROR,
            _ => exit::ERROR,
        }
    }
}

fn main() -> ExitCode {
    // Output piped into a reader that stops early (`dexitac sensor health |
    // head -1`) ends the process as it ends `cat`, by SIGPIPE, instead of
    // a panic in `println!` (Rust ignores SIGPIPE before `main`). The
    // firmware keeps the tanks safe whatever becomes of the host.
    #[cfg(unix)]
    // SAFETY: restores the default action of one signal before any thread
    // is started; no handler runs Rust code.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    let cli = Cli::parse();
    logging::init(cli.verbose, cli.quiet);
    let Some(command) = cli.command else {
        println!(
            "dexitac {}: wire protocol v{}. See `dexitac --help`.",
            env!("CARGO_PKG_VERSION"),
            dexitac_protocol::PROTOCOL_VERSION
        );
        return ExitCode::SUCCESS;
    };
    match command.run() {
        Ok(outcome) => outcome.code(),
        Err(e) => {
            // The error and those of its causes that its message does not
            // already quote (thiserror errors often show their source).
            let mut message = e.to_string();
            for cause in e.chain().skip(1) {
                let cause = cause.to_string();
                if !message.contains(&cause) {
                    message = format!("{message}: {cause}");
                }
            }
            eprintln!("dexitac {}: error: {message}", command.name());
            ExitCode::from(command.error_code())
        }
    }
}
