// Microfacet transmission (paper Eq. 1, Walter et al. 2007) with the TR, Beckmann, GTR
// (TR Smith G) and GG (its own Smith G, from the LUT) distributions of microfacet.wgsl, and
// the BTDF suffixes. Twin of src/bsdf/btdf.rs.
// Parameters (generated accessors, declaration order): tr: alpha, eta; beckmann: alpha, eta; gtr: alpha, gamma, eta;
// gg: beta, p, eta; scale: scale; absorb: tau; diffuse: kd. Suffixes get the wrapped
// model's value as `inner`.

const BTDF_L2_MIN: f32 = 1e-20;

// Walter's refraction microfacet of a valid configuration (valid = false: f_t = 0).
struct BtdfGeom {
    valid: bool,
    eta: f32,
    m: vec3<f32>,
    im: f32,
    om: f32,
    l2: f32,
}

fn btdf_geometry(wi: vec3<f32>, wo: vec3<f32>, eta: f32) -> BtdfGeom {
    var g: BtdfGeom;
    g.valid = false;
    g.eta = eta;
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

// |i.m| |o.m| (1 - F(i.m)) D (G1(i)/|mu_i|) (G1(o)/|mu_o|) / |i + eta o|^2; 0 when the
// configuration is not valid.
fn btdf_transmit(g: BtdfGeom, d: f32, g1i_over_mu: f32, g1o_over_mu: f32) -> f32 {
    if (!g.valid) {
        return 0.0;
    }
    return g.im * (-g.om) * fresnel_transmittance(g.im, g.eta) * d * g1i_over_mu * g1o_over_mu / g.l2;
}

fn btdf_tr_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let alpha = btdf_tr_alpha(o);
    let g = btdf_geometry(wi, wo, btdf_tr_eta(o));
    return btdf_transmit(g, ggx_d_vec(g.m, alpha), ggx_g1_over_mu(wi, alpha), ggx_g1_over_mu(wo, alpha));
}

fn btdf_beckmann_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let alpha = btdf_beckmann_alpha(o);
    let g = btdf_geometry(wi, wo, btdf_beckmann_eta(o));
    return btdf_transmit(g, beckmann_d_vec(g.m, alpha), ggx_g1_over_mu(wi, alpha), ggx_g1_over_mu(wo, alpha));
}

fn btdf_gtr_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let alpha = btdf_gtr_alpha(o);
    let g = btdf_geometry(wi, wo, btdf_gtr_eta(o));
    return btdf_transmit(g, gtr_d_vec(g.m, alpha, btdf_gtr_gamma(o)), ggx_g1_over_mu(wi, alpha), ggx_g1_over_mu(wo, alpha));
}

// The GG shape of the candidate (two ln Γ) and its G1(μ)/μ at every entry of its problem's
// μ table (kernel.wgsl), computed by `btdf_gg_prepare` when the generated module calls it
// after loading the candidate (BTDF_GG_PREPARED: the model has one GG node). Each G1
// takes two rows of four texel fetches of the Λ table, fetched lane by lane on lavapipe:
// 32 fetches per record were that model's whole cost there.
var<private> BTDF_GG_SHAPE: Gg;
var<private> BTDF_GG_G1_OVER_MU: array<f32, MU_TABLE_LEN>;

fn btdf_gg_prepare(o: u32) {
    BTDF_GG_SHAPE = gg_new(btdf_gg_beta(o), btdf_gg_p(o));
    if (MU_TABLES) {
        let n = mu_table_len();
        for (var i = 0u; i < n; i = i + 1u) {
            // A direction of that cosine (G1 depends on its polar angle alone).
            let mu = mu_table_at(i);
            let w = vec3<f32>(sqrt(max(1.0 - mu * mu, 0.0)), 0.0, mu);
            BTDF_GG_G1_OVER_MU[i] = gg_g1_over_mu(w, BTDF_GG_SHAPE);
        }
    }
}

// The GG Smith G from the Lambda table (LUT).
fn btdf_gg_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    var s: Gg;
    if (BTDF_GG_PREPARED) {
        s = BTDF_GG_SHAPE;
    } else {
        s = gg_new(btdf_gg_beta(o), btdf_gg_p(o));
    }
    let g = btdf_geometry(wi, wo, btdf_gg_eta(o));
    if (BTDF_GG_PREPARED && MU_TABLES) {
        let slots = min(RECORD_MU, vec2<u32>(MU_TABLE_LEN - 1u));
        return btdf_transmit(g, gg_d_vec(g.m, s), BTDF_GG_G1_OVER_MU[slots.x], BTDF_GG_G1_OVER_MU[slots.y]);
    }
    return btdf_transmit(g, gg_d_vec(g.m, s), gg_g1_over_mu(wi, s), gg_g1_over_mu(wo, s));
}

// Suffixes.
fn btdf_scale_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    return inner * btdf_scale_scale(o);
}

fn btdf_absorb_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    return inner * exp(-btdf_absorb_tau(o) / max(abs(wo.z), 1e-20));
}

fn btdf_diffuse_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    if (wi.z > 0.0 && wo.z < 0.0) {
        return inner + btdf_diffuse_kd(o) * INV_PI;
    }
    return inner;
}

// The anisotropic forms (`btdf(tr|beckmann|gg)+aniso`), over the stretched distributions
// of aniso.wgsl.

// Parameters: alpha_u, alpha_v, phi0, eta.
fn btdf_aniso_tr_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let au = btdf_aniso_tr_alpha_u(o);
    let av = btdf_aniso_tr_alpha_v(o);
    let f = aniso_frame(btdf_aniso_tr_phi0(o));
    let li = aniso_local(wi, f);
    let lo = aniso_local(wo, f);
    let g = btdf_geometry(li, lo, btdf_aniso_tr_eta(o));
    return btdf_transmit(g, aniso_ggx_d(g.m, au, av), aniso_ggx_g1_over_mu(li, au, av), aniso_ggx_g1_over_mu(lo, au, av));
}

// Parameters: alpha_u, alpha_v, phi0, eta (masked by the anisotropic TR Λ).
fn btdf_aniso_beckmann_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let au = btdf_aniso_beckmann_alpha_u(o);
    let av = btdf_aniso_beckmann_alpha_v(o);
    let f = aniso_frame(btdf_aniso_beckmann_phi0(o));
    let li = aniso_local(wi, f);
    let lo = aniso_local(wo, f);
    let g = btdf_geometry(li, lo, btdf_aniso_beckmann_eta(o));
    return btdf_transmit(g, aniso_beckmann_d(g.m, au, av), aniso_ggx_g1_over_mu(li, au, av), aniso_ggx_g1_over_mu(lo, au, av));
}

// Parameters: beta_u, beta_v, phi0, p, eta.
fn btdf_aniso_gg_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let bu = btdf_aniso_gg_beta_u(o);
    let bv = btdf_aniso_gg_beta_v(o);
    let s = gg_new(sqrt(bu * bv), btdf_aniso_gg_p(o));
    let f = aniso_frame(btdf_aniso_gg_phi0(o));
    let li = aniso_local(wi, f);
    let lo = aniso_local(wo, f);
    let g = btdf_geometry(li, lo, btdf_aniso_gg_eta(o));
    return btdf_transmit(g, aniso_gg_d(g.m, s, bu, bv), aniso_gg_g1_over_mu(li, s, bu, bv), aniso_gg_g1_over_mu(lo, s, bu, bv));
}
