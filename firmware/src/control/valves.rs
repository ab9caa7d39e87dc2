//! The valve bank: chamber states -> the 16 valve outputs, break-before-make.
//!
//! Input: a [`Chambers`] array (one [`ValveState`] per chamber). Output:
//! [`ValveLevels`], one bit per inlet and per outlet valve (bit `i` =
//! chamber `i`, 1 = open / energised). Because a [`ValveState`] cannot say
//! "inlet and outlet open", `inlets & outlets == 0` holds for every value
//! built from one. When a chamber flips from inflate to deflate (or back),
//! [`ValveLevels::transition`] closes the old valve before opening the new
//! one, so even the few microseconds between two GPIO writes never connect
//! the two tanks.

use dexitac_protocol::{Chambers, ValveState, CHAMBER_COUNT};

// One bit per chamber in a u8.
const _: () = assert!(CHAMBER_COUNT <= 8, "ValveLevels holds at most 8 chambers");

/// The safe valve state: every chamber sealed (all 16 valves closed).
pub const SAFE_CHAMBERS: Chambers = [ValveState::Hold; CHAMBER_COUNT];

/// Every chamber deflating (all outlets open): [`dexitac_protocol::HostMsg::VentAll`].
pub const VENT_CHAMBERS: Chambers = [ValveState::Deflate; CHAMBER_COUNT];

/// The levels of the 16 valve outputs: bit `i` is chamber `i`'s valve.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ValveLevels {
    /// Open inlet valves (chamber inflates from the positive tank).
    pub inlets: u8,
    /// Open outlet valves (chamber deflates into the negative tank).
    pub outlets: u8,
}

impl ValveLevels {
    /// All valves closed.
    pub const CLOSED: ValveLevels = ValveLevels {
        inlets: 0,
        outlets: 0,
    };

    /// The valve levels for `chambers`.
    pub fn from_chambers(chambers: &Chambers) -> ValveLevels {
        chambers
            .iter()
            .enumerate()
            .fold(ValveLevels::CLOSED, |levels, (i, state)| {
                let bit = 1u8 << i;
                ValveLevels {
                    inlets: levels.inlets | if state.inlet_open() { bit } else { 0 },
                    outlets: levels.outlets | if state.outlet_open() { bit } else { 0 },
                }
            })
    }

    /// Whether some chamber has its inlet and outlet open together (never
    /// true for levels built by this module).
    pub const fn shorts_tanks(self) -> bool {
        self.inlets & self.outlets != 0
    }

    /// The two steps to go from `self` to `to` break-before-make: first the
    /// valves open in both (every valve that must close is closed), then
    /// `to`. Write them in this order.
    pub const fn transition(self, to: ValveLevels) -> [ValveLevels; 2] {
        let closed_first = ValveLevels {
            inlets: self.inlets & to.inlets,
            outlets: self.outlets & to.outlets,
        };
        [closed_first, to]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inflate_opens_only_the_inlet() {
        let mut chambers = SAFE_CHAMBERS;
        chambers[3] = ValveState::Inflate;
        chambers[5] = ValveState::Deflate;
        let levels = ValveLevels::from_chambers(&chambers);
        assert_eq!(levels.inlets, 1 << 3);
        assert_eq!(levels.outlets, 1 << 5);
        assert!(!levels.shorts_tanks());
    }

    #[test]
    fn safe_state_closes_every_valve() {
        assert_eq!(
            ValveLevels::from_chambers(&SAFE_CHAMBERS),
            ValveLevels::CLOSED
        );
    }

    #[test]
    fn inflate_to_deflate_closes_inlet_before_opening_outlet() {
        let from = ValveLevels::from_chambers(&[ValveState::Inflate; CHAMBER_COUNT]);
        let to = ValveLevels::from_chambers(&VENT_CHAMBERS);
        let [first, second] = from.transition(to);
        assert_eq!(first, ValveLevels::CLOSED);
        assert_eq!(second, to);
    }
}
