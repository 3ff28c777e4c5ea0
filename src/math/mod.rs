//! Shared scattering math in f64: the CPU twin of `shaders/common.wgsl`.
//!
//! Conventions (docs/conventions.md): local frame with the normal on +z, directions point away
//! from the surface, μ = cos θ = z. Special functions (ln Γ, incomplete gamma and beta,
//! χ² and F tails, Gauss–Legendre quadrature) live in [`special`].

pub mod special;

pub use special::{beta_i, chi2_sf, f_sf, gamma_q, gauss_legendre, ln_gamma};

use glam::DVec3;
use std::f64::consts::PI;

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

/// Trowbridge–Reitz / GGX normal distribution D(m) for cos θm (Walter 2007, Eq. 33).
pub fn ggx_d(cos_m: f64, alpha: f64) -> f64 {
    if cos_m <= 0.0 {
        return 0.0;
    }
    let a2 = alpha * alpha;
    let c2 = cos_m * cos_m;
    let t = c2 * (a2 - 1.0) + 1.0;
    a2 / (PI * t * t)
}

/// Smith Λ for the GGX distribution at direction cosine `cos_v` (Heitz 2014, Eq. 72).
pub fn ggx_lambda(cos_v: f64, alpha: f64) -> f64 {
    let c2 = (cos_v * cos_v).max(1e-300);
    let tan2 = ((1.0 - c2) / c2).max(0.0);
    0.5 * ((1.0 + alpha * alpha * tan2).sqrt() - 1.0)
}

/// Smith G1 for GGX (Walter 2007, Eq. 34); zero when v and m are on opposite sides
/// relative to the macro-normal.
pub fn ggx_g1(cos_v: f64, cos_vm: f64, alpha: f64) -> f64 {
    if cos_v * cos_vm <= 0.0 {
        return 0.0;
    }
    1.0 / (1.0 + ggx_lambda(cos_v, alpha))
}

/// Beckmann NDF (Walter 2007, Eq. 25).
pub fn beckmann_d(cos_m: f64, alpha: f64) -> f64 {
    if cos_m <= 0.0 {
        return 0.0;
    }
    let c2 = cos_m * cos_m;
    let tan2 = (1.0 - c2) / c2;
    let a2 = alpha * alpha;
    (-tan2 / a2).exp() / (PI * a2 * c2 * c2)
}

/// Burley's generalised Trowbridge–Reitz NDF (Burley 2012, Appendix B), normalised so
/// that ∫ D(m) cos θm dω = 1; γ = 2 is GGX, γ = 1 is Berry.
pub fn gtr_d(cos_m: f64, alpha: f64, gamma: f64) -> f64 {
    if cos_m <= 0.0 {
        return 0.0;
    }
    let a2 = (alpha * alpha).max(1e-12);
    let c2 = cos_m * cos_m;
    let denom = a2 * c2 + (1.0 - c2);
    gtr_norm(a2, gamma) * denom.powf(-gamma)
}

/// Normalisation constant of GTR: (γ−1)(α²−1) / (π (1 − (α²)^(1−γ))), with its limits
/// at γ = 1 and α = 1 taken analytically (the plain form is 0/0 there).
pub fn gtr_norm(a2: f64, gamma: f64) -> f64 {
    let ln_a2 = a2.ln();
    let x = (1.0 - gamma) * ln_a2; // (α²)^(1−γ) = e^x
                                   // (γ−1)(α²−1) / (1 − e^x) = (α²−1)/ln α² · (x / (e^x − 1)) ... with x/(e^x−1) → 1 at x→0
    let ratio = if x.abs() < 1e-8 {
        1.0 - 0.5 * x
    } else {
        x / x.exp_m1()
    };
    let a_term = if ln_a2.abs() < 1e-8 {
        1.0 + 0.5 * ln_a2
    } else {
        (a2 - 1.0) / ln_a2
    };
    a_term * ratio / PI
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

    #[test]
    fn gtr_gamma_two_is_ggx() {
        for &alpha in &[0.01, 0.1, 0.5, 0.9, 1.0] {
            for &c in &[0.05, 0.3, 0.7, 1.0] {
                let a = gtr_d(c, alpha, 2.0);
                let b = ggx_d(c, alpha);
                assert!(
                    (a - b).abs() <= 1e-9 * b.max(1.0),
                    "alpha {alpha} c {c}: {a} vs {b}"
                );
            }
        }
    }

    #[test]
    fn ndfs_are_normalised() {
        // ∫ D(m) cos θm dω = 2π ∫ D(cos) cos sin dθ
        let n = 200_000;
        for &alpha in &[0.05, 0.3, 0.8] {
            for (name, d) in [
                (
                    "ggx",
                    Box::new(move |c: f64| ggx_d(c, alpha)) as Box<dyn Fn(f64) -> f64>,
                ),
                ("beckmann", Box::new(move |c: f64| beckmann_d(c, alpha))),
                ("gtr1.5", Box::new(move |c: f64| gtr_d(c, alpha, 1.5))),
                ("gtr1", Box::new(move |c: f64| gtr_d(c, alpha, 1.0))),
                ("gtr3", Box::new(move |c: f64| gtr_d(c, alpha, 3.0))),
            ] {
                let mut s = 0.0;
                for k in 0..n {
                    // integrate in u = cos θ: dω = 2π du
                    let u = (k as f64 + 0.5) / n as f64;
                    s += d(u) * u;
                }
                let integral = 2.0 * PI * s / n as f64;
                assert!(
                    (integral - 1.0).abs() < 2e-3,
                    "{name} alpha {alpha}: {integral}"
                );
            }
        }
    }
}
