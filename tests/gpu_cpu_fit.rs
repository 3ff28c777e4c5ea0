//! The same fit on both backends (issue 3): `fa(lambert)` on synthetic glossy data with the
//! same seed reaches the same best loss within 1% on the GPU engine (f32, lavapipe in CI)
//! and the CPU reference (f64), and the same parameters within their uncertainties.

mod common;

use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::inference::fit::{fit, FitOptions};
use common::synth_geometry;

#[test]
fn fa_lambert_reaches_the_same_optimum_on_gpu_and_cpu() {
    let (model, _, data) = synth_geometry(
        "fa(lambert)",
        "lobe.alpha=0.12,lobe.eta=1.6,lobe.ks=0.9,base.rho=0.15:0.35:0.55",
        "specular",
        &[450.0, 550.0, 650.0],
        (0.015, 1e-4),
        17,
    );
    let gpu = GpuBackend::new().expect("a Vulkan adapter (CI installs lavapipe)");
    let opts = FitOptions {
        restarts: 8,
        seed: 4,
        ..Default::default()
    };
    for loss in [
        Loss::new(Metric::Rmse, Weights::Uniform),
        Loss::new(Metric::Smape, Weights::Relunc),
    ] {
        let c = fit(&model, &data, loss, &CpuBackend::new(), &opts, &mut |_| {}).unwrap();
        let g = fit(&model, &data, loss, &gpu, &opts, &mut |_| {}).unwrap();
        let rel = (g.best.loss - c.best.loss).abs() / c.best.loss;
        assert!(
            c.best.loss.is_finite() && rel < 0.01,
            "{loss}: gpu {} vs cpu {}",
            g.best.loss,
            c.best.loss
        );
        for (i, name) in c.flat_names.iter().enumerate() {
            let tol = 3.0 * c.flat_std[i].unwrap_or(0.0) + 1e-3 * c.flat_params[i].abs().max(1e-3);
            assert!(
                (g.flat_params[i] - c.flat_params[i]).abs() <= tol,
                "{loss} {name}: gpu {} vs cpu {}",
                g.flat_params[i],
                c.flat_params[i]
            );
        }
    }
}
