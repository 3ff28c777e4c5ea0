//! What Monte Carlo reports (`fit --mc N`, JSON `monte_carlo`): plain data, kept apart
//! from [`crate::inference::mc`] so that a fit report can hold it while the Monte Carlo
//! driver calls the fit (one direction of dependency: `mc` → `fit` → `mc_summary`).

use serde::Serialize;

/// One flat parameter's Monte Carlo summary.
#[derive(Clone, Debug, Serialize)]
pub struct McParam {
    pub name: String,
    /// Best fit of the measured data.
    pub value: f64,
    pub mean: f64,
    pub sd: f64,
    /// 95 % shortest coverage interval [lo, hi].
    pub interval: [f64; 2],
    /// The linearized standard uncertainty of the fit (None where undetermined).
    pub linear_sd: Option<f64>,
    /// Fraction of replicas whose value lies on a declared bound (within 1e-6 of the
    /// range).
    pub on_bound: f64,
}

/// What `--mc N` reports (JSON `monte_carlo`).
#[derive(Clone, Debug, Serialize)]
pub struct McSummary {
    pub replicas: usize,
    /// Replicas whose refit ended at a finite loss (the statistics use these).
    pub converged: usize,
    pub scale_rel: f64,
    pub seed: u64,
    pub restarts_per_replica: usize,
    pub coverage: f64,
    /// Fitted (free) parameters only; fixed ones have no distribution.
    pub params: Vec<McParam>,
    /// Correlation of the free parameters over the replicas (null where a parameter does
    /// not vary).
    pub correlation: Vec<Vec<Option<f64>>>,
    pub warnings: Vec<String>,
    pub seconds: f64,
    pub evaluations: u64,
    /// Backend evaluators the replicas needed (each optimizer step is one submission per
    /// evaluator).
    pub batches: usize,
}
