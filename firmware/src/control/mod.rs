//! The safety loop: host commands and tank readings in, valve and pump
//! outputs, acks and telemetry out.
//!
//! A [`Controller`] is driven by two calls, both non-blocking:
//!
//! - [`Controller::receive`] with the serial bytes that arrived: frames are
//!   decoded ([`dexitac_protocol::Decoder`]), dispatched ([`dispatch`]) and
//!   answered with an ack, a nack or a hello reply. Commands change the
//!   *desired* state only.
//! - [`Controller::tick`] once per control period (1 ms): reads the tanks,
//!   evaluates every trip condition ([`safety`]), regulates the pumps
//!   ([`pumps`]), writes the valve and pump outputs, and sends fault events
//!   and telemetry.
//!
//! The outputs are written only by `tick`, so a command takes effect at the
//! next tick (at most one period later), after the safety checks of that
//! tick. Pumps only run while armed.
//!
//! ```
//! use dexitac_firmware::{ByteQueue, Config, Controller, Clock, PressureSource, Pumps,
//!     PumpOutputs, TankReadings, Valves};
//! use dexitac_protocol::{ArmState, Chambers, EncodedFrame, HostMsg, ResetCause};
//!
//! struct Rig { now_ms: u32 }
//! impl Clock for Rig { fn now_ms(&self) -> u32 { self.now_ms } }
//! impl PressureSource for Rig {
//!     fn read_tanks(&mut self) -> TankReadings {
//!         TankReadings { positive_pa: Ok(0), negative_pa: Ok(0) }
//!     }
//! }
//! impl Valves for Rig { fn set_chambers(&mut self, _: &Chambers) {} }
//! impl Pumps for Rig { fn set_pumps(&mut self, _: PumpOutputs) {} }
//!
//! let mut rig = Rig { now_ms: 0 };
//! let mut tx = ByteQueue::<512>::new();
//! let mut ctl = Controller::new(Config::default(), ResetCause::PowerOn);
//! ctl.receive(&EncodedFrame::new(1, &HostMsg::Arm).unwrap(), &rig, &mut tx);
//! ctl.tick(&mut rig, &mut tx);
//! assert_eq!(ctl.state(), ArmState::Armed);
//! // The host falls silent: tripped after 500 ms.
//! for _ in 0..500 { rig.now_ms += 1; ctl.tick(&mut rig, &mut tx); }
//! assert_eq!(ctl.state(), ArmState::Tripped);
//! ```

pub mod dispatch;
pub mod hw;
pub mod pumps;
pub mod safety;
pub mod valves;

use dexitac_protocol::{
    ArmState, Chambers, Decoder, EncodedFrame, Fault, FaultEvent, FaultFlags, FrameError, HostMsg,
    McuMsg, NackReason, PumpMode, ResetCause, TankTargets, Telemetry,
};

use crate::queue::FrameSink;
use hw::{Clock, PressureSource, Pumps, TankReadings, Valves};
use pumps::{MonitorLimits, PumpMonitor, Tank};
use safety::{tank_conditions, valid_reading};
use valves::SAFE_CHAMBERS;

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
    /// A running pump's sensor must move by [`Config::stuck_min_change_pa`]
    /// within this time, in milliseconds.
    pub stuck_window_ms: u32,
    /// Smallest change that counts as the sensor moving, in pascal.
    pub stuck_min_change_pa: i32,
    /// Tank targets until the host sets its own.
    pub default_targets: TankTargets,
}

/// Default control period: 1 ms (1 kHz).
pub const DEFAULT_TICK_PERIOD_MS: u32 = 1;
/// Default host-silence deadline: 500 ms.
pub const DEFAULT_HOST_SILENCE_MS: u32 = 500;
/// Default pump hysteresis: 2 kPa.
pub const DEFAULT_PUMP_HYSTERESIS_PA: i32 = 2_000;
/// Default pump run-time limit: 15 s (a 200 ml tank fills to the limit in a
/// few seconds; a pump running longer pumps into a leak).
pub const DEFAULT_PUMP_MAX_RUN_MS: u32 = 15_000;
/// Default stuck-sensor window: 1 s.
pub const DEFAULT_STUCK_WINDOW_MS: u32 = 1_000;
/// Default smallest sensor movement while pumping: 300 Pa (below the
/// hysteresis, so a pump topping up its tank always moves it enough).
pub const DEFAULT_STUCK_MIN_CHANGE_PA: i32 = 300;
/// Default tank targets: +40 kPa and -45 kPa, inside the limits with margin
/// for the pressure overshoot after a pump stops.
pub const DEFAULT_TARGETS_PA: (i32, i32) = (40_000, -45_000);

impl Default for Config {
    fn default() -> Self {
        Config {
            tick_period_ms: DEFAULT_TICK_PERIOD_MS,
            host_silence_ms: DEFAULT_HOST_SILENCE_MS,
            pump_hysteresis_pa: DEFAULT_PUMP_HYSTERESIS_PA,
            pump_max_run_ms: DEFAULT_PUMP_MAX_RUN_MS,
            stuck_window_ms: DEFAULT_STUCK_WINDOW_MS,
            stuck_min_change_pa: DEFAULT_STUCK_MIN_CHANGE_PA,
            default_targets: match TankTargets::new(DEFAULT_TARGETS_PA.0, DEFAULT_TARGETS_PA.1) {
                Ok(t) => t,
                // Unreachable: the constants lie inside the limits (checked
                // by the test `default_targets_are_inside_the_limits`).
                Err(_) => TANK_TARGETS_ZERO,
            },
        }
    }
}

/// Both targets at 0 Pa (always inside the limits).
const TANK_TARGETS_ZERO: TankTargets = match TankTargets::new(0, 0) {
    Ok(t) => t,
    Err(_) => panic!("0 Pa lies inside both limits"),
};

impl Config {
    fn monitor_limits(&self) -> MonitorLimits {
        MonitorLimits {
            max_run_ms: self.pump_max_run_ms,
            stuck_window_ms: self.stuck_window_ms,
            stuck_min_change_pa: self.stuck_min_change_pa,
        }
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
    /// Outgoing frames dropped because the transmit queue was full.
    pub tx_dropped: u32,
}

/// The safety loop. See the [module docs](self) and the fault table in the
/// crate docs.
pub struct Controller {
    config: Config,
    reset_cause: ResetCause,
    decoder: Decoder<HostMsg>,
    state: ArmState,
    faults: FaultFlags,
    /// Conditions present at the last tick.
    present: FaultFlags,
    chambers: Chambers,
    positive_mode: PumpMode,
    negative_mode: PumpMode,
    targets: TankTargets,
    pumps: PumpOutputs,
    positive_monitor: PumpMonitor,
    negative_monitor: PumpMonitor,
    last_readings: TankReadings,
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
        Controller {
            config,
            reset_cause,
            decoder: Decoder::new(),
            state: ArmState::Disarmed,
            faults: FaultFlags::NONE,
            present: FaultFlags::NONE,
            chambers: SAFE_CHAMBERS,
            positive_mode: PumpMode::Off,
            negative_mode: PumpMode::Off,
            targets: config.default_targets,
            pumps: PumpOutputs::OFF,
            positive_monitor: PumpMonitor::default(),
            negative_monitor: PumpMonitor::default(),
            last_readings: TankReadings {
                positive_pa: Ok(0),
                negative_pa: Ok(0),
            },
            last_frame_ms: 0,
            last_tick_ms: None,
            telemetry_interval_ms: 0,
            last_telemetry_ms: 0,
            loop_overruns: 0,
            tx_seq: 0,
            link: LinkStats::default(),
        }
    }

    /// The safety state.
    pub fn state(&self) -> ArmState {
        self.state
    }

    /// Faults seen since the last disarm.
    pub fn faults(&self) -> FaultFlags {
        self.faults
    }

    /// The valve state the outputs are driven to (at the next tick).
    pub fn chambers(&self) -> Chambers {
        self.chambers
    }

    /// The pump outputs written at the last tick.
    pub fn pumps(&self) -> PumpOutputs {
        self.pumps
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
                    self.send(&reply, tx);
                }
                Err(error) => {
                    self.link.frame_errors = self.link.frame_errors.wrapping_add(1);
                    if let Some(nack) = nack_for(error) {
                        self.send(&nack, tx);
                    }
                }
            }
        }
    }

    /// One control period: read the tanks, check every trip condition,
    /// regulate the pumps, write the outputs, send fault events and
    /// telemetry.
    pub fn tick<H>(&mut self, hw: &mut H, tx: &mut impl FrameSink)
    where
        H: Clock + PressureSource + Valves + Pumps,
    {
        let now_ms = hw.now_ms();
        self.count_overrun(now_ms);
        let readings = hw.read_tanks();
        self.last_readings = readings;

        let present = self.conditions(readings, now_ms);
        self.present = present;
        self.faults = FaultFlags(self.faults.0 | present.0);
        if self.state == ArmState::Armed && !present.is_empty() {
            self.trip();
            for fault in present.iter() {
                self.send_fault(fault, now_ms, tx);
            }
        }

        self.pumps = self.regulate(readings);
        self.record_pumps(readings, now_ms);
        hw.set_chambers(&self.chambers);
        hw.set_pumps(self.pumps);
        self.send_telemetry_if_due(now_ms, tx);
    }

    fn count_overrun(&mut self, now_ms: u32) {
        if let Some(last) = self.last_tick_ms {
            if now_ms.wrapping_sub(last) > self.config.tick_period_ms {
                self.loop_overruns = self.loop_overruns.wrapping_add(1);
            }
        }
        self.last_tick_ms = Some(now_ms);
    }

    /// Every condition present now (host silence only while armed).
    fn conditions(&mut self, readings: TankReadings, now_ms: u32) -> FaultFlags {
        let limits = self.config.monitor_limits();
        let positive_findings = match valid_reading(readings.positive_pa) {
            Some(pa) => self.positive_monitor.check(pa, now_ms, &limits),
            None => Default::default(),
        };
        let negative_findings = match valid_reading(readings.negative_pa) {
            Some(pa) => self.negative_monitor.check(pa, now_ms, &limits),
            None => Default::default(),
        };
        let mut flags = FaultFlags(
            tank_conditions(Tank::Positive, readings.positive_pa, positive_findings).0
                | tank_conditions(Tank::Negative, readings.negative_pa, negative_findings).0,
        );
        if self.state == ArmState::Armed
            && now_ms.wrapping_sub(self.last_frame_ms) >= self.config.host_silence_ms
        {
            flags = flags.with(Fault::HostSilence);
        }
        flags
    }

    /// Enters the latched tripped state: pumps off, valves sealed.
    fn trip(&mut self) {
        self.state = ArmState::Tripped;
        self.enter_safe_state();
    }

    /// Pumps off (modes and outputs), every valve closed.
    fn enter_safe_state(&mut self) {
        self.chambers = SAFE_CHAMBERS;
        self.positive_mode = PumpMode::Off;
        self.negative_mode = PumpMode::Off;
        self.pumps = PumpOutputs::OFF;
        self.positive_monitor.reset();
        self.negative_monitor.reset();
    }

    /// The pump outputs for this tick: off unless armed with a valid reading.
    fn regulate(&self, readings: TankReadings) -> PumpOutputs {
        if self.state != ArmState::Armed {
            return PumpOutputs::OFF;
        }
        let hysteresis_pa = self.config.pump_hysteresis_pa;
        let positive_on = valid_reading(readings.positive_pa).is_some_and(|pa| {
            pumps::regulate(
                Tank::Positive,
                self.positive_mode,
                self.pumps.positive_on,
                pa,
                self.targets.positive_pa(),
                hysteresis_pa,
            )
        });
        let negative_on = valid_reading(readings.negative_pa).is_some_and(|pa| {
            pumps::regulate(
                Tank::Negative,
                self.negative_mode,
                self.pumps.negative_on,
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

    fn record_pumps(&mut self, readings: TankReadings, now_ms: u32) {
        let positive_pa = valid_reading(readings.positive_pa).unwrap_or(0);
        let negative_pa = valid_reading(readings.negative_pa).unwrap_or(0);
        self.positive_monitor
            .record(self.pumps.positive_on, positive_pa, now_ms);
        self.negative_monitor
            .record(self.pumps.negative_on, negative_pa, now_ms);
    }

    /// Encodes and queues `msg`; a full queue drops it (counted).
    fn send(&mut self, msg: &McuMsg, tx: &mut impl FrameSink) {
        let seq = self.tx_seq;
        self.tx_seq = self.tx_seq.wrapping_add(1);
        let sent = match EncodedFrame::new(seq, msg) {
            Ok(frame) => tx.send(&frame).is_ok(),
            Err(_) => false,
        };
        if !sent {
            self.link.tx_dropped = self.link.tx_dropped.wrapping_add(1);
        }
    }

    fn send_fault(&mut self, fault: Fault, now_ms: u32, tx: &mut impl FrameSink) {
        let event = FaultEvent {
            time_ms: now_ms,
            fault,
            positive_tank_pa: self.reported_pa(Tank::Positive),
            negative_tank_pa: self.reported_pa(Tank::Negative),
        };
        self.send(&McuMsg::Fault(event), tx);
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
        self.send(&McuMsg::Telemetry(telemetry), tx);
    }

    /// The state report for `now_ms`.
    pub fn telemetry(&self, now_ms: u32) -> Telemetry {
        Telemetry {
            time_ms: now_ms,
            positive_tank_pa: self.reported_pa(Tank::Positive),
            negative_tank_pa: self.reported_pa(Tank::Negative),
            chambers: self.chambers,
            positive_pump_on: self.pumps.positive_on,
            negative_pump_on: self.pumps.negative_on,
            state: self.state,
            faults: self.faults,
            loop_overruns: self.loop_overruns,
        }
    }

    /// The last reading of `tank`, or [`dexitac_protocol::NO_READING_PA`] when the sensor gave none
    /// (the sensor fault flag says why).
    fn reported_pa(&self, tank: Tank) -> i32 {
        let reading = match tank {
            Tank::Positive => self.last_readings.positive_pa,
            Tank::Negative => self.last_readings.negative_pa,
        };
        reading.unwrap_or(dexitac_protocol::NO_READING_PA)
    }
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
