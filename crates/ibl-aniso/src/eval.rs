//! The `aniso-eval` evaluator: orthographic spheres of anisotropic GGX (r, η) under an
//! environment, seen from several azimuths and elevations, with a tangent field from a
//! `tpr-map` preset. Per case: the Monte Carlo truth with its standard error, every method
//! with the engine lookup and the oracle, and per F0 (1 and 0.04) the per-pixel relative error
//! of luminance e = |Ŷ−Y|/(Y+ε), ε = 0.01·mean(Y) (mean, 95th percentile, max), relRMSE =
//! √(Σ(Ŷ−Y)²/ΣY²) over pixels and channels, the MSE, and the wins against the LG18 bent
//! normal and the isotropic floor. A case is scored only when the truth's estimated mean
//! squared error is below 1% of the best method's MSE (`truth_error_share < 0.01`).

use crate::material::Material;
use crate::methods::{evaluate as eval_method, AsTables, Inputs, Lookup, Method, E01};
use crate::scene::{camera, plate_pixels, sphere_pixels, Field, Pixel, TprRoughness, UvMap};
use crate::truth::{mc_truth, TruthValue};
use ibl_core::bordered::BorderedMips;
use ibl_core::{luminance, CubeMips, Cubemap, Image};
use ibl_material::direction::Preset;
use ibl_prefilter::tree::TreeBuffers;
use ibl_shexp::dfg::Dfg;
use rayon::prelude::*;
use serde::Serialize;
use std::fmt::Write;
use std::path::PathBuf;

/// Which lookups chain-reading methods run with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LookupChoice {
    /// The target's chain read by its engine's lookup.
    Engine,
    /// The exact kernel at continuous roughness.
    Oracle,
    /// Both.
    Both,
}

/// The rendered object.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Scene {
    /// An orthographic unit sphere with ring tangents (turned by --tangent).
    Sphere,
    /// A perspective view of a flat disc (the frying pan), base tangent +X (turned by --tangent).
    Plate,
}

/// Parameters of the evaluation (CLI flags and RON keys alike).
#[derive(Clone, Debug, PartialEq, clap::Args, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// The object: an orthographic sphere, or a perspective plate seen from each azimuth and
    /// elevation (the view then varies per pixel).
    #[arg(long, value_enum, default_value_t = Scene::Sphere)]
    pub scene: Scene,
    /// Image size in pixels.
    #[arg(long, default_value_t = 32)]
    pub sphere_size: usize,
    /// Perceptual roughness values r (α = r²).
    #[arg(long, value_delimiter = ',', default_value = "0.2,0.5,0.8")]
    pub roughness: Vec<f32>,
    /// Kulla–Conty anisotropy values η in (−1, 1): α_t = r²(1+η), α_b = r²(1−η).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0,0.5,0.8,0.95",
        allow_negative_numbers = true
    )]
    pub eta: Vec<f32>,
    /// Camera azimuths in degrees about +Y.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0,90",
        allow_negative_numbers = true
    )]
    pub views: Vec<f32>,
    /// Camera elevations in degrees.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0,30",
        allow_negative_numbers = true
    )]
    pub elevations: Vec<f32>,
    /// Tangent field: a tpr-map preset (constant:DEG, linear:DEG, radial, spiral, wave)
    /// turning the sphere's ring tangent.
    #[arg(long, default_value = "constant:0")]
    pub tangent: String,
    /// A `tpr-map` output whose RG (the tangent's (x, y)·½ + ½, y up) turns the base tangent
    /// at the surface's UV, in place of the --tangent preset.
    #[arg(long, value_name = "FILE")]
    pub tpr_map: Option<std::path::PathBuf>,
    /// Take each pixel's anisotropic GGX lobe from the --tpr-map file's B and A channels (the
    /// roughness along t and along b, bilinearly at the surface's UV) instead of --roughness ×
    /// --eta: `r` for perceptual roughness (α = r², what tpr-map writes), `alpha` for α (tpr-map
    /// --store-alpha). One GGX case per view, reported at the map's mean lobe (r = √((ᾱ_t+ᾱ_b)/2),
    /// η = (ᾱ_t−ᾱ_b)/(ᾱ_t+ᾱ_b)); --as-lobes are unaffected.
    #[arg(long, value_enum, value_name = "UNITS")]
    pub tpr_roughness: Option<TprRoughness>,
    /// A `quat-map` output whose RGB (q·½ + ½) rotates each pixel's whole frame at the
    /// surface's UV: normals perturbed as the thesis's shader perturbs them.
    #[arg(long, value_name = "FILE")]
    pub quat_map: Option<std::path::PathBuf>,
    /// Methods: iso, bent-lg18, bent-filament, bent-khr, major-N[-bBETA][-kK][-cC], fis-N[-bB]
    /// (Křivánek & Colbert's lod bias +1, or B),
    /// fisb-N (the shipped blend), cv-N; for --as-lobes as-thesis-N, as-weighted-N,
    /// as-fis-N[-bB], as-strat-N, as-grid[j]-N[-bB] (equal-mass cells shaped to the lobe),
    /// as-quad-N[-bB][-kK] (equal-size cells, weighted). A lobe no listed method renders is
    /// skipped.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "iso,bent-lg18,bent-filament,bent-khr,major-16,fis-16"
    )]
    pub methods: Vec<String>,
    /// Ashikhmin–Shirley lobes NUxNV (e.g. 100x10,20000x70), rendered with the truth and the
    /// as-thesis-N / as-weighted-N methods.
    #[arg(long, value_delimiter = ',')]
    pub as_lobes: Vec<String>,
    /// Lookups the chain-reading methods run with.
    #[arg(long, value_enum, default_value_t = LookupChoice::Both)]
    pub lookup: LookupChoice,
    /// Monte Carlo samples per pixel of the truth.
    #[arg(long, default_value_t = 4096)]
    pub truth_samples: u32,
    /// Level-0 face size of the chain baked when no --prefiltered chain is given (default:
    /// the truth cube's face size, at most 256: a larger chain than the source only upsamples).
    #[arg(long, value_name = "N")]
    pub chain_size: Option<usize>,
    /// Engine whose lod mapping reads the chain (and whose chain is baked).
    #[arg(long, value_enum, default_value_t = ibl_target::Target::Gltf)]
    pub target: ibl_target::Target,
    /// Cube face size the environment is resampled to for the truth (default: its natural size).
    #[arg(long, value_name = "N")]
    pub size: Option<usize>,
    /// Skip the per-case EXR files (frames, truth, every method's radiance).
    #[arg(long)]
    pub no_pixels: bool,
    /// Set NaN/Inf input texels to 0 instead of refusing the input.
    #[arg(long)]
    pub sanitize: bool,
}

impl Default for Params {
    fn default() -> Self {
        ibl_core::params::clap_defaults()
    }
}

fn bad<T>(m: String) -> crate::Result<T> {
    Err(crate::Error::Core(ibl_core::Error::param(m)))
}

impl Params {
    /// The --as-lobes as (n_u, n_v).
    pub fn parse_as_lobes(&self) -> crate::Result<Vec<(f64, f64)>> {
        self.as_lobes
            .iter()
            .map(|l| {
                let parts: Vec<&str> = l.trim().split('x').collect();
                let nums: Option<Vec<f64>> =
                    parts.iter().map(|p| p.trim().parse::<f64>().ok()).collect();
                match nums.as_deref() {
                    Some([nu, nv]) if (1.0..=1e6).contains(nu) && (1.0..=1e6).contains(nv) => {
                        Ok((*nu, *nv))
                    }
                    _ => bad(format!(
                        "--as-lobes: '{l}' is not NUxNV with exponents in 1..=1e6"
                    )),
                }
            })
            .collect()
    }

    /// Checks the parameters and reads the --tpr-map / --quat-map files, before any
    /// environment is read; returns the parsed methods and the frame field.
    pub fn validate(&self) -> crate::Result<(Vec<Method>, Field)> {
        if !(4..=512).contains(&self.sphere_size) {
            return bad(format!(
                "--sphere-size {} is out of range 4..=512",
                self.sphere_size
            ));
        }
        if self.roughness.is_empty() || self.roughness.iter().any(|r| !(*r > 0.0 && *r <= 1.0)) {
            return bad("--roughness needs values in (0, 1]".into());
        }
        if self.eta.is_empty() || self.eta.iter().any(|e| e.is_nan() || e.abs() >= 1.0) {
            return bad("--eta needs values in (-1, 1)".into());
        }
        if self.views.is_empty() || self.views.iter().any(|v| !v.is_finite()) {
            return bad("--views needs finite azimuths in degrees".into());
        }
        if self.elevations.is_empty()
            || self
                .elevations
                .iter()
                .any(|v| v.is_nan() || v.abs() >= 90.0)
        {
            return bad("--elevations needs angles in (-90, 90) degrees".into());
        }
        if !(16..=1 << 20).contains(&self.truth_samples) {
            return bad(format!(
                "--truth-samples {} is out of range 16..=1048576",
                self.truth_samples
            ));
        }
        if let Some(n) = self.chain_size {
            if !(8..=1024).contains(&n) {
                return bad(format!("--chain-size {n} is out of range 8..=1024"));
            }
        }
        if let Some(n) = self.size {
            if n == 0 || n > 2048 {
                return bad(format!("--size {n} is out of range 1..=2048"));
            }
        }
        if self.target.spec().lod == ibl_target::LodMapping::Pmrem {
            return bad(format!(
                "--target {}: the engine filters its own chain, there is no lookup of ours to emulate",
                self.target.name()
            ));
        }
        let preset: Preset = self.tangent.parse().map_err(|e: String| {
            crate::Error::Core(ibl_core::Error::param(format!("--tangent: {e}")))
        })?;
        if self.methods.is_empty() {
            return bad("--methods needs at least one method".into());
        }
        self.parse_as_lobes()?;
        let methods = self
            .methods
            .iter()
            .map(|m| Method::parse(m.trim()))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| crate::Error::Core(ibl_core::Error::param(format!("--methods: {e}"))))?;
        if self.tpr_roughness.is_some() && self.tpr_map.is_none() {
            return bad("--tpr-roughness reads the --tpr-map file: give --tpr-map FILE".into());
        }
        let tpr = match (&self.tpr_map, self.tpr_roughness) {
            (Some(p), Some(_)) => Some(load_tpr_roughness_map(p)?),
            (Some(p), None) => Some(load_uv_map(p, "--tpr-map", 2)?),
            (None, _) => None,
        };
        let field = Field {
            preset,
            tpr,
            tpr_roughness: self.tpr_roughness,
            quat: self
                .quat_map
                .as_deref()
                .map(|p| load_uv_map(p, "--quat-map", 3))
                .transpose()?,
        };
        Ok((methods, field))
    }
}

/// Reads a map the scene samples at UV: at least `channels` channels, finite texels; a
/// quaternion map's texels must decode to a non-zero quaternion. One-line errors naming the
/// flag and the file.
fn load_uv_map(path: &std::path::Path, flag: &str, channels: usize) -> crate::Result<UvMap> {
    let err =
        |m: String| crate::Error::Core(ibl_core::Error::invalid(path, format!("{flag}: {m}")));
    // Unreadable or missing: the reader's own error (it names the file; I/O keeps its class).
    let loaded = ibl_material::map::load(path)?;
    let img = loaded.image;
    if img.channels < channels || (loaded.grey_alpha && channels > 2) {
        return Err(err(format!(
            "{} channel(s), the map needs {channels}",
            if loaded.grey_alpha { 2 } else { img.channels }
        )));
    }
    if img.width == 0 || img.height == 0 {
        return Err(err("empty image".into()));
    }
    if let Some(i) = img.data.iter().position(|v| !v.is_finite()) {
        return Err(err(format!("texel {} is not finite", i / img.channels)));
    }
    if channels == 3 {
        for (i, t) in img.data.chunks(img.channels).enumerate() {
            let q = ibl_material::quaternion::decode_quat(&t[..3]);
            if q[0] * q[0] + q[1] * q[1] + q[2] * q[2] < 1e-6 {
                return Err(err(format!(
                    "texel {i} is not a quaternion (q·½ + ½ decodes to 0): not a quat-map output?"
                )));
            }
        }
    }
    Ok(UvMap { image: img })
}

/// A `tpr-map` output whose B, A roughness channels are read (--tpr-roughness): four
/// channels, and B, A within [0, 1] (what tpr-map writes, perceptual r or α); one-line errors
/// naming the file.
fn load_tpr_roughness_map(path: &std::path::Path) -> crate::Result<UvMap> {
    let map = load_uv_map(path, "--tpr-map", 2)?;
    let img = &map.image;
    let err = |m: String| {
        crate::Error::Core(ibl_core::Error::invalid(
            path,
            format!("--tpr-map with --tpr-roughness: {m}"),
        ))
    };
    if img.channels < 4 {
        return Err(err(format!(
            "{} channel(s), the roughness channels B and A are missing (a tpr-map output has 4)",
            img.channels
        )));
    }
    for (i, t) in img.data.chunks(img.channels).enumerate() {
        if let Some(x) = t[2..4].iter().find(|x| !(0.0..=1.0).contains(*x)) {
            return Err(err(format!(
                "texel {i} has roughness {x} outside [0, 1] in B or A"
            )));
        }
    }
    Ok(map)
}

/// What a method reads, per environment.
pub struct Env {
    /// Name (file stem).
    pub name: String,
    /// The cube the truth reads (native resolution, nearest texel).
    pub cube: Cubemap,
    /// Engine lookup of the chain, if asked for.
    pub engine: Option<Lookup>,
    /// Oracle lookup, if asked for.
    pub oracle: Option<Lookup>,
    /// Box pyramid of `cube` for filtered importance sampling.
    pub pyramid: BorderedMips,
    /// Where the chain came from.
    pub chain_source: String,
}

impl Env {
    /// Builds the lookups of `params.lookup` from the truth cube and a chain.
    pub fn new(
        name: String,
        cube: Cubemap,
        chain: &CubeMips,
        chain_source: String,
        params: &Params,
    ) -> Env {
        let want_engine = params.lookup != LookupChoice::Oracle;
        let want_oracle = params.lookup != LookupChoice::Engine;
        Env {
            name,
            engine: want_engine.then(|| Lookup::Engine {
                chain: BorderedMips::new(chain),
                mapping: params.target.spec().lod,
            }),
            oracle: want_oracle.then(|| Lookup::Oracle {
                tree: ibl_prefilter::tree::CellTree::new(&cube),
                source: cube.clone(),
            }),
            pyramid: BorderedMips::new(&CubeMips::build(cube.clone(), 1)),
            cube,
            chain_source,
        }
    }
}

/// Error statistics of one method (one lookup, one F0) on one case.
#[derive(Clone, Debug, Serialize)]
pub struct Score {
    /// Method name.
    pub method: String,
    /// "engine", "oracle" or "none" (methods that do not read the chain).
    pub lookup: String,
    /// Schlick F0.
    pub f0: f64,
    /// Mean per-pixel relative error of luminance.
    pub mean_rel: f64,
    /// 95th percentile of it.
    pub p95_rel: f64,
    /// √(Σ(Ŷ−Y)²/ΣY²) over pixels and channels.
    pub rel_rmse: f64,
    /// Mean squared error per pixel and channel.
    pub mse: f64,
    /// Cube taps per pixel.
    pub cube_taps: usize,
    /// 2D-table taps per pixel.
    pub lut_taps: usize,
}

/// One case: environment × (r, η) × view.
#[derive(Clone, Debug, Serialize)]
pub struct Case {
    /// Environment name.
    pub env: String,
    /// Perceptual roughness.
    pub r: f32,
    /// Kulla–Conty anisotropy.
    pub eta: f32,
    /// The lobe.
    pub material: Material,
    /// Camera azimuth (degrees).
    pub azimuth: f32,
    /// Camera elevation (degrees).
    pub elevation: f32,
    /// View direction (towards the eye, world).
    pub v: [f32; 3],
    /// Shaded pixels.
    pub pixels: usize,
    /// Truth MSE estimate (mean se²) over the best method's MSE, per F0 (1, 0.04).
    pub truth_error_share: [f64; 2],
    /// Whether the case is scored (truth_error_share < 0.01 for both F0).
    pub scored: bool,
    /// Every method × lookup × F0.
    pub scores: Vec<Score>,
}

/// Per-case per-pixel outputs (for the report folder).
pub struct CaseImages {
    /// Pixels (frame and index).
    pub pixels: Vec<Pixel>,
    /// Truth per pixel.
    pub truth: Vec<TruthValue>,
    /// (method name, lookup name, per-pixel E0/E1).
    pub methods: Vec<(String, String, Vec<E01>)>,
}

/// One method × lookup on one case: names, per-pixel (E0, E1), (cube, table) taps.
type Run = (String, String, Vec<E01>, (usize, usize));

/// F0 values scored.
pub const F0S: [f64; 2] = [1.0, 0.04];

fn stats(truth: &[TruthValue], est: &[E01], f0: f64) -> (f64, f64, f64, f64) {
    let yt: Vec<f64> = truth
        .iter()
        .map(|t| {
            let c = t.radiance(f0);
            luminance([c[0] as f32, c[1] as f32, c[2] as f32]) as f64
        })
        .collect();
    let eps = 0.01 * yt.iter().sum::<f64>() / yt.len().max(1) as f64;
    let mut rel = Vec::with_capacity(yt.len());
    let (mut se, mut sy) = (0.0f64, 0.0f64);
    for ((t, e), y) in truth.iter().zip(est).zip(&yt) {
        let c = t.radiance(f0);
        let m: [f64; 3] = std::array::from_fn(|k| f0 * e.0[k] as f64 + (1.0 - f0) * e.1[k] as f64);
        let ym = luminance([m[0] as f32, m[1] as f32, m[2] as f32]) as f64;
        rel.push((ym - y).abs() / (y + eps).max(1e-30));
        for k in 0..3 {
            se += (m[k] - c[k]).powi(2);
            sy += c[k] * c[k];
        }
    }
    rel.sort_by(|a, b| a.total_cmp(b));
    let n = rel.len().max(1);
    let mean = rel.iter().sum::<f64>() / n as f64;
    let p95 = rel
        .get(((n as f64 * 0.95).ceil() as usize).saturating_sub(1))
        .copied()
        .unwrap_or(0.0);
    let rel_rmse = if sy > 0.0 { (se / sy).sqrt() } else { 0.0 };
    (mean, p95, rel_rmse, se / (3 * n) as f64)
}

/// Runs every case of `params` on one environment.
pub fn evaluate(
    env: &Env,
    params: &Params,
    methods: &[Method],
    preset: &Field,
) -> (Vec<Case>, Vec<CaseImages>) {
    evaluate_with(env, params, methods, preset, |_| true)
}

/// [`evaluate`], with the oracle lookup (when the environment has one) only for the methods
/// `use_oracle` accepts: the oracle sums the exact kernel per tap, the cost of a sweep.
pub fn evaluate_with(
    env: &Env,
    params: &Params,
    methods: &[Method],
    preset: &Field,
    use_oracle: impl Fn(&Method) -> bool,
) -> (Vec<Case>, Vec<CaseImages>) {
    let dfg = Dfg::standard();
    let mut cases = Vec::new();
    let mut images = Vec::new();
    let mut materials: Vec<(f32, f32, Material)> = Vec::new();
    // With the lobe from the tpr-map file, one GGX case whose pixels carry their own lobe
    // (`Pixel::material`); the case's r, η and material are set from the pixels' mean below.
    let from_file = preset.tpr_roughness.is_some() && preset.tpr.is_some();
    if from_file {
        materials.push((0.0, 0.0, Material::ggx_kc(0.5, 0.0)));
    } else {
        for &r in &params.roughness {
            for &eta in &params.eta {
                materials.push((r, eta, Material::ggx_kc(r, eta)));
            }
        }
    }
    for (nu, nv) in params.parse_as_lobes().unwrap_or_default() {
        materials.push((0.0, 0.0, Material::AshikhminShirley { nu, nv }));
    }
    for &(r0, eta0, mat) in &materials {
        // A lobe no method renders has nothing to score: no truth for it.
        if !methods.iter().any(|m| m.applies_to(&mat)) {
            continue;
        }
        {
            let as_tables = match mat {
                Material::AshikhminShirley { nu, nv } => Some(AsTables::bake(nu, nv, 128)),
                _ => None,
            };
            for &el in &params.elevations {
                for &az in &params.views {
                    let cam = camera(az, el);
                    let v = cam.2;
                    let pixels = match params.scene {
                        Scene::Sphere => sphere_pixels(params.sphere_size, cam, preset),
                        Scene::Plate => plate_pixels(params.sphere_size, az, el, preset),
                    };
                    // The lobe each pixel is shaded with: its own (from the file) for a GGX
                    // case, else the case's.
                    let lobe = |p: &Pixel| match (mat, p.material) {
                        (Material::Ggx { .. }, Some(m)) => m,
                        _ => mat,
                    };
                    let (r, eta, case_mat) = match mat {
                        Material::Ggx { .. } if from_file => mean_lobe(&pixels),
                        _ => (r0, eta0, mat),
                    };
                    let truth: Vec<TruthValue> = pixels
                        .par_iter()
                        .map(|p| {
                            mc_truth(
                                &env.cube,
                                &p.frame,
                                p.v,
                                &lobe(p),
                                params.truth_samples,
                                p.idx as u64,
                            )
                        })
                        .collect();
                    let mut runs: Vec<Run> = Vec::new();
                    for m in methods.iter().filter(|m| m.applies_to(&mat)) {
                        let oracle = env.oracle.as_ref().filter(|_| use_oracle(m));
                        let lookups: Vec<&Lookup> = if m.reads_chain() {
                            [env.engine.as_ref(), oracle]
                                .into_iter()
                                .flatten()
                                .collect()
                        } else {
                            vec![env
                                .engine
                                .as_ref()
                                .or(env.oracle.as_ref())
                                .expect("a lookup")]
                        };
                        for lk in lookups {
                            let inp = Inputs {
                                lookup: lk,
                                dfg,
                                pyramid: &env.pyramid,
                                cube: &env.cube,
                                as_tables: as_tables.as_ref(),
                            };
                            let est: Vec<E01> = pixels
                                .par_iter()
                                .map_init(TreeBuffers::default, |buf, p| {
                                    eval_method(m, &inp, &p.frame, p.v, &lobe(p), p.idx as u64, buf)
                                })
                                .collect();
                            let ln = if m.reads_chain() { lk.name() } else { "none" };
                            runs.push((m.name(), ln.to_string(), est, m.taps()));
                        }
                    }
                    let mut scores = Vec::new();
                    let mut share = [0.0f64; 2];
                    for (fi, &f0) in F0S.iter().enumerate() {
                        let truth_mse = truth
                            .iter()
                            .map(|t| t.radiance_se(f0).iter().map(|s| s * s).sum::<f64>() / 3.0)
                            .sum::<f64>()
                            / truth.len().max(1) as f64;
                        let mut best = f64::MAX;
                        for (name, ln, est, (ct, lt)) in &runs {
                            let (mean_rel, p95_rel, rel_rmse, mse) = stats(&truth, est, f0);
                            best = best.min(mse);
                            scores.push(Score {
                                method: name.clone(),
                                lookup: ln.clone(),
                                f0,
                                mean_rel,
                                p95_rel,
                                rel_rmse,
                                mse,
                                cube_taps: *ct,
                                lut_taps: *lt,
                            });
                        }
                        share[fi] = if best > 0.0 { truth_mse / best } else { 0.0 };
                    }
                    cases.push(Case {
                        env: env.name.clone(),
                        r,
                        eta,
                        material: case_mat,
                        azimuth: az,
                        elevation: el,
                        v: v.to_array(),
                        pixels: pixels.len(),
                        truth_error_share: share,
                        scored: share.iter().all(|s| *s < 0.01) && !pixels.is_empty(),
                        scores,
                    });
                    images.push(CaseImages {
                        pixels,
                        truth,
                        methods: runs.into_iter().map(|(a, b, c, _)| (a, b, c)).collect(),
                    });
                }
            }
        }
    }
    (cases, images)
}

/// The (r, η, lobe) a case whose pixels carry their own GGX lobe is reported at: the mean
/// (ᾱ_t, ᾱ_b) over its pixels, r = √((ᾱ_t+ᾱ_b)/2), η = (ᾱ_t−ᾱ_b)/(ᾱ_t+ᾱ_b).
fn mean_lobe(pixels: &[Pixel]) -> (f32, f32, Material) {
    let (mut st, mut sb, mut n) = (0.0f64, 0.0f64, 0usize);
    for (at, ab) in pixels
        .iter()
        .filter_map(|p| p.material.and_then(|m| m.ggx_alphas()))
    {
        st += at as f64;
        sb += ab as f64;
        n += 1;
    }
    if n == 0 {
        return (0.0, 0.0, Material::ggx_kc(0.5, 0.0));
    }
    let (at, ab) = (st / n as f64, sb / n as f64);
    (
        ((at + ab) / 2.0).sqrt() as f32,
        ((at - ab) / (at + ab)) as f32,
        Material::Ggx {
            alpha_t: at as f32,
            alpha_b: ab as f32,
        },
    )
}

/// Aggregate of one method × lookup × F0 over the scored cases.
#[derive(Clone, Debug, Serialize)]
pub struct Summary {
    /// Method.
    pub method: String,
    /// Lookup.
    pub lookup: String,
    /// F0.
    pub f0: f64,
    /// Scored cases.
    pub cases: usize,
    /// Mean relRMSE.
    pub rel_rmse: f64,
    /// Mean of the per-case mean relative error.
    pub mean_rel: f64,
    /// Mean of the per-case 95th percentile.
    pub p95_rel: f64,
    /// Cases with a lower MSE than bent-lg18 (same lookup and F0).
    pub wins_vs_bent: usize,
    /// Cases with a lower MSE than iso (same lookup and F0).
    pub wins_vs_iso: usize,
    /// Geometric mean of MSE / MSE(bent-lg18).
    pub gm_ratio_vs_bent: f64,
    /// Cube taps per pixel.
    pub cube_taps: usize,
}

/// Aggregates the scored cases per method, lookup and F0. Methods without a lookup ("none",
/// FIS) are compared with the engine baselines.
pub fn summarize(cases: &[Case]) -> Vec<Summary> {
    let mut out: Vec<Summary> = Vec::new();
    for c in cases.iter().filter(|c| c.scored) {
        for s in &c.scores {
            let base_lookup = if s.lookup == "none" {
                "engine"
            } else {
                s.lookup.as_str()
            };
            let find = |m: &str| {
                c.scores
                    .iter()
                    .find(|x| {
                        x.method == m
                            && x.f0 == s.f0
                            && (x.lookup == base_lookup
                                || (base_lookup == "engine"
                                    && x.lookup == "oracle"
                                    && !c.scores.iter().any(|y| y.lookup == "engine")))
                    })
                    .map(|x| x.mse)
            };
            let (bent, iso) = (find("bent-lg18"), find("iso"));
            let i = match out
                .iter()
                .position(|o| o.method == s.method && o.lookup == s.lookup && o.f0 == s.f0)
            {
                Some(i) => i,
                None => {
                    out.push(Summary {
                        method: s.method.clone(),
                        lookup: s.lookup.clone(),
                        f0: s.f0,
                        cases: 0,
                        rel_rmse: 0.0,
                        mean_rel: 0.0,
                        p95_rel: 0.0,
                        wins_vs_bent: 0,
                        wins_vs_iso: 0,
                        gm_ratio_vs_bent: 0.0,
                        cube_taps: s.cube_taps,
                    });
                    out.len() - 1
                }
            };
            let o = &mut out[i];
            o.cases += 1;
            o.rel_rmse += s.rel_rmse;
            o.mean_rel += s.mean_rel;
            o.p95_rel += s.p95_rel;
            if bent.is_some_and(|b| s.mse < b) {
                o.wins_vs_bent += 1;
            }
            if iso.is_some_and(|b| s.mse < b) {
                o.wins_vs_iso += 1;
            }
            if let Some(b) = bent {
                o.gm_ratio_vs_bent += ((s.mse + 1e-30) / (b + 1e-30)).ln();
            }
        }
    }
    for o in &mut out {
        let n = o.cases.max(1) as f64;
        o.rel_rmse /= n;
        o.mean_rel /= n;
        o.p95_rel /= n;
        o.gm_ratio_vs_bent = (o.gm_ratio_vs_bent / n).exp();
    }
    out
}

/// The markdown report: the summary, then one row per case and method (F0 = 1).
pub fn markdown(cases: &[Case], summary: &[Summary], chain_sources: &[String]) -> String {
    let mut s = String::new();
    let scored = cases.iter().filter(|c| c.scored).count();
    let _ = writeln!(s, "# aniso-eval\n");
    for c in chain_sources {
        let _ = writeln!(s, "- chain: {c}");
    }
    let _ = writeln!(
        s,
        "- cases: {} ({} scored: truth MSE < 1% of the best method's)\n",
        cases.len(),
        scored
    );
    let _ = writeln!(s, "| method | lookup | F0 | cube taps | cases | relRMSE | mean rel | p95 rel | wins vs bent-lg18 | wins vs iso | gm MSE ratio vs bent |");
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|---|");
    for o in summary {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {:.4} | {:.4} | {:.4} | {}/{} | {}/{} | {:.3} |",
            o.method,
            o.lookup,
            o.f0,
            o.cube_taps,
            o.cases,
            o.rel_rmse,
            o.mean_rel,
            o.p95_rel,
            o.wins_vs_bent,
            o.cases,
            o.wins_vs_iso,
            o.cases,
            o.gm_ratio_vs_bent
        );
    }
    let _ = writeln!(s, "\n## Cases (F0 = 1, relRMSE / mean relative error)\n");
    let mut names: Vec<(String, String)> = Vec::new();
    for c in cases {
        for x in c.scores.iter().filter(|x| x.f0 == 1.0) {
            let k = (x.method.clone(), x.lookup.clone());
            if !names.contains(&k) {
                names.push(k);
            }
        }
    }
    let _ = write!(s, "| env | material | az | el | truth share |");
    for (m, l) in &names {
        let _ = write!(s, " {m} ({l}) |");
    }
    let _ = writeln!(s);
    let _ = writeln!(s, "|{}", "---|".repeat(5 + names.len()));
    for c in cases {
        let mat = match c.material {
            Material::AshikhminShirley { nu, nv } => format!("AS {nu}×{nv}"),
            _ => format!("GGX r {} η {}", c.r, c.eta),
        };
        let _ = write!(
            s,
            "| {} | {mat} | {} | {} | {:.1e}{} |",
            c.env,
            c.azimuth,
            c.elevation,
            c.truth_error_share[0],
            if c.scored { "" } else { " (not scored)" }
        );
        for (m, l) in &names {
            match c
                .scores
                .iter()
                .find(|x| x.f0 == 1.0 && &x.method == m && &x.lookup == l)
            {
                Some(x) => {
                    let _ = write!(s, " {:.3} / {:.3} |", x.rel_rmse, x.mean_rel);
                }
                None => {
                    let _ = write!(s, " – |");
                }
            }
        }
        let _ = writeln!(s);
    }
    s
}

fn image_of(s: usize, pixels: &[Pixel], f: impl Fn(usize) -> [f32; 3]) -> Image {
    let mut img = Image::new(s, s, 3);
    for (k, p) in pixels.iter().enumerate() {
        img.texel_mut(p.idx % s, p.idx / s).copy_from_slice(&f(k));
    }
    img
}

/// Reinhard + sRGB (as `shexp-eval`'s montage).
fn display(c: [f32; 3]) -> [f32; 3] {
    c.map(|x| {
        let t = (x.max(0.0) / (1.0 + x.max(0.0))).clamp(0.0, 1.0);
        if t <= 0.0031308 {
            12.92 * t
        } else {
            1.055 * t.powf(1.0 / 2.4) - 0.055
        }
    })
}

/// Encoded outputs: report.md, report.json, and unless `no_pixels` one folder per case with
/// `case.json` (material, view, pixel index ↔ frame), EXRs of the frame (n, t), the truth (E0,
/// E1 and their standard errors) and each method's E0/E1, and a montage PNG (F0 = 1: truth,
/// then every method, over |error| ×4 of the truth's luminance).
pub fn encode_outputs(
    out_dir: &std::path::Path,
    params: &Params,
    cases: &[Case],
    images: &[CaseImages],
    summary: &[Summary],
    chain_sources: &[String],
    cubes: &[(String, &Cubemap)],
) -> crate::Result<Vec<(PathBuf, Vec<u8>)>> {
    use ibl_core::io::{self, WriteOptions};
    let mut files = Vec::new();
    let md = out_dir.join("report.md");
    files.push((md, markdown(cases, summary, chain_sources).into_bytes()));
    let js = out_dir.join("report.json");
    let json = serde_json::json!({ "params": params, "chains": chain_sources, "summary": summary, "cases": cases });
    files.push((js.clone(), io::data::encode(&js, &json)?));
    if params.no_pixels {
        return Ok(files);
    }
    let s = params.sphere_size;
    let exr = WriteOptions::default();
    // The truth's environment as a texel list (faces stacked vertically in Face::ALL order):
    // radiance, texel-centre direction and solid angle, so independent code can recompute any
    // pixel without our cube conventions; and the DFG table the split-sum methods read.
    for (name, cube) in cubes {
        let n = cube.size;
        let mut rad = Image::new(n, 6 * n, 3);
        let mut dir = Image::new(n, 6 * n, 3);
        let mut sa = Image::new(n, 6 * n, 3);
        for face in ibl_core::cube::Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    let y = face as usize * n + j;
                    rad.texel_mut(i, y).copy_from_slice(&cube.texel(face, i, j));
                    let d = ibl_core::cube::texel_direction(face, i, j, n);
                    dir.texel_mut(i, y).copy_from_slice(&d.to_array());
                    let w = ibl_core::cube::texel_solid_angle(i, j, n) as f32;
                    sa.texel_mut(i, y).copy_from_slice(&[w; 3]);
                }
            }
        }
        for (kind, img) in [("radiance", rad), ("direction", dir), ("solid_angle", sa)] {
            let p = out_dir.join(format!("env_{name}_{kind}.exr"));
            let b = io::encode_image(&p, &img, &exr)?;
            files.push((p, b));
        }
    }
    {
        let d = Dfg::standard();
        let mut img = Image::new(d.width, d.height, 3);
        for (k, ab) in d.data.iter().enumerate() {
            img.texel_mut(k % d.width, k / d.width)
                .copy_from_slice(&[ab[0], ab[1], 0.0]);
        }
        let p = out_dir.join("dfg.exr");
        let b = io::encode_image(&p, &img, &exr)?;
        files.push((p, b));
    }
    let png = WriteOptions {
        png_bits: 8,
        png_tonemap: false,
        png_srgb: false,
        ..Default::default()
    };
    for (ci, (c, im)) in cases.iter().zip(images).enumerate() {
        let dir = out_dir.join(format!("case{ci:03}_{}", c.env));
        let mut push = |name: &str, img: &Image| -> crate::Result<()> {
            let p = dir.join(name);
            let b = if name.ends_with(".png") {
                io::encode_image(&p, img, &png)?
            } else {
                io::encode_image(&p, img, &exr)?
            };
            files.push((p, b));
            Ok(())
        };
        let px = &im.pixels;
        push(
            "frame_n.exr",
            &image_of(s, px, |k| px[k].frame.n.to_array()),
        )?;
        push(
            "frame_t.exr",
            &image_of(s, px, |k| px[k].frame.t.to_array()),
        )?;
        let f32s = |a: [f64; 3]| a.map(|x| x as f32);
        push("truth_e0.exr", &image_of(s, px, |k| f32s(im.truth[k].e0)))?;
        push("truth_e1.exr", &image_of(s, px, |k| f32s(im.truth[k].e1)))?;
        push("truth_se0.exr", &image_of(s, px, |k| f32s(im.truth[k].se0)))?;
        push("truth_se1.exr", &image_of(s, px, |k| f32s(im.truth[k].se1)))?;
        for (m, l, est) in &im.methods {
            push(&format!("{m}_{l}_e0.exr"), &image_of(s, px, |k| est[k].0))?;
            push(&format!("{m}_{l}_e1.exr"), &image_of(s, px, |k| est[k].1))?;
        }
        // Montage: columns truth + methods; row 2 the |error| heat (4× relative to truth's max Y).
        let cols = 1 + im.methods.len();
        let mut mont = Image::new(s * cols, 2 * s, 3);
        let ymax = im
            .truth
            .iter()
            .map(|t| luminance(f32s(t.e0)))
            .fold(1e-6f32, f32::max);
        for (k, p) in px.iter().enumerate() {
            let (i, j) = (p.idx % s, p.idx / s);
            let t = f32s(im.truth[k].e0);
            mont.texel_mut(i, j).copy_from_slice(&display(t));
            for (mi, (_, _, est)) in im.methods.iter().enumerate() {
                let e = est[k].0;
                mont.texel_mut((mi + 1) * s + i, j)
                    .copy_from_slice(&display(e));
                let err = (luminance(e) - luminance(t)).abs() / ymax * 4.0;
                let h = err.clamp(0.0, 1.0);
                mont.texel_mut((mi + 1) * s + i, s + j).copy_from_slice(&[
                    h,
                    h * h,
                    0.2 * (1.0 - h),
                ]);
            }
        }
        push("montage.png", &mont)?;
        let meta = serde_json::json!({
            "case": c,
            "f0": F0S,
            "sphere_size": s,
            "methods": im.methods.iter().map(|(m, l, _)| format!("{m}_{l}")).collect::<Vec<_>>(),
            "pixels": im.pixels,
        });
        let p = dir.join("case.json");
        files.push((p.clone(), io::data::encode(&p, &meta)?));
    }
    Ok(files)
}
