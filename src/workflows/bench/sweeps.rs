//! `bench --sweep`: whole sweeps timed on each backend, and two sweeps' results compared
//! (rankings, best losses, parameters) against the tolerances stated below.

use crate::bsdf::Model;
use crate::output::results::Row;
use serde::Serialize;
use std::collections::BTreeMap;

/// Stated agreement expected between the f64 CPU and f32 GPU sweeps.
///
/// Best losses: 1e-3 relative (the costs themselves agree to ~1e-6 with the compensated
/// sums; the rest is where each optimizer stops: the searches differentiate with
/// unit-box steps of ≈ 1e-3, though LM fits end with an f64 polish). Fits whose losses
/// differ by more reached different local optima: which basin a restart falls into is
/// multi-start's chance, which the CPU shows against itself with another seed too, not
/// an f32 error; they are counted, and their parameters not compared. Models whose
/// losses agree within the loss tolerance are tied in the rankings.
///
/// Parameters, at one optimum: 1e-2 of their search box (unit-box coordinates, so a
/// log-scaled roughness is compared relatively), the resolution those steps give, or
/// 0.05 of their standard uncertainty where that is looser. Why the second: along a
/// direction the data leave loose (a parameter whose σ is most of its box, or one the
/// data determine only in combination with others) the loss changes by (δ/σ)² in units
/// of χ², 2.5e-3 at 0.05 σ, below any optimizer's stopping test, so two engines that stop
/// at the same loss may differ there by more than 1e-2 of the box; and 0.05 σ is far
/// below anything the fit claims about the parameter.
pub const SWEEP_LOSS_TOL: f64 = 1e-3;
pub const SWEEP_PARAM_TOL: f64 = 1e-2;
pub const SWEEP_PARAM_TOL_SIGMA: f64 = 0.05;

/// One backend's sweep, timed end to end (fits and results files; no pictures).
#[derive(Clone, Debug, Serialize)]
pub struct SweepTiming {
    pub backend: String,
    pub wall_seconds: f64,
    pub fits: usize,
    pub evaluations: u64,
    pub evals_per_s: f64,
    /// The device submissions (absent for the CPU reference).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub submissions: Option<crate::engine::SubmissionStats>,
    /// Thread-seconds per phase of fitting, summed over the sweep's workers.
    pub phases: crate::inference::fit::PhaseSeconds,
}

impl SweepTiming {
    pub fn new(
        backend: &str,
        wall_seconds: f64,
        rows: &[Row],
        submissions: Option<crate::engine::SubmissionStats>,
        phases: crate::inference::fit::PhaseSeconds,
    ) -> SweepTiming {
        let evaluations: u64 = rows.iter().map(|r| r.evaluations).sum();
        SweepTiming {
            backend: backend.to_string(),
            wall_seconds,
            fits: rows.len(),
            evaluations,
            evals_per_s: evaluations as f64 / wall_seconds.max(1e-9),
            submissions,
            phases,
        }
    }
}

/// A (data set, loss, weighting) in which the backends order two models oppositely and
/// at least one of them by more than the loss tolerance.
#[derive(Clone, Debug, Serialize)]
pub struct RankingDifference {
    pub data: String,
    pub loss: String,
    pub weights: String,
    pub cpu: Vec<String>,
    pub gpu: Vec<String>,
    /// The inverted pairs, `better < worse` as the CPU orders them, with both losses.
    pub inverted: Vec<InvertedPair>,
}

/// Two models that the backends order oppositely: the CPU's better one first.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct InvertedPair {
    pub better_on_cpu: String,
    pub better_on_gpu: String,
    /// The two best losses (CPU's better model first) on the CPU, then on the GPU.
    pub cpu_losses: [f64; 2],
    pub gpu_losses: [f64; 2],
}

/// A best loss for ordering: NaN (a failed fit) as +∞, last.
fn order_key(x: f64) -> f64 {
    if x.is_nan() {
        f64::INFINITY
    } else {
        x
    }
}

/// Whether `a` is better than `b` by more than `tol` relative (NaN counts as +∞).
fn decisively_below(a: f64, b: f64, tol: f64) -> bool {
    let (a, b) = (order_key(a), order_key(b));
    a < b && (b == f64::INFINITY || b - a > tol * a.abs().max(b.abs()))
}

/// The pairs of one group's models (name, best loss on the CPU, on the GPU) that the two
/// backends order oppositely with a gap above `tol` on at least one of them. Models whose
/// losses lie within `tol` are tied: a model that reduces to another (`dmg(on)` with no
/// grains is `on`) has the same optimum, and which of the two the last digit puts first
/// is noise, on one backend as between two.
pub fn inverted_pairs(models: &[(String, f64, f64)], tol: f64) -> Vec<InvertedPair> {
    let mut out = Vec::new();
    for (a, ca, ga) in models {
        for (b, cb, gb) in models {
            let (kca, kcb) = (order_key(*ca), order_key(*cb));
            let cpu_first = kca < kcb || (kca == kcb && a < b);
            if !cpu_first {
                continue;
            }
            let gpu_reversed = order_key(*gb) < order_key(*ga);
            let decisive = decisively_below(*ca, *cb, tol) || decisively_below(*gb, *ga, tol);
            if gpu_reversed && decisive {
                out.push(InvertedPair {
                    better_on_cpu: a.clone(),
                    better_on_gpu: b.clone(),
                    cpu_losses: [*ca, *cb],
                    gpu_losses: [*ga, *gb],
                });
            }
        }
    }
    out
}

/// Where a largest difference occurred.
#[derive(Clone, Debug, Default, Serialize)]
pub struct DiffAt {
    pub value: f64,
    /// `data · model · loss/weights [· parameter]`
    pub at: String,
}

#[derive(Clone, Debug, Serialize)]
pub struct SweepComparison {
    /// Fits present in both sweeps (same data, model, loss, weights, optimizer).
    pub fits_compared: usize,
    /// Per data set × loss × weighting, models ordered by best loss (ties broken by
    /// name): identical orders?
    pub rankings_identical: bool,
    /// Groups whose order so defined differs, ties included.
    pub groups_reordered: usize,
    /// No two models ordered oppositely by the backends with a gap above the loss
    /// tolerance on either: the rankings are the same up to ties within it.
    pub rankings_agree_up_to_ties: bool,
    /// The groups where they do not, with the inverted pairs.
    pub ranking_differences: Vec<RankingDifference>,
    /// Largest |gpu − cpu| / max(|cpu|, |gpu|) of the best losses (∞ if one is not finite).
    pub max_rel_loss_diff: DiffAt,
    /// Largest difference of a fitted parameter in its unit-box coordinate, over the fits
    /// whose best losses agree within the loss tolerance and the parameters both
    /// backends determined (finite standard uncertainty smaller than the range).
    pub max_param_diff_unit_box: DiffAt,
    /// The same comparison in units of the parameter's standard uncertainty (the larger
    /// of the two backends').
    pub max_param_diff_sigma: DiffAt,
    /// The largest parameter difference over its tolerance, min(unit-box difference /
    /// `param_tolerance`, σ difference / `param_tolerance_sigma`): at most 1 where every
    /// compared parameter is within its tolerance.
    pub max_param_diff_over_tolerance: DiffAt,
    /// Fits whose best losses differ beyond the loss tolerance (different optima): their
    /// parameters are not compared.
    pub fits_at_different_optima: usize,
    /// Of those, the fits whose best loss is lower on the second sweep (the GPU's).
    pub different_optima_lower_on_gpu: usize,
    /// Parameter values not compared because a backend left them undetermined.
    pub params_undetermined: usize,
    pub loss_tolerance: f64,
    pub param_tolerance: f64,
    pub param_tolerance_sigma: f64,
    /// Every parameter compared (fits at one optimum, determined by both) is within its
    /// tolerance. Fits at different optima are counted above, not judged here.
    pub within_tolerance: bool,
}

type FitId = (String, String, String, String, String);

fn fit_id(r: &Row) -> FitId {
    (
        r.data.clone(),
        r.model.clone(),
        r.loss.clone(),
        r.weights.clone(),
        r.optimizer.clone(),
    )
}

/// The models of each (data, loss, weights) group, ordered by best loss (NaN last, then
/// by name, so that the order is total).
fn rankings(rows: &[Row]) -> BTreeMap<(String, String, String), Vec<String>> {
    let mut groups: BTreeMap<(String, String, String), Vec<(f64, String)>> = BTreeMap::new();
    for r in rows {
        groups
            .entry((r.data.clone(), r.loss.clone(), r.weights.clone()))
            .or_default()
            .push((r.best_loss, r.model.clone()));
    }
    groups
        .into_iter()
        .map(|(k, mut v)| {
            v.sort_by(|a, b| {
                order_key(a.0)
                    .total_cmp(&order_key(b.0))
                    .then_with(|| a.1.cmp(&b.1))
            });
            (k, v.into_iter().map(|(_, m)| m).collect())
        })
        .collect()
}

fn rel_diff(c: f64, g: f64) -> f64 {
    if c == g {
        return 0.0;
    }
    if !(c.is_finite() && g.is_finite()) {
        return f64::INFINITY;
    }
    (g - c).abs() / c.abs().max(g.abs())
}

/// A fitted value of a results row: its name (`rho[1]` for an array entry), unit-box
/// coordinate, and whether the fit determined it (a finite standard uncertainty smaller
/// than the parameter's declared range; null where the normal matrix is singular).
#[derive(Clone, Debug)]
struct UnitParam {
    name: String,
    unit: f64,
    value: f64,
    std: Option<f64>,
    determined: bool,
}

/// `g`'s anisotropic frames turned into the form nearest `c`'s: (α_u, α_v, φ0) and
/// (α_v, α_u, φ0 ∓ 90°) are one surface, and a fit reports the form with |φ0| ≤ 45°
/// (`Model::canonical_form`), so two fits of one surface whose φ0 lies near ±45° can
/// report the two forms; compared as they stand they would differ by 90° in φ0.
fn align_frames(model: &str, c: &[UnitParam], g: &mut [UnitParam]) {
    let Ok(m) = Model::parse(model, 1) else {
        return;
    };
    let (names, decls) = (m.flat_names(), m.flat_decls());
    let at = |v: &[UnitParam], k: usize| v.iter().position(|p| p.name == names[k]);
    for [u, v, phi] in m.frames() {
        let (Some(cphi), Some(gu), Some(gv), Some(gphi)) =
            (at(c, phi), at(g, u), at(g, v), at(g, phi))
        else {
            continue;
        };
        let (pc, pg) = (c[cphi].value, g[gphi].value);
        let turned = pg - 90f64.copysign(pg);
        if (turned - pc).abs() < (pg - pc).abs() {
            let (a, b) = (g[gu].clone(), g[gv].clone());
            g[gu] = UnitParam { name: a.name, ..b };
            g[gv] = UnitParam { name: b.name, ..a };
            g[gphi].value = turned;
            g[gphi].unit = decls[phi].to_unit(turned);
        }
    }
}

/// A results row's fitted values ([`UnitParam`]), in the JSON's order.
fn unit_params(r: &Row) -> Vec<UnitParam> {
    let Ok(model) = Model::parse(&r.model, 1) else {
        return Vec::new();
    };
    let decls: BTreeMap<String, crate::bsdf::ParamDecl> = model
        .flat_names()
        .into_iter()
        .zip(model.flat_decls())
        .map(|(n, d)| (n.split(['[', '@']).next().unwrap_or("").to_string(), d))
        .collect();
    let object = |json: &str| match serde_json::from_str::<serde_json::Value>(json) {
        Ok(serde_json::Value::Object(map)) => map,
        _ => serde_json::Map::new(),
    };
    let (values, stds) = (object(&r.params), object(&r.param_std));
    // Entry i of a value (the value itself for a scalar).
    let entry = |v: Option<&serde_json::Value>, i: Option<usize>| -> Option<f64> {
        match (v?, i) {
            (serde_json::Value::Array(a), Some(i)) => a.get(i)?.as_f64(),
            (v, None) => v.as_f64(),
            _ => None,
        }
    };
    let mut out = Vec::new();
    for (name, v) in &values {
        let Some(d) = decls.get(name) else { continue };
        let indices: Vec<Option<usize>> = match v {
            serde_json::Value::Array(a) => (0..a.len()).map(Some).collect(),
            _ => vec![None],
        };
        for i in indices {
            let Some(x) = entry(Some(v), i) else { continue };
            let std = entry(stds.get(name), i);
            out.push(UnitParam {
                name: i.map_or(name.clone(), |i| format!("{name}[{i}]")),
                unit: d.to_unit(x),
                value: x,
                std,
                determined: std.is_some_and(|s| s.is_finite() && s < d.hi - d.lo),
            });
        }
    }
    out
}

/// How the per-group model rankings (data set × loss × weighting, models by best loss)
/// of two sweeps differ: the number of groups ordered differently, and those whose
/// difference is more than ties (a pair inverted beyond the loss tolerance, or a model
/// fitted on one side only).
fn ranking_differences(cpu: &[Row], gpu: &[Row]) -> (usize, Vec<RankingDifference>) {
    let (rc, rg) = (rankings(cpu), rankings(gpu));
    let best_losses = |rows: &[Row]| -> BTreeMap<(String, String, String, String), f64> {
        rows.iter()
            .map(|r| {
                let id = (
                    r.data.clone(),
                    r.model.clone(),
                    r.loss.clone(),
                    r.weights.clone(),
                );
                (id, r.best_loss)
            })
            .collect()
    };
    let (cpu_loss, gpu_loss) = (best_losses(cpu), best_losses(gpu));
    let mut reordered = 0;
    let mut diffs = Vec::new();
    for (k, order) in &rc {
        let other = rg.get(k).cloned().unwrap_or_default();
        if &other == order {
            continue;
        }
        reordered += 1;
        let group: Vec<(String, f64, f64)> = order
            .iter()
            .filter_map(|m| {
                let id = (k.0.clone(), m.clone(), k.1.clone(), k.2.clone());
                let (c, g) = (cpu_loss.get(&id)?, gpu_loss.get(&id)?);
                Some((m.clone(), *c, *g))
            })
            .collect();
        let inverted = inverted_pairs(&group, SWEEP_LOSS_TOL);
        // A model fitted on one backend only is a difference too.
        if !inverted.is_empty() || group.len() != order.len() || other.len() != order.len() {
            diffs.push(RankingDifference {
                data: k.0.clone(),
                loss: k.1.clone(),
                weights: k.2.clone(),
                cpu: order.clone(),
                gpu: other,
                inverted,
            });
        }
    }
    for (k, order) in &rg {
        if !rc.contains_key(k) {
            reordered += 1;
            diffs.push(RankingDifference {
                data: k.0.clone(),
                loss: k.1.clone(),
                weights: k.2.clone(),
                cpu: Vec::new(),
                gpu: order.clone(),
                inverted: Vec::new(),
            });
        }
    }
    (reordered, diffs)
}

/// Compare a CPU and a GPU sweep of the same tasks.
pub fn compare_sweeps(cpu: &[Row], gpu: &[Row]) -> SweepComparison {
    let gpu_by: BTreeMap<FitId, &Row> = gpu.iter().map(|r| (fit_id(r), r)).collect();
    let mut compared = 0;
    let (mut different_optima, mut undetermined) = (0, 0);
    let mut loss = DiffAt::default();
    let mut param = DiffAt::default();
    let mut param_sigma = DiffAt::default();
    let mut param_excess = DiffAt::default();
    let mut lower_on_gpu = 0;
    for c in cpu {
        let Some(g) = gpu_by.get(&fit_id(c)) else {
            continue;
        };
        compared += 1;
        let where_ = format!("{} · {} · {}/{}", c.data, c.model, c.loss, c.weights);
        let d = rel_diff(c.best_loss, g.best_loss);
        if d > loss.value || (d.is_nan() && !loss.value.is_nan()) {
            loss = DiffAt {
                value: d,
                at: where_.clone(),
            };
        }
        // Parameters are compared where both backends reached one optimum (the loss
        // difference above reports the others), and only those both determined: one
        // the data leave free takes any value at the same loss.
        if d.is_nan() || d > SWEEP_LOSS_TOL {
            different_optima += 1;
            lower_on_gpu += usize::from(order_key(g.best_loss) < order_key(c.best_loss));
            continue;
        }
        let (pcs, mut pgs) = (unit_params(c), unit_params(g));
        align_frames(&c.model, &pcs, &mut pgs);
        for (pc, pg) in pcs.into_iter().zip(pgs) {
            if !(pc.determined && pg.determined) {
                undetermined += 1;
                continue;
            }
            let at = || format!("{where_} · {}", pc.name);
            let larger =
                |d: f64, worst: &DiffAt| d > worst.value || (d.is_nan() && !worst.value.is_nan());
            let d_box = (pg.unit - pc.unit).abs();
            if larger(d_box, &param) {
                param = DiffAt {
                    value: d_box,
                    at: at(),
                };
            }
            let sigma = pc.std.unwrap_or(0.0).max(pg.std.unwrap_or(0.0));
            let d_sigma = (pg.value - pc.value).abs() / sigma;
            if larger(d_sigma, &param_sigma) {
                param_sigma = DiffAt {
                    value: d_sigma,
                    at: at(),
                };
            }
            // Within if either measure is (a NaN measure counts as out of bounds).
            let over = |d: f64, tol: f64| if d.is_nan() { f64::INFINITY } else { d / tol };
            let excess = over(d_box, SWEEP_PARAM_TOL).min(over(d_sigma, SWEEP_PARAM_TOL_SIGMA));
            if larger(excess, &param_excess) {
                param_excess = DiffAt {
                    value: excess,
                    at: at(),
                };
            }
        }
    }
    let (reordered, diffs) = ranking_differences(cpu, gpu);
    let within = param_excess.value <= 1.0;
    SweepComparison {
        fits_compared: compared,
        rankings_identical: reordered == 0,
        groups_reordered: reordered,
        rankings_agree_up_to_ties: diffs.is_empty(),
        ranking_differences: diffs,
        max_rel_loss_diff: loss,
        max_param_diff_unit_box: param,
        max_param_diff_sigma: param_sigma,
        max_param_diff_over_tolerance: param_excess,
        fits_at_different_optima: different_optima,
        different_optima_lower_on_gpu: lower_on_gpu,
        params_undetermined: undetermined,
        loss_tolerance: SWEEP_LOSS_TOL,
        param_tolerance: SWEEP_PARAM_TOL,
        param_tolerance_sigma: SWEEP_PARAM_TOL_SIGMA,
        within_tolerance: within,
    }
}

/// The `sweep` section of `bench --json`.
#[derive(Clone, Debug, Serialize)]
pub struct SweepBench {
    pub data: Vec<String>,
    pub restarts: usize,
    pub backends: Vec<SweepTiming>,
    /// GPU wall time ÷ CPU wall time (null unless both ran).
    pub gpu_cpu_time_ratio: Option<f64>,
    /// Null unless both backends ran.
    pub comparison: Option<SweepComparison>,
    /// SIMD wall time ÷ CPU wall time (null unless both ran).
    pub simd_cpu_time_ratio: Option<f64>,
    /// The SIMD engine's sweep (the `gpu` side) against the CPU reference's; null unless
    /// both ran.
    pub simd_comparison: Option<SweepComparison>,
    /// `--sweep-reference-seed`: the CPU reference's sweep with another seed, compared
    /// with its first (absent without it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_seed: Option<ReferenceSeed>,
}

/// The CPU reference's sweep with a second seed against its first: multi-start variance
/// alone. In `comparison`, the `cpu` side is the first sweep and the `gpu` side the
/// second.
#[derive(Clone, Debug, Serialize)]
pub struct ReferenceSeed {
    pub seed: u64,
    pub wall_seconds: f64,
    pub comparison: SweepComparison,
}

/// One backend's timed sweep: its rows, wall seconds, and what it measured of itself
/// (device submissions, time per phase).
pub type TimedSweep = (Vec<Row>, f64, crate::workflows::sweep::SweepStats);

/// Run the sweep `cfg` into a fresh temporary folder (its `out` is replaced; the folder
/// is removed afterwards) and time it: `bench --sweep`.
pub fn timed_sweep(
    cfg: crate::workflows::sweep::SweepConfig,
    obs: &mut dyn crate::workflows::sweep::SweepObserver,
) -> anyhow::Result<TimedSweep> {
    use anyhow::Context;
    let backend = cfg.backend.name();
    let dir = std::env::temp_dir().join(format!(
        "bsdfit-bench-sweep-{}-{backend}-{}",
        std::process::id(),
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0)
    ));
    std::fs::create_dir_all(&dir).with_context(|| {
        format!(
            "--sweep: cannot create the temporary folder {}",
            dir.display()
        )
    })?;
    let cfg = crate::workflows::sweep::SweepConfig {
        out: dir.clone(),
        ..cfg
    };
    let result = (|| {
        obs.note(&format!(
            "bench --sweep: sweep on {backend} (seed {}) into {}",
            cfg.seed,
            dir.display()
        ));
        let t0 = std::time::Instant::now();
        let stats = crate::workflows::sweep::run(&cfg, obs)?;
        let wall = t0.elapsed().as_secs_f64();
        let rows = crate::output::results::read_results(
            &dir.join(crate::output::results::RESULTS_CSV),
            false,
            &mut |m| obs.note(&format!("note: {m}")),
        )?;
        Ok((rows, wall, stats))
    })();
    if let Err(e) = std::fs::remove_dir_all(&dir) {
        obs.note(&format!("note: could not remove {}: {e}", dir.display()));
    }
    result
}

/// `bench --sweep`: the sweep `base` once on each of `backends` (CPU first), timed and compared; with `reference_seed`, the CPU reference's sweep once more
/// with that seed, compared with its first (the spread of multi-start search alone).
pub fn sweep_bench(
    base: &crate::workflows::sweep::SweepConfig,
    backends: &[crate::engine::BackendChoice],
    reference_seed: Option<u64>,
    obs: &mut dyn crate::workflows::sweep::SweepObserver,
) -> anyhow::Result<SweepBench> {
    use crate::engine::BackendChoice;
    use anyhow::Context;
    let data = crate::workflows::sweep::expand_data(&base.data).context("--sweep-data")?;
    let on = |backend: BackendChoice, seed: u64| crate::workflows::sweep::SweepConfig {
        backend,
        seed,
        ..base.clone()
    };
    let mut timings = Vec::new();
    let mut results = Vec::new();
    for &backend in backends {
        let id = backend.name();
        let (rows, wall, stats) = timed_sweep(on(backend, base.seed), obs)
            .with_context(|| format!("--sweep on {id} (seed {})", base.seed))?;
        timings.push(SweepTiming::new(
            id,
            wall,
            &rows,
            stats.submissions,
            stats.phases,
        ));
        results.push((id, rows));
    }
    let find = |id: &str| timings.iter().find(|t| t.backend == id);
    let ratio = match (find("cpu"), find("gpu")) {
        (Some(c), Some(g)) => Some(g.wall_seconds / c.wall_seconds.max(1e-9)),
        _ => None,
    };
    let rows_of = |id: &str| results.iter().find(|(b, _)| *b == id).map(|(_, r)| r);
    let comparison = match (rows_of("cpu"), rows_of("gpu")) {
        (Some(c), Some(g)) => Some(compare_sweeps(c, g)),
        _ => None,
    };
    let simd_cpu_time_ratio = match (find("cpu"), find("simd")) {
        (Some(c), Some(s)) => Some(s.wall_seconds / c.wall_seconds.max(1e-9)),
        _ => None,
    };
    let simd_comparison = match (rows_of("cpu"), rows_of("simd")) {
        (Some(c), Some(s)) => Some(compare_sweeps(c, s)),
        _ => None,
    };
    let reference_seed = match (reference_seed, rows_of("cpu")) {
        (Some(seed), Some(first)) => {
            let (rows, wall, _) = timed_sweep(on(BackendChoice::Cpu, seed), obs)
                .with_context(|| format!("--sweep on cpu (seed {seed})"))?;
            Some(ReferenceSeed {
                seed,
                wall_seconds: wall,
                comparison: compare_sweeps(first, &rows),
            })
        }
        (Some(_), None) => {
            obs.note("note: --sweep-reference-seed needs the CPU reference's sweep; skipped");
            None
        }
        (None, _) => None,
    };
    Ok(SweepBench {
        data: data.iter().map(|p| p.display().to_string()).collect(),
        restarts: base.restarts,
        backends: timings,
        gpu_cpu_time_ratio: ratio,
        comparison,
        simd_cpu_time_ratio,
        simd_comparison,
        reference_seed,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::ParamDecl;

    fn group(v: &[(&str, f64, f64)]) -> Vec<(String, f64, f64)> {
        v.iter().map(|&(m, c, g)| (m.to_string(), c, g)).collect()
    }

    #[test]
    fn ties_within_the_tolerance_are_not_inversions() {
        // dmg(on) reduces to on: equal optima whose last digits order them differently.
        let g = group(&[
            ("on", 2.0000001, 2.0),
            ("dmg(on)", 2.0, 2.0000002),
            ("lambert", 3.0, 3.0),
        ]);
        assert!(inverted_pairs(&g, 1e-3).is_empty());
        // A gap of 5e-4 relative on one backend only is still within 1e-3.
        let g = group(&[("a", 1.0, 1.0005), ("b", 1.0005, 1.0)]);
        assert!(inverted_pairs(&g, 1e-3).is_empty());
    }

    #[test]
    fn a_decisive_gap_on_either_backend_is_an_inversion() {
        // The CPU puts a 2 % ahead; the GPU, stuck 3 % higher, puts it behind b.
        let g = group(&[("a", 1.0, 1.03), ("b", 1.02, 1.02), ("c", 2.0, 2.0)]);
        let inv = inverted_pairs(&g, 1e-3);
        assert_eq!(inv.len(), 1, "{inv:?}");
        assert_eq!(inv[0].better_on_cpu, "a");
        assert_eq!(inv[0].better_on_gpu, "b");
        assert_eq!(inv[0].cpu_losses, [1.0, 1.02]);
        assert_eq!(inv[0].gpu_losses, [1.03, 1.02]);
        // Decisive on the GPU only (CPU tie, GPU gap): an inversion too.
        let g = group(&[("a", 1.0, 1.01), ("b", 1.0, 1.0)]);
        assert_eq!(inverted_pairs(&g, 1e-3).len(), 1);
        // A NaN loss ranks last; finite against NaN is decisive.
        let g = group(&[("a", 1.0, f64::NAN), ("b", 2.0, 2.0)]);
        assert_eq!(inverted_pairs(&g, 1e-3).len(), 1);
    }

    /// A results row of `vmf` (ρ per channel, r in [0, 1]) with the given loss,
    /// parameters and standard uncertainties (JSON).
    fn vmf_row(data: &str, loss: f64, params: &str, std: &str) -> Row {
        Row {
            data: data.into(),
            data_hash: String::new(),
            data_path: String::new(),
            kind: "brdf".into(),
            material: String::new(),
            model: "vmf".into(),
            loss: "rmse".into(),
            weights: "uniform".into(),
            optimizer: "lm".into(),
            restarts: 8,
            seed: 1,
            samples: 100,
            n_params: 4,
            best_loss: loss,
            chi2_red: 1.0,
            restarts_within_1pct: 8,
            evaluations: 1,
            params: params.into(),
            param_std: std.into(),
            warnings: "[]".into(),
            seconds: 0.0,
            backend: String::new(),
            constraints: String::new(),
        }
    }

    #[test]
    fn parameters_are_compared_at_one_optimum_where_both_determine_them() {
        let p = |rho1: f64, r: f64| format!(r#"{{"rho":[0.2,{rho1},0.4],"r":{r}}}"#);
        let determined = r#"{"rho":[0.01,0.01,0.01],"r":0.02}"#;
        // r undetermined on the GPU (singular: null), ρ[1] off by 0.05.
        let r_free = r#"{"rho":[0.01,0.01,0.01],"r":null}"#;
        let cpu = [
            vmf_row("a", 1.0, &p(0.30, 0.2), determined),
            vmf_row("b", 1.0, &p(0.30, 0.2), determined),
            vmf_row("c", 1.0, &p(0.30, 0.2), determined),
        ];
        let gpu = [
            // Same optimum, r free on the GPU: r's 0.6 is not compared, ρ[1]'s 0.05 is.
            vmf_row("a", 1.0 + 1e-6, &p(0.35, 0.8), r_free),
            // Another optimum (2 % higher): its parameters are not compared.
            vmf_row("b", 1.02, &p(0.9, 0.9), determined),
            // Same optimum, the same parameters.
            vmf_row("c", 1.0, &p(0.30, 0.2), determined),
        ];
        let c = compare_sweeps(&cpu, &gpu);
        assert_eq!(c.fits_compared, 3);
        assert_eq!(c.fits_at_different_optima, 1);
        assert_eq!(c.params_undetermined, 1);
        let rho = ParamDecl::rgb("rho", 0.0, 1.0, 0.5, "").quadratic_hi();
        let expected = (rho.to_unit(0.35) - rho.to_unit(0.30)).abs();
        assert!(
            (c.max_param_diff_unit_box.value - expected).abs() < 1e-12,
            "{:?}",
            c.max_param_diff_unit_box
        );
        assert!(
            c.max_param_diff_unit_box.at.ends_with("rho[1]"),
            "{:?}",
            c.max_param_diff_unit_box
        );
        // 0.05 in ρ[1] against σ = 0.01: 5σ.
        assert!(
            (c.max_param_diff_sigma.value - 5.0).abs() < 1e-9,
            "{:?}",
            c.max_param_diff_sigma
        );
        assert!(c.max_rel_loss_diff.value > 0.019 && c.max_rel_loss_diff.at.starts_with("b "));
        // The GPU's other optimum is the higher one.
        assert_eq!(c.different_optima_lower_on_gpu, 0);
        // ρ[1]: 5σ, and several hundredths of the box: out of both tolerances.
        assert!(
            c.max_param_diff_over_tolerance.value > 1.0
                && c.max_param_diff_over_tolerance.at.ends_with("rho[1]"),
            "{:?}",
            c.max_param_diff_over_tolerance
        );
        assert!(!c.within_tolerance);
    }

    /// Two fits of one anisotropic surface with φ0 near 45°, one in each form
    /// ((α_u, α_v, φ0) and (α_v, α_u, φ0 − 90°)): within tolerance once aligned; the same
    /// numbers without the swap of the roughnesses are another surface, and are not.
    #[test]
    fn the_two_forms_of_an_anisotropic_frame_are_one_surface() {
        let row = |params: &str| Row {
            model: "ggx+aniso".into(),
            ..vmf_row(
                "a",
                1.0,
                params,
                r#"{"ks":[0.01,0.01,0.01],"alpha_u":0.01,"alpha_v":0.01,"phi0":1.0,"eta":0.05}"#,
            )
        };
        let p = |au: f64, av: f64, phi: f64| {
            format!(
                r#"{{"ks":[0.2,0.3,0.4],"alpha_u":{au},"alpha_v":{av},"phi0":{phi},"eta":1.5}}"#
            )
        };
        let cpu = [row(&p(0.1, 0.3, 44.9))];
        let c = compare_sweeps(&cpu, &[row(&p(0.3, 0.1, -45.05))]);
        assert!(c.within_tolerance, "{:?}", c.max_param_diff_over_tolerance);
        assert!(
            c.max_param_diff_unit_box.value < 1e-3,
            "{:?}",
            c.max_param_diff_unit_box
        );
        let c = compare_sweeps(&cpu, &[row(&p(0.1, 0.3, -45.05))]);
        assert!(!c.within_tolerance, "{:?}", c.max_param_diff_over_tolerance);
    }

    #[test]
    fn a_loose_parameter_is_within_tolerance_at_a_small_fraction_of_its_sigma() {
        let p = |r: f64| format!(r#"{{"rho":[0.2,0.3,0.4],"r":{r}}}"#);
        // r's σ is 0.9 of its box [0, 1]: the data barely determine it.
        let loose = r#"{"rho":[0.01,0.01,0.01],"r":0.9}"#;
        let cpu = [vmf_row("a", 1.0, &p(0.50), loose)];
        // 0.03 apart, beyond the box tolerance in unit-box terms, but 0.033 σ: within.
        let gpu = [vmf_row("a", 1.0, &p(0.53), loose)];
        let c = compare_sweeps(&cpu, &gpu);
        assert!(c.max_param_diff_unit_box.value > SWEEP_PARAM_TOL);
        assert!(c.max_param_diff_sigma.value < SWEEP_PARAM_TOL_SIGMA);
        assert!(c.max_param_diff_over_tolerance.value <= 1.0);
        assert!(c.within_tolerance);
        // 0.1 of the box is 0.11 σ: out of both.
        let gpu = [vmf_row("a", 1.0, &p(0.60), loose)];
        let c = compare_sweeps(&cpu, &gpu);
        assert!(c.max_param_diff_over_tolerance.value > 1.0);
        assert!(!c.within_tolerance);
    }
}
