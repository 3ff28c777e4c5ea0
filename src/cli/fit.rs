//! `bsdfit fit`.

use super::{BackendArgs, DataArgs};
use crate::bsdf::Model;
use crate::data::{Dataset, Kind};
use crate::engine::{
    self,
    loss::{Loss, Metric, Weights},
};
use crate::inference::fit::{fit, FitOptions, FitReport, Optimizer};
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
    /// Loss: smape rmse ngan low (BRDF), f cosf logf logcosf (BTDF), chi2 (any).
    #[arg(long, default_value = "rmse")]
    pub loss: String,
    /// Weights: uniform, relunc (BRDF, paper §2.2), invunc (BTDF, paper §2.3.2).
    #[arg(long, default_value = "uniform")]
    pub weights: String,
    #[arg(long, value_enum, default_value = "compass")]
    pub optimizer: Optimizer,
    /// Number of random restarts (stepped in lockstep).
    #[arg(long, default_value_t = 32)]
    pub restarts: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[command(flatten)]
    pub backend: BackendArgs,
    /// Write the fit report (DESIGN §8) as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Fit each measured φ plane separately (anisotropic samples, paper §2.3.2); the JSON
    /// is then {"per_axis": [{"phi": …, "fit": report}, …]}.
    #[arg(long)]
    pub per_axis: bool,
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

pub fn run(a: FitArgs) -> Result<()> {
    let data = a.data_args.read(&a.data)?;
    let loss = parse_loss(&a.loss, &a.weights, data.kind)?;
    let backend = engine::select(a.backend.backend, &mut |m| eprintln!("{m}"))?;
    let opts = FitOptions {
        optimizer: a.optimizer,
        restarts: a.restarts,
        seed: a.seed,
        ..Default::default()
    };
    let run = |data: &Dataset| -> Result<FitReport> {
        let model = Model::for_data(&a.model, data).context("--model")?;
        let bar = indicatif::ProgressBar::new(a.restarts as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} {msg} [{elapsed_precise}] {bar:30} {pos}/{len} restarts converged",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar.set_message(format!("fitting {}", model.spec));
        let report = fit(&model, data, loss, backend.as_ref(), &opts, &mut |active| {
            bar.set_position((a.restarts - active) as u64)
        })?;
        bar.finish_and_clear();
        print!("{}", report.summary());
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
        let text = serde_json::to_string_pretty(&json)?;
        std::fs::write(path, text).with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    Ok(())
}
