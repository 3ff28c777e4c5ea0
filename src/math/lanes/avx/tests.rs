//! Accuracy of the AVX lanes' vector functions against f64, and the sixteen AVX-512
//! lanes against two eight-lane halves.

use super::*;

/// `op` of each run of eight values, in the AVX lanes.
#[target_feature(enable = "avx2,fma")]
fn in_avx8(xs: &[f32], op: impl Fn(Avx8) -> Avx8) -> Vec<f32> {
    xs.chunks_exact(8)
        .flat_map(|c| {
            let v = op(Avx8(unsafe { _mm256_loadu_ps(c.as_ptr()) }));
            (0..8).map(move |j| v.lane(j) as f32)
        })
        .collect()
}

/// arccos of the AVX f32 lanes against f64 on [−1, 1]: within 3e-7 absolute (a few
/// f32 ulps of values up to π), NaN never passing.
#[test]
fn vector_acos_is_within_a_few_ulps() {
    if !(is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")) {
        eprintln!("no AVX2 on this processor: the AVX lanes are never used here");
        return;
    }
    let xs: Vec<f32> = (0..16000)
        .map(|k| -1.0 + k as f32 / 8000.0)
        .chain([1.0])
        .collect();
    let xs = &xs[..xs.len() / 8 * 8];
    let got = unsafe { in_avx8(xs, |v| v.acos()) };
    for (&x, &a) in xs.iter().zip(&got) {
        let want = (x as f64).acos();
        assert!(
            (a as f64 - want).abs() <= 3e-7,
            "acos({x}) = {a}, want {want}"
        );
    }
}

/// ln of the AVX f32 lanes against f64 from subnormals to f32::MAX: within 2 f32
/// epsilons of |ln x| plus 1e-7·ε absolute (in units of the result near x = 1, where it is
/// small), libm's special values at 0, −0, x < 0, NaN and ∞, NaN never passing
/// otherwise.
#[test]
fn vector_ln_is_within_a_few_ulps() {
    if !(is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")) {
        eprintln!("no AVX2 on this processor: the AVX lanes are never used here");
        return;
    }
    // Every binade (subnormals too) at 64 points, the neighbourhood of 1 densely, and
    // the special values.
    let mut xs: Vec<f32> = (0..64 * 278)
        .map(|k| 2f64.powf(-149.0 + k as f64 / 64.0) as f32)
        .chain((-4000..4000).map(|k| 1.0 + k as f32 * 1e-4))
        .chain((-50..50).map(|k| 1.0 + k as f32 * f32::EPSILON))
        .filter(|x| x.is_finite() && *x > 0.0)
        .collect();
    let special = [0.0, -0.0, -1.0, -f32::MIN_POSITIVE, f32::NAN, f32::INFINITY];
    xs.extend(special);
    xs.extend([f32::MAX, f32::MIN_POSITIVE, 1e-45]);
    while !xs.len().is_multiple_of(8) {
        xs.push(1.0);
    }
    let got = unsafe { in_avx8(&xs, |v| v.ln()) };
    for (&x, &a) in xs.iter().zip(&got) {
        let want = (x as f64).ln();
        let ok = if want.is_nan() {
            a.is_nan()
        } else if want.is_infinite() {
            a as f64 == want
        } else {
            (a as f64 - want).abs() <= 2.0 * f32::EPSILON as f64 * want.abs() + 1e-14
        };
        assert!(ok, "ln({x:e}) = {a:e}, want {want:e}");
    }
}

/// x^e of the AVX f32 lanes against f64 for exponents of both signs, integer and
/// not, from subnormal x to f32::MAX: within (3|e ln x| + 6) f32 epsilons relative
/// (the error e^(e ln x) inherits from ln), ∞ where the result overflows f32, 0 to
/// twice f32's smallest normal where it is below that (e^x flushes); libm's special
/// values (0, −0, x < 0 with e not an integer, NaN, ±∞, e = 0) exactly, NaN never
/// passing otherwise.
#[test]
fn vector_powf_is_within_its_bound() {
    if !(is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")) {
        eprintln!("no AVX2 on this processor: the AVX lanes are never used here");
        return;
    }
    let mut xs: Vec<f32> = (0..16 * 278)
        .map(|k| 2f64.powf(-149.0 + k as f64 / 16.0) as f32)
        .chain((-400..400).map(|k| 1.0 + k as f32 * 1e-3))
        .filter(|x| x.is_finite() && *x > 0.0)
        .collect();
    let special = [0.0, -0.0, -1.0, -2.5, -1e-3, f32::NAN, f32::INFINITY];
    xs.extend(special);
    xs.extend([-f32::INFINITY, f32::MAX, 1.0]);
    while !xs.len().is_multiple_of(8) {
        xs.push(1.0);
    }
    for e in [-3.7, -2.0, -1.0, -0.5, 0.0, 0.3, 1.0, 2.0, 3.0, 4.6, 10.0] {
        let got = unsafe { in_avx8(&xs, |v| v.powf(e)) };
        for (&x, &a) in xs.iter().zip(&got) {
            let want = (x as f64).powf(e);
            let libm = x.powf(e as f32);
            let exact = !x.is_finite() || x == 0.0 || e == 0.0 || want.is_nan();
            let ok = if exact {
                a.to_bits() == libm.to_bits() || (a.is_nan() && libm.is_nan())
            } else {
                let bound = (3.0 * (e * (x.abs() as f64).ln()).abs() + 6.0) * f32::EPSILON as f64;
                let close = ((a as f64 - want) / want).abs() <= bound;
                let overflow = a as f64 == want.signum() * f64::INFINITY;
                if want.abs() > f32::MAX as f64 {
                    overflow
                } else if want.abs() > f32::MAX as f64 * (1.0 - bound) {
                    // Within the error of f32::MAX: either answer.
                    close || overflow
                } else if want.abs() < 2.0 * f32::MIN_POSITIVE as f64 {
                    close || (0.0..=2.0 * f32::MIN_POSITIVE).contains(&a.abs())
                } else {
                    close
                }
            };
            assert!(ok, "{x:e}^{e} = {a:e}, want {want:e} (libm {libm:e})");
        }
    }
}

/// The sixteen AVX-512 lanes give the eight AVX lanes' values bit for bit, operation
/// by operation (the halves of e^x, e^x − 1, ln, x^e and arccos, the mask-register
/// comparisons, NaN handling of min and max, select, any, same_bits).
#[test]
fn sixteen_lanes_are_two_eight_lane_halves() {
    if !(is_x86_feature_detected!("avx512f")
        && is_x86_feature_detected!("avx512vl")
        && is_x86_feature_detected!("avx512dq")
        && is_x86_feature_detected!("avx512bw"))
    {
        eprintln!("no AVX-512 on this processor: the sixteen lanes are never used here");
        return;
    }
    #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma")]
    fn run(a: &[f32; 16], b: &[f32; 16]) -> (Vec<Vec<u32>>, Vec<Vec<u32>>) {
        fn ops<R: Real>(a: R, b: R) -> Vec<R> {
            let m = a.lt(b) | !b.le(R::splat(0.5));
            vec![
                (a / b + a * b - b).sqrt(),
                a.min(b),
                a.max(b),
                a.abs().clamp(-1.0, 1.0).acos(),
                (a * R::splat(40.0)).exp(),
                (a * R::splat(0.3)).exp_m1(),
                (a.abs() + R::splat(1e-3)).ln(),
                a.powf(2.5),
                a.powf(3.0),
                R::select(m & a.le(b), -a, b),
            ]
        }
        // Each operation's lanes as f32 bits.
        fn lanes<R: Real>(v: Vec<R>) -> Vec<Vec<u32>> {
            v.iter()
                .map(|r| {
                    (0..R::LANES)
                        .map(|j| (r.lane(j) as f32).to_bits())
                        .collect()
                })
                .collect()
        }
        let load16 = |x: &[f32; 16]| Avx16(unsafe { _mm512_loadu_ps(x.as_ptr()) });
        let load8 = |x: &[f32]| Avx8(unsafe { _mm256_loadu_ps(x.as_ptr()) });
        let got = lanes(ops(load16(a), load16(b)));
        let lo = lanes(ops(load8(&a[..8]), load8(&b[..8])));
        let hi = lanes(ops(load8(&a[8..]), load8(&b[8..])));
        let want = lo
            .into_iter()
            .zip(hi)
            .map(|(l, h)| [l, h].concat())
            .collect();
        // any and same_bits look at every lane, the sixteenth too.
        let x = load16(a);
        let last = Avx16(_mm512_mask_blend_ps(1 << 15, x.0, _mm512_set1_ps(99.0)));
        assert!(Avx16::any(x.lt(Avx16::splat(-1.5))) && !Avx16::any(x.lt(Avx16::splat(-9.0))));
        assert!(x.same_bits(x) && !x.same_bits(last));
        (got, want)
    }
    let a: [f32; 16] = std::array::from_fn(|j| {
        [0.5, -1.0, 2.0, 1e-30, f32::NAN, 3.0, 0.0, 7.5][j % 8] * (1.0 + j as f32 / 16.0)
    });
    // Some lanes equal (a comparison's ≤ against <) and one at the 0.5 compared with.
    let b: [f32; 16] = std::array::from_fn(|j| match j % 5 {
        0 => a[j],
        1 => 0.5,
        _ => [0.25, 4.0, -2.0, 1.0, 1.0, f32::NAN, 0.0, 2.5][(j + 3) % 8],
    });
    let (got, want) = unsafe { run(&a, &b) };
    assert_eq!(got, want);
}

/// e^x and e^x − 1 of the AVX f32 lanes against f64, over [−87, 88.7] and near 0:
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
    // Up to 88.7, where e^x nears f32::MAX (and n = 128 has no f32 power of two).
    let mut xs: Vec<f32> = (0..8000)
        .map(|k| -87.0 + 175.72 * k as f32 / 8000.0)
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
