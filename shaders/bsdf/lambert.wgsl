// Lambertian reflection: f = ρ/π. Twin of src/bsdf/lambert.rs.
// Parameters at P[o]: rho.
fn lambert_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    return P[o] * INV_PI;
}
