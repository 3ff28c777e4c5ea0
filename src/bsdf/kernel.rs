//! One model source for two CPU engines: a node written once over a [`Real`] as a
//! [`Kernel`] is the f64 reference (`Kernel::block::<f64>`, one direction at a time) and
//! the SIMD engine (`Kernel::block::<F32x8>`, `::<F32x16>` or `::<F64x4>`: eight,
//! sixteen or four directions in the lanes of one value), as Mitsuba's Dr.Jit types or
//! pbrt-v4's `PBRT_CPU_GPU` functions serve several back ends from one text.
//!
//! A node opts in with `impl Kernel for X` and `kernel_methods!()` in its `impl Bsdf`,
//! which derives `eval`, `eval_channels` and the lane entry points from the kernel. A
//! node that does not (a model added with `eval` alone, as `tests/toy_model.rs` shows)
//! still runs on the SIMD engine: the default lane entry points unpack the lanes and
//! call its f64 `eval_channels` ([`by_reference`]).

use super::{Bsdf, Channels, Children, Dir};
use crate::math::lanes::{level, vectorized, F32x16, F32x8, F64x4, Level, Real, V3};
use glam::DVec3;

/// A direction pair (ωi, ωo) in lanes.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub struct LaneDir<R> {
    pub wi: V3<R>,
    pub wo: V3<R>,
    /// Where the SIMD engine lays out a block: the slots of μi = ωi.z and μo = ωo.z among
    /// the block's distinct polar cosines (exact small integers; equal cosines, equal
    /// slots), for per-block tables of factors of μ alone ([`SlotMemo`]); −1 where there
    /// are none (the f64 reference, a direction at a time).
    pub mu_slots: [R; 2],
}

impl<R: Real> LaneDir<R> {
    /// A direction pair without μ slots.
    pub fn new(wi: V3<R>, wo: V3<R>) -> Self {
        LaneDir {
            wi,
            wo,
            mu_slots: [R::splat(-1.0); 2],
        }
    }
}

/// The children's values for a block of m lane-directions × n channels: child k at
/// lane-direction d, channel i is `values[(k · m + d) · n + i]` (the layout of
/// [`Children`]).
#[derive(Clone, Copy, Debug)]
pub struct LaneChildren<'a, R> {
    values: &'a [R],
    m: usize,
    n: usize,
}

impl<'a, R: Real> LaneChildren<'a, R> {
    pub fn new(values: &'a [R], m: usize, n: usize) -> Self {
        LaneChildren { values, m, n }
    }
    /// Child k's values at lane-direction d, one per channel.
    #[inline(always)]
    pub fn at(&self, k: usize, d: usize) -> &'a [R] {
        let at = (k * self.m + d) * self.n;
        &self.values[at..at + self.n]
    }
}

/// A node's evaluation written once over the number type.
pub trait Kernel: Bsdf {
    /// Whether the node needs f64 lanes (its f32 form loses what data can see); a model
    /// with one such node runs in [`F64x4`] on the SIMD engine.
    const F64_LANES: bool = false;
    /// Whether the node's f32 kernel runs faster in eight lanes than in sixteen: one
    /// whose cost is in per-lane work that wider lanes share less (a memo that hits only
    /// when every lane repeats its argument, a series run until its slowest lane has
    /// converged). A model with one such node runs in eight f32 lanes everywhere.
    const NARROW_LANES: bool = false;
    /// The n = `p.len()` channels at every lane-direction of `dirs`: `out[d · n + i]`
    /// receives lane-direction d, channel i; `children` holds the children's values the
    /// same way. Per lane, the value [`Bsdf::eval`] gives (for R = f64 it *is* `eval`).
    fn block<R: Real>(
        &self,
        p: Channels,
        dirs: &[LaneDir<R>],
        children: LaneChildren<R>,
        out: &mut [R],
    );
}

/// A node that passes its one child's values through (the suffixes `+peraxis` and
/// `+aniso`, whose work is in the layout or in the nodes below): its kernel copies them.
pub trait PassThrough: Bsdf {}

impl<T: PassThrough> Kernel for T {
    #[inline(always)]
    fn block<R: Real>(
        &self,
        p: Channels,
        dirs: &[LaneDir<R>],
        children: LaneChildren<R>,
        out: &mut [R],
    ) {
        for (d, _, out) in lanes(dirs, p.len(), out) {
            out.copy_from_slice(children.at(0, d))
        }
    }
}

/// Which lanes a model runs in on the SIMD engine.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
pub enum LaneKind {
    /// Eight f32 lanes (the GPU engine's precision).
    F32x8,
    /// Sixteen f32 lanes (the same precision, one AVX-512 register).
    F32x16,
    /// Four f64 lanes.
    F64x4,
}

impl LaneKind {
    /// The kind as it runs on this processor: sixteen f32 lanes only where AVX-512 runs
    /// ([`level`]; else eight, two AVX registers' worth being no faster than one).
    pub fn on_this_processor(self) -> LaneKind {
        match self {
            LaneKind::F32x16 if level() != Level::Avx512 => LaneKind::F32x8,
            kind => kind,
        }
    }
}

/// [`Bsdf::eval`] of a kernel: one direction, one channel.
#[inline]
pub fn eval_one<K: Kernel>(k: &K, p: &[f64], wi: DVec3, wo: DVec3, children: &[f64]) -> f64 {
    let mut out = [0.0];
    let dirs = [LaneDir::new(wi.into(), wo.into())];
    k.block::<f64>(
        Channels::one(p),
        &dirs,
        LaneChildren::new(children, 1, 1),
        &mut out,
    );
    out[0]
}

/// [`Bsdf::eval_channels`] of a kernel: the f64 reference, a direction at a time.
#[inline]
pub fn eval_f64<K: Kernel>(k: &K, p: Channels, dirs: &[Dir], children: Children, out: &mut [f64]) {
    // The directions as V3<f64>, a stack chunk at a time.
    const CHUNK: usize = 32;
    let n = p.len();
    let m = dirs.len();
    if n == 0 || m == 0 {
        return;
    }
    if m <= CHUNK {
        let zero = V3::from(DVec3::ZERO);
        let mut lane = [LaneDir::new(zero, zero); CHUNK];
        for (l, &(wi, wo)) in lane.iter_mut().zip(dirs) {
            *l = LaneDir::new(wi.into(), wo.into());
        }
        k.block::<f64>(p, &lane[..m], LaneChildren::new(children.values, m, n), out);
    } else {
        let lane: Vec<LaneDir<f64>> = dirs
            .iter()
            .map(|&(wi, wo)| LaneDir::new(wi.into(), wo.into()))
            .collect();
        k.block::<f64>(p, &lane, LaneChildren::new(children.values, m, n), out);
    }
}

/// The lane entry points of a node without a kernel: each lane through its f64
/// `eval_channels`, rounded to the lanes' precision.
pub fn by_reference<R: Real>(
    b: &(impl Bsdf + ?Sized),
    p: Channels,
    dirs: &[LaneDir<R>],
    children: LaneChildren<R>,
    out: &mut [R],
) {
    let (n, m, l) = (p.len(), dirs.len(), R::LANES);
    let flat: Vec<Dir> = dirs
        .iter()
        .flat_map(|LaneDir { wi, wo, .. }| {
            (0..l).map(|j| {
                (
                    DVec3::new(wi.x.lane(j), wi.y.lane(j), wi.z.lane(j)),
                    DVec3::new(wo.x.lane(j), wo.y.lane(j), wo.z.lane(j)),
                )
            })
        })
        .collect();
    let nc = children.values.len() / (m * n).max(1);
    // Child k at direction D = d·L + j, channel i: (k · mL + D) · n + i.
    let mut child = vec![0.0; nc * m * l * n];
    for k in 0..nc {
        for d in 0..m {
            for i in 0..n {
                let v = children.at(k, d)[i];
                for j in 0..l {
                    child[(k * m * l + d * l + j) * n + i] = v.lane(j);
                }
            }
        }
    }
    let mut values = vec![0.0; m * l * n];
    b.eval_channels(p, &flat, Children::new(&child, m * l, n), &mut values);
    for d in 0..m {
        for i in 0..n {
            out[d * n + i] = R::from_fn(|j| values[(d * l + j) * n + i]);
        }
    }
}

/// The `eval`, `eval_channels` and lane entry points of a [`Bsdf`] that implements
/// [`Kernel`]: put `super::kernel::kernel_methods!();` in its `impl Bsdf` block. (A
/// model defined outside the crate, as `tests/toy_model.rs`'s, implements `eval` and
/// gets the per-lane fallback.)
macro_rules! kernel_methods {
    () => {
        fn eval(&self, p: &[f64], wi: glam::DVec3, wo: glam::DVec3, children: &[f64]) -> f64 {
            $crate::bsdf::kernel::eval_one(self, p, wi, wo, children)
        }
        fn eval_channels(
            &self,
            p: $crate::bsdf::Channels,
            dirs: &[$crate::bsdf::Dir],
            children: $crate::bsdf::Children,
            out: &mut [f64],
        ) {
            $crate::bsdf::kernel::eval_f64(self, p, dirs, children, out)
        }
        fn eval_f32x8(
            &self,
            p: $crate::bsdf::Channels,
            dirs: &[$crate::bsdf::kernel::LaneDir<$crate::math::lanes::F32x8>],
            children: $crate::bsdf::kernel::LaneChildren<$crate::math::lanes::F32x8>,
            out: &mut [$crate::math::lanes::F32x8],
        ) {
            $crate::bsdf::kernel::run_lanes(self, p, dirs, children, out)
        }
        fn eval_f32x16(
            &self,
            p: $crate::bsdf::Channels,
            dirs: &[$crate::bsdf::kernel::LaneDir<$crate::math::lanes::F32x16>],
            children: $crate::bsdf::kernel::LaneChildren<$crate::math::lanes::F32x16>,
            out: &mut [$crate::math::lanes::F32x16],
        ) {
            $crate::bsdf::kernel::run_lanes(self, p, dirs, children, out)
        }
        fn eval_f64x4(
            &self,
            p: $crate::bsdf::Channels,
            dirs: &[$crate::bsdf::kernel::LaneDir<$crate::math::lanes::F64x4>],
            children: $crate::bsdf::kernel::LaneChildren<$crate::math::lanes::F64x4>,
            out: &mut [$crate::math::lanes::F64x4],
        ) {
            $crate::bsdf::kernel::run_lanes(self, p, dirs, children, out)
        }
        fn lanes(&self) -> Option<$crate::bsdf::kernel::LaneKind> {
            Some(if <Self as $crate::bsdf::kernel::Kernel>::F64_LANES {
                $crate::bsdf::kernel::LaneKind::F64x4
            } else if <Self as $crate::bsdf::kernel::Kernel>::NARROW_LANES {
                $crate::bsdf::kernel::LaneKind::F32x8
            } else {
                $crate::bsdf::kernel::LaneKind::F32x16
            })
        }
    };
}

pub(crate) use kernel_methods;

/// A kernel in lanes, compiled for this processor's vector extensions: one instance of
/// `block` per instruction set, each with the kernel inlined whole, picked at run time.
/// With AVX the lanes are cast to the AVX types of the same layout
/// ([`crate::math::lanes::avx`]), whose every operation is one instruction.
#[inline]
pub fn run_lanes<K: Kernel, R: LaneReal>(
    k: &K,
    p: Channels,
    dirs: &[LaneDir<R>],
    children: LaneChildren<R>,
    out: &mut [R],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if level() == Level::Baseline {
            return k.block::<R>(p, dirs, children, out);
        }
        if R::AVX512 && level() != Level::Avx512 {
            // Sixteen lanes asked for where AVX-512 does not run (a test's choice): the
            // array form, compiled for what the processor has.
            return vectorized(
                #[inline(always)]
                || k.block::<R>(p, dirs, children, out),
            );
        }
        #[allow(clippy::let_unit_value)]
        let () = R::SAME_LAYOUT;
        // SAFETY: R and R::Reg have one size and alignment (SAME_LAYOUT), LaneDir and
        // V3 are repr(C), so the slices hold the same lanes as AVX registers.
        let (dirs, values, out) = unsafe {
            (
                std::slice::from_raw_parts(dirs.as_ptr() as *const LaneDir<R::Reg>, dirs.len()),
                std::slice::from_raw_parts(
                    children.values.as_ptr() as *const R::Reg,
                    children.values.len(),
                ),
                std::slice::from_raw_parts_mut(out.as_mut_ptr() as *mut R::Reg, out.len()),
            )
        };
        let children = LaneChildren::new(values, children.m, children.n);
        // Past the tests above, `vectorized` runs this in its AVX2 or AVX-512 function,
        // the only places the AVX types may be used (Avx16 in the AVX-512 one only).
        vectorized(
            #[inline(always)]
            || k.block::<R::Reg>(p, dirs, children, out),
        )
    }
    #[cfg(not(target_arch = "x86_64"))]
    k.block::<R>(p, dirs, children, out)
}

/// What a lane type needs besides [`Real`]: on x86-64, an AVX form of the same layout
/// ([`run_lanes`] runs kernels in it where the processor has AVX2).
#[cfg(target_arch = "x86_64")]
pub trait LaneBase: crate::math::lanes::avx::Avx {}
#[cfg(target_arch = "x86_64")]
impl<T: crate::math::lanes::avx::Avx> LaneBase for T {}
#[cfg(not(target_arch = "x86_64"))]
pub trait LaneBase: Real {}
#[cfg(not(target_arch = "x86_64"))]
impl<T: Real> LaneBase for T {}

/// A lane type a model tree can be evaluated in: calls the node's entry point for it.
pub trait LaneReal: LaneBase {
    fn eval_node(
        b: &dyn Bsdf,
        p: Channels,
        dirs: &[LaneDir<Self>],
        children: LaneChildren<Self>,
        out: &mut [Self],
    );
}

/// [`LaneReal`] of a lane type: the node's entry point of that type.
macro_rules! lane_real {
    ($($t:ty => $entry:ident),*) => {$(
        impl LaneReal for $t {
            #[inline]
            fn eval_node(
                b: &dyn Bsdf,
                p: Channels,
                dirs: &[LaneDir<Self>],
                children: LaneChildren<Self>,
                out: &mut [Self],
            ) {
                b.$entry(p, dirs, children, out)
            }
        }
    )*};
}
lane_real!(F32x8 => eval_f32x8, F32x16 => eval_f32x16, F64x4 => eval_f64x4);

/// Lane-direction d of a block with its n outputs: the loop of a [`Kernel::block`]
/// whose directions are independent (`for (d, (wi, wo), out) in lanes(dirs, n, out)`).
/// An iterator rather than a closure: kernels are compiled once per instruction set,
/// and a closure with a call site in each would be left out of line, without the
/// vector extensions.
#[inline(always)]
pub fn lanes<'a, R: Real>(
    dirs: &'a [LaneDir<R>],
    n: usize,
    out: &'a mut [R],
) -> impl Iterator<Item = (usize, (V3<R>, V3<R>), &'a mut [R])> + 'a {
    dirs.iter()
        .zip(out.chunks_exact_mut(n.max(1)))
        .enumerate()
        .map(|(d, (dir, o))| (d, (dir.wi, dir.wo), o))
}

/// A one-entry cache of a function of one value, keyed on its bits: in a block of
/// directions consecutive ones often share θi (a goniometer scans θo at a fixed θi) or
/// θo (several φo at one θo), so a factor of μi or μo alone (a Fresnel transmittance) is
/// computed once per run. Exact: the same argument gives the same value. In lanes it
/// hits when every lane repeats.
#[derive(Clone, Copy, Debug)]
pub struct Memo<R> {
    last: Option<(R, R)>,
}

impl<R: Real> Default for Memo<R> {
    fn default() -> Self {
        Memo { last: None }
    }
}

impl<R: Real> Memo<R> {
    /// f(x), from the cache when x is the previous argument. (A closure passed here is
    /// marked `#[inline(always)]`: out of line, it would be compiled without the vector
    /// extensions of the kernel that calls it.)
    #[inline(always)]
    pub fn get(&mut self, x: R, f: impl FnOnce(R) -> R) -> R {
        match self.last {
            Some((key, value)) if key.same_bits(x) => value,
            _ => {
                let value = f(x);
                self.last = Some((x, value));
                value
            }
        }
    }
}

/// A table of a function of μ alone over one block of lane-directions, keyed by the
/// engine's μ slots ([`LaneDir::mu_slots`]): each distinct μ of the block is computed
/// once, where a [`Memo`] recomputes whenever any lane's μ differs from the last
/// lane-direction's (in sixteen lanes, nearly always: the lanes span several θo). A
/// value is computed in lanes with the others of its lane-direction, each lane's
/// arithmetic its own, so the table's values are the memo's bit for bit. Without slots
/// (the f64 reference) it is a [`Memo`].
#[derive(Clone, Debug)]
pub struct SlotMemo<R> {
    values: Vec<f64>,
    memo: Memo<R>,
}

impl<R: Real> Default for SlotMemo<R> {
    fn default() -> Self {
        SlotMemo {
            values: Vec::new(),
            memo: Memo::default(),
        }
    }
}

impl<R: Real> SlotMemo<R> {
    /// f(x) where x is the lanes' μ and `slot` their slots.
    #[inline(always)]
    pub fn get(&mut self, slot: R, x: R, f: impl FnOnce(R) -> R) -> R {
        // The one-entry memo first: a hit costs one comparison, the table a load per lane.
        match self.memo.last {
            Some((key, value)) if key.same_bits(x) => return value,
            _ if slot.lane(0) < 0.0 => return self.memo.get(x, f),
            _ => {}
        }
        let value = self.tabulated(slot, x, f);
        self.memo.last = Some((x, value));
        value
    }

    /// f(x) from the table, the lanes it lacks computed and added.
    #[inline(always)]
    fn tabulated(&mut self, slot: R, x: R, f: impl FnOnce(R) -> R) -> R {
        let mut at = [0.0; 16];
        slot.store_all_f64(&mut at[..R::LANES]);
        let mut miss = false;
        let values = &self.values;
        let v = R::from_fn(|j| match values.get(at[j] as usize) {
            Some(&v) if !v.is_nan() => v,
            _ => {
                miss = true;
                0.0
            }
        });
        if !miss {
            return v;
        }
        let fresh = f(x);
        for (j, &s) in at[..R::LANES].iter().enumerate() {
            let s = s as usize;
            if s >= self.values.len() {
                self.values.resize(s + 1, f64::NAN);
            }
            self.values[s] = fresh.lane(j);
        }
        fresh
    }
}
