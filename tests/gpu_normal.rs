//! Levenberg–Marquardt normal equations reduced on the device (shaders/engine/normal.wgsl)
//! against the host reduction (`engine::normal_equations_of_values`, the reference rule)
//! of the **same** f32 model values, read back from the same evaluator. Runs on whatever
//! Vulkan adapter exists — lavapipe in CI; a missing adapter fails the test.
//!
//! Bound, derived from f32 arithmetic (U = 2⁻²⁴, f32's unit roundoff). The host forms,
//! in f64 from the f32 values y′, r_k = √w_k (g(y′_0k) − g(y_k)) and d_jk = √w_k (g(y′_jk) −
//! g(y′_0k)) = h_j J_kj, the latter as a difference of two residuals, so to within
//! 4 ε64 √w_k (|g(y′_jk)| + |g(y′_0k)| + 2 |g(y_k)|) (ε64 = 2⁻⁵³), which is added to the
//! device's error below (the device differences g(y′) directly and keeps changes the
//! host's f64 rounds away). The device's d_jk carries a relative error of
//! at most 5.5 U (w, √w, a each rounded to f32 once, the difference, the two products) and
//! r_k one of 3.5 U plus an absolute 2 U √w_k a_k (|y′_0k| + |y_k|) (a y′ and g(y) rounded
//! to f32 before they cancel). For the logarithmic losses both also carry log1p's
//! absolute error, 2.2e-6 |ln(1 + a y′)| per value (shaders/engine/loss.wgsl). A device sum
//! Σ u_k v_k (u, v each an r or a d) then errs by at most
//!   Σ_k (|u_k| ε_v,k + |v_k| ε_u,k + ε_u,k ε_v,k) + 3 U Σ_k |u_k v_k|
//! (the product's rounding, and a Neumaier-compensated or pairwise-compensated sum's
//! 2 U |Σ| + O(K U²) Σ|t|). The tests allow twice that, divided by the steps as the host
//! divides. NaN never passes unless the host has NaN at the same entry; an infinite entry
//! must be the same infinity.

use bsdfit::bsdf::Model;
use bsdfit::data::{bundled_data_dir, Dataset, ReadOptions};
use bsdfit::engine::gpu::GpuBackend;
use bsdfit::engine::loss::{Loss, LossTerms, Metric, Term, Weights};
use bsdfit::engine::wgsl::{normal_entries, Shape};
use bsdfit::engine::{normal_equations_of_values, Backend, Problem};
use bsdfit::optim::{difference_points, NormalEquations};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// f32's unit roundoff.
const U: f64 = 1.0 / 16_777_216.0;
/// f64's unit roundoff: the host reference's resolution.
const E64: f64 = f64::EPSILON / 2.0;
/// log1p_f32's error relative to |ln(1 + x)| (loss.wgsl), plus a few U.
const LOG_REL: f64 = 2.2e-6 + 4.0 * U;
/// LM's forward-difference step on an f32 backend: 4 √U (src/inference/fit.rs).
fn lm_step() -> f64 {
    4.0 * U.sqrt()
}

fn gpu(shape: Shape) -> GpuBackend {
    GpuBackend::new()
        .unwrap_or_else(|e| {
            panic!("no GPU adapter: {e}. These tests need Vulkan (CI installs mesa-vulkan-drivers for lavapipe).")
        })
        .with_shape(shape)
        .with_device_normal(true)
}

fn bundled(name: &str) -> Dataset {
    Dataset::read(&bundled_data_dir().join(name), &ReadOptions::default())
        .unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// LM's signed steps for unit-box points: +h, or −h where +h would leave the box.
fn lm_steps(points: &[f64], h: f64) -> Vec<f64> {
    points
        .iter()
        .map(|&x| if x + h <= 1.0 { h } else { -h })
        .collect()
}

/// The per-sample factors of one group as the host forms them (f64, from the f32 values),
/// with each one's error bound on the device: index 0 is r, index j ≥ 1 is d_{j−1}.
struct Factors {
    value: Vec<Vec<f64>>,
    error: Vec<Vec<f64>>,
}

fn factors(vals: &[f64], t: &LossTerms, p: usize) -> Factors {
    let k = t.y.len();
    let log = t.term == Term::LogSquare;
    let y0 = &vals[..k];
    let mut value = vec![vec![0.0; k]; p + 1];
    let mut error = vec![vec![0.0; k]; p + 1];
    for m in 0..k {
        let rw = t.w[m].sqrt();
        let g0 = t.transform(m, y0[m]);
        let gy = t.transform(m, t.y[m]);
        value[0][m] = rw * (g0 - gy);
        let abs_r = if log {
            rw * (LOG_REL * g0.abs() + U * gy.abs())
        } else {
            2.0 * U * rw * t.a[m] * (y0[m].abs() + t.y[m].abs())
        };
        error[0][m] = 3.5 * U * value[0][m].abs() + abs_r + 2.0 * E64 * rw * (g0.abs() + gy.abs());
        for j in 1..=p {
            let gj = t.transform(m, vals[j * k + m]);
            value[j][m] = rw * (gj - g0);
            let abs_d = if log {
                rw * LOG_REL * (gj.abs() + g0.abs())
            } else {
                0.0
            };
            let host = 4.0 * E64 * rw * (gj.abs() + g0.abs() + 2.0 * gy.abs());
            error[j][m] = 5.5 * U * value[j][m].abs() + abs_d + host;
        }
    }
    Factors { value, error }
}

/// Twice the error bound of the device's Σ u v (see the module doc).
fn sum_bound(f: &Factors, u: usize, v: usize) -> f64 {
    let (fu, fv, eu, ev) = (&f.value[u], &f.value[v], &f.error[u], &f.error[v]);
    let mut b = 0.0;
    for m in 0..fu.len() {
        b += fu[m].abs() * ev[m]
            + fv[m].abs() * eu[m]
            + eu[m] * ev[m]
            + 3.0 * U * (fu[m] * fv[m]).abs();
    }
    2.0 * b
}

/// One entry, device against host: the same NaN, the same infinity, or within `bound`.
fn entry_ok(dev: f64, host: f64, bound: f64) -> bool {
    if host.is_nan() || dev.is_nan() {
        return host.is_nan() && dev.is_nan();
    }
    if host.is_infinite() || dev.is_infinite() {
        return host == dev;
    }
    // A bound made of non-finite host factors says nothing: only equal values pass then.
    (dev - host).abs() <= bound || (!bound.is_finite() && dev == host)
}

/// Device-reduced normal equations of the groups at unit-box `points` (signed `steps`)
/// against the host's reduction of the same evaluator's f32 values; returns the mismatches
/// (empty when every entry passes), the device results and the values.
#[allow(clippy::too_many_arguments)]
fn compare_groups(
    backend: &GpuBackend,
    model: &Model,
    data: &Dataset,
    loss: Loss,
    phys: &[f64],
    steps: &[f64],
    label: &str,
) -> (Vec<String>, Vec<NormalEquations>, Vec<f64>) {
    let p = model.dim;
    let problem = Problem { model, data, loss };
    let mut ev = backend.prepare(problem).expect("evaluator");
    let dev = ev
        .normal_equations(phys, steps)
        .expect("device normal equations");
    let vals = ev.values(phys).expect("values");
    let terms = loss.terms(data);
    let n = steps.len() / p;
    let host = normal_equations_of_values(&vals, &[&terms], &vec![0; n], steps, p);
    let k = data.len();
    let mut bad = Vec::new();
    for (g, (d, h)) in dev.iter().zip(&host).enumerate() {
        let f = factors(&vals[g * (p + 1) * k..(g + 1) * (p + 1) * k], &terms, p);
        let hs = &steps[g * p..(g + 1) * p];
        for a in 0..p {
            for b in 0..p {
                let bound = sum_bound(&f, a + 1, b + 1) / (hs[a] * hs[b]).abs();
                let (x, y) = (d.jtj[a * p + b], h.jtj[a * p + b]);
                if !entry_ok(x, y, bound) {
                    bad.push(format!(
                        "{label} group {g} JᵀJ[{a}, {b}]: device {x:e} host {y:e} (bound {bound:.2e})"
                    ));
                }
            }
            let bound = sum_bound(&f, a + 1, 0) / hs[a].abs();
            if !entry_ok(d.jtr[a], h.jtr[a], bound) {
                bad.push(format!(
                    "{label} group {g} Jᵀr[{a}]: device {:e} host {:e} (bound {bound:.2e})",
                    d.jtr[a], h.jtr[a]
                ));
            }
        }
        let bound = sum_bound(&f, 0, 0);
        if !entry_ok(d.ss, h.ss, bound) {
            bad.push(format!(
                "{label} group {g} Σr²: device {:e} host {:e} (bound {bound:.2e})",
                d.ss, h.ss
            ));
        }
    }
    (bad, dev, vals)
}

/// Points at the edges of the box: the first two parameters (rmg's τ0 and β, its
/// roughness; the BTDF's scale S and lobe width α or β) at their bounds in every combination, with the other coordinates at 0, 1 or random; every corner where
/// all parameters sit at a bound (0/1 patterns); and random interior points.
fn edge_points(p: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let mut points = Vec::new();
    for tau in [0.0, 1.0] {
        for beta in [0.0, 1.0] {
            for rest in 0..3 {
                points.push(tau);
                points.push(beta);
                for _ in 2..p {
                    points.push(match rest {
                        0 => 0.0,
                        1 => 1.0,
                        _ => rng.random(),
                    });
                }
            }
        }
    }
    for _ in 0..12 {
        points.extend((0..p).map(|_| if rng.random::<bool>() { 1.0 } else { 0.0 }));
    }
    for _ in 0..12 {
        points.extend((0..p).map(|_| rng.random::<f64>()));
    }
    points
}

/// rmg(eon) (P = 10 on RGB data: 66 sums per group, added up in several blocks by the CPU
/// devices' form of the pass) at the edges of its box and inside it, on
/// bundled data, with LM's own step and signs, for the losses LM fits BRDFs with. The
/// device reduction was once removed for NaN Jacobian columns at rmg(eon) points; these
/// are the points to keep checking.
#[test]
fn rmg_eon_edge_points_match_the_host_reduction() {
    let mut failures = Vec::new();
    for shape in Shape::ALL {
        let backend = gpu(shape);
        for file in ["red-brick.csv", "w80-g40-full.csv", "black-velvet.csv"] {
            let data = bundled(file);
            let model = Model::parse("rmg(eon)", data.channel_count()).unwrap();
            let p = model.dim;
            assert!(
                normal_entries(p) > 16,
                "rmg(eon) should need several entry blocks"
            );
            let mut rng = ChaCha8Rng::seed_from_u64(7);
            let points = edge_points(p, &mut rng);
            let steps = lm_steps(&points, lm_step());
            let unit = difference_points(&points, &steps, p);
            let phys: Vec<f64> = unit.chunks(p).flat_map(|u| model.from_unit(u)).collect();
            for (metric, weights) in [
                (Metric::Chi2, Weights::Uniform),
                (Metric::Rmse, Weights::Relunc),
                (Metric::Ngan, Weights::Uniform),
            ] {
                let label = format!("{shape:?} {file} {metric}/{weights}");
                let loss = Loss::new(metric, weights);
                let (bad, dev, _) =
                    compare_groups(&backend, &model, &data, loss, &phys, &steps, &label);
                failures.extend(bad);
                // Every model value is finite here, so every sum must be.
                for (g, ne) in dev.iter().enumerate() {
                    if ne.jtj.iter().chain(&ne.jtr).any(|v| !v.is_finite()) || !ne.ss.is_finite() {
                        failures.push(format!("{label} group {g}: a non-finite sum"));
                    }
                }
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} device/host mismatches:\n{}",
        failures.len(),
        failures[..failures.len().min(40)].join("\n")
    );
}

/// The BTDF losses, the logarithmic ones included (log1p on the device), at the same kind
/// of edge points (scale and lobe width at their bounds), on the bundled diffuser data.
#[test]
fn btdf_edge_points_match_the_host_reduction() {
    let mut failures = Vec::new();
    for shape in Shape::ALL {
        let backend = gpu(shape);
        for (file, spec) in [
            ("diffuser-a.csv", "btdf(tr)+scale"),
            ("diffuser-d.csv", "btdf(gg)+scale"),
        ] {
            let data = bundled(file);
            let model = Model::parse(spec, data.channel_count()).unwrap();
            let p = model.dim;
            let mut rng = ChaCha8Rng::seed_from_u64(8);
            let points = edge_points(p, &mut rng);
            let steps = lm_steps(&points, lm_step());
            let unit = difference_points(&points, &steps, p);
            let phys: Vec<f64> = unit.chunks(p).flat_map(|u| model.from_unit(u)).collect();
            for metric in [Metric::F, Metric::Logf, Metric::Logcosf, Metric::Chi2] {
                let label = format!("{shape:?} {file} {spec} {metric}");
                let loss = Loss::new(metric, Weights::Invunc);
                let (bad, _, _) =
                    compare_groups(&backend, &model, &data, loss, &phys, &steps, &label);
                failures.extend(bad);
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} device/host mismatches:\n{}",
        failures.len(),
        failures[..failures.len().min(20)].join("\n")
    );
}

/// Non-finite model values follow the host's f64 rule: a NaN or ±∞ value at a moved
/// candidate j spoils row and column j of JᵀJ and Jᵀr_j (as NaN or ±∞, 0·∞ = NaN, ∞ − ∞ =
/// NaN), one at the point spoils everything and Σr² reads +∞. The values are made
/// non-finite by physical parameters outside any bound (NaN, +∞), which the evaluator takes
/// as given. (Parameters the WGSL clamps — rmg's τ0, β and η_g — turn a NaN into a bound
/// on the device, so their values stay finite: the checks below follow the values.)
#[test]
fn non_finite_values_follow_the_host_rule() {
    let data = bundled("red-brick.csv");
    let k = data.len();
    let mut failures = Vec::new();
    for shape in Shape::ALL {
        let backend = gpu(shape);
        for spec in ["lambert", "rmg(eon)"] {
            let model = Model::parse(spec, data.channel_count()).unwrap();
            let p = model.dim;
            let mut rng = ChaCha8Rng::seed_from_u64(3);
            let point: Vec<f64> = (0..p).map(|_| rng.random_range(0.2..0.8)).collect();
            // Group 0: clean. Group 1 + 2j: NaN in candidate j + 1's parameter j. Group
            // 2 + 2j: +∞ there. Last group: NaN in the point's last parameter (a base
            // albedo, never clamped).
            let n = 3 + 2 * p;
            let points = point.repeat(n);
            let steps = lm_steps(&points, lm_step());
            let unit = difference_points(&points, &steps, p);
            let mut phys: Vec<f64> = unit.chunks(p).flat_map(|u| model.from_unit(u)).collect();
            let at = |g: usize, c: usize, j: usize| (g * (p + 1) + c) * p + j;
            for j in 0..p {
                phys[at(1 + 2 * j, j + 1, j)] = f64::NAN;
                phys[at(2 + 2 * j, j + 1, j)] = f64::INFINITY;
            }
            phys[at(n - 1, 0, p - 1)] = f64::NAN;
            let loss = Loss::new(Metric::Chi2, Weights::Uniform);
            let label = format!("{shape:?} {spec}");
            let (bad, dev, vals) =
                compare_groups(&backend, &model, &data, loss, &phys, &steps, &label);
            failures.extend(bad);
            // Independently of the host code: a column with a NaN value has NaN sums, one
            // with only ±∞ non-finite ones (±∞, or NaN where ∞·0 or ∞ − ∞ occurs), a
            // clean one's sums with clean columns are finite.
            let row_has = |g: usize, c: usize, f: fn(&f64) -> bool| {
                let row = (g * (p + 1) + c) * k;
                vals[row..row + k].iter().any(f)
            };
            let has_nan = |g: usize, c: usize| row_has(g, c, |v| v.is_nan());
            let has_inf = |g: usize, c: usize| row_has(g, c, |v| v.is_infinite());
            let expect = |nan: bool, inf: bool, v: f64| {
                if nan {
                    v.is_nan()
                } else if inf {
                    !v.is_finite()
                } else {
                    v.is_finite()
                }
            };
            let mut spoiled_columns = 0;
            for (g, ne) in dev.iter().enumerate() {
                if has_nan(g, 0) {
                    if !(ne.jtj.iter().chain(&ne.jtr).all(|v| v.is_nan()) && ne.ss == f64::INFINITY)
                    {
                        failures.push(format!(
                            "{label} group {g}: a NaN point must spoil every sum"
                        ));
                    }
                    continue;
                }
                let nan_col: Vec<bool> = (0..p).map(|j| has_nan(g, j + 1)).collect();
                let inf_col: Vec<bool> = (0..p).map(|j| has_inf(g, j + 1)).collect();
                spoiled_columns += (0..p).filter(|&j| nan_col[j] || inf_col[j]).count();
                for a in 0..p {
                    for b in 0..p {
                        let v = ne.jtj[a * p + b];
                        if !expect(nan_col[a] || nan_col[b], inf_col[a] || inf_col[b], v) {
                            failures.push(format!("{label} group {g}: JᵀJ[{a}, {b}] = {v}"));
                        }
                    }
                    if !expect(nan_col[a], inf_col[a], ne.jtr[a]) {
                        failures.push(format!("{label} group {g}: Jᵀr[{a}] = {}", ne.jtr[a]));
                    }
                }
                if !ne.ss.is_finite() {
                    failures.push(format!("{label} group {g}: Σr² = {}", ne.ss));
                }
            }
            if !has_nan(n - 1, 0) || spoiled_columns < 3 {
                failures.push(format!(
                    "{label}: the injected parameters made too few NaN values to test anything ({spoiled_columns} columns)"
                ));
            }
        }
    }
    assert!(
        failures.is_empty(),
        "{} failures:\n{}",
        failures.len(),
        failures[..failures.len().min(40)].join("\n")
    );
}

/// With bindings so small that a group's values take many windows, each window is a
/// submission of its own (the device path reads back NE sums per group and tile of each
/// window, the host path each window's values), and a group's normal equations are the
/// f64 sum over its windows: within the f32 bound of `compare_groups` of the host's
/// reduction of the same values, and close to one submission's.
#[test]
fn small_bindings_split_groups_over_windows() {
    let data = bundled("red-brick.csv");
    let k = data.len();
    for (spec, device_path) in [
        ("rmg(eon)", true),
        ("rmg(eon)", false),
        ("rmg(eon)+retro", true),
    ] {
        let model = Model::parse(spec, data.channel_count()).unwrap();
        let p = model.dim;
        // A third of one group's values per binding.
        let binding = ((p + 1) * k * 4 / 3) as u64;
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = 9;
        let points: Vec<f64> = (0..n * p).map(|_| rng.random::<f64>()).collect();
        let steps = lm_steps(&points, lm_step());
        let unit = difference_points(&points, &steps, p);
        let phys: Vec<f64> = unit.chunks(p).flat_map(|u| model.from_unit(u)).collect();
        let loss = Loss::new(Metric::Chi2, Weights::Uniform);
        let problem = Problem {
            model: &model,
            data: &data,
            loss,
        };
        let reference = gpu(Shape::CPU_DEVICE)
            .prepare(problem)
            .unwrap()
            .normal_equations(&phys, &steps)
            .unwrap();
        let backend = gpu(Shape::CPU_DEVICE)
            .with_device_normal(device_path)
            .with_max_binding(binding);
        let label = format!("{spec}, device {device_path}, binding {binding} B");
        let (bad, dev, _) = compare_groups(&backend, &model, &data, loss, &phys, &steps, &label);
        assert!(bad.is_empty(), "{}", bad.join("\n"));
        for (g, (a, b)) in dev.iter().zip(&reference).enumerate() {
            for (x, y) in a.jtj.iter().chain(&a.jtr).zip(b.jtj.iter().chain(&b.jtr)) {
                assert!(
                    x.is_finite() && (x - y).abs() <= 1e-4 * y.abs() + 1e-4 * b.ss.abs().sqrt(),
                    "{label}: group {g}: {x} split, {y} in one submission"
                );
            }
        }
        let mut ev = backend.prepare(problem).unwrap();
        ev.normal_equations(&phys, &steps).unwrap();
        let one_submission = if device_path {
            n * normal_entries(p) * 4
        } else {
            n * (p + 1) * k * 4
        } as u64;
        if device_path {
            assert!(
                ev.read_back_bytes() >= 3 * one_submission,
                "{label}: {} bytes read back: not split into windows",
                ev.read_back_bytes()
            );
        } else {
            // Every value once, window after window (record slots: samples and padding).
            assert!(ev.read_back_bytes() >= one_submission, "{label}");
        }
    }
}
