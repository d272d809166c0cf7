//! Per-level sample tables of filtered importance sampling (Křivánek & Colbert 2008;
//! Lagarde & de Rousiers 2014, "Moving Frostbite to PBR" §4.9.2): tangent-space light
//! directions, their weights and the source mip each one reads, built once per level.

use glam::Vec3;
use ibl_brdf::ggx::{d_ggx, sample_ggx_d};
use ibl_core::sampling::hammersley;

/// Light direction l = reflect(−v, h) = 2(v·h)h − v for v = n = +z (Karis 2013, n = v = r).
#[inline]
pub(crate) fn reflect_view(h: Vec3) -> Vec3 {
    Vec3::new(2.0 * h.z * h.x, 2.0 * h.z * h.y, 2.0 * h.z * h.z - 1.0)
}

/// Density of l = reflect(−v, h) when h ∝ D(h)(n·h), with n = v: D(h)(n·h)/(4 v·h) = D(h)/4
/// (Walter et al. 2007, eq. 14 Jacobian of the reflection).
#[inline]
pub(crate) fn pdf_l_given_n_eq_v(n_dot_h: f32, alpha: f32) -> f32 {
    d_ggx(n_dot_h, alpha) * 0.25
}

/// Solid angle a sample stands for: Ω_s = 1/(N·pdf(l)) (Křivánek & Colbert 2008, eq. 13;
/// Lagarde & de Rousiers 2014, listing 19).
#[inline]
pub(crate) fn sample_solid_angle(pdf_l: f32, count: u32) -> f32 {
    1.0 / (count as f32 * pdf_l)
}

/// Mean texel solid angle of an n×n cube: Ω_p = 4π/(6n²).
#[inline]
pub(crate) fn mean_texel_solid_angle(n: usize) -> f32 {
    4.0 * std::f32::consts::PI / (6.0 * (n * n) as f32)
}

/// Mip level whose texels cover the sample's solid angle: 0.5·log2(Ω_s/Ω_p) + bias
/// (Křivánek & Colbert 2008, eq. 13: each mip level quadruples the texel solid angle, hence
/// the 1/2 on log2; Lagarde & de Rousiers use bias = 1, we choose it from measurement).
#[inline]
pub(crate) fn source_lod(omega_s: f32, omega_p: f32, bias: f32) -> f32 {
    0.5 * (omega_s / omega_p).log2() + bias
}

/// The samples of one level, in the tangent frame of the output texel (n = +z).
#[derive(Clone, Debug)]
pub(crate) struct SampleTable {
    /// Light directions l with n·l > 0.
    pub dirs: Vec<Vec3>,
    /// n·l / Σ n·l: the weights sum to one, so a constant environment stays constant.
    pub weights: Vec<f32>,
    /// Source mip level to read, clamped to the pyramid: integer part and fraction.
    pub mips: Vec<u32>,
    pub fracs: Vec<f32>,
}

impl SampleTable {
    /// Draws `count` Hammersley points of D(h)(n·h), reflects them about h and records, for
    /// each light direction above the horizon, its weight n·l and the source mip whose texel
    /// solid angle matches the sample's (source pyramid of `source_size` faces, `max_lod` its
    /// coarsest level).
    pub fn build(
        roughness: f32,
        count: u32,
        source_size: usize,
        lod_bias: f32,
        max_lod: u32,
    ) -> Self {
        assert!(
            roughness > 0.0 && count > 0,
            "tables are for rough levels with samples"
        );
        let alpha = roughness * roughness;
        let omega_p = mean_texel_solid_angle(source_size);
        let mut dirs = Vec::with_capacity(count as usize);
        let mut raw = Vec::with_capacity(count as usize);
        let mut lods = Vec::with_capacity(count as usize);
        for i in 0..count {
            let (u1, u2) = hammersley(i, count);
            let h = sample_ggx_d(u1, u2, alpha);
            let l = reflect_view(h);
            if l.z <= 0.0 {
                continue;
            }
            let omega_s = sample_solid_angle(pdf_l_given_n_eq_v(h.z, alpha), count);
            lods.push(source_lod(omega_s, omega_p, lod_bias).clamp(0.0, max_lod as f32));
            dirs.push(l.normalize());
            raw.push(l.z as f64);
        }
        let total: f64 = raw.iter().sum();
        let weights = raw.iter().map(|w| (w / total) as f32).collect();
        let mips = lods
            .iter()
            .map(|l: &f32| (l.floor() as u32).min(max_lod))
            .collect::<Vec<_>>();
        let fracs = lods.iter().zip(&mips).map(|(l, m)| l - *m as f32).collect();
        SampleTable {
            dirs,
            weights,
            mips,
            fracs,
        }
    }

    /// Samples kept (above the horizon).
    pub fn len(&self) -> usize {
        self.dirs.len()
    }

    /// The continuous lod of sample `k`.
    #[cfg(test)]
    pub fn lod(&self, k: usize) -> f32 {
        self.mips[k] as f32 + self.fracs[k]
    }
}

/// An orthonormal tangent frame (t, b) around unit n (Duff et al. 2017, "Building an
/// Orthonormal Basis, Revisited", listing 3): branch-free, exact at n = ±z.
#[inline]
pub fn tangent_frame(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    let t = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
    let bt = Vec3::new(b, sign + n.y * n.y * a, -n.y);
    (t, bt)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::kernel_d_nl;
    use ibl_core::sampling::Pcg32;

    #[test]
    fn weights_sum_to_one_and_directions_are_unit_and_above_horizon() {
        for r in [0.01f32, 0.2, 0.5, 0.8, 1.0] {
            let t = SampleTable::build(r, 257, 64, 1.0, 6);
            let s: f64 = t.weights.iter().map(|w| *w as f64).sum();
            assert!((s - 1.0).abs() < 1e-6, "r {r}: {s}");
            for (d, w) in t.dirs.iter().zip(&t.weights) {
                assert!((d.length() - 1.0).abs() < 1e-5 && d.z > 0.0 && *w > 0.0);
            }
            for k in 0..t.len() {
                assert!(t.lod(k) >= 0.0 && t.lod(k) <= 6.0 && t.fracs[k] < 1.0);
            }
        }
    }

    #[test]
    fn roughness_one_keeps_about_half_the_draws() {
        // α = 1: h is cosine-distributed and n·l > 0 needs (n·h)² > 1/2, probability 1/2.
        let t = SampleTable::build(1.0, 4096, 64, 1.0, 6);
        let kept = t.len() as f32 / 4096.0;
        assert!((kept - 0.5).abs() < 0.01, "{kept}");
    }

    /// The weighted table is an estimator of the normalised kernel: for a smooth test function
    /// of l its weighted sum must match ∫K f / ∫K computed by quadrature in (θ, φ).
    #[test]
    fn weighted_table_integrates_the_normalised_kernel() {
        let f = |l: Vec3| 1.0 + 0.5 * l.x + 0.3 * l.y * l.y + 2.0 * (1.0 - l.z).powi(2);
        for r in [0.1f32, 0.4, 0.7, 1.0] {
            let alpha = r * r;
            let t = SampleTable::build(r, 4096, 64, 0.0, 6);
            let est: f64 = t
                .dirs
                .iter()
                .zip(&t.weights)
                .map(|(d, w)| *w as f64 * f(*d) as f64)
                .sum();
            // Quadrature over the hemisphere in θ_l, φ (midpoint, fine).
            let (m, p) = (4000, 64);
            let (mut num, mut den) = (0.0f64, 0.0f64);
            for a in 0..m {
                let th = (a as f64 + 0.5) / m as f64 * std::f64::consts::FRAC_PI_2;
                let s2 = (th / 2.0).sin().powi(2) as f32;
                let k = kernel_d_nl(s2, alpha) as f64 * th.sin();
                for b in 0..p {
                    let ph = (b as f64 + 0.5) / p as f64 * 2.0 * std::f64::consts::PI;
                    let l = Vec3::new(
                        (th.sin() * ph.cos()) as f32,
                        (th.sin() * ph.sin()) as f32,
                        th.cos() as f32,
                    );
                    num += k * f(l) as f64;
                    den += k;
                }
            }
            let want = num / den;
            eprintln!("r {r}: table {est:.6} vs quadrature {want:.6}");
            assert!((est - want).abs() < 2e-3 * want, "r {r}: {est} vs {want}");
        }
    }

    #[test]
    fn lod_follows_sample_solid_angle() {
        // Doubling the source size adds one level; quadrupling the count removes one.
        let a = SampleTable::build(0.5, 64, 64, 0.0, 20);
        let b = SampleTable::build(0.5, 64, 128, 0.0, 20);
        let c = SampleTable::build(0.5, 256, 64, 0.0, 20);
        assert!(
            (b.lod(0) - a.lod(0) - 1.0).abs() < 1e-4,
            "{} {}",
            a.lod(0),
            b.lod(0)
        );
        assert!((a.lod(0) - c.lod(0) - 1.0).abs() < 1e-4);
        // The first Hammersley point is h = n, the lobe's peak: pdf = D(1)/4 = 1/(4πα²).
        let alpha = 0.25f32;
        let omega_s = 4.0 * std::f32::consts::PI * alpha * alpha / 64.0;
        let want = 0.5 * (omega_s / mean_texel_solid_angle(64)).log2();
        assert!((a.lod(0) - want).abs() < 1e-4, "{} vs {want}", a.lod(0));
    }

    #[test]
    fn tangent_frame_is_orthonormal_everywhere() {
        let mut rng = Pcg32::new(3, 3);
        let mut dirs = vec![
            Vec3::Z,
            -Vec3::Z,
            Vec3::X,
            Vec3::new(0.0, 0.0, -1.0 + 1e-7).normalize(),
        ];
        for _ in 0..1000 {
            let v = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            );
            if v.length() > 1e-3 {
                dirs.push(v.normalize());
            }
        }
        for n in dirs {
            let (t, b) = tangent_frame(n);
            assert!(
                (t.length() - 1.0).abs() < 1e-5 && (b.length() - 1.0).abs() < 1e-5,
                "{n}"
            );
            assert!(
                t.dot(b).abs() < 1e-5 && t.dot(n).abs() < 1e-5 && b.dot(n).abs() < 1e-5,
                "{n}"
            );
            assert!((t.cross(b) - n).length() < 1e-4, "right-handed at {n}");
        }
    }
}
