//! Stage 6, displacement of the contact centre (Sec. III-B, Eq. 3):
//! `D(t) = |c(t+1) - c(t)|`, Euclidean, in mm, frame to frame and against a
//! held anchor (SPEC section 4: a slow slip moves the centre little per
//! frame, so the grasp logic also compares with the centre held when the
//! grasp became stable). The px -> mm conversion lives here and only here.

use crate::PointPx;

/// Euclidean distance between two working-frame points, mm.
pub fn distance_mm(a: PointPx, b: PointPx, mm_per_px: f64) -> f64 {
    (a.x - b.x).hypot(a.y - b.y) * mm_per_px
}

/// Shifts of the current contact centre.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Shift {
    /// Against the previous frame's centre, mm (`None` without both).
    pub frame_to_frame_mm: Option<f64>,
    /// Against the held anchor, mm (`None` without an anchor or a contact).
    pub from_anchor_mm: Option<f64>,
}

/// Follows the contact centre over frames.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ShiftTracker {
    mm_per_px: f64,
    previous: Option<PointPx>,
    anchor: Option<PointPx>,
}

impl ShiftTracker {
    /// A tracker for a sensor of `mm_per_px`.
    pub fn new(mm_per_px: f64) -> Self {
        Self {
            mm_per_px,
            previous: None,
            anchor: None,
        }
    }

    /// Feeds the next frame's centre (`None`: no contact) and returns the
    /// shifts.
    pub fn update(&mut self, centre: Option<PointPx>) -> Shift {
        let d = |a: Option<PointPx>| Some(distance_mm(a?, centre?, self.mm_per_px));
        let shift = Shift {
            frame_to_frame_mm: d(self.previous),
            from_anchor_mm: d(self.anchor),
        };
        self.previous = centre;
        shift
    }

    /// Holds the latest centre as the anchor (e.g. when the grasp became
    /// stable). Returns false when there is no centre to hold.
    pub fn hold_anchor(&mut self) -> bool {
        self.anchor = self.previous;
        self.anchor.is_some()
    }

    /// Drops the anchor.
    pub fn release_anchor(&mut self) {
        self.anchor = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slow_drift_is_small_per_frame_but_large_from_the_anchor() {
        let mut t = ShiftTracker::new(0.1);
        assert_eq!(t.update(Some(PointPx::new(100.0, 100.0))), Shift::default());
        assert!(t.hold_anchor());
        let mut last = Shift::default();
        for k in 1..=60 {
            last = t.update(Some(PointPx::new(100.0 + k as f64, 100.0)));
            assert!((last.frame_to_frame_mm.unwrap() - 0.1).abs() < 1e-9);
        }
        assert!((last.from_anchor_mm.unwrap() - 6.0).abs() < 1e-9);
        assert_eq!(t.update(None), Shift::default());
        t.release_anchor();
        assert_eq!(t.update(Some(PointPx::new(0.0, 0.0))).from_anchor_mm, None);
    }
}
