//! Levenberg–Marquardt on the f32 GPU engine ends with an f64 polish of each problem's
//! best restart on the CPU reference, so that its optima are f64 optima.
//!
//! The cases are bundled diffuser measurements whose transmission lobes make roughness,
//! scale and refractive index nearly collinear (a long, narrow χ² valley). There the f32
//! search's forward differences (unit-box steps ≈ 1e-3) tilt the Gauss–Newton step and it
//! stalls 6–10 % above the optimum the f64 reference reaches from the same starts; the
//! polish must carry it the rest of the way. The fits' conclusions (χ², standard
//! uncertainties) are f64 too, whichever backend searched.

use bsdfit::bsdf::Model;
use bsdfit::data::{bundled_data_dir, Dataset, ReadOptions};
use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::Backend;
use bsdfit::inference::fit::{fit, FitOptions, FitReport, Optimizer};

fn fit_on(backend: &dyn Backend, file: &str, spec: &str, loss: Loss) -> FitReport {
    let data = Dataset::read(&bundled_data_dir().join(file), &ReadOptions::default()).unwrap();
    let model = Model::for_data(spec, &data).unwrap();
    // 8 restarts (the sweep's default when this test was written), seed 1.
    let opts = FitOptions {
        optimizer: Optimizer::Lm,
        restarts: 8,
        seed: 1,
        ..Default::default()
    };
    fit(&model, &data, loss, backend, &opts, &mut |_| {}).unwrap()
}

#[test]
fn gpu_lm_reaches_the_f64_optimum_in_a_narrow_valley() {
    let gpu = GpuBackend::new().expect("a Vulkan adapter (lavapipe in CI)");
    let cpu = CpuBackend::new();
    for (file, spec, loss) in [
        (
            "diffuser-d.csv",
            "btdf(tr)+scale+peraxis",
            Loss::new(Metric::Chi2, Weights::Uniform),
        ),
        (
            "diffuser-a.csv",
            "btdf(tr)+scale",
            Loss::new(Metric::F, Weights::Invunc),
        ),
    ] {
        let (c, g) = (
            fit_on(&cpu, file, spec, loss),
            fit_on(&gpu, file, spec, loss),
        );
        assert!(
            c.best.loss.is_finite() && g.best.loss.is_finite(),
            "{file} {spec}"
        );
        // Both are f64 LM optima from the same starts: they agree to LM's f64
        // convergence, far inside the 1e-3 stated for f32 searches.
        let rel = (g.best.loss - c.best.loss).abs() / c.best.loss;
        assert!(
            rel < 1e-6,
            "{file} {spec}: gpu {} cpu {} (relative {rel:.2e})",
            g.best.loss,
            c.best.loss
        );
        for (name, (a, b)) in c
            .flat_names
            .iter()
            .zip(c.flat_params.iter().zip(&g.flat_params))
        {
            assert!(
                (a - b).abs() <= 1e-3 * a.abs().max(1e-3),
                "{file} {spec}: {name} cpu {a} gpu {b}"
            );
        }
        // χ² and the standard uncertainties are computed in f64 on the CPU for both fits.
        // Where χ² is the loss it is stationary at the optimum, so optima 1e-6 apart in
        // loss give χ²_red and uncertainties that agree to ~1e-6 (measured 7.6e-6 and
        // 1.2e-6); computed from the f32 engine's central differences, the uncertainties
        // differed by up to 3.2e-4 (η on diffuser-d), above the 1e-4 bound. Where another
        // loss is fitted, χ²_red and the uncertainties change to first order along the
        // valley: two f64 LM runs that stop 2.7e-9 apart in `f` (both by ftol, their steps
        // down to the forward differences' resolution) are 3e-5 apart in the scale and
        // 1.4e-4 apart in χ²_red; the bound is then the search's loss tolerance, 1e-3.
        let conclusion_tol = if loss.metric == Metric::Chi2 {
            1e-4
        } else {
            1e-3
        };
        let rel = (g.best.chi2_red - c.best.chi2_red).abs() / c.best.chi2_red;
        assert!(
            rel < conclusion_tol,
            "{file} {spec}: χ²_red relative difference {rel:.2e}"
        );
        for (name, (a, b)) in c.flat_names.iter().zip(c.flat_std.iter().zip(&g.flat_std)) {
            let (a, b) = (a.expect("determined"), b.expect("determined"));
            assert!(
                (a - b).abs() <= conclusion_tol * a,
                "{file} {spec}: standard uncertainty of {name}: cpu {a} gpu {b}"
            );
        }
    }
}
