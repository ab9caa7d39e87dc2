//! `dexitac run --config RIG.toml --check`: the rig config is loaded and
//! checked with no port or camera opened.

use std::process::{Command, Output};

fn dexitac(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dexitac"))
        .args(args)
        .output()
        .expect("run dexitac")
}

fn stderr(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
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
