//! Tank pressure sensors: ADC samples -> gauge pressure in pascal, corrected
//! for the sensors' supply.
//!
//! # Wiring
//!
//! The two sensors (-100..300 kPa) are **ratiometric**: their output is
//! 10 %..90 % of their own 5 V supply (0.5..4.5 V at exactly 5 V). On a USB
//! supply of 4.75..5.25 V the output moves with the supply, so a conversion
//! that assumes 5.000 V is off by up to 5 % of the reading plus 5 % of the
//! 0.5 V offset (a real +50 kPa reads +40 kPa at 4.75 V).
//!
//! The board therefore measures the supply too, on the same ADC:
//!
//! | signal | divider | ADC input |
//! |---|---|---|
//! | positive tank sensor | 2/3 (10 k / 20 k) | PA0, ADC1_IN0 |
//! | negative tank sensor | 2/3 (10 k / 20 k) | PA1, ADC1_IN1 |
//! | sensor supply (5 V rail at the sensors' connector) | 1/2 (10 k / 10 k) | PB1, ADC1_IN9 |
//!
//! Both counts are relative to the ADC reference (VDDA), so their ratio
//! does not depend on VDDA at all:
//!
//! ```text
//! fraction = Vout / Vsupply = (sensor_counts / supply_counts) * (1/2) / (2/3)
//! pressure = min_pa + (max_pa - min_pa) * (fraction - 10 %) / 80 %
//! ```
//!
//! [`FrontEnd`] does this in integer arithmetic (parts per million), with a
//! zero offset measured at boot ([`FrontEnd::with_zero_pa`]). A supply outside
//! [`SUPPLY_MIN_MV`]..[`SUPPLY_MAX_MV`] (judged against a nominal 3.3 V VDDA,
//! which the on-board regulator holds to about ±2 %) or a fraction outside
//! the sensor's band (open or shorted wire) is [`SensorError::OutOfRange`].
//!
//! # Oversampling
//!
//! The ADC is idle most of each 1 ms tick: the board takes [`OVERSAMPLE`]
//! conversions of every channel per tick ([`SensorSamples`]). [`trimmed_sum`]
//! drops the two lowest and two highest (a solenoid or pump spike) and sums
//! the middle ones; the control core filters further over ticks
//! ([`crate::control::filter`]).
//!
//! ```
//! use dexitac_firmware::sensor::{FrontEnd, NOMINAL_FRONT_END};
//! let fe: FrontEnd = NOMINAL_FRONT_END;
//! // 50 kPa on a 4.75 V supply, VDDA 3.3 V: still 50 kPa (within a count).
//! let sensor = fe.sensor_counts(50_000, 4_750, 3_300);
//! let supply = fe.supply_counts(4_750, 3_300);
//! let pa = fe.pressure_pa(u32::from(sensor), u32::from(supply)).unwrap();
//! assert!((pa - 50_000).abs() < 300, "{pa}");
//! ```

use crate::control::hw::SensorError;

/// Conversions per channel per control tick.
pub const OVERSAMPLE: usize = 8;
/// Conversions dropped at each end before averaging ([`trimmed_sum`]).
pub const TRIM: usize = 2;
/// Conversions that [`trimmed_sum`] adds up.
pub const KEPT: usize = OVERSAMPLE - 2 * TRIM;

/// Full scale of the 12-bit ADC, in counts.
pub const ADC_FULL_SCALE_COUNTS: u32 = 4_095;
/// The ADC reference the supply check assumes, in millivolt.
pub const NOMINAL_VDDA_MV: u32 = 3_300;
/// Lowest accepted sensor supply, in millivolt.
pub const SUPPLY_MIN_MV: u32 = 4_500;
/// Highest accepted sensor supply, in millivolt.
pub const SUPPLY_MAX_MV: u32 = 5_500;

/// Lowest pressure the tank sensors can measure, in pascal (-100 kPa).
pub const SENSOR_MIN_PA: i32 = -100_000;
/// Highest pressure the tank sensors can measure, in pascal (+300 kPa).
pub const SENSOR_MAX_PA: i32 = 300_000;

/// One tick's conversions of one channel, or why there are none.
pub type ChannelSamples = Result<[u16; OVERSAMPLE], SensorError>;

/// One tick's conversions of the three analog inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SensorSamples {
    /// The positive tank's sensor.
    pub positive: ChannelSamples,
    /// The negative tank's sensor.
    pub negative: ChannelSamples,
    /// The sensors' supply through its divider.
    pub supply: ChannelSamples,
}

/// The sum of the [`KEPT`] middle values of `samples` (the [`TRIM`] lowest
/// and highest dropped).
pub fn trimmed_sum(samples: &[u16; OVERSAMPLE]) -> u32 {
    let mut sorted = *samples;
    sorted.sort_unstable();
    sorted
        .iter()
        .skip(TRIM)
        .take(KEPT)
        .map(|&c| u32::from(c))
        .sum()
}

/// A voltage divider `numerator / denominator` in front of an ADC input.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Divider {
    /// Numerator of the ratio (output / input).
    pub numerator: u32,
    /// Denominator of the ratio.
    pub denominator: u32,
}

/// The analog front end of both tank sensors: dividers, the sensors'
/// ratiometric transfer function and a zero offset.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrontEnd {
    /// Divider between a sensor output and its ADC input.
    pub sensor_divider: Divider,
    /// Divider between the sensor supply and its ADC input.
    pub supply_divider: Divider,
    /// Sensor output at [`FrontEnd::min_pa`], in ppm of its supply (10 %).
    pub out_at_min_ppm: i64,
    /// Sensor output at [`FrontEnd::max_pa`], in ppm of its supply (90 %).
    pub out_at_max_ppm: i64,
    /// The sensor's lowest pressure, in pascal.
    pub min_pa: i32,
    /// The sensor's highest pressure, in pascal.
    pub max_pa: i32,
    /// Tolerated output outside the band (tolerance, noise) before the
    /// reading counts as out of range, in ppm of the supply.
    pub margin_ppm: i64,
    /// Subtracted from every reading: the reading of atmosphere at boot.
    pub zero_pa: i32,
}

/// The board's front end: dividers 2/3 and 1/2, 10..90 % output, no zero
/// offset yet.
pub const NOMINAL_FRONT_END: FrontEnd = FrontEnd {
    sensor_divider: Divider {
        numerator: 2,
        denominator: 3,
    },
    supply_divider: Divider {
        numerator: 1,
        denominator: 2,
    },
    out_at_min_ppm: 100_000,
    out_at_max_ppm: 900_000,
    min_pa: SENSOR_MIN_PA,
    max_pa: SENSOR_MAX_PA,
    margin_ppm: 15_000,
    zero_pa: 0,
};

impl FrontEnd {
    /// This front end with `zero_pa` subtracted from every reading.
    pub const fn with_zero_pa(self, zero_pa: i32) -> FrontEnd {
        FrontEnd { zero_pa, ..self }
    }

    /// Whether a supply measurement (sum or single conversion, with
    /// `supply_counts` for `n` conversions) lies in the accepted range,
    /// assuming the nominal VDDA.
    pub fn supply_ok(&self, supply_counts: u32, n: u32) -> bool {
        let lo = u32::from(self.supply_counts(SUPPLY_MIN_MV, NOMINAL_VDDA_MV)) * n;
        let hi = u32::from(self.supply_counts(SUPPLY_MAX_MV, NOMINAL_VDDA_MV)) * n;
        (lo..=hi).contains(&supply_counts)
    }

    /// Gauge pressure from a sensor's counts and the supply's counts (sums
    /// over the same number of conversions), zero offset subtracted.
    pub fn pressure_pa(&self, sensor_counts: u32, supply_counts: u32) -> Result<i32, SensorError> {
        let sd = &self.sensor_divider;
        let vd = &self.supply_divider;
        // fraction = sensor / supply * (vd.num / vd.den) / (sd.num / sd.den)
        let num = i64::from(sensor_counts)
            * i64::from(vd.numerator)
            * i64::from(sd.denominator)
            * 1_000_000;
        let den = i64::from(supply_counts) * i64::from(vd.denominator) * i64::from(sd.numerator);
        if den <= 0 || self.out_at_max_ppm <= self.out_at_min_ppm {
            return Err(SensorError::OutOfRange);
        }
        let fraction_ppm = num / den;
        if fraction_ppm < self.out_at_min_ppm - self.margin_ppm
            || fraction_ppm > self.out_at_max_ppm + self.margin_ppm
        {
            return Err(SensorError::OutOfRange);
        }
        let span_pa = i64::from(self.max_pa) - i64::from(self.min_pa);
        let span_ppm = self.out_at_max_ppm - self.out_at_min_ppm;
        let pa = i64::from(self.min_pa) + (fraction_ppm - self.out_at_min_ppm) * span_pa / span_ppm;
        let clamped = pa.clamp(i64::from(self.min_pa), i64::from(self.max_pa));
        i32::try_from(clamped - i64::from(self.zero_pa)).map_err(|_| SensorError::OutOfRange)
    }

    /// One tick's pressure of a sensor channel: trimmed sums of the sensor
    /// and the supply, supply checked.
    pub fn convert(
        &self,
        sensor: &ChannelSamples,
        supply: &ChannelSamples,
    ) -> Result<i32, SensorError> {
        let supply_sum = trimmed_sum(supply.as_ref().map_err(|e| *e)?);
        // KEPT is a small constant (4).
        if !self.supply_ok(supply_sum, KEPT as u32) {
            return Err(SensorError::OutOfRange);
        }
        let sensor_sum = trimmed_sum(sensor.as_ref().map_err(|e| *e)?);
        self.pressure_pa(sensor_sum, supply_sum)
    }

    /// The counts a sensor at `pressure_pa` (true gauge pressure, no zero
    /// offset) gives on a `supply_mv` supply with reference `vdda_mv`
    /// (simulation and tests; clamped to the ADC range).
    pub fn sensor_counts(&self, pressure_pa: i32, supply_mv: u32, vdda_mv: u32) -> u16 {
        let span_pa = i64::from(self.max_pa) - i64::from(self.min_pa);
        let span_ppm = self.out_at_max_ppm - self.out_at_min_ppm;
        let fraction_ppm = self.out_at_min_ppm
            + (i64::from(pressure_pa) - i64::from(self.min_pa)) * span_ppm / span_pa.max(1);
        let out_uv = fraction_ppm * i64::from(supply_mv) / 1_000;
        self.counts(out_uv, self.sensor_divider, vdda_mv)
    }

    /// The counts the supply input gives for a `supply_mv` supply with
    /// reference `vdda_mv` (simulation and tests; clamped to the ADC range).
    pub fn supply_counts(&self, supply_mv: u32, vdda_mv: u32) -> u16 {
        self.counts(i64::from(supply_mv) * 1_000, self.supply_divider, vdda_mv)
    }

    fn counts(&self, input_uv: i64, divider: Divider, vdda_mv: u32) -> u16 {
        let adc_uv =
            input_uv * i64::from(divider.numerator) / i64::from(divider.denominator.max(1));
        let counts =
            adc_uv * i64::from(ADC_FULL_SCALE_COUNTS) / (i64::from(vdda_mv.max(1)) * 1_000);
        u16::try_from(counts.clamp(0, i64::from(ADC_FULL_SCALE_COUNTS))).unwrap_or(0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all(c: u16) -> ChannelSamples {
        Ok([c; OVERSAMPLE])
    }

    #[test]
    fn supply_error_is_corrected() {
        let fe = NOMINAL_FRONT_END;
        for supply_mv in [4_750, 5_000, 5_250] {
            for vdda_mv in [3_240, 3_300, 3_360] {
                for pa in [-57_000, 0, 40_000, 50_000] {
                    let s = all(fe.sensor_counts(pa, supply_mv, vdda_mv));
                    let v = all(fe.supply_counts(supply_mv, vdda_mv));
                    let got = fe.convert(&s, &v).unwrap();
                    // One count of the sensor is ~150 Pa; the supply count
                    // quantisation adds a little.
                    assert!((got - pa).abs() <= 300, "{pa} at {supply_mv} mV: {got}");
                }
            }
        }
    }

    #[test]
    fn uncorrected_conversion_would_be_ten_kpa_off_at_4_75_v() {
        // What the issue describes: assume 5.000 V and read a real 50 kPa.
        let fe = NOMINAL_FRONT_END;
        let s = all(fe.sensor_counts(50_000, 4_750, 3_300));
        let assumed_supply = all(fe.supply_counts(5_000, 3_300));
        let got = fe.convert(&s, &assumed_supply).unwrap();
        assert!((39_000..41_000).contains(&got), "{got}");
    }

    #[test]
    fn open_wire_and_bad_supply_are_out_of_range() {
        let fe = NOMINAL_FRONT_END;
        let v = all(fe.supply_counts(5_000, 3_300));
        assert_eq!(fe.convert(&all(0), &v), Err(SensorError::OutOfRange));
        assert_eq!(fe.convert(&all(4_095), &v), Err(SensorError::OutOfRange));
        let s = all(fe.sensor_counts(0, 5_000, 3_300));
        let low = all(fe.supply_counts(4_200, 3_300));
        assert_eq!(fe.convert(&s, &low), Err(SensorError::OutOfRange));
        assert_eq!(
            fe.convert(&s, &Err(SensorError::NoSample)),
            Err(SensorError::NoSample)
        );
    }

    #[test]
    fn zero_offset_is_subtracted() {
        let fe = NOMINAL_FRONT_END.with_zero_pa(1_500);
        let s = all(fe.sensor_counts(1_500, 5_000, 3_300));
        let v = all(fe.supply_counts(5_000, 3_300));
        assert!(fe.convert(&s, &v).unwrap().abs() <= 200);
    }

    #[test]
    fn trimming_drops_two_spikes_at_each_end() {
        let samples = [1000, 4095, 1001, 0, 999, 1000, 4095, 0];
        assert_eq!(trimmed_sum(&samples), 1000 + 1001 + 999 + 1000);
    }

    proptest::proptest! {
        /// The conversion never decreases with the sensor's counts, and is
        /// inside the sensor range or an error.
        #[test]
        fn conversion_is_monotonic_and_in_range(a in 0u32..=4095 * 4, b in 0u32..=4095 * 4) {
            let fe = NOMINAL_FRONT_END;
            let supply = 4 * u32::from(fe.supply_counts(5_000, 3_300));
            let (lo, hi) = (a.min(b), a.max(b));
            if let (Ok(p_lo), Ok(p_hi)) = (fe.pressure_pa(lo, supply), fe.pressure_pa(hi, supply)) {
                proptest::prop_assert!(p_lo <= p_hi);
                proptest::prop_assert!((SENSOR_MIN_PA..=SENSOR_MAX_PA).contains(&p_lo));
                proptest::prop_assert!((SENSOR_MIN_PA..=SENSOR_MAX_PA).contains(&p_hi));
            }
        }
    }
}
