//! The diagnosis on data shaped like real measurements (issue "Diagnosis that holds on
//! data nobody here made"): a new parameter known to a few per cent is determined however
//! strongly it correlates with others; a significant effect whose parameter ends on a
//! bound is adopted, and the evidence says what the bound means; a narrow lobe is found
//! from the flagged region; dense data are explored on a subsample and confirmed on all
//! of them; a tape-shaped ALTA file without `#PARAM_OUT` reads with `--alta-values` and
//! diagnoses to a retro lobe.
//!
//! The data are synthesized here, with seeds, geometries and parameters used nowhere else.

mod common;

use bsdfit::bsdf::Model;
use bsdfit::data::{Dataset, Kind};
use bsdfit::engine::Backend;
use bsdfit::workflows::diagnose::{diagnose, DiagnoseOptions, Diagnosis, Effect};
use common::synth_rows;
use std::sync::OnceLock;

fn backend() -> &'static dyn Backend {
    static B: OnceLock<Box<dyn Backend>> = OnceLock::new();
    B.get_or_init(common::gpu_engine).as_ref()
}

fn run(name: &str, data: &Dataset, start: &str, opts: &DiagnoseOptions) -> Diagnosis {
    let d = diagnose(data, start, backend(), opts, &mut |l| {
        eprintln!("[{name}] {l}")
    })
    .unwrap();
    eprintln!(
        "[{name}] {} → {}",
        d.steps
            .iter()
            .map(|s| format!("{} ({:.3})", s.model, s.chi2_red))
            .collect::<Vec<_>>()
            .join(" → "),
        d.effects
            .iter()
            .map(|e| e.name())
            .collect::<Vec<_>>()
            .join(", ")
    );
    d
}

fn synth(spec: &str, params: &str, rows: &[[f64; 4]], noise: (f64, f64), seed: u64) -> Dataset {
    let btdf = Model::parse(spec, 1).unwrap().kind == Kind::Btdf;
    let wl: Vec<f64> = if btdf {
        vec![633.0]
    } else {
        vec![460.0, 560.0, 640.0]
    };
    synth_rows(spec, params, rows, &wl, noise, seed).2
}

/// An elliptic diffuser measured at normal incidence on two planes: its second
/// roughness trades off against the index of refraction and the scale (at normal
/// incidence only their combination shapes the lobe), and with its frame φ0 as well (two
/// widths for three parameters). With the frame free, the roughnesses are not determined
/// on their own, and the fit says so; held with what they trade off against, the second
/// is known to a few per cent, so `+aniso` is adopted, the evidence saying what was held.
#[test]
fn a_determined_parameter_is_adopted_whatever_it_correlates_with() {
    let mut rows = Vec::new();
    for (k, phi) in [0.0, 90.0].into_iter().enumerate() {
        for i in 0..=48 {
            let t = -24.0 + i as f64;
            if k == 1 && t == 0.0 {
                continue;
            }
            rows.push([0.0, 0.0, t, phi]);
        }
    }
    let data = synth(
        "btdf(tr)+scale+aniso",
        "scale=0.7,alpha_u=0.05,alpha_v=0.09,phi0=0,eta=1.45",
        &rows,
        (0.02, 1e-4),
        9101,
    );
    let d = run(
        "anisotropy",
        &data,
        "btdf(tr)+scale",
        &DiagnoseOptions::default(),
    );
    assert_eq!(
        d.effects.first(),
        Some(&Effect::Anisotropy),
        "{:#}",
        d.to_json()
    );
    let last = d.steps.last().unwrap();
    assert!(last.chi2_red < 1.3, "{:#}", d.to_json());
    let fit = &d.steps[1].fit;
    let names = fit.model.flat_names();
    let j = names
        .iter()
        .position(|n| n == "alpha_v")
        .expect("an anisotropic alpha");
    // The frame left free (its truth is 0°, where the widths are stationary in φ0): no σ
    // for the roughnesses along its axes, and the fit's warnings say why.
    assert_eq!(
        fit.cov.std[j], None,
        "alpha_v quoted with φ0 free: {:?}",
        fit.cov.std
    );
    assert!(
        fit.cov
            .warnings
            .iter()
            .any(|w| w.contains("along the axes of the frame phi0")),
        "{:?}",
        fit.cov.warnings
    );
    let evidence = d.to_json()["steps"][1]["evidence"]
        .as_str()
        .unwrap()
        .to_string();
    let held = evidence
        .split("Determined: ")
        .nth(1)
        .unwrap_or_else(|| panic!("no identifiability note: {evidence}"));
    eprintln!("Determined: {}", &held[..held.len().min(300)]);
    assert!(
        held.contains("is determined (±") && held.contains("held at the fitted values"),
        "{evidence}"
    );
}

/// A retroreflective lobe brighter than `+mrm82` can make it (k_r = 1, its bound) and
/// one `+retro` makes freely: the effect is adopted whichever lobe wins, and where the
/// winner's k_r sits on its bound, the evidence says which bound and what it means.
#[test]
fn a_parameter_on_a_bound_is_information_not_a_veto() {
    let rows = common::tape_rows();
    let data = synth(
        "lambert+mrm82",
        "rho=0.3:0.35:0.4,kr=1,alpha_r=0.04,f0=0.6,f82=1",
        &rows,
        (0.03, 1e-3),
        9202,
    );
    let opts = DiagnoseOptions {
        max_steps: 1,
        factors_past_max_steps: 0,
        ..Default::default()
    };
    let d = run("bound", &data, "lambert", &opts);
    assert_eq!(
        d.effects.first(),
        Some(&Effect::RetroLobe),
        "{:#}",
        d.to_json()
    );
    let adopted = &d.steps[1];
    if adopted.model.contains("mrm82") && adopted.evidence.contains("kr") {
        assert!(
            adopted.evidence.contains("at the top of its range"),
            "{}",
            adopted.evidence
        );
    }
    assert!(
        d.steps[1].chi2_red < 0.2 * d.steps[0].chi2_red,
        "{:#}",
        d.to_json()
    );
}

/// A retro peak only 2° wide, sampled within 3° of the retro direction: random starts of
/// α_r rarely land near it, the flagged region's width seeds it.
#[test]
fn a_narrow_peak_is_found_from_the_flagged_region() {
    let mut rows = Vec::new();
    for ti in [20.0, 40.0, 60.0] {
        let mut to: f64 = -80.0;
        while to <= 80.0 {
            if (to - ti).abs() > 0.2 {
                rows.push([ti, 0.0, to, 0.0]);
            }
            to += 5.0;
        }
        for d in [-3.0, -2.0, -1.5, -1.0, -0.5, 0.5, 1.0, 1.5, 2.0, 3.0] {
            rows.push([ti, 0.0, ti + d, 0.0]);
        }
    }
    let data = synth(
        "eon+retro",
        "rho=0.3:0.31:0.33,r=0.2,kr=0.05,alpha_r=0.02",
        &rows,
        (0.02, 1e-4),
        9303,
    );
    let d = run("narrow", &data, "eon", &DiagnoseOptions::default());
    assert_eq!(
        d.effects.first(),
        Some(&Effect::RetroLobe),
        "{:#}",
        d.to_json()
    );
    assert!(d.steps.last().unwrap().chi2_red < 1.5, "{:#}", d.to_json());
}

/// Dense data: 6,000 samples explored on a subsample of 1,500, the path confirmed on all.
#[test]
fn dense_data_are_explored_on_a_subsample_and_confirmed_on_all() {
    let (_, rows) = bsdfit::workflows::synth::geometry("grid:4").unwrap();
    let data = synth(
        "fa(eon)",
        "base.rho=0.5:0.45:0.4,base.r=0.5,lobe.alpha=0.15,lobe.eta=1.5,lobe.ks=0.3",
        &rows,
        (0.02, 1e-4),
        9404,
    );
    assert!(data.len() > 6000, "{}", data.len());
    let opts = DiagnoseOptions {
        explore: 1500,
        ..Default::default()
    };
    let mut lines = Vec::new();
    let d = diagnose(&data, "eon", backend(), &opts, &mut |l| lines.push(l)).unwrap();
    assert!(
        lines.iter().any(|l| l.contains("stratified subsample")),
        "{lines:#?}"
    );
    assert_eq!(
        d.effects.first(),
        Some(&Effect::SpecularLobe),
        "{:#}",
        d.to_json()
    );
    let last = d.steps.last().unwrap();
    // The staircase is the full data's.
    assert_eq!(last.fit.z.len(), data.len());
    assert!(
        last.evidence.contains("Confirmed on all"),
        "{}",
        last.evidence
    );
    assert!(last.chi2_red < 1.3, "{:#}", d.to_json());
}

/// A tape-shaped ALTA file (3 incidences, the hemisphere and the retro peak, values
/// BRDF × cos θo) without `#PARAM_OUT`, read with `--alta-values brdf-cos`: `diagnose` from
/// `lambert` names the retro lobe.
#[test]
fn a_tape_shaped_alta_file_without_param_out_diagnoses_to_a_retro_lobe() {
    let rows = common::tape_rows();
    let model = Model::parse("fa(lambert)+mrm82+falloff", 1).unwrap();
    let flat = model
        .params_from_assignments(
            "kr=0.8,alpha_r=0.045,f0=0.2,f82=0.6,q=0.5,lobe.alpha=0.12,lobe.eta=1.6,lobe.ks=0.08,base.rho=0.9",
        )
        .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("tape.dat");
    let mut text = String::from(
        "#SAMPLE \"synthetic tape\"\n#DIM 3 1\n#VS 0\n#PARAM_IN ISOTROPIC_TL_TV_PROJ_DPHI\n",
    );
    for r in &rows {
        let wi = common::dir(r[0].to_radians(), 0.0);
        let wo = common::dir(r[2].to_radians(), r[3].to_radians());
        if wo.z < 1e-3 {
            continue;
        }
        let f = model.eval(&flat, 0, wi, wo) * wo.z;
        // ALTA's ISOTROPIC_TL_TV_PROJ_DPHI: θl, then θv projected on the azimuth Δφ of
        // V (L at azimuth 0): x = θv cos Δφ, y = θv sin Δφ.
        let (tv, dphi) = (r[2].to_radians(), r[3].to_radians());
        text += &format!(
            "{} {} {} {}\n",
            r[0].to_radians(),
            tv * dphi.cos(),
            tv * dphi.sin(),
            f
        );
    }
    std::fs::write(&path, text).unwrap();
    let out = std::process::Command::new(common::bin())
        .args(["diagnose"])
        .arg(&path)
        .args([
            "--model",
            "lambert",
            "--assume-uncertainty",
            "0.03,0.001",
            "--alta-values",
            "brdf-cos",
            "--max-steps",
            "2",
            "--bootstrap",
            "0",
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stderr.contains("--alta-values brdf-cos"), "{stderr}");
    let effects = stdout
        .lines()
        .find(|l| l.starts_with("effects:"))
        .unwrap_or_default();
    assert!(effects.contains("retro_lobe"), "{stdout}");
}

/// A dense, off-plane RGB measurement of a micrograin surface (θi and θo every 10° to 80°,
/// φo every 10° from 0° to 180°: 1,539 direction pairs × RGB, 3 % + 0.001 noise, the
/// size of a real material sampled from a database) hiding a specular coat and a retro
/// lobe over `rmg(lambert)`: from `lambert` the diagnosis names the grazing decay, the
/// specular lobe and the retro lobe, and ends consistent. (Its time is measured in
/// docs/performance.md, not here.)
#[test]
fn a_dense_off_plane_rgb_micrograin_surface_names_its_hidden_lobe_and_retro() {
    let mut rows = Vec::new();
    for ti in (0..=80).step_by(10) {
        for to in (0..=80).step_by(10) {
            for po in (0..=180).step_by(10) {
                rows.push([ti as f64, 0.0, to as f64, po as f64]);
            }
        }
    }
    let data = synth(
        "rmg(lambert)+coat+retro",
        "tau0=0.45,beta=0.35,rho_g=0.55:0.5:0.4,eta_g=1.4,base.rho=0.35:0.4:0.5,kc=0.05,alpha_c=0.12,kr=0.25,alpha_r=0.12",
        &rows,
        (0.03, 0.001),
        8101,
    );
    assert_eq!(data.len(), 1539 * 3);
    let d = run("dense-rgb", &data, "lambert", &DiagnoseOptions::default());
    names_the_micrograin_lobes_consistently(&d);
    // Every bootstrap the diagnosis ran settled its verdict or says why it could not.
    for s in d.steps.iter().flat_map(|s| &s.candidates) {
        if let bsdfit::workflows::diagnose::PTest::Bootstrap(c) = &s.p_test {
            assert!(c.replicates <= 999 && c.batches.last() == Some(&c.replicates));
            assert!(c.undecided.is_none() || c.p >= s.level, "{c:?}");
        }
    }
}

/// A micrograin surface with a coat and a retro lobe (the defaults of `synth`), measured
/// off-plane at four incidences (θo 10–80°, φo every 30°: 384 direction pairs × RGB, 3 % +
/// 0.001 noise). The greedy path takes the micrograin body for a Fresnel aggregate's and
/// ends inconsistent; a data-driven factor (the body's profile or the NDF) would absorb
/// what the micrograin layer does, so the factors are the last resort: the analytic search
/// backtracks first, finds the truth's model consistent, and no factor is ever fitted.
#[test]
fn the_analytic_search_backtracks_before_any_data_driven_factor() {
    let mut rows = Vec::new();
    for ti in [0.0, 20.0, 40.0, 60.0] {
        for to in (10..=80).step_by(10) {
            for po in (0..360).step_by(30) {
                rows.push([ti, 0.0, to as f64, po as f64]);
            }
        }
    }
    let data = synth("rmg(lambert)+coat+retro", "", &rows, (0.03, 0.001), 1);
    assert_eq!(data.len(), 384 * 3);
    let mut lines = Vec::new();
    let d = diagnose(
        &data,
        "lambert",
        backend(),
        &DiagnoseOptions::default(),
        &mut |l| {
            eprintln!("[factor-last] {l}");
            lines.push(l)
        },
    )
    .unwrap();
    names_the_micrograin_lobes_consistently(&d);
    let factor_rounds: Vec<&String> = lines
        .iter()
        .filter(|l| l.contains("data-driven factors"))
        .collect();
    assert!(factor_rounds.is_empty(), "{factor_rounds:?}");
    assert!(
        !d.effects.iter().any(|e| e.is_data_driven()),
        "a data-driven factor named: {:?}",
        d.effects
    );
}

/// The effects of `rmg(lambert)+coat+retro` are named and the diagnosis ends consistent.
fn names_the_micrograin_lobes_consistently(d: &Diagnosis) {
    for e in [
        Effect::GrazingDecay,
        Effect::SpecularLobe,
        Effect::RetroLobe,
    ] {
        assert!(d.effects.contains(&e), "{e:?} not named: {:?}", d.effects);
    }
    let last = d.steps.last().unwrap();
    assert!(
        last.fit.p_consistent() > 0.01,
        "ends at χ²_red {:.3} on {} dof",
        last.chi2_red,
        last.fit.dof
    );
}
