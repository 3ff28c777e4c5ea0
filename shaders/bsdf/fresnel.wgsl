// The highlight's Fresnel curve made data-driven (`+fresnel`): in channel c the GGX
// highlight takes ks F(theta_d; eta) exp(s_c(theta_d)), s_c a Catmull-Rom spline through 9
// knots at x = 8 (1 - cos theta_d) (s_c = 0 at normal incidence), continued linearly past
// both ends (knot_factor, knots.wgsl). f32 twin of src/bsdf/fresnel.rs, which documents the
// curve and the knots.

// The GGX highlight with its Fresnel factor reshaped: ks F(wi.h; eta) factor D G1 G1 / (4 mu_i mu_o).
fn fresnel_highlight(ks: f32, alpha: f32, eta: f32, knots: array<f32, 9>, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let h = half_vector(wi, wo);
    let cos_d = dot(wi, h);
    return ks * fresnel_dielectric(cos_d, eta) * knot_factor(knots, cos_d) * ggx_reflection(alpha, wi, wo, h);
}

// `ggx` with a data-driven Fresnel curve. Parameters: ks, alpha, eta, fresnel1 .. fresnel8.
fn ggx_fresnel_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let knots = array<f32, 9>(
        0.0,
        ggx_fresnel_fresnel1(o),
        ggx_fresnel_fresnel2(o),
        ggx_fresnel_fresnel3(o),
        ggx_fresnel_fresnel4(o),
        ggx_fresnel_fresnel5(o),
        ggx_fresnel_fresnel6(o),
        ggx_fresnel_fresnel7(o),
        ggx_fresnel_fresnel8(o),
    );
    return fresnel_highlight(ggx_fresnel_ks(o), ggx_fresnel_alpha(o), ggx_fresnel_eta(o), knots, wi, wo);
}

// `fa(B)` whose highlight has a data-driven Fresnel curve. Parameters: lobe.alpha,
// lobe.eta, lobe.ks, lobe.fresnel1 .. 8; the base's transmittance stays dielectric.
fn fa_fresnel_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, base: f32) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let knots = array<f32, 9>(
        0.0,
        fa_fresnel_lobe_fresnel1(o),
        fa_fresnel_lobe_fresnel2(o),
        fa_fresnel_lobe_fresnel3(o),
        fa_fresnel_lobe_fresnel4(o),
        fa_fresnel_lobe_fresnel5(o),
        fa_fresnel_lobe_fresnel6(o),
        fa_fresnel_lobe_fresnel7(o),
        fa_fresnel_lobe_fresnel8(o),
    );
    let eta = fa_fresnel_lobe_eta(o);
    let transmit = fresnel_transmittance(wi.z, eta) * fresnel_transmittance(wo.z, eta);
    return fresnel_highlight(fa_fresnel_lobe_ks(o), fa_fresnel_lobe_alpha(o), eta, knots, wi, wo) + transmit * base;
}

// The `+fresnel` node passes its inner model's value through.
fn fresnel_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    return inner;
}

// `M+coat` whose coat lobe has a data-driven angular reflectance (the coat has no Fresnel
// factor of its own). Parameters: kc, alpha_c, fresnel_c1 .. 8.
fn coat_fresnel_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    let kc = coat_fresnel_kc(o);
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return (1.0 - kc) * inner;
    }
    let knots = array<f32, 9>(
        0.0,
        coat_fresnel_fresnel_c1(o),
        coat_fresnel_fresnel_c2(o),
        coat_fresnel_fresnel_c3(o),
        coat_fresnel_fresnel_c4(o),
        coat_fresnel_fresnel_c5(o),
        coat_fresnel_fresnel_c6(o),
        coat_fresnel_fresnel_c7(o),
        coat_fresnel_fresnel_c8(o),
    );
    let h = half_vector(wi, wo);
    let lobe = knot_factor(knots, dot(wi, h)) * ggx_reflection(coat_fresnel_alpha_c(o), wi, wo, h);
    return (1.0 - kc) * inner + kc * lobe;
}
