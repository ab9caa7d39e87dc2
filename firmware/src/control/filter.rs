//! Tick-to-tick filtering of one tank's pressure: a moving average.
//!
//! Input: one pressure per tick (already the trimmed mean of
//! [`crate::sensor::OVERSAMPLE`] conversions). Output: the mean of the last
//! [`FILTER_TICKS`] values, in pascal. With white noise of standard
//! deviation σ per conversion, the filtered value has about
//! σ / sqrt(4 · 16) = σ / 8. A step reaches the output fully
//! [`FILTER_TICKS`] ticks later (a ramp lags by half of that).

/// Ticks in the moving average (16 ms at 1 kHz).
pub const FILTER_TICKS: usize = 16;

/// A moving average over the last [`FILTER_TICKS`] values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MovingAverage {
    window: [i32; FILTER_TICKS],
    next: usize,
    len: usize,
    sum: i64,
}

impl Default for MovingAverage {
    fn default() -> Self {
        Self::new()
    }
}

impl MovingAverage {
    /// An empty filter.
    pub const fn new() -> Self {
        MovingAverage {
            window: [0; FILTER_TICKS],
            next: 0,
            len: 0,
            sum: 0,
        }
    }

    /// Adds `value_pa`; returns the mean of the values held (at most
    /// [`FILTER_TICKS`]), rounded toward zero.
    pub fn push(&mut self, value_pa: i32) -> i32 {
        if let Some(slot) = self.window.get_mut(self.next) {
            if self.len == FILTER_TICKS {
                self.sum -= i64::from(*slot);
            } else {
                self.len += 1;
            }
            *slot = value_pa;
            self.sum += i64::from(value_pa);
        }
        self.next = (self.next + 1) % FILTER_TICKS;
        self.mean()
    }

    /// The mean of the values held (0 when empty).
    pub fn mean(&self) -> i32 {
        // len <= FILTER_TICKS, and the mean of i32 values fits an i32.
        let n = i64::try_from(self.len.max(1)).unwrap_or(1);
        i32::try_from(self.sum / n).unwrap_or(0)
    }

    /// Whether the window is full.
    pub const fn is_full(&self) -> bool {
        self.len == FILTER_TICKS
    }

    /// Forgets every value.
    pub fn reset(&mut self) {
        *self = Self::new();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_reaches_the_output_after_the_window() {
        let mut f = MovingAverage::new();
        for _ in 0..FILTER_TICKS {
            f.push(0);
        }
        let mut out = 0;
        for _ in 0..FILTER_TICKS {
            out = f.push(16_000);
        }
        assert_eq!(out, 16_000);
        let mut f2 = f;
        f2.push(0);
        assert_eq!(f2.mean(), 15_000);
    }

    #[test]
    fn partial_window_averages_what_it_has() {
        let mut f = MovingAverage::new();
        assert_eq!(f.push(100), 100);
        assert_eq!(f.push(300), 200);
        assert!(!f.is_full());
    }
}
