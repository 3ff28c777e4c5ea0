//! The CPU reference backend: f64, rayon across candidates.
//!
//! **Channels together.** At prepare time the samples of each problem are grouped by
//! direction: every sample with the same (ωi, ωo) and measurement plane becomes one row
//! of one direction, whose rows are its channels (one per wavelength measured there; a
//! repeated measurement is one more row). Consecutive directions with the same channels
//! form a [`Block`] of up to [`BLOCK`] directions, evaluated in one call of
//! [`Node::eval_channels`](crate::bsdf::Node::eval_channels): a node computes what does
//! not depend on its rgb parameters (half vector, D, G1, Fresnel factors, the
//! micrograin weight, EON's directional albedos, VMF's scattering orders) once per
//! direction and only the per-channel products per channel — as BBM (Peers 2023, the
//! library the benchmark paper's BRDF fits used) evaluates the RGB channels of a
//! direction in one call — and pays its dynamic dispatch once per block. The values
//! equal the per-channel `Node::eval` bit for bit (`tests/channels.rs`).
//!
//! **Per-row overhead.** Per candidate, the scalar views of every (plane, channel) group
//! are gathered once from a slot table into a buffer that each rayon worker keeps
//! ([`Scratch`]); nothing is allocated per candidate for the loss. The loss constants are
//! stored in direction order with g(y) and √w precomputed ([`LossTerms::reordered`]), so
//! a row's term is a few flops on contiguous arrays, and the loss sums its terms in that
//! order (the sample order itself when a file lists each direction's channels
//! together, as `synth` writes them). `costs_of` sums terms; `values_of` scatters values
//! back to sample order; `normal_equations_of` forms residuals directly, in direction
//! order.
//!
//! **Throughput.** On an RGB `fa(lambert)` set of 381 directions × 3 channels = 1,143
//! rows (`bsdfit synth --model 'fa(lambert)' --geometry hemi`), `RAYON_NUM_THREADS=1
//! bsdfit bench --backend cpu --models 'fa(lambert)' --data FILE --seconds 3` measures
//! 4.8–6.3e7 evaluations per CPU-second on an "AMD EPYC" (`lscpu`; Zen 3 at 2.25 GHz,
//! 2 cores shared with other jobs), against 8.3–9.4e6 for the evaluator this replaced
//! (one `Node::eval` per sample and channel, the geometry recomputed for each channel).
//! At 2.25 GHz that is 36–47 cycles per row, most of them (`perf`) in the lobe's
//! shared factors: three square roots and two divisions per direction, shared by its
//! three rows. Measured again with the current code (the same command): 1.6e8 per
//! CPU-second, 14 cycles per row, 3–4× BBM's rate.

use super::{Backend, Evaluator, Problem};
use crate::bsdf::{Channels, Dir, Model};
use crate::engine::loss::{LossTerms, Term, EPS};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};

#[derive(Debug, Default, Clone)]
pub struct CpuBackend;

impl CpuBackend {
    pub fn new() -> Self {
        CpuBackend
    }
}

impl Backend for CpuBackend {
    fn name(&self) -> String {
        format!("cpu (f64, rayon, {} threads)", rayon::current_num_threads())
    }
    fn id(&self) -> &'static str {
        "cpu"
    }
    fn prepare_many<'a>(
        &'a self,
        problems: &[Problem<'a>],
    ) -> anyhow::Result<Box<dyn Evaluator + 'a>> {
        super::check_shared(problems)?;
        let parts: Vec<Part> = problems.iter().map(|&p| Part::new(p)).collect();
        let model = problems[0].model;
        let widest = parts.iter().map(|p| p.widest).max().unwrap_or(0);
        Ok(Box::new(CpuEvaluator {
            slots: model.slot_table(),
            widest,
            scratch_len: model.scratch_len(widest),
            parts,
        }))
    }
}

/// Most directions evaluated in one call of the model tree: enough to pay each node's
/// dynamic dispatch and setup once for many directions, few enough that a block's values
/// (directions × channels × nodes) stay in the L1 cache.
const BLOCK: usize = 32;

/// Consecutive directions of one problem with the same channels (the same groups in
/// the same order, `n` of them), evaluated in one call: directions `dirs` of the
/// problem, rows `start..start + n · dirs.len()` (each direction's n rows in turn).
#[derive(Clone, Debug)]
struct Block {
    dirs: std::ops::Range<usize>,
    start: usize,
    n: usize,
}

/// One problem of a batch, with what its evaluations reuse.
struct Part<'a> {
    problem: Problem<'a>,
    /// (ωi, ωo) of each direction, in direction order.
    dirs: Vec<Dir>,
    blocks: Vec<Block>,
    /// Per row (samples in direction order): the sample it is, and its scalar-view group.
    sample: Vec<usize>,
    group: Vec<u32>,
    /// The loss constants in row order.
    rows: LossTerms,
    /// The most rows of one block.
    widest: usize,
    evaluations: AtomicU64,
}

impl<'a> Part<'a> {
    /// Group the samples by direction (ωi, ωo bit for bit) and plane, directions in the
    /// order their first samples come in [`walk_order`](super::walk_order), rows of a
    /// direction in sample order.
    fn new(problem: Problem<'a>) -> Part<'a> {
        let model = problem.model;
        let samples = &problem.data.samples;
        let mut index: HashMap<([u64; 6], usize), usize> = HashMap::new();
        let mut first: Vec<Dir> = Vec::new();
        let mut direction_of = vec![0; samples.len()];
        let mut group = vec![0u32; samples.len()];
        for k in super::walk_order(problem.data) {
            let s = &samples[k];
            let (wi, wo) = (s.wi(), s.wo());
            let g = model.group_of(s);
            let key = (
                [wi.x, wi.y, wi.z, wo.x, wo.y, wo.z].map(f64::to_bits),
                g / model.channels,
            );
            direction_of[k] = *index.entry(key).or_insert_with(|| {
                first.push((wi, wo));
                first.len() - 1
            });
            group[k] = g as u32;
        }
        // Counting sort of the samples by direction (stable: sample order within one).
        let mut count = vec![0usize; first.len() + 1];
        for &d in &direction_of {
            count[d + 1] += 1;
        }
        for d in 0..first.len() {
            count[d + 1] += count[d];
        }
        let mut order = vec![0usize; samples.len()];
        let mut next = count.clone();
        for (k, &d) in direction_of.iter().enumerate() {
            order[next[d]] = k;
            next[d] += 1;
        }
        let group: Vec<u32> = order.iter().map(|&k| group[k]).collect();
        // Blocks: runs of consecutive directions whose rows name the same groups.
        let rows_of = |d: usize| count[d]..count[d + 1];
        let mut blocks: Vec<Block> = Vec::new();
        for d in 0..first.len() {
            let rows = rows_of(d);
            let extend = blocks.last().is_some_and(|b| {
                b.dirs.len() < BLOCK
                    && b.n == rows.len()
                    && group[b.start..b.start + b.n] == group[rows.clone()]
            });
            match blocks.last_mut() {
                Some(b) if extend => b.dirs.end = d + 1,
                _ => blocks.push(Block {
                    dirs: d..d + 1,
                    start: rows.start,
                    n: rows.len(),
                }),
            }
        }
        let terms = problem.loss.terms(problem.data);
        Part {
            problem,
            widest: blocks.iter().map(|b| b.n * b.dirs.len()).max().unwrap_or(0),
            dirs: first,
            blocks,
            group,
            rows: terms.reordered(&order),
            sample: order,
            evaluations: AtomicU64::new(0),
        }
    }

    /// Calls `f(first row, values)` with the model values of every block's rows for one
    /// candidate (`scratch.views` already holds its scalar views).
    #[inline]
    fn for_each_block(&self, scratch: &mut Scratch, mut f: impl FnMut(usize, &[f64])) {
        let model = self.problem.model;
        let stride = model.scalar_count();
        let Scratch {
            views,
            out,
            children,
        } = scratch;
        for b in &self.blocks {
            let p = Channels::new(views, stride, &self.group[b.start..b.start + b.n]);
            let out = &mut out[..b.n * b.dirs.len()];
            model
                .root
                .eval_channels(p, &self.dirs[b.dirs.clone()], out, children);
            f(b.start, out);
        }
    }

    /// The loss of one candidate: the terms of the loss's shape, summed in row order.
    fn cost(&self, scratch: &mut Scratch) -> f64 {
        let t = &self.rows;
        let mut sum = 0.0;
        // One loop per term shape, so that the row loop has no branch on it.
        match t.term {
            Term::Square => self.for_each_block(scratch, |start, values| {
                let r = start..start + values.len();
                for (((&v, &a), &gy), &w) in values
                    .iter()
                    .zip(&t.a[r.clone()])
                    .zip(&t.gy[r.clone()])
                    .zip(&t.w[r])
                {
                    let d = a * v - gy;
                    sum += w * d * d;
                }
            }),
            Term::LogSquare => self.for_each_block(scratch, |start, values| {
                let r = start..start + values.len();
                for (((&v, &a), &gy), &w) in values
                    .iter()
                    .zip(&t.a[r.clone()])
                    .zip(&t.gy[r.clone()])
                    .zip(&t.w[r])
                {
                    let d = (a * v).ln_1p() - gy;
                    sum += w * d * d;
                }
            }),
            Term::AbsRatio => self.for_each_block(scratch, |start, values| {
                let r = start..start + values.len();
                for ((&v, &y), &w) in values.iter().zip(&t.y[r.clone()]).zip(&t.w[r]) {
                    sum += w * (v - y).abs() / (v.abs() + y.abs() + EPS);
                }
            }),
        }
        t.finish_sum(sum)
    }
}

/// What one rayon worker reuses from candidate to candidate.
struct Scratch {
    /// The scalar views of every group ([`Model::views_into`]).
    views: Vec<f64>,
    /// The values of one block's rows, and its nodes' children's values.
    out: Vec<f64>,
    children: Vec<f64>,
}

pub struct CpuEvaluator<'a> {
    parts: Vec<Part<'a>>,
    /// The flat index of every group's scalars ([`Model::slot_table`]).
    slots: Vec<usize>,
    /// The most rows of one block over the parts, and the scratch it needs.
    widest: usize,
    scratch_len: usize,
}

impl CpuEvaluator<'_> {
    fn check(&self, owners: &[usize], params: &[f64]) -> anyhow::Result<()> {
        let p = self.dim();
        anyhow::ensure!(
            p > 0 && params.len() == owners.len() * p,
            "parameter batch of {} values is not {} candidates of P = {p}",
            params.len(),
            owners.len()
        );
        anyhow::ensure!(
            owners.iter().all(|&q| q < self.parts.len()),
            "a candidate names a problem outside the batch's {}",
            self.parts.len()
        );
        Ok(())
    }

    fn count(&self, owners: &[usize]) {
        for &q in owners {
            let part = &self.parts[q];
            part.evaluations
                .fetch_add(part.sample.len() as u64, Ordering::Relaxed);
        }
    }

    fn scratch(&self) -> Scratch {
        Scratch {
            views: Vec::with_capacity(self.slots.len()),
            out: vec![0.0; self.widest],
            children: vec![0.0; self.scratch_len],
        }
    }

    /// `f(part, scratch)` for every candidate, in parallel, with the candidate's views in
    /// the scratch.
    fn map_candidates<T: Send>(
        &self,
        owners: &[usize],
        params: &[f64],
        f: impl Fn(&Part, &mut Scratch) -> T + Sync + Send,
    ) -> Vec<T> {
        params
            .par_chunks(self.dim())
            .zip(owners.par_iter())
            .map_init(
                || self.scratch(),
                |scratch, (flat, &q)| {
                    Model::views_into(flat, &self.slots, &mut scratch.views);
                    f(&self.parts[q], scratch)
                },
            )
            .collect()
    }
}

impl Evaluator for CpuEvaluator<'_> {
    fn dim(&self) -> usize {
        self.parts[0].problem.model.dim
    }

    fn problems(&self) -> usize {
        self.parts.len()
    }

    fn samples_of(&self, q: usize) -> usize {
        self.parts[q].sample.len()
    }

    fn costs_of(&mut self, owners: &[usize], params: &[f64]) -> anyhow::Result<Vec<f64>> {
        self.check(owners, params)?;
        let out = self.map_candidates(owners, params, |part, scratch| part.cost(scratch));
        self.count(owners);
        Ok(out)
    }

    fn values_of(&mut self, owners: &[usize], params: &[f64]) -> anyhow::Result<Vec<f64>> {
        self.check(owners, params)?;
        let rows = self.map_candidates(owners, params, |part, scratch| {
            let mut row = vec![0.0; part.sample.len()];
            part.for_each_block(scratch, |start, values| {
                for (&k, &v) in part.sample[start..start + values.len()].iter().zip(values) {
                    row[k] = v;
                }
            });
            row
        });
        self.count(owners);
        Ok(rows.concat())
    }

    /// Residuals r_k = √w_k (g(y′_k) − g(y_k)) of every candidate in direction order,
    /// then the normal equations of each group of P + 1 (sums over rows in that order).
    fn normal_equations_of(
        &mut self,
        owners: &[usize],
        params: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<crate::optim::NormalEquations>> {
        let p = self.dim();
        anyhow::ensure!(
            steps.len() == owners.len() * p,
            "{} steps for {} groups of P = {p}",
            steps.len(),
            owners.len()
        );
        let expanded: Vec<usize> = owners
            .iter()
            .flat_map(|&q| std::iter::repeat_n(q, p + 1))
            .collect();
        self.check(&expanded, params)?;
        let residuals = self.map_candidates(&expanded, params, |part, scratch| {
            let t = &part.rows;
            let mut row = Vec::with_capacity(part.sample.len());
            part.for_each_block(scratch, |start, values| {
                row.extend(
                    values
                        .iter()
                        .enumerate()
                        .map(|(i, &v)| t.residual(start + i, v)),
                );
            });
            row
        });
        self.count(&expanded);
        Ok(residuals
            .par_chunks(p + 1)
            .zip(steps.par_chunks(p))
            .map(|(rows, h)| {
                let k = rows[0].len();
                crate::optim::NormalEquations::from_residuals(&rows.concat(), h, k)
            })
            .collect())
    }

    fn evaluations_of(&self, q: usize) -> u64 {
        self.parts[q].evaluations.load(Ordering::Relaxed)
    }
}
