//! The diffuse SH forms engines take, made from our 3-band irradiance coefficients c_lm
//! (docs/CONVENTIONS.md basis; E(n)/π = Σ c_lm Y_lm(n)): Filament's and Unity's pre-scaled polynomial
//! coefficients (cmgen's `sh.txt` and KTX1 `sh` metadata; Unity's SphericalHarmonicsL2 and
//! its shader constants) and three.js's `LightProbe` JSON.

use crate::orient::Orientation;
use glam::Vec3;
use ibl_core::sh::{cosine_lobe_zonal, eval_basis3};

/// Polynomials P_i of the pre-scaled form, in SH index order:
/// 1, y, z, x, xy, yz, 3z²−1, xz, x²−y² (Y_i = K_i·P_i with K_i > 0).
pub(crate) fn polynomial_basis(d: Vec3) -> [f64; 9] {
    let (x, y, z) = (d.x as f64, d.y as f64, d.z as f64);
    [
        1.0,
        y,
        z,
        x,
        x * y,
        y * z,
        3.0 * z * z - 1.0,
        x * z,
        x * x - y * y,
    ]
}

/// Coefficients p_i with E/π(t) = Σ p_i P_i(t) in the engine file's frame (t ↦ our A·t): the
/// form Filament's shader evaluates (google/filament `shaders/src/surface_light_indirect.fs`,
/// `Irradiance_SphericalHarmonics`: sh[0] + sh[1]·y + sh[2]·z + sh[3]·x + sh[4]·yx + sh[5]·yz +
/// sh[6]·(3z²−1) + sh[7]·zx + sh[8]·(x²−y²)) and Unity's SampleSH9 after PackSH
/// (Unity-Technologies/Graphics `Packages/com.unity.render-pipelines.core/ShaderLibrary/
/// SphericalHarmonics.hlsl`). Basis sign conventions (Unity's and Filament's Condon–Shortley
/// signs) cancel in this form: the engines pre-multiply by the same signed constants.
///
/// `irradiance` holds at least the 9 coefficients of bands 0–2 (higher bands are ignored).
/// Fitted by least squares on 64 directions, exact since E/π∘A lies in the span.
pub fn prescaled_polynomial(irradiance: &[[f32; 3]], o: Orientation) -> [[f64; 3]; 9] {
    let dirs = fibonacci_sphere(64);
    let mut ata = [[0.0f64; 9]; 9];
    let mut atb = [[0.0f64; 3]; 9];
    for t in dirs {
        let p = polynomial_basis(t);
        let y = eval_basis3(o.ours_from_file(t));
        let mut g = [0.0f64; 3];
        for i in 0..9 {
            for c in 0..3 {
                g[c] += irradiance[i][c] as f64 * y[i] as f64;
            }
        }
        for i in 0..9 {
            for j in 0..9 {
                ata[i][j] += p[i] * p[j];
            }
            for c in 0..3 {
                atb[i][c] += p[i] * g[c];
            }
        }
    }
    solve9(ata, atb)
}

#[cfg(test)]
/// Evaluates Σ p_i P_i(t) (Filament's and Unity's shader form).
pub(crate) fn eval_polynomial(p: &[[f64; 3]; 9], t: Vec3) -> [f64; 3] {
    let b = polynomial_basis(t);
    let mut out = [0.0; 3];
    for i in 0..9 {
        for c in 0..3 {
            out[c] += p[i][c] * b[i];
        }
    }
    out
}

/// cmgen's `sh.txt` (`--sh-shader`, google/filament `tools/cmgen/src/cmgen.cpp`, `outputSh`):
/// one line per coefficient, `(r, g, b); // L{l}{m}, irradiance, pre-scaled base`, each value
/// fixed with 15 decimals in an 18-character field.
pub fn filament_sh_txt(p: &[[f64; 3]; 9]) -> String {
    let mut s = String::new();
    for l in 0..3i32 {
        for m in -l..=l {
            let v = p[(l * (l + 1) + m) as usize];
            s.push_str(&format!(
                "({:>18.15}, {:>18.15}, {:>18.15}); // L{l}{m}, irradiance, pre-scaled base\n",
                v[0], v[1], v[2]
            ));
        }
    }
    s
}

/// The KTX1 `sh` metadata value cmgen writes (cmgen.cpp: `sstr << v.r << " " << v.g << " " <<
/// v.b << "\n"` per coefficient, C++'s default 6 significant digits), read back by Filament's
/// `Ktx1Bundle::getSphericalHarmonics` (google/filament `libs/image/src/Ktx1Bundle.cpp`).
pub fn filament_ktx_sh_metadata(p: &[[f64; 3]; 9]) -> String {
    let mut s = String::new();
    for v in p {
        s.push_str(&format!(
            "{} {} {}\n",
            fmt_g6(v[0]),
            fmt_g6(v[1]),
            fmt_g6(v[2])
        ));
    }
    s
}

/// C++ iostream default float formatting (`%g`, 6 significant digits).
pub(crate) fn fmt_g6(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return if v.is_finite() {
            "0".into()
        } else {
            format!("{v}")
        };
    }
    // The exponent of the value rounded to 6 digits decides the style (999999.7 → 1e+06).
    let sci = format!("{:.5e}", v);
    let (mant, exp) = sci.split_once('e').unwrap_or((&sci, "0"));
    let exp: i32 = exp.parse().unwrap_or(0);
    if !(-4..6).contains(&exp) {
        let mant = trim_zeros(mant);
        format!("{mant}e{}{:02}", if exp < 0 { '-' } else { '+' }, exp.abs())
    } else {
        let decimals = (5 - exp).max(0) as usize;
        trim_zeros(&format!("{:.*}", decimals, v)).to_string()
    }
}

fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// Unity's SphericalHarmonicsL2 as `[channel][coefficient]` (its `sh[rgb, i]` indexing): the
/// pre-multiplied coefficients its shader packs without further scaling (PackSH in
/// SphericalHarmonics.hlsl packs them straight into unity_SHAr … unity_SHC), i.e. the
/// polynomial form of E/π in Unity's left-handed frame (ours with z negated). Unity's own
/// basis carries Condon–Shortley signs (`kSHBasisCoef = { k0, −k1, k1, −k1, k2, −k2, k3, −k2,
/// k4 }`) and pre-multiplies by them and by the clamped-cosine factors 1, 2/3, 1/4
/// (`kClampedCosineCoefs`), which is what lands here.
pub fn unity_sh_l2(irradiance: &[[f32; 3]]) -> [[f64; 9]; 3] {
    let p = prescaled_polynomial(irradiance, Orientation::FLIP_Z);
    let mut out = [[0.0; 9]; 3];
    for i in 0..9 {
        for c in 0..3 {
            out[c][i] = p[i][c];
        }
    }
    out
}

/// Unity's seven shader constants unity_SHAr, SHAg, SHAb, SHBr, SHBg, SHBb, SHC from a
/// SphericalHarmonicsL2 (PackSH in SphericalHarmonics.hlsl).
pub fn unity_shader_constants(sh: &[[f64; 9]; 3]) -> [[f64; 4]; 7] {
    let mut out = [[0.0; 4]; 7];
    for c in 0..3 {
        let s = sh[c];
        out[c] = [s[3], s[1], s[2], s[0] - s[6]];
        out[3 + c] = [s[4], s[5], 3.0 * s[6], s[7]];
    }
    out[6] = [sh[0][8], sh[1][8], sh[2][8], 1.0];
    out
}

/// Radiance coefficients L_lm in our basis and frame recovered from the irradiance ones
/// (L_lm = c_lm·π/Â_l): what three.js's `LightProbe.sh` holds (mrdoob/three.js
/// `src/math/SphericalHarmonics3.js`: `getBasisAt` is docs/CONVENTIONS.md's basis; `getIrradianceAt`
/// applies Â_l itself).
pub(crate) fn three_radiance(irradiance: &[[f32; 3]]) -> [[f64; 3]; 9] {
    let mut out = [[0.0; 3]; 9];
    for l in 0..3usize {
        let f = std::f64::consts::PI / cosine_lobe_zonal(l);
        for m in -(l as isize)..=(l as isize) {
            let i = (l as isize * (l as isize + 1) + m) as usize;
            for c in 0..3 {
                out[i][c] = irradiance[i][c] as f64 * f;
            }
        }
    }
    out
}

/// A three.js `LightProbe` in the form `LightProbe.toJSON` writes (mrdoob/three.js
/// `src/lights/LightProbe.js`, `src/lights/Light.js`, `src/core/Object3D.js`), read back by
/// `ObjectLoader.parse` (`src/loaders/ObjectLoader.js`, case 'LightProbe':
/// `new LightProbe().fromJSON(data)` reads `intensity` and `sh`). Its `uuid` is derived from
/// the coefficients ([`content_uuid`]): unique per content, and the same bytes on every run.
pub fn three_light_probe_json(irradiance: &[[f32; 3]]) -> serde_json::Value {
    let sh: Vec<f64> = three_radiance(irradiance)
        .iter()
        .flatten()
        .copied()
        .collect();
    let bytes: Vec<u8> = sh.iter().flat_map(|v| v.to_le_bytes()).collect();
    let uuid = content_uuid("three.LightProbe", &bytes);
    serde_json::json!({
        "metadata": {
            "version": 4.6,
            "type": "Object",
            "generator": "Object3D.toJSON"
        },
        "object": {
            "uuid": uuid,
            "type": "LightProbe",
            "layers": 1,
            "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1],
            "up": [0, 1, 0],
            "color": 0xffffff,
            "intensity": 1,
            "sh": sh
        }
    })
}

/// A UUID derived from content (RFC 9562 version 8, "custom": the first 122 bits of
/// BLAKE3(`kind` ‖ 0 ‖ `content`) with the version and variant bits set). Chosen over a random
/// v4 uuid because the pipeline cache and the golden byte manifests need the same bytes for
/// the same inputs; a hash of the content is still unique per content (two documents share a
/// uuid only when they hold the same probe), where a constant collided for every probe.
pub fn content_uuid(kind: &str, content: &[u8]) -> String {
    let mut h = blake3::Hasher::new();
    h.update(kind.as_bytes());
    h.update(&[0]);
    h.update(content);
    let mut b = [0u8; 16];
    b.copy_from_slice(&h.finalize().as_bytes()[..16]);
    b[6] = (b[6] & 0x0f) | 0x80;
    b[8] = (b[8] & 0x3f) | 0x80;
    let hex: String = b.iter().map(|x| format!("{x:02x}")).collect();
    format!(
        "{}-{}-{}-{}-{}",
        &hex[0..8],
        &hex[8..12],
        &hex[12..16],
        &hex[16..20],
        &hex[20..32]
    )
}

/// n points of a Fibonacci spiral on the unit sphere (fixed, deterministic).
pub(crate) fn fibonacci_sphere(n: usize) -> Vec<Vec3> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|k| {
            let z = 1.0 - (2 * k + 1) as f64 / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = golden * k as f64;
            Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32)
        })
        .collect()
}

/// Solves the 9×9 system A·x = b (three right-hand sides) by Gaussian elimination with
/// partial pivoting; A is symmetric positive definite here.
fn solve9(mut a: [[f64; 9]; 9], mut b: [[f64; 3]; 9]) -> [[f64; 3]; 9] {
    for k in 0..9 {
        let p = (k..9)
            .max_by(|&i, &j| a[i][k].abs().total_cmp(&a[j][k].abs()))
            .unwrap();
        a.swap(k, p);
        b.swap(k, p);
        for i in k + 1..9 {
            let f = a[i][k] / a[k][k];
            for j in k..9 {
                a[i][j] -= f * a[k][j];
            }
            for c in 0..3 {
                b[i][c] -= f * b[k][c];
            }
        }
    }
    let mut x = [[0.0; 3]; 9];
    for k in (0..9).rev() {
        for c in 0..3 {
            let mut s = b[k][c];
            for j in k + 1..9 {
                s -= a[k][j] * x[j][c];
            }
            x[k][c] = s / a[k][k];
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::sampling::Pcg32;
    use ibl_core::sh::eval_rgb;

    /// Irradiance coefficients of a lopsided environment: every coefficient non-zero, no two
    /// alike, so a wrong sign or order anywhere shows.
    fn coeffs() -> Vec<[f32; 3]> {
        (0..9)
            .map(|i| {
                let i = i as f32;
                [
                    0.9 - 0.07 * i,
                    0.3 + 0.05 * (i - 4.0),
                    if (i as usize).is_multiple_of(2) {
                        0.11 * i
                    } else {
                        -0.09 * i
                    },
                ]
            })
            .collect()
    }

    fn dirs() -> Vec<Vec3> {
        let mut rng = Pcg32::new(5, 7);
        (0..500)
            .map(|_| {
                Vec3::new(
                    rng.next_f32() * 2.0 - 1.0,
                    rng.next_f32() * 2.0 - 1.0,
                    rng.next_f32() * 2.0 - 1.0,
                )
            })
            .filter(|d| d.length() > 0.1)
            .map(|d| d.normalize())
            .collect()
    }

    #[test]
    fn polynomial_form_reproduces_our_irradiance_in_every_frame() {
        let c = coeffs();
        for o in [
            Orientation::IDENTITY,
            Orientation::FLIP_Z,
            Orientation::FLIP_X,
            Orientation::TURN_Y_90,
        ] {
            let p = prescaled_polynomial(&c, o);
            for t in dirs() {
                let e = eval_polynomial(&p, t);
                let ours = eval_rgb(&c, o.ours_from_file(t));
                for k in 0..3 {
                    assert!((e[k] - ours[k] as f64).abs() < 1e-5, "{o:?} {t:?}");
                }
            }
        }
        // In our own frame the form is c_i·K_i: the constants of docs/CONVENTIONS.md.
        let p = prescaled_polynomial(&c, Orientation::IDENTITY);
        let k = [
            0.282095, 0.488603, 0.488603, 0.488603, 1.092548, 1.092548, 0.315392, 1.092548,
            0.546274,
        ];
        for i in 0..9 {
            assert!((p[i][0] - c[i][0] as f64 * k[i]).abs() < 1e-5, "{i}");
        }
    }

    /// Unity's published path, ported from Unity-Technologies/Graphics
    /// `Packages/com.unity.render-pipelines.core/ShaderLibrary/SphericalHarmonics.hlsl`: raw
    /// radiance coefficients in Unity's signed basis, pre-multiplied by kSHBasisCoef and
    /// kClampedCosineCoefs, packed (PackSH) and evaluated (SHEvalLinearL0L1 + SHEvalLinearL2).
    #[test]
    #[allow(clippy::excessive_precision)] // Unity's constants as published
    fn unity_sh_matches_unitys_published_formulas() {
        const K: [f64; 9] = [
            0.28209479177387814347,
            -0.48860251190291992159,
            0.48860251190291992159,
            -0.48860251190291992159,
            1.09254843059207907054,
            -1.09254843059207907054,
            0.31539156525252000603,
            -1.09254843059207907054,
            0.54627421529603953527,
        ];
        const COS: [f64; 9] = [
            1.0,
            2.0 / 3.0,
            2.0 / 3.0,
            2.0 / 3.0,
            0.25,
            0.25,
            0.25,
            0.25,
            0.25,
        ];
        let c = coeffs();
        // Our radiance L(d) = Σ (π/Â_l c_i) Y_i(d); Unity sees it at u with d = (u.x, u.y, −u.z).
        let rad = three_radiance(&c);
        let radiance_unity = |u: Vec3| {
            eval_rgb(
                &rad.iter().map(|v| v.map(|x| x as f32)).collect::<Vec<_>>(),
                Vec3::new(u.x, u.y, -u.z),
            )
        };
        // Project onto Unity's signed basis Y^U_i = K_i·P_i by a fine quadrature (Fibonacci
        // points, equal weights 4π/n).
        let n = 200_000;
        let pts = fibonacci_sphere(n);
        let mut lu = [[0.0f64; 3]; 9];
        for &u in &pts {
            let l = radiance_unity(u);
            let p = polynomial_basis(u);
            for i in 0..9 {
                for ch in 0..3 {
                    lu[i][ch] += l[ch] as f64 * K[i] * p[i] * 4.0 * std::f64::consts::PI / n as f64;
                }
            }
        }
        let ours = unity_sh_l2(&c);
        for i in 0..9 {
            for ch in 0..3 {
                let premultiplied = lu[i][ch] * K[i] * COS[i];
                assert!(
                    (premultiplied - ours[ch][i]).abs() < 2e-4,
                    "coefficient {i} channel {ch}: {premultiplied} vs {}",
                    ours[ch][i]
                );
            }
        }
        // SampleSH9 on the packed constants is E/π in Unity's frame.
        let k = unity_shader_constants(&ours);
        for u in dirs() {
            let (x, y, z) = (u.x as f64, u.y as f64, u.z as f64);
            let va = [x, y, z, 1.0];
            let vb = [x * y, y * z, z * z, z * x];
            let vc = x * x - y * y;
            let dot = |a: [f64; 4], b: [f64; 4]| a.iter().zip(b).map(|(p, q)| p * q).sum::<f64>();
            let expect = eval_rgb(&c, Vec3::new(u.x, u.y, -u.z));
            for ch in 0..3 {
                let e = dot(k[ch], va) + dot(k[3 + ch], vb) + k[6][ch] * vc;
                assert!((e - expect[ch] as f64).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn light_probe_uuids_differ_per_content_and_repeat_per_run() {
        let c = coeffs();
        let mut d = c.clone();
        d[0][0] += 0.25;
        let (a, a2, b) = (
            three_light_probe_json(&c),
            three_light_probe_json(&c),
            three_light_probe_json(&d),
        );
        let u = a["object"]["uuid"].as_str().unwrap().to_string();
        assert_eq!(u, a2["object"]["uuid"].as_str().unwrap());
        assert_ne!(u, b["object"]["uuid"].as_str().unwrap());
        assert_ne!(u, "6c1b3f3e-6a8e-4f0e-9b1a-1b1ba5eb1b00");
        // RFC 9562 layout: 8-4-4-4-12 hex, version 8, variant 10.
        let parts: Vec<&str> = u.split('-').collect();
        assert_eq!(
            parts.iter().map(|p| p.len()).collect::<Vec<_>>(),
            [8, 4, 4, 4, 12]
        );
        assert!(u.chars().all(|ch| ch == '-' || ch.is_ascii_hexdigit()));
        assert!(parts[2].starts_with('8'), "{u}");
        assert!(matches!(&parts[3][..1], "8" | "9" | "a" | "b"), "{u}");
    }

    #[test]
    fn three_probe_json_is_radiance_in_our_basis() {
        // three's getIrradianceAt (SphericalHarmonics3.js): Σ L_i·Â_l·Y_i, constants as there.
        let c = coeffs();
        let j = three_light_probe_json(&c);
        assert_eq!(j["object"]["type"], "LightProbe");
        let sh: Vec<f64> = j["object"]["sh"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(sh.len(), 27);
        for n in dirs() {
            let (x, y, z) = (n.x as f64, n.y as f64, n.z as f64);
            let w = [
                0.886227,
                2.0 * 0.511664 * y,
                2.0 * 0.511664 * z,
                2.0 * 0.511664 * x,
                2.0 * 0.429043 * x * y,
                2.0 * 0.429043 * y * z,
                0.743125 * z * z - 0.247708,
                2.0 * 0.429043 * x * z,
                0.429043 * (x * x - y * y),
            ];
            let ours = eval_rgb(&c, n);
            for ch in 0..3 {
                let e: f64 = (0..9).map(|i| sh[3 * i + ch] * w[i]).sum();
                assert!((e / std::f64::consts::PI - ours[ch] as f64).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn filament_text_forms() {
        let mut p = [[0.0f64; 3]; 9];
        p[0] = [0.793924391269684, 0.837475955486298, 0.940771281719208];
        p[3] = [-0.005460172425956, -1.0e-7, 123456.7];
        let txt = filament_sh_txt(&p);
        let lines: Vec<&str> = txt.lines().collect();
        assert_eq!(lines.len(), 9);
        assert_eq!(lines[0], "( 0.793924391269684,  0.837475955486298,  0.940771281719208); // L00, irradiance, pre-scaled base");
        assert!(lines[1].ends_with("// L1-1, irradiance, pre-scaled base"));
        assert!(lines[8].ends_with("// L22, irradiance, pre-scaled base"));
        let meta = filament_ktx_sh_metadata(&p);
        let first: Vec<&str> = meta.lines().collect();
        assert_eq!(first[0], "0.793924 0.837476 0.940771");
        assert_eq!(first[3], "-0.00546017 -1e-07 123457");
        assert_eq!(first[1], "0 0 0");
        // What Filament parses back (whitespace-separated floats) is p to 6 digits.
        for (line, v) in first.iter().zip(p) {
            let got: Vec<f64> = line
                .split_whitespace()
                .map(|s| s.parse().unwrap())
                .collect();
            for k in 0..3 {
                assert!((got[k] - v[k]).abs() <= 5e-6 * v[k].abs().max(1e-30));
            }
        }
        assert_eq!(fmt_g6(1e6), "1e+06");
        assert_eq!(fmt_g6(999999.7), "1e+06");
        assert_eq!(fmt_g6(0.0001), "0.0001");
        assert_eq!(fmt_g6(0.00001234567), "1.23457e-05");
    }
}
