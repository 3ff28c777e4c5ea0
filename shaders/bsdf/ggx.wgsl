// GGX microfacet reflection (Walter et al. 2007). Twin of src/bsdf/ggx.rs; D and G1 from
// microfacet.wgsl. Parameters at P[o]: ks, alpha, eta.

fn ggx_reflect(ks: f32, alpha: f32, eta: f32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let h = half_vector(wi, wo);
    return ks * fresnel_dielectric(dot(wi, h), eta) * ggx_reflection(alpha, wi, wo, h);
}

fn ggx_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    return ggx_reflect(P[o], P[o + 1u], P[o + 2u], wi, wo);
}
