//! `dexitac fit-actuator`: least-squares calibration of the linear
//! pressure -> angle actuator model (`dexitac_gripper::actuator`) from
//! measured rows.

use std::path::{Path, PathBuf};

use anyhow::Context;
use dexitac_gripper::actuator::{self, LineFit};

use crate::exit::Outcome;

/// Arguments of `dexitac fit-actuator`.
#[derive(Debug, clap::Args)]
pub struct FitArgs {
    /// Measured `pressure_kpa,angle_deg` rows (optional header, `#` comments).
    #[arg(long, value_name = "DATA.csv")]
    data: PathBuf,
    /// Which joint the data are from (names the keys in --out).
    #[arg(long, value_enum, default_value = "rot")]
    joint: JointArg,
    /// Write the fitted model as a TOML fragment for a gripper config.
    #[arg(long, value_name = "FIT.toml")]
    out: Option<PathBuf>,
}

/// The joint a calibration is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum JointArg {
    /// Rot joint: `[rot] slope_deg_per_kpa, intercept_deg`.
    Rot,
    /// Dex joint, one chamber pressurised alone: `[dex] bend_slope_deg_per_kpa`.
    Dex,
}

impl FitArgs {
    /// Runs `dexitac fit-actuator`.
    pub fn run(&self) -> anyhow::Result<Outcome> {
        run_fit(self)?;
        Ok(Outcome::Success)
    }
}

fn run_fit(args: &FitArgs) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.data)
        .with_context(|| format!("cannot read {}", args.data.display()))?;
    let data = args.data.display();
    let points = actuator::parse_csv(&text).with_context(|| data.to_string())?;
    let fit = actuator::fit_line(&points).with_context(|| data.to_string())?;
    println!("{} points from {}", fit.points, args.data.display());
    println!("slope          {:.6} deg/kPa", fit.slope_deg_per_kpa);
    println!("intercept      {:.4} deg", fit.intercept_deg);
    println!("R^2            {:.6}", fit.r_squared);
    println!("RMS residual   {:.4} deg", fit.rms_residual_deg);
    println!("max |residual| {:.4} deg", fit.max_abs_residual_deg);
    if let Some(out) = &args.out {
        std::fs::write(out, fit_toml(&fit, args.joint, &args.data))
            .with_context(|| format!("cannot write {}", out.display()))?;
        println!("wrote {}", out.display());
    }
    Ok(())
}

/// The fit as a TOML fragment to paste into a gripper config.
fn fit_toml(fit: &LineFit, joint: JointArg, data: &Path) -> String {
    let quality = format!(
        "# dexitac fit-actuator --data {}\n# points = {}, R^2 = {:.6}, RMS residual = {:.4} deg, max |residual| = {:.4} deg\n",
        data.display(),
        fit.points,
        fit.r_squared,
        fit.rms_residual_deg,
        fit.max_abs_residual_deg
    );
    match joint {
        JointArg::Rot => format!(
            "{quality}[rot]\nslope_deg_per_kpa = {:?}\nintercept_deg = {:?}\n",
            fit.slope_deg_per_kpa, fit.intercept_deg
        ),
        JointArg::Dex => format!(
            "{quality}# The Dex model has no intercept (straight at 0 kPa); the fitted one was {:.4} deg.\n[dex]\nbend_slope_deg_per_kpa = {:?}\n",
            fit.intercept_deg,
            fit.slope_deg_per_kpa.abs()
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_toml_is_valid_toml_with_the_fitted_values() {
        let fit = actuator::fit_line(&[(0.0, 1.0), (10.0, 16.0), (20.0, 31.0)]).unwrap();
        let text = fit_toml(&fit, JointArg::Rot, Path::new("a.csv"));
        let table: toml::Table = toml::from_str(&text).unwrap();
        let rot = table["rot"].as_table().unwrap();
        assert_eq!(rot["slope_deg_per_kpa"].as_float(), Some(1.5));
        assert_eq!(rot["intercept_deg"].as_float(), Some(1.0));
        let text = fit_toml(&fit, JointArg::Dex, Path::new("a.csv"));
        let table: toml::Table = toml::from_str(&text).unwrap();
        assert_eq!(table["dex"]["bend_slope_deg_per_kpa"].as_float(), Some(1.5));
    }
}
