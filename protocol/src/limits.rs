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
