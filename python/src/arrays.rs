//! numpy arrays in and out: frames are borrowed (no copy) after their
//! dtype, shape and layout are checked; results are handed to numpy as
//! owned arrays (the `Vec` moves, nothing is copied).

use numpy::{
    PyArray1, PyArray2, PyArrayDyn, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use dexitac_tactile::frame::{self, Prepared, RawFrame, MAX_SIDE_PX};
use dexitac_tactile::params::FrameParams;
use dexitac_tactile::PointPx;

/// A frame array checked and borrowed from numpy: `uint8`, `(H, W)` grey or
/// `(H, W, C)` with C = 1, 3 (RGB) or 4 (RGBA), C-contiguous, not empty.
pub struct FrameArray<'py> {
    array: PyReadonlyArrayDyn<'py, u8>,
    /// Width, px.
    pub width: usize,
    /// Height, px.
    pub height: usize,
    /// Channels per pixel.
    pub channels: usize,
}

impl<'py> FrameArray<'py> {
    /// Checks `obj` (`what` names it in errors) and borrows its pixels.
    pub fn borrow(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<Self> {
        let Ok(untyped) = obj.cast::<PyUntypedArray>() else {
            return Err(PyValueError::new_err(format!(
                "{what} must be a numpy.ndarray of dtype uint8, got {}",
                type_name(obj)
            )));
        };
        let Ok(typed) = obj.cast::<PyArrayDyn<u8>>() else {
            return Err(PyValueError::new_err(format!(
                "{what} must have dtype uint8, got {} (convert with frame.astype(np.uint8) \
                 after scaling to 0..255)",
                untyped.dtype().str().map_or("?".into(), |s| s.to_string())
            )));
        };
        let shape = typed.shape().to_vec();
        let (height, width, channels) = match shape[..] {
            [h, w] => (h, w, 1),
            [h, w, c] if matches!(c, 1 | 3 | 4) => (h, w, c),
            _ => {
                return Err(PyValueError::new_err(format!(
                    "{what} must have shape (H, W) or (H, W, C) with C = 1, 3 (RGB) or 4 (RGBA), \
                     got {shape:?}"
                )))
            }
        };
        if width == 0 || height == 0 {
            return Err(PyValueError::new_err(format!(
                "{what} is empty (shape {shape:?})"
            )));
        }
        if width > MAX_SIDE_PX || height > MAX_SIDE_PX {
            return Err(PyValueError::new_err(format!(
                "{what} is {width}x{height} px; the largest side accepted is {MAX_SIDE_PX} px"
            )));
        }
        if !typed.is_c_contiguous() {
            return Err(PyValueError::new_err(format!(
                "{what} must be C-contiguous (a slice or transpose is a strided view): pass \
                 np.ascontiguousarray({what})"
            )));
        }
        let array = typed.try_readonly().map_err(|e| {
            PyValueError::new_err(format!("{what} cannot be borrowed for reading: {e}"))
        })?;
        Ok(Self {
            array,
            width,
            height,
            channels,
        })
    }

    /// The borrowed pixels as the pipeline's raw frame.
    pub fn raw(&self) -> PyResult<RawFrame<'_>> {
        let data = self.array.as_slice().map_err(|e| {
            PyValueError::new_err(format!("frame pixels cannot be read in place: {e}"))
        })?;
        Ok(RawFrame {
            width: self.width,
            height: self.height,
            channels: self.channels,
            data,
        })
    }

    /// Grey, crop and rescale to the working frame ([`frame::prepare`]),
    /// read straight from the numpy buffer.
    pub fn prepare(&self, params: &FrameParams, what: &str) -> PyResult<Prepared> {
        frame::prepare(&self.raw()?, params)
            .map_err(|e| PyValueError::new_err(format!("{what}: {e}")))
    }
}

fn type_name(obj: &Bound<'_, PyAny>) -> String {
    obj.get_type()
        .name()
        .map_or_else(|_| "?".to_string(), |n| n.to_string())
}

/// `(N, 2)` float64 array of points.
pub fn points<'py>(py: Python<'py>, points: &[PointPx]) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let flat: Vec<f64> = points.iter().flat_map(|p| [p.x, p.y]).collect();
    PyArray1::from_vec(py, flat).reshape([points.len(), 2])
}

/// `(rows, cols)` array from a row-major `Vec`.
pub fn grid<'py, T: numpy::Element>(
    py: Python<'py>,
    values: Vec<T>,
    rows: usize,
    cols: usize,
) -> PyResult<Bound<'py, PyArray2<T>>> {
    PyArray1::from_vec(py, values).reshape([rows, cols])
}
