//! The shipped Ashikhmin–Shirley method (issue 23 items 6–7): `as-grid-32` of
//! bench/aniso-as-taps.md, as one source of truth — the constants in [`SHIPPED_AS`], the CPU
//! steps [`shade`] that the evaluator's `as-grid-N` runs, and the GLSL / HLSL / WGSL snippets
//! [`emit`] writes from the same constants and the same steps.
//!
//! What it reads: the half-vector LUT of the lobe (`hv-lut`: RGB = h·½+½, A = p_h/p_h(n),
//! bilinear, clamped to the edge, with its sidecar's p_h(n) as a uniform) and the environment
//! cube with its box mip pyramid (`generateMipmap`), as the anisotropic GGX snippet.
//!
//! The method: the thesis's sampler (Marcolongo 2020 §4.3.2) is the polar (Box–Muller) map of
//! a standard Gaussian in g = (√(n_u+1)·x, √(n_v+1)·y), (x, y) = θ(cos φ, sin φ): ξ1 =
//! atan2(g_y, g_x)/2π, ξ2 = 1 − exp(−|g|²/2). Its Hammersley cells are polar cells of that
//! plane, needles along a thin lobe that no isotropic mip read fits. Here the taps sit at the
//! midpoints of an a × b grid of equal-mass Cartesian cells, g = (Φ⁻¹((i+½)/a), Φ⁻¹((j+½)/b))
//! with a/b = √((n_v+1)/(n_u+1)) ([`grid_shape`], a uniform pair the application computes once
//! a material), so each cell is as long as wide on the sphere and Křivánek & Colbert's lod of
//! its pdf fits it: lod = ½(log2(1/(N p_l)) − log2 Ω_texel) + B, p_l = A·p_h(n)/(4 v·h).
//! Weight F(v·h)(n·l)/max(n·v, n·l) (the map keeps p_h, so exact importance sampling):
//! E0 = mean w·L, E1 = mean w·(1−v·h)⁵·L, specular = F0·E0 + (1−F0)·E1.

use crate::scene::Frame;
use crate::ship::E01;
use glam::Vec3;
use ibl_core::bordered::BorderedMips;
use ibl_core::Image;
use std::fmt::Write;

/// The shipped constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShippedAs {
    /// Tap budget N (a·b ≤ N taps are read).
    pub taps: usize,
    /// Added to Křivánek & Colbert's lod (their +1 over-blurs thin lobes: 0, the training
    /// optimum of bench/aniso-as-taps.md).
    pub lod_bias: f32,
    /// The Schlick exponent of E1.
    pub schlick_power: f32,
}

/// What the snippets and the evaluator's `as-grid-32` carry.
pub const SHIPPED_AS: ShippedAs = ShippedAs {
    taps: 32,
    lod_bias: 0.0,
    schlick_power: 5.0,
};

/// The grid (a, b) for exponents (n_u, n_v) and a budget of `taps`: a·b ≤ taps cells whose
/// extents on the sphere, ∝ 1/(a√(n_u+1)) along t and 1/(b√(n_v+1)) along b, are as equal as
/// the budget allows. The cost |ln((a/b)/ratio)| + 2 ln(N/(ab)) weighs a cell's aspect against
/// unread taps (a 70 × 20000 lobe at N = 32 takes 32 × 1, not 23 × 1).
pub fn grid_shape(nu: f64, nv: f64, taps: usize) -> (usize, usize) {
    let taps = taps.max(1);
    let ratio = ((nv + 1.0) / (nu + 1.0)).sqrt();
    let cost = |a: usize| {
        let b = taps / a;
        let aspect = (a as f64 / b as f64 / ratio).ln().abs();
        aspect + 2.0 * (taps as f64 / (a * b) as f64).ln()
    };
    let a = (1..=taps)
        .min_by(|&x, &y| cost(x).total_cmp(&cost(y)))
        .unwrap_or(1);
    (a, taps / a)
}

/// Φ⁻¹(p), the standard normal quantile, in f32 as the snippets compute it (Acklam 2003's
/// rational approximation, relative error < 1.2·10⁻⁹ in exact arithmetic; in f32 |Φ(x) − p|
/// stays under 2e-5, the worst by cancellation at the central branch's edge — a tap moved by
/// 2e-4 of a standard deviation — and under 1e-4·p in the tails),
/// p clamped to [1e-30, 1 − 6e-8].
pub fn normal_quantile(p: f32) -> f32 {
    let k = |c: &[f64], x: f32| c.iter().fold(0.0f32, |acc, &c| acc * x + c as f32);
    let p = p.clamp(1e-30, 1.0 - 6e-8);
    if !(0.02425..=1.0 - 0.02425).contains(&p) {
        let q = (-2.0 * (if p < 0.5 { p } else { 1.0 - p }).ln()).sqrt();
        let x = k(&QUANTILE_C, q) / (k(&QUANTILE_D, q) * q + 1.0);
        return if p < 0.5 { x } else { -x };
    }
    let q = p - 0.5;
    let r = q * q;
    k(&QUANTILE_A, r) * q / (k(&QUANTILE_B, r) * r + 1.0)
}

/// Acklam 2003's coefficients (central numerator, denominator; tail numerator, denominator),
/// highest power first; the snippets carry them as the f32 these round to.
const QUANTILE_A: [f64; 6] = [
    -3.969683028665376e1,
    2.209460984245205e2,
    -2.759285104469687e2,
    1.38357751867269e2,
    -3.066479806614716e1,
    2.506628277459239,
];
const QUANTILE_B: [f64; 5] = [
    -5.447609879822406e1,
    1.615858368580409e2,
    -1.556989798598866e2,
    6.680131188771972e1,
    -1.328068155288572e1,
];
const QUANTILE_C: [f64; 6] = [
    -7.784894002430293e-3,
    -3.223964580411365e-1,
    -2.400758277161838,
    -2.549732539343734,
    4.374664141464968,
    2.938163982698783,
];
const QUANTILE_D: [f64; 4] = [
    7.784695709041462e-3,
    3.224671290700398e-1,
    2.445134137142996,
    3.754408661907416,
];

/// `c` as the Horner form the Rust steps evaluate, in shader text: ((c0·x + c1)·x + …).
fn horner(c: &[f64], x: &str) -> String {
    let mut s = crate::ship::lit(c[0] as f32);
    for &k in &c[1..] {
        s = format!("({s} * {x} + {})", crate::ship::lit(k as f32));
    }
    s
}

/// The LUT coordinates (ξ1, ξ2) of the point g of the lobe's Gaussian plane: ξ1 =
/// atan2(g_y, g_x)/2π in [0, 1), ξ2 = 1 − exp(−|g|²/2). Uniform for g ~ N(0, I).
pub fn gaussian_to_xi(gx: f32, gy: f32) -> (f32, f32) {
    let xi1 = gy.atan2(gx) / std::f32::consts::TAU;
    let xi1 = if xi1 < 0.0 { xi1 + 1.0 } else { xi1 };
    (xi1, 1.0 - (-0.5 * (gx * gx + gy * gy)).exp())
}

/// What [`shade`] needs of the lobe: its LUT, p_h(n) and the tap grid (a, b).
#[derive(Clone, Copy)]
pub struct Lobe<'a> {
    /// The `hv-lut` table (RGBA: h·½+½, p_h/p_h(n)).
    pub lut: &'a Image,
    /// p_h at h = n (the sidecar's `p_h_n`).
    pub pdf_h_n: f32,
    /// The tap grid ([`grid_shape`]).
    pub grid: (usize, usize),
}

/// Every tap of [`shade`] in order, as (l in the frame's local coordinates, v·h, lod):
/// the geometry alone, for the shading and for the conformance check's read classes.
#[allow(clippy::too_many_arguments)]
pub fn for_each_tap(
    lobe: &Lobe,
    vl: Vec3,
    log2_texel_solid_angle: f32,
    max_lod: f32,
    bias: f32,
    shift: Option<glam::Vec2>,
    mut f: impl FnMut(Vec3, f32, f32),
) {
    let (a, b) = lobe.grid;
    let count = (a * b) as f32;
    let s = shift.unwrap_or(glam::Vec2::splat(0.5));
    for i in 0..a {
        let gx = normal_quantile((i as f32 + s.x) / a as f32);
        for j in 0..b {
            let gy = normal_quantile((j as f32 + s.y) / b as f32);
            let (xi1, xi2) = gaussian_to_xi(gx, gy);
            let (h, ratio) = ibl_lut::hv::lookup(lobe.lut, xi1 as f64, xi2 as f64);
            let h = h.as_vec3().normalize();
            let vh = vl.dot(h);
            let l = 2.0 * vh * h - vl;
            if vh <= 0.0 || l.z <= 0.0 {
                continue;
            }
            let pl = ratio as f32 * lobe.pdf_h_n / (4.0 * vh);
            let lod = if pl > 0.0 {
                (0.5 * (-(count * pl).log2() - log2_texel_solid_angle) + bias).clamp(0.0, max_lod)
            } else {
                max_lod
            };
            f(l, vh, lod);
        }
    }
}

/// (E0, E1) of one pixel: the taps of [`for_each_tap`] read from the pyramid, weighted by
/// (n·l)/max(n·v, n·l) (× (1−v·h)⁵ for E1); cell midpoints, or the grid shifted by `shift`
/// (the evaluator's `as-gridj-N`).
pub fn shade(
    pyr: &BorderedMips,
    lobe: &Lobe,
    frame: &Frame,
    v: Vec3,
    bias: f32,
    shift: Option<glam::Vec2>,
) -> E01 {
    let vl = frame.to_local(v).normalize();
    let (a, b) = lobe.grid;
    if vl.z <= 0.0 || a * b == 0 {
        return ([0.0; 3], [0.0; 3]);
    }
    let count = (a * b) as f32;
    let (mut e0, mut e1) = (Vec3::ZERO, Vec3::ZERO);
    let (log2_sa, max_lod) = (pyr.base_log2_texel_solid_angle(), pyr.max_lod() as f32);
    for_each_tap(lobe, vl, log2_sa, max_lod, bias, shift, |l, vh, lod| {
        let c = Vec3::from(pyr.sample(frame.to_world(l), lod));
        let w = l.z / vl.z.max(l.z);
        let chi = (1.0 - vh.min(1.0)).powf(SHIPPED_AS.schlick_power);
        e0 += w * c;
        e1 += (w * chi) * c;
    });
    ((e0 / count).into(), (e1 / count).into())
}

/// The shader languages (as [`crate::ship::Lang`]).
pub use crate::ship::Lang;

const HEADER: &str = "\
Ashikhmin-Shirley specular IBL at <= 32 taps: the half-vector LUT read on a grid of
equal-mass cells shaped to the lobe (issue 23, `as-grid-32` of bench/aniso-as-taps.md).
Generated by `aniso-eval --emit-shader` from ibl-aniso's ship_as.rs, the same constants and
steps as the evaluator's CPU emulation; do not edit.
Reads: hvLut, the lobe's `hv-lut` table (RGBA float, bilinear, clamp to edge, no mips; texel
(i, j) at (xi1, xi2) = ((i + 0.5) / W, (j + 0.5) / H), row 0 first), pdfHN its sidecar's p_h_n;
the environment cube with its full box mip chain (generateMipmap), seamless trilinear.
Inputs: gridA x gridB the tap grid, a along t (ibl_aniso::ship_as::grid_shape(n_u, n_v, 32),
once per material: a / b = sqrt((n_v + 1) / (n_u + 1)), a b <= 32); n, t, b an orthonormal
world frame (n_u along t); v the unit direction towards the eye;
log2TexelSolidAngle = log2(4 pi / (6 size^2)) of mip 0; maxLod = levels - 1.
Returns F0 E0 + (1 - F0) E1 (Schlick).";

/// The snippet in `lang`.
pub fn emit(lang: Lang) -> String {
    let c = SHIPPED_AS;
    let mut s = String::new();
    for line in HEADER.lines() {
        let _ = writeln!(s, "// {line}");
    }
    let (body, quantile) = match lang {
        Lang::Glsl => (GLSL, quantile_glsl()),
        Lang::Hlsl => (HLSL, quantile_glsl()),
        Lang::Wgsl => (WGSL, quantile_wgsl()),
    };
    s.push_str(
        &body
            .replace("{BIAS}", &crate::ship::lit(c.lod_bias))
            .replace("{POW}", &crate::ship::lit(c.schlick_power))
            .replace("{TAU}", &crate::ship::lit(std::f32::consts::TAU))
            .replace("{TAPS}", &c.taps.to_string())
            .replace("{QUANTILE}", &quantile),
    );
    s
}

/// The quantile in GLSL (also HLSL): the steps of [`normal_quantile`].
fn quantile_glsl() -> String {
    format!(
        "
float anisoAsQuantile(float p) {{
    p = clamp(p, 1e-30, 1.0 - 6e-8);
    if (p < 0.02425 || p > 1.0 - 0.02425) {{
        float q = sqrt(-2.0 * log(p < 0.5 ? p : 1.0 - p));
        float x = {c} / ({d} * q + 1.0);
        return p < 0.5 ? x : -x;
    }}
    float q = p - 0.5;
    float r = q * q;
    return {a} * q / ({b} * r + 1.0);
}}
",
        a = horner(&QUANTILE_A, "r"),
        b = horner(&QUANTILE_B, "r"),
        c = horner(&QUANTILE_C, "q"),
        d = horner(&QUANTILE_D, "q"),
    )
}

/// The quantile in WGSL.
fn quantile_wgsl() -> String {
    format!(
        "
fn aniso_as_quantile(p_in: f32) -> f32 {{
    let p = clamp(p_in, 1e-30, 1.0 - 6e-8);
    if (p < 0.02425 || p > 1.0 - 0.02425) {{
        let q = sqrt(-2.0 * log(select(1.0 - p, p, p < 0.5)));
        let x = {c} / ({d} * q + 1.0);
        return select(-x, x, p < 0.5);
    }}
    let q = p - 0.5;
    let r = q * q;
    return {a} * q / ({b} * r + 1.0);
}}
",
        a = horner(&QUANTILE_A, "r"),
        b = horner(&QUANTILE_B, "r"),
        c = horner(&QUANTILE_C, "q"),
        d = horner(&QUANTILE_D, "q"),
    )
}

const GLSL: &str = r#"
const float ANISO_AS_LOD_BIAS = {BIAS};
const float ANISO_AS_SCHLICK_POWER = {POW};
const float ANISO_AS_TAU = {TAU};
const int ANISO_AS_MAX_TAPS = {TAPS};
{QUANTILE}
vec3 anisoAsSpecular(samplerCube env, sampler2D hvLut, float pdfHN, int gridA, int gridB,
                     float log2TexelSolidAngle, float maxLod, vec3 n, vec3 t, vec3 b, vec3 v, vec3 f0) {
    vec3 vl = normalize(vec3(dot(v, t), dot(v, b), dot(v, n)));
    if (vl.z <= 0.0 || gridA * gridB <= 0) { return vec3(0.0); }
    float count = float(gridA * gridB);
    vec3 e0 = vec3(0.0);
    vec3 e1 = vec3(0.0);
    for (int i = 0; i < gridA; i++) {
        float gx = anisoAsQuantile((float(i) + 0.5) / float(gridA));
        for (int j = 0; j < gridB; j++) {
            float gy = anisoAsQuantile((float(j) + 0.5) / float(gridB));
            float xi1 = atan(gy, gx) / ANISO_AS_TAU;
            if (xi1 < 0.0) { xi1 += 1.0; }
            float xi2 = 1.0 - exp(-0.5 * (gx * gx + gy * gy));
            vec4 lut = textureLod(hvLut, vec2(xi1, xi2), 0.0);
            vec3 h = normalize(2.0 * lut.rgb - 1.0);
            float vh = dot(vl, h);
            vec3 l = 2.0 * vh * h - vl;
            if (vh <= 0.0 || l.z <= 0.0) { continue; }
            float pl = lut.a * pdfHN / (4.0 * vh);
            float lod = maxLod;
            if (pl > 0.0) {
                lod = clamp(0.5 * (-log2(count * pl) - log2TexelSolidAngle) + ANISO_AS_LOD_BIAS, 0.0, maxLod);
            }
            vec3 c = textureLod(env, t * l.x + b * l.y + n * l.z, lod).rgb;
            float w = l.z / max(vl.z, l.z);
            float chi = pow(1.0 - min(vh, 1.0), ANISO_AS_SCHLICK_POWER);
            e0 += w * c;
            e1 += (w * chi) * c;
        }
    }
    return (f0 * e0 + (1.0 - f0) * e1) / count;
}
"#;

const HLSL: &str = r#"
static const float ANISO_AS_LOD_BIAS = {BIAS};
static const float ANISO_AS_SCHLICK_POWER = {POW};
static const float ANISO_AS_TAU = {TAU};
static const int ANISO_AS_MAX_TAPS = {TAPS};
{QUANTILE}
float3 anisoAsSpecular(TextureCube env, SamplerState samp, Texture2D hvLut, SamplerState lutSamp,
                       float pdfHN, int gridA, int gridB, float log2TexelSolidAngle, float maxLod,
                       float3 n, float3 t, float3 b, float3 v, float3 f0) {
    float3 vl = normalize(float3(dot(v, t), dot(v, b), dot(v, n)));
    if (vl.z <= 0.0 || gridA * gridB <= 0) { return float3(0.0, 0.0, 0.0); }
    float count = float(gridA * gridB);
    float3 e0 = float3(0.0, 0.0, 0.0);
    float3 e1 = float3(0.0, 0.0, 0.0);
    for (int i = 0; i < gridA; i++) {
        float gx = anisoAsQuantile((float(i) + 0.5) / float(gridA));
        for (int j = 0; j < gridB; j++) {
            float gy = anisoAsQuantile((float(j) + 0.5) / float(gridB));
            float xi1 = atan2(gy, gx) / ANISO_AS_TAU;
            if (xi1 < 0.0) { xi1 += 1.0; }
            float xi2 = 1.0 - exp(-0.5 * (gx * gx + gy * gy));
            float4 lut = hvLut.SampleLevel(lutSamp, float2(xi1, xi2), 0.0);
            float3 h = normalize(2.0 * lut.rgb - 1.0);
            float vh = dot(vl, h);
            float3 l = 2.0 * vh * h - vl;
            if (vh <= 0.0 || l.z <= 0.0) { continue; }
            float pl = lut.a * pdfHN / (4.0 * vh);
            float lod = maxLod;
            if (pl > 0.0) {
                lod = clamp(0.5 * (-log2(count * pl) - log2TexelSolidAngle) + ANISO_AS_LOD_BIAS, 0.0, maxLod);
            }
            float3 c = env.SampleLevel(samp, t * l.x + b * l.y + n * l.z, lod).rgb;
            float w = l.z / max(vl.z, l.z);
            float chi = pow(1.0 - min(vh, 1.0), ANISO_AS_SCHLICK_POWER);
            e0 += w * c;
            e1 += (w * chi) * c;
        }
    }
    return (f0 * e0 + (1.0 - f0) * e1) / count;
}
"#;

const WGSL: &str = r#"
const ANISO_AS_LOD_BIAS: f32 = {BIAS};
const ANISO_AS_SCHLICK_POWER: f32 = {POW};
const ANISO_AS_TAU: f32 = {TAU};
const ANISO_AS_MAX_TAPS: i32 = {TAPS};

{QUANTILE}
fn aniso_as_specular(env: texture_cube<f32>, samp: sampler, hv_lut: texture_2d<f32>, lut_samp: sampler,
                     pdf_h_n: f32, grid_a: i32, grid_b: i32, log2_texel_solid_angle: f32, max_lod: f32,
                     n: vec3<f32>, t: vec3<f32>, b: vec3<f32>, v: vec3<f32>, f0: vec3<f32>) -> vec3<f32> {
    let vl = normalize(vec3<f32>(dot(v, t), dot(v, b), dot(v, n)));
    if (vl.z <= 0.0 || grid_a * grid_b <= 0) { return vec3<f32>(0.0); }
    let count = f32(grid_a * grid_b);
    var e0 = vec3<f32>(0.0);
    var e1 = vec3<f32>(0.0);
    for (var i = 0; i < grid_a; i = i + 1) {
        let gx = aniso_as_quantile((f32(i) + 0.5) / f32(grid_a));
        for (var j = 0; j < grid_b; j = j + 1) {
            let gy = aniso_as_quantile((f32(j) + 0.5) / f32(grid_b));
            var xi1 = atan2(gy, gx) / ANISO_AS_TAU;
            if (xi1 < 0.0) { xi1 = xi1 + 1.0; }
            let xi2 = 1.0 - exp(-0.5 * (gx * gx + gy * gy));
            let lut = textureSampleLevel(hv_lut, lut_samp, vec2<f32>(xi1, xi2), 0.0);
            let h = normalize(2.0 * lut.rgb - vec3<f32>(1.0));
            let vh = dot(vl, h);
            let l = 2.0 * vh * h - vl;
            if (vh <= 0.0 || l.z <= 0.0) { continue; }
            let pl = lut.a * pdf_h_n / (4.0 * vh);
            var lod = max_lod;
            if (pl > 0.0) {
                lod = clamp(0.5 * (-log2(count * pl) - log2_texel_solid_angle) + ANISO_AS_LOD_BIAS, 0.0, max_lod);
            }
            let c = textureSampleLevel(env, samp, t * l.x + b * l.y + n * l.z, lod).rgb;
            let w = l.z / max(vl.z, l.z);
            let chi = pow(1.0 - min(vh, 1.0), ANISO_AS_SCHLICK_POWER);
            e0 = e0 + w * c;
            e1 = e1 + (w * chi) * c;
        }
    }
    return (f0 * e0 + (vec3<f32>(1.0) - f0) * e1) / count;
}
"#;

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::sampling::Pcg32;
    use ibl_core::{CubeMips, Cubemap};

    #[test]
    fn normal_quantile_inverts_the_normal_cdf_and_is_odd() {
        let phi = |x: f64| 0.5 * ibl_brdf::special::erfc(-x * std::f64::consts::FRAC_1_SQRT_2);
        // Dyadic p: p and 1 − p are exact in f32.
        for k in 1..2048 {
            let p = k as f64 / 2048.0;
            let x = normal_quantile(p as f32) as f64;
            // f32 steps: a few ulps of p (and erfc's own 1.2e-7).
            // The central branch's f32 Horner form cancels near its edge (p ≈ 0.025): there
            // Φ(x) is 1e-5 off p, a tap moved by 2e-4 of a standard deviation.
            let m = p.min(1.0 - p);
            let tol = if m < 0.02 { 1e-4 * m } else { 2e-5 };
            assert!((phi(x) - p).abs() < tol, "{p}: {x}: {}", phi(x) - p);
            let y = normal_quantile((1.0 - p) as f32) as f64;
            assert!((x + y).abs() < 2e-6 * x.abs().max(1.0), "{p}: {x} {y}");
        }
        for p in [1e-12f32, 1e-6, 1e-3] {
            let x = normal_quantile(p) as f64;
            assert!(((phi(x) - p as f64) / p as f64).abs() < 1e-4, "{p}: {x}");
        }
        for p in [0.0, 1.0, -1.0, 2.0] {
            assert!(normal_quantile(p).is_finite(), "{p}");
        }
    }

    #[test]
    fn gaussian_plane_to_xi_maps_the_standard_normal_to_the_uniform_square() {
        // χ² of (ξ1, ξ2) over 8 × 8 bins for g from independent normal quantiles of a seeded
        // generator: 63 degrees of freedom, p ≈ 1e-4 at 110.
        let mut rng = Pcg32::new(7, 3);
        let n = 64_000;
        let mut bins = [0u32; 64];
        for _ in 0..n {
            let gx = normal_quantile(rng.next_f32() * 0.999_99 + 5e-6);
            let gy = normal_quantile(rng.next_f32() * 0.999_99 + 5e-6);
            let (x1, x2) = gaussian_to_xi(gx, gy);
            assert!((0.0..=1.0).contains(&x1) && (0.0..=1.0).contains(&x2));
            let (i, j) = (((x1 * 8.0) as usize).min(7), ((x2 * 8.0) as usize).min(7));
            bins[j * 8 + i] += 1;
        }
        let e = n as f64 / 64.0;
        let chi2: f64 = bins.iter().map(|&c| (c as f64 - e).powi(2) / e).sum();
        assert!(chi2 < 110.0, "χ² {chi2}: {bins:?}");
    }

    #[test]
    fn grid_shapes_fit_the_lobe() {
        assert_eq!(grid_shape(100.0, 100.0, 32), (5, 6));
        assert_eq!(grid_shape(100.0, 100.0, 16), (4, 4));
        assert_eq!(grid_shape(20000.0, 70.0, 32), (1, 32));
        assert_eq!(grid_shape(70.0, 20000.0, 32), (32, 1));
        assert_eq!(grid_shape(1e6, 1.0, 7), (1, 7));
        for n in 1..=64 {
            for (nu, nv) in [(1.0, 1.0), (100.0, 10.0), (10.0, 1e4), (1e6, 1e6)] {
                let (a, b) = grid_shape(nu, nv, n);
                assert!(
                    a * b <= n && a * b * 4 >= n * 3,
                    "({nu}, {nv}) {n}: {a} × {b}"
                );
            }
        }
    }

    #[test]
    fn edges_give_finite_values_and_nothing_below_the_horizon() {
        // Exponents from 1 to 10⁶, views from the normal to grazing and below, a sun of 10⁵.
        let mut cube = Cubemap::constant(16, [1.0; 3]);
        cube.faces[2].texel_mut(8, 8).copy_from_slice(&[1e5; 3]);
        let pyr = BorderedMips::new(&CubeMips::build(cube, 5));
        let n = Vec3::new(0.0, 0.0, -1.0);
        let t = Vec3::X;
        let frame = Frame {
            t,
            b: n.cross(t),
            n,
        };
        for (nu, nv) in [(1.0, 1.0), (1e6, 1.0), (1.0, 1e6), (1e6, 1e6)] {
            let a = ibl_brdf::AshikhminShirley::new(nu, nv);
            let lut = ibl_lut::hv::hv_table(&a, 64, &ibl_core::progress::NoProgress);
            let grid = grid_shape(nu, nv, SHIPPED_AS.taps);
            for z in [1.0f32, 0.3, 1e-3, 0.0, -0.2] {
                let v = frame.to_world(Vec3::new((1.0 - z * z).max(0.0).sqrt(), 0.0, z));
                let lobe = Lobe {
                    lut: &lut,
                    pdf_h_n: a.pdf_h_at_normal() as f32,
                    grid,
                };
                let e = shade(&pyr, &lobe, &frame, v, 0.0, None);
                assert!(
                    e.0.iter().chain(&e.1).all(|c| c.is_finite() && *c >= 0.0),
                    "{nu} {nv} {z}: {e:?}"
                );
                if z <= 0.0 {
                    assert_eq!(e, ([0.0; 3], [0.0; 3]));
                }
            }
        }
    }

    fn constant(text: &str, name: &str) -> String {
        let line = text
            .lines()
            .find(|l| l.contains(name) && l.contains('='))
            .unwrap_or_else(|| panic!("{name} in {text}"));
        line.split('=')
            .nth(1)
            .unwrap()
            .trim()
            .trim_end_matches(';')
            .trim()
            .to_string()
    }

    #[test]
    fn snippets_carry_the_emulations_constants_and_coefficients() {
        for (lang, _) in Lang::ALL {
            let text = emit(lang);
            for (name, value) in [
                ("ANISO_AS_LOD_BIAS", SHIPPED_AS.lod_bias),
                ("ANISO_AS_SCHLICK_POWER", SHIPPED_AS.schlick_power),
                ("ANISO_AS_TAU", std::f32::consts::TAU),
            ] {
                let v: f32 = constant(&text, name).parse().unwrap();
                assert_eq!(v, value, "{lang:?} {name}");
            }
            for c in QUANTILE_A
                .iter()
                .chain(&QUANTILE_B)
                .chain(&QUANTILE_C)
                .chain(&QUANTILE_D)
            {
                let l = crate::ship::lit(*c as f32);
                assert!(text.contains(&l), "{lang:?}: {l}");
                assert_eq!(l.parse::<f32>().unwrap(), *c as f32);
            }
            assert!(
                !text.contains("{QUANTILE}") && !text.contains("{BIAS}"),
                "{lang:?}"
            );
        }
    }

    use crate::ship::tests::assert_compiles;

    #[test]
    fn snippets_compile_in_real_front_ends() {
        let dir = std::env::temp_dir().join(format!("ibl-aniso-ship-as-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let call =
            "anisoAsSpecular(env, lut, 20.0, 1, 32, -5.0, 6.0, n, t, cross(n, t), n, vec3(0.04))";
        let glsl_file = dir.join("aniso_as.frag");
        std::fs::write(
            &glsl_file,
            format!(
                "#version 450\n{}layout(binding = 0) uniform samplerCube env;\nlayout(binding = 1) uniform sampler2D lut;\n\
                 layout(location = 0) in vec3 n;\nlayout(location = 0) out vec4 color;\n\
                 void main() {{\n vec3 t = normalize(cross(vec3(0.0, 1.0, 0.0), n));\n color = vec4({call}, 1.0);\n}}\n",
                emit(Lang::Glsl)
            ),
        )
        .unwrap();
        let es_main = format!(
            "uniform samplerCube env;\nuniform sampler2D lut;\nin vec3 n;\nout vec4 color;\n\
             void main() {{\n vec3 t = normalize(cross(vec3(0.0, 1.0, 0.0), n));\n color = vec4({call}, 1.0);\n}}\n"
        );
        let es_file = dir.join("aniso_as_es300.frag");
        std::fs::write(
            &es_file,
            format!(
                "#version 300 es\nprecision highp float;\nprecision highp int;\n{}{es_main}",
                emit(Lang::Glsl)
            ),
        )
        .unwrap();
        let gl330_file = dir.join("aniso_as_330.frag");
        std::fs::write(
            &gl330_file,
            format!("#version 330\n{}{es_main}", emit(Lang::Glsl)),
        )
        .unwrap();
        let hlsl_file = dir.join("aniso_as.hlsl");
        std::fs::write(
            &hlsl_file,
            emit(Lang::Hlsl)
                + "TextureCube env : register(t0);\nSamplerState samp : register(s0);\n\
                   Texture2D lut : register(t1);\nSamplerState lutSamp : register(s1);\n\
                   float4 main(float3 n : TEXCOORD0) : SV_Target {\n\
                   float3 t = normalize(cross(float3(0.0, 1.0, 0.0), n));\n\
                   return float4(anisoAsSpecular(env, samp, lut, lutSamp, 20.0, 1, 32, -5.0, 6.0, n, t, cross(n, t), n, float3(0.04, 0.04, 0.04)), 1.0);\n}\n",
        )
        .unwrap();
        let wgsl_file = dir.join("aniso_as.wgsl");
        std::fs::write(
            &wgsl_file,
            emit(Lang::Wgsl)
                + "@group(0) @binding(0) var env: texture_cube<f32>;\n\
                   @group(0) @binding(1) var samp: sampler;\n\
                   @group(0) @binding(2) var lut: texture_2d<f32>;\n\
                   @fragment fn main(@location(0) n: vec3<f32>) -> @location(0) vec4<f32> {\n\
                   let t = normalize(cross(vec3<f32>(0.0, 1.0, 0.0), n));\n\
                   let c = aniso_as_specular(env, samp, lut, samp, 20.0, 1, 32, -5.0, 6.0, n, t, cross(n, t), n, vec3<f32>(0.04));\n\
                   return vec4<f32>(c, 1.0);\n}\n",
        )
        .unwrap();
        let spv = dir.join("hlsl.spv");
        assert_compiles("glslangValidator", &[], &glsl_file);
        assert_compiles("glslangValidator", &[], &es_file);
        assert_compiles("glslangValidator", &[], &gl330_file);
        assert_compiles(
            "glslangValidator",
            &[
                "-D",
                "-V",
                "-e",
                "main",
                "-S",
                "frag",
                "-o",
                spv.to_str().unwrap(),
            ],
            &hlsl_file,
        );
        assert_compiles("naga", &[], &wgsl_file);
        std::fs::remove_dir_all(&dir).ok();
    }
}
