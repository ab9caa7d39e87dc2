//! The simulated rig: everything the real gripper does, on the PC.
//!
//! [`mcu`] runs the firmware's own control core ([`dexitac_firmware::Controller`])
//! behind a pseudo-terminal, so the host reaches it through its normal
//! serial code path ([`crate::link`]).

pub mod mcu;
