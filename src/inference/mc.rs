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
use crate::choice::field_error;
use crate::data::Dataset;
use crate::engine::loss::{Loss, Term};
use crate::engine::Backend;
use crate::inference::fit::{fit_many, FitOptions, ManyStats};
pub use crate::inference::mc_summary::{shortest_interval, McParam, McSummary, COVERAGE};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::time::Instant;

/// Monte Carlo and linearized standard deviations that differ by more than this factor
/// (either way) get a warning.
pub const DISAGREEMENT: f64 = 1.5;

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

/// Refit N replicas of `data` and summarise the distribution of the free parameters.
/// `best` is the fit of the measured data and `linear_std` its linearized standard
/// uncertainties (flat, None where undetermined). Also returns the replicas' fitted flat
/// vectors (those that converged), for quantities derived from several parameters (the
/// tabulated factors' knots, [`crate::inference::knots::mc_bands`]).
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
) -> anyhow::Result<(McSummary, Vec<Vec<f64>>)> {
    if mc.replicas < 2 {
        return Err(field_error("{mc} needs at least 2 replicas"));
    }
    if !(mc.scale_rel.is_finite() && (0.0..1.0).contains(&mc.scale_rel)) {
        return Err(field_error(format!(
            "{{mc_scale}} must be a relative uncertainty in [0, 1), got {}",
            mc.scale_rel
        )));
    }
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
    let fitted = good.iter().map(|f| f.to_vec()).collect();
    let summary = McSummary {
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
    };
    Ok((summary, fitted))
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
    use crate::data::{Kind, RawRow, ReadOptions};
    use crate::engine::cpu::CpuBackend;
    use crate::engine::loss::{Metric, Weights};
    use crate::inference::fit::Optimizer;
    use std::f64::consts::PI;

    /// BRDF samples at one wavelength: (value, uncertainty) at assorted angles.
    fn data(rows: &[(f64, f64)]) -> Dataset {
        let rows: Vec<(usize, RawRow)> = rows
            .iter()
            .enumerate()
            .map(|(i, &(value, uncertainty))| {
                let row = RawRow {
                    theta_i: 5.0 + 10.0 * i as f64,
                    phi_i: 0.0,
                    theta_o: 30.0,
                    phi_o: 180.0,
                    wavelength_nm: 550.0,
                    value,
                    uncertainty,
                };
                (i + 1, row)
            })
            .collect();
        Dataset::from_rows(Kind::Brdf, "d", &rows, "d.csv", &ReadOptions::default()).unwrap()
    }

    fn chi2() -> Loss {
        Loss::new(Metric::Chi2, Weights::Uniform)
    }

    /// Lambert's χ² optimum in closed form, ρ̂ = π Σ(y/u²)/Σ(1/u²), held in [lo, hi].
    fn rho_hat(d: &Dataset, [lo, hi]: [f64; 2]) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for s in &d.samples {
            num += s.value / (s.uncertainty * s.uncertainty);
            den += 1.0 / (s.uncertainty * s.uncertainty);
        }
        (PI * num / den).clamp(lo, hi)
    }

    /// ρ fitted within `bounds` (`--bounds`).
    fn run(d: &Dataset, bounds: [f64; 2], linear: f64, replicas: usize, seed: u64) -> McSummary {
        let model = Model::for_data("lambert", d).unwrap();
        let opts = FitOptions {
            optimizer: Optimizer::Lm,
            restarts: 1,
            screen: 1,
            constraints: crate::inference::constraints::ConstraintSpec::parse(
                &[],
                &[format!("rho={}:{}", bounds[0], bounds[1])],
                &[],
                false,
            )
            .unwrap(),
            ..FitOptions::default()
        };
        let mc = McOptions {
            replicas,
            scale_rel: 0.0,
            seed,
            restarts: 1,
        };
        let best = [rho_hat(d, bounds)];
        let backend = CpuBackend::new();
        monte_carlo(
            &model,
            d,
            chi2(),
            &backend,
            &opts,
            &best,
            &[Some(linear)],
            &mc,
            &mut |_| {},
        )
        .unwrap()
        .0
    }

    /// Each replica of a Lambert χ² fit has its optimum in closed form: the summary's
    /// mean, standard deviation (n − 1), shortest 95 % interval (19 of 20 values) and
    /// share of replicas on a bound are those of the replicas' ρ̂, drawn again here.
    #[test]
    fn lambert_replicas_summarise_to_their_closed_form_optima() {
        // ρ inside [0, 1]; then within --bounds rho=0.05:0.95, ρ̂ near each end, where
        // about half the replicas end on the bound.
        let (wide, narrow) = ([0.0, 1.0], [0.05, 0.95]);
        for (rows, bounds, seed, bound) in [
            (
                &[(0.10, 0.004), (0.11, 0.006), (0.095, 0.005), (0.102, 0.008)][..],
                wide,
                7,
                false,
            ),
            (
                &[(0.016, 0.01), (0.015, 0.012), (0.017, 0.01)][..],
                narrow,
                3,
                true,
            ),
            (
                &[(0.3025, 0.01), (0.304, 0.012), (0.301, 0.01)][..],
                narrow,
                4,
                true,
            ),
        ] {
            let d = data(rows);
            let n = 20;
            let sum = run(&d, bounds, 0.01, n, seed);
            let mut reps: Vec<f64> = ReplicaSource::new(&d, chi2(), 0.0, seed)
                .draw(n)
                .iter()
                .map(|r| rho_hat(r, bounds))
                .collect();
            let mean = reps.iter().sum::<f64>() / n as f64;
            let sd = (reps.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
            let on_bound = (reps.iter())
                .filter(|&&r| r == bounds[0] || r == bounds[1])
                .count() as f64
                / n as f64;
            reps.sort_by(f64::total_cmp);
            let widths: Vec<f64> = (0..2).map(|i| reps[i + 18] - reps[i]).collect();
            let lo = if widths[1] < widths[0] { 1 } else { 0 };
            let interval = [reps[lo], reps[lo + 18]];
            let p = &sum.params[0];
            let tol = 1e-4 * sd;
            assert_eq!((sum.replicas, sum.converged), (n, n));
            assert_eq!(p.value, rho_hat(&d, bounds));
            assert!(sum.evaluations > 0 && sum.batches > 0, "{sum:?}");
            let failed = sum.warnings.iter().any(|w| w.contains("no finite fit"));
            assert!(!failed, "{:?}", sum.warnings);
            assert_eq!(p.linear_sd, Some(0.01));
            assert!((p.mean - mean).abs() < tol, "mean {} vs {mean}", p.mean);
            assert!((p.sd - sd).abs() < tol, "sd {} vs {sd}", p.sd);
            assert!(
                (p.interval[0] - interval[0]).abs() < tol,
                "{:?} vs {interval:?}",
                p.interval
            );
            assert!(
                (p.interval[1] - interval[1]).abs() < tol,
                "{:?} vs {interval:?}",
                p.interval
            );
            assert_eq!(p.on_bound, on_bound);
            assert_eq!(sum.correlation, vec![vec![Some(1.0)]]);
            let warned = sum.warnings.iter().any(|w| w.contains("on a bound"));
            assert_eq!(warned, on_bound >= 0.05, "{:?}", sum.warnings);
            if bound {
                assert!(on_bound > 0.2 && on_bound < 0.8, "{on_bound}");
            } else {
                assert_eq!(on_bound, 0.0);
            }
        }
    }

    /// y* = (y + u z)(1 + s z₀): mean y, standard deviation u per value; the scale draw
    /// z₀ shared by all values of a replica; log losses floor the draws at 0.
    #[test]
    fn replica_draws_have_the_stated_distribution() {
        let n = 4000;
        let one = data(&[(10.0, 1.0)]);
        let v: Vec<f64> = (ReplicaSource::new(&one, chi2(), 0.0, 5).draw(n).iter())
            .map(|r| r.samples[0].value)
            .collect();
        let mean = v.iter().sum::<f64>() / n as f64;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
        assert!((mean - 10.0).abs() < 0.07, "{mean}");
        assert!((sd - 1.0).abs() < 0.05, "{sd}");
        // Values with negligible uncertainty and a 10 % scale: each replica is the data
        // times one factor 1 + 0.1 z₀.
        let two = data(&[(10.0, 1e-4), (20.0, 2e-4)]);
        let reps = ReplicaSource::new(&two, chi2(), 0.1, 5).draw(n);
        let first: Vec<f64> = reps.iter().map(|r| r.samples[0].value).collect();
        for r in &reps {
            let ratio = r.samples[1].value / r.samples[0].value;
            assert!((ratio - 2.0).abs() < 1e-3, "{ratio}");
        }
        let mean = first.iter().sum::<f64>() / n as f64;
        let sd = (first.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
        assert!(
            (mean - 10.0).abs() < 0.07 && (sd - 1.0).abs() < 0.05,
            "{mean} {sd}"
        );
        // A value 0.1 ± 1: about 46 % of the draws fall below 0; a log loss floors them.
        let low = data(&[(0.1, 1.0)]);
        let logf = Loss::new(Metric::Logf, Weights::Uniform);
        for (loss, floored) in [(chi2(), false), (logf, true)] {
            let v: Vec<f64> = (ReplicaSource::new(&low, loss, 0.0, 5).draw(n).iter())
                .map(|r| r.samples[0].value)
                .collect();
            let below = v.iter().filter(|&&x| x < 0.0).count() as f64 / n as f64;
            let zero = v.iter().filter(|&&x| x == 0.0).count() as f64 / n as f64;
            if floored {
                assert!(below == 0.0 && (zero - 0.46).abs() < 0.04, "{below} {zero}");
            } else {
                assert!((below - 0.46).abs() < 0.04 && zero == 0.0, "{below} {zero}");
            }
        }
    }

    #[test]
    fn shortest_intervals_by_hand() {
        // Four values, half of them: [0, 5] 5 wide, [5, 9] 4, [9, 10] 1.
        assert_eq!(shortest_interval(&[0.0, 5.0, 9.0, 10.0], 0.5), [9.0, 10.0]);
        // Three of five: [0, 2] and [1, 3] equally short: the first.
        assert_eq!(
            shortest_interval(&[0.0, 1.0, 2.0, 3.0, 10.0], 0.6),
            [0.0, 2.0]
        );
        // All of them, one of them, none.
        assert_eq!(shortest_interval(&[1.0, 2.0, 4.0], 1.0), [1.0, 4.0]);
        assert_eq!(shortest_interval(&[1.0, 2.0, 4.0], 0.01), [1.0, 1.0]);
        assert!(shortest_interval(&[], 0.95).iter().all(|v| v.is_nan()));
    }

    #[test]
    fn pearson_correlation_by_hand() {
        // Deviations (−1.5, −0.5, 0.5, 1.5) and (−1.5, 0.5, −0.5, 1.5): 4/5.
        let a = [1.0, 2.0, 3.0, 4.0];
        assert!((correlation(&a, &[1.0, 3.0, 2.0, 4.0]).unwrap() - 0.8).abs() < 1e-15);
        assert!((correlation(&a, &[2.0, 4.0, 6.0, 8.0]).unwrap() - 1.0).abs() < 1e-15);
        assert!((correlation(&a, &[8.0, 6.0, 4.0, 2.0]).unwrap() + 1.0).abs() < 1e-15);
        // Shifted: the means are subtracted.
        assert!(
            (correlation(&[11.0, 12.0, 13.0, 14.0], &[1.0, 3.0, 2.0, 4.0]).unwrap() - 0.8).abs()
                < 1e-12
        );
        assert_eq!(correlation(&a, &[3.0; 4]), None);
    }

    /// Each warning's condition at and beside its threshold.
    #[test]
    fn disagreement_warnings_at_their_thresholds() {
        let param = |sd: f64, linear: Option<f64>, value: f64, on_bound: f64| McParam {
            name: "p".into(),
            value,
            mean: value,
            sd,
            interval: [0.0, 3.0],
            linear_sd: linear,
            on_bound,
        };
        let says = |p: McParam, what: &str| disagreement(&p).is_some_and(|w| w.contains(what));
        assert!(says(param(1.0, Some(1.0), 1.5, 0.05), "on a bound"));
        assert!(disagreement(&param(1.0, Some(1.0), 1.5, 0.049)).is_none());
        assert!(says(param(1.0, None, 1.5, 0.0), "undetermined"));
        // Factors up to 1.5 either way are agreement.
        assert!(disagreement(&param(1.5, Some(1.0), 1.5, 0.0)).is_none());
        assert!(disagreement(&param(1.0, Some(1.5), 1.5, 0.0)).is_none());
        assert!(says(
            param(1.51, Some(1.0), 1.5, 0.0),
            "differ by a factor 1.51"
        ));
        assert!(says(
            param(1.0, Some(1.51), 1.5, 0.0),
            "differ by a factor 0.66"
        ));
        // [1, 4] about 2: 1 below, 2 above, a ratio of 2 is not "more than 2".
        let shifted = |value: f64| McParam {
            interval: [1.0, 4.0],
            ..param(1.0, Some(1.0), value, 0.0)
        };
        assert!(disagreement(&shifted(2.0)).is_none());
        assert!(disagreement(&shifted(3.0)).is_none());
        assert!(says(shifted(1.9), "asymmetric"));
        assert!(says(shifted(3.1), "asymmetric"));
        // A best fit on an end of the interval is not judged by the ratio.
        assert!(disagreement(&shifted(1.0)).is_none());
        assert!(disagreement(&shifted(4.0)).is_none());
    }

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
