//! Lane types of the same layout as [`F32x8`], [`F64x4`] and [`F32x16`] whose operations
//! are AVX instructions (and FMA): kernels run in them inside the functions compiled for
//! AVX2 + FMA or AVX-512 (`bsdf::kernel::run_lanes`), where an explicit instruction per
//! operation leaves nothing to the compiler's vectorizer (which kept part of the array
//! form scalar). Never used outside such a function ([`Avx16`] only inside the AVX-512
//! one).

use super::{F32x16, F32x8, F64x4, Real};
use std::arch::x86_64::*;
use std::ops::{Add, BitAnd, BitOr, Div, Mul, Neg, Not, Sub};

/// A comparison's result: every bit of a lane set where it holds.
macro_rules! avx_type {
    ($name:ident, $mask:ident, $reg:ty, $t:ty, $n:literal, $array:ident,
     add $add:ident, sub $sub:ident, mul $mul:ident, div $div:ident, sqrt $sqrt:ident,
     min $min:ident, max $max:ident, set1 $set1:ident, cmp $cmp:ident,
     blend $blend:ident, and $and:ident, or $or:ident, xor $xor:ident,
     andnot $andnot:ident, movemask $movemask:ident,
     exp $exp:ident, exp_m1 $exp_m1:ident, acos $acos:ident, ln $ln:ident,
     powf $powf:ident, mul_add $mul_add:ident) => {
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
            const F64: bool = std::mem::size_of::<$t>() == 8;
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
                $name($ln(self.0))
            }
            #[inline(always)]
            fn acos(self) -> Self {
                $name($acos(self.0))
            }
            #[inline(always)]
            fn exp_m1(self) -> Self {
                $name($exp_m1(self.0))
            }
            #[inline(always)]
            fn powf(self, e: f64) -> Self {
                $name($powf(self.0, e))
            }
            #[inline(always)]
            fn mul_add(self, a: Self, b: Self) -> Self {
                $name($mul_add(self.0, a.0, b.0))
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
    };
}

avx_type!(Avx8, Avx8Mask, __m256, f32, 8, F32x8,
    add _mm256_add_ps, sub _mm256_sub_ps, mul _mm256_mul_ps, div _mm256_div_ps,
    sqrt _mm256_sqrt_ps, min _mm256_min_ps, max _mm256_max_ps, set1 _mm256_set1_ps,
    cmp _mm256_cmp_ps, blend _mm256_blendv_ps, and _mm256_and_ps, or _mm256_or_ps,
    xor _mm256_xor_ps, andnot _mm256_andnot_ps, movemask _mm256_movemask_ps,
    exp exp_f32, exp_m1 exp_m1_f32, acos acos_f32, ln ln_f32, powf pow_f32,
    mul_add fused_f32);
avx_type!(Avx4d, Avx4dMask, __m256d, f64, 4, F64x4,
    add _mm256_add_pd, sub _mm256_sub_pd, mul _mm256_mul_pd, div _mm256_div_pd,
    sqrt _mm256_sqrt_pd, min _mm256_min_pd, max _mm256_max_pd, set1 _mm256_set1_pd,
    cmp _mm256_cmp_pd, blend _mm256_blendv_pd, and _mm256_and_pd, or _mm256_or_pd,
    xor _mm256_xor_pd, andnot _mm256_andnot_pd, movemask _mm256_movemask_pd,
    exp exp_f64, exp_m1 exp_m1_f64, acos acos_f64, ln ln_f64, powf pow_f64,
    mul_add unfused_f64);

/// a · b + c in eight f32 lanes, one rounding (FMA).
#[inline(always)]
fn fused_f32(a: __m256, b: __m256, c: __m256) -> __m256 {
    // SAFETY: FMA is enabled with AVX2 in every function these types run in.
    unsafe { _mm256_fmadd_ps(a, b, c) }
}

/// a · b + c in four f64 lanes, rounded twice (the reference's operations).
#[inline(always)]
fn unfused_f64(a: __m256d, b: __m256d, c: __m256d) -> __m256d {
    // SAFETY: as fused_f32.
    unsafe { _mm256_add_pd(_mm256_mul_pd(a, b), c) }
}

/// e^x in eight f32 lanes: x = n ln 2 + r (Cody–Waite, |r| ≤ ½ ln 2), e^r by the
/// degree-7 polynomial of Cephes' `expf`, 2^n by the exponent bits; x clamped to
/// ln f32::MAX above (beyond it ∞), and 0 below −87.3 (where f32's normal range ends).
/// Relative error a few f32 ulps, where libm's per lane calls cost as much as a whole GGX
/// evaluation.
#[inline(always)]
fn exp_f32(x: __m256) -> __m256 {
    // SAFETY: AVX2 and FMA instructions only, inside the functions compiled for both
    // (module comment).
    unsafe {
        // Below −87.3 the result (subnormal or 0) is returned as 0, above ln f32::MAX ∞.
        let tiny = _mm256_cmp_ps::<_CMP_LT_OQ>(x, _mm256_set1_ps(-87.3));
        let huge = _mm256_cmp_ps::<_CMP_GT_OQ>(x, _mm256_set1_ps(88.722_84));
        let x = _mm256_min_ps(
            _mm256_max_ps(x, _mm256_set1_ps(-87.3)),
            _mm256_set1_ps(88.722_84),
        );
        let n = _mm256_round_ps::<{ _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC }>(
            _mm256_mul_ps(x, _mm256_set1_ps(std::f32::consts::LOG2_E)),
        );
        let r = _mm256_fnmadd_ps(n, _mm256_set1_ps(0.693_359_4), x);
        let r = _mm256_fnmadd_ps(n, _mm256_set1_ps(-2.121_944_4e-4), r);
        let mut p = _mm256_set1_ps(1.987_569_1e-4);
        for k in [
            1.398_199_9e-3,
            8.333_452e-3,
            4.166_579_6e-2,
            0.166_666_65,
            0.5,
        ] {
            p = _mm256_fmadd_ps(p, r, _mm256_set1_ps(k));
        }
        let p = _mm256_add_ps(
            _mm256_fmadd_ps(_mm256_mul_ps(p, r), r, r),
            _mm256_set1_ps(1.0),
        );
        // 2^128 has no f32 (x above 88.38 rounds to n = 128): 2^127 and p doubled.
        let top = _mm256_cmp_ps::<_CMP_GT_OQ>(n, _mm256_set1_ps(127.5));
        let p = _mm256_blendv_ps(p, _mm256_add_ps(p, p), top);
        let n = _mm256_min_ps(n, _mm256_set1_ps(127.0));
        let bits = _mm256_slli_epi32::<23>(_mm256_add_epi32(
            _mm256_cvtps_epi32(n),
            _mm256_set1_epi32(127),
        ));
        _mm256_blendv_ps(
            _mm256_andnot_ps(tiny, _mm256_mul_ps(p, _mm256_castsi256_ps(bits))),
            _mm256_set1_ps(f32::INFINITY),
            huge,
        )
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
            p = _mm256_fmadd_ps(p, x, _mm256_set1_ps(k));
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

/// ln x in eight f32 lanes: x = m · 2^e with m in [√½, √2), ln m = t − t²/2 + t³ P(t) in
/// t = m − 1 by Cephes' `logf` polynomial, e ln 2 added in two parts (Cody–Waite).
/// Subnormal x scaled by 2²³ first; 0 gives −∞, x < 0 and NaN give NaN, +∞ gives +∞ (as
/// libm). A few f32 ulps (tested), where libm's calls lane by lane were a fifth of
/// `btdf(gg)`'s time (its D takes two logarithms).
#[inline(always)]
fn ln_f32(x: __m256) -> __m256 {
    // SAFETY: as exp_f32.
    unsafe {
        let one = _mm256_set1_ps(1.0);
        let subnormal = _mm256_cmp_ps::<_CMP_LT_OQ>(x, _mm256_set1_ps(f32::MIN_POSITIVE));
        let xs = _mm256_blendv_ps(x, _mm256_mul_ps(x, _mm256_set1_ps(8_388_608.0)), subnormal);
        let bits = _mm256_castps_si256(xs);
        // m in [½, 1) and its exponent e: xs = m · 2^e.
        let e = _mm256_sub_epi32(_mm256_srli_epi32::<23>(bits), _mm256_set1_epi32(126));
        let m = _mm256_castsi256_ps(_mm256_or_si256(
            _mm256_and_si256(bits, _mm256_set1_epi32(0x007f_ffff)),
            _mm256_set1_epi32(0x3f00_0000),
        ));
        let e = _mm256_sub_ps(
            _mm256_cvtepi32_ps(e),
            _mm256_and_ps(subnormal, _mm256_set1_ps(23.0)),
        );
        // m below √½: t = 2m − 1 and e − 1, so that |t| ≤ √2 − 1.
        let low = _mm256_cmp_ps::<_CMP_LT_OQ>(m, _mm256_set1_ps(std::f32::consts::FRAC_1_SQRT_2));
        let t = _mm256_add_ps(_mm256_sub_ps(m, one), _mm256_and_ps(low, m));
        let e = _mm256_sub_ps(e, _mm256_and_ps(low, one));
        let t2 = _mm256_mul_ps(t, t);
        let mut p = _mm256_set1_ps(7.037_683_6e-2);
        for k in [
            -1.151_461e-1,
            1.167_699_9e-1,
            -1.242_014_1e-1,
            1.424_932_3e-1,
            -1.666_805_8e-1,
            2.000_071_4e-1,
            -2.499_999_4e-1,
            3.333_333e-1,
        ] {
            p = _mm256_fmadd_ps(p, t, _mm256_set1_ps(k));
        }
        let y = _mm256_mul_ps(_mm256_mul_ps(p, t), t2);
        let y = _mm256_fmadd_ps(e, _mm256_set1_ps(-2.121_944_4e-4), y);
        let y = _mm256_fnmadd_ps(_mm256_set1_ps(0.5), t2, y);
        let r = _mm256_fmadd_ps(e, _mm256_set1_ps(0.693_359_4), _mm256_add_ps(t, y));
        // libm's special values: ln 0 = −∞, ln(x < 0) = NaN, ln NaN = NaN, ln ∞ = ∞.
        let zero = _mm256_setzero_ps();
        let r = _mm256_blendv_ps(
            r,
            _mm256_set1_ps(f32::INFINITY),
            _mm256_cmp_ps::<_CMP_EQ_OQ>(x, _mm256_set1_ps(f32::INFINITY)),
        );
        let r = _mm256_blendv_ps(
            r,
            _mm256_set1_ps(f32::NEG_INFINITY),
            _mm256_cmp_ps::<_CMP_EQ_OQ>(x, zero),
        );
        _mm256_blendv_ps(
            r,
            _mm256_set1_ps(f32::NAN),
            _mm256_cmp_ps::<_CMP_NGE_UQ>(x, zero),
        )
    }
}

/// ln x in four f64 lanes: lane by lane (the f64 lanes give the reference's values bit
/// for bit).
#[inline(always)]
fn ln_f64(x: __m256d) -> __m256d {
    // SAFETY: same size and layout.
    let a: [f64; 4] = unsafe { std::mem::transmute::<__m256d, [f64; 4]>(x) };
    unsafe { std::mem::transmute::<[f64; 4], __m256d>(a.map(f64::ln)) }
}

/// x^e in eight f32 lanes as e^(e ln x), by the vector ln and e^x: the relative error
/// grows with |e ln x| (about 2ε·|e ln x| plus e^x's few ulps: 1e-5 where the result
/// nears f32's smallest normal), where libm's `powf` lane by lane was a fifth of a
/// micrograin model with a retro falloff. libm's special values: e = 0 gives 1 (NaN and
/// ∞ too), e = 1 gives x; 0 and ∞ give 0 or ∞ by e's sign; x < 0 gives −|x|^e for an odd integer e,
/// |x|^e for an even one, and NaN otherwise (−∞ excepted); NaN gives NaN; overflow ∞.
#[inline(always)]
fn pow_f32(x: __m256, e: f64) -> __m256 {
    if e == 0.0 {
        // SAFETY: as exp_f32.
        return unsafe { _mm256_set1_ps(1.0) };
    }
    if e == 1.0 {
        // x itself, exactly as libm (a retro falloff's q starts at 1).
        return x;
    }
    let e = e as f32;
    let integer = e.fract() == 0.0;
    let odd = integer && (e * 0.5).fract() != 0.0;
    // SAFETY: as exp_f32.
    unsafe {
        let sign = _mm256_set1_ps(-0.0);
        let y = _mm256_mul_ps(ln_f32(_mm256_andnot_ps(sign, x)), _mm256_set1_ps(e));
        let r = exp_f32(y);
        let r = if !integer {
            // (−∞ excepted: (−∞)^e is ∞^e for an e not an odd integer.)
            let negative = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_LT_OQ>(x, _mm256_setzero_ps()),
                _mm256_cmp_ps::<_CMP_GT_OQ>(x, _mm256_set1_ps(f32::NEG_INFINITY)),
            );
            _mm256_blendv_ps(r, _mm256_set1_ps(f32::NAN), negative)
        } else if odd {
            // x's sign bit, so that −0 and −∞ keep theirs as in libm.
            _mm256_or_ps(r, _mm256_and_ps(x, sign))
        } else {
            r
        };
        // NaN in, NaN out (e^x clamps its argument, so it would not pass NaN on).
        _mm256_blendv_ps(r, x, _mm256_cmp_ps::<_CMP_UNORD_Q>(x, x))
    }
}

/// x^e in four f64 lanes: lane by lane (the f64 lanes give the reference's values bit
/// for bit).
#[inline(always)]
fn pow_f64(x: __m256d, e: f64) -> __m256d {
    // SAFETY: same size and layout.
    let a: [f64; 4] = unsafe { std::mem::transmute::<__m256d, [f64; 4]>(x) };
    unsafe { std::mem::transmute::<[f64; 4], __m256d>(a.map(|x| x.powf(e))) }
}

/// arccos x in eight f32 lanes, through arcsin (Cephes' `asinf` polynomial): for
/// |x| ≤ ½, π/2 − asin x; beyond, 2 asin √((1 − |x|)/2), taken from π where x < 0. A
/// few f32 ulps (tested), where libm's calls lane by lane took a tenth of `eon`.
#[inline(always)]
fn acos_f32(x: __m256) -> __m256 {
    // SAFETY: as exp_f32.
    unsafe {
        let half = _mm256_set1_ps(0.5);
        let a = _mm256_andnot_ps(_mm256_set1_ps(-0.0), x);
        let big = _mm256_cmp_ps::<_CMP_GT_OQ>(a, half);
        let z_big = _mm256_mul_ps(half, _mm256_sub_ps(_mm256_set1_ps(1.0), a));
        let z = _mm256_blendv_ps(_mm256_mul_ps(a, a), z_big, big);
        let s = _mm256_blendv_ps(a, _mm256_sqrt_ps(z_big), big);
        let mut p = _mm256_set1_ps(4.216_32e-2);
        for k in [2.418_131e-2, 4.547_002_6e-2, 7.495_300_3e-2, 0.166_667_52] {
            p = _mm256_fmadd_ps(p, z, _mm256_set1_ps(k));
        }
        // asin of s: s + s z P(z).
        let asin = _mm256_fmadd_ps(_mm256_mul_ps(p, z), s, s);
        let negative = _mm256_cmp_ps::<_CMP_LT_OQ>(x, _mm256_setzero_ps());
        // |x| ≤ ½: π/2 − sign(x) asin|x|.
        let signed = _mm256_blendv_ps(asin, _mm256_sub_ps(_mm256_setzero_ps(), asin), negative);
        let small = _mm256_sub_ps(_mm256_set1_ps(std::f32::consts::FRAC_PI_2), signed);
        // |x| > ½: 2 asin √((1 − |x|)/2), or π minus it.
        let twice = _mm256_add_ps(asin, asin);
        let pi = _mm256_set1_ps(std::f32::consts::PI);
        let large = _mm256_blendv_ps(twice, _mm256_sub_ps(pi, twice), negative);
        _mm256_blendv_ps(small, large, big)
    }
}

#[inline(always)]
fn acos_f64(x: __m256d) -> __m256d {
    // SAFETY: same size and layout.
    let a: [f64; 4] = unsafe { std::mem::transmute::<__m256d, [f64; 4]>(x) };
    unsafe { std::mem::transmute::<[f64; 4], __m256d>(a.map(f64::acos)) }
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

/// Sixteen f32 lanes in one AVX-512 register ([`F32x16`]'s layout). Comparisons give a
/// mask register (a bit a lane); e^x, e^x − 1, ln, x^e and arccos run the eight-lane polynomials
/// on each half, which costs the same instructions per lane.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct Avx16(pub __m512);

/// A comparison's result in sixteen lanes: bit j set where lane j holds.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub struct Avx16Mask(pub __mmask16);

// SAFETY (every `unsafe` below): Avx16 exists only inside the function compiled with
// AVX-512 (F, VL, DQ, BW; see the module's comment and `run_lanes`); the operations are
// that extension's intrinsics on registers of the right type.
impl BitAnd for Avx16Mask {
    type Output = Self;
    #[inline(always)]
    fn bitand(self, o: Self) -> Self {
        Avx16Mask(self.0 & o.0)
    }
}
impl BitOr for Avx16Mask {
    type Output = Self;
    #[inline(always)]
    fn bitor(self, o: Self) -> Self {
        Avx16Mask(self.0 | o.0)
    }
}
impl Not for Avx16Mask {
    type Output = Self;
    #[inline(always)]
    fn not(self) -> Self {
        Avx16Mask(!self.0)
    }
}
/// The arithmetic of [`Avx16`]: one AVX-512 instruction each.
macro_rules! avx16_arithmetic {
    ($($op:ident $f:ident $intrinsic:ident),*) => {$(
        impl $op for Avx16 {
            type Output = Self;
            #[inline(always)]
            fn $f(self, o: Self) -> Self {
                unsafe { Avx16($intrinsic(self.0, o.0)) }
            }
        }
    )*};
}
avx16_arithmetic!(Add add _mm512_add_ps, Sub sub _mm512_sub_ps, Mul mul _mm512_mul_ps,
    Div div _mm512_div_ps);
impl Neg for Avx16 {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        unsafe { Avx16(_mm512_xor_ps(self.0, _mm512_set1_ps(-0.0))) }
    }
}
impl Avx16 {
    #[inline(always)]
    fn array(self) -> F32x16 {
        // SAFETY: same size and layout.
        unsafe { std::mem::transmute::<__m512, F32x16>(self.0) }
    }
    #[inline(always)]
    fn from_array(a: F32x16) -> Self {
        // SAFETY: same size and layout.
        Avx16(unsafe { std::mem::transmute::<F32x16, __m512>(a) })
    }
    /// The two halves, for the eight-lane AVX functions. (Called by name: a function
    /// passed as a value is called through a shim compiled without the extensions.)
    #[inline(always)]
    fn halves(self) -> (__m256, __m256) {
        unsafe {
            (
                _mm512_castps512_ps256(self.0),
                _mm512_extractf32x8_ps::<1>(self.0),
            )
        }
    }
    #[inline(always)]
    fn join((lo, hi): (__m256, __m256)) -> Self {
        unsafe { Avx16(_mm512_insertf32x8::<1>(_mm512_castps256_ps512(lo), hi)) }
    }
}
impl Real for Avx16 {
    type Mask = Avx16Mask;
    const LANES: usize = 16;
    const F64: bool = false;
    #[inline(always)]
    fn splat(x: f64) -> Self {
        unsafe { Avx16(_mm512_set1_ps(x as f32)) }
    }
    #[inline(always)]
    fn lane(self, i: usize) -> f64 {
        self.array().0[i] as f64
    }
    #[inline(always)]
    fn from_fn(f: impl FnMut(usize) -> f64) -> Self {
        Self::from_array(F32x16::from_fn(f))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        unsafe { Avx16(_mm512_sqrt_ps(self.0)) }
    }
    #[inline(always)]
    fn abs(self) -> Self {
        unsafe { Avx16(_mm512_abs_ps(self.0)) }
    }
    /// The other operand where one is NaN (as `f64::min`; the instruction returns its
    /// second operand where either is NaN).
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        unsafe {
            let m = _mm512_min_ps(self.0, o.0);
            let nan = _mm512_cmp_ps_mask::<_CMP_UNORD_Q>(o.0, o.0);
            Avx16(_mm512_mask_blend_ps(nan, m, self.0))
        }
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        unsafe {
            let m = _mm512_max_ps(self.0, o.0);
            let nan = _mm512_cmp_ps_mask::<_CMP_UNORD_Q>(o.0, o.0);
            Avx16(_mm512_mask_blend_ps(nan, m, self.0))
        }
    }
    #[inline(always)]
    fn clamp(self, lo: f64, hi: f64) -> Self {
        unsafe {
            let lo = _mm512_set1_ps(lo as f32);
            Avx16(_mm512_min_ps(
                _mm512_max_ps(self.0, lo),
                _mm512_set1_ps(hi as f32),
            ))
        }
    }
    #[inline(always)]
    fn exp(self) -> Self {
        let (lo, hi) = self.halves();
        Self::join((exp_f32(lo), exp_f32(hi)))
    }
    #[inline(always)]
    fn ln(self) -> Self {
        let (lo, hi) = self.halves();
        Self::join((ln_f32(lo), ln_f32(hi)))
    }
    #[inline(always)]
    fn acos(self) -> Self {
        let (lo, hi) = self.halves();
        Self::join((acos_f32(lo), acos_f32(hi)))
    }
    #[inline(always)]
    fn exp_m1(self) -> Self {
        let (lo, hi) = self.halves();
        Self::join((exp_m1_f32(lo), exp_m1_f32(hi)))
    }
    #[inline(always)]
    fn powf(self, e: f64) -> Self {
        let (lo, hi) = self.halves();
        Self::join((pow_f32(lo, e), pow_f32(hi, e)))
    }
    #[inline(always)]
    fn mul_add(self, a: Self, b: Self) -> Self {
        unsafe { Avx16(_mm512_fmadd_ps(self.0, a.0, b.0)) }
    }
    #[inline(always)]
    fn lt(self, o: Self) -> Avx16Mask {
        unsafe { Avx16Mask(_mm512_cmp_ps_mask::<_CMP_LT_OQ>(self.0, o.0)) }
    }
    #[inline(always)]
    fn le(self, o: Self) -> Avx16Mask {
        unsafe { Avx16Mask(_mm512_cmp_ps_mask::<_CMP_LE_OQ>(self.0, o.0)) }
    }
    #[inline(always)]
    fn select(m: Avx16Mask, a: Self, b: Self) -> Self {
        unsafe { Avx16(_mm512_mask_blend_ps(m.0, b.0, a.0)) }
    }
    #[inline(always)]
    fn any(m: Avx16Mask) -> bool {
        m.0 != 0
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
            _mm512_cmpeq_epi32_mask(_mm512_castps_si512(self.0), _mm512_castps_si512(o.0)) == 0xFFFF
        }
    }
}

/// The AVX type of the same layout as an array lane type.
pub trait Avx: Real {
    type Reg: Real;
    /// Whether `Reg` needs AVX-512 (else AVX2 suffices).
    const AVX512: bool = false;
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
impl Avx for F32x16 {
    type Reg = Avx16;
    const AVX512: bool = true;
}

#[cfg(test)]
mod tests;
