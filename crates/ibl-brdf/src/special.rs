//! Special functions the distributions need: the complementary error function.

/// erfc(x) with fractional error below 1.2e-7 everywhere (Numerical Recipes, 2nd ed., §6.2,
/// `erfcc`: a Chebyshev fit of exp(−x²) erfc), finite for all x (2 at −∞, 0 at +∞).
pub fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.26551223
        + t * (1.00002368
            + t * (0.37409196
                + t * (0.09678418
                    + t * (-0.18628806
                        + t * (0.27886807
                            + t * (-1.13520398
                                + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277))))))));
    let r = t * poly.exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// erf(x) = 1 − erfc(x).
pub(crate) fn erf(x: f64) -> f64 {
    1.0 - erfc(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn erfc_against_quadrature_of_the_gaussian() {
        // erfc(x) = 2/√π ∫_x^∞ e^{−t²} dt, by Gauss–Legendre on [x, x+12].
        let mut worst = 0.0f64;
        for k in 0..60 {
            let x = -3.0 + 0.15 * k as f64;
            let q = crate::quadrature::integrate(x, x + 12.0, 200, |t| (-t * t).exp()) * 2.0
                / std::f64::consts::PI.sqrt();
            worst = worst.max(((erfc(x) - q) / q).abs());
        }
        eprintln!("erfc relative error vs quadrature: {worst:.2e}");
        assert!(worst < 2e-7);
        assert_eq!(erfc(f64::INFINITY), 0.0);
        assert!((erfc(f64::NEG_INFINITY) - 2.0).abs() < 1e-12);
        assert!((erf(0.0)).abs() < 1e-7);
    }
}
