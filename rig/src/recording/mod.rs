//! Recording and replay in MCAP: the task loop's events (frames, markers,
//! contact centres, grasp decisions, commands, telemetry, task events) to an
//! MCAP file that Foxglove and the ROS 2 tools open, and back.
//!
//! ```text
//! RuntimeEvent ──> Recorder ──> FILE.mcap (zstd chunks, JSON messages)
//! FILE.mcap ──> Recording ──> ReplaySource (FrameSource) ──> Pipeline ──> replay::compare
//! ```
//!
//! - [`Recorder`] writes: [`Recorder::write_event`] for every
//!   [`RuntimeEvent`](crate::event::RuntimeEvent) of the loop (or
//!   [`Recorder::spawn`] to consume a channel of them), the lower-level
//!   [`Recorder::write_frame_result`] for one sensor's frame and pipeline
//!   result without a board, and [`Recorder::write_rest`] for the rest
//!   frames the pipeline was calibrated on (replay recalibrates on them).
//! - [`Recording::open`] reads a file back (every message typed);
//!   [`ReplaySource`] gives a sensor's recorded frames as a
//!   [`FrameSource`](crate::source::FrameSource), at recorded or maximum
//!   speed; [`replay::replay`] runs the pipeline again and compares the
//!   contact centres with the recorded ones.
//!
//! Topics, schemas, fields and units: `rig/RECORDING.md` and
//! [`topic`]. Times: every message's MCAP `log_time` is
//! `start_unix_ns + t_ms * 1e6`, `t_ms` being the loop's clock.
//!
//! # Damaged files
//!
//! A file whose writer did not finish (killed process, full disk) has no
//! summary and may end inside a record. [`Recording::open`] reads messages
//! front to back (the summary is not needed) and, by default, refuses such
//! a file with [`ReadError::Damaged`] naming how many messages were readable;
//! with `recover` it keeps those messages and notes the damage in
//! [`Recording::damage`]. A chunk cut short is lost whole (zstd chunks are
//! about 1 MiB).

mod messages;
mod reader;
pub mod replay;
mod writer;

pub use messages::{
    CircleAnnotation, Color, CommandMsg, CompressedImage, ContactMsg, DecisionMsg,
    ImageAnnotations, Point2, PointsAnnotation, SchemaKind, Session, StoppedMsg, TaskMsg,
    TelemetryMsg, Time,
};
pub use reader::{ReadError, RecordedFrame, Recording, ReplaySource, TopicInfo};
pub use writer::{
    ObservationRef, RecordError, RecordOptions, RecordStats, Recorder, RecorderThread,
};

/// The topics of a recording (`{i}`: sensor index).
pub mod topic {
    /// `dexitac.Session`, the first message.
    pub const SESSION: &str = "/dexitac/session";
    /// `dexitac.GraspDecision`.
    pub const DECISION: &str = "/grasp/decision";
    /// `dexitac.Command`.
    pub const COMMAND: &str = "/link/command";
    /// `dexitac.Telemetry`.
    pub const TELEMETRY: &str = "/link/telemetry";
    /// `dexitac.TaskEvent`.
    pub const TASK: &str = "/task/event";
    /// `dexitac.Stopped`.
    pub const STOPPED: &str = "/run/stopped";

    /// `foxglove.CompressedImage`: sensor `i`'s working frames (PNG).
    pub fn image(sensor: usize) -> String {
        format!("/sensor{sensor}/image")
    }
    /// `foxglove.CompressedImage`: the rest frames sensor `i` was calibrated on.
    pub fn rest(sensor: usize) -> String {
        format!("/sensor{sensor}/rest")
    }
    /// `foxglove.ImageAnnotations`: markers and contact over sensor `i`'s frames.
    pub fn annotations(sensor: usize) -> String {
        format!("/sensor{sensor}/annotations")
    }
    /// `dexitac.Contact`: sensor `i`'s pipeline result per frame.
    pub fn contact(sensor: usize) -> String {
        format!("/sensor{sensor}/contact")
    }

    /// The sensor index and the per-sensor topic's last part (`image`,
    /// `rest`, ...) of a `/sensor{i}/...` topic.
    pub fn parse_sensor(topic: &str) -> Option<(usize, &str)> {
        let rest = topic.strip_prefix("/sensor")?;
        let (index, leaf) = rest.split_once('/')?;
        Some((index.parse().ok()?, leaf))
    }
}
