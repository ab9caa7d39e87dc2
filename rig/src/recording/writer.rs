//! The recorder: runtime events and pipeline results to MCAP messages.

use std::collections::{BTreeMap, HashMap};
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Sender};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use base64::Engine;
use dexitac_protocol::{HostMsg, Telemetry, ValveState, NO_READING_PA};
use serde::Serialize;

use super::messages::*;
use super::topic;
use crate::event;
use crate::event::{RuntimeEvent, SensorReport, StopReason};
use dexitac_gripper::grasp::{Cause, CentreMm, Command, Decision};
use dexitac_gripper::manipulation::TaskEvent;
use dexitac_tactile::contact::Contact;
use dexitac_tactile::frame::GreyFrame;
use dexitac_tactile::pipeline::{FrameResult, Pipeline};
use dexitac_tactile::PointPx;

/// Marker coordinates in the annotations are rounded to this many px
/// (1/100 px: far below the detector's precision; keeps the JSON short).
const MARKER_ROUND_PX: f64 = 0.01;
/// zstd level of the chunks (3: zstd's default, ~100 MB/s on one core).
const ZSTD_LEVEL: u32 = 3;

/// Why recording failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file could not be created or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The MCAP writer failed (usually an I/O error underneath).
    #[error("MCAP writer: {0}")]
    Mcap(#[from] mcap::McapError),
    /// A frame could not be encoded as PNG.
    #[error("PNG encoding of a sensor {sensor} frame: {reason}")]
    Png {
        /// The sensor.
        sensor: usize,
        /// What the encoder said.
        reason: String,
    },
    /// A message could not be serialised (a bug: every message is plain data).
    #[error("JSON encoding of a {topic} message: {source}")]
    Json {
        /// The topic.
        topic: String,
        /// What serde said.
        source: serde_json::Error,
    },
    /// The recorder thread panicked.
    #[error("the recorder thread stopped unexpectedly")]
    Thread,
}

/// What to record and how to describe it.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordOptions {
    /// What produces the recording (`sim`, `run`, `record`).
    pub source: String,
    /// Free text for [`Session::description`].
    pub description: String,
    /// Record the working frames (PNG) when the events carry them.
    pub frames: bool,
    /// Record one frame in this many observations per sensor (1: every
    /// frame; 0 is taken as 1). Contacts and markers are recorded for
    /// every observation.
    pub frame_every: u32,
    /// Working-frame scale, mm per px (contact disc size in the annotations).
    pub mm_per_px: f64,
    /// The sensor configuration TOML to store (replay uses it by default).
    pub sensor_config_toml: Option<String>,
}

impl Default for RecordOptions {
    fn default() -> Self {
        RecordOptions {
            source: "dexitac".into(),
            description: String::new(),
            frames: true,
            frame_every: 1,
            mm_per_px: dexitac_tactile::params::MM_PER_PX,
            sensor_config_toml: None,
        }
    }
}

/// Counts and costs of a recording.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RecordStats {
    /// Messages written, per topic.
    pub messages: BTreeMap<String, u64>,
    /// Observations written.
    pub observations: u64,
    /// Frames written (PNG), rest frames excluded.
    pub frames: u64,
    /// Time spent writing observations that carried a frame (PNG encoding,
    /// base64, JSON, compression), total.
    pub frame_write: Duration,
    /// Time spent writing observations without a frame, total.
    pub observation_write: Duration,
    /// File size after finishing, bytes.
    pub bytes: u64,
    /// Span of the recorded clock, ms (last `t_ms` − first).
    pub span_ms: u64,
}

/// One observation to write: a borrowed [`SensorReport`] (what
/// [`RuntimeEvent::Observation`] carries), or a frame's pipeline result
/// without a task loop ([`Recorder::write_frame_result`]).
#[derive(Debug, Clone, Copy)]
pub struct ObservationRef<'a> {
    /// The sensor.
    pub sensor: usize,
    /// Capture time, ms.
    pub t_ms: u64,
    /// Contact centre, mm from the image centre.
    pub centre_mm: Option<CentreMm>,
    /// Detected markers, working px.
    pub markers: &'a [PointPx],
    /// The contact, working px.
    pub contact: Option<&'a Contact>,
    /// Pipeline time, ms.
    pub pipeline_ms: f64,
    /// The working frame, if shared.
    pub frame: Option<&'a GreyFrame>,
}

impl<'a> From<&'a SensorReport> for ObservationRef<'a> {
    fn from(r: &'a SensorReport) -> Self {
        ObservationRef {
            sensor: r.sensor,
            t_ms: r.t_ms,
            centre_mm: r.centre_mm,
            markers: &r.markers,
            contact: r.contact.as_ref(),
            pipeline_ms: r.pipeline_ms,
            frame: r.frame.as_deref(),
        }
    }
}

/// Writes one MCAP recording.
pub struct Recorder<W: Write + Seek> {
    writer: mcap::Writer<W>,
    schemas: HashMap<SchemaKind, u16>,
    channels: HashMap<String, (u16, u32)>,
    start_unix_ns: u64,
    options: RecordOptions,
    observations: HashMap<usize, u64>,
    t_range_ms: Option<(u64, u64)>,
    stats: RecordStats,
    path: PathBuf,
}

impl Recorder<BufWriter<File>> {
    /// Creates `path` (replacing it) and writes the session message.
    pub fn create(path: &Path, options: RecordOptions) -> Result<Self, RecordError> {
        let file = File::create(path).map_err(|source| RecordError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let mut r = Recorder::new(BufWriter::new(file), options)?;
        r.path = path.to_path_buf();
        Ok(r)
    }
}

impl<W: Write + Seek> Recorder<W> {
    /// A recorder writing to `w`; the clock's zero is now.
    pub fn new(w: W, options: RecordOptions) -> Result<Self, RecordError> {
        let start_unix_ns = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        Recorder::with_start(w, options, start_unix_ns)
    }

    /// A recorder whose clock zero is `start_unix_ns` (for reproducible files).
    pub fn with_start(
        w: W,
        mut options: RecordOptions,
        start_unix_ns: u64,
    ) -> Result<Self, RecordError> {
        options.frame_every = options.frame_every.max(1);
        let writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(ZSTD_LEVEL)
            .profile("")
            .library(format!("dexitac {}", env!("CARGO_PKG_VERSION")))
            .create(w)?;
        let mut r = Recorder {
            writer,
            schemas: HashMap::new(),
            channels: HashMap::new(),
            start_unix_ns,
            options,
            observations: HashMap::new(),
            t_range_ms: None,
            stats: RecordStats::default(),
            path: PathBuf::from("<stream>"),
        };
        let session = Session {
            timestamp: Time::from_ns(start_unix_ns),
            version: env!("CARGO_PKG_VERSION").into(),
            source: r.options.source.clone(),
            description: r.options.description.clone(),
            start_unix_ns,
            frames: r.options.frames,
            frame_every: r.options.frame_every,
            mm_per_px: r.options.mm_per_px,
            sensor_config_toml: r.options.sensor_config_toml.clone(),
        };
        r.put(topic::SESSION, SchemaKind::Session, 0, &session)?;
        Ok(r)
    }

    fn log_time(&self, t_ms: u64) -> u64 {
        self.start_unix_ns
            .saturating_add(t_ms.saturating_mul(1_000_000))
    }

    fn stamp(&self, t_ms: u64) -> Time {
        Time::from_ns(self.log_time(t_ms))
    }

    /// Writes one JSON message on `topic` (channel and schema added on first use).
    fn put<T: Serialize>(
        &mut self,
        topic: &str,
        schema: SchemaKind,
        t_ms: u64,
        msg: &T,
    ) -> Result<(), RecordError> {
        let data = serde_json::to_vec(msg).map_err(|source| RecordError::Json {
            topic: topic.to_string(),
            source,
        })?;
        let schema_id = match self.schemas.get(&schema) {
            Some(&id) => id,
            None => {
                let id = self.writer.add_schema(
                    schema.name(),
                    "jsonschema",
                    schema.json_schema().as_bytes(),
                )?;
                self.schemas.insert(schema, id);
                id
            }
        };
        let (channel_id, sequence) = match self.channels.get_mut(topic) {
            Some((id, seq)) => {
                *seq += 1;
                (*id, *seq)
            }
            None => {
                let id = self
                    .writer
                    .add_channel(schema_id, topic, "json", &BTreeMap::new())?;
                self.channels.insert(topic.to_string(), (id, 0));
                (id, 0)
            }
        };
        let log_time = self.log_time(t_ms);
        self.writer.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id,
                sequence,
                log_time,
                publish_time: log_time,
            },
            &data,
        )?;
        *self.stats.messages.entry(topic.to_string()).or_insert(0) += 1;
        if topic != topic::SESSION {
            self.t_range_ms = Some(match self.t_range_ms {
                None => (t_ms, t_ms),
                Some((a, b)) => (a.min(t_ms), b.max(t_ms)),
            });
        }
        Ok(())
    }

    fn image(
        &self,
        sensor: usize,
        t_ms: u64,
        frame: &GreyFrame,
    ) -> Result<CompressedImage, RecordError> {
        let png = encode_png(frame).map_err(|reason| RecordError::Png { sensor, reason })?;
        Ok(CompressedImage {
            timestamp: self.stamp(t_ms),
            frame_id: format!("sensor{sensor}"),
            data: base64::engine::general_purpose::STANDARD.encode(png),
            format: "png".into(),
        })
    }

    /// Writes the rest frames sensor `sensor` was calibrated on (replay
    /// recalibrates on them; without them it uses the first frames).
    pub fn write_rest(&mut self, sensor: usize, frames: &[GreyFrame]) -> Result<(), RecordError> {
        for frame in frames {
            let msg = self.image(sensor, 0, frame)?;
            self.put(&topic::rest(sensor), SchemaKind::CompressedImage, 0, &msg)?;
        }
        Ok(())
    }

    /// Writes one event of the task loop.
    pub fn write_event(&mut self, event: &RuntimeEvent) -> Result<(), RecordError> {
        match event {
            RuntimeEvent::Observation(r) => self.write_observation(ObservationRef::from(r)),
            RuntimeEvent::Decision { t_ms, decision } => {
                let msg = decision_msg(self.stamp(*t_ms), *t_ms, decision);
                self.put(topic::DECISION, SchemaKind::Decision, *t_ms, &msg)
            }
            RuntimeEvent::CommandSent {
                t_ms,
                msg,
                reason,
                from_frame,
            } => {
                let msg = command_msg(
                    self.stamp(*t_ms),
                    *t_ms,
                    msg,
                    reason,
                    from_frame.map(|d| d.as_secs_f64() * 1e3),
                );
                self.put(topic::COMMAND, SchemaKind::Command, *t_ms, &msg)
            }
            RuntimeEvent::Telemetry { t_ms, telemetry } => {
                let msg = telemetry_msg(self.stamp(*t_ms), *t_ms, telemetry);
                self.put(topic::TELEMETRY, SchemaKind::Telemetry, *t_ms, &msg)
            }
            RuntimeEvent::Task { t_ms, event } => {
                let msg = TaskMsg {
                    timestamp: self.stamp(*t_ms),
                    t_ms: *t_ms,
                    kind: match event {
                        TaskEvent::Stroke { .. } => "stroke",
                        TaskEvent::Guard { .. } => "guard",
                        TaskEvent::Completed => "completed",
                    }
                    .into(),
                    detail: format!("{event:?}"),
                };
                self.put(topic::TASK, SchemaKind::Task, *t_ms, &msg)
            }
            RuntimeEvent::Stopped {
                t_ms,
                max_loop_gap,
                outcome,
            } => {
                let msg = StoppedMsg {
                    timestamp: self.stamp(*t_ms),
                    t_ms: *t_ms,
                    ok: outcome.is_ok(),
                    outcome: match outcome {
                        Ok(StopReason::Requested) => "requested".into(),
                        Ok(StopReason::FramesEnded) => "frames ended".into(),
                        Err(e) => e.clone(),
                    },
                    max_loop_gap_ms: max_loop_gap.as_secs_f64() * 1e3,
                };
                self.put(topic::STOPPED, SchemaKind::Stopped, *t_ms, &msg)
            }
        }
    }

    /// Writes one sensor's frame and pipeline result (no board needed).
    pub fn write_frame_result(
        &mut self,
        sensor: usize,
        t_ms: u64,
        frame: &GreyFrame,
        pipeline: &Pipeline,
        result: &FrameResult,
    ) -> Result<(), RecordError> {
        let markers = result.markers.positions();
        self.write_observation(ObservationRef {
            sensor,
            t_ms,
            centre_mm: result.contact.map(|c| event::centre_mm(pipeline, c.centre)),
            markers: &markers,
            contact: result.contact.as_ref(),
            pipeline_ms: result.times.total_ms,
            frame: Some(frame),
        })
    }

    /// Writes one observation: the frame (when recorded and due), the
    /// annotations and the contact.
    pub fn write_observation(&mut self, obs: ObservationRef<'_>) -> Result<(), RecordError> {
        let started = Instant::now();
        let n = self.observations.entry(obs.sensor).or_insert(0);
        let due = *n % u64::from(self.options.frame_every) == 0;
        *n += 1;
        let frame = obs.frame.filter(|_| self.options.frames && due);
        let stamp = self.stamp(obs.t_ms);
        if let Some(frame) = frame {
            let msg = self.image(obs.sensor, obs.t_ms, frame)?;
            self.put(
                &topic::image(obs.sensor),
                SchemaKind::CompressedImage,
                obs.t_ms,
                &msg,
            )?;
        }
        let annotations = annotations(stamp, obs.markers, obs.contact, self.options.mm_per_px);
        self.put(
            &topic::annotations(obs.sensor),
            SchemaKind::ImageAnnotations,
            obs.t_ms,
            &annotations,
        )?;
        let contact = ContactMsg {
            timestamp: stamp,
            t_ms: obs.t_ms,
            sensor: obs.sensor,
            found: obs.contact.is_some(),
            centre_px: obs.contact.map(|c| Point2 {
                x: c.centre.x,
                y: c.centre.y,
            }),
            centre_mm: obs.centre_mm.map(|c| Point2 {
                x: c.x_mm,
                y: c.y_mm,
            }),
            area_mm2: obs.contact.map(|c| c.area_mm2),
            method: obs.contact.map(|c| c.source.name().to_string()),
            markers: obs.markers.len(),
            pipeline_ms: obs.pipeline_ms,
        };
        self.put(
            &topic::contact(obs.sensor),
            SchemaKind::Contact,
            obs.t_ms,
            &contact,
        )?;
        self.stats.observations += 1;
        if frame.is_some() {
            self.stats.frames += 1;
            self.stats.frame_write += started.elapsed();
        } else {
            self.stats.observation_write += started.elapsed();
        }
        Ok(())
    }

    /// Finishes the file (chunk, summary, footer) and returns the counts.
    pub fn finish(self) -> Result<RecordStats, RecordError> {
        self.finish_into_inner().map(|(stats, _)| stats)
    }

    /// Finishes the file and returns the counts and the writer.
    pub fn finish_into_inner(mut self) -> Result<(RecordStats, W), RecordError> {
        self.writer.finish()?;
        let mut w = self.writer.into_inner();
        let path = self.path;
        let io = |source| RecordError::Io {
            path: path.clone(),
            source,
        };
        w.flush().map_err(io)?;
        self.stats.bytes = w.stream_position().map_err(io)?;
        self.stats.span_ms = self.t_range_ms.map_or(0, |(a, b)| b - a);
        Ok((self.stats, w))
    }
}

impl<W: Write + Seek + Send + 'static> Recorder<W> {
    /// Moves the recorder to a thread that writes every event sent to the
    /// returned channel and finishes the file when every sender is gone.
    pub fn spawn(self) -> RecorderThread {
        let (tx, rx) = mpsc::channel::<RuntimeEvent>();
        let handle = std::thread::spawn(move || {
            let mut recorder = self;
            for event in rx {
                recorder.write_event(&event)?;
            }
            recorder.finish()
        });
        RecorderThread { tx, handle }
    }
}

/// A recorder running on its own thread.
pub struct RecorderThread {
    tx: Sender<RuntimeEvent>,
    handle: JoinHandle<Result<RecordStats, RecordError>>,
}

impl RecorderThread {
    /// A sender of events to record (clone it for several producers).
    pub fn sender(&self) -> Sender<RuntimeEvent> {
        self.tx.clone()
    }

    /// Drops this handle's sender, waits until every other sender is gone
    /// and the file is finished.
    pub fn finish(self) -> Result<RecordStats, RecordError> {
        drop(self.tx);
        self.handle.join().map_err(|_| RecordError::Thread)?
    }
}

/// PNG (fast compression, adaptive filter) of a grey frame.
fn encode_png(frame: &GreyFrame) -> Result<Vec<u8>, String> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder;
    let mut out = Vec::with_capacity(frame.data().len() / 2);
    let (w, h) = (
        u32::try_from(frame.width()).map_err(|e| e.to_string())?,
        u32::try_from(frame.height()).map_err(|e| e.to_string())?,
    );
    PngEncoder::new_with_quality(&mut out, CompressionType::Fast, FilterType::Adaptive)
        .write_image(frame.data(), w, h, image::ExtendedColorType::L8)
        .map_err(|e| e.to_string())?;
    Ok(out)
}

fn round_px(v: f64) -> f64 {
    (v / MARKER_ROUND_PX).round() * MARKER_ROUND_PX
}

/// Foxglove's image annotations put the origin at the top-left corner of
/// the top-left pixel; our px coordinates have pixel centres at integers.
const FOXGLOVE_PX_OFFSET: f64 = 0.5;

const MARKER_COLOUR: Color = Color {
    r: 0.1,
    g: 0.8,
    b: 1.0,
    a: 1.0,
};
const CONTACT_COLOUR: Color = Color {
    r: 1.0,
    g: 0.2,
    b: 0.1,
    a: 1.0,
};
const CLEAR: Color = Color {
    r: 0.0,
    g: 0.0,
    b: 0.0,
    a: 0.0,
};

/// Markers as points; the contact as a circle of the contact's area.
fn annotations(
    stamp: Time,
    markers: &[PointPx],
    contact: Option<&Contact>,
    mm_per_px: f64,
) -> ImageAnnotations {
    let circles = contact
        .filter(|c| c.centre.is_finite())
        .map(|c| {
            let radius_mm = (c.area_mm2.max(0.0) / std::f64::consts::PI).sqrt();
            let diameter = if mm_per_px > 0.0 {
                2.0 * radius_mm / mm_per_px
            } else {
                0.0
            };
            CircleAnnotation {
                timestamp: stamp,
                position: Point2 {
                    x: c.centre.x + FOXGLOVE_PX_OFFSET,
                    y: c.centre.y + FOXGLOVE_PX_OFFSET,
                },
                diameter: if diameter.is_finite() { diameter } else { 0.0 },
                thickness: 2.0,
                fill_color: CLEAR,
                outline_color: CONTACT_COLOUR,
            }
        })
        .into_iter()
        .collect();
    let points = vec![PointsAnnotation {
        timestamp: stamp,
        kind: 1,
        points: markers
            .iter()
            .filter(|p| p.is_finite())
            .map(|p| Point2 {
                x: round_px(p.x + FOXGLOVE_PX_OFFSET),
                y: round_px(p.y + FOXGLOVE_PX_OFFSET),
            })
            .collect(),
        outline_color: MARKER_COLOUR,
        outline_colors: Vec::new(),
        fill_color: MARKER_COLOUR,
        thickness: 3.0,
    }];
    ImageAnnotations {
        circles,
        points,
        texts: Vec::new(),
    }
}

fn decision_msg(stamp: Time, t_ms: u64, d: &Decision) -> DecisionMsg {
    let (cause, sensor, shifts) = match d.cause {
        Cause::BothStable => ("both_stable", None, None),
        Cause::Disturbance {
            sensor,
            frame_shift_mm,
            anchored_shift_mm,
        } => (
            "disturbance",
            Some(sensor),
            Some((frame_shift_mm, anchored_shift_mm)),
        ),
        Cause::Slip {
            sensor,
            frame_shift_mm,
            anchored_shift_mm,
        } => (
            "slip",
            Some(sensor),
            Some((frame_shift_mm, anchored_shift_mm)),
        ),
        Cause::ContactLost { sensor } => ("contact_lost", Some(sensor), None),
        Cause::NoContact { sensor } => ("no_contact", Some(sensor), None),
    };
    let finite = |v: f64| v.is_finite().then_some(v);
    DecisionMsg {
        timestamp: stamp,
        t_ms,
        decided_t_ms: d.t_ms,
        command: match d.command {
            Command::Seal => "seal",
            Command::ReopenInflation => "reopen_inflation",
            Command::Release => "release",
        }
        .into(),
        cause: cause.into(),
        sensor,
        frame_shift_mm: shifts.and_then(|s| finite(s.0)),
        anchored_shift_mm: shifts.and_then(|s| finite(s.1)),
    }
}

fn command_msg(
    stamp: Time,
    t_ms: u64,
    msg: &HostMsg,
    reason: &str,
    from_frame_ms: Option<f64>,
) -> CommandMsg {
    // The debug form starts with the variant's name.
    let debug = format!("{msg:?}");
    let kind = debug
        .split(|c: char| !c.is_alphanumeric())
        .next()
        .unwrap_or_default()
        .to_string();
    CommandMsg {
        timestamp: stamp,
        t_ms,
        reason: reason.into(),
        kind,
        // Plain wire data (integers, bools, enums) always serialises.
        msg: serde_json::to_value(msg).unwrap_or(serde_json::Value::String(debug)),
        from_frame_ms,
    }
}

fn valve_name(v: ValveState) -> (&'static str, i8) {
    match v {
        ValveState::Hold => ("hold", 0),
        ValveState::Inflate => ("inflate", 1),
        ValveState::Deflate => ("deflate", -1),
    }
}

fn telemetry_msg(stamp: Time, t_ms: u64, t: &Telemetry) -> TelemetryMsg {
    let kpa = |pa: i32| (pa != NO_READING_PA).then(|| f64::from(pa) / 1e3);
    TelemetryMsg {
        timestamp: stamp,
        t_ms,
        mcu_time_ms: t.time_ms,
        positive_tank_kpa: kpa(t.positive_tank_pa),
        negative_tank_kpa: kpa(t.negative_tank_pa),
        valves: t
            .chambers
            .iter()
            .map(|&v| valve_name(v).0.to_string())
            .collect(),
        valve_codes: t.chambers.iter().map(|&v| valve_name(v).1).collect(),
        positive_pump_on: t.positive_pump_on,
        negative_pump_on: t.negative_pump_on,
        state: format!("{:?}", t.state),
        faults: t.faults.0,
        loop_overruns: t.loop_overruns,
    }
}
