//! Deriving the stages a scene needs, and saying why each one is or is not baked.
//!
//! For every probe: its cube (`<probe>/cube`), its diffuse irradiance (`<probe>/irradiance`),
//! and for its glossy part either the GGX prefiltered chain (`<probe>/prefilter`, split-sum,
//! only up to the largest roughness the probe serves) or the SH-exponential fit
//! (`<probe>/shexp`). Shared tables: the split-sum DFG table once (`dfg`) when a split-sum probe
//! lights an isotropic GGX material, the Fresnel-tail table once (`fresnel-tail`) when a probe is
//! served by SH-exp, and one half-vector LUT (`hv-lut/<nu>x<nv>`) and one size/bias table
//! (`as-size-bias/<nu>x<nv>`) per distinct (n_u, n_v) among anisotropic materials. For every
//! material: a quaternion map (`<material>/quat-map`) only when it is anisotropic and
//! bump-mapped, a TPR map (`<material>/tpr-map`) only when it uses one. An anisotropic GGX material
//! (`AnisotropicGgx(roughness, eta)`) is lit by the shipped VNDF filtered-importance-sampling
//! snippet (`aniso-eval --emit-shader`), which reads the probe's cube with its box mips: it
//! needs no chain, no DFG table and no Ashikhmin–Shirley table of its own.
//!
//! Every candidate is listed, needed or not, so `bake plan` shows each decision.

use crate::error::Diagnostic;
use crate::kinds::scene_kinds as K;
use crate::kinds::{self, AnyParams};
use crate::need::Need;
use crate::schema::{Input, Model, Pipeline, Scene, Serving};

/// A stage the scene implies.
#[derive(Clone, Debug)]
pub struct Derived {
    pub id: String,
    pub kind: &'static str,
    /// `None` when this build has no such kind (an error only if the stage is needed).
    pub params: Option<AnyParams>,
    pub reads: Vec<String>,
    pub need: Need,
    /// Where in the pipeline file the decision comes from.
    pub offset: usize,
}

/// Inputs the scene adds (probe environments, material folders): (name, input, offset).
pub type SceneInput = (String, Input, usize);

struct Builder<'a> {
    pipeline: &'a Pipeline,
    scene: &'a Scene,
    out: Vec<Derived>,
    diags: &'a mut Vec<Diagnostic>,
}

impl Builder<'_> {
    /// The scene's parameters for `kind` with `overrides` applied; `None` if the
    /// kind is not in this build. They are validated by the graph once it knows which stages
    /// are needed (a stage the scene does not need may be needed by the pipeline's outputs).
    fn params(
        &mut self,
        kind: &str,
        overrides: &[(&str, serde_json::Value)],
        offset: usize,
    ) -> Option<AnyParams> {
        let k = kinds::find(kind)?;
        let mut p = self
            .scene
            .params
            .get(kind)
            .cloned()
            .unwrap_or_else(|| k.default_params());
        for (key, value) in overrides {
            match k.with(&p, key, value.clone()) {
                Ok(q) => p = q,
                Err(e) => {
                    self.diags
                        .push(self.pipeline.diag(offset, format!("scene: {e}")));
                    return Some(p);
                }
            }
        }
        Some(p)
    }

    fn stage(
        &mut self,
        id: String,
        kind: &'static str,
        reads: Vec<String>,
        need: Need,
        overrides: &[(&str, serde_json::Value)],
        offset: usize,
    ) {
        let params = self.params(kind, overrides, offset);
        self.out.push(Derived {
            id,
            kind,
            params,
            reads,
            need,
            offset,
        });
    }
}

/// The stages and inputs `scene` implies.
pub fn derive(
    pipeline: &Pipeline,
    scene: &Scene,
    diags: &mut Vec<Diagnostic>,
) -> (Vec<Derived>, Vec<SceneInput>) {
    use Need::*;
    let mut inputs = Vec::new();
    let mut b = Builder {
        pipeline,
        scene,
        out: Vec::new(),
        diags,
    };

    // An env or folder naming a declared input reads that input; otherwise it is a path.
    let mut source = |name: String, path: &str, folder: bool, at: usize| -> String {
        if pipeline.inputs.contains_key(path) {
            return path.to_string();
        }
        // A probe may also name a folder of six faces.
        let is_folder = folder || pipeline.resolve(path).is_dir();
        let input = if is_folder {
            Input::Folder(path.to_string())
        } else {
            Input::File(path.to_string())
        };
        inputs.push((name.clone(), input, at));
        name
    };

    let split_sum: Vec<&str> = scene
        .probes
        .iter()
        .filter(|(p, _)| p.served_by == Serving::SplitSum)
        .map(|(p, _)| p.id.as_str())
        .collect();
    let sh_exp: Vec<&str> = scene
        .probes
        .iter()
        .filter(|(p, _)| p.served_by == Serving::ShExp)
        .map(|(p, _)| p.id.as_str())
        .collect();
    for (probe, at) in &scene.probes {
        let env = source(format!("{}.env", probe.id), &probe.env, false, *at);
        let cube = format!("{}/cube", probe.id);
        b.stage(
            cube.clone(),
            K::equirect_to_cube(),
            vec![env],
            Needed(format!("environment of probe '{}'", probe.id)),
            &[],
            *at,
        );
        b.stage(
            format!("{}/irradiance", probe.id),
            K::irradiance(),
            vec![cube.clone()],
            Needed(format!("diffuse lighting of probe '{}'", probe.id)),
            &[],
            *at,
        );
        let (pre, fit) = match probe.served_by {
            Serving::SplitSum => (
                Needed(format!(
                    "probe '{}' is served by split-sum up to roughness {}",
                    probe.id, probe.max_roughness
                )),
                NotNeeded(format!(
                    "not needed by the scene: probe '{}' is served by split-sum",
                    probe.id
                )),
            ),
            Serving::ShExp => (
                NotNeeded(format!(
                    "not needed by the scene: probe '{}' is served by SH-exp",
                    probe.id
                )),
                Needed(format!("probe '{}' is served by SH-exp", probe.id)),
            ),
        };
        b.stage(
            format!("{}/prefilter", probe.id),
            K::prefilter(),
            vec![cube.clone()],
            pre,
            &[("max_roughness", serde_json::json!(probe.max_roughness))],
            *at,
        );
        b.stage(
            format!("{}/shexp", probe.id),
            K::shexp_fit(),
            vec![cube],
            fit,
            &[],
            *at,
        );
    }

    let isotropic: Vec<&str> = scene
        .materials
        .iter()
        .filter(|m| m.model == Model::Ggx)
        .map(|m| m.id.as_str())
        .collect();
    let dfg = if split_sum.is_empty() {
        NotNeeded("not needed by the scene: no probe is served by split-sum".into())
    } else if !scene.materials.is_empty() && isotropic.is_empty() {
        NotNeeded("not needed by the scene: no isotropic GGX material".into())
    } else {
        Needed(format!(
            "split-sum DFG table, shared by probe(s) {}",
            quoted(&split_sum)
        ))
    };
    b.stage(K::dfg().into(), K::dfg(), vec![], dfg, &[], scene.offset);
    let tail = if sh_exp.is_empty() {
        NotNeeded("not needed by the scene: no probe is served by SH-exp".into())
    } else {
        Needed(format!(
            "Fresnel tail of the SH-exp probe(s) {}",
            quoted(&sh_exp)
        ))
    };
    b.stage(
        K::fresnel_tail().into(),
        K::fresnel_tail(),
        vec![],
        tail,
        &[],
        scene.offset,
    );

    // One hv-lut and one size/bias table per distinct (n_u, n_v), in order of first use.
    let mut pairs: Vec<((f64, f64), Vec<&str>, usize)> = Vec::new();
    for m in &scene.materials {
        if let Model::AshikhminShirley { n_u, n_v } = m.model {
            match pairs
                .iter_mut()
                .find(|(p, _, _)| p.0.to_bits() == n_u.to_bits() && p.1.to_bits() == n_v.to_bits())
            {
                Some((_, users, _)) => users.push(&m.id),
                None => pairs.push(((n_u, n_v), vec![&m.id], m.offset)),
            }
        }
    }
    if pairs.is_empty() {
        for kind in [K::hv_lut(), K::as_size_bias()] {
            b.stage(
                kind.into(),
                kind,
                vec![],
                NotNeeded("not needed by the scene: no Ashikhmin-Shirley material".into()),
                &[],
                scene.offset,
            );
        }
    }
    for ((nu, nv), users, at) in &pairs {
        // f64's Display is compact: 100 → "100", 0.5 → "0.5".
        let why = format!("anisotropic (n_u, n_v) = ({nu}, {nv}) of {}", quoted(users));
        let over = [("nu", serde_json::json!(nu)), ("nv", serde_json::json!(nv))];
        for kind in [K::hv_lut(), K::as_size_bias()] {
            b.stage(
                format!("{kind}/{nu}x{nv}"),
                kind,
                vec![],
                Needed(why.clone()),
                &over,
                *at,
            );
        }
    }

    for m in &scene.materials {
        let folder = source(format!("{}.folder", m.id), &m.folder, true, m.offset);
        let quat = match (m.model, m.bump_mapped) {
            (Model::Ggx, _) => NotNeeded(format!(
                "not needed by the scene: material '{}' is isotropic GGX",
                m.id
            )),
            (_, false) => NotNeeded(format!(
                "not needed by the scene: material '{}' is not bump-mapped",
                m.id
            )),
            _ => Needed(format!(
                "material '{}' is anisotropic and bump-mapped",
                m.id
            )),
        };
        b.stage(
            format!("{}/quat-map", m.id),
            K::quat_map(),
            vec![folder],
            quat,
            &[],
            m.offset,
        );
        let tpr = if m.tpr_map {
            Needed(format!("material '{}' uses a TPR map", m.id))
        } else {
            NotNeeded(format!(
                "not needed by the scene: material '{}' has no TPR map",
                m.id
            ))
        };
        // The material's own keys override the scene's tpr-map parameters one by one.
        let own = m
            .tpr_params
            .as_ref()
            .map(|p| p.canonical())
            .unwrap_or_default();
        let over: Vec<(&str, serde_json::Value)> = m
            .tpr_keys
            .iter()
            .filter_map(|k| Some((k.as_str(), own.get(k)?.clone())))
            .collect();
        b.stage(
            format!("{}/tpr-map", m.id),
            K::tpr_map(),
            vec![],
            tpr,
            &over,
            m.offset,
        );
    }
    (b.out, inputs)
}

fn quoted(ids: &[&str]) -> String {
    ids.iter()
        .map(|s| format!("'{s}'"))
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(all(
    test,
    feature = "prefilter",
    feature = "material",
    feature = "shexp",
    feature = "lut"
))]
mod tests {
    use super::*;
    use crate::schema;
    use std::path::Path;

    fn derive_from(scene: &str) -> Vec<Derived> {
        let p = schema::parse(Path::new("s.ron"), format!("(scene: {scene})"))
            .unwrap_or_else(|e| panic!("{e}"));
        let mut diags = vec![];
        let (d, _) = derive(&p, p.scene.as_ref().unwrap(), &mut diags);
        assert!(diags.is_empty(), "{diags:?}");
        d
    }

    fn find<'a>(d: &'a [Derived], id: &str) -> &'a Derived {
        d.iter().find(|s| s.id == id).unwrap_or_else(|| {
            panic!(
                "no stage {id} in {:?}",
                d.iter().map(|s| &s.id).collect::<Vec<_>>()
            )
        })
    }

    fn needed(d: &[Derived], id: &str) -> bool {
        matches!(find(d, id).need, Need::Needed(_))
    }

    const PROBES: &str = r#"probes: [(id: "lobby", env: "a.exr", max_roughness: 0.6), (id: "sky", env: "b.exr", served_by: ShExp)]"#;

    #[test]
    fn probes_get_a_chain_up_to_their_roughness_or_an_shexp_fit() {
        let d = derive_from(&format!(
            "({PROBES}, params: {{\"prefilter\": (size: 32)}})"
        ));
        assert!(
            needed(&d, "lobby/cube")
                && needed(&d, "lobby/irradiance")
                && needed(&d, "lobby/prefilter")
        );
        assert!(!needed(&d, "lobby/shexp"));
        assert!(!needed(&d, "sky/prefilter") && needed(&d, "sky/shexp"));
        assert_eq!(
            find(&d, "sky/prefilter").need,
            Need::NotNeeded("not needed by the scene: probe 'sky' is served by SH-exp".into())
        );
        let pre =
            crate::kinds::canonical_text(find(&d, "lobby/prefilter").params.as_ref().unwrap());
        assert!(
            pre.contains("\"max_roughness\":0.6") && pre.contains("\"size\":32"),
            "{pre}"
        );
        assert_eq!(
            find(&d, "lobby/prefilter").reads,
            vec!["lobby/cube".to_string()]
        );
        // One DFG table (split-sum) and one Fresnel tail (SH-exp), shared.
        assert_eq!(d.iter().filter(|s| s.kind == "dfg").count(), 1);
        assert!(needed(&d, "dfg") && needed(&d, "fresnel-tail"));
        // No anisotropic material: no AS tables at all.
        assert!(!needed(&d, "hv-lut") && !needed(&d, "as-size-bias"));
    }

    #[test]
    fn one_as_table_pair_per_distinct_exponents_and_quaternions_only_for_bumped_anisotropic() {
        let d = derive_from(&format!(
            r#"({PROBES}, materials: [
                (id: "steel", folder: "m/steel", model: Ggx, bump_mapped: true),
                (id: "brushed", folder: "m/brushed", model: AshikhminShirley(n_u: 100, n_v: 10), bump_mapped: true, tpr_map: true),
                (id: "satin", folder: "m/satin", model: AshikhminShirley(n_u: 100, n_v: 10)),
                (id: "hair", folder: "m/hair", model: AshikhminShirley(n_u: 20000, n_v: 70), bump_mapped: true),
            ], params: {{"tpr-map": (size: 8, preset: "radial")}})"#
        ));
        let hv: Vec<&str> = d
            .iter()
            .filter(|s| s.kind == "hv-lut")
            .map(|s| s.id.as_str())
            .collect();
        assert_eq!(hv, ["hv-lut/100x10", "hv-lut/20000x70"]);
        assert_eq!(
            d.iter()
                .filter(|s| s.kind == "as-size-bias" && matches!(s.need, Need::Needed(_)))
                .count(),
            2
        );
        let sb = crate::kinds::canonical_text(
            find(&d, "as-size-bias/20000x70").params.as_ref().unwrap(),
        );
        assert!(
            sb.contains("\"nu\":20000.0") && sb.contains("\"nv\":70.0"),
            "{sb}"
        );
        assert!(needed(&d, "brushed/quat-map") && needed(&d, "hair/quat-map"));
        assert!(!needed(&d, "steel/quat-map") && !needed(&d, "satin/quat-map"));
        assert!(
            matches!(&find(&d, "satin/quat-map").need, Need::NotNeeded(w) if w.contains("not bump-mapped"))
        );
        assert!(
            matches!(&find(&d, "steel/quat-map").need, Need::NotNeeded(w) if w.contains("isotropic"))
        );
        assert!(needed(&d, "brushed/tpr-map") && !needed(&d, "hair/tpr-map"));
        assert!(
            needed(&d, "dfg"),
            "steel is isotropic and lobby is split-sum"
        );
    }

    #[test]
    fn no_split_sum_probe_or_no_isotropic_material_means_no_dfg() {
        let d = derive_from(r#"(probes: [(id: "sky", env: "b.exr", served_by: ShExp)])"#);
        assert!(!needed(&d, "dfg"));
        let d = derive_from(
            r#"(probes: [(id: "p", env: "b.exr")], materials: [(id: "a", folder: "f", model: AshikhminShirley(n_u: 1, n_v: 2))])"#,
        );
        assert!(!needed(&d, "dfg") && needed(&d, "hv-lut/1x2"));
        assert!(!needed(&d, "fresnel-tail"));
    }

    #[test]
    fn an_anisotropic_ggx_material_needs_the_cube_and_no_split_sum_or_as_table() {
        // The shipped anisotropic method (VNDF FIS) reads the probe's cube and its box mips.
        let d = derive_from(
            r#"(probes: [(id: "p", env: "b.exr")], materials: [
                (id: "brushed", folder: "f", model: AnisotropicGgx(roughness: 0.4, eta: 0.8), bump_mapped: true),
                (id: "satin", folder: "g", model: AnisotropicGgx(roughness: 0.6, eta: -0.3)),
            ])"#,
        );
        assert!(needed(&d, "p/cube"));
        assert!(!needed(&d, "dfg"), "no isotropic GGX material");
        assert_eq!(
            find(&d, "hv-lut").need,
            Need::NotNeeded("not needed by the scene: no Ashikhmin-Shirley material".into())
        );
        assert!(needed(&d, "brushed/quat-map") && !needed(&d, "satin/quat-map"));
    }

    #[test]
    fn a_materials_tpr_params_override_the_scenes_key_by_key() {
        let d = derive_from(
            r#"(materials: [
                (id: "a", folder: "f", model: Ggx, tpr_map: true, tpr_params: (preset: "spiral:0.5,0.5,2", bits: 16)),
                (id: "b", folder: "g", model: Ggx, tpr_map: true),
            ], params: {"tpr-map": (size: 8, preset: "radial", bits: 8, y_down: true)})"#,
        );
        let tpr = |id: &str| crate::kinds::canonical_text(find(&d, id).params.as_ref().unwrap());
        let a = tpr("a/tpr-map");
        // Given keys win (even one set to its default: bits 16), the others are the scene's.
        assert!(
            a.contains("\"preset\":\"spiral:0.5,0.5,2\"") && a.contains("\"bits\":16"),
            "{a}"
        );
        assert!(
            a.contains("\"size\":")
                && !a.contains("\"size\":null")
                && a.contains("\"y_down\":true"),
            "the scene's size and y_down are kept: {a}"
        );
        let b = tpr("b/tpr-map");
        assert!(
            b.contains("\"preset\":\"radial") && b.contains("\"bits\":8"),
            "{b}"
        );
    }
}
