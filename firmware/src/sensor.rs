//! Tank pressure sensors: 12-bit ADC counts -> gauge pressure in pascal.
//!
//! The sensors measure -100..300 kPa with a ratiometric analog output of
//! 10 %..90 % of their 5 V supply (0.5..4.5 V), divided by 2/3 to the
//! STM32's 3.3 V ADC range: 0.33..3.0 V, i.e. about 410..3686 counts of the
//! 12-bit ADC. The linear map between the two ends is the calibration
//! ([`SensorCalibration`]); **[`CALIBRATION`] is the one place to change it**
//! for another sensor or divider. A count outside the band (plus a margin)
//! means an open or shorted wire: [`SensorError::OutOfRange`].
//!
//! ```
//! use dexitac_firmware::sensor::CALIBRATION;
//! assert_eq!(CALIBRATION.counts_to_pa(CALIBRATION.counts_at_min), Ok(-100_000));
//! assert_eq!(CALIBRATION.counts_to_pa(CALIBRATION.counts_at_max), Ok(300_000));
//! assert!(CALIBRATION.counts_to_pa(0).is_err()); // open wire
//! ```

use crate::control::hw::SensorError;
use crate::control::safety::{SENSOR_MAX_PA, SENSOR_MIN_PA};

/// A linear sensor calibration: two points (counts -> pascal) and the
/// margin of counts tolerated outside them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SensorCalibration {
    /// ADC counts at the sensor's lowest pressure.
    pub counts_at_min: u16,
    /// ADC counts at the sensor's highest pressure.
    pub counts_at_max: u16,
    /// The sensor's lowest pressure, in pascal.
    pub min_pa: i32,
    /// The sensor's highest pressure, in pascal.
    pub max_pa: i32,
    /// Counts tolerated below `counts_at_min` / above `counts_at_max`
    /// (noise, tolerance) before the reading counts as out of range.
    pub margin_counts: u16,
}

/// The calibration of both tank sensors (-100..300 kPa at 0.5..4.5 V,
/// divider 2/3, 12-bit ADC at 3.3 V).
pub const CALIBRATION: SensorCalibration = SensorCalibration {
    counts_at_min: 410,
    counts_at_max: 3686,
    min_pa: SENSOR_MIN_PA,
    max_pa: SENSOR_MAX_PA,
    margin_counts: 60,
};

impl SensorCalibration {
    /// Converts ADC counts to pascal (rounded toward zero), clamped to the
    /// sensor range inside the margin; counts past the margin are
    /// [`SensorError::OutOfRange`].
    pub fn counts_to_pa(&self, counts: u16) -> Result<i32, SensorError> {
        let lo = self.counts_at_min.saturating_sub(self.margin_counts);
        let hi = self.counts_at_max.saturating_add(self.margin_counts);
        if counts < lo || counts > hi || self.counts_at_max <= self.counts_at_min {
            return Err(SensorError::OutOfRange);
        }
        let span_counts = i64::from(self.counts_at_max) - i64::from(self.counts_at_min);
        let span_pa = i64::from(self.max_pa) - i64::from(self.min_pa);
        let offset_counts = i64::from(counts) - i64::from(self.counts_at_min);
        let pa = i64::from(self.min_pa) + offset_counts * span_pa / span_counts;
        let clamped = pa.clamp(i64::from(self.min_pa), i64::from(self.max_pa));
        i32::try_from(clamped).map_err(|_| SensorError::OutOfRange)
    }

    /// The counts a sensor outputs at `pressure_pa` (inverse of
    /// [`SensorCalibration::counts_to_pa`]; for simulation and tests).
    pub fn pa_to_counts(&self, pressure_pa: i32) -> u16 {
        let span_counts = i64::from(self.counts_at_max) - i64::from(self.counts_at_min);
        let span_pa = i64::from(self.max_pa) - i64::from(self.min_pa);
        if span_pa == 0 {
            return self.counts_at_min;
        }
        let counts = i64::from(self.counts_at_min)
            + (i64::from(pressure_pa) - i64::from(self.min_pa)) * span_counts / span_pa;
        u16::try_from(counts.clamp(0, 4095)).unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_gauge_reads_near_zero() {
        let counts = CALIBRATION.pa_to_counts(0);
        let pa = CALIBRATION.counts_to_pa(counts).unwrap();
        // One count is 400 kPa / 3276 = 122 Pa.
        assert!(pa.abs() <= 123, "{pa}");
    }

    #[test]
    fn counts_past_the_margin_are_out_of_range() {
        assert_eq!(CALIBRATION.counts_to_pa(349), Err(SensorError::OutOfRange));
        assert_eq!(CALIBRATION.counts_to_pa(4095), Err(SensorError::OutOfRange));
        assert_eq!(CALIBRATION.counts_to_pa(350), Ok(SENSOR_MIN_PA));
        assert_eq!(CALIBRATION.counts_to_pa(3746), Ok(SENSOR_MAX_PA));
    }

    proptest::proptest! {
        /// Every count converts to an in-range pressure or an error, and the
        /// conversion never decreases with the count.
        #[test]
        fn conversion_is_monotonic_and_in_range(a in 0u16..=4095, b in 0u16..=4095) {
            let (lo, hi) = (a.min(b), a.max(b));
            if let (Ok(p_lo), Ok(p_hi)) = (CALIBRATION.counts_to_pa(lo), CALIBRATION.counts_to_pa(hi)) {
                proptest::prop_assert!(p_lo <= p_hi);
                proptest::prop_assert!((SENSOR_MIN_PA..=SENSOR_MAX_PA).contains(&p_lo));
                proptest::prop_assert!((SENSOR_MIN_PA..=SENSOR_MAX_PA).contains(&p_hi));
            }
        }
    }

    #[test]
    fn limits_round_trip_within_one_count() {
        for pa in [-57_000, 50_000, -100_000, 300_000, 0] {
            let back = CALIBRATION
                .counts_to_pa(CALIBRATION.pa_to_counts(pa))
                .unwrap();
            assert!((back - pa).abs() <= 123, "{pa} -> {back}");
        }
    }
}
