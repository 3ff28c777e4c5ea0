// rmg(B): rough dielectric micrograin layer over a base (Lucas et al. 2023). Twin of
// src/bsdf/rmg.rs. Parameters (generated accessors, declaration order): tau0, beta, rho_g, eta_g; `base` is the base value.
fn rmg_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>, base: f32) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let tau0 = rmg_tau0(o);
    let beta = rmg_beta(o);
    let w = mg_weight(tau0, beta, wi.z, wo.z);
    let grain = mg_rough_grain(tau0, beta, rmg_eta_g(o), rmg_rho_g(o), wi, wo);
    return w * grain + (1.0 - w) * base;
}

// Per candidate, before the record loop (RMG_PREPARED: the model has one rmg node): G1(μ)/μ
// at every μ of the candidate's problem (micrograin.wgsl, MG_G1_OVER_MU). The CPU twin
// tabulates the same factors per block of directions, keyed by the same μ (RoughGrainMemo).
fn rmg_prepare(o: u32) {
    mg_fill_g1_table(rmg_tau0(o), rmg_beta(o));
}
