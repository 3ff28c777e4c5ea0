//! Oracles written here from the definitions (module doc): for Lambert, f = ρ/π is
//! linear in ρ, so every loss's weighted residual has the Jacobian J_k = √w_k g′(ρ/π)/π
//! in closed form, and the sandwich B⁻¹MB⁻¹ is a ratio of sums; the helpers are checked
//! on matrices whose inverses, eigenvectors and correlations are worked out by hand.
use super::*;
use crate::bsdf::ParamDecl;
use crate::data::{Kind, RawRow, ReadOptions};
use crate::engine::cpu::CpuBackend;
use crate::engine::loss::Weights;
use crate::engine::{Backend, Problem};
use crate::inference::constraints::Prior;

/// Eight BRDF samples at one wavelength per entry of `wavelengths` (θi, θo in
/// degrees, value, uncertainty), with their scatter about ρ/π ≈ 0.1 scaled by
/// `scatter`.
fn data(wavelengths: &[f64], scatter: f64) -> Dataset {
    let base = [
        (10.0, 20.0, 0.004, 0.006),
        (25.0, 40.0, -0.010, 0.008),
        (40.0, 15.0, 0.007, 0.005),
        (55.0, 60.0, -0.002, 0.012),
        (70.0, 35.0, 0.012, 0.010),
        (15.0, 75.0, -0.006, 0.007),
        (30.0, 50.0, 0.001, 0.009),
        (65.0, 5.0, -0.008, 0.006),
    ];
    let mut rows = Vec::new();
    for (c, &nm) in wavelengths.iter().enumerate() {
        for &(ti, to, dev, u) in &base {
            let row = RawRow {
                theta_i: ti,
                phi_i: 0.0,
                theta_o: to,
                phi_o: 180.0,
                wavelength_nm: nm,
                value: 0.1 + 0.01 * c as f64 + scatter * dev,
                uncertainty: u,
            };
            rows.push((rows.len() + 1, row));
        }
    }
    Dataset::from_rows(Kind::Brdf, "d", &rows, "d.csv", &ReadOptions::default()).unwrap()
}

fn lambert(data: &Dataset) -> Model {
    Model::for_data("lambert", data).unwrap()
}

fn cov_of(data: &Dataset, loss: Loss, flat: &[f64], space: &Constraints) -> Covariance {
    let model = lambert(data);
    let cpu = CpuBackend::new();
    let problem = Problem {
        model: &model,
        data,
        loss,
    };
    let mut eval = cpu.prepare(problem).unwrap();
    covariance(&model, data, loss, eval.as_mut(), flat, space).unwrap()
}

/// The per-sample weight w and inner factor a of a loss, from docs/losses.md.
fn w_and_a(loss: Loss, s: &crate::data::Sample) -> (f64, f64) {
    const E: f64 = 1e-6;
    let (y, u) = (s.value, s.uncertainty);
    let w = match loss.weights {
        Weights::Uniform => 1.0,
        Weights::Relunc => 1.0 / (u.abs() / (y.abs() + E) + E),
        Weights::Invunc => 1.0 / u,
    };
    let (ci, si, so, co) = (
        s.theta_i.cos(),
        s.theta_i.sin(),
        s.theta_o.sin(),
        s.theta_o.cos(),
    );
    match loss.metric {
        Metric::Chi2 => (1.0 / (u * u), 1.0),
        Metric::Smape | Metric::F | Metric::Logf => (w, 1.0),
        Metric::Rmse => (w * ci * ci, 1.0),
        Metric::Ngan => (w * ci * ci * si * so, 1.0),
        Metric::Low => (w * ci * ci * si, 1.0),
        Metric::Cosf | Metric::Logcosf => (w, co),
    }
}

/// χ² of ρ on one channel's samples.
fn chi2_at(data: &Dataset, rho: f64) -> f64 {
    let f = rho / std::f64::consts::PI;
    data.samples
        .iter()
        .map(|s| ((f - s.value) / s.uncertainty).powi(2))
        .sum()
}

/// σ(ρ) of Lambert at `rho` on one channel: B = Σ J², M = Σ J² w σ², σ_k = g′(y_k) u_k,
/// var = M/B² times the Birge factor max(1, χ²/(K − 1)). SMAPE reports the χ² form.
fn sigma_by_hand(data: &Dataset, loss: Loss, rho: f64) -> f64 {
    let pi = std::f64::consts::PI;
    let loss = if loss.metric == Metric::Smape {
        Loss::new(Metric::Chi2, Weights::Uniform)
    } else {
        loss
    };
    let log = loss.metric.term() == Term::LogSquare;
    let slope = |a: f64, v: f64| if log { a / (1.0 + a * v) } else { a };
    let (mut b, mut m) = (0.0, 0.0);
    for s in &data.samples {
        let (w, a) = w_and_a(loss, s);
        let j = w.sqrt() * slope(a, rho / pi) / pi;
        b += j * j;
        m += j * j * w * (slope(a, s.value) * s.uncertainty).powi(2);
    }
    let birge = (chi2_at(data, rho) / (data.len() - 1) as f64).max(1.0);
    (m / (b * b) * birge).sqrt()
}

/// Every loss's standard uncertainty of a linear model is the sandwich of its
/// weighted residuals (the plain (JᵀWJ)⁻¹ for χ²), scaled by χ²_red where that
/// exceeds 1 and not where it is below.
#[test]
fn lambert_sigma_is_the_sandwich_of_every_loss() {
    let losses = [
        Loss::new(Metric::Chi2, Weights::Uniform),
        Loss::new(Metric::Smape, Weights::Relunc),
        Loss::new(Metric::Rmse, Weights::Uniform),
        Loss::new(Metric::Ngan, Weights::Relunc),
        Loss::new(Metric::Low, Weights::Invunc),
        Loss::new(Metric::F, Weights::Invunc),
        Loss::new(Metric::Cosf, Weights::Uniform),
        Loss::new(Metric::Logf, Weights::Relunc),
        Loss::new(Metric::Logcosf, Weights::Invunc),
    ];
    for scatter in [0.2, 3.0] {
        let d = data(&[550.0], scatter);
        let space = Constraints::none(&lambert(&d));
        let red = chi2_at(&d, 0.31) / 7.0;
        assert!((scatter < 1.0) == (red < 1.0), "χ²_red {red}");
        for loss in losses {
            let got = cov_of(&d, loss, &[0.31], &space).std[0].unwrap();
            let want = sigma_by_hand(&d, loss, 0.31);
            assert!(
                (got / want - 1.0).abs() < 1e-6,
                "{loss}, χ²_red {red}: σ {got} vs {want}"
            );
        }
    }
}

/// χ² over all channels at `flat` (one ρ per channel).
fn chi2_flat(data: &Dataset, flat: &[f64]) -> f64 {
    let pi = std::f64::consts::PI;
    (data.samples.iter())
        .map(|s| ((flat[s.channel] / pi - s.value) / s.uncertainty).powi(2))
        .sum()
}

/// χ²'s σ is the textbook 1/√(Σ J²) (times √χ²_red where that exceeds 1), each
/// channel's ρ from its own samples only, uncorrelated with the others; a fixed
/// parameter has no σ and no correlation and leaves one more degree of freedom; a
/// prior is one more residual (θ − mean)/sd: Σ J² + 1/sd², its χ² counted in χ²_red
/// over K + 1 − P.
#[test]
fn chi2_channels_fixed_parameters_and_priors() {
    let pi = std::f64::consts::PI;
    let d = data(&[450.0, 550.0, 650.0], 3.0);
    let model = lambert(&d);
    let chi2 = Loss::new(Metric::Chi2, Weights::Uniform);
    let flat = [0.32, 0.34, 0.36];
    let k = d.len() as f64;
    let textbook = |c: usize, free: f64| {
        let b: f64 = (d.samples.iter())
            .filter(|s| s.channel == c)
            .map(|s| (1.0 / (pi * s.uncertainty)).powi(2))
            .sum();
        let birge = (chi2_flat(&d, &flat) / (k - free)).max(1.0);
        (birge / b).sqrt()
    };
    assert!(chi2_flat(&d, &flat) / (k - 3.0) > 1.2);
    let all = cov_of(&d, chi2, &flat, &Constraints::none(&model));
    for c in 0..3 {
        let got = all.std[c].unwrap();
        assert!((got / textbook(c, 3.0) - 1.0).abs() < 1e-9, "{c}: {got}");
        for o in 0..3 {
            let want = if o == c { 1.0 } else { 0.0 };
            assert!((all.correlation[c][o].unwrap() - want).abs() < 1e-9);
        }
    }
    assert!(all.warnings.is_empty(), "{:?}", all.warnings);

    let mut held = Constraints::none(&model);
    held.fixed[1] = Some(0.34);
    held.free = vec![0, 2];
    let some = cov_of(&d, chi2, &flat, &held);
    assert_eq!(some.std[1], None);
    assert!((0..3).all(|o| some.correlation[1][o].is_none() && some.correlation[o][1].is_none()));
    for c in [0, 2] {
        let got = some.std[c].unwrap();
        assert!((got / textbook(c, 2.0) - 1.0).abs() < 1e-9, "{c}: {got}");
    }
    assert!((some.correlation[0][2].unwrap()).abs() < 1e-9);

    // A prior on ρ: 0.3 ± 0.002, off the data's ρ by several sd, so that χ²_red
    // (with the prior's residual, over K + 1 − P) exceeds 1.
    let one = data(&[550.0], 0.2);
    let mut prior = Constraints::none(&lambert(&one));
    let sd = 0.002;
    prior.priors.push(Prior {
        name: "rho".into(),
        index: 0,
        mean: 0.3,
        sd,
    });
    let rho = 0.31;
    let b: f64 = (one.samples.iter())
        .map(|s| (1.0 / (pi * s.uncertainty)).powi(2))
        .sum::<f64>()
        + 1.0 / (sd * sd);
    let chi2_total = chi2_at(&one, rho) + ((rho - 0.3) / sd).powi(2);
    let red = chi2_total / (one.len() + 1 - 1) as f64;
    assert!(red > 1.5, "{red}");
    let got = cov_of(&one, chi2, &[rho], &prior).std[0].unwrap();
    let want = (red / b).sqrt();
    assert!((got / want - 1.0).abs() < 1e-9, "σ {got} vs {want}");
}

/// 9,000 samples: more than one of the CPU evaluator's windows (8,192 rows) and
/// many of the Jacobian's chunks (1,024 rows), every row still counted once.
#[test]
fn chi2_sigma_over_several_windows() {
    let pi = std::f64::consts::PI;
    let mut rows = Vec::new();
    for ti in 0..60 {
        for to in 1..76 {
            for po in [0.0, 90.0] {
                let k = rows.len();
                let row = RawRow {
                    theta_i: ti as f64,
                    phi_i: 0.0,
                    theta_o: to as f64,
                    phi_o: po,
                    wavelength_nm: 550.0,
                    value: 0.1 + 0.002 * ((k * 7919) % 11) as f64 / 10.0,
                    uncertainty: 0.005 + 0.001 * (k % 7) as f64,
                };
                rows.push((k + 1, row));
            }
        }
    }
    let d = Dataset::from_rows(Kind::Brdf, "w", &rows, "w.csv", &ReadOptions::default()).unwrap();
    assert_eq!(d.len(), 9000);
    let space = Constraints::none(&lambert(&d));
    let chi2 = Loss::new(Metric::Chi2, Weights::Uniform);
    let b: f64 = (d.samples.iter())
        .map(|s| (1.0 / (pi * s.uncertainty)).powi(2))
        .sum();
    let birge = (chi2_at(&d, 0.32) / (d.len() - 1) as f64).max(1.0);
    let want = (birge / b).sqrt();
    let got = cov_of(&d, chi2, &[0.32], &space).std[0].unwrap();
    assert!((got / want - 1.0).abs() < 1e-9, "σ {got} vs {want}");
    // The same through a sum-of-squares loss other than χ² (the loss's residuals).
    let rmse = Loss::new(Metric::Rmse, Weights::Uniform);
    let got = cov_of(&d, rmse, &[0.32], &space).std[0].unwrap();
    let want = sigma_by_hand(&d, rmse, 0.32);
    assert!((got / want - 1.0).abs() < 1e-6, "σ {got} vs {want}");
}

#[test]
fn central_differences_step_du_in_the_unit_box_and_stop_at_its_edges() {
    let d = data(&[550.0], 0.2);
    let space = Constraints::none(&lambert(&d));
    let (batch, steps) = central_difference_batch(&[0.3], &space);
    assert_eq!(batch.len(), 3);
    assert_eq!(batch[0], 0.3);
    assert!((batch[1] - (0.3 + DU)).abs() < 1e-14 && (batch[2] - (0.3 - DU)).abs() < 1e-14);
    assert!((steps[0] - 2.0 * DU).abs() < 1e-14);
    let (batch, steps) = central_difference_batch(&[1.0], &space);
    assert_eq!(batch[1], 1.0);
    assert!((batch[2] - (1.0 - DU)).abs() < 1e-14 && (steps[0] - DU).abs() < 1e-14);
    let (batch, steps) = central_difference_batch(&[0.0], &space);
    assert_eq!(batch[2], 0.0);
    assert!((batch[1] - DU).abs() < 1e-14 && (steps[0] - DU).abs() < 1e-14);
}

#[test]
fn priors_add_one_over_sd_squared_to_their_diagonal() {
    let d = data(&[450.0, 550.0, 650.0], 0.2);
    let mut space = Constraints::none(&lambert(&d));
    space.fixed[0] = Some(0.3);
    space.free = vec![1, 2];
    space.priors.push(Prior {
        name: "rho".into(),
        index: 2,
        mean: 0.3,
        sd: 0.5,
    });
    space.priors.push(Prior {
        name: "rho".into(),
        index: 0,
        mean: 0.3,
        sd: 0.25,
    });
    let (mut b, mut m) = (DMatrix::from_element(2, 2, 1.0), DMatrix::zeros(2, 2));
    add_prior_rows(&mut b, &mut m, &space);
    assert_eq!(b, DMatrix::from_row_slice(2, 2, &[1.0, 1.0, 1.0, 5.0]));
    assert_eq!(m, DMatrix::from_row_slice(2, 2, &[0.0, 0.0, 0.0, 4.0]));
}

#[test]
fn the_pseudo_inverse_inverts_what_is_determined_and_flags_the_rest() {
    let close = |a: &DMatrix<f64>, b: &[f64]| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12);
    // [[4, 2], [2, 3]]⁻¹ = [[3, −2], [−2, 4]]/8.
    let (inv, und) = pseudo_inverse(
        &DMatrix::from_row_slice(2, 2, &[4.0, 2.0, 2.0, 3.0]),
        &[1.0, 1.0],
    )
    .unwrap();
    assert!(close(&inv, &[0.375, -0.25, -0.25, 0.5]), "{inv}");
    assert_eq!(und, [false, false]);
    // [[1, 1], [1, 1]] = 2vvᵀ, v = (1, 1)/√2: B⁺ = vvᵀ/2; both lie along the null space.
    let (inv, und) = pseudo_inverse(&DMatrix::from_element(2, 2, 1.0), &[1.0, 1.0]).unwrap();
    assert!(close(&inv, &[0.25; 4]), "{inv}");
    assert_eq!(und, [true, true]);
    // Singular values below 1e-10 of the largest count as 0, those above do not.
    let diag = |a: f64, b: f64| DMatrix::from_row_slice(2, 2, &[a, 0.0, 0.0, b]);
    let (inv, und) = pseudo_inverse(&diag(4.0, 1e-10), &[1.0, 1.0]).unwrap();
    assert!(close(&inv, &[0.25, 0.0, 0.0, 0.0]), "{inv}");
    assert_eq!(und, [false, true]);
    // Exactly 1e-10 of the largest is not above it.
    let (_, und) = pseudo_inverse(&diag(1.0, 1e-10), &[1.0, 1.0]).unwrap();
    assert_eq!(und, [false, true]);
    let (inv, und) = pseudo_inverse(&diag(4.0, 1e-9), &[1.0, 1.0]).unwrap();
    assert!(
        (inv[(1, 1)] / 1e9 - 1.0).abs() < 1e-9 && und == [false, false],
        "{inv}"
    );
    let (inv, und) = pseudo_inverse(&diag(0.0, 0.0), &[1.0, 1.0]).unwrap();
    assert!(close(&inv, &[0.0; 4]) && und == [true, true]);
    assert!(pseudo_inverse(&diag(f64::NAN, 1.0), &[1.0, 1.0]).is_err());
    assert!(pseudo_inverse(&diag(1.0, f64::INFINITY), &[1.0, 1.0]).is_err());
}

fn empty(p: usize) -> Covariance {
    Covariance {
        std: vec![None; p],
        correlation: vec![vec![None; p]; p],
        warnings: vec![],
        ridges: vec![],
        effective_params: None,
        with_prior: None,
        data_share: None,
    }
}

#[test]
fn standard_uncertainties_and_correlations_from_the_covariance() {
    let cov = DMatrix::from_row_slice(
        4,
        4,
        &[
            4.0, 1.2, 0.0, 3.0, //
            1.2, 9.0, 0.0, 0.0, //
            0.0, 0.0, -1.0, 0.0, //
            3.0, 0.0, 0.0, 0.0,
        ],
    );
    let mut out = empty(4);
    set_std_and_correlation(&mut out, &cov, &[false; 4]);
    // A negative variance has no σ; a zero one has σ = 0 and no correlation.
    assert_eq!(out.std, [Some(2.0), Some(3.0), None, Some(0.0)]);
    let c = |a: usize, b: usize| out.correlation[a][b];
    assert_eq!((c(0, 0), c(1, 1)), (Some(1.0), Some(1.0)));
    assert!((c(0, 1).unwrap() - 0.2).abs() < 1e-15 && c(0, 1) == c(1, 0));
    assert!((0..4).all(|o| c(2, o).is_none() && c(o, 2).is_none()));
    assert!((0..4).all(|o| c(3, o).is_none() && c(o, 3).is_none()));
    // An undetermined parameter has no σ even where its variance is finite.
    let mut out = empty(4);
    set_std_and_correlation(&mut out, &cov, &[false, true, false, false]);
    assert_eq!(out.std, [Some(2.0), None, None, Some(0.0)]);
    assert_eq!(out.correlation[0][1], None);
}

fn decl(lo: f64, hi: f64) -> ParamDecl {
    ParamDecl::rgb("p", lo, hi, lo, "test")
}

#[test]
fn warnings_name_undetermined_parameters_wide_sigmas_and_tight_pairs() {
    let names = ["a", "b", "c"];
    let decls = [decl(1.0, 2.0), decl(0.0, 2.0), decl(0.0, 1.0)];
    let mut out = empty(3);
    out.std = vec![Some(1.5), Some(1.5), None];
    for a in 0..2 {
        for b in 0..2 {
            out.correlation[a][b] = Some(if a == b { 1.0 } else { -0.995 });
        }
    }
    let w = determinacy_warnings(&out, &[false, false, true], &names, &decls);
    assert_eq!(w.len(), 3, "{w:?}");
    assert!(w[0].contains("singular") && w[0].ends_with(": c"), "{w:?}");
    // σ 1.5 exceeds a's range 1, not b's range 2.
    assert!(
        w[1].starts_with("a is not determined") && w[1].contains("range 1"),
        "{w:?}"
    );
    assert!(
        w[2].starts_with("a and b are not separately determined"),
        "{w:?}"
    );
    // |correlation| 0.99 itself and σ equal to the range pass.
    out.std = vec![Some(1.0), Some(2.0), None];
    out.correlation[0][1] = Some(0.99);
    out.correlation[1][0] = Some(0.99);
    let w = determinacy_warnings(&out, &[false; 3], &names, &decls);
    assert!(w.is_empty(), "{w:?}");
}

/// C = [[1, 0, r], [0, 1, r], [r, r, 1]]: every pairwise |correlation| ≤ r, while
/// (C⁻¹)₃₃ = 1/(1 − 2r²) and (C⁻¹)₁₁ = (1 − r²)/(1 − 2r²), so R₃² = 2r² and
/// R₁² = r²/(1 − r²): at r = 0.705 all three exceed 0.99², at r = 0.7 none does
/// (R₃ = 0.98995).
#[test]
fn a_three_way_trade_off_warns_on_its_multiple_correlation() {
    let names = ["a", "b", "c"];
    let with = |r: f64, ab: f64| {
        let mut out = empty(3);
        out.std = vec![Some(1.0); 3];
        let c = [[1.0, ab, r], [ab, 1.0, r], [r, r, 1.0]];
        out.correlation = (c.iter())
            .map(|row| row.iter().map(|&v| Some(v)).collect())
            .collect();
        out
    };
    let w = multiple_correlation_warnings(&with(0.705, 0.0), &names, &[true; 3]);
    assert_eq!(w.len(), 3, "{w:?}");
    assert!(
        w[2].starts_with("c is not separately determined from a, b"),
        "{w:?}"
    );
    let r3: f64 = w[2]
        .split("multiple correlation ")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .and_then(|s| s.parse().ok())
        .unwrap();
    assert!((r3 - (2.0f64 * 0.705 * 0.705).sqrt()).abs() < 1e-4, "{r3}");
    assert!(multiple_correlation_warnings(&with(0.7, 0.0), &names, &[true; 3]).is_empty());
    // A parameter with a pairwise |correlation| above 0.99 is left to that warning.
    let w = multiple_correlation_warnings(&with(0.1, 0.995), &names, &[true; 3]);
    assert!(w.is_empty(), "{w:?}");
    // A parameter with σ = 0 (no correlations) takes no part.
    let mut four = empty(4);
    let three = with(0.705, 0.0);
    four.std = vec![Some(1.0), Some(1.0), Some(1.0), Some(0.0)];
    for a in 0..3 {
        four.correlation[a][..3].copy_from_slice(&three.correlation[a]);
    }
    let w = multiple_correlation_warnings(&four, &["a", "b", "c", "d"], &[true; 4]);
    assert_eq!(w.len(), 3, "{w:?}");
    // Fewer than three determined parameters: nothing to add.
    let mut two = with(0.705, 0.0);
    two.std[2] = None;
    assert!(multiple_correlation_warnings(&two, &names, &[true; 3]).is_empty());
}

#[test]
fn ridges_are_the_weak_eigenvectors_in_the_unit_box() {
    let decls = [decl(0.0, 1.0), decl(0.0, 1.0), decl(0.0, 4.0)];
    let flat = [0.5, 0.5, 2.0];
    // [[a, b], [b, a]] with a = 200.5, b = −199.5: eigenvalue a − b = 400 along
    // (1, −1)/√2 (σ 0.05: no ridge) and a + b = 1 along (1, 1)/√2 (σ 1: a ridge).
    let jtj = DMatrix::from_row_slice(2, 2, &[200.5, -199.5, -199.5, 200.5]);
    let r = ridges(&jtj, 1.0, &[0, 1], &unit_slopes(&[0, 1], &flat, &decls));
    assert_eq!(r.len(), 1, "{r:?}");
    assert!((r[0].unit_std - 1.0).abs() < 1e-12, "{r:?}");
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let [(i, a), (j, b)] = r[0].components[..] else {
        panic!("{r:?}")
    };
    assert!((i, j) == (0, 1) || (i, j) == (1, 0), "{r:?}");
    assert!((a.abs() - h).abs() < 1e-9 && (a - b).abs() < 1e-9, "{r:?}");
    // χ²_red scales the standard uncertainty by its root.
    let r = ridges(&jtj, 4.0, &[0, 1], &unit_slopes(&[0, 1], &flat, &decls));
    assert!((r[0].unit_std - 2.0).abs() < 1e-12, "{r:?}");
    // The weakest direction first: one the data do not constrain at all (σ ∞), then
    // σ = 1/√50 along the first parameter.
    let jtj = DMatrix::from_row_slice(2, 2, &[50.0, 0.0, 0.0, 0.0]);
    let r = ridges(&jtj, 1.0, &[0, 2], &unit_slopes(&[0, 2], &flat, &decls));
    assert_eq!(r.len(), 2, "{r:?}");
    assert!(r[0].unit_std.is_infinite() && r[0].components.len() == 1);
    assert_eq!(r[0].components[0].0, 2);
    assert!(
        (r[1].unit_std - 50f64.sqrt().recip()).abs() < 1e-12,
        "{r:?}"
    );
    assert_eq!(r[1].components[0].0, 0);
    // In unit-box terms: the third parameter's range is 4, so JᵀJ = 1 in physical
    // units is 16 in the box (σ 0.25), and 400 on the first σ 0.05 (no ridge).
    let jtj = DMatrix::from_row_slice(2, 2, &[400.0, 0.0, 0.0, 1.0]);
    let r = ridges(&jtj, 1.0, &[0, 2], &unit_slopes(&[0, 2], &flat, &decls));
    assert_eq!(r.len(), 1, "{r:?}");
    assert!((r[0].unit_std - 0.25).abs() < 1e-9, "{r:?}");
    assert_eq!(r[0].components.len(), 1);
    assert_eq!(r[0].components[0].0, 2);
    // Components below 0.2 in size are left out, the rest sorted by size.
    let (c, s) = (0.95f64, (1.0 - 0.95f64 * 0.95).sqrt());
    let (l1, l2) = (1.0, 1e4);
    let m = [
        c * c * l1 + s * s * l2,
        c * s * (l1 - l2),
        c * s * (l1 - l2),
        s * s * l1 + c * c * l2,
    ];
    let r = ridges(
        &DMatrix::from_row_slice(2, 2, &m),
        1.0,
        &[0, 1],
        &unit_slopes(&[0, 1], &flat, &decls),
    );
    assert_eq!(r.len(), 1, "{r:?}");
    assert_eq!(r[0].components.len(), 2, "{r:?}");
    assert_eq!(r[0].components[0].0, 0, "{r:?}");
    let c = 0.99f64;
    let s = (1.0 - c * c).sqrt();
    let m = [
        c * c * l1 + s * s * l2,
        c * s * (l1 - l2),
        c * s * (l1 - l2),
        s * s * l1 + c * c * l2,
    ];
    let r = ridges(
        &DMatrix::from_row_slice(2, 2, &m),
        1.0,
        &[0, 1],
        &unit_slopes(&[0, 1], &flat, &decls),
    );
    assert_eq!(r[0].components.len(), 1, "{r:?}");
    let jtj = DMatrix::from_row_slice(2, 2, &[400.0, 0.0, 0.0, 1600.0]);
    assert!(ridges(&jtj, 1.0, &[0, 2], &unit_slopes(&[0, 2], &flat, &decls)).is_empty());
    let jtj = DMatrix::from_row_slice(2, 2, &[f64::NAN, 0.0, 0.0, 1.0]);
    assert!(ridges(&jtj, 1.0, &[0, 2], &unit_slopes(&[0, 2], &flat, &decls)).is_empty());
    // A standard uncertainty of exactly 0.1 (λ = 100) is a ridge ("at least" 0.1).
    let jtj = DMatrix::from_row_slice(2, 2, &[400.0, 0.0, 0.0, 100.0]);
    let r = ridges(&jtj, 1.0, &[0, 1], &unit_slopes(&[0, 1], &flat, &decls));
    assert_eq!(r.len(), 1, "{r:?}");
    assert_eq!((r[0].unit_std, r[0].components[0].0), (0.1, 1));
    // An eigenvalue of exactly 1e-10 of the largest is no constraint at all; nor is
    // one above 0 but below that.
    let jtj = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, 1e-10]);
    let r = ridges(&jtj, 1.0, &[0, 1], &unit_slopes(&[0, 1], &flat, &decls));
    assert!(
        r[0].unit_std.is_infinite() && r[0].components[0].0 == 1,
        "{r:?}"
    );
    let jtj = DMatrix::from_row_slice(2, 2, &[50.0, 0.0, 0.0, 3e-12]);
    let r = ridges(&jtj, 1.0, &[0, 1], &unit_slopes(&[0, 1], &flat, &decls));
    assert!(
        r[0].unit_std.is_infinite() && r[0].components[0].0 == 1,
        "{r:?}"
    );
}

#[test]
fn unit_slopes_of_linear_and_log_parameters() {
    let lin = decl(0.0, 4.0);
    assert!((unit_slope(&lin, 1.0) - 4.0).abs() < 1e-9);
    assert!((unit_slope(&lin, 0.0) - 4.0).abs() < 1e-9);
    assert!((unit_slope(&lin, 4.0) - 4.0).abs() < 1e-9);
    assert!((unit_std(&lin, 1.0, 0.2) - 0.05).abs() < 1e-9);
    // v = lo (hi/lo)^u: dv/du = v ln(hi/lo).
    let log = decl(0.01, 1.0).log();
    let want = 0.1 * 100f64.ln();
    assert!((unit_slope(&log, 0.1) / want - 1.0).abs() < 1e-6);
    assert!((unit_std(&log, 0.1, 0.01) - 0.01 / want).abs() < 1e-9);
}

#[test]
fn the_free_parameters_are_laid_out_over_the_flat_vector() {
    let mut free = empty(2);
    free.std = vec![Some(1.0), Some(2.0)];
    free.correlation = vec![vec![Some(1.0), Some(0.5)], vec![Some(0.5), Some(1.0)]];
    free.warnings = vec!["w".into()];
    let out = expand(free, &[0, 2], 3);
    assert_eq!(out.std, [Some(1.0), None, Some(2.0)]);
    assert_eq!(out.correlation[0][2], Some(0.5));
    assert_eq!(out.correlation[2][2], Some(1.0));
    assert!((0..3).all(|o| out.correlation[1][o].is_none()));
    assert_eq!(out.warnings, ["w"]);
}

#[test]
fn ridge_words() {
    let names: Vec<String> = ["a", "b", "c"].iter().map(|s| s.to_string()).collect();
    let r = Ridge {
        components: vec![(2, -0.71), (0, 0.7), (1, -0.2)],
        unit_std: 1.0,
    };
    assert_eq!(r.words(&names), "−0.71 c + 0.70 a − 0.20 b");
}
