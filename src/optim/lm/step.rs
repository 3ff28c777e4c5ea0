//! One Levenberg–Marquardt iteration of every active restart: each solves its damped
//! normal equations for a step within the unit box, the trial points go to the
//! objective in one batch, and each restart accepts or rejects its step and updates λ.

use super::state::{LmState, RestartState};
use super::termination::{Outcome, Termination};
use super::LmOptions;
use crate::optim::{sanitize, BatchResiduals, NormalEquations};
use nalgebra::{DMatrix, DVector};

/// Forward-difference steps at each of `points`: +h, or −h where +h leaves the box.
pub(super) fn fd_steps(points: &[f64], h: f64) -> Vec<f64> {
    points
        .iter()
        .map(|&x| if x + h <= 1.0 { h } else { -h })
        .collect()
}

impl LmState {
    /// One iteration: every running restart with a finite Σr² solves its damped system,
    /// and those whose step could show a gain evaluate it, all in one batch. Returns
    /// false, having evaluated nothing, when no restart has a step left to take.
    pub(super) fn step(
        &mut self,
        obj: &mut dyn BatchResiduals,
        opts: &LmOptions,
    ) -> anyhow::Result<bool> {
        let active = self.stop_not_finite();
        if active.is_empty() {
            return Ok(false);
        }
        let (moving, trial) = self.trial_points(&active, opts);
        if moving.is_empty() {
            return Ok(false);
        }
        // One batch: the trial points with their neighbours (the backend may reduce the
        // normal equations where it evaluates the residuals).
        let p = self.dim;
        let normal = obj.normal_equations_of(&moving, &trial, &fd_steps(&trial, opts.fd_step))?;
        for (ne, (a, &i)) in normal.into_iter().zip(moving.iter().enumerate()) {
            self.restarts[i].take_step(ne, &trial[a * p..(a + 1) * p], opts);
        }
        Ok(true)
    }

    /// The running restarts whose Σr² is finite; the others stop.
    fn stop_not_finite(&mut self) -> Vec<usize> {
        let active: Vec<usize> = (0..self.restarts.len())
            .filter(|&i| self.restarts[i].running() && self.restarts[i].ss.is_finite())
            .collect();
        for s in &mut self.restarts {
            if !s.ss.is_finite() {
                s.stop_for(Termination::NotFinite);
            }
        }
        active
    }

    /// The restarts of `active` whose damped step could show a gain, and their trial
    /// points (one after the other); the others stop, converged.
    fn trial_points(&mut self, active: &[usize], opts: &LmOptions) -> (Vec<usize>, Vec<f64>) {
        let mut trial = Vec::with_capacity(active.len() * self.dim);
        let mut moving = Vec::new();
        for &i in active {
            let s = &mut self.restarts[i];
            match s.trial_point(opts.ftol) {
                Some(x) => {
                    trial.extend(x);
                    moving.push(i);
                }
                None => s.stop_for(Termination::PredictedGain),
            }
        }
        (moving, trial)
    }
}

impl RestartState {
    /// The point the damped Gauss–Newton step leads to from x, clipped to the box, or
    /// None where the step's predicted gain is below `ftol`·Σr².
    fn trial_point(&self, ftol: f64) -> Option<Vec<f64>> {
        let p = self.x.len();
        let ne = &self.normal;
        let jtj = DMatrix::from_row_slice(p, p, &ne.jtj);
        let g = DVector::from_column_slice(&ne.jtr);
        let dmax = (0..p).map(|j| jtj[(j, j)]).fold(0.0, f64::max).max(1e-300);
        let mut a_mat = jtj.clone();
        for j in 0..p {
            let d = self.scale[j].max(jtj[(j, j)]);
            a_mat[(j, j)] += self.lambda * d.max(1e-9 * dmax);
        }
        let delta = bounded_step(&a_mat, &g, &self.x);
        // The Gauss–Newton model's Σr² decrease for the damped step (before clipping
        // to the box), −2gᵀδ − δᵀJᵀJδ ≥ −gᵀδ ≥ 0. Below ftol·Σr² the restart has
        // converged as far as its arithmetic can show: without this test a backend
        // whose Σr² carries rounding noise above ftol (f32) rejects step after step
        // until λ overflows, P + 1 evaluations each.
        let step = delta.map(|d| if d.is_finite() { d } else { 0.0 });
        let predicted = -2.0 * g.dot(&step) - (&jtj * &step).dot(&step);
        let measurable = predicted > ftol * self.ss; // false for NaN too
        measurable.then(|| {
            (0..p)
                .map(|j| (self.x[j] + step[j]).clamp(0.0, 1.0))
                .collect()
        })
    }

    /// Accept the step to `x_new` (whose normal equations are `ne`) if it lowers Σr²,
    /// λ falling, else reject it, λ rising; then stop if the iteration says so.
    fn take_step(&mut self, ne: NormalEquations, x_new: &[f64], opts: &LmOptions) {
        let p = x_new.len();
        self.iterations += 1;
        self.evaluations += p + 1;
        let ss_new = sanitize(ne.ss);
        let length: f64 = x_new
            .iter()
            .zip(&self.x)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt();
        let outcome = if ss_new < self.ss {
            let gain = (self.ss - ss_new) / self.ss.max(1e-300);
            self.x.copy_from_slice(x_new);
            for j in 0..p {
                let d = ne.jtj[j * p + j];
                if d.is_finite() {
                    self.scale[j] = self.scale[j].max(d);
                }
            }
            self.ss = ss_new;
            self.normal = ne;
            self.lambda = (self.lambda / 3.0).max(1e-12);
            Outcome::Accepted { gain, length }
        } else {
            self.lambda *= 4.0;
            Outcome::Rejected { length }
        };
        if let Some(why) = self.termination(outcome, opts) {
            self.stop_for(why);
        }
    }
}

/// The damped Gauss–Newton step −A⁻¹g restricted to the box: a parameter on a bound of
/// the unit box whose step would leave it is held there and the system solved for the
/// others (an active set, as in projected Levenberg–Marquardt methods, e.g. Kanzow, Yamashita
/// & Fukushima 2004). Clamping the full step instead gives the free parameters a step
/// computed for a move the bound forbids; it is then rejected, λ grows, and a fit whose
/// optimum lies on a bound (σ = 0, k_s = 0) crawls there in many rejected iterations.
///
/// A parameter exactly on its bound counts as on it. An ε-active set (held within 1e-4 of
/// a bound, as in Bertsekas' projected Newton method) was needed while the damping used
/// the current diag(JᵀJ) (VMF, whose r = 0 is exact Lambert while r → 0⁺ is not, had
/// r creep towards 0 and block the albedos); with the running-maximum scaling the
/// restarts converge there without it (`tests/bounded_lm.rs`), and without its bias of
/// up to 1e-4 in the unit box.
fn bounded_step(a: &DMatrix<f64>, g: &DVector<f64>, x: &[f64]) -> DVector<f64> {
    let p = x.len();
    let mut held = vec![false; p];
    loop {
        let free: Vec<usize> = (0..p).filter(|&j| !held[j]).collect();
        let mut delta = DVector::zeros(p);
        if !free.is_empty() {
            let sub = DMatrix::from_fn(free.len(), free.len(), |r, c| a[(free[r], free[c])]);
            let rhs = DVector::from_fn(free.len(), |r, _| -g[free[r]]);
            let d = match sub.clone().cholesky() {
                Some(ch) => ch.solve(&rhs),
                None => sub
                    .lu()
                    .solve(&rhs)
                    .unwrap_or_else(|| DVector::zeros(free.len())),
            };
            for (r, &j) in free.iter().enumerate() {
                delta[j] = d[r];
            }
        }
        let mut changed = false;
        for &j in &free {
            let leaves = (x[j] <= 0.0 && delta[j] < 0.0) || (x[j] >= 1.0 && delta[j] > 0.0);
            if leaves {
                held[j] = true;
                changed = true;
            }
        }
        if !changed {
            return delta;
        }
    }
}
