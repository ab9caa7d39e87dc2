//! `dexitac sim` and `dexitac run` on bad input: a clear message and a
//! non-zero exit, never a panic.

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
        "name = \"x\"\nduration_s = 5\n[[poke]]\ntarget = \"elbow\"\n",
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
}

#[test]
fn run_with_a_bad_config_or_port_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("gripper.toml");
    std::fs::write(&config, "grasp_chambers = [0, 99]\n").unwrap();
    let o = dexitac(&[
        "run",
        "--render",
        "--port",
        "/dev/null-nope",
        "--config",
        config.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("grasp_chambers"), "{}", stderr(&o));
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
