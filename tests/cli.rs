//! The command line end to end (docs/output.md): `synth` then `fit --json`, and clear errors
//! (exit code 1, file and line named, never a panic) for bad input.

mod common;

use serde_json::Value;
use std::path::{Path, PathBuf};

use common::cli::{assert_clear_error, assert_ok, bsdfit, p, text};

/// An Oren–Nayar dataset (σ = 0.7 rad, 3 channels, inplane10, 1.5% noise) in `dir`.
fn synth_on(dir: &Path) -> PathBuf {
    let data = dir.join("on.csv");
    let out = bsdfit(&[
        "synth",
        "--model",
        "on",
        "--params",
        "rho=0.3:0.5:0.7,sigma=0.7",
        "--geometry",
        "inplane10",
        "--noise",
        "0.015,0.0001",
        "--seed",
        "5",
        "--out",
        p(&data),
    ]);
    assert_ok(&out, "synth");
    let written = std::fs::read_to_string(&data).unwrap();
    assert!(
        written.starts_with("# bsdfit dataset v1\n"),
        "{}",
        &written[..written.len().min(200)]
    );
    assert!(written.contains("# kind: brdf"));
    data
}

const BTDF_FILE: &str = "# bsdfit dataset v1\n# kind: btdf\ntheta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty\n\
0,0,0,0,633,5.0,0.1\n0,0,5,0,633,2.0,0.05\n0,0,10,0,633,0.8,0.02\n0,0,-5,0,633,2.1,0.05\n0,0,-10,0,633,0.7,0.02\n";

#[test]
fn synth_then_fit_recovers_sigma_and_writes_the_report() {
    let dir = tempfile::tempdir().unwrap();
    let data = synth_on(dir.path());
    let json = dir.path().join("fit.json");
    let out = bsdfit(&[
        "fit",
        p(&data),
        "--model",
        "on",
        "--loss",
        "rmse",
        "--optimizer",
        "compass",
        "--backend",
        "cpu",
        "--restarts",
        "8",
        "--json",
        p(&json),
    ]);
    assert_ok(&out, "fit");
    assert!(!text(&out.stderr).contains("panicked"));
    let r: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for key in [
        "model",
        "loss",
        "weights",
        "optimizer",
        "backend",
        "restarts",
        "evaluations",
        "seconds",
        "best",
    ] {
        assert!(r.get(key).is_some(), "missing key {key} in {r:#}");
    }
    assert_eq!(r["model"], "on");
    assert_eq!(r["loss"], "rmse");
    assert_eq!(r["weights"], "uniform");
    assert_eq!(r["optimizer"], "compass");
    assert_eq!(r["backend"], "cpu");
    assert_eq!(r["restarts"], 8);
    assert!(
        r["evaluations"].as_u64().is_some_and(|e| e > 0),
        "{}",
        r["evaluations"]
    );
    assert!(
        r["seconds"]
            .as_f64()
            .is_some_and(|s| s.is_finite() && s >= 0.0),
        "{}",
        r["seconds"]
    );
    let best = &r["best"];
    for key in ["loss", "chi2_red", "params", "param_std"] {
        assert!(best.get(key).is_some(), "missing best.{key}");
    }
    let loss = best["loss"].as_f64().unwrap();
    assert!(loss.is_finite() && loss > 0.0, "loss {loss}");
    let chi = best["chi2_red"].as_f64().unwrap();
    assert!(chi.is_finite() && chi > 0.0 && chi < 2.0, "chi2_red {chi}");
    let rho = best["params"]["rho"].as_array().expect("rho is an array");
    assert_eq!(rho.len(), 3);
    for (v, want) in rho.iter().zip([0.3, 0.5, 0.7]) {
        let v = v.as_f64().unwrap();
        assert!((v - want).abs() < 0.02, "rho {v} vs {want}");
    }
    let sigma = best["params"]["sigma"].as_f64().unwrap();
    assert!((sigma - 0.7).abs() < 0.05, "sigma {sigma}");
    let std_rho = best["param_std"]["rho"]
        .as_array()
        .expect("param_std.rho is an array");
    assert_eq!(std_rho.len(), 3);
    assert!(
        std_rho
            .iter()
            .all(|v| v.as_f64().is_some_and(|s| s.is_finite() && s > 0.0)),
        "{std_rho:?}"
    );
    let std_sigma = best["param_std"]["sigma"].as_f64().unwrap();
    assert!(
        std_sigma.is_finite() && std_sigma > 0.0 && std_sigma < 0.05,
        "std sigma {std_sigma}"
    );
    // The human summary names the parameters.
    let so = text(&out.stdout);
    assert!(so.contains("sigma") && so.contains("rho[2]"), "{so}");
}

#[test]
fn nan_cell_names_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("bad.csv");
    std::fs::write(
        &f,
        "# bsdfit dataset v1\n# kind: brdf\ntheta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty\n\
0,0,10,0,550,0.25,0.01\n0,0,20,0,550,0.24,0.01\n10,0,30,0,550,0.23,0.01\n10,0,40,0,550,NaN,0.01\n10,0,50,0,550,0.2,0.01\n",
    )
    .unwrap();
    let out = bsdfit(&["fit", p(&f), "--model", "lambert", "--backend", "cpu"]);
    assert_clear_error(&out, &["bad.csv:7", "value"]);
}

#[test]
fn unknown_model_spec() {
    let dir = tempfile::tempdir().unwrap();
    let data = synth_on(dir.path());
    let out = bsdfit(&["fit", p(&data), "--model", "lambret", "--backend", "cpu"]);
    assert_clear_error(&out, &["unknown model 'lambret'", "lambert"]);
    let out = bsdfit(&["fit", p(&data), "--model", "fa(eon", "--backend", "cpu"]);
    assert_clear_error(&out, &["fa(eon", "')'"]);
    let out = bsdfit(&[
        "synth",
        "--model",
        "nope",
        "--out",
        p(&dir.path().join("x.csv")),
    ]);
    assert_clear_error(&out, &["unknown model 'nope'"]);
}

/// A bad `--params` assignment is refused naming the option as the command line spells
/// it (the library's message names only the assignment), for synth and render alike.
#[test]
fn bad_params_name_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let out = bsdfit(&[
        "synth",
        "--model",
        "lambert",
        "--params",
        "albedo=0.5",
        "--out",
        p(&dir.path().join("x.csv")),
    ]);
    let err = assert_clear_error(
        &out,
        &["error: --params: model lambert has no parameter 'albedo' (it has: rho)"],
    );
    assert!(!dir.path().join("x.csv").exists(), "{err}");
    let data = synth_on(dir.path());
    let out = bsdfit(&[
        "render",
        p(&data),
        "--model",
        "on",
        "--params",
        "sigma",
        "--out",
        p(&dir.path().join("r")),
    ]);
    assert_clear_error(&out, &["error: --params: 'sigma' is not name=value"]);
}

/// A battery case id past the plan would run nothing and print an empty table: it is
/// refused, naming the flag and the plan's range.
#[test]
fn battery_case_past_the_plan_is_refused() {
    let out = bsdfit(&[
        "battery",
        "--cases",
        "0",
        "--nulls",
        "2",
        "--misspecified",
        "3",
        "--misspecified-btdf",
        "1",
        "--case",
        "6",
    ]);
    assert_clear_error(
        &out,
        &[
            "error: --case 6: this battery has cases 0–5 (0 per effect × ",
            "3 misspecified, 1 misspecified BTDF)",
        ],
    );
}

/// Refusals that have an obvious next step name it: a geometry of the other kind, a MERL
/// table of the wrong data, a JSON that holds no fit to render.
#[test]
fn refusals_name_the_next_step() {
    let dir = tempfile::tempdir().unwrap();
    let out = bsdfit(&[
        "synth",
        "--model",
        "on",
        "--geometry",
        "oblique",
        "--out",
        p(&dir.path().join("x.csv")),
    ]);
    assert_clear_error(
        &out,
        &["is a btdf geometry but on is a brdf model: give a brdf geometry (`bsdfit models`"],
    );
    let out = bsdfit(&[
        "synth",
        "--model",
        "on",
        "--wavelengths",
        "550",
        "--out",
        p(&dir.path().join("x.binary")),
    ]);
    assert_clear_error(
        &out,
        &["this is brdf data in 1 channel: give three wavelengths, e.g. --wavelengths 450,550,650"],
    );
    let out = bsdfit(&[
        "synth",
        "--model",
        "btdf(tr)",
        "--out",
        p(&dir.path().join("t.binary")),
    ]);
    assert_clear_error(
        &out,
        &["this is btdf data in 1 channel: write it as a bsdfit CSV"],
    );
    let data = synth_on(dir.path());
    let json = dir.path().join("other.json");
    std::fs::write(&json, r#"{"per_axis": []}"#).unwrap();
    let out = bsdfit(&[
        "render",
        p(&data),
        "--fit",
        p(&json),
        "--out",
        p(&dir.path().join("r")),
    ]);
    assert_clear_error(
        &out,
        &["the JSON has no model and best.params: give a fit report of `bsdfit fit --json`"],
    );
}

/// The library names its options as fields; the command line prints them as its flags
/// (diagnose's significance level and start model, sweep's optimizers).
#[test]
fn library_fields_print_as_flags() {
    let dir = tempfile::tempdir().unwrap();
    let data = synth_on(dir.path());
    let diagnose = |extra: &[&str]| {
        let mut args = vec!["diagnose", p(&data), "--backend", "cpu"];
        args.extend_from_slice(extra);
        bsdfit(&args)
    };
    let out = diagnose(&["--model", "on", "--alpha", "2"]);
    assert_clear_error(&out, &["error: --alpha must be in (0, 1), got 2"]);
    let out = diagnose(&["--model", "lambret"]);
    assert_clear_error(
        &out,
        &["error: --model: model spec 'lambret': unknown model 'lambret'"],
    );
    let out = bsdfit(&[
        "sweep",
        p(&data),
        "--models",
        "lambert",
        "--optimizer",
        "newton",
        "--backend",
        "cpu",
        "--out",
        p(&dir.path().join("run")),
    ]);
    assert_clear_error(
        &out,
        &["error: --optimizer: unknown 'newton' (auto, lm, compass)"],
    );
}

#[test]
fn unknown_loss_and_weights() {
    let dir = tempfile::tempdir().unwrap();
    let data = synth_on(dir.path());
    let out = bsdfit(&[
        "fit",
        p(&data),
        "--model",
        "on",
        "--loss",
        "l3",
        "--backend",
        "cpu",
    ]);
    assert_clear_error(&out, &["unknown loss 'l3'"]);
    let out = bsdfit(&[
        "fit",
        p(&data),
        "--model",
        "on",
        "--weights",
        "heavy",
        "--backend",
        "cpu",
    ]);
    assert_clear_error(&out, &["unknown weights 'heavy'"]);
}

#[test]
fn brdf_loss_on_btdf_data() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("t.csv");
    std::fs::write(&f, BTDF_FILE).unwrap();
    let out = bsdfit(&[
        "fit",
        p(&f),
        "--model",
        "lambert",
        "--loss",
        "rmse",
        "--backend",
        "cpu",
    ]);
    assert_clear_error(&out, &["rmse", "btdf"]);
    // A BRDF model on BTDF data, with a loss valid for both.
    let out = bsdfit(&[
        "fit",
        p(&f),
        "--model",
        "lambert",
        "--loss",
        "chi2",
        "--backend",
        "cpu",
    ]);
    assert_clear_error(&out, &["brdf", "btdf"]);
}

#[test]
fn lm_with_a_non_sum_of_squares_loss() {
    let dir = tempfile::tempdir().unwrap();
    let data = synth_on(dir.path());
    let out = bsdfit(&[
        "fit",
        p(&data),
        "--model",
        "on",
        "--loss",
        "smape",
        "--optimizer",
        "lm",
        "--backend",
        "cpu",
    ]);
    assert_clear_error(&out, &["lm", "smape"]);
}

#[test]
fn data_errors_are_clear() {
    let dir = tempfile::tempdir().unwrap();
    // Missing file.
    let missing = dir.path().join("missing.csv");
    let out = bsdfit(&["fit", p(&missing), "--model", "lambert", "--backend", "cpu"]);
    assert_clear_error(&out, &["missing.csv"]);
    // Two requested wavelengths map to the same channel.
    let data = synth_on(dir.path());
    let out = bsdfit(&[
        "fit",
        p(&data),
        "--model",
        "on",
        "--wavelengths",
        "640,660",
        "--backend",
        "cpu",
    ]);
    assert_clear_error(&out, &["on.csv", "650"]);
    // Fewer samples than parameters (docs/conventions.md).
    let f = dir.path().join("two.csv");
    std::fs::write(
        &f,
        "# kind: brdf\ntheta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty\n0,0,10,0,550,0.25,0.01\n0,0,20,0,550,0.24,0.01\n",
    )
    .unwrap();
    let out = bsdfit(&["fit", p(&f), "--model", "on", "--backend", "cpu"]);
    assert_clear_error(&out, &["two.csv", "2 samples"]);
    // One sample cannot determine the one parameter of lambert: "1 sample", singular.
    let f = dir.path().join("one.csv");
    std::fs::write(
        &f,
        "# kind: brdf\ntheta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty\n0,0,10,0,550,0.25,0.01\n",
    )
    .unwrap();
    let out = bsdfit(&["fit", p(&f), "--model", "lambert", "--backend", "cpu"]);
    let e = assert_clear_error(&out, &["one.csv", "1 sample cannot"]);
    assert!(!e.contains("1 samples"), "{e}");
    // A geometry written twice (once with a signed angle) is two independent samples,
    // announced, not an error (docs/conventions.md).
    let f = dir.path().join("dup.csv");
    std::fs::write(
        &f,
        "# kind: brdf\ntheta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty\n10,0,-20,0,550,0.25,0.01\n10,0,20,180,550,0.24,0.01\n",
    )
    .unwrap();
    let out = bsdfit(&[
        "fit",
        p(&f),
        "--model",
        "lambert",
        "--backend",
        "cpu",
        "--restarts",
        "2",
    ]);
    assert_ok(&out, "fit on a repeated geometry");
    let err = text(&out.stderr);
    assert!(
        err.contains("dup.csv") && err.contains("measured more than once"),
        "the repeat is announced:\n{err}"
    );
}

#[test]
fn zero_uncertainty_needs_the_flag_and_is_announced() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("z.csv");
    let mut s =
        String::from("# kind: brdf\ntheta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty\n");
    for (k, t) in [10, 20, 30, 40, 50, 60].iter().enumerate() {
        s += &format!(
            "0,0,{t},0,550,0.2{k},{}\n",
            if k == 2 { "0" } else { "0.01" }
        );
    }
    std::fs::write(&f, s).unwrap();
    let out = bsdfit(&[
        "fit",
        p(&f),
        "--model",
        "lambert",
        "--backend",
        "cpu",
        "--restarts",
        "2",
    ]);
    assert_clear_error(&out, &["z.csv:5", "allow-zero-uncertainty"]);
    let out = bsdfit(&[
        "fit",
        p(&f),
        "--model",
        "lambert",
        "--backend",
        "cpu",
        "--restarts",
        "2",
        "--allow-zero-uncertainty",
    ]);
    assert_ok(&out, "fit --allow-zero-uncertainty");
    let err = text(&out.stderr);
    assert!(
        err.contains("zero uncertaint"),
        "the floor is announced:\n{err}"
    );
}

#[test]
fn synth_rejects_out_of_bounds_parameters() {
    let dir = tempfile::tempdir().unwrap();
    let out = bsdfit(&[
        "synth",
        "--model",
        "on",
        "--params",
        "sigma=3",
        "--out",
        p(&dir.path().join("x.csv")),
    ]);
    assert_clear_error(&out, &["sigma", "bounds"]);
    let out = bsdfit(&[
        "synth",
        "--model",
        "on",
        "--params",
        "rho=0.5",
        "--noise",
        "0,0",
        "--out",
        p(&dir.path().join("x.csv")),
    ]);
    assert_clear_error(&out, &["noise"]);
}

#[test]
fn convert_reads_any_format_and_says_where_it_came_from() {
    let dir = tempfile::tempdir().unwrap();
    let alta = dir.path().join("tape.dat");
    std::fs::write(
        &alta,
        "#SAMPLE \"tape\"\n#DIM 3 1\n#PARAM_IN ISOTROPIC_TL_TV_PROJ_DPHI\n#PARAM_OUT INV_STERADIAN_COSINE_FACTOR\n0.5 0.5 0 1.2\n0.5 -0.5 0 2.4\n0.5 0.2 0.2 0.8\n",
    )
    .unwrap();
    let out_csv = dir.path().join("tape.csv");
    let out = bsdfit(&["convert", p(&alta), "--out", p(&out_csv)]);
    assert_clear_error(&out, &["tape.dat", "--assume-uncertainty"]);
    let out = bsdfit(&[
        "convert",
        p(&alta),
        "--out",
        p(&out_csv),
        "--assume-uncertainty",
        "0.05,0.001",
    ]);
    assert_ok(&out, "convert");
    let err = text(&out.stderr);
    assert!(err.contains("wrote") && err.contains("3 samples"), "{err}");
    let csv = std::fs::read_to_string(&out_csv).unwrap();
    assert!(
        csv.contains("# material: tape")
            && csv.contains("(ALTA text)")
            && csv.contains("# uncertainty: assumed"),
        "{csv}"
    );
    // The converted file fits, and the fit reports the assumption.
    let out = bsdfit(&[
        "fit",
        p(&out_csv),
        "--model",
        "lambert",
        "--backend",
        "cpu",
        "--restarts",
        "2",
    ]);
    assert_ok(&out, "fit of the converted file");
    assert!(
        text(&out.stdout).contains("uncertainties were assumed"),
        "{}",
        text(&out.stdout)
    );
    // A bad --assume-uncertainty is a clear error.
    let out = bsdfit(&[
        "convert",
        p(&alta),
        "--out",
        p(&out_csv),
        "--assume-uncertainty",
        "5%",
    ]);
    assert_clear_error(&out, &["--assume-uncertainty", "REL,ABS"]);
}

/// `bench --sweep` on a tiny data folder (two synthetic Lambertian files, `--models
/// lambert`, 2 restarts): both backends run the sweep, and the JSON carries the timing
/// of each, the GPU/CPU ratio and the comparison. Speed is not asserted; agreement is,
/// since a Lambertian fit is linear and well conditioned.
#[test]
fn bench_sweep_times_both_backends_and_compares_them() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data");
    std::fs::create_dir(&data).unwrap();
    for (name, rho, seed) in [("a", "0.3:0.5:0.7", "1"), ("b", "0.6:0.4:0.2", "2")] {
        let out = bsdfit(&[
            "synth",
            "--model",
            "lambert",
            "--params",
            &format!("rho={rho}"),
            "--noise",
            "0.01,0.0001",
            "--seed",
            seed,
            "--out",
            p(&data.join(format!("{name}.csv"))),
        ]);
        assert_ok(&out, "synth");
    }
    let json = dir.path().join("bench.json");
    let out = bsdfit(&[
        "bench",
        "--models",
        "lambert",
        "--seconds",
        "0.02",
        "--restarts",
        "4",
        "--sweep",
        "--sweep-data",
        p(&data),
        "--sweep-restarts",
        "2",
        "--json",
        p(&json),
    ]);
    assert_ok(&out, "bench --sweep");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(v["rows"].as_array().is_some_and(|r| !r.is_empty()), "{v}");
    let s = &v["sweep"];
    let backends = s["backends"].as_array().expect("sweep.backends");
    let ids: Vec<&str> = backends
        .iter()
        .filter_map(|b| b["backend"].as_str())
        .collect();
    assert_eq!(ids, ["cpu", "simd", "gpu"], "{s}");
    for b in backends {
        // 2 files × (rmse/uniform, rmse/relunc, chi2) = 6 fits per backend
        assert_eq!(b["fits"], 6, "{b}");
        assert!(b["wall_seconds"].as_f64().is_some_and(|w| w > 0.0), "{b}");
        assert!(b["evaluations"].as_u64().is_some_and(|e| e > 0), "{b}");
        assert!(b["evals_per_s"].as_f64().is_some_and(|e| e > 0.0), "{b}");
        // Every phase timed, none negative or NaN; the search did run.
        let ph = &b["phases"];
        for key in ["setup", "screening", "search", "polish", "conclusions"] {
            assert!(ph[key].as_f64().is_some_and(|s| s >= 0.0), "{key}: {ph}");
        }
        assert!(ph["search"].as_f64().unwrap() > 0.0, "{ph}");
    }
    assert!(
        s["gpu_cpu_time_ratio"].as_f64().is_some_and(|r| r > 0.0),
        "{s}"
    );
    // The GPU's device submissions: some, and no more evaluations in all than the sweep
    // counted (its polish and the fits' conclusions run on the CPU); the CPU reference
    // submits nothing.
    // The host engines submit nothing.
    assert!(backends[0].get("submissions").is_none(), "{s}");
    assert!(backends[1].get("submissions").is_none(), "{s}");
    let sub = &backends[2]["submissions"];
    let n = sub["submissions"].as_f64().expect("gpu submissions");
    assert!(n > 0.0, "{sub}");
    let on_device = sub["evaluations"]["mean"].as_f64().unwrap() * n;
    let counted = backends[2]["evaluations"].as_f64().unwrap();
    assert!(
        on_device > 0.0 && on_device <= counted * (1.0 + 1e-9),
        "{sub} vs {counted}"
    );
    let cand = &sub["candidates"];
    assert!(cand["median"].as_f64().unwrap() >= 1.0, "{sub}");
    assert!(cand["max"].as_f64() >= cand["p90"].as_f64(), "{sub}");
    assert!(sub["seconds"]["median"].as_f64().unwrap() > 0.0, "{sub}");
    assert!(
        s["simd_cpu_time_ratio"].as_f64().is_some_and(|r| r > 0.0),
        "{s}"
    );
    // The GPU's sweep and the SIMD engine's, each against the CPU reference's.
    for c in [&s["comparison"], &s["simd_comparison"]] {
        sweep_comparison_is_within_tolerance(c);
    }
    let stdout = text(&out.stdout);
    assert!(stdout.contains("GPU/CPU sweep time ratio"), "{stdout}");
    assert!(stdout.contains("SIMD/CPU sweep time ratio"), "{stdout}");
}

/// A comparison of `bench --sweep` (an f32 engine's sweep against the CPU reference's)
/// on the Lambertian fits of its test.
fn sweep_comparison_is_within_tolerance(c: &serde_json::Value) {
    assert_eq!(c["fits_compared"], 6, "{c}");
    assert_eq!(c["rankings_identical"], true, "{c}");
    assert_eq!(c["groups_reordered"], 0, "{c}");
    assert_eq!(c["rankings_agree_up_to_ties"], true, "{c}");
    // The bounds are the test's own, not the bench's: a Lambertian fit is linear and both
    // backends end it with the same f64 polish, so they reach the same optimum to the
    // polish's stopping test (measured: 5e-11 in the loss, 5e-8 of the unit box), far
    // inside the bench's documented tolerances, which the JSON must state unchanged.
    let loss = c["max_rel_loss_diff"]["value"].as_f64().unwrap();
    let param = c["max_param_diff_unit_box"]["value"].as_f64().unwrap();
    assert!(loss <= 1e-8, "{c}");
    assert!(param <= 1e-6, "{c}");
    for (key, documented) in [
        ("loss_tolerance", 1e-3),
        ("param_tolerance", 1e-2),
        ("param_tolerance_sigma", 0.05),
    ] {
        assert_eq!(c[key].as_f64(), Some(documented), "{key}: {c}");
    }
    assert_eq!(c["fits_at_different_optima"], 0, "{c}");
    let over = c["max_param_diff_over_tolerance"]["value"]
        .as_f64()
        .unwrap();
    assert!(over <= 1.0, "{c}");
    assert_eq!(c["within_tolerance"], true, "{c}");
}

/// With `--backend cpu` only the CPU sweep is timed, and nothing is compared.
#[test]
fn bench_sweep_with_the_cpu_backend_times_the_cpu_only() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a.csv");
    let out = bsdfit(&[
        "synth",
        "--model",
        "lambert",
        "--params",
        "rho=0.5",
        "--noise",
        "0.01,0.0001",
        "--out",
        p(&file),
    ]);
    assert_ok(&out, "synth");
    let json = dir.path().join("bench.json");
    let bench_cpu = |more: &[&str]| {
        let mut args = vec![
            "bench",
            "--backend",
            "cpu",
            "--models",
            "lambert",
            "--sweep",
            "--sweep-data",
            p(&file),
        ];
        args.extend(more);
        bsdfit(&args)
    };
    let out = bench_cpu(&[
        "--seconds",
        "0.02",
        "--sweep-restarts",
        "2",
        "--sweep-reference-seed",
        "7",
        "--json",
        p(&json),
    ]);
    assert_ok(&out, "bench --sweep --backend cpu");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let ids: Vec<&str> = v["sweep"]["backends"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|b| b["backend"].as_str())
        .collect();
    assert_eq!(ids, ["cpu"]);
    assert!(v["sweep"]["gpu_cpu_time_ratio"].is_null() && v["sweep"]["comparison"].is_null());
    // The reference against itself with seed 7: 3 fits (rmse/uniform, rmse/relunc,
    // chi2) of a convex Lambertian loss, so both seeds reach the same optimum.
    let r = &v["sweep"]["reference_seed"];
    assert_eq!(r["seed"], 7, "{r}");
    let c = &r["comparison"];
    assert_eq!(c["fits_compared"], 3, "{c}");
    assert_eq!(c["rankings_agree_up_to_ties"], true, "{c}");
    assert!(
        c["max_rel_loss_diff"]["value"]
            .as_f64()
            .is_some_and(|d| d < 1e-6),
        "{c}"
    );
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("seed 1 against seed 7"), "{text}");
    // Its own seed is refused, naming the option.
    let out = bench_cpu(&["--sweep-reference-seed", "1"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--sweep-reference-seed 1"), "{err}");
}

/// `bench --data FILE` measures on the file: the rows name it and count its samples,
/// and the CPU rows carry the thread count and a positive rate; a model of the other
/// kind is a clear error naming the option, before anything is measured.
#[test]
fn bench_measures_on_a_data_file() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("fa.csv");
    let out = bsdfit(&[
        "synth",
        "--model",
        "fa(lambert)",
        "--geometry",
        "offplane",
        "--out",
        p(&file),
    ]);
    assert_ok(&out, "synth");
    let json = dir.path().join("bench.json");
    let out = bsdfit(&[
        "bench",
        "--backend",
        "cpu",
        "--models",
        "fa(lambert),lambert",
        "--data",
        p(&file),
        "--restarts",
        "2",
        "--seconds",
        "0.02",
        "--json",
        p(&json),
    ]);
    assert_ok(&out, "bench --data");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let rows = v.as_array().unwrap();
    assert_eq!(rows.len(), 2, "{v}");
    // offplane: 36 directions, 3 channels each.
    for r in rows {
        assert_eq!(r["data"].as_str(), Some(p(&file)), "{r}");
        assert_eq!(r["samples"], 108, "{r}");
        assert_eq!(r["backend"], "cpu", "{r}");
        assert!(r["threads"].as_u64().is_some_and(|t| t >= 1), "{r}");
        assert!(r["evals_per_s"].as_f64().is_some_and(|e| e > 0.0), "{r}");
    }
    let out = bsdfit(&[
        "bench",
        "--backend",
        "cpu",
        "--models",
        "btdf(tr)",
        "--data",
        p(&file),
    ]);
    assert_clear_error(&out, &["--models", "btdf(tr)", "brdf"]);
}

/// Real ALTA files often come without `#PARAM_OUT` (issue "Real files as they come"):
/// `--alta-values brdf|brdf-cos` says what their values are. On the tape-shaped fixture
/// (tests/fixtures/, values BRDF × cos θo, no `#PARAM_OUT`): `fit` refuses it naming the
/// option, fits it with the option and prints the reader's notice, and `--help` lists the
/// values with their meaning. Every command that reads data takes the option and hands it
/// to the reader: with `#PARAM_OUT INV_STERADIAN_COSINE_FACTOR` put back, `--alta-values
/// brdf` is refused by each of them, naming both.
#[test]
fn alta_values_option_reads_files_without_param_out() {
    let dir = tempfile::tempdir().unwrap();
    let file =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/alta_tape_no_param_out.dat");
    let fit = |extra: &[&str]| {
        let mut args = vec![
            "fit",
            p(&file),
            "--model",
            "lambert",
            "--assume-uncertainty",
            "0.03,0.001",
            "--backend",
            "cpu",
            "--restarts",
            "2",
        ];
        args.extend_from_slice(extra);
        bsdfit(&args)
    };
    let out = fit(&[]);
    assert_clear_error(
        &out,
        &[
            "alta_tape_no_param_out.dat: missing #PARAM_OUT line",
            "--alta-values brdf (the BRDF, sr⁻¹)",
            "--alta-values brdf-cos (BRDF × cos θo)",
        ],
    );
    let json = dir.path().join("fit.json");
    let out = fit(&["--alta-values", "brdf-cos", "--json", p(&json)]);
    assert_ok(&out, "fit --alta-values brdf-cos");
    let err = text(&out.stderr);
    assert!(
        err.contains("value kind taken from --alta-values brdf-cos")
            && err.contains("divided by cos θo"),
        "{err}"
    );
    let r: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(r["model"], "lambert", "{r:#}");
    // A value the option does not know is a usage error that lists the two it knows.
    let out = fit(&["--alta-values", "cos"]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains("brdf-cos") && !err.contains("panicked"),
        "{err}"
    );

    let help = text(&bsdfit(&["fit", "--help"]).stdout);
    assert!(
        help.contains("--alta-values")
            && help.contains("brdf:")
            && help.contains("brdf-cos:")
            && help.contains("INV_STERADIAN_COSINE_FACTOR"),
        "{help}"
    );

    // Every data command hands the option to the reader.
    let header = dir.path().join("tape-header.dat");
    let text_with = std::fs::read_to_string(&file).unwrap().replace(
        "#PARAM_IN ISOTROPIC_TL_TV_PROJ_DPHI\n",
        "#PARAM_IN ISOTROPIC_TL_TV_PROJ_DPHI\n#PARAM_OUT INV_STERADIAN_COSINE_FACTOR\n",
    );
    std::fs::write(&header, text_with).unwrap();
    let h = p(&header);
    let (csv, out_dir) = (dir.path().join("out.csv"), dir.path().join("out"));
    let (csv, out_dir) = (p(&csv), p(&out_dir));
    // (command, its arguments, whether it takes --backend)
    let commands: [(&str, Vec<&str>, bool); 7] = [
        ("fit", vec!["fit", h, "--model", "lambert"], true),
        ("diagnose", vec!["diagnose", h, "--model", "lambert"], true),
        ("convert", vec!["convert", h, "--out", csv], false),
        (
            "sweep",
            vec!["sweep", h, "--models", "lambert", "--out", out_dir],
            true,
        ),
        (
            "eval",
            vec!["eval", p(&json), "--at", h, "--out", csv],
            false,
        ),
        (
            "bench",
            vec!["bench", "--data", h, "--models", "lambert"],
            true,
        ),
        (
            "render",
            vec![
                "render", h, "--model", "lambert", "--params", "rho=0.5", "--out", out_dir,
            ],
            false,
        ),
    ];
    for (name, mut args, backend) in commands {
        let help = text(&bsdfit(&[name, "--help"]).stdout);
        assert!(help.contains("--alta-values"), "{name} --help:\n{help}");
        if backend {
            args.extend(["--backend", "cpu"]);
        }
        args.extend([
            "--assume-uncertainty",
            "0.03,0.001",
            "--alta-values",
            "brdf",
        ]);
        let out = bsdfit(&args);
        assert_clear_error(
            &out,
            &[
                "tape-header.dat:6: #PARAM_OUT INV_STERADIAN_COSINE_FACTOR (BRDF × cos θo)",
                "disagrees with --alta-values brdf (the BRDF, sr⁻¹)",
            ],
        );
    }
    // With the agreeing value, convert reads the header file and the header-less one alike.
    let a = dir.path().join("a.csv");
    let b = dir.path().join("b.csv");
    for (input, out) in [(h, &a), (p(&file), &b)] {
        let o = bsdfit(&[
            "convert",
            input,
            "--out",
            p(out),
            "--assume-uncertainty",
            "0.03,0.001",
            "--alta-values",
            "brdf-cos",
        ]);
        assert_ok(&o, "convert --alta-values brdf-cos");
    }
    let rows = |f: &Path| -> Vec<String> {
        std::fs::read_to_string(f)
            .unwrap()
            .lines()
            .filter(|l| !l.starts_with('#'))
            .map(String::from)
            .collect()
    };
    assert_eq!(rows(&a), rows(&b));
    assert_eq!(rows(&b).len(), 1 + 27, "header + 27 samples");
    assert!(std::fs::read_to_string(&b)
        .unwrap()
        .contains("from --alta-values brdf-cos"));
}

/// `fit --per-axis` on data measured on one plane says what to do instead.
#[test]
fn per_axis_on_one_plane_names_the_next_step() {
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/data/black-velvet.csv");
    let out = bsdfit(&[
        "fit",
        data,
        "--model",
        "lambert",
        "--per-axis",
        "--backend",
        "cpu",
    ]);
    assert_clear_error(&out, &["is measured on a single plane", "drop --per-axis"]);
}

/// `render --fit results.json` that matches no row says what the rows hold.
#[test]
fn render_without_a_matching_row_lists_what_the_results_hold() {
    let tmp = tempfile::tempdir().unwrap();
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/data/black-velvet.csv");
    let results = tmp.path().join("results.json");
    let row =
        |data: &str, model: &str| serde_json::json!({"data": data, "model": model, "params": {}});
    let write =
        |rows: Vec<Value>| std::fs::write(&results, Value::Array(rows).to_string()).unwrap();
    let out_dir = tmp.path().join("r");
    let render = |model: &str| {
        bsdfit(&[
            "render",
            data,
            "--fit",
            p(&results),
            "--model",
            model,
            "--out",
            p(&out_dir),
        ])
    };
    write(vec![
        row("red-brick", "lambert"),
        row("white-standard", "on"),
    ]);
    assert_clear_error(
        &render("lambert"),
        &[
            "is for data 'black-velvet'",
            "the rows are for: red-brick, white-standard",
        ],
    );
    write(vec![
        row("black-velvet", "on"),
        row("black-velvet", "fa(lambert)"),
    ]);
    assert_clear_error(&render("lambert"), &["its rows' models: fa(lambert), on"]);
}
