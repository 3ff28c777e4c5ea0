// Back-vector retroreflective GGX lobe added to a model. Twin of src/model/retro.rs.
// Parameters at P[o]: kr, alpha_r; `inner` is the wrapped model's value.
fn retro_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, inner: f32) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return inner;
    }
    let kr = P[o];
    let alpha = P[o + 1u];
    let wo_back = vec3<f32>(-wo.x, -wo.y, wo.z);
    let h = half_vector(wi, wo_back);
    let g = ggx_g1(wi.z, dot(wi, h), alpha) * ggx_g1(wo.z, dot(wo_back, h), alpha);
    return inner + kr * ggx_d(h.z, alpha) * g / (4.0 * wi.z * wo.z);
}
