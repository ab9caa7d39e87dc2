//! The hardware seen by the control core: four small traits.
//!
//! The board layer implements them with stm32f1xx-hal (GPIO, ADC, SysTick),
//! the QEMU build with a [`crate::tank_model::TankModel`], the tests with
//! fakes. The pressure source delivers raw ADC conversions
//! ([`SensorSamples`]); the core converts, corrects and filters them
//! ([`crate::sensor`], [`super::filter`]). Times are milliseconds since reset
//! (wrapping `u32`).

use dexitac_protocol::Chambers;

use super::PumpOutputs;
pub use crate::sensor::SensorSamples;

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

/// The tank pressure sensors and their supply.
pub trait PressureSource {
    /// Converts every analog input [`crate::sensor::OVERSAMPLE`] times.
    /// Called once per control tick.
    fn read_samples(&mut self) -> SensorSamples;
}

/// The 16 chamber valves (8 inlets, 8 outlets).
///
/// A chamber's state is a [`dexitac_protocol::ValveState`], which has no
/// value for "inlet and outlet open". The controller changes a chamber
/// between inflate and deflate only through [`dexitac_protocol::ValveState::Hold`]
/// held for the valve dead time ([`crate::control::valves::ValveDriver`]), so
/// a valve that releases late cannot join the tanks either. Implementations
/// should still write closing valves before opening ones
/// ([`crate::control::valves::ValveLevels::transition`]).
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
