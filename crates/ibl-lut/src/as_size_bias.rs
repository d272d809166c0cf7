//! The Ashikhmin-Shirley "size/bias" table of Marcolongo 2020 §4.3.3 (`brdfIntegration.exe`).
//!
//! With Schlick's F = F0(1 − χ) + χ, χ = (1 − v·h)⁵, and the AS BRDF written through the
//! light density p_l = p_h/(4 v·h) as f_s = p_l(l) F / max(n·v, n·l) (§2.4), the split-sum
//! BRDF integral is F0·s(v) + b(v) with
//!   s(v) = ∫ p_l(l) (1 − χ) (n·l)/max(n·v, n·l) dl,   b(v) = ∫ p_l(l) χ (n·l)/max(n·v, n·l) dl,
//! the "size" (slope) and "bias" (intercept) of a line in F0. Both are expectations under
//! l ~ p_l, estimated as (1/N) Σ over half vectors h_i ~ p_h, l_i = 2(v·h_i)h_i − v, where a
//! sample whose l falls below the horizon (or whose h faces away from v) contributes 0 —
//! that lost energy is the darkening the thesis describes for rough exponents.
//! Erratum (§4.3.3): the printed sums lack their 1/N.
//!
//! Layout (docs/CONVENTIONS.md, thesis): column s = (2/π) atan(|b·v|/|t·v|), row t = √(n·v), at texel
//! centres; inverse (t·v, b·v, n·v) = (cos(πs/2)√(1−t⁴), sin(πs/2)√(1−t⁴), t²). AS has
//! rectangular symmetry, so the quarter of azimuths covers them all. R = size, G = bias
//! (PNG adds B = 0, as the thesis does).
//!
//! Half vectors come either from the AS formulas directly (default: exact, any exponent) or,
//! as the thesis does, through a half-vector LUT (`--sampler hv-lut`, a float LUT of
//! `--hv-size`² built in memory and read bilinearly); the tests measure their agreement.

use crate::error::{Error, Result};
use crate::hv;
use crate::table::{self, map_rows, texel_centre, Baked, Describe, Format};
use glam::DVec3;
use ibl_brdf::AshikhminShirley;
use ibl_core::progress::{NoProgress, Progress};
use ibl_core::sampling::hammersley;
use ibl_core::Image;
use std::f64::consts::FRAC_PI_2;
use std::path::{Path, PathBuf};

/// Where the half vectors of the estimator come from.
///
/// CLI values are `direct` and `hv-lut`; in RON the second is `hv_lut` (RON identifiers
/// cannot hold '-'), in JSON either spelling.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "snake_case")]
pub enum Sampler {
    /// The AS sampling formulas (Marcolongo 2020 §4.3.2) evaluated in f64.
    #[default]
    Direct,
    /// A float half-vector LUT of `hv_size`² texels, read bilinearly (the thesis's route).
    #[value(alias = "hv_lut")]
    #[serde(alias = "hv-lut")]
    HvLut,
}

/// Parameters of the `as-size-bias` bake: CLI flags and RON keys alike.
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
    /// Table side in texels (size × size).
    #[arg(
        long,
        value_name = "N",
        default_value_t = 64,
        allow_negative_numbers = true
    )]
    pub size: usize,
    /// Hammersley samples per texel.
    #[arg(
        long,
        value_name = "N",
        default_value_t = 1024,
        allow_negative_numbers = true
    )]
    pub samples: u32,
    /// Half-vector source: the AS formulas, or a half-vector LUT as in the thesis.
    #[arg(long, value_enum, default_value_t = Sampler::Direct)]
    pub sampler: Sampler,
    /// Side of the half-vector LUT used by `--sampler hv-lut`.
    #[arg(
        long,
        value_name = "N",
        default_value_t = 256,
        allow_negative_numbers = true
    )]
    pub hv_size: usize,
    /// Treat -o as a folder and name the file brdfIntegration[NU,NV].png as the thesis does.
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
    /// Checks the parameters before any work and returns the lobe they describe.
    pub fn validate(&self) -> Result<AshikhminShirley> {
        let a = hv::lobe(self.nu, self.nv)?;
        table::check_size("size", self.size)?;
        table::check_size("hv-size", self.hv_size)?;
        table::check_samples(self.samples)?;
        Ok(a)
    }
}

/// The view vector of table coordinates (s, t) (the thesis's inverse mapping).
pub fn view_of(s: f64, t: f64) -> DVec3 {
    let (sp, cp) = (FRAC_PI_2 * s).sin_cos();
    let nv = t * t;
    let st = (1.0 - nv * nv).max(0.0).sqrt();
    DVec3::new(cp * st, sp * st, nv)
}

#[cfg(test)]
/// The table coordinates (s, t) of a view vector (the thesis's forward mapping, valid for any
/// azimuth thanks to the rectangular symmetry).
pub(crate) fn coords_of(v: DVec3) -> (f64, f64) {
    let s = if v.x == 0.0 && v.y == 0.0 {
        0.0
    } else {
        v.y.abs().atan2(v.x.abs()) / FRAC_PI_2
    };
    (s, v.z.max(0.0).sqrt())
}

/// The half vectors of one bake: h_i for the first N Hammersley points (built once, shared by
/// every texel).
#[derive(Clone, Debug)]
pub struct SampleSet {
    /// The unit half vectors h drawn from p_h (tangent space, +z the normal).
    pub h: Vec<DVec3>,
}

impl SampleSet {
    /// From the AS sampling formulas.
    pub fn direct(a: &AshikhminShirley, samples: u32) -> Self {
        SampleSet {
            h: (0..samples)
                .map(|i| xi(i, samples))
                .map(|(x1, x2)| a.sample(x1, x2).h)
                .collect(),
        }
    }

    /// Through a half-vector LUT, as the thesis's `brdfIntegration.exe` does.
    pub fn through_lut(lut: &Image, samples: u32) -> Self {
        SampleSet {
            h: (0..samples)
                .map(|i| xi(i, samples))
                .map(|(x1, x2)| hv::lookup(lut, x1, x2).0)
                .collect(),
        }
    }
}

fn xi(i: u32, n: u32) -> (f64, f64) {
    let (a, b) = hammersley(i, n);
    (a as f64, b as f64)
}

/// (size, bias) at the unit view `v` (v.z > 0) from the sample set.
pub fn size_bias(set: &SampleSet, v: DVec3) -> [f64; 2] {
    let (mut s, mut b) = (0.0, 0.0);
    for &h in &set.h {
        let vh = v.dot(h);
        if vh <= 0.0 {
            continue;
        }
        let nl = 2.0 * vh * h.z - v.z;
        if nl <= 0.0 {
            continue;
        }
        let w = nl / v.z.max(nl);
        let chi = (1.0 - vh).clamp(0.0, 1.0).powi(5);
        s += w * (1.0 - chi);
        b += w * chi;
    }
    let n = set.h.len() as f64;
    [s / n, b / n]
}

/// The sample set the parameters ask for.
pub(crate) fn sample_set(a: &AshikhminShirley, params: &Params) -> SampleSet {
    match params.sampler {
        Sampler::Direct => SampleSet::direct(a, params.samples),
        Sampler::HvLut => SampleSet::through_lut(
            &hv::hv_table(a, params.hv_size, &NoProgress),
            params.samples,
        ),
    }
}

/// The whole table: size × size, R = size, G = bias.
pub fn size_bias_table(set: &SampleSet, size: usize, progress: &dyn Progress) -> Image {
    map_rows(size, size, 2, progress, |j, row| {
        let t = texel_centre(j, size);
        for (i, px) in row.chunks_exact_mut(2).enumerate() {
            let [s, b] = size_bias(set, view_of(texel_centre(i, size), t));
            px[0] = s as f32;
            px[1] = b as f32;
        }
    })
}

/// How the bias table describes itself in its JSON/RON dump.
pub fn describe(params: &Params) -> Describe<'static> {
    Describe {
        table:
            "Ashikhmin-Shirley size/bias (Marcolongo 2020 section 4.3.3): integral = F0*size + bias",
        channels: &["size s(v)", "bias b(v)"],
        s: "(2/pi) atan(|b.v|/|t.v|) at texel centres (i+0.5)/W",
        t: "sqrt(n.v) at texel centres (j+0.5)/H, row 0 first",
        params: serde_json::to_value(params).expect("params serialise"),
    }
}

/// The output path: `out`, or `out/brdfIntegration[NU,NV].png` with thesis names.
pub fn output_path(params: &Params, a: &AshikhminShirley, out: &Path) -> Result<PathBuf> {
    let p = hv::thesis_or_plain_path(out, params.thesis_names, "brdfIntegration", a);
    Format::of(&p)?;
    Ok(p)
}

/// Bakes the table and encodes it.
pub fn run(params: &Params, out: &Path, progress: &dyn Progress) -> Result<Baked> {
    let a = params.validate()?;
    let path = output_path(params, &a, out)?;
    let set = sample_set(&a, params);
    let image = size_bias_table(&set, params.size, progress);
    if image.data.iter().any(|v| !v.is_finite()) {
        return Err(Error::param("internal error: non-finite size/bias texel"));
    }
    let bytes = table::encode(&path, &image, &describe(params), 16, params.half)?;
    let details = serde_json::json!({
        "table": "as-size-bias", "nu": a.nu, "nv": a.nv, "size": params.size,
        "samples": params.samples, "sampler": params.sampler,
    });
    Ok(Baked {
        files: vec![(path, bytes)],
        image,
        details,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference::AsReference;

    fn ron<T: serde::de::DeserializeOwned>(s: &str) -> Result<T, ron::error::SpannedError> {
        ron::Options::default()
            .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
            .from_str(s)
    }

    #[test]
    fn defaults_and_validation() {
        let p: Params = ron("(nu: 20000, nv: 70)").unwrap();
        assert_eq!(
            (p.size, p.samples, p.sampler, p.hv_size),
            (64, 1024, Sampler::Direct, 256)
        );
        assert!(p.validate().is_ok());
        assert!(Params::default().validate().is_err());
        assert!(Params {
            samples: 0,
            ..p.clone()
        }
        .validate()
        .is_err());
        assert!(Params {
            nv: Some(0.5),
            ..p.clone()
        }
        .validate()
        .is_err());
        let q: Params = ron("(nu: 1, nv: 1.5, sampler: hv_lut, hv_size: 32)").unwrap();
        assert_eq!((q.sampler, q.nv), (Sampler::HvLut, Some(1.5)));
        assert!(ron::<Params>("(nu: 1, nv: 1, smaples: 3)").is_err());
    }

    #[test]
    fn view_mapping_round_trips() {
        // (t = 1 is the normal, where the azimuth s is undefined.)
        for &(s, t) in &[
            (0.0, 0.5),
            (0.3, 0.7),
            (1.0, 0.999),
            (0.99, 0.01),
            (0.0, 1.0),
        ] {
            let v = view_of(s, t);
            assert!((v.length() - 1.0).abs() < 1e-12);
            let (s2, t2) = coords_of(v);
            assert!(
                (s - s2).abs() < 1e-7 && (t - t2).abs() < 1e-12,
                "{s} {t} {s2} {t2}"
            );
            // Rectangular symmetry: flipping t or b gives the same coordinates.
            assert_eq!(coords_of(DVec3::new(-v.x, -v.y, v.z)), (s2, t2));
        }
    }

    #[test]
    fn direct_table_matches_the_quadrature_reference() {
        let reference = AsReference::new(256);
        for (nu, nv) in [(100.0, 10.0), (20000.0, 70.0), (1.0, 1.0)] {
            let a = AshikhminShirley::new(nu, nv);
            let set = SampleSet::direct(&a, 1024);
            let size = 8;
            let img = size_bias_table(&set, size, &NoProgress);
            let (mut sum, mut worst) = (0.0f64, 0.0f64);
            for j in 0..size {
                for i in 0..size {
                    let r = reference
                        .size_bias(&a, view_of(texel_centre(i, size), texel_centre(j, size)));
                    for (c, rc) in r.iter().enumerate() {
                        let e = (img.texel(i, j)[c] as f64 - rc).abs();
                        sum += e;
                        worst = worst.max(e);
                    }
                }
            }
            let mean = sum / (2 * size * size) as f64;
            eprintln!(
                "AS({nu},{nv}) 8² × 1024 vs quadrature: mean abs error {mean:.2e}, max {worst:.2e}"
            );
            assert!(mean < 3e-3 && worst < 2e-2, "{mean} {worst}");
        }
    }

    #[test]
    fn hv_lut_route_agrees_with_the_direct_formulas() {
        for (nu, nv) in [(100.0, 10.0), (1000.0, 50.0)] {
            let a = AshikhminShirley::new(nu, nv);
            let direct = size_bias_table(&SampleSet::direct(&a, 1024), 8, &NoProgress);
            let lut = hv::hv_table(&a, 256, &NoProgress);
            let via = size_bias_table(&SampleSet::through_lut(&lut, 1024), 8, &NoProgress);
            let worst = direct
                .data
                .iter()
                .zip(&via.data)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0f32, f32::max);
            let mean = direct
                .data
                .iter()
                .zip(&via.data)
                .map(|(x, y)| (x - y).abs())
                .sum::<f32>()
                / direct.data.len() as f32;
            eprintln!(
                "AS({nu},{nv}) direct vs 256² float hv-lut: mean {mean:.2e}, max {worst:.2e}"
            );
            assert!(mean < 2e-3 && worst < 1e-2);
        }
    }

    #[test]
    fn every_texel_is_finite_over_the_exponent_range() {
        for nu in [1.0, 20000.0, 1e6] {
            for nv in [1.0, 70.0, 1e6] {
                let a = AshikhminShirley::new(nu, nv);
                let img = size_bias_table(&SampleSet::direct(&a, 64), 16, &NoProgress);
                assert!(
                    img.data
                        .chunks(2)
                        .all(|t| t.iter().all(|v| v.is_finite() && *v >= 0.0)
                            && t[0] + t[1] <= 1.0 + 1e-6),
                    "{nu} {nv}"
                );
            }
        }
        // n·v → 0 and n·v = 1 exactly.
        let set = SampleSet::direct(&AshikhminShirley::new(1e6, 1.0), 256);
        for v in [view_of(0.5, 1e-9), view_of(0.0, 1.0), view_of(1.0, 1.0)] {
            let [s, b] = size_bias(&set, v);
            assert!(s.is_finite() && b.is_finite());
        }
    }
}
