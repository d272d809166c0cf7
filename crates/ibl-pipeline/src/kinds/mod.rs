//! The stage-kind registry: every bake ([`ibl_bake::Bake`], defined once in its library and
//! also the source of its command line) is a stage kind through one blanket adapter, which
//! erases its `Params` type and runs it in-process; the executor writes the encoded files
//! atomically.
//!
//! Adding a bake is one line in [`all`].

pub mod cli;

pub use ibl_bake::{ron_options, Arity, BakeError, BakeParams};
use ibl_bake::{Bake, Job};
use ibl_core::progress::Progress;
use std::any::Any;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Every stage kind this build of the runner knows, in the order `bake kinds` lists them.
pub fn all() -> Vec<&'static dyn Kind> {
    #[allow(unused_mut)] // without the optional bakes nothing is pushed
    let mut kinds: Vec<&'static dyn Kind> = vec![&ibl_env::EQUIRECT_TO_CUBE, &ibl_env::IRRADIANCE];
    #[cfg(feature = "prefilter")]
    kinds.push(&ibl_prefilter::PREFILTER);
    #[cfg(feature = "shexp")]
    kinds.push(&ibl_shexp::SHEXP_FIT);
    #[cfg(feature = "lut")]
    kinds.extend([
        &ibl_lut::DFG as &dyn Kind,
        &ibl_lut::FRESNEL_TAIL,
        &ibl_lut::HV_LUT,
        &ibl_lut::AS_SIZE_BIAS,
    ]);
    #[cfg(feature = "material")]
    kinds.extend([&ibl_material::QUAT_MAP as &dyn Kind, &ibl_material::TPR_MAP]);
    kinds
}

/// The name of a bake the scene derives, through the bake itself; a build without the bake's
/// library (its feature off) still knows the name, to say the scene needs it.
macro_rules! kind_name {
    ($feature:literal, $bake:ty, $name:literal) => {{
        #[cfg(feature = $feature)]
        let name = <$bake as Bake>::NAME;
        #[cfg(not(feature = $feature))]
        let name = $name;
        name
    }};
}

/// The kinds a scene derives, named through their bakes.
pub mod scene_kinds {
    use super::Bake;
    /// `equirect-to-cube`.
    pub fn equirect_to_cube() -> &'static str {
        ibl_env::EquirectToCube::NAME
    }
    /// `irradiance`.
    pub fn irradiance() -> &'static str {
        ibl_env::Irradiance::NAME
    }
    /// `prefilter`.
    pub fn prefilter() -> &'static str {
        kind_name!("prefilter", ibl_prefilter::Prefilter, "prefilter")
    }
    /// `shexp-fit`.
    pub fn shexp_fit() -> &'static str {
        kind_name!("shexp", ibl_shexp::ShexpFit, "shexp-fit")
    }
    /// `dfg`.
    pub fn dfg() -> &'static str {
        kind_name!("lut", ibl_lut::Dfg, "dfg")
    }
    /// `fresnel-tail`.
    pub fn fresnel_tail() -> &'static str {
        kind_name!("lut", ibl_lut::FresnelTail, "fresnel-tail")
    }
    /// `hv-lut`.
    pub fn hv_lut() -> &'static str {
        kind_name!("lut", ibl_lut::HvLut, "hv-lut")
    }
    /// `as-size-bias`.
    pub fn as_size_bias() -> &'static str {
        kind_name!("lut", ibl_lut::AsSizeBias, "as-size-bias")
    }
    /// `quat-map`.
    pub fn quat_map() -> &'static str {
        kind_name!("material", ibl_material::QuatMap, "quat-map")
    }
    /// `tpr-map`.
    pub fn tpr_map() -> &'static str {
        kind_name!("material", ibl_material::TprMap, "tpr-map")
    }
}

/// The kind called `name`.
pub fn find(name: &str) -> Option<&'static dyn Kind> {
    all().into_iter().find(|k| k.name() == name)
}

/// Names of all kinds, for error messages.
pub fn names() -> Vec<&'static str> {
    all().iter().map(|k| k.name()).collect()
}

/// A stage's parameters with their type erased (the kind that parsed them knows it).
pub type AnyParams = Arc<dyn ParamsObj>;

/// What the runner needs of parameters without knowing their type.
pub trait ParamsObj: Any + Send + Sync + fmt::Debug {
    /// The parameters as `Any`, for the kind that knows their type.
    fn as_any(&self) -> &dyn Any;
    /// Canonical form for cache keys: JSON with object keys sorted, every field present.
    fn canonical(&self) -> serde_json::Value;
    /// Command-line flags that make the CLI parse these parameters (non-defaults only).
    fn cli_args(&self) -> Result<Vec<String>, String>;
}

impl<P: BakeParams> ParamsObj for P {
    fn as_any(&self) -> &dyn Any {
        self
    }
    fn canonical(&self) -> serde_json::Value {
        // serde_json's map is a BTreeMap (no `preserve_order`), so keys come out sorted;
        // f32 values as the user wrote them (0.2, not 0.20000000298023224).
        let mut v = serde_json::to_value(self).expect("Params serialise to JSON");
        ibl_core::io::data::shortest_f32(&mut v);
        v
    }
    fn cli_args(&self) -> Result<Vec<String>, String> {
        cli::to_args(self)
    }
}

/// Rewrites a bake's message for a pipeline, whose user writes RON keys, not CLI flags:
/// "pass --y-down" becomes "set y_down: true", "drop --y-down" "set y_down: false", and any
/// other "--max-roughness" of the kind's parameters "max_roughness". The libraries word
/// their messages for the CLIs they share with the pipeline.
pub fn ron_terms(message: &str, names: &[String]) -> String {
    let mut out = message.to_string();
    // Longest first, so that --size does not rewrite the front of --size-bias.
    let mut names: Vec<&String> = names.iter().collect();
    names.sort_by_key(|n| std::cmp::Reverse(n.len()));
    for name in names {
        let flag = format!("--{}", name.replace('_', "-"));
        if !out.contains(&flag) {
            continue;
        }
        for (verb, value) in [("pass ", "true"), ("use ", "true"), ("drop ", "false")] {
            out = out.replace(&format!("{verb}{flag}"), &format!("set {name}: {value}"));
        }
        // Whole flags only: the next character must not continue the flag's name.
        let mut rewritten = String::with_capacity(out.len());
        let mut rest = out.as_str();
        while let Some(at) = rest.find(&flag) {
            let after = &rest[at + flag.len()..];
            rewritten.push_str(&rest[..at]);
            if after.starts_with(|c: char| c.is_ascii_alphanumeric() || c == '-') {
                rewritten.push_str(&flag);
            } else {
                rewritten.push_str(name);
            }
            rest = after;
        }
        rewritten.push_str(rest);
        out = rewritten;
    }
    out
}

/// The canonical text of parameters hashed into cache keys.
pub fn canonical_text(p: &AnyParams) -> String {
    serde_json::to_string(&p.canonical()).expect("JSON value prints")
}

/// What a bake produced: encoded files (not yet written) and warnings for the log.
#[derive(Default)]
pub struct Baked {
    /// Each output path with its encoded bytes.
    pub files: Vec<(PathBuf, Vec<u8>)>,
    /// Warnings for the stage's log, in RON terms.
    pub warnings: Vec<String>,
}

/// One independent piece of a stage's work (one material of a folder of materials): the
/// runner gives it its own cache key, so one changed file re-bakes one item. Running the
/// kind on `inputs` into `dir` bakes exactly this item's outputs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Item {
    /// The files it reads (its key hashes them), given to the bake as its inputs.
    pub inputs: Vec<PathBuf>,
    /// The folder its run writes into, inside the stage's folder.
    pub dir: PathBuf,
}

/// A stage kind, type-erased: everything the planner, executor and ninja emitter ask of it.
pub trait Kind: Send + Sync {
    /// The name used in pipelines (`kind: "prefilter"`).
    fn name(&self) -> &'static str;
    /// One line for `bake kinds`.
    fn summary(&self) -> &'static str;
    /// The CLI that runs the same bake: binary name, then subcommand if any.
    fn command(&self) -> &'static [&'static str];
    /// The cargo package that builds that binary.
    fn package(&self) -> &'static str;
    /// The library crate the bake lives in: its fingerprint is the tool part of the stage keys
    /// (`cache::tool_for`).
    fn library(&self) -> &'static str;
    /// How many sources it reads, and what they are.
    fn reads(&self) -> Arity;
    /// The RON keys (= long flags with `_` for `-`) this kind's parameters accept.
    fn param_names(&self) -> Vec<String>;
    /// Parses the RON text of `params: (...)` (missing keys take their defaults).
    fn parse(&self, ron: &str) -> Result<AnyParams, ron::error::SpannedError>;
    /// The parameters every key left out takes.
    fn default_params(&self) -> AnyParams;
    /// Non-default parameters exercising every kind of field (tests round-trip them).
    fn example_params(&self) -> AnyParams;
    /// `p` with `key` set to `value` (the scene's overrides: max roughness, n_u and n_v).
    fn with(&self, p: &AnyParams, key: &str, value: serde_json::Value)
        -> Result<AnyParams, String>;
    /// The bake's own validation of its parameters (before any work).
    fn validate(&self, p: &AnyParams) -> Result<(), BakeError>;
    /// The `-o` argument for a stage writing into `dir`.
    fn out_arg(&self, p: &AnyParams, dir: &Path) -> PathBuf;
    /// What a downstream stage reads of this stage's outputs (the cube folder, the KTX2 file...).
    fn product(&self, p: &AnyParams, dir: &Path) -> PathBuf;
    /// The files a run will write, known before running (for ninja and for `plan`).
    fn outputs(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
    ) -> Result<Vec<PathBuf>, BakeError>;
    /// Runs the bake in-process; nothing is written.
    fn run(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
        progress: &dyn Progress,
    ) -> Result<Baked, BakeError>;
    /// The CLI commands (argv, binary name first) that run the same bake; `rel` writes a path
    /// as the command line should name it.
    fn argv(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
        rel: &dyn Fn(&Path) -> PathBuf,
    ) -> Result<Vec<Vec<String>>, String>;
    /// Checks that `p` survives `Params → CLI args → clap → Params` unchanged.
    fn cli_round_trip(&self, p: &AnyParams) -> Result<Vec<String>, String>;
    /// The command line of the same bake (without the flags every binary shares).
    fn cli(&self) -> clap::Command;
    /// The stage's work split into independent items, each baked by `run(p, &item.inputs,
    /// &item.dir)`; `None` when the kind bakes its inputs as one piece.
    fn items(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
    ) -> Option<Result<Vec<Item>, BakeError>>;
}

/// The single command most CLIs take: `BIN [SUB] INPUTS... -o OUT FLAGS... --quiet`.
pub fn standard_argv(
    command: &[&str],
    inputs: &[PathBuf],
    out: &Path,
    flags: Vec<String>,
) -> Vec<String> {
    let mut args: Vec<String> = command.iter().map(|s| s.to_string()).collect();
    args.extend(inputs.iter().map(|p| p.display().to_string()));
    args.push("-o".into());
    args.push(out.display().to_string());
    args.extend(flags);
    args.push("--quiet".into());
    args
}

/// `p` as the parameters of bake `B` (the kind that parsed them).
fn typed<'a, B: Bake>(bake: &B, p: &'a AnyParams) -> &'a B::Params {
    p.as_any()
        .downcast_ref::<B::Params>()
        .unwrap_or_else(|| panic!("parameters of another kind given to '{}'", bake.name()))
}

/// `e` in a pipeline's terms: RON keys where the bake's message names CLI flags.
fn in_ron_terms<B: Bake>(bake: &B, e: BakeError) -> BakeError {
    BakeError {
        message: ron_terms(&e.message, &bake.param_names()),
        ..e
    }
}

/// Every bake is a stage kind: plain calls of its one definition over its own `Params` type.
impl<B: Bake> Kind for B {
    fn name(&self) -> &'static str {
        Bake::name(self)
    }
    fn summary(&self) -> &'static str {
        B::SUMMARY
    }
    fn command(&self) -> &'static [&'static str] {
        B::COMMAND
    }
    fn package(&self) -> &'static str {
        Bake::package(self)
    }
    fn library(&self) -> &'static str {
        B::LIBRARY
    }
    fn reads(&self) -> Arity {
        B::READS.arity
    }
    fn param_names(&self) -> Vec<String> {
        cli::fields(&B::Params::default())
            .map(|f| f.into_iter().map(|(n, _)| n).collect())
            .unwrap_or_default()
    }
    fn parse(&self, ron: &str) -> Result<AnyParams, ron::error::SpannedError> {
        let p: B::Params = ron_options().from_str(ron)?;
        Ok(Arc::new(p))
    }
    fn default_params(&self) -> AnyParams {
        Arc::new(B::Params::default())
    }
    fn example_params(&self) -> AnyParams {
        Arc::new(self.example())
    }
    fn with(
        &self,
        p: &AnyParams,
        key: &str,
        value: serde_json::Value,
    ) -> Result<AnyParams, String> {
        let name = Bake::name(self);
        let mut v = serde_json::to_value(typed(self, p)).map_err(|e| e.to_string())?;
        let obj = v.as_object_mut().ok_or("parameters are not a struct")?;
        if !obj.contains_key(key) {
            return Err(format!("'{name}' has no parameter '{key}'"));
        }
        obj.insert(key.to_string(), value);
        let p: B::Params =
            serde_json::from_value(v).map_err(|e| format!("'{name}' parameter '{key}': {e}"))?;
        Ok(Arc::new(p))
    }
    fn validate(&self, p: &AnyParams) -> Result<(), BakeError> {
        self.validate_stage(typed(self, p))
            .map_err(|e| in_ron_terms(self, e))
    }
    fn out_arg(&self, p: &AnyParams, dir: &Path) -> PathBuf {
        self.stage_out(typed(self, p), dir)
    }
    fn product(&self, p: &AnyParams, dir: &Path) -> PathBuf {
        let p = typed(self, p);
        Bake::product(self, p, &self.stage_out(p, dir))
    }
    fn outputs(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
    ) -> Result<Vec<PathBuf>, BakeError> {
        let mut outputs = Vec::new();
        for j in self.jobs(typed(self, p), inputs, dir)? {
            outputs.extend(Bake::outputs(self, &j.params, &j.inputs, &j.out)?);
        }
        Ok(outputs)
    }
    fn run(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
        progress: &dyn Progress,
    ) -> Result<Baked, BakeError> {
        let names = self.param_names();
        let mut baked = Baked::default();
        let jobs = self
            .jobs(typed(self, p), inputs, dir)
            .map_err(|e| in_ron_terms(self, e))?;
        for Job {
            params,
            inputs,
            out,
        } in jobs
        {
            let b = Bake::run(self, &params, &inputs, &out, progress)
                .map_err(|e| in_ron_terms(self, e))?;
            baked.files.extend(b.files);
            baked
                .warnings
                .extend(b.warnings.iter().map(|w| ron_terms(w, &names)));
        }
        Ok(baked)
    }
    fn argv(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
        rel: &dyn Fn(&Path) -> PathBuf,
    ) -> Result<Vec<Vec<String>>, String> {
        self.cli_jobs(typed(self, p), inputs, dir, rel)
            .map_err(|e| e.message)?
            .into_iter()
            .map(|j| {
                Ok(standard_argv(
                    B::COMMAND,
                    &j.inputs,
                    &j.out,
                    j.params.cli_args()?,
                ))
            })
            .collect()
    }
    fn cli_round_trip(&self, p: &AnyParams) -> Result<Vec<String>, String> {
        let p = typed(self, p);
        let args = cli::to_args(p)?;
        let back: B::Params = cli::from_args(&args)?;
        let (a, b) = (
            serde_json::to_value(p).unwrap(),
            serde_json::to_value(&back).unwrap(),
        );
        if a != b {
            return Err(format!(
                "'{}': {args:?} parse back to {b} instead of {a}",
                Bake::name(self)
            ));
        }
        Ok(args)
    }
    fn cli(&self) -> clap::Command {
        ibl_bake::command(self)
    }
    fn items(
        &self,
        p: &AnyParams,
        inputs: &[PathBuf],
        dir: &Path,
    ) -> Option<Result<Vec<Item>, BakeError>> {
        if !B::ITEMIZED {
            return None;
        }
        // Each of the bake's runs is an item: its inputs, and the folder its `-o` writes in.
        Some(self.jobs(typed(self, p), inputs, dir).map(|jobs| {
            jobs.into_iter()
                .map(|j| Item {
                    dir: j.out.parent().unwrap_or(dir).to_path_buf(),
                    inputs: j.inputs,
                })
                .collect()
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pipeline_messages_name_ron_keys() {
        let names: Vec<String> = ["y_down", "size", "size_bias", "sanitize", "max_roughness"]
            .map(String::from)
            .to_vec();
        assert_eq!(
            ron_terms("leans y-down (DirectX): pass --y-down", &names),
            "leans y-down (DirectX): set y_down: true"
        );
        assert_eq!(ron_terms("drop --y-down", &names), "set y_down: false");
        assert_eq!(
            ron_terms(
                "--size 9 and --size-bias 2; --max-roughness -1 (--sanitize)",
                &names
            ),
            "size 9 and size_bias 2; max_roughness -1 (sanitize)"
        );
        // Flags of other tools stay as they are.
        assert_eq!(ron_terms("--other", &names), "--other");
    }

    #[test]
    fn every_bakes_help_has_no_rustdoc_links_or_file_citations() {
        for k in all() {
            let problems = ibl_cli::help_problems(k.cli());
            assert!(problems.is_empty(), "{}: {problems:#?}", k.name());
        }
    }

    #[test]
    fn every_kind_round_trips_its_parameters_through_its_cli() {
        for k in all() {
            for p in [k.default_params(), k.example_params()] {
                let args = k
                    .cli_round_trip(&p)
                    .unwrap_or_else(|e| panic!("{}: {e}", k.name()));
                eprintln!("{}: {args:?}", k.name());
            }
            assert!(
                !k.cli_round_trip(&k.example_params()).unwrap().is_empty(),
                "{}: the example must differ from the defaults",
                k.name()
            );
        }
    }

    #[test]
    fn empty_params_are_the_defaults_and_unknown_keys_are_refused_with_the_valid_names() {
        for k in all() {
            let p = k.parse("()").unwrap();
            assert_eq!(
                canonical_text(&p),
                canonical_text(&k.default_params()),
                "{}",
                k.name()
            );
            let e = k
                .parse("(no_such_key: 1)")
                .err()
                .unwrap_or_else(|| panic!("{} accepted an unknown key", k.name()));
            let msg = e.code.to_string();
            let first = &k.param_names()[0];
            assert!(
                msg.contains(first.as_str()),
                "{}: message should list valid names: {msg}",
                k.name()
            );
        }
    }

    /// Values to try for a field that currently holds `v` (the example's value first).
    fn other_values(
        v: &serde_json::Value,
        example: Option<&serde_json::Value>,
    ) -> Vec<serde_json::Value> {
        use serde_json::{json, Value};
        let mut out: Vec<Value> = example.into_iter().cloned().collect();
        match v {
            Value::Bool(b) => out.push(json!(!b)),
            Value::Number(n) => {
                let x = n.as_f64().unwrap_or(0.0);
                out.extend([json!(x as i64 + 1), json!(x * 2.0 + 1.0), json!(x / 2.0)]);
            }
            Value::String(t) => out.extend([json!(format!("{t}x")), json!("1")]),
            Value::Array(a) => {
                out.push(json!([]));
                if let Some(first) = a.first() {
                    out.push(Value::Array(vec![first.clone()]));
                }
            }
            _ => {}
        }
        // Options that are unset, and anything else: common shapes.
        out.extend([
            json!(1),
            json!(0.5),
            json!("x"),
            json!(true),
            json!("8x8"),
            json!("radial"),
            Value::Null,
        ]);
        out
    }

    #[test]
    fn canonical_text_is_stable_and_changes_with_any_field() {
        for k in all() {
            let (d, e) = (k.default_params(), k.example_params());
            assert_eq!(canonical_text(&d), canonical_text(&k.default_params()));
            assert_ne!(canonical_text(&d), canonical_text(&e), "{}", k.name());
            let (dv, ev) = (d.canonical(), e.canonical());
            for name in k.param_names() {
                let current = &dv[&name];
                // For an enum, serde's refusal of "x" lists its variants.
                let variants: Vec<serde_json::Value> = match k.with(&d, &name, "x".into()) {
                    Err(e) => e.split('`').skip(3).step_by(2).map(|v| v.into()).collect(),
                    Ok(_) => vec![],
                };
                let changed = other_values(current, ev.get(&name))
                    .into_iter()
                    .chain(variants)
                    .filter(|v| v != current)
                    .find_map(|v| k.with(&d, &name, v).ok())
                    .unwrap_or_else(|| {
                        panic!("{}: no other value for '{name}' (now {current})", k.name())
                    });
                assert_ne!(
                    canonical_text(&changed),
                    canonical_text(&d),
                    "{}: changing '{name}' does not change the canonical text",
                    k.name()
                );
                assert_ne!(
                    changed.canonical()[&name],
                    *current,
                    "{}: '{name}'",
                    k.name()
                );
            }
        }
    }
}
