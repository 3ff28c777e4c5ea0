// The parity suite shared by tests/gpu_parity.rs and tests/simd_parity.rs (included
// there with `include!`): an f32 engine, `tested()` (named ENGINE in messages), against
// the f64 CPU reference on random valid inputs, for every model the registry derives and
// every loss. The includer states the tolerance in its module documentation.

use bsdfit::bsdf::{every_spec, Model};
use bsdfit::data::{Dataset, Kind, RawRow, ReadOptions};
use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::{Backend, Problem};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const REL: f64 = 2e-3;
const REL_COST: f64 = 1e-3;
const FLOOR: f64 = 1e-30;
const CANDIDATES: usize = 12;
fn assert_no_failures(failures: &[String]) {
    assert!(
        failures.is_empty(),
        "{ENGINE}/CPU parity failures:\n{}",
        failures.join("\n")
    );
}

/// Random geometries (θ up to 85°, any φ) with random positive values and uncertainties.
fn random_dataset(kind: Kind, channels: usize, n: usize, seed: u64) -> Dataset {
    random_dataset_in(kind, channels, n, seed, 0.0..85.0)
}

/// [`random_dataset`] with θi and θo in `theta` (degrees).
fn random_dataset_in(
    kind: Kind,
    channels: usize,
    n: usize,
    seed: u64,
    theta: std::ops::Range<f64>,
) -> Dataset {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let wl = [450.0, 550.0, 650.0];
    let mut rows = Vec::new();
    for i in 0..n {
        let ti: f64 = rng.random_range(theta.clone());
        let to: f64 = rng.random_range(theta.clone());
        let value: f64 = rng.random_range(0.01..2.0);
        rows.push((
            i + 1,
            RawRow {
                theta_i: ti,
                phi_i: rng.random_range(0.0..360.0),
                theta_o: to,
                phi_o: rng.random_range(0.0..360.0),
                wavelength_nm: wl[i % channels],
                value,
                uncertainty: value * rng.random_range(0.005..0.05),
            },
        ));
    }
    Dataset::from_rows(kind, "random", &rows, "<random>", &ReadOptions::default())
        .expect("valid random data")
}

/// A goniometer's grid, as measured: a few incidences (θi 0°, 25°, 50°, 75°), each seen
/// from θo 0° to 80° in 10° steps on three φo planes, every direction in every channel.
/// Unlike the random set (one channel per direction), directions repeat: consecutive
/// records share ωi or ωo, and each record holds all its channels, which the kernel
/// evaluates in one call (and rmg's grain memo reuses across them).
fn grid_dataset(kind: Kind, channels: usize, seed: u64) -> Dataset {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let wl = [450.0, 550.0, 650.0];
    let mut rows = Vec::new();
    for ti in [0.0, 25.0, 50.0, 75.0] {
        for phi_o in [0.0, 90.0, 180.0] {
            for to in (0..=8).map(|i| 10.0 * i as f64) {
                for &wavelength_nm in &wl[..channels] {
                    let value: f64 = rng.random_range(0.01..2.0);
                    let (theta_i, theta_o, uncertainty) = (ti, to, value * 0.02);
                    let row = RawRow {
                        theta_i,
                        phi_i: 0.0,
                        theta_o,
                        phi_o,
                        wavelength_nm,
                        value,
                        uncertainty,
                    };
                    rows.push((rows.len() + 1, row));
                }
            }
        }
    }
    Dataset::from_rows(kind, "grid", &rows, "<grid>", &ReadOptions::default())
        .expect("valid grid data")
}

fn random_params(model: &Model, n: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .flat_map(|_| {
            let u: Vec<f64> = (0..model.dim).map(|_| rng.random::<f64>()).collect();
            model.from_unit(&u)
        })
        .collect()
}

/// Every spec the registry derives for both kinds (catalogue, per-plane variants, and each
/// model outside the catalogue), so a new model is compared without editing this file.
fn all_specs() -> Vec<(Kind, String)> {
    let mut v: Vec<(Kind, String)> = Vec::new();
    for kind in [Kind::Brdf, Kind::Btdf] {
        v.extend(every_spec(kind).into_iter().map(|s| (kind, s)));
    }
    // Nested combinations beyond one suffix on a core model.
    v.push((Kind::Brdf, "rmg(ggx)+retro".into()));
    v.push((Kind::Brdf, "fa(vmf)+mrm82+falloff".into()));
    v.push((Kind::Btdf, "btdf(gtr)+scale+diffuse".into()));
    v
}

/// Compare the tested engine's and the CPU's model values on random data and parameters; returns the worst
/// relative error or a description of the first mismatch.
fn compare_values(spec: &str, kind: Kind, channels: usize, seed: u64) -> Result<f64, String> {
    let data = random_dataset(kind, channels, 200, seed);
    let model = Model::parse(spec, channels).map_err(|e| e.to_string())?;
    let params = random_params(&model, CANDIDATES, seed + 1);
    compare_model_values(&model, &data, &params, REL)
}

/// The tested engine against CPU model values for candidates `params` on `data`, each value within
/// `rel · |cpu| + FLOOR` of its own CPU value; NaN never passes.
fn compare_model_values(
    model: &Model,
    data: &Dataset,
    params: &[f64],
    rel: f64,
) -> Result<f64, String> {
    compare_model_values_within(model, data, params, rel, &[])
}

/// [`compare_model_values`] with, per value (candidate-major), an allowance added to the
/// bound (none where `extra` is shorter).
fn compare_model_values_within(
    model: &Model,
    data: &Dataset,
    params: &[f64],
    rel: f64,
    extra: &[f64],
) -> Result<f64, String> {
    let loss = Loss::new(Metric::Chi2, Weights::Uniform);
    let problem = Problem { model, data, loss };
    let cpu = CpuBackend::new();
    let c = cpu.prepare(problem).unwrap().values(params).unwrap();
    let g = tested()
        .prepare(problem)
        .map_err(|e| format!("{e:#}"))?
        .values(params)
        .map_err(|e| format!("{e:#}"))?;
    assert_eq!(c.len(), g.len());
    let k = data.len();
    let mut worst = 0.0f64;
    let (mut bad, mut first_bad) = (0usize, None);
    for (n, (crow, grow)) in c.chunks(k).zip(g.chunks(k)).enumerate() {
        for (j, (&cv, &gv)) in crow.iter().zip(grow).enumerate() {
            if !cv.is_finite() {
                return Err(format!(
                    "CPU value not finite: candidate {n} sample {j}: {cv}"
                ));
            }
            let err = (gv - cv).abs();
            let bound = rel * cv.abs() + FLOOR + extra.get(n * k + j).copied().unwrap_or(0.0);
            if err.is_nan() || err > bound {
                bad += 1;
                let s = &data.samples[j];
                first_bad.get_or_insert_with(|| format!(
                    "candidate {n} sample {j} (wi {:?} wo {:?} ch {}): {ENGINE} {gv} cpu {cv} (bound {bound:.3e}); params {:?}",
                    s.wi(),
                    s.wo(),
                    s.channel,
                    &params[n * model.dim..(n + 1) * model.dim]
                ));
            }
            if cv.abs() > 1e-12 {
                worst = worst.max(if err.is_nan() {
                    f64::INFINITY
                } else {
                    err / cv.abs()
                });
            }
        }
    }
    match first_bad {
        None => Ok(worst),
        Some(first) => Err(format!(
            "{bad} of {} values out of bound (worst relative error {worst:.2e}); first: {first}",
            c.len()
        )),
    }
}

#[test]
fn every_model_matches_the_cpu_reference() {
    let mut failures = Vec::new();
    for (kind, spec) in all_specs() {
        let channels = if kind == Kind::Brdf { 3 } else { 1 };
        for seed in [11u64, 12] {
            match compare_values(&spec, kind, channels, seed * 100) {
                Ok(worst) => eprintln!("{spec:<28} seed {seed}: worst relative error {worst:.2e}"),
                Err(e) => failures.push(format!("{spec} (seed {seed}): {e}")),
            }
        }
    }
    assert_no_failures(&failures);
}

/// The same data with every direction as an f32 engine receives it: its components
/// rounded to f32 (the angles recomputed from the rounded vector).
fn with_f32_directions(data: &Dataset) -> Dataset {
    let mut rounded = data.clone();
    let angles = |w: glam::DVec3| {
        let w = w.as_vec3().as_dvec3();
        (w.x.hypot(w.y).atan2(w.z.abs()), w.y.atan2(w.x))
    };
    for s in &mut rounded.samples {
        (s.theta_i, s.phi_i) = angles(s.wi());
        (s.theta_o, s.phi_o) = angles(s.wo());
    }
    rounded
}

/// Every model on a goniometric grid (directions shared by channels and by consecutive
/// records), NaN never passing. Bound per sample: REL · |cpu| + FLOOR as on random data,
/// plus twice what the f64 model itself moves when its directions are rounded to f32 as
/// an f32 engine receives them: no f32 engine can do better than its inputs. That term matters
/// only where a factor of the model crosses zero at the sample: on this grid, BTDF
/// samples at the edge of the refraction's validity (ωi·m → 0⁺, 1 + η ωi·ωo ≈ 0), where
/// rounding the directions alone changes f by 0.6 % (at values of 1e-14 sr⁻¹).
#[test]
fn every_model_matches_the_cpu_reference_on_a_goniometer_grid() {
    let mut failures = Vec::new();
    for (kind, spec) in all_specs() {
        let channels = if kind == Kind::Brdf { 3 } else { 1 };
        let data = grid_dataset(kind, channels, 21);
        match compare_with_f32_direction_allowance(&spec, &data, 22) {
            Ok(worst) => eprintln!("{spec:<28} grid: worst relative error {worst:.2e}"),
            Err(e) => failures.push(format!("{spec} (grid): {e}")),
        }
    }
    assert_no_failures(&failures);
}

/// [`compare_model_values_within`] at CANDIDATES random parameter vectors (seeded
/// `seed`), each value allowed, beyond REL · |cpu| + FLOOR, twice what the f64 model
/// moves when the directions are rounded to f32 as the tested engine receives them.
fn compare_with_f32_direction_allowance(spec: &str, data: &Dataset, seed: u64) -> Result<f64, String> {
    let model = Model::parse(spec, data.channel_count()).unwrap();
    let params = random_params(&model, CANDIDATES, seed);
    let loss = Loss::new(Metric::Chi2, Weights::Uniform);
    let cpu = CpuBackend::new();
    let values = |d: &Dataset| {
        cpu.prepare(Problem {
            model: &model,
            data: d,
            loss,
        })
        .unwrap()
        .values(&params)
        .unwrap()
    };
    let (exact, rounded) = (values(data), values(&with_f32_directions(data)));
    let inputs: Vec<f64> = exact
        .iter()
        .zip(&rounded)
        .map(|(a, b)| 2.0 * (a - b).abs())
        .collect();
    compare_model_values_within(&model, data, &params, REL, &inputs)
}

/// The costs of `engine` against the CPU reference's for the candidates `params`, each
/// within REL_COST relative (1e-12 absolute near 0); a line per failure, naming `what`.
fn compare_costs(engine: &dyn Backend, problem: Problem, params: &[f64], what: &str) -> Vec<String> {
    let c = CpuBackend::new().prepare(problem).unwrap().costs(params).unwrap();
    let g = engine.prepare(problem).unwrap().costs(params).unwrap();
    c.iter()
        .zip(&g)
        .enumerate()
        .filter(|(_, (cv, gv))| !(cv.is_finite() && (*gv - *cv).abs() <= REL_COST * cv.abs() + 1e-12))
        .map(|(n, (cv, gv))| format!("{what}: candidate {n}: {ENGINE} {gv} cpu {cv}"))
        .collect()
}

/// Sharp lobes at α = 0.002 on their peaks: GGX reflection (`ggx`, the lobe of
/// `fa(lambert)`) within 0.05° of the mirror direction and exactly on it, the `+retro`
/// and MRM lobes (with and without `+falloff`) within 0.05° of ωo = ωi and exactly on it. The f32 GGX must be written without
/// the cos²θh(α² − 1) + 1 cancellation (it alone costs up to 5 % there). Bound, per value:
/// |gpu − cpu| ≤ PEAK_REL · |cpu| with PEAK_REL = REL = 2e-3 (purely relative: every value
/// here is on a lobe); NaN never passes.
#[test]
fn small_alpha_peaks_match_the_cpu_reference() {
    const PEAK_REL: f64 = REL;
    // (spec, parameters, lobe peak: mirror or retro)
    let cases = [
        ("ggx", "ks=0.8,alpha=0.002,eta=1.5", false),
        (
            "fa(lambert)",
            "lobe.alpha=0.002,lobe.eta=1.5,lobe.ks=0.8,base.rho=0.5",
            false,
        ),
        ("lambert+retro", "rho=0.5,kr=0.3,alpha_r=0.002", true),
        (
            "lambert+mrm82+falloff",
            "rho=0.5,kr=0.7,f0=0.2,alpha_r=0.002,f82=0.3,q=2",
            true,
        ),
        (
            "lambert+mrm",
            "rho=0.5,kr=0.3,alpha_r=0.002,eta_r=2.5",
            true,
        ),
    ];
    // Offsets (Δθo, Δφo) in degrees from the peak: exactly on it, then within 0.05°.
    let offsets = [
        (0.0, 0.0),
        (0.01, 0.0),
        (-0.01, 0.0),
        (0.02, 0.0),
        (0.05, 0.0),
        (-0.05, 0.0),
        (0.0, 0.05),
        (0.0, -0.02),
        (0.03, 0.03),
    ];
    let mut failures = Vec::new();
    for (spec, assign, retro) in cases {
        let mut rows = Vec::new();
        for ti in [0.0, 1.0, 10.0, 30.0, 45.0, 60.0, 75.0, 85.0] {
            let phis: &[f64] = if ti == 0.0 {
                &[0.0]
            } else {
                &[0.0, 37.0, 123.0, 290.0]
            };
            for &phi_i in phis {
                for (dt, dp) in offsets {
                    if ti + dt == 0.0 && dp != 0.0 {
                        continue; // the pole has one azimuth
                    }
                    let phi_o = if retro { phi_i } else { phi_i + 180.0 };
                    rows.push((
                        rows.len() + 1,
                        RawRow {
                            theta_i: ti,
                            phi_i,
                            theta_o: ti + dt,
                            phi_o: phi_o + dp,
                            wavelength_nm: 550.0,
                            value: 1.0,
                            uncertainty: 0.01,
                        },
                    ));
                }
            }
        }
        let data = Dataset::from_rows(
            Kind::Brdf,
            "peaks",
            &rows,
            "<peaks>",
            &ReadOptions::default(),
        )
        .expect("valid peak data");
        let model = Model::parse(spec, 1).unwrap();
        let params = model.params_from_assignments(assign).unwrap();
        match compare_model_values(&model, &data, &params, PEAK_REL) {
            Ok(worst) => eprintln!("{spec:<28} α = 0.002 peaks: worst relative error {worst:.2e}"),
            Err(e) => failures.push(format!("{spec}: {e}")),
        }
    }
    assert!(
        failures.is_empty(),
        "small-α peak parity failures (bound {PEAK_REL:e} relative):\n{}",
        failures.join("\n")
    );
}

#[test]
fn every_loss_matches_the_cpu_reference() {
    let cases = [
        (Kind::Brdf, "fa(eon)", 3usize),
        (Kind::Brdf, "on", 3),
        (Kind::Btdf, "btdf(tr)+scale", 1),
    ];
    let mut failures = Vec::new();
    for (kind, spec, channels) in cases {
        let data = random_dataset(kind, channels, 300, 5);
        let model = Model::parse(spec, channels).unwrap();
        let params = random_params(&model, 40, 6);
        for metric in [
            Metric::Smape,
            Metric::Rmse,
            Metric::Ngan,
            Metric::Low,
            Metric::F,
            Metric::Cosf,
            Metric::Logf,
            Metric::Logcosf,
            Metric::Chi2,
        ] {
            for weights in [Weights::Uniform, Weights::Relunc, Weights::Invunc] {
                let loss = Loss::new(metric, weights);
                let problem = Problem {
                    model: &model,
                    data: &data,
                    loss,
                };
                let what = format!("{spec} {loss}");
                failures.extend(compare_costs(tested(), problem, &params, &what));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "loss parity failures:\n{}",
        failures.join("\n")
    );
}

