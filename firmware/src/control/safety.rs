//! Trip conditions: one tank's reading -> the faults it shows.
//!
//! Input: a [`TankReadings`](super::hw::TankReadings) half (pascal or a [`SensorError`]) and the pump
//! monitor's findings. Output: [`FaultFlags`]. The hard limits come from the
//! protocol crate at compile time; no command can move them.

use dexitac_protocol::{Fault, FaultFlags};

use super::hw::SensorError;
use super::pumps::{PumpFindings, Tank};

/// Lowest pressure the tank sensors can measure, in pascal (-100 kPa).
pub const SENSOR_MIN_PA: i32 = -100_000;

/// Highest pressure the tank sensors can measure, in pascal (+300 kPa).
pub const SENSOR_MAX_PA: i32 = 300_000;

/// The faults of one tank.
const fn faults_of(tank: Tank) -> (Fault, Fault, Fault) {
    match tank {
        Tank::Positive => (
            Fault::PositiveOverLimit,
            Fault::PositiveSensor,
            Fault::PositivePumpRunTime,
        ),
        Tank::Negative => (
            Fault::NegativeOverLimit,
            Fault::NegativeSensor,
            Fault::NegativePumpRunTime,
        ),
    }
}

/// A usable reading: the sensor answered and its value lies in the
/// sensor's range.
pub fn valid_reading(reading: Result<i32, SensorError>) -> Option<i32> {
    reading
        .ok()
        .filter(|pa| (SENSOR_MIN_PA..=SENSOR_MAX_PA).contains(pa))
}

/// The conditions one tank shows now: sensor fault (no valid reading, or
/// stuck while its pump runs), over-limit, pump run time.
pub fn tank_conditions(
    tank: Tank,
    reading: Result<i32, SensorError>,
    findings: PumpFindings,
) -> FaultFlags {
    let (over_limit, sensor, run_time) = faults_of(tank);
    let mut flags = FaultFlags::NONE;
    match valid_reading(reading) {
        None => flags = flags.with(sensor),
        Some(pa) if tank.at_or_past_limit(pa) => flags = flags.with(over_limit),
        Some(_) => {}
    }
    if findings.sensor_stuck {
        flags = flags.with(sensor);
    }
    if findings.run_time_exceeded {
        flags = flags.with(run_time);
    }
    flags
}

#[cfg(test)]
mod tests {
    use super::*;
    use dexitac_protocol::{NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA};

    #[test]
    fn reading_at_limit_is_over_limit() {
        let f = tank_conditions(
            Tank::Positive,
            Ok(POSITIVE_TANK_MAX_PA),
            PumpFindings::default(),
        );
        assert!(f.contains(Fault::PositiveOverLimit));
        let f = tank_conditions(
            Tank::Negative,
            Ok(NEGATIVE_TANK_MIN_PA),
            PumpFindings::default(),
        );
        assert!(f.contains(Fault::NegativeOverLimit));
        let f = tank_conditions(
            Tank::Negative,
            Ok(NEGATIVE_TANK_MIN_PA + 1),
            PumpFindings::default(),
        );
        assert!(f.is_empty());
    }

    #[test]
    fn reading_outside_sensor_range_is_sensor_fault() {
        for reading in [
            Ok(SENSOR_MAX_PA + 1),
            Ok(SENSOR_MIN_PA - 1),
            Err(SensorError::OutOfRange),
            Err(SensorError::NoSample),
        ] {
            let f = tank_conditions(Tank::Positive, reading, PumpFindings::default());
            assert_eq!(f, FaultFlags::NONE.with(Fault::PositiveSensor));
        }
    }
}
