//! Real spherical harmonics of docs/CONVENTIONS.md: orthonormal, no Condon–Shortley phase, index
//! i = l(l+1)+m, +z the polar axis, evaluated on the direction's own x, y, z.

use glam::Vec3;

/// Number of coefficients of `bands` bands (l = 0 … bands−1).
#[inline]
pub const fn num_coeffs(bands: usize) -> usize {
    bands * bands
}

/// Index of (l, m): l(l+1)+m.
#[inline]
pub const fn index(l: usize, m: isize) -> usize {
    ((l * (l + 1)) as isize + m) as usize
}

/// Fills `out` (length bands²) with Y_lm(d) for a unit direction d.
///
/// Uses the sin^|m|θ-free associated Legendre recurrence and the polynomial recurrences
/// C_m = x C_{m−1} − y S_{m−1}, S_m = x S_{m−1} + y C_{m−1} (C_m = sin^mθ cos mφ), so no
/// trigonometry is evaluated. Bands 0–2 reproduce the constants of docs/CONVENTIONS.md.
pub fn eval_basis(d: Vec3, bands: usize, out: &mut [f32]) {
    if bands <= 3 {
        let all = eval_basis3(d);
        let n = num_coeffs(bands);
        out[..n].copy_from_slice(&all[..n]);
        return;
    }
    let (x, y, z) = (d.x as f64, d.y as f64, d.z as f64);
    debug_assert!(out.len() >= num_coeffs(bands));
    if bands == 0 {
        return;
    }
    // p[l] for the current m: P̃_l^m(z) = P_l^m(z) / sin^m θ, without the CS phase.
    let mut c_m = 1.0f64; // C_0
    let mut s_m = 0.0f64; // S_0
    let mut pmm = 1.0f64; // P̃_m^m = (2m−1)!!
    for m in 0..bands {
        if m > 0 {
            let c = x * c_m - y * s_m;
            let s = x * s_m + y * c_m;
            c_m = c;
            s_m = s;
            pmm *= (2 * m - 1) as f64;
        }
        let mut p_lm2 = 0.0f64;
        let mut p_lm1 = pmm;
        for l in m..bands {
            let p = if l == m {
                pmm
            } else if l == m + 1 {
                z * (2 * m + 1) as f64 * pmm
            } else {
                ((2 * l - 1) as f64 * z * p_lm1 - (l + m - 1) as f64 * p_lm2) / (l - m) as f64
            };
            if l > m {
                p_lm2 = p_lm1;
                p_lm1 = p;
            }
            let k = norm_factor(l, m);
            if m == 0 {
                out[index(l, 0)] = (k * p) as f32;
            } else {
                let k2 = std::f64::consts::SQRT_2 * k * p;
                out[index(l, m as isize)] = (k2 * c_m) as f32;
                out[index(l, -(m as isize))] = (k2 * s_m) as f32;
            }
        }
    }
}

/// The first three bands in closed form (the docs/CONVENTIONS.md polynomials with full-precision
/// constants): the hot path of irradiance projection.
#[inline]
pub fn eval_basis3(d: Vec3) -> [f32; 9] {
    const C0: f32 = 0.282_094_8; // 1/(2√π)
    const C1: f32 = 0.488_602_5; // √3/(2√π)
    const C2: f32 = 1.092_548_4; // √15/(2√π)
    const C20: f32 = 0.315_391_57; // √5/(4√π)
    const C22: f32 = 0.546_274_2; // √15/(4√π)
    let (x, y, z) = (d.x, d.y, d.z);
    [
        C0,
        C1 * y,
        C1 * z,
        C1 * x,
        C2 * x * y,
        C2 * y * z,
        C20 * (3.0 * z * z - 1.0),
        C2 * x * z,
        C22 * (x * x - y * y),
    ]
}

/// K_l^m = sqrt((2l+1)/(4π) · (l−m)!/(l+m)!).
fn norm_factor(l: usize, m: usize) -> f64 {
    let mut ratio = 1.0f64;
    for k in (l - m + 1)..=(l + m) {
        ratio /= k as f64;
    }
    ((2 * l + 1) as f64 / (4.0 * std::f64::consts::PI) * ratio).sqrt()
}

/// Zonal coefficient Â_l of the clamped cosine max(cos θ, 0) convolution (Ramamoorthi &
/// Hanrahan 2001, eq. 8 with the 2π/(2l+1) factor folded in): Â0 = π, Â1 = 2π/3,
/// Â_l = 0 for odd l > 1, Â_l = 2π (−1)^{l/2−1} / ((l+2)(l−1)) · l! / (2^l ((l/2)!)²) for even l.
pub fn cosine_lobe_zonal(l: usize) -> f64 {
    use std::f64::consts::PI;
    match l {
        0 => PI,
        1 => 2.0 * PI / 3.0,
        l if l % 2 == 1 => 0.0,
        l => {
            let sign = if (l / 2 - 1) % 2 == 0 { 1.0 } else { -1.0 };
            // l! / (2^l ((l/2)!)^2) = C(l, l/2) / 2^l
            let mut binom_over_pow = 1.0f64;
            for k in 0..l / 2 {
                binom_over_pow *= (l - k) as f64 / ((k + 1) as f64 * 4.0);
            }
            2.0 * PI * sign / ((l + 2) as f64 * (l - 1) as f64) * binom_over_pow
        }
    }
}

/// Σ_i c_i Y_i(d) for RGB coefficients.
pub fn eval_rgb(coeffs: &[[f32; 3]], d: Vec3) -> [f32; 3] {
    let bands = (coeffs.len() as f64).sqrt() as usize;
    let mut y = vec![0.0f32; num_coeffs(bands)];
    eval_basis(d, bands, &mut y);
    let mut out = [0.0f32; 3];
    for (c, yi) in coeffs.iter().zip(&y) {
        for k in 0..3 {
            out[k] += c[k] * yi;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampling::Pcg32;

    #[test]
    fn bands_0_to_2_match_design_constants() {
        let mut rng = Pcg32::new(1, 1);
        for _ in 0..20 {
            let d = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            )
            .normalize();
            let (x, y, z) = (d.x, d.y, d.z);
            let want = [
                0.282095,
                0.488603 * y,
                0.488603 * z,
                0.488603 * x,
                1.092548 * x * y,
                1.092548 * y * z,
                0.315392 * (3.0 * z * z - 1.0),
                1.092548 * x * z,
                0.546274 * (x * x - y * y),
            ];
            let mut got = [0.0; 9];
            eval_basis(d, 3, &mut got);
            for i in 0..9 {
                assert!(
                    (got[i] - want[i]).abs() < 2e-6,
                    "i={i}: {} vs {}",
                    got[i],
                    want[i]
                );
            }
        }
    }

    #[test]
    fn closed_form_bands_match_the_recurrence() {
        let mut rng = Pcg32::new(3, 3);
        for _ in 0..100 {
            let d = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            )
            .normalize();
            let mut general = [0.0f32; 16];
            eval_basis(d, 4, &mut general);
            let fast = eval_basis3(d);
            for i in 0..9 {
                assert!((general[i] - fast[i]).abs() < 1e-6, "{i}");
            }
        }
    }

    #[test]
    fn basis_is_orthonormal_up_to_band_6() {
        // Gauss-like quadrature: fine equirect grid with exact row solid angles.
        let bands = 7;
        let n = num_coeffs(bands);
        let (w, h) = (256, 128);
        let mut gram = vec![0.0f64; n * n];
        let mut y = vec![0.0f32; n];
        for j in 0..h {
            let sa = crate::equirect::row_solid_angle(j, w, h);
            for i in 0..w {
                eval_basis(crate::equirect::pixel_direction(i, j, w, h), bands, &mut y);
                for a in 0..n {
                    for b in 0..n {
                        gram[a * n + b] += y[a] as f64 * y[b] as f64 * sa;
                    }
                }
            }
        }
        for a in 0..n {
            for b in 0..n {
                let want = if a == b { 1.0 } else { 0.0 };
                assert!(
                    (gram[a * n + b] - want).abs() < 2e-3,
                    "({a},{b}) {}",
                    gram[a * n + b]
                );
            }
        }
    }

    #[test]
    fn cosine_lobe_zonal_known_values() {
        use std::f64::consts::PI;
        assert!((cosine_lobe_zonal(2) - PI / 4.0).abs() < 1e-12);
        assert!((cosine_lobe_zonal(4) + PI / 24.0).abs() < 1e-12);
        assert_eq!(cosine_lobe_zonal(3), 0.0);
    }
}
