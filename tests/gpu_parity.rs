//! GPU (f32, WGSL) against CPU (f64, Rust) on random valid inputs, for every model of the
//! catalogue and every loss. Runs on whatever Vulkan adapter exists — lavapipe in CI; a
//! missing adapter fails the test rather than skipping it.
//!
//! Tolerance: f32 has a unit roundoff of 6e-8; a model evaluation chains some hundred
//! operations including exp/pow/acos (a few ulp each), so a relative error near 1e-5 is
//! typical (the worst measured on lavapipe: 4.3e-4, far in the tails of a BTDF lobe with
//! α = 0.025, values of 1e-9 sr⁻¹). Model values are compared **per sample**:
//! |gpu − cpu| ≤ REL · |cpu| + FLOOR, REL = 2e-3, with no term scaled by the batch (a GGX
//! peak at 1e4 sr⁻¹ must not excuse an error of 0.1 elsewhere). FLOOR = 1e-30 sr⁻¹ is
//! f32's range, not its precision: a narrow lobe seen far from its peak can be 1e-70 in
//! f64, and its f32 factors (D, G, Fresnel, each ≥ f32's smallest normal 1.2e-38 or
//! flushed) can only return 0 or a subnormal product there. Costs (sums over all samples)
//! are compared with REL_COST = 1e-3. NaN never passes.
//!
//! Random data gives every direction one channel; a goniometer's grid (directions shared
//! by all channels and by consecutive records, as measured) is compared too, with an
//! allowance for the conditioning of the f32 directions (see its test).
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::wgsl::Shape;
use std::sync::OnceLock;

const ENGINE: &str = "gpu";

include!("common/parity_suite.rs");

fn gpu() -> &'static GpuBackend {
    static G: OnceLock<GpuBackend> = OnceLock::new();
    G.get_or_init(|| {
        GpuBackend::new().unwrap_or_else(|e| {
            panic!("no GPU adapter: {e}. The parity tests need Vulkan (CI installs mesa-vulkan-drivers for lavapipe).")
        })
    })
}

fn tested() -> &'static dyn Backend {
    gpu()
}

/// Micrograin (`rmg`: G1(μ)/μ), VMF (σ(±μ)) and GG transmission (G1(μ)/μ from its Λ
/// table) compute per candidate what depends on μ alone at every polar cosine of the
/// problem, where the data have few (its μ table) and one thread walks a candidate's
/// records; otherwise per record. On the goniometer grid (at most 24 cosines) the
/// one-slice shape takes the tables and the sliced one does not: the two must agree to
/// f32 rounding, since the tables hold the same functions at the records' own f32
/// cosines (GG's at a direction of that cosine in the xz plane, its sine from the
/// cosine). Bound per value: 1e-5 relative (a few f32 ulps through the rest of the
/// model; the same code otherwise), NaN never passing. (Each path is also checked against
/// the CPU reference: the tables on the grid, per record on random directions.)
#[test]
fn mu_tables_give_the_per_record_values() {
    let one_slice = GpuBackend::new()
        .expect("GPU adapter")
        .with_shape(Shape::CPU_DEVICE);
    let sliced = GpuBackend::new()
        .expect("GPU adapter")
        .with_shape(Shape::GPU_DEVICE);
    let mut failures = Vec::new();
    let cases = [
        (Kind::Brdf, "rmg(ggx)"),
        (Kind::Brdf, "rmg(vmf)"),
        (Kind::Brdf, "fa(vmf)"),
        (Kind::Brdf, "dmg(vmf)"),
        (Kind::Brdf, "vmf"),
        (Kind::Btdf, "btdf(gg)"),
        (Kind::Btdf, "btdf(gg)+absorb"),
    ];
    for (kind, spec) in cases {
        let channels = if kind == Kind::Brdf { 3 } else { 1 };
        let data = grid_dataset(kind, channels, 23);
        let model = Model::parse(spec, channels).unwrap();
        // The module the one-slice shape compiles for this batch uses the tables.
        let src = bsdfit::engine::wgsl::compose(
            &model,
            bsdfit::engine::loss::Term::Square,
            Shape::CPU_DEVICE.for_batch(true),
        );
        assert!(src.contains("const MU_TABLES: bool = true;"), "{spec}");
        let params = random_params(&model, CANDIDATES, 24);
        let problem = Problem {
            model: &model,
            data: &data,
            loss: Loss::new(Metric::Chi2, Weights::Uniform),
        };
        let values = |b: &GpuBackend| b.prepare(problem).unwrap().values(&params).unwrap();
        let (table, per_record) = (values(&one_slice), values(&sliced));
        let bad = table
            .iter()
            .zip(&per_record)
            .filter(|(a, b)| {
                let err = (*a - *b).abs();
                // NaN (either value, or both) fails.
                err.is_nan() || err > 1e-5 * a.abs().max(b.abs()) + FLOOR
            })
            .count();
        if bad > 0 {
            failures.push(format!("{spec}: {bad} of {} values differ", table.len()));
        }
    }
    assert_no_failures(&failures);
}

#[test]
fn the_workgroup_reduced_shape_matches_too() {
    // lavapipe picks the one-slice shape; force the GPU shape (32 lanes × 8 slices with the
    // workgroup-memory reduction) so both kernel paths are checked on every machine.
    let forced = GpuBackend::new()
        .expect("GPU adapter")
        .with_shape(Shape::GPU_DEVICE);
    let data = random_dataset(Kind::Brdf, 3, 333, 21);
    for spec in ["lambert", "fa(eon)", "ggx+retro"] {
        let model = Model::parse(spec, 3).unwrap();
        let params = random_params(&model, 70, 22);
        for metric in [Metric::Rmse, Metric::Smape, Metric::Chi2] {
            let problem = Problem {
                model: &model,
                data: &data,
                loss: Loss::new(metric, Weights::Relunc),
            };
            let failures = compare_costs(&forced, problem, &params, &format!("{spec} {metric}"));
            assert_no_failures(&failures);
            let cv = CpuBackend::new()
                .prepare(problem)
                .unwrap()
                .values(&params)
                .unwrap();
            let gv = forced.prepare(problem).unwrap().values(&params).unwrap();
            for (a, b) in cv.iter().zip(&gv) {
                assert!(
                    a.is_finite() && (a - b).abs() <= REL * a.abs() + FLOOR,
                    "{spec} values: gpu {b} cpu {a}"
                );
            }
        }
    }
}

#[test]
fn large_batches_are_chunked_and_complete() {
    // More candidates than one dispatch dimension holds (65535 workgroups): exercises the
    // y dimension and, with the poisoned outputs, proves every cost was written.
    let data = random_dataset(Kind::Brdf, 1, 8, 9);
    let model = Model::parse("lambert", 1).unwrap();
    let n = 70_000;
    let params: Vec<f64> = (0..n).map(|i| (i % 1000) as f64 / 1000.0).collect();
    let problem = Problem {
        model: &model,
        data: &data,
        loss: Loss::new(Metric::Rmse, Weights::Uniform),
    };
    let c = CpuBackend::new()
        .prepare(problem)
        .unwrap()
        .costs(&params)
        .unwrap();
    let g = gpu().prepare(problem).unwrap().costs(&params).unwrap();
    assert_eq!(g.len(), n);
    for (i, (cv, gv)) in c.iter().zip(&g).enumerate() {
        assert!(
            cv.is_finite() && (gv - cv).abs() <= REL_COST * cv.abs() + 1e-7,
            "candidate {i}: gpu {gv} cpu {cv}"
        );
    }
}

#[test]
fn lm_normal_equations_match_the_cpu_reference() {
    // JᵀJ, Jᵀr and Σr² reduced on the device from the GPU's f32 model values
    // (shaders/engine/normal.wgsl) against the CPU's f64 reduction of its f64 values, for
    // the same forward differences (unit-box step h = 1e-2). The device's own f32
    // arithmetic in the reduction (a few U per sum, tests/gpu_normal.rs) is far below the
    // model values' error, which the bound below is made of. Bound per entry, relative to
    // its own columns, never to the matrix's largest entry. Each GPU residual carries the
    // f32 error of its model value, |δr_k| ≤ ρ · √w_k · a_k · |y′_k| (ρ = 1e-4, ten times
    // the model values' typical f32 relative error, see the module doc), so each Jacobian
    // column is off by a vector of norm at most n = 2ρ ‖√w a y′‖ / h. By Cauchy–Schwarz:
    // |ΔJᵀJ_ij| ≤ 1e-2 · √(JᵀJ_ii JᵀJ_jj) + n (‖J_i‖ + ‖J_j‖) + n²,
    // |ΔJᵀr_j| ≤ 1e-2 · √(JᵀJ_jj Σr²) + n ‖r‖ + ‖J_j‖ ρ‖√w a y′‖,
    // and 5e-3 relative for Σr² (model values agree to REL = 2e-3, and squaring doubles a
    // relative error). A column that the data barely constrain has a small norm, and its
    // entries are then dominated by the f32 term: that is the resolution f32 differences
    // have, not an error. The CPU reference has a resolution too: it differences whole f64
    // residuals, r_k(moved_j) − r_k, each rounded to ε64 |√w_k (g(y′_k) − g(y_k))|, so a
    // change of g(y′) below ε64 |g(y)| vanishes there (a BTDF tail of 1e-30 sr⁻¹ beside a
    // measured g(y) of 0.5), while the device differences g(y′) directly; its columns are
    // known to n64 = 4 ε64 ‖√w (|g(y′)| + |g(y)|)‖ / h, added to n. Both workgroup shapes.
    let cases = [
        (Kind::Brdf, "lambert", 3usize, Metric::Chi2),
        (Kind::Brdf, "ggx", 3, Metric::Ngan),
        (Kind::Brdf, "fa(eon)", 3, Metric::Rmse),
        (Kind::Brdf, "rmg(eon)", 3, Metric::Rmse),
        (Kind::Brdf, "rmg(eon)", 3, Metric::Chi2),
        (Kind::Brdf, "ggx+retro", 3, Metric::Chi2),
        (Kind::Btdf, "btdf(tr)+scale", 1, Metric::F),
        (Kind::Btdf, "btdf(tr)+scale", 1, Metric::Logcosf),
        (Kind::Btdf, "btdf(gg)+scale", 1, Metric::Logf),
    ];
    for shape in Shape::ALL {
        // The device's reduction (CPU devices default to the host's, checked against it
        // in tests/gpu_normal.rs).
        let gpu_shaped = GpuBackend::new()
            .expect("GPU adapter")
            .with_shape(shape)
            .with_device_normal(true);
        for (kind, spec, channels, metric) in cases {
            let data = random_dataset(kind, channels, 150, 31);
            let model = Model::parse(spec, channels).unwrap();
            let p = model.dim;
            let loss = Loss::new(metric, Weights::Uniform);
            let problem = Problem {
                model: &model,
                data: &data,
                loss,
            };
            let mut rng = ChaCha8Rng::seed_from_u64(32);
            let n = 5;
            let mut points = Vec::new();
            let mut steps = Vec::new();
            for _ in 0..n {
                let x: Vec<f64> = (0..p).map(|_| rng.random_range(0.1..0.9)).collect();
                points.extend(x);
                steps.extend((0..p).map(|j| if j % 2 == 0 { 1e-2 } else { -1e-2 }));
            }
            let unit = bsdfit::optim::difference_points(&points, &steps, p);
            let phys: Vec<f64> = unit.chunks(p).flat_map(|u| model.from_unit(u)).collect();
            let c = CpuBackend::new()
                .prepare(problem)
                .unwrap()
                .normal_equations(&phys, &steps)
                .unwrap();
            // ‖√w a y′‖ at each restart's point (the first of its P + 1 candidates).
            let values = CpuBackend::new()
                .prepare(problem)
                .unwrap()
                .values(&phys)
                .unwrap();
            let terms = loss.terms(&data);
            let k = data.len();
            let value_norm: Vec<f64> = values
                .chunks(k * (p + 1))
                .map(|group| {
                    group[..k]
                        .iter()
                        .enumerate()
                        .map(|(m, v)| terms.w[m] * (terms.a[m] * v).powi(2))
                        .sum::<f64>()
                        .sqrt()
                })
                .collect();
            // ‖√w (|g(y′)| + |g(y)|)‖ at each restart's point: the scale of the CPU's own
            // f64 cancellation.
            let residual_scale: Vec<f64> = values
                .chunks(k * (p + 1))
                .map(|group| {
                    group[..k]
                        .iter()
                        .enumerate()
                        .map(|(m, &v)| {
                            let s =
                                terms.transform(m, v).abs() + terms.transform(m, terms.y[m]).abs();
                            terms.w[m] * s * s
                        })
                        .sum::<f64>()
                        .sqrt()
                })
                .collect();
            const RHO: f64 = 1e-4;
            const H: f64 = 1e-2;
            let g = gpu_shaped
                .prepare(problem)
                .unwrap()
                .normal_equations(&phys, &steps)
                .unwrap();
            for (r, (a, b)) in c.iter().zip(&g).enumerate() {
                let diag: Vec<f64> = (0..p).map(|j| a.jtj[j * p + j]).collect();
                let noise =
                    2.0 * RHO * value_norm[r] / H + 4.0 * f64::EPSILON * residual_scale[r] / H;
                for (i, (x, y)) in a.jtj.iter().zip(&b.jtj).enumerate() {
                    let (ni, nj) = (diag[i / p].sqrt(), diag[i % p].sqrt());
                    let bound = 1e-2 * ni * nj + noise * (ni + nj) + noise * noise;
                    let ok = x.is_finite() && (x - y).abs() <= bound;
                    assert!(
                        ok,
                        "{spec} {shape:?} restart {r} JᵀJ[{}, {}]: cpu {x} gpu {y} (bound {bound:.3e}; ‖J_i‖ {ni:.3e}, ‖J_j‖ {nj:.3e}, f32 column noise {noise:.3e})",
                        i / p,
                        i % p
                    );
                }
                for (j, (x, y)) in a.jtr.iter().zip(&b.jtr).enumerate() {
                    let nj = diag[j].sqrt();
                    let bound =
                        1e-2 * nj * a.ss.sqrt() + noise * a.ss.sqrt() + nj * RHO * value_norm[r];
                    assert!(
                        x.is_finite() && (x - y).abs() <= bound,
                        "{spec} {shape:?} Jᵀr[{j}]: cpu {x} gpu {y} (bound {bound:.3e})"
                    );
                }
                assert!(
                    a.ss.is_finite() && (a.ss - b.ss).abs() <= 5e-3 * a.ss,
                    "{spec} {shape:?} Σr²: cpu {} gpu {}",
                    a.ss,
                    b.ss
                );
            }
        }
    }
}
