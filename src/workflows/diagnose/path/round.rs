//! A round's fits: the candidates the cache lacks, then the check that none of them shows
//! the current fit to have missed its own optimum.

use super::super::fit::{fit_all, refit_from_candidates};
use super::super::regions::flagged_regions;
use super::super::score::consistency;
use super::super::{Candidate, DiagnoseOptions, FitResult, Step};
use super::FitCache;
use crate::data::Dataset;
use crate::engine::Backend;

/// Fit the candidates `cands` of the round after `current` that the cache lacks (none
/// where the round was fitted already: `score_round` asks again).
pub(super) fn fit_round(
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    cache: &mut FitCache,
    current: &FitResult,
    cands: &[Candidate],
) {
    let todo: Vec<Candidate> = cands
        .iter()
        .filter(|c| !cache.contains_key(&c.spec))
        .cloned()
        .collect();
    if todo.is_empty() {
        return;
    }
    let flagged = flagged_regions(data, &current.z);
    let fits = fit_all(&todo, data, backend, opts, current, &flagged);
    for (c, f) in todo.iter().zip(fits) {
        cache.insert(c.spec.clone(), f.map_err(|e| format!("{e:#}")));
    }
}

/// The path's last fit, or its refit where the round's candidates show it had missed its
/// optimum ([`refit_from_candidates`]); the step then says so and holds the refit.
pub(super) fn refit_missed(
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
    cache: &FitCache,
    steps: &mut [Step],
    cands: &[Candidate],
) -> FitResult {
    let step = steps.last_mut().expect("a step");
    let fitted: Vec<&FitResult> = cands
        .iter()
        .filter_map(|c| cache.get(&c.spec)?.as_ref().ok())
        .collect();
    // A refit that fails leaves the path as it was: it is a check, not a step.
    let (refit, from) = match refit_from_candidates(&step.fit, &fitted, data, backend, opts) {
        Ok(Some(found)) => found,
        Ok(None) => return step.fit.clone(),
        Err(e) => {
            log(format!(
                "  {} — its refit failed ({e:#}); kept as fitted",
                step.model
            ));
            return step.fit.clone();
        }
    };
    let words = format!(
        "the fits of {} went below its fit, which had missed its optimum: refitted from their optima without what they add, χ²_red {:.3} → {:.3}",
        from.join(", "),
        step.chi2_red,
        refit.chi2_red
    );
    log(format!("  {} — {words}", step.model));
    let (_, now) = consistency(&refit, opts.alpha);
    step.evidence += &format!(" Then {words}; now {now}.");
    step.chi2_red = refit.chi2_red;
    step.loss = refit.loss;
    step.fit = refit;
    step.fit.clone()
}
