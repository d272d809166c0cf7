//! The `quat-map` bake (Marcolongo 2020 §3.4): a normal map to the map of the quaternions that
//! rotate the tangent frame onto each texel's normal, stored as q·0.5 + 0.5 in RGB, with a
//! `--check` that decodes what was written back to frames and measures it.

use crate::normal::{
    convention_check, ConventionCheck, Decoder, Decoding, NormalImage, RawTexel, Texel,
};
use crate::quaternion::{
    angle_between, decode_quat, encode_quat, frame_from_quat, handedness, normalize_quat,
    orthonormality_error, quantisation_bound, quat_from_vector, storage_eps, StorageDepth,
};
use crate::Result;
use ibl_core::io::{self, ColorSpace, WriteOptions};
use ibl_core::progress::Progress;
use ibl_core::traverse::ordered_row_reduce;
use ibl_core::{Error, Image};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Parameters of the bake: CLI flags and RON keys alike.
/// One struct serves one file (`quat-map NORMAL -o OUT`) and a batch (`--batch DIR`, the
/// last three fields), flat so that every field is one flag and one RON key.
#[derive(Clone, Debug, PartialEq, clap::Args, serde::Serialize, serde::Deserialize)]
#[group(id = "quat_map::Params")]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Green points down the image (DirectX convention): flip it before converting.
    #[arg(long)]
    pub y_down: bool,
    /// Two-channel (BC5-style) map: x, y from R, G (grey, alpha for a grey+alpha PNG);
    /// z = sqrt(max(0, 1 − x² − y²)).
    #[arg(long)]
    pub two_channel: bool,
    /// Texels store the vector itself (float maps in [−1, 1]), not v·0.5 + 0.5.
    #[arg(long)]
    pub signed: bool,
    /// Decoded normals shorter than this carry no direction: stored as the identity and counted.
    #[arg(long, value_name = "L", default_value_t = 0.01)]
    pub min_length: f64,
    /// PNG output bit depth: 16 or 8.
    #[arg(long, value_name = "8|16", default_value_t = 16)]
    pub bits: u8,
    /// EXR output: 16-bit half floats instead of 32-bit.
    #[arg(long)]
    pub half: bool,
    /// Store NaN/Inf input texels as the identity instead of refusing the input.
    #[arg(long)]
    pub sanitize: bool,
    /// Decode the encoded output (after quantisation) back to (t', b', n') and report the
    /// angular error of n' against the input normal and the deviation from orthonormality.
    #[arg(long)]
    pub check: bool,
    /// Batch: file name of the normal map in each material folder (case-insensitive, * and ?).
    #[arg(long, value_name = "GLOB", default_value = "normal.*")]
    pub input_name: String,
    /// Batch: file name of the quaternion map written beside it (.png or .exr); {stem} stands
    /// for the input's name without its extension, one output per matching file, so a flat
    /// folder converts in one go: --input-name "*_normal.png" --output-name "{stem}_quat.png".
    #[arg(long, value_name = "NAME", default_value = "quaternion.png")]
    pub output_name: String,
    /// Batch: convert even the outputs that are up to date.
    #[arg(long)]
    pub force: bool,
}

impl Default for Params {
    fn default() -> Self {
        ibl_core::params::clap_defaults()
    }
}

impl Params {
    /// Checks the parameters before any input is read.
    pub fn validate(&self) -> ibl_core::Result<()> {
        if self.bits != 8 && self.bits != 16 {
            return Err(Error::param(format!("--bits {} (use 8 or 16)", self.bits)));
        }
        if !(self.min_length.is_finite() && (0.0..1.0).contains(&self.min_length)) {
            return Err(Error::param(format!(
                "--min-length {} is out of range [0, 1)",
                self.min_length
            )));
        }
        Ok(())
    }

    /// Validation that depends on the output file's format.
    pub fn validate_output(&self, out: &Path) -> ibl_core::Result<()> {
        self.validate()?;
        crate::output::validate(out, self.bits, self.half, "quaternion maps")
    }

    /// How this run decodes the input normals.
    pub fn decoding(&self) -> Decoding {
        Decoding {
            y_down: self.y_down,
            two_channel: self.two_channel,
            signed: self.signed,
            min_length: self.min_length,
        }
    }

    /// The batch-only fields are at their defaults (one-file mode refuses them).
    pub fn batch_fields_are_default(&self) -> bool {
        let d = Params::default();
        self.input_name == d.input_name
            && self.output_name == d.output_name
            && self.force == d.force
    }

    /// Everything that changes the output's bytes (not `check`): the batch's skip key.
    pub(crate) fn output_key(&self) -> serde_json::Value {
        serde_json::json!({
            "y_down": self.y_down, "two_channel": self.two_channel, "signed": self.signed,
            "min_length": self.min_length, "bits": self.bits, "half": self.half, "sanitize": self.sanitize,
            "output_name": self.output_name,
        })
    }

    /// How the output stores its texels.
    pub fn storage(&self, out: &Path) -> StorageDepth {
        match (io::extension(out).as_str(), self.half) {
            ("exr", true) => StorageDepth::Half,
            ("exr", false) => StorageDepth::Float,
            _ => StorageDepth::Bits(self.bits),
        }
    }

    fn write_options(&self) -> WriteOptions {
        crate::output::write_options(self.bits, self.half)
    }
}

/// What the conversion met in the input.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ConvertStats {
    /// Texels converted.
    pub texels: u64,
    /// Shorter than `min_length`: stored as the identity.
    pub degenerate: u64,
    /// NaN/Inf texels stored as the identity (`--sanitize`).
    pub non_finite: u64,
    /// Exactly −z: the half-turn about t.
    pub antipodal: u64,
    /// z < 0: the normal points into the surface (valid rotations, suspicious data).
    pub back_facing: u64,
    /// Two-channel texels with x² + y² > 1 (z clamped to 0).
    pub outside_disk: u64,
    /// Decoded length below 0.5 before renormalising (warned about above 1% of the texels).
    pub short: u64,
    /// Range of decoded lengths of the texels with a direction (both 0 when none has one).
    pub min_length: f64,
    /// Largest decoded length among the texels with a direction.
    pub max_length: f64,
    /// Whether the slopes are more integrable with green flipped (DirectX vs OpenGL).
    pub convention: Option<ConventionCheck>,
    /// The y convention the map was read with.
    pub y_down: bool,
    /// How the input was read when its content and name disagree
    /// ([`crate::map::LoadedMap::read_as`]); a warning, not part of the reports.
    #[serde(skip)]
    pub read_as: Option<String>,
}

impl ConvertStats {
    fn merge(mut self, o: ConvertStats) -> ConvertStats {
        self.texels += o.texels;
        self.degenerate += o.degenerate;
        self.non_finite += o.non_finite;
        self.antipodal += o.antipodal;
        self.back_facing += o.back_facing;
        self.outside_disk += o.outside_disk;
        self.short += o.short;
        self.min_length = self.min_length.min(o.min_length);
        self.max_length = self.max_length.max(o.max_length);
        self
    }

    /// The identity of [`Self::merge`] (min_length +∞: call [`Self::finish`] at the end).
    fn empty() -> ConvertStats {
        ConvertStats {
            min_length: f64::INFINITY,
            max_length: 0.0,
            ..Default::default()
        }
    }

    /// After the last merge: no length counted (no texel with a direction) gives 0..0, not
    /// +∞..0 (which JSON cannot hold and would print as null).
    fn finish(mut self) -> ConvertStats {
        if self.min_length > self.max_length {
            self.min_length = 0.0;
            self.max_length = 0.0;
        }
        self
    }

    /// One-line warnings about unusual texels.
    pub fn warnings(&self, path: &Path) -> Vec<String> {
        let p = path.display();
        let mut w: Vec<String> = self.read_as.iter().cloned().collect();
        if self.degenerate > 0 {
            w.push(format!(
                "{p}: {} zero-length normal texel(s) stored as the identity quaternion",
                self.degenerate
            ));
        }
        if self.non_finite > 0 {
            w.push(format!(
                "{p}: {} NaN/Inf texel(s) stored as the identity quaternion (--sanitize)",
                self.non_finite
            ));
        }
        if self.back_facing > 0 {
            w.push(format!(
                "{p}: {} texel(s) with z < 0 (pointing into the surface; {} exactly −z)",
                self.back_facing, self.antipodal
            ));
        }
        if self.outside_disk > 0 {
            w.push(format!(
                "{p}: {} two-channel texel(s) outside the unit disk (z set to 0)",
                self.outside_disk
            ));
        }
        if let Some(c) = self.convention.as_ref().filter(|c| c.suggests_flip()) {
            let (looks, advice) = if self.y_down {
                ("y-up (OpenGL)", "drop --y-down")
            } else {
                ("y-down (DirectX)", "pass --y-down")
            };
            w.push(format!(
                "{p}: may be a {looks} normal map: its slopes integrate better with green flipped (agreement {:+.2}, −1..1); if so, {advice}",
                c.agreement
            ));
        }
        // Lossy 8-bit sources leave a few short texels; many mean the map was read wrongly.
        if self.short * 100 > self.texels {
            w.push(format!(
                "{p}: {} of {} texels decode shorter than 0.5 (not a normal map, or not stored as v·0.5 + 0.5?)",
                self.short, self.texels
            ));
        }
        w
    }
}

/// Converts every texel of a normal map; returns the encoded quaternion image (RGB in
/// [0, 1]) and what was met. Deterministic: rows are independent, stats merged in order.
pub fn convert(decoder: &Decoder, img: &Image, progress: &dyn Progress) -> (Image, ConvertStats) {
    let (w, ch) = (img.width, img.channels);
    let mut out = Image::new(img.width, img.height, 3);
    let identity = encode_quat([1.0, 0.0, 0.0]);
    let rows: Vec<ConvertStats> = ibl_core::traverse::map_image_rows_with(
        &mut out.data,
        w * 3,
        w,
        "quaternions",
        progress,
        || (),
        |_, j, orow| {
            let irow = &img.data[j * w * ch..(j + 1) * w * ch];
            let mut s = ConvertStats::empty();
            for (o, t) in orow.chunks_exact_mut(3).zip(irow.chunks_exact(ch)) {
                let rgb = match decoder.decode_raw(t) {
                    RawTexel::Vector {
                        v,
                        len,
                        outside_disk,
                    } => {
                        s.min_length = s.min_length.min(len);
                        s.max_length = s.max_length.max(len);
                        s.short += (len < 0.5) as u64;
                        s.outside_disk += outside_disk as u64;
                        s.back_facing += (v[2] < 0.0) as u64;
                        s.antipodal += (v[0] == 0.0 && v[1] == 0.0 && v[2] < 0.0) as u64;
                        encode_quat(quat_from_vector(v, len))
                    }
                    RawTexel::Degenerate { .. } => {
                        s.degenerate += 1;
                        identity
                    }
                    RawTexel::NonFinite => {
                        s.non_finite += 1;
                        identity
                    }
                };
                o.copy_from_slice(&rgb);
            }
            s.texels = w as u64;
            s
        },
    );
    let stats = rows
        .into_iter()
        .fold(ConvertStats::empty(), ConvertStats::merge)
        .finish();
    (out, stats)
}

/// What `--check` measured on the written (quantised) map.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CheckReport {
    /// Texels with a direction (degenerate and non-finite inputs are not compared).
    pub compared: u64,
    /// Angle between n' decoded from the stored quaternion and the input's unit normal.
    pub max_angle_error_rad: f64,
    /// Mean angle between n' decoded from the stored quaternion and the input's unit normal.
    pub mean_angle_error_rad: f64,
    /// The quantisation bound 2·asin(√3·eps) for the output's storage.
    pub angle_bound_rad: f64,
    /// max |f_i·f_j − δ_ij| of (t', b', n') from the stored q as a shader decodes it
    /// (the thesis's formulas, q not renormalised).
    pub max_orthonormality_error: f64,
    /// Its bound: the frame is |q|²·R, so the Gram error is | |q|⁴ − 1 | ≤ (1 + √3·eps)⁴ − 1.
    pub orthonormality_bound: f64,
    /// The same after renormalising q (what is left is floating-point rounding).
    pub max_orthonormality_error_renormalised: f64,
    /// Frames with det(t', b', n') ≤ 0 (must be 0).
    pub left_handed: u64,
    /// How the output stores its texels (the bound depends on it).
    pub storage: StorageDepth,
}

impl CheckReport {
    /// Whether every measured error is within its quantisation bound and no frame is left-handed.
    pub fn within_bounds(&self) -> bool {
        // 1e-6 rad / 1e-6 of slack for single-precision decoding of the input.
        self.left_handed == 0
            && self.max_angle_error_rad <= self.angle_bound_rad + 1e-6
            && self.max_orthonormality_error <= self.orthonormality_bound + 1e-6
    }

    /// The check as one line for the log.
    pub fn summary(&self) -> String {
        format!(
            "check: {} texels, n' error max {:.3e} rad ({:.4}°, bound {:.3e}), mean {:.3e} rad; orthonormality error {:.3e} (bound {:.3e}), {:.1e} renormalised; {} left-handed",
            self.compared,
            self.max_angle_error_rad,
            self.max_angle_error_rad.to_degrees(),
            self.angle_bound_rad,
            self.mean_angle_error_rad,
            self.max_orthonormality_error,
            self.orthonormality_bound,
            self.max_orthonormality_error_renormalised,
            self.left_handed
        )
    }
}

#[derive(Clone, Copy, Default)]
struct CheckRow {
    compared: u64,
    max_angle: f64,
    sum_angle: f64,
    max_ortho: f64,
    max_ortho_unit: f64,
    left_handed: u64,
}

impl CheckRow {
    fn merge(mut self, r: CheckRow) -> CheckRow {
        self.compared += r.compared;
        self.max_angle = self.max_angle.max(r.max_angle);
        self.sum_angle += r.sum_angle;
        self.max_ortho = self.max_ortho.max(r.max_ortho);
        self.max_ortho_unit = self.max_ortho_unit.max(r.max_ortho_unit);
        self.left_handed += r.left_handed;
        self
    }
}

/// Decodes the stored map back to frames and compares them with the input normals.
pub fn check(
    decoder: &Decoder,
    input: &Image,
    stored: &Image,
    storage: StorageDepth,
) -> ibl_core::Result<CheckReport> {
    if (stored.width, stored.height) != (input.width, input.height) || stored.channels < 3 {
        return Err(Error::param(
            "check: the decoded quaternion map does not match the input's size",
        ));
    }
    let (w, ich, sch) = (input.width, input.channels, stored.channels);
    let row = |j: usize| {
        let irow = &input.data[j * w * ich..(j + 1) * w * ich];
        let srow = &stored.data[j * w * sch..(j + 1) * w * sch];
        let mut r = CheckRow::default();
        for (t, s) in irow.chunks_exact(ich).zip(srow.chunks_exact(sch)) {
            let Texel::Unit { n, .. } = decoder.decode(t) else {
                continue;
            };
            let q = decode_quat(s);
            let f = frame_from_quat(q);
            let angle = angle_between(f[2], n);
            r.compared += 1;
            r.max_angle = r.max_angle.max(angle);
            r.sum_angle += angle;
            r.max_ortho = r.max_ortho.max(orthonormality_error(&f));
            let fu = frame_from_quat(normalize_quat(q));
            r.max_ortho_unit = r.max_ortho_unit.max(orthonormality_error(&fu));
            r.left_handed += (handedness(&f) <= 0.0) as u64;
        }
        r
    };
    let total = ordered_row_reduce(input.height, row, CheckRow::default(), CheckRow::merge);
    let eps = storage_eps(storage);
    Ok(CheckReport {
        compared: total.compared,
        max_angle_error_rad: total.max_angle,
        mean_angle_error_rad: if total.compared > 0 {
            total.sum_angle / total.compared as f64
        } else {
            0.0
        },
        angle_bound_rad: quantisation_bound(eps),
        max_orthonormality_error: total.max_ortho,
        orthonormality_bound: (1.0 + 3f64.sqrt() * eps).powi(4) - 1.0,
        max_orthonormality_error_renormalised: total.max_ortho_unit,
        left_handed: total.left_handed,
        storage,
    })
}

/// What the bake produced, before anything is written.
pub struct Baked {
    /// Encoded files, ready for [`io::write_many_atomic`].
    pub files: Vec<(PathBuf, Vec<u8>)>,
    /// What the conversion met.
    pub stats: ConvertStats,
    /// The round-trip check, with `--check`.
    pub check: Option<CheckReport>,
}

/// Converts a loaded normal map and encodes the quaternion map for `out` (.png or .exr).
/// With `check`, the encoded bytes are decoded again and measured.
pub fn run(
    params: &Params,
    normal: &NormalImage,
    out: &Path,
    progress: &dyn Progress,
) -> Result<Baked> {
    params.validate_output(out)?;
    crate::output::refuse_overwriting_input(out, [normal.path.as_path()])?;
    let decoder = Decoder::new(params.decoding(), normal)?;
    let (image, mut stats) = convert(&decoder, &normal.image, progress);
    stats.convention = Some(convention_check(&decoder, &normal.image));
    stats.y_down = params.y_down;
    stats.read_as = normal.read_as.clone();
    if stats.non_finite > 0 && !params.sanitize {
        return Err(Error::NonFinite {
            path: normal.path.clone(),
            count: stats.non_finite as usize,
        }
        .into());
    }
    let bytes = io::encode_image(out, &image, &params.write_options())?;
    drop(image);
    let check = if params.check {
        let stored = io::decode_image(out, &bytes, ColorSpace::Linear)?;
        Some(check(
            &decoder,
            &normal.image,
            &stored,
            params.storage(out),
        )?)
    } else {
        None
    };
    Ok(Baked {
        files: vec![(out.to_path_buf(), bytes)],
        stats,
        check,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::progress::NoProgress;

    fn fixture(name: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/normals")
            .join(name)
    }

    #[test]
    fn defaults_agree_between_clap_serde_and_default() {
        let from_ron: Params = ron::from_str("()").unwrap();
        assert_eq!(from_ron, Params::default());
        assert_eq!(Params::default().bits, 16);
        assert_eq!(Params::default().output_name, "quaternion.png");
        assert!(Params::default().batch_fields_are_default());
        assert_eq!(Params::default().min_length, 0.01);
        assert!(ron::from_str::<Params>("(bitz: 8)").is_err());
        let p: Params = ron::from_str("(y_down: true, bits: 8)").unwrap();
        assert!(p.y_down && p.bits == 8);
    }

    #[test]
    fn parameters_are_validated_against_the_output() {
        assert!(Params {
            bits: 12,
            ..Default::default()
        }
        .validate()
        .is_err());
        assert!(Params {
            min_length: f64::NAN,
            ..Default::default()
        }
        .validate()
        .is_err());
        let p = Params::default();
        assert!(p.validate_output(Path::new("q.png")).is_ok());
        assert!(p.validate_output(Path::new("q.exr")).is_ok());
        assert!(p.validate_output(Path::new("q.hdr")).is_err());
        assert!(Params {
            half: true,
            ..Default::default()
        }
        .validate_output(Path::new("q.png"))
        .is_err());
        assert!(Params {
            bits: 8,
            ..Default::default()
        }
        .validate_output(Path::new("q.exr"))
        .is_err());
    }

    /// Round trip on the real fixtures for every storage: n' from the stored (quantised)
    /// quaternion matches the input normal within the derived bound; frames orthonormal
    /// within |q|² rounding and right-handed everywhere.
    #[test]
    fn round_trip_on_fixtures_within_the_quantisation_bound() {
        for name in ["0000.png", "0003_256.png", "0008_128.png"] {
            let normal = crate::normal::load(&fixture(name)).unwrap();
            for (out, bits, half) in [
                ("q.png", 16, false),
                ("q.png", 8, false),
                ("q.exr", 16, true),
                ("q.exr", 16, false),
            ] {
                let p = Params {
                    bits,
                    half,
                    check: true,
                    ..Default::default()
                };
                let baked = run(&p, &normal, Path::new(out), &NoProgress).unwrap();
                let c = baked.check.unwrap();
                eprintln!("{name} {out} bits {bits} half {half}: {}", c.summary());
                assert!(c.within_bounds(), "{c:?}");
                assert_eq!(c.left_handed, 0);
                assert!(c.max_orthonormality_error_renormalised < 1e-6);
                assert_eq!(c.compared + baked.stats.degenerate, baked.stats.texels);
            }
        }
    }

    fn encode_normal(n: [f64; 3]) -> [f32; 3] {
        n.map(|v| (v * 0.5 + 0.5) as f32)
    }

    fn one_texel(n: [f64; 3]) -> NormalImage {
        let rgb = encode_normal(n);
        NormalImage {
            image: Image::from_data(1, 1, 3, rgb.to_vec()).unwrap(),
            grey_alpha: false,
            path: "t.exr".into(),
            read_as: None,
        }
    }

    #[test]
    fn hand_checked_texels_through_the_bake() {
        let s = std::f64::consts::FRAC_1_SQRT_2;
        let dec = Decoder::new(Params::default().decoding(), &one_texel([0.0, 0.0, 1.0])).unwrap();
        // (normal, expected stored RGB): identity, 90° tilts to ±x and ±y, −z.
        let cases = [
            ([0.0, 0.0, 1.0], [1.0, 0.5, 0.5]),
            ([1.0, 0.0, 0.0], [0.5 + 0.5 * s, 0.5, 0.5 - 0.5 * s]),
            ([-1.0, 0.0, 0.0], [0.5 + 0.5 * s, 0.5, 0.5 + 0.5 * s]),
            ([0.0, 1.0, 0.0], [0.5 + 0.5 * s, 0.5 + 0.5 * s, 0.5]),
            ([0.0, -1.0, 0.0], [0.5 + 0.5 * s, 0.5 - 0.5 * s, 0.5]),
            ([0.0, 0.0, -1.0], [0.5, 1.0, 0.5]),
        ];
        for (n, rgb) in cases {
            let (img, stats) = convert(&dec, &one_texel(n).image, &NoProgress);
            for k in 0..3 {
                assert!(
                    (img.data[k] as f64 - rgb[k]).abs() < 1e-6,
                    "{n:?}: {:?} vs {rgb:?}",
                    img.data
                );
            }
            assert_eq!(stats.antipodal, (n[2] == -1.0) as u64);
        }
        // Degenerate (mid-grey) → identity, counted.
        let grey = NormalImage {
            image: Image::from_data(1, 1, 3, vec![0.5; 3]).unwrap(),
            grey_alpha: false,
            path: "g.exr".into(),
            read_as: None,
        };
        let (img, stats) = convert(&dec, &grey.image, &NoProgress);
        assert_eq!(
            (img.data.as_slice(), stats.degenerate),
            (&[1.0f32, 0.5, 0.5][..], 1)
        );
    }

    #[test]
    fn length_range_is_a_number_even_when_no_texel_has_a_direction() {
        let dec = Decoder::new(Params::default().decoding(), &one_texel([0.0, 0.0, 1.0])).unwrap();
        // Only mid-grey (degenerate) texels: no length counted.
        let grey = Image::from_data(2, 1, 3, vec![0.5; 6]).unwrap();
        let (_, stats) = convert(&dec, &grey, &NoProgress);
        assert_eq!(
            (stats.degenerate, stats.min_length, stats.max_length),
            (2, 0.0, 0.0)
        );
        let j = serde_json::to_value(&stats).unwrap();
        assert_eq!(
            (j["min_length"].as_f64(), j["max_length"].as_f64()),
            (Some(0.0), Some(0.0)),
            "{j}"
        );
        // With directions: the range of their lengths.
        let (_, stats) = convert(&dec, &one_texel([0.0, 0.0, 1.0]).image, &NoProgress);
        assert_eq!((stats.min_length, stats.max_length), (1.0, 1.0));
    }

    #[test]
    fn y_down_mirrors_the_b_component() {
        let normal = crate::normal::load(&fixture("0008_128.png")).unwrap();
        let up = run(
            &Params {
                bits: 16,
                ..Default::default()
            },
            &normal,
            Path::new("a.exr"),
            &NoProgress,
        )
        .unwrap();
        let down = run(
            &Params {
                y_down: true,
                ..Default::default()
            },
            &normal,
            Path::new("a.exr"),
            &NoProgress,
        )
        .unwrap();
        let a = io::decode_image(Path::new("a.exr"), &up.files[0].1, ColorSpace::Linear).unwrap();
        let b = io::decode_image(Path::new("a.exr"), &down.files[0].1, ColorSpace::Linear).unwrap();
        // Flipping y negates b = y/(2a) and leaves a and c: stored G ↦ 1 − G.
        let worst = a
            .data
            .chunks(3)
            .zip(b.data.chunks(3))
            .map(|(p, q)| {
                (p[0] - q[0])
                    .abs()
                    .max((p[2] - q[2]).abs())
                    .max((p[1] + q[1] - 1.0).abs())
            })
            .fold(0.0f32, f32::max);
        eprintln!("y-down mirror: max deviation {worst:.2e}");
        assert!(worst < 1e-6);
    }

    #[test]
    fn two_channel_maps_reconstruct_z_within_the_bound() {
        // Unit normals of the upper hemisphere stored as 16-bit R, G with B = 0 (as BC5 decodes).
        let mut rng = ibl_core::sampling::Pcg32::new(9, 2);
        let n = 64;
        let mut truth = Vec::new();
        let mut img = Image::new(n, n, 3);
        for px in img.data.chunks_mut(3) {
            let z = rng.next_f64();
            let phi = std::f64::consts::TAU * rng.next_f64();
            let r = (1.0 - z * z).sqrt();
            let v = [r * phi.cos(), r * phi.sin(), z];
            px.copy_from_slice(&[
                ((v[0] * 0.5 + 0.5) * 65535.0).round() as f32 / 65535.0,
                ((v[1] * 0.5 + 0.5) * 65535.0).round() as f32 / 65535.0,
                0.0,
            ]);
            truth.push(v);
        }
        let normal = NormalImage {
            image: img,
            grey_alpha: false,
            path: "bc5.png".into(),
            read_as: None,
        };
        let p = Params {
            two_channel: true,
            check: true,
            ..Default::default()
        };
        let baked = run(&p, &normal, Path::new("q.exr"), &NoProgress).unwrap();
        let c = baked.check.unwrap();
        assert!(c.within_bounds(), "{c:?}");
        // Against the true normals: the input's own 16-bit x, y rounding dominates; near the
        // horizon z = sqrt(1 − x² − y²) amplifies it (dz = −(x dx + y dy)/z).
        let stored =
            io::decode_image(Path::new("q.exr"), &baked.files[0].1, ColorSpace::Linear).unwrap();
        let mut worst = 0.0f64;
        for (t, v) in stored.data.chunks(3).zip(&truth) {
            let np = frame_from_quat(decode_quat(t))[2];
            let e = angle_between(np, *v);
            let allowed = 2.0 / 65535.0 / v[2].max(1e-3) + 1e-4;
            assert!(e < allowed, "{v:?}: {e}");
            worst = worst.max(e);
        }
        eprintln!(
            "two-channel 16-bit: n' vs true normals max {worst:.2e} rad; stats {:?}",
            baked.stats.outside_disk
        );
    }

    #[test]
    fn a_wrong_y_convention_is_flagged() {
        // 0008_128 is a y-up map: its slopes integrate far better read as y-up.
        let normal = crate::normal::load(&fixture("0008_128.png")).unwrap();
        let right = run(&Params::default(), &normal, Path::new("q.png"), &NoProgress).unwrap();
        let wrong = run(
            &Params {
                y_down: true,
                ..Default::default()
            },
            &normal,
            Path::new("q.png"),
            &NoProgress,
        )
        .unwrap();
        let (c, w) = (
            right.stats.convention.clone().unwrap(),
            wrong.stats.warnings(Path::new("n.png")),
        );
        eprintln!("0008_128: {c:?}; with --y-down: {w:?}");
        assert!(c.agreement > 0.3 && !c.suggests_flip());
        assert!(right.stats.warnings(Path::new("n.png")).is_empty());
        assert!(w.iter().any(|w| w.contains("drop --y-down")), "{w:?}");
    }

    #[test]
    fn non_finite_inputs_are_refused_unless_sanitized() {
        let img = NormalImage {
            image: Image::from_data(2, 1, 3, vec![f32::NAN, 0.5, 1.0, 0.5, 0.5, 1.0]).unwrap(),
            grey_alpha: false,
            path: "n.exr".into(),
            read_as: None,
        };
        let e = run(&Params::default(), &img, Path::new("q.png"), &NoProgress)
            .err()
            .unwrap();
        assert!(e.to_string().contains("1 NaN/Inf"), "{e}");
        let ok = run(
            &Params {
                sanitize: true,
                check: true,
                ..Default::default()
            },
            &img,
            Path::new("q.png"),
            &NoProgress,
        )
        .unwrap();
        assert_eq!(ok.stats.non_finite, 1);
        assert_eq!(ok.check.unwrap().compared, 1);
    }

    #[test]
    fn a_normal_map_read_against_its_name_is_one_warning() {
        let d = tempfile::tempdir().unwrap();
        let png = std::fs::read(fixture("0003_256.png")).unwrap();
        let named_exr = d.path().join("n.exr");
        std::fs::write(&named_exr, &png).unwrap();
        let normal = crate::normal::load(&named_exr).unwrap();
        let baked = run(&Params::default(), &normal, Path::new("q.png"), &NoProgress).unwrap();
        let w = baked.stats.warnings(&named_exr);
        assert_eq!(
            w[0],
            format!(
                "{}: holds PNG data but is named .exr; read as PNG (by its content)",
                named_exr.display()
            )
        );
        // Read as the PNG it is: the same bytes as from its proper name.
        let proper = crate::normal::load(&fixture("0003_256.png")).unwrap();
        assert!(proper.read_as.is_none());
        let want = run(&Params::default(), &proper, Path::new("q.png"), &NoProgress).unwrap();
        assert_eq!(baked.files[0].1, want.files[0].1);
        assert!(!want
            .stats
            .warnings(Path::new("n.png"))
            .iter()
            .any(|l| l.contains("read as")));
    }

    #[test]
    fn deterministic_across_thread_counts() {
        let normal = crate::normal::load(&fixture("0003_256.png")).unwrap();
        ibl_testkit::thread_count_independent(&[1, 2, 3], || {
            run(&Params::default(), &normal, Path::new("q.png"), &NoProgress)
                .unwrap()
                .files[0]
                .1
                .clone()
        });
    }
}
