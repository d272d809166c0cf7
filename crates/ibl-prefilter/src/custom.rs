//! The `custom` target's lookup (`prefilter --target custom`, docs/CUSTOM_LOOKUP.md), defined
//! once: [`CustomLookup`] holds its few constants, computes the lod exactly as the shaders do
//! (`ibl_target::lod::custom_lod`, the same f32 expression), reads a chain on the CPU as the
//! emitted shader does ([`CustomLookup::read`]), computes what the chain's alpha channel holds
//! ([`correction`], [`midpoint_alpha`]) and its power factors ([`CustomLookup::fit_power`]),
//! and emits the GLSL / HLSL / WGSL function and the KTX2 key/value data
//! from those same constants.
//!
//! lod = clamp(s·log2(1 + r²/α₀), 0, N − 1), s = (N − 1)/log2(1 + 1/α₀): level l holds
//! α_l = α₀((1 + 1/α₀)^(l/(N−1)) − 1), geometric in α above α₀ (a lobe's width, hence the texels
//! it needs, goes as α while the level sizes halve) and linear in α below it down to the mirror.
//!
//! Two taps, levels l = ⌊lod⌋ and l + 1, t = lod − l, and a polynomial in lod through exact
//! points. Each level's alpha channel holds the luminance of the kernel at the middle of the
//! interval above it, less the level's own: M_l = Y(mid_l) − Y(L_l) at level l's texels (on the
//! mirror level 0, less the two levels' blend; 0 on the last level). Both taps bring theirs.
//! Above the mirror's interval the read's luminance is exp2 of Lagrange's cubic in the log of
//! luminance through t = 0, ½, 1 and 3/2 (level l, its midpoint, level l + 1 and the next
//! interval's midpoint; the quadratic through the first three on the last interval), times the
//! chain's power factor ([`CustomLookup::fit_power`]); on the mirror's interval it is the
//! quadratic in luminance, linear in its nodes ([`correction`] keeps its power). The colour is
//! the linear blend's, scaled. A linear blend alone leaves the curvature of radiance in lod (a
//! small light's peak grows as r⁻⁴): 2–7% mean error between levels on the fixtures; a
//! polynomial in luminance 0.1–1.8%; in the log, an exponential in lod is a line: 0.1–0.8%
//! (docs/notes/custom-quad.md, custom-log.md).

use crate::fit::read_at_texels;
use crate::spatial;
use glam::Vec3;
use ibl_core::bordered::BorderedMips;
use ibl_core::cube::{
    solid_angle_table, texel_direction, texel_solid_angle, CubeMips, Cubemap, Face,
};
use ibl_core::{luminance, Rgb};
use ibl_target::lod::{custom_lod, custom_scale};
use serde::Serialize;

/// The lookup formula as the sidecar and the KTX2 metadata state it.
pub const FORMULA: &str = "lod = clamp(scale * log2(1 + r*r*inv_alpha0), 0, max_lod); l = max(min(floor(lod), max_lod - 1), 0); t = lod - l; a = textureLod(chain, R, l); b = textureLod(chain, R, l + 1); ya = dot(a.rgb, luma); yb = dot(b.rgb, luma); first interval (l == 0): lum = Lagrange quadratic at t through (0, ya), (1/2, (ya + yb)/2 + a.a), (1, yb); above: with e = floor*(ya + yb) + 1e-30 and g(y) = log2(max(y, 0) + e), lum = (exp2(P) - e) * (1 + t*(t - 1/2)*(t - 1)*(power[l].x + power[l].y*(t - 1/2))), P Lagrange's polynomial at t through (0, g(ya)), (1/2, g(ya + a.a)), (1, g(yb)) and, unless l + 1 == max_lod, (3/2, g(yb + b.a)); c = a.rgb + (b.rgb - a.rgb) * t; y = dot(c, luma); radiance = y > 0 ? c * max(lum / y, 0) : c";

/// Names of the emitted shader files, written beside the chain.
pub const SHADER_FILES: [&str; 3] = ["lookup.glsl", "lookup.hlsl", "lookup.wgsl"];

/// Luminance weights of the correction (Rec. 709, `ibl_core::luminance`'s).
pub const LUMA: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// The log's floor relative to the two taps' luminance: g(y) = log2(y + e), e = FLOOR·(y_a +
/// y_b) + [`TINY`]. Far below every value that matters (0.1% of the taps' sum), it keeps the
/// log finite on black texels and the interpolation linear, not logarithmic, among values
/// below it; relative to the pixel's own taps, so the lookup does not depend on the
/// environment's scale.
pub const FLOOR: f32 = 1e-3;
/// The log's absolute floor (black pixels: every node e, the read 0).
pub const TINY: f32 = 1e-30;

/// The custom lookup's constants for one chain (`prefilter.json` `"custom_lookup"`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CustomLookup {
    /// The formula (see [`FORMULA`]).
    pub formula: &'static str,
    /// α₀, the knee between linear and geometric spacing in α.
    pub alpha0: f32,
    /// s = (N − 1)/log2(1 + 1/α₀).
    pub scale: f32,
    /// 1/α₀ as the shader multiplies by it.
    pub inv_alpha0: f32,
    /// N − 1, the last level (the lod is clamped to it).
    pub max_lod: f32,
    /// Levels N of the chain.
    pub levels: usize,
    /// Face size of level 0.
    pub size: usize,
    /// Texture taps per lookup (two bilinear taps, levels l and l + 1).
    pub taps: usize,
    /// Luminance weights of the correction.
    pub luma: [f32; 3],
    /// Per interval l (0 ..= N − 2), the constants (c₀, c₁) of the power factor
    /// 1 + t(t − ½)(t − 1)·(c₀ + c₁(t − ½)) ([`CustomLookup::fit_power`]): 0 on the first interval
    /// (its linear read keeps the power) and until fitted. Per chain (they depend on the
    /// environment, as the alpha does).
    pub power: Vec<[f32; 2]>,
}

/// A custom chain as its shader samples it: the RGB levels and their alpha channel (the
/// midpoints, [`correction`]), each bordered for seamless reads.
pub struct CustomChain {
    /// The levels' RGB.
    pub rgb: BorderedMips,
    /// The alpha channel, in each of the three channels.
    pub alpha: BorderedMips,
}

impl CustomChain {
    /// Borders `rgb` and `alpha` (a chain of the same shape, A in channel 0).
    pub fn new(rgb: &CubeMips, alpha: &CubeMips) -> Self {
        CustomChain {
            rgb: BorderedMips::new(rgb),
            alpha: BorderedMips::new(alpha),
        }
    }
}

/// The shaders' shared expressions (GLSL, HLSL and WGSL write them alike), each the emulation's
/// ([`CustomLookup::read_taps`]) operation for operation: the first interval's quadratic in
/// luminance, the log read's quadratic and cubic, the power factor, and their comments.
mod expr {
    pub(super) const FIRST: &str = "(1.0 - t) * (1.0 - 2.0 * t) * ya + 4.0 * t * (1.0 - t) * (0.5 * (ya + yb) + a.a) + t * (2.0 * t - 1.0) * yb";
    pub(super) const LOG_QUADRATIC: &str =
        "(1.0 - t) * (1.0 - 2.0 * t) * ga + 4.0 * t * (1.0 - t) * gm + t * (2.0 * t - 1.0) * gb";
    pub(super) const LOG_CUBIC: &str = "-(4.0 / 3.0) * p * q * s * ga + 4.0 * t * q * s * gm - 4.0 * t * p * s * gb + (4.0 / 3.0) * t * p * q * log2(max(yb + b.a, 0.0) + e)";
    pub(super) const FACTOR: &str =
        "max(exp2(g) - e, 0.0) * (1.0 + (t * p * q) * (pw.x + pw.y * p))";
    pub(super) const FIRST_COMMENT: &str = "        // Above the mirror: the quadratic in luminance through level 0, the midpoint (the\n        // alpha holds it less the two levels' blend) and level 1.";
    pub(super) const LOG_COMMENT: &str = "        // Lagrange in t of the log of luminance through the levels (t = 0, 1) and the kernel\n        // at the midpoints (t = 1/2, and 3/2 but on the last interval; each alpha holds its\n        // midpoint less its level), then the chain's power factor.";
}

impl CustomLookup {
    /// The lookup of a chain of `levels` levels of base `size` with knee `alpha0`.
    pub fn new(alpha0: f32, levels: usize, size: usize) -> Self {
        CustomLookup {
            formula: FORMULA,
            alpha0,
            scale: custom_scale(alpha0, levels),
            inv_alpha0: 1.0 / alpha0,
            max_lod: levels.saturating_sub(1) as f32,
            levels,
            size,
            taps: 2,
            luma: LUMA,
            power: vec![[0.0; 2]; levels.saturating_sub(1).max(1)],
        }
    }

    /// The lod the shader computes for perceptual roughness `r`.
    pub fn lod(&self, r: f32) -> f32 {
        custom_lod(r, self.scale, self.inv_alpha0, self.max_lod)
    }

    /// The level l = ⌊lod⌋ (at most N − 2) and t = lod − l the shader reads at roughness `r`.
    pub fn interval(&self, r: f32) -> (usize, f32) {
        let lod = self.lod(r.clamp(0.0, 1.0));
        let l = lod.floor().min(self.max_lod - 1.0).max(0.0);
        (l as usize, lod - l)
    }

    /// The roughness at the middle of interval `l` (lod l + ½), where the alpha channel makes
    /// the read exact: α = α₀((1 + 1/α₀)^((l + ½)/(N−1)) − 1), in f64.
    pub fn mid_roughness(&self, l: usize) -> f32 {
        let last = (self.levels.max(2) - 1) as f64;
        let a0 = self.alpha0 as f64;
        let a = a0 * ((1.0 + 1.0 / a0).powf((l as f64 + 0.5) / last) - 1.0);
        a.sqrt() as f32
    }

    /// The CPU emulation of the emitted shader, operation for operation in f32: two seamless
    /// bilinear taps (levels l and l + 1, RGBA), the midpoints from their alpha, Lagrange's
    /// polynomial in t through the levels and the midpoints ([`Self::read_taps`]), and the linear
    /// blend c scaled to its luminance, c·max(lum/Y(c), 0).
    pub fn read(&self, chain: &CustomChain, d: Vec3, r: f32) -> Rgb {
        self.read_taps(r, |l| {
            let [x, y, z] = chain.rgb.bilinear(d, l);
            [x, y, z, chain.alpha.bilinear(d, l)[0]]
        })
    }

    /// [`Self::read`] from any sampler: `tap(level)` is the RGBA a bilinear tap of that level
    /// returns (levels past the last clamp to it, as `textureLod` does).
    pub fn read_taps(&self, r: f32, tap: impl Fn(usize) -> [f32; 4]) -> Rgb {
        let (l, t) = self.interval(r);
        let [a0, a1, a2, aa] = tap(l);
        let [b0, b1, b2, ba] = tap(l + 1);
        let dot = |x: f32, y: f32, z: f32| self.luma[0] * x + self.luma[1] * y + self.luma[2] * z;
        let (ya, yb) = (dot(a0, a1, a2), dot(b0, b1, b2));
        let big_y = self.luminance(l, t, [ya, aa], [yb, ba]);
        let c = [a0 + (b0 - a0) * t, a1 + (b1 - a1) * t, a2 + (b2 - a2) * t];
        let y = dot(c[0], c[1], c[2]);
        if y > 0.0 {
            let k = (big_y / y).max(0.0);
            c.map(|v| v * k)
        } else {
            c
        }
    }

    /// The luminance the read returns in interval `l` at `t` from the taps' luminance and alpha,
    /// `a` = [Y(level l), its alpha] and `b` the same of level l + 1 (the shader's `lum`).
    pub fn luminance(&self, l: usize, t: f32, [ya, aa]: [f32; 2], [yb, ba]: [f32; 2]) -> f32 {
        if l == 0 {
            let (q0, qm, q1) = Self::quadratic_weights(t);
            return q0 * ya + qm * (0.5 * (ya + yb) + aa) + q1 * yb;
        }
        let e = FLOOR * (ya.max(0.0) + yb.max(0.0)) + TINY;
        let g = |y: f32| (y.max(0.0) + e).log2();
        let (ga, gm, gb) = (g(ya), g(ya + aa), g(yb));
        let p = if Self::reads_quadratic(l as f32, self.max_lod) {
            let (q0, qm, q1) = Self::quadratic_weights(t);
            q0 * ga + qm * gm + q1 * gb
        } else {
            let (w0, wm, w1, w3) = Self::cubic_weights(t);
            w0 * ga + wm * gm + w1 * gb + w3 * g(yb + ba)
        };
        let c = self.power.get(l).copied().unwrap_or([0.0; 2]);
        (p.exp2() - e).max(0.0) * (1.0 + Self::power_shape(t) * (c[0] + c[1] * (t - 0.5)))
    }

    /// t(t − ½)(t − 1): the power factor's shape, zero at the three nodes of an interval (where
    /// the read is the kernel's), of the sign pattern the log read's power error has between
    /// them on the default chain (docs/notes/custom-log.md); times (t − ½), its symmetric part,
    /// which small levels add. The shader's expression.
    pub fn power_shape(t: f32) -> f32 {
        t * (t - 0.5) * (t - 1.0)
    }

    /// Whether interval `l` is read by a quadratic (through its own midpoint only) rather
    /// than the cubic (the next interval's midpoint too): the first interval, whose lower level
    /// is the mirror (read linearly in luminance: next to a one-texel sun its texels are dark
    /// while the midpoint is bright, and a polynomial in the log through such a step overshoots
    /// by 10²–10³% of the sun's power), and the last, which has no interval above it. The
    /// shader's expression.
    pub fn reads_quadratic(l: f32, max_lod: f32) -> bool {
        l < 0.5 || l + 1.0 >= max_lod
    }

    /// Lagrange's weights at t for the nodes 0, ½, 1 (the shader's expressions, in f32).
    pub fn quadratic_weights(t: f32) -> (f32, f32, f32) {
        (
            (1.0 - t) * (1.0 - 2.0 * t),
            4.0 * t * (1.0 - t),
            t * (2.0 * t - 1.0),
        )
    }

    /// Lagrange's weights at t for the nodes 0, ½, 1, 3/2 (the shader's expressions, in f32).
    pub fn cubic_weights(t: f32) -> (f32, f32, f32, f32) {
        let (p, q, s) = (t - 0.5, t - 1.0, t - 1.5);
        (
            -(4.0 / 3.0) * p * q * s,
            4.0 * t * q * s,
            -4.0 * t * p * s,
            (4.0 / 3.0) * t * p * q,
        )
    }

    /// Fits [`Self::power`] to `chain`: per interval above the first, the c_l that keeps the
    /// read's power (∫ luminance dω) equal to the kernel's at t = k/8, k ≠ 0, 4, 8, by least
    /// squares on the relative error against the linear blend of the two levels' read powers
    /// (on the same grid, so its quadrature error cancels; the kernel's power is constant in
    /// lod and a linear blend of the levels keeps it). The read in the log is exact at the
    /// nodes but not linear in them, so its power drifts between them (±0.3–0.6% of a one-texel
    /// 10⁵ sun's, docs/notes/custom-log.md); this puts it back within 0.1%. Integrated at the
    /// centres of a grid of 8× the finer level's size a face (at least 64², at most 256²: the
    /// sharpened levels' reads need it, 2× left 0.28% of a sun on a 64² chain, 8× 0.20%),
    /// summed in order: the same bits for any thread count.
    pub fn fit_power(&mut self, chain: &CustomChain) {
        use rayon::prelude::*;
        self.power.iter_mut().for_each(|c| *c = [0.0; 2]);
        let sizes = chain.rgb.sizes();
        for l in 1..self.power.len().min(sizes.len().saturating_sub(1)) {
            let m = (8 * sizes[l]).clamp(64, 256);
            let ts: Vec<f32> = (0..=8).map(|k| k as f32 / 8.0).collect();
            let rows: Vec<Vec<f64>> = (0..6 * m)
                .into_par_iter()
                .map(|row| {
                    let (face, j) = (Face::from_index(row / m), row % m);
                    let mut acc = vec![0.0f64; ts.len()];
                    for i in 0..m {
                        let d = texel_direction(face, i, j, m);
                        let w = texel_solid_angle(i, j, m);
                        // The two taps once; the luminance of the read at every t from them
                        // (luminance(c·lum/Y(c)) = lum; the nodes t = 0, 1 are the levels).
                        let [ya, yb] = [l, l + 1].map(|k| {
                            [
                                luminance(chain.rgb.bilinear(d, k)),
                                chain.alpha.bilinear(d, k)[0],
                            ]
                        });
                        for (a, &t) in acc.iter_mut().zip(&ts) {
                            let y = match t {
                                0.0 => ya[0],
                                1.0 => yb[0],
                                _ => self.luminance(l, t, ya, yb),
                            };
                            *a += w * y as f64;
                        }
                    }
                    acc
                })
                .collect();
            let mut pw = vec![0.0f64; ts.len()];
            for row in rows {
                for (p, v) in pw.iter_mut().zip(row) {
                    *p += v;
                }
            }
            // Least squares of e(t) + φ(t)(c₀ + c₁(t − ½)) = 0 over the six t: 2×2 normal equations.
            let (mut a, mut b) = ([[0.0f64; 2]; 2], [0.0f64; 2]);
            for (k, &t) in ts.iter().enumerate() {
                let lin = (1.0 - t as f64) * pw[0] + t as f64 * pw[8];
                if k % 4 == 0 || lin <= 0.0 {
                    continue;
                }
                let e = pw[k] / lin - 1.0;
                let phi = Self::power_shape(t) as f64;
                let x = [phi, phi * (t as f64 - 0.5)];
                for r in 0..2 {
                    for c in 0..2 {
                        a[r][c] += x[r] * x[c];
                    }
                    b[r] -= x[r] * e;
                }
            }
            let det = a[0][0] * a[1][1] - a[0][1] * a[1][0];
            let c = [
                (b[0] * a[1][1] - b[1] * a[0][1]) / det,
                (a[0][0] * b[1] - a[1][0] * b[0]) / det,
            ];
            if c.iter().all(|x| x.is_finite()) {
                self.power[l] = c.map(|x| x as f32);
            }
        }
    }

    /// Shortest decimal that parses back to the same f32 (Rust's `{:?}`), always with a point
    /// or an exponent so every shading language reads it as a float.
    fn lit(x: f32) -> String {
        let s = format!("{x:?}");
        if s.contains('.') || s.contains('e') {
            s
        } else {
            format!("{s}.0")
        }
    }

    fn header(&self, comment: &str) -> String {
        format!(
            "{comment} ibl custom lookup (prefilter --target custom; docs/CUSTOM_LOOKUP.md), generated for\n\
             {comment} this chain: {n} levels of {s}x{s}, alpha0 = {a0}.\n\
             {comment} Two taps (levels l and l + 1) and a polynomial in lod (of the log of luminance\n\
             {comment} above the first interval) through the levels and the kernel at the intervals'\n\
             {comment} midpoints, which the alpha channel holds. Sample the RGBA16F chain as stored: all\n\
             {comment} levels, seamless, with a linear filter. IBL_LOOKUP_POWER is this chain's (pass it\n\
             {comment} as a uniform to share the function between probes: KTX2 key ibl.lookup.power).\n",
            n = self.levels,
            s = self.size,
            a0 = Self::lit(self.alpha0),
        )
    }

    fn luma_lit(&self) -> String {
        self.luma.map(Self::lit).join(", ")
    }

    /// The body shared by GLSL and HLSL after the lod (`vec4` / `float4` …, the tap with
    /// `{lod}` for its level): the two taps, the midpoints and Lagrange's polynomial.
    fn c_like_body(v4: &str, v3: &str, v2: &str, tap: &str) -> String {
        let (ta, tb) = (tap.replace("{lod}", "l"), tap.replace("{lod}", "l + 1.0"));
        let (c1, c2, first) = (expr::FIRST_COMMENT, expr::LOG_COMMENT, expr::FIRST);
        let (lq, lc, fac) = (expr::LOG_QUADRATIC, expr::LOG_CUBIC, expr::FACTOR);
        format!(
            "    float l = max(min(floor(lod), IBL_LOOKUP_MAX_LOD - 1.0), 0.0);\n\
             \x20   float t = lod - l;\n\
             \x20   {v4} a = {ta};\n\
             \x20   {v4} b = {tb};\n\
             \x20   float ya = dot(a.rgb, IBL_LOOKUP_LUMA);\n\
             \x20   float yb = dot(b.rgb, IBL_LOOKUP_LUMA);\n\
             \x20   float p = t - 0.5;\n\
             \x20   float q = t - 1.0;\n\
             \x20   float s = t - 1.5;\n\
             \x20   float lum;\n\
             \x20   if (l < 0.5) {{\n\
             {c1}\n\
             \x20       lum = {first};\n\
             \x20   }} else {{\n\
             {c2}\n\
             \x20       float e = IBL_LOOKUP_FLOOR * (max(ya, 0.0) + max(yb, 0.0)) + 1e-30;\n\
             \x20       float ga = log2(max(ya, 0.0) + e);\n\
             \x20       float gm = log2(max(ya + a.a, 0.0) + e);\n\
             \x20       float gb = log2(max(yb, 0.0) + e);\n\
             \x20       float g = l + 1.0 >= IBL_LOOKUP_MAX_LOD\n\
             \x20           ? {lq}\n\
             \x20           : {lc};\n\
             \x20       {v2} pw = IBL_LOOKUP_POWER[int(l)];\n\
             \x20       lum = {fac};\n\
             \x20   }}\n\
             \x20   {v3} c = a.rgb + (b.rgb - a.rgb) * t;\n\
             \x20   float y = dot(c, IBL_LOOKUP_LUMA);\n\
             \x20   return y > 0.0 ? c * max(lum / y, 0.0) : c;\n\
             }}\n"
        )
    }

    /// The power factors as `{v2}(c0, c1), …`.
    fn power_lits(&self, v2: &str) -> String {
        self.power
            .iter()
            .map(|c| format!("{v2}({}, {})", Self::lit(c[0]), Self::lit(c[1])))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The GLSL function `iblCustomSpecular(samplerCube, vec3 R, float roughness)`.
    pub fn glsl(&self) -> String {
        format!(
            "{h}const float IBL_LOOKUP_SCALE = {s};\n\
             const float IBL_LOOKUP_INV_ALPHA0 = {i};\n\
             const float IBL_LOOKUP_MAX_LOD = {m};\n\
             const vec3 IBL_LOOKUP_LUMA = vec3({y});\n\
             const float IBL_LOOKUP_FLOOR = {fl};\n\
             // This chain's power factors per interval (fitted to its environment, as its alpha).\n\
             const vec2 IBL_LOOKUP_POWER[{np}] = vec2[{np}]({pw});\n\n\
             vec3 iblCustomSpecular(samplerCube chain, vec3 R, float roughness) {{\n\
             \x20   float r = clamp(roughness, 0.0, 1.0);\n\
             \x20   float lod = clamp(IBL_LOOKUP_SCALE * log2(1.0 + r * r * IBL_LOOKUP_INV_ALPHA0), 0.0, IBL_LOOKUP_MAX_LOD);\n\
             {body}",
            h = self.header("//"),
            s = Self::lit(self.scale),
            i = Self::lit(self.inv_alpha0),
            m = Self::lit(self.max_lod),
            y = self.luma_lit(),
            fl = Self::lit(FLOOR),
            np = self.power.len(),
            pw = self.power_lits("vec2"),
            body = Self::c_like_body("vec4", "vec3", "vec2", "textureLod(chain, R, {lod})"),
        )
    }

    /// The HLSL function `iblCustomSpecular(TextureCube, SamplerState, float3 R, float roughness)`.
    pub fn hlsl(&self) -> String {
        format!(
            "{h}static const float IBL_LOOKUP_SCALE = {s};\n\
             static const float IBL_LOOKUP_INV_ALPHA0 = {i};\n\
             static const float IBL_LOOKUP_MAX_LOD = {m};\n\
             static const float3 IBL_LOOKUP_LUMA = float3({y});\n\
             static const float IBL_LOOKUP_FLOOR = {fl};\n\
             // This chain's power factors per interval (fitted to its environment, as its alpha).\n\
             static const float2 IBL_LOOKUP_POWER[{np}] = {{ {pw} }};\n\n\
             float3 iblCustomSpecular(TextureCube chain, SamplerState trilinear, float3 R, float roughness) {{\n\
             \x20   float r = clamp(roughness, 0.0, 1.0);\n\
             \x20   float lod = clamp(IBL_LOOKUP_SCALE * log2(1.0 + r * r * IBL_LOOKUP_INV_ALPHA0), 0.0, IBL_LOOKUP_MAX_LOD);\n\
             {body}",
            h = self.header("//"),
            s = Self::lit(self.scale),
            i = Self::lit(self.inv_alpha0),
            m = Self::lit(self.max_lod),
            y = self.luma_lit(),
            fl = Self::lit(FLOOR),
            np = self.power.len(),
            pw = self.power_lits("float2"),
            body = Self::c_like_body("float4", "float3", "float2", "chain.SampleLevel(trilinear, R, {lod})"),
        )
    }

    /// The WGSL function `ibl_custom_specular(texture_cube<f32>, sampler, dir, roughness)`.
    pub fn wgsl(&self) -> String {
        format!(
            "{h}const IBL_LOOKUP_SCALE: f32 = {s};\n\
             const IBL_LOOKUP_INV_ALPHA0: f32 = {i};\n\
             const IBL_LOOKUP_MAX_LOD: f32 = {m};\n\
             const IBL_LOOKUP_LUMA: vec3<f32> = vec3<f32>({y});\n\
             const IBL_LOOKUP_FLOOR: f32 = {fl};\n\
             // This chain's power factors per interval (fitted to its environment, as its alpha).\n\
             const IBL_LOOKUP_POWER = array<vec2<f32>, {np}>({pw});\n\n\
             fn ibl_custom_specular(chain: texture_cube<f32>, trilinear: sampler, dir: vec3<f32>, roughness: f32) -> vec3<f32> {{\n\
             \x20   let r = clamp(roughness, 0.0, 1.0);\n\
             \x20   let lod = clamp(IBL_LOOKUP_SCALE * log2(1.0 + r * r * IBL_LOOKUP_INV_ALPHA0), 0.0, IBL_LOOKUP_MAX_LOD);\n\
             \x20   let l = max(min(floor(lod), IBL_LOOKUP_MAX_LOD - 1.0), 0.0);\n\
             \x20   let t = lod - l;\n\
             \x20   let a = textureSampleLevel(chain, trilinear, dir, l);\n\
             \x20   let b = textureSampleLevel(chain, trilinear, dir, l + 1.0);\n\
             \x20   let ya = dot(a.rgb, IBL_LOOKUP_LUMA);\n\
             \x20   let yb = dot(b.rgb, IBL_LOOKUP_LUMA);\n\
             \x20   let p = t - 0.5;\n\
             \x20   let q = t - 1.0;\n\
             \x20   let s = t - 1.5;\n\
             \x20   var lum: f32;\n\
             \x20   if (l < 0.5) {{\n\
             {c1}\n\
             \x20       lum = {first};\n\
             \x20   }} else {{\n\
             {c2}\n\
             \x20       let e = IBL_LOOKUP_FLOOR * (max(ya, 0.0) + max(yb, 0.0)) + 1e-30;\n\
             \x20       let ga = log2(max(ya, 0.0) + e);\n\
             \x20       let gm = log2(max(ya + a.a, 0.0) + e);\n\
             \x20       let gb = log2(max(yb, 0.0) + e);\n\
             \x20       var g: f32;\n\
             \x20       if (l + 1.0 >= IBL_LOOKUP_MAX_LOD) {{\n\
             \x20           g = {lq};\n\
             \x20       }} else {{\n\
             \x20           g = {lc};\n\
             \x20       }}\n\
             \x20       var power = IBL_LOOKUP_POWER;\n\
             \x20       let pw = power[u32(l)];\n\
             \x20       lum = {fac};\n\
             \x20   }}\n\
             \x20   let c = a.rgb + (b.rgb - a.rgb) * t;\n\
             \x20   let y = dot(c, IBL_LOOKUP_LUMA);\n\
             \x20   if (y > 0.0) {{\n\
             \x20       return c * max(lum / y, 0.0);\n\
             \x20   }}\n\
             \x20   return c;\n\
             }}\n",
            h = self.header("//"),
            s = Self::lit(self.scale),
            i = Self::lit(self.inv_alpha0),
            m = Self::lit(self.max_lod),
            y = self.luma_lit(),
            fl = Self::lit(FLOOR),
            np = self.power.len(),
            pw = self.power_lits("vec2<f32>"),
            c1 = expr::FIRST_COMMENT,
            c2 = expr::LOG_COMMENT,
            first = expr::FIRST,
            lq = expr::LOG_QUADRATIC,
            lc = expr::LOG_CUBIC,
            fac = expr::FACTOR,
        )
    }

    /// The three shader files ([`SHADER_FILES`]) and their text.
    pub fn shaders(&self) -> [(&'static str, String); 3] {
        [
            (SHADER_FILES[0], self.glsl()),
            (SHADER_FILES[1], self.hlsl()),
            (SHADER_FILES[2], self.wgsl()),
        ]
    }

    /// KTX2 key/value data: the formula and its constants as NUL-terminated UTF-8 strings
    /// (floats in the shortest form that parses back to the same f32), and the roughness of
    /// every level.
    pub fn metadata(&self, level_roughness: &[f32]) -> Vec<(String, Vec<u8>)> {
        let rs: Vec<String> = level_roughness.iter().map(|&r| Self::lit(r)).collect();
        [
            ("ibl.lookup", FORMULA.to_string()),
            ("ibl.lookup.scale", Self::lit(self.scale)),
            ("ibl.lookup.inv_alpha0", Self::lit(self.inv_alpha0)),
            ("ibl.lookup.max_lod", Self::lit(self.max_lod)),
            ("ibl.lookup.alpha0", Self::lit(self.alpha0)),
            ("ibl.lookup.luma", self.luma.map(Self::lit).join(",")),
            ("ibl.lookup.floor", Self::lit(FLOOR)),
            (
                "ibl.lookup.power",
                self.power
                    .iter()
                    .flat_map(|c| c.map(Self::lit))
                    .collect::<Vec<_>>()
                    .join(","),
            ),
            ("ibl.level_roughness", rs.join(",")),
        ]
        .into_iter()
        .map(|(k, v)| {
            let mut b = v.into_bytes();
            b.push(0);
            (k.to_string(), b)
        })
        .collect()
    }
}

/// The first interval's alpha (level 0, the mirror): M = Y(mid) − (Y(lo) + Y(hi))/2 per texel
/// of `lo`, `mid` the kernel at [`CustomLookup::mid_roughness`]`(0)` on lo's texels, `hi` level 1
/// read at lo's centres: relative to the blend, the midpoint follows the level above's read
/// between centres. The first interval is read by the quadratic in luminance, linear in its
/// three values, so two constraints keep its power, in this order:
///
/// - **Never negative.** Through a steep fall (a sun's texel: y₀ = 100, Y(mid) = 4, y₁ = 1)
///   Lagrange's quadratic dips below zero and the shader's clamp at zero would add power. With
///   m = (y₀ + y₁)/2 + M, q ≥ 0 on [0, 1] iff m ≥ (√y₀ − √y₁)²/4 (the minimum over t of its
///   value); M is held at that bound, linear in the values, so a bilinear blend of texels that
///   meet it meets it too (up to the level above's read between centres).
/// - **Zero power.** Σ_p W_p M_p = 0 (W the bilinear read's weights, `spatial::read_weights`,
///   on levels of at most `spatial::READ_POWER_MAX_SIZE`; texel solid angles above, where the
///   two differ by < 10⁻⁴), so the read, whose Lagrange weights sum to one at every t, keeps the
///   levels' power at every lod. The imbalance S is taken from each texel in proportion to its
///   slack M − bound, which keeps the first constraint while |S| ≤ Σ W·slack.
///
/// Rounded to half precision, as the chain stores it, and in all three channels (a
/// [`BorderedMips`] reads it as RGB).
pub fn correction(lo: &Cubemap, mid: &Cubemap, hi: &Cubemap) -> Cubemap {
    let n = lo.size;
    assert_eq!(mid.size, n, "the midpoint on level l's texels");
    let y = |t: &[f32]| luminance([t[0], t[1], t[2]]) as f64;
    let hi = read_at_texels(hi, n);
    // Per texel (M, its lower bound).
    let mut mb: Vec<(f64, f64)> = Vec::with_capacity(6 * n * n);
    for (f, (l, m)) in lo.faces.iter().zip(&mid.faces).enumerate() {
        let h = &hi.faces[f].data;
        for (p, (l, m)) in l
            .data
            .chunks_exact(3)
            .zip(m.data.chunks_exact(3))
            .enumerate()
        {
            let (y0, ym) = (y(l).max(0.0), y(m).max(0.0));
            let y1 = y(&h[3 * p..3 * p + 3]).max(0.0);
            let base = 0.5 * (y0 + y1);
            let bound = 0.25 * (y0.sqrt() - y1.sqrt()).powi(2) - base;
            let v = ym - base;
            mb.push(if v.is_finite() && bound.is_finite() {
                (v.max(bound), bound)
            } else {
                (0.0, 0.0)
            });
        }
    }
    let w: std::sync::Arc<[f64]> = if n <= spatial::READ_POWER_MAX_SIZE {
        spatial::read_weights(n)
    } else {
        let sa = solid_angle_table(n);
        (0..6).flat_map(|_| sa.iter().map(|&s| s as f64)).collect()
    };
    let (mut sum, mut slack) = (0.0f64, 0.0f64);
    for (&(v, bound), wp) in mb.iter().zip(w.iter()) {
        sum += wp * v;
        slack += wp * (v - bound);
    }
    let f = if slack > 0.0 {
        (sum / slack).clamp(-1.0, 1.0)
    } else {
        0.0
    };
    let mut a = Cubemap::new(n);
    for (face, chunk) in a.faces.iter_mut().zip(mb.chunks_exact(n * n)) {
        for (t, &(v, bound)) in face.data.chunks_exact_mut(3).zip(chunk) {
            t.fill(ibl_core::io::f16_round((v - f * (v - bound)) as f32));
        }
    }
    a
}

/// The alpha of a level l ≥ 1: M = Y(mid) − Y(lo) per texel of `lo` (level l as stored), `mid`
/// the kernel at [`CustomLookup::mid_roughness`]`(l)` on lo's texels, rounded to half
/// precision, in all three channels. The shader reads it as a difference (its bilinear read is
/// the difference of the reads, between centres too) and takes the log of ya + a.a: no bound
/// is needed (the log's polynomial is exponentiated, never negative) and no balance (the read
/// is not linear in it; [`CustomLookup::fit_power`] keeps the power instead).
pub fn midpoint_alpha(lo: &Cubemap, mid: &Cubemap) -> Cubemap {
    let n = lo.size;
    assert_eq!(mid.size, n, "the midpoint on level l's texels");
    let mut a = Cubemap::new(n);
    for ((out, l), m) in a.faces.iter_mut().zip(&lo.faces).zip(&mid.faces) {
        for ((t, l), m) in out
            .data
            .chunks_exact_mut(3)
            .zip(l.data.chunks_exact(3))
            .zip(m.data.chunks_exact(3))
        {
            let y = |v: &[f32]| luminance([v[0], v[1], v[2]]);
            let v = y(m) - y(l);
            t.fill(ibl_core::io::f16_round(if v.is_finite() { v } else { 0.0 }));
        }
    }
    a
}

/// The last level's alpha: zero (no interval above it to hold a midpoint of).
pub fn zero_alpha(level: &Cubemap) -> Cubemap {
    Cubemap::new(level.size)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_target::LodMapping;

    /// The constants a shader text declares, parsed back (independently of the emitter: the
    /// name, then the first float literal after it on its line).
    fn constants(text: &str) -> [f32; 3] {
        [
            "IBL_LOOKUP_SCALE",
            "IBL_LOOKUP_INV_ALPHA0",
            "IBL_LOOKUP_MAX_LOD",
        ]
        .map(|name| {
            let line = text
                .lines()
                .find(|l| l.contains(&format!("{name}:")) || l.contains(&format!("{name} =")))
                .unwrap_or_else(|| panic!("{name} not declared"));
            let v = line.split('=').nth(1).unwrap().trim().trim_end_matches(';');
            v.parse::<f32>().unwrap()
        })
    }

    /// An independent lod: the formula of docs/CUSTOM_LOOKUP.md from the parsed constants,
    /// in f64.
    fn lod_by_hand(c: [f32; 3], r: f64) -> f64 {
        let r = r.clamp(0.0, 1.0);
        (c[0] as f64 * (1.0 + r * r * c[1] as f64).log2()).clamp(0.0, c[2] as f64)
    }

    #[test]
    fn emitted_shaders_parse_back_to_the_same_constants_and_lod() {
        for (a0, n, size) in [(0.02f32, 6usize, 256usize), (0.003, 7, 256), (0.5, 5, 64)] {
            let mut lk = CustomLookup::new(a0, n, size);
            lk.power = (0..n - 1)
                .map(|l| [0.01 * l as f32 - 0.013, 0.002 - 0.003 * l as f32])
                .collect();
            let m = LodMapping::Custom { alpha0: a0 };
            for (name, text) in lk.shaders() {
                let c = constants(&text);
                assert_eq!(c, [lk.scale, lk.inv_alpha0, lk.max_lod], "{name}");
                // Two taps, and the formula's text is the one documented.
                let taps = [" textureLod(", ".SampleLevel(", " textureSampleLevel("]
                    .iter()
                    .map(|t| text.matches(t).count())
                    .sum::<usize>();
                assert_eq!(taps, 2, "{name}");
                assert!(text.contains("log2(1.0 + r * r * IBL_LOOKUP_INV_ALPHA0)"));
                assert!(text.contains("max(min(floor(lod), IBL_LOOKUP_MAX_LOD - 1.0), 0.0)"));
                assert!(text.contains("c * max(lum / y, 0.0)"));
                assert!(text.contains("4.0 * t * q * s * gm"));
                assert!(text.contains("(4.0 / 3.0) * t * p * q * log2(max(yb + b.a, 0.0) + e)"));
                assert!(text.contains("exp2(g) - e"));
                // The power factors as declared: one per interval, in order.
                let pw_line = text
                    .lines()
                    .find(|l| l.contains("IBL_LOOKUP_POWER") && l.contains('='))
                    .unwrap();
                let after = pw_line.split('=').nth(1).unwrap();
                let pw: Vec<[f32; 2]> = after
                    .split('(')
                    .skip(1)
                    .filter_map(|piece| {
                        let v: Vec<f32> = piece
                            .split(')')
                            .next()?
                            .split(',')
                            .map(|x| x.trim().parse().ok())
                            .collect::<Option<_>>()?;
                        (v.len() == 2).then(|| [v[0], v[1]])
                    })
                    .collect();
                assert_eq!(pw, lk.power, "{name}");
                // The luminance weights as declared.
                let luma_line = text
                    .lines()
                    .find(|l| l.contains("IBL_LOOKUP_LUMA"))
                    .unwrap();
                let inner = luma_line
                    .split('(')
                    .nth(1)
                    .unwrap()
                    .split(')')
                    .next()
                    .unwrap();
                let w: Vec<f32> = inner
                    .split(',')
                    .map(|x| x.trim().parse().unwrap())
                    .collect();
                assert_eq!(w, LUMA, "{name}");
                for k in 0..=64 {
                    let r = k as f32 / 64.0;
                    let by_hand = lod_by_hand(c, r as f64);
                    // The emulation, the engine-mapping view and the hand formula agree.
                    assert!((lk.lod(r) as f64 - by_hand).abs() < 1e-5, "{name} r {r}");
                    assert_eq!(lk.lod(r), m.lod(r, n, size), "r {r}");
                }
            }
            // Level l's roughness is where the lookup lands.
            for l in 0..n {
                let r = m.level_roughness(l, n, size);
                assert!((lk.lod(r) - l as f32).abs() < 2e-4, "a0 {a0} l {l}");
            }
            // The metadata carries the same constants.
            let md = lk.metadata(&m.level_roughnesses(n, size));
            let get = |k: &str| {
                let v = &md.iter().find(|e| e.0 == k).unwrap().1;
                assert_eq!(v.last(), Some(&0));
                String::from_utf8(v[..v.len() - 1].to_vec()).unwrap()
            };
            assert_eq!(get("ibl.lookup.scale").parse::<f32>().unwrap(), lk.scale);
            assert_eq!(
                get("ibl.lookup.inv_alpha0").parse::<f32>().unwrap(),
                lk.inv_alpha0
            );
            assert_eq!(
                get("ibl.lookup.max_lod").parse::<f32>().unwrap(),
                lk.max_lod
            );
            assert_eq!(get("ibl.level_roughness").split(',').count(), n);
            assert_eq!(get("ibl.lookup.luma"), "0.2126,0.7152,0.0722");
            // The interval's middle is lod l + ½.
            for l in 0..n - 1 {
                let (il, t) = lk.interval(lk.mid_roughness(l));
                assert_eq!(il, l, "a0 {a0}");
                assert!((t - 0.5).abs() < 1e-4, "a0 {a0} l {l}: t {t}");
            }
        }
    }

    /// The emitted GLSL (ES 3.0 fragment shader) and HLSL compile with glslangValidator and
    /// the WGSL validates with naga, each inside a minimal shader that calls the function;
    /// skipped where a tool is absent (scripts/setup-shader-validators.sh installs both).
    #[test]
    fn emitted_shaders_compile_where_the_validators_are() {
        let lk = CustomLookup::new(0.01, 6, 256);
        let dir = tempfile::tempdir().unwrap();
        let run = |tool: &str, args: &[&str], src: &str, name: &str| {
            let path = dir.path().join(name);
            std::fs::write(&path, src).unwrap();
            let Ok(out) = std::process::Command::new(tool)
                .args(args)
                .arg(&path)
                .output()
            else {
                eprintln!("{tool} not found: {name} not compiled");
                return;
            };
            let msg = String::from_utf8_lossy(&out.stdout).to_string()
                + &String::from_utf8_lossy(&out.stderr);
            assert!(out.status.success(), "{tool} {name}: {msg}");
        };
        let glsl = format!(
            "#version 300 es\nprecision highp float;\n{}\nuniform samplerCube u_chain;\nin vec3 v_r;\nuniform float u_roughness;\nout vec4 o;\nvoid main() {{ o = vec4(iblCustomSpecular(u_chain, v_r, u_roughness), 1.0); }}\n",
            lk.glsl()
        );
        run("glslangValidator", &[], &glsl, "custom.frag");
        let hlsl = format!(
            "{}\nTextureCube g_chain : register(t0);\nSamplerState g_s : register(s0);\nfloat4 main(float3 r : TEXCOORD0) : SV_Target {{ return float4(iblCustomSpecular(g_chain, g_s, r, 0.3), 1.0); }}\n",
            lk.hlsl()
        );
        let spv = dir.path().join("custom.spv");
        let spv = spv.to_str().unwrap();
        run(
            "glslangValidator",
            &["-D", "-V", "-e", "main", "-S", "frag", "-o", spv],
            &hlsl,
            "custom.hlsl",
        );
        let wgsl = format!(
            "{}\n@group(0) @binding(0) var t: texture_cube<f32>;\n@group(0) @binding(1) var s: sampler;\n@fragment fn main(@location(0) r: vec3<f32>) -> @location(0) vec4<f32> {{ return vec4<f32>(ibl_custom_specular(t, s, r, 0.3), 1.0); }}\n",
            lk.wgsl()
        );
        run("naga", &[], &wgsl, "custom.wgsl");
    }

    use crate::bake::{bake_chain, Params};
    use crate::kernel::SourceTexels;
    use crate::runtime::{
        abs_rel_stats, abs_rel_stats_of, probe_directions, roughness_grid, Reference,
    };
    use ibl_core::cube::{texel_direction, texel_solid_angle, Cubemap, Face};
    use ibl_core::envmap::Environment;
    use ibl_core::progress::NoProgress;
    use ibl_target::Target;

    /// A sky with a small bright patch, a gradient and a dark floor (as runtime's tests).
    fn sky(n: usize) -> Cubemap {
        Cubemap::from_fn(n, |d| {
            let d = d.normalize();
            let sun = (d.dot(Vec3::new(0.4, 0.7, 0.59).normalize()) - 0.97).max(0.0) * 300.0;
            let base = 0.2 + 0.8 * d.y.max(0.0) + 0.1 * (3.0 * d.x).sin().abs();
            [base + sun, base * 0.9 + sun, base * 0.7 + 0.5 * sun]
        })
    }

    fn params(target: Target, size: usize, levels: usize) -> Params {
        Params {
            size,
            levels: Some(levels),
            target,
            ..Default::default()
        }
    }

    /// The emulated shader read of a custom chain against the exact kernel summed by brute
    /// force over every source texel, at the 33 roughness values: bounded, better than the
    /// linear (gltf) lookup of a chain of the same levels at every r ≥ 0.1 taken together, and
    /// better than its own two taps without the correction (a linear blend).
    #[test]
    fn emulation_against_the_brute_force_kernel_at_33_roughness_values() {
        let src = sky(32);
        let env = Environment::Cube(src.clone());
        let texels = SourceTexels::new(&src);
        let brute = Reference::Brute {
            texels: &texels,
            source: &src,
        };
        let rs = roughness_grid(33);
        let dirs = probe_directions(96);
        let worst = |st: &[crate::runtime::AbsRel]| {
            let hi: Vec<f64> = rs
                .iter()
                .zip(st)
                .filter(|(r, _)| **r >= 0.1)
                .map(|(_, s)| s.mean)
                .collect();
            (hi.iter().cloned().fold(0.0, f64::max), hi)
        };
        let p = params(Target::Custom, 32, 4);
        let chain = bake_chain(&p, &env, &NoProgress).unwrap();
        let lk = chain.report.custom_lookup.clone().unwrap();
        let alpha = chain
            .correction
            .as_ref()
            .expect("custom chains have an alpha");
        let cc = CustomChain::new(&chain.mips, alpha);
        let (custom, profile) = worst(&abs_rel_stats_of(
            &|d, r| lk.read(&cc, d, r),
            &rs,
            &dirs,
            &brute,
        ));
        // Without the midpoints: the same two levels blended linearly (one trilinear tap).
        let (blend, _) = worst(&abs_rel_stats_of(
            &|d, r| cc.rgb.sample(d, lk.lod(r)),
            &rs,
            &dirs,
            &brute,
        ));
        let pg = params(Target::Gltf, 32, 4);
        let g = bake_chain(&pg, &env, &NoProgress).unwrap();
        let (gltf, _) = worst(&abs_rel_stats(
            &BorderedMips::new(&g.mips),
            pg.lookup(),
            &rs,
            &dirs,
            &brute,
        ));
        // Measured 2026-11-26: worst over r ≥ 0.1 on this 32² × 4 chain 0.85% custom, 2.3%
        // its levels blended linearly, 4.0% gltf (fitted levels).
        assert!(custom < 0.015, "custom worst {custom}: {profile:?}");
        assert!(
            custom < 0.5 * blend,
            "custom {custom} vs its linear blend {blend}"
        );
        assert!(custom < 0.5 * gltf, "custom {custom} vs gltf {gltf}");
    }

    /// Power of a cube-valued function over the sphere, sampled at the centres of an n×n grid.
    fn power(n: usize, f: impl Fn(Vec3) -> Rgb) -> f64 {
        let mut s = 0.0;
        for face in Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    let v = f(texel_direction(face, i, j, n));
                    s += ibl_core::luminance(v) as f64 * texel_solid_angle(i, j, n);
                }
            }
        }
        s
    }

    /// A one-texel 10⁵ sun over a dim sky keeps its power through the custom lookup at every
    /// roughness, between the levels too: the first interval's read is linear in levels whose
    /// *read* keeps it (`crate::spatial::keep_read_power`) and a correction whose read integrates
    /// to zero and never turns the quadratic negative ([`correction`]), the others read in the
    /// log with the chain's power factors ([`CustomLookup::fit_power`]). On this small chain
    /// (64² × 4, last level 8²; the sun's lobe at level 1 half a texel wide, where sharpening a
    /// level for its bilinear read, `spatial::sharpen_for_bilinear`, assumes more) measured
    /// 0.20% at worst (r = 0.17, just past level 1; 0.12% unsharpened, 0.48% with a
    /// one-constant factor), bounded here at 0.3%; the default 256² chain keeps it within 0.093%
    /// (bench/runtime.md "sun power", the goal 0.1%). Integrated through the emulation
    /// on a 256² grid a face. The first linear correction, without its lower bound, lost 0.93%
    /// here at r = 0.1.
    #[test]
    fn sun_power_is_kept_between_levels() {
        let n = 64;
        let mut src = Cubemap::constant(n, [0.05, 0.05, 0.05]);
        let (face, i, j) = (Face::from_index(2), 11, 19);
        let k = 3 * (j * n + i);
        src.faces[face as usize].data[k..k + 3].copy_from_slice(&[1e5, 1e5, 1e5]);
        let mut want = 0.0f64;
        for f in Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    want +=
                        ibl_core::luminance(src.texel(f, i, j)) as f64 * texel_solid_angle(i, j, n);
                }
            }
        }
        let env = Environment::Cube(src.clone());
        let p = params(Target::Custom, 64, 4);
        let chain = bake_chain(&p, &env, &NoProgress).unwrap();
        let b = CustomChain::new(&chain.mips, chain.correction.as_ref().unwrap());
        let lk = chain.report.custom_lookup.clone().unwrap();
        let levels = &chain.report.level_roughness;
        let mut rs: Vec<f32> = vec![0.1, 0.17, 0.29, 0.41, 0.58, 0.77, 0.93];
        assert!(rs
            .iter()
            .all(|r| levels.iter().all(|l| (l - r).abs() > 1e-3)));
        rs.extend(levels);
        let mut unfitted = lk.clone();
        unfitted.power.iter_mut().for_each(|c| *c = [0.0; 2]);
        let (mut worst, mut worst_unfitted) = (0.0f64, 0.0f64);
        for r in rs {
            let got = power(256, |d| lk.read(&b, d, r));
            let e = (got - want).abs() / want;
            eprintln!(
                "r {r} lod {} power {:+.4}%",
                lk.lod(r),
                100.0 * (got - want) / want
            );
            assert!(e < 3e-3, "r {r}: power {got} vs {want} ({:.3}%)", 100.0 * e);
            worst = worst.max(e);
            let raw = power(256, |d| unfitted.read(&b, d, r));
            worst_unfitted = worst_unfitted.max((raw - want).abs() / want);
        }
        // The factors do the work: without them the log read drifts (measured 0.48%).
        assert!(
            worst_unfitted > 2.0 * worst,
            "power factors: {worst} fitted vs {worst_unfitted} without"
        );
    }

    /// The alpha channel is what the lookup needs at each interval's middle: for a chain
    /// baked with its own α₀ (the midpoints are the chain's, not the default's), no level is
    /// fitted to a linear blend (the quadratic's three points are the kernel's), and at the
    /// texel centres of level l at lod l + ½ the read's luminance is the kernel's there, to the
    /// alpha's half precision and its balance (Σ W A = 0).
    #[test]
    fn the_read_at_each_midpoint_is_the_kernel_there() {
        let src = sky(32);
        let texels = SourceTexels::new(&src);
        for a0 in [0.003f32, 0.05] {
            let p = Params {
                custom_alpha0: Some(a0),
                fit_lookup: Some(true),
                ..params(Target::Custom, 32, 4)
            };
            let chain = bake_chain(&p, &Environment::Cube(src.clone()), &NoProgress).unwrap();
            assert!(
                chain.report.level.iter().all(|l| l.fit.is_none()),
                "a0 {a0}"
            );
            let lk = chain.report.custom_lookup.clone().unwrap();
            let alpha = chain.correction.as_ref().unwrap();
            let cc = CustomChain::new(&chain.mips, alpha);
            for l in 0..3 {
                let n = chain.mips.levels[l].size;
                let r = lk.mid_roughness(l);
                // Levels whose texels are footprint means hold the kernel's mean: compare
                // the read there with the texel-centre kernel only where texels are small
                // next to the lobe (the chain's own level 0 and 1 at these α₀).
                if crate::bake::footprint_factor(n, r) > 1 {
                    continue;
                }
                let (mut worst, mut count) = (0.0f64, 0);
                for face in Face::ALL {
                    for j in (0..n).step_by(3) {
                        for i in (0..n).step_by(3) {
                            let d = texel_direction(face, i, j, n);
                            let want = ibl_core::luminance(texels.convolve(d.normalize(), r * r));
                            let got = ibl_core::luminance(lk.read(&cc, d, r));
                            let e = ((got - want) / want.max(1e-3)).abs() as f64;
                            worst = worst.max(e);
                            count += 1;
                        }
                    }
                }
                assert!(count > 50);
                // The tree's own error (0.02–0.1%) and the alpha's half precision.
                assert!(worst < 4e-3, "a0 {a0} level {l}: worst {worst}");
            }
        }
    }

    /// `correction` on synthetic levels: M is Y(mid) − (Y(lo) + Y(hi))/2 up to a balance shift
    /// and half rounding, and its read integrates to zero.
    #[test]
    fn correction_is_the_midpoint_difference_balanced_to_zero_power() {
        let lo = sky(16);
        // The midpoint: the level plus a curvature term of nearly zero mean.
        let mut mid = Cubemap::new(16);
        for face in Face::ALL {
            for j in 0..16 {
                for i in 0..16 {
                    let d = texel_direction(face, i, j, 16).normalize();
                    let x = lo.texel(face, i, j);
                    let k = 3 * (j * 16 + i);
                    for c in 0..3 {
                        mid.faces[face as usize].data[k + c] =
                            x[c] + 0.05 * (3.0 * d.x).sin() + 0.02 * d.y;
                    }
                }
            }
        }
        let hi = lo.downsample();
        let a = correction(&lo, &mid, &hi);
        let hi = read_at_texels(&hi, 16);
        let w = spatial::read_weights(16);
        let (mut sum, mut abs, mut worst) = (0.0f64, 0.0f64, 0.0f64);
        for face in Face::ALL {
            for j in 0..16 {
                for i in 0..16 {
                    let y = |c: &Cubemap| ibl_core::luminance(c.texel(face, i, j)) as f64;
                    let raw = y(&mid) - 0.5 * (y(&lo) + y(&hi));
                    let got = a.texel(face, i, j);
                    assert!(got[0] == got[1] && got[1] == got[2]);
                    let got = got[0] as f64;
                    worst = worst.max((got - raw).abs() / y(&mid).max(1e-2));
                    let wp = w[face as usize * 256 + j * 16 + i];
                    sum += wp * got;
                    abs += wp * got.abs();
                }
            }
        }
        assert!(
            sum.abs() < 2e-3 * abs,
            "Σ W M = {sum} against Σ W |M| = {abs}"
        );
        // The shift, relative to the midpoint's value, is the imbalance over Σ W·slack: small
        // for levels that keep their power.
        assert!(worst < 0.05, "worst relative change {worst}");
    }

    /// Lagrange's weights: one at their node, zero at the others, summing to one at every t
    /// (what keeps the power); the cubic reproduces a cubic.
    #[test]
    fn lagrange_weights_interpolate() {
        let (q, c) = (CustomLookup::quadratic_weights, CustomLookup::cubic_weights);
        assert_eq!(q(0.0), (1.0, 0.0, 0.0));
        assert_eq!(q(0.5), (0.0, 1.0, 0.0));
        assert_eq!(q(1.0), (0.0, 0.0, 1.0));
        assert_eq!(c(0.0), (1.0, 0.0, 0.0, 0.0));
        assert_eq!(c(0.5), (0.0, 1.0, 0.0, 0.0));
        assert_eq!(c(1.0), (0.0, 0.0, 1.0, 0.0));
        for k in 0..=40 {
            let t = k as f32 / 40.0;
            let (a, b, d) = q(t);
            assert!((a + b + d - 1.0).abs() < 1e-6);
            let (a, b, d, e) = c(t);
            assert!((a + b + d + e - 1.0).abs() < 1e-6);
            let f = |x: f32| 0.3 - 1.2 * x + 0.7 * x * x - 0.4 * x * x * x;
            let got = a * f(0.0) + b * f(0.5) + d * f(1.0) + e * f(1.5);
            assert!((got - f(t)).abs() < 1e-5, "t {t}: {got} vs {}", f(t));
        }
    }

    /// The custom chain and its report are bit-identical whatever the thread count.
    #[test]
    fn bit_identical_for_any_thread_count() {
        let env = Environment::Cube(sky(32));
        let p = params(Target::Custom, 16, 4);
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| bake_chain(&p, &env, &NoProgress).unwrap())
        };
        let (a, b) = (run(1), run(3));
        crate::test_util::assert_same_bits(&a.mips, &b.mips);
        crate::test_util::assert_same_bits(
            a.correction.as_ref().unwrap(),
            b.correction.as_ref().unwrap(),
        );
        let ja = serde_json::to_string(&a.report).unwrap();
        let jb = serde_json::to_string(&b.report).unwrap();
        assert_eq!(ja, jb);
        assert!(ja.contains("\"custom_lookup\":{"), "{ja}");
    }

    /// Pipelines and scenes reach the custom target through the same Params (RON keys), and
    /// --custom-alpha0 is checked before any work.
    #[test]
    fn ron_params_select_the_custom_lookup_and_bad_knees_are_refused() {
        let p: Params =
            ron::from_str("(target: custom, custom_alpha0: Some(0.02), size: 64)").unwrap();
        p.validate().unwrap();
        assert_eq!(p.lookup(), LodMapping::Custom { alpha0: 0.02 });
        assert_eq!(p.chain_levels(), 4, "down to 8×8 faces");
        let lk = p.custom_lookup().unwrap();
        assert_eq!((lk.levels, lk.size, lk.alpha0), (4, 64, 0.02));
        let d: Params = ron::from_str("(target: custom)").unwrap();
        assert_eq!(
            d.lookup(),
            LodMapping::Custom {
                alpha0: ibl_target::lod::CUSTOM_ALPHA0
            }
        );
        for bad in [
            "(target: gltf, custom_alpha0: Some(0.02))",
            "(target: custom, custom_alpha0: Some(0.0))",
            "(target: custom, custom_alpha0: Some(NaN))",
            "(target: custom, custom_alpha0: Some(100.0))",
        ] {
            let p: Params = ron::from_str(bad).unwrap();
            let e = p.validate().unwrap_err().to_string();
            assert!(
                e.contains("--custom-alpha0") && !e.contains('\n'),
                "{bad}: {e}"
            );
        }
        // The correction lives in the alpha channel: formats and layouts without one are
        // refused before any work.
        for bad in [
            "(target: custom, format: Some(bc6h))",
            "(target: custom, format: Some(rgb9e5))",
            "(target: custom, layout: Some(faces))",
        ] {
            let p: Params = ron::from_str(bad).unwrap();
            let e = p.validate().unwrap_err().to_string();
            assert!(
                e.contains("alpha channel") && !e.contains('\n'),
                "{bad}: {e}"
            );
        }
    }
}
