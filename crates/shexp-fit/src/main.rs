//! `shexp-fit`: parse, fit the SH-exponential probe with `ibl_shexp::fit`, write, report.

use clap::Parser;
use ibl_shexp::fit::{run, Params};
use std::path::PathBuf;

/// Fits the spherical-harmonic-exponential glossy probe of Silvennoinen et al. 2025 (Silvennoinen et al. 2025):
/// per colour channel, P (order --p-order, at the reflection vector) and Q (order --q-order
/// without DC, at the half-reflection vector) by least squares on log E0 (eq. 13), then, by
/// default, refined on the relative linear error (--objective log skips that). --alphas are GGX
/// α values (α = roughness²). --alpha-knots adds coefficient sets interpolated in α (beyond
/// the paper; the file keeps eq. 11's p and q).
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// Input environment: .exr/.hdr equirect or cross, a folder of faces, or a .ktx2 cube.
    input: PathBuf,
    /// Output coefficient file: .json (default) or .ron.
    #[arg(short, long)]
    output: PathBuf,
    #[command(flatten)]
    params: Params,
    #[command(flatten)]
    common: ibl_cli::CommonArgs,
}

fn main() {
    let cli = ibl_cli::parse::<Cli>("shexp-fit");
    ibl_cli::run("shexp-fit", cli.common.clone(), |ctx| {
        cli.params.validate()?;
        ibl_cli::check_output(&cli.output, ibl_cli::OutputKind::File)?;
        let env = ctx.load_environment(&cli.input, cli.params.sanitize)?;
        let baked = run(&cli.params, &env, &cli.output, ctx.progress())?;
        let outputs = ibl_cli::write_outputs(&baked.files)?;
        let c = &baked.fitted.coeffs;
        let t = &baked.fitted.timings;
        ctx.info(format!(
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
        ));
        if let Some(k) = &c.alpha_knots {
            ctx.info(format!(
                "alpha knots {:?}: {} × {} coefficients per channel, log-space RMS residual {:.4}",
                k.alphas,
                k.alphas.len(),
                c.p.len() + c.q.len(),
                k.residual
            ));
        }
        let details = serde_json::json!({
            "face_size": baked.fitted.face_size,
            "rows": c.rows,
            "unknowns_per_channel": c.p.len() + c.q.len(),
            "residual": c.residual,
            "residual_rgb": c.residual_rgb,
            "condition_number": c.condition_number,
            "alpha_knots": c.alpha_knots.as_ref().map(|k| &k.alphas),
            "timings": t,
        });
        Ok::<_, ibl_shexp::Error>((outputs, details))
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn help_has_no_rustdoc_links_or_file_citations() {
        let problems = ibl_cli::help_problems(<super::Cli as clap::CommandFactory>::command());
        assert!(problems.is_empty(), "{problems:#?}");
    }
}
