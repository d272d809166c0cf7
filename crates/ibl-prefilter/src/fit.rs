//! Levels fitted to the engine's lookup (`--fit-lookup`): what each level stores so that the
//! blend an engine makes between levels matches the exact kernel at continuous roughness,
//! instead of each level being the exact kernel at its own roughness only.
//!
//! An engine reads level j with weight w_j(r) = max(0, 1 − |lod(r) − j|), its lod mapping fixed
//! (`ibl_target::LodMapping`). Between levels the blend of two GGX lobes is not the lobe at the
//! roughness between them: near a small bright source the peak radiance goes as 1/α² = r⁻⁴,
//! a convex function of r, so the blend of two exact levels overshoots there (and a level's
//! tail undershoots). The mapping being fixed, the stored values are ours to choose.
//!
//! Per texel and channel, level l stores L_l = P(r_l) + δ_l, P(r) the exact kernel at r
//! filtered at level l's resolution, with δ_l the minimax step: the one that minimises the
//! largest relative error of the lookup, max over r of |Σ_j w_j(r) L_j − P(r)| / Y(P(r)) (Y the
//! luminance, as the runtime report measures), over r_l and [`FIT_NODES`] nodes a side of it in
//! [r_{l−1}, r_{l+1}]. The runtime report takes the worst roughness, so the worst is what is
//! minimised: a least-squares fit measured worse, trading a large error at r_l itself for the
//! middle of the interval (studio, 64² × 5 levels: 26% → 52% at r = r_1; minimax: 17%).
//!
//! Each level keeps the power of its exact level (Σ texel·solid angle, per channel: [`Power`]).
//! The exact kernel has the environment's power at every roughness, so a blend of levels that
//! each keep it does too; left free, the per-texel fit moved a level's power by up to 31% (a
//! one-texel sun on a 16² chain) where the blend overshoots near a small source. The constraint
//! couples the texels through one Lagrange multiplier per level and channel: what is minimised
//! is Σ_t Ω_t g_t(δ_t), g_t texel t's worst relative error, subject to Σ_t Ω_t δ_t = 0, and
//! bright texels, whose relative error is cheapest to move, carry the change
//! (`power_kept_steps`). Measured on the fixtures the worst runtime error is unchanged to
//! 0.1 point (7 levels of 256²: 2.3 / 1.3 / 3.1 / 9.6% on city / sunset / interior / studio).
//!
//! The levels have different resolutions, so they are solved one at a time, fine to coarse (a
//! Gauss–Seidel sweep): level l − 1 enters as stored, read as the engine reads it at level l's
//! texel centres ([`read_at_texels`]; already fitted; level 0, the mirror, stays exact), and the
//! coarser level l + 1, not solved yet (its exact level, computed before any fit, read the same
//! way), is assumed to move by the same fraction of its value, δ_{l+1} = δ_l·P(r_{l+1})/P(r_l)
//! (held at its exact value the fit over-corrects, l + 1 then moving the same way; moved by
//! the same absolute δ a level whose values are 10× smaller would be off by 10× more). The
//! lookup's error at a node is then affine in δ, |c_k + (w_l + w_{l+1}·P(r_{l+1})/P(r_l))·δ| /
//! Y_k with c_k its error at δ = 0; the maximum of these is convex in δ and is minimised by a
//! ternary search, δ ≥ −P(r_l) so that L ≥ 0. A second sweep ([`SWEEPS`]) fits each level
//! again with both neighbours as stored and read ([`Coarser::Fixed`]); it needs no new kernel
//! evaluations (the nodes are kept) and lowers the worst error a little more (7 levels of 256²:
//! interior 3.4 → 3.1%, studio 10.1 → 9.5%; further sweeps changed nothing measurable).
//!
//! The last level's texels stay the kernel's (at r = 1 the lookup reads it alone; only its
//! bilinear read is fitted, as every level of at most 8² texels a face is: `crate::spatial`,
//! added after this fit as a correction), and level 1 is fitted over
//! [r_1, r_2] only: between the mirror and level 1 no single value per texel can follow a small
//! source (the exact blend is off by 100–250% there).

use crate::stats::ErrorStats;
use ibl_core::cube::Cubemap;
use ibl_core::luminance;
use ibl_target::LodMapping;
use serde::Serialize;

/// Nodes per side of a fitted level (midpoints of `FIT_NODES` equal steps in r).
pub const FIT_NODES: usize = 2;

/// Gauss–Seidel sweeps over the levels (the first with the coarser neighbour following).
pub const SWEEPS: usize = 2;

/// How the coarser neighbour's value enters a level's fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coarser {
    /// Not fitted yet: assumed to move by the same fraction of its value (first sweep).
    Follows,
    /// As stored (later sweeps).
    Fixed,
}

/// What the engine reads of `level` at the texel centres of an n×n level (its bilinear tap
/// there, seamless across faces): how a neighbouring level enters this one's fit.
///
/// The neighbours of a chain level are twice and half its size, and there the taps need no
/// direction: a coarse texel's centre is the shared corner of 2×2 finer texels (weights ½,
/// always inside the face), and a fine texel's centre lies a quarter of a coarse texel from
/// its nearest coarse centres (weights ¼, ¾), inside the face but for the outermost ring,
/// which is read through the sampler (re-projected across the edge). The same lerps as
/// [`Cubemap::sample_bilinear`], whose weights there are these to f32 round-off (through the
/// normalised direction); the sampler on every texel was 10–25% of the fit's time.
pub fn read_at_texels(level: &Cubemap, n: usize) -> Cubemap {
    use rayon::prelude::*;
    let m = level.size;
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    // A face a job: every texel is its own read (the same bits for any thread count).
    if m == 2 * n {
        let mut out = Cubemap::new(n);
        out.faces
            .par_iter_mut()
            .zip(&level.faces)
            .for_each(|(o, src)| {
                for j in 0..n {
                    for i in 0..n {
                        let (a, b) = (src.texel(2 * i, 2 * j), src.texel(2 * i + 1, 2 * j));
                        let (c, e) = (src.texel(2 * i, 2 * j + 1), src.texel(2 * i + 1, 2 * j + 1));
                        let t = o.texel_mut(i, j);
                        for k in 0..3 {
                            let (top, bot) = (lerp(a[k], b[k], 0.5), lerp(c[k], e[k], 0.5));
                            t[k] = lerp(top, bot, 0.5);
                        }
                    }
                }
            });
        return out;
    }
    if n == 2 * m && m >= 2 {
        let mut out = Cubemap::new(n);
        // Fine texel i's centre at coarse coordinate (i − 1)/2 + ¼: even i past coarse
        // centre i/2 − 1 by ¾, odd i past (i − 1)/2 by ¼.
        let tap = |i: usize| -> (usize, f32) {
            if i.is_multiple_of(2) {
                (i / 2 - 1, 0.75)
            } else {
                ((i - 1) / 2, 0.25)
            }
        };
        let faces = out.faces.par_iter_mut().zip(&level.faces).enumerate();
        faces.for_each(|(fi, (o, src))| {
            let face = ibl_core::cube::Face::from_index(fi);
            for j in 0..n {
                for i in 0..n {
                    let t = o.texel_mut(i, j);
                    if i == 0 || j == 0 || i == n - 1 || j == n - 1 {
                        let d = ibl_core::cube::texel_direction(face, i, j, n);
                        t.copy_from_slice(&level.sample_bilinear(d));
                        continue;
                    }
                    let ((x0, fx), (y0, fy)) = (tap(i), tap(j));
                    let (a, b) = (src.texel(x0, y0), src.texel(x0 + 1, y0));
                    let (c, e) = (src.texel(x0, y0 + 1), src.texel(x0 + 1, y0 + 1));
                    for k in 0..3 {
                        let (top, bot) = (lerp(a[k], b[k], fx), lerp(c[k], e[k], fx));
                        t[k] = lerp(top, bot, fy);
                    }
                }
            }
        });
        return out;
    }
    Cubemap::from_fn(n, |d| level.sample_bilinear(d))
}

/// A roughness at which the fit of level l compares the lookup with the exact kernel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Node {
    /// The node's roughness r.
    pub roughness: f32,
    /// The engine's blend weight at this roughness of level l − 1.
    pub w_lo: f64,
    /// The engine's blend weight at this roughness of level l itself.
    pub w_self: f64,
    /// The engine's blend weight at this roughness of level l + 1.
    pub w_hi: f64,
}

/// What the fit of one level needs: the neighbours' roughness and the nodes.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// The level l being fitted.
    pub level: usize,
    /// r_{l−1} (the mirror 0 for level 1).
    pub lo: f32,
    /// r_{l+1}, none for the chain's last level (or where the lookup never goes past l).
    pub hi: Option<f32>,
    /// Where the lookup is compared with the exact kernel, `FIT_NODES` each side of r_l.
    pub nodes: Vec<Node>,
}

/// The engine's weight of level `j` at roughness `r`: its lod clamped to the chain, then linear
/// between levels (a trilinear sampler).
pub fn blend_weight(mapping: LodMapping, r: f32, levels: usize, size: usize, j: usize) -> f64 {
    let lod = mapping.lod(r, levels, size) as f64;
    (1.0 - (lod - j as f64).abs()).max(0.0)
}

/// The nodes of level `l` (≥ 1) of a chain of `levels` levels read through `mapping`:
/// `per_side` midpoints of equal steps in r on [r_{l−1}, r_l] (not for level 1, next to the
/// mirror) and on [r_l, r_{l+1}].
pub fn plan(mapping: LodMapping, l: usize, levels: usize, size: usize, per_side: usize) -> Plan {
    assert!(l >= 1 && l < levels, "level {l} of {levels} is not fitted");
    let r_at = |j: usize| mapping.level_roughness(j, levels, size);
    let (lo, rl) = (r_at(l - 1), r_at(l));
    let hi = (l + 1 < levels).then(|| r_at(l + 1)).filter(|&h| h > rl);
    let mut nodes = Vec::new();
    let mut side = |a: f32, b: f32| {
        let h = (b - a) as f64 / per_side as f64;
        for i in 0..per_side {
            let r = (a as f64 + (i as f64 + 0.5) * h) as f32;
            let w = |j: usize| blend_weight(mapping, r, levels, size, j);
            nodes.push(Node {
                roughness: r,
                w_lo: w(l - 1),
                w_self: w(l),
                w_hi: if l + 1 < levels { w(l + 1) } else { 0.0 },
            });
        }
    };
    // Not the interval next to the mirror: there the blend of a sharp image and a lobe is off
    // by 100–250% at small sources whatever level 1 stores (measured, bench/runtime.md), and
    // fitting it would pull level 1 far from its own roughness.
    if rl > lo && l >= 2 {
        side(lo, rl);
    }
    if let Some(h) = hi {
        side(rl, h);
    }
    Plan {
        level: l,
        lo,
        hi,
        nodes,
    }
}

/// Whether a fitted level keeps the power of its exact level.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Power {
    /// Σ texel·solid angle of each channel is the exact level's (what the bake does).
    Kept,
    /// Each texel's own minimax step, free (the unconstrained optimum).
    Free,
}

/// The fitted values of one level (see the module doc): `exact` the kernel at r_l, `lo` the
/// finer neighbour and `hi` the coarser one as read at this level's texel centres, `at_nodes[k]`
/// the kernel at `plan.nodes[k]`, all at the level's size. A texel whose weights vanish (black
/// everywhere) keeps its exact value.
pub fn fit_level(
    plan: &Plan,
    exact: &Cubemap,
    lo: &Cubemap,
    hi: Option<&Cubemap>,
    at_nodes: &[Cubemap],
    coarser: Coarser,
    power: Power,
) -> Cubemap {
    use rayon::prelude::*;
    assert_eq!(at_nodes.len(), plan.nodes.len());
    let n = exact.size;
    let per_face = n * n;
    let omega = ibl_core::cube::solid_angle_table(n);
    let mut out = exact.clone();
    // One channel at a time: the hulls of one channel are what the bake holds at its peak
    // (three at once were 40% of it at 512²).
    for c in 0..3 {
        // Each texel's error as a function of its step δ, as the vertices of that convex
        // piecewise-linear function. Texels are independent here: in parallel, in chunks of
        // a fixed size collected in order (the same result for any thread count), each
        // chunk's vertices in one buffer (one allocation per chunk, not per texel: the
        // per-texel vectors were half the fit's time and most of its peak at 512²).
        let chunks: Vec<HullChunk> = (0..(6 * per_face).div_ceil(HULL_CHUNK))
            .into_par_iter()
            .map(|k| {
                let range = k * HULL_CHUNK..((k + 1) * HULL_CHUNK).min(6 * per_face);
                let mut chunk = HullChunk::with_capacity(range.len());
                let mut terms = Vec::with_capacity(plan.nodes.len() + 1);
                let mut scratch = HullScratch::default();
                let (mut f, mut t) = (range.start / per_face, range.start % per_face);
                for _ in range {
                    let px = |c: &Cubemap| {
                        let d = &c.faces[f].data[3 * t..3 * t + 3];
                        [d[0] as f64, d[1] as f64, d[2] as f64]
                    };
                    let (plo, phi, pl) = (px(lo), hi.map(px).unwrap_or([0.0; 3]), px(exact));
                    // The coarser level moves by the same fraction of its value.
                    let coarser_ratio = if pl[c] > 0.0 && coarser == Coarser::Follows {
                        phi[c] / pl[c]
                    } else {
                        0.0
                    };
                    // The lookup's error at r_l and at each node, affine in the step δ.
                    terms.clear();
                    terms.push(Term::new(0.0, 1.0, luma(pl)));
                    for (node, cube) in plan.nodes.iter().zip(at_nodes) {
                        let p = px(cube);
                        let base = node.w_lo * plo[c] + node.w_self * pl[c] + node.w_hi * phi[c];
                        let slope = node.w_self + node.w_hi * coarser_ratio;
                        terms.push(Term::new(base - p[c], slope, luma(p)));
                    }
                    chunk.push(&terms, -pl[c], &mut scratch);
                    t += 1;
                    if t == per_face {
                        (f, t) = (f + 1, 0);
                    }
                }
                chunk
            })
            .collect();
        let hulls = Hulls { chunks };
        let steps = match power {
            Power::Free => (0..hulls.len())
                .map(|t| hulls.get(t).0[hulls.chunks[t / HULL_CHUNK].at[t % HULL_CHUNK] as usize].0)
                .collect(),
            Power::Kept => {
                // Texel i's solid angle, its index within its face a mask when n is a power
                // of two (a division per call was a third of the steps' time).
                let mask = per_face.is_power_of_two().then(|| per_face - 1);
                power_kept_steps(&hulls, |i| {
                    omega[mask.map_or_else(|| i % per_face, |m| i & m)] as f64
                })
            }
        };
        drop(hulls);
        for (i, delta) in steps.into_iter().enumerate() {
            let (f, t) = (i / per_face, i % per_face);
            let v = &mut out.faces[f].data[3 * t + c];
            let stored = (*v as f64 + delta).max(0.0);
            if stored.is_finite() {
                *v = stored as f32;
            }
        }
    }
    out
}

/// The steps δ_t of channel `c` that minimise Σ_t Ω_t g_t(δ_t) (g_t a texel's worst relative
/// error) subject to Σ_t Ω_t δ_t = 0: the level keeps its exact power, at every roughness the
/// exact kernel's. Lagrange: each texel minimises g_t(δ) + μδ alone (Ω_t cancels), at a vertex
/// of its hull; as the price μ moves away from 0 a texel steps to its next vertex when μ
/// reaches minus the slope between them. The steps, sorted by that price, are taken until the
/// power change crosses 0, and the last one only in part, so the change is exactly 0. Bright
/// texels, whose relative error is cheapest to move, carry it.
fn power_kept_steps<'a>(hulls: &'a Hulls, omega: impl Fn(usize) -> f64 + Sync) -> Vec<f64> {
    // Every texel with its chunk and its index there (in texel order, chunk by chunk).
    let texels = || {
        hulls
            .chunks
            .iter()
            .enumerate()
            .flat_map(|(k, c)| (0..c.len()).map(move |u| (k * HULL_CHUNK + u, c, u)))
    };
    let mut steps: Vec<f64> = texels()
        .map(|(_, c, u)| c.get(u).0[c.at[u] as usize].0)
        .collect();
    // Ordered sum: the same bits for any thread count.
    let change: f64 = steps.iter().enumerate().map(|(t, d)| omega(t) * d).sum();
    if change == 0.0 || !change.is_finite() {
        return steps;
    }
    // Too much power (change > 0): prices rise, texels step left; too little: right.
    let left = change > 0.0;
    // Texel t's steps that way ([`steps_of`]), (price to reach, texel, vertex moved to), in
    // order of rising price (its hull is convex with strict corners). Left: vertices i−1 … 0;
    // right: i+1 … and past the last vertex, where g rises along its steepest piece without
    // end (a step, marked by the vertex count, that can take any amount).
    let vertex = |t: usize, j: usize| hulls.get(t).0.get(j).map(|v| v.0);
    // Power moved by one step (from the adjacent vertex; infinite for the unbounded one).
    let moved = |&(_, t, j): &(f64, u32, u32)| -> f64 {
        let (t, j) = (t as usize, j as usize);
        let v = hulls.get(t).0;
        match v.get(j) {
            Some(to) => {
                let from = if left { j + 1 } else { j - 1 };
                omega(t) * (to.0 - v[from].0)
            }
            None => {
                if left {
                    f64::NEG_INFINITY
                } else {
                    f64::INFINITY
                }
            }
        }
    };
    // The steps are taken in the total order (price, texel, vertex) until the power change
    // crosses 0. Sorting every step (or selecting medians of all of them, before) cost more
    // than the hulls: instead a radix select. One pass sums the power each range of prices
    // moves (2^[`PRICE_BUCKET_BITS`] ranges, by the leading bits of the price in `total_cmp`
    // order), which gives the range where the change crosses 0; a second takes every step
    // below that range (a texel's steps rise in price, so each moves to the farthest vertex
    // it reaches there) and keeps only the steps inside it, which are then ordered. Both
    // passes in texel order: the same sums, bits, for any thread count.
    let bucket = |price: f64| -> usize {
        let k = price.to_bits();
        let k = if (k as i64) < 0 { !k } else { k | (1 << 63) };
        (k >> (64 - PRICE_BUCKET_BITS)) as usize
    };
    // The events of a group of chunks in parallel (their slopes and the hulls they read are
    // most of the cost), then added in texel order: the same sums, bits, as one pass.
    use rayon::prelude::*;
    let mut sums = vec![0.0f64; 1 << PRICE_BUCKET_BITS];
    let per_chunk = |(k, c): (usize, &'a HullChunk)| -> Vec<(u32, f64)> {
        (0..c.len())
            .flat_map(|u| steps_of(c, u, k * HULL_CHUNK + u, left))
            .map(|e| (bucket(e.0) as u32, moved(&e)))
            .collect()
    };
    for (g, group) in hulls.chunks.chunks(EVENT_GROUP).enumerate() {
        let group: Vec<Vec<(u32, f64)>> = group
            .par_iter()
            .enumerate()
            .map(|(k, c)| per_chunk((g * EVENT_GROUP + k, c)))
            .collect();
        for (b, m) in group.into_iter().flatten() {
            sums[b as usize] += m;
        }
    }
    let mut left_over = change;
    let mut crossing = usize::MAX;
    for (b, &sum) in sums.iter().enumerate() {
        if sum == 0.0 {
            continue;
        }
        if (left_over + sum) * left_over <= 0.0 || !sum.is_finite() {
            crossing = b;
            break;
        }
        left_over += sum;
    }
    drop(sums);
    // Each texel's steps are its own: a chunk a job, the crossing range's events collected in
    // texel order (the walk below sums them in the order they come).
    let mut events: Vec<(f64, u32, u32)> = hulls
        .chunks
        .par_iter()
        .zip(steps.par_chunks_mut(HULL_CHUNK))
        .enumerate()
        .map(|(k, (c, st))| {
            let mut inside = Vec::new();
            for (u, step) in st.iter_mut().enumerate() {
                for e in steps_of(c, u, k * HULL_CHUNK + u, left) {
                    let b = bucket(e.0);
                    if b < crossing {
                        *step = c.get(u).0[e.2 as usize].0;
                    } else if b == crossing {
                        inside.push(e);
                    } else {
                        break;
                    }
                }
            }
            inside
        })
        .collect::<Vec<_>>()
        .concat();
    // Inside the crossing range: split at the median (deterministic introselect), take the
    // cheaper half whole when the change does not cross 0 inside it, else look inside it;
    // small ranges are sorted and walked one step at a time.
    let order = |a: &(f64, u32, u32), b: &(f64, u32, u32)| {
        a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2))
    };
    let mut rest: &mut [(f64, u32, u32)] = &mut events;
    const WALK: usize = 2048;
    while rest.len() > WALK {
        let mid = rest.len() / 2;
        rest.select_nth_unstable_by(mid, order);
        let (head, tail) = std::mem::take(&mut rest).split_at_mut(mid);
        let sum: f64 = head.iter().map(moved).sum();
        if (left_over + sum) * left_over <= 0.0 || !sum.is_finite() {
            rest = head;
            continue;
        }
        for &(_, t, j) in head.iter() {
            let to = hulls.get(t as usize).0[j as usize].0;
            let t = t as usize;
            // The farthest vertex this half reaches.
            if (left && to < steps[t]) || (!left && to > steps[t]) {
                steps[t] = to;
            }
        }
        left_over += sum;
        rest = tail;
    }
    rest.sort_unstable_by(order);
    for &(_, t, j) in rest.iter() {
        let (t, j) = (t as usize, j as usize);
        let Some(to) = vertex(t, j) else {
            steps[t] -= left_over / omega(t);
            return steps;
        };
        let moved = omega(t) * (to - steps[t]);
        if (left_over + moved) * left_over <= 0.0 && moved != 0.0 {
            // This step crosses 0: only the share of it that makes the change exactly 0.
            steps[t] += (to - steps[t]) * (-left_over / moved);
            return steps;
        }
        left_over += moved;
        steps[t] = to;
    }
    steps
}

/// Texel t's steps the way `left` says ([`power_kept_steps`]), u its index in its chunk c.
fn steps_of(
    c: &HullChunk,
    u: usize,
    t: usize,
    left: bool,
) -> impl Iterator<Item = (f64, u32, u32)> + '_ {
    let (v, ray) = c.get(u);
    let i = c.at[u] as usize;
    let slope = move |j: usize| (v[j].1 - v[j - 1].1) / (v[j].0 - v[j - 1].0);
    let n = if left { i } else { v.len() - i };
    (0..n).map(move |k| {
        let texel = t as u32;
        if left {
            let j = i - k;
            (-slope(j), texel, (j - 1) as u32)
        } else {
            let j = i + 1 + k;
            if j < v.len() {
                (slope(j), texel, j as u32)
            } else {
                (ray, texel, j as u32)
            }
        }
    })
}

/// Leading bits of a price that name its range in [`power_kept_steps`]'s radix select
/// (sign, exponent and 4 bits of mantissa: ranges a sixteenth of a binade wide).
const PRICE_BUCKET_BITS: u32 = 16;

/// Chunks of [`Hulls`] whose events [`power_kept_steps`] lists at once (about 100 KB each).
const EVENT_GROUP: usize = 8;

/// Texels a chunk of [`Hulls`] holds: the unit of the parallel build, fixed so that the
/// result does not depend on the thread count.
const HULL_CHUNK: usize = 4096;

/// The hulls of a range of texels, their vertices in one buffer: texel t's are
/// `vertices[start[t]..start[t + 1]]`.
struct HullChunk {
    vertices: Vec<(f64, f64)>,
    start: Vec<u32>,
    ray: Vec<f64>,
    /// The free minimiser's vertex (of g alone, the price 0).
    at: Vec<u32>,
}

impl HullChunk {
    fn with_capacity(texels: usize) -> Self {
        let mut start = Vec::with_capacity(texels + 1);
        start.push(0);
        HullChunk {
            vertices: Vec::with_capacity(4 * texels),
            start,
            ray: Vec::with_capacity(texels),
            at: Vec::with_capacity(texels),
        }
    }

    /// Appends the hull of one texel (see [`Hull::of`]).
    fn push(&mut self, terms: &[Term], lowest: f64, scratch: &mut HullScratch) {
        let first = self.vertices.len();
        let ray = hull_into(terms, lowest, scratch, &mut self.vertices);
        self.start.push(self.vertices.len() as u32);
        self.ray.push(ray);
        self.at
            .push(argmin_index(&self.vertices[first..], 0.0) as u32);
    }

    fn len(&self) -> usize {
        self.ray.len()
    }

    /// Texel t's vertices and ray.
    fn get(&self, t: usize) -> (&[(f64, f64)], f64) {
        let (a, b) = (self.start[t] as usize, self.start[t + 1] as usize);
        (&self.vertices[a..b], self.ray[t])
    }
}

/// The hulls of every texel of a level (one channel), in chunks of [`HULL_CHUNK`] texels
/// (every chunk full but the last).
struct Hulls {
    chunks: Vec<HullChunk>,
}

impl Hulls {
    fn len(&self) -> usize {
        self.chunks.iter().map(HullChunk::len).sum()
    }

    /// Texel t's vertices (sorted by δ) and the slope past the last one.
    #[inline]
    fn get(&self, t: usize) -> (&[(f64, f64)], f64) {
        self.chunks[t / HULL_CHUNK].get(t % HULL_CHUNK)
    }

    #[cfg(test)]
    fn of(hulls: &[Hull]) -> Hulls {
        let chunks = hulls
            .chunks(HULL_CHUNK)
            .map(|hs| {
                let mut c = HullChunk::with_capacity(hs.len());
                for h in hs {
                    c.vertices.extend_from_slice(&h.vertices);
                    c.start.push(c.vertices.len() as u32);
                    c.ray.push(h.ray);
                    c.at.push(argmin_index(&h.vertices, 0.0) as u32);
                }
                c
            })
            .collect();
        Hulls { chunks }
    }
}

/// Reusable buffers of [`hull_into`].
#[derive(Default)]
struct HullScratch {
    live: Vec<Term>,
    lines: Vec<(f64, f64)>,
}

/// A texel-channel's worst relative error g(δ) = max_k |offset_k + slope_k·δ| / scale_k on
/// [lowest, ∞), by its vertices (δ_i, g_i) sorted by δ: g is convex and piecewise linear, so
/// the minimiser of g(δ) + μδ is one of them for any price μ (the tests' form of a hull;
/// the fit stores them in [`Hulls`]).
#[cfg(test)]
#[derive(Clone, Debug, PartialEq)]
struct Hull {
    vertices: Vec<(f64, f64)>,
    /// The slope of g past the last vertex (its steepest piece, max_k |slope_k| / scale_k).
    ray: f64,
}

#[cfg(test)]
impl Hull {
    /// The hull of the terms (those with a zero or non-finite scale, black there, left out; a
    /// single vertex at 0 when none is left).
    fn of(terms: &[Term], lowest: f64) -> Hull {
        let mut vertices = Vec::new();
        let ray = hull_into(terms, lowest, &mut HullScratch::default(), &mut vertices);
        Hull { vertices, ray }
    }

    /// argmin over δ of g(δ) + μδ.
    fn argmin(&self, mu: f64) -> f64 {
        self.vertices[argmin_index(&self.vertices, mu)].0
    }
}

/// Appends the vertices of the hull of `terms` on [lowest, ∞) to `out` ([`Hull`]) and returns
/// its ray. g is the upper envelope of the 2k lines ±(offset_k + slope_k·δ) (scaled), walked
/// from `lowest` rightwards: from the line on top there (the steeper of equals), the next
/// piece is the line of larger slope that crosses the current one first (the steepest of
/// those crossing at the same point), until none is steeper. At most 2k pieces of 2k
/// candidates each, where taking every crossing of two pieces as a candidate vertex, sorted
/// and then filtered to the corners (before) was O(k³) and a sort per texel.
///
/// The same function as before to round-off (a vertex's δ is its two lines' crossing, its g
/// the value of the line on top there), but only its corners: the old candidate filter kept,
/// by round-off, points on straight pieces (crossings of two lines below the envelope) as
/// vertices in 72% of random hulls, and their near-equal prices, sometimes falling from one
/// vertex to the next, sent a texel back a vertex in the final walk of [`power_kept_steps`]
/// (measured on an 8² level of city, Filament 128²: the constrained objective 0.414221
/// there, 0.414217 now).
fn hull_into(
    terms: &[Term],
    lowest: f64,
    scratch: &mut HullScratch,
    out: &mut Vec<(f64, f64)>,
) -> f64 {
    let live = &mut scratch.live;
    live.clear();
    live.extend(
        terms
            .iter()
            .filter(|t| {
                t.scale > 0.0 && t.scale.is_finite() && t.offset.is_finite() && t.slope.is_finite()
            })
            .map(|t| {
                let inv = 1.0 / t.scale;
                Term::new(t.offset * inv, t.slope * inv, 1.0)
            }),
    );
    let live = &*live;
    if live.is_empty() || live.iter().all(|t| t.slope == 0.0) {
        out.push((0.0f64.max(lowest), 0.0));
        return f64::INFINITY;
    }
    let g = |d: f64| {
        live.iter()
            .map(|t| (t.offset + t.slope * d).abs())
            .fold(0.0, f64::max)
    };
    // The 2k lines m·δ + q: (slope, intercept) = ±(slope_k, offset_k).
    let lines = &mut scratch.lines;
    lines.clear();
    lines.extend(
        live.iter()
            .flat_map(|t| [(t.slope, t.offset), (-t.slope, -t.offset)]),
    );
    let lines = &*lines;
    // On top at `lowest`: the largest value, the steeper of equals.
    let mut cur = 0;
    let mut top = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    for (i, &(m, q)) in lines.iter().enumerate() {
        let v = (q + m * lowest, m);
        if v > top {
            (top, cur) = (v, i);
        }
    }
    let first = out.len();
    let mut x = lowest;
    out.push((x, g(x)));
    loop {
        let (m0, q0) = lines[cur];
        // The steeper line crossing the current one first (the steepest of equals): the
        // crossing of line i is (q0 − q_i) / (m_i − m0), its denominator positive, compared
        // by cross-multiplication (one division a vertex rather than one a candidate).
        let mut next: Option<(f64, f64, usize)> = None;
        for (i, &(m, q)) in lines.iter().enumerate() {
            if m <= m0 {
                continue;
            }
            let (num, den) = (q0 - q, m - m0);
            match next {
                Some((bn, bd, j))
                    if bn * den < num * bd || (bn * den == num * bd && lines[j].0 >= m) => {}
                _ => next = Some((num, den, i)),
            }
        }
        let Some((num, den, i)) = next else {
            break;
        };
        cur = i;
        let xc = num / den;
        if !xc.is_finite() {
            break;
        }
        if xc > x {
            x = xc;
            // Keep the corners only: a point on or above the chord of its neighbours (a
            // round-off corner) is dropped, so prices rise strictly.
            let p = (x, lines[cur].1 + lines[cur].0 * x);
            while out.len() - first >= 2 {
                let (a, b) = (out[out.len() - 2], out[out.len() - 1]);
                let cross = (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0);
                if cross <= 0.0 {
                    out.pop();
                } else {
                    break;
                }
            }
            out.push(p);
        }
    }
    live.iter().map(|t| t.slope.abs()).fold(0.0, f64::max)
}

/// The vertex minimising g(δ) + μδ (the first of equals).
fn argmin_index(vertices: &[(f64, f64)], mu: f64) -> usize {
    let mut best = (0, vertices[0].1 + mu * vertices[0].0);
    for (i, v) in vertices.iter().enumerate().skip(1) {
        let c = v.1 + mu * v.0;
        if c < best.1 {
            best = (i, c);
        }
    }
    best.0
}

fn luma(p: [f64; 3]) -> f64 {
    luminance([p[0] as f32, p[1] as f32, p[2] as f32]) as f64
}

/// One roughness of a texel's fit: the lookup's error there is (offset + slope·δ), relative
/// to `scale` (the exact luminance).
#[derive(Clone, Copy, Debug)]
struct Term {
    offset: f64,
    slope: f64,
    scale: f64,
}

impl Term {
    fn new(offset: f64, slope: f64, scale: f64) -> Self {
        Term {
            offset,
            slope,
            scale,
        }
    }
}

/// argmin over δ ≥ `lowest` of max_k |offset_k + slope_k·δ| / scale_k: one texel's free
/// minimax step (terms with a zero scale, black there, left out; 0 when none is left).
#[cfg(test)]
fn minimax_step(terms: &[Term], lowest: f64) -> f64 {
    Hull::of(terms, lowest).argmin(0.0)
}

/// What `prefilter.json` says of a fitted level: it is no longer the exact kernel at its
/// roughness, and by how much.
#[derive(Clone, Debug, Serialize)]
pub struct LevelFit {
    /// Roughness values the lookup was fitted at besides the level's own (the nodes).
    pub roughness: Vec<f32>,
    /// r of the neighbours: the finer one as stored, the coarser one assumed to move alike.
    pub neighbours: Vec<f32>,
    /// The stored level against the exact kernel at the level's own roughness (luminance,
    /// every texel).
    pub mean_abs_rel_from_exact: f64,
    /// The largest of those per-texel relative deviations.
    pub max_abs_rel_from_exact: f64,
}

impl LevelFit {
    /// The report of level `plan.level`: the stored (`fitted`) level against the `exact` one.
    pub fn new(plan: &Plan, fitted: &Cubemap, exact: &Cubemap) -> Self {
        let s = ErrorStats::between(fitted, exact);
        LevelFit {
            roughness: plan.nodes.iter().map(|n| n.roughness).collect(),
            neighbours: std::iter::once(plan.lo).chain(plan.hi).collect(),
            mean_abs_rel_from_exact: s.mean_abs_rel,
            max_abs_rel_from_exact: s.max_abs_rel,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::{bake_chain, Params};
    use glam::Vec3;
    use ibl_core::envmap::{load_environment, Environment};
    use ibl_core::progress::NoProgress;
    use ibl_target::Target;

    fn constant(v: [f32; 6]) -> Cubemap {
        let mut c = Cubemap::new(1);
        for (f, face) in c.faces.iter_mut().enumerate() {
            face.data.fill(v[f]);
        }
        c
    }

    /// A peaked 1-D toy per texel: P(r) = s·(r² + 0.01)⁻², a different scale s per face.
    fn toy(r: f64, s: f64) -> f64 {
        s * (r * r + 0.01).powi(-2)
    }

    /// Independent of the plan and of the search: the lookup's weights by hand (lod = 4r on
    /// 5 levels, r_j = j/4), its worst relative error over a dense grid of r on the level's
    /// range (level l moved by δ, the coarser level by the same fraction of its value in the
    /// first sweep, held in later ones),
    /// minimised by a dense scan of δ
    /// then refined. The fit with many nodes reaches the same worst error, below the exact
    /// level's where the blend overshoots.
    #[test]
    fn minimax_step_matches_a_brute_force_scan() {
        let scales = [1.0, 0.5, 3.0, 0.01, 7.0, 100.0];
        for (l, coarser) in [1usize, 2, 3, 4]
            .into_iter()
            .flat_map(|l| [(l, Coarser::Follows), (l, Coarser::Fixed)])
        {
            let plan = plan(LodMapping::Linear, l, 5, 64, 32);
            let at = |r: f32| constant(scales.map(|s| toy(r as f64, s) as f32));
            let nodes: Vec<Cubemap> = plan.nodes.iter().map(|q| at(q.roughness)).collect();
            // A finer neighbour that is not its exact value (as after its own fit).
            let lo_stored = |s: f64| 0.9 * toy((l - 1) as f64 / 4.0, s);
            let lo = constant(scales.map(|s| lo_stored(s) as f32));
            let hi = plan.hi.map(at);
            let got = fit_level(
                &plan,
                &at(l as f32 / 4.0),
                &lo,
                hi.as_ref(),
                &nodes,
                coarser,
                Power::Free,
            );
            for (f, &s) in scales.iter().enumerate() {
                let pj = |j: usize| toy(j as f64 / 4.0, s);
                // Level 1 is fitted over [r_1, r_2] only (not next to the mirror).
                let a = if l == 1 { 0.25 } else { (l - 1) as f64 / 4.0 };
                let b = ((l + 1).min(4)) as f64 / 4.0;
                let worst = |delta: f64| {
                    let steps = 4000;
                    (0..=steps)
                        .map(|k| {
                            let r = a + (b - a) * k as f64 / steps as f64;
                            let lod = 4.0 * r;
                            let w = |j: usize| (1.0 - (lod - j as f64).abs()).max(0.0);
                            let mut v = w(l - 1) * lo_stored(s) + w(l) * (pj(l) + delta);
                            if l < 4 {
                                let follows = match coarser {
                                    Coarser::Follows => 1.0 + delta / pj(l),
                                    Coarser::Fixed => 1.0,
                                };
                                v += w(l + 1) * pj(l + 1) * follows;
                            }
                            ((v - toy(r, s)) / toy(r, s)).abs()
                        })
                        .fold(0.0, f64::max)
                };
                let p0 = pj(l);
                let grid = (0..=2000).map(|k| -p0 + 3.0 * p0 * k as f64 / 2000.0);
                let mut best = grid.fold((f64::MAX, 0.0), |acc, d| {
                    let e = worst(d);
                    if e < acc.0 {
                        (e, d)
                    } else {
                        acc
                    }
                });
                let step = 3.0 * p0 / 2000.0;
                for k in -100..=100 {
                    let d = best.1 + step * k as f64 / 100.0;
                    let e = worst(d);
                    if e < best.0 {
                        best = (e, d);
                    }
                }
                let fitted = got.faces[f].data[0] as f64;
                let reached = worst(fitted - p0);
                assert!(
                    (reached - best.0).abs() < 2e-3 * best.0 + 1e-6,
                    "level {l} face {f}: fit {fitted} reaches {reached}, brute force {} at {}",
                    best.0,
                    p0 + best.1
                );
                assert!(
                    reached <= worst(0.0) * (1.0 + 1e-3) + 1e-9,
                    "level {l}: {reached} vs exact {}",
                    worst(0.0)
                );
            }
        }
    }

    /// The hull against its definition, independently of how it is built: on random terms
    /// (some with zero slopes, equal slopes, zero or non-finite scales), the piecewise-linear
    /// function of its vertices and ray equals g(δ) = max_k |offset_k + slope_k·δ| / scale_k on
    /// a dense grid of [lowest, ∞), its slopes rise strictly (every vertex a corner), and the
    /// first vertex is the bound.
    #[test]
    fn hull_is_the_upper_envelope_with_strict_corners() {
        use ibl_core::sampling::Pcg32;
        let mut rng = Pcg32::new(31, 2);
        for case in 0..20000 {
            let k = 1 + case % 7;
            let terms: Vec<Term> = (0..k)
                .map(|i| {
                    let u = |rng: &mut Pcg32| rng.next_f64() * 2.0 - 1.0;
                    let slope = match (case / 7 + i) % 5 {
                        0 => 0.0,
                        1 => 0.5,
                        _ => u(&mut rng),
                    };
                    let scale = match (case / 3 + i) % 11 {
                        0 => 0.0,
                        1 => f64::INFINITY,
                        _ => 0.1 + rng.next_f64(),
                    };
                    Term::new(u(&mut rng) * 3.0, slope, scale)
                })
                .collect();
            let lowest = -4.0 * rng.next_f64();
            let h = Hull::of(&terms, lowest);
            let live: Vec<&Term> = terms
                .iter()
                .filter(|t| t.scale > 0.0 && t.scale.is_finite())
                .collect();
            if live.iter().all(|t| t.slope == 0.0) {
                assert_eq!(h.vertices, vec![(0.0f64.max(lowest), 0.0)], "case {case}");
                continue;
            }
            let g = |d: f64| {
                live.iter()
                    .map(|t| (t.offset + t.slope * d).abs() / t.scale)
                    .fold(0.0, f64::max)
            };
            let v = &h.vertices;
            assert_eq!(v[0].0, lowest, "case {case}");
            let slopes: Vec<f64> = v
                .windows(2)
                .map(|w| (w[1].1 - w[0].1) / (w[1].0 - w[0].0))
                .chain([h.ray])
                .collect();
            assert!(
                slopes.windows(2).all(|s| s[1] > s[0]),
                "case {case}: slopes {slopes:?} of {v:?}"
            );
            let piecewise = |d: f64| match v.iter().position(|p| p.0 > d) {
                None => v[v.len() - 1].1 + h.ray * (d - v[v.len() - 1].0),
                Some(0) => unreachable!("below the bound"),
                Some(i) => {
                    let (a, b) = (v[i - 1], v[i]);
                    a.1 + (b.1 - a.1) * (d - a.0) / (b.0 - a.0)
                }
            };
            let far = v[v.len() - 1].0 + 10.0;
            for s in 0..=400 {
                let d = lowest + (far - lowest) * s as f64 / 400.0;
                let (got, want) = (piecewise(d), g(d));
                assert!(
                    (got - want).abs() <= 1e-9 * (1.0 + want),
                    "case {case}: at {d} hull {got} vs g {want}; {v:?}"
                );
            }
        }
    }

    /// The direct taps of a neighbour twice or half the size give what the sampler reads at
    /// the texel centres (to f32 round-off), edges and corners included; other sizes are read
    /// through the sampler.
    #[test]
    fn read_at_texels_matches_the_sampler() {
        use ibl_core::sampling::Pcg32;
        let mut rng = Pcg32::new(3, 11);
        for (m, n) in [
            (2, 1),
            (4, 2),
            (16, 8),
            (1, 2),
            (2, 4),
            (8, 16),
            (32, 64),
            (4, 4),
            (1, 1),
        ] {
            let mut level = Cubemap::new(m);
            for face in &mut level.faces {
                for v in &mut face.data {
                    *v = 10f32.powf(4.0 * rng.next_f32() - 2.0);
                }
            }
            let got = read_at_texels(&level, n);
            let want = Cubemap::from_fn(n, |d| level.sample_bilinear(d));
            assert_eq!(got.size, n);
            // The sampler's weights carry the f32 round-off of face coordinates of size ~n
            // (n·2⁻²⁴ a weight): what separates the two reads, ~10⁻⁵ of the level's largest
            // value at 64²; a wrong tap or weight is off by a sizeable fraction of it.
            let top = level
                .faces
                .iter()
                .flat_map(|f| &f.data)
                .fold(0.0f32, |a, &b| a.max(b));
            for (g, w) in got.faces.iter().zip(&want.faces) {
                for (a, b) in g.data.iter().zip(&w.data) {
                    let tol = 1e-7 * n.max(m) as f32 * top + 1e-6 * b.abs();
                    assert!((a - b).abs() <= tol, "{m} → {n}: {a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn a_finer_level_read_at_coarse_texel_centres_is_the_mean_of_its_four_texels() {
        // A coarse texel's centre is the shared corner of the 2×2 finer texels under it: the
        // engine's bilinear tap there weighs them equally.
        let fine = Cubemap::from_fn(8, |d| [d.x + 2.0, d.y * d.y, (3.0 * d.z).sin() + 1.5]);
        let coarse = read_at_texels(&fine, 4);
        for face in ibl_core::cube::Face::ALL {
            for j in 0..4 {
                for i in 0..4 {
                    let got = coarse.texel(face, i, j);
                    for c in 0..3 {
                        let want = [(0, 0), (1, 0), (0, 1), (1, 1)]
                            .iter()
                            .map(|(a, b)| fine.texel(face, 2 * i + a, 2 * j + b)[c])
                            .sum::<f32>()
                            / 4.0;
                        assert!((got[c] - want).abs() < 1e-5, "{face:?} {i} {j}: {got:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn minimax_step_is_no_worse_than_a_dense_scan_on_random_terms() {
        use ibl_core::sampling::Pcg32;
        let mut rng = Pcg32::new(17, 4);
        for case in 0..500 {
            let k = 1 + case % 6;
            let terms: Vec<Term> = (0..k)
                .map(|_| {
                    let u = |rng: &mut Pcg32| rng.next_f64() * 2.0 - 1.0;
                    Term::new(u(&mut rng) * 3.0, u(&mut rng), 0.1 + rng.next_f64())
                })
                .collect();
            let lowest = -2.0 * rng.next_f64();
            let worst = |d: f64| {
                terms
                    .iter()
                    .map(|t| (t.offset + t.slope * d).abs() / t.scale)
                    .fold(0.0, f64::max)
            };
            let got = minimax_step(&terms, lowest);
            assert!(got >= lowest);
            let scan = (0..=200_000)
                .map(|i| lowest + 100.0 * i as f64 / 200_000.0)
                .map(worst)
                .fold(f64::MAX, f64::min);
            assert!(
                worst(got) <= scan + 1e-12,
                "case {case}: {} vs scan {scan}",
                worst(got)
            );
        }
    }

    /// Power kept: the steps change Σ Ω δ by nothing, and are the constrained optimum of
    /// Σ Ω g: no transfer of power between two texels lowers it (a separable convex problem
    /// with one linear constraint: pairwise optimality is global). Random texels with bright,
    /// dim and black ones, the change either way.
    #[test]
    fn power_kept_steps_keep_power_at_the_constrained_optimum() {
        use ibl_core::sampling::Pcg32;
        let mut rng = Pcg32::new(23, 8);
        for case in 0..40 {
            let count = 5 + case % 30;
            let mut lowest = Vec::new();
            let mut terms_of = Vec::new();
            let hulls: Vec<Hull> = (0..count)
                .map(|_| {
                    let y = 10f64.powf(4.0 * rng.next_f64() - 2.0);
                    let pl = y * (0.5 + rng.next_f64());
                    let terms: Vec<Term> = std::iter::once(Term::new(0.0, 1.0, y))
                        .chain((0..4).map(|_| {
                            let off = (rng.next_f64() - 0.5 + 0.3 * (case % 3) as f64) * pl;
                            Term::new(off, 0.2 + 0.8 * rng.next_f64(), y * (0.5 + rng.next_f64()))
                        }))
                        .collect();
                    lowest.push(-pl);
                    let h = Hull::of(&terms, -pl);
                    terms_of.push(terms);
                    h
                })
                .collect();
            let omega = |t: usize| 0.5 + (t % 7) as f64 * 0.1;
            let steps = power_kept_steps(&Hulls::of(&hulls), omega);
            let free: Vec<f64> = hulls.iter().map(|h| h.argmin(0.0)).collect();
            let power: f64 = steps.iter().enumerate().map(|(t, d)| omega(t) * d).sum();
            let scale: f64 = free
                .iter()
                .enumerate()
                .map(|(t, d)| omega(t) * d.abs())
                .sum();
            assert!(
                power.abs() <= 1e-9 * scale.max(1e-300),
                "case {case}: {power} of {scale}"
            );
            let g = |t: usize, d: f64| {
                terms_of[t]
                    .iter()
                    .map(|x| (x.offset + x.slope * d).abs() / x.scale)
                    .fold(0.0, f64::max)
            };
            let total = |d: &[f64]| -> f64 { (0..count).map(|t| omega(t) * g(t, d[t])).sum() };
            let best = total(&steps);
            for a in 0..count {
                for b in 0..count {
                    if a == b {
                        continue;
                    }
                    for eps in [1e-3, 1e-2] {
                        let e = eps * (steps[a].abs() + steps[b].abs() + 1e-3);
                        let mut d = steps.clone();
                        d[a] += e / omega(a);
                        d[b] -= e / omega(b);
                        if d[b] < lowest[b] {
                            continue;
                        }
                        let moved = total(&d);
                        assert!(
                            moved >= best - 1e-9 * best.abs().max(1e-12),
                            "case {case}: moving power {a} → {b} lowers {best} to {moved}"
                        );
                    }
                }
            }
        }
    }

    /// The radix select and the median splits inside the crossing range take the same steps
    /// as the plain definition: every step sorted by (price, texel, vertex) and walked until
    /// the change crosses 0. Thousands of texels with prices over several binades, and copies
    /// of one hull (equal prices: one range holding more steps than are walked directly).
    #[test]
    fn power_kept_steps_match_a_walk_of_every_step_sorted() {
        use ibl_core::sampling::Pcg32;
        fn by_sorting(hulls: &[Hull], omega: impl Fn(usize) -> f64) -> Vec<f64> {
            let at: Vec<usize> = hulls
                .iter()
                .map(|h| argmin_index(&h.vertices, 0.0))
                .collect();
            let mut steps: Vec<f64> = hulls
                .iter()
                .zip(&at)
                .map(|(h, &i)| h.vertices[i].0)
                .collect();
            let mut left_over: f64 = steps.iter().enumerate().map(|(t, d)| omega(t) * d).sum();
            let left = left_over > 0.0;
            let mut events = Vec::new();
            for (t, (h, &i)) in hulls.iter().zip(&at).enumerate() {
                let v = &h.vertices;
                let slope = |j: usize| (v[j].1 - v[j - 1].1) / (v[j].0 - v[j - 1].0);
                if left {
                    events.extend((1..=i).map(|j| (-slope(j), t, j - 1)));
                } else {
                    events.extend((i + 1..v.len()).map(|j| (slope(j), t, j)));
                    events.push((h.ray, t, v.len()));
                }
            }
            events.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
            for (_, t, j) in events {
                let Some(&(to, _)) = hulls[t].vertices.get(j) else {
                    steps[t] -= left_over / omega(t);
                    break;
                };
                let moved = omega(t) * (to - steps[t]);
                if (left_over + moved) * left_over <= 0.0 {
                    steps[t] += (to - steps[t]) * (-left_over / moved);
                    break;
                }
                left_over += moved;
                steps[t] = to;
            }
            steps
        }
        let mut rng = Pcg32::new(41, 6);
        for case in 0..12 {
            let count = [3000, 20000][case % 2];
            // From case 6 most texels copy the first, from case 9 all do.
            let (copies, share) = (case >= 6, if case >= 9 { 1.0 } else { 0.7 });
            let mut hulls = Vec::new();
            let mut template = None;
            for _ in 0..count {
                if let Some(h) = template.as_ref().filter(|_| copies) {
                    if rng.next_f64() < share {
                        hulls.push(Hull::clone(h));
                        continue;
                    }
                }
                let y = 10f64.powf(4.0 * rng.next_f64() - 2.0);
                let pl = y * (0.5 + rng.next_f64());
                let terms: Vec<Term> = std::iter::once(Term::new(0.0, 1.0, y))
                    .chain((0..4).map(|_| {
                        let off = (rng.next_f64() - 0.5 + 0.4 * (case % 3) as f64 - 0.4) * pl;
                        Term::new(off, 0.2 + 0.8 * rng.next_f64(), y * (0.5 + rng.next_f64()))
                    }))
                    .collect();
                let h = Hull::of(&terms, -pl);
                template.get_or_insert_with(|| h.clone());
                hulls.push(h);
            }
            let omega = |t: usize| 0.5 + (t % 7) as f64 * 0.1;
            let got = power_kept_steps(&Hulls::of(&hulls), omega);
            let want = by_sorting(&hulls, omega);
            let mut partial = 0;
            for (t, (a, b)) in got.iter().zip(&want).enumerate() {
                if a != b {
                    // The step taken in part: the change before it summed in another order.
                    partial += 1;
                    assert!(
                        (a - b).abs() <= 1e-9 * (a.abs() + b.abs()),
                        "case {case} texel {t}: {a} vs {b}"
                    );
                }
            }
            assert!(partial <= 1, "case {case}: {partial} texels differ");
            let power: f64 = got.iter().enumerate().map(|(t, d)| omega(t) * d).sum();
            let scale: f64 = got
                .iter()
                .enumerate()
                .map(|(t, d)| omega(t) * d.abs())
                .sum();
            assert!(
                power.abs() <= 1e-9 * scale,
                "case {case}: {power} of {scale}"
            );
        }
    }

    #[test]
    fn minimax_step_handles_black_and_degenerate_terms() {
        // Black everywhere: no step. One term: its root.
        let t = |o, s, y| Term::new(o, s, y);
        assert_eq!(
            minimax_step(&[t(0.0, 1.0, 0.0), t(1.0, 0.5, 0.0)], -1.0),
            0.0
        );
        assert!((minimax_step(&[t(-2.0, 0.5, 1.0)], -10.0) - 4.0).abs() < 1e-9);
        // Two terms pulling apart: the step balances them, |d| / 1 = |2 + d| / 2 → d = −2/3.
        let d = minimax_step(&[t(0.0, 1.0, 1.0), t(2.0, 1.0, 2.0)], -10.0);
        assert!((d + 2.0 / 3.0).abs() < 1e-9, "{d}");
        // Never below the floor that keeps the level non-negative.
        assert!(minimax_step(&[t(5.0, 1.0, 1.0)], -1.0) >= -1.0);
    }

    fn worst_runtime(chain: &crate::bake::Chain, a: f32, b: f32) -> f64 {
        let rt = chain.report.runtime.as_ref().unwrap();
        rt.roughness
            .iter()
            .zip(&rt.mean_abs_rel)
            .filter(|(r, _)| **r >= a && **r <= b)
            .map(|(_, e)| *e)
            .fold(0.0, f64::max)
    }

    #[test]
    fn fitted_chain_has_a_lower_runtime_error_on_a_fixture() {
        let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/hdri/studio_256.exr");
        let env = load_environment(&path, false).unwrap().env;
        let base = Params {
            size: 64,
            levels: Some(5),
            ..Default::default()
        };
        let bake = |fit| {
            let p = Params {
                fit_lookup: Some(fit),
                ..base.clone()
            };
            bake_chain(&p, &env, &NoProgress).unwrap()
        };
        let (exact, fitted) = (bake(false), bake(true));
        let (e, f) = (
            worst_runtime(&exact, 0.25, 1.0),
            worst_runtime(&fitted, 0.25, 1.0),
        );
        eprintln!("studio 64² × 5, worst over r ∈ [0.25, 1]: exact {e:.4}, fitted {f:.4}");
        assert!(f < 0.8 * e, "fitted {f} vs exact {e}");
        // The report says the fitted levels moved, the mirror and the last level did not.
        assert!(fitted.report.fit_lookup && !exact.report.fit_lookup);
        let lv = &fitted.report.level;
        assert!(lv[0].fit.is_none() && lv[4].fit.is_none());
        for lv in &lv[1..4] {
            let fit = lv.fit.as_ref().unwrap();
            assert!(fit.mean_abs_rel_from_exact > 0.0, "level {}", lv.level);
            let sides = if lv.level == 1 { 1 } else { 2 };
            assert_eq!(fit.roughness.len(), sides * FIT_NODES);
        }
        for (l, (a, b)) in fitted
            .mips
            .levels
            .iter()
            .zip(&exact.mips.levels)
            .enumerate()
        {
            assert_eq!(a == b, l == 0, "level {l}");
        }
        assert!(exact
            .report
            .level
            .iter()
            .all(|l| l.fit.is_none() && l.read_fit.is_none()));
        // The 8² and 4² levels are fitted to their bilinear read (crate::spatial): the last
        // level keeps the exact level's power, and the lookup at r = 1, which reads it alone,
        // is closer to the kernel.
        for l in 0..5 {
            let rf = &fitted.report.level[l].read_fit;
            assert_eq!(rf.is_some(), l >= 3, "level {l}");
            if let Some(rf) = rf {
                assert!(
                    rf.mean_abs_rel_after < 0.6 * rf.mean_abs_rel_before,
                    "{rf:?}"
                );
            }
        }
        // The power kept on a level this small is its read's (crate::spatial::keep_read_power).
        let w = crate::spatial::read_weights(4);
        let power = |c: &Cubemap| -> [f64; 3] {
            let mut p = [0.0f64; 3];
            for (f, face) in c.faces.iter().enumerate() {
                for (i, t) in face.data.chunks_exact(3).enumerate() {
                    for ch in 0..3 {
                        p[ch] += w[f * 16 + i] * t[ch] as f64;
                    }
                }
            }
            p
        };
        let (pf, pe) = (power(&fitted.mips.levels[4]), power(&exact.mips.levels[4]));
        for c in 0..3 {
            assert!((pf[c] / pe[c] - 1.0).abs() < 1e-5, "{pf:?} vs {pe:?}");
        }
        let at_one = |c: &crate::bake::Chain| {
            *c.report
                .runtime
                .as_ref()
                .unwrap()
                .mean_abs_rel
                .last()
                .unwrap()
        };
        eprintln!(
            "r = 1: exact {:.4}, fitted {:.4}",
            at_one(&exact),
            at_one(&fitted)
        );
        assert!(at_one(&fitted) < 0.6 * at_one(&exact));
    }

    #[test]
    fn a_bright_sun_and_a_black_environment_stay_finite_and_non_negative() {
        let sun = Cubemap::from_fn(32, |d| {
            let d = d.normalize();
            if d.dot(Vec3::new(0.3, 0.8, 0.52).normalize()) > 0.999 {
                [1e5, 9e4, 7e4]
            } else {
                [0.01, 0.02, 0.03]
            }
        });
        for (name, cube) in [("sun", sun), ("black", Cubemap::new(32))] {
            let p = Params {
                size: 16,
                fit_lookup: Some(true),
                ..Default::default()
            };
            let chain = bake_chain(&p, &Environment::Cube(cube), &NoProgress).unwrap();
            for (l, level) in chain.mips.levels.iter().enumerate() {
                for face in &level.faces {
                    assert!(
                        face.data.iter().all(|v| v.is_finite() && *v >= 0.0),
                        "{name} level {l}"
                    );
                }
            }
            if name == "black" {
                assert!(chain
                    .mips
                    .levels
                    .iter()
                    .all(|c| c.faces.iter().all(|f| f.data.iter().all(|v| *v == 0.0))));
            }
        }
    }

    #[test]
    fn fitted_chain_is_identical_for_any_thread_count() {
        let env = Environment::Cube(Cubemap::from_fn(32, |d| {
            let d = d.normalize();
            let spot = (d.dot(Vec3::new(-0.5, 0.6, 0.62).normalize()) - 0.95).max(0.0) * 500.0;
            [0.3 + d.y.max(0.0) + spot, 0.2 + spot, 0.4 + 0.5 * spot]
        }));
        let p = Params {
            size: 32,
            levels: Some(5),
            target: Target::Filament,
            fit_lookup: Some(true),
            ..Default::default()
        };
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| bake_chain(&p, &env, &NoProgress).unwrap().mips)
        };
        let one = run(1);
        assert!(one == run(2) && one == run(3));
    }
}
