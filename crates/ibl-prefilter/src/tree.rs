//! Hierarchical evaluation of the exact kernel: the source as a quadtree of cells per cube face
//! (each a union of source texels, keeping its energy, solid angle and the first and second
//! moments of its texel directions), cut per tile of output texels by an opening-angle
//! criterion (Barnes & Hut 1986, "A hierarchical O(N log N) force-calculation algorithm"), and
//! the exact kernel summed over the cut with a second-order expansion per cell.
//!
//! Why not only filtered importance sampling: FIS reads box-blurred mips where its samples are
//! sparse, which is the kernel's long GGX tail (mass beyond θ_h is α²/(tan²θ_h + α²)); a bright
//! light seen through that tail lands on a few blurred samples, and texels lit mostly by it are
//! off by tens of percent on studio-like HDRIs even at 1024 samples (bench/prefilter.md). Here
//! the tail is summed with the exact kernel over cells whose size is a fixed fraction θ of their
//! distance: because the kernel depends on l only through c = n·l, a cell is placed at the mean
//! of c over its energy (first-order term zero, so a point light is exact at any distance) and
//! corrected by f''·Var(c)/2; cells across the horizon of max(n·l, 0) are split finer and
//! integrated with the kink.
//!
//! The normalisation Σ K Ω comes from the same cells (with solid-angle moments), so a constant
//! environment is reproduced to rounding, and the finest cells are the source texels placed at
//! their centres exactly as the brute-force reference places them: with θ → 0 the sum *is* the
//! reference.
//!
//! Neither the normalisation nor the cuts depend on the radiance: both are summed or built for
//! one quadrant of one face (where the tile grid is symmetric) and carried to every other tile
//! by the cube's symmetries (`CellMap`); the levels sum only the numerator elsewhere.

use glam::Vec3;
use ibl_core::cube::{texel_direction, Cubemap, Face};
use ibl_core::progress::Progress;
use ibl_core::traverse::map_cube_tiles_with;
use ibl_core::{luminance, Rgb};
use std::f32::consts::FRAC_PI_2;
use std::sync::atomic::{AtomicU64, Ordering};

/// Accuracy knobs of the hierarchical sum.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct TreeParams {
    /// Opening angle: a cell is summed as one point when its diameter is at most `theta`
    /// times its angular distance to the output tile.
    pub theta: f32,
    /// Finest cells: their mean angle is at most 2α/`kappa` (the lobe's half width in l is
    /// ~1.3α), or the source texels when those are coarser.
    pub kappa: f32,
    /// Cells straddling the horizon of a tile (where max(n·l, 0) has its kink) are split down
    /// to a diameter of `horizon`/r radians: the share of the kernel near its horizon grows
    /// with the roughness r (it is the whole cosine lobe at r = 1).
    pub horizon: f32,
}

impl TreeParams {
    /// Diameter straddling cells are split to at roughness r.
    pub(crate) fn horizon_at(&self, roughness: f32) -> f32 {
        self.horizon / roughness.max(1e-3)
    }
}

/// Second moments in the order xx, yy, zz, xy, xz, yz.
type Sym3 = [f32; 6];

/// One level of the quadtree: cells of an s×s cube, face-major, row-major.
///
/// The kernel depends on l only through c = n·l: f(c) = max(c, 0)/t(c)². A cell is summed as
/// Σ_i w_i f(n·l_i) ≈ W [f(c̄) + ½ f''(c̄) Var(c)] with c̄ = n·m̄ and Var(c) = nᵀ C n from the
/// cell's weighted mean m̄ of texel directions and their covariance C: exact to second order,
/// the first-order term zero by construction. Cells that may straddle the horizon model c as
/// uniform on [c̄ − √(3Var), c̄ + √(3Var)] and integrate the Taylor polynomial over c > 0. The
/// numerator weights texels by luminance (where the energy sits), the normalisation by solid
/// angle.
struct CellLevel {
    size: usize,
    /// Unit axis and half-angle of a cone holding the whole cell.
    axis: Vec<Vec3>,
    /// Empty on the finest level, whose cells all have the radius `point_radius`.
    radius: Vec<f32>,
    point_radius: f32,
    /// Radiance × solid angle summed over the cell, and the solid angle.
    energy: Vec<Rgb>,
    /// Empty on the finest level, whose texels' solid angles repeat on every face
    /// (`face_omega`, one face's table): the finest level is the largest thing the bake
    /// holds, and these two columns were a quarter of it.
    omega: Vec<f32>,
    face_omega: Vec<f32>,
    /// Moments; empty on the finest level, whose cells are points at their texel centres
    /// (exactly as the brute-force reference places them), mean = axis, 1 − |m̄|² = 0, C = 0.
    moments: Vec<Moments>,
}

/// Cells ahead of the one gathered whose data [`CellLevel::prefetch`] asks for.
const PREFETCH_AHEAD: usize = 8;

impl CellLevel {
    /// Asks the cache for what gathering cell `c` reads first (its moments, or its direction
    /// on the finest level, and its energy): a hint, which reads nothing.
    #[inline(always)]
    fn prefetch(&self, c: usize) {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
            let first = if self.moments.is_empty() {
                self.axis.as_ptr().wrapping_add(c) as *const i8
            } else {
                self.moments.as_ptr().wrapping_add(c) as *const i8
            };
            let energy = self.energy.as_ptr().wrapping_add(c) as *const i8;
            // SAFETY: a prefetch only hints the cache; it cannot fault at any address.
            unsafe {
                _mm_prefetch::<_MM_HINT_T0>(first);
                _mm_prefetch::<_MM_HINT_T0>(energy);
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        let _ = c;
    }

    /// Half-angle of the cone holding cell `c`.
    #[inline]
    fn radius(&self, c: usize) -> f32 {
        if self.radius.is_empty() {
            self.point_radius
        } else {
            self.radius[c]
        }
    }

    /// Solid angle of cell `c`.
    #[inline]
    fn omega(&self, c: usize) -> f32 {
        if self.omega.is_empty() {
            self.face_omega[c % (self.size * self.size)]
        } else {
            self.omega[c]
        }
    }
}

/// Mean direction (inside the unit ball), 1 − |m̄|² (kept in f64 until stored: it is what
/// makes 1 − n·m̄ exact for narrow lobes), and covariance, under luminance (`lum`) and solid
/// angle (`area`) weights.
#[derive(Clone, Copy)]
struct Moments {
    lum: (Vec3, f32, Sym3),
    area: (Vec3, f32, Sym3),
}

// SAFETY: every field is f32s (Vec3, f32, [f32; 6]), for which all-zero bits are 0.0.
unsafe impl bytemuck::Zeroable for Moments {}

/// Build-time sums of a cell in f64: energy, and for each weight (luminance × Ω, Ω) its total,
/// first and second moments of the texel directions.
#[derive(Clone, Copy, Default)]
struct Sums {
    e: [f64; 3],
    w: [f64; 2],
    m: [[f64; 3]; 2],
    s: [[f64; 6]; 2],
}

impl Sums {
    fn add_point(&mut self, d: Vec3, c: Rgb, omega: f64) {
        let lum = luminance(c) as f64 * omega;
        for k in 0..3 {
            self.e[k] += c[k] as f64 * omega;
        }
        let (x, y, z) = (d.x as f64, d.y as f64, d.z as f64);
        for (k, w) in [lum, omega].into_iter().enumerate() {
            self.w[k] += w;
            self.m[k][0] += w * x;
            self.m[k][1] += w * y;
            self.m[k][2] += w * z;
            let s = &mut self.s[k];
            s[0] += w * x * x;
            s[1] += w * y * y;
            s[2] += w * z * z;
            s[3] += w * x * y;
            s[4] += w * x * z;
            s[5] += w * y * z;
        }
    }

    fn add(&mut self, o: &Sums) {
        for k in 0..3 {
            self.e[k] += o.e[k];
        }
        for k in 0..2 {
            self.w[k] += o.w[k];
            for a in 0..3 {
                self.m[k][a] += o.m[k][a];
            }
            for a in 0..6 {
                self.s[k][a] += o.s[k][a];
            }
        }
    }

    /// Mean, 1 − |mean|² and covariance under weight `k`.
    fn moments(&self, k: usize) -> (Vec3, f32, Sym3) {
        let w = self.w[k];
        let m = self.m[k].map(|v| v / w);
        let s = self.s[k].map(|v| v / w);
        let q = (1.0 - (m[0] * m[0] + m[1] * m[1] + m[2] * m[2])).max(0.0);
        let c = [
            s[0] - m[0] * m[0],
            s[1] - m[1] * m[1],
            s[2] - m[2] * m[2],
            s[3] - m[0] * m[1],
            s[4] - m[0] * m[2],
            s[5] - m[1] * m[2],
        ];
        (
            Vec3::new(m[0] as f32, m[1] as f32, m[2] as f32),
            q as f32,
            c.map(|v| v as f32),
        )
    }
}

/// The source as a quadtree of cells, finest level = the source texels.
pub struct CellTree {
    /// Coarsest (roots) first.
    levels: Vec<CellLevel>,
}

/// Bound on the error of `ibl_core::approx::acos` plus f32 rounding: the cut's cone tests pad
/// by it so bounds stay bounds.
const FAST_ACOS_ERROR: f32 = 1e-4;

/// acos for the cut's cone tests (Abramowitz & Stegun 4.4.45, see `ibl_core::approx`).
#[inline]
fn fast_acos(x: f32) -> f32 {
    ibl_core::approx::acos(x as f64) as f32
}

/// Largest angle from unit `centre` to the corners of the face rectangle [s0,s1]×[t0,t1] (the
/// farthest point of a convex spherical quad from a point inside it is a corner).
fn cone_radius(face: Face, centre: Vec3, s0: f32, s1: f32, t0: f32, t1: f32) -> f32 {
    let mut r = 0.0f32;
    for (s, t) in [(s0, t0), (s1, t0), (s0, t1), (s1, t1)] {
        let c = face.direction(s, t).normalize();
        r = r.max(centre.dot(c).clamp(-1.0, 1.0).acos());
    }
    // Rounding of acos near 1 is ~1e-4 rad at worst; pad so the bound stays a bound.
    r + 1e-4
}

impl CellTree {
    /// The cell hierarchy of `cube`: per level, the texels' summed radiance × solid angle and their moments.
    pub fn new(cube: &Cubemap) -> Self {
        use rayon::prelude::*;
        let n = cube.size;
        // Finest level: the source texels as points. Their cone radius is only used to skip
        // texels behind every output direction, so a cheap bound does: radial projection onto
        // the sphere is 1-Lipschitz outside it, so centre-to-corner chords are ≤ √2/n and the
        // angle ≤ 2·asin(chord/2) ≤ 1.12·chord.
        let sa = ibl_core::cube::solid_angle_table(n);
        let texel_radius = 1.12 * std::f32::consts::SQRT_2 / n as f32 + 1e-4;
        // Each column filled in place (no row structs to split: the finest level is the
        // largest thing the bake holds), a texel row at a time: a texel's face and row from
        // its index were two integer divisions a texel, a fifth of the stage.
        let m = 6 * n * n;
        // Zeroed allocations (`vec!` of a glam vector or of a struct writes every element,
        // on this thread; a zeroed one is fresh pages the fill below touches in parallel).
        let mut axis: Vec<Vec3> = bytemuck::zeroed_vec(m);
        let mut energy = vec![[0.0f32; 3]; m];
        axis.par_chunks_mut(n)
            .zip(energy.par_chunks_mut(n))
            .enumerate()
            .for_each(|(row, (axis, energy))| {
                let (face, j) = (Face::from_index(row / n), row % n);
                for (i, (a, e)) in axis.iter_mut().zip(energy.iter_mut()).enumerate() {
                    *a = texel_direction(face, i, j, n);
                    let om = sa[j * n + i];
                    let c = cube.texel(face, i, j);
                    *e = [c[0] * om, c[1] * om, c[2] * om];
                }
            });
        let finest = CellLevel {
            size: n,
            axis,
            radius: Vec::new(),
            point_radius: texel_radius,
            energy,
            omega: Vec::new(),
            face_omega: sa,
            moments: Vec::new(),
        };
        // Coarser levels while the size halves exactly, built one face at a time (a quadtree
        // never crosses a face): the f64 build sums of only one face are held at once (those
        // of a whole 128² level were 18 MB, more than the level they build).
        let mut sizes = Vec::new();
        let mut s = n;
        while s.is_multiple_of(2) {
            s /= 2;
            sizes.push(s);
        }
        let mut coarse: Vec<CellLevel> = sizes.iter().map(|&h| Self::empty_level(h)).collect();
        let (sa, finest_axis) = (&finest.face_omega, &finest.axis);
        for f in 0..6 {
            let face = Face::from_index(f);
            let mut sums: Vec<Sums> = Vec::new();
            let mut s = n;
            for (level, &h) in coarse.iter_mut().zip(&sizes) {
                let parent: Vec<Sums> = (0..h * h)
                    .into_par_iter()
                    .map(|p| {
                        let (j, i) = (p / h, p % h);
                        let mut acc = Sums::default();
                        for (dj, di) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                            let (ci, cj) = (2 * i + di, 2 * j + dj);
                            if s == n {
                                acc.add_point(
                                    finest_axis[(f * n + cj) * n + ci],
                                    cube.texel(face, ci, cj),
                                    sa[cj * n + ci] as f64,
                                );
                            } else {
                                acc.add(&sums[cj * s + ci]);
                            }
                        }
                        acc
                    })
                    .collect();
                Self::fill_face_from_sums(level, f, &parent);
                sums = parent;
                s = h;
            }
        }
        let mut levels = vec![finest];
        levels.extend(coarse);
        levels.reverse();
        CellTree { levels }
    }

    /// A level of s×s faces, zeroed, to be filled face by face.
    fn empty_level(s: usize) -> CellLevel {
        let len = 6 * s * s;
        CellLevel {
            size: s,
            axis: bytemuck::zeroed_vec(len),
            radius: vec![0.0; len],
            point_radius: 0.0,
            energy: vec![[0.0; 3]; len],
            omega: vec![0.0; len],
            face_omega: Vec::new(),
            moments: bytemuck::zeroed_vec(len),
        }
    }

    /// Face `f` of `level` from its cells' build sums (`sums`, row-major on the face).
    fn fill_face_from_sums(level: &mut CellLevel, f: usize, sums: &[Sums]) {
        use rayon::prelude::*;
        let s = level.size;
        let step = 2.0 / s as f32;
        let range = f * s * s..(f + 1) * s * s;
        // Filled in place, column by column (no row structs to split).
        level.axis[range.clone()]
            .par_iter_mut()
            .zip(level.radius[range.clone()].par_iter_mut())
            .zip(level.energy[range.clone()].par_iter_mut())
            .zip(level.omega[range.clone()].par_iter_mut())
            .zip(level.moments[range].par_iter_mut())
            .enumerate()
            .for_each(|(k, ((((axis, radius), energy), omega), moments))| {
                let c = &sums[k];
                let (j, i) = (k / s, k % s);
                let area = c.moments(1);
                let lum = if c.w[0] > 0.0 { c.moments(0) } else { area };
                *axis = area.0.normalize();
                let (s0, t0) = (i as f32 * step - 1.0, j as f32 * step - 1.0);
                *radius = cone_radius(Face::from_index(f), *axis, s0, s0 + step, t0, t0 + step);
                *energy = c.e.map(|v| v as f32);
                *omega = c.w[1] as f32;
                *moments = Moments { lum, area };
            });
    }

    /// Face size of the finest level (the source).
    pub fn size(&self) -> usize {
        self.levels.last().unwrap().size
    }

    /// One direction of [`Self::brute_convolve_many`] (the tests' form).
    #[cfg(test)]
    pub(crate) fn brute_convolve(&self, n: Vec3, alpha: f32) -> Rgb {
        self.brute_convolve_many(&[n], alpha)[0]
    }

    /// The exact kernel of roughness α summed by brute force over every source texel (the
    /// finest cells, placed at their centres) and normalised by its own sum, as
    /// `SourceTexels::convolve` does, in every direction of `dirs`: the bake's error
    /// estimate, without a second copy of the source texels. One pass over the texels serves
    /// every direction, each with the bits it has alone: the finest level (28 bytes a texel,
    /// 11 MB for a 256² source) does not stay in cache between directions, so a pass per
    /// direction was bound by memory, not by the kernel's arithmetic.
    pub(crate) fn brute_convolve_many(&self, dirs: &[Vec3], alpha: f32) -> Vec<Rgb> {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has just been checked for AVX2.
            return unsafe { self.brute_convolve_avx2(dirs, alpha) };
        }
        self.brute_convolve_lanes(dirs, alpha)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn brute_convolve_avx2(&self, dirs: &[Vec3], alpha: f32) -> Vec<Rgb> {
        self.brute_convolve_lanes(dirs, alpha)
    }

    /// [`Self::brute_convolve_many`]'s body, compiled for AVX2 and for the baseline (no fused
    /// multiply-add in either: the same bits). Per run of 64 texels: the run's channels and
    /// solid angles copied out as columns once, then for each direction the weights and
    /// sums in [`LANES`] f32 lanes, flushed in lane order to that direction's f64 totals.
    #[inline(always)]
    fn brute_convolve_lanes(&self, dirs: &[Vec3], alpha: f32) -> Vec<Rgb> {
        const RUN: usize = 64;
        let lv = self.levels.last().unwrap();
        let a2 = alpha * alpha;
        let one_m = 1.0 - a2;
        let mut acc = vec![[0.0f64; 4]; dirs.len()];
        let size = lv.size;
        let per_face = size * size;
        let mut cols = [[0.0f32; RUN]; 4];
        for start in (0..lv.axis.len()).step_by(RUN) {
            let end = (start + RUN).min(lv.axis.len());
            let m = end - start;
            // A run of texels on one row of a face lies on a line of the face plane, where
            // n·(unnormalised direction) is linear: both ends below −1e-3 put every texel of
            // the run below the horizon (n·l < −5e-4 after normalising by at most √3), where
            // the kernel is exactly 0. Skipping those zeros leaves every sum as it was and
            // halves the estimate's work.
            let one_row = start / size == (end - 1) / size;
            let below = |n: Vec3| {
                one_row && n.dot(lv.axis[start]) < -1e-3 && n.dot(lv.axis[end - 1]) < -1e-3
            };
            if dirs.iter().all(|&n| below(n)) {
                continue;
            }
            // The run's columns; zero past its end (a short last run adds zeros).
            if m < RUN {
                cols = [[0.0f32; RUN]; 4];
            }
            for (k, e) in lv.energy[start..end].iter().enumerate() {
                cols[0][k] = e[0];
                cols[1][k] = e[1];
                cols[2][k] = e[2];
            }
            // The texels' indices on their face (a run crosses at most one face edge).
            let t0 = start % per_face;
            let first = m.min(per_face - t0);
            cols[3][..first].copy_from_slice(&lv.face_omega[t0..t0 + first]);
            cols[3][first..m].copy_from_slice(&lv.face_omega[..m - first]);
            for (&n, acc) in dirs.iter().zip(acc.iter_mut()) {
                if below(n) {
                    continue;
                }
                // The weights (a loop with no sum in it, which the compiler vectorises).
                let mut w = [0.0f32; RUN];
                for (w, d) in w[..m].iter_mut().zip(&lv.axis[start..end]) {
                    let s2 = 0.25 * (n - *d).length_squared();
                    let t = a2 + one_m * s2;
                    *w = (1.0 - 2.0 * s2).max(0.0) / (t * t);
                }
                let mut lanes = [[0.0f32; LANES]; 4];
                for q in 0..RUN / LANES {
                    let w = &w[q * LANES..(q + 1) * LANES];
                    for (c, lane) in lanes.iter_mut().enumerate() {
                        let v = &cols[c][q * LANES..(q + 1) * LANES];
                        for k in 0..LANES {
                            lane[k] += w[k] * v[k];
                        }
                    }
                }
                for c in 0..4 {
                    acc[c] += lanes[c].iter().map(|v| *v as f64).sum::<f64>();
                }
            }
        }
        acc.into_iter()
            .map(|acc| {
                if acc[3] <= 0.0 {
                    return [0.0; 3];
                }
                [
                    (acc[0] / acc[3]) as f32,
                    (acc[1] / acc[3]) as f32,
                    (acc[2] / acc[3]) as f32,
                ]
            })
            .collect()
    }

    /// Source texels held (the finest level's cells).
    pub(crate) fn texel_count(&self) -> usize {
        self.levels.last().unwrap().axis.len()
    }

    /// Index of the level whose cells are the leaves for roughness α: the coarsest with a
    /// mean cell angle at most 2α/κ, or the source texels.
    fn leaf_level(&self, alpha: f32, kappa: f32) -> usize {
        let target = 2.0 * alpha / kappa;
        let angle = |s: usize| (4.0 * std::f32::consts::PI / 6.0).sqrt() / s as f32;
        self.levels
            .iter()
            .position(|l| angle(l.size) <= target)
            .unwrap_or(self.levels.len() - 1)
    }

    /// Cells to sum for every output direction within `tile_radius` of `tile_centre`.
    fn cut(
        &self,
        tile_centre: Vec3,
        tile_radius: f32,
        spec: &CutSpec,
        out: &mut CutList,
        stack: &mut Vec<(usize, usize)>,
    ) {
        let CutSpec {
            leaf,
            theta,
            horizon,
            numerator_only,
        } = *spec;
        out.clear();
        out.numerator_only = numerator_only;
        stack.clear();
        let finest = self.levels.len() - 1;
        stack.extend((0..self.levels[0].axis.len()).rev().map(|c| (0, c)));
        while let Some((li, c)) = stack.pop() {
            let lv = &self.levels[li];
            let rc = lv.radius(c);
            let ang = fast_acos(tile_centre.dot(lv.axis[c]));
            let dmin = ang - tile_radius - rc - FAST_ACOS_ERROR;
            if dmin >= FRAC_PI_2 {
                // Every pair is ≥ 90° apart: n·l ≤ 0, the kernel is exactly zero.
                continue;
            }
            // Far cells are points once small next to their distance, near ones at the leaf
            // level; cells across the horizon are split further (below the leaf level too) as
            // the kink of max(n·l, 0) is not smooth.
            let straddles = ang + tile_radius + rc + FAST_ACOS_ERROR > FRAC_PI_2;
            let small = li >= leaf || 2.0 * rc <= theta * dmin;
            if li == finest || (small && (!straddles || 2.0 * rc <= horizon)) {
                out.push(lv, li, c, straddles);
                continue;
            }
            let (s, child) = (lv.size, &self.levels[li + 1]);
            let (f, rest) = (c / (s * s), c % (s * s));
            let (j, i) = (rest / s, rest % s);
            let cs = child.size;
            for (dj, di) in [(1, 1), (1, 0), (0, 1), (0, 0)] {
                stack.push((li + 1, (f * cs + 2 * j + dj) * cs + 2 * i + di));
            }
        }
        out.finish();
    }
}

/// What decides a level's cuts: the leaf level, the opening angle and the horizon split.
#[derive(Clone, Copy)]
struct CutSpec {
    leaf: usize,
    theta: f32,
    horizon: f32,
    /// The cut's cells carry only the numerator's columns (see [`CutList::numerator_only`]).
    numerator_only: bool,
}

/// Cells of a cut as structure-of-arrays for the summation loop: for the numerator and the
/// normalisation each, mean (x, y, z), 1 − |mean|², covariance (6); then energy and Ω.
#[derive(Default)]
struct CellBlock {
    /// [mx, my, mz, mq, mc0..mc5, gx, gy, gz, gq, gc0..gc5, er, eg, eb, om]
    cols: [Vec<f32>; COLS],
    /// The cells as rows while the cut is built (one push a cell instead of 24), turned
    /// into `cols` by [`CellBlock::pad`].
    rows: Vec<[f32; COLS]>,
}

const COLS: usize = 24;
/// Lanes of the summation loop (one AVX register, two SSE ones).
const LANES: usize = 8;

/// The normalisation's columns of [`CellBlock::cols`] (its moments and Ω): left empty in a
/// cut that sums only the numerator.
fn normalisation_column(k: usize) -> bool {
    (10..20).contains(&k) || k == 23
}

impl CellBlock {
    fn push(&mut self, lv: &CellLevel, c: usize, numerator_only: bool) {
        let (lum, area) = match lv.moments.get(c) {
            Some(m) => (m.lum, m.area),
            None => ((lv.axis[c], 0.0, [0.0; 6]), (lv.axis[c], 0.0, [0.0; 6])),
        };
        let e = lv.energy[c];
        let mut row = [0.0f32; COLS];
        let (m, q, cov) = lum;
        row[0..4].copy_from_slice(&[m.x, m.y, m.z, q]);
        row[4..10].copy_from_slice(&cov);
        row[20..23].copy_from_slice(&e);
        if !numerator_only {
            let (m, q, cov) = area;
            row[10..14].copy_from_slice(&[m.x, m.y, m.z, q]);
            row[14..20].copy_from_slice(&cov);
            row[23] = lv.omega(c);
        }
        self.rows.push(row);
    }

    /// Pads to a whole number of lanes with empty cells (zero energy and solid angle), and
    /// turns the rows into columns (the normalisation's only if `!numerator_only`: a fifth of
    /// the levels' cut time went to building and transposing them).
    fn pad(&mut self, numerator_only: bool) {
        while !self.rows.len().is_multiple_of(LANES) {
            // A unit mean (+z) keeps the arithmetic finite; the weights multiply zeros.
            let mut empty = [0.0f32; COLS];
            empty[2] = 1.0;
            empty[12] = 1.0;
            self.rows.push(empty);
        }
        for (k, col) in self.cols.iter_mut().enumerate() {
            col.clear();
            if !(numerator_only && normalisation_column(k)) {
                col.extend(self.rows.iter().map(|r| r[k]));
            }
        }
    }
}

/// The cells summed for one tile: those wholly above the horizon of every texel of the tile,
/// and those that may straddle it (summed with the kink-aware cell model).
#[derive(Default)]
pub(crate) struct CutList {
    smooth: CellBlock,
    horizon: CellBlock,
    /// Only the numerator's columns are built: the sums made from it are `sums::<true, false>`.
    numerator_only: bool,
    /// The cells in the order pushed, as (level, cell, straddles) packed by [`pack_cell`]: what
    /// [`CutList::fill_from_image`] carries to the symmetric tiles.
    cells: Vec<u32>,
}

/// A cut's cell packed in 32 bits (the quadrant's cuts are held for a whole level): level
/// (bits 28…31), cell index (1…27), straddles the horizon (bit 0). Trees past
/// [`PACKED_CELLS`] cells a level or 16 levels are not packed (their levels are traversed
/// tile by tile); the packing of such a tree's cells is never read.
fn pack_cell(level: usize, c: usize, straddles: bool) -> u32 {
    ((level as u32) << 28) | ((c as u32 & (PACKED_CELLS as u32 - 1)) << 1) | straddles as u32
}

/// Cells a level may have for [`pack_cell`] (6 × 4096² faces fit).
const PACKED_CELLS: usize = 1 << 27;

/// Level, cell and horizon flag of a [`pack_cell`].
fn unpack_cell(e: u32) -> (usize, usize, bool) {
    (
        (e >> 28) as usize,
        ((e >> 1) as usize) & (PACKED_CELLS - 1),
        e & 1 == 1,
    )
}

/// The cell sum of the kernel (see [`CellLevel`]) for one weight: mean at chord² + q = `dq`
/// from n (shared by every roughness of a cut), variance `var` of n·l over the cell.
/// f(c) = max(c, 0)/t² with t = α² + (1−α²)(1−c)/2 is the kernel without α²/π (which cancels
/// in the ratio).
#[inline(always)]
fn weight_at<const HORIZON: bool>(dq: f32, var: f32, a2: f32, b: f32) -> f32 {
    let s2 = 0.25 * dq;
    let c = 1.0 - 2.0 * s2;
    let u = 1.0 / (a2 + b * s2);
    let uu = u * u;
    // f'' = u³(2b + 1.5 b² c u).
    let f2 = uu * u * (2.0 * b + 1.5 * b * b * c * u);
    let var = if var > 0.0 { var } else { 0.0 };
    if !HORIZON {
        // The whole cell is above the horizon: f(c̄) + f''(c̄)·var/2. Selects rather than
        // f32::max (whose NaN rule blocks vectorisation).
        let w = c * uu + 0.5 * f2 * var;
        return if c > 0.0 { w } else { 0.0 };
    }
    // n·l over the cell modelled as uniform on [c̄ − w, c̄ + w] (variance w²/3), the Taylor
    // polynomial of f integrated over its part above the horizon: with the cell wholly above,
    // this is f + f''·var/2 again; across, it follows the kink of max(n·l, 0). A point cell
    // (w → 0) gets a tiny w, which gives f(c̄) for c̄ > 0 and 0 below.
    let f = c * uu;
    let f1 = uu * (1.0 + b * c * u);
    let w = (3.0 * var).sqrt();
    let w = if w > 1e-12 { w } else { 1e-12 };
    let x0 = if -c > -w { -c } else { -w };
    let (x1, x0s) = (w, x0 * x0);
    let integral =
        f * (x1 - x0) + 0.5 * f1 * (x1 * x1 - x0s) + (f2 * (1.0 / 6.0)) * (x1 * x1 * x1 - x0s * x0);
    let spread = integral * (0.5 / w);
    if c + w > 0.0 {
        spread
    } else {
        0.0
    }
}

/// The per-cell terms of one weight kind (`o` = 0: numerator, 10: normalisation) that every
/// roughness shares, for the cells `start ..` (as many as `dq` holds): chord² + (1 − |m̄|²)
/// from n, and Var(n·l) = nᵀ C n (one straight loop the compiler vectorises).
#[inline(always)]
fn geometry(block: &CellBlock, o: usize, start: usize, n: Vec3, dq: &mut [f32], var: &mut [f32]) {
    let nn = [
        n.x * n.x,
        n.y * n.y,
        n.z * n.z,
        2.0 * n.x * n.y,
        2.0 * n.x * n.z,
        2.0 * n.y * n.z,
    ];
    let c = &block.cols;
    let len = dq.len();
    let col = |k: usize| &c[o + k][start..start + len];
    let (mx, my, mz, mq) = (col(0), col(1), col(2), col(3));
    let (c0, c1, c2, c3, c4, c5) = (col(4), col(5), col(6), col(7), col(8), col(9));
    let var = &mut var[..len];
    for k in 0..len {
        let (dx, dy, dz) = (n.x - mx[k], n.y - my[k], n.z - mz[k]);
        var[k] = nn[0] * c0[k]
            + nn[1] * c1[k]
            + nn[2] * c2[k]
            + nn[3] * c3[k]
            + nn[4] * c4[k]
            + nn[5] * c5[k];
        dq[k] = (dx * dx + dy * dy + dz * dz) + mq[k];
    }
}

/// Adds the f32 lanes `l` to the f64 lanes `a` lane by lane, and clears them: a vector
/// conversion and add. (A sum across the lanes at every flush made the compiler keep each lane
/// in a scalar register of its own and rebuild the vectors with shuffles at every step of the
/// loop, a third of the sum's time.)
#[inline(always)]
fn flush(a: &mut [f64; LANES], l: &mut [f32; LANES]) {
    for (a, l) in a.iter_mut().zip(l.iter()) {
        *a += *l as f64;
    }
    *l = [0.0; LANES];
}

/// Cells summed per pass of [`accumulate`]: their columns and scratch (30 × 4 bytes a cell,
/// 30 KB) stay in the L1 cache while every roughness reads them, where a whole cut (~700
/// cells) streamed from L2 once per roughness and bound the sum. A multiple of the 64-cell
/// flush period, so the flushes (and the bits) are those of one pass over the cut.
const CELLS_PER_PASS: usize = 256;

/// Σ over a block of (W_num·E_rgb, W_den·Ω) for every α² of `a2s` (into `acc`, one entry
/// each), in 8 f32 lanes flushed every 64 cells into 8 f64 lanes (`scratch`), summed across
/// at the end. The geometry is computed once for all of them; only the kernel's radial profile
/// is evaluated per roughness. `NUM` and `DEN` pick the sums made (the numerator's three, the
/// normalisation's one); each has the same bits alone as with the other.
#[inline(always)]
fn accumulate<const HORIZON: bool, const NUM: bool, const DEN: bool>(
    block: &CellBlock,
    n: Vec3,
    a2s: &[f32],
    scratch: &mut SumScratch,
    acc: &mut [[f64; 4]],
) {
    const L: usize = LANES;
    const _: () = assert!(CELLS_PER_PASS.is_multiple_of(64));
    let len = block.cols[0].len();
    debug_assert!(len.is_multiple_of(L));
    if len == 0 {
        return;
    }
    let pass = CELLS_PER_PASS.min(len);
    let SumScratch { cells, lanes } = scratch;
    // Grown, never shrunk: every value read is written first in each pass, and a resize
    // to the smaller pass of the horizon block and back zeroed 6 KB per texel (6.6% of a
    // default bake's instructions were that memset).
    if cells.len() < 6 * pass {
        cells.resize(6 * pass, 0.0);
    }
    lanes.clear();
    lanes.resize(a2s.len(), [[0.0; L]; 4]);
    let (dm, rest) = cells[..6 * pass].split_at_mut(pass);
    let (vm, rest) = rest.split_at_mut(pass);
    let (dg, rest) = rest.split_at_mut(pass);
    let (vg, rest) = rest.split_at_mut(pass);
    let (wm, wg) = rest.split_at_mut(pass);
    for start in (0..len).step_by(pass) {
        let m = pass.min(len - start);
        if NUM {
            geometry(block, 0, start, n, &mut dm[..m], vm);
        }
        if DEN {
            geometry(block, 10, start, n, &mut dg[..m], vg);
        }
        let col = |k: usize| &block.cols[k][start..start + m];
        // Ω is not built in a numerator-only cut; the unused fourth lanes read the red energy.
        let (er, eg, eb) = (col(20), col(21), col(22));
        let om = if DEN { col(23) } else { er };
        for (&a2, wide) in a2s.iter().zip(lanes.iter_mut()) {
            let b = 1.0 - a2;
            // The weights over the pass's cells (a loop the compiler vectorises; its scalar
            // tail never runs, blocks being padded to whole lanes), then their sums in whole
            // chunks of L cells: fixed-length slices carry no bounds checks and compile to
            // vector multiply-adds (indexed, the sums stayed scalar: a fifth of the bake's
            // CPU). The same operations in the same order: the same bits.
            let (dm, vm, dg, vg) = (&dm[..m], &vm[..m], &dg[..m], &vg[..m]);
            let (wm, wg) = (&mut wm[..m], &mut wg[..m]);
            for k in 0..m {
                if NUM {
                    wm[k] = weight_at::<HORIZON>(dm[k], vm[k], a2, b);
                }
                if DEN {
                    wg[k] = weight_at::<HORIZON>(dg[k], vg[k], a2, b);
                }
            }
            // All four lanes updated whatever NUM and DEN (the unused ones discarded): with
            // only some of them, the compiler kept each lane in a scalar register of its own
            // and rebuilt the vectors with shuffles at every step (the numerator alone was
            // slower than both).
            let mut lanes = [[0.0f32; L]; 4];
            let chunks = wm
                .chunks_exact(L)
                .zip(wg.chunks_exact(L))
                .zip(er.chunks_exact(L))
                .zip(eg.chunks_exact(L))
                .zip(eb.chunks_exact(L))
                .zip(om.chunks_exact(L));
            for (q, (((((wm8, wg8), er8), eg8), eb8), om8)) in chunks.enumerate() {
                let (wn8, wd8) = match (NUM, DEN) {
                    (true, true) => (wm8, wg8),
                    (true, false) => (wm8, wm8),
                    _ => (wg8, wg8),
                };
                for k in 0..L {
                    lanes[0][k] += wn8[k] * er8[k];
                    lanes[1][k] += wn8[k] * eg8[k];
                    lanes[2][k] += wn8[k] * eb8[k];
                    lanes[3][k] += wd8[k] * om8[k];
                }
                let i = start + (q + 1) * L;
                if i.is_multiple_of(64) || i == len {
                    for (w, l) in wide.iter_mut().zip(lanes.iter_mut()) {
                        flush(w, l);
                    }
                }
            }
        }
    }
    for (acc, wide) in acc.iter_mut().zip(lanes.iter()) {
        for (c, (a, w)) in acc.iter_mut().zip(wide).enumerate() {
            if (c < 3 && NUM) || (c == 3 && DEN) {
                *a += w.iter().sum::<f64>();
            }
        }
    }
}

/// Both blocks of a cut, for every α² of `a2s` (the sums `NUM` and `DEN` pick, the others
/// left 0). Compiled twice on x86-64: for AVX2 (8 lanes in one register) and for the SSE2
/// baseline. Neither allows fused multiply-add, so both give the same bits.
#[inline(always)]
fn accumulate_cut_multi<const NUM: bool, const DEN: bool>(
    cut: &CutList,
    n: Vec3,
    a2s: &[f32],
    scratch: &mut SumScratch,
    acc: &mut [[f64; 4]],
) {
    acc.iter_mut().for_each(|a| *a = [0.0; 4]);
    accumulate::<false, NUM, DEN>(&cut.smooth, n, a2s, scratch, acc);
    accumulate::<true, NUM, DEN>(&cut.horizon, n, a2s, scratch, acc);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn accumulate_cut_multi_avx2<const NUM: bool, const DEN: bool>(
    cut: &CutList,
    n: Vec3,
    a2s: &[f32],
    scratch: &mut SumScratch,
    acc: &mut [[f64; 4]],
) {
    accumulate_cut_multi::<NUM, DEN>(cut, n, a2s, scratch, acc)
}

/// One roughness of [`accumulate_cut_multi`] (the sums `NUM` and `DEN` pick), through its
/// AVX2 build if `avx2` (the caller has checked the CPU for it) or the baseline one.
#[cfg(test)]
fn accumulate_cut<const NUM: bool, const DEN: bool>(
    cut: &CutList,
    n: Vec3,
    a2: f32,
    scratch: &mut SumScratch,
    avx2: bool,
) -> [f64; 4] {
    let mut acc = [[0.0f64; 4]];
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        assert!(std::arch::is_x86_feature_detected!("avx2"));
        // SAFETY: the CPU has just been checked for AVX2.
        unsafe { accumulate_cut_multi_avx2::<NUM, DEN>(cut, n, &[a2], scratch, &mut acc) };
        return acc[0];
    }
    assert!(!avx2, "AVX2 is an x86-64 build");
    accumulate_cut_multi::<NUM, DEN>(cut, n, &[a2], scratch, &mut acc);
    acc[0]
}

impl CutList {
    fn clear(&mut self) {
        self.smooth
            .cols
            .iter_mut()
            .chain(self.horizon.cols.iter_mut())
            .for_each(Vec::clear);
        self.smooth.rows.clear();
        self.horizon.rows.clear();
        self.cells.clear();
    }

    /// The cut of a tile from that of its image under a symmetry of the cube (`cells`, as
    /// [`CutList::cells`] recorded it): every cell carried by `map`, in the same order.
    fn fill_from_image(
        &mut self,
        tree: &CellTree,
        cells: &[u32],
        map: &CellMap,
        numerator_only: bool,
    ) {
        self.clear();
        self.numerator_only = numerator_only;
        self.cells.extend(cells.iter().map(|&e| {
            let (li, c, straddles) = unpack_cell(e);
            pack_cell(li, map.apply(tree.levels[li].size, c), straddles)
        }));
        // Gathered with each cell's data prefetched PREFETCH_AHEAD cells ahead: the gather
        // waited on the first load of every cell's moments (half of its time; the cells of a
        // cut are scattered over the tree's levels).
        for k in 0..self.cells.len() {
            if let Some(&e) = self.cells.get(k + PREFETCH_AHEAD) {
                let (li, c, _) = unpack_cell(e);
                tree.levels[li].prefetch(c);
            }
            let (li, c, straddles) = unpack_cell(self.cells[k]);
            self.gather(&tree.levels[li], c, straddles);
        }
        self.finish();
    }

    fn push(&mut self, lv: &CellLevel, level: usize, c: usize, straddles: bool) {
        self.cells.push(pack_cell(level, c, straddles));
        self.gather(lv, c, straddles);
    }

    /// Adds cell `c` of `lv` to the block it belongs to.
    #[inline]
    fn gather(&mut self, lv: &CellLevel, c: usize, straddles: bool) {
        let num = self.numerator_only;
        if straddles {
            self.horizon.push(lv, c, num)
        } else {
            self.smooth.push(lv, c, num)
        }
    }

    fn finish(&mut self) {
        self.smooth.pad(self.numerator_only);
        self.horizon.pad(self.numerator_only);
    }

    /// Cells summed (padding included).
    pub fn len(&self) -> usize {
        self.smooth.cols[0].len() + self.horizon.cols[0].len()
    }

    /// Σ_cells W_num E / Σ_cells W_den Ω with each W the cell sum of the kernel (see
    /// [`CellLevel`]); the normalisation comes from the same cells, so a constant environment
    /// comes back exactly.
    pub fn convolve(&self, n: Vec3, alpha: f32, scratch: &mut SumScratch) -> Rgb {
        let mut acc = [[0.0f64; 4]];
        let mut out = [[0.0f32; 3]];
        self.convolve_multi(n, &[alpha * alpha], scratch, &mut acc, &mut out);
        out[0]
    }

    /// The cut's sums for every α² of `a2s` (into `acc`): W_num·E_rgb if `NUM`, W_den·Ω if
    /// `DEN`, the others 0.
    fn sums<const NUM: bool, const DEN: bool>(
        &self,
        n: Vec3,
        a2s: &[f32],
        scratch: &mut SumScratch,
        acc: &mut [[f64; 4]],
    ) {
        assert!(
            !(DEN && self.numerator_only),
            "a numerator-only cut has no normalisation"
        );
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has just been checked for AVX2.
            unsafe { accumulate_cut_multi_avx2::<NUM, DEN>(self, n, a2s, scratch, acc) }
        } else {
            accumulate_cut_multi::<NUM, DEN>(self, n, a2s, scratch, acc)
        }
        #[cfg(not(target_arch = "x86_64"))]
        accumulate_cut_multi::<NUM, DEN>(self, n, a2s, scratch, acc);
    }

    /// [`Self::convolve`] at every α² of `a2s` at once (into `out`, `acc` as scratch): the
    /// cut and the geometry of its cells are shared, only the kernel's profile differs.
    fn convolve_multi(
        &self,
        n: Vec3,
        a2s: &[f32],
        scratch: &mut SumScratch,
        acc: &mut [[f64; 4]],
        out: &mut [Rgb],
    ) {
        self.sums::<true, true>(n, a2s, scratch, acc);
        for (o, acc) in out.iter_mut().zip(acc.iter()) {
            *o = ratio(acc, acc[3]);
        }
    }
}

/// The numerator sums `acc[0..3]` over the normalisation `den` (black where it vanishes).
#[inline]
fn ratio(acc: &[f64; 4], den: f64) -> Rgb {
    if den <= 0.0 {
        [0.0; 3]
    } else {
        [
            (acc[0] / den) as f32,
            (acc[1] / den) as f32,
            (acc[2] / den) as f32,
        ]
    }
}

/// The cut of the w×h tile of an n×n face whose first texel is (i0, j0), into `buf.cut`.
fn tile_cut(
    tree: &CellTree,
    n: usize,
    face: Face,
    (i0, j0, w, h): (usize, usize, usize, usize),
    spec: &CutSpec,
    buf: &mut TreeBuffers,
) {
    let coord = |k: usize| (2.0 * k.min(n) as f32 / n as f32) - 1.0;
    let (s0, s1, t0, t1) = (coord(i0), coord(i0 + w), coord(j0), coord(j0 + h));
    let centre = face.direction(0.5 * (s0 + s1), 0.5 * (t0 + t1)).normalize();
    let radius = cone_radius(face, centre, s0, s1, t0, t1);
    tree.cut(centre, radius, spec, &mut buf.cut, &mut buf.stack);
}

/// A symmetry of the cube (a signed permutation of x, y, z) acting on the cells of a level:
/// for each face, the face its cells go to and how their (i, j) become the new (i, j).
#[derive(Clone, Copy, Debug, PartialEq)]
struct CellMap {
    /// Per face: (the face it goes to, the new i is the old j (else i), flip the new i, flip
    /// the new j), a flip taking k to s − 1 − k on an s × s level.
    faces: [(usize, bool, bool, bool); 6],
}

/// A face's axis a, and the directions u, v its s and t run along: `Face::direction(s, t)` =
/// a + s u + t v, each a signed unit axis.
fn face_frame(f: Face) -> [[i32; 3]; 3] {
    let v = |d: Vec3| [d.x as i32, d.y as i32, d.z as i32];
    let a = f.direction(0.0, 0.0);
    [
        v(a),
        v(f.direction(1.0, 0.0) - a),
        v(f.direction(0.0, 1.0) - a),
    ]
}

impl CellMap {
    /// The symmetry that carries texel (i, j) of +X, mirrored in i if `flip_s` and in j if
    /// `flip_t`, onto texel (i, j) of `face` (so a tile of `face` gets the cut of its image in
    /// +X's quadrant [n/2, n)²).
    ///
    /// +X's direction at the mirrored (s', t') = (±s, ±t) is (1, −t', −s'); `face`'s at (s, t)
    /// is a + s u + t v. The linear map G taking the first to the second for every (s, t) has
    /// the columns G e_x = a, G e_y = −σ_t v, G e_z = −σ_s u (σ = −1 where mirrored).
    fn new(face: Face, flip_s: bool, flip_t: bool) -> Self {
        let [a, u, v] = face_frame(face);
        let (ss, st) = (if flip_s { -1 } else { 1 }, if flip_t { -1 } else { 1 });
        let cols = [a, v.map(|x| -st * x), u.map(|x| -ss * x)];
        let g = |d: [i32; 3]| -> [i32; 3] {
            let mut out = [0; 3];
            for (k, col) in cols.iter().enumerate() {
                for r in 0..3 {
                    out[r] += col[r] * d[k];
                }
            }
            out
        };
        let frames = Face::ALL.map(face_frame);
        let faces = Face::ALL.map(|f| {
            let [fa, fu, fv] = face_frame(f);
            let (ga, gu, gv) = (g(fa), g(fu), g(fv));
            let to = frames
                .iter()
                .position(|fr| fr[0] == ga)
                .expect("a symmetry maps face axes to face axes");
            let [_, tu, tv] = frames[to];
            let neg = |x: [i32; 3]| x.map(|c| -c);
            // The new i runs along tu: it is the old i if G u = ±tu, else the old j (G v = ±tu).
            let swap = gv == tu || gv == neg(tu);
            let (new_i_dir, new_j_dir) = if swap { (gv, gu) } else { (gu, gv) };
            debug_assert!(new_i_dir == tu || new_i_dir == neg(tu));
            debug_assert!(new_j_dir == tv || new_j_dir == neg(tv));
            (to, swap, new_i_dir != tu, new_j_dir != tv)
        });
        CellMap { faces }
    }

    /// Where cell `c` of an s × s level goes.
    #[inline]
    fn apply(&self, s: usize, c: usize) -> usize {
        let (f, r) = (c / (s * s), c % (s * s));
        let (j, i) = (r / s, r % s);
        let (to, swap, flip_i, flip_j) = self.faces[f];
        let (i, j) = if swap { (j, i) } else { (i, j) };
        let i = if flip_i { s - 1 - i } else { i };
        let j = if flip_j { s - 1 - j } else { j };
        (to * s + j) * s + i
    }
}

/// Index within the quadrant [n/2, n) of texel index `k`'s mirror image across the face's
/// centre line (itself when it is in that half).
#[inline]
fn fold(k: usize, n: usize) -> usize {
    k.max(n - 1 - k) - n / 2
}

/// The normalisation Σ W_den·Ω of a level's every texel, for every α² of `a2s`, from one
/// quadrant of one face: `[(j' · n/2 + i') · a2s.len() + k]` for the texel (n/2 + i', n/2 + j')
/// of +X, and the cuts of its tiles. None where the tile grid is not symmetric (n not a
/// multiple of 2t) or the tree too large for [`pack_cell`].
///
/// The normalisation does not depend on the environment: its moments are the cells' solid
/// angle ones, and the cut (cones of solid-angle axes, tile by tile) is geometry too. The cube
/// of cells, the texel grid and a tile grid that divides each half face are all invariant under
/// the cube's 48 symmetries (signed permutations of x, y, z), and the kernel depends only on
/// n·l. Every face's direction is a signed permutation of (1, s, t) (`Face::direction`), so
/// texel (i, j) of any face is the image of texel (i, j) of +X, and mirroring s or t maps +X's
/// quadrants onto each other: the sum over a texel's cut is that of its image in the quadrant
/// (to rounding, and to an opening decision that rounding tips, which moves a cell's share
/// between its model and its children's). Computed once for a 24th of the texels, the
/// normalisation is half the cell sum's work of the other 23.
fn normalisation_quadrant(
    tree: &CellTree,
    n: usize,
    t: usize,
    spec: &CutSpec,
    a2s: &[f32],
) -> Option<Quadrant> {
    use rayon::prelude::*;
    let h = n / 2;
    let packable =
        tree.levels.len() <= 16 && tree.levels.iter().all(|l| l.axis.len() <= PACKED_CELLS);
    if n < 2 * t || !n.is_multiple_of(2 * t) || !packable {
        return None;
    }
    let count = a2s.len();
    let tiles = h / t;
    // A job per row of tiles, concatenated in order: the same bits for any thread count.
    let rows: Vec<(Vec<f64>, Vec<u32>, Vec<usize>)> = (0..tiles)
        .into_par_iter()
        .map_init(
            || (TreeBuffers::default(), vec![[0.0f64; 4]; count]),
            |(buf, acc), ty| {
                let j0 = h + ty * t;
                let mut rows = vec![0.0f64; t * h * count];
                // The row's cuts one after another (one allocation, not one a tile: the
                // level's small allocations outlived it as heap the fit's peak then sat on).
                let (mut cuts, mut ends) = (Vec::new(), Vec::with_capacity(tiles));
                for tx in 0..tiles {
                    let i0 = h + tx * t;
                    tile_cut(tree, n, Face::Px, (i0, j0, t, t), spec, buf);
                    cuts.extend_from_slice(&buf.cut.cells);
                    ends.push(cuts.len());
                    for jj in 0..t {
                        for ii in 0..t {
                            let d = texel_direction(Face::Px, i0 + ii, j0 + jj, n);
                            buf.cut.sums::<false, true>(d, a2s, &mut buf.scratch, acc);
                            let q = (jj * h + tx * t + ii) * count;
                            for (k, a) in acc.iter().enumerate() {
                                rows[q + k] = a[3];
                            }
                        }
                    }
                }
                (rows, cuts, ends)
            },
        )
        .collect();
    let mut q = Quadrant {
        den: Vec::with_capacity(h * h * count),
        cells: Vec::with_capacity(rows.iter().map(|r| r.1.len()).sum()),
        ends: Vec::with_capacity(tiles * tiles),
        tiles,
        t,
    };
    for (den, cells, ends) in rows {
        q.den.extend_from_slice(&den);
        let base = q.cells.len();
        q.cells.extend_from_slice(&cells);
        q.ends.extend(ends.into_iter().map(|e| base + e));
    }
    Some(q)
}

/// What a level's every tile takes from +X's quadrant [n/2, n)² (see
/// [`normalisation_quadrant`]).
struct Quadrant {
    /// The normalisation: `[(j' · n/2 + i') · count + k]` for texel (n/2 + i', n/2 + j').
    den: Vec<f64>,
    /// The cuts of the quadrant's tiles one after another, as [`CutList::cells`] (tile
    /// ty' · tiles + tx' ends at `ends[ty' · tiles + tx']`): every other tile's cut is its
    /// image under a symmetry.
    cells: Vec<u32>,
    ends: Vec<usize>,
    /// Tiles along the quadrant's edge, and their edge in texels.
    tiles: usize,
    t: usize,
}

impl Quadrant {
    /// The cut of the tile of `face` whose first texel is (i0, j0), into `cut`: its image's
    /// in the quadrant, carried by the symmetry between them. The cut a traversal would give,
    /// to an opening decision that rounding tips.
    fn cut(
        &self,
        tree: &CellTree,
        face: Face,
        (i0, j0): (usize, usize),
        numerator_only: bool,
        cut: &mut CutList,
    ) {
        // Tiles mirror as texels do, on a grid of 2 · tiles.
        let (tx, ty, side) = (i0 / self.t, j0 / self.t, 2 * self.tiles);
        let map = CellMap::new(face, tx < self.tiles, ty < self.tiles);
        let k = fold(ty, side) * self.tiles + fold(tx, side);
        let start = if k == 0 { 0 } else { self.ends[k - 1] };
        cut.fill_from_image(tree, &self.cells[start..self.ends[k]], &map, numerator_only);
    }
}

/// Output texels per tile edge: tiles share one cut, so they must stay small next to the
/// distances the opening criterion sees; coarse levels use smaller tiles.
fn tile_size(n: usize) -> usize {
    if n >= 64 {
        8
    } else {
        4.min(n)
    }
}

/// What a level cost.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct TreeWork {
    /// Σ over output texels of the cells summed for it.
    pub cell_evaluations: u64,
    /// Cuts built (one per tile).
    pub cuts: u64,
}

/// The exact kernel of roughness r > 0 summed hierarchically around one direction (a cut of
/// radius 0): what [`tree_level`] computes for a texel, at any direction. `stack`, `cut` and
/// `scratch` are reusable buffers.
pub(crate) fn tree_convolve(
    tree: &CellTree,
    d: Vec3,
    roughness: f32,
    p: &TreeParams,
    buffers: &mut TreeBuffers,
) -> Rgb {
    let alpha = roughness * roughness;
    let spec = CutSpec {
        leaf: tree.leaf_level(alpha, p.kappa),
        theta: p.theta,
        horizon: p.horizon_at(roughness),
        numerator_only: false,
    };
    let n = d.normalize();
    tree.cut(n, 1e-4, &spec, &mut buffers.cut, &mut buffers.stack);
    buffers.cut.convolve(n, alpha, &mut buffers.scratch)
}

/// [`tree_convolve`] at several roughness values r > 0 around one direction (into `out`, one
/// each): roughness values grouped by [`leaf_groups`] share one cut (the group's finest leaf
/// level and horizon split), as [`tree_levels`] groups a level's. What the runtime report's reference
/// evaluates at its 33 roughness values: a cut per group instead of per roughness.
pub(crate) fn tree_convolve_many(
    tree: &CellTree,
    d: Vec3,
    roughness: &[f32],
    p: &TreeParams,
    buffers: &mut TreeBuffers,
    out: &mut [Rgb],
) {
    debug_assert_eq!(roughness.len(), out.len());
    let n = d.normalize();
    let leaf: Vec<usize> = roughness
        .iter()
        .map(|r| tree.leaf_level(r * r, p.kappa))
        .collect();
    let (mut a2s, mut acc, mut vals) = (Vec::new(), Vec::new(), Vec::new());
    for group in leaf_groups(&leaf) {
        let spec = CutSpec {
            leaf: group.iter().map(|&j| leaf[j]).max().unwrap_or(0),
            theta: p.theta,
            horizon: group
                .iter()
                .map(|&j| p.horizon_at(roughness[j]))
                .fold(f32::INFINITY, f32::min),
            numerator_only: false,
        };
        tree.cut(n, 1e-4, &spec, &mut buffers.cut, &mut buffers.stack);
        a2s.clear();
        a2s.extend(group.iter().map(|&j| {
            let a = roughness[j] * roughness[j];
            a * a
        }));
        acc.resize(a2s.len(), [0.0f64; 4]);
        vals.resize(a2s.len(), [0.0f32; 3]);
        buffers
            .cut
            .convolve_multi(n, &a2s, &mut buffers.scratch, &mut acc, &mut vals);
        for (k, &j) in group.iter().enumerate() {
            out[j] = vals[k];
        }
    }
}

/// Scratch of the cell sum: the per-cell terms of a pass, and each roughness's f64 lanes.
#[derive(Default)]
pub struct SumScratch {
    cells: Vec<f32>,
    lanes: Vec<[[f64; LANES]; 4]>,
}

/// Reusable buffers of [`tree_convolve`].
#[derive(Default)]
pub struct TreeBuffers {
    cut: CutList,
    stack: Vec<(usize, usize)>,
    scratch: SumScratch,
}

/// One level of the chain by the hierarchical sum: an n×n cube at roughness r > 0.
pub(crate) fn tree_level(
    tree: &CellTree,
    n: usize,
    roughness: f32,
    p: &TreeParams,
    progress: &dyn Progress,
) -> (Cubemap, TreeWork) {
    let (mut cubes, work) = tree_levels_one_cut(tree, n, &[roughness], p, progress);
    (cubes.pop().expect("one roughness"), work)
}

/// n×n cubes at several roughness values r > 0 from one cut per tile (what the lookup fit
/// needs at a level: its own roughness and its nodes). The cut is the finest any of them asks
/// for (the smallest α's leaf level, the largest r's horizon split), so every cube is at least
/// as accurate as alone; the cut and each cell's geometry are computed once. `TreeWork` is per
/// cube (every cube sums the same cells).
pub(crate) fn tree_levels(
    tree: &CellTree,
    n: usize,
    roughness: &[f32],
    p: &TreeParams,
    progress: &dyn Progress,
) -> (Vec<Cubemap>, Vec<TreeWork>) {
    // Roughness values whose leaf levels are within SHARED_LEAF_LEVELS of the finest share a
    // cut: a finer leaf level costs the rougher cubes of the group their near cells (4× per
    // level), but building one cut instead of several and sharing each cell's geometry cost
    // less (a level and its fit nodes at 256² × 5: 0.72 → 0.62 s of CPU); much rougher
    // values (a wider span of leaf levels) get a cut of their own.
    let leaf: Vec<usize> = roughness
        .iter()
        .map(|r| tree.leaf_level(r * r, p.kappa))
        .collect();
    let mut out: Vec<Option<(Cubemap, TreeWork)>> = roughness.iter().map(|_| None).collect();
    for group in leaf_groups(&leaf) {
        let rs: Vec<f32> = group.iter().map(|&j| roughness[j]).collect();
        let (cubes, work) = tree_levels_one_cut(tree, n, &rs, p, progress);
        for (j, c) in group.into_iter().zip(cubes) {
            out[j] = Some((c, work));
        }
    }
    out.into_iter().map(|c| c.expect("every roughness")).unzip()
}

/// How many leaf levels coarser than a group's finest a roughness may ask for and still share
/// the group's cut in [`tree_levels`] and [`tree_convolve_many`].
const SHARED_LEAF_LEVELS: usize = 2;

/// Indices of roughness values (by their leaf levels `leaf`) grouped to share a cut: the
/// finest leaf level left, with every value at most [`SHARED_LEAF_LEVELS`] coarser, in index
/// order; then the next.
fn leaf_groups(leaf: &[usize]) -> Vec<Vec<usize>> {
    let mut done = vec![false; leaf.len()];
    let mut groups = Vec::new();
    while let Some(finest) = (0..leaf.len()).filter(|&j| !done[j]).map(|j| leaf[j]).max() {
        let group: Vec<usize> = (0..leaf.len())
            .filter(|&j| !done[j] && finest - leaf[j] <= SHARED_LEAF_LEVELS)
            .collect();
        group.iter().for_each(|&j| done[j] = true);
        groups.push(group);
    }
    groups
}

/// [`tree_levels`] for roughness values sharing one cut per tile.
fn tree_levels_one_cut(
    tree: &CellTree,
    n: usize,
    roughness: &[f32],
    p: &TreeParams,
    progress: &dyn Progress,
) -> (Vec<Cubemap>, TreeWork) {
    let a2s: Vec<f32> = roughness.iter().map(|r| (r * r) * (r * r)).collect();
    let spec = CutSpec {
        leaf: roughness
            .iter()
            .map(|r| tree.leaf_level(r * r, p.kappa))
            .max()
            .unwrap_or(0),
        theta: p.theta,
        horizon: roughness
            .iter()
            .map(|&r| p.horizon_at(r))
            .fold(f32::INFINITY, f32::min),
        numerator_only: false,
    };
    let t = tile_size(n);
    let (work, cuts) = (AtomicU64::new(0), AtomicU64::new(0));
    let count = roughness.len();
    let quadrant = normalisation_quadrant(tree, n, t, &spec, &a2s);
    let cubes = map_cube_tiles_with(
        n,
        t,
        count,
        progress,
        || {
            (
                TreeBuffers::default(),
                vec![[0.0f64; 4]; count],
                vec![[0.0f32; 3]; count],
            )
        },
        |(buf, acc, texel), face, i0, j0, w, h, out| {
            match &quadrant {
                Some(q) => q.cut(tree, face, (i0, j0), true, &mut buf.cut),
                None => tile_cut(tree, n, face, (i0, j0, w, h), &spec, buf),
            }
            cuts.fetch_add(1, Ordering::Relaxed);
            work.fetch_add((w * h * buf.cut.len()) as u64, Ordering::Relaxed);
            for jj in 0..h {
                for ii in 0..w {
                    let (i, j) = (i0 + ii, j0 + jj);
                    let d = texel_direction(face, i, j, n);
                    match quadrant.as_ref().map(|q| &q.den) {
                        Some(den) => {
                            buf.cut.sums::<true, false>(d, &a2s, &mut buf.scratch, acc);
                            let q = (fold(j, n) * (n / 2) + fold(i, n)) * count;
                            for (c, (acc, &dv)) in acc.iter().zip(&den[q..q + count]).enumerate() {
                                out[(c * h + jj) * w + ii] = ratio(acc, dv);
                            }
                        }
                        None => {
                            buf.cut
                                .convolve_multi(d, &a2s, &mut buf.scratch, acc, texel);
                            for (c, v) in texel.iter().enumerate() {
                                out[(c * h + jj) * w + ii] = *v;
                            }
                        }
                    }
                }
            }
        },
    );
    (
        cubes,
        TreeWork {
            cell_evaluations: work.into_inner(),
            cuts: cuts.into_inner(),
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernel::SourceTexels;
    use ibl_core::progress::NoProgress;
    use ibl_core::sampling::Pcg32;

    const TIGHT: TreeParams = TreeParams {
        theta: 0.0,
        kappa: 1e9,
        horizon: 0.0,
    };

    fn random_cube(n: usize, seed: u64) -> Cubemap {
        let mut rng = Pcg32::new(seed, 9);
        let mut c = Cubemap::new(n);
        for f in &mut c.faces {
            f.data.iter_mut().for_each(|v| *v = rng.next_f32() * 4.0);
        }
        c
    }

    #[test]
    fn fast_acos_is_within_its_bound() {
        let mut worst = 0.0f64;
        for k in 0..=200_000 {
            let x = -1.0 + 2.0 * k as f64 / 200_000.0;
            worst = worst.max((fast_acos(x as f32) as f64 - x.acos()).abs());
        }
        eprintln!("fast_acos: worst error {worst:.2e} rad");
        assert!(worst < FAST_ACOS_ERROR as f64, "{worst}");
    }

    /// The per-cell model on its own: one cell's numerator against the exact sum over its
    /// texels. Far cells sit exactly at the opening criterion of the default preset
    /// (distance from the cell = diameter/0.7): the second-order model against the centroid
    /// alone. Cells across the horizon: the kink model against the plain second-order one.
    #[test]
    fn cell_model_matches_the_sum_over_its_texels() {
        let n = 32;
        let cube = random_cube(n, 7);
        let tree = CellTree::new(&cube);
        let li = tree.levels.iter().position(|l| l.size == 4).unwrap();
        let lv = &tree.levels[li];
        let k = n / lv.size;
        let mut rng = Pcg32::new(8, 8);
        let mut scratch = SumScratch::default();
        // (second order, centroid only) far; (kink, plain) at the horizon.
        let (mut far, mut horizon) = (Vec::new(), Vec::new());
        for c in 0..lv.axis.len() {
            let (f, rest) = (c / (lv.size * lv.size), c % (lv.size * lv.size));
            let (cj, ci) = (rest / lv.size, rest % lv.size);
            let face = Face::from_index(f);
            let texels: Vec<(Vec3, f32)> = (0..k * k)
                .map(|t| {
                    let (i, j) = (ci * k + t % k, cj * k + t / k);
                    let om = ibl_core::cube::texel_solid_angle(i, j, n) as f32;
                    (
                        texel_direction(face, i, j, n),
                        cube.texel(face, i, j)[0] * om,
                    )
                })
                .collect();
            for _ in 0..20 {
                let alpha = 0.1 + 0.9 * rng.next_f32();
                let a2 = alpha * alpha;
                let v = Vec3::new(
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                );
                let axis = lv.axis[c];
                let perp = (v - axis * v.dot(axis)).normalize();
                let (rc, diameter) = (lv.radius(c), 2.0 * lv.radius(c));
                let far_angle = rc + diameter / 0.7;
                let kink_angle = FRAC_PI_2 + (rng.next_f32() - 0.5) * rc;
                for (kind, angle) in [(0, far_angle), (1, kink_angle)] {
                    if angle >= FRAC_PI_2 + rc && kind == 0 {
                        continue;
                    }
                    let nd = axis * angle.cos() + perp * angle.sin();
                    let exact: f64 = texels
                        .iter()
                        .map(|(l, e)| {
                            let s2 = 0.25 * (nd - *l).length_squared() as f64;
                            let t = a2 as f64 + (1.0 - a2 as f64) * s2;
                            (1.0 - 2.0 * s2).max(0.0) / (t * t) * *e as f64
                        })
                        .sum();
                    let model =
                        |straddles: bool, drop_covariance: bool, scratch: &mut SumScratch| {
                            let mut cut = CutList::default();
                            cut.push(lv, li, c, straddles);
                            cut.finish();
                            if drop_covariance {
                                let block = if straddles {
                                    &mut cut.horizon
                                } else {
                                    &mut cut.smooth
                                };
                                block.cols[4..10]
                                    .iter_mut()
                                    .for_each(|col| col.iter_mut().for_each(|v| *v = 0.0));
                            }
                            accumulate_cut::<true, true>(&cut, nd, a2, scratch, false)[0]
                        };
                    if kind == 0 {
                        let e2 = (model(false, false, &mut scratch) - exact).abs() / exact;
                        let e1 = (model(false, true, &mut scratch) - exact).abs() / exact;
                        far.push((e2, e1));
                    } else {
                        // Near the horizon the sum is small: measure against the cell's energy
                        // times the kernel's value scale there.
                        let scale = texels.iter().map(|(_, e)| *e as f64).sum::<f64>()
                            / (a2 as f64 + 0.5 * (1.0 - a2 as f64)).powi(2);
                        let ek = (model(true, false, &mut scratch) - exact).abs() / scale;
                        let ep = (model(false, false, &mut scratch) - exact).abs() / scale;
                        horizon.push((ek, ep));
                    }
                }
            }
        }
        let stats = |v: &[(f64, f64)], pick: fn(&(f64, f64)) -> f64| {
            (
                v.iter().map(pick).sum::<f64>() / v.len() as f64,
                v.iter().map(pick).fold(0.0, f64::max),
            )
        };
        let (far2, far1) = (stats(&far, |p| p.0), stats(&far, |p| p.1));
        let (hk, hp) = (stats(&horizon, |p| p.0), stats(&horizon, |p| p.1));
        eprintln!(
            "cell model at the default opening angle ({} cases): second order mean {:.2e} worst {:.2e}, centroid only mean {:.2e} worst {:.2e}",
            far.len(),
            far2.0,
            far2.1,
            far1.0,
            far1.1
        );
        eprintln!("cells across the horizon ({} cases, error / cell energy·f(0)): kink model mean {:.2e} worst {:.2e}, plain second order mean {:.2e} worst {:.2e}", horizon.len(), hk.0, hk.1, hp.0, hp.1);
        assert!(far2.0 < 0.5 * far1.0 && far2.0 < 0.03, "{far2:?} {far1:?}");
        assert!(hk.0 < 0.5 * hp.0, "{hk:?} {hp:?}");
    }

    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_and_baseline_sums_are_bit_identical_and_each_sum_alone_too() {
        let avx2 = std::arch::is_x86_feature_detected!("avx2");
        if !avx2 {
            eprintln!("no AVX2 here: the baseline's sums alone only");
        }
        let cube = random_cube(16, 4);
        let tree = CellTree::new(&cube);
        let p = TreeParams {
            theta: 0.7,
            kappa: 4.0,
            horizon: 0.12,
        };
        let spec = CutSpec {
            leaf: tree.leaf_level(0.25, p.kappa),
            theta: p.theta,
            horizon: p.horizon_at(0.5),
            numerator_only: false,
        };
        let (mut cut, mut stack, mut scratch) =
            (CutList::default(), Vec::new(), SumScratch::default());
        let centre = Vec3::new(0.3, 0.5, -0.8).normalize();
        tree.cut(centre, 0.2, &spec, &mut cut, &mut stack);
        assert!(!cut.smooth.cols[0].is_empty() && !cut.horizon.cols[0].is_empty());
        let mut rng = Pcg32::new(6, 6);
        for _ in 0..200 {
            let n = (centre
                + 0.1
                    * Vec3::new(
                        rng.next_f32() - 0.5,
                        rng.next_f32() - 0.5,
                        rng.next_f32() - 0.5,
                    ))
            .normalize();
            let bits = |v: [f64; 4]| v.map(f64::to_bits);
            let a = accumulate_cut::<true, true>(&cut, n, 0.0625, &mut scratch, false);
            // Each sum alone (the levels' numerator, the quadrant's normalisation) has the
            // bits it has beside the other, and leaves the other at 0.
            let (num, den) = ([a[0], a[1], a[2], 0.0], [0.0, 0.0, 0.0, a[3]]);
            let sums = |s: &mut SumScratch| {
                [
                    accumulate_cut::<true, false>(&cut, n, 0.0625, s, false),
                    accumulate_cut::<false, true>(&cut, n, 0.0625, s, false),
                ]
            };
            assert_eq!(sums(&mut scratch).map(bits), [bits(num), bits(den)]);
            if avx2 {
                let s = &mut scratch;
                let b = [
                    accumulate_cut::<true, true>(&cut, n, 0.0625, s, true),
                    accumulate_cut::<true, false>(&cut, n, 0.0625, s, true),
                    accumulate_cut::<false, true>(&cut, n, 0.0625, s, true),
                ];
                assert_eq!(b.map(bits), [bits(a), bits(num), bits(den)]);
            }
        }
    }

    /// Several roughness values from one cut per tile (the lookup fit's nodes) against each
    /// alone: the shared cut is the finest any of them asks for, so they agree to the tree's
    /// accuracy, and a roughness alone is what `tree_level` gives, bit for bit.
    /// The quadrant's normalisation against every texel's own (its own tile's cut, summed
    /// where it is): the cube's symmetries hold to rounding at every face, quadrant and size
    /// the bake folds, with the horizon split and several roughness values; and sizes whose tile
    /// grid is not symmetric are not folded.
    #[test]
    fn every_texels_normalisation_is_its_image_in_the_quadrant() {
        let tree = CellTree::new(&random_cube(64, 3));
        let p = TreeParams {
            theta: 0.7,
            kappa: 4.0,
            horizon: 0.12,
        };
        let rs = [0.1f32, 0.3, 0.6, 1.0];
        let a2s: Vec<f32> = rs.iter().map(|r| (r * r) * (r * r)).collect();
        let spec = CutSpec {
            leaf: tree.leaf_level(rs[0] * rs[0], p.kappa),
            theta: p.theta,
            horizon: p.horizon_at(rs[rs.len() - 1]),
            numerator_only: false,
        };
        for n in [8usize, 16, 32, 64] {
            let t = tile_size(n);
            let den = normalisation_quadrant(&tree, n, t, &spec, &a2s)
                .expect("a folded size")
                .den;
            let (mut buf, mut acc) = (TreeBuffers::default(), vec![[0.0f64; 4]; a2s.len()]);
            let mut worst = 0.0f64;
            for face in Face::ALL {
                for (j0, i0) in (0..n)
                    .step_by(t)
                    .flat_map(|j| (0..n).step_by(t).map(move |i| (j, i)))
                {
                    tile_cut(&tree, n, face, (i0, j0, t, t), &spec, &mut buf);
                    for (j, i) in (j0..j0 + t).flat_map(|j| (i0..i0 + t).map(move |i| (j, i))) {
                        let d = texel_direction(face, i, j, n);
                        buf.cut
                            .sums::<false, true>(d, &a2s, &mut buf.scratch, &mut acc);
                        let q = (fold(j, n) * (n / 2) + fold(i, n)) * a2s.len();
                        for (k, a) in acc.iter().enumerate() {
                            assert!(a[3] > 0.0);
                            worst = worst.max((den[q + k] / a[3] - 1.0).abs());
                        }
                    }
                }
            }
            eprintln!("n {n}: worst relative difference {worst:.1e}");
            assert!(worst < 1e-6, "n {n}: {worst}");
        }
        assert!(normalisation_quadrant(&tree, 4, tile_size(4), &spec, &a2s).is_none());
        assert!(normalisation_quadrant(&tree, 20, tile_size(20), &spec, &a2s).is_none());
    }

    /// Each symmetry carries +X's texels (mirrored as asked) onto the face's same (i, j), moves
    /// directions as a rotation or reflection does (the cell's direction is the image of the
    /// original's), and is a bijection on the cells of every level.
    #[test]
    fn cell_maps_are_the_cube_symmetries_they_claim() {
        for face in Face::ALL {
            for (flip_s, flip_t) in [(false, false), (true, false), (false, true), (true, true)] {
                let map = CellMap::new(face, flip_s, flip_t);
                for s in [1usize, 2, 4, 8] {
                    let mut seen = vec![false; 6 * s * s];
                    for c in 0..6 * s * s {
                        let m = map.apply(s, c);
                        assert!(!seen[m], "{face:?} {flip_s} {flip_t}: not a bijection");
                        seen[m] = true;
                    }
                    for j in 0..s {
                        for i in 0..s {
                            let (pi, pj) = (
                                if flip_s { s - 1 - i } else { i },
                                if flip_t { s - 1 - j } else { j },
                            );
                            let from = (Face::Px as usize * s + pj) * s + pi;
                            let to = (face as usize * s + j) * s + i;
                            assert_eq!(map.apply(s, from), to, "{face:?} {flip_s} {flip_t} s {s}");
                        }
                    }
                }
                // Dot products between cell directions are kept (an orthogonal map).
                let s = 4;
                let dir = |c: usize| {
                    let (f, r) = (c / (s * s), c % (s * s));
                    texel_direction(Face::from_index(f), r % s, r / s, s)
                };
                for (a, b) in [(0usize, 37usize), (5, 90), (17, 17), (63, 2)] {
                    let before = dir(a).dot(dir(b));
                    let after = dir(map.apply(s, a)).dot(dir(map.apply(s, b)));
                    assert!(
                        (before - after).abs() < 1e-6,
                        "{face:?}: {before} vs {after}"
                    );
                }
            }
        }
    }

    /// A tile's cut carried from its image in the quadrant holds the cells a traversal of the
    /// tile itself picks, with the same horizon split, on every face and quadrant.
    #[test]
    fn image_cuts_are_the_traversed_cuts() {
        let tree = CellTree::new(&random_cube(64, 4));
        let spec = CutSpec {
            leaf: tree.leaf_level(0.01, 4.0),
            theta: 0.7,
            horizon: 0.12 / 0.5,
            numerator_only: false,
        };
        let (n, t) = (32usize, tile_size(32));
        let q = normalisation_quadrant(&tree, n, t, &spec, &[0.01]).expect("a folded size");
        let mut buf = TreeBuffers::default();
        let mut image = CutList::default();
        let (mut tiles, mut differ) = (0, 0);
        for face in Face::ALL {
            for j0 in (0..n).step_by(t) {
                for i0 in (0..n).step_by(t) {
                    tile_cut(&tree, n, face, (i0, j0, t, t), &spec, &mut buf);
                    q.cut(&tree, face, (i0, j0), false, &mut image);
                    let mut a = buf.cut.cells.clone();
                    let mut b = image.cells.clone();
                    a.sort_unstable();
                    b.sort_unstable();
                    tiles += 1;
                    differ += (a != b) as usize;
                    assert_eq!(buf.cut.len(), image.len());
                }
            }
        }
        eprintln!("{differ} of {tiles} tiles' cuts differ from their images'");
        assert_eq!(differ, 0);
    }

    #[test]
    fn shared_cuts_agree_with_separate_levels() {
        let cube = random_cube(32, 5);
        let tree = CellTree::new(&cube);
        let texels = SourceTexels::new(&cube);
        let p = TreeParams {
            theta: 0.7,
            kappa: 2.0,
            horizon: 0.12,
        };
        let rs = [0.4f32, 0.45, 0.5, 0.9, 1.0];
        let (many, work) = tree_levels(&tree, 8, &rs, &p, &NoProgress);
        assert_eq!((many.len(), work.len()), (rs.len(), rs.len()));
        for (k, &r) in rs.iter().enumerate() {
            let (alone, _) = tree_level(&tree, 8, r, &p, &NoProgress);
            let (mine, _) = tree_levels(&tree, 8, &[r], &p, &NoProgress);
            assert_eq!(
                alone.faces, mine[0].faces,
                "r {r}: one roughness is tree_level"
            );
            // Mean relative error of each against the brute force.
            let (mut shared, mut single, mut count) = (0.0f64, 0.0f64, 0.0f64);
            for face in Face::ALL {
                for j in 0..8 {
                    for i in 0..8 {
                        let exact = texels.convolve(texel_direction(face, i, j, 8), r * r);
                        let (a, b) = (many[k].texel(face, i, j), alone.texel(face, i, j));
                        for c in 0..3 {
                            shared += ((a[c] - exact[c]).abs() / exact[c]) as f64;
                            single += ((b[c] - exact[c]).abs() / exact[c]) as f64;
                            count += 1.0;
                        }
                    }
                }
            }
            let (shared, single) = (shared / count, single / count);
            eprintln!("r {r}: mean error shared cut {shared:.2e}, alone {single:.2e}");
            assert!(
                shared < 1e-2 && shared < 1.5 * single + 1e-4,
                "r {r}: {shared} vs {single}"
            );
        }
    }

    #[test]
    fn tree_sums_match_the_source_at_every_level() {
        let cube = random_cube(12, 1);
        let tree = CellTree::new(&cube);
        assert_eq!(
            tree.levels.iter().map(|l| l.size).collect::<Vec<_>>(),
            vec![3, 6, 12]
        );
        let total = |lv: &CellLevel| lv.energy.iter().map(|e| e[1] as f64).sum::<f64>();
        let om = |lv: &CellLevel| (0..lv.axis.len()).map(|c| lv.omega(c) as f64).sum::<f64>();
        for lv in &tree.levels {
            assert!((total(lv) - total(&tree.levels[2])).abs() < 1e-4 * total(lv));
            assert!((om(lv) - 4.0 * std::f64::consts::PI).abs() < 1e-4);
        }
    }

    #[test]
    fn cones_hold_their_cells() {
        // Every source texel centre lies within its ancestors' cones.
        let cube = random_cube(16, 2);
        let tree = CellTree::new(&cube);
        for (li, lv) in tree.levels.iter().enumerate() {
            let s = lv.size;
            let k = 16 / s;
            for face in Face::ALL {
                for j in 0..16 {
                    for i in 0..16 {
                        let d = texel_direction(face, i, j, 16);
                        let c = (face as usize * s + j / k) * s + i / k;
                        let ang = lv.axis[c].dot(d).clamp(-1.0, 1.0).acos();
                        assert!(ang <= lv.radius(c), "level {li}: {ang} > {}", lv.radius(c));
                        if let Some(m) = lv.moments.get(c) {
                            let angm = m.lum.0.normalize().dot(lv.axis[c]).clamp(-1.0, 1.0).acos();
                            assert!(angm <= lv.radius(c), "energy centroid outside the cone");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn brute_force_skips_only_runs_where_the_kernel_is_zero() {
        // The horizon skip of brute_convolve (and its AVX2 build) against the plain sum over
        // every texel, in the same order and lanes: the same bits in every direction, including directions on
        // face edges and corners where a run's ends straddle the horizon.
        let cube = random_cube(128, 21);
        let tree = CellTree::new(&cube);
        let lv = tree.levels.last().unwrap();
        let plain = |n: Vec3, alpha: f32| -> Rgb {
            let a2 = alpha * alpha;
            let mut acc = [0.0f64; 4];
            for start in (0..lv.axis.len()).step_by(64) {
                let end = (start + 64).min(lv.axis.len());
                // Texel k of the run in lane k % LANES (zeros past the run's end add
                // nothing to a lane).
                let mut lanes = [[0.0f32; LANES]; 4];
                for k in start..end {
                    let s2 = 0.25 * (n - lv.axis[k]).length_squared();
                    let t = a2 + (1.0 - a2) * s2;
                    let w = (1.0 - 2.0 * s2).max(0.0) / (t * t);
                    let e = lv.energy[k];
                    let lane = (k - start) % LANES;
                    lanes[0][lane] += w * e[0];
                    lanes[1][lane] += w * e[1];
                    lanes[2][lane] += w * e[2];
                    lanes[3][lane] += w * lv.omega(k);
                }
                for c in 0..4 {
                    acc[c] += lanes[c].iter().map(|v| *v as f64).sum::<f64>();
                }
            }
            std::array::from_fn(|c| (acc[c] / acc[3]) as f32)
        };
        let mut rng = Pcg32::new(4, 4);
        let mut dirs: Vec<Vec3> = (0..40)
            .map(|_| {
                Vec3::new(
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                )
                .normalize()
            })
            .collect();
        dirs.extend([Vec3::X, Vec3::NEG_Y, Vec3::new(1.0, 1.0, 0.0).normalize()]);
        dirs.push(Vec3::ONE.normalize());
        for &d in &dirs {
            for alpha in [0.01f32, 0.2, 1.0] {
                let (a, b) = (tree.brute_convolve(d, alpha), plain(d, alpha));
                assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits), "{d} α {alpha}");
            }
        }
        // Many directions in one pass: each with the bits it has alone.
        for alpha in [0.01f32, 0.2, 1.0] {
            let many = tree.brute_convolve_many(&dirs, alpha);
            for (d, a) in dirs.iter().zip(many) {
                let b = plain(*d, alpha);
                assert_eq!(
                    a.map(f32::to_bits),
                    b.map(f32::to_bits),
                    "{d} α {alpha} (many)"
                );
            }
        }
    }

    #[test]
    fn shared_cuts_of_the_report_are_no_worse_than_one_cut_per_roughness() {
        // tree_convolve_many groups roughness values by leaf level: a group's cut is as fine
        // as its finest member asks, so against the brute force every member is about as
        // accurate as with its own cut or better, and a member alone in its group is its own
        // cut to the bit.
        let cube = random_cube(32, 8);
        let tree = CellTree::new(&cube);
        let texels = SourceTexels::new(&cube);
        let p = TreeParams {
            theta: 0.7,
            kappa: 4.0,
            horizon: 0.12,
        };
        let rs: Vec<f32> = (1..=32).map(|k| k as f32 / 32.0).collect();
        let leaf: Vec<usize> = rs.iter().map(|r| tree.leaf_level(r * r, p.kappa)).collect();
        let groups = leaf_groups(&leaf);
        assert!(groups.len() > 1, "{groups:?}");
        assert_eq!(
            leaf_groups(&[5, 5, 4, 3, 2, 1, 0, 6]),
            vec![vec![0, 1, 2, 7], vec![3, 4, 5], vec![6]]
        );
        let mut buf = TreeBuffers::default();
        let mut rng = Pcg32::new(5, 1);
        let (mut shared, mut single, mut count) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..12 {
            let d = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            )
            .normalize();
            let mut many = vec![[0.0f32; 3]; rs.len()];
            tree_convolve_many(&tree, d, &rs, &p, &mut buf, &mut many);
            for (k, &r) in rs.iter().enumerate() {
                let one = tree_convolve(&tree, d, r, &p, &mut buf);
                if groups.iter().any(|g| g == &[k]) {
                    assert_eq!(many[k], one, "r {r}");
                }
                let exact = texels.convolve(d, r * r);
                for c in 0..3 {
                    shared += ((many[k][c] - exact[c]).abs() / exact[c]) as f64;
                    single += ((one[c] - exact[c]).abs() / exact[c]) as f64;
                    count += 1.0;
                }
            }
        }
        let (shared, single) = (shared / count, single / count);
        eprintln!(
            "report cuts vs brute force: shared {shared:.2e}, one per roughness {single:.2e}"
        );
        assert!(
            shared < 3e-3 && shared <= 1.1 * single + 1e-6,
            "{shared} vs {single}"
        );
    }

    #[test]
    fn fully_refined_cut_is_the_brute_force_reference() {
        // θ = 0 and leaves at the source texels: the cut is every texel above the horizon,
        // and the sum must equal the brute force to rounding.
        let cube = random_cube(8, 3);
        let tree = CellTree::new(&cube);
        let texels = SourceTexels::new(&cube);
        let mut worst = 0.0f32;
        for r in [0.3f32, 0.7, 1.0] {
            let (out, _) = tree_level(&tree, 4, r, &TIGHT, &NoProgress);
            for face in Face::ALL {
                for j in 0..4 {
                    for i in 0..4 {
                        let a = out.texel(face, i, j);
                        let b = texels.convolve(texel_direction(face, i, j, 4), r * r);
                        for k in 0..3 {
                            worst = worst.max((a[k] - b[k]).abs() / b[k]);
                        }
                    }
                }
            }
        }
        eprintln!("fully refined tree vs brute force: worst relative difference {worst:.2e}");
        assert!(worst < 2e-5, "{worst}");
    }

    #[test]
    fn point_light_is_exact_at_any_distance() {
        // A single bright texel in black: every cell holding it has its centroid on it, so the
        // hierarchical sum of the numerator is exact whatever the opening angle.
        let n = 16;
        let mut cube = Cubemap::new(n);
        cube.faces[Face::Pz as usize]
            .texel_mut(5, 9)
            .copy_from_slice(&[1e5, 1e5, 1e5]);
        let tree = CellTree::new(&cube);
        let texels = SourceTexels::new(&cube);
        let p = TreeParams {
            theta: 0.5,
            kappa: 4.0,
            horizon: 0.5,
        };
        let (out, _) = tree_level(&tree, 8, 0.5, &p, &NoProgress);
        let mut worst = 0.0f32;
        for face in Face::ALL {
            for j in 0..8 {
                for i in 0..8 {
                    let b = texels.convolve(texel_direction(face, i, j, 8), 0.25)[0];
                    if b > 1e-3 {
                        worst = worst.max((out.texel(face, i, j)[0] - b).abs() / b);
                    }
                }
            }
        }
        eprintln!("point light, θ = 0.5: worst relative error {worst:.2e} (normalisation only)");
        assert!(worst < 1e-3, "{worst}");
    }
}
