//! Forward kinematics: chamber pressures -> joint variables -> fingertip pose.
//!
//! Each bellows joint is a constant-curvature (CC) arc (Webster & Jones
//! 2010, cited by the paper's Sec. IV-A). An arc of length `s` bent by the
//! angle `theta` in the plane at angle `phi` about the joint axis has the
//! homogeneous transform
//!
//! ```text
//! T = Rz(phi) * [ Ry(theta) | p ] * Rz(-phi),
//! p = ( s (1 - cos theta) / theta, 0, s sin theta / theta )
//! ```
//!
//! which equals the Denavit-Hartenberg product
//! `Rz(phi) Ry(theta/2) Tz(2 (s/theta) sin(theta/2)) Ry(theta/2) Rz(-phi)`
//! ([`arc_dh_product`]; the tests check both agree). At `theta -> 0` both are
//! written with `sinc` so no term divides by zero: the straight joint is
//! `Tz(s)` exactly.
//!
//! A finger is, from its base (palm side) to its tip:
//! connector (thickness t) -> first joint -> two connectors (2 t) -> second
//! joint -> connector (t) -> fingertip sensor. The assembly order
//! ([`FingerType`]) decides whether the Rot or the Dex joint comes first; the
//! transforms are multiplied in that order, as the paper does with its D-H
//! matrices. The finger frame has z along the straight finger, and the Rot
//! joint's positive angle bends towards +x when its bending plane is 0 deg.
//!
//! Units: lengths mm, angles rad inside (deg only in configs and outputs),
//! pressures kPa.

use nalgebra::{IsometryMatrix3, Matrix3, Rotation3, Translation3, Unit, Vector3};

use crate::actuator::{self, DexState, PressureError};
use crate::configuration::{FingerType, GripperConfig, JointGeometry};

/// A rigid transform: rotation matrix and translation (mm), the top three
/// rows of a homogeneous matrix `[R p; 0 0 0 1]` ([`IsometryMatrix3`] of
/// nalgebra, which keeps the rotation as a 3x3 matrix). `a * b` is `a`
/// then `b` in `a`'s frame (post-multiplication, as along a kinematic
/// chain); `t * point` maps a point of the child frame to the parent frame;
/// `t.translation.vector` is the origin of the child frame in mm.
pub type Transform = IsometryMatrix3<f64>;

/// A pure translation, mm.
pub fn translation(x_mm: f64, y_mm: f64, z_mm: f64) -> Transform {
    Transform::from_parts(Translation3::new(x_mm, y_mm, z_mm), Rotation3::identity())
}

/// A pure rotation by `angle_rad` about a coordinate axis. For a unit
/// coordinate axis nalgebra's axis-angle formula multiplies only by 0 and
/// 1, so the matrix is the textbook `Rx`, `Ry` or `Rz` exactly.
fn about(axis: Unit<Vector3<f64>>, angle_rad: f64) -> Transform {
    Transform::from_parts(
        Translation3::identity(),
        Rotation3::from_axis_angle(&axis, angle_rad),
    )
}

/// Rotation about the y axis by `angle_rad`.
pub fn rot_y(angle_rad: f64) -> Transform {
    about(Vector3::y_axis(), angle_rad)
}

/// Rotation about the z axis by `angle_rad`.
pub fn rot_z(angle_rad: f64) -> Transform {
    about(Vector3::z_axis(), angle_rad)
}

/// Roll-pitch-yaw: `Rz(yaw) * Ry(pitch) * Rx(roll)`, angles in rad.
pub fn from_rpy(roll_rad: f64, pitch_rad: f64, yaw_rad: f64) -> Transform {
    Transform::from_parts(
        Translation3::identity(),
        Rotation3::from_euler_angles(roll_rad, pitch_rad, yaw_rad),
    )
}

/// `sin(x) / x`, exact 1 at 0. Below |x| = 1e-4 the Taylor series
/// `1 - x^2/6 + x^4/120` is used; its error there is below 1e-22.
pub fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-4 {
        let x2 = x * x;
        1.0 - x2 / 6.0 + x2 * x2 / 120.0
    } else {
        x.sin() / x
    }
}

/// The CC arc transform (closed form): length `length_mm`, bending angle
/// `theta_rad` (= curvature x length), bending plane `phi_rad` about z.
///
/// Written without any `1/theta`: `(1 - cos t)/t = (t/2) sinc(t/2)^2` and
/// `sin t / t = sinc t`, so `theta = 0` gives the straight `Tz(length)`.
///
/// ```
/// use dexitac_gripper::kinematics::arc;
/// let quarter = arc(26.0, std::f64::consts::FRAC_PI_2, 0.0);
/// let r = 26.0 / std::f64::consts::FRAC_PI_2; // radius of curvature
/// assert!((quarter.translation.vector.x - r).abs() < 1e-12);
/// assert!((quarter.translation.vector.z - r).abs() < 1e-12);
/// ```
pub fn arc(length_mm: f64, theta_rad: f64, phi_rad: f64) -> Transform {
    let (sin_phi, cos_phi) = phi_rad.sin_cos();
    arc_in_plane(length_mm, theta_rad, cos_phi, sin_phi)
}

/// [`arc`] with the bending plane given by its unit direction
/// `(cos_phi, sin_phi)`; the matrix `Rz(phi) Ry(theta) Rz(-phi)` written out
/// from one `sin_cos(theta / 2)` (the hot path of the workspace sampler).
fn arc_in_plane(length_mm: f64, theta_rad: f64, cos_phi: f64, sin_phi: f64) -> Transform {
    let half = 0.5 * theta_rad;
    let (sh, ch) = half.sin_cos();
    let sinc_half = if half.abs() < 1e-4 {
        sinc(half)
    } else {
        sh / half
    };
    // (1 - cos t)/t = (t/2) sinc(t/2)^2; sin t / t = sinc(t/2) cos(t/2).
    let in_plane_mm = length_mm * half * sinc_half * sinc_half;
    let along_mm = length_mm * sinc_half * ch;
    let cos_t = 1.0 - 2.0 * sh * sh;
    let sin_t = 2.0 * sh * ch;
    let (c, s) = (cos_phi, sin_phi);
    let k = cos_t - 1.0;
    #[rustfmt::skip]
    let rotation = Matrix3::new(
        1.0 + c * c * k, s * c * k,       c * sin_t,
        s * c * k,       1.0 + s * s * k, s * sin_t,
        -c * sin_t,      -s * sin_t,      cos_t,
    );
    Transform::from_parts(
        Translation3::new(in_plane_mm * c, in_plane_mm * s, along_mm),
        // Orthonormal by construction (the tests check it).
        Rotation3::from_matrix_unchecked(rotation),
    )
}

/// The same arc as [`arc`], built as the product of elementary D-H style
/// transforms `Rz(phi) Ry(theta/2) Tz(chord) Ry(theta/2) Rz(-phi)` with
/// `chord = length * sinc(theta/2)` (Webster & Jones 2010, Sec. 3.1.2).
pub fn arc_dh_product(length_mm: f64, theta_rad: f64, phi_rad: f64) -> Transform {
    let chord_mm = length_mm * sinc(0.5 * theta_rad);
    rot_z(phi_rad)
        * rot_y(0.5 * theta_rad)
        * translation(0.0, 0.0, chord_mm)
        * rot_y(0.5 * theta_rad)
        * rot_z(-phi_rad)
}

/// The joint variables of one finger.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FingerJoints {
    /// Rot joint bending angle, rad (positive towards the bending plane).
    pub rot_angle_rad: f64,
    /// Dex joint state.
    pub dex: DexState,
}

/// Transform of the Rot joint (CC arc of fixed length in its bending plane).
pub fn rot_transform(geometry: &JointGeometry, rot_angle_rad: f64) -> Transform {
    arc(
        geometry.rot_length_mm,
        rot_angle_rad,
        geometry.rot_bend_plane_deg.to_radians(),
    )
}

/// Transform of the Dex joint (CC arc: bend vector and current length).
pub fn dex_transform(dex: &DexState) -> Transform {
    let theta_rad = dex.bend_rad();
    if theta_rad > 0.0 {
        let (c, s) = (dex.bend_x_rad / theta_rad, dex.bend_y_rad / theta_rad);
        arc_in_plane(dex.length_mm, theta_rad, c, s)
    } else {
        // The plane is irrelevant for a straight joint.
        arc_in_plane(dex.length_mm, 0.0, 1.0, 0.0)
    }
}

/// Fingertip pose in the finger's base frame for given joint variables,
/// multiplying the joint transforms in the assembly order of `finger`.
pub fn fingertip_pose(
    geometry: &JointGeometry,
    finger: FingerType,
    joints: &FingerJoints,
) -> Transform {
    let rot = rot_transform(geometry, joints.rot_angle_rad);
    let dex = dex_transform(&joints.dex);
    let (first, second) = match finger {
        FingerType::RotDex => (rot, dex),
        FingerType::DexRot => (dex, rot),
    };
    base_part(geometry, &first) * tip_part(geometry, &second)
}

/// The palm half of the chain: `Tz(t) * first joint`. The fingertip pose
/// is `base_part(first) * tip_part(second)`; the workspace sampler
/// precomputes each half once per joint state.
pub fn base_part(geometry: &JointGeometry, first_joint: &Transform) -> Transform {
    translation(0.0, 0.0, geometry.connector_thickness_mm) * first_joint
}

/// The tip half of the chain: `Tz(2 t) * second joint * Tz(t + fingertip)`.
pub fn tip_part(geometry: &JointGeometry, second_joint: &Transform) -> Transform {
    let t_mm = geometry.connector_thickness_mm;
    translation(0.0, 0.0, 2.0 * t_mm)
        * second_joint
        * translation(0.0, 0.0, t_mm + geometry.fingertip_length_mm)
}

/// Forward kinematics of one finger: Rot chamber and the three Dex chamber
/// pressures (kPa) -> fingertip pose in the finger's base frame.
///
/// Pressures are clamped to the configured pressure range and joint
/// variables to the joint limits; a non-finite pressure is an error.
pub fn finger_forward(
    config: &GripperConfig,
    finger: FingerType,
    rot_kpa: f64,
    dex_kpa: [f64; 3],
) -> Result<Transform, PressureError> {
    let rot_angle_rad = actuator::rot_angle_rad(&config.rot, &config.pressure, rot_kpa)?;
    let dex = actuator::dex_state(&config.dex, &config.pressure, dex_kpa)?;
    let joints = FingerJoints { rot_angle_rad, dex };
    Ok(fingertip_pose(&config.geometry, finger, &joints))
}

/// Forward kinematics of the whole gripper: the 8 chamber pressures (kPa,
/// indexed like the protocol's chambers) -> each finger's fingertip pose in
/// the palm frame, in the order of `config.fingers`.
pub fn gripper_forward(
    config: &GripperConfig,
    chamber_kpa: &[f64; dexitac_protocol::CHAMBER_COUNT],
) -> Result<Vec<Transform>, PressureError> {
    config
        .fingers
        .iter()
        .map(|mount| {
            let pick = |chamber: usize| chamber_kpa[chamber];
            let dex_kpa = mount.dex_chambers.map(pick);
            let tip = finger_forward(config, config.finger, pick(mount.rot_chamber), dex_kpa)?;
            Ok(mount.transform() * tip)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point3;
    use proptest::prelude::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    fn close(a: f64, b: f64, tol: f64) -> bool {
        (a - b).abs() <= tol
    }

    fn assert_orthonormal(r: &Matrix3<f64>, tol: f64) {
        let rrt = r * r.transpose();
        for i in 0..3 {
            for j in 0..3 {
                let dot = rrt[(i, j)];
                let want = if i == j { 1.0 } else { 0.0 };
                assert!(close(dot, want, tol), "R R^T [{i}][{j}] = {dot}");
            }
        }
        assert!(
            close(r.determinant(), 1.0, tol),
            "det = {}",
            r.determinant()
        );
    }

    fn assert_transforms_close(a: &Transform, b: &Transform, tol: f64) {
        let (ma, mb) = (a.to_homogeneous(), b.to_homogeneous());
        for i in 0..4 {
            for j in 0..4 {
                assert!(
                    close(ma[(i, j)], mb[(i, j)], tol),
                    "[{i}][{j}]: {} vs {}",
                    ma[(i, j)],
                    mb[(i, j)]
                );
            }
        }
    }

    /// The frame's z axis in parent coordinates: the finger's pointing
    /// direction at a fingertip pose.
    fn z_axis(t: &Transform) -> Vector3<f64> {
        t.rotation * Vector3::z()
    }

    #[test]
    fn zero_curvature_gives_a_straight_joint_of_the_right_length() {
        for phi in [0.0, 1.0, -2.5] {
            let t = arc(26.0, 0.0, phi);
            assert_eq!(t.translation.vector, Vector3::new(0.0, 0.0, 26.0));
            assert_transforms_close(&t, &translation(0.0, 0.0, 26.0), 1e-15);
        }
    }

    #[test]
    fn tiny_curvature_is_continuous_with_the_straight_joint() {
        // Both sides of the series threshold agree with the exact formula.
        for theta in [1e-300, 1e-12, 9.99e-5, 1.0001e-4, 1e-3] {
            let t = arc(30.0, theta, 0.0);
            let exact_x = 30.0 * (1.0 - f64::cos(theta)) / theta;
            let exact_z = 30.0 * f64::sin(theta) / theta;
            // 1 - cos(theta) cancels catastrophically for tiny theta, so
            // compare x against its leading term s*theta/2 there.
            let want_x = if theta < 1e-3 { 15.0 * theta } else { exact_x };
            assert!(close(t.translation.vector.x, want_x, 1e-12 * 30.0));
            assert!(close(t.translation.vector.z, exact_z, 1e-12 * 30.0));
        }
    }

    #[test]
    fn quarter_circle_ends_at_the_closed_form_point() {
        let l = 26.0;
        let theta = FRAC_PI_2;
        let t = arc(l, theta, 0.0);
        let x = l / theta * (1.0 - theta.cos());
        let z = l / theta * theta.sin();
        assert!(close(t.translation.vector.x, x, 1e-12));
        assert!(close(t.translation.vector.y, 0.0, 1e-12));
        assert!(close(t.translation.vector.z, z, 1e-12));
        // Tangent at the end points along +x.
        let zt = z_axis(&t);
        assert!(close(zt[0], 1.0, 1e-12) && close(zt[2], 0.0, 1e-12));
    }

    #[test]
    fn half_circle_ends_one_diameter_to_the_side() {
        let l = 10.0 * PI; // radius 10 mm
        let t = arc(l, PI, FRAC_PI_2); // bend towards +y
        assert!(close(t.translation.vector.x, 0.0, 1e-12));
        assert!(close(t.translation.vector.y, 20.0, 1e-12));
        assert!(close(t.translation.vector.z, 0.0, 1e-12));
    }

    #[test]
    fn full_circle_returns_to_the_start_pointing_the_same_way() {
        let t = arc(50.0, 2.0 * PI, 0.3);
        assert_transforms_close(&t, &Transform::identity(), 1e-12);
    }

    #[test]
    fn rpy_matches_the_elementary_rotations() {
        let t = from_rpy(0.0, FRAC_PI_2, 0.0);
        let z = z_axis(&t);
        assert!(close(z[0], 1.0, 1e-15) && close(z[2], 0.0, 1e-15));
        // nalgebra's Euler angles are the same convention as the product.
        let (roll, pitch, yaw) = (0.3, -1.1, 2.4);
        let product = rot_z(yaw) * rot_y(pitch) * about(Vector3::x_axis(), roll);
        assert_transforms_close(&from_rpy(roll, pitch, yaw), &product, 1e-15);
    }

    #[test]
    fn zero_pressure_fingers_stand_straight_out_of_their_mounts() {
        for preset in crate::configuration::Preset::ALL {
            let c = preset.config();
            let tips = gripper_forward(&c, &[0.0; 8]).unwrap();
            // 2 + 26 + 2*2 + 26 + 2 + 31 mm.
            let length_mm = 91.0;
            for (mount, tip) in c.fingers.iter().zip(&tips) {
                let base = mount.transform();
                let axis = z_axis(&base);
                for (k, a) in axis.iter().enumerate() {
                    let want = base.translation.vector[k] + length_mm * a;
                    assert!(close(tip.translation.vector[k], want, 1e-9), "{preset:?}");
                }
                assert_transforms_close(
                    &Transform::from_parts(Translation3::identity(), tip.rotation),
                    &Transform::from_parts(Translation3::identity(), base.rotation),
                    1e-12,
                );
            }
        }
    }

    #[test]
    fn fingers_reject_nan_pressures() {
        let c = crate::configuration::Preset::HookGrip.config();
        let mut p = [0.0; 8];
        p[5] = f64::NAN;
        assert!(gripper_forward(&c, &p).is_err());
        assert!(finger_forward(&c, FingerType::RotDex, f64::NAN, [0.0; 3]).is_err());
    }

    proptest! {
        #[test]
        fn any_finite_pressures_give_a_valid_pose_within_reach(
            p in proptest::array::uniform4(-1e6f64..1e6),
            dex_rot in any::<bool>(),
        ) {
            let c = crate::configuration::Preset::PinchGrip.config();
            let finger = if dex_rot { FingerType::DexRot } else { FingerType::RotDex };
            let t = finger_forward(&c, finger, p[0], [p[1], p[2], p[3]]).unwrap();
            assert_orthonormal(t.rotation.matrix(), 1e-9);
            let [x, y, z]: [f64; 3] = t.translation.vector.into();
            prop_assert!((x * x + y * y + z * z).sqrt() <= crate::workspace::reach_mm(&c) + 1e-9);
            // Beyond the tank range the pose is the one at the limit.
            let clamp = |v: f64| v.clamp(c.pressure.min_kpa, c.pressure.max_kpa);
            let at_limit = finger_forward(&c, finger, clamp(p[0]), [clamp(p[1]), clamp(p[2]), clamp(p[3])]).unwrap();
            prop_assert_eq!(t, at_limit);
        }

        #[test]
        fn closed_form_arc_equals_the_dh_product(
            length in 0.0f64..200.0,
            theta in -7.0f64..7.0,
            phi in -7.0f64..7.0,
        ) {
            assert_transforms_close(
                &arc(length, theta, phi),
                &arc_dh_product(length, theta, phi),
                1e-9 * (1.0 + length),
            );
        }

        #[test]
        fn composed_rotations_stay_orthonormal(
            angles in proptest::collection::vec((-10.0f64..10.0, -10.0f64..10.0, -10.0f64..10.0), 1..20),
        ) {
            let mut t = Transform::identity();
            for (a, b, c) in angles {
                t = t * arc(20.0, a, b) * from_rpy(a, b, c);
            }
            assert_orthonormal(t.rotation.matrix(), 1e-9);
        }

        #[test]
        fn composition_is_associative_and_applies_in_order(
            a in -4.0f64..4.0, b in -4.0f64..4.0, c in -4.0f64..4.0,
            p in proptest::array::uniform3(-100.0f64..100.0),
        ) {
            let ta = arc(26.0, a, b);
            let tb = from_rpy(b, c, a) * translation(1.0, -2.0, 3.0);
            let tc = arc(13.0, c, a);
            assert_transforms_close(&(ta * tb * tc), &(ta * (tb * tc)), 1e-9);
            let p = Point3::from(p);
            let direct = (ta * tb) * p;
            let stepwise = ta * (tb * p);
            for k in 0..3 {
                prop_assert!(close(direct[k], stepwise[k], 1e-9));
            }
        }

        #[test]
        fn arc_end_lies_on_its_circle_and_keeps_the_chord(
            length in 0.1f64..100.0,
            theta in 0.01f64..6.2,
            phi in -3.2f64..3.2,
        ) {
            let t = arc(length, theta, phi);
            let [x, y, z]: [f64; 3] = t.translation.vector.into();
            let radius = length / theta;
            // Centre of curvature at radius * (cos phi, sin phi, 0).
            let (cx, cy) = (radius * phi.cos(), radius * phi.sin());
            let dist = ((x - cx).powi(2) + (y - cy).powi(2) + z * z).sqrt();
            prop_assert!(close(dist, radius, 1e-9 * (1.0 + radius)));
            let chord = (x * x + y * y + z * z).sqrt();
            prop_assert!(close(chord, 2.0 * radius * (theta / 2.0).sin(), 1e-9 * (1.0 + length)));
        }
    }
}
