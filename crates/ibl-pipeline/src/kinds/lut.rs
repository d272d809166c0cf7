//! Stage kinds of `ibl-lut`: the split-sum DFG table, the Fresnel-tail table, and the
//! Ashikhmin-Shirley size/bias table and half-vector LUT (one per (n_u, n_v)).

use super::{Adapter, Arity};
use ibl_core::progress::Progress;
use ibl_lut::{as_size_bias as sb, dfg, fresnel_tail as tail, hv};
use std::path::Path;

/// A table's output file in the stage folder, or the folder itself when the thesis's file
/// names (which carry n_u, n_v) are asked for.
fn table_out(dir: &Path, name: &str, thesis_names: bool) -> std::path::PathBuf {
    if thesis_names {
        dir.to_path_buf()
    } else {
        dir.join(name)
    }
}

fn baked(b: ibl_lut::Baked) -> super::Baked {
    super::Baked {
        files: b.files,
        warnings: vec![],
    }
}

pub static DFG: Adapter<dfg::Params> = Adapter {
    name: "dfg",
    summary: "split-sum DFG table (GGX, height-correlated Smith)",
    command: &["brdf-lut", "dfg"],
    package: "brdf-lut",
    library: "ibl-lut",
    reads: Arity::NONE,
    out: |_, dir| dir.join("dfg.exr"),
    product: |_, out| out.to_path_buf(),
    outputs: |_, _, out| Ok(vec![out.to_path_buf()]),
    run: |p, _, out, progress: &dyn Progress| Ok(baked(dfg::run(p, out, progress)?)),
    validate: |p| Ok(p.validate()?),
    example: || super::example("(size: 16, samples: 64, multiscatter: true, half: true)"),
    argv: None,
    items: None,
};

pub static FRESNEL_TAIL: Adapter<tail::Params> = Adapter {
    name: "fresnel-tail",
    summary: "Fresnel-tail table of the SH-exponential probes (Silvennoinen et al. 2025 eq. 15)",
    command: &["brdf-lut", "fresnel-tail"],
    package: "brdf-lut",
    library: "ibl-lut",
    reads: Arity::NONE,
    out: |_, dir| dir.join("fresnel-tail.exr"),
    product: |_, out| out.to_path_buf(),
    outputs: |_, _, out| Ok(vec![out.to_path_buf()]),
    run: |p, _, out, progress: &dyn Progress| Ok(baked(tail::run(p, out, progress)?)),
    validate: |p| Ok(p.validate()?),
    example: || super::example("(size: 16, samples: 64, half: true)"),
    argv: None,
    items: None,
};

pub static AS_SIZE_BIAS: Adapter<sb::Params> = Adapter {
    name: "as-size-bias",
    summary: "Ashikhmin-Shirley size/bias table for one (n_u, n_v)",
    command: &["brdf-lut", "as-size-bias"],
    package: "brdf-lut",
    library: "ibl-lut",
    reads: Arity::NONE,
    out: |p, dir| table_out(dir, "as-size-bias.exr", p.thesis_names),
    // Invalid parameters never reach a run (the graph checks them); the folder is a fallback.
    product: |p, out| {
        p.validate()
            .and_then(|a| sb::output_path(p, &a, out))
            .unwrap_or_else(|_| out.to_path_buf())
    },
    outputs: |p, _, out| Ok(vec![sb::output_path(p, &p.validate()?, out)?]),
    run: |p, _, out, progress: &dyn Progress| Ok(baked(sb::run(p, out, progress)?)),
    validate: |p| {
        p.validate()?;
        Ok(())
    },
    example: || {
        super::example("(nu: 100, nv: 10.5, size: 16, samples: 64, sampler: r#hv-lut, hv_size: 32, thesis_names: true, half: true)")
    },
    argv: None,
    items: None,
};

pub static HV_LUT: Adapter<hv::Params> = Adapter {
    name: "hv-lut",
    summary: "Ashikhmin-Shirley half-vector LUT (and its sidecar) for one (n_u, n_v)",
    command: &["hv-lut"],
    package: "hv-lut",
    library: "ibl-lut",
    reads: Arity::NONE,
    out: |p, dir| table_out(dir, "hv.exr", p.thesis_names),
    product: |p, out| {
        p.validate()
            .and_then(|a| hv::output_paths(p, &a, out))
            .map(|o| o.0)
            .unwrap_or_else(|_| out.to_path_buf())
    },
    outputs: |p, _, out| {
        let (image, sidecar) = hv::output_paths(p, &p.validate()?, out)?;
        Ok(vec![image, sidecar])
    },
    run: |p, _, out, progress: &dyn Progress| Ok(baked(hv::run(p, out, progress)?)),
    validate: |p| {
        p.validate()?;
        Ok(())
    },
    example: || {
        super::example("(nu: 20000, nv: 70, size: 16, bits: 8, thesis_names: true, half: true)")
    },
    argv: None,
    items: None,
};
