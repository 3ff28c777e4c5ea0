//! `bsdfit fit`.

use super::progress::Progress;
use super::{BackendArgs, ConstraintArgs, DataArgs};
use crate::data::Dataset;
use crate::engine;
use crate::inference::fit::{FitReport, Optimizer};
use crate::output::files::write_result;
use crate::workflows::fit::{parse_metric, parse_weights, FitRequest, FitResponse, Stage};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct FitArgs {
    #[arg(help = super::DATA_FILE_HELP)]
    pub data: PathBuf,
    /// Model spec, e.g. lambert, on, fa(eon), rmg(ggx), btdf(tr)+scale.
    #[arg(long)]
    pub model: String,
    /// Loss. Default chi2 = Σ((y′−y)/u)², which fits BRDF and BTDF data alike: every v1
    /// data file carries a standard uncertainty per value, so χ² weighs each sample by
    /// what it is worth. The benchmark's losses remain: smape rmse ngan low (BRDF), f cosf
    /// logf logcosf (BTDF); docs/losses.md defines each.
    #[arg(long, default_value_t = FitRequest::default().loss.to_string())]
    pub loss: String,
    /// Weighting of that loss: uniform; relunc, 1/(u/|y| + ε), the inverse relative
    /// uncertainty (the BRDF losses' uncertainty weighting); invunc, 1/u (the BTDF
    /// losses'). chi2 already weighs by 1/u² whatever is given.
    #[arg(long, default_value_t = FitRequest::default().weights.to_string())]
    pub weights: String,
    /// Optimizer. Default: lm (Levenberg–Marquardt) for sum-of-squares losses — chi2 and
    /// every loss but smape — and compass search for smape.
    #[arg(long, value_parser = super::choice::<Optimizer>())]
    pub optimizer: Option<Optimizer>,
    /// Number of random restarts (stepped in lockstep); the same default as `diagnose`.
    #[arg(long, default_value_t = FitRequest::default().restarts, value_parser = super::parse_restarts, allow_hyphen_values = true)]
    pub restarts: usize,
    /// Seed of the random restarts (a non-negative integer).
    #[arg(long, default_value_t = FitRequest::default().seed, value_parser = super::parse_seed, allow_hyphen_values = true)]
    pub seed: u64,
    #[command(flatten)]
    pub backend: BackendArgs,
    /// Write the fit report (docs/output.md) as JSON here (checked before the fit starts; if
    /// the write fails afterwards, the JSON is printed to stdout instead).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Fit each measured φ plane separately (for anisotropic samples: one isotropic fit per
    /// plane); the JSON is then {"per_axis": [{"phi": …, "fit": report}, …]}.
    #[arg(long)]
    pub per_axis: bool,
    #[command(flatten)]
    pub constraints: ConstraintArgs,
    /// Monte Carlo uncertainty: refit N replicas of the data, each value drawn from
    /// N(value, u²), all replicas stepped together; reports per parameter the mean, σ and
    /// 95 % shortest coverage interval, the correlations, and the linearized σ beside them
    /// (with a warning where they disagree). 0: off.
    #[arg(long, default_value_t = FitRequest::default().mc, value_name = "N")]
    pub mc: usize,
    /// With --mc: an instrument's fully correlated relative scale uncertainty (e.g. 0.01):
    /// every value of a replica is multiplied by one draw of N(1, REL²).
    #[arg(
        long,
        default_value_t = FitRequest::default().mc_scale,
        value_name = "REL",
        allow_hyphen_values = true
    )]
    pub mc_scale: f64,
    /// With --mc: random restarts per replica, besides starting from the best fit.
    #[arg(long, default_value_t = FitRequest::default().mc_restarts, value_name = "R")]
    pub mc_restarts: usize,
    /// The smoothness prior of a data-driven factor's knots (`+ndf`, `+fresnel`, `+body`), a χ²
    /// term on their second differences: `auto` chooses its σ from the data (the smallest χ² + 2·
    /// effective parameters among 0.03, 0.1, 0.3, 1, 3, 10, 30; reported), `off`, or a σ.
    /// Needs the chi2 loss unless off; models without knots ignore it.
    #[arg(
        long,
        default_value = "auto",
        value_name = "auto|off|SD",
        allow_hyphen_values = true
    )]
    pub smoothness: String,
    #[command(flatten)]
    pub data_args: DataArgs,
}

impl FitArgs {
    /// The fit these arguments ask for; a loss or weighting that names none fails here.
    fn request(&self) -> Result<FitRequest> {
        Ok(FitRequest {
            model: self.model.clone(),
            loss: parse_metric(&self.loss)?,
            weights: parse_weights(&self.weights)?,
            optimizer: self.optimizer,
            restarts: self.restarts,
            seed: self.seed,
            constraints: self.constraints.spec(false)?,
            mc: self.mc,
            mc_scale: self.mc_scale,
            mc_restarts: self.mc_restarts,
            smoothness: self
                .smoothness
                .parse()
                .map_err(|e: String| crate::choice::field_error(format!("{{smoothness}}: {e}")))?,
        })
    }
}

pub fn run(a: FitArgs) -> Result<()> {
    if let Some(path) = &a.json {
        crate::output::check_writable_file(path, "--json")?;
    }
    let request = a.request()?;
    request.check()?;
    anyhow::ensure!(
        !(a.mc > 0 && a.per_axis),
        "--mc and --per-axis cannot be combined"
    );
    let data = a.data_args.read(&a.data)?;
    // A misspelt model, loss or parameter name fails before any work.
    let model = request.preflight(&data, &mut |w| eprintln!("{w}"))?;
    let backend = engine::select(a.backend.backend, &mut |m| eprintln!("{m}"))?;
    let mut mc_error = None;
    let mut run = |data: &Dataset| -> Result<FitReport> {
        let mut progress = Progress::new("fit", a.restarts as u64, "restarts converged");
        progress.set_message(format!("fitting {}", model.spec));
        let mut mc_progress: Option<Progress> = None;
        let total = request.mc_total() as u64;
        let outcome = request.run(data, backend.as_ref(), &mut |stage, active| match stage {
            Stage::Fit => progress.set_position(a.restarts.saturating_sub(active) as u64),
            Stage::MonteCarlo => {
                let bar = mc_progress.get_or_insert_with(|| {
                    progress.finish();
                    let bar = Progress::new("mc", total, "replica restarts converged");
                    bar.set_message(format!("refitting {} replicas", a.mc));
                    bar
                });
                bar.set_position(total.saturating_sub(active as u64))
            }
        })?;
        progress.finish();
        if let Some(mut bar) = mc_progress {
            bar.finish();
        }
        if let Some(line) = &outcome.fallback {
            // Also among the summary's warnings; said here too, beside the other notices.
            eprintln!("{line}");
        }
        print!("{}", outcome.report.summary());
        outcome.check_finite(data, backend.as_ref())?;
        let FitResponse {
            report,
            mc_error: failed,
            ..
        } = outcome;
        if failed.is_some() {
            mc_error = failed;
        }
        Ok(report)
    };
    let json = if a.per_axis {
        // The paper's approach for anisotropic samples (§2.3.2): one fit per φ plane.
        anyhow::ensure!(
            data.axes.len() > 1,
            "--per-axis: {} is measured on a single plane (φ = {}°), so the fit without --per-axis is that plane's fit: drop --per-axis",
            a.data.display(),
            data.axes[0]
        );
        let mut fits = Vec::new();
        for (i, phi) in data.axes.iter().enumerate() {
            println!("== plane φ = {phi}° ==");
            let report = run(&data.axis_subset(i))?;
            fits.push(serde_json::json!({ "phi": phi, "fit": report }));
        }
        serde_json::json!({ "per_axis": fits })
    } else {
        serde_json::to_value(run(&data)?)?
    };
    if let Some(path) = &a.json {
        let text = serde_json::to_string_pretty(&json)? + "\n";
        write_result(path, &text, true)?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(e) = mc_error {
        return Err(e.context("--mc"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    /// `bsdfit fit` without options asks for the library's default fit: the command line
    /// writes no default of its own.
    #[test]
    fn cli_defaults_are_the_library_defaults() {
        let cli = super::super::Cli::try_parse_from(["bsdfit", "fit", "d.csv", "--model", "on"])
            .expect("parses");
        let super::super::Command::Fit(a) = cli.command else {
            panic!("not fit");
        };
        let library = FitRequest {
            model: "on".into(),
            ..FitRequest::default()
        };
        assert_eq!(
            format!("{:?}", a.request().expect("the defaults parse")),
            format!("{library:?}")
        );
    }
}
