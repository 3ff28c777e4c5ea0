// Energy-preserving Oren–Nayar (Portsmouth, Kutz, Hill 2025). Twin of src/bsdf/eon.rs,
// which cites the equations. Parameters (generated accessors, declaration order): rho, r.

const C1_FON: f32 = 0.287793409;   // 1/2 − 2/(3π)
const C2_FON: f32 = 0.072488718;   // 2/3 − 28/(15π)

fn e_fon_exact(mu_in: f32, r: f32) -> f32 {
    let mu = clamp(mu_in, 1e-7, 1.0);
    let af = 1.0 / (1.0 + C1_FON * r);
    let bf = r * af;
    let si = sqrt(max(1.0 - mu * mu, 0.0));
    let g = si * (acos(mu) - si * mu) + (2.0 / 3.0) * ((si / mu) * (1.0 - si * si * si) - si);
    return af + bf * INV_PI * g;
}

fn f_fon(rho: f32, r: f32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    let s = dot(wi, wo) - wi.z * wo.z;
    var s_over_t = s;
    if (s > 0.0) {
        s_over_t = s / max(wi.z, wo.z);
    }
    let af = 1.0 / (1.0 + C1_FON * r);
    return rho * INV_PI * af * (1.0 + r * s_over_t);
}

fn eon_eval(o: u32, wi: vec3<f32>, wo: vec3<f32>) -> f32 {
    if (wi.z <= 0.0 || wo.z <= 0.0) {
        return 0.0;
    }
    let rho = eon_rho(o);
    let r = eon_r(o);
    let f_ss = f_fon(rho, r, wi, wo);
    let af = 1.0 / (1.0 + C1_FON * r);
    let e_avg = af * (1.0 + C2_FON * r);
    let rho_ms = rho * rho * e_avg / (1.0 - rho * (1.0 - e_avg));
    let eps = 1e-7;
    let f_ms = rho_ms * INV_PI * max(1.0 - e_fon_exact(wo.z, r), eps) * max(1.0 - e_fon_exact(wi.z, r), eps)
        / max(1.0 - e_avg, eps);
    return f_ss + f_ms;
}
