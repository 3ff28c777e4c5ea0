// The data-driven NDF of a GGX lobe (`+ndf`): D = D_GGX(alpha) exp(s(theta_m)) / N with s a
// Catmull-Rom spline through NDF_KNOTS knots (s = 0 at the normal), and the Smith G1 = mu / (mu +
// C(mu)) of that same D, C read from a 65-entry table at mu_j = (j/64)^2. f32 twin of
// src/bsdf/ndf.rs, which documents the distribution, the knots and the quadrature. A
// candidate's table is built by its node's prepare function after the candidate is loaded
// (into NDF_TABLE for the highlight of ggx or fa or the lobe of btdf(tr), COAT_NDF_TABLE
// for a coat: a model has at most one of each); without the prepared constant, per record.

const NDF_KNOTS: u32 = 32u;
const NDF_MU_POINTS: u32 = 65u;
// The last knot's coordinate: the knot coordinate runs over [0, NDF_KNOTS - 1].
const NDF_LAST: f32 = f32(NDF_KNOTS - 1u);

struct NdfTable {
    alpha: f32,
    inv_norm: f32,
    s: array<f32, NDF_KNOTS>,
    c: array<f32, NDF_MU_POINTS>,
}

// The table of the highlight (ggx or fa) and of a coat lobe: a model has at most one of each.
var<private> NDF_TABLE: NdfTable;
var<private> COAT_NDF_TABLE: NdfTable;

// The knot coordinate x in [0, NDF_LAST] of y = 2 sin^2(theta/2): knot k at x = k.
fn ndf_knot_coordinate(y: f32) -> f32 {
    // pow is undefined at 0 in WGSL; y = 0 is the normal, knot 0.
    if (y <= 0.0) {
        return 0.0;
    }
    return NDF_LAST * pow(y, 1.0 / 3.0);
}

// s at knot coordinate x: the Catmull-Rom spline through the knots, even through the
// normal (s_-1 = s_1) and linear past the last knot.
fn ndf_deviation(tab: ptr<private, NdfTable>, x: f32) -> f32 {
    let xc = clamp(x, 0.0, NDF_LAST);
    let k = min(u32(xc), NDF_KNOTS - 2u);
    let t = xc - f32(k);
    var p0 = (*tab).s[1];
    if (k > 0u) {
        p0 = (*tab).s[k - 1u];
    }
    let p1 = (*tab).s[k];
    let p2 = (*tab).s[k + 1u];
    var p3 = 2.0 * (*tab).s[NDF_KNOTS - 1u] - (*tab).s[NDF_KNOTS - 2u];
    if (k + 2u < NDF_KNOTS) {
        p3 = (*tab).s[k + 2u];
    }
    let a = 2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3;
    let b = -p0 + 3.0 * (p1 - p2) + p3;
    return 0.5 * (2.0 * p1 + t * ((p2 - p0) + t * (a + t * b)));
}

// t = alpha cos / sqrt(alpha^2 cos^2 + sin^2) at knot coordinate x (y = (x/NDF_LAST)^3).
fn ndf_knot_t(x: f32, alpha: f32) -> f32 {
    let r = x / NDF_LAST;
    let y = r * r * r;
    let c = 1.0 - y;
    let s2 = y * (2.0 - y);
    return alpha * c / sqrt(alpha * alpha * c * c + s2);
}

// The quadrature pieces of a knot interval: one per 4 units of change of s, 1 to 4.
fn ndf_pieces(a: f32, b: f32) -> u32 {
    return u32(clamp(ceil(abs(b - a) / 4.0), 1.0, 4.0));
}

// The table's cosines a node at sin(theta_m) = sm faces away from (mu_j < sm).
fn ndf_facing_count(sm: f32) -> u32 {
    return min(u32(ceil(f32(NDF_MU_POINTS - 1u) * sqrt(sm))) + 1u, NDF_MU_POINTS);
}

// The azimuth integral of (-(w.m))+ for w at (mu, sw) and m at (cm, sm).
fn ndf_facing_away(mu: f32, sw: f32, cm: f32, sm: f32) -> f32 {
    let a = mu * cm;
    let b = sw * sm;
    if (b <= a) {
        return 0.0;
    }
    let r = a / b;
    let psi = acos(clamp(-r, -1.0, 1.0));
    return 2.0 * (b * sqrt(max(1.0 - r * r, 0.0)) - a * (PI - psi));
}

// The table of alpha and the knots s[1] .. s[NDF_KNOTS - 1] the caller has set (from its first
// knot's generated `_run` accessor): 1/N and C(mu_j).
fn ndf_build(tab: ptr<private, NdfTable>, alpha: f32) {
    (*tab).alpha = alpha;
    (*tab).s[0] = 0.0;
    for (var j = 0u; j < NDF_MU_POINTS; j = j + 1u) {
        (*tab).c[j] = 0.0;
    }
    var gx = array<f32, 4>(0.1834346424956498, 0.5255324099163290, 0.7966664774136267, 0.9602898564975363);
    var gw = array<f32, 4>(0.3626837833783620, 0.3137066458778873, 0.2223810344533745, 0.1012285362903763);
    let a2 = alpha * alpha;
    var norm = 0.0;
    for (var k = 0u; k < NDF_KNOTS - 1u; k = k + 1u) {
        let pieces = ndf_pieces((*tab).s[k], (*tab).s[k + 1u]);
        for (var piece = 0u; piece < pieces; piece = piece + 1u) {
            let x0 = f32(k) + f32(piece) / f32(pieces);
            let x1 = f32(k) + f32(piece + 1u) / f32(pieces);
            let hi = ndf_knot_t(x0, alpha);
            let lo = ndf_knot_t(x1, alpha);
            let mid = 0.5 * (hi + lo);
            let half = 0.5 * (hi - lo);
            for (var g = 0u; g < 8u; g = g + 1u) {
                var t = mid + half * gx[g / 2u];
                if (g % 2u == 0u) {
                    t = mid - half * gx[g / 2u];
                }
                let wt = half * gw[g / 2u];
                let q = t * t + a2 * (1.0 - t * t);
                let rq = sqrt(q);
                let cm = t / rq;
                let sm2 = a2 * (1.0 - t * t) / q;
                let sm = sqrt(sm2);
                let x = clamp(ndf_knot_coordinate(sm2 / (1.0 + cm)), x0, x1);
                let e = exp(ndf_deviation(tab, x));
                norm = norm + e * 2.0 * t * wt;
                let weight = e * rq * INV_PI * wt;
                let count = ndf_facing_count(sm);
                for (var j = 0u; j < count; j = j + 1u) {
                    let r = f32(j) / f32(NDF_MU_POINTS - 1u);
                    let mu = r * r;
                    let sw = sqrt(max(1.0 - mu * mu, 0.0));
                    (*tab).c[j] = (*tab).c[j] + weight * ndf_facing_away(mu, sw, cm, sm);
                }
            }
        }
    }
    let inv = 1.0 / norm;
    (*tab).inv_norm = inv;
    for (var j = 0u; j < NDF_MU_POINTS; j = j + 1u) {
        (*tab).c[j] = (*tab).c[j] * inv;
    }
}

// C(mu), linear in sqrt(mu) between the table's cosines mu_j = (j/64)^2.
fn ndf_c(tab: ptr<private, NdfTable>, mu: f32) -> f32 {
    let x = sqrt(clamp(mu, 0.0, 1.0)) * f32(NDF_MU_POINTS - 1u);
    let j = min(u32(x), NDF_MU_POINTS - 2u);
    let f = x - f32(j);
    return (*tab).c[j] + f * ((*tab).c[j + 1u] - (*tab).c[j]);
}

// D at m = any positive multiple of a unit normal (0 for m.z <= 0).
fn ndf_d(tab: ptr<private, NdfTable>, m: vec3<f32>) -> f32 {
    if (m.z <= 0.0) {
        return 0.0;
    }
    let a2 = (*tab).alpha * (*tab).alpha;
    let c2 = m.z * m.z;
    let s2 = m.x * m.x + m.y * m.y;
    let len2 = c2 + s2;
    let len = sqrt(len2);
    let t = a2 * c2 + s2;
    let ggx = a2 * (len2 * len2) / (PI * t * t);
    return ggx * exp(ndf_deviation(tab, ndf_knot_coordinate(s2 / (len * (len + m.z))))) * (*tab).inv_norm;
}

// Smith's G1(w)/|mu| of the table's D, 1/(|mu| + C(|mu|)); no side test.
fn ndf_g1_over_mu(tab: ptr<private, NdfTable>, w: vec3<f32>) -> f32 {
    let mu = abs(w.z);
    return 1.0 / (mu + ndf_c(tab, mu));
}

// D(h) G1(wi) G1(wo) / (4 mu_i mu_o) at m = any positive multiple of the half vector, with
// the chi+ side tests of Smith G1; wi and wo above the surface.
fn ndf_reflection(tab: ptr<private, NdfTable>, wi: vec3<f32>, wo: vec3<f32>, m: vec3<f32>) -> f32 {
    if (m.z <= 0.0 || dot(wi, m) * wi.z <= 0.0 || dot(wo, m) * wo.z <= 0.0) {
        return 0.0;
    }
    return ndf_d(tab, m) / (4.0 * (wi.z + ndf_c(tab, wi.z)) * (wo.z + ndf_c(tab, wo.z)));
}

// The half vector as the GGX lobe takes it: m the unnormalised sum wi + wo (the normal
// where it vanishes) in xyz, cos theta_d = wi.h in w.
fn ndf_half(wi: vec3<f32>, wo: vec3<f32>) -> vec4<f32> {
    let sum = wi + wo;
    let len = length(sum);
    if (len < 1e-12) {
        return vec4<f32>(0.0, 0.0, 1.0, wi.z);
    }
    return vec4<f32>(sum, 0.5 * len);
}

// F(wi.h; eta) times the kernel, as the GGX lobe takes them.
fn ndf_lobe(tab: ptr<private, NdfTable>, eta: f32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let h = ndf_half(wi, wo);
    return fresnel_dielectric(h.w, eta) * ndf_reflection(tab, wi, wo, h.xyz);
}

// `ggx` with the data-driven NDF. Parameters: ks, alpha, eta, ndf1 .. ndf31.
fn ggx_ndf_prepare(o: u32) {
    for (var k = 1u; k < NDF_KNOTS; k = k + 1u) {
        NDF_TABLE.s[k] = ggx_ndf_ndf1_run(o, k - 1u);
    }
    ndf_build(&NDF_TABLE, ggx_ndf_alpha(o));
}

fn ggx_ndf_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (!GGX_NDF_PREPARED) {
        ggx_ndf_prepare(o);
    }
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    return ggx_ndf_ks(o) * ndf_lobe(&NDF_TABLE, ggx_ndf_eta(o), wi, wo);
}

// `fa(B)` with the data-driven NDF. Parameters: lobe.alpha, lobe.eta, lobe.ks, lobe.ndf1 .. 15.
fn fa_ndf_prepare(o: u32) {
    for (var k = 1u; k < NDF_KNOTS; k = k + 1u) {
        NDF_TABLE.s[k] = fa_ndf_lobe_ndf1_run(o, k - 1u);
    }
    ndf_build(&NDF_TABLE, fa_ndf_lobe_alpha(o));
}

fn fa_ndf_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, base: f32) -> f32 {
    if (!FA_NDF_PREPARED) {
        fa_ndf_prepare(o);
    }
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let eta = fa_ndf_lobe_eta(o);
    let transmit = fresnel_transmittance(wi.z, eta) * fresnel_transmittance(wo.z, eta);
    return fa_ndf_lobe_ks(o) * ndf_lobe(&NDF_TABLE, eta, wi, wo) + transmit * base;
}

// `M+coat` with a data-driven coat lobe. Parameters: kc, alpha_c, ndf_c1 .. ndf_c15.
fn coat_ndf_prepare(o: u32) {
    for (var k = 1u; k < NDF_KNOTS; k = k + 1u) {
        COAT_NDF_TABLE.s[k] = coat_ndf_ndf_c1_run(o, k - 1u);
    }
    ndf_build(&COAT_NDF_TABLE, coat_ndf_alpha_c(o));
}

fn coat_ndf_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    if (!COAT_NDF_PREPARED) {
        coat_ndf_prepare(o);
    }
    let kc = coat_ndf_kc(o);
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return (1.0 - kc) * inner;
    }
    return (1.0 - kc) * inner + kc * ndf_reflection(&COAT_NDF_TABLE, wi, wo, wi + wo);
}

// The `+ndf` node passes its inner model's value through.
fn ndf_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    return inner;
}
