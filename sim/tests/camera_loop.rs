//! The camera source in the task loop, without a camera: two fake UVC
//! cameras play recorded MJPEG streams (synthetic pressed frames encoded as
//! JPEG) into `runtime::run` against the simulated board over a pty; one
//! camera is unplugged mid-run and comes back. Both sensors must keep
//! producing contact observations, the loop must not end on the unplug, and
//! the board must end disarmed.
//!
//! Real time, on purpose: what is measured is the camera source's threads
//! (capture, reconnect after an unplug, halt) against the wall clock, which
//! a virtual clock cannot drive. The bounds are counts of frames, not speeds.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};
use std::time::Duration;

use dexitac_protocol::ArmState;
use dexitac_rig::camera::fake::FakeDevice;
use dexitac_rig::camera::{decode, CameraConfig, CameraEvent, CameraSource, Mode, PixelFormat};
use dexitac_rig::event::{RuntimeEvent, StopReason};
use dexitac_rig::link::{Link, LinkConfig};
use dexitac_rig::source::Clock;
use dexitac_rig::task_loop::{ControlConfig, Sensor};
use dexitac_sim::mcu::{SimMcu, SimMcuConfig};
use dexitac_tactile::calibrate;
use dexitac_tactile::frame::{self, GreyFrame, RawFrame};
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::synth::{self, Press, Scene, SensorSpec};
use dexitac_tactile::PointPx;

fn mjpeg(frame: &GreyFrame) -> Vec<u8> {
    decode::encode_mjpeg(frame, 90).unwrap()
}

/// What the pipeline sees of an MJPEG buffer.
fn through_camera(jpeg: &[u8], params: &Params) -> GreyFrame {
    let mode = Mode {
        format: PixelFormat::Mjpeg,
        width_px: 640,
        height_px: 480,
        stride_bytes: 0,
        fps: None,
    };
    let g = decode::to_grey(jpeg, &mode).unwrap();
    let raw = RawFrame {
        width: 640,
        height: 480,
        channels: 1,
        data: g.data(),
    };
    frame::prepare(&raw, &params.frame).unwrap().grey
}

/// Two fake MJPEG cameras with pressed frames; camera 0 is unplugged after
/// `unplug.0` frames for `unplug.1`. `stop` is the cameras' own stop flag.
fn fake_sensors(
    params: &Params,
    unplug: (u64, Duration),
    stop: Option<Arc<AtomicBool>>,
    cam_tx: &mpsc::Sender<CameraEvent>,
) -> Vec<Sensor> {
    let sensor = SensorSpec::nominal(640, 480);
    // Everything slow first (rendering, encoding, calibrating): a camera
    // plays from the moment it is opened, so opening camera 0 before
    // camera 1's frames were made once let its unplug pass before the loop
    // had started, on a loaded machine.
    let prepared: Vec<_> = (0..2u64)
        .map(|finger| {
            let rest = mjpeg(&synth::rest_frame(&sensor, 100 + finger).image);
            let cal = calibrate::calibrate(&[through_camera(&rest, params)], params).unwrap();
            let pressed: Vec<Vec<u8>> = (0..4)
                .map(|seed| {
                    mjpeg(
                        &synth::render(&Scene {
                            sensor: sensor.clone(),
                            presses: vec![Press {
                                centre: PointPx::new(300.0 + 20.0 * finger as f64, 240.0),
                                width_px: 25.0,
                                strength: 0.6,
                                shear_px: PointPx::new(0.0, 0.0),
                                flat_radius_px: 0.0,
                            }],
                            dropout: 0.0,
                            seed: 10 * finger + seed,
                        })
                        .image,
                    )
                })
                .collect();
            (cal, pressed)
        })
        .collect();
    let mut sensors = Vec::new();
    for (finger, (cal, pressed)) in prepared.into_iter().enumerate() {
        let mut fake = FakeDevice::new(PixelFormat::Mjpeg, 640, 480, pressed)
            .named(&format!("fake{finger}"))
            .period(Duration::from_millis(33));
        if finger == 0 {
            fake = fake.unplug_after(unplug.0, unplug.1);
        }
        let config = CameraConfig {
            warmup_frames: 2,
            reconnect_min_ms: 50,
            ..CameraConfig::default()
        };
        let cam = CameraSource::open(Box::new(fake), &config, &params.frame, stop.clone()).unwrap();
        cam.report_to(cam_tx.clone());
        sensors.push(Sensor {
            source: Box::new(cam),
            pipeline: Pipeline::new(cal, params.clone()),
        });
    }
    sensors
}

/// A finished task loop: its result, its events, the simulated board, and
/// how long `runtime::run` took.
struct LoopRun {
    result: Result<StopReason, dexitac_rig::task_loop::RuntimeError>,
    events: mpsc::Receiver<RuntimeEvent>,
    mcu: SimMcu,
    took: Duration,
}

/// Runs the task loop on `sensors` against a simulated board until `stop`
/// is set `after` the start.
fn run_loop(
    config: &ControlConfig,
    sensors: Vec<Sensor>,
    stop: &Arc<AtomicBool>,
    after: Duration,
) -> LoopRun {
    let mcu = SimMcu::spawn(SimMcuConfig::default()).unwrap();
    let mut link = Link::open(mcu.port_path(), LinkConfig::default()).unwrap();
    let stopper = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            std::thread::sleep(after);
            stop.store(true, Ordering::Relaxed);
        })
    };
    let (tx, events) = mpsc::channel();
    let t0 = std::time::Instant::now();
    let result = dexitac_rig::task_loop::run(config, &mut link, sensors, Clock::wall(), stop, &tx);
    let took = t0.elapsed();
    stopper.join().unwrap();
    LoopRun {
        result,
        events,
        mcu,
        took,
    }
}

#[test]
fn fake_cameras_feed_the_loop_through_an_unplug() {
    let params = Params::default();
    let stop = Arc::new(AtomicBool::new(false));
    let (cam_tx, cam_rx) = mpsc::channel();
    let sensors = fake_sensors(
        &params,
        (15, Duration::from_millis(300)),
        Some(stop.clone()),
        &cam_tx,
    );
    let run = run_loop(
        &ControlConfig::default(),
        sensors,
        &stop,
        Duration::from_millis(2_000),
    );
    assert_eq!(run.result.unwrap(), StopReason::Requested);
    let camera_events: Vec<CameraEvent> = cam_rx.try_iter().collect();
    assert!(
        matches!(
            &camera_events[..],
            [CameraEvent::Lost { device, .. }, CameraEvent::Recovered { .. }] if device == "fake0"
        ),
        "{camera_events:?}"
    );
    // Contact observations per sensor, with their times.
    let mut seen: [Vec<u64>; 2] = [Vec::new(), Vec::new()];
    for event in run.events.iter() {
        if let RuntimeEvent::Observation(r) = event {
            if r.centre_mm.is_some() {
                seen[r.sensor].push(r.t_ms);
            }
        }
    }
    assert!(seen[1].len() >= 30, "sensor 1: {} contacts", seen[1].len());
    // Sensor 0 went quiet for the unplug, then came back.
    let gaps: Vec<u64> = seen[0].windows(2).map(|w| w[1] - w[0]).collect();
    let (at, longest) = gaps
        .iter()
        .copied()
        .enumerate()
        .max_by_key(|g| g.1)
        .unwrap_or((0, 0));
    assert!(longest >= 300, "no gap for the unplug: {gaps:?}");
    let (before, after) = (at + 1, seen[0].len() - at - 1);
    assert!(
        before >= 5 && after >= 10,
        "{before} before, {after} after: {:?}",
        seen[0]
    );
    // The board acks the disarm before it publishes the snapshot that shows
    // it: read the state two control ticks on, not after a guessed sleep.
    let s = run.mcu.snapshot_after_ticks(Duration::from_secs(2));
    assert_eq!(s.state, ArmState::Disarmed, "{s:?}");
}

/// The loop ends (here: stop requested) while a camera is lost for an hour
/// and the cameras were given no stop flag: the loop halts its sources, so
/// `run` returns at once with the board disarmed instead of waiting for the
/// camera.
#[test]
fn the_loop_ends_promptly_while_a_camera_is_lost() {
    let params = Params::default();
    let (cam_tx, _cam_rx) = mpsc::channel();
    let sensors = fake_sensors(&params, (10, Duration::from_secs(3600)), None, &cam_tx);
    let stop = Arc::new(AtomicBool::new(false));
    // The stop request is under test, not the sensor watchdog (which would
    // end the run on its own 500 ms after closing began: its test is
    // sim/tests/runtime_safety.rs).
    let config = ControlConfig {
        sensor_timeout_ms: u64::MAX,
        ..ControlConfig::default()
    };
    let run = run_loop(&config, sensors, &stop, Duration::from_millis(1_500));
    assert_eq!(run.result.unwrap(), StopReason::Requested);
    assert!(
        run.took < Duration::from_secs(30),
        "run took {:?}",
        run.took
    );
    // The board acks the disarm before it publishes the snapshot that shows
    // it: read the state two control ticks on, not after a guessed sleep.
    let s = run.mcu.snapshot_after_ticks(Duration::from_secs(2));
    assert_eq!(s.state, ArmState::Disarmed, "{s:?}");
}
