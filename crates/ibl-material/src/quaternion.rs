//! The quaternion of a normal-map texel (Marcolongo 2020 §3.4) and the tangent frame it encodes.
//!
//! A quaternion q = a + b·i + c·j (d = 0: the rotation axis lies in the tangent plane) acts
//! on a vector v as r_q(v) = q̄·v·q. [`quat_from_normal`] picks the shortest rotation taking
//! n = (0, 0, 1) to the texel's normal n'; [`frame_from_quat`] is what a shader does with the
//! stored q to get the whole perturbed frame (t', b', n').
//!
//! Erratum (Marcolongo 2020 §3.4, the b' line): the thesis prints b' = (2bc, a²−b²+c², 2ab).
//! Rotating j by q̄·j·q gives b' = (2bc, a²−b²+c², −2ab); with the printed sign
//! t'·b' = 8a²bc ≠ 0 and the frame is not orthonormal. [`frame_from_quat`] uses the
//! rotation's sign; the tests check it against an independent Hamilton-product rotation.

/// Quaternion components (a, b, c) of a + b·i + c·j; the k component is 0 by construction.
pub(crate) type Quat3 = [f64; 3];
/// A vector in tangent space: (t, b, n) components.
pub type Vec3 = [f64; 3];

/// Shortest-arc unit quaternion with q̄·k·q = n for a unit normal n = (x, y, z),
/// Marcolongo 2020 §3.4: a = sqrt((z+1)/2), b = y/(2a), c = −x/(2a), a ≥ 0.
/// See [`quat_from_vector`], which this calls with n's own length (any length works: where
/// the length under- or overflows, the fallback scales n by its largest component first).
pub fn quat_from_normal(n: Vec3) -> Quat3 {
    quat_from_vector(n, length(n))
}

/// The thesis's quaternion (§3.4) for the direction of a not necessarily unit vector
/// v = (x, y, z) of length `len`: q = (w, y, −x)/sqrt(w² + x² + y²) with w = len + z.
/// For a unit v this is a = sqrt((1+z)/2), b = y/(2a), c = −x/(2a), since
/// w² + r² = 2·len·(len + z); it saves normalising v first.
///
/// Stability: for z < 0, len + z cancels (the thesis's a → 0 and b = y/(2a) loses every
/// digit near −z); there we use the equal w = r²/(len − z), r² = x² + y², which cancels
/// nothing — the b = s·y/r, c = −s·x/r with s = sqrt((1−z)/2) in other words.
/// For v on −z exactly (r = 0) every half-turn about a tangent-plane axis is shortest; we
/// return the half-turn about t, q = (0, 1, 0), the limit approached from the +y side, which
/// keeps t' = t. A zero vector gives the identity; NaN/∞ components give NaN.
#[inline(always)]
pub(crate) fn quat_from_vector(v: Vec3, len: f64) -> Quat3 {
    let [x, y, z] = v;
    let r2 = x * x + y * y;
    let w = if z >= 0.0 { len + z } else { r2 / (len - z) };
    let norm2 = w * w + r2;
    if norm2 > 1e-280 && norm2 < f64::INFINITY {
        let inv = 1.0 / norm2.sqrt();
        [w * inv, y * inv, -x * inv]
    } else {
        quat_from_scaled_vector(v)
    }
}

/// [`quat_from_vector`] when w² + r² under- or overflowed (v tiny or huge, `len` possibly 0
/// or ∞ then), or near −z where r² underflows: v is divided by its largest |component| so
/// the length is computed on values in [−1, 1], and the z < 0 side works with r and the
/// ratio t = w/r = r/(len − z). Not recursive.
#[cold]
#[inline(never)]
fn quat_from_scaled_vector(v: Vec3) -> Quat3 {
    let [x, y, z] = v;
    if !(x.is_finite() && y.is_finite() && z.is_finite()) {
        return [f64::NAN; 3];
    }
    if x == 0.0 && y == 0.0 {
        return if z < 0.0 {
            [0.0, 1.0, 0.0]
        } else {
            [1.0, 0.0, 0.0]
        };
    }
    let m = x.abs().max(y.abs()).max(z.abs());
    let [x, y, z] = [x / m, y / m, z / m];
    let len = (x * x + y * y + z * z).sqrt();
    let r = x.hypot(y);
    if z >= 0.0 {
        // w = len + z ≥ 1: nothing under- or overflows.
        let w = len + z;
        let inv = 1.0 / (w * w + r * r).sqrt();
        return [w * inv, y * inv, -x * inv];
    }
    let t = r / (len - z);
    let inv = 1.0 / (1.0 + t * t).sqrt();
    [t * inv, y / r * inv, -x / r * inv]
}

/// The rotated tangent frame (t', b', n') = (q̄·i·q, q̄·j·q, q̄·k·q), Marcolongo 2020 §3.4 with the
/// b' erratum fixed:
/// t' = (a²+b²−c², 2bc, 2ac), b' = (2bc, a²−b²+c², −2ab), n' = (−2ac, 2ab, a²−b²−c²).
///
/// These are the shader's formulas: for a quantised, not quite unit q they give |q|² times
/// a rotation (orthogonal, scaled), which is what [`orthonormality_error`] then measures.
pub fn frame_from_quat(q: Quat3) -> [Vec3; 3] {
    let [a, b, c] = q;
    let (aa, bb, cc) = (a * a, b * b, c * c);
    [
        [aa + bb - cc, 2.0 * b * c, 2.0 * a * c],
        [2.0 * b * c, aa - bb + cc, -2.0 * a * b],
        [-2.0 * a * c, 2.0 * a * b, aa - bb - cc],
    ]
}

/// A unit quaternion stored in a texel: q·0.5 + 0.5 (identity → (1, 0.5, 0.5)).
#[inline]
pub(crate) fn encode_quat(q: Quat3) -> [f32; 3] {
    q.map(|v| (v * 0.5 + 0.5) as f32)
}

/// Inverse of [`encode_quat`] (not renormalised: the shader's view of the texel).
#[inline]
pub fn decode_quat(rgb: &[f32]) -> Quat3 {
    [
        rgb[0] as f64 * 2.0 - 1.0,
        rgb[1] as f64 * 2.0 - 1.0,
        rgb[2] as f64 * 2.0 - 1.0,
    ]
}

/// q / |q| (the identity for a zero quaternion).
pub(crate) fn normalize_quat(q: Quat3) -> Quat3 {
    let len = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2]).sqrt();
    if len > 0.0 {
        q.map(|v| v / len)
    } else {
        [1.0, 0.0, 0.0]
    }
}

/// Bound on the angle (radians) between n' decoded from a stored quaternion and the exact n',
/// when each stored component is off by at most `eps` in q units (q = 2e − 1, so for an
/// N-bit channel eps = 1/(2^N − 1), the half-step 0.5/(2^N − 1) doubled).
///
/// |Δq| ≤ √3·eps (d is exactly 0), the angle between q and q + Δq as 4-vectors is at most
/// asin(|Δq|), and a rotation moves by twice the quaternion angle: 2·asin(√3·eps).
/// 16-bit: 5.29e-5 rad (0.0030°); 8-bit: 1.36e-2 rad (0.78°).
pub fn quantisation_bound(eps: f64) -> f64 {
    2.0 * (3f64.sqrt() * eps).min(1.0).asin()
}

/// Largest rounding error, in q units, of storing q·0.5+0.5 at a given depth:
/// N-bit integers 1/(2^N − 1); half floats 2^-11 (spacing 2^-11 on [0.5, 1], half of it
/// doubled); 32-bit floats 2^-23.
pub fn storage_eps(depth: StorageDepth) -> f64 {
    match depth {
        StorageDepth::Bits(n) => 1.0 / ((1u64 << n) - 1) as f64,
        StorageDepth::Half => 2f64.powi(-11),
        StorageDepth::Float => 2f64.powi(-23),
    }
}

/// How a map's texels are stored on disk.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum StorageDepth {
    /// Unsigned normalised integers of this many bits (8 or 16).
    Bits(u8),
    /// Half floats (EXR).
    Half,
    /// 32-bit floats (EXR).
    Float,
}

/// a·b.
#[inline]
pub fn dot(a: Vec3, b: Vec3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// a×b (right-handed).
#[inline]
pub fn cross(a: Vec3, b: Vec3) -> Vec3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// |a|.
#[inline]
pub fn length(a: Vec3) -> f64 {
    dot(a, a).sqrt()
}

/// Angle between two (not necessarily unit) vectors, accurate at small angles:
/// atan2(|a×b|, a·b).
#[inline]
pub fn angle_between(a: Vec3, b: Vec3) -> f64 {
    length(cross(a, b)).atan2(dot(a, b))
}

/// max |f_i·f_j − δ_ij| over the frame's Gram matrix.
pub(crate) fn orthonormality_error(f: &[Vec3; 3]) -> f64 {
    let mut e = 0.0f64;
    for i in 0..3 {
        for j in i..3 {
            let target = if i == j { 1.0 } else { 0.0 };
            e = e.max((dot(f[i], f[j]) - target).abs());
        }
    }
    e
}

/// det(t', b', n') = (t' × b')·n': +1 for a right-handed orthonormal frame.
#[inline]
pub(crate) fn handedness(f: &[Vec3; 3]) -> f64 {
    dot(cross(f[0], f[1]), f[2])
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::sampling::Pcg32;

    /// Hamilton product of (w, x, y, z) quaternions: the independent reference.
    fn hamilton(p: [f64; 4], q: [f64; 4]) -> [f64; 4] {
        [
            p[0] * q[0] - p[1] * q[1] - p[2] * q[2] - p[3] * q[3],
            p[0] * q[1] + p[1] * q[0] + p[2] * q[3] - p[3] * q[2],
            p[0] * q[2] - p[1] * q[3] + p[2] * q[0] + p[3] * q[1],
            p[0] * q[3] + p[1] * q[2] - p[2] * q[1] + p[3] * q[0],
        ]
    }

    /// r_q(v) = q̄·v·q by two Hamilton products.
    fn rotate(q: Quat3, v: Vec3) -> Vec3 {
        let q4 = [q[0], q[1], q[2], 0.0];
        let qbar = [q[0], -q[1], -q[2], 0.0];
        let r = hamilton(hamilton(qbar, [0.0, v[0], v[1], v[2]]), q4);
        assert!(r[0].abs() < 1e-12);
        [r[1], r[2], r[3]]
    }

    /// Rodrigues: rotate v about unit axis k by angle θ (second independent reference).
    fn rodrigues(v: Vec3, k: Vec3, theta: f64) -> Vec3 {
        let (s, c) = theta.sin_cos();
        let kxv = cross(k, v);
        let kv = dot(k, v);
        [0, 1, 2].map(|i| v[i] * c + kxv[i] * s + k[i] * kv * (1.0 - c))
    }

    fn random_unit(rng: &mut Pcg32) -> Vec3 {
        let z = 2.0 * rng.next_f64() - 1.0;
        let phi = 2.0 * std::f64::consts::PI * rng.next_f64();
        let r = (1.0 - z * z).max(0.0).sqrt();
        [r * phi.cos(), r * phi.sin(), z]
    }

    fn dist(a: Vec3, b: Vec3) -> f64 {
        length([a[0] - b[0], a[1] - b[1], a[2] - b[2]])
    }

    #[test]
    fn frame_equals_hamilton_rotation_of_the_basis() {
        let mut rng = Pcg32::new(7, 1);
        let mut worst = 0.0f64;
        for _ in 0..20_000 {
            // Any quaternion with d = 0, unit or not (the shader sees quantised ones).
            let q = [0, 1, 2].map(|_| 2.0 * rng.next_f64() - 1.0);
            let f = frame_from_quat(q);
            for (k, e) in [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
                .iter()
                .enumerate()
            {
                worst = worst.max(dist(f[k], rotate(q, *e)));
            }
        }
        eprintln!("frame vs Hamilton rotation: max |Δ| = {worst:.3e}");
        assert!(worst < 1e-14);
    }

    #[test]
    fn printed_bitangent_is_wrong_and_the_fixed_one_is_orthogonal() {
        let q = normalize_quat([0.8, 0.3, -0.4]);
        let [a, b, c] = q;
        let f = frame_from_quat(q);
        let printed = [2.0 * b * c, a * a - b * b + c * c, 2.0 * a * b];
        let tb_printed = dot(f[0], printed);
        eprintln!(
            "t'·b'(printed) = {tb_printed:.6}, 8a²bc = {:.6}, t'·b'(fixed) = {:.2e}",
            8.0 * a * a * b * c,
            dot(f[0], f[1])
        );
        assert!((tb_printed - 8.0 * a * a * b * c).abs() < 1e-12);
        assert!(tb_printed.abs() > 0.1);
        assert!(dot(f[0], f[1]).abs() < 1e-15);
        assert!(dist(f[1], rotate(q, [0.0, 1.0, 0.0])) < 1e-15);
    }

    #[test]
    fn quaternion_rotates_z_onto_the_normal_everywhere() {
        let mut rng = Pcg32::new(11, 3);
        let (mut worst_n, mut worst_unit, mut worst_ortho, mut min_det) =
            (0.0f64, 0.0f64, 0.0f64, 2.0f64);
        for _ in 0..50_000 {
            let n = random_unit(&mut rng);
            let q = quat_from_normal(n);
            assert!(q[0] >= 0.0);
            worst_unit = worst_unit.max((length(q) - 1.0).abs());
            worst_n = worst_n.max(dist(rotate(q, [0.0, 0.0, 1.0]), n));
            let f = frame_from_quat(q);
            worst_ortho = worst_ortho.max(orthonormality_error(&f));
            min_det = min_det.min(handedness(&f));
        }
        eprintln!("q̄kq vs n: {worst_n:.2e}, |q|-1: {worst_unit:.2e}, orthonormality: {worst_ortho:.2e}, min det {min_det}");
        assert!(worst_n < 1e-14 && worst_unit < 1e-15 && worst_ortho < 1e-14);
        assert!((min_det - 1.0).abs() < 1e-14);
    }

    #[test]
    fn rotation_is_the_shortest_arc() {
        // The rotation angle 2·acos(a) equals the angle between z and n (no rotation taking
        // z to n is shorter), and the axis is perpendicular to both.
        let mut rng = Pcg32::new(5, 9);
        for _ in 0..10_000 {
            let n = random_unit(&mut rng);
            if n[2] < -0.999 {
                continue;
            }
            let q = quat_from_normal(n);
            let angle = 2.0 * q[0].clamp(-1.0, 1.0).acos();
            assert!(
                (angle - angle_between([0.0, 0.0, 1.0], n)).abs() < 1e-7,
                "{n:?}"
            );
            // q̄ v q rotates about −(b, c, 0): perpendicular to z and to n.
            let axis = [-q[1], -q[2], 0.0];
            assert!(dot(axis, n).abs() < 1e-12);
        }
    }

    /// Expected frame by Rodrigues about k = ẑ×n̂ by acos(n_z): independent of the thesis's algebra.
    fn rodrigues_frame(n: Vec3) -> [Vec3; 3] {
        let k = cross([0.0, 0.0, 1.0], n);
        let kl = length(k);
        let theta = angle_between([0.0, 0.0, 1.0], n);
        let k = k.map(|v| v / kl);
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]].map(|e| rodrigues(e, k, theta))
    }

    #[test]
    fn hand_checked_texels() {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        // Identity: stored as (1, 0.5, 0.5), the thesis's footnote 6.
        assert_eq!(quat_from_normal([0.0, 0.0, 1.0]), [1.0, 0.0, 0.0]);
        assert_eq!(encode_quat([1.0, 0.0, 0.0]), [1.0, 0.5, 0.5]);
        // 90° tilt towards +x: rotation by +90° about +y; t' = −z, b' = y.
        let q = quat_from_normal([1.0, 0.0, 0.0]);
        assert!(dist(q, [s, 0.0, -s]) < 1e-15);
        let f = frame_from_quat(q);
        assert!(dist(f[0], [0.0, 0.0, -1.0]) < 1e-15 && dist(f[1], [0.0, 1.0, 0.0]) < 1e-15);
        // 90° tilt towards +y: rotation by −90° about +x; b' = −z, t' = x.
        let q = quat_from_normal([0.0, 1.0, 0.0]);
        assert!(dist(q, [s, s, 0.0]) < 1e-15);
        let f = frame_from_quat(q);
        assert!(dist(f[0], [1.0, 0.0, 0.0]) < 1e-15 && dist(f[1], [0.0, 0.0, -1.0]) < 1e-15);
        // −z: the half-turn about t.
        let q = quat_from_normal([0.0, 0.0, -1.0]);
        assert_eq!(q, [0.0, 1.0, 0.0]);
        assert_eq!(encode_quat(q), [0.5, 1.0, 0.5]);
        let f = frame_from_quat(q);
        assert_eq!(f, [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]);
        // ±x, ±y tilts of 30°, 45°, 90°, 135° against Rodrigues.
        for deg in [30.0f64, 45.0, 90.0, 135.0, 179.0] {
            let (st, ct) = deg.to_radians().sin_cos();
            for n in [[st, 0.0, ct], [-st, 0.0, ct], [0.0, st, ct], [0.0, -st, ct]] {
                let f = frame_from_quat(quat_from_normal(n));
                let r = rodrigues_frame(n);
                for k in 0..3 {
                    assert!(
                        dist(f[k], r[k]) < 1e-13,
                        "{deg}° {n:?} axis {k}: {:?} vs {:?}",
                        f[k],
                        r[k]
                    );
                }
            }
        }
        // A tilt of 45° towards +x stores c = −sin(22.5°).
        let q = quat_from_normal([s, 0.0, s]);
        assert!(
            dist(
                q,
                [22.5f64.to_radians().cos(), 0.0, -22.5f64.to_radians().sin()]
            ) < 1e-15
        );
    }

    #[test]
    fn stable_near_minus_z_where_the_printed_formula_fails() {
        let mut worst = 0.0f64;
        for e in [1e-3, 1e-5, 1e-7, 1e-9, 1e-12, 1e-200] {
            for dir in [[1.0, 0.0], [0.0, 1.0], [-0.6, 0.8]] {
                let len = (1.0f64 + e * e).sqrt();
                let n = [e * dir[0] / len, e * dir[1] / len, -1.0 / len];
                let q = quat_from_normal(n);
                let err = angle_between(rotate(q, [0.0, 0.0, 1.0]), n);
                worst = worst.max(err);
                // The printed a = sqrt((z+1)/2), b = y/(2a) form: 1 + z cancels to 0.
                let a = ((n[2] + 1.0) * 0.5).sqrt();
                let naive = [a, n[1] / (2.0 * a), -n[0] / (2.0 * a)];
                if e <= 1e-9 {
                    let bad = frame_from_quat(naive)[2];
                    assert!(!bad.iter().all(|v| v.is_finite()) || angle_between(bad, n) > 1e-3);
                }
            }
        }
        eprintln!("near −z: max angle error {worst:.2e} rad");
        assert!(worst < 1e-15);
        // Unnormalised vectors give the same quaternion as their direction.
        let mut rng = Pcg32::new(3, 3);
        for _ in 0..10_000 {
            let n = random_unit(&mut rng);
            let k = 1e-3 + 5.0 * rng.next_f64();
            let q = quat_from_vector(n.map(|v| v * k), k);
            assert!(dist(q, quat_from_normal(n)) < 1e-14);
            assert!((length(q) - 1.0).abs() < 1e-15);
        }
        assert_eq!(quat_from_vector([0.0; 3], 0.0), [1.0, 0.0, 0.0]);
    }

    #[test]
    fn tiny_and_huge_vectors_give_their_direction_s_rotation() {
        // All components below ~1e-154: the squares underflow and length() gives 0. The
        // closed form for a tilt of θ towards +x: q = (cos θ/2, 0, −sin θ/2).
        let half = |deg: f64| {
            let (s, c) = (deg / 2.0).to_radians().sin_cos();
            [c, 0.0, -s]
        };
        let s = std::f64::consts::FRAC_1_SQRT_2;
        for (v, deg, unit) in [
            ([1e-200, 0.0, 1e-200], 45.0, [s, 0.0, s]),
            ([1e-200, 0.0, -1e-200], 135.0, [s, 0.0, -s]),
            ([1e200, 0.0, 1e200], 45.0, [s, 0.0, s]),
            ([1e200, 0.0, -1e200], 135.0, [s, 0.0, -s]),
        ] {
            for q in [quat_from_normal(v), quat_from_vector(v, length(v))] {
                assert!(dist(q, half(deg)) < 1e-15, "{v:?}: {q:?}");
                // Independently: q̄·k·q by Hamilton products is the unit direction.
                assert!(
                    dist(rotate(q, [0.0, 0.0, 1.0]), unit) < 1e-15,
                    "{v:?}: {q:?}"
                );
            }
        }
        // Random directions at every scale agree with the unit vector's quaternion.
        let mut rng = Pcg32::new(21, 4);
        let mut worst = 0.0f64;
        for _ in 0..10_000 {
            let n = random_unit(&mut rng);
            for k in [1e-200, 1e-170, 1e-155, 1e150, 1e200, 1e300] {
                let v = n.map(|c| c * k);
                let q = quat_from_vector(v, length(v));
                worst = worst.max(dist(q, quat_from_normal(n)));
                worst = worst.max(dist(quat_from_normal(v), quat_from_normal(n)));
            }
        }
        eprintln!("scaled vectors vs their direction: max |Δq| {worst:.2e}");
        assert!(worst < 1e-14);
        // Zero, and exactly −z however small.
        assert_eq!(quat_from_normal([0.0; 3]), [1.0, 0.0, 0.0]);
        assert_eq!(quat_from_normal([0.0, 0.0, -1e-300]), [0.0, 1.0, 0.0]);
        assert_eq!(quat_from_normal([0.0, 0.0, 1e-300]), [1.0, 0.0, 0.0]);
    }

    #[test]
    fn quantisation_bound_values() {
        let b16 = quantisation_bound(storage_eps(StorageDepth::Bits(16)));
        let b8 = quantisation_bound(storage_eps(StorageDepth::Bits(8)));
        eprintln!(
            "bounds: 16-bit {b16:.3e} rad, 8-bit {b8:.3e} rad ({:.3}°)",
            b8.to_degrees()
        );
        assert!((b16 - 5.286e-5).abs() < 1e-8 && (b8 - 1.3585e-2).abs() < 1e-5);
        // The bound is attained in order of magnitude by a worst-case rounding.
        let q = normalize_quat([0.9, 0.3, -0.3]);
        let eps = storage_eps(StorageDepth::Bits(8));
        let qq = [q[0] - eps, q[1] + eps, q[2] - eps];
        let err = angle_between(frame_from_quat(q)[2], frame_from_quat(qq)[2]);
        assert!(err <= b8 && err > b8 / 10.0, "{err} vs {b8}");
    }
}
