//! Deterministic quadrature: Gauss–Legendre nodes, used by the numerical Smith Λ of
//! distributions without a closed form and by the independent references of the LUT bakes.

/// The n-point Gauss–Legendre rule on [−1, 1] as (node, weight) pairs, nodes ascending.
/// Newton's iteration on P_n from the Tricomi initial guesses; exact for polynomials of
/// degree 2n−1. Panics only for n = 0.
pub fn gauss_legendre(n: usize) -> Vec<(f64, f64)> {
    assert!(n > 0, "a Gauss–Legendre rule needs at least one node");
    let mut out = vec![(0.0, 0.0); n];
    let nf = n as f64;
    for i in 0..n.div_ceil(2) {
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (nf + 0.5)).cos();
        let mut dp = 1.0;
        for _ in 0..100 {
            // P_n(x) and P_n'(x) by the three-term recurrence.
            let (mut p0, mut p1) = (1.0f64, x);
            for k in 2..=n {
                let kf = k as f64;
                let p2 = ((2.0 * kf - 1.0) * x * p1 - (kf - 1.0) * p0) / kf;
                p0 = p1;
                p1 = p2;
            }
            let pn = if n == 1 { x } else { p1 };
            let pm = if n == 1 { 1.0 } else { p0 };
            dp = nf * (x * pn - pm) / (x * x - 1.0);
            let dx = pn / dp;
            x -= dx;
            if dx.abs() < 1e-15 {
                break;
            }
        }
        let w = 2.0 / ((1.0 - x * x) * dp * dp);
        out[i] = (-x, w);
        out[n - 1 - i] = (x, w);
    }
    if n % 2 == 1 {
        out[n / 2].0 = 0.0;
    }
    out
}

/// ∫_a^b f(x) dx by an n-point Gauss–Legendre rule.
pub fn integrate(a: f64, b: f64, n: usize, f: impl Fn(f64) -> f64) -> f64 {
    let h = 0.5 * (b - a);
    let c = 0.5 * (b + a);
    gauss_legendre(n)
        .iter()
        .map(|&(x, w)| w * f(c + h * x))
        .sum::<f64>()
        * h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rules_are_exact_for_polynomials_and_sum_to_two() {
        for n in [1usize, 2, 3, 8, 33, 256, 1024] {
            let r = gauss_legendre(n);
            let s: f64 = r.iter().map(|p| p.1).sum();
            assert!((s - 2.0).abs() < 1e-12, "n {n}: {s}");
            assert!(r.windows(2).all(|w| w[0].0 < w[1].0));
            // ∫ x^(2n−2) over [−1,1] = 2/(2n−1), exact for this rule.
            let k = (2 * n - 2) as i32;
            let q: f64 = r.iter().map(|&(x, w)| w * x.powi(k)).sum();
            assert!((q - 2.0 / (k as f64 + 1.0)).abs() < 1e-11, "n {n}: {q}");
        }
        let e = integrate(0.0, std::f64::consts::PI, 12, f64::sin);
        assert!((e - 2.0).abs() < 1e-12);
    }
}
