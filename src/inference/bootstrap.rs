//! Extension tests calibrated by a parametric bootstrap.
//!
//! The F test of a nested extension assumes the regular case: the null model is the
//! extension at an interior point of its parameter space, where every parameter is
//! identified. Many extensions of the catalogue break it. Their null sits on a bound
//! (σ = 0 in `on`, k_s = 0 in `fa(B)`, k_r = 0 in `+retro`, β at its floor in `dmg`),
//! where the statistic follows a mixture that puts mass at 0 (Self & Liang 1987: the
//! nominal p-value is too large), or some of the extension's parameters vanish from the
//! model at the null (the lobe's α and η when k_s = 0), where the fit maximises over them
//! and the nominal p-value is too small (Davies 1987).
//!
//! The bootstrap draws B replicate data sets from the fitted null model with the stated
//! uncertainties (y*_k = y′_k + u_k z_k), refits the null and the extension to each (all
//! replicates in lockstep, [`fit_many`]), and compares the observed statistic
//! T = ΔP·F = Δχ² / (χ²₁/ν₁) with the replicates' T*_b (Davison & Hinkley 1997, §4.2):
//!
//! - where any replicate reaches T, the p-value is the empirical
//!   (1 + #{T*_b ≥ T}) / (B + 1), valid for any B (the observed data and the replicates are
//!   exchangeable under the null);
//! - where none does, the count only says p ≤ 1/(B + 1), and the p-value comes from a tail
//!   fitted to the replicates, capped at that bound: π · P(χ²_ν ≥ T/a), π the share of
//!   replicates with T*_b > 0 (the mass at 0 of a null on a bound), a·χ²_ν matched to the
//!   mean and variance of the positive T*_b (Satterthwaite's approximation, which the
//!   Self–Liang mixtures and the Davies sup statistics both follow in their tails to good
//!   accuracy). A test at a level below 1/(B + 1) thus rejects only when T exceeds every
//!   replicate, which happens with probability 1/(B + 1) under the null, and the tail
//!   decides within that: the fitted tail cannot make the test reject more often than
//!   the count allows. (A tail fitted to ~50 positive replicates is a noisy estimate;
//!   used wherever fewer than ten replicates reach T it rejected 2.8 % of null data sets
//!   at α = 0.01 in `tests/bootstrap.rs`.)
//!
//! The observed T is computed by the same procedure as the replicates' (the measured data
//! is refitted alongside them, as replicate 0): a statistic computed by one optimizer
//! setting and referred to a distribution computed by another is not calibrated — e.g.
//! at `on`'s null σ = 0 the gradient in σ vanishes, so a fit started there stays there
//! unless a random start finds the σ > 0 optimum, and more restarts on one side than the
//! other shift the whole distribution. Every extension refit starts from the data set's
//! own null optimum carried into the extension (so Δχ² ≥ 0), from the extension's optimum
//! on the measured data (found by the thorough fit: without it, a few restarts may miss a
//! many-parameter extension's optimum on the measured data and lose the test's power),
//! and from screened random starts.
//!
//! How many replicates: B is not fixed but drawn in batches, the test stopping as soon
//! as its verdict at the level is settled:
//!
//! - early, once h replicates reach T (h = max(10, ⌈level·(B + 1)⌉), B the planned
//!   replicates): the sequential p-value h/l of Besag & Clifford (1991), l the replicates
//!   drawn up to the h-th that reaches T, is exact, and it cannot fall below the level
//!   — a candidate that is far from significant is settled after about 2h replicates;
//! - at the planned B, by the count or the tail, the usual way;
//! - beyond B, where the planned B could not decide: no replicate reaches T, the bound
//!   1/(B + 1) is not below the level, and either too few replicates are positive to fit
//!   a tail or the fitted tail is within a factor of ten of the level (a tail fitted to a
//!   few dozen replicates and extrapolated beyond all of them: on one bundled diffuser,
//!   three seeds gave 1.6e-5, 7.5e-4 and a count p of 0.02 for one candidate at a level of
//!   2.5e-3, so near the level it is a coin, not a verdict). Then more replicates are drawn,
//!   doubling B, up to a stated maximum, until the count or a tail far from the level
//!   decides; a test still undecided there says so and why. Growing only when none reaches
//!   T keeps the count's decisions valid: it rejects only where the test at the final B,
//!   run from the start, would have.

use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::{Loss, Metric, Weights};
use crate::engine::Backend;
use crate::inference::fit::{fit_many, FitOptions, ManyStats, Optimizer, PhaseSeconds, Smoothness};
use crate::inference::mc::ReplicaSource;
use crate::math::chi2_sf;
use serde::Serialize;
use std::time::Instant;

/// Replicate statistics at or below this count as 0 (a nested extension that did not move
/// off its null, up to the optimizer's tolerance).
const ZERO: f64 = 1e-3;
/// Positive replicates needed to fit the tail.
const MIN_POSITIVE: usize = 10;
/// A fitted tail decides only this many times below or above the level (module doc).
const TAIL_MARGIN: f64 = 10.0;
/// Replicates reaching T that stop the test early (at least; module doc).
const SEQUENTIAL_H: usize = 10;
/// Replicates of the first batch: a candidate far from significance is settled there.
const FIRST_BATCH: usize = 24;
/// Replicates refitted in one lockstep call at most (bounds the memory of a batch).
const CHUNK: usize = 128;

/// How the bootstrap runs.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct BootstrapOptions {
    /// Planned replicates B (0: no bootstrap): the test stops before them where the
    /// verdict is settled early, and goes beyond them only where they cannot decide.
    pub replicates: usize,
    /// The most replicates drawn where the planned B cannot decide (module doc); at most
    /// `replicates` keeps B fixed.
    pub max_replicates: usize,
    /// Random restarts per replicate fit (at least 1), besides the carried-over optima.
    /// One: on the calibration test's null sets a second moved no p-value by more than
    /// sampling noise, and the carried-over optima find the replicates' optima.
    pub restarts: usize,
    pub seed: u64,
}

impl Default for BootstrapOptions {
    fn default() -> Self {
        BootstrapOptions {
            replicates: 99,
            max_replicates: 999,
            restarts: 1,
            seed: 1,
        }
    }
}

impl BootstrapOptions {
    /// The cumulative replicate counts after each batch: 24, then doubling up to the
    /// planned B, then doubling up to the maximum.
    pub fn schedule(&self) -> Vec<usize> {
        let planned = self.replicates;
        let mut out = vec![];
        let mut n = FIRST_BATCH.min(planned);
        while n < planned {
            out.push(n);
            n = (2 * n + 1).min(planned);
        }
        out.push(planned);
        let mut n = planned;
        while n < self.max_replicates {
            n = (2 * n + 1).min(self.max_replicates);
            out.push(n);
        }
        out
    }
}

/// Where a calibrated p-value came from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PSource {
    /// (1 + #{T*_b ≥ T}) / (B + 1).
    Empirical,
    /// h/l: stopped early once h replicates reached T (Besag & Clifford 1991).
    Sequential,
    /// π · P(χ²_ν ≥ T/a) fitted to the replicates.
    Tail,
    /// Too few positive replicates to fit a tail: the empirical bound 1/(B + 1) (or more).
    EmpiricalBound,
}

/// A bootstrap-calibrated p-value and what it rests on.
#[derive(Clone, Debug, Serialize)]
pub struct Calibrated {
    pub p: f64,
    pub source: PSource,
    /// The observed statistic T = Δχ² / (χ²₁/ν₁), from the measured data refitted by the
    /// replicates' procedure.
    pub statistic: f64,
    /// Replicates drawn and those whose two fits both ended finite (the counts use these).
    pub replicates: usize,
    pub fitted: usize,
    /// Replicates with T*_b ≥ T.
    pub exceeding: usize,
    /// Share π of replicates with T*_b > 0, and the fitted tail a·χ²_ν (None when not
    /// fitted).
    pub positive_share: f64,
    pub tail: Option<(f64, f64)>,
    /// The level the test was run for (its stopping rules depend on it).
    pub level: f64,
    /// The replicates drawn after each batch (the last is `replicates`).
    pub batches: Vec<usize>,
    /// Why the test could not decide at the level within the most replicates allowed
    /// (its p-value is then a bound above the level).
    pub undecided: Option<String>,
    pub seconds: f64,
    /// Model-sample evaluations of the refits (null and extension).
    pub evaluations: u64,
    /// Where the refits' time went (the extension's and every null refit's).
    pub phases: PhaseSeconds,
}

impl Calibrated {
    /// "bootstrap: 3 of 99 replicates reach T = …" and the like, per source.
    pub fn describe(&self) -> String {
        let head = match (self.source, self.tail) {
            (PSource::Tail, Some((a, nu))) => format!(
                "bootstrap: {} of {} replicates reach T = {:.4}; tail {:.2}·{:.3}·χ²_{:.2} fitted to them",
                self.exceeding, self.fitted, self.statistic, self.positive_share, a, nu
            ),
            (PSource::EmpiricalBound, _) => format!(
                "bootstrap: {} of {} replicates reach T = {:.4}, too few positive to fit a tail (p is a bound)",
                self.exceeding, self.fitted, self.statistic
            ),
            (PSource::Sequential, _) => format!(
                "bootstrap: {} of {} replicates reach T = {:.4}; stopped early, p = h/l cannot fall below the level",
                self.exceeding, self.fitted, self.statistic
            ),
            _ => format!(
                "bootstrap: {} of {} replicates reach T = {:.4}",
                self.exceeding, self.fitted, self.statistic
            ),
        };
        match &self.undecided {
            Some(why) => format!("{head}; undecided: {why}"),
            None => head,
        }
    }
}

/// T = Δχ² / (χ²₁/ν₁), Δχ² = χ²₀ − χ²₁ clipped at 0 (ΔP times the F statistic).
/// Values at or below [`ZERO`] are 0: the rounding of an extension fit that stayed at its
/// null must not count as an improvement, on the measured data or on a replicate.
pub fn statistic(chi2_null: f64, chi2_ext: f64, dof_ext: usize) -> f64 {
    let t = (chi2_null - chi2_ext).max(0.0) / (chi2_ext / dof_ext.max(1) as f64);
    if t > ZERO {
        t
    } else {
        0.0
    }
}

/// The p-value of `t` against the replicate statistics `reps` (module doc): the p-value,
/// its source, the share π of positive replicates and the fitted tail (a, ν).
pub fn p_value(t: f64, reps: &[f64]) -> (f64, PSource, f64, Option<(f64, f64)>) {
    let b = reps.len();
    let exceeding = reps.iter().filter(|&&r| r >= t).count();
    let empirical = (1 + exceeding) as f64 / (b + 1) as f64;
    let positive: Vec<f64> = reps.iter().copied().filter(|&r| r > ZERO).collect();
    let share = positive.len() as f64 / b.max(1) as f64;
    if exceeding > 0 {
        return (empirical, PSource::Empirical, share, None);
    }
    if positive.len() < MIN_POSITIVE {
        return (empirical, PSource::EmpiricalBound, share, None);
    }
    let n = positive.len() as f64;
    let mean = positive.iter().sum::<f64>() / n;
    let var = positive.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0);
    if var <= 0.0 || mean <= 0.0 {
        return (empirical, PSource::EmpiricalBound, share, None);
    }
    // a·χ²_ν has mean aν and variance 2a²ν.
    let a = var / (2.0 * mean);
    let nu = 2.0 * mean * mean / var;
    let tail = (share * chi2_sf(t / a, nu)).min(empirical);
    (tail, PSource::Tail, share, Some((a, nu)))
}

/// The count l of replicates up to and including the h-th with T*_b ≥ t (in drawing
/// order), if h of them reach t.
pub fn hth_exceedance(t: f64, reps: &[f64], h: usize) -> Option<usize> {
    let mut seen = 0;
    for (i, &r) in reps.iter().enumerate() {
        if r >= t {
            seen += 1;
            if seen == h {
                return Some(i + 1);
            }
        }
    }
    None
}

/// The replicates reaching T that stop a test at `level` planned with `planned`
/// replicates early: enough that h/l ≥ level for every l ≤ planned + 1.
pub fn sequential_h(level: f64, planned: usize) -> usize {
    SEQUENTIAL_H.max((level * (planned + 1) as f64).ceil() as usize)
}

/// Replicate data sets drawn from a fitted model's values with the stated uncertainties.
pub fn null_replicates(data: &Dataset, values: &[f64], count: usize, seed: u64) -> Vec<Dataset> {
    let source = with_values(data, values);
    (1..=count).map(|i| replicate(&source, seed, i)).collect()
}

fn with_values(data: &Dataset, values: &[f64]) -> Dataset {
    let mut fitted = data.clone();
    for (s, &v) in fitted.samples.iter_mut().zip(values) {
        s.value = v;
    }
    fitted
}

/// Replicate `i` (from 1) drawn about `source`'s values: its own seed, so that the
/// replicates are the same however the batches cut them.
fn replicate(source: &Dataset, seed: u64, i: usize) -> Dataset {
    let seed = seed ^ (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    ReplicaSource::new(source, chi2(), 0.0, seed)
        .draw(1)
        .pop()
        .expect("one replicate drawn")
}

fn chi2() -> Loss {
    Loss::new(Metric::Chi2, Weights::Uniform)
}

/// The null model refitted to the measured data (index 0) and to replicates drawn from
/// its fit (1, 2, …), grown on demand and shared by the candidates of a round: the
/// optima (physical) and χ² (non-finite where a fit failed).
#[derive(Clone)]
pub struct NullRefits {
    model: Model,
    measured: Dataset,
    /// The null's fitted values, which the replicates scatter about.
    source: Dataset,
    start: Vec<f64>,
    seed: u64,
    pub flat: Vec<Vec<f64>>,
    pub chi2: Vec<f64>,
    pub seconds: f64,
    pub evaluations: u64,
    pub phases: PhaseSeconds,
    /// The smoothness prior of the null's knots in its refits ([`Self::with_smoothness`]).
    smoothness: Smoothness,
}

impl NullRefits {
    /// No refit yet: the null `model` fitted at `flat` with values `values` on `data`.
    pub fn new(model: &Model, flat: &[f64], values: &[f64], data: &Dataset, seed: u64) -> Self {
        NullRefits {
            model: model.clone(),
            measured: data.clone(),
            source: with_values(data, values),
            start: flat.to_vec(),
            seed,
            flat: vec![],
            chi2: vec![],
            seconds: 0.0,
            evaluations: 0,
            phases: PhaseSeconds::default(),
            smoothness: Smoothness::Auto,
        }
    }

    /// Refit the null's knots (a data-driven factor) under this prior: the σ_s its fit
    /// chose on the measured data, so that the refits are of the model the test is about
    /// (by default the options' smoothness, which in a lockstep refit means no prior).
    pub fn with_smoothness(mut self, smoothness: Smoothness) -> Self {
        self.smoothness = smoothness;
        self
    }

    /// Replicates refitted so far (the measured data not counted).
    pub fn replicates(&self) -> usize {
        self.chi2.len().saturating_sub(1)
    }

    /// Data set `i`: the measured data (0) or replicate `i`, drawn again from its own seed
    /// on each call (cheap beside its refits, and lighter than holding up to 999 copies of
    /// the data).
    pub fn dataset(&self, i: usize) -> Dataset {
        if i == 0 {
            self.measured.clone()
        } else {
            replicate(&self.source, self.seed, i)
        }
    }

    /// Refit the null to the measured data and to replicates up to `count`, those not yet
    /// refitted, in lockstep.
    pub fn grow(
        &mut self,
        count: usize,
        backend: &dyn Backend,
        base: &FitOptions,
        boot: &BootstrapOptions,
    ) -> anyhow::Result<()> {
        let from = self.chi2.len();
        if from > count {
            return Ok(());
        }
        let t0 = Instant::now();
        let opts = FitOptions {
            initial_points: vec![self.start.clone()],
            problem_points: vec![],
            smoothness: match self.smoothness {
                Smoothness::Auto => base.smoothness,
                own => own,
            },
            ..replicate_options(base, boot)
        };
        for chunk in chunks(from, count) {
            let datas: Vec<Dataset> = chunk.clone().map(|i| self.dataset(i)).collect();
            let (optima, stats) = refit(&self.model, &datas, backend, &opts)?;
            self.flat.extend(optima.iter().map(|o| o.flat.clone()));
            self.chi2.extend(optima.iter().map(|o| o.loss));
            self.evaluations += stats.evaluations;
            self.phases += stats.phases;
        }
        self.seconds += t0.elapsed().as_secs_f64();
        Ok(())
    }
}

/// Indices `from..=to` in lockstep calls of at most [`CHUNK`].
fn chunks(from: usize, to: usize) -> Vec<std::ops::RangeInclusive<usize>> {
    (from..=to)
        .step_by(CHUNK)
        .map(|a| a..=(a + CHUNK - 1).min(to))
        .collect()
}

/// Refits of replicates: Levenberg–Marquardt on χ², stopped once a step gains less than
/// 1e-7 of χ² (T needs χ² to ~1e-3 absolute, and replicate fits start next to their
/// optimum; the 1e-10 of a reported fit would only make the unidentified parameters of
/// an irregular null crawl along their flat valley).
fn replicate_options(base: &FitOptions, boot: &BootstrapOptions) -> FitOptions {
    FitOptions {
        optimizer: Optimizer::Lm,
        restarts: boot.restarts.max(1),
        seed: boot.seed ^ 0x5eed_b007,
        lm: crate::optim::lm::LmOptions {
            ftol: 1e-7,
            max_iterations: 100,
            ..base.lm.clone()
        },
        ..base.clone()
    }
}

/// χ² fits of `model` to every data set, in lockstep.
fn refit(
    model: &Model,
    datas: &[Dataset],
    backend: &dyn Backend,
    opts: &FitOptions,
) -> anyhow::Result<(Vec<crate::inference::fit::Optimum>, ManyStats)> {
    let refs: Vec<&Dataset> = datas.iter().collect();
    let losses = vec![chi2(); refs.len()];
    let (optima, _, stats) = fit_many(model, &refs, &losses, backend, opts, &mut |_| {})?;
    Ok((optima, stats))
}

/// The null refitted to the measured data and to the planned replicates (a fixed-B
/// bootstrap's first half; [`calibrate`] grows it further where it needs to).
pub fn refit_null(
    null: &Model,
    null_flat: &[f64],
    null_values: &[f64],
    data: &Dataset,
    backend: &dyn Backend,
    base: &FitOptions,
    boot: &BootstrapOptions,
) -> anyhow::Result<NullRefits> {
    anyhow::ensure!(
        boot.replicates >= 1,
        "the bootstrap needs at least 1 replicate"
    );
    let mut nulls = NullRefits::new(null, null_flat, null_values, data, boot.seed);
    nulls.grow(boot.replicates, backend, base, boot)?;
    Ok(nulls)
}

/// What a calibration has gathered so far: the observed T and the replicates' T*_b in
/// drawing order (those whose two fits ended finite).
struct Gathered {
    observed: f64,
    reps: Vec<f64>,
    drawn: usize,
}

/// A settled test: p, its source, the share π of positive replicates, the fitted tail
/// (a, ν), and why it could not decide, if it could not.
type Settled = (f64, PSource, f64, Option<(f64, f64)>, Option<String>);

/// The verdict of the replicates gathered so far, or None to draw more: the module doc's
/// rules (`last`: no more may be drawn).
fn settle(g: &Gathered, level: f64, boot: &BootstrapOptions, last: bool) -> Option<Settled> {
    let t = g.observed;
    let h = sequential_h(level, boot.replicates);
    // Besag & Clifford's rule within the planned replicates (beyond them the count
    // decides at the first replicate that reaches T).
    let within_plan = g.drawn <= boot.replicates;
    if let Some(l) = hth_exceedance(t, &g.reps, h).filter(|_| within_plan) {
        let share = g.reps.iter().filter(|&&r| r > ZERO).count() as f64 / g.reps.len() as f64;
        return Some((h as f64 / l as f64, PSource::Sequential, share, None, None));
    }
    if g.drawn < boot.replicates && !last {
        return None;
    }
    let (p, source, share, tail) = p_value(t, &g.reps);
    let uncapped = tail.map(|(a, nu)| share * chi2_sf(t / a, nu));
    // Where none reaches T, the count decides once its bound is below the level, and a
    // fitted tail where it is far from the level: a tail fitted to a few dozen replicates
    // and extrapolated beyond all of them is uncertain by an order of magnitude (module
    // doc), so near the level it leaves the verdict open.
    let far = |q: f64| q < level / TAIL_MARGIN || q > level * TAIL_MARGIN;
    let bound = 1.0 / (g.reps.len() + 1) as f64;
    let decided = source == PSource::Empirical || bound < level || uncapped.is_some_and(far);
    if decided {
        return Some((p, source, share, tail, None));
    }
    if !last {
        return None;
    }
    let positive = g.reps.iter().filter(|&&r| r > ZERO).count();
    let need = (1.0 / level).ceil() as usize;
    let why = match uncapped {
        Some(q) => format!(
            "no replicate of {} reaches T; the tail fitted to them gives {q:.1e}, within a factor {TAIL_MARGIN} of the level {level:.1e}, and the count bounds p only by 1/(B + 1) = {:.1e}; more than {need} replicates could decide (raise the maximum: --bootstrap-max, or bootstrap_max in Python)",
            g.reps.len(),
            bound
        ),
        None => format!(
            "no replicate of {} reaches T and only {positive} are positive (a tail needs {MIN_POSITIVE}), so p is only bounded by 1/(B + 1) = {p:.1e}, not below the level {level:.1e}; more than {need} replicates could decide (raise the maximum: --bootstrap-max, or bootstrap_max in Python)",
            g.reps.len()
        ),
    };
    // Undecided: the count's bound stands (the candidate is not significant), whatever a
    // tail near the level said.
    Some((p.max(bound), source, share, tail, Some(why)))
}

/// The calibrated p-value at `level` of extending the null of `nulls` to `ext` (`dof_ext`
/// = K − P of the extension): `ext` refitted to the measured data and to replicates in
/// batches until the verdict at the level is settled (module doc), T of the measured
/// data against the replicates'. `embed` carries a null optimum into the extension's
/// parameters; `ext_flat`, the extension's optimum on the measured data, is one more start
/// of every refit. The null refits grow as the batches need them.
#[allow(clippy::too_many_arguments)]
pub fn calibrate(
    ext: &Model,
    ext_flat: &[f64],
    embed: &dyn Fn(&[f64]) -> Vec<f64>,
    nulls: &mut NullRefits,
    dof_ext: usize,
    level: f64,
    backend: &dyn Backend,
    base: &FitOptions,
    boot: &BootstrapOptions,
) -> anyhow::Result<Calibrated> {
    anyhow::ensure!(
        boot.replicates >= 1,
        "the bootstrap needs at least 1 replicate"
    );
    let t0 = Instant::now();
    let null_seconds = nulls.seconds;
    let opts = replicate_options(base, boot);
    let schedule = boot.schedule();
    let mut g = Gathered {
        observed: f64::NAN,
        reps: vec![],
        drawn: 0,
    };
    let (mut evaluations, mut phases) = (0, PhaseSeconds::default());
    let mut batches = vec![];
    for (k, &upto) in schedule.iter().enumerate() {
        nulls.grow(upto, backend, base, boot)?;
        let from = if k == 0 { 0 } else { g.drawn + 1 };
        for chunk in chunks(from, upto) {
            let datas: Vec<Dataset> = chunk.clone().map(|i| nulls.dataset(i)).collect();
            let opts = FitOptions {
                initial_points: vec![ext_flat.to_vec()],
                problem_points: chunk.clone().map(|i| embed(&nulls.flat[i])).collect(),
                ..opts.clone()
            };
            let (optima, stats) = refit(ext, &datas, backend, &opts)?;
            evaluations += stats.evaluations;
            phases += stats.phases;
            for (i, o) in chunk.zip(&optima) {
                let c0 = nulls.chi2[i];
                if i == 0 {
                    anyhow::ensure!(
                        o.loss.is_finite() && c0.is_finite(),
                        "refitting {} or its null to the measured data ended non-finite",
                        ext.spec
                    );
                    g.observed = statistic(c0, o.loss, dof_ext);
                } else if o.loss.is_finite() && c0.is_finite() {
                    g.reps.push(statistic(c0, o.loss, dof_ext));
                }
            }
        }
        g.drawn = upto;
        batches.push(upto);
        let last = k + 1 == schedule.len();
        if g.reps.is_empty() {
            anyhow::ensure!(
                !last,
                "no bootstrap replicate of {} could be fitted",
                ext.spec
            );
            continue;
        }
        if let Some((p, source, positive_share, tail, undecided)) = settle(&g, level, boot, last) {
            phases += nulls.phases;
            return Ok(Calibrated {
                p,
                source,
                statistic: g.observed,
                replicates: g.drawn,
                fitted: g.reps.len(),
                exceeding: g.reps.iter().filter(|&&r| r >= g.observed).count(),
                positive_share,
                tail,
                level,
                batches,
                undecided,
                // The extension's refits and all the null refits it rests on (shared
                // with the round's other candidates).
                seconds: t0.elapsed().as_secs_f64() + null_seconds,
                evaluations: evaluations + nulls.evaluations,
                phases,
            });
        }
    }
    anyhow::bail!("the bootstrap of {} drew no batch", ext.spec)
}

#[cfg(test)]
#[path = "bootstrap_tests.rs"]
mod tests;
