//! Levenberg–Marquardt with Marquardt's diagonal scaling, kept as the running maximum of
//! diag(JᵀJ) (Moré 1978, "The Levenberg-Marquardt algorithm: implementation and theory";
//! as MINPACK), batched: each iteration sends one batch, the trial point of every active restart with its
//! forward-difference neighbours, whose normal equations give the trial's Σr² and, if the
//! step is accepted, the next Jacobian; a rejected step keeps the normal equations of the
//! point it stays at. So an iteration costs P + 1 evaluations and one submission (a
//! Jacobian batch and a trial batch cost P + 2 and two, and recomputed an unchanged
//! Jacobian after each rejected step). Steps are projected onto the unit box. A restart
//! stops when an accepted step gains less than `ftol` of Σr², or when the next step's
//! predicted gain is below it, before evaluating that step (MINPACK's ftol test also
//! weighs the predicted reduction).
//!
//! Split as argmin splits a solver: `state` holds what each restart carries from one
//! iteration to the next (point, Σr², λ, scaling, counters), `step` is one iteration
//! of every active restart (the damped normal equations solved, the trial points sent in
//! one batch, each step accepted or rejected), and `termination` says why a restart
//! stops. [`minimize`] only drives them.

mod state;
mod step;
mod termination;

pub use termination::Termination;

use super::{BatchResiduals, RestartResult};
use state::LmState;

#[derive(Clone, Debug)]
pub struct LmOptions {
    pub max_iterations: usize,
    /// Forward-difference step in the unit box (larger for f32 backends).
    pub fd_step: f64,
    pub initial_lambda: f64,
    /// Stop when an accepted step improves Σr² by less than this fraction, or when the
    /// next step's predicted improvement (the Gauss–Newton model's) is below it: no
    /// evaluation could then tell the step from rounding (MINPACK's ftol test uses both
    /// the actual and the predicted reduction in the same way).
    pub ftol: f64,
    /// Stop when the step is shorter than this (unit box).
    pub xtol: f64,
    /// Stop a restart whose Σr² fell by less than `stall_gain` of itself over its last
    /// `stall_window` iterations (0: never). Why: in a long, curved valley LM crawls,
    /// each step accepted or rejected in turn and gaining far more than `ftol` now and
    /// then, so neither `ftol` nor `xtol` stops it before `max_iterations`; at the default
    /// 1e-6 per 20 iterations, the 200-iteration cap would gain at most ~1e-5 more. On the
    /// default sweep such crawls were a fifth of the f64 polish's iterations, and (in
    /// lockstep) each was a submission of its own.
    pub stall_window: usize,
    pub stall_gain: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        LmOptions {
            max_iterations: 200,
            fd_step: 1e-6,
            initial_lambda: 1e-3,
            ftol: 1e-10,
            xtol: 1e-9,
            stall_window: 20,
            stall_gain: 1e-6,
        }
    }
}

/// Minimise Σ r² from every start; costs are reported as `finish(start, Σ r²)`.
pub fn minimize(
    obj: &mut dyn BatchResiduals,
    starts: &[Vec<f64>],
    opts: &LmOptions,
    finish: &dyn Fn(usize, f64) -> f64,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<Vec<RestartResult>> {
    let mut state = LmState::start(obj, starts, opts)?;
    for _ in 0..opts.max_iterations {
        if !state.step(obj, opts)? {
            break;
        }
        progress(state.running());
    }
    state.stop_running(Termination::MaxIterations);
    Ok(state.results(finish))
}

#[cfg(test)]
mod tests {
    use super::super::BatchObjective;
    use super::*;

    /// Exponential decay y = a·exp(−b t) + c on the unit box (a ∈ [0,1] etc.), each
    /// model value perturbed by a relative `noise` × a deterministic function of the point
    /// that changes with it at the scale of rounding (0: exact; 3e-7: Σr² as an f32
    /// evaluator computes it).
    struct Decay {
        t: Vec<f64>,
        y: Vec<f64>,
        noise: f64,
    }
    impl BatchObjective for Decay {
        fn dim(&self) -> usize {
            3
        }
        fn costs(&mut self, pts: &[f64]) -> anyhow::Result<Vec<f64>> {
            Ok(self
                .residuals(pts)?
                .chunks(self.t.len())
                .map(|r| r.iter().map(|v| v * v).sum())
                .collect())
        }
    }
    impl BatchResiduals for Decay {
        fn residuals(&mut self, pts: &[f64]) -> anyhow::Result<Vec<f64>> {
            let mut out = Vec::new();
            for x in pts.chunks(3) {
                for (i, (t, y)) in self.t.iter().zip(&self.y).enumerate() {
                    let f = x[0] * (-4.0 * x[1] * t).exp() + x[2];
                    let phase = (x[0] * 1e7 + x[1] * 3e7 + x[2] * 7e7 + i as f64).sin();
                    out.push(f * (1.0 + self.noise * phase) - y);
                }
            }
            Ok(out)
        }
        fn residual_count(&self) -> usize {
            self.t.len()
        }
    }

    const TRUTH: [f64; 3] = [0.7, 0.45, 0.12];

    /// The decay of `TRUTH` at 40 times in [0, 2) plus `misfit`·cos(i) (a residual of the
    /// data's own, so that Σr² does not vanish at the optimum), evaluated with `noise`.
    fn decay(misfit: f64, noise: f64) -> Decay {
        let t: Vec<f64> = (0..40).map(|i| i as f64 / 20.0).collect();
        let y = t
            .iter()
            .enumerate()
            .map(|(i, t)| {
                TRUTH[0] * (-4.0 * TRUTH[1] * t).exp() + TRUTH[2] + misfit * (i as f64).cos()
            })
            .collect();
        Decay { t, y, noise }
    }

    /// Best restart's point, checked against `TRUTH` within `tol`; its cost.
    fn best_near_truth(out: &[RestartResult], tol: f64) -> f64 {
        let best = out.iter().min_by(|a, b| a.cost.total_cmp(&b.cost)).unwrap();
        for (a, b) in best.x.iter().zip(TRUTH) {
            assert!((a - b).abs() < tol, "{:?}", best.x);
        }
        best.cost
    }

    /// With Σr² noisy at ~1e-7 (f32) and ftol above that noise, every restart stops on
    /// the predicted reduction once no step can show a gain, near the optimum, instead of
    /// rejecting noise-level steps until λ or the step length ends it.
    #[test]
    fn a_noisy_sum_of_squares_stops_on_the_predicted_reduction() {
        let mut d = decay(0.01, 3e-7);
        let starts = super::super::random_starts(3, 6, 3);
        let opts = LmOptions {
            fd_step: 1e-3,
            ftol: 1e-6,
            ..LmOptions::default()
        };
        let out = minimize(&mut d, &starts, &opts, &|_, s| s, &mut |_| {}).unwrap();
        best_near_truth(&out, 2e-2);
        // 71 iterations in all here; 119 without the predicted-reduction test, whose
        // restarts end only on λ or the step length.
        let iterations: usize = out.iter().map(|r| r.iterations).sum();
        assert!(iterations < 90, "{iterations} iterations in all");
    }

    /// Each restart's reason to stop, from `minimize`'s loop run on the state.
    fn stops(obj: &mut Decay, starts: &[Vec<f64>], opts: &LmOptions) -> Vec<Termination> {
        let mut state = LmState::start(obj, starts, opts).unwrap();
        for _ in 0..opts.max_iterations {
            if !state.step(obj, opts).unwrap() {
                break;
            }
        }
        state.stop_running(Termination::MaxIterations);
        state.restarts.iter().map(|s| s.stop.unwrap()).collect()
    }

    /// The noisy decay's restarts all end on the predicted reduction (as
    /// [`a_noisy_sum_of_squares_stops_on_the_predicted_reduction`] expects of them), and
    /// restarts cut off by the iteration cap say so.
    #[test]
    fn each_restart_says_why_it_stopped() {
        let starts = super::super::random_starts(3, 6, 3);
        let noisy = LmOptions {
            fd_step: 1e-3,
            ftol: 1e-6,
            ..LmOptions::default()
        };
        let why = stops(&mut decay(0.01, 3e-7), &starts, &noisy);
        assert!(
            why.iter().all(|&w| w == Termination::PredictedGain),
            "{why:?}"
        );
        let short = LmOptions {
            max_iterations: 3,
            ..LmOptions::default()
        };
        let why = stops(&mut decay(0.01, 0.0), &starts, &short);
        assert!(
            why.iter().all(|&w| w == Termination::MaxIterations),
            "{why:?}"
        );
        // `minimize` hands each restart's reason on with its result.
        let results = minimize(
            &mut decay(0.01, 3e-7),
            &starts,
            &noisy,
            &|_, s| s,
            &mut |_| {},
        )
        .unwrap();
        let stop = crate::optim::Stop::Lm(Termination::PredictedGain);
        assert!(results.iter().all(|r| r.stop == stop), "{results:?}");
        assert!(stop.converged() && stop.status() == "predicted_gain");
        let results = minimize(
            &mut decay(0.01, 0.0),
            &starts,
            &short,
            &|_, s| s,
            &mut |_| {},
        )
        .unwrap();
        let stop = crate::optim::Stop::Lm(Termination::MaxIterations);
        assert!(results.iter().all(|r| r.stop == stop), "{results:?}");
        assert!(!stop.converged());
    }

    /// The progress callback gets the number of restarts still running after each
    /// iteration: never more than the starts, never rising, and 0 once all have stopped.
    #[test]
    fn progress_counts_the_running_restarts() {
        let mut d = decay(0.0, 0.0);
        let starts = super::super::random_starts(3, 6, 3);
        let mut seen = Vec::new();
        minimize(
            &mut d,
            &starts,
            &LmOptions::default(),
            &|_, s| s,
            &mut |n| seen.push(n),
        )
        .unwrap();
        assert_eq!(seen.first(), Some(&6), "{seen:?}");
        assert_eq!(seen.last(), Some(&0), "{seen:?}");
        assert!(seen.windows(2).all(|w| w[1] <= w[0]), "{seen:?}");
    }

    #[test]
    fn fits_an_exponential_decay_from_several_starts() {
        let mut d = decay(0.0, 0.0);
        let starts = super::super::random_starts(3, 6, 3);
        let opts = LmOptions::default();
        let out = minimize(&mut d, &starts, &opts, &|_, s| s, &mut |_| {}).unwrap();
        assert!(best_near_truth(&out, 1e-5) < 1e-12);
    }
}
