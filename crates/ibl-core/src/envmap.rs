//! Environment inputs and cubemap outputs: an equirect image, a folder of six faces, a
//! horizontal or vertical cross, a 6:1 / 1:6 strip, or a KTX2 cube in; faces or KTX2 out.

use crate::cube::{CubeMips, Cubemap, Face};
use crate::equirect::{self, Filter};
use crate::error::{Error, Result};
use crate::image::{check_texels, Image, TexelReport};
use crate::io::{self, ColorSpace};
use crate::progress::Progress;
use std::path::{Path, PathBuf};

/// An environment as read from disk.
// Both variants own megabytes of texels; boxing the larger header would buy nothing.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug)]
pub enum Environment {
    /// Latitude-longitude image (docs/CONVENTIONS.md mapping).
    Equirect(Image),
    /// A cubemap (from faces, a cross, a strip or a KTX2 file's level 0).
    Cube(Cubemap),
}

/// What to do with negative texel values (the ringing of lossy codecs such as DWAB, or
/// over-subtracted HDR merges): a flag (`--negative`) and a RON key (`negative`).
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
#[serde(rename_all = "lowercase")]
pub enum Negative {
    /// Set them to 0, saying how much power that adds (the default).
    #[default]
    Clamp,
    /// Keep them as they are (linear bakes such as an SH projection integrate them
    /// meaningfully; a cube written as rgba32f keeps them).
    Keep,
    /// Refuse the input.
    Refuse,
}

/// How an environment is read: NaN/Inf refused or zeroed, negatives clamped, kept or refused.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct EnvPolicy {
    /// Set NaN/Inf texels to 0 instead of refusing the input.
    pub sanitize: bool,
    /// What to do with negative texels.
    pub negative: Negative,
}

/// Negative texels an environment held, weighed by solid angle.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct NegativeReport {
    /// Channel values below 0.
    pub count: usize,
    /// The most negative value (0 when none).
    pub most_negative: f32,
    /// Σ over channels of ∫ max(−L, 0) dω: the power clamping adds.
    pub negative_power: f64,
    /// Σ over channels of ∫ L dω as read, negatives included.
    pub power: f64,
    /// What was done.
    pub policy: Negative,
}

impl NegativeReport {
    /// The negative power as a share of the environment's power as read, in percent, in
    /// words ("12.7% of the environment's power").
    fn share(&self) -> String {
        if self.power > 0.0 {
            format!(
                "{:.3}% of the environment's power",
                100.0 * self.negative_power / self.power
            )
        } else {
            "more than the environment's whole power (its power as read is not positive)".into()
        }
    }

    /// The one-line warning (or refusal) for `path`; `None` when there were no negatives.
    pub fn message(&self, path: &Path) -> Option<String> {
        if self.count == 0 {
            return None;
        }
        let (p, n, m) = (path.display(), self.count, self.most_negative);
        Some(match self.policy {
            Negative::Clamp => format!(
                "{p}: clamped {n} negative texel values to 0 (most negative {m}), adding +{} \
                 (--negative keep keeps them, --negative refuse refuses the input)",
                self.share()
            ),
            Negative::Keep => format!(
                "{p}: kept {n} negative texel values (most negative {m}), which take away {} \
                 (--negative keep)",
                self.share()
            ),
            Negative::Refuse => format!(
                "{p}: {n} negative texel values (most negative {m}, {}): refused by \
                 --negative refuse (clamp sets them to 0, keep keeps them)",
                self.share()
            ),
        })
    }
}

/// Measures the negative texels of `env` (solid-angle weighted) and applies `policy`.
pub fn apply_negative_policy(
    env: &mut Environment,
    path: &Path,
    policy: Negative,
) -> Result<NegativeReport> {
    let mut r = NegativeReport {
        policy,
        ..Default::default()
    };
    let mut visit = |data: &mut [f32], channels: usize, sa: &dyn Fn(usize) -> f64| {
        visit_negatives(&mut r, policy, data, channels, sa)
    };
    match env {
        Environment::Equirect(img) => {
            let (w, h, c) = (img.width, img.height, img.channels);
            let rows: Vec<f64> = (0..h)
                .map(|j| crate::equirect::row_solid_angle(j, w, h))
                .collect();
            visit(&mut img.data, c, &|k| rows[k / w]);
        }
        Environment::Cube(cube) => {
            let sa = crate::cube::solid_angle_table(cube.size);
            for face in &mut cube.faces {
                let c = face.channels;
                visit(&mut face.data, c, &|k| sa[k] as f64);
            }
        }
    }
    refuse_negatives(&r, path)?;
    Ok(r)
}

/// Adds the negative texels of `data` (pixel k weighing `sa(k)`) to `r`, clamping them under
/// `Clamp`. Colour channels are weighed (all of them, or the first three of RGBA); a negative
/// alpha is clamped under `Clamp` as before, but carries no power.
fn visit_negatives(
    r: &mut NegativeReport,
    policy: Negative,
    data: &mut [f32],
    channels: usize,
    sa: &dyn Fn(usize) -> f64,
) {
    for (k, px) in data.chunks_exact_mut(channels).enumerate() {
        let w = sa(k);
        let (colour, alpha) = px.split_at_mut(channels.min(3));
        for v in alpha.iter_mut().filter(|v| **v < 0.0) {
            if policy == Negative::Clamp {
                *v = 0.0;
            }
        }
        for v in colour {
            r.power += *v as f64 * w;
            if *v < 0.0 {
                r.count += 1;
                r.most_negative = r.most_negative.min(*v);
                r.negative_power -= *v as f64 * w;
                if policy == Negative::Clamp {
                    *v = 0.0;
                }
            }
        }
    }
}

/// The refusal of `--negative refuse` when `r` found negatives.
fn refuse_negatives(r: &NegativeReport, path: &Path) -> Result<()> {
    if r.policy == Negative::Refuse && r.count > 0 {
        return Err(Error::invalid(
            path,
            r.message(path)
                .expect("negatives")
                .trim_start_matches(&format!("{}: ", path.display()))
                .to_string(),
        ));
    }
    Ok(())
}

/// An environment plus what the input checks found.
#[derive(Clone, Debug)]
pub struct LoadedEnvironment {
    /// The environment as read (negative values clamped, NaN/Inf set to 0 if asked).
    pub env: Environment,
    /// The file it was read from.
    pub path: PathBuf,
    /// What the texel checks found (clamped negatives, non-finite values).
    pub report: TexelReport,
    /// How files whose content and name disagree were read ([`io::content_mismatch`]), one
    /// line each.
    pub read_as: Vec<String>,
    /// The negative texels, their power and what was done with them.
    pub negative: NegativeReport,
}

impl LoadedEnvironment {
    /// Warnings to print: files read by content against their name, then negative texels
    /// (with the power clamping added or keeping took away) and NaN/Inf zeroed.
    pub fn warnings(&self) -> Vec<String> {
        input_warnings(&self.path, &self.read_as, &self.negative, &self.report)
    }

    /// What the input checks found, as a streamed read of the same file reports it.
    pub fn checks(&self) -> InputChecks {
        InputChecks {
            report: self.report.clone(),
            read_as: self.read_as.clone(),
            negative: self.negative.clone(),
        }
    }
}

impl Environment {
    /// The default cube face size: the largest power of two not above width/4 for an equirect,
    /// the cube's own size otherwise.
    pub fn natural_face_size(&self) -> usize {
        match self {
            Environment::Equirect(img) => equirect_natural_face_size(img.width),
            Environment::Cube(c) => c.size,
        }
    }

    /// Resamples to a cube with n×n faces (turned by `rotate_deg` about +Y). A cube of the
    /// same size and no rotation is returned as it is.
    pub fn to_cube(
        &self,
        n: usize,
        filter: Filter,
        rotate_deg: f32,
        progress: &dyn Progress,
    ) -> Cubemap {
        match self {
            Environment::Equirect(img) => {
                equirect::equirect_to_cube(img, n, filter, rotate_deg, progress)
            }
            Environment::Cube(c) if c.size == n && rotate_deg == 0.0 => c.clone(),
            Environment::Cube(c) => cube_to_cube(c, n, filter, rotate_deg, progress),
        }
    }
}

/// The largest power of two not above width/4: the natural face size of a `width`-wide
/// equirect.
fn equirect_natural_face_size(width: usize) -> usize {
    let q = (width / 4).max(1);
    1usize << (usize::BITS - 1 - q.leading_zeros())
}

/// Resamples a cube to another size: exact box reduction for power-of-two down-sizing,
/// otherwise a stratified average of bilinear taps over each texel.
fn cube_to_cube(
    src: &Cubemap,
    n: usize,
    filter: Filter,
    rotate_deg: f32,
    progress: &dyn Progress,
) -> Cubemap {
    if rotate_deg == 0.0
        && filter != Filter::Bilinear
        && n < src.size
        && src.size.is_multiple_of(n)
        && (src.size / n).is_power_of_two()
    {
        let mut c = src.downsample();
        while c.size > n {
            c = c.downsample();
        }
        return c;
    }
    let k = match filter {
        Filter::Area | Filter::Adaptive => (src.size.div_ceil(n) * 2).clamp(1, 16),
        Filter::Bilinear => 1,
    };
    crate::traverse::map_cube_texels(n, progress, |face, i, j| {
        let step = 2.0 / n as f32;
        let mut acc = [0.0f32; 3];
        let mut ws = 0.0;
        for b in 0..k {
            for a in 0..k {
                let s = i as f32 * step - 1.0 + (a as f32 + 0.5) * step / k as f32;
                let t = j as f32 * step - 1.0 + (b as f32 + 0.5) * step / k as f32;
                let q = 1.0 + s * s + t * t;
                let w = 1.0 / (q * q.sqrt());
                let c = src.sample_bilinear(equirect::rotate_y(face.direction(s, t), -rotate_deg));
                for c_ in 0..3 {
                    acc[c_] += c[c_] * w;
                }
                ws += w;
            }
        }
        acc.map(|a| a / ws)
    })
}

const IMAGE_EXTS: [&str; 5] = ["exr", "hdr", "png", "jpg", "jpeg"];

/// Finds `stem.<ext>` in `dir` for any readable extension.
pub(crate) fn find_with_stem(dir: &Path, stem: &str) -> Option<PathBuf> {
    IMAGE_EXTS
        .iter()
        .map(|e| dir.join(format!("{stem}.{e}")))
        .find(|p| p.is_file())
}

/// Reads one HDR image and applies the input policy (NaN/Inf refused unless `sanitize`,
/// negatives clamped), with the warning when its content and name disagree.
pub(crate) fn read_hdr_image(
    path: &Path,
    sanitize: bool,
) -> Result<(Image, TexelReport, Option<String>)> {
    read_hdr_image_shaped(path, sanitize, &|_, _| Ok(()))
}

/// [`read_hdr_image`], with the shape the caller needs checked on the header's size before
/// anything is decoded (`shape` returns the error for a size it cannot use).
fn read_hdr_image_shaped(
    path: &Path,
    sanitize: bool,
    shape: &(dyn Fn(u64, u64) -> Result<()> + Sync),
) -> Result<(Image, TexelReport, Option<String>)> {
    // Large files whose format decodes from a stream are not held whole: the header, the
    // size and the name check need the first bytes only.
    const HEAD: usize = 64 << 10;
    let file_len = std::fs::metadata(path)
        .map_err(|e| Error::io(path, e))?
        .len();
    if file_len > 2 * HEAD as u64 {
        let head = read_head(path, HEAD)?;
        if let Some((w, h)) = io::declared_size(&head) {
            shape(w, h)?;
        }
        if let Some(img) = io::decode_file_streamed(path, &head, file_len) {
            let mut img = img?;
            shape(img.width as u64, img.height as u64)?;
            let report = check_finite(&mut img, path, sanitize)?;
            return Ok((img, report, io::content_mismatch(path, &head)));
        }
    }
    let bytes = io::budget::read_file(path)?;
    if let Some((w, h)) = io::declared_size(&bytes) {
        shape(w, h)?;
    }
    let mut img = io::decode_image(path, &bytes, ColorSpace::Srgb)?;
    shape(img.width as u64, img.height as u64)?;
    let report = check_finite(&mut img, path, sanitize)?;
    Ok((img, report, io::content_mismatch(path, &bytes)))
}

/// The first `len` bytes of `path` (fewer if it is shorter).
fn read_head(path: &Path, len: usize) -> Result<Vec<u8>> {
    use std::io::Read;
    let f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut head = Vec::with_capacity(len);
    f.take(len as u64)
        .read_to_end(&mut head)
        .map_err(|e| Error::io(path, e))?;
    Ok(head)
}

/// The NaN/Inf half of [`check_texels`]: refused unless `sanitize` (then 0). Negative values
/// are left for [`apply_negative_policy`], which needs the layout to weigh them.
fn check_finite(img: &mut Image, path: &Path, sanitize: bool) -> Result<TexelReport> {
    let mut report = TexelReport::default();
    let bad = img.data.iter().filter(|v| !v.is_finite()).count();
    if bad > 0 {
        if !sanitize {
            return Err(Error::NonFinite {
                path: path.to_path_buf(),
                count: bad,
            });
        }
        img.data
            .iter_mut()
            .filter(|v| !v.is_finite())
            .for_each(|v| *v = 0.0);
        report.non_finite_zeroed = bad;
    }
    Ok(report)
}

/// Loads an environment from a file or a folder of faces, negatives clamped (see
/// [`load_environment_with`]).
pub fn load_environment(path: &Path, sanitize: bool) -> Result<LoadedEnvironment> {
    load_environment_with(
        path,
        EnvPolicy {
            sanitize,
            negative: Negative::Clamp,
        },
    )
}

/// Loads an environment from a file or a folder of faces under `policy`; the report says
/// what the negative texels weighed and what was done with them.
pub fn load_environment_with(path: &Path, policy: EnvPolicy) -> Result<LoadedEnvironment> {
    let mut loaded = load_unchecked(path, policy.sanitize)?;
    let r = apply_negative_policy(&mut loaded.env, path, policy.negative)?;
    if policy.negative == Negative::Clamp {
        loaded.report.negative_clamped = r.count;
        loaded.report.most_negative = r.most_negative;
    }
    loaded.negative = r;
    Ok(loaded)
}

/// An environment opened for a bake: read whole, or (a large equirect whose format reads row
/// by row) left open to be resampled as its rows stream in, never held whole.
// One per run, moved once: boxing the loaded variant would buy nothing.
#[allow(clippy::large_enum_variant)]
pub enum Opened {
    /// Read and checked.
    Loaded(LoadedEnvironment),
    /// An equirect to resample with [`EquirectStream::to_cube`].
    Streamed(EquirectStream),
}

impl From<LoadedEnvironment> for Opened {
    fn from(l: LoadedEnvironment) -> Self {
        Opened::Loaded(l)
    }
}

impl Opened {
    /// The file or folder it comes from.
    pub fn path(&self) -> &Path {
        match self {
            Opened::Loaded(l) => &l.path,
            Opened::Streamed(s) => &s.path,
        }
    }

    /// [`Environment::natural_face_size`] of the environment.
    pub fn natural_face_size(&self) -> usize {
        match self {
            Opened::Loaded(l) => l.env.natural_face_size(),
            Opened::Streamed(s) => s.natural_face_size(),
        }
    }

    /// The warnings known when opened (a streamed input's come with its cube).
    pub fn warnings(&self) -> Vec<String> {
        match self {
            Opened::Loaded(l) => l.warnings(),
            Opened::Streamed(_) => Vec::new(),
        }
    }
}

/// A large equirect read as a stream of rows (Radiance HDR): the checks of
/// [`load_environment_with`] (NaN/Inf, negatives, the name against the content) are made row
/// by row as the rows arrive, with the same reports.
pub struct EquirectStream {
    path: PathBuf,
    rows: Box<dyn crate::stream::RowSource>,
    policy: EnvPolicy,
    read_as: Option<String>,
}

/// A cube resampled from an [`EquirectStream`] and what the input checks found.
#[derive(Clone, Debug)]
pub struct StreamedCube {
    /// The cube, bit-identical to the whole-image resample of the checked input.
    pub cube: Cubemap,
    /// With [`EquirectStream::to_cube_with_mirror`]: the adaptive cube of the same size
    /// (`crate::equirect::adaptive_from_area` of `cube`, the same bits).
    pub mirror: Option<Cubemap>,
    /// What the texel checks found (as [`LoadedEnvironment::report`]).
    pub report: TexelReport,
    /// How a file whose content and name disagree was read.
    pub read_as: Vec<String>,
    /// The negative texels, their power and what was done with them.
    pub negative: NegativeReport,
    /// What the streamed read held.
    pub window: crate::stream::WindowStats,
}

impl StreamedCube {
    /// The warnings [`LoadedEnvironment::warnings`] gives for the same input.
    pub fn warnings(&self, path: &Path) -> Vec<String> {
        input_warnings(path, &self.read_as, &self.negative, &self.report)
    }
}

/// What the input checks of a streamed read found: the reports of [`LoadedEnvironment`]
/// without its image.
#[derive(Clone, Debug)]
pub struct InputChecks {
    /// What the texel checks found (as [`LoadedEnvironment::report`]).
    pub report: TexelReport,
    /// How a file whose content and name disagree was read.
    pub read_as: Vec<String>,
    /// The negative texels, their power and what was done with them.
    pub negative: NegativeReport,
}

impl InputChecks {
    /// The warnings [`LoadedEnvironment::warnings`] gives for the same input.
    pub fn warnings(&self, path: &Path) -> Vec<String> {
        input_warnings(path, &self.read_as, &self.negative, &self.report)
    }
}

/// Warnings of an input: files read by content against their name, then negative texels and
/// NaN/Inf zeroed.
fn input_warnings(
    path: &Path,
    read_as: &[String],
    negative: &NegativeReport,
    report: &TexelReport,
) -> Vec<String> {
    let mut w = read_as.to_vec();
    w.extend(negative.message(path));
    let zeroed = TexelReport {
        negative_clamped: 0,
        ..report.clone()
    };
    w.extend(zeroed.warnings(path));
    w
}

impl EquirectStream {
    /// The file read.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// [`Environment::natural_face_size`] of the equirect.
    pub fn natural_face_size(&self) -> usize {
        equirect_natural_face_size(self.width())
    }

    /// Width of the equirect.
    pub fn width(&self) -> usize {
        self.rows.width()
    }

    /// Height of the equirect.
    pub fn height(&self) -> usize {
        self.rows.height()
    }

    /// Reads the whole file instead ([`load_environment_with`] under the same policy), for a
    /// use that needs the image itself.
    pub fn load(self) -> Result<LoadedEnvironment> {
        load_environment_with(&self.path, self.policy)
    }

    /// The window a resample to n² faces will hold, before reading (for budgets).
    pub fn window(&self, n: usize) -> crate::stream::WindowStats {
        crate::stream::window_stats(
            self.width(),
            self.height(),
            self.rows.channels(),
            n,
            crate::stream::DEFAULT_BAND,
        )
    }

    /// Reads the rows, checking them, into a cube with n×n faces turned by `rotate_deg`
    /// (by `filter`): the cube [`Environment::to_cube`] makes from the loaded image. A
    /// NaN/Inf refused or negatives refused is the error of [`load_environment_with`], after
    /// the whole file is read (the counts are the file's).
    pub fn to_cube(
        self,
        n: usize,
        filter: Filter,
        rotate_deg: f32,
        progress: &dyn Progress,
    ) -> Result<StreamedCube> {
        self.streamed_cube(n, filter, false, rotate_deg, progress)
    }

    /// [`Self::to_cube`] by the area filter, with its adaptive mirror (`mirror`) from the
    /// same read.
    pub fn to_cube_with_mirror(
        self,
        n: usize,
        rotate_deg: f32,
        progress: &dyn Progress,
    ) -> Result<StreamedCube> {
        self.streamed_cube(n, Filter::Area, true, rotate_deg, progress)
    }

    fn streamed_cube(
        self,
        n: usize,
        filter: Filter,
        mirror: bool,
        rotate_deg: f32,
        progress: &dyn Progress,
    ) -> Result<StreamedCube> {
        let (mut checked, path, read_as) = self.checked();
        let (cube, mirror, window) = crate::stream::streamed(
            &mut checked,
            n,
            filter,
            mirror,
            rotate_deg,
            crate::stream::DEFAULT_BAND,
            progress,
        )?;
        let checks = checked.finish(&path, read_as)?;
        Ok(StreamedCube {
            cube,
            mirror,
            report: checks.report,
            read_as: checks.read_as,
            negative: checks.negative,
            window,
        })
    }

    /// Reads the rows, checking them, and hands them to `visit` in order, `band` rows at a
    /// time (the last band may be shorter) as an image of that many rows, with the first
    /// row's index: for a use that reduces the equirect row by row (a projection, a box
    /// reduction) and never needs it whole. The values are the loaded image's (the same
    /// checks); a NaN/Inf refused or negatives refused is the error of
    /// [`load_environment_with`], after the whole file is read.
    pub fn read_bands(
        self,
        band: usize,
        mut visit: impl FnMut(usize, &crate::image::Image) -> Result<()>,
    ) -> Result<InputChecks> {
        use crate::stream::RowSource;
        let (mut checked, path, read_as) = self.checked();
        let (w, h, ch) = (checked.w, checked.h, checked.channels());
        let band = band.clamp(1, h.max(1));
        let bytes = (band * w * ch * 4) as u64;
        let _budget = io::budget::reserve(
            &path,
            &format!("a streamed read of a {w}x{h} image ({band} rows at a time)"),
            bytes,
        )?;
        let mut data = Vec::new();
        data.try_reserve_exact(band * w * ch)
            .map_err(|_| io::budget::out_of_memory(&path, bytes))?;
        let mut first = 0;
        while first < h {
            let count = band.min(h - first);
            data.clear();
            checked.read_rows(count, &mut data)?;
            let img = crate::image::Image::from_data(w, count, ch, std::mem::take(&mut data))?;
            visit(first, &img)?;
            data = img.data;
            first += count;
        }
        checked.finish(&path, read_as)
    }

    /// The rows behind the input checks, the file, and how it was read.
    fn checked(self) -> (CheckedRows, PathBuf, Option<String>) {
        let EquirectStream {
            path,
            rows,
            policy,
            read_as,
        } = self;
        let (w, h) = (rows.width(), rows.height());
        let checked = CheckedRows {
            inner: rows,
            policy,
            non_finite: 0,
            negative: NegativeReport {
                policy: policy.negative,
                ..Default::default()
            },
            row: 0,
            w,
            h,
        };
        (checked, path, read_as)
    }
}

/// Rows with the input checks of [`check_finite`] and [`apply_negative_policy`] applied to
/// each as it arrives (the same values, the same sums in the same order).
struct CheckedRows {
    inner: Box<dyn crate::stream::RowSource>,
    policy: EnvPolicy,
    non_finite: usize,
    negative: NegativeReport,
    row: usize,
    w: usize,
    h: usize,
}

impl CheckedRows {
    /// What the checks found once every row is read, or the refusal of
    /// [`load_environment_with`] under the same policy.
    fn finish(self, path: &Path, read_as: Option<String>) -> Result<InputChecks> {
        let mut report = TexelReport::default();
        if self.non_finite > 0 {
            if !self.policy.sanitize {
                return Err(Error::NonFinite {
                    path: path.to_path_buf(),
                    count: self.non_finite,
                });
            }
            report.non_finite_zeroed = self.non_finite;
        }
        let negative = self.negative;
        refuse_negatives(&negative, path)?;
        if self.policy.negative == Negative::Clamp {
            report.negative_clamped = negative.count;
            report.most_negative = negative.most_negative;
        }
        Ok(InputChecks {
            report,
            read_as: read_as.into_iter().collect(),
            negative,
        })
    }
}

impl crate::stream::RowSource for CheckedRows {
    fn path(&self) -> &Path {
        self.inner.path()
    }
    fn width(&self) -> usize {
        self.w
    }
    fn height(&self) -> usize {
        self.h
    }
    fn channels(&self) -> usize {
        self.inner.channels()
    }
    fn read_rows(&mut self, count: usize, out: &mut Vec<f32>) -> Result<()> {
        let start = out.len();
        self.inner.read_rows(count, out)?;
        let ch = self.inner.channels();
        for row in out[start..].chunks_exact_mut(self.w * ch) {
            for v in row.iter_mut().filter(|v| !v.is_finite()) {
                self.non_finite += 1;
                if self.policy.sanitize {
                    *v = 0.0;
                }
            }
            let sa = crate::equirect::row_solid_angle(self.row, self.w, self.h);
            visit_negatives(&mut self.negative, self.policy.negative, row, ch, &|_| sa);
            self.row += 1;
        }
        Ok(())
    }
}

/// Equirects whose decoded image (12 bytes a pixel) reaches this size are streamed by
/// [`open_environment_with`] (2048×1024 and up): below it the image is small against the bake
/// (a 1024×512 one is 6 MB, a tenth of a 256² bake), and the whole read is cheaper than the
/// streamed resample's texel order (8 bytes a cube texel, and ~50 ns a texel to make it).
pub const STREAM_IMAGE_BYTES: u64 = 16 << 20;

/// Opens an environment for a bake that resamples it to a cube: an equirect of at least
/// [`STREAM_IMAGE_BYTES`] decoded, in a format read row by row (Radiance HDR, scan-line
/// OpenEXR in increasing line order), is left open as an [`EquirectStream`] (its rows read as
/// the resample needs them, neither the file nor the image ever held whole); anything else is
/// [`load_environment_with`].
pub fn open_environment_with(path: &Path, policy: EnvPolicy) -> Result<Opened> {
    open_streaming_from(path, policy, STREAM_IMAGE_BYTES)
}

/// [`open_environment_with`], streaming equirects of at least `min_image_bytes` decoded.
pub(crate) fn open_streaming_from(
    path: &Path,
    policy: EnvPolicy,
    min_image_bytes: u64,
) -> Result<Opened> {
    let streamable = path.is_file() && io::container::Container::from_extension(path).is_none();
    if streamable {
        let file_len = std::fs::metadata(path)
            .map_err(|e| Error::io(path, e))?
            .len();
        let head = read_head(path, 64 << 10)?;
        let equirect = matches!(io::declared_size(&head),
            Some((w, h)) if w == 2 * h && w.saturating_mul(h).saturating_mul(12) >= min_image_bytes);
        if equirect && io::container::Container::sniff(&head).is_none() {
            if let Some(rows) = io::open_rows_streamed(path, &head, file_len) {
                return Ok(Opened::Streamed(EquirectStream {
                    path: path.to_path_buf(),
                    rows: rows?,
                    policy,
                    read_as: io::content_mismatch(path, &head),
                }));
            }
        }
    }
    load_environment_with(path, policy).map(Opened::Loaded)
}

/// Reads an environment, NaN/Inf handled, negatives as read.
fn load_unchecked(path: &Path, sanitize: bool) -> Result<LoadedEnvironment> {
    if path.is_dir() {
        // Find all six first (a missing face is reported before any decoding), then decode
        // them in parallel: the decoders themselves run on one thread each.
        let paths = Face::ALL
            .iter()
            .map(|face| {
                find_with_stem(path, face.name())
                    .or_else(|| find_with_stem(path, &format!("m0_{}", face.name())))
                    .ok_or_else(|| {
                        Error::invalid(
                            path,
                            format!(
                                "folder has no face '{}' (expected px, nx, py, ny, pz, nz images)",
                                face.name()
                            ),
                        )
                    })
            })
            .collect::<Result<Vec<PathBuf>>>()?;
        // Square faces of one size, checked on each header before any face is decoded.
        let mut first: Option<(u64, u64, PathBuf)> = None;
        for p in &paths {
            let bytes = io::budget::read_file(p)?;
            let Some((w, h)) = io::declared_size(&bytes) else {
                continue;
            };
            if w != h {
                return Err(Error::invalid(
                    p,
                    format!("a cube face must be square, this one is {w}x{h}"),
                ));
            }
            match &first {
                Some((fw, _, fp)) if *fw != w => {
                    return Err(Error::invalid(
                        p,
                        format!("face of {w}x{h}, but {} is {fw}x{fw}", fp.display()),
                    ))
                }
                Some(_) => {}
                None => first = Some((w, h, p.clone())),
            }
        }
        use rayon::prelude::*;
        let decoded = paths
            .par_iter()
            .map(|p| read_hdr_image(p, sanitize))
            .collect::<Result<Vec<_>>>()?;
        let mut report = TexelReport::default();
        let mut read_as = Vec::new();
        let mut faces = Vec::with_capacity(6);
        for (img, r, note) in decoded {
            merge(&mut report, &r);
            read_as.extend(note);
            faces.push(img);
        }
        let faces: [Image; 6] = faces.try_into().expect("six faces");
        let cube = Cubemap::from_faces(faces).map_err(|e| Error::invalid(path, e.to_string()))?;
        // Faces written in an engine's frame say so in a sidecar: read back in ours.
        let sidecar = crate::orientation::sidecar_path(path);
        let recorded = if sidecar.is_file() {
            let bytes = std::fs::read(&sidecar).map_err(|e| Error::io(&sidecar, e))?;
            Some(
                crate::orientation::from_sidecar(&bytes)
                    .map_err(|e| Error::invalid(&sidecar, e))?,
            )
        } else {
            None
        };
        let cube = undo_orientation(cube, recorded, path, &mut read_as);
        return Ok(LoadedEnvironment {
            env: Environment::Cube(cube),
            path: path.to_path_buf(),
            report,
            read_as,
            negative: NegativeReport::default(),
        });
    }
    if !path.exists() {
        return Err(Error::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or folder"),
        ));
    }
    if let Some((mut mips, note, metadata)) = read_container_cube(path)? {
        let mut cube = mips.levels.swap_remove(0);
        let mut report = TexelReport::default();
        for face in &mut cube.faces {
            merge(&mut report, &check_finite(face, path, sanitize)?);
        }
        let mut read_as: Vec<String> = note.into_iter().collect();
        // The orientation a KTX key or (DDS) a sidecar records; none: a foreign file.
        let recorded = match crate::orientation::from_metadata(&metadata) {
            Some(m) => Some(m.map_err(|e| Error::invalid(path, e))?),
            None => {
                let sidecar = crate::orientation::sidecar_path(path);
                if sidecar.is_file() {
                    let bytes = std::fs::read(&sidecar).map_err(|e| Error::io(&sidecar, e))?;
                    Some(
                        crate::orientation::from_sidecar(&bytes)
                            .map_err(|e| Error::invalid(&sidecar, e))?,
                    )
                } else {
                    read_as.push(format!(
                        "{}: no {} metadata (nor {}): read as a cube in docs/CONVENTIONS.md's frame; if an engine's tool wrote it in its own frame (Bevy's z negated, cmgen's turn), the bake is turned the same way",
                        path.display(),
                        crate::orientation::METADATA_KEY,
                        sidecar.file_name().unwrap_or_default().to_string_lossy()
                    ));
                    None
                }
            }
        };
        let cube = undo_orientation(cube, recorded, path, &mut read_as);
        return Ok(LoadedEnvironment {
            env: Environment::Cube(cube),
            path: path.to_path_buf(),
            report,
            read_as,
            negative: NegativeReport::default(),
        });
    }
    let (img, report, note) = read_hdr_image_shaped(path, sanitize, &|w, h| {
        if layout_of(w, h).is_some() {
            Ok(())
        } else {
            Err(layout_error(path, w, h))
        }
    })?;
    let env = classify_layout(path, img)?;
    Ok(LoadedEnvironment {
        env,
        path: path.to_path_buf(),
        report,
        read_as: note.into_iter().collect(),
        negative: NegativeReport::default(),
    })
}

fn merge(into: &mut TexelReport, r: &TexelReport) {
    into.negative_clamped += r.negative_clamped;
    into.non_finite_zeroed += r.non_finite_zeroed;
    into.most_negative = into.most_negative.min(r.most_negative);
}

/// The layouts [`classify_layout`] takes, from a size alone: "equirect", "cross" or "strip".
fn layout_of(w: u64, h: u64) -> Option<&'static str> {
    if w == 2 * h {
        Some("equirect")
    } else if 3 * w == 4 * h || 4 * w == 3 * h {
        Some("cross")
    } else if w == 6 * h || h == 6 * w {
        Some("strip")
    } else {
        None
    }
}

fn layout_error(path: &Path, w: u64, h: u64) -> Error {
    Error::unsupported(
        path,
        format!(
            "layout of a {w}x{h} image (expected 2:1 equirect, 4:3 or 3:4 cross, 6:1 or 1:6 strip)"
        ),
    )
}

/// Decides the layout of a single image from its aspect ratio.
pub fn classify_layout(path: &Path, img: Image) -> Result<Environment> {
    let (w, h) = (img.width, img.height);
    if w == 2 * h {
        return Ok(Environment::Equirect(img));
    }
    // (columns, rows, face positions as (face, column, row, rotated 180°)).
    type Slot = (Face, usize, usize, bool);
    let hcross: [Slot; 6] = [
        (Face::Px, 2, 1, false),
        (Face::Nx, 0, 1, false),
        (Face::Py, 1, 0, false),
        (Face::Ny, 1, 2, false),
        (Face::Pz, 1, 1, false),
        (Face::Nz, 3, 1, false),
    ];
    let vcross: [Slot; 6] = [
        (Face::Px, 2, 1, false),
        (Face::Nx, 0, 1, false),
        (Face::Py, 1, 0, false),
        (Face::Ny, 1, 2, false),
        (Face::Pz, 1, 1, false),
        (Face::Nz, 1, 3, true),
    ];
    let hstrip: [Slot; 6] = std::array::from_fn(|k| (Face::from_index(k), k, 0, false));
    let vstrip: [Slot; 6] = std::array::from_fn(|k| (Face::from_index(k), 0, k, false));
    let layout = if 3 * w == 4 * h {
        (w / 4, hcross)
    } else if 4 * w == 3 * h {
        (w / 3, vcross)
    } else if w == 6 * h {
        (h, hstrip)
    } else if h == 6 * w {
        (w, vstrip)
    } else {
        return Err(Error::unsupported(
            path,
            format!("layout of a {w}x{h} image (expected 2:1 equirect, 4:3 or 3:4 cross, 6:1 or 1:6 strip)"),
        ));
    };
    let (n, slots) = layout;
    let faces: [Image; 6] = std::array::from_fn(|k| {
        let (_, col, row, flip) = slots[k];
        let mut f = Image::new(n, n, 3);
        for j in 0..n {
            for i in 0..n {
                let (si, sj) = if flip { (n - 1 - i, n - 1 - j) } else { (i, j) };
                f.texel_mut(i, j)
                    .copy_from_slice(&img.rgb(col * n + si, row * n + sj));
            }
        }
        f
    });
    Ok(Environment::Cube(Cubemap::from_faces(faces)?))
}

pub use crate::io::layout::Layout;

/// Reads `path` as a KTX2, KTX1 or DDS cube (found by its magic bytes, or by its extension
/// when it is too short to have any); `None` if it is not a container file. A container
/// holding a 2D image is refused here (cube readers need six faces). With the cube, the
/// warning when the file's name says another format ([`io::content_mismatch`]).
/// A cube read from a file written in an engine's frame (`recorded`: A, ours from file),
/// turned back into ours (texel d of ours is the file's at Aᵀ·d), with a line saying so.
fn undo_orientation(
    cube: Cubemap,
    recorded: Option<crate::orientation::Matrix>,
    path: &Path,
    notes: &mut Vec<String>,
) -> Cubemap {
    use crate::orientation as o;
    match recorded {
        Some(m) if m != o::IDENTITY => {
            notes.push(format!(
                "{}: stored in an engine's frame (ours from file: {}), read back in ours",
                path.display(),
                o::format(&m)
            ));
            o::transform(&cube, &o::transpose(&m))
        }
        _ => cube,
    }
}

/// The cube chain of a KTX2 / KTX1 / DDS file (`None` for other files), how a content /
/// name mismatch was read, and the container's key/value metadata.
#[allow(clippy::type_complexity)]
fn read_container_cube(
    path: &Path,
) -> Result<Option<(CubeMips, Option<String>, Vec<(String, Vec<u8>)>)>> {
    if path.is_dir() {
        return Ok(None);
    }
    let named = io::container::Container::from_extension(path).is_some();
    let mut head = [0u8; 12];
    let n = {
        use std::io::Read;
        let mut f = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
        f.read(&mut head).map_err(|e| Error::io(path, e))?
    };
    if io::container::Container::sniff(&head[..n]).is_none() {
        if named {
            return Err(Error::invalid(
                path,
                "not a KTX2, KTX or DDS file (the identifier is missing or the file is truncated)",
            ));
        }
        return Ok(None);
    }
    let bytes = io::budget::read_file(path)?;
    let tex = io::container::read(path, &bytes)?.expect("sniffed");
    if tex.payload.faces != 6 {
        return Err(Error::unsupported(
            path,
            "a 2D texture, not a cube map (convert it to an equirect .exr first)",
        ));
    }
    let note = io::content_mismatch(path, &head[..n]);
    io::texture::decode_cube(path, &tex.payload).map(|m| Some((m, note, tex.metadata)))
}

/// The A channel of a cube chain in a container (`rgba16f`, `rgba32f`), each of the three
/// channels holding it ([`io::texture::decode_alpha`]); `None` for face images and formats
/// without one. The custom lookup keeps its mid-interval correction there.
pub fn read_cube_chain_alpha(path: &Path) -> Result<Option<CubeMips>> {
    if path.is_dir() {
        return Ok(None);
    }
    let bytes = io::budget::read_file(path)?;
    match io::container::read(path, &bytes)? {
        Some(tex) => io::texture::decode_alpha(path, &tex.payload),
        None => Ok(None),
    }
}

/// Loads a cube chain written by [`crate::output::encode_cube`] (faces or any container).
pub fn read_cube_chain(path: &Path) -> Result<CubeMips> {
    if let Some((mips, _, _)) = read_container_cube(path)? {
        return Ok(mips);
    }
    if find_with_stem(path, "m0_px").is_some() && find_with_stem(path, "px").is_some() {
        return Err(Error::invalid(
            path,
            "holds both a single cube (px…) and a chain (m0_px…): bake into separate folders",
        ));
    }
    let mut levels: Vec<Cubemap> = Vec::new();
    for l in 0.. {
        let stem = format!("m{l}_px");
        if find_with_stem(path, &stem).is_none() {
            break;
        }
        let faces: Vec<Image> = Face::ALL
            .iter()
            .map(|f| {
                let p = find_with_stem(path, &format!("m{l}_{}", f.name())).ok_or_else(|| {
                    Error::invalid(path, format!("missing face m{l}_{}", f.name()))
                })?;
                let mut img = io::read_image(&p, ColorSpace::Linear)?;
                check_texels(&mut img, &p, false)?;
                Ok(img)
            })
            .collect::<Result<_>>()?;
        let cube = Cubemap::from_faces(faces.try_into().expect("six"))?;
        // Levels halve (cube::mip_sizes): anything else is a level left by another bake.
        if let Some(first) = levels.first() {
            let want = (first.size >> l).max(1);
            if cube.size != want {
                return Err(Error::invalid(
                    path,
                    format!(
                        "level {l} is {}² but a chain from {}² needs {want}²: m{l}_* is left from another bake",
                        cube.size, first.size
                    ),
                ));
            }
        }
        levels.push(cube);
    }
    if levels.is_empty() {
        match load_environment(path, false)?.env {
            Environment::Cube(c) => levels.push(c),
            Environment::Equirect(_) => {
                return Err(Error::invalid(
                    path,
                    "expected a cube, found an equirect image",
                ))
            }
        }
    }
    Ok(CubeMips { levels })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::progress::NoProgress;
    use glam::Vec3;

    /// Writes `img` encoded as `as_ext` under the name `name` (a name that may disagree).
    fn write_as(dir: &Path, name: &str, as_ext: &str, img: &Image) -> PathBuf {
        let bytes = io::encode_image(
            Path::new(&format!("x.{as_ext}")),
            img,
            &io::WriteOptions::default(),
        )
        .unwrap();
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        p
    }

    #[test]
    fn a_large_hdr_read_from_a_stream_is_the_same_image_and_truncation_still_fails() {
        // Above 128 KiB a Radiance file is decoded from a buffered reader (its bytes not held
        // whole): the same texels as decoding its bytes, the same checks before decoding.
        let d = tempfile::tempdir().unwrap();
        let (w, h) = (512, 256);
        let data: Vec<f32> = (0..w * h * 3)
            .map(|k| ((k * 7919) % 1009) as f32 * 0.37 + (k % 3) as f32)
            .collect();
        let img = Image::from_data(w, h, 3, data).unwrap();
        let p = write_as(d.path(), "big.hdr", "hdr", &img);
        let bytes = std::fs::read(&p).unwrap();
        assert!(bytes.len() > 128 << 10, "{}", bytes.len());
        let want = io::decode_image(&p, &bytes, ColorSpace::Linear).unwrap();
        let (got, _, note) = read_hdr_image(&p, false).unwrap();
        assert_eq!(got, want);
        assert!(note.is_none());
        // The same bytes under another name: read by content, with the warning.
        let q = d.path().join("big.exr");
        std::fs::write(&q, &bytes).unwrap();
        let (got, _, note) = read_hdr_image(&q, false).unwrap();
        assert_eq!(got, want);
        assert!(note.unwrap().contains("Radiance"));
        // Cut short: an error naming the file, never a panic or a black band.
        let cut = d.path().join("cut.hdr");
        std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
        let err = read_hdr_image(&cut, false).unwrap_err().to_string();
        assert!(err.contains("cut.hdr"), "{err}");
    }

    fn same_bits(a: &Cubemap, b: &Cubemap) -> bool {
        a.faces.iter().zip(&b.faces).all(|(x, y)| {
            x.data.len() == y.data.len()
                && x.data
                    .iter()
                    .zip(&y.data)
                    .all(|(p, q)| p.to_bits() == q.to_bits())
        })
    }

    #[test]
    fn a_large_hdr_opened_as_a_stream_gives_the_loaded_cube_and_reports() {
        // Above 128 KiB a Radiance equirect is resampled as its rows arrive: the cube, the
        // reports and the warnings of loading it whole and resampling that.
        let d = tempfile::tempdir().unwrap();
        let (w, h) = (600, 300);
        let data: Vec<f32> = (0..w * h * 3)
            .map(|k| match k % 101 {
                0 => 3e4,
                1..=7 => 0.0,
                _ => ((k * 7919) % 1009) as f32 * 0.37 + (k % 3) as f32,
            })
            .collect();
        let img = Image::from_data(w, h, 3, data).unwrap();
        for name in ["big.hdr", "big_named.exr"] {
            let p = write_as(d.path(), name, "hdr", &img);
            let policy = EnvPolicy::default();
            let Opened::Streamed(s) = open_streaming_from(&p, policy, 0).unwrap() else {
                panic!("{name} is streamed")
            };
            let loaded = load_environment_with(&p, policy).unwrap();
            for (n, rot) in [(64, 0.0), (37, 30.0)] {
                let want = loaded.env.to_cube(n, Filter::Area, rot, &NoProgress);
                let Opened::Streamed(s) = open_streaming_from(&p, policy, 0).unwrap() else {
                    unreachable!()
                };
                let got = s.to_cube(n, Filter::Area, rot, &NoProgress).unwrap();
                assert!(same_bits(&got.cube, &want), "{name} -> {n}");
                assert_eq!(got.report, loaded.report);
                assert_eq!(got.negative, loaded.negative);
                assert_eq!(got.warnings(&p), loaded.warnings());
                assert!(got.window.peak_rows < h / 4, "{:?}", got.window);
            }
            drop(s);
            // Cut short: opened (the header is whole), then an error naming the file and
            // the scan line, never a cube.
            let bytes = std::fs::read(&p).unwrap();
            let cut = d.path().join(format!("cut_{name}"));
            std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
            let Opened::Streamed(s) = open_streaming_from(&cut, policy, 0).unwrap() else {
                panic!("streamed")
            };
            let e = s
                .to_cube(32, Filter::Area, 0.0, &NoProgress)
                .unwrap_err()
                .to_string();
            assert!(
                e.starts_with(&format!("{}: ", cut.display()))
                    && e.contains("scan line")
                    && !e.contains('\n'),
                "{e}"
            );
            // The same for rows handed out in bands: the bands before the cut, then the error.
            let Opened::Streamed(s) = open_streaming_from(&cut, policy, 0).unwrap() else {
                panic!("streamed")
            };
            let mut seen = 0;
            let e = s
                .read_bands(32, |_, band| {
                    seen += band.height;
                    Ok(())
                })
                .unwrap_err()
                .to_string();
            assert!(
                e.starts_with(&format!("{}: ", cut.display())) && e.contains("scan line"),
                "{e}"
            );
            assert!(seen < h, "{seen} rows of a cut file");
            // Corrupt mid-stream: a run overrunning its line.
            let mut bad = bytes.clone();
            let at = bytes.len() / 2;
            bad[at..at + 64].fill(200);
            let q = d.path().join(format!("bad_{name}"));
            std::fs::write(&q, &bad).unwrap();
            if let Ok(Opened::Streamed(s)) = open_streaming_from(&q, policy, 0) {
                let e = s
                    .to_cube(32, Filter::Area, 0.0, &NoProgress)
                    .unwrap_err()
                    .to_string();
                assert!(e.contains("bad_") && e.contains("scan line"), "{e}");
            }
        }
        // Small files and other formats are loaded whole.
        let small = write_as(d.path(), "small.hdr", "hdr", &Image::new(64, 32, 3));
        assert!(matches!(
            open_environment_with(&small, EnvPolicy::default()).unwrap(),
            Opened::Loaded(_)
        ));
        let png = write_as(d.path(), "big2.png", "png", &img);
        assert!(matches!(
            open_streaming_from(&png, EnvPolicy::default(), 0).unwrap(),
            Opened::Loaded(_)
        ));
    }

    #[test]
    fn a_large_scan_line_exr_opened_as_a_stream_gives_the_loaded_cube_and_reports() {
        // Every scan-line compression, half and float channels, NaN and negatives: a file
        // whose blocks follow one another in increasing line order is streamed block by
        // block, with the loaded read's cube (bit for bit), reports and warnings; decreasing
        // line order and tiles are read whole. Corrupt or cut: one error naming the file.
        use exr::prelude::{
            f16, Blocks, Compression, Encoding, LineOrder, SpecificChannels, Vec2, WritableImage,
        };
        let d = tempfile::tempdir().unwrap();
        let (w, h) = (600usize, 300usize);
        let value = |x: usize, y: usize, c: usize| -> f32 {
            // A hash (splitmix64's finaliser): noise no codec compresses much.
            let mut k = ((y * w + x) * 4 + c) as u64 + 1;
            k = (k ^ (k >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            k = (k ^ (k >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            match (k ^ (k >> 31)) % 1009 {
                0 => f32::NAN,
                1..=3 => -0.5,
                4 => 2e4,
                v => v as f32 * 0.013,
            }
        };
        let policy = EnvPolicy {
            sanitize: true,
            negative: Negative::Clamp,
        };
        let cases = [
            (Compression::Uncompressed, LineOrder::Increasing, None, true),
            (Compression::RLE, LineOrder::Increasing, None, true),
            (Compression::ZIP1, LineOrder::Increasing, None, true),
            (Compression::ZIP16, LineOrder::Increasing, None, true),
            (Compression::PIZ, LineOrder::Increasing, None, true),
            (Compression::PXR24, LineOrder::Increasing, None, true),
            (Compression::ZIP16, LineOrder::Decreasing, None, false),
            (
                Compression::ZIP1,
                LineOrder::Increasing,
                Some(64usize),
                false,
            ),
        ];
        for (k, (compression, line_order, tile, streams)) in cases.into_iter().enumerate() {
            let blocks = match tile {
                None => Blocks::ScanLines,
                Some(t) => Blocks::Tiles(Vec2(t, t)),
            };
            let channels = SpecificChannels::rgba(|Vec2(x, y)| {
                (
                    f16::from_f32(value(x, y, 0)),
                    f16::from_f32(value(x, y, 1)),
                    value(x, y, 2),
                    f16::from_f32(1.0),
                )
            });
            let image = exr::prelude::Image::from_encoded_channels(
                (w, h),
                Encoding {
                    compression,
                    blocks,
                    line_order,
                },
                channels,
            );
            let p = d.path().join(format!("case{k}.exr"));
            image.write().to_file(&p).unwrap();
            let at = format!("{compression:?} {line_order:?} {tile:?}");
            let opened = open_streaming_from(&p, policy, 0).unwrap();
            let Opened::Streamed(s) = opened else {
                assert!(
                    !streams,
                    "{at}: read whole ({} bytes)",
                    std::fs::metadata(&p).unwrap().len()
                );
                continue;
            };
            assert!(streams, "{at}: streamed");
            let loaded = load_environment_with(&p, policy).unwrap();
            let want = loaded.env.to_cube(48, Filter::Area, 10.0, &NoProgress);
            let got = s.to_cube(48, Filter::Area, 10.0, &NoProgress).unwrap();
            assert!(same_bits(&got.cube, &want), "{at}");
            assert_eq!(got.report, loaded.report, "{at}");
            assert!(got.report.non_finite_zeroed > 0 && got.report.negative_clamped > 0);
            assert_eq!(got.negative, loaded.negative, "{at}");
            assert_eq!(got.warnings(&p), loaded.warnings(), "{at}");
            if compression == Compression::ZIP1 {
                // A damaged block in the middle: decompression fails there.
                let mut bytes = std::fs::read(&p).unwrap();
                let mid = bytes.len() / 2;
                bytes[mid..mid + 200].iter_mut().for_each(|b| *b = !*b);
                let q = d.path().join("damaged.exr");
                std::fs::write(&q, &bytes).unwrap();
                if let Ok(Opened::Streamed(s)) = open_streaming_from(&q, policy, 0) {
                    let e = s
                        .to_cube(48, Filter::Area, 0.0, &NoProgress)
                        .unwrap_err()
                        .to_string();
                    assert!(e.starts_with(&format!("{}: ", q.display())), "{e}");
                }
                // Cut short: refused before any row is read, as the whole read refuses it.
                let cut = d.path().join("cut.exr");
                std::fs::write(&cut, &bytes[..mid]).unwrap();
                let e = open_streaming_from(&cut, policy, 0)
                    .err()
                    .unwrap()
                    .to_string();
                let whole = load_environment_with(&cut, policy).unwrap_err().to_string();
                assert_eq!(e, whole);
            }
        }
    }

    #[test]
    fn the_fixtures_streamed_give_their_loaded_cubes() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fixtures/hdri");
        let mut streamed = 0;
        for entry in std::fs::read_dir(&root).unwrap() {
            let p = entry.unwrap().path();
            let policy = EnvPolicy::default();
            let Opened::Streamed(s) = open_streaming_from(&p, policy, 0).unwrap() else {
                continue;
            };
            let loaded = load_environment_with(&p, policy).unwrap();
            let want = loaded.env.to_cube(64, Filter::Area, 0.0, &NoProgress);
            let got = s.to_cube(64, Filter::Area, 0.0, &NoProgress).unwrap();
            assert!(same_bits(&got.cube, &want), "{}", p.display());
            assert_eq!(got.warnings(&p), loaded.warnings());
            streamed += 1;
        }
        // Every fixture is an equirect in a format read row by row.
        assert!(streamed >= 4, "{streamed} fixtures streamed");
    }

    /// An image owned as a row source, standing for a decoder that can yield NaN, Inf and
    /// negatives (RGBE cannot).
    struct OwnedRows(Image, usize);

    impl crate::stream::RowSource for OwnedRows {
        fn path(&self) -> &Path {
            Path::new("rows.exr")
        }
        fn width(&self) -> usize {
            self.0.width
        }
        fn height(&self) -> usize {
            self.0.height
        }
        fn channels(&self) -> usize {
            self.0.channels
        }
        fn read_rows(&mut self, count: usize, out: &mut Vec<f32>) -> Result<()> {
            let stride = self.0.width * self.0.channels;
            out.extend_from_slice(&self.0.data[self.1 * stride..(self.1 + count) * stride]);
            self.1 += count;
            Ok(())
        }
    }

    #[test]
    fn streamed_checks_give_the_reports_of_the_whole_read() {
        // NaN, Inf and negatives (and a negative alpha) under every policy: the same cube,
        // reports, warnings and refusals as checking the whole image.
        let (w, h) = (90, 45);
        for ch in [1, 3, 4] {
            let mut img = Image::new(w, h, ch);
            for (k, v) in img.data.iter_mut().enumerate() {
                *v = match k % 53 {
                    0 => f32::NAN,
                    1 if k % 2 == 0 => f32::INFINITY,
                    2..=4 => -0.25 * (k % 7) as f32,
                    _ => (k % 13) as f32 * 0.5,
                };
            }
            let path = Path::new("rows.exr");
            for sanitize in [false, true] {
                for negative in [Negative::Clamp, Negative::Keep, Negative::Refuse] {
                    let policy = EnvPolicy { sanitize, negative };
                    // The whole read: check_finite, then the negative policy.
                    let whole = (|| {
                        let mut im = img.clone();
                        let mut report = check_finite(&mut im, path, sanitize)?;
                        let mut env = Environment::Equirect(im);
                        let neg = apply_negative_policy(&mut env, path, negative)?;
                        if negative == Negative::Clamp {
                            report.negative_clamped = neg.count;
                            report.most_negative = neg.most_negative;
                        }
                        Ok::<_, Error>((env, report, neg))
                    })();
                    let stream = EquirectStream {
                        path: path.to_path_buf(),
                        rows: Box::new(OwnedRows(img.clone(), 0)),
                        policy,
                        read_as: None,
                    };
                    let got = stream.to_cube(11, Filter::Area, 15.0, &NoProgress);
                    // The same rows handed out in bands of 7 (the last one 3).
                    let mut rows = Vec::new();
                    let banded = EquirectStream {
                        path: path.to_path_buf(),
                        rows: Box::new(OwnedRows(img.clone(), 0)),
                        policy,
                        read_as: None,
                    }
                    .read_bands(7, |first, band| {
                        assert_eq!((first % 7, band.width, band.channels), (0, w, ch));
                        assert_eq!(band.height, 7.min(h - first));
                        rows.extend_from_slice(&band.data);
                        Ok(())
                    });
                    match (whole, got, banded) {
                        (Ok((env, report, neg)), Ok(got), Ok(banded)) => {
                            let want = env.to_cube(11, Filter::Area, 15.0, &NoProgress);
                            assert!(same_bits(&got.cube, &want), "{ch} {policy:?}");
                            assert_eq!(got.report, report, "{ch} {policy:?}");
                            assert_eq!(got.negative, neg, "{ch} {policy:?}");
                            let Environment::Equirect(im) = &env else {
                                unreachable!()
                            };
                            let bits =
                                |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                            assert_eq!(bits(&rows), bits(&im.data), "{ch} {policy:?}");
                            assert_eq!(banded.report, report, "{ch} {policy:?}");
                            assert_eq!(banded.negative, neg, "{ch} {policy:?}");
                        }
                        (Err(a), Err(b), Err(c)) => {
                            assert_eq!(a.to_string(), b.to_string());
                            assert_eq!(a.to_string(), c.to_string());
                        }
                        (a, b, c) => panic!(
                            "{ch} {policy:?}: {:?} vs {:?} vs {:?}",
                            a.err(),
                            b.err(),
                            c.err()
                        ),
                    }
                }
            }
        }
    }

    #[test]
    fn a_file_read_against_its_name_is_one_warning_naming_it() {
        let d = tempfile::tempdir().unwrap();
        let img = Image::from_data(8, 4, 3, vec![0.5; 96]).unwrap();
        for (name, ext, holds) in [
            ("exr_data.png", "exr", "OpenEXR"),
            ("png_data.exr", "png", "PNG"),
            ("radiance.txt", "hdr", "Radiance HDR"),
            ("no_extension", "exr", "OpenEXR"),
        ] {
            let p = write_as(d.path(), name, ext, &img);
            let loaded = load_environment(&p, false).unwrap();
            let w = loaded.warnings();
            assert_eq!(w.len(), 1, "{name}: {w:?}");
            assert!(
                w[0].starts_with(&p.display().to_string())
                    && w[0].contains(&format!("holds {holds} data"))
                    && w[0].contains(&format!("read as {holds}"))
                    && !w[0].contains('\n'),
                "{}",
                w[0]
            );
            let named = name
                .rsplit_once('.')
                .map_or("has no extension".into(), |(_, e)| format!("named .{e}"));
            assert!(w[0].contains(&named), "{}", w[0]);
        }
        // Named as what it holds: nothing to say.
        let p = write_as(d.path(), "fine.exr", "exr", &img);
        assert!(load_environment(&p, false).unwrap().warnings().is_empty());
    }

    #[test]
    fn a_face_or_container_read_against_its_name_is_warned_about() {
        let d = tempfile::tempdir().unwrap();
        let faces = d.path().join("faces");
        std::fs::create_dir(&faces).unwrap();
        let face = Image::from_data(4, 4, 3, vec![1.0; 48]).unwrap();
        for f in Face::ALL {
            let (name, ext) = if f == Face::Nz {
                ("nz.png".to_string(), "exr")
            } else {
                (format!("{}.exr", f.name()), "exr")
            };
            write_as(&faces, &name, ext, &face);
        }
        let w = load_environment(&faces, false).unwrap().warnings();
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].contains("nz.png: holds OpenEXR data but is named .png"),
            "{}",
            w[0]
        );

        let mips = CubeMips {
            levels: vec![Cubemap::constant(4, [1.0, 2.0, 3.0])],
        };
        let ktx = io::ktx2::encode_cube(&mips, io::FloatDepth::F32);
        let p = d.path().join("cube.exr");
        std::fs::write(&p, &ktx).unwrap();
        let loaded = load_environment(&p, false).unwrap();
        assert!(matches!(loaded.env, Environment::Cube(_)));
        // A KTX2 without our orientation key is foreign: warned about too (issue 22).
        let (orient, w): (Vec<String>, Vec<String>) = loaded
            .warnings()
            .into_iter()
            .partition(|w| w.contains("no ibl.orientation metadata"));
        assert_eq!(orient.len(), 1, "{orient:?}");
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].ends_with(
                "cube.exr: holds KTX2 data but is named .exr; read as KTX2 (by its content)"
            ),
            "{}",
            w[0]
        );
        let p = d.path().join("cube.ktx2");
        std::fs::write(&p, &ktx).unwrap();
        let w = load_environment(&p, false).unwrap().warnings();
        assert!(
            w.len() == 1 && w[0].contains("no ibl.orientation metadata"),
            "{w:?}"
        );
    }

    fn labelled_cube(n: usize) -> Cubemap {
        let mut c = Cubemap::new(n);
        for (f, face) in c.faces.iter_mut().enumerate() {
            for j in 0..n {
                for i in 0..n {
                    face.texel_mut(i, j)
                        .copy_from_slice(&[f as f32, i as f32, j as f32]);
                }
            }
        }
        c
    }

    /// Builds a cross image by the inverse of `classify_layout`'s table, from directions:
    /// each cross texel is filled from the face its direction falls on.
    #[test]
    fn horizontal_cross_edges_are_continuous() {
        // A smooth function of direction painted into an hcross must come back continuous.
        let n = 16;
        let mut img = Image::new(4 * n, 3 * n, 3);
        let slots = [
            (Face::Px, 2, 1),
            (Face::Nx, 0, 1),
            (Face::Py, 1, 0),
            (Face::Ny, 1, 2),
            (Face::Pz, 1, 1),
            (Face::Nz, 3, 1),
        ];
        for (face, col, row) in slots {
            for j in 0..n {
                for i in 0..n {
                    let d = crate::cube::texel_direction(face, i, j, n);
                    img.texel_mut(col * n + i, row * n + j)
                        .copy_from_slice(&[d.x, d.y, d.z]);
                }
            }
        }
        // The slot table is checked independently of the reader: across every internal seam of
        // the painted cross (nx|pz|px|nz in the middle row, py above and ny below pz) adjacent
        // pixels must hold neighbouring directions. A wrong slot or a flipped face breaks this.
        let dir = |x: usize, y: usize| Vec3::from_slice(img.texel(x, y)).normalize();
        let limit = 2.0 * std::f32::consts::FRAC_PI_2 / n as f32;
        let mut worst = 0.0f32;
        for k in 0..n {
            let y = n + k;
            for col in 1..4 {
                worst = worst.max(dir(col * n - 1, y).angle_between(dir(col * n, y)));
            }
            let x = n + k;
            worst = worst.max(dir(x, n - 1).angle_between(dir(x, n)));
            worst = worst.max(dir(x, 2 * n - 1).angle_between(dir(x, 2 * n)));
        }
        assert!(worst < limit, "seam jump {worst} rad (limit {limit})");
        let Environment::Cube(c) = classify_layout(Path::new("x.exr"), img).unwrap() else {
            panic!()
        };
        for face in Face::ALL {
            for j in 0..n {
                for i in 0..n {
                    let t = Vec3::from(c.texel(face, i, j));
                    let d = crate::cube::texel_direction(face, i, j, n);
                    assert!((t - d).length() < 1e-6, "{face:?} {i} {j}");
                }
            }
        }
    }

    #[test]
    fn vertical_cross_has_nz_rotated() {
        let n = 4;
        let cube = labelled_cube(n);
        let mut img = Image::new(3 * n, 4 * n, 3);
        for j in 0..n {
            for i in 0..n {
                img.texel_mut(n + i, 3 * n + j).copy_from_slice(&cube.texel(
                    Face::Nz,
                    n - 1 - i,
                    n - 1 - j,
                ));
            }
        }
        let Environment::Cube(c) = classify_layout(Path::new("x.exr"), img).unwrap() else {
            panic!()
        };
        assert_eq!(c.texel(Face::Nz, 1, 2), cube.texel(Face::Nz, 1, 2));
    }

    #[test]
    fn odd_aspect_is_unsupported() {
        let err = classify_layout(Path::new("odd.exr"), Image::new(5, 3, 3)).unwrap_err();
        assert!(err.to_string().contains("odd.exr"));
    }

    #[test]
    fn natural_face_size_is_pow2_below_quarter_width() {
        assert_eq!(
            Environment::Equirect(Image::new(1024, 512, 3)).natural_face_size(),
            256
        );
        assert_eq!(
            Environment::Equirect(Image::new(1000, 500, 3)).natural_face_size(),
            128
        );
        assert_eq!(
            Environment::Equirect(Image::new(2, 1, 3)).natural_face_size(),
            1
        );
    }

    #[test]
    fn every_layout_and_format_reads_back() {
        use crate::io::format::PixelFormat;
        use crate::output::{cube_output_paths, encode_cube, Encoding};
        let mips = CubeMips::build(labelled_cube(8), 2);
        for &layout in Layout::all() {
            for format in PixelFormat::ALL {
                if layout == Layout::Faces
                    && !matches!(format, PixelFormat::Rgba32f | PixelFormat::Rgba16f)
                {
                    continue;
                }
                let dir = tempfile::tempdir().unwrap();
                let enc = Encoding {
                    layout,
                    format,
                    ..Default::default()
                };
                let out = encode_cube(dir.path(), &mips, &enc, "cube", &[]).unwrap();
                let paths: Vec<_> = out.files.iter().map(|f| f.0.clone()).collect();
                assert_eq!(
                    paths,
                    cube_output_paths(dir.path(), mips.levels.len(), layout, "cube")
                );
                io::write_many_atomic(&out.files).unwrap();
                let target = layout
                    .container_path(dir.path(), "cube")
                    .unwrap_or_else(|| dir.path().to_path_buf());
                let back = read_cube_chain(&target).unwrap();
                if format == PixelFormat::Rgba32f {
                    assert_eq!(back, mips);
                } else {
                    // What the reader decodes is what the encoder measured.
                    for (l, (a, b)) in mips.levels.iter().zip(&back.levels).enumerate() {
                        let (mean, max) = crate::io::texture::relative_errors(&a.faces, &b.faces);
                        assert!(
                            (mean - out.levels[l].mean_rel).abs() < 1e-12,
                            "{layout:?} {format:?}"
                        );
                        assert!((max - out.levels[l].max_rel).abs() < 1e-12);
                    }
                }
            }
        }
    }
}
