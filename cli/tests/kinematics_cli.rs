//! `dexitac workspace` and `dexitac fit-actuator` end to end: run the built
//! binary, check the files it writes and its errors.

use std::path::Path;
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

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

fn run_workspace(dir: &Path, finger: &str, extra: &[&str]) -> serde_json::Value {
    let out_dir = dir.to_str().unwrap();
    let mut args = vec![
        "workspace",
        "--finger",
        finger,
        "--levels",
        "4",
        "--voxel-mm",
        "6",
        "--image-px",
        "96",
        "--out",
        out_dir,
    ];
    args.extend_from_slice(extra);
    let out = dexitac(&args);
    assert!(out.status.success(), "{}", stderr(&out));
    json(&dir.join(format!("{finger}-workspace.json")))
}

#[test]
fn workspace_writes_points_views_and_volume() {
    let dir = tempfile::tempdir().unwrap();
    let report = run_workspace(dir.path(), "dex-rot", &[]);

    let csv = std::fs::read_to_string(dir.path().join("dex-rot-points.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next(),
        Some("rot_kpa,dex0_kpa,dex1_kpa,dex2_kpa,x_mm,y_mm,z_mm")
    );
    let rows: Vec<Vec<f64>> = lines
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 4 * 4 * 4 * 4);
    assert!(rows.iter().all(|r| r.len() == 7));
    // Pressures span the tank range.
    assert_eq!(rows[0][0], -57.0);
    assert_eq!(rows.last().unwrap()[3], 50.0);

    for view in ["xy", "xz", "3d"] {
        let img = image::open(dir.path().join(format!("dex-rot-{view}.png"))).unwrap();
        assert_eq!((img.width(), img.height()), (96, 96));
        let svg = std::fs::read_to_string(dir.path().join(format!("dex-rot-{view}.svg"))).unwrap();
        assert!(svg.contains("dex-rot finger workspace") && svg.contains("x (mm)"));
    }

    assert_eq!(report["finger"], "dex-rot");
    // The configuration reported is the one computed: a Dex-Rot finger with
    // the joints of a Dex-Rot preset by default.
    assert_eq!(
        report["config"],
        "dex-rot finger, joints of HookGrip (preset hookgrip)"
    );
    assert_eq!(report["subject"]["joints_config_finger"], "dex-rot");
    assert_eq!(report["point"], "joint-end");
    assert_eq!(report["points_csv"]["samples"], 256);
    let volume = report["volume"]["volume_mm3"].as_f64().unwrap();
    assert!(volume > 0.0);
    let size = &report["extents"]["size_mm"];
    assert!((0..3).all(|k| size[k].as_f64().unwrap() > 0.0));
}

#[test]
fn workspace_never_reports_a_preset_of_the_other_finger_type_as_its_configuration() {
    let dir = tempfile::tempdir().unwrap();
    let report = run_workspace(dir.path(), "dex-rot", &["--preset", "pinchgrip"]);
    assert_eq!(report["finger"], "dex-rot");
    let config = report["config"].as_str().unwrap();
    assert!(
        config.starts_with("dex-rot finger, joints of PinchGrip"),
        "{config}"
    );
    assert!(config.contains("a rot-dex configuration"), "{config}");
    assert_eq!(report["subject"]["finger"], "dex-rot");
    assert_eq!(report["subject"]["joints_from"], "preset pinchgrip");
    assert_eq!(report["subject"]["joints_config_finger"], "rot-dex");
    let report = run_workspace(dir.path(), "rot-dex", &[]);
    assert_eq!(
        report["config"],
        "rot-dex finger, joints of SupportGrip (preset supportgrip)"
    );
}

#[test]
fn workspace_dex_rot_is_larger_than_rot_dex_from_the_cli() {
    let dir = tempfile::tempdir().unwrap();
    let volume = |finger| {
        let r = run_workspace(dir.path(), finger, &["--preset", "hookgrip"]);
        r["volume"]["volume_mm3"].as_f64().unwrap()
    };
    assert!(volume("dex-rot") > volume("rot-dex"));
}

#[test]
fn workspace_reports_a_bad_config_and_a_bad_argument() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("bad.toml");
    std::fs::write(&config, "name = \"x\"\nfinger = \"dex-dex\"\n").unwrap();
    let out_dir = dir.path().join("out");
    let out = dexitac(&[
        "workspace",
        "--finger",
        "rot-dex",
        "--config",
        config.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr(&out).contains("invalid gripper config"),
        "{}",
        stderr(&out)
    );

    let out = dexitac(&[
        "workspace",
        "--finger",
        "rot-dex",
        "--voxel-mm=0",
        "--levels",
        "3",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("voxel"), "{}", stderr(&out));
    // Nothing is written before the arguments are checked.
    assert!(!out_dir.exists());

    let out = dexitac(&[
        "workspace",
        "--finger",
        "rot-dex",
        "--levels",
        "41",
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("--levels"), "{}", stderr(&out));
}

#[test]
fn fit_actuator_fits_and_writes_the_model() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("rot.csv");
    let mut text = String::from("pressure_kpa,angle_deg\n");
    for i in 0..=20 {
        let p = -50.0 + 5.0 * f64::from(i);
        // Alternating +-0.2 deg "noise" around 1.2 deg/kPa + 3 deg.
        let noise = if i % 2 == 0 { 0.2 } else { -0.2 };
        text += &format!("{p},{}\n", 1.2 * p + 3.0 + noise);
    }
    std::fs::write(&data, text).unwrap();
    let fit_path = dir.path().join("fit.toml");
    let out = dexitac(&[
        "fit-actuator",
        "--data",
        data.to_str().unwrap(),
        "--out",
        fit_path.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("R^2"), "{stdout}");
    let table: toml::Table = toml::from_str(&std::fs::read_to_string(&fit_path).unwrap()).unwrap();
    let slope = table["rot"]["slope_deg_per_kpa"].as_float().unwrap();
    let intercept = table["rot"]["intercept_deg"].as_float().unwrap();
    assert!((slope - 1.2).abs() < 0.01, "{slope}");
    assert!((intercept - 3.0).abs() < 0.1, "{intercept}");
}

#[test]
fn fit_actuator_names_the_bad_line_and_refuses_degenerate_data() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("bad.csv");
    std::fs::write(&data, "pressure_kpa,angle_deg\n0,0\n10;12\n").unwrap();
    let out = dexitac(&["fit-actuator", "--data", data.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("line 3"), "{}", stderr(&out));

    std::fs::write(&data, "10,1\n10,2\n10,3\n").unwrap();
    let out = dexitac(&["fit-actuator", "--data", data.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).contains("degenerate"), "{}", stderr(&out));

    let out = dexitac(&["fit-actuator", "--data", "/nonexistent/data.csv"]);
    assert_eq!(out.status.code(), Some(2));
}
