//! Unit tests of the path search's racing of bootstraps.

use super::*;
use crate::data::Kind;
use crate::workflows::diagnose::score::PTest;
use crate::workflows::diagnose::testdata;

/// A scored candidate, laid out by hand: significant (decided) or waiting for a bootstrap
/// (`pending`: an irregular null whose nominal p is not settled), its ΔBIC, share of the
/// flagged misfit removed, and χ² with its parameter count.
fn scored(spec: &str, effect: Effect, pending: bool, dbic: f64, removal: f64, chi2: f64) -> Scored {
    let data = testdata::dataset(Kind::Brdf, &[[10.0, 0.0, 30.0, 0.0]], 1);
    let model = Model::for_data(spec, &data).unwrap();
    let params = model.dim;
    let fit = FitResult {
        model,
        flat: vec![],
        values: vec![],
        z: vec![],
        chi2,
        dof: 100,
        params,
        chi2_red: chi2 / 100.0,
        loss: chi2,
        cov: Default::default(),
        seconds: 0.0,
        note: None,
        smoothness: None,
    };
    Scored {
        candidate: Candidate {
            spec: spec.into(),
            effect,
            nested: true,
        },
        fit: Some(fit),
        dp: 1,
        delta_chi2: 10.0,
        f: Some(10.0),
        p: Some(1e-5),
        p_nominal: Some(1e-5),
        p_test: if pending {
            PTest::FNominal("the bootstrap was not run".into())
        } else {
            PTest::F
        },
        irregular: pending.then(|| "on a bound".to_string()),
        level: 1e-3,
        delta_bic: dbic,
        delta_bic_scaled: dbic,
        significant: true,
        identifiable: true,
        identifiable_why: String::new(),
        identifiable_note: String::new(),
        on_bound: vec![],
        removal: vec![],
        removal_flagged: Some(removal),
        removal_outside: None,
        frame_test: None,
        too_wide: None,
        verdict: String::new(),
    }
}

/// The candidates of a round that need a bootstrap.
fn waiting(round: &[Scored]) -> Vec<usize> {
    (0..round.len())
        .filter(|&i| round[i].needs_calibration())
        .collect()
}

/// The race before a round's bootstraps, over every candidate that needs one.
fn race(round: &mut [Scored], opts: &DiagnoseOptions) {
    let pending = waiting(round);
    defer_undeciding(round, &pending, 1000, opts, &mut |_| {});
}

fn deferred_after(mut round: Vec<Scored>) -> Vec<bool> {
    race(&mut round, &DiagnoseOptions::default());
    round.iter().map(|s| s.is_deferred()).collect()
}

/// A pending candidate far behind the decided winner is deferred, and not significant
/// until tested; one that would win if significant, or would be a rival too close to tell
/// apart from the winner, is not; nor is anything with `calibrate_all`.
#[test]
fn only_tests_that_cannot_change_the_choice_are_deferred() {
    let winner = || {
        scored(
            "fa(lambert)",
            Effect::SpecularLobe,
            false,
            -1000.0,
            0.9,
            100.0,
        )
    };
    let behind = || scored("on", Effect::Backscatter, true, -20.0, 0.1, 400.0);
    assert_eq!(deferred_after(vec![winner(), behind()]), [false, true]);
    let mut round = vec![winner(), behind()];
    race(&mut round, &DiagnoseOptions::default());
    assert!(!round[1].significant && !round[1].adoptable());
    assert!(
        round[1].verdict.contains("adopts `fa(lambert)`"),
        "{}",
        round[1].verdict
    );
    // It would win if significant: removes more of the flagged misfit.
    let ahead = scored("on", Effect::Backscatter, true, -2000.0, 0.95, 50.0);
    assert_eq!(deferred_after(vec![winner(), ahead]), [false, false]);
    // It would be a rival: another effect, as good a fit with the same parameter count
    // (their BICs within 6).
    let mut rival = scored("eon", Effect::Backscatter, true, -998.0, 0.85, 101.0);
    rival.fit.as_mut().unwrap().params = winner().fit.unwrap().params;
    assert_eq!(deferred_after(vec![winner(), rival]), [false, false]);
    // Where the round would stop either way (nothing decided adoptable), nothing is
    // deferred either: the pending one is the only possible winner.
    assert_eq!(deferred_after(vec![behind()]), [false]);
    let all = DiagnoseOptions {
        calibrate_all: true,
        ..Default::default()
    };
    let mut round = vec![winner(), behind()];
    race(&mut round, &all);
    assert!(!round[1].is_deferred());
}

/// The round's bootstraps run one at a time, the likely winner first: three forms of one
/// effect all waiting (on, eon, vmf over one null), the best by BIC is calibrated first;
/// once it is significant the round adopts it whatever the other two's tests say, so they
/// are deferred and no more bootstraps run. Had it failed, the next best would be next.
#[test]
fn the_likely_winner_is_calibrated_first_and_its_rivals_of_one_effect_deferred() {
    let forms = || {
        vec![
            scored("on", Effect::Backscatter, true, -20.0, 0.5, 90.0),
            scored("eon", Effect::Backscatter, true, -25.0, 0.5, 89.0),
            scored("vmf", Effect::Backscatter, true, -22.0, 0.5, 89.5),
        ]
    };
    let opts = DiagnoseOptions::default();
    let mut round = forms();
    let all = waiting(&round);
    let first = next_to_calibrate(&mut round, &all, 1000, &opts, &mut |_| {});
    assert_eq!(first, Some(1), "the best by BIC first");
    assert!(
        round.iter().all(|s| !s.is_deferred()),
        "nothing decided yet"
    );
    // Its bootstrap says significant: the other two cannot change the choice.
    round[1].p_test = PTest::F;
    let rest = [0, 2];
    assert_eq!(
        next_to_calibrate(&mut round, &rest, 1000, &opts, &mut |_| {}),
        None
    );
    assert!(round[0].is_deferred() && round[2].is_deferred());
    assert_eq!(pick(&round, 1000).unwrap().candidate.spec, "eon");
    // Its bootstrap says not significant: the next best is tested.
    let mut round = forms();
    round[1].significant = false;
    round[1].p_test = PTest::F;
    assert_eq!(
        next_to_calibrate(&mut round, &rest, 1000, &opts, &mut |_| {}),
        Some(2)
    );
    assert!(!round[0].is_deferred(), "on could still be the winner");
}

/// A backtrack that would try a deferred candidate runs its bootstrap first: Lambertian
/// data with a little backscatter (`on`, σ = 0.1, in-plane: its nominal p needs the bootstrap), `on` scored against `lambert`
/// and deferred, is calibrated by the backtrack's choice and judged on that test.
#[test]
fn a_backtrack_calibrates_a_deferred_candidate_before_trying_it() {
    use crate::engine::cpu::CpuBackend;
    use crate::workflows::diagnose::{fit_model, Candidate};
    let rows = testdata::in_plane_rows(&[10.0, 40.0, 65.0], true);
    let data = testdata::synthesized("on", "rho=0.5,sigma=0.1", &rows, (0.02, 1e-4), 5);
    let backend = CpuBackend::new();
    let opts = DiagnoseOptions {
        restarts: 4,
        bootstrap: crate::inference::bootstrap::BootstrapOptions {
            replicates: 39,
            max_replicates: 39,
            ..Default::default()
        },
        ..Default::default()
    };
    let null = Model::for_data("lambert", &data).unwrap();
    let current = fit_model(&null, &data, &backend, &opts, &[]).unwrap();
    let ext = Model::for_data("on", &data).unwrap();
    let start = super::super::embed(&null, &current.flat, &ext);
    let fit = fit_model(&ext, &data, &backend, &opts, &[start]);
    let candidate = Candidate {
        spec: "on".into(),
        effect: Effect::Backscatter,
        nested: true,
    };
    let mut s = super::super::score::score(&data, &current, &[], candidate, fit, 1, &opts);
    assert!(s.irregular.is_some(), "σ = 0 is on a bound");
    s.defer("test".into());
    let mut round = vec![s];
    let picked = backtrack_alternative(
        &mut round,
        Some(Effect::SpecularLobe),
        "fa(lambert)",
        Instead::OtherEffect,
        &data,
        &backend,
        &opts,
        &current,
        &mut |_| {},
    );
    assert!(!round[0].is_deferred(), "{:?}", round[0].p_test);
    assert!(
        matches!(round[0].p_test, PTest::Bootstrap(_)),
        "{:?} (nominal p {:?})",
        round[0].p_test,
        round[0].p_nominal
    );
    assert_eq!(picked.is_some(), round[0].adoptable());
    // The adopted candidate itself is never an alternative: not as another effect, nor
    // as another form of its own effect.
    for instead in [Instead::OtherEffect, Instead::OtherForm] {
        round[0].defer("test".into());
        let same = backtrack_alternative(
            &mut round,
            Some(Effect::Backscatter),
            "on",
            instead,
            &data,
            &backend,
            &opts,
            &current,
            &mut |_| {},
        );
        assert!(same.is_none() && round[0].is_deferred());
    }
    // Another model of the adopted effect is one, as another form.
    round[0].defer("test".into());
    let other_form = backtrack_alternative(
        &mut round,
        Some(Effect::Backscatter),
        "eon",
        Instead::OtherForm,
        &data,
        &backend,
        &opts,
        &current,
        &mut |_| {},
    );
    assert!(!round[0].is_deferred());
    assert_eq!(other_form.is_some(), round[0].adoptable());
}

/// A path of `effects` steps after its start, the last one `last`.
fn path_ending(effects: usize, last: Effect) -> Vec<Step> {
    let fit = scored("lambert", last, false, 0.0, 0.0, 400.0).fit.unwrap();
    (0..=effects)
        .map(|k| {
            let effect = (k > 0).then_some(if k == effects {
                last
            } else {
                Effect::SpecularLobe
            });
            testdata::step("lambert", effect, &fit)
        })
        .collect()
}

#[test]
fn past_max_steps_only_a_path_that_just_took_a_factor_goes_on_and_only_for_the_factors_left() {
    let opts = DiagnoseOptions {
        max_steps: 4,
        factors_past_max_steps: 2,
        ..Default::default()
    };
    let factor = Effect::HighlightFresnel;
    // Within the budget the ordinary rule applies (no factors-only round).
    assert!(!factors_only(&path_ending(3, factor), &opts));
    // At the budget: on after a factor, not after an analytic effect.
    assert!(factors_only(&path_ending(4, factor), &opts));
    assert!(!factors_only(&path_ending(4, Effect::Backscatter), &opts));
    assert!(factors_only(&path_ending(5, Effect::BodyProfile), &opts));
    // The extra budget spent, or switched off, or no factors at all: stop.
    assert!(!factors_only(
        &path_ending(6, Effect::HighlightShape),
        &opts
    ));
    let none = DiagnoseOptions {
        factors_past_max_steps: 0,
        ..opts.clone()
    };
    assert!(!factors_only(&path_ending(4, factor), &none));
    let analytic = DiagnoseOptions {
        data_driven: false,
        ..opts.clone()
    };
    assert!(!factors_only(&path_ending(4, factor), &analytic));
    // The stop says which budget ended the path.
    let mut steps = path_ending(6, Effect::HighlightShape);
    let fit = steps[6].fit.clone();
    assert_eq!(stop_before_round(&mut steps, &fit, &opts), Some(false));
    assert!(
        steps[6]
            .evidence
            .ends_with("Stopped after 6 effects (--max-steps 4 then factors only)"),
        "{}",
        steps[6].evidence
    );
}
