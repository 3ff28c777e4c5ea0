// Shared scattering math in f32: the GPU twin of src/math/mod.rs.
// Conventions (docs/conventions.md): normal on +z, directions point away from the surface.

const PI: f32 = 3.14159265358979;
const INV_PI: f32 = 0.318309886183791;

// Exact unpolarised dielectric Fresnel, index 1 → eta (Walter et al. 2007, Eq. 22).
fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let c = abs(cos_i);
    let g2 = eta * eta - 1.0 + c * c;
    if (g2 <= 0.0) {
        return 1.0;
    }
    let g = sqrt(g2);
    let a = (g - c) / (g + c);
    let b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
    return clamp(0.5 * a * a * (1.0 + b * b), 0.0, 1.0);
}

// 1 - fresnel_dielectric without its cancellation where F -> 1 (twin of
// math::fresnel_transmittance): T = (Ts + Tp)/2 = 2cg (1/(c + g)^2 + eta^2/(eta^2 c + g)^2),
// g = eta cos(theta_t).
fn fresnel_transmittance(cos_i: f32, eta: f32) -> f32 {
    let c = abs(cos_i);
    let g2 = eta * eta - 1.0 + c * c;
    if (g2 <= 0.0) {
        return 0.0;
    }
    let g = sqrt(g2);
    let e2c = eta * eta * c;
    return clamp(2.0 * c * g * (1.0 / ((c + g) * (c + g)) + eta * eta / ((e2c + g) * (e2c + g))), 0.0, 1.0);
}

fn half_vector(wi: vec3<f32>, wo: vec3<f32>) -> vec3<f32> {
    let h = wi + wo;
    let len = length(h);
    if (len < 1e-12) {
        return vec3<f32>(0.0, 0.0, 1.0);
    }
    return h / len;
}
