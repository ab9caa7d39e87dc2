//! Recording and replay end to end: a short simulated run recorded through
//! the sim's event tap and read by the `mcap` crate's own reader; `dexitac
//! record` over a folder of frames, `dexitac replay` on it, and on a
//! truncated copy.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::{Command, Output};

use dexitac::params::Params;
use dexitac::recording::{replay, topic, RecordOptions, Recorder, Recording};
use dexitac::sim::plant::{ContactState, FINGER_COUNT};
use dexitac::sim::render::Renderer;
use dexitac::sim::rig::{self, run_scenario, SimOptions};
use dexitac::sim::scenario::Scenario;
use dexitac::synth::SensorSpec;

#[test]
fn a_recorded_sim_run_is_readable_by_the_mcap_reader_and_replays_exactly() {
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
        speed: 2.0,
        seed,
        // A loaded two-core machine; the recording is under test here.
        stall_tolerance_ms: 10_000,
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
