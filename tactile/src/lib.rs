//! The DexiTac tactile pipeline (paper Sec. III-B), pure: frames in,
//! contacts out. No camera, window, serial port or file format here.
//!
//! One module per step: [`frame`] (grey, crop, rescale) -> [`markers`] (DoH
//! blobs) -> [`density`] (kernel density, Eq. 1) -> [`contact`] (region and
//! centre, Eq. 2) -> [`displacement`] (Eq. 3). [`calibrate`] builds the rest
//! reference (from rest frames, or estimated from the frames themselves),
//! [`area`] is the sensing area detections are kept in, [`surface`] the
//! skin's shape (flat or a dome), [`tracking`] adds marker tracking beyond
//! the paper, and
//! [`pipeline`] runs the stages on one frame with per-stage times.
//! [`params`] holds the tunables and their TOML form, [`sensor_setup`] tunes
//! a detector to a skin's pin count and checks a skin's health.
//!
//! With the `synth` feature: `synth` renders seeded synthetic frames with
//! ground truth, and `bench` measures accuracy against run time on them.
#![warn(missing_docs)]

pub mod area;
#[cfg(feature = "synth")]
pub mod bench;
pub mod calibrate;
pub mod contact;
pub mod density;
pub mod displacement;
pub mod frame;
pub mod markers;
mod numeric;
pub mod params;
pub mod pipeline;
pub mod sensor_setup;
pub mod surface;
#[cfg(feature = "synth")]
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
