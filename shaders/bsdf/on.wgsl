// Oren–Nayar 1994 qualitative model. Twin of src/bsdf/on.rs (see there for the
// vector form of the angular term). Parameters (generated accessors, declaration order): rho, sigma.
fn on_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let mu_i = wi.z;
    let mu_o = wo.z;
    if (mu_i <= 0.0 || mu_o <= 0.0) {
        return 0.0;
    }
    let rho = on_rho(o);
    let sigma = on_sigma(o);
    let s2 = sigma * sigma;
    let a = 1.0 - 0.5 * s2 / (s2 + 0.33);
    let b = 0.45 * s2 / (s2 + 0.09);
    let s = dot(wi, wo) - mu_i * mu_o;
    return rho * INV_PI * (a + b * max(s, 0.0) / max(mu_i, mu_o));
}
