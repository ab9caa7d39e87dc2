//! One criterion benchmark per pipeline stage on a synthetic 640x480 frame
//! (nominal contact, default parameters: density grid step 8), plus the whole pipeline on a contact and a no-contact
//! frame. `cargo bench -p dexitac --bench stages`.

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;

use dexitac_tactile::calibrate::{self, Calibration};
use dexitac_tactile::density::{self, DensitySetup};
use dexitac_tactile::frame::{self, RawFrame};
use dexitac_tactile::params::{DensityMode, Params};
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::synth::{self, Category, SynthFrame};
use dexitac_tactile::{contact, markers, tracking};

fn fixture() -> (Calibration, SynthFrame, SynthFrame) {
    let sensor = Category::Nominal.sensor(640, 480, 1);
    let rest = synth::rest_frame(&sensor, 2);
    let cal = calibrate::calibrate(&[rest.image], &Params::default()).expect("calibrates");
    let pressed = synth::render(&Category::Nominal.scene(&sensor, 3));
    let idle = synth::render(&Category::NoContact.scene(&sensor, 4));
    (cal, pressed, idle)
}

fn stages(c: &mut Criterion) {
    let (cal, pressed, idle) = fixture();
    let params = Params::default();
    let img = &pressed.image;
    let rgb: Vec<u8> = img.data().iter().flat_map(|&v| [v, v, v]).collect();
    let raw = RawFrame {
        width: 640,
        height: 480,
        channels: 3,
        data: &rgb,
    };
    c.bench_function("frame_prepare_rgb_640x480", |b| {
        b.iter(|| frame::prepare(black_box(&raw), &params.frame).expect("valid"))
    });
    c.bench_function("markers_detect_640x480", |b| {
        b.iter(|| markers::detect(black_box(img), &cal.detector))
    });
    let found = markers::detect(img, &cal.detector).positions();
    c.bench_function("tracking_match_rest", |b| {
        b.iter(|| tracking::track(&cal.rest_markers, black_box(&found), 640, 480, 7.5, 0.3))
    });
    let field = tracking::track(&cal.rest_markers, &found, 640, 480, 7.5, 0.3);
    for step in [4, 8] {
        let setup = DensitySetup {
            step_px: step,
            ..cal.density
        };
        c.bench_function(&format!("density_fast_s{step}_full_grid"), |b| {
            b.iter(|| density::estimate(black_box(&found), &setup, None))
        });
    }
    let exact = DensitySetup {
        mode: DensityMode::Exact,
        ..cal.density
    };
    let mut group = c.benchmark_group("slow");
    group.sample_size(10);
    group.bench_function("density_exact_f64_640x480", |b| {
        b.iter(|| density::estimate(black_box(&found), &exact, None))
    });
    group.finish();
    let map = density::estimate(&found, &cal.density, None);
    c.bench_function("contact_segment_s8", |b| {
        b.iter(|| {
            contact::segment(
                black_box(&map),
                &cal.density_reference(),
                &params.contact,
                0.1,
            )
        })
    });
    let region = contact::segment(&map, &cal.density_reference(), &params.contact, 0.1);
    c.bench_function("contact_locate_tracking", |b| {
        b.iter(|| {
            contact::locate(
                black_box(region),
                &cal.rest_markers,
                &field,
                &cal.surface,
                cal.pitch_px,
                &params.contact,
                0.1,
            )
        })
    });
    let pipeline = Pipeline::new(cal, params);
    c.bench_function("pipeline_contact_640x480", |b| {
        b.iter(|| pipeline.run(black_box(&pressed.image)).expect("size"))
    });
    c.bench_function("pipeline_no_contact_640x480", |b| {
        b.iter(|| pipeline.run(black_box(&idle.image)).expect("size"))
    });
}

criterion_group!(benches, stages);
criterion_main!(benches);
