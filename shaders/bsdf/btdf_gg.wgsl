// btdf(gg): microfacet transmission with the generalized Gaussian NDF (Holzschuch &
// Pacanowski 2017) and its own Smith G from the Lambda table. Twin of the GG part of
// src/model/btdf.rs. Needs btdf.wgsl (core) and common.wgsl.
//
// requires: var<storage, read> LUT: array<f32>;  declared by the engine, holding
// LambdaTable::to_f32() from index 0: LUT[ip * BTDF_GG_NA + ia], ip <-> ln p uniform on
// [ln 0.2, ln 5] (BTDF_GG_NP points), ia <-> x = b/(1+b) uniform on [0, 1] (BTDF_GG_NA
// points), b = r_c(p) * beta * tan(theta); value T = Lambda / (J0(p) (a + 1/r_c(p))).
// Parameters at P[o]: beta, p, eta.

const BTDF_GG_NP: u32 = 33u;
const BTDF_GG_NA: u32 = 129u;
const BTDF_GG_LNP_LO: f32 = -1.6094379124341003;
const BTDF_GG_LNP_HI: f32 = 1.6094379124341003;

// ln Gamma(x), x > 0: upward recurrence to z >= 10, then Stirling's series to 1/z^9. No
// cancellation-prone coefficients, so f32 keeps ~1e-6 relative accuracy in Gamma over the
// range used (0.2 <= x <= 7.5). The CPU side uses crate::math::ln_gamma (Lanczos, f64).
fn btdf_ln_gamma(x: f32) -> f32 {
    var z = x;
    var prod = 1.0;
    for (var k = 0; k < 12 && z < 10.0; k = k + 1) {
        prod = prod * z;
        z = z + 1.0;
    }
    let zi = 1.0 / z;
    let zi2 = zi * zi;
    let series = zi * (1.0 / 12.0 - zi2 * (1.0 / 360.0 - zi2 * (1.0 / 1260.0 - zi2 * (1.0 / 1680.0 - zi2 * (1.0 / 1188.0)))));
    return (z - 0.5) * log(z) - z + 0.9189385332046728 + series - log(prod);
}

struct BtdfGg {
    beta: f32,
    p: f32,
    rc: f32,
    j0: f32,
    ln_norm: f32,
}

fn btdf_gg_shape(beta: f32, p: f32) -> BtdfGg {
    let lg = btdf_ln_gamma(1.0 / p);
    var s: BtdfGg;
    s.beta = beta;
    s.p = p;
    s.rc = exp(-log(p) / (2.0 * p));
    s.j0 = exp(btdf_ln_gamma(1.5 / p) - lg) * INV_PI;
    s.ln_norm = log(p) - lg - log(PI * beta * beta);
    return s;
}

// Bilinear T(p, x) from the LUT (same arithmetic as LambdaTable::interpolate).
fn btdf_gg_table(p: f32, x: f32) -> f32 {
    let fp = clamp((log(p) - BTDF_GG_LNP_LO) / (BTDF_GG_LNP_HI - BTDF_GG_LNP_LO), 0.0, 1.0) * f32(BTDF_GG_NP - 1u);
    let ip = min(u32(fp), BTDF_GG_NP - 2u);
    let u = fp - f32(ip);
    let fa = clamp(x, 0.0, 1.0) * f32(BTDF_GG_NA - 1u);
    let ia = min(u32(fa), BTDF_GG_NA - 2u);
    let v = fa - f32(ia);
    let k = ip * BTDF_GG_NA + ia;
    let t0 = LUT[k] + (LUT[k + 1u] - LUT[k]) * v;
    let t1 = LUT[k + BTDF_GG_NA] + (LUT[k + BTDF_GG_NA + 1u] - LUT[k + BTDF_GG_NA]) * v;
    return t0 + (t1 - t0) * u;
}

// D = p / (pi beta^2 Gamma(1/p)) exp(-(tan^2/beta^2)^p) / cos^4.
fn btdf_gg_d(c2: f32, s2: f32, s: BtdfGg) -> f32 {
    if (c2 < BTDF_C2_MIN) {
        return 0.0;
    }
    let z = s2 / c2 / (s.beta * s.beta);
    var e = 0.0;
    if (z > 0.0) {
        e = exp(clamp(s.p * log(z), -80.0, 80.0));
    }
    return exp(s.ln_norm - e - 2.0 * log(c2));
}

// Smith G1(v)/|v.z| = 1 / (mu + T J0 (beta sin + mu / r_c)).
fn btdf_gg_g1_over_mu(v: vec3<f32>, s: BtdfGg) -> f32 {
    let mu = abs(v.z);
    let bs = s.beta * sqrt(v.x * v.x + v.y * v.y);
    let w = bs * s.rc;
    let x = w / (mu + w);
    let t = btdf_gg_table(s.p, x);
    return 1.0 / (mu + t * s.j0 * (bs + mu / s.rc));
}

fn btdf_gg_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let beta = P[o];
    let p = P[o + 1u];
    let eta = P[o + 2u];
    let g = btdf_geometry(wi, wo, eta);
    if (!g.valid) {
        return 0.0;
    }
    let s = btdf_gg_shape(beta, p);
    let d = btdf_gg_d(btdf_c2(g), btdf_s2(g), s);
    return btdf_transmit(g, eta, d, btdf_gg_g1_over_mu(wi, s), btdf_gg_g1_over_mu(wo, s));
}
