//! `dexitac sim` and `dexitac run` on bad input: a clear message and a
//! non-zero exit, never a panic; `dexitac run --check` on the example rig
//! config; `dexitac run` against the simulated board.

use std::process::{Command, Output};

fn dexitac(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dexitac"))
        .args(args)
        .output()
        .expect("run dexitac")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn unknown_scenario_is_a_clear_error() {
    let o = dexitac(&["sim", "--scenario", "no-such-thing"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("not a preset"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"));
}

#[test]
fn malformed_scenario_file_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.toml");
    std::fs::write(
        &path,
        "[scenario]\nname = \"x\"\nduration_s = 5\n[[scenario.poke]]\ntarget = \"elbow\"\n",
    )
    .unwrap();
    let o = dexitac(&["sim", "--scenario", path.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("bad.toml"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"));
}

#[test]
fn out_of_range_speed_is_refused() {
    let o = dexitac(&["sim", "--speed", "1e9"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("speed"), "{}", stderr(&o));
    let o = dexitac(&["sim", "--speed", "NaN"]);
    assert_eq!(o.status.code(), Some(2));
    // The window shows real time; virtual time has no pace to show.
    let o = dexitac(&["sim", "--speed", "max", "--view"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("real time"), "{}", stderr(&o));
}

#[test]
fn run_with_a_bad_config_or_port_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("rig.toml");
    // A chamber that does not exist (the old flat key `grasp_chambers` is now
    // `[chambers] grasp_per_finger`: this checks the range, not the schema).
    std::fs::write(&config, "[chambers]\ngrasp_per_finger = [[0, 99], [4]]\n").unwrap();
    let o = dexitac(&[
        "run",
        "--render",
        "--port",
        "/dev/null-nope",
        "--config",
        config.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(
        stderr(&o).contains("chambers.grasp_per_finger") && stderr(&o).contains("chamber 99"),
        "{}",
        stderr(&o)
    );
    std::fs::write(&config, "# defaults\n").unwrap();
    let o = dexitac(&[
        "run",
        "--render",
        "--port",
        "/dev/null-nope",
        "--config",
        config.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("/dev/null-nope"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("panicked"));
}

#[test]
fn list_shows_the_presets() {
    let o = dexitac(&["sim", "--list"]);
    assert!(o.status.success());
    let out = String::from_utf8_lossy(&o.stdout);
    for name in ["disturbance", "grasp-hold", "slip", "no-object"] {
        assert!(out.contains(name), "{out}");
    }
}

#[test]
fn run_plays_directories_of_frames_against_the_board_then_stops_safely() {
    use dexitac_protocol::{ArmState, ValveState, CHAMBER_COUNT};
    use dexitac_sim::mcu::{SimMcu, SimMcuConfig};
    use dexitac_tactile::synth::{self, Press, Scene, SensorSpec};
    use dexitac_tactile::PointPx;

    let dir = tempfile::tempdir().unwrap();
    let sensor = SensorSpec::nominal(640, 480);
    let mut dirs = Vec::new();
    for finger in 0..2 {
        let d = dir.path().join(format!("sensor{finger}"));
        std::fs::create_dir(&d).unwrap();
        for i in 0..8u64 {
            let presses = if i == 0 {
                vec![] // the rest frame comes first
            } else {
                vec![Press {
                    centre: PointPx::new(320.0, 240.0),
                    width_px: 25.0,
                    strength: 0.6,
                    shear_px: PointPx::new(0.0, 0.0),
                    flat_radius_px: 0.0,
                }]
            };
            let f = synth::render(&Scene {
                sensor: sensor.clone(),
                presses,
                dropout: 0.0,
                seed: i,
            });
            let img = image::GrayImage::from_raw(640, 480, f.image.data().to_vec()).unwrap();
            img.save(d.join(format!("f{i:03}.png"))).unwrap();
        }
        dirs.push(d);
    }
    let config = dir.path().join("rig.toml");
    std::fs::write(&config, "[tanks]\npositive_kpa = 30.0\n").unwrap();
    let mcu = SimMcu::spawn(SimMcuConfig::default()).unwrap();
    let port = mcu.port_path().to_str().unwrap().to_string();
    let o = dexitac(&[
        "run",
        "--port",
        &port,
        "--config",
        config.to_str().unwrap(),
        "--frames",
        dirs[0].to_str().unwrap(),
        "--frames",
        dirs[1].to_str().unwrap(),
        "--fps",
        "20",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("stopped: Ok(FramesEnded)"),
        "{}",
        stderr(&o)
    );
    // The host exits on the disarm's ack, which the simulated board writes
    // before it publishes the snapshot that shows it.
    let s = mcu.snapshot_after_ticks(std::time::Duration::from_secs(2));
    assert_eq!(s.state, ArmState::Disarmed, "{s:?}");
    assert_eq!(s.chambers, [ValveState::Hold; CHAMBER_COUNT]);
}

/// The example rig config in the repository passes `run --check` (which
/// opens no port); a gripper preset given as a rig config names the bad key
/// and its line.
#[test]
fn the_example_rig_config_checks_and_a_wrong_file_names_key_and_line() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let out = dexitac(&[
        "run",
        "--config",
        root.join("config/rig.example.toml").to_str().unwrap(),
        "--check",
    ]);
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("ClosureGrip"), "{text}");
    assert!(text.contains("fingertip 1"), "{text}");
    let out = dexitac(&[
        "run",
        "--config",
        root.join("gripper/presets/hookgrip.toml").to_str().unwrap(),
        "--check",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(
        err.contains("unknown field `assembly`") && err.contains("line 7"),
        "{err}"
    );
    assert_eq!(err.matches("unknown field").count(), 1, "said once: {err}");
}

/// `--speed max` runs on the virtual clock: two runs of one scenario with
/// one seed write the same events.log, timeseries.csv and summary.json,
/// byte for byte (a shortened disturbance scenario: its first poke only).
#[test]
fn speed_max_gives_the_same_files_for_the_same_seed() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("short.toml");
    let preset = include_str!("../../sim/src/scenarios/disturbance.toml");
    assert!(preset.contains("duration_s = 30.0"));
    std::fs::write(
        &scenario,
        preset.replace("duration_s = 30.0", "duration_s = 13.5"),
    )
    .unwrap();
    let run = |out: &std::path::Path| {
        let o = dexitac(&[
            "sim",
            "--speed",
            "max",
            "--seed",
            "7",
            "--scenario",
            scenario.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", stderr(&o));
    };
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    run(&a);
    run(&b);
    for file in ["events.log", "timeseries.csv", "summary.json"] {
        let (x, y) = (
            std::fs::read(a.join(file)).unwrap(),
            std::fs::read(b.join(file)).unwrap(),
        );
        assert!(x.len() > 100, "{file}: {} bytes", x.len());
        assert!(x == y, "{file} differs between two runs with one seed");
    }
    let events = std::fs::read_to_string(a.join("events.log")).unwrap();
    assert!(events.contains("disturbance"), "{events}");
}
