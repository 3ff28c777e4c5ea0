// GGX microfacet reflection (Walter et al. 2007). Twin of src/bsdf/ggx.rs; the lobe
// (ggx_reflect, shared with fa) is in microfacet.wgsl. Parameters (generated accessors, declaration order): ks, alpha, eta.

fn ggx_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    return ggx_reflect(ggx_ks(o), ggx_alpha(o), ggx_eta(o), wi, wo);
}
