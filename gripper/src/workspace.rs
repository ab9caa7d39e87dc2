//! Workspace of one finger: sample the chamber-pressure space, run the
//! forward kinematics, and measure the reachable set of fingertip points.
//!
//! Input: a [`GripperConfig`] (joint geometry, actuator models, pressure
//! range) and a [`FingerType`]. The pressure space of a finger is its four
//! chambers (Rot, Dex 0..2); a [`Grid`] samples each on evenly spaced
//! pressures from `pressure.min_kpa` to `pressure.max_kpa`
//! (`rot_levels * dex_levels^3` points). Output points are in the finger's
//! base frame (z along the straight finger, Rot bending towards +x), mm.
//! [`TipPoint`] picks the joint end (as the paper measured) or the
//! fingertip.
//!
//! **Volume** ([`volume`]): voxel occupancy. The fingertip positions of a
//! dense grid are binned into cubes of edge `voxel_mm`; the volume is the
//! number of occupied cubes times `voxel_mm^3`. It converges to the volume
//! of the reachable set when the grid is dense enough that neighbouring
//! grid points land closer than one voxel (no holes inside) and the voxel
//! is small against the workspace (the boundary layer of partly covered
//! voxels adds about `area * voxel_mm / 2`). [`VolumeEstimate`] reports the
//! largest distance between grid neighbours (`max_neighbour_gap_mm`) so
//! a caller can see whether the first condition holds, and
//! [`Grid::for_gap`] sizes the grid for a given gap. Since the occupancy is
//! about `V0 + c * voxel_mm`, `2 V(v) - V(2v)` extrapolates to `V0`
//! (`dexitac workspace` reports both). We chose voxels
//! over a convex hull because the workspaces are not convex (the Rot-Dex
//! set is a bent shell), so a hull would count empty space as reachable.
//! The settings of `dexitac workspace` and the measured convergence are in
//! `gripper/KINEMATICS.md`.

use crate::actuator::{dex_state, rot_angle_rad, PressureError};
use crate::configuration::{FingerType, GripperConfig};
use nalgebra::Point3;

use crate::kinematics::{
    base_part, dex_transform, finger_forward, rot_transform, tip_part, Transform,
};

/// Fewest pressure levels per chamber (the two ends of the range).
pub const MIN_LEVELS: usize = 2;
/// Most pressure levels per chamber.
pub const MAX_LEVELS: usize = 1000;
/// Most grid points: 2e8, about 4 s of [`volume`] in release
/// (gripper/KINEMATICS.md).
pub const MAX_POINTS: u64 = 200_000_000;
/// Smallest voxel edge, mm: keeps the occupancy bitmap below ~1 GB for a
/// finger of 100 mm reach.
pub const MIN_VOXEL_MM: f64 = 0.1;

/// Error of a workspace computation.
#[derive(Debug, thiserror::Error)]
pub enum WorkspaceError {
    /// `levels` outside `MIN_LEVELS..=MAX_LEVELS`.
    #[error("pressure levels per chamber must be {MIN_LEVELS}..={MAX_LEVELS}, got {0}")]
    Levels(usize),
    /// The grid has more than [`MAX_POINTS`] points.
    #[error("pressure grid of {0} points is above the limit of {MAX_POINTS}: use fewer levels or a larger voxel")]
    TooManyPoints(u64),
    /// Voxel edge not finite or below [`MIN_VOXEL_MM`].
    #[error("voxel edge must be at least {MIN_VOXEL_MM} mm, got {0}")]
    Voxel(f64),
    /// The forward kinematics rejected a pressure.
    #[error(transparent)]
    Pressure(#[from] PressureError),
}

/// Which point of the finger the workspace is of.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum TipPoint {
    /// The end of the second joint (its outer connector), where the paper
    /// put its ArUco marker (Sec. IV-A, Fig. 7(a1)).
    JointEnd,
    /// The fingertip: `geometry.fingertip_length_mm` beyond the joint end.
    Fingertip,
}

impl TipPoint {
    /// The configuration whose chain ends at this point.
    pub fn config(self, config: &GripperConfig) -> GripperConfig {
        let mut out = config.clone();
        if self == TipPoint::JointEnd {
            out.geometry.fingertip_length_mm = 0.0;
        }
        out
    }
}

/// What a workspace is computed for: a finger type with the joints of a
/// configuration. Only the configuration's joint geometry, actuator models
/// and pressure range are used, in the assembly order of `finger`; its own
/// finger type, assembly and palm mounts play no part (the workspace is in
/// the finger's base frame). So a Dex-Rot workspace computed with the
/// joints of a Rot-Dex preset is a Dex-Rot workspace, and is reported as
/// one ([`Subject::label`]).
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct Subject {
    /// The finger type computed (assembly order, palm to tip).
    pub finger: FingerType,
    /// Where the joints came from, e.g. `preset hookgrip` or a file path.
    pub joints_from: String,
    /// The name of the configuration the joints came from.
    pub joints_config: String,
    /// That configuration's own finger type, not used by the workspace.
    pub joints_config_finger: FingerType,
}

impl Subject {
    /// `finger` with the joints of `joints`, read from `joints_from`.
    pub fn new(finger: FingerType, joints: &GripperConfig, joints_from: impl Into<String>) -> Self {
        Subject {
            finger,
            joints_from: joints_from.into(),
            joints_config: joints.name.clone(),
            joints_config_finger: joints.finger,
        }
    }

    /// One line for people, e.g. `dex-rot finger, joints of HookGrip
    /// (preset hookgrip)`; names the configuration's own finger type when
    /// it differs from the one computed.
    ///
    /// ```
    /// use dexitac_gripper::configuration::{FingerType, Preset};
    /// use dexitac_gripper::workspace::Subject;
    /// let pinch = Preset::PinchGrip.config();
    /// let s = Subject::new(FingerType::DexRot, &pinch, "preset pinchgrip");
    /// assert_eq!(
    ///     s.label(),
    ///     "dex-rot finger, joints of PinchGrip (preset pinchgrip, a rot-dex configuration; its finger order is not used)"
    /// );
    /// ```
    pub fn label(&self) -> String {
        let other = if self.joints_config_finger == self.finger {
            String::new()
        } else {
            format!(
                ", a {} configuration; its finger order is not used",
                self.joints_config_finger.name()
            )
        };
        format!(
            "{} finger, joints of {} ({}{other})",
            self.finger.name(),
            self.joints_config,
            self.joints_from
        )
    }
}

/// One sample: the four chamber pressures and the fingertip position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Rot chamber pressure, kPa.
    pub rot_kpa: f64,
    /// Dex chamber pressures, kPa.
    pub dex_kpa: [f64; 3],
    /// Fingertip position in the finger base frame, mm.
    pub tip_mm: [f64; 3],
}

/// Axis-aligned bounds of a point set, mm.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Extents {
    /// Smallest x, y, z, mm.
    pub min_mm: [f64; 3],
    /// Largest x, y, z, mm.
    pub max_mm: [f64; 3],
    /// `max - min` per axis, mm.
    pub size_mm: [f64; 3],
}

/// A voxel-occupancy volume estimate and how it was made.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct VolumeEstimate {
    /// Estimated volume, mm^3.
    pub volume_mm3: f64,
    /// Voxel edge, mm.
    pub voxel_mm: f64,
    /// Number of occupied voxels.
    pub occupied_voxels: u64,
    /// The pressure grid.
    pub grid: Grid,
    /// Number of grid points.
    pub samples: u64,
    /// Largest fingertip distance between two grid neighbours, mm. Above
    /// `voxel_mm` the occupancy may have holes (volume underestimated).
    pub max_neighbour_gap_mm: f64,
    /// Extents of the sampled fingertip positions.
    pub extents: Extents,
}

/// The pressure grid: evenly spaced levels per chamber, the Rot chamber
/// and each of the three Dex chambers with their own count.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Grid {
    /// Levels of the Rot chamber pressure.
    pub rot_levels: usize,
    /// Levels of each Dex chamber pressure.
    pub dex_levels: usize,
}

impl Grid {
    /// The same count for all four chambers.
    pub const fn uniform(levels: usize) -> Self {
        Grid {
            rot_levels: levels,
            dex_levels: levels,
        }
    }

    /// Number of grid points, `rot_levels * dex_levels^3`.
    pub fn points(&self) -> u64 {
        self.rot_levels as u64 * (self.dex_levels as u64).pow(3)
    }

    /// A grid on which neighbouring fingertip positions land at most about
    /// `gap_mm` apart. Each chamber step moves the tip by at most the reach
    /// times the joint rotation per step (plus the Dex extension per step);
    /// the measured gap is about 0.7 to 0.85 of that bound
    /// (gripper/KINEMATICS.md), so the bound is set to `1.1 gap_mm`. Levels are
    /// clamped to `MIN_LEVELS..=MAX_LEVELS`; [`volume`] reports the gap it
    /// measured.
    pub fn for_gap(config: &GripperConfig, gap_mm: f64) -> Self {
        let range_kpa = config.pressure.max_kpa - config.pressure.min_kpa;
        let reach = reach_mm(config);
        let rot_mm_per_kpa = reach * config.rot.slope_deg_per_kpa.abs().to_radians();
        let dex_mm_per_kpa = reach * config.dex.bend_slope_deg_per_kpa.abs().to_radians()
            + config.dex.extension_slope_mm_per_kpa.abs() / 3.0;
        let levels = |mm_per_kpa: f64| {
            let steps = (range_kpa * mm_per_kpa / (1.1 * gap_mm)).ceil();
            if steps.is_finite() {
                (steps as usize)
                    .saturating_add(1)
                    .clamp(MIN_LEVELS, MAX_LEVELS)
            } else {
                MAX_LEVELS
            }
        };
        Grid {
            rot_levels: levels(rot_mm_per_kpa),
            dex_levels: levels(dex_mm_per_kpa),
        }
    }

    fn check(&self) -> Result<(), WorkspaceError> {
        for levels in [self.rot_levels, self.dex_levels] {
            if !(MIN_LEVELS..=MAX_LEVELS).contains(&levels) {
                return Err(WorkspaceError::Levels(levels));
            }
        }
        match self.points() {
            n if n > MAX_POINTS => Err(WorkspaceError::TooManyPoints(n)),
            _ => Ok(()),
        }
    }
}

/// `levels` evenly spaced pressures over the configured range, kPa.
fn pressure_levels(config: &GripperConfig, levels: usize) -> Vec<f64> {
    let (lo, hi) = (config.pressure.min_kpa, config.pressure.max_kpa);
    let last = (levels - 1) as f64;
    (0..levels)
        .map(|i| lo + (hi - lo) * i as f64 / last)
        .collect()
}

/// Samples the pressure grid, the Rot pressure slowest, Dex chamber 2
/// fastest.
pub fn sample(
    config: &GripperConfig,
    finger: FingerType,
    grid: Grid,
) -> Result<Vec<Sample>, WorkspaceError> {
    grid.check()?;
    let rot = pressure_levels(config, grid.rot_levels);
    let p = pressure_levels(config, grid.dex_levels);
    let mut out = Vec::with_capacity(grid.rot_levels * grid.dex_levels.pow(3));
    for &rot_kpa in &rot {
        for &d0 in &p {
            for &d1 in &p {
                for &d2 in &p {
                    let dex_kpa = [d0, d1, d2];
                    let tip = finger_forward(config, finger, rot_kpa, dex_kpa)?;
                    out.push(Sample {
                        rot_kpa,
                        dex_kpa,
                        tip_mm: tip.translation.vector.into(),
                    });
                }
            }
        }
    }
    Ok(out)
}

/// Bounds of the points (all zero for an empty set).
pub fn extents<'a>(points: impl IntoIterator<Item = &'a [f64; 3]>) -> Extents {
    let mut min_mm = [f64::INFINITY; 3];
    let mut max_mm = [f64::NEG_INFINITY; 3];
    for p in points {
        for k in 0..3 {
            min_mm[k] = min_mm[k].min(p[k]);
            max_mm[k] = max_mm[k].max(p[k]);
        }
    }
    if min_mm[0] > max_mm[0] {
        return Extents {
            min_mm: [0.0; 3],
            max_mm: [0.0; 3],
            size_mm: [0.0; 3],
        };
    }
    Extents {
        min_mm,
        max_mm,
        size_mm: [0, 1, 2].map(|k| max_mm[k] - min_mm[k]),
    }
}

/// Longest possible distance from the finger base to its tip, mm: the sum
/// of all link and (longest) arc lengths; an arc's chord is never longer
/// than the arc.
pub fn reach_mm(config: &GripperConfig) -> f64 {
    let g = &config.geometry;
    4.0 * g.connector_thickness_mm
        + g.rot_length_mm
        + config.dex.max_length_mm
        + g.fingertip_length_mm
}

/// Occupancy bitmap over the cube `[-reach, reach]^3`.
struct Voxels {
    origin_mm: f64,
    voxel_mm: f64,
    side: usize,
    bits: Vec<u64>,
}

impl Voxels {
    fn new(reach_mm: f64, voxel_mm: f64) -> Self {
        // +2: one voxel of slack on each side for rounding at the bound.
        let side = (2.0 * reach_mm / voxel_mm).ceil() as usize + 2;
        let cells = side * side * side;
        Voxels {
            origin_mm: -reach_mm - voxel_mm,
            voxel_mm,
            side,
            bits: vec![0; cells.div_ceil(64)],
        }
    }

    fn mark(&mut self, p: [f64; 3]) {
        let last = self.side - 1;
        // Tips lie within the reach, so the clamp only catches rounding.
        let idx = p.map(|c| (((c - self.origin_mm) / self.voxel_mm) as usize).min(last));
        let cell = (idx[0] * self.side + idx[1]) * self.side + idx[2];
        self.bits[cell / 64] |= 1 << (cell % 64);
    }

    fn count(&self) -> u64 {
        self.bits.iter().map(|w| u64::from(w.count_ones())).sum()
    }
}

fn distance_sq(a: [f64; 3], b: [f64; 3]) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
}

/// The two halves of the finger chain ([`base_part`] and [`tip_part`]),
/// computed once per Rot level and once per Dex grid point, so a grid point
/// costs one transform-point product instead of the full forward
/// kinematics. The half at the palm is kept as a transform, the tip half
/// only as its end point.
enum Halves {
    /// Rot-Dex: Rot half at the palm.
    RotFirst {
        rot: Vec<Transform>,
        dex: Vec<Point3<f64>>,
    },
    /// Dex-Rot: Dex half at the palm.
    DexFirst {
        rot: Vec<Point3<f64>>,
        dex: Vec<Transform>,
    },
}

impl Halves {
    fn new(config: &GripperConfig, finger: FingerType, grid: Grid) -> Result<Self, WorkspaceError> {
        let g = &config.geometry;
        let rot_joints = pressure_levels(config, grid.rot_levels)
            .into_iter()
            .map(|p| {
                Ok(rot_transform(
                    g,
                    rot_angle_rad(&config.rot, &config.pressure, p)?,
                ))
            })
            .collect::<Result<Vec<_>, PressureError>>()?;
        let p = pressure_levels(config, grid.dex_levels);
        let mut dex_joints = Vec::with_capacity(p.len().pow(3));
        for &d0 in &p {
            for &d1 in &p {
                for &d2 in &p {
                    let state = dex_state(&config.dex, &config.pressure, [d0, d1, d2])?;
                    dex_joints.push(dex_transform(&state));
                }
            }
        }
        let base = |joints: Vec<Transform>| joints.iter().map(|t| base_part(g, t)).collect();
        let tip = |joints: Vec<Transform>| {
            joints
                .iter()
                .map(|t| Point3::from(tip_part(g, t).translation.vector))
                .collect()
        };
        Ok(match finger {
            FingerType::RotDex => Halves::RotFirst {
                rot: base(rot_joints),
                dex: tip(dex_joints),
            },
            FingerType::DexRot => Halves::DexFirst {
                rot: tip(rot_joints),
                dex: base(dex_joints),
            },
        })
    }

    /// Fingertip position for Rot level `i` and Dex grid point `j`.
    fn tip(&self, i: usize, j: usize) -> [f64; 3] {
        let tip = match self {
            Halves::RotFirst { rot, dex } => rot[i] * dex[j],
            Halves::DexFirst { rot, dex } => dex[j] * rot[i],
        };
        tip.coords.into()
    }
}

/// Checks a voxel edge: finite and at least [`MIN_VOXEL_MM`].
pub fn check_voxel(voxel_mm: f64) -> Result<(), WorkspaceError> {
    if voxel_mm.is_finite() && voxel_mm >= MIN_VOXEL_MM {
        Ok(())
    } else {
        Err(WorkspaceError::Voxel(voxel_mm))
    }
}

/// Voxel-occupancy volume of the finger's workspace (see the module doc),
/// streaming over the grid (memory: about 150 bytes per Dex grid point,
/// `dex_levels^3` of them, plus the bitmap).
pub fn volume(
    config: &GripperConfig,
    finger: FingerType,
    grid: Grid,
    voxel_mm: f64,
) -> Result<VolumeEstimate, WorkspaceError> {
    grid.check()?;
    check_voxel(voxel_mm)?;
    let halves = Halves::new(config, finger, grid)?;
    let n = grid.dex_levels;
    let slab_len = n * n * n;
    let mut voxels = Voxels::new(reach_mm(config), voxel_mm);
    let mut prev = vec![[0.0; 3]; slab_len];
    let mut cur = vec![[0.0; 3]; slab_len];
    let mut gap_sq: f64 = 0.0;
    let mut min_mm = [f64::INFINITY; 3];
    let mut max_mm = [f64::NEG_INFINITY; 3];
    for i0 in 0..grid.rot_levels {
        for (j, tip_slot) in cur.iter_mut().enumerate() {
            let tip = halves.tip(i0, j);
            voxels.mark(tip);
            for k in 0..3 {
                min_mm[k] = min_mm[k].min(tip[k]);
                max_mm[k] = max_mm[k].max(tip[k]);
            }
            *tip_slot = tip;
        }
        for j in 0..slab_len {
            // Neighbours along Dex 2, Dex 1, Dex 0 (strides 1, n, n^2).
            for (stride, coord) in [(1, j % n), (n, (j / n) % n), (n * n, j / (n * n))] {
                if coord + 1 < n {
                    gap_sq = gap_sq.max(distance_sq(cur[j], cur[j + stride]));
                }
            }
            if i0 > 0 {
                gap_sq = gap_sq.max(distance_sq(cur[j], prev[j]));
            }
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    let gap = gap_sq.sqrt();
    let occupied_voxels = voxels.count();
    Ok(VolumeEstimate {
        volume_mm3: occupied_voxels as f64 * voxel_mm.powi(3),
        voxel_mm,
        occupied_voxels,
        grid,
        samples: grid.points(),
        max_neighbour_gap_mm: gap,
        extents: Extents {
            min_mm,
            max_mm,
            size_mm: [0, 1, 2].map(|k| max_mm[k] - min_mm[k]),
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::configuration::Preset;

    #[test]
    fn dex_rot_workspace_is_larger_than_rot_dex_as_the_paper_reports() {
        // Same joints, same actuator models: only the assembly order
        // differs. The paper tracked the joint end (Sec. IV-A). All presets
        // share the joints, so one is enough.
        let c = TipPoint::JointEnd.config(&Preset::PinchGrip.config());
        let voxel_mm = 6.0;
        let grid = Grid::for_gap(&c, voxel_mm);
        let rot_dex = volume(&c, FingerType::RotDex, grid, voxel_mm).unwrap();
        let dex_rot = volume(&c, FingerType::DexRot, grid, voxel_mm).unwrap();
        for v in [&rot_dex, &dex_rot] {
            assert!(v.max_neighbour_gap_mm <= voxel_mm, "holes: {v:?}");
        }
        assert!(
            dex_rot.volume_mm3 > 1.3 * rot_dex.volume_mm3,
            "dex-rot {} mm^3 vs rot-dex {} mm^3",
            dex_rot.volume_mm3,
            rot_dex.volume_mm3
        );
    }

    #[test]
    fn a_straight_rigid_finger_has_a_point_workspace() {
        let mut c = Preset::PinchGrip.config();
        c.rot.slope_deg_per_kpa = 0.0;
        c.dex.bend_slope_deg_per_kpa = 0.0;
        c.dex.extension_slope_mm_per_kpa = 0.0;
        let v = volume(&c, FingerType::DexRot, Grid::uniform(4), 1.0).unwrap();
        assert_eq!(v.occupied_voxels, 1);
        assert_eq!(v.max_neighbour_gap_mm, 0.0);
        // 2 + 26 + 4 + 26 + 2 + 31 mm along z.
        assert!((v.extents.max_mm[2] - 91.0).abs() < 1e-9);
        assert!(v.extents.size_mm.iter().all(|&s| s.abs() < 1e-9));
    }

    #[test]
    fn volume_of_a_pure_extension_line_is_its_length_in_voxels() {
        // Only the Dex extension moves the tip: a 9 mm segment along z
        // (length 22..31 mm) covers 9 or 10 voxels of 1 mm.
        let mut c = Preset::PinchGrip.config();
        c.rot.slope_deg_per_kpa = 0.0;
        c.dex.bend_slope_deg_per_kpa = 0.0;
        let v = volume(&c, FingerType::RotDex, Grid::uniform(40), 1.0).unwrap();
        assert!((v.extents.size_mm[2] - 9.0).abs() < 1e-9, "{v:?}");
        assert!((9..=10).contains(&v.occupied_voxels), "{v:?}");
    }

    #[test]
    fn sample_and_volume_agree_on_the_extents() {
        let c = Preset::HookGrip.config();
        let pts = sample(&c, FingerType::DexRot, Grid::uniform(5)).unwrap();
        assert_eq!(pts.len(), 625);
        let e = extents(pts.iter().map(|s| &s.tip_mm));
        let v = volume(&c, FingerType::DexRot, Grid::uniform(5), 1.0).unwrap();
        assert_eq!(e, v.extents);
        // Every tip is within the reach.
        let reach = reach_mm(&c);
        assert!(pts
            .iter()
            .all(|s| distance_sq(s.tip_mm, [0.0; 3]).sqrt() <= reach));
    }

    #[test]
    fn precomputed_halves_give_exactly_the_forward_kinematics() {
        let c = TipPoint::Fingertip.config(&Preset::ClosureGrip.config());
        let grid = Grid {
            rot_levels: 4,
            dex_levels: 3,
        };
        for finger in [FingerType::RotDex, FingerType::DexRot] {
            let halves = Halves::new(&c, finger, grid).unwrap();
            let pts = sample(&c, finger, grid).unwrap();
            for (k, s) in pts.iter().enumerate() {
                assert_eq!(halves.tip(k / 27, k % 27), s.tip_mm, "{finger:?} {k}");
            }
        }
    }

    #[test]
    fn the_subject_names_the_finger_computed_not_the_configs() {
        let hook = Preset::HookGrip.config();
        let s = Subject::new(FingerType::DexRot, &hook, "preset hookgrip");
        assert_eq!(
            s.label(),
            "dex-rot finger, joints of HookGrip (preset hookgrip)"
        );
        let s = Subject::new(FingerType::RotDex, &hook, "preset hookgrip");
        assert!(s.label().starts_with("rot-dex finger, joints of HookGrip"));
        assert!(s.label().contains("a dex-rot configuration"));
    }

    #[test]
    fn bad_levels_and_voxels_are_errors() {
        let c = Preset::HookGrip.config();
        assert!(matches!(
            sample(&c, FingerType::DexRot, Grid::uniform(1)),
            Err(WorkspaceError::Levels(1))
        ));
        assert!(matches!(
            volume(
                &c,
                FingerType::DexRot,
                Grid {
                    rot_levels: 1001,
                    dex_levels: 3
                },
                1.0
            ),
            Err(WorkspaceError::Levels(1001))
        ));
        assert!(matches!(
            sample(&c, FingerType::DexRot, Grid::uniform(200)),
            Err(WorkspaceError::TooManyPoints(1_600_000_000))
        ));
        for bad in [0.0, -1.0, f64::NAN, 0.05] {
            assert!(matches!(
                volume(&c, FingerType::DexRot, Grid::uniform(3), bad),
                Err(WorkspaceError::Voxel(_))
            ));
        }
    }
}
