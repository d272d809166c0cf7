//! The `shexp-eval` evaluator: Silvennoinen et al. 2025 §5.1 on any environment. Spheres seen from several
//! views at several roughnesses, for chrome (F0 = 1) and a dielectric (F0 = 0.04); each pixel's
//! reflected radiance E = F0·E0 + (1−F0)·E1 computed three ways:
//! - ground truth: exact summation of f_DV·L·(n·l) over every texel of the environment resampled
//!   to `truth_size` (its own error is measured against a cube of twice the size on a subset of
//!   pixels and reported as a fraction of the errors it measures);
//! - split-sum: prefiltered chain × DFG table;
//! - SH-exp: eq. 11 × the Fresnel-tail factor (both eq. 15 as printed and B/(A+B) measured).
//!
//! Camera: orthographic, looking at the unit sphere horizontally from azimuth φ (degrees, about
//! +Y; φ = 0 looks from +Z). Pixel (i, j), row 0 at the top, covers the disc x² + y² < 1.

use crate::coeffs::Coeffs;
use crate::dfg::FresnelTail;
use crate::splitsum::SplitSum;
use crate::truth::TexelSet;
use glam::Vec3;
use ibl_core::envmap::Environment;
use ibl_core::equirect::Filter;
use ibl_core::progress::{NoProgress, Progress};
use ibl_core::{traverse, Cubemap, Image, Rgb};
use std::fmt::Write;
use std::time::Instant;

/// The two materials of §5.1.
pub const MATERIALS: [(&str, f32); 2] = [("chrome", 1.0), ("dielectric", 0.04)];

/// Parameters of the evaluation (CLI flags and RON keys alike).
#[derive(Clone, Debug, PartialEq, clap::Args, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Sphere image size in pixels.
    #[arg(long, default_value_t = 64)]
    pub sphere_size: usize,
    /// Face size of the ground-truth cube (exact summation over all its texels).
    #[arg(long, default_value_t = 32)]
    pub truth_size: usize,
    /// Perceptual roughness values of the cases (α = r²); default r = 0.5 … 1 (α = 0.25 … 1,
    /// the perceptual spacing of Silvennoinen et al. 2025 §5.1).
    #[arg(long, value_delimiter = ',', default_value = "0.5,0.6,0.7,0.8,0.9,1")]
    pub roughness: Vec<f32>,
    /// Camera azimuths in degrees (horizontal views).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0,90,180,270",
        allow_negative_numbers = true
    )]
    pub views: Vec<f32>,
    /// Level-0 face size of the split-sum chain baked when no --prefiltered folder is given.
    #[arg(long, default_value_t = 128)]
    pub ss_size: usize,
    /// Measure the ground truth's own error against a cube of twice `truth_size`, on every
    /// k-th pixel (0: skip).
    #[arg(long, default_value_t = 5)]
    pub truth_check_stride: usize,
    /// Cube face size the environment is resampled to (default: its natural size).
    #[arg(long, value_name = "N")]
    pub size: Option<usize>,
    /// Set NaN/Inf input texels to 0 instead of refusing the input.
    #[arg(long)]
    pub sanitize: bool,
}

impl Default for Params {
    fn default() -> Self {
        ibl_core::params::clap_defaults()
    }
}

impl Params {
    /// Checks the parameters before any input is read.
    pub fn validate(&self) -> crate::Result<()> {
        let bad = |m: String| Err(crate::Error::Core(ibl_core::Error::param(m)));
        if self.sphere_size < 4 || self.sphere_size > 1024 {
            return bad(format!(
                "--sphere-size {} is out of range 4..=1024",
                self.sphere_size
            ));
        }
        if self.truth_size < 4 || self.truth_size > 256 {
            return bad(format!(
                "--truth-size {} is out of range 4..=256",
                self.truth_size
            ));
        }
        if self.roughness.is_empty() || self.roughness.iter().any(|r| !(*r > 0.0 && *r <= 1.0)) {
            return bad("--roughness needs values in (0, 1]".into());
        }
        if self.views.is_empty() || self.views.iter().any(|v| !v.is_finite()) {
            return bad("--views needs finite azimuths in degrees".into());
        }
        if self.ss_size < 8 || self.ss_size > 1024 {
            return bad(format!(
                "--ss-size {} is out of range 8..=1024",
                self.ss_size
            ));
        }
        if let Some(n) = self.size {
            if n == 0 || n > 4096 {
                return bad(format!("--size {n} is out of range 1..=4096"));
            }
        }
        Ok(())
    }
}

/// One case: material × view × roughness.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Case {
    /// Material name (chrome, plastic, ...).
    pub material: String,
    /// Fresnel reflectance at normal incidence F0.
    pub f0: f32,
    /// View elevation in degrees.
    pub view_deg: f32,
    /// Perceptual roughness r.
    pub roughness: f32,
    /// GGX α = r².
    pub alpha: f32,
    /// Mean of GT² over the disc pixels and channels (to read MSEs relatively).
    pub gt_mean_square: f64,
    /// MSE of the split sum against the truth.
    pub mse_split_sum: f64,
    /// SH-exp with the Fresnel tail the probe records.
    pub mse_shexp: f64,
    /// SH-exp with eq. 15 as printed and with B/(A+B) (equal for chrome).
    pub mse_shexp_printed: f64,
    /// SH-exp with the Fresnel ratio B/(A+B).
    pub mse_shexp_ratio: f64,
    /// The floor eq. 15 puts under SH-exp: MSE of the exact E0 times the Fresnel factor (the
    /// error SH-exp would keep with a perfect fit; 0 for chrome).
    pub mse_exact_e0_fresnel: f64,
    /// MSE on display-referred values (Reinhard + sRGB, as the PNGs), a perceptual check.
    pub mse_display_split_sum: f64,
    /// Same with SH-exp.
    pub mse_display_shexp: f64,
    /// mse_shexp / mse_split_sum.
    pub ratio: f64,
    /// Whether SH-exp has the lower MSE.
    pub shexp_wins: bool,
    /// MSE of the truth cube against one of twice its size (subset of pixels), relative to
    /// the smaller of the two methods' MSE on the same pixels: < 0.01 means the truth's RMS
    /// error is below 1/10 of the smaller RMS error it measures.
    pub truth_error_share: f64,
}

/// Memory per probe of each representation.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Memory {
    /// Bytes of the SH-exp probe (f32 RGB).
    pub shexp_bytes: usize,
    /// Face size of each level of the split-sum chain.
    pub split_sum_sizes: Vec<usize>,
    /// Bytes of the chain as RGB32F.
    pub split_sum_bytes_rgb32f: usize,
    /// Bytes of the chain as RGBA16F.
    pub split_sum_bytes_rgba16f: usize,
    /// split-sum (RGBA16F) / SH-exp (f32).
    pub ratio_rgba16f: f64,
    /// split-sum (RGB32F) / SH-exp (f32).
    pub ratio_rgb32f: f64,
}

/// Everything measured on one environment.
#[derive(Clone, Debug, serde::Serialize)]
pub struct EnvReport {
    /// Environment name.
    pub name: String,
    /// The SH-exp representation scored ([`Coeffs::describe`]).
    pub representation: String,
    /// When the probe carries α knots: the wins of its eq. 11 `p`, `q` alone, for comparison.
    pub wins_eq11: Option<usize>,
    /// Face size of the environment cube.
    pub face_size: usize,
    /// The Fresnel tail used for SH-exp.
    pub fresnel: FresnelTail,
    /// Where the split-sum chain came from.
    pub split_sum_source: String,
    /// Every case scored.
    pub cases: Vec<Case>,
    /// Memory of each representation.
    pub memory: Memory,
    /// Cases SH-exp wins on MSE.
    pub wins: usize,
    /// Wins on display-referred MSE.
    pub wins_display: usize,
    /// Timings stay out of the written reports (which are identical run to run).
    #[serde(skip)]
    pub seconds_truth: f64,
    /// Seconds spent on the two methods.
    #[serde(skip)]
    pub seconds_methods: f64,
    /// Worst `truth_error_share` over the cases.
    pub worst_truth_error_share: f64,
}

/// Rendered images of one case (RGB, sphere_size²), for the montage.
pub struct CaseImages {
    /// The ground truth.
    pub truth: Image,
    /// The split sum.
    pub split_sum: Image,
    /// SH-exp.
    pub shexp: Image,
}

/// Orthographic camera frame for azimuth φ: (right, up, towards-camera).
pub fn camera(view_deg: f32) -> (Vec3, Vec3, Vec3) {
    let (s, c) = view_deg.to_radians().sin_cos();
    let v = Vec3::new(s, 0.0, c);
    let up = Vec3::Y;
    let right = up.cross(v).normalize();
    (right, up, v)
}

/// Normal of pixel (i, j) of an s×s sphere image, or None outside the disc.
pub(crate) fn pixel_normal(i: usize, j: usize, s: usize, cam: (Vec3, Vec3, Vec3)) -> Option<Vec3> {
    let x = 2.0 * (i as f32 + 0.5) / s as f32 - 1.0;
    let y = 1.0 - 2.0 * (j as f32 + 0.5) / s as f32;
    let r2 = x * x + y * y;
    if r2 >= 1.0 {
        return None;
    }
    let z = (1.0 - r2).sqrt();
    Some((cam.0 * x + cam.1 * y + cam.2 * z).normalize())
}

/// One disc pixel of a view: its normal and the truth (E0, E1) per roughness, plus the same
/// from the cube of twice the size on the checked subset.
pub struct TruthPixel {
    /// Pixel index (row-major) in the sphere image.
    pub idx: usize,
    /// Unit surface normal of the pixel.
    pub n: Vec3,
    /// (E0, E1) per roughness.
    pub gt: Vec<([f64; 3], [f64; 3])>,
    /// The same from the cube of twice the size, on the checked subset.
    pub gt2: Option<Vec<([f64; 3], [f64; 3])>>,
}

/// The ground truth of every view's pixels (the expensive part, shared by all methods).
pub struct Truth {
    /// Per view: the view direction and the disc pixels.
    pub views: Vec<(Vec3, Vec<TruthPixel>)>,
    /// Seconds the truth took.
    pub seconds: f64,
    /// Face size of the environment.
    pub face_size: usize,
}

/// Exact summation over the `truth_size` cube (and `2·truth_size` on every
/// `truth_check_stride`-th pixel) for every view and roughness of `params`.
pub fn compute_truth(cube: &Cubemap, params: &Params, progress: &dyn Progress) -> Truth {
    let t0 = Instant::now();
    let resample =
        |n: usize| Environment::Cube(cube.clone()).to_cube(n, Filter::Area, 0.0, &NoProgress);
    let truth = TexelSet::from_cube(&resample(params.truth_size));
    let truth2 = (params.truth_check_stride > 0)
        .then(|| TexelSet::from_cube(&resample(params.truth_size * 2)));
    let alphas: Vec<f32> = params.roughness.iter().map(|r| r * r).collect();
    let na = alphas.len();
    let s = params.sphere_size;
    progress.start("ground truth", (params.views.len() * s) as u64);
    let mut views = Vec::new();
    for &vd in &params.views {
        let cam = camera(vd);
        let pixels = traverse::ordered_row_reduce(
            s,
            |j| {
                let mut out = Vec::new();
                for i in 0..s {
                    let Some(n) = pixel_normal(i, j, s, cam) else {
                        continue;
                    };
                    let mut gt = vec![([0.0; 3], [0.0; 3]); na];
                    truth.e0_e1(n, cam.2, &alphas, &mut gt);
                    let idx = j * s + i;
                    let gt2 = truth2
                        .as_ref()
                        .filter(|_| idx.is_multiple_of(params.truth_check_stride))
                        .map(|t2| {
                            let mut b2 = vec![([0.0; 3], [0.0; 3]); na];
                            t2.e0_e1(n, cam.2, &alphas, &mut b2);
                            b2
                        });
                    out.push(TruthPixel { idx, n, gt, gt2 });
                }
                progress.inc(1);
                out
            },
            Vec::new(),
            |mut all, row| {
                all.extend(row);
                all
            },
        );
        views.push((cam.2, pixels));
    }
    progress.finish();
    Truth {
        views,
        seconds: t0.elapsed().as_secs_f64(),
        face_size: cube.size,
    }
}

/// SH-exp reflected radiance E = F0·E0 + (1−F0)·E1 at one pixel: eq. 11 times the Fresnel
/// factor of `tail` (for a probe fitted on E0/(A+B), times F0·A + B·(…) — see [`crate::coeffs::Target`]).
pub(crate) fn shexp_radiance(
    coeffs: &Coeffs,
    dfg: &crate::dfg::Dfg,
    n: Vec3,
    v: Vec3,
    roughness: f32,
    f0: f32,
    tail: FresnelTail,
) -> Rgb {
    let e = coeffs.e0(n, v, roughness * roughness);
    let nv = n.dot(v).max(0.0);
    let k = match coeffs.target {
        crate::coeffs::Target::E0 => dfg.shexp_fresnel_factor(nv, roughness, f0, tail),
        crate::coeffs::Target::E0OverAlbedo => {
            let (a, b) = dfg.ab(nv, roughness);
            (a + b) * dfg.shexp_fresnel_factor(nv, roughness, f0, tail)
        }
    };
    e.map(|c| c * k)
}

/// Renders and scores every case on one environment. `cube` is the working environment the
/// probe and chain were made from; the truth uses it resampled to `truth_size`.
pub fn evaluate(
    name: &str,
    cube: &Cubemap,
    coeffs: &Coeffs,
    ss: &SplitSum,
    params: &Params,
    progress: &dyn Progress,
) -> (EnvReport, Vec<(usize, CaseImages)>) {
    let truth = compute_truth(cube, params, progress);
    score(name, &truth, coeffs, ss, params, true)
}

/// Scores the methods against a computed truth (images only with `with_images`).
pub fn score(
    name: &str,
    truth: &Truth,
    coeffs: &Coeffs,
    ss: &SplitSum,
    params: &Params,
    with_images: bool,
) -> (EnvReport, Vec<(usize, CaseImages)>) {
    let alphas: Vec<f32> = params.roughness.iter().map(|r| r * r).collect();
    let na = alphas.len();
    let s = params.sphere_size;
    let t1 = Instant::now();
    let mut cases = Vec::new();
    let mut images = Vec::new();
    for (mi, &(mat, f0)) in MATERIALS.iter().enumerate() {
        for (vi, &vd) in params.views.iter().enumerate() {
            let (v, pixels) = &truth.views[vi];
            for (ai, (&r, &alpha)) in params.roughness.iter().zip(&alphas).enumerate() {
                let mut img = with_images.then(|| CaseImages {
                    truth: Image::new(s, s, 3),
                    split_sum: Image::new(s, s, 3),
                    shexp: Image::new(s, s, 3),
                });
                let (mut gt2s, mut e_ss, mut e_sh, mut e_pr, mut e_ra) =
                    (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
                let (mut e_fl, mut d_ss, mut d_sh) = (0.0f64, 0.0f64, 0.0f64);
                let (mut chk_t, mut chk_ss, mut chk_sh) = (0.0f64, 0.0f64, 0.0f64);
                let mut count = 0usize;
                let combine = |g: &([f64; 3], [f64; 3])| -> [f64; 3] {
                    std::array::from_fn(|k| f0 as f64 * g.0[k] + (1.0 - f0 as f64) * g.1[k])
                };
                for px in pixels {
                    let gt = combine(&px.gt[ai]);
                    let ssv = ss.specular(px.n, *v, r, f0);
                    let shp =
                        shexp_radiance(coeffs, &ss.dfg, px.n, *v, r, f0, FresnelTail::Printed);
                    let shr = shexp_radiance(coeffs, &ss.dfg, px.n, *v, r, f0, FresnelTail::Ratio);
                    let sh = if coeffs.fresnel == FresnelTail::Printed {
                        shp
                    } else {
                        shr
                    };
                    let nv = px.n.dot(*v).max(0.0);
                    let floor_k = ss.dfg.shexp_fresnel_factor(nv, r, f0, coeffs.fresnel) as f64;
                    let (dg, dss, dsh) = (display(gt.map(|g| g as f32)), display(ssv), display(sh));
                    let mut sq = [0.0f64; 4];
                    for k in 0..3 {
                        gt2s += gt[k] * gt[k];
                        sq[0] += (ssv[k] as f64 - gt[k]).powi(2);
                        sq[1] += (sh[k] as f64 - gt[k]).powi(2);
                        sq[2] += (shp[k] as f64 - gt[k]).powi(2);
                        sq[3] += (shr[k] as f64 - gt[k]).powi(2);
                        e_fl += (px.gt[ai].0[k] * floor_k - gt[k]).powi(2);
                        d_ss += ((dss[k] - dg[k]) as f64).powi(2);
                        d_sh += ((dsh[k] - dg[k]) as f64).powi(2);
                    }
                    if let Some(img) = &mut img {
                        let (x, y) = (px.idx % s, px.idx / s);
                        img.truth
                            .texel_mut(x, y)
                            .copy_from_slice(&gt.map(|g| g as f32));
                        img.split_sum.texel_mut(x, y).copy_from_slice(&ssv);
                        img.shexp.texel_mut(x, y).copy_from_slice(&sh);
                    }
                    e_ss += sq[0];
                    e_sh += sq[1];
                    e_pr += sq[2];
                    e_ra += sq[3];
                    if let Some(g2) = &px.gt2 {
                        let gt_fine = combine(&g2[ai]);
                        for k in 0..3 {
                            chk_t += (gt_fine[k] - gt[k]).powi(2);
                        }
                        chk_ss += sq[0];
                        chk_sh += sq[1];
                    }
                    count += 3;
                }
                let c = count.max(1) as f64;
                let (mse_ss, mse_sh) = (e_ss / c, e_sh / c);
                let share = if chk_ss.min(chk_sh) > 0.0 {
                    chk_t / chk_ss.min(chk_sh)
                } else {
                    0.0
                };
                cases.push(Case {
                    material: mat.to_string(),
                    f0,
                    view_deg: vd,
                    roughness: r,
                    alpha,
                    gt_mean_square: gt2s / c,
                    mse_split_sum: mse_ss,
                    mse_shexp: mse_sh,
                    mse_shexp_printed: e_pr / c,
                    mse_shexp_ratio: e_ra / c,
                    mse_exact_e0_fresnel: e_fl / c,
                    mse_display_split_sum: d_ss / c,
                    mse_display_shexp: d_sh / c,
                    ratio: if mse_ss > 0.0 {
                        mse_sh / mse_ss
                    } else {
                        f64::INFINITY
                    },
                    shexp_wins: mse_sh < mse_ss,
                    truth_error_share: share,
                });
                if let Some(img) = img {
                    images.push((mi * params.views.len() * na + vi * na + ai, img));
                }
            }
        }
    }
    let wins = cases.iter().filter(|c| c.shexp_wins).count();
    let wins_display = cases
        .iter()
        .filter(|c| c.mse_display_shexp < c.mse_display_split_sum)
        .count();
    let worst = cases
        .iter()
        .map(|c| c.truth_error_share)
        .fold(0.0, f64::max);
    let memory = Memory {
        shexp_bytes: coeffs.bytes(),
        split_sum_sizes: ss.sizes(),
        split_sum_bytes_rgb32f: ss.bytes(12),
        split_sum_bytes_rgba16f: ss.bytes(8),
        ratio_rgba16f: ss.bytes(8) as f64 / coeffs.bytes() as f64,
        ratio_rgb32f: ss.bytes(12) as f64 / coeffs.bytes() as f64,
    };
    // A knotted probe also holds eq. 11's p and q: score them too, side by side.
    let wins_eq11 = coeffs
        .alpha_knots
        .is_some()
        .then(|| score(name, truth, &coeffs.eq11(), ss, params, false).0.wins);
    let report = EnvReport {
        name: name.to_string(),
        representation: coeffs.describe(),
        wins_eq11,
        face_size: truth.face_size,
        fresnel: coeffs.fresnel,
        split_sum_source: ss.source.clone(),
        cases,
        memory,
        wins,
        wins_display,
        seconds_truth: truth.seconds,
        seconds_methods: t1.elapsed().as_secs_f64(),
        worst_truth_error_share: worst,
    };
    (report, images)
}

/// The split-sum baseline for a working cube: `ibl-prefilter`'s chain at level-0 size
/// `ss_size` (its defaults: levels down to 4², r = l/(N−1)) and `ibl-lut`'s DFG table.
pub fn default_split_sum(cube: &Cubemap, ss_size: usize) -> crate::Result<SplitSum> {
    let chain = crate::splitsum::shared_chain(cube, ss_size)?;
    let levels = chain.levels.len();
    Ok(SplitSum::new(
        &chain,
        default_dfg(),
        format!("ibl-prefilter, {levels} levels from {ss_size}²"),
    ))
}

/// The DFG table used by the evaluator (see [`crate::dfg::Dfg::standard`]).
pub fn default_dfg() -> crate::dfg::Dfg {
    crate::dfg::Dfg::standard().clone()
}

/// Encoded outputs of an evaluation for `out_dir`: report.md, report.json and one montage PNG
/// per environment and material.
pub fn encode_outputs(
    out_dir: &std::path::Path,
    params: &Params,
    reports: &[EnvReport],
    images: &[Vec<(usize, CaseImages)>],
) -> crate::Result<Vec<(std::path::PathBuf, Vec<u8>)>> {
    use ibl_core::io::{self, WriteOptions};
    let mut files = Vec::new();
    let md = out_dir.join("report.md");
    files.push((md, markdown(reports).into_bytes()));
    let js = out_dir.join("report.json");
    let bytes = io::data::encode(&js, &reports)?;
    files.push((js, bytes));
    let opts = WriteOptions {
        png_bits: 8,
        png_tonemap: false,
        png_srgb: false,
        ..Default::default()
    };
    for (r, imgs) in reports.iter().zip(images) {
        for (mat, img) in montages(params, imgs) {
            let p = out_dir.join(format!("{}_{mat}.png", r.name));
            let b = io::encode_image(&p, &img, &opts)?;
            files.push((p, b));
        }
    }
    Ok(files)
}

/// Reinhard + sRGB, as `ibl_core::io` tone-maps PNG previews.
fn display(c: Rgb) -> [f32; 3] {
    let l = ibl_core::luminance(c).max(0.0);
    c.map(|x| {
        let t = (x / (1.0 + l)).clamp(0.0, 1.0);
        if t <= 0.003_130_8 {
            12.92 * t
        } else {
            1.055 * t.powf(1.0 / 2.4) - 0.055
        }
    })
}

/// Black → red → yellow → white for t ∈ [0, 1].
fn heat(t: f32) -> [f32; 3] {
    let t = t.clamp(0.0, 1.0);
    [
        (3.0 * t).min(1.0),
        (3.0 * t - 1.0).clamp(0.0, 1.0),
        (3.0 * t - 2.0).clamp(0.0, 1.0),
    ]
}

/// One montage per material: rows = roughness, columns = per view [truth, split-sum, SH-exp,
/// |error| split-sum, |error| SH-exp]; heat maps share one scale per case (the larger method's
/// maximum luminance error). Display-ready values (8-bit PNG, no further tone mapping).
pub fn montages(params: &Params, images: &[(usize, CaseImages)]) -> Vec<(String, Image)> {
    let s = params.sphere_size;
    let (nv, na) = (params.views.len(), params.roughness.len());
    let mut out = Vec::new();
    for (mi, (mat, _)) in MATERIALS.iter().enumerate() {
        let mut m = Image::new(5 * nv * s, na * s, 3);
        for v in m.data.iter_mut() {
            *v = 0.08;
        }
        for vi in 0..nv {
            for ai in 0..na {
                let key = mi * nv * na + vi * na + ai;
                let Some((_, img)) = images.iter().find(|(k, _)| *k == key) else {
                    continue;
                };
                let err = |a: &Image, x: usize, y: usize| -> f32 {
                    let (p, q) = (a.rgb(x, y), img.truth.rgb(x, y));
                    ibl_core::luminance([
                        (p[0] - q[0]).abs(),
                        (p[1] - q[1]).abs(),
                        (p[2] - q[2]).abs(),
                    ])
                };
                let mut scale = 0.0f32;
                for y in 0..s {
                    for x in 0..s {
                        scale = scale
                            .max(err(&img.split_sum, x, y))
                            .max(err(&img.shexp, x, y));
                    }
                }
                let scale = if scale > 0.0 { scale } else { 1.0 };
                for y in 0..s {
                    for x in 0..s {
                        let dx = 2.0 * (x as f32 + 0.5) / s as f32 - 1.0;
                        let dy = 1.0 - 2.0 * (y as f32 + 0.5) / s as f32;
                        if dx * dx + dy * dy >= 1.0 {
                            continue;
                        }
                        let cols = [
                            display(img.truth.rgb(x, y)),
                            display(img.split_sum.rgb(x, y)),
                            display(img.shexp.rgb(x, y)),
                            heat(err(&img.split_sum, x, y) / scale),
                            heat(err(&img.shexp, x, y) / scale),
                        ];
                        for (c, col) in cols.iter().enumerate() {
                            let px = (vi * 5 + c) * s + x;
                            m.texel_mut(px, ai * s + y).copy_from_slice(col);
                        }
                    }
                }
            }
        }
        out.push((mat.to_string(), m));
    }
    out
}

/// Markdown table of one or more environments' cases, with the win share and memory.
pub fn markdown(reports: &[EnvReport]) -> String {
    let mut s = String::new();
    let total: usize = reports.iter().map(|r| r.cases.len()).sum();
    let wins: usize = reports.iter().map(|r| r.wins).sum();
    let _ = writeln!(s, "# SH-exp vs split-sum (Silvennoinen et al. 2025 §5.1)\n");
    let wins_d: usize = reports.iter().map(|r| r.wins_display).sum();
    let _ = writeln!(
        s,
        "SH-exp has the lower MSE in **{wins} of {total} cases ({:.0}%)** (paper: 95% of 192); on display-referred values (Reinhard + sRGB) in {wins_d} ({:.0}%).\n",
        100.0 * wins as f64 / total.max(1) as f64,
        100.0 * wins_d as f64 / total.max(1) as f64
    );
    let _ = writeln!(s, "Ground truth: exact summation over every texel of the environment resampled to a cube (size below); its own error, measured against a cube of twice the size on a subset of pixels, is given as MSE(truth) / min(MSE split-sum, MSE SH-exp) (< 0.01 means its RMS error is below 1/10 of what it measures).\n");
    for r in reports {
        let _ = writeln!(s, "## {}\n", r.name);
        let _ = writeln!(
            s,
            "environment cube {}², split-sum chain {:?} ({}), SH-exp {} with Fresnel tail `{:?}`; wins {}/{} (on display-referred values {}/{}); worst truth error share {:.2e}\n",
            r.face_size,
            r.memory.split_sum_sizes,
            r.split_sum_source,
            r.representation,
            r.fresnel,
            r.wins,
            r.cases.len(),
            r.wins_display,
            r.cases.len(),
            r.worst_truth_error_share
        );
        if let Some(w) = r.wins_eq11 {
            let _ = writeln!(
                s,
                "eq. 11 alone (the same file's p and q, without the knots): wins {w}/{}\n",
                r.cases.len()
            );
        }
        let _ = writeln!(
            s,
            "memory per probe: SH-exp {} B (f32), split-sum {} B as RGBA16F ({:.0}×), {} B as RGB32F ({:.0}×)\n",
            r.memory.shexp_bytes, r.memory.split_sum_bytes_rgba16f, r.memory.ratio_rgba16f, r.memory.split_sum_bytes_rgb32f, r.memory.ratio_rgb32f
        );
        let _ = writeln!(s, "| material | view ° | r | α | MSE split-sum | MSE SH-exp | SH/SS | win | MSE SH (eq.15 printed) | MSE SH (B/(A+B)) | MSE exact E0 × Fresnel | rel. MSE SS | rel. MSE SH |");
        let _ = writeln!(
            s,
            "|---|---:|---:|---:|---:|---:|---:|:---:|---:|---:|---:|---:|---:|"
        );
        for c in &r.cases {
            let _ = writeln!(
                s,
                "| {} | {:.0} | {:.2} | {:.3} | {:.3e} | {:.3e} | {:.3} | {} | {:.3e} | {:.3e} | {:.3e} | {:.2e} | {:.2e} |",
                c.material,
                c.view_deg,
                c.roughness,
                c.alpha,
                c.mse_split_sum,
                c.mse_shexp,
                c.ratio,
                if c.shexp_wins { "✓" } else { "✗" },
                c.mse_shexp_printed,
                c.mse_shexp_ratio,
                c.mse_exact_e0_fresnel,
                c.mse_split_sum / c.gt_mean_square.max(1e-30),
                c.mse_shexp / c.gt_mean_square.max(1e-30)
            );
        }
        let _ = writeln!(s);
    }
    s
}

/// Win share per roughness over all reports: (roughness, wins, cases, geometric-mean ratio).
pub fn wins_by_roughness(reports: &[EnvReport]) -> Vec<(f32, usize, usize, f64)> {
    let mut rs: Vec<f32> = reports
        .iter()
        .flat_map(|r| r.cases.iter().map(|c| c.roughness))
        .collect();
    rs.sort_by(|a, b| a.partial_cmp(b).unwrap());
    rs.dedup();
    rs.into_iter()
        .map(|r| {
            let cs: Vec<&Case> = reports
                .iter()
                .flat_map(|e| e.cases.iter())
                .filter(|c| c.roughness == r)
                .collect();
            let w = cs.iter().filter(|c| c.shexp_wins).count();
            let g = (cs.iter().map(|c| c.ratio.max(1e-30).ln()).sum::<f64>()
                / cs.len().max(1) as f64)
                .exp();
            (r, w, cs.len(), g)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dfg::Dfg;
    use crate::fit;
    use crate::splitsum::prefilter_chain;

    #[test]
    fn camera_and_pixels_see_the_front_hemisphere() {
        let s = 16;
        for vd in [0.0f32, 90.0, 225.0] {
            let cam = camera(vd);
            assert!(
                (cam.0.dot(cam.2)).abs() < 1e-6 && (cam.0.cross(cam.1) - cam.2).length() < 1e-5
            );
            let mut count = 0;
            for j in 0..s {
                for i in 0..s {
                    if let Some(n) = pixel_normal(i, j, s, cam) {
                        assert!(n.dot(cam.2) > 0.0);
                        count += 1;
                    }
                }
            }
            assert!(count > 150 && count < 256);
        }
        // Row 0 is the top of the sphere, column 0 its left (−right).
        let cam = camera(0.0);
        assert!(pixel_normal(8, 0, 17, cam).unwrap().y > 0.9);
        assert!(pixel_normal(0, 8, 17, cam).unwrap().x < -0.9);
    }

    #[test]
    fn constant_environment_scores_split_sum_exact_and_truth_agrees() {
        // L = c: split-sum is exact up to its tables; the truth must equal c·(F0·A + B).
        let c = 0.8f32;
        let cube = Cubemap::constant(16, [c; 3]);
        let fp = fit::Params {
            normals: 16,
            views: 16,
            samples: 64,
            ..Default::default()
        };
        let coeffs = fit::fit_cube(&fp, &cube, &NoProgress).unwrap().coeffs;
        let ss = SplitSum::new(
            &prefilter_chain(&cube, 16, 5, 1, 32),
            Dfg::standard().clone(),
            "fallback",
        );
        let params = Params {
            sphere_size: 12,
            truth_size: 16,
            roughness: vec![0.5, 1.0],
            views: vec![0.0],
            ..Default::default()
        };
        let (rep, imgs) = evaluate("const", &cube, &coeffs, &ss, &params, &NoProgress);
        assert_eq!(rep.cases.len(), 4);
        for case in &rep.cases {
            let rel = case.mse_split_sum / case.gt_mean_square;
            eprintln!(
                "{} r={}: rel MSE split-sum {rel:.2e}, SH-exp {:.2e}",
                case.material,
                case.roughness,
                case.mse_shexp / case.gt_mean_square
            );
            // Left: the DFG table's bilinear interpolation and its texel-centre clamp (r ≤ 1 − 0.5/64).
            assert!(rel < 1e-3, "{rel}");
        }
        let m = montages(&params, &imgs);
        assert_eq!(m.len(), 2);
        assert_eq!((m[0].1.width, m[0].1.height), (5 * 12, 2 * 12));
        let md = markdown(&[rep]);
        assert!(md.contains("| chrome | 0 | 0.50 |"));
    }
}
