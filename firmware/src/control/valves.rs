//! The valve bank: chamber states -> the 16 valve outputs, with a dead time
//! between one valve of a chamber closing and the other opening.
//!
//! # Dead time
//!
//! A solenoid valve does not close when its coil is switched off: the
//! armature takes its *release time* to return (the paper: the valves
//! respond in more than 10 ms; small 2/2 solenoid valves of this class
//! release in about 5..20 ms). Writing "outlet off, inlet on" in one go
//! therefore joins the two tanks through the chamber for that time.
//! [`ValveDriver`] lets a chamber's inlet open only after its outlet has been
//! *commanded* closed for at least the dead time, and the reverse
//! ([`crate::Config::valve_dead_time_ms`], default
//! [`crate::control::DEFAULT_VALVE_DEAD_TIME_MS`] = 30 ms: the 20 ms worst
//! case of the class plus 50 %). Closing is never delayed. The property test
//! `inlet_and_outlet_never_physically_open_together` checks it against a
//! valve model that releases 5..25 ms late.
//!
//! # Levels
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

/// Drives the chambers' valves toward the desired states, never opening a
/// valve before the other valve of its chamber has been commanded closed
/// for the dead time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ValveDriver {
    driven: Chambers,
    /// When each chamber's inlet was last commanded closed, ms.
    inlet_closed_at_ms: [u32; CHAMBER_COUNT],
    /// When each chamber's outlet was last commanded closed, ms.
    outlet_closed_at_ms: [u32; CHAMBER_COUNT],
    /// The first [`ValveDriver::drive`] has run (before it, the valves may
    /// still be releasing from before a reset: every valve counts as closed
    /// at the time of the first call).
    started: bool,
}

impl Default for ValveDriver {
    fn default() -> Self {
        Self::new()
    }
}

impl ValveDriver {
    /// Every valve closed.
    pub const fn new() -> Self {
        ValveDriver {
            driven: SAFE_CHAMBERS,
            inlet_closed_at_ms: [0; CHAMBER_COUNT],
            outlet_closed_at_ms: [0; CHAMBER_COUNT],
            started: false,
        }
    }

    /// The states driven at the last call.
    pub const fn driven(&self) -> Chambers {
        self.driven
    }

    /// The states to drive now for `desired`: closing at once, opening only
    /// after the chamber's other valve has been closed for `dead_time_ms`.
    /// A chamber waiting for its dead time is held ([`ValveState::Hold`]).
    pub fn drive(&mut self, desired: &Chambers, now_ms: u32, dead_time_ms: u32) -> Chambers {
        if !self.started {
            self.started = true;
            self.inlet_closed_at_ms = [now_ms; CHAMBER_COUNT];
            self.outlet_closed_at_ms = [now_ms; CHAMBER_COUNT];
        }
        let chambers = self
            .driven
            .iter_mut()
            .zip(desired)
            .zip(self.inlet_closed_at_ms.iter_mut())
            .zip(self.outlet_closed_at_ms.iter_mut());
        for (((driven, want), inlet_closed_at), outlet_closed_at) in chambers {
            // Close first: a valve not wanted open is closed now.
            if driven.inlet_open() && !want.inlet_open() {
                *inlet_closed_at = now_ms;
                *driven = ValveState::Hold;
            }
            if driven.outlet_open() && !want.outlet_open() {
                *outlet_closed_at = now_ms;
                *driven = ValveState::Hold;
            }
            // Then open, if the other valve has been closed long enough.
            let since_outlet = now_ms.wrapping_sub(*outlet_closed_at);
            let since_inlet = now_ms.wrapping_sub(*inlet_closed_at);
            match want {
                ValveState::Inflate if !driven.outlet_open() && since_outlet >= dead_time_ms => {
                    *driven = ValveState::Inflate;
                }
                ValveState::Deflate if !driven.inlet_open() && since_inlet >= dead_time_ms => {
                    *driven = ValveState::Deflate;
                }
                _ => {}
            }
        }
        self.driven
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
    fn switching_sides_holds_for_the_dead_time() {
        let mut d = ValveDriver::new();
        let inflate = [ValveState::Inflate; CHAMBER_COUNT];
        // Nothing opens within the dead time after start (a valve may still
        // be releasing from before a reset).
        assert_eq!(d.drive(&inflate, 100, 30), SAFE_CHAMBERS);
        assert_eq!(d.drive(&inflate, 130, 30), inflate);
        // Inflate -> deflate: inlet closes at 200, outlet opens at 230.
        for t in 200..230 {
            assert_eq!(d.drive(&VENT_CHAMBERS, t, 30), SAFE_CHAMBERS, "t = {t}");
        }
        assert_eq!(d.drive(&VENT_CHAMBERS, 230, 30), VENT_CHAMBERS);
        // Hold closes at once.
        assert_eq!(d.drive(&SAFE_CHAMBERS, 231, 30), SAFE_CHAMBERS);
        // The same valve may reopen at once; the other one may not.
        assert_eq!(d.drive(&VENT_CHAMBERS, 232, 30), VENT_CHAMBERS);
        assert_eq!(d.drive(&inflate, 233, 30), SAFE_CHAMBERS);
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
