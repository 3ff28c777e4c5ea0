//! What Levenberg–Marquardt carries from one iteration to the next: per restart its
//! point, Σr², normal equations, damping and counters.

use super::step::fd_steps;
use super::termination::Termination;
use super::LmOptions;
use crate::optim::{sanitize, BatchResiduals, NormalEquations, RestartResult};
use std::collections::VecDeque;

/// One restart's state.
pub(super) struct RestartState {
    pub(super) x: Vec<f64>,
    pub(super) ss: f64,
    /// The normal equations at x.
    pub(super) normal: NormalEquations,
    pub(super) lambda: f64,
    /// The damping's scaling: the largest diag(JᵀJ) met at the accepted points so far
    /// (Moré 1978; MINPACK's `mode = 1`), not the current one. Why: a parameter the
    /// data barely determine at the current point (a base albedo under a nearly opaque
    /// grain layer) gets almost no damping from its own diag(JᵀJ), so its Gauss–Newton
    /// steps run far beyond where the model is linear, are rejected, and λ rises for all
    /// parameters; the running maximum keeps its damping where it was once meaningful.
    pub(super) scale: Vec<f64>,
    /// Why the restart stopped; None while it runs.
    pub(super) stop: Option<Termination>,
    pub(super) iterations: usize,
    pub(super) evaluations: usize,
    /// Σr² after each of the last `stall_window` iterations, oldest first.
    pub(super) recent: VecDeque<f64>,
}

impl RestartState {
    /// A restart at `x` (P = `p` coordinates), whose normal equations are `normal`
    /// (P + 1 evaluations).
    fn new(x: &[f64], normal: NormalEquations, p: usize, opts: &LmOptions) -> RestartState {
        RestartState {
            x: x.to_vec(),
            ss: sanitize(normal.ss),
            scale: (0..p).map(|j| normal.jtj[j * p + j]).collect(),
            normal,
            lambda: opts.initial_lambda,
            stop: None,
            iterations: 0,
            evaluations: p + 1,
            recent: VecDeque::new(),
        }
    }

    pub(super) fn running(&self) -> bool {
        self.stop.is_none()
    }

    /// Stop the restart for `why`, unless it has stopped already (the first reason holds).
    pub(super) fn stop_for(&mut self, why: Termination) {
        self.stop.get_or_insert(why);
    }
}

/// Every restart's state: the restarts step in lockstep.
pub(super) struct LmState {
    pub(super) restarts: Vec<RestartState>,
    /// P, the unit box's dimension.
    pub(super) dim: usize,
}

impl LmState {
    /// The restarts at `starts`, with the normal equations of all of them from one batch.
    pub(super) fn start(
        obj: &mut dyn BatchResiduals,
        starts: &[Vec<f64>],
        opts: &LmOptions,
    ) -> anyhow::Result<LmState> {
        let p = obj.dim();
        let flat: Vec<f64> = starts.iter().flatten().copied().collect();
        let every: Vec<usize> = (0..starts.len()).collect();
        let normal0 = obj.normal_equations_of(&every, &flat, &fd_steps(&flat, opts.fd_step))?;
        Ok(LmState {
            restarts: starts
                .iter()
                .zip(normal0)
                .map(|(x, normal)| RestartState::new(x, normal, p, opts))
                .collect(),
            dim: p,
        })
    }

    /// How many restarts still run.
    pub(super) fn running(&self) -> usize {
        self.restarts.iter().filter(|s| s.running()).count()
    }

    /// Stop every restart still running for `why`.
    pub(super) fn stop_running(&mut self, why: Termination) {
        for s in &mut self.restarts {
            s.stop_for(why);
        }
    }

    /// Each restart's outcome, its cost `finish(restart, Σr²)`.
    pub(super) fn results(self, finish: &dyn Fn(usize, f64) -> f64) -> Vec<RestartResult> {
        self.restarts
            .into_iter()
            .enumerate()
            .map(|(i, s)| RestartResult {
                cost: finish(i, s.ss),
                x: s.x,
                iterations: s.iterations,
                evaluations: s.evaluations,
                stop: crate::optim::Stop::Lm(s.stop.unwrap_or(Termination::MaxIterations)),
            })
            .collect()
    }
}
