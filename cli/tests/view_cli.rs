//! The live view from the command line: headless snapshots of a short
//! simulated run and of `dexitac view --render`, clear messages without a
//! display, and (when `Xvfb` is installed) the real window.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

use dexitac_view::draw::{INFLATE_COLOUR, NO_FRAME, POSITIVE_TANK_COLOUR};
use dexitac_view::layout::Rect;
use dexitac_view::Layout;

#[path = "../../tests/support/required.rs"]
mod required;

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
    std::fs::write(
        &path,
        "[scenario]\nname = \"view-test\"\nduration_s = 5.0\n",
    )
    .unwrap();
    path
}

#[test]
fn sim_writes_dashboard_snapshots_headless() {
    let dir = tempfile::tempdir().unwrap();
    let snaps = dir.path().join("snaps");
    let out = dir.path().join("out");
    let o = dexitac()
        .env_remove("DISPLAY")
        // Virtual time: no window, so nothing needs real time.
        .args(["sim", "--speed", "max"])
        .args(["--scenario", short_scenario(dir.path()).to_str().unwrap()])
        .args(["--out", out.to_str().unwrap()])
        .args(["--snapshot", snaps.to_str().unwrap()])
        .args(["--snapshot-every-s", "1"])
        .args(["--record", dir.path().join("run.mcap").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    // The recorder on the same event tap still got every observation.
    let all = format!("{}{}", String::from_utf8_lossy(&o.stdout), stderr(&o));
    let recorded: u64 = all
        .split("recorded ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or(0);
    // Every observation the rig made (`frames` in its summary).
    let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
    let frames: u64 = summary
        .split("\"frames\":")
        .nth(1)
        .and_then(|r| r.trim_start().split([',', '}', '\n']).next())
        .and_then(|n| n.trim().parse().ok())
        .expect("frames in summary.json");
    assert!(frames > 20, "{summary}");
    assert_eq!(recorded, frames, "{all}");
    let files = pngs(&snaps);
    // One per simulated second (the run ends at 5 s) and one at the end.
    assert!(files.len() >= 5, "{files:?}\n{}", stderr(&o));
    let first = files[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(first.starts_with("view_0001."), "{first}");
    let last = image::open(files.last().unwrap()).unwrap().into_rgb8();
    assert_eq!(last.dimensions(), (1280, 720));
    // By the end the tanks were charged and the fingers closing: the frame
    // panels show frames, the positive tank has a curve, and chamber 0's
    // lane (a grasping chamber) shows the inflation the MCU reported.
    let layout = Layout;
    let frame_px = *last.get_pixel(10, 40);
    assert_ne!(frame_px, NO_FRAME, "no frame drawn");
    let has = |r: Rect, c: image::Rgb<u8>| {
        (r.y..r.y + r.h).any(|y| (r.x..r.x + r.w).any(|x| *last.get_pixel(x as u32, y as u32) == c))
    };
    assert!(has(layout.pressure_chart(), POSITIVE_TANK_COLOUR));
    assert!(
        has(layout.lane(1), INFLATE_COLOUR),
        "chamber 0 never inflated"
    );
    assert!(
        !has(layout.lane(3), INFLATE_COLOUR),
        "chamber 2 is not a grasping chamber"
    );
    // The run's own outputs are still written.
    assert!(out.join("summary.json").exists());
    assert!(stderr(&o).contains("snapshot(s)"), "{}", stderr(&o));
}

#[test]
fn view_render_headless_runs_the_pipeline_and_algorithm_1() {
    let dir = tempfile::tempdir().unwrap();
    let o = dexitac()
        .env_remove("DISPLAY")
        .args(["view", "--render", "--headless", "--duration-s", "6"])
        .args(["--snapshot", dir.path().to_str().unwrap()])
        .args(["--snapshot-every-s", "5"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let files = pngs(dir.path());
    // One at 5 s (the first event at or after it), one at the end (6 s).
    assert_eq!(files.len(), 2, "{files:?}\n{}", stderr(&o));
    let first = files[0].file_name().unwrap().to_string_lossy().into_owned();
    assert!(first.starts_with("view_0005."), "{first}");
    // The steady simulated press has been still for 3 s by then: Algorithm
    // 1 sealed (the status line's phase box is the HOLDING colour).
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
    // A frame that is not an image: reported, exit 1, the snapshots written.
    let frames = dir.path().join("frames");
    std::fs::create_dir(&frames).unwrap();
    let sensor = dexitac_tactile::synth::Category::Nominal.sensor(640, 480, 1);
    let rest = dexitac_tactile::synth::rest_frame(&sensor, 2).image;
    image::GrayImage::from_raw(640, 480, rest.data().to_vec())
        .unwrap()
        .save(frames.join("0_rest.png"))
        .unwrap();
    std::fs::write(frames.join("1_broken.png"), b"not a png").unwrap();
    let snaps = dir.path().join("snaps");
    let o = dexitac()
        .env_remove("DISPLAY")
        .args(["view", "--headless", "--snapshot", snaps.to_str().unwrap()])
        .args(["--frames", frames.to_str().unwrap()])
        .output()
        .unwrap();
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("1_broken.png") && !e.contains("panicked"), "{e}");
    // The view still wrote its final picture (the run FAILED on it).
    assert_eq!(pngs(&snaps).len(), 1, "{e}");
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

/// The variable that makes the window tests required (`.ci/run` sets it
/// and installs Xvfb and xdotool).
const REQUIRE_WINDOW_TESTS: &str = "DEXITAC_REQUIRE_WINDOW_TESTS";

/// The one way out of a window test that cannot run: fails under
/// [`REQUIRE_WINDOW_TESTS`], otherwise says "skipped" on stderr
/// (`tests/support/required.rs`).
fn skip(why: &str) {
    required::skip(REQUIRE_WINDOW_TESTS, "the window tests", why);
}

/// What a window test needs, or [`skip`] with the reason it cannot run.
/// Helpers return `Err(reason)` for every way they can fail to set up, so
/// no early return (`?`) can pass a test that ran nothing.
fn or_skip<T>(ready: Result<T, String>) -> Option<T> {
    ready.map_err(|why| skip(&why)).ok()
}

#[test]
fn a_window_test_that_cannot_run_fails_only_when_required() {
    required::check_verdicts(REQUIRE_WINDOW_TESTS);
}

/// `program` on `PATH`, or why the test cannot run without it.
fn needs(program: &str, what_for: &str) -> Result<(), String> {
    if on_path(program) {
        Ok(())
    } else {
        Err(format!("{program} is not installed ({what_for})"))
    }
}

/// Starts Xvfb on a free display. The window tests run in parallel in one
/// process: each takes its own display number (a process-wide counter), as
/// two tests that both saw the same number free would share one server,
/// and the first to finish would kill the other's display. A number another
/// process took meanwhile makes Xvfb exit at once: the next one is tried.
fn start_xvfb() -> Result<Xvfb, String> {
    static NEXT: AtomicU32 = AtomicU32::new(0);
    needs("Xvfb", "apt-get install xvfb to run this test")?;
    let base = 100 + std::process::id() % 300;
    let mut last_failure = String::from("no free X display number in :100..:699");
    for _ in 0..20 {
        let n = base + NEXT.fetch_add(1, Ordering::Relaxed) % 300;
        let socket = format!("/tmp/.X11-unix/X{n}");
        if Path::new(&socket).exists() || Path::new(&format!("/tmp/.X{n}-lock")).exists() {
            continue;
        }
        let display = format!(":{n}");
        let child = Command::new("Xvfb")
            .args([&display, "-screen", "0", "1400x900x24", "-nolisten", "tcp"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| format!("Xvfb did not start: {e}"))?;
        let mut xvfb = Xvfb { child, display };
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            if let Ok(Some(status)) = xvfb.child.try_wait() {
                last_failure = format!("Xvfb exited at start-up on :{n} ({status})");
                break;
            }
            if Path::new(&socket).exists() {
                return Ok(xvfb);
            }
            if Instant::now() > deadline {
                return Err(format!("Xvfb did not open {socket} within 10 s"));
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    Err(last_failure)
}

#[test]
fn real_window_under_xvfb_shows_the_run_and_closes_on_ctrl_c() {
    let Some(x) = or_skip(start_xvfb()) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let snaps = dir.path().join("snaps");
    let log = dir.path().join("stderr.txt");
    let child = dexitac()
        .env("DISPLAY", &x.display)
        .args(["view", "--render", "--duration-s", "2"])
        .args(["--snapshot", snaps.to_str().unwrap()])
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .unwrap();
    let mut guard = Killed(child);
    let child = &mut guard.0;
    // The frames end after 2 s; the window then lingers until Ctrl-C.
    let deadline = Instant::now() + Duration::from_secs(60);
    while pngs(&snaps).is_empty() && Instant::now() < deadline {
        if let Ok(Some(status)) = child.try_wait() {
            panic!("dexitac view exited early: {status}");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(!pngs(&snaps).is_empty(), "no snapshot within 60 s");
    std::thread::sleep(Duration::from_millis(500));
    assert!(
        child.try_wait().unwrap().is_none(),
        "the window should linger"
    );
    // SAFETY: kill only sends a signal to our own child's pid.
    unsafe {
        libc::kill(child.id() as i32, libc::SIGINT);
    }
    let status = child.wait().unwrap();
    let e = std::fs::read_to_string(&log).unwrap();
    assert!(status.success(), "{e}");
    // The window drew frames (not just the snapshots).
    assert!(e.contains("live view drew"), "{e}");
}

fn on_path(program: &str) -> bool {
    std::env::var_os("PATH")
        .is_some_and(|p| std::env::split_paths(&p).any(|d| d.join(program).is_file()))
}

#[test]
fn closing_the_sim_window_stops_the_run_safely() {
    let ready = needs("xdotool", "it presses Esc in the window").and_then(|()| start_xvfb());
    let Some(x) = or_skip(ready) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let scenario = dir.path().join("long.toml");
    std::fs::write(
        &scenario,
        "[scenario]\nname = \"view-long\"\nduration_s = 120.0\n",
    )
    .unwrap();
    let out = dir.path().join("out");
    // stderr to a file: the status line would fill a pipe nobody reads.
    let log = dir.path().join("stderr.txt");
    let child = dexitac()
        .env("DISPLAY", &x.display)
        .args(["sim", "--view", "--host-silence-ms", "10000"])
        .args(["--scenario", scenario.to_str().unwrap()])
        .args(["--out", out.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(&log).unwrap())
        .spawn()
        .unwrap();
    let mut child = Killed(child);
    let started = Instant::now();
    let xdotool = |args: &[&str]| {
        Command::new("xdotool")
            .env("DISPLAY", &x.display)
            .args(args)
            .output()
            .unwrap()
    };
    std::thread::sleep(Duration::from_secs(3));
    // Press Esc in the window until the process ends (key events can be
    // lost while the window maps; there is no window manager).
    let status = loop {
        if let Some(status) = child.0.try_wait().unwrap() {
            break status;
        }
        assert!(
            started.elapsed() < Duration::from_secs(90),
            "still running: {}",
            std::fs::read_to_string(&log).unwrap_or_default()
        );
        let found = xdotool(&["search", "--name", "dexitac sim"]);
        if let Some(id) = String::from_utf8_lossy(&found.stdout).lines().next() {
            xdotool(&["windowfocus", id]);
            xdotool(&["key", "--window", id, "Escape"]);
        }
        std::thread::sleep(Duration::from_secs(1));
    };
    let e = std::fs::read_to_string(&log).unwrap();
    assert!(status.success(), "{e}");
    assert!(
        e.contains("the run stopped: valves sealed, MCU disarmed"),
        "{e}"
    );
    // Stopped long before the scenario's 120 s, with its results written.
    assert!(started.elapsed() < Duration::from_secs(90));
    assert!(out.join("summary.json").exists());
}

/// A child process killed on drop (a failed test leaves nothing running).
struct Killed(std::process::Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}
