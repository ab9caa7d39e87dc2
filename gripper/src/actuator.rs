//! Actuator model: chamber pressure (kPa) -> joint variables, and its
//! least-squares calibration from measured (pressure, angle) pairs.
//!
//! The paper (Sec. III-A, Fig. 6) measures each joint's angle against the
//! pressure difference (chamber gauge pressure: positive from the + tank,
//! negative from the - tank) and finds it approximately linear:
//! `angle_deg = slope_deg_per_kpa * pressure_kpa + intercept_deg`.
//!
//! * **Rot joint** (one chamber): that line, clamped to the joint limits.
//! * **Dex joint** (three chambers at 120 deg about the joint axis): the
//!   linearised constant-curvature model of Webster & Jones (2010, Sec. 3.2):
//!   with chamber lengths `l_i = l0 + c p_i`, the arc length is the mean
//!   `l0 + c mean(p)` and the bending vector is `(2 c / 3 r) |sum p_i u_i|`
//!   pointing away from the chambers that extend most (`u_i` the unit vector
//!   to chamber i). So one chamber alone at `p` bends the joint by
//!   `bend_slope_deg_per_kpa * p` (the Fig. 6(b) line), equal pressures only
//!   extend it, and the bend magnitude is clamped to `max_bend_deg`.
//!
//! Pressures are first clamped to the pressure range (the tank limits,
//! +50 / -57 kPa by default); NaN or infinite pressures are rejected.
//!
//! The slopes and limits in [`RotActuator::default`] and
//! [`DexActuator::default`] are **not** from the paper (Fig. 6's data are
//! not in its text): they are plausible placeholders, to be replaced by a
//! calibration with `dexitac fit-actuator` ([`fit_line`]).

use std::f64::consts::TAU;

use serde::Deserialize;

/// Rot joint bending per kPa (placeholder, see the module doc).
pub const ROT_SLOPE_DEG_PER_KPA: f64 = 1.5;
/// Rot joint limits, deg (placeholder).
pub const ROT_LIMIT_DEG: f64 = 75.0;
/// Dex joint bending per kPa of one chamber (placeholder).
pub const DEX_BEND_SLOPE_DEG_PER_KPA: f64 = 0.9;
/// Dex joint maximum bend, deg (placeholder).
pub const DEX_MAX_BEND_DEG: f64 = 45.0;
/// Dex joint extension per kPa of mean chamber pressure (placeholder).
pub const DEX_EXTENSION_MM_PER_KPA: f64 = 0.1;
/// Dex joint length limits, mm (placeholder: 26 mm rest length -4 / +5 mm).
pub const DEX_LENGTH_LIMITS_MM: [f64; 2] = [22.0, 31.0];

/// Error: a pressure that cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum PressureError {
    /// A chamber pressure is NaN or infinite.
    #[error("chamber pressure is not a finite number: {0} kPa")]
    NotFinite(f64),
}

/// The chamber pressure range, kPa (defaults: the tank limits).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PressureRange {
    /// Lowest chamber pressure (the - tank), kPa.
    pub min_kpa: f64,
    /// Highest chamber pressure (the + tank), kPa.
    pub max_kpa: f64,
}

impl Default for PressureRange {
    fn default() -> Self {
        Self {
            min_kpa: f64::from(dexitac_protocol::limits::NEGATIVE_TANK_MIN_KPA),
            max_kpa: f64::from(dexitac_protocol::limits::POSITIVE_TANK_MAX_KPA),
        }
    }
}

impl PressureRange {
    /// Clamps a finite pressure into the range; rejects NaN and infinities.
    pub fn clamp(&self, pressure_kpa: f64) -> Result<f64, PressureError> {
        if !pressure_kpa.is_finite() {
            return Err(PressureError::NotFinite(pressure_kpa));
        }
        Ok(pressure_kpa.clamp(self.min_kpa, self.max_kpa))
    }
}

/// Rot joint actuator: one chamber, angle linear in pressure.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RotActuator {
    /// Angle per kPa, deg/kPa.
    pub slope_deg_per_kpa: f64,
    /// Angle at 0 kPa, deg.
    pub intercept_deg: f64,
    /// Lower joint limit, deg.
    pub min_angle_deg: f64,
    /// Upper joint limit, deg.
    pub max_angle_deg: f64,
}

impl Default for RotActuator {
    fn default() -> Self {
        Self {
            slope_deg_per_kpa: ROT_SLOPE_DEG_PER_KPA,
            intercept_deg: 0.0,
            min_angle_deg: -ROT_LIMIT_DEG,
            max_angle_deg: ROT_LIMIT_DEG,
        }
    }
}

/// Dex joint actuator: three chambers, bending in two directions plus
/// extension.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DexActuator {
    /// Arc length at 0 kPa in every chamber, mm (paper Table I: h = 26 mm).
    pub rest_length_mm: f64,
    /// Direction of chamber 0 about the joint axis, deg from +x; chambers
    /// 1 and 2 follow at +120 and +240 deg.
    pub first_chamber_deg: f64,
    /// Bend per kPa with one chamber pressurised alone, deg/kPa.
    pub bend_slope_deg_per_kpa: f64,
    /// Largest bend angle, deg.
    pub max_bend_deg: f64,
    /// Length change per kPa of mean chamber pressure, mm/kPa.
    pub extension_slope_mm_per_kpa: f64,
    /// Shortest arc length, mm.
    pub min_length_mm: f64,
    /// Longest arc length, mm.
    pub max_length_mm: f64,
}

impl Default for DexActuator {
    fn default() -> Self {
        Self {
            rest_length_mm: crate::configuration::ACTUATOR_LENGTH_MM,
            first_chamber_deg: 0.0,
            bend_slope_deg_per_kpa: DEX_BEND_SLOPE_DEG_PER_KPA,
            max_bend_deg: DEX_MAX_BEND_DEG,
            extension_slope_mm_per_kpa: DEX_EXTENSION_MM_PER_KPA,
            min_length_mm: DEX_LENGTH_LIMITS_MM[0],
            max_length_mm: DEX_LENGTH_LIMITS_MM[1],
        }
    }
}

/// The Dex joint's variables.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DexState {
    /// Bend angle component towards the joint's +x, rad.
    pub bend_x_rad: f64,
    /// Bend angle component towards the joint's +y, rad.
    pub bend_y_rad: f64,
    /// Arc length, mm.
    pub length_mm: f64,
}

impl DexState {
    /// Total bend angle, rad.
    pub fn bend_rad(&self) -> f64 {
        self.bend_x_rad.hypot(self.bend_y_rad)
    }
}

/// Rot joint angle (rad) for a chamber pressure (kPa).
pub fn rot_angle_rad(
    rot: &RotActuator,
    range: &PressureRange,
    pressure_kpa: f64,
) -> Result<f64, PressureError> {
    let p_kpa = range.clamp(pressure_kpa)?;
    let angle_deg = rot.slope_deg_per_kpa * p_kpa + rot.intercept_deg;
    Ok(angle_deg
        .clamp(rot.min_angle_deg, rot.max_angle_deg)
        .to_radians())
}

/// Dex joint variables for its three chamber pressures (kPa).
pub fn dex_state(
    dex: &DexActuator,
    range: &PressureRange,
    pressures_kpa: [f64; 3],
) -> Result<DexState, PressureError> {
    let mut sum = [0.0_f64; 2];
    let mut mean_kpa = 0.0;
    // Unit vector to chamber 0, then rotated by 120 deg per chamber.
    let (mut uy, mut ux) = dex.first_chamber_deg.to_radians().sin_cos();
    let (s120, c120) = (TAU / 3.0).sin_cos();
    for &p in &pressures_kpa {
        let p_kpa = range.clamp(p)?;
        sum[0] += p_kpa * ux;
        sum[1] += p_kpa * uy;
        mean_kpa += p_kpa / 3.0;
        (ux, uy) = (c120 * ux - s120 * uy, s120 * ux + c120 * uy);
    }
    // Bend away from the chambers that extend most.
    let slope_rad = dex.bend_slope_deg_per_kpa.to_radians();
    let (mut bx, mut by) = (-slope_rad * sum[0], -slope_rad * sum[1]);
    let bend = bx.hypot(by);
    let max_rad = dex.max_bend_deg.to_radians();
    if bend > max_rad {
        let scale = max_rad / bend;
        bx *= scale;
        by *= scale;
    }
    let length_mm = (dex.rest_length_mm + dex.extension_slope_mm_per_kpa * mean_kpa)
        .clamp(dex.min_length_mm, dex.max_length_mm);
    Ok(DexState {
        bend_x_rad: bx,
        bend_y_rad: by,
        length_mm,
    })
}

/// Fewest points [`fit_line`] accepts: two points always fit exactly, so a
/// third is needed before the residuals say anything.
pub const MIN_FIT_POINTS: usize = 3;

/// Error of the actuator calibration.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// A CSV row is not two numbers.
    #[error("line {line}: expected `pressure_kpa,angle_deg` (two numbers), got {content:?}")]
    BadRow {
        /// 1-based line number in the file.
        line: usize,
        /// The offending line.
        content: String,
    },
    /// A CSV value is NaN or infinite.
    #[error("line {line}: value is not finite: {content:?}")]
    NotFinite {
        /// 1-based line number in the file.
        line: usize,
        /// The offending line.
        content: String,
    },
    /// Fewer than [`MIN_FIT_POINTS`] points.
    #[error("too few points: {got} (need at least {MIN_FIT_POINTS})")]
    TooFewPoints {
        /// Number of points given.
        got: usize,
    },
    /// All pressures (nearly) equal: the slope is undetermined.
    #[error("degenerate data: all pressures are equal (spread {spread_kpa} kPa)")]
    ConstantPressure {
        /// Largest minus smallest pressure, kPa.
        spread_kpa: f64,
    },
    /// The values are so large that the sums overflow.
    #[error("values too large to fit (sums overflow f64)")]
    Overflow,
    /// All angles equal: the joint did not move, R^2 is undefined.
    #[error("degenerate data: the angle never changes ({angle_deg} deg): did the joint move?")]
    ConstantAngle {
        /// The constant angle, deg.
        angle_deg: f64,
    },
}

/// A least-squares line `angle = slope * pressure + intercept` and its fit
/// quality.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct LineFit {
    /// Slope, deg/kPa.
    pub slope_deg_per_kpa: f64,
    /// Intercept (angle at 0 kPa), deg.
    pub intercept_deg: f64,
    /// Coefficient of determination, 1 - SS_res / SS_tot.
    pub r_squared: f64,
    /// Root mean square residual, deg.
    pub rms_residual_deg: f64,
    /// Largest absolute residual, deg.
    pub max_abs_residual_deg: f64,
    /// Number of points.
    pub points: usize,
}

/// Parses `pressure_kpa,angle_deg` rows with the `csv` crate. Blank lines
/// and lines starting with `#` are skipped; fields are trimmed; a first row
/// of two fields that are not numbers is a header. Errors name the 1-based
/// line and carry its text.
pub fn parse_csv(text: &str) -> Result<Vec<(f64, f64)>, FitError> {
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .trim(csv::Trim::All)
        .comment(Some(b'#'))
        .from_reader(text.as_bytes());
    // The line's text as written, for the error.
    let raw = |byte: u64| {
        let start = usize::try_from(byte).unwrap_or(usize::MAX).min(text.len());
        text.get(start..)
            .and_then(|rest| rest.lines().next())
            .unwrap_or_default()
            .to_owned()
    };
    let mut points = Vec::new();
    let mut seen_data_or_header = false;
    for record in reader.records() {
        let record = match record {
            Ok(r) => r,
            Err(e) => {
                let (line, byte) = e.position().map_or((0, 0), |p| (p.line(), p.byte()));
                return Err(FitError::BadRow {
                    line: usize::try_from(line).unwrap_or(usize::MAX),
                    content: raw(byte),
                });
            }
        };
        let (line, byte) = record.position().map_or((0, 0), |p| (p.line(), p.byte()));
        let first = record.get(0).unwrap_or_default();
        // Blank, or a comment after leading blanks (the reader's own
        // comment rule takes `#` only in the first column).
        if (record.len() == 1 && first.is_empty()) || first.starts_with('#') {
            continue;
        }
        let line = usize::try_from(line).unwrap_or(usize::MAX);
        let parsed = match (record.len(), record.get(0), record.get(1)) {
            (2, Some(a), Some(b)) => a.parse::<f64>().ok().zip(b.parse::<f64>().ok()),
            _ => None,
        };
        let is_first = !seen_data_or_header;
        seen_data_or_header = true;
        match parsed {
            Some((p, a)) if p.is_finite() && a.is_finite() => points.push((p, a)),
            Some(_) => {
                return Err(FitError::NotFinite {
                    line,
                    content: raw(byte),
                })
            }
            // A non-numeric first row of two fields is the header.
            None if is_first && record.len() == 2 => {}
            None => {
                return Err(FitError::BadRow {
                    line,
                    content: raw(byte),
                })
            }
        }
    }
    Ok(points)
}

/// Ordinary least squares of `angle` on `pressure` (centred sums, so large
/// offsets do not cost precision).
///
/// ```
/// let pts = [(0.0, 1.0), (10.0, 16.0), (20.0, 31.0), (30.0, 46.0)];
/// let fit = dexitac_gripper::actuator::fit_line(&pts).unwrap();
/// assert!((fit.slope_deg_per_kpa - 1.5).abs() < 1e-12);
/// assert!((fit.intercept_deg - 1.0).abs() < 1e-12);
/// ```
pub fn fit_line(points: &[(f64, f64)]) -> Result<LineFit, FitError> {
    let n = points.len();
    if n < MIN_FIT_POINTS {
        return Err(FitError::TooFewPoints { got: n });
    }
    let nf = n as f64;
    let mean_p = points.iter().map(|q| q.0).sum::<f64>() / nf;
    let mean_a = points.iter().map(|q| q.1).sum::<f64>() / nf;
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    let (mut p_min, mut p_max) = (f64::INFINITY, f64::NEG_INFINITY);
    for &(p, a) in points {
        let (dp, da) = (p - mean_p, a - mean_a);
        sxx += dp * dp;
        sxy += dp * da;
        syy += da * da;
        p_min = p_min.min(p);
        p_max = p_max.max(p);
    }
    if ![mean_p, mean_a, sxx, sxy, syy]
        .iter()
        .all(|v| v.is_finite())
    {
        return Err(FitError::Overflow);
    }
    // Spread below ~1e-9 of the pressures' magnitude is rounding noise.
    let spread_kpa = p_max - p_min;
    if spread_kpa <= 1e-9 * (1.0 + mean_p.abs()) {
        return Err(FitError::ConstantPressure { spread_kpa });
    }
    if syy == 0.0 {
        return Err(FitError::ConstantAngle { angle_deg: mean_a });
    }
    let slope = sxy / sxx;
    let intercept = mean_a - slope * mean_p;
    let mut ss_res = 0.0;
    let mut max_abs: f64 = 0.0;
    for &(p, a) in points {
        let r = a - (slope * p + intercept);
        ss_res += r * r;
        max_abs = max_abs.max(r.abs());
    }
    if !(slope.is_finite() && intercept.is_finite() && ss_res.is_finite()) {
        return Err(FitError::Overflow);
    }
    Ok(LineFit {
        slope_deg_per_kpa: slope,
        intercept_deg: intercept,
        r_squared: 1.0 - ss_res / syy,
        rms_residual_deg: (ss_res / nf).sqrt(),
        max_abs_residual_deg: max_abs,
        points: n,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Deterministic pseudo-noise in [-1, 1] (SplitMix64), so the test is
    /// reproducible without a RNG dependency.
    fn noise(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *seed;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    #[test]
    fn fit_recovers_a_known_line_from_noisy_data() {
        let mut seed = 7;
        let pts: Vec<(f64, f64)> = (0..200)
            .map(|i| {
                let p = -57.0 + 107.0 * i as f64 / 199.0;
                (p, 1.3 * p - 4.0 + 0.5 * noise(&mut seed))
            })
            .collect();
        let fit = fit_line(&pts).unwrap();
        assert!((fit.slope_deg_per_kpa - 1.3).abs() < 0.01, "{fit:?}");
        assert!((fit.intercept_deg + 4.0).abs() < 0.2, "{fit:?}");
        assert!(fit.r_squared > 0.999, "{fit:?}");
        // Uniform noise in [-0.5, 0.5] has RMS 0.5/sqrt(3) = 0.289.
        assert!((fit.rms_residual_deg - 0.289).abs() < 0.05, "{fit:?}");
        assert!(fit.max_abs_residual_deg <= 0.5 + 0.05, "{fit:?}");
        assert_eq!(fit.points, 200);
    }

    #[test]
    fn fit_errors_on_degenerate_input() {
        assert_eq!(
            fit_line(&[(1.0, 2.0), (2.0, 3.0)]),
            Err(FitError::TooFewPoints { got: 2 })
        );
        assert!(matches!(
            fit_line(&[(5.0, 1.0), (5.0, 2.0), (5.0, 3.0)]),
            Err(FitError::ConstantPressure { .. })
        ));
        assert!(matches!(
            fit_line(&[(1.0, 2.0), (2.0, 2.0), (3.0, 2.0)]),
            Err(FitError::ConstantAngle { .. })
        ));
        assert_eq!(
            fit_line(&[(1e300, 2.0), (-1e300, 3.0), (0.0, 1.0)]),
            Err(FitError::Overflow)
        );
    }

    proptest! {
        #[test]
        fn fit_never_panics_and_returns_finite_numbers(
            pts in proptest::collection::vec((-1e308f64..1e308, -1e308f64..1e308), 0..20),
        ) {
            if let Ok(fit) = fit_line(&pts) {
                prop_assert!(fit.slope_deg_per_kpa.is_finite());
                prop_assert!(fit.intercept_deg.is_finite());
                prop_assert!(fit.r_squared.is_finite());
                prop_assert!(fit.rms_residual_deg.is_finite());
                prop_assert!(fit.max_abs_residual_deg.is_finite());
            }
        }
    }

    #[test]
    fn csv_skips_header_comments_and_blank_lines() {
        let text = "pressure_kpa,angle_deg\n# a comment\n\n0, 1\n10,16\n 20 , 31 \n";
        assert_eq!(
            parse_csv(text).unwrap(),
            vec![(0.0, 1.0), (10.0, 16.0), (20.0, 31.0)]
        );
    }

    #[test]
    fn csv_bad_rows_name_their_line() {
        let err = parse_csv("p,a\n1,2\n3;4\n").unwrap_err();
        assert_eq!(
            err,
            FitError::BadRow {
                line: 3,
                content: "3;4".into()
            }
        );
        let err = parse_csv("1,2\n3,x\n").unwrap_err();
        assert!(matches!(err, FitError::BadRow { line: 2, .. }));
        let err = parse_csv("1,2\n3,4,5\n").unwrap_err();
        assert!(matches!(err, FitError::BadRow { line: 2, .. }));
        let err = parse_csv("1,2\nNaN,4\n").unwrap_err();
        assert!(matches!(err, FitError::NotFinite { line: 2, .. }));
        // A header is only allowed first.
        let err = parse_csv("1,2\np,a\n").unwrap_err();
        assert!(matches!(err, FitError::BadRow { line: 2, .. }));
        // Line numbers count skipped lines; the content is the line as written.
        let err = parse_csv("# c\n\n  \n1,2\n 3 , oops \n").unwrap_err();
        assert_eq!(
            err,
            FitError::BadRow {
                line: 5,
                content: " 3 , oops ".into()
            }
        );
    }

    #[test]
    fn csv_accepts_quoted_fields_and_crlf_line_ends() {
        let text = "\"pressure_kpa\",\"angle_deg\"\r\n\"0\",1\r\n10,16\r\n";
        assert_eq!(parse_csv(text).unwrap(), vec![(0.0, 1.0), (10.0, 16.0)]);
    }

    #[test]
    fn nan_and_infinite_pressures_are_rejected() {
        let range = PressureRange::default();
        let rot = RotActuator::default();
        let dex = DexActuator::default();
        assert!(rot_angle_rad(&rot, &range, f64::NAN).is_err());
        assert!(rot_angle_rad(&rot, &range, f64::INFINITY).is_err());
        assert!(dex_state(&dex, &range, [0.0, f64::NAN, 0.0]).is_err());
        assert!(dex_state(&dex, &range, [f64::NEG_INFINITY, 0.0, 0.0]).is_err());
    }

    #[test]
    fn one_dex_chamber_bends_away_from_itself_by_the_slope() {
        let dex = DexActuator {
            max_bend_deg: 90.0,
            ..DexActuator::default()
        };
        let s = dex_state(&dex, &PressureRange::default(), [20.0, 0.0, 0.0]).unwrap();
        // Chamber 0 sits at +x, so the joint bends towards -x.
        assert!((s.bend_x_rad + (0.9f64 * 20.0).to_radians()).abs() < 1e-12);
        assert!(s.bend_y_rad.abs() < 1e-12);
        // Equal pressures only extend.
        let s = dex_state(&dex, &PressureRange::default(), [30.0; 3]).unwrap();
        assert!(s.bend_rad() < 1e-12);
        assert!((s.length_mm - 29.0).abs() < 1e-12);
    }

    proptest! {
        #[test]
        fn extreme_pressures_clamp_to_the_joint_limits(
            p in proptest::array::uniform4(-1e300f64..1e300),
        ) {
            let range = PressureRange::default();
            let rot = RotActuator::default();
            let dex = DexActuator::default();
            let angle = rot_angle_rad(&rot, &range, p[0]).unwrap();
            prop_assert!(angle >= rot.min_angle_deg.to_radians() - 1e-15);
            prop_assert!(angle <= rot.max_angle_deg.to_radians() + 1e-15);
            let s = dex_state(&dex, &range, [p[1], p[2], p[3]]).unwrap();
            prop_assert!(s.bend_rad() <= dex.max_bend_deg.to_radians() * (1.0 + 1e-12));
            prop_assert!(s.length_mm >= dex.min_length_mm && s.length_mm <= dex.max_length_mm);
        }

        #[test]
        fn fit_is_exact_on_noise_free_lines(
            slope in -10.0f64..10.0,
            intercept in -100.0f64..100.0,
            offset in -1e4f64..1e4,
            n in 3usize..50,
        ) {
            let pts: Vec<(f64, f64)> = (0..n)
                .map(|i| {
                    let p = offset + i as f64 * 0.7;
                    (p, slope * p + intercept)
                })
                .collect();
            match fit_line(&pts) {
                Ok(fit) => {
                    let scale = 1.0 + intercept.abs() + (slope * offset).abs();
                    prop_assert!((fit.slope_deg_per_kpa - slope).abs() < 1e-6 * (1.0 + slope.abs()));
                    prop_assert!((fit.intercept_deg - intercept).abs() < 1e-6 * scale);
                    prop_assert!(fit.rms_residual_deg < 1e-6 * scale);
                }
                // slope * p rounds to one value for every point only when
                // the slope is (nearly) zero.
                Err(FitError::ConstantAngle { .. }) => prop_assert!(slope.abs() < 1e-9),
                Err(e) => prop_assert!(false, "unexpected {e}"),
            }
        }
    }
}
