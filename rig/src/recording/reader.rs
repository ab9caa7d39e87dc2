//! Reading a recording back: every message typed, frames kept PNG-encoded
//! until used; [`ReplaySource`] plays one sensor's frames as a
//! [`FrameSource`].

use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};

use base64::Engine;
use serde::de::DeserializeOwned;

use super::messages::*;
use super::topic;
use crate::source::{Clock, FrameSource, SourceError, TimedFrame};
use dexitac_tactile::frame::GreyFrame;

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The file is not MCAP at all.
    #[error("{path} is not an MCAP file ({reason})")]
    NotMcap {
        /// The file.
        path: PathBuf,
        /// What the reader said.
        reason: String,
    },
    /// The file is damaged or was not finished (truncated, killed writer).
    #[error(
        "{path} is damaged or unfinished: {reason}; {messages} message(s) before the damage are \
         readable"
    )]
    Damaged {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
        /// Messages readable before the damage.
        messages: usize,
    },
    /// The file is MCAP but has no dexitac session message.
    #[error("{path} is not a dexitac recording (no {} message)", topic::SESSION)]
    NotDexitac {
        /// The file.
        path: PathBuf,
    },
    /// A message does not match its schema.
    #[error("{path}: message {index} on {topic}: {reason}")]
    Message {
        /// The file.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// Its position in the file, from 0.
        index: usize,
        /// What is wrong.
        reason: String,
    },
}

/// One recorded frame, still PNG-encoded.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordedFrame {
    /// The sensor.
    pub sensor: usize,
    /// Capture time on the recording's clock, ms.
    pub t_ms: u64,
    /// The PNG bytes.
    pub png: Vec<u8>,
}

impl RecordedFrame {
    /// Decodes the frame (grey; colour PNGs are converted).
    pub fn decode(&self) -> Result<GreyFrame, String> {
        let img = image::load_from_memory_with_format(&self.png, image::ImageFormat::Png)
            .map_err(|e| e.to_string())?
            .into_luma8();
        let (w, h) = (img.width() as usize, img.height() as usize);
        GreyFrame::new(w, h, img.into_raw()).map_err(|e| e.to_string())
    }
}

/// A topic's schema and message count.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicInfo {
    /// Schema name.
    pub schema: String,
    /// Messages read.
    pub messages: u64,
}

/// A recording read into memory.
#[derive(Debug, Clone, Default)]
pub struct Recording {
    /// The file.
    pub path: PathBuf,
    /// The session message.
    pub session: Option<Session>,
    /// Rest frames per sensor.
    pub rest: BTreeMap<usize, Vec<RecordedFrame>>,
    /// Frames of every sensor, in file order.
    pub frames: Vec<RecordedFrame>,
    /// Contacts of every sensor, in file order.
    pub contacts: Vec<ContactMsg>,
    /// Grasp decisions.
    pub decisions: Vec<DecisionMsg>,
    /// Commands.
    pub commands: Vec<CommandMsg>,
    /// Telemetry.
    pub telemetry: Vec<TelemetryMsg>,
    /// Task events.
    pub tasks: Vec<TaskMsg>,
    /// How the loop stopped.
    pub stopped: Vec<StoppedMsg>,
    /// Annotations per sensor, in file order.
    pub annotations: BTreeMap<usize, Vec<ImageAnnotations>>,
    /// Every topic with its schema and count.
    pub topics: BTreeMap<String, TopicInfo>,
    /// When opened with `recover`: what was wrong with the file.
    pub damage: Option<String>,
}

fn json<T: DeserializeOwned>(
    path: &Path,
    topic: &str,
    index: usize,
    data: &[u8],
) -> Result<T, ReadError> {
    serde_json::from_slice(data).map_err(|e| ReadError::Message {
        path: path.to_path_buf(),
        topic: topic.to_string(),
        index,
        reason: e.to_string(),
    })
}

impl Recording {
    /// Reads `path`. A damaged or unfinished file is an error unless
    /// `recover` is set; then the messages before the damage are kept (see
    /// [the module docs](super#damaged-files)). The whole file is read into
    /// memory (frames stay PNG-encoded until used).
    pub fn open(path: &Path, recover: bool) -> Result<Recording, ReadError> {
        let bytes = std::fs::read(path).map_err(|source| ReadError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Recording::from_bytes(path, &bytes, recover)
    }

    /// Reads a recording held in memory (`path` names it in errors).
    pub fn from_bytes(path: &Path, bytes: &[u8], recover: bool) -> Result<Recording, ReadError> {
        if !bytes.starts_with(mcap::MAGIC) {
            return Err(ReadError::NotMcap {
                path: path.to_path_buf(),
                reason: "no MCAP magic at the start".into(),
            });
        }
        // mcap 0.26 reserves a record's claimed length inside a chunk before
        // reading it: one corrupt length aborts the process. The chunks are
        // checked first, and the stream stops before a bad one.
        let bad_chunk = check_chunks(bytes);
        let stream = mcap::MessageStream::new(bytes).map_err(|e| ReadError::NotMcap {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        let mut rec = Recording {
            path: path.to_path_buf(),
            ..Recording::default()
        };
        let mut damage = None;
        let mut index = 0;
        for message in stream {
            if let Some((reason, before)) = &bad_chunk {
                if index >= *before {
                    damage = Some(reason.clone());
                    break;
                }
            }
            let message = match message {
                Ok(m) => m,
                Err(e) => {
                    damage = Some(e.to_string());
                    break;
                }
            };
            rec.add(&message, index)?;
            index += 1;
        }
        if damage.is_none() {
            if let Some((reason, _)) = bad_chunk {
                damage = Some(reason);
            }
        }
        // A finished file ends with a footer; without one, the writer did
        // not finish (the stream may still have ended on a record boundary).
        if damage.is_none() {
            if let Err(e) = mcap::read::footer(bytes) {
                damage = Some(format!("no footer ({e})"));
            }
        }
        if let Some(reason) = damage {
            if !recover {
                return Err(ReadError::Damaged {
                    path: path.to_path_buf(),
                    reason,
                    messages: index,
                });
            }
            rec.damage = Some(format!("{reason} (kept {index} messages before it)"));
        }
        if rec.session.is_none() {
            return Err(ReadError::NotDexitac {
                path: path.to_path_buf(),
            });
        }
        Ok(rec)
    }

    fn add(&mut self, m: &mcap::Message<'_>, index: usize) -> Result<(), ReadError> {
        let topic = m.channel.topic.as_str();
        let schema = m
            .channel
            .schema
            .as_ref()
            .map(|s| s.name.clone())
            .unwrap_or_default();
        self.topics
            .entry(topic.to_string())
            .or_insert(TopicInfo {
                schema,
                messages: 0,
            })
            .messages += 1;
        let path = self.path.clone();
        let data = &m.data;
        let bad = |reason: String| ReadError::Message {
            path: path.clone(),
            topic: topic.to_string(),
            index,
            reason,
        };
        match topic {
            topic::SESSION => self.session = Some(json(&path, topic, index, data)?),
            topic::DECISION => self.decisions.push(json(&path, topic, index, data)?),
            topic::COMMAND => self.commands.push(json(&path, topic, index, data)?),
            topic::TELEMETRY => self.telemetry.push(json(&path, topic, index, data)?),
            topic::TASK => self.tasks.push(json(&path, topic, index, data)?),
            topic::STOPPED => self.stopped.push(json(&path, topic, index, data)?),
            _ => match topic::parse_sensor(topic) {
                Some((sensor, "image" | "rest")) => {
                    let img: CompressedImage = json(&path, topic, index, data)?;
                    if img.format != "png" {
                        return Err(bad(format!("image format {:?}, expected png", img.format)));
                    }
                    let png = base64::engine::general_purpose::STANDARD
                        .decode(img.data.as_bytes())
                        .map_err(|e| bad(format!("image data: {e}")))?;
                    let start = self.session.as_ref().map_or(0, |s| s.start_unix_ns);
                    let frame = RecordedFrame {
                        sensor,
                        t_ms: m.log_time.saturating_sub(start) / 1_000_000,
                        png,
                    };
                    if topic.ends_with("/rest") {
                        self.rest.entry(sensor).or_default().push(frame);
                    } else {
                        self.frames.push(frame);
                    }
                }
                Some((sensor, "contact")) => {
                    let c: ContactMsg = json(&path, topic, index, data)?;
                    if c.sensor != sensor {
                        return Err(bad(format!(
                            "sensor {} on sensor {sensor}'s topic",
                            c.sensor
                        )));
                    }
                    self.contacts.push(c);
                }
                Some((sensor, "annotations")) => {
                    let a: ImageAnnotations = json(&path, topic, index, data)?;
                    self.annotations.entry(sensor).or_default().push(a);
                }
                // Topics of later versions or other tools: counted, not read.
                _ => {}
            },
        }
        Ok(())
    }

    /// The sensors that have frames, contacts or rest frames.
    pub fn sensors(&self) -> Vec<usize> {
        let mut s: Vec<usize> = self
            .frames
            .iter()
            .map(|f| f.sensor)
            .chain(self.contacts.iter().map(|c| c.sensor))
            .chain(self.rest.keys().copied())
            .collect();
        s.sort_unstable();
        s.dedup();
        s
    }

    /// Sensor `sensor`'s frames, in order.
    pub fn frames_of(&self, sensor: usize) -> impl Iterator<Item = &RecordedFrame> {
        self.frames.iter().filter(move |f| f.sensor == sensor)
    }
}

/// One sensor's recorded frames as a frame source.
///
/// At maximum speed (`paced = false`) every frame is returned at once; at
/// recorded speed a frame is returned when the clock reaches its recorded
/// time less the first frame's. Either way [`TimedFrame::t_ms`] is the
/// recorded capture time, so results line up with the recording.
pub struct ReplaySource {
    frames: VecDeque<RecordedFrame>,
    paced: bool,
    first_ms: Option<u64>,
    path: PathBuf,
}

impl ReplaySource {
    /// Sensor `sensor`'s frames of `recording`.
    pub fn new(recording: &Recording, sensor: usize, paced: bool) -> Self {
        let frames: VecDeque<RecordedFrame> = recording.frames_of(sensor).cloned().collect();
        ReplaySource {
            first_ms: frames.front().map(|f| f.t_ms),
            frames,
            paced,
            path: recording.path.clone(),
        }
    }

    /// Frames left.
    pub fn remaining(&self) -> usize {
        self.frames.len()
    }
}

impl FrameSource for ReplaySource {
    fn next_frame(&mut self, clock: &Clock) -> Result<Option<TimedFrame>, SourceError> {
        let Some(f) = self.frames.pop_front() else {
            return Ok(None);
        };
        if self.paced {
            clock.sleep_until(f.t_ms.saturating_sub(self.first_ms.unwrap_or(0)));
        }
        let frame = f.decode().map_err(|reason| SourceError::Decode {
            path: self.path.clone(),
            reason: format!("sensor {} frame at {} ms: {reason}", f.sensor, f.t_ms),
        })?;
        Ok(Some(TimedFrame {
            t_ms: f.t_ms,
            frame,
        }))
    }
}

/// Largest uncompressed chunk a recording may hold, bytes (the writer's
/// chunks are far smaller).
const MAX_CHUNK_BYTES: u64 = 256 << 20;
/// MCAP opcode of a message record.
const OP_MESSAGE: u8 = 0x05;

/// The first chunk whose contents cannot be read safely (a size beyond
/// [`MAX_CHUNK_BYTES`], data that does not decompress, a record longer than
/// what is left of its chunk), and the number of messages in the chunks
/// before it. Damage outside chunks is left to the message stream, which
/// reports it as an error.
fn check_chunks(bytes: &[u8]) -> Option<(String, usize)> {
    let reader = mcap::read::LinearReader::new(bytes).ok()?;
    let mut messages = 0usize;
    for record in reader {
        let Ok(mcap::records::Record::Chunk { header, data }) = record else {
            if record.is_err() {
                return None;
            }
            continue;
        };
        let before = messages;
        let bad = |reason: String| Some((format!("bad chunk: {reason}"), before));
        if header.uncompressed_size > MAX_CHUNK_BYTES {
            return bad(format!("claims {} bytes", header.uncompressed_size));
        }
        let raw: std::borrow::Cow<'_, [u8]> = match header.compression.as_str() {
            "" => data,
            "zstd" => match zstd::bulk::decompress(&data, header.uncompressed_size as usize) {
                Ok(v) => v.into(),
                Err(e) => return bad(format!("zstd: {e}")),
            },
            other => return bad(format!("unknown compression {other:?}")),
        };
        let mut rest = &raw[..];
        while !rest.is_empty() {
            let Some((&op, tail)) = rest.split_first() else {
                break;
            };
            let Some(len) = tail
                .get(..8)
                .and_then(|b| <[u8; 8]>::try_from(b).ok())
                .map(u64::from_le_bytes)
            else {
                return bad("a record header runs past the chunk".into());
            };
            let body = &tail[8..];
            if len > body.len() as u64 {
                return bad(format!("a record of {len} bytes in {} left", body.len()));
            }
            messages += usize::from(op == OP_MESSAGE);
            rest = &body[len as usize..];
        }
    }
    None
}
