//! Optimizers over the unit box [0,1]^P, all restarts stepped in lockstep.
//!
//! Solver and problem are separate (as in argmin): a solver sees only a
//! [`BatchObjective`] — costs of a batch of unit-box points — and never a backend.
//! Each point of a batch is tagged with the start (restart) it belongs to, so that one
//! objective can hold many independent problems (data sets, Monte Carlo replicas) whose
//! restarts the solver steps together without knowing it.

pub mod compass;
pub mod lm;

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
        let mut jtj = vec![0.0; p * p];
        let mut jtr = vec![0.0; p];
        let mut jrow = vec![0.0; p];
        for m in 0..k {
            for j in 0..p {
                jrow[j] = (rows[(j + 1) * k + m] - r0[m]) / steps[j];
                jtr[j] += jrow[j] * r0[m];
            }
            // The upper triangle only; JᵀJ is symmetric (x·y = y·x exactly in IEEE
            // arithmetic, so the mirrored sums are the same numbers).
            for a in 0..p {
                let ja = jrow[a];
                for (t, &jb) in jtj[a * p + a..(a + 1) * p].iter_mut().zip(&jrow[a..]) {
                    *t += ja * jb;
                }
            }
        }
        for a in 0..p {
            for b in 0..a {
                jtj[a * p + b] = jtj[b * p + a];
            }
        }
        NormalEquations {
            jtj,
            jtr,
            ss: sanitize(r0.iter().map(|v| v * v).sum()),
        }
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
