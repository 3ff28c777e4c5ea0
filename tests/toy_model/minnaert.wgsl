// Minnaert's darkening law: f = ρ/π (μi μo)^(k−1). Twin of tests/toy_model/minnaert.rs.
// Parameters (generated accessors, declaration order): rho, k.
fn minnaert_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    return minnaert_rho(o) * INV_PI * pow(wi.z * wo.z, minnaert_k(o) - 1.0);
}
