//! The material bakes as both front-ends see them: `quat-map` and `tpr-map`, the binaries and
//! the pipeline's stage kinds, each this one [`Bake`]. A quat-map stage converts one normal
//! map, or every material folder under a folder; a tpr-map stage reads its maps as sources.

use crate::{batch, normal, quat_map as qm, tpr_map as tpr};
use ibl_bake::{Arity, Bake, BakeError, Baked, Job, Reads, Writes};
use ibl_core::error::ErrorClass;
use ibl_core::progress::Progress;
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

/// Normal maps to quaternion maps.
pub struct QuatMap;

/// The quat-map bake.
pub static QUAT_MAP: QuatMap = QuatMap;

impl Bake for QuatMap {
    type Params = qm::Params;

    const NAME: &'static str = "quat-map";
    const SUMMARY: &'static str =
        "normal maps to quaternion maps (a file, or every material folder under a folder)";
    const ABOUT: &'static str =
        "Normal map → quaternion map (Marcolongo 2020 §3.4): per texel the unit quaternion \
         q = a + b·i + c·j (no k part) of the shortest rotation from +z to the normal, stored as \
         RGB = (a, b, c)·0.5 + 0.5 (16-bit PNG by default, or EXR).\n\n\
         Convention: q rotates a vector v as q̄·v·q (conjugate first), so the normal is \
         n' = q̄·(0, 0, 1)·q. A shader decodes (a, b, c) = 2·RGB − 1 and rebuilds the whole \
         perturbed frame: t' = (a²+b²−c², 2bc, 2ac), b' = (2bc, a²−b²+c², −2ab), \
         n' = (−2ac, 2ab, a²−b²−c²). A quaternion library rotates as q·v·q̄ instead (glam's \
         Quat::mul_vec3, three.js applyQuaternion, Eigen): give it the conjugate, e.g. glam \
         Quat::from_xyzw(−b, −c, 0, a); passing (b, c, 0, a) unchanged mirrors the normals (x and \
         y negated).\n\n\
         With --batch DIR every folder under DIR holding normal.* gets quaternion.png beside it; \
         outputs that are newer than their input and made with the same options are skipped \
         (recorded in a hidden sidecar .quaternion.png.opts).";
    const COMMAND: &'static [&'static str] = &["quat-map"];
    const LIBRARY: &'static str = "ibl-material";
    const READS: Reads = Reads {
        arity: Arity {
            min: 1,
            max: usize::MAX,
            what: "normal maps or folders of material folders holding normal.*",
        },
        cli_input: Some("Input normal map (.png 8/16-bit, .jpg, .exr), read as linear data"),
    };
    const WRITES: Writes = Writes::file("Output quaternion map (.png or .exr)");
    const ITEMIZED: bool = true;
    fn outputs(
        &self,
        _: &qm::Params,
        _: &[PathBuf],
        out: &Path,
    ) -> Result<Vec<PathBuf>, BakeError> {
        Ok(vec![out.to_path_buf()])
    }
    fn validate(&self, p: &qm::Params, out: &Path) -> Result<(), BakeError> {
        if !p.batch_fields_are_default() {
            return Err(ibl_core::Error::param(
                "--input-name, --output-name and --force apply to --batch only",
            )
            .into());
        }
        Ok(p.validate_output(out)?)
    }
    fn validate_stage(&self, p: &qm::Params) -> Result<(), BakeError> {
        Ok(p.validate_output(Path::new(&p.output_name))?)
    }
    fn run(
        &self,
        p: &qm::Params,
        inputs: &[PathBuf],
        out: &Path,
        progress: &dyn Progress,
    ) -> Result<Baked, BakeError> {
        let input = ibl_bake::one_input(Self::NAME, inputs)?;
        let normal = normal::load(input)?;
        let b = qm::run(p, &normal, out, progress)?;
        let mut baked = Baked {
            warnings: b.stats.warnings(input),
            details: serde_json::json!({ "stats": b.stats, "check": b.check }),
            files: b.files,
            info: vec![],
        };
        if let Some(check) = &b.check {
            if check.within_bounds() {
                baked.info.push(check.summary());
            } else {
                baked.warnings.push(format!(
                    "{}: outside the quantisation bound: {}",
                    out.display(),
                    check.summary()
                ));
            }
        }
        Ok(baked)
    }
    fn example(&self) -> qm::Params {
        ibl_bake::example("(y_down: true, two_channel: true, min_length: 0.125, bits: 8, sanitize: true, check: true, input_name: \"nrm_*.png\", output_name: \"q.png\", force: true)")
    }
    /// One conversion per normal map: one input writes into the stage folder; several inputs
    /// each into a sub-folder named after the input; a folder input, every material folder
    /// under it.
    fn jobs(
        &self,
        p: &qm::Params,
        inputs: &[PathBuf],
        dir: &Path,
    ) -> Result<Vec<Job<qm::Params>>, BakeError> {
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
            return Err(BakeError::input(
                Self::NAME,
                format!(
                    "two inputs would write {} (read a folder of material folders instead)",
                    w[0].display()
                ),
            ));
        }
        let one = single(p);
        Ok(jobs
            .into_iter()
            .map(|(input, out)| Job {
                params: one.clone(),
                inputs: vec![input],
                out,
            })
            .collect())
    }
}

/// The TPR map's file in a stage folder: EXR when half floats are asked for, PNG otherwise.
fn tpr_out(p: &tpr::Params, dir: &Path) -> PathBuf {
    dir.join(if p.half { "tpr.exr" } else { "tpr.png" })
}

/// `p` with the maps a stage reads: with a preset or expression the one read is the roughness
/// map; otherwise the reads are the angle (direction) map, then the roughness map.
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
            return Err(BakeError::input(
                "tpr-map",
                "give a preset or an expr, or read an angle map",
            ))
        }
        _ => {
            return Err(BakeError::input(
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

/// Tangent-plane rotation maps.
pub struct TprMap;

/// The tpr-map bake.
pub static TPR_MAP: TprMap = TprMap;

impl Bake for TprMap {
    type Params = tpr::Params;

    const NAME: &'static str = "tpr-map";
    const SUMMARY: &'static str =
        "tangent-plane rotation map (direction field + directional roughness)";
    const ABOUT: &'static str =
        "Tangent-plane rotation map (Marcolongo 2020 §3.5): RGBA with RG = the rotated tangent \
         (x, y)·0.5 + 0.5 in tangent space (b = n × t) and BA = perceptual roughness along t and \
         b (α = r²; --store-alpha stores α). Directions come from a preset, an angle/direction \
         map or expressions in u, v (texel centres (i+0.5)/W, (j+0.5)/H, row 0 first); \
         zero-length or non-finite ones become +x and are counted.\n\n\
         Examples: tpr-map -o pan.png --size 1024 --preset radial:0.5,0.5 --roughness 0.2,0.6; \
         tpr-map -o wave.png --size 512 --expr \"x = cos(pi*v); y = sin(pi*v)\".";
    const COMMAND: &'static [&'static str] = &["tpr-map"];
    const LIBRARY: &'static str = "ibl-material";
    const READS: Reads = Reads {
        arity: Arity {
            min: 0,
            max: 2,
            what: "an angle or direction map then a roughness map; with a preset or expr, a roughness map",
        },
        // The command line names its maps with --angle-map and --roughness-map.
        cli_input: None,
    };
    const WRITES: Writes = Writes::file("Output map (.png or .exr)");
    fn stage_out(&self, p: &tpr::Params, dir: &Path) -> PathBuf {
        tpr_out(p, dir)
    }
    fn outputs(
        &self,
        _: &tpr::Params,
        _: &[PathBuf],
        out: &Path,
    ) -> Result<Vec<PathBuf>, BakeError> {
        Ok(vec![out.to_path_buf()])
    }
    fn validate(&self, p: &tpr::Params, out: &Path) -> Result<(), BakeError> {
        p.validate_output(out)?;
        p.compile()?;
        Ok(())
    }
    fn validate_stage(&self, p: &tpr::Params) -> Result<(), BakeError> {
        if p.angle_map.is_some() || p.roughness_map.is_some() {
            return Err(BakeError::input("tpr-map", "give the angle and roughness maps as the stage's reads, not as parameters (so their content is part of the cache key)"));
        }
        // Maps come from the reads: check the rest with a stand-in angle map when needed.
        let mut q = p.clone();
        if q.preset.is_none() && q.expr.is_none() {
            q.angle_map = Some(PathBuf::from("reads"));
        }
        self.validate(&q, &tpr_out(p, Path::new(".")))
    }
    fn run(
        &self,
        p: &tpr::Params,
        _: &[PathBuf],
        out: &Path,
        progress: &dyn Progress,
    ) -> Result<Baked, BakeError> {
        p.compile()?;
        let maps = tpr::load_inputs(p)?;
        let b = tpr::run(p, &maps, out, progress)?;
        Ok(Baked {
            warnings: b.stats.warnings(),
            details: serde_json::json!({ "stats": b.stats }),
            files: b.files,
            info: vec![],
        })
    }
    fn example(&self) -> tpr::Params {
        ibl_bake::example("(size: \"16x8\", preset: \"spiral:0.25,0.5,3\", angle_map_kind: direction, roughness: \"0.5,0.25\", store_alpha: true, y_down: true, bits: 8)")
    }
    /// One run, its maps the stage's reads.
    fn jobs(
        &self,
        p: &tpr::Params,
        inputs: &[PathBuf],
        dir: &Path,
    ) -> Result<Vec<Job<tpr::Params>>, BakeError> {
        Ok(vec![Job {
            params: with_maps(p, inputs)?,
            inputs: vec![],
            out: tpr_out(p, dir),
        }])
    }
    /// The maps are flags of the command line, named as it names them.
    fn cli_jobs(
        &self,
        p: &tpr::Params,
        inputs: &[PathBuf],
        dir: &Path,
        rel: &dyn Fn(&Path) -> PathBuf,
    ) -> Result<Vec<Job<tpr::Params>>, BakeError> {
        let inputs: Vec<PathBuf> = inputs.iter().map(|i| rel(i)).collect();
        Ok(vec![Job {
            params: with_maps(p, &inputs)?,
            inputs: vec![],
            out: rel(&tpr_out(p, dir)),
        }])
    }
}
