//! `dexitac workspace` (finger workspace: points CSV, PNG views, extents and
//! volume JSON) and `dexitac fit-actuator` (least-squares calibration of the
//! linear pressure -> angle model). Arguments, runs and I/O only; the
//! computations are in `dexitac_gripper::{configuration, actuator, kinematics, workspace}`.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use dexitac_gripper::actuator::{self, FitError, LineFit};
use dexitac_gripper::configuration::{ConfigError, FingerType, GripperConfig, Preset};
use dexitac_gripper::workspace::{self, Grid, TipPoint, VolumeEstimate, WorkspaceError};
use dexitac_view::figures::workspace::{self as workspace_figure, View, WorkspaceFigure};

/// Error of the kinematics subcommands.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// The gripper config could not be loaded.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The workspace computation failed.
    #[error(transparent)]
    Workspace(#[from] WorkspaceError),
    /// The calibration data could not be fitted.
    #[error("{path}: {source}")]
    Fit {
        /// The data file.
        path: PathBuf,
        /// What is wrong with it.
        source: FitError,
    },
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A figure could not be drawn or written.
    #[error(transparent)]
    Figure(#[from] dexitac_view::figures::FigureError),
    /// A command-line value is out of range.
    #[error("--{arg}: {reason}")]
    Arg {
        /// The argument name.
        arg: &'static str,
        /// What is allowed.
        reason: &'static str,
    },
}

/// Prints an error as `dexitac <command>: error: ...` and maps it to the
/// exit status (0 ok, 2 error).
pub fn exit(command: &str, result: Result<(), CliError>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("dexitac {command}: error: {e}");
            ExitCode::from(2)
        }
    }
}

/// Finger assembly order on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum FingerArg {
    /// Rot joint at the palm, Dex joint outside.
    RotDex,
    /// Dex joint at the palm, Rot joint outside.
    DexRot,
}

impl From<FingerArg> for FingerType {
    fn from(f: FingerArg) -> Self {
        match f {
            FingerArg::RotDex => FingerType::RotDex,
            FingerArg::DexRot => FingerType::DexRot,
        }
    }
}

/// Built-in gripper preset on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PresetArg {
    /// Configuration 1: Dex-Rot, horizontal.
    Hookgrip,
    /// Configuration 2: Rot-Dex, horizontal.
    Supportgrip,
    /// Configuration 3: Dex-Rot, vertical.
    Closuregrip,
    /// Configuration 4: Rot-Dex, vertical.
    Pinchgrip,
}

impl From<PresetArg> for Preset {
    fn from(p: PresetArg) -> Self {
        match p {
            PresetArg::Hookgrip => Preset::HookGrip,
            PresetArg::Supportgrip => Preset::SupportGrip,
            PresetArg::Closuregrip => Preset::ClosureGrip,
            PresetArg::Pinchgrip => Preset::PinchGrip,
        }
    }
}

/// Which point's workspace, on the command line.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PointArg {
    /// End of the second joint, as the paper measured it.
    JointEnd,
    /// Fingertip (the config's fingertip_length_mm further out).
    Fingertip,
}

impl From<PointArg> for TipPoint {
    fn from(p: PointArg) -> Self {
        match p {
            PointArg::JointEnd => TipPoint::JointEnd,
            PointArg::Fingertip => TipPoint::Fingertip,
        }
    }
}

/// Arguments of `dexitac workspace`.
#[derive(Debug, clap::Args)]
pub struct WorkspaceArgs {
    /// Finger assembly order, palm to tip.
    #[arg(long, value_enum)]
    finger: FingerArg,
    /// Gripper config (TOML) for the joint geometry and actuator models;
    /// default: the built-in presets' joints.
    #[arg(long, value_name = "GRIPPER.toml", conflicts_with = "preset")]
    config: Option<PathBuf>,
    /// Take the joints from this built-in preset instead.
    #[arg(long, value_enum)]
    preset: Option<PresetArg>,
    /// The point whose workspace is computed.
    #[arg(long, value_enum, default_value = "joint-end")]
    point: PointArg,
    /// Pressure levels per chamber for the points CSV and the views
    /// (levels^4 points, 2..=40).
    #[arg(long, default_value_t = 11)]
    levels: usize,
    /// Voxel edge of the volume estimate, mm; the pressure grid of the
    /// volume is chosen so that neighbouring samples land about one voxel
    /// apart.
    #[arg(long, default_value_t = 2.0)]
    voxel_mm: f64,
    /// Width and height of the PNG views, px.
    #[arg(long, default_value_t = 800)]
    image_px: u32,
    /// Output directory (created if missing).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
}

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

/// Most pressure levels per chamber in the points CSV.
const MAX_CSV_LEVELS: usize = 40;

/// Most pixels per side of a view.
const MAX_IMAGE_PX: u32 = 8192;

/// Runs `dexitac workspace`.
pub fn run_workspace(args: &WorkspaceArgs) -> Result<(), CliError> {
    if !(64..=MAX_IMAGE_PX).contains(&args.image_px) {
        return Err(CliError::Arg {
            arg: "image-px",
            reason: "must be 64..=8192",
        });
    }
    workspace::check_voxel(args.voxel_mm)?;
    if !(workspace::MIN_LEVELS..=MAX_CSV_LEVELS).contains(&args.levels) {
        return Err(CliError::Arg {
            arg: "levels",
            reason: "must be 2..=40 (40^4 = 2.56 million CSV rows)",
        });
    }
    let (base, source) = match (&args.config, args.preset) {
        (Some(path), _) => (GripperConfig::load(path)?, path.display().to_string()),
        (None, Some(p)) => {
            let p = Preset::from(p);
            (p.config(), format!("preset {}", p.name()))
        }
        // Every preset has the same joints; PinchGrip stands for them.
        (None, None) => (Preset::PinchGrip.config(), "preset pinchgrip".into()),
    };
    let point = TipPoint::from(args.point);
    let config = point.config(&base);
    let finger = FingerType::from(args.finger);
    std::fs::create_dir_all(&args.out).map_err(|source| CliError::Io {
        path: args.out.clone(),
        source,
    })?;
    let prefix = finger.name();

    let samples = workspace::sample(&config, finger, Grid::uniform(args.levels))?;
    let csv_path = args.out.join(format!("{prefix}-points.csv"));
    write_points(&csv_path, &samples)?;
    let tips: Vec<[f64; 3]> = samples.iter().map(|s| s.tip_mm).collect();
    let tip = if point == TipPoint::Fingertip {
        "fingertip"
    } else {
        "joint end"
    };
    let title = format!("{prefix} finger workspace ({source}, {tip})");
    for view in [View::Xy, View::Xz, View::ThreeD] {
        let figure = WorkspaceFigure {
            points: &tips,
            view,
            title: &title,
            size_px: args.image_px,
        };
        workspace_figure::write(&figure, &args.out, &format!("{prefix}-{}", view.name()))?;
    }

    let started = Instant::now();
    let fine = workspace::volume(
        &config,
        finger,
        Grid::for_gap(&config, args.voxel_mm),
        args.voxel_mm,
    )?;
    let coarse_mm = 2.0 * args.voxel_mm;
    let coarse = workspace::volume(
        &config,
        finger,
        Grid::for_gap(&config, coarse_mm),
        coarse_mm,
    )?;
    let elapsed_s = started.elapsed().as_secs_f64();

    let points_csv = serde_json::json!({
        "file": csv_path.file_name().map(|n| n.to_string_lossy()),
        "grid": Grid::uniform(args.levels),
        "samples": samples.len(),
        "extents": workspace::extents(samples.iter().map(|s| &s.tip_mm)),
    });
    let json = workspace_json(&config, &source, finger, point, points_csv, &fine, &coarse);
    let json_path = args.out.join(format!("{prefix}-workspace.json"));
    let text = serde_json::to_string_pretty(&json).map_err(|e| CliError::Io {
        path: json_path.clone(),
        source: e.into(),
    })?;
    std::fs::write(&json_path, text + "\n").map_err(|source| CliError::Io {
        path: json_path.clone(),
        source,
    })?;

    let e = &fine.extents;
    println!(
        "{} finger ({}, {}): extents x {:.1}..{:.1}, y {:.1}..{:.1}, z {:.1}..{:.1} mm",
        prefix,
        point_name(point),
        source,
        e.min_mm[0],
        e.max_mm[0],
        e.min_mm[1],
        e.max_mm[1],
        e.min_mm[2],
        e.max_mm[2]
    );
    println!(
        "volume {:.0} mm^3 at {} mm voxels ({} samples, max neighbour gap {:.2} mm), {:.0} mm^3 at {} mm, extrapolated {:.0} mm^3; {:.2} s",
        fine.volume_mm3,
        fine.voxel_mm,
        fine.samples,
        fine.max_neighbour_gap_mm,
        coarse.volume_mm3,
        coarse.voxel_mm,
        extrapolate(&fine, &coarse),
        elapsed_s
    );
    if fine.max_neighbour_gap_mm > fine.voxel_mm {
        eprintln!(
            "dexitac workspace: warning: neighbouring samples land up to {:.2} mm apart, more than the {} mm voxel: the volume may be underestimated",
            fine.max_neighbour_gap_mm, fine.voxel_mm
        );
    }
    println!("wrote {}", args.out.display());
    Ok(())
}

fn point_name(point: TipPoint) -> &'static str {
    match point {
        TipPoint::JointEnd => "joint-end",
        TipPoint::Fingertip => "fingertip",
    }
}

/// Richardson extrapolation to zero voxel size, assuming the occupancy
/// volume is `V0 + c * voxel` (boundary layer) and the coarse voxel is
/// twice the fine one: `V0 = 2 V(v) - V(2v)`.
fn extrapolate(fine: &VolumeEstimate, coarse: &VolumeEstimate) -> f64 {
    2.0 * fine.volume_mm3 - coarse.volume_mm3
}

fn workspace_json(
    config: &GripperConfig,
    source: &str,
    finger: FingerType,
    point: TipPoint,
    points_csv: serde_json::Value,
    fine: &VolumeEstimate,
    coarse: &VolumeEstimate,
) -> serde_json::Value {
    serde_json::json!({
        "finger": finger,
        "point": point,
        "config": config.name,
        "config_description": config.description,
        "config_finger": config.finger,
        "assembly": config.assembly,
        "config_source": source,
        "frame": "finger base frame: z along the straight finger, Rot joint bending towards +x; mm",
        "pressure_range_kpa": [config.pressure.min_kpa, config.pressure.max_kpa],
        "extents": fine.extents,
        "volume": {
            "method": "voxel occupancy of the fingertip positions on a pressure grid whose neighbouring samples land about one voxel apart; extrapolated = 2 V(voxel) - V(2 voxel)",
            "volume_mm3": fine.volume_mm3,
            "volume_cm3": fine.volume_mm3 / 1000.0,
            "voxel_mm": fine.voxel_mm,
            "occupied_voxels": fine.occupied_voxels,
            "grid": fine.grid,
            "samples": fine.samples,
            "max_neighbour_gap_mm": fine.max_neighbour_gap_mm,
            "coarse_voxel_mm": coarse.voxel_mm,
            "coarse_volume_mm3": coarse.volume_mm3,
            "extrapolated_volume_mm3": extrapolate(fine, coarse),
        },
        "points_csv": points_csv,
    })
}

fn write_points(path: &Path, samples: &[workspace::Sample]) -> Result<(), CliError> {
    let io = |source| CliError::Io {
        path: path.to_owned(),
        source,
    };
    let mut w = BufWriter::new(File::create(path).map_err(io)?);
    writeln!(w, "rot_kpa,dex0_kpa,dex1_kpa,dex2_kpa,x_mm,y_mm,z_mm").map_err(io)?;
    for s in samples {
        let [d0, d1, d2] = s.dex_kpa;
        let [x, y, z] = s.tip_mm;
        writeln!(
            w,
            "{:.3},{d0:.3},{d1:.3},{d2:.3},{x:.4},{y:.4},{z:.4}",
            s.rot_kpa
        )
        .map_err(io)?;
    }
    w.flush().map_err(io)
}

/// Runs `dexitac fit-actuator`.
pub fn run_fit(args: &FitArgs) -> Result<(), CliError> {
    let text = std::fs::read_to_string(&args.data).map_err(|source| CliError::Io {
        path: args.data.clone(),
        source,
    })?;
    let fit_err = |source| CliError::Fit {
        path: args.data.clone(),
        source,
    };
    let points = actuator::parse_csv(&text).map_err(fit_err)?;
    let fit = actuator::fit_line(&points).map_err(fit_err)?;
    println!("{} points from {}", fit.points, args.data.display());
    println!("slope          {:.6} deg/kPa", fit.slope_deg_per_kpa);
    println!("intercept      {:.4} deg", fit.intercept_deg);
    println!("R^2            {:.6}", fit.r_squared);
    println!("RMS residual   {:.4} deg", fit.rms_residual_deg);
    println!("max |residual| {:.4} deg", fit.max_abs_residual_deg);
    if let Some(out) = &args.out {
        std::fs::write(out, fit_toml(&fit, args.joint, &args.data)).map_err(|source| {
            CliError::Io {
                path: out.clone(),
                source,
            }
        })?;
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
