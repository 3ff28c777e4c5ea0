// Fresnel aggregate: GGX lobe + Fresnel-transmitted diffuse base. Twin of src/bsdf/fa.rs.
// Parameters (generated accessors, declaration order): lobe.alpha, lobe.eta, lobe.ks; `base` is the base model's value.
fn fa_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, base: f32) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let alpha = fa_lobe_alpha(o);
    let eta = fa_lobe_eta(o);
    let ks = fa_lobe_ks(o);
    let transmit = fresnel_transmittance(wi.z, eta) * fresnel_transmittance(wo.z, eta);
    return ggx_reflect(ks, alpha, eta, wi, wo) + transmit * base;
}
