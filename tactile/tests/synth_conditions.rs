//! Tests of the synthetic-frame generator itself (`synth`), not of the
//! pipeline: the original categories' frames are unchanged, and each new
//! condition (light change, blur, texture, dome, housing, two-colour pins,
//! rim clamp) is rendered as documented.

use dexitac_tactile::synth::{
    self, Category, DistractorKind, FrameConditions, Press, SensorSpec, SynthFrame,
};
use dexitac_tactile::PointPx;

/// FNV-1a 64 over the image bytes and the truth (contacts, rest and moved
/// markers as f64 bits).
fn fingerprint(f: &SynthFrame) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |b: u8| {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    };
    for &b in f.image.data() {
        eat(b);
    }
    for p in f.contacts.iter().chain(&f.rest_markers).chain(&f.markers) {
        for b in
            p.x.to_bits()
                .to_le_bytes()
                .into_iter()
                .chain(p.y.to_bits().to_le_bytes())
        {
            eat(b);
        }
    }
    h
}

/// Fingerprints of frames of the original categories, recorded before the
/// condition options were added ("WxH category sSENSOR_SEED rest|kSCENE_SEED";
/// the rest frame's seed is `sensor seed ^ 0xA5A5` as in `bench`).
const LEGACY: &[(&str, u64)] = &[
    ("640x480 nominal s1 rest", 0x5a517c495dfbac39),
    ("640x480 nominal s1 k0", 0x8b96ba523f29b198),
    ("640x480 nominal s1 k1001", 0x6e509560d478b285),
    ("640x480 nominal s6 rest", 0x7ce2e92f6d1b5810),
    ("640x480 nominal s6 k0", 0xc23dce6d1c5a8725),
    ("640x480 nominal s6 k1001", 0x4723b6f7178eb0c5),
    ("640x480 edge s1 rest", 0x5a517c495dfbac39),
    ("640x480 edge s1 k0", 0x9265ec05ec7a3f1f),
    ("640x480 edge s1 k1001", 0xc5e6595e7c08115a),
    ("640x480 edge s6 rest", 0x7ce2e92f6d1b5810),
    ("640x480 edge s6 k0", 0xdf61cf8fbf8d6db9),
    ("640x480 edge s6 k1001", 0x624c1ce1f9e5b22f),
    ("640x480 large s1 rest", 0x5a517c495dfbac39),
    ("640x480 large s1 k0", 0x81c90820aac3a785),
    ("640x480 large s1 k1001", 0x2068df40eeabbd1f),
    ("640x480 large s6 rest", 0x7ce2e92f6d1b5810),
    ("640x480 large s6 k0", 0x030c3b446fe6bd50),
    ("640x480 large s6 k1001", 0x722afbcd9e472254),
    ("640x480 small s1 rest", 0x5a517c495dfbac39),
    ("640x480 small s1 k0", 0x6d25fbd97dbcc3a1),
    ("640x480 small s1 k1001", 0x689bfb1f7343c30b),
    ("640x480 small s6 rest", 0x7ce2e92f6d1b5810),
    ("640x480 small s6 k0", 0xf2dafba635a002ec),
    ("640x480 small s6 k1001", 0xb3e67bb50586fc7c),
    ("640x480 two s1 rest", 0x5a517c495dfbac39),
    ("640x480 two s1 k0", 0x957d52b324753318),
    ("640x480 two s1 k1001", 0x925d8c966e3bee6c),
    ("640x480 two s6 rest", 0x7ce2e92f6d1b5810),
    ("640x480 two s6 k0", 0x0a99d10a49da3d5d),
    ("640x480 two s6 k1001", 0x90de4d4021e968e4),
    ("640x480 shear s1 rest", 0x5a517c495dfbac39),
    ("640x480 shear s1 k0", 0x2f3785d7a593e027),
    ("640x480 shear s1 k1001", 0x9b84577489546b83),
    ("640x480 shear s6 rest", 0x7ce2e92f6d1b5810),
    ("640x480 shear s6 k0", 0x7d051181de3421a6),
    ("640x480 shear s6 k1001", 0x18edfb56b347b938),
    ("640x480 degraded s1 rest", 0xf102c61fea622441),
    ("640x480 degraded s1 k0", 0x841f00d10922a539),
    ("640x480 degraded s1 k1001", 0x2c076dfd18fafc09),
    ("640x480 degraded s6 rest", 0x2386d1d63c78f94e),
    ("640x480 degraded s6 k0", 0xfa6464cbaf7865a9),
    ("640x480 degraded s6 k1001", 0x38f270cc4e20eab1),
    ("640x480 saturated s1 rest", 0x953d3b0e711c83a4),
    ("640x480 saturated s1 k0", 0x5add520519819072),
    ("640x480 saturated s1 k1001", 0x3a9491b2ef00b33b),
    ("640x480 saturated s6 rest", 0x887f1c6992b95331),
    ("640x480 saturated s6 k0", 0x82feb8b1afedeaeb),
    ("640x480 saturated s6 k1001", 0x558ce329e6c3d729),
    ("640x480 dropout s1 rest", 0x5a517c495dfbac39),
    ("640x480 dropout s1 k0", 0x2c5282e5a7278b87),
    ("640x480 dropout s1 k1001", 0x6a40f6dd7f0c87b4),
    ("640x480 dropout s6 rest", 0x7ce2e92f6d1b5810),
    ("640x480 dropout s6 k0", 0xfcab78ff87bf5e89),
    ("640x480 dropout s6 k1001", 0xffedee498c464dad),
    ("640x480 rounded_rect s1 rest", 0x57a349b3bcd7bd02),
    ("640x480 rounded_rect s1 k0", 0x97ac6cd3649cf732),
    ("640x480 rounded_rect s1 k1001", 0x6136495ddc00adef),
    ("640x480 rounded_rect s6 rest", 0xb9dee51cff2c4e12),
    ("640x480 rounded_rect s6 k0", 0xa518166d81ee5a5e),
    ("640x480 rounded_rect s6 k1001", 0xf96e0778aafaab45),
    ("640x480 no_contact s1 rest", 0xa5461bd1eae117f7),
    ("640x480 no_contact s1 k0", 0xe143f3684e064961),
    ("640x480 no_contact s1 k1001", 0x4de531a8c489a9a5),
    ("640x480 no_contact s6 rest", 0x25f0df4dcb2f0a81),
    ("640x480 no_contact s6 k0", 0x68051ab9557fd70b),
    ("640x480 no_contact s6 k1001", 0x803dac09bfac2646),
    ("160x120 nominal s1 rest", 0x3bcf2b7134653993),
    ("160x120 nominal s1 k0", 0xcb9aeed0b2405cae),
    ("160x120 nominal s1 k1001", 0x85d5c61c77dc5957),
    ("160x120 nominal s6 rest", 0x56f4657adf298a7c),
    ("160x120 nominal s6 k0", 0xf1094e5f088c7add),
    ("160x120 nominal s6 k1001", 0x66d0bbcff52aa3b8),
    ("160x120 edge s1 rest", 0x3bcf2b7134653993),
    ("160x120 edge s1 k0", 0xbb92e68d47f6dfd2),
    ("160x120 edge s1 k1001", 0xe375cee1c290842c),
    ("160x120 edge s6 rest", 0x56f4657adf298a7c),
    ("160x120 edge s6 k0", 0x7ad7a0096fe7f245),
    ("160x120 edge s6 k1001", 0xcb1bebc76465e67e),
    ("160x120 large s1 rest", 0x3bcf2b7134653993),
    ("160x120 large s1 k0", 0xe06704fb7fdc3ef1),
    ("160x120 large s1 k1001", 0xb2c14e3823c88e6a),
    ("160x120 large s6 rest", 0x56f4657adf298a7c),
    ("160x120 large s6 k0", 0xe31933862a9d2590),
    ("160x120 large s6 k1001", 0xee1c9c2e32d9d09e),
    ("160x120 small s1 rest", 0x3bcf2b7134653993),
    ("160x120 small s1 k0", 0xd779bfe8570c63c9),
    ("160x120 small s1 k1001", 0xf4a10081b1978630),
    ("160x120 small s6 rest", 0x56f4657adf298a7c),
    ("160x120 small s6 k0", 0x3dcfcdb6cff9992c),
    ("160x120 small s6 k1001", 0x1c6fc2a7bbeb6e9b),
    ("160x120 two s1 rest", 0x3bcf2b7134653993),
    ("160x120 two s1 k0", 0x73ddc1d5458a6500),
    ("160x120 two s1 k1001", 0x7a5bef67f488d847),
    ("160x120 two s6 rest", 0x56f4657adf298a7c),
    ("160x120 two s6 k0", 0xf7482b5b7e964dde),
    ("160x120 two s6 k1001", 0x9f5824b13b7eb372),
    ("160x120 shear s1 rest", 0x3bcf2b7134653993),
    ("160x120 shear s1 k0", 0x0dd90a94be7b0c55),
    ("160x120 shear s1 k1001", 0x403027545423a73f),
    ("160x120 shear s6 rest", 0x56f4657adf298a7c),
    ("160x120 shear s6 k0", 0x122d4973ffff4c64),
    ("160x120 shear s6 k1001", 0xd90bb2f5a61e69fd),
    ("160x120 degraded s1 rest", 0x331a0fe6721b3623),
    ("160x120 degraded s1 k0", 0x5a4429cb8e934b29),
    ("160x120 degraded s1 k1001", 0x343f01e917af07c4),
    ("160x120 degraded s6 rest", 0xdcc712be5c61eb84),
    ("160x120 degraded s6 k0", 0x9294b1fd7548db62),
    ("160x120 degraded s6 k1001", 0xe1c0ccb429f99a0e),
    ("160x120 saturated s1 rest", 0xf6bf37b1d658b39f),
    ("160x120 saturated s1 k0", 0xea42a7819ff99e0e),
    ("160x120 saturated s1 k1001", 0xf789742e057e55f9),
    ("160x120 saturated s6 rest", 0x1dd1355b494fd2e3),
    ("160x120 saturated s6 k0", 0xdf6d76d36285a92a),
    ("160x120 saturated s6 k1001", 0x46b988c06ad083cf),
    ("160x120 dropout s1 rest", 0x3bcf2b7134653993),
    ("160x120 dropout s1 k0", 0x71fd7239392329a9),
    ("160x120 dropout s1 k1001", 0x5591a164bf3de2d2),
    ("160x120 dropout s6 rest", 0x56f4657adf298a7c),
    ("160x120 dropout s6 k0", 0x2562c8353d7cb9ac),
    ("160x120 dropout s6 k1001", 0x071f9aaf4b76d556),
    ("160x120 rounded_rect s1 rest", 0x1f4ff38a1f66c844),
    ("160x120 rounded_rect s1 k0", 0x4cdb947f86f2692d),
    ("160x120 rounded_rect s1 k1001", 0x878e29ebb815e6ae),
    ("160x120 rounded_rect s6 rest", 0xca65c94f54f3b1cf),
    ("160x120 rounded_rect s6 k0", 0xd453b7ee8bded528),
    ("160x120 rounded_rect s6 k1001", 0x0ebbd68e9759adca),
    ("160x120 no_contact s1 rest", 0x88e3ce0f5f106170),
    ("160x120 no_contact s1 k0", 0x3ccbdea9f00aa720),
    ("160x120 no_contact s1 k1001", 0x17327cf0ca5d969c),
    ("160x120 no_contact s6 rest", 0x2a08c56abdb73306),
    ("160x120 no_contact s6 k0", 0x6c4ddd58df488819),
    ("160x120 no_contact s6 k1001", 0x9bfd01f966de92c9),
    ("nominal spec rest", 0x9c5a89e8aed05f72),
    ("1280x960 nominal s1 rest", 0x29df1864e7f03dd4),
    ("1280x960 nominal s1 k0", 0x18cf677ebff06959),
    ("1280x960 nominal s1 k1001", 0xc62a4455952906d8),
    ("1280x960 nominal s6 rest", 0x007c8de1f5a2f4f6),
    ("1280x960 nominal s6 k0", 0x5b8b1c3d641ec664),
    ("1280x960 nominal s6 k1001", 0x1852e2446a7a9600),
    ("1280x960 degraded s1 rest", 0x4b016ca8f0ab8698),
    ("1280x960 degraded s1 k0", 0xb9fa088c30c6b6df),
    ("1280x960 degraded s1 k1001", 0x120dd193a2f3c848),
    ("1280x960 degraded s6 rest", 0xf0eed71e9945420b),
    ("1280x960 degraded s6 k0", 0x081916c0c24923a3),
    ("1280x960 degraded s6 k1001", 0x3a2974440fdcb5f3),
    ("1280x960 saturated s1 rest", 0x30d3603865919a55),
    ("1280x960 saturated s1 k0", 0x6fae006a5a99fc63),
    ("1280x960 saturated s1 k1001", 0xc37673c4ca71ba57),
    ("1280x960 saturated s6 rest", 0x24bf9d0a29a18a29),
    ("1280x960 saturated s6 k0", 0xa9326839aa6748b4),
    ("1280x960 saturated s6 k1001", 0xd36bb4dd2bde4b71),
    ("1280x960 rounded_rect s1 rest", 0xb00f97c1928ea736),
    ("1280x960 rounded_rect s1 k0", 0x8f45b578a8d44301),
    ("1280x960 rounded_rect s1 k1001", 0x2cbf69fbcee1cab8),
    ("1280x960 rounded_rect s6 rest", 0x38eab59439f4b315),
    ("1280x960 rounded_rect s6 k0", 0x1f0a16fc45f50789),
    ("1280x960 rounded_rect s6 k1001", 0xcac59da908f52a86),
];

fn render_named(name: &str) -> SynthFrame {
    let parts: Vec<&str> = name.split(' ').collect();
    if name == "nominal spec rest" {
        return synth::rest_frame(&SensorSpec::nominal(640, 480), 3);
    }
    let (w, h) = parts[0].split_once('x').unwrap();
    let (w, h): (usize, usize) = (w.parse().unwrap(), h.parse().unwrap());
    let cat = Category::from_name(parts[1]).unwrap();
    let sensor_seed: u64 = parts[2][1..].parse().unwrap();
    let sensor = cat.sensor(w, h, sensor_seed);
    match parts[3] {
        "rest" => synth::rest_frame(&sensor, sensor_seed ^ 0xA5A5),
        k => synth::render(&cat.scene(&sensor, k[1..].parse().unwrap())),
    }
}

#[test]
fn original_categories_render_byte_identical_frames() {
    let changed: Vec<&str> = LEGACY
        .iter()
        .filter(|(name, want)| fingerprint(&render_named(name)) != *want)
        .map(|(name, _)| *name)
        .collect();
    assert!(changed.is_empty(), "frames changed: {changed:?}");
}

/// The first scene of `cat` on `sensor` from seed `from` on that has a
/// contact.
fn contact_scene(cat: Category, sensor: &SensorSpec, from: u64) -> synth::Scene {
    (from..from + 100)
        .map(|k| cat.scene(sensor, k))
        .find(|s| !s.presses.is_empty())
        .expect("three scenes in four have a contact")
}

fn pixel(f: &SynthFrame, x: i64, y: i64) -> f64 {
    let (w, h) = (f.image.width() as i64, f.image.height() as i64);
    f64::from(f.image.data()[(y.clamp(0, h - 1) * w + x.clamp(0, w - 1)) as usize])
}

/// Brightest pixel within `r` px of `p`.
fn peak_near(f: &SynthFrame, p: PointPx, r: i64) -> f64 {
    let (cx, cy) = (p.x.round() as i64, p.y.round() as i64);
    let mut best = 0f64;
    for y in cy - r..=cy + r {
        for x in cx - r..=cx + r {
            best = best.max(pixel(f, x, y));
        }
    }
    best
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn condition_frames_are_deterministic_for_a_seed() {
    for cat in Category::CONDITIONS {
        let sensor = cat.sensor(320, 240, 3);
        assert_eq!(sensor, cat.sensor(320, 240, 3), "{}", cat.name());
        let a = synth::render(&cat.scene(&sensor, 9));
        let b = synth::render(&cat.scene(&sensor, 9));
        assert_eq!(fingerprint(&a), fingerprint(&b), "{}", cat.name());
        assert_eq!(a.distractors, b.distractors);
        assert_eq!(a.marker_levels, b.marker_levels);
        let c = synth::render(&cat.scene(&sensor, 10));
        assert_ne!(a.image.data(), c.image.data(), "{}", cat.name());
        let r1 = synth::rest_frame(&sensor, 4);
        let r2 = synth::rest_frame(&sensor, 4);
        assert_eq!(fingerprint(&r1), fingerprint(&r2), "{}", cat.name());
    }
}

#[test]
fn every_category_names_itself_and_one_in_four_condition_scenes_is_empty() {
    for cat in Category::ALL.into_iter().chain(Category::CONDITIONS) {
        assert_eq!(Category::from_name(cat.name()), Some(cat));
        assert_eq!(cat.is_condition(), Category::CONDITIONS.contains(&cat));
    }
    let sensor = Category::Dim.sensor(160, 120, 1);
    let empty = (0..400)
        .filter(|&k| Category::Dim.scene(&sensor, k).presses.is_empty())
        .count();
    assert!((70..130).contains(&empty), "{empty} of 400 without contact");
}

#[test]
fn true_markers_lie_inside_the_sensing_area() {
    for cat in Category::ALL.into_iter().chain(Category::CONDITIONS) {
        let sensor = cat.sensor(640, 480, 2);
        let scene = match cat {
            Category::NoContact => cat.scene(&sensor, 0),
            _ => contact_scene(cat, &sensor, 0),
        };
        let f = synth::render(&scene);
        assert_eq!(f.area, sensor.sensing_area());
        assert_eq!(f.markers.len(), f.marker_levels.len());
        assert!(f.markers.len() > 500, "{}: {}", cat.name(), f.markers.len());
        for m in f.rest_markers.iter().chain(&f.markers) {
            assert!(f.area.contains(*m), "{}: {m:?}", cat.name());
        }
        for c in &f.contacts {
            assert!(f.area.contains(*c), "{}: {c:?}", cat.name());
        }
    }
}

#[test]
fn dome_has_about_950_markers_bunching_up_towards_the_rim() {
    let sensor = SensorSpec::domed(640, 480);
    let dome = sensor.dome.unwrap();
    let rest = sensor.rest_markers();
    assert!((900..=1000).contains(&rest.len()), "{}", rest.len());
    let rim = dome.rim_radius_px();
    let radius = |p: &PointPx| (p.x - sensor.centre.x).hypot(p.y - sensor.centre.y);
    let nearest = |p: &PointPx| {
        rest.iter()
            .filter(|q| *q != p)
            .map(|q| (q.x - p.x).hypot(q.y - p.y))
            .fold(f64::INFINITY, f64::min)
    };
    let pitch_in = |lo: f64, hi: f64| {
        median(
            rest.iter()
                .filter(|p| (lo * rim..hi * rim).contains(&radius(p)))
                .map(nearest)
                .collect(),
        )
    };
    let (centre, middle, edge) = (pitch_in(0.0, 0.3), pitch_in(0.5, 0.7), pitch_in(0.9, 1.0));
    assert!((centre - 16.5).abs() < 0.5, "{centre}");
    assert!(edge < middle && middle < centre, "{centre} {middle} {edge}");
    assert!(edge < 0.75 * centre, "{centre} {edge}");
    // The Dome category's sensors: the same layout, 900-1000 markers.
    for seed in 1..5 {
        let n = Category::Dome.sensor(640, 480, seed).rest_markers().len();
        assert!((900..=1000).contains(&n), "seed {seed}: {n}");
    }
}

/// Radial over tangential standard deviation of the bright blob around `m`
/// (background-subtracted intensity moments within `r` px).
fn radial_over_tangential(f: &SynthFrame, centre: PointPx, m: PointPx, r: i64) -> f64 {
    let (ux, uy) = {
        let (dx, dy) = (m.x - centre.x, m.y - centre.y);
        let n = dx.hypot(dy);
        (dx / n, dy / n)
    };
    let (mut s, mut srr, mut stt) = (0.0, 0.0, 0.0);
    let (cx, cy) = (m.x.round() as i64, m.y.round() as i64);
    for y in cy - r..=cy + r {
        for x in cx - r..=cx + r {
            let v = (pixel(f, x, y) - 40.0).max(0.0);
            let (dx, dy) = (x as f64 - m.x, y as f64 - m.y);
            let (a, t) = (dx * ux + dy * uy, -dx * uy + dy * ux);
            s += v;
            srr += v * a * a;
            stt += v * t * t;
        }
    }
    (srr / s).sqrt() / (stt / s).sqrt()
}

#[test]
fn dome_markers_are_ellipses_foreshortened_along_the_radius() {
    // Sparse markers (40 px arc pitch) so that each blob is alone; no noise.
    let mut sensor = SensorSpec::domed(640, 480);
    sensor.pitch_px = 40.0;
    sensor.marker_diameter_px = 12.0;
    sensor.noise_sigma = 0.0;
    let dome = sensor.dome.unwrap();
    let f = synth::rest_frame(&sensor, 1);
    let radius = |p: &PointPx| (p.x - sensor.centre.x).hypot(p.y - sensor.centre.y);
    let outer = *f
        .markers
        .iter()
        .max_by(|a, b| radius(a).total_cmp(&radius(b)))
        .unwrap();
    let inner = *f
        .markers
        .iter()
        .filter(|p| radius(p) > 30.0)
        .min_by(|a, b| radius(a).total_cmp(&radius(b)))
        .unwrap();
    let c_outer = dome.foreshortening(sensor.centre, outer);
    let c_inner = dome.foreshortening(sensor.centre, inner);
    assert!(c_outer < 0.55 && c_inner > 0.95, "{c_outer} {c_inner}");
    let q_outer = radial_over_tangential(&f, sensor.centre, outer, 9);
    let q_inner = radial_over_tangential(&f, sensor.centre, inner, 9);
    // The blob's edge softness widens both axes a little: a thin ellipse
    // measures a bit rounder than cos(theta).
    assert!(
        q_outer < 0.75 && q_outer > c_outer - 0.05,
        "{q_outer} vs {c_outer}"
    );
    assert!((q_inner - 1.0).abs() < 0.08, "{q_inner}");
}

#[test]
fn dome_contact_pushes_markers_away_along_the_dome() {
    let sensor = Category::Dome.sensor(640, 480, 1);
    let dome = sensor.dome.unwrap();
    let press = Press {
        centre: PointPx::new(sensor.centre.x + 120.0, sensor.centre.y - 40.0),
        width_px: 20.0,
        strength: 0.8,
        shear_px: PointPx::new(0.0, 0.0),
        flat_radius_px: 0.0,
    };
    let presses = [press];
    // The truth is the press centre (no shear), up to the lift/project round
    // trip.
    let t = sensor.visible_centre(&press);
    assert!((t.x - press.centre.x).hypot(t.y - press.centre.y) < 1e-9);
    let c = press.centre;
    let mut moved = 0;
    for p in sensor.rest_markers() {
        let u = sensor.displacement_at(p, &presses);
        let (dx, dy) = (p.x - c.x, p.y - c.y);
        let d = dx.hypot(dy);
        if d > 150.0 {
            assert!(u.x.hypot(u.y) < 1e-6, "{p:?} {u:?}");
        } else if d > 5.0 && u.x.hypot(u.y) > 0.5 {
            // Outward from the contact (in the image, up to the dome's
            // curvature) and on the dome (inside the rim).
            assert!(
                (u.x * dx + u.y * dy) / (u.x.hypot(u.y) * d) > 0.8,
                "{p:?} {u:?}"
            );
            moved += 1;
        }
        let q = sensor.displaced(p, &presses);
        assert!(dome.foreshortening(sensor.centre, q) > 0.0);
    }
    assert!(moved > 8, "{moved}");
    // A sheared contact's truth moves along the dome by the shear's arc.
    let sheared = Press {
        shear_px: PointPx::new(3.0, 0.0),
        flat_radius_px: 0.0,
        ..press
    };
    let t = sensor.visible_centre(&sheared);
    assert!(t.x > c.x + 2.0 && t.x < c.x + 3.0, "{t:?}");
}

#[test]
fn housing_lights_and_dust_lie_outside_the_sensing_area() {
    for cat in [Category::Housing, Category::TacTip] {
        for seed in 1..6 {
            let sensor = cat.sensor(640, 480, seed);
            let housing = sensor.housing.clone().unwrap();
            let rest = synth::rest_frame(&sensor, 7);
            let f = synth::render(&contact_scene(cat, &sensor, seed));
            assert_eq!(rest.distractors, f.distractors);
            let leds: Vec<PointPx> = f
                .distractors
                .iter()
                .filter(|d| d.kind == DistractorKind::Led)
                .map(|d| d.at)
                .collect();
            assert!((4..=8).contains(&leds.len()), "{}", leds.len());
            assert_eq!(leds.len(), housing.leds.len());
            assert!(f
                .distractors
                .iter()
                .any(|d| d.kind == DistractorKind::Speck));
            assert!(f
                .distractors
                .iter()
                .any(|d| d.kind == DistractorKind::Reflection));
            for d in &f.distractors {
                let sd = f.area.signed_distance_px(d.at);
                assert!(sd > 1.0, "{:?} at {sd} px from the outline", d.kind);
            }
            for led in &leds {
                // On the bezel, saturated: a small blob clipped at 255.
                let sd = f.area.signed_distance_px(*led);
                assert!(sd < housing.bezel_px, "{sd}");
                let (x, y) = (led.x.round() as i64, led.y.round() as i64);
                if x > 0 && y > 0 && x < 639 && y < 479 {
                    assert_eq!(pixel(&rest, x, y), 255.0);
                    assert!(pixel(&rest, x + 12, y + 12) < 255.0 || sd > 6.0);
                }
            }
            // The housing is bright, the bezel next to the sensing area dark.
            let corner = pixel(&rest, 3, 3);
            assert!(corner > 150.0, "{corner}");
        }
    }
}

#[test]
fn dim_frame_under_changed_light_rest_under_nominal_light() {
    let sensor = Category::Dim.sensor(640, 480, 1);
    assert_eq!(sensor.frame_conditions, FrameConditions::NONE);
    let scene = contact_scene(Category::Dim, &sensor, 0);
    let fc = scene.sensor.frame_conditions;
    assert!((0.30..0.37).contains(&fc.gain), "{fc:?}");
    assert!((0.45..0.65).contains(&fc.corner_light), "{fc:?}");
    assert!((0.25..0.35).contains(&fc.gradient), "{fc:?}");
    assert!(fc.extra_noise_sigma >= 3.0, "{fc:?}");
    // The rest frame of the scene's sensor is that of the category's sensor:
    // its frame conditions are ignored.
    let rest = synth::rest_frame(&sensor, 5);
    assert_eq!(
        rest.image.data(),
        synth::rest_frame(&scene.sensor, 5).image.data()
    );
    let f = synth::render(&scene);
    // Markers (same positions away from the contact) a third as bright.
    let c = f.contacts[0];
    let ratios: Vec<f64> = rest
        .markers
        .iter()
        .filter(|m| (m.x - c.x).hypot(m.y - c.y) > 100.0)
        .map(|m| (peak_near(&f, *m, 1) - 5.0) / (peak_near(&rest, *m, 1) - 5.0))
        .collect();
    let r = median(ratios);
    assert!(r > 0.12 && r < 0.4, "{r}");
    // Vignetting and gradient as specified.
    let (w, h) = (640, 480);
    let plain = FrameConditions {
        gradient: 0.0,
        ..fc
    };
    let corner = plain.light_at(0.0, 0.0, w, h) / plain.light_at(319.5, 239.5, w, h);
    assert!((corner - fc.corner_light).abs() < 1e-9, "{corner}");
    let flat = FrameConditions {
        corner_light: 1.0,
        gain: 1.0,
        ..fc
    };
    let (a, b) = (flat.gradient_angle_rad.cos(), flat.gradient_angle_rad.sin());
    let far = |t: f64| {
        flat.light_at(
            319.5 + t * 320.0 * a.signum(),
            239.5 + t * 240.0 * b.signum(),
            w,
            h,
        )
    };
    assert!((far(1.0) - far(-1.0) - fc.gradient).abs() < 1e-9);
}

#[test]
fn overexposed_markers_clip_with_wide_flat_tops() {
    let sensor = Category::Overexposed.sensor(640, 480, 1);
    let rest = synth::rest_frame(&sensor, 5);
    let f = synth::render(&contact_scene(Category::Overexposed, &sensor, 0));
    let r = (sensor.marker_diameter_px / 2.0) as i64;
    let clipped = |img: &SynthFrame, m: &PointPx| {
        let (cx, cy) = (m.x.round() as i64, m.y.round() as i64);
        let mut n = 0;
        for y in cy - r..=cy + r {
            for x in cx - r..=cx + r {
                n += usize::from(pixel(img, x, y) == 255.0);
            }
        }
        n
    };
    let central: Vec<&PointPx> = f
        .markers
        .iter()
        .filter(|m| (m.x - sensor.centre.x).hypot(m.y - sensor.centre.y) < 100.0)
        .collect();
    let flat: Vec<f64> = central.iter().map(|m| clipped(&f, m) as f64).collect();
    // Most of a 6-8 px disc (28-50 px) is at 255.
    assert!(median(flat) >= 15.0);
    assert!(rest.image.data().iter().all(|&v| v < 255));
}

#[test]
fn blur_lowers_the_marker_peaks() {
    let sensor = Category::Blurred.sensor(640, 480, 1);
    assert!(sensor.psf_sigma_px > 0.9 && sensor.psf_sigma_px < 1.1);
    let scene = contact_scene(Category::Blurred, &sensor, 0);
    let psf = scene.sensor.frame_conditions.psf_sigma_px.unwrap();
    assert!((1.8..2.8).contains(&psf), "{psf}");
    let rest = synth::rest_frame(&sensor, 5);
    let f = synth::render(&scene);
    let c = f.contacts[0];
    let far: Vec<&PointPx> = rest
        .markers
        .iter()
        .filter(|m| (m.x - c.x).hypot(m.y - c.y) > 100.0)
        .collect();
    let rest_peak = median(far.iter().map(|m| peak_near(&rest, **m, 1)).collect());
    let frame_peak = median(far.iter().map(|m| peak_near(&f, **m, 1)).collect());
    assert!(frame_peak < 0.8 * rest_peak, "{frame_peak} vs {rest_peak}");
    // Without the PSF the rest markers peak higher still.
    let mut sharp = sensor.clone();
    sharp.psf_sigma_px = 0.0;
    let sharp_rest = synth::rest_frame(&sharp, 5);
    let sharp_peak = median(far.iter().map(|m| peak_near(&sharp_rest, **m, 1)).collect());
    assert!(rest_peak < sharp_peak, "{rest_peak} vs {sharp_peak}");
}

#[test]
fn gaussian_blur_keeps_the_sum_and_spreads_by_sigma() {
    let (w, h) = (41, 41);
    let mut img = vec![0f32; w * h];
    img[20 * w + 20] = 1000.0;
    dexitac_tactile::frame::gaussian_blur(&mut img, w, h, 2.0);
    let sum: f32 = img.iter().sum();
    assert!((sum - 1000.0).abs() < 0.01, "{sum}");
    let var_x: f64 = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| f64::from(img[y * w + x]) * (x as f64 - 20.0).powi(2))
        .sum::<f64>()
        / 1000.0;
    assert!((var_x - 4.0).abs() < 0.2, "{var_x}");
    assert!((img[20 * w + 17] - img[20 * w + 23]).abs() < 1e-4);
    assert!((img[17 * w + 20] - img[20 * w + 17]).abs() < 1e-4);
    let before = img.clone();
    dexitac_tactile::frame::gaussian_blur(&mut img, w, h, 0.0);
    assert_eq!(img, before);
}

#[test]
fn texture_moves_with_the_skin() {
    // No markers, no noise, no vignetting: the skin's texture alone.
    let mut sensor = Category::Textured.sensor(640, 480, 1);
    let mut texture = sensor.texture.unwrap();
    assert!(texture.follows_skin && (4.0..8.0).contains(&texture.amplitude));
    texture.amplitude = 40.0;
    sensor.texture = Some(texture);
    sensor.marker_contrast = 0.0;
    sensor.noise_sigma = 0.0;
    sensor.vignette = 0.0;
    sensor.skin_level = 100.0;
    let rest = synth::rest_frame(&sensor, 1);
    let press = Press {
        centre: sensor.centre,
        width_px: 30.0,
        strength: 0.9,
        shear_px: PointPx::new(0.0, 0.0),
        flat_radius_px: 0.0,
    };
    let scene = synth::Scene {
        sensor: sensor.clone(),
        presses: vec![press],
        dropout: 0.0,
        seed: 2,
    };
    let f = synth::render(&scene);
    let bilinear = |img: &SynthFrame, p: PointPx| {
        let (x0, y0) = (p.x.floor(), p.y.floor());
        let (fx, fy) = (p.x - x0, p.y - y0);
        let (x, y) = (x0 as i64, y0 as i64);
        (1.0 - fy) * ((1.0 - fx) * pixel(img, x, y) + fx * pixel(img, x + 1, y))
            + fy * ((1.0 - fx) * pixel(img, x, y + 1) + fx * pixel(img, x + 1, y + 1))
    };
    let (mut moving, mut fixed, mut n) = (0.0, 0.0, 0);
    for y in 150..330 {
        for x in 230..410 {
            let p = PointPx::new(x as f64, y as f64);
            let u = sensor.displacement_at(p, &scene.presses);
            if u.x.hypot(u.y) < 4.0 {
                continue;
            }
            let q = PointPx::new(p.x + u.x, p.y + u.y);
            moving += (bilinear(&f, q) - pixel(&rest, x, y)).abs();
            fixed += (pixel(&f, x, y) - pixel(&rest, x, y)).abs();
            n += 1;
        }
    }
    let (moving, fixed) = (moving / n as f64, fixed / n as f64);
    assert!(n > 1000, "{n}");
    assert!(moving < 1.5 && moving < 0.25 * fixed, "{moving} vs {fixed}");
    // Away from the contact the texture is where it was at rest.
    assert_eq!(pixel(&f, 100, 240), pixel(&rest, 100, 240));
}

#[test]
fn two_colour_pins_are_the_same_dim_pins_at_rest_and_in_frames() {
    let sensor = Category::TwoColour.sensor(640, 480, 1);
    let pins = sensor.pin_colours.unwrap();
    let rest = synth::rest_frame(&sensor, 5);
    let f = synth::render(&contact_scene(Category::TwoColour, &sensor, 0));
    assert_eq!(rest.marker_levels, f.marker_levels);
    let dim = f.marker_levels.iter().filter(|&&l| l < 1.0).count();
    let frac = dim as f64 / f.marker_levels.len() as f64;
    assert!(
        (frac - pins.dim_fraction).abs() < 0.04,
        "{frac} vs {pins:?}"
    );
    assert!((0.55..0.65).contains(&pins.dim_level));
    let central =
        |m: &&(PointPx, f64)| (m.0.x - sensor.centre.x).hypot(m.0.y - sensor.centre.y) < 120.0;
    let pairs: Vec<(PointPx, f64)> = rest
        .markers
        .iter()
        .copied()
        .zip(rest.marker_levels.iter().copied())
        .collect();
    let level = |dim: bool| {
        median(
            pairs
                .iter()
                .filter(central)
                .filter(|m| (m.1 < 1.0) == dim)
                .map(|m| peak_near(&rest, m.0, 1) - sensor.skin_level)
                .collect(),
        )
    };
    let ratio = level(true) / level(false);
    assert!((ratio - pins.dim_level).abs() < 0.08, "{ratio}");
}

#[test]
fn rim_clamped_contacts_sit_near_the_rim_with_zero_displacement_at_it() {
    let sensor = Category::RimClamped.sensor(640, 480, 1);
    let clamp = sensor.rim_clamp_px.unwrap();
    assert!((12.0..20.0).contains(&clamp));
    let radius = sensor.sensing_area().shape.inner_radius_px();
    let mut free = sensor.clone();
    free.rim_clamp_px = None;
    for k in 0..40 {
        let scene = Category::RimClamped.scene(&sensor, k);
        let Some(press) = scene.presses.first() else {
            continue;
        };
        let c = press.centre;
        let from_rim = -sensor.sensing_area().signed_distance_px(c);
        assert!((25.0..70.0).contains(&from_rim), "{from_rim}");
        // On the rim, near the contact: no displacement; a little inside,
        // less than the free skin's.
        let (ux, uy) = (
            (c.x - sensor.centre.x) / radius,
            (c.y - sensor.centre.y) / radius,
        );
        let n = ux.hypot(uy);
        let (ux, uy) = (ux / n, uy / n);
        for da in [-0.2, -0.1, 0.0, 0.1, 0.2] {
            let (ca, sa) = (f64::cos(da), f64::sin(da));
            let (rx, ry) = (ux * ca - uy * sa, ux * sa + uy * ca);
            let on_rim = PointPx::new(sensor.centre.x + radius * rx, sensor.centre.y + radius * ry);
            let u = sensor.displacement_at(on_rim, &scene.presses);
            assert!(u.x.hypot(u.y) < 1e-9, "{on_rim:?} {u:?}");
            let near = PointPx::new(on_rim.x - 8.0 * rx, on_rim.y - 8.0 * ry);
            let clamped = sensor.displacement_at(near, &scene.presses);
            let unclamped = free.displacement_at(near, &scene.presses);
            assert!(clamped.x.hypot(clamped.y) <= 0.5 * unclamped.x.hypot(unclamped.y) + 1e-12);
        }
        // No shear: the truth is the press centre.
        let f = synth::render(&scene);
        assert_eq!(f.contacts, vec![c]);
    }
}
