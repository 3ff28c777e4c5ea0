//! The SIMD CPU engine (f32 or f64 lanes, the models' one source instantiated for the
//! processor's vector extensions) against the CPU reference (the same source in f64, one
//! direction at a time) on random valid inputs, for every model the registry derives
//! and every loss: the GPU engine's parity suite (`tests/common/parity_suite.rs`) with
//! the SIMD engine in its place, and the GPU engine's accuracy contract.
//!
//! Tolerance: the models run in f32 lanes (unit roundoff 6e-8) unless one of their nodes
//! needs f64, through some hundred operations, so model values are compared per sample
//! with |simd − cpu| ≤ REL · |cpu| + FLOOR, REL = 2e-3, FLOOR = 1e-30 sr⁻¹ (f32's range),
//! and costs with REL_COST = 1e-3, as the GPU engine's (tests/gpu_parity.rs says why).
//! NaN never passes. Every instruction set the processor has is checked: the run-time
//! dispatch picks the widest, and `BSDFIT_SIMD=avx2` or `=baseline` (CI runs this file
//! once more with the baseline) caps it. Also: a model without a kernel (evaluated lane
//! by lane through the reference) and a data set whose blocks end in partial lanes.

mod common;

use bsdfit::engine::simd::SimdBackend;

const ENGINE: &str = "simd";

include!("common/parity_suite.rs");

fn tested() -> &'static dyn Backend {
    static S: std::sync::OnceLock<SimdBackend> = std::sync::OnceLock::new();
    S.get_or_init(SimdBackend::new)
}

/// In f64 lanes every model gives the reference's values bit for bit: the same
/// operations on the same numbers (the vector square root and division are IEEE's, and
/// the transcendental functions run lane by lane in f64), so this checks the lanes'
/// machinery itself (packing directions, padding a block's last lanes, the AVX types,
/// the children's values, the order values come back in) with nothing to hide behind a
/// tolerance. NaN never passes.
#[test]
fn f64_lanes_give_the_reference_values_bit_for_bit() {
    let mut failures = Vec::new();
    for (kind, spec) in all_specs() {
        let channels = if kind == Kind::Brdf { 3 } else { 1 };
        let data = random_dataset(kind, channels, 61, 90);
        failures.extend(f64_lanes_differ(&spec, channels, &data, (4, 91)));
    }
    assert_no_failures(&failures);
}

/// The model `spec` on `data` at `draw.0` random parameter vectors (seed `draw.1`) in the SIMD engine's f64
/// lanes against the CPU reference: None where every value is the reference's bit for bit
/// (NaN never is), else what differs.
fn f64_lanes_differ(
    spec: &str,
    channels: usize,
    data: &Dataset,
    draw: (usize, u64),
) -> Option<String> {
    let f64_lanes = SimdBackend::with_lanes(bsdfit::bsdf::kernel::LaneKind::F64x4);
    let model = Model::parse(spec, channels).unwrap();
    let params = random_params(&model, draw.0, draw.1);
    let problem = Problem {
        model: &model,
        data,
        loss: Loss::new(Metric::Chi2, Weights::Uniform),
    };
    let c = CpuBackend::new()
        .prepare(problem)
        .unwrap()
        .values(&params)
        .unwrap();
    let s = f64_lanes.prepare(problem).unwrap().values(&params).unwrap();
    let differ = |(a, b): &(&f64, &f64)| !(a.is_finite() && a.to_bits() == b.to_bits());
    let bad = c.iter().zip(&s).filter(differ).count();
    let (a, b) = c.iter().zip(&s).find(differ)?;
    Some(format!(
        "{spec}: {bad} of {} values differ (first: cpu {a:e}, simd f64 {b:e})",
        c.len()
    ))
}

/// The per-block tables of factors of μ alone (`SlotMemo`, keyed by the engine's μ slots)
/// on data that repeat a set of polar angles, as goniometers do: each lane
/// of a lane-direction has its own μ, and the same μ comes back many lane-directions
/// later, so values come from the table, from the one-entry memo and from fresh
/// computations. In f64 lanes every model must give the reference's values bit for bit
/// (a value taken from another slot, or another block's, would not).
#[test]
fn tables_of_mu_give_the_reference_values_bit_for_bit() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    // 25 polar angles: in the engine's walk order (by μi, then μo) μo changes at nearly
    // every direction, and each of its values comes back under every μi.
    let thetas: Vec<f64> = (0..25).map(|k| 3.5 * k as f64).collect();
    let mut failures = Vec::new();
    for (kind, spec) in all_specs() {
        let channels = if kind == Kind::Brdf { 3 } else { 1 };
        // Every channel at each direction, so that the engine's blocks run long.
        let mut rows: Vec<(usize, RawRow)> = Vec::new();
        for _ in 0..600 / channels {
            let (ti, to) = (rng.random_range(0..25), rng.random_range(0..25));
            let phi_o = rng.random_range(0.0..360.0);
            for wavelength_nm in [450.0, 550.0, 650.0].into_iter().take(channels) {
                let value: f64 = rng.random_range(0.01..2.0);
                let row = RawRow {
                    theta_i: thetas[ti],
                    phi_i: 0.0,
                    theta_o: thetas[to],
                    phi_o,
                    wavelength_nm,
                    value,
                    uncertainty: 0.02 * value,
                };
                rows.push((rows.len() + 1, row));
            }
        }
        let data = Dataset::from_rows(kind, "grid", &rows, "<grid>", &ReadOptions::default())
            .expect("valid grid data");
        failures.extend(f64_lanes_differ(&spec, channels, &data, (3, 92)));
    }
    assert_no_failures(&failures);
}

/// Every model at grazing angles (θi and θo between 86° and 89.9°), where the f32 lanes
/// directions are least accurate: the bound of the random test plus, per value, twice
/// what the f64 model moves when its directions are rounded to f32 (as on the grid).
#[test]
fn every_model_matches_the_cpu_reference_at_grazing_angles() {
    let mut failures = Vec::new();
    for (kind, spec) in all_specs() {
        let channels = if kind == Kind::Brdf { 3 } else { 1 };
        let data = random_dataset_in(kind, channels, 200, 77, 86.0..89.9);
        match compare_with_f32_direction_allowance(&spec, &data, 78) {
            Ok(worst) => eprintln!("{spec:<28} grazing: worst relative error {worst:.2e}"),
            Err(e) => failures.push(format!("{spec} (grazing): {e}")),
        }
    }
    assert_no_failures(&failures);
}

/// The lanes a model runs in: sixteen f32 lanes unless a node asks for eight or for f64,
/// and sixteen only under AVX-512; every kernel of the catalogue is named (a node
/// without one is evaluated through the reference).
#[test]
fn lane_kinds_and_kernels_are_reported() {
    use bsdfit::bsdf::kernel::LaneKind;
    use bsdfit::math::lanes::{level, Level};
    let m = Model::parse("fa(lambert)", 3).unwrap();
    assert_eq!(m.lane_kind(), LaneKind::F32x16);
    // The micrograin's memos make eight lanes its faster width; f64 where a node asks.
    let rmg = Model::parse("rmg(lambert)+coat", 3).unwrap();
    assert_eq!(rmg.lane_kind(), LaneKind::F32x8);
    // Sixteen lanes run only where AVX-512 does (the parity tests above then check them;
    // under BSDFIT_SIMD=avx2 or baseline, the eight).
    let sixteen = LaneKind::F32x16.on_this_processor();
    assert_eq!(sixteen == LaneKind::F32x16, level() == Level::Avx512);
    assert_eq!(LaneKind::F32x8.on_this_processor(), LaneKind::F32x8);
    assert!(
        m.nodes_without_kernel().is_empty(),
        "{:?}",
        m.nodes_without_kernel()
    );
    eprintln!(
        "instruction set: {}",
        bsdfit::math::lanes::instruction_set()
    );
    // No catalogue node runs lane by lane through the reference, over every spec the
    // registry derives, `+aniso` forms included (the per-lane fallback is for models
    // defined outside the crate, as tests/toy_model.rs's).
    let mut missing: Vec<(String, Vec<&str>)> = Vec::new();
    for spec in [Kind::Brdf, Kind::Btdf].into_iter().flat_map(every_spec) {
        let m = Model::parse(&spec, 3).unwrap().nodes_without_kernel();
        if !m.is_empty() {
            missing.push((spec, m));
        }
    }
    assert!(missing.is_empty(), "nodes without a kernel: {missing:?}");
    // The walk reaches the anisotropic lobes (a walk that skipped them would pass).
    let anisotropic = [Kind::Brdf, Kind::Btdf]
        .into_iter()
        .flat_map(every_spec)
        .filter(|s| s.contains("+aniso"))
        .count();
    assert!(anisotropic >= 4, "{anisotropic} +aniso specs walked");
}

/// The level that runs is the one `BSDFIT_SIMD` asks for (CI runs this file three times:
/// no cap, `avx2`, `baseline`), judged from the processor's own feature flags here: a cap
/// that was ignored would test the widest level three times and pass.
#[test]
fn the_level_that_runs_is_the_one_asked_for() {
    use bsdfit::math::lanes::{instruction_set, level, Level};
    let cap = std::env::var("BSDFIT_SIMD").unwrap_or_default();
    #[cfg(target_arch = "x86_64")]
    {
        let has = |f: &str| match f {
            "avx2" => std::arch::is_x86_feature_detected!("avx2"),
            "fma" => std::arch::is_x86_feature_detected!("fma"),
            "avx512f" => std::arch::is_x86_feature_detected!("avx512f"),
            "avx512vl" => std::arch::is_x86_feature_detected!("avx512vl"),
            "avx512dq" => std::arch::is_x86_feature_detected!("avx512dq"),
            "avx512bw" => std::arch::is_x86_feature_detected!("avx512bw"),
            _ => unreachable!(),
        };
        let avx2 = has("avx2") && has("fma");
        let avx512 = avx2
            && ["avx512f", "avx512vl", "avx512dq", "avx512bw"]
                .iter()
                .all(|f| has(f));
        let widest = if avx512 {
            Level::Avx512
        } else if avx2 {
            Level::Avx2
        } else {
            Level::Baseline
        };
        let want = match cap.as_str() {
            "baseline" => Level::Baseline,
            "avx2" => {
                if !avx2 {
                    common::missing("AVX2 (BSDFIT_SIMD=avx2 on a processor without it)");
                    return;
                }
                Level::Avx2
            }
            "" | "avx512" => widest,
            other => panic!("BSDFIT_SIMD={other}: this test knows baseline, avx2, avx512"),
        };
        assert_eq!(
            level(),
            want,
            "BSDFIT_SIMD={cap:?}: ran {}",
            instruction_set()
        );
    }
    #[cfg(not(target_arch = "x86_64"))]
    assert_eq!(level(), Level::Baseline, "BSDFIT_SIMD={cap:?}");
}

/// Costs of the SIMD engine (summed in lane order, in partial sums) against the
/// reference's on data whose directions do not fill whole lanes (7 and 13 directions per
/// channel set) and hold repeated channels: padding lanes add nothing.
#[test]
fn partial_lanes_add_nothing() {
    let model = Model::parse("ggx", 3).unwrap();
    let mut failures = Vec::new();
    for n in [1usize, 7, 13] {
        let data = random_dataset(Kind::Brdf, 3, n, 40 + n as u64);
        let params = random_params(&model, 6, 41);
        for metric in [Metric::Chi2, Metric::Smape, Metric::Low] {
            let problem = Problem {
                model: &model,
                data: &data,
                loss: Loss::new(metric, Weights::Relunc),
            };
            let what = format!("{n} directions, {metric}");
            failures.extend(compare_costs(tested(), problem, &params, &what));
        }
    }
    assert_no_failures(&failures);
}
