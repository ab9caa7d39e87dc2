//! Camera buffer decoding at 640x480 on a synthetic rest frame: MJPEG
//! straight to luma (what the camera source does) against a full colour
//! decode then grey (what `image` would do), YUYV luma extraction, and the
//! whole camera step (decode + `frame::prepare`).
//! `cargo bench -p dexitac --bench camera_decode`.

use criterion::{criterion_group, criterion_main, Criterion};
use std::hint::black_box;

use dexitac_rig::camera::{decode, Mode, PixelFormat};
use dexitac_tactile::frame::{self, RawFrame};
use dexitac_tactile::params::Params;
use dexitac_tactile::synth::{self, Category};

fn camera_decode(c: &mut Criterion) {
    let sensor = Category::Nominal.sensor(640, 480, 1);
    let grey = synth::render(&Category::Nominal.scene(&sensor, 3)).image;
    let params = Params::default();
    for quality in [75u8, 90] {
        let jpeg = decode::encode_mjpeg(&grey, quality).expect("encodes");
        eprintln!("MJPEG q{quality}: {} bytes per 640x480 frame", jpeg.len());
        c.bench_function(&format!("mjpeg_q{quality}_to_luma_640x480"), |b| {
            b.iter(|| decode::mjpeg_luma(black_box(&jpeg)).expect("decodes"))
        });
        c.bench_function(&format!("mjpeg_q{quality}_rgb_then_grey_640x480"), |b| {
            b.iter(|| {
                image::load_from_memory(black_box(&jpeg))
                    .expect("decodes")
                    .into_luma8()
            })
        });
    }
    let yuyv = decode::pack_yuyv(&grey);
    c.bench_function("yuyv_to_luma_640x480", |b| {
        b.iter(|| decode::yuyv_luma(black_box(&yuyv), 640, 480, 0).expect("decodes"))
    });
    let jpeg = decode::encode_mjpeg(&grey, 90).expect("encodes");
    let mode = Mode {
        format: PixelFormat::Mjpeg,
        width_px: 640,
        height_px: 480,
        stride_bytes: 0,
        fps: None,
    };
    c.bench_function("camera_frame_mjpeg_q90_decode_prepare_640x480", |b| {
        b.iter(|| {
            let g = decode::to_grey(black_box(&jpeg), &mode).expect("decodes");
            let raw = RawFrame {
                width: g.width(),
                height: g.height(),
                channels: 1,
                data: g.data(),
            };
            frame::prepare(&raw, &params.frame).expect("prepares")
        })
    });
}

criterion_group!(benches, camera_decode);
criterion_main!(benches);
