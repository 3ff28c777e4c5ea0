//! Comparing a fitted candidate with the current model: the F test (nested), the BIC, the
//! identifiability of the new parameters, and the consistency test of a fit.

use super::regions::RegionStat;
use super::{Candidate, FitResult};
use crate::bsdf::Model;
use crate::data::Dataset;
use crate::inference::stats::{self, f_test, format_p};
use anyhow::Result;

/// A fitted candidate and its comparison with the current model.
#[derive(Clone, Debug)]
pub struct Scored {
    pub candidate: Candidate,
    pub fit: Option<FitResult>,
    /// Extra parameters over the current model.
    pub dp: i64,
    pub delta_chi2: f64,
    /// F statistic and its p-value (nested candidates).
    pub f: Option<f64>,
    pub p: Option<f64>,
    /// BIC(candidate) − BIC(current), χ² taken as is.
    pub delta_bic: f64,
    /// The same with both χ² divided by max(1, χ²_red of the candidate).
    pub delta_bic_scaled: f64,
    pub significant: bool,
    pub identifiable: bool,
    /// New parameters that ended on a bound of their range (a step that needs them there
    /// is not adopted: the optimum lies outside what the model can express).
    pub on_bound: Vec<String>,
    /// Share of the current model's χ² removed inside each flagged region (region words,
    /// fraction; negative where the candidate fits that region worse).
    pub removal: Vec<(String, f64)>,
    /// Share removed inside the flagged regions together, and outside them; None when no
    /// region is flagged or the fit failed.
    pub removal_flagged: Option<f64>,
    pub removal_outside: Option<f64>,
    pub verdict: String,
}

impl Scored {
    /// Significant, its new parameters determined and inside their ranges.
    pub fn adoptable(&self) -> bool {
        self.significant && self.identifiable && self.on_bound.is_empty()
    }
}

/// The flat names of a candidate's parameters that the current model lacks.
fn new_param_indices(old: &Model, new: &Model) -> Vec<usize> {
    let old_names: Vec<String> = old.flat_names();
    let names = new.flat_names();
    let is_old = |n: &str| {
        old_names.iter().any(|o| {
            o == n || n.strip_prefix("base.") == Some(o) || n.strip_prefix("lobe.") == Some(o)
        })
    };
    (0..names.len()).filter(|&j| !is_old(&names[j])).collect()
}

/// New parameters within 1e-6 of an edge of their unit box.
fn new_params_on_bound(old: &Model, fit: &FitResult) -> Vec<String> {
    let names = fit.model.flat_names();
    let decls = fit.model.flat_decls();
    new_param_indices(old, &fit.model)
        .into_iter()
        .filter(|&j| {
            let u = decls[j].to_unit(fit.flat[j]);
            // Sitting at the neutral value on a bound is the current model, not a new
            // effect held back by the range; that is judged by significance instead.
            let neutral = decls[j]
                .neutral
                .is_some_and(|v| (v - fit.flat[j]).abs() <= 1e-9 * v.abs().max(1.0));
            !(1e-6..=1.0 - 1e-6).contains(&u) && !neutral
        })
        .map(|j| format!("{} = {:.4}", names[j], fit.flat[j]))
        .collect()
}

/// How much of the current misfit a candidate removes inside each flagged region, in them
/// together, and outside them.
#[allow(clippy::type_complexity)]
fn removal(
    flagged: &[RegionStat],
    current: &FitResult,
    fit: &FitResult,
) -> (Vec<(String, f64)>, Option<f64>, Option<f64>) {
    if flagged.is_empty() {
        return (vec![], None, None);
    }
    let share = |before: f64, after: f64| {
        if before > 0.0 {
            1.0 - after / before
        } else {
            0.0
        }
    };
    let per: Vec<(String, f64)> = flagged
        .iter()
        .map(|r| (r.words.clone(), share(r.chi2(&current.z), r.chi2(&fit.z))))
        .collect();
    let inside = |k: usize| flagged.iter().any(|r| r.contains(k));
    let (mut b_in, mut a_in, mut b_out, mut a_out) = (0.0, 0.0, 0.0, 0.0);
    for (k, (zb, za)) in current.z.iter().zip(&fit.z).enumerate() {
        if inside(k) {
            b_in += zb * zb;
            a_in += za * za;
        } else {
            b_out += zb * zb;
            a_out += za * za;
        }
    }
    (per, Some(share(b_in, a_in)), Some(share(b_out, a_out)))
}

/// Whether the extension's new parameters are determined: at least one of them has a
/// standard uncertainty within its range and a multiple correlation with the others
/// below 0.999.
fn new_params_determined(old: &Model, fit: &FitResult) -> (bool, String) {
    let names = fit.model.flat_names();
    let decls = fit.model.flat_decls();
    let new_idx = new_param_indices(old, &fit.model);
    if new_idx.is_empty() {
        return (true, String::new());
    }
    let p = names.len();
    let det: Vec<usize> = (0..p)
        .filter(|&j| fit.cov.std[j].is_some_and(|s| s > 0.0))
        .collect();
    let c = nalgebra::DMatrix::from_fn(det.len(), det.len(), |a, b| {
        fit.cov.correlation[det[a]][det[b]].unwrap_or(0.0)
    });
    let ci = c.try_inverse();
    let mut bad = Vec::new();
    let mut ok = false;
    for &j in &new_idx {
        let Some(s) = fit.cov.std[j] else {
            bad.push(format!("{} undetermined", names[j]));
            continue;
        };
        if s > decls[j].hi - decls[j].lo {
            bad.push(format!("{} ± {s:.2e} exceeds its range", names[j]));
            continue;
        }
        let r = match (&ci, det.iter().position(|&d| d == j)) {
            (Some(ci), Some(a)) if ci[(a, a)] > 1.0 => (1.0 - 1.0 / ci[(a, a)]).sqrt(),
            _ => 0.0,
        };
        if r > 0.999 {
            bad.push(format!(
                "{} not separable from the other parameters (multiple correlation {r:.4})",
                names[j]
            ));
            continue;
        }
        ok = true;
    }
    (ok, bad.join(", "))
}

pub(super) fn score(
    data: &Dataset,
    current: &FitResult,
    flagged: &[RegionStat],
    candidate: Candidate,
    fit: Result<FitResult>,
    m: usize,
    alpha: f64,
) -> Scored {
    let k = data.len();
    let fit = match fit {
        Ok(f) => f,
        Err(e) => {
            return Scored {
                candidate,
                fit: None,
                dp: 0,
                delta_chi2: 0.0,
                f: None,
                p: None,
                delta_bic: f64::INFINITY,
                delta_bic_scaled: f64::INFINITY,
                significant: false,
                identifiable: false,
                on_bound: vec![],
                removal: vec![],
                removal_flagged: None,
                removal_outside: None,
                verdict: format!("fit failed: {e:#}"),
            }
        }
    };
    let dp = fit.params as i64 - current.params as i64;
    let delta_chi2 = current.chi2 - fit.chi2;
    let s = fit.chi2_red.max(1.0);
    let delta_bic = stats::delta_bic(current.chi2, fit.chi2, dp, k, 1.0);
    let delta_bic_scaled = stats::delta_bic(current.chi2, fit.chi2, dp, k, s);
    let (f, p) = if candidate.nested && dp > 0 {
        let (fstat, p) = f_test(delta_chi2, dp as usize, fit.chi2, fit.dof);
        (Some(fstat), Some(p))
    } else {
        (None, None)
    };
    let level = alpha / m.max(1) as f64;
    let significant = match p {
        Some(p) => p < level && delta_bic_scaled < 0.0,
        None => delta_bic_scaled < -10.0,
    };
    let (identifiable, why) = new_params_determined(&current.model, &fit);
    let on_bound = new_params_on_bound(&current.model, &fit);
    let (removal, removal_flagged, removal_outside) = removal(flagged, current, &fit);
    let verdict = if !significant {
        match p {
            Some(p) => format!(
                "not significant ({}, need < {level:.1e}; scaled ΔBIC {delta_bic_scaled:+.1})",
                format_p(p)
            ),
            None => {
                format!("not significant (swap: scaled ΔBIC {delta_bic_scaled:+.1}, need < −10)")
            }
        }
    } else if !identifiable {
        format!("significant but not identifiable: {why}")
    } else if !on_bound.is_empty() {
        format!(
            "significant but a new parameter ends on a bound: {}",
            on_bound.join(", ")
        )
    } else {
        "significant".into()
    };
    Scored {
        candidate,
        fit: Some(fit),
        dp,
        delta_chi2,
        f,
        p,
        delta_bic,
        delta_bic_scaled,
        significant,
        identifiable,
        on_bound,
        removal,
        removal_flagged,
        removal_outside,
        verdict,
    }
}

/// The consistency test of a fit: P(χ²_{K−P} ≥ χ²) ≥ α, and its verdict in words.
pub(super) fn consistency(fit: &FitResult, alpha: f64) -> (bool, String) {
    let p = fit.p_consistent();
    let ok = p >= alpha;
    let verdict = if ok {
        "consistent with the uncertainties"
    } else {
        "the misfit exceeds the uncertainties"
    };
    (
        ok,
        format!(
            "χ²_red = {:.3} on {} dof: {verdict} ({}, α = {alpha})",
            fit.chi2_red,
            fit.dof,
            format_p(p)
        ),
    )
}
