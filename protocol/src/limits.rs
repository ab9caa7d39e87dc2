//! Hard limits shared by firmware and host.
//!
//! These are the actuator limits of the DexiTac gripper (paper Sec. III-A,
//! "Pneumatic system"): the soft bellows actuators tolerate at most +50 kPa
//! and at least -57 kPa. The firmware trips when a tank crosses them; the
//! host cannot ask for a target outside them ([`crate::TankTargets`]).

/// Number of actuator chambers: 2 fingers x (1 Rot + 3 Dex) chambers, each
/// with one inlet and one outlet solenoid valve (8 + 8 valves).
pub const CHAMBER_COUNT: usize = 8;

/// Highest pressure the positive tank may hold, in pascal (+50 kPa).
pub const POSITIVE_TANK_MAX_PA: i32 = 50_000;

/// Lowest pressure the negative tank may hold, in pascal (-57 kPa).
pub const NEGATIVE_TANK_MIN_PA: i32 = -57_000;

/// [`POSITIVE_TANK_MAX_PA`] in kilopascal.
pub const POSITIVE_TANK_MAX_KPA: i32 = POSITIVE_TANK_MAX_PA / 1000;

/// [`NEGATIVE_TANK_MIN_PA`] in kilopascal.
pub const NEGATIVE_TANK_MIN_KPA: i32 = NEGATIVE_TANK_MIN_PA / 1000;

/// A calibration gain of exactly 1, in parts per million.
pub const GAIN_UNITY_PPM: u32 = 1_000_000;

/// Largest zero offset a sensor calibration may carry, either sign, in
/// pascal (±10 kPa): 2.5 % of the tank sensors' 400 kPa span, the whole
/// error band of a typical -100..300 kPa part and 2.5 times the 4 kPa the
/// firmware's boot zero accepts. A larger offset is a broken sensor or a
/// zero taken on a pressurised tank, not something to calibrate out.
pub const CALIBRATION_OFFSET_MAX_PA: i32 = 10_000;

/// Smallest calibration gain, in parts per million (0.9).
///
/// The span errors of the parts (sensor, 1 % divider resistors) stay under
/// 5 %; 0.9..1.1 leaves twice that. The bound also limits what a *wrong*
/// calibration can do to the trip point: on a sensor that reads true, a
/// gain `g` and offset `o` trip the positive tank at a true
/// `50 kPa / g + o`, at worst 65.6 kPa (gain 0.9, offset +10 kPa).
pub const CALIBRATION_GAIN_MIN_PPM: u32 = 900_000;

/// Largest calibration gain, in parts per million (1.1); see
/// [`CALIBRATION_GAIN_MIN_PPM`].
pub const CALIBRATION_GAIN_MAX_PPM: u32 = 1_100_000;
