//! What the task loop reports as it runs ([`RuntimeEvent`]): observations
//! of each sensor, decisions, commands, MCU events, the end. The recorder,
//! the live view and the CLI's status line all consume these.

use std::sync::Arc;
use std::time::Duration;

use dexitac_gripper::grasp::{CentreMm, Decision};
use dexitac_gripper::manipulation::TaskEvent;
use dexitac_protocol::{HostMsg, Telemetry};
use dexitac_tactile::contact::Contact;
use dexitac_tactile::frame::GreyFrame;
use dexitac_tactile::pipeline::{FrameResult, Pipeline};
use dexitac_tactile::PointPx;

/// Why the loop stopped without an error.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// The stop flag was set (Ctrl-C, end of a scenario).
    Requested,
    /// Every frame source ended.
    FramesEnded,
}

/// What the loop reports as it runs (times on its clock, ms).
#[derive(Debug, Clone)]
pub enum RuntimeEvent {
    /// A sensor's pipeline result.
    Observation(SensorReport),
    /// The grasp state machine decided.
    Decision {
        /// When the loop handled it.
        t_ms: u64,
        /// The decision (its `t_ms` is the frame's capture time).
        decision: Decision,
    },
    /// A command was sent and acknowledged.
    CommandSent {
        /// When its bytes were written.
        t_ms: u64,
        /// The command.
        msg: HostMsg,
        /// Why it was sent.
        reason: &'static str,
        /// Wall time from the deciding frame's arrival to the bytes written.
        from_frame: Option<Duration>,
    },
    /// A telemetry report.
    Telemetry {
        /// When it arrived.
        t_ms: u64,
        /// The report.
        telemetry: Telemetry,
    },
    /// The manipulation primitive reported (and commanded `event.drive()`).
    Task {
        /// When the loop handled it.
        t_ms: u64,
        /// What happened.
        event: TaskEvent,
    },
    /// The loop ended (after the shutdown commands).
    Stopped {
        /// When.
        t_ms: u64,
        /// The longest wall-clock gap between two passes of the link
        /// thread's loop (a stalled loop sends no heartbeat: the firmware
        /// trips after its host-silence deadline).
        max_loop_gap: Duration,
        /// How: `Ok` or the error's text.
        outcome: Result<StopReason, String>,
    },
}

/// One sensor's pipeline result on one frame.
#[derive(Debug, Clone)]
pub struct SensorReport {
    /// The sensor.
    pub sensor: usize,
    /// Capture time.
    pub t_ms: u64,
    /// The contact centre, mm from the image centre.
    pub centre_mm: Option<CentreMm>,
    /// Detected markers (working px), for density snapshots.
    pub markers: Arc<Vec<PointPx>>,
    /// Pipeline time, ms (wall clock).
    pub pipeline_ms: f64,
    /// The contact in working px (centre, area, how it was found).
    pub contact: Option<Contact>,
    /// The working grey frame, when [`ControlConfig::share_frames`](crate::task_loop::ControlConfig::share_frames) is
    /// set (recording, live view); `None` otherwise.
    pub frame: Option<Arc<GreyFrame>>,
}

impl SensorReport {
    /// The report of `pipeline`'s `result` on the frame captured at `t_ms`;
    /// `frame` is kept when given (shared frames).
    pub fn new(
        sensor: usize,
        t_ms: u64,
        pipeline: &Pipeline,
        result: &FrameResult,
        frame: Option<GreyFrame>,
    ) -> Self {
        SensorReport {
            sensor,
            t_ms,
            centre_mm: result.contact.map(|c| centre_mm(pipeline, c.centre)),
            markers: Arc::new(result.markers.positions()),
            pipeline_ms: result.times.total_ms,
            contact: result.contact,
            frame: frame.map(Arc::new),
        }
    }
}

/// The pipeline's contact centre in mm from the image centre.
pub fn centre_mm(pipeline: &Pipeline, centre_px: PointPx) -> CentreMm {
    let cal = &pipeline.calibration;
    let mm = pipeline.params.frame.mm_per_px;
    CentreMm {
        x_mm: (centre_px.x - (cal.width as f64 - 1.0) / 2.0) * mm,
        y_mm: (centre_px.y - (cal.height as f64 - 1.0) / 2.0) * mm,
    }
}
