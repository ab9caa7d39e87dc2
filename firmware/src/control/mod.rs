//! The safety loop: host commands and sensor samples in, valve and pump
//! outputs, acks and telemetry out.
//!
//! A [`Controller`] is driven by two calls, both non-blocking:
//!
//! - [`Controller::receive`] with the serial bytes that arrived: frames are
//!   decoded ([`dexitac_protocol::Decoder`]), dispatched ([`dispatch`]) and
//!   answered with an ack, a nack or a hello reply. Commands change the
//!   *desired* state only.
//! - [`Controller::tick`] once per control period (1 ms): converts and
//!   filters the sensor samples ([`crate::sensor`], [`filter`]), corrects
//!   the filtered readings by the sensor calibration
//!   ([`crate::calibration`]), evaluates every trip condition ([`safety`]),
//!   regulates the pumps ([`pumps`]), drives the valves through their dead
//!   time ([`valves::ValveDriver`]), writes the outputs, and sends fault
//!   events and telemetry.
//! - [`Controller::store_calibration`] after `receive`, on the board: writes
//!   a calibration the host set to its [`CalibrationStore`] (flash), only
//!   while not armed with both pumps off.
//!
//! The outputs are written only by `tick`, so a command takes effect at the
//! next tick (at most one period later, plus the valve dead time when a
//! chamber changes sides), after the safety checks of that tick. Pumps only
//! run while armed.
//!
//! ```
//! use dexitac_firmware::{Clock, Config, Controller, PressureSource, Pumps, PumpOutputs,
//!     TxQueues, Valves};
//! use dexitac_firmware::sensor::{SensorSamples, NOMINAL_FRONT_END, OVERSAMPLE};
//! use dexitac_protocol::{ArmState, Chambers, EncodedFrame, HostMsg, ResetCause};
//!
//! struct Rig { now_ms: u32 }
//! impl Clock for Rig { fn now_ms(&self) -> u32 { self.now_ms } }
//! impl PressureSource for Rig {
//!     fn read_samples(&mut self) -> SensorSamples {
//!         // Both tanks at atmosphere, 5 V supply, 3.3 V reference.
//!         let fe = NOMINAL_FRONT_END;
//!         let tank = Ok([fe.sensor_counts(0, 5_000, 3_300); OVERSAMPLE]);
//!         let supply = Ok([fe.supply_counts(5_000, 3_300); OVERSAMPLE]);
//!         SensorSamples { positive: tank, negative: tank, supply }
//!     }
//! }
//! impl Valves for Rig { fn set_chambers(&mut self, _: &Chambers) {} }
//! impl Pumps for Rig { fn set_pumps(&mut self, _: PumpOutputs) {} }
//!
//! let mut rig = Rig { now_ms: 0 };
//! let mut tx = TxQueues::<512, 128>::new();
//! let mut ctl = Controller::new(Config::default(), ResetCause::PowerOn);
//! // The sensors are zeroed in the first ticks; arm after that.
//! for _ in 0..100 { rig.now_ms += 1; ctl.tick(&mut rig, &mut tx); }
//! ctl.receive(&EncodedFrame::new(1, &HostMsg::Arm).unwrap(), &rig, &mut tx);
//! assert_eq!(ctl.state(), ArmState::Armed);
//! // The host falls silent: tripped after 500 ms, and latched.
//! for _ in 0..500 { rig.now_ms += 1; ctl.tick(&mut rig, &mut tx); }
//! assert_eq!(ctl.state(), ArmState::Tripped);
//! ```

pub mod dispatch;
pub mod filter;
pub mod hw;
pub mod pumps;
pub mod safety;
pub mod valves;

use dexitac_protocol::{
    ActiveZero, ArmState, Calibration, CalibrationRecord, CalibrationReport, CalibrationSource,
    Chambers, Decoder, EncodedFrame, Fault, FaultEvent, FaultFlags, FrameError, HostMsg, LastStop,
    McuMsg, NackReason, PumpMode, ResetCause, TankTargets, Telemetry, ValveState,
    MAX_TELEMETRY_FRAME_LEN,
};

use crate::calibration::{self, CalibrationStore, StoreError};
use crate::queue::{FrameSink, Priority};
use crate::sensor::NOMINAL_FRONT_END;
use hw::{Clock, PressureSource, Pumps, SensorError, Valves};
use pumps::{MonitorLimits, PumpMonitor, Tank};
use safety::{valid_reading, Correction, TankChannel};
use valves::{ValveDriver, SAFE_CHAMBERS};

/// Run-time tunables of the safety loop. The hard tank limits are not
/// here: they are compile-time constants of the protocol crate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Config {
    /// Control period, in milliseconds; a tick later than this counts as an
    /// overrun.
    pub tick_period_ms: u32,
    /// Trip when armed and no valid frame arrived for this long, in milliseconds.
    pub host_silence_ms: u32,
    /// Pump hysteresis: a pump restarts when its tank falls this far short
    /// of the target, in pascal.
    pub pump_hysteresis_pa: i32,
    /// Longest continuous pump run, in milliseconds.
    pub pump_max_run_ms: u32,
    /// Plausibility window: a running pump's tank must rise by
    /// [`Config::min_rise_pa`] within this time, in milliseconds.
    pub rise_window_ms: u32,
    /// Smallest rise of the filtered reading per window while pumping, in
    /// pascal; a move of the reading by this much also shows that the
    /// sensor follows its tank (see [`pumps::PumpMonitor`]).
    pub min_rise_pa: i32,
    /// Stall pressures of the fastest pumps allowed for, in pascal
    /// (positive, negative): the pressure each pump drives its tank toward.
    pub pump_stall_pa: (i32, i32),
    /// Time constant of the fastest pump allowed for, into its tank, in
    /// milliseconds. With the stall pressures it bounds how fast a running
    /// pump can raise its tank while the reading has not confirmed it.
    pub fastest_pump_tau_ms: u32,
    /// How far a tank's true pressure may lie beyond a filtered reading that
    /// follows the tank (toward the limit), in pascal.
    pub reading_margin_pa: i32,
    /// Longest time a pump that is to run may be held off by the pressure
    /// bound without its reading moving, in milliseconds; then
    /// `*PumpNoRise` trips (a stuck sensor; see [`pumps::PumpMonitor`]).
    pub pump_max_hold_ms: u32,
    /// Tank targets until the host sets its own.
    pub default_targets: TankTargets,
    /// Targets must stay this far inside each hard limit, in pascal.
    pub guard_band_pa: i32,
    /// A chamber's inlet opens only after its outlet has been commanded
    /// closed this long, and the reverse, in milliseconds.
    pub valve_dead_time_ms: u32,
    /// Consecutive ticks a condition must hold before it trips (filtered
    /// reading past a limit, no valid reading).
    pub trip_after_ticks: u32,
    /// Accepted distance of the boot-time zero reading from the expected
    /// zero (the calibration's offset, 0 Pa without one), in pascal.
    pub zero_window_pa: i32,
    /// Baud rate of the host link (for the smallest telemetry interval).
    pub link_baud: u32,
}

/// Default control period: 1 ms (1 kHz).
pub const DEFAULT_TICK_PERIOD_MS: u32 = 1;
/// Default host-silence deadline: 500 ms.
pub const DEFAULT_HOST_SILENCE_MS: u32 = 500;
/// Default pump hysteresis: 2 kPa.
pub const DEFAULT_PUMP_HYSTERESIS_PA: i32 = 2_000;
/// Time the nominal tank model ([`crate::tank_model::TankModelParams::default`])
/// takes to pump its slower tank from atmosphere to the hard limit with the
/// pump running throughout (leak included): -57 kPa at 4.57 s (+50 kPa
/// takes 4.02 s). Checked against the model by the test
/// `fill_time_matches_the_tank_model`.
pub const NOMINAL_FILL_TIME_MS: u32 = 4_570;
/// Default pump run-time limit: 1.5 x [`NOMINAL_FILL_TIME_MS`]. A pump 30 %
/// weaker than nominal still reaches the largest target the guard band
/// allows within it; a pump that runs longer pumps into a leak, or its
/// sensor reads too low.
pub const DEFAULT_PUMP_MAX_RUN_MS: u32 = NOMINAL_FILL_TIME_MS * 3 / 2;
/// Default plausibility window: 1 s.
pub const DEFAULT_RISE_WINDOW_MS: u32 = 1_000;
/// Default smallest rise per window: 1.5 kPa. The filtered reading's noise
/// (sensor noise of ±2 % of full scale, i.e. ±8 kPa per conversion) has a
/// standard deviation of about 0.35 kPa, 0.5 kPa for a difference of two;
/// the slowest pump the tests allow (30 % weak, a leak, at the largest
/// target) still rises more than 4 kPa per second.
pub const DEFAULT_MIN_RISE_PA: i32 = 1_500;
/// Default pump stall pressures: +80 kPa and -85 kPa, those of the tank
/// model ([`crate::tank_model::TankModelParams::default`]; checked by the
/// test `fastest_pump_matches_the_tank_model`). A real pump's come from its
/// data sheet (maximum pressure and vacuum).
pub const DEFAULT_PUMP_STALL_PA: (i32, i32) = (80_000, -85_000);
/// Default time constant of the fastest pump: 3 076 ms, the tank model's
/// 4 000 ms for a pump 30 % stronger than nominal (4 000 / 1.3, rounded
/// down: toward the faster pump).
pub const DEFAULT_FASTEST_PUMP_TAU_MS: u32 = 3_076;
/// Default reading margin: 3 kPa. It covers the filtered noise (sensor
/// noise of ±2 % of full scale: about 0.54 kPa standard deviation, 1.6 kPa
/// at three), the boot zero's residue and the filter's lag; or a sensor
/// that freezes, with its pump off, up to 3 kPa below the pressure it
/// showed (a zero error of ±3 kPa). With the 6 kPa guard band it leaves the
/// weakest pump the tests allow (30 % weak, leak) time to confirm a top-up
/// from target - hysteresis before the bound reaches the limit.
pub const DEFAULT_READING_MARGIN_PA: i32 = 3_000;
/// Default longest hold of a pump by the pressure bound without its reading
/// moving 1.5 kPa: 10 s. While held the pump is off, so the true pressure
/// stays below the bound (< the limit); the hold ends as soon as the
/// reading moves ([`DEFAULT_MIN_RISE_PA`]), which a healthy tank's does
/// within 10 s through chamber traffic or its leak (the tank model's leak,
/// 120 s time constant, lowers 38 kPa by 1.5 kPa in about 5 s) or noise.
/// A frozen reading never moves: `*PumpNoRise` after 10 s.
pub const DEFAULT_PUMP_MAX_HOLD_MS: u32 = 10_000;
/// Default tank targets: +40 kPa and -45 kPa.
pub const DEFAULT_TARGETS_PA: (i32, i32) = (40_000, -45_000);
/// Default guard band: 6 kPa (targets at most +44 / -51 kPa). It covers
/// the boot zero's error ([`DEFAULT_ZERO_WINDOW_PA`]), the filtered noise
/// and the pump's overshoot while the filter catches up.
pub const DEFAULT_GUARD_BAND_PA: i32 = 6_000;
/// Default valve dead time: 30 ms = the 20 ms worst-case release of the
/// valve class (the paper: the valves respond in more than 10 ms) + 50 %.
pub const DEFAULT_VALVE_DEAD_TIME_MS: u32 = 30;
/// Default consecutive ticks before a trip: 3.
pub const DEFAULT_TRIP_AFTER_TICKS: u32 = 3;
/// Default accepted boot zero: within ±4 kPa of the expected zero (a
/// sensor's zero tolerance, about ±1 % of its 400 kPa span; the expected
/// zero is the calibration's offset, 0 Pa without one). A reading further
/// away (tank still pressurised after a reset) keeps the expected zero.
pub const DEFAULT_ZERO_WINDOW_PA: i32 = 4_000;
/// Default link baud rate: 115 200.
pub const DEFAULT_LINK_BAUD: u32 = 115_200;
/// Ticks after boot at which the sensors are zeroed: two filter windows.
pub const ZERO_AT_TICK: u32 = 2 * filter::FILTER_TICKS as u32;

/// The smallest telemetry interval for a link of `baud` (8N1, 10 bits a
/// byte): twice the line time of the largest telemetry frame
/// ([`MAX_TELEMETRY_FRAME_LEN`]), so at least half the line stays free for
/// replies and fault events. 8 ms at 115 200 baud (a 44-byte frame takes
/// 3.8 ms).
pub const fn min_telemetry_interval_ms(baud: u32) -> u16 {
    let bits = 2 * MAX_TELEMETRY_FRAME_LEN as u64 * 10 * 1_000;
    let baud = if baud == 0 { 1 } else { baud as u64 };
    let ms = bits.div_ceil(baud);
    if ms > u16::MAX as u64 {
        u16::MAX
    } else {
        ms as u16
    }
}

impl Default for Config {
    fn default() -> Self {
        Config {
            tick_period_ms: DEFAULT_TICK_PERIOD_MS,
            host_silence_ms: DEFAULT_HOST_SILENCE_MS,
            pump_hysteresis_pa: DEFAULT_PUMP_HYSTERESIS_PA,
            pump_max_run_ms: DEFAULT_PUMP_MAX_RUN_MS,
            rise_window_ms: DEFAULT_RISE_WINDOW_MS,
            min_rise_pa: DEFAULT_MIN_RISE_PA,
            pump_stall_pa: DEFAULT_PUMP_STALL_PA,
            fastest_pump_tau_ms: DEFAULT_FASTEST_PUMP_TAU_MS,
            reading_margin_pa: DEFAULT_READING_MARGIN_PA,
            pump_max_hold_ms: DEFAULT_PUMP_MAX_HOLD_MS,
            default_targets: match TankTargets::new(DEFAULT_TARGETS_PA.0, DEFAULT_TARGETS_PA.1) {
                Ok(t) => t,
                // Unreachable: the constants lie inside the limits (checked
                // by the test `default_targets_are_inside_the_guard_band`).
                Err(_) => TANK_TARGETS_ZERO,
            },
            guard_band_pa: DEFAULT_GUARD_BAND_PA,
            valve_dead_time_ms: DEFAULT_VALVE_DEAD_TIME_MS,
            trip_after_ticks: DEFAULT_TRIP_AFTER_TICKS,
            zero_window_pa: DEFAULT_ZERO_WINDOW_PA,
            link_baud: DEFAULT_LINK_BAUD,
        }
    }
}

/// Both targets at 0 Pa (always inside the limits).
const TANK_TARGETS_ZERO: TankTargets = match TankTargets::new(0, 0) {
    Ok(t) => t,
    Err(_) => panic!("0 Pa lies inside both limits"),
};

impl Config {
    fn monitor_limits(&self, tank: Tank) -> MonitorLimits {
        let stall_pa = match tank {
            Tank::Positive => self.pump_stall_pa.0,
            Tank::Negative => self.pump_stall_pa.1,
        };
        MonitorLimits {
            max_run_ms: self.pump_max_run_ms,
            rise_window_ms: self.rise_window_ms,
            min_rise_pa: self.min_rise_pa,
            limit_pa: tank.toward_limit_pa(tank.limit_pa()),
            stall_pa: tank.toward_limit_pa(stall_pa),
            fastest_tau_ms: self.fastest_pump_tau_ms,
            reading_margin_pa: self.reading_margin_pa,
            period_ms: self.tick_period_ms,
            max_hold_ms: self.pump_max_hold_ms,
        }
    }

    /// Whether `targets` keep [`Config::guard_band_pa`] inside both limits.
    pub fn targets_inside_guard_band(&self, targets: TankTargets) -> bool {
        [
            (Tank::Positive, targets.positive_pa()),
            (Tank::Negative, targets.negative_pa()),
        ]
        .iter()
        .all(|&(tank, target_pa)| {
            tank.toward_limit_pa(target_pa)
                <= tank
                    .toward_limit_pa(tank.limit_pa())
                    .saturating_sub(self.guard_band_pa)
        })
    }

    /// The smallest telemetry interval of this link.
    pub const fn min_telemetry_interval_ms(&self) -> u16 {
        min_telemetry_interval_ms(self.link_baud)
    }
}

/// The pump outputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PumpOutputs {
    /// The positive (pressure) pump runs.
    pub positive_on: bool,
    /// The negative (vacuum) pump runs.
    pub negative_on: bool,
}

impl PumpOutputs {
    /// Both pumps off.
    pub const OFF: PumpOutputs = PumpOutputs {
        positive_on: false,
        negative_on: false,
    };
}

/// Counters of the serial link.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkStats {
    /// Frames decoded and dispatched.
    pub frames_ok: u32,
    /// Byte runs that were not a valid frame (COBS, CRC, length, version,
    /// malformed or unknown message).
    pub frame_errors: u32,
    /// Urgent frames (replies, fault events) dropped: their queue was full.
    pub urgent_dropped: u32,
    /// Telemetry frames dropped: the line was busy.
    pub telemetry_dropped: u32,
}

/// What one [`Controller::tick`] changed that the board must act on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TickReport {
    /// Faults latched in this tick (the board records the first across a
    /// reset, [`crate::persist`]).
    pub new_faults: FaultFlags,
}

/// The boot-time zeroing of the sensors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Zero {
    /// Waiting for [`ZERO_AT_TICK`] ticks of readings.
    Pending { ticks: u32 },
    /// Done: each sensor's settled reading of atmosphere then (before any
    /// correction), if it had a valid one. Whether it is the zero in use
    /// depends on the calibration ([`calibration::choose_zero`]).
    Done {
        positive_pa: Option<i32>,
        negative_pa: Option<i32>,
    },
}

/// The safety loop. See the [module docs](self) and the fault table in the
/// crate docs.
pub struct Controller {
    config: Config,
    reset_cause: ResetCause,
    last_stop: LastStop,
    decoder: Decoder<HostMsg>,
    state: ArmState,
    /// Latched faults: set by a condition, cleared only by `ClearFaults`.
    faults: FaultFlags,
    /// Conditions present at the last tick.
    present: FaultFlags,
    /// Faults reported from outside the core (clock), latched at the next tick.
    external: FaultFlags,
    /// The valve states the host asked for.
    chambers: Chambers,
    valves: ValveDriver,
    positive_mode: PumpMode,
    negative_mode: PumpMode,
    targets: TankTargets,
    pumps: PumpOutputs,
    positive: TankChannel,
    negative: TankChannel,
    zero: Zero,
    calibration: Calibration,
    calibration_source: CalibrationSource,
    calibration_record: CalibrationRecord,
    /// A calibration from the host waits for [`Controller::store_calibration`].
    calibration_write_pending: bool,
    positive_monitor: PumpMonitor,
    negative_monitor: PumpMonitor,
    /// The pumps the regulator wants (its hysteresis state); a pump held
    /// off by its monitor is wanted but not driven ([`Controller::pumps`]).
    demand: PumpOutputs,
    /// The pumps the monitors hold off this tick (the pressure bound).
    held: PumpOutputs,
    last_frame_ms: u32,
    last_tick_ms: Option<u32>,
    telemetry_interval_ms: u16,
    last_telemetry_ms: u32,
    loop_overruns: u32,
    tx_seq: u16,
    link: LinkStats,
}

impl Controller {
    /// A disarmed controller in the safe state. `reset_cause` is reported
    /// in the hello reply.
    pub fn new(config: Config, reset_cause: ResetCause) -> Self {
        // Built in place (no local to move out: the controller is large).
        // The identity calibration and the pending zero need no correction,
        // which is what `TankChannel::new` starts with.
        Controller {
            config,
            reset_cause,
            last_stop: LastStop::None,
            decoder: Decoder::new(),
            state: ArmState::Disarmed,
            faults: FaultFlags::NONE,
            present: FaultFlags::NONE,
            external: FaultFlags::NONE,
            chambers: SAFE_CHAMBERS,
            valves: ValveDriver::new(),
            positive_mode: PumpMode::Off,
            negative_mode: PumpMode::Off,
            targets: config.default_targets,
            pumps: PumpOutputs::OFF,
            positive: TankChannel::new(),
            negative: TankChannel::new(),
            zero: Zero::Pending { ticks: 0 },
            calibration: Calibration::IDENTITY,
            calibration_source: CalibrationSource::Default,
            calibration_record: CalibrationRecord::NotPersisted,
            calibration_write_pending: false,
            positive_monitor: PumpMonitor::default(),
            negative_monitor: PumpMonitor::default(),
            demand: PumpOutputs::OFF,
            held: PumpOutputs::OFF,
            last_frame_ms: 0,
            last_tick_ms: None,
            telemetry_interval_ms: 0,
            last_telemetry_ms: 0,
            loop_overruns: 0,
            tx_seq: 0,
            link: LinkStats::default(),
        }
    }

    /// The same controller, reporting `last_stop` (read from the record
    /// that survived the reset) in its hello reply.
    pub fn with_last_stop(mut self, last_stop: LastStop) -> Self {
        self.last_stop = last_stop;
        self
    }

    /// The same controller, with the calibration stored in `page`
    /// ([`Controller::load_calibration_record`]).
    pub fn with_calibration_record(mut self, page: &[u8]) -> Self {
        self.load_calibration_record(page);
        self
    }

    /// Applies the calibration stored in `page` (the flash page of the
    /// record, [`calibration::decode`]) if it holds a valid record, else
    /// the identity; the hello reply reports which. Called once at boot.
    pub fn load_calibration_record(&mut self, page: &[u8]) {
        let loaded = calibration::decode(page);
        self.calibration_record = loaded.record;
        match loaded.calibration {
            Some(stored) => {
                self.calibration = stored;
                self.calibration_source = CalibrationSource::Flash;
            }
            None => {
                self.calibration = Calibration::IDENTITY;
                self.calibration_source = CalibrationSource::Default;
            }
        }
        self.apply_calibration();
    }

    /// Latches `fault` at the next tick (a condition found outside the
    /// control core, e.g. [`Fault::ClockFallback`]); it trips like any other.
    pub fn report_fault(&mut self, fault: Fault) {
        self.external = self.external.with(fault);
    }

    /// The safety state.
    pub fn state(&self) -> ArmState {
        self.state
    }

    /// Latched faults (until `ClearFaults`).
    pub fn faults(&self) -> FaultFlags {
        self.faults
    }

    /// Fault conditions present at the last tick.
    pub fn present(&self) -> FaultFlags {
        self.present
    }

    /// The valve states driven at the last tick (after the dead time).
    pub fn chambers(&self) -> Chambers {
        self.valves.driven()
    }

    /// The pump outputs written at the last tick.
    pub fn pumps(&self) -> PumpOutputs {
        self.pumps
    }

    /// The filtered, corrected tank readings of the last tick: (positive,
    /// negative).
    pub fn readings(&self) -> (Result<i32, SensorError>, Result<i32, SensorError>) {
        (self.positive.reading(), self.negative.reading())
    }

    /// The zeros in use, in pascal (positive, negative), once the
    /// boot-time zeroing is done.
    pub fn zero_offsets_pa(&self) -> Option<(i32, i32)> {
        match self.zero {
            Zero::Done { .. } => Some((
                self.positive.correction().zero_pa,
                self.negative.correction().zero_pa,
            )),
            Zero::Pending { .. } => None,
        }
    }

    /// The calibration in use, where it came from, its flash record and the
    /// zeros (the hello reply's [`dexitac_protocol::HelloReply::calibration`]).
    pub fn calibration_report(&self) -> CalibrationReport {
        CalibrationReport {
            calibration: self.calibration,
            source: self.calibration_source,
            record: self.calibration_record,
            positive_zero: self.active_zero(Tank::Positive),
            negative_zero: self.active_zero(Tank::Negative),
        }
    }

    /// Whether a calibration from the host waits to be stored
    /// ([`Controller::store_calibration`]).
    pub fn calibration_write_pending(&self) -> bool {
        self.calibration_write_pending
    }

    /// Writes a calibration the host set since the last call to `store`,
    /// if the MCU is not armed and both pumps are off (else it stays
    /// pending; arming waits for it). Returns the record's new state when
    /// it wrote (or tried to).
    ///
    /// The board calls this after [`Controller::receive`], having fed the
    /// watchdog: a flash page erase stalls the STM32F103 for up to 40 ms.
    pub fn store_calibration(
        &mut self,
        store: &mut impl CalibrationStore,
    ) -> Option<CalibrationRecord> {
        if !self.calibration_write_pending
            || self.state == ArmState::Armed
            || self.pumps != PumpOutputs::OFF
        {
            return None;
        }
        self.calibration_write_pending = false;
        self.calibration_record = match store.write_record(&calibration::encode(&self.calibration))
        {
            Ok(()) => CalibrationRecord::Valid {
                version: calibration::RECORD_VERSION,
            },
            Err(StoreError::NotPersisted) => CalibrationRecord::NotPersisted,
            Err(StoreError::Failed) => CalibrationRecord::WriteFailed,
        };
        Some(self.calibration_record)
    }

    /// Applies `calibration` at once (from the host; the dispatcher checked
    /// state and plausibility) and marks it for the store.
    fn set_calibration(&mut self, calibration: Calibration) {
        self.calibration = calibration;
        self.calibration_source = CalibrationSource::Host;
        self.calibration_record = CalibrationRecord::WritePending;
        self.calibration_write_pending = true;
        self.apply_calibration();
    }

    /// The zero `tank`'s readings are corrected by.
    fn active_zero(&self, tank: Tank) -> ActiveZero {
        let (boot_pa, zeroed) = match (self.zero, tank) {
            (Zero::Pending { .. }, _) => (None, false),
            (Zero::Done { positive_pa, .. }, Tank::Positive) => (positive_pa, true),
            (Zero::Done { negative_pa, .. }, Tank::Negative) => (negative_pa, true),
        };
        let sensor = match tank {
            Tank::Positive => self.calibration.positive,
            Tank::Negative => self.calibration.negative,
        };
        calibration::choose_zero(sensor, boot_pa, zeroed, self.config.zero_window_pa)
    }

    /// Sets both channels' corrections from the calibration and the zeros.
    fn apply_calibration(&mut self) {
        let positive = Correction {
            zero_pa: self.active_zero(Tank::Positive).zero_pa,
            gain_ppm: self.calibration.positive.gain_ppm,
        };
        let negative = Correction {
            zero_pa: self.active_zero(Tank::Negative).zero_pa,
            gain_ppm: self.calibration.negative.gain_ppm,
        };
        self.positive.set_correction(positive);
        self.negative.set_correction(negative);
    }

    /// Ticks that came later than the control period.
    pub fn loop_overruns(&self) -> u32 {
        self.loop_overruns
    }

    /// Serial link counters.
    pub fn link_stats(&self) -> LinkStats {
        self.link
    }

    /// The configuration.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Feeds received serial bytes: every complete frame is dispatched and
    /// answered through `tx`. Corrupted frames are dropped and counted.
    pub fn receive(&mut self, bytes: &[u8], clock: &impl Clock, tx: &mut impl FrameSink) {
        for byte in bytes {
            let Some(result) = self.decoder.push(*byte) else {
                continue;
            };
            match result {
                Ok(frame) => {
                    self.link.frames_ok = self.link.frames_ok.wrapping_add(1);
                    self.last_frame_ms = clock.now_ms();
                    let reply = dispatch::dispatch(self, frame.seq, frame.msg, clock.now_ms());
                    self.send(&reply, Priority::Urgent, tx);
                }
                Err(error) => {
                    self.link.frame_errors = self.link.frame_errors.wrapping_add(1);
                    if let Some(nack) = nack_for(error) {
                        self.send(&nack, Priority::Urgent, tx);
                    }
                }
            }
        }
    }

    /// One control period: convert and filter the sensor samples, check
    /// every trip condition, regulate the pumps, drive the valves through
    /// their dead time, write the outputs, send fault events and telemetry.
    pub fn tick<H>(&mut self, hw: &mut H, tx: &mut impl FrameSink) -> TickReport
    where
        H: Clock + PressureSource + Valves + Pumps,
    {
        let now_ms = hw.now_ms();
        self.count_overrun(now_ms);
        let samples = hw.read_samples();
        self.positive.update(
            Tank::Positive,
            NOMINAL_FRONT_END.convert(&samples.positive, &samples.supply),
        );
        self.negative.update(
            Tank::Negative,
            NOMINAL_FRONT_END.convert(&samples.negative, &samples.supply),
        );
        self.zero_if_due();

        let present = self.conditions(now_ms);
        self.present = present;
        let new_faults = present.union(self.external).without(self.faults);
        self.external = FaultFlags::NONE;
        if !new_faults.is_empty() {
            self.faults = self.faults.union(new_faults);
            self.state = ArmState::Tripped;
            self.enter_safe_state();
            for fault in new_faults.iter() {
                self.send_fault(fault, now_ms, tx);
            }
        }

        self.demand = self.regulate();
        self.pumps = PumpOutputs {
            positive_on: self.demand.positive_on && !self.held.positive_on,
            negative_on: self.demand.negative_on && !self.held.negative_on,
        };
        self.record_pumps(now_ms);
        let desired = close_toward_bad_tanks(self.chambers, present);
        let driven = self
            .valves
            .drive(&desired, now_ms, self.config.valve_dead_time_ms);
        hw.set_chambers(&driven);
        hw.set_pumps(self.pumps);
        self.send_telemetry_if_due(now_ms, tx);
        TickReport { new_faults }
    }

    fn count_overrun(&mut self, now_ms: u32) {
        if let Some(last) = self.last_tick_ms {
            if now_ms.wrapping_sub(last) > self.config.tick_period_ms {
                self.loop_overruns = self.loop_overruns.wrapping_add(1);
            }
        }
        self.last_tick_ms = Some(now_ms);
    }

    /// Zeroes both sensors once, [`ZERO_AT_TICK`] ticks after boot, on the
    /// settled, uncorrected reading of atmosphere (pumps off and valves
    /// closed since boot). A reading outside [`Config::zero_window_pa`] of
    /// the calibration's offset (or none) keeps the offset
    /// ([`calibration::choose_zero`]).
    fn zero_if_due(&mut self) {
        let Zero::Pending { ticks } = self.zero else {
            return;
        };
        if ticks + 1 < ZERO_AT_TICK {
            self.zero = Zero::Pending { ticks: ticks + 1 };
            return;
        }
        let atmosphere = |channel: &TankChannel| {
            valid_reading(channel.uncorrected()).filter(|_| channel.settled())
        };
        self.zero = Zero::Done {
            positive_pa: atmosphere(&self.positive),
            negative_pa: atmosphere(&self.negative),
        };
        self.apply_calibration();
    }

    /// Whether the boot-time zeroing is done (arming waits for it).
    pub fn zeroed(&self) -> bool {
        matches!(self.zero, Zero::Done { .. })
    }

    /// Every condition present now (host silence only while armed).
    fn conditions(&mut self, now_ms: u32) -> FaultFlags {
        let trip_after = self.config.trip_after_ticks;
        // What the pumps would do this tick if nothing trips.
        let wanted = self.regulate();
        let positive_findings = self.positive_monitor.check(
            valid_reading(self.positive.reading()).map(|pa| Tank::Positive.toward_limit_pa(pa)),
            now_ms,
            wanted.positive_on,
            &self.config.monitor_limits(Tank::Positive),
        );
        let negative_findings = self.negative_monitor.check(
            valid_reading(self.negative.reading()).map(|pa| Tank::Negative.toward_limit_pa(pa)),
            now_ms,
            wanted.negative_on,
            &self.config.monitor_limits(Tank::Negative),
        );
        self.held = PumpOutputs {
            positive_on: positive_findings.hold_off,
            negative_on: negative_findings.hold_off,
        };
        let mut flags = self
            .positive
            .conditions(Tank::Positive, positive_findings, trip_after)
            .union(
                self.negative
                    .conditions(Tank::Negative, negative_findings, trip_after),
            );
        if self.state == ArmState::Armed
            && now_ms.wrapping_sub(self.last_frame_ms) >= self.config.host_silence_ms
        {
            flags = flags.with(Fault::HostSilence);
        }
        flags
    }

    /// Pumps off (modes and outputs), every valve commanded closed.
    fn enter_safe_state(&mut self) {
        self.chambers = SAFE_CHAMBERS;
        self.positive_mode = PumpMode::Off;
        self.negative_mode = PumpMode::Off;
        self.pumps = PumpOutputs::OFF;
        self.demand = PumpOutputs::OFF;
        self.positive_monitor.reset();
        self.negative_monitor.reset();
    }

    /// The pump outputs for this tick: off unless armed with a valid reading.
    fn regulate(&self) -> PumpOutputs {
        if self.state != ArmState::Armed {
            return PumpOutputs::OFF;
        }
        let hysteresis_pa = self.config.pump_hysteresis_pa;
        let positive_on = valid_reading(self.positive.reading()).is_some_and(|pa| {
            pumps::regulate(
                Tank::Positive,
                self.positive_mode,
                self.demand.positive_on,
                pa,
                self.targets.positive_pa(),
                hysteresis_pa,
            )
        });
        let negative_on = valid_reading(self.negative.reading()).is_some_and(|pa| {
            pumps::regulate(
                Tank::Negative,
                self.negative_mode,
                self.demand.negative_on,
                pa,
                self.targets.negative_pa(),
                hysteresis_pa,
            )
        });
        PumpOutputs {
            positive_on,
            negative_on,
        }
    }

    fn record_pumps(&mut self, now_ms: u32) {
        let toward = |tank: Tank, channel: &TankChannel| {
            tank.toward_limit_pa(valid_reading(channel.reading()).unwrap_or(0))
        };
        let positive = toward(Tank::Positive, &self.positive);
        let negative = toward(Tank::Negative, &self.negative);
        self.positive_monitor
            .record(self.pumps.positive_on, positive, now_ms);
        self.negative_monitor
            .record(self.pumps.negative_on, negative, now_ms);
    }

    /// Encodes and queues `msg`; a full queue drops it (counted).
    fn send(&mut self, msg: &McuMsg, priority: Priority, tx: &mut impl FrameSink) {
        let seq = self.tx_seq;
        self.tx_seq = self.tx_seq.wrapping_add(1);
        let sent = match EncodedFrame::new(seq, msg) {
            Ok(frame) => tx.send(&frame, priority).is_ok(),
            Err(_) => false,
        };
        if !sent {
            let counter = match priority {
                Priority::Urgent => &mut self.link.urgent_dropped,
                Priority::Telemetry => &mut self.link.telemetry_dropped,
            };
            *counter = counter.wrapping_add(1);
        }
    }

    fn send_fault(&mut self, fault: Fault, now_ms: u32, tx: &mut impl FrameSink) {
        let event = FaultEvent {
            time_ms: now_ms,
            fault,
            positive_tank_pa: self.reported_pa(Tank::Positive),
            negative_tank_pa: self.reported_pa(Tank::Negative),
        };
        self.send(&McuMsg::Fault(event), Priority::Urgent, tx);
    }

    fn send_telemetry_if_due(&mut self, now_ms: u32, tx: &mut impl FrameSink) {
        let interval_ms = u32::from(self.telemetry_interval_ms);
        let since_ms = now_ms.wrapping_sub(self.last_telemetry_ms);
        if interval_ms == 0 || since_ms < interval_ms {
            return;
        }
        // Keep the cadence after a late tick (the next report comes a little
        // sooner), but restart it after a gap of more than one interval.
        self.last_telemetry_ms = if since_ms < 2 * interval_ms {
            self.last_telemetry_ms.wrapping_add(interval_ms)
        } else {
            now_ms
        };
        let telemetry = self.telemetry(now_ms);
        self.send(&McuMsg::Telemetry(telemetry), Priority::Telemetry, tx);
    }

    /// The state report for `now_ms`.
    pub fn telemetry(&self, now_ms: u32) -> Telemetry {
        Telemetry {
            time_ms: now_ms,
            positive_tank_pa: self.reported_pa(Tank::Positive),
            negative_tank_pa: self.reported_pa(Tank::Negative),
            chambers: self.valves.driven(),
            positive_pump_on: self.pumps.positive_on,
            negative_pump_on: self.pumps.negative_on,
            state: self.state,
            faults: self.faults,
            loop_overruns: self.loop_overruns,
        }
    }

    /// The filtered reading of `tank`, or [`dexitac_protocol::NO_READING_PA`]
    /// when the sensor gave none (the sensor fault flag says why).
    fn reported_pa(&self, tank: Tank) -> i32 {
        let reading = match tank {
            Tank::Positive => self.positive.reading(),
            Tank::Negative => self.negative.reading(),
        };
        reading.unwrap_or(dexitac_protocol::NO_READING_PA)
    }

    /// Whether the negative tank may take the chambers' air: a valid
    /// reading inside its limit, and no over-limit or sensor condition.
    fn negative_tank_usable(&self) -> bool {
        let [over_limit, sensor, ..] = safety::faults_of(Tank::Negative);
        valid_reading(self.negative.reading())
            .is_some_and(|pa| !Tank::Negative.at_or_past_limit(pa))
            && !self.present.contains(over_limit)
            && !self.present.contains(sensor)
    }
}

/// `chambers` with every valve toward a tank that shows an over-limit or
/// sensor condition held closed: no chamber is exposed to a tank past its
/// limit (or of unknown pressure), whatever was commanded.
fn close_toward_bad_tanks(mut chambers: Chambers, present: FaultFlags) -> Chambers {
    let bad = |tank: Tank| {
        let [over_limit, sensor, ..] = safety::faults_of(tank);
        present.contains(over_limit) || present.contains(sensor)
    };
    let (positive_bad, negative_bad) = (bad(Tank::Positive), bad(Tank::Negative));
    for state in chambers.iter_mut() {
        if (positive_bad && *state == ValveState::Inflate)
            || (negative_bad && *state == ValveState::Deflate)
        {
            *state = ValveState::Hold;
        }
    }
    chambers
}

/// The nack for a frame error, if the frame passed its CRC (its sequence
/// number can be trusted); corrupted frames get no answer.
fn nack_for(error: FrameError) -> Option<McuMsg> {
    match error {
        FrameError::Malformed { seq } => Some(McuMsg::Nack {
            seq,
            reason: NackReason::Malformed,
        }),
        FrameError::UnknownMessage { seq, .. } => Some(McuMsg::Nack {
            seq,
            reason: NackReason::UnknownMessage,
        }),
        FrameError::TooLong
        | FrameError::Cobs
        | FrameError::TooShort
        | FrameError::Crc
        | FrameError::WrongVersion { .. } => None,
    }
}

#[cfg(test)]
mod tests;
