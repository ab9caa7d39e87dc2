//! Numerical stress tests: degenerate marker sets, extreme kernel widths,
//! blank / saturated / noise frames, tiny and huge images, f32 fast path
//! against the f64 reference. Documented behaviour: no panic, no NaN or
//! infinity in any output; degenerate inputs give "no contact" or a typed
//! error.

use dexitac_tactile::calibrate::{self, Calibration};
use dexitac_tactile::contact;
use dexitac_tactile::density::{self, DensitySetup};
use dexitac_tactile::frame::{self, GreyFrame, RawFrame};
use dexitac_tactile::markers;
use dexitac_tactile::params::{DensityMode, FrameParams, Params};
use dexitac_tactile::pipeline::Pipeline;
use dexitac_tactile::synth::{self, Category, Rng};
use dexitac_tactile::tracking;
use dexitac_tactile::PointPx;
use proptest::prelude::*;

fn setup(w: usize, h: usize, h_px: f64, mode: DensityMode, step: usize) -> DensitySetup {
    DensitySetup {
        width: w,
        height: h,
        h_px,
        mm_per_px: 0.1,
        mode,
        step_px: step,
        truncate_sigmas: 3.0,
        skin: None,
    }
}

fn all_finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite() && *x >= 0.0)
}

fn calibration() -> (Calibration, Params) {
    let params = Params::default();
    let sensor = Category::Nominal.sensor(640, 480, 8);
    let rest = synth::rest_frame(&sensor, 3);
    (
        calibrate::calibrate(&[rest.image], &params).unwrap(),
        params,
    )
}

#[test]
fn degenerate_marker_sets_give_finite_densities() {
    let sets: Vec<Vec<PointPx>> = vec![
        vec![],
        vec![PointPx::new(40.0, 30.0)],
        vec![PointPx::new(40.0, 30.0), PointPx::new(41.0, 30.0)],
        vec![PointPx::new(20.0, 20.0); 500],
        vec![
            PointPx::new(0.0, 0.0),
            PointPx::new(79.0, 59.0),
            PointPx::new(-50.0, 30.0),
            PointPx::new(1e9, -1e9),
        ],
        vec![
            PointPx::new(f64::NAN, 1.0),
            PointPx::new(f64::INFINITY, 2.0),
            PointPx::new(3.0, f64::NEG_INFINITY),
        ],
    ];
    for markers in &sets {
        for h in [0.5, 15.0, 500.0] {
            let exact = density::exact(markers, 80, 60, h, 0.1);
            assert!(
                exact.iter().all(|v| v.is_finite() && *v >= 0.0),
                "h {h}: {markers:?}"
            );
            for step in [1, 4, 16] {
                let m =
                    density::estimate(markers, &setup(80, 60, h, DensityMode::Fast, step), None);
                assert!(all_finite(&m.values_per_mm2), "h {h} step {step}");
            }
        }
    }
    let none = density::exact(&[], 10, 10, 15.0, 0.1);
    assert!(none.iter().all(|&v| v == 0.0));
}

#[test]
fn f32_fast_path_matches_f64_reference_on_the_same_markers() {
    let sensor = Category::Nominal.sensor(160, 120, 4);
    let mut sensor = sensor;
    sensor.pitch_px = 15.0;
    let markers = sensor.rest_markers();
    let exact = density::exact(&markers, 160, 120, 15.0, 0.1);
    let peak = exact.iter().cloned().fold(0.0, f64::max);
    let mut s = setup(160, 120, 15.0, DensityMode::Fast, 1);
    s.truncate_sigmas = 8.0;
    let fast = density::estimate(&markers, &s, None);
    let worst = fast
        .values_per_mm2
        .iter()
        .zip(&exact)
        .map(|(&f, &e)| (f as f64 - e).abs())
        .fold(0.0, f64::max);
    // f32 rounding only (truncation at 8 h is below 1e-13 of a kernel).
    assert!(worst <= 1e-5 * peak, "{worst} vs peak {peak}");
}

#[test]
fn blank_saturated_and_noise_frames_give_no_contact_and_finite_output() {
    let (cal, params) = calibration();
    let pipeline = Pipeline::new(cal, params);
    let mut rng = Rng::new(5);
    let noise: Vec<u8> = (0..640 * 480)
        .map(|_| (rng.next_u64() & 0xFF) as u8)
        .collect();
    let frames = [
        vec![0u8; 640 * 480],
        vec![255u8; 640 * 480],
        vec![128u8; 640 * 480],
        noise,
    ];
    for data in frames {
        let f = GreyFrame::new(640, 480, data).unwrap();
        let r = pipeline.run(&f).unwrap();
        for m in &r.markers.list {
            assert!(m.pos.is_finite() && m.strength.is_finite());
        }
        assert!(
            r.contact.is_none(),
            "{:?} with {} markers",
            r.contact,
            r.markers.len()
        );
        // None is a marker image: noise too (following alone would put a
        // centroid near every rest place in it).
        assert!(r.blank, "not blank: {} markers", r.markers.len());
        for t in [
            r.times.detect_ms,
            r.times.kde_ms,
            r.times.segment_ms,
            r.times.total_ms,
        ] {
            assert!(t.is_finite() && t >= 0.0);
        }
    }
}

#[test]
fn blank_or_noise_rest_frames_are_typed_errors() {
    let mut rng = Rng::new(9);
    let noise: Vec<u8> = (0..640 * 480)
        .map(|_| (rng.next_u64() & 0xFF) as u8)
        .collect();
    for data in [vec![0u8; 640 * 480], vec![255u8; 640 * 480], noise] {
        let f = GreyFrame::new(640, 480, data).unwrap();
        // Pure noise may pass as "markers"; it must not panic either way.
        let _ = calibrate::calibrate(&[f], &Params::default()).map(|c| c.rest_markers.len());
    }
    let black = GreyFrame::new(640, 480, vec![0u8; 640 * 480]).unwrap();
    assert!(calibrate::calibrate(&[black], &Params::default()).is_err());
    assert!(calibrate::calibrate(&[], &Params::default()).is_err());
}

#[test]
fn tiny_and_huge_inputs_are_rescaled_or_rejected() {
    let fp = FrameParams::default();
    for (w, h) in [(1usize, 1usize), (3, 2), (16, 12), (2560, 1920), (1000, 10)] {
        let data = vec![77u8; w * h];
        let raw = RawFrame {
            width: w,
            height: h,
            channels: 1,
            data: &data,
        };
        let p = frame::prepare(&raw, &fp).unwrap();
        let (gw, gh) = (p.grey.width(), p.grey.height());
        // The input's aspect, scaled down (never up) to fit 640x480.
        assert!(
            gw == 640 || gh == 480 || (gw, gh) == (w, h),
            "{w}x{h} -> {gw}x{gh}"
        );
        assert!(gw <= 640 && gh <= 480 && gw <= w && gh <= h);
        let aspect = |a: usize, b: usize| a as f64 / b as f64;
        assert!((aspect(gw, gh) - aspect(w, h)).abs() <= aspect(w, h) / gh.min(gw) as f64);
        assert!(p.grey.data().iter().all(|&v| v == 77));
        let c = p.to_input(PointPx::new(gw as f64 - 1.0, gh as f64 - 1.0));
        assert!(c.x <= w as f64 && c.y <= h as f64);
        let stretched = FrameParams {
            keep_aspect: false,
            ..FrameParams::default()
        };
        let p = frame::prepare(&raw, &stretched).unwrap();
        assert_eq!((p.grey.width(), p.grey.height()), (640, 480));
    }
    let raw = RawFrame {
        width: 20_000,
        height: 1,
        channels: 1,
        data: &[],
    };
    assert!(frame::prepare(&raw, &fp).is_err());
    // A tiny working size: detection and calibration degrade to errors.
    let tiny = GreyFrame::new(8, 8, vec![9; 64]).unwrap();
    assert!(markers::auto_detector(&tiny, &Params::default().markers).is_err());
}

#[test]
fn segment_handles_zero_nan_and_infinite_densities() {
    let (cal, params) = calibration();
    let g = cal.rest_density.grid;
    for fill in [0.0f32, f32::NAN, f32::INFINITY, 1e30] {
        let map = density::DensityMap {
            grid: g,
            roi: g.full(),
            values_per_mm2: vec![fill; g.nx * g.ny],
        };
        if let Some(r) = contact::segment(&map, &cal.density_reference(), &params.contact, 0.1) {
            assert!(
                r.centre.is_finite() && r.area_mm2.is_finite(),
                "{fill}: {r:?}"
            );
        }
    }
}

#[test]
fn radial_fit_with_coincident_markers_is_none_or_finite() {
    let rest = vec![PointPx::new(10.0, 10.0); 20];
    let cur: Vec<PointPx> = rest.iter().map(|p| PointPx::new(p.x + 1.0, p.y)).collect();
    let field = tracking::track(&rest, &cur, 40, 40, 7.5, 0.3);
    if let Some(fit) = tracking::radial_centre(&rest, &field, &field.moved, 0.3) {
        assert!(fit.centre.is_finite());
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn any_marker_set_and_kernel_gives_finite_fast_density(
        pts in prop::collection::vec((-200.0f64..900.0, -200.0f64..700.0), 0..60),
        h in 0.5f64..300.0,
        step in 1usize..=16,
    ) {
        let markers: Vec<PointPx> = pts.iter().map(|&(x, y)| PointPx::new(x, y)).collect();
        let m = density::estimate(&markers, &setup(160, 120, h, DensityMode::Fast, step), None);
        prop_assert!(all_finite(&m.values_per_mm2));
    }

    #[test]
    fn any_small_frame_prepares_and_detects_without_panic(
        w in 1usize..64,
        h in 1usize..48,
        seed in any::<u64>(),
        channels in prop::sample::select(vec![1usize, 3, 4]),
    ) {
        let mut rng = Rng::new(seed);
        let data: Vec<u8> = (0..w * h * channels).map(|_| (rng.next_u64() & 0xFF) as u8).collect();
        let raw = RawFrame { width: w, height: h, channels, data: &data };
        let fp = FrameParams { work_width_px: 64, work_height_px: 48, ..FrameParams::default() };
        let p = frame::prepare(&raw, &fp).unwrap();
        let det = markers::Detector {
            lobe_px: 3,
            bin: 1,
            min_level_ratio: 0.3,
            min_rel_strength: 0.05,
            min_contrast: 6.0,
            radius_px: 3.0,
            cell_px: 8,
            window_px: None,
            area: None,
            rim: None,
            dark: false,
            surface: dexitac_tactile::surface::Surface::Flat,
        };
        for m in markers::detect(&p.grey, &det).list {
            prop_assert!(m.pos.is_finite());
        }
    }
}
