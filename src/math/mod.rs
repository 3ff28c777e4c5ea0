//! Shared scattering math in f64: the CPU twin of `shaders/bsdf/common.wgsl`. The
//! microfacet distributions are in [`crate::bsdf::microfacet`].
//!
//! Conventions (docs/conventions.md): local frame with the normal on +z, directions point away
//! from the surface, μ = cos θ = z. Special functions (ln Γ, incomplete gamma and beta,
//! χ² and F tails, Gauss–Legendre quadrature) live in [`special`].

pub mod lanes;
pub mod special;

pub use special::{beta_i, chi2_sf, f_sf, gamma_q, gauss_legendre, ln_gamma};

use glam::DVec3;
use lanes::Real;

/// Σ aᵢbᵢ in eight interleaved partial sums (vectorisable; an in-order sum is not).
pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(x, y)| x * y)
        .sum();
    for (x, y) in ca.zip(cb) {
        for i in 0..8 {
            acc[i] += x[i] * y[i];
        }
    }
    acc.iter().sum::<f64>() + tail
}

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
    fresnel_dielectric_in(cos_i, eta)
}

/// [`fresnel_dielectric`] over any [`Real`] (lanes of directions; `f64` is the reference).
#[inline(always)]
pub fn fresnel_dielectric_in<R: Real>(cos_i: R, eta: R) -> R {
    let c = cos_i.abs();
    let g2 = c.mul_add(c, eta * eta - R::splat(1.0));
    // g² ≤ 0: total internal reflection (only possible for eta < 1).
    let tir = g2.le(R::zero());
    let g = g2.sqrt();
    // ½ a² (1 + b²) with a = (g − c)/(g + c), b = n/d, n = c(g + c) − 1, d = c(g − c) + 1,
    // over one common denominator: one division instead of two (the CPU backend evaluates
    // this once per sample direction; d ≥ 1 − c² > 0 and g + c > 0 past the test above).
    let (gm, gp) = (g - c, g + c);
    // (x.mul_add(y, z) is x·y + z, fused in f32 lanes only: the reference keeps its bits.)
    let n = c.mul_add(gp, R::splat(-1.0));
    let d = c.mul_add(gm, R::splat(1.0));
    let f = (R::splat(0.5) * gm * gm * d.mul_add(d, n * n) / (gp * gp * (d * d))).clamp(0.0, 1.0);
    R::select(tir, R::splat(1.0), f)
}

/// 1 − [`fresnel_dielectric`], the unpolarised transmittance, without the cancellation of
/// 1 − F where F → 1 (grazing microfacets in a BTDF's tails lose up to 1e4 ulps in f32
/// that way; the WGSL twin `fresnel_transmittance` in shaders/bsdf/common.wgsl is what
/// that matters for). With g = η cos θt (g² = η² − 1 + c²): T_s = 1 − R_s = 4cg/(c + g)²
/// and T_p = 1 − R_p = 4η²cg/(η²c + g)² (Born & Wolf, Principles of Optics, §1.5.3), and
/// T = (T_s + T_p)/2, a sum of positive terms.
pub fn fresnel_transmittance(cos_i: f64, eta: f64) -> f64 {
    fresnel_transmittance_in(cos_i, eta)
}

/// [`fresnel_transmittance`] over any [`Real`].
#[inline(always)]
pub fn fresnel_transmittance_in<R: Real>(cos_i: R, eta: R) -> R {
    let c = cos_i.abs();
    let g2 = c.mul_add(c, eta * eta - R::splat(1.0));
    // g² ≤ 0: total internal reflection (only possible for eta < 1).
    let tir = g2.le(R::zero());
    let g = g2.sqrt();
    let e2 = eta * eta;
    // 2cg (1/s² + η²/p²), s = c + g, p = η²c + g, over one common denominator (one
    // division instead of two; still a sum of positive terms).
    let s2 = (c + g) * (c + g);
    let p = e2.mul_add(c, g);
    let p2 = p * p;
    let t = (R::splat(2.0) * c * g * e2.mul_add(s2, p2) / (s2 * p2)).clamp(0.0, 1.0);
    R::select(tir, R::zero(), t)
}

/// Reflection half vector of two directions (unnormalised input allowed).
pub fn half_vector(wi: DVec3, wo: DVec3) -> DVec3 {
    let h = wi + wo;
    let len = h.length();
    if len < 1e-12 {
        DVec3::Z
    } else {
        // One division and three products rather than three divisions (≤ 1 ulp apart).
        h * (1.0 / len)
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

    /// T = 1 − F in f64 (where 1 − F is still accurate), and in f32 it keeps its relative
    /// accuracy at grazing microfacets where 1 − F in f32 does not.
    #[test]
    fn fresnel_transmittance_is_one_minus_reflectance() {
        for eta in [1.0, 1.05, 1.5, 2.4, 5.0] {
            for k in 0..=100 {
                let c = k as f64 / 100.0;
                let (t, f) = (fresnel_transmittance(c, eta), fresnel_dielectric(c, eta));
                assert!(
                    (t - (1.0 - f)).abs() < 1e-13,
                    "eta {eta} c {c}: {t} vs {}",
                    1.0 - f
                );
            }
        }
        // f32 at c = 1e-4, eta = 1.5: T ≈ 4.5e-4; the two forms against the f64 value.
        let (c, eta) = (1e-4f64, 1.5f64);
        let exact = fresnel_transmittance(c, eta);
        let (c32, e32) = (c as f32, eta as f32);
        let g = (e32 * e32 - 1.0 + c32 * c32).sqrt();
        let e2c = e32 * e32 * c32;
        let t32 =
            2.0 * c32 * g * (1.0 / ((c32 + g) * (c32 + g)) + e32 * e32 / ((e2c + g) * (e2c + g)));
        let a = (g - c32) / (g + c32);
        let b = (c32 * (g + c32) - 1.0) / (c32 * (g - c32) + 1.0);
        let one_minus_f32 = 1.0 - 0.5 * a * a * (1.0 + b * b);
        let rel = |v: f32| (v as f64 - exact).abs() / exact;
        assert!(rel(t32) < 1e-6, "stable form in f32: {:e}", rel(t32));
        assert!(
            rel(one_minus_f32) > 1e-5,
            "1 − F in f32 was expected to lose digits: {:e}",
            rel(one_minus_f32)
        );
    }
}
