//! The live view's renderer on a full dashboard: two 640x480 simulated
//! fingertip frames pressed off-centre with their pipeline results, a 3 s
//! contact trail, 20 s of telemetry at the loop's 20 ms period (valves
//! switching) and grasp phases. `cargo bench -p dexitac --bench view`.

use std::hint::black_box;
use std::sync::Arc;

use criterion::{criterion_group, criterion_main, Criterion};
use dexitac_gripper::grasp::{Cause, Command, Decision};
use dexitac_protocol::{ArmState, HostMsg, Telemetry, ValveState};
use dexitac_rig::event::RuntimeEvent;
use dexitac_sim::plant::ContactState;
use dexitac_sim::render::Renderer;
use dexitac_tactile::calibrate;
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::synth::SensorSpec;
use dexitac_view::{Dashboard, DashboardConfig};

fn dashboard() -> Dashboard {
    let params = Params::default();
    let mut d = Dashboard::new(DashboardConfig::default());
    d.apply(&RuntimeEvent::CommandSent {
        t_ms: 0,
        msg: HostMsg::SealAll,
        reason: "close fingers",
        from_frame: None,
    });
    for sensor in 0..2 {
        let mut renderer = Renderer::new(
            SensorSpec::nominal(640, 480),
            params.frame.mm_per_px,
            sensor as u64 + 1,
        );
        let rest = [renderer.render(None), renderer.render(None)];
        let cal = calibrate::calibrate(&rest, &params).expect("calibrates");
        let pipeline = Pipeline::new(cal, params.clone());
        // 3 s of a contact sliding 2 mm, one frame per 33 ms.
        for k in 0..=90u64 {
            let t_ms = 17_000 + k * 33;
            let contact = ContactState {
                centre_mm: [1.0 + 2.0 * k as f64 / 90.0, -0.5],
                shear_mm: [0.0, 0.0],
                normal_n: 1.5,
                width_mm: 3.0,
            };
            let frame = renderer.render(Some(&contact));
            let r = pipeline.run(&frame).expect("pipeline");
            d.apply(&RuntimeEvent::Observation(
                dexitac_rig::event::SensorReport {
                    sensor,
                    t_ms,
                    centre_mm: r
                        .contact
                        .map(|c| dexitac_rig::event::centre_mm(&pipeline, c.centre)),
                    markers: Arc::new(r.markers.positions()),
                    pipeline_ms: r.times.total_ms,
                    contact: r.contact,
                    frame: Some(Arc::new(frame)),
                },
            ));
        }
    }
    for k in 0..1_000u64 {
        let t_ms = k * 20;
        let state = match (k / 150) % 3 {
            0 => ValveState::Inflate,
            1 => ValveState::Hold,
            _ => ValveState::Deflate,
        };
        d.apply(&RuntimeEvent::Telemetry {
            t_ms,
            telemetry: Telemetry {
                time_ms: t_ms as u32,
                positive_tank_pa: 38_000 + (k % 50) as i32 * 40,
                negative_tank_pa: -44_000,
                chambers: [state; 8],
                positive_pump_on: k % 40 < 5,
                negative_pump_on: false,
                state: ArmState::Armed,
                faults: Default::default(),
                loop_overruns: 0,
            },
        });
        if k == 300 {
            d.apply(&RuntimeEvent::Decision {
                t_ms,
                decision: Decision {
                    t_ms,
                    command: Command::Seal,
                    cause: Cause::BothStable,
                },
            });
        }
    }
    d
}

fn render(c: &mut Criterion) {
    let d = dashboard();
    c.bench_function("view_render_1280x720", |b| {
        b.iter(|| black_box(&d).render())
    });
}

criterion_group!(benches, render);
criterion_main!(benches);
