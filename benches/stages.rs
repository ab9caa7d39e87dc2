//! One criterion benchmark per pipeline stage on a synthetic 640x480 frame
//! (nominal contact, default parameters: density grid step 8), plus the whole pipeline on a contact and a no-contact
//! frame, and on contact frames in turn. `cargo bench -p dexitac-benches --bench stages`.
//!
//! A benchmark that runs one frame again and again lets the CPU's branch
//! predictors learn that frame: `pipeline_contact_640x480_in_turn` runs
//! `IN_TURN` different contact frames one after the other, as a camera
//! or `dexitac analyze` would, and `..._each_repeated` the same frames, each
//! again and again before the next (BENCHMARKS.md, session 26).

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;

use dexitac_tactile::calibrate::{self, Calibration};
use dexitac_tactile::density::{self, DensitySetup};
use dexitac_tactile::frame::{self, RawFrame};
use dexitac_tactile::params::{DensityMode, Params};
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::synth::{self, Category, SynthFrame};
use dexitac_tactile::{contact, markers, tracking};

/// Contact frames of `pipeline_contact_640x480_in_turn`.
const IN_TURN: u64 = 16;

fn fixture() -> (Calibration, SynthFrame, SynthFrame, Vec<SynthFrame>) {
    let sensor = Category::Nominal.sensor(640, 480, 1);
    let rest = synth::rest_frame(&sensor, 2);
    let cal = calibrate::calibrate(&[rest.image], &Params::default()).expect("calibrates");
    let pressed = synth::render(&Category::Nominal.scene(&sensor, 3));
    let idle = synth::render(&Category::NoContact.scene(&sensor, 4));
    let in_turn = (0..IN_TURN)
        .map(|k| synth::render(&Category::Nominal.scene(&sensor, 100 + k)))
        .collect();
    (cal, pressed, idle, in_turn)
}

fn stages(c: &mut Criterion) {
    let (cal, pressed, idle, in_turn) = fixture();
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
    let mut next = 0;
    c.bench_function("pipeline_contact_640x480_in_turn", |b| {
        b.iter(|| {
            next = (next + 1) % in_turn.len();
            pipeline.run(black_box(&in_turn[next].image)).expect("size")
        })
    });
    // The same frames, each run its share of the iterations in a row.
    c.bench_function("pipeline_contact_640x480_each_repeated", |b| {
        b.iter_custom(|iters| {
            let started = std::time::Instant::now();
            for i in 0..iters {
                let k = (i * IN_TURN / iters.max(1)) as usize;
                black_box(pipeline.run(black_box(&in_turn[k].image)).expect("size"));
            }
            started.elapsed()
        })
    });
}

criterion_group!(benches, stages);
criterion_main!(benches);
