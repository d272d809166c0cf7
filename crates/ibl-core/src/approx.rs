//! Fast approximations shared by the bakes, each with its error bound tested here.

/// Worst error of [`acos`] in radians over [−1, 1] (Abramowitz & Stegun quote 6.7e-5; 6.8e-5
/// measured in f64 at 200,001 points).
pub const ACOS_ERROR: f64 = 6.8e-5;

/// arccos(x) within [`ACOS_ERROR`] (Abramowitz & Stegun 1964, eq. 4.4.45): for starting guesses
/// and conservative cone tests whose callers pad by the bound. `x` is clamped to [−1, 1].
#[inline]
pub fn acos(x: f64) -> f64 {
    let a = x.abs().min(1.0);
    let r = (1.0 - a).sqrt()
        * (1.570_728_8 + a * (-0.212_114_4 + a * (0.074_261_0 + a * -0.018_729_3)));
    if x < 0.0 {
        std::f64::consts::PI - r
    } else {
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn acos_is_within_its_bound_everywhere() {
        let mut worst = 0.0f64;
        for k in 0..=200_000 {
            let x = -1.0 + 2.0 * k as f64 / 200_000.0;
            worst = worst.max((acos(x) - x.acos()).abs());
        }
        eprintln!("approx::acos: worst error {worst:.2e} rad");
        assert!(worst < ACOS_ERROR, "{worst}");
        assert_eq!(acos(1.5), acos(1.0));
        assert!((acos(-1.0) - std::f64::consts::PI).abs() < ACOS_ERROR);
    }
}
