//! Integer floor and ceiling of an `f64` without a libm call.
//!
//! The default x86-64 target (SSE2) has no rounding instruction, so
//! `f64::ceil` and `f64::floor` are library calls; the per-marker hot paths
//! (a centroid window's reach, a density kernel's cells) make thousands a
//! frame. A truncating conversion and one compare give the same integers.

/// `v.ceil() as i64`, for every `v` (NaN gives 0, out of range saturates,
/// as the conversion does).
pub(crate) fn ceil_i64(v: f64) -> i64 {
    let t = v as i64;
    t + ((t as f64) < v && t < i64::MAX) as i64
}

/// `v.floor() as i64`, for every `v` (NaN gives 0, out of range saturates).
pub(crate) fn floor_i64(v: f64) -> i64 {
    let t = v as i64;
    t - ((t as f64) > v && t > i64::MIN) as i64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edges_match_the_library() {
        for v in [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.0 - f64::EPSILON,
            -(2.0 - f64::EPSILON),
            4503599627370495.5,
            -4503599627370495.5,
            9.3e18,
            -9.3e18,
            f64::MAX,
            f64::MIN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ] {
            assert_eq!(ceil_i64(v), v.ceil() as i64, "ceil {v}");
            assert_eq!(floor_i64(v), v.floor() as i64, "floor {v}");
        }
    }

    proptest::proptest! {
        /// Any bit pattern: the same integer as the library's rounding
        /// followed by the conversion.
        #[test]
        fn any_value_matches_the_library(bits in proptest::prelude::any::<u64>(), small in -1e6f64..1e6) {
            for v in [f64::from_bits(bits), small] {
                proptest::prop_assert_eq!(ceil_i64(v), v.ceil() as i64);
                proptest::prop_assert_eq!(floor_i64(v), v.floor() as i64);
            }
        }
    }
}
