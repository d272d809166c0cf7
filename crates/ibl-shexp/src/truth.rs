//! Ground truth of the reflection integrals E0 and E1 (Silvennoinen et al. 2025 eqs. 6–7) by exact summation of
//! f_DV · L · (n·l) over every texel of a cube (texel-centre direction, exact texel solid angle):
//! the midpoint rule of the piecewise-constant environment, exact up to the variation of the
//! BRDF inside one texel (measured by comparing two cube sizes, see `eval`).

use glam::Vec3;
use ibl_brdf::fresnel::schlick_weight as schlick_tail;
use ibl_core::cube::{texel_direction, texel_solid_angle, Cubemap, Face};
use std::f32::consts::PI;

/// Texel directions and radiance × solid angle, structure-of-arrays for the summation loop.
#[derive(Clone, Debug)]
pub struct TexelSet {
    /// Face size of the source cube.
    pub size: usize,
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    /// L · Ω per channel.
    lw: [Vec<f32>; 3],
}

impl TexelSet {
    /// Every texel of `cube` with its direction and radiance × solid angle.
    pub fn from_cube(cube: &Cubemap) -> Self {
        let n = cube.size;
        let mut s = TexelSet {
            size: n,
            x: vec![],
            y: vec![],
            z: vec![],
            lw: [vec![], vec![], vec![]],
        };
        for face in Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    let d = texel_direction(face, i, j, n);
                    let sa = texel_solid_angle(i, j, n) as f32;
                    let c = cube.texel(face, i, j);
                    s.x.push(d.x);
                    s.y.push(d.y);
                    s.z.push(d.z);
                    for (lw, ck) in s.lw.iter_mut().zip(c) {
                        lw.push(ck * sa);
                    }
                }
            }
        }
        s
    }

    /// Texels in the set.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Whether the set has no texel.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// E0 and E1 at (n, v) for every α of `alphas`: `out[a] = (E0 rgb, E1 rgb)`.
    /// n, v unit, world space; n·v ≤ 0 gives zeros.
    pub fn e0_e1(&self, n: Vec3, v: Vec3, alphas: &[f32], out: &mut [([f64; 3], [f64; 3])]) {
        for o in out.iter_mut() {
            *o = ([0.0; 3], [0.0; 3]);
        }
        let nv = n.dot(v);
        if nv <= 0.0 {
            return;
        }
        // Per α constants: α², the view part of V's denominator.
        let consts: Vec<(f32, f32)> = alphas
            .iter()
            .map(|&a| (a * a, (nv * nv * (1.0 - a * a) + a * a).sqrt()))
            .collect();
        // f32 partial sums per chunk, promoted to f64 per chunk: 6·n² terms stay accurate.
        const CHUNK: usize = 256;
        let len = self.len();
        let mut part = vec![[0.0f32; 6]; alphas.len()];
        let mut start = 0;
        while start < len {
            let end = (start + CHUNK).min(len);
            for p in part.iter_mut() {
                *p = [0.0; 6];
            }
            for i in start..end {
                let l = Vec3::new(self.x[i], self.y[i], self.z[i]);
                let nl = n.dot(l);
                if nl <= 0.0 {
                    continue;
                }
                let vl = v.dot(l);
                // h = (v + l)/|v + l|: n·h and v·h without forming h.
                let len_h = (2.0 + 2.0 * vl).max(1e-12).sqrt();
                let nh = ((nv + nl) / len_h).max(0.0);
                let vh = ((1.0 + vl) / len_h).clamp(0.0, 1.0);
                let tail = schlick_tail(vh);
                let (l0, l1, l2) = (self.lw[0][i], self.lw[1][i], self.lw[2][i]);
                for (a, &(a2, gv_root)) in consts.iter().enumerate() {
                    let t = nh * nh * (a2 - 1.0) + 1.0;
                    let d = a2 / (PI * t * t);
                    let vis = 0.5 / (nl * gv_root + nv * (nl * nl * (1.0 - a2) + a2).sqrt());
                    let f = d * vis * nl;
                    let ft = f * tail;
                    let p = &mut part[a];
                    p[0] += f * l0;
                    p[1] += f * l1;
                    p[2] += f * l2;
                    p[3] += ft * l0;
                    p[4] += ft * l1;
                    p[5] += ft * l2;
                }
            }
            for (o, p) in out.iter_mut().zip(&part) {
                for k in 0..3 {
                    o.0[k] += p[k] as f64;
                    o.1[k] += p[3 + k] as f64;
                }
            }
            start = end;
        }
    }

    /// E0 alone at one α.
    pub fn e0(&self, n: Vec3, v: Vec3, alpha: f32) -> [f64; 3] {
        let mut out = [([0.0; 3], [0.0; 3])];
        self.e0_e1(n, v, &[alpha], &mut out);
        out[0].0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_brdf::ggx::f_dv;

    #[test]
    fn constant_cube_sums_to_the_albedo_integral() {
        // L = 1: E0 = ∫ f_DV (n·l), E1 = ∫ f_DV (1−v·h)⁵ (n·l): against a fine (cos θ, φ) grid.
        let set = TexelSet::from_cube(&Cubemap::constant(48, [1.0, 1.0, 1.0]));
        for (alpha, theta) in [(0.25f32, 0.1f32), (0.6, 1.0), (1.0, 1.4)] {
            let v = Vec3::new(theta.sin(), 0.0, theta.cos());
            let mut out = [([0.0; 3], [0.0; 3])];
            set.e0_e1(Vec3::Z, v, &[alpha], &mut out);
            let k = 500;
            let (mut q0, mut q1) = (0.0f64, 0.0f64);
            for a in 0..k {
                let z = (a as f64 + 0.5) / k as f64;
                let st = (1.0 - z * z).sqrt();
                for b in 0..2 * k {
                    let phi = std::f64::consts::PI * (b as f64 + 0.5) / k as f64;
                    let l = Vec3::new((st * phi.cos()) as f32, (st * phi.sin()) as f32, z as f32);
                    let f = (f_dv(v, l, alpha) * l.z) as f64;
                    q0 += f;
                    q1 += f * schlick_tail(v.dot((v + l).normalize())) as f64;
                }
            }
            let w = 2.0 * std::f64::consts::PI / (2 * k * k) as f64;
            let (q0, q1) = (q0 * w, q1 * w);
            eprintln!(
                "α={alpha} θ={theta}: cube E0 {:.5} vs {q0:.5}, E1 {:.5} vs {q1:.5}",
                out[0].0[0], out[0].1[0]
            );
            assert!((out[0].0[0] - q0).abs() < 3e-3 * q0.max(0.1));
            assert!((out[0].1[0] - q1).abs() < 3e-3 * q0.max(0.1));
        }
    }

    #[test]
    fn back_facing_view_gives_zero() {
        let set = TexelSet::from_cube(&Cubemap::constant(4, [1.0, 1.0, 1.0]));
        assert_eq!(set.e0(Vec3::Z, -Vec3::Z, 0.5), [0.0; 3]);
    }
}
