//! Mesa's llvmpipe (lavapipe, the CI's Vulkan device) ends every loop of a shader
//! invocation once all of its loops together have run 65,535 iterations, silently. An
//! invocation walks one tile of its candidate's records, so a tile too long for that
//! (a large data set, or a model with loops of its own in each evaluation) came back as
//! a partial sum that looked complete. The kernels detect it (`loops_completed` in
//! shaders/engine/kernel.wgsl); the engine then runs the submission again with tiles a
//! quarter as long, remembers that size for the model, and fails with an error naming
//! the cause only where even 16-record tiles are cut short. On any device a batch either
//! matches the CPU reference or fails that way: never a silently wrong number.
//!
//! The tests start from tiles far longer than lavapipe's limit allows (`with_tile`), so
//! that the path is taken on every shape, and check on lavapipe that it was taken.
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

/// Records per tile the tests start from: one invocation walking this many records
/// passes lavapipe's 65,535 loop iterations whatever the model.
const LONG_TILE: u32 = 1 << 20;

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
/// on every shape, starting from tiles too long for lavapipe. On lavapipe the engine must
/// have taken the shorter-tile path on some shape (its remembered tile is shorter than
/// the one it started from); on a device without the limit it keeps the tile it was given.
fn check(spec: &str, n: usize) {
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
    let (mut tiles, mut lavapipe) = (Vec::new(), false);
    for shape in Shape::ALL {
        let gpu = GpuBackend::new()
            .expect("a Vulkan adapter (lavapipe in CI)")
            .with_shape(shape)
            .with_tile(LONG_TILE);
        let mut ev = gpu.prepare(problem).unwrap();
        let costs = ev
            .costs(&params)
            .unwrap_or_else(|e| panic!("{spec} {shape:?}: {e}"));
        let values = ev
            .values(&params)
            .unwrap_or_else(|e| panic!("{spec} {shape:?}: {e}"));
        assert_eq!(costs.len(), ref_costs.len(), "{spec} {shape:?}");
        assert_eq!(values.len(), ref_values.len(), "{spec} {shape:?}");
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
        tiles.push(gpu.tile_for(&model));
        lavapipe = gpu.adapter_name().contains("llvmpipe");
    }
    if lavapipe {
        // Shapes that split the records over many invocations stay under the limit; the
        // CPU-device shape walks them in one and must have shrunk its tile.
        assert!(
            tiles.iter().any(|&t| t < LONG_TILE),
            "{spec}: no shape took the shorter-tile path on lavapipe: {tiles:?}"
        );
    } else {
        assert!(tiles.iter().all(|&t| t == LONG_TILE), "{spec}: {tiles:?}");
    }
}

#[test]
fn large_data_sets_are_evaluated_right_on_every_shape() {
    // 70,000 samples in one tile pass the limit on lavapipe: the tiles shrink there.
    check("lambert", 70_000);
}

#[test]
fn a_model_with_a_loop_of_its_own_on_many_samples() {
    // The micrograin series is a loop of its own in each evaluation: 150,000 samples of
    // rmg(lambert) come back right on every shape (on lavapipe in shorter tiles).
    check("rmg(lambert)", 150_000);
}

#[test]
fn the_backend_remembers_the_shorter_tile() {
    let data = large_dataset(70_000);
    let model = Model::parse("lambert", 1).unwrap();
    let loss = Loss::new(Metric::Chi2, Weights::Uniform);
    let problem = Problem {
        model: &model,
        data: &data,
        loss,
    };
    let params = [0.1, 0.2, 0.3];
    let gpu = GpuBackend::new()
        .expect("a Vulkan adapter (lavapipe in CI)")
        .with_shape(Shape::CPU_DEVICE)
        .with_tile(LONG_TILE);
    let lavapipe = gpu.adapter_name().contains("llvmpipe");
    let mut first = gpu.prepare(problem).unwrap();
    let c1 = first.costs(&params).unwrap();
    let mut second = gpu.prepare(problem).unwrap();
    let c2 = second.costs(&params).unwrap();
    assert!(
        c1.iter().zip(&c2).all(|(a, b)| close(*a, *b, 1e-6)),
        "{c1:?} vs {c2:?}"
    );
    // On lavapipe the first evaluator read back a cut-short submission for every tile
    // too long (each a quarter of the one before, 3 partial costs per tile of the 70,000
    // records) and then the one that ran through; the second starts with that tile.
    // Elsewhere both read back one submission of 3 costs.
    let tile = gpu.tile_for(&model);
    let bytes = |tile: u32| 4 * params.len() as u64 * 70_000u64.div_ceil(tile as u64);
    let mut expected_first = 0;
    if lavapipe {
        assert!(tile < LONG_TILE, "the shorter tile is remembered: {tile}");
        let mut t = LONG_TILE;
        while t > tile {
            expected_first += bytes(t);
            t /= 4;
        }
    } else {
        assert_eq!(tile, LONG_TILE);
    }
    assert_eq!(second.read_back_bytes(), bytes(tile));
    expected_first += bytes(tile);
    assert_eq!(first.read_back_bytes(), expected_first);
}
