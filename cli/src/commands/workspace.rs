//! `dexitac workspace`: a finger's workspace (points CSV, views, extents
//! and volume JSON). Arguments, runs and I/O only; the computations are in
//! `dexitac_gripper::{configuration, kinematics, workspace}`.

use crate::exit::Outcome;
use crate::shared::progress;
use std::path::{Path, PathBuf};
use std::time::Instant;

use dexitac_gripper::configuration::{ConfigError, FingerType, GripperConfig, Preset};
use dexitac_gripper::workspace::{self, Grid, TipPoint, VolumeEstimate, WorkspaceError};
use dexitac_view::figures::workspace::{self as workspace_figure, View, WorkspaceFigure};

/// Error of `dexitac workspace`.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// The gripper config could not be loaded.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The workspace computation failed.
    #[error(transparent)]
    Workspace(#[from] WorkspaceError),
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

impl WorkspaceArgs {
    /// Runs `dexitac workspace`.
    pub fn run(&self) -> anyhow::Result<Outcome> {
        run_workspace(self)?;
        Ok(Outcome::Success)
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

/// Most pressure levels per chamber in the points CSV.
const MAX_CSV_LEVELS: usize = 40;

/// Most pixels per side of a view.
const MAX_IMAGE_PX: u32 = 8192;

/// Runs `dexitac workspace`.
fn run_workspace(args: &WorkspaceArgs) -> Result<(), CliError> {
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
    let finger = FingerType::from(args.finger);
    // Every preset has the same joints; by default one with the finger asked for.
    let preset = args.preset.map_or(Preset::for_finger(finger), Preset::from);
    let (base, source) = match &args.config {
        Some(path) => (GripperConfig::load(path)?, path.display().to_string()),
        None => (preset.config(), format!("preset {}", preset.name())),
    };
    let subject = workspace::Subject::new(finger, &base, source);
    let point = TipPoint::from(args.point);
    let config = point.config(&base);
    std::fs::create_dir_all(&args.out).map_err(|source| CliError::Io {
        path: args.out.clone(),
        source,
    })?;
    let prefix = finger.name();

    // Steps: sample, three views, two volumes.
    let bar = progress::bar(6, "steps");
    let samples = workspace::sample(&config, finger, Grid::uniform(args.levels))?;
    bar.inc(1);
    let csv_path = args.out.join(format!("{prefix}-points.csv"));
    write_points(&csv_path, &samples)?;
    let tips: Vec<[f64; 3]> = samples.iter().map(|s| s.tip_mm).collect();
    let tip = if point == TipPoint::Fingertip {
        "fingertip"
    } else {
        "joint end"
    };
    let title = format!("{prefix} finger workspace ({}, {tip})", subject.joints_from);
    for view in [View::Xy, View::Xz, View::ThreeD] {
        let figure = WorkspaceFigure {
            points: &tips,
            view,
            title: &title,
            size_px: args.image_px,
        };
        workspace_figure::write(&figure, &args.out, &format!("{prefix}-{}", view.name()))?;
        bar.inc(1);
    }

    let started = Instant::now();
    let fine = workspace::volume(
        &config,
        finger,
        Grid::for_gap(&config, args.voxel_mm),
        args.voxel_mm,
    )?;
    bar.inc(1);
    let coarse_mm = 2.0 * args.voxel_mm;
    let coarse = workspace::volume(
        &config,
        finger,
        Grid::for_gap(&config, coarse_mm),
        coarse_mm,
    )?;
    bar.finish_and_clear();
    let elapsed_s = started.elapsed().as_secs_f64();

    let points_csv = serde_json::json!({
        "file": csv_path.file_name().map(|n| n.to_string_lossy()),
        "grid": Grid::uniform(args.levels),
        "samples": samples.len(),
        "extents": workspace::extents(samples.iter().map(|s| &s.tip_mm)),
    });
    let json = workspace_json(&config, &subject, point, points_csv, &fine, &coarse);
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
        "{}, {}: extents x {:.1}..{:.1}, y {:.1}..{:.1}, z {:.1}..{:.1} mm",
        subject.label(),
        point_name(point),
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
        tracing::warn!("dexitac workspace: neighbouring samples land up to {:.2} mm apart, more than the {} mm voxel: the volume may be underestimated",
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
    subject: &workspace::Subject,
    point: TipPoint,
    points_csv: serde_json::Value,
    fine: &VolumeEstimate,
    coarse: &VolumeEstimate,
) -> serde_json::Value {
    serde_json::json!({
        "finger": subject.finger,
        "point": point,
        "config": subject.label(),
        "subject": subject,
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
    let csv_io = |e: csv::Error| CliError::Io {
        path: path.to_owned(),
        source: e.into(),
    };
    let mut w = csv::Writer::from_path(path).map_err(csv_io)?;
    w.write_record([
        "rot_kpa", "dex0_kpa", "dex1_kpa", "dex2_kpa", "x_mm", "y_mm", "z_mm",
    ])
    .map_err(csv_io)?;
    for s in samples {
        let [d0, d1, d2] = s.dex_kpa;
        let [x, y, z] = s.tip_mm;
        let kpa = |v: f64| format!("{v:.3}");
        let mm = |v: f64| format!("{v:.4}");
        w.write_record([
            kpa(s.rot_kpa),
            kpa(d0),
            kpa(d1),
            kpa(d2),
            mm(x),
            mm(y),
            mm(z),
        ])
        .map_err(csv_io)?;
    }
    w.flush().map_err(io)
}
