//! The path search: adopt the best significant candidate of each round, continue greedily,
//! and revisit the steps of a path that ends inconsistent ([`diagnose`]).

use super::fit::calibrate_round;
use super::regions::flagged_regions;
use super::score::{consistency, score};
use super::symmetry::frame_test;
use super::{
    describe_regions, extensions, fit_model, Candidate, DiagnoseOptions, Diagnosis, Effect,
    FitResult, RoundSeconds, Scored, Step,
};
use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::Backend;
use crate::inference::stats::format_p;
use anyhow::Result;

mod round;
mod search;
use round::{fit_round, refit_missed};
use search::{analytic_search, note_choice, with_factors};
#[cfg(test)]
use search::{backtrack_alternative, Instead};

/// Every candidate fitted so far in a diagnosis, by spec (a failed fit by its error).
type FitCache = std::collections::HashMap<String, std::result::Result<FitResult, String>>;

/// Candidates whose share of the flagged misfit removed is within this of the best
/// candidate's are tied; the BIC breaks ties.
const REMOVAL_TIE: f64 = 0.10;

/// The candidate to adopt: among the adoptable ones ([`Scored::adoptable`]), the one that
/// removes the largest share of χ² inside the regions the residuals flag — the evidence
/// names the pattern, so the effect adopted must be the one that removes it — with ties
/// (within [`REMOVAL_TIE`]) and rounds without a flagged region decided by the BIC.
fn choose(scored: &[Scored]) -> Option<&Scored> {
    let adoptable: Vec<&Scored> = scored.iter().filter(|s| s.adoptable()).collect();
    let top = adoptable
        .iter()
        .filter_map(|s| s.removal_flagged)
        .fold(f64::NEG_INFINITY, f64::max);
    adoptable
        .into_iter()
        .filter(|s| {
            !top.is_finite() || s.removal_flagged.unwrap_or(f64::NEG_INFINITY) >= top - REMOVAL_TIE
        })
        .min_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic))
}

/// Two effects whose candidates' BICs are closer than this are not told apart: a Bayes
/// factor below e³ ≈ 20 between them (Kass & Raftery's "strong" evidence starts at 6).
/// Naming either would be a guess.
pub const AMBIGUOUS_BIC: f64 = 6.0;

/// The adoptable candidate of another effect than `best`'s that the data tell apart from
/// `best` least, if they do not tell them apart: the two BICs, (χ²_o − χ²_b)/s +
/// (P_o − P_b) ln K with one scale s = max(1, χ²_red of `best`) for both, within
/// [`AMBIGUOUS_BIC`]. (Each candidate's own scale would make two equally good fits look
/// far apart when the misfit is large. A rival that fits as well only with more
/// parameters is told apart by them: measured on the battery, counting it as a tie stops
/// a quarter of the hidden diffuse floors, which a GGX base and a micrograin layer also
/// fit with three more parameters.)
fn rival<'a>(scored: &'a [Scored], best: &Scored, samples: usize) -> Option<&'a Scored> {
    let b = best.fit.as_ref()?;
    let s = b.chi2_red.max(1.0);
    let apart = |o: &Scored| -> f64 {
        let f = o.fit.as_ref().expect("adoptable candidates have fits");
        ((f.chi2 - b.chi2) / s + (f.params as f64 - b.params as f64) * (samples as f64).ln()).abs()
    };
    scored
        .iter()
        .filter(|o| o.adoptable() && o.candidate.effect != best.candidate.effect)
        .min_by(|x, y| apart(x).total_cmp(&apart(y)))
        .filter(|o| apart(o) < AMBIGUOUS_BIC)
}

/// "`M` removes 71 % of χ² within 15° of the retro direction (4 % elsewhere); `N`
/// [effect] removes 12 % there": the adopted candidate against the best of each other
/// effect, in the region the residuals flagged first.
fn removal_words(best: &Scored, scored: &[Scored]) -> String {
    let Some((region, share)) = best.removal.first() else {
        return String::new();
    };
    let pct = |x: f64| format!("{:.0} %", 100.0 * x);
    let mut s = format!(
        "`{}` removes {} of χ² {region}",
        best.candidate.spec,
        pct(*share)
    );
    if best.removal.len() > 1 {
        if let Some(all) = best.removal_flagged {
            s += &format!(" ({} in all flagged regions", pct(all));
            s += &best
                .removal_outside
                .map(|o| format!(", {} elsewhere)", pct(o)))
                .unwrap_or(")".into());
        }
    } else if let Some(o) = best.removal_outside {
        s += &format!(" ({} elsewhere)", pct(o));
    }
    let mut others: Vec<&Scored> = Vec::new();
    for c in scored {
        if c.candidate.effect == best.candidate.effect || c.fit.is_none() {
            continue;
        }
        match others
            .iter_mut()
            .find(|o| o.candidate.effect == c.candidate.effect)
        {
            Some(o) if c.removal.first().map(|r| r.1) > o.removal.first().map(|r| r.1) => *o = c,
            Some(_) => {}
            None => others.push(c),
        }
    }
    others.sort_by(|a, b| {
        let r = |x: &Scored| x.removal.first().map(|r| r.1).unwrap_or(f64::NEG_INFINITY);
        r(b).total_cmp(&r(a))
    });
    for o in others.iter().take(2) {
        if let Some((_, share)) = o.removal.first() {
            s += &format!(
                "; `{}` [{}] removes {} there",
                o.candidate.spec,
                o.candidate.effect,
                pct(*share)
            );
        }
    }
    // The largest misfit comes first: a step that leaves most of it must say so.
    let best_there = scored
        .iter()
        .filter_map(|c| c.removal.first().map(|r| r.1))
        .fold(f64::NEG_INFINITY, f64::max);
    if *share < 0.2 {
        s += &format!(
            ". No candidate explains the largest misfit, {region} (the best removes {} of it): this step is adopted for the smaller misfit it does remove, on the numbers above",
            pct(best_there.max(0.0))
        );
    }
    s
}

/// Build the step that adopts `best` after `current` (its evidence: the test that adopted
/// it, the runner-up of another effect, the consistency verdict and the remaining regions).
fn adopt_step(
    data: &Dataset,
    current: &FitResult,
    best: &Scored,
    scored: &[Scored],
    opts: &DiagnoseOptions,
) -> (Step, bool) {
    let m = scored.len();
    let mut ranked: Vec<&Scored> = scored.iter().filter(|s| s.adoptable()).collect();
    ranked.sort_by(|a, b| a.delta_bic.total_cmp(&b.delta_bic));
    let fit = best.fit.clone().expect("a significant candidate has a fit");
    let effect = best.candidate.effect;
    let test = match (best.f, best.p) {
        (Some(f), Some(p)) => format!(
            "{} over {}: Δχ² = {:.1} for {} more parameter(s), F({}, {}) = {f:.1}, {} ({}), ΔBIC = {:.1}",
            fit.model.spec,
            current.model.spec,
            best.delta_chi2,
            best.dp,
            best.dp,
            fit.dof,
            format_p(p),
            best.p_test.describe(),
            best.delta_bic
        ),
        _ => format!(
            "{} instead of {} (not nested, compared by BIC): Δχ² = {:.1}, ΔBIC = {:.1} (scaled {:.1})",
            fit.model.spec, current.model.spec, best.delta_chi2, best.delta_bic, best.delta_bic_scaled
        ),
    };
    let rank = ranked
        .iter()
        .position(|s| s.candidate.spec == best.candidate.spec)
        .unwrap_or(0);
    let other = ranked.iter().find(|s| s.candidate.effect != effect);
    let runner = match other {
        Some(r) if rank == 0 => format!(
            "; next best {} [{}] ΔBIC {:.1} worse",
            r.candidate.spec,
            r.candidate.effect,
            r.delta_bic - best.delta_bic
        ),
        Some(r) => format!(
            "; {} [{}] fitted better at this step (ΔBIC {:.1} lower) but led to a worse final model",
            r.candidate.spec,
            r.candidate.effect,
            best.delta_bic - r.delta_bic
        ),
        None => String::new(),
    };
    let (ok, text) = consistency(&fit, opts.alpha);
    let regions = describe_regions(data, &fit.z);
    let removal = removal_words(best, scored);
    let removal = if removal.is_empty() {
        String::new()
    } else {
        format!(" Where the residuals pointed: {removal}.")
    };
    let mut notes = String::new();
    if !best.on_bound.is_empty() {
        notes += &format!(" On a bound: {}.", best.on_bound.join("; "));
    }
    if !best.identifiable_note.is_empty() {
        notes += &format!(" Determined: {}.", best.identifiable_note);
    }
    if let Some(t) = best.frame_test.as_ref().filter(|t| t.shows_anisotropy()) {
        notes += &format!(" {}", t.shown_words());
    }
    let siblings: Vec<String> = scored
        .iter()
        .filter(|s| s.candidate.effect == effect && s.candidate.spec != best.candidate.spec)
        .map(|s| match &s.fit {
            Some(f) => format!(
                "`{}` χ²_red = {:.3}, ΔBIC {:+.1} ({})",
                s.candidate.spec, f.chi2_red, s.delta_bic, s.verdict
            ),
            None => format!("`{}` ({})", s.candidate.spec, s.verdict),
        })
        .collect();
    if !siblings.is_empty() {
        notes += &format!(
            " The effect's other models this round: {}.",
            siblings.join("; ")
        );
    }
    let evidence = format!(
        "{} ({}): {test} (best of {m} candidates{runner}).{removal}{notes} Now {text}. {}",
        effect,
        effect.signature(),
        capitalize(&regions)
    );
    let step = Step {
        model: fit.model.spec.clone(),
        effect: Some(effect),
        chi2_red: fit.chi2_red,
        loss: fit.loss,
        evidence,
        fit,
        candidates: vec![],
        round_seconds: None,
        removed: vec![],
    };
    (step, ok)
}

fn log_step(
    log: &mut dyn FnMut(String),
    k: usize,
    step: &Step,
    data: &Dataset,
    opts: &DiagnoseOptions,
) {
    let (_, text) = consistency(&step.fit, opts.alpha);
    log(format!("step {k}: {} — {text}", step.model));
    log(format!(
        "  residuals: {}",
        describe_regions(data, &step.fit.z)
    ));
}

/// Continue a path greedily: fit every extension of its last model, adopt the best
/// significant one, repeat. Returns the path and whether it ended consistent.
fn extend_path(
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
    cache: &mut FitCache,
    mut steps: Vec<Step>,
) -> Result<(Vec<Step>, bool)> {
    loop {
        let current = steps.last().expect("a step").fit.clone();
        if let Some(consistent) = stop_before_round(&mut steps, &current, opts) {
            return Ok((steps, consistent));
        }
        let all = extensions(&current.model.spec, data)?;
        // The data-driven factors are offered after the analytic effects: only in a round
        // where no analytic candidate is adopted (or none exists).
        let (mut driven, analytic): (Vec<Candidate>, Vec<Candidate>) =
            all.into_iter().partition(|c| c.effect.is_data_driven());
        if !opts.data_driven {
            driven.clear();
        }
        let past_budget = factors_only(&steps, opts);
        if past_budget && driven.is_empty() {
            let stopped = stopped_by_budget(&steps, opts);
            steps
                .last_mut()
                .unwrap()
                .evidence
                .push_str(&format!("{stopped}, no data-driven factor left to add"));
            return Ok((steps, consistency(&current, opts.alpha).0));
        }
        let cands = if analytic.is_empty() || past_budget {
            std::mem::take(&mut driven)
        } else {
            analytic
        };
        if cands.is_empty() {
            steps.last_mut().unwrap().evidence.push_str(&format!(
                "{STOPPED}the catalogue has no extension of this model"
            ));
            return Ok((steps, consistency(&current, opts.alpha).0));
        }
        log(format!(
            "  fitting {} candidate extensions of {} on {}",
            cands.len(),
            current.model.spec,
            backend.id()
        ));
        let t0 = std::time::Instant::now();
        fit_round(data, backend, opts, cache, &current, &cands);
        let current = refit_missed(data, backend, opts, log, cache, &mut steps, &cands);
        let fits = t0.elapsed().as_secs_f64();
        let (scored, mut seconds) = score_round(data, backend, opts, log, cache, &current, cands);
        seconds.fits += fits;
        log_round(log, &scored);
        steps.last_mut().unwrap().round_seconds = Some(seconds);
        if std::env::var_os("BSDFIT_TRACE").is_some() {
            eprintln!(
                "trace: round after {}: fits {:.1} s, scoring {:.1} s, bootstraps {:.1} s",
                current.model.spec, seconds.fits, seconds.scoring, seconds.bootstraps
            );
        }
        match pick(&scored, data.len()) {
            Ok(best) => adopt(data, opts, log, &mut steps, &current, &best, scored),
            Err(why) if !driven.is_empty() => {
                let (d, o) = (data, opts);
                if let Some(consistent) =
                    try_factors(d, backend, o, log, cache, &mut steps, scored, driven, &why)
                {
                    return Ok((steps, consistent));
                }
            }
            Err(why) => return Ok(stop(log, steps, &current, scored, &why, opts)),
        }
    }
}

/// The data-driven factors `driven` of the path's last model, fitted after a round whose
/// analytic candidates `scored` adopted nothing (`why`): adopts the best significant one
/// (None: the path goes on) or stops the path saying why (whether it ended consistent).
#[allow(clippy::too_many_arguments)]
fn try_factors(
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
    cache: &mut FitCache,
    steps: &mut Vec<Step>,
    mut scored: Vec<Scored>,
    driven: Vec<Candidate>,
    why: &str,
) -> Option<bool> {
    let current = steps.last().expect("a step").fit.clone();
    log(format!(
        "  → no analytic effect ({why}); trying the data-driven factors"
    ));
    let (more, more_seconds) = score_round(data, backend, opts, log, cache, &current, driven);
    log_round(log, &more);
    let last = steps.last_mut().unwrap();
    match last.round_seconds.as_mut() {
        Some(s) => {
            s.fits += more_seconds.fits;
            s.scoring += more_seconds.scoring;
            s.bootstraps += more_seconds.bootstraps;
        }
        None => last.round_seconds = Some(more_seconds),
    }
    let picked = pick(&more, data.len());
    scored.extend(more);
    match picked {
        Ok(best) => {
            adopt(data, opts, log, steps, &current, &best, scored);
            None
        }
        Err(why_driven) => {
            let why = format!("{why}; no data-driven factor either ({why_driven})");
            let (done, consistent) = stop(log, std::mem::take(steps), &current, scored, &why, opts);
            *steps = done;
            Some(consistent)
        }
    }
}

/// Adopt `best` of a round's `scored` candidates as the path's next step.
fn adopt(
    data: &Dataset,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
    steps: &mut Vec<Step>,
    current: &FitResult,
    best: &Scored,
    scored: Vec<Scored>,
) {
    let (step, _) = adopt_step(data, current, best, &scored, opts);
    log(format!(
        "  → adopt {} [{}]",
        step.model, best.candidate.effect
    ));
    log_step(log, steps.len(), &step, data, opts);
    steps.last_mut().unwrap().candidates = scored;
    steps.push(step);
}

/// How a path's stop is written in its last step's evidence (read back where the
/// data-driven factors go on from an analytic path's end: [`search::with_factors`]).
const STOPPED: &str = ". Stopped: ";

/// End the path at its last model, saying `why`; whether it ended consistent.
fn stop(
    log: &mut dyn FnMut(String),
    mut steps: Vec<Step>,
    current: &FitResult,
    scored: Vec<Scored>,
    why: &str,
    opts: &DiagnoseOptions,
) -> (Vec<Step>, bool) {
    log(format!("  → stop: {why}"));
    let last = steps.last_mut().unwrap();
    last.evidence.push_str(&format!("{STOPPED}{why}"));
    last.candidates = scored;
    (steps, consistency(current, opts.alpha).0)
}

/// Whether a path has used its `--max-steps` effects but may still take a data-driven
/// factor it lacks, and only that: its last step took one and `--factors-past-max-steps`
/// leaves room. The factors come last and at most once each, so the step budget, which
/// bounds the search of the catalogue's effects, would otherwise cut a path between two
/// factors (on NIST's PTFE grid the path's fourth step adopts the coat's Fresnel curve and
/// its fifth the body's profile, χ²_red 3.75 → 0.78).
fn factors_only(steps: &[Step], opts: &DiagnoseOptions) -> bool {
    let effects = steps.len() - 1;
    effects >= opts.max_steps
        && effects < opts.max_steps + opts.factors_past_max_steps
        && opts.data_driven
        && steps
            .last()
            .and_then(|s| s.effect)
            .is_some_and(Effect::is_data_driven)
}

/// Whether a path ends before another round of candidates, and if so whether it ended
/// consistent (its last step saying why it stopped): its last model is consistent and
/// the options say to stop there, or it has taken --max-steps effects (and may take no
/// more factors: [`factors_only`]).
fn stop_before_round(
    steps: &mut [Step],
    current: &FitResult,
    opts: &DiagnoseOptions,
) -> Option<bool> {
    if consistency(current, opts.alpha).0 && opts.stop_when_consistent {
        let last = steps.last_mut().unwrap();
        last.evidence.push_str(if last.effect.is_none() {
            ". Stopped: nothing to add"
        } else {
            ". Stopped: nothing significant remains"
        });
        return Some(true);
    }
    if steps.len() > opts.max_steps && !factors_only(steps, opts) {
        let stopped = stopped_by_budget(steps, opts);
        steps.last_mut().unwrap().evidence.push_str(&stopped);
        return Some(consistency(current, opts.alpha).0);
    }
    None
}

/// The words a path that has used its step budget ends with: how many effects it took
/// and which budget ended it (`--max-steps`, or the factors past it).
fn stopped_by_budget(steps: &[Step], opts: &DiagnoseOptions) -> String {
    let effects = steps.len() - 1;
    if effects > opts.max_steps {
        format!(
            ". Stopped after {effects} effects (--max-steps {} then factors only)",
            opts.max_steps
        )
    } else {
        format!(". Stopped after {effects} effects (--max-steps)")
    }
}

/// Fit and score every candidate extension of `current` against it, the p-values
/// calibrated where the F test does not hold ([`calibrate_round`]). A model met again on
/// another path (backtracking) keeps its first fit from `cache`: each fit is a
/// multi-start search over the same data, its seeds a small part of it.
fn score_round(
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
    cache: &mut FitCache,
    current: &FitResult,
    cands: Vec<Candidate>,
) -> (Vec<Scored>, RoundSeconds) {
    let t0 = std::time::Instant::now();
    fit_round(data, backend, opts, cache, current, &cands);
    let flagged = flagged_regions(data, &current.z);
    let fits: Vec<Result<FitResult>> = cands
        .iter()
        .map(|c| match &cache[&c.spec] {
            Ok(f) => Ok(f.clone()),
            Err(e) => Err(anyhow::anyhow!("{e}")),
        })
        .collect();
    let fitted = std::time::Instant::now();
    let m = cands.len();
    let mut scored: Vec<Scored> = cands
        .into_iter()
        .zip(fits)
        .map(|(c, f)| score(data, current, &flagged, c, f, m, opts))
        .collect();
    test_frames(&mut scored, data, backend, opts, log, cache);
    let scored_at = std::time::Instant::now();
    let samples = data.len();
    calibrate_round(
        &mut scored,
        data,
        backend,
        opts,
        current,
        log,
        &mut |scored, waiting, log| next_to_calibrate(scored, waiting, samples, opts, log),
    );
    let seconds = RoundSeconds {
        fits: (fitted - t0).as_secs_f64(),
        scoring: (scored_at - fitted).as_secs_f64(),
        bootstraps: scored_at.elapsed().as_secs_f64(),
    };
    (scored, seconds)
}

/// Test whether each anisotropic candidate that could be adopted does better than an
/// isotropic lobe of the same shape ([`frame_test`]; at one incidence azimuth, whether its
/// frame breaks the mirror symmetry about the plane of incidence); one that does not is
/// refused, in words. The isotropic twins' fits are cached like the candidates'.
fn test_frames(
    scored: &mut [Scored],
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
    cache: &mut FitCache,
) {
    let could_adopt = |s: &Scored| {
        s.candidate.effect == Effect::Anisotropy
            && s.identifiable
            && s.delta_bic_scaled < 0.0
            && s.fit.is_some()
    };
    if !scored.iter().any(could_adopt) {
        return;
    }
    let coverage = data.azimuth_coverage();
    let turned = data.turned_to_incidence_planes();
    for s in scored.iter_mut().filter(|s| could_adopt(s)) {
        let fit = s.fit.as_ref().expect("could_adopt checks the fit");
        let key = format!(
            "{} [frame turned with the plane of incidence]",
            s.candidate.spec
        );
        let cached = cache.get(&key).and_then(|r| r.as_ref().ok()).cloned();
        match frame_test(
            fit,
            &coverage,
            &turned,
            backend,
            opts,
            s.level,
            cached.as_ref(),
        ) {
            Ok(Some((test, twin))) => {
                log(format!(
                    "    frame test of {}: {} ({})",
                    s.candidate.spec,
                    if test.shows_anisotropy() {
                        "anisotropic"
                    } else {
                        "not told from an isotropic lobe"
                    },
                    test.describe()
                ));
                cache.insert(key, Ok(twin));
                s.set_frame_test(test);
            }
            Ok(None) => {}
            Err(e) => {
                log(format!(
                    "    frame test of {}: the isotropic twin's fit failed ({e:#}); not adopted",
                    s.candidate.spec
                ));
                s.refuse(format!(
                    "its frame could not be tested against an isotropic lobe ({e:#})"
                ));
            }
        }
    }
}

/// The round's choice were the candidates `pending` all significant or all not (a spec,
/// or why the round stops).
fn outcome_if(
    scored: &[Scored],
    pending: &[usize],
    significant: bool,
    samples: usize,
) -> std::result::Result<String, String> {
    let mut v = scored.to_vec();
    for &i in pending {
        v[i].significant = significant;
    }
    pick(&v, samples).map(|s| s.candidate.spec.clone())
}

/// Race the round before each of its bootstraps: where the round adopts the same candidate
/// whether the candidates still `pending` a bootstrap all turn out significant or none
/// does, their tests cannot change the path, and they are deferred ([`Scored::defer`]).
/// Checking the two extremes suffices: adding adoptable candidates can change the choice
/// only by being chosen, by raising the best share of flagged misfit removed (which would
/// have changed one extreme), or by being a rival (which the optimistic extreme sees).
fn defer_undeciding(
    scored: &mut [Scored],
    pending: &[usize],
    samples: usize,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
) {
    if pending.is_empty() || opts.bootstrap.replicates == 0 || opts.calibrate_all {
        return;
    }
    let (Ok(with), Ok(without)) = (
        outcome_if(scored, pending, true, samples),
        outcome_if(scored, pending, false, samples),
    ) else {
        return;
    };
    if with != without {
        return;
    }
    for &i in pending {
        log(format!(
            "    bootstrap of {} deferred: the round adopts {with} whether or not it is significant",
            scored[i].candidate.spec
        ));
        scored[i].defer(format!(
            "the round adopts `{with}` whether or not this candidate is significant (calibrated if a backtrack needs it)"
        ));
    }
}

/// The round's next bootstrap, one at a time ([`calibrate_round`]): the candidates
/// `waiting` for one whose verdict can no longer change the round's choice are deferred
/// first ([`defer_undeciding`]); of the rest, the one the round would adopt were they all
/// significant goes first, so that once it is shown significant its rivals of the same
/// effect (forms whose tests share one null, often all near the same T) need no test of
/// their own. Where no extreme names a winner, the first waiting.
fn next_to_calibrate(
    scored: &mut [Scored],
    waiting: &[usize],
    samples: usize,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
) -> Option<usize> {
    defer_undeciding(scored, waiting, samples, opts, log);
    let waiting: Vec<usize> = waiting
        .iter()
        .copied()
        .filter(|&i| !scored[i].is_deferred())
        .collect();
    let optimistic = outcome_if(scored, &waiting, true, samples).ok();
    waiting
        .iter()
        .copied()
        .find(|&i| optimistic.as_deref() == Some(scored[i].candidate.spec.as_str()))
        .or(waiting.first().copied())
}

/// The round's candidate table in the log: each candidate's fit, test, BIC, share of the
/// flagged misfit removed, fit time and verdict.
fn log_round(log: &mut dyn FnMut(String), scored: &[Scored]) {
    log(format!(
        "    {:<26} {:<14} {:>10} {:>4} {:>10} {:>10} {:<9} {:>10} {:>7} {:>6}  verdict",
        "model", "effect", "χ²_red", "ΔP", "F", "p", "test", "ΔBIC", "flagged", "s"
    ));
    for s in scored {
        log(format!(
            "    {:<26} {:<14} {:>10} {:>4} {:>10} {:>10} {:<9} {:>10.1} {:>7} {:>6.1}  {}",
            s.candidate.spec,
            s.candidate.effect.name(),
            s.fit
                .as_ref()
                .map(|f| format!("{:.3}", f.chi2_red))
                .unwrap_or("-".into()),
            s.dp,
            s.f.map(|f| format!("{f:.1}")).unwrap_or("-".into()),
            s.p.map(|p| format!("{p:.1e}")).unwrap_or("-".into()),
            s.p_test.label(),
            s.delta_bic,
            s.removal_flagged
                .map(|r| format!("{:.0}%", 100.0 * r))
                .unwrap_or("-".into()),
            s.fit.as_ref().map(|f| f.seconds).unwrap_or(0.0),
            s.verdict
        ));
    }
}

/// The candidate the round adopts ([`choose`]), or why the path stops here: no
/// candidate is adoptable, or another effect's candidate explains the misfit as well
/// ([`rival`]) and naming either would be a guess.
fn pick(scored: &[Scored], samples: usize) -> std::result::Result<Scored, String> {
    let Some(best) = choose(scored).cloned() else {
        return Err(if scored.iter().any(|s| s.significant) {
            "the only significant extensions add parameters the data does not determine"
        } else {
            "no extension improves the fit significantly; the remaining misfit is not one of the catalogue's effects, or the geometry cannot separate it"
        }
        .to_string());
    };
    if let Some(rival) = rival(scored, &best, samples) {
        let chi2 = |s: &Scored| s.fit.as_ref().map_or(f64::NAN, |f| f.chi2_red);
        return Err(format!(
            "the data cannot tell two effects apart: `{}` [{}] (χ²_red {:.3}) and `{}` [{}] (χ²_red {:.3}) explain the misfit equally well (their scaled BICs within {AMBIGUOUS_BIC}); measure where they differ to decide",
            best.candidate.spec,
            best.candidate.effect,
            chi2(&best),
            rival.candidate.spec,
            rival.candidate.effect,
            chi2(rival)
        ));
    }
    Ok(best)
}

/// Run the discrepancy workflow from `start` on `data`. `log` receives progress lines
/// (the start fit, each round's candidate table, the decision).
///
/// The path is greedy (the best significant extension at each step). When it ends with
/// the misfit still exceeding the uncertainties, or consistent only through a data-driven
/// factor (then only its analytic steps), each earlier step is revisited once with
/// the best significant candidate of another effect, continued greedily, and the path
/// whose final model has the lowest BIC is reported — the first that ends consistent, if
/// any (an effect can mimic another at first, e.g. rough micrograins a coarsely sampled
/// specular lobe).
///
/// A path that adopted a data-driven factor then drops the analytic effects adopted before
/// it that no longer improve the fit ([`super::prune`]).
///
/// Dense data (more than [`DiagnoseOptions::explore`] samples) are explored on a
/// stratified subsample and the path is confirmed on all of them ([`super::explore`]).
pub fn diagnose(
    data: &Dataset,
    start: &str,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
) -> Result<Diagnosis> {
    if super::explore::dense(data, opts) {
        let sub = super::explore::subsample(data, opts.explore);
        log(format!(
            "exploring on a stratified subsample of {} of the {} samples",
            sub.len(),
            data.len()
        ));
        let explored = diagnose_path(&sub, start, backend, opts, log)?;
        return super::explore::confirm(explored, data, sub.len(), backend, opts, log);
    }
    diagnose_path(data, start, backend, opts, log)
}

/// [`diagnose`] on all of `data`.
fn diagnose_path(
    data: &Dataset,
    start: &str,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
) -> Result<Diagnosis> {
    let model = Model::for_data(start, data).map_err(|e| crate::workflows::fit::model_error(&e))?;
    anyhow::ensure!(
        model.kind == data.kind,
        "model {} is a {} model but the data is {}",
        model.spec,
        model.kind,
        data.kind
    );
    let first = fit_model(&model, data, backend, opts, &[])?;
    let (_, text) = consistency(&first, opts.alpha);
    let regions = describe_regions(data, &first.z);
    let step0 = Step {
        model: model.spec.clone(),
        effect: None,
        chi2_red: first.chi2_red,
        loss: first.loss,
        evidence: format!("{text}. {}", capitalize(&regions)),
        fit: first,
        candidates: vec![],
        round_seconds: None,
        removed: vec![],
    };
    log_step(log, 0, &step0, data, opts);
    let mut cache = FitCache::new();
    // The analytic search first, greedy and then backtracking without the data-driven
    // factors: they are the last resort, tried only where no analytic path ends consistent
    // (and each costs the fits of many knots; a micrograin base first taken for a Fresnel
    // aggregate leaves a misfit a tabulated NDF would absorb, which the backtrack cures).
    let analytic = DiagnoseOptions {
        data_driven: false,
        ..opts.clone()
    };
    let searched = analytic_search(data, backend, &analytic, log, &mut cache, step0)?;
    let greedy = searched.paths[0].clone();
    let mut best_path = if opts.data_driven && !searched.consistent {
        with_factors(data, backend, opts, log, &mut cache, searched)?
    } else {
        searched.paths[searched.best].clone()
    };
    note_choice(log, &greedy, &mut best_path);
    let best_path = super::prune::prune(data, backend, opts, log, best_path)?;
    Ok(Diagnosis::of_steps(
        model.spec.clone(),
        best_path,
        opts.alpha,
        backend.name(),
    ))
}

fn capitalize(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_uppercase().collect::<String>() + c.as_str(),
        None => String::new(),
    }
}

#[cfg(test)]
#[path = "path_tests.rs"]
mod tests;
