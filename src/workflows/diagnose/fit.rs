//! Fitting a model for the diagnosis: a multi-start χ² fit and its statistics, and the
//! fits of a round's candidates.

use super::{embed, Candidate, DiagnoseOptions};
use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::normalised_residuals;
use crate::engine::Backend;
use crate::inference::covariance::Covariance;
use crate::inference::fit::{fit_outcome, FitOptions, Optimizer};
use crate::inference::stats::consistency_p;
use anyhow::{Context, Result};

/// One fitted model (χ² statistics, parameters, residuals).
#[derive(Clone, Debug)]
pub struct FitResult {
    pub model: Model,
    pub flat: Vec<f64>,
    /// Model values at the samples.
    pub values: Vec<f64>,
    /// Normalized residuals z = (y′ − y)/u.
    pub z: Vec<f64>,
    /// χ² of the data plus the priors' (`--prior`).
    pub chi2: f64,
    /// Samples + priors − fitted parameters.
    pub dof: usize,
    /// Fitted parameters (the model's, less those fixed by `--fix`).
    pub params: usize,
    pub chi2_red: f64,
    /// Best value of the driving loss.
    pub loss: f64,
    pub cov: Covariance,
    pub seconds: f64,
}

impl FitResult {
    pub fn spec(&self) -> &str {
        &self.model.spec
    }
    /// P(χ²_{K−P} ≥ χ²).
    pub fn p_consistent(&self) -> f64 {
        consistency_p(self.chi2, self.dof)
    }
}

/// Multi-start fit of `model` with extra starting points `seeds` (physical parameters).
pub fn fit_model(
    model: &Model,
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    seeds: &[Vec<f64>],
) -> Result<FitResult> {
    // SMAPE is not a sum of squares: LM cannot fit it, compass can.
    let optimizer = if opts.optimizer == Optimizer::Lm && !opts.loss.is_sum_of_squares() {
        Optimizer::Compass
    } else {
        opts.optimizer
    };
    let fit_opts = FitOptions {
        optimizer,
        restarts: opts.restarts.max(1),
        seed: opts.seed,
        screen: opts.screen,
        initial_points: seeds.to_vec(),
        constraints: opts.constraints.clone(),
        ..Default::default()
    };
    let o = fit_outcome(model, data, opts.loss, backend, &fit_opts, &mut |_| {})?;
    let chi2 = o.chi2 + o.chi2_prior;
    Ok(FitResult {
        model: model.clone(),
        z: normalised_residuals(data, &o.values),
        flat: o.flat,
        values: o.values,
        chi2,
        dof: o.dof,
        params: o.constraints.dim(),
        chi2_red: chi2 / o.dof as f64,
        loss: o.loss,
        cov: o.cov,
        seconds: o.seconds,
    })
}

/// Fit every candidate from the current optimum embedded in its parameters (plus random
/// starts): one after the other, or one thread each with `parallel`.
pub(super) fn fit_all(
    cands: &[Candidate],
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    current: &FitResult,
) -> Vec<Result<FitResult>> {
    let one = |c: &Candidate| -> Result<FitResult> {
        let model = Model::for_data(&c.spec, data)?;
        let seed = embed(&current.model, &current.flat, &model);
        fit_model(&model, data, backend, opts, &[seed])
            .with_context(|| format!("fitting {}", c.spec))
    };
    if opts.parallel && cands.len() > 1 {
        std::thread::scope(|scope| {
            let handles: Vec<_> = cands.iter().map(|c| scope.spawn(move || one(c))).collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or_else(|_| Err(anyhow::anyhow!("a candidate fit panicked")))
                })
                .collect()
        })
    } else {
        cands.iter().map(one).collect()
    }
}
