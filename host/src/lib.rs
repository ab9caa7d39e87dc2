//! DexiTac host library: everything the `dexitac` command runs on the PC.
//!
//! The tactile pipeline follows the paper's Sec. III-B, one module per step:
//! [`frame`] (grey, crop, rescale) -> [`markers`] (DoH blobs) ->
//! [`density`] (kernel density, Eq. 1) -> [`contact`] (region and centre,
//! Eq. 2) -> [`displacement`] (Eq. 3). [`calibrate`] builds the rest
//! reference, [`tracking`] adds marker tracking beyond the paper, and
//! [`pipeline`] runs the stages on one frame with per-stage times.
//! [`synth`] renders seeded synthetic frames with ground truth; [`bench`](mod@bench)
//! measures accuracy against run time on them.
#![warn(missing_docs)]

pub use dexitac_protocol as protocol;

pub mod bench;
pub mod calibrate;
pub mod contact;
pub mod density;
pub mod displacement;
pub mod frame;
pub mod grasp;
pub mod link;
pub mod markers;
pub mod params;
pub mod pipeline;
pub mod runtime;
pub mod sim;
pub mod synth;
pub mod tracking;

#[cfg(test)]
mod test_fixtures;

/// A point in pixel coordinates: x right, y down, pixel centres at integers.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PointPx {
    /// x, px.
    pub x: f64,
    /// y, px.
    pub y: f64,
}

impl PointPx {
    /// A point.
    pub const fn new(x: f64, y: f64) -> Self {
        Self { x, y }
    }

    /// True when both coordinates are finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite()
    }
}

// Gripper configurations, actuator model, kinematics and workspace (issue 6).
pub mod actuator;
pub mod gripper;
pub mod kinematics;
pub mod workspace;

// Tactile-guarded manipulation primitives (issue 6, item 5).
pub mod manipulation;

// The live view: dashboard, window and PNG snapshots (issue 7, item 4).
pub mod view;
// Recording and replay in MCAP (issue 7, items 2b and 3).
pub mod recording;
// Tactile cameras, frame-folder replay and sensor setup helpers (issue 7).
pub mod camera;
pub mod sensor_setup;
pub mod sources;
