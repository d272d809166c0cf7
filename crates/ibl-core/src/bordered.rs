//! Seamless trilinear reads of a cube mip chain by direction and level of detail: every face is
//! stored with a one-texel border copied from its neighbours, so a bilinear tap never branches
//! on face edges. The one sampler filtered importance sampling (ibl-prefilter) and the SH-exp
//! E0 estimator and split-sum lookups (ibl-shexp) read through; matches
//! `Cubemap::sample_bilinear` (same border re-projection).

use crate::cube::{CubeMips, Cubemap, Face};
use crate::Rgb;
use glam::Vec3;

/// One mip with bordered faces: (n+2)² RGB texels per face, face after face.
#[derive(Clone, Debug)]
struct BorderedLevel {
    n: usize,
    data: Vec<[f32; 3]>,
}

impl BorderedLevel {
    /// Copies the cube and fills each border texel from the face its direction lands on
    /// (`Cubemap::texel_wrapped`, the re-projection `Cubemap::sample_bilinear` uses; a corner
    /// border texel is the mean of the three texels meeting at that cube corner, as on GPUs).
    fn new(cube: &Cubemap) -> Self {
        let n = cube.size;
        let s = n + 2;
        use rayon::prelude::*;
        let mut data = vec![[0.0f32; 3]; 6 * s * s];
        // A face a job: the chain's level 0 is most of a report's serial time otherwise.
        data.par_chunks_mut(s * s).enumerate().for_each(|(f, out)| {
            let face = Face::from_index(f);
            // The interior is the face itself, row by row; only the border re-projects (every
            // texel through `texel_wrapped` was most of the runtime report's serial time).
            let src = &cube.faces[face as usize].data;
            for (y, row) in src.chunks_exact(3 * n).enumerate() {
                let dst = &mut out[(y + 1) * s + 1..][..n];
                for (d, t) in dst.iter_mut().zip(row.chunks_exact(3)) {
                    *d = [t[0], t[1], t[2]];
                }
            }
            let wrapped =
                |x: usize, y: usize| cube.texel_wrapped(face, x as isize - 1, y as isize - 1);
            for x in 0..s {
                out[x] = wrapped(x, 0);
                out[(s - 1) * s + x] = wrapped(x, s - 1);
            }
            for y in 1..s - 1 {
                out[y * s] = wrapped(0, y);
                out[y * s + s - 1] = wrapped(s - 1, y);
            }
        });
        BorderedLevel { n, data }
    }

    #[inline]
    fn at(&self, face: usize, x: usize, y: usize) -> [f32; 3] {
        let s = self.n + 2;
        self.data[face * s * s + y * s + x]
    }

    /// Bilinear tap at face coordinates (sc, tc) ∈ [−1, 1]² of `face`.
    #[inline]
    fn bilinear(&self, face: usize, sc: f32, tc: f32) -> [f32; 3] {
        let n = self.n as f32;
        // Texel space with centres at integers, shifted by the border: x ∈ [0.5, n + 0.5].
        let x = ((sc + 1.0) * 0.5 * n + 0.5).clamp(0.0, n + 0.999);
        let y = ((tc + 1.0) * 0.5 * n + 0.5).clamp(0.0, n + 0.999);
        // x, y ≥ 0: truncation is the floor, and stays inline where `f32::floor` is a libm
        // call on the x86-64 baseline (no SSE4.1 round; 9% of shexp-fit's time).
        let (x0, y0) = (x as usize, y as usize);
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let a = self.at(face, x0, y0);
        let b = self.at(face, x0 + 1, y0);
        let c = self.at(face, x0, y0 + 1);
        let d = self.at(face, x0 + 1, y0 + 1);
        let mut out = [0.0f32; 3];
        for k in 0..3 {
            let top = a[k] + (b[k] - a[k]) * fx;
            let bot = c[k] + (d[k] - c[k]) * fx;
            out[k] = top + (bot - top) * fy;
        }
        out
    }
}

/// A cube mip chain (level 0 the finest) prepared for seamless bilinear and trilinear reads.
#[derive(Clone, Debug)]
pub struct BorderedMips {
    levels: Vec<BorderedLevel>,
    /// log2 of the base level's texel solid angle at a face centre ≈ 4π / (6 n²).
    base_log2_texel_sa: f32,
}

impl BorderedMips {
    /// Pads every level of `mips` with its neighbours' texels.
    pub fn new(mips: &CubeMips) -> Self {
        let n0 = mips.levels[0].size as f32;
        BorderedMips {
            levels: mips.levels.iter().map(BorderedLevel::new).collect(),
            base_log2_texel_sa: (4.0 * std::f32::consts::PI / (6.0 * n0 * n0)).log2(),
        }
    }

    /// Number of levels.
    pub fn num_levels(&self) -> usize {
        self.levels.len()
    }

    /// Index of the coarsest level.
    pub fn max_lod(&self) -> u32 {
        (self.levels.len() - 1) as u32
    }

    /// Face size of level 0.
    pub fn size(&self) -> usize {
        self.levels[0].n
    }

    /// Face sizes of the chain, largest first.
    pub fn sizes(&self) -> Vec<usize> {
        self.levels.iter().map(|l| l.n).collect()
    }

    /// log2 of the base texel's solid angle, the offset of the filtered-importance-sampling lod.
    pub fn base_log2_texel_solid_angle(&self) -> f32 {
        self.base_log2_texel_sa
    }

    /// Bytes of the unpadded chain at `bytes_per_texel` (for memory reports).
    pub fn chain_bytes(&self, bytes_per_texel: usize) -> usize {
        self.levels
            .iter()
            .map(|l| 6 * l.n * l.n * bytes_per_texel)
            .sum()
    }

    /// Seamless bilinear read of level `level` (clamped to the chain) in direction `d` (need
    /// not be normalised).
    pub fn bilinear(&self, d: Vec3, level: usize) -> Rgb {
        let (face, sc, tc) = Face::from_direction(d);
        self.levels[level.min(self.levels.len() - 1)].bilinear(face as usize, sc, tc)
    }

    /// Trilinear read: bilinear on levels `level` and `level + 1`, blended by `frac`.
    #[inline]
    pub fn trilinear(&self, d: Vec3, level: usize, frac: f32) -> Rgb {
        let (face, sc, tc) = Face::from_direction(d);
        let f = face as usize;
        let m = level.min(self.levels.len() - 1);
        let a = self.levels[m].bilinear(f, sc, tc);
        if frac <= 0.0 || m + 1 >= self.levels.len() {
            return a;
        }
        let b = self.levels[m + 1].bilinear(f, sc, tc);
        [
            a[0] + (b[0] - a[0]) * frac,
            a[1] + (b[1] - a[1]) * frac,
            a[2] + (b[2] - a[2]) * frac,
        ]
    }

    /// Trilinear read at a continuous level of detail (clamped to the chain).
    #[inline]
    pub fn sample(&self, d: Vec3, lod: f32) -> Rgb {
        let lod = lod.clamp(0.0, self.max_lod() as f32);
        // lod ≥ 0: truncation is the floor (see `BorderedLevel::bilinear`).
        let l0 = lod as usize;
        self.trilinear(d, l0, lod - l0 as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cube::texel_direction;
    use crate::sampling::Pcg32;

    fn noisy_cube(n: usize, seed: u64) -> Cubemap {
        let mut rng = Pcg32::new(seed, 3);
        let mut c = Cubemap::new(n);
        for f in &mut c.faces {
            f.data.iter_mut().for_each(|v| *v = rng.next_f32() * 4.0);
        }
        c
    }

    #[test]
    fn bilinear_matches_the_core_sampler_everywhere() {
        // Random directions, including edges and corners, against Cubemap::sample_bilinear.
        let cube = noisy_cube(7, 1);
        let s = BorderedMips::new(&CubeMips {
            levels: vec![cube.clone()],
        });
        let mut rng = Pcg32::new(2, 2);
        let mut dirs: Vec<Vec3> = (0..20000)
            .map(|_| {
                Vec3::new(
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                    rng.next_f32() - 0.5,
                )
            })
            .filter(|d| d.length() > 1e-3)
            .collect();
        dirs.extend([
            Vec3::ONE,
            Vec3::new(1.0, 1.0, 0.3),
            Vec3::new(-1.0, 0.2, 1.0),
            Vec3::new(1.0, -1.0, -1.0),
        ]);
        let mut worst = 0.0f32;
        for d in dirs {
            let a = s.bilinear(d, 0);
            let b = cube.sample_bilinear(d);
            for k in 0..3 {
                worst = worst.max((a[k] - b[k]).abs());
            }
        }
        eprintln!("bordered bilinear vs core sample_bilinear: worst difference {worst:.2e}");
        assert!(worst < 1e-5, "{worst}");
    }

    #[test]
    fn every_padded_texel_is_the_wrapped_texel_bit_for_bit() {
        // The interior is copied and only the border re-projected: both must be what
        // `texel_wrapped` gives at every padded coordinate, down to the 1² level.
        for n in [1, 2, 3, 8] {
            let cube = noisy_cube(n, 10 + n as u64);
            let level = BorderedLevel::new(&cube);
            for face in Face::ALL {
                for y in 0..n + 2 {
                    for x in 0..n + 2 {
                        let want = cube.texel_wrapped(face, x as isize - 1, y as isize - 1);
                        let got = level.at(face as usize, x, y);
                        assert_eq!(
                            got.map(f32::to_bits),
                            want.map(f32::to_bits),
                            "n {n} {face:?} ({x}, {y})"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn texel_centres_read_back_exactly_and_constant_stays_constant() {
        let cube = noisy_cube(5, 3);
        let s = BorderedMips::new(&CubeMips {
            levels: vec![cube.clone()],
        });
        for face in Face::ALL {
            for j in 0..5 {
                for i in 0..5 {
                    let a = s.bilinear(texel_direction(face, i, j, 5), 0);
                    let b = cube.texel(face, i, j);
                    for k in 0..3 {
                        assert!((a[k] - b[k]).abs() < 1e-5);
                    }
                }
            }
        }
        let s = BorderedMips::new(&CubeMips::build(Cubemap::constant(16, [3.0, 1.0, 0.25]), 1));
        let mut rng = Pcg32::new(4, 4);
        for _ in 0..1000 {
            let d = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            );
            let m = (rng.next_u32() % 5) as usize;
            assert_eq!(s.trilinear(d, m, rng.next_f32()), [3.0, 1.0, 0.25]);
        }
    }

    #[test]
    fn trilinear_blends_levels_and_clamps() {
        let s = BorderedMips::new(&CubeMips::build(noisy_cube(8, 4), 1));
        let d = Vec3::new(0.3, -0.2, 0.9);
        let (a, b) = (s.bilinear(d, 1), s.bilinear(d, 2));
        for t in [s.trilinear(d, 1, 0.25), s.sample(d, 1.25)] {
            for k in 0..3 {
                assert!((t[k] - (0.75 * a[k] + 0.25 * b[k])).abs() < 1e-5);
            }
        }
        // Beyond the top the 1×1 level is returned; below 0 the base.
        assert_eq!(s.sample(d, 99.0), s.bilinear(d, 3));
        assert_eq!(s.sample(d, -3.0), s.bilinear(d, 0));
        assert_eq!(s.trilinear(d, 3, 0.5), s.bilinear(d, 3));
        assert_eq!((s.num_levels(), s.max_lod(), s.size()), (4, 3, 8));
        assert_eq!(s.sizes(), vec![8, 4, 2, 1]);
        assert_eq!(s.chain_bytes(12), 6 * 12 * (64 + 16 + 4 + 1));
    }
}
