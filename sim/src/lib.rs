//! The simulated rig: everything the real gripper does, on the PC.
//!
//! - [`mcu`] runs the firmware's own control core
//!   ([`dexitac_firmware::Controller`]) behind a pseudo-terminal, so the host
//!   reaches it through its normal serial code path ([`dexitac_rig::link`]), and
//!   steps the [`plant`] (actuators, fingers, object, pokes) on every tick.
//! - [`render`] draws each fingertip's marker frame from the plant's contact.
//! - [`scenario`] loads the scenarios (TOML, with embedded presets).
//! - [`rig`] wires them to the host's task loop ([`dexitac_rig::task_loop`]) and
//!   records what happened ([`rig::SimReport`]); [`output`] writes its text
//!   files (`dexitac sim --out DIR`; the figures are the view crate's).
//! - [`line`](mod@line) makes the serial line noisy (corruption tests).
//! - [`task_report`] measures what a manipulation task achieved.
//! - [`status`] says whether a run ended normally and which pokes it
//!   reached, for every output of a run.
#![warn(missing_docs)]

pub mod line;
pub mod mcu;
pub mod output;
pub mod plant;
pub mod render;
pub mod rig;
pub mod scenario;
pub mod status;
pub mod task_report;
