//! LM's search settings, and the f64 polish of each problem's best restart (on the CPU
//! reference, or on the SIMD engine's f64 lanes, whose values are the reference's).

use super::UnitBox;
use crate::bsdf::Model;
use crate::engine::loss::Finisher;
use crate::engine::Evaluator;
use crate::inference::constraints::Constraints;
use crate::optim::{lm, RestartResult};

/// LM's `ftol` for restarts whose best is then polished in f64 (see [`search_options`]).
pub const POLISHED_SEARCH_FTOL: f64 = 1e-4;

/// LM's stall test for restarts whose best is then polished: a restart that gained less
/// than 1e-3 over its last 10 iterations stops (the polish continues the best restart in
/// f64, where the step is not tilted by f32's forward differences). On the default
/// sweep (seeds 1–4) it left every mean loss excess over the best known unchanged to 3
/// digits and saved 2–3 % of the evaluations, mostly single-restart submissions;
/// 1e-2 saved 7 % but lost quality.
pub const POLISHED_SEARCH_STALL: (usize, f64) = (10, 1e-3);

/// LM's forward-difference step (unit box) for restarts whose best is then polished:
/// 4√u of f32, the smallest step whose f32 differences are not mostly rounding noise.
pub const POLISHED_SEARCH_FD_STEP: f64 = 9.765625e-4;

/// LM's options for the restarts, before any polish.
///
/// With the f64 polish (the default) the restarts only have to find each problem's
/// basin, and they search the same way on every backend: forward differences with the
/// step f32 needs, and a stop at a predicted gain of 1e-4 of Σr². The f64 CPU reference
/// and the f32 GPU engine then take the same steps up to rounding, so the two differ
/// only where rounding tips a restart into another basin. On the default sweep (seeds
/// 1–8) that left 0–2 of its 36 rankings different between them (4 of 288 in all),
/// against 0–3 per seed when the CPU searched with f64's step to f64's floor, which took
/// twice its evaluations for slightly better optima (docs/losses.md).
///
/// Without the polish, each backend goes as far as its arithmetic allows: a step well
/// above √u (`u` the backend's unit roundoff) and a stop at 16u, below which an f32 Σr²
/// cannot tell a gain from rounding (f64 keeps `lm`'s own 1e-6 and 1e-10).
pub(super) fn search_options(lm: &lm::LmOptions, polish: bool, u: f64) -> lm::LmOptions {
    let mut o = lm.clone();
    if polish {
        o.fd_step = o.fd_step.max(POLISHED_SEARCH_FD_STEP);
        o.ftol = o.ftol.max(POLISHED_SEARCH_FTOL);
        o.stall_window = POLISHED_SEARCH_STALL.0;
        o.stall_gain = o.stall_gain.max(POLISHED_SEARCH_STALL.1);
    } else {
        o.fd_step = o.fd_step.max(4.0 * u.sqrt());
        o.ftol = o.ftol.max(16.0 * u);
    }
    o
}

/// The polish's stall test, in units of the mean squared residual: a restart whose Σr²
/// fell by less than this many times Σr²/n (n the residual rows) over `lm`'s stall window
/// stops. Why: on a misfit model (χ²_red ≫ 1) Gauss–Newton's model of Σr² ignores the
/// residuals' curvature, and LM crawls, accepting and rejecting steps in turn. A fit of
/// `fa(lambert)+ndf` to the Cornell acrylic spent its 200 iterations gaining ≈ 0.005 in χ²
/// per iteration (1.2 in all, of 37,446) while the Gauss–Newton decrement still promised
/// 45. For a χ² loss the unit is χ²_red: a point whose χ² is δ above the optimum has every
/// parameter within √δ standard deviations of it, so a crawl slower than this is moving
/// the parameters by a small fraction of their uncertainty. Only for fits with a prior
/// (the knots of the data-driven factors), where it was measured: on a fit without knots
/// (`lambert+retro` on the bundled red brick, χ²_red 144) the polish crawled 150 iterations
/// on a plateau, gaining 2e-7 of Σr² per iteration, then sped up and reached a χ² 15 %
/// lower; this test cut it at χ²_red 170. A stall test cannot tell a plateau from a
/// minimum; where the knots' weakly held directions make long crawls, it is worth it.
pub const POLISH_STALL_MEAN_SQUARES: f64 = 0.1;

/// Continue the best restart of each problem (`per` consecutive restarts each) with
/// Levenberg–Marquardt in f64 (`eval`, holding every problem: the CPU reference or the
/// SIMD engine's f64 lanes, the same model values), from
/// where the search stopped, with f64's forward-difference step and tolerance (an f64
/// run never ends above its start). Returns, per problem, the polished restart (index
/// within the problem).
///
/// Why: the search's forward differences use unit-box steps of ≈ 1e-3 (all f32 allows),
/// whose truncation error tilts the Gauss–Newton step; in a long, narrow valley (strongly
/// correlated parameters, e.g. a BTDF's roughness, scale and index) the search stalls
/// where the tilted step stops descending, up to 10 % above the f64 optimum on the
/// bundled diffusers. One f64 continuation per problem costs a few per cent of the
/// search's evaluations (a fifth of a GPU sweep's time, whose polish is the CPU's
/// work), and makes every backend's optima f64 optima.
pub(super) fn polish_in_f64(
    eval: &mut dyn Evaluator,
    model: &Model,
    space: &Constraints,
    finishers: &[Finisher],
    results: &mut [RestartResult],
    per: usize,
    lm_opts: &lm::LmOptions,
) -> anyhow::Result<Vec<usize>> {
    let best: Vec<usize> = results
        .chunks(per)
        .enumerate()
        .map(|(q, r)| {
            let i = (0..r.len())
                .min_by(|&a, &b| r[a].cost.total_cmp(&r[b].cost))
                .expect("at least one restart");
            q * per + i
        })
        .collect();
    let starts: Vec<Vec<f64>> = best.iter().map(|&i| results[i].x.clone()).collect();
    let mut lm_opts = lm_opts.clone();
    if space.prior_rows() > 0 {
        // The most rows of any problem: its stall threshold, the smallest, holds for all.
        let rows = (0..finishers.len())
            .map(|q| eval.samples_of(q) + space.prior_rows())
            .max()
            .unwrap_or(1)
            .max(1);
        lm_opts.stall_gain = lm_opts
            .stall_gain
            .max(POLISH_STALL_MEAN_SQUARES / rows as f64);
    }
    let mut obj = UnitBox {
        model,
        space,
        eval,
        finishers: finishers.to_vec(),
        start_problem: (0..finishers.len()).collect(),
    };
    let out = lm::minimize(
        &mut obj,
        &starts,
        &lm_opts,
        &|q, s| finishers[q].finish_sum(s),
        &mut |_| {},
    )?;
    for (&i, r) in best.iter().zip(out) {
        // Non-finite only if f64 fails where f32 did not: keep the f32 point then.
        if r.cost.is_finite() {
            results[i].x = r.x;
            results[i].cost = r.cost;
            results[i].stop = r.stop;
        }
    }
    Ok(best.iter().enumerate().map(|(q, &i)| i - q * per).collect())
}
