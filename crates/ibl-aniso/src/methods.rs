//! The runtime methods, each reading the environment as a shader reads our bakes: the
//! prefiltered GGX chain through a [`Lookup`] (the target's lod mapping, trilinear, seamless,
//! or the exact kernel at continuous roughness, the "oracle"), and the DFG table
//! (`ibl_shexp::dfg::Dfg`, `ibl-lut`'s bake). Every method returns (E0, E1) so both F0 = 1 and
//! F0 = 0.04 follow from one pass: with the split sum L̄·(F0·A + B), E0 = L̄(A+B), E1 = L̄·B.

use crate::major_axis;
use crate::material::{iso_roughness, Material};
use crate::scene::Frame;
use glam::Vec3;
use ibl_core::bordered::BorderedMips;
use ibl_core::sampling::{hammersley, Pcg32};
use ibl_core::{Cubemap, Rgb};
use ibl_prefilter::runtime::Reference;
use ibl_prefilter::tree::{CellTree, TreeBuffers, TreeParams};
use ibl_shexp::dfg::Dfg;

/// Křivánek & Colbert 2008's lod bias (GPU Gems 3 ch. 20, eq. 13's +1): the published FIS
/// that `fis-N` runs as the baseline the shipped rule is scored against.
pub const KC_LOD_BIAS: f32 = 1.0;

/// A `-bB` lod bias of a method name: finite, |B| ≤ 8.
fn lod_bias(b: &str) -> Option<f32> {
    b.parse::<f32>()
        .ok()
        .filter(|b| b.is_finite() && b.abs() <= 8.0)
}
use ibl_target::LodMapping;

/// How a method reads prefiltered radiance at (direction, perceptual roughness).
#[allow(clippy::large_enum_variant)] // one or two per environment
pub enum Lookup {
    /// The target's baked chain read by its engine's lookup (`ibl_prefilter::runtime::lookup`).
    Engine {
        /// The chain, bordered for seamless reads.
        chain: BorderedMips,
        /// The target's level ↔ roughness mapping.
        mapping: LodMapping,
    },
    /// The exact half-vector kernel at continuous roughness (`Reference::Tree` over the
    /// source): the method's error without the chain's.
    Oracle {
        /// Cell hierarchy of the source.
        tree: CellTree,
        /// The source cube (roughness 0 reads it bilinearly).
        source: Cubemap,
    },
}

/// The tree knobs of `prefilter --quality default` (measured within 0.02% of the brute force).
pub const ORACLE_TREE: TreeParams = TreeParams {
    theta: 0.7,
    kappa: 4.0,
    horizon: 0.12,
};

impl Lookup {
    /// Prefiltered radiance in world direction d at perceptual roughness r.
    pub fn radiance(&self, d: Vec3, r: f32, buf: &mut TreeBuffers) -> Rgb {
        let r = r.clamp(0.0, 1.0);
        match self {
            Lookup::Engine { chain, mapping } => {
                ibl_prefilter::runtime::lookup(chain, *mapping, d, r)
            }
            Lookup::Oracle { tree, source } => Reference::Tree {
                tree,
                source,
                params: ORACLE_TREE,
            }
            .radiance(d.normalize(), r, buf),
        }
    }

    /// "engine" or "oracle".
    pub fn name(&self) -> &'static str {
        match self {
            Lookup::Engine { .. } => "engine",
            Lookup::Oracle { .. } => "oracle",
        }
    }
}

/// A runtime method.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub enum Method {
    /// M0: isotropic split sum at r = √((α_t+α_b)/2) along reflect(v, n): the floor.
    Iso,
    /// M1a: bent normal of Lagarde & Golubev 2018 / Unity HDRP (Cocco et al.'s baseline).
    BentLg18,
    /// M1b: bent normal of Filament.
    BentFilament,
    /// M1c: bent normal of KHR_materials_anisotropy / glTF-Sample-Viewer.
    BentKhr,
    /// M2: major-axis sampling (Cocco et al. 2024).
    MajorAxis(major_axis::Params),
    /// M3: VNDF filtered importance sampling over a box pyramid of the source (Křivánek &
    /// Colbert 2008 with Heitz 2018's visible normals), N taps.
    Fis {
        /// Taps.
        taps: usize,
        /// Added to every tap's lod: Křivánek & Colbert's +1 (`fis-N`), or B (`fis-N-bB`).
        lod_bias: f32,
    },
    /// M3c: the shipped method (`crate::ship::shade`): the isotropic split sum at r_iso
    /// mixed into `fis-N` by the fitted weight w(|η|, r_iso) (`crate::ship::fis_weight`; w = 0
    /// at η = 0 below its roughness ramp: exactly the floor). N pyramid taps + 1 chain tap
    /// (none of the N where w = 0).
    FisBlend {
        /// FIS taps.
        taps: usize,
    },
    /// M3b: the isotropic split sum corrected by VNDF FIS as a control variate: split sum at
    /// r_iso + FIS(α_t, α_b) − FIS(α_iso, α_iso), both FIS sums over the same N rotated points
    /// (2N pyramid taps + 1 chain tap). At η = 0 the two sums are the same numbers and cancel
    /// exactly: the method *is* the isotropic floor there.
    Cv {
        /// Taps of each FIS sum.
        taps: usize,
    },
    /// M4a: Ashikhmin–Shirley as the thesis writes it (Marcolongo 2020 §4.3): N fixed
    /// Hammersley points through the baked half-vector LUT, the raw cube read bilinearly at
    /// l = reflect(v, h), the mean times F0·s + b from the baked size/bias table.
    AsThesis {
        /// Taps.
        taps: usize,
    },
    /// M4b: the same taps weighted by F(v·h)(n·l)/max(n·v, n·l) (the unbiased estimator of
    /// exact p_h sampling, docs/ANISOTROPY.md §2.3 of the design): no size/bias table.
    AsWeighted {
        /// Taps.
        taps: usize,
    },
    /// M4c: the weighted taps placed and filtered: the N Hammersley points shifted per pixel
    /// (Cranley–Patterson, as `fis-N`) through the LUT's inverse CDF — equal-mass strata of
    /// p_h that differ from pixel to pixel instead of one fixed pattern — and each tap read
    /// from the box pyramid at the filtered-importance-sampling lod of its pdf
    /// p_l = A·p_h(n)/(4 v·h) (Křivánek & Colbert 2008 eq. 13, +1 bias, as `fis-N`).
    AsFis {
        /// Taps.
        taps: usize,
        /// Added to the lod (`as-fis-N`: 1, Křivánek & Colbert's; `as-fis-N-bB`: B); `None`
        /// reads the raw cube bilinearly (`as-strat-N`: the stratification alone).
        bias: Option<f32>,
    },
    /// M4d: the weighted taps on a grid of equal-mass cells shaped to the lobe. The lobe is
    /// a Gaussian in the plane g = (√(n_u+1)·x, √(n_v+1)·y) of the half vector's polar slope
    /// (x, y) = θ(cos φ, sin φ) (exactly: the thesis's sampler at ξ1 = atan2(g_y, g_x)/2π,
    /// ξ2 = 1 − exp(−|g|²/2) is p_h for g ~ N(0, I)), so an a × b grid of normal quantiles
    /// with a/b = √((n_v+1)/(n_u+1)) cuts it into cells of 1/(ab) of the mass that are as
    /// long as wide on the sphere. The isotropic lod of each tap's pdf (Křivánek & Colbert
    /// eq. 13 + B) then fits its cell; the Hammersley set's polar cells are needles along a
    /// thin lobe, which no isotropic lod fits.
    AsGrid {
        /// Tap budget N (a·b ≤ N taps are read).
        taps: usize,
        /// Added to the lod.
        bias: f32,
        /// Each pixel shifts the grid by a Cranley–Patterson rotation (else cell midpoints).
        jitter: bool,
    },
    /// M4e: a quadrature with tap weights. The lobe's Gaussian plane (as [`Method::AsGrid`])
    /// is cut into a × b cells of equal size over [−K, K]² (the outer cells take the mass
    /// beyond), square on the sphere; each tap reads the pyramid at its cell's centre with a
    /// filter of the cell's solid angle and is weighted by the cell's exact mass of p_h times
    /// F(v·h)(n·l)/max(n·v, n·l). Equal-mass cells grow long in the lobe's tails, where
    /// one isotropic read cannot cover them; equal-size cells are what a box filter fits.
    AsQuad {
        /// Tap budget N (a·b ≤ N taps are read).
        taps: usize,
        /// Added to the lod.
        bias: f32,
        /// Half-width K of the covered square, in standard deviations.
        k: f32,
    },
}

/// The Ashikhmin–Shirley tables a lobe's runtime reads, baked in memory by `ibl-lut` exactly
/// as `hv-lut` and `brdf-lut as-size-bias` write them (float).
pub struct AsTables {
    /// The half-vector LUT (RGB = h·½+½, A = p_h/p_h(n)).
    pub hv: ibl_core::Image,
    /// The size/bias table (R = s, G = b) over (u, v) = (2/π·atan|v_y/v_x|, √(n·v)).
    pub size_bias: ibl_core::Image,
    /// p_h at h = n, √((n_u+1)(n_v+1))/2π: the LUT's A channel times it is p_h (a uniform
    /// of the shader).
    pub pdf_h_n: f64,
    /// The lobe's exponents (n_u, n_v), uniforms of the shader.
    pub exponents: (f64, f64),
}

impl AsTables {
    /// Bakes both tables for (n_u, n_v): a `hv_size`² LUT, and a 64² size/bias table from 1024
    /// direct samples (`brdf-lut as-size-bias` at its sampler default).
    pub fn bake(nu: f64, nv: f64, hv_size: usize) -> AsTables {
        let a = ibl_brdf::AshikhminShirley::new(nu, nv);
        let p = ibl_core::progress::NoProgress;
        let set = ibl_lut::as_size_bias::SampleSet::direct(&a, 1024);
        AsTables {
            hv: ibl_lut::hv::hv_table(&a, hv_size, &p),
            size_bias: ibl_lut::as_size_bias::size_bias_table(&set, 64, &p),
            pdf_h_n: a.pdf_h_at_normal(),
            exponents: (nu, nv),
        }
    }

    /// (s, b) at a local view, bilinear between texel centres (as a GPU reads the table).
    pub fn size_bias_at(&self, v: Vec3) -> (f32, f32) {
        let u = if v.x == 0.0 && v.y == 0.0 {
            0.0
        } else {
            v.y.abs().atan2(v.x.abs()) / std::f32::consts::FRAC_PI_2
        };
        let t = v.z.max(0.0).sqrt();
        let img = &self.size_bias;
        let (w, h) = (img.width, img.height);
        let x = (u * w as f32 - 0.5).clamp(0.0, (w - 1) as f32);
        let y = (t * h as f32 - 0.5).clamp(0.0, (h - 1) as f32);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let mut c = [0.0f32; 2];
        for (xx, yy, wt) in [
            (x0, y0, (1.0 - fx) * (1.0 - fy)),
            (x1, y0, fx * (1.0 - fy)),
            (x0, y1, (1.0 - fx) * fy),
            (x1, y1, fx * fy),
        ] {
            let tx = img.texel(xx, yy);
            c[0] += wt * tx[0];
            c[1] += wt * tx[1];
        }
        (c[0], c[1])
    }
}

impl Method {
    /// Short name for reports and file names.
    pub fn name(&self) -> String {
        match self {
            Method::Iso => "iso".into(),
            Method::BentLg18 => "bent-lg18".into(),
            Method::BentFilament => "bent-filament".into(),
            Method::BentKhr => "bent-khr".into(),
            Method::MajorAxis(p) => {
                let mut s = format!("major-{}", p.taps);
                if p.beta != 2.3 {
                    s += &format!("-b{}", p.beta);
                }
                if p.k != 1.0 {
                    s += &format!("-k{}", p.k);
                }
                if p.c != 1.0 {
                    s += &format!("-c{}", p.c);
                }
                s
            }
            Method::Fis { taps, lod_bias } if *lod_bias == KC_LOD_BIAS => format!("fis-{taps}"),
            Method::Fis { taps, lod_bias } => format!("fis-{taps}-b{lod_bias}"),
            Method::Cv { taps } => format!("cv-{taps}"),
            Method::FisBlend { taps } => format!("fisb-{taps}"),
            Method::AsThesis { taps } => format!("as-thesis-{taps}"),
            Method::AsWeighted { taps } => format!("as-weighted-{taps}"),
            Method::AsFis { taps, bias } => match bias {
                None => format!("as-strat-{taps}"),
                Some(b) if *b == 1.0 => format!("as-fis-{taps}"),
                Some(b) => format!("as-fis-{taps}-b{b}"),
            },
            Method::AsQuad { taps, bias, k } => {
                let mut s = format!("as-quad-{taps}");
                if *bias != 0.0 {
                    s += &format!("-b{bias}");
                }
                if *k != AS_QUAD_K {
                    s += &format!("-k{k}");
                }
                s
            }
            Method::AsGrid { taps, bias, jitter } => {
                let j = if *jitter { "j" } else { "" };
                if *bias == 0.0 {
                    format!("as-grid{j}-{taps}")
                } else {
                    format!("as-grid{j}-{taps}-b{bias}")
                }
            }
        }
    }

    /// Parses `iso`, `bent-lg18`, `bent-filament`, `bent-khr`, `major-N[-bBETA][-kK][-cC]`,
    /// `fis-N[-bB]`, `fisb-N`, `cv-N`, `as-thesis-N`, `as-weighted-N`, `as-fis-N[-bB]`, `as-strat-N`,
    /// `as-grid-N[-bB]`, `as-gridj-N[-bB]`.
    pub fn parse(s: &str) -> Result<Method, String> {
        let bad = || {
            format!("unknown method '{s}' (iso, bent-lg18, bent-filament, bent-khr, major-N[-bBETA][-kK][-cC], fis-N[-bB], fisb-N, cv-N, as-thesis-N, as-weighted-N, as-fis-N[-bB], as-strat-N, as-grid[j]-N[-bB])")
        };
        let taps = |t: &str| -> Result<usize, String> {
            let n: usize = t.parse().map_err(|_| bad())?;
            if (1..=256).contains(&n) {
                Ok(n)
            } else {
                Err(format!("method '{s}': taps must be in 1..=256"))
            }
        };
        match s {
            "iso" => Ok(Method::Iso),
            "bent-lg18" => Ok(Method::BentLg18),
            "bent-filament" => Ok(Method::BentFilament),
            "bent-khr" => Ok(Method::BentKhr),
            _ => {
                if let Some(rest) = s.strip_prefix("fis-") {
                    let (n, lod_bias) = match rest.split_once("-b") {
                        Some((n, b)) => (n, lod_bias(b).ok_or_else(bad)?),
                        None => (rest, KC_LOD_BIAS),
                    };
                    return Ok(Method::Fis {
                        taps: taps(n)?,
                        lod_bias,
                    });
                }
                if let Some(rest) = s.strip_prefix("fisb-") {
                    return Ok(Method::FisBlend { taps: taps(rest)? });
                }
                if let Some(rest) = s.strip_prefix("cv-") {
                    return Ok(Method::Cv { taps: taps(rest)? });
                }
                if let Some(rest) = s.strip_prefix("as-thesis-") {
                    return Ok(Method::AsThesis { taps: taps(rest)? });
                }
                if let Some(rest) = s.strip_prefix("as-fis-") {
                    let (n, bias) = match rest.split_once("-b") {
                        Some((n, b)) => (n, lod_bias(b).ok_or_else(bad)?),
                        None => (rest, KC_LOD_BIAS),
                    };
                    return Ok(Method::AsFis {
                        taps: taps(n)?,
                        bias: Some(bias),
                    });
                }
                if let Some(rest) = s.strip_prefix("as-quad-") {
                    let (n, mut opts) = rest.split_at(rest.find('-').unwrap_or(rest.len()));
                    let (mut bias, mut k) = (0.0, AS_QUAD_K);
                    while let Some(o) = opts.strip_prefix('-') {
                        let key = o.chars().next().ok_or_else(bad)?;
                        let body = &o[1..];
                        // A number, its own leading '-' included, up to the next '-'.
                        let end = body
                            .char_indices()
                            .skip(1)
                            .find(|&(_, c)| c == '-')
                            .map_or(body.len(), |(i, _)| i);
                        let (num, tail) = body.split_at(end);
                        match key {
                            'b' => bias = lod_bias(num).ok_or_else(bad)?,
                            'k' => {
                                k = num
                                    .parse::<f32>()
                                    .ok()
                                    .filter(|x| x.is_finite() && (0.5..=6.0).contains(x))
                                    .ok_or_else(bad)?
                            }
                            _ => return Err(bad()),
                        }
                        opts = tail;
                    }
                    return Ok(Method::AsQuad {
                        taps: taps(n)?,
                        bias,
                        k,
                    });
                }
                for (prefix, jitter) in [("as-grid-", false), ("as-gridj-", true)] {
                    if let Some(rest) = s.strip_prefix(prefix) {
                        let (n, bias) = match rest.split_once("-b") {
                            Some((n, b)) => (n, lod_bias(b).ok_or_else(bad)?),
                            None => (rest, 0.0),
                        };
                        return Ok(Method::AsGrid {
                            taps: taps(n)?,
                            bias,
                            jitter,
                        });
                    }
                }
                if let Some(rest) = s.strip_prefix("as-strat-") {
                    return Ok(Method::AsFis {
                        taps: taps(rest)?,
                        bias: None,
                    });
                }
                if let Some(rest) = s.strip_prefix("as-weighted-") {
                    return Ok(Method::AsWeighted { taps: taps(rest)? });
                }
                let rest = s.strip_prefix("major-").ok_or_else(bad)?;
                let mut parts = rest.split('-');
                let mut p = major_axis::Params {
                    taps: taps(parts.next().unwrap_or(""))?,
                    ..Default::default()
                };
                for part in parts {
                    let num = |x: &str| -> Result<f32, String> {
                        x.parse::<f32>()
                            .ok()
                            .filter(|v| v.is_finite() && *v > 0.0)
                            .ok_or_else(bad)
                    };
                    if let Some(b) = part.strip_prefix('b') {
                        p.beta = num(b)?;
                    } else if let Some(k) = part.strip_prefix('k') {
                        p.k = num(k)?;
                    } else if let Some(c) = part.strip_prefix('c') {
                        p.c = num(c)?;
                    } else {
                        return Err(bad());
                    }
                }
                Ok(Method::MajorAxis(p))
            }
        }
    }

    /// Cube taps and 2D-table taps per pixel.
    pub fn taps(&self) -> (usize, usize) {
        match self {
            Method::Iso | Method::BentLg18 | Method::BentFilament | Method::BentKhr => (1, 1),
            Method::MajorAxis(p) => (p.taps, 1),
            Method::Fis { taps, .. } => (*taps, 0),
            Method::Cv { taps } => (2 * *taps + 1, 1),
            Method::FisBlend { taps } => (*taps + 1, 1),
            Method::AsThesis { taps } => (*taps, *taps + 1),
            Method::AsWeighted { taps } | Method::AsFis { taps, .. } => (*taps, *taps),
            Method::AsGrid { taps, .. } | Method::AsQuad { taps, .. } => (*taps, *taps),
        }
    }

    /// Whether the method reads the chain (and so runs with both lookups).
    pub fn reads_chain(&self) -> bool {
        !matches!(
            self,
            Method::Fis { .. }
                | Method::AsThesis { .. }
                | Method::AsWeighted { .. }
                | Method::AsFis { .. }
                | Method::AsGrid { .. }
                | Method::AsQuad { .. }
        )
    }

    /// Whether the method renders `mat` (the GGX methods GGX, the thesis route AS).
    pub fn applies_to(&self, mat: &Material) -> bool {
        match self {
            Method::AsThesis { .. }
            | Method::AsWeighted { .. }
            | Method::AsFis { .. }
            | Method::AsGrid { .. }
            | Method::AsQuad { .. } => matches!(mat, Material::AshikhminShirley { .. }),
            _ => matches!(mat, Material::Ggx { .. }),
        }
    }
}

/// What every method may read.
pub struct Inputs<'a> {
    /// The chain lookup.
    pub lookup: &'a Lookup,
    /// The DFG table (A, B) at (n·v, perceptual roughness).
    pub dfg: &'a Dfg,
    /// The box pyramid of the source, for filtered importance sampling.
    pub pyramid: &'a BorderedMips,
    /// The raw source cube (the thesis's route reads it bilinearly).
    pub cube: &'a Cubemap,
    /// The Ashikhmin–Shirley tables of the case's lobe, if it is one.
    pub as_tables: Option<&'a AsTables>,
}

/// (E0, E1) of one pixel (defined in [`crate::ship`], whose shading returns it, so `ship`
/// needs nothing of `methods`).
pub use crate::ship::E01;

fn split(l: Rgb, dfg: &Dfg, nv: f32, r: f32) -> E01 {
    let (a, b) = dfg.ab(nv, r);
    (l.map(|c| c * (a + b)), l.map(|c| c * b))
}

/// cross(cross(g, v), g): the normal facing v perpendicular to the grain direction g
/// (HDRP `ComputeGrainNormal`, Filament's `anisotropicNormal`).
fn grain_normal(grain: Vec3, v: Vec3) -> Vec3 {
    grain.cross(v).cross(grain)
}

fn lerp(a: Vec3, b: Vec3, t: f32) -> Vec3 {
    a + (b - a) * t
}

fn reflect_view(v: Vec3, n: Vec3) -> Vec3 {
    2.0 * v.dot(n) * n - v
}

fn saturate(x: f32) -> f32 {
    x.clamp(0.0, 1.0)
}

/// Evaluates `method` at one pixel (frame, view v towards the eye, material); `seed` fixes the
/// per-pixel rotation of stochastic methods.
pub fn evaluate(
    method: &Method,
    inp: &Inputs,
    frame: &Frame,
    v: Vec3,
    mat: &Material,
    seed: u64,
    buf: &mut TreeBuffers,
) -> E01 {
    let n = frame.n;
    let nv = n.dot(v);
    if nv <= 0.0 {
        return ([0.0; 3], [0.0; 3]);
    }
    if let (Method::AsThesis { taps } | Method::AsWeighted { taps }, Some(tab)) =
        (method, inp.as_tables)
    {
        let weighted = matches!(method, Method::AsWeighted { .. });
        return as_route(inp.cube, tab, frame, v, *taps, weighted);
    }
    if let (Method::AsFis { taps, bias }, Some(tab)) = (method, inp.as_tables) {
        let rot = fis_rotation(seed);
        return as_fis(inp.pyramid, tab, frame, v, *taps, *bias, rot);
    }
    if let (Method::AsGrid { taps, bias, jitter }, Some(tab)) = (method, inp.as_tables) {
        let shift = jitter.then(|| fis_rotation(seed));
        return as_grid(inp.pyramid, tab, frame, v, *taps, *bias, shift);
    }
    if let (Method::AsQuad { taps, bias, k }, Some(tab)) = (method, inp.as_tables) {
        return as_quad(inp.pyramid, tab, frame, v, *taps, *bias, *k);
    }
    let Some((at, ab)) = mat.ggx_alphas() else {
        return ([0.0; 3], [0.0; 3]);
    };
    let r_iso = iso_roughness(at, ab);
    // Kulla–Conty η and the engines' grain direction: b when α_t ≥ α_b (η ≥ 0), else t.
    let eta = if at + ab > 0.0 {
        (at - ab) / (at + ab)
    } else {
        0.0
    };
    let grain = if eta >= 0.0 { frame.b } else { frame.t };
    match method {
        Method::Iso => {
            let l = inp.lookup.radiance(reflect_view(v, n), r_iso, buf);
            split(l, inp.dfg, nv, r_iso)
        }
        Method::BentLg18 => {
            // Unity-Technologies/Graphics
            // `Packages/com.unity.render-pipelines.core/ShaderLibrary/ImageBasedLighting.hlsl`
            // (`GetGGXAnisotropicModifiedNormalAndRoughness`, `GetAnisotropicModifiedNormal`):
            // stretch = |η|·sat(1.5√r), n' = normalize(lerp(n, grain normal, stretch)),
            // r' = r·sat(1.2 − |η|); DFG at r (Lagarde & Golubev 2018).
            let stretch = eta.abs() * saturate(1.5 * r_iso.sqrt());
            let nb = lerp(n, grain_normal(grain, v), stretch).normalize();
            let rb = r_iso * saturate(1.2 - eta.abs());
            let l = inp.lookup.radiance(reflect_view(v, nb), rb, buf);
            split(l, inp.dfg, nv, r_iso)
        }
        Method::BentFilament => {
            // google/filament `shaders/src/surface_lighting.fs` (`getReflectedVector`):
            // bendFactor = |η|·sat(5·perceptualRoughness), bentNormal =
            // normalize(mix(n, anisotropicNormal, bendFactor)), r = reflect(−v, bentNormal);
            // the chain read at the material's roughness.
            let bend = eta.abs() * saturate(5.0 * r_iso);
            let nb = lerp(n, grain_normal(grain, v), bend).normalize();
            let l = inp.lookup.radiance(reflect_view(v, nb), r_iso, buf);
            split(l, inp.dfg, nv, r_iso)
        }
        Method::BentKhr => {
            // KhronosGroup/glTF-Sample-Viewer `source/Renderer/shaders/ibl.glsl`
            // (`getIBLRadianceAnisotropy`): the material in KHR form (r_k = √α_b, s), the
            // grain normal of the bitangent, a = (1 − s(1 − r_k))⁴,
            // bentNormal = normalize(mix(anisotropicNormal, n, a)); lod and DFG at r_k.
            let (hi, lo) = if at >= ab { (at, ab) } else { (ab, at) };
            let (rk, s) = crate::material::khr_inverse(hi, lo);
            let bend = 1.0 - s * (1.0 - rk);
            let a = bend * bend * bend * bend;
            let nb = lerp(grain_normal(grain, v), n, a).normalize();
            let l = inp.lookup.radiance(reflect_view(v, nb), rk, buf);
            split(l, inp.dfg, nv, rk)
        }
        Method::MajorAxis(p) => {
            // Eq. 5: the DFG at h1 = √((α_t+α_b)/2), the mean of N taps at one lod.
            let o = frame.to_local(v).normalize();
            let s2 = std::f32::consts::SQRT_2;
            let (dirs, r) = major_axis::taps(o, at / s2, ab / s2, p);
            let mut acc = [0.0f32; 3];
            for d in &dirs {
                let c = inp.lookup.radiance(frame.to_world(*d), r, buf);
                for k in 0..3 {
                    acc[k] += c[k];
                }
            }
            let inv = 1.0 / dirs.len() as f32;
            split(acc.map(|c| c * inv), inp.dfg, nv, r_iso)
        }
        Method::Fis { taps, lod_bias } => {
            fis(inp.pyramid, frame, v, at, ab, *taps, *lod_bias, seed)
        }
        Method::FisBlend { taps } => {
            let l = inp.lookup.radiance(reflect_view(v, n), r_iso, buf);
            let iso = split(l, inp.dfg, nv, r_iso);
            let rot = fis_rotation(seed);
            crate::ship::shade_blend_n(inp.pyramid, frame, v, at, ab, *taps as u32, rot, iso)
        }
        Method::Cv { taps } => {
            let l = inp.lookup.radiance(reflect_view(v, n), r_iso, buf);
            let base = split(l, inp.dfg, nv, r_iso);
            let a_iso = r_iso * r_iso;
            let an = fis(inp.pyramid, frame, v, at, ab, *taps, KC_LOD_BIAS, seed);
            let is = fis(
                inp.pyramid,
                frame,
                v,
                a_iso,
                a_iso,
                *taps,
                KC_LOD_BIAS,
                seed,
            );
            let cv = |b: [f32; 3], x: [f32; 3], y: [f32; 3]| -> [f32; 3] {
                std::array::from_fn(|k| (b[k] + (x[k] - y[k])).max(0.0))
            };
            (cv(base.0, an.0, is.0), cv(base.1, an.1, is.1))
        }
        Method::AsThesis { .. }
        | Method::AsWeighted { .. }
        | Method::AsFis { .. }
        | Method::AsGrid { .. }
        | Method::AsQuad { .. } => ([0.0; 3], [0.0; 3]),
    }
}

/// Marcolongo 2020 §4.3 (`env_bump_aniso.frag`): N fixed Hammersley points, h from the
/// half-vector LUT (bilinear), l = 2(v·h)h − v, the raw cube read bilinearly; as written the
/// mean radiance (with the 1/N the thesis omits, README errata) times F0·s + b of the size/bias
/// table; weighted, each tap times F(v·h)(n·l)/max(n·v, n·l) and no table.
fn as_route(
    cube: &Cubemap,
    tab: &AsTables,
    frame: &Frame,
    v: Vec3,
    taps: usize,
    weighted: bool,
) -> E01 {
    let vl = frame.to_local(v).normalize();
    let (mut e0, mut e1) = ([0.0f32; 3], [0.0f32; 3]);
    let n = taps as u32;
    for i in 0..n {
        let (x1, x2) = hammersley(i, n);
        let (h, _) = ibl_lut::hv::lookup(&tab.hv, x1 as f64, x2 as f64);
        let h = h.as_vec3();
        let vh = vl.dot(h);
        let l = 2.0 * vh * h - vl;
        // The thesis's shader reads every tap, below the horizon too: the size/bias table
        // holds the horizon's loss. The weighted estimator gives such taps weight 0.
        if weighted && (vh <= 0.0 || l.z <= 0.0) {
            continue;
        }
        let c = cube.sample_bilinear(frame.to_world(l));
        let (w, chi) = if weighted {
            (l.z / vl.z.max(l.z), (1.0 - vh.min(1.0)).powi(5))
        } else {
            (1.0, 0.0)
        };
        for k in 0..3 {
            e0[k] += w * c[k];
            e1[k] += w * chi * c[k];
        }
    }
    let inv = 1.0 / n as f32;
    if weighted {
        (e0.map(|c| c * inv), e1.map(|c| c * inv))
    } else {
        let (s, b) = tab.size_bias_at(vl);
        (e0.map(|c| c * inv * (s + b)), e0.map(|c| c * inv * b))
    }
}

/// `as-fis-N`: Ashikhmin–Shirley by the baked half-vector LUT, stratified per pixel and
/// filtered. Taps h from the LUT at the rotated Hammersley point (bilinear: the inverse CDF of
/// p_h, so each of the N cells of the point set holds 1/N of p_h's mass), l = reflect(v, h),
/// weight F(v·h)(n·l)/max(n·v, n·l) (exact p_h importance sampling), the box pyramid read at
/// lod ½(log2(1/(N p_l)) − log2 Ω_texel) + 1 with p_l = A·p_h(n)/(4 v·h).
fn as_fis(
    pyr: &BorderedMips,
    tab: &AsTables,
    frame: &Frame,
    v: Vec3,
    taps: usize,
    bias: Option<f32>,
    rotation: glam::Vec2,
) -> E01 {
    let vl = frame.to_local(v).normalize();
    if vl.z <= 0.0 || taps == 0 {
        return ([0.0; 3], [0.0; 3]);
    }
    let n = taps as u32;
    let mut acc = AsTaps::new(pyr, tab, frame, vl, n, bias);
    for i in 0..n {
        let (x1, x2) = hammersley(i, n);
        let u = glam::Vec2::new(x1, x2) + rotation;
        let u = u - u.floor();
        acc.tap(u.x as f64, u.y as f64);
    }
    acc.finish()
}

/// `as-grid[j]-N[-bB]` ([`Method::AsGrid`]): the shipped steps ([`crate::ship_as::shade`])
/// on the grid [`crate::ship_as::grid_shape`] gives for the lobe and N.
fn as_grid(
    pyr: &BorderedMips,
    tab: &AsTables,
    frame: &Frame,
    v: Vec3,
    taps: usize,
    bias: f32,
    shift: Option<glam::Vec2>,
) -> E01 {
    let (nu, nv) = tab.exponents;
    let lobe = crate::ship_as::Lobe {
        lut: &tab.hv,
        pdf_h_n: tab.pdf_h_n as f32,
        grid: crate::ship_as::grid_shape(nu, nv, taps),
    };
    crate::ship_as::shade(pyr, &lobe, frame, v, bias, shift)
}

/// The default half-width K of `as-quad-N`'s square, in standard deviations.
pub const AS_QUAD_K: f32 = 2.5;

/// `as-quad-N[-bB][-kK]` ([`Method::AsQuad`]).
fn as_quad(
    pyr: &BorderedMips,
    tab: &AsTables,
    frame: &Frame,
    v: Vec3,
    taps: usize,
    bias: f32,
    k: f32,
) -> E01 {
    let vl = frame.to_local(v).normalize();
    if vl.z <= 0.0 || taps == 0 {
        return ([0.0; 3], [0.0; 3]);
    }
    let (a, b) = crate::ship_as::grid_shape(tab.exponents.0, tab.exponents.1, taps);
    let cells_x = quad_cells(a, k as f64);
    let cells_y = quad_cells(b, k as f64);
    let log2_sa = pyr.base_log2_texel_solid_angle();
    let max_lod = pyr.max_lod() as f32;
    let (mut e0, mut e1) = (Vec3::ZERO, Vec3::ZERO);
    for &(gx, dx, mx) in &cells_x {
        for &(gy, dy, my) in &cells_y {
            let (xi1, xi2) = crate::ship_as::gaussian_to_xi(gx as f32, gy as f32);
            let (h, ratio) = ibl_lut::hv::lookup(&tab.hv, xi1 as f64, xi2 as f64);
            let h = h.as_vec3().normalize();
            let vh = vl.dot(h);
            let l = 2.0 * vh * h - vl;
            if vh <= 0.0 || l.z <= 0.0 || ratio <= 0.0 {
                continue;
            }
            // dω_h/dg = p_g(g)/p_h(h); dω_l = 4 (v·h) dω_h.
            let p_g = (-(gx * gx + gy * gy) * 0.5).exp() / std::f64::consts::TAU;
            let p_h = ratio * tab.pdf_h_n;
            let omega = (dx * dy * p_g / p_h) as f32 * 4.0 * vh;
            let lod = (0.5 * (omega.log2() - log2_sa) + bias).clamp(0.0, max_lod);
            let c = Vec3::from(pyr.sample(frame.to_world(l), lod));
            let w = (mx * my) as f32 * l.z / vl.z.max(l.z);
            let chi = (1.0 - vh.min(1.0)).powi(5);
            e0 += w * c;
            e1 += w * chi * c;
        }
    }
    (e0.into(), e1.into())
}

/// `as-quad`'s cells along one axis of the Gaussian plane: m equal cells over [−K, K], each
/// (centre, width, mass of N(0, 1)), the first and last also holding the tails beyond ±K.
pub(crate) fn quad_cells(m: usize, k: f64) -> Vec<(f64, f64, f64)> {
    let phi = |x: f64| 0.5 * ibl_brdf::special::erfc(-x * std::f64::consts::FRAC_1_SQRT_2);
    let w = 2.0 * k / m as f64;
    (0..m)
        .map(|i| {
            let lo = -k + i as f64 * w;
            let hi = lo + w;
            let p_lo = if i == 0 { 0.0 } else { phi(lo) };
            let p_hi = if i + 1 == m { 1.0 } else { phi(hi) };
            (lo + 0.5 * w, w, p_hi - p_lo)
        })
        .collect()
}

/// The weighted, filtered Ashikhmin–Shirley taps of `as-fis`: h from the LUT at
/// (ξ1, ξ2), l = reflect(v, h), weight F(v·h)(n·l)/max(n·v, n·l) (exact p_h importance
/// sampling), the box pyramid read at lod ½(log2(1/(N p_l)) − log2 Ω_texel) + B with
/// p_l = A·p_h(n)/(4 v·h) (Křivánek & Colbert 2008 eq. 13), or the raw cube without a bias.
struct AsTaps<'a> {
    pyr: &'a BorderedMips,
    tab: &'a AsTables,
    frame: &'a Frame,
    vl: Vec3,
    n: u32,
    bias: Option<f32>,
    log2_sa: f32,
    max_lod: f32,
    e0: Vec3,
    e1: Vec3,
}

impl<'a> AsTaps<'a> {
    fn new(
        pyr: &'a BorderedMips,
        tab: &'a AsTables,
        frame: &'a Frame,
        vl: Vec3,
        n: u32,
        bias: Option<f32>,
    ) -> Self {
        AsTaps {
            pyr,
            tab,
            frame,
            vl,
            n,
            bias,
            log2_sa: pyr.base_log2_texel_solid_angle(),
            max_lod: pyr.max_lod() as f32,
            e0: Vec3::ZERO,
            e1: Vec3::ZERO,
        }
    }

    fn tap(&mut self, xi1: f64, xi2: f64) {
        let (h, a) = ibl_lut::hv::lookup(&self.tab.hv, xi1, xi2);
        let h = h.as_vec3().normalize();
        let vl = self.vl;
        let vh = vl.dot(h);
        let l = 2.0 * vh * h - vl;
        if vh <= 0.0 || l.z <= 0.0 {
            return;
        }
        let pl = (a * self.tab.pdf_h_n) as f32 / (4.0 * vh);
        let lod = match self.bias {
            None => 0.0,
            Some(_) if pl <= 0.0 => self.max_lod,
            Some(b) => {
                (0.5 * (-(self.n as f32 * pl).log2() - self.log2_sa) + b).clamp(0.0, self.max_lod)
            }
        };
        let c = Vec3::from(self.pyr.sample(self.frame.to_world(l), lod));
        let w = l.z / vl.z.max(l.z);
        let chi = (1.0 - vh.min(1.0)).powi(5);
        self.e0 += w * c;
        self.e1 += w * chi * c;
    }

    fn finish(self) -> E01 {
        let inv = 1.0 / self.n as f32;
        ((self.e0 * inv).into(), (self.e1 * inv).into())
    }
}

/// VNDF filtered importance sampling (`fis-N`): the shipped method's emulation
/// ([`crate::ship`]) at N taps, with a per-pixel Cranley–Patterson rotation drawn from `seed`.
#[allow(clippy::too_many_arguments)]
fn fis(
    pyr: &BorderedMips,
    frame: &Frame,
    v: Vec3,
    at: f32,
    ab: f32,
    taps: usize,
    lod_bias: f32,
    seed: u64,
) -> E01 {
    let rot = fis_rotation(seed);
    crate::ship::shade_n(pyr, frame, v, at, ab, taps as u32, rot, lod_bias)
}

/// The per-pixel rotation of `fis-N` at `seed`.
pub(crate) fn fis_rotation(seed: u64) -> glam::Vec2 {
    let mut rng = Pcg32::new(seed, 0xf15);
    let (s1, s2) = (rng.next_f32(), rng.next_f32());
    glam::Vec2::new(s1, s2)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::CubeMips;

    fn inputs_const() -> (Lookup, Dfg, BorderedMips) {
        let cube = Cubemap::constant(16, [1.0; 3]);
        let lookup = Lookup::Engine {
            chain: BorderedMips::new(&CubeMips::build(cube.clone(), 4)),
            mapping: LodMapping::Linear,
        };
        let dfg = ibl_shexp::dfg::Dfg::standard().clone();
        let pyr = BorderedMips::new(&CubeMips::build(cube, 1));
        (lookup, dfg, pyr)
    }

    fn frame() -> Frame {
        let n = Vec3::new(0.1, 0.3, 0.9).normalize();
        let t = Vec3::Y.cross(n).normalize();
        Frame {
            t,
            b: n.cross(t),
            n,
        }
    }

    #[test]
    fn furnace_every_split_sum_method_equals_its_dfg() {
        // Constant environment: every chain method returns exactly its DFG term (A+B, B).
        let (lookup, dfg, pyr) = inputs_const();
        let cube0 = Cubemap::constant(4, [1.0; 3]);
        let inp = Inputs {
            lookup: &lookup,
            dfg: &dfg,
            pyramid: &pyr,
            cube: &cube0,
            as_tables: None,
        };
        let f = frame();
        let v = f.to_world(Vec3::new(0.5, 0.2, 0.8).normalize());
        let mat = Material::ggx_kc(0.6, 0.7);
        let mut buf = TreeBuffers::default();
        for m in [
            Method::Iso,
            Method::BentLg18,
            Method::BentFilament,
            Method::MajorAxis(Default::default()),
        ] {
            let (e0, e1) = evaluate(&m, &inp, &f, v, &mat, 1, &mut buf);
            let (a, b) = dfg.ab(f.n.dot(v), 0.6);
            assert!(
                (e0[0] - (a + b)).abs() < 1e-3 && (e1[0] - b).abs() < 1e-3,
                "{m:?} {e0:?} {a} {b}"
            );
        }
    }

    #[test]
    fn methods_are_symmetric_under_tangent_flip_and_axis_swap() {
        let cube = Cubemap::from_fn(16, |d| [1.0 + d.x, 1.0 + 0.5 * d.y, 1.0 + d.z * d.x]);
        let lookup = Lookup::Engine {
            chain: BorderedMips::new(&CubeMips::build(cube.clone(), 4)),
            mapping: LodMapping::Linear,
        };
        let dfg = ibl_shexp::dfg::Dfg::standard().clone();
        let pyr = BorderedMips::new(&CubeMips::build(cube, 1));
        let cube0 = Cubemap::constant(4, [1.0; 3]);
        let inp = Inputs {
            lookup: &lookup,
            dfg: &dfg,
            pyramid: &pyr,
            cube: &cube0,
            as_tables: None,
        };
        let f = frame();
        let v = f.to_world(Vec3::new(0.4, -0.3, 0.7).normalize());
        let mat = Material::ggx_kc(0.5, 0.8);
        let (at, ab) = mat.ggx_alphas().unwrap();
        let swapped = Material::Ggx {
            alpha_t: ab,
            alpha_b: at,
        };
        let mut buf = TreeBuffers::default();
        for m in [
            Method::Iso,
            Method::BentLg18,
            Method::BentFilament,
            Method::BentKhr,
            Method::MajorAxis(Default::default()),
        ] {
            let a = evaluate(&m, &inp, &f, v, &mat, 1, &mut buf);
            let b = evaluate(&m, &inp, &f.flipped(), v, &mat, 1, &mut buf);
            let c = evaluate(&m, &inp, &f.turned(), v, &swapped, 1, &mut buf);
            for k in 0..3 {
                assert!(
                    (a.0[k] - b.0[k]).abs() < 1e-4 * a.0[k].abs().max(1.0),
                    "{m:?} flip {a:?} {b:?}"
                );
                assert!(
                    (a.0[k] - c.0[k]).abs() < 1e-4 * a.0[k].abs().max(1.0),
                    "{m:?} swap {a:?} {c:?}"
                );
            }
        }
    }

    #[test]
    fn as_fis_pdf_from_the_lut_is_the_exact_p_h() {
        // The lod of as-fis-N reads p_h as the LUT's A channel times p_h(n): check it against
        // ibl-brdf's closed form at the LUT's own taps (bilinear: a few percent at most).
        for (nu, nv) in [(100.0, 10.0), (20.0, 700.0)] {
            let tab = AsTables::bake(nu, nv, 128);
            let a = ibl_brdf::AshikhminShirley::new(nu, nv);
            let mut worst = 0.0f64;
            for i in 0..64u32 {
                let (x1, x2) = hammersley(i, 64);
                let (h, q) = ibl_lut::hv::lookup(&tab.hv, x1 as f64, x2 as f64);
                let h = h.normalize();
                let exact = a.pdf_h(h);
                worst = worst.max((q * tab.pdf_h_n - exact).abs() / exact.max(1e-9));
            }
            assert!(worst < 0.1, "({nu}, {nv}): {worst}");
        }
    }

    #[test]
    fn as_routes_agree_with_each_other_and_the_truth_under_a_constant_environment() {
        let cube = Cubemap::constant(8, [1.0; 3]);
        let (lookup, dfg, pyr) = inputs_const();
        let tab = AsTables::bake(100.0, 10.0, 128);
        let inp = Inputs {
            lookup: &lookup,
            dfg: &dfg,
            pyramid: &pyr,
            cube: &cube,
            as_tables: Some(&tab),
        };
        let f = frame();
        let mat = Material::AshikhminShirley {
            nu: 100.0,
            nv: 10.0,
        };
        let mut buf = TreeBuffers::default();
        for (x, y) in [(0.0f32, 0.0f32), (0.5, 0.3), (-0.7, 0.5)] {
            let v = f.to_world(Vec3::new(x, y, 1.0).normalize());
            let a = evaluate(
                &Method::AsThesis { taps: 256 },
                &inp,
                &f,
                v,
                &mat,
                1,
                &mut buf,
            );
            let b = evaluate(
                &Method::AsWeighted { taps: 256 },
                &inp,
                &f,
                v,
                &mat,
                1,
                &mut buf,
            );
            let t = crate::truth::mc_truth(&cube, &f, v, &mat, 4096, 3);
            eprintln!(
                "view ({x}, {y}): thesis {:.4} weighted {:.4} truth {:.4} ± {:.4}",
                a.0[0], b.0[0], t.e0[0], t.se0[0]
            );
            // As written, the thesis's E0 is (s + b): the same expectation as M4b's weight.
            assert!((a.0[0] - b.0[0]).abs() < 0.01, "{a:?} {b:?}");
            // Stratified, filtered taps: the same estimator (the pyramid of a constant is
            // constant), so the same expectation.
            // The lobe-shaped grids and the weighted quadrature: the same expectation at 32
            // taps (a constant environment is the directional albedo), within the error of a
            // 32-point rule in two dimensions.
            for name in ["as-grid-32", "as-quad-32"] {
                let g = evaluate(
                    &Method::parse(name).unwrap(),
                    &inp,
                    &f,
                    v,
                    &mat,
                    1,
                    &mut buf,
                );
                assert!((g.0[0] - b.0[0]).abs() < 0.02, "{name}: {g:?} {b:?}");
                assert!((g.1[0] - b.1[0]).abs() < 0.01, "{name}: {g:?} {b:?}");
            }
            // The shifted grid is unbiased: its mean over pixels' shifts.
            let gj = Method::parse("as-gridj-32").unwrap();
            let mean = (0..64)
                .map(|seed| evaluate(&gj, &inp, &f, v, &mat, seed, &mut buf).0[0])
                .sum::<f32>()
                / 64.0;
            assert!((mean - b.0[0]).abs() < 0.01, "as-gridj-32: {mean} {b:?}");
            let fis = Method::parse("as-fis-256").unwrap();
            let c = evaluate(&fis, &inp, &f, v, &mat, 1, &mut buf);
            assert!((c.0[0] - b.0[0]).abs() < 0.01, "{c:?} {b:?}");
            assert!((c.1[0] - b.1[0]).abs() < 0.005, "{c:?} {b:?}");
            assert!(
                (b.0[0] as f64 - t.e0[0]).abs() < 0.02 + 4.0 * t.se0[0],
                "{b:?} {t:?}"
            );
            assert!(
                (b.1[0] as f64 - t.e1[0]).abs() < 0.01 + 4.0 * t.se1[0],
                "{b:?} {t:?}"
            );
        }
    }

    #[test]
    fn parses_method_names() {
        assert_eq!(
            Method::parse("major-16").unwrap(),
            Method::MajorAxis(Default::default())
        );
        let m = Method::parse("major-8-b1.5-k2").unwrap();
        assert_eq!(m.name(), "major-8-b1.5-k2");
        assert_eq!(
            Method::parse("major-16-c1.4").unwrap().name(),
            "major-16-c1.4"
        );
        assert_eq!(
            Method::parse("fis-32").unwrap(),
            Method::Fis {
                taps: 32,
                lod_bias: KC_LOD_BIAS
            }
        );
        assert_eq!(Method::parse("cv-8").unwrap(), Method::Cv { taps: 8 });
        for n in [
            "as-fis-32",
            "as-fis-32-b0",
            "as-fis-16-b-1",
            "as-strat-32",
            "fisb-16",
            "fis-16-b0",
            "fis-16-b0.25",
            "fis-8-b-0.5",
        ] {
            assert_eq!(Method::parse(n).unwrap().name(), n);
        }
        assert!(Method::parse("as-fis-32-bx").is_err() && Method::parse("as-fis-32-b99").is_err());
        assert!(Method::parse("fis-16-bx").is_err() && Method::parse("fis-16-bNaN").is_err());
        // `fis-N-b1` is Křivánek & Colbert's own bias: the published `fis-N`.
        assert_eq!(Method::parse("fis-16-b1").unwrap().name(), "fis-16");
        assert_eq!(Method::Cv { taps: 8 }.taps(), (17, 1));
        for bad in ["major-0", "major-x", "fis-", "bent", "major-4-q1"] {
            assert!(Method::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn control_variate_is_exactly_the_isotropic_floor_at_eta_zero() {
        // A non-constant environment, so that FIS and the split sum differ: at η = 0 the two
        // FIS sums cancel bit for bit; at η = 0.8 the correction is non-zero.
        let cube = Cubemap::from_fn(16, |d| [1.0 + 4.0 * d.x.max(0.0), d.y.abs(), 0.3]);
        let lookup = Lookup::Engine {
            chain: BorderedMips::new(&CubeMips::build(cube.clone(), 4)),
            mapping: LodMapping::Linear,
        };
        let dfg = ibl_shexp::dfg::Dfg::standard().clone();
        let pyr = BorderedMips::new(&CubeMips::build(cube.clone(), 1));
        let inp = Inputs {
            lookup: &lookup,
            dfg: &dfg,
            pyramid: &pyr,
            cube: &cube,
            as_tables: None,
        };
        let f = frame();
        let v = f.to_world(Vec3::new(0.5, 0.2, 0.8).normalize());
        let mut buf = TreeBuffers::default();
        for r in [0.05, 0.3, 0.7, 1.0] {
            let mat = Material::ggx_kc(r, 0.0);
            let iso = evaluate(&Method::Iso, &inp, &f, v, &mat, 5, &mut buf);
            let cv = evaluate(&Method::Cv { taps: 8 }, &inp, &f, v, &mat, 5, &mut buf);
            assert_eq!(iso, cv, "r {r}");
            let mat = Material::ggx_kc(r, 0.8);
            let iso = evaluate(&Method::Iso, &inp, &f, v, &mat, 5, &mut buf);
            let cv = evaluate(&Method::Cv { taps: 8 }, &inp, &f, v, &mat, 5, &mut buf);
            assert_ne!(iso, cv, "r {r}");
        }
    }
    #[test]
    fn quadrature_cells_hold_all_the_mass() {
        for m in [1, 2, 5, 32] {
            let cells = quad_cells(m, 2.5);
            let mass: f64 = cells.iter().map(|c| c.2).sum();
            assert!((mass - 1.0).abs() < 1e-12, "{m}: {mass}");
            for (c, d) in cells.iter().zip(cells.iter().rev()) {
                assert!((c.0 + d.0).abs() < 1e-12 && (c.2 - d.2).abs() < 1e-6);
            }
        }
    }
}
