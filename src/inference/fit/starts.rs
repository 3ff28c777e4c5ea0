//! Where the restarts start: the given points, then the best of a screened pool of
//! random draws, ranked on each problem's own data.

use super::{FitOptions, Optimizer, UnitBox};
use crate::optim::{random_starts, BatchObjective};

/// Starting points in the unit box for each of `problems` problems, problem-major: the
/// given initial points, then the best `restarts` of `restarts × screen` random draws
/// (the same draws for every problem, screened on each problem's own data).
pub(super) fn screened_starts(
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
