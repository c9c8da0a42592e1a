//! A NaN-aware maximum and minimum, for folds over measurements and computed values
//! (the tests' bounds, a diagnostic's extremes): `f64::max` and `f64::min` drop a NaN,
//! so a fold with them over samples one of which is NaN returns the largest of the
//! others, and a bound checked on it passes.

/// The larger of `a` and `b`, or NaN if either is NaN: a fold over measurements with
/// it (`.fold(0.0, nan_max)`) ends NaN if any sample was, where `f64::max` would drop
/// the NaN and let a bound check pass on the other samples.
pub fn nan_max(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

/// The smaller of two values, NaN if either is: the minimum's fold, as [`nan_max`].
pub fn nan_min(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.min(b)
    }
}

#[cfg(test)]
mod tests {
    use super::{nan_max, nan_min};

    #[test]
    fn nan_max_keeps_a_nan_sample() {
        assert_eq!([1.0, 3.0, 2.0].into_iter().fold(0.0, nan_max), 3.0);
        assert_eq!([-1.0].into_iter().fold(f64::NEG_INFINITY, nan_max), -1.0);
        assert_eq!(
            [1.0, -3.0, 2.0].into_iter().fold(f64::INFINITY, nan_min),
            -3.0
        );
        assert!([1.0, f64::NAN, 2.0]
            .into_iter()
            .fold(f64::INFINITY, nan_min)
            .is_nan());
        for at in 0..3 {
            let mut v = [1.0, 3.0, 2.0];
            v[at] = f64::NAN;
            assert!(
                v.into_iter().fold(0.0, nan_max).is_nan(),
                "NaN at {at} dropped"
            );
            // What f64::max does: the NaN is lost.
            assert_eq!(
                v.into_iter().fold(0.0, f64::max),
                if at == 1 { 2.0 } else { 3.0 }
            );
        }
    }
}
