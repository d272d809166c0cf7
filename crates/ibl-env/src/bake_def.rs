//! The environment bakes as both front-ends see them: `equirect-to-cube` and `irradiance`, the
//! binaries and the pipeline's stage kinds, each this one [`Bake`].

use crate::{equirect_to_cube as e2c, irradiance as irr};
use ibl_bake::{Bake, BakeError, Baked, OutputKind, Reads, Writes};
use ibl_core::progress::Progress;
use std::path::{Path, PathBuf};

/// Environment to an area-filtered cube.
pub struct EquirectToCube;

/// The equirect-to-cube bake.
pub static EQUIRECT_TO_CUBE: EquirectToCube = EquirectToCube;

/// Where `--to-equirect` writes for `-o out`: the file, or `out/equirect.exr` for a folder.
fn equirect_path(out: &Path) -> PathBuf {
    if ibl_core::io::extension(out).is_empty() {
        out.join("equirect.exr")
    } else {
        out.to_path_buf()
    }
}

impl Bake for EquirectToCube {
    type Params = e2c::Params;

    const NAME: &'static str = "equirect-to-cube";
    const SUMMARY: &'static str = "environment to an area-filtered cubemap (faces or KTX2)";
    const ABOUT: &'static str =
        "Latitude-longitude HDR (or a cross, strip, face folder or KTX2, DDS or KTX1 cube) to an area-filtered \
         cubemap: DIR/px.exr … DIR/nz.exr, or DIR/cube.ktx2 with --layout ktx2.";
    const COMMAND: &'static [&'static str] = &["equirect-to-cube"];
    const LIBRARY: &'static str = "ibl-env";
    const READS: Reads = Reads {
        cli_input: Some(
            "Input environment: .exr/.hdr/.png equirect or cross, a folder of faces, or a .ktx2, .dds or .ktx cube",
        ),
        ..Reads::ENVIRONMENT
    };
    const WRITES: Writes = Writes::folder("Output folder (or file with --to-equirect)");
    fn output_kind(&self, p: &e2c::Params, out: &Path) -> OutputKind {
        // --to-equirect writes a file, or DIR/equirect.exr when -o has no extension.
        if p.to_equirect && out.extension().is_some() {
            OutputKind::File
        } else {
            OutputKind::Folder
        }
    }
    fn product(&self, p: &e2c::Params, out: &Path) -> PathBuf {
        if p.to_equirect {
            equirect_path(out)
        } else {
            ibl_bake::cube_product(out, p.encoding(), p.cube_name())
        }
    }
    fn outputs(
        &self,
        p: &e2c::Params,
        _: &[PathBuf],
        out: &Path,
    ) -> Result<Vec<PathBuf>, BakeError> {
        if p.to_equirect {
            Ok(vec![equirect_path(out)])
        } else {
            Ok(e2c::output_paths(p, out)?)
        }
    }
    fn stale_cube(&self, p: &e2c::Params) -> Option<&'static str> {
        (!p.to_equirect).then(|| p.cube_name())
    }
    fn validate(&self, p: &e2c::Params, _: &Path) -> Result<(), BakeError> {
        Ok(p.validate()?)
    }
    fn run(
        &self,
        p: &e2c::Params,
        inputs: &[PathBuf],
        out: &Path,
        progress: &dyn Progress,
    ) -> Result<Baked, BakeError> {
        // A large equirect whose format reads row by row is resampled as its rows arrive
        // (the same cube, any filter; --to-equirect reads it whole).
        let input = ibl_bake::one_input(Self::NAME, inputs)?;
        let env = if !p.to_equirect {
            ibl_core::envmap::open_environment_with(input, p.env_policy())?
        } else {
            ibl_core::envmap::load_environment_with(input, p.env_policy())?.into()
        };
        let mut warnings = env.warnings();
        let baked = e2c::run(p, env, out, progress)?;
        warnings.extend(baked.warnings);
        Ok(Baked {
            files: baked.files,
            warnings,
            info: vec![],
            details: serde_json::json!({
                "face_size": baked.face_size,
                "encoding": ibl_bake::encoding_details(&baked.encoding),
            }),
        })
    }
    fn example(&self) -> e2c::Params {
        ibl_bake::example("(size: 16, rotate: -12.5, layout: ktx2, half: true, zstd: 19, filter: bilinear, to_equirect: true, sanitize: true, negative: keep)")
    }
}

/// Diffuse irradiance: SH coefficients and the irradiance cube.
pub struct Irradiance;

/// The irradiance bake.
pub static IRRADIANCE: Irradiance = Irradiance;

impl Bake for Irradiance {
    type Params = irr::Params;

    const NAME: &'static str = "irradiance";
    const SUMMARY: &'static str = "SH projection, E/π coefficients and the irradiance cube";
    const ABOUT: &'static str =
        "Diffuse irradiance of an environment: DIR/sh.json (radiance projection and E/π \
         coefficients) and the irradiance cube DIR/px.exr … nz.exr (E/π).";
    const COMMAND: &'static [&'static str] = &["irradiance"];
    const LIBRARY: &'static str = "ibl-env";
    const READS: Reads = Reads::ENVIRONMENT;
    const WRITES: Writes = Writes::folder("Output folder");
    fn outputs(
        &self,
        p: &irr::Params,
        _: &[PathBuf],
        out: &Path,
    ) -> Result<Vec<PathBuf>, BakeError> {
        Ok(p.output_paths(out)?)
    }
    fn stale_cube(&self, p: &irr::Params) -> Option<&'static str> {
        Some(p.cube_name())
    }
    fn validate(&self, p: &irr::Params, _: &Path) -> Result<(), BakeError> {
        Ok(p.validate()?)
    }
    fn run(
        &self,
        p: &irr::Params,
        inputs: &[PathBuf],
        out: &Path,
        progress: &dyn Progress,
    ) -> Result<Baked, BakeError> {
        // A large equirect whose format reads row by row is opened, not read: its rows are
        // projected and reduced as they arrive.
        let input = ibl_core::envmap::open_environment_with(
            ibl_bake::one_input(Self::NAME, inputs)?,
            p.env_policy(),
        )?;
        let path = input.path().to_path_buf();
        let baked = irr::run(p, input, out, progress)?;
        let mut warnings = baked.input.warnings(&path);
        if baked.negative_clamped > 0 {
            warnings.push(format!(
                "SH ringing: clamped {} negative irradiance values to 0 (try --window or --exact)",
                baked.negative_clamped
            ));
        }
        warnings.extend(baked.warnings);
        Ok(Baked {
            files: baked.files,
            warnings,
            info: vec![],
            // Two different clamps, named apart: the input's negative texels (the input
            // policy's warning) and the output's negative irradiance (SH ringing).
            details: serde_json::json!({
                "coefficients": baked.coefficients,
                "input_negative_clamped": baked.input.report.negative_clamped,
                "input_negative": baked.input.negative,
                "ringing_negative_clamped": baked.negative_clamped,
                "encoding": ibl_bake::encoding_details(&baked.encoding),
            }),
        })
    }
    fn example(&self) -> irr::Params {
        ibl_bake::example("(bands: 5, size: 8, exact: true, exact_source_width: 64, window: true, sh_file: \"coeffs.ron\", rotate: 90, layout: dds, format: bc6h, bc6h_quality: fast, sanitize: true, negative: refuse)")
    }
}
