//! Cost of recording one observation on the simulated rig's 640x480 frame
//! (pressed, sensor noise as rendered): with its frame (PNG, base64, JSON,
//! zstd chunk) and without (markers, contact). Written to a byte-counting
//! sink, so the numbers exclude the disk. `cargo bench -p dexitac --bench recording`.

use std::io::{Seek, SeekFrom, Write};

use criterion::{criterion_group, criterion_main, Criterion};

use dexitac_rig::recording::{RecordOptions, Recorder};
use dexitac_sim::plant::ContactState;
use dexitac_sim::render::Renderer;
use dexitac_tactile::calibrate;
use dexitac_tactile::params::Params;
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::synth::SensorSpec;

/// Counts bytes; seeks move the position (the MCAP writer seeks back to
/// patch chunk headers).
#[derive(Default)]
struct Sink {
    pos: u64,
    len: u64,
}

impl Write for Sink {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.pos += buf.len() as u64;
        self.len = self.len.max(self.pos);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Seek for Sink {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        self.pos = match to {
            SeekFrom::Start(p) => p,
            SeekFrom::End(d) => self.len.saturating_add_signed(d),
            SeekFrom::Current(d) => self.pos.saturating_add_signed(d),
        };
        Ok(self.pos)
    }
}

fn recording(c: &mut Criterion) {
    let params = Params::default();
    let mut r = Renderer::new(SensorSpec::nominal(640, 480), params.frame.mm_per_px, 1);
    let rest = [r.render(None), r.render(None)];
    let pipeline = Pipeline::new(
        calibrate::calibrate(&rest, &params).expect("calibrates"),
        params,
    );
    let frame = r.render(Some(&ContactState {
        centre_mm: [1.0, -0.5],
        shear_mm: [0.0, 0.0],
        normal_n: 1.5,
        width_mm: 2.5,
    }));
    let result = pipeline.run(&frame).expect("runs");
    for (name, frames) in [
        ("record_observation_with_frame_640x480", true),
        ("record_observation_without_frame", false),
    ] {
        let options = RecordOptions {
            frames,
            ..RecordOptions::default()
        };
        let mut rec = Recorder::new(Sink::default(), options).expect("recorder");
        let mut t_ms = 0;
        c.bench_function(name, |b| {
            b.iter(|| {
                t_ms += 33;
                rec.write_frame_result(0, t_ms, &frame, &pipeline, &result)
                    .expect("written")
            })
        });
        let stats = rec.finish().expect("finished");
        eprintln!(
            "{name}: {} observations, {:.1} kB per observation after compression",
            stats.observations,
            stats.bytes as f64 / 1e3 / stats.observations.max(1) as f64
        );
    }
}

criterion_group!(benches, recording);
criterion_main!(benches);
