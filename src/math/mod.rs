//! Shared scattering math in f64: the CPU twin of `shaders/bsdf/common.wgsl`. The
//! microfacet distributions are in [`crate::bsdf::microfacet`].
//!
//! Conventions (docs/conventions.md): local frame with the normal on +z, directions point away
//! from the surface, μ = cos θ = z. Special functions (ln Γ, incomplete gamma and beta,
//! χ² and F tails, Gauss–Legendre quadrature) live in [`special`].

pub mod special;

pub use special::{beta_i, chi2_sf, f_sf, gamma_q, gauss_legendre, ln_gamma};

use glam::DVec3;

/// Unit direction from polar angle θ and azimuth φ (radians), upper hemisphere.
pub fn direction(theta: f64, phi: f64) -> DVec3 {
    let (st, ct) = theta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    DVec3::new(st * cp, st * sp, ct)
}

/// Exact unpolarised Fresnel reflectance of a dielectric interface, light arriving from
/// the side of index 1 onto index `eta` (Walter et al. 2007, Eq. 22). `cos_i` is the
/// cosine between the direction and the (micro)normal; its sign is ignored.
pub fn fresnel_dielectric(cos_i: f64, eta: f64) -> f64 {
    let c = cos_i.abs();
    let g2 = eta * eta - 1.0 + c * c;
    if g2 <= 0.0 {
        return 1.0; // total internal reflection (only possible for eta < 1)
    }
    let g = g2.sqrt();
    let a = (g - c) / (g + c);
    let b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0);
    (0.5 * a * a * (1.0 + b * b)).clamp(0.0, 1.0)
}

/// Reflection half vector of two directions (unnormalised input allowed).
pub fn half_vector(wi: DVec3, wo: DVec3) -> DVec3 {
    let h = wi + wo;
    let len = h.length();
    if len < 1e-12 {
        DVec3::Z
    } else {
        h / len
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_limits() {
        // Normal incidence: ((η−1)/(η+1))²
        let f0 = fresnel_dielectric(1.0, 1.5);
        assert!((f0 - 0.04).abs() < 1e-12, "{f0}");
        // Grazing incidence reflects everything.
        assert!((fresnel_dielectric(0.0, 1.5) - 1.0).abs() < 1e-12);
        // Index matched interface reflects nothing.
        assert!(fresnel_dielectric(0.3, 1.0).abs() < 1e-12);
    }
}
