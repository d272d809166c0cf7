//! The SH-exponential fit as both front-ends see it: the `shexp-fit` binary and the pipeline's
//! `shexp-fit` stage kind are this one [`Bake`].

use crate::fit::{self, Params};
use ibl_bake::{Bake, BakeError, Baked, Reads, Writes};
use ibl_core::progress::Progress;
use std::path::{Path, PathBuf};

/// The SH-exponential glossy probe fit.
pub struct ShexpFit;

/// The SH-exponential fit bake.
pub static SHEXP_FIT: ShexpFit = ShexpFit;

impl Bake for ShexpFit {
    type Params = Params;

    const NAME: &'static str = "shexp-fit";
    const SUMMARY: &'static str = "SH-exponential glossy probe fit (Silvennoinen et al. 2025)";
    const ABOUT: &'static str =
        "Fits the spherical-harmonic-exponential glossy probe of Silvennoinen et al. 2025: per \
         colour channel, P (order --p-order, at the reflection vector) and Q (order --q-order \
         without DC, at the half-reflection vector) by least squares on log E0 (eq. 13), then, by \
         default, refined on the relative linear error (--objective log skips that). --alphas are \
         GGX α values (α = roughness²). --alpha-knots adds coefficient sets interpolated in α \
         (beyond the paper; the file keeps eq. 11's p and q).";
    const COMMAND: &'static [&'static str] = &["shexp-fit"];
    const LIBRARY: &'static str = "ibl-shexp";
    const READS: Reads = Reads::ENVIRONMENT;
    const WRITES: Writes = Writes::file("Output coefficient file: .json (default) or .ron");
    fn stage_out(&self, _: &Params, dir: &Path) -> PathBuf {
        dir.join("shexp.json")
    }
    fn outputs(&self, p: &Params, _: &[PathBuf], out: &Path) -> Result<Vec<PathBuf>, BakeError> {
        let mut files = vec![out.to_path_buf()];
        if p.emit_shader {
            files.push(out.with_extension("glsl"));
            files.push(out.with_extension("hlsl"));
        }
        Ok(files)
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
        // A large equirect whose format reads row by row is opened, not read: its rows
        // stream into the working cube.
        let input = ibl_bake::open_environment(Self::NAME, inputs, p.sanitize)?;
        let baked = fit::run(p, input, out, progress)?;
        let c = &baked.fitted.coeffs;
        let t = &baked.fitted.timings;
        let mut info = vec![format!(
            "fitted {} + {} coefficients per channel from {} rows on a {}² cube: log-space RMS residual {:.4}, condition number {:.1}; {:.3} s (E0 {:.3} s, solve {:.3} s)",
            c.p.len(),
            c.q.len(),
            c.rows,
            baked.fitted.face_size,
            c.residual,
            c.condition_number,
            t.total(),
            t.estimate,
            t.solve
        )];
        if let Some(k) = &c.alpha_knots {
            info.push(format!(
                "alpha knots {:?}: {} × {} coefficients per channel, log-space RMS residual {:.4}",
                k.alphas,
                k.alphas.len(),
                c.p.len() + c.q.len(),
                k.residual
            ));
        }
        Ok(Baked {
            details: serde_json::json!({
                "face_size": baked.fitted.face_size,
                "rows": c.rows,
                "unknowns_per_channel": c.p.len() + c.q.len(),
                "residual": c.residual,
                "residual_rgb": c.residual_rgb,
                "condition_number": c.condition_number,
                "alpha_knots": c.alpha_knots.as_ref().map(|k| &k.alphas),
                "timings": t,
            }),
            files: baked.files,
            warnings: baked.warnings,
            info,
        })
    }
    fn example(&self) -> Params {
        ibl_bake::example("(p_order: 3, q_order: 1, views: 8, normals: 8, alphas: [0.25, 1.0], alpha_knots: [0.25, 1.0], samples: 64, size: 16, floor: 0.01, weight_power: 2, cosine_weight: true, lod_bias: 0.5, estimator: exact, exact_size: 8, emit_shader: true, sanitize: true)")
    }
}
