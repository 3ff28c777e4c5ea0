//! `bsdfit fit`.

use super::checks::{check_batch_memory, nonfinite_message};
use super::progress::Progress;
use super::{BackendArgs, ConstraintArgs, DataArgs};
use crate::bsdf::Model;
use crate::data::{Dataset, Kind};
use crate::engine::{
    self,
    loss::{Loss, Metric, Weights},
};
use crate::inference::fit::{fit, FitOptions, FitReport, Optimizer};
use crate::inference::mc::{monte_carlo, McOptions};
use crate::output::files::write_result;
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

#[derive(Args)]
pub struct FitArgs {
    /// Dataset file (bsdfit CSV v1).
    pub data: PathBuf,
    /// Model spec, e.g. lambert, on, fa(eon), rmg(ggx), btdf(tr)+scale.
    #[arg(long)]
    pub model: String,
    /// Loss. Default chi2 = Σ((y′−y)/u)², which fits BRDF and BTDF data alike: every v1
    /// data file carries a standard uncertainty per value, so χ² weighs each sample by
    /// what it is worth. The paper's losses remain: smape rmse ngan low (BRDF), f cosf
    /// logf logcosf (BTDF).
    #[arg(long, default_value = "chi2")]
    pub loss: String,
    /// Weights: uniform, relunc (BRDF, paper §2.2), invunc (BTDF, paper §2.3.2). chi2
    /// already weighs by 1/u².
    #[arg(long, default_value = "uniform")]
    pub weights: String,
    /// Optimizer. Default: lm (Levenberg–Marquardt) for sum-of-squares losses — chi2 and
    /// every loss but smape — and compass search for smape.
    #[arg(long, value_enum)]
    pub optimizer: Option<Optimizer>,
    /// Number of random restarts (stepped in lockstep); the same default as `diagnose`.
    #[arg(long, default_value_t = super::DEFAULT_RESTARTS, value_parser = super::parse_restarts, allow_hyphen_values = true)]
    pub restarts: usize,
    /// Seed of the random restarts (a non-negative integer).
    #[arg(long, default_value_t = 1, value_parser = super::parse_seed, allow_hyphen_values = true)]
    pub seed: u64,
    #[command(flatten)]
    pub backend: BackendArgs,
    /// Write the fit report (docs/output.md) as JSON here (checked before the fit starts; if
    /// the write fails afterwards, the JSON is printed to stdout instead).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Fit each measured φ plane separately (anisotropic samples, paper §2.3.2); the JSON
    /// is then {"per_axis": [{"phi": …, "fit": report}, …]}.
    #[arg(long)]
    pub per_axis: bool,
    #[command(flatten)]
    pub constraints: ConstraintArgs,
    /// Monte Carlo uncertainty: refit N replicas of the data, each value drawn from
    /// N(value, u²), all replicas stepped together; reports per parameter the mean, σ and
    /// 95 % shortest coverage interval, the correlations, and the linearized σ beside them
    /// (with a warning where they disagree). 0: off.
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub mc: usize,
    /// With --mc: an instrument's fully correlated relative scale uncertainty (e.g. 0.01):
    /// every value of a replica is multiplied by one draw of N(1, REL²).
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "REL",
        allow_hyphen_values = true
    )]
    pub mc_scale: f64,
    /// With --mc: random restarts per replica, besides starting from the best fit.
    #[arg(long, default_value_t = 3, value_name = "R")]
    pub mc_restarts: usize,
    #[command(flatten)]
    pub data_args: DataArgs,
}

/// The loss named by `--loss`/`--weights`, checked against the kind of data.
pub fn parse_loss(loss: &str, weights: &str, kind: Kind) -> Result<Loss> {
    let metric: Metric = loss
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--loss: {e}"))?;
    let weights: Weights = weights
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--weights: {e}"))?;
    anyhow::ensure!(
        metric.applies_to(kind),
        "--loss {metric} is not defined for {kind} data (use one of {:?} or chi2)",
        Metric::for_kind(kind)
            .iter()
            .map(|m| m.to_string())
            .collect::<Vec<_>>()
    );
    Ok(Loss::new(metric, weights))
}

/// The optimizer of `--optimizer`, or the default for the loss: LM where it applies.
pub fn optimizer_for(given: Option<Optimizer>, loss: Loss) -> Optimizer {
    given.unwrap_or(if loss.is_sum_of_squares() {
        Optimizer::Lm
    } else {
        Optimizer::Compass
    })
}

pub fn run(a: FitArgs) -> Result<()> {
    if let Some(path) = &a.json {
        crate::output::check_writable_file(path, "--json")?;
    }
    anyhow::ensure!(
        a.mc == 0 || a.mc >= 2,
        "--mc {}: a distribution needs at least 2 replicas (0 turns Monte Carlo off)",
        a.mc
    );
    anyhow::ensure!(
        a.mc_scale.is_finite() && (0.0..1.0).contains(&a.mc_scale),
        "--mc-scale {}: a relative uncertainty in [0, 1)",
        a.mc_scale
    );
    anyhow::ensure!(
        a.mc > 0 || a.mc_scale == 0.0,
        "--mc-scale needs --mc N (the number of replicas)"
    );
    anyhow::ensure!(
        !(a.mc > 0 && a.per_axis),
        "--mc and --per-axis cannot be combined"
    );
    let data = a.data_args.read(&a.data)?;
    let loss = parse_loss(&a.loss, &a.weights, data.kind)?;
    let model = Model::for_data(&a.model, &data).context("--model")?;
    let constraints = a.constraints.spec(false);
    // Resolve now: a misspelt name fails before any work.
    crate::inference::constraints::Constraints::resolve(&model, &constraints, false)?;
    check_batch_memory(
        a.restarts,
        model.dim,
        data.len(),
        &format!("{} on {}", model.spec, a.data.display()),
        &mut |w| eprintln!("{w}"),
    )?;
    let backend = engine::select(a.backend.backend, &mut |m| eprintln!("{m}"))?;
    let opts = FitOptions {
        optimizer: optimizer_for(a.optimizer, loss),
        restarts: a.restarts,
        seed: a.seed,
        constraints,
        ..Default::default()
    };
    let mut mc_error = None;
    let mut run = |data: &Dataset| -> Result<FitReport> {
        let model = Model::for_data(&a.model, data).context("--model")?;
        let mut progress = Progress::new("fit", a.restarts as u64, "restarts converged");
        progress.set_message(format!("fitting {}", model.spec));
        let mut report = fit(&model, data, loss, backend.as_ref(), &opts, &mut |active| {
            progress.set_position(a.restarts.saturating_sub(active) as u64)
        })?;
        progress.finish();
        let finite = report.best.chi2_red.is_finite() && report.best.loss.is_finite();
        if a.mc > 0 && finite {
            let mc = McOptions {
                replicas: a.mc,
                scale_rel: a.mc_scale,
                seed: a.seed,
                restarts: a.mc_restarts,
            };
            let total = (a.mc * (a.mc_restarts.max(1) + 1)) as u64;
            let mut progress = Progress::new("mc", total, "replica restarts converged");
            progress.set_message(format!("refitting {} replicas", a.mc));
            let outcome = monte_carlo(
                &model,
                data,
                loss,
                backend.as_ref(),
                &opts,
                &report.flat_params,
                &report.flat_std,
                &mc,
                &mut |active| progress.set_position(total.saturating_sub(active as u64)),
            );
            progress.finish();
            match outcome {
                Ok(summary) => report.monte_carlo = Some(summary),
                // The fit itself stands: report it, then fail.
                Err(e) => {
                    report.warnings.push(format!("--mc failed: {e:#}"));
                    mc_error = Some(e);
                }
            }
        }
        print!("{}", report.summary());
        if !finite {
            anyhow::bail!(nonfinite_message(
                &model,
                data,
                loss,
                &report.flat_params,
                report.best.chi2_red,
                report.best.loss,
                backend.as_ref(),
            ));
        }
        Ok(report)
    };
    let json = if a.per_axis {
        // The paper's approach for anisotropic samples (§2.3.2): one fit per φ plane.
        anyhow::ensure!(
            data.axes.len() > 1,
            "--per-axis: {} is measured on a single plane (φ = {}°)",
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
