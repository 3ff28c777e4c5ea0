// A second GGX specular lobe blended into a model: (1 − kc) inner + kc · lobe. Twin of
// src/bsdf/coat.rs; D and G1 from microfacet.wgsl.
// Parameters (generated accessors, declaration order): kc, alpha_c; `inner` is the
// wrapped model's value.
fn coat_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    let kc = coat_kc(o);
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return (1.0 - kc) * inner;
    }
    let h = half_vector(wi, wo);
    return (1.0 - kc) * inner + kc * ggx_reflection(coat_alpha_c(o), wi, wo, h);
}
