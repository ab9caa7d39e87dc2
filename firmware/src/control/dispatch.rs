//! Command dispatch: one decoded [`HostMsg`] -> a change of the desired
//! state and the reply ([`McuMsg::Ack`], [`McuMsg::Nack`] or
//! [`McuMsg::HelloReply`]).
//!
//! | command | disarmed | armed | tripped (faults latched) |
//! |---|---|---|---|
//! | `Hello`, `Ping`, `Heartbeat` | ack | ack | ack |
//! | `SetTelemetryInterval` | ack; nack `IntervalTooShort` below the link's minimum (0 = off is fine) | same | same |
//! | `SetTankTargets` | ack; nack `GuardBand` unless both targets keep the guard band inside the limits | same | same |
//! | `SealAll` (all valves closed) | ack | ack | ack |
//! | `VentAll` (all outlets open, pump modes off) | ack; nack `Refused` while the negative tank is past its limit or has no valid reading | same | same |
//! | `SetChambers`, `SetPumps` | nack `NotArmed` | ack | nack `Tripped` |
//! | `Arm` | ack, unless a fault condition is present, the sensors are not zeroed yet or a calibration waits to be stored: nack `Refused` | ack | nack `Tripped` |
//! | `Disarm` (pumps off, valves sealed; faults stay latched) | ack | ack -> disarmed | ack, stays tripped |
//! | `ClearFaults { faults }` | ack | ack | clears the named faults; nack `Refused` (nothing cleared) while a named fault's condition is present; with no fault left -> disarmed |
//! | `SetCalibration` (applied at once, then stored: [`Controller::store_calibration`]) | ack; nack `Implausible` unless [`dexitac_protocol::Calibration::check`] passes | nack `Refused` | nack `Tripped` |
//!
//! A refused command changes nothing.

use dexitac_protocol::{
    ArmState, Calibration, FaultFlags, HelloReply, HostMsg, McuMsg, NackReason, PumpMode,
    CHAMBER_COUNT, NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA, PROTOCOL_VERSION,
};

use super::valves::{SAFE_CHAMBERS, VENT_CHAMBERS};
use super::Controller;
use crate::FIRMWARE_VERSION;

/// Applies `msg` (frame sequence number `seq`) to `ctl`; returns the reply.
pub fn dispatch(ctl: &mut Controller, seq: u16, msg: HostMsg, now_ms: u32) -> McuMsg {
    match apply(ctl, msg, now_ms) {
        Ok(Reply::Ack) => McuMsg::Ack { seq },
        Ok(Reply::Hello) => McuMsg::HelloReply(hello_reply(ctl)),
        Err(reason) => McuMsg::Nack { seq, reason },
    }
}

/// A successful command's answer.
enum Reply {
    Ack,
    Hello,
}

fn apply(ctl: &mut Controller, msg: HostMsg, now_ms: u32) -> Result<Reply, NackReason> {
    match msg {
        HostMsg::Hello => return Ok(Reply::Hello),
        HostMsg::Ping { .. } | HostMsg::Heartbeat => {}
        HostMsg::SetTelemetryInterval { interval_ms } => {
            if interval_ms != 0 && interval_ms < ctl.config.min_telemetry_interval_ms() {
                return Err(NackReason::IntervalTooShort);
            }
            ctl.telemetry_interval_ms = interval_ms;
            // The first report goes out at the next tick and starts the
            // cadence there (a gap of two intervals restarts it).
            ctl.last_telemetry_ms = now_ms.wrapping_sub(2 * u32::from(interval_ms));
        }
        HostMsg::SetTankTargets(targets) => {
            if !ctl.config.targets_inside_guard_band(targets) {
                return Err(NackReason::GuardBand);
            }
            ctl.targets = targets;
        }
        HostMsg::SealAll => ctl.chambers = SAFE_CHAMBERS,
        HostMsg::VentAll => {
            if !ctl.negative_tank_usable() {
                return Err(NackReason::Refused);
            }
            ctl.chambers = VENT_CHAMBERS;
            ctl.positive_mode = PumpMode::Off;
            ctl.negative_mode = PumpMode::Off;
        }
        HostMsg::SetChambers { chambers } => {
            require_armed(ctl.state)?;
            ctl.chambers = chambers;
        }
        HostMsg::SetPumps { positive, negative } => {
            require_armed(ctl.state)?;
            ctl.positive_mode = positive;
            ctl.negative_mode = negative;
        }
        HostMsg::Arm => arm(ctl)?,
        HostMsg::Disarm => {
            if ctl.state == ArmState::Armed {
                ctl.state = ArmState::Disarmed;
            }
            ctl.enter_safe_state();
        }
        HostMsg::ClearFaults { faults } => clear_faults(ctl, faults)?,
        HostMsg::SetCalibration(calibration) => calibrate(ctl, calibration)?,
    }
    Ok(Reply::Ack)
}

fn require_armed(state: ArmState) -> Result<(), NackReason> {
    match state {
        ArmState::Armed => Ok(()),
        ArmState::Disarmed => Err(NackReason::NotArmed),
        ArmState::Tripped => Err(NackReason::Tripped),
    }
}

fn arm(ctl: &mut Controller) -> Result<(), NackReason> {
    match ctl.state {
        ArmState::Armed => Ok(()),
        ArmState::Tripped => Err(NackReason::Tripped),
        ArmState::Disarmed
            if !ctl.present.is_empty() || !ctl.zeroed() || ctl.calibration_write_pending() =>
        {
            Err(NackReason::Refused)
        }
        ArmState::Disarmed => {
            ctl.state = ArmState::Armed;
            Ok(())
        }
    }
}

/// Clears the named faults, unless one of them is still present.
fn clear_faults(ctl: &mut Controller, faults: FaultFlags) -> Result<(), NackReason> {
    if !faults.intersection(ctl.present).is_empty() {
        return Err(NackReason::Refused);
    }
    ctl.faults = ctl.faults.without(faults);
    if ctl.state == ArmState::Tripped && ctl.faults.is_empty() {
        ctl.state = ArmState::Disarmed;
    }
    Ok(())
}

/// Applies a calibration: only while disarmed, only a plausible one.
fn calibrate(ctl: &mut Controller, calibration: Calibration) -> Result<(), NackReason> {
    match ctl.state {
        ArmState::Disarmed => {}
        ArmState::Armed => return Err(NackReason::Refused),
        ArmState::Tripped => return Err(NackReason::Tripped),
    }
    calibration.check().map_err(|_| NackReason::Implausible)?;
    ctl.set_calibration(calibration);
    Ok(())
}

fn hello_reply(ctl: &Controller) -> HelloReply {
    HelloReply {
        protocol_version: PROTOCOL_VERSION,
        firmware_version: FIRMWARE_VERSION,
        positive_tank_max_pa: POSITIVE_TANK_MAX_PA,
        negative_tank_min_pa: NEGATIVE_TANK_MIN_PA,
        // CHAMBER_COUNT is 8 (protocol crate), which fits a u8.
        chamber_count: CHAMBER_COUNT as u8,
        reset_cause: ctl.reset_cause,
        latched_faults: ctl.faults,
        last_stop: ctl.last_stop,
        min_telemetry_interval_ms: ctl.config.min_telemetry_interval_ms(),
        calibration: ctl.calibration_report(),
    }
}
