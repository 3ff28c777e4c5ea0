// Lambertian reflection: f = ρ/π. Twin of src/bsdf/lambert.rs.
// Parameters (generated accessors, declaration order): rho.
fn lambert_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    return lambert_rho(o) * INV_PI;
}
