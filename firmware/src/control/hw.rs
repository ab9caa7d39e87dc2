//! The hardware seen by the control core: four small traits.
//!
//! The board layer implements them with stm32f1xx-hal (GPIO, ADC, SysTick),
//! the QEMU build with a [`crate::tank_model::TankModel`], the tests with
//! fakes. Pressures are gauge pressures in whole pascal, times are
//! milliseconds since reset (wrapping `u32`).

use dexitac_protocol::Chambers;

use super::PumpOutputs;

/// Why a pressure sensor gave no usable reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorError {
    /// The raw signal lies outside the sensor's output band (open or shorted
    /// wire, dead sensor).
    OutOfRange,
    /// The converter did not deliver a sample.
    NoSample,
}

impl core::fmt::Display for SensorError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SensorError::OutOfRange => f.write_str("sensor signal out of range"),
            SensorError::NoSample => f.write_str("no sample from the converter"),
        }
    }
}

/// One reading of both tank sensors, in pascal (gauge).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TankReadings {
    /// The positive (pressure) tank.
    pub positive_pa: Result<i32, SensorError>,
    /// The negative (vacuum) tank.
    pub negative_pa: Result<i32, SensorError>,
}

/// The tank pressure sensors.
pub trait PressureSource {
    /// Reads both tanks now. Called once per control tick.
    fn read_tanks(&mut self) -> TankReadings;
}

/// The 16 chamber valves (8 inlets, 8 outlets).
///
/// A chamber's state is a [`dexitac_protocol::ValveState`], which has no
/// value for "inlet and outlet open", so an implementation cannot be asked
/// to short the tanks. Implementations should switch break-before-make:
/// [`crate::control::valves::ValveLevels::transition`] gives the order.
pub trait Valves {
    /// Drives every chamber's valve pair to `chambers`. Called once per
    /// control tick with the full state (idempotent).
    fn set_chambers(&mut self, chambers: &Chambers);
}

/// The two pumps.
pub trait Pumps {
    /// Switches both pumps. Called once per control tick (idempotent).
    fn set_pumps(&mut self, pumps: PumpOutputs);
}

/// Milliseconds since reset.
pub trait Clock {
    /// The current time in milliseconds (wraps after ~49 days).
    fn now_ms(&self) -> u32;
}
