//! The shipped anisotropic IBL method (issue 23 items 6–7): VNDF filtered importance sampling
//! at 16 taps (`fis-16`, the winner of `bench/aniso.md`, at lod bias 0: `fis-16-b0`) blended
//! into the isotropic split sum as the anisotropy vanishes (`fisb-16`), as one source of
//! truth — the constants in [`SHIPPED`], the CPU emulation [`shade`] the evaluator runs, and
//! the GLSL / HLSL / WGSL snippets [`glsl`], [`hlsl`], [`wgsl`] written from the same
//! constants and the same steps.
//!
//! What it reads: the environment cube with its box mip pyramid — `equirect-to-cube`'s cube
//! with the mips the engine's `generateMipmap` (2×2 box per level, power-of-two faces) builds,
//! read trilinearly and seamlessly (`ibl_core::bordered::BorderedMips::sample`, the evaluator's
//! model of a GPU's `textureLod` with `GL_TEXTURE_CUBE_MAP_SEAMLESS`) — and the engine's own
//! isotropic split-sum result at r_iso = √((α_t+α_b)/2) (its prefiltered chain and DFG table,
//! which the engine computes for its isotropic materials anyway), passed in.
//!
//! Why the blend (goal G2, "never worse than the isotropic floor at η = 0"): at η = 0 the
//! anisotropic lobe *is* the isotropic one, and the prefiltered chain integrates it over the
//! whole lobe where 16 FIS taps only estimate it (2.81× the floor's MSE under a small sun at
//! r = 0.2). So the method reads the isotropic split sum at η = 0 below r₀ (w = 0: exactly
//! the floor, and no FIS tap is taken) and mixes in FIS as |η| or r grows:
//! specular = iso + (fis − iso)·w,
//! w = max(clamp(|η|/η₁, 0, 1)^p, clamp((r_iso − r₀)/Δr, 0, 1)), (η₁, p, r₀, Δr) fitted on
//! training environments and scored on held-out ones (`examples/fit_blend.rs`,
//! bench/aniso-blend.md). The roughness ramp is there because the floor's own error changes
//! with r: below r₀ a small source makes 16 taps noisier than the chain (the 2.8× above), but
//! on rough lobes the split sum's read along the mirror direction (no off-specular shift, the
//! lobe's shape at grazing views ignored) costs more than FIS's noise, even at η = 0: FIS has
//! 0.02–0.6× the floor's MSE there on every training environment and view (r ≥ 0.6).
//!
//! FIS: Křivánek & Colbert 2008 (GPU Gems 3 ch. 20) filtered importance sampling with
//! Heitz 2018's visible-normal sampling of anisotropic GGX: N Hammersley points (shifted by a
//! per-pixel rotation the caller supplies, Cranley–Patterson), m ~ D_v(m), l = reflect(v, m),
//! weight G2/G1 = (1+Λ(v))/(1+Λ(v)+Λ(l)), lod = ½(log2 Ω_s − log2 Ω_p) + bias with
//! Ω_s = 1/(N p_l), p_l = D(m) G1(v) / (4 n·v) (Křivánek & Colbert eq. 13; the +1 bias is
//! theirs). E0 = mean w·L (F0 = 1), E1 = mean w·(1−v·m)⁵·L, specular = F0·E0 + (1−F0)·E1.
//! Note on eq. 13: the chapter's pdf is that of the *light* direction (p_l = p_h/(4 v·h)); with
//! visible normals p_h = D G1(v) (v·m)/(n·v), so p_l = D G1(v)/(4 n·v) — the v·h cancels. Using
//! D(m)(n·m)/(4 v·h) (their GGX sampler's pdf) with VNDF taps would mis-size every tap.
//! Reading, not corrected: Ω_p is one texel's *mean* solid angle 4π/(6 size²); on a cube a
//! face-centre texel is 1.91× that and a corner texel 0.37×, so the lod is ~0.47 levels high at
//! face centres and ~0.72 low at corners (using the local texel's Ω_p instead was measured and
//! did not help: docs/notes/fis-bias.md).
//! Erratum of eq. 13's +1 bias for VNDF taps: it over-blurs. A bias of 0 halves the MSE of
//! 16 taps on training environments (geometric mean 0.43×, 0.69× held out) and shrinks FIS's
//! loss to the isotropic split sum at η = 0 (worst 3.2× → 2.8×, so the blend stays;
//! docs/notes/fis-bias.md; evaluator `fis-N-bB`).
//! [`SHIPPED`] carries 0, the training optimum; the evaluator's `fis-N` keeps the published +1.

use crate::scene::Frame;
use glam::{Vec2, Vec3};
use ibl_core::bordered::BorderedMips;

/// (E0, E1) of one pixel.
pub type E01 = ([f32; 3], [f32; 3]);
use std::fmt::Write;

/// The shipped method's constants: the emulation and the three snippets read these only.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Shipped {
    /// Taps per pixel (cube reads).
    pub taps: u32,
    /// Added to the lod of Křivánek & Colbert 2008 eq. 13 (they recommend +1; fitted here).
    pub lod_bias: f32,
    /// Exponent of the Schlick tail (1 − v·m)^p.
    pub schlick_power: f32,
    /// Smallest α along either axis: α = 0 (r = 0) would make D(m) infinite.
    pub alpha_min: f32,
    /// |η| from which the method is pure FIS: below it the isotropic split sum is mixed in
    /// with weight 1 − w, w = max(clamp(|η|/blend_eta, 0, 1)^blend_power, the roughness
    /// ramp) ([`fis_weight`]). Fitted on training environments by `examples/fit_blend.rs`
    /// (bench/aniso-blend.md).
    pub blend_eta: f32,
    /// Exponent of the η term of the blend weight.
    pub blend_power: f32,
    /// r_iso = √((α_t+α_b)/2) where the roughness ramp clamp((r_iso − r₀)/Δr, 0, 1) of the
    /// blend weight starts: below it an isotropic lobe reads only the split sum.
    pub blend_r0: f32,
    /// The ramp's width Δr (FIS alone from r₀ + Δr, whatever η).
    pub blend_r_width: f32,
}

/// The shipped method: `fisb-16` of `bench/aniso.md` (FIS at 16 taps and lod bias 0, blended
/// into the isotropic split sum as the anisotropy vanishes).
pub const SHIPPED: Shipped = Shipped {
    taps: 16,
    // Not Křivánek & Colbert's +1: with visible-normal taps it over-blurs. 0 is the training
    // optimum of the sweep in docs/notes/fis-bias.md (MSE 0.43× of +1 on training, 0.69× held
    // out).
    lod_bias: 0.0,
    schlick_power: 5.0,
    alpha_min: 1e-3,
    // bench/aniso-blend.md: the training optimum over η₁ ∈ {0.1 … 2} × p ∈ {0.15 … 2} × the
    // roughness ramps (r₀ ∈ {0.2 … 1}, Δr ∈ {0.1 … 0.4}, or none) among the rules that keep
    // goal G2 on training (every gated η = 0 case at most 1.05× the floor's MSE); an
    // η₁(r) = a + b·r family was tried and lost the leave-one-environment-out comparison.
    // FIS at the lod bias above beats the isotropic split sum for nearly every η ≠ 0, so the
    // η term is almost a switch: w = 0.85 at |η| = 0.1, 0.94 at 0.2, 1 from 0.3.
    blend_eta: 0.3,
    blend_power: 0.15,
    // The ramp: FIS from r = 0.45 whatever η; at η = 0 the split sum alone up to r = 0.25,
    // where FIS alone exceeds the floor 2.8× (interior_256, r = 0.2: docs/notes/fis-bias.md)
    // and a ramp starting at 0.2 breaks G2 on training (1.24× at r = 0.4).
    blend_r0: 0.25,
    blend_r_width: 0.2,
};

/// The steps, in the order every snippet defines them (GLSL/HLSL name, WGSL name): the
/// emulation's functions of the same role are [`lambda`], [`d_ggx`], [`sample_vndf`],
/// [`hammersley`], [`fis_weight`], [`shade`].
pub const STEPS: [(&str, &str); 6] = [
    ("anisoFisLambda", "aniso_fis_lambda"),
    ("anisoFisD", "aniso_fis_d"),
    ("anisoFisSampleVndf", "aniso_fis_sample_vndf"),
    ("anisoFisHammersley", "aniso_fis_hammersley"),
    ("anisoFisWeight", "aniso_fis_weight"),
    ("anisoFisSpecular", "aniso_fis_specular"),
];

/// 1/2^24: the radical inverse keeps the top 24 reversed bits (exact in f32), as
/// `ibl_core::sampling::hammersley` does.
const INV_2_24: f32 = 1.0 / 16_777_216.0;

/// Smith Λ of anisotropic GGX for w.z > 0 (Heitz 2014 eqs. 72, 80), written without the
/// cancelling −1: a / (2(1 + √(1 + a))), a = (α_x² w_x² + α_y² w_y²)/w_z².
pub fn lambda(w: Vec3, ax: f32, ay: f32) -> f32 {
    let a = (ax * ax * w.x * w.x + ay * ay * w.y * w.y) / (w.z * w.z);
    a / (2.0 * (1.0 + (1.0 + a).sqrt()))
}

/// D(m) of anisotropic GGX (Heitz 2014 eq. 85); 0 below the horizon.
pub fn d_ggx(m: Vec3, ax: f32, ay: f32) -> f32 {
    if m.z <= 0.0 {
        return 0.0;
    }
    let s = Vec3::new(m.x / ax, m.y / ay, m.z);
    let t = s.dot(s);
    1.0 / (std::f32::consts::PI * ax * ay * t * t)
}

/// Visible-normal sample of anisotropic GGX (Heitz 2018, "Sampling the GGX Distribution of
/// Visible Normals", listing 1), v local with v.z > 0, u in [0, 1)².
pub fn sample_vndf(v: Vec3, u: Vec2, ax: f32, ay: f32) -> Vec3 {
    let vh = Vec3::new(ax * v.x, ay * v.y, v.z).normalize();
    let lensq = vh.x * vh.x + vh.y * vh.y;
    let t1 = if lensq > 0.0 {
        Vec3::new(-vh.y, vh.x, 0.0) / lensq.sqrt()
    } else {
        Vec3::X
    };
    let t2 = vh.cross(t1);
    let r = u.x.clamp(0.0, 1.0).sqrt();
    let phi = std::f32::consts::TAU * u.y;
    let p1 = r * phi.cos();
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
    let pz = (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
    let nh = p1 * t1 + p2 * t2 + pz * vh;
    let ne = Vec3::new(ax * nh.x, ay * nh.y, nh.z.max(0.0));
    let l = ne.length();
    if l > 0.0 {
        ne / l
    } else {
        Vec3::Z
    }
}

/// The i-th of [`SHIPPED`]`.taps` Hammersley points shifted by `rotation` modulo 1.
pub fn hammersley(i: u32, rotation: Vec2) -> Vec2 {
    let h = Vec2::new(
        i as f32 / SHIPPED.taps as f32,
        (i.reverse_bits() >> 8) as f32 * INV_2_24,
    );
    let s = h + rotation;
    s - s.floor()
}

/// The blend weight of FIS against the isotropic split sum for the lobe (α_t, α_b):
/// w = max(clamp(|η|/η₁, 0, 1)^p, clamp((r_iso − r₀)/Δr, 0, 1)) with the Kulla–Conty
/// η = (α_t − α_b)/(α_t + α_b), r_iso = √((α_t+α_b)/2) (w = 0 for α_t = α_b = 0) and
/// (η₁, p, r₀, Δr) = [`SHIPPED`]`.blend_eta`, `.blend_power`, `.blend_r0`, `.blend_r_width`.
pub fn fis_weight(at: f32, ab: f32) -> f32 {
    let s = at + ab;
    if s.is_nan() || s <= 0.0 {
        return 0.0;
    }
    // The roughness ramp: exactly 0 below r₀ (a clamp of a negative), so an isotropic lobe
    // there reads the split sum alone.
    let ramp = (((0.5 * s).sqrt() - SHIPPED.blend_r0) / SHIPPED.blend_r_width).clamp(0.0, 1.0);
    let eta = ((at - ab) / s).abs();
    // Exactly 0 at η = 0 without pow: a GPU's pow(0, p) is exp2(p·log2 0), which SwiftShader
    // returns as about 2e-7 at p = 0.15 (the browser check's η = 0 cases then missed the floor
    // by 6e-6 relative); the snippets test η the same way.
    if eta.is_nan() || eta <= 0.0 {
        return ramp;
    }
    let w = (eta / SHIPPED.blend_eta)
        .clamp(0.0, 1.0)
        .powf(SHIPPED.blend_power);
    w.max(ramp)
}

/// The shipped method at one pixel (`fisb-16`): iso + (fis − iso)·w per E0 and E1, w =
/// [`fis_weight`], fis = [`shade_fis`], `iso` the engine's isotropic split sum at r_iso as
/// (E0, E1). At w = 0 (η = 0 and r_iso ≤ r₀) it returns `iso` untouched and takes no FIS tap.
pub fn shade(
    pyr: &BorderedMips,
    frame: &Frame,
    v: Vec3,
    at: f32,
    ab: f32,
    rotation: Vec2,
    iso: E01,
) -> E01 {
    shade_blend_n(pyr, frame, v, at, ab, SHIPPED.taps, rotation, iso)
}

/// [`shade`] with `taps` FIS taps (the evaluator's `fisb-N`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn shade_blend_n(
    pyr: &BorderedMips,
    frame: &Frame,
    v: Vec3,
    at: f32,
    ab: f32,
    taps: u32,
    rotation: Vec2,
    iso: E01,
) -> E01 {
    let w = fis_weight(at, ab);
    if w <= 0.0 {
        return iso;
    }
    let f = shade_n(pyr, frame, v, at, ab, taps, rotation, SHIPPED.lod_bias);
    let mix = |a: [f32; 3], b: [f32; 3]| -> [f32; 3] {
        std::array::from_fn(|k| a[k] + (b[k] - a[k]) * w)
    };
    (mix(iso.0, f.0), mix(iso.1, f.1))
}

/// Pure VNDF FIS at N = [`SHIPPED`]`.taps` and its lod bias (`fis-16-b0`; the evaluator's
/// `fis-16` is the published +1): (E0, E1) of the pyramid `pyr` for the frame, the view v
/// (world, towards the eye), α_t along t, α_b along b and the per-pixel rotation. Returns
/// zeros when v is below the shading normal.
pub fn shade_fis(
    pyr: &BorderedMips,
    frame: &Frame,
    v: Vec3,
    at: f32,
    ab: f32,
    rotation: Vec2,
) -> E01 {
    shade_n(
        pyr,
        frame,
        v,
        at,
        ab,
        SHIPPED.taps,
        rotation,
        SHIPPED.lod_bias,
    )
}

/// [`shade_fis`] with `taps` in place of [`SHIPPED`]`.taps` and `lod_bias` added to every
/// tap's lod in place of the shipped rule's (the evaluator's `fis-N[-bB]`).
#[allow(clippy::too_many_arguments)]
pub(crate) fn shade_n(
    pyr: &BorderedMips,
    frame: &Frame,
    v: Vec3,
    at: f32,
    ab: f32,
    taps: u32,
    rotation: Vec2,
    lod_bias: f32,
) -> E01 {
    let (at, ab) = (at.max(SHIPPED.alpha_min), ab.max(SHIPPED.alpha_min));
    let vl = frame.to_local(v).normalize();
    if vl.z <= 0.0 || taps == 0 {
        return ([0.0; 3], [0.0; 3]);
    }
    let lv = lambda(vl, at, ab);
    let g1 = 1.0 / (1.0 + lv);
    let log2_sa = pyr.base_log2_texel_solid_angle();
    let max_lod = pyr.max_lod() as f32;
    let (mut e0, mut e1) = (Vec3::ZERO, Vec3::ZERO);
    for i in 0..taps {
        let h = Vec2::new(
            i as f32 / taps as f32,
            (i.reverse_bits() >> 8) as f32 * INV_2_24,
        ) + rotation;
        let m = sample_vndf(vl, h - h.floor(), at, ab);
        let l = 2.0 * vl.dot(m) * m - vl;
        if l.z <= 0.0 {
            continue;
        }
        let pl = g1 * d_ggx(m, at, ab) / (4.0 * vl.z);
        let lod = if pl > 0.0 {
            (0.5 * (-(taps as f32 * pl).log2() - log2_sa) + lod_bias).clamp(0.0, max_lod)
        } else {
            max_lod
        };
        let c = Vec3::from(pyr.sample(frame.to_world(l), lod));
        let w = (1.0 + lv) / (1.0 + lv + lambda(l, at, ab));
        let chi = (1.0 - vl.dot(m).clamp(0.0, 1.0)).powf(SHIPPED.schlick_power);
        e0 += w * c;
        e1 += w * chi * c;
    }
    let inv = 1.0 / taps as f32;
    ((e0 * inv).into(), (e1 * inv).into())
}

/// The snippets' `anisoFisSpecular` step for step, at the level of the returned radiance:
/// `iso_specular` (the engine's isotropic split sum F0·E0 + (1−F0)·E1 at r_iso, the snippets'
/// `isoSpecular`) untouched when w = [`fis_weight`] is 0 (η = 0, r_iso ≤ r₀: bit for bit, no
/// tap), else
/// iso + (fis − iso)·w with fis = [`specular`] of [`shade_fis`] (zeros below the horizon, as
/// the snippet's `isoSpecular − isoSpecular·w`). Equal to [`specular`] of [`shade`] up to
/// rounding (the blend is linear); this is the form the browser check compares with.
pub fn shade_specular(
    pyr: &BorderedMips,
    frame: &Frame,
    v: Vec3,
    (at, ab): (f32, f32),
    f0: [f32; 3],
    rotation: Vec2,
    iso_specular: [f32; 3],
) -> [f32; 3] {
    let w = fis_weight(at, ab);
    if w <= 0.0 {
        return iso_specular;
    }
    let fis = specular(&shade_fis(pyr, frame, v, at, ab, rotation), f0);
    std::array::from_fn(|k| iso_specular[k] + (fis[k] - iso_specular[k]) * w)
}

/// Specular radiance F0·E0 + (1−F0)·E1 (Schlick), what the snippets' last step returns.
pub fn specular(e: &E01, f0: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|k| f0[k] * e.0[k] + (1.0 - f0[k]) * e.1[k])
}

/// A float literal GLSL, HLSL and WGSL all read back to the same f32.
pub(crate) fn lit(v: f32) -> String {
    let s = format!("{v:?}");
    if s.contains('.') || s.contains('e') {
        s
    } else {
        format!("{s}.0")
    }
}

/// The shader languages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lang {
    /// GLSL ES 3.00 (WebGL2), GLSL 3.30+ and Vulkan GLSL (its own bit reversal,
    /// `anisoFisRadicalInverse`: ES 3.00 and 3.30 lack `bitfieldReverse`).
    Glsl,
    /// HLSL SM 5+ (reversebits).
    Hlsl,
    /// WGSL.
    Wgsl,
}

impl Lang {
    /// Every language, with its file extension.
    pub const ALL: [(Lang, &'static str); 3] = [
        (Lang::Glsl, "glsl"),
        (Lang::Hlsl, "hlsl"),
        (Lang::Wgsl, "wgsl"),
    ];
}

const HEADER: &str = "\
Anisotropic GGX specular IBL: VNDF filtered importance sampling blended into the isotropic
split sum as the anisotropy vanishes (issue 23, `fisb-16` of bench/aniso.md). Generated by
`aniso-eval --emit-shader` from ibl-aniso's ship.rs, the same constants and steps as the
evaluator's CPU emulation; do not edit.
Reads: the environment cube with its full box mip chain (generateMipmap), seamless trilinear.
Inputs: n, t, b an orthonormal world frame (t the tangent, alpha_t along it); v the unit
direction towards the eye; alpha_t = r^2 (1 + eta), alpha_b = r^2 (1 - eta) (Kulla-Conty);
log2TexelSolidAngle = log2(4 pi / (6 size^2)) of mip 0; maxLod = levels - 1;
rotation in the unit square per pixel (blue noise, or 0 for a fixed pattern);
isoSpecular the engine's own isotropic split sum for this pixel at
r = sqrt((alpha_t + alpha_b) / 2) (prefiltered chain times F0 A + B), returned as is at
eta = 0 (no tap taken).
Returns iso + (fis - iso) w, fis = F0 E0 + (1 - F0) E1 (Schlick), w = anisoFisWeight.
The cube is read with the engine's direction convention: flip l here if the engine's cube
is mirrored.";

/// The snippet in `lang`.
pub fn emit(lang: Lang) -> String {
    let c = SHIPPED;
    let mut s = String::new();
    for line in HEADER.lines() {
        let _ = writeln!(s, "// {line}");
    }
    let (taps, bias, pow, amin) = (
        format!("{}u", c.taps),
        lit(c.lod_bias),
        lit(c.schlick_power),
        lit(c.alpha_min),
    );
    let pi = lit(std::f32::consts::PI);
    let inv = lit(INV_2_24);
    let body = match lang {
        Lang::Glsl => GLSL,
        Lang::Hlsl => HLSL,
        Lang::Wgsl => WGSL,
    };
    s.push_str(
        &body
            .replace("{TAPS}", &taps)
            .replace("{BIAS}", &bias)
            .replace("{POW}", &pow)
            .replace("{AMIN}", &amin)
            .replace("{PI}", &pi)
            .replace("{INV24}", &inv)
            .replace("{BETA}", &lit(c.blend_eta))
            .replace("{BPOW}", &lit(c.blend_power))
            .replace("{BR0}", &lit(c.blend_r0))
            .replace("{BRW}", &lit(c.blend_r_width)),
    );
    s
}

/// The GLSL snippet.
pub fn glsl() -> String {
    emit(Lang::Glsl)
}
/// The HLSL snippet.
pub fn hlsl() -> String {
    emit(Lang::Hlsl)
}
/// The WGSL snippet.
pub fn wgsl() -> String {
    emit(Lang::Wgsl)
}

const GLSL: &str = r#"
const uint ANISO_FIS_TAPS = {TAPS};
const float ANISO_FIS_LOD_BIAS = {BIAS};
const float ANISO_FIS_SCHLICK_POWER = {POW};
const float ANISO_FIS_ALPHA_MIN = {AMIN};
const float ANISO_FIS_PI = {PI};
const float ANISO_FIS_INV_2_24 = {INV24};
const float ANISO_FIS_BLEND_ETA = {BETA};
const float ANISO_FIS_BLEND_POWER = {BPOW};
const float ANISO_FIS_BLEND_R0 = {BR0};
const float ANISO_FIS_BLEND_R_WIDTH = {BRW};

float anisoFisLambda(vec3 w, float ax, float ay) {
    float a = (ax * ax * w.x * w.x + ay * ay * w.y * w.y) / (w.z * w.z);
    return a / (2.0 * (1.0 + sqrt(1.0 + a)));
}

float anisoFisD(vec3 m, float ax, float ay) {
    if (m.z <= 0.0) { return 0.0; }
    vec3 s = vec3(m.x / ax, m.y / ay, m.z);
    float t = dot(s, s);
    return 1.0 / (ANISO_FIS_PI * ax * ay * t * t);
}

vec3 anisoFisSampleVndf(vec3 v, vec2 u, float ax, float ay) {
    vec3 vh = normalize(vec3(ax * v.x, ay * v.y, v.z));
    float lensq = vh.x * vh.x + vh.y * vh.y;
    vec3 t1 = vec3(1.0, 0.0, 0.0);
    if (lensq > 0.0) { t1 = vec3(-vh.y, vh.x, 0.0) / sqrt(lensq); }
    vec3 t2 = cross(vh, t1);
    float r = sqrt(clamp(u.x, 0.0, 1.0));
    float phi = 2.0 * ANISO_FIS_PI * u.y;
    float p1 = r * cos(phi);
    float s = 0.5 * (1.0 + vh.z);
    float p2 = (1.0 - s) * sqrt(max(1.0 - p1 * p1, 0.0)) + s * r * sin(phi);
    float pz = sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0));
    vec3 nh = p1 * t1 + p2 * t2 + pz * vh;
    vec3 ne = vec3(ax * nh.x, ay * nh.y, max(nh.z, 0.0));
    float l = length(ne);
    if (l > 0.0) { return ne / l; }
    return vec3(0.0, 0.0, 1.0);
}

// The 32-bit reversal of bits, by shifts and masks: GLSL ES 3.00 (WebGL2) and GLSL 3.30 have
// no bitfieldReverse (GLSL 4.00 / ES 3.10), so the snippet carries its own and runs as is in
// WebGL2, GLSL 3.30+ and Vulkan GLSL. Same result as bitfieldReverse for every uint.
uint anisoFisRadicalInverse(uint bits) {
    bits = (bits << 16u) | (bits >> 16u);
    bits = ((bits & 0x55555555u) << 1u) | ((bits & 0xAAAAAAAAu) >> 1u);
    bits = ((bits & 0x33333333u) << 2u) | ((bits & 0xCCCCCCCCu) >> 2u);
    bits = ((bits & 0x0F0F0F0Fu) << 4u) | ((bits & 0xF0F0F0F0u) >> 4u);
    bits = ((bits & 0x00FF00FFu) << 8u) | ((bits & 0xFF00FF00u) >> 8u);
    return bits;
}

vec2 anisoFisHammersley(uint i, vec2 rotation) {
    vec2 h = vec2(float(i) / float(ANISO_FIS_TAPS), float(anisoFisRadicalInverse(i) >> 8u) * ANISO_FIS_INV_2_24);
    return fract(h + rotation);
}

float anisoFisWeight(float alphaT, float alphaB) {
    float s = alphaT + alphaB;
    if (!(s > 0.0)) { return 0.0; }
    float ramp = clamp((sqrt(0.5 * s) - ANISO_FIS_BLEND_R0) / ANISO_FIS_BLEND_R_WIDTH, 0.0, 1.0);
    float eta = abs((alphaT - alphaB) / s);
    if (!(eta > 0.0)) { return ramp; }
    return max(pow(clamp(eta / ANISO_FIS_BLEND_ETA, 0.0, 1.0), ANISO_FIS_BLEND_POWER), ramp);
}

vec3 anisoFisSpecular(samplerCube env, float log2TexelSolidAngle, float maxLod, vec3 n, vec3 t, vec3 b,
                      vec3 v, float alphaT, float alphaB, vec3 f0, vec2 rotation, vec3 isoSpecular) {
    float wb = anisoFisWeight(alphaT, alphaB);
    if (wb <= 0.0) { return isoSpecular; }
    float at = max(alphaT, ANISO_FIS_ALPHA_MIN);
    float ab = max(alphaB, ANISO_FIS_ALPHA_MIN);
    vec3 vl = normalize(vec3(dot(v, t), dot(v, b), dot(v, n)));
    if (vl.z <= 0.0) { return isoSpecular - isoSpecular * wb; }
    float lv = anisoFisLambda(vl, at, ab);
    float g1 = 1.0 / (1.0 + lv);
    vec3 e0 = vec3(0.0);
    vec3 e1 = vec3(0.0);
    for (uint i = 0u; i < ANISO_FIS_TAPS; i++) {
        vec3 m = anisoFisSampleVndf(vl, anisoFisHammersley(i, rotation), at, ab);
        vec3 l = 2.0 * dot(vl, m) * m - vl;
        if (l.z <= 0.0) { continue; }
        float pl = g1 * anisoFisD(m, at, ab) / (4.0 * vl.z);
        float lod = maxLod;
        if (pl > 0.0) {
            lod = clamp(0.5 * (-log2(float(ANISO_FIS_TAPS) * pl) - log2TexelSolidAngle) + ANISO_FIS_LOD_BIAS, 0.0, maxLod);
        }
        vec3 c = textureLod(env, t * l.x + b * l.y + n * l.z, lod).rgb;
        float w = (1.0 + lv) / (1.0 + lv + anisoFisLambda(l, at, ab));
        float chi = pow(1.0 - clamp(dot(vl, m), 0.0, 1.0), ANISO_FIS_SCHLICK_POWER);
        e0 += w * c;
        e1 += (w * chi) * c;
    }
    e0 /= float(ANISO_FIS_TAPS);
    e1 /= float(ANISO_FIS_TAPS);
    vec3 fis = f0 * e0 + (vec3(1.0) - f0) * e1;
    return isoSpecular + (fis - isoSpecular) * wb;
}
"#;

const HLSL: &str = r#"
static const uint ANISO_FIS_TAPS = {TAPS};
static const float ANISO_FIS_LOD_BIAS = {BIAS};
static const float ANISO_FIS_SCHLICK_POWER = {POW};
static const float ANISO_FIS_ALPHA_MIN = {AMIN};
static const float ANISO_FIS_PI = {PI};
static const float ANISO_FIS_INV_2_24 = {INV24};
static const float ANISO_FIS_BLEND_ETA = {BETA};
static const float ANISO_FIS_BLEND_POWER = {BPOW};
static const float ANISO_FIS_BLEND_R0 = {BR0};
static const float ANISO_FIS_BLEND_R_WIDTH = {BRW};

float anisoFisLambda(float3 w, float ax, float ay) {
    float a = (ax * ax * w.x * w.x + ay * ay * w.y * w.y) / (w.z * w.z);
    return a / (2.0 * (1.0 + sqrt(1.0 + a)));
}

float anisoFisD(float3 m, float ax, float ay) {
    if (m.z <= 0.0) { return 0.0; }
    float3 s = float3(m.x / ax, m.y / ay, m.z);
    float t = dot(s, s);
    return 1.0 / (ANISO_FIS_PI * ax * ay * t * t);
}

float3 anisoFisSampleVndf(float3 v, float2 u, float ax, float ay) {
    float3 vh = normalize(float3(ax * v.x, ay * v.y, v.z));
    float lensq = vh.x * vh.x + vh.y * vh.y;
    float3 t1 = float3(1.0, 0.0, 0.0);
    if (lensq > 0.0) { t1 = float3(-vh.y, vh.x, 0.0) / sqrt(lensq); }
    float3 t2 = cross(vh, t1);
    float r = sqrt(saturate(u.x));
    float phi = 2.0 * ANISO_FIS_PI * u.y;
    float p1 = r * cos(phi);
    float s = 0.5 * (1.0 + vh.z);
    float p2 = (1.0 - s) * sqrt(max(1.0 - p1 * p1, 0.0)) + s * r * sin(phi);
    float pz = sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0));
    float3 nh = p1 * t1 + p2 * t2 + pz * vh;
    float3 ne = float3(ax * nh.x, ay * nh.y, max(nh.z, 0.0));
    float l = length(ne);
    if (l > 0.0) { return ne / l; }
    return float3(0.0, 0.0, 1.0);
}

float2 anisoFisHammersley(uint i, float2 rotation) {
    float2 h = float2(float(i) / float(ANISO_FIS_TAPS), float(reversebits(i) >> 8u) * ANISO_FIS_INV_2_24);
    return frac(h + rotation);
}

float anisoFisWeight(float alphaT, float alphaB) {
    float s = alphaT + alphaB;
    if (!(s > 0.0)) { return 0.0; }
    float ramp = saturate((sqrt(0.5 * s) - ANISO_FIS_BLEND_R0) / ANISO_FIS_BLEND_R_WIDTH);
    float eta = abs((alphaT - alphaB) / s);
    if (!(eta > 0.0)) { return ramp; }
    return max(pow(saturate(eta / ANISO_FIS_BLEND_ETA), ANISO_FIS_BLEND_POWER), ramp);
}

float3 anisoFisSpecular(TextureCube env, SamplerState samp, float log2TexelSolidAngle, float maxLod,
                        float3 n, float3 t, float3 b, float3 v, float alphaT, float alphaB, float3 f0,
                        float2 rotation, float3 isoSpecular) {
    float wb = anisoFisWeight(alphaT, alphaB);
    if (wb <= 0.0) { return isoSpecular; }
    float at = max(alphaT, ANISO_FIS_ALPHA_MIN);
    float ab = max(alphaB, ANISO_FIS_ALPHA_MIN);
    float3 vl = normalize(float3(dot(v, t), dot(v, b), dot(v, n)));
    if (vl.z <= 0.0) { return isoSpecular - isoSpecular * wb; }
    float lv = anisoFisLambda(vl, at, ab);
    float g1 = 1.0 / (1.0 + lv);
    float3 e0 = float3(0.0, 0.0, 0.0);
    float3 e1 = float3(0.0, 0.0, 0.0);
    for (uint i = 0u; i < ANISO_FIS_TAPS; i++) {
        float3 m = anisoFisSampleVndf(vl, anisoFisHammersley(i, rotation), at, ab);
        float3 l = 2.0 * dot(vl, m) * m - vl;
        if (l.z <= 0.0) { continue; }
        float pl = g1 * anisoFisD(m, at, ab) / (4.0 * vl.z);
        float lod = maxLod;
        if (pl > 0.0) {
            lod = clamp(0.5 * (-log2(float(ANISO_FIS_TAPS) * pl) - log2TexelSolidAngle) + ANISO_FIS_LOD_BIAS, 0.0, maxLod);
        }
        float3 c = env.SampleLevel(samp, t * l.x + b * l.y + n * l.z, lod).rgb;
        float w = (1.0 + lv) / (1.0 + lv + anisoFisLambda(l, at, ab));
        float chi = pow(1.0 - saturate(dot(vl, m)), ANISO_FIS_SCHLICK_POWER);
        e0 += w * c;
        e1 += (w * chi) * c;
    }
    e0 /= float(ANISO_FIS_TAPS);
    e1 /= float(ANISO_FIS_TAPS);
    float3 fis = f0 * e0 + (1.0 - f0) * e1;
    return isoSpecular + (fis - isoSpecular) * wb;
}
"#;

const WGSL: &str = r#"
const ANISO_FIS_TAPS: u32 = {TAPS};
const ANISO_FIS_LOD_BIAS: f32 = {BIAS};
const ANISO_FIS_SCHLICK_POWER: f32 = {POW};
const ANISO_FIS_ALPHA_MIN: f32 = {AMIN};
const ANISO_FIS_PI: f32 = {PI};
const ANISO_FIS_INV_2_24: f32 = {INV24};
const ANISO_FIS_BLEND_ETA: f32 = {BETA};
const ANISO_FIS_BLEND_POWER: f32 = {BPOW};
const ANISO_FIS_BLEND_R0: f32 = {BR0};
const ANISO_FIS_BLEND_R_WIDTH: f32 = {BRW};

fn aniso_fis_lambda(w: vec3<f32>, ax: f32, ay: f32) -> f32 {
    let a = (ax * ax * w.x * w.x + ay * ay * w.y * w.y) / (w.z * w.z);
    return a / (2.0 * (1.0 + sqrt(1.0 + a)));
}

fn aniso_fis_d(m: vec3<f32>, ax: f32, ay: f32) -> f32 {
    if (m.z <= 0.0) { return 0.0; }
    let s = vec3<f32>(m.x / ax, m.y / ay, m.z);
    let t = dot(s, s);
    return 1.0 / (ANISO_FIS_PI * ax * ay * t * t);
}

fn aniso_fis_sample_vndf(v: vec3<f32>, u: vec2<f32>, ax: f32, ay: f32) -> vec3<f32> {
    let vh = normalize(vec3<f32>(ax * v.x, ay * v.y, v.z));
    let lensq = vh.x * vh.x + vh.y * vh.y;
    var t1 = vec3<f32>(1.0, 0.0, 0.0);
    if (lensq > 0.0) { t1 = vec3<f32>(-vh.y, vh.x, 0.0) / sqrt(lensq); }
    let t2 = cross(vh, t1);
    let r = sqrt(clamp(u.x, 0.0, 1.0));
    let phi = 2.0 * ANISO_FIS_PI * u.y;
    let p1 = r * cos(phi);
    let s = 0.5 * (1.0 + vh.z);
    let p2 = (1.0 - s) * sqrt(max(1.0 - p1 * p1, 0.0)) + s * r * sin(phi);
    let pz = sqrt(max(1.0 - p1 * p1 - p2 * p2, 0.0));
    let nh = p1 * t1 + p2 * t2 + pz * vh;
    let ne = vec3<f32>(ax * nh.x, ay * nh.y, max(nh.z, 0.0));
    let l = length(ne);
    if (l > 0.0) { return ne / l; }
    return vec3<f32>(0.0, 0.0, 1.0);
}

fn aniso_fis_hammersley(i: u32, rotation: vec2<f32>) -> vec2<f32> {
    let h = vec2<f32>(f32(i) / f32(ANISO_FIS_TAPS), f32(reverseBits(i) >> 8u) * ANISO_FIS_INV_2_24);
    return fract(h + rotation);
}

fn aniso_fis_weight(alpha_t: f32, alpha_b: f32) -> f32 {
    let s = alpha_t + alpha_b;
    if (!(s > 0.0)) { return 0.0; }
    let ramp = clamp((sqrt(0.5 * s) - ANISO_FIS_BLEND_R0) / ANISO_FIS_BLEND_R_WIDTH, 0.0, 1.0);
    let eta = abs((alpha_t - alpha_b) / s);
    if (!(eta > 0.0)) { return ramp; }
    return max(pow(clamp(eta / ANISO_FIS_BLEND_ETA, 0.0, 1.0), ANISO_FIS_BLEND_POWER), ramp);
}

fn aniso_fis_specular(env: texture_cube<f32>, samp: sampler, log2_texel_solid_angle: f32, max_lod: f32,
                      n: vec3<f32>, t: vec3<f32>, b: vec3<f32>, v: vec3<f32>, alpha_t: f32, alpha_b: f32,
                      f0: vec3<f32>, rotation: vec2<f32>, iso_specular: vec3<f32>) -> vec3<f32> {
    let wb = aniso_fis_weight(alpha_t, alpha_b);
    if (wb <= 0.0) { return iso_specular; }
    let at = max(alpha_t, ANISO_FIS_ALPHA_MIN);
    let ab = max(alpha_b, ANISO_FIS_ALPHA_MIN);
    let vl = normalize(vec3<f32>(dot(v, t), dot(v, b), dot(v, n)));
    if (vl.z <= 0.0) { return iso_specular - iso_specular * wb; }
    let lv = aniso_fis_lambda(vl, at, ab);
    let g1 = 1.0 / (1.0 + lv);
    var e0 = vec3<f32>(0.0);
    var e1 = vec3<f32>(0.0);
    for (var i = 0u; i < ANISO_FIS_TAPS; i = i + 1u) {
        let m = aniso_fis_sample_vndf(vl, aniso_fis_hammersley(i, rotation), at, ab);
        let l = 2.0 * dot(vl, m) * m - vl;
        if (l.z <= 0.0) { continue; }
        let pl = g1 * aniso_fis_d(m, at, ab) / (4.0 * vl.z);
        var lod = max_lod;
        if (pl > 0.0) {
            lod = clamp(0.5 * (-log2(f32(ANISO_FIS_TAPS) * pl) - log2_texel_solid_angle) + ANISO_FIS_LOD_BIAS, 0.0, max_lod);
        }
        let c = textureSampleLevel(env, samp, t * l.x + b * l.y + n * l.z, lod).rgb;
        let w = (1.0 + lv) / (1.0 + lv + aniso_fis_lambda(l, at, ab));
        let chi = pow(1.0 - clamp(dot(vl, m), 0.0, 1.0), ANISO_FIS_SCHLICK_POWER);
        e0 = e0 + w * c;
        e1 = e1 + (w * chi) * c;
    }
    e0 = e0 / f32(ANISO_FIS_TAPS);
    e1 = e1 / f32(ANISO_FIS_TAPS);
    let fis = f0 * e0 + (vec3<f32>(1.0) - f0) * e1;
    return iso_specular + (fis - iso_specular) * wb;
}
"#;

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::material::Material;
    use crate::methods::{evaluate, Inputs, Lookup, Method};
    use ibl_brdf::microfacet::Microfacet;
    use ibl_brdf::Ggx;
    use ibl_core::sampling::Pcg32;
    use ibl_core::{CubeMips, Cubemap};
    use ibl_prefilter::tree::TreeBuffers;

    /// The constant `name` of `text`, whatever the language's declaration syntax.
    fn constant(text: &str, name: &str) -> String {
        let line = text
            .lines()
            .find(|l| l.contains(&format!("{name} ")) || l.contains(&format!("{name}:")))
            .unwrap_or_else(|| panic!("{name} missing"));
        let v = line.split('=').nth(1).expect("an initialiser");
        v.trim().trim_end_matches(';').trim().to_string()
    }

    #[test]
    fn snippets_carry_the_emulations_constants_and_steps() {
        for (lang, _) in Lang::ALL {
            let text = emit(lang);
            let taps = constant(&text, "ANISO_FIS_TAPS");
            assert_eq!(
                taps.trim_end_matches('u').parse::<u32>().unwrap(),
                SHIPPED.taps,
                "{lang:?}"
            );
            for (name, want) in [
                ("ANISO_FIS_LOD_BIAS", SHIPPED.lod_bias),
                ("ANISO_FIS_SCHLICK_POWER", SHIPPED.schlick_power),
                ("ANISO_FIS_ALPHA_MIN", SHIPPED.alpha_min),
                ("ANISO_FIS_PI", std::f32::consts::PI),
                ("ANISO_FIS_INV_2_24", INV_2_24),
                ("ANISO_FIS_BLEND_ETA", SHIPPED.blend_eta),
                ("ANISO_FIS_BLEND_POWER", SHIPPED.blend_power),
                ("ANISO_FIS_BLEND_R0", SHIPPED.blend_r0),
                ("ANISO_FIS_BLEND_R_WIDTH", SHIPPED.blend_r_width),
            ] {
                let got: f32 = constant(&text, name).parse().unwrap();
                assert_eq!(got.to_bits(), want.to_bits(), "{lang:?} {name}");
            }
            // Every step defined once, in the emulation's order, and used by the last one.
            let mut at = 0;
            for (g, w) in STEPS {
                let name = if lang == Lang::Wgsl { w } else { g };
                let def = if lang == Lang::Wgsl {
                    format!("fn {name}(")
                } else {
                    format!(" {name}(")
                };
                let pos = text[at..]
                    .find(&def)
                    .unwrap_or_else(|| panic!("{lang:?}: {name} missing or out of order"));
                at += pos + def.len();
                assert!(text.matches(name).count() >= 1);
            }
            for (g, w) in &STEPS[..STEPS.len() - 1] {
                let name = if lang == Lang::Wgsl { w } else { g };
                assert!(
                    text.matches(&format!("{name}(")).count() >= 2,
                    "{name} unused"
                );
            }
            // Balanced, fully substituted.
            assert_eq!(text.matches('{').count(), text.matches('}').count());
            assert_eq!(text.matches('(').count(), text.matches(')').count());
            for hole in [
                "{TAPS}", "{BIAS}", "{POW}", "{AMIN}", "{PI}", "{INV24}", "{BETA}", "{BPOW}",
            ] {
                assert!(!text.contains(hole), "{lang:?} {hole}");
            }
            // No float literal loses precision: each constant prints back exactly (above).
        }
    }

    #[test]
    fn emulation_steps_agree_with_ibl_brdf() {
        // The f32 steps the snippets mirror against ibl-brdf's f64 GGX (Λ, D, VNDF sample)
        // and ibl-core's Hammersley set.
        let mut rng = Pcg32::new(23, 7);
        let mut worst = [0.0f32; 3];
        for _ in 0..4000 {
            let ax = 0.01 + rng.next_f32();
            let ay = 0.01 + rng.next_f32();
            let g = Ggx::new(ax, ay);
            let v = Vec3::new(
                rng.next_f32() * 2.0 - 1.0,
                rng.next_f32() * 2.0 - 1.0,
                0.02 + rng.next_f32(),
            )
            .normalize();
            let u = Vec2::new(rng.next_f32(), rng.next_f32());
            let m = sample_vndf(v, u, ax, ay);
            let m_ref = g.sample_visible(v, u.x, u.y).unwrap();
            worst[0] = worst[0].max((m - m_ref).length());
            let rel = |a: f32, b: f32| (a - b).abs() / b.abs().max(1e-3);
            worst[1] = worst[1].max(rel(lambda(v, ax, ay), g.lambda(v)));
            worst[2] = worst[2].max(rel(d_ggx(m_ref, ax, ay), g.d(m_ref)));
        }
        assert!(
            worst[0] < 2e-4 && worst[1] < 1e-4 && worst[2] < 2e-3,
            "{worst:?}"
        );
        for i in 0..SHIPPED.taps {
            let (a, b) = ibl_core::sampling::hammersley(i, SHIPPED.taps);
            assert_eq!(hammersley(i, Vec2::ZERO), Vec2::new(a, b));
        }
    }

    #[test]
    fn the_evaluators_fis_at_the_shipped_bias_is_the_shipped_emulation() {
        let cube = Cubemap::from_fn(16, |d| [d.x.max(0.0) * 3.0, d.y.abs(), 0.2 + d.z * d.z]);
        let pyr = BorderedMips::new(&CubeMips::build(cube.clone(), 1));
        let lookup = Lookup::Engine {
            chain: BorderedMips::new(&CubeMips::build(cube.clone(), 4)),
            mapping: ibl_target::LodMapping::Linear,
        };
        let dfg = ibl_shexp::dfg::Dfg::standard().clone();
        let inp = Inputs {
            lookup: &lookup,
            dfg: &dfg,
            pyramid: &pyr,
            cube: &cube,
            as_tables: None,
        };
        let n = Vec3::new(0.2, -0.3, 0.9).normalize();
        let t = Vec3::Y.cross(n).normalize();
        let frame = Frame {
            t,
            b: n.cross(t),
            n,
        };
        let v = frame.to_world(Vec3::new(0.4, 0.1, 0.7).normalize());
        // FIS at the shipped taps and lod bias (`fis-16-b0`); `fis-16` is the published +1.
        let method = Method::Fis {
            taps: SHIPPED.taps as usize,
            lod_bias: SHIPPED.lod_bias,
        };
        let mut buf = TreeBuffers::default();
        for (r, eta) in [(0.3, 0.0), (0.6, 0.8), (0.9, -0.5)] {
            let mat = Material::ggx_kc(r, eta);
            let (at, ab) = mat.ggx_alphas().unwrap();
            for seed in [1u64, 99] {
                let got = evaluate(&method, &inp, &frame, v, &mat, seed, &mut buf);
                let rot = crate::methods::fis_rotation(seed);
                let want = shade_fis(&pyr, &frame, v, at, ab, rot);
                assert_eq!(got, want);
                assert!(got.0.iter().all(|c| c.is_finite() && *c > 0.0));
                // The shipped blend: the evaluator's fisb-16 is `shade` over its own iso.
                let iso = evaluate(&Method::Iso, &inp, &frame, v, &mat, seed, &mut buf);
                let blend = Method::parse(&format!("fisb-{}", SHIPPED.taps)).unwrap();
                let got = evaluate(&blend, &inp, &frame, v, &mat, seed, &mut buf);
                assert_eq!(got, shade(&pyr, &frame, v, at, ab, rot, iso));
                let w = fis_weight(at, ab);
                if eta == 0.0 && r <= SHIPPED.blend_r0 {
                    // Exactly the isotropic floor, bit for bit.
                    assert_eq!(w, 0.0);
                    assert_eq!(got, iso);
                } else if w >= 1.0 {
                    for k in 0..3 {
                        assert!((got.0[k] - want.0[k]).abs() <= 1e-6 * want.0[k].abs().max(1.0));
                    }
                }
            }
        }
    }

    #[test]
    fn shade_specular_is_the_blended_shade_and_passes_iso_through_at_eta_0() {
        // The snippet's radiance-level blend against the (E0, E1)-level `shade`: equal up to
        // rounding (linear), and at η = 0 the iso input comes back bit for bit.
        let cube = Cubemap::from_fn(16, |d| [d.x.max(0.0) * 3.0, d.y.abs(), 0.2 + d.z * d.z]);
        let pyr = BorderedMips::new(&CubeMips::build(cube, 1));
        let n = Vec3::new(0.2, -0.3, 0.9).normalize();
        let t = Vec3::Y.cross(n).normalize();
        let frame = Frame {
            t,
            b: n.cross(t),
            n,
        };
        let mut rng = Pcg32::new(5, 23);
        for (r, eta) in [
            (0.2, 0.0),
            (0.02, 0.0),
            (1.0, 0.0),
            (0.35, 0.0),
            (0.6, 0.3),
            (0.9, -1.0),
        ] {
            let (at, ab) = Material::ggx_kc(r, eta).ggx_alphas().unwrap();
            for view in [Vec3::new(0.4, 0.1, 0.7), Vec3::new(0.3, 0.2, -0.5)] {
                let v = frame.to_world(view.normalize());
                let iso_e = (
                    [rng.next_f32(), 2.0 * rng.next_f32(), 0.1],
                    [0.3 * rng.next_f32(), 0.05, 0.02],
                );
                let rot = Vec2::new(rng.next_f32(), rng.next_f32());
                for f0 in [[1.0f32; 3], [0.04; 3]] {
                    let iso = specular(&iso_e, f0);
                    let got = shade_specular(&pyr, &frame, v, (at, ab), f0, rot, iso);
                    if fis_weight(at, ab) == 0.0 {
                        assert!(eta == 0.0 && r <= SHIPPED.blend_r0);
                        assert_eq!(got.map(f32::to_bits), iso.map(f32::to_bits), "{r}");
                        continue;
                    }
                    let want = specular(&shade(&pyr, &frame, v, at, ab, rot, iso_e), f0);
                    for k in 0..3 {
                        assert!(
                            (got[k] - want[k]).abs() <= 1e-6 * want[k].abs().max(1.0),
                            "{r} {eta} {got:?} {want:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn blend_weight_is_the_kulla_conty_eta_rule_and_the_roughness_ramp() {
        assert_eq!(fis_weight(0.0, 0.0), 0.0);
        assert_eq!(fis_weight(f32::NAN, 0.1), 0.0);
        let s = SHIPPED;
        for r in [0.05f32, 0.2, 0.3, 0.4, 0.7, 1.0] {
            let ramp = ((r - s.blend_r0) / s.blend_r_width).clamp(0.0, 1.0) as f64;
            let mut last = -1.0;
            for i in 0..=40 {
                let eta = -1.0 + i as f32 / 20.0;
                let (at, ab) = Material::ggx_kc(r, eta).ggx_alphas().unwrap();
                let w = fis_weight(at, ab);
                // Symmetric in η (t ↔ b), within [0, 1], 1 from |η| ≥ η₁, monotone in |η|.
                let (at2, ab2) = Material::ggx_kc(r, -eta).ggx_alphas().unwrap();
                assert!((w - fis_weight(at2, ab2)).abs() < 1e-6, "{r} {eta}");
                assert!((0.0..=1.0).contains(&w));
                // The lobe's own η: at r = 0.05 and |η| near 1 the α floor makes it smaller
                // than the nominal one (α_t = 10⁻³, α_b = 0.005: η 0.67).
                let lobe = ((at as f64 - ab as f64) / (at as f64 + ab as f64)).abs();
                if lobe >= SHIPPED.blend_eta as f64 + 1e-4 || r >= s.blend_r0 + s.blend_r_width {
                    assert_eq!(w, 1.0, "{r} {eta}");
                }
                if eta == 0.0 && r <= s.blend_r0 {
                    assert_eq!(w, 0.0, "{r}: exactly the floor at η = 0 below r₀");
                }
                let want = if lobe > 0.0 {
                    (lobe / SHIPPED.blend_eta as f64)
                        .min(1.0)
                        .powf(SHIPPED.blend_power as f64)
                } else {
                    0.0
                }
                .max(ramp);
                assert!((w as f64 - want).abs() < 1e-4, "{r} {eta} {w} {want}");
                if eta >= 0.0 {
                    assert!(w >= last - 1e-6);
                    last = w;
                }
            }
        }
    }

    #[test]
    fn furnace_and_edges() {
        // Constant environment: E0 = the mean of G2/G1 over VNDF taps, which tends to the
        // directional albedo; at 16 taps with r = 0.5 within a few percent of the truth's.
        let pyr = BorderedMips::new(&CubeMips::build(Cubemap::constant(8, [1.0; 3]), 1));
        let frame = Frame {
            t: Vec3::X,
            b: Vec3::Y,
            n: Vec3::Z,
        };
        let v = Vec3::new(0.5, 0.2, 0.8).normalize();
        let (at, ab) = Material::ggx_kc(0.5, 0.6).ggx_alphas().unwrap();
        let e = shade_fis(&pyr, &frame, v, at, ab, Vec2::new(0.3, 0.7));
        let albedo = crate::truth::albedo_quadrature(&Ggx::new(at, ab), v, 64);
        assert!((e.0[0] as f64 - albedo).abs() < 0.03, "{e:?} {albedo}");
        assert!(e.1[0] > 0.0 && e.1[0] < e.0[0]);
        // r = 0, η = ±1, grazing and below-horizon views: finite, non-negative.
        for (at, ab) in [(0.0, 0.0), (2.0, 0.0), (0.0, 2.0), (1.0, 1.0)] {
            for v in [
                Vec3::new(1.0, 0.0, 1e-4),
                Vec3::new(0.0, -1.0, 1e-6),
                Vec3::Z,
            ] {
                let e = shade_fis(&pyr, &frame, v.normalize(), at, ab, Vec2::new(0.9, 0.1));
                assert!(
                    e.0.iter().chain(&e.1).all(|c| c.is_finite() && *c >= 0.0),
                    "{at} {ab} {v} {e:?}"
                );
            }
        }
        let below = shade_fis(&pyr, &frame, -Vec3::Z, 0.2, 0.2, Vec2::ZERO);
        assert_eq!(below, ([0.0; 3], [0.0; 3]));
        let s = specular(&e, [0.04; 3]);
        assert!((s[0] - (0.04 * e.0[0] + 0.96 * e.1[0])).abs() < 1e-7);
    }

    /// Runs `tool args file` and returns its output, or None when the tool is not installed
    /// (`scripts/setup-shader-validators.sh` installs both).
    fn run_tool(tool: &str, args: &[&str], file: &std::path::Path) -> Option<std::process::Output> {
        std::process::Command::new(tool)
            .args(args)
            .arg(file)
            .output()
            .ok()
    }

    pub(crate) fn assert_compiles(tool: &str, args: &[&str], file: &std::path::Path) {
        match run_tool(tool, args, file) {
            // CI installs both (.ci/run runs scripts/setup-shader-validators.sh), so there a
            // missing tool is a failure, never a silent pass.
            None if std::env::var_os("CI").is_some() => panic!(
                "{tool} not installed (scripts/setup-shader-validators.sh): {} not validated",
                file.display()
            ),
            None => eprintln!("{tool} not installed: {} not validated", file.display()),
            Some(out) => assert!(
                out.status.success(),
                "{tool} {}: {}{}",
                file.display(),
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            ),
        }
    }

    #[test]
    fn snippets_compile_in_real_front_ends() {
        // The three snippets inside a fragment shader that calls the last step: GLSL and HLSL
        // through Khronos glslang (HLSL to SPIR-V), WGSL through naga (wgpu's front end).
        let dir = std::env::temp_dir().join(format!("ibl-aniso-ship-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let glsl_file = dir.join("aniso_fis.frag");
        let glsl_main = "layout(binding = 0) uniform samplerCube env;\n\
             layout(location = 0) in vec3 n;\nlayout(location = 0) out vec4 color;\n\
             void main() {\n vec3 t = normalize(cross(vec3(0.0, 1.0, 0.0), n));\n\
             color = vec4(anisoFisSpecular(env, -5.0, 6.0, n, t, cross(n, t), n, 0.3, 0.1, vec3(0.04), vec2(0.5), vec3(0.1)), 1.0);\n}\n";
        std::fs::write(&glsl_file, format!("#version 450\n{}{glsl_main}", glsl())).unwrap();
        // The same text verbatim under GLSL ES 3.00 (WebGL2) and GLSL 3.30, which have no
        // bitfieldReverse: the snippet must carry its own bit reversal.
        assert!(!glsl().contains("bitfieldReverse("));
        let es_file = dir.join("aniso_fis_es300.frag");
        let es_main = "uniform samplerCube env;\nin vec3 n;\nout vec4 color;\n\
             void main() {\n vec3 t = normalize(cross(vec3(0.0, 1.0, 0.0), n));\n\
             color = vec4(anisoFisSpecular(env, -5.0, 6.0, n, t, cross(n, t), n, 0.3, 0.1, vec3(0.04), vec2(0.5), vec3(0.1)), 1.0);\n}\n";
        std::fs::write(
            &es_file,
            format!(
                "#version 300 es\nprecision highp float;\nprecision highp int;\n{}{es_main}",
                glsl()
            ),
        )
        .unwrap();
        let gl330_file = dir.join("aniso_fis_330.frag");
        std::fs::write(&gl330_file, format!("#version 330\n{}{es_main}", glsl())).unwrap();
        let hlsl_file = dir.join("aniso_fis.hlsl");
        let hlsl_main = "TextureCube env : register(t0);\nSamplerState samp : register(s0);\n\
             float4 main(float3 n : TEXCOORD0) : SV_Target {\n\
             float3 t = normalize(cross(float3(0.0, 1.0, 0.0), n));\n\
             return float4(anisoFisSpecular(env, samp, -5.0, 6.0, n, t, cross(n, t), n, 0.3, 0.1, float3(0.04, 0.04, 0.04), float2(0.5, 0.5), float3(0.1, 0.1, 0.1)), 1.0);\n}\n";
        std::fs::write(&hlsl_file, hlsl() + hlsl_main).unwrap();
        let wgsl_file = dir.join("aniso_fis.wgsl");
        let wgsl_main = "@group(0) @binding(0) var env: texture_cube<f32>;\n\
             @group(0) @binding(1) var samp: sampler;\n\
             @fragment fn main(@location(0) n: vec3<f32>) -> @location(0) vec4<f32> {\n\
             let t = normalize(cross(vec3<f32>(0.0, 1.0, 0.0), n));\n\
             let c = aniso_fis_specular(env, samp, -5.0, 6.0, n, t, cross(n, t), n, 0.3, 0.1, vec3<f32>(0.04), vec2<f32>(0.5), vec3<f32>(0.1));\n\
             return vec4<f32>(c, 1.0);\n}\n";
        std::fs::write(&wgsl_file, wgsl() + wgsl_main).unwrap();
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
