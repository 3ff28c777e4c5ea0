//! Microfacet distributions in vector form: the normal distribution D(m) and the Smith
//! masking Λ(ω) / G1(ω, m) of GGX (Trowbridge–Reitz), Beckmann, Burley's GTR and the
//! generalized Gaussian, shared by the reflection lobes (`ggx`, the lobe of `fa`, `+retro`),
//! the transmission terms (`btdf`) and the micrograin NDF. Twin: `shaders/bsdf/microfacet.wgsl`.
//!
//! Conventions (DESIGN §1): local frame with the macro-normal on +z; m and ω are unit
//! vectors. Every form takes cos²θ = z² and sin²θ = x² + y² from the components, never
//! sin²θ = 1 − cos²θ: near a sharp peak (α ≲ 1e-2) 1 − cos²θ keeps only the rounding of
//! cos θ (f32: 6e-8, while sin²θ is ~α² = 4e-6 at α = 2e-3), and the textbook GGX
//! denominator cos²θ (α² − 1) + 1 cancels the same way. GGX is written
//! D = α² / (π (α² cos²θ + sin²θ)²), which has no cancellation at all.
//!
//! D is normalised so that ∫ D(m) m.z dω_m = 1 and is 0 for m.z ≤ 0. Λ does not depend on
//! the side of ω (the sign of ω.z).

use super::WgslFn;
use glam::DVec3;
use std::f64::consts::PI;

/// The WGSL twin, for the `sources` of every model that uses it.
pub const MICROFACET_WGSL: (&str, &str) = (
    "microfacet",
    include_str!("../../shaders/bsdf/microfacet.wgsl"),
);

/// A node whose twin is one file `shaders/bsdf/<name>.wgsl` defining `<name>_eval` on top
/// of `microfacet.wgsl` ([`WgslFn::single`] with this module's twin).
pub fn single_wgsl(name: &'static str, source: &'static str) -> WgslFn {
    let mut w = WgslFn::single(name, source);
    w.sources.insert(0, MICROFACET_WGSL);
    w
}

/// A microfacet normal distribution D(m).
pub trait Distribution {
    /// D at the unit microfacet normal `m` (0 below the surface, m.z ≤ 0).
    fn d(&self, m: DVec3) -> f64;
}

/// Smith masking of a distribution (Heitz 2014): Λ(ω) and the G1 built from it.
pub trait Masking {
    /// Smith Λ at the unit direction `w` (infinite at grazing, w.z = 0).
    fn lambda(&self, w: DVec3) -> f64;

    /// G1(ω)/|ω.z| = 1 / (|ω.z| (1 + Λ(ω))) without the side test, in a form that stays
    /// finite as ω.z → 0 (what the BTDF's |μ| divisions need).
    fn g1_over_mu(&self, w: DVec3) -> f64;

    /// Smith G1(ω, m) = χ⁺((ω·m)/(ω·n)) / (1 + Λ(ω)) (Walter 2007, Eq. 34 for GGX): zero
    /// when ω and m lie on opposite sides relative to the macro-normal.
    fn g1(&self, w: DVec3, m: DVec3) -> f64 {
        if w.dot(m) * w.z <= 0.0 {
            return 0.0;
        }
        w.z.abs() * self.g1_over_mu(w)
    }
}

/// cos²θ and sin²θ of a unit vector, from its components.
pub fn cos2_sin2(v: DVec3) -> (f64, f64) {
    (v.z * v.z, v.x * v.x + v.y * v.y)
}

/// The microfacet reflection kernel D(h) G1(ωi, h) G1(ωo, h) / (4 μi μo) at the unit half
/// vector `h` of ωi and ωo (Walter 2007, Eq. 20 without its Fresnel factor); ωi and ωo
/// must be above the surface.
pub fn reflection<M: Distribution + Masking>(ndf: &M, wi: DVec3, wo: DVec3, h: DVec3) -> f64 {
    ndf.d(h) * ndf.g1(wi, h) * ndf.g1(wo, h) / (4.0 * wi.z * wo.z)
}

// ---------------------------------------------------------------------------------------
// GGX / Trowbridge–Reitz

/// GGX (Trowbridge–Reitz) of roughness α (Walter 2007, Eqs. 33–34; Heitz 2014, Eq. 72).
#[derive(Clone, Copy, Debug)]
pub struct Ggx {
    pub alpha: f64,
}

impl Distribution for Ggx {
    /// α² / (π (α² cos²θm + sin²θm)²).
    fn d(&self, m: DVec3) -> f64 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        let (c2, s2) = cos2_sin2(m);
        let t = a2 * c2 + s2;
        a2 / (PI * t * t)
    }
}

impl Masking for Ggx {
    /// ½ (√(1 + α² tan²θ) − 1) = α² sin²θ / (2 μ (μ + √(μ² + α² sin²θ))), μ = |cos θ|.
    fn lambda(&self, w: DVec3) -> f64 {
        let mu = w.z.abs();
        let as2 = self.alpha * self.alpha * (w.x * w.x + w.y * w.y);
        as2 / (2.0 * mu * (mu + (mu * mu + as2).sqrt()))
    }

    /// 2 / (μ + √(μ² + α² sin²θ)).
    fn g1_over_mu(&self, w: DVec3) -> f64 {
        let mu = w.z.abs();
        let s2 = w.x * w.x + w.y * w.y;
        2.0 / (mu + (mu * mu + self.alpha * self.alpha * s2).sqrt())
    }
}

// ---------------------------------------------------------------------------------------
// Beckmann and GTR (the `btdf` terms pair them with the GGX Λ, as the benchmark paper)

/// Below this cos²θm the exponential NDFs (Beckmann, GG) are returned as 0; they are
/// below e^-(10^6) there for every parameter in bounds.
pub const C2_MIN: f64 = 1e-30;

/// Beckmann of roughness α (Walter 2007, Eq. 25).
#[derive(Clone, Copy, Debug)]
pub struct Beckmann {
    pub alpha: f64,
}

impl Distribution for Beckmann {
    /// exp(−tan²θm/α²) / (π α² cos⁴θm).
    fn d(&self, m: DVec3) -> f64 {
        let (c2, s2) = cos2_sin2(m);
        if m.z <= 0.0 || c2 < C2_MIN {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        (-(s2 / c2) / a2 - 2.0 * c2.ln()).exp() / (PI * a2)
    }
}

/// Burley's generalized Trowbridge–Reitz (Burley 2012, Appendix B): γ = 2 is GGX, γ = 1
/// Berry.
#[derive(Clone, Copy, Debug)]
pub struct Gtr {
    pub alpha: f64,
    pub gamma: f64,
}

impl Distribution for Gtr {
    /// c(α, γ) / (α² cos²θm + sin²θm)^γ, normalised by [`gtr_norm`].
    fn d(&self, m: DVec3) -> f64 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = (self.alpha * self.alpha).max(1e-12);
        let (c2, s2) = cos2_sin2(m);
        gtr_norm(a2, self.gamma) * (-self.gamma * (a2 * c2 + s2).ln()).exp()
    }
}

/// Normalisation constant of GTR: (γ−1)(α²−1) / (π (1 − (α²)^(1−γ))), with its limits
/// at γ = 1 and α = 1 taken analytically (the plain form is 0/0 there).
pub fn gtr_norm(a2: f64, gamma: f64) -> f64 {
    let ln_a2 = a2.ln();
    // (γ−1)(α²−1) / (1 − e^x) with x = (1−γ) ln α², i.e. (α²−1)/ln α² · x/(e^x − 1),
    // each factor → 1 at its 0/0 point.
    let x = (1.0 - gamma) * ln_a2;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::half_vector;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_dir(rng: &mut ChaCha8Rng) -> DVec3 {
        let mu: f64 = rng.random_range(1e-4..1.0);
        let phi: f64 = rng.random_range(0.0..2.0 * PI);
        let s = (1.0 - mu * mu).sqrt();
        DVec3::new(s * phi.cos(), s * phi.sin(), mu)
    }

    /// Refactoring check: the vector forms against the cosine forms they replace, on
    /// random inputs (α log-uniform in [1e-3, 1]). Where the old GGX denominator
    /// t = c²(α²−1)+1 is itself small its f64 rounding (~ε/t) dominates the difference.
    #[test]
    fn vector_forms_match_the_forms_they_replace() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let eps = f64::EPSILON;
        let (mut worst_d, mut worst_near_peak, mut worst_g) = (0.0f64, 0.0f64, 0.0f64);
        let mut worst_model = 0.0f64;
        for _ in 0..200_000 {
            let alpha = (1e-3f64.ln() * rng.random::<f64>()).exp();
            let gamma = rng.random_range(0.5..4.0);
            let (wi, wo) = (random_dir(&mut rng), random_dir(&mut rng));
            let h = half_vector(wi, wo);
            let ggx = Ggx { alpha };
            let old = crate::math::ggx_d(h.z, alpha);
            let new = ggx.d(h);
            let t = h.z * h.z * (alpha * alpha - 1.0) + 1.0;
            let rel = (new - old).abs() / old;
            assert!(rel <= 1e-12 + 8.0 * eps / t, "D {alpha} {h}: {old} {new}");
            if t >= 1e-3 {
                worst_d = worst_d.max(rel);
            } else {
                worst_near_peak = worst_near_peak.max(rel);
            }
            for w in [wi, wo] {
                let old = crate::math::ggx_g1(w.z, w.dot(h), alpha);
                let new = ggx.g1(w, h);
                let err = (new - old).abs() / old;
                assert!(err <= 1e-12, "G1 {alpha} {w}: {old} {new}");
                worst_g = worst_g.max(err);
                let old = crate::bsdf::btdf::tr_g1_over_mu(w, alpha);
                let err = (ggx.g1_over_mu(w) - old).abs() / old;
                assert!(err <= 1e-12, "G1/mu {alpha} {w}");
            }
            // The models: ggx (and fa's lobe) and the retro lobe, old transcriptions.
            let old_lobe = |wi: DVec3, wo: DVec3| {
                let h = half_vector(wi, wo);
                crate::math::ggx_d(h.z, alpha)
                    * crate::math::ggx_g1(wi.z, wi.dot(h), alpha)
                    * crate::math::ggx_g1(wo.z, wo.dot(h), alpha)
                    / (4.0 * wi.z * wo.z)
            };
            let old = crate::math::fresnel_dielectric(wi.dot(h), 1.5) * old_lobe(wi, wo);
            let new = crate::bsdf::ggx::ggx_reflect(1.0, alpha, 1.5, wi, wo);
            let rel = (new - old).abs() / old;
            assert!(
                rel <= 1e-12 + 8.0 * eps / t,
                "ggx {alpha} {wi} {wo}: {old} {new}"
            );
            if t >= 1e-3 {
                worst_model = worst_model.max(rel);
            }
            let back = DVec3::new(-wo.x, -wo.y, wo.z);
            let old = old_lobe(wi, back);
            let new = crate::bsdf::retro::retro_lobe(1.0, alpha, wi, wo);
            let tb = {
                let hb = half_vector(wi, back);
                hb.z * hb.z * (alpha * alpha - 1.0) + 1.0
            };
            let rel = (new - old).abs() / old;
            assert!(
                rel <= 1e-12 + 8.0 * eps / tb,
                "retro {alpha} {wi} {wo}: {old} {new}"
            );
            if tb >= 1e-3 {
                worst_model = worst_model.max(rel);
            }
            let (c2, s2) = cos2_sin2(h);
            for (old, new) in [
                (crate::bsdf::btdf::tr_d(c2, s2, alpha), ggx.d(h)),
                (
                    crate::bsdf::btdf::beckmann_d(c2, s2, alpha),
                    Beckmann { alpha }.d(h),
                ),
                (
                    crate::bsdf::btdf::gtr_d(c2, s2, alpha, gamma),
                    Gtr { alpha, gamma }.d(h),
                ),
            ] {
                assert!(old == new, "btdf form {alpha} {h}: {old} {new}");
            }
        }
        eprintln!(
            "worst relative change: GGX D {worst_d:.1e} (old t ≥ 1e-3), {worst_near_peak:.1e} (old t < 1e-3); G1 {worst_g:.1e}; ggx and retro lobes {worst_model:.1e} (old t ≥ 1e-3); btdf forms bit-identical"
        );
    }
}
