//! The DexiTac rig on the PC: what connects the pure tactile and gripper
//! crates to hardware.
//!
//! - [`config`]: the rig config (one TOML for a real rig and the
//!   simulator's scenarios);
//! - [`source`]: the [`FrameSource`](source::FrameSource) trait, timed
//!   frames and the [`Clock`](source::Clock);
//! - [`event`]: what the task loop reports ([`RuntimeEvent`](event::RuntimeEvent));
//! - [`link`]: the serial link to the board (framing, acks, heartbeat);
//! - [`task_loop`]: the paper's processes (one thread per sensor, one link
//!   thread) with Algorithm 1 in between;
//! - [`sensor_loop`]: the sensors without a board (record, view), and the
//!   event tee;
//! - [`camera`]: V4L2 tactile cameras; [`sources`]: frame folders;
//! - [`recording`]: MCAP recording, reading and replay.
#![warn(missing_docs)]

pub mod camera;
pub mod config;
pub mod event;
pub mod link;
pub mod recording;
pub mod sensor_loop;
pub mod source;
pub mod sources;
pub mod task_loop;
