//! The simulated gripper and object: actuator pressures -> finger closure ->
//! contact normal force -> grip, object held or dropped, contact centres.
//!
//! Stepped once per firmware control tick (1 ms of simulated time) by the
//! simulated MCU ([`crate::mcu`]), with the tank pressures of the
//! firmware's tank model and the valve outputs the firmware drives.
//!
//! # Model (explicit Euler, SI-like units in the names)
//!
//! - **Actuators.** Chamber `i` of finger `i / 4` (chamber 0 and 4 are the
//!   Rot joints, 1-3 and 5-7 the Dex bellows). An open inlet fills the
//!   chamber from the positive tank, an open outlet empties it into the
//!   negative tank, first order with [`PlantParams::fill_tau_s`] (the
//!   500 mm tube and the valve orifice); a sealed chamber leaks toward
//!   atmosphere with [`PlantParams::sealed_leak_tau_s`] (silicone bellows and
//!   push-in fittings). The firmware's own tank model still draws the air
//!   from the tanks.
//! - **Fingers.** Joint angle linear in the pressure difference to
//!   atmosphere (paper Fig. 6): `theta = deg_per_kpa * p`, with `p` the mean
//!   pressure of the finger's grasping chambers. The fingertip travels
//!   `lever_mm * theta` toward the object; it touches when that exceeds the
//!   gap, and the soft finger then presses with
//!   `stiffness_n_per_mm * (travel - gap)`.
//! - **Object.** Rests on the table until the lift starts; then its load
//!   (weight, inertia of the lift/move trajectory, poke forces) is carried by
//!   friction, capacity `mu * (F0 + F1)`. Below capacity the skin shears
//!   elastically (`load / 2 / shear_stiffness` per fingertip); above, the
//!   object slides at `slip_rate * (load - capacity)`. Sliding further than
//!   [`ObjectParams::drop_slide_mm`] (off the fingertip pads), or any load
//!   with no grip, drops it.
//! - **Pokes** (the paper's disturbance experiment): on the object (adds
//!   load), on a soft actuator (pushes that finger off the object: less
//!   normal force, its contact rolls), on the rigid back of a fingertip
//!   (twists the object: load and opposite rolls on both sensors).
//! - **Contact centres** in sensor mm (origin at the sensor centre, y along
//!   the load direction): the contact point on the skin plus the elastic
//!   tangential displacement plus the slide, plus a small roll with the
//!   joint angle.
//!
//! - **Manipulation** (issue 6): each finger's manipulation joint turns
//!   `manip_deg_per_kpa` per kPa of pressure difference between its two
//!   chambers ([`MANIPULATION_CHAMBERS`]); while both fingers touch it the
//!   object follows their mean angle ([`WorldState::object_deg`]), its
//!   contacts roll by [`ObjectParams::manip_roll_mm_per_deg`] per degree and
//!   creep in x by [`ObjectParams::manip_creep_x_mm_per_deg`] per degree of
//!   travel (a loose object; 0 by default).
//!
//! The coefficients are not measured on the real gripper; they are chosen
//! so that forces and shifts have the magnitudes of the paper's experiments
//! (a 100 g object, ~3 N pokes, shifts of 0.5-5 mm). All live in
//! [`PlantParams`], loadable from a scenario file.

use dexitac_protocol::{Chambers, ValveState, CHAMBER_COUNT};
use serde::Deserialize;

use dexitac_gripper::manipulation::MANIPULATION_CHAMBERS;

/// Standard gravity, m/s^2.
const GRAVITY_M_PER_S2: f64 = 9.81;
/// Chambers per finger.
pub const CHAMBERS_PER_FINGER: usize = 4;
/// Fingers (and tactile sensors): the gripper's.
pub use dexitac_gripper::configuration::FINGER_COUNT;

/// Gripper and actuator coefficients.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlantParams {
    /// Chamber fill/empty time constant through an open valve, s.
    pub fill_tau_s: f64,
    /// Leak time constant of a sealed chamber, s.
    pub sealed_leak_tau_s: f64,
    /// Joint angle per kPa of chamber pressure (paper Fig. 6: linear), deg/kPa.
    pub deg_per_kpa: f64,
    /// Fingertip travel per radian of joint angle, mm.
    pub lever_mm: f64,
    /// Normal force per mm of fingertip travel past the object surface, N/mm.
    pub stiffness_n_per_mm: f64,
    /// Contact centre roll per degree of joint angle past first touch, mm/deg.
    pub roll_mm_per_deg: f64,
    /// Normal force lost per newton of a poke on a soft actuator.
    pub actuator_push_coupling: f64,
    /// Contact roll per newton of a poke on a soft actuator, mm/N.
    pub actuator_roll_mm_per_n: f64,
    /// Tangential load per newton of a poke on the back of a fingertip.
    pub back_load_coupling: f64,
    /// Contact roll (object twist) per newton of a poke on the back of a fingertip, mm/N.
    pub back_twist_mm_per_n: f64,
    /// Manipulation joint angle per kPa of pressure difference between its
    /// two chambers ([`MANIPULATION_CHAMBERS`]), deg/kPa; 0: the joint does
    /// not move the object (the grasp scenarios).
    pub manip_deg_per_kpa: f64,
}

impl Default for PlantParams {
    fn default() -> Self {
        PlantParams {
            fill_tau_s: 1.2,
            sealed_leak_tau_s: 40.0,
            deg_per_kpa: 1.0,
            lever_mm: 40.0,
            stiffness_n_per_mm: 0.15,
            roll_mm_per_deg: 0.012,
            actuator_push_coupling: 0.5,
            actuator_roll_mm_per_n: 0.45,
            back_load_coupling: 0.8,
            back_twist_mm_per_n: 0.35,
            manip_deg_per_kpa: 0.0,
        }
    }
}

/// The grasped object.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObjectParams {
    /// Mass, kg.
    pub mass_kg: f64,
    /// Gap between each open fingertip and the object surface, mm.
    pub gap_mm: f64,
    /// Friction coefficient between skin and object.
    pub friction: f64,
    /// Tangential stiffness of one fingertip's skin, N/mm.
    pub shear_stiffness_n_per_mm: f64,
    /// Slide speed per newton of load above the friction capacity, mm/s/N.
    pub slip_rate_mm_per_s_per_n: f64,
    /// The object falls after sliding this far, mm.
    pub drop_slide_mm: f64,
    /// Where the contact lands on each sensor, mm from the sensor centre (x, y).
    pub contact_mm: [[f64; 2]; FINGER_COUNT],
    /// Contact patch width on the skin, mm.
    pub contact_width_mm: f64,
    /// Contact centre shift (x, y) per degree of object rotation by the
    /// manipulation joints, mm/deg (the object rolls on the pads).
    pub manip_roll_mm_per_deg: [f64; 2],
    /// Contact centre x creep per degree of manipulation travel (either
    /// direction): the object working loose, mm/deg.
    pub manip_creep_x_mm_per_deg: f64,
}

impl Default for ObjectParams {
    fn default() -> Self {
        ObjectParams {
            mass_kg: 0.1,
            gap_mm: 5.6,
            friction: 0.8,
            shear_stiffness_n_per_mm: 2.5,
            slip_rate_mm_per_s_per_n: 15.0,
            drop_slide_mm: 15.0,
            contact_mm: [[-1.5, -2.0], [2.0, -1.0]],
            contact_width_mm: 2.5,
            manip_roll_mm_per_deg: [0.0, 0.0],
            manip_creep_x_mm_per_deg: 0.0,
        }
    }
}

/// Where a poke pushes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PokeTarget {
    /// The object itself (along the load direction).
    Object,
    /// The soft actuator of a finger.
    Actuator,
    /// The rigid back of a fingertip.
    FingertipBack,
}

/// The force profile of a poke.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum PokeShape {
    /// Half a sine period over the duration (a hand-held rod's push).
    #[default]
    HalfSine,
    /// Linear rise over the first third, then held (a growing pull).
    RampHold,
}

/// An external force on the rig.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Poke {
    /// What is pushed.
    pub target: PokeTarget,
    /// Which finger (actuator and fingertip pokes), 0 or 1.
    #[serde(default)]
    pub finger: usize,
    /// Onset, s of simulated time.
    pub at_s: f64,
    /// Duration, s.
    pub duration_s: f64,
    /// Peak force, N.
    pub peak_n: f64,
    /// Profile.
    #[serde(default)]
    pub shape: PokeShape,
}

impl Poke {
    /// The force at time `t_s`, N.
    pub fn force_n(&self, t_s: f64) -> f64 {
        let u = (t_s - self.at_s) / self.duration_s.max(1e-6);
        if !(0.0..1.0).contains(&u) {
            return 0.0;
        }
        match self.shape {
            PokeShape::HalfSine => self.peak_n * (std::f64::consts::PI * u).sin(),
            PokeShape::RampHold => self.peak_n * (3.0 * u).min(1.0),
        }
    }
}

/// The arm's trajectory: lift, then move across (paper: 120 mm, 100 mm).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Trajectory {
    /// Lift start, s (None: the object is never lifted).
    pub lift_at_s: Option<f64>,
    /// Lift height, mm.
    pub lift_mm: f64,
    /// Lift duration, s.
    pub lift_s: f64,
    /// Move start, s.
    pub move_at_s: Option<f64>,
    /// Move distance, mm.
    pub move_mm: f64,
    /// Move duration, s.
    pub move_s: f64,
}

impl Default for Trajectory {
    fn default() -> Self {
        Trajectory {
            lift_at_s: None,
            lift_mm: 120.0,
            lift_s: 2.0,
            move_at_s: None,
            move_mm: 100.0,
            move_s: 2.0,
        }
    }
}

/// Minimum-jerk position, velocity and acceleration along a move of
/// `dist` starting at `t0` over `dur` (position units of `dist`, per s, per s^2).
fn min_jerk(t_s: f64, t0: f64, dur: f64, dist: f64) -> (f64, f64, f64) {
    let dur = dur.max(1e-3);
    let u = ((t_s - t0) / dur).clamp(0.0, 1.0);
    let moving = t_s > t0 && t_s < t0 + dur;
    let p = dist * (10.0 * u.powi(3) - 15.0 * u.powi(4) + 6.0 * u.powi(5));
    if !moving {
        return (p, 0.0, 0.0);
    }
    let v = dist / dur * (30.0 * u.powi(2) - 60.0 * u.powi(3) + 30.0 * u.powi(4));
    let a = dist / (dur * dur) * (60.0 * u - 180.0 * u.powi(2) + 120.0 * u.powi(3));
    (p, v, a)
}

impl Trajectory {
    /// Height and horizontal position of the gripper, mm, and its vertical
    /// acceleration, m/s^2.
    pub fn at(&self, t_s: f64) -> (f64, f64, f64) {
        let (z, _, az) = self.lift_at_s.map_or((0.0, 0.0, 0.0), |t0| {
            min_jerk(t_s, t0, self.lift_s, self.lift_mm)
        });
        let (x, _, _) = self.move_at_s.map_or((0.0, 0.0, 0.0), |t0| {
            min_jerk(t_s, t0, self.move_s, self.move_mm)
        });
        (z, x, az / 1000.0)
    }

    /// Whether the lift has begun at `t_s`.
    pub fn lifting(&self, t_s: f64) -> bool {
        self.lift_at_s.is_some_and(|t0| t_s >= t0)
    }
}

/// Where the object is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ObjectState {
    /// No object in this scenario.
    Absent,
    /// Between the fingers (on the table or lifted).
    InGrasp,
    /// Fell out of the grasp.
    Dropped,
}

/// One fingertip contact as the tactile renderer needs it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactState {
    /// Contact centre on the sensor, mm from the sensor centre.
    pub centre_mm: [f64; 2],
    /// Stretch of the skin under the contact, mm, rendered as the press's
    /// shear. The plant leaves it at zero: the tactile pipeline's hybrid
    /// centre reads a stretched skin's shear as a shift several times its
    /// size (2.5 px of shear moved the centre by ~9 px in a simulated run),
    /// so the lift alone would look like a disturbance.
    pub shear_mm: [f64; 2],
    /// Normal force, N.
    pub normal_n: f64,
    /// Patch width, mm.
    pub width_mm: f64,
}

/// Everything observable about the world at one instant.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldState {
    /// Simulated time, ms.
    pub t_ms: u64,
    /// Chamber pressures, kPa.
    pub chambers_kpa: [f64; CHAMBER_COUNT],
    /// Valve outputs driven by the firmware.
    pub valves: Chambers,
    /// Tank pressures (positive, negative), kPa.
    pub tanks_kpa: (f64, f64),
    /// Joint angle of each finger's grasp, deg.
    pub finger_deg: [f64; FINGER_COUNT],
    /// Contact on each fingertip, if touching.
    pub contacts: [Option<ContactState>; FINGER_COUNT],
    /// The object.
    pub object: ObjectState,
    /// Slide of the object in the grasp, mm.
    pub slide_mm: f64,
    /// Friction capacity, N.
    pub capacity_n: f64,
    /// Tangential load, N.
    pub load_n: f64,
    /// Total external (poke) force, N.
    pub external_n: f64,
    /// Gripper height and horizontal position, mm.
    pub gripper_mm: (f64, f64),
    /// Manipulation joint angle of each finger, deg.
    pub manip_deg: [f64; FINGER_COUNT],
    /// Object rotation by the manipulation joints, deg (it follows the
    /// fingers' mean manipulation angle while both touch it).
    pub object_deg: f64,
    /// Accumulated x creep of the contacts, mm.
    pub creep_x_mm: f64,
}

/// The world: actuators, fingers, object and pokes.
#[derive(Debug, Clone)]
pub struct Plant {
    params: PlantParams,
    object: Option<ObjectParams>,
    grasp_chambers: Vec<usize>,
    trajectory: Trajectory,
    pokes: Vec<Poke>,
    state: WorldState,
    trace_period_ms: u64,
    trace: Vec<WorldState>,
    transitions: Vec<(u64, Chambers)>,
    dropped_at_ms: Option<u64>,
}

impl Plant {
    /// A world at rest at t = 0 (chambers at atmosphere, fingers open).
    /// `grasp_chambers` close the fingers when inflated.
    pub fn new(
        params: PlantParams,
        object: Option<ObjectParams>,
        grasp_chambers: &[usize],
        trajectory: Trajectory,
        pokes: Vec<Poke>,
    ) -> Self {
        let state = WorldState {
            t_ms: 0,
            chambers_kpa: [0.0; CHAMBER_COUNT],
            valves: [ValveState::Hold; CHAMBER_COUNT],
            tanks_kpa: (0.0, 0.0),
            finger_deg: [0.0; FINGER_COUNT],
            contacts: [None; FINGER_COUNT],
            object: if object.is_some() {
                ObjectState::InGrasp
            } else {
                ObjectState::Absent
            },
            slide_mm: 0.0,
            capacity_n: 0.0,
            load_n: 0.0,
            external_n: 0.0,
            gripper_mm: (0.0, 0.0),
            manip_deg: [0.0; FINGER_COUNT],
            object_deg: 0.0,
            creep_x_mm: 0.0,
        };
        Plant {
            params,
            object,
            grasp_chambers: grasp_chambers
                .iter()
                .copied()
                .filter(|&c| c < CHAMBER_COUNT)
                .collect(),
            trajectory,
            pokes,
            state,
            trace_period_ms: 0,
            trace: Vec::new(),
            transitions: Vec::new(),
            dropped_at_ms: None,
        }
    }

    /// Records the state every `period_ms` of simulated time (0: never).
    pub fn with_trace(mut self, period_ms: u64) -> Self {
        self.trace_period_ms = period_ms;
        self
    }

    /// The recorded states, oldest first.
    pub fn trace(&self) -> &[WorldState] {
        &self.trace
    }

    /// Every change of the valve outputs: (time, new outputs), ms.
    pub fn transitions(&self) -> &[(u64, Chambers)] {
        &self.transitions
    }

    /// When the object fell out of the grasp, ms.
    pub fn dropped_at_ms(&self) -> Option<u64> {
        self.dropped_at_ms
    }

    /// The current state.
    pub fn state(&self) -> &WorldState {
        &self.state
    }

    /// The pokes of this world.
    pub fn pokes(&self) -> &[Poke] {
        &self.pokes
    }

    /// Advances by `dt_ms` to `t_ms` with the firmware's outputs.
    pub fn step(&mut self, t_ms: u64, dt_ms: u32, tanks_pa: (i32, i32), valves: &Chambers) {
        if *valves != self.state.valves {
            self.transitions.push((t_ms, *valves));
        }
        self.advance(t_ms, dt_ms, tanks_pa, valves);
        if self.state.object == ObjectState::Dropped && self.dropped_at_ms.is_none() {
            self.dropped_at_ms = Some(t_ms);
        }
        if self.trace_period_ms > 0 && t_ms % self.trace_period_ms == 0 {
            self.trace.push(self.state.clone());
        }
    }

    fn advance(&mut self, t_ms: u64, dt_ms: u32, tanks_pa: (i32, i32), valves: &Chambers) {
        let dt_s = f64::from(dt_ms) / 1e3;
        let t_s = t_ms as f64 / 1e3;
        let p = &self.params;
        let s = &mut self.state;
        s.t_ms = t_ms;
        s.valves = *valves;
        s.tanks_kpa = (f64::from(tanks_pa.0) / 1e3, f64::from(tanks_pa.1) / 1e3);
        for (pressure, valve) in s.chambers_kpa.iter_mut().zip(valves) {
            let (goal, tau) = match valve {
                ValveState::Inflate => (s.tanks_kpa.0, p.fill_tau_s),
                ValveState::Deflate => (s.tanks_kpa.1, p.fill_tau_s),
                ValveState::Hold => (0.0, p.sealed_leak_tau_s),
            };
            *pressure += (goal - *pressure) * (dt_s / tau.max(dt_s));
        }
        let pokes: Vec<(Poke, f64)> = self
            .pokes
            .iter()
            .map(|k| (*k, k.force_n(t_s)))
            .filter(|(_, f)| *f != 0.0)
            .collect();
        s.external_n = pokes.iter().map(|(_, f)| f).sum();
        let (z, x, az) = self.trajectory.at(t_s);
        s.gripper_mm = (z, x);
        for (f, [a, b]) in MANIPULATION_CHAMBERS.into_iter().enumerate() {
            s.finger_deg[f] =
                p.deg_per_kpa * finger_pressure_kpa(&s.chambers_kpa, &self.grasp_chambers, f);
            s.manip_deg[f] = p.manip_deg_per_kpa * (s.chambers_kpa[a] - s.chambers_kpa[b]);
        }
        let Some(obj) = &self.object else {
            s.contacts = [None; FINGER_COUNT];
            return;
        };
        if s.object != ObjectState::InGrasp {
            s.contacts = [None; FINGER_COUNT];
            return;
        }
        // Normal forces and poke effects per finger.
        let mut normal_n = [0.0; FINGER_COUNT];
        let mut roll_mm = [[0.0; 2]; FINGER_COUNT];
        let mut extra_load_n = 0.0;
        for f in 0..FINGER_COUNT {
            let travel_mm = p.lever_mm * s.finger_deg[f].to_radians();
            normal_n[f] = p.stiffness_n_per_mm * (travel_mm - obj.gap_mm);
            let touch_deg = (obj.gap_mm / p.lever_mm).to_degrees();
            roll_mm[f][0] = p.roll_mm_per_deg * (s.finger_deg[f] - touch_deg).max(0.0);
        }
        for (poke, force_n) in &pokes {
            let f = poke.finger.min(FINGER_COUNT - 1);
            match poke.target {
                PokeTarget::Object => extra_load_n += force_n,
                PokeTarget::Actuator => {
                    normal_n[f] -= p.actuator_push_coupling * force_n;
                    roll_mm[f][0] += p.actuator_roll_mm_per_n * force_n;
                }
                PokeTarget::FingertipBack => {
                    extra_load_n += p.back_load_coupling * force_n;
                    roll_mm[f][0] -= p.back_twist_mm_per_n * force_n;
                    roll_mm[1 - f][0] += p.back_twist_mm_per_n * force_n;
                }
            }
        }
        let touching: Vec<bool> = normal_n.iter().map(|&n| n > 0.0).collect();
        let grip_n: f64 = normal_n.iter().map(|n| n.max(0.0)).sum();
        s.capacity_n = obj.friction * grip_n;
        let lifted = self.trajectory.lifting(t_s);
        s.load_n = if lifted {
            (obj.mass_kg * (GRAVITY_M_PER_S2 + az) + extra_load_n).max(0.0)
        } else {
            // On the table: the table carries the weight and the pokes.
            0.0
        };
        let both = touching.iter().all(|&t| t);
        if lifted && (!both || s.load_n > s.capacity_n) {
            let excess_n = if both {
                s.load_n - s.capacity_n
            } else {
                s.load_n.max(1.0)
            };
            s.slide_mm += obj.slip_rate_mm_per_s_per_n * excess_n * dt_s;
        }
        if s.slide_mm > obj.drop_slide_mm {
            s.object = ObjectState::Dropped;
            s.contacts = [None; FINGER_COUNT];
            return;
        }
        if both {
            let deg = s.manip_deg.iter().sum::<f64>() / FINGER_COUNT as f64;
            s.creep_x_mm += obj.manip_creep_x_mm_per_deg * (deg - s.object_deg).abs();
            s.object_deg = deg;
        }
        let manip_roll_mm = obj.manip_roll_mm_per_deg.map(|k| k * s.object_deg);
        let carried_n = s.load_n.min(s.capacity_n);
        let shear_mm = if both {
            carried_n / 2.0 / obj.shear_stiffness_n_per_mm.max(1e-6)
        } else {
            0.0
        };
        for f in 0..FINGER_COUNT {
            s.contacts[f] = touching[f].then(|| {
                let base = obj.contact_mm[f];
                ContactState {
                    centre_mm: [
                        base[0] + roll_mm[f][0] + manip_roll_mm[0] + s.creep_x_mm,
                        base[1] + s.slide_mm + shear_mm + roll_mm[f][1] + manip_roll_mm[1],
                    ],
                    // The tangential displacement moves the press on the
                    // skin (the object rolls on the soft pad); no separate
                    // skin stretch is rendered (see `ContactState::shear_mm`).
                    shear_mm: [0.0, 0.0],
                    normal_n: normal_n[f],
                    width_mm: obj.contact_width_mm,
                }
            });
        }
    }
}

/// Mean pressure of finger `f`'s grasping chambers, kPa (0 if it has none).
fn finger_pressure_kpa(chambers_kpa: &[f64; CHAMBER_COUNT], grasp: &[usize], f: usize) -> f64 {
    let mine: Vec<f64> = grasp
        .iter()
        .filter(|&&c| c / CHAMBERS_PER_FINGER == f)
        .filter_map(|&c| chambers_kpa.get(c).copied())
        .collect();
    if mine.is_empty() {
        0.0
    } else {
        mine.iter().sum::<f64>() / mine.len() as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const GRASP: [usize; 4] = [0, 1, 4, 5];

    fn inflate() -> Chambers {
        let mut c = [ValveState::Hold; CHAMBER_COUNT];
        for i in GRASP {
            c[i] = ValveState::Inflate;
        }
        c
    }

    fn run(plant: &mut Plant, from_ms: u64, to_ms: u64, valves: &Chambers) {
        for t in from_ms + 1..=to_ms {
            plant.step(t, 1, (40_000, -45_000), valves);
        }
    }

    #[test]
    fn inflating_the_grasp_chambers_closes_the_fingers_onto_the_object() {
        let mut plant = Plant::new(
            PlantParams::default(),
            Some(ObjectParams::default()),
            &GRASP,
            Trajectory::default(),
            vec![],
        );
        run(&mut plant, 0, 3_000, &inflate());
        let s = plant.state();
        assert!(s
            .contacts
            .iter()
            .all(|c| c.is_some_and(|c| c.normal_n > 1.0)));
        assert!(s.finger_deg[0] > 20.0);
    }

    #[test]
    fn a_sealed_grip_holds_the_lifted_object_and_no_grip_drops_it() {
        let trajectory = Trajectory {
            lift_at_s: Some(4.0),
            ..Trajectory::default()
        };
        let mut held = Plant::new(
            PlantParams::default(),
            Some(ObjectParams::default()),
            &GRASP,
            trajectory.clone(),
            vec![],
        );
        run(&mut held, 0, 3_500, &inflate());
        run(&mut held, 3_500, 8_000, &[ValveState::Hold; CHAMBER_COUNT]);
        assert_eq!(held.state().object, ObjectState::InGrasp);
        let mut open = Plant::new(
            PlantParams::default(),
            Some(ObjectParams::default()),
            &GRASP,
            trajectory,
            vec![],
        );
        run(&mut open, 0, 8_000, &[ValveState::Hold; CHAMBER_COUNT]);
        assert_eq!(open.state().object, ObjectState::Dropped);
    }

    #[test]
    fn poke_profiles_start_and_end_at_zero() {
        let poke = Poke {
            target: PokeTarget::Object,
            finger: 0,
            at_s: 1.0,
            duration_s: 0.5,
            peak_n: 3.0,
            shape: PokeShape::HalfSine,
        };
        assert_eq!(poke.force_n(0.99), 0.0);
        assert!((poke.force_n(1.25) - 3.0).abs() < 1e-9);
        assert_eq!(poke.force_n(1.5), 0.0);
    }

    fn valve() -> impl Strategy<Value = ValveState> {
        prop_oneof![
            Just(ValveState::Hold),
            Just(ValveState::Inflate),
            Just(ValveState::Deflate)
        ]
    }

    fn poke() -> impl Strategy<Value = Poke> {
        (
            0..3usize,
            0..2usize,
            0.0..8.0f64,
            0.05..3.0f64,
            0.0..20.0f64,
            any::<bool>(),
        )
            .prop_map(|(target, finger, at_s, duration_s, peak_n, ramp)| Poke {
                target: [
                    PokeTarget::Object,
                    PokeTarget::Actuator,
                    PokeTarget::FingertipBack,
                ][target],
                finger,
                at_s,
                duration_s,
                peak_n,
                shape: if ramp {
                    PokeShape::RampHold
                } else {
                    PokeShape::HalfSine
                },
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Any valve sequence, step size and pokes: pressures stay between
        /// the tanks' (and atmosphere), every output is finite, the slide
        /// only grows and a dropped object stays dropped.
        #[test]
        fn the_plant_stays_bounded_and_finite(
            steps in proptest::collection::vec(
                (proptest::array::uniform8(valve()), 1u32..=10, 0..200u32), 1..40),
            pokes in proptest::collection::vec(poke(), 0..4),
            lift_at_s in proptest::option::of(0.0..5.0f64),
        ) {
            let trajectory = Trajectory { lift_at_s, ..Trajectory::default() };
            let mut plant = Plant::new(
                PlantParams::default(),
                Some(ObjectParams::default()),
                &GRASP,
                trajectory,
                pokes,
            );
            let (pos_pa, neg_pa) = (45_000, -50_000);
            let mut t = 0;
            let mut slide = 0.0;
            let mut dropped = false;
            for (valves, dt_ms, repeat) in steps {
                for _ in 0..repeat {
                    t += u64::from(dt_ms);
                    plant.step(t, dt_ms, (pos_pa, neg_pa), &valves);
                    let s = plant.state();
                    for p in s.chambers_kpa {
                        prop_assert!(p.is_finite() && (-50.0 - 1e-9..=45.0 + 1e-9).contains(&p), "{p}");
                    }
                    prop_assert!(s.slide_mm.is_finite() && s.slide_mm >= slide);
                    slide = s.slide_mm;
                    prop_assert!(s.capacity_n.is_finite() && s.capacity_n >= 0.0);
                    prop_assert!(s.load_n.is_finite() && s.load_n >= 0.0);
                    for c in s.contacts.iter().flatten() {
                        prop_assert!(c.centre_mm.iter().all(|v| v.is_finite()));
                        prop_assert!(c.normal_n > 0.0 && c.normal_n.is_finite());
                    }
                    if dropped {
                        prop_assert_eq!(s.object, ObjectState::Dropped);
                        prop_assert!(s.contacts.iter().all(Option::is_none));
                    }
                    dropped = s.object == ObjectState::Dropped;
                }
            }
        }
    }

    #[test]
    fn min_jerk_reaches_the_distance() {
        let (p, v, _) = min_jerk(3.0, 1.0, 2.0, 120.0);
        assert!((p - 120.0).abs() < 1e-9 && v == 0.0);
        let (p, _, _) = min_jerk(2.0, 1.0, 2.0, 120.0);
        assert!((p - 60.0).abs() < 1e-9);
    }
}
