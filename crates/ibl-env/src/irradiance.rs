//! The `irradiance` bake: solid-angle-exact SH projection of an environment, the SH
//! coefficients of E/π, and an irradiance cubemap (E/π) from the SH or by brute-force
//! cosine convolution.

use glam::Vec3;
use ibl_core::cube::{solid_angle_table, texel_direction, CubeMips, Cubemap, Face};
use ibl_core::envmap::{Environment, EquirectStream, InputChecks, Opened};
use ibl_core::equirect::{pixel_direction, rotate_y, row_solid_angle};
use ibl_core::io;
use ibl_core::io::texture::LevelEncoding;
use ibl_core::output::{self, Encoding};
use ibl_core::progress::Progress;
use ibl_core::sh::{self, cosine_lobe_zonal, num_coeffs};
use ibl_core::traverse::{map_cube_texels, ordered_row_reduce};
use ibl_core::{Error, Image, Result};
use ibl_target::{DiffuseForm, Target};
use rayon::prelude::*;
use std::path::{Path, PathBuf};

/// Largest band count accepted (l ≤ 15).
pub(crate) const MAX_BANDS: usize = 16;

ibl_core::cube_output_params! {
/// Parameters of the bake: CLI flags and RON keys alike.
#[derive(Clone, Debug, PartialEq, clap::Args, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// SH bands (l = 0 … bands−1); 3 gives the classic 9 coefficients.
    #[arg(long, default_value_t = 3)]
    pub bands: usize,
    /// Face size of the irradiance cube.
    #[arg(long, default_value_t = 32)]
    pub size: usize,
    /// Build the cube by brute-force cosine convolution of the source (the reference)
    /// instead of from the SH coefficients, for any target. Targets whose engine samples the
    /// cube (gltf, bevy, custom: `Target::reads_diffuse_cube`) get it without this flag,
    /// since a 3-band SH cannot hold a sun and the engine shows every texel.
    #[arg(long)]
    pub exact: bool,
    /// Build the cube from the SH coefficients even for a target whose engine samples the
    /// cube (smooth, ringing-free only with `--window`; cheaper); refused with `--exact`.
    /// Targets whose engine reads SH already get the cube that matches their coefficients.
    #[arg(long)]
    pub from_sh: bool,
    /// Width of the equirect the source is box-reduced to (solid-angle exact) before the
    /// exact convolution; 0 keeps the source's own texels. The cosine lobe is so smooth that
    /// the reduction costs little: against the native texels at 32², 256 wide is 0.04% relative
    /// MAE on city_512 (worst texel 0.8%, its sun) and exact on the 256-wide fixtures, 128 wide
    /// 0.05–0.4% (worst 1–4.6%); the work is width² × size², 0.27 s of CPU at 256 against 1.26 s
    /// at 512 (measured 2026-11-26). 256 keeps the default bake fast for the targets that get
    /// the exact cube by default.
    #[arg(long, default_value_t = 256, value_name = "W")]
    pub exact_source_width: usize,
    /// Damp bands against ringing (Lanczos σ factors sinc(l/bands)) in the irradiance
    /// coefficients and the cube made from them; the radiance projection is left exact.
    #[arg(long)]
    pub window: bool,
    /// File name of the coefficients inside the output folder (`.json` or `.ron`).
    #[arg(long, default_value = "sh.json", value_name = "NAME")]
    pub sh_file: String,
    /// Turn the environment about +Y by this many degrees first.
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    pub rotate: f32,
    /// Set NaN/Inf input texels to 0 instead of refusing the input.
    #[arg(long)]
    pub sanitize: bool,
    /// Negative input texels: clamp them to 0 (saying how much power that adds), keep them
    /// (the SH projection is linear and integrates them as they are; so does `--exact`) or
    /// refuse the input.
    #[arg(long, value_enum, default_value_t = ibl_core::envmap::Negative::Clamp)]
    pub negative: ibl_core::envmap::Negative,
    /// Engine the outputs are made for: the cube's orientation and its SH form as an extra
    /// file (Filament sh.txt, three.js LightProbe.json, Unity SphericalHarmonicsL2.json).
    #[arg(long, value_enum, default_value_t = Target::Gltf)]
    pub target: Target,
}
}

impl Default for Params {
    fn default() -> Self {
        ibl_core::params::clap_defaults()
    }
}

impl Params {
    /// How the input environment is read (`--sanitize`, `--negative`).
    pub fn env_policy(&self) -> ibl_core::envmap::EnvPolicy {
        ibl_core::envmap::EnvPolicy {
            sanitize: self.sanitize,
            negative: self.negative,
        }
    }

    /// Checks the parameters before any input is read (bands within 1..=MAX_BANDS, ...).
    pub fn validate(&self) -> Result<()> {
        if self.bands == 0 || self.bands > MAX_BANDS {
            return Err(Error::param(format!(
                "--bands {} is out of range 1..={MAX_BANDS}",
                self.bands
            )));
        }
        if self.size == 0 || self.size > 4096 {
            return Err(Error::param(format!(
                "--size {} is out of range 1..=4096",
                self.size
            )));
        }
        let ext = io::extension(Path::new(&self.sh_file));
        if ext != "json" && ext != "ron" {
            return Err(Error::param(format!(
                "--sh-file '{}' must end in .json or .ron",
                self.sh_file
            )));
        }
        ibl_core::params::check_rotate(self.rotate)?;
        if self.exact && self.from_sh {
            return Err(Error::param(
                "--exact and --from-sh ask for opposite cubes: give at most one",
            ));
        }
        if self.bands < 3 && self.target_sh_file().is_some() {
            return Err(Error::param(format!(
                "--target {} takes 9 SH coefficients: --bands must be at least 3",
                self.target.name()
            )));
        }
        self.encoding()?;
        Ok(())
    }

    /// Whether the cube is the exact cosine convolution: `--exact`, or by default when the
    /// target's engine samples the cube (it shows the cube itself, not our SH), unless
    /// `--from-sh`.
    pub fn exact_cube(&self) -> bool {
        self.exact || (!self.from_sh && self.target.reads_diffuse_cube())
    }

    /// The engine's own SH file, if the target takes one.
    pub(crate) fn target_sh_file(&self) -> Option<&'static str> {
        self.target.spec().files.sh
    }

    /// The irradiance cube's output encoding, checked: the flags over the target's container
    /// and format.
    pub fn encoding(&self) -> Result<Encoding> {
        self.cube_output()
            .resolve(self.target.encoding())
            .and_then(|e| self.target.check_encoding(e))
    }

    /// Name (stem) of the irradiance cube's container: `irradiance`, or the target's.
    pub fn cube_name(&self) -> &'static str {
        self.target.spec().files.irradiance.unwrap_or("irradiance")
    }

    /// Every file [`run`] writes into `out_dir` (for planning and cleaning).
    pub fn output_paths(&self, out_dir: &Path) -> Result<Vec<PathBuf>> {
        let enc = self.encoding()?;
        let mut files = vec![out_dir.join(&self.sh_file)];
        files.extend(output::cube_output_paths(
            out_dir,
            1,
            enc.layout,
            self.cube_name(),
        ));
        files.extend(output::encoding_sidecar_path(
            out_dir,
            self.cube_name(),
            &enc,
        ));
        if let Some(name) = self.target_sh_file() {
            files.push(out_dir.join(name));
        }
        files.extend(self.target.spec().orientation.sidecar_path(
            out_dir,
            enc.layout,
            self.cube_name(),
        ));
        files.push(out_dir.join(ibl_target::NOTE_NAME));
        Ok(files)
    }
}

/// The engine's SH file for `target` from the 3-band irradiance coefficients (E/π, our basis
/// and frame), or `None` when the engine takes the irradiance cube only.
pub(crate) fn target_sh_bytes(target: Target, irradiance: &[[f32; 3]]) -> Option<Vec<u8>> {
    use ibl_target::sh;
    let spec = target.spec();
    let json = |v: serde_json::Value| {
        let mut b = serde_json::to_vec_pretty(&v).expect("JSON of numbers");
        b.push(b'\n');
        b
    };
    match spec.diffuse {
        DiffuseForm::FilamentSh => Some(
            sh::filament_sh_txt(&sh::prescaled_polynomial(irradiance, spec.orientation))
                .into_bytes(),
        ),
        DiffuseForm::ThreeLightProbe => Some(json(sh::three_light_probe_json(irradiance))),
        DiffuseForm::UnityShL2 => {
            let l2 = sh::unity_sh_l2(irradiance);
            let k = sh::unity_shader_constants(&l2);
            let names = [
                "unity_SHAr",
                "unity_SHAg",
                "unity_SHAb",
                "unity_SHBr",
                "unity_SHBg",
                "unity_SHBb",
                "unity_SHC",
            ];
            let shader: serde_json::Map<String, serde_json::Value> = names
                .iter()
                .zip(k)
                .map(|(n, v)| (n.to_string(), serde_json::json!(v)))
                .collect();
            Some(json(serde_json::json!({
                "SphericalHarmonicsL2": l2,
                "layout": "sh[rgb][i], i = l(l+1)+m; pre-multiplied: E/pi(n) = sh[0] + sh[1] y + sh[2] z + sh[3] x + sh[4] xy + sh[5] yz + sh[6] (3z^2-1) + sh[7] xz + sh[8] (x^2-y^2) in Unity's left-handed frame",
                "shader": shader,
            })))
        }
        DiffuseForm::IrradianceCube | DiffuseForm::BabylonManifest => None,
    }
}

/// The coefficients file: radiance projection L_lm and the coefficients of E/π.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ShCoefficients {
    /// SH bands projected (l = 0..bands−1, bands² coefficients per channel).
    pub bands: usize,
    /// L_lm = ∫ L(ω) Y_lm(ω) dω, as [r, g, b] in index order l(l+1)+m.
    pub radiance: Vec<[f32; 3]>,
    /// c_lm = (Â_l / π) · w_l · L_lm, so that E(n)/π = Σ c_lm Y_lm(n).
    pub irradiance: Vec<[f32; 3]>,
    /// Whether the Lanczos window w_l was applied (otherwise w_l = 1).
    pub windowed: bool,
}

/// Lanczos σ factor of band l for `bands` bands: sinc(l/bands), sinc(x) = sin(πx)/(πx)
/// (Sloan 2008, "Stupid Spherical Harmonics Tricks", §"windowing").
pub(crate) fn lanczos_window(l: usize, bands: usize) -> f64 {
    if l == 0 {
        return 1.0;
    }
    let x = std::f64::consts::PI * l as f64 / bands as f64;
    x.sin() / x
}

/// ∫ L Y_lm dω over an equirect image's own pixels, each at its centre direction (turned by
/// `rotate_deg`) with the exact row solid angle. Ordered row sums: thread-count independent.
pub(crate) fn project_equirect(img: &Image, bands: usize, rotate_deg: f32) -> Vec<[f64; 3]> {
    let n = num_coeffs(bands);
    let row = |j: usize| project_row(img, j, j, img.height, bands, rotate_deg);
    ordered_row_reduce(img.height, row, vec![[0.0f64; 3]; n], add_coeffs)
}

/// Row `local` of `rows` (row `j` of an equirect `height` rows high) projected as
/// [`project_equirect`] projects each of its rows.
fn project_row(
    rows: &Image,
    local: usize,
    j: usize,
    height: usize,
    bands: usize,
    rotate_deg: f32,
) -> Vec<[f64; 3]> {
    let n = num_coeffs(bands);
    let w = rows.width;
    let sa = row_solid_angle(j, w, height);
    let mut acc = vec![[0.0f64; 3]; n];
    let mut y = vec![0.0f32; n];
    for i in 0..w {
        let c = rows.rgb(i, local);
        if c == [0.0; 3] {
            continue;
        }
        sh::eval_basis(
            rotate_y(pixel_direction(i, j, w, height), rotate_deg),
            bands,
            &mut y,
        );
        for (a, yi) in acc.iter_mut().zip(&y) {
            for k in 0..3 {
                a[k] += c[k] as f64 * *yi as f64;
            }
        }
    }
    acc.iter_mut()
        .for_each(|a| a.iter_mut().for_each(|v| *v *= sa));
    acc
}

/// ∫ L Y_lm dω over a cube's texels with their exact solid angles (turned by `rotate_deg`).
/// Summed in f64: radiance near the f32 limit (10³⁸) times a row's solid angles overflows
/// f32 partial sums, and finite input must give finite coefficients.
pub fn project_cube(cube: &Cubemap, bands: usize, rotate_deg: f32) -> Vec<[f64; 3]> {
    let n = num_coeffs(bands);
    let size = cube.size;
    let sa = solid_angle_table(size);
    let row = |r: usize| {
        let (face, j) = (Face::from_index(r / size), r % size);
        let mut acc = vec![[0.0f64; 3]; n];
        let mut y = vec![0.0f32; n];
        let texels = &cube.faces[face as usize].data[j * size * 3..(j + 1) * size * 3];
        for (i, (c, s)) in texels
            .chunks_exact(3)
            .zip(&sa[j * size..(j + 1) * size])
            .enumerate()
        {
            sh::eval_basis(
                rotate_y(texel_direction(face, i, j, size), rotate_deg),
                bands,
                &mut y,
            );
            let s = *s as f64;
            let (r_, g_, b_) = (c[0] as f64 * s, c[1] as f64 * s, c[2] as f64 * s);
            for (a, yi) in acc.iter_mut().zip(&y) {
                let yi = *yi as f64;
                a[0] += r_ * yi;
                a[1] += g_ * yi;
                a[2] += b_ * yi;
            }
        }
        acc
    };
    ordered_row_reduce(6 * size, row, vec![[0.0f64; 3]; n], add_coeffs)
}

fn add_coeffs(mut a: Vec<[f64; 3]>, b: Vec<[f64; 3]>) -> Vec<[f64; 3]> {
    for (x, y) in a.iter_mut().zip(&b) {
        for k in 0..3 {
            x[k] += y[k];
        }
    }
    a
}

/// Radiance projection of any environment.
pub fn project(env: &Environment, bands: usize, rotate_deg: f32) -> Vec<[f64; 3]> {
    match env {
        Environment::Equirect(img) => project_equirect(img, bands, rotate_deg),
        Environment::Cube(c) => project_cube(c, bands, rotate_deg),
    }
}

/// Coefficients of E/π from the radiance projection: c_lm = (Â_l/π) w_l L_lm
/// (Ramamoorthi & Hanrahan 2001, eq. 7).
pub fn irradiance_coefficients(radiance: &[[f64; 3]], bands: usize, window: bool) -> Vec<[f64; 3]> {
    let mut out = radiance.to_vec();
    for l in 0..bands {
        let w = if window {
            lanczos_window(l, bands)
        } else {
            1.0
        };
        let f = cosine_lobe_zonal(l) / std::f64::consts::PI * w;
        for m in -(l as isize)..=(l as isize) {
            out[sh::index(l, m)].iter_mut().for_each(|v| *v *= f);
        }
    }
    out
}

/// A source flattened for brute-force convolution: unit directions and L·Ω per texel,
/// black texels dropped (they contribute nothing).
struct WeightedTexels {
    dirs: Vec<Vec3>,
    /// Radiance × solid angle, and the solid angle itself (for the cosine-weight sum).
    radiance_times_sa: Vec<[f32; 4]>,
}

/// Reduces an equirect image by an integer factor with solid-angle weights (energy exact).
fn reduce_equirect(img: &Image, factor: usize) -> Image {
    if factor <= 1 {
        return img.clone();
    }
    let mut out = Image::new(img.width / factor, img.height / factor, 3);
    reduce_band(img, 0, img.height, factor, &mut out);
    out
}

/// Rows `first` … of an equirect `height` rows high (`band`, a whole number of `factor` rows)
/// reduced by `factor` into their rows of `out` ([`reduce_equirect`]'s arithmetic).
fn reduce_band(band: &Image, first: usize, height: usize, factor: usize, out: &mut Image) {
    let width = band.width;
    for yb in 0..band.height / factor {
        let y = first / factor + yb;
        for x in 0..out.width {
            let mut acc = [0.0f64; 3];
            let mut ws = 0.0f64;
            for b in 0..factor {
                let sa = row_solid_angle(y * factor + b, width, height);
                for a in 0..factor {
                    let c = band.rgb(x * factor + a, yb * factor + b);
                    for k in 0..3 {
                        acc[k] += c[k] as f64 * sa;
                    }
                    ws += sa;
                }
            }
            out.texel_mut(x, y)
                .copy_from_slice(&acc.map(|v| (v / ws) as f32));
        }
    }
}

/// The factor a `w`×`h` equirect is box-reduced by for the exact convolution (`w` brought to
/// about `exact_source_width`; 0 keeps the source): only exact divisors keep the reduction
/// energy-exact.
fn reduce_factor(w: usize, h: usize, exact_source_width: usize) -> usize {
    let factor = w.checked_div(exact_source_width).unwrap_or(1).max(1);
    (1..=factor)
        .rev()
        .find(|&f| w.is_multiple_of(f) && h.is_multiple_of(f))
        .unwrap_or(1)
}

fn weighted_texels(
    env: &Environment,
    exact_source_width: usize,
    rotate_deg: f32,
) -> WeightedTexels {
    let mut t = WeightedTexels {
        dirs: Vec::new(),
        radiance_times_sa: Vec::new(),
    };
    // Black texels are kept: they carry no radiance but their solid angle belongs to the
    // cosine-weight sum that normalises the result.
    let mut push = |d: Vec3, c: [f32; 3], sa: f64| {
        t.dirs.push(rotate_y(d, rotate_deg));
        let w = c.map(|v| (v as f64 * sa) as f32);
        t.radiance_times_sa.push([w[0], w[1], w[2], sa as f32]);
    };
    match env {
        Environment::Equirect(img) => {
            let factor = reduce_factor(img.width, img.height, exact_source_width);
            let src = reduce_equirect(img, factor);
            for j in 0..src.height {
                let sa = row_solid_angle(j, src.width, src.height);
                for i in 0..src.width {
                    push(
                        pixel_direction(i, j, src.width, src.height),
                        src.rgb(i, j),
                        sa,
                    );
                }
            }
        }
        Environment::Cube(c) => {
            let sa = solid_angle_table(c.size);
            for face in Face::ALL {
                for j in 0..c.size {
                    for i in 0..c.size {
                        push(
                            texel_direction(face, i, j, c.size),
                            c.texel(face, i, j),
                            sa[j * c.size + i] as f64,
                        );
                    }
                }
            }
        }
    }
    t
}

/// E(n)/π over every source texel, the brute-force reference: Σ L(ω) max(n·ω, 0) Ω divided by
/// Σ max(n·ω, 0) Ω (which tends to π). Dividing by the discrete cosine weight rather than π
/// makes a constant environment come out exactly L at any source size (a 1×1 cube's point
/// sum alone is 9% off) and lowers the midpoint-rule error elsewhere.
pub fn convolve_cosine_exact(
    env: &Environment,
    size: usize,
    exact_source_width: usize,
    rotate_deg: f32,
    progress: &dyn Progress,
) -> Cubemap {
    let mut src = weighted_texels(env, exact_source_width, rotate_deg);
    // The blocks below sum 256 terms in f32: radiance near the f32 limit would overflow them.
    // Scale by a power of two (exact) so that a block cannot, and undo it in f64.
    let top = src
        .radiance_times_sa
        .iter()
        .flat_map(|v| v[..3].iter())
        .fold(0.0f32, |m, v| m.max(v.abs()));
    let unscale = if top > 1e30 {
        let k = (top as f64 / 1e30).log2().ceil() as i32;
        let f = 2f32.powi(-k);
        src.radiance_times_sa
            .iter_mut()
            .for_each(|v| v[..3].iter_mut().for_each(|x| *x *= f));
        2f64.powi(k)
    } else {
        1.0
    };
    map_cube_texels(size, progress, |face, i, j| {
        let n = texel_direction(face, i, j, size);
        let mut acc = [0.0f64; 4];
        // Blocks of f32 sums folded into f64 keep both speed and precision.
        for (dirs, vals) in src.dirs.chunks(256).zip(src.radiance_times_sa.chunks(256)) {
            let mut block = [0.0f32; 4];
            for (d, v) in dirs.iter().zip(vals) {
                let c = n.dot(*d).max(0.0);
                for k in 0..4 {
                    block[k] += v[k] * c;
                }
            }
            for k in 0..4 {
                acc[k] += block[k] as f64;
            }
        }
        let norm = if acc[3] > 0.0 { unscale / acc[3] } else { 0.0 };
        [acc[0], acc[1], acc[2]].map(|a| (a * norm) as f32)
    })
}

/// The irradiance cube E/π evaluated from SH coefficients (f32 or f64), summed in f64;
/// negative values (ringing under strong suns) are clamped to 0 and counted. A value beyond
/// the f32 range comes out infinite ([`run`] refuses it).
pub fn cube_from_sh<C: Copy + Into<f64> + Sync>(
    coeffs: &[[C; 3]],
    size: usize,
    progress: &dyn Progress,
) -> (Cubemap, usize) {
    let bands = (coeffs.len() as f64).sqrt() as usize;
    let cube = map_cube_texels(size, progress, |face, i, j| {
        let mut y = vec![0.0f32; num_coeffs(bands)];
        sh::eval_basis(texel_direction(face, i, j, size), bands, &mut y);
        let mut out = [0.0f64; 3];
        for (c, yi) in coeffs.iter().zip(&y) {
            for k in 0..3 {
                out[k] += c[k].into() * *yi as f64;
            }
        }
        out.map(|v| v as f32)
    });
    let mut clamped = 0;
    let mut cube = cube;
    for face in &mut cube.faces {
        for v in &mut face.data {
            if *v < 0.0 {
                *v = 0.0;
                clamped += 1;
            }
        }
    }
    (cube, clamped)
}

/// What the bake produced, before anything is written.
pub struct Baked {
    /// Encoded files (coefficients and cube), ready for [`io::write_many_atomic`].
    pub files: Vec<(PathBuf, Vec<u8>)>,
    /// The coefficients written to the coefficients file.
    pub coefficients: ShCoefficients,
    /// Irradiance-cube values below zero from SH ringing, clamped to 0.
    pub negative_clamped: usize,
    /// What the output encoding cost.
    pub encoding: Vec<LevelEncoding>,
    /// Things the user should know (values clamped by the output format).
    pub warnings: Vec<String>,
    /// What the input's checks found (its warnings come first, from [`InputChecks::warnings`]).
    pub input: InputChecks,
}

/// An image and its hold on the memory budget.
type HeldImage = (Image, io::budget::Reservation);

/// Rows of a streamed equirect held at a time (rounded up to whole reduction blocks).
const STREAM_BAND: usize = 32;

/// The radiance projection of a streamed equirect and, when the exact cube is wanted, the
/// equirect box-reduced for it ([`reduce_factor`]), as the rows arrive: the same bits as
/// [`project_equirect`] and [`weighted_texels`]' reduction of the loaded image (rows projected
/// in parallel, folded in row order), holding a band of rows and the reduced image, never the
/// source (at 8192×4096, 3 MB instead of 400 MB).
fn project_streamed(
    params: &Params,
    stream: EquirectStream,
) -> Result<(Vec<[f64; 3]>, Option<HeldImage>, InputChecks)> {
    let (w, h) = (stream.width(), stream.height());
    let factor = reduce_factor(w, h, params.exact_source_width);
    // The reduced image is held against the memory budget until the cube is convolved: with
    // --exact-source-width 0 it is the whole image the stream otherwise never holds.
    let (rw, rh) = (w / factor, h / factor);
    let hold = match params.exact_cube() {
        true => Some(io::budget::reserve(
            stream.path(),
            &format!("the {rw}x{rh} equirect the exact cube convolves"),
            (rw * rh * 12) as u64,
        )?),
        false => None,
    };
    let mut reduced = hold.as_ref().map(|_| Image::new(rw, rh, 3));
    let mut radiance = vec![[0.0f64; 3]; num_coeffs(params.bands)];
    let band = factor * STREAM_BAND.div_ceil(factor);
    let checks = stream.read_bands(band, |first, rows| {
        let partials: Vec<_> = (0..rows.height)
            .into_par_iter()
            .map(|k| project_row(rows, k, first + k, h, params.bands, params.rotate))
            .collect();
        radiance = partials
            .into_iter()
            .fold(std::mem::take(&mut radiance), add_coeffs);
        match &mut reduced {
            // Unreduced, the texels as read (reduce_equirect's clone).
            Some(out) if factor == 1 => {
                for k in 0..rows.height {
                    for i in 0..w {
                        out.texel_mut(i, first + k).copy_from_slice(&rows.rgb(i, k));
                    }
                }
            }
            Some(out) => reduce_band(rows, first, h, factor, out),
            None => {}
        }
        Ok(())
    })?;
    Ok((radiance, reduced.zip(hold), checks))
}

/// Projects, convolves and encodes `DIR/<sh_file>` and the irradiance cube from an
/// environment, loaded or opened as a stream (`ibl_core::envmap::open_environment_with`).
pub fn run(
    params: &Params,
    input: impl Into<Opened>,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<Baked> {
    params.validate()?;
    let input = input.into();
    let path = input.path().to_path_buf();
    // The source the exact cube convolves, with the width it is reduced to there (a streamed
    // one comes reduced).
    let (radiance, exact_source, checks, hold) = match input {
        Opened::Loaded(l) => {
            let radiance = project(&l.env, params.bands, params.rotate);
            let checks = l.checks();
            let source = params
                .exact_cube()
                .then_some((l.env, params.exact_source_width));
            (radiance, source, checks, None)
        }
        Opened::Streamed(s) => {
            let (radiance, reduced, checks) = project_streamed(params, s)?;
            let (source, hold) = match reduced {
                Some((img, hold)) => (Some((Environment::Equirect(img), 0)), Some(hold)),
                None => (None, None),
            };
            (radiance, source, checks, hold)
        }
    };
    let irr = irradiance_coefficients(&radiance, params.bands, params.window);
    // The coefficients file holds 32-bit floats, as every engine reading SH takes them: a
    // coefficient beyond their range (a constant 10³⁸ sky has L00 = 3.5·10³⁸) is refused
    // rather than written as infinity (JSON's null).
    let to_f32 = |v: &[[f64; 3]], what: &str| -> Result<Vec<[f32; 3]>> {
        let big = v.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
        if big.is_nan() || big > f32::MAX as f64 {
            return Err(Error::invalid(
                &path,
                format!(
                    "the {what} SH coefficients reach {big:.3e}, beyond the largest 32-bit float \
                     ({:.3e}) that {} and engines store: scale the environment down",
                    f32::MAX,
                    params.sh_file
                ),
            ));
        }
        Ok(v.iter().map(|c| c.map(|x| x as f32)).collect())
    };
    let coefficients = ShCoefficients {
        bands: params.bands,
        radiance: to_f32(&radiance, "radiance")?,
        irradiance: to_f32(&irr, "irradiance")?,
        windowed: params.window,
    };
    let (cube, negative_clamped) = match &exact_source {
        Some((env, width)) => (
            convolve_cosine_exact(env, params.size, *width, params.rotate, progress),
            0,
        ),
        None => cube_from_sh(&irr, params.size, progress),
    };
    drop((exact_source, hold));
    // Finite input, finite output: E/π is at most the largest radiance, so only input within
    // a factor of the f32 limit can get here; no pixel format holds more than rgba32f.
    if let Some(v) = cube
        .faces
        .iter()
        .flat_map(|f| f.data.iter())
        .find(|v| !v.is_finite())
    {
        return Err(Error::invalid(
            &path,
            format!(
                "the irradiance reaches {v}, beyond the largest 32-bit float ({:.3e}) that any \
                 output format holds: scale the environment down",
                f32::MAX
            ),
        ));
    }
    let sh_path = out_dir.join(&params.sh_file);
    let mut files = vec![(sh_path.clone(), io::data::encode(&sh_path, &coefficients)?)];
    let enc = params.encoding()?;
    // The engine's orientation: an exact texel permutation.
    let orientation = params.target.spec().orientation;
    let cube = orientation.apply(&cube);
    let encoded = output::encode_cube(
        out_dir,
        &CubeMips { levels: vec![cube] },
        &enc,
        params.cube_name(),
        &orientation.metadata(params.target.name()),
    )?;
    let names = |f: &[(PathBuf, Vec<u8>)]| ibl_target::note::names(f.iter().map(|f| f.0.as_path()));
    let mut outputs = ibl_target::note::Outputs {
        irradiance: names(&encoded.files),
        sh: Some(params.sh_file.clone()),
        ..Default::default()
    };
    files.extend(encoded.files);
    let sidecar = output::encoding_sidecar(out_dir, params.cube_name(), &enc, &encoded.levels)?;
    outputs.sidecars = names(sidecar.as_slice());
    files.extend(sidecar);
    if let (Some(name), Some(bytes)) = (
        params.target_sh_file(),
        target_sh_bytes(params.target, &coefficients.irradiance),
    ) {
        files.push((out_dir.join(name), bytes));
        outputs.engine_sh = Some(name.to_string());
    }
    if let Some(side) = orientation.sidecar(
        out_dir,
        enc.layout,
        params.cube_name(),
        params.target.name(),
    ) {
        outputs.orientation = ibl_target::note::names([side.0.as_path()]).pop();
        files.push(side);
    }
    // The how-to-load note, naming only what this run wrote (every target, gltf too).
    let note = ibl_target::note::load_note(
        params.target,
        ibl_target::note::Writer::Irradiance,
        &outputs,
    );
    files.push((out_dir.join(ibl_target::NOTE_NAME), note.into_bytes()));
    Ok(Baked {
        files,
        coefficients,
        negative_clamped,
        encoding: encoded.levels,
        warnings: encoded.warnings,
        input: checks,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use ibl_core::progress::NoProgress;
    use std::f64::consts::PI;

    fn load(name: &str) -> Environment {
        let p = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../fixtures/hdri")
            .join(name);
        ibl_core::envmap::load_environment(&p, false).unwrap().env
    }

    #[test]
    fn a_streamed_input_gives_the_loaded_files() {
        // At the streaming threshold the equirect is projected and reduced as its rows
        // arrive: the same files, bit for bit, and the same reports, for the SH cube, the
        // exact cube from a reduced source and from the source's own texels, turned or not.
        use ibl_core::envmap::{load_environment_with, open_environment_with, EnvPolicy};
        let d = tempfile::tempdir().unwrap();
        let p = ibl_core::stream::write_streamable_equirect(d.path(), "env.hdr");
        let policy = EnvPolicy::default();
        for (exact, exact_source_width, rotate) in [
            (false, 256, 0.0),
            (true, 256, 30.0),
            (true, 512, 0.0),
            (true, 0, 0.0),
        ] {
            let params = Params {
                size: 8,
                exact,
                exact_source_width,
                rotate,
                ..Default::default()
            };
            let opened = open_environment_with(&p, policy).unwrap();
            assert!(matches!(opened, Opened::Streamed(_)));
            let a = run(&params, opened, d.path(), &NoProgress).unwrap();
            let loaded = load_environment_with(&p, policy).unwrap();
            let b = run(&params, loaded, d.path(), &NoProgress).unwrap();
            assert!(a.files == b.files, "{exact} {exact_source_width} {rotate}");
            assert_eq!(a.input.report, b.input.report);
            assert_eq!(a.input.warnings(&p), b.input.warnings(&p));
        }
    }

    #[test]
    fn the_cube_is_exact_by_default_exactly_for_targets_whose_engine_samples_it() {
        for (target, exact) in [
            (Target::Gltf, true),
            (Target::Bevy, true),
            (Target::Custom, true),
            (Target::Three, false),
            (Target::Filament, false),
            (Target::Babylon, false),
            (Target::Unity, false),
        ] {
            let p = Params {
                target,
                ..Params::default()
            };
            assert_eq!(p.exact_cube(), exact, "{target:?}");
            let forced = Params {
                exact: true,
                ..p.clone()
            };
            assert!(forced.exact_cube() && forced.validate().is_ok());
            let sh = Params {
                from_sh: true,
                ..p.clone()
            };
            assert!(!sh.exact_cube() && sh.validate().is_ok());
            let both = Params {
                exact: true,
                from_sh: true,
                ..p
            };
            let e = both.validate().unwrap_err().to_string();
            assert!(
                e.contains("--exact and --from-sh") && !e.contains('\n'),
                "{e}"
            );
        }
        // The RON keys are the flags.
        let p: Params = ron::from_str("(from_sh: true)").unwrap();
        assert!(p.from_sh && !p.exact_cube());
    }

    #[test]
    fn defaults_agree_between_clap_serde_and_default() {
        assert_eq!(ron::from_str::<Params>("()").unwrap(), Params::default());
        assert_eq!(Params::default().bands, 3);
        assert!(ron::from_str::<Params>("(band: 3)").is_err());
    }

    #[test]
    fn constant_environment_has_only_dc_and_unit_irradiance() {
        // L = 1 everywhere: L00 = sqrt(4π), E/π = 1.
        let cube = Cubemap::constant(8, [1.0, 1.0, 1.0]);
        let rad = project_cube(&cube, 3, 0.0);
        assert!((rad[0][0] - (4.0 * PI).sqrt()).abs() < 1e-5);
        assert!(rad[1..].iter().all(|c| c[0].abs() < 1e-6));
        let irr = irradiance_coefficients(&rad, 3, false);
        let c: Vec<[f32; 3]> = irr.iter().map(|c| c.map(|x| x as f32)).collect();
        let (e, _) = cube_from_sh(&c, 4, &NoProgress);
        assert!(e
            .faces
            .iter()
            .all(|f| f.data.iter().all(|v| (v - 1.0).abs() < 1e-5)));
        // The brute-force sum over an 8² cube discretises the horizon kink of max(n·ω, 0);
        // its error shrinks with the source resolution.
        for (src, tol) in [(8, 2e-3), (64, 5e-5)] {
            let exact = convolve_cosine_exact(
                &Environment::Cube(Cubemap::constant(src, [1.0; 3])),
                4,
                0,
                0.0,
                &NoProgress,
            );
            let worst = exact
                .faces
                .iter()
                .flat_map(|f| f.data.iter())
                .map(|v| (v - 1.0).abs())
                .fold(0.0f32, f32::max);
            eprintln!("white furnace of the exact convolution from a {src}² cube: worst error {worst:.2e}");
            assert!(worst < tol, "{src}: {worst}");
        }
    }

    #[test]
    fn clamped_cosine_sky_matches_closed_form() {
        // L(ω) = max(ω·y, 0): E(n)/π has the closed form of irradiance from a cosine sky;
        // at n = +y it is (1/π)∫ cos² = 2/3, at n = −y it is 0. Bands 3 capture it up to
        // the l = 4 term: Â4 L4 is small; the exact convolution must match tightly.
        let w = 256;
        let mut img = Image::new(w, w / 2, 3);
        for j in 0..w / 2 {
            for i in 0..w {
                let d = pixel_direction(i, j, w, w / 2);
                let v = d.y.max(0.0);
                img.texel_mut(i, j).copy_from_slice(&[v, v, v]);
            }
        }
        let env = Environment::Equirect(img);
        let exact = convolve_cosine_exact(&env, 8, 0, 0.0, &NoProgress);
        let top = exact.texel(Face::Py, 4, 4)[0];
        let n = texel_direction(Face::Py, 4, 4, 8);
        // E/π(n) for L = max(ω·y,0) is (1/π)∫ max(ω·y,0) max(ω·n,0) dω; at n·y = c near 1
        // this is (2/3)c + O(1−c) — compare at the exact texel direction by quadrature.
        let mut q = 0.0f64;
        let k = 400;
        for b in 0..k {
            for a in 0..2 * k {
                let d = pixel_direction(a, b, 2 * k, k);
                q += (d.y.max(0.0) * d.dot(n).max(0.0)) as f64 * row_solid_angle(b, 2 * k, k);
            }
        }
        let want = q / PI;
        assert!(((top as f64 - want) / want).abs() < 2e-3, "{top} vs {want}");
        let rad = project(&env, 3, 0.0);
        let l00 = rad[0][0];
        // ∫ max(y,0) Y00 = 0.282095 · π.
        assert!((l00 - 0.28209479 * PI).abs() / l00 < 1e-3, "{l00}");
    }

    #[test]
    fn rotation_of_projection_matches_rotated_cube() {
        let env = load("studio_256.exr");
        let a = project(&env, 3, 90.0);
        let rotated = env.to_cube(64, ibl_core::equirect::Filter::Area, 90.0, &NoProgress);
        let b = project_cube(&rotated, 3, 0.0);
        for i in 0..9 {
            let scale = a[0][1].abs();
            assert!(
                (a[i][1] - b[i][1]).abs() < 0.02 * scale,
                "coefficient {i}: {} vs {}",
                a[i][1],
                b[i][1]
            );
        }
    }

    #[test]
    fn sh_cube_is_within_measured_distance_of_exact_on_fixtures() {
        for name in [
            "city_512.exr",
            "studio_256.exr",
            "sunset_256.exr",
            "interior_256.exr",
        ] {
            let env = load(name);
            let rad = project(&env, 3, 0.0);
            let irr: Vec<[f32; 3]> = irradiance_coefficients(&rad, 3, false)
                .iter()
                .map(|c| c.map(|x| x as f32))
                .collect();
            let (sh_cube, _) = cube_from_sh(&irr, 16, &NoProgress);
            let exact = convolve_cosine_exact(&env, 16, 0, 0.0, &NoProgress);
            let (mut num, mut den, mut worst) = (0.0f64, 0.0f64, 0.0f64);
            for f in 0..6 {
                for (a, b) in sh_cube.faces[f].data.iter().zip(&exact.faces[f].data) {
                    num += (a - b).abs() as f64;
                    den += *b as f64;
                    worst = worst.max(((a - b) / b.max(1e-6)).abs() as f64);
                }
            }
            let rel = num / den;
            eprintln!(
                "{name}: 3-band SH irradiance vs exact: relative MAE {:.4}, worst texel {:.3}",
                rel, worst
            );
            // The cosine convolution is diagonal in SH, so the first 9 coefficients of the
            // exact irradiance must be the bake's coefficients (the exact cube is finer: 32²).
            let exact32 = convolve_cosine_exact(&env, 32, 0, 0.0, &NoProgress);
            let back = project_cube(&exact32, 3, 0.0);
            let scale = irr[0][1] as f64;
            for i in 0..9 {
                let d = (back[i][1] - irr[i][1] as f64).abs() / scale;
                assert!(d < 5e-3, "{name}: coefficient {i} differs by {d} of c00");
            }
            // What 3 bands cannot represent is the ringing reported above; bound it loosely
            // so that a broken basis or convolution (errors of order 1) cannot pass.
            assert!(rel < 0.15, "{name}: {rel}");
        }
    }

    #[test]
    fn exact_cube_with_reduced_source_matches_native_texels() {
        let env = load("city_512.exr");
        let a = convolve_cosine_exact(&env, 8, 0, 0.0, &NoProgress);
        let b = convolve_cosine_exact(&env, 8, 256, 0.0, &NoProgress);
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for f in 0..6 {
            for (x, y) in a.faces[f].data.iter().zip(&b.faces[f].data) {
                num += (x - y).abs() as f64;
                den += *x as f64;
            }
        }
        eprintln!(
            "exact irradiance, 256-wide reduced source vs native 512: relative MAE {:.2e}",
            num / den
        );
        assert!(num / den < 1e-3);
    }

    #[test]
    fn projection_is_thread_count_independent() {
        let env = load("sunset_256.exr");
        ibl_testkit::thread_count_independent(&[1, 2, 3], || project(&env, 4, 0.0));
    }
}
