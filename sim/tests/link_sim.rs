//! The serial link against the simulated MCU (the firmware's own control
//! core behind a pty), through the normal serial-port code path.
//!
//! Real time, on purpose: the pty, the serial-port crate's timeouts and the
//! MCU thread are what is under test.

use std::io::{Read, Write};
use std::thread;
use std::time::{Duration, Instant};

use dexitac_protocol::{
    ArmState, Calibration, CalibrationRecord, CalibrationSource, Decoder, EncodedFrame, Fault,
    FirmwareVersion, HelloReply, HostMsg, McuMsg, NackReason, ResetCause, SensorCalibration,
    ValveState, ZeroSource, CHAMBER_COUNT, NEGATIVE_TANK_MIN_PA, POSITIVE_TANK_MAX_PA,
};
use dexitac_rig::link::{Link, LinkConfig, LinkError, McuEvent, SerialLink};
use dexitac_sim::mcu::{SimMcu, SimMcuConfig};
use serialport::{SerialPort, TTYPort};

fn connect() -> (SimMcu, SerialLink) {
    let mcu = SimMcu::spawn(SimMcuConfig::default()).expect("simulated MCU");
    // The firmware zeroes its sensors in its first milliseconds and refuses
    // to arm until then.
    let booted = dexitac_firmware::control::ZERO_AT_TICK as u64 + 1;
    let until = Instant::now() + Duration::from_secs(2);
    while mcu.snapshot().time_ms <= booted && Instant::now() < until {
        thread::sleep(Duration::from_millis(1));
    }
    let link = Link::open(mcu.port_path(), LinkConfig::default()).expect("open pty");
    (mcu, link)
}

/// Waits up to 100 ms for the MCU's outputs to satisfy `ok` (they change on
/// the control tick after the ack).
fn wait_for(mcu: &SimMcu, ok: impl Fn(&dexitac_sim::mcu::McuSnapshot) -> bool) -> bool {
    let until = Instant::now() + Duration::from_millis(100);
    while Instant::now() < until {
        if ok(&mcu.snapshot()) {
            return true;
        }
        thread::sleep(Duration::from_millis(1));
    }
    false
}

fn chambers() -> [ValveState; CHAMBER_COUNT] {
    let mut c = [ValveState::Hold; CHAMBER_COUNT];
    c[0] = ValveState::Inflate;
    c[4] = ValveState::Deflate;
    c
}

#[test]
fn hello_reports_version_limits_and_reset_cause() {
    let (_mcu, mut link) = connect();
    let reply = link.hello().expect("hello");
    assert_eq!(reply.firmware_version, dexitac_firmware::FIRMWARE_VERSION);
    assert_eq!(reply.reset_cause, ResetCause::PowerOn);
}

#[test]
fn armed_chamber_commands_reach_the_valves_and_telemetry() {
    let (mcu, mut link) = connect();
    link.hello().expect("hello");
    link.command(HostMsg::Arm).expect("arm");
    link.command(HostMsg::SetChambers {
        chambers: chambers(),
    })
    .expect("set chambers");
    link.command(HostMsg::SetTelemetryInterval { interval_ms: 10 })
        .expect("telemetry");
    assert!(wait_for(&mcu, |s| s.chambers == chambers()));

    let mut telemetry = Vec::new();
    let until = Instant::now() + Duration::from_secs(2);
    while telemetry.len() < 5 && Instant::now() < until {
        link.keep_alive().expect("heartbeat");
        for e in link.poll(Duration::from_millis(20)).expect("poll") {
            if let McuEvent::Telemetry(t) = e {
                telemetry.push(t);
            }
        }
    }
    assert!(telemetry.len() >= 5, "{} telemetry frames", telemetry.len());
    assert!(telemetry
        .iter()
        .all(|t| t.chambers == chambers() && t.state == ArmState::Armed));
    assert!(telemetry.windows(2).all(|w| w[0].time_ms < w[1].time_ms));
    link.command(HostMsg::SealAll).expect("seal");
    assert!(wait_for(&mcu, |s| s.chambers == [ValveState::Hold; CHAMBER_COUNT]));
}

#[test]
fn commands_that_need_arming_are_nacked_while_disarmed() {
    let (mcu, mut link) = connect();
    link.hello().expect("hello");
    let err = link
        .command(HostMsg::SetChambers {
            chambers: chambers(),
        })
        .unwrap_err();
    assert!(
        matches!(
            err,
            LinkError::Nack {
                reason: NackReason::NotArmed,
                ..
            }
        ),
        "{err}"
    );
    assert_eq!(mcu.snapshot().chambers, [ValveState::Hold; CHAMBER_COUNT]);
}

#[test]
fn heartbeats_keep_the_mcu_armed_and_silence_trips_it() {
    let (mcu, mut link) = connect();
    link.hello().expect("hello");
    link.command(HostMsg::Arm).expect("arm");
    link.command(HostMsg::SetChambers {
        chambers: chambers(),
    })
    .expect("set chambers");
    // Three silence deadlines with heartbeats: still armed.
    let until = Instant::now() + Duration::from_millis(1_500);
    while Instant::now() < until {
        link.keep_alive().expect("heartbeat");
        link.poll(Duration::from_millis(10)).expect("poll");
    }
    assert_eq!(mcu.snapshot().state, ArmState::Armed);

    // Silence: tripped to the safe state within the deadline (500 ms),
    // with a fault event.
    let silent_since = Instant::now();
    let mut fault = None;
    while fault.is_none() && silent_since.elapsed() < Duration::from_secs(2) {
        fault = link
            .poll(Duration::from_millis(10))
            .expect("poll")
            .into_iter()
            .find_map(|e| match e {
                McuEvent::Fault(f) => Some(f),
                _ => None,
            });
    }
    let fault = fault.expect("a fault event");
    assert_eq!(fault.fault, Fault::HostSilence);
    let tripped_after = silent_since.elapsed();
    assert!(
        tripped_after < Duration::from_millis(800),
        "tripped after {tripped_after:?}"
    );
    let snapshot = mcu.snapshot();
    assert_eq!(snapshot.state, ArmState::Tripped);
    assert_eq!(snapshot.chambers, [ValveState::Hold; CHAMBER_COUNT]);
    assert!(!snapshot.pumps.positive_on && !snapshot.pumps.negative_on);
}

#[test]
fn a_board_reset_is_seen_and_the_link_reconnects() {
    let (mcu, mut link) = connect();
    link.hello().expect("hello");
    link.command(HostMsg::Arm).expect("arm");
    link.command(HostMsg::SetTelemetryInterval { interval_ms: 10 })
        .expect("telemetry");
    let until = Instant::now() + Duration::from_millis(300);
    while Instant::now() < until {
        link.keep_alive().expect("heartbeat");
        link.poll(Duration::from_millis(10)).expect("poll");
    }
    assert!(link.silent_for() < Duration::from_millis(100));
    mcu.reset();
    // The firmware restarts with telemetry off: the line goes quiet.
    let until = Instant::now() + Duration::from_secs(2);
    while link.silent_for() < Duration::from_millis(200) && Instant::now() < until {
        link.poll(Duration::from_millis(10)).expect("poll");
    }
    assert!(link.silent_for() >= Duration::from_millis(200));
    let reply = link
        .reconnect(Instant::now() + Duration::from_secs(2))
        .expect("reconnect");
    assert_eq!(reply.reset_cause, ResetCause::Software);
    assert_eq!(mcu.snapshot().state, ArmState::Disarmed);
    link.command(HostMsg::Arm).expect("re-arm");
    assert!(wait_for(&mcu, |s| s.state == ArmState::Armed));
}

fn nack_reason(err: LinkError) -> NackReason {
    match err {
        LinkError::Nack { reason, .. } => reason,
        other => panic!("expected a nack, got {other}"),
    }
}

#[test]
fn a_calibration_is_stored_as_on_the_board_and_survives_a_reset() {
    let (mcu, mut link) = connect();
    // A fresh simulated flash page: nothing stored, the identity applies.
    let report = link.hello().expect("hello").calibration;
    assert_eq!(report.calibration, Calibration::IDENTITY);
    assert_eq!(report.source, CalibrationSource::Default);
    assert_eq!(report.record, CalibrationRecord::Empty);
    let calibration = Calibration {
        positive: SensorCalibration {
            offset_pa: 2_000,
            gain_ppm: 1_050_000,
        },
        negative: SensorCalibration {
            offset_pa: -1_500,
            gain_ppm: 970_000,
        },
    };
    // Implausible, or armed: refused, nothing applied.
    let implausible = Calibration {
        positive: SensorCalibration {
            offset_pa: 20_000,
            gain_ppm: 1_000_000,
        },
        ..calibration
    };
    let err = link
        .command(HostMsg::SetCalibration(implausible))
        .unwrap_err();
    assert_eq!(nack_reason(err), NackReason::Implausible);
    link.command(HostMsg::Arm).expect("arm");
    let err = link
        .command(HostMsg::SetCalibration(calibration))
        .unwrap_err();
    assert_eq!(nack_reason(err), NackReason::Refused);
    link.command(HostMsg::Disarm).expect("disarm");
    assert_eq!(mcu.calibration().calibration, Calibration::IDENTITY);

    link.command(HostMsg::SetCalibration(calibration))
        .expect("calibrate");
    let report = link.hello().expect("hello").calibration;
    assert_eq!(report.calibration, calibration);
    assert_eq!(report.source, CalibrationSource::Host);
    assert_eq!(report.record, CalibrationRecord::Valid { version: 1 });
    // The tanks are at atmosphere: the boot zero (about 0 Pa) lies within
    // the window around both offsets and stays in use.
    assert_eq!(report.positive_zero.source, ZeroSource::Boot);
    assert_eq!(mcu.calibration(), report);

    // A board reset: the record is read back from the (simulated) flash.
    mcu.reset();
    let until = Instant::now() + Duration::from_secs(2);
    let after = loop {
        let reply = link.hello().expect("hello");
        if reply.reset_cause == ResetCause::Software {
            break reply;
        }
        assert!(Instant::now() < until, "no reset seen");
        thread::sleep(Duration::from_millis(5));
    };
    assert_eq!(after.calibration.calibration, calibration);
    assert_eq!(after.calibration.source, CalibrationSource::Flash);
    assert_eq!(
        after.calibration.record,
        CalibrationRecord::Valid { version: 1 }
    );
}

#[test]
fn a_silent_port_times_out_after_the_retries() {
    let (host, _device) = TTYPort::pair().expect("pty pair");
    let mut host = host;
    host.set_timeout(Duration::from_millis(2)).expect("timeout");
    let config = LinkConfig {
        ack_timeout_ms: 20,
        retries: 2,
        ..LinkConfig::default()
    };
    let mut link = Link::new(host, config);
    let err = link.command(HostMsg::Arm).unwrap_err();
    assert!(
        matches!(err, LinkError::Timeout { attempts: 3, .. }),
        "{err}"
    );
    assert_eq!(link.stats().frames_sent, 3);
}

#[test]
fn another_protocol_version_is_a_clear_error() {
    let (host, mut device) = TTYPort::pair().expect("pty pair");
    let mut host = host;
    host.set_timeout(Duration::from_millis(2)).expect("timeout");
    device
        .set_timeout(Duration::from_millis(5))
        .expect("timeout");
    let fake = thread::spawn(move || {
        let mut decoder = Decoder::<HostMsg>::new();
        let mut buf = [0u8; 64];
        let start = Instant::now();
        while start.elapsed() < Duration::from_secs(5) {
            let n = device.read(&mut buf).unwrap_or(0);
            let frames: Vec<_> = decoder.feed(&buf[..n]).flatten().collect();
            if frames.iter().any(|f| f.msg == HostMsg::Hello) {
                let reply = McuMsg::HelloReply(HelloReply {
                    protocol_version: 99,
                    firmware_version: FirmwareVersion {
                        major: 9,
                        minor: 0,
                        patch: 0,
                    },
                    positive_tank_max_pa: POSITIVE_TANK_MAX_PA,
                    negative_tank_min_pa: NEGATIVE_TANK_MIN_PA,
                    chamber_count: CHAMBER_COUNT as u8,
                    reset_cause: ResetCause::PowerOn,
                    latched_faults: Default::default(),
                    last_stop: Default::default(),
                    min_telemetry_interval_ms: 8,
                    calibration: Default::default(),
                });
                device
                    .write_all(&EncodedFrame::new(0, &reply).expect("fits"))
                    .expect("write");
                return device;
            }
        }
        device
    });
    let err = Link::new(host, LinkConfig::default()).hello().unwrap_err();
    let _device = fake.join().expect("fake MCU");
    assert!(
        matches!(err, LinkError::VersionMismatch { mcu: 99, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("protocol v99"), "{err}");
}

#[test]
fn opening_a_missing_port_is_a_clear_error() {
    let err = Link::open("/dev/does-not-exist", LinkConfig::default())
        .err()
        .expect("error");
    assert!(err.to_string().contains("/dev/does-not-exist"), "{err}");
}
