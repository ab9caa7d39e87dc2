//! The tactile sensors without a board (`dexitac record`, `dexitac view`):
//! one thread per sensor runs frames through its pipeline and sends each
//! result as a [`RuntimeEvent::Observation`]; optionally Algorithm 1 runs
//! on the observations ([`run_with_grasp`]) so its decisions show too.
//!
//! ```text
//! sensor 0: FrameSource -> Pipeline --\
//!                                       mpsc -> (Algorithm 1) -> RuntimeEvent sender
//! sensor 1: FrameSource -> Pipeline --/
//! ```

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::time::Duration;

use dexitac_gripper::grasp::{Grasp, Observation};
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::pipeline::PipelineError;

use crate::event::{RuntimeEvent, SensorReport, StopReason};
use crate::source::{Clock, FrameSource, SourceError};
use crate::task_loop::Sensor;

/// Why a sensor's loop ended early.
#[derive(Debug, Clone, thiserror::Error)]
pub enum SensorLoopError {
    /// The frame source failed.
    #[error("sensor {sensor}: {reason}")]
    Source {
        /// The sensor.
        sensor: usize,
        /// The source's error, as text (sources' errors are not `Clone`).
        reason: String,
    },
    /// The pipeline rejected a frame.
    #[error("sensor {sensor}: frame at {t_ms} ms: {source}")]
    Frame {
        /// The sensor.
        sensor: usize,
        /// The frame's time, ms.
        t_ms: u64,
        /// What was wrong with the frame.
        source: PipelineError,
    },
    /// Nobody receives the events any more.
    #[error("sensor {sensor}: the receiver of its events stopped")]
    ReceiverGone {
        /// The sensor.
        sensor: usize,
    },
    /// The sensor's thread panicked.
    #[error("sensor {sensor}: its thread panicked")]
    Panicked {
        /// The sensor.
        sensor: usize,
    },
    /// The Algorithm 1 thread of [`run_with_grasp`] panicked.
    #[error("the Algorithm 1 thread panicked")]
    GraspPanicked,
}

fn source_error(sensor: usize, e: &SourceError) -> SensorLoopError {
    SensorLoopError::Source {
        sensor,
        reason: e.to_string(),
    }
}

/// One sensor: frames through the pipeline to `tx` until the source ends,
/// the deadline (frame time, ms) passes or `stop` is set. Returns the
/// number of frames processed.
pub fn sensor_loop(
    sensor: usize,
    mut source: Box<dyn FrameSource>,
    pipeline: &Pipeline,
    clock: Clock,
    deadline_ms: Option<u64>,
    stop: &AtomicBool,
    tx: &Sender<RuntimeEvent>,
) -> Result<u64, SensorLoopError> {
    let mut n = 0;
    while !stop.load(Ordering::Relaxed) {
        let Some(frame) = source
            .next_frame(&clock)
            .map_err(|e| source_error(sensor, &e))?
        else {
            break;
        };
        if deadline_ms.is_some_and(|d| frame.t_ms > d) {
            break;
        }
        let result = pipeline
            .run(&frame.frame)
            .map_err(|source| SensorLoopError::Frame {
                sensor,
                t_ms: frame.t_ms,
                source,
            })?;
        let event = RuntimeEvent::Observation(SensorReport::new(
            sensor,
            frame.t_ms,
            pipeline,
            &result,
            Some(frame.frame),
        ));
        if tx.send(event).is_err() {
            return Err(SensorLoopError::ReceiverGone { sensor });
        }
        n += 1;
    }
    Ok(n)
}

/// Runs [`sensor_loop`] for each sensor on a thread of its own, all
/// sending to `tx`; a failing sensor sets `stop`, which ends the others.
/// Returns each sensor's frame count or failure, in sensor order.
pub fn sensor_threads(
    sensors: Vec<Sensor>,
    clock: Clock,
    deadline_ms: Option<u64>,
    stop: &AtomicBool,
    tx: &Sender<RuntimeEvent>,
) -> Vec<Result<u64, SensorLoopError>> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = sensors
            .into_iter()
            .enumerate()
            .map(|(sensor, s)| {
                let tx = tx.clone();
                let clock = clock.clone();
                scope.spawn(move || {
                    let r =
                        sensor_loop(sensor, s.source, &s.pipeline, clock, deadline_ms, stop, &tx);
                    if r.is_err() {
                        stop.store(true, Ordering::Relaxed);
                    }
                    r
                })
            })
            .collect();
        handles
            .into_iter()
            .enumerate()
            .map(|(sensor, h)| {
                h.join()
                    .unwrap_or(Err(SensorLoopError::Panicked { sensor }))
            })
            .collect()
    })
}

/// How often Algorithm 1's clock ticks without frames (no-contact timeout).
const TICK: Duration = Duration::from_millis(20);

/// Algorithm 1 on the observations: forwards each observation to `tx`,
/// followed by the decision it caused, until every sensor thread ended.
fn relay(observations: Receiver<RuntimeEvent>, clock: Clock, tx: &Sender<RuntimeEvent>) {
    let mut grasp = Grasp::new(Default::default());
    grasp.start(0);
    loop {
        let (event, decision) = match observations.recv_timeout(TICK) {
            Ok(event) => {
                let decision = match &event {
                    RuntimeEvent::Observation(r) => grasp.observe(
                        r.sensor,
                        Observation {
                            t_ms: r.t_ms,
                            centre_mm: r.centre_mm,
                        },
                    ),
                    _ => None,
                };
                (Some(event), decision)
            }
            Err(RecvTimeoutError::Timeout) => (None, grasp.tick(clock.now_ms())),
            Err(RecvTimeoutError::Disconnected) => return,
        };
        // The receiver may have closed: the sensors end on the stop flag.
        if let Some(e) = event {
            let _ = tx.send(e);
        }
        if let Some(decision) = decision {
            let _ = tx.send(RuntimeEvent::Decision {
                t_ms: decision.t_ms,
                decision,
            });
        }
    }
}

/// Sensors -> pipeline -> Algorithm 1 -> `tx`: [`sensor_threads`] and one
/// thread for Algorithm 1 (no board: only its decisions are reported); ends
/// with a `Stopped` event. Returns the first sensor failure.
pub fn run_with_grasp(
    sensors: Vec<Sensor>,
    clock: Clock,
    deadline_ms: Option<u64>,
    stop: &AtomicBool,
    tx: Sender<RuntimeEvent>,
) -> Option<SensorLoopError> {
    std::thread::scope(|scope| {
        let (obs_tx, obs_rx) = mpsc::channel();
        let relay_tx = tx.clone();
        let relay_clock = clock.clone();
        let relay = scope.spawn(move || relay(obs_rx, relay_clock, &relay_tx));
        let mut failure = sensor_threads(sensors, clock.clone(), deadline_ms, stop, &obs_tx)
            .into_iter()
            .find_map(Result::err);
        // The relay ends when the last sender of observations is gone.
        drop(obs_tx);
        if relay.join().is_err() && failure.is_none() {
            failure = Some(SensorLoopError::GraspPanicked);
        }
        let outcome = match &failure {
            Some(e) => Err(e.to_string()),
            None if stop.load(Ordering::Relaxed) => Ok(StopReason::Requested),
            None => Ok(StopReason::FramesEnded),
        };
        // The receiver may have closed already.
        let _ = tx.send(RuntimeEvent::Stopped {
            t_ms: clock.now_ms(),
            max_loop_gap: Duration::ZERO,
            outcome,
        });
        failure
    })
}

/// A sender whose events are copied to `first` and `second` by a thread of
/// its own: `first` (a recorder) does not wait for `second` (a view), and
/// goes on when the other side has closed. The thread ends when the
/// returned sender is dropped.
pub fn tee(first: Sender<RuntimeEvent>, second: Sender<RuntimeEvent>) -> Sender<RuntimeEvent> {
    let (tx, rx) = mpsc::channel::<RuntimeEvent>();
    std::thread::spawn(move || {
        for event in rx {
            // Either side may have closed: the other still gets everything.
            let _ = first.send(event.clone());
            let _ = second.send(event);
        }
    });
    tx
}
