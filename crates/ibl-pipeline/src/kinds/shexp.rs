//! Stage kind of `ibl-shexp`: the SH-exponential glossy fit of an environment.

use super::env::{one_input, ENVIRONMENT};
use super::{Adapter, Arity, Baked};
use ibl_core::envmap::load_environment;
use ibl_core::progress::Progress;
use ibl_shexp::fit::{self, Params};

pub static SHEXP_FIT: Adapter<Params> = Adapter {
    name: "shexp-fit",
    summary: "SH-exponential glossy probe fit (Silvennoinen et al. 2025)",
    command: &["shexp-fit"],
    package: "shexp-fit",
    library: "ibl-shexp",
    reads: Arity::one(ENVIRONMENT),
    out: |_, dir| dir.join("shexp.json"),
    product: |_, out| out.to_path_buf(),
    outputs: |p, _, out| {
        let mut files = vec![out.to_path_buf()];
        if p.emit_shader {
            files.push(out.with_extension("glsl"));
            files.push(out.with_extension("hlsl"));
        }
        Ok(files)
    },
    run: |p, inputs, out, progress: &dyn Progress| {
        let env = load_environment(one_input("shexp-fit", inputs)?, p.sanitize)?;
        let baked = fit::run(p, &env, out, progress)?;
        Ok(Baked {
            files: baked.files,
            warnings: env.warnings(),
        })
    },
    validate: |p| Ok(p.validate()?),
    example: || {
        super::example("(p_order: 3, q_order: 1, views: 8, normals: 8, alphas: [0.25, 1.0], alpha_knots: [0.25, 1.0], samples: 64, size: 16, floor: 0.01, weight_power: 2, cosine_weight: true, lod_bias: 0.5, estimator: exact, exact_size: 8, emit_shader: true, sanitize: true)")
    },
    argv: None,
    items: None,
};
