//! Fast seamless trilinear lookups in a cube mip chain for the E0 estimator: every face is
//! stored with a one-texel border copied from its neighbours, so a bilinear tap never
//! branches on face edges. Matches `Cubemap::sample_bilinear` (same border re-projection).

use glam::Vec3;
use ibl_core::cube::{face_texel_index, texel_coord, CubeMips, Face};
use ibl_core::Rgb;

/// One padded level: six faces of (n+2)² RGB texels, face-major.
#[derive(Clone, Debug)]
struct Level {
    n: usize,
    data: Vec<[f32; 3]>,
}

impl Level {
    fn stride(&self) -> usize {
        self.n + 2
    }

    #[inline]
    fn at(&self, face: usize, x: usize, y: usize) -> [f32; 3] {
        let s = self.stride();
        self.data[face * s * s + y * s + x]
    }

    /// Bilinear tap at face coordinates (sc, tc) ∈ [−1, 1]² of `face`.
    #[inline]
    fn bilinear(&self, face: usize, sc: f32, tc: f32) -> [f32; 3] {
        let n = self.n as f32;
        // Texel space with centres at integers, shifted by the border: x ∈ [0.5, n+0.5].
        let x = ((sc + 1.0) * 0.5 * n + 0.5).clamp(0.0, n + 0.999);
        let y = ((tc + 1.0) * 0.5 * n + 0.5).clamp(0.0, n + 0.999);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let (x0, y0) = (x0 as usize, y0 as usize);
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

/// A cube mip chain prepared for trilinear sampling by direction and level of detail.
#[derive(Clone, Debug)]
pub struct MipSampler {
    levels: Vec<Level>,
    /// log2 of the base level's texel solid angle at a face centre ≈ 4π / (6 n²).
    base_log2_texel_sa: f32,
}

impl MipSampler {
    /// Pads every level of `mips` with its neighbours' texels.
    pub fn new(mips: &CubeMips) -> Self {
        let levels = mips
            .levels
            .iter()
            .map(|cube| {
                let n = cube.size;
                let s = n + 2;
                let mut data = vec![[0.0f32; 3]; 6 * s * s];
                for face in Face::ALL {
                    for y in 0..s {
                        for x in 0..s {
                            let (i, j) = (x as isize - 1, y as isize - 1);
                            let t = if i >= 0 && j >= 0 && (i as usize) < n && (j as usize) < n {
                                cube.texel(face, i as usize, j as usize)
                            } else {
                                // The border tap's direction lies past the edge: its major
                                // axis names the neighbouring face (as Cubemap::sample_bilinear).
                                let sc = (2.0 * (i as f32 + 0.5)) / n as f32 - 1.0;
                                let tc = (2.0 * (j as f32 + 0.5)) / n as f32 - 1.0;
                                let (f2, s2, t2) = Face::from_direction(face.direction(sc, tc));
                                let (i2, j2) = face_texel_index(s2, t2, n);
                                cube.texel(f2, i2, j2)
                            };
                            data[face as usize * s * s + y * s + x] = t;
                        }
                    }
                }
                Level { n, data }
            })
            .collect();
        let n0 = mips.levels[0].size as f32;
        MipSampler {
            levels,
            base_log2_texel_sa: (4.0 * std::f32::consts::PI / (6.0 * n0 * n0)).log2(),
        }
    }

    /// Number of levels.
    pub fn num_levels(&self) -> usize {
        self.levels.len()
    }

    /// log2 of the base texel's solid angle, the offset of the filtered-importance-sampling lod.
    pub fn base_log2_texel_solid_angle(&self) -> f32 {
        self.base_log2_texel_sa
    }

    /// Bilinear sample of one level (seamless).
    pub fn sample_level(&self, d: Vec3, level: usize) -> Rgb {
        let (face, sc, tc) = Face::from_direction(d);
        self.levels[level.min(self.levels.len() - 1)].bilinear(face as usize, sc, tc)
    }

    /// Trilinear sample: bilinear in the two levels around `lod` (clamped to the chain) and a
    /// linear blend between them. `d` need not be normalised.
    #[inline]
    pub fn sample(&self, d: Vec3, lod: f32) -> Rgb {
        let (face, sc, tc) = Face::from_direction(d);
        let f = face as usize;
        let top = (self.levels.len() - 1) as f32;
        let lod = lod.clamp(0.0, top);
        let l0 = lod.floor();
        let t = lod - l0;
        let l0 = l0 as usize;
        let a = self.levels[l0].bilinear(f, sc, tc);
        if t <= 0.0 || l0 + 1 >= self.levels.len() {
            return a;
        }
        let b = self.levels[l0 + 1].bilinear(f, sc, tc);
        [
            a[0] + (b[0] - a[0]) * t,
            a[1] + (b[1] - a[1]) * t,
            a[2] + (b[2] - a[2]) * t,
        ]
    }

    /// Bytes of the unpadded chain at `bytes_per_texel` (for memory reports).
    pub fn chain_bytes(&self, bytes_per_texel: usize) -> usize {
        self.levels
            .iter()
            .map(|l| 6 * l.n * l.n * bytes_per_texel)
            .sum()
    }

    /// Face sizes of the chain, largest first.
    pub fn sizes(&self) -> Vec<usize> {
        self.levels.iter().map(|l| l.n).collect()
    }
}

/// Direction through the centre of texel (i, j): re-exported so callers need not import cube.
#[inline]
pub fn texel_centre(face: Face, i: usize, j: usize, n: usize) -> Vec3 {
    face.direction(texel_coord(i, n), texel_coord(j, n))
        .normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::sampling::Pcg32;
    use ibl_core::Cubemap;

    fn noisy_cube(n: usize, seed: u64) -> Cubemap {
        let mut rng = Pcg32::new(seed, 3);
        let mut c = Cubemap::new(n);
        for f in &mut c.faces {
            for v in &mut f.data {
                *v = rng.next_f32() * 4.0;
            }
        }
        c
    }

    #[test]
    fn bilinear_matches_the_core_sampler_everywhere() {
        let cube = noisy_cube(9, 1);
        let mips = CubeMips::build(cube.clone(), 1);
        let s = MipSampler::new(&mips);
        let mut rng = Pcg32::new(2, 2);
        let mut worst = 0.0f32;
        for _ in 0..20_000 {
            let d = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            );
            if d.length() < 1e-3 {
                continue;
            }
            let a = s.sample(d, 0.0);
            let b = cube.sample_bilinear(d);
            for k in 0..3 {
                worst = worst.max((a[k] - b[k]).abs());
            }
        }
        eprintln!("max |padded − core bilinear| = {worst:.2e}");
        assert!(worst < 1e-4);
    }

    #[test]
    fn trilinear_blends_levels_and_clamps() {
        let mips = CubeMips::build(noisy_cube(8, 4), 1);
        let s = MipSampler::new(&mips);
        let d = Vec3::new(0.3, -0.2, 0.9);
        let a = s.sample_level(d, 1);
        let b = s.sample_level(d, 2);
        let m = s.sample(d, 1.25);
        for k in 0..3 {
            assert!((m[k] - (0.75 * a[k] + 0.25 * b[k])).abs() < 1e-5);
        }
        // Beyond the top the 1×1 level is returned; below 0 the base.
        assert_eq!(s.sample(d, 99.0), s.sample_level(d, 3));
        assert_eq!(s.sample(d, -3.0), s.sample_level(d, 0));
        assert_eq!(s.num_levels(), 4);
        assert_eq!(s.chain_bytes(12), 6 * 12 * (64 + 16 + 4 + 1));
    }
}
