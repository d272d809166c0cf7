//! `shexp-eval`: Silvennoinen et al. 2025 §5.1 on any environment — ground truth, split-sum and SH-exp on
//! rendered spheres, with MSEs, win share, memory, PNG montages and a markdown report.

use clap::Parser;
use ibl_shexp::eval::{self, Params};
use ibl_shexp::{fit, splitsum::SplitSum, Coeffs};
use std::path::PathBuf;

/// Renders chrome and dielectric spheres from several views and roughnesses under each
/// environment, three ways (exact ground truth, split-sum, SH-exp), and reports the MSEs, the
/// share of cases SH-exp wins and the memory per probe. Writes OUT/report.md, OUT/report.json
/// and OUT/<env>_<material>.png (columns per view: truth, split-sum, SH-exp, |error| heat maps).
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// Input environments (.exr/.hdr equirect or cross, face folders, .ktx2/.ktx/.dds cubes).
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// Coefficients written by shexp-fit (one environment only); default: fit with the
    /// paper's settings (or --fit-params).
    #[arg(long)]
    coeffs: Option<PathBuf>,
    /// Prefiltered chain (a folder of m{l}_<face> images or a .ktx2/.ktx/.dds) written by `prefilter`
    /// (one environment only); default: bake one at --ss-size.
    #[arg(long)]
    prefiltered: Option<PathBuf>,
    /// Fit parameters (RON or JSON, keys as shexp-fit's flags) used when --coeffs is absent.
    #[arg(long)]
    fit_params: Option<PathBuf>,
    /// Output folder.
    #[arg(long, default_value = "report")]
    out: PathBuf,
    #[command(flatten)]
    params: Params,
    #[command(flatten)]
    common: ibl_cli::CommonArgs,
}

fn main() {
    let cli = ibl_cli::parse::<Cli>("shexp-eval");
    ibl_cli::run("shexp-eval", cli.common.clone(), |ctx| {
        cli.params.validate()?;
        if cli.inputs.len() > 1 && (cli.coeffs.is_some() || cli.prefiltered.is_some()) {
            return Err(ibl_shexp::Error::Core(ibl_core::Error::param(
                "--coeffs and --prefiltered apply to a single environment",
            )));
        }
        ibl_cli::check_output(&cli.out, ibl_cli::OutputKind::Folder)?;
        ibl_core::ownership::check_output_folder(&cli.out, "--out", true)?;
        let fit_params: fit::Params = match &cli.fit_params {
            Some(p) => ibl_core::io::data::read_as(p, "an SH-exp fit-parameter file")?,
            None => fit::Params::default(),
        };
        fit_params.validate()?;
        let coeffs: Option<Coeffs> = match &cli.coeffs {
            Some(p) => {
                let c: Coeffs = ibl_core::io::data::read_as(p, "an SH-exp coefficient file")?;
                c.validate(p)?;
                Some(c)
            }
            None => None,
        };
        let chain = match &cli.prefiltered {
            Some(p) => Some((
                ibl_core::envmap::read_cube_chain(p)?,
                p.display().to_string(),
            )),
            None => None,
        };
        // Load every input first: a bad file fails before any work.
        let mut envs = Vec::new();
        for input in &cli.inputs {
            envs.push(ctx.load_environment(input, cli.params.sanitize)?);
        }
        let mut reports = Vec::new();
        let mut images = Vec::new();
        for (input, env) in cli.inputs.iter().zip(&envs) {
            let name = input
                .file_stem()
                .and_then(|s| s.to_str())
                .unwrap_or("env")
                .to_string();
            let cube = fit::working_cube(&env.env, cli.params.size, ctx.progress());
            let c = match &coeffs {
                Some(c) => c.clone(),
                None => fit::fit_cube(&fit_params, &cube, ctx.progress())?.coeffs,
            };
            let ss = match &chain {
                Some((mips, src)) => SplitSum::new(
                    mips,
                    eval::default_dfg(),
                    format!("{src} ({} levels)", mips.levels.len()),
                ),
                None => eval::default_split_sum(&cube, cli.params.ss_size)?,
            };
            let (rep, imgs) = eval::evaluate(&name, &cube, &c, &ss, &cli.params, ctx.progress());
            ctx.info(format!(
                "{name}: SH-exp wins {}/{} cases (ground truth {:.2} s, methods {:.2} s)",
                rep.wins,
                rep.cases.len(),
                rep.seconds_truth,
                rep.seconds_methods
            ));
            reports.push(rep);
            images.push(imgs);
        }
        let files = eval::encode_outputs(&cli.out, &cli.params, &reports, &images)?;
        let paths: Vec<PathBuf> = files.iter().map(|f| f.0.clone()).collect();
        ibl_core::ownership::check_writes(&cli.out, &paths, cli.common.overwrite)?;
        let outputs = ibl_cli::write_outputs(&files)?;
        ibl_cli::record_outputs("shexp-eval", &cli.out, &files)?;
        if !cli.common.quiet && !cli.common.json {
            print!("{}", eval::markdown(&reports));
        }
        let total: usize = reports.iter().map(|r| r.cases.len()).sum();
        let wins: usize = reports.iter().map(|r| r.wins).sum();
        let details = serde_json::json!({
            "wins": wins,
            "cases": total,
            "win_share": wins as f64 / total.max(1) as f64,
            "environments": reports,
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
