// Back-vector retroreflective GGX lobe added to a model. Twin of src/bsdf/retro.rs; D and
// G1 from microfacet.wgsl.
// Parameters (generated accessors, declaration order): kr, alpha_r; `inner` is the wrapped
// model's value, `eff` the lobe's entrance-angle efficiency (falloff.wgsl; 1 without +falloff).
fn retro_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32, eff: f32) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return inner;
    }
    let kr = retro_kr(o);
    let alpha = retro_alpha_r(o);
    let wo_back = vec3<f32>(-wo.x, -wo.y, wo.z);
    let h = half_vector(wi, wo_back);
    return inner + eff * kr * ggx_reflection(alpha, wi, wo_back, h);
}
