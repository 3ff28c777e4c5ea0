// Per-sample loss terms: the GPU twin of src/engine/loss.rs. TERM is a constant generated
// per pipeline (see src/engine/wgsl.rs): 0 = |y′−y|/(|y′|+|y|+ε) (SMAPE),
// 1 = (a y′ − a y)², 2 = (log1p(a y′) − log1p(a y))². The kernel returns their sum; the
// host finishes it (Σ/K, sqrt(Σ/K) or Σ) per problem, in f64 (LossTerms::finish_sum), so
// problems whose losses share a term shape share a pipeline.

const LOSS_EPS: f32 = 1e-6;

// ln(1 + x) to a few ulps of x for small x; WGSL has no log1p. log(1 + x) rounds 1 + x to
// a multiple of 2^-23 first, losing every digit of x ≲ 1e-7 and most below 1e-4 (BTDF
// tails). The classic remedy, Goldberg's ln(u)·x/(u − 1) with u = fl(1 + x) (D. Goldberg,
// "What every computer scientist should know about floating-point arithmetic", ACM
// Computing Surveys 23(1), 1991, Theorem 4), assumes a log accurate to a few ulps near 1;
// Vulkan only requires log to an absolute error of 2^-21 on [0.5, 2] (SPIR-V
// GLSL.std.450 precision table), i.e. no relative accuracy at all at ln(1 + 1e-6), and
// lavapipe shows it (tests/gpu_accuracy.rs). So small |x| takes the series of
// ln(1 + x) = 2 atanh(s), s = x/(2 + x): 2s(1 + s²/3 + s⁴/5 + s⁶/7 + s⁸/9), truncated at
// |x| < 0.25 (|s| < 1/7) by less than s¹⁰/11 < 2e-9 relative, every operation relative;
// beyond, ln(1 + x) ≥ 0.22 in magnitude and log's 2^-21 is below 2.2e-6 of it.
fn log1p_f32(x: f32) -> f32 {
    if (abs(x) < 0.25) {
        let s = x / (2.0 + x);
        let s2 = s * s;
        return 2.0 * s * (1.0 + s2 * (1.0 / 3.0 + s2 * (0.2 + s2 * (1.0 / 7.0 + s2 * (1.0 / 9.0)))));
    }
    return log(1.0 + x);
}

// `v` is the measured value as the term compares it: y for SMAPE, otherwise already
// transformed by the term's g (g(y), computed in f64).
fn loss_term(yp: f32, v: f32, w: f32, a: f32) -> f32 {
    if (TERM == 0u) {
        return w * abs(yp - v) / (abs(yp) + abs(v) + LOSS_EPS);
    }
    if (TERM == 2u) {
        let d = log1p_f32(a * yp) - v;
        return w * d * d;
    }
    let d = a * yp - v;
    return w * d * d;
}
