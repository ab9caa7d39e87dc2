//! Robustness of the default tactile pipeline beyond `dexitac bench-pipeline`
//! (numbers quoted in BENCHMARKS.md, tactile pipeline):
//!
//! 1. small contacts (width 4-8 px) found, per seed, on the benchmark's
//!    sensors and frames (`bench::evaluate`, 40 frames per seed);
//! 2. false contacts and skipped frames on contact-free frames of every
//!    sensor type (the scenes of every category with their presses removed:
//!    noise, blur, vignetting, saturation, dropout, rounded-rectangle);
//! 3. false contacts when one marker of such a frame is displaced by a
//!    glitch (0.5-3 px in a random direction, 5 per frame), run through the
//!    tracking-only rule.
//!
//! `cargo run --release -p dexitac --example tactile_robustness -- [SEEDS...]`
//! (default seeds 1 2 3).

use dexitac_tactile::bench::{self, Setting};
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::synth::{self, Category, Rng};
use dexitac_tactile::{calibrate, contact, PointPx};

fn main() {
    let seeds: Vec<u64> = std::env::args()
        .skip(1)
        .filter_map(|s| s.parse().ok())
        .collect();
    let seeds = if seeds.is_empty() {
        vec![1, 2, 3]
    } else {
        seeds
    };
    let params = Params::default();
    let setting = Setting {
        name: "default",
        params: params.clone(),
    };
    for &seed in &seeds {
        let samples = match bench::evaluate(&setting, &[Category::Small], 40, 640, 480, seed) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("tactile_robustness: {e}");
                std::process::exit(2);
            }
        };
        let s = bench::summarize(Category::Small, &samples);
        println!(
            "seed {seed}: small contacts found {}/{}, error median {:.2} px, p95 {:.2} px",
            s.found, s.frames, s.error_median_px, s.error_p95_px
        );
    }
    let (mut frames, mut false_contacts, mut skipped, mut glitches, mut glitch_fp) =
        (0, 0, 0, 0, 0);
    let mut rng = Rng::new(77);
    for &seed in &seeds {
        for (ci, cat) in Category::ALL.iter().copied().enumerate() {
            for j in 0..4u64 {
                let sensor_seed = 1000 + seed + ci as u64 * 4 + j;
                let sensor = cat.sensor(640, 480, sensor_seed);
                let rest = synth::rest_frame(&sensor, sensor_seed ^ 0xA5A5);
                let Ok(cal) = calibrate::calibrate(&[rest.image], &params) else {
                    eprintln!("tactile_robustness: calibration failed ({})", cat.name());
                    continue;
                };
                let p = Pipeline::new(cal, params.clone());
                for k in 0..10 {
                    let mut scene = cat.scene(&sensor, seed * 7919 + k);
                    scene.presses.clear();
                    let f = synth::render(&scene);
                    let Ok(r) = p.run(&f.image) else { continue };
                    frames += 1;
                    false_contacts += usize::from(r.contact.is_some());
                    skipped += usize::from(r.skipped);
                    for _ in 0..5 {
                        let mut field = r.field.clone();
                        let n = (rng.unit() * field.displacement.len() as f64) as usize;
                        let a = rng.range(0.0, std::f64::consts::TAU);
                        let m = rng.range(0.5, 3.0);
                        if let Some(u) = field.displacement.get_mut(n) {
                            *u = Some(PointPx::new(m * a.cos(), m * a.sin()));
                            if !field.moved.contains(&n) {
                                field.moved.push(n);
                            }
                        }
                        let cal = &p.calibration;
                        let c = contact::locate(
                            None,
                            &cal.rest_markers,
                            &field,
                            &cal.surface,
                            cal.pitch_px,
                            &params.contact,
                            cal.density.mm_per_px,
                        );
                        glitches += 1;
                        glitch_fp += usize::from(c.is_some());
                    }
                }
            }
        }
    }
    println!(
        "contact-free frames of every sensor type: {frames}, false contacts {false_contacts}, \
         skipped {skipped}; one-marker glitches: {glitch_fp} false contacts of {glitches}"
    );
}
