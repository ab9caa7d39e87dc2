//! `dexitac bench-pipeline`: accuracy against run time (see `dexitac_tactile::bench`).

use anyhow::anyhow;
use std::fmt::Write as _;
use std::path::PathBuf;

use dexitac_tactile::bench::{self, Pooled, Summary};
use dexitac_tactile::params::DensityMode;
use dexitac_tactile::synth::Category;

use crate::exit::Outcome;
use crate::shared::out_dir::{self, Owned};
use crate::shared::progress;

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

/// Plot colours, one per setting in `bench::settings()` order.
const COLOURS: [([u8; 3], &str); 10] = [
    ([200, 0, 0], "red"),
    ([255, 140, 0], "orange"),
    ([150, 100, 50], "brown"),
    ([200, 200, 0], "olive"),
    ([0, 160, 160], "teal"),
    ([0, 0, 220], "blue"),
    ([140, 0, 200], "purple"),
    ([255, 0, 200], "magenta"),
    ([0, 200, 255], "sky blue"),
    ([0, 0, 0], "black"),
];

/// The files `dexitac bench-pipeline` writes into --out-dir.
const OWNED: [Owned; 3] = [
    Owned::File("results.md"),
    Owned::File("pareto.png"),
    Owned::File("pareto.svg"),
];

impl BenchArgs {
    /// Runs the command.
    pub fn run(&self) -> anyhow::Result<Outcome> {
        run_inner(self)?;
        Ok(Outcome::Success)
    }
}

fn run_inner(args: &BenchArgs) -> anyhow::Result<()> {
    out_dir::prepare("bench-pipeline", &args.out_dir, &OWNED)?;
    let settings = bench::settings();
    const SIZES: [(usize, usize); 3] = [(320, 240), (640, 480), (1280, 960)];
    let bar = progress::bar((settings.len() + SIZES.len()) as u64, "settings and sizes");
    let mut details = String::new();
    let mut pooled: Vec<Pooled> = Vec::new();
    for setting in settings {
        bar.inc(1);
        let exact = setting.params.density.mode == DensityMode::Exact;
        let frames = if exact {
            args.exact_frames
        } else {
            args.frames
        };
        tracing::info!(
            "bench-pipeline: {} ({frames} frames per scene)",
            setting.name
        );
        let samples = bench::evaluate(&setting, &Category::ALL, frames, 640, 480, args.seed)
            .map_err(|e| anyhow!("{e}"))?;
        let sums: Vec<Summary> = Category::ALL
            .iter()
            .map(|&c| bench::summarize(c, &samples))
            .collect();
        let _ = writeln!(details, "{}", bench::markdown(setting.name, &sums));
        pooled.push(bench::pool(setting.name, &samples));
    }
    let mut report = String::new();
    let _ = writeln!(
        report,
        "### Pareto (640x480, seed {}, {} frames per scene, {} for exact)\n",
        args.seed, args.frames, args.exact_frames
    );
    let _ = writeln!(report, "{}", bench::pareto_markdown(&pooled));
    let _ = writeln!(report, "Plot colours (pareto.png):");
    for (p, (_, name)) in pooled.iter().zip(COLOURS) {
        let _ = writeln!(report, "- {name}: {}", p.name);
    }
    let _ = writeln!(report, "\n### Time against image size (default setting)\n");
    let _ = writeln!(
        report,
        "| size | contact: detect | kde | segment | total ms | no contact: total ms |"
    );
    let _ = writeln!(report, "|---|---|---|---|---|---|");
    for (w, h) in SIZES {
        bar.inc(1);
        tracing::info!("bench-pipeline: timing {w}x{h}");
        let (c, n) =
            bench::time_at_size(w, h, args.frames, args.seed).map_err(|e| anyhow!("{e}"))?;
        let _ = writeln!(
            report,
            "| {w}x{h} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
            c.detect_ms, c.kde_ms, c.segment_ms, c.total_ms, n.total_ms
        );
    }
    let _ = writeln!(
        report,
        "\n### Fast density path against the exact f64 reference (640x480, 3 nominal frames)\n"
    );
    let _ = writeln!(
        report,
        "| grid step px | max abs diff / rest density | mean abs diff / rest density |"
    );
    let _ = writeln!(report, "|---|---|---|");
    for (step, worst, mean) in bench::density_difference(&[1, 2, 4, 8], 3, args.seed) {
        let _ = writeln!(report, "| {step} | {worst:.2e} | {mean:.2e} |");
    }
    let _ = writeln!(report, "\n### Per scene\n\n{details}");
    print!("{report}");
    let colours: Vec<[u8; 3]> = COLOURS.iter().map(|c| c.0).collect();
    dexitac_view::figures::pareto::write(&pooled, &colours, &args.out_dir)
        .map_err(|e| anyhow!("{e}"))?;
    let png = args.out_dir.join("pareto.png");
    bar.finish_and_clear();
    std::fs::write(args.out_dir.join("results.md"), &report)
        .map_err(|e| anyhow!("cannot write results.md: {e}"))?;
    tracing::info!(
        "bench-pipeline: wrote {}, pareto.svg and results.md",
        png.display()
    );
    Ok(())
}
