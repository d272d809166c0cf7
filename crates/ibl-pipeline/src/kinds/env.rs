//! Stage kinds of `ibl-env`: `equirect-to-cube` and `irradiance`.

use super::{input_error, Adapter, Arity, BakeError, Baked};
use ibl_core::envmap::load_environment;
use ibl_core::output::Encoding;
use ibl_core::progress::Progress;
use ibl_env::equirect_to_cube as e2c;
use ibl_env::irradiance as irr;
use std::path::{Path, PathBuf};

/// An environment input: an equirect image, a cross or strip, a folder of faces, a KTX2 cube.
pub(super) const ENVIRONMENT: &str = "an environment: equirect, cross, face folder or KTX2 cube";

pub(super) fn one_input<'a>(kind: &str, inputs: &'a [PathBuf]) -> Result<&'a Path, BakeError> {
    match inputs {
        [p] => Ok(p),
        _ => Err(input_error(
            kind,
            format!("expected one input, got {}", inputs.len()),
        )),
    }
}

/// Where a cube (or chain) written for `out` is read from by the next stage (parameters are
/// validated before any product is asked for; an invalid encoding reads as the default).
pub(super) fn cube_product<E>(out: &Path, enc: Result<Encoding, E>, name: &str) -> PathBuf {
    enc.unwrap_or_default()
        .layout
        .container_path(out, name)
        .unwrap_or_else(|| out.to_path_buf())
}

pub static EQUIRECT_TO_CUBE: Adapter<e2c::Params> = Adapter {
    name: "equirect-to-cube",
    summary: "environment to an area-filtered cubemap (faces or KTX2)",
    command: &["equirect-to-cube"],
    package: "equirect-to-cube",
    library: "ibl-env",
    reads: Arity::one(ENVIRONMENT),
    out: super::in_dir,
    product: |p, out| {
        if p.to_equirect {
            out.join("equirect.exr")
        } else {
            cube_product(out, p.encoding(), p.cube_name())
        }
    },
    outputs: |p, _, out| {
        if p.to_equirect {
            Ok(vec![out.join("equirect.exr")])
        } else {
            Ok(e2c::output_paths(p, out)?)
        }
    },
    run: |p, inputs, out, progress: &dyn Progress| {
        let env = load_environment(one_input("equirect-to-cube", inputs)?, p.sanitize)?;
        let baked = e2c::run(p, &env, out, progress)?;
        let mut warnings = env.warnings();
        warnings.extend(baked.warnings);
        Ok(Baked {
            files: baked.files,
            warnings,
        })
    },
    validate: |p| Ok(p.validate()?),
    argv: None,
    items: None,
    example: || {
        super::example("(size: 16, rotate: -12.5, layout: ktx2, half: true, zstd: 19, filter: bilinear, to_equirect: true, sanitize: true)")
    },
};

pub static IRRADIANCE: Adapter<irr::Params> = Adapter {
    name: "irradiance",
    summary: "SH projection, E/π coefficients and the irradiance cube",
    command: &["irradiance"],
    package: "irradiance",
    library: "ibl-env",
    reads: Arity::one(ENVIRONMENT),
    out: super::in_dir,
    product: |_, out| out.to_path_buf(),
    outputs: |p, _, out| Ok(p.output_paths(out)?),
    run: |p, inputs, out, progress: &dyn Progress| {
        let env = load_environment(one_input("irradiance", inputs)?, p.sanitize)?;
        let baked = irr::run(p, &env, out, progress)?;
        let mut warnings = env.warnings();
        if baked.negative_clamped > 0 {
            warnings.push(format!(
                "SH ringing: clamped {} negative irradiance values to 0 (try window or exact)",
                baked.negative_clamped
            ));
        }
        warnings.extend(baked.warnings);
        Ok(Baked {
            files: baked.files,
            warnings,
        })
    },
    validate: |p| Ok(p.validate()?),
    argv: None,
    items: None,
    example: || {
        super::example("(bands: 5, size: 8, exact: true, exact_source_width: 64, window: true, sh_file: \"coeffs.ron\", rotate: 90, layout: dds, format: bc6h, bc6h_quality: fast, sanitize: true)")
    },
};
