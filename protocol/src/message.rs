//! The messages: [`HostMsg`] (PC -> MCU) and [`McuMsg`] (MCU -> PC).
//!
//! Every type here is fixed-size (no vectors, no strings), so each message
//! has a compile-time maximum encoded size ([`postcard::experimental::max_size::MaxSize`]).
//! Pressures travel as whole pascals in `i32` fields named `_pa`; times as
//! milliseconds in fields named `_ms`.
//!
//! **The order of enum variants is the wire format.** Append new variants at
//! the end and bump [`crate::PROTOCOL_VERSION`] when a layout changes; the
//! wire snapshot tests (`protocol/tests/wire_snapshots.rs`) fail on any
//! renumbering.

use core::fmt;

use postcard::experimental::max_size::MaxSize;
use serde::{Deserialize, Serialize};

use crate::limits::{
    CALIBRATION_GAIN_MAX_PPM, CALIBRATION_GAIN_MIN_PPM, CALIBRATION_OFFSET_MAX_PA, CHAMBER_COUNT,
    GAIN_UNITY_PPM, NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA,
};

/// What one chamber's valve pair does. A chamber has one inlet (from the
/// positive tank) and one outlet (into the negative tank); this type has no
/// value for "both open", so that state cannot be commanded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ValveState {
    /// Inlet and outlet closed: the air in the chamber is held (sealed).
    #[default]
    Hold,
    /// Inlet open, outlet closed: the chamber inflates from the positive tank.
    Inflate,
    /// Inlet closed, outlet open: the chamber deflates into the negative tank.
    Deflate,
}

impl ValveState {
    /// Whether the inlet valve is open.
    pub const fn inlet_open(self) -> bool {
        matches!(self, ValveState::Inflate)
    }

    /// Whether the outlet valve is open.
    pub const fn outlet_open(self) -> bool {
        matches!(self, ValveState::Deflate)
    }

    /// The state as -1 (deflate), 0 (hold) or 1 (inflate), as logged in
    /// time-series files.
    pub const fn as_sign(self) -> i8 {
        match self {
            ValveState::Hold => 0,
            ValveState::Inflate => 1,
            ValveState::Deflate => -1,
        }
    }
}

/// The state of all chambers, indexed by chamber number `0..CHAMBER_COUNT`.
pub type Chambers = [ValveState; CHAMBER_COUNT];

/// What a pump should do. The firmware still switches a pump off whenever
/// its tank reaches the hard limit, whatever the mode.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PumpMode {
    /// Pump off.
    #[default]
    Off,
    /// Run the pump with hysteresis to hold its tank at the target pressure.
    Regulate,
}

/// Tank pressure targets, guaranteed inside the hard limits: the positive
/// target in `0..=POSITIVE_TANK_MAX_PA`, the negative target in
/// `NEGATIVE_TANK_MIN_PA..=0`. Decoding a frame whose targets lie outside
/// fails (as [`crate::FrameError::Malformed`]), so no such value can reach
/// the firmware's command handler.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, MaxSize)]
#[serde(try_from = "RawTankTargets")]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TankTargets {
    positive_pa: i32,
    negative_pa: i32,
}

/// The unchecked wire form of [`TankTargets`] (same layout).
#[derive(Deserialize)]
struct RawTankTargets {
    positive_pa: i32,
    negative_pa: i32,
}

/// A tank target outside the hard limits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LimitError {
    /// The positive tank target is below 0 or above [`POSITIVE_TANK_MAX_PA`].
    PositiveTarget {
        /// The rejected value, in pascal.
        requested_pa: i32,
    },
    /// The negative tank target is above 0 or below [`NEGATIVE_TANK_MIN_PA`].
    NegativeTarget {
        /// The rejected value, in pascal.
        requested_pa: i32,
    },
}

impl fmt::Display for LimitError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LimitError::PositiveTarget { requested_pa } => write!(
                f,
                "positive tank target {requested_pa} Pa is outside 0..={POSITIVE_TANK_MAX_PA} Pa"
            ),
            LimitError::NegativeTarget { requested_pa } => write!(
                f,
                "negative tank target {requested_pa} Pa is outside {NEGATIVE_TANK_MIN_PA}..=0 Pa"
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for LimitError {}

impl TankTargets {
    /// Targets for both tanks, if both lie inside the hard limits.
    pub const fn new(positive_pa: i32, negative_pa: i32) -> Result<Self, LimitError> {
        if positive_pa < 0 || positive_pa > POSITIVE_TANK_MAX_PA {
            return Err(LimitError::PositiveTarget {
                requested_pa: positive_pa,
            });
        }
        if negative_pa > 0 || negative_pa < NEGATIVE_TANK_MIN_PA {
            return Err(LimitError::NegativeTarget {
                requested_pa: negative_pa,
            });
        }
        Ok(TankTargets {
            positive_pa,
            negative_pa,
        })
    }

    /// The positive tank target, in pascal.
    pub const fn positive_pa(self) -> i32 {
        self.positive_pa
    }

    /// The negative tank target, in pascal.
    pub const fn negative_pa(self) -> i32 {
        self.negative_pa
    }
}

impl TryFrom<RawTankTargets> for TankTargets {
    type Error = LimitError;

    fn try_from(raw: RawTankTargets) -> Result<Self, LimitError> {
        TankTargets::new(raw.positive_pa, raw.negative_pa)
    }
}

/// The calibration of one tank pressure sensor. The firmware reports (and
/// checks against the limits)
///
/// ```text
/// calibrated = (reading - zero) * gain_ppm / 1 000 000
/// ```
///
/// where `reading` is the sensor's filtered reading through its nominal
/// transfer function and `zero` is the boot zero or `offset_pa`
/// ([`ActiveZero`], which applies when is in the firmware's README).
/// Integers only: no floats on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SensorCalibration {
    /// The sensor's reading of atmosphere (its zero error), in pascal:
    /// subtracted from every reading unless the boot zero replaces it.
    pub offset_pa: i32,
    /// Gain applied after the zero, in parts per million
    /// ([`GAIN_UNITY_PPM`] = 1.0).
    pub gain_ppm: u32,
}

impl SensorCalibration {
    /// No correction: offset 0, gain 1.
    pub const IDENTITY: SensorCalibration = SensorCalibration {
        offset_pa: 0,
        gain_ppm: GAIN_UNITY_PPM,
    };

    /// Whether the offset lies within ±[`CALIBRATION_OFFSET_MAX_PA`].
    pub const fn offset_plausible(self) -> bool {
        self.offset_pa >= -CALIBRATION_OFFSET_MAX_PA && self.offset_pa <= CALIBRATION_OFFSET_MAX_PA
    }

    /// Whether the gain lies in
    /// [`CALIBRATION_GAIN_MIN_PPM`]..=[`CALIBRATION_GAIN_MAX_PPM`].
    pub const fn gain_plausible(self) -> bool {
        self.gain_ppm >= CALIBRATION_GAIN_MIN_PPM && self.gain_ppm <= CALIBRATION_GAIN_MAX_PPM
    }
}

impl Default for SensorCalibration {
    fn default() -> Self {
        SensorCalibration::IDENTITY
    }
}

/// The calibration of both tank sensors ([`HostMsg::SetCalibration`],
/// [`CalibrationReport`]). Any value decodes; the firmware refuses one
/// that fails [`Calibration::check`] with [`NackReason::Implausible`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Calibration {
    /// The positive tank's sensor.
    pub positive: SensorCalibration,
    /// The negative tank's sensor.
    pub negative: SensorCalibration,
}

impl Calibration {
    /// No correction on either sensor.
    pub const IDENTITY: Calibration = Calibration {
        positive: SensorCalibration::IDENTITY,
        negative: SensorCalibration::IDENTITY,
    };

    /// Whether every offset and gain lies within the plausible range
    /// ([`crate::limits::CALIBRATION_OFFSET_MAX_PA`],
    /// [`crate::limits::CALIBRATION_GAIN_MIN_PPM`]..=[`crate::limits::CALIBRATION_GAIN_MAX_PPM`]);
    /// the first value outside it otherwise.
    pub const fn check(&self) -> Result<(), CalibrationError> {
        if !self.positive.offset_plausible() {
            return Err(CalibrationError::PositiveOffset {
                offset_pa: self.positive.offset_pa,
            });
        }
        if !self.positive.gain_plausible() {
            return Err(CalibrationError::PositiveGain {
                gain_ppm: self.positive.gain_ppm,
            });
        }
        if !self.negative.offset_plausible() {
            return Err(CalibrationError::NegativeOffset {
                offset_pa: self.negative.offset_pa,
            });
        }
        if !self.negative.gain_plausible() {
            return Err(CalibrationError::NegativeGain {
                gain_ppm: self.negative.gain_ppm,
            });
        }
        Ok(())
    }
}

/// A calibration value outside the plausible range ([`Calibration::check`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationError {
    /// The positive sensor's offset lies beyond ±10 kPa.
    PositiveOffset {
        /// The rejected offset, in pascal.
        offset_pa: i32,
    },
    /// The positive sensor's gain lies outside 0.9..1.1.
    PositiveGain {
        /// The rejected gain, in parts per million.
        gain_ppm: u32,
    },
    /// The negative sensor's offset lies beyond ±10 kPa.
    NegativeOffset {
        /// The rejected offset, in pascal.
        offset_pa: i32,
    },
    /// The negative sensor's gain lies outside 0.9..1.1.
    NegativeGain {
        /// The rejected gain, in parts per million.
        gain_ppm: u32,
    },
}

impl fmt::Display for CalibrationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let offset = |f: &mut fmt::Formatter<'_>, tank: &str, offset_pa: i32| {
            write!(
                f,
                "{tank} sensor offset {offset_pa} Pa is outside ±{CALIBRATION_OFFSET_MAX_PA} Pa"
            )
        };
        let gain = |f: &mut fmt::Formatter<'_>, tank: &str, gain_ppm: u32| {
            write!(
                f,
                "{tank} sensor gain {gain_ppm} ppm is outside \
                 {CALIBRATION_GAIN_MIN_PPM}..={CALIBRATION_GAIN_MAX_PPM} ppm"
            )
        };
        match *self {
            CalibrationError::PositiveOffset { offset_pa } => offset(f, "positive", offset_pa),
            CalibrationError::PositiveGain { gain_ppm } => gain(f, "positive", gain_ppm),
            CalibrationError::NegativeOffset { offset_pa } => offset(f, "negative", offset_pa),
            CalibrationError::NegativeGain { gain_ppm } => gain(f, "negative", gain_ppm),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for CalibrationError {}

/// Where the calibration in use came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationSource {
    /// No usable record at boot: [`Calibration::IDENTITY`].
    #[default]
    Default,
    /// The record read from flash at boot.
    Flash,
    /// [`HostMsg::SetCalibration`] since boot ([`CalibrationReport::record`]
    /// says whether it was stored).
    Host,
}

/// The state of the calibration record in the MCU's flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CalibrationRecord {
    /// This build keeps no record (the QEMU build): a calibration from the
    /// host lasts until the next reset.
    #[default]
    NotPersisted,
    /// The record's page is erased: no calibration was ever stored.
    Empty,
    /// A valid record of this version (read at boot or just written).
    Valid {
        /// The record format's version.
        version: u16,
    },
    /// A record whose CRC does not match (torn write, worn flash): ignored.
    BadCrc,
    /// An intact record of a format this firmware does not know: ignored.
    UnknownVersion {
        /// The record's version.
        version: u16,
    },
    /// The page holds something that is not a record: ignored.
    NotARecord,
    /// An intact record whose values fail [`Calibration::check`]: ignored.
    Implausible {
        /// The record's version.
        version: u16,
    },
    /// A calibration from the host waits to be written (it is written as
    /// soon as the MCU is disarmed with the pumps off; arming waits for it).
    WritePending,
    /// Writing the record failed (erase, program or verify error): the
    /// calibration applies until reset, the page may hold anything.
    WriteFailed,
}

impl CalibrationRecord {
    /// Whether nothing went wrong with the record: not one that was ignored
    /// (bad CRC, unknown version, not a record, implausible values) or
    /// whose write failed. An empty page, a pending write and a build
    /// without a store are sound.
    pub const fn is_sound(self) -> bool {
        !matches!(
            self,
            CalibrationRecord::BadCrc
                | CalibrationRecord::UnknownVersion { .. }
                | CalibrationRecord::NotARecord
                | CalibrationRecord::Implausible { .. }
                | CalibrationRecord::WriteFailed
        )
    }
}

/// Where the zero subtracted from a sensor's reading came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ZeroSource {
    /// The boot zero has not been taken yet: the calibration's offset applies.
    #[default]
    Pending,
    /// The reading of atmosphere at boot (it lay within the firmware's
    /// window around the calibration's offset).
    Boot,
    /// The calibration's offset (the boot reading lay outside the window,
    /// e.g. a tank still under pressure after a reset, or was not valid).
    Offset,
}

/// The zero a sensor's readings are corrected by now.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ActiveZero {
    /// Subtracted from the reading before the gain, in pascal.
    pub zero_pa: i32,
    /// Where it came from.
    pub source: ZeroSource,
}

/// The calibration the MCU applies, in its hello reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CalibrationReport {
    /// Offsets and gains in use.
    pub calibration: Calibration,
    /// Where they came from.
    pub source: CalibrationSource,
    /// The flash record (read at boot, or after the last write).
    pub record: CalibrationRecord,
    /// The zero the positive sensor's readings are corrected by.
    pub positive_zero: ActiveZero,
    /// The zero the negative sensor's readings are corrected by.
    pub negative_zero: ActiveZero,
}

/// A command from the host (PC) to the MCU. Every command is answered with
/// [`McuMsg::Ack`] or [`McuMsg::Nack`] carrying the command frame's sequence
/// number, except [`HostMsg::Hello`], answered with [`McuMsg::HelloReply`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum HostMsg {
    /// Ask for the protocol and firmware versions, limits and reset cause.
    Hello,
    /// Liveness check; acked. The nonce is opaque to the MCU.
    Ping {
        /// Any value chosen by the host.
        nonce: u32,
    },
    /// Set every chamber's valves at once (needs the MCU armed).
    SetChambers {
        /// The new state per chamber.
        chambers: Chambers,
    },
    /// Close every inlet and outlet: hold the air in all chambers.
    SealAll,
    /// Emergency: open every outlet (deflate all chambers) and stop the pumps.
    /// Accepted in every state, except while the negative tank is past its
    /// limit or has no valid reading ([`NackReason::Refused`]): the outlets
    /// would expose the chambers to that tank.
    VentAll,
    /// Pump control (needs the MCU armed).
    SetPumps {
        /// Mode of the positive (pressure) pump.
        positive: PumpMode,
        /// Mode of the negative (vacuum) pump.
        negative: PumpMode,
    },
    /// Tank pressure targets for [`PumpMode::Regulate`].
    SetTankTargets(TankTargets),
    /// Arm the MCU: allow valve and pump commands. Refused
    /// ([`NackReason::Tripped`]) while any fault is latched, and
    /// ([`NackReason::Refused`]) while a fault condition is present.
    Arm,
    /// Disarm: pumps off, all valves sealed. Does **not** clear latched
    /// faults: only [`HostMsg::ClearFaults`] does.
    Disarm,
    /// Telemetry period; 0 stops telemetry.
    SetTelemetryInterval {
        /// Milliseconds between two [`McuMsg::Telemetry`] frames.
        interval_ms: u16,
    },
    /// Keeps an armed MCU from tripping on host silence (any valid frame does).
    Heartbeat,
    /// Acknowledge latched faults: clears exactly the named faults. Refused
    /// ([`NackReason::Refused`], nothing cleared) while the condition of a
    /// named fault is still present. When no fault stays latched the MCU
    /// leaves [`ArmState::Tripped`] for [`ArmState::Disarmed`].
    ClearFaults {
        /// The faults being acknowledged (a person named them).
        faults: FaultFlags,
    },
    /// Set both sensors' calibration (offset and gain), applied at once and
    /// stored in flash. Only while disarmed: refused with
    /// [`NackReason::Refused`] while armed, [`NackReason::Tripped`] while
    /// faults are latched, and [`NackReason::Implausible`] (nothing
    /// applied) when [`Calibration::check`] fails. The hello reply shows
    /// the result ([`HelloReply::calibration`]).
    SetCalibration(Calibration),
}

/// Firmware version, semantic-versioning style.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FirmwareVersion {
    /// Major version.
    pub major: u8,
    /// Minor version.
    pub minor: u8,
    /// Patch version.
    pub patch: u8,
}

/// Why the MCU last reset (from the STM32 RCC_CSR flags).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ResetCause {
    /// Power-on or brown-out reset.
    PowerOn,
    /// NRST pin.
    Pin,
    /// Software reset (SYSRESETREQ).
    Software,
    /// Independent watchdog: the control loop stalled.
    IndependentWatchdog,
    /// Window watchdog.
    WindowWatchdog,
    /// Low-power management reset.
    LowPower,
    /// No flag set, or not known on this target (e.g. under QEMU).
    Unknown,
}

/// The MCU's answer to [`HostMsg::Hello`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HelloReply {
    /// The MCU's [`crate::PROTOCOL_VERSION`].
    pub protocol_version: u8,
    /// The firmware's version.
    pub firmware_version: FirmwareVersion,
    /// The positive tank's hard limit compiled into the firmware, in pascal.
    pub positive_tank_max_pa: i32,
    /// The negative tank's hard limit compiled into the firmware, in pascal.
    pub negative_tank_min_pa: i32,
    /// Number of chambers the firmware drives.
    pub chamber_count: u8,
    /// Why the MCU last reset.
    pub reset_cause: ResetCause,
    /// Faults latched now (waiting for [`HostMsg::ClearFaults`]).
    pub latched_faults: FaultFlags,
    /// What last stopped the outputs before this boot (kept in no-init RAM
    /// across the reset).
    pub last_stop: LastStop,
    /// The smallest telemetry interval the MCU accepts, in milliseconds
    /// (from the baud rate and the telemetry frame size).
    pub min_telemetry_interval_ms: u16,
    /// The sensor calibration in use, where it came from and the state of
    /// its flash record.
    pub calibration: CalibrationReport,
}

/// What last forced the outputs safe before the current boot, as recorded
/// in RAM that survives a reset (not a power loss).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum LastStop {
    /// Nothing recorded (power-on, or the record did not survive).
    #[default]
    None,
    /// The safety loop tripped; the first fault of that trip.
    Trip {
        /// The fault.
        fault: Fault,
    },
    /// A panic, at this source line of the firmware.
    Panic {
        /// Source line of the panic.
        line: u32,
    },
    /// A HardFault exception at this program counter.
    HardFault {
        /// The faulting instruction's address.
        pc: u32,
    },
    /// An interrupt or exception without a handler.
    UnexpectedInterrupt {
        /// Its IRQ number (negative: a core exception).
        irqn: i16,
    },
}

/// Why a command was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NackReason {
    /// The frame passed its CRC but its message did not decode (including
    /// tank targets outside the hard limits).
    Malformed,
    /// The frame passed its CRC but names a message this firmware does not know.
    UnknownMessage,
    /// The command needs the MCU armed.
    NotArmed,
    /// Faults are latched: acknowledge them with [`HostMsg::ClearFaults`],
    /// then arm.
    Tripped,
    /// The command cannot run in the current state (e.g. arm while a fault
    /// condition is still present, vent onto a tank past its limit, clear a
    /// fault whose condition is present, calibrate while armed).
    Refused,
    /// A tank target lies inside the limits but not the firmware's guard
    /// band (a margin inside each limit).
    GuardBand,
    /// A telemetry interval shorter than the line can carry
    /// ([`HelloReply::min_telemetry_interval_ms`]).
    IntervalTooShort,
    /// A calibration outside the plausible range ([`Calibration::check`]):
    /// nothing applied.
    Implausible,
}

/// The MCU's safety state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ArmState {
    /// Pumps off, valves sealed; only safe commands are accepted.
    #[default]
    Disarmed,
    /// Valve and pump commands are accepted.
    Armed,
    /// A fault is latched: pumps off, valves in the safe state, until every
    /// latched fault is acknowledged with [`HostMsg::ClearFaults`].
    Tripped,
}

/// A condition that trips the safety loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Fault {
    /// The positive tank reached [`POSITIVE_TANK_MAX_PA`].
    PositiveOverLimit,
    /// The negative tank reached [`NEGATIVE_TANK_MIN_PA`].
    NegativeOverLimit,
    /// The positive tank's sensor (or its supply) reads out of range.
    PositiveSensor,
    /// The negative tank's sensor (or its supply) reads out of range.
    NegativeSensor,
    /// The positive pump ran longer than its run-time limit.
    PositivePumpRunTime,
    /// The negative pump ran longer than its run-time limit.
    NegativePumpRunTime,
    /// No valid frame from the host within the silence deadline while armed.
    HostSilence,
    /// The positive pump ran but its tank's reading did not rise: stuck
    /// sensor, dead pump or a leak.
    PositivePumpNoRise,
    /// The negative pump ran but its tank's reading did not fall: stuck
    /// sensor, dead pump or a leak.
    NegativePumpNoRise,
    /// The crystal (HSE) did not start: the MCU runs on its internal clock.
    ClockFallback,
}

/// The fault in words, for people (logs, error messages).
impl fmt::Display for Fault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Fault::PositiveOverLimit => "positive tank over its pressure limit",
            Fault::NegativeOverLimit => "negative tank over its vacuum limit",
            Fault::PositiveSensor => "positive tank sensor (or its supply) out of range",
            Fault::NegativeSensor => "negative tank sensor (or its supply) out of range",
            Fault::PositivePumpRunTime => "positive pump over its run-time limit",
            Fault::NegativePumpRunTime => "negative pump over its run-time limit",
            Fault::HostSilence => "host silent past the deadline",
            Fault::PositivePumpNoRise => {
                "positive pump ran but its tank did not rise (stuck sensor, dead pump, leak)"
            }
            Fault::NegativePumpNoRise => {
                "negative pump ran but its tank did not fall (stuck sensor, dead pump, leak)"
            }
            Fault::ClockFallback => "crystal did not start: running on the internal clock",
        })
    }
}

impl Fault {
    /// Every fault, in wire order.
    pub const ALL: [Fault; 10] = [
        Fault::PositiveOverLimit,
        Fault::NegativeOverLimit,
        Fault::PositiveSensor,
        Fault::NegativeSensor,
        Fault::PositivePumpRunTime,
        Fault::NegativePumpRunTime,
        Fault::HostSilence,
        Fault::PositivePumpNoRise,
        Fault::NegativePumpNoRise,
        Fault::ClockFallback,
    ];

    /// This fault's bit in [`FaultFlags`].
    pub const fn bit(self) -> u16 {
        1 << (self as u16)
    }
}

/// A set of [`Fault`]s, one bit each ([`Fault::bit`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaultFlags(pub u16);

impl FaultFlags {
    /// No fault.
    pub const NONE: FaultFlags = FaultFlags(0);

    /// Whether `fault` is in the set.
    pub const fn contains(self, fault: Fault) -> bool {
        self.0 & fault.bit() != 0
    }

    /// The set with `fault` added.
    pub const fn with(self, fault: Fault) -> FaultFlags {
        FaultFlags(self.0 | fault.bit())
    }

    /// Whether the set is empty.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The faults in both sets.
    pub const fn union(self, other: FaultFlags) -> FaultFlags {
        FaultFlags(self.0 | other.0)
    }

    /// The faults of `self` that are not in `other`.
    pub const fn without(self, other: FaultFlags) -> FaultFlags {
        FaultFlags(self.0 & !other.0)
    }

    /// The faults in both `self` and `other`.
    pub const fn intersection(self, other: FaultFlags) -> FaultFlags {
        FaultFlags(self.0 & other.0)
    }

    /// The faults in the set, in wire order.
    pub fn iter(self) -> impl Iterator<Item = Fault> {
        Fault::ALL.into_iter().filter(move |f| self.contains(*f))
    }
}

/// The pressure reported for a tank whose sensor gives no valid reading
/// (out of range, no sample): far outside any real gauge pressure.
pub const NO_READING_PA: i32 = i32::MIN;

/// Periodic state report from the MCU.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Telemetry {
    /// MCU time since reset, in milliseconds (wraps after ~49 days).
    pub time_ms: u32,
    /// Positive tank pressure, gauge, in pascal; [`NO_READING_PA`] when the
    /// sensor gives no valid reading.
    pub positive_tank_pa: i32,
    /// Negative tank pressure, gauge, in pascal; [`NO_READING_PA`] when the
    /// sensor gives no valid reading.
    pub negative_tank_pa: i32,
    /// The valve state of every chamber.
    pub chambers: Chambers,
    /// Whether the positive pump is running.
    pub positive_pump_on: bool,
    /// Whether the negative pump is running.
    pub negative_pump_on: bool,
    /// The safety state.
    pub state: ArmState,
    /// Faults latched (until [`HostMsg::ClearFaults`]).
    pub faults: FaultFlags,
    /// Control-loop ticks that overran their period since reset.
    pub loop_overruns: u32,
}

/// Sent once when a fault trips the safety loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaultEvent {
    /// MCU time of the trip, in milliseconds.
    pub time_ms: u32,
    /// What tripped.
    pub fault: Fault,
    /// Positive tank pressure at the trip, in pascal ([`NO_READING_PA`] if none).
    pub positive_tank_pa: i32,
    /// Negative tank pressure at the trip, in pascal ([`NO_READING_PA`] if none).
    pub negative_tank_pa: i32,
}

/// A message from the MCU to the host.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, MaxSize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum McuMsg {
    /// Answer to [`HostMsg::Hello`].
    HelloReply(HelloReply),
    /// The command with this sequence number was accepted.
    Ack {
        /// Sequence number of the acknowledged host frame.
        seq: u16,
    },
    /// The command with this sequence number was refused.
    Nack {
        /// Sequence number of the refused host frame.
        seq: u16,
        /// Why.
        reason: NackReason,
    },
    /// Periodic state report.
    Telemetry(Telemetry),
    /// A fault tripped the safety loop.
    Fault(FaultEvent),
}

/// A message type that travels in a frame.
pub trait Message: Serialize + for<'de> Deserialize<'de> + MaxSize {
    /// Number of enum variants: a decoded tag at or past this is an unknown message.
    const VARIANT_COUNT: u8;
    /// Direction byte, covered by the frame CRC but not sent, so that a frame
    /// is only accepted by a receiver of its own direction.
    const DIRECTION: u8;
}

impl Message for HostMsg {
    const VARIANT_COUNT: u8 = 13;
    const DIRECTION: u8 = b'H';
}

impl Message for McuMsg {
    const VARIANT_COUNT: u8 = 5;
    const DIRECTION: u8 = b'M';
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::string::ToString;

    use super::*;

    fn with_positive(offset_pa: i32, gain_ppm: u32) -> Calibration {
        Calibration {
            positive: SensorCalibration {
                offset_pa,
                gain_ppm,
            },
            negative: SensorCalibration::IDENTITY,
        }
    }

    #[test]
    fn calibration_limits_are_inclusive() {
        assert_eq!(Calibration::IDENTITY.check(), Ok(()));
        for (offset_pa, gain_ppm) in [
            (CALIBRATION_OFFSET_MAX_PA, CALIBRATION_GAIN_MIN_PPM),
            (-CALIBRATION_OFFSET_MAX_PA, CALIBRATION_GAIN_MAX_PPM),
        ] {
            assert_eq!(with_positive(offset_pa, gain_ppm).check(), Ok(()));
        }
        assert_eq!(
            with_positive(CALIBRATION_OFFSET_MAX_PA + 1, GAIN_UNITY_PPM).check(),
            Err(CalibrationError::PositiveOffset { offset_pa: 10_001 })
        );
        assert_eq!(
            with_positive(0, CALIBRATION_GAIN_MIN_PPM - 1).check(),
            Err(CalibrationError::PositiveGain { gain_ppm: 899_999 })
        );
        let negative = Calibration {
            positive: SensorCalibration::IDENTITY,
            negative: SensorCalibration {
                offset_pa: i32::MIN,
                gain_ppm: 0,
            },
        };
        assert_eq!(
            negative.check(),
            Err(CalibrationError::NegativeOffset {
                offset_pa: i32::MIN
            })
        );
        let gain = Calibration {
            negative: SensorCalibration {
                offset_pa: 0,
                gain_ppm: CALIBRATION_GAIN_MAX_PPM + 1,
            },
            ..negative
        };
        assert_eq!(
            gain.check(),
            Err(CalibrationError::NegativeGain {
                gain_ppm: 1_100_001
            })
        );
    }

    #[test]
    fn only_ignored_or_failed_records_are_unsound() {
        assert!(CalibrationRecord::Empty.is_sound());
        assert!(CalibrationRecord::NotPersisted.is_sound());
        assert!(CalibrationRecord::WritePending.is_sound());
        assert!(CalibrationRecord::Valid { version: 1 }.is_sound());
        assert!(!CalibrationRecord::BadCrc.is_sound());
        assert!(!CalibrationRecord::UnknownVersion { version: 2 }.is_sound());
        assert!(!CalibrationRecord::NotARecord.is_sound());
        assert!(!CalibrationRecord::Implausible { version: 1 }.is_sound());
        assert!(!CalibrationRecord::WriteFailed.is_sound());
    }

    #[test]
    fn calibration_errors_name_the_sensor_and_the_range() {
        let e = CalibrationError::NegativeGain {
            gain_ppm: 1_300_000,
        };
        assert_eq!(
            e.to_string(),
            "negative sensor gain 1300000 ppm is outside 900000..=1100000 ppm"
        );
        let e = CalibrationError::PositiveOffset { offset_pa: -12_000 };
        assert_eq!(
            e.to_string(),
            "positive sensor offset -12000 Pa is outside ±10000 Pa"
        );
    }
}
