// Minimal Retroreflective Microfacet lobe (MRM; back-vector GGX with height-correlated
// Smith G2 and Fresnel on the back-vector) added to a model. Twin of src/bsdf/mrm.rs; the
// GGX D is in microfacet.wgsl.
// Parameters (generated accessors, declaration order): mrm_eval: kr, alpha_r, eta_r;
// mrm82_eval: kr, alpha_r, f0, f82. `inner` is the wrapped model's
// value, `eff` the lobe's entrance-angle efficiency (falloff.wgsl; 1 without +falloff).

// mu Lambda(w) of GGX = a2 sin^2 / (2 (mu + sqrt(mu^2 + a2 sin^2))), finite at mu = 0.
fn mrm_mu_lambda(alpha: f32, w: vec3<f32>) -> f32 {
    let mu = abs(w.z);
    let as2 = alpha * alpha * (w.x * w.x + w.y * w.y);
    return as2 / (2.0 * (mu + sqrt(mu * mu + as2)));
}

// D(b) G2(wi, wo_back) / (4 mu_i mu_o), height-correlated Smith G2 (Heitz 2014, Eq. 99),
// written D / (4 (mu_i mu_o + mu_o a_i + mu_i a_o)) with a = mu Lambda.
fn mrm_kernel(alpha: f32, wi: vec3<f32>, wo_back: vec3<f32>, b: vec3<f32>) -> f32 {
    let denom = wi.z * wo_back.z + wo_back.z * mrm_mu_lambda(alpha, wi) + wi.z * mrm_mu_lambda(alpha, wo_back);
    return ggx_d_vec(b, alpha) / (4.0 * denom);
}

// OpenPBR F82-tint Fresnel, clamped to [0, 1]; mu_bar = 1/7.
fn mrm_schlick(mu: f32, f0: f32) -> f32 {
    let c = 1.0 - mu;
    let c2 = c * c;
    return f0 + (1.0 - f0) * c2 * c2 * c;
}

fn mrm_fresnel_f82(mu: f32, f0: f32, f82: f32) -> f32 {
    let mu_bar = 1.0 / 7.0;
    let cb = 1.0 - mu_bar;
    let cb2 = cb * cb;
    let peak = mu_bar * cb2 * cb2 * cb2;
    let c = 1.0 - mu;
    let c2 = c * c;
    let f = mrm_schlick(mu, f0) - mu * c2 * c2 * c2 * (1.0 - f82) * mrm_schlick(mu_bar, f0) / peak;
    return clamp(f, 0.0, 1.0);
}

fn mrm_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32, eff: f32) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return inner;
    }
    let alpha = mrm_alpha_r(o);
    let wo_back = vec3<f32>(-wo.x, -wo.y, wo.z);
    let b = half_vector(wi, wo_back);
    let f = fresnel_dielectric(dot(wi, b), mrm_eta_r(o));
    return inner + eff * mrm_kr(o) * f * mrm_kernel(alpha, wi, wo_back, b);
}

fn mrm82_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32, eff: f32) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return inner;
    }
    let alpha = mrm82_alpha_r(o);
    let wo_back = vec3<f32>(-wo.x, -wo.y, wo.z);
    let b = half_vector(wi, wo_back);
    let f = mrm_fresnel_f82(dot(wi, b), mrm82_f0(o), mrm82_f82(o));
    return inner + eff * mrm82_kr(o) * f * mrm_kernel(alpha, wi, wo_back, b);
}
