//! Backward elimination once a data-driven factor is adopted. The path offers the
//! data-driven factors (`+ndf`, `+fresnel`, `+body`) only after no analytic effect is
//! significant, so an analytic effect adopted earlier may only have stood in for the
//! factor the catalogue lacked: a retroreflective lobe and its falloff for a body that
//! darkens toward grazing, micrograins for a body that brightens there (measured on the
//! bodies of `tests/data_driven_body.rs`). Each analytic step before the last
//! data-driven one is undone in turn, latest first, and refitted from the current optimum
//! (one between two factors too: an analytic effect adopted after one factor may only
//! stand in for the next);
//! where the F test of the removed parameters is not significant at the diagnosis's
//! level, the effect is dropped (stepwise regression's backward step). The path then
//! ends with one more step that names what was dropped and why.

use super::score::consistency;
use super::{describe_regions, fit_model, DiagnoseOptions, Effect, FitResult, Step};
use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::Backend;
use crate::inference::stats::{f_test, format_p};
use anyhow::Result;

/// A spec's core term and its suffixes, split at the `+` outside parentheses:
/// `fa(lambert)+mrm82+falloff` → (`fa(lambert)`, [`mrm82`, `falloff`]).
fn split(spec: &str) -> (String, Vec<String>) {
    let mut parts = vec![String::new()];
    let mut depth = 0i32;
    for c in spec.chars() {
        match c {
            '(' => depth += 1,
            ')' => depth -= 1,
            '+' if depth == 0 => {
                parts.push(String::new());
                continue;
            }
            _ => {}
        }
        parts.last_mut().expect("one part").push(c);
    }
    let core = parts.remove(0);
    (core, parts)
}

fn join(core: &str, suffixes: &[String]) -> String {
    std::iter::once(core)
        .chain(suffixes.iter().map(String::as_str))
        .collect::<Vec<_>>()
        .join("+")
}

/// `current` without what the step from `before` to `after` did: the suffixes it
/// appended, or its change of the core term. None where that cannot be undone alone: the
/// step replaced a suffix, or a later step changed the same core term again.
pub(super) fn without_step(current: &str, before: &str, after: &str) -> Option<String> {
    let (mut core, mut suffixes) = split(current);
    let (b_core, b_suf) = split(before);
    let (a_core, a_suf) = split(after);
    // What the step added, as a multiset difference; it must have removed nothing.
    let mut added = a_suf.clone();
    for s in &b_suf {
        let i = added.iter().position(|x| x == s)?;
        added.remove(i);
    }
    if a_core == b_core {
        if added.is_empty() {
            return None;
        }
        for s in &added {
            let i = suffixes.iter().position(|x| x == s)?;
            suffixes.remove(i);
        }
    } else {
        if core != a_core || !added.is_empty() {
            return None;
        }
        core = b_core;
    }
    Some(join(&core, &suffixes))
}

/// The path with the analytic effects a data-driven factor made redundant dropped (see
/// the module doc); unchanged where no data-driven factor was adopted or every earlier
/// effect is still needed.
pub(super) fn prune(
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    log: &mut dyn FnMut(String),
    mut steps: Vec<Step>,
) -> Result<Vec<Step>> {
    let Some(last_driven) = steps
        .iter()
        .rposition(|s| s.effect.is_some_and(Effect::is_data_driven))
    else {
        return Ok(steps);
    };
    let mut current: FitResult = steps.last().expect("a step").fit.clone();
    let (mut removed, mut verdicts) = (Vec::new(), Vec::new());
    for i in (1..last_driven).rev() {
        let Some(effect) = steps[i].effect.filter(|e| !e.is_data_driven()) else {
            continue;
        };
        let Some(spec) = without_step(current.spec(), &steps[i - 1].model, &steps[i].model) else {
            continue;
        };
        let Ok(model) = Model::for_data(&spec, data) else {
            continue;
        };
        let start = super::embed(&current.model, &current.flat, &model);
        let fit = match fit_model(&model, data, backend, opts, &[start]) {
            Ok(f) => f,
            Err(e) => {
                log(format!(
                    "  ✂ {spec} (without {effect}) could not be fitted: {e:#}"
                ));
                continue;
            }
        };
        let fewer = current.params.saturating_sub(fit.params);
        if fewer == 0 {
            continue;
        }
        let d_chi2 = fit.chi2 - current.chi2;
        let (f, p) = f_test(d_chi2, fewer, current.chi2, current.dof);
        let verdict = format!(
            "without it `{spec}` has Δχ² = {d_chi2:.1} for {fewer} fewer parameter(s), F = {f:.1}, {} (drop if ≥ {})",
            format_p(p),
            opts.alpha
        );
        if p < opts.alpha {
            log(format!(
                "  ✂ {effect} kept beside the data-driven factors: {verdict}"
            ));
            continue;
        }
        log(format!("  ✂ {effect} dropped: {verdict}"));
        removed.push(effect);
        verdicts.push(format!("{effect}: {verdict}"));
        current = fit;
    }
    if removed.is_empty() {
        return Ok(steps);
    }
    let (_, text) = consistency(&current, opts.alpha);
    let driven: Vec<&str> = steps
        .iter()
        .filter_map(|s| s.effect.filter(|e| e.is_data_driven()).map(Effect::name))
        .collect();
    let evidence = format!(
        "Backward elimination: beside the data-driven factors ({}), the earlier effects {} no longer improve the fit significantly; they stood in for a shape the catalogue lacks. {}. Now {text}. {}",
        driven.join(", "),
        removed.iter().map(|e| e.name()).collect::<Vec<_>>().join(", "),
        verdicts.join("; "),
        describe_regions(data, &current.z)
    );
    log(format!("step {}: {} — {text}", steps.len(), current.spec()));
    steps.push(Step {
        model: current.spec().to_string(),
        effect: None,
        chi2_red: current.chi2_red,
        loss: current.loss,
        evidence,
        fit: current,
        candidates: vec![],
        round_seconds: None,
        removed,
    });
    Ok(steps)
}

#[cfg(test)]
mod tests {
    use super::without_step;

    #[test]
    fn a_step_is_undone_in_the_current_spec() {
        // Appended suffixes, with later ones kept.
        assert_eq!(
            without_step(
                "fa(lambert)+mrm82+falloff+body",
                "fa(lambert)+mrm82",
                "fa(lambert)+mrm82+falloff"
            ),
            Some("fa(lambert)+mrm82+body".into())
        );
        assert_eq!(
            without_step("fa(lambert)+mrm82+body", "fa(lambert)", "fa(lambert)+mrm82"),
            Some("fa(lambert)+body".into())
        );
        // A change of the core term.
        assert_eq!(
            without_step("rmg(lambert)+coat+body", "lambert", "rmg(lambert)"),
            Some("lambert+coat+body".into())
        );
        // Not undoable alone: the core changed again later, or the step replaced a suffix.
        assert_eq!(without_step("fa(on)+body", "lambert", "fa(lambert)"), None);
        assert_eq!(
            without_step("lambert+mrm+body", "lambert+retro", "lambert+mrm"),
            None
        );
        // Nothing added.
        assert_eq!(without_step("ggx+body", "ggx", "ggx"), None);
    }

    /// An analytic step between two data-driven factors is tried too. Data from a plain
    /// Fresnel aggregate (`fa(lambert)`); a path that took the body's profile, then a
    /// backscattering base (`fa(vmf)`), then the Fresnel curve: the vMF base adds nothing
    /// the truth has, so beside the factors its removal is not significant and it is
    /// dropped. Eliminating only before the first factor would never try it.
    #[test]
    fn an_analytic_step_between_two_factors_is_eliminated_when_it_adds_nothing() {
        use super::super::{fit_model, testdata, DiagnoseOptions, Effect, Step};
        use crate::bsdf::Model;
        use crate::engine::simd::SimdBackend;
        let rows = testdata::in_plane_rows(&[0.0, 20.0, 40.0, 60.0], false);
        let data = testdata::synthesized("fa(lambert)", "", &rows, (0.01, 1e-3), 3);
        let backend = SimdBackend::new();
        let opts = DiagnoseOptions {
            restarts: 4,
            ..Default::default()
        };
        let last = Model::for_data("fa(vmf)+body+fresnel", &data).unwrap();
        let fit = fit_model(&last, &data, &backend, &opts, &[]).unwrap();
        let path = [
            ("fa(lambert)", None),
            ("fa(lambert)+body", Some(Effect::BodyProfile)),
            ("fa(vmf)+body", Some(Effect::Backscatter)),
            ("fa(vmf)+body+fresnel", Some(Effect::HighlightFresnel)),
        ];
        let steps: Vec<Step> = path
            .iter()
            .map(|&(model, effect)| testdata::step(model, effect, &fit))
            .collect();
        let mut log = Vec::new();
        let pruned = super::prune(&data, &backend, &opts, &mut |l| log.push(l), steps).unwrap();
        let end = pruned.last().unwrap();
        assert_eq!(end.removed, [Effect::Backscatter], "{log:#?}");
        assert_eq!(end.model, "fa(lambert)+body+fresnel", "{log:#?}");
    }
}
