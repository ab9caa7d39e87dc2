//! `dexitac.read_recording`: an MCAP recording (`dexitac record`, or
//! `sim`/`run --record --record-frames`) read with the rig crate's reader;
//! its frames as numpy arrays, each with the observation recorded for it.

use std::collections::{HashMap, VecDeque};
use std::path::PathBuf;

use numpy::PyArray2;
use pyo3::exceptions::{PyIndexError, PyOSError, PyValueError};
use pyo3::prelude::*;

use dexitac_rig::recording::{ContactMsg, ReadError, RecordedFrame, Recording as RigRecording};
use dexitac_tactile::frame::GreyFrame;
use dexitac_tactile::params::Params;

use crate::arrays;
use crate::config;
use crate::sensor::Sensor;

/// An MCAP recording read into memory (frames stay PNG-encoded until
/// iterated). Iterate it for its frames in file order
/// (`RecordedFrame`: sensor, time, frame, recorded observation).
#[pyclass(frozen, module = "dexitac")]
pub struct Recording {
    inner: RigRecording,
    /// Per frame of `inner.frames`, the contact recorded for it (paired by
    /// sensor and capture time, in order, as `dexitac replay` pairs them).
    recorded: Vec<Option<ContactMsg>>,
}

/// Reads the recording at `path`. A damaged or unfinished file raises
/// ValueError unless `recover=True` (then the messages before the damage
/// are kept; see `Recording.damage`). OSError when the file cannot be read.
#[pyfunction]
#[pyo3(signature = (path, recover=false))]
pub fn read_recording(py: Python<'_>, path: PathBuf, recover: bool) -> PyResult<Recording> {
    let inner = py
        .detach(|| RigRecording::open(&path, recover))
        .map_err(|e| match e {
            ReadError::Io { .. } => PyOSError::new_err(e.to_string()),
            other => PyValueError::new_err(other.to_string()),
        })?;
    let mut queue: HashMap<(usize, u64), VecDeque<ContactMsg>> = HashMap::new();
    for c in &inner.contacts {
        queue
            .entry((c.sensor, c.t_ms))
            .or_default()
            .push_back(c.clone());
    }
    let recorded = inner
        .frames
        .iter()
        .map(|f| {
            queue
                .get_mut(&(f.sensor, f.t_ms))
                .and_then(VecDeque::pop_front)
        })
        .collect();
    Ok(Recording { inner, recorded })
}

fn decode(f: &RecordedFrame) -> PyResult<GreyFrame> {
    f.decode().map_err(|e| {
        PyValueError::new_err(format!(
            "sensor {} frame at {} ms: cannot decode: {e}",
            f.sensor, f.t_ms
        ))
    })
}

fn grey_array<'py>(py: Python<'py>, g: GreyFrame) -> PyResult<Bound<'py, PyArray2<u8>>> {
    let (w, h) = (g.width(), g.height());
    arrays::grid(py, g.data().to_vec(), h, w)
}

#[pymethods]
impl Recording {
    /// The file.
    #[getter]
    fn path(&self) -> PathBuf {
        self.inner.path.clone()
    }

    /// The sensors with frames, contacts or rest frames.
    #[getter]
    fn sensors(&self) -> Vec<usize> {
        self.inner.sensors()
    }

    /// The sensor config (TOML text) the recording was made with, if one
    /// was given.
    #[getter]
    fn sensor_config_toml(&self) -> Option<String> {
        self.inner
            .session
            .as_ref()
            .and_then(|s| s.sensor_config_toml.clone())
    }

    /// What made it: "sim", "run", "record", ...
    #[getter]
    fn source(&self) -> Option<String> {
        self.inner.session.as_ref().map(|s| s.source.clone())
    }

    /// Free text of the session (scenario, frame folders, ...).
    #[getter]
    fn description(&self) -> Option<String> {
        self.inner.session.as_ref().map(|s| s.description.clone())
    }

    /// With `recover=True`: what was wrong with the file, else None.
    #[getter]
    fn damage(&self) -> Option<String> {
        self.inner.damage.clone()
    }

    /// The rest frames sensor `sensor` was calibrated on, (H, W) uint8
    /// working frames (empty when none were recorded).
    fn rest_frames<'py>(
        &self,
        py: Python<'py>,
        sensor: usize,
    ) -> PyResult<Vec<Bound<'py, PyArray2<u8>>>> {
        self.inner
            .rest
            .get(&sensor)
            .map_or(&[][..], Vec::as_slice)
            .iter()
            .map(|f| grey_array(py, decode(f)?))
            .collect()
    }

    /// A `Sensor` calibrated as `dexitac replay` calibrates it: on the
    /// sensor's recorded rest frames, else on its first `rest_frames`
    /// frames; `config` None = the recording's sensor config, else the
    /// paper's parameters. Its `process` on this recording's frames
    /// reproduces the recorded contacts (`centre_work_px`) exactly.
    #[pyo3(signature = (sensor=0, config=None, rest_frames=1))]
    fn sensor(
        &self,
        py: Python<'_>,
        sensor: usize,
        config: Option<&Bound<'_, PyAny>>,
        rest_frames: usize,
    ) -> PyResult<Sensor> {
        let params = match (config.filter(|c| !c.is_none()), self.sensor_config_toml()) {
            (Some(c), _) => config::params(Some(c))?,
            (None, Some(text)) => Params::from_toml_str(&text).map_err(|e| {
                PyValueError::new_err(format!("the recording's sensor config: {e}"))
            })?,
            (None, None) => Params::default(),
        };
        let frames: Vec<&RecordedFrame> = match self.inner.rest.get(&sensor) {
            Some(rest) if !rest.is_empty() => rest.iter().collect(),
            _ => self
                .inner
                .frames_of(sensor)
                .take(rest_frames.max(1))
                .collect(),
        };
        if frames.is_empty() {
            return Err(PyValueError::new_err(format!(
                "sensor {sensor} has no frames in this recording (sensors: {:?})",
                self.inner.sensors()
            )));
        }
        let rest = py.detach(|| frames.into_iter().map(decode).collect::<PyResult<Vec<_>>>())?;
        Sensor::from_working_frames(rest, params)
    }

    fn __len__(&self) -> usize {
        self.inner.frames.len()
    }

    /// The `index`-th frame of the file (all sensors, file order).
    fn __getitem__(&self, py: Python<'_>, index: isize) -> PyResult<RecordedFrameItem> {
        let n = self.inner.frames.len() as isize;
        let k = if index < 0 { index + n } else { index };
        if !(0..n).contains(&k) {
            return Err(PyIndexError::new_err(format!(
                "frame {index} of a recording with {n} frames"
            )));
        }
        self.item(py, k as usize)
    }

    fn __iter__(slf: Bound<'_, Self>) -> RecordingIter {
        RecordingIter {
            recording: slf.unbind(),
            next: 0,
        }
    }

    fn __repr__(&self) -> String {
        format!(
            "Recording({}, sensors {:?}, {} frames, {} contacts)",
            self.inner.path.display(),
            self.inner.sensors(),
            self.inner.frames.len(),
            self.inner.contacts.len()
        )
    }
}

impl Recording {
    fn item(&self, py: Python<'_>, k: usize) -> PyResult<RecordedFrameItem> {
        let f = &self.inner.frames[k];
        let grey = py.detach(|| decode(f))?;
        Ok(RecordedFrameItem {
            sensor: f.sensor,
            t_ms: f.t_ms,
            frame: grey_array(py, grey)?.unbind(),
            recorded: self.recorded[k].as_ref().map(RecordedContact::from),
        })
    }
}

/// Iterator over a recording's frames.
#[pyclass(module = "dexitac")]
pub struct RecordingIter {
    recording: Py<Recording>,
    next: usize,
}

#[pymethods]
impl RecordingIter {
    fn __iter__(slf: PyRef<'_, Self>) -> PyRef<'_, Self> {
        slf
    }

    fn __next__(&mut self, py: Python<'_>) -> PyResult<Option<RecordedFrameItem>> {
        let rec = self.recording.get();
        if self.next >= rec.inner.frames.len() {
            return Ok(None);
        }
        let item = rec.item(py, self.next)?;
        self.next += 1;
        Ok(Some(item))
    }
}

/// One recorded frame and the observation recorded with it.
#[pyclass(frozen, name = "RecordedFrame", module = "dexitac")]
pub struct RecordedFrameItem {
    /// The sensor.
    #[pyo3(get)]
    sensor: usize,
    /// Capture time on the recording's clock, ms.
    #[pyo3(get)]
    t_ms: u64,
    /// The working frame, (H, W) uint8.
    #[pyo3(get)]
    frame: Py<PyArray2<u8>>,
    /// What the pipeline found when the frame was recorded (None when the
    /// recording has no contact message for it).
    #[pyo3(get)]
    recorded: Option<RecordedContact>,
}

#[pymethods]
impl RecordedFrameItem {
    fn __repr__(&self) -> String {
        format!(
            "RecordedFrame(sensor={}, t_ms={}, recorded={})",
            self.sensor,
            self.t_ms,
            self.recorded
                .as_ref()
                .map_or("None".into(), RecordedContact::__repr__)
        )
    }
}

/// A recorded pipeline result (`dexitac.Contact` message).
#[pyclass(frozen, module = "dexitac")]
#[derive(Clone)]
pub struct RecordedContact {
    /// Whether a contact was found.
    #[pyo3(get)]
    found: bool,
    /// Contact centre (x, y), working px, exact.
    #[pyo3(get)]
    centre_work_px: Option<(f64, f64)>,
    /// Contact centre (x, y), mm from the working frame's centre.
    #[pyo3(get)]
    centre_mm: Option<(f64, f64)>,
    /// Contact area, mm^2.
    #[pyo3(get)]
    area_mm2: Option<f64>,
    /// How the centre was found ("density", "density+tracking", "tracking").
    #[pyo3(get)]
    source: Option<String>,
    /// Detected markers.
    #[pyo3(get)]
    n_markers: usize,
    /// Pipeline time when recorded, ms.
    #[pyo3(get)]
    pipeline_ms: f64,
}

impl From<&ContactMsg> for RecordedContact {
    fn from(c: &ContactMsg) -> Self {
        Self {
            found: c.found,
            centre_work_px: c.centre_px.map(|p| (p.x, p.y)),
            centre_mm: c.centre_mm.map(|p| (p.x, p.y)),
            area_mm2: c.area_mm2,
            source: c.method.clone(),
            n_markers: c.markers,
            pipeline_ms: c.pipeline_ms,
        }
    }
}

#[pymethods]
impl RecordedContact {
    fn __repr__(&self) -> String {
        match self.centre_work_px {
            Some((x, y)) if self.found => format!(
                "RecordedContact(centre_work_px=({x:.3}, {y:.3}), n_markers={})",
                self.n_markers
            ),
            _ => format!("RecordedContact(none, n_markers={})", self.n_markers),
        }
    }
}
