//! The streamed reductions against direct sums, for every model of the catalogue and
//! every loss: what a backend returns per candidate (the loss, LM's normal equations,
//! the screening's rescaled Σr²) reduced inside the engine over windows of samples and
//! tiles of records must equal the same quantity summed directly over the candidate's
//! whole row of model values, in sample order, in f64.
//!
//! Every model is checked under one loss (the losses taken in turn), and every loss on
//! two models, on random data shaped like measurements: random directions, each seen in
//! every channel but for a tenth of the samples (so records have empty channel slots).
//!
//! Bounds:
//! - CPU reference (f64 throughout, more than one window of rows): costs within 1e-12
//!   relative of the direct sum (the same terms in another order), normal-equation
//!   entries within 1e-9 of √(S_aa S_bb) (Cauchy–Schwarz bounds |S_ab| by it; the
//!   differences of residuals lose a few digits to cancellation), the screening's Σr²
//!   within 1e-8 relative (a square term's rescaled Σr² is a closed form there).
//! - GPU engine (f32 kernels), cut into many tiles and windows (short tiles and a small
//!   binding forced): costs against the f64 sum of the terms of its own f32 values,
//!   within 1e-5 of the sum of the terms' magnitudes Σ w (|a y′| + |g(y)|)² (SMAPE: Σ w;
//!   f32 rounds each term's inputs to 6e-8 relative and sums them with compensation);
//!   normal equations against one unsplit submission's of the same path (the device's
//!   reduction, or the host's of the values read back), within 1e-5 of √(S_aa S_bb)
//!   (compensated f32 partial sums per tile, added in f64).
//!
//! NaN passes only where both sides are NaN.

use bsdfit::bsdf::{every_spec, Model};
use bsdfit::data::{Dataset, Kind, RawRow, ReadOptions};
use bsdfit::engine::cpu::{CpuBackend, WINDOW_ROWS};
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::loss::{Loss, Metric, Term, Weights};
use bsdfit::engine::reduce::rescaled_sum_squares;
use bsdfit::engine::wgsl::Shape;
use bsdfit::engine::{normal_equations_of_values, Backend, Problem};
use bsdfit::optim::{difference_points, NormalEquations};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const WAVELENGTHS: [f64; 3] = [450.0, 550.0, 650.0];

/// `directions` random directions (θ up to 85°, any φ), each in every channel but for a
/// tenth of the samples dropped at random; random positive values and uncertainties.
fn measured_like(kind: Kind, channels: usize, directions: usize, seed: u64) -> Dataset {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut rows = Vec::new();
    for _ in 0..directions {
        let (ti, pi): (f64, f64) = (rng.random_range(0.0..85.0), rng.random_range(0.0..360.0));
        let (to, po): (f64, f64) = (rng.random_range(0.0..85.0), rng.random_range(0.0..360.0));
        for &wavelength_nm in &WAVELENGTHS[..channels] {
            if rng.random::<f64>() < 0.1 {
                continue;
            }
            let value: f64 = rng.random_range(0.01..2.0);
            rows.push((
                rows.len() + 1,
                RawRow {
                    theta_i: ti,
                    phi_i: pi,
                    theta_o: to,
                    phi_o: po,
                    wavelength_nm,
                    value,
                    uncertainty: value * rng.random_range(0.005..0.05),
                },
            ));
        }
    }
    Dataset::from_rows(
        kind,
        "measured-like",
        &rows,
        "<random>",
        &ReadOptions::default(),
    )
    .expect("valid random data")
}

fn random_unit(dim: usize, n: usize, seed: u64) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n * dim).map(|_| rng.random::<f64>()).collect()
}

/// Every loss that applies to `kind`, uncertainty-weighted and uniform, and χ².
fn losses(kind: Kind) -> Vec<Loss> {
    let mut out: Vec<Loss> = Metric::for_kind(kind)
        .iter()
        .flat_map(|&m| [Weights::Uniform, Weights::uncertainty_for(kind)].map(|w| Loss::new(m, w)))
        .collect();
    out.push(Loss::new(Metric::Chi2, Weights::Uniform));
    out
}

/// (kind, channels, spec, loss): every model under one loss (in turn), and every loss on
/// two models of each kind.
fn cases() -> Vec<(Kind, usize, String, Loss)> {
    let mut out = Vec::new();
    for (kind, channels, pair) in [
        (Kind::Brdf, 3, ["lambert", "fa(eon)"]),
        (Kind::Btdf, 1, ["btdf(tr)+scale", "btdf(gg)+absorb"]),
    ] {
        let ls = losses(kind);
        for (i, spec) in every_spec(kind).into_iter().enumerate() {
            out.push((kind, channels, spec, ls[i % ls.len()]));
        }
        for spec in pair {
            for &loss in &ls {
                out.push((kind, channels, spec.to_string(), loss));
            }
        }
    }
    out
}

/// LM's groups at unit-box `points`: physical parameters of each point and its P moved
/// copies, and the signed unit-box steps.
fn groups(model: &Model, points: &[f64], h: f64) -> (Vec<f64>, Vec<f64>) {
    let p = model.dim;
    let steps: Vec<f64> = points
        .iter()
        .map(|&x| if x + h <= 1.0 { h } else { -h })
        .collect();
    let unit = difference_points(points, &steps, p);
    let phys = unit.chunks(p).flat_map(|u| model.from_unit(u)).collect();
    (phys, steps)
}

/// Each entry of `a` against `b` within `rel` of √(S_aa S_bb) (and Σr² within `rel` of
/// itself); NaN only against NaN. Returns the failures.
fn compare_normal(a: &NormalEquations, b: &NormalEquations, rel: f64, label: &str) -> Vec<String> {
    let p = b.jtr.len();
    let mut bad = Vec::new();
    let ok = |x: f64, y: f64, scale: f64| {
        if x.is_nan() || y.is_nan() {
            return x.is_nan() && y.is_nan();
        }
        if x.is_infinite() || y.is_infinite() {
            return x == y;
        }
        (x - y).abs() <= rel * scale + 1e-300
    };
    for i in 0..p {
        for j in 0..p {
            let scale = (b.jtj[i * p + i] * b.jtj[j * p + j]).abs().sqrt();
            if !ok(a.jtj[i * p + j], b.jtj[i * p + j], scale) {
                bad.push(format!(
                    "{label}: JᵀJ[{i},{j}] {} vs {}",
                    a.jtj[i * p + j],
                    b.jtj[i * p + j]
                ));
            }
        }
        let scale = (b.jtj[i * p + i] * b.ss).abs().sqrt();
        if !ok(a.jtr[i], b.jtr[i], scale) {
            bad.push(format!("{label}: Jᵀr[{i}] {} vs {}", a.jtr[i], b.jtr[i]));
        }
    }
    if !ok(a.ss, b.ss, b.ss.abs()) {
        bad.push(format!("{label}: Σr² {} vs {}", a.ss, b.ss));
    }
    bad
}

#[test]
fn cpu_streamed_reductions_equal_direct_f64_sums() {
    // More rows than one window holds, so that every reduction adds windows up.
    let directions = WINDOW_ROWS / 3 + 600;
    let brdf = measured_like(Kind::Brdf, 3, directions, 1);
    let btdf = measured_like(Kind::Btdf, 1, WINDOW_ROWS + 1500, 2);
    assert!(brdf.len() > WINDOW_ROWS && btdf.len() > WINDOW_ROWS);
    let cpu = CpuBackend::new();
    let mut failures = Vec::new();
    for (i, (kind, channels, spec, loss)) in cases().into_iter().enumerate() {
        let data = if kind == Kind::Brdf { &brdf } else { &btdf };
        let model = Model::parse(&spec, channels).unwrap();
        let p = model.dim;
        let label = format!("{spec} {loss}");
        let problem = Problem {
            model: &model,
            data,
            loss,
        };
        let mut ev = cpu.prepare(problem).unwrap();
        let terms = loss.terms(data);
        // Costs of 3 random points.
        let params: Vec<f64> = random_unit(p, 3, 10 + i as u64)
            .chunks(p)
            .flat_map(|u| model.from_unit(u))
            .collect();
        let streamed = ev.costs(&params).unwrap();
        let values = ev.values(&params).unwrap();
        for (c, row) in values.chunks(data.len()).enumerate() {
            let direct = terms.loss(row);
            let ok = if direct.is_nan() {
                streamed[c].is_nan()
            } else {
                (streamed[c] - direct).abs() <= 1e-12 * direct.abs()
            };
            if !ok {
                failures.push(format!("{label}: cost {} vs direct {direct}", streamed[c]));
            }
        }
        if loss.metric.term() == Term::AbsRatio {
            continue; // SMAPE has no residuals
        }
        // The screening's rescaled Σr².
        let screened = rescaled_sum_squares(ev.as_mut(), &[0, 0, 0], &params, 100.0).unwrap();
        for (c, row) in values.chunks(data.len()).enumerate() {
            let direct = terms.rescaled_sum_squares(row, 100.0);
            let ok = if direct.is_nan() {
                screened[c].is_nan()
            } else {
                (screened[c] - direct).abs() <= 1e-8 * direct.abs()
            };
            if !ok {
                failures.push(format!(
                    "{label}: screening {} vs direct {direct}",
                    screened[c]
                ));
            }
        }
        // Normal equations of 2 groups, LM's f64 step.
        let points = random_unit(p, 2, 20 + i as u64);
        let (phys, steps) = groups(&model, &points, 1e-6);
        let streamed = ev.normal_equations(&phys, &steps).unwrap();
        let vals = ev.values(&phys).unwrap();
        let direct = normal_equations_of_values(&vals, &[&terms], &[0, 0], &steps, p);
        for (g, (a, b)) in streamed.iter().zip(&direct).enumerate() {
            failures.extend(compare_normal(a, b, 1e-9, &format!("{label} group {g}")));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

fn gpu() -> GpuBackend {
    GpuBackend::new().unwrap_or_else(|e| {
        panic!("no GPU adapter: {e}. These tests need Vulkan (CI installs mesa-vulkan-drivers for lavapipe).")
    })
}

// The cases in two halves (every other one), two tests the harness runs side by side: on
// lavapipe most of a case's time is the compilation of its shaders, on one core, and one
// test of every case took 163 s of the CI's 2 cores while the other idled.
#[test]
fn gpu_streamed_reductions_equal_direct_sums_of_its_values_even_cases() {
    gpu_streamed_reductions_equal_direct_sums(0);
}

#[test]
fn gpu_streamed_reductions_equal_direct_sums_of_its_values_odd_cases() {
    gpu_streamed_reductions_equal_direct_sums(1);
}

/// The cases i with i % 2 == `half`.
fn gpu_streamed_reductions_equal_direct_sums(half: usize) {
    let brdf = measured_like(Kind::Brdf, 3, 700, 3);
    let btdf = measured_like(Kind::Btdf, 1, 1500, 4);
    // Tiles of 64 records and a binding of 64 KiB: every pass takes many tiles and
    // several windows. The device reduces the normal equations (the path of GPUs).
    let split = gpu()
        .with_tile(64)
        .with_max_binding(64 << 10)
        .with_device_normal(true);
    let whole = gpu().with_tile(1 << 14).with_device_normal(true);
    let host_split = gpu()
        .with_tile(64)
        .with_max_binding(64 << 10)
        .with_device_normal(false);
    let host_whole = gpu().with_tile(1 << 14).with_device_normal(false);
    let mut failures = Vec::new();
    for (i, (kind, channels, spec, loss)) in cases().into_iter().enumerate() {
        if i % 2 != half {
            continue;
        }
        let data = if kind == Kind::Brdf { &brdf } else { &btdf };
        let model = Model::parse(&spec, channels).unwrap();
        let p = model.dim;
        let label = format!("{spec} {loss}");
        let problem = Problem {
            model: &model,
            data,
            loss,
        };
        let terms = loss.terms(data);
        let params: Vec<f64> = random_unit(p, 3, 30 + i as u64)
            .chunks(p)
            .flat_map(|u| model.from_unit(u))
            .collect();
        let mut ev = split.prepare(problem).unwrap();
        let costs = ev.costs(&params).unwrap();
        let values = ev.values(&params).unwrap();
        for (c, row) in values.chunks(data.len()).enumerate() {
            let direct: f64 = (0..row.len()).map(|k| terms.term_at(k, row[k])).sum();
            let scale: f64 = (0..row.len())
                .map(|k| match terms.term {
                    Term::AbsRatio => terms.w[k],
                    _ => {
                        terms.w[k] * (terms.transform(k, row[k]).abs() + terms.gy[k].abs()).powi(2)
                    }
                })
                .sum();
            let streamed = terms.finisher().sum_of(costs[c]);
            let ok = if direct.is_nan() {
                streamed.is_nan()
            } else {
                (streamed - direct).abs() <= 1e-5 * scale + 1e-30
            };
            if !ok {
                failures.push(format!("{label}: cost sum {streamed} vs direct {direct}"));
            }
        }
        if loss.metric.term() == Term::AbsRatio {
            continue;
        }
        let points = random_unit(p, 2, 40 + i as u64);
        let (phys, steps) = groups(&model, &points, 4.0 * (f32::EPSILON as f64 / 2.0).sqrt());
        let one = whole
            .prepare(problem)
            .unwrap()
            .normal_equations(&phys, &steps)
            .unwrap();
        let tiled = ev.normal_equations(&phys, &steps).unwrap();
        let normal = |b: &GpuBackend| {
            b.prepare(problem)
                .unwrap()
                .normal_equations(&phys, &steps)
                .unwrap()
        };
        let (host, host_one) = (normal(&host_split), normal(&host_whole));
        for (g, (a, b)) in tiled.iter().zip(&one).enumerate() {
            failures.extend(compare_normal(
                a,
                b,
                1e-5,
                &format!("{label} group {g}, device"),
            ));
        }
        for (g, (a, b)) in host.iter().zip(&host_one).enumerate() {
            failures.extend(compare_normal(
                a,
                b,
                1e-5,
                &format!("{label} group {g}, host"),
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Records split over several textures (segments, each a submission of its own) give
/// the result of one texture: where the segments hold whole tiles, the very same bits
/// (each tile's partial sums are the same and the host adds them in the same order).
#[test]
fn records_split_over_several_textures_give_the_unsplit_result() {
    let data = measured_like(Kind::Brdf, 3, 3000, 5);
    for (spec, loss) in [
        ("fa(eon)", Loss::new(Metric::Chi2, Weights::Uniform)),
        ("rmg(ggx)", Loss::new(Metric::Logf, Weights::Uniform)),
    ] {
        let model = Model::parse(spec, 3).unwrap();
        let loss = if loss.metric.applies_to(Kind::Brdf) {
            loss
        } else {
            Loss::new(Metric::Ngan, Weights::Relunc)
        };
        let problem = Problem {
            model: &model,
            data: &data,
            loss,
        };
        let p = model.dim;
        let params: Vec<f64> = random_unit(p, 5, 50)
            .chunks(p)
            .flat_map(|u| model.from_unit(u))
            .collect();
        let (phys, steps) = groups(&model, &random_unit(p, 3, 51), 1e-3);
        for shape in [Shape::CPU_DEVICE_TILED, Shape::GPU_DEVICE] {
            for device_normal in [true, false] {
                let one = gpu()
                    .with_shape(shape)
                    .with_tile(128)
                    .with_device_normal(device_normal);
                let split = gpu()
                    .with_shape(shape)
                    .with_tile(128)
                    .with_device_normal(device_normal)
                    .with_segment_records(1024);
                let (mut a, mut b) = (
                    one.prepare(problem).unwrap(),
                    split.prepare(problem).unwrap(),
                );
                let label = format!("{spec} {shape:?} device normal {device_normal}");
                assert_eq!(
                    a.costs(&params).unwrap(),
                    b.costs(&params).unwrap(),
                    "{label}: costs"
                );
                assert_eq!(
                    a.values(&params).unwrap(),
                    b.values(&params).unwrap(),
                    "{label}: values"
                );
                let (na, nb) = (
                    a.normal_equations(&phys, &steps).unwrap(),
                    b.normal_equations(&phys, &steps).unwrap(),
                );
                for (g, (x, y)) in na.iter().zip(&nb).enumerate() {
                    if device_normal {
                        assert_eq!(x, y, "{label}: group {g}");
                    } else {
                        // The host reduces each window's values in blocks: the same values,
                        // summed in another order.
                        let bad = compare_normal(x, y, 1e-12, &format!("{label}: group {g}"));
                        assert!(bad.is_empty(), "{}", bad.join("\n"));
                    }
                }
                // The split really happened: a submission per segment.
                let count = |g: &GpuBackend| g.submissions().unwrap().submissions;
                assert!(count(&split) >= 3 * count(&one), "{label}: submissions");
            }
        }
    }
}
