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
        let (tr, cr) = (std::time::Instant::now(), pf::process_cpu_seconds());
        // A large equirect whose format reads row by row is opened, not read: its rows
        // stream into the resample (its read time is then inside the resample's).
        let env = ibl_bake::open_environment(Self::NAME, inputs, p.sanitize)?;
        let read_seconds = tr.elapsed().as_secs_f64();
        let read_cpu = pf::process_cpu_seconds() - cr;
        // The input's warnings first (run consumes the input to free its image early),
        // then the chain's own (an upsampled source, a kernel wider than a level's support);
        // the report's note is information, not a warning.
        let mut warnings = env.warnings();
        let baked = pf::run(p, env, out, progress)?;
        let chain = &baked.chain;
        let mut stages_cpu = serde_json::Map::new();
        stages_cpu.insert("read".into(), read_cpu.into());
        for (k, v) in &chain.cpu_seconds {
            stages_cpu.insert(k.clone(), (*v).into());
        }
        stages_cpu.insert("encode".into(), baked.encode_cpu_seconds.into());
        let mut peaks = serde_json::Map::new();
        for (k, v) in &chain.peak_mib {
            peaks.insert(k.clone(), (*v).into());
        }
        peaks.insert("encode".into(), pf::peak_rss_mib().into());
        warnings.extend(chain.warnings.iter().cloned());
        Ok(Baked {
            details: serde_json::json!({
                "report": chain.report,
                "resample_seconds": chain.resample_seconds,
                "source_seconds": chain.source_seconds,
                "estimate_seconds": chain.estimate_seconds,
                "runtime_seconds": chain.runtime_seconds,
                "level_seconds": chain.level_seconds,
                // Every stage's seconds (what the bench charts; write = the summary's seconds
                // minus their sum, as the files are written after this).
                "stages": {
                    "read": read_seconds,
                    "resample": chain.resample_seconds,
                    "source_tree": chain.tree_seconds,
                    "source_texels_and_level0": chain.source_seconds - chain.tree_seconds,
                    "levels": chain.level_seconds,
                    "level_work": chain.level_work,
                    "estimate": chain.estimate_seconds,
                    "fit": chain.fit_seconds,
                    "fit_kernel": chain.fit_kernel_seconds,
                    "runtime": chain.runtime_seconds,
                    "encode": baked.encode_seconds,
                },
                // The same stages in CPU seconds of every thread (the shared machine's wall
                // clock is noisy); write is measured by the bench around the whole process.
                "stages_cpu": stages_cpu,
                // Peak resident MiB of the process at the end of each stage.
                "stages_peak_mib": peaks,
                // What run() reserved against the memory budget for the bake's working set.
                "working_set_estimate_mib":
                    pf::working_set_bytes(p.size, chain.report.source_size) as f64 / (1u64 << 20) as f64,
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
