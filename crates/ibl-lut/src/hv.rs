//! The Ashikhmin-Shirley half-vector LUT of Marcolongo 2020 §4.3.2 (`halfVectorSampling.exe`):
//! texel (i, j) holds the half vector sampled from (ξ1, ξ2) = ((i+0.5)/W, (j+0.5)/H), i.e. at
//! texel centres with row 0 first (ξ2 = 0.5/H, next to the normal):
//!   RGB = h·0.5 + 0.5 in tangent space (R along t, G along b, B along n),
//!   A   = p_h(h)/p_h(n) = (n·h)^{e(h)} ∈ [0, 1].
//! A JSON sidecar records n_u, n_v and p_h(n) = √((n_u+1)(n_v+1))/(2π), so a shader restores
//! p_h(h) = A·p_h(n). EXR float by default; PNG 8/16-bit as the thesis (which wrote 8-bit PNG;
//! note that 8 bits quantise h in steps of 2/255, coarser than the lobe of n ≳ 10⁴, which the
//! benchmark measures).

use crate::error::{Error, Result};
use crate::table::{self, map_rows, texel_centre, Baked, Format};
use glam::DVec3;
use ibl_brdf::AshikhminShirley;
use ibl_core::io::{self, FloatDepth, WriteOptions};
use ibl_core::progress::Progress;
use ibl_core::Image;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The exponent range the bakes accept (and test): 1 ≤ n ≤ 10⁶.
pub(crate) const EXPONENT_RANGE: (f64, f64) = (1.0, 1e6);

/// Checks an AS exponent given as `--name`.
pub(crate) fn check_exponent(name: &str, value: Option<f64>) -> Result<f64> {
    let v = value.ok_or_else(|| Error::param(format!("--{name} is required")))?;
    if !v.is_finite() || v < EXPONENT_RANGE.0 || v > EXPONENT_RANGE.1 {
        return Err(Error::param(format!(
            "--{name} {v} is out of range {}..={:e}",
            EXPONENT_RANGE.0, EXPONENT_RANGE.1
        )));
    }
    Ok(v)
}

/// The lobe of `--nu` and `--nv`, both checked against [`EXPONENT_RANGE`] (the first
/// check of every Ashikhmin-Shirley bake).
pub fn lobe(nu: Option<f64>, nv: Option<f64>) -> Result<AshikhminShirley> {
    let nu = check_exponent("nu", nu)?;
    let nv = check_exponent("nv", nv)?;
    Ok(AshikhminShirley::new(nu, nv))
}

/// `out` itself, or with thesis names `out/STEM[NU,NV].png` (see [`thesis_file_name`]).
pub(crate) fn thesis_or_plain_path(
    out: &Path,
    thesis_names: bool,
    stem: &str,
    a: &AshikhminShirley,
) -> PathBuf {
    if thesis_names {
        out.join(thesis_file_name(stem, a.nu, a.nv))
    } else {
        out.to_path_buf()
    }
}

/// Parameters of `hv-lut`: CLI flags and RON keys alike.
#[derive(Clone, Debug, PartialEq, clap::Args, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Shininess exponent n_u along the tangent (1 ..= 1e6).
    #[arg(
        long,
        value_name = "NU",
        required = true,
        allow_negative_numbers = true
    )]
    pub nu: Option<f64>,
    /// Shininess exponent n_v along the bitangent (1 ..= 1e6).
    #[arg(
        long,
        value_name = "NV",
        required = true,
        allow_negative_numbers = true
    )]
    pub nv: Option<f64>,
    /// LUT side in texels (size × size).
    #[arg(
        long,
        value_name = "N",
        default_value_t = 256,
        allow_negative_numbers = true
    )]
    pub size: usize,
    /// PNG bit depth (8 as the thesis, or 16).
    #[arg(long, value_name = "8|16", default_value_t = 16)]
    pub bits: u8,
    /// Treat -o as a folder and name the file halfVectorSampling[NU,NV].png as the thesis does.
    #[arg(long)]
    pub thesis_names: bool,
    /// Write half floats in EXR outputs.
    #[arg(long)]
    pub half: bool,
}

impl Default for Params {
    fn default() -> Self {
        ibl_core::params::clap_defaults()
    }
}

impl Params {
    /// Checks the parameters and returns the distribution.
    pub fn validate(&self) -> Result<AshikhminShirley> {
        let a = lobe(self.nu, self.nv)?;
        table::check_size("size", self.size)?;
        if self.bits != 8 && self.bits != 16 {
            return Err(Error::param(format!(
                "--bits {} must be 8 or 16",
                self.bits
            )));
        }
        Ok(a)
    }
}

/// The thesis's file name for a LUT: `halfVectorSampling[NU,NV].png` (§4.3.2; §5.2 prints it
/// with a space before '[' — we follow §4.3.2), numbers in their shortest decimal form.
pub(crate) fn thesis_file_name(stem: &str, nu: f64, nv: f64) -> String {
    format!("{stem}[{nu},{nv}].png")
}

/// The LUT as an RGBA float image.
pub fn hv_table(a: &AshikhminShirley, size: usize, progress: &dyn Progress) -> Image {
    map_rows(size, size, 4, progress, |j, row| {
        let xi2 = texel_centre(j, size);
        for (i, t) in row.chunks_exact_mut(4).enumerate() {
            let s = a.sample(texel_centre(i, size), xi2);
            t[0] = (s.h.x * 0.5 + 0.5) as f32;
            t[1] = (s.h.y * 0.5 + 0.5) as f32;
            t[2] = (s.h.z * 0.5 + 0.5) as f32;
            t[3] = s.ratio as f32;
        }
    })
}

/// Reads a half vector back from a LUT at (ξ1, ξ2) as a GPU would: bilinear between texel
/// centres, clamped to the edge, decoded (2·RGB − 1) and renormalised; also the interpolated
/// pdf ratio A.
pub fn lookup(lut: &Image, xi1: f64, xi2: f64) -> (DVec3, f64) {
    let (w, h) = (lut.width, lut.height);
    let x = (xi1 * w as f64 - 0.5).clamp(0.0, (w - 1) as f64);
    let y = (xi2 * h as f64 - 0.5).clamp(0.0, (h - 1) as f64);
    let (x0, y0) = (x.floor() as usize, y.floor() as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let (fx, fy) = (x - x0 as f64, y - y0 as f64);
    let mut c = [0.0f64; 4];
    for (xx, yy, wt) in [
        (x0, y0, (1.0 - fx) * (1.0 - fy)),
        (x1, y0, fx * (1.0 - fy)),
        (x0, y1, (1.0 - fx) * fy),
        (x1, y1, fx * fy),
    ] {
        for (k, v) in lut.texel(xx, yy).iter().enumerate() {
            c[k] += wt * *v as f64;
        }
    }
    let hv = DVec3::new(2.0 * c[0] - 1.0, 2.0 * c[1] - 1.0, 2.0 * c[2] - 1.0);
    let len = hv.length();
    let hv = if len > 0.0 { hv / len } else { DVec3::Z };
    (hv, c[3])
}

/// The sidecar the shader reads to restore p_h.
#[derive(Serialize, serde::Deserialize, Debug, PartialEq)]
pub struct Sidecar {
    /// What the table is, with its reference (Marcolongo 2020 §4.3.2).
    pub table: String,
    /// The version of the tool that wrote it.
    pub tool_version: String,
    /// Phong exponent n_u of the lobe.
    pub nu: f64,
    /// Phong exponent n_v of the lobe.
    pub nv: f64,
    /// p_h(n) = √((n_u+1)(n_v+1))/(2π): multiply A by it to get p_h(h).
    pub p_h_n: f64,
    /// Edge length of the square table in texels.
    pub size: usize,
    /// File name of the table image beside the sidecar.
    pub image: String,
    /// How the image stores values (PNG bits, EXR half or float).
    pub encoding: String,
    /// How texel (i, j) maps to (ξ₁, ξ₂) and how the channels encode h and the pdf ratio.
    pub layout: String,
}

/// Why `-o` must name an image.
const IMAGE_ONLY: &str = "the half-vector LUT is an image";

/// Output paths: (image, sidecar).
pub fn output_paths(
    params: &Params,
    a: &AshikhminShirley,
    out: &Path,
) -> Result<(PathBuf, PathBuf)> {
    let image = thesis_or_plain_path(out, params.thesis_names, "halfVectorSampling", a);
    Format::image_of(&image, IMAGE_ONLY)?;
    Ok((image.clone(), image.with_extension("json")))
}

/// Bakes the LUT and encodes it and its sidecar.
pub fn run(params: &Params, out: &Path, progress: &dyn Progress) -> Result<Baked> {
    let a = params.validate()?;
    let (image_path, sidecar_path) = output_paths(params, &a, out)?;
    let image = hv_table(&a, params.size, progress);
    if image.data.iter().any(|v| !v.is_finite()) {
        return Err(Error::param("internal error: non-finite half-vector texel"));
    }
    let is_png = Format::image_of(&image_path, IMAGE_ONLY)? == Format::Png;
    let opts = WriteOptions {
        float: if params.half {
            FloatDepth::F16
        } else {
            FloatDepth::F32
        },
        png_bits: params.bits,
        png_tonemap: false,
        png_srgb: false,
    };
    let bytes = io::encode_image(&image_path, &image, &opts)?;
    let sidecar = Sidecar {
        table: "Ashikhmin-Shirley half-vector LUT (Marcolongo 2020 section 4.3.2)".into(),
        tool_version: ibl_core::TOOL_VERSION.into(),
        nu: a.nu,
        nv: a.nv,
        p_h_n: a.pdf_h_at_normal(),
        size: params.size,
        image: image_path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default(),
        encoding: if is_png { format!("PNG {}-bit, linear", params.bits) } else if params.half { "EXR half".into() } else { "EXR float".into() },
        layout: "texel (i,j): xi1 = (i+0.5)/W, xi2 = (j+0.5)/H, row 0 first; RGB = h*0.5+0.5 in tangent space \
                 (R: t, G: b, B: n); A = p_h(h)/p_h(n), so p_h(h) = A * p_h_n"
            .into(),
    };
    let side = io::data::encode(&sidecar_path, &sidecar)?;
    let details = serde_json::json!({ "table": "hv", "nu": a.nu, "nv": a.nv, "p_h_n": a.pdf_h_at_normal(), "size": params.size });
    Ok(Baked {
        files: vec![(image_path, bytes), (sidecar_path, side)],
        image,
        details,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::progress::NoProgress;

    #[test]
    fn defaults_and_validation() {
        let p: Params = ron::from_str("()").unwrap();
        assert_eq!(p, Params::default());
        assert_eq!((p.size, p.bits, p.nu), (256, 16, None));
        assert!(p.validate().is_err(), "nu and nv are required");
        let ok = Params {
            nu: Some(20000.0),
            nv: Some(70.0),
            ..Default::default()
        };
        assert!(ok.validate().is_ok());
        for bad in [
            Params {
                nu: Some(0.0),
                ..ok.clone()
            },
            Params {
                nv: Some(f64::NAN),
                ..ok.clone()
            },
            Params {
                nu: Some(2e6),
                ..ok.clone()
            },
            Params {
                size: 0,
                ..ok.clone()
            },
            Params {
                bits: 12,
                ..ok.clone()
            },
        ] {
            assert!(bad.validate().is_err(), "{bad:?}");
        }
    }

    #[test]
    fn texels_decode_to_the_sampled_half_vectors() {
        let a = AshikhminShirley::new(20000.0, 70.0);
        let n = 16;
        let img = hv_table(&a, n, &NoProgress);
        for j in 0..n {
            for i in 0..n {
                let t = img.texel(i, j);
                let s = a.sample(texel_centre(i, n), texel_centre(j, n));
                let h = DVec3::new(
                    2.0 * t[0] as f64 - 1.0,
                    2.0 * t[1] as f64 - 1.0,
                    2.0 * t[2] as f64 - 1.0,
                );
                assert!((h - s.h).length() < 1e-6);
                assert!((t[3] as f64 - a.pdf_h(s.h) / a.pdf_h_at_normal()).abs() < 1e-5);
                // At a texel centre, the lookup returns the texel itself.
                let (hl, r) = lookup(&img, texel_centre(i, n), texel_centre(j, n));
                assert!((hl - s.h).length() < 1e-6 && (r - t[3] as f64).abs() < 1e-7);
            }
        }
    }

    #[test]
    fn every_texel_is_finite_over_the_exponent_range() {
        for nu in [1.0, 70.0, 20000.0, 1e6] {
            for nv in [1.0, 1e6] {
                let img = hv_table(&AshikhminShirley::new(nu, nv), 32, &NoProgress);
                assert!(
                    img.data
                        .iter()
                        .all(|v| v.is_finite() && (0.0..=1.0).contains(v)),
                    "{nu} {nv}"
                );
            }
        }
    }

    #[test]
    fn shared_lobe_check_and_output_path() {
        assert_eq!(
            lobe(Some(20000.0), Some(70.0)).unwrap(),
            AshikhminShirley::new(20000.0, 70.0)
        );
        for (nu, nv, flag) in [
            (None, Some(1.0), "--nu"),
            (Some(1.0), Some(0.5), "--nv"),
            (Some(2e6), Some(1.0), "--nu"),
        ] {
            let e = lobe(nu, nv).unwrap_err().to_string();
            assert!(e.contains(flag), "{e}");
        }
        let a = AshikhminShirley::new(1.5, 70.0);
        let out = Path::new("dir");
        assert_eq!(thesis_or_plain_path(out, false, "x", &a), out);
        assert_eq!(
            thesis_or_plain_path(out, true, "x", &a),
            out.join("x[1.5,70].png")
        );
    }

    #[test]
    fn thesis_names() {
        assert_eq!(
            thesis_file_name("halfVectorSampling", 20000.0, 70.0),
            "halfVectorSampling[20000,70].png"
        );
        assert_eq!(
            thesis_file_name("brdfIntegration", 1.5, 1e6),
            "brdfIntegration[1.5,1000000].png"
        );
    }
}
