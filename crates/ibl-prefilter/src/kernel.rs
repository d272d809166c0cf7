//! The exact prefilter kernel of the split-sum radiance term and its brute-force convolution:
//! K(l) ∝ D_GGX(n·h, α)·max(n·l, 0) with h = normalize(n + l), normalised to unit sum
//! (Karis 2013 with n = v = r; Cocco et al. 2024 §3 eq. 2).
//!
//! Erratum noted against Cocco et al. 2024 §3: the text writes the filter as
//! K(ω_i) = D(T ω_i)(ω̃_g·ω_i), i.e. D evaluated at the *light* direction, which has unit
//! integral by the NDF's normalisation. The filter that the split sum with n = v = r actually
//! produces (and that the issue and Karis 2013 integrate) is D evaluated at the *half vector*
//! h = normalize(n + l) times n·l; it does not integrate to one
//! (∫ D(h)(n·l) dl = 4∫ D(h)(n·h)(2(n·h)²−1) dh < 4), so it must be normalised by its sum.
//! Both kernels are radially symmetric but the half-vector one is about twice as wide.

use glam::Vec3;
use ibl_core::cube::{Cubemap, Face};
use ibl_core::progress::Progress;
use ibl_core::traverse::map_cube_texels;
use ibl_core::Rgb;

#[cfg(test)]
/// sin²θ_h of the half vector of unit `n` and `l`: |n − l|²/4. Computed from the chord so it
/// stays exact where 1 − n·l cancels (narrow lobes).
#[inline]
pub(crate) fn sin2_half(n: Vec3, l: Vec3) -> f32 {
    (n - l).length_squared() * 0.25
}

#[cfg(test)]
/// D_GGX(n·h, α)·max(n·l, 0) as a function of s2 = sin²θ_h (n = v): with cos²θ_h = 1 − s2 the
/// GGX denominator (Walter et al. 2007, eq. 33) is (n·h)²(α²−1)+1 = α² + (1−α²)·s2, and
/// n·l = cos 2θ_h = 1 − 2·s2. Needs α > 0 (roughness 0 is the mirror, a delta).
#[inline]
pub(crate) fn kernel_d_nl(s2: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let t = a2 + (1.0 - a2) * s2;
    a2 * (1.0 - 2.0 * s2).max(0.0) / (std::f32::consts::PI * t * t)
}

/// The source of a brute-force convolution: every texel of a cube as structure-of-arrays,
/// grouped in square tiles so whole tiles below the horizon of `n` can be skipped exactly.
pub struct SourceTexels {
    /// Face size of the source cube.
    pub size: usize,
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    /// Radiance times solid angle, per channel.
    r: Vec<f32>,
    g: Vec<f32>,
    b: Vec<f32>,
    /// Texel solid angle.
    omega: Vec<f32>,
    tiles: Vec<Tile>,
}

/// A tile of texels stored contiguously, with the (unnormalised) directions of its four
/// corners: every direction inside is a positive combination of them, so n·corner ≤ 0 at all
/// four corners proves n·l ≤ 0 (a zero kernel) over the whole tile.
#[derive(Clone, Copy)]
struct Tile {
    start: usize,
    len: usize,
    corners: [Vec3; 4],
}

/// Texels per tile edge.
const TILE: usize = 8;

impl SourceTexels {
    /// Every texel of `cube` with its direction and solid angle.
    pub fn new(cube: &Cubemap) -> Self {
        use rayon::prelude::*;
        let n = cube.size;
        let sa = ibl_core::cube::solid_angle_table(n);
        let coord = |k: usize| 2.0 * k as f32 / n as f32 - 1.0;
        // One face per task, tiles in order within it: the layout is thread-count independent.
        let faces: Vec<SourceTexels> = Face::ALL
            .par_iter()
            .map(|&face| {
                let mut s = SourceTexels::empty(n);
                for tj in (0..n).step_by(TILE) {
                    for ti in (0..n).step_by(TILE) {
                        let (i1, j1) = ((ti + TILE).min(n), (tj + TILE).min(n));
                        let start = s.x.len();
                        for j in tj..j1 {
                            for i in ti..i1 {
                                let d = ibl_core::cube::texel_direction(face, i, j, n);
                                let om = sa[j * n + i];
                                let c = cube.texel(face, i, j);
                                s.x.push(d.x);
                                s.y.push(d.y);
                                s.z.push(d.z);
                                s.r.push(c[0] * om);
                                s.g.push(c[1] * om);
                                s.b.push(c[2] * om);
                                s.omega.push(om);
                            }
                        }
                        let corners = [
                            face.direction(coord(ti), coord(tj)),
                            face.direction(coord(i1), coord(tj)),
                            face.direction(coord(ti), coord(j1)),
                            face.direction(coord(i1), coord(j1)),
                        ];
                        s.tiles.push(Tile {
                            start,
                            len: s.x.len() - start,
                            corners,
                        });
                    }
                }
                s
            })
            .collect();
        let mut all = SourceTexels::empty(n);
        for f in faces {
            let base = all.x.len();
            all.tiles.extend(f.tiles.iter().map(|t| Tile {
                start: t.start + base,
                ..*t
            }));
            all.x.extend(f.x);
            all.y.extend(f.y);
            all.z.extend(f.z);
            all.r.extend(f.r);
            all.g.extend(f.g);
            all.b.extend(f.b);
            all.omega.extend(f.omega);
        }
        all
    }

    /// No texels (where the bake sums over the cell tree's own copy of them).
    pub(crate) fn none() -> Self {
        Self::empty(0)
    }

    fn empty(size: usize) -> Self {
        SourceTexels {
            size,
            x: Vec::new(),
            y: Vec::new(),
            z: Vec::new(),
            r: Vec::new(),
            g: Vec::new(),
            b: Vec::new(),
            omega: Vec::new(),
            tiles: Vec::new(),
        }
    }

    /// Texels held.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Whether the source has no texel.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// The exact kernel of roughness α summed over every texel with its solid angle and
    /// normalised by the kernel's own sum: Σ K(l_i) L_i Ω_i / Σ K(l_i) Ω_i.
    pub fn convolve(&self, n: Vec3, alpha: f32) -> Rgb {
        let a2 = alpha * alpha;
        let mut acc = [0.0f64; 4];
        for tile in &self.tiles {
            if tile.corners.iter().all(|c| n.dot(*c) <= 0.0) {
                continue;
            }
            let part = self.tile_sum(n, a2, tile.start, tile.len);
            for k in 0..4 {
                acc[k] += part[k] as f64;
            }
        }
        if acc[3] <= 0.0 {
            return [0.0; 3];
        }
        [
            (acc[0] / acc[3]) as f32,
            (acc[1] / acc[3]) as f32,
            (acc[2] / acc[3]) as f32,
        ]
    }

    /// Sum over one tile in eight f32 lanes (vectorises; a tile holds at most 64 texels so
    /// f32 partial sums lose nothing that matters before the f64 total).
    #[inline]
    fn tile_sum(&self, n: Vec3, a2: f32, start: usize, len: usize) -> [f32; 4] {
        const L: usize = 8;
        let one_m = 1.0 - a2;
        let mut lanes = [[0.0f32; L]; 4];
        let end = start + len;
        let mut i = start;
        // Kernel without its constant α²/π, which cancels in the normalisation.
        let weight = |x: f32, y: f32, z: f32| {
            let (dx, dy, dz) = (n.x - x, n.y - y, n.z - z);
            let s2 = 0.25 * (dx * dx + dy * dy + dz * dz);
            let t = a2 + one_m * s2;
            (1.0 - 2.0 * s2).max(0.0) / (t * t)
        };
        while i + L <= end {
            let xs: &[f32; L] = self.x[i..i + L].try_into().unwrap();
            let ys: &[f32; L] = self.y[i..i + L].try_into().unwrap();
            let zs: &[f32; L] = self.z[i..i + L].try_into().unwrap();
            let rs: &[f32; L] = self.r[i..i + L].try_into().unwrap();
            let gs: &[f32; L] = self.g[i..i + L].try_into().unwrap();
            let bs: &[f32; L] = self.b[i..i + L].try_into().unwrap();
            let os: &[f32; L] = self.omega[i..i + L].try_into().unwrap();
            for k in 0..L {
                let w = weight(xs[k], ys[k], zs[k]);
                lanes[0][k] += w * rs[k];
                lanes[1][k] += w * gs[k];
                lanes[2][k] += w * bs[k];
                lanes[3][k] += w * os[k];
            }
            i += L;
        }
        let mut out = [0.0f32; 4];
        for c in 0..4 {
            out[c] = lanes[c].iter().sum();
        }
        for k in i..end {
            let w = weight(self.x[k], self.y[k], self.z[k]);
            out[0] += w * self.r[k];
            out[1] += w * self.g[k];
            out[2] += w * self.b[k];
            out[3] += w * self.omega[k];
        }
        out
    }
}

/// The brute-force reference of one level: every output texel of an n×n cube convolved with
/// the exact kernel over every source texel. Roughness 0 is the mirror: the source box-reduced
/// to n (the source size must then be n·2^k).
pub(crate) fn reference_level(
    src: &Cubemap,
    texels: &SourceTexels,
    n: usize,
    roughness: f32,
    progress: &dyn Progress,
) -> Cubemap {
    if roughness <= 0.0 {
        let mut c = src.clone();
        while c.size > n {
            c = c.downsample();
        }
        return c;
    }
    let alpha = roughness * roughness;
    map_cube_texels(n, progress, |face, i, j| {
        texels.convolve(ibl_core::cube::texel_direction(face, i, j, n), alpha)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_brdf::ggx::d_ggx;
    use ibl_core::cube::{texel_direction, texel_solid_angle};
    use ibl_core::progress::NoProgress;
    use ibl_core::sampling::Pcg32;

    fn random_dir(rng: &mut Pcg32) -> Vec3 {
        let z = 1.0 - 2.0 * rng.next_f32();
        let phi = 2.0 * std::f32::consts::PI * rng.next_f32();
        let s = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(s * phi.cos(), s * phi.sin(), z)
    }

    #[test]
    fn kernel_matches_d_ggx_at_half_vector_times_n_dot_l() {
        let mut rng = Pcg32::new(1, 2);
        let mut worst = 0.0f32;
        for _ in 0..2000 {
            let n = random_dir(&mut rng);
            let l = random_dir(&mut rng);
            let alpha = 0.05 + 0.95 * rng.next_f32();
            let h = (n + l).normalize();
            let want = d_ggx(n.dot(h), alpha) * n.dot(l).max(0.0);
            let got = kernel_d_nl(sin2_half(n, l), alpha);
            let rel = (got - want).abs() / want.max(1e-3);
            worst = worst.max(rel);
        }
        eprintln!("kernel vs d_ggx(n·h)·n·l: worst relative difference {worst:.2e}");
        assert!(worst < 1e-4, "{worst}");
    }

    #[test]
    fn kernel_is_stable_for_narrow_lobes() {
        // α = 1e-4 (r = 0.01): 1 − n·l cancels in f32, the chord form must not.
        let n = Vec3::Z;
        let theta = 1e-4f32;
        let l = Vec3::new(theta.sin(), 0.0, theta.cos());
        let s2 = sin2_half(n, l);
        let exact = ((theta as f64) / 2.0).sin().powi(2);
        assert!(
            ((s2 as f64 - exact) / exact).abs() < 1e-5,
            "{s2} vs {exact}"
        );
        let k = kernel_d_nl(s2, 1e-4);
        assert!(k.is_finite() && k > 0.0);
    }

    /// ∫ D(h)(n·l) dl by a fine midpoint rule in θ_l (the kernel is radially symmetric), and
    /// the same through the half vector: dl = 4(n·h) dh with n = v.
    #[test]
    fn kernel_integral_matches_half_vector_form() {
        for alpha in [0.1f32, 0.5, 1.0] {
            let m = 200_000;
            let (mut by_l, mut by_h) = (0.0f64, 0.0f64);
            for k in 0..m {
                let tl = (k as f64 + 0.5) / m as f64 * std::f64::consts::FRAC_PI_2;
                let s2 = ((tl / 2.0).sin()).powi(2) as f32;
                by_l += kernel_d_nl(s2, alpha) as f64
                    * 2.0
                    * std::f64::consts::PI
                    * tl.sin()
                    * (std::f64::consts::FRAC_PI_2 / m as f64);
                let th = (k as f64 + 0.5) / m as f64 * std::f64::consts::FRAC_PI_4;
                let c = th.cos();
                by_h += d_ggx(c as f32, alpha) as f64
                    * (2.0 * c * c - 1.0)
                    * 4.0
                    * c
                    * 2.0
                    * std::f64::consts::PI
                    * th.sin()
                    * (std::f64::consts::FRAC_PI_4 / m as f64);
            }
            eprintln!("alpha {alpha}: ∫D(h)(n·l)dl = {by_l:.6} (via h: {by_h:.6})");
            assert!((by_l - by_h).abs() < 1e-3 * by_h, "{by_l} {by_h}");
            assert!(by_l < 4.0 && by_l > 0.0);
        }
    }

    #[test]
    fn constant_source_convolves_to_itself() {
        let cube = Cubemap::constant(8, [0.5, 2.0, 7.0]);
        let t = SourceTexels::new(&cube);
        for r in [0.05f32, 0.3, 1.0] {
            let out = t.convolve(Vec3::new(0.3, -0.8, 0.2).normalize(), r * r);
            for (k, want) in [0.5f32, 2.0, 7.0].iter().enumerate() {
                assert!((out[k] - want).abs() < 1e-5 * want, "{r}: {out:?}");
            }
        }
    }

    #[test]
    fn tile_skip_changes_nothing() {
        // Compare against a plain loop over every texel with no skipping and f64 sums.
        let n = 12; // not a multiple of the tile size: partial tiles too
        let mut cube = Cubemap::new(n);
        let mut rng = Pcg32::new(5, 1);
        for f in &mut cube.faces {
            f.data.iter_mut().for_each(|v| *v = rng.next_f32() * 10.0);
        }
        let t = SourceTexels::new(&cube);
        let mut worst = 0.0f64;
        for _ in 0..40 {
            let nd = random_dir(&mut rng);
            let alpha = 0.1 + 0.9 * rng.next_f32();
            let got = t.convolve(nd, alpha);
            let (mut num, mut den) = ([0.0f64; 3], 0.0f64);
            for face in Face::ALL {
                for j in 0..n {
                    for i in 0..n {
                        let l = texel_direction(face, i, j, n);
                        let w = kernel_d_nl(sin2_half(nd, l), alpha) as f64
                            * texel_solid_angle(i, j, n);
                        let c = cube.texel(face, i, j);
                        for k in 0..3 {
                            num[k] += w * c[k] as f64;
                        }
                        den += w;
                    }
                }
            }
            for k in 0..3 {
                worst = worst.max(((got[k] as f64 - num[k] / den) / (num[k] / den)).abs());
            }
        }
        eprintln!(
            "tiled/skipped convolution vs plain f64 loop: worst relative difference {worst:.2e}"
        );
        assert!(worst < 1e-5, "{worst}");
    }

    #[test]
    fn reference_level_zero_is_the_box_reduced_source() {
        let mut cube = Cubemap::new(8);
        for (fi, f) in cube.faces.iter_mut().enumerate() {
            f.data
                .iter_mut()
                .enumerate()
                .for_each(|(k, v)| *v = (k * 3 + fi) as f32 % 5.0);
        }
        let t = SourceTexels::new(&cube);
        let r = reference_level(&cube, &t, 4, 0.0, &NoProgress);
        assert_eq!(r, cube.downsample());
    }
}
