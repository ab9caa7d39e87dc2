//! Trip conditions of one tank: filtered reading and pump findings -> the
//! faults it shows.
//!
//! Input: one tick's pressure of the tank (pascal, or a [`SensorError`]) and
//! the pump monitor's findings. The filtered value is corrected by the
//! sensor's zero and gain ([`crate::calibration::correct`]) before any
//! check. Output: [`FaultFlags`]. A reading trips only
//! after [`crate::Config::trip_after_ticks`] consecutive ticks (of the
//! filtered value past the limit, or of no valid reading), so one noisy
//! sample or one EMI spike cannot trip. The hard limits come from the
//! protocol crate at compile time; no command can move them.

use dexitac_protocol::{Fault, FaultFlags};

use super::filter::MovingAverage;
use super::hw::SensorError;
use super::pumps::{PumpFindings, Tank};
pub use crate::sensor::{SENSOR_MAX_PA, SENSOR_MIN_PA};

/// The faults of one tank: over limit, sensor, run time, no rise.
pub const fn faults_of(tank: Tank) -> [Fault; 4] {
    match tank {
        Tank::Positive => [
            Fault::PositiveOverLimit,
            Fault::PositiveSensor,
            Fault::PositivePumpRunTime,
            Fault::PositivePumpNoRise,
        ],
        Tank::Negative => [
            Fault::NegativeOverLimit,
            Fault::NegativeSensor,
            Fault::NegativePumpRunTime,
            Fault::NegativePumpNoRise,
        ],
    }
}

/// A usable reading: the sensor answered and its value lies in the
/// sensor's range.
pub fn valid_reading(reading: Result<i32, SensorError>) -> Option<i32> {
    reading
        .ok()
        .filter(|pa| (SENSOR_MIN_PA..=SENSOR_MAX_PA).contains(pa))
}

/// The correction of one sensor's filtered reading: a zero subtracted,
/// then a gain ([`crate::calibration::correct`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Correction {
    /// Subtracted from the filtered reading, in pascal.
    pub zero_pa: i32,
    /// Applied after the zero, in parts per million.
    pub gain_ppm: u32,
}

impl Correction {
    /// No correction.
    pub const NONE: Correction = Correction {
        zero_pa: 0,
        gain_ppm: dexitac_protocol::GAIN_UNITY_PPM,
    };

    fn apply(self, filtered_pa: i32) -> i32 {
        crate::calibration::correct(filtered_pa, self.zero_pa, self.gain_ppm)
    }
}

/// One tank's filtered, corrected reading and trip counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TankChannel {
    filter: MovingAverage,
    correction: Correction,
    /// The filtered reading before the correction.
    uncorrected: Result<i32, SensorError>,
    reading: Result<i32, SensorError>,
    invalid_ticks: u32,
    over_limit_ticks: u32,
}

impl Default for TankChannel {
    fn default() -> Self {
        Self::new()
    }
}

impl TankChannel {
    /// No reading yet (reported as [`SensorError::NoSample`]).
    pub const fn new() -> Self {
        TankChannel {
            filter: MovingAverage::new(),
            correction: Correction::NONE,
            uncorrected: Err(SensorError::NoSample),
            reading: Err(SensorError::NoSample),
            invalid_ticks: 0,
            over_limit_ticks: 0,
        }
    }

    /// Takes one tick's pressure: a valid one enters the filter and the
    /// filtered value is corrected, an invalid one counts toward the sensor
    /// fault (and makes the reading an error, so the pump stops at once).
    pub fn update(&mut self, tank: Tank, raw: Result<i32, SensorError>) {
        match valid_reading(raw) {
            Some(pa) => {
                let filtered = self.filter.push(pa);
                self.uncorrected = Ok(filtered);
                let corrected = self.correction.apply(filtered);
                self.reading = Ok(corrected);
                self.invalid_ticks = 0;
                self.over_limit_ticks = if tank.at_or_past_limit(corrected) {
                    self.over_limit_ticks.saturating_add(1)
                } else {
                    0
                };
            }
            None => {
                let error = Err(raw.err().unwrap_or(SensorError::OutOfRange));
                self.uncorrected = error;
                self.reading = error;
                self.invalid_ticks = self.invalid_ticks.saturating_add(1);
            }
        }
    }

    /// Corrects the readings from now on by `correction`; the last reading
    /// is corrected again at once (the over-limit count goes on from the
    /// next tick, on the new value).
    pub fn set_correction(&mut self, correction: Correction) {
        self.correction = correction;
        if let Ok(filtered) = self.uncorrected {
            self.reading = Ok(correction.apply(filtered));
        }
    }

    /// The correction in use.
    pub const fn correction(&self) -> Correction {
        self.correction
    }

    /// The filtered, corrected reading of the last tick, or why there is none.
    pub const fn reading(&self) -> Result<i32, SensorError> {
        self.reading
    }

    /// The filtered reading of the last tick before the correction (what
    /// the boot zero measures).
    pub const fn uncorrected(&self) -> Result<i32, SensorError> {
        self.uncorrected
    }

    /// Whether the filter holds a full window.
    pub const fn settled(&self) -> bool {
        self.filter.is_full()
    }

    /// The conditions this tank shows now.
    pub fn conditions(
        &self,
        tank: Tank,
        findings: PumpFindings,
        trip_after_ticks: u32,
    ) -> FaultFlags {
        let [over_limit, sensor, run_time, no_rise] = faults_of(tank);
        let mut flags = FaultFlags::NONE;
        if self.invalid_ticks >= trip_after_ticks {
            flags = flags.with(sensor);
        }
        if self.over_limit_ticks >= trip_after_ticks {
            flags = flags.with(over_limit);
        }
        if findings.run_time_exceeded {
            flags = flags.with(run_time);
        }
        if findings.no_rise || findings.unconfirmed_hold {
            flags = flags.with(no_rise);
        }
        flags
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use dexitac_protocol::{NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA};

    fn after(tank: Tank, readings: &[Result<i32, SensorError>]) -> FaultFlags {
        let mut c = TankChannel::new();
        for r in readings {
            c.update(tank, *r);
        }
        c.conditions(tank, PumpFindings::default(), 3)
    }

    #[test]
    fn reading_at_limit_trips_after_three_ticks() {
        let at = Ok(POSITIVE_TANK_MAX_PA);
        assert!(after(Tank::Positive, &[at, at]).is_empty());
        assert!(after(Tank::Positive, &[at, at, at]).contains(Fault::PositiveOverLimit));
        let at = Ok(NEGATIVE_TANK_MIN_PA);
        assert!(after(Tank::Negative, &[at, at, at]).contains(Fault::NegativeOverLimit));
        let inside = Ok(NEGATIVE_TANK_MIN_PA + 1);
        assert!(after(Tank::Negative, &[inside; 5]).is_empty());
    }

    #[test]
    fn an_interrupted_run_over_the_limit_restarts_the_count() {
        let (at, below) = (Ok(POSITIVE_TANK_MAX_PA + 20_000), Ok(0));
        // Filtered: 20 kPa past the limit, then one tick pulls the mean
        // below it, then two more ticks past: never three in a row.
        let mut c = TankChannel::new();
        c.update(Tank::Positive, at);
        c.update(Tank::Positive, at);
        assert!(c
            .conditions(Tank::Positive, PumpFindings::default(), 3)
            .is_empty());
        for _ in 0..3 {
            c.update(Tank::Positive, below);
        }
        c.update(Tank::Positive, at);
        assert!(c
            .conditions(Tank::Positive, PumpFindings::default(), 3)
            .is_empty());
    }

    #[test]
    fn invalid_readings_trip_after_three_ticks() {
        for bad in [
            Ok(SENSOR_MAX_PA + 1),
            Ok(SENSOR_MIN_PA - 1),
            Err(SensorError::OutOfRange),
            Err(SensorError::NoSample),
        ] {
            assert!(after(Tank::Positive, &[bad, bad]).is_empty());
            let f = after(Tank::Positive, &[bad, bad, bad]);
            assert_eq!(f, FaultFlags::NONE.with(Fault::PositiveSensor));
        }
    }
}
