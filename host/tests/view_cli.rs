//! The live view from the command line: headless snapshots of a short
//! simulated run and of `dexitac view --render`, clear messages without a
//! display, and (when `Xvfb` is installed) the real window.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

fn dexitac() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dexitac"))
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn pngs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .map(|r| r.filter_map(Result::ok).map(|e| e.path()).collect())
        .unwrap_or_default();
    v.retain(|p| p.extension().is_some_and(|e| e == "png"));
    v.sort();
    v
}

/// A short scenario: charge, close, hold.
fn short_scenario(dir: &Path) -> PathBuf {
    let path = dir.join("short.toml");
    std::fs::write(&path, "name = \"view-test\"\nduration_s = 5.0\n").unwrap();
    path
}

#[test]
fn sim_writes_dashboard_snapshots_headless() {
    let dir = tempfile::tempdir().unwrap();
    let snaps = dir.path().join("snaps");
    let out = dir.path().join("out");
    let o = dexitac()
        .env_remove("DISPLAY")
        .args(["sim", "--speed", "2", "--host-silence-ms", "10000"])
        .args(["--scenario", short_scenario(dir.path()).to_str().unwrap()])
        .args(["--out", out.to_str().unwrap()])
        .args(["--snapshot", snaps.to_str().unwrap()])
        .args(["--snapshot-every-s", "1"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let files = pngs(&snaps);
    // One per simulated second (the run ends at 5 s) and one at the end.
    assert!(files.len() >= 5, "{files:?}\n{}", stderr(&o));
    let first = files[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(first.starts_with("view_0001."), "{first}");
    let last = image::open(files.last().unwrap()).unwrap().into_rgb8();
    assert_eq!(last.dimensions(), (1280, 720));
    // By the end the tanks were charged and the fingers closed: the
    // positive tank lane is not empty, and the frame panels show frames.
    let frame_px = *last.get_pixel(10, 40);
    assert_ne!(frame_px, image::Rgb([28, 28, 34]), "no frame drawn");
    // The run's own outputs are still written.
    assert!(out.join("summary.json").exists());
    assert!(stderr(&o).contains("snapshot(s)"), "{}", stderr(&o));
}

#[test]
fn view_render_headless_runs_the_pipeline_and_algorithm_1() {
    let dir = tempfile::tempdir().unwrap();
    let o = dexitac()
        .env_remove("DISPLAY")
        .args(["view", "--render", "--headless", "--duration-s", "10"])
        .args(["--snapshot", dir.path().to_str().unwrap()])
        .args(["--snapshot-every-s", "5"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let files = pngs(dir.path());
    let names: Vec<_> = files
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    // Frames every 33 ms: the first frame at or after 5 s and 10 s; the
    // last (the end, 10.032 s) is also the final one.
    assert_eq!(
        names,
        ["view_0005.016s.png", "view_0010.032s.png"],
        "{}",
        stderr(&o)
    );
    // At 5 s the scripted press has been still for 4 s: Algorithm 1 sealed
    // (the status line's phase box is the HOLDING colour).
    let at_5s = image::open(&files[0]).unwrap().into_rgb8();
    let holding = image::Rgb([120, 200, 120]);
    let row: Vec<_> = (0..640).map(|x| *at_5s.get_pixel(x, 2)).collect();
    assert!(row.contains(&holding), "no HOLDING phase at 5 s");
}

#[test]
fn no_display_is_a_clear_message_before_anything_runs() {
    let started = Instant::now();
    let o = dexitac()
        .env_remove("DISPLAY")
        .args(["view", "--render"])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(
        e.contains("DISPLAY is not set") && e.contains("--headless --snapshot"),
        "{e}"
    );
    assert!(!e.contains("panicked"));
    let dir = tempfile::tempdir().unwrap();
    let o = dexitac()
        .env_remove("DISPLAY")
        .args(["sim", "--view", "--out", dir.path().to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = stderr(&o);
    assert!(e.contains("--snapshot DIR"), "{e}");
    // Refused before the 30 s scenario started.
    assert!(started.elapsed() < Duration::from_secs(20));
    assert!(!dir.path().join("summary.json").exists());
}

#[test]
fn bad_view_arguments_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    for args in [
        vec!["view", "--render", "--headless"],
        vec!["view", "--render", "--fps", "0"],
        vec!["view"],
        vec!["sim", "--snapshot", "x", "--snapshot-every-s", "NaN"],
    ] {
        let o = dexitac().args(&args).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(!stderr(&o).contains("panicked"));
    }
    // A folder without frames.
    let o = dexitac()
        .env_remove("DISPLAY")
        .args([
            "view",
            "--headless",
            "--snapshot",
            dir.path().to_str().unwrap(),
        ])
        .args(["--frames", dir.path().to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("rest frame"), "{}", stderr(&o));
}

/// An Xvfb server on a free display, killed on drop.
struct Xvfb {
    child: std::process::Child,
    display: String,
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn start_xvfb() -> Option<Xvfb> {
    let found = std::env::var_os("PATH")
        .is_some_and(|p| std::env::split_paths(&p).any(|d| d.join("Xvfb").is_file()));
    if !found {
        eprintln!("skipped: Xvfb is not installed (apt-get install xvfb to run this test)");
        return None;
    }
    let n = (100..400)
        .map(|k| k + std::process::id() % 300)
        .find(|n| !Path::new(&format!("/tmp/.X11-unix/X{n}")).exists())?;
    let display = format!(":{n}");
    let child = Command::new("Xvfb")
        .args([&display, "-screen", "0", "1400x900x24", "-nolisten", "tcp"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .ok()?;
    let xvfb = Xvfb { child, display };
    let socket = format!("/tmp/.X11-unix/X{n}");
    let deadline = Instant::now() + Duration::from_secs(10);
    while !Path::new(&socket).exists() {
        if Instant::now() > deadline {
            eprintln!("skipped: Xvfb did not start");
            return None;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    Some(xvfb)
}

#[test]
fn real_window_under_xvfb_shows_the_run_and_closes_on_ctrl_c() {
    let Some(x) = start_xvfb() else { return };
    let dir = tempfile::tempdir().unwrap();
    let mut child = dexitac()
        .env("DISPLAY", &x.display)
        .args(["view", "--render", "--duration-s", "2"])
        .args(["--snapshot", dir.path().to_str().unwrap()])
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The frames end after 2 s; the window then lingers until Ctrl-C.
    let deadline = Instant::now() + Duration::from_secs(60);
    while pngs(dir.path()).is_empty() && Instant::now() < deadline {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("dexitac view exited early: {status}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(!pngs(dir.path()).is_empty(), "no snapshot within 60 s");
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the window should linger"
    );
    // SAFETY: kill only sends a signal to our own child's pid.
    unsafe {
        libc::kill(child.id() as i32, libc::SIGINT);
    }
    let o = child.wait_with_output().unwrap();
    let e = stderr(&o);
    assert!(o.status.success(), "{e}");
    // The window drew frames (not just the snapshots).
    assert!(e.contains("live view drew"), "{e}");
}
