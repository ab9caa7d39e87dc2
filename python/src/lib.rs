//! The dexitac tactile pipeline as a Python extension module, `import
//! dexitac` (built by maturin from `python/pyproject.toml`; the Python
//! API, its stubs and tests are in `python/`).
//!
//! numpy frames in, contacts out: `Sensor.from_rest(rest)`, then
//! `sensor.process(frame)`. Every call goes to the library functions the
//! `dexitac` binary calls (`frame::prepare`, `calibrate`, `Pipeline::run`,
//! `sensor_setup`, the rig crate's recording reader), so a frame gives the
//! same result here as in `dexitac analyze`, to the last digit. Bad input
//! raises `ValueError` (arrays, configs, frames) or `OSError` (files);
//! frames are borrowed from numpy without a copy, and the GIL is released
//! while a frame is processed.
#![warn(missing_docs)]

use std::path::PathBuf;

use numpy::{PyArrayDyn, PyArrayMethods};
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;

mod arrays;
mod config;
mod recording;
mod sensor;
mod shift;

/// Reads a PNG or JPEG file into a uint8 array as `dexitac analyze` decodes
/// it: (H, W) grey, (H, W, 3) RGB or (H, W, 4) RGBA (other pixel types
/// become grey).
#[pyfunction]
fn read_image(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyArrayDyn<u8>>> {
    let img = py.detach(|| {
        image::ImageReader::open(&path)
            .map_err(|e| PyOSError::new_err(format!("cannot open {}: {e}", path.display())))?
            .with_guessed_format()
            .map_err(|e| PyOSError::new_err(format!("cannot read {}: {e}", path.display())))?
            .decode()
            .map_err(|e| {
                PyValueError::new_err(format!("cannot decode image {}: {e}", path.display()))
            })
    })?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let (channels, data) = match img {
        image::DynamicImage::ImageLuma8(b) => (1, b.into_raw()),
        image::DynamicImage::ImageRgb8(b) => (3, b.into_raw()),
        image::DynamicImage::ImageRgba8(b) => (4, b.into_raw()),
        other => (1, other.to_luma8().into_raw()),
    };
    let shape: Vec<usize> = if channels == 1 {
        vec![h, w]
    } else {
        vec![h, w, channels]
    };
    numpy::PyArray1::from_vec(py, data).reshape(shape)
}

/// The dexitac tactile pipeline: numpy frames in, contacts out.
#[pymodule(name = "dexitac")]
fn dexitac_python(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<sensor::Sensor>()?;
    m.add_class::<sensor::Observation>()?;
    m.add_class::<sensor::Contact>()?;
    m.add_class::<sensor::StageTimes>()?;
    m.add_class::<sensor::TuneResult>()?;
    m.add_class::<sensor::HealthReport>()?;
    m.add_class::<shift::ShiftTracker>()?;
    m.add_class::<shift::Shift>()?;
    m.add_class::<recording::Recording>()?;
    m.add_class::<recording::RecordedFrameItem>()?;
    m.add_class::<recording::RecordedContact>()?;
    m.add_function(wrap_pyfunction!(sensor::tune, m)?)?;
    m.add_function(wrap_pyfunction!(recording::read_recording, m)?)?;
    m.add_function(wrap_pyfunction!(read_image, m)?)?;
    Ok(())
}
