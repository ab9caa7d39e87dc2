//! `dexitac sensor tune | health`: set up a fingertip's skin.
//!
//! - `sensor tune --rest REST.png --pins N [--config SENSOR.toml] [--out
//!   OUT.toml]`: tunes the marker detector so the rest frame shows the
//!   skin's N pins ([`dexitac_tactile::sensor_setup::tune`]); writes the sensor
//!   config (all fields, the base config's values elsewhere) to `--out`, or
//!   to stdout. Exit 0 when the count is matched exactly, 1 when only the
//!   closest count was found (the config is still written), 2 on bad input.
//! - `sensor health --rest REST.png [--config SENSOR.toml] [--pins N]
//!   [FRAME...]`: checks current no-contact frames (files or folders)
//!   against the rest frame ([`dexitac_tactile::sensor_setup::health`]). Exit 0
//!   pass, 1 warn, 2 fail, 3 when the check could not run (bad input).

use crate::exit::Outcome;
use crate::shared::sources::load_sensor_config;
use anyhow::anyhow;
use std::path::{Path, PathBuf};

use dexitac_rig::sources;
use dexitac_tactile::frame::GreyFrame;
use dexitac_tactile::params::Params;
use dexitac_tactile::sensor_setup::{self, HealthLimits, HealthReport, Verdict};
use dexitac_tactile::PointPx;

/// `dexitac sensor` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum SensorCommand {
    /// Tune the marker detector to the skin's known pin count on a rest
    /// frame; writes a sensor config for `analyze --config` and `run`.
    Tune(TuneArgs),
    /// Check a skin: missing, merged, extra or damaged markers, sensing-area
    /// coverage and marker jitter against the rest frame. Exit 0 pass, 1
    /// warn, 2 fail, 3 error.
    Health(HealthArgs),
}

/// Arguments of `dexitac sensor tune`.
#[derive(Debug, clap::Args)]
pub struct TuneArgs {
    /// Rest (no-contact) frame.
    #[arg(long, value_name = "REST.png")]
    rest: PathBuf,
    /// Number of pins (markers) on the skin.
    #[arg(long, value_name = "N")]
    pins: usize,
    /// Base sensor config (TOML); defaults to the paper's parameters.
    #[arg(long, value_name = "SENSOR.toml")]
    config: Option<PathBuf>,
    /// Where to write the tuned config (default: stdout).
    #[arg(long, value_name = "OUT.toml")]
    out: Option<PathBuf>,
}

/// Arguments of `dexitac sensor health`.
#[derive(Debug, clap::Args)]
pub struct HealthArgs {
    /// Reference rest (no-contact) frame.
    #[arg(long, value_name = "REST.png")]
    rest: PathBuf,
    /// Sensor config (TOML); defaults to the paper's parameters.
    #[arg(long, value_name = "SENSOR.toml")]
    config: Option<PathBuf>,
    /// The skin's pin count, to check the rest frame against.
    #[arg(long, value_name = "N")]
    pins: Option<usize>,
    /// Fail below this sensing-area coverage, percent.
    #[arg(long, default_value_t = 98.0)]
    min_coverage_pct: f64,
    /// Warn above this marker jitter, px.
    #[arg(long, default_value_t = 0.5)]
    max_jitter_px: f64,
    /// Current no-contact frames to check (files or folders; none: the
    /// rest frame itself).
    #[arg(value_name = "FRAME")]
    frames: Vec<PathBuf>,
}

fn load(path: &Path, params: &Params) -> anyhow::Result<GreyFrame> {
    sources::load_frame(path, &params.frame).map_err(|e| anyhow!("{e}"))
}

impl SensorCommand {
    /// Runs `dexitac sensor tune` ([`Outcome::Negative`]: no exact pin
    /// count) or `dexitac sensor health` (pass, warn or fail).
    pub fn run(&self) -> anyhow::Result<Outcome> {
        match self {
            SensorCommand::Tune(args) => Ok(Outcome::from_ok(tune_inner(args)?)),
            SensorCommand::Health(args) => {
                let report = health_inner(args)?;
                print_report(&report);
                Ok(match report.verdict {
                    Verdict::Pass => Outcome::Success,
                    Verdict::Warn => Outcome::Negative,
                    Verdict::Fail => Outcome::HealthFail,
                })
            }
        }
    }
}

fn tune_inner(args: &TuneArgs) -> anyhow::Result<bool> {
    let base = load_sensor_config(args.config.as_deref())?;
    let rest = load(&args.rest, &base)?;
    let before = sensor_setup::count_markers(&rest, &base.markers);
    let r = sensor_setup::tune(&rest, args.pins, &base).map_err(|e| anyhow!("{e}"))?;
    let tuned = Params {
        markers: r.markers.clone(),
        ..base
    };
    let summary = format!("{}: {}", args.rest.display(), r.summary(before));
    let text = sensor_setup::params_toml(
        &tuned,
        &format!("Sensor config tuned by `dexitac sensor tune`.\n{summary}"),
    );
    // The written file must load back as the tuned parameters.
    Params::from_toml_str(&text).map_err(|e| anyhow!("internal: tuned config invalid: {e}"))?;
    match &args.out {
        Some(path) => std::fs::write(path, &text)
            .map_err(|e| anyhow!("cannot write {}: {e}", path.display()))?,
        None => print!("{text}"),
    }
    tracing::info!("dexitac sensor tune: {summary}");
    if !r.exact {
        tracing::info!(
            "dexitac sensor tune: no setting finds exactly {} markers; the closest was written \
             (check the rest frame: nothing touching, in focus, evenly lit)",
            r.pins
        );
        // The commonest cause on data sets without a rest frame: a median
        // image of taps, whose pins under the taps are smeared.
        if r.holes {
            tracing::warn!(
                "dexitac sensor tune: the rest's marker lattice has holes (a pressed rest, or \
                 the median image of taps?): tune on a no-contact frame; without one, \
                 `dexitac analyze --rest-from-frames` estimates the rest from the frames"
            );
        }
    }
    Ok(r.exact)
}

fn health_inner(args: &HealthArgs) -> anyhow::Result<HealthReport> {
    let params = load_sensor_config(args.config.as_deref())?;
    let rest = load(&args.rest, &params)?;
    let mut frames = Vec::new();
    for path in &args.frames {
        if path.is_dir() {
            for f in sources::image_files(path).map_err(|e| anyhow!("{e}"))? {
                frames.push(load(&f, &params)?);
            }
        } else {
            frames.push(load(path, &params)?);
        }
    }
    let limits_ok = (0.0..=100.0).contains(&args.min_coverage_pct)
        && args.max_jitter_px.is_finite()
        && args.max_jitter_px >= 0.0;
    if !limits_ok {
        return Err(anyhow!(
            "--min-coverage-pct must lie in 0..=100, --max-jitter-px >= 0"
        ));
    }
    let limits = HealthLimits {
        min_coverage: args.min_coverage_pct / 100.0,
        max_jitter_px: args.max_jitter_px,
        ..HealthLimits::default()
    };
    sensor_setup::health(&rest, &frames, &params, &limits, args.pins).map_err(|e| anyhow!("{e}"))
}

fn positions(list: &[PointPx]) -> String {
    const SHOWN: usize = 8;
    let mut s: Vec<String> = list
        .iter()
        .take(SHOWN)
        .map(|p| format!("({:.0}, {:.0})", p.x, p.y))
        .collect();
    if list.len() > SHOWN {
        s.push(format!("... {} more", list.len() - SHOWN));
    }
    if s.is_empty() {
        String::new()
    } else {
        format!("  at {}", s.join(" "))
    }
}

fn print_report(r: &HealthReport) {
    println!(
        "rest frame: {} markers, pitch {:.1} px; {} frame(s) checked",
        r.rest_markers, r.pitch_px, r.frames
    );
    for (name, list) in [
        ("missing", &r.missing),
        ("merged", &r.merged),
        ("extra", &r.extra),
        ("damaged", &r.damaged),
        ("flickering", &r.flickering),
    ] {
        println!("{name:>11}: {:4}{}", list.len(), positions(list));
    }
    println!(
        "{:>11}: {:.1} % of the sensing area at or above the contact threshold",
        "coverage",
        100.0 * r.coverage
    );
    match r.jitter_px {
        Some((median, max)) => println!("{:>11}: median {median:.3} px, max {max:.3} px", "jitter"),
        None => println!("{:>11}: n/a (give two or more frames)", "jitter"),
    }
    println!("{}", r.verdict);
    for reason in &r.reasons {
        println!("  - {reason}");
    }
}
