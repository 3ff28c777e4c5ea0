//! `bsdfit diagnose`.

use super::{BackendArgs, DataArgs};
use crate::engine::{
    self,
    loss::{Loss, Metric, Weights},
};
use crate::inference::fit::Optimizer;
use crate::workflows::diagnose::{diagnose, write_report, DiagnoseOptions};
use anyhow::{Context, Result};
use clap::Args;
use std::path::PathBuf;

/// `bsdfit diagnose DATA --model START [--json OUT] [--report DIR]`.
#[derive(Args, Clone, Debug)]
pub struct DiagnoseArgs {
    /// Dataset file (bsdfit CSV v1).
    pub data: PathBuf,
    /// Start model spec, e.g. lambert, on, btdf(beckmann).
    #[arg(long)]
    pub model: String,
    /// Loss that drives each fit (the statistics always use χ²).
    #[arg(long, default_value = "chi2")]
    pub loss: String,
    #[arg(long, default_value = "uniform")]
    pub weights: String,
    #[arg(long, value_enum, default_value = "lm")]
    pub optimizer: Optimizer,
    /// Random restarts per fit (plus the current optimum as one more start).
    #[arg(long, default_value_t = 16)]
    pub restarts: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Significance level (consistency test; F tests at α / number of candidates).
    #[arg(long, default_value_t = 0.01)]
    pub alpha: f64,
    /// Most effects to add.
    #[arg(long, default_value_t = 4)]
    pub max_steps: usize,
    #[command(flatten)]
    pub backend: BackendArgs,
    /// Write the diagnosis (DESIGN §8) as JSON here.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write residual maps, the χ²_red staircase and the candidate tables here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    #[command(flatten)]
    pub data_args: DataArgs,
    /// Keep the greedy path even when it ends with the misfit exceeding the uncertainties
    /// (by default each step is then revisited once with another effect's best candidate).
    #[arg(long)]
    pub no_backtrack: bool,
    /// Fit a round's candidates concurrently, one thread each (pays off on a real GPU; on a
    /// software device such as lavapipe, or the CPU backend, it only adds contention).
    #[arg(long)]
    pub parallel: bool,
}

pub fn run(a: &DiagnoseArgs) -> Result<()> {
    let data = a.data_args.read(&a.data)?;
    let metric: Metric = a
        .loss
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--loss: {e}"))?;
    let weights: Weights = a
        .weights
        .parse()
        .map_err(|e: String| anyhow::anyhow!("--weights: {e}"))?;
    anyhow::ensure!(
        metric.applies_to(data.kind),
        "--loss {metric} is not defined for {} data",
        data.kind
    );
    anyhow::ensure!(a.alpha > 0.0 && a.alpha < 1.0, "--alpha must be in (0, 1)");
    let backend = engine::select(a.backend.backend, &mut |m| eprintln!("{m}"))?;
    let opts = DiagnoseOptions {
        loss: Loss::new(metric, weights),
        optimizer: a.optimizer,
        restarts: a.restarts,
        seed: a.seed,
        alpha: a.alpha,
        max_steps: a.max_steps,
        parallel: a.parallel,
        backtrack: !a.no_backtrack,
        ..Default::default()
    };
    println!(
        "diagnose {} ({} samples, {} channel(s), {} plane(s)) from {}",
        data.material,
        data.len(),
        data.channel_count(),
        data.axes.len(),
        a.model
    );
    let d = diagnose(&data, &a.model, backend.as_ref(), &opts, &mut |line| {
        println!("{line}")
    })?;
    println!(
        "effects: {}\nfinal model: {}",
        if d.effects.is_empty() {
            "none".to_string()
        } else {
            d.effects
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(", ")
        },
        d.final_model
    );
    println!(
        "χ²_red: {}",
        d.steps
            .iter()
            .map(|s| format!("{:.3}", s.chi2_red))
            .collect::<Vec<_>>()
            .join(" → ")
    );
    if let Some(path) = &a.json {
        std::fs::write(path, serde_json::to_string_pretty(&d.to_json())?)
            .with_context(|| format!("cannot write {}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(dir) = &a.report {
        write_report(dir, &data, &d)?;
        eprintln!("wrote {}", dir.join("index.html").display());
    }
    Ok(())
}
