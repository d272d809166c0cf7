//! The split-sum DFG table (Karis 2013; Silvennoinen et al. 2025 §3.2; docs/CONVENTIONS.md): for view cosine s = n·v
//! (columns) and perceptual roughness t = r (rows), both at texel centres, GGX with α = r²
//! and height-correlated Smith G2,
//!   R = A = ∫ f_DV (1 − χ) (n·l) dl,   G = B = ∫ f_DV χ (n·l) dl,   χ = (1 − v·h)⁵,
//! so that specular = F0·A + B. With `multiscatter` a third channel stores
//! E_ss = A + B, the single-scattering directional albedo used by the multiple-scattering
//! compensation of Fdez-Agüera 2019 (see [`MULTISCATTER_SHADER`]).
//!
//! Estimators (both on the first N Hammersley points, v taken in the xz plane):
//! - `vndf` (default): visible normals (Heitz 2018); the disk points are tabulated once, and
//!   the weight G2/G1(v) ≤ 1 keeps grazing views accurate;
//! - `ndf`: h ~ D(h)(n·h), one half-vector table per row (it does not depend on n·v; only
//!   h_x, h_z are kept); weight G2 (v·h)/((n·v)(n·h)), up to 1/(n·v) at grazing views.
//!
//! At 1024 samples on a 16² table, against the quadrature reference: vndf mean 2.5e-4 /
//! max 1.1e-3, ndf mean 7.8e-4 / max 8.9e-3 (test `estimators_compared_to_the_reference`).
//! α is clamped to [`ALPHA_MIN`] (α = 0 is a delta that no finite sample set integrates).

use crate::error::{Error, Result};
use crate::table::{self, map_rows, texel_centre, Baked, Describe};
use ibl_brdf::ggx::sample_ggx_d;
use ibl_core::progress::Progress;
use ibl_core::sampling::hammersley;
use ibl_core::Image;
use std::path::Path;

/// Smallest GGX α a table row uses: rows with r² below it (only r < 0.01) integrate α = 1e-4,
/// a lobe 0.006° wide, indistinguishable from the mirror at 16-bit precision.
pub(crate) const ALPHA_MIN: f32 = 1e-4;

/// The shader side of the multiple-scattering channel (Fdez-Agüera 2019, §4–5):
/// ```glsl
/// vec3 dfg   = texture(dfgLut, vec2(NoV, roughness)).rgb;   // (A, B, Ess = A + B)
/// vec3 FssEss = F0 * dfg.x + dfg.y;                          // single scattering
/// float Ems  = 1.0 - dfg.z;                                  // energy lost to multiple bounces
/// vec3 Favg  = F0 + (1.0 - F0) / 21.0;                       // cosine-weighted Schlick average
/// vec3 Fms   = FssEss * Favg / (1.0 - Ems * Favg);
/// vec3 specular = FssEss * prefiltered + Fms * Ems * irradiance;
/// ```
pub const MULTISCATTER_SHADER: &str = "FssEss = F0*A + B; Ems = 1 - Ess; Favg = F0 + (1-F0)/21; \
Fms = FssEss*Favg/(1 - Ems*Favg); specular = FssEss*radiance + Fms*Ems*irradiance";

/// The Monte-Carlo estimator of a table.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum Estimator {
    /// Visible-normal sampling (Heitz 2018).
    #[default]
    Vndf,
    /// Sampling of D(h)(n·h) (Walter et al. 2007).
    Ndf,
}

/// The per-row sample table of an estimator.
pub(crate) enum RowSamples {
    Vndf(DiskTable),
    Ndf(HalfVectorTable),
}

impl RowSamples {
    pub fn new(estimator: Estimator, alpha: f32, samples: u32) -> Self {
        match estimator {
            Estimator::Vndf => RowSamples::Vndf(DiskTable::new(samples)),
            Estimator::Ndf => RowSamples::Ndf(HalfVectorTable::new(alpha, samples)),
        }
    }

    /// (A, B) at `n_dot_v` for the row's α.
    #[inline]
    pub fn integrate(&self, n_dot_v: f32, alpha: f32) -> [f32; 2] {
        match self {
            RowSamples::Vndf(t) => integrate_vndf(t, n_dot_v, alpha),
            RowSamples::Ndf(t) => integrate(t, n_dot_v, alpha),
        }
    }
}

/// Parameters of the `dfg` bake: CLI flags and RON keys alike.
#[derive(Clone, Debug, PartialEq, clap::Args, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Table side in texels (size × size).
    #[arg(
        long,
        value_name = "N",
        default_value_t = 128,
        allow_negative_numbers = true
    )]
    pub size: usize,
    /// Hammersley samples per texel.
    #[arg(
        long,
        value_name = "N",
        default_value_t = 1024,
        allow_negative_numbers = true
    )]
    pub samples: u32,
    /// Add a third channel E_ss = A + B for multiple-scattering compensation.
    #[arg(long)]
    pub multiscatter: bool,
    /// Monte-Carlo estimator: visible normals (vndf) or D(h)(n·h) (ndf).
    #[arg(long, value_enum, default_value_t = Estimator::Vndf)]
    pub estimator: Estimator,
    /// Write half floats in EXR outputs.
    #[arg(long)]
    pub half: bool,
}

impl Default for Params {
    fn default() -> Self {
        ibl_core::params::clap_defaults()
    }
}

impl Params {
    /// Checks the parameters (size, samples) before any work.
    pub fn validate(&self) -> Result<()> {
        table::check_size("size", self.size)?;
        table::check_samples(self.samples)
    }
}

/// The GGX α of a table row at perceptual roughness r: r², at least [`ALPHA_MIN`].
#[inline]
pub fn alpha_of(roughness: f32) -> f32 {
    (roughness * roughness).max(ALPHA_MIN)
}

/// One row's half vectors h_i ~ D(h)(n·h) from the first `samples` Hammersley points, as the
/// (h_x, h_z) the estimator needs.
#[derive(Clone, Debug)]
pub struct HalfVectorTable {
    /// h_x of each sampled half vector (tangent space, v in the x–z plane).
    pub hx: Vec<f32>,
    /// h_z = n·h of each sampled half vector.
    pub hz: Vec<f32>,
}

impl HalfVectorTable {
    /// `samples` GGX half vectors of roughness α from the Hammersley set.
    pub fn new(alpha: f32, samples: u32) -> Self {
        let (mut hx, mut hz) = (
            Vec::with_capacity(samples as usize),
            Vec::with_capacity(samples as usize),
        );
        for i in 0..samples {
            let (u1, u2) = hammersley(i, samples);
            let h = sample_ggx_d(u1, u2, alpha);
            hx.push(h.x);
            hz.push(h.z);
        }
        HalfVectorTable { hx, hz }
    }
}

/// (A, B) at view cosine `n_dot_v` ∈ [0, 1] for the table's α.
///
/// Branch-free over 8 lanes so it vectorises: a sample with v·h ≤ 0 or n·l ≤ 0 has n·l
/// clamped to 0 and its weight selected to 0 (at n·v = 0, V's denominator
/// n·l √(n·v²(1−α²)+α²) + n·v √(n·l²(1−α²)+α²) is then 0 too, and the ratio would be 0/0);
/// for n·l > 0 the denominator is ≥ n·l·α > 0.
pub fn integrate(table: &HalfVectorTable, n_dot_v: f32, alpha: f32) -> [f32; 2] {
    const L: usize = 8;
    let nv = n_dot_v;
    let vx = (1.0 - nv * nv).max(0.0).sqrt();
    let a2 = alpha * alpha;
    let k = 1.0 - a2;
    let sv = (nv * nv * k + a2).sqrt();
    let sample = |hx: f32, hz: f32| -> (f32, f32) {
        let vh = vx * hx + nv * hz;
        let nl = (2.0 * vh * hz - nv).max(0.0);
        let den = nl * sv + nv * (nl * nl * k + a2).sqrt();
        // 4 V (n·l)(v·h)/(n·h) with V = 0.5/den; 0 for samples below the horizon.
        let w = if nl > 0.0 {
            2.0 * nl * vh / (den * hz)
        } else {
            0.0
        };
        let x = (1.0 - vh).clamp(0.0, 1.0);
        let x2 = x * x;
        let fc = x2 * x2 * x;
        (w - fc * w, fc * w)
    };
    let n = table.hx.len();
    let (mut acc_a, mut acc_b) = ([0.0f32; L], [0.0f32; L]);
    let (hx_chunks, hz_chunks) = (table.hx.chunks_exact(L), table.hz.chunks_exact(L));
    let (hx_rest, hz_rest) = (hx_chunks.remainder(), hz_chunks.remainder());
    for (cx, cz) in hx_chunks.zip(hz_chunks) {
        for l in 0..L {
            let (a, b) = sample(cx[l], cz[l]);
            acc_a[l] += a;
            acc_b[l] += b;
        }
    }
    for (l, (&x, &z)) in hx_rest.iter().zip(hz_rest).enumerate() {
        let (a, b) = sample(x, z);
        acc_a[l] += a;
        acc_b[l] += b;
    }
    let sum = |acc: [f32; L]| acc.iter().map(|&v| v as f64).sum::<f64>();
    [
        (sum(acc_a) / n as f64) as f32,
        (sum(acc_b) / n as f64) as f32,
    ]
}

/// The α- and view-independent part of Heitz 2018's visible-normal sampler for N Hammersley
/// points: the disk point (t1, t2) = √u1 (cos 2πu2, sin 2πu2) and √(1 − t1²).
#[derive(Clone, Debug)]
pub(crate) struct DiskTable {
    pub t1: Vec<f32>,
    pub t2: Vec<f32>,
    pub c1: Vec<f32>,
}

impl DiskTable {
    pub fn new(samples: u32) -> Self {
        let mut t = DiskTable {
            t1: vec![],
            t2: vec![],
            c1: vec![],
        };
        for i in 0..samples {
            let (u1, u2) = hammersley(i, samples);
            let r = (u1 as f64).sqrt();
            let (s, c) = (std::f64::consts::TAU * u2 as f64).sin_cos();
            let t1 = r * c;
            t.t1.push(t1 as f32);
            t.t2.push((r * s) as f32);
            t.c1.push((1.0 - t1 * t1).max(0.0).sqrt() as f32);
        }
        t
    }
}

/// (A, B) at view cosine `n_dot_v` by visible-normal sampling (Heitz 2018, listing 1, with
/// v in the xz plane so T1 = y, T2 = (−V_h.z, 0, V_h.x)). The weight f·(n·l)/pdf is then
/// G2/G1(v) = (1+Λ(v))/(1+Λ(v)+Λ(l)) = n·l (n·v + s_v) / (n·l s_v + n·v s_l) with
/// s_x = √(α² + (1−α²) x²): bounded by 1, which is why this estimator's error is far lower
/// than D sampling's at grazing views.
pub(crate) fn integrate_vndf(table: &DiskTable, n_dot_v: f32, alpha: f32) -> [f32; 2] {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { integrate_vndf_avx2(table, n_dot_v, alpha) };
    }
    integrate_vndf_portable(table, n_dot_v, alpha)
}

/// [`integrate_vndf`] compiled for AVX2 (8 lanes per instruction instead of 4). Rust never
/// contracts a·b + c into FMA, and each of the 8 accumulators is summed in sample order, so the
/// result is bit-identical to the portable build (tested).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn integrate_vndf_avx2(table: &DiskTable, n_dot_v: f32, alpha: f32) -> [f32; 2] {
    integrate_vndf_portable(table, n_dot_v, alpha)
}

#[inline(always)]
fn integrate_vndf_portable(table: &DiskTable, n_dot_v: f32, alpha: f32) -> [f32; 2] {
    const L: usize = 8;
    let nv = n_dot_v;
    let vx = (1.0 - nv * nv).max(0.0).sqrt();
    let a2 = alpha * alpha;
    let k = 1.0 - a2;
    let sv = (nv * nv * k + a2).sqrt();
    // Stretched view V_h = normalize(α v_x, 0, v_z).
    let vl = (a2 * vx * vx + nv * nv).sqrt();
    let (wx, wz) = (alpha * vx / vl, nv / vl);
    let s = 0.5 * (1.0 + wz);
    let sample = |t1: f32, t2: f32, c1: f32| -> (f32, f32) {
        let t2 = (1.0 - s) * c1 + s * t2;
        let t3 = (1.0 - t1 * t1 - t2 * t2).max(0.0).sqrt();
        // N_h = t1 T1 + t2 T2 + t3 V_h; unstretch: (α N_h.x, α N_h.y, max(0, N_h.z)).
        let nx = alpha * (t3 * wx - t2 * wz);
        let ny = alpha * t1;
        let nz = (t2 * wx + t3 * wz).max(0.0);
        let inv = 1.0 / (nx * nx + ny * ny + nz * nz).sqrt().max(1e-30);
        let (hx, hz) = (nx * inv, nz * inv);
        let vh = vx * hx + nv * hz;
        let nl = (2.0 * vh * hz - nv).max(0.0);
        let sl = (nl * nl * k + a2).sqrt();
        // 0 below the horizon (at n·v = 0 the ratio would be 0/0 there).
        let w = if nl > 0.0 {
            nl * (nv + sv) / (nl * sv + nv * sl)
        } else {
            0.0
        };
        let x = (1.0 - vh).clamp(0.0, 1.0);
        let x2 = x * x;
        let fc = x2 * x2 * x;
        (w - fc * w, fc * w)
    };
    let n = table.t1.len();
    let (mut acc_a, mut acc_b) = ([0.0f32; L], [0.0f32; L]);
    let (c1s, c2s, c3s) = (
        table.t1.chunks_exact(L),
        table.t2.chunks_exact(L),
        table.c1.chunks_exact(L),
    );
    let rest = (c1s.remainder(), c2s.remainder(), c3s.remainder());
    for ((x, y), z) in c1s.zip(c2s).zip(c3s) {
        for l in 0..L {
            let (a, b) = sample(x[l], y[l], z[l]);
            acc_a[l] += a;
            acc_b[l] += b;
        }
    }
    for l in 0..rest.0.len() {
        let (a, b) = sample(rest.0[l], rest.1[l], rest.2[l]);
        acc_a[l] += a;
        acc_b[l] += b;
    }
    let sum = |acc: [f32; L]| acc.iter().map(|&v| v as f64).sum::<f64>();
    [
        (sum(acc_a) / n as f64) as f32,
        (sum(acc_b) / n as f64) as f32,
    ]
}

#[cfg(test)]
/// One DFG value (A, B) at (n·v, roughness) with `samples` Hammersley samples and the default
/// (VNDF) estimator — the same number the default table stores at that texel.
pub(crate) fn dfg_value(n_dot_v: f32, roughness: f32, samples: u32) -> [f32; 2] {
    dfg_value_with(Estimator::Vndf, n_dot_v, roughness, samples)
}

#[cfg(test)]
/// [`dfg_value`] with a chosen estimator.
pub(crate) fn dfg_value_with(
    estimator: Estimator,
    n_dot_v: f32,
    roughness: f32,
    samples: u32,
) -> [f32; 2] {
    let alpha = alpha_of(roughness);
    RowSamples::new(estimator, alpha, samples).integrate(n_dot_v, alpha)
}

/// The whole table: size × size, channels (A, B) or (A, B, A+B).
pub fn dfg_table(size: usize, samples: u32, multiscatter: bool, progress: &dyn Progress) -> Image {
    dfg_table_with(Estimator::Vndf, size, samples, multiscatter, progress)
}

/// [`dfg_table`] with a chosen estimator.
pub fn dfg_table_with(
    estimator: Estimator,
    size: usize,
    samples: u32,
    multiscatter: bool,
    progress: &dyn Progress,
) -> Image {
    let ch = if multiscatter { 3 } else { 2 };
    map_dfg_rows(estimator, size, samples, ch, progress, |[a, b], t| {
        t[0] = a;
        t[1] = b;
        if multiscatter {
            t[2] = a + b;
        }
    })
}

/// The texel loop of the GGX tables over (n·v, roughness) at texel centres (columns n·v, rows
/// r, α = [`alpha_of`] r): integrates (A, B) at every texel with the estimator's row samples
/// (the VNDF disk table is built once, the D-sampling half vectors once per row) and hands them
/// to `put(ab, texel)` to fill that texel's `channels` values.
pub(crate) fn map_dfg_rows<P>(
    estimator: Estimator,
    size: usize,
    samples: u32,
    channels: usize,
    progress: &dyn Progress,
    put: P,
) -> Image
where
    P: Fn([f32; 2], &mut [f32]) + Sync,
{
    // The VNDF disk table does not depend on the row: build it once.
    let shared = (estimator == Estimator::Vndf).then(|| RowSamples::new(estimator, 1.0, samples));
    map_rows(size, size, channels, progress, |j, row| {
        let alpha = alpha_of(texel_centre(j, size) as f32);
        let own;
        let table = match &shared {
            Some(t) => t,
            None => {
                own = RowSamples::new(estimator, alpha, samples);
                &own
            }
        };
        for (i, t) in row.chunks_exact_mut(channels).enumerate() {
            put(table.integrate(texel_centre(i, size) as f32, alpha), t);
        }
    })
}

/// How the table describes itself.
pub fn describe(params: &Params) -> Describe<'static> {
    Describe {
        table: "split-sum DFG (GGX, height-correlated Smith, alpha = roughness^2)",
        channels: if params.multiscatter {
            &["A (F0 scale)", "B (bias)", "Ess = A + B"]
        } else {
            &["A (F0 scale)", "B (bias)"]
        },
        s: "n.v at texel centres (i+0.5)/W",
        t: "perceptual roughness r at texel centres (j+0.5)/H, row 0 first",
        params: serde_json::to_value(params).expect("params serialise"),
    }
}

/// Bakes the table and encodes it for `out` (.exr, .png 16-bit, .json, .ron).
pub fn run(params: &Params, out: &Path, progress: &dyn Progress) -> Result<Baked> {
    params.validate()?;
    table::Format::of(out)?;
    let image = dfg_table_with(
        params.estimator,
        params.size,
        params.samples,
        params.multiscatter,
        progress,
    );
    if image.data.iter().any(|v| !v.is_finite()) {
        return Err(Error::param("internal error: non-finite DFG texel"));
    }
    let bytes = table::encode(out, &image, &describe(params), 16, params.half)?;
    // ALPHA_MIN's shortest decimal (1e-4): widened to f64 it would print as 9.999999747e-5.
    let alpha_min: f64 = ALPHA_MIN
        .to_string()
        .parse()
        .expect("an f32 prints as a number");
    let details = serde_json::json!({
        "table": "dfg", "size": params.size, "samples": params.samples,
        "multiscatter": params.multiscatter, "estimator": params.estimator, "alpha_min": alpha_min,
    });
    Ok(Baked {
        files: vec![(out.to_path_buf(), bytes)],
        image,
        details,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference::DfgReference;
    use ibl_core::progress::NoProgress;

    #[test]
    fn defaults_agree_between_clap_serde_and_default() {
        let p: Params = ron::from_str("()").unwrap();
        assert_eq!(p, Params::default());
        assert_eq!(
            (p.size, p.samples, p.multiscatter, p.estimator),
            (128, 1024, false, Estimator::Vndf)
        );
        assert_eq!(
            ron::from_str::<Params>("(estimator: ndf)")
                .unwrap()
                .estimator,
            Estimator::Ndf
        );
        assert!(ron::from_str::<Params>("(sise: 4)").is_err());
        assert!(Params {
            size: 0,
            ..Default::default()
        }
        .validate()
        .is_err());
        assert!(Params {
            samples: 0,
            ..Default::default()
        }
        .validate()
        .is_err());
    }

    #[test]
    fn summary_reports_the_alpha_clamp_in_use() {
        let p = Params {
            size: 2,
            samples: 4,
            ..Default::default()
        };
        let baked = run(&p, Path::new("dfg.exr"), &NoProgress).unwrap();
        let a = &baked.details["alpha_min"];
        assert_eq!(a.as_f64().map(|v| v as f32), Some(ALPHA_MIN), "{a}");
        // Printed as the constant reads, not as its f64 widening (9.999999747e-5).
        assert_eq!(a.as_f64().unwrap().to_string(), ALPHA_MIN.to_string());
    }

    #[test]
    fn half_vector_table_matches_the_sampler() {
        let t = HalfVectorTable::new(0.3, 64);
        for i in [0u32, 1, 17, 63] {
            let (u1, u2) = hammersley(i, 64);
            let h = sample_ggx_d(u1, u2, 0.3);
            assert_eq!((t.hx[i as usize], t.hz[i as usize]), (h.x, h.z));
        }
        // The first Hammersley point is the normal.
        assert_eq!((t.hx[0], t.hz[0]), (0.0, 1.0));
    }

    #[test]
    fn table_at_1024_samples_is_within_2e3_of_the_quadrature_reference() {
        let size = 16;
        let img = dfg_table(size, 1024, true, &NoProgress);
        let reference = DfgReference::new(256);
        let (mut sum, mut worst) = (0.0f64, 0.0f64);
        for j in 0..size {
            for i in 0..size {
                let nv = texel_centre(i, size);
                let alpha = alpha_of(texel_centre(j, size) as f32) as f64;
                let r = reference.dfg(nv, alpha);
                let t = img.texel(i, j);
                assert!(t.iter().all(|v| v.is_finite()));
                assert_eq!(t[2], t[0] + t[1]);
                for c in 0..2 {
                    let e = (t[c] as f64 - r[c]).abs();
                    sum += e;
                    worst = worst.max(e);
                }
            }
        }
        let mean = sum / (2 * size * size) as f64;
        eprintln!("DFG 16² × 1024 vs 256² quadrature: mean abs error {mean:.2e}, max {worst:.2e}");
        // Measured: mean 2.5e-4, max 1.1e-3.
        assert!(worst < 2e-3, "max {worst}");
        assert!(mean < 3e-4, "mean {mean}");
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn avx2_build_is_bit_identical_to_the_portable_one() {
        if !std::is_x86_feature_detected!("avx2") {
            eprintln!(
                "SKIPPED avx2_build_is_bit_identical_to_the_portable_one: this CPU has no AVX2, \
                 so integrate_vndf runs the portable build and there is nothing to compare"
            );
            return;
        }
        let disk = DiskTable::new(333);
        for &(nv, alpha) in &[(0.0f32, 0.5f32), (0.01, 1e-4), (0.3, 0.2), (0.9, 1.0)] {
            // SAFETY: the CPU has AVX2 (checked above).
            let fast = unsafe { integrate_vndf_avx2(&disk, nv, alpha) };
            assert_eq!(fast, integrate_vndf_portable(&disk, nv, alpha));
            // ... and the dispatch takes that path.
            assert_eq!(integrate_vndf(&disk, nv, alpha), fast);
        }
    }

    #[test]
    #[cfg(not(target_arch = "x86_64"))]
    fn avx2_build_is_bit_identical_to_the_portable_one() {
        eprintln!(
            "SKIPPED avx2_build_is_bit_identical_to_the_portable_one: not x86_64, there is only \
             the portable build"
        );
    }

    #[test]
    fn estimators_compared_to_the_reference() {
        let size = 16;
        let reference = DfgReference::new(256);
        let disk = DiskTable::new(1024);
        let (mut ed, mut ev, mut md, mut mv) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for j in 0..size {
            let alpha = alpha_of(texel_centre(j, size) as f32);
            let ht = HalfVectorTable::new(alpha, 1024);
            for i in 0..size {
                let nv = texel_centre(i, size) as f32;
                let r = reference.dfg(nv as f64, alpha as f64);
                let d = integrate(&ht, nv, alpha);
                let v = integrate_vndf(&disk, nv, alpha);
                for c in 0..2 {
                    let (x, y) = ((d[c] as f64 - r[c]).abs(), (v[c] as f64 - r[c]).abs());
                    ed += x;
                    ev += y;
                    md = md.max(x);
                    mv = mv.max(y);
                }
            }
        }
        let n = (2 * size * size) as f64;
        let (ed, ev) = (ed / n, ev / n);
        eprintln!(
            "16² × 1024: D sampling mean {ed:.2e} max {md:.2e}; VNDF mean {ev:.2e} max {mv:.2e}"
        );
        // Limits a little above the measured values (module doc): VNDF mean 2.5e-4 / max
        // 1.1e-3, D sampling mean 7.8e-4 / max 8.9e-3. Both estimators are deterministic
        // (Hammersley), so the margin only absorbs compiler/libm rounding.
        assert!(ev < 3e-4 && mv < 1.3e-3, "VNDF mean {ev:.2e} max {mv:.2e}");
        assert!(
            ed < 9e-4 && md < 1.05e-2,
            "D sampling mean {ed:.2e} max {md:.2e}"
        );
        // The reason VNDF is the default: lower error on both counts.
        assert!(ev < ed && mv < md);
    }

    /// A published table: three.js's `src/renderers/shaders/DFGLUTData.js` (r18x; 16×16
    /// RG16F, 4096 samples per texel; rows n·v and columns roughness at texel centres,
    /// α = r², height-correlated Smith), a few texels decoded from its half floats as
    /// (row = n·v index, column = roughness index, A, B). Away from the two most grazing rows
    /// it agrees with our quadrature reference to 2.7e-3 (its half-float and MC noise); at
    /// n·v = 1/32 its A is up to 0.014 below the reference (ours is within 1.1e-3 there).
    const THREE_JS: [(usize, usize, f64, f64); 15] = [
        (2, 2, 0.57958984375, 0.403564453125),
        (4, 5, 0.78369140625, 0.1322021484375),
        (7, 7, 0.8447265625, 0.0301361083984375),
        (11, 3, 0.994140625, 0.002239227294921875),
        (15, 9, 0.828125, 0.0001042485237121582),
        (1, 13, 0.78564453125, 0.03936767578125),
        (3, 10, 0.75341796875, 0.046844482421875),
        (5, 12, 0.6689453125, 0.01617431640625),
        (6, 1, 0.92578125, 0.07391357421875),
        (8, 15, 0.46142578125, 0.0028629302978515625),
        (9, 8, 0.8349609375, 0.01065826416015625),
        (10, 14, 0.479248046875, 0.001766204833984375),
        (12, 6, 0.95263671875, 0.0016527175903320312),
        (13, 0, 1.0, 9.316205978393555e-05),
        (14, 11, 0.66845703125, 0.0003380775451660156),
    ];

    #[test]
    fn matches_the_three_js_published_table() {
        let img = dfg_table(16, 1024, false, &NoProgress);
        let (mut worst, mut sum) = (0.0f64, 0.0f64);
        for &(row, col, a, b) in &THREE_JS {
            // Our table: column = n·v, row = roughness.
            let t = img.texel(row, col);
            let e = (t[0] as f64 - a).abs().max((t[1] as f64 - b).abs());
            worst = worst.max(e);
            sum += e;
        }
        eprintln!(
            "DFG 16² × 1024 vs three.js DFGLUTData ({} texels): max {worst:.2e}, mean {:.2e}",
            THREE_JS.len(),
            sum / THREE_JS.len() as f64
        );
        assert!(worst < 4e-3 && sum / (THREE_JS.len() as f64) < 2e-3);
    }

    #[test]
    fn edges_are_finite_and_mirror_limit_is_exact() {
        for &r in &[0.0f32, 1e-3, 0.5, 1.0] {
            for &nv in &[0.0f32, 1e-6, 1e-3, 0.5, 1.0] {
                for (samples, e) in [
                    (1u32, Estimator::Vndf),
                    (1, Estimator::Ndf),
                    (7, Estimator::Ndf),
                    (7, Estimator::Vndf),
                    (1024, Estimator::Ndf),
                    (1024, Estimator::Vndf),
                ] {
                    let [a, b] = dfg_value_with(e, nv, r, samples);
                    assert!(
                        a.is_finite() && b.is_finite() && a >= 0.0 && b >= 0.0,
                        "{r} {nv} {samples} {e:?}: {a} {b}"
                    );
                    assert!(a + b <= 1.0 + 1e-5, "{r} {nv} {samples} {e:?}: {a} + {b}");
                }
            }
        }
        // r = 0: a mirror, A = 1 − (1 − n·v)⁵, B = (1 − n·v)⁵ (G2 ≈ 1 away from grazing).
        let [a, b] = dfg_value(0.5, 0.0, 256);
        let w = 0.5f32.powi(5);
        assert!(
            (a - (1.0 - w)).abs() < 1e-4 && (b - w).abs() < 1e-4,
            "{a} {b}"
        );
    }

    #[test]
    fn value_and_table_agree_and_threads_do_not_matter() {
        for e in [Estimator::Vndf, Estimator::Ndf] {
            let a = ibl_testkit::thread_count_independent(&[1, 2, 3], || {
                dfg_table_with(e, 8, 64, false, &NoProgress)
            });
            let v = dfg_value_with(e, texel_centre(3, 8) as f32, texel_centre(5, 8) as f32, 64);
            assert_eq!(a.texel(3, 5), &v);
        }
    }
}
