//! End-to-end test of `dexitac analyze`: synthetic frames with known contact
//! centres are written as PNG files, the binary is run on them, and the CSV
//! is checked against the truth. Bad files must be reported per file without
//! stopping the run.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use dexitac_tactile::synth::{self, Category, SynthFrame};
use dexitac_tactile::PointPx;

fn save_grey(frame: &SynthFrame, path: &Path) {
    let img = &frame.image;
    image::save_buffer(
        path,
        img.data(),
        img.width() as u32,
        img.height() as u32,
        image::ExtendedColorType::L8,
    )
    .unwrap();
}

fn save_rgb(frame: &SynthFrame, path: &Path) {
    let img = &frame.image;
    let rgb: Vec<u8> = img.data().iter().flat_map(|&v| [v, v, v]).collect();
    image::save_buffer(
        path,
        &rgb,
        img.width() as u32,
        img.height() as u32,
        image::ExtendedColorType::Rgb8,
    )
    .unwrap();
}

fn run(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dexitac"))
        .args(args)
        .output()
        .unwrap()
}

struct Fixture {
    _dir: tempfile::TempDir,
    root: PathBuf,
    truth: Vec<(String, Option<PointPx>)>,
}

fn fixture() -> Fixture {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().to_path_buf();
    let frames = root.join("frames");
    std::fs::create_dir(&frames).unwrap();
    let sensor = Category::Nominal.sensor(640, 480, 21);
    save_grey(&synth::rest_frame(&sensor, 1), &root.join("rest.png"));
    let mut truth = Vec::new();
    for k in 0..3u64 {
        let f = synth::render(&Category::Nominal.scene(&sensor, 40 + k));
        let name = format!("press_{k}");
        if k == 2 {
            save_rgb(&f, &frames.join(format!("{name}.png")));
        } else if k == 1 {
            let img = &f.image;
            let buf = image::GrayImage::from_raw(
                img.width() as u32,
                img.height() as u32,
                img.data().to_vec(),
            )
            .unwrap();
            buf.save(frames.join(format!("{name}.jpg"))).unwrap();
        } else {
            save_grey(&f, &frames.join(format!("{name}.png")));
        }
        truth.push((name, Some(f.contacts[0])));
    }
    let idle = synth::render(&Category::NoContact.scene(&sensor, 50));
    save_grey(&idle, &frames.join("idle.png"));
    truth.push(("idle".into(), None));
    Fixture {
        _dir: dir,
        root,
        truth,
    }
}

/// Parses the CSV into (frame, cx, cy, n_markers).
fn read_csv(path: &Path) -> (String, Vec<(String, f64, f64, usize)>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header = lines.next().unwrap().to_string();
    let rows = lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (
                f[0].to_string(),
                f[1].parse().unwrap(),
                f[2].parse().unwrap(),
                f[3].parse().unwrap(),
            )
        })
        .collect();
    (header, rows)
}

#[test]
fn analyze_writes_centres_matching_the_truth() {
    let fx = fixture();
    let out = fx.root.join("pred.csv");
    let markers = fx.root.join("markers");
    let field = fx.root.join("field");
    let r = run(&[
        "analyze",
        "--rest",
        fx.root.join("rest.png").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--markers-out",
        markers.to_str().unwrap(),
        "--field-out",
        field.to_str().unwrap(),
        fx.root.join("frames").to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let (header, rows) = read_csv(&out);
    assert!(
        header.starts_with("frame,cx,cy,n_markers,t_detect_ms,t_kde_ms,t_segment_ms,t_total_ms")
    );
    assert_eq!(rows.len(), fx.truth.len());
    assert!(
        header.ends_with("shift_mm,shift_from_anchor_mm"),
        "{header}"
    );
    check_shifts(&out);
    for (name, truth) in &fx.truth {
        let row = rows.iter().find(|r| &r.0 == name).unwrap();
        assert!(row.3 > 500, "{name}: {} markers", row.3);
        match truth {
            Some(t) => {
                let err = (row.1 - t.x).hypot(row.2 - t.y);
                assert!(
                    err < 1.5,
                    "{name}: centre ({}, {}) vs truth {t:?}",
                    row.1,
                    row.2
                );
            }
            None => assert!(row.1.is_nan() && row.2.is_nan(), "{name}: false contact"),
        }
        let m = std::fs::read_to_string(markers.join(format!("{name}.csv"))).unwrap();
        assert!(m.starts_with("x,y\n"));
        assert_eq!(m.lines().count(), row.3 + 1);
        check_field(&field.join(format!("{name}.csv")), *truth);
    }
}

/// A frame's `--field-out` CSV: one row per rest marker, nearly all of them
/// in place without a contact; with one, the markers that moved more than
/// 2 px lie around it.
fn check_field(path: &Path, truth: Option<PointPx>) {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(
        text.starts_with("rest_x,rest_y,x,y\n"),
        "{}",
        path.display()
    );
    let rows: Vec<Vec<Option<f64>>> = text
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().ok()).collect())
        .collect();
    assert!(rows.len() > 500, "{} rest markers", rows.len());
    let moved: Vec<(f64, f64)> = rows
        .iter()
        .filter_map(|r| {
            let (rx, ry) = (r[0].unwrap(), r[1].unwrap());
            let (x, y) = (r[2]?, r[3]?);
            ((x - rx).hypot(y - ry) > 2.0).then_some((rx, ry))
        })
        .collect();
    let lost = rows.iter().filter(|r| r[2].is_none()).count();
    match truth {
        None => assert!(
            moved.len() + lost <= rows.len() / 100,
            "no contact: {} moved, {lost} lost",
            moved.len()
        ),
        Some(t) => {
            assert!(moved.len() >= 5, "{} moved", moved.len());
            for (x, y) in moved {
                assert!(
                    (x - t.x).hypot(y - t.y) < 80.0,
                    "({x}, {y}) moved, far from the contact {t:?}"
                );
            }
        }
    }
}

/// Rows come in file order (idle, press_0, press_1, press_2): the shift
/// columns are the centre moves in mm (0.1 mm/px by default) from the previous
/// row and from the first contact.
fn check_shifts(out: &Path) {
    let text = std::fs::read_to_string(out).unwrap();
    let rows: Vec<Vec<f64>> = text
        .lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            let n = f.len();
            vec![
                f[1].parse().unwrap(),
                f[2].parse().unwrap(),
                f[n - 2].parse().unwrap(),
                f[n - 1].parse().unwrap(),
            ]
        })
        .collect();
    assert!(
        rows[0][2].is_nan() && rows[0][3].is_nan(),
        "idle: {:?}",
        rows[0]
    );
    assert!(
        rows[1][2].is_nan() && rows[1][3] == 0.0,
        "first contact: {:?}",
        rows[1]
    );
    let mm = |a: &[f64], b: &[f64]| (a[0] - b[0]).hypot(a[1] - b[1]) * 0.1;
    assert!(
        (rows[2][2] - mm(&rows[2], &rows[1])).abs() < 1e-3,
        "{rows:?}"
    );
    assert!(
        (rows[3][3] - mm(&rows[3], &rows[1])).abs() < 1e-3,
        "{rows:?}"
    );
}

#[test]
fn bad_files_are_reported_and_do_not_stop_the_run() {
    let fx = fixture();
    let bad = fx.root.join("bad");
    std::fs::create_dir(&bad).unwrap();
    std::fs::write(bad.join("text.png"), b"this is not a png").unwrap();
    std::fs::write(bad.join("empty.png"), b"").unwrap();
    let small = synth::rest_frame(&Category::Nominal.sensor(320, 240, 1), 1);
    save_grey(&small, &bad.join("small.png"));
    let out = fx.root.join("pred.csv");
    let good = fx.root.join("frames").join("press_0.png");
    let r = run(&[
        "analyze",
        "--rest",
        fx.root.join("rest.png").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        bad.join("text.png").to_str().unwrap(),
        good.to_str().unwrap(),
        bad.join("empty.png").to_str().unwrap(),
        bad.join("small.png").to_str().unwrap(),
        bad.join("missing.png").to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&r.stderr);
    for name in ["text.png", "empty.png", "small.png", "missing.png"] {
        assert!(stderr.contains(name), "no message for {name}: {stderr}");
    }
    assert!(stderr.contains("wrong size 320x240"), "{stderr}");
    let (_, rows) = read_csv(&out);
    assert_eq!(rows.len(), 1);
    assert_eq!(rows[0].0, "press_0");
    assert!(rows[0].1.is_finite());
}

#[test]
fn bad_config_and_bad_rest_stop_with_a_message() {
    let fx = fixture();
    let cfg = fx.root.join("sensor.toml");
    std::fs::write(&cfg, "[density]\nkernel_width_px = 0.0\n").unwrap();
    let out = fx.root.join("pred.csv");
    let frame = fx.root.join("frames").join("idle.png");
    let r = run(&[
        "analyze",
        "--rest",
        fx.root.join("rest.png").to_str().unwrap(),
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        frame.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("density.kernel_width_px"));
    let black = fx.root.join("black.png");
    image::save_buffer(
        &black,
        &[0u8; 64 * 48],
        64,
        48,
        image::ExtendedColorType::L8,
    )
    .unwrap();
    let r = run(&[
        "analyze",
        "--rest",
        black.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        frame.to_str().unwrap(),
    ]);
    assert_eq!(r.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&r.stderr).contains("rest"));
}

#[test]
fn top_level_help_lists_analyze() {
    let r = run(&["--help"]);
    assert!(r.status.success());
    let text = String::from_utf8_lossy(&r.stdout);
    assert!(
        text.contains("analyze") && text.contains("bench-pipeline"),
        "{text}"
    );
}

#[test]
fn larger_input_is_rescaled_and_centres_are_in_input_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let sensor = Category::Nominal.sensor(1280, 960, 3);
    let rest = dir.path().join("rest.png");
    save_grey(&synth::rest_frame(&sensor, 1), &rest);
    let f = synth::render(&Category::Nominal.scene(&sensor, 77));
    let frame = dir.path().join("big.png");
    save_grey(&f, &frame);
    let out = dir.path().join("pred.csv");
    let r = run(&[
        "analyze",
        "--rest",
        rest.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        frame.to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let (_, rows) = read_csv(&out);
    let t = f.contacts[0];
    let err = (rows[0].1 - t.x).hypot(rows[0].2 - t.y);
    // 2 input px per working px: 1 working px is 2 input px.
    assert!(
        err < 2.0,
        "centre ({}, {}) vs truth {t:?}",
        rows[0].1,
        rows[0].2
    );
}

#[test]
fn synth_frames_then_analyze_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sf");
    let r = run(&[
        "synth-frames",
        "--out",
        out.to_str().unwrap(),
        "--frames",
        "2",
        "--category",
        "edge",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let truth = std::fs::read_to_string(out.join("truth.csv")).unwrap();
    assert_eq!(truth.lines().count(), 3, "{truth}");
    let pred = out.join("pred.csv");
    let r = run(&[
        "analyze",
        "--rest",
        out.join("rest.png").to_str().unwrap(),
        "--out",
        pred.to_str().unwrap(),
        out.join("frames").to_str().unwrap(),
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let (_, rows) = read_csv(&pred);
    for (line, row) in truth.lines().skip(1).zip(&rows) {
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f[0], row.0);
        let (tx, ty): (f64, f64) = (f[1].parse().unwrap(), f[2].parse().unwrap());
        // The generator's edge contacts take the density centre: 1.50 px
        // off on frame 1, 57 px from the frame's edge (BENCHMARKS.md,
        // session 27: the tracked lines' centre, 0.02 px here, lies beyond
        // the contact wherever pressed pins also move by parallax).
        assert!((row.1 - tx).hypot(row.2 - ty) < 2.0, "{line} vs {row:?}");
    }
    let bad = run(&[
        "synth-frames",
        "--out",
        out.to_str().unwrap(),
        "--category",
        "nope",
    ]);
    assert_eq!(bad.status.code(), Some(2));
}

/// Frames of the same name from two folders get distinct labels and marker
/// files (the second no longer overwrites the first); a marker folder that
/// already holds marker files is refused; the run ends with a summary line.
#[test]
fn same_named_frames_from_two_folders_stay_apart() {
    let fx = fixture();
    let (name, _) = &fx.truth[0];
    for run_dir in ["run1", "run2"] {
        let d = fx.root.join(run_dir);
        std::fs::create_dir_all(&d).unwrap();
        std::fs::copy(
            fx.root.join("frames").join(format!("{name}.png")),
            d.join(format!("{name}.png")),
        )
        .unwrap();
    }
    let out = fx.root.join("two.csv");
    let markers = fx.root.join("two-markers");
    let args = |markers: &std::path::Path| {
        run(&[
            "analyze",
            "--rest",
            fx.root.join("rest.png").to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--markers-out",
            markers.to_str().unwrap(),
            fx.root.join("run1").to_str().unwrap(),
            fx.root.join("run2").to_str().unwrap(),
        ])
    };
    let r = args(&markers);
    let stderr = String::from_utf8_lossy(&r.stderr).into_owned();
    assert!(r.status.success(), "{stderr}");
    assert!(
        stderr.contains("2 frame(s) analysed") && stderr.contains("median"),
        "{stderr}"
    );
    let (_, rows) = read_csv(&out);
    let labels: Vec<&str> = rows.iter().map(|r| r.0.as_str()).collect();
    assert_eq!(labels, [format!("run1/{name}"), format!("run2/{name}")]);
    for run_dir in ["run1", "run2"] {
        assert!(markers.join(format!("{run_dir}__{name}.csv")).is_file());
    }
    let again = args(&markers);
    assert_eq!(again.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&again.stderr).contains("already holds 2 CSV file(s)"));
}

#[test]
fn a_rest_with_holes_is_replaced_by_one_from_the_frames_unless_kept() {
    // The rest's middle pins painted out (as the median image of taps
    // loses them); 20 frames with presses at random places. By default the
    // rest is estimated from the frames, with --keep-rest the given one is
    // used, both with a warning.
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let frames = root.join("frames");
    std::fs::create_dir(&frames).unwrap();
    let sensor = Category::Nominal.sensor(640, 480, 21);
    let mut rest = synth::rest_frame(&sensor, 1);
    let level = {
        let mut v = rest.image.data().to_vec();
        v.sort_unstable();
        v[v.len() / 4]
    };
    let data: Vec<u8> = rest
        .image
        .data()
        .iter()
        .enumerate()
        .map(|(k, &v)| {
            let (x, y) = ((k % 640) as f64, (k / 640) as f64);
            if (x - 320.0).hypot(y - 240.0) < 80.0 {
                level
            } else {
                v
            }
        })
        .collect();
    rest.image = dexitac_tactile::frame::GreyFrame::new(640, 480, data).unwrap();
    save_grey(&rest, &root.join("rest.png"));
    for k in 0..20u64 {
        let f = synth::render(&Category::Nominal.scene(&sensor, 60 + k));
        save_grey(&f, &frames.join(format!("press_{k:02}.png")));
    }
    let rest = root.join("rest.png");
    let out = root.join("pred.csv");
    let args = |keep: bool| {
        let mut a = vec![
            "analyze",
            "--rest",
            rest.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            frames.to_str().unwrap(),
        ];
        if keep {
            a.push("--keep-rest");
        }
        a
    };
    let o = run(&args(false));
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    assert!(err.contains("has holes"), "{err}");
    assert!(
        err.contains("Using the rest estimated from the frames"),
        "{err}"
    );
    let o = run(&args(true));
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{err}");
    assert!(err.contains("has holes"), "{err}");
    assert!(!err.contains("Using the rest estimated"), "{err}");
}

/// A `--field-in` CSV of the generator's true places: one row per true
/// rest marker, `rest_x,rest_y,x,y`.
fn write_true_field(frame: &SynthFrame, path: &Path) {
    assert_eq!(frame.markers.len(), frame.rest_markers.len(), "no dropout");
    let mut text = String::from("rest_x,rest_y,x,y\n");
    for (r, m) in frame.rest_markers.iter().zip(&frame.markers) {
        text.push_str(&format!("{:.4},{:.4},{:.4},{:.4}\n", r.x, r.y, m.x, m.y));
    }
    std::fs::write(path, text).unwrap();
}

#[test]
fn field_in_runs_the_contact_stages_on_given_markers() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path();
    let (frames, fields) = (root.join("frames"), root.join("true"));
    std::fs::create_dir(&frames).unwrap();
    std::fs::create_dir(&fields).unwrap();
    let sensor = Category::Nominal.sensor(640, 480, 21);
    save_grey(&synth::rest_frame(&sensor, 1), &root.join("rest.png"));
    let mut truth = Vec::new();
    for k in 0..2u64 {
        let f = synth::render(&Category::Nominal.scene(&sensor, 60 + k));
        let name = format!("press_{k}");
        save_grey(&f, &frames.join(format!("{name}.png")));
        write_true_field(&f, &fields.join(format!("{name}.csv")));
        truth.push((name, f.contacts[0]));
    }
    let idle = synth::render(&Category::NoContact.scene(&sensor, 70));
    save_grey(&idle, &frames.join("idle.png"));
    write_true_field(&idle, &fields.join("idle.csv"));
    // One frame's CSV is garbled, another's is missing.
    save_grey(&idle, &frames.join("garbled.png"));
    std::fs::write(
        fields.join("garbled.csv"),
        "rest_x,rest_y,x,y\n1,2,three,4\n",
    )
    .unwrap();
    save_grey(&idle, &frames.join("no_field.png"));
    let rest = root.join("rest.png");
    let analyze = |field_in: &Path, out: &Path, more: &[&str]| {
        let mut args = vec![
            "analyze",
            "--rest",
            rest.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--field-in",
            field_in.to_str().unwrap(),
        ];
        args.extend_from_slice(more);
        args.push(frames.to_str().unwrap());
        run(&args)
    };
    let out = root.join("true.csv");
    let r = analyze(&fields, &out, &[]);
    assert_eq!(r.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(stderr.contains("`three` is not a number"), "{stderr}");
    assert!(stderr.contains("no_field.csv"), "{stderr}");
    let (_, rows) = read_csv(&out);
    assert_eq!(rows.len(), 3, "{rows:?}");
    for (name, t) in &truth {
        let row = rows.iter().find(|r| &r.0 == name).unwrap();
        let err = (row.1 - t.x).hypot(row.2 - t.y);
        assert!(err < 1.0, "{name}: ({}, {}) vs {t:?}", row.1, row.2);
        assert!(row.3 > 500, "{name}: {} markers", row.3);
    }
    let idle_row = rows.iter().find(|r| r.0 == "idle").unwrap();
    assert!(idle_row.1.is_nan(), "false contact on the true idle field");
    // What --field-out writes, --field-in reads (a lost marker's x, y empty).
    let (own, own_field, back) = (
        root.join("own.csv"),
        root.join("own"),
        root.join("back.csv"),
    );
    let two_frames = |out: &Path, flag: &str| {
        let r = run(&[
            "analyze",
            "--rest",
            rest.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            flag,
            own_field.to_str().unwrap(),
            frames.join("press_0.png").to_str().unwrap(),
            frames.join("idle.png").to_str().unwrap(),
        ]);
        assert!(
            r.status.success(),
            "{flag}: {}",
            String::from_utf8_lossy(&r.stderr)
        );
    };
    two_frames(&own, "--field-out");
    two_frames(&back, "--field-in");
    let ((_, a), (_, b)) = (read_csv(&own), read_csv(&back));
    assert_eq!(a.len(), 2);
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.0, y.0);
        assert_eq!(x.1.is_nan(), y.1.is_nan(), "{x:?} vs {y:?}");
        if x.1.is_finite() {
            assert!((x.1 - y.1).hypot(x.2 - y.2) < 2.5, "{x:?} vs {y:?}");
        }
    }
}
