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

use super::{sanitize, BatchResiduals, NormalEquations, RestartResult};
use nalgebra::{DMatrix, DVector};

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

struct State {
    x: Vec<f64>,
    ss: f64,
    /// The normal equations at x.
    normal: NormalEquations,
    lambda: f64,
    /// The damping's scaling: the largest diag(JᵀJ) met at the accepted points so far
    /// (Moré 1978; MINPACK's `mode = 1`), not the current one. Why: a parameter the
    /// data barely determine at the current point (a base albedo under a nearly opaque
    /// grain layer) gets almost no damping from its own diag(JᵀJ), so its Gauss–Newton
    /// steps run far beyond where the model is linear, are rejected, and λ rises for all
    /// parameters; the running maximum keeps its damping where it was once meaningful.
    scale: Vec<f64>,
    active: bool,
    iterations: usize,
    evaluations: usize,
    /// Σr² after each of the last `stall_window` iterations, oldest first.
    recent: std::collections::VecDeque<f64>,
}

/// Minimise Σ r² from every start; costs are reported as `finish(start, Σ r²)`.
pub fn minimize(
    obj: &mut dyn BatchResiduals,
    starts: &[Vec<f64>],
    opts: &LmOptions,
    finish: &dyn Fn(usize, f64) -> f64,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<Vec<RestartResult>> {
    let p = obj.dim();
    // Forward-difference steps at each of `points`: +h, or −h where +h leaves the box.
    let steps = |points: &[f64]| -> Vec<f64> {
        points
            .iter()
            .map(|&x| {
                if x + opts.fd_step <= 1.0 {
                    opts.fd_step
                } else {
                    -opts.fd_step
                }
            })
            .collect()
    };
    let flat: Vec<f64> = starts.iter().flatten().copied().collect();
    let every: Vec<usize> = (0..starts.len()).collect();
    let normal0 = obj.normal_equations_of(&every, &flat, &steps(&flat))?;
    let mut st: Vec<State> = starts
        .iter()
        .zip(normal0)
        .map(|(x, normal)| State {
            x: x.clone(),
            ss: sanitize(normal.ss),
            scale: (0..p).map(|j| normal.jtj[j * p + j]).collect(),
            normal,
            lambda: opts.initial_lambda,
            active: true,
            iterations: 0,
            evaluations: p + 1,
            recent: std::collections::VecDeque::new(),
        })
        .collect();
    for _ in 0..opts.max_iterations {
        let act: Vec<usize> = (0..st.len())
            .filter(|&i| st[i].active && st[i].ss.is_finite())
            .collect();
        for (i, s) in st.iter_mut().enumerate() {
            if !s.ss.is_finite() && !act.contains(&i) {
                s.active = false;
            }
        }
        if act.is_empty() {
            break;
        }
        // Solve each damped system at the restart's current point.
        let mut trial = Vec::with_capacity(act.len() * p);
        let (mut moving, mut converged) = (Vec::new(), Vec::new());
        for &i in &act {
            let s = &st[i];
            let ne = &s.normal;
            let jtj = DMatrix::from_row_slice(p, p, &ne.jtj);
            let g = DVector::from_column_slice(&ne.jtr);
            let dmax = (0..p).map(|j| jtj[(j, j)]).fold(0.0, f64::max).max(1e-300);
            let mut a_mat = jtj.clone();
            for j in 0..p {
                let d = s.scale[j].max(jtj[(j, j)]);
                a_mat[(j, j)] += s.lambda * d.max(1e-9 * dmax);
            }
            let delta = bounded_step(&a_mat, &g, &s.x);
            let start = trial.len();
            for j in 0..p {
                let v = s.x[j] + if delta[j].is_finite() { delta[j] } else { 0.0 };
                trial.push(v.clamp(0.0, 1.0));
            }
            // The Gauss–Newton model's Σr² decrease for the damped step (before clipping
            // to the box), −2gᵀδ − δᵀJᵀJδ ≥ −gᵀδ ≥ 0. Below ftol·Σr² the restart has
            // converged as far as its arithmetic can show: without this test a backend
            // whose Σr² carries rounding noise above ftol (f32) rejects step after step
            // until λ overflows, P + 1 evaluations each.
            let step = delta.map(|d| if d.is_finite() { d } else { 0.0 });
            let predicted = -2.0 * g.dot(&step) - (&jtj * &step).dot(&step);
            let measurable = predicted > opts.ftol * s.ss; // false for NaN too
            if !measurable {
                trial.truncate(start);
                converged.push(i);
            } else {
                moving.push(i);
            }
        }
        for &i in &converged {
            st[i].active = false;
        }
        let act = moving;
        if act.is_empty() {
            break;
        }
        // One batch: the trial points with their neighbours (the backend may reduce the
        // normal equations where it evaluates the residuals).
        let normal = obj.normal_equations_of(&act, &trial, &steps(&trial))?;
        for (ne, (a, &i)) in normal.into_iter().zip(act.iter().enumerate()) {
            let s = &mut st[i];
            s.iterations += 1;
            s.evaluations += p + 1;
            let x_new = &trial[a * p..(a + 1) * p];
            let ss_new = sanitize(ne.ss);
            let step: f64 = x_new
                .iter()
                .zip(&s.x)
                .map(|(a, b)| (a - b) * (a - b))
                .sum::<f64>()
                .sqrt();
            if ss_new < s.ss {
                let gain = (s.ss - ss_new) / s.ss.max(1e-300);
                s.x.copy_from_slice(x_new);
                for j in 0..p {
                    let d = ne.jtj[j * p + j];
                    if d.is_finite() {
                        s.scale[j] = s.scale[j].max(d);
                    }
                }
                s.ss = ss_new;
                s.normal = ne;
                s.lambda = (s.lambda / 3.0).max(1e-12);
                if gain < opts.ftol || step < opts.xtol {
                    s.active = false;
                }
            } else {
                s.lambda *= 4.0;
                if s.lambda > 1e12 || step < opts.xtol {
                    s.active = false;
                }
            }
            if opts.stall_window > 0 {
                s.recent.push_back(s.ss);
                if s.recent.len() > opts.stall_window {
                    let old = s.recent.pop_front().unwrap_or(s.ss);
                    // false for NaN: a NaN Σr² has already stopped the restart
                    if old - s.ss < opts.stall_gain * old {
                        s.active = false;
                    }
                }
            }
        }
        progress(st.iter().filter(|s| s.active).count());
    }
    Ok(st
        .into_iter()
        .enumerate()
        .map(|(i, s)| RestartResult {
            cost: finish(i, s.ss),
            x: s.x,
            iterations: s.iterations,
            evaluations: s.evaluations,
        })
        .collect())
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

    #[test]
    fn fits_an_exponential_decay_from_several_starts() {
        let mut d = decay(0.0, 0.0);
        let starts = super::super::random_starts(3, 6, 3);
        let opts = LmOptions::default();
        let out = minimize(&mut d, &starts, &opts, &|_, s| s, &mut |_| {}).unwrap();
        assert!(best_near_truth(&out, 1e-5) < 1e-12);
    }
}
