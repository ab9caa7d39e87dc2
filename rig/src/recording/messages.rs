//! The messages of a recording: their JSON layout (serde) and the JSON
//! schemas written into the MCAP file.
//!
//! Images and annotations use Foxglove's well-known schemas
//! (`foxglove.CompressedImage`, `foxglove.ImageAnnotations`), so the
//! Foxglove app shows them without setup; everything else has a `dexitac.*`
//! schema. Every message carries a Foxglove-style `timestamp` (`{sec,
//! nsec}`, Unix time: the recording's start plus the loop's clock) and, in
//! the `dexitac.*` ones, the loop's clock itself as `t_ms`. The table of
//! topics is in `rig/RECORDING.md`.

use serde::{Deserialize, Serialize};

/// A Foxglove `time`: seconds and nanoseconds since the Unix epoch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    /// Whole seconds.
    pub sec: u32,
    /// Nanoseconds, `0..1e9`.
    pub nsec: u32,
}

impl Time {
    /// The time of `ns` nanoseconds since the epoch (saturating at the
    /// largest `u32` second).
    pub fn from_ns(ns: u64) -> Self {
        Time {
            sec: u32::try_from(ns / 1_000_000_000).unwrap_or(u32::MAX),
            nsec: (ns % 1_000_000_000) as u32,
        }
    }
}

/// A point in 2-D image coordinates, px (`foxglove.Point2`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Point2 {
    /// x, px (right).
    pub x: f64,
    /// y, px (down).
    pub y: f64,
}

/// An RGBA colour, each in `0..=1` (`foxglove.Color`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Color {
    /// Red.
    pub r: f64,
    /// Green.
    pub g: f64,
    /// Blue.
    pub b: f64,
    /// Alpha.
    pub a: f64,
}

/// `foxglove.CompressedImage`: one PNG-encoded working grey frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage {
    /// Capture time.
    pub timestamp: Time,
    /// The sensor: `sensor0`, `sensor1`.
    pub frame_id: String,
    /// The encoded image, base64 in JSON.
    pub data: String,
    /// `png`.
    pub format: String,
}

/// `foxglove.CircleAnnotation`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CircleAnnotation {
    /// Time of the frame it belongs to.
    pub timestamp: Time,
    /// Centre, px.
    pub position: Point2,
    /// Diameter, px.
    pub diameter: f64,
    /// Line thickness, px.
    pub thickness: f64,
    /// Fill colour.
    pub fill_color: Color,
    /// Outline colour.
    pub outline_color: Color,
}

/// `foxglove.PointsAnnotation` (type 1: individual points).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointsAnnotation {
    /// Time of the frame it belongs to.
    pub timestamp: Time,
    /// 1 = POINTS.
    #[serde(rename = "type")]
    pub kind: u8,
    /// The points, px.
    pub points: Vec<Point2>,
    /// Outline colour.
    pub outline_color: Color,
    /// Per-point colours (none: `outline_color` for all).
    pub outline_colors: Vec<Color>,
    /// Fill colour.
    pub fill_color: Color,
    /// Point size, px.
    pub thickness: f64,
}

/// `foxglove.ImageAnnotations`: the detected markers and the contact
/// centre over one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageAnnotations {
    /// The contact (centre; diameter of a disc of the contact's area).
    pub circles: Vec<CircleAnnotation>,
    /// The detected markers.
    pub points: Vec<PointsAnnotation>,
    /// Text annotations: none (the schema requires the field).
    #[serde(alias = "labels")]
    pub texts: Vec<serde_json::Value>,
}

/// `dexitac.Session`: what the recording holds; the first message.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Session {
    /// When the recording started.
    pub timestamp: Time,
    /// `dexitac` version that wrote it.
    pub version: String,
    /// What produced it: `sim`, `run`, `record`, or a test.
    pub source: String,
    /// Free text (scenario, frame folders, ...).
    pub description: String,
    /// The loop clock's zero as Unix time, ns: `log_time = start_unix_ns + t_ms * 1e6`.
    pub start_unix_ns: u64,
    /// Whether frames are recorded.
    pub frames: bool,
    /// One frame in this many observations is recorded (per sensor).
    pub frame_every: u32,
    /// Working-frame scale, mm per px.
    pub mm_per_px: f64,
    /// The sensor configuration's TOML (`dexitac analyze --config`), when one was given.
    pub sensor_config_toml: Option<String>,
}

/// `dexitac.Contact`: one sensor's pipeline result for one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ContactMsg {
    /// Capture time.
    pub timestamp: Time,
    /// Capture time on the loop's clock, ms.
    pub t_ms: u64,
    /// The sensor.
    pub sensor: usize,
    /// Whether a contact was found.
    pub found: bool,
    /// Contact centre, working px (exact `f64`).
    pub centre_px: Option<Point2>,
    /// Contact centre, mm from the image centre.
    pub centre_mm: Option<Point2>,
    /// Contact area, mm².
    pub area_mm2: Option<f64>,
    /// How the centre was found (`density`, `density+tracking`, `tracking`).
    pub method: Option<String>,
    /// Detected markers.
    pub markers: usize,
    /// Pipeline time, ms (wall clock).
    pub pipeline_ms: f64,
}

/// `dexitac.GraspDecision`: a decision of the grasp state machine (Algorithm 1).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DecisionMsg {
    /// When the loop handled it.
    pub timestamp: Time,
    /// When the loop handled it, ms.
    pub t_ms: u64,
    /// The deciding observation's or tick's time, ms.
    pub decided_t_ms: u64,
    /// `seal`, `reopen_inflation` or `release`.
    pub command: String,
    /// `both_stable`, `disturbance`, `slip`, `contact_lost`, `no_contact`.
    pub cause: String,
    /// The sensor behind the cause, if one.
    pub sensor: Option<usize>,
    /// Frame-to-frame shift D, mm (disturbance, slip).
    pub frame_shift_mm: Option<f64>,
    /// Shift from the anchor A, mm (disturbance, slip).
    pub anchored_shift_mm: Option<f64>,
}

/// `dexitac.Command`: a command sent to the MCU and acknowledged.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CommandMsg {
    /// When its bytes were written.
    pub timestamp: Time,
    /// When its bytes were written, ms.
    pub t_ms: u64,
    /// Why it was sent.
    pub reason: String,
    /// The message's variant (`SetChambers`, `SealAll`, ...).
    pub kind: String,
    /// The whole wire message as JSON (serde's externally tagged form).
    pub msg: serde_json::Value,
    /// Wall time from the deciding frame's arrival to the bytes written, ms.
    pub from_frame_ms: Option<f64>,
}

/// `dexitac.Telemetry`: the MCU's periodic report.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TelemetryMsg {
    /// When it arrived.
    pub timestamp: Time,
    /// When it arrived, ms.
    pub t_ms: u64,
    /// MCU time since reset, ms.
    pub mcu_time_ms: u32,
    /// Positive tank, gauge kPa (`null`: no valid reading).
    pub positive_tank_kpa: Option<f64>,
    /// Negative tank, gauge kPa (`null`: no valid reading).
    pub negative_tank_kpa: Option<f64>,
    /// Valve state per chamber: `hold`, `inflate`, `deflate`.
    pub valves: Vec<String>,
    /// The same as numbers for plots: hold 0, inflate 1, deflate -1.
    pub valve_codes: Vec<i8>,
    /// Positive pump running.
    pub positive_pump_on: bool,
    /// Negative pump running.
    pub negative_pump_on: bool,
    /// Safety state (`Disarmed`, `Armed`, `Tripped`).
    pub state: String,
    /// Fault flags since the last disarm (bits of `dexitac_protocol::FaultFlags`).
    pub faults: u16,
    /// Control-loop overruns since reset.
    pub loop_overruns: u32,
}

/// `dexitac.TaskEvent`: a manipulation primitive's event.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TaskMsg {
    /// When the loop handled it.
    pub timestamp: Time,
    /// When the loop handled it, ms.
    pub t_ms: u64,
    /// `stroke`, `guard` or `completed`.
    pub kind: String,
    /// The event in full (Rust debug form).
    pub detail: String,
}

/// `dexitac.Stopped`: how the task loop ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StoppedMsg {
    /// When.
    pub timestamp: Time,
    /// When, ms.
    pub t_ms: u64,
    /// Whether it ended without an error.
    pub ok: bool,
    /// The stop reason or the error's text.
    pub outcome: String,
    /// Longest wall-clock stall of the link thread, ms.
    pub max_loop_gap_ms: f64,
}

/// JSON schema of a Foxglove `time` (shared by every schema).
const TIME: &str = r#"{"type":"object","title":"time","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}}"#;
const POINT2: &str = r#"{"title":"foxglove.Point2","type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"}}}"#;
const COLOR: &str = r#"{"title":"foxglove.Color","type":"object","properties":{"r":{"type":"number"},"g":{"type":"number"},"b":{"type":"number"},"a":{"type":"number"}}}"#;

/// A schema: its name and JSON-schema text.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SchemaKind {
    /// `foxglove.CompressedImage`.
    CompressedImage,
    /// `foxglove.ImageAnnotations`.
    ImageAnnotations,
    /// `dexitac.Session`.
    Session,
    /// `dexitac.Contact`.
    Contact,
    /// `dexitac.GraspDecision`.
    Decision,
    /// `dexitac.Command`.
    Command,
    /// `dexitac.Telemetry`.
    Telemetry,
    /// `dexitac.TaskEvent`.
    Task,
    /// `dexitac.Stopped`.
    Stopped,
}

impl SchemaKind {
    /// The schema's name (Foxglove recognises its own by name).
    pub fn name(self) -> &'static str {
        match self {
            SchemaKind::CompressedImage => "foxglove.CompressedImage",
            SchemaKind::ImageAnnotations => "foxglove.ImageAnnotations",
            SchemaKind::Session => "dexitac.Session",
            SchemaKind::Contact => "dexitac.Contact",
            SchemaKind::Decision => "dexitac.GraspDecision",
            SchemaKind::Command => "dexitac.Command",
            SchemaKind::Telemetry => "dexitac.Telemetry",
            SchemaKind::Task => "dexitac.TaskEvent",
            SchemaKind::Stopped => "dexitac.Stopped",
        }
    }

    /// The JSON schema (draft-07 subset, as Foxglove's own files).
    pub fn json_schema(self) -> String {
        let props = match self {
            SchemaKind::CompressedImage => format!(
                r#""timestamp":{TIME},"frame_id":{{"type":"string"}},"data":{{"type":"string","contentEncoding":"base64"}},"format":{{"type":"string"}}"#
            ),
            SchemaKind::ImageAnnotations => format!(
                r#""circles":{{"type":"array","items":{{"title":"foxglove.CircleAnnotation","type":"object","properties":{{"timestamp":{TIME},"position":{POINT2},"diameter":{{"type":"number"}},"thickness":{{"type":"number"}},"fill_color":{COLOR},"outline_color":{COLOR}}}}}}},"points":{{"type":"array","items":{{"title":"foxglove.PointsAnnotation","type":"object","properties":{{"timestamp":{TIME},"type":{{"title":"foxglove.PointsAnnotationType","oneOf":[{{"title":"UNKNOWN","const":0}},{{"title":"POINTS","const":1}},{{"title":"LINE_LOOP","const":2}},{{"title":"LINE_STRIP","const":3}},{{"title":"LINE_LIST","const":4}}]}},"points":{{"type":"array","items":{POINT2}}},"outline_color":{COLOR},"outline_colors":{{"type":"array","items":{COLOR}}},"fill_color":{COLOR},"thickness":{{"type":"number"}}}}}}}},"texts":{{"type":"array","items":{{"title":"foxglove.TextAnnotation","type":"object"}}}}"#
            ),
            SchemaKind::Session => format!(
                r#""timestamp":{TIME},"version":{{"type":"string"}},"source":{{"type":"string"}},"description":{{"type":"string"}},"start_unix_ns":{{"type":"integer"}},"frames":{{"type":"boolean"}},"frame_every":{{"type":"integer"}},"mm_per_px":{{"type":"number"}},"sensor_config_toml":{{"type":["string","null"]}}"#
            ),
            SchemaKind::Contact => format!(
                r#""timestamp":{TIME},"t_ms":{{"type":"integer"}},"sensor":{{"type":"integer"}},"found":{{"type":"boolean"}},"centre_px":{{"type":["object","null"],"properties":{{"x":{{"type":"number"}},"y":{{"type":"number"}}}}}},"centre_mm":{{"type":["object","null"],"properties":{{"x":{{"type":"number"}},"y":{{"type":"number"}}}}}},"area_mm2":{{"type":["number","null"]}},"method":{{"type":["string","null"]}},"markers":{{"type":"integer"}},"pipeline_ms":{{"type":"number"}}"#
            ),
            SchemaKind::Decision => format!(
                r#""timestamp":{TIME},"t_ms":{{"type":"integer"}},"decided_t_ms":{{"type":"integer"}},"command":{{"type":"string"}},"cause":{{"type":"string"}},"sensor":{{"type":["integer","null"]}},"frame_shift_mm":{{"type":["number","null"]}},"anchored_shift_mm":{{"type":["number","null"]}}"#
            ),
            SchemaKind::Command => format!(
                r#""timestamp":{TIME},"t_ms":{{"type":"integer"}},"reason":{{"type":"string"}},"kind":{{"type":"string"}},"msg":{{}},"from_frame_ms":{{"type":["number","null"]}}"#
            ),
            SchemaKind::Telemetry => format!(
                r#""timestamp":{TIME},"t_ms":{{"type":"integer"}},"mcu_time_ms":{{"type":"integer"}},"positive_tank_kpa":{{"type":["number","null"]}},"negative_tank_kpa":{{"type":["number","null"]}},"valves":{{"type":"array","items":{{"type":"string"}}}},"valve_codes":{{"type":"array","items":{{"type":"integer"}}}},"positive_pump_on":{{"type":"boolean"}},"negative_pump_on":{{"type":"boolean"}},"state":{{"type":"string"}},"faults":{{"type":"integer"}},"loop_overruns":{{"type":"integer"}}"#
            ),
            SchemaKind::Task => format!(
                r#""timestamp":{TIME},"t_ms":{{"type":"integer"}},"kind":{{"type":"string"}},"detail":{{"type":"string"}}"#
            ),
            SchemaKind::Stopped => format!(
                r#""timestamp":{TIME},"t_ms":{{"type":"integer"}},"ok":{{"type":"boolean"}},"outcome":{{"type":"string"}},"max_loop_gap_ms":{{"type":"number"}}"#
            ),
        };
        format!(
            r#"{{"title":"{}","type":"object","properties":{{{props}}}}}"#,
            self.name()
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [SchemaKind; 9] = [
        SchemaKind::CompressedImage,
        SchemaKind::ImageAnnotations,
        SchemaKind::Session,
        SchemaKind::Contact,
        SchemaKind::Decision,
        SchemaKind::Command,
        SchemaKind::Telemetry,
        SchemaKind::Task,
        SchemaKind::Stopped,
    ];

    #[test]
    fn every_schema_is_valid_json_titled_with_its_name() {
        for kind in ALL {
            let v: serde_json::Value = serde_json::from_str(&kind.json_schema())
                .unwrap_or_else(|e| panic!("{}: {e}", kind.name()));
            assert_eq!(v["title"], kind.name());
            assert!(
                v["properties"]["timestamp"].is_object() || kind == SchemaKind::ImageAnnotations
            );
        }
    }

    #[test]
    fn time_splits_nanoseconds() {
        assert_eq!(
            Time::from_ns(1_700_000_000_123_456_789),
            Time {
                sec: 1_700_000_000,
                nsec: 123_456_789
            }
        );
    }
}
