//! A simulated pair of buffer tanks with their pumps and the 8 chambers, in
//! place of the real sensors (QEMU build, host simulator, tests).
//!
//! First-order model, integer arithmetic in millipascal, explicit Euler
//! steps of whole milliseconds:
//!
//! - a running pump drives its tank toward the pump's stall pressure with
//!   time constant [`TankModelParams::pump_tau_ms`];
//! - each tank leaks toward 0 kPa (atmosphere) with
//!   [`TankModelParams::leak_tau_ms`];
//! - an open inlet moves air from the positive tank into the chamber, an
//!   open outlet from the chamber into the negative tank, with
//!   [`TankModelParams::valve_tau_ms`]; the tank changes by the chamber's
//!   change times the volume ratio (a 5 ml chamber on a 200 ml tank). The
//!   valves are given as [`ValveLevels`], which *can* have a chamber's inlet
//!   and outlet open together (a valve still releasing): air then flows from
//!   the positive tank through the chamber into the negative one.
//!
//! Stable for any step `dt_ms <= tau` (each update moves a pressure at most
//! the whole way to its goal); [`TankModel::advance`] splits longer steps.

use dexitac_protocol::{Chambers, CHAMBER_COUNT};

use crate::control::valves::ValveLevels;
use crate::control::PumpOutputs;

/// Parameters of the [`TankModel`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TankModelParams {
    /// Stall pressure of the positive pump, in pascal.
    pub positive_stall_pa: i32,
    /// Stall pressure of the negative pump, in pascal.
    pub negative_stall_pa: i32,
    /// Time constant of the running positive pump, in milliseconds.
    pub pump_tau_ms: u32,
    /// Time constant of the running negative pump, in milliseconds.
    pub negative_pump_tau_ms: u32,
    /// Time constant of the tanks' leak, in milliseconds.
    pub leak_tau_ms: u32,
    /// Time constant of a chamber filling through an open valve, in milliseconds.
    pub valve_tau_ms: u32,
    /// Tank volume over chamber volume (200 ml / 5 ml).
    pub tank_to_chamber_volume: u32,
}

impl Default for TankModelParams {
    fn default() -> Self {
        TankModelParams {
            positive_stall_pa: 80_000,
            negative_stall_pa: -85_000,
            pump_tau_ms: 4_000,
            negative_pump_tau_ms: 4_000,
            leak_tau_ms: 120_000,
            valve_tau_ms: 150,
            tank_to_chamber_volume: 40,
        }
    }
}

/// The simulated tanks and chambers.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TankModel {
    params: TankModelParams,
    positive_mpa: i64,
    negative_mpa: i64,
    chambers_mpa: [i64; CHAMBER_COUNT],
}

const MPA_PER_PA: i64 = 1000;

/// `value` moved toward `goal` by `dt / tau` of the distance (never past it).
fn relax(value: i64, goal: i64, dt_ms: u32, tau_ms: u32) -> i64 {
    let tau = i64::from(tau_ms.max(1));
    let dt = i64::from(dt_ms).min(tau);
    value + (goal - value) * dt / tau
}

impl TankModel {
    /// Both tanks and every chamber at 0 kPa (atmosphere).
    pub fn new(params: TankModelParams) -> Self {
        TankModel {
            params,
            positive_mpa: 0,
            negative_mpa: 0,
            chambers_mpa: [0; CHAMBER_COUNT],
        }
    }

    /// The tank pressures in pascal: (positive, negative).
    pub fn tanks_pa(&self) -> (i32, i32) {
        (to_pa(self.positive_mpa), to_pa(self.negative_mpa))
    }

    /// The pressure of chamber `index` in pascal, if it exists.
    pub fn chamber_pa(&self, index: usize) -> Option<i32> {
        self.chambers_mpa.get(index).map(|&mpa| to_pa(mpa))
    }

    /// Advances the model by `dt_ms` with the given outputs (valves open
    /// exactly as the chamber states say).
    pub fn advance(&mut self, dt_ms: u32, pumps: PumpOutputs, chambers: &Chambers) {
        self.advance_levels(dt_ms, pumps, ValveLevels::from_chambers(chambers));
    }

    /// Advances the model by `dt_ms` with the valves physically open as
    /// `valves` says (inlet and outlet of a chamber may be open together).
    pub fn advance_levels(&mut self, dt_ms: u32, pumps: PumpOutputs, valves: ValveLevels) {
        let mut left = dt_ms;
        let max_step = self.params.valve_tau_ms.clamp(1, 10);
        while left > 0 {
            let step = left.min(max_step);
            self.step(step, pumps, valves);
            left -= step;
        }
    }

    fn step(&mut self, dt_ms: u32, pumps: PumpOutputs, valves: ValveLevels) {
        let p = self.params;
        let ratio = i64::from(p.tank_to_chamber_volume.max(1));
        for (i, chamber) in self.chambers_mpa.iter_mut().enumerate() {
            let bit = 1u8 << i;
            let sources = [
                (valves.inlets & bit != 0, &mut self.positive_mpa),
                (valves.outlets & bit != 0, &mut self.negative_mpa),
            ];
            for (open, source) in sources {
                if open {
                    let before = *chamber;
                    *chamber = relax(before, *source, dt_ms, p.valve_tau_ms);
                    *source -= (*chamber - before) / ratio;
                }
            }
        }
        if pumps.positive_on {
            let goal = i64::from(p.positive_stall_pa) * MPA_PER_PA;
            self.positive_mpa = relax(self.positive_mpa, goal, dt_ms, p.pump_tau_ms);
        }
        if pumps.negative_on {
            let goal = i64::from(p.negative_stall_pa) * MPA_PER_PA;
            self.negative_mpa = relax(self.negative_mpa, goal, dt_ms, p.negative_pump_tau_ms);
        }
        self.positive_mpa = relax(self.positive_mpa, 0, dt_ms, p.leak_tau_ms);
        self.negative_mpa = relax(self.negative_mpa, 0, dt_ms, p.leak_tau_ms);
    }
}

fn to_pa(mpa: i64) -> i32 {
    // Pressures stay between the stall pressures, far inside i32.
    i32::try_from(mpa / MPA_PER_PA).unwrap_or(if mpa < 0 { i32::MIN } else { i32::MAX })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::valves::SAFE_CHAMBERS;
    use dexitac_protocol::ValveState;

    fn chambers_strategy() -> impl proptest::strategy::Strategy<Value = Chambers> {
        use proptest::prelude::*;
        proptest::array::uniform8(prop_oneof![
            Just(ValveState::Hold),
            Just(ValveState::Inflate),
            Just(ValveState::Deflate)
        ])
    }

    proptest::proptest! {
        /// Numerical stability: whatever the outputs and step lengths, every
        /// pressure stays between the two stall pressures.
        #[test]
        fn pressures_stay_between_the_stall_pressures(
            steps in proptest::collection::vec(
                (0u32..2_000, proptest::bool::ANY, proptest::bool::ANY, chambers_strategy()),
                1..30,
            )
        ) {
            let params = TankModelParams::default();
            let mut m = TankModel::new(params);
            let range = params.negative_stall_pa..=params.positive_stall_pa;
            for (dt_ms, positive_on, negative_on, chambers) in steps {
                m.advance(dt_ms, PumpOutputs { positive_on, negative_on }, &chambers);
                let (p, n) = m.tanks_pa();
                proptest::prop_assert!(range.contains(&p), "positive tank {}", p);
                proptest::prop_assert!(range.contains(&n), "negative tank {}", n);
                for i in 0..CHAMBER_COUNT {
                    let c = m.chamber_pa(i).unwrap();
                    proptest::prop_assert!(range.contains(&c), "chamber {} at {}", i, c);
                }
            }
        }
    }

    #[test]
    fn a_chamber_open_both_ways_joins_the_tanks() {
        let mut m = TankModel::new(TankModelParams::default());
        let on = PumpOutputs {
            positive_on: true,
            negative_on: true,
        };
        m.advance(3_000, on, &SAFE_CHAMBERS);
        let (p0, n0) = m.tanks_pa();
        let both = ValveLevels {
            inlets: 0xFF,
            outlets: 0xFF,
        };
        m.advance_levels(500, PumpOutputs::OFF, both);
        let (p1, n1) = m.tanks_pa();
        assert!(p1 < p0 - 5_000 && n1 > n0 + 5_000, "{p0} {n0} -> {p1} {n1}");
    }

    #[test]
    fn running_pump_raises_its_tank_toward_stall() {
        let mut m = TankModel::new(TankModelParams::default());
        let on = PumpOutputs {
            positive_on: true,
            negative_on: true,
        };
        m.advance(1_000, on, &SAFE_CHAMBERS);
        let (pos, neg) = m.tanks_pa();
        assert!(pos > 10_000 && pos < 80_000, "{pos}");
        assert!(neg < -10_000 && neg > -85_000, "{neg}");
    }

    #[test]
    fn inflating_chamber_draws_from_the_positive_tank() {
        let mut m = TankModel::new(TankModelParams::default());
        let on = PumpOutputs {
            positive_on: true,
            negative_on: false,
        };
        m.advance(3_000, on, &SAFE_CHAMBERS);
        let before = m.tanks_pa().0;
        let mut chambers = SAFE_CHAMBERS;
        chambers[0] = ValveState::Inflate;
        m.advance(1_000, PumpOutputs::OFF, &chambers);
        let after = m.tanks_pa().0;
        let chamber = m.chamber_pa(0).unwrap();
        assert!(after < before, "{before} -> {after}");
        assert!((chamber - after).abs() < 1_000, "{chamber} vs {after}");
    }
}
