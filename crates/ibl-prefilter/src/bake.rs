//! The `prefilter` bake: `Params` (CLI flags and RON keys alike) and the pure `run` that turns
//! a loaded environment into the encoded mip chain plus `prefilter.json`.

use crate::custom::{self, CustomChain, CustomLookup};
use crate::error::{Error, Result};
use crate::filter::filter_level;
use crate::fit;
use crate::kernel::{reference_level, SourceTexels};
use crate::runtime::{self, Reference, RuntimeReport};
use crate::samples::SampleTable;
use crate::spatial;
use crate::tree::{tree_level, tree_levels, CellTree, TreeParams};
use ibl_core::bordered::BorderedMips;
use ibl_core::cube::{mip_sizes, texel_direction, Cubemap, Face};
use ibl_core::envmap::{Environment, Opened};
use ibl_core::equirect::Filter;
use ibl_core::io;
use ibl_core::io::format::PixelFormat;
use ibl_core::io::texture::LevelEncoding;
use ibl_core::output::{self, Encoding};
use ibl_core::progress::Progress;
use ibl_core::{luminance, CubeMips};
use ibl_target::{LodMapping, Target};
use serde::Serialize;
use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Accuracy presets, chosen from the benchmark (bench/prefilter.md).
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum Quality {
    /// Previews: about half the time of default; measured worst level 0.2% mean absolute
    /// relative error (single texels up to 5%).
    Draft,
    /// Contract: within 1% mean absolute relative error of the brute-force reference at every
    /// level; measured worst level 0.24% (studio, 7 levels of 256²).
    #[default]
    Default,
    /// Contract: within 0.3%; measured worst level 0.007%, about 2.5× the time of default.
    High,
}

impl Quality {
    /// The `--quality` value naming this preset.
    pub fn name(self) -> &'static str {
        match self {
            Quality::Draft => "draft",
            Quality::Default => "default",
            Quality::High => "high",
        }
    }

    /// Opening angle, leaf size and horizon split of the hierarchical sum.
    pub fn tree_params(self) -> TreeParams {
        match self {
            Quality::Draft => TreeParams {
                theta: 1.0,
                kappa: 3.0,
                horizon: 0.25,
            },
            // κ = 4: κ = 2 cost 18% less CPU (worst level 0.24% against the brute force
            // instead of 0.03%) but let a level lose 0.21% of a one-texel sun's power
            // (custom::tests::sun_power_is_kept_between_levels), above the 0.1% the chain
            // promises; kept at 4.
            Quality::Default => TreeParams {
                theta: 0.7,
                kappa: 4.0,
                horizon: 0.12,
            },
            Quality::High => TreeParams {
                theta: 0.4,
                kappa: 6.0,
                horizon: 0.06,
            },
        }
    }

    /// Hammersley points per texel of filtered importance sampling (`--method fis`).
    pub(crate) fn fis_samples(self) -> u32 {
        match self {
            Quality::Draft => 64,
            Quality::Default => 256,
            Quality::High => 1024,
        }
    }
}

/// How the rough levels are computed.
#[derive(
    Clone,
    Copy,
    Debug,
    PartialEq,
    Eq,
    Default,
    serde::Serialize,
    serde::Deserialize,
    clap::ValueEnum,
)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    /// The exact kernel summed hierarchically over the source: far cells as points with
    /// second-order moments, near ones at a leaf level (the default).
    #[default]
    Tree,
    /// Filtered importance sampling (Křivánek & Colbert 2008; Lagarde & de Rousiers 2014):
    /// `--samples` Hammersley samples per texel read from box-filtered mips. Faster per
    /// sample, but biased in the GGX tail (see bench/prefilter.md); kept for comparison.
    Fis,
}

impl Method {
    /// The `--method` value naming this method.
    pub fn name(self) -> &'static str {
        match self {
            Method::Tree => "tree",
            Method::Fis => "filtered-importance-sampling",
        }
    }
}

/// Mip bias added to the solid-angle lod of every FIS sample. Lagarde & de Rousiers use 1;
/// against the brute-force reference 0 measured best at most levels and sample counts
/// (studio, sunset, interior fixtures at 32², 32–1024 samples, biases 0, 0.5, 1).
pub(crate) const LOD_BIAS: f32 = 0.0;

ibl_core::cube_output_params! {
/// Parameters of the bake: CLI flags and RON keys alike.
#[derive(Clone, Debug, PartialEq, clap::Args, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Params {
    /// Face size of level 0 in texels; level l is size/2^l.
    #[arg(long, value_name = "N", default_value_t = 256)]
    pub size: usize,
    /// Number of levels N (default: down to 4×4 faces, or the target's default); level l has
    /// the roughness the target's lookup reads there (l/(N−1) for gltf and bevy).
    #[arg(long, value_name = "N")]
    pub levels: Option<usize>,
    /// Engine the chain is made for: its level roughness, default level count and orientation.
    #[arg(long, value_enum, default_value_t = Target::Gltf)]
    pub target: Target,
    /// Accuracy preset (chosen from the benchmark against the brute-force reference).
    #[arg(long, value_enum, default_value_t = Quality::Default)]
    pub quality: Quality,
    /// Algorithm for the rough levels: hierarchical exact kernel, or filtered importance sampling.
    #[arg(long, value_enum, default_value_t = Method::Tree)]
    pub method: Method,
    /// Hammersley samples per texel with --method fis (default from --quality).
    #[arg(long, value_name = "S")]
    pub samples: Option<u32>,
    /// Stop the chain at the last level with roughness ≤ R (spacing of the full chain kept).
    #[arg(long, value_name = "R")]
    pub max_roughness: Option<f32>,
    /// Brute-force reference: the exact kernel summed over every source texel (slow).
    #[arg(long)]
    pub reference: bool,
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
    /// Fit the levels to the target's lookup (true/false; default true, false for three and
    /// with --reference): each inner level stores what makes the engine's blend between levels
    /// closest to the exact kernel at every roughness (the worst relative error minimised), and
    /// levels of 8² texels a face or less what makes its bilinear read closest, no longer the
    /// exact kernel at their own roughness (each level keeping its power); prefilter.json says
    /// by how much, per level. Costs about 2.5–3× the bake time (bench/runtime.md); false gives
    /// the exact levels peers write.
    #[arg(long, value_name = "BOOL")]
    pub fit_lookup: Option<bool>,
    /// With --target custom: α₀ of the lookup lod = s·log2(1 + r²/α₀) (default
    /// ibl_target::lod::CUSTOM_ALPHA0, chosen on the design fixtures; docs/CUSTOM_LOOKUP.md).
    #[arg(long, value_name = "A0")]
    pub custom_alpha0: Option<f32>,
}
}

impl Default for Params {
    fn default() -> Self {
        ibl_core::params::clap_defaults()
    }
}

/// Range of --custom-alpha0 (below, level 1 is a mirror to half precision; above, the spacing
/// is linear in α, the levels crowding at high roughness).
pub const CUSTOM_ALPHA0_MIN: f32 = 1e-4;
/// See [`CUSTOM_ALPHA0_MIN`].
pub const CUSTOM_ALPHA0_MAX: f32 = 10.0;
/// CPU seconds of the whole process (every thread) so far: the stage timings report it next
/// to wall time, which says little on a shared machine.
pub fn process_cpu_seconds() -> f64 {
    #[cfg(unix)]
    {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: clock_gettime only writes the timespec passed to it.
        if unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) } == 0 {
            return ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9;
        }
    }
    0.0
}

/// Hands memory freed by the last stage back to the system (glibc keeps it per thread arena,
/// where another thread's next stage cannot reuse it, so the peak grew stage after stage).
pub(crate) fn release_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only returns free heap pages to the kernel.
    unsafe {
        libc::malloc_trim(0);
    }
}

/// Peak resident memory of the process so far in MiB (VmHWM of /proc/self/status; 0 where
/// there is none): the stage timings record it after every stage.
pub fn peak_rss_mib() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// Process CPU seconds and peak memory per stage of a bake.
struct CpuStages {
    mark: f64,
    stages: Vec<(String, f64)>,
    peaks: Vec<(String, f64)>,
}

impl CpuStages {
    fn start() -> Self {
        CpuStages {
            mark: process_cpu_seconds(),
            stages: Vec::new(),
            peaks: Vec::new(),
        }
    }

    /// CPU seconds since the last mark (and a new mark).
    fn lap(&mut self) -> f64 {
        let now = process_cpu_seconds();
        let d = now - self.mark;
        self.mark = now;
        d
    }

    /// Records the CPU seconds since the last mark as stage `name`.
    fn stage(&mut self, name: String) {
        release_freed_memory();
        let d = self.lap();
        self.peaks.push((name.clone(), peak_rss_mib()));
        self.stages.push((name, d));
    }
}

/// The exact kernel the runtime report compares the lookup with: the cell tree at the knobs
/// the default preset had when the report's figures were published (measured 0.02% from the
/// brute force), fixed so the report measures the same thing whatever the bake's own preset.
pub const RUNTIME_REFERENCE: TreeParams = TreeParams {
    theta: 0.7,
    kappa: 4.0,
    horizon: 0.12,
};

#[cfg(test)]
thread_local! {
    /// Bakes on this thread that let their engine (the cell tree) go before the lookup fit's
    /// sweeps: what keeps the tree out of the fit's peak memory.
    static ENGINES_LET_GO_BEFORE_FIT: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Largest level-0 face accepted.
pub const MAX_SIZE: usize = 4096;
/// Largest sample count accepted per texel.
pub const MAX_SAMPLES: u32 = 1 << 16;
/// The source is at most this many times the output size (see [`source_face_size`]): finer
/// would change the levels by far less than their error while the tree's memory grows 4× per
/// step (about 200 MB for a 512² source).
pub(crate) const MAX_SOURCE_FACTOR: usize = 2;

/// Smallest face of gltf's default chain. The linear lookup lod = r(N−1) reads between levels
/// everywhere: down to 4×4 (7 levels on 256²) its worst error over r ∈ [0.25, 1] is 4.0 / 2.5 /
/// 5.9 / 26.6% on the city / sunset / interior / studio fixtures against 4.5 / 2.2 / 6.5 / 30.5%
/// down to 8×8, and over r ∈ [0.1, 0.25) 6–37% against 10–78%; 2×2 faces cost 13% at r ≈ 1
/// (bench/runtime.md).
pub const GLTF_SMALLEST_FACE: usize = 4;

/// Smallest face of a default `custom` chain: 8×8 (6 levels on 256²). With the midpoints the
/// blend between levels is no longer what costs (docs/notes/custom-quad.md), and an 8×8 last
/// level is read at r = 1 within 0.3–0.4% where the 4×4 one of a 7-level chain left 1.2–1.6%
/// (design fixtures city / interior, worst mean over r ≥ 0.1: 0.50 / 0.55% with 6 levels,
/// 1.21 / 1.61% with 7, 0.67 / 1.30% with 5; `bench-ibl-prefilter -- --custom-design`).
pub const CUSTOM_SMALLEST_FACE: usize = 8;

/// Targets whose levels are fitted to the lookup unless --fit-lookup says otherwise: every one
/// whose engine reads the chain through a fixed lod mapping. At the same bytes the fitted chain
/// measured a lower worst error over r ∈ [0.25, 1] on every fixture and every target
/// (city / sunset / interior / studio, 256², bench/runtime.md): gltf and Bevy × 7 levels
/// 2.3 / 1.3 / 3.1 / 9.6% against 4.0 / 2.5 / 5.9 / 26.6% exact; Filament × 6 3.8 / 2.5 / 4.3 /
/// 9.1% against 5.0 / 3.3 / 5.4 / 17.8%; Unity × 7 1.3 / 0.8 / 2.2 / 7.1% against 3.7 / 2.5 /
/// 3.9 / 15.2%; Babylon × 9 3.1 / 2.2 / 3.5 / 9.6% against 5.7 / 3.4 / 6.0 / 18.4%. three.js
/// filters its own chain (PMREM) from level 0, so nothing of ours is read between levels.
fn fit_by_default(target: Target) -> bool {
    target != Target::Three
}

/// Levels a chain from `size` can hold (halving down to 1×1).
pub fn max_levels(size: usize) -> usize {
    mip_sizes(size, 1).len()
}

impl Params {
    /// Checks the parameters before any input is read.
    pub fn validate(&self) -> Result<()> {
        if self.size == 0 || self.size > MAX_SIZE {
            return Err(Error::param(format!(
                "--size {} is out of range 1..={MAX_SIZE}",
                self.size
            )));
        }
        if let Some(n) = self.levels {
            let m = max_levels(self.size);
            if n == 0 || n > m {
                return Err(Error::param(format!(
                    "--levels {n} is out of range 1..={m} for --size {}",
                    self.size
                )));
            }
        }
        if let Some(s) = self.samples {
            if s == 0 || s > MAX_SAMPLES {
                return Err(Error::param(format!(
                    "--samples {s} is out of range 1..={MAX_SAMPLES}"
                )));
            }
            if self.method != Method::Fis {
                return Err(Error::param("--samples applies to --method fis (the default tree method is tuned by --quality)"));
            }
        }
        if let Some(r) = self.max_roughness {
            if !(0.0..=1.0).contains(&r) {
                return Err(Error::param(format!(
                    "--max-roughness {r} is out of range 0..=1"
                )));
            }
        }
        ibl_core::params::check_rotate(self.rotate)?;
        if let Some(a) = self.custom_alpha0 {
            if self.target != Target::Custom {
                return Err(Error::param(format!(
                    "--custom-alpha0 applies to --target custom (--target {} has its engine's fixed lookup)",
                    self.target.name()
                )));
            }
            if !(CUSTOM_ALPHA0_MIN..=CUSTOM_ALPHA0_MAX).contains(&a) {
                return Err(Error::param(format!(
                    "--custom-alpha0 {a} is out of range {CUSTOM_ALPHA0_MIN}..={CUSTOM_ALPHA0_MAX}"
                )));
            }
        }
        if self.target == Target::Babylon
            && (!self.size.is_power_of_two() || self.written_levels() != max_levels(self.size))
        {
            return Err(Error::param(format!(
                "--target babylon needs a power-of-two --size and its full chain down to 1×1 ({} levels for --size {}): Babylon's .env holds every level",
                max_levels(self.size),
                self.size
            )));
        }
        if !self.target.spec().lod.reads_chain() {
            return Err(Error::param(format!(
                "--target {} reads no prefiltered chain: three.js filters the environment itself (PMREMGenerator); bake its cube with equirect-to-cube --target three and its LightProbe with irradiance --target three",
                self.target.name()
            )));
        }
        let enc = self.encoding()?;
        if self.target == Target::Custom
            && (!matches!(enc.format, PixelFormat::Rgba16f | PixelFormat::Rgba32f)
                || enc.layout.codec().is_none())
        {
            return Err(Error::param(format!(
                "--target custom stores its lookup's correction in the alpha channel: it needs --format rgba16f or rgba32f in a container (ktx2, ktx1, dds), not {} in {}",
                enc.format.name(),
                enc.layout.codec().map_or("face images", |c| c.name())
            )));
        }
        Ok(())
    }

    /// The chain's output encoding, checked: the flags over the target's container and format.
    pub fn encoding(&self) -> Result<Encoding> {
        Ok(self
            .target
            .check_encoding(self.cube_output().resolve(self.target.encoding())?)?)
    }

    /// Name (stem) of the chain's container: `prefilter`, or the target's file name.
    pub fn chain_name(&self) -> &'static str {
        self.target.spec().files.specular
    }

    /// Levels of the full chain N: --levels, else down to 4×4 faces (gltf: 7 levels on 256²,
    /// the runtime-error / bytes choice of bench/runtime.md, kept relative to the size) or the
    /// target's default (a full chain to 1×1 for Babylon, whose lookup depends on the size alone).
    pub fn chain_levels(&self) -> usize {
        let m = max_levels(self.size);
        self.levels.unwrap_or_else(|| match self.target {
            Target::Gltf => mip_sizes(self.size, GLTF_SMALLEST_FACE).len(),
            Target::Custom => mip_sizes(self.size, CUSTOM_SMALLEST_FACE).len(),
            Target::Babylon => m,
            t => t.spec().levels.min(m),
        })
    }

    /// The lookup the chain is read through: the target's, with --custom-alpha0 applied.
    pub fn lookup(&self) -> LodMapping {
        match (self.target.spec().lod, self.custom_alpha0) {
            (LodMapping::Custom { .. }, Some(alpha0)) => LodMapping::Custom { alpha0 },
            (m, _) => m,
        }
    }

    /// Largest level fitted to its bilinear read ([`crate::spatial`]), with --fit-lookup.
    pub fn read_fit_max_size(&self) -> usize {
        if self.target == Target::Custom {
            spatial::CUSTOM_SPATIAL_MAX_SIZE
        } else {
            spatial::SPATIAL_MAX_SIZE
        }
    }

    /// With --target custom, the lookup's constants for this chain (the power factors zero:
    /// the bake fits them, `Chain::report.custom_lookup`).
    pub fn custom_lookup(&self) -> Option<CustomLookup> {
        match self.lookup() {
            LodMapping::Custom { alpha0 } => {
                Some(CustomLookup::new(alpha0, self.chain_levels(), self.size))
            }
            _ => None,
        }
    }

    /// Roughness of level `l` of the full chain, as the target's lookup reads it.
    pub fn level_roughness(&self, l: usize) -> f32 {
        self.lookup()
            .level_roughness(l, self.chain_levels(), self.size)
    }

    /// Levels actually baked: all N, or those with r ≤ --max-roughness.
    pub(crate) fn baked_levels(&self) -> usize {
        let n = self.chain_levels();
        match self.max_roughness {
            Some(r) if n > 1 => (0..n)
                .take_while(|&l| self.level_roughness(l) <= r + 1e-6)
                .count()
                .max(1),
            _ => n,
        }
    }

    /// Levels written: with --max-roughness still the full chain N. glTF, Bevy and Filament
    /// compute the lod from the file's level count (a chain cut to k levels is read at
    /// lod = r·(k − 1) of the shorter chain: every level at the wrong roughness, 24–34% off);
    /// Babylon's `.env` holds every level; and every lookup (Unity's fixed 6 too) blends the
    /// last kept level with the next one for r between their roughness, up to max_roughness.
    /// The levels past the cut hold the exact kernel at their roughness, unfitted
    /// ([`LevelReport::beyond_max_roughness`]): --max-roughness saves the lookup fit of the
    /// rough levels and says which levels carry the accuracy contract, never the mapping.
    pub fn written_levels(&self) -> usize {
        self.chain_levels()
    }

    /// Whether levels are fitted to the lookup ([`crate::fit`]): --fit-lookup, else on where it
    /// lowered the worst runtime error over r ∈ [0.25, 1] on every fixture (bench/runtime.md),
    /// never for the brute-force --reference, whose levels are the exact kernel by definition.
    pub fn fits_lookup(&self) -> bool {
        self.fit_lookup
            .unwrap_or(!self.reference && fit_by_default(self.target))
    }

    /// Whether inner levels are fitted to the engine's linear blend between levels
    /// ([`crate::fit`]): with the lookup fit, for every target but custom, whose lookup reads
    /// a polynomial through the levels and the intervals' midpoints instead (its levels stay the
    /// kernel's, so that the polynomial's nodes are exact; [`crate::custom`]).
    pub(crate) fn fits_blend(&self) -> bool {
        self.fits_lookup() && self.target != Target::Custom
    }

    /// Hammersley points per texel with --method fis.
    pub(crate) fn fis_samples(&self) -> u32 {
        self.samples.unwrap_or_else(|| self.quality.fis_samples())
    }
}

/// Bytes per source-cube texel the bake holds at once: the source cube (12), its cell tree
/// (the texels' directions and energies, 24; the coarser cells with their moments, about 37)
/// and slack; measured at 256² and 512² (bench/speed.md: `stages_peak_mib` of the source
/// stage).
const SOURCE_TEXEL_BYTES: u64 = 80;
/// Bytes per level-0 texel: the levels as computed and as stored, the fit's working set, the
/// runtime report's bordered copy and the encoded files.
const CHAIN_TEXEL_BYTES: u64 = 160;

/// The memory the bake of `size`² faces from a `src`² source cube holds at its peak, besides
/// the process itself and the input's image (freed after the resample; a streamed input is
/// never held whole, and the window of rows its resample holds is reserved by the resample):
/// what `run` reserves against the memory budget before it starts.
pub fn working_set_bytes(size: usize, src: usize) -> u64 {
    let (size, src) = (size as u64, src as u64);
    6 * src * src * SOURCE_TEXEL_BYTES + 6 * size * size * CHAIN_TEXEL_BYTES
}

/// Face size of the source the levels are filtered from: the output size times the largest
/// power of two (at most [`MAX_SOURCE_FACTOR`]) that the input's own resolution supports, so
/// detail finer than level 0 still reaches the rough levels and level 0 is an exact box
/// reduction of it.
pub fn source_face_size(natural: usize, size: usize) -> usize {
    let mut s = size;
    while s * 2 <= natural && s * 2 <= size * MAX_SOURCE_FACTOR {
        s *= 2;
    }
    s
}

/// Error of a level against a brute-force reference (defined in [`crate::stats`], below the
/// bake, the fit and the runtime report that all use it; named here too, its first home).
pub use crate::stats::ErrorStats;

/// What `prefilter.json` records.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    /// The tool that wrote the report (`prefilter`).
    pub tool: &'static str,
    /// The tool's version.
    pub version: &'static str,
    /// Face size of level 0.
    pub size: usize,
    /// Levels written.
    pub levels: usize,
    /// Levels N of the full chain.
    pub chain_levels: usize,
    /// The engine the chain is made for.
    pub target: Target,
    /// Its runtime level ↔ roughness mapping (the roughness of every level is in `level`).
    pub lookup: &'static str,
    /// Roughness of every level written.
    pub level_roughness: Vec<f32>,
    /// Whether levels 1… are fitted to the lookup (`--fit-lookup`): each level's `fit` says
    /// how far it is from the exact kernel at its roughness.
    pub fit_lookup: bool,
    /// "tree", "filtered-importance-sampling" or "reference" (brute force over every source
    /// texel).
    pub method: &'static str,
    /// The preset, or "custom" with --samples.
    pub quality: String,
    /// The kernel every level approximates.
    pub kernel: &'static str,
    /// Face size of the cube the levels are filtered from: the input resampled (area filter)
    /// at up to [`MAX_SOURCE_FACTOR`]× --size when its resolution allows.
    pub source_size: usize,
    /// How level 0, the mirror, was made from an equirect input: `adaptive` when the source
    /// cube is --size itself (the input is not finer than the chain: the footprint mean where
    /// a texel spans 0.75 source pixels or more, the bilinear reading where it spans half of
    /// one or less, blended between; [`Resampled`]), `area` when it is the source cube
    /// box-reduced (or the input is a cube).
    pub level0_filter: Filter,
    /// Knobs of the tree method, or of FIS (samples per texel, mip bias).
    pub tree: Option<TreeParams>,
    /// FIS samples per texel (with `--method fis`).
    pub fis_samples: Option<u32>,
    /// FIS source-mip bias (with `--method fis`).
    pub fis_lod_bias: Option<f32>,
    /// Rotation about +Y applied to the source, in degrees.
    pub rotate: f32,
    /// --max-roughness, if given, and what it did.
    pub max_roughness: Option<f32>,
    /// Why the chain stops early (`--max-roughness`), if it does.
    pub note: Option<String>,
    /// One entry per level written.
    pub level: Vec<LevelReport>,
    /// The output encoding and what it cost per level against the float chain (filled by
    /// [`run`]; the bake alone leaves it empty).
    pub encoding: Option<serde_json::Value>,
    /// The error the target's own lookup sees between levels (see [`crate::runtime`]).
    pub runtime: Option<RuntimeReport>,
    /// With --target custom: the lookup's constants (also in the KTX2 key/value data and the
    /// emitted lookup.glsl / .hlsl / .wgsl).
    pub custom_lookup: Option<CustomLookup>,
}

/// What one level of `prefilter.json` records.
#[derive(Clone, Debug, Serialize)]
pub struct LevelReport {
    /// Level index, 0 the mirror.
    pub level: usize,
    /// Face size in texels.
    pub size: usize,
    /// Perceptual roughness r of the level.
    pub roughness: f32,
    /// GGX α = r².
    pub alpha: f32,
    /// Points per texel whose mean the texel stores (1: its centre; k² when the level's texels
    /// are not much smaller than the lobe, see [`footprint_factor`]).
    pub footprint_samples: usize,
    /// Kernel evaluations (tree cells or FIS samples) per texel, averaged over the level.
    pub evaluations_per_texel: f64,
    /// Error of this level's luminance against the exact kernel summed by brute force over
    /// every source texel, at a fixed set of probe texels (none for the mirror level and for
    /// --reference, which is that brute force everywhere). With `fit`, of the exact kernel the
    /// fit started from.
    pub estimated_error: Option<EstimatedError>,
    /// With --fit-lookup: the level stores the lookup's best fit, not the exact kernel at its
    /// roughness (see [`crate::fit`]), and this is how far it moved.
    pub fit: Option<fit::LevelFit>,
    /// With --fit-lookup, on levels of at most [`Params::read_fit_max_size`]² texels a face:
    /// the level is corrected so the engine's bilinear read between its texels matches the
    /// exact kernel (see [`crate::spatial`]), and the read's error before and after.
    pub read_fit: Option<spatial::ReadFit>,
    /// A level past `--max-roughness`, written so the engine's lookup keeps the full chain's
    /// level count ([`Params::written_levels`]): the exact kernel at its roughness, not fitted
    /// to the lookup (absent when false).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub beyond_max_roughness: bool,
}

/// The error of one level measured against the brute-force kernel on probe texels.
#[derive(Clone, Debug, Serialize)]
pub struct EstimatedError {
    /// Mean |baked − exact| / exact over the probes and channels.
    pub mean_abs_rel: f64,
    /// Root mean square of the same relative error.
    pub rms_rel: f64,
    /// Largest relative error.
    pub max_abs_rel: f64,
    /// Probe texels measured.
    pub probe_texels: usize,
}

/// A baked chain before encoding, with timings and work (not part of the report, which must
/// be identical from run to run).
pub struct Chain {
    /// The levels, mirror first.
    pub mips: CubeMips,
    /// `--target custom`: the chain's alpha channel, the lookup's midpoints
    /// ([`crate::custom::correction`]), in each of the three channels; none for the others.
    pub correction: Option<CubeMips>,
    /// The levels as the files will hold them (in the target's orientation and the output's
    /// lossy format), encoded once for the runtime report and written as they are; `None`
    /// for rgba32f.
    pub encoded: Option<output::PreEncoded>,
    /// What `prefilter.json` will record.
    pub report: Report,
    /// Seconds per level (0 for the mirror level).
    pub level_seconds: Vec<f64>,
    /// Kernel evaluations per level (Σ over texels of cells or samples; 0 for the mirror).
    pub level_work: Vec<u64>,
    /// Seconds spent on the input resample (area filter to the source size).
    pub resample_seconds: f64,
    /// Seconds spent building the source structures (tree or mips, brute-force texel table).
    pub source_seconds: f64,
    /// Seconds spent on the error estimates.
    pub estimate_seconds: f64,
    /// Seconds spent on the runtime-lookup error (with a lossy format, the chain's one encode
    /// and its decode included: the files are made from those bytes).
    pub runtime_seconds: f64,
    /// Seconds spent fitting levels to the lookup (the extra kernel levels it evaluates).
    pub fit_seconds: f64,
    /// Of `fit_seconds`: the kernel at the fit's nodes and the dense kernel of the read fit.
    pub fit_kernel_seconds: f64,
    /// Of `source_seconds`: the cell tree (the rest is the brute-force texel table).
    pub tree_seconds: f64,
    /// CPU seconds (all threads) per stage, in order: resample, source, each level, estimate,
    /// fit, runtime.
    pub cpu_seconds: Vec<(String, f64)>,
    /// Peak resident memory of the process (MiB) at the end of each of those stages.
    pub peak_mib: Vec<(String, f64)>,
    /// Things the user should know (e.g. level 0 upsampled from a smaller input).
    pub warnings: Vec<String>,
}

/// What [`run`] produced, before anything is written.
pub struct Baked {
    /// Encoded files (the chain and `prefilter.json`), ready for [`io::write_many_atomic`].
    pub files: Vec<(PathBuf, Vec<u8>)>,
    /// The float chain and its report.
    pub chain: Chain,
    /// What the output encoding cost per level (its seconds included).
    pub encoding: Vec<LevelEncoding>,
    /// Seconds from the float chain to the encoded bytes (orientation, metadata, every file
    /// of the chain, the sidecar; a lossy format's texels were encoded by the runtime report).
    pub encode_seconds: f64,
    /// CPU seconds (all threads) of the same.
    pub encode_cpu_seconds: f64,
}

/// Name of the Babylon.js `.env` written with `--target babylon`.
pub(crate) const BABYLON_ENV_NAME: &str = "environment.env";

/// Name of the sidecar report.
pub(crate) const REPORT_NAME: &str = "prefilter.json";

/// Bakes the chain and encodes the outputs for `out_dir` (nothing is written). A streamed
/// input ([`ibl_core::envmap::open_environment_with`]) is resampled as its rows arrive: its
/// warnings (the input checks') come first in the chain's.
pub fn run(
    params: &Params,
    input: impl Into<Opened>,
    out_dir: &Path,
    progress: &dyn Progress,
) -> Result<Baked> {
    let input: Opened = input.into();
    let enc = params.encoding()?;
    params.validate()?;
    // What the bake will hold, against the run's memory budget before any of it is
    // allocated: refused in a line rather than swapped (the input is already read, under
    // its own reservation, or streamed through a window the resample reserves).
    let natural = input.natural_face_size();
    let src = source_face_size(natural, params.size);
    let _working_set = ibl_core::io::budget::reserve(
        input.path(),
        &format!(
            "baking {}² faces from a {src}² source cube (its cell tree, the levels and their fit)",
            params.size
        ),
        working_set_bytes(params.size, src),
    )?;
    let (resampled, input_warnings) = match input {
        Opened::Loaded(input) => {
            let resampled = Resampled::new(params, &input.env, progress);
            // The input's image is not read again: freed before the tree and the levels.
            drop(input);
            (resampled, Vec::new())
        }
        Opened::Streamed(stream) => Resampled::streamed(params, stream, progress)?,
    };
    let mut chain = bake_resampled(params, resampled, progress)?;
    chain.warnings.splice(0..0, input_warnings);
    let te = Instant::now();
    let ce = process_cpu_seconds();
    // The engine's orientation: an exact texel permutation of every level.
    // (No copy of the chain where the files hold our frame, as gltf's do. Nor where the
    // runtime stage already encoded the turned chain into a container: the file is made
    // from those bytes, and only face images and Babylon's `.env` read float texels.)
    let orientation = params.target.spec().orientation;
    let floats_written =
        chain.encoded.is_none() || enc.layout.codec().is_none() || params.target == Target::Babylon;
    let oriented = if orientation.is_identity() || !floats_written {
        Cow::Borrowed(&chain.mips)
    } else {
        Cow::Owned(orientation.apply_mips(&chain.mips))
    };
    let spec = params.target.spec();
    let mut metadata = target_metadata(params.target, &chain.mips);
    metadata.extend(spec.orientation.metadata(params.target.name()));
    if let Some(lk) = &chain.report.custom_lookup {
        metadata.extend(lk.metadata(&chain.report.level_roughness));
    }
    // Custom chains are in our frame (no orientation to apply to the alpha).
    let encoded = output::encode_chain_from(
        out_dir,
        &oriented,
        chain.encoded.take(),
        chain.correction.as_ref(),
        &enc,
        params.chain_name(),
        &metadata,
    )?;
    chain.report.encoding = Some(output::encoding_report(&enc, &encoded.levels));
    chain.warnings.extend(encoded.warnings);
    // Babylon loads the `.env` alone: the chain's own files (EXR faces) would be strays.
    let mut files = if params.target == Target::Babylon {
        Vec::new()
    } else {
        encoded.files
    };
    let mut outputs = ibl_target::note::Outputs {
        chain: ibl_target::note::names(files.iter().map(|f| f.0.as_path())),
        levels: chain.mips.levels.len(),
        report: Some(REPORT_NAME.to_string()),
        max_roughness: chain.report.note.clone(),
        ..Default::default()
    };
    if params.target != Target::Babylon {
        if let Some(side) = spec.orientation.sidecar(
            out_dir,
            enc.layout,
            params.chain_name(),
            params.target.name(),
        ) {
            outputs.orientation = ibl_target::note::names([side.0.as_path()]).pop();
            files.push(side);
        }
    }
    let json = out_dir.join(REPORT_NAME);
    let bytes = io::data::encode(&json, &chain.report)?;
    files.push((json, bytes));
    if params.target == Target::Babylon {
        // The .env carries the chain and the irradiance polynomial of the same environment.
        let path = out_dir.join(BABYLON_ENV_NAME);
        let irradiance = ibl_target::babylon::irradiance_sh(&chain.mips.levels[0]);
        let bytes = ibl_target::babylon::encode_env(&path, &oriented, &irradiance, orientation)?;
        files.push((path, bytes));
        outputs.env = Some(BABYLON_ENV_NAME.to_string());
    }
    if let Some(lk) = &chain.report.custom_lookup {
        for (name, text) in lk.shaders() {
            outputs.lookup.push(name.to_string());
            files.push((out_dir.join(name), text.into_bytes()));
        }
    }
    // The how-to-load note, naming only what this run wrote (every target, gltf too).
    let note =
        ibl_target::note::load_note(params.target, ibl_target::note::Writer::Prefilter, &outputs);
    files.push((out_dir.join(ibl_target::NOTE_NAME), note.into_bytes()));
    Ok(Baked {
        files,
        chain,
        encoding: encoded.levels,
        encode_seconds: te.elapsed().as_secs_f64(),
        encode_cpu_seconds: process_cpu_seconds() - ce,
    })
}

/// Key/value metadata a target's engine reads from the chain's container: Filament's cmgen
/// puts the 9 pre-scaled irradiance SH in the KTX's `sh` key (google/filament
/// `tools/cmgen/src/cmgen.cpp`, `setMetadata("sh", ...)`), computed here from level 0.
fn target_metadata(target: Target, mips: &CubeMips) -> Vec<(String, Vec<u8>)> {
    if target.spec().diffuse != ibl_target::DiffuseForm::FilamentSh {
        return Vec::new();
    }
    let irradiance = ibl_target::babylon::irradiance_sh(&mips.levels[0]);
    let p = ibl_target::sh::prescaled_polynomial(&irradiance, target.spec().orientation);
    vec![(
        "sh".to_string(),
        ibl_target::sh::filament_ktx_sh_metadata(&p).into_bytes(),
    )]
}

/// Paths [`run`] writes for `params` (for planning and cleaning).
pub fn output_paths(params: &Params, out_dir: &Path) -> Result<Vec<PathBuf>> {
    let enc = params.encoding()?;
    let mut p = if params.target == Target::Babylon {
        Vec::new()
    } else {
        output::chain_output_paths(
            out_dir,
            params.written_levels(),
            enc.layout,
            params.chain_name(),
        )
    };
    p.push(out_dir.join(REPORT_NAME));
    if params.target == Target::Babylon {
        p.push(out_dir.join(BABYLON_ENV_NAME));
    } else {
        p.extend(params.target.spec().orientation.sidecar_path(
            out_dir,
            enc.layout,
            params.chain_name(),
        ));
    }
    if params.custom_lookup().is_some() {
        p.extend(custom::SHADER_FILES.iter().map(|f| out_dir.join(f)));
    }
    p.push(out_dir.join(ibl_target::NOTE_NAME));
    Ok(p)
}

/// What the rough levels are computed from.
enum Engine {
    Tree(CellTree, TreeParams),
    Fis(BorderedMips, u32),
    Reference,
}

/// Bakes the chain in memory.
pub fn bake_chain(params: &Params, env: &Environment, progress: &dyn Progress) -> Result<Chain> {
    params.validate()?;
    bake_resampled(params, Resampled::new(params, env, progress), progress)
}

/// The source cube the levels are filtered from, resampled from the input (the first stage
/// of [`bake_chain`], apart so that [`run`] can drop the input's image before the rest: a
/// 4k equirect is 100 MB, more than everything the bake builds from it at 256²).
///
/// The rough levels integrate the footprint-mean cube (`Filter::Area`: a sun keeps its
/// power exactly). Level 0 is the mirror, read texel for texel: where the input is no finer
/// than the chain (a small panorama, and the faces' corners, whose texels subtend 0.44× the
/// centre's angle) the footprint mean shows each source pixel as a flat block, so there
/// level 0 is the adaptive resample (`mirror`), the panorama as a mirror, a skybox and the
/// engines' own routes read it (bilinearly). Measured through the glTF Sample Viewer's
/// lookup, the mirror sphere from interior_256 at 256²: 4.2% → 0.7% mean error
/// (`docs/notes/resample-adaptive.md`).
struct Resampled {
    cube: Cubemap,
    /// Level 0 when it is not the (box-reduced) source cube.
    mirror: Option<Cubemap>,
    natural: usize,
    seconds: f64,
    cpu: CpuStages,
}

impl Resampled {
    fn new(params: &Params, env: &Environment, progress: &dyn Progress) -> Self {
        let t0 = Instant::now();
        let mut cpu = CpuStages::start();
        let natural = env.natural_face_size();
        let src_size = source_face_size(natural, params.size);
        let cube = env.to_cube(src_size, Filter::Area, params.rotate, progress);
        let mirror = match env {
            Environment::Equirect(img) if src_size == params.size => Some(
                ibl_core::equirect::adaptive_from_area(img, &cube, params.rotate),
            ),
            _ => None,
        };
        let seconds = t0.elapsed().as_secs_f64();
        cpu.stage("resample".into());
        Resampled {
            cube,
            mirror,
            natural,
            seconds,
            cpu,
        }
    }

    /// The source cube of a streamed equirect, resampled as its rows arrive (the same texels
    /// as [`Resampled::new`] from the loaded image), and the input's warnings.
    fn streamed(
        params: &Params,
        stream: ibl_core::envmap::EquirectStream,
        progress: &dyn Progress,
    ) -> Result<(Self, Vec<String>)> {
        let t0 = Instant::now();
        let mut cpu = CpuStages::start();
        let path = stream.path().to_path_buf();
        let natural = stream.natural_face_size();
        let src_size = source_face_size(natural, params.size);
        let streamed = if src_size == params.size {
            stream.to_cube_with_mirror(src_size, params.rotate, progress)?
        } else {
            stream.to_cube(src_size, Filter::Area, params.rotate, progress)?
        };
        let seconds = t0.elapsed().as_secs_f64();
        cpu.stage("resample".into());
        let warnings = streamed.warnings(&path);
        Ok((
            Resampled {
                cube: streamed.cube,
                mirror: streamed.mirror,
                natural,
                seconds,
                cpu,
            },
            warnings,
        ))
    }
}

/// [`bake_chain`] from its resampled source.
fn bake_resampled(params: &Params, resampled: Resampled, progress: &dyn Progress) -> Result<Chain> {
    let Resampled {
        cube: source,
        mirror,
        natural,
        seconds: resample_seconds,
        mut cpu,
    } = resampled;
    let size = params.size;
    let n_chain = params.chain_levels();
    let n_baked = params.baked_levels();
    let src_size = source.size;
    let mut warnings = Vec::new();
    if natural < size {
        warnings.push(format!("the input holds about {natural}² texels per cube face, less than --size {size}: level 0 is upsampled"));
    }
    let t1 = Instant::now();
    // Level 0 is the mirror: the source box-reduced to --size (src_size = size·2^k); at the
    // same size the adaptive resample ([`Resampled`]), or the source itself, not a copy.
    let level0_filter = if mirror.is_some() {
        Filter::Adaptive
    } else {
        Filter::Area
    };
    let level0 = if let Some(m) = mirror {
        Cow::Owned(m)
    } else if source.size > size {
        let mut l0 = source.downsample();
        while l0.size > size {
            l0 = l0.downsample();
        }
        Cow::Owned(l0)
    } else {
        Cow::Borrowed(&source)
    };
    // The brute-force texel table: the tree method sums over its own finest cells instead
    // (the same texels), so the bake holds the source once.
    let tree_method = !params.reference && params.method == Method::Tree;
    let texels = if tree_method {
        SourceTexels::none()
    } else {
        SourceTexels::new(&source)
    };
    let tt = Instant::now();
    let engine = if params.reference {
        Engine::Reference
    } else {
        match params.method {
            Method::Tree => Engine::Tree(CellTree::new(&source), params.quality.tree_params()),
            Method::Fis => Engine::Fis(
                BorderedMips::new(&CubeMips::build(source.clone(), 1)),
                params.fis_samples(),
            ),
        }
    };
    let source_seconds = t1.elapsed().as_secs_f64();
    let tree_seconds = tt.elapsed().as_secs_f64();
    cpu.stage("source".into());
    let mut estimate_cpu = 0.0;

    let mut stages = vec![Stage {
        exact: level0,
        values: None,
        correction: None,
        fitting: None,
    }];
    let mut reports = vec![LevelReport {
        level: 0,
        size,
        roughness: 0.0,
        alpha: 0.0,
        footprint_samples: 1,
        evaluations_per_texel: 0.0,
        estimated_error: None,
        fit: None,
        read_fit: None,
        beyond_max_roughness: false,
    }];
    let (mut level_seconds, mut level_work) = (vec![0.0], vec![0u64]);
    let mut estimate_seconds = 0.0;
    let mut fit_seconds = 0.0;
    let fits = params.fits_lookup();
    // The exact levels first (with --max-roughness and the fit, one more past the last baked
    // level: its coarser neighbour, which the engine's blend reads and the fit needs).
    // Levels past --max-roughness that the engine's lookup needs are the exact kernel too.
    let n_written = params.written_levels();
    let n_exact = if n_written > n_baked {
        n_written
    } else if fits && n_baked < n_chain {
        n_baked + 1
    } else {
        n_baked
    };
    for l in 1..n_exact {
        let t = Instant::now();
        let n = (size >> l).max(1);
        let r = params.level_roughness(l);
        // Texels not much smaller than the lobe store the mean of the convolved radiance over
        // their footprint: the level is computed k× finer and box-reduced (exact means of the
        // fine texels, solid-angle weighted).
        let k = footprint_factor(n, r);
        // With the lookup fit, the kernel at the fit's nodes too, in the same pass (the
        // tree shares its cuts and cell geometry between them).
        let plan = (params.fits_blend() && l < n_baked.min(n_chain - 1))
            .then(|| fit::plan(params.lookup(), l, n_chain, size, fit::FIT_NODES));
        let node_rs: Vec<f32> = plan
            .iter()
            .flat_map(|p| p.nodes.iter().map(|q| q.roughness))
            .collect();
        // Nodes smooth at half the level's size are computed there and upsampled; the rest
        // share the level's own cuts. Not in a --reference bake, which approximates nothing.
        let (half, full): (Vec<usize>, Vec<usize>) = (0..node_rs.len())
            .partition(|&k| !params.reference && node_at_half_size(n, node_rs[k]));
        let mut rs = vec![r];
        rs.extend(full.iter().map(|&k| node_rs[k]));
        let mut cubes = convolve_level_many(&engine, &source, &texels, n, &rs, progress);
        let half_rs: Vec<f32> = half.iter().map(|&k| node_rs[k]).collect();
        let halves = convolve_level_many(&engine, &source, &texels, n / 2, &half_rs, progress);
        let mut nodes: Vec<Option<(Cubemap, u64)>> = vec![None; node_rs.len()];
        for (k, cube) in full.into_iter().zip(cubes.drain(1..)) {
            nodes[k] = Some(cube);
        }
        for (k, (cube, w)) in half.into_iter().zip(halves) {
            nodes[k] = Some((cube.upsample_quadratic(), w));
        }
        cubes.extend(nodes.into_iter().map(|c| c.expect("every node")));
        let (fine_cube, work) = cubes.remove(0);
        let node_work: u64 = cubes.iter().map(|c| c.1).sum();
        let fitting = plan.map(|plan| {
            let at_nodes = cubes.into_iter().map(|(c, _)| reduce_to(c, n)).collect();
            (plan, at_nodes)
        });
        level_seconds.push(t.elapsed().as_secs_f64());
        level_work.push(work + node_work);
        cpu.stage(format!("level {l}"));
        let te = Instant::now();
        // The estimate compares the computed texels (the fine ones when a footprint is
        // averaged: the reduction itself is exact) with the brute force.
        let estimated_error = (!params.reference).then(|| match &engine {
            Engine::Tree(tree, _) => estimate_error(
                &fine_cube,
                &|d, a| tree.brute_convolve_many(d, a),
                tree.texel_count(),
                r,
            ),
            _ => estimate_error(
                &fine_cube,
                &|d, a| d.iter().map(|&d| texels.convolve(d, a)).collect(),
                texels.len(),
                r,
            ),
        });
        estimate_seconds += te.elapsed().as_secs_f64();
        estimate_cpu += cpu.lap();
        let exact = reduce_to(fine_cube, n);
        reports.push(LevelReport {
            level: l,
            size: n,
            roughness: r,
            alpha: r * r,
            footprint_samples: k * k,
            evaluations_per_texel: work as f64 / (6 * n * n) as f64,
            estimated_error,
            fit: None,
            read_fit: None,
            beyond_max_roughness: l >= n_baked,
        });
        stages.push(Stage {
            values: None,
            exact: Cow::Owned(exact),
            correction: None,
            fitting,
        });
    }
    let tf = Instant::now();
    let mut fit_kernel_seconds = 0.0;
    if fits {
        let sources = (&engine, &source, &texels);
        fit_kernel_seconds = fit_inputs(
            params,
            n_baked,
            sources,
            &mut stages,
            &mut reports,
            &mut level_work,
            progress,
        );
    }
    fit_seconds += tf.elapsed().as_secs_f64();
    // Charged to the fit's stage below, not to the reference's.
    let fit_inputs_cpu = cpu.lap();
    // The runtime report's reference (the cell tree's exact kernel at the report's directions)
    // needs the source structures and nothing the fit makes: computed here, it lets the tree
    // and the texel table go before the fit's per-texel hulls are built (the 512² bake's peak
    // was both at once). The custom lookup's midpoints, after the fit, still need them.
    let tr = Instant::now();
    let engine_kind = (
        matches!(engine, Engine::Tree(..)),
        matches!(engine, Engine::Fis(..)),
    );
    let reference_table = {
        let own_tree;
        let tree = match &engine {
            Engine::Tree(t, _) => t,
            _ => {
                own_tree = CellTree::new(&source);
                &own_tree
            }
        };
        Reference::Tree {
            tree,
            source: &source,
            params: RUNTIME_REFERENCE,
        }
        .table(runtime::REPORT_DIRECTIONS)
    };
    let engine_after_fit = if params.target == Target::Custom {
        Some((engine, texels))
    } else {
        drop((engine, texels));
        #[cfg(test)]
        ENGINES_LET_GO_BEFORE_FIT.with(|c| c.set(c.get() + 1));
        None
    };
    release_freed_memory();
    let reference_seconds = tr.elapsed().as_secs_f64();
    cpu.stage("reference".into());
    let tf = Instant::now();
    if fits {
        fit_sweeps(params, n_baked, &mut stages);
    }
    fit_seconds += tf.elapsed().as_secs_f64();
    cpu.stages.push(("estimate".into(), estimate_cpu));
    cpu.stage("fit".into());
    if let Some((_, fit_cpu)) = cpu.stages.last_mut() {
        *fit_cpu += fit_inputs_cpu;
    }
    // The extra coarser neighbour is not part of a cut chain.
    stages.truncate(n_written);
    reports.truncate(n_written);
    level_seconds.truncate(n_written);
    level_work.truncate(n_written);
    {
        // Each level's fit report on its own (its sums in their own order: the same bits
        // for any thread count).
        use rayon::prelude::*;
        reports
            .par_iter_mut()
            .zip(stages.par_iter())
            .for_each(|(report, st)| {
                if let Some((plan, _)) = &st.fitting {
                    report.fit = Some(fit::LevelFit::new(plan, st.values(), &st.exact));
                }
            });
    }
    // A level 0 that is the source itself (--size the source's size: nothing is fitted or
    // corrected on level 0) becomes the source, moved, not copied (a serial copy of the
    // largest level), unless the custom target's midpoints still read the source.
    let source_power = spatial::texel_power(&source);
    let take_source = params.target != Target::Custom
        && matches!(stages[0].exact, Cow::Borrowed(_))
        && stages[0].values.is_none()
        && stages[0].correction.is_none();
    let mut levels: Vec<Cubemap> = stages
        .into_iter()
        .skip(usize::from(take_source))
        .map(Stage::into_stored)
        .collect();
    let source = if take_source {
        levels.insert(0, source);
        None
    } else {
        Some(source)
    };
    release_freed_memory();
    // The custom lookup reads its levels through its own bilinear taps: the levels too large
    // for the read fit store v − k·δ²v, whose bilinear read follows the kernel between the
    // centres (spatial::sharpen_for_bilinear; half the read's error). The stock targets' levels
    // are fitted to their engine's blend instead, which a sharpening would undo.
    if params.target == Target::Custom {
        for (l, level) in levels.iter_mut().enumerate().skip(1) {
            if level.size > params.read_fit_max_size() {
                let f = footprint_factor(level.size, params.level_roughness(l));
                spatial::sharpen_for_bilinear(level, spatial::sharpen_weight(f));
            }
        }
    }
    // A sun's power at every roughness is the power of the read, which on a small level
    // differs from the texels' (crate::spatial::keep_read_power; 0.28% on the 4² last level
    // before). Each small level's read is given the source's power, for every engine target
    // (each reads its levels through a seamless bilinear tap); the brute-force --reference
    // of a stock target stays the exact kernel's texels by definition, and so does its mirror
    // level ("the source box-reduced to --size", tests/stability.rs; only a chain of ≤ 32² has
    // a mirror this small).
    if params.target == Target::Custom || !params.reference {
        let power = source_power;
        let skip = usize::from(params.target != Target::Custom);
        use rayon::prelude::*;
        // One level a job: each level's weights are summed in their own fixed order (the same
        // bits for any thread count), and the small levels' integrations (5–7 ms apiece; 29 ms
        // and 115 ms for the gltf default's 7 levels before spatial::read_weights walked its
        // cells once an axis) no longer run one after the other on one core.
        levels
            .par_iter_mut()
            .skip(skip)
            .filter(|level| level.size <= spatial::READ_POWER_MAX_SIZE)
            .for_each(|level| {
                let w = spatial::read_weights(level.size);
                spatial::keep_read_power(level, power, &w);
            });
    }
    // The custom lookup's alpha channel: per interval, the kernel's luminance at its midpoint
    // on the finer level's texels, less that level's own (less the blend on the mirror).
    let tc = Instant::now();
    let mut custom_lookup = params.custom_lookup();
    let correction = custom_lookup.as_mut().map(|lk| {
        let top = levels.len() - 1;
        let mut alpha: Vec<Cubemap> = vec![custom::zero_alpha(&levels[top])];
        for l in (0..top).rev() {
            let n = levels[l].size;
            let (engine, texels) = engine_after_fit
                .as_ref()
                .expect("the custom target keeps its engine for the midpoints");
            let source = source.as_ref().expect("the custom target keeps its source");
            let (mid, w) =
                convolve_level_many(engine, source, texels, n, &[lk.mid_roughness(l)], progress)
                    .remove(0);
            level_work[l] += w;
            let mut mid = reduce_to(mid, n);
            // The midpoint is a node of the read as the levels are: sharpened alike.
            let f = footprint_factor(n, lk.mid_roughness(l));
            spatial::sharpen_for_bilinear(&mut mid, spatial::sharpen_weight(f));
            // As the levels: a small level's read keeps the source's power (the midpoint is a
            // node of the read, and the log read has no balance to absorb a bias).
            if l > 0 && n <= spatial::READ_POWER_MAX_SIZE {
                spatial::keep_read_power(&mut mid, source_power, &spatial::read_weights(n));
            }
            let m = if l == 0 {
                custom::correction(&levels[0], &mid, &levels[1])
            } else {
                custom::midpoint_alpha(&levels[l], &mid)
            };
            alpha.insert(0, m);
        }
        CubeMips { levels: alpha }
    });
    // The power factors, fitted on the chain as written (the levels lent to a CubeMips, not
    // copied).
    if let (Some(lk), Some(alpha)) = (custom_lookup.as_mut(), &correction) {
        let mips = CubeMips {
            levels: std::mem::take(&mut levels),
        };
        lk.fit_power(&CustomChain::new(&mips, alpha));
        levels = mips.levels;
    }
    fit_seconds += tc.elapsed().as_secs_f64();
    if correction.is_some() {
        cpu.stage("midpoints".into());
    }
    let note = (n_baked < n_chain).then(|| {
        format!(
            "--max-roughness {}: levels 0..={} (roughness <= {}) carry the accuracy contract{}; levels {}..={} are the exact kernel at their roughness, unfitted, kept because {}'s lookup ({}) reads each level at its roughness only on the full chain of {} levels (and blends level {} with level {} up to the cut)",
            params.max_roughness.unwrap_or(1.0),
            n_baked - 1,
            params.level_roughness(n_baked - 1),
            if fits { " and are fitted to the lookup" } else { "" },
            n_baked,
            n_written - 1,
            params.target.name(),
            params.target.spec().lod.name(),
            n_chain,
            n_baked - 1,
            n_baked
        )
    });
    let (method, quality) = if params.reference {
        ("reference", "reference".to_string())
    } else if params.method == Method::Fis && params.samples.is_some() {
        (params.method.name(), "custom".to_string())
    } else {
        (params.method.name(), params.quality.name().to_string())
    };
    let report = Report {
        tool: "prefilter",
        version: ibl_core::TOOL_VERSION,
        size,
        levels: n_written,
        chain_levels: n_chain,
        method,
        quality,
        kernel: "D_GGX(n·h, α)·max(n·l, 0), h = normalize(n + l), n = v, α = r², r of each level as the target's lookup reads it, normalised to unit sum",
        target: params.target,
        lookup: params.lookup().name(),
        level_roughness: (0..n_written).map(|l| params.level_roughness(l)).collect(),
        fit_lookup: params.fits_lookup(),
        source_size: src_size,
        level0_filter,
        tree: engine_kind.0.then(|| params.quality.tree_params()),
        fis_samples: engine_kind.1.then(|| params.fis_samples()),
        fis_lod_bias: engine_kind.1.then_some(LOD_BIAS),
        rotate: params.rotate,
        max_roughness: params.max_roughness,
        note,
        level: reports,
        encoding: None,
        runtime: None,
        custom_lookup: custom_lookup.clone(),
    };
    // The report reads the reference computed before the fit: the source goes before the
    // report's bordered copy of the chain (12 bytes a texel: 19 MB of the 512² bake).
    drop(source);
    release_freed_memory();
    let mips = CubeMips { levels };
    // The error the target's lookup sees, against the exact kernel (the cell tree at
    // RUNTIME_REFERENCE, 0.02% from brute force: far below the lookup errors it measures;
    // computed before the fit, above).
    let tr = Instant::now();
    drop(engine_after_fit);
    let reference = Reference::Table(&reference_table);
    // The engine samples what the format decodes to: a lossy chain is looked up decoded, from
    // the very bytes its file will hold (encoded in the target's orientation, as written: a
    // BC6H block of a turned face is another block), then turned back into our frame.
    // Those bytes are kept for the file, so the chain is encoded once.
    let enc = params.encoding()?;
    let (encoded, decoded) = if enc.format.is_lossless() {
        (None, None)
    } else {
        let orientation = params.target.spec().orientation;
        let encoded = if orientation.is_identity() {
            ibl_core::io::texture::encode_chain(&mips, enc.format, enc.bc6h_quality)
        } else {
            let oriented = orientation.apply_mips(&mips);
            ibl_core::io::texture::encode_chain(&oriented, enc.format, enc.bc6h_quality)
        };
        let file = ibl_core::io::texture::decode_cube(Path::new("chain"), &encoded.0)?;
        let decoded = if orientation.is_identity() {
            file
        } else {
            orientation.inverse().apply_mips(&file)
        };
        (Some(encoded), Some(decoded))
    };
    let looked_up = decoded.as_ref().unwrap_or(&mips);
    let mut runtime_report = match (&correction, &custom_lookup) {
        (Some(alpha), Some(lk)) => runtime::evaluate_custom(
            &CustomChain::new(looked_up, alpha),
            lk,
            runtime::REPORT_DIRECTIONS,
            &reference,
        ),
        _ => runtime::evaluate_with(
            looked_up,
            params.target,
            params.lookup(),
            runtime::REPORT_DIRECTIONS,
            &reference,
        ),
    };
    runtime_report.format = enc.format.name();
    let runtime_seconds = reference_seconds + tr.elapsed().as_secs_f64();
    cpu.stage("runtime".into());
    let report = Report {
        runtime: Some(runtime_report),
        ..report
    };
    Ok(Chain {
        mips,
        correction,
        encoded,
        report,
        level_seconds,
        level_work,
        resample_seconds,
        source_seconds,
        estimate_seconds,
        runtime_seconds,
        fit_seconds,
        fit_kernel_seconds,
        tree_seconds,
        cpu_seconds: cpu.stages,
        peak_mib: cpu.peaks,
        warnings,
    })
}

/// The part of the lookup fit (`--fit-lookup`) that needs the source structures: the small
/// levels fitted to their bilinear read ([`crate::spatial`]), and the kernel at the nodes of
/// every level [`fit_sweeps`] then fits to the engine's blend between levels. Returns the
/// seconds spent in the kernel (the fit's nodes and the read fit's dense levels).
fn fit_inputs(
    params: &Params,
    n_baked: usize,
    (engine, source, texels): (&Engine, &Cubemap, &SourceTexels),
    stages: &mut [Stage],
    reports: &mut [LevelReport],
    level_work: &mut [u64],
    progress: &dyn Progress,
) -> f64 {
    let mut kernel_seconds = 0.0;
    let (size, n_chain) = (params.size, params.chain_levels());
    let lookup = params.lookup();
    // Small levels fitted to their bilinear read (crate::spatial): a correction of the
    // exact level, later added to what the per-texel fit stores (both are small and the
    // read is linear in the texels).
    for (l, st) in stages.iter_mut().enumerate().skip(1) {
        let n = st.exact.size;
        if n > params.read_fit_max_size() {
            continue;
        }
        let r = params.level_roughness(l);
        let dense_size = n * spatial::SAMPLES_PER_EDGE;
        let tk = Instant::now();
        let (dense, w) = convolve_points(engine, source, texels, dense_size, r, progress);
        kernel_seconds += tk.elapsed().as_secs_f64();
        level_work[l] += w;
        let (read, report) = spatial::fit_bilinear(&st.exact, &dense);
        st.correction = Some(read);
        reports[l].read_fit = Some(report);
    }
    // The kernel at the fit's nodes of every level the sweeps fit (the level pass computes
    // them beside each level; any it did not are computed here, while the engine is held).
    if params.fits_blend() {
        for l in 1..n_baked.min(n_chain - 1) {
            let n = stages[l].exact.size;
            if stages[l].fitting.is_none() {
                let plan = fit::plan(lookup, l, n_chain, size, fit::FIT_NODES);
                let tk = Instant::now();
                let at_nodes: Vec<Cubemap> = plan
                    .nodes
                    .iter()
                    .map(|q| {
                        let (c, w) =
                            convolve_level(engine, source, texels, n, q.roughness, progress);
                        level_work[l] += w;
                        reduce_to(c, n)
                    })
                    .collect();
                kernel_seconds += tk.elapsed().as_secs_f64();
                stages[l].fitting = Some((plan, at_nodes));
            }
        }
    }
    kernel_seconds
}

/// The per-texel lookup fit ([`crate::fit`]) of every inner level, from the kernel at its
/// nodes that [`fit_inputs`] left in each stage: needs no source structure.
fn fit_sweeps(params: &Params, n_baked: usize, stages: &mut [Stage]) {
    let n_chain = params.chain_levels();
    // The per-texel lookup fit (crate::fit), fine to coarse: Gauss–Seidel sweeps. The
    // neighbours enter as the engine reads them at this level's texel centres: the finer
    // one as stored (fitted already), the coarser one exact (first sweep, assumed to
    // follow) then as stored. The last level's values stay the kernel's: at r = 1 the
    // lookup reads it alone.
    let sweeps = if params.fits_blend() { fit::SWEEPS } else { 0 };
    for sweep in 0..sweeps {
        for l in 1..n_baked.min(n_chain - 1) {
            let n = stages[l].exact.size;
            // A level with no read correction is read as it is, not copied (`Stage::stored`
            // borrows it; a copy of level 0 was most of the reads' time at 512²).
            let lo = fit::read_at_texels(&stages[l - 1].stored(), n);
            let hi = fit::read_at_texels(&stages[l + 1].stored(), n);
            let coarser = if sweep == 0 {
                fit::Coarser::Follows
            } else {
                fit::Coarser::Fixed
            };
            let st = &stages[l];
            let (plan, at_nodes) = st.fitting.as_ref().expect("planned above");
            let hi = plan.hi.map(|_| &hi);
            let values = fit::fit_level(
                plan,
                &st.exact,
                &lo,
                hi,
                at_nodes,
                coarser,
                fit::Power::Kept,
            );
            stages[l].values = Some(values);
            release_freed_memory();
        }
    }
}

/// One level on its way through the lookup fit.
struct Stage<'a> {
    /// The kernel at the level's roughness (footprint means where they apply); level 0 may
    /// be the source itself.
    exact: Cow<'a, Cubemap>,
    /// What the per-texel lookup fit stores (crate::fit); none where it does not apply (the
    /// level stores `exact`: one copy, not two, of level 0, the largest).
    values: Option<Cubemap>,
    /// The level fitted to its bilinear read (crate::spatial), on small levels.
    correction: Option<Cubemap>,
    /// The per-texel fit's plan and the kernel at its nodes, kept for the later sweeps.
    fitting: Option<(fit::Plan, Vec<Cubemap>)>,
}

impl Stage<'_> {
    /// What the level stores: the per-texel fit's values plus the read correction (the
    /// read-fitted exact level minus the exact level), never negative and never black where
    /// the exact level is not: a texel channel the sum takes to 0 or below keeps the per-texel
    /// fit's value, else the exact one. Both keep the exact level's power; where a texel was
    /// replaced, its channel is rescaled to it.
    fn stored(&self) -> Cow<'_, Cubemap> {
        let Some(read) = &self.correction else {
            return Cow::Borrowed(self.values());
        };
        let mut out = self.values().clone();
        let mut clamped = false;
        for ((o, f), e) in out.faces.iter_mut().zip(&read.faces).zip(&self.exact.faces) {
            for ((v, f), e) in o.data.iter_mut().zip(&f.data).zip(&e.data) {
                let sum = *v + (f - e);
                if sum > 0.0 || *e <= 0.0 {
                    clamped |= sum < 0.0;
                    *v = sum.max(0.0);
                } else {
                    clamped = true;
                    *v = if *v > 0.0 { *v } else { *e };
                }
            }
        }
        if clamped {
            let (want, got) = (self.exact.mean_radiance(), out.mean_radiance());
            for face in &mut out.faces {
                for t in face.data.chunks_exact_mut(3) {
                    for c in 0..3 {
                        if got[c] > 0.0 {
                            t[c] = (t[c] as f64 * want[c] / got[c]) as f32;
                        }
                    }
                }
            }
        }
        Cow::Owned(out)
    }

    /// What the per-texel fit stores, the exact level where it does not apply.
    fn values(&self) -> &Cubemap {
        self.values.as_ref().unwrap_or(&self.exact)
    }

    /// [`Self::stored`], consuming the stage (no copy of a level left as it is).
    fn into_stored(self) -> Cubemap {
        if self.correction.is_some() {
            return self.stored().into_owned();
        }
        self.values.unwrap_or_else(|| self.exact.into_owned())
    }
}

/// Level texels at roughness `r` by the chosen method: `n`×`n` faces, computed k× finer where
/// the footprint is averaged ([`footprint_factor`]; [`reduce_to`] gives the level), and the
/// kernel evaluations spent.
fn convolve_level(
    engine: &Engine,
    source: &Cubemap,
    texels: &SourceTexels,
    n: usize,
    r: f32,
    progress: &dyn Progress,
) -> (Cubemap, u64) {
    let fine = n * footprint_factor(n, r);
    convolve_points(engine, source, texels, fine, r, progress)
}

/// [`convolve_level`] at every roughness of `rs` (same order): the tree method evaluates
/// those with the same fine size in one pass, sharing its cuts.
fn convolve_level_many(
    engine: &Engine,
    source: &Cubemap,
    texels: &SourceTexels,
    n: usize,
    rs: &[f32],
    progress: &dyn Progress,
) -> Vec<(Cubemap, u64)> {
    let Engine::Tree(tree, p) = engine else {
        return rs
            .iter()
            .map(|&r| convolve_level(engine, source, texels, n, r, progress))
            .collect();
    };
    let fine: Vec<usize> = rs.iter().map(|&r| n * footprint_factor(n, r)).collect();
    let mut out: Vec<Option<(Cubemap, u64)>> = rs.iter().map(|_| None).collect();
    for (i, &f) in fine.iter().enumerate() {
        if out[i].is_some() {
            continue;
        }
        let group: Vec<usize> = (i..rs.len()).filter(|&j| fine[j] == f).collect();
        let group_rs: Vec<f32> = group.iter().map(|&j| rs[j]).collect();
        let (cubes, w) = tree_levels(tree, f, &group_rs, p, progress);
        for ((j, c), w) in group.into_iter().zip(cubes).zip(w) {
            out[j] = Some((c, w.cell_evaluations));
        }
    }
    out.into_iter()
        .map(|c| c.expect("every roughness"))
        .collect()
}

/// The kernel at roughness `r` at the texel centres of a `fine`×`fine` cube by the chosen
/// method, and the kernel evaluations spent.
fn convolve_points(
    engine: &Engine,
    source: &Cubemap,
    texels: &SourceTexels,
    fine: usize,
    r: f32,
    progress: &dyn Progress,
) -> (Cubemap, u64) {
    match engine {
        Engine::Reference => (
            reference_level(source, texels, fine, r, progress),
            (6 * fine * fine * texels.len()) as u64,
        ),
        Engine::Tree(tree, p) => {
            let (cube, w) = tree_level(tree, fine, r, p, progress);
            (cube, w.cell_evaluations)
        }
        Engine::Fis(pyr, count) => {
            let table = SampleTable::build(r, *count, pyr.size(), LOD_BIAS, pyr.max_lod());
            (
                filter_level(pyr, &table, fine, progress),
                (6 * fine * fine * table.len()) as u64,
            )
        }
    }
}

/// Whether the lookup fit's node cube at roughness r for an n×n level is computed at n/2 and
/// upsampled ([`Cubemap::upsample_quadratic`]) instead of at n: where the lobe spans at least
/// [`NODE_HALF_LOBE_TEXELS`] half-size texels (α ≥ that many texel edges) and those texels
/// store centre values ([`footprint_factor`] 1), the convolved field is smooth on their scale
/// and the upsampling's third-order error stays far below the fit's own. A quarter of the
/// texels: the fit's nodes were two thirds of level 1's work.
///
/// Measured on six fixtures (four full-size, the two damaged held-out ones), the runtime error
/// against the brute force (`examples/runtime-check`) and the sidecar's: the default gltf bake
/// moved by at most 0.007 point at any roughness, 256² × 5 levels by 0.043; the stock targets'
/// nodes (filament, unity, babylon: narrow lobes next to the mirror) stay at full size and
/// their chains are unchanged. Narrower bounds cost accuracy: at 1.5 texels filament's interior
/// moved 0.105 point at r = 0.03, with no bound 0.29; the 64² level's nodes at 32² without
/// footprint means moved esplanade 0.36 point.
fn node_at_half_size(n: usize, roughness: f32) -> bool {
    let edge = std::f32::consts::FRAC_PI_2 / (n / 2).max(1) as f32;
    n >= 32
        && footprint_factor(n / 2, roughness) == 1
        && roughness * roughness >= NODE_HALF_LOBE_TEXELS * edge
}

/// Half-size texel edges the lobe's α must span for [`node_at_half_size`].
const NODE_HALF_LOBE_TEXELS: f32 = 2.0;

/// Box-reduces `cube` to `n`×`n` faces (exact footprint means of its texels).
fn reduce_to(mut cube: Cubemap, n: usize) -> Cubemap {
    while cube.size > n {
        cube = cube.downsample();
    }
    cube
}

/// A texel's edge must be at most this fraction of the lobe's width α (radians) to be stored
/// as its centre value; coarser texels store their footprint's mean.
pub(crate) const FOOTPRINT_LOBE_FRACTION: f32 = 0.25;
/// Finest face the footprint means are computed at (bounds their cost: a few thousand texels).
pub(crate) const FOOTPRINT_MAX_SIZE: usize = 64;

/// Sub-texels per edge k (a power of two) whose mean an n×n texel of roughness r stores: the
/// smallest with a sub-texel edge (π/2)/(n·k) ≤ [`FOOTPRINT_LOBE_FRACTION`]·α, at most
/// [`FOOTPRINT_MAX_SIZE`]/n; 1 (the centre value) where texels are already small next to the
/// lobe. Mean over the footprint = ∫ over the texel of the convolved radiance / Ω, so the
/// level keeps the environment's power whatever its size.
pub(crate) fn footprint_factor(n: usize, roughness: f32) -> usize {
    let alpha = (roughness * roughness).max(1e-6);
    let edge = std::f32::consts::FRAC_PI_2 / n as f32;
    let mut k = 1;
    while edge / k as f32 > FOOTPRINT_LOBE_FRACTION * alpha && n * k * 2 <= FOOTPRINT_MAX_SIZE {
        k *= 2;
    }
    k
}

/// Probe texels of an n×n level: a g×g grid on each face (fewer on tiny faces).
pub fn probe_texels(n: usize, g: usize) -> Vec<(Face, usize, usize)> {
    let mut v = Vec::new();
    for face in Face::ALL {
        let mut seen = Vec::new();
        for b in 0..g {
            for a in 0..g {
                let ij = (((2 * a + 1) * n) / (2 * g), ((2 * b + 1) * n) / (2 * g));
                if !seen.contains(&ij) {
                    seen.push(ij);
                    v.push((face, ij.0, ij.1));
                }
            }
        }
    }
    v
}

/// Brute-force kernel evaluations spent on the estimate of one level (at most 4×4 probes per
/// face; fewer on large sources).
const ESTIMATE_BUDGET: usize = 10_000_000;

/// Estimated error of a level: its probe texels against the exact kernel summed by brute force
/// over every source texel.
pub(crate) fn estimate_error(
    level: &Cubemap,
    brute: &(dyn Fn(&[glam::Vec3], f32) -> Vec<ibl_core::Rgb> + Sync),
    source_texels: usize,
    roughness: f32,
) -> EstimatedError {
    use rayon::prelude::*;
    let per_face = (ESTIMATE_BUDGET / (6 * source_texels.max(1))).max(1);
    let g = ((per_face as f64).sqrt() as usize).clamp(1, 4);
    let probes = probe_texels(level.size, g);
    let alpha = roughness * roughness;
    // One group of probes a thread, each group one pass over the source
    // (`CellTree::brute_convolve_many`: a pass per probe was bound by reading the source, not
    // by the kernel; the estimate's CPU halved). Each probe's sum is its own, so the grouping,
    // hence the thread count, leaves the bits as they are.
    let group = probes.len().div_ceil(rayon::current_num_threads()).max(1);
    let pairs: Vec<(f64, f64)> = probes
        .par_chunks(group)
        .flat_map_iter(|group| {
            let dirs: Vec<glam::Vec3> = group
                .iter()
                .map(|&(f, i, j)| texel_direction(f, i, j, level.size))
                .collect();
            let values = brute(&dirs, alpha);
            group
                .iter()
                .zip(values)
                .map(|(&(f, i, j), r)| {
                    (luminance(level.texel(f, i, j)) as f64, luminance(r) as f64)
                })
                .collect::<Vec<_>>()
        })
        .collect();
    let s = ErrorStats::from_pairs(pairs);
    EstimatedError {
        mean_abs_rel: s.mean_abs_rel,
        rms_rel: s.rms_rel,
        max_abs_rel: s.max_abs_rel,
        probe_texels: s.texels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_streamed_input_bakes_the_chain_of_the_loaded_one() {
        // A Radiance equirect at the streaming threshold (2048×1024): `run` from its opened
        // stream and from the loaded image give the same files, bit for bit, and the same
        // warnings.
        use ibl_core::envmap::{load_environment, open_environment_with, EnvPolicy};
        let d = tempfile::tempdir().unwrap();
        let p = ibl_core::stream::write_streamable_equirect(d.path(), "env.hdr");
        // 32²: the source cube (128²) box-reduced to level 0; 512², the input's natural
        // size: level 0 is the adaptive mirror, which the streamed read makes in its one pass.
        for (size, levels, level0) in [(32, 4, Filter::Area), (512, 2, Filter::Adaptive)] {
            let params = Params {
                size,
                levels: Some(levels),
                rotate: 20.0,
                ..Default::default()
            };
            let opened = open_environment_with(&p, EnvPolicy::default()).unwrap();
            assert!(matches!(opened, Opened::Streamed(_)));
            let np = &ibl_core::progress::NoProgress;
            let a = run(&params, opened, d.path(), np).unwrap();
            let loaded = load_environment(&p, false).unwrap();
            if level0 == Filter::Adaptive {
                // The mirror is the adaptive resample itself (made from the area cube's texels).
                let direct = loaded.env.to_cube(size, Filter::Adaptive, 20.0, np);
                assert_eq!(a.chain.mips.levels[0].faces, direct.faces);
            }
            let b = run(&params, loaded, d.path(), np).unwrap();
            assert_eq!(a.chain.report.level0_filter, level0);
            assert_eq!(b.chain.report.level0_filter, level0);
            crate::test_util::assert_same_bits(&a.chain.mips, &b.chain.mips);
            assert_eq!(a.chain.warnings, b.chain.warnings);
            let names = |b: &Baked| b.files.iter().map(|f| f.0.clone()).collect::<Vec<_>>();
            assert_eq!(names(&a), names(&b));
            // The chain's files (not the sidecar, which records times).
            for (f, g) in a.files.iter().zip(&b.files) {
                if f.0.extension().is_some_and(|e| e == "exr") {
                    assert!(f.1 == g.1, "{}", f.0.display());
                }
            }
        }
    }

    /// A lossy chain is encoded once: the runtime report looks up the very blocks the file
    /// holds (in Bevy's frame, z negated: a BC6H block of a mirrored face is another block),
    /// and the sidecar's per-level encoding error is the file's.
    #[test]
    fn the_runtime_report_of_a_lossy_chain_reads_the_files_own_texels() {
        use ibl_core::envmap::LoadedEnvironment;
        use ibl_core::io::texture::{decode_cube, relative_errors};
        let src = Cubemap::from_fn(32, |d| {
            let d = d.normalize();
            let sun = 40.0
                * d.dot(glam::Vec3::new(0.6, 0.5, -0.62).normalize())
                    .max(0.0)
                    .powi(16);
            [
                0.8 + sun + 0.5 * d.z,
                0.6 + 0.8 * sun + 0.4 * d.y * d.y,
                0.3 + 0.3 * (3.0 * d.x).sin().abs() + 0.2 * d.z.max(0.0),
            ]
        });
        let np = &ibl_core::progress::NoProgress;
        let d = tempfile::tempdir().unwrap();
        let table = Reference::Tree {
            tree: &CellTree::new(&src),
            source: &src,
            params: RUNTIME_REFERENCE,
        }
        .table(runtime::REPORT_DIRECTIONS);
        let orientation = Target::Bevy.spec().orientation;
        assert!(!orientation.is_identity());
        for format in [PixelFormat::Rgba32f, PixelFormat::Bc6h] {
            let params = Params {
                size: 16,
                levels: Some(3),
                target: Target::Bevy,
                format: Some(format),
                zstd: None,
                ..Default::default()
            };
            let loaded = LoadedEnvironment {
                env: Environment::Cube(src.clone()),
                path: d.path().join("src.exr"),
                report: Default::default(),
                read_as: Vec::new(),
                negative: Default::default(),
            };
            let baked = run(&params, loaded, d.path(), np).unwrap();
            let (path, bytes) = baked
                .files
                .iter()
                .find(|f| f.0.extension().is_some_and(|e| e == "ktx2"))
                .unwrap();
            let tex = io::container::read(path, bytes).unwrap().unwrap();
            assert_eq!(tex.payload.format, format);
            let file = decode_cube(path, &tex.payload).unwrap();
            // The lookup of the file's texels, turned back into our frame, against the same
            // reference the bake used: the report's numbers to the bit.
            let ours = orientation.inverse().apply_mips(&file);
            let want = runtime::evaluate_with(
                &ours,
                Target::Bevy,
                params.lookup(),
                runtime::REPORT_DIRECTIONS,
                &Reference::Table(&table),
            );
            let got = baked.chain.report.runtime.as_ref().unwrap();
            assert_eq!(got.mean_abs_rel, want.mean_abs_rel, "{format:?}");
            assert_eq!(got.p99_abs_rel, want.p99_abs_rel, "{format:?}");
            // Each level's reported encoding error is the file's against the float level.
            let float = orientation.apply_mips(&baked.chain.mips);
            for (l, e) in baked.encoding.iter().enumerate() {
                let (mean, max) = relative_errors(&float.levels[l].faces, &file.levels[l].faces);
                assert_eq!((e.mean_rel, e.max_rel), (mean, max), "{format:?} level {l}");
            }
            if format == PixelFormat::Bc6h {
                assert!(baked.encoding.iter().all(|e| e.mean_rel > 0.0));
            }
        }
    }

    #[test]
    fn defaults_agree_between_clap_serde_and_default() {
        let from_ron: Params = ron::from_str("()").unwrap();
        assert_eq!(from_ron, Params::default());
        assert_eq!(Params::default().size, 256);
        assert_eq!(Params::default().quality, Quality::Default);
        // gltf's default chain is its TargetSpec row: 7 levels on 256², down to 4×4.
        let gltf = Target::Gltf.spec();
        assert_eq!((gltf.size, gltf.levels), (256, 7));
        assert_eq!(Params::default().chain_levels(), gltf.levels);
        assert_eq!(mip_sizes(256, GLTF_SMALLEST_FACE).last(), Some(&4));
        let p: Params =
            ron::from_str("(size: 64, levels: Some(4), quality: high, layout: Some(ktx2))")
                .unwrap();
        assert_eq!(
            (p.size, p.levels, p.quality, p.encoding().unwrap().layout),
            (64, Some(4), Quality::High, ibl_core::output::Layout::Ktx2)
        );
    }

    #[test]
    fn unknown_keys_and_out_of_range_values_are_refused() {
        assert!(ron::from_str::<Params>("(sise: 4)").is_err());
        for p in [
            Params {
                size: 0,
                ..Default::default()
            },
            Params {
                size: 32,
                levels: Some(7),
                ..Default::default()
            },
            Params {
                levels: Some(0),
                ..Default::default()
            },
            Params {
                samples: Some(0),
                ..Default::default()
            },
            Params {
                max_roughness: Some(1.5),
                ..Default::default()
            },
            Params {
                max_roughness: Some(f32::NAN),
                ..Default::default()
            },
            Params {
                rotate: f32::INFINITY,
                ..Default::default()
            },
        ] {
            assert!(p.validate().is_err(), "{p:?}");
        }
        assert!(Params {
            size: 32,
            levels: Some(6),
            ..Default::default()
        }
        .validate()
        .is_ok());
    }

    #[test]
    fn max_roughness_keeps_the_spacing_of_the_full_chain() {
        let p = Params {
            size: 64,
            levels: Some(5),
            max_roughness: Some(0.6),
            ..Default::default()
        };
        // r = 0, 0.25, 0.5, 0.75, 1 → keeps 0..=2.
        assert_eq!(p.baked_levels(), 3);
        let p = Params {
            max_roughness: Some(0.5),
            ..p
        };
        assert_eq!(p.baked_levels(), 3, "r = 0.5 exactly is kept");
        let p = Params {
            max_roughness: Some(0.0),
            ..p
        };
        assert_eq!(p.baked_levels(), 1);
    }

    /// A sky with a soft sun (relative errors meaningful everywhere).
    fn sunny_sky(n: usize) -> Cubemap {
        Cubemap::from_fn(n, |d| {
            let d = d.normalize();
            let sun = (d.dot(glam::Vec3::new(0.4, 0.7, 0.59).normalize()) - 0.9).max(0.0) * 80.0;
            let base = 0.2 + 0.8 * d.y.max(0.0) + 0.1 * (3.0 * d.x).sin().abs();
            [base + sun, base * 0.9 + sun, base * 0.7 + 0.5 * sun]
        })
    }

    /// Issue 22: a chain cut by --max-roughness is read by the engine it was made for at the
    /// intended roughness. glTF / Bevy / Filament compute the lod from the file's level count,
    /// Babylon's `.env` holds a full chain and every lookup blends the last kept level with the
    /// next: the chain keeps its level count (levels past the cut: the exact kernel, unfitted)
    /// and its lookup error at r <= max_roughness is the uncut chain's.
    #[test]
    fn a_max_roughness_chain_is_read_at_the_intended_roughness_by_its_engine() {
        use ibl_core::envmap::Environment;
        use ibl_core::progress::NoProgress;
        let env = Environment::Cube(sunny_sky(32));
        let max_r = 0.45;
        for (target, levels) in [
            (Target::Gltf, Some(5)),
            (Target::Bevy, Some(5)),
            (Target::Filament, Some(5)),
            (Target::Unity, Some(5)),
            (Target::Babylon, None),
        ] {
            let full = Params {
                size: 16,
                levels,
                target,
                quality: Quality::Draft,
                ..Default::default()
            };
            let cut = Params {
                max_roughness: Some(max_r),
                ..full.clone()
            };
            assert!(cut.baked_levels() < cut.chain_levels(), "{target:?}");
            let a = bake_chain(&full, &env, &NoProgress).unwrap();
            let b = bake_chain(&cut, &env, &NoProgress).unwrap();
            let lod = target.spec().lod;
            let n = b.mips.levels.len();
            assert_eq!(n, cut.chain_levels(), "{target:?} keeps the level count");
            assert!(b.report.level[cut.baked_levels()].beyond_max_roughness);
            assert!(!b.report.level[cut.baked_levels() - 1].beyond_max_roughness);
            assert!(b.report.note.as_deref().unwrap().contains("full chain"));
            // The engine's lookup, on the file's own level count, lands on each level at the
            // roughness the level was baked for.
            for (l, rep) in b.report.level.iter().enumerate() {
                if rep.roughness < 1.0 {
                    let got = lod.lod(rep.roughness, n, cut.size);
                    assert!(
                        (got - l as f32).abs() < 1e-3,
                        "{target:?} level {l}: lod {got}"
                    );
                }
            }
            // The runtime error at r <= max_roughness is the uncut chain's (or lower: the
            // last kept level is fitted against an exact neighbour rather than a fitted one).
            let (ra, rb) = (a.report.runtime.unwrap(), b.report.runtime.unwrap());
            for ((r, ea), eb) in ra
                .roughness
                .iter()
                .zip(&ra.mean_abs_rel)
                .zip(&rb.mean_abs_rel)
            {
                if *r <= max_r {
                    eprintln!("{target:?} r {r:.3}: uncut {ea:.4} cut {eb:.4}");
                    assert!(
                        (ea - eb).abs() <= 0.3 * ea + 0.002,
                        "{target:?} r {r}: uncut {ea} cut {eb}"
                    );
                }
            }
        }
    }

    /// Issue 22: no stored level holds a black or negative face where the exact level is
    /// not (the read fit clamped the 1×1 level of a Babylon chain to black), for every target,
    /// on a sky and on a 10⁵ sun on black.
    #[test]
    fn no_fitted_face_is_black_or_negative_where_the_exact_one_is_not() {
        use ibl_core::envmap::Environment;
        use ibl_core::progress::NoProgress;
        let mut sun = Cubemap::new(32);
        let k = (9 * 32 + 21) * 3;
        sun.faces[Face::Pz as usize].data[k..k + 3].copy_from_slice(&[1e5, 9e4, 7e4]);
        for env in [sunny_sky(32), sun] {
            let env = Environment::Cube(env);
            for target in [
                Target::Gltf,
                Target::Bevy,
                Target::Filament,
                Target::Unity,
                Target::Babylon,
            ] {
                let params = Params {
                    size: 16,
                    target,
                    quality: Quality::Draft,
                    ..Default::default()
                };
                let fitted = bake_chain(&params, &env, &NoProgress).unwrap();
                let exact = bake_chain(
                    &Params {
                        fit_lookup: Some(false),
                        ..params.clone()
                    },
                    &env,
                    &NoProgress,
                )
                .unwrap();
                for (l, (f, e)) in fitted
                    .mips
                    .levels
                    .iter()
                    .zip(&exact.mips.levels)
                    .enumerate()
                {
                    for face in 0..6 {
                        let (fd, ed) = (&f.faces[face].data, &e.faces[face].data);
                        assert!(
                            fd.iter().all(|v| v.is_finite() && *v >= 0.0),
                            "{target:?} level {l} face {face}: negative or non-finite"
                        );
                        for c in 0..3 {
                            let sum = |d: &[f32]| d.iter().skip(c).step_by(3).sum::<f32>();
                            if sum(ed) > 0.0 {
                                assert!(
                                    sum(fd) > 0.0,
                                    "{target:?} level {l} ({}²) face {face} channel {c}: black where exact is {}",
                                    f.size,
                                    sum(ed)
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn source_is_a_power_of_two_multiple_of_the_output_up_to_the_input() {
        assert_eq!(source_face_size(256, 256), 256);
        assert_eq!(source_face_size(64, 32), 64);
        assert_eq!(source_face_size(1024, 32), 64);
        assert_eq!(source_face_size(16, 32), 32);
        assert_eq!(source_face_size(100, 24), 48);
    }

    /// Σ L·Ω over the cube: the power of the environment.
    fn power(c: &Cubemap) -> f64 {
        let sa = ibl_core::cube::solid_angle_table(c.size);
        c.faces
            .iter()
            .map(|f| {
                f.data
                    .chunks_exact(3)
                    .zip(&sa)
                    .map(|(t, s)| luminance([t[0], t[1], t[2]]) as f64 * *s as f64)
                    .sum::<f64>()
            })
            .sum()
    }

    /// The power of what a sampler reads of a level: the read's Σ W_p L_p for levels of at most
    /// spatial::READ_POWER_MAX_SIZE a face (what the bake keeps there, spatial::keep_read_power),
    /// the texels' Σ Ω_p L_p above.
    fn level_power(c: &Cubemap) -> f64 {
        if c.size > spatial::READ_POWER_MAX_SIZE {
            return power(c);
        }
        let w = spatial::read_weights(c.size);
        let n2 = c.size * c.size;
        c.faces
            .iter()
            .enumerate()
            .map(|(f, face)| {
                face.data
                    .chunks_exact(3)
                    .enumerate()
                    .map(|(p, t)| luminance([t[0], t[1], t[2]]) as f64 * w[f * n2 + p])
                    .sum::<f64>()
            })
            .sum()
    }

    #[test]
    fn a_one_texel_sun_keeps_its_power_at_every_level_down_to_1x1() {
        use ibl_core::envmap::Environment;
        use ibl_core::progress::NoProgress;
        // One bright texel off every face's centre and axis on a dim sky.
        let n = 32;
        let mut src = Cubemap::constant(n, [0.002, 0.002, 0.002]);
        let k = (11 * n + 20) * 3;
        src.faces[Face::Py as usize].data[k..k + 3].copy_from_slice(&[5000.0, 4000.0, 3000.0]);
        let p0 = power(&src);
        for target in [Target::Gltf, Target::Filament, Target::Unity] {
            // The exact levels, then the levels fitted to the lookup (the default).
            let params = Params {
                size: 16,
                levels: Some(5),
                target,
                fit_lookup: Some(false),
                ..Default::default()
            };
            let chain = bake_chain(&params, &Environment::Cube(src.clone()), &NoProgress).unwrap();
            assert_eq!(chain.mips.levels.last().unwrap().size, 1);
            for (l, c) in chain.mips.levels.iter().enumerate() {
                // A stock target's mirror level keeps the texels' power (it is the source
                // box-reduced), the others their read's.
                let e = if l == 0 { power(c) } else { level_power(c) } / p0 - 1.0;
                eprintln!("{target:?} level {l} ({}²): power {e:+.2e}", c.size);
                assert!(e.abs() < 1e-3, "{target:?} level {l}: power off by {e:.2e}");
            }
            // Without the footprint means the coarse levels would be off (centre values).
            let last = chain.report.level.last().unwrap();
            assert!(last.footprint_samples > 1);
            let fitted = bake_chain(
                &Params {
                    fit_lookup: Some(true),
                    ..params.clone()
                },
                &Environment::Cube(src.clone()),
                &NoProgress,
            )
            .unwrap();
            // Levels fitted to the lookup keep it too (crate::fit::Power::Kept, and the read
            // fit's constraint in crate::spatial).
            for (l, c) in fitted.mips.levels.iter().enumerate() {
                // A stock target's mirror level keeps the texels' power (it is the source
                // box-reduced), the others their read's.
                let e = if l == 0 { power(c) } else { level_power(c) } / p0 - 1.0;
                eprintln!("{target:?} fitted level {l} ({}²): power {e:+.2e}", c.size);
                assert!(
                    e.abs() < 1e-3,
                    "{target:?} fitted level {l}: power off by {e:.2e}"
                );
            }
            assert!(fitted.report.level[1].fit.is_some());
        }
    }

    /// The default bake (fitted levels, shared cuts, the runtime report) gives the same bits
    /// on one thread as on three.
    #[test]
    fn bits_do_not_depend_on_the_thread_count() {
        use ibl_core::envmap::Environment;
        use ibl_core::progress::NoProgress;
        let n = 32;
        let mut src = Cubemap::from_fn(n, |d| {
            let d = d.normalize();
            let sun = (d.dot(glam::Vec3::new(0.3, 0.8, 0.5).normalize()) - 0.98).max(0.0) * 2e4;
            [0.1 + d.y.max(0.0) + sun, 0.2 + sun, 0.3 + 0.5 * sun]
        });
        src.faces[2].data[100] = 50.0;
        let params = Params {
            size: 16,
            ..Default::default()
        };
        let bake = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| bake_chain(&params, &Environment::Cube(src.clone()), &NoProgress))
                .unwrap()
        };
        let (one, three) = (bake(1), bake(3));
        assert!(one.report.fit_lookup);
        for (a, b) in one.mips.levels.iter().zip(&three.mips.levels) {
            let bits = |c: &Cubemap| -> Vec<u32> {
                c.faces
                    .iter()
                    .flat_map(|f| f.data.iter().map(|v| v.to_bits()))
                    .collect()
            };
            assert_eq!(bits(a), bits(b), "level of {}²", a.size);
        }
        let (ra, rb) = (one.report.runtime.unwrap(), three.report.runtime.unwrap());
        assert_eq!(ra.mean_abs_rel, rb.mean_abs_rel);
    }

    #[test]
    fn the_tree_goes_before_the_fit_except_where_the_midpoints_need_it() {
        // The stock targets' fit runs without the cell tree (the report reads a table made
        // before it); the custom target's midpoints, after the fit, still convolve with it.
        let sky = Cubemap::from_fn(32, |d| {
            let d = d.normalize();
            let v = 0.2 + d.y.max(0.0) + 50.0 * (d.x - 0.95).max(0.0);
            [v, 0.9 * v, 0.7 * v]
        });
        let env = ibl_core::envmap::Environment::Cube(sky);
        for (target, let_go) in [
            (Target::Gltf, 1),
            (Target::Filament, 1),
            (Target::Custom, 0),
        ] {
            let before = ENGINES_LET_GO_BEFORE_FIT.with(|c| c.get());
            let params = Params {
                size: 16,
                target,
                ..Default::default()
            };
            let chain = bake_chain(&params, &env, &ibl_core::progress::NoProgress).unwrap();
            assert!(chain.report.runtime.is_some());
            let after = ENGINES_LET_GO_BEFORE_FIT.with(|c| c.get());
            assert_eq!(after - before, let_go, "{target:?}");
        }
    }

    #[test]
    fn footprint_factor_grows_only_where_texels_rival_the_lobe() {
        assert_eq!(footprint_factor(256, 0.2), 1);
        assert_eq!(footprint_factor(128, 0.25), 1);
        assert_eq!(footprint_factor(1, 1.0), 8);
        assert_eq!(footprint_factor(2, 0.9), 4);
        for n in [1, 2, 4, 8, 16] {
            let k = footprint_factor(n, 0.05);
            assert!(k.is_power_of_two() && n * k <= FOOTPRINT_MAX_SIZE);
        }
    }

    #[test]
    fn probes_are_distinct_and_inside() {
        for n in [1usize, 2, 3, 8, 64] {
            let p = probe_texels(n, 4);
            assert!(p.iter().all(|&(_, i, j)| i < n && j < n));
            assert_eq!(probe_texels(n, 4).len(), 6 * n.min(4) * n.min(4), "n {n}");
        }
    }
}
