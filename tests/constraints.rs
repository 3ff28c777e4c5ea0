//! `--fix`, `--bounds` and `--prior` each change what they should (issue: user control of
//! a fit). Synthetic data from known parameters with 2% noise, fitted on the CPU reference
//! with χ² and Levenberg–Marquardt.

mod common;

use bsdfit::bsdf::Model;
use bsdfit::data::Dataset;
use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::inference::constraints::ConstraintSpec;
use bsdfit::inference::fit::{fit, FitOptions, FitReport, Optimizer};

const NOISE: (f64, f64) = (0.02, 1e-4);

fn chi2() -> Loss {
    Loss::new(Metric::Chi2, Weights::Uniform)
}

fn run(model: &Model, data: &Dataset, c: ConstraintSpec) -> FitReport {
    let opts = FitOptions {
        optimizer: Optimizer::Lm,
        restarts: 8,
        seed: 1,
        constraints: c,
        ..Default::default()
    };
    fit(model, data, chi2(), &CpuBackend::new(), &opts, &mut |_| {})
        .unwrap_or_else(|e| panic!("{}: {e:#}", model.spec))
}

fn spec(fix: &[&str], bounds: &[&str], priors: &[&str]) -> ConstraintSpec {
    ConstraintSpec::parse(fix, bounds, priors, false).unwrap()
}

fn value(r: &FitReport, name: &str) -> (f64, Option<f64>) {
    let i = r
        .flat_names
        .iter()
        .position(|n| n == name)
        .unwrap_or_else(|| panic!("{name} not in {:?}", r.flat_names));
    (r.flat_params[i], r.flat_std[i])
}

fn ggx_data(seed: u64) -> (Model, Vec<f64>, Dataset) {
    common::synth_geometry(
        "ggx",
        "ks=0.6,alpha=0.2,eta=1.6",
        "inplane10",
        &[550.0],
        NOISE,
        seed,
    )
}

/// A fixed parameter holds its value exactly, is not counted among the fitted parameters
/// (ν grows by one), reports σ = 0, and the others are still recovered within noise.
#[test]
fn fix_holds_the_value_and_frees_a_degree_of_freedom() {
    let (model, _, data) = ggx_data(3);
    let free = run(&model, &data, ConstraintSpec::default());
    let fixed = run(&model, &data, spec(&["eta=1.6"], &[], &[]));
    assert_eq!(value(&fixed, "eta"), (1.6, Some(0.0)));
    assert_eq!(fixed.n_params, free.n_params - 1);
    assert_eq!(fixed.dof, free.dof + 1);
    assert_eq!(free.dof, data.len() - model.dim);
    for (name, truth) in [("ks[0]", 0.6), ("alpha", 0.2)] {
        let (v, s) = value(&fixed, name);
        let s = s.unwrap_or_else(|| panic!("{name} undetermined"));
        assert!(
            (v - truth).abs() < 4.0 * s,
            "{name} = {v} ± {s}, truth {truth}"
        );
        // Fixing a correlated parameter at its true value can only tighten the others.
        let (_, s_free) = value(&free, name);
        assert!(
            s <= s_free.unwrap() * 1.001,
            "{name}: σ {s} vs {s_free:?} free"
        );
    }
    // Fixing it at a wrong value moves the others and raises χ².
    let wrong = run(&model, &data, spec(&["eta=2.5"], &[], &[]));
    assert_eq!(value(&wrong, "eta").0, 2.5);
    assert!(
        wrong.best.loss > fixed.best.loss * 1.5,
        "{} vs {}",
        wrong.best.loss,
        fixed.best.loss
    );
    assert!(wrong.constraints.as_ref().unwrap()["fixed"]["eta"] == 2.5);
}

/// Bounds that contain the optimum change nothing; bounds that exclude it hold the
/// parameter on the bound, with a warning that says so.
#[test]
fn bounds_confine_the_search_and_a_bound_hit_is_reported() {
    let (model, _, data) = ggx_data(4);
    let free = run(&model, &data, ConstraintSpec::default());
    let inside = run(&model, &data, spec(&[], &["alpha=0.1:0.4"], &[]));
    let (a_free, s_free) = value(&free, "alpha");
    let (a_in, _) = value(&inside, "alpha");
    assert!(
        (a_free - a_in).abs() < 0.05 * s_free.unwrap(),
        "{a_free} vs {a_in}"
    );
    assert!(
        inside.warnings.iter().all(|w| !w.contains("bound")),
        "{:?}",
        inside.warnings
    );
    let outside = run(&model, &data, spec(&[], &["alpha=0.3:0.5"], &[]));
    let (a_out, _) = value(&outside, "alpha");
    assert!(
        (a_out - 0.3).abs() < 1e-6,
        "alpha = {a_out}, bounds 0.3:0.5"
    );
    assert!(
        outside.warnings.iter().any(|w| w.contains("alpha")
            && w.contains("lower bound")
            && w.contains("the bounds given")),
        "{:?}",
        outside.warnings
    );
    assert!(outside.best.loss > free.best.loss);
}

/// For a model linear in its parameter (lambert: f = ρ/π) the χ² + prior optimum is the
/// precision-weighted mean of the data's estimate and the prior, and its variance is the
/// inverse of the summed precisions: the prior enters as exactly one residual.
#[test]
fn a_prior_is_one_more_residual_with_the_textbook_posterior() {
    let (model, _, data) =
        common::synth_geometry("lambert", "rho=0.5", "inplane10", &[550.0], NOISE, 5);
    let free = run(&model, &data, ConstraintSpec::default());
    let (rho_hat, _) = value(&free, "rho[0]");
    // The data's information about ρ, Σ (1/(π u))², without any Birge scaling.
    let info: f64 = data
        .samples
        .iter()
        .map(|s| (1.0 / (std::f64::consts::PI * s.uncertainty)).powi(2))
        .sum();
    let sigma_data = info.sqrt().recip();
    // A prior as informative as the data, centred 5σ away.
    let (mean, sd) = (rho_hat + 5.0 * sigma_data, sigma_data);
    let with = run(
        &model,
        &data,
        spec(&[], &[], &[&format!("rho={mean}:{sd}")]),
    );
    let expect = (rho_hat * info + mean / (sd * sd)) / (info + 1.0 / (sd * sd));
    let (rho_post, s_post) = value(&with, "rho[0]");
    assert!(
        (rho_post - expect).abs() < 0.01 * sigma_data,
        "posterior {rho_post}, expected {expect} (σ_data {sigma_data})"
    );
    // σ_post = (info + 1/sd²)^−½, times the Birge ratio when χ²_red > 1.
    let birge = with.best.chi2_red.max(1.0).sqrt();
    let s_expect = (info + 1.0 / (sd * sd)).sqrt().recip() * birge;
    let s_post = s_post.unwrap();
    assert!(
        (s_post / s_expect - 1.0).abs() < 0.02,
        "σ_post {s_post}, expected {s_expect}"
    );
    // χ²_red counts the prior: (χ² + prior)/(N + 1 − 1).
    assert_eq!(with.dof, data.len());
    let c = with.constraints.as_ref().unwrap();
    let chi2_prior = c["chi2_prior"].as_f64().unwrap();
    assert!((chi2_prior - ((rho_post - mean) / sd).powi(2)).abs() < 1e-9);
    assert!(
        (with.best.chi2_red - with.best.loss / data.len() as f64).abs() < 1e-9 * with.best.chi2_red,
        "χ²_red {} vs (χ² + prior)/ν {}",
        with.best.chi2_red,
        with.best.loss / data.len() as f64
    );
}

/// Priors are a χ² term: other losses refuse them rather than mix units.
#[test]
fn a_prior_needs_the_chi2_loss() {
    let (model, _, data) = ggx_data(6);
    let opts = FitOptions {
        optimizer: Optimizer::Lm,
        restarts: 2,
        constraints: spec(&[], &[], &["alpha=0.2:0.01"]),
        ..Default::default()
    };
    let err = fit(
        &model,
        &data,
        Loss::new(Metric::Rmse, Weights::Uniform),
        &CpuBackend::new(),
        &opts,
        &mut |_| {},
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("prior needs loss='chi2'"), "{err}");
}

/// The CLI: the options reach the fit, the JSON records them, bad names fail before work.
#[test]
fn cli_fix_bounds_prior_reach_the_fit_and_the_json() {
    let dir = std::env::temp_dir().join(format!("bsdfit-constraints-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let data = dir.join("ggx.csv");
    let st = std::process::Command::new(common::bin())
        .args([
            "synth",
            "--model",
            "ggx",
            "--params",
            "ks=0.6,alpha=0.2,eta=1.6",
        ])
        .args(["--geometry", "inplane10", "--out"])
        .arg(&data)
        .output()
        .unwrap();
    assert!(
        st.status.success(),
        "{}",
        String::from_utf8_lossy(&st.stderr)
    );
    let json = dir.join("fit.json");
    let out = std::process::Command::new(common::bin())
        .arg("fit")
        .arg(&data)
        .args(["--model", "ggx", "--backend", "cpu", "--restarts", "4"])
        .args([
            "--fix",
            "eta=1.6",
            "--bounds",
            "alpha=0.05:0.5",
            "--prior",
            "ks=0.6:0.1",
        ])
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // synth writes three channels: ks is per channel, so its prior is three residuals.
    assert!(
        stdout.contains("(fixed)") && stdout.contains("3 priors in χ²"),
        "{stdout}"
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["constraints"]["fixed"]["eta"], 1.6);
    assert_eq!(
        v["constraints"]["bounds"]["alpha"],
        serde_json::json!([0.05, 0.5])
    );
    assert_eq!(v["constraints"]["priors"][2]["name"], "ks[2]");
    assert_eq!(v["n_params"], 4);
    let bad = std::process::Command::new(common::bin())
        .arg("fit")
        .arg(&data)
        .args(["--model", "ggx", "--backend", "cpu", "--fix", "sigma=0.3"])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        !bad.status.success()
            && err.contains("--fix sigma=0.3")
            && err.contains("no parameter 'sigma'"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
