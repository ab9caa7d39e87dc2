//! The host's task loop (paper Fig. 4, Algorithm 1 processes 1-3): one
//! thread per tactile sensor (frame source -> pipeline -> observation), one
//! link thread (grasp state machine, commands and acks, heartbeat,
//! telemetry), channels between them.
//!
//! ```text
//! sensor 0: FrameSource -> Pipeline -> Observation --\
//!                                                      mpsc -> link thread: Grasp -> Link -> MCU
//! sensor 1: FrameSource -> Pipeline -> Observation --/              |
//!                                                        RuntimeEvent (log, recorder, status line)
//! ```
//!
//! # Commands (two-finger grasp)
//!
//! The *grasping chambers* ([`ControlConfig::grasp_chambers`], default
//! [`DEFAULT_GRASP_CHAMBERS`]) are the chambers whose inflation closes the
//! fingers: for each finger its Rot joint (chambers 0 and 4) and the Dex
//! bellows on the palm side (chambers 1 and 5). The other Dex bellows (2, 3,
//! 6, 7) bend the finger sideways or extend it, which a two-finger grasp does
//! not use; they stay sealed.
//!
//! | event | command |
//! | --- | --- |
//! | start | `Hello` (refuses to start while the MCU reports latched faults: a person acknowledges them, the host never clears them), `Arm`, tank targets, both pumps `Regulate`, telemetry on |
//! | tanks charged | `SetChambers`: grasping chambers `Inflate`, others `Hold` (fingers close) |
//! | [`Command::Seal`] (stable) | `SealAll` |
//! | [`Command::ReopenInflation`] (disturbance) | `SetChambers`: grasping chambers `Inflate` |
//! | [`Command::Release`] (slip, no contact, contact lost) | `SetChambers`: grasping chambers `Deflate` (fingers open) |
//! | stop (end, Ctrl-C, any error) | `SealAll`, then `Disarm` |
//!
//! With tactile feedback off ([`ControlConfig::tactile_feedback`], the
//! paper's ablation) the frames are still processed and reported, but the
//! grasp runs open loop: inflate for [`ControlConfig::open_loop_close_ms`]
//! (default: the paper's ClosureGrip time to stable, Table III), then seal,
//! and nothing after that.
//!
//! # Manipulation
//!
//! With a [`ControlConfig::task`] (and tactile feedback on), the first
//! [`Command::Seal`] starts the [`dexitac_gripper::manipulation::Primitive`]. From then
//! on the primitive owns the grasp: it gets every observation and clock tick,
//! the grasp state machine none (the manipulated object moves the contact
//! centres by design; the primitive's tactile guards take its place). Each
//! of its events is reported ([`RuntimeEvent::Task`]) and sent as
//! `SetChambers`: grasping chambers `Hold` (sealed), the manipulation
//! chambers ([`dexitac_gripper::manipulation::MANIPULATION_CHAMBERS`]) per the drive.
//!
//! # Stopping
//!
//! The loop ends when the stop flag is set (Ctrl-C, end of a scenario), when
//! every frame source has ended, or on an error (link failure, MCU fault or
//! reset, a sensor thread failing). In every case it then seals the valves
//! and disarms the MCU (pumps off, valves sealed); if the link itself is
//! dead the firmware reaches the same safe state on its host-silence trip.
//!
//! # Clock
//!
//! Every time in the loop comes from an injected [`Clock`]: the wall clock
//! on the rig, a clock running `speed` times faster in the simulator in
//! real time. The link's ack and heartbeat timeouts run on the link's own
//! clock ([`Link::with_clock`]); give it the same one.
//!
//! On a **virtual clock** ([`Clock::is_virtual`]) the loop runs in lock
//! step on one thread, and a run repeats exactly:
//!
//! 1. every sensor whose next frame is due ([`FrameSource::next_due_ms`])
//!    gets its frame and pipeline run (the sensors in parallel, their
//!    results handled in sensor order); processing takes no virtual time;
//! 2. the time-driven steps and the link's events are handled, as below;
//! 3. the link's read of the simulated port moves the time on by one read
//!    timeout when no byte is waiting, and the simulated MCU and plant
//!    catch up with it.
//!
//! Every source must then report when its frames are due.
//!
//! # Watchdogs
//!
//! Two checks end a run whose inputs went away, each within a stated time
//! on the loop's clock:
//!
//! - **A sensor stops delivering frames** (a camera hangs, a renderer
//!   stalls) for [`ControlConfig::sensor_timeout_ms`] once the fingers
//!   began to close: the run ends with [`RuntimeError::SensorStalled`]. The
//!   shutdown then seals the valves, so the grasp keeps its air and goes on
//!   holding the object, and disarms the MCU: nobody moves an object the
//!   host can no longer feel. It is the end of the run: a person decides
//!   what happens to the object.
//! - **The MCU's telemetry stops** for [`ControlConfig::mcu_silence_ms`]
//!   while it is on: the loop says hello and listens for as long again. If
//!   the MCU answers but its telemetry stays off, it has restarted (the
//!   firmware boots disarmed, valves sealed, telemetry off), and the run
//!   ends with [`RuntimeError::McuReset`] and the reset cause of its hello,
//!   within twice that time; a run is never re-armed behind a person's
//!   back. Telemetry again means it was only late, and the run goes on.
//!   Without an answer, the link's error ends the run; the board then trips
//!   on host silence on its own. A telemetry clock that runs backwards is a
//!   reset as well.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::time::Duration;

use dexitac_protocol::{
    Chambers, FaultEvent, HostMsg, NackReason, PumpMode, ResetCause, TankTargets, ValveState,
    CHAMBER_COUNT,
};

use crate::event::{RuntimeEvent, SensorReport, StopReason};
use crate::link::{Link, LinkError, McuEvent, Port};
use crate::source::{Clock, FrameSource, HaltHandle};
use dexitac_gripper::grasp::{Command, Decision, Grasp, GraspParams, Observation, SENSOR_COUNT};
use dexitac_gripper::manipulation::{Primitive, TaskEvent, TaskParams};
use dexitac_tactile::pipeline::Pipeline;

/// Default grasping chambers: each finger's Rot joint and palm-side Dex bellows.
pub const DEFAULT_GRASP_CHAMBERS: [usize; 4] = [0, 1, 4, 5];
/// Open-loop closing time without tactile feedback, ms: the paper's average
/// time to a stable ClosureGrip (Table III: 3.38 s and 3.40 s).
pub const OPEN_LOOP_CLOSE_MS: u64 = 3_400;
/// A sensor without a frame for this long, once closing began, ends the
/// run, ms (15 frame periods of a 30 fps camera; see [Watchdogs](self#watchdogs)).
pub const SENSOR_TIMEOUT_MS: u64 = 500;
/// The MCU silent for this long while its telemetry is on is asked whether
/// it restarted, ms (10 periods of the default 20 ms telemetry).
pub const MCU_SILENCE_MS: u64 = 200;

/// One tactile sensor: its frames and its calibrated pipeline.
pub struct Sensor {
    /// The frame source.
    pub source: Box<dyn FrameSource>,
    /// The calibrated pipeline.
    pub pipeline: Pipeline,
}

/// Settings of the task loop.
#[derive(Debug, Clone, PartialEq)]
pub struct ControlConfig {
    /// Algorithm 1 thresholds.
    pub grasp: GraspParams,
    /// Chambers whose inflation closes the fingers.
    pub grasp_chambers: Vec<usize>,
    /// Tank targets (positive, negative), Pa.
    pub tank_targets_pa: (i32, i32),
    /// Start closing when the positive tank reaches this fraction of its target.
    pub charge_fraction: f64,
    /// Start closing at the latest this long after arming, ms.
    pub charge_timeout_ms: u64,
    /// Telemetry period asked of the MCU, ms.
    pub telemetry_interval_ms: u16,
    /// Close the loop on the tactile observations (false: the paper's ablation).
    pub tactile_feedback: bool,
    /// Without tactile feedback: seal this long after closing began, ms.
    pub open_loop_close_ms: u64,
    /// A manipulation primitive to run once the grasp is stable and sealed
    /// (see [Manipulation](self#manipulation)).
    pub task: Option<TaskParams>,
    /// Send each working frame with its [`RuntimeEvent::Observation`]
    /// (for recording and the live view; costs one move per frame).
    pub share_frames: bool,
    /// A sensor without a frame for this long after closing began ends the
    /// run, ms ([Watchdogs](self#watchdogs)).
    pub sensor_timeout_ms: u64,
    /// The MCU silent this long with telemetry on is checked for a
    /// restart, ms ([Watchdogs](self#watchdogs)).
    pub mcu_silence_ms: u64,
}

impl Default for ControlConfig {
    fn default() -> Self {
        ControlConfig {
            grasp: GraspParams::default(),
            grasp_chambers: DEFAULT_GRASP_CHAMBERS.to_vec(),
            tank_targets_pa: dexitac_firmware::control::DEFAULT_TARGETS_PA,
            charge_fraction: 0.9,
            charge_timeout_ms: 8_000,
            telemetry_interval_ms: 20,
            tactile_feedback: true,
            open_loop_close_ms: OPEN_LOOP_CLOSE_MS,
            task: None,
            share_frames: false,
            sensor_timeout_ms: SENSOR_TIMEOUT_MS,
            mcu_silence_ms: MCU_SILENCE_MS,
        }
    }
}

/// Why the task loop failed.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    /// The serial link failed.
    #[error("link: {0}")]
    Link(#[from] LinkError),
    /// The MCU tripped its safety loop.
    #[error("the MCU tripped: {} at {} ms (tanks {} / {} Pa)", .0.fault, .0.time_ms, .0.positive_tank_pa, .0.negative_tank_pa)]
    McuFault(FaultEvent),
    /// The MCU restarted during the run (it is disarmed, in its safe state).
    #[error("the MCU reset during the run (reset cause {cause:?}, noticed at {t_ms} ms)")]
    McuReset {
        /// The reset cause its hello reported (`None`: its telemetry clock
        /// ran backwards).
        cause: Option<ResetCause>,
        /// When the loop noticed, ms on its clock.
        t_ms: u64,
    },
    /// A sensor stopped delivering frames while the gripper held or closed.
    #[error("sensor {sensor} delivered no frame for {silent_ms} ms (last at {last_ms} ms): the grasp was sealed and the MCU disarmed")]
    SensorStalled {
        /// The sensor.
        sensor: usize,
        /// Its last frame's time (or when closing began), ms.
        last_ms: u64,
        /// How long it had been silent, ms.
        silent_ms: u64,
    },
    /// The MCU holds latched faults from an earlier trip: a person must
    /// acknowledge them (`ClearFaults`) before a run can arm it.
    #[error("the MCU has latched faults {:?} (last stop {:?}): acknowledge them before running", .faults.iter().collect::<Vec<_>>(), .last_stop)]
    McuFaultsLatched {
        /// The latched faults.
        faults: dexitac_protocol::FaultFlags,
        /// What stopped the outputs before the MCU's last boot.
        last_stop: dexitac_protocol::LastStop,
    },
    /// A sensor thread failed.
    #[error("sensor {sensor}: {reason}")]
    Sensor {
        /// The sensor.
        sensor: usize,
        /// What failed.
        reason: String,
    },
    /// The configuration is not usable.
    #[error("configuration: {0}")]
    Config(String),
}

/// A sensor thread's message to the link thread.
enum SensorMsg {
    Report {
        /// When the frame came out of its source, µs on the loop's clock.
        arrived_us: u64,
        report: SensorReport,
    },
    Failed {
        sensor: usize,
        reason: String,
    },
    Ended,
}

/// Niceness of the sensor threads: image processing yields the CPU to the
/// link thread, whose heartbeat and commands have deadlines (the firmware's
/// host-silence trip), whatever else runs on the machine.
const SENSOR_THREAD_NICE: i32 = 10;

/// Lowers the calling thread's scheduling priority (Linux: per thread).
/// Best effort: on failure the thread runs at the default priority.
pub fn lower_thread_priority() {
    #[cfg(target_os = "linux")]
    // SAFETY: setpriority only reads its integer arguments; `who = 0` is
    // the calling thread on Linux.
    unsafe {
        libc::setpriority(libc::PRIO_PROCESS, 0, SENSOR_THREAD_NICE);
    }
}

/// One frame of a sensor through its pipeline: `None` when the source has
/// ended.
fn next_report(
    sensor: usize,
    setup: &mut Sensor,
    share_frames: bool,
    clock: &Clock,
) -> Option<SensorMsg> {
    let frame = match setup.source.next_frame(clock) {
        Ok(Some(frame)) => frame,
        Ok(None) => return None,
        Err(e) => {
            return Some(SensorMsg::Failed {
                sensor,
                reason: e.to_string(),
            })
        }
    };
    let arrived_us = clock.now_us();
    Some(match setup.pipeline.run(&frame.frame) {
        Ok(result) => SensorMsg::Report {
            arrived_us,
            report: SensorReport::new(
                sensor,
                frame.t_ms,
                &setup.pipeline,
                &result,
                share_frames.then_some(frame.frame),
            ),
        },
        Err(e) => SensorMsg::Failed {
            sensor,
            reason: e.to_string(),
        },
    })
}

fn sensor_thread(
    sensor: usize,
    mut setup: Sensor,
    share_frames: bool,
    clock: Clock,
    stop: &AtomicBool,
    tx: &Sender<SensorMsg>,
) {
    lower_thread_priority();
    while !stop.load(Ordering::Relaxed) {
        let Some(msg) = next_report(sensor, &mut setup, share_frames, &clock) else {
            break;
        };
        let failed = matches!(msg, SensorMsg::Failed { .. });
        // The receiver only disappears when the loop has ended.
        if tx.send(msg).is_err() || failed {
            return;
        }
    }
    let _ = tx.send(SensorMsg::Ended);
}

/// A pass of the threaded loop slower than this (wall clock) is logged
/// with where its time went, ms.
const SLOW_PASS_MS: u64 = 50;

/// Wall-clock times of one pass of the threaded loop, to say where a stall
/// went (a slow pass is logged as a warning).
struct PassPhases {
    start: std::time::Instant,
    marks: [Duration; 3],
    frames: usize,
}

impl PassPhases {
    fn start() -> Self {
        PassPhases {
            start: std::time::Instant::now(),
            marks: [Duration::ZERO; 3],
            frames: 0,
        }
    }

    fn waited(&mut self) {
        self.marks[0] = self.start.elapsed();
    }

    fn sensors_done(&mut self) {
        self.marks[1] = self.start.elapsed();
    }

    fn time_done(&mut self) {
        self.marks[2] = self.start.elapsed();
    }

    fn finish(&self, t_ms: u64) {
        let total = self.start.elapsed();
        if total > Duration::from_millis(SLOW_PASS_MS) {
            let [waited, sensors, time] = self.marks;
            tracing::warn!(
                "task loop: a pass at {:.3} s took {total:.1?}: waiting for frames {waited:.1?}, {} frame(s) and their commands {:.1?}, timers {:.1?}, board (heartbeat, telemetry) {:.1?}",
                t_ms as f64 / 1e3,
                self.frames,
                sensors.saturating_sub(waited),
                time.saturating_sub(sensors),
                total.saturating_sub(time),
            );
        }
    }
}

/// Where the loop is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Stage {
    Charging { since_ms: u64 },
    Closing { since_ms: u64 },
    Sealed,
}

struct Control<'a, P> {
    config: &'a ControlConfig,
    link: &'a mut Link<P>,
    clock: Clock,
    events: &'a Sender<RuntimeEvent>,
    grasp: Grasp,
    stage: Stage,
    positive_tank_pa: Option<i32>,
    /// The longest gap between two passes of the loop, µs on its clock.
    max_loop_gap_us: u64,
    task: Option<Primitive>,
    /// Each sensor's latest frame, ms on the loop's clock.
    last_frame_ms: [Option<u64>; SENSOR_COUNT],
    /// When closing began (the sensor watchdog's start), ms.
    closing_began_ms: Option<u64>,
    /// When the MCU was asked for telemetry, µs.
    telemetry_on_since_us: Option<u64>,
}

impl<P: Port> Control<'_, P> {
    fn chambers(&self, state: ValveState) -> Chambers {
        let mut c = [ValveState::Hold; CHAMBER_COUNT];
        for &i in &self.config.grasp_chambers {
            if let Some(slot) = c.get_mut(i) {
                *slot = state;
            }
        }
        c
    }

    fn send(
        &mut self,
        msg: HostMsg,
        reason: &'static str,
        arrived_us: Option<u64>,
    ) -> Result<(), RuntimeError> {
        if let Err(e) = self.link.command(msg) {
            return Err(self.explain(e));
        }
        let written_us = self.link.last_command_written_us();
        let from_frame = arrived_us
            .zip(written_us)
            .map(|(a, w)| Duration::from_micros(w.saturating_sub(a)));
        let _ = self.events.send(RuntimeEvent::CommandSent {
            t_ms: written_us.map_or_else(|| self.clock.now_ms(), |w| w / 1_000),
            msg,
            reason,
            from_frame,
        });
        Ok(())
    }

    /// A refusal because the MCU tripped is reported as the trip itself
    /// (its fault event is usually still queued on the link).
    fn explain(&mut self, e: LinkError) -> RuntimeError {
        if matches!(
            e,
            LinkError::Nack {
                reason: NackReason::Tripped,
                ..
            }
        ) {
            if let Ok(events) = self.link.poll(Duration::from_millis(5)) {
                for event in events {
                    if let McuEvent::Fault(f) = event {
                        return RuntimeError::McuFault(f);
                    }
                }
            }
        }
        e.into()
    }

    fn setup(&mut self) -> Result<(), RuntimeError> {
        let hello = self.link.hello()?;
        if !hello.latched_faults.is_empty() {
            return Err(RuntimeError::McuFaultsLatched {
                faults: hello.latched_faults,
                last_stop: hello.last_stop,
            });
        }
        let calibration = hello.calibration;
        if !calibration.record.is_sound() {
            tracing::warn!(
                "the board's sensor calibration record is unusable ({:?}); it runs with {:?}: see `dexitac calibrate --show`",
                calibration.record,
                calibration.calibration
            );
        } else {
            tracing::info!(
                "sensor calibration: {:?} ({:?}, record {:?})",
                calibration.calibration,
                calibration.source,
                calibration.record
            );
        }
        self.arm()?;
        let (pos, neg) = self.config.tank_targets_pa;
        let targets =
            TankTargets::new(pos, neg).map_err(|e| RuntimeError::Config(e.to_string()))?;
        self.send(HostMsg::SetTankTargets(targets), "setup", None)?;
        self.send(
            HostMsg::SetPumps {
                positive: PumpMode::Regulate,
                negative: PumpMode::Regulate,
            },
            "setup",
            None,
        )?;
        self.link.command(HostMsg::SetTelemetryInterval {
            interval_ms: self.config.telemetry_interval_ms,
        })?;
        self.telemetry_on_since_us =
            (self.config.telemetry_interval_ms > 0).then(|| self.clock.now_us());
        self.stage = Stage::Charging {
            since_ms: self.clock.now_ms(),
        };
        Ok(())
    }

    /// Arms the MCU; a refusal in the MCU's first milliseconds (its sensors
    /// are zeroed then) is retried a few times.
    fn arm(&mut self) -> Result<(), RuntimeError> {
        const ATTEMPTS: u32 = 5;
        for attempt in 1..=ATTEMPTS {
            match self.link.command(HostMsg::Arm) {
                Err(LinkError::Nack {
                    reason: NackReason::Refused,
                    ..
                }) if attempt < ATTEMPTS => self.clock.sleep(Duration::from_millis(20)),
                other => return Ok(other?),
            }
        }
        Ok(())
    }

    fn start_closing(&mut self) -> Result<(), RuntimeError> {
        let now = self.clock.now_ms();
        self.send(
            HostMsg::SetChambers {
                chambers: self.chambers(ValveState::Inflate),
            },
            "close fingers",
            None,
        )?;
        self.grasp.start(now);
        self.stage = Stage::Closing { since_ms: now };
        self.closing_began_ms = Some(now);
        Ok(())
    }

    /// The sensor watchdog: once closing began, every sensor delivers a
    /// frame at least every [`ControlConfig::sensor_timeout_ms`].
    fn check_sensors(&self, now: u64) -> Result<(), RuntimeError> {
        let Some(began) = self.closing_began_ms else {
            return Ok(());
        };
        for (sensor, last) in self.last_frame_ms.iter().enumerate() {
            let last_ms = last.map_or(began, |t| t.max(began));
            let silent_ms = now.saturating_sub(last_ms);
            if silent_ms > self.config.sensor_timeout_ms {
                return Err(RuntimeError::SensorStalled {
                    sensor,
                    last_ms,
                    silent_ms,
                });
            }
        }
        Ok(())
    }

    /// Time-driven steps: charging done, open-loop seal, no-contact
    /// timeout, the sensor watchdog.
    fn on_time(&mut self) -> Result<(), RuntimeError> {
        let now = self.clock.now_ms();
        self.check_sensors(now)?;
        match self.stage {
            Stage::Charging { since_ms } => {
                let target = f64::from(self.config.tank_targets_pa.0);
                let charged = self
                    .positive_tank_pa
                    .is_some_and(|p| f64::from(p) >= self.config.charge_fraction * target);
                if charged || now.saturating_sub(since_ms) >= self.config.charge_timeout_ms {
                    self.start_closing()?;
                }
            }
            Stage::Closing { since_ms }
                if !self.config.tactile_feedback
                    && now.saturating_sub(since_ms) >= self.config.open_loop_close_ms =>
            {
                self.send(HostMsg::SealAll, "open-loop seal", None)?;
                self.stage = Stage::Sealed;
            }
            _ => {}
        }
        if self.task_started() {
            if let Some(e) = self.task.as_mut().and_then(|p| p.tick(now)) {
                self.on_task(e, None)?;
            }
        } else if self.config.tactile_feedback {
            if let Some(d) = self.grasp.tick(now) {
                self.act(d, None)?;
            }
        }
        Ok(())
    }

    fn act(&mut self, decision: Decision, arrived: Option<u64>) -> Result<(), RuntimeError> {
        tracing::debug!(
            "task loop: {:.3} s: Algorithm 1 decided {:?} ({:?})",
            self.clock.now_ms() as f64 / 1e3,
            decision.command,
            decision.cause
        );
        let _ = self.events.send(RuntimeEvent::Decision {
            t_ms: self.clock.now_ms(),
            decision,
        });
        let (msg, reason) = match decision.command {
            Command::Seal => (HostMsg::SealAll, "stable: seal"),
            Command::ReopenInflation => (
                HostMsg::SetChambers {
                    chambers: self.chambers(ValveState::Inflate),
                },
                "disturbance: reopen inflation",
            ),
            Command::Release => (
                HostMsg::SetChambers {
                    chambers: self.chambers(ValveState::Deflate),
                },
                "release",
            ),
        };
        self.stage = Stage::Sealed;
        self.send(msg, reason, arrived)?;
        if decision.command == Command::Seal {
            let now = self.clock.now_ms();
            if let Some(e) = self.task.as_mut().and_then(|p| p.start(now)) {
                self.on_task(e, arrived)?;
            }
        }
        Ok(())
    }

    /// A manipulation primitive has started (it then owns the grasp).
    fn task_started(&self) -> bool {
        self.task.as_ref().is_some_and(|p| p.running() || p.done())
    }

    /// Reports a primitive's event and commands its drive: the grasping
    /// chambers stay sealed, the manipulation chambers follow the drive.
    fn on_task(&mut self, event: TaskEvent, arrived: Option<u64>) -> Result<(), RuntimeError> {
        let _ = self.events.send(RuntimeEvent::Task {
            t_ms: self.clock.now_ms(),
            event,
        });
        let mut chambers = [ValveState::Hold; CHAMBER_COUNT];
        for (i, state) in event.drive().valves() {
            if let Some(slot) = chambers.get_mut(i) {
                *slot = state;
            }
        }
        let reason = match event {
            TaskEvent::Stroke { .. } => "task: stroke",
            TaskEvent::Guard { stopped: true, .. } => "task: guard stop",
            TaskEvent::Guard { stopped: false, .. } => "task: guard return",
            TaskEvent::Completed => "task: completed",
        };
        self.send(HostMsg::SetChambers { chambers }, reason, arrived)
    }

    fn on_sensor(&mut self, msg: SensorMsg) -> Result<bool, RuntimeError> {
        match msg {
            SensorMsg::Report {
                arrived_us: arrived,
                report,
            } => {
                let (sensor, t_ms, centre_mm) = (report.sensor, report.t_ms, report.centre_mm);
                if let Some(last) = self.last_frame_ms.get_mut(sensor) {
                    *last = Some(arrived / 1_000);
                }
                let _ = self.events.send(RuntimeEvent::Observation(report));
                let started = self.task_started();
                if let Some(e) = self
                    .task
                    .as_mut()
                    .and_then(|p| p.observe(sensor, t_ms, centre_mm))
                {
                    self.on_task(e, Some(arrived))?;
                }
                if !started
                    && self.config.tactile_feedback
                    && !matches!(self.stage, Stage::Charging { .. })
                {
                    let obs = Observation { t_ms, centre_mm };
                    if let Some(d) = self.grasp.observe(sensor, obs) {
                        self.act(d, Some(arrived))?;
                    }
                }
                Ok(true)
            }
            SensorMsg::Failed { sensor, reason } => Err(RuntimeError::Sensor { sensor, reason }),
            SensorMsg::Ended => Ok(false),
        }
    }

    fn on_mcu(&mut self) -> Result<(), RuntimeError> {
        self.link.keep_alive()?;
        let events = self.link.poll(Duration::ZERO)?;
        self.on_mcu_events(events, None)?;
        let silence = self.telemetry_on_since_us.map(|since| {
            let asked = Duration::from_micros(self.clock.now_us().saturating_sub(since));
            self.link.telemetry_silent_for().min(asked)
        });
        let limit = Duration::from_millis(self.config.mcu_silence_ms);
        if let Some(silence) = silence.filter(|s| *s > limit) {
            // No answer to the hello: the link's error ends the run. An
            // answer and still no telemetry for as long again: it restarted
            // (telemetry is off after a boot). Telemetry again: it was only
            // late (a busy MCU thread in the simulator, a slow USB adapter).
            tracing::warn!("task loop: no telemetry from the MCU for {silence:?}: saying hello");
            let reply = self.link.hello()?;
            let late = self.link.poll(limit)?;
            if self.on_mcu_events(late, Some(reply.reset_cause))? {
                tracing::warn!(
                    "task loop: the MCU's telemetry resumed ({:?} late); it did not restart",
                    silence
                );
            } else {
                return Err(RuntimeError::McuReset {
                    cause: Some(reply.reset_cause),
                    t_ms: self.clock.now_ms(),
                });
            }
        }
        Ok(())
    }

    /// Handles the MCU's events; whether one was telemetry. `cause`: the
    /// reset cause a hello just reported, for a reset seen among them.
    fn on_mcu_events(
        &mut self,
        events: Vec<McuEvent>,
        cause: Option<ResetCause>,
    ) -> Result<bool, RuntimeError> {
        let mut telemetry_seen = false;
        for event in events {
            match event {
                McuEvent::Telemetry(telemetry) => {
                    telemetry_seen = true;
                    self.positive_tank_pa = Some(telemetry.positive_tank_pa);
                    let _ = self.events.send(RuntimeEvent::Telemetry {
                        t_ms: self.clock.now_ms(),
                        telemetry,
                    });
                }
                McuEvent::Fault(fault) => return Err(RuntimeError::McuFault(fault)),
                McuEvent::McuReset => {
                    return Err(RuntimeError::McuReset {
                        cause,
                        t_ms: self.clock.now_ms(),
                    })
                }
            }
        }
        Ok(telemetry_seen)
    }

    /// Notes the time of a pass of the loop (for the longest gap).
    fn pass(&mut self, last_pass_us: &mut u64) {
        let now = self.clock.now_us();
        self.max_loop_gap_us = self.max_loop_gap_us.max(now.saturating_sub(*last_pass_us));
        *last_pass_us = now;
    }

    fn run(
        &mut self,
        rx: &Receiver<SensorMsg>,
        stop: &AtomicBool,
    ) -> Result<StopReason, RuntimeError> {
        self.setup()?;
        let mut live = SENSOR_COUNT;
        // Wake often enough to keep the heartbeat well inside its period
        // (its period is clock time; this wait is wall-clock time).
        let speed = self.clock.speed().max(1.0);
        let wait =
            Duration::from_secs_f64(self.link.config().heartbeat_ms as f64 / 4.0 / speed / 1e3)
                .clamp(Duration::from_millis(1), Duration::from_millis(10));
        let mut last_pass_us = self.clock.now_us();
        loop {
            self.pass(&mut last_pass_us);
            if stop.load(Ordering::Relaxed) {
                return Ok(StopReason::Requested);
            }
            let mut phases = PassPhases::start();
            let received = rx.recv_timeout(wait);
            phases.waited();
            match received {
                Ok(msg) => {
                    let mut handled = 0;
                    // This frame, then what queued up while it was handled.
                    for msg in std::iter::once(msg).chain(std::iter::from_fn(|| rx.try_recv().ok()))
                    {
                        if self.on_sensor(msg)? {
                            handled += 1;
                        } else {
                            live = live.saturating_sub(1);
                        }
                    }
                    if live == 0 {
                        return Ok(StopReason::FramesEnded);
                    }
                    phases.frames = handled;
                }
                Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return Ok(StopReason::FramesEnded),
            }
            phases.sensors_done();
            self.on_time()?;
            phases.time_done();
            self.on_mcu()?;
            phases.finish(self.clock.now_ms());
        }
    }

    /// The loop in lock step on a virtual clock (see [Clock](self#clock)).
    fn run_lockstep(
        &mut self,
        sensors: &mut [Sensor],
        stop: &AtomicBool,
    ) -> Result<StopReason, RuntimeError> {
        self.setup()?;
        let share = self.config.share_frames;
        let mut ended = [false; SENSOR_COUNT];
        let mut last_pass_us = self.clock.now_us();
        loop {
            self.pass(&mut last_pass_us);
            if stop.load(Ordering::Relaxed) {
                return Ok(StopReason::Requested);
            }
            let now = self.clock.now_ms();
            let due: Vec<bool> = sensors
                .iter()
                .zip(&ended)
                .map(|(s, &e)| !e && s.source.next_due_ms().is_some_and(|t| t <= now))
                .collect();
            if due.iter().any(|&d| d) {
                let clock = &self.clock;
                // Both sensors' frames at once (each has its own source and
                // pipeline); their results in sensor order.
                let results: Vec<(usize, Option<SensorMsg>)> = std::thread::scope(|scope| {
                    let handles: Vec<_> = sensors
                        .iter_mut()
                        .enumerate()
                        .filter(|(i, _)| due.get(*i).copied().unwrap_or(false))
                        .map(|(i, s)| (i, scope.spawn(move || next_report(i, s, share, clock))))
                        .collect();
                    handles
                        .into_iter()
                        .map(|(i, h)| {
                            let msg = h.join().unwrap_or_else(|_| {
                                Some(SensorMsg::Failed {
                                    sensor: i,
                                    reason: "its frame source or pipeline panicked".into(),
                                })
                            });
                            (i, msg)
                        })
                        .collect()
                });
                // The batch arrives when the last of it is done (a source
                // may have moved the virtual time while it ran).
                let arrived = self.clock.now_us();
                for (i, msg) in results {
                    match msg {
                        Some(mut msg) => {
                            if let SensorMsg::Report { arrived_us, .. } = &mut msg {
                                *arrived_us = arrived;
                            }
                            self.on_sensor(msg)?;
                        }
                        None => {
                            if let Some(e) = ended.get_mut(i) {
                                *e = true;
                            }
                        }
                    }
                }
                if ended.iter().all(|&e| e) {
                    return Ok(StopReason::FramesEnded);
                }
            }
            self.on_time()?;
            // One read of the simulated port: the time moves on here.
            self.on_mcu()?;
        }
    }

    /// Seal, then disarm; the first error is returned, both are tried.
    fn shutdown(&mut self) -> Result<(), LinkError> {
        let sealed = self.link.command(HostMsg::SealAll);
        let disarmed = self.link.command(HostMsg::Disarm);
        sealed.and(disarmed)
    }
}

/// Runs the task loop until `stop` is set, the frames end, or an error.
/// Always ends with the gripper sealed and the MCU disarmed (see the
/// [module docs](self)). `sensors` must hold one entry per fingertip.
pub fn run<P: Port>(
    config: &ControlConfig,
    link: &mut Link<P>,
    sensors: Vec<Sensor>,
    clock: Clock,
    stop: &AtomicBool,
    events: &Sender<RuntimeEvent>,
) -> Result<StopReason, RuntimeError> {
    if sensors.len() != SENSOR_COUNT {
        return Err(RuntimeError::Config(format!(
            "{} sensors given, the gripper has {SENSOR_COUNT}",
            sensors.len()
        )));
    }
    link.set_clock(clock.clone());
    let mut control = Control {
        config,
        link,
        clock: clock.clone(),
        events,
        grasp: Grasp::new(config.grasp),
        stage: Stage::Charging { since_ms: 0 },
        positive_tank_pa: None,
        max_loop_gap_us: 0,
        task: config
            .task
            .clone()
            .filter(|_| config.tactile_feedback)
            .map(Primitive::new),
        last_frame_ms: [None; SENSOR_COUNT],
        closing_began_ms: None,
        telemetry_on_since_us: None,
    };
    let (result, shutdown) = if clock.is_virtual() {
        let mut sensors = sensors;
        if let Some(i) = sensors
            .iter()
            .position(|s| s.source.next_due_ms().is_none())
        {
            return Err(RuntimeError::Config(format!(
                "sensor {i}'s frame source cannot run on a virtual clock (it does not say when its frames are due)"
            )));
        }
        let result = control.run_lockstep(&mut sensors, stop);
        (result, control.shutdown())
    } else {
        run_threaded(&mut control, sensors, stop)
    };
    let result = match (result, shutdown) {
        (Err(e), _) => Err(e),
        (Ok(_), Err(e)) => Err(e.into()),
        (Ok(reason), Ok(())) => Ok(reason),
    };
    let _ = events.send(RuntimeEvent::Stopped {
        t_ms: clock.now_ms(),
        max_loop_gap: Duration::from_micros(control.max_loop_gap_us),
        outcome: result.as_ref().map(|r| *r).map_err(|e| e.to_string()),
    });
    result
}

/// The loop with one thread per sensor (real time).
fn run_threaded<P: Port>(
    control: &mut Control<'_, P>,
    sensors: Vec<Sensor>,
    stop: &AtomicBool,
) -> (Result<StopReason, RuntimeError>, Result<(), LinkError>) {
    let sensor_stop = AtomicBool::new(false);
    let (tx, rx) = mpsc::channel();
    let halts: Vec<HaltHandle> = sensors
        .iter()
        .filter_map(|s| s.source.halt_handle())
        .collect();
    let share = control.config.share_frames;
    // The gripper is sealed and disarmed as soon as the loop ends, before
    // waiting for the sensor threads (a camera may be blocked on a lost
    // device until its halt handle is called).
    std::thread::scope(|scope| {
        for (i, sensor) in sensors.into_iter().enumerate() {
            let tx = tx.clone();
            let sensor_stop = &sensor_stop;
            let clock = control.clock.clone();
            scope.spawn(move || sensor_thread(i, sensor, share, clock, sensor_stop, &tx));
        }
        drop(tx);
        let result = control.run(&rx, stop);
        let shutdown = control.shutdown();
        sensor_stop.store(true, Ordering::Relaxed);
        for halt in &halts {
            halt();
        }
        (result, shutdown)
    })
}
