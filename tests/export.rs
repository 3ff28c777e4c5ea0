//! Using a fit elsewhere (docs/export.md): `bsdfit eval` and `bsdfit export`, and the data
//! tests that go with them — a MERL round trip, ALTA text against v1 CSV, and a two-plane
//! BTDF whose normal point belongs to both scans.

mod common;

use bsdfit::bsdf::Model;
use bsdfit::data::readers::{self, merl};
use bsdfit::data::{Dataset, ReadOptions};
use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::inference::fit::{fit, FitOptions, FitReport, Optimizer};
use bsdfit::inference::saved::{FitFile, Propagator, SavedFit};
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::cli::{assert_clear_error, assert_ok, bsdfit, p, text};

/// `bsdfit synth` then `bsdfit fit --backend cpu --json`: the data file and the fit JSON.
fn synth_and_fit(
    dir: &Path,
    name: &str,
    model: &str,
    params: &str,
    geometry: &str,
    wavelengths: &str,
) -> (PathBuf, PathBuf) {
    let data = dir.join(format!("{name}.csv"));
    let json = dir.join(format!("{name}.json"));
    let out = bsdfit(&[
        "synth",
        "--model",
        model,
        "--params",
        params,
        "--geometry",
        geometry,
        "--wavelengths",
        wavelengths,
        "--seed",
        "3",
        "--out",
        p(&data),
    ]);
    assert_ok(&out, "synth");
    let out = bsdfit(&[
        "fit",
        p(&data),
        "--model",
        model,
        "--backend",
        "cpu",
        "--restarts",
        "4",
        "--json",
        p(&json),
    ]);
    assert_ok(&out, "fit");
    (data, json)
}

fn saved(json: &Path) -> SavedFit {
    FitFile::read(json).unwrap().select(None, "fit").unwrap()
}

// ---------------------------------------------------------------------------------------
// eval

/// `eval --at` uses only the geometries of its file: a file with zero uncertainties is
/// read with a floor the user did not ask for, and its notice is not shown; the notices
/// about how the file was read are.
#[test]
fn eval_hides_the_notices_of_its_placeholder_uncertainties() {
    let dir = tempfile::tempdir().unwrap();
    let (data, json) = synth_and_fit(dir.path(), "lam", "lambert", "rho=0.5", "inplane10", "550");
    // The same rows with every uncertainty 0 (the last column), and one row repeated.
    let written = std::fs::read_to_string(&data).unwrap();
    let mut zeroed: Vec<String> = written
        .lines()
        .map(|l| match l.rsplit_once(',') {
            Some((head, _)) if !l.starts_with('#') && !l.starts_with("theta") => {
                format!("{head},0")
            }
            _ => l.to_string(),
        })
        .collect();
    let last = zeroed.last().unwrap().clone();
    zeroed.push(last);
    let at = dir.path().join("zero.csv");
    std::fs::write(&at, zeroed.join("\n") + "\n").unwrap();
    let out_csv = dir.path().join("eval.csv");
    let out = bsdfit(&["eval", p(&json), "--at", p(&at), "--out", p(&out_csv)]);
    assert_ok(&out, "eval --at");
    let err = text(&out.stderr);
    assert!(!err.contains("replaced by max("), "{err}");
    assert!(
        err.contains("note: ") && err.contains("1 geometry"),
        "{err}"
    );
}

#[test]
fn eval_of_lambert_propagates_u_rho_over_pi_exactly_and_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let (data, json) = synth_and_fit(
        dir.path(),
        "lam",
        "lambert",
        "rho=0.2:0.5:0.8",
        "inplane10",
        "450,550,650",
    );
    let out_csv = dir.path().join("eval.csv");
    let out = bsdfit(&["eval", p(&json), "--at", p(&data), "--out", p(&out_csv)]);
    assert_ok(&out, "eval --at");
    // The v1 reader reads the output back: same geometries, in the same order.
    let back = Dataset::read(&out_csv, &ReadOptions::default()).unwrap();
    let input = Dataset::read(&data, &ReadOptions::default()).unwrap();
    assert_eq!(back.len(), input.len());
    let report: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let rho = report["best"]["params"]["rho"].as_array().unwrap();
    let u_rho = report["best"]["param_std"]["rho"].as_array().unwrap();
    for (b, s) in back.samples.iter().zip(&input.samples) {
        assert!((b.wi() - s.wi()).length() < 1e-12 && (b.wo() - s.wo()).length() < 1e-12);
        assert_eq!(b.wavelength_nm, s.wavelength_nm);
        // f = ρ/π, so u_f = u_ρ/π exactly (the central difference of a linear function).
        let c = s.channel;
        let f = rho[c].as_f64().unwrap() / std::f64::consts::PI;
        let u = u_rho[c].as_f64().unwrap() / std::f64::consts::PI;
        assert!((b.value - f).abs() <= 1e-14 * f, "{} vs {f}", b.value);
        assert!(
            (b.uncertainty - u).abs() <= 1e-8 * u,
            "u {} vs u_ρ/π = {u}",
            b.uncertainty
        );
    }
    assert!(back.meta["uncertainty"].contains("propagated from the fit's covariance"));
    assert_eq!(back.meta["fit_model"], "lambert");

    // --geometry: the named geometry at every channel of the fit.
    let out = bsdfit(&["eval", p(&json), "--geometry", "hemi", "--out", p(&out_csv)]);
    assert_ok(&out, "eval --geometry");
    let back = Dataset::read(&out_csv, &ReadOptions::default()).unwrap();
    let (_, rows) = bsdfit::workflows::synth::geometry("hemi").unwrap();
    assert_eq!(back.len(), rows.len() * 3);
    assert_eq!(back.channels, vec![450.0, 550.0, 650.0]);
}

/// Draws from N(mean, cov) with the Cholesky factor of cov.
fn mc_std(
    fit: &SavedFit,
    draws: usize,
    seed: u64,
    g: usize,
    wi: glam::DVec3,
    wo: glam::DVec3,
) -> f64 {
    let p = fit.model.dim;
    let cov = nalgebra::DMatrix::from_row_slice(p, p, &fit.covariance());
    let l = cov
        .cholesky()
        .expect("a determined fit has a positive definite covariance");
    let l = l.l();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let n = Normal::new(0.0, 1.0).unwrap();
    let (mut sum, mut sum2) = (0.0, 0.0);
    for _ in 0..draws {
        let z = nalgebra::DVector::from_fn(p, |_, _| n.sample(&mut rng));
        let d = &l * z;
        let theta: Vec<f64> = fit.flat.iter().zip(d.iter()).map(|(a, b)| a + b).collect();
        let f = fit.model.eval(&theta, g, wi, wo);
        sum += f;
        sum2 += f * f;
    }
    let m = sum / draws as f64;
    (sum2 / draws as f64 - m * m).max(0.0).sqrt()
}

#[test]
fn propagated_uncertainty_matches_monte_carlo_over_the_covariance() {
    // A GGX fit on sparse data, so that its parameters are uncertain and correlated (k_s
    // with η through the Fresnel factor): the first-order u_f = sqrt(gᵀ cov g) must agree
    // with the spread of f over parameter draws from N(θ̂, cov).
    let (model, _, data) = common::synth_geometry(
        "ggx",
        "ks=0.5,alpha=0.2,eta=1.5",
        "inplane10",
        &[550.0],
        (0.03, 1e-4),
        4,
    );
    let opts = FitOptions {
        optimizer: Optimizer::Lm,
        restarts: 6,
        ..Default::default()
    };
    let report = fit(
        &model,
        &data,
        Loss::new(Metric::Chi2, Weights::Uniform),
        &CpuBackend::new(),
        &opts,
        &mut |_| {},
    )
    .unwrap();
    let fit = SavedFit::from_value(&serde_json::to_value(&report).unwrap(), "report").unwrap();
    assert!(fit.std.iter().all(|s| s.is_some()), "{:?}", report.warnings);
    // The test exercises the off-diagonal terms: some correlation is strong.
    let strongest = fit
        .correlation
        .iter()
        .enumerate()
        .flat_map(|(a, row)| row.iter().enumerate().filter(move |(b, _)| *b != a))
        .filter_map(|(_, c)| *c)
        .fold(0.0f64, |m, c| m.max(c.abs()));
    assert!(strongest > 0.5, "correlations {:?}", fit.correlation);
    let prop = Propagator::new(&fit);
    let mut diag_only_differs = false;
    for (ti, to, po) in [
        (30.0f64, 30.0f64, 180.0f64),
        (10.0, 60.0, 180.0),
        (50.0, 20.0, 90.0),
    ] {
        let wi = common::dir(ti.to_radians(), 0.0);
        let wo = common::dir(to.to_radians(), po.to_radians());
        let lin = prop.eval(0, wi, wo);
        let mc = mc_std(&fit, 40_000, 9, 0, wi, wo);
        eprintln!(
            "θi {ti}°, θo {to}°, φo {po}°: f = {:.6e}, propagated u = {:.4e}, Monte Carlo {mc:.4e} (ratio {:.4})",
            lin.value,
            lin.uncertainty,
            mc / lin.uncertainty
        );
        // 40 000 draws: the standard error of a standard deviation is 1/sqrt(2N) = 0.35 %;
        // the model is close to linear over ±1σ, so 3 % is MC noise plus curvature.
        assert!(
            (mc / lin.uncertainty - 1.0).abs() < 0.03,
            "θi {ti}, θo {to}, φo {po}: propagated {} vs Monte Carlo {mc}",
            lin.uncertainty
        );
        // Without the correlations the answer would be visibly different somewhere.
        let p = fit.model.dim;
        let cov = fit.covariance();
        let h = 1e-6;
        let mut u2_diag = 0.0;
        for j in 0..p {
            let mut a = fit.flat.clone();
            let mut b = fit.flat.clone();
            a[j] += h * fit.flat[j].abs().max(1e-3);
            b[j] -= h * fit.flat[j].abs().max(1e-3);
            let g = (fit.model.eval(&a, 0, wi, wo) - fit.model.eval(&b, 0, wi, wo)) / (a[j] - b[j]);
            u2_diag += g * g * cov[j * p + j];
        }
        if (u2_diag.sqrt() / lin.uncertainty - 1.0).abs() > 0.1 {
            diag_only_differs = true;
        }
    }
    assert!(
        diag_only_differs,
        "the correlations never mattered: a weak test"
    );
}

#[test]
fn malformed_fit_files_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let (_, json) = synth_and_fit(
        dir.path(),
        "g",
        "ggx",
        "ks=0.5,alpha=0.2,eta=1.5",
        "specular",
        "550",
    );
    let good: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let out_csv = dir.path().join("o.csv");
    let case = |name: &str, body: &str, needles: &[&str]| {
        let f = dir.path().join(name);
        std::fs::write(&f, body).unwrap();
        for args in [
            vec![
                "eval",
                p(&f),
                "--geometry",
                "inplane10",
                "--out",
                p(&out_csv),
            ],
            vec!["export", p(&f), "--format", "merl", "--out", p(&out_csv)],
        ] {
            let out = bsdfit(&args);
            let mut all = needles.to_vec();
            all.push(name);
            assert_clear_error(&out, &all);
        }
    };
    case("empty.json", "", &["not JSON"]);
    case("truncated.json", "{\"model\": \"ggx\", ", &["not JSON"]);
    case(
        "other.json",
        "{\"model\": \"ggx\"}",
        &["not a fit report", "channels"],
    );
    let mut v = good.clone();
    v["model"] = Value::from("on");
    case(
        "renamed.json",
        &v.to_string(),
        &["'flat_names'", "not the parameters of on"],
    );
    let mut v = good.clone();
    v["model"] = Value::from("ggx(");
    case("spec.json", &v.to_string(), &["'model'"]);
    let mut v = good.clone();
    v["flat_params"][1] = Value::from(3.0);
    case(
        "bounds.json",
        &v.to_string(),
        &["alpha = 3 is outside its bounds"],
    );
    let mut v = good.clone();
    v["flat_params"][0] = Value::Null;
    case(
        "null.json",
        &v.to_string(),
        &["flat_params[0]", "not a number"],
    );
    let mut v = good.clone();
    v["correlation"] = serde_json::json!([[1.0]]);
    case("corr.json", &v.to_string(), &["'correlation'", "3 × 3"]);
    let mut v = good.clone();
    v["flat_std"][2] = Value::from(-1.0);
    case("std.json", &v.to_string(), &["flat_std[2]"]);
    case(
        "sweep.json",
        &format!("[{good}]"),
        &["results.json", "fit --json"],
    );
    case(
        "diag.json",
        r#"{"start_model": "lambert", "final_model": "fa(lambert)", "effects": [], "steps": []}"#,
        &["diagnose"],
    );
    // A per-axis report: eval takes each sample's plane; export needs --plane.
    let per_axis =
        serde_json::json!({"per_axis": [{"phi": 0.0, "fit": good}, {"phi": 90.0, "fit": good}]});
    let f = dir.path().join("per_axis.json");
    std::fs::write(&f, per_axis.to_string()).unwrap();
    let out = bsdfit(&["export", p(&f), "--format", "merl", "--out", p(&out_csv)]);
    assert_clear_error(
        &out,
        &["per_axis.json", "one fit per measurement plane", "--plane"],
    );
    let out = bsdfit(&[
        "export",
        p(&f),
        "--format",
        "merl",
        "--plane",
        "45",
        "--out",
        p(&out_csv),
    ]);
    assert_clear_error(&out, &["--plane 45", "φ = 0°, 90°"]);
    // A geometry of the other kind, and a data file of other wavelengths.
    let out = bsdfit(&["eval", p(&json), "--geometry", "ptb5", "--out", p(&out_csv)]);
    assert_clear_error(&out, &["ggx is a brdf model", "btdf"]);
    let other = dir.path().join("other.csv");
    std::fs::write(
        &other,
        "# kind: brdf\ntheta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty\n10,0,20,180,633,0.1,0.01\n",
    )
    .unwrap();
    let out = bsdfit(&["eval", p(&json), "--at", p(&other), "--out", p(&out_csv)]);
    assert_clear_error(
        &out,
        &["other.csv:3", "633 nm is not a channel of the fit (550 nm)"],
    );
}

// ---------------------------------------------------------------------------------------
// export

#[test]
fn merl_export_reads_back_as_the_model_at_the_cell_centres() {
    let dir = tempfile::tempdir().unwrap();
    let (_, json) = synth_and_fit(
        dir.path(),
        "fa",
        "fa(lambert)",
        "lobe.alpha=0.12,lobe.eta=1.5,lobe.ks=0.6:0.8:1.0,base.rho=0.15:0.3:0.6",
        "specular+offplane",
        "450,550,650",
    );
    let table = dir.path().join("fa.binary");
    let out = bsdfit(&["export", p(&json), "--format", "merl", "--out", p(&table)]);
    assert_ok(&out, "export merl");
    assert!(text(&out.stderr).contains("R, G, B = fit channels 650, 550, 450 nm"));
    let bytes = std::fs::read(&table).unwrap();
    assert_eq!(bytes.len(), merl::FILE_BYTES);
    let opts = ReadOptions {
        assume_uncertainty: Some((0.05, 1e-3)),
        max_samples: Some(60_000),
        ..Default::default()
    };
    let back = merl::parse(&bytes, "fa.binary", &opts).unwrap();
    let fit = saved(&json);
    // The MERL channels R, G, B are read at 650, 550, 450 nm: the fit's channels of the
    // same wavelengths.
    let mut worst = 0.0f64;
    for s in &back.samples {
        let c = fit.channel_of(s.wavelength_nm).unwrap();
        let f = fit.model.eval(&fit.flat, c, s.wi(), s.wo());
        let rel = (s.value - f).abs() / f.abs().max(1e-300);
        worst = worst.max(rel);
    }
    // The table stores f64 (MERL's format is doubles), and the reader's cell centres pass
    // through degrees (~1e-16 rad): the read-back equals the model to 1e-9 relative, far
    // inside float32's 6e-8 that a float MERL loader would keep.
    eprintln!(
        "MERL round trip: largest relative difference {worst:.2e} over {} samples",
        back.len()
    );
    assert!(worst < 1e-9, "largest relative difference {worst:e}");
    assert_eq!(back.len(), 3 * 60_000);

    // Models and formats that do not go together are clear errors.
    let (_, btdf_json) = synth_and_fit(
        dir.path(),
        "bt",
        "btdf(tr)",
        "alpha=0.2,eta=1.5",
        "oblique",
        "633",
    );
    let out = bsdfit(&[
        "export",
        p(&btdf_json),
        "--format",
        "merl",
        "--out",
        p(&table),
    ]);
    assert_clear_error(&out, &["btdf(tr) is a BTDF model", "--format tabulated"]);
    let xml = dir.path().join("fa.xml");
    let out = bsdfit(&["export", p(&json), "--format", "mitsuba", "--out", p(&xml)]);
    assert_clear_error(
        &out,
        &[
            "fa(lambert) has no exact Mitsuba 3 counterpart",
            "lambert (→ diffuse)",
            "ggx (→ roughconductor",
            "--format merl",
        ],
    );
    let out = bsdfit(&[
        "export",
        p(&btdf_json),
        "--format",
        "mitsuba",
        "--out",
        p(&xml),
    ]);
    assert_clear_error(
        &out,
        &["btdf(tr) has no exact Mitsuba 3 counterpart", "tabulated"],
    );
    // Five channels are not RGB without --rgb.
    let (_, five) = synth_and_fit(
        dir.path(),
        "five",
        "lambert",
        "rho=0.5",
        "inplane10",
        "450,500,550,600,650",
    );
    let out = bsdfit(&["export", p(&five), "--format", "merl", "--out", p(&table)]);
    assert_clear_error(&out, &["5 channels", "--rgb"]);
    let out = bsdfit(&[
        "export",
        p(&five),
        "--format",
        "merl",
        "--rgb",
        "600,500,450",
        "--out",
        p(&table),
    ]);
    assert_ok(&out, "export merl --rgb");
    assert!(text(&out.stderr).contains("R, G, B = fit channels 600, 500, 450 nm"));
}

#[test]
fn tabulated_export_is_the_documented_grid_and_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let (_, json) = synth_and_fit(
        dir.path(),
        "on",
        "on",
        "rho=0.3:0.6,sigma=0.5",
        "inplane10",
        "500,600",
    );
    let table = dir.path().join("on-table.csv");
    let out = bsdfit(&[
        "export",
        p(&json),
        "--format",
        "tabulated",
        "--theta-step",
        "10",
        "--theta-max",
        "80",
        "--phi-step",
        "30",
        "--out",
        p(&table),
    ]);
    assert_ok(&out, "export tabulated");
    let back = Dataset::read(&table, &ReadOptions::default()).unwrap();
    // θ = 0…80° by 10° (9 values), φo = 0…330° by 30° (12), one row at θo = 0; 2 channels.
    assert_eq!(back.len(), 9 * (1 + 8 * 12) * 2);
    let fit = saved(&json);
    for s in &back.samples {
        let c = fit.channel_of(s.wavelength_nm).unwrap();
        let f = fit.model.eval(&fit.flat, c, s.wi(), s.wo());
        assert!((s.value - f).abs() <= 1e-12 * f, "{} vs {f}", s.value);
        assert!(s.uncertainty > 0.0 && s.uncertainty < 0.1 * f);
    }
    let out = bsdfit(&[
        "export",
        p(&json),
        "--format",
        "tabulated",
        "--theta-max",
        "90",
        "--out",
        p(&table),
    ]);
    assert_clear_error(&out, &["--theta-max 90"]);
    let out = bsdfit(&[
        "export",
        p(&json),
        "--format",
        "merl",
        "--theta-step",
        "2",
        "--out",
        p(&table),
    ]);
    assert_clear_error(&out, &["--theta-step applies to --format tabulated only"]);
}

#[test]
#[ignore = "needs python3 with mitsuba (pip install mitsuba); scripts/test.sh runs it with --ignored"]
fn mitsuba_export_evaluates_as_bsdfit_in_mitsuba() {
    let python = std::env::var("BSDFIT_PYTHON").unwrap_or_else(|_| "python3".into());
    let importable = Command::new(&python)
        .args(["-c", "import mitsuba"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !importable {
        common::missing(&format!(
            "{python} cannot import mitsuba (pip install mitsuba, or set BSDFIT_PYTHON)"
        ));
        return;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/check-mitsuba-export.py");
    let out = Command::new(&python)
        .arg(&script)
        .args(["--bsdfit", common::bin()])
        .output()
        .expect("run the check script");
    println!("{}", text(&out.stdout));
    assert!(
        out.status.success(),
        "check-mitsuba-export.py failed:\n{}\n{}",
        text(&out.stdout),
        text(&out.stderr)
    );
}

// ---------------------------------------------------------------------------------------
// ALTA text against v1 CSV

/// (θi, θo, φo) in degrees of a hemisphere of directions with φi = 0.
fn hemisphere_rows() -> Vec<(f64, f64, f64)> {
    let mut v = Vec::new();
    for ti in [0.0, 20.0, 40.0, 60.0] {
        for to in [10.0, 25.0, 40.0, 55.0, 70.0] {
            for po in [0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0] {
                v.push((ti, to, po));
            }
        }
    }
    v
}

#[test]
fn alta_text_and_v1_csv_of_the_same_data_fit_to_the_same_parameters() {
    let (rel, abs) = (0.04, 2e-3);
    let model = Model::parse("on", 1).unwrap();
    let truth = model.params_from_assignments("rho=0.55,sigma=0.6").unwrap();
    let mut rng = common::rng(17);
    let n = Normal::new(0.0, 1.0).unwrap();
    let dir = tempfile::tempdir().unwrap();
    for cosine in [false, true] {
        let (mut alta, mut v1) = (String::new(), String::new());
        alta += "#SAMPLE \"synthetic on\"\n#DIM 3 1\n#PARAM_IN ISOTROPIC_TL_TV_PROJ_DPHI\n";
        alta += if cosine {
            "#PARAM_OUT INV_STERADIAN_COSINE_FACTOR\n"
        } else {
            "#PARAM_OUT INV_STERADIAN\n"
        };
        v1 += "# bsdfit dataset v1\n# material: synthetic on\n# kind: brdf\n";
        v1 += "theta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty\n";
        for (ti, to, po) in hemisphere_rows() {
            let (tir, tor, por) = (ti.to_radians(), to.to_radians(), po.to_radians());
            let f = model.eval(&truth, 0, common::dir(tir, 0.0), common::dir(tor, por));
            let noisy: f64 = f * (1.0 + rel * n.sample(&mut rng));
            // ALTA: θl and the view direction projected, x = θv cos Δφ, y = θv sin Δφ.
            let (x, y) = (tor * por.cos(), tor * por.sin());
            let written = if cosine { noisy * tor.cos() } else { noisy };
            alta += &format!("{tir:e} {x:e} {y:e} {written:e}\n");
            // v1: the same values with the uncertainties --assume-uncertainty gives them
            // (docs: u = sqrt((REL·|y|)² + ABS²) of the value as written, and for cosine-
            // weighted values both divided by cos θo).
            let u_written = (rel * written).hypot(abs);
            let (value, u) = if cosine {
                (written / tor.cos(), u_written / tor.cos())
            } else {
                (written, u_written)
            };
            v1 += &format!("{ti},0,{to},{po},550,{value:e},{u:e}\n");
        }
        let alta_path = dir.path().join(format!("on-{cosine}.dat"));
        let v1_path = dir.path().join(format!("on-{cosine}.csv"));
        std::fs::write(&alta_path, alta).unwrap();
        std::fs::write(&v1_path, v1).unwrap();
        let a = readers::load(
            &alta_path,
            &ReadOptions {
                assume_uncertainty: Some((rel, abs)),
                ..Default::default()
            },
        )
        .unwrap();
        let b = readers::load(&v1_path, &ReadOptions::default()).unwrap();
        assert_eq!(a.len(), b.len());
        assert_eq!(a.channels, b.channels);
        for (s, t) in a.samples.iter().zip(&b.samples) {
            assert!((s.wi() - t.wi()).length() < 1e-12 && (s.wo() - t.wo()).length() < 1e-12);
            assert!((s.value - t.value).abs() <= 1e-13 * t.value.abs());
            assert!((s.uncertainty - t.uncertainty).abs() <= 1e-13 * t.uncertainty);
        }
        let run = |d: &Dataset| -> FitReport {
            let m = Model::for_data("on", d).unwrap();
            let opts = FitOptions {
                optimizer: Optimizer::Lm,
                restarts: 6,
                seed: 2,
                ..Default::default()
            };
            fit(
                &m,
                d,
                Loss::new(Metric::Chi2, Weights::Uniform),
                &CpuBackend::new(),
                &opts,
                &mut |_| {},
            )
            .unwrap()
        };
        let (fa, fb) = (run(&a), run(&b));
        eprintln!(
            "ALTA ({}) vs v1: {}",
            if cosine {
                "INV_STERADIAN_COSINE_FACTOR"
            } else {
                "INV_STERADIAN"
            },
            (0..fa.flat_params.len())
                .map(|j| format!(
                    "{} {} vs {} (Δ/σ = {:.1e})",
                    fa.flat_names[j],
                    fa.flat_params[j],
                    fb.flat_params[j],
                    (fa.flat_params[j] - fb.flat_params[j]).abs()
                        / fb.flat_std[j].unwrap_or(f64::NAN)
                ))
                .collect::<Vec<_>>()
                .join(", ")
        );
        for j in 0..fa.flat_params.len() {
            let s = fb.flat_std[j].unwrap();
            assert!(
                (fa.flat_params[j] - fb.flat_params[j]).abs() <= 1e-4 * s,
                "cosine {cosine}: {} ALTA {} vs v1 {} (std {s})",
                fa.flat_names[j],
                fa.flat_params[j],
                fb.flat_params[j]
            );
            let sa = fa.flat_std[j].unwrap();
            assert!((sa - s).abs() <= 1e-6 * s, "std {sa} vs {s}");
        }
        assert!(
            (fa.best.chi2_red - fb.best.chi2_red).abs() <= 1e-8 * fb.best.chi2_red,
            "χ²_red {} vs {}",
            fa.best.chi2_red,
            fb.best.chi2_red
        );
        // The ALTA fit says its uncertainties were assumed; the v1 one gave its own.
        assert!(fa.warnings.iter().any(|w| w.contains("assumed")));
        assert!(!fb.warnings.iter().any(|w| w.contains("assumed")));
        // …and the truth is recovered within the stated uncertainties.
        for (j, t) in truth.iter().enumerate() {
            let s = fb.flat_std[j].unwrap();
            assert!(
                (fb.flat_params[j] - t).abs() < 4.0 * s,
                "{} {} vs {t} ± {s}",
                fb.flat_names[j],
                fb.flat_params[j]
            );
        }
    }
}

// ---------------------------------------------------------------------------------------
// Two-plane BTDF with the normal point in both scans

#[test]
fn two_plane_btdf_recovers_both_widths_with_the_normal_point_in_each_scan() {
    // An anisotropic diffuser measured on φt = 0° and φt = 90°, θt = −20…20° in 1° steps:
    // both scans pass through the normal, so the θt = 0 row is in each, written with its
    // scan's azimuth, and the dataset gives each copy to its own plane.
    // Normal incidence, as the PTB measurements of anisotropic samples.
    let mut rows = Vec::new();
    for phi in [0.0, 90.0] {
        for k in -20..=20 {
            rows.push([0.0, 0.0, k as f64, phi]);
        }
    }
    let spec = "btdf(tr)+scale+peraxis";
    let (model, truth, data) = common::synth_rows(
        spec,
        "alpha=0.12:0.3,eta=1.5,scale=0.8",
        &rows,
        &[633.0],
        (0.01, 1e-4),
        23,
    );
    assert_eq!(model.axes, vec![0.0, 90.0]);
    let normal: Vec<usize> = data
        .samples
        .iter()
        .filter(|s| s.theta_o == 0.0)
        .map(|s| s.axis)
        .collect();
    assert_eq!(normal, vec![0, 1], "one normal sample per plane");
    let opts = FitOptions {
        optimizer: Optimizer::Lm,
        restarts: 8,
        seed: 5,
        ..Default::default()
    };
    let r = fit(
        &model,
        &data,
        Loss::new(Metric::Chi2, Weights::Uniform),
        &CpuBackend::new(),
        &opts,
        &mut |_| {},
    )
    .unwrap();
    assert!(
        r.best.chi2_red > 0.6 && r.best.chi2_red < 1.6,
        "χ²_red {}",
        r.best.chi2_red
    );
    let get = |name: &str| {
        let i = r.flat_names.iter().position(|n| n == name).unwrap();
        (r.flat_params[i], r.flat_std[i].expect(name), truth[i])
    };
    let (a0, s0, t0) = get("alpha@phi0");
    let (a90, s90, t90) = get("alpha@phi90");
    eprintln!(
        "two planes: χ²_red {:.3}; {}",
        r.best.chi2_red,
        r.flat_names
            .iter()
            .zip(&r.flat_params)
            .zip(&r.flat_std)
            .zip(&truth)
            .map(|(((n, v), s), t)| format!(
                "{n} = {v:.5} ± {:.5} (truth {t})",
                s.unwrap_or(f64::NAN)
            ))
            .collect::<Vec<_>>()
            .join(", ")
    );
    for (name, v, s, t) in [("alpha@phi0", a0, s0, t0), ("alpha@phi90", a90, s90, t90)] {
        assert!((v - t).abs() < 4.0 * s, "{name} = {v} ± {s}, truth {t}");
        // …and the data say something: the standard uncertainty is a small part of it.
        assert!(s < 0.1 * t, "{name}: std {s} for {t}");
    }
    // The two widths are told apart.
    assert!(
        (a90 - a0) > 4.0 * s0.hypot(s90),
        "{a0} ± {s0} vs {a90} ± {s90}"
    );
    for name in ["eta", "scale"] {
        let (v, s, t) = get(name);
        assert!((v - t).abs() < 4.0 * s, "{name} = {v} ± {s}, truth {t}");
    }
}

// ---------------------------------------------------------------------------------------
// rgl

/// The fields of a tensor file: name → (dtype, shape, bytes), read by the published layout.
fn tensor_fields(bytes: &[u8]) -> std::collections::BTreeMap<String, (u8, Vec<u64>, Vec<u8>)> {
    assert_eq!(&bytes[..12], b"tensor_file\0");
    assert_eq!(&bytes[12..14], &[1, 0]);
    let u16_at = |i: usize| u16::from_le_bytes([bytes[i], bytes[i + 1]]) as usize;
    let u64_at = |i: usize| u64::from_le_bytes(bytes[i..i + 8].try_into().unwrap());
    let n = u32::from_le_bytes(bytes[14..18].try_into().unwrap());
    let mut at = 18;
    let mut out = std::collections::BTreeMap::new();
    for _ in 0..n {
        let len = u16_at(at);
        let name = String::from_utf8(bytes[at + 2..at + 2 + len].to_vec()).unwrap();
        at += 2 + len;
        let ndim = u16_at(at);
        let dtype = bytes[at + 2];
        let offset = u64_at(at + 3) as usize;
        let shape: Vec<u64> = (0..ndim).map(|k| u64_at(at + 11 + 8 * k)).collect();
        at += 11 + 8 * ndim;
        let count: u64 = shape.iter().product();
        let size = count as usize * if dtype == 10 { 4 } else { 1 };
        assert_eq!(offset % 8, 0, "{name} is not aligned");
        out.insert(name, (dtype, shape, bytes[offset..offset + size].to_vec()));
    }
    out
}

#[test]
fn rgl_export_tabulates_f_cos_on_the_half_vector_grid_and_refuses_what_it_cannot_hold() {
    let dir = tempfile::tempdir().unwrap();
    let (_, json) = synth_and_fit(
        dir.path(),
        "lam",
        "lambert",
        "rho=0.2:0.5:0.8",
        "hemi",
        "450,550,650",
    );
    let out = dir.path().join("lam.bsdf");
    assert_ok(
        &bsdfit(&["export", p(&json), "--format", "rgl", "--out", p(&out)]),
        "export rgl",
    );
    let fields = tensor_fields(&std::fs::read(&out).unwrap());
    for name in [
        "description",
        "jacobian",
        "theta_i",
        "phi_i",
        "ndf",
        "sigma",
        "vndf",
        "luminance",
        "rgb",
    ] {
        assert!(fields.contains_key(name), "{name} missing");
    }
    let f32s = |b: &[u8]| -> Vec<f32> {
        b.chunks(4)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
            .collect()
    };
    let (_, shape, rgb) = &fields["rgb"];
    let theta_i = f32s(&fields["theta_i"].2);
    let nt = theta_i.len();
    let nn = bsdfit::workflows::rgl::THETA_M_NODES;
    assert_eq!(shape, &vec![1, nt as u64, 3, nn as u64, nn as u64]);
    assert_eq!(fields["jacobian"].2, vec![0]);
    assert_eq!(
        fields["luminance"].1,
        vec![1, nt as u64, nn as u64, nn as u64]
    );
    let rgb = f32s(rgb);
    // Lambert: every cell holds ρ/π · cos θo of the direction its half vector gives, in
    // each channel: R, G, B are the longest, middle and shortest wavelength (ρ = 0.8,
    // 0.5, 0.2 in the data). The cell (x, y) of an n × n table sits at u = (x, y)/(n − 1),
    // θm = u_x² · π/2 and φm = (2u_y − 1) · π, by the format's definition (written here,
    // not taken from the library).
    let fit = saved(&json);
    let rho_rgb = [fit.flat[2], fit.flat[1], fit.flat[0]];
    let mut checked = 0;
    for (k, &ti) in theta_i.iter().enumerate().step_by(17) {
        let wi = glam::DVec3::new((ti as f64).sin(), 0.0, (ti as f64).cos());
        for (y, x) in [(64, 20), (10, 100), (100, 60), (127, 127), (0, 0), (1, 1)] {
            let (ux, uy) = (x as f64 / (nn - 1) as f64, y as f64 / (nn - 1) as f64);
            let (tm, pm) = (
                ux * ux * std::f64::consts::FRAC_PI_2,
                (2.0 * uy - 1.0) * std::f64::consts::PI,
            );
            let m = glam::DVec3::new(tm.sin() * pm.cos(), tm.sin() * pm.sin(), tm.cos());
            let wo = 2.0 * wi.dot(m) * m - wi;
            for (c, rho) in rho_rgb.iter().enumerate() {
                let want = if wo.z > 1e-9 && wi.dot(m) > 0.0 {
                    rho / std::f64::consts::PI * wo.z
                } else {
                    0.0
                };
                let got = rgb[((k * 3 + c) * nn + y) * nn + x] as f64;
                assert!(
                    (got - want).abs() <= 1e-6 * want.max(1e-3),
                    "θi node {k}, channel {c}, cell ({x}, {y}): {got} vs {want}"
                );
                checked += 1;
            }
        }
    }
    assert!(checked >= 60);

    // BTDF and per-plane fits: a clear error that names the alternative.
    let (_, btdf) = synth_and_fit(
        dir.path(),
        "tr",
        "btdf(tr)",
        "alpha=0.3,eta=1.5",
        "ptb5",
        "633",
    );
    let o = bsdfit(&[
        "export",
        p(&btdf),
        "--format",
        "rgl",
        "--out",
        p(&dir.path().join("tr.bsdf")),
    ]);
    assert_clear_error(&o, &["BTDF", "reflection only", "--format tabulated"]);
    assert!(!dir.path().join("tr.bsdf").exists());
    let o = bsdfit(&[
        "export",
        p(&json),
        "--format",
        "rgl",
        "--spectral",
        "--rgb",
        "650,550,450",
        "--out",
        p(&dir.path().join("x.bsdf")),
    ]);
    assert_clear_error(&o, &["--rgb", "--spectral"]);
}

#[test]
fn rgl_files_read_back_as_data_and_refuse_what_they_cannot_be() {
    let dir = tempfile::tempdir().unwrap();
    let (_, json) = synth_and_fit(
        dir.path(),
        "on",
        "on",
        "rho=0.2:0.5:0.8,sigma=0.5",
        "hemi",
        "450,550,650",
    );
    let out = dir.path().join("on.bsdf");
    assert_ok(
        &bsdfit(&["export", p(&json), "--format", "rgl", "--out", p(&out)]),
        "export rgl",
    );
    // Without an assumed uncertainty the file is refused, naming the option.
    let o = bsdfit(&["convert", p(&out), "--out", p(&dir.path().join("x.csv"))]);
    assert_clear_error(&o, &["RGL .bsdf", "--assume-uncertainty"]);
    // Sampled at a geometry: the fitted model's values, to the table's interpolation.
    let opts = ReadOptions {
        assume_uncertainty: Some((0.01, 1e-5)),
        sample_geometry: Some("hemi+specular".into()),
        ..Default::default()
    };
    let data = readers::load(&out, &opts).unwrap();
    assert_eq!(data.channels, vec![450.0, 550.0, 650.0]);
    assert!(data
        .notices
        .iter()
        .any(|n| n.contains("RGL measured material")));
    let fit = saved(&json);
    let prop = Propagator::new(&fit);
    let mut rel: Vec<f64> = data
        .samples
        .iter()
        .map(|s| {
            let want = prop.eval(s.channel, s.wi(), s.wo()).value;
            (s.value - want).abs() / want
        })
        .collect();
    rel.sort_by(f64::total_cmp);
    let (median, worst) = (rel[rel.len() / 2], rel[rel.len() - 1]);
    // Bilinear in the table, linear between 1° incidence nodes: measured median 2e-4, the
    // largest 1.4e-2 (grazing θo, where f·cos θo varies fastest across a cell).
    assert!(
        median < 1e-3 && worst < 3e-2,
        "median {median}, largest {worst}"
    );
    // Damaged files: clear errors, never a panic.
    let bytes = std::fs::read(&out).unwrap();
    for (name, damaged) in [
        ("truncated", bytes[..bytes.len() / 2].to_vec()),
        ("header only", bytes[..40].to_vec()),
        ("wrong version", {
            let mut b = bytes.clone();
            b[12] = 7;
            b
        }),
    ] {
        let path = dir.path().join(format!("{name}.bsdf"));
        std::fs::write(&path, damaged).unwrap();
        let e = readers::load(&path, &opts).unwrap_err().to_string();
        assert!(e.contains(&*path.display().to_string()), "{name}: {e}");
    }
}
