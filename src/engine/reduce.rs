//! Reductions over streamed model values, on the host.
//!
//! A backend hands a batch's model values over window by window ([`ValueWindow`]): for
//! each candidate, the values at a run of rows of its problem, in the evaluator's row
//! order (the CPU reference's direction order; the GPU engine's record slots, with
//! padding rows). What the optimizers and the conclusions need per candidate is then
//! reduced here, window after window, in f64: the Levenberg–Marquardt normal equations
//! ([`GramSums`]), the screening's rescaled Σr² ([`rescaled_sum_squares`]), a whole
//! row of values where one is really needed ([`values_in_sample_order`], one candidate
//! at the end of a fit). Nothing of length candidates × samples is ever held: memory
//! is one window, plus a few numbers per candidate.

use super::loss::{LossTerms, Term, NO_SAMPLE};
use super::Evaluator;
use crate::math::dot;
use crate::optim::{sanitize, NormalEquations};
use rayon::prelude::*;
use std::ops::Range;

/// Model values as a backend computed them: the GPU engine's f32, read back, or the
/// CPU reference's f64. Reductions widen each value to f64 as they read it.
#[derive(Clone, Copy)]
pub enum Values<'a> {
    F32(&'a [f32]),
    F64(&'a [f64]),
}

impl Values<'_> {
    pub fn len(&self) -> usize {
        match self {
            Values::F32(v) => v.len(),
            Values::F64(v) => v.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Value i, widened.
    #[inline]
    pub fn at(&self, i: usize) -> f64 {
        match self {
            Values::F32(v) => v[i] as f64,
            Values::F64(v) => v[i],
        }
    }
}

/// One candidate's share of a [`ValueWindow`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WindowPart {
    /// The candidate's index in the batch.
    pub candidate: usize,
    /// Its problem.
    pub problem: usize,
    /// The rows of that problem the window holds (its evaluator's row order).
    pub rows: Range<usize>,
    /// Where the candidate's values start in the window's values (`rows.len()` of them).
    pub offset: usize,
}

/// Model values of a batch at some rows of each candidate's problem.
pub struct ValueWindow<'a> {
    /// The candidates with rows in this window, in batch order (a candidate whose problem
    /// has no rows here is absent).
    pub parts: &'a [WindowPart],
    pub values: Values<'a>,
    /// Every problem's loss constants in row order.
    pub rows: &'a [RowTerms],
}

impl ValueWindow<'_> {
    /// The values of part i.
    pub fn values_of(&self, part: &WindowPart) -> Values<'_> {
        let r = part.offset..part.offset + part.rows.len();
        match self.values {
            Values::F32(v) => Values::F32(&v[r]),
            Values::F64(v) => Values::F64(&v[r]),
        }
    }
}

/// A problem's loss constants in its evaluator's row order: row r is sample `sample[r]`
/// of the problem, or padding ([`NO_SAMPLE`], every constant 0).
#[derive(Clone, Debug)]
pub struct RowTerms {
    pub sample: Vec<u32>,
    pub terms: LossTerms,
}

impl RowTerms {
    /// `terms` (in sample order) laid out in the row order `sample`.
    pub fn new(terms: &LossTerms, sample: Vec<u32>) -> RowTerms {
        RowTerms {
            terms: terms.in_rows(sample.iter().copied()),
            sample,
        }
    }

    pub fn rows(&self) -> usize {
        self.sample.len()
    }
}

/// Per group of m + 1 candidates (a point and the point moved along each of m
/// parameters), the sums behind its Levenberg–Marquardt normal equations, not yet divided
/// by the steps: with r the point's weighted residuals and d_j = r(moved_j) − r, the
/// upper triangle of Σ d_a d_b (row-major), Σ d_j r and Σ r². Sums over disjoint rows
/// add up ([`GramSums::add`]); [`GramSums::finish`] divides by the steps.
#[derive(Clone, Debug, PartialEq)]
pub struct GramSums {
    pub m: usize,
    /// m(m + 1)/2 + m + 1 sums, in the order above (the GPU's `normal` pass writes the
    /// same layout).
    pub sums: Vec<f64>,
}

/// How many sums [`GramSums`] holds for m moved points.
pub fn gram_entries(m: usize) -> usize {
    m * (m + 1) / 2 + m + 1
}

impl GramSums {
    pub fn zeros(m: usize) -> GramSums {
        GramSums {
            m,
            sums: vec![0.0; gram_entries(m)],
        }
    }

    pub fn add(&mut self, other: &GramSums) {
        for (a, b) in self.sums.iter_mut().zip(&other.sums) {
            *a += b;
        }
    }

    /// Add sums a device reduced in f32 (the same layout).
    pub fn add_f32(&mut self, sums: &[f32]) {
        for (a, &b) in self.sums.iter_mut().zip(sums) {
            *a += b as f64;
        }
    }

    /// The sums over `rows` of one problem whose loss constants (row order) are `terms`:
    /// `values` holds the point's values at those rows, then each moved point's, m + 1
    /// runs of `rows.len()`.
    ///
    /// The residuals are formed as [`LossTerms::residuals_into`] forms them and each sum
    /// is an 8-way interleaved dot product (vectorised), so that a problem reduced in one
    /// call gives exactly what the normal equations from whole residual rows give
    /// ([`NormalEquations::from_differences`]) where its rows fit one block. Longer runs
    /// are reduced a block of [`gram_block_rows`] rows at a time, so that the block's
    /// residuals and differences stay in the core's cache while its m(m + 1)/2 + m + 1
    /// dot products read them (whole rows of a dense set's window would be read from
    /// memory by every one of them).
    pub fn of_rows(terms: &LossTerms, rows: Range<usize>, values: Values, m: usize) -> GramSums {
        let n = rows.len();
        let block = gram_block_rows(m);
        let mut out = GramSums::zeros(m);
        with_scratch(|scratch| {
            let GramScratch { r0, diff } = scratch;
            for from in (0..n.max(1)).step_by(block) {
                let len = block.min(n - from.min(n));
                let sub = LossSlice::of(terms, rows.start + from..rows.start + from + len);
                r0.clear();
                sub.residuals_into(values, from, r0);
                diff.clear();
                for j in 0..m {
                    let start = diff.len();
                    sub.residuals_into(values, (j + 1) * n + from, diff);
                    for (d, &r) in diff[start..].iter_mut().zip(r0.iter()) {
                        *d -= r;
                    }
                }
                let row = |j: usize| &diff[j * len..(j + 1) * len];
                let mut e = 0;
                for a in 0..m {
                    for b in a..m {
                        out.sums[e] += dot(row(a), row(b));
                        e += 1;
                    }
                }
                for a in 0..m {
                    out.sums[e] += dot(row(a), r0);
                    e += 1;
                }
                out.sums[e] += r0.iter().map(|v| v * v).sum::<f64>();
            }
        });
        out
    }

    /// The normal equations: JᵀJ_ab = Σ d_a d_b / (h_a h_b), Jᵀr_j = Σ d_j r / h_j,
    /// Σr² (+∞ where NaN), with h the signed unit-box steps.
    pub fn finish(&self, steps: &[f64]) -> NormalEquations {
        let m = self.m;
        let mut jtj = vec![0.0; m * m];
        let mut e = 0;
        for a in 0..m {
            for b in a..m {
                let v = self.sums[e] / (steps[a] * steps[b]);
                jtj[a * m + b] = v;
                jtj[b * m + a] = v;
                e += 1;
            }
        }
        let jtr = (0..m).map(|j| self.sums[e + j] / steps[j]).collect();
        NormalEquations {
            jtj,
            jtr,
            ss: sanitize(self.sums[e + m]),
        }
    }
}

/// Rows of one block of [`GramSums::of_rows`]: the point's residuals and the m
/// differences of a block take at most 256 KiB, within a core's L2 cache.
pub fn gram_block_rows(m: usize) -> usize {
    ((256 << 10) / (8 * (m + 1))).max(64)
}

/// Buffers [`GramSums::of_rows`] reuses.
#[derive(Default)]
struct GramScratch {
    r0: Vec<f64>,
    diff: Vec<f64>,
}

thread_local! {
    /// Each thread's [`GramScratch`], kept from call to call: fresh buffers of this size
    /// are pages the kernel must clear and map again every time (a sixth of a dense
    /// fit's time on lavapipe went to page faults before).
    static GRAM_SCRATCH: std::cell::RefCell<GramScratch> = Default::default();
}

/// `f` with this thread's scratch (a fresh one if the thread's is in use).
fn with_scratch<R>(f: impl FnOnce(&mut GramScratch) -> R) -> R {
    GRAM_SCRATCH.with(|cell| match cell.try_borrow_mut() {
        Ok(mut s) => f(&mut s),
        Err(_) => f(&mut GramScratch::default()),
    })
}

/// The loss constants of a run of rows.
struct LossSlice<'a> {
    term: Term,
    a: &'a [f64],
    gy: &'a [f64],
    sqrt_w: &'a [f64],
}

impl<'a> LossSlice<'a> {
    fn of(t: &'a LossTerms, rows: Range<usize>) -> Self {
        LossSlice {
            term: t.term,
            a: &t.a[rows.clone()],
            gy: &t.gy[rows.clone()],
            sqrt_w: &t.sqrt_w[rows],
        }
    }

    /// The weighted residuals of values[from..from + n] (n = the slice's rows), appended.
    fn residuals_into(&self, values: Values, from: usize, out: &mut Vec<f64>) {
        let rows = self.a.iter().zip(self.gy).zip(self.sqrt_w);
        match (self.term, values) {
            (Term::LogSquare, Values::F32(v)) => out.extend(
                rows.zip(&v[from..])
                    .map(|(((&a, &gy), &sw), &v)| sw * ((a * v as f64).ln_1p() - gy)),
            ),
            (Term::LogSquare, Values::F64(v)) => out.extend(
                rows.zip(&v[from..])
                    .map(|(((&a, &gy), &sw), &v)| sw * ((a * v).ln_1p() - gy)),
            ),
            (_, Values::F32(v)) => out.extend(
                rows.zip(&v[from..])
                    .map(|(((&a, &gy), &sw), &v)| sw * (a * v as f64 - gy)),
            ),
            (_, Values::F64(v)) => out.extend(
                rows.zip(&v[from..])
                    .map(|(((&a, &gy), &sw), &v)| sw * (a * v - gy)),
            ),
        }
    }
}

/// Checks a batch of groups: N = owners.len() groups of m + 1 candidates of P parameters
/// (`params`, N × (m + 1) × P) with steps N × m. Returns m.
pub fn check_groups(
    owners: &[usize],
    params: &[f64],
    steps: &[f64],
    p: usize,
) -> anyhow::Result<usize> {
    let n = owners.len();
    anyhow::ensure!(p > 0, "a model without parameters has no normal equations");
    if n == 0 {
        anyhow::ensure!(
            params.is_empty() && steps.is_empty(),
            "parameters for no group"
        );
        return Ok(p);
    }
    anyhow::ensure!(
        steps.len().is_multiple_of(n),
        "{} steps for {n} groups",
        steps.len()
    );
    let m = steps.len() / n;
    anyhow::ensure!(
        params.len() == n * (m + 1) * p,
        "parameter batch of {} values is not {n} groups of {} candidates of P = {p}",
        params.len(),
        m + 1
    );
    Ok(m)
}

/// The normal equations of groups of m + 1 candidates (each group's point, then the point
/// moved along each of m parameters: `params` N × (m + 1) × P, `owners` each group's
/// problem, `steps` N × m the signed unit-box steps), reduced on the host from the
/// evaluator's value windows. Within a window the groups are reduced in parallel.
pub fn normal_equations<E: Evaluator + ?Sized>(
    eval: &mut E,
    owners: &[usize],
    params: &[f64],
    steps: &[f64],
) -> anyhow::Result<Vec<NormalEquations>> {
    let m = check_groups(owners, params, steps, eval.dim())?;
    let expanded: Vec<usize> = owners
        .iter()
        .flat_map(|&q| std::iter::repeat_n(q, m + 1))
        .collect();
    let mut sums = vec![GramSums::zeros(m); owners.len()];
    eval.value_windows(&expanded, params, &mut |w: &ValueWindow| {
        // Each group's m + 1 parts are consecutive and cover the same rows.
        let groups: Vec<(usize, usize)> = w
            .parts
            .iter()
            .enumerate()
            .filter(|(_, part)| part.candidate % (m + 1) == 0)
            .map(|(i, part)| (part.candidate / (m + 1), i))
            .collect();
        let partial: Vec<(usize, GramSums)> = groups
            .par_iter()
            .map(|&(g, i)| {
                let first = &w.parts[i];
                debug_assert!(w.parts[i + m].candidate == first.candidate + m);
                let n = first.rows.len();
                let values = match w.values {
                    Values::F32(v) => Values::F32(&v[first.offset..first.offset + (m + 1) * n]),
                    Values::F64(v) => Values::F64(&v[first.offset..first.offset + (m + 1) * n]),
                };
                let terms = &w.rows[first.problem].terms;
                (g, GramSums::of_rows(terms, first.rows.clone(), values, m))
            })
            .collect();
        for (g, s) in partial {
            sums[g].add(&s);
        }
        Ok(())
    })?;
    Ok(sums
        .iter()
        .zip(steps.chunks(m.max(1)))
        .map(|(s, h)| s.finish(h))
        .collect())
}

/// Every candidate's model values at every sample of its problem, in sample order, the
/// candidates' rows one after the other. This allocates candidates × samples: for one
/// candidate (a fit's best point) or small batches (tests), never for the optimizers.
pub fn values_in_sample_order<E: Evaluator + ?Sized>(
    eval: &mut E,
    owners: &[usize],
    params: &[f64],
) -> anyhow::Result<Vec<f64>> {
    let mut start = Vec::with_capacity(owners.len());
    let mut total = 0;
    for &q in owners {
        start.push(total);
        total += eval.samples_of(q);
    }
    let mut out = vec![f64::NAN; total];
    eval.value_windows(owners, params, &mut |w: &ValueWindow| {
        for part in w.parts {
            let sample = &w.rows[part.problem].sample[part.rows.clone()];
            let values = w.values_of(part);
            let base = start[part.candidate];
            for (i, &k) in sample.iter().enumerate() {
                if k != NO_SAMPLE {
                    out[base + k as usize] = values.at(i);
                }
            }
        }
        Ok(())
    })?;
    Ok(out)
}

/// Per candidate, Σr² of its model values after their best common rescaling s·y′ with
/// s ∈ [1/max_scale, max_scale], or unscaled where that is lower (the rule of
/// [`LossTerms::rescaled_sum_squares`], which ranks LM's random starts), streamed: one
/// pass gathers Σ w a² y′ y, Σ w a² y′² and the unscaled Σr²; for a square term the
/// rescaled Σr² follows in closed form, s² Σ w a² y′² − 2s Σ w a² y′ y + Σ w a² y²; for
/// the logarithmic term a second pass evaluates it at each candidate's s.
pub fn rescaled_sum_squares<E: Evaluator + ?Sized>(
    eval: &mut E,
    owners: &[usize],
    params: &[f64],
    max_scale: f64,
) -> anyhow::Result<Vec<f64>> {
    let n = owners.len();
    // Per candidate: Σ c y′ y, Σ c y′², Σ c y², Σ r²(1), with c = w a².
    let mut moments = vec![[0.0f64; 4]; n];
    let mut log_term = false;
    eval.value_windows(owners, params, &mut |w: &ValueWindow| {
        let partial: Vec<(usize, [f64; 4])> = w
            .parts
            .par_iter()
            .map(|part| {
                let t = &w.rows[part.problem].terms;
                let v = w.values_of(part);
                let mut m = [0.0; 4];
                for (i, row) in part.rows.clone().enumerate() {
                    let f = v.at(i);
                    let c2 = t.w[row] * t.a[row] * t.a[row];
                    m[0] += c2 * f * t.y[row];
                    m[1] += c2 * f * f;
                    m[2] += c2 * t.y[row] * t.y[row];
                    let r = t.residual(row, f);
                    m[3] += r * r;
                }
                (part.candidate, m)
            })
            .collect();
        for (c, m) in partial {
            for (a, b) in moments[c].iter_mut().zip(m) {
                *a += b;
            }
        }
        log_term |= w.rows.iter().any(|r| r.terms.term == Term::LogSquare);
        Ok(())
    })?;
    let scale = |m: &[f64; 4]| -> Option<f64> {
        let (fy, ff, unscaled) = (m[0], m[1], m[3]);
        (ff > 0.0 && fy > 0.0 && !unscaled.is_nan())
            .then(|| (fy / ff).clamp(1.0 / max_scale, max_scale))
    };
    if !log_term {
        return Ok(moments
            .iter()
            .map(|m| match scale(m) {
                Some(s) => m[3].min((s * s * m[1] - 2.0 * s * m[0] + m[2]).max(0.0)),
                None => m[3],
            })
            .collect());
    }
    // The logarithmic term: Σr² at each candidate's own scale, in a second pass.
    let scales: Vec<Option<f64>> = moments.iter().map(scale).collect();
    let mut scaled = vec![0.0f64; n];
    eval.value_windows(owners, params, &mut |w: &ValueWindow| {
        for part in w.parts {
            let Some(s) = scales[part.candidate] else {
                continue;
            };
            let t = &w.rows[part.problem].terms;
            let v = w.values_of(part);
            let mut sum = 0.0;
            for (i, row) in part.rows.clone().enumerate() {
                let r = t.residual(row, s * v.at(i));
                sum += r * r;
            }
            scaled[part.candidate] += sum;
        }
        Ok(())
    })?;
    Ok(moments
        .iter()
        .zip(&scales)
        .zip(&scaled)
        .map(|((m, s), &sc)| match s {
            Some(_) => m[3].min(sc),
            None => m[3],
        })
        .collect())
}

/// Normal equations of groups of P + 1 candidates from their model values in sample
/// order (the rows of each group's P + 1 candidates, K_owner values each) and the
/// unit-box steps (N × P): the reference the streamed reductions are tested against.
pub fn normal_equations_of_values<V: Copy + Into<f64>>(
    values: &[V],
    terms: &[&LossTerms],
    owners: &[usize],
    steps: &[f64],
    p: usize,
) -> Vec<NormalEquations> {
    let (mut at, mut r0, mut diff) = (0, Vec::new(), Vec::new());
    owners
        .iter()
        .zip(steps.chunks(p))
        .map(|(&q, h)| {
            let t = terms[q];
            let k = t.y.len();
            let vals = &values[at..at + k * (p + 1)];
            at += k * (p + 1);
            r0.clear();
            t.residuals_into(&vals[..k], &mut r0);
            diff.clear();
            for row in vals[k..].chunks(k.max(1)) {
                let start = diff.len();
                t.residuals_into(row, &mut diff);
                for (d, &r) in diff[start..].iter_mut().zip(&r0) {
                    *d -= r;
                }
            }
            NormalEquations::from_differences(&r0, &diff, h)
        })
        .collect()
}
