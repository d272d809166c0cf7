//! `shader-emulate`: the CPU side of conformance/render/shader-check.sh (input grids, the
//! emulation the Rust tests use, the GPU-against-CPU gate). A developer tool, not a bake.

use clap::{Parser, Subcommand};
use shader_emulate::{
    aniso_inputs, aniso_pyramid, as_inputs, compare, custom_inputs, custom_lookup_from_sidecar,
    emulate_aniso, emulate_as, emulate_custom, Grid, IsoSplitSum, Kind, Result,
};
use std::path::PathBuf;

/// Inputs for the emitted shaders, their CPU emulation, and the comparison with what a GPU
/// returned for the same inputs (conformance/render/shader-check.sh).
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Writes the input grid of a shader.
    Inputs {
        /// Which shader.
        kind: Kind,
        /// Custom: lattice directions (26 axis/edge/corner directions are added).
        #[arg(long, default_value_t = 512)]
        dirs: usize,
        /// Custom: roughness values k/(n−1).
        #[arg(long, default_value_t = 33)]
        roughness: usize,
        /// Aniso: normals (each with 3 views and 35 (r, η) materials).
        #[arg(long, default_value_t = 24)]
        normals: usize,
        /// aniso: the prefiltered chain (`prefilter --target custom`'s prefilter.ktx2) whose
        /// isotropic split sum is each case's isoSpecular input.
        #[arg(long)]
        iso_chain: Option<PathBuf>,
        /// aniso: that chain's prefilter.json (its custom lookup constants).
        #[arg(long)]
        iso_sidecar: Option<PathBuf>,
        /// as: the lobe's `hv-lut` table (.exr, float), its sidecar beside it (.json).
        #[arg(long)]
        lut: Option<PathBuf>,
        /// Output JSON.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Evaluates the CPU emulation at every input case.
    Emulate {
        /// Input grid (from `inputs`).
        inputs: PathBuf,
        /// Custom: the chain (prefilter.ktx2). Aniso and as: the environment cube (its level 0
        /// is read, and box-mipped down to 1×1 as generateMipmap does).
        #[arg(long)]
        chain: PathBuf,
        /// Custom: the bake's prefilter.json (its "custom_lookup").
        #[arg(long)]
        sidecar: Option<PathBuf>,
        /// Custom, diagnosis: read through a GPU model whose cube-corner texel is the average
        /// of the three (the GL specification's recommendation) instead of the emulation.
        #[arg(long)]
        gl_corners: bool,
        /// Diagnosis: move every input by this relative amount first (seeded, uniform), to
        /// measure how much the emulation itself moves under float-rounding-sized changes.
        #[arg(long)]
        jitter: Option<f32>,
        /// Output JSON.
        #[arg(short, long)]
        output: PathBuf,
    },
    /// Compares the GPU's outputs with the emulation's; exit 1 above the gates.
    Compare {
        /// The emulation's outputs.
        cpu: PathBuf,
        /// The GPU's outputs (conformance/render/shader-check.mjs).
        gpu: PathBuf,
        /// Gate on the mean relative difference over the cases that touch no cube-corner
        /// texel.
        #[arg(long)]
        max_mean: Option<f64>,
        /// Gate on its 99th percentile.
        #[arg(long)]
        max_p99: Option<f64>,
        /// Gate on the mean over the cases that touch a cube-corner texel (exact cube-corner
        /// directions, a tie of the face choice, are reported only).
        #[arg(long)]
        corner_max_mean: Option<f64>,
        /// Gate on their 99th percentile.
        #[arg(long)]
        corner_max_p99: Option<f64>,
        /// Also write the statistics as JSON here.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Label of the printed line.
        #[arg(long, default_value = "shader")]
        label: String,
        /// The emulation's inputs, to print the worst case's.
        #[arg(long)]
        inputs: Option<PathBuf>,
    },
}

fn run(cli: Cli) -> Result<bool> {
    match cli.cmd {
        Cmd::Inputs {
            kind,
            dirs,
            roughness,
            normals,
            iso_chain,
            iso_sidecar,
            lut,
            output,
        } => {
            let g = match kind {
                Kind::Custom => custom_inputs(dirs, roughness),
                Kind::As => {
                    let Some(lut) = lut else {
                        return Err(shader_emulate::Error::Invalid {
                            path: output.display().to_string(),
                            msg: "as inputs need --lut hv.exr (an hv-lut table)".into(),
                        });
                    };
                    as_inputs(normals, &lut)?
                }
                Kind::Aniso => {
                    let (Some(chain), Some(sc)) = (iso_chain, iso_sidecar) else {
                        return Err(shader_emulate::Error::Invalid {
                            path: output.display().to_string(),
                            msg: "aniso inputs need --iso-chain prefilter.ktx2 and --iso-sidecar prefilter.json (the isotropic split sum)".into(),
                        });
                    };
                    let mips = ibl_core::envmap::read_cube_chain(&chain)?;
                    let lookup = custom_lookup_from_sidecar(&sc, &mips)?;
                    let alpha = shader_emulate::chain_alpha(&chain)?;
                    let chain = ibl_prefilter::custom::CustomChain::new(&mips, &alpha);
                    aniso_inputs(
                        normals,
                        &IsoSplitSum {
                            chain: &chain,
                            lookup: &lookup,
                            dfg: ibl_shexp::dfg::Dfg::standard(),
                        },
                    )
                }
            };
            g.write(&output)?;
            Ok(true)
        }
        Cmd::Emulate {
            inputs,
            chain,
            sidecar,
            gl_corners,
            jitter,
            output,
        } => {
            let mut inp = Grid::read(&inputs)?;
            if let Some(eps) = jitter {
                inp = shader_emulate::jitter(&inp, eps, 1);
            }
            if inp.role != shader_emulate::Role::Inputs {
                return Err(shader_emulate::Error::Invalid {
                    path: inputs.display().to_string(),
                    msg: "holds outputs, not inputs".into(),
                });
            }
            let mips = ibl_core::envmap::read_cube_chain(&chain)?;
            let out = match inp.kind {
                Kind::Custom => {
                    let Some(sc) = sidecar else {
                        return Err(shader_emulate::Error::Invalid {
                            path: chain.display().to_string(),
                            msg: "the custom lookup needs --sidecar prefilter.json".into(),
                        });
                    };
                    let lk = custom_lookup_from_sidecar(&sc, &mips)?;
                    let alpha = shader_emulate::chain_alpha(&chain)?;
                    if gl_corners {
                        shader_emulate::emulate_custom_gl_corners(&inp, &mips, &alpha, &lk)
                    } else {
                        let chain = ibl_prefilter::custom::CustomChain::new(&mips, &alpha);
                        emulate_custom(&inp, &chain, &lk)
                    }
                }
                Kind::Aniso => emulate_aniso(
                    &inp,
                    &aniso_pyramid(mips.levels.into_iter().next().unwrap()),
                ),
                Kind::As => emulate_as(
                    &inp,
                    &aniso_pyramid(mips.levels.into_iter().next().unwrap()),
                )?,
            };
            out.write(&output)?;
            Ok(true)
        }
        Cmd::Compare {
            cpu,
            gpu,
            max_mean,
            max_p99,
            corner_max_mean,
            corner_max_p99,
            label,
            inputs,
            json,
        } => {
            let c = Grid::read(&cpu)?;
            let g = Grid::read(&gpu)?;
            let inp = match &inputs {
                Some(p) => Some(Grid::read(p)?),
                None => None,
            };
            let cmp = compare(&c, &g, &gpu)?;
            let mut pass = true;
            for (group, st, gm, gp) in [
                ("exact", &cmp.exact, max_mean, max_p99),
                ("corner", &cmp.corner, corner_max_mean, corner_max_p99),
                ("tie (reported)", &cmp.tie, None, None),
            ] {
                let Some(s) = st else { continue };
                let ok = gm.is_none_or(|m| s.mean <= m) && gp.is_none_or(|m| s.p99 <= m);
                pass &= ok;
                let gate = |m: Option<f64>| m.map_or("-".into(), |m| format!("{m:.1e}"));
                println!(
                    "{label} {group}: {} cases, relative difference mean {:.2e} p99 {:.2e} max {:.2e} (gates mean {} p99 {}: {}); worst case {}: cpu {:?} gpu {:?}{}",
                    s.count,
                    s.mean,
                    s.p99,
                    s.max,
                    gate(gm),
                    gate(gp),
                    if ok { "ok" } else { "FAIL" },
                    s.worst,
                    &c.case(s.worst)[..3],
                    &g.case(s.worst)[..3],
                    inp.as_ref().map_or(String::new(), |i| format!(" inputs {:?}", i.case(s.worst))),
                );
            }
            if let Some(s) = &cmp.pass_through {
                // The emitted function returns its isoSpecular argument untouched at η = 0.
                let ok = cmp.pass_through_identical == s.count;
                pass &= ok;
                println!(
                    "{label} pass-through (eta = 0, isoSpecular returned): {} cases, {} bit-identical, relative difference max {:.2e} ({}); worst case {}: cpu {:?} gpu {:?}",
                    s.count,
                    cmp.pass_through_identical,
                    s.max,
                    if ok { "ok" } else { "FAIL" },
                    s.worst,
                    &c.case(s.worst)[..3],
                    &g.case(s.worst)[..3],
                );
            }
            if let Some(p) = json {
                let text = serde_json::to_string_pretty(&cmp).expect("serialisable");
                std::fs::write(&p, text).map_err(|e| shader_emulate::Error::Invalid {
                    path: p.display().to_string(),
                    msg: e.to_string(),
                })?;
            }
            Ok(pass)
        }
    }
}

fn main() {
    let cli = Cli::parse();
    match run(cli) {
        Ok(true) => {}
        Ok(false) => std::process::exit(1),
        Err(e) => {
            eprintln!("shader-emulate: error: {e}");
            std::process::exit(2);
        }
    }
}
