//! Round trip, replay and damaged-file tests of the recorder and reader
//! (`dexitac_rig::recording`), on frames of the simulated fingertip.

use std::io::Cursor;
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use dexitac_protocol::{
    ArmState, FaultFlags, HostMsg, Telemetry, ValveState, CHAMBER_COUNT, NO_READING_PA,
};

use dexitac_gripper::grasp::{Cause, Command, Decision};
use dexitac_gripper::manipulation::TaskEvent;
use dexitac_rig::event::{RuntimeEvent, StopReason};
use dexitac_rig::recording::*;
use dexitac_sim::plant::ContactState;
use dexitac_sim::render::Renderer;
use dexitac_tactile::calibrate;
use dexitac_tactile::frame::GreyFrame;
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::synth::SensorSpec;

const START_NS: u64 = 1_700_000_000_000_000_000;

/// Rest frames and pressed frames of one simulated fingertip, the contact
/// moving 0.5 mm per frame.
fn frames(seed: u64, n: usize) -> (Vec<GreyFrame>, Vec<GreyFrame>) {
    let mut r = Renderer::new(
        SensorSpec::nominal(640, 480),
        Params::default().frame.mm_per_px,
        seed,
    );
    let rest = vec![r.render(None), r.render(None)];
    let pressed = (0..n)
        .map(|i| {
            r.render(Some(&ContactState {
                centre_mm: [0.5 * i as f64, -1.0],
                shear_mm: [0.0, 0.0],
                normal_n: 1.5,
                width_mm: 2.5,
            }))
        })
        .collect();
    (rest, pressed)
}

fn telemetry(i: u32) -> Telemetry {
    let mut chambers = [ValveState::Hold; CHAMBER_COUNT];
    chambers[0] = ValveState::Inflate;
    chambers[1] = ValveState::Deflate;
    Telemetry {
        time_ms: 20 * i,
        positive_tank_pa: 40_000 + i as i32,
        negative_tank_pa: if i == 0 { NO_READING_PA } else { -45_000 },
        chambers,
        positive_pump_on: true,
        negative_pump_on: i % 2 == 0,
        state: ArmState::Armed,
        faults: FaultFlags(0),
        loop_overruns: i,
    }
}

/// A recording of sensor 0's frames (pipeline results through the
/// lower-level API) and one of each other event.
fn record(
    frame_every: u32,
) -> (
    Vec<u8>,
    Vec<GreyFrame>,
    Vec<dexitac_tactile::pipeline::FrameResult>,
) {
    let params = Params::default();
    let (rest, pressed) = frames(3, 4);
    let pipeline = Pipeline::new(calibrate::calibrate(&rest, &params).unwrap(), params);
    let options = RecordOptions {
        source: "test".into(),
        frame_every,
        ..RecordOptions::default()
    };
    let mut rec = Recorder::with_start(Cursor::new(Vec::new()), options, START_NS).unwrap();
    rec.write_rest(0, &rest).unwrap();
    let mut results = Vec::new();
    for (i, f) in pressed.iter().enumerate() {
        let result = pipeline.run(f).unwrap();
        rec.write_frame_result(0, 100 + 33 * i as u64, f, &pipeline, &result)
            .unwrap();
        results.push(result);
    }
    let events = [
        RuntimeEvent::Decision {
            t_ms: 250,
            decision: Decision {
                t_ms: 199,
                command: Command::ReopenInflation,
                cause: Cause::Disturbance {
                    sensor: 0,
                    frame_shift_mm: 0.75,
                    anchored_shift_mm: 1.25,
                },
            },
        },
        RuntimeEvent::CommandSent {
            t_ms: 251,
            msg: HostMsg::SealAll,
            reason: "stable: seal",
            from_frame: Some(Duration::from_micros(1_500)),
        },
        RuntimeEvent::Telemetry {
            t_ms: 260,
            telemetry: telemetry(0),
        },
        RuntimeEvent::Telemetry {
            t_ms: 280,
            telemetry: telemetry(1),
        },
        RuntimeEvent::Task {
            t_ms: 300,
            event: TaskEvent::Completed,
        },
        RuntimeEvent::Stopped {
            t_ms: 400,
            max_loop_gap: Duration::from_millis(12),
            outcome: Ok(StopReason::Requested),
        },
    ];
    for e in &events {
        rec.write_event(e).unwrap();
    }
    let (stats, cursor) = rec.finish_into_inner().unwrap();
    assert_eq!(stats.observations, 4);
    assert_eq!(stats.bytes as usize, cursor.get_ref().len());
    (cursor.into_inner(), pressed, results)
}

fn read(bytes: &[u8]) -> Result<Recording, ReadError> {
    Recording::from_bytes(Path::new("test.mcap"), bytes, false)
}

#[test]
fn round_trip_keeps_frames_byte_for_byte_and_every_value() {
    let (bytes, pressed, results) = record(1);
    let rec = read(&bytes).unwrap();
    assert_eq!(rec.damage, None);
    let session = rec.session.as_ref().unwrap();
    assert_eq!(session.start_unix_ns, START_NS);
    assert_eq!(session.source, "test");
    assert_eq!(rec.rest[&0].len(), 2);
    assert_eq!(rec.frames.len(), pressed.len());
    for (i, (f, original)) in rec.frames.iter().zip(&pressed).enumerate() {
        assert_eq!(f.t_ms, 100 + 33 * i as u64);
        let back = f.decode().unwrap();
        assert_eq!((back.width(), back.height()), (640, 480));
        assert_eq!(back.data(), original.data(), "frame {i} differs");
    }
    assert_eq!(rec.contacts.len(), results.len());
    let mut found = 0;
    for (c, r) in rec.contacts.iter().zip(&results) {
        assert_eq!(c.found, r.contact.is_some());
        assert_eq!(c.markers, r.markers.positions().len());
        if let Some(contact) = r.contact {
            found += 1;
            let p = c.centre_px.unwrap();
            // Exact: JSON numbers round-trip f64 bit for bit.
            assert_eq!((p.x, p.y), (contact.centre.x, contact.centre.y));
            assert_eq!(c.area_mm2, Some(contact.area_mm2));
        }
    }
    assert!(
        found >= 3,
        "the pressed frames show a contact ({found} of 4)"
    );
    let d = &rec.decisions[0];
    assert_eq!(
        (d.t_ms, d.decided_t_ms, d.command.as_str(), d.cause.as_str()),
        (250, 199, "reopen_inflation", "disturbance")
    );
    assert_eq!(
        (d.frame_shift_mm, d.anchored_shift_mm),
        (Some(0.75), Some(1.25))
    );
    let c = &rec.commands[0];
    assert_eq!(
        (c.kind.as_str(), c.reason.as_str()),
        ("SealAll", "stable: seal")
    );
    assert_eq!(c.from_frame_ms, Some(1.5));
    let t = &rec.telemetry;
    assert_eq!(t.len(), 2);
    assert_eq!(t[0].positive_tank_kpa, Some(40.0));
    assert_eq!(t[0].negative_tank_kpa, None, "no reading stays no reading");
    assert_eq!(t[1].negative_tank_kpa, Some(-45.0));
    assert_eq!(t[0].valve_codes[..3], [1, -1, 0]);
    assert_eq!(t[0].valves[0], "inflate");
    assert_eq!(t[1].state, "Armed");
    assert_eq!(rec.tasks[0].kind, "completed");
    assert!(rec.stopped[0].ok);
    assert_eq!(rec.stopped[0].max_loop_gap_ms, 12.0);
    assert_eq!(rec.annotations[&0].len(), 4);
    assert_eq!(
        rec.topics["/sensor0/image"].schema,
        "foxglove.CompressedImage"
    );
    assert_eq!(rec.topics["/sensor0/contact"].messages, 4);
}

#[test]
fn frame_decimation_keeps_every_contact() {
    let (bytes, _, _) = record(3);
    let rec = read(&bytes).unwrap();
    assert_eq!(rec.frames.len(), 2, "observations 0 and 3 of 4");
    assert_eq!(rec.contacts.len(), 4);
    assert_eq!(rec.session.unwrap().frame_every, 3);
}

#[test]
fn replay_reproduces_the_recorded_centres_exactly() {
    let (bytes, _, _) = record(1);
    let rec = read(&bytes).unwrap();
    let out = replay::replay(&rec, &Params::default(), 1).unwrap();
    let s = &out.summary;
    assert_eq!(s.frames, 4);
    assert_eq!(s.unmatched, 0);
    assert_eq!(s.disagreements, 0);
    assert!(s.both_found >= 3);
    assert_eq!(s.max_px, 0.0);
    assert!(s.within(0.0));
    assert!(s.calibrated_on[0].1.contains("2 recorded rest"));
}

#[test]
fn replay_with_other_parameters_reports_the_difference() {
    let (bytes, _, _) = record(1);
    let rec = read(&bytes).unwrap();
    let mut params = Params::default();
    params.density.kernel_width_px *= 1.6;
    let out = replay::replay(&rec, &params, 1).unwrap();
    assert!(
        !out.summary.within(0.0),
        "a wider kernel moves the centres: {:?}",
        out.summary
    );
}

#[test]
fn replay_source_plays_one_sensor_in_order() {
    use dexitac_rig::source::{Clock, FrameSource};
    let (bytes, pressed, _) = record(1);
    let rec = read(&bytes).unwrap();
    let mut src = ReplaySource::new(&rec, 0, false);
    let clock = Clock::wall();
    let mut n = 0;
    while let Some(f) = src.next_frame(&clock).unwrap() {
        assert_eq!(f.t_ms, 100 + 33 * n as u64);
        assert_eq!(f.frame.data(), pressed[n].data());
        n += 1;
    }
    assert_eq!(n, 4);
    assert!(ReplaySource::new(&rec, 1, false)
        .next_frame(&clock)
        .unwrap()
        .is_none());
}

#[test]
fn truncated_file_is_an_error_and_recoverable() {
    let (bytes, _, _) = record(1);
    for cut in [bytes.len() - 1, bytes.len() * 2 / 3, bytes.len() / 3, 40] {
        let part = &bytes[..cut];
        match read(part) {
            Err(ReadError::Damaged { messages, .. }) => {
                let rec = Recording::from_bytes(Path::new("t.mcap"), part, true);
                match rec {
                    Ok(r) => {
                        assert!(r.damage.is_some());
                        assert!(r.contacts.len() <= 4);
                    }
                    // Cut before the session message: nothing to keep.
                    Err(ReadError::NotDexitac { .. }) => assert_eq!(messages, 0),
                    Err(e) => panic!("cut at {cut}: recover failed: {e}"),
                }
            }
            other => panic!("cut at {cut}: expected Damaged, got {other:?}"),
        }
    }
}

#[test]
fn garbage_and_corrupt_files_are_errors_not_panics() {
    assert!(matches!(read(b""), Err(ReadError::NotMcap { .. })));
    assert!(matches!(
        read(b"not an mcap file at all"),
        Err(ReadError::NotMcap { .. })
    ));
    let (bytes, _, _) = record(1);
    // Flip bytes across the file: each must give an error or a readable
    // recording, never a panic or an abort. (A flip on a record length
    // inside a zstd chunk once made mcap reserve 93 TB; the chunks are now
    // checked first, and 600 places are tried.)
    for at in (8..bytes.len()).step_by(bytes.len() / 600 + 1) {
        let mut bad = bytes.clone();
        bad[at] ^= 0x5a;
        let _ = read(&bad);
        let _ = Recording::from_bytes(Path::new("t.mcap"), &bad, true);
    }
}

#[test]
fn missing_file_names_the_path() {
    let e = Recording::open(Path::new("/nonexistent/x.mcap"), false).unwrap_err();
    assert!(e.to_string().contains("/nonexistent/x.mcap"), "{e}");
}

#[test]
fn spawned_recorder_writes_a_channel_of_events() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("events.mcap");
    let rec = Recorder::create(&path, RecordOptions::default()).unwrap();
    let thread = rec.spawn();
    let tx = thread.sender();
    let (_, pressed) = frames(5, 1);
    tx.send(RuntimeEvent::Observation(
        dexitac_rig::event::SensorReport {
            sensor: 1,
            t_ms: 7,
            centre_mm: None,
            markers: Arc::new(vec![dexitac_tactile::PointPx::new(1.234_567, 2.0)]),
            pipeline_ms: 3.0,
            contact: None,
            frame: Some(Arc::new(pressed[0].clone())),
        },
    ))
    .unwrap();
    drop(tx);
    let stats = thread.finish().unwrap();
    assert_eq!((stats.observations, stats.frames), (1, 1));
    let rec = Recording::open(&path, false).unwrap();
    assert_eq!(rec.frames[0].sensor, 1);
    assert_eq!(rec.frames[0].t_ms, 7);
    // Foxglove's origin is the top-left pixel's corner: centre 1.234 -> 1.73.
    assert_eq!(rec.annotations[&1][0].points[0].points[0].x, 1.73);
    assert_eq!(rec.annotations[&1][0].points[0].points[0].y, 2.5);
    assert!(!rec.contacts[0].found);
}

#[test]
fn paced_replay_waits_for_the_recorded_times() {
    use dexitac_rig::source::{Clock, FrameSource};
    let (bytes, _, _) = record(1);
    let rec = read(&bytes).unwrap();
    // Frames at 100, 133, 166, 199 ms: paced, the last comes 99 ms of
    // clock time after the first (a lower bound: sleeps never end early).
    let clock = Clock::wall();
    let mut src = ReplaySource::new(&rec, 0, true);
    let mut times = Vec::new();
    while let Some(f) = src.next_frame(&clock).unwrap() {
        times.push(f.t_ms);
    }
    assert_eq!(times, [100, 133, 166, 199]);
    assert!(clock.now_ms() >= 99, "{} ms", clock.now_ms());
}

/// The subset of JSON Schema that Foxglove's schemas use: `type`,
/// `required`, `properties`, `items`, `minimum`, `maximum`, `oneOf` of
/// `const`s. Pushes what `value` breaks to `errors`.
fn check_schema(
    value: &serde_json::Value,
    schema: &serde_json::Value,
    path: &str,
    errors: &mut Vec<String>,
) {
    use serde_json::Value;
    if let Some(t) = schema.get("type").and_then(Value::as_str) {
        let ok = match t {
            "object" => value.is_object(),
            "array" => value.is_array(),
            "string" => value.is_string(),
            "integer" => value.is_i64() || value.is_u64(),
            "number" => value.is_number(),
            "boolean" => value.is_boolean(),
            _ => true,
        };
        if !ok {
            errors.push(format!("{path}: not a {t}: {value}"));
            return;
        }
    }
    if let Some(required) = schema.get("required").and_then(Value::as_array) {
        for key in required.iter().filter_map(Value::as_str) {
            if value.get(key).is_none() {
                errors.push(format!("{path}: missing {key}"));
            }
        }
    }
    if let Some(props) = schema.get("properties").and_then(Value::as_object) {
        for (key, sub) in props {
            if let Some(v) = value.get(key) {
                check_schema(v, sub, &format!("{path}.{key}"), errors);
            }
        }
    }
    if let (Some(items), Some(values)) = (schema.get("items"), value.as_array()) {
        for (i, v) in values.iter().enumerate() {
            check_schema(v, items, &format!("{path}[{i}]"), errors);
        }
    }
    if let Some(x) = value.as_f64() {
        if schema
            .get("minimum")
            .and_then(Value::as_f64)
            .is_some_and(|m| x < m)
            || schema
                .get("maximum")
                .and_then(Value::as_f64)
                .is_some_and(|m| x > m)
        {
            errors.push(format!("{path}: {x} out of range"));
        }
    }
    if let Some(options) = schema.get("oneOf").and_then(Value::as_array) {
        let consts: Vec<&Value> = options.iter().filter_map(|o| o.get("const")).collect();
        if !consts.is_empty() && !consts.contains(&value) {
            errors.push(format!("{path}: {value} is none of {consts:?}"));
        }
    }
}

/// Every `foxglove.*` message matches Foxglove's own JSON schema
/// (`sim/tests/data/foxglove/`, from `@foxglove/schemas` 2.1.0), so the
/// Foxglove app shows frames and annotations without setup.
#[test]
fn foxglove_messages_have_the_fields_foxglove_requires() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/foxglove");
    let schema = |name: &str| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(format!("{name}.json"))).unwrap())
            .unwrap()
    };
    let schemas = [
        ("foxglove.CompressedImage", schema("CompressedImage")),
        ("foxglove.ImageAnnotations", schema("ImageAnnotations")),
    ];
    // The checker itself catches a missing required field.
    let mut errors = Vec::new();
    check_schema(
        &serde_json::json!({"circles": [], "points": []}),
        &schemas[1].1,
        "probe",
        &mut errors,
    );
    assert_eq!(errors, ["probe: missing texts"]);

    let (bytes, _, _) = record(1);
    let mut checked = std::collections::BTreeMap::<String, usize>::new();
    let mut circles = 0;
    for message in mcap::MessageStream::new(&bytes).unwrap() {
        let message = message.unwrap();
        let Some(s) = message.channel.schema.as_ref() else {
            continue;
        };
        let Some((_, json_schema)) = schemas.iter().find(|(n, _)| *n == s.name) else {
            assert!(!s.name.starts_with("foxglove."), "unchecked {}", s.name);
            continue;
        };
        let value: serde_json::Value = serde_json::from_slice(&message.data).unwrap();
        circles += value["circles"].as_array().map_or(0, Vec::len);
        let mut errors = Vec::new();
        check_schema(&value, json_schema, &message.channel.topic, &mut errors);
        assert!(errors.is_empty(), "{errors:?}");
        *checked.entry(s.name.clone()).or_default() += 1;
    }
    assert!(checked["foxglove.CompressedImage"] >= 4, "{checked:?}");
    assert_eq!(checked["foxglove.ImageAnnotations"], 4, "{checked:?}");
    assert!(circles >= 1, "no contact circle to check");
}
