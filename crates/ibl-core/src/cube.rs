//! Cube faces and directions (docs/CONVENTIONS.md table), exact texel solid angles, cubemaps with mip
//! levels, seamless bilinear sampling across faces and solid-angle-weighted downsampling.

use crate::error::{Error, Result};
use crate::image::Image;
use crate::Rgb;
use glam::Vec3;

/// Cube faces in file and KTX2 order: +X −X +Y −Y +Z −Z.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Face {
    /// +X.
    Px = 0,
    /// −X.
    Nx = 1,
    /// +Y (up).
    Py = 2,
    /// −Y.
    Ny = 3,
    /// +Z.
    Pz = 4,
    /// −Z.
    Nz = 5,
}

impl Face {
    /// The six faces in file and KTX2 order (the `Face as usize` index).
    pub const ALL: [Face; 6] = [Face::Px, Face::Nx, Face::Py, Face::Ny, Face::Pz, Face::Nz];

    /// File-name stem (`px` … `nz`).
    pub fn name(self) -> &'static str {
        ["px", "nx", "py", "ny", "pz", "nz"][self as usize]
    }

    /// The face at index `i` of [`Face::ALL`] (panics above 5).
    pub fn from_index(i: usize) -> Face {
        Face::ALL[i]
    }

    /// Unnormalised direction of face coordinates (sc, tc) ∈ [−1, 1]² (docs/CONVENTIONS.md table).
    #[inline]
    pub fn direction(self, sc: f32, tc: f32) -> Vec3 {
        match self {
            Face::Px => Vec3::new(1.0, -tc, -sc),
            Face::Nx => Vec3::new(-1.0, -tc, sc),
            Face::Py => Vec3::new(sc, 1.0, tc),
            Face::Ny => Vec3::new(sc, -1.0, -tc),
            Face::Pz => Vec3::new(sc, -tc, 1.0),
            Face::Nz => Vec3::new(-sc, -tc, -1.0),
        }
    }

    /// Face and (sc, tc) of a direction: the inverse of [`Face::direction`] on the major axis.
    /// A zero vector maps to the centre of +X.
    #[inline]
    pub fn from_direction(d: Vec3) -> (Face, f32, f32) {
        let a = d.abs();
        if a.x >= a.y && a.x >= a.z {
            if a.x == 0.0 {
                return (Face::Px, 0.0, 0.0);
            }
            let inv = 1.0 / a.x;
            if d.x > 0.0 {
                (Face::Px, -d.z * inv, -d.y * inv)
            } else {
                (Face::Nx, d.z * inv, -d.y * inv)
            }
        } else if a.y >= a.z {
            let inv = 1.0 / a.y;
            if d.y > 0.0 {
                (Face::Py, d.x * inv, d.z * inv)
            } else {
                (Face::Ny, d.x * inv, -d.z * inv)
            }
        } else {
            let inv = 1.0 / a.z;
            if d.z > 0.0 {
                (Face::Pz, d.x * inv, -d.y * inv)
            } else {
                (Face::Nz, -d.x * inv, -d.y * inv)
            }
        }
    }
}

/// The texel of an n×n cube that integer coordinates (i, j) of `face`, possibly one texel
/// outside it across one edge, read: the texel itself, or the neighbouring face's texel that
/// the tap's direction lands on (the re-projection that makes bilinear reads seamless).
#[inline]
fn wrapped_index(n: usize, face: Face, i: isize, j: isize) -> (Face, usize, usize) {
    let m = n as isize;
    if i >= 0 && j >= 0 && i < m && j < m {
        return (face, i as usize, j as usize);
    }
    let sc = (2.0 * (i as f32 + 0.5)) / n as f32 - 1.0;
    let tc = (2.0 * (j as f32 + 0.5)) / n as f32 - 1.0;
    // The tap's direction lies past the edge, so its major axis names the neighbour.
    let d = face.direction(sc, tc);
    let (f2, s2, t2) = Face::from_direction(d);
    let (i2, j2) = face_texel_index(s2, t2, n);
    (f2, i2, j2)
}

/// The texels whose mean a seamless read takes at integer coordinates (i, j) of `face`, at most
/// one texel outside it: one texel ([`wrapped_index`]), or, past two edges at once (the
/// cube-corner texel, which no face holds), the three texels meeting at that cube corner — the
/// face's own corner texel and the two neighbours' across each edge. Returns them and their
/// count (1 or 3).
///
/// The rule is the GPU's: OpenGL 4.6 core §8.13.1 "Seamless Cube Map Filtering" (4.2: §3.10.10):
/// "If a texture sample location would lie in the texture border in both u and v (in one of the
/// corners of the cube), there is no unique neighboring face from which to extract one texel.
/// The recommended method to generate this texel is to average the values of the three
/// available samples"; SwiftShader does (measured in conformance/render/shader-check.sh, the
/// GPU agreeing to f32 rounding), and so does Mesa's llvmpipe (mesa/mesa,
/// src/gallium/auxiliary/gallivm/lp_bld_sample_soa.c: "New corner texel color is all colors
/// added / 3"). Vulkan's "Cube Map Edge Handling" (textures chapter, #textures-cubemapedge)
/// leaves the corner texel's value to the implementation; D3D10+ hardware and Metal share the
/// same sampler units. Re-projecting a single texel there instead (this crate before) was off
/// by up to 2.4% in reads of 4×4–8×8 levels and 7.9% mean in the anisotropic FIS's corner taps
/// (docs/notes/corner.md).
#[inline]
fn ghost_indices(n: usize, face: Face, i: isize, j: isize) -> ([(Face, usize, usize); 3], usize) {
    let m = n as isize;
    let out = |x: isize| x < 0 || x >= m;
    let one = wrapped_index(n, face, i, j);
    if !(out(i) && out(j)) {
        return ([one; 3], 1);
    }
    let (ci, cj) = (i.clamp(0, m - 1), j.clamp(0, m - 1));
    (
        [
            (face, ci as usize, cj as usize),
            wrapped_index(n, face, i, cj),
            wrapped_index(n, face, ci, j),
        ],
        3,
    )
}

/// The texels a seamless bilinear read of an n×n cube in direction `d` blends, with their
/// weights, as (face·n² + j·n + i, weight): [`Cubemap::sample_bilinear`] is their weighted sum
/// (to round-off). Four taps, one of which may be the cube-corner texel, the mean of three
/// texels ([`ghost_indices`]) and so three entries of a third of its weight; unused entries
/// have weight 0 (and index 0). The read is linear in the texels; this is its row, for
/// fitting texels to what a read of them should give.
pub fn bilinear_taps(n: usize, d: Vec3) -> [(usize, f32); 6] {
    let (face, sc, tc) = Face::from_direction(d);
    bilinear_taps_at(n, face, sc, tc)
}

/// [`bilinear_taps`] of the point (sc, tc) ∈ [−1, 1]² of face `face` given by its face
/// coordinates: for callers that walk a face's own grid, with no direction to re-project.
pub fn bilinear_taps_at(n: usize, face: Face, sc: f32, tc: f32) -> [(usize, f32); 6] {
    let ((x0, fx), (y0, fy)) = (bilinear_cell(n, sc), bilinear_cell(n, tc));
    let weights = bilinear_weights(fx, fy);
    let mut taps = [(0usize, 0.0f32); 6];
    // All four taps on the face (all but a band one texel wide at its edges): their indices
    // directly, the same entries the seam rules below give them (a third of the cost of a read
    // weights' integration went to those rules).
    let m = n as isize;
    if x0 >= 0 && y0 >= 0 && x0 + 1 < m && y0 + 1 < m {
        let p = face as usize * n * n + y0 as usize * n + x0 as usize;
        taps[..4].copy_from_slice(&[
            (p, weights[0]),
            (p + 1, weights[1]),
            (p + n, weights[2]),
            (p + n + 1, weights[3]),
        ]);
        return taps;
    }
    let mut k = 0;
    for ((texels, count), w) in bilinear_cell_taps(n, face, x0, y0).into_iter().zip(weights) {
        for &p in &texels[..count] {
            // A 2×2 footprint holds at most one cube-corner texel (4 + 2 entries).
            taps[k] = (p, w / count as f32);
            k += 1;
        }
    }
    taps
}

/// The bilinear cell of face coordinate `c` ∈ [−1, 1] along an n-texel edge: its first texel
/// (−1 before the first texel centre, n − 1 past the last: the seam band) and the fraction of
/// the way to the next centre. Per axis, so that callers walking a grid compute it once a row
/// or column ([`bilinear_taps_at`] is these on both axes).
#[inline]
pub fn bilinear_cell(n: usize, c: f32) -> (isize, f32) {
    let x = (c + 1.0) * 0.5 * n as f32 - 0.5;
    let x0 = floor(x);
    (x0 as isize, x - x0)
}

/// The weights of a bilinear cell's four taps at fractions (fx, fy), in the order of
/// [`bilinear_cell_taps`]: (x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1).
#[inline]
pub fn bilinear_weights(fx: f32, fy: f32) -> [f32; 4] {
    [
        (1.0 - fx) * (1.0 - fy),
        fx * (1.0 - fy),
        (1.0 - fx) * fy,
        fx * fy,
    ]
}

/// The texels of the four taps of the bilinear cell whose first texel is (x0, y0) of face
/// `face` (−1 ≤ x0, y0 ≤ n − 1), in the order of [`bilinear_taps_at`]'s weights: each as up to
/// three indices face·n² + j·n + i and their count (a tap past an edge re-projected from the
/// neighbour face, a cube-corner tap the three texels meeting there, [`ghost_indices`]). What
/// [`bilinear_taps_at`] blends, for callers that read many points of one cell.
pub fn bilinear_cell_taps(n: usize, face: Face, x0: isize, y0: isize) -> [([usize; 3], usize); 4] {
    let mut out = [([0usize; 3], 0usize); 4];
    for (k, (i, j)) in [(x0, y0), (x0 + 1, y0), (x0, y0 + 1), (x0 + 1, y0 + 1)]
        .into_iter()
        .enumerate()
    {
        let (texels, count) = ghost_indices(n, face, i, j);
        for (e, &(f, i, j)) in texels[..count].iter().enumerate() {
            out[k].0[e] = f as usize * n * n + j * n + i;
        }
        out[k].1 = count;
    }
    out
}

/// Face coordinate of the centre of texel `i` on an `n`-texel edge: 2(i+0.5)/n − 1.
#[inline]
pub(crate) fn texel_coord(i: usize, n: usize) -> f32 {
    (2.0 * (i as f32 + 0.5)) / n as f32 - 1.0
}

/// Unit direction through the centre of texel (i, j) of face `face` of an n×n cube.
#[inline]
pub fn texel_direction(face: Face, i: usize, j: usize, n: usize) -> Vec3 {
    face.direction(texel_coord(i, n), texel_coord(j, n))
        .normalize()
}

/// Solid angle subtended by the face rectangle [0, x]×[0, y] on the unit-distance plane:
/// atan2(xy, sqrt(x²+y²+1)). Differences of it give exact texel solid angles.
#[inline]
fn area_element(x: f64, y: f64) -> f64 {
    (x * y).atan2((x * x + y * y + 1.0).sqrt())
}

/// Face coordinate of corner k of an n×n face's texel grid: k·(2/n) − 1.
#[inline]
fn corner(k: usize, n: usize) -> f64 {
    k as f64 * (2.0 / n as f64) - 1.0
}

/// Exact solid angle of texel (i, j) of an n×n face (the same on every face).
pub fn texel_solid_angle(i: usize, j: usize, n: usize) -> f64 {
    let (x0, y0) = (corner(i, n), corner(j, n));
    let (x1, y1) = (corner(i + 1, n), corner(j + 1, n));
    area_element(x0, y0) - area_element(x0, y1) - area_element(x1, y0) + area_element(x1, y1)
}

/// Solid angles of every texel of an n×n face, row-major (one table serves all six faces).
/// Equal to [`texel_solid_angle`] texel by texel; the area element is evaluated once per grid
/// corner ((n+1)² atan2 rather than 4n²), rows in parallel.
pub fn solid_angle_table(n: usize) -> Vec<f32> {
    use rayon::prelude::*;
    let corners: Vec<f64> = (0..=n)
        .into_par_iter()
        .flat_map_iter(|j| {
            let y = corner(j, n);
            (0..=n).map(move |i| area_element(corner(i, n), y))
        })
        .collect();
    let w = n + 1;
    let mut t = vec![0.0f32; n * n];
    t.par_chunks_mut(n.max(1)).enumerate().for_each(|(j, row)| {
        for (i, v) in row.iter_mut().enumerate() {
            let a = |ii: usize, jj: usize| corners[jj * w + ii];
            *v = (a(i, j) - a(i, j + 1) - a(i + 1, j) + a(i + 1, j + 1)) as f32;
        }
    });
    t
}

/// Edge lengths of a mip chain from `size` down to `min_size` (both included when reachable):
/// size, size/2, … (rounded down, never below 1). The one function for mip sizes.
pub fn mip_sizes(size: usize, min_size: usize) -> Vec<usize> {
    let mut sizes = vec![size.max(1)];
    let mut s = size.max(1);
    while s > min_size.max(1) && s > 1 {
        s = (s / 2).max(1);
        sizes.push(s);
    }
    sizes
}

/// A cubemap of RGB float faces, each `size`×`size`, in [`Face::ALL`] order.
#[derive(Clone, Debug, PartialEq)]
pub struct Cubemap {
    /// Edge length of each face in texels.
    pub size: usize,
    /// The faces, in [`Face::ALL`] order (RGB, row 0 at the top as in docs/CONVENTIONS.md).
    pub faces: [Image; 6],
}

impl Cubemap {
    /// A black cube with faces of `size`×`size` texels.
    pub fn new(size: usize) -> Self {
        Cubemap {
            size,
            faces: std::array::from_fn(|_| Image::new(size, size, 3)),
        }
    }

    /// Builds a cube from six square images of equal size (converted to RGB).
    pub fn from_faces(faces: [Image; 6]) -> Result<Self> {
        let size = faces[0].width;
        for (f, img) in faces.iter().enumerate() {
            if img.width != size || img.height != size || size == 0 {
                return Err(Error::param(format!(
                    "cube face {} is {}x{}, expected {size}x{size}",
                    Face::from_index(f).name(),
                    img.width,
                    img.height
                )));
            }
        }
        Ok(Cubemap {
            size,
            faces: faces.map(|f| f.to_channels(3)),
        })
    }

    /// A cube whose every texel is `c`.
    pub fn constant(size: usize, c: Rgb) -> Self {
        let mut cube = Cubemap::new(size);
        for face in &mut cube.faces {
            for t in face.data.chunks_exact_mut(3) {
                t.copy_from_slice(&c);
            }
        }
        cube
    }

    /// A cube whose texel (face, i, j) is `f` of its centre direction (analytic test
    /// environments, synthetic skies).
    pub fn from_fn(size: usize, f: impl Fn(Vec3) -> Rgb) -> Self {
        let mut cube = Cubemap::new(size);
        for face in Face::ALL {
            for j in 0..size {
                for i in 0..size {
                    cube.faces[face as usize]
                        .texel_mut(i, j)
                        .copy_from_slice(&f(texel_direction(face, i, j, size)));
                }
            }
        }
        cube
    }

    /// RGB of texel column `i`, row `j` of `face` (no bounds clamping).
    #[inline]
    pub fn texel(&self, face: Face, i: usize, j: usize) -> Rgb {
        let o = (j * self.size + i) * 3;
        let d = &self.faces[face as usize].data;
        [d[o], d[o + 1], d[o + 2]]
    }

    /// Texel at integer coordinates that may lie one texel outside the face: such taps are
    /// re-projected onto the neighbouring face through their direction, which makes bilinear
    /// filtering seamless across edges; past two edges at once (the cube-corner texel) the
    /// mean of the three texels meeting at that corner, as GPUs do ([`ghost_indices`]).
    #[inline]
    pub fn texel_wrapped(&self, face: Face, i: isize, j: isize) -> Rgb {
        let (texels, count) = ghost_indices(self.size, face, i, j);
        if count == 1 {
            let (f, i, j) = texels[0];
            return self.texel(f, i, j);
        }
        let [a, b, c] = texels.map(|(f, i, j)| self.texel(f, i, j));
        std::array::from_fn(|k| (a[k] + b[k] + c[k]) / 3.0)
    }

    /// Seamless bilinear sample in direction `d` (need not be normalised).
    pub fn sample_bilinear(&self, d: Vec3) -> Rgb {
        let (face, sc, tc) = Face::from_direction(d);
        let n = self.size as f32;
        let x = (sc + 1.0) * 0.5 * n - 0.5;
        let y = (tc + 1.0) * 0.5 * n - 0.5;
        let x0 = floor(x);
        let y0 = floor(y);
        let fx = x - x0;
        let fy = y - y0;
        let (x0, y0) = (x0 as isize, y0 as isize);
        let a = self.texel_wrapped(face, x0, y0);
        let b = self.texel_wrapped(face, x0 + 1, y0);
        let c = self.texel_wrapped(face, x0, y0 + 1);
        let e = self.texel_wrapped(face, x0 + 1, y0 + 1);
        let mut out = [0.0; 3];
        for k in 0..3 {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bot = c[k] + (e[k] - c[k]) * fx;
            out[k] = top + (bot - top) * fy;
        }
        out
    }

    /// Solid-angle-weighted 2×2 box reduction to a cube of half the size (odd sizes: the
    /// last row/column is folded into the previous texel), the exact mean radiance of each
    /// coarse texel's footprint.
    pub fn downsample(&self) -> Cubemap {
        let n = self.size;
        let m = (n / 2).max(1);
        if n == 1 {
            return self.clone();
        }
        let sa = solid_angle_table(n);
        let mut out = Cubemap::new(m);
        for (fi, face) in out.faces.iter_mut().enumerate() {
            let src = &self.faces[fi];
            for j in 0..m {
                for i in 0..m {
                    let (i0, i1) = (2 * i, if i == m - 1 { n } else { 2 * i + 2 });
                    let (j0, j1) = (2 * j, if j == m - 1 { n } else { 2 * j + 2 });
                    let mut acc = [0.0f64; 3];
                    let mut w = 0.0f64;
                    for y in j0..j1 {
                        for x in i0..i1 {
                            let s = sa[y * n + x] as f64;
                            let t = src.texel(x, y);
                            for k in 0..3 {
                                acc[k] += t[k] as f64 * s;
                            }
                            w += s;
                        }
                    }
                    let dst = face.texel_mut(i, j);
                    for k in 0..3 {
                        dst[k] = (acc[k] / w) as f32;
                    }
                }
            }
        }
        out
    }

    /// A cube of twice the size whose texels are this cube's values interpolated at their
    /// centres by the quadratic through the three nearest texels per axis (Lagrange, tensor
    /// product; texels past a face edge as [`Self::texel_wrapped`] gives them, seamless), each
    /// clamped at 0 (the quadratic overshoots next to a peak; light is never negative). A fine
    /// centre sits a quarter of a coarse texel from the nearest coarse centre, so the weights
    /// are fixed: (0.15625, 0.9375, −0.09375) and mirrored. Exact for a quadratic in the face
    /// coordinates within a face, its error third order in the texel size: what a smooth field
    /// sampled at half the resolution can give back (the lookup fit's node cubes,
    /// `ibl_prefilter`).
    pub fn upsample_quadratic(&self) -> Cubemap {
        use rayon::prelude::*;
        let n = self.size;
        let m = 2 * n;
        // Weights of the coarse texels c − 1, c, c + 1 at offset t = ∓¼ from centre c.
        let w = |t: f32| [t * (t - 1.0) / 2.0, 1.0 - t * t, t * (t + 1.0) / 2.0];
        let (lo, hi) = (w(-0.25), w(0.25));
        let mut out = Cubemap::new(m);
        out.faces
            .par_iter_mut()
            .zip(Face::ALL)
            .for_each(|(dst, face)| {
                for j in 0..m {
                    let (cj, wy) = ((j / 2) as isize, if j % 2 == 0 { lo } else { hi });
                    for i in 0..m {
                        let (ci, wx) = ((i / 2) as isize, if i % 2 == 0 { lo } else { hi });
                        let mut acc = [0.0f32; 3];
                        // Off the face's border row the nine texels are on the face: read
                        // them directly (the seam rules only past the edge).
                        let inner =
                            ci >= 1 && cj >= 1 && ci + 1 < n as isize && cj + 1 < n as isize;
                        for (b, wb) in wy.iter().enumerate() {
                            for (a, wa) in wx.iter().enumerate() {
                                let (x, y) = (ci + a as isize - 1, cj + b as isize - 1);
                                let t = if inner {
                                    self.texel(face, x as usize, y as usize)
                                } else {
                                    self.texel_wrapped(face, x, y)
                                };
                                for k in 0..3 {
                                    acc[k] += wa * wb * t[k];
                                }
                            }
                        }
                        let o = dst.texel_mut(i, j);
                        for k in 0..3 {
                            o[k] = acc[k].max(0.0);
                        }
                    }
                }
            });
        out
    }

    /// Mean radiance over the sphere (solid-angle weighted), in f64 for energy tests.
    pub fn mean_radiance(&self) -> [f64; 3] {
        let sa = solid_angle_table(self.size);
        let mut acc = [0.0f64; 3];
        for face in &self.faces {
            for (t, s) in face.data.chunks_exact(3).zip(&sa) {
                for k in 0..3 {
                    acc[k] += t[k] as f64 * *s as f64;
                }
            }
        }
        acc.map(|a| a / (4.0 * std::f64::consts::PI))
    }
}

/// ⌊x⌋ of a texel coordinate, inline: on the x86-64 baseline (no SSE4.1 `roundss`)
/// `f32::floor` is a call into libm, which the reads' texel lookups made millions of times a
/// bake. Truncate, then step down where truncation rounded a negative value up: exact for the
/// finite values a read meets (|x| < 2⁶³); a NaN gives 0, whose texel index (0) and fraction
/// (NaN) are what `f32::floor`'s NaN gave.
#[inline(always)]
fn floor(x: f32) -> f32 {
    let t = x as i64 as f32;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// Texel index of face coordinates, clamped to the face.
#[inline]
pub fn face_texel_index(sc: f32, tc: f32, n: usize) -> (usize, usize) {
    let fi = floor((sc + 1.0) * 0.5 * n as f32) as isize;
    let fj = floor((tc + 1.0) * 0.5 * n as f32) as isize;
    (
        fi.clamp(0, n as isize - 1) as usize,
        fj.clamp(0, n as isize - 1) as usize,
    )
}

/// A mip chain of cubemaps, level 0 the largest.
#[derive(Clone, Debug, PartialEq)]
pub struct CubeMips {
    /// The levels, each half the size of the previous (rounded down, at least 1).
    pub levels: Vec<Cubemap>,
}

impl CubeMips {
    /// Box-filtered chain from `base` down to faces of `min_size` texels.
    pub fn build(base: Cubemap, min_size: usize) -> Self {
        let mut levels = vec![base];
        while levels.last().unwrap().size > min_size.max(1) {
            let next = levels.last().unwrap().downsample();
            levels.push(next);
        }
        CubeMips { levels }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    fn close(a: Vec3, b: Vec3) -> bool {
        (a - b).length() < 1e-5
    }

    #[test]
    fn quadratic_upsampling_is_exact_for_quadratics_and_close_for_smooth_fields() {
        // A constant comes back exactly everywhere (corners and edges included).
        let c = Cubemap::from_fn(4, |_| [2.0, 0.5, 0.0]);
        let up = c.upsample_quadratic();
        assert_eq!(up.size, 8);
        assert!(up.faces.iter().all(|f| f
            .data
            .chunks(3)
            .all(|t| (t[0] - 2.0).abs() < 1e-6 && (t[1] - 0.5).abs() < 1e-6 && t[2] == 0.0)));
        // A quadratic in the face coordinates (s, t) of each texel centre, inside a face
        // (fine texels whose three coarse neighbours per axis lie on the face): exact.
        let n = 8;
        let mut c = Cubemap::new(n);
        let q = |s: f32, t: f32| 3.0 + 0.5 * s - 0.25 * t + 0.7 * s * s + 0.3 * s * t - 0.4 * t * t;
        let centre = |k: usize, n: usize| (2 * k + 1) as f32 / n as f32 - 1.0;
        for face in Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    let v = q(centre(i, n), centre(j, n)) + face as usize as f32;
                    c.faces[face as usize]
                        .texel_mut(i, j)
                        .copy_from_slice(&[v, v, v]);
                }
            }
        }
        let up = c.upsample_quadratic();
        for face in Face::ALL {
            for j in 2..2 * n - 2 {
                for i in 2..2 * n - 2 {
                    let want = q(centre(i, 2 * n), centre(j, 2 * n)) + face as usize as f32;
                    let got = up.texel(face, i, j)[0];
                    assert!(
                        (got - want).abs() < 2e-5,
                        "{face:?} {i} {j}: {got} vs {want}"
                    );
                }
            }
        }
        // A smooth lobe on the sphere, across edges and corners: within a fraction of the
        // error of taking the nearest coarse texel
        let f = |d: Vec3| {
            let x = (2.5 * (d.normalize().dot(Vec3::new(0.6, 0.5, 0.62).normalize()) - 1.0)).exp();
            [x, 1.0 - 0.5 * x, 0.25]
        };
        let (coarse, fine) = (Cubemap::from_fn(16, f), Cubemap::from_fn(32, f));
        let up = coarse.upsample_quadratic();
        let (mut err, mut nearest) = (0.0f64, 0.0f64);
        for face in Face::ALL {
            for j in 0..32 {
                for i in 0..32 {
                    let (a, b) = (up.texel(face, i, j)[0], fine.texel(face, i, j)[0]);
                    err = err.max((a - b).abs() as f64);
                    nearest = nearest.max((coarse.texel(face, i / 2, j / 2)[0] - b).abs() as f64);
                }
            }
        }
        // (measured: 0.0034 against 0.038, the worst at a cube corner, whose ghost is a mean.)
        assert!(err < 0.1 * nearest, "{err} vs nearest {nearest}");
    }

    #[test]
    fn from_fn_writes_each_texel_from_its_centre_direction() {
        let c = Cubemap::from_fn(5, |d| d.to_array());
        for face in Face::ALL {
            for (i, j) in [(0, 0), (4, 1), (2, 3)] {
                let t = c.texel(face, i, j);
                assert!(close(Vec3::from(t), texel_direction(face, i, j, 5)));
            }
        }
    }

    #[test]
    fn face_centres_and_corners_follow_design_table() {
        // Centres.
        let expect = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
        for (f, e) in Face::ALL.iter().zip(expect) {
            assert!(close(f.direction(0.0, 0.0).normalize(), e), "{f:?}");
        }
        // Top-left corner (sc, tc) = (−1, −1) of each face, i.e. texel (0, 0) of row 0.
        let tl = [
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(-1.0, 1.0, -1.0),
            Vec3::new(-1.0, 1.0, -1.0),
            Vec3::new(-1.0, -1.0, 1.0),
            Vec3::new(-1.0, 1.0, 1.0),
            Vec3::new(1.0, 1.0, -1.0),
        ];
        for (f, e) in Face::ALL.iter().zip(tl) {
            assert!(close(f.direction(-1.0, -1.0), e), "{f:?}");
        }
        // Bottom-right corner (1, 1).
        let br = [
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(-1.0, -1.0, 1.0),
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(1.0, -1.0, -1.0),
            Vec3::new(1.0, -1.0, 1.0),
            Vec3::new(-1.0, -1.0, -1.0),
        ];
        for (f, e) in Face::ALL.iter().zip(br) {
            assert!(close(f.direction(1.0, 1.0), e), "{f:?}");
        }
    }

    #[test]
    fn direction_texel_direction_round_trips() {
        let n = 37;
        for face in Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    let d = texel_direction(face, i, j, n);
                    let (f2, s, t) = Face::from_direction(d);
                    assert_eq!(f2, face);
                    assert_eq!(face_texel_index(s, t, n), (i, j));
                    assert!(close(f2.direction(s, t).normalize(), d));
                }
            }
        }
    }

    #[test]
    fn solid_angles_sum_to_four_pi() {
        for n in [1usize, 2, 3, 16, 255] {
            let mut sum = 0.0f64;
            for j in 0..n {
                for i in 0..n {
                    sum += texel_solid_angle(i, j, n);
                }
            }
            assert!((6.0 * sum - 4.0 * PI).abs() < 1e-9, "n={n}: {}", 6.0 * sum);
        }
    }

    #[test]
    fn solid_angle_table_equals_the_texel_formula() {
        for n in [1usize, 2, 7, 64] {
            let t = solid_angle_table(n);
            assert_eq!(t.len(), n * n);
            for j in 0..n {
                for i in 0..n {
                    assert_eq!(
                        t[j * n + i],
                        texel_solid_angle(i, j, n) as f32,
                        "n={n} ({i},{j})"
                    );
                }
            }
        }
    }

    #[test]
    fn solid_angle_matches_numeric_integration() {
        // dω = dA / (1+x²+y²)^{3/2} integrated by the midpoint rule over one texel.
        let (n, i, j) = (8, 1, 6);
        let k = 400;
        let x0 = 2.0 * i as f64 / n as f64 - 1.0;
        let y0 = 2.0 * j as f64 / n as f64 - 1.0;
        let h = 2.0 / n as f64 / k as f64;
        let mut s = 0.0;
        for a in 0..k {
            for b in 0..k {
                let x = x0 + (a as f64 + 0.5) * h;
                let y = y0 + (b as f64 + 0.5) * h;
                s += h * h / (1.0 + x * x + y * y).powf(1.5);
            }
        }
        assert!((s - texel_solid_angle(i, j, n)).abs() < 1e-8);
    }

    #[test]
    fn the_inline_floor_is_f32_floor() {
        let mut rng = crate::sampling::Pcg32::new(7, 1);
        let mut xs = vec![
            0.0f32, -0.0, 0.5, -0.5, 1.0, -1.0, 1e-30, -1e-30, 8388607.5, -8388607.5,
        ];
        xs.extend([16777216.0f32, -16777217.0, 1e18, -1e18]);
        for k in -2000..2000 {
            let v = k as f32 / 7.0;
            xs.extend([
                v,
                f32::from_bits(v.to_bits() + 1),
                f32::from_bits(v.to_bits().wrapping_sub(1)),
            ]);
        }
        xs.extend((0..10_000).map(|_| (rng.next_f32() - 0.5) * 4096.0));
        // (== takes −0 for 0: a read's coordinate x − 0.5 is never −0.)
        for x in xs.into_iter().filter(|x| !x.is_nan()) {
            assert_eq!(floor(x), x.floor(), "{x:e}");
        }
        assert_eq!(floor(f32::NAN), 0.0);
    }

    #[test]
    fn mip_sizes_halve_to_the_floor() {
        assert_eq!(mip_sizes(256, 8), vec![256, 128, 64, 32, 16, 8]);
        assert_eq!(mip_sizes(100, 8), vec![100, 50, 25, 12, 6]);
        assert_eq!(mip_sizes(1, 8), vec![1]);
    }

    #[test]
    fn bilinear_is_seamless_across_edges_and_corners() {
        // A cube holding a smooth function of direction: samples just either side of an edge
        // and at a corner must agree with the function closely.
        let n = 64;
        let f = |d: Vec3| 1.0 + d.x + 0.5 * d.y * d.z;
        let mut cube = Cubemap::new(n);
        for face in Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    let v = f(texel_direction(face, i, j, n));
                    cube.faces[face as usize]
                        .texel_mut(i, j)
                        .copy_from_slice(&[v, v, v]);
                }
            }
        }
        for d in [
            Vec3::new(1.0, 0.3, 0.999),
            Vec3::new(1.0, 0.3, 1.001),
            Vec3::new(1.0, 1.0, 1.0),
            Vec3::new(-1.0, 0.999, -1.0),
        ] {
            let got = cube.sample_bilinear(d)[0];
            let want = f(d.normalize());
            assert!((got - want).abs() < 0.01, "{d}: {got} vs {want}");
        }
    }

    #[test]
    fn bilinear_taps_are_the_rows_of_sample_bilinear() {
        // A cube of distinct values per texel and channel: the taps' weighted sum is the
        // sampler's result everywhere (edges and corners of tiny faces included), the weights
        // sum to 1 and each index is a texel of the cube.
        use crate::sampling::Pcg32;
        let mut rng = Pcg32::new(7, 1);
        for n in [1usize, 2, 3, 4, 8] {
            let mut cube = Cubemap::new(n);
            for face in cube.faces.iter_mut() {
                face.data
                    .iter_mut()
                    .for_each(|v| *v = rng.next_f64() as f32);
            }
            for _ in 0..2000 {
                let d = Vec3::new(
                    rng.next_f64() as f32 - 0.5,
                    rng.next_f64() as f32 - 0.5,
                    rng.next_f64() as f32 - 0.5,
                );
                if d.length() < 1e-3 {
                    continue;
                }
                let taps = bilinear_taps(n, d);
                let w: f32 = taps.iter().map(|t| t.1).sum();
                assert!((w - 1.0).abs() < 1e-5);
                let want = cube.sample_bilinear(d);
                for (c, want) in want.iter().enumerate() {
                    let got: f32 = taps
                        .iter()
                        .map(|&(k, w)| {
                            assert!(k < 6 * n * n);
                            w * cube.faces[k / (n * n)].data[3 * (k % (n * n)) + c]
                        })
                        .sum();
                    assert!((got - want).abs() < 1e-5, "n {n}, {d}: {got} vs {want}");
                }
            }
        }
    }

    /// A cube of distinct random values per texel and channel.
    fn random_cube(n: usize, seed: u64) -> Cubemap {
        let mut rng = crate::sampling::Pcg32::new(seed, 5);
        let mut cube = Cubemap::new(n);
        for face in cube.faces.iter_mut() {
            face.data
                .iter_mut()
                .for_each(|v| *v = rng.next_f64() as f32 * 4.0);
        }
        cube
    }

    #[test]
    fn corner_ghost_texel_is_the_mean_of_the_three_texels_at_the_cube_corner() {
        // Independent of the re-projection: the three texels meeting at a cube corner are the
        // three whose centres lie nearest that corner's direction (one per face), found by
        // brute force over all texels; every face's four corner ghosts must read their mean
        // (OpenGL 4.6 §8.13.1's recommended rule), for every size including 1×1.
        for n in [1usize, 2, 3, 4, 7] {
            let cube = random_cube(n, n as u64);
            for face in Face::ALL {
                for (gi, gj) in [
                    (-1, -1),
                    (n as isize, -1),
                    (-1, n as isize),
                    (n as isize, n as isize),
                ] {
                    let c = |x: isize| (2.0 * (x as f32 + 0.5)) / n as f32 - 1.0;
                    let g = face.direction(c(gi), c(gj));
                    let corner = Vec3::new(g.x.signum(), g.y.signum(), g.z.signum()).normalize();
                    let mut all: Vec<(f32, Rgb)> = Vec::new();
                    for f in Face::ALL {
                        for j in 0..n {
                            for i in 0..n {
                                let d = texel_direction(f, i, j, n);
                                all.push((-d.dot(corner), cube.texel(f, i, j)));
                            }
                        }
                    }
                    all.sort_by(|a, b| a.0.total_cmp(&b.0));
                    let got = cube.texel_wrapped(face, gi, gj);
                    for k in 0..3 {
                        let want = (all[0].1[k] + all[1].1[k] + all[2].1[k]) / 3.0;
                        assert!(
                            (got[k] - want).abs() < 1e-6,
                            "n {n} {face:?} ({gi}, {gj}): {got:?} vs mean {want}"
                        );
                    }
                    // The fourth nearest is farther: the three are the corner's, not a tie.
                    if n > 1 {
                        assert!(all[3].0 > all[2].0 + 1e-4, "n {n}");
                    }
                }
            }
        }
    }

    #[test]
    fn a_read_near_a_cube_corner_blends_the_mean_of_three() {
        // Only the three texels at the +X+Y+Z corner are lit (values 3, 6, 12 on a 4×4 cube):
        // a read on +X inside its corner texel's quarter towards that corner blends the face's
        // texel (3), the two neighbours' (6, 12) and the corner ghost (their mean, 7) by the
        // bilinear weights; a single re-projected texel (3, 6 or 12, the old rule) differs.
        let n = 4;
        let mut cube = Cubemap::new(n);
        let corner = Vec3::ONE.normalize();
        let mut lit = Vec::new();
        for f in Face::ALL {
            let (mut best, mut at) = (-2.0, (0, 0));
            for j in 0..n {
                for i in 0..n {
                    let d = texel_direction(f, i, j, n).dot(corner);
                    if d > best {
                        (best, at) = (d, (i, j));
                    }
                }
            }
            if best > 0.5 {
                lit.push((f, at));
            }
        }
        assert_eq!(lit.len(), 3);
        let value = |f: Face| match f {
            Face::Px => 3.0,
            Face::Py => 6.0,
            _ => 12.0,
        };
        for &(f, (i, j)) in &lit {
            cube.faces[f as usize].texel_mut(i, j).fill(value(f));
        }
        // +X: (sc, tc) → (1, −tc, −sc); its +Y+Z corner is at sc = −1, tc = −1, texel (0, 0).
        // Face coordinates a quarter and a third of a texel past the corner texel's centre.
        let (qx, qy) = (0.25f32, 1.0 / 3.0);
        let sc = -1.0 + (0.5 - qx) * 2.0 / n as f32;
        let tc = -1.0 + (0.5 - qy) * 2.0 / n as f32;
        let d = Face::Px.direction(sc, tc);
        // Texel-space weights: the ghost column/row is x = −1 / y = −1, fraction qx / qy of it.
        let (wx, wy) = (qx, qy);
        let (pz, py) = (12.0, 6.0); // the neighbours across the −sc (+Z) and −tc (+Y) edges
        let want = (1.0 - wx) * (1.0 - wy) * 3.0
            + wx * (1.0 - wy) * pz
            + (1.0 - wx) * wy * py
            + wx * wy * (3.0 + 6.0 + 12.0) / 3.0;
        let got = cube.sample_bilinear(d)[0];
        assert!((got - want).abs() < 1e-5, "{got} vs {want}");
        let bordered = crate::bordered::BorderedMips::new(&CubeMips {
            levels: vec![cube.clone()],
        });
        assert!((bordered.bilinear(d, 0)[0] - want).abs() < 1e-5);
    }

    #[test]
    fn constant_cube_reads_constant_everywhere_and_tap_weights_sum_to_one() {
        // Property: for random directions (and every cube corner, edge and face centre
        // direction), on sizes 1…8, the read of a constant cube is that constant (corners
        // included: three equal texels average to their value, which GL requires of any
        // corner rule), the taps' weights are ≥ 0 and sum to 1, and the taps' row reproduces
        // the read of a random cube.
        let mut rng = crate::sampling::Pcg32::new(11, 3);
        let c = [0.7f32, 123.25, 3.0e-3];
        let mut dirs: Vec<Vec3> = Vec::new();
        for x in [-1.0f32, 0.0, 1.0] {
            for y in [-1.0f32, 0.0, 1.0] {
                for z in [-1.0f32, 0.0, 1.0] {
                    if (x, y, z) != (0.0, 0.0, 0.0) {
                        dirs.push(Vec3::new(x, y, z));
                        // Just off the corner/edge, on each side of the face choice.
                        dirs.push(Vec3::new(x * 1.001, y, z * 0.999));
                    }
                }
            }
        }
        for _ in 0..3000 {
            let d = Vec3::new(
                rng.next_f64() as f32 - 0.5,
                rng.next_f64() as f32 - 0.5,
                rng.next_f64() as f32 - 0.5,
            );
            if d.length() > 1e-3 {
                dirs.push(d);
            }
        }
        for n in 1..=8usize {
            let cube = Cubemap::constant(n, c);
            let random = random_cube(n, 100 + n as u64);
            for &d in &dirs {
                let got = cube.sample_bilinear(d);
                for k in 0..3 {
                    assert!((got[k] - c[k]).abs() <= 2e-6 * c[k], "n {n} {d}: {got:?}");
                }
                let taps = bilinear_taps(n, d);
                assert!(taps.iter().all(|t| t.1 >= 0.0 && t.0 < 6 * n * n));
                let w: f32 = taps.iter().map(|t| t.1).sum();
                assert!((w - 1.0).abs() < 1e-5, "n {n} {d}: weights sum to {w}");
                let want = random.sample_bilinear(d);
                for (k, want) in want.iter().enumerate() {
                    let got: f32 = taps
                        .iter()
                        .map(|&(p, w)| w * random.faces[p / (n * n)].data[3 * (p % (n * n)) + k])
                        .sum();
                    assert!((got - want).abs() < 1e-5, "n {n}, {d}: {got} vs {want}");
                }
            }
        }
    }

    #[test]
    fn downsample_preserves_mean_radiance() {
        let n = 10;
        let mut cube = Cubemap::new(n);
        for (fi, face) in cube.faces.iter_mut().enumerate() {
            for (k, v) in face.data.iter_mut().enumerate() {
                *v = ((k * 7 + fi * 13) % 11) as f32;
            }
        }
        let a = cube.mean_radiance();
        let b = cube.downsample().mean_radiance();
        for k in 0..3 {
            assert!((a[k] - b[k]).abs() < 1e-5 * a[k].abs().max(1.0));
        }
    }
}
