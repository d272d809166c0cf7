//! Monte-Carlo estimation of the base reflectance E0(v, n, α) = ∫ L(l) f_DV (n·l) dl
//! (Silvennoinen et al. 2025 eq. 6) with visible-normal samples read through filtered importance sampling
//! (Colbert & Křivánek 2007) from a mip chain.
//!
//! The per-sample table (reflected directions in tangent space, weights G2/G1(v), lods) depends
//! only on the local view and α, so it is built once per (view, α) before the row loop; a row
//! then only rotates the table into its normal's frame and reads the chain.

use glam::Vec3;
use ibl_brdf::ggx::{g1, g2, pdf_vndf_reflected, sample_vndf};
use ibl_brdf::reflect;
use ibl_core::bordered::BorderedMips;
use ibl_core::sampling::hammersley;

/// One precomputed sample: reflected direction l in tangent space, its estimator weight
/// G2(v,l)/G1(v)/N and its lod before the environment's texel-size offset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TableEntry {
    /// Light direction l in the local frame (n = +z).
    pub l: [f32; 3],
    /// G2(v,l)/G1(v)/N: the sample's weight in E0.
    pub weight: f32,
    /// Source lod of the sample before the texel-size offset.
    pub lod: f32,
}

/// Samples of one (view, α): directions under the horizon are dropped (they carry zero weight).
pub(crate) fn sample_table(v: Vec3, alpha: f32, samples: usize, lod_bias: f32) -> Vec<TableEntry> {
    let n = samples.max(1);
    let mut out = Vec::with_capacity(n);
    let g1v = g1(v.z, alpha);
    for i in 0..n {
        let (u1, u2) = hammersley(i as u32, n as u32);
        let h = sample_vndf(v, u1, u2, alpha);
        let l = reflect(v, h);
        if l.z <= 0.0 || g1v <= 0.0 {
            continue;
        }
        // VNDF estimator of ∫ D V (n·l) dl: f (n·l) / pdf_l = G2 / G1(v).
        let weight = g2(v.z, l.z, alpha) / g1v / n as f32;
        let pdf = pdf_vndf_reflected(v, h, alpha).max(1e-20);
        // Filtered importance sampling: the sample's solid angle 1/(N pdf) against a texel's;
        // +bias (1 in Colbert & Křivánek) for the overlap of neighbouring samples.
        let lod = 0.5 * (1.0 / (n as f32 * pdf)).log2() + lod_bias;
        out.push(TableEntry {
            l: l.to_array(),
            weight,
            lod,
        });
    }
    out
}

/// Tables for a fixed set of local views and α values: `tables[a * views + k]`.
#[derive(Clone, Debug)]
pub struct Estimator {
    /// Local view directions (n = +z).
    pub views: Vec<Vec3>,
    /// GGX α values.
    pub alphas: Vec<f32>,
    /// Samples drawn per table.
    pub samples: usize,
    tables: Vec<Vec<TableEntry>>,
}

impl Estimator {
    /// Builds all tables (in parallel over (α, view) with `ibl_core::traverse`, kept in order).
    pub fn new(views: &[Vec3], alphas: &[f32], samples: usize, lod_bias: f32) -> Self {
        let nv = views.len();
        let tables = ibl_core::traverse::ordered_row_reduce(
            alphas.len() * nv,
            |i| {
                vec![sample_table(
                    views[i % nv],
                    alphas[i / nv],
                    samples,
                    lod_bias,
                )]
            },
            Vec::with_capacity(alphas.len() * nv),
            |mut all, one| {
                all.extend(one);
                all
            },
        );
        Estimator {
            views: views.to_vec(),
            alphas: alphas.to_vec(),
            samples,
            tables,
        }
    }

    /// The table of α `alpha_index` and view `view_index`.
    pub fn table(&self, alpha_index: usize, view_index: usize) -> &[TableEntry] {
        &self.tables[alpha_index * self.views.len() + view_index]
    }

    /// E0 for the normal `n` with tangent frame (t, b) and the view `views[view_index]` of
    /// that frame, at `alphas[alpha_index]`.
    #[inline]
    pub fn e0(
        &self,
        env: &BorderedMips,
        frame: (Vec3, Vec3, Vec3),
        alpha_index: usize,
        view_index: usize,
    ) -> [f64; 3] {
        estimate_with_table(env, frame, self.table(alpha_index, view_index))
    }
}

/// Σ weight · L(frame · l) over a table, accumulated in f64.
#[inline]
pub(crate) fn estimate_with_table(
    env: &BorderedMips,
    frame: (Vec3, Vec3, Vec3),
    table: &[TableEntry],
) -> [f64; 3] {
    let (t, b, n) = frame;
    let offset = -0.5 * env.base_log2_texel_solid_angle();
    let mut acc = [0.0f64; 3];
    for e in table {
        let d = t * e.l[0] + b * e.l[1] + n * e.l[2];
        let c = env.sample(d, e.lod + offset);
        acc[0] += (c[0] * e.weight) as f64;
        acc[1] += (c[1] * e.weight) as f64;
        acc[2] += (c[2] * e.weight) as f64;
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_brdf::ggx::f_dv;
    use ibl_core::{CubeMips, Cubemap};

    #[test]
    fn constant_environment_gives_the_directional_albedo() {
        // L = 1: E0 = ∫ f_DV (n·l) dl, compared with a fine quadrature of f_DV.
        let env = BorderedMips::new(&CubeMips::build(Cubemap::constant(8, [1.0, 1.0, 1.0]), 1));
        for (alpha, theta) in [(0.2f32, 0.2f32), (0.5, 1.0), (1.0, 1.5)] {
            let v = Vec3::new(theta.sin(), 0.0, theta.cos());
            let mc = estimate_with_table(
                &env,
                (Vec3::X, Vec3::Y, Vec3::Z),
                &sample_table(v, alpha, 4096, 1.0),
            )[0];
            let k = 600;
            let mut quad = 0.0f64;
            for a in 0..k {
                let z = (a as f64 + 0.5) / k as f64;
                let st = (1.0 - z * z).sqrt();
                for bb in 0..2 * k {
                    let phi = std::f64::consts::PI * (bb as f64 + 0.5) / k as f64;
                    let l = Vec3::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, z as f32);
                    quad += (f_dv(v, l, alpha) * l.z) as f64;
                }
            }
            quad *= 2.0 * std::f64::consts::PI / (2 * k * k) as f64;
            eprintln!("α={alpha} θ={theta}: E0 MC {mc:.5} quadrature {quad:.5}");
            assert!((mc - quad).abs() < 2e-3 * quad.max(0.1), "{mc} vs {quad}");
        }
    }

    #[test]
    fn tables_are_finite_and_drop_only_zero_weight_samples() {
        for alpha in [0.2f32, 1.0] {
            for vz in [1.0f32, 0.05, 1e-4] {
                let v = Vec3::new((1.0 - vz * vz).sqrt(), 0.0, vz);
                let t = sample_table(v, alpha, 256, 1.0);
                assert!(!t.is_empty());
                for e in &t {
                    assert!(
                        e.weight.is_finite() && e.weight >= 0.0 && e.lod.is_finite(),
                        "{e:?}"
                    );
                    assert!(e.l[2] > 0.0);
                }
            }
        }
    }
}
