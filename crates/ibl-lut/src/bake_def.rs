//! The table bakes as both front-ends see them: `brdf-lut dfg | fresnel-tail | as-size-bias`,
//! `hv-lut`, and the pipeline's stage kinds of the same names, each one [`Bake`].

use crate::{as_size_bias as sb, dfg, fresnel_tail as tail, hv};
use ibl_bake::{Bake, BakeError, Baked, OutputKind, Reads, Writes};
use ibl_core::progress::Progress;
use std::path::{Path, PathBuf};

/// `-o` of the `brdf-lut` tables.
const TABLE_OUT: Writes = Writes::file(
    "Output file (.exr, .png, .json or .ron); for as-size-bias with --thesis-names, a folder",
);

/// A table's result as the front-ends take it (tables warn of nothing).
fn table(b: crate::Baked) -> Baked {
    Baked {
        files: b.files,
        details: b.details,
        ..Baked::default()
    }
}

/// A table's file in the stage folder, or the folder itself when the thesis's file names (which
/// carry n_u, n_v) are asked for.
fn table_out(dir: &Path, name: &str, thesis_names: bool) -> PathBuf {
    if thesis_names {
        dir.to_path_buf()
    } else {
        dir.join(name)
    }
}

/// `-o` names a folder with the thesis's file names, a file otherwise.
fn thesis_kind(thesis_names: bool) -> OutputKind {
    if thesis_names {
        OutputKind::Folder
    } else {
        OutputKind::File
    }
}

/// The [`Bake`] of a `brdf-lut` table that reads nothing and writes the one file `-o` names
/// (`<name>.exr` in a stage's folder).
macro_rules! one_file_table {
    ($(#[$doc:meta])* $ty:ident, $bake:ident, $module:ident, $name:literal, $summary:literal,
     $about:expr, $example:literal) => {
        $(#[$doc])*
        pub struct $ty;
        #[doc = concat!("The ", $name, " bake.")]
        pub static $bake: $ty = $ty;

        impl Bake for $ty {
            type Params = $module::Params;
            const NAME: &'static str = $name;
            const SUMMARY: &'static str = $summary;
            const ABOUT: &'static str = $about;
            const COMMAND: &'static [&'static str] = &["brdf-lut", $name];
            const LIBRARY: &'static str = "ibl-lut";
            const READS: Reads = Reads::NOTHING;
            const WRITES: Writes = TABLE_OUT;
            fn stage_out(&self, _: &$module::Params, dir: &Path) -> PathBuf {
                dir.join(concat!($name, ".exr"))
            }
            fn outputs(
                &self,
                _: &$module::Params,
                _: &[PathBuf],
                out: &Path,
            ) -> Result<Vec<PathBuf>, BakeError> {
                Ok(vec![out.to_path_buf()])
            }
            fn validate(&self, p: &$module::Params, _: &Path) -> Result<(), BakeError> {
                Ok(p.validate()?)
            }
            fn run(
                &self,
                p: &$module::Params,
                _: &[PathBuf],
                out: &Path,
                progress: &dyn Progress,
            ) -> Result<Baked, BakeError> {
                Ok(table($module::run(p, out, progress)?))
            }
            fn example(&self) -> $module::Params {
                ibl_bake::example($example)
            }
        }
    };
}

one_file_table!(
    /// The split-sum DFG table.
    Dfg,
    DFG,
    dfg,
    "dfg",
    "split-sum DFG table (GGX, height-correlated Smith)",
    "Split-sum DFG (Karis 2013): R = A, G = B, specular = F0·A + B; with --multiscatter a \
     third channel B(lue) = E_ss = A + B.\n\n\
     Axes: column s = n·v, row t = perceptual roughness r, both at texel centres \
     ((i + 0.5)/N), row 0 (r ≈ 0) stored first. BRDF: GGX with α = r², masking-shadowing by \
     the height-correlated Smith G2 (Heitz 2014), V = G2/(4 n·v n·l).",
    "(size: 16, samples: 64, multiscatter: true, half: true)"
);

one_file_table!(
    /// The Fresnel-tail table of the SH-exponential probes.
    FresnelTail,
    FRESNEL_TAIL,
    tail,
    "fresnel-tail",
    "Fresnel-tail table of the SH-exponential probes (Silvennoinen et al. 2025 eq. 15)",
    "Fresnel tail (Silvennoinen et al. 2025 eq. 15): s = n·v, t = roughness; \
     R = ∫f_DV(1−v·h)⁵(n·l)dl, G = R / ∫f_DV(n·l)dl.",
    "(size: 16, samples: 64, half: true)"
);

/// The Ashikhmin-Shirley size/bias table for one (n_u, n_v).
pub struct AsSizeBias;
/// The size/bias bake.
pub static AS_SIZE_BIAS: AsSizeBias = AsSizeBias;

impl Bake for AsSizeBias {
    type Params = sb::Params;
    const NAME: &'static str = "as-size-bias";
    const SUMMARY: &'static str = "Ashikhmin-Shirley size/bias table for one (n_u, n_v)";
    const ABOUT: &'static str =
        "Ashikhmin-Shirley size/bias (Marcolongo 2020 §4.3.3): s = (2/π)atan(|b·v|/|t·v|), \
         t = √(n·v); R = size, G = bias.";
    const COMMAND: &'static [&'static str] = &["brdf-lut", "as-size-bias"];
    const LIBRARY: &'static str = "ibl-lut";
    const READS: Reads = Reads::NOTHING;
    const WRITES: Writes = TABLE_OUT;
    fn output_kind(&self, p: &sb::Params, _: &Path) -> OutputKind {
        thesis_kind(p.thesis_names)
    }
    fn stage_out(&self, p: &sb::Params, dir: &Path) -> PathBuf {
        table_out(dir, "as-size-bias.exr", p.thesis_names)
    }
    // Invalid parameters never reach a run (the graph checks them); the folder is a fallback.
    fn product(&self, p: &sb::Params, out: &Path) -> PathBuf {
        p.validate()
            .and_then(|a| sb::output_path(p, &a, out))
            .unwrap_or_else(|_| out.to_path_buf())
    }
    fn outputs(
        &self,
        p: &sb::Params,
        _: &[PathBuf],
        out: &Path,
    ) -> Result<Vec<PathBuf>, BakeError> {
        Ok(vec![sb::output_path(p, &p.validate()?, out)?])
    }
    fn validate(&self, p: &sb::Params, _: &Path) -> Result<(), BakeError> {
        p.validate()?;
        Ok(())
    }
    fn run(
        &self,
        p: &sb::Params,
        _: &[PathBuf],
        out: &Path,
        progress: &dyn Progress,
    ) -> Result<Baked, BakeError> {
        Ok(table(sb::run(p, out, progress)?))
    }
    fn example(&self) -> sb::Params {
        ibl_bake::example("(nu: 100, nv: 10.5, size: 16, samples: 64, sampler: r#hv-lut, hv_size: 32, thesis_names: true, half: true)")
    }
}

/// The Ashikhmin-Shirley half-vector LUT (and its sidecar) for one (n_u, n_v).
pub struct HvLut;
/// The half-vector LUT bake.
pub static HV_LUT: HvLut = HvLut;

impl Bake for HvLut {
    type Params = hv::Params;
    const NAME: &'static str = "hv-lut";
    const SUMMARY: &'static str =
        "Ashikhmin-Shirley half-vector LUT (and its sidecar) for one (n_u, n_v)";
    const ABOUT: &'static str =
        "The Ashikhmin-Shirley half-vector LUT of Marcolongo 2020 §4.3.2: texel (ξ1, ξ2) at \
         texel centres → h; RGB = h·0.5+0.5 (tangent space), A = p_h(h)/p_h(n). A JSON sidecar \
         next to the image, named after it (-o hv.exr writes hv.json), records n_u, n_v and \
         p_h(n). EXR float by default, PNG 8/16-bit by extension.";
    const COMMAND: &'static [&'static str] = &["hv-lut"];
    const LIBRARY: &'static str = "ibl-lut";
    const READS: Reads = Reads::NOTHING;
    const WRITES: Writes =
        Writes::file("Output image (.exr or .png), or a folder with --thesis-names");
    fn output_kind(&self, p: &hv::Params, _: &Path) -> OutputKind {
        thesis_kind(p.thesis_names)
    }
    fn stage_out(&self, p: &hv::Params, dir: &Path) -> PathBuf {
        table_out(dir, "hv.exr", p.thesis_names)
    }
    fn product(&self, p: &hv::Params, out: &Path) -> PathBuf {
        p.validate()
            .and_then(|a| hv::output_paths(p, &a, out))
            .map(|o| o.0)
            .unwrap_or_else(|_| out.to_path_buf())
    }
    fn outputs(
        &self,
        p: &hv::Params,
        _: &[PathBuf],
        out: &Path,
    ) -> Result<Vec<PathBuf>, BakeError> {
        let (image, sidecar) = hv::output_paths(p, &p.validate()?, out)?;
        Ok(vec![image, sidecar])
    }
    fn validate(&self, p: &hv::Params, _: &Path) -> Result<(), BakeError> {
        p.validate()?;
        Ok(())
    }
    fn run(
        &self,
        p: &hv::Params,
        _: &[PathBuf],
        out: &Path,
        progress: &dyn Progress,
    ) -> Result<Baked, BakeError> {
        Ok(table(hv::run(p, out, progress)?))
    }
    fn example(&self) -> hv::Params {
        ibl_bake::example("(nu: 20000, nv: 70, size: 16, bits: 8, thesis_names: true, half: true)")
    }
}
