//! Mesa's llvmpipe (lavapipe, the CI's Vulkan device) ends every loop of a shader
//! invocation once all of its loops together have run 65,535 iterations, silently. A
//! thread of the one-slice evaluation kernel walks all samples of its candidate, so a
//! large data set came back as a partial sum that looked complete (70,000 lambert samples:
//! 6 % short). The kernels now detect it (`loops_completed` in shaders/engine/kernel.wgsl);
//! the engine then moves to a kernel that splits each candidate's samples over 32 threads,
//! and fails with an error naming the cause only where that is cut short too (for a
//! loop-free model that takes more samples than fit one binding; a model with loops of its
//! own gets there sooner, not within this test's 150,000 samples on lavapipe). On any
//! device a batch either matches the CPU reference or fails that way: never a silently
//! wrong number.
//!
//! Tolerance: costs within 1e-3 relative of the f64 reference (f32 compensated sums over
//! up to 1e5 terms, tests/gpu_accuracy.rs), values within 2e-3 relative per sample (the
//! parity tests' bound); NaN never passes.

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

fn close(a: f64, b: f64, rel: f64) -> bool {
    a.is_finite() && (a - b).abs() <= rel * b.abs()
}

/// Costs and values of `spec` at a few points on `n` samples: equal to the CPU reference's
/// on every shape, or (only where `may_fail`) an error that names the loop limit.
fn check(spec: &str, n: usize, may_fail: bool) -> Vec<String> {
    let data = large_dataset(n);
    let model = Model::parse(spec, 1).unwrap();
    let loss = Loss::new(Metric::Chi2, Weights::Uniform);
    let params: Vec<f64> = [0.2, 0.5, 0.8]
        .iter()
        .flat_map(|&u| model.from_unit(&vec![u; model.dim]))
        .collect();
    let problem = Problem {
        model: &model,
        data: &data,
        loss,
    };
    let reference = CpuBackend::new();
    let mut cpu = reference.prepare(problem).unwrap();
    let (ref_costs, ref_values) = (cpu.costs(&params).unwrap(), cpu.values(&params).unwrap());
    let mut outcomes = Vec::new();
    for shape in Shape::ALL {
        let gpu = GpuBackend::new()
            .expect("a Vulkan adapter (lavapipe in CI)")
            .with_shape(shape);
        let mut ev = gpu.prepare(problem).unwrap();
        match (ev.costs(&params), ev.values(&params)) {
            (Ok(costs), Ok(values)) => {
                for (a, b) in costs.iter().zip(&ref_costs) {
                    assert!(
                        close(*a, *b, 1e-3),
                        "{spec} {shape:?}: cost {a}, reference {b}"
                    );
                }
                for (i, (a, b)) in values.iter().zip(&ref_values).enumerate() {
                    assert!(
                        close(*a, *b, 2e-3),
                        "{spec} {shape:?}: value {i} {a}, reference {b}"
                    );
                }
                outcomes.push(format!("{shape:?}: right"));
            }
            (c, v) => {
                let msg = c.err().or(v.err()).unwrap().to_string();
                assert!(may_fail, "{spec} {shape:?}: {msg}");
                assert!(
                    msg.contains("65,535") && msg.contains("--backend cpu"),
                    "{spec} {shape:?}: unclear error: {msg}"
                );
                outcomes.push(format!("{shape:?}: {msg}"));
            }
        }
    }
    outcomes
}

#[test]
fn large_data_sets_are_evaluated_right_on_every_shape() {
    // 70,000 samples: one thread per candidate walking them all passes the limit on
    // lavapipe, so the one-slice shapes move to the sliced kernel there.
    let outcomes = check("lambert", 70_000, false);
    assert_eq!(outcomes.len(), 4);
}

#[test]
fn a_model_with_a_loop_of_its_own_on_many_samples() {
    // The micrograin series is a loop of its own in each evaluation: 150,000 samples of
    // rmg(lambert) come back right on every shape (on lavapipe through the sliced
    // kernel), or with the error that names the limit, never wrong.
    let outcomes = check("rmg(lambert)", 150_000, true);
    assert_eq!(outcomes.len(), 4);
}

#[test]
fn the_backend_remembers_which_data_sets_need_the_sliced_kernel() {
    let data = large_dataset(70_000);
    let model = Model::parse("lambert", 1).unwrap();
    let loss = Loss::new(Metric::Chi2, Weights::Uniform);
    let problem = Problem {
        model: &model,
        data: &data,
        loss,
    };
    let params = [0.1, 0.2, 0.3];
    let gpu = GpuBackend::new().expect("a Vulkan adapter (lavapipe in CI)");
    let lavapipe = gpu.adapter_name().contains("llvmpipe");
    let mut first = gpu.prepare(problem).unwrap();
    let c1 = first.costs(&params).unwrap();
    let mut second = gpu.prepare(problem).unwrap();
    let c2 = second.costs(&params).unwrap();
    assert_eq!(c1, c2, "the same kernel gives the same costs");
    // Three costs of 4 bytes per submission: the first evaluator on lavapipe read back a
    // cut-short submission and then its rerun, the second starts with the sliced kernel.
    let per_submission = 4 * params.len() as u64;
    assert_eq!(second.read_back_bytes(), per_submission);
    let expected_first = if lavapipe { 2 } else { 1 } * per_submission;
    assert_eq!(first.read_back_bytes(), expected_first);
}
