//! One Levenberg–Marquardt iteration of every active restart: each solves its damped
//! normal equations for a step within the unit box, the trial points' Σr² go to the
//! objective in one batch, each restart accepts or rejects its step and updates λ, and
//! the accepted points' normal equations go in a second batch.

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
    /// and those whose step could show a gain evaluate it. Returns false, having
    /// evaluated nothing, when no restart has a step left to take.
    ///
    /// The trial points' Σr² come first, one evaluation each, and only the accepted
    /// points' Jacobians (P more each) after: a rejected step keeps the Jacobian it
    /// already has, so evaluating its neighbours with it would be thrown away. Rejections
    /// are frequent where λ is still being found (515 of 1,162 iterations of a
    /// data-driven NDF fit of a real file, 44 % of its evaluations before this split).
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
        let p = self.dim;
        let ss = obj.sum_squares_of(&moving, &trial)?;
        let lower: Vec<bool> = (0..moving.len())
            .map(|a| sanitize(ss[a]) < self.restarts[moving[a]].ss)
            .collect();
        let accepted = (0..moving.len()).filter(|&a| lower[a]);
        let owners: Vec<usize> = accepted.clone().map(|a| moving[a]).collect();
        let points: Vec<f64> = accepted
            .flat_map(|a| trial[a * p..(a + 1) * p].iter().copied())
            .collect();
        // One batch: the accepted points with their neighbours (the backend may reduce
        // the normal equations where it evaluates the residuals).
        let mut normal = if owners.is_empty() {
            Vec::new()
        } else {
            obj.normal_equations_of(&owners, &points, &fd_steps(&points, opts.fd_step))?
        }
        .into_iter();
        for (a, &i) in moving.iter().enumerate() {
            let x_new = &trial[a * p..(a + 1) * p];
            let s = &mut self.restarts[i];
            if lower[a] {
                let ne = normal
                    .next()
                    .expect("one set of normal equations per accepted point");
                s.accept(ne, x_new, opts);
            } else {
                s.reject(x_new, opts);
            }
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

    /// Accept the step to `x_new`, whose Σr² was lower and whose normal equations are
    /// `ne` (their Σr² is the trial's, up to the rounding of another reduction order):
    /// λ falls; then stop if the iteration says so.
    fn accept(&mut self, ne: NormalEquations, x_new: &[f64], opts: &LmOptions) {
        let p = x_new.len();
        self.iterations += 1;
        self.evaluations += p + 2;
        let ss_new = sanitize(ne.ss);
        let length = self.distance_to(x_new);
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
        self.conclude(Outcome::Accepted { gain, length }, opts);
    }

    /// Reject the step to `x_new`, whose Σr² was not lower (or not finite): nothing moves
    /// but λ, which rises; then stop if the iteration says so.
    fn reject(&mut self, x_new: &[f64], opts: &LmOptions) {
        self.iterations += 1;
        self.evaluations += 1;
        let length = self.distance_to(x_new);
        self.lambda *= 4.0;
        self.conclude(Outcome::Rejected { length }, opts);
    }

    /// The step's Euclidean length in the unit box.
    fn distance_to(&self, x_new: &[f64]) -> f64 {
        x_new
            .iter()
            .zip(&self.x)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
            .sqrt()
    }

    fn conclude(&mut self, outcome: Outcome, opts: &LmOptions) {
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

#[cfg(test)]
mod tests {
    //! One iteration's parts against steps solved by hand: 2 × 2 systems whose inverses
    //! are written out, and restarts whose state is set by hand.
    use super::*;
    use crate::optim::BatchObjective;
    use std::collections::VecDeque;

    fn restart(x: [f64; 2], normal: NormalEquations, lambda: f64, scale: [f64; 2]) -> RestartState {
        RestartState {
            x: x.to_vec(),
            ss: normal.ss,
            normal,
            lambda,
            scale: scale.to_vec(),
            stop: None,
            iterations: 0,
            evaluations: 3,
            recent: VecDeque::new(),
        }
    }

    fn ne(jtj: [f64; 4], jtr: [f64; 2], ss: f64) -> NormalEquations {
        NormalEquations {
            jtj: jtj.to_vec(),
            jtr: jtr.to_vec(),
            ss,
        }
    }

    /// −A⁻¹g for a 2 × 2 A, by its adjugate.
    fn solve2(a: [f64; 4], g: [f64; 2]) -> [f64; 2] {
        let det = a[0] * a[3] - a[1] * a[2];
        [
            -(a[3] * g[0] - a[1] * g[1]) / det,
            -(-a[2] * g[0] + a[0] * g[1]) / det,
        ]
    }

    fn close(a: &[f64], b: &[f64]) -> bool {
        a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-12)
    }

    #[test]
    fn forward_differences_step_back_only_where_forward_leaves_the_box() {
        let h = 1e-6;
        assert_eq!(
            fd_steps(&[0.0, 0.5, 1.0 - 2e-6, 1.0 - 1e-7, 1.0], h),
            [h, h, h, -h, -h]
        );
    }

    /// The damped step −(JᵀJ + λD)⁻¹g, D = diag(max(scale_j, (JᵀJ)_jj, 1e-9·max_j (JᵀJ)_jj)).
    #[test]
    fn the_trial_point_is_the_damped_gauss_newton_step() {
        let jtj = [4.0, 1.0, 1.0, 2.0];
        let g = [0.4, -0.3];
        // The running scale 5 beats (JᵀJ)₀₀ = 4; (JᵀJ)₁₁ = 2 beats its scale 1.
        let s = restart([0.5, 0.5], ne(jtj, g, 1.0), 0.5, [5.0, 1.0]);
        let a = [4.0 + 0.5 * 5.0, 1.0, 1.0, 2.0 + 0.5 * 2.0];
        let d = solve2(a, g);
        let x = s.trial_point(1e-10).unwrap();
        assert!(close(&x, &[0.5 + d[0], 0.5 + d[1]]), "{x:?} vs {d:?}");
        // A diagonal of JᵀJ that vanishes is damped by 1e-9 of the largest.
        let jtj = [1e6, 0.0, 0.0, 0.0];
        let s = restart([0.5, 0.5], ne(jtj, [1.0, 1e-6], 1.0), 2.0, [0.0, 0.0]);
        let x = s.trial_point(1e-10).unwrap();
        let want = [0.5 - 1.0 / (1e6 * 3.0), 0.5 - 1e-6 / (2.0 * 1e-3)];
        assert!(close(&x, &want), "{x:?} vs {want:?}");
        // Clipped to the box.
        let s = restart(
            [0.9, 0.1],
            ne([1.0, 0.0, 0.0, 1.0], [-1.0, 1.0], 1.0),
            0.0,
            [1.0, 1.0],
        );
        assert_eq!(s.trial_point(1e-10).unwrap(), [1.0, 0.0]);
    }

    /// The Gauss–Newton model's decrease −2gᵀδ − δᵀJᵀJδ against ftol·Σr².
    #[test]
    fn a_step_whose_predicted_gain_is_below_ftol_is_not_taken() {
        // JᵀJ = I, g = (−0.1, 0), λ = 0: δ = (0.1, 0), predicted 0.02 − 0.01 = 0.01.
        let s = restart(
            [0.5, 0.5],
            ne([1.0, 0.0, 0.0, 1.0], [-0.1, 0.0], 1.0),
            0.0,
            [1.0; 2],
        );
        assert!(s.trial_point(0.0099).is_some());
        assert!(s.trial_point(0.0101).is_none());
        // Relative to Σr²: at Σr² = 100 the same step predicts 1e-4 of it.
        let s = restart(
            [0.5, 0.5],
            ne([1.0, 0.0, 0.0, 1.0], [-0.1, 0.0], 100.0),
            0.0,
            [1.0; 2],
        );
        assert!(s.trial_point(0.99e-4).is_some());
        assert!(s.trial_point(1.01e-4).is_none());
        // No gradient, no gain.
        let s = restart(
            [0.5, 0.5],
            ne([1.0, 0.0, 0.0, 1.0], [0.0, 0.0], 1.0),
            0.0,
            [1.0; 2],
        );
        assert!(s.trial_point(0.0).is_none());
    }

    #[test]
    fn an_accepted_step_moves_and_lowers_lambda_a_rejected_one_raises_it() {
        let old = ne([1.0, 0.0, 0.0, 1.0], [0.1, 0.1], 10.0);
        let opts = LmOptions::default();
        let mut s = restart([0.5, 0.5], old.clone(), 0.3, [1.0, 1.0]);
        // The new diagonal of JᵀJ (4, 2) raises the running scale (1, 1) where larger;
        // the trial point and its two neighbours were evaluated (3 + 1 + 3).
        s.accept(
            ne([4.0, 0.0, 0.0, 2.0], [0.2, 0.0], 6.0),
            &[0.8, 0.1],
            &opts,
        );
        assert_eq!(s.x, [0.8, 0.1]);
        assert_eq!((s.ss, s.normal.ss, s.normal.jtr[0]), (6.0, 6.0, 0.2));
        assert!((s.lambda - 0.1).abs() < 1e-15, "{}", s.lambda);
        assert_eq!(s.scale, [4.0, 2.0]);
        assert_eq!((s.iterations, s.evaluations, s.stop), (1, 7, None));
        // Rejected: nothing moves but λ, times 4; the trial point alone was evaluated.
        s.reject(&[0.7, 0.2], &opts);
        assert_eq!(
            (s.x.as_slice(), s.ss, s.normal.jtj[0]),
            (&[0.8, 0.1][..], 6.0, 4.0)
        );
        assert!((s.lambda - 0.4).abs() < 1e-15, "{}", s.lambda);
        assert_eq!(s.scale, [4.0, 2.0]);
        assert_eq!((s.iterations, s.evaluations), (2, 8));
        // A NaN diagonal leaves its scale; λ never falls below 1e-12.
        s.lambda = 1e-12;
        s.accept(
            ne([f64::NAN, 0.0, 0.0, 1.0], [0.0, 0.0], 3.0),
            &[0.6, 0.2],
            &opts,
        );
        assert_eq!(
            (s.lambda, s.ss, s.scale.as_slice()),
            (1e-12, 3.0, &[4.0, 2.0][..])
        );
    }

    /// The gain (Σr² − Σr²_new)/Σr² and the step's length (Euclidean, unit box) reach
    /// the termination test.
    #[test]
    fn gain_and_length_reach_the_termination_test() {
        let opts = LmOptions::default();
        let step = |ss_new: f64, to: [f64; 2]| {
            let mut s = restart(
                [0.5, 0.5],
                ne([1.0, 0.0, 0.0, 1.0], [0.0; 2], 10.0),
                1e-3,
                [1.0; 2],
            );
            if ss_new < s.ss {
                s.accept(ne([1.0, 0.0, 0.0, 1.0], [0.0; 2], ss_new), &to, &opts);
            } else {
                s.reject(&to, &opts);
            }
            s.stop
        };
        // Gains 5e-11 and 2e-10 of Σr² = 10.
        assert_eq!(step(10.0 - 5e-10, [0.7, 0.7]), Some(Termination::SmallGain));
        assert_eq!(step(10.0 - 2e-9, [0.7, 0.7]), None);
        // Lengths √2·4e-10 < 1e-9 and 5e-10·√(1 + 16) > 1e-9.
        assert_eq!(
            step(5.0, [0.5 + 4e-10, 0.5 + 4e-10]),
            Some(Termination::SmallStep)
        );
        assert_eq!(step(5.0, [0.5 + 5e-10, 0.5 - 2e-9]), None);
        assert_eq!(
            step(11.0, [0.5 + 4e-10, 0.5 + 4e-10]),
            Some(Termination::SmallStep)
        );
    }

    #[test]
    fn a_bound_the_step_would_leave_holds_its_parameter() {
        let a = DMatrix::from_row_slice(2, 2, &[2.0, 1.0, 1.0, 2.0]);
        let step = |g: [f64; 2], x: [f64; 2]| {
            let d = bounded_step(&a, &DVector::from_column_slice(&g), &x);
            [d[0], d[1]]
        };
        // Inside the box: −A⁻¹g = −(1, 1)/3.
        let third = 1.0 / 3.0;
        assert!(close(&step([1.0, 1.0], [0.5, 0.5]), &[-third, -third]));
        // On the lower bound the first is held and the second solved alone: −1/2.
        assert!(close(&step([1.0, 1.0], [0.0, 0.5]), &[0.0, -0.5]));
        // On the upper bound, moving up: held likewise.
        assert!(close(&step([-1.0, -1.0], [1.0, 0.5]), &[0.0, 0.5]));
        // On a bound but moving into the box: free.
        assert!(close(&step([-1.0, -1.0], [0.0, 0.5]), &[third, third]));
        assert!(close(&step([1.0, 1.0], [1.0, 0.5]), &[-third, -third]));
        // Both held: no step.
        assert!(close(&step([1.0, 1.0], [0.0, 0.0]), &[0.0, 0.0]));
        // Not positive definite: solved by LU, [[1, 2], [2, 1]]⁻¹ = [[−1, 2], [2, −1]]/3.
        let indefinite = DMatrix::from_row_slice(2, 2, &[1.0, 2.0, 2.0, 1.0]);
        let d = bounded_step(
            &indefinite,
            &DVector::from_column_slice(&[1.0, 0.0]),
            &[0.5, 0.5],
        );
        assert!(close(d.as_slice(), &[third, -2.0 * third]), "{d}");
        // Singular: no step.
        let singular = DMatrix::from_element(2, 2, 1.0);
        let d = bounded_step(
            &singular,
            &DVector::from_column_slice(&[1.0, 0.0]),
            &[0.5, 0.5],
        );
        assert_eq!(d.as_slice(), [0.0, 0.0]);
    }

    /// r = x − (0.3, 0.6): Σr² is minimal at (0.3, 0.6).
    struct Shifted;
    impl BatchObjective for Shifted {
        fn dim(&self) -> usize {
            2
        }
        fn costs(&mut self, pts: &[f64]) -> anyhow::Result<Vec<f64>> {
            let r = self.residuals(pts)?;
            Ok(r.chunks(2).map(|r| r[0] * r[0] + r[1] * r[1]).collect())
        }
    }
    impl BatchResiduals for Shifted {
        fn residuals(&mut self, pts: &[f64]) -> anyhow::Result<Vec<f64>> {
            Ok(pts
                .chunks(2)
                .flat_map(|x| [x[0] - 0.3, x[1] - 0.6])
                .collect())
        }
        fn residual_count(&self) -> usize {
            2
        }
    }

    /// A stopped restart takes no more steps, one whose Σr² is not finite stops as
    /// such, and each running one moves to its own trial point.
    #[test]
    fn only_running_restarts_with_a_finite_sum_of_squares_step() {
        let opts = LmOptions::default();
        let starts = vec![
            vec![0.9, 0.9],
            vec![0.1, 0.2],
            vec![0.5, 0.5],
            vec![0.8, 0.1],
        ];
        let mut state = LmState::start(&mut Shifted, &starts, &opts).unwrap();
        state.restarts[0].stop = Some(Termination::SmallGain);
        state.restarts[2].ss = f64::NAN;
        assert!(state.step(&mut Shifted, &opts).unwrap());
        let r = &state.restarts;
        assert_eq!((r[0].x.as_slice(), r[0].iterations), (&[0.9, 0.9][..], 0));
        assert_eq!(r[0].stop, Some(Termination::SmallGain));
        assert_eq!((r[2].x.as_slice(), r[2].iterations), (&[0.5, 0.5][..], 0));
        assert_eq!(r[2].stop, Some(Termination::NotFinite));
        for (i, s) in r.iter().enumerate().filter(|(i, _)| i % 2 == 1) {
            assert_eq!(s.iterations, 1, "{i}");
            // λ = 1e-3 on JᵀJ = I: a step of 1/(1 + 1e-3) of the way to the optimum.
            for (x, (x0, t)) in s.x.iter().zip(starts[i].iter().zip([0.3, 0.6])) {
                let want = x0 + (t - x0) / (1.0 + 1e-3);
                assert!((x - want).abs() < 1e-6, "{i}: {x} vs {want}");
            }
        }
        assert_eq!(state.running(), 2);
        // Nothing left that can move: no step, nothing evaluated.
        for s in &mut state.restarts {
            s.stop_for(Termination::MaxIterations);
        }
        assert!(!state.step(&mut Shifted, &opts).unwrap());
    }

    /// [`Shifted`], counting the points whose residuals it evaluates.
    struct Counted(usize);
    impl BatchObjective for Counted {
        fn dim(&self) -> usize {
            2
        }
        fn costs(&mut self, pts: &[f64]) -> anyhow::Result<Vec<f64>> {
            self.0 += pts.len() / 2;
            Shifted.costs(pts)
        }
    }
    impl BatchResiduals for Counted {
        fn residuals(&mut self, pts: &[f64]) -> anyhow::Result<Vec<f64>> {
            self.0 += pts.len() / 2;
            Shifted.residuals(pts)
        }
        fn residual_count(&self) -> usize {
            2
        }
    }

    /// A rejected step costs its trial point alone; an accepted one its trial point, then
    /// the point and its P neighbours for the normal equations.
    #[test]
    fn a_rejected_step_evaluates_its_trial_point_only() {
        let opts = LmOptions::default();
        let mut obj = Counted(0);
        let mut state = LmState::start(&mut obj, &[vec![0.5, 0.5], vec![0.1, 0.2]], &opts).unwrap();
        assert_eq!(obj.0, 6);
        // The first restart's gradient turned uphill: its step raises Σr² and is rejected.
        let s = &mut state.restarts[0];
        s.normal.jtr = s.normal.jtr.iter().map(|g| -g).collect();
        obj.0 = 0;
        assert!(state.step(&mut obj, &opts).unwrap());
        assert_eq!(
            obj.0,
            2 + 3,
            "two trial points, then one accepted point's three"
        );
        let r = &state.restarts;
        assert_eq!(
            (r[0].x.as_slice(), r[0].evaluations),
            (&[0.5, 0.5][..], 3 + 1)
        );
        assert_ne!(r[1].x, [0.1, 0.2]);
        assert_eq!(r[1].evaluations, 3 + 4);
        assert!(r[0].lambda > r[1].lambda);
    }
}
