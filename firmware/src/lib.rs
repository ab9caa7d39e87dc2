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
//!   trips, valve dead time, telemetry). Hardware reaches it only through
//!   the traits in [`control::hw`] ([`Valves`], [`Pumps`], [`PressureSource`],
//!   [`Clock`]), so the same code runs on the board, in QEMU and in the host
//!   simulator.
//! - [`sensor`]: ADC samples -> pascal, ratiometric to the measured sensor
//!   supply, with oversampling.
//! - [`calibration`]: the sensors' offset and gain (applied to the filtered
//!   readings before every check), with the boot zero; the flash record
//!   that keeps them ([`CalibrationStore`]).
//! - [`queue`]: transmit queues by priority ([`TxQueues`], [`FrameSink`]).
//! - [`persist`]: the record of the last trip / panic / fault that survives a reset.
//! - [`led`]: the status LED's blink codes.
//! - [`tank_model`]: a simulated pair of tanks (QEMU build, host simulator, tests).
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
//! while tripped or disarmed, unless the negative tank is past its limit or
//! has no valid reading; the pumps stay off.
//!
//! # Fault table
//!
//! Every condition is checked once per control tick (1 ms) on the
//! *filtered* readings ([`control::filter`]). "Trip" means: state
//! [`ArmState::Tripped`](dexitac_protocol::ArmState::Tripped), the safe state
//! above, pump modes reset to off, one
//! [`McuMsg::Fault`](dexitac_protocol::McuMsg::Fault) sent per new fault
//! (urgent queue), the fault latched in the telemetry's fault flags. A trip
//! is **latched** in every state (a condition that appears while disarmed
//! latches too): [`HostMsg::Disarm`](dexitac_protocol::HostMsg::Disarm) does
//! not clear it; only [`HostMsg::ClearFaults`](dexitac_protocol::HostMsg::ClearFaults)
//! naming the fault does, and only once its condition is gone. Arm is
//! refused while any fault is latched (`Tripped`) or a condition is present
//! (`Refused`). Detection times are at the defaults of [`Config`].
//!
//! | condition | detected when (worst case) | outputs | cleared by |
//! |---|---|---|---|
//! | positive / negative tank over limit | filtered reading at or past +50 / -57 kPa for 3 consecutive ticks: <= 19 ms after a step of the true pressure past the limit (16 ms filter + 3 ticks) | trip; the pump stops at once when the filtered reading reaches the limit; valves toward that tank held closed while the condition lasts | `ClearFaults` once the reading is back inside |
//! | sensor (`*Sensor`) | no valid reading for 3 consecutive ticks (output outside its 10..90 % band by more than 1.5 %, supply outside 4.5..5.5 V, no conversion): 3 ms | trip; the pump stops on the first invalid tick; valves toward that tank held closed | `ClearFaults` once readings are valid |
//! | pump no rise (`*PumpNoRise`: stuck sensor, dead pump, leak) | pump on for a whole 1 s window and its filtered reading rose less than 1.5 kPa: <= 2.016 s of continuous pumping; or the pump has been held off for [`control::DEFAULT_PUMP_MAX_HOLD_MS`] (10 s) without its reading moving 1.5 kPa while the regulator still wants it. The hold (no fault) switches the pump off when one more tick could let the fastest pump allowed for carry the tank past its limit from the last reading that followed the tank + 3 kPa ([`control::pumps::PumpMonitor`]), before the true pressure can reach the limit; a move of the reading by 1.5 kPa with the pump off releases it | trip (the hold only keeps that pump off) | `ClearFaults` (after a hold, the pump is held and trips again at its next start until the reading has moved 1.5 kPa with the pump off) |
//! | pump run time (`*PumpRunTime`) | one pump run longer than [`control::DEFAULT_PUMP_MAX_RUN_MS`] (6.855 s = 1.5 x the nominal fill time): 1 tick after | trip | `ClearFaults` |
//! | host silence | armed and no valid frame for 500 ms: exactly 500 ms | trip | `ClearFaults` |
//! | clock fallback | crystal not ready within about 30 ms at boot (board) | latched at the first tick; runs on the internal clock | `ClearFaults` |
//! | frame corrupted (COBS, CRC, length, version) | decoder error | frame dropped, nothing actuated, counted | automatic (next frame) |
//! | frame malformed / unknown message (CRC ok) | decoder error | [`NackReason::Malformed`](dexitac_protocol::NackReason::Malformed) / `UnknownMessage`, nothing actuated | automatic |
//! | command not allowed | dispatch | `Nack` (`NotArmed`, `Tripped`, `Refused`, `GuardBand`, `IntervalTooShort`, `Implausible`), nothing actuated or applied | as the reason says |
//! | calibration record unusable (erased, bad CRC, unknown version, implausible values) | at boot ([`calibration::decode`]) | identity calibration with the boot zero; reported in the hello reply | a new `SetCalibration` |
//! | transmit queue full | [`FrameSink::send`] fails | telemetry dropped first (own queue); counted in [`LinkStats`] | automatic |
//! | control loop late | tick later than [`Config::tick_period_ms`] | counted (`loop_overruns` in telemetry) | none needed |
//! | control loop stalled | independent watchdog not fed for 50 ms (board) | MCU reset -> safe state, `ResetCause::IndependentWatchdog` in the hello reply | host re-arms |
//! | panic, HardFault, interrupt without handler | board handlers | outputs forced low at once, cause recorded in no-init RAM ([`persist`]), watchdog reset; `last_stop` in the hello reply | host re-arms |
//!
//! A tank whose sensor gives no reading is reported as
//! [`NO_READING_PA`](dexitac_protocol::NO_READING_PA) (`i32::MIN`) Pa in
//! telemetry and fault events (the sensor fault flag says why).
#![no_std]
#![forbid(unsafe_code)]
#![warn(missing_docs)]

#[cfg(test)]
extern crate std;

pub mod calibration;
pub mod control;
pub mod cost_scenario;
pub mod led;
pub mod persist;
pub mod queue;
pub mod reset;
pub mod sensor;
pub mod tank_model;

pub use calibration::CalibrationStore;
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
