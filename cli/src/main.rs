//! `dexitac`: the DexiTac command-line tool.

mod commands;

use commands::{
    analyze, bench_pipeline as bench_cmd, kinematics as cli_kinematics, record as cli_record,
    run as cli_run, sensor as cli_sensor, sim as cli_sim, synth_frames as synth_cmd,
    view as cli_view,
};

use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// DexiTac: soft dexterous tactile gripping — host tools for the pneumatic
/// two-finger gripper with camera-based tactile fingertips.
#[derive(Debug, Parser)]
#[command(name = "dexitac", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Tactile pipeline on image files: contact centre per frame to a CSV.
    ///
    /// Writes `frame,cx,cy,n_markers,t_detect_ms,t_kde_ms,t_segment_ms,t_total_ms`
    /// then `area_mm2,source,skipped,shift_mm,shift_from_anchor_mm`; cx, cy in
    /// input-image pixels (NaN when no contact); shifts are the contact
    /// centre's move from the previous frame and from the first contact, mm.
    /// Frames that cannot be read are reported on stderr and left out; the
    /// exit status is then 1.
    Analyze(AnalyzeArgs),
    /// Accuracy against run time on synthetic scenes, per setting and scene
    /// category (Markdown to stdout, plot and tables to --out-dir).
    BenchPipeline(BenchArgs),
    /// The whole system on the simulated rig (firmware core behind a pty,
    /// pneumatics, object, rendered fingertip cameras); results to --out.
    Sim(cli_sim::SimArgs),
    /// The task loop on the real gripper: serial port, gripper config, frame sources.
    Run(cli_run::RunArgs),
    /// Seeded synthetic tactile frames with truth (rest.png, frames/,
    /// truth.csv) to try `analyze` without a sensor.
    SynthFrames(synth_cmd::SynthArgs),
    /// Workspace of one finger: points CSV, X-Y / X-Z / 3-D views (PNG),
    /// extents and volume (JSON) in --out.
    Workspace(cli_kinematics::WorkspaceArgs),
    /// Fit the linear pressure -> angle actuator model to measured
    /// `pressure_kpa,angle_deg` rows by least squares.
    FitActuator(cli_kinematics::FitArgs),
    /// Live view of the tactile sensors without a board: frames ->
    /// pipeline -> dashboard (window, or PNG snapshots with --headless).
    View(cli_view::ViewArgs),
    /// Record the fingertips without a board: frames -> pipeline -> MCAP
    /// (frames, markers, contact centres; see host/RECORDING.md).
    Record(cli_record::RecordArgs),
    /// Run the pipeline again over a recording's frames and compare the
    /// contact centres with the recorded ones (exit 1 when they differ).
    Replay(cli_record::ReplayArgs),
    /// List the tactile cameras (V4L2 capture devices) with their formats
    /// and sizes. Exit 1 when there is none.
    Cameras,
    /// Sensor setup: tune the marker detector to the pin count, check a
    /// skin's health.
    #[command(subcommand)]
    Sensor(cli_sensor::SensorCommand),
}

/// Arguments of `dexitac analyze`.
#[derive(Debug, clap::Args)]
pub struct AnalyzeArgs {
    /// Rest (no-contact) frame; repeat for several.
    #[arg(long, required = true, value_name = "REST.png")]
    rest: Vec<PathBuf>,
    /// Sensor config (TOML); defaults to the paper's parameters.
    #[arg(long, value_name = "SENSOR.toml")]
    config: Option<PathBuf>,
    /// Output CSV, one row per frame.
    #[arg(long, value_name = "PRED.csv")]
    out: PathBuf,
    /// Write the detected markers of each frame to `DIR/<frame>.csv` (x,y).
    #[arg(long, value_name = "DIR")]
    markers_out: Option<PathBuf>,
    /// Frames (PNG or JPEG files, or directories of them).
    #[arg(required = true, value_name = "FRAME")]
    frames: Vec<PathBuf>,
}

/// Arguments of `dexitac bench-pipeline`.
#[derive(Debug, clap::Args)]
pub struct BenchArgs {
    /// Frames per scene category for the fast settings.
    #[arg(long, default_value_t = 40)]
    frames: usize,
    /// Frames per scene category for the exact (f64, every pixel) settings.
    #[arg(long, default_value_t = 6)]
    exact_frames: usize,
    /// Seed of the synthetic scenes.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Directory for results.md and pareto.png.
    #[arg(long, default_value = "bench-out")]
    out_dir: PathBuf,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Some(Command::Analyze(args)) => analyze::run(&args),
        Some(Command::BenchPipeline(args)) => bench_cmd::run(&args),
        Some(Command::Sim(args)) => cli_sim::run(&args),
        Some(Command::Run(args)) => cli_run::run(&args),
        Some(Command::SynthFrames(args)) => synth_cmd::run(&args),
        Some(Command::Workspace(args)) => {
            cli_kinematics::exit("workspace", cli_kinematics::run_workspace(&args))
        }
        Some(Command::FitActuator(args)) => {
            cli_kinematics::exit("fit-actuator", cli_kinematics::run_fit(&args))
        }
        Some(Command::View(args)) => cli_view::run(&args),
        Some(Command::Record(args)) => cli_record::run_record(&args),
        Some(Command::Replay(args)) => cli_record::run_replay(&args),
        Some(Command::Cameras) => cli_sensor::cameras(),
        Some(Command::Sensor(cli_sensor::SensorCommand::Tune(args))) => cli_sensor::tune(&args),
        Some(Command::Sensor(cli_sensor::SensorCommand::Health(args))) => cli_sensor::health(&args),
        None => {
            println!(
                "dexitac {}: wire protocol v{}. See `dexitac --help`.",
                env!("CARGO_PKG_VERSION"),
                dexitac_protocol::PROTOCOL_VERSION
            );
            ExitCode::SUCCESS
        }
    }
}
