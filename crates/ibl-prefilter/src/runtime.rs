//! The error an engine's own lookup sees: emulates a target's read of a baked chain (its
//! level ↔ roughness mapping, bilinear within a level and seamless across faces through
//! `ibl_core::bordered`, linear between levels) at continuous roughness and at directions
//! between texel centres, against the exact GGX-prefiltered radiance at that roughness.

pub use crate::custom::CustomLookup;

use crate::kernel::SourceTexels;
use crate::stats::ErrorStats;
use crate::tree::{tree_convolve, tree_convolve_many, CellTree, TreeBuffers, TreeParams};
use glam::Vec3;
use ibl_core::bordered::BorderedMips;
use ibl_core::cube::{CubeMips, Cubemap};
use ibl_core::{luminance, Rgb};
use ibl_target::{LodMapping, Target};
use serde::Serialize;

/// Roughness values of the report: k/32, k = 0 … 32.
pub(crate) const ROUGHNESS_STEPS: usize = 33;
/// Directions of the report (a modest count: the sidecar must not dominate the bake).
pub const REPORT_DIRECTIONS: usize = 128;

/// `steps` roughness values evenly spaced over [0, 1].
pub(crate) fn roughness_grid(steps: usize) -> Vec<f32> {
    let d = steps.saturating_sub(1).max(1) as f32;
    (0..steps).map(|k| k as f32 / d).collect()
}

/// `n` low-discrepancy unit directions (a spherical Fibonacci lattice, turned by an
/// irrational angle so no point falls on a texel centre or a face edge of any level).
pub fn probe_directions(n: usize) -> Vec<Vec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let (s, c) = (0.7390851332f64.sin(), 0.7390851332f64.cos());
    (0..n)
        .map(|k| {
            let z = 1.0 - (2 * k + 1) as f64 / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * k as f64 + 0.5772156649;
            let (x, y) = (r * phi.cos(), r * phi.sin());
            // Tilt about x so the lattice's poles are not on the cube's axes.
            Vec3::new(x as f32, (y * c - z * s) as f32, (y * s + z * c) as f32)
        })
        .collect()
}

/// A target's read of a chain: the lod its shader asks for roughness `r` (clamped to the chain
/// as a sampler does), then a seamless trilinear tap.
pub fn lookup(chain: &BorderedMips, mapping: LodMapping, d: Vec3, r: f32) -> Rgb {
    let lod = mapping.lod(r, chain.num_levels(), chain.size());
    chain.sample(d, lod)
}

/// The exact prefiltered radiance the lookup is compared with.
pub enum Reference<'a> {
    /// The exact kernel summed hierarchically (the bake's default method; measured within
    /// 0.02% of the brute force at the default preset), roughness 0 the source itself
    /// (bilinear).
    Tree {
        /// The source's cell hierarchy.
        tree: &'a CellTree,
        /// The source cube (roughness 0 reads it directly).
        source: &'a Cubemap,
        /// The tree method's knobs.
        params: TreeParams,
    },
    /// The exact kernel summed over every source texel (`--reference`): slow, for tests.
    Brute {
        /// Every source texel.
        texels: &'a SourceTexels,
        /// The source cube (roughness 0 reads it directly).
        source: &'a Cubemap,
    },
    /// Another reference's values at the report's directions and roughness values, computed
    /// beforehand ([`Reference::table`]). It answers only there: a read at any other direction
    /// or roughness panics (a caller's error, not an input's).
    Table(&'a ReferenceTable),
}

/// A reference's values at a report's directions and roughness values. The bake computes it
/// before its lookup fit and lets the cell tree go: the fit's peak memory no longer holds the
/// tree (100 MB of the 512² bake's 197).
pub struct ReferenceTable {
    dirs: Vec<Vec3>,
    roughness: Vec<f32>,
    /// `values[direction][roughness]`.
    values: Vec<Vec<Rgb>>,
    name: &'static str,
}

impl ReferenceTable {
    /// The values at direction `d` (one of the table's) for every roughness of `roughness`
    /// (each one of the table's).
    fn at(&self, d: Vec3, roughness: &[f32]) -> Vec<Rgb> {
        let i = self
            .dirs
            .iter()
            .position(|&x| x == d)
            .expect("a reference table answers at its own directions");
        roughness
            .iter()
            .map(|r| {
                let k = self
                    .roughness
                    .iter()
                    .position(|x| x == r)
                    .expect("a reference table answers at its own roughness values");
                self.values[i][k]
            })
            .collect()
    }
}

/// The reference at every direction of `dirs` and roughness of `roughness`
/// (`[direction][roughness]`). Parallel over directions, collected in order: the same bits
/// for any thread count.
fn reference_values(reference: &Reference, roughness: &[f32], dirs: &[Vec3]) -> Vec<Vec<Rgb>> {
    use rayon::prelude::*;
    dirs.par_iter()
        .map_init(TreeBuffers::default, |buf, &d| {
            reference.radiance_many(d, roughness, buf)
        })
        .collect()
}

impl Reference<'_> {
    /// Radiance prefiltered at roughness `r` in direction `d`.
    pub fn radiance(&self, d: Vec3, r: f32, buffers: &mut TreeBuffers) -> Rgb {
        match self {
            Reference::Tree { source, .. } | Reference::Brute { source, .. } if r <= 0.0 => {
                source.sample_bilinear(d)
            }
            Reference::Tree { tree, params, .. } => tree_convolve(tree, d, r, params, buffers),
            Reference::Brute { texels, .. } => texels.convolve(d.normalize(), r * r),
            Reference::Table(t) => t.at(d, &[r])[0],
        }
    }

    /// [`Self::radiance`] at every roughness of `roughness` (the tree shares its cuts
    /// between roughness values of one leaf level: `crate::tree::tree_convolve_many`).
    pub fn radiance_many(&self, d: Vec3, roughness: &[f32], buffers: &mut TreeBuffers) -> Vec<Rgb> {
        match self {
            Reference::Tree {
                tree,
                params,
                source,
            } => {
                let mut out = vec![[0.0f32; 3]; roughness.len()];
                let (idx, rs): (Vec<usize>, Vec<f32>) = roughness
                    .iter()
                    .enumerate()
                    .filter(|(_, &r)| r > 0.0)
                    .map(|(k, &r)| (k, r))
                    .unzip();
                let mut vals = vec![[0.0f32; 3]; rs.len()];
                tree_convolve_many(tree, d, &rs, params, buffers, &mut vals);
                for (k, v) in idx.into_iter().zip(vals) {
                    out[k] = v;
                }
                for (o, &r) in out.iter_mut().zip(roughness) {
                    if r <= 0.0 {
                        *o = source.sample_bilinear(d);
                    }
                }
                out
            }
            Reference::Brute { .. } => roughness
                .iter()
                .map(|&r| self.radiance(d, r, buffers))
                .collect(),
            Reference::Table(t) => t.at(d, roughness),
        }
    }

    /// This reference's values at the report's roughness values and `directions` directions
    /// (those [`evaluate_with`] and [`evaluate_custom`] read), to be read as
    /// [`Reference::Table`] once this one is gone.
    pub fn table(&self, directions: usize) -> ReferenceTable {
        let roughness = roughness_grid(ROUGHNESS_STEPS);
        let dirs = probe_directions(directions);
        let values = reference_values(self, &roughness, &dirs);
        ReferenceTable {
            dirs,
            roughness,
            values,
            name: self.name(),
        }
    }

    /// Name written into the report.
    pub fn name(&self) -> &'static str {
        match self {
            Reference::Tree { .. } => "exact GGX kernel, hierarchical sum (cell tree)",
            Reference::Brute { .. } => "exact GGX kernel, brute force over every source texel",
            Reference::Table(t) => t.name,
        }
    }
}

/// Mean absolute relative error of luminance of the lookup against the reference, per
/// roughness (references below 1e-6 of their mean skipped, see [`ErrorStats::from_pairs`]).
/// Parallel over roughness, ordered sums: deterministic.
pub fn mean_abs_rel(
    chain: &BorderedMips,
    mapping: LodMapping,
    roughness: &[f32],
    dirs: &[Vec3],
    reference: &Reference,
) -> Vec<f64> {
    abs_rel_stats(chain, mapping, roughness, dirs, reference)
        .into_iter()
        .map(|s| s.mean)
        .collect()
}

/// The lookup's error at one roughness over the directions.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct AbsRel {
    /// Mean |lookup − exact| / exact of luminance.
    pub mean: f64,
    /// Its 99th percentile over the directions (nearest rank): the worst direction a mean
    /// hides, such as a ring beside a sun.
    pub p99: f64,
}

/// Nearest-rank `q` quantile of `v` (sorted in place).
pub fn quantile(v: &mut [f64], q: f64) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let k = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[k - 1]
}

/// Mean and 99th percentile of the absolute relative error of luminance of the lookup against
/// the reference, per roughness (references below 1e-6 of their mean skipped, as
/// [`ErrorStats::from_pairs`] does). Parallel over roughness, ordered sums: deterministic.
pub fn abs_rel_stats(
    chain: &BorderedMips,
    mapping: LodMapping,
    roughness: &[f32],
    dirs: &[Vec3],
    reference: &Reference,
) -> Vec<AbsRel> {
    abs_rel_stats_of(
        &|d, r| lookup(chain, mapping, d, r),
        roughness,
        dirs,
        reference,
    )
}

/// [`abs_rel_stats`] of any read `read(d, r)` (the custom lookup's two taps).
pub fn abs_rel_stats_of(
    read: &(dyn Fn(Vec3, f32) -> Rgb + Sync),
    roughness: &[f32],
    dirs: &[Vec3],
    reference: &Reference,
) -> Vec<AbsRel> {
    // The reference per direction at every roughness at once (one cut per group of roughness
    // values sharing a leaf level, not one per roughness: the report cost 9% of the bake),
    // then the statistics per roughness; a table made at these directions is read as it is.
    let computed;
    let refs: &[Vec<Rgb>] = match reference {
        Reference::Table(t) if t.dirs == dirs && t.roughness == roughness => &t.values,
        _ => {
            computed = reference_values(reference, roughness, dirs);
            &computed
        }
    };
    roughness
        .iter()
        .enumerate()
        .map(|(k, &r)| {
            let pairs: Vec<(f64, f64)> = dirs
                .iter()
                .zip(refs)
                .map(|(&d, y)| {
                    let x = read(d, r);
                    (luminance(x) as f64, luminance(y[k]) as f64)
                })
                .collect();
            let mean_ref = pairs.iter().map(|p| p.1).sum::<f64>() / pairs.len().max(1) as f64;
            let floor = 1e-6 * mean_ref.max(1e-30);
            let mut e: Vec<f64> = pairs
                .iter()
                .filter(|p| p.1 > floor)
                .map(|(x, y)| ((x - y) / y).abs())
                .collect();
            AbsRel {
                mean: ErrorStats::from_pairs(pairs).mean_abs_rel,
                p99: quantile(&mut e, 0.99),
            }
        })
        .collect()
}

/// What `prefilter.json` records under `"runtime"`.
#[derive(Clone, Debug, Serialize)]
pub struct RuntimeReport {
    /// The engine whose lookup was evaluated.
    pub target: Target,
    /// The target's level ↔ roughness mapping as its shader computes the lod.
    pub lookup: &'static str,
    /// Continuous roughness values evaluated.
    pub roughness: Vec<f32>,
    /// Mean |lookup − exact| / exact of luminance at each roughness.
    pub mean_abs_rel: Vec<f64>,
    /// The 99th percentile of |lookup − exact| / exact over the directions at each roughness.
    pub p99_abs_rel: Vec<f64>,
    /// Directions per roughness (low-discrepancy, between texel centres).
    pub directions: usize,
    /// What the lookups were compared with.
    pub reference: &'static str,
    /// The pixel format the looked-up chain was decoded from (the engine samples the decoded
    /// texels; rgba32f is the float chain itself).
    pub format: &'static str,
}

/// Evaluates `target`'s lookup of `mips` (as baked, in our frame: the targets' orientations
/// are exact texel permutations and do not change the error).
pub fn evaluate(
    mips: &CubeMips,
    target: Target,
    directions: usize,
    reference: &Reference,
) -> RuntimeReport {
    evaluate_with(mips, target, target.spec().lod, directions, reference)
}

/// [`evaluate`] through `mapping` (the custom lookup's constants are the bake's).
pub fn evaluate_with(
    mips: &CubeMips,
    target: Target,
    mapping: LodMapping,
    directions: usize,
    reference: &Reference,
) -> RuntimeReport {
    let chain = BorderedMips::new(mips);
    report_of(
        &|d, r| lookup(&chain, mapping, d, r),
        target,
        mapping,
        directions,
        reference,
    )
}

/// The report of any read at the report's roughness values and `directions` directions.
fn report_of(
    read: &(dyn Fn(Vec3, f32) -> Rgb + Sync),
    target: Target,
    mapping: LodMapping,
    directions: usize,
    reference: &Reference,
) -> RuntimeReport {
    let roughness = roughness_grid(ROUGHNESS_STEPS);
    let dirs = probe_directions(directions);
    let stats = abs_rel_stats_of(read, &roughness, &dirs, reference);
    RuntimeReport {
        target,
        lookup: mapping.name(),
        mean_abs_rel: stats.iter().map(|s| s.mean).collect(),
        p99_abs_rel: stats.iter().map(|s| s.p99).collect(),
        roughness,
        directions,
        reference: reference.name(),
        format: "rgba32f",
    }
}

/// [`evaluate`] of the custom lookup: its two taps and the polynomial through the midpoints
/// ([`CustomLookup::read`]) on `chain` as baked.
pub fn evaluate_custom(
    chain: &crate::custom::CustomChain,
    lk: &CustomLookup,
    directions: usize,
    reference: &Reference,
) -> RuntimeReport {
    report_of(
        &|d, r| lk.read(chain, d, r),
        Target::Custom,
        LodMapping::Custom { alpha0: lk.alpha0 },
        directions,
        reference,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::{bake_chain, Params, Quality};
    use ibl_core::cube::Face;
    use ibl_core::envmap::Environment;
    use ibl_core::progress::NoProgress;

    fn sky(n: usize) -> Cubemap {
        // A bright patch, a gradient and a dark floor: relative errors are meaningful
        // everywhere and a sun-like feature makes the lookup's between-level blend visible.
        Cubemap::from_fn(n, |d| {
            let d = d.normalize();
            let sun = (d.dot(Vec3::new(0.4, 0.7, 0.59).normalize()) - 0.97).max(0.0) * 300.0;
            let base = 0.2 + 0.8 * d.y.max(0.0) + 0.1 * (3.0 * d.x).sin().abs();
            [base + sun, base * 0.9 + sun, base * 0.7 + 0.5 * sun]
        })
    }

    /// The sky of `n`² faces and its chain baked with `params`.
    fn sky_chain(n: usize, params: &Params) -> (Cubemap, crate::bake::Chain) {
        let src = sky(n);
        let env = Environment::Cube(src.clone());
        let chain = bake_chain(params, &env, &NoProgress).unwrap();
        (src, chain)
    }

    #[test]
    fn grids_and_directions() {
        let r = roughness_grid(33);
        assert_eq!((r.len(), r[0], r[32]), (33, 0.0, 1.0));
        let d = probe_directions(500);
        assert!(d.iter().all(|v| (v.length() - 1.0).abs() < 1e-5));
        // Spread over all six faces, never exactly on a texel centre of an 8² face.
        let mut faces = [0usize; 6];
        for v in &d {
            let (f, sc, tc) = Face::from_direction(*v);
            faces[f as usize] += 1;
            let off = |c: f32| ((c + 1.0) * 4.0).fract();
            assert!((off(sc) - 0.5).abs() > 1e-4 || (off(tc) - 0.5).abs() > 1e-4);
        }
        assert!(faces.iter().all(|&k| k > 50), "{faces:?}");
    }

    /// Independent check: the lookup recomputed by hand for a few directions (lod by the
    /// engine's formula, the core's own bilinear sampler per level, linear blend) and the
    /// reference by brute force over every source texel; the mean over them matches what
    /// `mean_abs_rel` reports with the tree reference.
    #[test]
    fn lookup_and_error_match_a_brute_force_recomputation() {
        let params = Params {
            size: 16,
            levels: Some(5),
            quality: Quality::High,
            ..Default::default()
        };
        let (src, chain) = sky_chain(32, &params);
        let bordered = BorderedMips::new(&chain.mips);
        let texels = SourceTexels::new(&src);
        let tree = CellTree::new(&src);
        let brute = Reference::Brute {
            texels: &texels,
            source: &src,
        };
        let fast = Reference::Tree {
            tree: &tree,
            source: &src,
            params: Quality::High.tree_params(),
        };
        let dirs = probe_directions(40);
        for (target, rs) in [
            (Target::Gltf, [0.13f32, 0.4, 0.77, 1.0]),
            (Target::Filament, [0.2, 0.5, 0.6, 0.9]),
            (Target::Unity, [0.1, 0.35, 0.7, 0.95]),
        ] {
            let m = target.spec().lod;
            let levels = chain.mips.levels.len();
            let got = mean_abs_rel(&bordered, m, &rs, &dirs, &fast);
            for (k, &r) in rs.iter().enumerate() {
                let lod = match target {
                    Target::Gltf => r * (levels - 1) as f32,
                    Target::Filament => (levels - 1) as f32 * r * (2.0 - r),
                    _ => (6.0 * r * (1.7 - 0.7 * r)).min((levels - 1) as f32),
                };
                let (l0, t) = (lod.floor() as usize, lod.fract());
                let mut sum = 0.0f64;
                let mut buf = TreeBuffers::default();
                for &d in &dirs {
                    let a = chain.mips.levels[l0].sample_bilinear(d);
                    let b = chain.mips.levels[(l0 + 1).min(levels - 1)].sample_bilinear(d);
                    let x = luminance([0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * t)) as f64;
                    let y = luminance(brute.radiance(d, r, &mut buf)) as f64;
                    sum += ((x - y) / y).abs();
                }
                let mean = sum / dirs.len() as f64;
                assert!(
                    (mean - got[k]).abs() < 2e-3 + 0.02 * mean,
                    "{target:?} r {r}: by hand {mean}, evaluator {}",
                    got[k]
                );
            }
        }
    }

    #[test]
    fn exact_levels_read_at_their_roughness_have_only_the_bake_error() {
        // Where the lod lands exactly on a level and the level is large next to the lobe, the
        // lookup's error is the bake's (< 1%); between levels it is larger.
        let params = Params {
            size: 32,
            levels: Some(3),
            fit_lookup: Some(false),
            ..Default::default()
        };
        let (src, chain) = sky_chain(64, &params);
        let tree = CellTree::new(&src);
        let reference = Reference::Tree {
            tree: &tree,
            source: &src,
            params: Quality::High.tree_params(),
        };
        let b = BorderedMips::new(&chain.mips);
        let e = mean_abs_rel(
            &b,
            LodMapping::Linear,
            &[0.5, 0.25],
            &probe_directions(300),
            &reference,
        );
        assert!(e[0] < 0.01, "on level 1: {}", e[0]);
        assert!(
            e[1] > 2.0 * e[0],
            "between levels {} vs on a level {}",
            e[1],
            e[0]
        );
    }

    /// The bake's report reads a table made before the fit (the tree gone by then): it is the
    /// report the live tree gives, bit for bit; and a table answers single reads at its own
    /// directions and roughness values as the tree does.
    #[test]
    fn a_reference_table_is_the_reference_it_was_made_from() {
        let params = Params {
            size: 16,
            levels: Some(3),
            ..Default::default()
        };
        let (src, chain) = sky_chain(32, &params);
        let tree = CellTree::new(&src);
        let live = Reference::Tree {
            tree: &tree,
            source: &src,
            params: crate::bake::RUNTIME_REFERENCE,
        };
        let table = live.table(REPORT_DIRECTIONS);
        let read = Reference::Table(&table);
        let report = |reference: &Reference| {
            let (t, m) = (Target::Gltf, LodMapping::Linear);
            evaluate_with(&chain.mips, t, m, REPORT_DIRECTIONS, reference)
        };
        let (a, b) = (report(&live), report(&read));
        assert_eq!(a.mean_abs_rel, b.mean_abs_rel);
        assert_eq!(a.p99_abs_rel, b.p99_abs_rel);
        assert_eq!(a.reference, b.reference);
        let d = probe_directions(REPORT_DIRECTIONS)[17];
        let grid = roughness_grid(ROUGHNESS_STEPS);
        let mut buf = TreeBuffers::default();
        let many = live.radiance_many(d, &grid, &mut buf);
        assert_eq!(read.radiance(d, grid[9], &mut buf), many[9]);
        assert_eq!(
            read.radiance(d, 0.0, &mut buf),
            live.radiance(d, 0.0, &mut buf)
        );
        assert_eq!(read.radiance_many(d, &grid[3..6], &mut buf), many[3..6]);
    }
}
