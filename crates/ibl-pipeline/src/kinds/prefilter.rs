//! Stage kind of `ibl-prefilter`: the GGX prefiltered specular chain.

use super::env::{cube_product, one_input, ENVIRONMENT};
use super::{Adapter, Arity, Baked};
use ibl_core::envmap::load_environment;
use ibl_core::progress::Progress;
use ibl_prefilter::bake::{self as pf, Params};

pub static PREFILTER: Adapter<Params> = Adapter {
    name: "prefilter",
    summary: "GGX prefiltered specular mip chain (split-sum radiance)",
    command: &["prefilter"],
    package: "prefilter",
    library: "ibl-prefilter",
    reads: Arity::one(ENVIRONMENT),
    out: super::in_dir,
    product: |p, out| cube_product(out, p.encoding(), p.chain_name()),
    outputs: |p, _, out| Ok(pf::output_paths(p, out)?),
    run: |p, inputs, out, progress: &dyn Progress| {
        let env = load_environment(one_input("prefilter", inputs)?, p.sanitize)?;
        let baked = pf::run(p, &env, out, progress)?;
        // Everything the CLI tells the user: the input's, the chain's own warnings (an
        // upsampled source, a kernel wider than a level's support), and the report's note.
        let mut warnings = env.warnings();
        warnings.extend(baked.chain.warnings.iter().cloned());
        warnings.extend(baked.chain.report.note.clone());
        warnings.extend(baked.chain.warnings.iter().cloned());
        Ok(Baked {
            files: baked.files,
            warnings,
        })
    },
    validate: |p| Ok(p.validate()?),
    argv: None,
    items: None,
    example: || {
        super::example("(size: 16, levels: 3, quality: high, method: fis, samples: 32, max_roughness: 0.25, layout: ktx1, format: b10g11r11, reference: true, rotate: 45.5, sanitize: true)")
    },
};
