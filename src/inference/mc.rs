//! Parameter uncertainty by Monte Carlo (the propagation of distributions of the GUM's
//! Supplement 1, JCGM 101:2008): N replicas of the data, each value drawn from its stated
//! distribution, all refitted together ([`fit_many`]: replicas × restarts step in lockstep,
//! one backend submission per optimizer step), and the fitted parameters' distribution
//! summarised per parameter by its mean, standard deviation and 95 % shortest coverage
//! interval (JCGM 101 §7.7.2), with the correlation matrix.
//!
//! Replica values: y*_k = (y_k + u_k z_k)(1 + s z₀), z ~ N(0, 1) independent, z₀ one draw per
//! replica shared by all its values (`--mc-scale s`, an instrument's fully correlated
//! relative scale uncertainty; 0 by default). Each replica is fitted from the best fit of
//! the measured data plus `restarts` screened random starts (the same draws as the fit).
//!
//! The linearized standard uncertainties (the covariance at the optimum) are reported
//! beside; where the two disagree by more than [`DISAGREEMENT`] (either way), or the
//! interval is strongly asymmetric about the best fit, or ends on a declared bound, the
//! summary warns: the linear error is then not a coverage interval.

use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::{Loss, Term};
use crate::engine::Backend;
use crate::inference::fit::{fit_many, FitOptions, ManyStats};
pub use crate::inference::mc_summary::{McParam, McSummary};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::time::Instant;

/// Monte Carlo and linearized standard deviations that differ by more than this factor
/// (either way) get a warning.
pub const DISAGREEMENT: f64 = 1.5;
/// Coverage probability of the reported intervals.
pub const COVERAGE: f64 = 0.95;

#[derive(Clone, Debug)]
pub struct McOptions {
    /// Number of replicas N.
    pub replicas: usize,
    /// Fully correlated relative scale uncertainty s (0: none).
    pub scale_rel: f64,
    /// Seed of the replicas' draws.
    pub seed: u64,
    /// Random restarts per replica, besides the best fit of the measured data.
    pub restarts: usize,
}

/// Samples held in memory at once across replicas: larger runs are refitted in chunks.
const MAX_REPLICA_SAMPLES: usize = 4_000_000;

/// Draws replica data sets of `data` (see the module doc), `count` at a time.
pub struct ReplicaSource<'a> {
    data: &'a Dataset,
    scale_rel: f64,
    floor: Option<f64>,
    rng: ChaCha8Rng,
    normal: Normal<f64>,
}

impl<'a> ReplicaSource<'a> {
    pub fn new(data: &'a Dataset, loss: Loss, scale_rel: f64, seed: u64) -> Self {
        ReplicaSource {
            data,
            scale_rel,
            // log(1 + a·y) needs a·y > −1: log losses get their draws floored at 0.
            floor: (loss.metric.term() == Term::LogSquare).then_some(0.0),
            rng: ChaCha8Rng::seed_from_u64(seed),
            normal: Normal::new(0.0, 1.0).expect("unit normal"),
        }
    }

    pub fn draw(&mut self, count: usize) -> Vec<Dataset> {
        (0..count)
            .map(|_| {
                let scale = 1.0 + self.scale_rel * self.normal.sample(&mut self.rng);
                let mut r = self.data.clone();
                for s in &mut r.samples {
                    let z = self.normal.sample(&mut self.rng);
                    let v = (s.value + s.uncertainty * z) * scale;
                    s.value = self.floor.map_or(v, |f| v.max(f));
                }
                r
            })
            .collect()
    }
}

/// Shortest interval holding `p` of the sorted values (JCGM 101 §7.7.2).
pub fn shortest_interval(sorted: &[f64], p: f64) -> [f64; 2] {
    let n = sorted.len();
    if n == 0 {
        return [f64::NAN, f64::NAN];
    }
    let q = ((p * n as f64).round() as usize).clamp(1, n);
    let mut best = [sorted[0], sorted[q - 1]];
    for i in 0..=n - q {
        if sorted[i + q - 1] - sorted[i] < best[1] - best[0] {
            best = [sorted[i], sorted[i + q - 1]];
        }
    }
    best
}

/// Refit N replicas of `data` and summarise the distribution of the free parameters.
/// `best` is the fit of the measured data and `linear_std` its linearized standard
/// uncertainties (flat, None where undetermined).
#[allow(clippy::too_many_arguments)]
pub fn monte_carlo(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    backend: &dyn Backend,
    opts: &FitOptions,
    best: &[f64],
    linear_std: &[Option<f64>],
    mc: &McOptions,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<McSummary> {
    anyhow::ensure!(mc.replicas >= 2, "--mc needs at least 2 replicas");
    anyhow::ensure!(
        mc.scale_rel.is_finite() && (0.0..1.0).contains(&mc.scale_rel),
        "--mc-scale must be a relative uncertainty in [0, 1), got {}",
        mc.scale_rel
    );
    let t0 = Instant::now();
    let mut rep_opts = opts.clone();
    rep_opts.restarts = mc.restarts.max(1);
    rep_opts.initial_points = vec![best.to_vec()];
    let mut source = ReplicaSource::new(data, loss, mc.scale_rel, mc.seed);
    let chunk = (MAX_REPLICA_SAMPLES / data.len().max(1)).clamp(1, mc.replicas);
    let (mut optima, mut stats) = (Vec::with_capacity(mc.replicas), ManyStats::default());
    let mut space = None;
    let per = rep_opts.restarts + 1;
    while optima.len() < mc.replicas {
        let done = optima.len();
        let reps = source.draw(chunk.min(mc.replicas - done));
        let refs: Vec<&Dataset> = reps.iter().collect();
        let losses = vec![loss; reps.len()];
        let (o, sp, st) = fit_many(model, &refs, &losses, backend, &rep_opts, &mut |active| {
            // Restarts of earlier chunks have all converged.
            progress(active + (mc.replicas - done - reps.len()) * per)
        })?;
        optima.extend(o);
        stats.evaluations += st.evaluations;
        stats.batches += st.batches;
        space = Some(sp);
    }
    let space = space.expect("at least one chunk");
    let good: Vec<&Vec<f64>> = optima
        .iter()
        .filter(|o| o.loss.is_finite())
        .map(|o| &o.flat)
        .collect();
    let mut warnings = Vec::new();
    if good.len() < optima.len() {
        warnings.push(format!(
            "{} of {} replicas found no finite fit and were left out",
            optima.len() - good.len(),
            optima.len()
        ));
    }
    anyhow::ensure!(good.len() >= 2, "fewer than 2 replicas could be fitted");
    let names = model.flat_names();
    let free = &space.free;
    let n = good.len() as f64;
    let mut columns: Vec<Vec<f64>> = Vec::with_capacity(free.len());
    let mut params = Vec::with_capacity(free.len());
    for &j in free {
        let mut col: Vec<f64> = good.iter().map(|f| f[j]).collect();
        let mean = col.iter().sum::<f64>() / n;
        let sd = (col.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        let (lo, hi) = (space.decls[j].lo, space.decls[j].hi);
        // f32 backends stop within a few ulps of a bound: 1e-6 of the range counts as on it.
        let tol = 1e-6 * (hi - lo).abs().max(1e-300);
        let on_bound = col
            .iter()
            .filter(|&&v| (v - lo).abs() <= tol || (hi - v).abs() <= tol)
            .count() as f64
            / n;
        columns.push(col.clone());
        col.sort_by(f64::total_cmp);
        let interval = shortest_interval(&col, COVERAGE);
        let p = McParam {
            name: names[j].clone(),
            value: best[j],
            mean,
            sd,
            interval,
            linear_sd: linear_std.get(j).copied().flatten(),
            on_bound,
        };
        warnings.extend(disagreement(&p));
        params.push(p);
    }
    let correlation = columns
        .iter()
        .map(|a| columns.iter().map(|b| correlation(a, b)).collect())
        .collect();
    Ok(McSummary {
        replicas: mc.replicas,
        converged: good.len(),
        scale_rel: mc.scale_rel,
        seed: mc.seed,
        restarts_per_replica: rep_opts.restarts,
        coverage: COVERAGE,
        params,
        correlation,
        warnings,
        seconds: t0.elapsed().as_secs_f64(),
        evaluations: stats.evaluations,
        batches: stats.batches,
    })
}

/// Where the linearized standard uncertainty is not a coverage interval (module doc).
fn disagreement(p: &McParam) -> Option<String> {
    let [lo, hi] = p.interval;
    if p.on_bound >= 0.05 {
        return Some(format!(
            "{}: {:.0} % of the replicas end on a bound of its range; its interval [{lo:.4}, {hi:.4}] is bounded, and the linearized σ does not describe it",
            p.name,
            100.0 * p.on_bound
        ));
    }
    let Some(lin) = p.linear_sd else {
        return Some(format!(
            "{}: the linearized σ is undetermined; Monte Carlo gives σ = {:.3e}, 95 % in [{lo:.4}, {hi:.4}]",
            p.name, p.sd
        ));
    };
    let ratio = p.sd / lin.max(1e-300);
    if !(1.0 / DISAGREEMENT..=DISAGREEMENT).contains(&ratio) {
        return Some(format!(
            "{}: Monte Carlo σ = {:.3e} and linearized σ = {lin:.3e} differ by a factor {ratio:.2} (more than {DISAGREEMENT}): use the Monte Carlo interval [{lo:.4}, {hi:.4}]",
            p.name, p.sd
        ));
    }
    let (below, above) = (p.value - lo, hi - p.value);
    if below > 0.0 && above > 0.0 && (below / above).max(above / below) > 2.0 {
        return Some(format!(
            "{}: the 95 % interval [{lo:.4}, {hi:.4}] is asymmetric about the best fit {:.4} (−{below:.3e}, +{above:.3e}); ±2σ would misstate it",
            p.name, p.value
        ));
    }
    None
}

fn correlation(a: &[f64], b: &[f64]) -> Option<f64> {
    let n = a.len() as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma) * (x - ma);
        sbb += (y - mb) * (y - mb);
    }
    let d = (saa * sbb).sqrt();
    (d > 0.0).then(|| (sab / d).clamp(-1.0, 1.0))
}

impl McSummary {
    /// The human-readable table of the fit's summary.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "  Monte Carlo ({} of {} replicas refitted{}, {} restarts each, {:.2} s, {} evaluations):\n",
            self.converged,
            self.replicas,
            if self.scale_rel > 0.0 {
                format!(", scale uncertainty {}", self.scale_rel)
            } else {
                String::new()
            },
            self.restarts_per_replica + 1,
            self.seconds,
            self.evaluations
        );
        s += &format!(
            "    {:<14} {:>12} {:>12} {:>11} {:>11}  {:<27}\n",
            "parameter", "best", "mean", "σ (MC)", "σ (linear)", "95 % shortest interval"
        );
        for p in &self.params {
            let lin = p
                .linear_sd
                .map_or("undetermined".to_string(), |v| format!("{v:.3e}"));
            s += &format!(
                "    {:<14} {:>12.6} {:>12.6} {:>11.3e} {:>11}  [{:.6}, {:.6}]\n",
                p.name, p.value, p.mean, p.sd, lin, p.interval[0], p.interval[1]
            );
        }
        for w in &self.warnings {
            s += &format!("  warning (Monte Carlo): {w}\n");
        }
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shortest_interval_of_a_skewed_sample_hugs_the_mode() {
        // Values 0..100 squared: dense near 0, so the shortest 50 % interval starts there.
        let v: Vec<f64> = (0..100).map(|i| (i as f64).powi(2)).collect();
        let [lo, hi] = shortest_interval(&v, 0.5);
        assert_eq!(lo, 0.0);
        assert_eq!(hi, 49.0f64.powi(2));
        // A symmetric sample: the central interval.
        let u: Vec<f64> = (0..101).map(|i| i as f64).collect();
        let [a, b] = shortest_interval(&u, 0.95);
        assert!((b - a - 95.0).abs() <= 1.0, "[{a}, {b}]");
    }
}
