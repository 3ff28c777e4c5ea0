//! What a fit found at its optimum: χ², the parameter covariance and the warnings,
//! computed in f64 on the CPU reference.

use super::Optimum;
use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::{chi2, Loss};
use crate::engine::{Backend, Problem};
use crate::inference::constraints::Constraints;
use crate::inference::covariance::{covariance, Covariance};
use std::time::Instant;

/// What a fit found, before it is dressed as a [`FitReport`](super::FitReport).
#[derive(Clone, Debug)]
pub struct Conclusions {
    /// Best physical parameter vector.
    pub flat: Vec<f64>,
    /// Its loss.
    pub loss: f64,
    /// Model values at the best parameters, one per sample.
    pub values: Vec<f64>,
    /// χ² = Σ ((y′ − y)/u)² at the best parameters.
    pub chi2: f64,
    /// Σ ((θ − mean)/sd)² of the priors at the best parameters (0 without priors).
    pub chi2_prior: f64,
    /// Degrees of freedom: samples + priors − fitted parameters.
    pub dof: usize,
    /// The constraints the fit was made under.
    pub constraints: Constraints,
    pub cov: Covariance,
    /// Restarts whose final loss is within 1% of the best.
    pub within: usize,
    pub evaluations: u64,
    pub seconds: f64,
    /// Why the best restart stopped.
    pub stop: crate::optim::Stop,
    /// How the smoothness prior's σ_s was chosen ([`super::Smoothness::Auto`]).
    pub smoothness: Option<super::SmoothnessChoice>,
}

/// χ², the covariance and the warnings at a problem's optimum, in f64 on the CPU
/// reference whatever the search ran on.
///
/// Why not on the search's backend: they take one point and its 2P central-difference
/// neighbours, a few hundred thousand evaluations at most, which a device serves in a
/// handful of latency-bound submissions plus an evaluator (upload, buffers) per fit (on
/// lavapipe the conclusions took 7.9 s of the default sweep's 52 s of thread time, against
/// 2.5 s on the CPU); and f32 central differences leave the covariance's Jacobian with
/// relative errors of ~u/1e-4 ≈ 6e-4, where f64 gives ~1e-8.
pub(super) fn conclude(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    best: Optimum,
    space: Constraints,
) -> anyhow::Result<Conclusions> {
    let t0 = Instant::now();
    let cpu = crate::engine::cpu::CpuBackend::new();
    let mut eval = cpu.prepare(Problem { model, data, loss })?;
    let mut flat = best.flat;
    // One form of each anisotropic surface (|φ0| ≤ 45°) where its parameters are free
    // within their declared bounds: the values, and so the loss, are the same.
    let declared = model.flat_decls();
    let prior_on = |j: usize| space.priors.iter().any(|p| p.index == j);
    model.canonical_form(&mut flat, |j| {
        space.fixed[j].is_none() && space.decls[j] == declared[j] && !prior_on(j)
    });
    let searched = best.evaluations;
    let values = eval.values(&flat)?;
    let chi2 = chi2(data, &values);
    let mut cov = covariance(model, data, loss, eval.as_mut(), &flat, &space)?;
    cov.warnings.extend(space.on_bound_warnings(&flat));
    Ok(Conclusions {
        loss: best.loss,
        chi2_prior: space.prior_chi2(&flat),
        dof: data.len() + space.prior_rows() - space.dim(),
        constraints: space,
        flat,
        values,
        chi2,
        cov,
        within: best.within,
        stop: best.stop,
        smoothness: None,
        evaluations: searched + eval.evaluations(),
        seconds: t0.elapsed().as_secs_f64(),
    })
}
