//! Recording and replay end to end: a short simulated run recorded through
//! the sim's event tap and read by the `mcap` crate's own reader; `dexitac
//! record` over a folder of frames, `dexitac replay` on it, and on a
//! truncated copy; `dexitac run --record` on a simulated board, stopped by
//! Ctrl-C and killed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use dexitac_protocol::ValveState;
use dexitac_rig::recording::{replay, topic, ReadError, RecordOptions, Recorder, Recording};
use dexitac_sim::mcu::{SimMcu, SimMcuConfig};
use dexitac_sim::plant::{ContactState, FINGER_COUNT};
use dexitac_sim::render::Renderer;
use dexitac_sim::rig::{self, run_scenario, Pace, SimOptions};
use dexitac_sim::scenario::Scenario;
use dexitac_tactile::params::Params;
use dexitac_tactile::synth::SensorSpec;

/// One test at a time: they share two cores with real-time runs.
static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn serial() -> std::sync::MutexGuard<'static, ()> {
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

#[test]
fn a_recorded_sim_run_is_readable_by_the_mcap_reader_and_replays_exactly() {
    let _serial = serial();
    let mut scenario = Scenario::load("grasp-hold").expect("preset");
    // Charging takes ~2.5 s; closing and contact follow.
    scenario.duration_s = 5.0;
    let seed = 4;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sim.mcap");
    let params = Params::default();
    let mut recorder = Recorder::create(
        &path,
        RecordOptions {
            source: "sim".into(),
            ..RecordOptions::default()
        },
    )
    .unwrap();
    for finger in 0..FINGER_COUNT {
        recorder
            .write_rest(finger, &rig::rest_frames(finger, &params, seed))
            .unwrap();
    }
    let thread = recorder.spawn();
    let options = SimOptions {
        speed: Pace::Max,
        seed,
        event_tap: Some(thread.sender()),
        share_frames: true,
        ..SimOptions::default()
    };
    let report = run_scenario(&scenario, &options).expect("simulated rig");
    drop(options);
    let stats = thread.finish().unwrap();
    assert!(report.loop_result.is_ok(), "{:?}", report.loop_result);

    // The mcap crate's reader: summary, schemas, per-channel counts.
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes)
        .expect("summary")
        .expect("a finished file has a summary");
    let stats_rec = summary.stats.as_ref().expect("statistics");
    let mut counts: BTreeMap<String, (String, u64)> = BTreeMap::new();
    for (id, channel) in &summary.channels {
        let schema = channel
            .schema
            .as_ref()
            .map(|s| s.name.clone())
            .unwrap_or_default();
        assert_eq!(channel.message_encoding, "json");
        let n = stats_rec
            .channel_message_counts
            .get(id)
            .copied()
            .unwrap_or(0);
        counts.insert(channel.topic.clone(), (schema, n));
    }
    for s in summary.schemas.values() {
        assert_eq!(s.encoding, "jsonschema", "{}", s.name);
        let _: serde_json::Value = serde_json::from_slice(&s.data).expect("schema is JSON");
    }
    let count = |t: &str| counts.get(t).map_or(0, |c| c.1);
    let schema = |t: &str| counts.get(t).map(|c| c.0.as_str()).unwrap_or("");
    for sensor in 0..FINGER_COUNT {
        let observed = report
            .observations
            .iter()
            .filter(|o| o.sensor == sensor)
            .count() as u64;
        assert!(observed > 5, "sensor {sensor}: {observed} observations");
        assert_eq!(count(&topic::contact(sensor)), observed);
        assert_eq!(count(&topic::image(sensor)), observed);
        assert_eq!(count(&topic::annotations(sensor)), observed);
        assert_eq!(count(&topic::rest(sensor)), 2);
        assert_eq!(schema(&topic::image(sensor)), "foxglove.CompressedImage");
        assert_eq!(schema(&topic::rest(sensor)), "foxglove.CompressedImage");
        assert_eq!(
            schema(&topic::annotations(sensor)),
            "foxglove.ImageAnnotations"
        );
        assert_eq!(schema(&topic::contact(sensor)), "dexitac.Contact");
    }
    assert_eq!(count(topic::COMMAND), report.commands.len() as u64);
    assert_eq!(count(topic::DECISION), report.decisions.len() as u64);
    assert!(count(topic::TELEMETRY) > 10);
    assert_eq!(schema(topic::TELEMETRY), "dexitac.Telemetry");
    assert_eq!(count(topic::STOPPED), 1);
    assert_eq!(count(topic::SESSION), 1);
    assert_eq!(
        stats_rec.message_count,
        stats.messages.values().sum::<u64>()
    );

    // Our reader and the replay: same centres, bit for bit.
    let rec = Recording::open(&path, false).unwrap();
    for (c, o) in rec.contacts.iter().zip(&report.observations) {
        assert_eq!((c.sensor, c.t_ms), (o.sensor, o.t_ms));
        assert_eq!(
            c.centre_mm.map(|p| (p.x, p.y)),
            o.centre_mm.map(|m| (m.x_mm, m.y_mm))
        );
    }
    assert!(rec.contacts.iter().any(|c| c.found), "the fingers touched");
    let out = replay::replay(&rec, &params, 1).unwrap();
    assert_eq!(out.summary.frames, report.observations.len());
    assert!(out.summary.both_found > 0);
    assert!(out.summary.within(0.0), "{:?}", out.summary);
}

fn dexitac(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dexitac"))
        .args(args)
        .output()
        .expect("run dexitac")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// A rest frame and `n` pressed frames of a simulated fingertip as PNGs.
fn frame_dir(dir: &Path, seed: u64, n: usize) {
    std::fs::create_dir_all(dir).unwrap();
    let mut r = Renderer::new(SensorSpec::nominal(640, 480), 0.1, seed);
    for i in 0..=n {
        let contact = (i > 0).then_some(ContactState {
            centre_mm: [0.4 * i as f64, 0.5],
            shear_mm: [0.0, 0.0],
            normal_n: 1.5,
            width_mm: 2.5,
        });
        let f = r.render(contact.as_ref());
        image::GrayImage::from_raw(f.width() as u32, f.height() as u32, f.data().to_vec())
            .unwrap()
            .save(dir.join(format!("f{i:03}.png")))
            .unwrap();
    }
}

#[test]
fn record_then_replay_on_the_command_line_and_a_truncated_file() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    frame_dir(&a, 1, 3);
    frame_dir(&b, 2, 3);
    let out = dir.path().join("rec.mcap");
    let o = dexitac(&[
        "record",
        "--out",
        out.to_str().unwrap(),
        "--frames",
        a.to_str().unwrap(),
        "--frames",
        b.to_str().unwrap(),
        "--fps",
        "100",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("6 observation(s), 6 frame(s)"),
        "{}",
        text(&o)
    );

    let csv = dir.path().join("cmp.csv");
    let o = dexitac(&[
        "replay",
        out.to_str().unwrap(),
        "--out",
        csv.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(text(&o).contains("reproduces"), "{}", text(&o));
    let rows = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(rows.lines().count(), 7, "{rows}");
    assert!(
        rows.lines().skip(1).all(|l| l.ends_with(",agree")),
        "{rows}"
    );

    // The recording as a frame source: recorded again from its own frames
    // (rest frames and all), the copy replays the same way.
    let again = dir.path().join("again.mcap");
    let o = dexitac(&[
        "record",
        "--out",
        again.to_str().unwrap(),
        "--recording",
        out.to_str().unwrap(),
        "--max-speed",
    ]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    assert!(
        text(&o).contains("6 observation(s), 6 frame(s)"),
        "{}",
        text(&o)
    );
    let o = dexitac(&["replay", again.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(0), "{}", text(&o));
    let (first, copy) = (
        Recording::open(&out, false).unwrap(),
        Recording::open(&again, false).unwrap(),
    );
    // Same frames per sensor (the file interleaves the two sensors in
    // arrival order, which may differ between the runs).
    fn frames(r: &Recording) -> Vec<(usize, u64, &[u8])> {
        let mut f: Vec<(usize, u64, &[u8])> = r
            .frames
            .iter()
            .map(|f| (f.sensor, f.t_ms, f.png.as_slice()))
            .collect();
        f.sort_by_key(|f| (f.0, f.1));
        f
    }
    assert_eq!(first.frames.len(), 6);
    assert!(frames(&first) == frames(&copy), "the frames differ");
    assert!(first.rest == copy.rest, "the rest frames differ");
    let centres = |r: &Recording| {
        r.contacts
            .iter()
            .map(|c| (c.sensor, c.t_ms, c.centre_px))
            .collect::<Vec<_>>()
    };
    let (mut c1, mut c2) = (centres(&first), centres(&copy));
    c1.sort_by_key(|c| (c.0, c.1));
    c2.sort_by_key(|c| (c.0, c.1));
    assert_eq!(c1.len(), 6);
    assert_eq!(c1, c2);

    // Other parameters: the replay differs and says so with exit status 1.
    let config = dir.path().join("wide.toml");
    std::fs::write(&config, "[density]\nkernel_width_px = 24.0\n").unwrap();
    let o = dexitac(&[
        "replay",
        out.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(1), "{}", text(&o));
    assert!(text(&o).contains("DIFFERS"), "{}", text(&o));

    // A truncated copy: a clear error, then what --recover keeps.
    let bytes = std::fs::read(&out).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 4]).unwrap();
    let o = dexitac(&["replay", cut.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(text(&o).contains("damaged or unfinished"), "{}", text(&o));
    assert!(text(&o).contains("--recover"), "{}", text(&o));
    assert!(!text(&o).contains("panicked"), "{}", text(&o));
    let o = dexitac(&["replay", cut.to_str().unwrap(), "--recover"]);
    assert!(!text(&o).contains("panicked"), "{}", text(&o));
    assert!(text(&o).contains("warning"), "{}", text(&o));

    let o = dexitac(&["replay", dir.path().join("missing.mcap").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).contains("missing.mcap"), "{}", text(&o));
    let o = dexitac(&["replay", config.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).contains("not an MCAP file"), "{}", text(&o));
}

/// Kills the child on drop, whatever the test does.
struct Child(std::process::Child);

impl Drop for Child {
    fn drop(&mut self) {
        if self.0.kill().is_ok() {
            let _ = self.0.wait();
        }
    }
}

/// `dexitac run --render --record FILE --record-frames` on a simulated
/// board, until it has closed the fingers for `after_closing`.
fn recorded_run(dir: &Path, after_closing: Duration, extra: &[&str]) -> (SimMcu, Child, PathBuf) {
    let mcu = SimMcu::spawn(SimMcuConfig {
        // A busy two-core machine may stall the host; the recording is
        // under test here, the silence trip in sim_safety.rs.
        firmware: dexitac_firmware::Config {
            host_silence_ms: 10_000,
            ..dexitac_firmware::Config::default()
        },
        ..SimMcuConfig::default()
    })
    .expect("simulated MCU");
    let config = dir.join("gripper.toml");
    std::fs::write(&config, "# defaults\n").unwrap();
    let file = dir.join("run.mcap");
    let child = Child(
        Command::new(env!("CARGO_BIN_EXE_dexitac"))
            .args([
                "run",
                "--render",
                "--record-frames",
                "--fps",
                "15",
                "--port",
            ])
            .arg(mcu.port_path())
            .arg("--config")
            .arg(&config)
            .arg("--record")
            .arg(&file)
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("spawn dexitac run"),
    );
    let until = Instant::now() + Duration::from_secs(60);
    while !mcu.snapshot().chambers.contains(&ValveState::Inflate) {
        assert!(Instant::now() < until, "the host never closed the fingers");
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(after_closing);
    (mcu, child, file)
}

/// Sends Ctrl-C to the child and waits for it to exit successfully.
fn interrupt(child: &mut Child) {
    let pid = i32::try_from(child.0.id()).expect("pid");
    // SAFETY: kill only sends a signal to our own child process.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGINT) }, 0);
    let until = Instant::now() + Duration::from_secs(20);
    let status = loop {
        if let Some(status) = child.0.try_wait().expect("wait") {
            break status;
        }
        assert!(Instant::now() < until, "dexitac run ignored Ctrl-C");
        std::thread::sleep(Duration::from_millis(5));
    };
    assert!(status.success(), "{status:?}");
}

/// `run` with the live view's snapshots and a recording at once: both get
/// every event (the recording replays exactly, the snapshots are written).
#[test]
fn run_records_and_snapshots_the_live_view_together() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let snaps = dir.path().join("snaps");
    let (_mcu, mut child, file) = recorded_run(
        dir.path(),
        Duration::from_millis(1_000),
        &[
            "--snapshot",
            snaps.to_str().unwrap(),
            "--snapshot-every-s",
            "0.5",
        ],
    );
    interrupt(&mut child);
    let rec = Recording::open(&file, false).expect("a finished recording");
    assert!(rec.frames.len() >= 4, "{} frames", rec.frames.len());
    assert_eq!(rec.stopped.len(), 1);
    let out = replay::replay(&rec, &Params::default(), 1).unwrap();
    assert!(out.summary.within(0.0), "{:?}", out.summary);
    let pngs = std::fs::read_dir(&snaps)
        .expect("the snapshot directory")
        .filter_map(Result::ok)
        .filter(|e| e.path().extension().is_some_and(|x| x == "png"))
        .count();
    assert!(pngs >= 2, "{pngs} snapshot(s)");
}

#[test]
fn run_records_until_ctrl_c_and_a_killed_run_leaves_a_recoverable_file() {
    let _serial = serial();
    let dir = tempfile::tempdir().unwrap();
    let (_mcu, mut child, file) = recorded_run(dir.path(), Duration::from_millis(700), &[]);
    interrupt(&mut child);
    let rec = Recording::open(&file, false).expect("a finished recording");
    assert_eq!(rec.session.as_ref().unwrap().source, "run");
    let reasons: Vec<&str> = rec.commands.iter().map(|c| c.reason.as_str()).collect();
    assert!(reasons.contains(&"close fingers"), "{reasons:?}");
    assert!(!rec.telemetry.is_empty());
    assert!(rec.telemetry.iter().any(|t| t.valve_codes.contains(&1)));
    assert_eq!(rec.stopped.len(), 1);
    assert!(rec.frames.len() >= 4, "{} frames", rec.frames.len());
    let out = replay::replay(&rec, &Params::default(), 1).unwrap();
    assert!(out.summary.within(0.0), "{:?}", out.summary);

    // Killed while recording: no summary; refused, then recovered.
    let dir = tempfile::tempdir().unwrap();
    let (_mcu, mut child, file) = recorded_run(dir.path(), Duration::from_millis(1_500), &[]);
    child.0.kill().expect("kill");
    let _ = child.0.wait();
    match Recording::open(&file, false) {
        Err(e @ ReadError::Damaged { .. }) => eprintln!("as expected: {e}"),
        other => panic!("expected Damaged, got {other:?}"),
    }
    let rec = Recording::open(&file, true).expect("recovered");
    assert!(rec.damage.is_some());
    assert!(
        !rec.frames.is_empty(),
        "whole chunks before the kill are kept"
    );
}
