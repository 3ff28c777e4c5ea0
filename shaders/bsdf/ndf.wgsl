// The data-driven NDF of a GGX highlight (`+ndf`): D = D_GGX(alpha) exp(s(theta_m)) / N with
// s a Catmull-Rom spline through 16 knots (s = 0 at the normal), and the Smith G1 = mu / (mu + C(mu)) of
// that same D, C read from a 65-entry table at mu_j = (j/64)^2. f32 twin of src/bsdf/ndf.rs, which documents
// the distribution, the knots and the quadrature. The table of a candidate is built into
// NDF_TABLE by ggx_ndf_prepare / fa_ndf_prepare after the candidate is loaded (a model has
// at most one data-driven highlight); without the prepared constant, per record.

const NDF_KNOTS: u32 = 16u;
const NDF_MU_POINTS: u32 = 65u;

struct NdfTable {
    alpha: f32,
    inv_norm: f32,
    s: array<f32, 16>,
    c: array<f32, 65>,
}

var<private> NDF_TABLE: NdfTable;

// The knot coordinate x in [0, 15] of y = 2 sin^2(theta/2): knot k at x = k.
fn ndf_knot_coordinate(y: f32) -> f32 {
    return 15.0 * sqrt(sqrt(max(y, 0.0)));
}

// s at knot coordinate x: the Catmull-Rom spline through the knots, even through the
// normal (s_-1 = s_1) and linear past the last knot.
fn ndf_deviation(x: f32) -> f32 {
    let xc = clamp(x, 0.0, 15.0);
    let k = min(u32(xc), NDF_KNOTS - 2u);
    let t = xc - f32(k);
    var p0 = NDF_TABLE.s[1];
    if (k > 0u) {
        p0 = NDF_TABLE.s[k - 1u];
    }
    let p1 = NDF_TABLE.s[k];
    let p2 = NDF_TABLE.s[k + 1u];
    var p3 = 2.0 * NDF_TABLE.s[NDF_KNOTS - 1u] - NDF_TABLE.s[NDF_KNOTS - 2u];
    if (k + 2u < NDF_KNOTS) {
        p3 = NDF_TABLE.s[k + 2u];
    }
    let a = 2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3;
    let b = -p0 + 3.0 * (p1 - p2) + p3;
    return 0.5 * (2.0 * p1 + t * ((p2 - p0) + t * (a + t * b)));
}

// t = alpha cos / sqrt(alpha^2 cos^2 + sin^2) of knot k (y_k = (k/15)^4).
fn ndf_knot_t(k: u32, alpha: f32) -> f32 {
    let r = f32(k) / 15.0;
    let y = r * r * r * r;
    let c = 1.0 - y;
    let s2 = y * (2.0 - y);
    return alpha * c / sqrt(alpha * alpha * c * c + s2);
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

// The table of alpha and the 15 free knots: 1/N and C(mu_j).
fn ndf_build(alpha: f32, knots: array<f32, 15>) {
    NDF_TABLE.alpha = alpha;
    NDF_TABLE.s[0] = 0.0;
    var free = knots;
    for (var k = 1u; k < NDF_KNOTS; k = k + 1u) {
        NDF_TABLE.s[k] = free[k - 1u];
    }
    for (var j = 0u; j < NDF_MU_POINTS; j = j + 1u) {
        NDF_TABLE.c[j] = 0.0;
    }
    var gx = array<f32, 4>(0.1834346424956498, 0.5255324099163290, 0.7966664774136267, 0.9602898564975363);
    var gw = array<f32, 4>(0.3626837833783620, 0.3137066458778873, 0.2223810344533745, 0.1012285362903763);
    let a2 = alpha * alpha;
    var norm = 0.0;
    for (var k = 0u; k < NDF_KNOTS - 1u; k = k + 1u) {
        let hi = ndf_knot_t(k, alpha);
        let lo = ndf_knot_t(k + 1u, alpha);
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
            let x = clamp(ndf_knot_coordinate(sm2 / (1.0 + cm)), f32(k), f32(k + 1u));
            let e = exp(ndf_deviation(x));
            norm = norm + e * 2.0 * t * wt;
            let weight = e * rq * INV_PI * wt;
            for (var j = 0u; j < NDF_MU_POINTS; j = j + 1u) {
                let r = f32(j) / f32(NDF_MU_POINTS - 1u);
                let mu = r * r;
                let sw = sqrt(max(1.0 - mu * mu, 0.0));
                NDF_TABLE.c[j] = NDF_TABLE.c[j] + weight * ndf_facing_away(mu, sw, cm, sm);
            }
        }
    }
    let inv = 1.0 / norm;
    NDF_TABLE.inv_norm = inv;
    for (var j = 0u; j < NDF_MU_POINTS; j = j + 1u) {
        NDF_TABLE.c[j] = NDF_TABLE.c[j] * inv;
    }
}

// C(mu), linear in sqrt(mu) between the table's cosines mu_j = (j/64)^2.
fn ndf_c(mu: f32) -> f32 {
    let x = sqrt(clamp(mu, 0.0, 1.0)) * f32(NDF_MU_POINTS - 1u);
    let j = min(u32(x), NDF_MU_POINTS - 2u);
    let f = x - f32(j);
    return NDF_TABLE.c[j] + f * (NDF_TABLE.c[j + 1u] - NDF_TABLE.c[j]);
}

// D(h) G1(wi) G1(wo) / (4 mu_i mu_o) at m = any positive multiple of the half vector, with
// the chi+ side tests of Smith G1; wi and wo above the surface.
fn ndf_reflection(wi: vec3<f32>, wo: vec3<f32>, m: vec3<f32>) -> f32 {
    if (m.z <= 0.0 || dot(wi, m) * wi.z <= 0.0 || dot(wo, m) * wo.z <= 0.0) {
        return 0.0;
    }
    let a2 = NDF_TABLE.alpha * NDF_TABLE.alpha;
    let c2 = m.z * m.z;
    let s2 = m.x * m.x + m.y * m.y;
    let len2 = c2 + s2;
    let len = sqrt(len2);
    let t = a2 * c2 + s2;
    let ggx = a2 * (len2 * len2) / (PI * t * t);
    let e = exp(ndf_deviation(ndf_knot_coordinate(s2 / (len * (len + m.z))))) * NDF_TABLE.inv_norm;
    return ggx * e / (4.0 * (wi.z + ndf_c(wi.z)) * (wo.z + ndf_c(wo.z)));
}

// F(wi.h; eta) times the kernel, as the GGX lobe takes them (h from the unnormalised sum).
fn ndf_lobe(eta: f32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let sum = wi + wo;
    let len = length(sum);
    var m = sum;
    var cos_h = 0.5 * len;
    if (len < 1e-12) {
        m = vec3<f32>(0.0, 0.0, 1.0);
        cos_h = wi.z;
    }
    return fresnel_dielectric(cos_h, eta) * ndf_reflection(wi, wo, m);
}

// `ggx` with the data-driven NDF. Parameters: ks, alpha, eta, ndf1 .. ndf15.
fn ggx_ndf_prepare(o: u32) {
    ndf_build(ggx_ndf_alpha(o), array<f32, 15>(
        ggx_ndf_ndf1(o),
        ggx_ndf_ndf2(o),
        ggx_ndf_ndf3(o),
        ggx_ndf_ndf4(o),
        ggx_ndf_ndf5(o),
        ggx_ndf_ndf6(o),
        ggx_ndf_ndf7(o),
        ggx_ndf_ndf8(o),
        ggx_ndf_ndf9(o),
        ggx_ndf_ndf10(o),
        ggx_ndf_ndf11(o),
        ggx_ndf_ndf12(o),
        ggx_ndf_ndf13(o),
        ggx_ndf_ndf14(o),
        ggx_ndf_ndf15(o),
    ));
}

fn ggx_ndf_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (!GGX_NDF_PREPARED) {
        ggx_ndf_prepare(o);
    }
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    return ggx_ndf_ks(o) * ndf_lobe(ggx_ndf_eta(o), wi, wo);
}

// `fa(B)` with the data-driven NDF. Parameters: lobe.alpha, lobe.eta, lobe.ks, lobe.ndf1 .. 15.
fn fa_ndf_prepare(o: u32) {
    ndf_build(fa_ndf_lobe_alpha(o), array<f32, 15>(
        fa_ndf_lobe_ndf1(o),
        fa_ndf_lobe_ndf2(o),
        fa_ndf_lobe_ndf3(o),
        fa_ndf_lobe_ndf4(o),
        fa_ndf_lobe_ndf5(o),
        fa_ndf_lobe_ndf6(o),
        fa_ndf_lobe_ndf7(o),
        fa_ndf_lobe_ndf8(o),
        fa_ndf_lobe_ndf9(o),
        fa_ndf_lobe_ndf10(o),
        fa_ndf_lobe_ndf11(o),
        fa_ndf_lobe_ndf12(o),
        fa_ndf_lobe_ndf13(o),
        fa_ndf_lobe_ndf14(o),
        fa_ndf_lobe_ndf15(o),
    ));
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
    return fa_ndf_lobe_ks(o) * ndf_lobe(eta, wi, wo) + transmit * base;
}

// The `+ndf` node passes its inner model's value through.
fn ndf_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    return inner;
}
