// Microfacet transmission (paper Eq. 1, Walter et al. 2007) with the TR, Beckmann and GTR
// distributions (TR Smith G), and the BTDF suffixes. Twin of src/model/btdf.rs.
// btdf(gg) is in btdf_gg.wgsl (it reads the LUT); it uses the core functions below.
// Parameters at P[o]: tr: alpha, eta; beckmann: alpha, eta; gtr: alpha, gamma, eta;
// scale: scale; absorb: tau; diffuse: kd. Suffixes get the wrapped model's value as `inner`.

const BTDF_L2_MIN: f32 = 1e-20;
const BTDF_C2_MIN: f32 = 1e-30;

// Walter's refraction microfacet of a valid configuration (valid = false: f_t = 0).
struct BtdfGeom {
    valid: bool,
    m: vec3<f32>,
    im: f32,
    om: f32,
    l2: f32,
}

fn btdf_geometry(wi: vec3<f32>, wo: vec3<f32>, eta: f32) -> BtdfGeom {
    var g: BtdfGeom;
    g.valid = false;
    g.m = vec3<f32>(0.0, 0.0, 1.0);
    g.im = 0.0;
    g.om = 0.0;
    g.l2 = 1.0;
    if (!(wi.z > 0.0 && wo.z < 0.0 && eta > 1.0)) {
        return g;
    }
    // v = i + eta o, keeping its relative accuracy when it is small (eta near 1, o near -i).
    let v = (wi + wo) + (eta - 1.0) * wo;
    let l2 = dot(v, v);
    if (!(l2 > BTDF_L2_MIN)) {
        return g;
    }
    var m = -v * inverseSqrt(l2);
    if (m.z < 0.0) {
        m = -m;
    }
    let im = dot(wi, m);
    let om = dot(wo, m);
    if (!(m.z > 0.0 && im > 0.0 && om < 0.0)) {
        return g;
    }
    g.valid = true;
    g.m = m;
    g.im = im;
    g.om = om;
    g.l2 = l2;
    return g;
}

// |i.m| |o.m| (1 - F(i.m)) D (G1(i)/|mu_i|) (G1(o)/|mu_o|) / |i + eta o|^2.
fn btdf_transmit(g: BtdfGeom, eta: f32, d: f32, g1i_over_mu: f32, g1o_over_mu: f32) -> f32 {
    return g.im * (-g.om) * (1.0 - fresnel_dielectric(g.im, eta)) * d * g1i_over_mu * g1o_over_mu / g.l2;
}

// NDFs in terms of c2 = cos^2 and s2 = sin^2 of the microfacet normal.
fn btdf_tr_d(c2: f32, s2: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let t = a2 * c2 + s2;
    return a2 / (PI * t * t);
}

fn btdf_beckmann_d(c2: f32, s2: f32, alpha: f32) -> f32 {
    if (c2 < BTDF_C2_MIN) {
        return 0.0;
    }
    let a2 = alpha * alpha;
    return exp(-(s2 / c2) / a2 - 2.0 * log(c2)) / (PI * a2);
}

fn btdf_gtr_d(c2: f32, s2: f32, alpha: f32, gamma: f32) -> f32 {
    let a2 = max(alpha * alpha, 1e-12);
    return gtr_norm(a2, gamma) * exp(-gamma * log(a2 * c2 + s2));
}

// Smith G1(v)/|v.z| for Trowbridge-Reitz: 2 / (mu + sqrt(mu^2 + alpha^2 sin^2)).
fn btdf_tr_g1_over_mu(v: vec3<f32>, alpha: f32) -> f32 {
    let mu = abs(v.z);
    let s2 = v.x * v.x + v.y * v.y;
    return 2.0 / (mu + sqrt(mu * mu + alpha * alpha * s2));
}

fn btdf_c2(g: BtdfGeom) -> f32 {
    return g.m.z * g.m.z;
}

fn btdf_s2(g: BtdfGeom) -> f32 {
    return g.m.x * g.m.x + g.m.y * g.m.y;
}

fn btdf_tr_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let alpha = P[o];
    let eta = P[o + 1u];
    let g = btdf_geometry(wi, wo, eta);
    if (!g.valid) {
        return 0.0;
    }
    let d = btdf_tr_d(btdf_c2(g), btdf_s2(g), alpha);
    return btdf_transmit(g, eta, d, btdf_tr_g1_over_mu(wi, alpha), btdf_tr_g1_over_mu(wo, alpha));
}

fn btdf_beckmann_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let alpha = P[o];
    let eta = P[o + 1u];
    let g = btdf_geometry(wi, wo, eta);
    if (!g.valid) {
        return 0.0;
    }
    let d = btdf_beckmann_d(btdf_c2(g), btdf_s2(g), alpha);
    return btdf_transmit(g, eta, d, btdf_tr_g1_over_mu(wi, alpha), btdf_tr_g1_over_mu(wo, alpha));
}

fn btdf_gtr_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let alpha = P[o];
    let gamma = P[o + 1u];
    let eta = P[o + 2u];
    let g = btdf_geometry(wi, wo, eta);
    if (!g.valid) {
        return 0.0;
    }
    let d = btdf_gtr_d(btdf_c2(g), btdf_s2(g), alpha, gamma);
    return btdf_transmit(g, eta, d, btdf_tr_g1_over_mu(wi, alpha), btdf_tr_g1_over_mu(wo, alpha));
}

// Suffixes.
fn btdf_scale_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    return inner * P[o];
}

fn btdf_absorb_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    return inner * exp(-P[o] / max(abs(wo.z), 1e-20));
}

fn btdf_diffuse_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    if (wi.z > 0.0 && wo.z < 0.0) {
        return inner + P[o] * INV_PI;
    }
    return inner;
}
