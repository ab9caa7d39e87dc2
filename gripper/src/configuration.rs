//! Gripper configurations: finger type, palm geometry, chamber map, joint
//! geometry and actuator models, from TOML.
//!
//! The paper (Sec. II-B, Fig. 1(b)) builds four configurations from the
//! same joints by changing the assembly order of each finger (base -> tip)
//! and the palm:
//!
//! | preset | finger | assembly | paper |
//! | --- | --- | --- | --- |
//! | [`Preset::HookGrip`] | Dex-Rot | horizontal | "Dex joint at the top, Rot below"; "the use of the Dex-Rot finger gives the HookGrip a large working space" |
//! | [`Preset::SupportGrip`] | Rot-Dex | horizontal | "Dex internal, Rot external"; "the working space of the Rot-Dex finger is smaller" |
//! | [`Preset::ClosureGrip`] | Dex-Rot | vertical | "Dex external, Rot internal"; "the use of Dex-Rot makes the ClosureGrip more capable" |
//! | [`Preset::PinchGrip`] | Rot-Dex | vertical | "Rot joint at the top and the Dex joint at the bottom" |
//!
//! The presets are embedded in the binary (`gripper/presets/*.toml`);
//! a user file has the same format, and every section except the top-level
//! keys and `[[fingers]]` may be left out (it then takes the defaults).
//!
//! Palm frame: origin at the palm centre, z pointing from the palm towards
//! the object (the approach direction), x from the first finger to the
//! second. Each finger's base frame has z along the straight finger; its
//! pose in the palm frame is `position_mm` and `rpy_deg`
//! (`Rz(yaw) Ry(pitch) Rx(roll)`). The paper gives no palm dimensions: the
//! presets' mount poses are our reading of Fig. 1(b), to be measured on the
//! real palm.
//!
//! ```
//! use dexitac_gripper::configuration::{FingerType, Preset};
//! let hook = Preset::HookGrip.config();
//! assert_eq!(hook.finger, FingerType::DexRot);
//! assert_eq!(hook.fingers.len(), 2);
//! ```

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::actuator::{DexActuator, PressureRange, RotActuator};
use crate::kinematics::{self, Transform};
use dexitac_protocol::limits::{NEGATIVE_TANK_MIN_KPA, POSITIVE_TANK_MAX_KPA};
use dexitac_protocol::CHAMBER_COUNT;

/// Side length of a joint connector, mm (paper Table I, `l`).
pub const CONNECTOR_SIDE_MM: f64 = 18.0;
/// Thickness of a joint connector, mm (paper Table I, `t`).
pub const CONNECTOR_THICKNESS_MM: f64 = 2.0;
/// Length of a bellows actuator, mm (paper Table I, `h`).
pub const ACTUATOR_LENGTH_MM: f64 = 26.0;
/// Diameter of a bellows actuator, mm (paper Table I, `d`).
pub const ACTUATOR_DIAMETER_MM: f64 = 10.0;
/// Fingertip (DigiTac-v1.5) length along the finger axis, mm. Paper
/// Table II gives the sensor as 22 x 28 x 31 mm (L x W x H); we take H as
/// the length along the finger (an assumption).
pub const FINGERTIP_LENGTH_MM: f64 = 31.0;
/// Number of fingers on the palm.
pub const FINGER_COUNT: usize = 2;

/// Error loading or validating a gripper configuration.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The config file could not be read.
    #[error("cannot read gripper config {path}: {source}")]
    Io {
        /// The file that failed.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Not valid TOML, a missing key, or an unknown / mistyped field.
    #[error("invalid gripper config: {0}")]
    Parse(#[from] toml::de::Error),
    /// A field has a value outside its allowed range.
    #[error("invalid gripper config value {field} = {value}: {reason}")]
    Invalid {
        /// Dotted field name, e.g. `rot.max_angle_deg`.
        field: String,
        /// The offending value, formatted.
        value: String,
        /// What is allowed.
        reason: &'static str,
    },
    /// No preset has this name.
    #[error("no gripper preset `{0}` (hookgrip, supportgrip, closuregrip, pinchgrip)")]
    UnknownPreset(String),
    /// A key that a configuration without a preset needs.
    #[error("{0} is missing (give it, or a preset to start from)")]
    Missing(&'static str),
}

/// Assembly order of a finger, from the palm to the fingertip.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum FingerType {
    /// Rot joint first (at the palm), then the Dex joint.
    RotDex,
    /// Dex joint first (at the palm), then the Rot joint.
    DexRot,
}

impl FingerType {
    /// The name used in configs and on the command line.
    pub const fn name(self) -> &'static str {
        match self {
            FingerType::RotDex => "rot-dex",
            FingerType::DexRot => "dex-rot",
        }
    }
}

/// How the fingers sit on the palm (paper Sec. II-B: configurations 1 and 2
/// are horizontal assemblies, 3 and 4 vertical). A label: the geometry
/// itself is in each finger's mount pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Assembly {
    /// Horizontal assembly (HookGrip, SupportGrip).
    Horizontal,
    /// Vertical assembly (ClosureGrip, PinchGrip).
    Vertical,
}

impl Assembly {
    /// The name used in configs.
    pub const fn name(self) -> &'static str {
        match self {
            Assembly::Horizontal => "horizontal",
            Assembly::Vertical => "vertical",
        }
    }
}

/// Fixed geometry of a finger's joints and links.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct JointGeometry {
    /// Connector thickness, mm; each joint has one connector at each end.
    pub connector_thickness_mm: f64,
    /// Rot joint arc length (constant: its bending does not extend it), mm.
    pub rot_length_mm: f64,
    /// Rot joint bending plane about the joint axis, deg from +x.
    pub rot_bend_plane_deg: f64,
    /// Fingertip length from the last connector to the tip point, mm.
    pub fingertip_length_mm: f64,
}

impl Default for JointGeometry {
    fn default() -> Self {
        Self {
            connector_thickness_mm: CONNECTOR_THICKNESS_MM,
            rot_length_mm: ACTUATOR_LENGTH_MM,
            rot_bend_plane_deg: 0.0,
            fingertip_length_mm: FINGERTIP_LENGTH_MM,
        }
    }
}

/// One finger on the palm: its mount pose and which chambers drive it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FingerMount {
    /// A name for outputs, e.g. `left`.
    pub name: String,
    /// Finger base position in the palm frame, mm.
    pub position_mm: [f64; 3],
    /// Finger base orientation `[roll, pitch, yaw]`, deg.
    pub rpy_deg: [f64; 3],
    /// Chamber index (`0..8`, as in the protocol) of the Rot joint.
    pub rot_chamber: usize,
    /// Chamber indices of the Dex joint's chambers 0, 1, 2.
    pub dex_chambers: [usize; 3],
}

impl FingerMount {
    /// The finger base frame in the palm frame.
    pub fn transform(&self) -> Transform {
        let [x, y, z] = self.position_mm;
        let [r, p, w] = self.rpy_deg.map(f64::to_radians);
        kinematics::translation(x, y, z) * kinematics::from_rpy(r, p, w)
    }
}

/// A complete gripper configuration.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GripperConfig {
    /// Configuration name, e.g. `HookGrip`.
    pub name: String,
    /// Free text.
    #[serde(default)]
    pub description: String,
    /// Assembly order of both fingers.
    pub finger: FingerType,
    /// Horizontal or vertical assembly on the palm.
    pub assembly: Assembly,
    /// Joint and link geometry.
    #[serde(default)]
    pub geometry: JointGeometry,
    /// Rot joint actuator model.
    #[serde(default)]
    pub rot: RotActuator,
    /// Dex joint actuator model.
    #[serde(default)]
    pub dex: DexActuator,
    /// Chamber pressure range.
    #[serde(default)]
    pub pressure: PressureRange,
    /// The two fingers.
    pub fingers: Vec<FingerMount>,
}

/// The four configurations of the paper.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Preset {
    /// Configuration 1: Dex-Rot fingers, horizontal.
    HookGrip,
    /// Configuration 2: Rot-Dex fingers, horizontal.
    SupportGrip,
    /// Configuration 3: Dex-Rot fingers, vertical.
    ClosureGrip,
    /// Configuration 4: Rot-Dex fingers, vertical.
    PinchGrip,
}

impl Preset {
    /// Every preset.
    pub const ALL: [Preset; 4] = [
        Preset::HookGrip,
        Preset::SupportGrip,
        Preset::ClosureGrip,
        Preset::PinchGrip,
    ];

    /// Lower-case name, as on the command line (`hookgrip`, ...).
    pub const fn name(self) -> &'static str {
        match self {
            Preset::HookGrip => "hookgrip",
            Preset::SupportGrip => "supportgrip",
            Preset::ClosureGrip => "closuregrip",
            Preset::PinchGrip => "pinchgrip",
        }
    }

    /// The embedded TOML text.
    pub const fn toml(self) -> &'static str {
        match self {
            Preset::HookGrip => include_str!("../presets/hookgrip.toml"),
            Preset::SupportGrip => include_str!("../presets/supportgrip.toml"),
            Preset::ClosureGrip => include_str!("../presets/closuregrip.toml"),
            Preset::PinchGrip => include_str!("../presets/pinchgrip.toml"),
        }
    }

    /// The first preset (in [`Preset::ALL`] order) whose fingers are of
    /// type `finger`: HookGrip for Dex-Rot, SupportGrip for Rot-Dex.
    pub fn for_finger(finger: FingerType) -> Preset {
        match finger {
            FingerType::DexRot => Preset::HookGrip,
            FingerType::RotDex => Preset::SupportGrip,
        }
    }

    /// The preset by name (case-insensitive), if any.
    pub fn from_name(name: &str) -> Option<Preset> {
        Self::ALL
            .into_iter()
            .find(|p| p.name().eq_ignore_ascii_case(name))
    }

    /// The parsed, validated preset.
    pub fn config(self) -> GripperConfig {
        // The presets are part of the build and the test
        // `every_preset_loads_and_validates` parses each one.
        GripperConfig::from_toml_str(self.toml()).expect("embedded preset is valid")
    }
}

impl GripperConfig {
    /// Parses and validates a configuration.
    pub fn from_toml_str(text: &str) -> Result<Self, ConfigError> {
        let config: GripperConfig = toml::from_str(text)?;
        config.validate()?;
        Ok(config)
    }

    /// Reads, parses and validates a configuration file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::from_toml_str(&text)
    }

    /// Checks every value's range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let g = &self.geometry;
        at_least(
            "geometry.connector_thickness_mm",
            g.connector_thickness_mm,
            0.0,
        )?;
        positive("geometry.rot_length_mm", g.rot_length_mm)?;
        finite("geometry.rot_bend_plane_deg", g.rot_bend_plane_deg)?;
        at_least("geometry.fingertip_length_mm", g.fingertip_length_mm, 0.0)?;

        let r = &self.rot;
        finite("rot.slope_deg_per_kpa", r.slope_deg_per_kpa)?;
        finite("rot.intercept_deg", r.intercept_deg)?;
        within("rot.min_angle_deg", r.min_angle_deg, -360.0, 360.0)?;
        within("rot.max_angle_deg", r.max_angle_deg, r.min_angle_deg, 360.0)?;

        let d = &self.dex;
        positive("dex.rest_length_mm", d.rest_length_mm)?;
        finite("dex.first_chamber_deg", d.first_chamber_deg)?;
        finite("dex.bend_slope_deg_per_kpa", d.bend_slope_deg_per_kpa)?;
        within("dex.max_bend_deg", d.max_bend_deg, 0.0, 360.0)?;
        finite(
            "dex.extension_slope_mm_per_kpa",
            d.extension_slope_mm_per_kpa,
        )?;
        positive("dex.min_length_mm", d.min_length_mm)?;
        at_least("dex.max_length_mm", d.max_length_mm, d.min_length_mm)?;

        let p = &self.pressure;
        let (tank_min, tank_max) = (
            f64::from(NEGATIVE_TANK_MIN_KPA),
            f64::from(POSITIVE_TANK_MAX_KPA),
        );
        within("pressure.min_kpa", p.min_kpa, tank_min, tank_max)?;
        within("pressure.max_kpa", p.max_kpa, p.min_kpa, tank_max)?;
        if p.max_kpa <= p.min_kpa {
            return Err(invalid(
                "pressure.max_kpa",
                p.max_kpa,
                "must be above pressure.min_kpa",
            ));
        }
        self.validate_fingers()
    }

    fn validate_fingers(&self) -> Result<(), ConfigError> {
        if self.fingers.len() != FINGER_COUNT {
            return Err(invalid(
                "fingers",
                self.fingers.len(),
                "the gripper has exactly 2 fingers",
            ));
        }
        let mut used = [false; CHAMBER_COUNT];
        for (i, f) in self.fingers.iter().enumerate() {
            for (k, v) in f.position_mm.iter().chain(&f.rpy_deg).enumerate() {
                let what = if k < 3 { "position_mm" } else { "rpy_deg" };
                if !v.is_finite() {
                    return Err(ConfigError::Invalid {
                        field: format!("fingers[{i}].{what}"),
                        value: v.to_string(),
                        reason: "must be finite",
                    });
                }
            }
            for chamber in std::iter::once(f.rot_chamber).chain(f.dex_chambers) {
                let field = format!("fingers[{i}] chamber");
                match used.get_mut(chamber) {
                    None => {
                        return Err(ConfigError::Invalid {
                            field,
                            value: chamber.to_string(),
                            reason: "chamber index must be 0..=7",
                        })
                    }
                    Some(true) => {
                        return Err(ConfigError::Invalid {
                            field,
                            value: chamber.to_string(),
                            reason: "each chamber drives exactly one joint",
                        })
                    }
                    Some(slot) => *slot = true,
                }
            }
        }
        Ok(())
    }
}

fn invalid(field: &str, value: impl ToString, reason: &'static str) -> ConfigError {
    ConfigError::Invalid {
        field: field.to_owned(),
        value: value.to_string(),
        reason,
    }
}

fn finite(field: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(invalid(field, v, "must be finite"))
    }
}

fn positive(field: &str, v: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(invalid(field, v, "must be finite and > 0"))
    }
}

fn at_least(field: &str, v: f64, min: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= min {
        Ok(())
    } else {
        Err(invalid(
            field,
            v,
            "must be finite and not below its lower bound",
        ))
    }
}

fn within(field: &str, v: f64, min: f64, max: f64) -> Result<(), ConfigError> {
    if v.is_finite() && v >= min && v <= max {
        Ok(())
    } else {
        Err(invalid(
            field,
            v,
            "out of range (see the gripper config docs)",
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kinematics::gripper_forward;

    #[test]
    fn every_preset_loads_and_validates() {
        for preset in Preset::ALL {
            let c = GripperConfig::from_toml_str(preset.toml())
                .unwrap_or_else(|e| panic!("{}: {e}", preset.name()));
            assert_eq!(c.name.to_ascii_lowercase(), preset.name());
            assert_eq!(Preset::from_name(&c.name), Some(preset));
        }
    }

    #[test]
    fn for_finger_is_the_first_preset_with_that_finger() {
        for finger in [FingerType::DexRot, FingerType::RotDex] {
            let first = Preset::ALL
                .into_iter()
                .find(|p| p.config().finger == finger);
            assert_eq!(Some(Preset::for_finger(finger)), first);
        }
    }

    #[test]
    fn presets_follow_the_paper() {
        use Assembly::*;
        use FingerType::*;
        let want = [
            (Preset::HookGrip, DexRot, Horizontal),
            (Preset::SupportGrip, RotDex, Horizontal),
            (Preset::ClosureGrip, DexRot, Vertical),
            (Preset::PinchGrip, RotDex, Vertical),
        ];
        for (preset, finger, assembly) in want {
            let c = preset.config();
            assert_eq!((c.finger, c.assembly), (finger, assembly), "{preset:?}");
            assert_eq!(c.geometry, JointGeometry::default());
        }
    }

    #[test]
    fn a_minimal_user_file_takes_the_defaults() {
        let text = r#"
            name = "mine"
            finger = "rot-dex"
            assembly = "vertical"
            [[fingers]]
            name = "a"
            position_mm = [0, 0, 0]
            rpy_deg = [0, 0, 0]
            rot_chamber = 7
            dex_chambers = [6, 5, 4]
            [[fingers]]
            name = "b"
            position_mm = [50, 0, 0]
            rpy_deg = [0, 0, 180]
            rot_chamber = 0
            dex_chambers = [1, 2, 3]
        "#;
        let c = GripperConfig::from_toml_str(text).unwrap();
        assert_eq!(c.rot, RotActuator::default());
        assert_eq!(c.pressure, PressureRange::default());
    }

    /// The PinchGrip preset with the line `key = ...` replaced by
    /// `key = value`.
    fn with(key: &str, value: &str) -> Result<GripperConfig, ConfigError> {
        let base = Preset::PinchGrip.toml();
        let prefix = format!("{key} =");
        let mut found = false;
        let text: Vec<String> = base
            .lines()
            .map(|line| {
                if line.trim_start().starts_with(&prefix) {
                    found = true;
                    format!("{key} = {value}")
                } else {
                    line.to_owned()
                }
            })
            .collect();
        assert!(found, "{key} not in the preset");
        GripperConfig::from_toml_str(&text.join("\n"))
    }

    #[test]
    fn bad_toml_gives_typed_errors() {
        assert!(matches!(
            GripperConfig::from_toml_str("name = "),
            Err(ConfigError::Parse(_))
        ));
        // Missing required key.
        assert!(matches!(
            GripperConfig::from_toml_str("name = \"x\"\nfinger = \"rot-dex\"\n"),
            Err(ConfigError::Parse(_))
        ));
        // Unknown finger type and unknown field.
        let text = Preset::PinchGrip
            .toml()
            .replace("\"rot-dex\"", "\"rot-rot\"");
        assert!(matches!(
            GripperConfig::from_toml_str(&text),
            Err(ConfigError::Parse(_))
        ));
        let typo =
            Preset::PinchGrip
                .toml()
                .replacen("[rot]\n", "[rot]\nslope_deg_per_kpaa = 1.0\n", 1);
        assert!(matches!(
            GripperConfig::from_toml_str(&typo),
            Err(ConfigError::Parse(_))
        ));
        let missing = GripperConfig::load(Path::new("/nonexistent/grip.toml"));
        assert!(matches!(missing, Err(ConfigError::Io { .. })));
    }

    #[test]
    fn out_of_range_values_are_rejected_with_their_field() {
        let cases = [
            ("min_angle_deg", "80.0", "rot.max_angle_deg"),
            ("min_length_mm", "0.0", "dex.min_length_mm"),
            ("max_bend_deg", "nan", "dex.max_bend_deg"),
            ("max_kpa", "300.0", "pressure.max_kpa"),
            ("min_kpa", "-100.0", "pressure.min_kpa"),
            ("rot_length_mm", "-1.0", "geometry.rot_length_mm"),
        ];
        for (key, value, field) in cases {
            match with(key, value) {
                Err(ConfigError::Invalid { field: f, .. }) => assert_eq!(f, field, "{key}"),
                other => panic!("{key} = {value}: {other:?}"),
            }
        }
    }

    #[test]
    fn chamber_map_must_use_each_chamber_once() {
        let base = Preset::PinchGrip.toml();
        let dup = base.replacen("rot_chamber = 4", "rot_chamber = 0", 1);
        assert_ne!(dup, base);
        assert!(matches!(
            GripperConfig::from_toml_str(&dup),
            Err(ConfigError::Invalid { reason, .. }) if reason.contains("exactly one")
        ));
        let out = base.replacen("rot_chamber = 4", "rot_chamber = 8", 1);
        assert!(matches!(
            GripperConfig::from_toml_str(&out),
            Err(ConfigError::Invalid { reason, .. }) if reason.contains("0..=7")
        ));
    }

    #[test]
    fn rot_pressure_closes_the_fingers_of_every_preset() {
        // At rest the fingers are straight; inflating both Rot chambers
        // moves each fingertip towards the other finger (vertical) or
        // towards the object side (+z, horizontal: the hook).
        for preset in Preset::ALL {
            let c = preset.config();
            let rest = gripper_forward(&c, &[0.0; 8]).unwrap();
            let mut p = [0.0; 8];
            for f in &c.fingers {
                p[f.rot_chamber] = 40.0;
            }
            let bent = gripper_forward(&c, &p).unwrap();
            for (a, b) in rest.iter().zip(&bent) {
                let (ra, rb) = (a.translation.vector, b.translation.vector);
                match c.assembly {
                    Assembly::Vertical => {
                        assert!((rb[0] - ra[0]) * ra[0].signum() < -1.0, "{preset:?}")
                    }
                    Assembly::Horizontal => assert!(rb[2] > ra[2] + 1.0, "{preset:?}"),
                }
            }
        }
    }
}
