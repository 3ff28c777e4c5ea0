// A GGX lobe whose NDF and Fresnel curve are both data-driven (`M+ndf+fresnel`): in
// channel c, ks F(theta_d; eta) exp(s_c(theta_d)) D G1 G1 / (4 mu_i mu_o) with D, G1 the
// tabulated NDF of ndf.wgsl (its table built by the prepare functions) and exp(s_c) the
// Fresnel curve of knots.wgsl. f32 twin of src/bsdf/ndf_fresnel.rs.

// F(wi.h; eta) times the curve's factor times the kernel, the half vector as `ndf_lobe`
// takes it (`ndf_half`).
fn ndf_fresnel_lobe(tab: ptr<private, NdfTable>, eta: f32, knots: array<f32, 9>, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let h = ndf_half(wi, wo);
    return fresnel_dielectric(h.w, eta) * knot_factor(knots, h.w) * ndf_reflection(tab, wi, wo, h.xyz);
}

// `ggx` with a data-driven NDF and Fresnel curve. Parameters: ks, alpha, eta, ndf1 ..
// ndf31, fresnel1 .. fresnel8.
fn ggx_ndf_fresnel_prepare(o: u32) {
    for (var k = 1u; k < NDF_KNOTS; k = k + 1u) {
        NDF_TABLE.s[k] = ggx_ndf_fresnel_ndf1_run(o, k - 1u);
    }
    ndf_build(&NDF_TABLE, ggx_ndf_fresnel_alpha(o));
}

fn ggx_ndf_fresnel_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (!GGX_NDF_FRESNEL_PREPARED) {
        ggx_ndf_fresnel_prepare(o);
    }
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let knots = array<f32, 9>(
        0.0,
        ggx_ndf_fresnel_fresnel1(o),
        ggx_ndf_fresnel_fresnel2(o),
        ggx_ndf_fresnel_fresnel3(o),
        ggx_ndf_fresnel_fresnel4(o),
        ggx_ndf_fresnel_fresnel5(o),
        ggx_ndf_fresnel_fresnel6(o),
        ggx_ndf_fresnel_fresnel7(o),
        ggx_ndf_fresnel_fresnel8(o),
    );
    return ggx_ndf_fresnel_ks(o) * ndf_fresnel_lobe(&NDF_TABLE, ggx_ndf_fresnel_eta(o), knots, wi, wo);
}

// `fa(B)` whose highlight has a data-driven NDF and Fresnel curve. Parameters:
// lobe.alpha, lobe.eta, lobe.ks, lobe.ndf1 .. 15, lobe.fresnel1 .. 8; the base's
// transmittance stays dielectric.
fn fa_ndf_fresnel_prepare(o: u32) {
    for (var k = 1u; k < NDF_KNOTS; k = k + 1u) {
        NDF_TABLE.s[k] = fa_ndf_fresnel_lobe_ndf1_run(o, k - 1u);
    }
    ndf_build(&NDF_TABLE, fa_ndf_fresnel_lobe_alpha(o));
}

fn fa_ndf_fresnel_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, base: f32) -> f32 {
    if (!FA_NDF_FRESNEL_PREPARED) {
        fa_ndf_fresnel_prepare(o);
    }
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let knots = array<f32, 9>(
        0.0,
        fa_ndf_fresnel_lobe_fresnel1(o),
        fa_ndf_fresnel_lobe_fresnel2(o),
        fa_ndf_fresnel_lobe_fresnel3(o),
        fa_ndf_fresnel_lobe_fresnel4(o),
        fa_ndf_fresnel_lobe_fresnel5(o),
        fa_ndf_fresnel_lobe_fresnel6(o),
        fa_ndf_fresnel_lobe_fresnel7(o),
        fa_ndf_fresnel_lobe_fresnel8(o),
    );
    let eta = fa_ndf_fresnel_lobe_eta(o);
    let transmit = fresnel_transmittance(wi.z, eta) * fresnel_transmittance(wo.z, eta);
    return fa_ndf_fresnel_lobe_ks(o) * ndf_fresnel_lobe(&NDF_TABLE, eta, knots, wi, wo) + transmit * base;
}

// `M+coat` whose coat lobe has a data-driven NDF and angular reflectance (no Fresnel
// factor of its own). Parameters: kc, alpha_c, ndf_c1 .. 15, fresnel_c1 .. 8.
fn coat_ndf_fresnel_prepare(o: u32) {
    for (var k = 1u; k < NDF_KNOTS; k = k + 1u) {
        COAT_NDF_TABLE.s[k] = coat_ndf_fresnel_ndf_c1_run(o, k - 1u);
    }
    ndf_build(&COAT_NDF_TABLE, coat_ndf_fresnel_alpha_c(o));
}

fn coat_ndf_fresnel_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    if (!COAT_NDF_FRESNEL_PREPARED) {
        coat_ndf_fresnel_prepare(o);
    }
    let kc = coat_ndf_fresnel_kc(o);
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return (1.0 - kc) * inner;
    }
    let knots = array<f32, 9>(
        0.0,
        coat_ndf_fresnel_fresnel_c1(o),
        coat_ndf_fresnel_fresnel_c2(o),
        coat_ndf_fresnel_fresnel_c3(o),
        coat_ndf_fresnel_fresnel_c4(o),
        coat_ndf_fresnel_fresnel_c5(o),
        coat_ndf_fresnel_fresnel_c6(o),
        coat_ndf_fresnel_fresnel_c7(o),
        coat_ndf_fresnel_fresnel_c8(o),
    );
    let sum = wi + wo;
    let lobe = knot_factor(knots, 0.5 * length(sum)) * ndf_reflection(&COAT_NDF_TABLE, wi, wo, sum);
    return (1.0 - kc) * inner + kc * lobe;
}
