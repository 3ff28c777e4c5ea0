//! One fit: a model, a dataset, a loss, multi-start optimisation on a backend, and the
//! report of docs/output.md (best loss, χ²_red, parameters with standard uncertainties).
//!
//! Laid out by job: `options` (what a fit is asked), `unit_box` (the optimizers' view of an
//! evaluator), `starts` (screened random starts), `many` (the lockstep multi-fit driver),
//! `polish` (LM's search settings and the f64 polish), `conclude` (χ² and covariance at
//! the optimum) and `report` (the JSON report). The entry points are here.

mod conclude;
mod many;
mod options;
mod polish;
mod report;
pub mod smoothness;
mod starts;
mod unit_box;

pub use conclude::Conclusions;
pub use many::{fit_many, ManyStats, Optimum, PhaseSeconds};
pub use options::{FitOptions, Optimizer};
pub use polish::{POLISHED_SEARCH_FD_STEP, POLISHED_SEARCH_FTOL, POLISHED_SEARCH_STALL};
pub use report::{Best, FitReport};
pub use smoothness::{Smoothness, SmoothnessChoice};
pub use unit_box::UnitBox;

use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::{Loss, Metric};
use crate::engine::Backend;
use conclude::conclude;
use report::make_report;
use std::time::Instant;

/// Fit `model` to `data` under `loss` and report it (docs/output.md).
pub fn fit(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    backend: &dyn Backend,
    opts: &FitOptions,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<FitReport> {
    let o = fit_outcome(model, data, loss, backend, opts, progress)?;
    Ok(make_report(model, data, loss, opts, backend, o))
}

/// Fit `model` to `data` under `loss`: multi-start optimisation on `backend`, then χ² and
/// the parameter covariance at the best point.
pub fn fit_outcome(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    backend: &dyn Backend,
    opts: &FitOptions,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<Conclusions> {
    let knots = model.flat_decls().iter().any(|d| d.knot);
    if knots && opts.smoothness == Smoothness::Auto && loss.metric == Metric::Chi2 {
        return smoothness::choose(opts, |o| {
            fit_outcome(model, data, loss, backend, o, &mut *progress)
        });
    }
    let t0 = Instant::now();
    let (optima, space, stats) = fit_many(model, &[data], &[loss], backend, opts, progress)?;
    if std::env::var_os("BSDFIT_TRACE").is_some() {
        eprintln!(
            "trace: {:?}, {} evaluations",
            stats.phases, stats.evaluations
        );
    }
    let best = optima.into_iter().next().expect("one problem, one optimum");
    let mut o = conclude(model, data, loss, best, space)?;
    o.seconds = t0.elapsed().as_secs_f64();
    Ok(o)
}

/// Fit one model to several data sets (a sweep's stage: same model and loss term shape,
/// any losses and weightings) in lockstep ([`fit_many`]), then report each fit, with the
/// stage's time per phase. A report's `seconds` are the stage's, shared among its fits by
/// their sample counts; its `evaluations` its own.
pub fn fit_stage(
    model: &Model,
    datas: &[&Dataset],
    losses: &[Loss],
    backend: &dyn Backend,
    opts: &FitOptions,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<(Vec<FitReport>, PhaseSeconds)> {
    let t0 = Instant::now();
    let (optima, space, stats) = fit_many(model, datas, losses, backend, opts, progress)?;
    let mut phases = stats.phases;
    let clock = Instant::now();
    let mut outcomes = Vec::with_capacity(datas.len());
    for ((data, &loss), best) in datas.iter().zip(losses).zip(optima) {
        outcomes.push(conclude(model, data, loss, best, space.clone())?);
    }
    phases.conclusions += clock.elapsed().as_secs_f64();
    let seconds = t0.elapsed().as_secs_f64();
    let total: usize = datas.iter().map(|d| d.len()).sum::<usize>().max(1);
    let reports = outcomes
        .into_iter()
        .zip(datas.iter().zip(losses))
        .map(|(mut o, (data, &loss))| {
            o.seconds = seconds * data.len() as f64 / total as f64;
            make_report(model, data, loss, opts, backend, o)
        })
        .collect();
    Ok((reports, phases))
}
