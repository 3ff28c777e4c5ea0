// Shared scattering math in f32: the GPU twin of src/math/mod.rs.
// Conventions (DESIGN §1): normal on +z, directions point away from the surface.

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

// Beckmann NDF (Walter 2007, Eq. 25).
fn beckmann_d(cos_m: f32, alpha: f32) -> f32 {
    if (cos_m <= 0.0) {
        return 0.0;
    }
    let c2 = cos_m * cos_m;
    let tan2 = (1.0 - c2) / c2;
    let a2 = alpha * alpha;
    return exp(-tan2 / a2) / (PI * a2 * c2 * c2);
}

// Normalisation of Burley's GTR with its γ = 1 and α = 1 limits (see src/math/mod.rs).
fn gtr_norm(a2: f32, gamma: f32) -> f32 {
    let ln_a2 = log(a2);
    let x = (1.0 - gamma) * ln_a2;
    var ratio = 1.0 - 0.5 * x;
    if (abs(x) >= 1e-4) {
        ratio = x / (exp(x) - 1.0);
    }
    var a_term = 1.0 + 0.5 * ln_a2;
    if (abs(ln_a2) >= 1e-4) {
        a_term = (a2 - 1.0) / ln_a2;
    }
    return a_term * ratio * INV_PI;
}

// Burley 2012 generalised Trowbridge–Reitz NDF; γ = 2 is GGX.
fn gtr_d(cos_m: f32, alpha: f32, gamma: f32) -> f32 {
    if (cos_m <= 0.0) {
        return 0.0;
    }
    let a2 = max(alpha * alpha, 1e-12);
    let c2 = cos_m * cos_m;
    let denom = a2 * c2 + (1.0 - c2);
    return gtr_norm(a2, gamma) * pow(denom, -gamma);
}

fn half_vector(wi: vec3<f32>, wo: vec3<f32>) -> vec3<f32> {
    let h = wi + wo;
    let len = length(h);
    if (len < 1e-12) {
        return vec3<f32>(0.0, 0.0, 1.0);
    }
    return h / len;
}
