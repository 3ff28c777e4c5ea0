//! `bsdfit export --format zemax|astm`, checked by an independent reader written from the
//! formats' definitions in Python (tests/optical/read_formats.py, standard library only,
//! its own cell geometry by spherical trigonometry), by an independent TIS integral here,
//! and by round trips: a measured-style Zemax BTDF read, fitted, exported and read back to
//! the same table; exports read back and refitted to the same parameters.

mod common;

use bsdfit::bsdf::Model;
use bsdfit::inference::saved::{FitFile, SavedFit};
use common::cli::{assert_clear_error, assert_ok, bsdfit, p, text};
use common::optical::{oracle, steps, zemax_text, ZemaxSpec};
use glam::DVec3;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The independent reader's view of a file, or `None` (and a skip, a failure under CI)
/// without python3.
fn python_read(kind: &str, file: &Path) -> Option<Value> {
    let python = std::env::var("BSDFIT_PYTHON").unwrap_or_else(|_| "python3".into());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/optical/read_formats.py");
    let Ok(out) = Command::new(&python)
        .arg(&script)
        .arg(kind)
        .arg(file)
        .output()
    else {
        common::missing(&format!(
            "{python} (the independent reader of the written files)"
        ));
        return None;
    };
    assert!(
        out.status.success(),
        "read_formats.py failed: {}",
        text(&out.stderr)
    );
    Some(serde_json::from_slice(&out.stdout).expect("JSON"))
}

fn f64s(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

/// The directions of a geometry (degrees; θo from −n when `transmitted`).
fn dirs(g: &[f64], transmitted: bool) -> (DVec3, DVec3) {
    let d = |t: f64, p: f64| common::dir(t.to_radians(), p.to_radians());
    let mut wo = d(g[2], g[3]);
    if transmitted {
        wo.z = -wo.z;
    }
    (d(g[0], g[1]), wo)
}

/// A fit report `bsdfit fit --json` could have written, for `spec` with `params` (by
/// name) on `channels` and `axes`.
fn fit_json(spec: &str, channels: &[f64], axes: &[f64], params: &[(&str, f64)], std: f64) -> Value {
    let m = Model::parse_for(spec, channels.len(), axes).unwrap();
    let names = m.flat_names();
    for (k, _) in params {
        assert!(
            names.iter().any(|n| n == k),
            "{spec} has no parameter {k} ({names:?})"
        );
    }
    let flat: Vec<f64> = names
        .iter()
        .zip(m.defaults())
        .map(|(n, d)| params.iter().find(|(k, _)| k == n).map_or(d, |(_, v)| *v))
        .collect();
    let p = names.len();
    json!({
        "model": spec, "channels": channels, "axes": axes, "material": "test material",
        "flat_names": names, "flat_params": flat, "flat_std": vec![std; p],
        "correlation": (0..p).map(|a| (0..p).map(|b| if a == b { 1.0 } else { 0.0 }).collect::<Vec<_>>()).collect::<Vec<_>>(),
        "warnings": [],
    })
}

fn write_json(dir: &Path, name: &str, v: &Value) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, serde_json::to_string(v).unwrap()).unwrap();
    path
}

fn saved(json: &Path) -> SavedFit {
    FitFile::read(json).unwrap().select(None, "fit").unwrap()
}

fn value_of(fit: &SavedFit, name: &str) -> (f64, f64) {
    let i = fit
        .model
        .flat_names()
        .iter()
        .position(|n| n == name)
        .unwrap();
    (fit.flat[i], fit.std[i].unwrap_or(f64::NAN))
}

/// TIS by brute force, independently of the writer's rule: Gauss–Legendre in cos θ and
/// the midpoint rule in φ over the whole hemisphere.
fn brute_tis(fit: &SavedFit, aoi: f64, phi_i: f64, transmitted: bool) -> f64 {
    let view = fit.model.scalars(&fit.flat, 0);
    let wi = common::dir(aoi.to_radians(), phi_i.to_radians());
    let gl = bsdfit::math::special::gauss_legendre(160, 0.0, 1.0);
    let n_phi = 480;
    let mut sum = 0.0;
    for &(mu, w) in &gl {
        for k in 0..n_phi {
            let phi = (k as f64 + 0.5) * 2.0 * std::f64::consts::PI / n_phi as f64;
            let mut wo = common::dir_mu(mu, phi);
            if transmitted {
                wo.z = -wo.z;
            }
            sum += w * mu * fit.model.root.eval(&view, wi, wo);
        }
    }
    sum * 2.0 * std::f64::consts::PI / n_phi as f64
}

// ---------------------------------------------------------------------------------------

const TRUTH: [(&str, f64); 3] = [("alpha", 0.3), ("eta", 1.5), ("scale", 0.8)];

/// A measured-style plane-symmetric BTDF as a scatterometer writes it: 13 incidences,
/// 19 azimuths, 11 radial angles, 1% noise, four significant digits, zeros beyond the
/// horizon.
fn measured_btdf(dir: &Path) -> (PathBuf, ZemaxSpec<'static>) {
    let z = ZemaxSpec {
        symmetry: "PlaneSymmetrical",
        spectral: "Monochrome",
        kind: "BTDF",
        rotations: vec![0.0],
        aoi: steps(0.0, 60.0, 5.0),
        azimuths: steps(0.0, 180.0, 10.0),
        radials: vec![
            0.0, 5.0, 10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0, 80.0,
        ],
        eol: "\r\n",
    };
    let truth = fit_json("btdf(tr)+scale", &[633.0], &[0.0], &TRUTH, 0.0);
    let fit = SavedFit::from_value(&truth, "truth").unwrap();
    let view = fit.model.scalars(&fit.flat, 0);
    let noise = std::cell::RefCell::new((
        rand_chacha::ChaCha8Rng::seed_from_u64(11),
        Normal::new(0.0, 0.01).unwrap(),
    ));
    let f = |_: usize, rot: f64, aoi: f64, a: f64, r: f64| {
        let Some(g) = oracle(rot, aoi, a, r) else {
            return 0.0;
        };
        let (wi, wo) = dirs(&g, true);
        let v = fit.model.root.eval(&view, wi, wo);
        let (rng, n) = &mut *noise.borrow_mut();
        let noisy = v * (1.0 + n.sample(rng));
        format!("{noisy:.3E}").parse().unwrap()
    };
    let path = dir.join("diffuser.bsdf");
    std::fs::write(&path, zemax_text(&z, &f, 0.75)).unwrap();
    (path, z)
}

#[test]
fn a_measured_style_zemax_btdf_is_fitted_exported_and_read_back_to_the_same_table() {
    let dir = tempfile::tempdir().unwrap();
    let (data, z) = measured_btdf(dir.path());
    let json = dir.path().join("fit.json");
    let out = bsdfit(&[
        "fit",
        p(&data),
        "--model",
        "btdf(tr)+scale",
        "--backend",
        "cpu",
        "--restarts",
        "4",
        "--assume-uncertainty",
        "0.01,1e-5",
        "--json",
        p(&json),
    ]);
    assert_ok(&out, "fit");
    let fit = saved(&json);
    for (name, truth) in TRUTH {
        let (v, s) = value_of(&fit, name);
        eprintln!("{name} = {v} ± {s}, truth {truth}");
        // The σ that sets both tolerances (here and in the refit below) is bounded by the
        // truth, so that an inflated covariance cannot pass: at most 0.5 % of it
        // (measured 0.006–0.06 % with 1 % noise on ~2,000 cells).
        assert!(
            (v - truth).abs() < 4.0 * s && s <= 0.005 * truth,
            "{name} = {v} ± {s}, truth {truth}"
        );
    }
    // Exported at the grid of the fit's data (the default for a Zemax data file).
    let exported = dir.path().join("export.bsdf");
    let out = bsdfit(&[
        "export",
        p(&json),
        "--format",
        "zemax",
        "--out",
        p(&exported),
    ]);
    assert_ok(&out, "export");
    assert!(
        text(&out.stderr).contains("the grid of the fit's data"),
        "{}",
        text(&out.stderr)
    );
    let Some(t) = python_read("zemax", &exported) else {
        return;
    };
    assert_eq!(t["symmetry"], "PlaneSymmetrical");
    assert_eq!(t["kind"], "BTDF");
    assert_eq!(f64s(&t["aoi"]), z.aoi);
    assert_eq!(f64s(&t["azimuths"]), z.azimuths);
    assert_eq!(f64s(&t["radials"]), z.radials);
    let tables = t["tables"].as_array().unwrap();
    assert_eq!(tables.len(), 13);
    let view = fit.model.scalars(&fit.flat, 0);
    let mut peak = 0f64;
    let mut compared = 0;
    let model_at = |c: &Value| {
        let (wi, wo) = dirs(&f64s(&c["geometry"]), true);
        fit.model.root.eval(&view, wi, wo)
    };
    for tb in tables {
        for c in tb["cells"].as_array().unwrap() {
            if c["above_horizon"].as_bool().unwrap() {
                peak = peak.max(model_at(c));
            }
        }
    }
    for tb in tables {
        for c in tb["cells"].as_array().unwrap() {
            let got = c["value"].as_f64().unwrap();
            if !c["above_horizon"].as_bool().unwrap() {
                assert_eq!(got, 0.0, "a cell beyond the horizon: {c}");
                continue;
            }
            let want = model_at(c);
            if want > 1e-6 * peak {
                assert!((got - want).abs() <= 1e-6 * want, "{got} vs {want} at {c}");
                compared += 1;
            }
        }
        // The TIS line is the model's integral over the hemisphere (to 1e-3: the brute
        // force rule itself errs by ~2e-4 at the BTDF's cut-off, where f jumps to 0).
        let aoi = tb["aoi"].as_f64().unwrap();
        let want = brute_tis(&fit, aoi, 90.0, true);
        let got = tb["tis"].as_f64().unwrap();
        assert!(
            (got - want).abs() < 1e-3 * want,
            "TIS at {aoi}°: {got} vs {want}"
        );
    }
    assert!(compared > 1500, "{compared} cells compared");
    // Read back by bsdfit and refitted: the same parameters, within 4σ of the first fit.
    let json2 = dir.path().join("refit.json");
    let out = bsdfit(&[
        "fit",
        p(&exported),
        "--model",
        "btdf(tr)+scale",
        "--backend",
        "cpu",
        "--restarts",
        "4",
        "--assume-uncertainty",
        "0.01,1e-5",
        "--json",
        p(&json2),
    ]);
    assert_ok(&out, "refit");
    let refit = saved(&json2);
    for (name, _) in TRUTH {
        let ((a, sa), (b, _)) = (value_of(&fit, name), value_of(&refit, name));
        assert!((a - b).abs() < 4.0 * sa, "{name}: {a} ± {sa} then {b}");
    }
}

#[test]
fn the_tis_of_a_written_lambertian_btdf_is_its_transmittance() {
    let dir = tempfile::tempdir().unwrap();
    let kd = 0.6;
    let v = fit_json(
        "btdf(tr)+scale+diffuse",
        &[550.0],
        &[0.0],
        &[("kd", kd), ("scale", 0.0)],
        0.01,
    );
    let json = write_json(dir.path(), "lambert.json", &v);
    let out_file = dir.path().join("lambert.bsdf");
    let out = bsdfit(&[
        "export",
        p(&json),
        "--format",
        "zemax",
        "--out",
        p(&out_file),
        "--geometry",
        "aoi=0:10:80,85,89;azimuth=0:30:180;radial=0:10:180",
    ]);
    assert_ok(&out, "export");
    let Some(t) = python_read("zemax", &out_file) else {
        return;
    };
    assert_eq!(t["kind"], "BTDF");
    for tb in t["tables"].as_array().unwrap() {
        let tis = tb["tis"].as_f64().unwrap();
        assert!((tis - kd).abs() < 1e-3, "TIS {tis} at AOI {}", tb["aoi"]);
        for c in tb["cells"].as_array().unwrap() {
            let want = if c["above_horizon"].as_bool().unwrap() {
                kd / std::f64::consts::PI
            } else {
                0.0
            };
            assert!((c["value"].as_f64().unwrap() - want).abs() < 1e-9, "{c}");
        }
    }
}

#[test]
fn an_astm_export_holds_the_model_and_its_propagated_uncertainty_and_refits() {
    let dir = tempfile::tempdir().unwrap();
    let rho = [("rho[0]", 0.2), ("rho[1]", 0.5), ("rho[2]", 0.8)];
    let v = fit_json("lambert", &[450.0, 550.0, 650.0], &[0.0], &rho, 0.01);
    let json = write_json(dir.path(), "lambert.json", &v);
    let astm = dir.path().join("lambert.astm");
    let out = bsdfit(&["export", p(&json), "--format", "astm", "--out", p(&astm)]);
    assert_ok(&out, "export");
    let Some(t) = python_read("astm", &astm) else {
        return;
    };
    let rows = t["rows"].as_array().unwrap();
    assert_eq!(
        t["keys"]["NUM_POINTS"]
            .as_str()
            .unwrap()
            .parse::<usize>()
            .unwrap(),
        rows.len()
    );
    assert_eq!(
        t["vars"],
        json!([
            "theta_i", "phi_i", "theta_s", "phi_s", "450nm", "550nm", "650nm", "u_450nm",
            "u_550nm", "u_650nm"
        ])
    );
    let pi = std::f64::consts::PI;
    for r in rows {
        assert!(!r["transmitted"].as_bool().unwrap());
        for (k, w) in ["450nm", "550nm", "650nm"].iter().enumerate() {
            let f = r["values"][w].as_f64().unwrap();
            let u = r["values"][format!("u_{w}")].as_f64().unwrap();
            // f = ρ/π, and its standard uncertainty u_ρ/π exactly.
            assert!(
                (f - rho[k].1 / pi).abs() < 1e-9 && (u - 0.01 / pi).abs() < 1e-6,
                "{r}"
            );
        }
    }
    // Read back (its own uncertainties: no assumption needed) and refitted.
    let json2 = dir.path().join("refit.json");
    let out = bsdfit(&[
        "fit",
        p(&astm),
        "--model",
        "lambert",
        "--backend",
        "cpu",
        "--restarts",
        "2",
        "--json",
        p(&json2),
    ]);
    assert_ok(&out, "refit");
    let refit = saved(&json2);
    for (name, want) in rho {
        let (got, s) = value_of(&refit, name);
        assert!(
            (got - want).abs() < 4.0 * s.max(1e-12) + 1e-9,
            "{name} = {got} ± {s}, exported {want}"
        );
    }
}

#[test]
fn an_astm_btdf_export_writes_transmitted_directions_beyond_90_degrees() {
    let dir = tempfile::tempdir().unwrap();
    let v = fit_json("btdf(tr)+scale", &[633.0], &[0.0], &TRUTH, 0.01);
    let json = write_json(dir.path(), "btdf.json", &v);
    let astm = dir.path().join("btdf.astm");
    assert_ok(
        &bsdfit(&[
            "export",
            p(&json),
            "--format",
            "astm",
            "--geometry",
            "oblique",
            "--out",
            p(&astm),
        ]),
        "export",
    );
    let Some(t) = python_read("astm", &astm) else {
        return;
    };
    let fit = saved(&json);
    let view = fit.model.scalars(&fit.flat, 0);
    for r in t["rows"].as_array().unwrap() {
        assert!(r["transmitted"].as_bool().unwrap(), "{r}");
        let (wi, wo) = dirs(&f64s(&r["geometry"]), true);
        let want = fit.model.root.eval(&view, wi, wo);
        let got = r["values"]["633nm"].as_f64().unwrap();
        assert!(
            (got - want).abs() <= 1e-8 * want.abs() + 1e-300,
            "{got} vs {want}: {r}"
        );
    }
}

#[test]
fn a_per_plane_fit_is_an_asymmetrical_table_with_each_plane_its_own_model() {
    let dir = tempfile::tempdir().unwrap();
    let spec = "btdf(tr)+scale+peraxis";
    let v = fit_json(
        spec,
        &[633.0],
        &[0.0, 90.0],
        &[
            ("alpha@phi0", 0.1),
            ("alpha@phi90", 0.4),
            ("scale", 0.8),
            ("eta", 1.5),
        ],
        0.01,
    );
    let fit = SavedFit::from_value(&v, "x").unwrap();
    let json = write_json(dir.path(), "pp.json", &v);
    let out_file = dir.path().join("pp.bsdf");
    let out = bsdfit(&[
        "export",
        p(&json),
        "--format",
        "zemax",
        "--out",
        p(&out_file),
        "--geometry",
        "aoi=0,30;azimuth=0:15:345;radial=0:5:60;symmetry=asymmetrical",
    ]);
    assert_ok(&out, "export");
    let Some(t) = python_read("zemax", &out_file) else {
        return;
    };
    assert_eq!(t["symmetry"], "Asymmetrical");
    let eval_plane = |k: usize, g: &[f64]| {
        let view = fit.model.scalars(&fit.flat, k);
        let (wi, wo) = dirs(g, true);
        fit.model.root.eval(&view, wi, wo)
    };
    let mut on_planes = 0;
    for tb in t["tables"].as_array().unwrap() {
        for c in tb["cells"].as_array().unwrap() {
            let g = f64s(&c["geometry"]);
            let got = c["value"].as_f64().unwrap();
            if !c["above_horizon"].as_bool().unwrap() || g[2] < 1e-6 {
                continue;
            }
            let (a, b) = (eval_plane(0, &g), eval_plane(1, &g));
            let m = g[3].rem_euclid(180.0);
            if m.min(180.0 - m) < 1e-6 {
                assert!(
                    (got - a).abs() <= 1e-8 * a.abs(),
                    "plane 0 at {g:?}: {got} vs {a}"
                );
                on_planes += 1;
            } else if (m - 90.0).abs() < 1e-6 {
                assert!(
                    (got - b).abs() <= 1e-8 * b.abs(),
                    "plane 90 at {g:?}: {got} vs {b}"
                );
                on_planes += 1;
            } else {
                assert!(
                    got >= a.min(b) * (1.0 - 1e-8) && got <= a.max(b) * (1.0 + 1e-8),
                    "between planes at {g:?}: {got} not in [{a}, {b}]"
                );
            }
        }
    }
    assert!(on_planes > 20, "{on_planes}");
    // On a plane-symmetric file's grid, the azimuths are mirrored to the whole circle.
    let half = ZemaxSpec {
        symmetry: "PlaneSymmetrical",
        spectral: "Monochrome",
        kind: "BTDF",
        rotations: vec![0.0],
        aoi: vec![0.0, 20.0],
        azimuths: vec![0.0, 60.0, 120.0, 180.0],
        radials: vec![0.0, 10.0, 30.0],
        eol: "\n",
    };
    let half_file = dir.path().join("half.bsdf");
    std::fs::write(&half_file, zemax_text(&half, &|_, _, _, _, _| 1.0, 0.5)).unwrap();
    let out = bsdfit(&[
        "export",
        p(&json),
        "--format",
        "zemax",
        "--out",
        p(&out_file),
        "--geometry",
        p(&half_file),
    ]);
    assert_ok(&out, "export on a plane-symmetric file's grid");
    assert!(
        text(&out.stderr).contains("mirrored"),
        "{}",
        text(&out.stderr)
    );
    let Some(t) = python_read("zemax", &out_file) else {
        return;
    };
    assert_eq!(t["symmetry"], "Asymmetrical");
    assert_eq!(
        f64s(&t["azimuths"]),
        vec![0.0, 60.0, 120.0, 180.0, 240.0, 300.0]
    );
    // An explicitly plane-symmetric grid cannot hold it: refused, saying what to do.
    let out = bsdfit(&[
        "export",
        p(&json),
        "--format",
        "zemax",
        "--out",
        p(&out_file),
        "--geometry",
        "symmetry=planesymmetrical",
    ]);
    assert_clear_error(&out, &["asymmetrical table"]);
}

#[test]
fn a_spectral_astm_brdf_in_radians_is_fitted_and_diagnosed_like_any_measurement() {
    // 31 wavelengths 400…700 nm, radians, off-plane geometries, written here from the
    // definition (a Cornell-style file); a Lambertian spectrum with 1% noise.
    let dir = tempfile::tempdir().unwrap();
    let wl: Vec<f64> = (0..31).map(|k| 400.0 + 10.0 * k as f64).collect();
    let rho = |w: f64| 0.2 + 0.5 * (w - 400.0) / 300.0;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let n = Normal::new(0.0, 0.01).unwrap();
    let mut rows = Vec::new();
    for ti in [10.0f64, 30.0, 50.0] {
        for ts in [15.0f64, 35.0, 55.0, 75.0] {
            for ps in [-135.0f64, -60.0, 0.0, 45.0, 120.0, 180.0] {
                let mut cells: Vec<String> = [ti, 0.0, ts, ps]
                    .iter()
                    .map(|a| format!("{:.9}", a.to_radians()))
                    .collect();
                cells.extend(wl.iter().map(|&w| {
                    format!(
                        "{:.6}",
                        rho(w) / std::f64::consts::PI * (1.0 + n.sample(&mut rng))
                    )
                }));
                rows.push(cells.join(","));
            }
        }
    }
    let header = format!(
        "SOURCE test\nMEAS_NAME spectral white\nSAMPLE_NAME \"spectral white\"\nNUM_POINTS {}\nVARS theta_i,phi_i,theta_s,phi_s,{}\n",
        rows.len(),
        wl.iter().map(|w| format!("{w}")).collect::<Vec<_>>().join(",")
    );
    let file = dir.path().join("white.astm");
    std::fs::write(&file, header + &rows.join("\n") + "\n").unwrap();
    let json = dir.path().join("fit.json");
    let out = bsdfit(&[
        "fit",
        p(&file),
        "--model",
        "lambert",
        "--backend",
        "cpu",
        "--restarts",
        "2",
        "--assume-uncertainty",
        "0.01,1e-5",
        "--json",
        p(&json),
    ]);
    assert_ok(&out, "fit");
    let fit = saved(&json);
    assert_eq!(fit.channels, wl);
    for (k, &w) in wl.iter().enumerate() {
        let (v, s) = value_of(&fit, &format!("rho[{k}]"));
        assert!(
            (v - rho(w)).abs() < 4.0 * s,
            "ρ({w}) = {v} ± {s}, truth {}",
            rho(w)
        );
    }
    let out = bsdfit(&[
        "diagnose",
        p(&file),
        "--model",
        "lambert",
        "--backend",
        "cpu",
        "--restarts",
        "2",
        "--bootstrap",
        "0",
        "--max-steps",
        "1",
        "--assume-uncertainty",
        "0.01,1e-5",
    ]);
    assert_ok(&out, "diagnose");
}

#[test]
fn convert_sweep_and_eval_at_read_both_formats() {
    let dir = tempfile::tempdir().unwrap();
    let (zemax, _) = measured_btdf(dir.path());
    let astm = dir.path().join("btdf.astm");
    // 550 nm: the nominal wavelength of a Monochrome table without a wavelength comment.
    let v = fit_json("btdf(tr)+scale", &[550.0], &[0.0], &TRUTH, 0.01);
    let json = write_json(dir.path(), "btdf.json", &v);
    assert_ok(
        &bsdfit(&[
            "export",
            p(&json),
            "--format",
            "astm",
            "--geometry",
            "oblique",
            "--out",
            p(&astm),
        ]),
        "export",
    );
    for data in [&zemax, &astm] {
        let csv = dir.path().join("converted.csv");
        let out = bsdfit(&[
            "convert",
            p(data),
            "--assume-uncertainty",
            "0.01,1e-5",
            "--allow-zero-uncertainty",
            "--out",
            p(&csv),
        ]);
        assert_ok(&out, "convert");
        let ds = bsdfit::data::Dataset::read(&csv, &Default::default()).unwrap();
        assert_eq!(ds.kind, bsdfit::data::Kind::Btdf);
        let evaluated = dir.path().join("eval.csv");
        assert_ok(
            &bsdfit(&["eval", p(&json), "--at", p(data), "--out", p(&evaluated)]),
            "eval --at",
        );
        // eval --at reads the geometries (no assumption needed) and gives the same rows.
        let e = bsdfit::data::Dataset::read(&evaluated, &ReadOptionsAllowZero::get()).unwrap();
        assert_eq!(e.len(), ds.len());
    }
    let out = bsdfit(&[
        "sweep",
        p(&zemax),
        p(&astm),
        "--models",
        "btdf(tr)+scale",
        "--losses",
        "chi2",
        "--restarts",
        "2",
        "--backend",
        "cpu",
        "--assume-uncertainty",
        "0.01,1e-5",
        "--allow-zero-uncertainty",
        "--no-pictures",
        "--out",
        p(&dir.path().join("sweep")),
    ]);
    assert_ok(&out, "sweep");
    assert!(
        text(&out.stderr).contains("2 new fits"),
        "{}",
        text(&out.stderr)
    );
}

/// Read options that floor zero uncertainties (model rows where the model is 0).
struct ReadOptionsAllowZero;

impl ReadOptionsAllowZero {
    fn get() -> bsdfit::data::ReadOptions {
        bsdfit::data::ReadOptions {
            allow_zero_uncertainty: true,
            ..Default::default()
        }
    }
}

/// `export --geometry`'s symmetry word: any case of the format's words, and a clear
/// refusal of anything else, naming the option as each front end spells it.
#[test]
fn the_geometry_symmetry_is_one_of_the_formats_words() {
    use bsdfit::data::readers::zemax::Symmetry;
    use bsdfit::workflows::optical::zemax::ZemaxGrid;
    let g = ZemaxGrid::parse("symmetry=asymmetrical4D", Symmetry::PlaneSymmetrical).unwrap();
    assert_eq!(g.symmetry, Symmetry::Asymmetrical4D);
    let e = ZemaxGrid::parse("symmetry=Radial", Symmetry::PlaneSymmetrical).unwrap_err();
    // The library names the option in words; the command line prints it as its flag.
    let words = "symmetry 'radial' is not PlaneSymmetrical, Asymmetrical or Asymmetrical4D";
    assert_eq!(e.to_string(), format!("geometry: {words}"));
    assert_eq!(bsdfit::cli::error_text(&e), format!("--geometry: {words}"));
}
