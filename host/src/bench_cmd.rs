//! `dexitac bench-pipeline`: accuracy against run time (see `dexitac::bench`).

use std::fmt::Write as _;
use std::process::ExitCode;

use dexitac::bench::{self, Summary};
use dexitac::synth::Category;

use crate::BenchArgs;

/// Runs the subcommand.
pub fn run(args: &BenchArgs) -> ExitCode {
    match run_inner(args) {
        Ok(()) => ExitCode::SUCCESS,
        Err(msg) => {
            eprintln!("dexitac bench-pipeline: error: {msg}");
            ExitCode::from(2)
        }
    }
}

fn run_inner(args: &BenchArgs) -> Result<(), String> {
    std::fs::create_dir_all(&args.out_dir)
        .map_err(|e| format!("cannot create {}: {e}", args.out_dir.display()))?;
    let mut report = String::new();
    let mut points = Vec::new();
    for setting in bench::settings() {
        let exact = setting.params.density.mode == dexitac::params::DensityMode::Exact;
        let frames = if exact {
            args.exact_frames
        } else {
            args.frames
        };
        eprintln!(
            "bench-pipeline: {} ({frames} frames per scene)",
            setting.name
        );
        let samples = bench::evaluate(&setting, &Category::ALL, frames, 640, 480, args.seed)
            .map_err(|e| e.to_string())?;
        let sums: Vec<Summary> = Category::ALL
            .iter()
            .map(|&c| bench::summarize(c, &samples))
            .collect();
        let table = bench::markdown(setting.name, &sums);
        println!("{table}");
        let _ = writeln!(report, "{table}");
        points.push((setting.name, sums));
    }
    std::fs::write(args.out_dir.join("results.md"), &report)
        .map_err(|e| format!("cannot write results.md: {e}"))?;
    Ok(())
}
