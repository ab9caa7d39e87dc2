//! The rig config: one TOML file for a real rig (`dexitac run --config
//! RIG.toml`) and, with its own `[scenario]` table added, for a simulator
//! scenario (`dexitac sim --scenario FILE`). Commented example:
//! `config/rig.example.toml`.
//!
//! | table | what | type it feeds (its `Default` holds the paper's numbers) |
//! | --- | --- | --- |
//! | `[link]` | serial port and baud | [`LinkSection`] -> [`LinkConfig`] |
//! | `[chambers]` | the grasping chambers of each finger | [`ChamberSection`] |
//! | `[tanks]` | tank targets, kPa | [`TankSection`] |
//! | `[grasp]` | Algorithm 1: T1, T2, the stable span, the no-contact timeout | [`GraspParams`] |
//! | `[control]` | tactile feedback on/off, open-loop close time, telemetry period | [`ControlSection`] |
//! | `[[fingertip]]` | a sensor config per fingertip (`dexitac analyze --config` format) | [`FingertipSection`] -> [`Params`] |
//! | `[gripper]` | one of the four presets, or inline, or a preset with inline changes | [`GripperSection`] -> [`GripperConfig`] |
//! | `[task]` | optional: a manipulation primitive once the grasp is stable | [`TaskParams`] |
//! | `[scenario]` | simulator only | the sim crate's scenario |
//!
//! Every table and key is optional; unknown keys are errors that name the
//! key, the line and the column (a typo must not fall back to a default).
//!
//! ```
//! use dexitac_rig::config::RigConfig;
//! let rig: RigConfig = RigConfig::from_toml_str("[tanks]\npositive_kpa = 35.0\n", "example").unwrap();
//! assert_eq!(rig.control().tank_targets_pa.0, 35_000);
//! let err = RigConfig::<dexitac_rig::config::NoScenario>::from_toml_str("[tanks]\npositive = 35.0\n", "example")
//!     .unwrap_err();
//! assert!(err.to_string().contains("line 2"), "{err}");
//! ```

use std::marker::PhantomData;
use std::path::{Path, PathBuf};

use dexitac_gripper::actuator::{DexActuator, PressureRange, RotActuator};
use dexitac_gripper::configuration::{
    Assembly, ConfigError, FingerMount, FingerType, GripperConfig, JointGeometry, Preset,
};
use dexitac_gripper::grasp::{GraspParams, SENSOR_COUNT};
use dexitac_gripper::manipulation::TaskParams;
use dexitac_protocol::{CHAMBER_COUNT, NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA};
use dexitac_tactile::params::{Params, ParamsError};
use serde::de::{self, Deserialize, Deserializer};

use crate::link::LinkConfig;
use crate::task_loop::{ControlConfig, DEFAULT_GRASP_CHAMBERS};

/// Why a rig config could not be used.
#[derive(Debug, thiserror::Error)]
pub enum RigConfigError {
    /// The file could not be read.
    #[error("cannot read rig config {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// Not TOML, an unknown key or a wrong type (the message names the key,
    /// line and column).
    #[error("rig config {origin}: {source}")]
    Parse {
        /// The file or preset.
        origin: String,
        /// The TOML error.
        source: toml::de::Error,
    },
    /// A value out of its range.
    #[error("rig config {origin}: {key}: {reason}")]
    Invalid {
        /// The file or preset.
        origin: String,
        /// The dotted key, e.g. `tanks.positive_kpa`.
        key: String,
        /// What is allowed.
        reason: String,
    },
    /// A fingertip's sensor config could not be used.
    #[error("rig config {origin}: fingertip {index}: {source}")]
    Sensor {
        /// The file or preset.
        origin: String,
        /// The fingertip (0 or 1).
        index: usize,
        /// Why.
        source: ParamsError,
    },
    /// The gripper configuration is not usable.
    #[error("rig config {origin}: [gripper]: {source}")]
    Gripper {
        /// The file or preset.
        origin: String,
        /// Why.
        source: ConfigError,
    },
}

/// `[link]`: the serial link to the board.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LinkSection {
    /// The board's serial port (`--port` overrides it).
    pub port: Option<PathBuf>,
    /// Line speed, baud.
    pub baud: u32,
}

impl Default for LinkSection {
    fn default() -> Self {
        LinkSection {
            port: None,
            baud: LinkConfig::default().baud,
        }
    }
}

/// `[chambers]`: which chambers close each finger.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ChamberSection {
    /// Per finger, the chambers whose inflation closes it (the others stay
    /// sealed during a grasp). Default: each finger's Rot joint and its
    /// palm-side Dex bellows, `[[0, 1], [4, 5]]`.
    pub grasp_per_finger: Vec<Vec<usize>>,
}

impl Default for ChamberSection {
    fn default() -> Self {
        let half = DEFAULT_GRASP_CHAMBERS.len() / SENSOR_COUNT;
        ChamberSection {
            grasp_per_finger: DEFAULT_GRASP_CHAMBERS
                .chunks(half.max(1))
                .map(<[usize]>::to_vec)
                .collect(),
        }
    }
}

/// `[tanks]`: the targets the board regulates its tanks to.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TankSection {
    /// Positive tank target, kPa.
    pub positive_kpa: f64,
    /// Negative tank target, kPa.
    pub negative_kpa: f64,
}

impl Default for TankSection {
    fn default() -> Self {
        let (p, n) = ControlConfig::default().tank_targets_pa;
        TankSection {
            positive_kpa: f64::from(p) / 1e3,
            negative_kpa: f64::from(n) / 1e3,
        }
    }
}

/// `[control]`: how the task loop drives the grasp.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ControlSection {
    /// Close the loop on the tactile observations (false: the paper's
    /// ablation, an open-loop seal after `open_loop_close_ms`).
    pub tactile_feedback: bool,
    /// Without tactile feedback: seal this long after closing began, ms
    /// (default: the paper's ClosureGrip time to stable, Table III).
    pub open_loop_close_ms: u64,
    /// Telemetry period asked of the board, ms.
    pub telemetry_interval_ms: u16,
    /// A fingertip camera without a frame this long once closing began
    /// ends the run sealed and disarmed, ms (task loop, "Watchdogs").
    pub sensor_timeout_ms: u64,
    /// The board without telemetry this long is asked whether it
    /// restarted, ms (task loop, "Watchdogs").
    pub mcu_silence_ms: u64,
}

impl Default for ControlSection {
    fn default() -> Self {
        let c = ControlConfig::default();
        ControlSection {
            tactile_feedback: c.tactile_feedback,
            open_loop_close_ms: c.open_loop_close_ms,
            telemetry_interval_ms: c.telemetry_interval_ms,
            sensor_timeout_ms: c.sensor_timeout_ms,
            mcu_silence_ms: c.mcu_silence_ms,
        }
    }
}

/// `[[fingertip]]`: one fingertip's sensor.
#[derive(Debug, Clone, PartialEq, Default, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FingertipSection {
    /// Its sensor config (TOML, as `dexitac analyze --config`), relative to
    /// the rig config's folder; none: the paper's parameters.
    pub sensor_config: Option<PathBuf>,
}

/// `[gripper]`: `preset = "closuregrip"` (hookgrip, supportgrip,
/// closuregrip, pinchgrip), or a whole configuration inline (the keys of
/// `gripper/presets/*.toml`), or a preset with some of those keys changed.
#[derive(Debug, Clone, PartialEq, Default, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GripperSection {
    /// One of the four presets to start from.
    pub preset: Option<String>,
    /// Configuration name.
    pub name: Option<String>,
    /// Free text.
    pub description: Option<String>,
    /// Assembly order of both fingers.
    pub finger: Option<FingerType>,
    /// Horizontal or vertical assembly.
    pub assembly: Option<Assembly>,
    /// Joint and link geometry.
    pub geometry: Option<JointGeometry>,
    /// Rot joint actuator model.
    pub rot: Option<RotActuator>,
    /// Dex joint actuator model.
    pub dex: Option<DexActuator>,
    /// Chamber pressure range.
    pub pressure: Option<PressureRange>,
    /// The two fingers.
    pub fingers: Option<Vec<FingerMount>>,
}

impl GripperSection {
    /// The configuration: the preset (if any) with the inline keys applied;
    /// without a preset the inline keys must make a whole configuration.
    /// `Ok(None)` when the table is empty.
    pub fn resolve(&self) -> Result<Option<GripperConfig>, ConfigError> {
        let base = match &self.preset {
            Some(name) => Some(
                Preset::from_name(name)
                    .ok_or_else(|| ConfigError::UnknownPreset(name.clone()))?
                    .config(),
            ),
            None => None,
        };
        let mut c = match base {
            Some(c) => c,
            None if *self == GripperSection::default() => return Ok(None),
            None => GripperConfig {
                name: self
                    .name
                    .clone()
                    .ok_or(ConfigError::Missing("gripper.name"))?,
                description: String::new(),
                finger: self.finger.ok_or(ConfigError::Missing("gripper.finger"))?,
                assembly: self
                    .assembly
                    .ok_or(ConfigError::Missing("gripper.assembly"))?,
                geometry: JointGeometry::default(),
                rot: RotActuator::default(),
                dex: DexActuator::default(),
                pressure: PressureRange::default(),
                fingers: self
                    .fingers
                    .clone()
                    .ok_or(ConfigError::Missing("gripper.fingers"))?,
            },
        };
        if let Some(v) = &self.name {
            c.name = v.clone();
        }
        if let Some(v) = &self.description {
            c.description = v.clone();
        }
        if let Some(v) = self.finger {
            c.finger = v;
        }
        if let Some(v) = self.assembly {
            c.assembly = v;
        }
        if let Some(v) = self.geometry {
            c.geometry = v;
        }
        if let Some(v) = self.rot {
            c.rot = v;
        }
        if let Some(v) = self.dex {
            c.dex = v;
        }
        if let Some(v) = self.pressure {
            c.pressure = v;
        }
        if let Some(v) = &self.fingers {
            c.fingers = v.clone();
        }
        c.validate()?;
        Ok(Some(c))
    }
}

/// The `[scenario]` slot of a real rig's config: always refused (a
/// scenario belongs to `dexitac sim --scenario FILE`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct NoScenario(PhantomData<()>);

impl<'de> Deserialize<'de> for NoScenario {
    fn deserialize<D: Deserializer<'de>>(_: D) -> Result<Self, D::Error> {
        Err(de::Error::custom(
            "a rig config has no [scenario] table (that is a simulator scenario: \
             dexitac sim --scenario FILE)",
        ))
    }
}

/// A rig config; `S` is the `[scenario]` table's type (the simulator's, or
/// [`NoScenario`] on a real rig).
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(
    default,
    deny_unknown_fields,
    bound(deserialize = "S: Deserialize<'de>")
)]
pub struct RigConfig<S = NoScenario> {
    /// `[link]`.
    pub link: LinkSection,
    /// `[chambers]`.
    pub chambers: ChamberSection,
    /// `[tanks]`.
    pub tanks: TankSection,
    /// `[grasp]`: Algorithm 1.
    pub grasp: GraspParams,
    /// `[control]`.
    pub control: ControlSection,
    /// `[[fingertip]]`: at most one per finger, in finger order.
    pub fingertip: Vec<FingertipSection>,
    /// `[gripper]`.
    pub gripper: GripperSection,
    /// `[task]`.
    pub task: Option<TaskParams>,
    /// `[scenario]`.
    pub scenario: Option<S>,
}

impl<S> Default for RigConfig<S> {
    fn default() -> Self {
        RigConfig {
            link: LinkSection::default(),
            chambers: ChamberSection::default(),
            tanks: TankSection::default(),
            grasp: GraspParams::default(),
            control: ControlSection::default(),
            fingertip: Vec::new(),
            gripper: GripperSection::default(),
            task: None,
            scenario: None,
        }
    }
}

impl<S: for<'de> Deserialize<'de>> RigConfig<S> {
    /// Parses and checks a config; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Self, RigConfigError> {
        let config: RigConfig<S> =
            toml::from_str(text).map_err(|source| RigConfigError::Parse {
                origin: origin.into(),
                source,
            })?;
        config.check(origin)?;
        Ok(config)
    }

    /// Reads, parses and checks a config file. Fingertip sensor configs
    /// are taken relative to the file's folder.
    pub fn load(path: &Path) -> Result<Self, RigConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| RigConfigError::Read {
            path: path.into(),
            source,
        })?;
        let mut config = Self::from_toml_str(&text, &path.display().to_string())?;
        let dir = path.parent().unwrap_or(Path::new(""));
        for f in &mut config.fingertip {
            if let Some(p) = &mut f.sensor_config {
                if p.is_relative() {
                    *p = dir.join(&*p);
                }
            }
        }
        Ok(config)
    }
}

impl<S> RigConfig<S> {
    /// The rig tables and the `[scenario]` table, apart.
    pub fn split_scenario(self) -> (RigConfig, Option<S>) {
        let rig = RigConfig {
            link: self.link,
            chambers: self.chambers,
            tanks: self.tanks,
            grasp: self.grasp,
            control: self.control,
            fingertip: self.fingertip,
            gripper: self.gripper,
            task: self.task,
            scenario: None,
        };
        (rig, self.scenario)
    }

    fn check(&self, origin: &str) -> Result<(), RigConfigError> {
        let invalid = |key: &str, reason: String| RigConfigError::Invalid {
            origin: origin.into(),
            key: key.into(),
            reason,
        };
        let per_finger = &self.chambers.grasp_per_finger;
        let all: Vec<usize> = per_finger.iter().flatten().copied().collect();
        if per_finger.len() != SENSOR_COUNT || all.is_empty() {
            return Err(invalid(
                "chambers.grasp_per_finger",
                format!("give a list of chambers for each of the {SENSOR_COUNT} fingers"),
            ));
        }
        if let Some(c) = all.iter().find(|&&c| c >= CHAMBER_COUNT) {
            return Err(invalid(
                "chambers.grasp_per_finger",
                format!("chamber {c} does not exist (0..{CHAMBER_COUNT})"),
            ));
        }
        let mut sorted = all.clone();
        sorted.sort_unstable();
        sorted.dedup();
        if sorted.len() != all.len() {
            return Err(invalid(
                "chambers.grasp_per_finger",
                "a chamber is listed twice".into(),
            ));
        }
        // The firmware refuses targets closer to its hard limits than its
        // guard band: say so here, before any port is opened.
        let band = dexitac_firmware::control::DEFAULT_GUARD_BAND_PA;
        let limit_kpa = (
            f64::from(NEGATIVE_TANK_MIN_PA + band) / 1e3,
            f64::from(POSITIVE_TANK_MAX_PA - band) / 1e3,
        );
        let t = self.tanks;
        if !(t.positive_kpa.is_finite() && t.positive_kpa > 0.0 && t.positive_kpa <= limit_kpa.1) {
            return Err(invalid(
                "tanks.positive_kpa",
                format!(
                    "must lie in (0, {}] kPa (the +50 kPa limit less the firmware's guard band)",
                    limit_kpa.1
                ),
            ));
        }
        if !(t.negative_kpa.is_finite() && t.negative_kpa < 0.0 && t.negative_kpa >= limit_kpa.0) {
            return Err(invalid(
                "tanks.negative_kpa",
                format!(
                    "must lie in [{}, 0) kPa (the -57 kPa limit less the firmware's guard band)",
                    limit_kpa.0
                ),
            ));
        }
        self.grasp
            .validate()
            .map_err(|reason| invalid("grasp", reason.into()))?;
        if self.control.telemetry_interval_ms == 0 {
            return Err(invalid(
                "control.telemetry_interval_ms",
                "must be positive".into(),
            ));
        }
        let telemetry_ms = u64::from(self.control.telemetry_interval_ms);
        if self.control.mcu_silence_ms < 3 * telemetry_ms {
            return Err(invalid(
                "control.mcu_silence_ms",
                format!(
                    "must be at least 3 telemetry periods ({} ms)",
                    3 * telemetry_ms
                ),
            ));
        }
        if self.control.sensor_timeout_ms == 0 {
            return Err(invalid(
                "control.sensor_timeout_ms",
                "must be positive".into(),
            ));
        }
        if self.fingertip.len() > SENSOR_COUNT {
            return Err(invalid(
                "fingertip",
                format!("at most {SENSOR_COUNT} [[fingertip]] tables (one per finger)"),
            ));
        }
        if let Some(task) = &self.task {
            task.validate().map_err(|(field, value, reason)| {
                invalid(&format!("task.{field}"), format!("{value}: {reason}"))
            })?;
        }
        self.gripper
            .resolve()
            .map_err(|source| RigConfigError::Gripper {
                origin: origin.into(),
                source,
            })?;
        Ok(())
    }

    /// The task loop's settings (the values were checked when the config
    /// was parsed).
    pub fn control(&self) -> ControlConfig {
        ControlConfig {
            grasp: self.grasp,
            grasp_chambers: self.chambers.grasp_per_finger.concat(),
            tank_targets_pa: (
                (self.tanks.positive_kpa * 1e3).round() as i32,
                (self.tanks.negative_kpa * 1e3).round() as i32,
            ),
            telemetry_interval_ms: self.control.telemetry_interval_ms,
            tactile_feedback: self.control.tactile_feedback,
            open_loop_close_ms: self.control.open_loop_close_ms,
            sensor_timeout_ms: self.control.sensor_timeout_ms,
            mcu_silence_ms: self.control.mcu_silence_ms,
            task: self.task.clone(),
            ..ControlConfig::default()
        }
    }

    /// The link's settings.
    pub fn link(&self) -> LinkConfig {
        LinkConfig {
            baud: self.link.baud,
            ..LinkConfig::default()
        }
    }

    /// Each fingertip's pipeline parameters, for `sensors` fingertips
    /// (a fingertip without a `[[fingertip]]` table gets the paper's).
    pub fn sensor_params(&self, sensors: usize) -> Result<Vec<Params>, RigConfigError> {
        (0..sensors)
            .map(|index| {
                match self
                    .fingertip
                    .get(index)
                    .and_then(|f| f.sensor_config.as_ref())
                {
                    Some(path) => Params::load(path).map_err(|source| RigConfigError::Sensor {
                        origin: path.display().to_string(),
                        index,
                        source,
                    }),
                    None => Ok(Params::default()),
                }
            })
            .collect()
    }

    /// The gripper configuration (`None` without a `[gripper]` table).
    pub fn gripper_config(&self) -> Option<GripperConfig> {
        // Checked when the config was parsed.
        self.gripper.resolve().ok().flatten()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_empty_config_is_the_paper_default() {
        let rig = RigConfig::<NoScenario>::from_toml_str("", "empty").unwrap();
        let c = rig.control();
        let d = ControlConfig::default();
        assert_eq!(c.grasp, d.grasp);
        assert_eq!(c.grasp_chambers, d.grasp_chambers);
        assert_eq!(c.tank_targets_pa, d.tank_targets_pa);
        assert_eq!(c.open_loop_close_ms, d.open_loop_close_ms);
        assert!(rig.gripper_config().is_none());
    }

    #[test]
    fn a_gripper_preset_file_is_not_a_rig_config_and_the_error_names_key_and_line() {
        let text = include_str!("../../gripper/presets/hookgrip.toml");
        let err = RigConfig::<NoScenario>::from_toml_str(text, "hookgrip.toml").unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("unknown field `assembly`"), "{msg}");
        assert!(msg.contains("line 7"), "{msg}");
    }

    #[test]
    fn a_scenario_table_is_refused_on_a_real_rig() {
        let err = RigConfig::<NoScenario>::from_toml_str("[scenario]\nname = \"x\"\n", "rig")
            .unwrap_err();
        assert!(err.to_string().contains("no [scenario] table"), "{err}");
    }

    #[test]
    fn a_preset_with_changes_resolves() {
        let rig = RigConfig::<NoScenario>::from_toml_str(
            "[gripper]\npreset = \"pinchgrip\"\n[gripper.rot]\nslope_deg_per_kpa = 1.2\n\
             intercept_deg = 0.5\nmin_angle_deg = -70.0\nmax_angle_deg = 70.0\n",
            "rig",
        )
        .unwrap();
        let g = rig.gripper_config().unwrap();
        assert_eq!(g.name, Preset::PinchGrip.config().name);
        assert_eq!(g.rot.slope_deg_per_kpa, 1.2);
        let err =
            RigConfig::<NoScenario>::from_toml_str("[gripper]\npreset = \"clawgrip\"\n", "rig")
                .unwrap_err();
        assert!(err.to_string().contains("clawgrip"), "{err}");
    }

    #[test]
    fn out_of_range_values_name_their_key() {
        for (text, key) in [
            ("[tanks]\npositive_kpa = 60.0\n", "tanks.positive_kpa"),
            ("[tanks]\nnegative_kpa = -80.0\n", "tanks.negative_kpa"),
            ("[grasp]\nslip_shift_mm = 0.1\n", "grasp"),
            (
                "[chambers]\ngrasp_per_finger = [[0, 9], [4]]\n",
                "chambers.grasp_per_finger",
            ),
            (
                "[chambers]\ngrasp_per_finger = [[0, 1], [1]]\n",
                "chambers.grasp_per_finger",
            ),
            ("[[fingertip]]\n[[fingertip]]\n[[fingertip]]\n", "fingertip"),
        ] {
            let err = RigConfig::<NoScenario>::from_toml_str(text, "rig").unwrap_err();
            assert!(err.to_string().contains(key), "{text}: {err}");
        }
    }
}
