// dmg(B): diffuse micrograin layer over a base (Lucas et al. 2023). Twin of src/bsdf/dmg.rs.
// Parameters (generated accessors, declaration order): tau0, beta, rho_g; `base` is the base model's value.
fn dmg_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, base: f32) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let w = mg_weight(dmg_tau0(o), dmg_beta(o), wi.z, wo.z);
    return w * dmg_rho_g(o) * INV_PI + (1.0 - w) * base;
}
