//! The discrepancy workflow (docs/diagnose.md): for every effect of the catalogue,
//! data in which the effect is present, a start model without it, and the assertion that
//! `diagnose` names the effect and that χ²_red falls by ≥ 5× to below 3; controls with
//! nothing missing must add no effect.
//!
//! The data is made independently of the tuned defaults: goniometer geometries written
//! here (not the named `synth` geometries: other incidence angles, steps, azimuths), seeds
//! and parameter values used nowhere else, a different noise level per test. Each
//! geometry is chosen so the hidden effect is identifiable, as each test says.

mod common;

use bsdfit::bsdf::Model;
use bsdfit::data::{Dataset, Kind};
use bsdfit::engine::Backend;
use bsdfit::workflows::diagnose::{diagnose, DiagnoseOptions, Diagnosis, Effect};
use common::synth_rows;
use std::sync::OnceLock;

/// One backend for the whole file: the GPU engine (lavapipe in CI, where its absence fails).
fn backend() -> &'static dyn Backend {
    static B: OnceLock<Box<dyn Backend>> = OnceLock::new();
    B.get_or_init(common::gpu_engine).as_ref()
}

fn opts(seed: u64) -> DiagnoseOptions {
    DiagnoseOptions {
        restarts: 16,
        seed,
        ..Default::default()
    }
}

/// Signed in-plane angles from `lo` to `hi` in `step`.
fn steps(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let n = ((hi - lo) / step).round() as usize;
    (0..=n).map(|i| lo + i as f64 * step).collect()
}

/// In-plane BRDF rows in the plane φ = `phi` (30°, not the usual 0°): θo signed, negative
/// on the mirror side; the exact retro direction is omitted (the detector hides the
/// source). `extra` adds θo offsets around the mirror (−θi + d) or the retro (θi + d).
fn brdf_rows(
    theta_i: &[f64],
    theta_o: &[f64],
    phi: f64,
    mirror_offsets: &[f64],
    retro_offsets: &[f64],
) -> Vec<[f64; 4]> {
    let mut rows = Vec::new();
    for &ti in theta_i {
        let mut tos: Vec<f64> = theta_o.to_vec();
        tos.extend(mirror_offsets.iter().map(|d| -ti + d));
        tos.extend(retro_offsets.iter().map(|d| ti + d));
        tos.sort_by(|a, b| a.total_cmp(b));
        tos.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
        for to in tos {
            if (to - ti).abs() < 0.5 || to.abs() > 88.0 {
                continue;
            }
            rows.push([ti, phi, to, phi]);
        }
    }
    rows
}

/// BTDF rows: incidences `theta_i` in the plane φ = 0, θt signed on each plane `planes`.
fn btdf_rows(theta_i: &[f64], theta_t: &[f64], planes: &[f64]) -> Vec<[f64; 4]> {
    let mut rows = Vec::new();
    for &ti in theta_i {
        for (k, &phi) in planes.iter().enumerate() {
            for &t in theta_t {
                if k > 0 && t == 0.0 {
                    continue; // θt = 0 lies on every plane: measured once
                }
                rows.push([ti, 0.0, t, phi]);
            }
        }
    }
    rows
}

/// Synthesize `spec` with `params` on `rows` (wavelengths: 3 channels for a BRDF, one for
/// a BTDF), noise u = sqrt((rel·f)² + abs²).
fn synth(spec: &str, params: &str, rows: &[[f64; 4]], noise: (f64, f64), seed: u64) -> Dataset {
    let btdf = Model::parse(spec, 1).unwrap().kind == Kind::Btdf;
    let wl: Vec<f64> = if btdf {
        vec![589.0]
    } else {
        vec![470.0, 540.0, 610.0]
    };
    let mut data = synth_rows(spec, params, rows, &wl, noise, seed).2;
    data.material = format!("hidden {spec}");
    data
}

/// Run the workflow and print its staircase (collected into the table).
fn run(name: &str, data: &Dataset, start: &str, seed: u64) -> Diagnosis {
    let t0 = std::time::Instant::now();
    let d = diagnose(data, start, backend(), &opts(seed), &mut |l| {
        eprintln!("[{name}] {l}")
    })
    .unwrap();
    eprintln!(
        "TABLE | {name} | {} | {} | {} | {:.2} s",
        d.effects
            .iter()
            .map(|e| e.name())
            .collect::<Vec<_>>()
            .join(", "),
        d.steps
            .iter()
            .map(|s| format!("{} ({:.3})", s.model, s.chi2_red))
            .collect::<Vec<_>>()
            .join(" → "),
        d.final_model,
        t0.elapsed().as_secs_f64()
    );
    d
}

/// The effect was found first, and χ²_red fell ≥ 5× to below 3.
fn assert_found(d: &Diagnosis, effect: Effect) {
    assert!(
        !d.effects.is_empty(),
        "no effect found; steps: {:#?}",
        d.to_json()
    );
    assert_eq!(
        d.effects[0],
        effect,
        "wrong effect; diagnosis: {:#}",
        d.to_json()
    );
    let before = d.steps[0].chi2_red;
    let after = d.steps.last().unwrap().chi2_red;
    assert!(
        after < 3.0 && before >= 5.0 * after,
        "χ²_red {before:.3} → {after:.3}: {:#}",
        d.to_json()
    );
}

// ---------------------------------------------------------------------------------------
// BRDF effects

/// specular_lobe: a glossy coat over a grey diffuse base. Identifiable because the rows
/// include points 1.5–4.5° from the mirror direction at four incidences, which resolve
/// the lobe's width and its Fresnel growth with θi.
#[test]
fn hidden_specular_lobe_is_found() {
    let rows = brdf_rows(
        &[5.0, 25.0, 45.0, 65.0],
        &steps(-84.0, 84.0, 6.0),
        30.0,
        &[-4.5, -3.0, -1.5, 1.5, 3.0, 4.5],
        &[],
    );
    let data = synth(
        "fa(lambert)",
        "base.rho=0.21:0.34:0.47,lobe.alpha=0.13,lobe.eta=1.42,lobe.ks=0.55",
        &rows,
        (0.02, 2e-4),
        4101,
    );
    let d = run("specular_lobe", &data, "lambert", 11);
    assert_found(&d, Effect::SpecularLobe);
    assert!(
        d.steps[0].evidence.contains("of the mirror direction"),
        "{}",
        d.steps[0].evidence
    );
    assert!(
        d.steps[0].evidence.contains("too dark"),
        "{}",
        d.steps[0].evidence
    );
}

/// backscatter: a rough (Oren–Nayar σ = 0.55) matte surface. Identifiable because the
/// rows cover θi up to 75° on both sides of the normal: the source-side excess grows with θi.
#[test]
fn hidden_backscatter_is_found() {
    let rows = brdf_rows(
        &[0.0, 15.0, 35.0, 55.0, 75.0],
        &steps(-85.0, 85.0, 5.0),
        30.0,
        &[],
        &[],
    );
    let data = synth(
        "on",
        "rho=0.62:0.55:0.48,sigma=0.55",
        &rows,
        (0.012, 1e-4),
        4202,
    );
    let d = run("backscatter", &data, "lambert", 12);
    assert_found(&d, Effect::Backscatter);
    let e = &d.steps[0].evidence;
    assert!(
        e.contains("source (backscatter) side") || e.contains("retro direction"),
        "{e}"
    );
}

/// retro_lobe: a retroreflective sheet (a sharp lobe, α_r = 0.06, on a rough diffuse
/// base). Identifiable because the rows include points 1–4° from the retro direction;
/// starting from `eon` so that the base roughness is already in the model.
#[test]
fn hidden_retro_lobe_is_found() {
    let rows = brdf_rows(
        &[10.0, 30.0, 50.0, 70.0],
        &steps(-80.0, 80.0, 8.0),
        30.0,
        &[],
        &[-4.0, -2.5, -1.0, 1.0, 2.5, 4.0],
    );
    let data = synth(
        "eon+retro",
        "rho=0.41:0.44:0.52,r=0.35,kr=0.9,alpha_r=0.06",
        &rows,
        (0.015, 1e-4),
        4303,
    );
    let d = run("retro_lobe", &data, "eon", 13);
    assert_found(&d, Effect::RetroLobe);
    assert!(
        d.steps[0].evidence.contains("of the retro direction"),
        "{}",
        d.steps[0].evidence
    );
}

/// retro_falloff: a retroreflective sheet whose retro peak falls with the entrance angle
/// (efficiency (μi μo)^q, q = 1.3, on a back-vector lobe over a rough diffuse base), started
/// from the same model without the efficiency. Identifiable because the retro peak is
/// sampled (1–4° from it) at five incidences from 5° to 65°, over which μi^(2q) falls
/// 25-fold.
#[test]
fn hidden_retro_falloff_is_found() {
    let rows = brdf_rows(
        &[5.0, 20.0, 35.0, 50.0, 65.0],
        &steps(-81.0, 81.0, 9.0),
        30.0,
        &[],
        &[-4.0, -2.0, -1.0, 1.0, 2.0, 4.0],
    );
    let data = synth(
        "eon+retro+falloff",
        "rho=0.36:0.47:0.28,r=0.4,kr=0.8,alpha_r=0.07,q=1.3",
        &rows,
        (0.015, 1e-4),
        4353,
    );
    let d = run("retro_falloff", &data, "eon+retro", 23);
    assert_found(&d, Effect::RetroFalloff);
    assert_eq!(d.steps[1].model, "eon+retro+falloff");
    assert!(
        d.steps[0].evidence.contains("retro direction"),
        "{}",
        d.steps[0].evidence
    );
}

/// grazing_decay: dark micrograins over a bright Oren–Nayar base (dmg). Identifiable
/// because θo reaches 86° at every incidence, where the grains hide the base.
#[test]
fn hidden_grazing_decay_is_found() {
    let rows = brdf_rows(
        &[0.0, 20.0, 40.0, 60.0],
        &steps(-86.0, 86.0, 4.0),
        30.0,
        &[],
        &[],
    );
    let data = synth(
        "dmg(on)",
        "tau0=0.35,beta=0.7,rho_g=0.12:0.15:0.2,base.rho=0.7:0.75:0.8,base.sigma=0.3",
        &rows,
        (0.01, 1e-4),
        4404,
    );
    let d = run("grazing_decay", &data, "on", 14);
    assert_found(&d, Effect::GrazingDecay);
    assert!(
        d.steps[0].evidence.contains("too bright at grazing")
            || d.steps[0].evidence.contains("tails"),
        "{}",
        d.steps[0].evidence
    );
}

/// diffuse_floor (BRDF): a dark glossy dielectric whose Lambertian body reflection a pure
/// `ggx` cannot give. Identifiable because the rows reach far from the mirror direction.
#[test]
fn hidden_brdf_diffuse_floor_is_found() {
    let rows = brdf_rows(
        &[10.0, 30.0, 50.0],
        &steps(-84.0, 84.0, 4.0),
        30.0,
        &[-3.0, 3.0],
        &[],
    );
    let data = synth(
        "fa(lambert)",
        "base.rho=0.07:0.05:0.09,lobe.alpha=0.22,lobe.eta=1.55,lobe.ks=0.8",
        &rows,
        (0.015, 1e-4),
        4505,
    );
    let d = run("diffuse_floor (BRDF)", &data, "ggx", 15);
    assert_found(&d, Effect::DiffuseFloor);
}

/// Two hidden effects at once, on coarse 10° sampling (the paper's): a glossy coat over a
/// rough diffuse base, started from `lambert`. Rough micrograins (`rmg`) can mimic a lobe
/// this coarsely sampled, so the greedy path may go astray; the workflow must still end
/// with both effects named and the misfit within the uncertainties.
#[test]
fn two_hidden_effects_are_found() {
    let rows = brdf_rows(
        &[0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0, 70.0],
        &steps(-80.0, 80.0, 10.0),
        30.0,
        &[],
        &[],
    );
    let data = synth(
        "fa(eon)",
        "base.rho=0.66:0.7:0.74,base.r=0.3,lobe.alpha=0.1,lobe.eta=1.5,lobe.ks=0.9",
        &rows,
        (0.01, 2e-4),
        5212,
    );
    let d = run("specular_lobe + backscatter", &data, "lambert", 22);
    let mut effects = d.effects.clone();
    effects.sort_by_key(|e| e.name());
    assert_eq!(
        effects,
        [Effect::Backscatter, Effect::SpecularLobe],
        "{:#}",
        d.to_json()
    );
    let (before, after) = (d.steps[0].chi2_red, d.steps.last().unwrap().chi2_red);
    assert!(
        after < 3.0 && before >= 5.0 * after,
        "χ²_red {before:.3} → {after:.3}"
    );
}

// ---------------------------------------------------------------------------------------
// BTDF effects

/// scale: S = 0.58. Only separable from η_t with oblique incidence (docs/models.md: at normal
/// incidence α, η_t and S trade off), so the rows have θi = 0, 25 and 50°.
#[test]
fn hidden_scale_is_found() {
    let rows = btdf_rows(&[0.0, 25.0, 50.0], &steps(-78.0, 78.0, 3.0), &[0.0]);
    let data = synth(
        "btdf(tr)+scale",
        "scale=0.58,alpha=0.21,eta=1.38",
        &rows,
        (0.02, 2e-4),
        4606,
    );
    let d = run("scale", &data, "btdf(tr)", 16);
    assert_found(&d, Effect::Scale);
}

/// absorption: τ = 0.45. The deficit grows as 1/μt, so the rows reach θt = ±81° at three
/// incidences (at normal incidence and small θt it would be a constant factor, i.e. scale).
#[test]
fn hidden_absorption_is_found() {
    let rows = btdf_rows(&[0.0, 35.0, 55.0], &steps(-81.0, 81.0, 3.0), &[0.0]);
    let data = synth(
        "btdf(beckmann)+absorb",
        "tau=0.45,alpha=0.27,eta=1.55",
        &rows,
        (0.02, 2e-4),
        4707,
    );
    let d = run("absorption", &data, "btdf(beckmann)", 17);
    assert_found(&d, Effect::Absorption);
    assert!(
        d.steps[0].evidence.contains("too bright"),
        "{}",
        d.steps[0].evidence
    );
}

/// long_tail: a Trowbridge–Reitz (GGX) diffuser fitted with Beckmann, whose tails fall
/// far too fast. Identifiable because θt reaches 80° with a noise floor well below the
/// tails (abs 2e-5).
#[test]
fn hidden_long_tail_is_found() {
    let rows = btdf_rows(&[0.0, 20.0, 45.0], &steps(-80.0, 80.0, 2.5), &[0.0]);
    let data = synth("btdf(tr)", "alpha=0.09,eta=1.47", &rows, (0.02, 2e-5), 4808);
    let d = run("long_tail", &data, "btdf(beckmann)", 18);
    assert_found(&d, Effect::LongTail);
    assert_eq!(d.steps[1].model, "btdf(tr)");
    assert!(
        d.steps[0].evidence.contains("tails") || d.steps[0].evidence.contains("flanks"),
        "{}",
        d.steps[0].evidence
    );
}

/// anisotropy: an anisotropic surface (α_u = 0.07 along φ0 = 20°, α_v = 0.16 across)
/// measured on the planes of its axes (φ = 20° and 110°, not the PTB's 0/90°).
/// Identifiable only because both planes are measured, at 1.5° steps; at normal incidence
/// S and η_t are not (the workflow must not add them).
#[test]
fn hidden_anisotropy_is_found() {
    let rows = btdf_rows(&[0.0], &steps(-33.0, 33.0, 1.5), &[20.0, 110.0]);
    let data = synth(
        "btdf(tr)+aniso",
        "alpha_u=0.07,alpha_v=0.16,phi0=20,eta=1.5",
        &rows,
        (0.02, 1e-4),
        4909,
    );
    assert_eq!(data.axes, vec![20.0, 110.0]);
    let d = run("anisotropy", &data, "btdf(tr)", 19);
    assert_found(&d, Effect::Anisotropy);
    assert!(
        !d.effects.contains(&Effect::Scale),
        "scale is not identifiable at normal incidence: {:#}",
        d.to_json()
    );
    let e = &d.steps[0].evidence;
    assert!(
        e.contains("φ = 20° plane") || e.contains("φ = 110° plane") || e.contains("peak"),
        "{e}"
    );
}

/// diffuse_floor (BTDF): a sharp transmission lobe on a flat Lambertian floor
/// (k_d = 0.035). Identifiable because the rows reach θt = ±84° at two incidences, where
/// the lobe is negligible and the floor is flat.
#[test]
fn hidden_btdf_diffuse_floor_is_found() {
    let rows = btdf_rows(&[0.0, 40.0], &steps(-84.0, 84.0, 3.0), &[0.0]);
    let data = synth(
        "btdf(tr)+diffuse",
        "kd=0.035,alpha=0.11,eta=1.6",
        &rows,
        (0.02, 1e-4),
        5010,
    );
    let d = run("diffuse_floor (BTDF)", &data, "btdf(tr)", 20);
    assert_found(&d, Effect::DiffuseFloor);
    assert!(
        d.steps[0].evidence.contains("tails"),
        "{}",
        d.steps[0].evidence
    );
}

// ---------------------------------------------------------------------------------------
// Controls: nothing missing

/// Data made by the start model itself, over several seeds and models: no effect may be
/// added. Each case runs the whole workflow, and once more with the consistency gate
/// switched off so that every candidate is fitted and the F/BIC gates alone decide.
#[test]
fn controls_add_no_effect() {
    let brdf = brdf_rows(
        &[5.0, 30.0, 55.0],
        &steps(-80.0, 80.0, 8.0),
        30.0,
        &[-2.0, 2.0],
        &[],
    );
    let btdf = btdf_rows(&[0.0, 30.0], &steps(-72.0, 72.0, 4.0), &[0.0]);
    let cases: [(&str, &str, &Vec<[f64; 4]>); 4] = [
        ("lambert", "rho=0.33:0.52:0.71", &brdf),
        ("eon", "rho=0.58:0.49:0.37,r=0.45", &brdf),
        ("btdf(tr)", "alpha=0.17,eta=1.44", &btdf),
        ("btdf(beckmann)", "alpha=0.23,eta=1.62", &btdf),
    ];
    let seeds = [7001u64, 7002, 7003];
    let (mut runs, mut added_full, mut added_gated) = (0, 0, 0);
    for (spec, params, rows) in cases {
        for (k, &seed) in seeds.iter().enumerate() {
            let data = synth(spec, params, rows, (0.015, 1e-4), seed);
            let name = format!("control {spec} seed {seed}");
            let d = run(&name, &data, spec, 30 + k as u64);
            runs += 1;
            if !d.effects.is_empty() {
                added_full += 1;
                eprintln!("FALSE POSITIVE (full workflow) {name}: {:#}", d.to_json());
            }
            let forced = DiagnoseOptions {
                stop_when_consistent: false,
                max_steps: 1,
                factors_past_max_steps: 0,
                ..opts(40 + k as u64)
            };
            let d = diagnose(&data, spec, backend(), &forced, &mut |l| {
                eprintln!("[{name}, forced] {l}")
            })
            .unwrap();
            if !d.effects.is_empty() {
                added_gated += 1;
                eprintln!(
                    "FALSE POSITIVE (F/BIC gates alone) {name}: {:#}",
                    d.to_json()
                );
            }
        }
    }
    eprintln!("CONTROLS: {runs} runs; effects added: {added_full} with the full workflow, {added_gated} by the F/BIC gates alone");
    assert_eq!(
        added_full, 0,
        "false positives in {added_full} of {runs} control runs"
    );
    assert_eq!(
        added_gated, 0,
        "the F/BIC gates alone added an effect in {added_gated} of {runs} control runs"
    );
}

/// Null data (each start model is the truth) diagnosed over `seeds` seeds per case: the
/// number of runs, of effects added by the full workflow, and of effects added by the
/// F/BIC gates alone (the consistency gate switched off, so every candidate is fitted
/// and tested).
fn false_positives(cases: &[(&str, &str, &Vec<[f64; 4]>)], seeds: u64) -> (usize, usize, usize) {
    let (mut runs, mut inconsistent, mut added_full, mut added_gated) = (0, 0, 0, 0);
    for &(spec, params, rows) in cases {
        for seed in 0..seeds {
            let data = synth(spec, params, rows, (0.015, 1e-4), 90_000 + seed);
            let d = diagnose(&data, spec, backend(), &opts(seed), &mut |_| {}).unwrap();
            runs += 1;
            inconsistent += (d.steps[0].fit.p_consistent() < 0.01) as usize;
            added_full += (!d.effects.is_empty()) as usize;
            let forced = DiagnoseOptions {
                stop_when_consistent: false,
                max_steps: 1,
                factors_past_max_steps: 0,
                ..opts(seed)
            };
            let d = diagnose(&data, spec, backend(), &forced, &mut |_| {}).unwrap();
            if !d.effects.is_empty() {
                added_gated += 1;
                eprintln!("F/BIC false positive: {spec} seed {seed}: {:?}", d.effects);
            }
        }
    }
    eprintln!(
        "FP RATE: {runs} runs; χ² consistency rejected {inconsistent}; effects added {added_full} (full workflow), {added_gated} (F/BIC gates alone)"
    );
    (runs, added_full, added_gated)
}

fn null_geometries() -> (Vec<[f64; 4]>, Vec<[f64; 4]>) {
    let brdf = brdf_rows(
        &[5.0, 30.0, 55.0],
        &steps(-80.0, 80.0, 8.0),
        30.0,
        &[-2.0, 2.0],
        &[],
    );
    let btdf = btdf_rows(&[0.0, 30.0], &steps(-72.0, 72.0, 4.0), &[0.0]);
    (brdf, btdf)
}

/// The false-positive rate over many seeds (slow: `cargo test --release --test diagnose --
/// --ignored`; `BSDFIT_FP_SEEDS` seeds per model, default 25).
#[test]
#[ignore]
fn control_false_positive_rate_over_many_seeds() {
    let n: u64 = std::env::var("BSDFIT_FP_SEEDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(25);
    let (brdf, btdf) = null_geometries();
    let (runs, added_full, added_gated) = false_positives(
        &[
            ("lambert", "rho=0.33:0.52:0.71", &brdf),
            ("eon", "rho=0.58:0.49:0.37,r=0.45", &brdf),
            ("btdf(tr)", "alpha=0.17,eta=1.44", &btdf),
            ("btdf(beckmann)", "alpha=0.23,eta=1.62", &btdf),
        ],
        n,
    );
    assert!(
        added_full * 20 <= runs && added_gated * 20 <= runs,
        "false-positive rate above 5 %"
    );
}

/// The same control, reduced for CI: a BRDF and a BTDF null case over three fixed seeds.
/// At a Bonferroni-corrected α = 0.01 and a falling BIC required, a gate that fires on
/// any of these twelve diagnoses is miscalibrated (the expected count is below 0.1).
#[test]
fn control_false_positive_rate_reduced() {
    let (brdf, btdf) = null_geometries();
    let (runs, added_full, added_gated) = false_positives(
        &[
            ("lambert", "rho=0.33:0.52:0.71", &brdf),
            ("btdf(tr)", "alpha=0.17,eta=1.44", &btdf),
        ],
        3,
    );
    assert_eq!(runs, 6);
    assert_eq!(
        (added_full, added_gated),
        (0, 0),
        "effects added to null data"
    );
}

// ---------------------------------------------------------------------------------------
// CLI: the JSON of docs/output.md and the report

#[test]
fn cli_writes_the_design_json_and_report() {
    let dir = tempfile::tempdir().unwrap();
    let rows = brdf_rows(
        &[10.0, 40.0, 60.0],
        &steps(-80.0, 80.0, 10.0),
        0.0,
        &[-3.0, 3.0],
        &[],
    );
    let data = synth(
        "fa(on)",
        "base.rho=0.3:0.35:0.4,base.sigma=0.2,lobe.alpha=0.2,lobe.eta=1.5,lobe.ks=0.7",
        &rows,
        (0.02, 1e-4),
        5111,
    );
    let file = dir.path().join("data.csv");
    data.write(&file).unwrap();
    let json = dir.path().join("d.json");
    let report = dir.path().join("report");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_bsdfit"))
        .args([
            "diagnose",
            file.to_str().unwrap(),
            "--model",
            "on",
            "--restarts",
            "12",
            "--seed",
            "21",
        ])
        .args([
            "--json",
            json.to_str().unwrap(),
            "--report",
            report.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("effects: specular_lobe"), "{stdout}");
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let keys: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
    assert_eq!(keys, ["start_model", "final_model", "effects", "steps"]);
    assert_eq!(v["start_model"], "on");
    assert_eq!(v["final_model"], "fa(on)");
    assert_eq!(v["effects"], serde_json::json!(["specular_lobe"]));
    let steps = v["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 2);
    for s in steps {
        let keys: Vec<&str> = s.as_object().unwrap().keys().map(|k| k.as_str()).collect();
        assert_eq!(keys, ["model", "effect", "chi2_red", "loss", "evidence"]);
        assert!(s["chi2_red"].as_f64().unwrap() > 0.0 && s["loss"].as_f64().is_some());
        assert!(!s["evidence"].as_str().unwrap().is_empty());
    }
    assert!(steps[0]["effect"].is_null());
    assert_eq!(steps[0]["model"], "on");
    assert_eq!(steps[1]["effect"], "specular_lobe");
    assert!(steps[0]["evidence"]
        .as_str()
        .unwrap()
        .contains("mirror direction"));
    for f in [
        "residuals_0.svg",
        "residuals_1.svg",
        "staircase.svg",
        "candidates.json",
        "diagnosis.json",
        "index.html",
    ] {
        let p = report.join(f);
        assert!(
            p.exists() && std::fs::metadata(&p).unwrap().len() > 100,
            "{} missing",
            p.display()
        );
    }
    assert!(std::fs::read_to_string(report.join("residuals_0.svg"))
        .unwrap()
        .starts_with("<svg"));
}

// ---------------------------------------------------------------------------------------
// Bootstrap-calibrated p-values (irregular nulls)

/// Data with backscatter (`on`, σ = 0.25) diagnosed from `lambert`: every extension of
/// `lambert` has an irregular null (σ, k_s, β, k_r on a bound; lobe and grain parameters
/// unidentified there). With `calibrate_all` every candidate whose verdict depends on its
/// p-value is calibrated by the bootstrap, and its JSON says which test gave the p-value
/// and the counts behind it; by default the bootstraps that cannot change the round's
/// choice are deferred, and say which candidate the round adopts regardless. Backscatter
/// is the effect found either way.
#[test]
fn bootstrap_calibrates_irregular_nulls() {
    let (bootstrapped, deferred) = bootstrap_round(true);
    assert!(
        bootstrapped >= 1 && deferred == 0,
        "{bootstrapped} {deferred}"
    );
    let (bootstrapped, deferred) = bootstrap_round(false);
    assert!(deferred >= 1, "{bootstrapped} {deferred}");
}

/// The first round of that diagnosis: its candidates bootstrapped and deferred.
fn bootstrap_round(calibrate_all: bool) -> (usize, usize) {
    let ti: Vec<f64> = (0..8).map(|k| 5.0 + 10.0 * k as f64).collect();
    let rows = brdf_rows(&ti, &steps(-80.0, 80.0, 10.0), 15.0, &[], &[]);
    let data = synth(
        "on",
        "rho=0.5:0.45:0.4,sigma=0.25",
        &rows,
        (0.02, 1e-4),
        6203,
    );
    let opts = DiagnoseOptions {
        restarts: 8,
        seed: 3,
        bootstrap: bsdfit::inference::bootstrap::BootstrapOptions {
            replicates: 59,
            restarts: 2,
            seed: 11,
            ..Default::default()
        },
        calibrate_all,
        ..Default::default()
    };
    let t0 = std::time::Instant::now();
    let d = diagnose(&data, "lambert", backend(), &opts, &mut |l| {
        eprintln!("[bootstrap] {l}")
    })
    .unwrap();
    eprintln!(
        "diagnosis with the bootstrap: {:.1} s",
        t0.elapsed().as_secs_f64()
    );
    assert_eq!(d.effects, [Effect::Backscatter], "{:#}", d.to_json());
    let round = d.candidates_json();
    let first = round[0]["candidates"].as_array().unwrap();
    let (mut bootstrapped, mut deferred) = (0, 0);
    for c in first {
        let name = c["model"].as_str().unwrap();
        let test = &c["p_test"];
        if !c["nested"].as_bool().unwrap() {
            assert!(test.is_null(), "{name}: {test}");
            continue;
        }
        let irregular = !c["irregular_null"].is_null();
        let kind = test["test"].as_str().unwrap();
        assert_eq!(
            kind == "F",
            !irregular,
            "{name}: {kind}, irregular {irregular}"
        );
        assert!(!c["p_test_description"].as_str().unwrap().is_empty());
        if kind == "deferred" {
            deferred += 1;
            let why = test["why"].as_str().unwrap();
            assert!(why.contains("adopts `on`"), "{name}: {why}");
            assert_eq!(c["significant"], false, "{name}");
        }
        if kind == "bootstrap" {
            bootstrapped += 1;
            let b = &test["bootstrap"];
            // Stopped early or at the planned 59 (none of these grows: the level is 1.1e-3
            // and each either reaches the sequential stop or settles by the count or tail).
            let drawn = b["replicates"].as_u64().unwrap();
            assert_eq!(b["batches"].as_array().unwrap().last().unwrap(), drawn);
            assert!(drawn <= 59 || b["source"] != "sequential", "{name}: {b}");
            let fitted = b["fitted"].as_u64().unwrap();
            assert!(fitted * 10 >= drawn * 9, "{name}: {b}");
            // The count and the p-value agree: (1 + #)/(B + 1) where a replicate reached
            // T, at most 1/(B + 1) from the fitted tail where none did.
            let p = c["p"].as_f64().unwrap();
            let n = b["exceeding"].as_u64().unwrap() as f64;
            let fitted = b["fitted"].as_u64().unwrap() as f64;
            match b["source"].as_str().unwrap() {
                "empirical" => assert!(n >= 1.0 && (p - (1.0 + n) / (fitted + 1.0)).abs() < 1e-12),
                "tail" => assert!(n == 0.0 && p > 0.0 && p <= 1.0 / (fitted + 1.0)),
                "sequential" => assert!(n >= 10.0 && p >= 10.0 / fitted, "{name}: {b}"),
                other => assert_eq!(other, "empirical_bound"),
            }
            assert_eq!(b["p"].as_f64().unwrap(), p, "{name}");
        }
    }
    (bootstrapped, deferred)
}
