// Microfacet distributions in vector form: D(m) and Smith G1 of GGX (Trowbridge-Reitz),
// Beckmann, GTR and the generalized Gaussian. f32 twin of src/bsdf/microfacet.rs.
// m and w are unit vectors in the local frame (normal on +z); cos^2 = z^2 and
// sin^2 = x^2 + y^2 come from the components (never 1 - cos^2, which keeps only the
// rounding of cos near a sharp peak), and GGX is a2 / (pi (a2 cos^2 + sin^2)^2): the
// textbook cos^2 (a2 - 1) + 1 cancels in f32 for alpha below ~1e-2.
// Uses PI and INV_PI from common.wgsl.

// GGX D(m) = a2 / (pi (a2 cos^2 + sin^2)^2), 0 for m.z <= 0.
fn ggx_d_vec(m: vec3<f32>, alpha: f32) -> f32 {
    if (m.z <= 0.0) {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let t = a2 * (m.z * m.z) + (m.x * m.x + m.y * m.y);
    return a2 / (PI * t * t);
}

// GGX G1(w)/|w.z| = 2 / (mu + sqrt(mu^2 + a2 sin^2)), no side test; finite at mu = 0.
fn ggx_g1_over_mu(w: vec3<f32>, alpha: f32) -> f32 {
    let mu = abs(w.z);
    let s2 = w.x * w.x + w.y * w.y;
    return 2.0 / (mu + sqrt(mu * mu + alpha * alpha * s2));
}

// GGX Smith G1(w, m) = chi+((w.m)/(w.n)) / (1 + Lambda(w)).
fn ggx_g1(w: vec3<f32>, m: vec3<f32>, alpha: f32) -> f32 {
    if (dot(w, m) * w.z <= 0.0) {
        return 0.0;
    }
    return abs(w.z) * ggx_g1_over_mu(w, alpha);
}

// GGX reflection kernel D(h) G1(wi, h) G1(wo, h) / (4 mu_i mu_o) at the unit half vector h
// of wi and wo, both above the surface (Walter 2007, Eq. 20 without Fresnel).
fn ggx_reflection(alpha: f32, wi: vec3<f32>, wo: vec3<f32>, h: vec3<f32>) -> f32 {
    return ggx_d_vec(h, alpha) * ggx_g1(wi, h, alpha) * ggx_g1(wo, h, alpha) / (4.0 * wi.z * wo.z);
}
