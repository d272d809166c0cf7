//! Scenes: an orthographic sphere seen from an azimuth and an elevation, with a per-pixel
//! shading frame (t, b, n) whose tangent comes from a `tpr-map` direction preset applied to the
//! sphere's "lathe" tangent (rings about +Y) or from a `tpr-map` file, and a normal perturbed by
//! a `quat-map` file (the whole tangent frame rotated by each texel's quaternion, Marcolongo
//! 2020 §3.4), both read at the surface's UV.

use crate::material::{Material, MIN_ALPHA};
use glam::Vec3;
use ibl_core::Image;
use ibl_material::direction::Preset;
use serde::Serialize;

/// A right-handed shading frame: t the tangent (α_t's axis), b = n × t, n the normal.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Frame {
    /// Tangent.
    pub t: Vec3,
    /// Bitangent n × t.
    pub b: Vec3,
    /// Normal.
    pub n: Vec3,
}

impl Frame {
    /// World → local (t, b, n) components.
    #[inline]
    pub fn to_local(&self, d: Vec3) -> Vec3 {
        Vec3::new(d.dot(self.t), d.dot(self.b), d.dot(self.n))
    }

    /// Local → world.
    #[inline]
    pub fn to_world(&self, l: Vec3) -> Vec3 {
        self.t * l.x + self.b * l.y + self.n * l.z
    }

    /// The frame with t → −t (and so b → −b): every anisotropic lobe is symmetric under it.
    pub fn flipped(&self) -> Frame {
        Frame {
            t: -self.t,
            b: -self.b,
            n: self.n,
        }
    }

    /// The frame turned by 90° about n: (t, b) → (b, −t). With α_t ↔ α_b (η → −η) it
    /// describes the same lobe.
    pub fn turned(&self) -> Frame {
        Frame {
            t: self.b,
            b: -self.t,
            n: self.n,
        }
    }
}

/// Orthographic camera for azimuth φ about +Y (φ = 0 looks from +Z) and elevation θ (degrees):
/// (right, up, towards-camera v).
pub fn camera(azimuth_deg: f32, elevation_deg: f32) -> (Vec3, Vec3, Vec3) {
    let (sp, cp) = azimuth_deg.to_radians().sin_cos();
    let (st, ct) = elevation_deg.clamp(-89.0, 89.0).to_radians().sin_cos();
    let v = Vec3::new(sp * ct, st, cp * ct);
    let right = Vec3::Y.cross(v).normalize();
    let up = v.cross(right);
    (right, up, v)
}

/// Normal of pixel (i, j) of an s×s image of the unit sphere (row 0 at the top), or `None`
/// outside the disc.
pub fn pixel_normal(i: usize, j: usize, s: usize, cam: (Vec3, Vec3, Vec3)) -> Option<Vec3> {
    let x = 2.0 * (i as f32 + 0.5) / s as f32 - 1.0;
    let y = 1.0 - 2.0 * (j as f32 + 0.5) / s as f32;
    let r2 = x * x + y * y;
    if r2 >= 1.0 {
        return None;
    }
    let z = (1.0 - r2).sqrt();
    Some((cam.0 * x + cam.1 * y + cam.2 * z).normalize())
}

/// A map read at the surface's UV, as a shader reads a texture: bilinear, u wrapping (the
/// sphere's seam), v clamped; row 0 is v = 0 (the top), texel centres at (i + ½)/W, as
/// `tpr-map` writes them.
#[derive(Clone, Debug)]
pub struct UvMap {
    /// The texels (at least 3 channels for a quaternion map, 2 for a tangent map).
    pub image: Image,
}

impl UvMap {
    /// Channels 0..K bilinearly at (u, v).
    pub fn sample<const K: usize>(&self, u: f64, v: f64) -> [f64; K] {
        let img = &self.image;
        let (w, h) = (img.width as f64, img.height as f64);
        let x = u.rem_euclid(1.0) * w - 0.5;
        let y = (v.clamp(0.0, 1.0) * h - 0.5).clamp(0.0, h - 1.0);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let wrap = |i: f64| (i.rem_euclid(w)) as usize;
        let row = |j: f64| (j.clamp(0.0, h - 1.0)) as usize;
        let at =
            |i: usize, j: usize, k: usize| img.data[(j * img.width + i) * img.channels + k] as f64;
        let (i0, i1, j0, j1) = (wrap(x0), wrap(x0 + 1.0), row(y0), row(y0 + 1.0));
        std::array::from_fn(|k| {
            let top = at(i0, j0, k) * (1.0 - fx) + at(i1, j0, k) * fx;
            let bot = at(i0, j1, k) * (1.0 - fx) + at(i1, j1, k) * fx;
            top * (1.0 - fy) + bot * fy
        })
    }
}

/// The per-pixel frame field of a scene: the tangent direction from a `tpr-map` preset or a
/// `tpr-map` file, and optionally normals perturbed by a `quat-map` file.
#[derive(Clone, Debug)]
pub struct Field {
    /// The tangent preset (used when `tpr` is `None`).
    pub preset: Preset,
    /// A `tpr-map` output: RG = the tangent's (x, y)·½ + ½ in the (t₀, b₀) plane (y up).
    pub tpr: Option<UvMap>,
    /// A `quat-map` output: RGB = q·½ + ½, q = (a, b, c) the rotation of the tangent frame
    /// onto the texel's frame (identity = (1, ½, ½)).
    pub quat: Option<UvMap>,
    /// Whether each pixel's GGX lobe comes from `tpr`'s B, A channels, and in which units.
    pub tpr_roughness: Option<TprRoughness>,
}

/// What a `tpr-map` file's B and A channels hold: the roughness along t and along b
/// (crates/ibl-material/src/tpr_map.rs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, serde::Deserialize)]
pub enum TprRoughness {
    /// Perceptual roughness r (α = r²): what `tpr-map` writes by default.
    R,
    /// The GGX α itself: what `tpr-map --store-alpha` writes (the thesis's convention).
    Alpha,
}

impl From<Preset> for Field {
    fn from(preset: Preset) -> Field {
        Field {
            preset,
            tpr: None,
            quat: None,
            tpr_roughness: None,
        }
    }
}

impl Field {
    /// The GGX lobe at UV (u, v) when the field reads it from the `tpr-map` file (B, A
    /// bilinearly, then squared for perceptual roughness, as a shader squares the texture's
    /// value), each α floored at [`MIN_ALPHA`] as [`Material::ggx_kc`] floors it; `None`
    /// otherwise.
    pub fn material(&self, u: f64, v: f64) -> Option<Material> {
        let (map, units) = (self.tpr.as_ref()?, self.tpr_roughness?);
        let e: [f64; 4] = map.sample(u, v);
        let (x, y) = (e[2].clamp(0.0, 1.0) as f32, e[3].clamp(0.0, 1.0) as f32);
        let (at, ab) = match units {
            TprRoughness::R => (x * x, y * y),
            TprRoughness::Alpha => (x, y),
        };
        Some(Material::Ggx {
            alpha_t: at.max(MIN_ALPHA),
            alpha_b: ab.max(MIN_ALPHA),
        })
    }

    /// The frame at UV (u, v) of a surface whose base frame is (t₀, b₀, n) (orthonormal):
    /// first the quaternion rotates the whole base frame (t₀, b₀, n) → (t₁, b₁, n₁)
    /// (`ibl_material::quaternion::frame_from_quat`, the b' erratum fixed, q renormalised as
    /// after bilinear filtering), then the tangent direction d turns t₁ in its tangent plane:
    /// t = normalize(d_x t₁ + d_y b₁), b = n₁ × t, as the thesis's shader composes the two
    /// maps (Marcolongo 2020 §3.4–3.5).
    pub fn frame(&self, u: f64, v: f64, t0: Vec3, b0: Vec3, n: Vec3) -> Frame {
        let (mut t1, mut b1, mut n1) = (t0, b0, n);
        if let Some(q) = &self.quat {
            let e: [f64; 3] = q.sample(u, v);
            let q = ibl_material::quaternion::decode_quat(&[e[0] as f32, e[1] as f32, e[2] as f32]);
            let len = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
            if len > 1e-6 && len.is_finite() {
                let q = q.map(|c| c / len);
                let [tl, _, nl] = ibl_material::quaternion::frame_from_quat(q);
                let world = |l: [f64; 3]| {
                    (t0.as_dvec3() * l[0] + b0.as_dvec3() * l[1] + n.as_dvec3() * l[2]).as_vec3()
                };
                // Re-orthonormalise in f32 (the rotation is exact up to rounding).
                n1 = world(nl).normalize();
                let t = world(tl);
                t1 = (t - n1 * n1.dot(t)).normalize();
                b1 = n1.cross(t1);
            }
        }
        let d: [f64; 2] = match &self.tpr {
            Some(m) => {
                let e: [f64; 2] = m.sample(u, v);
                [2.0 * e[0] - 1.0, 2.0 * e[1] - 1.0]
            }
            None => self.preset.field(u, v, [1.0, 1.0], false),
        };
        let t = t1 * d[0] as f32 + b1 * d[1] as f32;
        let t = if t.length_squared() > 1e-12 && t.is_finite() {
            t.normalize()
        } else {
            t1
        };
        Frame {
            t,
            b: n1.cross(t),
            n: n1,
        }
    }
}

/// Pixels within this sine of the poles are masked: the ring tangent Y × n is undefined at
/// the poles (docs/ANISOTROPY.md §6.11).
pub const POLE_MASK: f32 = 0.1;

/// The sphere's frame at normal n: the lathe tangent t₀ = Y × n/|Y × n| (rings about +Y),
/// b₀ = n × t₀, turned in the tangent plane by the preset's direction at the equirect UV of n
/// (u = ½ + atan2(n_x, n_z)/2π, v = acos(n_y)/π), as `tpr-map` turns it. `None` near the poles.
pub fn sphere_frame(n: Vec3, field: &Field) -> Option<Frame> {
    let ring = Vec3::Y.cross(n);
    let len = ring.length();
    if len < POLE_MASK {
        return None;
    }
    let t0 = ring / len;
    let b0 = n.cross(t0);
    let (u, v) = sphere_uv(n);
    Some(field.frame(u, v, t0, b0, n))
}

/// The equirect UV of the sphere's normal n: u = ½ + atan2(n_x, n_z)/2π, v = acos(n_y)/π.
fn sphere_uv(n: Vec3) -> (f64, f64) {
    let u = 0.5 + (n.x as f64).atan2(n.z as f64) / std::f64::consts::TAU;
    let v = (n.y as f64).clamp(-1.0, 1.0).acos() / std::f64::consts::PI;
    (u, v)
}

/// One shaded pixel of a view.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Pixel {
    /// Row-major index in the s×s image.
    pub idx: usize,
    /// The shading frame.
    pub frame: Frame,
    /// Unit direction towards the eye.
    pub v: Vec3,
    /// The pixel's own lobe (from a `tpr-map` file's roughness channels), in place of the
    /// case's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub material: Option<Material>,
}

/// The shaded pixels of an s×s sphere image under `cam` with tangent field `preset`.
pub fn sphere_pixels(s: usize, cam: (Vec3, Vec3, Vec3), field: &Field) -> Vec<Pixel> {
    let mut out = Vec::new();
    for j in 0..s {
        for i in 0..s {
            let Some(n) = pixel_normal(i, j, s, cam) else {
                continue;
            };
            // Grazing rim pixels (n·v < 0.02) are dropped: every method is 0 there.
            if n.dot(cam.2) < 0.02 {
                continue;
            }
            if let Some(frame) = sphere_frame(n, field) {
                let (u, v) = sphere_uv(n);
                out.push(Pixel {
                    idx: j * s + i,
                    frame,
                    v: cam.2,
                    material: field.material(u, v),
                });
            }
        }
    }
    out
}

/// The plate: the unit disc x² + z² ≤ 1 in the plane y = 0 (normal +Y), seen by a pinhole
/// camera at distance 3 from the centre, at azimuth φ about +Y (φ = 0 from +Z) and elevation θ
/// above the plate, with a 50° vertical field of view (Marcolongo 2020's frying pan, Cocco et
/// al. 2024 Fig. 22). UV = ((x+1)/2, (1−z)/2) on the disc; the base tangent is +X, b₀ = n × t₀
/// = −Z, turned by `preset` (a `radial` preset gives the pan's concentric grooves). The view
/// varies per pixel: v = normalize(eye − p).
pub fn plate_pixels(s: usize, azimuth_deg: f32, elevation_deg: f32, field: &Field) -> Vec<Pixel> {
    let (sp, cp) = azimuth_deg.to_radians().sin_cos();
    let (st, ct) = elevation_deg.clamp(5.0, 89.0).to_radians().sin_cos();
    let dir = Vec3::new(sp * ct, st, cp * ct);
    let eye = 3.0 * dir;
    let fwd = -dir;
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let half = 25f32.to_radians().tan();
    let n = Vec3::Y;
    let t0 = Vec3::X;
    let b0 = n.cross(t0);
    let mut out = Vec::new();
    for j in 0..s {
        for i in 0..s {
            let x = (2.0 * (i as f32 + 0.5) / s as f32 - 1.0) * half;
            let y = (1.0 - 2.0 * (j as f32 + 0.5) / s as f32) * half;
            let ray = (fwd + right * x + up * y).normalize();
            if ray.y >= -1e-6 {
                continue;
            }
            let p = eye + ray * (-eye.y / ray.y);
            if p.x * p.x + p.z * p.z > 1.0 {
                continue;
            }
            let (u, v) = (0.5 * (p.x as f64 + 1.0), 0.5 * (1.0 - p.z as f64));
            out.push(Pixel {
                idx: j * s + i,
                frame: field.frame(u, v, t0, b0, n),
                v: (eye - p).normalize(),
                material: field.material(u, v),
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal_and_right_handed() {
        let preset: Preset = "spiral".parse().unwrap();
        for (az, el) in [(0.0, 0.0), (90.0, 30.0), (200.0, 60.0)] {
            let px = sphere_pixels(16, camera(az, el), &preset.clone().into());
            assert!(px.len() > 100, "{}", px.len());
            for p in px {
                let f = p.frame;
                assert!((f.t.length() - 1.0).abs() < 1e-5 && (f.b.length() - 1.0).abs() < 1e-5);
                assert!(f.t.dot(f.n).abs() < 1e-5 && f.t.cross(f.b).dot(f.n) > 0.999);
            }
        }
        let radial: Preset = "radial".parse().unwrap();
        let plate = plate_pixels(32, 30.0, 40.0, &radial.into());
        assert!(plate.len() > 150, "{}", plate.len());
        for p in plate {
            assert!(p.v.dot(p.frame.n) > 0.0 && (p.frame.t.length() - 1.0).abs() < 1e-5);
            assert!(p.frame.t.y.abs() < 1e-6);
        }
    }

    fn constant_map(w: usize, h: usize, texel: &[f32]) -> UvMap {
        let data = (0..w * h).flat_map(|_| texel.iter().copied()).collect();
        UvMap {
            image: Image::from_data(w, h, texel.len(), data).unwrap(),
        }
    }

    fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
        (a - b).length() <= tol
    }

    #[test]
    fn identity_quat_map_changes_nothing_and_a_rotation_rotates_the_frame() {
        let preset: Preset = "spiral".parse().unwrap();
        let plain: Field = preset.clone().into();
        let identity = Field {
            quat: Some(constant_map(8, 4, &[1.0, 0.5, 0.5])),
            ..plain.clone()
        };
        let cam = camera(30.0, 20.0);
        let a = sphere_pixels(24, cam, &plain);
        let b = sphere_pixels(24, cam, &identity);
        assert_eq!(a.len(), b.len());
        for (p, q) in a.iter().zip(&b) {
            assert!(close(p.frame.t, q.frame.t, 1e-6) && close(p.frame.n, q.frame.n, 1e-6));
            assert!(close(p.frame.b, q.frame.b, 1e-6));
        }
        // A known tilt: the quaternion quat-map stores for the tangent-space normal n'
        // (ibl_material::quaternion::quat_from_normal) turns n onto t₀ n'_x + b₀ n'_y + n n'_z.
        let nl = [0.35f64, -0.25, 0.9];
        let len = (nl[0] * nl[0] + nl[1] * nl[1] + nl[2] * nl[2]).sqrt();
        let nl = nl.map(|c| c / len);
        let q = ibl_material::quaternion::quat_from_normal(nl);
        let enc = q.map(|c| (c * 0.5 + 0.5) as f32);
        let tilted = Field {
            quat: Some(constant_map(8, 4, &enc)),
            ..Field::from("constant:0".parse::<Preset>().unwrap())
        };
        let base: Field = "constant:0".parse::<Preset>().unwrap().into();
        let (a, b) = (
            sphere_pixels(24, cam, &base),
            sphere_pixels(24, cam, &tilted),
        );
        assert_eq!(a.len(), b.len());
        let mut moved = 0;
        for (p, q) in a.iter().zip(&b) {
            let want = p
                .frame
                .to_world(Vec3::new(nl[0] as f32, nl[1] as f32, nl[2] as f32));
            assert!(close(q.frame.n, want, 2e-6), "{} {}", q.frame.n, want);
            // Orthonormal and right-handed.
            let f = q.frame;
            for (x, y) in [(f.t, f.b), (f.b, f.n), (f.n, f.t)] {
                assert!(x.dot(y).abs() < 2e-6);
            }
            for x in [f.t, f.b, f.n] {
                assert!((x.length() - 1.0).abs() < 2e-6);
            }
            assert!(f.t.cross(f.b).dot(f.n) > 0.99999);
            // The tangent is the base tangent rotated by the same rotation.
            let [tl, _, _] = ibl_material::quaternion::frame_from_quat(q_of(&enc));
            let tw = p
                .frame
                .to_world(Vec3::new(tl[0] as f32, tl[1] as f32, tl[2] as f32));
            assert!(close(f.t, tw.normalize(), 2e-5));
            moved += usize::from(!close(p.frame.n, q.frame.n, 0.1));
        }
        assert_eq!(moved, a.len());
    }

    fn q_of(enc: &[f32; 3]) -> [f64; 3] {
        let q = ibl_material::quaternion::decode_quat(enc);
        let l = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
        q.map(|c| c / l)
    }

    #[test]
    fn tpr_map_file_tangents_equal_the_preset() {
        // A tpr-map of constant:30 holds (cos 30°, sin 30°)·½ + ½ in RG everywhere.
        let (s, c) = 30f64.to_radians().sin_cos();
        let map = constant_map(
            16,
            8,
            &[(c * 0.5 + 0.5) as f32, (s * 0.5 + 0.5) as f32, 0.3, 1.0],
        );
        let preset: Preset = "constant:30".parse().unwrap();
        let from_file = Field {
            tpr: Some(map),
            ..Field::from("constant:0".parse::<Preset>().unwrap())
        };
        let from_preset: Field = preset.into();
        for cam in [camera(0.0, 0.0), camera(120.0, 45.0)] {
            let a = sphere_pixels(20, cam, &from_preset);
            let b = sphere_pixels(20, cam, &from_file);
            assert_eq!(a.len(), b.len());
            for (p, q) in a.iter().zip(&b) {
                assert!(
                    close(p.frame.t, q.frame.t, 1e-5),
                    "{} {}",
                    p.frame.t,
                    q.frame.t
                );
            }
        }
        let a = plate_pixels(16, 10.0, 50.0, &from_preset);
        let b = plate_pixels(16, 10.0, 50.0, &from_file);
        for (p, q) in a.iter().zip(&b) {
            assert!(close(p.frame.t, q.frame.t, 1e-5));
        }
    }

    #[test]
    fn uv_maps_are_sampled_bilinearly_with_u_wrapping() {
        // Two columns 0 and 1: at the seam (u = 0) the wrap mixes them half and half.
        let m = UvMap {
            image: Image::from_data(2, 1, 1, vec![0.0, 1.0]).unwrap(),
        };
        assert!((m.sample::<1>(0.25, 0.5)[0] - 0.0).abs() < 1e-12);
        assert!((m.sample::<1>(0.75, 0.5)[0] - 1.0).abs() < 1e-12);
        assert!((m.sample::<1>(0.0, 0.5)[0] - 0.5).abs() < 1e-12);
        assert!((m.sample::<1>(1.0, 0.0)[0] - 0.5).abs() < 1e-12);
        assert!((m.sample::<1>(0.5, 1.0)[0] - 0.5).abs() < 1e-12);
    }

    #[test]
    fn tpr_map_roughness_channels_give_the_pixel_lobe() {
        let field = |texel: &[f32], units| Field {
            tpr: Some(constant_map(8, 4, texel)),
            tpr_roughness: units,
            ..Field::from("constant:0".parse::<Preset>().unwrap())
        };
        let lobe = |f: &Field| f.material(0.3, 0.6).and_then(|m| m.ggx_alphas());
        // Perceptual r squared, α as stored, nothing without the flag.
        let r = lobe(&field(&[1.0, 0.5, 0.5, 0.25], Some(TprRoughness::R))).unwrap();
        assert_eq!(r, (0.25, 0.0625));
        let a = lobe(&field(&[1.0, 0.5, 0.5, 0.25], Some(TprRoughness::Alpha))).unwrap();
        assert_eq!(a, (0.5, 0.25));
        assert_eq!(lobe(&field(&[1.0, 0.5, 0.5, 0.25], None)), None);
        // r = 0 is floored as Material::ggx_kc floors it (a mirror axis has no D(m)).
        let z = lobe(&field(&[1.0, 0.5, 0.0, 1.0], Some(TprRoughness::R))).unwrap();
        assert_eq!(z, (MIN_ALPHA, 1.0));
        // The pixels carry it; without the flag they carry none.
        let px = sphere_pixels(
            8,
            camera(30.0, 20.0),
            &field(&[1.0, 0.5, 0.5, 0.25], Some(TprRoughness::R)),
        );
        assert!(!px.is_empty() && px.iter().all(|p| p.material.is_some()));
        let px = sphere_pixels(8, camera(30.0, 20.0), &field(&[1.0, 0.5, 0.5, 0.25], None));
        assert!(px.iter().all(|p| p.material.is_none()));
    }
}
