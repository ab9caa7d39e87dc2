//! Scenarios of the simulated rig: TOML files, with the paper's experiments
//! embedded as presets ([`PRESETS`]).
//!
//! A scenario file is a rig config (`dexitac_rig::config`, the format of
//! `dexitac run --config`; example `config/rig.example.toml`) with a
//! `[scenario]` table added. The rig tables (`[grasp]`, `[tanks]`,
//! `[chambers]`, `[control]`, `[task]`, ...) drive the simulated rig as
//! they drive the real one.
//!
//! ```toml
//! [scenario]
//! name = "my-scenario"
//! duration_s = 20.0
//! frame_period_ms = 33        # camera frame period (simulated time)
//! no_object = false           # true: nothing between the fingers
//! [scenario.object]           # sim::plant::ObjectParams (all optional)
//! mass_kg = 0.1
//! [scenario.plant]            # sim::plant::PlantParams (all optional)
//! [scenario.trajectory]       # lift and move, s and mm
//! lift_at_s = 10.0
//! [[scenario.poke]]           # external forces
//! target = "object"           # object | actuator | fingertip_back
//! finger = 0
//! at_s = 12.0
//! duration_s = 0.8
//! peak_n = 3.5
//! shape = "half_sine"         # half_sine | ramp_hold
//!
//! [task]                      # manipulation::TaskParams (optional)
//! kind = "pour"               # pour | rotate | shake | twist
//! stroke_ms = 3000
//! [grasp]                     # Algorithm 1 (optional), as on the real rig
//! stable_shift_mm = 0.5
//! ```
//!
//! Unknown keys are errors (a typo must not silently fall back to a default).

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::plant::{ObjectParams, PlantParams, Poke, Trajectory, FINGER_COUNT};
use dexitac_gripper::manipulation::TaskParams;
use dexitac_rig::config::{RigConfig, RigConfigError};

/// The embedded scenarios: (name, TOML).
pub const PRESETS: [(&str, &str); 8] = [
    ("disturbance", include_str!("scenarios/disturbance.toml")),
    ("grasp-hold", include_str!("scenarios/grasp-hold.toml")),
    ("slip", include_str!("scenarios/slip.toml")),
    ("no-object", include_str!("scenarios/no-object.toml")),
    ("pour", include_str!("scenarios/pour.toml")),
    ("rotate", include_str!("scenarios/rotate.toml")),
    ("shake", include_str!("scenarios/shake.toml")),
    ("twist", include_str!("scenarios/twist.toml")),
];

/// The default scenario: the paper's disturbance experiment.
pub const DEFAULT_SCENARIO: &str = "disturbance";

/// Why a scenario could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ScenarioError {
    /// Neither a preset name nor a readable file.
    #[error("no scenario `{name}`: not a preset ({known}) and not a file")]
    Unknown {
        /// What was asked for.
        name: String,
        /// The preset names.
        known: String,
    },
    /// The file could not be read.
    #[error("cannot read scenario {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The TOML does not parse, has unknown keys or wrong types, or a rig
    /// table is out of range (the message names the key and line).
    #[error(transparent)]
    Parse(#[from] RigConfigError),
    /// The file has no `[scenario]` table.
    #[error("scenario {origin}: no [scenario] table (a rig config alone is for `dexitac run`)")]
    NoScenario {
        /// The preset name or file.
        origin: String,
    },
    /// A value is out of its range.
    #[error("scenario {origin}: {field} = {value} is invalid: {reason}")]
    Invalid {
        /// The preset name or file.
        origin: String,
        /// The offending key.
        field: String,
        /// Its value.
        value: String,
        /// What is allowed.
        reason: &'static str,
    },
}

fn default_frame_period_ms() -> u64 {
    33
}

/// A scenario of the simulated rig: the `[scenario]` table of a rig config
/// file, with the file's `[task]` and its other rig tables.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Name, reported in `summary.json`.
    pub name: String,
    /// One-line description.
    #[serde(default)]
    pub description: String,
    /// Simulated run time, s.
    pub duration_s: f64,
    /// Camera frame period, ms of simulated time.
    #[serde(default = "default_frame_period_ms")]
    pub frame_period_ms: u64,
    /// Nothing between the fingers.
    #[serde(default)]
    pub no_object: bool,
    /// The object.
    #[serde(default)]
    pub object: ObjectParams,
    /// The gripper.
    #[serde(default)]
    pub plant: PlantParams,
    /// Lift and move.
    #[serde(default)]
    pub trajectory: Trajectory,
    /// External forces.
    #[serde(default, rename = "poke")]
    pub pokes: Vec<Poke>,
    /// A manipulation task to run once the grasp is stable: the file's
    /// top-level `[task]` table.
    #[serde(skip)]
    pub task: Option<TaskParams>,
    /// The file's rig tables (`[grasp]`, `[tanks]`, `[chambers]`,
    /// `[control]`, `[[fingertip]]`, `[gripper]`; `dexitac_rig::config`);
    /// its task is [`Scenario::task`].
    #[serde(skip)]
    pub rig: RigConfig,
}

impl Scenario {
    /// A preset by name, or a TOML file by path.
    pub fn load(name_or_path: &str) -> Result<Scenario, ScenarioError> {
        if let Some((name, text)) = PRESETS.iter().find(|(n, _)| *n == name_or_path) {
            return Scenario::from_toml_str(text, name);
        }
        let path = Path::new(name_or_path);
        if !path.exists() {
            return Err(ScenarioError::Unknown {
                name: name_or_path.to_string(),
                known: PRESETS.map(|(n, _)| n).join(", "),
            });
        }
        let text = std::fs::read_to_string(path).map_err(|source| ScenarioError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Scenario::from_toml_str(&text, &path.display().to_string())
    }

    /// Parses and validates a scenario; `origin` names it in errors.
    pub fn from_toml_str(text: &str, origin: &str) -> Result<Scenario, ScenarioError> {
        let rig = RigConfig::<Scenario>::from_toml_str(text, origin)?;
        let (mut rig, scenario) = rig.split_scenario();
        let mut scenario = scenario.ok_or_else(|| ScenarioError::NoScenario {
            origin: origin.to_string(),
        })?;
        scenario.task = rig.task.take();
        scenario.rig = rig;
        scenario.validate(origin)?;
        Ok(scenario)
    }

    /// The object, unless the scenario has none.
    pub fn object(&self) -> Option<&ObjectParams> {
        (!self.no_object).then_some(&self.object)
    }

    fn validate(&self, origin: &str) -> Result<(), ScenarioError> {
        let bad = |field: &str, value: String, reason| ScenarioError::Invalid {
            origin: origin.to_string(),
            field: field.to_string(),
            value,
            reason,
        };
        let positive = |field: &str, v: f64, max: f64| {
            if v.is_finite() && v > 0.0 && v <= max {
                Ok(())
            } else {
                Err(bad(
                    field,
                    v.to_string(),
                    "must be positive, finite and not absurdly large",
                ))
            }
        };
        let non_negative = |field: &str, v: f64| {
            if v.is_finite() && (0.0..=1e6).contains(&v) {
                Ok(())
            } else {
                Err(bad(field, v.to_string(), "must be finite and >= 0"))
            }
        };
        positive("duration_s", self.duration_s, 3_600.0)?;
        if !(5..=1_000).contains(&self.frame_period_ms) {
            return Err(bad(
                "frame_period_ms",
                self.frame_period_ms.to_string(),
                "must be 5..=1000",
            ));
        }
        let o = &self.object;
        positive("object.mass_kg", o.mass_kg, 100.0)?;
        non_negative("object.gap_mm", o.gap_mm)?;
        positive("object.friction", o.friction, 10.0)?;
        positive(
            "object.shear_stiffness_n_per_mm",
            o.shear_stiffness_n_per_mm,
            1e6,
        )?;
        non_negative(
            "object.slip_rate_mm_per_s_per_n",
            o.slip_rate_mm_per_s_per_n,
        )?;
        positive("object.drop_slide_mm", o.drop_slide_mm, 1e3)?;
        positive("object.contact_width_mm", o.contact_width_mm, 20.0)?;
        for c in o.contact_mm.iter().flatten() {
            if !(c.is_finite() && c.abs() <= 15.0) {
                return Err(bad(
                    "object.contact_mm",
                    c.to_string(),
                    "must lie within 15 mm of the sensor centre",
                ));
            }
        }
        let p = &self.plant;
        positive("plant.fill_tau_s", p.fill_tau_s, 1e3)?;
        positive("plant.sealed_leak_tau_s", p.sealed_leak_tau_s, 1e9)?;
        positive("plant.deg_per_kpa", p.deg_per_kpa, 100.0)?;
        positive("plant.lever_mm", p.lever_mm, 1e3)?;
        positive("plant.stiffness_n_per_mm", p.stiffness_n_per_mm, 1e3)?;
        for (field, v) in [
            ("plant.roll_mm_per_deg", p.roll_mm_per_deg),
            ("plant.actuator_push_coupling", p.actuator_push_coupling),
            ("plant.actuator_roll_mm_per_n", p.actuator_roll_mm_per_n),
            ("plant.back_load_coupling", p.back_load_coupling),
            ("plant.back_twist_mm_per_n", p.back_twist_mm_per_n),
            ("plant.manip_deg_per_kpa", p.manip_deg_per_kpa),
            (
                "object.manip_creep_x_mm_per_deg",
                o.manip_creep_x_mm_per_deg,
            ),
        ] {
            non_negative(field, v)?;
        }
        for v in o.manip_roll_mm_per_deg {
            if !(v.is_finite() && v.abs() <= 10.0) {
                return Err(bad(
                    "object.manip_roll_mm_per_deg",
                    v.to_string(),
                    "must be finite, |v| <= 10",
                ));
            }
        }
        let t = &self.trajectory;
        for (field, v) in [
            ("trajectory.lift_at_s", t.lift_at_s),
            ("trajectory.move_at_s", t.move_at_s),
        ] {
            if let Some(v) = v {
                non_negative(field, v)?;
            }
        }
        non_negative("trajectory.lift_mm", t.lift_mm)?;
        non_negative("trajectory.move_mm", t.move_mm)?;
        positive("trajectory.lift_s", t.lift_s, 1e3)?;
        positive("trajectory.move_s", t.move_s, 1e3)?;
        for poke in &self.pokes {
            if poke.finger >= FINGER_COUNT {
                return Err(bad(
                    "poke.finger",
                    poke.finger.to_string(),
                    "must be 0 or 1",
                ));
            }
            non_negative("poke.at_s", poke.at_s)?;
            positive("poke.duration_s", poke.duration_s, 1e3)?;
            non_negative("poke.peak_n", poke.peak_n)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_loads() {
        for (name, _) in PRESETS {
            let s = Scenario::load(name).unwrap();
            assert_eq!(s.name, name);
        }
        assert!(Scenario::load(DEFAULT_SCENARIO).is_ok());
    }

    #[test]
    fn unknown_names_keys_and_values_are_typed_errors() {
        assert!(matches!(
            Scenario::load("no-such-scenario"),
            Err(ScenarioError::Unknown { .. })
        ));
        assert!(matches!(
            Scenario::from_toml_str(
                "[scenario]\nname = \"x\"\nduration_s = 1.0\ntypo = 3\n",
                "t"
            ),
            Err(ScenarioError::Parse(_))
        ));
        assert!(matches!(
            Scenario::from_toml_str("[scenario]\nname = \"x\"\nduration_s = -1.0\n", "t"),
            Err(ScenarioError::Invalid { .. })
        ));
        assert!(matches!(
            Scenario::from_toml_str(
                "[scenario]\nname = \"x\"\nduration_s = 1.0\n[[scenario.poke]]\ntarget = \"object\"\nfinger = 7\nat_s = 0.0\nduration_s = 1.0\npeak_n = 1.0\n",
                "t"
            ),
            Err(ScenarioError::Invalid { .. })
        ));
        assert!(matches!(
            Scenario::from_toml_str("[scenario]\nname = \"x\"\nduration_s = nan\n", "t"),
            Err(ScenarioError::Invalid { .. })
        ));
    }

    #[test]
    fn a_scenario_file_loads_by_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.toml");
        std::fs::write(
            &path,
            "[scenario]\nname = \"file\"\nduration_s = 2.0\nno_object = true\n[tanks]\npositive_kpa = 35.0\n",
        )
        .unwrap();
        let s = Scenario::load(path.to_str().unwrap()).unwrap();
        assert_eq!(s.name, "file");
        assert!(s.object().is_none());
        assert_eq!(s.rig.tanks.positive_kpa, 35.0);
    }
}
