// Micrograin layer shared math (Lucas, Ribardière, Pacanowski, Barla 2023, ACM TOG 42(6)):
// visibility weight (Eqs. 21–23), NDF (Eq. 17), Smith Λ series (supplemental) and the rough
// dielectric grain. f32 twin of src/bsdf/micrograin.rs (same clamps, same 32-term series).
// Uses PI, INV_PI and fresnel_dielectric from common.wgsl, ggx_d_vec from microfacet.wgsl.

const MG_MU_MIN: f32 = 1e-6;
const MG_TAU_MIN: f32 = 1e-6;
const MG_TAU_MAX: f32 = 0.9999;
const MG_BETA_MIN: f32 = 1e-4;
const MG_LAMBDA_TERMS: i32 = 32; // the authors' shader stops at 7 (see micrograin.rs)
const MG_LAMBDA_TAIL_EPS: f32 = 1e-9; // early exit once the series' tail is negligible

fn mg_clamp_tau(t: f32) -> f32 {
    return clamp(t, MG_TAU_MIN, MG_TAU_MAX);
}

fn mg_clamp_beta(b: f32) -> f32 {
    return clamp(b, MG_BETA_MIN, 1.0);
}

// Λ0/τ0 = −ln(1 − τ0)/τ0 without cancellation at small τ0 (WGSL has no log1p).
fn mg_l0_over_tau(t: f32) -> f32 {
    if (t < 0.05) {
        return 1.0 + t * (0.5 + t * (1.0 / 3.0 + t * (0.25 + t * (0.2 + t * (1.0 / 6.0)))));
    }
    return -log(1.0 - t) / t;
}

// 1 − e^{−x} for x ≥ 0 without cancellation at small x (WGSL has no expm1).
fn mg_one_minus_exp_neg(x: f32) -> f32 {
    if (x < 0.1) {
        return x * (1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0 - x * (1.0 / 120.0 - x * (1.0 / 720.0))))));
    }
    return 1.0 - exp(-x);
}

// γβ(θ) = √(β² sin²θ + cos²θ).
fn mg_gamma_beta(beta: f32, mu: f32) -> f32 {
    let s2 = max(1.0 - mu * mu, 0.0);
    return sqrt(beta * beta * s2 + mu * mu);
}

// Visibility weight w = 1 − (1 − τ0)^{½(γβ(θi)/μi + γβ(θo)/μo)} (Eqs. 21–23).
fn mg_weight(tau0_in: f32, beta_in: f32, mu_i: f32, mu_o: f32) -> f32 {
    let tau0 = mg_clamp_tau(tau0_in);
    let beta = mg_clamp_beta(beta_in);
    let mi = clamp(abs(mu_i), MG_MU_MIN, 1.0);
    let mo = clamp(abs(mu_o), MG_MU_MIN, 1.0);
    let e = 0.5 * (mg_gamma_beta(beta, mi) / mi + mg_gamma_beta(beta, mo) / mo);
    let l0 = mg_l0_over_tau(tau0) * tau0;
    return clamp(mg_one_minus_exp_neg(l0 * e), 0.0, 1.0);
}

// Micrograin NDF (Eq. 17) at the unit micro-normal h: GGX(alpha = beta) reweighted by
// (Lambda0/tau0) e^{-Lambda0 u}, u = sin^2 / (beta^2 cos^2 + sin^2).
fn mg_ndf(tau0_in: f32, beta_in: f32, h: vec3<f32>) -> f32 {
    if (h.z <= 0.0) {
        return 0.0;
    }
    let tau0 = mg_clamp_tau(tau0_in);
    let beta = mg_clamp_beta(beta_in);
    let lt = mg_l0_over_tau(tau0);
    let l0 = lt * tau0;
    let s2 = h.x * h.x + h.y * h.y;
    let u = s2 / (beta * beta * (h.z * h.z) + s2);
    return lt * exp(-l0 * u) * ggx_d_vec(h, beta);
}

// vec2(σ, S): σ = μ/γβ, S = Λ·σ, so G1 = σ/(σ + S). Expects clamped τ0, β.
fn mg_lambda_parts(tau0: f32, beta: f32, mu_in: f32) -> vec2<f32> {
    let mu = clamp(mu_in, 0.0, 1.0);
    let s2 = max(1.0 - mu * mu, 0.0);
    let g = sqrt(beta * beta * s2 + mu * mu);
    let sn = mu / g;
    let c2 = beta * beta * s2 / (g * g);
    let lt = mg_l0_over_tau(tau0);
    let l0 = lt * tau0;
    var wk = lt * (1.0 - tau0); // Λ0/(e^{Λ0} − 1)
    var kk = 0.5;
    var c2k = 1.0;
    var j = c2 / (1.0 + sn); // J_0 = 1 − σ
    var sum = wk * kk * (c2 - sn * j);
    for (var k: i32 = 1; k < MG_LAMBDA_TERMS; k = k + 1) {
        let kf = f32(k);
        wk = wk * l0 / kf;
        kk = kk * (kf + 0.5) / (kf + 1.0);
        c2k = c2k * c2;
        j = (2.0 * kf * j - c2k * sn) / (2.0 * kf + 1.0);
        sum = sum + wk * kk * (c2k * c2 / (2.0 * kf + 1.0) - sn * j);
        // tail ≤ w_k c^{2k+2}/2 once k + 1 ≥ 2Λ0 (see micrograin.rs)
        if (kf + 1.0 >= 2.0 * l0 && wk * c2k * c2 <= MG_LAMBDA_TAIL_EPS * sum) {
            break;
        }
    }
    return vec2<f32>(sn, max(sum, 0.0));
}

// Smith G1 = 1/(1 + Λ).
fn mg_g1(tau0: f32, beta: f32, mu: f32) -> f32 {
    let p = mg_lambda_parts(mg_clamp_tau(tau0), mg_clamp_beta(beta), mu);
    return p.x / (p.x + p.y);
}

// G1(μ)/μ = 1/(γβ (σ + S)), finite at μ → 0.
fn mg_g1_over_mu(tau0: f32, beta: f32, mu: f32) -> f32 {
    let b = mg_clamp_beta(beta);
    let p = mg_lambda_parts(mg_clamp_tau(tau0), b, mu);
    return 1.0 / (mg_gamma_beta(b, clamp(mu, 0.0, 1.0)) * (p.x + p.y));
}

// G1(μ)/μ of the last μi and of the last μo, kept per invocation (keys: τ0, β, μ): a
// thread walks records in order, and consecutive records often share θi or θo (a
// goniometer scans θo at a fixed θi), so the Λ series runs once per run of them, as the
// CPU twin's RoughGrainMemo does. Exact: a pure function; NaN never matches.
var<private> MG_G1I_KEY: vec3<f32> = vec3<f32>(-1.0, -1.0, -1.0);
var<private> MG_G1I: f32;
var<private> MG_G1O_KEY: vec3<f32> = vec3<f32>(-1.0, -1.0, -1.0);
var<private> MG_G1O: f32;

// G1(μ)/μ from the memo (key, value) or computed and kept there.
fn mg_g1_over_mu_memo(key_at: ptr<private, vec3<f32>>, value_at: ptr<private, f32>, tau0: f32, beta: f32,
                      mu: f32) -> f32 {
    let key = vec3<f32>(tau0, beta, mu);
    if (!all(key == *key_at)) {
        *value_at = mg_g1_over_mu(tau0, beta, mu);
        *key_at = key;
    }
    return *value_at;
}

// G1(μ)/μ of the candidate at each entry of its problem's μ table (kernel.wgsl), computed
// by `rmg_prepare` once per candidate, before the record loop. Why: with the Λ series
// inside the record loop, even behind a memo that spares most records the series, `rmg`
// ran at 1.2e8 evaluations/s on lavapipe (w80-g40-full, 16 restarts); with the series
// taken out of the loop altogether (wrong values, a bound) 2.6e8, and with this table
// the same 2.6e8 (`bsdfit bench --models 'rmg(ggx)'`). A loop inside the record loop
// costs that SIMD device more than its trips. The values are those the memo would give,
// bit for bit: the table holds the records' own f32 cosines.
var<private> MG_G1_OVER_MU: array<f32, MU_TABLE_LEN>;

// Fill MG_G1_OVER_MU for the candidate (clamped τ0, β as mg_g1_over_mu clamps them).
fn mg_fill_g1_table(tau0: f32, beta: f32) {
    if (!MU_TABLES) {
        return;
    }
    let n = mu_table_len();
    for (var i = 0u; i < n; i = i + 1u) {
        MG_G1_OVER_MU[i] = mg_g1_over_mu(tau0, beta, mu_table_at(i));
    }
}

// G1(μ)/μ at the record's μ of table index `slot`: from MG_G1_OVER_MU when `tabulated`
// (the model's prepare function filled it, and every problem has a μ table: MU_TABLES),
// else from the memo. Both are constants, so a module holds one of the two paths.
fn mg_g1_over_mu_at(tabulated: bool, slot: u32, key_at: ptr<private, vec3<f32>>, value_at: ptr<private, f32>,
                    tau0: f32, beta: f32, mu: f32) -> f32 {
    if (tabulated && MU_TABLES) {
        return MG_G1_OVER_MU[min(slot, MU_TABLE_LEN - 1u)];
    }
    return mg_g1_over_mu_memo(key_at, value_at, tau0, beta, mu);
}

// The rough grain at one direction pair without ρ_g (RoughGrain::at in micrograin.rs):
// x = the specular term F(ωi·h) D G1i G1o/(4 μi μo), y = the product of the Fresnel
// transmittances (1 − F(μi))(1 − F(μo)). ρ_g is the grain's only per-channel parameter, so
// the channels of a record call this with the same arguments one after the other: the
// last call's arguments and result are kept per invocation and reused when they match
// exactly (a pure function, so a match is always right; NaN never matches). The Λ series
// inside is most of rmg's cost, which this divides by the channel count.
var<private> MG_MEMO_VALID: bool = false;
var<private> MG_MEMO_KEY: vec3<f32>;
var<private> MG_MEMO_WI: vec3<f32>;
var<private> MG_MEMO_WO: vec3<f32>;
var<private> MG_MEMO_VAL: vec2<f32>;

fn mg_rough_grain_shared(tau0: f32, beta: f32, eta_g: f32, wi: vec3<f32>, wo: vec3<f32>) -> vec2<f32> {
    let key = vec3<f32>(tau0, beta, eta_g);
    if (MG_MEMO_VALID && all(key == MG_MEMO_KEY) && all(wi == MG_MEMO_WI) && all(wo == MG_MEMO_WO)) {
        return MG_MEMO_VAL;
    }
    var value = vec2<f32>(0.0, 0.0);
    let mu_i = wi.z;
    let mu_o = wo.z;
    if (mu_i > 0.0 && mu_o > 0.0) {
        let eta = max(eta_g, 1.0);
        value.y = fresnel_transmittance(mu_i, eta) * fresnel_transmittance(mu_o, eta);
        let hs = wi + wo;
        let hl2 = dot(hs, hs);
        if (hl2 >= 1e-30) {
            let h = hs * inverseSqrt(hl2);
            let cd = clamp(dot(wi, h), 0.0, 1.0);
            value.x = fresnel_dielectric(cd, eta) * mg_ndf(tau0, beta, h)
                * mg_g1_over_mu_at(RMG_PREPARED, RECORD_MU.x, &MG_G1I_KEY, &MG_G1I, tau0, beta, mu_i)
                * mg_g1_over_mu_at(RMG_PREPARED, RECORD_MU.y, &MG_G1O_KEY, &MG_G1O, tau0, beta, mu_o) * 0.25;
        }
    }
    MG_MEMO_VALID = true;
    MG_MEMO_KEY = key;
    MG_MEMO_WI = wi;
    MG_MEMO_WO = wo;
    MG_MEMO_VAL = value;
    return value;
}

// Rough dielectric grain: F(ωi·h) D G1i G1o/(4 μi μo) + (1 − F(μi))(1 − F(μo)) ρ_g/π.
fn mg_rough_grain(tau0: f32, beta: f32, eta_g: f32, rho_g: f32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let parts = mg_rough_grain_shared(tau0, beta, eta_g, wi, wo);
    return parts.x + parts.y * rho_g * INV_PI;
}
