//! The split-sum baseline (Karis 2013; Silvennoinen et al. 2025 §3.2): a GGX-prefiltered mip chain looked up
//! at the reflection vector with lod = roughness·(N−1) (docs/CONVENTIONS.md), times the DFG table:
//! specular = L_pref(r, roughness) · (F0·A + B).
//!
//! The chain normally comes from `ibl-prefilter` (or a folder it wrote); [`prefilter_chain`]
//! is a small independent implementation (n = v = r, (n·l)-weighted, filtered importance
//! sampling) kept as the fallback and as a cross-check of the shared one.

use crate::dfg::Dfg;
use glam::Vec3;
use ibl_brdf::ggx::d_ggx;
use ibl_brdf::reflect;
use ibl_core::bordered::BorderedMips;
use ibl_core::cube::mip_sizes;
use ibl_core::progress::NoProgress;
use ibl_core::sampling::hammersley;
use ibl_core::{CubeMips, Cubemap, Rgb};

/// A prefiltered chain ready for lookups, with the DFG table.
pub struct SplitSum {
    chain: BorderedMips,
    /// The DFG table (A, B) of the split sum.
    pub dfg: Dfg,
    /// Where the chain came from (for reports).
    pub source: String,
}

impl SplitSum {
    /// The chain with seamless bordered lookups, the DFG table and where the chain came from.
    pub fn new(chain: &CubeMips, dfg: Dfg, source: impl Into<String>) -> Self {
        SplitSum {
            chain: BorderedMips::new(chain),
            dfg,
            source: source.into(),
        }
    }

    /// Levels in the chain.
    pub fn levels(&self) -> usize {
        self.chain.num_levels()
    }

    /// Face size of every level.
    pub fn sizes(&self) -> Vec<usize> {
        self.chain.sizes()
    }

    /// Bytes of the chain at `bytes_per_texel` (12 for RGB32F, 8 for RGBA16F).
    pub fn bytes(&self, bytes_per_texel: usize) -> usize {
        self.chain.chain_bytes(bytes_per_texel)
    }

    /// Prefiltered radiance in `dir` at perceptual roughness r: lod = r·(N−1), trilinear.
    pub fn radiance(&self, dir: Vec3, roughness: f32) -> Rgb {
        let top = (self.chain.num_levels() - 1) as f32;
        self.chain.sample(dir, roughness.clamp(0.0, 1.0) * top)
    }

    /// Reflected radiance E = L_pref(r) · (F0·A + B) for unit n, v (v towards the eye).
    pub fn specular(&self, n: Vec3, v: Vec3, roughness: f32, f0: f32) -> Rgb {
        let nv = n.dot(v).max(0.0);
        let r = reflect(v, n);
        let (a, b) = self.dfg.ab(nv, roughness);
        let k = f0 * a + b;
        self.radiance(r, roughness).map(|c| c * k)
    }
}

/// The shared prefiltered chain: `ibl-prefilter`'s bake at level-0 size `size` with its
/// defaults (levels halving down to 4², r = l/(N−1), filtered importance sampling at its
/// default quality), from the working cube; its levels the exact kernel (not fitted to the
/// lookup), as the references they are compared with.
pub(crate) fn shared_chain(source: &Cubemap, size: usize) -> crate::Result<CubeMips> {
    let params = ibl_prefilter::Params {
        size,
        fit_lookup: Some(false),
        ..Default::default()
    };
    let env = ibl_core::envmap::Environment::Cube(source.clone());
    let chain = ibl_prefilter::bake::bake_chain(&params, &env, &NoProgress)
        .map_err(|e| crate::Error::Core(ibl_core::Error::param(format!("prefilter: {e}"))))?;
    Ok(chain.mips)
}

/// Independent GGX prefilter (Karis 2013 with filtered importance sampling): level l of
/// `levels` has roughness l/(levels−1) and face size max(size >> l, min_size); each texel is
/// Σ L(l)(n·l) / Σ (n·l) over `samples` GGX-D samples with n = v = texel direction, read from
/// the box pyramid of `source` at lod 0.5·log2(Ω_s/Ω_p) + 1.
pub fn prefilter_chain(
    source: &Cubemap,
    size: usize,
    levels: usize,
    min_size: usize,
    samples: u32,
) -> CubeMips {
    use ibl_core::envmap::Environment;
    use ibl_core::equirect::Filter;
    let src_mips = CubeMips::build(source.clone(), 1);
    let pyr = BorderedMips::new(&src_mips);
    let sizes = mip_sizes(size, 1);
    let mut out = Vec::with_capacity(levels);
    for l in 0..levels {
        let n = sizes.get(l).copied().unwrap_or(1).max(min_size.min(size));
        if l == 0 {
            out.push(Environment::Cube(source.clone()).to_cube(n, Filter::Area, 0.0, &NoProgress));
            continue;
        }
        let r = l as f32 / (levels - 1).max(1) as f32;
        let alpha = (r * r).max(1e-4);
        // Per-level table in tangent space (n = v = +z): direction, n·l weight, lod.
        let mut table: Vec<(Vec3, f32, f32)> = Vec::new();
        let offset = -0.5 * pyr.base_log2_texel_solid_angle();
        for i in 0..samples {
            let (u1, u2) = hammersley(i, samples);
            let h = ibl_brdf::ggx::sample_ggx_d(u1, u2, alpha);
            let ldir = reflect(Vec3::Z, h);
            if ldir.z <= 0.0 {
                continue;
            }
            // pdf_l = D(h)(n·h)/(4 v·h) with v = n: D/4.
            let pdf = d_ggx(h.z, alpha) / 4.0;
            let lod = 0.5 * (1.0 / (samples as f32 * pdf)).log2() + 1.0 + offset;
            table.push((ldir, ldir.z, lod));
        }
        let cube = ibl_core::traverse::map_cube_texels(n, &NoProgress, |face, i, j| {
            let nrm = ibl_core::cube::texel_direction(face, i, j, n);
            let (t, b) = crate::basis::tangent_frame(nrm, 0.0);
            let mut acc = [0.0f64; 3];
            let mut w = 0.0f64;
            for (d, nl, lod) in &table {
                let dir = t * d.x + b * d.y + nrm * d.z;
                let c = pyr.sample(dir, *lod);
                for k in 0..3 {
                    acc[k] += (c[k] * nl) as f64;
                }
                w += *nl as f64;
            }
            acc.map(|a| (a / w.max(1e-30)) as f32)
        });
        out.push(cube);
    }
    CubeMips { levels: out }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_chain_agrees_with_the_independent_prefilter() {
        // Cross-check of the split-sum baseline: ibl-prefilter against this module's prefilter
        // on a smooth environment with a soft bright spot (relative RMS over directions).
        let n = 32;
        let mut cube = Cubemap::new(n);
        for face in ibl_core::Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    let d = ibl_core::cube::texel_direction(face, i, j, n);
                    let spot =
                        (20.0 * (d.dot(Vec3::new(0.6, 0.6, 0.5).normalize()) - 1.0)).exp() * 8.0;
                    cube.faces[face as usize].texel_mut(i, j).copy_from_slice(&[
                        1.0 + d.y + spot,
                        1.0,
                        0.5 + spot,
                    ]);
                }
            }
        }
        let a = SplitSum::new(
            &shared_chain(&cube, 32).unwrap(),
            Dfg::baked(8, 64),
            "shared",
        );
        let b = SplitSum::new(
            &prefilter_chain(&cube, 32, 4, 1, 1024),
            Dfg::baked(8, 64),
            "fallback",
        );
        assert_eq!(a.levels(), 4);
        for r in [0.5f32, 0.75, 1.0] {
            let (mut num, mut den) = (0.0f64, 0.0f64);
            for k in 0..500 {
                let d = crate::basis::fibonacci_sphere(k, 500);
                let (x, y) = (a.radiance(d, r)[0] as f64, b.radiance(d, r)[0] as f64);
                num += (x - y).powi(2);
                den += y * y;
            }
            let rel = (num / den).sqrt();
            eprintln!("r={r}: shared vs independent prefilter, relative RMS {rel:.2e}");
            assert!(rel < 0.02, "{rel}");
        }
    }

    #[test]
    fn constant_environment_is_reproduced_by_split_sum() {
        // Split-sum is exact for L = const: L_pref = c and F0·A + B is the albedo.
        let c = 1.7f32;
        let chain = prefilter_chain(&Cubemap::constant(16, [c; 3]), 16, 5, 1, 64);
        let ss = SplitSum::new(&chain, Dfg::baked(16, 256), "test");
        let n = Vec3::new(0.2, 0.9, 0.1).normalize();
        let v = Vec3::new(0.0, 1.0, 0.0);
        for r in [0.5f32, 1.0] {
            let e = ss.specular(n, v, r, 1.0);
            let (a, b) = ss.dfg.ab(n.dot(v), r);
            assert!((e[0] - c * (a + b)).abs() < 1e-4 * c, "{e:?}");
            let p = ss.radiance(Vec3::X, r);
            assert!((p[1] - c).abs() < 1e-4);
        }
        assert_eq!(ss.levels(), 5);
    }
}
