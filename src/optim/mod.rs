//! Optimizers over the unit box [0,1]^P, all restarts stepped in lockstep.
//!
//! Solver and problem are separate (as in argmin): a solver sees only a
//! [`BatchObjective`] — costs of a batch of unit-box points — and never a backend.

pub mod compass;
pub mod lm;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A batched objective on the unit box.
pub trait BatchObjective {
    fn dim(&self) -> usize;
    /// Costs of N points (N × P, row-major, each coordinate in [0, 1]). NaN means invalid.
    fn costs(&mut self, points: &[f64]) -> anyhow::Result<Vec<f64>>;
}

/// A batched sum-of-squares objective: residual vectors r(x) with cost = finish(Σ r²).
pub trait BatchResiduals: BatchObjective {
    /// Residuals of N points (N × K, row-major).
    fn residuals(&mut self, points: &[f64]) -> anyhow::Result<Vec<f64>>;
    /// K, the residual count per point.
    fn residual_count(&self) -> usize;
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
