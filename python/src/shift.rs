//! `dexitac.ShiftTracker`: the contact centre's shift over frames (paper
//! Eq. 3), frame to frame and against a held anchor, in mm; the tactile
//! crate's [`ShiftTracker`] on the working-px centres.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use dexitac_tactile::displacement::ShiftTracker as RustTracker;
use dexitac_tactile::PointPx;

use crate::sensor::{Contact, Observation};

/// Follows the contact centre over frames: `update(obs)` returns the shift
/// against the previous frame's centre and against the held anchor, mm.
///
/// `dexitac analyze` writes these as `shift_mm` and `shift_from_anchor_mm`,
/// holding the first contact as the anchor (`hold_anchor()` after the
/// first `update` with a contact; its own `from_anchor_mm` is then 0).
#[pyclass(module = "dexitac")]
pub struct ShiftTracker {
    inner: RustTracker,
}

/// Frame-to-frame and from-anchor shift, mm (None without both centres).
#[pyclass(frozen, module = "dexitac")]
pub struct Shift {
    /// Against the previous frame's centre, mm.
    #[pyo3(get)]
    frame_to_frame_mm: Option<f64>,
    /// Against the held anchor, mm.
    #[pyo3(get)]
    from_anchor_mm: Option<f64>,
}

#[pymethods]
impl Shift {
    fn __repr__(&self) -> String {
        let mm = |v: Option<f64>| v.map_or("None".to_string(), |v| format!("{v:.4}"));
        format!(
            "Shift(frame_to_frame_mm={}, from_anchor_mm={})",
            mm(self.frame_to_frame_mm),
            mm(self.from_anchor_mm)
        )
    }
}

#[pymethods]
impl ShiftTracker {
    /// A tracker for a sensor of `mm_per_px` mm per working px
    /// (`Sensor.mm_per_px`).
    #[new]
    fn new(mm_per_px: f64) -> PyResult<Self> {
        if !(mm_per_px.is_finite() && mm_per_px > 0.0) {
            return Err(PyValueError::new_err(format!(
                "mm_per_px must be finite and > 0, got {mm_per_px}"
            )));
        }
        Ok(Self {
            inner: RustTracker::new(mm_per_px),
        })
    }

    /// Feeds the next frame: an `Observation` (its contact), a `Contact`,
    /// or None (no contact). Returns the shifts.
    fn update(&mut self, frame: Option<&Bound<'_, PyAny>>) -> PyResult<Shift> {
        let centre = match frame.filter(|f| !f.is_none()) {
            None => None,
            Some(f) => {
                if let Ok(obs) = f.cast::<Observation>() {
                    obs.get().contact_ref().map(Contact::centre_work)
                } else if let Ok(c) = f.cast::<Contact>() {
                    Some(c.get().centre_work())
                } else {
                    return Err(PyValueError::new_err(
                        "update takes an Observation, a Contact or None",
                    ));
                }
            }
        };
        let s = self.inner.update(centre);
        Ok(Shift {
            frame_to_frame_mm: s.frame_to_frame_mm,
            from_anchor_mm: s.from_anchor_mm,
        })
    }

    /// Holds the latest centre as the anchor; False when the latest frame
    /// had no contact (then no anchor is held).
    fn hold_anchor(&mut self) -> bool {
        self.inner.hold_anchor()
    }

    /// Drops the anchor.
    fn release_anchor(&mut self) {
        self.inner.release_anchor()
    }
}

impl Contact {
    /// The centre, working px.
    pub fn centre_work(&self) -> PointPx {
        PointPx::new(self.centre_work_px.0, self.centre_work_px.1)
    }
}
