//! Dense data: explore on a stratified subsample, confirm on all data.
//!
//! A round fits every candidate extension with many restarts: on a dense scan (80,000
//! samples of a retroreflective tape) that took 500 s on two cores. The search for the
//! path — which effect, which model — needs far fewer samples than the final numbers do,
//! so `diagnose` runs it on a stratified subsample of [`DiagnoseOptions::explore`]
//! samples (every angular stratum kept in proportion), then refits the path's models on
//! all the data, each from its subsample optimum, and judges each step again there with
//! the same F test and BIC: a step that the full data do not confirm ends the path. The
//! staircase reported is the full data's.

use super::fit::FitResult;
use super::score::consistency;
use super::{describe_regions, fit_model, DiagnoseOptions, Diagnosis, Step};
use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::Backend;
use crate::inference::stats::{delta_bic, f_test, format_p};
use anyhow::Result;

/// Whether `data` is dense enough to explore on a subsample ([`subsample`]): a quarter
/// more samples than the subsample would hold.
pub(super) fn dense(data: &Dataset, opts: &DiagnoseOptions) -> bool {
    opts.explore > 0 && data.len() > opts.explore + opts.explore / 4
}

/// About `n` samples of `data`, deterministic and stratified: the samples are binned by
/// incidence (1°), outgoing polar angle (5°), outgoing azimuth relative to the incidence
/// plane (30°) and channel, and each bin keeps the same share of its samples, evenly
/// spaced through it (at least one), so every part of the scan keeps its weight.
pub fn subsample(data: &Dataset, n: usize) -> Dataset {
    let share = (n as f64 / data.len().max(1) as f64).min(1.0);
    let key = |k: usize| {
        let s = &data.samples[k];
        let dphi = (s.phi_o - s.phi_i).to_degrees().rem_euclid(360.0);
        (
            s.theta_i.to_degrees().round() as i64,
            (s.theta_o.to_degrees() / 5.0).floor() as i64,
            (dphi / 30.0).floor() as i64,
            s.channel,
            s.transmitted,
        )
    };
    let mut order: Vec<usize> = (0..data.len()).collect();
    order.sort_by_key(|&k| key(k));
    let mut keep = Vec::with_capacity(n + n / 8);
    let mut start = 0;
    while start < order.len() {
        let k0 = key(order[start]);
        let mut end = start + 1;
        while end < order.len() && key(order[end]) == k0 {
            end += 1;
        }
        let len = end - start;
        let take = ((len as f64 * share).round() as usize).clamp(1, len);
        for i in 0..take {
            keep.push(order[start + (2 * i + 1) * len / (2 * take)]);
        }
        start = end;
    }
    keep.sort_unstable();
    let mut sub = data.clone();
    sub.samples = keep.iter().map(|&k| data.samples[k].clone()).collect();
    sub.notices.clear();
    sub
}

/// Refit the explored path's models on all of `data`, each from its subsample optimum,
/// and judge every step again against the one before: the F test (nested steps) at the
/// level the exploration held it to, and the BIC scaled as there. The path ends at the
/// first step the full data do not confirm. Returns the confirmed diagnosis.
pub(super) fn confirm(
    explored: Diagnosis,
    data: &Dataset,
    explored_on: usize,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
) -> Result<Diagnosis> {
    log(format!(
        "confirming the path on all {} samples (explored on {explored_on})",
        data.len()
    ));
    // Each model continues from its subsample optimum: a local refit, not a new search.
    let local = DiagnoseOptions {
        restarts: 1,
        screen: 1,
        ..opts.clone()
    };
    let mut steps: Vec<Step> = Vec::with_capacity(explored.steps.len());
    let mut prev: Option<FitResult> = None;
    // The candidates of the round that adopted a step: the previous step's.
    let mut round = 1;
    for (k, step) in explored.steps.into_iter().enumerate() {
        let model = Model::for_data(&step.model, data)?;
        let full = fit_model(
            &model,
            data,
            backend,
            &local,
            std::slice::from_ref(&step.fit.flat),
        )?;
        let (ok, text) = consistency(&full, opts.alpha);
        let regions = describe_regions(data, &full.z);
        let mut evidence = step.evidence.clone();
        if let Some(p) = &prev {
            let dp = full.params as i64 - p.params as i64;
            let level = opts.alpha / round.max(1) as f64;
            let (verdict, confirmed) = judge(p, &full, dp, data.len(), level);
            log(format!("  step {k}: {} on all data: {verdict}", step.model));
            if !confirmed {
                let last: &mut Step = steps.last_mut().expect("step 0 precedes");
                last.evidence.push_str(&format!(
                    ". Stopped: the next step the subsample found, {} [{}], is not confirmed on all {} samples ({verdict})",
                    step.model,
                    step.effect.map(|e| e.name()).unwrap_or("-"),
                    data.len()
                ));
                break;
            }
            evidence = format!(
                "{evidence} Confirmed on all {} samples: {verdict}; now {text}. {}",
                data.len(),
                regions
            );
        } else {
            log(format!("  step 0: {} on all data: {text}", step.model));
            evidence = format!(
                "On all {} samples: {text}. {}. (The path was explored on a stratified subsample of {explored_on} samples, each step then confirmed on all data.) Explored: {}",
                data.len(),
                regions,
                step.evidence
            );
        }
        let _ = ok;
        round = step.candidates.len();
        prev = Some(full.clone());
        steps.push(Step {
            model: step.model,
            effect: step.effect,
            chi2_red: full.chi2_red,
            loss: full.loss,
            evidence,
            fit: full,
            candidates: step.candidates,
            round_seconds: step.round_seconds,
            removed: step.removed,
        });
    }
    Ok(Diagnosis::of_steps(
        explored.start_model,
        steps,
        explored.alpha,
        explored.backend,
    ))
}

/// A step from `before` to `after` judged on all data: F test and scaled BIC for a
/// nested step (one with more parameters), the scaled BIC by more than 10 otherwise.
fn judge(before: &FitResult, after: &FitResult, dp: i64, k: usize, level: f64) -> (String, bool) {
    let d_chi2 = before.chi2 - after.chi2;
    let scale = after.chi2_red.max(1.0);
    let dbic = delta_bic(before.chi2, after.chi2, dp, k, scale);
    if dp > 0 {
        let (f, p) = f_test(d_chi2, dp as usize, after.chi2, after.dof);
        let ok = p < level && dbic < 0.0;
        (
            format!(
                "Δχ² = {d_chi2:.1} for {dp} more parameter(s), F = {f:.1}, {} (need < {level:.1e}), scaled ΔBIC {dbic:+.1}",
                format_p(p)
            ),
            ok,
        )
    } else {
        (
            format!("Δχ² = {d_chi2:.1}, scaled ΔBIC {dbic:+.1} (need < −10)"),
            dbic < -10.0,
        )
    }
}
