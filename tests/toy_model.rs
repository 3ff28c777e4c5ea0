//! A model is three touches: its Rust file, its WGSL twin and one registry line. The toy
//! model of `tests/toy_model/` (Minnaert's law) is registered at run time by this test —
//! nothing in the library names it — and it then flows through everything a built-in
//! model does: the catalogue and `models` listing, synthesis, fits on the CPU reference
//! and the GPU engine (parameters back within the noise), a sweep with its report,
//! diagnose (which wraps it in the Fresnel aggregate to add a hidden specular lobe),
//! eval with propagated uncertainties, and the MERL and RGL exports (read back).

#[path = "toy_model/minnaert.rs"]
mod minnaert;

use bsdfit::bsdf::{self, Model};
use bsdfit::data::readers;
use bsdfit::data::{Dataset, Kind, ReadOptions};
use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::simd::SimdBackend;
use bsdfit::engine::{Backend, Problem};
use bsdfit::inference::fit::{fit, FitOptions, FitReport};
use bsdfit::inference::saved::FitFile;
use bsdfit::workflows::diagnose::{self, DiagnoseOptions, Effect};
use bsdfit::workflows::export;
use bsdfit::workflows::rgl;
use bsdfit::workflows::sweep::{self, Selection, SweepConfig, SweepObserver};
use bsdfit::workflows::synth::{geometry_expr, synthesize, Noise};
use rand::{Rng, SeedableRng};

/// The one registry line (idempotent: every test calls it).
fn register() {
    bsdf::registry::register(&minnaert::ENTRY).expect("the toy's name is new");
}

const WAVELENGTHS: [f64; 3] = [450.0, 550.0, 650.0];
/// 2 % relative noise plus a small absolute floor, as a goniometer's.
const NOISE: Noise = Noise {
    rel: 0.02,
    abs: 1e-4,
};

/// Data synthesized from `spec` at `params` on `geometry_name`, with [`NOISE`].
fn synth(spec: &str, params: &str, geometry_name: &str, seed: u64) -> (Model, Vec<f64>, Dataset) {
    let model = Model::parse(spec, WAVELENGTHS.len()).expect("the toy parses once registered");
    let flat = model.params_from_assignments(params).unwrap();
    let (_, rows) = geometry_expr(geometry_name).unwrap();
    let data = synthesize(&model, &flat, &rows, &WAVELENGTHS, NOISE, seed, "toy").unwrap();
    (model, flat, data)
}

fn chi2() -> Loss {
    Loss::new(Metric::Chi2, Weights::Uniform)
}

fn fit_on(model: &Model, data: &Dataset, backend: &dyn Backend) -> FitReport {
    let opts = FitOptions {
        restarts: 8,
        seed: 2,
        ..Default::default()
    };
    fit(model, data, chi2(), backend, &opts, &mut |_| {}).unwrap()
}

/// Every fitted parameter within 4 standard uncertainties of the truth, and χ²_red
/// near 1 (the noise is what the uncertainties say).
fn assert_recovered(r: &FitReport, truth: &[f64], backend: &str) {
    assert!(
        (0.7..1.4).contains(&r.best.chi2_red),
        "{backend}: χ²_red {}",
        r.best.chi2_red
    );
    for (i, name) in r.flat_names.iter().enumerate() {
        let sd = r.flat_std[i].expect("every parameter is determined");
        let z = (r.flat_params[i] - truth[i]) / sd;
        assert!(
            z.abs() < 4.0,
            "{backend}: {name} = {} ± {sd}, truth {} (z = {z:.1})",
            r.flat_params[i],
            truth[i]
        );
    }
}

#[test]
fn the_toy_model_is_in_the_catalogue_and_fits_on_every_backend() {
    register();
    // Declared a diffuse base: the catalogue puts it alone and under every layer.
    let brdf = bsdf::catalogue(Kind::Brdf);
    for spec in ["minnaert", "fa(minnaert)", "dmg(minnaert)", "rmg(minnaert)"] {
        assert!(brdf.iter().any(|s| s == spec), "{spec} not in {brdf:?}");
    }
    assert!(!bsdf::catalogue(Kind::Btdf)
        .iter()
        .any(|s| s.contains("minnaert")));
    assert_eq!(bsdf::spec_kind("fa(minnaert)").unwrap(), Kind::Brdf);

    let (model, truth, data) = synth("minnaert", "rho=0.2:0.4:0.6,k=0.8", "hemi", 5);
    let cpu = fit_on(&model, &data, &CpuBackend::new());
    assert_recovered(&cpu, &truth, "cpu");
    let gpu = GpuBackend::new().expect("a Vulkan adapter (CI installs lavapipe)");
    // The SIMD engine runs the toy without a fourth touch: it has no kernel, so its
    // lanes go through its f64 `eval`.
    let simd = SimdBackend::new();
    for (id, backend) in [("gpu", &gpu as &dyn Backend), ("simd", &simd)] {
        let other = fit_on(&model, &data, backend);
        assert_recovered(&other, &truth, id);
        // The backends find the same optimum: f32 evaluations, then an f64 polish.
        for (i, name) in cpu.flat_names.iter().enumerate() {
            let sd = cpu.flat_std[i].unwrap();
            let d = (other.flat_params[i] - cpu.flat_params[i]).abs();
            assert!(
                d < 0.01 * sd,
                "{name}: {id} {} vs cpu {}",
                other.flat_params[i],
                cpu.flat_params[i]
            );
        }
    }

    // A nested model: the toy under the Fresnel aggregate's lobe (a kernel above a node
    // without one, on the SIMD engine).
    let params = "base.rho=0.2:0.4:0.6,base.k=1.3,lobe.alpha=0.15,lobe.eta=1.5,lobe.ks=0.7";
    let (model, truth, data) = synth("fa(minnaert)", params, "specular+offplane", 6);
    assert_eq!(model.nodes_without_kernel(), ["minnaert"]);
    let r = fit_on(&model, &data, &CpuBackend::new());
    assert_recovered(&r, &truth, "cpu, fa(minnaert)");
    let r = fit_on(&model, &data, &simd);
    assert_recovered(&r, &truth, "simd, fa(minnaert)");
}

/// The toy's twins agree: GPU (f32, its WGSL) against CPU (f64, its Rust) model values at
/// random parameters of its whole box and random directions up to 85°, alone and under
/// `fa`. Per value |gpu − cpu| ≤ 2e-3·|cpu| + 1e-30 (the bound of `tests/gpu_parity.rs`:
/// a few ulp of f32 per operation over a chain of pow/exp; the floor is f32's range), and
/// NaN never passes.
#[test]
fn the_toy_models_wgsl_twin_matches_its_rust() {
    register();
    let gpu = GpuBackend::new().expect("a Vulkan adapter (CI installs lavapipe)");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let rows: Vec<[f64; 4]> = (0..300)
        .map(|_| {
            [
                rng.random_range(0.0..85.0),
                rng.random_range(0.0..360.0),
                rng.random_range(0.0..85.0),
                rng.random_range(0.0..360.0),
            ]
        })
        .collect();
    for spec in ["minnaert", "fa(minnaert)"] {
        let model = Model::parse(spec, WAVELENGTHS.len()).unwrap();
        let data = synthesize(
            &model,
            &model.defaults(),
            &rows,
            &WAVELENGTHS,
            NOISE,
            3,
            "toy",
        )
        .unwrap();
        let params: Vec<f64> = (0..12)
            .flat_map(|_| {
                let u: Vec<f64> = (0..model.dim).map(|_| rng.random::<f64>()).collect();
                model.from_unit(&u)
            })
            .collect();
        let problem = Problem {
            model: &model,
            data: &data,
            loss: chi2(),
        };
        let c = CpuBackend::new()
            .prepare(problem)
            .unwrap()
            .values(&params)
            .unwrap();
        let g = gpu.prepare(problem).unwrap().values(&params).unwrap();
        assert_eq!(c.len(), g.len());
        for (i, (&cv, &gv)) in c.iter().zip(&g).enumerate() {
            assert!(cv.is_finite(), "{spec}: CPU value {i} is {cv}");
            let err = (gv - cv).abs();
            assert!(
                err <= 2e-3 * cv.abs() + 1e-30,
                "{spec}: value {i}: gpu {gv} cpu {cv}"
            );
        }
    }
}

/// Quiet sweep progress.
struct Quiet;
impl SweepObserver for Quiet {
    fn note(&mut self, _: &str) {}
    fn begin(&mut self, _: u64, _: u64) {}
    fn alert(&mut self, line: &str) {
        panic!("a sweep fit warned or failed: {line}");
    }
    fn fit_ended(&mut self, _: &str) {}
    fn end(&mut self) {}
}

#[test]
fn the_toy_model_is_swept_with_its_report() {
    register();
    let dir = tempfile::tempdir().unwrap();
    let (_, _, data) = synth("minnaert", "rho=0.2:0.4:0.6,k=1.2", "hemi", 7);
    let csv = dir.path().join("toy.csv");
    data.write(&csv).unwrap();
    let models = ["minnaert", "fa(minnaert)", "lambert"];
    let cfg = SweepConfig {
        data: vec![csv],
        selection: Selection {
            models: Some(models.iter().map(|s| s.to_string()).collect()),
            ..SweepConfig::default().selection
        },
        restarts: 4,
        backend: bsdfit::engine::BackendChoice::Cpu,
        out: dir.path().join("out"),
        ..SweepConfig::default()
    };
    let stats = sweep::run(&cfg, &mut Quiet).unwrap();
    // Each model under RMSE (uniform and relative-uncertainty weights) and χ².
    assert_eq!(stats.new_fits, models.len() * 3);
    let text = std::fs::read_to_string(cfg.out.join("results.csv")).unwrap();
    let mut rows = csv::Reader::from_reader(text.as_bytes());
    let header = rows.headers().unwrap().clone();
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let chi2_red = |model: &str| -> f64 {
        csv::Reader::from_reader(text.as_bytes())
            .records()
            .map(|r| r.unwrap())
            .find(|r| &r[col("model")] == model && &r[col("loss")] == "chi2")
            .unwrap_or_else(|| panic!("no χ² row of {model}"))[col("chi2_red")]
        .parse()
        .unwrap()
    };
    // The truth fits the noise; Lambert (k = 1) cannot follow k = 1.2.
    assert!(chi2_red("minnaert") < 1.4, "{}", chi2_red("minnaert"));
    assert!(chi2_red("lambert") > 3.0 * chi2_red("minnaert"));
    let report = std::fs::read_to_string(cfg.out.join("report.html")).unwrap();
    assert!(report.contains("fa(minnaert)"));
}

#[test]
fn diagnose_wraps_the_toy_model_to_add_a_hidden_specular_lobe() {
    register();
    let params = "base.rho=0.3:0.4:0.5,base.k=0.9,lobe.alpha=0.1,lobe.eta=1.5,lobe.ks=0.8";
    let (_, _, data) = synth("fa(minnaert)", params, "specular+offplane", 8);
    // The candidates come from the declarations: fa, dmg and rmg accept diffuse bases.
    let candidates = diagnose::extensions("minnaert", &data).unwrap();
    let specs: Vec<(&str, Effect)> = candidates
        .iter()
        .map(|c| (c.spec.as_str(), c.effect))
        .collect();
    for want in [
        ("fa(minnaert)", Effect::SpecularLobe),
        ("minnaert+coat", Effect::SpecularLobe),
        ("dmg(minnaert)", Effect::GrazingDecay),
        ("rmg(minnaert)", Effect::GrazingDecay),
    ] {
        assert!(specs.contains(&want), "{want:?} not in {specs:?}");
    }
    let opts = DiagnoseOptions {
        loss: chi2(),
        restarts: 8,
        ..Default::default()
    };
    let d = diagnose::diagnose(&data, "minnaert", &CpuBackend::new(), &opts, &mut |_| {}).unwrap();
    assert_eq!(d.effects, vec![Effect::SpecularLobe], "{:?}", d.steps.len());
    assert_eq!(d.final_model, "fa(minnaert)");
}

#[test]
fn the_toy_fit_is_evaluated_and_exported() {
    register();
    let (model, truth, data) = synth("minnaert", "rho=0.2:0.4:0.6,k=0.8", "hemi", 9);
    let report = fit_on(&model, &data, &CpuBackend::new());
    let json = serde_json::to_string(&report).unwrap();
    let file = FitFile::parse(&json, "toy.json").unwrap();

    // eval: the fit's values at the data's geometries, with propagated uncertainties
    // small against the noise of one sample (the fit averages hundreds).
    let p = export::predict(&file, "toy.json", &data, "the data").unwrap();
    let fitted = bsdfit::inference::saved::SavedFit::from_value(
        &serde_json::to_value(&report).unwrap(),
        "toy.json",
    )
    .unwrap();
    for (s, e) in p.data.samples.iter().zip(&data.samples) {
        let g = fitted.channel_of(e.wavelength_nm).unwrap();
        let truth_f = model.eval(&truth, g, e.wi(), e.wo());
        let u = s.uncertainty;
        assert!(s.value.is_finite() && u.is_finite() && u >= 0.0);
        assert!(
            (s.value - truth_f).abs() < 4.0 * u + 0.01 * truth_f,
            "eval {} ± {u} vs truth {truth_f}",
            s.value
        );
        assert!(
            u < e.uncertainty,
            "propagated {u} vs measured {}",
            e.uncertainty
        );
    }

    // MERL: a full table, finite.
    let rgb = export::rgb_channels(&fitted, None).unwrap();
    let merl = export::merl_table(&fitted, rgb).unwrap();
    assert!(merl.len() > 1_000_000);

    // RGL .bsdf: written, read back at a hemisphere geometry, equal to the fit.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("toy.bsdf");
    std::fs::write(
        &path,
        rgl::rgl_file(&fitted, rgl::Channels::Rgb(rgb), "toy").unwrap(),
    )
    .unwrap();
    let opts = ReadOptions {
        assume_uncertainty: Some((0.01, 1e-6)),
        sample_geometry: Some("hemi".into()),
        ..Default::default()
    };
    let back = readers::load(&path, &opts).unwrap();
    let mut rel: Vec<f64> = back
        .samples
        .iter()
        .map(|s| {
            let g = fitted.channel_of(s.wavelength_nm).unwrap();
            let f = model.eval(&fitted.flat, g, s.wi(), s.wo());
            (s.value - f).abs() / f
        })
        .collect();
    rel.sort_by(f64::total_cmp);
    let median = rel[rel.len() / 2];
    assert!(
        median < 0.01,
        "RGL read-back: median relative error {median}"
    );
}
