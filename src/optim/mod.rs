//! Optimizers over the unit box [0,1]^P, all restarts stepped in lockstep.
//!
//! Solver and problem are separate (as in argmin): a solver sees only a
//! [`BatchObjective`] — costs of a batch of unit-box points — and never a backend.
//! Each point of a batch is tagged with the start (restart) it belongs to, so that one
//! objective can hold many independent problems (data sets, Monte Carlo replicas) whose
//! restarts the solver steps together without knowing it.

pub mod compass;
pub mod lm;

use crate::math::dot;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A batched objective on the unit box.
pub trait BatchObjective {
    fn dim(&self) -> usize;
    /// Costs of N points (N × P, row-major, each coordinate in [0, 1]). NaN means invalid.
    fn costs(&mut self, points: &[f64]) -> anyhow::Result<Vec<f64>>;
    /// Costs of N points, `owners[i]` the index of the start point i descends from. An
    /// objective made of several independent problems maps starts to problems; one made
    /// of a single problem ignores `owners` (the default).
    fn costs_of(&mut self, owners: &[usize], points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let _ = owners;
        self.costs(points)
    }
}

/// A batched sum-of-squares objective: residual vectors r(x) with cost = finish(Σ r²).
pub trait BatchResiduals: BatchObjective {
    /// Residuals of N points (N × K, row-major).
    fn residuals(&mut self, points: &[f64]) -> anyhow::Result<Vec<f64>>;
    /// K, the residual count per point.
    fn residual_count(&self) -> usize;

    /// The Gauss–Newton normal equations at each of N points (N × P) with the forward-
    /// difference Jacobian J_kj = (r_k(x + h_j e_j) − r_k(x)) / h_j, signed steps `steps`
    /// (N × P). This default forms them on the host from `residuals`; a backend can reduce
    /// them where the residuals are computed.
    fn normal_equations(
        &mut self,
        points: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<NormalEquations>> {
        normal_equations_on_host(self, points, steps)
    }

    /// [`Self::normal_equations`] of points tagged with their starts (see
    /// [`BatchObjective::costs_of`]).
    fn normal_equations_of(
        &mut self,
        owners: &[usize],
        points: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<NormalEquations>> {
        let _ = owners;
        self.normal_equations(points, steps)
    }

    /// [`Self::sum_squares`] of points tagged with their starts.
    fn sum_squares_of(&mut self, owners: &[usize], points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let _ = owners;
        self.sum_squares(points)
    }

    /// Σ r² of N points (+∞ where not finite).
    fn sum_squares(&mut self, points: &[f64]) -> anyhow::Result<Vec<f64>> {
        let k = self.residual_count();
        Ok(self
            .residuals(points)?
            .chunks(k)
            .map(|r| sanitize(r.iter().map(|v| v * v).sum()))
            .collect())
    }
}

/// The normal equations formed on the host from [`BatchResiduals::residuals`] (the
/// default of [`BatchResiduals::normal_equations`], callable by implementations that
/// override it for some problems only).
pub fn normal_equations_on_host<R: BatchResiduals + ?Sized>(
    obj: &mut R,
    points: &[f64],
    steps: &[f64],
) -> anyhow::Result<Vec<NormalEquations>> {
    let p = obj.dim();
    let k = obj.residual_count();
    let batch = difference_points(points, steps, p);
    let res = obj.residuals(&batch)?;
    Ok(res
        .chunks(k * (p + 1))
        .zip(steps.chunks(p))
        .map(|(rows, h)| NormalEquations::from_residuals(rows, h, k))
        .collect())
}

/// Per point: the point, then the point moved by each signed step (N × (P + 1) × P).
pub fn difference_points(points: &[f64], steps: &[f64], p: usize) -> Vec<f64> {
    let mut batch = Vec::with_capacity(points.len() * (p + 1));
    for (x, h) in points.chunks(p).zip(steps.chunks(p)) {
        batch.extend_from_slice(x);
        for (j, hj) in h.iter().enumerate() {
            batch.extend_from_slice(x);
            let last = batch.len() - p + j;
            batch[last] += hj;
        }
    }
    batch
}

/// JᵀJ (P × P, row-major), Jᵀr and Σ r² of one point.
#[derive(Clone, Debug, PartialEq)]
pub struct NormalEquations {
    pub jtj: Vec<f64>,
    pub jtr: Vec<f64>,
    pub ss: f64,
}

impl NormalEquations {
    /// From the residual rows of a point and its P moved copies ((P + 1) × K).
    pub fn from_residuals(rows: &[f64], steps: &[f64], k: usize) -> NormalEquations {
        let p = steps.len();
        let r0 = &rows[..k];
        let mut diff = vec![0.0; p * k];
        for (j, d) in diff.chunks_exact_mut(k.max(1)).enumerate().take(p) {
            let moved = &rows[(j + 1) * k..(j + 2) * k];
            for ((t, &a), &b) in d.iter_mut().zip(moved).zip(r0) {
                *t = a - b;
            }
        }
        Self::from_differences(r0, &diff, steps)
    }

    /// From the residuals r(x) (K) and the differences r(x + h_j e_j) − r(x), one
    /// contiguous row of K per parameter (P × K). The steps divide the P(P + 1)/2 + P
    /// sums instead of the P·K differences. Each sum is a dot product of two rows with
    /// independent partial sums, which the compiler vectorises (a row-by-row triangular
    /// update does not vectorise, and LM forms these for every candidate group it
    /// evaluates).
    pub fn from_differences(r0: &[f64], diff: &[f64], steps: &[f64]) -> NormalEquations {
        let p = steps.len();
        let k = r0.len();
        let row = |j: usize| &diff[j * k..(j + 1) * k];
        let mut jtj = vec![0.0; p * p];
        let mut jtr = vec![0.0; p];
        for a in 0..p {
            jtr[a] = dot(row(a), r0) / steps[a];
            for b in a..p {
                let v = dot(row(a), row(b)) / (steps[a] * steps[b]);
                jtj[a * p + b] = v;
                jtj[b * p + a] = v;
            }
        }
        NormalEquations {
            jtj,
            jtr,
            ss: sanitize(r0.iter().map(|v| v * v).sum()),
        }
    }

    /// Add further residual rows: `r0` their values at the point, `moved[j]` at the point
    /// moved by the signed step `steps[j]` (e.g. the priors' rows, known on the host).
    pub fn add_rows(&mut self, r0: &[f64], moved: &[Vec<f64>], steps: &[f64]) {
        let p = steps.len();
        let d: Vec<Vec<f64>> = moved
            .iter()
            .map(|m| m.iter().zip(r0).map(|(a, b)| a - b).collect())
            .collect();
        for a in 0..p {
            self.jtr[a] += dot(&d[a], r0) / steps[a];
            for b in 0..p {
                self.jtj[a * p + b] += dot(&d[a], &d[b]) / (steps[a] * steps[b]);
            }
        }
        self.ss = sanitize(self.ss + r0.iter().map(|v| v * v).sum::<f64>());
    }
}

/// Outcome of one restart.
#[derive(Clone, Debug)]
pub struct RestartResult {
    /// Best point in the unit box.
    pub x: Vec<f64>,
    pub cost: f64,
    pub iterations: usize,
    /// Candidate points evaluated for this restart.
    pub evaluations: usize,
    /// Why it stopped.
    pub stop: Stop,
}

/// Why a restart stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stop {
    /// Levenberg–Marquardt's reason.
    Lm(lm::Termination),
    /// Compass search: the step fell below its minimum (converged).
    StepBelowMinimum,
    /// Compass search: the restart used its evaluation budget.
    EvaluationBudget,
}

impl Stop {
    /// A short identifier (`small_gain`, `max_iterations`, …).
    pub fn status(self) -> &'static str {
        use lm::Termination as T;
        match self {
            Stop::Lm(T::NotFinite) => "not_finite",
            Stop::Lm(T::PredictedGain) => "predicted_gain",
            Stop::Lm(T::SmallGain) => "small_gain",
            Stop::Lm(T::SmallStep) => "small_step",
            Stop::Lm(T::Damping) => "damping",
            Stop::Lm(T::Stalled) => "stalled",
            Stop::Lm(T::MaxIterations) => "max_iterations",
            Stop::StepBelowMinimum => "step_below_minimum",
            Stop::EvaluationBudget => "evaluation_budget",
        }
    }

    /// Whether the optimizer stopped because it converged, not because it ran out of
    /// iterations or evaluations or met a non-finite cost.
    pub fn converged(self) -> bool {
        use lm::Termination as T;
        !matches!(
            self,
            Stop::Lm(T::NotFinite) | Stop::Lm(T::MaxIterations) | Stop::EvaluationBudget
        )
    }

    /// Why it stopped, in words.
    pub fn message(self) -> &'static str {
        use lm::Termination as T;
        match self {
            Stop::Lm(T::NotFinite) => "the cost is not finite at the point reached",
            Stop::Lm(T::PredictedGain) => {
                "the next step's predicted gain is below the tolerance (converged)"
            }
            Stop::Lm(T::SmallGain) => "the last step gained less than the tolerance (converged)",
            Stop::Lm(T::SmallStep) => "the step became shorter than the tolerance (converged)",
            Stop::Lm(T::Damping) => "no step lowered the cost however damped (converged)",
            Stop::Lm(T::Stalled) => "the cost stopped falling over the last iterations (converged)",
            Stop::Lm(T::MaxIterations) => "the iteration limit was reached before convergence",
            Stop::StepBelowMinimum => "the poll step fell below its minimum (converged)",
            Stop::EvaluationBudget => "the evaluation budget ran out before convergence",
        }
    }
}

/// Seeded uniform starting points in the unit box.
pub fn random_starts(dim: usize, count: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| (0..dim).map(|_| rng.random::<f64>()).collect())
        .collect()
}

/// NaN costs compare as +∞ so an invalid point never wins.
pub fn sanitize(c: f64) -> f64 {
    if c.is_nan() {
        f64::INFINITY
    } else {
        c
    }
}
