//! Stage kinds of `ibl-material`: quaternion maps of normal maps (one file, or every material
//! folder under a folder) and tangent-plane rotation (TPR) maps.

use super::{input_error, standard_argv, Adapter, Arity, BakeError, Baked, ParamsObj};
use ibl_core::error::ErrorClass;
use ibl_core::progress::Progress;
use ibl_material::{batch, normal, quat_map as qm, tpr_map as tpr};
use std::path::{Path, PathBuf};

fn invalid(path: &Path, why: impl std::fmt::Display) -> BakeError {
    BakeError {
        message: format!("{}: {why}", path.display()),
        class: ErrorClass::InvalidInput,
    }
}

/// Normal maps under `root` (itself included), walked by `ibl_core::walk` (symlinked folders
/// followed, loops refused): (folder relative to `root`, normal map, output file name), sorted.
/// Several files matching `pattern` in one folder are an error unless the output name has
/// {stem} (one output per file).
fn material_folders(
    root: &Path,
    pattern: &str,
    output_name: &str,
) -> Result<Vec<(PathBuf, PathBuf, String)>, BakeError> {
    let mut found = Vec::new();
    let mut problem = None;
    let per_file = output_name.contains(batch::STEM);
    ibl_core::walk::folders(root, &mut |dir, listing| {
        let files = match listing {
            Ok(l) => &l.files,
            Err(e) => {
                problem.get_or_insert_with(|| invalid(dir, e));
                return;
            }
        };
        let normals = batch::inputs_in(files, pattern, output_name);
        if normals.len() > 1 && !per_file {
            problem.get_or_insert_with(|| {
                invalid(
                    dir,
                    format!(
                        "{} files match '{pattern}' (give each its own output with \
                         output_name: \"{{stem}}_quat.png\")",
                        normals.len()
                    ),
                )
            });
            return;
        }
        let rel = dir
            .strip_prefix(root)
            .unwrap_or(Path::new(""))
            .to_path_buf();
        for (n, out) in normals {
            found.push((rel.clone(), n.clone(), out));
        }
    })
    .map_err(|e| invalid(root, e))?;
    if let Some(p) = problem {
        return Err(p);
    }
    found.sort();
    Ok(found)
}

/// The conversions a quat-map stage does: (normal map, quaternion map). One input writes into
/// the stage folder; several inputs each into a sub-folder named after the input.
fn quat_jobs(
    p: &qm::Params,
    inputs: &[PathBuf],
    dir: &Path,
) -> Result<Vec<(PathBuf, PathBuf)>, BakeError> {
    let mut jobs = Vec::new();
    for input in inputs {
        let base = if inputs.len() == 1 {
            dir.to_path_buf()
        } else {
            let stem = if input.is_dir() {
                input.file_name()
            } else {
                input.file_stem()
            };
            dir.join(stem.ok_or_else(|| invalid(input, "has no name"))?)
        };
        if input.is_dir() {
            let found = material_folders(input, &p.input_name, &p.output_name)?;
            if found.is_empty() {
                return Err(invalid(
                    input,
                    format!(
                        "no folder under it holds a file matching '{}'",
                        p.input_name
                    ),
                ));
            }
            jobs.extend(
                found
                    .into_iter()
                    .map(|(rel, normal, out)| (normal, base.join(rel).join(out))),
            );
        } else {
            let out = batch::output_name(&p.output_name, input);
            jobs.push((input.clone(), base.join(out)));
        }
    }
    let mut outs: Vec<&PathBuf> = jobs.iter().map(|j| &j.1).collect();
    outs.sort();
    if let Some(w) = outs.windows(2).find(|w| w[0] == w[1]) {
        return Err(input_error(
            "quat-map",
            format!(
                "two inputs would write {} (read a folder of material folders instead)",
                w[0].display()
            ),
        ));
    }
    Ok(jobs)
}

/// `p` as the one-file CLI takes it: the batch-only fields at their defaults (they only name
/// files, they do not change the bytes).
fn single(p: &qm::Params) -> qm::Params {
    let d = qm::Params::default();
    qm::Params {
        input_name: d.input_name,
        output_name: d.output_name,
        force: d.force,
        ..p.clone()
    }
}

pub static QUAT_MAP: Adapter<qm::Params> = Adapter {
    name: "quat-map",
    summary: "normal maps to quaternion maps (a file, or every material folder under a folder)",
    command: &["quat-map"],
    package: "quat-map",
    library: "ibl-material",
    reads: Arity {
        min: 1,
        max: usize::MAX,
        what: "normal maps or folders of material folders holding normal.*",
    },
    out: super::in_dir,
    product: |_, out| out.to_path_buf(),
    outputs: |p, inputs, out| {
        Ok(quat_jobs(p, inputs, out)?
            .into_iter()
            .map(|j| j.1)
            .collect())
    },
    run: |p, inputs, out, progress: &dyn Progress| {
        let one = single(p);
        let mut baked = Baked::default();
        for (input, output) in quat_jobs(p, inputs, out)? {
            let normal = normal::load(&input)?;
            let b = qm::run(&one, &normal, &output, progress)?;
            baked.warnings.extend(b.stats.warnings(&input));
            if let Some(c) = b.check.filter(|c| !c.within_bounds()) {
                baked.warnings.push(format!(
                    "{}: outside the quantisation bound: {}",
                    output.display(),
                    c.summary()
                ));
            }
            baked.files.extend(b.files);
        }
        Ok(baked)
    },
    validate: |p| Ok(p.validate_output(Path::new(&p.output_name))?),
    example: || {
        super::example("(y_down: true, two_channel: true, min_length: 0.125, bits: 8, sanitize: true, check: true, input_name: \"nrm_*.png\", output_name: \"q.png\", force: true)")
    },
    argv: Some(|p, inputs, dir, rel| {
        let flags = single(p).cli_args()?;
        Ok(quat_jobs(p, inputs, dir)
            .map_err(|e| e.message)?
            .into_iter()
            .map(|(i, o)| standard_argv(&["quat-map"], &[rel(&i)], &rel(&o), flags.clone()))
            .collect())
    }),
    // One item per conversion (normal map -> quaternion map), so one changed normal map
    // re-bakes one output.
    items: Some(|p, inputs, dir| {
        Ok(quat_jobs(p, inputs, dir)?
            .into_iter()
            .map(|(normal, out)| super::Item {
                inputs: vec![normal],
                dir: out.parent().unwrap_or(dir).to_path_buf(),
            })
            .collect())
    }),
};

/// The TPR map's file: EXR when half floats are asked for, PNG otherwise.
fn tpr_out(p: &tpr::Params, dir: &Path) -> PathBuf {
    dir.join(if p.half { "tpr.exr" } else { "tpr.png" })
}

/// `p` with the maps the stage reads: with a preset or expression the one read is the
/// roughness map; otherwise the reads are the angle (direction) map, then the roughness map.
fn with_maps(p: &tpr::Params, inputs: &[PathBuf]) -> Result<tpr::Params, BakeError> {
    let mut q = p.clone();
    let generated = p.preset.is_some() || p.expr.is_some();
    match (generated, inputs) {
        (true, []) => {}
        (true, [r]) => q.roughness_map = Some(r.clone()),
        (false, [a]) => q.angle_map = Some(a.clone()),
        (false, [a, r]) => {
            q.angle_map = Some(a.clone());
            q.roughness_map = Some(r.clone());
        }
        (false, []) => {
            return Err(input_error(
                "tpr-map",
                "give a preset or an expr, or read an angle map",
            ))
        }
        _ => {
            return Err(input_error(
                "tpr-map",
                format!(
                    "reads {} maps; with a preset or expr it takes at most a roughness map",
                    inputs.len()
                ),
            ))
        }
    }
    Ok(q)
}

pub static TPR_MAP: Adapter<tpr::Params> = Adapter {
    name: "tpr-map",
    summary: "tangent-plane rotation map (direction field + directional roughness)",
    command: &["tpr-map"],
    package: "tpr-map",
    library: "ibl-material",
    reads: Arity {
        min: 0,
        max: 2,
        what:
            "an angle or direction map then a roughness map; with a preset or expr, a roughness map",
    },
    out: tpr_out,
    product: |_, out| out.to_path_buf(),
    outputs: |_, _, out| Ok(vec![out.to_path_buf()]),
    run: |p, inputs, out, progress: &dyn Progress| {
        let q = with_maps(p, inputs)?;
        q.compile()?;
        let maps = tpr::load_inputs(&q)?;
        let b = tpr::run(&q, &maps, out, progress)?;
        Ok(Baked {
            files: b.files,
            warnings: b.stats.warnings(),
        })
    },
    validate: |p| {
        if p.angle_map.is_some() || p.roughness_map.is_some() {
            return Err(input_error("tpr-map", "give the angle and roughness maps as the stage's reads, not as parameters (so their content is part of the cache key)"));
        }
        // Maps come from the reads: check the rest with a stand-in angle map when needed.
        let mut q = p.clone();
        if q.preset.is_none() && q.expr.is_none() {
            q.angle_map = Some(PathBuf::from("reads"));
        }
        q.validate_output(&tpr_out(p, Path::new(".")))?;
        q.compile()?;
        Ok(())
    },
    example: || {
        super::example("(size: \"16x8\", preset: \"spiral:0.25,0.5,3\", angle_map_kind: direction, roughness: \"0.5,0.25\", store_alpha: true, y_down: true, bits: 8)")
    },
    argv: Some(|p, inputs, dir, rel| {
        let inputs: Vec<PathBuf> = inputs.iter().map(|i| rel(i)).collect();
        let q = with_maps(p, &inputs).map_err(|e| e.message)?;
        Ok(vec![standard_argv(
            &["tpr-map"],
            &[],
            &rel(&tpr_out(p, dir)),
            q.cli_args()?,
        )])
    }),
    items: None,
};
