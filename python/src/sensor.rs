//! `dexitac.Sensor`: one calibrated fingertip. It calls the library
//! functions `dexitac analyze` calls, in the same order: [`frame::prepare`]
//! on every frame, [`calibrate::calibrate_mapped`] (or
//! [`calibrate::calibrate_from_frames`]) on the rest, then
//! [`Pipeline::run`]; `tune` and `health` are those of `dexitac sensor`.

use std::time::Instant;

use numpy::PyArray2;
use pyo3::exceptions::{PyUserWarning, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyList;

use dexitac_rig::event;
use dexitac_tactile::area::WorkToInput;
use dexitac_tactile::calibrate;
use dexitac_tactile::density;
use dexitac_tactile::frame::GreyFrame;
use dexitac_tactile::params::FrameParams;
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::{FrameResult, Pipeline};
use dexitac_tactile::sensor_setup::{self, HealthLimits, HealthReport as RustHealth};
use dexitac_tactile::PointPx;

use crate::arrays::{self, FrameArray};
use crate::config;

/// A calibrated tactile sensor (one fingertip).
///
/// Make one with `Sensor.from_rest` (rest frames without contact) or
/// `Sensor.from_rest_frames` (no rest frame: estimated from the frames
/// themselves), then call `process` on each frame. All pixel coordinates
/// (`*_px`) are in the pixels of the arrays you pass (input px), as in the
/// CSV of `dexitac analyze`; frames are cropped and rescaled to the working
/// frame of the config inside.
#[pyclass(frozen, module = "dexitac")]
pub struct Sensor {
    pipeline: Pipeline,
    /// How an input frame becomes the working frame.
    prepare: FrameParams,
    /// Working px -> input px.
    map: WorkToInput,
    /// Input frame size (width, height), px.
    input_size: (usize, usize),
    /// The working rest frames (empty when estimated from frames).
    rest: Vec<GreyFrame>,
}

impl Sensor {
    /// A sensor whose input frames are working frames already (a
    /// recording's frames), calibrated as `dexitac replay` calibrates.
    pub fn from_working_frames(rest: Vec<GreyFrame>, params: Params) -> PyResult<Self> {
        let first = rest
            .first()
            .ok_or_else(|| PyValueError::new_err("no rest frame"))?;
        let (w, h) = (first.width(), first.height());
        let prepare = FrameParams {
            work_width_px: w as u32,
            work_height_px: h as u32,
            crop_px: None,
            keep_aspect: false,
            upscale: Some(1.0),
            ..params.frame.clone()
        };
        let cal = calibrate::calibrate(&rest, &params).map_err(calibration_error)?;
        Ok(Self {
            pipeline: Pipeline::new(cal, params),
            prepare,
            map: WorkToInput::IDENTITY,
            input_size: (w, h),
            rest,
        })
    }

    fn check_size(&self, frame: &FrameArray<'_>, what: &str) -> PyResult<()> {
        let (w, h) = self.input_size;
        if (frame.width, frame.height) != (w, h) {
            return Err(PyValueError::new_err(format!(
                "{what} is {}x{} px (W x H), the rest frame {w}x{h} px",
                frame.width, frame.height
            )));
        }
        Ok(())
    }

    fn first_rest(&self, what: &str) -> PyResult<&GreyFrame> {
        self.rest.first().ok_or_else(|| {
            PyValueError::new_err(format!(
                "{what} needs a rest frame: this sensor's rest was estimated from frames \
                 (Sensor.from_rest_frames); make one with Sensor.from_rest"
            ))
        })
    }

    fn to_input(&self, p: PointPx) -> (f64, f64) {
        let q = self.map.apply(p);
        (q.x, q.y)
    }

    fn points_input(&self, points: &[PointPx]) -> Vec<PointPx> {
        points.iter().map(|p| self.map.apply(*p)).collect()
    }

    /// Prepares frames (list or single array) as working frames.
    fn prepare_all(&self, frames: &Bound<'_, PyAny>, what: &str) -> PyResult<Vec<GreyFrame>> {
        let frames = sequence(frames, what)?;
        frames
            .iter()
            .enumerate()
            .map(|(k, f)| {
                let name = item_name(what, k, frames.len());
                let a = FrameArray::borrow(f, &name)?;
                self.check_size(&a, &name)?;
                Ok(a.prepare(&self.prepare, &name)?.grey)
            })
            .collect()
    }
}

/// Frames given as one array or a sequence of arrays.
fn sequence<'py>(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<Vec<Bound<'py, PyAny>>> {
    if obj.cast::<numpy::PyUntypedArray>().is_ok() {
        return Ok(vec![obj.clone()]);
    }
    if obj.is_instance_of::<pyo3::types::PyString>() {
        return Err(PyValueError::new_err(format!(
            "{what} must be numpy arrays (read files with dexitac.read_image)"
        )));
    }
    let items: Vec<Bound<'py, PyAny>> = obj
        .try_iter()
        .map_err(|_| {
            PyValueError::new_err(format!(
                "{what} must be a numpy array or a sequence of them"
            ))
        })?
        .collect::<PyResult<_>>()?;
    Ok(items)
}

/// `what[k]` in messages; plain `what` for a single array.
fn item_name(what: &str, k: usize, n: usize) -> String {
    if n == 1 {
        what.to_string()
    } else {
        format!("{what}[{k}]")
    }
}

fn calibration_error(e: calibrate::CalibrationError) -> PyErr {
    PyValueError::new_err(format!("rest calibration failed: {e}"))
}

/// A calibration on working frames ([`calibrated`]).
struct Calibrated {
    cal: calibrate::Calibration,
    /// The working frames it was made on.
    working: Vec<GreyFrame>,
    /// Working to input px.
    map: WorkToInput,
    /// The input frames' size, px.
    input_size: (usize, usize),
}

/// [`calibrate::calibrate_mapped`] or [`calibrate::calibrate_from_frames`].
type Calibrate = fn(
    &[GreyFrame],
    &Params,
    WorkToInput,
) -> Result<calibrate::Calibration, calibrate::CalibrationError>;

/// `calibrate` on `frames` prepared with `params`; when the pins are too
/// close for the detector, again on a working frame magnified as
/// `dexitac analyze` does ([`calibrate::upscale_for`], which `params`
/// then holds).
fn calibrated(
    py: Python<'_>,
    frames: &[Bound<'_, PyAny>],
    params: &mut Params,
    what: &str,
    calibrate: Calibrate,
) -> PyResult<Calibrated> {
    let (mut working, mut map, input_size) = prepare_rest(frames, params, what)?;
    let mut cal = py
        .detach(|| calibrate(&working, params, map))
        .map_err(calibration_error)?;
    if let Some(finer) = calibrate::upscale_for(&cal, &params.frame, input_size) {
        params.frame = finer;
        (working, map, _) = prepare_rest(frames, params, what)?;
        cal = py
            .detach(|| calibrate(&working, params, map))
            .map_err(calibration_error)?;
    }
    Ok(Calibrated {
        cal,
        working,
        map,
        input_size,
    })
}

/// Prepares each array of `frames` with the config's frame parameters;
/// all must have the same size. Returns the working frames, the map back to
/// input px and the input size.
fn prepare_rest(
    frames: &[Bound<'_, PyAny>],
    params: &Params,
    what: &str,
) -> PyResult<(Vec<GreyFrame>, WorkToInput, (usize, usize))> {
    let mut out = Vec::with_capacity(frames.len());
    let mut size = None;
    let mut map = WorkToInput::IDENTITY;
    for (k, f) in frames.iter().enumerate() {
        let name = item_name(what, k, frames.len());
        let a = FrameArray::borrow(f, &name)?;
        if let Some((w, h)) = size {
            if (a.width, a.height) != (w, h) {
                return Err(PyValueError::new_err(format!(
                    "{name} is {}x{} px, {what}[0] {w}x{h} px",
                    a.width, a.height
                )));
            }
        }
        size = Some((a.width, a.height));
        let p = a.prepare(&params.frame, &name)?;
        map = p.map();
        out.push(p.grey);
    }
    let size = size.ok_or_else(|| PyValueError::new_err(format!("{what}: no frame given")))?;
    Ok((out, map, size))
}

#[pymethods]
impl Sensor {
    /// Calibrates on one rest frame (no contact) or several (a list, their
    /// markers averaged), as `dexitac analyze --rest REST.png [--rest ...]`.
    ///
    /// `rest`: uint8 array (H, W) grey or (H, W, 3) RGB / (H, W, 4) RGBA,
    /// or a list of them. `config`: None (the paper's parameters), the
    /// sensor config as TOML text (str), a TOML file (pathlib.Path) or a
    /// dict of the same tables, e.g. `{"density": {"kernel_width_px": 12}}`.
    ///
    /// Pins closer than about 11 px (a small camera on a dense skin) are
    /// detected on a magnified working frame, as in `dexitac analyze`
    /// (`[frame] upscale`).
    ///
    /// Raises ValueError on a bad array or config, or when the rest frame
    /// shows too few markers; OSError when a config file cannot be read.
    /// Warns (UserWarning) when the rest's marker lattice has holes (a
    /// pressed rest, or the median image of taps).
    #[staticmethod]
    #[pyo3(signature = (rest, config=None))]
    fn from_rest(
        py: Python<'_>,
        rest: &Bound<'_, PyAny>,
        config: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let mut params = config::params(config)?;
        let frames = sequence(rest, "rest")?;
        let Calibrated {
            cal,
            working: rest,
            map,
            input_size,
        } = calibrated(
            py,
            &frames,
            &mut params,
            "rest",
            calibrate::calibrate_mapped,
        )?;
        if let Some(w) = cal.holey_rest_warning() {
            let msg =
                std::ffi::CString::new(w).map_err(|e| PyValueError::new_err(e.to_string()))?;
            PyErr::warn(py, py.get_type::<PyUserWarning>().as_any(), &msg, 1)?;
        }
        Ok(Self {
            prepare: params.frame.clone(),
            pipeline: Pipeline::new(cal, params),
            map,
            input_size,
            rest,
        })
    }

    /// No rest frame: estimates the rest from the frames themselves, as
    /// `dexitac analyze --rest-from-frames` (up to 63 evenly spaced frames;
    /// the pixel-wise median finds the pins, the frame nearest to it gives
    /// their places). When every frame presses the same place (a set of
    /// taps), the rest is a pressed skin (the lightest or the median
    /// press): only deeper presses are seen. Pins closer than about 11 px
    /// are detected on a magnified working frame, as in `from_rest`.
    #[staticmethod]
    #[pyo3(signature = (frames, config=None))]
    fn from_rest_frames(
        py: Python<'_>,
        frames: &Bound<'_, PyAny>,
        config: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let mut params = config::params(config)?;
        let all = sequence(frames, "frames")?;
        // The frames `dexitac analyze` picks: up to REST_FROM_FRAMES_MAX,
        // evenly spaced.
        let n = all.len().min(calibrate::REST_FROM_FRAMES_MAX);
        let picked: Vec<Bound<'_, PyAny>> =
            (0..n).map(|k| all[k * all.len() / n].clone()).collect();
        let Calibrated {
            cal,
            map,
            input_size,
            ..
        } = calibrated(
            py,
            &picked,
            &mut params,
            "frames",
            calibrate::calibrate_from_frames,
        )?;
        Ok(Self {
            prepare: params.frame.clone(),
            pipeline: Pipeline::new(cal, params),
            map,
            input_size,
            rest: Vec::new(),
        })
    }

    /// Runs the pipeline on one frame (same size and kind as the rest):
    /// grey, crop, rescale, markers, tracking, density, contact. With
    /// `density=True` the observation also carries the density on the whole
    /// grid (computed again after the pipeline, which only computes it near
    /// moved markers; not in the times).
    ///
    /// The GIL is released while the frame is processed: sensors in other
    /// threads run in parallel. Do not write to `frame` from another thread
    /// meanwhile (as for numpy's own functions that release the GIL).
    #[pyo3(signature = (frame, density=false))]
    fn process(
        &self,
        py: Python<'_>,
        frame: &Bound<'_, PyAny>,
        density: bool,
    ) -> PyResult<Observation> {
        let a = FrameArray::borrow(frame, "frame")?;
        self.check_size(&a, "frame")?;
        let raw = a.raw()?;
        let pipeline = &self.pipeline;
        let prepare = &self.prepare;
        let (prepare_ms, result, grid) = py.detach(|| {
            let t0 = Instant::now();
            let prepared = match dexitac_tactile::frame::prepare(&raw, prepare) {
                Ok(p) => p,
                Err(e) => return (0.0, Err(e.to_string()), None),
            };
            // As in `dexitac analyze`: preparation counts as detection.
            let prepare_ms = t0.elapsed().as_secs_f64() * 1e3;
            let result = pipeline.run(&prepared.grey).map_err(|e| e.to_string());
            let grid = match (&result, density) {
                (Ok(r), true) => Some(density::estimate(
                    &r.markers.positions(),
                    &pipeline.calibration.density,
                    None,
                )),
                _ => None,
            };
            (prepare_ms, result, grid)
        });
        let result = result.map_err(|e| PyValueError::new_err(format!("frame: {e}")))?;
        self.observation(py, &result, prepare_ms, grid)
    }

    /// Tunes the marker detector so the (first) rest frame shows `pins`
    /// markers, as `dexitac sensor tune --pins N`; returns the result with
    /// the tuned sensor config (TOML text, for `config=`). ValueError for
    /// pins < 7 or a sensor made by `from_rest_frames` (no rest frame).
    fn tune(&self, py: Python<'_>, pins: usize) -> PyResult<TuneResult> {
        let rest = self.first_rest("tune")?;
        let base = &self.pipeline.params;
        py.detach(|| tune_on(rest, pins, base))
    }

    /// Checks the skin on current no-contact frames against the (first)
    /// rest frame, as `dexitac sensor health`: missing, merged, extra,
    /// damaged or flickering markers, coverage, jitter; verdict "pass",
    /// "warn" or "fail". No frames: the rest frame is checked against
    /// itself. Not for a sensor made by `from_rest_frames` (ValueError).
    #[pyo3(signature = (frames=None, pins=None, min_coverage_pct=98.0, max_jitter_px=0.5))]
    fn health(
        &self,
        py: Python<'_>,
        frames: Option<&Bound<'_, PyAny>>,
        pins: Option<usize>,
        min_coverage_pct: f64,
        max_jitter_px: f64,
    ) -> PyResult<HealthReport> {
        let rest = self.first_rest("health")?;
        let frames = match frames {
            Some(f) => self.prepare_all(f, "frames")?,
            None => Vec::new(),
        };
        let limits_ok = (0.0..=100.0).contains(&min_coverage_pct)
            && max_jitter_px.is_finite()
            && max_jitter_px >= 0.0;
        if !limits_ok {
            return Err(PyValueError::new_err(
                "min_coverage_pct must lie in 0..=100, max_jitter_px >= 0",
            ));
        }
        let limits = HealthLimits {
            min_coverage: min_coverage_pct / 100.0,
            max_jitter_px,
            ..HealthLimits::default()
        };
        let params = &self.pipeline.params;
        let report = py
            .detach(|| sensor_setup::health(rest, &frames, params, &limits, pins))
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        Ok(HealthReport::new(report, self))
    }

    /// Rest marker positions, (N, 2) float64, input px. `displacements_px`
    /// of an observation has one row per rest marker, in this order.
    #[getter]
    fn rest_markers_px<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        arrays::points(
            py,
            &self.points_input(&self.pipeline.calibration.rest_markers),
        )
    }

    /// Median nearest-neighbour distance of the rest markers, working px.
    #[getter]
    fn pitch_work_px(&self) -> f64 {
        self.pipeline.calibration.pitch_px
    }

    /// Input frame size (width, height), px.
    #[getter]
    fn input_size_px(&self) -> (usize, usize) {
        self.input_size
    }

    /// Working frame size (width, height), px (after crop and rescale).
    #[getter]
    fn work_size_px(&self) -> (usize, usize) {
        let c = &self.pipeline.calibration;
        (c.width, c.height)
    }

    /// Sensor scale, mm per working px.
    #[getter]
    fn mm_per_px(&self) -> f64 {
        self.pipeline.params.frame.mm_per_px
    }

    /// Spacing of the density grid, working px (the grid's cell (j, i)
    /// samples working px (i, j) * step + (step - 1) / 2).
    #[getter]
    fn density_step_px(&self) -> usize {
        self.pipeline.calibration.density.grid().step_px
    }

    /// The rest density on the density grid, (rows, cols) float32,
    /// markers per mm^2.
    #[getter]
    fn rest_density<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let map = &self.pipeline.calibration.rest_density;
        arrays::grid(py, map.values_per_mm2.clone(), map.grid.ny, map.grid.nx)
    }

    /// The sensor config in use, as TOML text (every field).
    #[getter]
    fn config_toml(&self) -> String {
        sensor_setup::params_toml(&self.pipeline.params, "Sensor config of a dexitac.Sensor.")
    }

    fn __repr__(&self) -> String {
        let c = &self.pipeline.calibration;
        format!(
            "Sensor({} rest markers, pitch {:.1} working px, input {}x{} px, working {}x{} px, skin {})",
            c.rest_markers.len(),
            c.pitch_px,
            self.input_size.0,
            self.input_size.1,
            c.width,
            c.height,
            c.surface.describe(&c.rest_markers)
        )
    }
}

impl Sensor {
    fn observation(
        &self,
        py: Python<'_>,
        r: &FrameResult,
        prepare_ms: f64,
        grid: Option<density::DensityMap>,
    ) -> PyResult<Observation> {
        let markers = self.points_input(&r.markers.positions());
        let (sx, sy) = (self.map.scale_x, self.map.scale_y);
        let disp: Vec<PointPx> = r
            .field
            .displacement
            .iter()
            .map(|u| match u {
                Some(u) => PointPx::new(u.x * sx, u.y * sy),
                None => PointPx::new(f64::NAN, f64::NAN),
            })
            .collect();
        let contact = r.contact.map(|c| {
            let mm = event::centre_mm(&self.pipeline, c.centre);
            Contact {
                centre_px: self.to_input(c.centre),
                centre_work_px: (c.centre.x, c.centre.y),
                centre_mm: (mm.x_mm, mm.y_mm),
                area_mm2: c.area_mm2,
                source: c.source.name(),
            }
        });
        let t = r.times;
        let density = match grid {
            Some(g) => Some(arrays::grid(py, g.values_per_mm2, g.grid.ny, g.grid.nx)?.unbind()),
            None => None,
        };
        Ok(Observation {
            contact,
            markers_px: arrays::points(py, &markers)?.unbind(),
            displacements_px: arrays::points(py, &disp)?.unbind(),
            n_markers: r.markers.len(),
            skipped: r.skipped,
            blank: r.blank,
            times: StageTimes {
                prepare_ms,
                detect_ms: prepare_ms + t.detect_ms,
                kde_ms: t.kde_ms,
                segment_ms: t.segment_ms,
                total_ms: prepare_ms + t.total_ms,
            },
            density,
        })
    }
}

/// `dexitac sensor tune` on a working rest frame.
pub fn tune_on(rest: &GreyFrame, pins: usize, base: &Params) -> PyResult<TuneResult> {
    let before = sensor_setup::count_markers(rest, &base.markers);
    let r =
        sensor_setup::tune(rest, pins, base).map_err(|e| PyValueError::new_err(e.to_string()))?;
    let tuned = Params {
        markers: r.markers.clone(),
        ..base.clone()
    };
    let summary = r.summary(before);
    let text = sensor_setup::params_toml(
        &tuned,
        &format!("Sensor config tuned by dexitac.Sensor.tune.\n{summary}"),
    );
    // The text must load back as the tuned parameters.
    Params::from_toml_str(&text)
        .map_err(|e| PyValueError::new_err(format!("internal: tuned config invalid: {e}")))?;
    Ok(TuneResult {
        config_toml: text,
        found: r.found,
        pins: r.pins,
        exact: r.exact,
        ratio_range: r.ratio_range,
        tried: r.tried,
        holes: r.holes,
        summary,
    })
}

/// A contact: where and how large.
#[pyclass(frozen, module = "dexitac")]
#[derive(Clone)]
pub struct Contact {
    /// Contact centre (x, y), input px (the `cx`, `cy` of `dexitac analyze`).
    #[pyo3(get)]
    centre_px: (f64, f64),
    /// Contact centre (x, y), working px (what a recording stores).
    #[pyo3(get)]
    pub(crate) centre_work_px: (f64, f64),
    /// Contact centre (x, y), mm from the working frame's centre.
    #[pyo3(get)]
    centre_mm: (f64, f64),
    /// Contact area, mm^2.
    #[pyo3(get)]
    area_mm2: f64,
    /// How the centre was found: "density", "density+tracking" or "tracking".
    #[pyo3(get)]
    source: &'static str,
}

#[pymethods]
impl Contact {
    fn __repr__(&self) -> String {
        format!(
            "Contact(centre_px=({:.3}, {:.3}), centre_mm=({:.3}, {:.3}), area_mm2={:.3}, source={:?})",
            self.centre_px.0,
            self.centre_px.1,
            self.centre_mm.0,
            self.centre_mm.1,
            self.area_mm2,
            self.source
        )
    }
}

/// Wall-clock time per stage of one frame, ms (single thread, measured in
/// Rust; the columns of `dexitac analyze`).
#[pyclass(frozen, module = "dexitac")]
#[derive(Clone, Copy)]
pub struct StageTimes {
    /// Grey, crop and rescale.
    #[pyo3(get)]
    prepare_ms: f64,
    /// Preparation and marker detection (`t_detect_ms`).
    #[pyo3(get)]
    detect_ms: f64,
    /// Tracking and kernel density (`t_kde_ms`).
    #[pyo3(get)]
    kde_ms: f64,
    /// Region, centre and contact (`t_segment_ms`).
    #[pyo3(get)]
    segment_ms: f64,
    /// The whole frame, preparation included (`t_total_ms`).
    #[pyo3(get)]
    total_ms: f64,
}

#[pymethods]
impl StageTimes {
    fn __repr__(&self) -> String {
        format!(
            "StageTimes(prepare_ms={:.4}, detect_ms={:.4}, kde_ms={:.4}, segment_ms={:.4}, total_ms={:.4})",
            self.prepare_ms, self.detect_ms, self.kde_ms, self.segment_ms, self.total_ms
        )
    }
}

/// The result of one frame.
#[pyclass(frozen, module = "dexitac")]
pub struct Observation {
    /// The contact, or None.
    #[pyo3(get)]
    contact: Option<Contact>,
    /// Detected marker centres, (N, 2) float64, input px.
    #[pyo3(get)]
    markers_px: Py<PyArray2<f64>>,
    /// Per rest marker (`Sensor.rest_markers_px` order), its displacement
    /// (dx, dy), (M, 2) float64, input px; NaN where the marker was lost.
    /// In a frame blurrier than the rest, the blur's own shift of each
    /// centroid is taken off, and markers it shifts by 1 px or more are NaN.
    #[pyo3(get)]
    displacements_px: Py<PyArray2<f64>>,
    /// Number of detected markers.
    #[pyo3(get)]
    n_markers: usize,
    /// No marker moved strongly (or blank frame): the density stages were
    /// skipped (the `skipped` column of `dexitac analyze`).
    #[pyo3(get)]
    skipped: bool,
    /// Fewer than half the rest markers were found (covered, blank or not a
    /// tactile frame): no contact reported.
    #[pyo3(get)]
    blank: bool,
    /// Per-stage times.
    #[pyo3(get)]
    times: StageTimes,
    /// With `process(frame, density=True)`: the marker density on the
    /// density grid, (rows, cols) float32, markers per mm^2; else None.
    #[pyo3(get)]
    density: Option<Py<PyArray2<f32>>>,
}

impl Observation {
    /// The contact, if any.
    pub fn contact_ref(&self) -> Option<&Contact> {
        self.contact.as_ref()
    }
}

#[pymethods]
impl Observation {
    fn __repr__(&self) -> String {
        let contact = self
            .contact
            .as_ref()
            .map_or("None".to_string(), |c| c.__repr__());
        format!(
            "Observation(contact={contact}, n_markers={}, skipped={}, total_ms={:.4})",
            self.n_markers,
            if self.skipped { "True" } else { "False" },
            self.times.total_ms
        )
    }
}

/// What `Sensor.tune` found.
#[pyclass(frozen, module = "dexitac")]
pub struct TuneResult {
    /// The sensor config with the tuned `[markers]` (TOML text; pass it as
    /// `config=` or write it to a file).
    #[pyo3(get)]
    config_toml: String,
    /// Markers found with the tuned setting.
    #[pyo3(get)]
    found: usize,
    /// The pin count asked for.
    #[pyo3(get)]
    pins: usize,
    /// True when exactly `pins` markers are found.
    #[pyo3(get)]
    exact: bool,
    /// The strength thresholds around the chosen one that also find `pins`.
    #[pyo3(get)]
    ratio_range: Option<(f32, f32)>,
    /// Settings tried.
    #[pyo3(get)]
    tried: usize,
    /// The rest's marker lattice has holes with the tuned setting (a pressed
    /// rest, or the median image of taps): the count is not to be trusted.
    #[pyo3(get)]
    holes: bool,
    /// One line, as `dexitac sensor tune` logs it.
    #[pyo3(get)]
    summary: String,
}

#[pymethods]
impl TuneResult {
    fn __repr__(&self) -> String {
        format!("TuneResult({})", self.summary)
    }
}

/// What `Sensor.health` found. Positions are (N, 2) float64, input px.
#[pyclass(frozen, module = "dexitac")]
pub struct HealthReport {
    report: RustHealth,
    map: WorkToInput,
}

impl HealthReport {
    fn new(report: RustHealth, sensor: &Sensor) -> Self {
        Self {
            report,
            map: sensor.map,
        }
    }

    fn list<'py>(&self, py: Python<'py>, list: &[PointPx]) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let p: Vec<PointPx> = list.iter().map(|p| self.map.apply(*p)).collect();
        arrays::points(py, &p)
    }
}

#[pymethods]
impl HealthReport {
    /// "pass", "warn" or "fail" (exit 0, 1, 2 of `dexitac sensor health`).
    #[getter]
    fn verdict(&self) -> String {
        self.report.verdict.to_string().to_lowercase()
    }
    /// Why the verdict is not a pass, one reason per item.
    #[getter]
    fn reasons<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        PyList::new(py, &self.report.reasons)
    }
    /// Rest markers (the reference).
    #[getter]
    fn rest_markers(&self) -> usize {
        self.report.rest_markers
    }
    /// Rest marker pitch, working px.
    #[getter]
    fn pitch_work_px(&self) -> f64 {
        self.report.pitch_px
    }
    /// Frames checked.
    #[getter]
    fn frames(&self) -> usize {
        self.report.frames
    }
    /// Rest markers missing in at least half the frames.
    #[getter]
    fn missing_px<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.list(py, &self.report.missing)
    }
    /// Rest markers missing in some frames, fewer than half.
    #[getter]
    fn flickering_px<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.list(py, &self.report.flickering)
    }
    /// Detections standing for two or more missing rest markers.
    #[getter]
    fn merged_px<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.list(py, &self.report.merged)
    }
    /// Other detections with no rest marker.
    #[getter]
    fn extra_px<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.list(py, &self.report.extra)
    }
    /// Weak or shifted markers (rest positions).
    #[getter]
    fn damaged_px<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        self.list(py, &self.report.damaged)
    }
    /// Worst frame's fraction (0..1) of the sensing area at or above the
    /// contact threshold.
    #[getter]
    fn coverage(&self) -> f64 {
        self.report.coverage
    }
    /// Median and largest per-marker jitter, working px (None with fewer
    /// than two frames).
    #[getter]
    fn jitter_work_px(&self) -> Option<(f64, f64)> {
        self.report.jitter_px
    }

    fn __repr__(&self) -> String {
        let r = &self.report;
        format!(
            "HealthReport(verdict={:?}, rest_markers={}, frames={}, missing={}, merged={}, extra={}, \
             damaged={}, flickering={}, coverage={:.3})",
            self.verdict(),
            r.rest_markers,
            r.frames,
            r.missing.len(),
            r.merged.len(),
            r.extra.len(),
            r.damaged.len(),
            r.flickering.len(),
            r.coverage
        )
    }
}

/// Tunes the detector on a rest frame before any sensor exists (a skin the
/// default detector cannot calibrate on); see `Sensor.tune`.
#[pyfunction]
#[pyo3(signature = (rest, pins, config=None))]
pub fn tune(
    py: Python<'_>,
    rest: &Bound<'_, PyAny>,
    pins: usize,
    config: Option<&Bound<'_, PyAny>>,
) -> PyResult<TuneResult> {
    let params = config::params(config)?;
    let a = FrameArray::borrow(rest, "rest")?;
    let grey = a.prepare(&params.frame, "rest")?.grey;
    py.detach(|| tune_on(&grey, pins, &params))
}
