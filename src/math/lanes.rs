//! Numbers a model is written over once: `f64` for the reference, and SIMD lanes of
//! several directions at a time for the SIMD CPU engine ([`F32x8`], [`F64x4`]).
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
    ($(#[$doc:meta])* $name:ident, $t:ty, $n:literal) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq)]
        #[repr(C, align(32))]
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
    8
);
lane_type!(
    /// Four f64 lanes, for models whose f32 form loses what the data can see.
    F64x4,
    f64,
    4
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
    /// (x·x′ + y·y′) + z·z′, glam's order.
    #[inline(always)]
    pub fn dot(self, o: Self) -> R {
        self.x * o.x + self.y * o.y + self.z * o.z
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
    match level() {
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
            match cap.as_str() {
                "baseline" => Level::Baseline,
                "avx2" if avx2 => Level::Avx2,
                _ if avx512 => Level::Avx512,
                _ if avx2 => Level::Avx2,
                _ => Level::Baseline,
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

/// Lane types of the same layout as [`F32x8`] and [`F64x4`] whose operations are AVX
/// instructions: kernels run in them inside the functions compiled for AVX2 or AVX-512
/// (`bsdf::kernel::run_lanes`), where an explicit instruction per operation leaves
/// nothing to the compiler's vectorizer (which kept part of the array form scalar).
/// Never used outside such a function.
#[cfg(target_arch = "x86_64")]
pub mod avx {
    use super::{F32x8, F64x4, Lanes, Real};
    use std::arch::x86_64::*;
    use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

    /// A comparison's result: every bit of a lane set where it holds.
    macro_rules! avx_type {
        ($name:ident, $mask:ident, $reg:ty, $t:ty, $n:literal, $array:ident,
         add $add:ident, sub $sub:ident, mul $mul:ident, div $div:ident, sqrt $sqrt:ident,
         min $min:ident, max $max:ident, set1 $set1:ident, cmp $cmp:ident,
         blend $blend:ident, and $and:ident, or $or:ident, xor $xor:ident,
         andnot $andnot:ident, movemask $movemask:ident, full $full:literal,
         exp $exp:ident, exp_m1 $exp_m1:ident) => {
            #[derive(Clone, Copy, Debug)]
            #[repr(transparent)]
            pub struct $name(pub $reg);
            #[derive(Clone, Copy, Debug)]
            #[repr(transparent)]
            pub struct $mask(pub $reg);

            // SAFETY (every `unsafe` below): these types exist only inside functions
            // compiled with AVX2 (see the module's comment); the operations are the
            // intrinsics of that extension on registers of the right type.
            impl BitAnd for $mask {
                type Output = Self;
                #[inline(always)]
                fn bitand(self, o: Self) -> Self {
                    unsafe { $mask($and(self.0, o.0)) }
                }
            }
            impl BitOr for $mask {
                type Output = Self;
                #[inline(always)]
                fn bitor(self, o: Self) -> Self {
                    unsafe { $mask($or(self.0, o.0)) }
                }
            }
            impl Not for $mask {
                type Output = Self;
                #[inline(always)]
                fn not(self) -> Self {
                    unsafe { $mask($xor(self.0, $cmp::<_CMP_EQ_UQ>(self.0, self.0))) }
                }
            }
            impl Add for $name {
                type Output = Self;
                #[inline(always)]
                fn add(self, o: Self) -> Self {
                    unsafe { $name($add(self.0, o.0)) }
                }
            }
            impl Sub for $name {
                type Output = Self;
                #[inline(always)]
                fn sub(self, o: Self) -> Self {
                    unsafe { $name($sub(self.0, o.0)) }
                }
            }
            impl Mul for $name {
                type Output = Self;
                #[inline(always)]
                fn mul(self, o: Self) -> Self {
                    unsafe { $name($mul(self.0, o.0)) }
                }
            }
            impl Div for $name {
                type Output = Self;
                #[inline(always)]
                fn div(self, o: Self) -> Self {
                    unsafe { $name($div(self.0, o.0)) }
                }
            }
            impl Neg for $name {
                type Output = Self;
                #[inline(always)]
                fn neg(self) -> Self {
                    unsafe { $name($xor(self.0, $set1(-0.0))) }
                }
            }
            impl $name {
                #[inline(always)]
                fn array(self) -> $array {
                    // SAFETY: same size and layout.
                    unsafe { std::mem::transmute::<$reg, $array>(self.0) }
                }
                #[inline(always)]
                fn from_array(a: $array) -> Self {
                    // SAFETY: same size and layout.
                    $name(unsafe { std::mem::transmute::<$array, $reg>(a) })
                }
            }
            impl Real for $name {
                type Mask = $mask;
                const LANES: usize = $n;
                #[inline(always)]
                fn splat(x: f64) -> Self {
                    unsafe { $name($set1(x as $t)) }
                }
                #[inline(always)]
                fn lane(self, i: usize) -> f64 {
                    self.array().0[i] as f64
                }
                #[inline(always)]
                fn from_fn(f: impl FnMut(usize) -> f64) -> Self {
                    Self::from_array(<$array as Real>::from_fn(f))
                }
                #[inline(always)]
                fn sqrt(self) -> Self {
                    unsafe { $name($sqrt(self.0)) }
                }
                #[inline(always)]
                fn abs(self) -> Self {
                    unsafe { $name($andnot($set1(-0.0), self.0)) }
                }
                /// The other operand where one is NaN (as `f64::min`): minps returns its
                /// second operand where either is NaN, and self where that one is.
                #[inline(always)]
                fn min(self, o: Self) -> Self {
                    unsafe {
                        let m = $min(self.0, o.0);
                        let nan = $cmp::<_CMP_UNORD_Q>(o.0, o.0);
                        $name($blend(m, self.0, nan))
                    }
                }
                #[inline(always)]
                fn max(self, o: Self) -> Self {
                    unsafe {
                        let m = $max(self.0, o.0);
                        let nan = $cmp::<_CMP_UNORD_Q>(o.0, o.0);
                        $name($blend(m, self.0, nan))
                    }
                }
                #[inline(always)]
                fn clamp(self, lo: f64, hi: f64) -> Self {
                    unsafe { $name($min($max(self.0, $set1(lo as $t)), $set1(hi as $t))) }
                }
                #[inline(always)]
                fn exp(self) -> Self {
                    $name($exp(self.0))
                }
                #[inline(always)]
                fn ln(self) -> Self {
                    Self::from_array(self.array().ln())
                }
                #[inline(always)]
                fn acos(self) -> Self {
                    Self::from_array(self.array().acos())
                }
                #[inline(always)]
                fn exp_m1(self) -> Self {
                    $name($exp_m1(self.0))
                }
                #[inline(always)]
                fn powf(self, e: f64) -> Self {
                    Self::from_array(self.array().powf(e))
                }
                #[inline(always)]
                fn lt(self, o: Self) -> $mask {
                    unsafe { $mask($cmp::<_CMP_LT_OQ>(self.0, o.0)) }
                }
                #[inline(always)]
                fn le(self, o: Self) -> $mask {
                    unsafe { $mask($cmp::<_CMP_LE_OQ>(self.0, o.0)) }
                }
                #[inline(always)]
                fn select(m: $mask, a: Self, b: Self) -> Self {
                    unsafe { $name($blend(b.0, a.0, m.0)) }
                }
                #[inline(always)]
                fn any(m: $mask) -> bool {
                    unsafe { $movemask(m.0) != 0 }
                }
                #[inline(always)]
                fn store_f64(&self, out: &mut [f64], stride: usize, count: usize) {
                    self.array().store_f64(out, stride, count)
                }
                #[inline(always)]
                fn store_all_f64(&self, out: &mut [f64]) {
                    self.array().store_all_f64(out)
                }
                #[inline(always)]
                fn same_bits(self, o: Self) -> bool {
                    unsafe {
                        let eq = _mm256_cmpeq_epi64(
                            std::mem::transmute::<$reg, __m256i>(self.0),
                            std::mem::transmute::<$reg, __m256i>(o.0),
                        );
                        _mm256_movemask_epi8(eq) == -1
                    }
                }
            }
            impl From<$mask> for Lanes<$n> {
                fn from(m: $mask) -> Lanes<$n> {
                    let bits = unsafe { $movemask(m.0) };
                    Lanes(std::array::from_fn(|i| bits & (1 << i) != 0))
                }
            }
            const _: () = assert!($full == (1 << $n) - 1);
        };
    }

    avx_type!(Avx8, Avx8Mask, __m256, f32, 8, F32x8,
        add _mm256_add_ps, sub _mm256_sub_ps, mul _mm256_mul_ps, div _mm256_div_ps,
        sqrt _mm256_sqrt_ps, min _mm256_min_ps, max _mm256_max_ps, set1 _mm256_set1_ps,
        cmp _mm256_cmp_ps, blend _mm256_blendv_ps, and _mm256_and_ps, or _mm256_or_ps,
        xor _mm256_xor_ps, andnot _mm256_andnot_ps, movemask _mm256_movemask_ps, full 255,
        exp exp_f32, exp_m1 exp_m1_f32);
    avx_type!(Avx4d, Avx4dMask, __m256d, f64, 4, F64x4,
        add _mm256_add_pd, sub _mm256_sub_pd, mul _mm256_mul_pd, div _mm256_div_pd,
        sqrt _mm256_sqrt_pd, min _mm256_min_pd, max _mm256_max_pd, set1 _mm256_set1_pd,
        cmp _mm256_cmp_pd, blend _mm256_blendv_pd, and _mm256_and_pd, or _mm256_or_pd,
        xor _mm256_xor_pd, andnot _mm256_andnot_pd, movemask _mm256_movemask_pd, full 15,
        exp exp_f64, exp_m1 exp_m1_f64);

    /// e^x in eight f32 lanes: x = n ln 2 + r (Cody–Waite, |r| ≤ ½ ln 2), e^r by the
    /// degree-7 polynomial of Cephes' `expf`, 2^n by the exponent bits; x clamped to
    /// 88.7 above, and 0 below −87.3 (where f32's normal range ends). Relative error a few f32 ulps, where libm's per
    /// lane calls cost as much as a whole GGX evaluation.
    #[inline(always)]
    fn exp_f32(x: __m256) -> __m256 {
        // SAFETY: AVX2 instructions only, inside AVX2 functions (module comment).
        unsafe {
            // Below −87.3 the result (subnormal or 0) is returned as 0.
            let tiny = _mm256_cmp_ps::<_CMP_LT_OQ>(x, _mm256_set1_ps(-87.3));
            let x = _mm256_min_ps(
                _mm256_max_ps(x, _mm256_set1_ps(-87.3)),
                _mm256_set1_ps(88.7),
            );
            let n = _mm256_round_ps::<{ _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC }>(
                _mm256_mul_ps(x, _mm256_set1_ps(std::f32::consts::LOG2_E)),
            );
            let r = _mm256_sub_ps(x, _mm256_mul_ps(n, _mm256_set1_ps(0.693_359_4)));
            let r = _mm256_sub_ps(r, _mm256_mul_ps(n, _mm256_set1_ps(-2.121_944_4e-4)));
            let mut p = _mm256_set1_ps(1.987_569_1e-4);
            for k in [
                1.398_199_9e-3,
                8.333_452e-3,
                4.166_579_6e-2,
                0.166_666_65,
                0.5,
            ] {
                p = _mm256_add_ps(_mm256_mul_ps(p, r), _mm256_set1_ps(k));
            }
            let p = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(p, r), r), r),
                _mm256_set1_ps(1.0),
            );
            let bits = _mm256_slli_epi32::<23>(_mm256_add_epi32(
                _mm256_cvtps_epi32(n),
                _mm256_set1_epi32(127),
            ));
            _mm256_andnot_ps(tiny, _mm256_mul_ps(p, _mm256_castsi256_ps(bits)))
        }
    }

    /// e^x − 1 in eight f32 lanes without the cancellation near 0: its Taylor polynomial
    /// to x⁸/8! for |x| < ½ (truncation below 1e-8 relative), e^x − 1 beyond.
    #[inline(always)]
    fn exp_m1_f32(x: __m256) -> __m256 {
        // SAFETY: as exp_f32.
        unsafe {
            let mut p = _mm256_set1_ps(1.0 / 40320.0);
            for k in [
                1.0 / 5040.0,
                1.0 / 720.0,
                1.0 / 120.0,
                1.0 / 24.0,
                1.0 / 6.0,
                0.5,
                1.0,
            ] {
                p = _mm256_add_ps(_mm256_mul_ps(p, x), _mm256_set1_ps(k));
            }
            let small = _mm256_mul_ps(p, x);
            let large = _mm256_sub_ps(exp_f32(x), _mm256_set1_ps(1.0));
            let abs = _mm256_andnot_ps(_mm256_set1_ps(-0.0), x);
            _mm256_blendv_ps(
                large,
                small,
                _mm256_cmp_ps::<_CMP_LT_OQ>(abs, _mm256_set1_ps(0.5)),
            )
        }
    }

    /// e^x in four f64 lanes: lane by lane (the f64 lanes serve models that need f64's
    /// accuracy, which a short polynomial would not keep).
    #[inline(always)]
    fn exp_f64(x: __m256d) -> __m256d {
        // SAFETY: same size and layout.
        let a: [f64; 4] = unsafe { std::mem::transmute::<__m256d, [f64; 4]>(x) };
        unsafe { std::mem::transmute::<[f64; 4], __m256d>(a.map(f64::exp)) }
    }

    #[inline(always)]
    fn exp_m1_f64(x: __m256d) -> __m256d {
        // SAFETY: same size and layout.
        let a: [f64; 4] = unsafe { std::mem::transmute::<__m256d, [f64; 4]>(x) };
        unsafe { std::mem::transmute::<[f64; 4], __m256d>(a.map(f64::exp_m1)) }
    }

    /// The AVX type of the same layout as an array lane type.
    pub trait Avx: Real {
        type Reg: Real;
        /// Same size and alignment (checked where a slice is cast).
        const SAME_LAYOUT: () = assert!(
            std::mem::size_of::<Self>() == std::mem::size_of::<Self::Reg>()
                && std::mem::align_of::<Self>() == std::mem::align_of::<Self::Reg>()
        );
    }
    impl Avx for F32x8 {
        type Reg = Avx8;
    }
    impl Avx for F64x4 {
        type Reg = Avx4d;
    }

    #[cfg(test)]
    mod tests {
        use super::*;

        /// e^x and e^x − 1 of the AVX f32 lanes against f64, over [−87, 88] and near 0:
        /// within 4 f32 ulps (2.4e-7) relative, NaN never passing.
        #[test]
        fn vector_exp_is_within_a_few_ulps() {
            if !(is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")) {
                eprintln!("no AVX2 on this processor: the AVX lanes are never used here");
                return;
            }
            #[target_feature(enable = "avx2,fma")]
            fn run(xs: &[f32]) -> Vec<(f32, f32)> {
                xs.chunks_exact(8)
                    .flat_map(|c| {
                        let v = Avx8(unsafe { _mm256_loadu_ps(c.as_ptr()) });
                        let (e, m) = (v.exp(), v.exp_m1());
                        (0..8).map(move |j| (e.lane(j) as f32, m.lane(j) as f32))
                    })
                    .collect()
            }
            let mut xs: Vec<f32> = (0..8000)
                .map(|k| -87.0 + 175.0 * k as f32 / 8000.0)
                .collect();
            xs.extend((0..800).map(|k| (k as f32 - 400.0) * 1e-3));
            xs.extend((0..800).map(|k| (k as f32 - 400.0) * 1e-7));
            let got = unsafe { run(&xs) };
            for (&x, &(e, m)) in xs.iter().zip(&got) {
                let (we, wm) = ((x as f64).exp(), (x as f64).exp_m1());
                let (re, rm) = (
                    ((e as f64) - we) / we,
                    ((m as f64) - wm) / wm.abs().max(1e-300),
                );
                assert!(re.abs() <= 2.4e-7, "exp({x}) = {e}, want {we} ({re:e})");
                if x != 0.0 {
                    assert!(rm.abs() <= 2.4e-7, "exp_m1({x}) = {m}, want {wm} ({rm:e})");
                }
            }
        }
    }
}
