//! Pictures of DexiTac: the live view (what the tactile pipeline and the
//! board are doing, as one picture, in a native window and as PNG
//! snapshots) and the figures the commands write ([`figures`]).
//!
//! ```text
//! RuntimeEvent (task loop, sim event tap, `dexitac view`'s sensor loop)
//!   -> Dashboard::apply            (state: frames, markers, contacts, trails,
//!                                   telemetry history, grasp phase)
//!   -> Dashboard::render -> RgbImage (pure; same pixels for both outputs)
//!        -> window::ViewWindow      (minifb, X11)
//!        -> snapshot::Snapshots     (PNG every S seconds of event time)
//! ```
//!
//! - [`dashboard`]: [`Dashboard`], fed by [`dexitac_rig::event::RuntimeEvent`]s;
//! - [`layout`]: where each panel and chart sits on the image (the tests
//!   find pixels with it);
//! - [`draw`]: [`Dashboard::render`], the renderer;
//! - [`window`]: the native window;
//! - [`snapshot`]: headless PNG snapshots;
//! - [`live`]: the loop that feeds a dashboard from a channel and drives the
//!   window and the snapshots;
//! - [`raster`]: pixels, lines and the bitmap font the live view draws with;
//! - [`figures`]: the simulated run's figure and heatmaps, the tactile
//!   benchmark's Pareto plot, workspace views, drawn with `plotters` (PNG
//!   and SVG, text in an embedded DejaVu Sans).
//!
//! # Why a native window
//!
//! Tactile research code shows a sensor the way Bristol's TacTip tools,
//! DIGIT's `digit-interface` and the GelSight SDK examples do: an OpenCV
//! `imshow` window, opened by the program itself. It needs no setup, no
//! server and no second program, and works on a laptop next to the rig.
//! The view does the same with [`minifb`] (X11 only, libX11 loaded at run
//! time, so building needs no system package), and draws the dashboard
//! itself: the pixels in the window are exactly the pixels of the headless
//! PNG snapshots, so the docs and tests show what a user sees. The robotics
//! viewer side (Foxglove and friends) is covered by recordings in a
//! standard log format, which those viewers open after the fact.

#![warn(missing_docs)]

pub mod dashboard;
pub mod draw;
pub mod figures;
pub mod layout;
pub mod live;
pub mod raster;
pub mod snapshot;
pub mod window;

pub use dashboard::{Dashboard, DashboardConfig, GraspPhase};
pub use layout::Layout;
pub use live::{LiveEnd, LiveOptions, LiveSummary};
pub use snapshot::Snapshots;
pub use window::ViewWindow;

/// Why the live view failed.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// No X11 display to open a window on.
    #[error("no display: {0}")]
    NoDisplay(String),
    /// The window could not be opened or updated.
    #[error("window: {0}")]
    Window(String),
    /// A snapshot could not be written.
    #[error("snapshot {path}: {reason}")]
    Snapshot {
        /// The file or directory.
        path: std::path::PathBuf,
        /// What failed.
        reason: String,
    },
    /// A setting is not usable.
    #[error("{0}")]
    Config(String),
}
