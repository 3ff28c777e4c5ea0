//! One fit: a model, a dataset, a loss, multi-start optimisation on a backend, and the
//! report of docs/output.md (best loss, χ²_red, parameters with standard uncertainties).

use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::{chi2, Finisher, Loss};
use crate::engine::{Backend, Evaluator, Problem};
use crate::inference::constraints::{ConstraintSpec, Constraints};
use crate::inference::covariance::{covariance, Covariance};
use crate::optim::{compass, lm, random_starts, BatchObjective, BatchResiduals, RestartResult};
use serde::Serialize;
use serde_json::{Map, Value};
use std::time::Instant;

#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Optimizer {
    /// Compass search (Kolda, Lewis, Torczon 2003), BBM's optimizer; any loss.
    Compass,
    /// Levenberg–Marquardt; sum-of-squares losses only.
    Lm,
}

impl std::fmt::Display for Optimizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Optimizer::Compass => "compass",
            Optimizer::Lm => "lm",
        })
    }
}

#[derive(Clone, Debug)]
pub struct FitOptions {
    pub optimizer: Optimizer,
    pub restarts: usize,
    pub seed: u64,
    /// Draw this many random points per restart, evaluate them in one batch and start
    /// from the best (1 = plain random starts). Cheap, and it keeps restarts out of the
    /// flat, hopeless corners of the box that local optimizers cannot leave.
    pub screen: usize,
    /// Extra starting points (physical parameter vectors), tried before the random ones;
    /// e.g. a smaller model's optimum carried into its extension.
    pub initial_points: Vec<Vec<f64>>,
    /// One more starting point per problem of [`fit_many`] (physical), tried after
    /// `initial_points`: empty, or one per data set (e.g. each bootstrap replicate's own
    /// null optimum carried into the extension, so a nested extension can only improve).
    pub problem_points: Vec<Vec<f64>>,
    pub compass: compass::CompassOptions,
    pub lm: lm::LmOptions,
    /// Levenberg–Marquardt: the restarts only find the basins, with the same settings on
    /// every backend, and the best restart of each problem is continued in f64 on the
    /// CPU reference to f64's convergence (see [`search_options`], [`polish_in_f64`]).
    /// Off: every restart goes to the backend's own convergence, and nothing is polished.
    pub polish: bool,
    /// `--fix`, `--bounds`, `--prior` (resolved against each model fitted).
    pub constraints: ConstraintSpec,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            optimizer: Optimizer::Compass,
            restarts: 32,
            seed: 1,
            screen: 8,
            initial_points: vec![],
            problem_points: vec![],
            compass: Default::default(),
            lm: Default::default(),
            polish: true,
            constraints: Default::default(),
        }
    }
}

/// The best parameters of a fit (docs/output.md `best`).
#[derive(Clone, Debug, Serialize)]
pub struct Best {
    pub loss: f64,
    pub chi2_red: f64,
    /// Parameter name → value (an array per channel for rgb parameters).
    pub params: Map<String, Value>,
    /// Standard uncertainties, same shape; null where the data does not determine it.
    pub param_std: Map<String, Value>,
}

/// The JSON report of one fit (docs/output.md), with extras after the contract's fields.
#[derive(Clone, Debug, Serialize)]
pub struct FitReport {
    pub model: String,
    pub loss: String,
    pub weights: String,
    pub optimizer: String,
    pub backend: String,
    pub restarts: usize,
    pub evaluations: u64,
    pub seconds: f64,
    pub best: Best,
    pub data: String,
    pub material: String,
    pub samples: usize,
    pub channels: Vec<f64>,
    /// Measurement planes (φ, degrees) with parameters of their own (`+peraxis`), else [0].
    pub axes: Vec<f64>,
    pub seed: u64,
    /// Restarts whose final loss is within 1% of the best (a multi-modality signal).
    pub restarts_within_1pct: usize,
    /// Parameter names of the flat vector (rgb parameters as `name[c]`).
    pub flat_names: Vec<String>,
    pub flat_params: Vec<f64>,
    pub flat_std: Vec<Option<f64>>,
    /// Correlation matrix of the flat parameters (null entries where undetermined).
    pub correlation: Vec<Vec<Option<f64>>>,
    pub warnings: Vec<String>,
    /// Degrees of freedom of χ²_red: samples + priors − fitted parameters.
    pub dof: usize,
    /// Fitted parameters (the flat vector's, less those fixed by `--fix`).
    pub n_params: usize,
    /// What `--fix`, `--bounds` and `--prior` imposed (absent when nothing was):
    /// `{fixed: {name: value}, bounds: {name: [lo, hi]}, priors: [{name, index, mean, sd}],
    /// chi2_prior}`. Fixed parameters have a standard uncertainty of 0.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub constraints: Option<Value>,
    /// `--mc N`: the parameters' distribution over N refitted replicas of the data
    /// (absent without it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub monte_carlo: Option<crate::inference::mc_summary::McSummary>,
}

/// Adapts an evaluator (physical parameters) to the optimizers' unit box.
/// The optimizers see the free parameters only ([`Constraints`]); priors add residuals.
/// An evaluator holding several problems is shared by all their restarts: `start_problem`
/// says which problem each start (restart) belongs to.
pub struct UnitBox<'m, 'e> {
    pub model: &'m Model,
    pub space: &'m Constraints,
    pub eval: &'m mut (dyn Evaluator + 'e),
    /// How each problem's sums of terms become its loss (term shape, finish, K).
    pub finishers: Vec<Finisher>,
    /// The problem of each start; empty when every start belongs to problem 0.
    pub start_problem: Vec<usize>,
}

impl UnitBox<'_, '_> {
    fn to_physical(&self, points: &[f64]) -> Vec<f64> {
        points
            .chunks(self.space.dim())
            .flat_map(|u| self.space.from_unit(u))
            .collect()
    }

    fn problems_of(&self, owners: &[usize]) -> Vec<usize> {
        owners
            .iter()
            .map(|&s| self.start_problem.get(s).copied().unwrap_or(0))
            .collect()
    }

    /// Costs of unit-box points, `problems[i]` the problem of point i.
    pub fn problem_costs(
        &mut self,
        problems: &[usize],
        points: &[f64],
    ) -> anyhow::Result<Vec<f64>> {
        let phys = self.to_physical(points);
        let mut costs = self.eval.costs_of(problems, &phys)?;
        if !self.space.priors.is_empty() {
            // Priors come with the χ² loss only, whose cost is the plain sum of squares.
            for (c, flat) in costs.iter_mut().zip(phys.chunks(self.model.dim)) {
                *c += self.space.prior_chi2(flat);
            }
        }
        Ok(costs)
    }

    /// Residual rows (data, then priors) of physical points, `problems[i]` the problem of
    /// point i; the rows one after the other, each point's data residuals in its
    /// evaluator's row order. Holds points × samples: for tests and small batches only
    /// (the optimizers use the streamed sums of [`Self::normal_equations_of`]).
    fn problem_residuals(
        &mut self,
        problems: &[usize],
        phys: &[f64],
    ) -> anyhow::Result<Vec<Vec<f64>>> {
        let mut rows: Vec<Vec<f64>> = problems
            .iter()
            .map(|&q| Vec::with_capacity(self.eval.samples_of(q) + self.space.priors.len()))
            .collect();
        self.eval.value_windows(problems, phys, &mut |w| {
            for part in w.parts {
                let t = &w.rows[part.problem];
                let v = w.values_of(part);
                let row = &mut rows[part.candidate];
                for (i, r) in part.rows.clone().enumerate() {
                    if t.sample[r] != crate::engine::loss::NO_SAMPLE {
                        row.push(t.terms.residual(r, v.at(i)));
                    }
                }
            }
            Ok(())
        })?;
        for (row, flat) in rows.iter_mut().zip(phys.chunks(self.model.dim)) {
            row.extend(self.space.prior_residuals(flat));
        }
        Ok(rows)
    }
}

impl BatchObjective for UnitBox<'_, '_> {
    fn dim(&self) -> usize {
        self.space.dim()
    }
    fn costs(&mut self, points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let n = points.len() / self.space.dim().max(1);
        self.problem_costs(&vec![0; n], points)
    }
    fn costs_of(&mut self, owners: &[usize], points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let problems = self.problems_of(owners);
        self.problem_costs(&problems, points)
    }
}

impl BatchResiduals for UnitBox<'_, '_> {
    fn residuals(&mut self, points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let n = points.len() / self.space.dim().max(1);
        let phys = self.to_physical(points);
        Ok(self.problem_residuals(&vec![0; n], &phys)?.concat())
    }
    fn residual_count(&self) -> usize {
        self.eval.samples_of(0) + self.space.priors.len()
    }
    fn normal_equations(
        &mut self,
        points: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<crate::optim::NormalEquations>> {
        let n = points.len() / self.space.dim().max(1);
        let every: Vec<usize> = vec![0; n];
        self.normal_equations_of(&every, points, steps)
    }
    /// Reduced by the backend where it evaluates the model, over the free parameters
    /// (the moved points move free parameters only); each prior adds one residual row,
    /// whose share is added here.
    fn normal_equations_of(
        &mut self,
        owners: &[usize],
        points: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<crate::optim::NormalEquations>> {
        let p = self.space.dim();
        let problems = self.problems_of(owners);
        let unit = crate::optim::difference_points(points, steps, p);
        let phys = self.to_physical(&unit);
        let mut normal = self.eval.normal_equations_of(&problems, &phys, steps)?;
        if !self.space.priors.is_empty() {
            let dim = self.model.dim;
            for ((ne, group), h) in normal
                .iter_mut()
                .zip(phys.chunks(dim * (p + 1)))
                .zip(steps.chunks(p))
            {
                let rows: Vec<Vec<f64>> = group
                    .chunks(dim)
                    .map(|flat| self.space.prior_residuals(flat).collect())
                    .collect();
                ne.add_rows(&rows[0], &rows[1..], h);
            }
        }
        Ok(normal)
    }
    fn sum_squares_of(&mut self, owners: &[usize], points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let problems = self.problems_of(owners);
        let phys = self.to_physical(points);
        let squares = problems
            .iter()
            .all(|&q| self.finishers.get(q).is_some_and(|f| f.is_sum_of_squares()));
        if !squares {
            return Ok(self
                .problem_residuals(&problems, &phys)?
                .iter()
                .map(|r| crate::optim::sanitize(r.iter().map(|v| v * v).sum()))
                .collect());
        }
        // A sum-of-squares loss's terms are the squared residuals, w (g(y′) − g(y))², so
        // the data part of Σr² is the loss's own sum: one number per point from the
        // evaluator (reduced on the device by the GPU engine) instead of K model values
        // read back.
        let costs = self.eval.costs_of(&problems, &phys)?;
        Ok(costs
            .iter()
            .zip(&problems)
            .zip(phys.chunks(self.model.dim))
            .map(|((&c, &q), flat)| {
                let data = self.finishers[q].sum_of(c);
                crate::optim::sanitize(data + self.space.prior_chi2(flat))
            })
            .collect())
    }
    fn sum_squares(&mut self, points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let n = points.len() / self.space.dim().max(1);
        self.sum_squares_of(&vec![0; n], points)
    }
}

/// Starting points in the unit box for each of `problems` problems, problem-major: the
/// given initial points, then the best `restarts` of `restarts × screen` random draws
/// (the same draws for every problem, screened on each problem's own data).
fn screened_starts(
    obj: &mut UnitBox,
    problems: std::ops::Range<usize>,
    opts: &FitOptions,
) -> anyhow::Result<Vec<Vec<f64>>> {
    let initial: Vec<Vec<f64>> = opts
        .initial_points
        .iter()
        .map(|p| obj.space.to_unit(p))
        .collect();
    // Problem q's own start, if any, after the shared ones.
    let own =
        |q: usize| -> Option<Vec<f64>> { opts.problem_points.get(q).map(|p| obj.space.to_unit(p)) };
    let owns: Vec<Option<Vec<f64>>> = problems.clone().map(own).collect();
    let problems = problems.len();
    let pool = random_starts(obj.dim(), opts.restarts * opts.screen.max(1), opts.seed);
    let mut starts = Vec::with_capacity(problems * (initial.len() + opts.restarts));
    if opts.screen <= 1 {
        for own in &owns {
            starts.extend(initial.iter().cloned());
            starts.extend(own.iter().cloned());
            starts.extend(pool.iter().cloned());
        }
        return Ok(starts);
    }
    // One batch: the whole pool on every problem.
    let flat: Vec<f64> = pool.iter().flatten().copied().collect();
    let points = flat.repeat(problems);
    let owners: Vec<usize> = (0..problems)
        .flat_map(|q| std::iter::repeat_n(q, pool.len()))
        .collect();
    let lm = matches!(opts.optimizer, Optimizer::Lm)
        && obj.finishers.iter().all(|f| f.is_sum_of_squares());
    let costs = if lm {
        // Ranked by Σr² (the loss up to its monotone finish) of the model values after
        // their best rescaling within SCREEN_MAX_SCALE (`reduce::rescaled_sum_squares`:
        // the shape, not the level, which LM corrects easily), plus the priors'. From the
        // value windows: LM itself uses only the values (and normal-equation) kernels, so
        // a GPU engine then never compiles its costs kernel for the fit (on lavapipe
        // 0.05–0.3 s per model and loss shape, ≈ 6 % of the default sweep's thread time).
        let phys = obj.to_physical(&points);
        let ranks = crate::engine::reduce::rescaled_sum_squares(
            obj.eval,
            &owners,
            &phys,
            SCREEN_MAX_SCALE,
        )?;
        ranks
            .iter()
            .zip(phys.chunks(obj.model.dim))
            .map(|(&r, flat)| r + obj.space.prior_chi2(flat))
            .collect()
    } else {
        obj.problem_costs(&owners, &points)?
    };
    for (costs, own) in costs.chunks(pool.len()).zip(&owns) {
        let mut order: Vec<usize> = (0..pool.len()).collect();
        order.sort_by(|&a, &b| {
            crate::optim::sanitize(costs[a]).total_cmp(&crate::optim::sanitize(costs[b]))
        });
        starts.extend(initial.iter().cloned());
        starts.extend(own.iter().cloned());
        starts.extend(
            order
                .into_iter()
                .take(opts.restarts)
                .map(|i| pool[i].clone()),
        );
    }
    Ok(starts)
}

/// Largest factor by which LM's start screening rescales a point's model values
/// ([`LossTerms::rescaled_sum_squares`](crate::engine::loss::LossTerms::rescaled_sum_squares)).
/// Over the default sweep with seeds 1–6 (GPU) and 1–3 (CPU), each fit against the best
/// loss any run found: fits more than 1 % above it fell from 5–13 per run to 4–11, the
/// mean relative excess from 0.75–1.6e-3 to 0.46–0.79e-3 (one GPU seed 2.7e-3) and, on
/// one GPU seed, from 2.6 (its btdf(gg)+absorb fits of the long-tailed diffuser all
/// started on the dead plateau, 1,500× above the optimum; now every such fit is within
/// 9e-4), at the same number of evaluations. 100 did better there than 10.
const SCREEN_MAX_SCALE: f64 = 100.0;

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
    anyhow::ensure!(!datas.is_empty(), "no data set to fit");
    anyhow::ensure!(datas.len() == losses.len(), "one loss per data set");
    let space = Constraints::resolve(model, &opts.constraints, opts.constraints.lenient)?;
    for (data, loss) in datas.iter().zip(losses) {
        anyhow::ensure!(
            model.kind == data.kind,
            "model {} is a {} model but {} holds {} data",
            model.spec,
            model.kind,
            data.source.display(),
            data.kind
        );
        anyhow::ensure!(
            space.priors.is_empty() || loss.metric == crate::engine::loss::Metric::Chi2,
            "--prior needs --loss chi2: a prior is a χ² term, and {} is not in χ²'s units",
            loss.metric
        );
        anyhow::ensure!(
            data.len() + space.priors.len() > space.dim(),
            "{}: {} cannot determine the {} parameters of {}",
            data.source.display(),
            crate::data::count(data.len(), "sample", "samples"),
            space.dim(),
            model.spec
        );
        if opts.optimizer == Optimizer::Lm {
            anyhow::ensure!(
                loss.is_sum_of_squares(),
                "--optimizer lm needs a sum-of-squares loss; {} is not one (use compass)",
                loss.metric
            );
        }
    }
    anyhow::ensure!(opts.restarts > 0, "--restarts must be at least 1");
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
    // Problems go to the backend in as few evaluators as its sample capacity allows.
    let cap = backend.max_batch_samples().max(1);
    let mut chunks: Vec<std::ops::Range<usize>> = Vec::new();
    let (mut start, mut held) = (0, 0);
    for (q, d) in datas.iter().enumerate() {
        if q > start && held + d.len() > cap {
            chunks.push(start..q);
            start = q;
            held = 0;
        }
        held += d.len();
    }
    chunks.push(start..datas.len());
    let mut optima = Vec::with_capacity(datas.len());
    let mut stats = ManyStats::default();
    for range in chunks {
        let problems: Vec<Problem> = range
            .clone()
            .map(|q| Problem {
                model,
                data: datas[q],
                loss: losses[q],
            })
            .collect();
        let finishers: Vec<Finisher> = problems.iter().map(|p| p.loss.finisher(p.data)).collect();
        let clock = Instant::now();
        let mut eval = backend.prepare_many(&problems)?;
        stats.phases.setup += clock.elapsed().as_secs_f64();
        let n = problems.len();
        let per = opts.initial_points.len()
            + usize::from(!opts.problem_points.is_empty())
            + opts.restarts;
        let mut results: Vec<RestartResult> = {
            let mut obj = UnitBox {
                model,
                space: &space,
                eval: eval.as_mut(),
                finishers: finishers.clone(),
                start_problem: (0..n).flat_map(|q| std::iter::repeat_n(q, per)).collect(),
            };
            let clock = Instant::now();
            let starts = screened_starts(&mut obj, range.clone(), opts)?;
            stats.phases.screening += clock.elapsed().as_secs_f64();
            let clock = Instant::now();
            let results = match opts.optimizer {
                Optimizer::Compass => {
                    compass::minimize(&mut obj, &starts, &opts.compass, progress)?
                }
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
            stats.phases.search += clock.elapsed().as_secs_f64();
            results
        };
        let mut evaluations: Vec<u64> = (0..n).map(|q| eval.evaluations_of(q)).collect();
        // Each problem's polished restart (empty: none).
        let mut polished: Vec<usize> = Vec::new();
        if opts.optimizer == Optimizer::Lm && opts.polish {
            let clock = Instant::now();
            // The CPU reference polishes with the search's own evaluator; a device's is
            // dropped first, so that the two never hold the data at once.
            let cpu = crate::engine::cpu::CpuBackend::new();
            let mut polisher = if backend.id() == "cpu" {
                eval
            } else {
                drop(eval);
                cpu.prepare_many(&problems)?
            };
            let before: Vec<u64> = (0..n).map(|q| polisher.evaluations_of(q)).collect();
            polished = polish_in_f64(
                polisher.as_mut(),
                model,
                &space,
                &finishers,
                &mut results,
                per,
                &opts.lm,
            )?;
            for (q, e) in evaluations.iter_mut().enumerate() {
                *e += polisher.evaluations_of(q) - before[q];
            }
            stats.phases.polish += clock.elapsed().as_secs_f64();
        }
        for (q, restarts) in results.chunks(per).enumerate() {
            // A polished restart is the best: it was the best of the search, and the
            // polish only lowered its cost.
            let best = match polished.get(q) {
                Some(&i) => &restarts[i],
                None => restarts
                    .iter()
                    .min_by(|a, b| a.cost.total_cmp(&b.cost))
                    .expect("at least one restart"),
            };
            let tol = best.cost.abs() * 0.01 + 1e-300;
            optima.push(Optimum {
                flat: space.from_unit(&best.x),
                loss: best.cost,
                within: restarts
                    .iter()
                    .filter(|r| r.cost <= best.cost + tol)
                    .count(),
                evaluations: evaluations[q],
            });
        }
        stats.evaluations += evaluations.iter().sum::<u64>();
        stats.batches += 1;
    }
    Ok((optima, space, stats))
}

/// LM's `ftol` for restarts whose best is then polished in f64 (see [`search_options`]).
pub const POLISHED_SEARCH_FTOL: f64 = 1e-4;

/// LM's stall test for restarts whose best is then polished: a restart that gained less
/// than 1e-3 over its last 10 iterations stops (the polish continues the best restart in
/// f64, where the step is not tilted by f32's forward differences). On the default
/// sweep (seeds 1–4) it left every mean loss excess over the best known unchanged to 3
/// digits and saved 2–3 % of the evaluations, mostly single-restart submissions;
/// 1e-2 saved 7 % but lost quality.
pub const POLISHED_SEARCH_STALL: (usize, f64) = (10, 1e-3);

/// LM's forward-difference step (unit box) for restarts whose best is then polished:
/// 4√u of f32, the smallest step whose f32 differences are not mostly rounding noise.
pub const POLISHED_SEARCH_FD_STEP: f64 = 9.765625e-4;

/// LM's options for the restarts, before any polish.
///
/// With the f64 polish (the default) the restarts only have to find each problem's
/// basin, and they search the same way on every backend: forward differences with the
/// step f32 needs, and a stop at a predicted gain of 1e-4 of Σr². The f64 CPU reference
/// and the f32 GPU engine then take the same steps up to rounding, so the two differ
/// only where rounding tips a restart into another basin. On the default sweep (seeds
/// 1–8) that left 0–2 of its 36 rankings different between them (4 of 288 in all),
/// against 0–3 per seed when the CPU searched with f64's step to f64's floor, which took
/// twice its evaluations for slightly better optima (docs/losses.md).
///
/// Without the polish, each backend goes as far as its arithmetic allows: a step well
/// above √u (`u` the backend's unit roundoff) and a stop at 16u, below which an f32 Σr²
/// cannot tell a gain from rounding (f64 keeps `lm`'s own 1e-6 and 1e-10).
fn search_options(lm: &lm::LmOptions, polish: bool, u: f64) -> lm::LmOptions {
    let mut o = lm.clone();
    if polish {
        o.fd_step = o.fd_step.max(POLISHED_SEARCH_FD_STEP);
        o.ftol = o.ftol.max(POLISHED_SEARCH_FTOL);
        o.stall_window = POLISHED_SEARCH_STALL.0;
        o.stall_gain = o.stall_gain.max(POLISHED_SEARCH_STALL.1);
    } else {
        o.fd_step = o.fd_step.max(4.0 * u.sqrt());
        o.ftol = o.ftol.max(16.0 * u);
    }
    o
}

/// Continue the best restart of each problem (`per` consecutive restarts each) with
/// Levenberg–Marquardt in f64 on the CPU reference (`eval`, holding every problem), from
/// where the search stopped, with f64's forward-difference step and tolerance (an f64
/// run never ends above its start). Returns, per problem, the polished restart (index
/// within the problem).
///
/// Why: the search's forward differences use unit-box steps of ≈ 1e-3 (all f32 allows),
/// whose truncation error tilts the Gauss–Newton step; in a long, narrow valley (strongly
/// correlated parameters, e.g. a BTDF's roughness, scale and index) the search stalls
/// where the tilted step stops descending, up to 10 % above the f64 optimum on the
/// bundled diffusers. One f64 continuation per problem costs a few per cent of the
/// search's evaluations (a fifth of a GPU sweep's time, whose polish is the CPU's
/// work), and makes every backend's optima f64 optima.
fn polish_in_f64(
    eval: &mut dyn Evaluator,
    model: &Model,
    space: &Constraints,
    finishers: &[Finisher],
    results: &mut [RestartResult],
    per: usize,
    lm_opts: &lm::LmOptions,
) -> anyhow::Result<Vec<usize>> {
    let best: Vec<usize> = results
        .chunks(per)
        .enumerate()
        .map(|(q, r)| {
            let i = (0..r.len())
                .min_by(|&a, &b| r[a].cost.total_cmp(&r[b].cost))
                .expect("at least one restart");
            q * per + i
        })
        .collect();
    let starts: Vec<Vec<f64>> = best.iter().map(|&i| results[i].x.clone()).collect();
    let mut obj = UnitBox {
        model,
        space,
        eval,
        finishers: finishers.to_vec(),
        start_problem: (0..finishers.len()).collect(),
    };
    let out = lm::minimize(
        &mut obj,
        &starts,
        lm_opts,
        &|q, s| finishers[q].finish_sum(s),
        &mut |_| {},
    )?;
    for (&i, r) in best.iter().zip(out) {
        // Non-finite only if f64 fails where f32 did not: keep the f32 point then.
        if r.cost.is_finite() {
            results[i].x = r.x;
            results[i].cost = r.cost;
        }
    }
    Ok(best.iter().enumerate().map(|(q, &i)| i - q * per).collect())
}

/// What a fit found, before it is dressed as a [`FitReport`].
#[derive(Clone, Debug)]
pub struct FitOutcome {
    /// Best physical parameter vector.
    pub flat: Vec<f64>,
    /// Its loss.
    pub loss: f64,
    /// Model values at the best parameters, one per sample.
    pub values: Vec<f64>,
    /// χ² = Σ ((y′ − y)/u)² at the best parameters.
    pub chi2: f64,
    /// Σ ((θ − mean)/sd)² of the priors at the best parameters (0 without priors).
    pub chi2_prior: f64,
    /// Degrees of freedom: samples + priors − fitted parameters.
    pub dof: usize,
    /// The constraints the fit was made under.
    pub constraints: Constraints,
    pub cov: Covariance,
    /// Restarts whose final loss is within 1% of the best.
    pub within: usize,
    pub evaluations: u64,
    pub seconds: f64,
}

/// Fit `model` to `data` under `loss` and report it (docs/output.md).
pub fn fit(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    backend: &dyn Backend,
    opts: &FitOptions,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<FitReport> {
    let o = fit_outcome(model, data, loss, backend, opts, progress)?;
    Ok(make_report(model, data, loss, opts, backend, o))
}

/// Fit `model` to `data` under `loss`: multi-start optimisation on `backend`, then χ² and
/// the parameter covariance at the best point.
pub fn fit_outcome(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    backend: &dyn Backend,
    opts: &FitOptions,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<FitOutcome> {
    let t0 = Instant::now();
    let (optima, space, stats) = fit_many(model, &[data], &[loss], backend, opts, progress)?;
    if std::env::var_os("BSDFIT_TRACE").is_some() {
        eprintln!(
            "trace: {:?}, {} evaluations",
            stats.phases, stats.evaluations
        );
    }
    let best = optima.into_iter().next().expect("one problem, one optimum");
    let mut o = conclude(model, data, loss, best, space)?;
    o.seconds = t0.elapsed().as_secs_f64();
    Ok(o)
}

/// Fit one model to several data sets (a sweep's stage: same model and loss term shape,
/// any losses and weightings) in lockstep ([`fit_many`]), then report each fit, with the
/// stage's time per phase. A report's `seconds` are the stage's, shared among its fits by
/// their sample counts; its `evaluations` its own.
pub fn fit_stage(
    model: &Model,
    datas: &[&Dataset],
    losses: &[Loss],
    backend: &dyn Backend,
    opts: &FitOptions,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<(Vec<FitReport>, PhaseSeconds)> {
    let t0 = Instant::now();
    let (optima, space, stats) = fit_many(model, datas, losses, backend, opts, progress)?;
    let mut phases = stats.phases;
    let clock = Instant::now();
    let mut outcomes = Vec::with_capacity(datas.len());
    for ((data, &loss), best) in datas.iter().zip(losses).zip(optima) {
        outcomes.push(conclude(model, data, loss, best, space.clone())?);
    }
    phases.conclusions += clock.elapsed().as_secs_f64();
    let seconds = t0.elapsed().as_secs_f64();
    let total: usize = datas.iter().map(|d| d.len()).sum::<usize>().max(1);
    let reports = outcomes
        .into_iter()
        .zip(datas.iter().zip(losses))
        .map(|(mut o, (data, &loss))| {
            o.seconds = seconds * data.len() as f64 / total as f64;
            make_report(model, data, loss, opts, backend, o)
        })
        .collect();
    Ok((reports, phases))
}

/// χ², the covariance and the warnings at a problem's optimum, in f64 on the CPU
/// reference whatever the search ran on.
///
/// Why not on the search's backend: they take one point and its 2P central-difference
/// neighbours, a few hundred thousand evaluations at most, which a device serves in a
/// handful of latency-bound submissions plus an evaluator (upload, buffers) per fit (on
/// lavapipe the conclusions took 7.9 s of the default sweep's 52 s of thread time, against
/// 2.5 s on the CPU); and f32 central differences leave the covariance's Jacobian with
/// relative errors of ~u/1e-4 ≈ 6e-4, where f64 gives ~1e-8.
fn conclude(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    best: Optimum,
    space: Constraints,
) -> anyhow::Result<FitOutcome> {
    let t0 = Instant::now();
    let cpu = crate::engine::cpu::CpuBackend::new();
    let mut eval = cpu.prepare(Problem { model, data, loss })?;
    let flat = best.flat;
    let searched = best.evaluations;
    let values = eval.values(&flat)?;
    let chi2 = chi2(data, &values);
    let mut cov = covariance(model, data, loss, eval.as_mut(), &flat, &space)?;
    cov.warnings.extend(space.on_bound_warnings(&flat));
    Ok(FitOutcome {
        loss: best.loss,
        chi2_prior: space.prior_chi2(&flat),
        dof: data.len() + space.priors.len() - space.dim(),
        constraints: space,
        flat,
        values,
        chi2,
        cov,
        within: best.within,
        evaluations: searched + eval.evaluations(),
        seconds: t0.elapsed().as_secs_f64(),
    })
}

fn make_report(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    opts: &FitOptions,
    backend: &dyn Backend,
    o: FitOutcome,
) -> FitReport {
    // χ²_red counts each prior as one observation (module doc of `constraints`).
    let chi2_red = (o.chi2 + o.chi2_prior) / o.dof as f64;
    let flat = &o.flat;
    let mut cov = o.cov;
    for (j, f) in o.constraints.fixed.iter().enumerate() {
        if f.is_some() {
            cov.std[j] = Some(0.0); // fixed: exact by assumption
        }
    }
    let constraints = (!o.constraints.is_trivial()).then(|| {
        let mut v = o.constraints.to_json();
        v["chi2_prior"] = serde_json::json!(o.chi2_prior);
        v
    });
    let group = |vals: &[Option<f64>]| -> Map<String, Value> {
        let mut m = Map::new();
        for p in &model.params {
            let w = p.width(model.channels);
            let slice = &vals[p.index..p.index + w];
            // rgb and per-plane parameters are arrays (plane-major, then channel).
            let v = if w > 1 {
                Value::Array(slice.iter().map(|x| json_num(*x)).collect())
            } else {
                json_num(slice[0])
            };
            m.insert(p.name.clone(), v);
        }
        m
    };
    let params = group(&flat.iter().map(|&v| Some(v)).collect::<Vec<_>>());
    let param_std = group(&cov.std);
    FitReport {
        model: model.spec.clone(),
        loss: loss.metric.to_string(),
        weights: loss.weights.to_string(),
        optimizer: opts.optimizer.to_string(),
        backend: backend.id().to_string(),
        restarts: opts.restarts,
        evaluations: o.evaluations,
        seconds: o.seconds,
        best: Best {
            loss: o.loss,
            chi2_red,
            params,
            param_std,
        },
        data: data.source.display().to_string(),
        material: data.material.clone(),
        samples: data.len(),
        channels: data.channels.clone(),
        axes: model.axes.clone(),
        seed: opts.seed,
        restarts_within_1pct: o.within,
        flat_names: model.flat_names(),
        flat_params: flat.to_vec(),
        flat_std: cov.std,
        correlation: cov.correlation,
        warnings: data
            .assumed_uncertainty
            .map(|(rel, abs)| {
                format!(
                    "the data's uncertainties were assumed, not measured (u = sqrt((REL·|value|)² + ABS²), REL = {rel}, ABS = {abs} sr⁻¹): χ² and parameter uncertainties rest on that assumption"
                )
            })
            .into_iter()
            .chain(cov.warnings)
            .collect(),
        dof: o.dof,
        n_params: o.constraints.dim(),
        constraints,
        monte_carlo: None,
    }
}

fn json_num(v: Option<f64>) -> Value {
    match v {
        Some(x) if x.is_finite() => serde_json::Number::from_f64(x)
            .map(Value::Number)
            .unwrap_or(Value::Null),
        _ => Value::Null,
    }
}

impl FitReport {
    /// A compact human-readable summary.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "model {} fitted to '{}' ({} samples, {} channel(s)): loss {}/{} = {:.6e}, χ²_red = {:.3}\n",
            self.model,
            self.material,
            self.samples,
            self.channels.len(),
            self.loss,
            self.weights,
            self.best.loss,
            self.best.chi2_red
        );
        let fixed = self
            .constraints
            .as_ref()
            .and_then(|c| c.get("fixed"))
            .and_then(Value::as_object);
        for (i, name) in self.flat_names.iter().enumerate() {
            let std = match self.flat_std[i] {
                _ if fixed.is_some_and(|f| f.contains_key(name)) => "(fixed)".into(),
                Some(s) => format!("± {s:.3e}"),
                None => "(not determined)".into(),
            };
            s += &format!("  {name:<14} = {:<12.6} {std}\n", self.flat_params[i]);
        }
        s += &format!(
            "  {} restarts ({} within 1% of best), {} evaluations, {:.2} s on {}\n",
            self.restarts, self.restarts_within_1pct, self.evaluations, self.seconds, self.backend
        );
        if let Some(priors) = self
            .constraints
            .as_ref()
            .and_then(|c| c.get("priors"))
            .and_then(Value::as_array)
            .filter(|p| !p.is_empty())
        {
            let chi2_prior = self
                .constraints
                .as_ref()
                .and_then(|c| c["chi2_prior"].as_f64());
            s += &format!(
                "  {} in χ² (their share: {:.3}); χ²_red = (χ² + priors)/(samples + priors − fitted) with {} degrees of freedom\n",
                crate::data::count(priors.len(), "prior", "priors"),
                chi2_prior.unwrap_or(f64::NAN),
                self.dof
            );
        }
        for w in &self.warnings {
            s += &format!("  warning: {w}\n");
        }
        if let Some(mc) = &self.monte_carlo {
            s += &mc.summary();
        }
        s
    }
}
