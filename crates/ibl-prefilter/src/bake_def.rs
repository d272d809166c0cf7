//! The prefilter bake as both front-ends see it: the `prefilter` binary and the pipeline's
//! `prefilter` stage kind are this one [`Bake`].

use crate::bake::{self as pf, Params};
use ibl_bake::{Bake, BakeError, Baked, Reads, Writes};
use ibl_core::progress::Progress;
use std::path::{Path, PathBuf};

/// The GGX prefiltered specular chain.
pub struct Prefilter;

/// The prefilter bake.
pub static PREFILTER: Prefilter = Prefilter;

impl Bake for Prefilter {
    type Params = Params;

    const NAME: &'static str = "prefilter";
    const SUMMARY: &'static str = "GGX prefiltered specular mip chain (split-sum radiance)";
    const ABOUT: &'static str =
        "GGX prefiltered specular mip chain (split-sum radiance term): level l of N holds the \
         environment convolved with the GGX lobe of roughness l/(N−1). Writes \
         DIR/m{l}_{face}.exr (or DIR/prefilter.ktx2 with --layout ktx2) and DIR/prefilter.json.";
    const COMMAND: &'static [&'static str] = &["prefilter"];
    const LIBRARY: &'static str = "ibl-prefilter";
    const READS: Reads = Reads::ENVIRONMENT;
    const WRITES: Writes = Writes {
        value_name: Some("DIR"),
        ..Writes::folder("Output folder")
    };
    fn product(&self, p: &Params, out: &Path) -> PathBuf {
        ibl_bake::cube_product(out, p.encoding(), p.chain_name())
    }
    fn outputs(&self, p: &Params, _: &[PathBuf], out: &Path) -> Result<Vec<PathBuf>, BakeError> {
        Ok(pf::output_paths(p, out)?)
    }
    fn stale_cube(&self, p: &Params) -> Option<&'static str> {
        Some(p.chain_name())
    }
    fn validate(&self, p: &Params, _: &Path) -> Result<(), BakeError> {
        Ok(p.validate()?)
    }
    fn run(
        &self,
        p: &Params,
        inputs: &[PathBuf],
        out: &Path,
        progress: &dyn Progress,
    ) -> Result<Baked, BakeError> {
        let env = ibl_bake::environment(Self::NAME, inputs, p.sanitize)?;
        let baked = pf::run(p, &env, out, progress)?;
        let chain = &baked.chain;
        // The input's warnings, then the chain's own (an upsampled source, a kernel wider
        // than a level's support); the report's note is information, not a warning.
        let mut warnings = env.warnings();
        warnings.extend(chain.warnings.iter().cloned());
        Ok(Baked {
            details: serde_json::json!({
                "report": chain.report,
                "resample_seconds": chain.resample_seconds,
                "source_seconds": chain.source_seconds,
                "estimate_seconds": chain.estimate_seconds,
                "runtime_seconds": chain.runtime_seconds,
                "level_seconds": chain.level_seconds,
                "encoding": ibl_bake::encoding_details(&baked.encoding),
            }),
            info: chain.report.note.iter().cloned().collect(),
            warnings,
            files: baked.files,
        })
    }
    fn example(&self) -> Params {
        ibl_bake::example("(size: 16, levels: 3, quality: high, method: fis, samples: 32, max_roughness: 0.25, layout: ktx1, format: b10g11r11, reference: true, rotate: 45.5, sanitize: true)")
    }
}
