//! Compass (coordinate pattern) search, Kolda, Lewis & Torczon 2003 (SIAM Review 45(3),
//! §3.1), as BBM uses it: poll ±Δ along every axis, move to the best improving point,
//! else halve Δ; stop when Δ < Δ_min or the budget is spent. Every poll of every active
//! restart goes to the objective as one batch.

use super::{sanitize, BatchObjective, RestartResult, Stop};

#[derive(Clone, Debug)]
pub struct CompassOptions {
    /// Initial step as a fraction of the unit box (docs/losses.md: 0.25).
    pub initial_step: f64,
    /// Stop when the step falls below this (docs/losses.md: 1e-4).
    pub min_step: f64,
    /// Maximum candidate evaluations per restart.
    pub max_evaluations: usize,
    /// Step factor after a successful poll (1 = classic compass search).
    pub expansion: f64,
}

impl Default for CompassOptions {
    fn default() -> Self {
        CompassOptions {
            initial_step: 0.25,
            min_step: 1e-4,
            max_evaluations: 20_000,
            expansion: 1.0,
        }
    }
}

/// Run compass search from every start in lockstep; `progress` is told the number of
/// restarts still active after each batch.
pub fn minimize(
    obj: &mut dyn BatchObjective,
    starts: &[Vec<f64>],
    opts: &CompassOptions,
    progress: &mut dyn FnMut(usize),
) -> anyhow::Result<Vec<RestartResult>> {
    let p = obj.dim();
    let flat: Vec<f64> = starts.iter().flatten().copied().collect();
    let every: Vec<usize> = (0..starts.len()).collect();
    let c0 = obj.costs_of(&every, &flat)?;
    let mut res: Vec<RestartResult> = starts
        .iter()
        .zip(c0)
        .map(|(x, c)| RestartResult {
            x: x.clone(),
            cost: sanitize(c),
            iterations: 0,
            evaluations: 1,
            stop: Stop::StepBelowMinimum,
        })
        .collect();
    let mut step = vec![opts.initial_step; starts.len()];
    let mut active: Vec<bool> = vec![true; starts.len()];
    loop {
        // Build one batch: for each active restart, the 2P axis polls that stay in the box.
        let mut batch = Vec::new();
        let mut owner: Vec<(usize, usize)> = Vec::new(); // (restart, first candidate index)
        let mut counts = Vec::new();
        let mut tags = Vec::new(); // the restart of each candidate
        for (r, st) in res.iter().enumerate() {
            if !active[r] {
                continue;
            }
            let start = batch.len() / p.max(1);
            let mut n = 0;
            for j in 0..p {
                for sign in [1.0, -1.0] {
                    let v = (st.x[j] + sign * step[r]).clamp(0.0, 1.0);
                    if v == st.x[j] {
                        continue; // at the boundary: this poll adds nothing
                    }
                    batch.extend_from_slice(&st.x);
                    let last = batch.len() - p + j;
                    batch[last] = v;
                    n += 1;
                }
            }
            owner.push((r, start));
            counts.push(n);
            tags.extend(std::iter::repeat_n(r, n));
        }
        if owner.is_empty() {
            break;
        }
        let costs = if batch.is_empty() {
            vec![]
        } else {
            obj.costs_of(&tags, &batch)?
        };
        for ((r, start), n) in owner.into_iter().zip(counts) {
            let st = &mut res[r];
            st.iterations += 1;
            st.evaluations += n;
            let best = (start..start + n)
                .min_by(|&a, &b| sanitize(costs[a]).total_cmp(&sanitize(costs[b])));
            match best {
                Some(b) if sanitize(costs[b]) < st.cost => {
                    st.cost = sanitize(costs[b]);
                    st.x.copy_from_slice(&batch[b * p..(b + 1) * p]);
                    // Optional expansion after a success (Kolda et al. 2003 allow φ ≥ 1); the
                    // default 1 is classic compass search: φ = 2 gave no consistent gain on
                    // the catalogue (fewer evaluations on some models, more on others).
                    step[r] = (step[r] * opts.expansion).min(opts.initial_step);
                }
                _ => step[r] *= 0.5,
            }
            if step[r] < opts.min_step {
                active[r] = false;
                st.stop = Stop::StepBelowMinimum;
            } else if st.evaluations >= opts.max_evaluations {
                active[r] = false;
                st.stop = Stop::EvaluationBudget;
            }
        }
        progress(active.iter().filter(|a| **a).count());
    }
    Ok(res)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Quadratic {
        centre: Vec<f64>,
        calls: usize,
    }
    impl BatchObjective for Quadratic {
        fn dim(&self) -> usize {
            self.centre.len()
        }
        fn costs(&mut self, pts: &[f64]) -> anyhow::Result<Vec<f64>> {
            self.calls += 1;
            Ok(pts
                .chunks(self.centre.len())
                .map(|x| {
                    x.iter()
                        .zip(&self.centre)
                        .map(|(a, b)| (a - b) * (a - b) * 3.0)
                        .sum()
                })
                .collect())
        }
    }

    #[test]
    fn finds_the_minimum_of_a_quadratic_from_every_start() {
        let mut q = Quadratic {
            centre: vec![0.3, 0.71, 0.05],
            calls: 0,
        };
        let starts = super::super::random_starts(3, 8, 7);
        let out = minimize(&mut q, &starts, &CompassOptions::default(), &mut |_| {}).unwrap();
        for r in &out {
            for (a, b) in r.x.iter().zip(&q.centre) {
                assert!((a - b).abs() < 2e-4, "{:?}", r.x);
            }
        }
        // Lockstep: one batch per iteration for all restarts, not one per restart.
        let max_iter = out.iter().map(|r| r.iterations).max().unwrap();
        assert_eq!(q.calls, max_iter + 1);
        assert!(out.iter().all(|r| r.stop == Stop::StepBelowMinimum));
        assert!(Stop::StepBelowMinimum.converged());
    }

    /// A restart that uses its evaluation budget says so, and that it did not converge.
    #[test]
    fn a_spent_budget_is_the_stop_reason() {
        let mut q = Quadratic {
            centre: vec![0.3, 0.71, 0.05],
            calls: 0,
        };
        let opts = CompassOptions {
            max_evaluations: 20,
            ..Default::default()
        };
        let out = minimize(&mut q, &[vec![0.9, 0.1, 0.9]], &opts, &mut |_| {}).unwrap();
        assert_eq!(out[0].stop, Stop::EvaluationBudget);
        assert!(!out[0].stop.converged());
        assert_eq!(out[0].stop.status(), "evaluation_budget");
    }

    #[test]
    fn nan_costs_never_win() {
        struct NanLeft;
        impl BatchObjective for NanLeft {
            fn dim(&self) -> usize {
                1
            }
            fn costs(&mut self, pts: &[f64]) -> anyhow::Result<Vec<f64>> {
                Ok(pts
                    .iter()
                    .map(|&x| if x < 0.5 { f64::NAN } else { (x - 0.6).powi(2) })
                    .collect())
            }
        }
        let out = minimize(
            &mut NanLeft,
            &[vec![0.9]],
            &CompassOptions::default(),
            &mut |_| {},
        )
        .unwrap();
        assert!((out[0].x[0] - 0.6).abs() < 1e-3, "{:?}", out[0].x);
        assert!(out[0].cost.is_finite());
    }
}
