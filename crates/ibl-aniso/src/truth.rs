//! Ground truth of anisotropic specular reflection under an environment cube:
//!
//!   L_o = ∫ f(v, l) L(l) (n·l) dl = F0·E0 + (1−F0)·E1 (Schlick F, as `ibl_shexp::truth`),
//!
//! with f the microfacet BRDF D G2 F / (4 (n·v)(n·l)) of anisotropic GGX (Heitz 2014 eq. 18,
//! height-correlated G2, eq. 99) or the Ashikhmin–Shirley BRDF p_h F / (4 (v·h) max(n·v, n·l))
//! (Marcolongo 2020 §2.4). The environment is the cube at its native resolution read at the
//! nearest texel: the piecewise-constant environment the project defines.
//!
//! Two independent estimators:
//! - [`mc_truth`]: Monte Carlo. GGX draws visible normals (Heitz 2018) and weighs
//!   G2/G1(v); AS draws h ~ p_h exactly and weighs (n·l)/max(n·v, n·l). Each pixel runs
//!   [`BATCHES`] independently rotated Hammersley sets (Cranley–Patterson shifts from a hash of
//!   the pixel's seed): the result is bit-identical for any thread count and the spread of the
//!   batch means gives the standard error.
//! - [`texel_truth`]: the sum over every texel of a (small) cube, exact for the
//!   piecewise-constant cube up to the BRDF's variation inside a texel.

use crate::material::Material;
use crate::scene::Frame;
use glam::{DVec3, Vec3};
use ibl_brdf::microfacet::Microfacet;
use ibl_brdf::{reflect, AshikhminShirley, Beckmann, Ggx, Gtr, TangentTransform, Transformed};
use ibl_core::cube::{face_texel_index, texel_direction, texel_solid_angle, Face};
use ibl_core::sampling::{hammersley, Pcg32};
use ibl_core::Cubemap;
use serde::Serialize;

/// Independent batches of [`mc_truth`] (their means give the standard error).
pub const BATCHES: u32 = 16;

/// E0 and E1 (RGB) with their standard errors.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct TruthValue {
    /// ∫ f(F=1) L (n·l) dl.
    pub e0: [f64; 3],
    /// ∫ f(F=(1−v·h)⁵) L (n·l) dl.
    pub e1: [f64; 3],
    /// Standard error of e0 (0 for the texel sum).
    pub se0: [f64; 3],
    /// Standard error of e1.
    pub se1: [f64; 3],
}

impl TruthValue {
    /// Radiance for Schlick F0: F0·E0 + (1−F0)·E1.
    pub fn radiance(&self, f0: f64) -> [f64; 3] {
        std::array::from_fn(|k| f0 * self.e0[k] + (1.0 - f0) * self.e1[k])
    }

    /// Standard error of [`TruthValue::radiance`] (E0 and E1 share samples, so the errors are
    /// bounded by the sum).
    pub fn radiance_se(&self, f0: f64) -> [f64; 3] {
        std::array::from_fn(|k| f0 * self.se0[k] + (1.0 - f0) * self.se1[k])
    }
}

/// Radiance of the nearest texel of `cube` in direction d (the project's piecewise-constant
/// environment).
#[inline]
pub fn nearest(cube: &Cubemap, d: Vec3) -> [f32; 3] {
    let (face, sc, tc) = Face::from_direction(d);
    let (i, j) = face_texel_index(sc, tc, cube.size);
    cube.texel(face, i, j)
}

/// Calls `f` with the microfacet distribution of `mat` (None for Ashikhmin–Shirley, whose
/// BRDF is not of the D·G2 form).
pub fn with_microfacet<R>(mat: &Material, f: impl FnOnce(&dyn Microfacet) -> R) -> Option<R> {
    match *mat {
        Material::Ggx { alpha_t, alpha_b } => Some(f(&Ggx::new(alpha_t, alpha_b))),
        Material::Beckmann { alpha_t, alpha_b } => Some(f(&Beckmann::new(alpha_t, alpha_b))),
        Material::TransformedGtr {
            alpha_t,
            alpha_b,
            gamma,
        } => {
            let m = TangentTransform::new((alpha_t / alpha_b) as f64, 0.0, 0.0, 1.0);
            Some(f(&Transformed::new(Gtr::new(alpha_b, gamma), m)))
        }
        Material::AshikhminShirley { .. } => None,
    }
}

/// One microfacet sample: visible normals where the distribution has a sampler (weight
/// G2/G1(v), Heitz 2018 §2), else m ~ D(m)(n·m) (weight f·(n·l)/p_l = G2 (v·m)/((n·v)(n·m)),
/// Walter et al. 2007 eq. 38). Returns (weight, Schlick tail, local l).
#[inline]
fn sample_microfacet(
    g: &dyn Microfacet,
    vl: Vec3,
    lambda_v: f32,
    u1: f32,
    u2: f32,
) -> Option<(f64, f64, Vec3)> {
    if let Some(m) = g.sample_visible(vl, u1, u2) {
        let l = reflect(vl, m);
        if l.z <= 0.0 {
            return None;
        }
        let w = (1.0 + lambda_v as f64) / (1.0 + lambda_v as f64 + g.lambda(l) as f64);
        let vh = (vl.dot(m) as f64).clamp(0.0, 1.0);
        return Some((w, (1.0 - vh).powi(5), l));
    }
    let m = g.sample_d(u1, u2);
    let vh = vl.dot(m);
    if vh <= 0.0 || m.z <= 0.0 {
        return None;
    }
    let l = reflect(vl, m);
    if l.z <= 0.0 {
        return None;
    }
    let w = g.g2(vl, l, m) as f64 * vh as f64 / (vl.z as f64 * m.z as f64);
    Some((w, (1.0 - (vh as f64).min(1.0)).powi(5), l))
}

/// One sample's contribution: (weight for E0, Schlick tail χ = (1−v·h)⁵, local l), or None.
#[inline]
fn sample(mat: &Material, vl: Vec3, lambda_v: f32, u1: f32, u2: f32) -> Option<(f64, f64, Vec3)> {
    match *mat {
        Material::AshikhminShirley { nu, nv } => {
            let a = AshikhminShirley::new(nu, nv);
            let h = a.sample(u1 as f64, u2 as f64).h;
            let v = DVec3::new(vl.x as f64, vl.y as f64, vl.z as f64);
            let vh = v.dot(h);
            if vh <= 0.0 {
                return None;
            }
            let l = 2.0 * vh * h - v;
            if l.z <= 0.0 {
                return None;
            }
            // p_h F/(4 v·h max) · (n·l) / (p_h/(4 v·h)) = F (n·l)/max(n·v, n·l).
            let w = l.z / v.z.max(l.z);
            Some((w, (1.0 - vh.min(1.0)).powi(5), l.as_vec3()))
        }
        _ => with_microfacet(mat, |g| sample_microfacet(g, vl, lambda_v, u1, u2)).flatten(),
    }
}

/// Monte Carlo truth at one pixel: `samples` (rounded up to a multiple of [`BATCHES`]) over
/// `cube` at its native resolution, nearest texel. `v` towards the eye (world); zeros when
/// n·v ≤ 0. `seed` fixes the rotations (use the pixel's index).
pub fn mc_truth(
    cube: &Cubemap,
    frame: &Frame,
    v: Vec3,
    mat: &Material,
    samples: u32,
    seed: u64,
) -> TruthValue {
    let vl = frame.to_local(v);
    if vl.z <= 0.0 {
        return TruthValue::default();
    }
    let vl = vl.normalize();
    let lambda_v = with_microfacet(mat, |g| g.lambda(vl)).unwrap_or(0.0);
    let per = samples.div_ceil(BATCHES).max(1);
    let mut rng = Pcg32::new(seed, 0x5eed_a115);
    let mut means = [[0.0f64; 6]; BATCHES as usize];
    for mean in means.iter_mut() {
        let (s1, s2) = (rng.next_f32(), rng.next_f32());
        let mut acc = [0.0f64; 6];
        for i in 0..per {
            let (h1, h2) = hammersley(i, per);
            let (u1, u2) = ((h1 + s1).fract(), (h2 + s2).fract());
            let Some((w, chi, l)) = sample(mat, vl, lambda_v, u1, u2) else {
                continue;
            };
            let c = nearest(cube, frame.to_world(l));
            for k in 0..3 {
                acc[k] += w * c[k] as f64;
                acc[3 + k] += w * chi * c[k] as f64;
            }
        }
        for (m, a) in mean.iter_mut().zip(acc) {
            *m = a / per as f64;
        }
    }
    let b = BATCHES as f64;
    let mut out = TruthValue::default();
    for k in 0..6 {
        let mu = means.iter().map(|m| m[k]).sum::<f64>() / b;
        let var = means.iter().map(|m| (m[k] - mu).powi(2)).sum::<f64>() / (b - 1.0);
        let se = (var / b).sqrt();
        if k < 3 {
            out.e0[k] = mu;
            out.se0[k] = se;
        } else {
            out.e1[k - 3] = mu;
            out.se1[k - 3] = se;
        }
    }
    out
}

/// The BRDF·(n·l) for F = 1 and the Schlick tail at local (v, l); 0 below either horizon.
pub fn brdf_cos(mat: &Material, vl: Vec3, ll: Vec3) -> (f64, f64) {
    if vl.z <= 0.0 || ll.z <= 0.0 {
        return (0.0, 0.0);
    }
    let hs = vl + ll;
    if hs.length_squared() <= 1e-20 {
        return (0.0, 0.0);
    }
    let h = hs.normalize();
    let vh = (vl.dot(h) as f64).clamp(0.0, 1.0);
    let chi = (1.0 - vh).powi(5);
    let f = match *mat {
        Material::AshikhminShirley { nu, nv } => {
            let v = DVec3::new(vl.x as f64, vl.y as f64, vl.z as f64);
            let l = DVec3::new(ll.x as f64, ll.y as f64, ll.z as f64);
            AshikhminShirley::new(nu, nv).brdf(v, l, 1.0) * l.z
        }
        _ => with_microfacet(mat, |g| {
            g.d(h) as f64 * g.g2(vl, ll, h) as f64 / (4.0 * vl.z as f64)
        })
        .unwrap_or(0.0),
    };
    (f, f * chi)
}

/// Texel-sum truth: Σ over every texel of `cube` of f·(n·l)·L·Ω at the texel centre.
pub fn texel_truth(cube: &Cubemap, frame: &Frame, v: Vec3, mat: &Material) -> TruthValue {
    let vl = frame.to_local(v);
    let mut out = TruthValue::default();
    if vl.z <= 0.0 {
        return out;
    }
    let vl = vl.normalize();
    let n = cube.size;
    for face in Face::ALL {
        for j in 0..n {
            for i in 0..n {
                let d = texel_direction(face, i, j, n);
                let ll = frame.to_local(d);
                let (f, ft) = brdf_cos(mat, vl, ll);
                if f == 0.0 {
                    continue;
                }
                let sa = texel_solid_angle(i, j, n);
                let c = cube.texel(face, i, j);
                for k in 0..3 {
                    out.e0[k] += f * sa * c[k] as f64;
                    out.e1[k] += ft * sa * c[k] as f64;
                }
            }
        }
    }
    out
}

/// Directional albedo ∫ D G2 /(4 n·v) dl of a microfacet distribution by Gauss–Legendre
/// quadrature over the (u1, u2) square of its D(m)(n·m) sampler (`Microfacet::sample_d`): the
/// integrand G2 (v·m)/((n·v)(n·m)) is bounded there. Independent of the VNDF route the truth
/// takes.
pub fn albedo_quadrature(g: &dyn Microfacet, vl: Vec3, nodes: usize) -> f64 {
    let gl = ibl_brdf::quadrature::gauss_legendre(nodes);
    let mut sum = 0.0;
    for &(x1, w1) in &gl {
        for &(x2, w2) in &gl {
            let (u1, u2) = (0.5 * (x1 + 1.0), 0.5 * (x2 + 1.0));
            let m = g.sample_d(u1 as f32, u2 as f32);
            let vm = vl.dot(m);
            if vm <= 0.0 || m.z <= 0.0 {
                continue;
            }
            let l = reflect(vl, m);
            if l.z <= 0.0 {
                continue;
            }
            // ∫ D G2/(4 nv) |dl/dm| dm = ∫ D G2 (v·m)/nv dm, and dm = du/(D(m) m.z).
            let val = g.g2(vl, l, m) as f64 * vm as f64 / (vl.z as f64 * m.z as f64);
            sum += 0.25 * w1 * w2 * val;
        }
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> Frame {
        let n = Vec3::new(0.2, 0.9, 0.3).normalize();
        let t = Vec3::Y.cross(n).normalize();
        Frame {
            t,
            b: n.cross(t),
            n,
        }
    }

    fn sky(d: Vec3) -> [f32; 3] {
        let sun = Vec3::new(0.5, 0.8, 0.2).normalize();
        let s = (8.0 * (d.dot(sun) - 1.0)).exp() * 5.0;
        [
            0.3 + 0.5 * d.y.max(0.0) + s,
            0.4 + 0.2 * d.x + s,
            0.6 + 0.3 * d.z + s,
        ]
    }

    fn view(f: &Frame, theta_deg: f32, phi_deg: f32) -> Vec3 {
        let (st, ct) = theta_deg.to_radians().sin_cos();
        let (sp, cp) = phi_deg.to_radians().sin_cos();
        f.to_world(Vec3::new(st * cp, st * sp, ct))
    }

    #[test]
    fn furnace_equals_the_directional_albedo() {
        // Constant environment: E0 = the directional albedo (quadrature, an independent route).
        let cube = Cubemap::constant(8, [1.0; 3]);
        let f = frame();
        let mut worst: f64 = 0.0;
        let mut mats: Vec<Material> = [(0.4f32, 0.0f32), (0.5, 0.8), (0.8, 0.5), (1.0, 0.9)]
            .iter()
            .map(|&(r, eta)| Material::ggx_kc(r, eta))
            .collect();
        mats.push(Material::Beckmann {
            alpha_t: 0.5,
            alpha_b: 0.2,
        });
        mats.push(Material::TransformedGtr {
            alpha_t: 0.6,
            alpha_b: 0.3,
            gamma: 1.5,
        });
        mats.push(Material::TransformedGtr {
            alpha_t: 0.4,
            alpha_b: 0.2,
            gamma: 3.0,
        });
        for mat in mats {
            for (th, ph) in [(0.0, 0.0), (45.0, 30.0), (75.0, 100.0)] {
                let v = view(&f, th, ph);
                let t = mc_truth(&cube, &f, v, &mat, 4096, 7);
                let q =
                    with_microfacet(&mat, |g| albedo_quadrature(g, f.to_local(v), 256)).unwrap();
                let err = (t.e0[0] - q).abs();
                worst = worst.max(err);
                assert!(
                    err < 2e-3 + 4.0 * t.se0[0],
                    "{mat:?} θ {th}: MC {} ± {} vs {q}",
                    t.e0[0],
                    t.se0[0]
                );
            }
        }
        eprintln!("furnace: worst |MC − quadrature| {worst:.2e}");
        // AS: E0 of a constant environment is E[(n·l)/max(n·v, n·l)] ≤ 1, with E1 < E0.
        let t = mc_truth(
            &cube,
            &f,
            view(&f, 30.0, 10.0),
            &Material::AshikhminShirley {
                nu: 100.0,
                nv: 10.0,
            },
            4096,
            3,
        );
        assert!(
            t.e0[0] > 0.8 && t.e0[0] <= 1.0 && t.e1[0] < t.e0[0],
            "{t:?}"
        );
    }

    #[test]
    fn monte_carlo_agrees_with_the_texel_sum() {
        let cube = Cubemap::from_fn(48, sky);
        let f = frame();
        for (mat, th) in [
            (Material::ggx_kc(0.6, 0.5), 20.0),
            (Material::ggx_kc(0.8, -0.7), 60.0),
            (Material::AshikhminShirley { nu: 30.0, nv: 8.0 }, 40.0),
            (
                Material::Beckmann {
                    alpha_t: 0.6,
                    alpha_b: 0.25,
                },
                30.0,
            ),
            (
                Material::TransformedGtr {
                    alpha_t: 0.7,
                    alpha_b: 0.35,
                    gamma: 1.5,
                },
                45.0,
            ),
        ] {
            let v = view(&f, th, 50.0);
            let mc = mc_truth(&cube, &f, v, &mat, 1 << 14, 11);
            let tx = texel_truth(&cube, &f, v, &mat);
            for k in 0..3 {
                let d = (mc.e0[k] - tx.e0[k]).abs();
                // Texel-centre quadrature error of a 48² cube (≈ 1%) plus 4 standard errors.
                assert!(
                    d < 0.01 * tx.e0[k] + 4.0 * mc.se0[k],
                    "{mat:?} ch {k}: MC {} ± {} texels {}",
                    mc.e0[k],
                    mc.se0[k],
                    tx.e0[k]
                );
                let d1 = (mc.e1[k] - tx.e1[k]).abs();
                assert!(d1 < 0.01 * tx.e0[k] + 4.0 * mc.se1[k] + 1e-4);
            }
        }
    }

    #[test]
    fn symmetric_under_tangent_flip_and_axis_swap() {
        let cube = Cubemap::from_fn(32, sky);
        let f = frame();
        let v = view(&f, 50.0, 20.0);
        let mat = Material::ggx_kc(0.5, 0.8);
        let a = mc_truth(&cube, &f, v, &mat, 4096, 5);
        let b = mc_truth(&cube, &f.flipped(), v, &mat, 4096, 5);
        let (at, ab) = mat.ggx_alphas().unwrap();
        let swapped = Material::Ggx {
            alpha_t: ab,
            alpha_b: at,
        };
        let c = mc_truth(&cube, &f.turned(), v, &swapped, 4096, 9);
        for k in 0..3 {
            // t → −t mirrors every sample: equal up to rounding and the odd texel boundary.
            assert!(
                (a.e0[k] - b.e0[k]).abs() < 3.0 * a.se0[k] + 1e-6,
                "{a:?} {b:?}"
            );
            // η → −η with t ↔ b is the same lobe drawn differently: equal within the errors.
            let s = (a.se0[k].powi(2) + c.se0[k].powi(2)).sqrt();
            assert!((a.e0[k] - c.e0[k]).abs() < 4.0 * s, "{a:?} {c:?}");
        }
    }

    #[test]
    fn deterministic_and_edge_cases_finite() {
        let cube = Cubemap::from_fn(16, sky);
        let f = frame();
        let v = view(&f, 89.0, 0.0);
        for mat in [
            Material::ggx_kc(0.0, 0.0),
            Material::ggx_kc(1.0, 0.99),
            Material::ggx_kc(0.3, -0.99),
            Material::AshikhminShirley {
                nu: 20000.0,
                nv: 70.0,
            },
        ] {
            let a = mc_truth(&cube, &f, v, &mat, 256, 1);
            let b = mc_truth(&cube, &f, v, &mat, 256, 1);
            assert_eq!(a, b);
            assert!(
                a.e0.iter()
                    .chain(&a.e1)
                    .chain(&a.se0)
                    .all(|x| x.is_finite()),
                "{mat:?} {a:?}"
            );
        }
        // Below the horizon: zeros.
        let below = mc_truth(&cube, &f, -f.n, &Material::ggx_kc(0.5, 0.5), 64, 1);
        assert_eq!(below, TruthValue::default());
    }
}
