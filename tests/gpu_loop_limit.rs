//! Mesa's llvmpipe (lavapipe, the CI's Vulkan device) ends every loop of a shader
//! invocation once all of its loops together have run 65,535 iterations, silently. A
//! thread of the evaluation kernel walks all samples of its candidate, so a large data set
//! would come back as a partial sum that looks complete. The kernels detect it
//! (`loops_completed` in shaders/engine/kernel.wgsl) and the engine then fails with an
//! error that names the cause. On any device, a batch either matches the CPU reference or
//! fails that way: never a silently wrong number.
//!
//! Tolerance: costs within 1e-3 relative of the f64 reference (f32 compensated sums over
//! 70,000 terms; see tests/gpu_accuracy.rs); NaN never passes.

use bsdfit::bsdf::Model;
use bsdfit::data::{Dataset, Kind, RawRow, ReadOptions};
use bsdfit::engine::cpu::CpuBackend;
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Weights};
use bsdfit::engine::wgsl::Shape;
use bsdfit::engine::{Backend, Problem};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn large_dataset(n: usize) -> Dataset {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let rows: Vec<(usize, RawRow)> = (0..n)
        .map(|i| {
            let value: f64 = rng.random_range(0.05..0.5);
            (
                i + 1,
                RawRow {
                    theta_i: rng.random_range(0.0..80.0),
                    phi_i: rng.random_range(0.0..360.0),
                    theta_o: rng.random_range(0.0..80.0),
                    phi_o: rng.random_range(0.0..360.0),
                    wavelength_nm: 550.0,
                    value,
                    uncertainty: 0.02 * value,
                },
            )
        })
        .collect();
    Dataset::from_rows(
        Kind::Brdf,
        "large",
        &rows,
        "<large>",
        &ReadOptions::default(),
    )
    .expect("valid data")
}

#[test]
fn a_loop_limit_fails_loudly_or_the_costs_are_right() {
    // 70,000 samples in one thread: past llvmpipe's 65,535 iterations on lavapipe.
    let data = large_dataset(70_000);
    let model = Model::parse("lambert", 1).unwrap();
    let loss = Loss::new(Metric::Chi2, Weights::Uniform);
    let params: Vec<f64> = [0.1, 0.2, 0.3, 0.15].to_vec();
    let problem = Problem {
        model: &model,
        data: &data,
        loss,
    };
    let reference = CpuBackend::new()
        .prepare(problem)
        .unwrap()
        .costs(&params)
        .unwrap();
    for shape in [
        Shape::CPU_DEVICE,
        Shape::CPU_DEVICE_TILED,
        Shape::GPU_DEVICE,
    ] {
        let gpu = GpuBackend::new()
            .expect("a Vulkan adapter (lavapipe in CI)")
            .with_shape(shape);
        let lavapipe = gpu.adapter_name().contains("llvmpipe");
        let mut ev = gpu.prepare(problem).unwrap();
        let costs = ev.costs(&params);
        let values = ev.values(&params);
        // The GPU shape splits each candidate's samples over 8 slices: 8,750 per thread,
        // within the limit even on lavapipe.
        let must_fit = !lavapipe || shape == Shape::GPU_DEVICE;
        for (what, outcome) in [("costs", costs.map(Some)), ("values", values.map(|_| None))] {
            match outcome {
                Ok(Some(costs)) => {
                    for (a, b) in costs.iter().zip(&reference) {
                        assert!(
                            (a - b).abs() <= 1e-3 * b.abs(),
                            "{shape:?}: cost {a} against the reference {b}"
                        );
                    }
                    assert!(
                        must_fit,
                        "{shape:?}: lavapipe should have cut the loops short"
                    );
                }
                Ok(None) => assert!(
                    must_fit,
                    "{shape:?}: lavapipe should have cut the {what} loops short"
                ),
                Err(e) => {
                    assert!(!must_fit, "{shape:?} {what}: {e}");
                    let msg = e.to_string();
                    assert!(
                        msg.contains("65,535") && msg.contains("--backend cpu"),
                        "{shape:?} {what}: unclear error: {msg}"
                    );
                }
            }
        }
    }
}
