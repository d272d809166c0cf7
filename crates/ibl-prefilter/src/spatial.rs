//! Coarse levels fitted to the engine's bilinear read (part of `--fit-lookup`): what a level of
//! a few texels a face stores so that the seamless bilinear tap an engine makes between its
//! texels gives the exact kernel, not only at the texel centres.
//!
//! A level stored as footprint means (or centre values) is exact where it is stored, but an
//! engine never reads it there: it reads a bilinear blend of four texels, seamless across faces
//! (texels past an edge re-projected from the neighbour, a cube-corner texel the mean of the
//! three meeting there, as GPUs do: `ibl_core::cube::bilinear_taps`). On a
//! 4×4 face the radiance at r = 1 curves too much over a texel for that blend: measured 2.5–5.4%
//! mean error on four real environments (bench/runtime.md, `% at r = 1`), the largest error of
//! the whole lookup above r = 0.8. The read is linear in the texels v, so the texels that make it
//! closest to the exact radiance f are a linear least-squares problem:
//!
//!   min_v Σ_s Ω_s (B_s·v − f_s)² / (Y(f_s)² + ε²)   subject to   Σ_i Ω_i v_i = Σ_i Ω_i m_i,
//!
//! s over [`SAMPLES_PER_EDGE`]² points per texel (centres of a finer grid, so never a texel
//! centre), Ω_s their solid angles (the report averages over uniform directions), B_s the
//! lookup's four taps, the relative weight 1/Y² matching the report's relative error (ε = 10⁻³
//! of the mean luminance, so black regions do not dominate), one weight for the three channels
//! so they share the matrix. The constraint keeps the level's power (Σ texel·solid angle) that
//! of the footprint means m, exactly as before the fit (item 4 of issue 14: a sun's power kept
//! to 0.1% at every level). Normal equations (n² texels a face: 96 unknowns at 4×4, 384 at
//! 8×8), solved by Cholesky with the constraint by its Lagrange multiplier:
//! v = A⁻¹(b − μΩ), μ = (Ωᵀ A⁻¹ b − P) / (Ωᵀ A⁻¹ Ω).

use ibl_core::cube::{
    bilinear_cell, bilinear_cell_taps, bilinear_taps, bilinear_weights, solid_angle_table,
    texel_direction, Cubemap, Face,
};
use ibl_core::linalg::Cholesky;
use ibl_core::luminance;
use serde::Serialize;
use std::sync::{Arc, Mutex, OnceLock};

/// Levels whose faces have at most this many texels an edge are fitted to the bilinear read
/// (a 16² level's read is already within 0.1–0.4% at r = 1: bench/runtime.md, 5 levels).
pub const SPATIAL_MAX_SIZE: usize = 8;
/// [`SPATIAL_MAX_SIZE`] of the `custom` target: its 16² level holds r ≈ 0.59, whose lobes
/// still have detail a bilinear read of 16² texels blurs (studio 1.05 → 0.81%, city 0.64 →
/// 0.52% worst mean over r ≥ 0.1; docs/notes/custom-log.md), for 0.6 s of a dense fit.
pub const CUSTOM_SPATIAL_MAX_SIZE: usize = 16;

/// Fit samples per texel edge: the exact kernel is evaluated on a grid this much finer.
pub const SAMPLES_PER_EDGE: usize = 4;

/// What `prefilter.json` says of a level fitted to the bilinear read.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReadFit {
    /// Points the read was fitted at (the finer grid's texel centres, every face).
    pub samples: usize,
    /// Mean |read − exact| / exact of luminance over those points (solid-angle weighted), of
    /// the level as it was (footprint means or centre values).
    pub mean_abs_rel_before: f64,
    /// The same of the fitted level.
    pub mean_abs_rel_after: f64,
    /// Texel channels the fit would have made negative (or black where the exact level is
    /// not), stored at their exact value instead, the others fitted again around them.
    pub clamped: usize,
}

/// The fitted texels of a level: `stored` the level as computed (footprint means: their power
/// is kept), `dense` the exact kernel at the centres of a grid [`SAMPLES_PER_EDGE`]× finer.
/// Returns `stored` unchanged when there is nothing to fit (black) or the system is singular.
pub fn fit_bilinear(stored: &Cubemap, dense: &Cubemap) -> (Cubemap, ReadFit) {
    let n = stored.size;
    let m = dense.size;
    assert_eq!(m, n * SAMPLES_PER_EDGE, "dense grid of the fit");
    let k = 6 * n * n;
    let sa_dense = solid_angle_table(m);
    let sa = solid_angle_table(n);
    // Samples in a fixed order (face, row, column): the sums are sequential, so the result is
    // the same for any thread count.
    let mut samples = Vec::with_capacity(6 * m * m);
    for face in Face::ALL {
        for j in 0..m {
            for i in 0..m {
                let f = dense.texel(face, i, j);
                let taps = bilinear_taps(n, texel_direction(face, i, j, m));
                samples.push((taps, f, sa_dense[j * m + i] as f64));
            }
        }
    }
    let total: f64 = samples.iter().map(|s| s.2).sum();
    let mean_y = samples
        .iter()
        .map(|(_, f, w)| luminance(*f) as f64 * w)
        .sum::<f64>()
        / total;
    let before = read_error(stored, &samples);
    let unchanged = |before| {
        let report = ReadFit {
            samples: samples.len(),
            mean_abs_rel_before: before,
            mean_abs_rel_after: before,
            clamped: 0,
        };
        (stored.clone(), report)
    };
    if !(mean_y > 0.0 && mean_y.is_finite()) {
        return unchanged(before);
    }
    let eps2 = (1e-3 * mean_y).powi(2);
    let mut a = vec![0.0f64; k * k];
    let mut b = vec![[0.0f64; 3]; k];
    for (taps, f, omega) in &samples {
        let y = luminance(*f) as f64;
        let w = omega / (y * y + eps2);
        for &(p, wp) in taps {
            let wp = w * wp as f64;
            for c in 0..3 {
                b[p][c] += wp * f[c] as f64;
            }
            for &(q, wq) in taps {
                a[p * k + q] += wp * wq as f64;
            }
        }
    }
    // Σ_i Ω_i v_i: the texels' solid angles, the same table on every face.
    let omega: Vec<f64> = (0..k).map(|p| sa[p % (n * n)] as f64).collect();
    // One factorisation for the constraint's column and the three channels (it was done
    // again for each: four Cholesky factorisations of a 384² matrix were most of an 8²
    // level's fit).
    let Some(chol) = Cholesky::new(&a, k) else {
        return unchanged(before);
    };
    let a_inv_omega = chol.solve(&omega);
    let omega_a_omega: f64 = omega.iter().zip(&a_inv_omega).map(|(o, x)| o * x).sum();
    let mut fitted = stored.clone();
    let mut clamped = 0;
    for c in 0..3 {
        let rhs: Vec<f64> = b.iter().map(|v| v[c]).collect();
        let x = chol.solve(&rhs);
        let power: f64 = (0..k)
            .map(|p| omega[p] * stored.faces[p / (n * n)].data[3 * (p % (n * n)) + c] as f64)
            .sum();
        let omega_x: f64 = omega.iter().zip(&x).map(|(o, v)| o * v).sum();
        let mu = (omega_x - power) / omega_a_omega;
        let mut v: Vec<f64> = (0..k).map(|p| x[p] - mu * a_inv_omega[p]).collect();
        if v.iter().any(|v| !v.is_finite()) {
            return unchanged(before);
        }
        // Light is never negative, and a texel is never black where the exact level is not:
        // where the fit would go below zero (texels larger than what they hold, a 1×1 level),
        // the texel keeps its exact value (the footprint mean) and the other texels are
        // fitted again with it fixed, power kept (an active set, grown until no free texel is
        // negative; at worst every texel is pinned and the level is the exact one). Clamping
        // to 0 instead left a 1×1 Babylon face black (issue 22).
        let mut pinned: Vec<Option<f64>> = vec![None; k];
        let stored_c =
            |p: usize| stored.faces[p / (n * n)].data[3 * (p % (n * n)) + c].max(0.0) as f64;
        loop {
            let negative: Vec<usize> = (0..k)
                .filter(|&p| pinned[p].is_none() && v[p] <= 0.0 && stored_c(p) > 0.0)
                .chain((0..k).filter(|&p| pinned[p].is_none() && v[p] < 0.0))
                .collect();
            if negative.is_empty() {
                break;
            }
            for p in negative {
                if pinned[p].is_none() {
                    pinned[p] = Some(stored_c(p));
                    clamped += 1;
                }
            }
            let Some(w) = solve_pinned(&a, &rhs, &omega, power, &pinned) else {
                return unchanged(before);
            };
            v = w;
        }
        for (p, v) in v.iter().enumerate() {
            fitted.faces[p / (n * n)].data[3 * (p % (n * n)) + c] = *v as f32;
        }
    }
    let after = read_error(&fitted, &samples);
    let report = ReadFit {
        samples: samples.len(),
        mean_abs_rel_before: before,
        mean_abs_rel_after: after,
        clamped,
    };
    (fitted, report)
}

/// The power-constrained least-squares texels with some texels fixed (`pinned`): the normal
/// equations A·v = b restricted to the free texels, the fixed ones moved to the right-hand
/// side, and Σ Ω_i v_i = `power` by its Lagrange multiplier over the free texels.
fn solve_pinned(
    a: &[f64],
    b: &[f64],
    omega: &[f64],
    power: f64,
    pinned: &[Option<f64>],
) -> Option<Vec<f64>> {
    let k = b.len();
    let free: Vec<usize> = (0..k).filter(|&p| pinned[p].is_none()).collect();
    let mut v: Vec<f64> = pinned.iter().map(|p| p.unwrap_or(0.0)).collect();
    if free.is_empty() {
        return Some(v);
    }
    let m = free.len();
    let mut sub = vec![0.0f64; m * m];
    let mut rhs = vec![0.0f64; m];
    let mut om = vec![0.0f64; m];
    let fixed_power: f64 = (0..k).filter_map(|p| pinned[p].map(|x| omega[p] * x)).sum();
    for (r, &p) in free.iter().enumerate() {
        for (c, &q) in free.iter().enumerate() {
            sub[r * m + c] = a[p * k + q];
        }
        let fixed: f64 = (0..k)
            .filter_map(|q| pinned[q].map(|x| a[p * k + q] * x))
            .sum();
        rhs[r] = b[p] - fixed;
        om[r] = omega[p];
    }
    let chol = Cholesky::new(&sub, m)?;
    let (x, y) = (chol.solve(&rhs), chol.solve(&om));
    let oy: f64 = om.iter().zip(&y).map(|(o, v)| o * v).sum();
    let ox: f64 = om.iter().zip(&x).map(|(o, v)| o * v).sum();
    let mu = (ox - (power - fixed_power)) / oy;
    for (r, &p) in free.iter().enumerate() {
        v[p] = x[r] - mu * y[r];
    }
    v.iter().all(|v| v.is_finite()).then_some(v)
}

/// Levels of at most this many texels an edge have their read's power kept (every target,
/// [`keep_read_power`]). The read's power differs from the texels' by O(1/n²): on random
/// texels +0.11% at 4², +0.012% at 8², −0.002% at 16² (`read_weights_give_the_power_of_the_read`),
/// and a 10⁵ one-texel sun through a 4² last level lost 0.28% at r = 1 (bench/runtime.md); past
/// 32² the weights would cost more than they change.
pub const READ_POWER_MAX_SIZE: usize = 32;

/// W_p = ∫ (texel p's weight in the seamless bilinear read) dω over the sphere, for an n×n
/// cube (face·n² + j·n + i, as [`bilinear_taps`]): the read is linear in the texels, so the
/// power of what an engine reads of a level is Σ_p W_p v_p, not the texels' Σ_p Ω_p v_p. They
/// differ because a texel's bilinear tent spreads over its neighbours, whose solid angles
/// differ (most at the face corners), and past the face edges the taps are re-projected from
/// the neighbour face. Midpoint rule on a grid at least 256² a face and an even multiple of n,
/// so the read's kinks (the texel-centre lines) fall on the grid's cell edges and the rule is
/// exact up to the solid angle's curvature within a cell. Sequential sums: deterministic.
///
/// A pure function of n, integrated once a process for each n up to [`READ_POWER_MAX_SIZE`]
/// (393 216 points whatever n, 5–7 ms apiece): a bake's small levels, the runner's probes and
/// the custom lookup's midpoints ask for the same few sizes again and again.
pub fn read_weights(n: usize) -> Arc<[f64]> {
    /// The weights integrated so far, by size.
    type Held = Mutex<Vec<(usize, Arc<[f64]>)>>;
    static CACHE: OnceLock<Held> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    let held = |c: &Held| {
        let c = c.lock().unwrap_or_else(|e| e.into_inner());
        c.iter().find(|(m, _)| *m == n).map(|(_, w)| w.clone())
    };
    if let Some(w) = held(cache) {
        return w;
    }
    // Two threads asking at once both integrate: the same values, the first one kept.
    let w: Arc<[f64]> = integrate_read_weights(n).into();
    if n <= READ_POWER_MAX_SIZE {
        let mut c = cache.lock().unwrap_or_else(|e| e.into_inner());
        if !c.iter().any(|(m, _)| *m == n) {
            c.push((n, w.clone()));
        }
    }
    w
}

/// [`read_weights`], integrated.
fn integrate_read_weights(n: usize) -> Vec<f64> {
    let k = (256usize.div_ceil(n.max(1))).max(2).next_multiple_of(2);
    let m = n * k;
    let sa = solid_angle_table(m);
    // The grid's face coordinates, the same on both axes of every face: the taps from the
    // coordinates directly (a direction per point, re-projected onto its face, was 80 ms of a
    // 256² bake's CPU for its two levels of ≤ 32²).
    let coord: Vec<f32> = (0..m)
        .map(|i| 2.0 * (i as f32 + 0.5) / m as f32 - 1.0)
        .collect();
    // Each coordinate's bilinear cell (first texel x0 ∈ −1 ..= n − 1, fraction) as
    // `bilinear_taps_at` computes it, once an axis rather than once a point, and each
    // cell's taps once a face rather than once a point (the seam rules were most of the cost
    // on small levels, where most points lie in the band past the outer texel centres). The
    // same taps with the same f32 weights, added in the same order: the same bits as summing
    // `bilinear_taps_at` point by point (`read_weights_are_the_taps_summed`), 4–8× faster.
    let cell: Vec<(usize, f32)> = coord
        .iter()
        .map(|&c| {
            let (x0, f) = bilinear_cell(n, c);
            ((x0 + 1) as usize, f)
        })
        .collect();
    let mut w = vec![0.0f64; 6 * n * n];
    let mut taps = Vec::with_capacity((n + 1) * (n + 1));
    for face in Face::ALL {
        taps.clear();
        for y0 in -1..n as isize {
            for x0 in -1..n as isize {
                taps.push(bilinear_cell_taps(n, face, x0, y0));
            }
        }
        for j in 0..m {
            let row = &sa[j * m..(j + 1) * m];
            let (cy, fy) = cell[j];
            for i in 0..m {
                let o = row[i] as f64;
                let (cx, fx) = cell[i];
                let weights = bilinear_weights(fx, fy);
                for ((texels, count), wt) in taps[cy * (n + 1) + cx].iter().zip(weights) {
                    if *count == 1 {
                        w[texels[0]] += o * wt as f64;
                    } else {
                        let wt = o * (wt / *count as f32) as f64;
                        for &p in &texels[..*count] {
                            w[p] += wt;
                        }
                    }
                }
            }
        }
    }
    w
}

/// The weight k of [`sharpen_for_bilinear`] for texels that hold the mean of f × f
/// sub-texels (`footprint_factor`; 1: the centre value): k = 1/12 + (1 − 1/f²)/24.
///
/// A bilinear read of centre samples v = g misses a smooth g by −(h²/12)·g'' per axis on
/// average over a texel (the linear interpolant's mean error, the trapezoid rule's term); a
/// mean over f equally spaced sub-samples holds g + (1 − 1/f²)(h²/24)·g'' (the variance of their
/// offsets, (1 − 1/f²)h²/12, halved). Storing v − k·δ²v per axis (δ² the second difference,
/// ≈ h²·g'') takes both out to second order. Not fitted: on 128², 64² and 32² levels of three
/// panoramas the measured best k was 1/12 (centre values) and 1/8 (2 × 2 means; this gives
/// 0.115), and the bilinear read's error of the exact kernel halved: esplanade at r = 0.1 on
/// 128² 1.19 → 0.55%, studio 0.45 → 0.19%, city 0.52 → 0.24% (docs/notes/custom-log.md).
pub fn sharpen_weight(footprint: usize) -> f32 {
    let f = footprint.max(1) as f32;
    1.0 / 12.0 + (1.0 - 1.0 / (f * f)) / 24.0
}

/// Stores v − k·(δ²ᵢ + δ²ⱼ)v in every texel (the four neighbours across face edges as the
/// seamless read takes them), so that a bilinear read of the level matches the smooth function
/// its texels sample ([`sharpen_weight`]); a texel that would go negative keeps its value
/// (light is never negative; the read's error there is the bilinear one), and each channel is
/// rescaled to keep the level's texel power Σ_p Ω_p v_p. Unlike [`fit_bilinear`] it needs no
/// kernel values between the centres, so it serves the levels too large for that fit.
pub fn sharpen_for_bilinear(level: &mut Cubemap, k: f32) {
    let n = level.size;
    if n < 2 || k == 0.0 {
        return;
    }
    let before = texel_power(level);
    let src = level.clone();
    for face in Face::ALL {
        let out = &mut level.faces[face as usize].data;
        for j in 0..n {
            for i in 0..n {
                let v = src.texel(face, i, j);
                let (x, y) = (i as isize, j as isize);
                let nb = [(x - 1, y), (x + 1, y), (x, y - 1), (x, y + 1)]
                    .map(|(a, b)| src.texel_wrapped(face, a, b));
                let o = 3 * (j * n + i);
                for c in 0..3 {
                    let lap = nb[0][c] + nb[1][c] + nb[2][c] + nb[3][c] - 4.0 * v[c];
                    let s = v[c] - k * lap;
                    out[o + c] = if s >= 0.0 && s.is_finite() { s } else { v[c] };
                }
            }
        }
    }
    let after = texel_power(level);
    for face in &mut level.faces {
        for t in face.data.chunks_exact_mut(3) {
            for c in 0..3 {
                if after[c] > 0.0 && before[c] > 0.0 {
                    t[c] = (t[c] as f64 * (before[c] / after[c])) as f32;
                }
            }
        }
    }
}

/// The texels' power per channel, Σ_p Ω_p v_p.
pub fn texel_power(level: &Cubemap) -> [f64; 3] {
    let sa = solid_angle_table(level.size);
    let mut p = [0.0f64; 3];
    for face in &level.faces {
        for (t, s) in face.data.chunks_exact(3).zip(&sa) {
            for c in 0..3 {
                p[c] += t[c] as f64 * *s as f64;
            }
        }
    }
    p
}

/// Rescales each channel of `level` so that the power of its bilinear read, Σ_p W_p v_p with
/// `w` from [`read_weights`], is `power` (the exact level's texel power, which is the
/// environment's): then a linear blend of two such levels has that power at every lod in
/// between, which is the custom lookup's promise of a sun's power at every roughness (issue 26
/// item 3: 0.1%). One factor per channel and level (within 0.3% of 1 on a 4² level), so no
/// texel changes sign and a level's shape, fitted to the read and the blend, is kept.
/// Channels with no power are left as they are.
pub fn keep_read_power(level: &mut Cubemap, power: [f64; 3], w: &[f64]) {
    let n = level.size;
    assert_eq!(w.len(), 6 * n * n, "read weights of this level's size");
    let mut read = [0.0f64; 3];
    for (f, face) in level.faces.iter().enumerate() {
        for (p, t) in face.data.chunks_exact(3).enumerate() {
            for c in 0..3 {
                read[c] += w[f * n * n + p] * t[c] as f64;
            }
        }
    }
    let scale: [f64; 3] = std::array::from_fn(|c| {
        if read[c] > 0.0 && power[c] > 0.0 && (power[c] / read[c]).is_finite() {
            power[c] / read[c]
        } else {
            1.0
        }
    });
    for face in &mut level.faces {
        for t in face.data.chunks_exact_mut(3) {
            for c in 0..3 {
                t[c] = (t[c] as f64 * scale[c]) as f32;
            }
        }
    }
}

/// A fit sample: its read's taps (`bilinear_taps`: four, a cube-corner one as three texels of a third
/// of its weight, the GPU's corner rule), the exact value, its solid angle.
type Sample = ([(usize, f32); 6], [f32; 3], f64);

/// Solid-angle-weighted mean |read − exact| / exact of luminance at the samples (exact values
/// below 10⁻⁶ of the mean left out, as the runtime report does).
fn read_error(level: &Cubemap, samples: &[Sample]) -> f64 {
    let n = level.size;
    let total: f64 = samples.iter().map(|s| s.2).sum();
    let mean_y: f64 = samples
        .iter()
        .map(|(_, f, w)| luminance(*f) as f64 * w)
        .sum::<f64>()
        / total;
    let (mut err, mut weight) = (0.0, 0.0);
    for (taps, f, w) in samples {
        let y = luminance(*f) as f64;
        if y <= 1e-6 * mean_y {
            continue;
        }
        let mut read = [0.0f32; 3];
        for &(p, wp) in taps {
            let t = level.texel(Face::from_index(p / (n * n)), p % n, (p % (n * n)) / n);
            for c in 0..3 {
                read[c] += wp * t[c];
            }
        }
        err += w * ((luminance(read) as f64 - y) / y).abs();
        weight += w;
    }
    if weight > 0.0 {
        err / weight
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use ibl_core::cube::bilinear_taps_at;
    use ibl_core::sampling::Pcg32;

    /// Smooth and positive everywhere (no clamping), with a soft bright lobe and colour.
    fn smooth(d: Vec3) -> [f32; 3] {
        let d = d.normalize();
        let lobe = (d.dot(Vec3::new(0.4, 0.7, -0.59).normalize()) + 1.0).powi(3);
        [
            0.2 + 0.1 * d.z + lobe,
            0.3 + 0.15 * d.x * d.x + 0.5 * lobe,
            0.25 - 0.1 * d.y + 0.8 * lobe,
        ]
    }

    /// The fit's objective per channel, computed through the sampler itself (not the taps):
    /// Σ_s w_s (read(d_s) − f_s)², w_s = Ω_s / (Y(f_s)² + ε²).
    fn objective(level: &Cubemap, dense: &Cubemap) -> [f64; 3] {
        let m = dense.size;
        let sa = solid_angle_table(m);
        let mut mean_y = (0.0, 0.0);
        for face in Face::ALL {
            for (t, s) in dense.faces[face as usize].data.chunks_exact(3).zip(&sa) {
                mean_y.0 += luminance([t[0], t[1], t[2]]) as f64 * *s as f64;
                mean_y.1 += *s as f64;
            }
        }
        let eps2 = (1e-3 * mean_y.0 / mean_y.1).powi(2);
        let mut j = [0.0f64; 3];
        for face in Face::ALL {
            for y in 0..m {
                for x in 0..m {
                    let f = dense.texel(face, x, y);
                    let read = level.sample_bilinear(texel_direction(face, x, y, m));
                    let lum = luminance(f) as f64;
                    let w = sa[y * m + x] as f64 / (lum * lum + eps2);
                    for c in 0..3 {
                        j[c] += w * (read[c] as f64 - f[c] as f64).powi(2);
                    }
                }
            }
        }
        j
    }

    fn power(c: &Cubemap) -> [f64; 3] {
        let sa = solid_angle_table(c.size);
        let mut p = [0.0; 3];
        for face in &c.faces {
            for (t, s) in face.data.chunks_exact(3).zip(&sa) {
                for k in 0..3 {
                    p[k] += t[k] as f64 * *s as f64;
                }
            }
        }
        p
    }

    /// Sharpening for the bilinear read: the read of a smooth function's centre samples (and of
    /// its 2 × 2 footprint means) follows the function between the centres at least twice as
    /// closely; power is kept; a constant stays constant; a one-texel spike never makes a texel
    /// negative; the weight is 1/12 for centre values and tends to 1/8 for full-texel means.
    #[test]
    fn sharpening_halves_the_bilinear_read_error_and_keeps_power() {
        assert_eq!(sharpen_weight(1), 1.0 / 12.0);
        assert!((sharpen_weight(1 << 20) - 0.125).abs() < 1e-6);
        let mean_rel = |level: &Cubemap, m: usize| {
            let mut e = 0.0f64;
            for face in Face::ALL {
                for y in 0..m {
                    for x in 0..m {
                        let d = texel_direction(face, x, y, m);
                        let (got, want) = (level.sample_bilinear(d), smooth(d));
                        e += ((luminance(got) - luminance(want)) / luminance(want)).abs() as f64;
                    }
                }
            }
            e / (6 * m * m) as f64
        };
        for (n, f) in [(16usize, 1usize), (16, 2), (32, 1)] {
            let level = Cubemap::from_fn(n * f, smooth);
            let mut level = {
                let mut c = level;
                while c.size > n {
                    c = c.downsample();
                }
                c
            };
            let before = mean_rel(&level, 4 * n);
            let p0 = power(&level);
            sharpen_for_bilinear(&mut level, sharpen_weight(f));
            let after = mean_rel(&level, 4 * n);
            let p1 = power(&level);
            for c in 0..3 {
                assert!((p1[c] / p0[c] - 1.0).abs() < 1e-6, "n {n} f {f}: power");
            }
            assert!(after < 0.5 * before, "n {n} f {f}: {before} -> {after}");
        }
        let mut flat = Cubemap::constant(8, [0.3, 0.5, 0.7]);
        sharpen_for_bilinear(&mut flat, sharpen_weight(1));
        for face in &flat.faces {
            for t in face.data.chunks_exact(3) {
                for (c, want) in [0.3f32, 0.5, 0.7].iter().enumerate() {
                    assert!((t[c] - want).abs() < 1e-6);
                }
            }
        }
        let mut spike = Cubemap::constant(8, [0.01, 0.01, 0.01]);
        spike.faces[3].data[3 * (3 * 8 + 5)..3 * (3 * 8 + 5) + 3].fill(1e5);
        sharpen_for_bilinear(&mut spike, sharpen_weight(2));
        assert!(spike
            .faces
            .iter()
            .all(|f| f.data.iter().all(|v| *v >= 0.0 && v.is_finite())));
    }

    /// The fit is the constrained least-squares optimum: its power is the stored level's,
    /// and no perturbation that keeps the power (random, projected) lowers the objective,
    /// measured through `Cubemap::sample_bilinear` rather than the taps the fit used.
    #[test]
    fn fit_is_the_constrained_optimum_and_keeps_power() {
        for n in [1usize, 2, 4] {
            let dense = Cubemap::from_fn(n * SAMPLES_PER_EDGE, smooth);
            let stored = Cubemap::from_fn(n, smooth);
            let (fitted, report) = fit_bilinear(&stored, &dense);
            let (p0, p1) = (power(&stored), power(&fitted));
            for c in 0..3 {
                assert!(
                    (p1[c] / p0[c] - 1.0).abs() < 1e-6,
                    "n {n} power {p1:?} vs {p0:?}"
                );
            }
            assert!(
                report.mean_abs_rel_after < report.mean_abs_rel_before,
                "{report:?}"
            );
            // A 1×1 level cannot hold the lobe without a negative texel; larger ones can, and
            // are the optimum itself.
            assert_eq!(report.clamped > 0, n == 1, "n {n}: {report:?}");
            if report.clamped > 0 {
                continue;
            }
            let j0 = objective(&fitted, &dense);
            let sa = solid_angle_table(n);
            let mut rng = Pcg32::new(n as u64, 5);
            for _ in 0..20 {
                // A random direction of texel change with Σ Ω δ = 0.
                let mut delta: Vec<f64> = (0..6 * n * n).map(|_| rng.next_f64() - 0.5).collect();
                let om = |p: usize| sa[p % (n * n)] as f64;
                let (dot, norm) = (0..delta.len()).fold((0.0, 0.0), |(a, b), p| {
                    (a + om(p) * delta[p], b + om(p) * om(p))
                });
                for (p, d) in delta.iter_mut().enumerate() {
                    *d -= dot / norm * om(p);
                }
                for t in [-0.02f32, 0.02] {
                    let mut moved = fitted.clone();
                    for (p, d) in delta.iter().enumerate() {
                        for v in &mut moved.faces[p / (n * n)].data[3 * (p % (n * n))..][..3] {
                            *v += t * *d as f32;
                        }
                    }
                    let j1 = objective(&moved, &dense);
                    for c in 0..3 {
                        assert!(
                            j1[c] >= j0[c] * (1.0 - 1e-6),
                            "n {n} channel {c}: a feasible step lowers the objective {} → {}",
                            j0[c],
                            j1[c]
                        );
                    }
                }
            }
        }
    }

    /// On a smooth function the fitted 4×4 level's read is closer to it than the centre
    /// values' read, by Monte Carlo over random directions (independent of the fit's grid).
    #[test]
    fn fitted_read_is_closer_at_random_directions() {
        let n = 4;
        let dense = Cubemap::from_fn(n * SAMPLES_PER_EDGE, smooth);
        let centres = Cubemap::from_fn(n, smooth);
        let (fitted, _) = fit_bilinear(&centres, &dense);
        let mut rng = Pcg32::new(9, 9);
        let (mut e_centres, mut e_fitted) = (0.0, 0.0);
        let count = 20000;
        for _ in 0..count {
            // Uniform on the sphere (Archimedes: z uniform, azimuth uniform).
            let (z, phi) = (
                2.0 * rng.next_f32() - 1.0,
                std::f32::consts::TAU * rng.next_f32(),
            );
            let s = (1.0 - z * z).max(0.0).sqrt();
            let d = Vec3::new(s * phi.cos(), s * phi.sin(), z);
            let want = luminance(smooth(d)) as f64;
            let rel = |c: &Cubemap| ((luminance(c.sample_bilinear(d)) as f64 - want) / want).abs();
            e_centres += rel(&centres) / count as f64;
            e_fitted += rel(&fitted) / count as f64;
        }
        eprintln!("4×4 read: centre values {e_centres:.5}, fitted {e_fitted:.5}");
        assert!(e_fitted < 0.5 * e_centres, "{e_fitted} vs {e_centres}");
    }

    /// ∫ read dω of `level` through `Cubemap::sample_bilinear` (not the taps the weights
    /// use), midpoint rule on an m×m grid a face.
    fn read_power_by_sampling(level: &Cubemap, m: usize) -> [f64; 3] {
        let sa = solid_angle_table(m);
        let mut p = [0.0f64; 3];
        for face in Face::ALL {
            for j in 0..m {
                for i in 0..m {
                    let v = level.sample_bilinear(texel_direction(face, i, j, m));
                    for c in 0..3 {
                        p[c] += v[c] as f64 * sa[j * m + i] as f64;
                    }
                }
            }
        }
        p
    }

    /// The per-axis cells give the bits of the taps summed point by point (the plain form
    /// below, `bilinear_taps_at` at every grid point), at every size the bake asks for; and
    /// the integration is held once a process.
    #[test]
    fn read_weights_are_the_taps_summed() {
        for n in [1usize, 2, 3, 4, 8, 16, 32] {
            let k = (256usize.div_ceil(n)).max(2).next_multiple_of(2);
            let m = n * k;
            let sa = solid_angle_table(m);
            let coord: Vec<f32> = (0..m)
                .map(|i| 2.0 * (i as f32 + 0.5) / m as f32 - 1.0)
                .collect();
            let mut want = vec![0.0f64; 6 * n * n];
            for face in Face::ALL {
                for j in 0..m {
                    for i in 0..m {
                        let o = sa[j * m + i] as f64;
                        for (p, wp) in bilinear_taps_at(n, face, coord[i], coord[j]) {
                            want[p] += o * wp as f64;
                        }
                    }
                }
            }
            let got = read_weights(n);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(&want), "n {n}");
            assert!(Arc::ptr_eq(&got, &read_weights(n)), "n {n}: held once");
        }
    }

    /// The read weights integrate the read: Σ W = 4π, Σ W·v equals the read's power sampled
    /// through the sampler on another grid, and on a 4² level they differ from the texels'
    /// solid angles by more than the 0.1% a sun's power must keep (why they exist).
    #[test]
    fn read_weights_give_the_power_of_the_read() {
        for n in [1usize, 2, 4, 8, 16] {
            let w = read_weights(n);
            let total: f64 = w.iter().sum();
            assert!(
                (total / (4.0 * std::f64::consts::PI) - 1.0).abs() < 1e-5,
                "n {n}: {total}"
            );
            let mut rng = Pcg32::new(n as u64, 3);
            let mut level = Cubemap::new(n);
            for face in &mut level.faces {
                for v in &mut face.data {
                    *v = rng.next_f32() * 10.0;
                }
            }
            let by_weights: f64 = level
                .faces
                .iter()
                .enumerate()
                .flat_map(|(f, face)| {
                    let w = &w;
                    face.data
                        .chunks_exact(3)
                        .enumerate()
                        .map(move |(p, t)| w[f * n * n + p] * t[0] as f64)
                })
                .sum();
            let sampled = read_power_by_sampling(&level, 480);
            assert!(
                (by_weights / sampled[0] - 1.0).abs() < 2e-5,
                "n {n}: weights {by_weights} sampled {}",
                sampled[0]
            );
            let texels = texel_power(&level)[0];
            eprintln!(
                "n {n}: read power / texel power − 1 = {:+.5}%",
                100.0 * (sampled[0] / texels - 1.0)
            );
            if n == 4 {
                let sa = solid_angle_table(n);
                let worst = (0..6 * n * n)
                    .map(|p| (w[p] / sa[p % (n * n)] as f64 - 1.0).abs())
                    .fold(0.0, f64::max);
                assert!(worst > 1e-3, "4²: W/Ω − 1 at most {worst}");
            }
        }
    }

    /// After `keep_read_power` the read (sampled through the sampler) has the power asked
    /// for, per channel, on a level holding a bright texel (a sun) and a dim rest.
    #[test]
    fn keep_read_power_sets_the_power_of_the_read() {
        for n in [2usize, 4, 8] {
            let mut level = Cubemap::constant(n, [0.05, 0.04, 0.03]);
            let k = 3 * (n * n / 2 + 1);
            level.faces[2].data[k..k + 3].copy_from_slice(&[1e5, 5e4, 2e4]);
            let want = [1.0f64, 2.0, 3.0].map(|x| x * 1000.0);
            keep_read_power(&mut level, want, &read_weights(n));
            let got = read_power_by_sampling(&level, 480);
            for c in 0..3 {
                assert!(
                    (got[c] / want[c] - 1.0).abs() < 2e-5,
                    "n {n} c {c}: {got:?}"
                );
            }
        }
        // Black stays black.
        let mut black = Cubemap::new(4);
        keep_read_power(&mut black, [1.0; 3], &read_weights(4));
        assert!(black.faces.iter().all(|f| f.data.iter().all(|v| *v == 0.0)));
    }

    #[test]
    fn black_stays_black_and_a_sun_on_black_stays_finite_and_non_negative() {
        let (fitted, report) = fit_bilinear(&Cubemap::new(2), &Cubemap::new(8));
        assert!(fitted
            .faces
            .iter()
            .all(|f| f.data.iter().all(|v| *v == 0.0)));
        assert_eq!(report.mean_abs_rel_before, report.mean_abs_rel_after);
        // A cosine lobe of 10⁵ on black: half the sphere is exactly 0.
        let sun = |d: Vec3| {
            let c = d
                .normalize()
                .dot(Vec3::new(0.1, -0.99, 0.05).normalize())
                .max(0.0);
            [1e5 * c, 8e4 * c, 6e4 * c]
        };
        let (fitted, report) = fit_bilinear(&Cubemap::from_fn(4, sun), &Cubemap::from_fn(16, sun));
        assert!(fitted
            .faces
            .iter()
            .all(|f| f.data.iter().all(|v| v.is_finite() && *v >= 0.0)));
        assert!(report.mean_abs_rel_after.is_finite());
    }
}
