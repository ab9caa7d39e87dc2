//! Float and collection helpers for the per-frame hot paths.
//!
//! - Integer floor and ceiling of an `f64` without a libm call. The default
//!   x86-64 target (SSE2) has no rounding instruction, so `f64::ceil` and
//!   `f64::floor` are library calls; the per-marker hot paths (a centroid
//!   window's reach, a density kernel's cells) make thousands a frame. A
//!   truncating conversion and one compare give the same integers.
//! - Integer keys in `total_cmp`'s order, so that a median is selected with
//!   integer compares (the pipeline takes several medians over every
//!   marker of a frame).
//! - [`collect_bounded`]: a filtered iterator's items in one allocation.
//!
//! These give the library's results to the bit. [`norm`] is the one
//! exception: a square root where `hypot`, a libm call, would differ by an
//! ulp at most.

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

/// The length of `(x, y)`: `sqrt(x^2 + y^2)`. For the per-marker distances
/// (their squares neither overflow nor underflow).
pub(crate) fn norm(x: f64, y: f64) -> f64 {
    (x * x + y * y).sqrt()
}

/// The `u32` whose order is `f32::total_cmp`'s: negative values with every
/// bit flipped, the others with the sign bit set.
pub(crate) fn key_f32(x: f32) -> u32 {
    let b = x.to_bits();
    b ^ (((b as i32 >> 31) as u32) | 0x8000_0000)
}

/// The value of a [`key_f32`].
pub(crate) fn from_key_f32(k: u32) -> f32 {
    f32::from_bits(k ^ ((((!k) as i32 >> 31) as u32) | 0x8000_0000))
}

/// The `u64` whose order is `f64::total_cmp`'s ([`key_f32`] in 64 bits).
pub(crate) fn key_f64(x: f64) -> u64 {
    let b = x.to_bits();
    b ^ (((b as i64 >> 63) as u64) | 0x8000_0000_0000_0000)
}

/// The value of a [`key_f64`].
pub(crate) fn from_key_f64(k: u64) -> f64 {
    f64::from_bits(k ^ ((((!k) as i64 >> 63) as u64) | 0x8000_0000_0000_0000))
}

/// The value a sort by `f32::total_cmp` puts at `k` (`None` past the end).
pub(crate) fn select_f32(v: impl IntoIterator<Item = f32>, k: usize) -> Option<f32> {
    let mut keys: Vec<u32> = v.into_iter().map(key_f32).collect();
    (k < keys.len()).then(|| from_key_f32(*keys.select_nth_unstable(k).1))
}

/// The value a sort by `f64::total_cmp` puts at `k` (`None` past the end).
pub(crate) fn select_f64(v: impl IntoIterator<Item = f64>, k: usize) -> Option<f64> {
    let mut keys: Vec<u64> = v.into_iter().map(key_f64).collect();
    (k < keys.len()).then(|| from_key_f64(*keys.select_nth_unstable(k).1))
}

/// `it` collected into a vector allocated once, at its upper size bound:
/// `collect` on a filtered iterator starts from its lower bound, nothing,
/// and reallocates as it grows (2 % of a frame's instructions in session
/// 27's callgrind runs).
pub(crate) fn collect_bounded<T>(it: impl Iterator<Item = T>) -> Vec<T> {
    let mut v = Vec::with_capacity(it.size_hint().1.unwrap_or(0));
    v.extend(it);
    v
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

    #[test]
    fn a_bounded_collection_is_allocated_once_at_the_upper_bound() {
        let v = collect_bounded((0..10).filter(|x| x % 3 == 0));
        assert_eq!(v, [0, 3, 6, 9]);
        assert_eq!(v.capacity(), 10);
        // No upper bound: as `collect` would.
        assert_eq!(collect_bounded((0..).take_while(|&x| x < 3)), [0, 1, 2]);
    }

    proptest::proptest! {
        /// Keys sort as `total_cmp` does and give back the same bits: any
        /// pattern, so both zeros, infinities and NaN too.
        #[test]
        fn keys_keep_the_total_order(a in proptest::prelude::any::<u64>(), b in proptest::prelude::any::<u64>()) {
            let (x, y) = (f64::from_bits(a), f64::from_bits(b));
            proptest::prop_assert_eq!(key_f64(x).cmp(&key_f64(y)), x.total_cmp(&y));
            proptest::prop_assert_eq!(from_key_f64(key_f64(x)).to_bits(), a);
            let (x, y) = (f32::from_bits(a as u32), f32::from_bits(b as u32));
            proptest::prop_assert_eq!(key_f32(x).cmp(&key_f32(y)), x.total_cmp(&y));
            proptest::prop_assert_eq!(from_key_f32(key_f32(x)).to_bits(), a as u32);
        }

        /// The selection is the sorted value at `k`.
        #[test]
        fn selection_is_the_sorted_value(v in proptest::collection::vec(-5.0f64..5.0, 1..40), k in 0usize..40) {
            let mut sorted = v.clone();
            sorted.sort_by(f64::total_cmp);
            proptest::prop_assert_eq!(select_f64(v, k), sorted.get(k).copied());
        }

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
