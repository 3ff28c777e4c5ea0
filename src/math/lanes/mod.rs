//! Numbers a model is written over once: `f64` for the reference, and SIMD lanes of
//! several directions at a time for the SIMD CPU engine ([`F32x8`], [`F32x16`],
//! [`F64x4`]).
//!
//! **Why plain arrays.** A lane type is an array with element-wise operations marked
//! `#[inline(always)]`; [`vectorized`] runs a kernel inside a function compiled for the
//! processor's vector extensions (AVX-512, AVX2 + FMA, or the baseline: SSE2 on x86-64,
//! NEON on aarch64), chosen at run time, and LLVM turns each array operation into one
//! vector instruction of that width. So one binary serves every machine, and the model
//! source is ordinary arithmetic on a type parameter, the same text as the f64
//! reference. The crates considered do not give both: `wide` picks its instructions
//! when the crate is compiled (SSE2 pairs in a portable build, whatever the machine
//! runs), `pulp` dispatches at run time but writes each operation as a method of its
//! token (`simd.mul_f32s(a, b)`), so the model source could not be the reference's, and
//! `std::simd` is not stable.
//!
//! **Equality with the reference.** The `f64` implementation is the scalar operations
//! themselves (`select` is `if`), so a model written over [`Real`] and instantiated for
//! f64 computes what its hand-written scalar form computed, bit for bit, when it keeps
//! the same operations in the same order; [`V3`] does glam's vector operations in
//! glam's order.

use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// The AVX forms of the lane types.
#[cfg(target_arch = "x86_64")]
pub mod avx;

/// A number, or a vector of numbers evaluated in lanes.
pub trait Real:
    Copy
    + Send
    + Sync
    + std::fmt::Debug
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + 'static
{
    /// One truth value per lane.
    type Mask: Copy
        + BitAnd<Output = Self::Mask>
        + BitOr<Output = Self::Mask>
        + Not<Output = Self::Mask>;
    /// How many numbers one value holds.
    const LANES: usize;
    /// Whether the lanes hold f64 (the reference's arithmetic, which f64 lanes must
    /// reproduce bit for bit: a shortcut exact only to rounding is for f32 lanes alone).
    const F64: bool;
    /// Every lane `x` (rounded to the lane's precision).
    fn splat(x: f64) -> Self;
    /// Lane i as f64.
    fn lane(self, i: usize) -> f64;
    /// A value from its lanes.
    fn from_fn(f: impl FnMut(usize) -> f64) -> Self;
    fn sqrt(self) -> Self;
    fn abs(self) -> Self;
    /// `f64::min` per lane (a NaN argument gives the other).
    fn min(self, o: Self) -> Self;
    fn max(self, o: Self) -> Self;
    /// `f64::clamp` per lane.
    fn clamp(self, lo: f64, hi: f64) -> Self;
    fn exp(self) -> Self;
    fn ln(self) -> Self;
    fn acos(self) -> Self;
    fn exp_m1(self) -> Self;
    /// x^e per lane (`f64::powf`).
    fn powf(self, e: f64) -> Self;
    fn lt(self, o: Self) -> Self::Mask;
    fn le(self, o: Self) -> Self::Mask;
    /// Per lane: `a` where `m` holds, else `b`.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    /// Whether `m` holds in any lane.
    fn any(m: Self::Mask) -> bool;
    /// Lanes bit for bit equal to `o`'s (a memo's key).
    fn same_bits(self, o: Self) -> bool;
    /// self · a + b. Fused (one rounding, one instruction) in the f32 AVX lanes; else
    /// self * a + b rounded twice, so the reference and the f64 lanes keep their
    /// operations bit for bit where a model writes `x * y + z` as `x.mul_add(y, z)`.
    #[inline(always)]
    fn mul_add(self, a: Self, b: Self) -> Self {
        self * a + b
    }
    /// Every lane as f64 into `out[..LANES]`.
    #[inline(always)]
    fn store_all_f64(&self, out: &mut [f64]) {
        self.store_f64(out, 1, Self::LANES);
    }
    /// Lanes 0..count as f64 into `out[j · stride]`.
    #[inline(always)]
    fn store_f64(&self, out: &mut [f64], stride: usize, count: usize) {
        for j in 0..count {
            out[j * stride] = self.lane(j);
        }
    }

    #[inline(always)]
    fn gt(self, o: Self) -> Self::Mask {
        o.lt(self)
    }
    #[inline(always)]
    fn ge(self, o: Self) -> Self::Mask {
        o.le(self)
    }
    #[inline(always)]
    fn zero() -> Self {
        Self::splat(0.0)
    }
}

impl Real for f64 {
    type Mask = bool;
    const LANES: usize = 1;
    const F64: bool = true;
    #[inline(always)]
    fn splat(x: f64) -> f64 {
        x
    }
    #[inline(always)]
    fn lane(self, _: usize) -> f64 {
        self
    }
    #[inline(always)]
    fn from_fn(mut f: impl FnMut(usize) -> f64) -> f64 {
        f(0)
    }
    #[inline(always)]
    fn sqrt(self) -> f64 {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn abs(self) -> f64 {
        f64::abs(self)
    }
    #[inline(always)]
    fn min(self, o: f64) -> f64 {
        f64::min(self, o)
    }
    #[inline(always)]
    fn max(self, o: f64) -> f64 {
        f64::max(self, o)
    }
    #[inline(always)]
    fn clamp(self, lo: f64, hi: f64) -> f64 {
        f64::clamp(self, lo, hi)
    }
    #[inline(always)]
    fn exp(self) -> f64 {
        f64::exp(self)
    }
    #[inline(always)]
    fn ln(self) -> f64 {
        f64::ln(self)
    }
    #[inline(always)]
    fn acos(self) -> f64 {
        f64::acos(self)
    }
    #[inline(always)]
    fn exp_m1(self) -> f64 {
        f64::exp_m1(self)
    }
    #[inline(always)]
    fn powf(self, e: f64) -> f64 {
        f64::powf(self, e)
    }
    #[inline(always)]
    fn lt(self, o: f64) -> bool {
        self < o
    }
    #[inline(always)]
    fn le(self, o: f64) -> bool {
        self <= o
    }
    #[inline(always)]
    fn select(m: bool, a: f64, b: f64) -> f64 {
        if m {
            a
        } else {
            b
        }
    }
    #[inline(always)]
    fn any(m: bool) -> bool {
        m
    }
    #[inline(always)]
    fn same_bits(self, o: f64) -> bool {
        self.to_bits() == o.to_bits()
    }
}

/// Per-lane truth values of an N-lane type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Lanes<const N: usize>(pub [bool; N]);

impl<const N: usize> BitAnd for Lanes<N> {
    type Output = Self;
    #[inline(always)]
    fn bitand(self, o: Self) -> Self {
        Lanes(std::array::from_fn(|i| self.0[i] & o.0[i]))
    }
}
impl<const N: usize> BitOr for Lanes<N> {
    type Output = Self;
    #[inline(always)]
    fn bitor(self, o: Self) -> Self {
        Lanes(std::array::from_fn(|i| self.0[i] | o.0[i]))
    }
}
impl<const N: usize> Not for Lanes<N> {
    type Output = Self;
    #[inline(always)]
    fn not(self) -> Self {
        Lanes(std::array::from_fn(|i| !self.0[i]))
    }
}

/// Defines an array lane type of `$n` × `$t` with [`Real`].
macro_rules! lane_type {
    ($(#[$doc:meta])* $name:ident, $t:ty, $n:literal, align $align:literal) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq)]
        #[repr(C, align($align))]
        pub struct $name(pub [$t; $n]);

        impl $name {
            #[inline(always)]
            fn map(self, f: impl Fn($t) -> $t) -> Self {
                $name(std::array::from_fn(|i| f(self.0[i])))
            }
            #[inline(always)]
            fn zip(self, o: Self, f: impl Fn($t, $t) -> $t) -> Self {
                $name(std::array::from_fn(|i| f(self.0[i], o.0[i])))
            }
            #[inline(always)]
            fn test(self, o: Self, f: impl Fn($t, $t) -> bool) -> Lanes<$n> {
                Lanes(std::array::from_fn(|i| f(self.0[i], o.0[i])))
            }
        }
        impl Add for $name {
            type Output = Self;
            #[inline(always)]
            fn add(self, o: Self) -> Self {
                self.zip(o, |a, b| a + b)
            }
        }
        impl Sub for $name {
            type Output = Self;
            #[inline(always)]
            fn sub(self, o: Self) -> Self {
                self.zip(o, |a, b| a - b)
            }
        }
        impl Mul for $name {
            type Output = Self;
            #[inline(always)]
            fn mul(self, o: Self) -> Self {
                self.zip(o, |a, b| a * b)
            }
        }
        impl Div for $name {
            type Output = Self;
            #[inline(always)]
            fn div(self, o: Self) -> Self {
                self.zip(o, |a, b| a / b)
            }
        }
        impl Neg for $name {
            type Output = Self;
            #[inline(always)]
            fn neg(self) -> Self {
                self.map(|a| -a)
            }
        }
        impl Real for $name {
            type Mask = Lanes<$n>;
            const LANES: usize = $n;
            const F64: bool = std::mem::size_of::<$t>() == 8;
            #[inline(always)]
            fn splat(x: f64) -> Self {
                $name([x as $t; $n])
            }
            #[inline(always)]
            fn lane(self, i: usize) -> f64 {
                self.0[i] as f64
            }
            #[inline(always)]
            fn from_fn(mut f: impl FnMut(usize) -> f64) -> Self {
                $name(std::array::from_fn(|i| f(i) as $t))
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                self.map(<$t>::sqrt)
            }
            #[inline(always)]
            fn abs(self) -> Self {
                self.map(<$t>::abs)
            }
            #[inline(always)]
            fn min(self, o: Self) -> Self {
                self.zip(o, <$t>::min)
            }
            #[inline(always)]
            fn max(self, o: Self) -> Self {
                self.zip(o, <$t>::max)
            }
            #[inline(always)]
            fn clamp(self, lo: f64, hi: f64) -> Self {
                let (lo, hi) = (lo as $t, hi as $t);
                // Branch-free (a NaN lane gives lo, where f64::clamp passes NaN on).
                self.map(|x| x.max(lo).min(hi))
            }
            #[inline(always)]
            fn exp(self) -> Self {
                self.map(<$t>::exp)
            }
            #[inline(always)]
            fn ln(self) -> Self {
                self.map(<$t>::ln)
            }
            #[inline(always)]
            fn acos(self) -> Self {
                self.map(<$t>::acos)
            }
            #[inline(always)]
            fn exp_m1(self) -> Self {
                self.map(<$t>::exp_m1)
            }
            #[inline(always)]
            fn powf(self, e: f64) -> Self {
                let e = e as $t;
                self.map(|x| x.powf(e))
            }
            #[inline(always)]
            fn lt(self, o: Self) -> Lanes<$n> {
                self.test(o, |a, b| a < b)
            }
            #[inline(always)]
            fn le(self, o: Self) -> Lanes<$n> {
                self.test(o, |a, b| a <= b)
            }
            #[inline(always)]
            fn select(m: Lanes<$n>, a: Self, b: Self) -> Self {
                $name(std::array::from_fn(|i| if m.0[i] { a.0[i] } else { b.0[i] }))
            }
            #[inline(always)]
            fn any(m: Lanes<$n>) -> bool {
                m.0.iter().fold(false, |a, &b| a | b)
            }
            #[inline(always)]
            fn same_bits(self, o: Self) -> bool {
                (0..$n).fold(true, |a, i| a & (self.0[i].to_bits() == o.0[i].to_bits()))
            }
            #[inline(always)]
            fn store_f64(&self, out: &mut [f64], stride: usize, count: usize) {
                for (o, &x) in out.iter_mut().step_by(stride).zip(&self.0[..count]) {
                    *o = x as f64;
                }
            }
            #[inline(always)]
            fn store_all_f64(&self, out: &mut [f64]) {
                for (o, &x) in out[..$n].iter_mut().zip(&self.0) {
                    *o = x as f64;
                }
            }
        }
    };
}

lane_type!(
    /// Eight f32 lanes: one AVX register, two SSE or NEON registers.
    F32x8,
    f32,
    8,
    align 32
);
lane_type!(
    /// Sixteen f32 lanes: one AVX-512 register (the SIMD engine's f32 lanes where the
    /// processor has AVX-512).
    F32x16,
    f32,
    16,
    align 64
);
lane_type!(
    /// Four f64 lanes, for models whose f32 form loses what the data can see.
    F64x4,
    f64,
    4,
    align 32
);

/// A 3-vector of [`Real`]s: the directions of one lane-vector of direction pairs.
#[derive(Clone, Copy, Debug)]
#[repr(C)]
pub struct V3<R> {
    pub x: R,
    pub y: R,
    pub z: R,
}

impl<R: Real> V3<R> {
    #[inline(always)]
    pub fn new(x: R, y: R, z: R) -> Self {
        V3 { x, y, z }
    }
    /// (x·x′ + y·y′) + z·z′, glam's order (fused in f32 AVX lanes).
    #[inline(always)]
    pub fn dot(self, o: Self) -> R {
        self.z.mul_add(o.z, self.x.mul_add(o.x, self.y * o.y))
    }
    #[inline(always)]
    pub fn length(self) -> R {
        self.dot(self).sqrt()
    }
    #[inline(always)]
    pub fn scale(self, s: R) -> Self {
        V3::new(self.x * s, self.y * s, self.z * s)
    }
    /// Per lane: `a` where `m` holds, else `b`.
    #[inline(always)]
    pub fn select(m: R::Mask, a: Self, b: Self) -> Self {
        V3::new(
            R::select(m, a.x, b.x),
            R::select(m, a.y, b.y),
            R::select(m, a.z, b.z),
        )
    }
}

impl<R: Real> Add for V3<R> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        V3::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl From<V3<f64>> for glam::DVec3 {
    #[inline(always)]
    fn from(v: V3<f64>) -> Self {
        glam::DVec3::new(v.x, v.y, v.z)
    }
}

impl From<glam::DVec3> for V3<f64> {
    #[inline(always)]
    fn from(v: glam::DVec3) -> Self {
        V3::new(v.x, v.y, v.z)
    }
}

/// The instruction set [`vectorized`] compiles for on this machine, in words.
pub fn instruction_set() -> &'static str {
    level_name(level())
}

/// A level in words, as [`instruction_set`] gives it.
fn level_name(level: Level) -> &'static str {
    match level {
        Level::Avx512 => "AVX-512",
        Level::Avx2 => "AVX2+FMA",
        Level::Baseline if cfg!(target_arch = "aarch64") => "NEON",
        Level::Baseline if cfg!(target_arch = "x86_64") => "SSE2",
        Level::Baseline => "scalar",
    }
}

/// The widest vector extensions of this processor that the SIMD engine compiles for.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub enum Level {
    Avx512,
    Avx2,
    Baseline,
}

/// What this processor can run, detected once (`BSDFIT_SIMD=baseline|avx2` caps it:
/// how the other variants are tested on a machine that has more).
pub fn level() -> Level {
    static LEVEL: std::sync::OnceLock<Level> = std::sync::OnceLock::new();
    *LEVEL.get_or_init(|| {
        let cap = std::env::var("BSDFIT_SIMD").unwrap_or_default();
        #[cfg(target_arch = "x86_64")]
        {
            let avx2 = std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma");
            let avx512 = avx2
                && std::arch::is_x86_feature_detected!("avx512f")
                && std::arch::is_x86_feature_detected!("avx512vl")
                && std::arch::is_x86_feature_detected!("avx512dq")
                && std::arch::is_x86_feature_detected!("avx512bw");
            let widest = if avx512 {
                Level::Avx512
            } else if avx2 {
                Level::Avx2
            } else {
                Level::Baseline
            };
            match cap.trim() {
                "" | "avx512" => widest,
                "baseline" => Level::Baseline,
                "avx2" if avx2 => Level::Avx2,
                other => {
                    // A cap the processor cannot honour (or a misspelt one) must not pass
                    // silently for the level it asked for.
                    eprintln!(
                        "warning: BSDFIT_SIMD={other} {}: running {}",
                        if other == "avx2" {
                            "asks for AVX2, which this processor lacks"
                        } else {
                            "is not one of baseline, avx2, avx512"
                        },
                        level_name(widest)
                    );
                    widest
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = cap;
            Level::Baseline
        }
    })
}

/// Runs `f` compiled for the widest vector extensions this processor has (`f` and
/// everything it calls `#[inline(always)]` is compiled into each variant): the run-time
/// dispatch of the SIMD engine.
#[inline(always)]
pub fn vectorized<T>(f: impl FnOnce() -> T) -> T {
    #[cfg(target_arch = "x86_64")]
    {
        #[target_feature(
            enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma,bmi1,bmi2,lzcnt,popcnt"
        )]
        unsafe fn avx512<T>(f: impl FnOnce() -> T) -> T {
            f()
        }
        #[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
        unsafe fn avx2<T>(f: impl FnOnce() -> T) -> T {
            f()
        }
        match level() {
            // SAFETY: `level` found these features on this processor.
            Level::Avx512 => unsafe { avx512(f) },
            Level::Avx2 => unsafe { avx2(f) },
            Level::Baseline => f(),
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        f()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each lane operation is the scalar operation of its precision, lane by lane.
    #[test]
    fn lanes_are_the_scalar_operations() {
        let a = F32x8([0.5, -1.0, 2.0, 1e-30, f32::NAN, 3.0, 0.0, 7.5]);
        let b = F32x8([0.25, 4.0, -2.0, 1.0, 1.0, f32::NAN, 0.0, 2.5]);
        let vectorized = vectorized(|| (a / b + a * b - b).sqrt().min(a).clamp(0.0, 1.0));
        for i in 0..8 {
            // clamp in lanes is max(lo) then min(hi): a NaN lane becomes lo.
            #[allow(clippy::manual_clamp)]
            let want = ((a.0[i] / b.0[i] + a.0[i] * b.0[i] - b.0[i]).sqrt())
                .min(a.0[i])
                .max(0.0)
                .min(1.0);
            assert_eq!(vectorized.0[i].to_bits(), want.to_bits(), "lane {i}");
        }
        let m = a.lt(b);
        let s = F32x8::select(m, a, b);
        for i in 0..8 {
            assert_eq!(m.0[i], a.0[i] < b.0[i]);
            let want = if a.0[i] < b.0[i] { a.0[i] } else { b.0[i] };
            assert_eq!(s.0[i].to_bits(), want.to_bits());
        }
    }
}
