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
//! 1.6e8 evaluations per CPU-second on an "AMD EPYC" (`lscpu`; Zen 3 at 2.25 GHz, 2 cores
//! shared with other jobs): 14 cycles per row, 3–4× BBM's rate, most of them (`perf`) in
//! the lobe's shared factors (square roots and divisions per direction, shared by its
//! three rows). Evaluating per direction rather than per sample and channel is what
//! makes it so: the geometry is computed once for all channels.
//!
//! **Streamed.** A problem's rows are cut into windows of at most [`WINDOW_ROWS`] rows
//! (whole blocks). Costs are summed per (candidate, window) and normal equations per
//! (group, window), all pairs in parallel, and the partial sums of each candidate or
//! group added in window order (deterministic; a problem of one window sums exactly as
//! one pass would); value windows hold every candidate's values at one window's rows.
//! So the memory a batch takes is one window per worker, whatever the data's size, and
//! a batch of few candidates on much data still keeps every thread busy.

use super::reduce::{GramSums, RowTerms, ValueWindow, Values, WindowPart};
use super::simd::LaneDirs;
use super::{Backend, Evaluator, Problem};
use crate::bsdf::kernel::LaneKind;
use crate::bsdf::{Channels, Dir, Model};
use crate::engine::loss::{LossTerms, Term, EPS};
use crate::math::lanes::{F32x16, F32x8, F64x4};
use rayon::prelude::*;
use std::collections::HashMap;
use std::ops::Range;
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
        Ok(Box::new(CpuEvaluator::new(problems, Arith::Reference)?))
    }
}

/// Most directions evaluated in one call of the model tree: enough to pay each node's
/// dynamic dispatch and setup once for many directions, few enough that a block's values
/// (directions × channels × nodes) stay in the L1 cache.
const BLOCK: usize = 32;

/// [`BLOCK`] of the SIMD engine: its lanes take a block's 32 directions in four steps,
/// and the costs of a call (dispatch, the lanes' buffers, the instruction-set switch)
/// then weigh as much as the model; its values (f32 or f64 lanes) stay in L2.
const LANE_BLOCK: usize = 256;

/// Most rows of one window (whole blocks; a block larger than this is a window of its
/// own): a unit of parallel work and of the memory a value window takes per candidate
/// (64 KiB of f64). The bundled data sets, and most measured ones, are one window.
pub const WINDOW_ROWS: usize = 8192;

/// Consecutive directions of one problem with the same channels (the same groups in
/// the same order, `n` of them), evaluated in one call: directions `dirs` of the
/// problem, rows `start..start + n · dirs.len()` (each direction's n rows in turn).
#[derive(Clone, Debug)]
pub(super) struct Block {
    pub(super) dirs: std::ops::Range<usize>,
    pub(super) start: usize,
    pub(super) n: usize,
}

/// A run of whole blocks and the rows they hold.
#[derive(Clone, Debug)]
pub(super) struct Window {
    pub(super) blocks: Range<usize>,
    pub(super) rows: Range<usize>,
}

/// One problem of a batch, with what its evaluations reuse.
pub(super) struct Part<'a> {
    pub(super) problem: Problem<'a>,
    /// (ωi, ωo) of each direction, in direction order.
    dirs: Vec<Dir>,
    pub(super) blocks: Vec<Block>,
    windows: Vec<Window>,
    /// Per row (samples in direction order): its scalar-view group.
    pub(super) group: Vec<u32>,
    /// K, the problem's samples (= rows).
    samples: usize,
    /// The most rows of one block.
    widest: usize,
    /// The directions of every block in lanes, when the SIMD engine evaluates it.
    lanes: Option<LaneDirs>,
    evaluations: AtomicU64,
}

/// How an evaluator computes model values: the f64 reference, or SIMD lanes
/// ([`super::simd::SimdBackend`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Arith {
    Reference,
    Lanes(LaneKind),
}

impl<'a> Part<'a> {
    /// Group the samples by direction (ωi, ωo bit for bit) and plane, directions in the
    /// order their first samples come in [`walk_order`](super::walk_order), rows of a
    /// direction in sample order. Returns the part and its loss constants in row order.
    fn new(problem: Problem<'a>, arith: Arith) -> (Part<'a>, RowTerms) {
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
        drop(index);
        // Counting sort of the samples by direction (stable: sample order within one).
        let mut count = vec![0usize; first.len() + 1];
        for &d in &direction_of {
            count[d + 1] += 1;
        }
        for d in 0..first.len() {
            count[d + 1] += count[d];
        }
        let mut order = vec![0u32; samples.len()];
        let mut next = count.clone();
        for (k, &d) in direction_of.iter().enumerate() {
            order[next[d]] = k as u32;
            next[d] += 1;
        }
        drop(direction_of);
        let group: Vec<u32> = order.iter().map(|&k| group[k as usize]).collect();
        // Blocks: runs of consecutive directions whose rows name the same groups.
        let block = match arith {
            Arith::Reference => BLOCK,
            Arith::Lanes(_) => LANE_BLOCK,
        };
        let rows_of = |d: usize| count[d]..count[d + 1];
        let mut blocks: Vec<Block> = Vec::new();
        for d in 0..first.len() {
            let rows = rows_of(d);
            let extend = blocks.last().is_some_and(|b| {
                b.dirs.len() < block
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
        // Windows: runs of whole blocks of at most WINDOW_ROWS rows.
        let mut windows: Vec<Window> = Vec::new();
        for (i, b) in blocks.iter().enumerate() {
            let end = b.start + b.n * b.dirs.len();
            match windows.last_mut() {
                Some(w) if end - w.rows.start <= WINDOW_ROWS => {
                    w.blocks.end = i + 1;
                    w.rows.end = end;
                }
                _ => windows.push(Window {
                    blocks: i..i + 1,
                    rows: b.start..end,
                }),
            }
        }
        let terms = problem.loss.terms(problem.data);
        let rows = RowTerms::new(&terms, order);
        let lanes = match arith {
            Arith::Reference => None,
            Arith::Lanes(kind) => Some(LaneDirs::new(kind, model, &first, &blocks, &rows.terms)),
        };
        let part = Part {
            problem,
            widest: blocks.iter().map(|b| b.n * b.dirs.len()).max().unwrap_or(0),
            lanes,
            dirs: first,
            blocks,
            windows,
            group,
            samples: samples.len(),
            evaluations: AtomicU64::new(0),
        };
        (part, rows)
    }

    /// Calls `f(first row, values)` with the model values of the blocks `blocks` for one
    /// candidate (`scratch.views` already holds its scalar views).
    #[inline]
    fn for_each_block(
        &self,
        blocks: Range<usize>,
        scratch: &mut Scratch,
        f: impl FnMut(usize, &[f64]),
    ) {
        match &self.lanes {
            None => self.blocks_in_reference(blocks, scratch, f),
            Some(lanes) => self.blocks_in_lanes(lanes, blocks, scratch, f),
        }
    }

    #[inline]
    fn blocks_in_reference(
        &self,
        blocks: Range<usize>,
        scratch: &mut Scratch,
        mut f: impl FnMut(usize, &[f64]),
    ) {
        let model = self.problem.model;
        let stride = model.scalar_count();
        let Scratch {
            views,
            out,
            children,
            ..
        } = scratch;
        for b in &self.blocks[blocks] {
            let p = Channels::new(views, stride, &self.group[b.start..b.start + b.n]);
            let out = &mut out[..b.n * b.dirs.len()];
            model
                .root
                .eval_channels(p, &self.dirs[b.dirs.clone()], out, children);
            f(b.start, out);
        }
    }

    /// The model values of one candidate at a window's rows, into `out` (its rows' length).
    fn window_values(&self, w: &Window, scratch: &mut Scratch, out: &mut [f64]) {
        let first = w.rows.start;
        self.for_each_block(w.blocks.clone(), scratch, |start, values| {
            out[start - first..start - first + values.len()].copy_from_slice(values);
        });
    }

    /// The sum of one candidate's loss terms (`t`, in row order) over a window's rows,
    /// in row order.
    fn cost_sum(&self, t: &LossTerms, w: &Window, scratch: &mut Scratch) -> f64 {
        if let Some(lanes) = &self.lanes {
            return self.cost_sum_split(lanes, w, scratch);
        }
        let mut sum = 0.0;
        // One loop per term shape, so that the row loop has no branch on it.
        match t.term {
            Term::Square => self.for_each_block(w.blocks.clone(), scratch, |start, values| {
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
            Term::LogSquare => self.for_each_block(w.blocks.clone(), scratch, |start, values| {
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
            Term::AbsRatio => self.for_each_block(w.blocks.clone(), scratch, |start, values| {
                let r = start..start + values.len();
                for ((&v, &y), &w) in values.iter().zip(&t.y[r.clone()]).zip(&t.w[r]) {
                    sum += w * (v - y).abs() / (v.abs() + y.abs() + EPS);
                }
            }),
        }
        sum
    }
}

thread_local! {
    static SCRATCH: std::cell::RefCell<Scratch> = Default::default();
}

/// What one rayon worker reuses from task to task.
#[derive(Default)]
pub(super) struct Scratch {
    /// The scalar views of every group ([`Model::views_into`]).
    pub(super) views: Vec<f64>,
    /// The values of one block's rows, and its nodes' children's values.
    pub(super) out: Vec<f64>,
    children: Vec<f64>,
    /// A group's values at a window (normal equations).
    group_values: Vec<f64>,
    /// A block's values and its nodes' children's values in lanes (SIMD engine).
    pub(super) out32: Vec<F32x8>,
    pub(super) children32: Vec<F32x8>,
    pub(super) out16: Vec<F32x16>,
    pub(super) children16: Vec<F32x16>,
    pub(super) out64: Vec<F64x4>,
    pub(super) children64: Vec<F64x4>,
}

impl Scratch {
    /// Room for blocks of `widest` rows and the children of a model whose scratch is
    /// `scratch_len` values.
    fn fit(&mut self, widest: usize, scratch_len: usize) {
        if self.out.len() < widest {
            self.out.resize(widest, 0.0);
        }
        if self.children.len() < scratch_len {
            self.children.resize(scratch_len, 0.0);
        }
    }
}

pub struct CpuEvaluator<'a> {
    parts: Vec<Part<'a>>,
    /// Every problem's loss constants in row order.
    rows: Vec<RowTerms>,
    /// The flat index of every group's scalars ([`Model::slot_table`]).
    slots: Vec<usize>,
    /// The most rows of one block over the parts, and the scratch it needs.
    widest: usize,
    scratch_len: usize,
}

impl<'a> CpuEvaluator<'a> {
    /// An evaluator of `problems` that computes model values as `arith` says.
    pub(crate) fn new(problems: &[Problem<'a>], arith: Arith) -> anyhow::Result<Self> {
        super::check_shared(problems)?;
        let (parts, rows): (Vec<Part>, Vec<RowTerms>) =
            problems.iter().map(|&p| Part::new(p, arith)).unzip();
        let model = problems[0].model;
        let widest = parts.iter().map(|p| p.widest).max().unwrap_or(0);
        Ok(CpuEvaluator {
            slots: model.slot_table(),
            widest,
            scratch_len: model.scratch_len(widest),
            parts,
            rows,
        })
    }

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

    /// Count `per_candidate` evaluations of every sample for each candidate of
    /// `owners`: one atomic add per problem, not per candidate (on sixteen cores the
    /// serial part of a call is what keeps small batches from scaling).
    fn count(&self, owners: &[usize], per_candidate: u64) {
        let mut candidates = vec![0u64; self.parts.len()];
        for &q in owners {
            candidates[q] += 1;
        }
        for (part, k) in self.parts.iter().zip(candidates) {
            if k > 0 {
                part.evaluations
                    .fetch_add(k * per_candidate * part.samples as u64, Ordering::Relaxed);
            }
        }
    }

    /// `f` with this thread's scratch, grown to this evaluator's needs (a fresh one if
    /// the thread's is in use). Kept from task to task and call to call: fresh buffers
    /// are pages the kernel must clear and map again.
    fn with_scratch<R>(&self, f: impl FnOnce(&mut Scratch) -> R) -> R {
        SCRATCH.with(|cell| match cell.try_borrow_mut() {
            Ok(mut s) => {
                s.fit(self.widest, self.scratch_len);
                f(&mut s)
            }
            Err(_) => {
                let mut s = Scratch::default();
                s.fit(self.widest, self.scratch_len);
                f(&mut s)
            }
        })
    }

    /// Every (item, window of its problem) pair, items in order: `problem(i)` gives item
    /// i's problem.
    fn tasks(&self, items: usize, problem: impl Fn(usize) -> usize) -> Vec<(usize, usize)> {
        (0..items)
            .flat_map(|i| (0..self.parts[problem(i)].windows.len()).map(move |w| (i, w)))
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
        self.parts[q].samples
    }

    /// Every (candidate, window) sum in parallel, then each candidate's sums added in
    /// window order and finished (in the candidate's task where it has one window).
    fn costs_of(&mut self, owners: &[usize], params: &[f64]) -> anyhow::Result<Vec<f64>> {
        self.check(owners, params)?;
        let p = self.dim();
        let window_sum = |c: usize, w: usize| {
            self.with_scratch(|scratch| {
                let part = &self.parts[owners[c]];
                Model::views_into(&params[c * p..(c + 1) * p], &self.slots, &mut scratch.views);
                part.cost_sum(&self.rows[owners[c]].terms, &part.windows[w], scratch)
            })
        };
        let costs = if owners.iter().all(|&q| self.parts[q].windows.len() == 1) {
            // One window per candidate (sparse data): each task also finishes its cost,
            // so nothing but the collection runs between two parallel calls.
            (0..owners.len())
                .into_par_iter()
                .map(|c| self.rows[owners[c]].terms.finish_sum(window_sum(c, 0)))
                .collect()
        } else {
            let tasks = self.tasks(owners.len(), |i| owners[i]);
            let sums: Vec<f64> = tasks.par_iter().map(|&(c, w)| window_sum(c, w)).collect();
            let mut costs = vec![0.0; owners.len()];
            for (&(c, _), s) in tasks.iter().zip(sums) {
                costs[c] += s;
            }
            for (c, &q) in costs.iter_mut().zip(owners) {
                *c = self.rows[q].terms.finish_sum(*c);
            }
            costs
        };
        self.count(owners, 1);
        Ok(costs)
    }

    /// Window w of every problem in turn (w = 0, 1, …): the candidates whose problem has
    /// a window w, each evaluated there in parallel.
    fn value_windows(
        &mut self,
        owners: &[usize],
        params: &[f64],
        visit: &mut dyn FnMut(&ValueWindow) -> anyhow::Result<()>,
    ) -> anyhow::Result<()> {
        self.check(owners, params)?;
        let p = self.dim();
        let most = owners
            .iter()
            .map(|&q| self.parts[q].windows.len())
            .max()
            .unwrap_or(0);
        let mut values: Vec<f64> = Vec::new();
        for w in 0..most {
            let mut parts = Vec::new();
            let mut offset = 0;
            for (c, &q) in owners.iter().enumerate() {
                if let Some(win) = self.parts[q].windows.get(w) {
                    parts.push(WindowPart {
                        candidate: c,
                        problem: q,
                        rows: win.rows.clone(),
                        offset,
                    });
                    offset += win.rows.len();
                }
            }
            values.clear();
            values.resize(offset, 0.0);
            let mut slices: Vec<&mut [f64]> = Vec::with_capacity(parts.len());
            let mut rest = values.as_mut_slice();
            for part in &parts {
                let (head, tail) = rest.split_at_mut(part.rows.len());
                slices.push(head);
                rest = tail;
            }
            slices.into_par_iter().zip(&parts).for_each(|(out, part)| {
                self.with_scratch(|scratch| {
                    let c = part.candidate;
                    let pt = &self.parts[part.problem];
                    Model::views_into(&params[c * p..(c + 1) * p], &self.slots, &mut scratch.views);
                    pt.window_values(&pt.windows[w], scratch, out);
                })
            });
            visit(&ValueWindow {
                parts: &parts,
                values: Values::F64(&values),
                rows: &self.rows,
            })?;
        }
        self.count(owners, 1);
        Ok(())
    }

    /// Every (group, window) pair in parallel: the group's m + 1 candidates evaluated at
    /// the window's rows, reduced there to its sums ([`GramSums`]); then each group's sums
    /// added in window order and divided by the steps.
    fn normal_equations_of(
        &mut self,
        owners: &[usize],
        params: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<crate::optim::NormalEquations>> {
        let p = self.dim();
        let m = super::reduce::check_groups(owners, params, steps, p)?;
        anyhow::ensure!(
            owners.iter().all(|&q| q < self.parts.len()),
            "a group names a problem outside the batch's {}",
            self.parts.len()
        );
        let group_len = (m + 1) * p;
        let tasks = self.tasks(owners.len(), |g| owners[g]);
        let partial: Vec<GramSums> = tasks
            .par_iter()
            .map(|&(g, w)| {
                self.with_scratch(|scratch| {
                    let part = &self.parts[owners[g]];
                    let win = &part.windows[w];
                    let n = win.rows.len();
                    let mut values = std::mem::take(&mut scratch.group_values);
                    values.clear();
                    values.resize((m + 1) * n, 0.0);
                    for (j, flat) in params[g * group_len..(g + 1) * group_len]
                        .chunks(p)
                        .enumerate()
                    {
                        Model::views_into(flat, &self.slots, &mut scratch.views);
                        part.window_values(win, scratch, &mut values[j * n..(j + 1) * n]);
                    }
                    let sums = GramSums::of_rows(
                        &self.rows[owners[g]].terms,
                        win.rows.clone(),
                        Values::F64(&values),
                        m,
                    );
                    scratch.group_values = values;
                    sums
                })
            })
            .collect();
        let mut sums = vec![GramSums::zeros(m); owners.len()];
        for (&(g, _), s) in tasks.iter().zip(&partial) {
            sums[g].add(s);
        }
        self.count(owners, (m + 1) as u64);
        Ok(sums
            .iter()
            .zip(steps.chunks(m.max(1)))
            .map(|(s, h)| s.finish(h))
            .collect())
    }

    fn evaluations_of(&self, q: usize) -> u64 {
        self.parts[q].evaluations.load(Ordering::Relaxed)
    }
}
