// Microfacet distributions in vector form: D(m) and Smith G1 of GGX (Trowbridge-Reitz),
// Beckmann, GTR and the generalized Gaussian. f32 twin of src/bsdf/microfacet.rs.
// m and w are unit vectors in the local frame (normal on +z); cos^2 = z^2 and
// sin^2 = x^2 + y^2 come from the components (never 1 - cos^2, which keeps only the
// rounding of cos near a sharp peak), and GGX is a2 / (pi (a2 cos^2 + sin^2)^2): the
// textbook cos^2 (a2 - 1) + 1 cancels in f32 for alpha below ~1e-2.
// Uses PI and INV_PI from common.wgsl.

// GGX D(m) = a2 / (pi (a2 cos^2 + sin^2)^2), 0 for m.z <= 0.
fn ggx_d_vec(m: vec3<f32>, alpha: f32) -> f32 {
    if (m.z <= 0.0) {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let t = a2 * (m.z * m.z) + (m.x * m.x + m.y * m.y);
    return a2 / (PI * t * t);
}

// GGX G1(w)/|w.z| = 2 / (mu + sqrt(mu^2 + a2 sin^2)), no side test; finite at mu = 0.
fn ggx_g1_over_mu(w: vec3<f32>, alpha: f32) -> f32 {
    let mu = abs(w.z);
    let s2 = w.x * w.x + w.y * w.y;
    return 2.0 / (mu + sqrt(mu * mu + alpha * alpha * s2));
}

// GGX Smith G1(w, m) = chi+((w.m)/(w.n)) / (1 + Lambda(w)).
fn ggx_g1(w: vec3<f32>, m: vec3<f32>, alpha: f32) -> f32 {
    if (dot(w, m) * w.z <= 0.0) {
        return 0.0;
    }
    return abs(w.z) * ggx_g1_over_mu(w, alpha);
}

// GGX reflection kernel D(h) G1(wi, h) G1(wo, h) / (4 mu_i mu_o) at the unit half vector h
// of wi and wo, both above the surface (Walter 2007, Eq. 20 without Fresnel).
fn ggx_reflection(alpha: f32, wi: vec3<f32>, wo: vec3<f32>, h: vec3<f32>) -> f32 {
    return ggx_d_vec(h, alpha) * ggx_g1(wi, h, alpha) * ggx_g1(wo, h, alpha) / (4.0 * wi.z * wo.z);
}

// Beckmann and GTR D (btdf pairs them with the GGX G1, as the benchmark paper).
// Below MF_C2_MIN = cos^2 the exponential NDFs (Beckmann, GG) are 0 (< e^-(10^6) there).
const MF_C2_MIN: f32 = 1e-30;

// Beckmann D(m) = exp(-tan^2/a2) / (pi a2 cos^4).
fn beckmann_d_vec(m: vec3<f32>, alpha: f32) -> f32 {
    let c2 = m.z * m.z;
    if (m.z <= 0.0 || c2 < MF_C2_MIN) {
        return 0.0;
    }
    let s2 = m.x * m.x + m.y * m.y;
    let a2 = alpha * alpha;
    return exp(-(s2 / c2) / a2 - 2.0 * log(c2)) / (PI * a2);
}

// Normalisation of Burley's GTR with its gamma = 1 and alpha = 1 limits (see microfacet.rs).
fn gtr_norm(a2: f32, gamma: f32) -> f32 {
    let ln_a2 = log(a2);
    let x = (1.0 - gamma) * ln_a2;
    var ratio = 1.0 - 0.5 * x;
    if (abs(x) >= 1e-4) {
        ratio = x / (exp(x) - 1.0);
    }
    var a_term = 1.0 + 0.5 * ln_a2;
    if (abs(ln_a2) >= 1e-4) {
        a_term = (a2 - 1.0) / ln_a2;
    }
    return a_term * ratio * INV_PI;
}

// Burley 2012 generalized Trowbridge-Reitz D(m) = c(alpha, gamma) / (a2 cos^2 + sin^2)^gamma.
fn gtr_d_vec(m: vec3<f32>, alpha: f32, gamma: f32) -> f32 {
    if (m.z <= 0.0) {
        return 0.0;
    }
    let a2 = max(alpha * alpha, 1e-12);
    let t = a2 * (m.z * m.z) + (m.x * m.x + m.y * m.y);
    return gtr_norm(a2, gamma) * exp(-gamma * log(t));
}

// Generalized Gaussian (Holzschuch & Pacanowski 2017) with its Smith G1 from the Lambda
// table. requires: fn lut(k: u32) -> f32, declared by the engine, returning entry k of
// LambdaTable::to_f32() when the model has a GG term (layout and grid: see LambdaTable in
// src/bsdf/microfacet.rs): lut((ip + 1) * GG_NA_STRIDE + ia + 1) for grid
// node ip <-> ln p uniform on [ln 0.2, ln 5] (GG_NP points), ia <-> x = b/(1+b) uniform on
// [0, 1] (GG_NA points), with one ghost row/column stored on each side for the bicubic
// stencil; b = r_c(p) * beta * tan(theta); value T = Lambda / (J0(p) (a + 1/r_c(p))).

const GG_NP: u32 = 65u;
const GG_NA: u32 = 129u;
const GG_NA_STRIDE: u32 = 131u;
const GG_LNP_LO: f32 = -1.6094379124341003;
const GG_LNP_HI: f32 = 1.6094379124341003;

// ln Gamma(x), x > 0: ten steps of the upward recurrence, Gamma(x) = Gamma(x + 10) /
// (x (x + 1) … (x + 9)), then Stirling's series at z = x + 10 >= 10 to 1/z^9. No
// cancellation-prone coefficients, so f32 keeps ~1e-6 relative accuracy in Gamma over the
// range used (0.2 <= x <= 7.5; the product stays below 1e12). A fixed count rather than
// "until z >= 10": the compiler unrolls it, where a data-dependent loop costs masked
// iterations on SIMD CPU devices and counts against llvmpipe's loop limit (kernel.wgsl).
// The CPU side uses crate::math::ln_gamma (Lanczos, f64).
fn gg_ln_gamma(x: f32) -> f32 {
    var prod = 1.0;
    for (var k = 0; k < 10; k = k + 1) {
        prod = prod * (x + f32(k));
    }
    let z = x + 10.0;
    let zi = 1.0 / z;
    let zi2 = zi * zi;
    let series = zi * (1.0 / 12.0 - zi2 * (1.0 / 360.0 - zi2 * (1.0 / 1260.0 - zi2 * (1.0 / 1680.0 - zi2 * (1.0 / 1188.0)))));
    return (z - 0.5) * log(z) - z + 0.9189385332046728 + series - log(prod);
}

struct Gg {
    beta: f32,
    p: f32,
    rc: f32,
    j0: f32,
    ln_norm: f32,
}

fn gg_new(beta: f32, p: f32) -> Gg {
    let lg = gg_ln_gamma(1.0 / p);
    var s: Gg;
    s.beta = beta;
    s.p = p;
    s.rc = exp(-log(p) / (2.0 * p));
    s.j0 = exp(gg_ln_gamma(1.5 / p) - lg) * INV_PI;
    s.ln_norm = log(p) - lg - log(PI * beta * beta);
    return s;
}

// Catmull-Rom weights of the 4 nodes around a cell at fraction t (catmull_rom_weights).
fn gg_cr_weights(t: f32) -> vec4<f32> {
    let t2 = t * t;
    let t3 = t2 * t;
    return 0.5 * vec4<f32>(-t3 + 2.0 * t2 - t, 3.0 * t3 - 5.0 * t2 + 2.0, -3.0 * t3 + 4.0 * t2 + t, t3 - t2);
}

// Bicubic T(p, x) from the LUT (same arithmetic as LambdaTable::interpolate).
fn gg_table(p: f32, x: f32) -> f32 {
    let fp = clamp((log(p) - GG_LNP_LO) / (GG_LNP_HI - GG_LNP_LO), 0.0, 1.0) * f32(GG_NP - 1u);
    let ip = min(u32(fp), GG_NP - 2u);
    let wp = gg_cr_weights(fp - f32(ip));
    let fa = clamp(x, 0.0, 1.0) * f32(GG_NA - 1u);
    let ia = min(u32(fa), GG_NA - 2u);
    let wa = gg_cr_weights(fa - f32(ia));
    // Grid node (ip - 1, ia - 1) is stored at (ip, ia).
    var t = 0.0;
    for (var i = 0u; i < 4u; i = i + 1u) {
        let k = (ip + i) * GG_NA_STRIDE + ia;
        let r = wa.x * lut(k) + wa.y * lut(k + 1u) + wa.z * lut(k + 2u) + wa.w * lut(k + 3u);
        t = t + wp[i] * r;
    }
    // Cubic overshoot where T leaves 0 must not make Lambda negative (G1 > 1).
    return max(t, 0.0);
}

// GG D(m) = p / (pi beta^2 Gamma(1/p)) exp(-(tan^2/beta^2)^p) / cos^4.
fn gg_d_vec(m: vec3<f32>, s: Gg) -> f32 {
    let c2 = m.z * m.z;
    if (m.z <= 0.0 || c2 < MF_C2_MIN) {
        return 0.0;
    }
    let z = (m.x * m.x + m.y * m.y) / c2 / (s.beta * s.beta);
    var e = 0.0;
    if (z > 0.0) {
        e = exp(clamp(s.p * log(z), -80.0, 80.0));
    }
    return exp(s.ln_norm - e - 2.0 * log(c2));
}

// GG G1(w)/|w.z| = 1 / (mu + T J0 (beta sin + mu / r_c)), no side test.
fn gg_g1_over_mu(w: vec3<f32>, s: Gg) -> f32 {
    let mu = abs(w.z);
    let bs = s.beta * sqrt(w.x * w.x + w.y * w.y);
    let b = bs * s.rc;
    let x = b / (mu + b);
    let t = gg_table(s.p, x);
    return 1.0 / (mu + t * s.j0 * (bs + mu / s.rc));
}

// The GGX reflection lobe k_s·F·D·G2/(4 μi μo) of `ggx` and of fa's lobe (Walter 2007).
fn ggx_reflect(ks: f32, alpha: f32, eta: f32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let h = half_vector(wi, wo);
    return ks * fresnel_dielectric(dot(wi, h), eta) * ggx_reflection(alpha, wi, wo, h);
}
