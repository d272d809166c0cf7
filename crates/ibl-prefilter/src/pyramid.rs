//! The source pyramid filtered importance sampling reads: box-filtered cube mips stored with a
//! one-texel border copied from the neighbouring faces, so a bilinear tap never branches on
//! face edges, and trilinear reads between two mips.

use glam::Vec3;
use ibl_core::cube::{face_texel_index, Cubemap, Face};
use ibl_core::{CubeMips, Rgb};

/// One mip with bordered faces: (n+2)² texels per face, RGB, face after face.
struct BorderedCube {
    n: usize,
    data: Vec<f32>,
}

impl BorderedCube {
    /// Copies the cube and fills each border texel from the face its direction lands on,
    /// the same re-projection as `Cubemap::sample_bilinear`, so reads stay seamless.
    fn new(cube: &Cubemap) -> Self {
        let n = cube.size;
        let s = n + 2;
        let mut data = vec![0.0f32; 6 * s * s * 3];
        for face in Face::ALL {
            let base = face as usize * s * s;
            for pj in 0..s {
                for pi in 0..s {
                    let (i, j) = (pi as isize - 1, pj as isize - 1);
                    let c = if i >= 0 && j >= 0 && (i as usize) < n && (j as usize) < n {
                        cube.texel(face, i as usize, j as usize)
                    } else {
                        let sc = (2.0 * (i as f32 + 0.5)) / n as f32 - 1.0;
                        let tc = (2.0 * (j as f32 + 0.5)) / n as f32 - 1.0;
                        let (f2, s2, t2) = Face::from_direction(face.direction(sc, tc));
                        let (i2, j2) = face_texel_index(s2, t2, n);
                        cube.texel(f2, i2, j2)
                    };
                    let o = (base + pj * s + pi) * 3;
                    data[o..o + 3].copy_from_slice(&c);
                }
            }
        }
        BorderedCube { n, data }
    }

    /// Bilinear tap at face coordinates (sc, tc) ∈ [−1, 1]² of `face`.
    #[inline]
    fn bilinear(&self, face: usize, sc: f32, tc: f32) -> [f32; 3] {
        let n = self.n;
        let s = n + 2;
        // Texel centres sit at (k + 0.5) in face units; the border shifts indices by one.
        let x = (sc + 1.0) * 0.5 * n as f32 + 0.5;
        let y = (tc + 1.0) * 0.5 * n as f32 + 0.5;
        let x0 = (x.floor() as usize).min(n);
        let y0 = (y.floor() as usize).min(n);
        let fx = (x - x0 as f32).clamp(0.0, 1.0);
        let fy = (y - y0 as f32).clamp(0.0, 1.0);
        let o = ((face * s + y0) * s + x0) * 3;
        let row0 = &self.data[o..o + 6];
        let row1 = &self.data[o + s * 3..o + s * 3 + 6];
        let mut out = [0.0f32; 3];
        for k in 0..3 {
            let top = row0[k] + (row0[k + 3] - row0[k]) * fx;
            let bot = row1[k] + (row1[k + 3] - row1[k]) * fx;
            out[k] = top + (bot - top) * fy;
        }
        out
    }
}

/// Box-filtered mips of the source (level 0 the finest), read seamlessly and trilinearly.
pub struct SourcePyramid {
    levels: Vec<BorderedCube>,
}

impl SourcePyramid {
    pub fn new(mips: &CubeMips) -> Self {
        SourcePyramid {
            levels: mips.levels.iter().map(BorderedCube::new).collect(),
        }
    }

    /// Face size of level 0.
    pub fn size(&self) -> usize {
        self.levels[0].n
    }

    /// Index of the coarsest level.
    pub fn max_lod(&self) -> u32 {
        (self.levels.len() - 1) as u32
    }

    /// Seamless bilinear read of level `mip` in direction `d` (need not be normalised).
    pub fn bilinear(&self, d: Vec3, mip: u32) -> Rgb {
        let (face, sc, tc) = Face::from_direction(d);
        self.levels[mip as usize].bilinear(face as usize, sc, tc)
    }

    /// Trilinear read: bilinear on mips `mip` and `mip + 1`, blended by `frac`.
    #[inline]
    pub fn trilinear(&self, d: Vec3, mip: u32, frac: f32) -> Rgb {
        let (face, sc, tc) = Face::from_direction(d);
        let m = mip as usize;
        let a = self.levels[m].bilinear(face as usize, sc, tc);
        if frac <= 0.0 || m + 1 >= self.levels.len() {
            return a;
        }
        let b = self.levels[m + 1].bilinear(face as usize, sc, tc);
        [
            a[0] + (b[0] - a[0]) * frac,
            a[1] + (b[1] - a[1]) * frac,
            a[2] + (b[2] - a[2]) * frac,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::cube::texel_direction;
    use ibl_core::sampling::Pcg32;

    fn random_cube(n: usize, seed: u64) -> Cubemap {
        let mut rng = Pcg32::new(seed, 9);
        let mut c = Cubemap::new(n);
        for f in &mut c.faces {
            f.data.iter_mut().for_each(|v| *v = rng.next_f32() * 4.0);
        }
        c
    }

    #[test]
    fn bilinear_matches_core_seamless_sampler_everywhere() {
        // Random directions, including ones on edges and corners, against the core sampler.
        let cube = random_cube(7, 1);
        let pyr = SourcePyramid::new(&CubeMips {
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
            .collect();
        dirs.extend([
            Vec3::ONE,
            Vec3::new(1.0, 1.0, 0.3),
            Vec3::new(-1.0, 0.2, 1.0),
            Vec3::new(1.0, -1.0, -1.0),
        ]);
        let mut worst = 0.0f32;
        for d in dirs {
            let a = pyr.bilinear(d, 0);
            let b = cube.sample_bilinear(d);
            for k in 0..3 {
                worst = worst.max((a[k] - b[k]).abs());
            }
        }
        eprintln!("bordered bilinear vs core sample_bilinear: worst difference {worst:.2e}");
        assert!(worst < 1e-5, "{worst}");
    }

    #[test]
    fn texel_centres_read_back_exactly_and_constant_stays_constant() {
        let cube = random_cube(5, 3);
        let pyr = SourcePyramid::new(&CubeMips {
            levels: vec![cube.clone()],
        });
        for face in Face::ALL {
            for j in 0..5 {
                for i in 0..5 {
                    let a = pyr.bilinear(texel_direction(face, i, j, 5), 0);
                    let b = cube.texel(face, i, j);
                    for k in 0..3 {
                        assert!((a[k] - b[k]).abs() < 1e-5);
                    }
                }
            }
        }
        let mips = CubeMips::build(Cubemap::constant(16, [3.0, 1.0, 0.25]), 1);
        let pyr = SourcePyramid::new(&mips);
        let mut rng = Pcg32::new(4, 4);
        for _ in 0..1000 {
            let d = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            );
            let m = rng.next_u32() % 5;
            assert_eq!(pyr.trilinear(d, m, rng.next_f32()), [3.0, 1.0, 0.25]);
        }
    }

    #[test]
    fn trilinear_blends_the_two_mips() {
        let mips = CubeMips::build(random_cube(8, 5), 1);
        let pyr = SourcePyramid::new(&mips);
        let d = Vec3::new(0.3, 0.7, -0.2);
        let a = pyr.bilinear(d, 1);
        let b = pyr.bilinear(d, 2);
        let t = pyr.trilinear(d, 1, 0.25);
        for k in 0..3 {
            assert!((t[k] - (0.75 * a[k] + 0.25 * b[k])).abs() < 1e-5);
        }
        assert_eq!(pyr.max_lod(), 3);
        assert_eq!(pyr.trilinear(d, 3, 0.5), pyr.bilinear(d, 3));
    }
}
