//! `M+mrm`, `M+mrm82`: the Minimal Retroreflective Microfacet lobe (Raab, Belcour, Liu,
//! Portsmouth, "The Minimal Retroreflective Microfacet Model", JCGT 2026; docs/models.md)
//! added to any BRDF M. MRM is a microfacet BRDF whose microfacet selector is the
//! back-vector b = normalize(ω̄ + ω′) of one direction and the mirror ω̄ = (−x, −y, z) of
//! the other about the normal (their Eq. for b_r), with every term of Walter's microfacet
//! model (Walter et al. 2007, Eq. 20) evaluated on the mirrored direction:
//!
//! f = f_M + E · k_r · F(ωi·b) · D(b) · G2(ωi, ω̄o) / (4 μi μo),  b = normalize(ωi + ω̄o),
//!
//! with GGX D, E the lobe's entrance-angle efficiency ([`super::falloff`], 1 without
//! `+falloff`) and F on the back-vector:
//! - `+mrm`: k_r (the paper's colour multiplier ρ) in [0, 10] times the exact dielectric
//!   Fresnel F(c; η_r) (Walter 2007, Eq. 22), whose F0 is at most 0.44 for η_r ≤ 5;
//! - `+mrm82`: k_r in [0, 1] times the "F82-tint" Fresnel of OpenPBR (Kutz, Hasan,
//!   Edmondson 2021) that the paper fits to the 3M yellow tape (F0 = 0.19, F82 = 0):
//!   F(μ) = S(μ) − μ(1 − μ)⁶ (1 − F82) S(μ̄) / (μ̄ (1 − μ̄)⁶), S(μ) = F0 + (1 − F0)(1 − μ)⁵,
//!   μ̄ = 1/7, clamped to [0, 1]: with F82 < 1 and a small F0 the formula dips below 0 for
//!   μ slightly above μ̄ (e.g. −0.07 at μ = 0.2 for F0 = 0.19, F82 = 0).
//!
//! G2 is the **height-correlated** Smith masking-shadowing
//! G2 = 1 / (1 + Λ(ωi) + Λ(ω̄o)) (Heitz 2014, Eq. 99; the paper allows any reciprocal G2),
//! rather than the separable G1·G1 of `+retro`: the separable form treats masking and
//! shadowing as independent although both are likely for the same low-lying microfacets,
//! so it overestimates the occlusion (Heitz 2014, §6); and at the retro peak ωi and ω̄o
//! lie on opposite azimuths, where the correlation through height is what remains (the
//! correlation through direction matters only when the two directions are close). The two
//! differ only towards grazing angles (Λ ~ α² tan²θ / 4).
//!
//! Properties (checked by tests/physics_brdf.rs): reciprocal (ωi·b = ω̄o·b, and swapping ωi
//! and ωo mirrors b, which an isotropic D does not see; the paper's §3.1); the lobe's
//! directional albedo equals that of the forward microfacet BRDF with the same F at the
//! same incidence (the paper's §3.2), so it is ≤ k_r · max F ≤ k_r.
//!
//! The kernel is written D / (4 (μi μo + μo a(ωi) + μi a(ω̄o))), a(ω) = μ Λ(ω) =
//! α² sin²θ / (2 (μ + √(μ² + α² sin²θ))), which has no division by μ and no cancellation.
//! Twin: `shaders/bsdf/mrm.wgsl`.

use super::effect::{Adds, Effect};
use super::falloff;
use super::kernel::{lanes, Kernel, LaneChildren, LaneDir};
use super::microfacet::{ggx_d, single_wgsl};
use super::{Bsdf, Channels, Entry, InCatalogue, Node, ParamDecl, WgslFn};
use crate::data::Kind;
use crate::math::fresnel_dielectric_in;
use crate::math::lanes::{Real, V3};
use glam::DVec3;

/// The Fresnel factor on the back-vector.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fresnel {
    /// Exact dielectric Fresnel of index η_r (`+mrm`).
    Dielectric,
    /// OpenPBR's F82-tint Schlick form (F0, F82) (`+mrm82`).
    F82Tint,
}

#[derive(Debug, Clone, Copy)]
pub struct Mrm {
    pub fresnel: Fresnel,
}

/// μ Λ(ω) of GGX: α² sin²θ / (2 (μ + √(μ² + α² sin²θ))), finite at μ = 0 (= α sinθ / 2).
#[inline(always)]
fn mu_lambda<R: Real>(alpha: f64, w: V3<R>) -> R {
    let mu = w.z.abs();
    let as2 = R::splat(alpha * alpha) * (w.x * w.x + w.y * w.y);
    as2 / (R::splat(2.0) * (mu + (mu * mu + as2).sqrt()))
}

/// D(b) G2(ωi, ω̄o) / (4 μi μo) with the height-correlated Smith G2 of GGX, for ωi and
/// ω̄o above the surface and b their unit half vector (both then see b from its front).
#[inline(always)]
pub fn kernel<R: Real>(alpha: f64, wi: V3<R>, wo_back: V3<R>, b: V3<R>) -> R {
    let (mi, mo) = (wi.z, wo_back.z);
    let denom = mi * mo + mo * mu_lambda(alpha, wi) + mi * mu_lambda(alpha, wo_back);
    ggx_d(alpha, b) / (R::splat(4.0) * denom)
}

/// μ̄ = 1/7 of the F82-tint form (cos 81.8°, where F82 is specified).
const MU_BAR: f64 = 1.0 / 7.0;

/// Schlick's form F0 + (1 − F0)(1 − μ)⁵, the fifth power as `powi` computes it (x·(x²)²).
#[inline(always)]
fn schlick<R: Real>(mu: R, f0: f64) -> R {
    let x = R::splat(1.0) - mu;
    let x2 = x * x;
    R::splat(f0) + R::splat(1.0 - f0) * (x * (x2 * x2))
}

/// OpenPBR's F82-tint Fresnel at cos θ = `mu`, clamped to [0, 1] (see the module doc).
pub fn fresnel_f82(mu: f64, f0: f64, f82: f64) -> f64 {
    fresnel_f82_in(mu, f0, f82)
}

/// [`fresnel_f82`] over any [`Real`] (the sixth power as `powi` computes it, x²·(x²)²).
#[inline(always)]
fn fresnel_f82_in<R: Real>(mu: R, f0: f64, f82: f64) -> R {
    let c = R::splat(1.0) - mu;
    let c2 = c * c;
    let c6 = c2 * (c2 * c2);
    let peak = MU_BAR * (1.0 - MU_BAR).powi(6);
    let at_bar = schlick(MU_BAR, f0);
    (schlick(mu, f0) - mu * c6 * R::splat(1.0 - f82) * R::splat(at_bar) / R::splat(peak))
        .clamp(0.0, 1.0)
}

/// The MRM lobe alone (without M and the efficiency), `fresnel` evaluated at ωi·b: the
/// f64 form of [`Mrm`]'s kernel, for checks.
pub fn mrm_lobe(
    kr: f64,
    alpha: f64,
    fresnel: impl Fn(f64) -> f64,
    wi: DVec3,
    wo: DVec3,
) -> f64 {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return 0.0;
    }
    let back = V3::new(-wo.x, -wo.y, wo.z);
    let b = crate::math::half_vector(wi, back.into());
    kr * fresnel(wi.dot(b)) * kernel(alpha, wi.into(), back, b.into())
}

impl Kernel for Mrm {
    /// Per direction the back-vector ω̄o = (−o_x, −o_y, o_z), the unit half vector b of ωi
    /// and ω̄o (the normal where they cancel), the Fresnel factor at ωi·b and the kernel;
    /// per channel k_r, M's value and the efficiency slot's. 0 below the surface.
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], children: LaneChildren<R>, out: &mut [R]) {
        let alpha = p.get(0, 1);
        let (zero, one) = (R::zero(), R::splat(1.0));
        for (d, (wi, wo), out) in lanes(dirs, p.len(), out) {
            let above = zero.lt(wi.z) & zero.lt(wo.z);
            let back = V3::new(-wo.x, -wo.y, wo.z);
            let sum = wi + back;
            let len = sum.length();
            let b = V3::select(
                len.lt(R::splat(1e-12)),
                V3::new(zero, zero, one),
                sum.scale(one / len),
            );
            let cos = wi.dot(b);
            let fresnel = match self.fresnel {
                Fresnel::Dielectric => fresnel_dielectric_in(cos, R::splat(p.get(0, 2))),
                Fresnel::F82Tint => fresnel_f82_in(cos, p.get(0, 2), p.get(0, 3)),
            };
            let k = kernel(alpha, wi, back, b);
            let (inner, efficiency) = (children.at(0, d), children.at(1, d));
            for (i, o) in out.iter_mut().enumerate() {
                let lobe = R::select(above, R::splat(p.get(i, 0)) * fresnel * k, zero);
                *o = inner[i] + efficiency[i] * lobe;
            }
        }
    }
}

/// The lobe's scale (the paper's colour multiplier ρ): the lobe vanishes at k_r = 0.
pub const KR: ParamDecl =
    ParamDecl::rgb("kr", 0.0, 10.0, 0.5, "retro lobe scale")
        .neutral_at(0.0)
        .lobe_amplitude();
/// GGX roughness of the lobe (the paper's roughness r is √α: r = 0.23 is α = 0.053).
pub const ALPHA_R: ParamDecl =
    ParamDecl::shared("alpha_r", 1e-3, 1.0, 0.1, "retro lobe GGX roughness")
        .log()
        .lobe_width();
pub const ETA_R: ParamDecl = ParamDecl::shared(
    "eta_r",
    1.0,
    5.0,
    1.5,
    "retro lobe refractive index (Fresnel on the back-vector)",
);
/// The scale of `+mrm82`: the paper's colour multiplier ρ, bounded by 1 so that the lobe's
/// albedo (≤ k_r · max F ≤ k_r) never exceeds 1.
pub const KR82: ParamDecl =
    ParamDecl::rgb("kr", 0.0, 1.0, 0.5, "retro lobe scale (albedo-like)")
        .neutral_at(0.0)
        .lobe_amplitude();
/// F0 of the F82-tint Fresnel. Not a scale: Schlick's S(μ) → 1 at grazing for any F0, so
/// the lobe vanishes only at k_r = 0.
pub const F0: ParamDecl = ParamDecl::shared(
    "f0",
    0.0,
    1.0,
    0.19,
    "retro lobe F82-tint Fresnel at normal incidence",
);
pub const F82: ParamDecl = ParamDecl::shared(
    "f82",
    0.0,
    1.0,
    1.0,
    "retro lobe F82 tint: F(cos = 1/7) = f82 * Schlick(f0); 1 is plain Schlick",
);

impl Bsdf for Mrm {
    fn entry(&self) -> &'static Entry {
        match self.fresnel {
            Fresnel::Dielectric => &ENTRY,
            Fresnel::F82Tint => &F82_ENTRY,
        }
    }
    fn params(&self) -> Vec<ParamDecl> {
        match self.fresnel {
            Fresnel::Dielectric => vec![KR, ALPHA_R, ETA_R],
            Fresnel::F82Tint => vec![KR82, ALPHA_R, F0, F82],
        }
    }
    fn child_roles(&self) -> &'static [&'static str] {
        // The wrapped model M and the efficiency slot, both unprefixed.
        &["", ""]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        let source = include_str!("../../shaders/bsdf/mrm.wgsl");
        match self.fresnel {
            Fresnel::Dielectric => single_wgsl("mrm", source),
            Fresnel::F82Tint => {
                let mut w = single_wgsl("mrm", source);
                w.function = "mrm82_eval".into();
                w
            }
        }
    }
}

/// Registry entries (one line in [`super::registry::REGISTRY`]).
pub const ENTRY: Entry = Entry::suffix(
    "mrm",
    Some(Kind::Brdf),
    InCatalogue::No,
    "adds the MRM retroreflective lobe (back-vector GGX, height-correlated G2, dielectric Fresnel eta_r on the back-vector)",
    |inner| build(inner, Fresnel::Dielectric),
);
pub const F82_ENTRY: Entry = Entry::suffix(
    "mrm82",
    Some(Kind::Brdf),
    InCatalogue::No,
    "adds the MRM retroreflective lobe with the F82-tint Fresnel (f0, f82) on the back-vector",
    |inner| build(inner, Fresnel::F82Tint),
)
// k_r = 0 is M alone; F0 = F82 = 1 is `+retro` up to the height-correlated G2. On real tapes
// k_r and F0 trade off and k_r can end on its bound 1; `+retro` (k_r up to 10, no Fresnel)
// then carries the effect, and the residuals choose between them.
.adding(&[Adds::appended(Effect::RetroLobe)]);

fn build(inner: Node, fresnel: Fresnel) -> Result<Node, String> {
    let name = match fresnel {
        Fresnel::Dielectric => ENTRY.name,
        Fresnel::F82Tint => F82_ENTRY.name,
    };
    if inner.bsdf.kind() != Kind::Brdf {
        return Err(format!("+{name} applies to BRDF models"));
    }
    if falloff::is_retro_lobe(&inner) {
        return Err(format!(
            "+{name} after +{}: a model takes one retro lobe",
            inner.bsdf.name()
        ));
    }
    Ok(Node::with(Mrm { fresnel }, falloff::lobe_children(inner)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The F82-tint form's defining values: F(1) = F0, F(1/7) = F82 · Schlick(F0, 1/7),
    /// F(0) = 1, F82 = 1 is Schlick; and the clamp keeps it in [0, 1] where the formula
    /// dips below 0 (the paper's F0 = 0.19, F82 = 0 at μ = 0.2: −0.067 before clamping).
    #[test]
    fn f82_tint_takes_its_defining_values() {
        let schlick = |m: f64, f0: f64| f0 + (1.0 - f0) * (1.0 - m).powi(5);
        for f0 in [0.0, 0.04, 0.19, 0.5, 1.0] {
            for f82 in [0.0, 0.3, 1.0] {
                assert!((fresnel_f82(1.0, f0, f82) - f0).abs() < 1e-12);
                assert!((fresnel_f82(0.0, f0, f82) - 1.0).abs() < 1e-12);
                let at_bar = f82 * schlick(1.0 / 7.0, f0);
                assert!((fresnel_f82(1.0 / 7.0, f0, f82) - at_bar).abs() < 1e-12);
                for k in 0..=100 {
                    let m = k as f64 / 100.0;
                    let f = fresnel_f82(m, f0, f82);
                    assert!((0.0..=1.0).contains(&f), "F({m}; {f0}, {f82}) = {f}");
                    if f82 == 1.0 {
                        assert!((f - schlick(m, f0)).abs() < 1e-12);
                    }
                }
            }
        }
        let raw = schlick(0.2, 0.19)
            - 0.2 * 0.8f64.powi(6) * schlick(1.0 / 7.0, 0.19)
                / ((1.0 / 7.0) * (6.0f64 / 7.0).powi(6));
        assert!((raw + 0.067).abs() < 1e-3, "{raw}");
        assert_eq!(fresnel_f82(0.2, 0.19, 0.0), 0.0);
    }

    /// The lobe peaks on the retro direction with D(n) G2 / (4 μ²) there.
    #[test]
    fn the_lobe_peaks_at_the_retro_direction() {
        let alpha: f64 = 0.05;
        let t = 40f64.to_radians();
        let wi = DVec3::new(t.sin(), 0.0, t.cos());
        let peak = mrm_lobe(1.0, alpha, |_| 1.0, wi, wi);
        // On the peak b = n: D = 1/(π α²), Λ = (√(1 + α² tan²θ) − 1)/2 for both directions.
        let lambda = 0.5 * ((1.0 + alpha * alpha * t.tan().powi(2)).sqrt() - 1.0);
        let want = 1.0 / (std::f64::consts::PI * alpha * alpha)
            / (1.0 + 2.0 * lambda)
            / (4.0 * t.cos().powi(2));
        assert!((peak - want).abs() < 1e-10 * want, "{peak} vs {want}");
        for d in [-2.0f64, -0.5, 0.5, 2.0] {
            let to = t + d.to_radians();
            let wo = DVec3::new(to.sin(), 0.0, to.cos());
            assert!(mrm_lobe(1.0, alpha, |_| 1.0, wi, wo) < peak);
        }
    }
}
