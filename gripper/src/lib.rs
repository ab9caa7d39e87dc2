//! The DexiTac gripper, pure: the grasp state machine of the paper's
//! Algorithm 1 ([`grasp`]), the four configurations ([`configuration`]),
//! the linear pressure -> angle actuator model ([`actuator`]), forward
//! kinematics ([`kinematics`]) and workspaces ([`workspace`]), and the
//! tactile-guarded manipulation primitives ([`manipulation`]).
//!
//! Nothing here does I/O beyond reading a configuration file.
#![warn(missing_docs)]

pub mod actuator;
pub mod configuration;
pub mod grasp;
pub mod kinematics;
pub mod manipulation;
pub mod workspace;
