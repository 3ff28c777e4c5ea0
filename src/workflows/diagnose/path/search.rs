//! The order of the search: analytic paths first (the greedy path, then backtracking from
//! each of its steps), the data-driven factors last, at the ends of the analytic paths.

use super::super::fit::calibrate_round;
use super::super::score::consistency;
use super::super::{extensions, Candidate, DiagnoseOptions, Effect, FitResult, Scored, Step};
use super::{adopt_step, extend_path, log_step, try_factors, FitCache, STOPPED};
use crate::data::Dataset;
use crate::engine::Backend;
use crate::inference::stats::bic;
use anyhow::Result;

/// The paths of a search, the greedy one first.
pub(super) struct Searched {
    pub paths: Vec<Vec<Step>>,
    /// The path chosen: the lowest BIC at its end, the first consistent one if any.
    pub best: usize,
    /// Whether the chosen path ends consistent.
    pub consistent: bool,
}

impl Searched {
    fn new(greedy: Vec<Step>, consistent: bool) -> Searched {
        Searched {
            paths: vec![greedy],
            best: 0,
            consistent,
        }
    }
    /// Add `path`; it is chosen where its BIC is lower, or where it is the first that ends
    /// consistent. Whether the search is over (a consistent path is chosen).
    fn add(&mut self, path: Vec<Step>, consistent: bool, k: usize) -> bool {
        let lower = path_bic(&path, k) < path_bic(&self.paths[self.best], k);
        self.paths.push(path);
        if !self.consistent && (lower || consistent) {
            self.best = self.paths.len() - 1;
            self.consistent = consistent;
        }
        self.consistent
    }
}

/// The greedy path from `step0`, and where it ends with the misfit still exceeding the
/// uncertainties, its backtracking ([`backtrack`]) until a path ends consistent.
pub(super) fn analytic_search(
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
    cache: &mut FitCache,
    step0: Step,
) -> Result<Searched> {
    let (greedy, ok) = extend_path(data, backend, opts, log, cache, vec![step0])?;
    let mut searched = Searched::new(greedy, ok);
    if !ok && opts.backtrack {
        let greedy = searched.paths[0].clone();
        backtrack(data, backend, opts, log, cache, &greedy, 0, &mut searched)?;
    }
    Ok(searched)
}

/// Each step of the `greedy` path from round `first` on revisited once with the best
/// significant candidate of another effect (and of another form of the same effect),
/// continued greedily; every path into `searched`, until one ends consistent.
#[allow(clippy::too_many_arguments)]
fn backtrack(
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
    cache: &mut FitCache,
    greedy: &[Step],
    first: usize,
    searched: &mut Searched,
) -> Result<()> {
    let rounds = (first..greedy.len().saturating_sub(1))
        .flat_map(|r| [(r, Instead::OtherEffect), (r, Instead::OtherForm)]);
    for (r, instead) in rounds {
        let adopted = greedy[r + 1].effect;
        let mut scored = greedy[r].candidates.clone();
        let (d, o, fit) = (data, opts, &greedy[r].fit);
        let next = &greedy[r + 1].model;
        let Some(alt) =
            backtrack_alternative(&mut scored, adopted, next, instead, d, backend, o, fit, log)
        else {
            continue;
        };
        let scored = &scored;
        let alt = &scored[alt];
        let end = greedy.last().unwrap();
        log(format!(
            "  ↺ {} ended with χ²_red = {:.3}: trying {} [{}] instead of {next} at step {}",
            end.model,
            end.chi2_red,
            alt.candidate.spec,
            alt.candidate.effect,
            r + 1
        ));
        let mut steps: Vec<Step> = greedy[..=r].to_vec();
        steps[r].candidates = scored.clone();
        let (step, _) = adopt_step(data, &steps[r].fit, alt, scored, opts);
        log_step(log, r + 1, &step, data, opts);
        steps.push(step);
        let (path, consistent) = extend_path(data, backend, opts, log, cache, steps)?;
        if searched.add(path, consistent, data.len()) {
            break;
        }
    }
    Ok(())
}

/// Where no analytic path ends consistent: the data-driven factors at the end of each
/// analytic path that stopped before `--max-steps`, lowest BIC first, each path then
/// continued greedily and backtracked from its first data-driven round on. A path whose
/// last model takes no factor is cut back to its last model that does (on BTDF data a
/// path that swapped `btdf(tr)` for `btdf(gtr)` takes `+ndf` before the swap: only TR's
/// lobe has a data-driven form). The first path that ends consistent wins; else the
/// lowest BIC of all, the analytic paths' included.
pub(super) fn with_factors(
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
    cache: &mut FitCache,
    mut searched: Searched,
) -> Result<Vec<Step>> {
    let k = data.len();
    let paths = &searched.paths;
    let mut open: Vec<usize> = (0..paths.len())
        .filter(|&i| paths[i].len() <= opts.max_steps)
        .collect();
    open.sort_by(|&a, &b| path_bic(&paths[a], k).total_cmp(&path_bic(&paths[b], k)));
    // Each path up to its last model with a factor to try (none: left out).
    let takes_factors = |model: &str| {
        extensions(model, data).is_ok_and(|c| c.iter().any(|c| c.effect.is_data_driven()))
    };
    let cut: Vec<(Vec<Step>, String)> = open
        .iter()
        .filter_map(|&i| {
            let path = &paths[i];
            let last = path.iter().rposition(|s| takes_factors(&s.model))?;
            Some((path[..=last].to_vec(), path.last()?.model.clone()))
        })
        .collect();
    // Two paths can end at the same model (`rmg(lambert)` then `+coat`, or `lambert+coat`
    // then `rmg`): its factors are tried once.
    let mut ends = std::collections::HashSet::new();
    for (path, end) in cut {
        let model = path.last().expect("a step").model.clone();
        if !ends.insert(model.clone()) {
            continue;
        }
        if model != end {
            log(format!(
                "the path's end {end} takes no data-driven factor: back to {model}, its last model that does"
            ));
        }
        let first = path.len() - 1;
        let greedy = factors_at_end(data, backend, opts, log, cache, path)?;
        let consistent = consistency(&greedy.last().expect("a step").fit, opts.alpha).0;
        if searched.add(greedy.clone(), consistent, k) {
            break;
        }
        if opts.backtrack && greedy.len() > first + 1 {
            backtrack(
                data,
                backend,
                opts,
                log,
                cache,
                &greedy,
                first,
                &mut searched,
            )?;
            if searched.consistent {
                break;
            }
        }
    }
    Ok(searched.paths.swap_remove(searched.best))
}

/// The note on a path chosen over the `greedy` one (its last step's evidence and the log).
pub(super) fn note_choice(log: &mut dyn FnMut(String), greedy: &[Step], chosen: &mut [Step]) {
    if chosen.last().unwrap().model == greedy.last().unwrap().model {
        return;
    }
    let k = greedy.last().unwrap().fit.z.len();
    let note = format!(
        ". Chosen over the greedy path {} (final χ²_red = {:.3}, BIC {:.1} higher)",
        greedy
            .iter()
            .map(|s| s.model.as_str())
            .collect::<Vec<_>>()
            .join(" → "),
        greedy.last().unwrap().chi2_red,
        path_bic(greedy, k) - path_bic(chosen, k)
    );
    log(format!("  ↺ chose {}{note}", chosen.last().unwrap().model));
    chosen.last_mut().unwrap().evidence.push_str(&note);
}

/// The data-driven factors tried at the end of an analytic `path`, which stopped with the
/// misfit exceeding the uncertainties; the path then goes on greedily.
fn factors_at_end(
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
    cache: &mut FitCache,
    mut path: Vec<Step>,
) -> Result<Vec<Step>> {
    let last = path.last_mut().expect("a step");
    let driven: Vec<Candidate> = extensions(&last.model, data)?
        .into_iter()
        .filter(|c| c.effect.is_data_driven())
        .collect();
    if driven.is_empty() {
        return Ok(path);
    }
    // The analytic path's stop, said again as the reason the factors are tried.
    let why = match last.evidence.find(STOPPED) {
        Some(i) => last.evidence.split_off(i)[STOPPED.len()..].to_string(),
        None => "no analytic path ends consistent".to_string(),
    };
    log(format!(
        "no analytic path ends consistent; the data-driven factors on {}",
        last.model
    ));
    let scored = std::mem::take(&mut last.candidates);
    let (d, o) = (data, opts);
    if try_factors(d, backend, o, log, cache, &mut path, scored, driven, &why).is_some() {
        return Ok(path);
    }
    Ok(extend_path(data, backend, opts, log, cache, path)?.0)
}

/// BIC of a path's final model: χ² + P ln K.
fn path_bic(steps: &[Step], k: usize) -> f64 {
    let f = &steps.last().expect("a step").fit;
    bic(f.chi2, f.params, k)
}

/// Which candidates of a round a backtrack may try instead of the one it adopted.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(super) enum Instead {
    /// Another effect.
    OtherEffect,
    /// Another model of the same effect (`fa(lambert)` for `lambert+coat`: the adopted
    /// form of a specular lobe can be the wrong one — a conductor's highlight is first
    /// taken by a coat, whose blend then leaves the body's Fresnel dimming to false
    /// grazing and retro effects).
    OtherForm,
}

/// The candidate a backtrack tries at a round that adopted `adopted` (`adopted_spec`):
/// the adoptable one of another effect, or of the same effect in another model, with the
/// lowest ΔBIC, deferred tests calibrated now where they could be it (an index into
/// `scored`).
#[allow(clippy::too_many_arguments)]
pub(super) fn backtrack_alternative(
    scored: &mut [Scored],
    adopted: Option<Effect>,
    adopted_spec: &str,
    instead: Instead,
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    current: &FitResult,
    log: &mut dyn FnMut(String),
) -> Option<usize> {
    let mut order: Vec<usize> = (0..scored.len())
        .filter(|&i| {
            let s = &scored[i];
            let wanted = match instead {
                Instead::OtherEffect => Some(s.candidate.effect) != adopted,
                Instead::OtherForm => {
                    Some(s.candidate.effect) == adopted && s.candidate.spec != adopted_spec
                }
            };
            wanted && (s.adoptable() || s.is_deferred())
        })
        .collect();
    order.sort_by(|&a, &b| scored[a].delta_bic.total_cmp(&scored[b].delta_bic));
    for i in order {
        if scored[i].is_deferred() {
            scored[i].undefer();
            calibrate_round(
                std::slice::from_mut(&mut scored[i]),
                data,
                backend,
                opts,
                current,
                log,
                &mut |_, waiting, _| waiting.first().copied(),
            );
        }
        if scored[i].adoptable() {
            return Some(i);
        }
    }
    None
}
