// GGX microfacet reflection (Walter et al. 2007). Twin of src/model/ggx.rs.
// Parameters at P[o]: ks, alpha, eta.

fn ggx_reflect(ks: f32, alpha: f32, eta: f32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let mu_i = wi.z;
    let mu_o = wo.z;
    if (mu_i <= 0.0 || mu_o <= 0.0) {
        return 0.0;
    }
    let h = half_vector(wi, wo);
    let ih = dot(wi, h);
    let g = ggx_g1(mu_i, ih, alpha) * ggx_g1(mu_o, dot(wo, h), alpha);
    return ks * fresnel_dielectric(ih, eta) * ggx_d(h.z, alpha) * g / (4.0 * mu_i * mu_o);
}

fn ggx_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    return ggx_reflect(P[o], P[o + 1u], P[o + 2u], wi, wo);
}
