//! End-to-end tests of `dexitac cameras`, `dexitac sensor tune | health`
//! and the camera errors of `dexitac run --camera`, on synthetic frames
//! written as PNG files (no camera needed).

use std::path::Path;
use std::process::{Command, Output};

use dexitac_tactile::synth::{self, Scene, SensorSpec};

fn dexitac(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dexitac"))
        .args(args)
        .output()
        .unwrap()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A no-contact frame of the nominal sensor with `dropout` of its markers
/// hidden; returns the number of visible markers.
fn save_rest(path: &Path, dropout: f64, seed: u64) -> usize {
    let f = synth::render(&Scene {
        sensor: SensorSpec::nominal(640, 480),
        presses: vec![],
        dropout,
        seed,
    });
    image::GrayImage::from_raw(640, 480, f.image.data().to_vec())
        .unwrap()
        .save(path)
        .unwrap();
    f.markers.len()
}

#[test]
fn cameras_lists_devices_or_says_there_are_none() {
    let o = dexitac(&["cameras"]);
    match o.status.code() {
        Some(0) => assert!(stdout(&o).contains("/dev/video"), "{}", stdout(&o)),
        Some(1) => assert!(
            stderr(&o).contains("no capture devices found"),
            "{}",
            stderr(&o)
        ),
        other => panic!("exit {other:?}: {}", stderr(&o)),
    }
}

#[test]
fn run_with_a_missing_camera_says_which_and_why() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("gripper.toml");
    std::fs::write(&config, "# defaults\n").unwrap();
    let base = [
        "run",
        "--port",
        "/dev/null-nope",
        "--config",
        config.to_str().unwrap(),
    ];
    let o = dexitac(&[&base[..], &["--camera", "/dev/video-nope", "--camera", "1"]].concat());
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("/dev/video-nope: no such camera"),
        "{}",
        stderr(&o)
    );
    let o = dexitac(&[&base[..], &["--camera", "0"]].concat());
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--camera twice"), "{}", stderr(&o));
    let o = dexitac(
        &[
            &base[..],
            &[
                "--camera",
                "/dev/null",
                "--camera",
                "1",
                "--camera-size",
                "640by480",
            ],
        ]
        .concat(),
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--camera-size"), "{}", stderr(&o));
    let o = dexitac(&[&base[..], &["--camera", "/dev/null", "--camera", "1"]].concat());
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("/dev/null: not a video capture device"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn tune_writes_a_config_that_analyze_accepts() {
    let dir = tempfile::tempdir().unwrap();
    let rest = dir.path().join("rest.png");
    let visible = save_rest(&rest, 0.0, 1);
    let out = dir.path().join("tuned.toml");
    // A base config that finds too few markers.
    let base = dir.path().join("base.toml");
    std::fs::write(
        &base,
        "[markers]\nstrength_ratio = 0.95\nmin_contrast = 150.0\n",
    )
    .unwrap();
    let pins = visible.to_string();
    let o = dexitac(&[
        "sensor",
        "tune",
        "--rest",
        rest.to_str().unwrap(),
        "--pins",
        &pins,
        "--config",
        base.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    assert!(
        stderr(&o).contains(&format!("{visible} of {visible} pins found")),
        "{}",
        stderr(&o)
    );
    let frames = dir.path().join("frames");
    std::fs::create_dir(&frames).unwrap();
    save_rest(&frames.join("0001.png"), 0.0, 2);
    let o = dexitac(&[
        "analyze",
        "--rest",
        rest.to_str().unwrap(),
        "--config",
        out.to_str().unwrap(),
        "--out",
        dir.path().join("pred.csv").to_str().unwrap(),
        frames.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    // An impossible count: the closest is written, exit 1.
    let o = dexitac(&[
        "sensor",
        "tune",
        "--rest",
        rest.to_str().unwrap(),
        "--pins",
        "5000",
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stdout(&o).contains("[markers]"));
}

#[test]
fn health_passes_a_good_skin_and_fails_one_with_holes() {
    let dir = tempfile::tempdir().unwrap();
    let rest = dir.path().join("rest.png");
    save_rest(&rest, 0.0, 1);
    let good = dir.path().join("good");
    std::fs::create_dir(&good).unwrap();
    for seed in 2..5 {
        save_rest(&good.join(format!("{seed}.png")), 0.0, seed);
    }
    let o = dexitac(&[
        "sensor",
        "health",
        "--rest",
        rest.to_str().unwrap(),
        good.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}{}", stdout(&o), stderr(&o));
    assert!(stdout(&o).contains("PASS"), "{}", stdout(&o));
    assert!(stdout(&o).contains("jitter: median"), "{}", stdout(&o));
    let worn = dir.path().join("worn.png");
    save_rest(&worn, 0.2, 7);
    let o = dexitac(&[
        "sensor",
        "health",
        "--rest",
        rest.to_str().unwrap(),
        worn.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stdout(&o));
    assert!(stdout(&o).contains("FAIL"), "{}", stdout(&o));
    assert!(stdout(&o).contains("missing"), "{}", stdout(&o));
    let o = dexitac(&[
        "sensor",
        "health",
        "--rest",
        dir.path().join("nope.png").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(3));
    assert!(stderr(&o).contains("nope.png"), "{}", stderr(&o));
}

#[cfg(unix)]
#[test]
fn health_into_a_closed_pipe_does_not_panic() {
    // `dexitac sensor health ... | head -1`: the reader is gone before the
    // report is written. The process ends by SIGPIPE (as `cat` does), not
    // by a panic (exit 101) in `println!`.
    use std::os::unix::process::ExitStatusExt;
    use std::process::Stdio;
    let dir = tempfile::tempdir().unwrap();
    let rest = dir.path().join("rest.png");
    save_rest(&rest, 0.0, 1);
    let rest = rest.to_str().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_dexitac"))
        .args(["sensor", "health", "--rest", rest, rest])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let o = child.wait_with_output().unwrap();
    assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
    assert_eq!(o.status.signal(), Some(libc::SIGPIPE), "{:?}", o.status);
}
