//! Many fits per dispatch: an evaluator holding several independent problems (different
//! data sets, sizes, weightings, and losses of one term shape, each finished its own
//! way) gives each candidate exactly what a one-problem
//! evaluator gives it, on both backends, and `fit_many` finds the same optima as fitting
//! the problems one at a time.
//!
//! Tolerances: the CPU backend is the same f64 arithmetic either way, so its batched and
//! one-at-a-time results agree to 1e-12 relative; the GPU (f32) is compared with the f32
//! bound of the parity tests, 2e-3 relative per value (f32 roundoff 6e-8 amplified by the
//! models' transcendental chains), 1e-3 per cost. NaN never passes.

mod common;

use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::wgsl::Shape;
use bsdfit::engine::{Backend, Problem};
use bsdfit::inference::fit::{fit_many, fit_outcome, FitOptions, Optimizer};
use common::synth_geometry;

fn close(a: f64, b: f64, rel: f64) -> bool {
    a.is_finite() && b.is_finite() && (a - b).abs() <= rel * a.abs().max(b.abs()) + 1e-30
}

/// Three ggx data sets of different sizes and noise, the third weighted differently.
fn three_problems() -> (bsdfit::bsdf::Model, Vec<bsdfit::data::Dataset>) {
    let (model, _, a) = synth_geometry(
        "ggx",
        "ks=0.8,alpha=0.3,eta=1.5",
        "inplane10",
        &[550.0],
        (0.02, 1e-4),
        1,
    );
    let (_, _, b) = synth_geometry(
        "ggx",
        "ks=0.6,alpha=0.15,eta=1.8",
        "hemi",
        &[550.0],
        (0.01, 1e-4),
        2,
    );
    let (_, _, c) = synth_geometry(
        "ggx",
        "ks=0.9,alpha=0.5,eta=1.3",
        "inplane10",
        &[550.0],
        (0.05, 1e-3),
        3,
    );
    (model, vec![a, b, c])
}

fn check_mixed_batch(backend: &dyn Backend, rel_value: f64, rel_cost: f64) {
    let (model, data) = three_problems();
    // Three square-term losses with the three finishes: sqrt(Σ/K), Σ and Σ/K.
    let losses = [
        Loss::new(Metric::Rmse, Weights::Uniform),
        Loss::new(Metric::Chi2, Weights::Uniform),
        Loss::new(Metric::Ngan, Weights::Relunc),
    ];
    let problems: Vec<Problem> = data
        .iter()
        .zip(losses)
        .map(|(d, loss)| Problem {
            model: &model,
            data: d,
            loss,
        })
        .collect();
    // Candidates interleaved over the problems, in no particular order; then runs of one
    // problem long enough to fill a SIMD group of lanes (a subgroup tile of lavapipe's
    // 8 lanes sees one problem), and a tail that leaves lanes idle.
    let owners = [
        2usize, 0, 1, 1, 2, 0, 0, 2, 1, 1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 2, 2, 2,
    ];
    let params: Vec<f64> = (0..owners.len())
        .flat_map(|i| {
            let u: Vec<f64> = (0..model.dim)
                .map(|j| ((i * 7 + j * 3) % 10) as f64 / 10.0 + 0.05)
                .collect();
            model.from_unit(&u)
        })
        .collect();
    let mut many = backend.prepare_many(&problems).unwrap();
    assert_eq!(many.problems(), 3);
    let costs = many.costs_of(&owners, &params).unwrap();
    let values = many.values_of(&owners, &params).unwrap();
    let mut at = 0;
    for (i, &q) in owners.iter().enumerate() {
        let flat = &params[i * model.dim..(i + 1) * model.dim];
        let mut one = backend.prepare(problems[q]).unwrap();
        let c1 = one.costs(flat).unwrap()[0];
        let v1 = one.values(flat).unwrap();
        assert!(
            close(costs[i], c1, rel_cost),
            "{}: candidate {i} (problem {q}) cost {} alone {c1}",
            backend.id(),
            costs[i]
        );
        let k = data[q].len();
        assert_eq!(many.samples_of(q), k);
        for (j, (&a, &b)) in values[at..at + k].iter().zip(&v1).enumerate() {
            assert!(
                close(a, b, rel_value),
                "{}: candidate {i} (problem {q}) sample {j}: {a} alone {b}",
                backend.id()
            );
        }
        at += k;
    }
    assert_eq!(at, values.len(), "one row of K_q values per candidate");
}

#[test]
fn a_mixed_batch_gives_each_candidate_its_own_problem_cpu() {
    check_mixed_batch(&CpuBackend::new(), 1e-12, 1e-12);
}

#[test]
fn a_mixed_batch_gives_each_candidate_its_own_problem_gpu() {
    for shape in Shape::ALL {
        let gpu = GpuBackend::new()
            .expect("a Vulkan adapter (lavapipe in CI)")
            .with_shape(shape);
        check_mixed_batch(&gpu, 2e-3, 1e-3);
    }
}

#[test]
fn problems_of_different_models_or_loss_terms_are_refused() {
    let (model, data) = three_problems();
    let other = bsdfit::bsdf::Model::parse("lambert", 1).unwrap();
    let cpu = CpuBackend::new();
    let chi2 = Loss::new(Metric::Chi2, Weights::Uniform);
    let smape = Loss::new(Metric::Smape, Weights::Uniform);
    let p = |model, data, loss| Problem { model, data, loss };
    let err = cpu
        .prepare_many(&[p(&model, &data[0], chi2), p(&other, &data[1], chi2)])
        .err()
        .expect("different models refused");
    assert!(err.to_string().contains("share one model"), "{err}");
    let err = cpu
        .prepare_many(&[p(&model, &data[0], chi2), p(&model, &data[1], smape)])
        .err()
        .expect("different term shapes refused");
    assert!(
        err.to_string().contains("share one loss term shape"),
        "{err}"
    );
}

/// Lockstep fitting of all problems finds each problem's own optimum: the same loss as a
/// fit of that problem alone (same seed and starts), for compass and LM, on both backends,
/// with the problems' losses mixed as a sweep's stage mixes them (χ² and RMSE).
fn check_fit_many(backend: &dyn Backend, optimizer: Optimizer, rel: f64) {
    let (model, data) = three_problems();
    let chi2 = Loss::new(Metric::Chi2, Weights::Uniform);
    let losses = [chi2, Loss::new(Metric::Rmse, Weights::Uniform), chi2];
    let opts = FitOptions {
        optimizer,
        restarts: 4,
        ..Default::default()
    };
    let refs: Vec<&bsdfit::data::Dataset> = data.iter().collect();
    let (optima, _, stats) = fit_many(&model, &refs, &losses, backend, &opts, &mut |_| {}).unwrap();
    assert_eq!(optima.len(), 3);
    assert_eq!(stats.batches, 1, "three small problems share one evaluator");
    for (q, (d, &loss)) in data.iter().zip(&losses).enumerate() {
        let alone = fit_outcome(&model, d, loss, backend, &opts, &mut |_| {}).unwrap();
        assert!(
            close(optima[q].loss, alone.loss, rel),
            "{} {optimizer}: problem {q} batched loss {} alone {}",
            backend.id(),
            optima[q].loss,
            alone.loss
        );
        // χ²/N near 1 means each problem was fitted to its own data.
        if loss.metric == Metric::Chi2 {
            let red = optima[q].loss / d.len() as f64;
            assert!(red < 2.0, "problem {q}: χ²/N = {red}");
        }
    }
}

#[test]
fn fit_many_matches_fits_one_at_a_time_cpu() {
    check_fit_many(&CpuBackend::new(), Optimizer::Lm, 1e-9);
    check_fit_many(&CpuBackend::new(), Optimizer::Compass, 1e-9);
}

#[test]
fn fit_many_matches_fits_one_at_a_time_gpu() {
    let gpu = GpuBackend::new().expect("a Vulkan adapter (lavapipe in CI)");
    // f32 optimizers can stop at slightly different points: 1e-3 of χ² is far below the
    // χ² noise (√(2N) ≈ 20 of ~200).
    check_fit_many(&gpu, Optimizer::Lm, 1e-3);
}
