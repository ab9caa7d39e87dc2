//! Frame arrival -> command bytes written: the host's critical path, on the
//! same code the task loop runs (pipeline on a 640x480 frame, grasp state
//! machine, frame encoding, write to the serial port of the simulated MCU).
//!
//! Each sample: a grasp sealed on contact A (observations fed directly), then
//! one rendered frame arrives: either contact B (A + 1 mm: a disturbance,
//! answered by `SetChambers`) or, for a grasp one frame short of its stable
//! span, contact A again (answered by `SealAll`). The time runs from the
//! frame in hand to the command's bytes handed to the port.
//!
//! `cargo bench -p dexitac --bench loop_latency [-- SAMPLES]`

use std::time::Duration;

use dexitac_gripper::grasp::{CentreMm, Command, Grasp, GraspParams, Observation};
use dexitac_protocol::{HostMsg, ValveState, CHAMBER_COUNT};
use dexitac_rig::event::centre_mm;
use dexitac_rig::link::{Link, LinkConfig};
use dexitac_sim::mcu::{SimMcu, SimMcuConfig};
use dexitac_sim::plant::ContactState;
use dexitac_sim::render::Renderer;
use dexitac_tactile::calibrate;
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::synth::SensorSpec;

fn contact(x_mm: f64) -> ContactState {
    ContactState {
        centre_mm: [x_mm, -1.0],
        shear_mm: [0.0, 0.0],
        normal_n: 2.5,
        width_mm: 2.5,
    }
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn main() {
    let samples: usize = std::env::args()
        .skip(1)
        .find_map(|a| a.parse().ok())
        .unwrap_or(400);
    let params = Params::default();
    let mut renderer = Renderer::new(SensorSpec::nominal(640, 480), params.frame.mm_per_px, 7);
    let rest = [renderer.render(None), renderer.render(None)];
    let cal = calibrate::calibrate(&rest, &params).expect("calibration");
    let pipeline = Pipeline::new(cal, params);
    let frames_a: Vec<_> = (0..8)
        .map(|_| renderer.render(Some(&contact(0.0))))
        .collect();
    let frames_b: Vec<_> = (0..8)
        .map(|_| renderer.render(Some(&contact(1.0))))
        .collect();
    let a_mm = pipeline
        .run(&frames_a[0])
        .ok()
        .and_then(|r| r.contact)
        .map(|c| centre_mm(&pipeline, c.centre))
        .expect("contact A seen");

    let mcu = SimMcu::spawn(SimMcuConfig::default()).expect("simulated MCU");
    let mut link = Link::open(mcu.port_path(), LinkConfig::default()).expect("pty");
    link.hello().expect("hello");
    link.command(HostMsg::Arm).expect("arm");
    let mut inflate = [ValveState::Hold; CHAMBER_COUNT];
    for c in [0, 1, 4, 5] {
        inflate[c] = ValveState::Inflate;
    }

    let params = GraspParams::default();
    let span = params.stable_span_ms;
    let (mut total, mut pipe, mut rest_ms) = (Vec::new(), Vec::new(), Vec::new());
    for i in 0..samples {
        let disturbance = i % 2 == 0;
        // A grasp with 3 s of still contact on A (sealed) or 3 s minus one
        // frame (about to seal), fed as observations.
        let mut grasp = Grasp::new(params);
        grasp.start(0);
        let end = if disturbance { span + 100 } else { span - 33 };
        let mut t = 0;
        while t <= end {
            for s in 0..2 {
                let _ = grasp.observe(
                    s,
                    Observation {
                        t_ms: t,
                        centre_mm: Some(a_mm),
                    },
                );
            }
            t += 33;
        }
        let frame = if disturbance {
            &frames_b[i % frames_b.len()]
        } else {
            &frames_a[i % frames_a.len()]
        };
        let t_frame = if disturbance { end + 33 } else { span };
        // Sensor 1's latest frame, just before: the frame under test decides.
        let _ = grasp.observe(
            1,
            Observation {
                t_ms: t_frame - 1,
                centre_mm: Some(a_mm),
            },
        );
        link.keep_alive().expect("heartbeat");
        let _ = link.poll(Duration::ZERO).expect("poll");

        let arrived = link.clock().now_us();
        let result = pipeline.run(frame).expect("pipeline");
        let piped = link.clock().now_us();
        let centre: Option<CentreMm> = result.contact.map(|c| centre_mm(&pipeline, c.centre));
        let decision = grasp.observe(
            0,
            Observation {
                t_ms: t_frame,
                centre_mm: centre,
            },
        );
        let msg = match decision.map(|d| d.command) {
            Some(Command::ReopenInflation) => HostMsg::SetChambers { chambers: inflate },
            Some(Command::Seal) => HostMsg::SealAll,
            other => panic!("sample {i}: unexpected decision {other:?}"),
        };
        link.command(msg).expect("command");
        let written = link.last_command_written_us().expect("written");
        total.push((written - arrived) as f64 / 1e3);
        pipe.push((piped - arrived) as f64 / 1e3);
        rest_ms.push((written - piped) as f64 / 1e3);
    }
    link.command(HostMsg::Disarm).expect("disarm");
    for v in [&mut total, &mut pipe, &mut rest_ms] {
        v.sort_by(f64::total_cmp);
    }
    println!("frame arrival -> command bytes written, {samples} samples (half disturbance -> SetChambers, half stable -> SealAll)");
    println!("| part | median ms | p99 ms | max ms |");
    println!("| --- | --- | --- | --- |");
    for (name, v) in [
        ("total", &total),
        ("pipeline (640x480)", &pipe),
        ("decide + encode + write", &rest_ms),
    ] {
        println!(
            "| {name} | {:.3} | {:.3} | {:.3} |",
            percentile(v, 0.5),
            percentile(v, 0.99),
            v[v.len() - 1]
        );
    }
}
