//! DexiTac firmware library: the hardware-independent parts of the STM32F103
//! firmware, built and tested on the host.
//!
//! The firmware is the *safety loop* of the paper's double closed loop: it
//! keeps both buffer tanks inside the actuator limits (+50 kPa, -57 kPa,
//! [`dexitac_protocol::limits`]) with the pumps, drives the 8 chambers' 16
//! valves as the host commands, and reaches a safe state on any fault,
//! whatever the host sends.
//!
//! - [`control`]: the [`Controller`] (command dispatch, pump regulation,
//!   trips, telemetry). Hardware reaches it only through the traits in
//!   [`control::hw`] ([`Valves`], [`Pumps`], [`PressureSource`], [`Clock`]),
//!   so the same code runs on the board, in QEMU and in the host simulator.
//! - [`queue`]: fixed-size byte queues for the serial link ([`FrameSink`]).
//! - [`sensor`]: ADC counts -> pascal, the sensor calibration in one place.
//! - [`tank_model`]: a simulated pair of tanks (QEMU build, host simulator).
//! - [`reset`]: the reset cause from the STM32 `RCC_CSR` register.
//!
//! # Safe state
//!
//! **Both pumps off and every valve closed** (every chamber
//! [`ValveState::Hold`](dexitac_protocol::ValveState::Hold): the air in the
//! actuators is sealed, the tanks are cut off from the chambers). It is also
//! the de-energised state of the hardware (normally-closed valves, pump
//! drivers off), i.e. the state after a reset, a watchdog reset or a power
//! loss. The host may still vent explicitly ([`HostMsg::VentAll`](dexitac_protocol::HostMsg::VentAll))
//! while tripped or disarmed; the pumps stay off.
//!
//! # Fault table
//!
//! Every condition is checked once per control tick (1 ms). "Trip" means:
//! state [`ArmState::Tripped`](dexitac_protocol::ArmState::Tripped), the safe
//! state above, pump modes reset to off, one
//! [`McuMsg::Fault`](dexitac_protocol::McuMsg::Fault) sent per fault, the fault
//! added to the telemetry's fault flags. A trip is **latched**: nothing but
//! [`HostMsg::Disarm`](dexitac_protocol::HostMsg::Disarm) clears it; then
//! [`HostMsg::Arm`](dexitac_protocol::HostMsg::Arm) is accepted again if no
//! condition is still present.
//!
//! | condition | detected when | action | recovery |
//! |---|---|---|---|
//! | positive tank over limit | reading >= +50 kPa | trip (`PositiveOverLimit`) | Disarm; Arm refused while still >= limit |
//! | negative tank over limit | reading <= -57 kPa | trip (`NegativeOverLimit`) | Disarm; Arm refused while still <= limit |
//! | sensor out of range | ADC outside the sensor's output band, or reading outside -100..300 kPa | trip (`PositiveSensor` / `NegativeSensor`) | fix wiring; Disarm; Arm refused while out of range |
//! | sensor stuck | its pump on and the reading moved less than [`Config::stuck_min_change_pa`] for [`Config::stuck_window_ms`] | trip (`*Sensor`) | Disarm, Arm |
//! | pump run-time | a pump on without pause for longer than [`Config::pump_max_run_ms`] (leak, dead pump) | trip (`*PumpRunTime`) | Disarm, Arm |
//! | host silence | armed and no valid frame for [`Config::host_silence_ms`] (default 500 ms) | trip (`HostSilence`) | Disarm, Arm |
//! | frame corrupted (COBS, CRC, length, version) | decoder error | frame dropped, nothing actuated, counted | automatic (next frame) |
//! | frame malformed / unknown message (CRC ok) | decoder error | [`NackReason::Malformed`](dexitac_protocol::NackReason::Malformed) / `UnknownMessage`, nothing actuated | automatic |
//! | command not allowed in this state | dispatch | `Nack` (`NotArmed`, `Tripped`, `Refused`), nothing actuated | arm / disarm as the reason says |
//! | transmit queue full | [`FrameSink::send`] fails | frame dropped, counted ([`LinkStats::tx_dropped`]) | automatic; the host retries on a missing ack |
//! | control loop late | tick later than [`Config::tick_period_ms`] | counted (`loop_overruns` in telemetry) | none needed |
//! | control loop stalled | independent watchdog not fed (board) | MCU reset -> safe state, `ResetCause::IndependentWatchdog` in the hello reply | host re-arms |
//! | panic | panic handler (board) | outputs forced to the safe state, then watchdog reset | host re-arms |
//!
//! A tank whose sensor gives no reading is reported as
//! [`NO_READING_PA`](dexitac_protocol::NO_READING_PA) (`i32::MIN`) Pa in
//! telemetry and fault events (the sensor fault flag says why).
//!
//! Over-limit and sensor conditions are also evaluated while disarmed: they
//! show in the telemetry's fault flags and make `Arm` fail with
//! [`NackReason::Refused`](dexitac_protocol::NackReason::Refused); the pumps
//! are off anyway.
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(test)]
extern crate std;

pub mod control;
pub mod cost_scenario;
pub mod led;
pub mod persist;
pub mod queue;
pub mod reset;
pub mod sensor;
pub mod tank_model;

pub use control::hw::{Clock, PressureSource, Pumps, SensorError, Valves};
pub use control::{Config, Controller, LinkStats, PumpOutputs, TickReport};
pub use queue::{ByteQueue, FrameSink, Priority, QueueFull, TxQueues};
pub use sensor::SensorSamples;

use dexitac_protocol::FirmwareVersion;

/// This firmware's version, reported in the hello reply.
pub const FIRMWARE_VERSION: FirmwareVersion = FirmwareVersion {
    major: 0,
    minor: 2,
    patch: 0,
};
