//! Unit tests of the bootstrap (a file of their own: `bootstrap.rs` stays under 900 lines).
use super::*;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};

/// Draws of ½χ²₀ + ½χ²₁ (the statistic of one parameter on a bound): beyond every
/// replicate the fitted tail must give the exact ½·P(χ²₁ ≥ t), within the sampling
/// error of 2,000 replicates' moments; inside their range the count gives it.
#[test]
fn tail_of_a_boundary_mixture() {
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let n = Normal::new(0.0, 1.0).unwrap();
    let reps: Vec<f64> = (0..2000)
        .map(|_| {
            let z: f64 = n.sample(&mut rng);
            z.max(0.0).powi(2)
        })
        .collect();
    let max = reps.iter().copied().fold(0.0, f64::max);
    for t in [max + 0.5, max + 5.0] {
        let (p, source, share, tail) = p_value(t, &reps);
        let exact = 0.5 * chi2_sf(t, 1.0);
        assert_eq!(source, PSource::Tail, "t = {t}");
        assert!((share - 0.5).abs() < 0.04, "π = {share}");
        let (a, nu) = tail.unwrap();
        assert!(
            (a - 1.0).abs() < 0.2 && (nu - 1.0).abs() < 0.2,
            "{a}·χ²_{nu}"
        );
        assert!(
            (p / exact).ln().abs() < 0.7,
            "t = {t}: p = {p:.3e}, exact {exact:.3e}"
        );
    }
    // Inside the replicates' range the empirical count is used.
    let (p, source, ..) = p_value(1.0, &reps);
    assert!(p_value(max, &reps).1 == PSource::Empirical);
    let exact = 0.5 * chi2_sf(1.0, 1.0);
    assert_eq!(source, PSource::Empirical);
    assert!((p - exact).abs() < 0.03, "{p} vs {exact}");
}

/// T = Δχ²/(χ²₁/ν₁), a worse extension counting as 0, and so does anything up to
/// [`ZERO`]; ν₁ = 0 counts as 1.
#[test]
fn the_statistic_is_delta_chi2_over_the_extensions_reduced_chi2() {
    assert_eq!(statistic(120.0, 100.0, 50), 10.0);
    assert_eq!(statistic(100.0, 120.0, 50), 0.0);
    assert_eq!(statistic(100.0 + 5e-4, 100.0, 100), 0.0);
    // Exactly 1e-3 (1/1000, correctly rounded) is "at or below".
    assert_eq!(statistic(1001.0, 1000.0, 1), 0.0);
    assert!((statistic(100.0 + 2e-3, 100.0, 100) - 2e-3).abs() < 1e-12);
    assert_eq!(statistic(10.0, 5.0, 0), 1.0);
}

/// Each branch of the p-value against counts and tails worked out by hand.
#[test]
fn p_values_by_hand() {
    // B = 10, three replicates at or above T = 3 (3.0 itself counts): (1 + 3)/11;
    // six of ten positive.
    let reps = [0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 0.0, 0.0, 0.0];
    let (p, source, share, tail) = p_value(3.0, &reps);
    assert_eq!(
        (p, source, share, tail),
        (4.0 / 11.0, PSource::Empirical, 0.6, None)
    );
    // None reaches T and only 9 are positive: the bound 1/(B + 1).
    let mut reps = vec![0.5; 9];
    reps.push(0.0);
    let (p, source, share, tail) = p_value(1.0, &reps);
    assert_eq!(
        (p, source, share, tail),
        (1.0 / 11.0, PSource::EmpiricalBound, 0.9, None)
    );
    // Positive replicates all equal: no variance to fit a tail to.
    let (p, source, ..) = p_value(5.0, &[1.0; 12]);
    assert_eq!((p, source), (1.0 / 13.0, PSource::EmpiricalBound));
    // Ten positive replicates 2 ± d (mean 2, variance 10d²/9 = 2) and ten at 0:
    // a = var/(2·mean) = 1/2, ν = 2·mean²/var = 4, π = 1/2, and
    // P(χ²₄ ≥ x) = e^(−x/2)(1 + x/2): p = π·P(χ²₄ ≥ 2T) = ½e^(−T)(1 + T).
    let d = 1.8f64.sqrt();
    let mut reps: Vec<f64> = (0..10)
        .map(|i| if i % 2 == 0 { 2.0 + d } else { 2.0 - d })
        .collect();
    reps.extend([0.0; 10]);
    let (p, source, share, tail) = p_value(20.0, &reps);
    let (a, nu) = tail.unwrap();
    assert_eq!((source, share), (PSource::Tail, 0.5));
    assert!(
        (a - 0.5).abs() < 1e-12 && (nu - 4.0).abs() < 1e-12,
        "{a} {nu}"
    );
    let want = 0.5 * (-20.0f64).exp() * 21.0;
    assert!((p / want - 1.0).abs() < 1e-9, "{p} vs {want}");
    // Just above every replicate the tail (½e^(−3.4)·4.4 = 0.073) is capped at 1/21.
    let (p, source, ..) = p_value(3.4, &reps);
    assert_eq!((p, source), (1.0 / 21.0, PSource::Tail));
}

/// A replicate statistic of exactly [`ZERO`] is not positive.
#[test]
fn a_replicate_at_zero_is_not_positive() {
    let (_, _, share, _) = p_value(1.0, &[1e-3, 0.5, 2.0e-3, 0.0]);
    assert_eq!(share, 0.5);
}

/// The replicate fits: LM stopped at 1e-7 of χ² within 100 iterations, at least one
/// restart, a seed of their own; everything else as the base options.
#[test]
fn replicate_fits_use_lm_with_a_looser_tolerance() {
    let base = FitOptions {
        optimizer: Optimizer::Compass,
        restarts: 9,
        screen: 5,
        seed: 1,
        ..FitOptions::default()
    };
    for restarts in [0, 3] {
        let boot = BootstrapOptions {
            replicates: 9,
            restarts,
            seed: 1,
            ..Default::default()
        };
        let o = replicate_options(&base, &boot);
        assert_eq!(o.optimizer, Optimizer::Lm);
        assert_eq!(o.restarts, restarts.max(1));
        assert_eq!((o.lm.ftol, o.lm.max_iterations), (1e-7, 100));
        assert_eq!((o.screen, o.lm.xtol), (5, base.lm.xtol));
        assert_ne!(o.seed, boot.seed);
    }
}

#[test]
fn descriptions_name_the_source_of_the_p_value() {
    let mut c = Calibrated {
        p: 0.05,
        source: PSource::Empirical,
        statistic: 3.25,
        replicates: 99,
        fitted: 98,
        exceeding: 4,
        positive_share: 0.5,
        tail: None,
        level: 0.01,
        batches: vec![24, 49, 99],
        undecided: None,
        seconds: 1.0,
        evaluations: 10,
        phases: PhaseSeconds::default(),
    };
    assert_eq!(
        c.describe(),
        "bootstrap: 4 of 98 replicates reach T = 3.2500"
    );
    c.source = PSource::EmpiricalBound;
    c.exceeding = 0;
    assert!(c
        .describe()
        .ends_with("too few positive to fit a tail (p is a bound)"));
    c.source = PSource::Tail;
    c.tail = Some((1.25, 2.5));
    assert!(
        c.describe()
            .ends_with("tail 0.50·1.250·χ²_2.50 fitted to them"),
        "{}",
        c.describe()
    );
    c.source = PSource::Sequential;
    c.exceeding = 10;
    assert!(c.describe().contains("10 of 98") && c.describe().contains("stopped early"));
    c.undecided = Some("why".into());
    assert!(
        c.describe().ends_with("; undecided: why"),
        "{}",
        c.describe()
    );
}

/// Lambert data (ρ = 0.46, 2 % noise) and its Oren–Nayar extension, whose null σ = 0
/// is irregular: the null refits start with the measured data, the replicates scatter
/// about the null's fitted values by their uncertainties, and the calibrated p-value
/// agrees with its own counts.
#[test]
fn a_calibration_counts_its_replicates_and_agrees_with_its_p_value() {
    use crate::data::{Kind, RawRow, ReadOptions};
    use crate::engine::cpu::CpuBackend;
    use crate::workflows::diagnose::{embed, fit_model, DiagnoseOptions};
    let f = 0.46 / std::f64::consts::PI;
    let mut rows = Vec::new();
    for ti in [10.0, 35.0, 60.0] {
        for k in 0..=22 {
            let to = -77.0 + 7.0 * k as f64;
            if (to - ti).abs() > 0.5 {
                let i = rows.len();
                let wiggle = ((i * 7919) % 13) as f64 / 6.0 - 1.0;
                let row = RawRow {
                    theta_i: ti,
                    phi_i: 20.0,
                    theta_o: to,
                    phi_o: 20.0,
                    wavelength_nm: 550.0,
                    value: f * (1.0 + 0.02 * wiggle),
                    uncertainty: 0.02 * f,
                };
                rows.push((i + 1, row));
            }
        }
    }
    let data =
        Dataset::from_rows(Kind::Brdf, "b", &rows, "b.csv", &ReadOptions::default()).unwrap();
    let backend = CpuBackend::new();
    let opts = DiagnoseOptions {
        restarts: 4,
        seed: 1,
        ..Default::default()
    };
    let null = Model::for_data("lambert", &data).unwrap();
    let ext = Model::for_data("on", &data).unwrap();
    let current = fit_model(&null, &data, &backend, &opts, &[]).unwrap();
    let start = embed(&null, &current.flat, &ext);
    let fit = fit_model(&ext, &data, &backend, &opts, &[start]).unwrap();
    let base = FitOptions {
        optimizer: Optimizer::Lm,
        restarts: 2,
        screen: 1,
        ..FitOptions::default()
    };
    // B fixed at 19 (no growth), a level no count can settle early (h = 10 of 19).
    let boot = BootstrapOptions {
        replicates: 19,
        max_replicates: 19,
        restarts: 1,
        seed: 3,
    };
    let level = 0.01;
    let nulls = refit_null(
        &null,
        &current.flat,
        &current.values,
        &data,
        &backend,
        &base,
        &boot,
    )
    .unwrap();
    assert_eq!(
        (nulls.replicates(), nulls.flat.len(), nulls.chi2.len()),
        (19, 20, 20)
    );
    for (a, b) in nulls.dataset(0).samples.iter().zip(&data.samples) {
        assert_eq!(a.value, b.value);
    }
    let z: Vec<f64> = (1..=19)
        .map(|i| nulls.dataset(i))
        .flat_map(|r| {
            r.samples
                .iter()
                .zip(&current.values)
                .map(|(s, v)| (s.value - v) / s.uncertainty)
                .collect::<Vec<f64>>()
        })
        .collect();
    let n = z.len() as f64;
    let mean = z.iter().sum::<f64>() / n;
    let sd = (z.iter().map(|z| (z - mean).powi(2)).sum::<f64>() / n).sqrt();
    assert!(
        z.len() == 19 * data.len() && mean.abs() < 0.15 && (sd - 1.0).abs() < 0.1,
        "{mean} {sd}"
    );
    assert!(
        (nulls.chi2[0] / current.chi2 - 1.0).abs() < 1e-6,
        "{} {}",
        nulls.chi2[0],
        current.chi2
    );

    let embed_null = |g: &[f64]| embed(&null, g, &ext);
    let run = |nulls: &NullRefits| {
        let mut nulls = nulls.clone();
        calibrate(
            &ext,
            &fit.flat,
            &embed_null,
            &mut nulls,
            fit.dof,
            level,
            &backend,
            &base,
            &boot,
        )
    };
    let c = run(&nulls).unwrap();
    assert_eq!(c.replicates, 19);
    assert!(
        c.fitted >= 17 && c.fitted <= 19 && c.exceeding <= c.fitted,
        "{c:?}"
    );
    let t = statistic(current.chi2, fit.chi2, fit.dof);
    assert!(
        (c.statistic - t).abs() < 0.01 + 1e-3 * t,
        "T {} vs {t}",
        c.statistic
    );
    let bound = 1.0 / (c.fitted + 1) as f64;
    match c.source {
        PSource::Empirical => {
            assert_eq!(
                c.p,
                (1 + c.exceeding) as f64 / (c.fitted + 1) as f64,
                "{c:?}"
            )
        }
        PSource::EmpiricalBound => assert!(c.exceeding == 0 && c.p == bound, "{c:?}"),
        PSource::Tail => assert!(c.exceeding == 0 && c.p <= bound, "{c:?}"),
        PSource::Sequential => assert!(c.exceeding >= 10, "{c:?}"),
    }
    assert!(
        c.evaluations > nulls.evaluations && c.evaluations < 100 * nulls.evaluations,
        "{c:?}"
    );
    assert!(c.seconds >= nulls.seconds);
    // The refits are deterministic: the same calibration against null refits that
    // report 1000 more evaluations reports 1000 more; against a non-finite null χ²
    // of the measured data it is an error.
    let again = |chi2_0: f64, extra: u64| {
        let mut n = nulls.clone();
        n.chi2[0] = chi2_0;
        n.evaluations += extra;
        n
    };
    let c2 = run(&again(nulls.chi2[0], 1000)).unwrap();
    assert_eq!(c2.evaluations, c.evaluations + 1000);
    assert_eq!(
        (c2.p, c2.statistic, c2.exceeding),
        (c.p, c.statistic, c.exceeding)
    );
    // A replicate whose null refit is not finite is left out of the counts.
    let mut one_failed = again(nulls.chi2[0], 0);
    one_failed.chi2[5] = f64::NAN;
    assert_eq!(run(&one_failed).unwrap().fitted, c.fitted - 1);
    assert!(run(&again(f64::NAN, 0)).is_err());
}

/// Replicates drawn from a model's values, not the data's: y* = y′ + u z.
#[test]
fn null_replicates_scatter_about_the_models_values() {
    use crate::data::{Kind, RawRow, ReadOptions};
    let rows: Vec<(usize, RawRow)> = (0..3)
        .map(|i| {
            let row = RawRow {
                theta_i: 10.0 * i as f64,
                phi_i: 0.0,
                theta_o: 30.0,
                phi_o: 180.0,
                wavelength_nm: 550.0,
                value: 1.0,
                uncertainty: 1e-6,
            };
            (i + 1, row)
        })
        .collect();
    let data =
        Dataset::from_rows(Kind::Brdf, "n", &rows, "n.csv", &ReadOptions::default()).unwrap();
    let reps = null_replicates(&data, &[2.0, 3.0, 4.0], 5, 1);
    assert_eq!(reps.len(), 5);
    for r in &reps {
        for (s, v) in r.samples.iter().zip([2.0, 3.0, 4.0]) {
            assert!((s.value - v).abs() < 1e-4, "{} vs {v}", s.value);
        }
    }
}

/// Without positive replicates no tail can be fitted: the p-value is the empirical
/// bound 1/(B + 1), never 0.
#[test]
fn all_zero_replicates_give_the_empirical_bound() {
    let reps = vec![0.0; 99];
    let (p, source, share, tail) = p_value(5.0, &reps);
    assert_eq!(source, PSource::EmpiricalBound);
    assert_eq!(p, 0.01);
    assert_eq!(share, 0.0);
    assert!(tail.is_none());
    assert_eq!(p_value(0.0, &reps).0, 1.0);
}

/// The batches: 24, doubling to the planned B, then doubling to the maximum.
#[test]
fn the_schedule_doubles_to_the_plan_then_to_the_maximum() {
    let b = |replicates, max_replicates| BootstrapOptions {
        replicates,
        max_replicates,
        ..Default::default()
    };
    assert_eq!(b(99, 999).schedule(), [24, 49, 99, 199, 399, 799, 999]);
    assert_eq!(b(59, 999).schedule()[..4], [24, 49, 59, 119]);
    assert_eq!(b(19, 19).schedule(), [19]);
    assert_eq!(b(19, 5).schedule(), [19]);
    assert_eq!(b(99, 150).schedule(), [24, 49, 99, 150]);
    assert_eq!(
        BootstrapOptions::default().schedule(),
        b(99, 999).schedule()
    );
}

/// h = max(10, ⌈level·(B + 1)⌉); l counts up to the h-th replicate at or above T.
#[test]
fn the_sequential_stop_by_hand() {
    assert_eq!(sequential_h(0.01, 99), 10);
    assert_eq!(sequential_h(0.002, 999), 10);
    assert_eq!(sequential_h(0.5, 99), 50);
    let reps = [0.0, 3.0, 1.0, 2.0, 5.0, 2.0];
    assert_eq!(hth_exceedance(2.0, &reps, 1), Some(2));
    assert_eq!(hth_exceedance(2.0, &reps, 3), Some(5));
    assert_eq!(hth_exceedance(2.0, &reps, 4), Some(6));
    assert_eq!(hth_exceedance(2.0, &reps, 5), None);
}

/// Each rule of [`settle`] on replicates laid out by hand (planned B = 99).
#[test]
fn when_the_test_stops() {
    let boot = BootstrapOptions::default();
    let gathered = |observed: f64, reps: Vec<f64>| Gathered {
        observed,
        drawn: reps.len(),
        reps,
    };
    // Ten of the first 20 reach T = 1 (the 10th at l = 20): stopped at the first batch,
    // p = h/l = 0.5.
    // The even ones are 0 or exactly ZERO (counted as 0) before 12 and 0.3 from 12 on:
    // positive but below T, so the share of positive replicates is 18 of 24.
    let reps: Vec<f64> = (0..24)
        .map(|i| match (i % 2, i < 12) {
            (1, _) => 2.0,
            (_, true) if i % 4 == 0 => ZERO,
            (_, true) => 0.0,
            _ => 0.3,
        })
        .collect();
    let (p, source, share, ..) = settle(&gathered(1.0, reps), 0.01, &boot, false).unwrap();
    assert_eq!((p, source, share), (0.5, PSource::Sequential, 0.75));
    // A bound exactly at the level (99 replicates, 1/100 = 0.01) does not decide: the
    // count must fall below it. (Five positive: no tail is fitted.)
    let mut reps = vec![0.0; 99];
    reps[..5].fill(0.5);
    assert!(settle(&gathered(9.0, reps), 0.01, &boot, false).is_none());
    // Three of 49 reach T: not settled before the planned 99 ...
    let mut reps = vec![0.0; 49];
    reps[..3].fill(5.0);
    assert!(settle(&gathered(1.0, reps.clone()), 0.01, &boot, false).is_none());
    // ... and at 99 the count decides: p = 4/100.
    reps.resize(99, 0.0);
    let (p, source, _, _, why) = settle(&gathered(1.0, reps), 0.01, &boot, false).unwrap();
    assert_eq!((p, source, why), (0.04, PSource::Empirical, None));
    // None of 99 reaches T and 5 are positive: the bound 0.01 cannot reach 0.002, so
    // more are drawn; at the last batch it says why it could not decide.
    // (Two more sit exactly at ZERO: they count as 0, not as positive.)
    let mut reps = vec![0.0; 99];
    reps[..5].fill(0.5);
    reps[5..7].fill(ZERO);
    assert!(settle(&gathered(9.0, reps.clone()), 0.002, &boot, false).is_none());
    let (p, source, _, _, why) = settle(&gathered(9.0, reps.clone()), 0.002, &boot, true).unwrap();
    assert_eq!((p, source), (0.01, PSource::EmpiricalBound));
    let why = why.unwrap();
    assert!(
        why.contains("only 5 are positive") && why.contains("500"),
        "{why}"
    );
    // The same bound below a level of 0.02 decides.
    let (p, _, _, _, why) = settle(&gathered(9.0, reps), 0.02, &boot, false).unwrap();
    assert_eq!((p, why), (0.01, None));
    // Beyond the plan the first replicate that reaches T decides by the count, not by
    // h/l: ten of 199 reach T after none of the first 99 did.
    let mut reps = vec![0.0; 199];
    reps[150..160].fill(10.0);
    let (p, source, ..) = settle(&gathered(9.0, reps), 0.002, &boot, false).unwrap();
    assert_eq!((p, source), (11.0 / 200.0, PSource::Empirical));
    // Twenty positive replicates (0.5 … 19.5) and none at T: a tail far from the level
    // decides either way with no more replicates drawn; one within a factor of ten of it
    // does not, and at the last batch says why.
    let mut reps = vec![0.0; 99];
    for (i, r) in reps[..20].iter_mut().enumerate() {
        *r = 0.5 + i as f64;
    }
    let tail_p = |t: f64| {
        let (_, _, share, tail) = p_value(t, &reps);
        let (a, nu) = tail.unwrap();
        share * chi2_sf(t / a, nu)
    };
    let (mut near, mut far) = (0, 0);
    for k in 0..=90 {
        let t = 20.0 + 2.0 * k as f64;
        let q = tail_p(t);
        let settled = settle(&gathered(t, reps.clone()), 0.002, &boot, false);
        if (2e-4..=2e-2).contains(&q) {
            near += 1;
            assert!(settled.is_none(), "T = {t}: tail {q:.1e} settled");
            let (p, source, _, _, why) =
                settle(&gathered(t, reps.clone()), 0.002, &boot, true).unwrap();
            assert_eq!((source, p), (PSource::Tail, 0.01), "T = {t}: tail {q:.1e}");
            assert!(why.unwrap().contains("within a factor 10 of the level"));
        } else {
            far += 1;
            let (p, source, _, _, why) = settled.expect("a far tail decides");
            assert_eq!((source, why), (PSource::Tail, None), "T = {t}");
            assert_eq!(p < 0.002, q < 2e-4, "T = {t}: p = {p}");
        }
    }
    assert!(near > 0 && far > 0, "{near} near, {far} far");
    // Once the bound 1/(B + 1) is below the level, the count decides whatever the tail.
    let mut reps = vec![0.0; 799];
    for (i, r) in reps[..20].iter_mut().enumerate() {
        *r = 0.5 + i as f64;
    }
    let (p, ..) = settle(&gathered(30.0, reps), 0.002, &boot, false).unwrap();
    assert!(p <= 1.0 / 800.0, "{p}");
}
