//! Unit tests of the path search's racing of bootstraps.

use super::*;
use crate::data::Kind;
use crate::workflows::diagnose::score::PTest;

/// A scored candidate, laid out by hand: significant (decided) or waiting for a bootstrap
/// (`pending`: an irregular null whose nominal p is not settled), its ΔBIC, share of the
/// flagged misfit removed, and χ² with its parameter count.
fn scored(spec: &str, effect: Effect, pending: bool, dbic: f64, removal: f64, chi2: f64) -> Scored {
    let data = super::super::testdata::dataset(Kind::Brdf, &[[10.0, 0.0, 30.0, 0.0]], 1);
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
        verdict: String::new(),
    }
}

fn deferred_after(mut round: Vec<Scored>) -> Vec<bool> {
    defer_undeciding(&mut round, 1000, &DiagnoseOptions::default(), &mut |_| {});
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
    defer_undeciding(&mut round, 1000, &DiagnoseOptions::default(), &mut |_| {});
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
    defer_undeciding(&mut round, 1000, &all, &mut |_| {});
    assert!(!round[1].is_deferred());
}
