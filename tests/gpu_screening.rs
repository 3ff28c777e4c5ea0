//! LM's start screening ranks random points by the shape of their model values
//! (`LossTerms::rescaled_sum_squares`), not by raw Σr².
//!
//! The case: the bundled long-tailed diffuser under `btdf(gg)+absorb`, `f` loss. Much of
//! its box (strong absorption, near-specular GG lobes with a large exponent) gives a model
//! ≈ 0 at every sample, and raw Σr² = Σy² there beats any point that overshoots. With seed
//! 2, ranked by raw Σr², the f32 engine's eight restarts all started on that plateau, where
//! its Jacobian is exactly 0, and the fit ended at Σy²: a loss of 22.2 against the optimum's
//! 0.0151, 1,500× above it (the CPU reference escaped from one start in eight).

use bsdfit::bsdf::Model;
use bsdfit::data::{bundled_data_dir, Dataset, ReadOptions};
use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::Backend;
use bsdfit::inference::fit::{fit, FitOptions, Optimizer};

#[test]
fn lm_starts_off_the_dead_plateau_of_an_absorbing_btdf() {
    let gpu = GpuBackend::new().expect("a Vulkan adapter (lavapipe in CI)");
    let data = Dataset::read(
        &bundled_data_dir().join("diffuser-b.csv"),
        &ReadOptions::default(),
    )
    .unwrap();
    let model = Model::for_data("btdf(gg)+absorb", &data).unwrap();
    let loss = Loss::new(Metric::F, Weights::Uniform);
    let opts = FitOptions {
        optimizer: Optimizer::Lm,
        restarts: 8,
        seed: 2,
        ..Default::default()
    };
    let backends: [&dyn Backend; 2] = [&CpuBackend::new(), &gpu];
    let losses: Vec<f64> = backends
        .iter()
        .map(|b| {
            let rep = fit(&model, &data, loss, *b, &opts, &mut |_| {}).unwrap();
            eprintln!(
                "{}: loss {:.6e}, {} of 8 restarts within 1 %",
                rep.backend, rep.best.loss, rep.restarts_within_1pct
            );
            rep.best.loss
        })
        .collect();
    // Both reach the optimum: within the 1e-3 stated for comparing f32 and f64 searches
    // (here 2.4e-10 apart; from the plateau the GPU ended 1.5e3 above).
    let rel = (losses[1] - losses[0]).abs() / losses[0];
    assert!(
        losses.iter().all(|l| l.is_finite()) && rel < 1e-3,
        "cpu {} gpu {} (relative {rel:.2e})",
        losses[0],
        losses[1]
    );
}
