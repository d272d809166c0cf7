//! The `shexp-fit` bake: an environment to the 33 (by default) SH-exponential coefficients per
//! colour channel of Silvennoinen et al. 2025, by linear least squares in log space (eqs. 13–14).
//!
//! Rows: `normals` spherical-Fibonacci normals × `views` Fibonacci views uniform over each
//! normal's hemisphere (turned by a golden-ratio azimuth per normal) × every α of `alphas`.
//! Target: log max(E0, floor) with E0 estimated by `samples` VNDF samples through filtered
//! importance sampling (or exact summation, `estimator = exact`).
//! Floor: `floor` × the environment's mean luminance, on every channel (log E0 is undefined
//! where the lobe sees only black; 1e-3 of the mean keeps the log range to ≈ 7 nats there).
//! Then, with `objective = relative` (the default), the log-space solution is refined on the
//! linear error, relative per α group, plus `log_weight` × the log error ([`crate::refine`]);
//! the linear targets need no floor.
//! With `alpha_knots` (beyond the paper), the same rows are also solved for one coefficient set
//! per α knot, linear in α between knots ([`solve_rows_knots`]); `p` and `q` stay eq. 11's.

use crate::basis::{self, num_unknowns, tangent_frame, Features};
use crate::coeffs::{Coeffs, Objective, Target, CONVENTION, MAX_ORDER};
use crate::dfg::FresnelTail;
use crate::estimate::Estimator;
use crate::solve::least_squares;
use crate::truth::TexelSet;
use crate::{Error, Result};
use glam::Vec3;
use ibl_core::bordered::BorderedMips;
use ibl_core::envmap::{Environment, Opened};
use ibl_core::equirect::Filter;
use ibl_core::progress::{NoProgress, Progress};
use ibl_core::{traverse, CubeMips, Cubemap};
use rayon::prelude::*;
use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// How E0 is computed for each row.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum EstimatorKind {
    /// `samples` visible-normal samples through filtered importance sampling (the paper's way).
    #[default]
    Mc,
    /// Exact summation over every texel of the environment resampled to `exact_size`.
    Exact,
}

/// Parameters of the fit: CLI flags and RON keys alike.
#[derive(Clone, Debug, PartialEq, clap::Args, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// SH order (l_max) of P, the factor at the reflection vector: (p+1)² coefficients.
    #[arg(long, default_value_t = 4)]
    pub p_order: usize,
    /// SH order of Q, the factor at the half-reflection vector: (q+1)² − 1 coefficients (no DC).
    #[arg(long, default_value_t = 2)]
    pub q_order: usize,
    /// Views per normal, uniform over the normal's hemisphere.
    #[arg(long, default_value_t = 64)]
    pub views: usize,
    /// Normals, uniform over the sphere.
    #[arg(long, default_value_t = 64)]
    pub normals: usize,
    /// GGX α values of the rows (α = roughness², NOT perceptual roughness), comma-separated.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "0.2,0.4667,0.7333,1",
        allow_negative_numbers = true
    )]
    pub alphas: Vec<f32>,
    /// E0 samples per row (visible-normal samples, filtered importance sampling).
    #[arg(long, default_value_t = 1024)]
    pub samples: usize,
    /// Cube face size the environment is resampled to (default: its natural size, at most the
    /// finest size the Monte-Carlo estimator reads as such: finer faces give the same fit to
    /// f32 rounding).
    #[arg(long, value_name = "N")]
    pub size: Option<usize>,
    /// E0 floor before the log, relative to the environment's mean luminance.
    #[arg(long, default_value_t = 1e-3)]
    pub floor: f32,
    /// Row weights W = (E0/mean E0)^power on the squared log residual: 0 is the paper's plain
    /// log-space fit; 2 makes it a proxy of linear-space MSE (δlog ≈ δE/E).
    #[arg(long, default_value_t = 0.0, allow_negative_numbers = true)]
    pub weight_power: f32,
    /// Also weight rows by n·v (the projected area a pixel of a rendered sphere covers).
    #[arg(long)]
    pub cosine_weight: bool,
    /// Level-of-detail bias of filtered importance sampling (texel doublings).
    #[arg(long, default_value_t = 1.0, allow_negative_numbers = true)]
    pub lod_bias: f32,
    /// What the solve minimises: eq. 13's log-space error alone (`log`, the paper), or, from that
    /// solution, the linear error relative per α group plus `log-weight` × the log error
    /// (`relative`, Gauss–Newton; eq. 11's form is unchanged).
    #[arg(long, value_enum, default_value_t = Objective::Relative)]
    pub objective: Objective,
    /// Weight λ of the log-space error kept in the `relative` objective (0: linear error only).
    #[arg(long, default_value_t = 0.3)]
    pub log_weight: f64,
    /// Gauss–Newton iterations of `objective = relative`.
    #[arg(long, default_value_t = 20)]
    pub refine_iterations: usize,
    /// E0 estimator: Monte Carlo from the mip chain, or exact summation.
    #[arg(long, value_enum, default_value_t = EstimatorKind::Mc)]
    pub estimator: EstimatorKind,
    /// Cube face size of the exact estimator.
    #[arg(long, default_value_t = 32)]
    pub exact_size: usize,
    /// Fresnel tail consumers should apply (recorded in the output): eq. 15 printed or B/(A+B).
    #[arg(long, value_enum, default_value_t = FresnelTail::Ratio)]
    pub fresnel: FresnelTail,
    /// What exp(P·Q) reconstructs: E0 (Silvennoinen et al. 2025) or E0 divided by the DFG albedo A+B (ablation).
    #[arg(long, value_enum, default_value_t = Target::E0)]
    pub target: Target,
    /// Beyond eq. 11 (not in Silvennoinen et al. 2025): also fit coefficient sets at these GGX α knots,
    /// interpolated linearly in α (2–8 increasing values, e.g. 0.2,1), written as
    /// `alpha_knots` beside the eq. 11 `p` and `q`. Best measured with `--cosine-weight
    /// --log-weight 0` (bench/shexp.md); every knot needs a value of --alphas beside it.
    #[arg(long, value_delimiter = ',')]
    pub alpha_knots: Vec<f32>,
    /// Also write a GLSL and an HLSL snippet of eq. 11 beside the output (.glsl, .hlsl); with
    /// `--alpha-knots`, of the knots' interpolation.
    #[arg(long)]
    pub emit_shader: bool,
    /// Set NaN/Inf input texels to 0 instead of refusing the input.
    #[arg(long)]
    pub sanitize: bool,
}

impl Default for Params {
    fn default() -> Self {
        ibl_core::params::clap_defaults()
    }
}

/// Largest row count accepted (normals × views × α).
pub(crate) const MAX_ROWS: usize = 1 << 22;

impl Params {
    /// Checks the parameters before any input is read.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Core(ibl_core::Error::param(m)));
        if self.p_order == 0 || self.p_order > MAX_ORDER {
            return bad(format!(
                "--p-order {} is out of range 1..={MAX_ORDER}",
                self.p_order
            ));
        }
        if self.q_order > MAX_ORDER {
            return bad(format!(
                "--q-order {} is out of range 0..={MAX_ORDER}",
                self.q_order
            ));
        }
        if self.alphas.is_empty() {
            return bad("--alphas is empty: give at least one GGX α in (0, 1]".into());
        }
        if let Some(a) = self.alphas.iter().find(|a| !(**a > 0.0 && **a <= 1.0)) {
            return bad(format!(
                "--alphas value {a} is out of range (0, 1] (GGX α = roughness²)"
            ));
        }
        if !self.alpha_knots.is_empty() {
            let k = &self.alpha_knots;
            if k.len() < 2 || k.len() > crate::coeffs::MAX_KNOTS {
                return bad(format!(
                    "--alpha-knots needs 2..={} values (got {}); without it the probe is eq. 11",
                    crate::coeffs::MAX_KNOTS,
                    k.len()
                ));
            }
            if k.iter().any(|a| !(*a > 0.0 && *a <= 1.0)) || k.windows(2).any(|w| w[1] <= w[0]) {
                return bad(format!(
                    "--alpha-knots {k:?} must increase strictly within (0, 1] (GGX α)"
                ));
            }
            // Every knot's coefficients need rows where its hat weight is non-zero.
            for (i, knot) in k.iter().enumerate() {
                let lo = if i == 0 { f32::NEG_INFINITY } else { k[i - 1] };
                let hi = if i + 1 == k.len() {
                    f32::INFINITY
                } else {
                    k[i + 1]
                };
                if !self.alphas.iter().any(|a| *a > lo && *a < hi) {
                    return bad(format!(
                        "--alpha-knots {knot} has no --alphas value between its neighbours; add one"
                    ));
                }
            }
        }
        if self.views == 0 || self.normals == 0 {
            return bad("--views and --normals must be at least 1".into());
        }
        if self.samples == 0 || self.samples > 1 << 20 {
            return bad(format!(
                "--samples {} is out of range 1..={}",
                self.samples,
                1 << 20
            ));
        }
        let rows = self.rows();
        if rows > MAX_ROWS {
            return bad(format!(
                "{rows} rows (normals × views × alphas) exceed the limit of {MAX_ROWS}"
            ));
        }
        let k = num_unknowns(self.p_order, self.q_order);
        if rows < k {
            return bad(format!(
                "{rows} rows (normals × views × alphas) are fewer than the {k} unknowns"
            ));
        }
        if let Some(n) = self.size {
            if n == 0 || n > MAX_SIZE {
                return bad(format!("--size {n} is out of range 1..={MAX_SIZE}"));
            }
        }
        if self.exact_size == 0 || self.exact_size > 256 {
            return bad(format!(
                "--exact-size {} is out of range 1..=256",
                self.exact_size
            ));
        }
        if !(self.floor > 0.0 && self.floor < 1.0) {
            return bad(format!("--floor {} is out of range (0, 1)", self.floor));
        }
        if !self.weight_power.is_finite() || self.weight_power.abs() > 8.0 {
            return bad(format!(
                "--weight-power {} is out of range [-8, 8]",
                self.weight_power
            ));
        }
        if !(self.log_weight >= 0.0 && self.log_weight <= 1e6) {
            return bad(format!(
                "--log-weight {} is out of range [0, 1e6]",
                self.log_weight
            ));
        }
        if self.refine_iterations > 1000 {
            return bad(format!(
                "--refine-iterations {} is out of range 0..=1000",
                self.refine_iterations
            ));
        }
        if !self.lod_bias.is_finite() || self.lod_bias.abs() > 16.0 {
            return bad(format!(
                "--lod-bias {} is out of range [-16, 16]",
                self.lod_bias
            ));
        }
        Ok(())
    }

    /// Rows of the least-squares system: normals × views × α values (saturating).
    pub fn rows(&self) -> usize {
        self.normals
            .saturating_mul(self.views)
            .saturating_mul(self.alphas.len())
    }

    /// The working cube's face size for an environment whose natural face size is `natural`:
    /// `--size`, else the natural size, at most [`Params::resolved_size`] for the Monte-Carlo
    /// estimator.
    pub fn working_size(&self, natural: usize) -> usize {
        match (self.size, self.estimator) {
            (Some(n), _) => n,
            (None, EstimatorKind::Mc) => natural.min(self.resolved_size()),
            (None, EstimatorKind::Exact) => natural,
        }
    }

    /// The finest face size the Monte-Carlo estimator reads as such: the smallest power of
    /// two n at which its sharpest sample (the smallest lod of every (view, α) table, where
    /// the pdf peaks) reads no finer than mip level 0, 0.5·log2(4π/(6n²)) ≤ lod. From a
    /// larger cube every sample reads its mips only, box averages of the texels the
    /// area-filtered n² cube holds as exact area averages, so the fit is that cube's but for
    /// the box's equal weights against the texels' solid angles: measured with the defaults
    /// (n = 128), coefficients within 3e-8 relative from an 8192×4096 source at 2048² faces
    /// (7.7 s of CPU and 862 MiB against 1.6 s and 22 MiB), within 1.3e-4 from the 1024×512
    /// fixtures at 256², against log-space residuals of 0.37–0.58. Finer faces cost time and
    /// memory for nothing.
    pub fn resolved_size(&self) -> usize {
        let lod = (0..self.views)
            .flat_map(|k| {
                let v = basis::fibonacci_hemisphere(k, self.views);
                self.alphas.iter().flat_map(move |&a| {
                    crate::estimate::sample_table(v, a, self.samples, self.lod_bias)
                })
            })
            .map(|e| e.lod)
            .fold(f32::INFINITY, f32::min);
        if !lod.is_finite() {
            return MAX_SIZE;
        }
        // n ≥ √(2π/3)·2^(−lod), as a power of two.
        let n = ((2.0 * std::f64::consts::PI / 3.0).sqrt() * (-lod as f64).exp2()).ceil();
        (n.clamp(1.0, MAX_SIZE as f64) as usize).next_power_of_two()
    }
}

/// Largest working face size (`--size`'s range).
const MAX_SIZE: usize = 4096;

/// Where the fit's time went, in seconds.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Timings {
    /// Mip chain and padded sampler (or the exact estimator's texel set).
    pub prepare: f64,
    /// Per-(view, α) sample tables.
    pub tables: f64,
    /// E0 for every row (the Monte-Carlo or exact integrals).
    pub estimate: f64,
    /// Design matrix, QR and residuals.
    pub solve: f64,
}

impl Timings {
    /// Seconds of all phases.
    pub fn total(&self) -> f64 {
        self.prepare + self.tables + self.estimate + self.solve
    }
}

/// The fitted probe with its diagnostics.
#[derive(Clone, Debug)]
pub struct Fitted {
    /// The fitted coefficients.
    pub coeffs: Coeffs,
    /// Seconds per phase.
    pub timings: Timings,
    /// Face size of the environment fitted.
    pub face_size: usize,
}

/// E0 of every row and the features of every (normal, view) pair, before the solve.
pub struct Rows {
    /// Highest SH band of P.
    pub p_order: usize,
    /// Highest SH band of Q.
    pub q_order: usize,
    /// GGX α values.
    pub alphas: Vec<f32>,
    /// Y(r), Y(h_r) per (normal, view), normal-major.
    pub features: Vec<Features>,
    /// n·v per (normal, view).
    pub n_dot_v: Vec<f32>,
    /// E0 per (normal, view, α), α fastest.
    pub e0: Vec<[f64; 3]>,
    /// Normals sampled.
    pub normals: usize,
    /// Views per normal.
    pub views: usize,
}

impl Rows {
    /// The same rows with the features of other SH orders (the E0 targets do not depend on
    /// them): for order ablations without re-estimating E0.
    pub fn with_orders(&self, p_order: usize, q_order: usize) -> Rows {
        let views: Vec<Vec3> = (0..self.views)
            .map(|k| basis::fibonacci_hemisphere(k, self.views))
            .collect();
        let mut features = Vec::with_capacity(self.features.len());
        for i in 0..self.normals {
            let (frame, world) = row_geometry(i, self.normals, &views);
            for v in world {
                let mut f = Features::new(p_order, q_order);
                f.eval(frame.2, v);
                features.push(f);
            }
        }
        Rows {
            p_order,
            q_order,
            alphas: self.alphas.clone(),
            features,
            n_dot_v: self.n_dot_v.clone(),
            e0: self.e0.clone(),
            normals: self.normals,
            views: self.views,
        }
    }
}

/// The normal i of `normals`, its turned tangent frame, and the world view k of `views`.
pub fn row_geometry(i: usize, normals: usize, views: &[Vec3]) -> ((Vec3, Vec3, Vec3), Vec<Vec3>) {
    let n = basis::fibonacci_sphere(i, normals);
    let (t, b) = tangent_frame(n, basis::normal_turn(i));
    let world = views
        .iter()
        .map(|v| (t * v.x + b * v.y + n * v.z).normalize())
        .collect();
    ((t, b, n), world)
}

/// Computes every row's E0 (the expensive part), timed into `timings`.
pub fn estimate_rows(
    params: &Params,
    cube: &Cubemap,
    timings: &mut Timings,
    progress: &dyn Progress,
) -> Rows {
    estimate_rows_of(params, Cow::Borrowed(cube), timings, progress)
}

/// [`estimate_rows`] of a cube lent or given: a given one becomes the estimator's mip chain
/// without a copy (at an 8k source's natural 2048² faces the copy is 300 MB).
fn estimate_rows_of(
    params: &Params,
    cube: Cow<Cubemap>,
    timings: &mut Timings,
    progress: &dyn Progress,
) -> Rows {
    let views: Vec<Vec3> = (0..params.views)
        .map(|k| basis::fibonacci_hemisphere(k, params.views))
        .collect();
    let na = params.alphas.len();
    let (p, q) = (params.p_order, params.q_order);
    let per_normal: NormalRows;
    match params.estimator {
        EstimatorKind::Mc => {
            let t0 = Instant::now();
            let sampler = BorderedMips::new(&CubeMips::build(cube.into_owned(), 1));
            timings.prepare = t0.elapsed().as_secs_f64();
            let t0 = Instant::now();
            let est = Estimator::new(&views, &params.alphas, params.samples, params.lod_bias);
            timings.tables = t0.elapsed().as_secs_f64();
            let t0 = Instant::now();
            per_normal = map_normals(params, &views, progress, |frame, k, _, e0| {
                e0.extend((0..na).map(|a| est.e0(&sampler, frame, a, k)));
            });
            timings.estimate = t0.elapsed().as_secs_f64();
        }
        EstimatorKind::Exact => {
            let t0 = Instant::now();
            let size = params.exact_size.min(cube.size);
            let small =
                Environment::Cube(cube.into_owned()).to_cube(size, Filter::Area, 0.0, &NoProgress);
            let set = TexelSet::from_cube(&small);
            timings.prepare = t0.elapsed().as_secs_f64();
            let t0 = Instant::now();
            per_normal = map_normals(params, &views, progress, |frame, _, v, e0| {
                let mut out = vec![([0.0; 3], [0.0; 3]); na];
                set.e0_e1(frame.2, v, &params.alphas, &mut out);
                e0.extend(out.iter().map(|o| o.0));
            });
            timings.estimate = t0.elapsed().as_secs_f64();
        }
    }
    let (features, n_dot_v, e0) = per_normal;
    Rows {
        p_order: p,
        q_order: q,
        alphas: params.alphas.clone(),
        features,
        n_dot_v,
        e0,
        normals: params.normals,
        views: params.views,
    }
}

/// Features, n·v and E0 (α fastest) of consecutive (normal, view) pairs.
type NormalRows = (Vec<Features>, Vec<f32>, Vec<[f64; 3]>);

/// The rows of every normal, one normal per task over the shared ordered traversal
/// (`ibl_core::traverse`), concatenated in normal order whatever the thread count.
/// `e0_of(frame, k, v, e0)` appends the E0 of view k (world direction v) at every α.
fn map_normals<E>(params: &Params, views: &[Vec3], progress: &dyn Progress, e0_of: E) -> NormalRows
where
    E: Fn((Vec3, Vec3, Vec3), usize, Vec3, &mut Vec<[f64; 3]>) + Sync,
{
    let na = params.alphas.len();
    progress.start("E0 rows", params.normals as u64);
    let rows = traverse::ordered_row_reduce(
        params.normals,
        |i| {
            let (frame, world) = row_geometry(i, params.normals, views);
            let mut feats = Vec::with_capacity(views.len());
            let mut nv = Vec::with_capacity(views.len());
            let mut e0 = Vec::with_capacity(views.len() * na);
            for (k, v) in world.iter().enumerate() {
                let mut f = Features::new(params.p_order, params.q_order);
                f.eval(frame.2, *v);
                feats.push(f);
                nv.push(frame.2.dot(*v));
                e0_of(frame, k, *v, &mut e0);
            }
            progress.inc(1);
            (feats, nv, e0)
        },
        (vec![], vec![], vec![]),
        |mut all, row| {
            all.0.extend(row.0);
            all.1.extend(row.1);
            all.2.extend(row.2);
            all
        },
    );
    progress.finish();
    rows
}

/// Solve options beyond the rows themselves.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SolveOptions {
    /// Per-channel floor on E0.
    pub floor: [f64; 3],
    pub weight_power: f32,
    pub cosine_weight: bool,
    pub target: Target,
    pub objective: Objective,
    pub log_weight: f64,
    pub refine_iterations: usize,
}

/// p, q, the log-space RMS residual per channel and the condition number.
pub(crate) type Solved = (Vec<[f32; 3]>, Vec<[f32; 3]>, [f64; 3], f64);

/// Per knot p and q, the log-space RMS residual per channel and the condition number.
pub(crate) type SolvedKnots = (Vec<Vec<[f32; 3]>>, Vec<Vec<[f32; 3]>>, [f64; 3], f64);

/// Least squares of eq. 14 for each channel; returns (p, q, residual per channel, condition).
pub(crate) fn solve_rows(rows: &Rows, opts: &SolveOptions) -> Result<Solved> {
    let (mut p, mut q, residual, condition) = solve_rows_knots(rows, opts, &[])?;
    Ok((p.remove(0), q.remove(0), residual, condition))
}

/// Eq. 14 with one block of unknowns per α knot: row (pair, α) is w₀·[eq. 14 row] in block s
/// and w₁·[eq. 14 row] in block s+1 (the hat weights of [`basis::knot_weights`]), so the
/// coefficients are piecewise linear in α and the problem stays linear in log space. No knots
/// is eq. 14 itself (one block).
pub(crate) fn solve_rows_knots(
    rows: &Rows,
    opts: &SolveOptions,
    knots: &[f32],
) -> Result<SolvedKnots> {
    let (p, q) = (rows.p_order, rows.q_order);
    let k1 = num_unknowns(p, q);
    let blocks = knots.len().max(1);
    let k = k1 * blocks;
    let na = rows.alphas.len();
    let m = rows.e0.len();
    let vmfs: Vec<Vec<f32>> = rows
        .alphas
        .iter()
        .map(|&a| basis::vmf_factors(p.max(q), a))
        .collect();
    let mut a = vec![0.0f64; m * k];
    let mut one = vec![0.0f64; k1];
    for (pair, f) in rows.features.iter().enumerate() {
        for (ai, vmf) in vmfs.iter().enumerate() {
            let r = pair * na + ai;
            f.row(vmf, &mut one);
            let ((s0, w0), (s1, w1)) = basis::knot_weights(knots, rows.alphas[ai]);
            for (s, w) in [(s0, w0), (s1, w1)] {
                if w != 0.0 {
                    let block = &mut a[r * k + s * k1..r * k + (s + 1) * k1];
                    for (dst, v) in block.iter_mut().zip(&one) {
                        *dst += w as f64 * v;
                    }
                }
            }
        }
    }
    // E0/(A+B) target: the albedo at each row's (n·v, α) from the shared DFG table.
    let albedo: Vec<f64> = match opts.target {
        Target::E0 => vec![1.0; m],
        Target::E0OverAlbedo => {
            let dfg = crate::dfg::Dfg::standard();
            (0..m)
                .map(|r| {
                    let (a, b) = dfg.ab(rows.n_dot_v[r / na], rows.alphas[r % na].sqrt());
                    ((a + b) as f64).max(1e-6)
                })
                .collect()
        }
    };
    let target = |r: usize, c: usize| (rows.e0[r][c].max(opts.floor[c]) / albedo[r]).ln();
    let weighted = opts.weight_power != 0.0 || opts.cosine_weight;
    let mut x: Vec<Vec<f64>> = Vec::with_capacity(3);
    let mut condition = 0.0f64;
    let fail = || Error::RankDeficient {
        rows: m,
        unknowns: k,
    };
    if !weighted {
        let rhs: Vec<Vec<f64>> = (0..3)
            .map(|c| (0..m).map(|r| target(r, c)).collect())
            .collect();
        let sol = least_squares(&a, m, k, &rhs).ok_or_else(fail)?;
        condition = sol.condition;
        x = sol.x;
    } else {
        for c in 0..3 {
            let mean = (0..m)
                .map(|r| rows.e0[r][c].max(opts.floor[c]))
                .sum::<f64>()
                / m as f64;
            let sw: Vec<f64> = (0..m)
                .map(|r| {
                    let mut w =
                        (rows.e0[r][c].max(opts.floor[c]) / mean).powf(opts.weight_power as f64);
                    if opts.cosine_weight {
                        w *= rows.n_dot_v[r / na].max(0.0) as f64;
                    }
                    w.sqrt()
                })
                .collect();
            let mut aw = a.clone();
            for r in 0..m {
                for v in &mut aw[r * k..(r + 1) * k] {
                    *v *= sw[r];
                }
            }
            let rhs = vec![(0..m).map(|r| target(r, c) * sw[r]).collect::<Vec<f64>>()];
            let sol = least_squares(&aw, m, k, &rhs).ok_or_else(fail)?;
            condition = condition.max(sol.condition);
            x.push(sol.x.into_iter().next().expect("one rhs"));
        }
    }
    if opts.objective == Objective::Relative {
        let group: Vec<usize> = (0..m).map(|r| r % na).collect();
        let weight: Vec<f64> = (0..m)
            .map(|r| {
                if opts.cosine_weight {
                    rows.n_dot_v[r / na].max(0.0) as f64
                } else {
                    1.0
                }
            })
            .collect();
        x = x
            .into_par_iter()
            .enumerate()
            .map(|(c, x0)| {
                let target: Vec<f64> = (0..m).map(|r| rows.e0[r][c] / albedo[r]).collect();
                let problem = crate::refine::RelativeProblem {
                    a: &a,
                    m,
                    k,
                    target: &target,
                    weight: &weight,
                    group: &group,
                    log_weight: opts.log_weight,
                };
                problem.refine(&x0, opts.refine_iterations, 1e-6).0
            })
            .collect();
    }
    // Unweighted log-space RMS residual per channel.
    let mut residual = [0.0f64; 3];
    for r in 0..m {
        let row = &a[r * k..(r + 1) * k];
        for c in 0..3 {
            let fit: f64 = row.iter().zip(&x[c]).map(|(a, b)| a * b).sum();
            residual[c] += (fit - target(r, c)).powi(2);
        }
    }
    let residual = residual.map(|s| (s / m as f64).sqrt());
    let np = basis::coeffs_of_order(p);
    let coeff = |i: usize| [x[0][i] as f32, x[1][i] as f32, x[2][i] as f32];
    let pc = (0..blocks)
        .map(|b| (b * k1..b * k1 + np).map(coeff).collect())
        .collect();
    let qc = (0..blocks)
        .map(|b| (b * k1 + np..(b + 1) * k1).map(coeff).collect())
        .collect();
    Ok((pc, qc, residual, condition))
}

/// Per-channel E0 floor: `rel` × the cube's mean luminance. Errors on a black environment.
pub fn floor_for(cube: &Cubemap, rel: f32) -> Result<[f64; 3]> {
    let m = cube.mean_radiance();
    let lum = 0.2126 * m[0] + 0.7152 * m[1] + 0.0722 * m[2];
    if lum.is_nan() || lum <= 0.0 || !lum.is_finite() {
        return Err(Error::Core(ibl_core::Error::param(format!(
            "the environment's mean luminance is {lum}: log E0 is undefined for a black environment"
        ))));
    }
    Ok([rel as f64 * lum; 3])
}

/// Fits a cube (already at the working size).
pub fn fit_cube(params: &Params, cube: &Cubemap, progress: &dyn Progress) -> Result<Fitted> {
    fit_cube_of(params, Cow::Borrowed(cube), progress)
}

/// [`fit_cube`] of a cube lent or given (see [`estimate_rows_of`]).
fn fit_cube_of(params: &Params, cube: Cow<Cubemap>, progress: &dyn Progress) -> Result<Fitted> {
    params.validate()?;
    let floor = floor_for(&cube, params.floor)?;
    let face_size = cube.size;
    let mut timings = Timings::default();
    let rows = estimate_rows_of(params, cube, &mut timings, progress);
    let t0 = Instant::now();
    let coeffs = coeffs_from_rows(params, &rows, floor)?;
    timings.solve = t0.elapsed().as_secs_f64();
    Ok(Fitted {
        coeffs,
        timings,
        face_size,
    })
}

/// Solves rows estimated for `params` (orders, weights and target from `params`).
pub fn coeffs_from_rows(params: &Params, rows: &Rows, floor: [f64; 3]) -> Result<Coeffs> {
    let opts = SolveOptions {
        floor,
        weight_power: params.weight_power,
        cosine_weight: params.cosine_weight,
        target: params.target,
        objective: params.objective,
        log_weight: params.log_weight,
        refine_iterations: params.refine_iterations,
    };
    let (p, q, residual_rgb, condition) = solve_rows(rows, &opts)?;
    let rms = |rgb: [f64; 3]| (rgb.iter().map(|r| r * r).sum::<f64>() / 3.0).sqrt();
    let residual = rms(residual_rgb);
    let alpha_knots = if params.alpha_knots.is_empty() {
        None
    } else {
        let (p, q, res, _) = solve_rows_knots(rows, &opts, &params.alpha_knots)?;
        Some(crate::coeffs::AlphaKnots {
            alphas: params.alpha_knots.clone(),
            p,
            q,
            residual: rms(res),
        })
    };
    Ok(Coeffs {
        p_order: rows.p_order,
        q_order: rows.q_order,
        alphas: rows.alphas.clone(),
        p,
        q,
        residual,
        residual_rgb,
        condition_number: condition,
        rows: rows.e0.len(),
        samples: if params.estimator == EstimatorKind::Mc {
            params.samples
        } else {
            0
        },
        floor: floor.map(|f| f as f32),
        fresnel: params.fresnel,
        target: params.target,
        objective: params.objective,
        convention: CONVENTION.to_string(),
        alpha_knots,
    })
}

/// The working cube of an environment: `size` or its natural face size.
pub fn working_cube(env: &Environment, size: Option<usize>, progress: &dyn Progress) -> Cubemap {
    let n = size.unwrap_or_else(|| env.natural_face_size());
    env.to_cube(n, Filter::Area, 0.0, progress)
}

/// What the bake produced, before anything is written.
pub struct Baked {
    /// Encoded files, ready for `ibl_core::io::write_many_atomic`.
    pub files: Vec<(PathBuf, Vec<u8>)>,
    /// The fit and its diagnostics.
    pub fitted: Fitted,
    /// What the input's checks found (negative texels clamped, NaN/Inf zeroed).
    pub warnings: Vec<String>,
}

/// The working cube of an opened input and its warnings: a large equirect opened as a stream
/// (`ibl_core::envmap::open_environment_with`) is resampled as its rows arrive, never held
/// whole (at 8192×4096 the image alone is 400 MB), into the same bits as [`working_cube`].
fn working_cube_of(
    input: Opened,
    size: Option<usize>,
    progress: &dyn Progress,
) -> Result<(Cubemap, Vec<String>)> {
    match input {
        Opened::Loaded(l) => Ok((working_cube(&l.env, size, progress), l.warnings())),
        Opened::Streamed(s) => {
            let n = size.unwrap_or_else(|| s.natural_face_size());
            let path = s.path().to_path_buf();
            let streamed = s.to_cube(n, Filter::Area, 0.0, progress)?;
            let warnings = streamed.warnings(&path);
            Ok((streamed.cube, warnings))
        }
    }
}

/// Fits an environment (loaded, or opened as a stream) and encodes the coefficient file `out`
/// (JSON, or RON by extension) and, with `emit_shader`, `out` with `.glsl` / `.hlsl`
/// extensions.
pub fn run(
    params: &Params,
    input: impl Into<Opened>,
    out: &Path,
    progress: &dyn Progress,
) -> Result<Baked> {
    params.validate()?;
    let input = input.into();
    let size = params.working_size(input.natural_face_size());
    let (cube, warnings) = working_cube_of(input, Some(size), progress)?;
    let fitted = fit_cube_of(params, Cow::Owned(cube), progress)?;
    let mut files = vec![(
        out.to_path_buf(),
        ibl_core::io::data::encode(out, &fitted.coeffs)?,
    )];
    if params.emit_shader {
        files.push((
            out.with_extension("glsl"),
            crate::shader::glsl(&fitted.coeffs).into_bytes(),
        ));
        files.push((
            out.with_extension("hlsl"),
            crate::shader::hlsl(&fitted.coeffs).into_bytes(),
        ));
    }
    Ok(Baked {
        files,
        fitted,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small_params() -> Params {
        Params {
            normals: 24,
            views: 24,
            samples: 128,
            alphas: vec![0.2, 0.6, 1.0],
            ..Default::default()
        }
    }

    #[test]
    fn the_resolved_size_is_the_smallest_whose_level_0_no_sample_reads_finer() {
        // The defining property, and that faces above it fit the same: a cube twice as fine
        // changes the coefficients only by the mips' plain box averages against the area
        // filter's exact ones (1e-4 relative), far below the fit's residual.
        let lod_min = |p: &Params| {
            (0..p.views)
                .flat_map(|k| {
                    let v = basis::fibonacci_hemisphere(k, p.views);
                    p.alphas.iter().flat_map(move |&a| {
                        crate::estimate::sample_table(v, a, p.samples, p.lod_bias)
                    })
                })
                .map(|e| e.lod)
                .fold(f32::INFINITY, f32::min)
        };
        let level0 = |n: usize| 0.5 * (4.0 * std::f32::consts::PI / (6.0 * (n * n) as f32)).log2();
        for p in [
            Params::default(),
            Params {
                samples: 64,
                ..Default::default()
            },
            Params {
                alphas: vec![0.05, 1.0],
                lod_bias: 0.0,
                ..Default::default()
            },
        ] {
            let (n, lod) = (p.resolved_size(), lod_min(&p));
            assert!(n.is_power_of_two() && level0(n) <= lod + 1e-4, "{n} {lod}");
            assert!(n == 1 || level0(n / 2) > lod, "{n} is not the smallest");
            assert_eq!(p.working_size(8 * n), n);
            assert_eq!(p.working_size(n / 2), n / 2);
            let exact = Params {
                estimator: EstimatorKind::Exact,
                ..p.clone()
            };
            assert_eq!(exact.working_size(8 * n), 8 * n);
        }
        assert_eq!(Params::default().resolved_size(), 128);
        let env = ibl_core::envmap::load_environment(
            &Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/hdri/city_512.exr"),
            false,
        )
        .unwrap()
        .env;
        let params = Params::default();
        let fit = |n| {
            let cube = working_cube(&env, Some(n), &NoProgress);
            fit_cube(&params, &cube, &NoProgress).unwrap().coeffs
        };
        let (a, b) = (fit(128), fit(256));
        let flat = |c: &Coeffs| {
            c.p.iter()
                .chain(&c.q)
                .flatten()
                .copied()
                .collect::<Vec<f32>>()
        };
        let (fa, fb) = (flat(&a), flat(&b));
        let scale = fa.iter().fold(0.0f32, |m, v| m.max(v.abs()));
        let worst = fa
            .iter()
            .zip(&fb)
            .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()));
        assert!(worst < 5e-4 * scale, "{worst} of {scale}");
        assert!((a.residual - b.residual).abs() < 1e-3 * a.residual);
    }

    #[test]
    fn a_streamed_input_fits_the_loaded_one() {
        // At the streaming threshold the working cube is resampled as the rows arrive: the
        // same coefficient file, bit for bit, and the same warnings.
        use ibl_core::envmap::{load_environment, open_environment_with, EnvPolicy};
        let d = tempfile::tempdir().unwrap();
        let p = ibl_core::stream::write_streamable_equirect(d.path(), "env.hdr");
        let params = Params {
            size: Some(16),
            ..small_params()
        };
        // The default working size of this 2048-wide source is capped at the resolved one.
        assert_eq!(
            Params::default().working_size(512),
            Params::default().resolved_size()
        );
        let out = d.path().join("shexp.json");
        let opened = open_environment_with(&p, EnvPolicy::default()).unwrap();
        assert!(matches!(opened, Opened::Streamed(_)));
        let a = run(&params, opened, &out, &NoProgress).unwrap();
        let b = run(
            &params,
            load_environment(&p, false).unwrap(),
            &out,
            &NoProgress,
        )
        .unwrap();
        assert!(a.files == b.files);
        assert_eq!(a.warnings, b.warnings);
    }

    #[test]
    fn defaults_agree_between_clap_serde_and_default() {
        let from_ron: Params = ron::from_str("()").unwrap();
        assert_eq!(from_ron, Params::default());
        assert_eq!(Params::default().alphas, vec![0.2, 0.4667, 0.7333, 1.0]);
        assert_eq!(Params::default().rows(), 16384);
        assert!(ron::from_str::<Params>("(p_ordr: 3)").is_err());
    }

    #[test]
    fn bad_parameters_are_refused() {
        for p in [
            Params {
                p_order: 0,
                ..Default::default()
            },
            Params {
                alphas: vec![],
                ..Default::default()
            },
            Params {
                alphas: vec![0.0],
                ..Default::default()
            },
            Params {
                alphas: vec![f32::NAN],
                ..Default::default()
            },
            Params {
                normals: 2,
                views: 2,
                alphas: vec![0.5],
                ..Default::default()
            },
            Params {
                samples: 0,
                ..Default::default()
            },
            Params {
                floor: 0.0,
                ..Default::default()
            },
            Params {
                log_weight: -1.0,
                ..Default::default()
            },
            Params {
                log_weight: f64::NAN,
                ..Default::default()
            },
            Params {
                refine_iterations: 1001,
                ..Default::default()
            },
            Params {
                alpha_knots: vec![0.5],
                ..Default::default()
            },
            Params {
                alpha_knots: vec![0.6, 0.3],
                ..Default::default()
            },
            Params {
                alpha_knots: vec![0.2, 1.5],
                ..Default::default()
            },
            Params {
                alpha_knots: vec![0.2, f32::NAN],
                ..Default::default()
            },
            Params {
                // No --alphas value between 0.25 and 0.3 for the knot 0.28.
                alpha_knots: vec![0.25, 0.28, 0.3, 1.0],
                ..Default::default()
            },
        ] {
            assert!(p.validate().is_err(), "{p:?}");
        }
    }

    /// Known coefficients for span tests, varied by `seed`.
    fn known_coefficients(k: usize, seed: f64) -> Vec<[f64; 3]> {
        (0..k)
            .map(|i| {
                [
                    (i as f64 * 0.37 + seed).sin() * 0.5,
                    (i as f64 * 0.11 - seed).cos() * 0.3,
                    0.05 * (i as f64 + seed) / k as f64,
                ]
            })
            .collect()
    }

    /// Rows of `params`' geometry whose log E0 is exactly eq. 14's row · `x_at(α)`.
    fn span_rows(params: &Params, x_at: &dyn Fn(f32) -> Vec<[f64; 3]>) -> Rows {
        let views: Vec<Vec3> = (0..params.views)
            .map(|k| basis::fibonacci_hemisphere(k, params.views))
            .collect();
        let (p, q) = (params.p_order, params.q_order);
        let k = num_unknowns(p, q);
        let mut rows = Rows {
            p_order: p,
            q_order: q,
            alphas: params.alphas.clone(),
            features: vec![],
            n_dot_v: vec![],
            e0: vec![],
            normals: params.normals,
            views: params.views,
        };
        let mut row = vec![0.0f64; k];
        for i in 0..params.normals {
            let (frame, world) = row_geometry(i, params.normals, &views);
            for v in world {
                let mut f = Features::new(p, q);
                f.eval(frame.2, v);
                for &alpha in &params.alphas {
                    f.row(&basis::vmf_factors(p, alpha), &mut row);
                    let x = x_at(alpha);
                    let mut e = [0.0; 3];
                    for (c, ec) in e.iter_mut().enumerate() {
                        *ec = row.iter().zip(&x).map(|(a, x)| a * x[c]).sum::<f64>().exp();
                    }
                    rows.e0.push(e);
                }
                rows.n_dot_v.push(frame.2.dot(v));
                rows.features.push(f);
            }
        }
        rows
    }

    fn log_only() -> SolveOptions {
        SolveOptions {
            floor: [1e-30; 3],
            weight_power: 0.0,
            cosine_weight: false,
            target: Target::E0,
            objective: Objective::Log,
            log_weight: 0.0,
            refine_iterations: 0,
        }
    }

    #[test]
    fn span_reconstruction_is_exact() {
        // Solver correctness: a target log E0 that lies in the model's span (built from known
        // p, q through the same features) is recovered to round-off.
        let params = small_params();
        let views: Vec<Vec3> = (0..params.views)
            .map(|k| basis::fibonacci_hemisphere(k, params.views))
            .collect();
        let (p, q) = (params.p_order, params.q_order);
        let x_true = known_coefficients(num_unknowns(p, q), 0.0);
        let rows = span_rows(&params, &|_| x_true.clone());
        let (pc, qc, res, cond) = solve_rows(&rows, &log_only()).unwrap();
        let got: Vec<[f32; 3]> = pc.iter().chain(&qc).cloned().collect();
        let err = got
            .iter()
            .zip(&x_true)
            .flat_map(|(g, t)| (0..3).map(move |c| (g[c] as f64 - t[c]).abs()))
            .fold(0.0, f64::max);
        eprintln!("span test: max coefficient error {err:.2e}, residual {res:?}, κ = {cond:.1}");
        assert!(err < 1e-5, "{err}");
        assert!(res.iter().all(|r| *r < 1e-9));
        // And the reconstruction of eq. 11 through `Coeffs::e0` reproduces the targets.
        let c = Coeffs {
            p: pc,
            q: qc,
            residual_rgb: res,
            condition_number: cond,
            ..Coeffs::zeros(p, q, params.alphas.clone())
        };
        let (frame, world) = row_geometry(5, params.normals, &views);
        let e = c.e0(frame.2, world[3], params.alphas[1]);
        let want = rows.e0[(5 * params.views + 3) * 3 + 1];
        for ch in 0..3 {
            assert!(
                (e[ch] as f64 / want[ch] - 1.0).abs() < 1e-4,
                "{e:?} {want:?}"
            );
        }
    }

    #[test]
    fn knot_span_reconstruction_is_exact() {
        // Coefficients that are piecewise linear in α between three knots (known sets at the
        // knots, hat-interpolated between): the knot solve recovers every set to round-off,
        // and `Coeffs::e0` with those knots reproduces E0 at an α no row was fitted at.
        let params = Params {
            alphas: vec![0.2, 0.35, 0.5, 0.75, 1.0],
            ..small_params()
        };
        let knots = [0.2f32, 0.5, 1.0];
        let k = num_unknowns(params.p_order, params.q_order);
        let sets: Vec<Vec<[f64; 3]>> = (0..3).map(|s| known_coefficients(k, s as f64)).collect();
        let x_at = |alpha: f32| -> Vec<[f64; 3]> {
            let ((s0, w0), (s1, w1)) = basis::knot_weights(&knots, alpha);
            (0..k)
                .map(|i| {
                    std::array::from_fn(|c| w0 as f64 * sets[s0][i][c] + w1 as f64 * sets[s1][i][c])
                })
                .collect()
        };
        let rows = span_rows(&params, &x_at);
        let (pk, qk, res, _) = solve_rows_knots(&rows, &log_only(), &knots).unwrap();
        assert_eq!((pk.len(), qk.len()), (3, 3));
        let mut err = 0.0f64;
        for s in 0..3 {
            for (g, t) in pk[s].iter().chain(&qk[s]).zip(&sets[s]) {
                for c in 0..3 {
                    err = err.max((g[c] as f64 - t[c]).abs());
                }
            }
        }
        eprintln!("knot span test: max coefficient error {err:.2e}, residual {res:?}");
        assert!(err < 1e-5, "{err}");
        // Eq. 11 alone (one set) cannot hold it.
        let (_, _, res1, _) = solve_rows(&rows, &log_only()).unwrap();
        assert!(res1[0] > 1e-2 && res1[1] > 1e-2, "{res1:?}");
        // Reconstruction at α = 0.62 (between knots 0.5 and 1, no row there).
        let mut co = Coeffs::zeros(params.p_order, params.q_order, params.alphas.clone());
        co.alpha_knots = Some(crate::coeffs::AlphaKnots {
            alphas: knots.to_vec(),
            p: pk,
            q: qk,
            residual: 0.0,
        });
        let views: Vec<Vec3> = (0..params.views)
            .map(|k| basis::fibonacci_hemisphere(k, params.views))
            .collect();
        let (frame, world) = row_geometry(7, params.normals, &views);
        let (n, v) = (frame.2, world[4]);
        let mut f = Features::new(params.p_order, params.q_order);
        f.eval(n, v);
        let mut row = vec![0.0f64; k];
        f.row(&basis::vmf_factors(params.p_order, 0.62), &mut row);
        let x = x_at(0.62);
        let e = co.e0(n, v, 0.62);
        for c in 0..3 {
            let want: f64 = row.iter().zip(&x).map(|(a, x)| a * x[c]).sum::<f64>().exp();
            assert!((e[c] as f64 / want - 1.0).abs() < 1e-4, "{e:?} vs {want}");
        }
    }

    #[test]
    fn knots_follow_the_albedo_that_eq_11_cannot() {
        // L = c: E0 = c·(A+B)(n·v, α). Eq. 11's only α dependence is the vMF damping of bands
        // ≥ 1, so its DC cannot follow the albedo's fall with α; knots let the DC move with α.
        let params = Params {
            samples: 256,
            objective: Objective::Log,
            alphas: vec![0.2, 0.4, 0.6, 0.8, 1.0],
            alpha_knots: vec![0.2, 0.6, 1.0],
            ..small_params()
        };
        let c = 2.5f32;
        let co = fit_cube(&params, &Cubemap::constant(16, [c; 3]), &NoProgress)
            .unwrap()
            .coeffs;
        let knots = co.alpha_knots.as_ref().unwrap();
        eprintln!(
            "constant env: log RMS residual eq. 11 {:.4}, with knots {:.4}",
            co.residual, knots.residual
        );
        assert!(
            knots.residual < 0.75 * co.residual,
            "{} vs {}",
            knots.residual,
            co.residual
        );
        // Mean level at n = v (where A+B is largest) follows the albedo at both ends.
        let reference = ibl_lut::reference::DfgReference::new(256);
        for alpha in [0.2f32, 1.0] {
            let [a, b] = reference.dfg(1.0, alpha as f64);
            let e = co.e0(Vec3::Z, Vec3::Z, alpha)[0] as f64 / c as f64;
            let e11 = co.eq11().e0(Vec3::Z, Vec3::Z, alpha)[0] as f64 / c as f64;
            eprintln!(
                "α = {alpha}: albedo {:.3}, knots {e:.3}, eq. 11 {e11:.3}",
                a + b
            );
            assert!((e - (a + b)).abs() < (e11 - (a + b)).abs() + 1e-3);
        }
    }

    #[test]
    fn knots_lower_the_held_out_error_on_a_sun_sky() {
        let sun = Vec3::new(0.4, 0.6, -0.7).normalize();
        let cube = Cubemap::from_fn(16, |d| {
            let s = if d.dot(sun) > 0.985 { 300.0 } else { 0.0 };
            [0.5 + 0.3 * d.y + s, 0.6 + 0.2 * d.y + s, 0.9 + s]
        });
        let truth = TexelSet::from_cube(&cube);
        let alphas = [0.25, 0.4, 0.6, 0.8, 1.0];
        let plain = fit_cube(&small_params(), &cube, &NoProgress)
            .unwrap()
            .coeffs;
        let knotted = Params {
            alpha_knots: vec![0.2, 1.0],
            cosine_weight: true,
            log_weight: 0.0,
            ..small_params()
        };
        let co = fit_cube(&knotted, &cube, &NoProgress).unwrap().coeffs;
        let (e_plain, e_knots) = (
            held_out_relative_mse(&plain, &truth, &alphas),
            held_out_relative_mse(&co, &truth, &alphas),
        );
        eprintln!(
            "sun sky, held-out relative linear MSE: eq. 11 {e_plain:.4}, knots 0.2,1 {e_knots:.4}"
        );
        assert!(e_knots < 0.8 * e_plain, "{e_knots} vs {e_plain}");
        assert_eq!(co.bytes(), 2 * plain.bytes());
    }

    #[test]
    fn constant_environment_fits_the_mean_log_albedo() {
        // L = c: E0 = c·(A+B)(n·v, α), which eq. 11 cannot follow (it depends on r·h_r and α
        // through the undamped DC only); by rotation invariance the least-squares optimum is
        // the DC alone, exp(mean over rows of log E0). Check the targets against the DFG-like
        // integral and the fit against that optimum.
        let params = Params {
            estimator: EstimatorKind::Mc,
            samples: 512,
            objective: Objective::Log,
            ..small_params()
        };
        let c = 2.5f32;
        let cube = Cubemap::constant(16, [c, c, c]);
        let mut timings = Timings::default();
        let rows = estimate_rows(&params, &cube, &mut timings, &NoProgress);
        let na = params.alphas.len();
        let reference = ibl_lut::reference::DfgReference::new(256);
        let mut worst = 0.0f64;
        let mut mean_log = 0.0f64;
        for (r, e) in rows.e0.iter().enumerate() {
            let nv = rows.n_dot_v[r / na];
            let alpha = params.alphas[r % na];
            if r % 97 == 0 {
                let [a, b] = reference.dfg((nv as f64).clamp(1e-4, 1.0), alpha as f64);
                worst = worst.max((e[0] / (c as f64 * (a + b)) - 1.0).abs());
            }
            mean_log += e[0].ln();
        }
        mean_log /= rows.e0.len() as f64;
        eprintln!(
            "constant env: max relative error of E0 targets vs the albedo integral {worst:.2e}"
        );
        assert!(worst < 0.01, "{worst}");
        let fitted = fit_cube(&params, &cube, &NoProgress).unwrap();
        let co = &fitted.coeffs;
        let dc = (co.p[0][0] * 0.282_094_8) as f64;
        let logs: Vec<f64> = rows.e0.iter().map(|e| e[0].ln()).collect();
        let std_log =
            (logs.iter().map(|l| (l - mean_log).powi(2)).sum::<f64>() / logs.len() as f64).sqrt();
        eprintln!(
            "constant env: fitted exp(DC) = {:.4}, exp(mean log E0) = {:.4}, residual {:.4} vs std of log E0 {std_log:.4}; targets span {:.3}..{:.3} (×1/c: the albedo)",
            dc.exp(),
            mean_log.exp(),
            co.residual,
            logs.iter().cloned().fold(f64::INFINITY, f64::min).exp(),
            logs.iter().cloned().fold(f64::NEG_INFINITY, f64::max).exp(),
        );
        assert!((dc - mean_log).abs() < 0.02, "{dc} vs {mean_log}");
        // The non-DC terms can only use sampling correlations: the residual stays near the
        // spread of log E0, i.e. eq. 11 cannot represent the albedo's n·v and α dependence.
        assert!(
            co.residual <= std_log + 1e-9 && co.residual > 0.85 * std_log,
            "{} vs {std_log}",
            co.residual
        );
    }

    #[test]
    fn black_hemisphere_gives_a_finite_fit_that_follows_the_bright_side() {
        // Lower hemisphere black, upper a smooth sky: the floor keeps every log finite; the
        // reconstruction must stay finite everywhere and track E0 where the lobe sees the sky.
        let cube = Cubemap::from_fn(16, |d| {
            if d.y > 0.0 {
                [1.0 + d.y, 1.0, 0.5 + 0.5 * d.x.abs()]
            } else {
                [0.0; 3]
            }
        });
        let params = small_params();
        let fitted = fit_cube(&params, &cube, &NoProgress).unwrap();
        let co = &fitted.coeffs;
        assert!(co.p.iter().chain(&co.q).flatten().all(|v| v.is_finite()));
        let truth = TexelSet::from_cube(&cube);
        let mut worst_bright = 0.0f64;
        let mut worst_dark = 0.0f64;
        for i in 0..200 {
            let n = basis::fibonacci_sphere(i, 200);
            let v = (n + Vec3::new(0.1, 0.2, -0.1)).normalize();
            if n.dot(v) <= 0.05 {
                continue;
            }
            let e = co.e0(n, v, 0.6);
            assert!(e.iter().all(|x| x.is_finite() && *x >= 0.0));
            let t = truth.e0(n, v, 0.6);
            if n.y > 0.7 && v.y > 0.5 {
                worst_bright = worst_bright.max((e[0] as f64 / t[0] - 1.0).abs());
            }
            if n.y < -0.7 && v.y < -0.5 {
                worst_dark = worst_dark.max(e[0] as f64);
            }
        }
        eprintln!("black hemisphere: worst relative error facing the sky {worst_bright:.3}, worst E0 facing the black ground {worst_dark:.3e}, residual {:.3}", co.residual);
        assert!(worst_bright < 0.25, "{worst_bright}");
        assert!(worst_dark < 0.2, "{worst_dark}");
    }

    /// Relative linear MSE of a probe's E0 against exact summation at held-out (n, v, α),
    /// averaged over the α values (each normalised by its Σ truth², as the fit's groups).
    fn held_out_relative_mse(co: &Coeffs, truth: &TexelSet, alphas: &[f32]) -> f64 {
        let mut rng = ibl_core::sampling::Pcg32::new(77, 5);
        let mut uniform_sphere = || {
            let z = 1.0 - 2.0 * rng.next_f32();
            let phi = std::f32::consts::TAU * rng.next_f32();
            let s = (1.0 - z * z).max(0.0).sqrt();
            Vec3::new(s * phi.cos(), s * phi.sin(), z)
        };
        let pairs: Vec<(Vec3, Vec3)> = (0..300)
            .map(|_| {
                let n = uniform_sphere();
                let mut v = uniform_sphere();
                if v.dot(n) < 0.0 {
                    v = -v;
                }
                (n, v)
            })
            .collect();
        alphas
            .iter()
            .map(|&a| {
                let (mut err, mut energy) = (0.0f64, 0.0f64);
                for &(n, v) in &pairs {
                    let e = co.e0(n, v, a);
                    let t = truth.e0(n, v, a);
                    for c in 0..3 {
                        err += (e[c] as f64 - t[c]).powi(2);
                        energy += t[c] * t[c];
                    }
                }
                err / energy
            })
            .sum::<f64>()
            / alphas.len() as f64
    }

    #[test]
    fn relative_refinement_lowers_the_linear_error_at_held_out_directions() {
        // A dim sky with a bright sun: the log-space fit spends its accuracy on the dim rows;
        // the refinement must lower the linear error where no row was fitted, at α between and
        // on the fitted ones, without losing the log-space fit's finiteness.
        let sun = Vec3::new(0.4, 0.6, -0.7).normalize();
        let cube = Cubemap::from_fn(16, |d| {
            let s = if d.dot(sun) > 0.985 { 300.0 } else { 0.0 };
            [0.5 + 0.3 * d.y + s, 0.6 + 0.2 * d.y + s, 0.9 + s]
        });
        let log = Params {
            objective: Objective::Log,
            ..small_params()
        };
        let rel = Params {
            objective: Objective::Relative,
            ..small_params()
        };
        let truth = TexelSet::from_cube(&cube);
        let alphas = [0.25, 0.4, 0.6, 0.8, 1.0];
        let co_log = fit_cube(&log, &cube, &NoProgress).unwrap().coeffs;
        let co_rel = fit_cube(&rel, &cube, &NoProgress).unwrap().coeffs;
        assert_eq!(co_rel.objective, Objective::Relative);
        let (e_log, e_rel) = (
            held_out_relative_mse(&co_log, &truth, &alphas),
            held_out_relative_mse(&co_rel, &truth, &alphas),
        );
        eprintln!(
            "sun sky, held-out relative linear MSE: log fit {e_log:.4}, relative refinement {e_rel:.4}; log RMS residual {:.3} → {:.3}",
            co_log.residual, co_rel.residual
        );
        assert!(e_rel < 0.8 * e_log, "{e_rel} vs {e_log}");
        assert!(co_rel
            .p
            .iter()
            .chain(&co_rel.q)
            .flatten()
            .all(|v| v.is_finite()));
    }

    #[test]
    fn black_environment_is_refused() {
        let r = fit_cube(
            &small_params(),
            &Cubemap::constant(4, [0.0; 3]),
            &NoProgress,
        );
        assert!(r.is_err());
    }

    #[test]
    fn fit_is_deterministic_across_thread_counts() {
        let cube = Cubemap::from_fn(16, |d| [1.0 + d.x.max(0.0) * 5.0, 1.0 + d.y, 1.0]);
        let params = small_params();
        ibl_testkit::thread_count_independent(&[1, 2, 3], || {
            fit_cube(&params, &cube, &NoProgress).unwrap().coeffs
        });
    }

    #[test]
    fn mc_targets_agree_with_exact_summation() {
        // The MC + filtered-importance-sampling E0 against exact texel summation on a smooth
        // environment (FIS blurs, so only smooth content is compared tightly).
        let cube = Cubemap::from_fn(32, |d| {
            [1.0 + 0.8 * d.x, 1.0 + 0.5 * d.y * d.z, (1.5 + d.z).powi(2)]
        });
        let params = Params {
            samples: 512,
            ..small_params()
        };
        let mut t = Timings::default();
        let mc = estimate_rows(&params, &cube, &mut t, &NoProgress);
        let ex = estimate_rows(
            &Params {
                estimator: EstimatorKind::Exact,
                ..params.clone()
            },
            &cube,
            &mut t,
            &NoProgress,
        );
        let mut worst = 0.0f64;
        let mut rms = 0.0f64;
        for (a, b) in mc.e0.iter().zip(&ex.e0) {
            for c in 0..3 {
                let d = (a[c] / b[c]).ln();
                worst = worst.max(d.abs());
                rms += d * d;
            }
        }
        rms = (rms / (3 * mc.e0.len()) as f64).sqrt();
        eprintln!("MC+FIS vs exact E0: log RMS {rms:.2e}, worst {worst:.2e}");
        assert!(rms < 0.01 && worst < 0.06, "{rms} {worst}");
    }
}
