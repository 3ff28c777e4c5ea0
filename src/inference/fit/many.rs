//! The lockstep multi-fit driver: one model fitted to several data sets at once, all
//! problems × restarts stepped together, one backend submission per optimizer step.

use super::polish::{polish_in_f64, search_options};
use super::smoothness::Smoothness;
use super::starts::screened_starts;
use super::{FitOptions, Optimizer, UnitBox};
use crate::bsdf::kernel::LaneKind;
use crate::bsdf::Model;
use crate::choice::field_error;
use crate::data::Dataset;
use crate::engine::loss::{Finisher, Loss};
use crate::engine::simd::SimdBackend;
use crate::engine::{Backend, Evaluator, Problem};
use crate::inference::constraints::Constraints;
use crate::optim::{compass, lm, RestartResult, Stop};
use std::ops::Range;
use std::time::Instant;

/// The optimum of one problem of [`fit_many`].
#[derive(Clone, Debug)]
pub struct Optimum {
    /// Best physical parameter vector.
    pub flat: Vec<f64>,
    /// Its loss.
    pub loss: f64,
    /// Restarts whose final loss is within 1% of the best.
    pub within: usize,
    /// Model-sample evaluations made for this problem.
    pub evaluations: u64,
    /// Why the best restart stopped.
    pub stop: Stop,
}

/// What [`fit_many`] did besides the optima.
#[derive(Clone, Debug, Default)]
pub struct ManyStats {
    /// Model-sample evaluations.
    pub evaluations: u64,
    /// Evaluators prepared (submissions carry every problem of one evaluator).
    pub batches: usize,
    /// Where the time went.
    pub phases: PhaseSeconds,
}

/// Wall-clock seconds of the phases of fitting, on the thread that ran them (summed over
/// threads where several fits ran at once): where a sweep's time goes (`bench --sweep`).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct PhaseSeconds {
    /// Preparing the evaluators (uploads, tables; kernels compiled on first use).
    pub setup: f64,
    /// Ranking the random starts.
    pub screening: f64,
    /// The optimizer's restarts on the backend.
    pub search: f64,
    /// The f64 polish of each problem's best restart (LM only), on the CPU.
    pub polish: f64,
    /// χ², covariance and warnings at each optimum, on the CPU.
    pub conclusions: f64,
}

impl std::ops::AddAssign for PhaseSeconds {
    fn add_assign(&mut self, o: PhaseSeconds) {
        self.setup += o.setup;
        self.screening += o.screening;
        self.search += o.search;
        self.polish += o.polish;
        self.conclusions += o.conclusions;
    }
}

/// Fit one model to several data sets, all problems × restarts stepped in lockstep so
/// that each optimizer step is one submission to the backend (split only where the
/// backend cannot hold all the samples at once). `losses[q]` is problem q's loss (any
/// metric and weighting, all of one term shape: [`crate::engine::check_shared`]).
/// Returns each problem's optimum.
pub fn fit_many(
    model: &Model,
    datas: &[&Dataset],
    losses: &[Loss],
    backend: &dyn Backend,
    opts: &FitOptions,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<(Vec<Optimum>, Constraints, ManyStats)> {
    let space = check_request(model, datas, losses, opts)?;
    let mut optima = Vec::with_capacity(datas.len());
    let mut stats = ManyStats::default();
    for range in evaluator_ranges(datas, backend.max_batch_samples()) {
        let batch = Batch {
            model,
            space: &space,
            problems: range
                .clone()
                .map(|q| Problem {
                    model,
                    data: datas[q],
                    loss: losses[q],
                })
                .collect(),
            range,
            per: opts.initial_points.len()
                + usize::from(!opts.problem_points.is_empty())
                + opts.restarts,
        };
        optima.extend(batch.fit(backend, opts, progress, &mut stats)?);
    }
    Ok((optima, space, stats))
}

/// The constraints of `model` under `opts`, once the data sets, losses and options are
/// known to make a fit (an error saying what does not).
fn check_request(
    model: &Model,
    datas: &[&Dataset],
    losses: &[Loss],
    opts: &FitOptions,
) -> anyhow::Result<Constraints> {
    anyhow::ensure!(!datas.is_empty(), "no data set to fit");
    anyhow::ensure!(datas.len() == losses.len(), "one loss per data set");
    let mut space = Constraints::resolve(model, &opts.constraints, opts.constraints.lenient)?;
    if let (Smoothness::Sd(sd), false) = (opts.smoothness, space.smooth.is_empty()) {
        if let Some(loss) = losses
            .iter()
            .find(|l| l.metric != crate::engine::loss::Metric::Chi2)
        {
            return Err(field_error(format!(
                "{{smoothness}} needs {{loss=chi2}}: the smoothness prior is a χ² term, and {} is not in χ²'s units",
                loss.metric
            )));
        }
        space.smooth_sd = Some(sd);
    }
    for (data, loss) in datas.iter().zip(losses) {
        anyhow::ensure!(
            model.kind == data.kind,
            "model {} is a {} model but {} holds {} data",
            model.spec,
            model.kind,
            data.source.display(),
            data.kind
        );
        if !(space.priors.is_empty() || loss.metric == crate::engine::loss::Metric::Chi2) {
            return Err(field_error(format!(
                "{{prior}} needs {{loss=chi2}}: a prior is a χ² term, and {} is not in χ²'s units",
                loss.metric
            )));
        }
        anyhow::ensure!(
            data.len() + space.prior_rows() > space.dim(),
            "{}: {} cannot determine the {} parameters of {}",
            data.source.display(),
            crate::text::plural_with(data.len(), "sample", "samples"),
            space.dim(),
            model.spec
        );
        if opts.optimizer == Optimizer::Lm && !loss.is_sum_of_squares() {
            return Err(field_error(format!(
                "{{optimizer=lm}} needs a sum-of-squares loss; {} is not one (use compass)",
                loss.metric
            )));
        }
    }
    if opts.restarts == 0 {
        return Err(field_error("{restarts} must be at least 1"));
    }
    anyhow::ensure!(
        opts.initial_points
            .iter()
            .chain(&opts.problem_points)
            .all(|p| p.len() == model.dim),
        "an initial point does not have the {} parameters of {}",
        model.dim,
        model.spec
    );
    anyhow::ensure!(
        opts.problem_points.is_empty() || opts.problem_points.len() == datas.len(),
        "{} per-problem starting points for {} data sets",
        opts.problem_points.len(),
        datas.len()
    );
    Ok(space)
}

/// The problems (indices of `datas`) of each evaluator: as few evaluators as a backend
/// holding at most `capacity` samples at once allows, problems kept in order.
fn evaluator_ranges(datas: &[&Dataset], capacity: usize) -> Vec<Range<usize>> {
    let cap = capacity.max(1);
    let mut ranges: Vec<Range<usize>> = Vec::new();
    let (mut start, mut held) = (0, 0);
    for (q, d) in datas.iter().enumerate() {
        if q > start && held + d.len() > cap {
            ranges.push(start..q);
            start = q;
            held = 0;
        }
        held += d.len();
    }
    ranges.push(start..datas.len());
    ranges
}

/// The problems of [`fit_many`] that share one evaluator.
struct Batch<'a> {
    model: &'a Model,
    space: &'a Constraints,
    /// Which of `fit_many`'s problems these are.
    range: Range<usize>,
    problems: Vec<Problem<'a>>,
    /// Restarts per problem (given points, the problem's own point, random starts).
    per: usize,
}

impl Batch<'_> {
    /// Search (and polish) every problem of the batch on one evaluator; each problem's
    /// optimum, with what it cost added to `stats`.
    fn fit(
        &self,
        backend: &dyn Backend,
        opts: &FitOptions,
        progress: &mut dyn FnMut(usize),
        stats: &mut ManyStats,
    ) -> anyhow::Result<Vec<Optimum>> {
        let finishers: Vec<Finisher> = self
            .problems
            .iter()
            .map(|p| p.loss.finisher(p.data))
            .collect();
        let clock = Instant::now();
        let mut eval = backend.prepare_many(&self.problems)?;
        stats.phases.setup += clock.elapsed().as_secs_f64();
        let n = self.problems.len();
        let mut results = self.search(
            eval.as_mut(),
            &finishers,
            backend,
            opts,
            progress,
            &mut stats.phases,
        )?;
        let mut evaluations: Vec<u64> = (0..n).map(|q| eval.evaluations_of(q)).collect();
        // Each problem's polished restart (empty: none).
        let mut polished: Vec<usize> = Vec::new();
        if opts.optimizer == Optimizer::Lm && opts.polish {
            let clock = Instant::now();
            polished = self.polish(
                eval,
                backend,
                &finishers,
                &mut results,
                &mut evaluations,
                &opts.lm,
            )?;
            stats.phases.polish += clock.elapsed().as_secs_f64();
        }
        let optima = results
            .chunks(self.per)
            .enumerate()
            .map(|(q, restarts)| self.optimum(restarts, polished.get(q), evaluations[q]))
            .collect();
        stats.evaluations += evaluations.iter().sum::<u64>();
        stats.batches += 1;
        Ok(optima)
    }

    /// Every problem's restarts from their screened starts, with the optimizer of `opts`.
    fn search(
        &self,
        eval: &mut dyn Evaluator,
        finishers: &[Finisher],
        backend: &dyn Backend,
        opts: &FitOptions,
        progress: &mut dyn FnMut(usize),
        phases: &mut PhaseSeconds,
    ) -> anyhow::Result<Vec<RestartResult>> {
        let (n, per) = (self.problems.len(), self.per);
        let mut obj = UnitBox {
            model: self.model,
            space: self.space,
            eval,
            finishers: finishers.to_vec(),
            start_problem: (0..n).flat_map(|q| std::iter::repeat_n(q, per)).collect(),
        };
        let clock = Instant::now();
        let starts = screened_starts(&mut obj, self.range.clone(), opts)?;
        phases.screening += clock.elapsed().as_secs_f64();
        let clock = Instant::now();
        let results = match opts.optimizer {
            Optimizer::Compass => compass::minimize(&mut obj, &starts, &opts.compass, progress)?,
            Optimizer::Lm => {
                let lm_opts = search_options(&opts.lm, opts.polish, backend.unit_roundoff());
                lm::minimize(
                    &mut obj,
                    &starts,
                    &lm_opts,
                    &|start, s| finishers[start / per].finish_sum(s),
                    progress,
                )?
            }
        };
        phases.search += clock.elapsed().as_secs_f64();
        Ok(results)
    }

    /// [`polish_in_f64`] in f64, with the search's own evaluator `eval` if it is the CPU
    /// reference's, else on the SIMD engine's f64 lanes, whose model values are the
    /// reference's bit for bit (`tests/simd_parity.rs`) at a fraction of its time (only
    /// the order of the loss's sums differs); each problem's polish evaluations are added
    /// to `evaluations`. Returns each problem's polished restart.
    fn polish(
        &self,
        eval: Box<dyn Evaluator + '_>,
        backend: &dyn Backend,
        finishers: &[Finisher],
        results: &mut [RestartResult],
        evaluations: &mut [u64],
        lm_opts: &lm::LmOptions,
    ) -> anyhow::Result<Vec<usize>> {
        // The CPU reference polishes with the search's own evaluator; another's is
        // dropped first, so that the two never hold the data at once.
        let f64_lanes = SimdBackend::with_lanes(LaneKind::F64x4);
        let mut polisher = if backend.id() == "cpu" {
            eval
        } else {
            drop(eval);
            f64_lanes.prepare_many(&self.problems)?
        };
        let n = self.problems.len();
        let before: Vec<u64> = (0..n).map(|q| polisher.evaluations_of(q)).collect();
        let polished = polish_in_f64(
            polisher.as_mut(),
            self.model,
            self.space,
            finishers,
            results,
            self.per,
            lm_opts,
        )?;
        for (q, e) in evaluations.iter_mut().enumerate() {
            *e += polisher.evaluations_of(q) - before[q];
        }
        Ok(polished)
    }

    /// A problem's optimum: its best restart (`polished`, if one was), and how many of
    /// its restarts ended within 1 % of it.
    fn optimum(
        &self,
        restarts: &[RestartResult],
        polished: Option<&usize>,
        evaluations: u64,
    ) -> Optimum {
        // A polished restart is the best: it was the best of the search, and the
        // polish only lowered its cost.
        let best = match polished {
            Some(&i) => &restarts[i],
            None => restarts
                .iter()
                .min_by(|a, b| a.cost.total_cmp(&b.cost))
                .expect("at least one restart"),
        };
        let tol = best.cost.abs() * 0.01 + 1e-300;
        Optimum {
            flat: self.space.from_unit(&best.x),
            loss: best.cost,
            within: restarts
                .iter()
                .filter(|r| r.cost <= best.cost + tol)
                .count(),
            evaluations,
            stop: best.stop,
        }
    }
}
