//! The SIMD CPU engine: the CPU reference's evaluator (directions grouped by channels,
//! blocks, windows, the same streamed reductions in f64) with model values computed in
//! SIMD lanes of sixteen or eight f32 or four f64 directions ([`crate::math::lanes`])
//! from the same model source as the reference ([`crate::bsdf::kernel`]).
//!
//! **Precision.** A model runs in f32 lanes (the GPU engine's arithmetic, and its
//! accuracy contract: `tests/simd_parity.rs` holds it to the GPU parity bounds) unless
//! one of its nodes declares that it needs f64 ([`crate::bsdf::Model::lane_kind`]).
//! Losses and normal equations are summed in f64, as on the reference.
//!
//! **Where its code is.** The evaluator is the reference's ([`CpuEvaluator`], with
//! [`Arith::Lanes`]); what only the lanes do lives here: the blocks' directions packed
//! into lanes ([`LaneDirs`]), the values leaving the lanes, and the loss summed in lane
//! order in interleaved partial sums.
//!
//! **Where it is used.** `--backend simd`, and `--backend auto` where no hardware GPU
//! exists (a CPU-only cluster node, or a machine whose only Vulkan device is a
//! software rasterizer such as lavapipe).

use super::cpu::{Arith, Block, CpuEvaluator, Part, Scratch, Window};
use super::{Backend, Evaluator, Problem};
use crate::bsdf::kernel::{LaneDir, LaneKind, LaneReal};
use crate::bsdf::{Channels, Dir, Model};
use crate::engine::loss::{LossTerms, Term, EPS, NO_SAMPLE};
use crate::math::lanes::{instruction_set, vectorized, F32x16, F32x8, F64x4, Real, V3};
use std::ops::Range;

/// The SIMD CPU engine.
#[derive(Debug, Default, Clone)]
pub struct SimdBackend {
    /// Lanes for every model, whatever its nodes ask for (tests of the f64 lanes).
    lanes: Option<LaneKind>,
}

impl SimdBackend {
    pub fn new() -> Self {
        SimdBackend { lanes: None }
    }

    /// The engine with every model in the lanes `kind` (f64 lanes give the reference's
    /// values bit for bit: `tests/simd_parity.rs`).
    pub fn with_lanes(kind: LaneKind) -> Self {
        SimdBackend { lanes: Some(kind) }
    }
}

impl Backend for SimdBackend {
    fn name(&self) -> String {
        format!(
            "simd ({} lanes, rayon, {} threads)",
            instruction_set(),
            rayon::current_num_threads()
        )
    }
    fn id(&self) -> &'static str {
        "simd"
    }
    /// f32's: most models run in f32 lanes, and finite differences must step above it.
    fn unit_roundoff(&self) -> f64 {
        f32::EPSILON as f64 / 2.0
    }
    fn prepare_many<'a>(
        &'a self,
        problems: &[Problem<'a>],
    ) -> anyhow::Result<Box<dyn Evaluator + 'a>> {
        let model = problems
            .first()
            .ok_or_else(|| anyhow::anyhow!("no problem to evaluate"))?
            .model;
        let kind: LaneKind = self
            .lanes
            .unwrap_or_else(|| model.lane_kind().on_this_processor());
        Ok(Box::new(CpuEvaluator::new(problems, Arith::Lanes(kind))?))
    }
}

// ---------------------------------------------------------------------------------------
// The lane machinery: the blocks' directions packed into lanes, the values leaving the
// lanes, and the loss summed in lane order. The reference's evaluator
// ([`super::cpu::CpuEvaluator`]) runs it where its arithmetic is [`Arith::Lanes`].

/// Every block's directions as lane-directions (the last lane-direction of a block
/// padded with its last direction), block after block, and the loss constants in the
/// lane order of the blocks' values.
pub(super) struct LaneDirs {
    dirs: LaneVec,
    /// Block b's first lane-direction.
    at: Vec<usize>,
    /// Block b's first value in lane order: its m lane-directions × n channels × L
    /// lanes, value (d · n + i) · L + j at lane j of lane-direction d, channel i.
    values_at: Vec<usize>,
    /// The loss constants of the values in lane order (zero for a padding lane); a
    /// squared term's √w taken into a and g(y): w (a y′ − g(y))² = (√w a y′ − √w g(y))²,
    /// one product less per row.
    terms: LossTerms,
    /// A squared term's √w·a and √w·g(y) in f32 for f32 lanes ([`SquareSum32`]; `terms`
    /// then keeps no f64 copies of them).
    square32: Option<(Vec<f32>, Vec<f32>)>,
    /// The children's lane values the largest block needs ([`Model::scratch_len`]).
    scratch_len: usize,
}

enum LaneVec {
    F32x8(Vec<LaneDir<F32x8>>),
    F32x16(Vec<LaneDir<F32x16>>),
    F64x4(Vec<LaneDir<F64x4>>),
}

impl LaneDirs {
    /// The lanes of `blocks` of the model `model`, whose row-order loss constants are
    /// `rows`.
    pub(super) fn new(
        kind: LaneKind,
        model: &Model,
        dirs: &[Dir],
        blocks: &[Block],
        rows: &LossTerms,
    ) -> LaneDirs {
        fn pack<R: Real>(dirs: &[Dir], blocks: &[Block]) -> Vec<LaneDir<R>> {
            let mut v = Vec::new();
            for b in blocks {
                let d = &dirs[b.dirs.clone()];
                let slots = mu_slots(d);
                for first in (0..d.len()).step_by(R::LANES) {
                    let at = |j: usize| (first + j).min(d.len() - 1);
                    let c = |f: fn(&Dir) -> f64| R::from_fn(|j| f(&d[at(j)]));
                    let slot = |k: usize| R::from_fn(|j| slots[at(j)][k] as f64);
                    v.push(LaneDir {
                        wi: V3::new(c(|w| w.0.x), c(|w| w.0.y), c(|w| w.0.z)),
                        wo: V3::new(c(|w| w.1.x), c(|w| w.1.y), c(|w| w.1.z)),
                        mu_slots: [slot(0), slot(1)],
                    });
                }
            }
            v
        }
        let (dirs, l) = match kind {
            LaneKind::F32x8 => (LaneVec::F32x8(pack(dirs, blocks)), F32x8::LANES),
            LaneKind::F32x16 => (LaneVec::F32x16(pack(dirs, blocks)), F32x16::LANES),
            LaneKind::F64x4 => (LaneVec::F64x4(pack(dirs, blocks)), F64x4::LANES),
        };
        let (mut at, mut values_at) = (Vec::new(), Vec::new());
        // The row of each value in lane order, or NO_SAMPLE for a padding lane.
        let mut rows_of_values = Vec::new();
        let mut next = 0;
        for b in blocks {
            at.push(next);
            values_at.push(rows_of_values.len());
            let (n, len) = (b.n, b.dirs.len());
            let m = len.div_ceil(l);
            next += m;
            for d in 0..m {
                for i in 0..n {
                    for j in 0..l {
                        let direction = d * l + j;
                        rows_of_values.push(if direction < len {
                            (b.start + direction * n + i) as u32
                        } else {
                            NO_SAMPLE
                        });
                    }
                }
            }
        }
        let mut terms = rows.in_rows(rows_of_values.into_iter());
        if terms.term == Term::Square {
            for ((a, gy), s) in terms.a.iter_mut().zip(&mut terms.gy).zip(&terms.sqrt_w) {
                *a *= s;
                *gy *= s;
            }
        }
        let square32 =
            (terms.term == Term::Square && !matches!(kind, LaneKind::F64x4)).then(|| {
                let f32s = |v: &mut Vec<f64>| std::mem::take(v).iter().map(|&x| x as f32).collect();
                (f32s(&mut terms.a), f32s(&mut terms.gy))
            });
        let widest = blocks.iter().map(|b| b.n * b.dirs.len().div_ceil(l)).max();
        LaneDirs {
            dirs,
            at,
            values_at,
            terms,
            square32,
            scratch_len: model.scratch_len(widest.unwrap_or(0)),
        }
    }
}

/// Each direction's slots of μi and μo among the distinct polar cosines of `dirs`, a block
/// ([`LaneDir::mu_slots`]): one numbering for both, in order of first appearance.
fn mu_slots(dirs: &[Dir]) -> Vec<[u32; 2]> {
    let mut slot_of = std::collections::HashMap::new();
    let mut slot = |mu: f64| {
        let next = slot_of.len() as u32;
        *slot_of.entry(mu.to_bits()).or_insert(next)
    };
    dirs.iter()
        .map(|(wi, wo)| [slot(wi.z), slot(wo.z)])
        .collect()
}

/// The lane buffers of a worker's [`Scratch`] for one lane type.
trait LaneScratch: LaneReal {
    fn buffers(s: &mut Scratch) -> (&mut Vec<Self>, &mut Vec<Self>);
}
impl LaneScratch for F32x8 {
    fn buffers(s: &mut Scratch) -> (&mut Vec<Self>, &mut Vec<Self>) {
        (&mut s.out32, &mut s.children32)
    }
}
impl LaneScratch for F32x16 {
    fn buffers(s: &mut Scratch) -> (&mut Vec<Self>, &mut Vec<Self>) {
        (&mut s.out16, &mut s.children16)
    }
}
impl LaneScratch for F64x4 {
    fn buffers(s: &mut Scratch) -> (&mut Vec<Self>, &mut Vec<Self>) {
        (&mut s.out64, &mut s.children64)
    }
}

impl<'a> Part<'a> {
    /// [`Self::blocks_in_reference`] in lanes: each block's lane-directions through
    /// [`Node::eval_lanes`](crate::bsdf::Node::eval_lanes), its values widened to f64
    /// in row order (`f(first row, values)`).
    #[inline(always)]
    pub(super) fn blocks_in_lanes(
        &self,
        lanes: &LaneDirs,
        blocks: Range<usize>,
        scratch: &mut Scratch,
        mut f: impl FnMut(usize, &[f64]),
    ) {
        let mut rows = InRows(&mut f);
        match &lanes.dirs {
            LaneVec::F32x8(dirs) => self.blocks_in(dirs, lanes, blocks, scratch, &mut rows),
            LaneVec::F32x16(dirs) => self.blocks_in(dirs, lanes, blocks, scratch, &mut rows),
            LaneVec::F64x4(dirs) => self.blocks_in(dirs, lanes, blocks, scratch, &mut rows),
        }
    }

    /// Each block's values in lanes, handed to `sink` as they leave the kernel (inside
    /// the function compiled for the vector extensions, so the sink's loop is too).
    #[inline(always)]
    fn blocks_in<R: LaneScratch>(
        &self,
        lane_dirs: &[LaneDir<R>],
        lanes: &LaneDirs,
        blocks: Range<usize>,
        scratch: &mut Scratch,
        sink: &mut impl BlockSink,
    ) {
        let model = self.problem.model;
        let stride = model.scalar_count();
        let l = R::LANES;
        let views = std::mem::take(&mut scratch.views);
        let mut out = std::mem::take(&mut scratch.out);
        for (k, b) in blocks.clone().zip(&self.blocks[blocks]) {
            let (n, len) = (b.n, b.dirs.len());
            let m = len.div_ceil(l);
            let first = lanes.at[k];
            let (values, children) = R::buffers(scratch);
            values.resize(n * m, R::zero());
            if children.len() < lanes.scratch_len {
                children.resize(lanes.scratch_len, R::zero());
            }
            let p = Channels::new(&views, stride, &self.group[b.start..b.start + b.n]);
            model.root.eval_lanes(
                p,
                &lane_dirs[first..first + m],
                &mut values[..n * m],
                children,
            );
            let values = &values[..n * m];
            vectorized(
                #[inline(always)]
                || sink.block(b, lanes.values_at[k], values, &mut out),
            );
        }
        scratch.views = views;
        scratch.out = out;
    }

    /// [`Self::cost_sum`] of the SIMD engine: the terms in lane order (constants laid
    /// out so at prepare time, padding lanes 0), taken straight from the lane values
    /// (widened in registers, never stored as f64), summed in [`SPLIT`] interleaved
    /// partial sums, so that the additions do not wait on one another (one running sum
    /// costs an addition's latency per row, more than the model's lanes take). The
    /// reference keeps one sum in row order.
    pub(super) fn cost_sum_split(
        &self,
        lanes: &LaneDirs,
        w: &Window,
        scratch: &mut Scratch,
    ) -> f64 {
        let t = &lanes.terms;
        let (blocks, t_w) = (w.blocks.clone(), &t.w[..]);
        match t.term {
            Term::Square if lanes.square32.is_some() => {
                let (a, gy) = lanes.square32.as_ref().expect("matched");
                let mut sum = SquareSum32 {
                    acc: [0.0; SPLIT],
                    a,
                    gy,
                };
                match &lanes.dirs {
                    LaneVec::F32x8(d) => self.blocks_in(d, lanes, blocks, scratch, &mut sum),
                    LaneVec::F32x16(d) => self.blocks_in(d, lanes, blocks, scratch, &mut sum),
                    LaneVec::F64x4(_) => unreachable!("f64 lanes keep the f64 terms"),
                }
                sum.acc.iter().sum()
            }
            // a and gy hold √w·a and √w·g(y) here (LaneDirs::terms).
            Term::Square => {
                self.sum_in_lanes(lanes, blocks, scratch, [&t.a, &t.gy], |v, [a, gy]| {
                    let d = a * v - gy;
                    d * d
                })
            }
            Term::LogSquare => self.sum_in_lanes(
                lanes,
                blocks,
                scratch,
                [&t.a, &t.gy, t_w],
                |v, [a, gy, w]| {
                    let d = (a * v).ln_1p() - gy;
                    w * d * d
                },
            ),
            Term::AbsRatio => {
                self.sum_in_lanes(lanes, blocks, scratch, [&t.y, t_w], |v, [y, w]| {
                    w * (v - y).abs() / (v.abs() + y.abs() + EPS)
                })
            }
        }
    }

    /// Σ `term(value, constants)` over the blocks' values in lane order, the constants
    /// the entries of `cols` (lane order too) at each value ([`SplitSum`]).
    #[inline(always)]
    fn sum_in_lanes<const N: usize>(
        &self,
        lanes: &LaneDirs,
        blocks: Range<usize>,
        scratch: &mut Scratch,
        cols: [&[f64]; N],
        term: impl Fn(f64, [f64; N]) -> f64 + Copy,
    ) -> f64 {
        let mut sum = SplitSum {
            acc: [0.0; SPLIT],
            cols,
            term,
        };
        match &lanes.dirs {
            LaneVec::F32x8(dirs) => self.blocks_in(dirs, lanes, blocks, scratch, &mut sum),
            LaneVec::F32x16(dirs) => self.blocks_in(dirs, lanes, blocks, scratch, &mut sum),
            LaneVec::F64x4(dirs) => self.blocks_in(dirs, lanes, blocks, scratch, &mut sum),
        }
        sum.acc.iter().sum()
    }
}

/// What [`Part::blocks_in`] does with each block's lane values: `values[d · n + i]` is
/// lane-direction d, channel i of `block`, whose first value in lane order is
/// `lane_start`; `out` is room for the block's values as f64.
trait BlockSink {
    fn block<R: Real>(
        &mut self,
        block: &Block,
        lane_start: usize,
        values: &[R],
        out: &mut Vec<f64>,
    );
}

/// The values widened to f64 in row order, for a caller's `f(first row, values)`.
struct InRows<'f, F>(&'f mut F);

impl<F: FnMut(usize, &[f64])> BlockSink for InRows<'_, F> {
    #[inline(always)]
    fn block<R: Real>(&mut self, b: &Block, _: usize, values: &[R], out: &mut Vec<f64>) {
        let (n, len, l) = (b.n, b.dirs.len(), R::LANES);
        if out.len() < n * len {
            out.resize(n * len, 0.0);
        }
        let out = &mut out[..n * len];
        // Row (d·L + j)·n + i is lane j of values[d·n + i].
        for (d, o) in out.chunks_mut(n * l).enumerate() {
            let count = o.len() / n;
            for i in 0..n {
                values[d * n + i].store_f64(&mut o[i..], n, count);
            }
        }
        (self.0)(b.start, out);
    }
}

/// Partial sums of the SIMD engine's loss ([`Part::cost_sum_split`]).
const SPLIT: usize = 16;

/// Lane values summed in f32 between two additions to the f64 sums of [`SquareSum32`]:
/// each f32 partial sum then holds at most 64 terms, 64 ε of relative error at worst.
const F32_RUN: usize = 64;

/// [`SplitSum`] of a squared term (√w a y′ − √w g(y))² in f32 lanes: the residual and
/// its square in f32 with partial sums of [`F32_RUN`] lane values, widened to f64 only
/// there. Widening every value first took three times the instructions (a seventh of
/// `ggx`'s time). The residual's f32 rounding is of the order of the f32 model value's
/// own, so the sum keeps the engine's accuracy (`REL_COST` of the parity tests).
struct SquareSum32<'c> {
    acc: [f64; SPLIT],
    a: &'c [f32],
    gy: &'c [f32],
}

impl BlockSink for SquareSum32<'_> {
    #[inline(always)]
    fn block<R: Real>(&mut self, _: &Block, start: usize, values: &[R], _: &mut Vec<f64>) {
        let l = R::LANES;
        let end = start + values.len() * l;
        let (a, gy) = (&self.a[start..end], &self.gy[start..end]);
        for (r, run) in values.chunks(F32_RUN).enumerate() {
            let mut part = [0f32; SPLIT];
            for (s, chunk) in run.chunks(SPLIT / l).enumerate() {
                let at = (r * F32_RUN + s * (SPLIT / l)) * l;
                let (a, gy) = (&a[at..at + chunk.len() * l], &gy[at..at + chunk.len() * l]);
                for (u, v) in chunk.iter().enumerate() {
                    for j in 0..l {
                        let d = a[u * l + j] * v.lane(j) as f32 - gy[u * l + j];
                        part[u * l + j] += d * d;
                    }
                }
            }
            for (acc, p) in self.acc.iter_mut().zip(part) {
                *acc += p as f64;
            }
        }
    }
}

/// Σ `term(value, constants)` of each value in lane order (its entry of each column of
/// `cols` the constants), value k of a block into `acc[k mod SPLIT]`: with eight lanes,
/// lane j into `acc[j]`, so each lane value is widened and summed in registers.
struct SplitSum<'c, const N: usize, T> {
    acc: [f64; SPLIT],
    cols: [&'c [f64]; N],
    term: T,
}

impl<const N: usize, T: Fn(f64, [f64; N]) -> f64> BlockSink for SplitSum<'_, N, T> {
    #[inline(always)]
    fn block<R: Real>(&mut self, _: &Block, start: usize, values: &[R], _: &mut Vec<f64>) {
        let l = R::LANES;
        let cols = self.cols.map(|c| &c[start..start + values.len() * l]);
        let mut sums = self.acc;
        // SPLIT / l lane values a step, each lane into a sum of its own.
        for (s, chunk) in values.chunks(SPLIT / l).enumerate() {
            let at = s * SPLIT;
            let c = cols.map(|c| &c[at..at + chunk.len() * l]);
            for (u, v) in chunk.iter().enumerate() {
                for j in 0..l {
                    sums[u * l + j] += (self.term)(v.lane(j), c.map(|c| c[u * l + j]));
                }
            }
        }
        self.acc = sums;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// [`SquareSum32`] in eight and sixteen lanes (sixteen run in the SIMD engine only on
    /// AVX-512 hardware) against the same terms summed in f64, over two blocks of several
    /// f32 runs each and a partial one: within 1e-5 relative (32 f32 terms a partial sum).
    #[test]
    fn the_f32_squared_term_sums_every_lane_value() {
        fn check<R: Real>() {
            let (count, l) = (300, R::LANES);
            let a: Vec<f32> = (0..count * l).map(|k| 0.5 + (k % 7) as f32 * 0.1).collect();
            let gy: Vec<f32> = (0..count * l).map(|k| (k % 13) as f32 * 0.3).collect();
            let values: Vec<R> = (0..count)
                .map(|u| R::from_fn(|j| ((u * l + j) % 11) as f64 * 0.25))
                .collect();
            let want: f64 = (0..count * l)
                .map(|k| {
                    let v = values[k / l].lane(k % l);
                    (a[k] as f64 * v - gy[k] as f64).powi(2)
                })
                .sum();
            let mut sum = SquareSum32 {
                acc: [0.0; SPLIT],
                a: &a,
                gy: &gy,
            };
            let block = Block {
                dirs: 0..0,
                start: 0,
                n: 1,
            };
            let split = 137;
            sum.block(&block, 0, &values[..split], &mut Vec::new());
            sum.block(&block, split * l, &values[split..], &mut Vec::new());
            let got: f64 = sum.acc.iter().sum();
            assert!(
                (got - want).abs() <= 1e-5 * want,
                "{l} lanes: {got} against {want}"
            );
        }
        check::<F32x8>();
        check::<F32x16>();
    }
}
