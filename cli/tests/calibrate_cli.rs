//! `dexitac calibrate` against the simulated board (the firmware's control
//! core behind a pty, its calibration record in a simulated flash page):
//! show, set and read back, refusals with their exit codes, and `--zero`.

use std::process::{Command, Output};
use std::thread;
use std::time::{Duration, Instant};

use dexitac_protocol::{
    Calibration, CalibrationRecord, CalibrationSource, HostMsg, SensorCalibration, ZeroSource,
};
use dexitac_rig::link::{Link, LinkConfig};
use dexitac_sim::mcu::{SimMcu, SimMcuConfig};

/// A simulated board past its boot zero.
fn board(config: SimMcuConfig) -> SimMcu {
    let mcu = SimMcu::spawn(config).expect("simulated MCU");
    wait_booted(&mcu);
    mcu
}

fn wait_booted(mcu: &SimMcu) {
    let booted = u64::from(dexitac_firmware::control::ZERO_AT_TICK) + 5;
    let until = Instant::now() + Duration::from_secs(5);
    while mcu.snapshot().time_ms <= booted {
        assert!(Instant::now() < until, "the simulated board did not boot");
        thread::sleep(Duration::from_millis(2));
    }
}

/// Resets the simulated board and waits until the new run is past its
/// boot zero.
fn reset(mcu: &SimMcu) {
    let before_ms = mcu.snapshot().time_ms;
    mcu.reset();
    let until = Instant::now() + Duration::from_secs(5);
    while mcu.snapshot().time_ms >= before_ms {
        assert!(Instant::now() < until, "the simulated board did not reset");
        thread::sleep(Duration::from_millis(2));
    }
    wait_booted(mcu);
}

/// The number after `key` in `text` (e.g. `reads ` -> -9.2).
fn number_after(text: &str, key: &str) -> f64 {
    let at = text
        .find(key)
        .unwrap_or_else(|| panic!("no `{key}` in {text}"));
    let number: String = text[at + key.len()..]
        .chars()
        .take_while(|c| c.is_ascii_digit() || matches!(c, '+' | '-' | '.'))
        .collect();
    number
        .parse()
        .unwrap_or_else(|_| panic!("no number after `{key}` in {text}"))
}

fn calibrate(mcu: &SimMcu, args: &[&str]) -> (Output, String, String) {
    let port = mcu.port_path().to_str().expect("pty path").to_string();
    let out = Command::new(env!("CARGO_BIN_EXE_dexitac"))
        .args(["calibrate", "--port", &port])
        .args(args)
        .output()
        .expect("run dexitac calibrate");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    (out, stdout, stderr)
}

fn sensor(offset_pa: i32, gain_ppm: u32) -> SensorCalibration {
    SensorCalibration {
        offset_pa,
        gain_ppm,
    }
}

#[test]
fn calibrate_shows_sets_reads_back_and_refuses_with_clear_errors() {
    let mcu = board(SimMcuConfig::default());

    // A fresh board: nothing stored.
    let (out, text, _) = calibrate(&mcu, &["--show"]);
    assert_eq!(out.status.code(), Some(0), "{text}");
    assert!(text.contains("calibration: default"), "{text}");
    assert!(text.contains("none stored"), "{text}");
    assert!(
        text.contains("positive sensor: offset +0.000 kPa, gain 1.000000"),
        "{text}"
    );

    // Set both, read back, stored in the (simulated) flash.
    let (out, text, err) = calibrate(&mcu, &["--offset-kpa", "1.5,-1", "--gain", "1.05,0.97"]);
    assert_eq!(out.status.code(), Some(0), "{text}{err}");
    assert!(text.contains("set by the host"), "{text}");
    assert!(
        text.contains("stored in flash (record v1, CRC valid)"),
        "{text}"
    );
    assert!(
        text.contains("positive sensor: offset +1.500 kPa, gain 1.050000"),
        "{text}"
    );
    let want = Calibration {
        positive: sensor(1_500, 1_050_000),
        negative: sensor(-1_000, 970_000),
    };
    let report = mcu.calibration();
    assert_eq!(report.calibration, want);
    assert_eq!(report.record, CalibrationRecord::Valid { version: 1 });

    // Only the gains: the offsets stay.
    let (out, text, err) = calibrate(&mcu, &["--gain", "1,1"]);
    assert_eq!(out.status.code(), Some(0), "{text}{err}");
    assert_eq!(
        mcu.calibration().calibration,
        Calibration {
            positive: sensor(1_500, 1_000_000),
            negative: sensor(-1_000, 1_000_000),
        }
    );

    // Out of range or malformed: refused on the host, nothing sent, exit 2.
    let (out, _, err) = calibrate(&mcu, &["--gain", "1.5,1"]);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("positive sensor gain 1.500000 is outside 0.9..1.1"),
        "{err}"
    );
    let (out, _, err) = calibrate(&mcu, &["--offset-kpa", "0,-12"]);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("negative sensor offset -12.000 kPa is outside ±10 kPa"),
        "{err}"
    );
    let (out, _, err) = calibrate(&mcu, &["--offset-kpa", "1"]);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("give two values"), "{err}");
    let (out, _, err) = calibrate(&mcu, &["--show", "--gain", "1,1"]);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert_eq!(mcu.calibration().calibration.positive.gain_ppm, 1_000_000);

    // After a board reset the calibration comes back from flash.
    reset(&mcu);
    assert_eq!(mcu.calibration().source, CalibrationSource::Flash);
    let (out, text, _) = calibrate(&mcu, &["--show"]);
    assert_eq!(out.status.code(), Some(0), "{text}");
    assert!(text.contains("read from the board's flash"), "{text}");
    assert!(
        text.contains("negative sensor: offset -1.000 kPa"),
        "{text}"
    );
}

#[test]
fn calibrate_is_refused_by_an_armed_board() {
    // A long silence deadline: the test's own link arms the board, then
    // closes the port (ports are opened exclusively) for the command.
    let mcu = board(SimMcuConfig {
        firmware: dexitac_firmware::Config {
            host_silence_ms: 60_000,
            ..dexitac_firmware::Config::default()
        },
        ..SimMcuConfig::default()
    });
    {
        let mut link = Link::open(mcu.port_path(), LinkConfig::default()).expect("open pty");
        link.hello().expect("hello");
        link.command(HostMsg::Arm).expect("arm");
    }
    let (out, _, err) = calibrate(&mcu, &["--gain", "1.02,1"]);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("the board is armed"), "{err}");
    assert_eq!(mcu.calibration().calibration, Calibration::IDENTITY);
}

#[test]
fn calibrate_zero_takes_the_offsets_from_the_readings_of_atmosphere() {
    // A board whose stored offsets (+9 / -9 kPa) are wrong: its tanks are at
    // atmosphere and its (simulated) sensors exact, so at boot they read
    // 0 Pa, outside the 4 kPa window around the offsets: the offsets apply
    // and the readings are 9 kPa off.
    let mcu = board(SimMcuConfig::default());
    let (out, text, err) = calibrate(&mcu, &["--offset-kpa", "9,-9", "--gain", "1.02,1"]);
    assert_eq!(out.status.code(), Some(0), "{text}{err}");
    reset(&mcu);
    let report = mcu.calibration();
    assert_eq!(report.source, CalibrationSource::Flash);
    assert_eq!(
        report.positive_zero.source,
        ZeroSource::Offset,
        "{report:?}"
    );

    let (out, text, err) = calibrate(&mcu, &["--zero"]);
    assert_eq!(out.status.code(), Some(0), "{text}{err}");
    // (0 - 9 kPa) x 1.02 and (0 + 9 kPa) x 1, within the ADC's resolution.
    let positive = number_after(&text, "positive sensor: reads ");
    let negative = number_after(&text, "negative sensor: reads ");
    assert!((positive + 9.18).abs() < 0.3, "{text}");
    assert!((negative - 9.0).abs() < 0.3, "{text}");
    let report = mcu.calibration();
    // The sensors read atmosphere as 0 Pa: offsets of about 0, so the boot
    // zero (0 Pa) lies within the window again and applies; gains kept.
    for s in [report.calibration.positive, report.calibration.negative] {
        assert!(s.offset_pa.abs() <= 300, "{report:?}");
    }
    assert_eq!(report.calibration.positive.gain_ppm, 1_020_000);
    assert_eq!(report.positive_zero.source, ZeroSource::Boot);
    assert_eq!(report.negative_zero.source, ZeroSource::Boot);
    assert_eq!(report.record, CalibrationRecord::Valid { version: 1 });
}
