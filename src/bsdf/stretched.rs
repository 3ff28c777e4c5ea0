//! The anisotropic (stretched) microfacet machinery every `+aniso` lobe shares: the
//! tangent frame, the stretched GGX, Beckmann and generalized Gaussian distributions, the
//! parameters α_u, α_v, φ0, β_u, β_v, and the GGX lobe's kernel. Not a model: each
//! anisotropic lobe lives with its isotropic parent (`ggx.rs`, `fa.rs`, `coat.rs`,
//! `btdf.rs`), and `aniso.rs` is the `+aniso` suffix that puts them in place. WGSL twin:
//! the shared functions of `shaders/bsdf/aniso.wgsl`.
//!
//! The distributions are the stretched forms of Heitz 2014 ("Understanding the
//! Masking-Shadowing Function", §5.3): with the slopes of m scaled by 1/α_u and 1/α_v the
//! distribution is the α = 1 one, so, in the tangent frame (x along u, y along v),
//!
//! - GGX (Heitz 2014, Eq. 85 and 86; Burley 2012, Eq. 13):
//!   D(m) = 1 / (π α_u α_v ((m_x/α_u)² + (m_y/α_v)² + m_z²)²),
//!   Λ(ω) = ½ (√(1 + (α_u² ω_x² + α_v² ω_y²)/ω_z²) − 1);
//! - Beckmann: D(m) = exp(−((m_x/α_u)² + (m_y/α_v)²)/m_z²) / (π α_u α_v m_z⁴), masked by
//!   the GGX Λ above (as the isotropic `btdf(beckmann)`, after the benchmark paper);
//! - generalized Gaussian (Holzschuch & Pacanowski 2017): D(m) = p / (π β_u β_v Γ(1/p))
//!   exp(−(((m_x/β_u)² + (m_y/β_v)²)/m_z²)^p) / m_z⁴, its Λ the isotropic table at the
//!   projected width √(β_u² ω_x² + β_v² ω_y²) in place of β sinθ.
//!
//! Every form takes the directions turned into the tangent frame ([`Frame::local`]);
//! Fresnel factors, half vectors and the refraction geometry do not depend on the
//! azimuth, so the rest of each model is its isotropic code. Like the isotropic forms,
//! none computes 1 − cos²θ.
//!
//! The parametrisation has a symmetry: (α_u, α_v, φ0) and (α_v, α_u, φ0 ± 90°) are the
//! same surface, so φ0 ranges over [−90°, 90°] and every surface is found with
//! |φ0| ≤ 45°, away from the bounds; fits report that form ([`Bsdf::frame_params`]).

use super::microfacet::{
    gg_lambda_table, Distribution, Gg, LambdaRow, Masking, C2_MIN, MICROFACET_WGSL,
};
use super::{ParamDecl, WgslFn};
use crate::math::lanes::{Real, V3};
use glam::DVec3;
use std::f64::consts::PI;

/// The anisotropic lobes' WGSL: the stretched distributions, and each lobe's function.
pub(crate) const ANISO_WGSL: (&str, &str) =
    ("aniso", include_str!("../../shaders/bsdf/aniso.wgsl"));

/// The WGSL of an anisotropic lobe calling `function` (the BTDF lobes add `btdf.wgsl`).
pub(crate) fn wgsl(function: &str) -> WgslFn {
    WgslFn {
        sources: vec![MICROFACET_WGSL, ANISO_WGSL],
        function: function.into(),
    }
}

pub const ALPHA_U: ParamDecl = ParamDecl::shared(
    "alpha_u",
    1e-3,
    1.0,
    0.2,
    "GGX roughness along the tangent u",
)
.log()
.lobe_width()
.needs_planes();
pub const ALPHA_V: ParamDecl = ParamDecl::shared(
    "alpha_v",
    1e-3,
    1.0,
    0.2,
    "GGX roughness along the bitangent v",
)
.log()
.lobe_width()
.needs_planes();
pub const PHI0: ParamDecl = ParamDecl::shared(
    "phi0",
    -90.0,
    90.0,
    0.0,
    "azimuth of the tangent u against the data's phi = 0 (degrees)",
)
.needs_planes();
pub const BETA_U: ParamDecl = ParamDecl::shared(
    "beta_u",
    3e-3,
    1.0,
    0.2,
    "generalized Gaussian width along the tangent u",
)
.log()
.needs_planes();
pub const BETA_V: ParamDecl = ParamDecl::shared(
    "beta_v",
    3e-3,
    1.0,
    0.2,
    "generalized Gaussian width along the bitangent v",
)
.log()
.needs_planes();

/// The surface's tangent frame, turned by φ0 about the normal.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    cos: f64,
    sin: f64,
}

impl Frame {
    /// The frame whose tangent u lies at azimuth `phi0_deg` (degrees).
    pub fn new(phi0_deg: f64) -> Frame {
        let (sin, cos) = phi0_deg.to_radians().sin_cos();
        Frame { cos, sin }
    }
    /// `w` in the tangent frame: (w·u, w·v, w·n).
    #[inline]
    pub fn local(&self, w: DVec3) -> DVec3 {
        self.local_in(V3::from(w)).into()
    }
    /// [`Self::local`] over any [`Real`].
    #[inline(always)]
    pub fn local_in<R: Real>(&self, w: V3<R>) -> V3<R> {
        let (cos, sin) = (R::splat(self.cos), R::splat(self.sin));
        V3::new(w.x * cos + w.y * sin, w.y * cos - w.x * sin, w.z)
    }
}

/// (α_u ω_x)² + (α_v ω_y)²: α² sin²θ of the isotropic forms.
#[inline(always)]
fn projected2<R: Real>(au: f64, av: f64, w: V3<R>) -> R {
    let (x, y) = (R::splat(au) * w.x, R::splat(av) * w.y);
    x * x + y * y
}

/// (m_x/α_u)² + (m_y/α_v)²: sin²θ/α² of the isotropic forms.
#[inline(always)]
fn stretched2<R: Real>(au: f64, av: f64, m: V3<R>) -> R {
    let (x, y) = (m.x / R::splat(au), m.y / R::splat(av));
    x * x + y * y
}

/// Anisotropic GGX (Trowbridge–Reitz) in the tangent frame.
#[derive(Clone, Copy, Debug)]
pub struct AnisoGgx {
    pub au: f64,
    pub av: f64,
}

impl Distribution for AnisoGgx {
    fn d(&self, m: DVec3) -> f64 {
        self.d_in(m.into())
    }
}

impl Masking for AnisoGgx {
    fn lambda(&self, w: DVec3) -> f64 {
        let mu = w.z.abs();
        let as2 = projected2(self.au, self.av, V3::from(w));
        as2 / (2.0 * mu * (mu + (mu * mu + as2).sqrt()))
    }
    fn g1_over_mu(&self, w: DVec3) -> f64 {
        self.g1_over_mu_in(w.into())
    }
}

impl AnisoGgx {
    /// [`Distribution::d`] over any [`Real`].
    #[inline(always)]
    pub fn d_in<R: Real>(&self, m: V3<R>) -> R {
        let t = stretched2(self.au, self.av, m) + m.z * m.z;
        let d = R::splat(1.0) / (R::splat(PI * self.au * self.av) * t * t);
        R::select(m.z.le(R::zero()), R::zero(), d)
    }
    /// [`Masking::g1_over_mu`] over any [`Real`].
    #[inline(always)]
    pub fn g1_over_mu_in<R: Real>(&self, w: V3<R>) -> R {
        R::splat(2.0) / self.r(w)
    }
    /// μ + √(μ² + α_u² ω_x² + α_v² ω_y²), μ = |ω_z|: 2μ / G1(ω).
    #[inline(always)]
    fn r<R: Real>(&self, w: V3<R>) -> R {
        let mu = w.z.abs();
        mu + (mu * mu + projected2(self.au, self.av, w)).sqrt()
    }
    /// D(h) G1(ωi, h) G1(ωo, h) / (4 μi μo) at `m`, any positive multiple of the half
    /// vector: with G1(ω) = 2μ/(μ + r), r = √(μ² + α_u² ω_x² + α_v² ω_y²), the μi μo
    /// cancel, and D(m/|m|) = |m|⁴ / (π α_u α_v t²), t = (m_x/α_u)² + (m_y/α_v)² + m_z²,
    /// so the kernel is |m|⁴ / (π α_u α_v t² (μi + ri)(μo + ro)) (the isotropic
    /// [`super::microfacet::ggx_reflection`] at α_u = α_v). ωi and ωo above.
    #[inline]
    pub fn reflection(&self, wi: DVec3, wo: DVec3, m: DVec3) -> f64 {
        self.reflection_in(wi.into(), wo.into(), m.into())
    }
    /// [`Self::reflection`] over any [`Real`].
    #[inline(always)]
    pub fn reflection_in<R: Real>(&self, wi: V3<R>, wo: V3<R>, m: V3<R>) -> R {
        // D = 0 below; χ⁺ of G1: a facet facing away from ωi or ωo masks it.
        let zero = R::zero();
        let masked = m.z.le(zero) | (wi.dot(m) * wi.z).le(zero) | (wo.dot(m) * wo.z).le(zero);
        let t = stretched2(self.au, self.av, m) + m.z * m.z;
        let m2 = m.dot(m);
        let value = m2 * m2 / (R::splat(PI * self.au * self.av) * t * t * self.r(wi) * self.r(wo));
        R::select(masked, zero, value)
    }
}

/// Anisotropic Beckmann in the tangent frame.
#[derive(Clone, Copy, Debug)]
pub struct AnisoBeckmann {
    pub au: f64,
    pub av: f64,
}

impl Distribution for AnisoBeckmann {
    fn d(&self, m: DVec3) -> f64 {
        self.d_in(m.into())
    }
}

impl AnisoBeckmann {
    /// [`Distribution::d`] over any [`Real`].
    #[inline(always)]
    pub fn d_in<R: Real>(&self, m: V3<R>) -> R {
        let c2 = m.z * m.z;
        let s = stretched2(self.au, self.av, m);
        let d = (-s / c2 - R::splat(2.0) * c2.ln()).exp() / R::splat(PI * self.au * self.av);
        R::select(m.z.le(R::zero()) | c2.lt(R::splat(C2_MIN)), R::zero(), d)
    }
}

/// Anisotropic generalized Gaussian in the tangent frame: the isotropic form's shape
/// constants (they depend on p alone) with its own normalisation and widths.
#[derive(Clone, Copy, Debug)]
pub struct AnisoGg {
    pub bu: f64,
    pub bv: f64,
    shape: Gg,
    /// ln(p / (π β_u β_v Γ(1/p))).
    ln_norm: f64,
}

impl AnisoGg {
    pub fn new(bu: f64, bv: f64, p: f64) -> AnisoGg {
        let shape = Gg::new(1.0, p);
        AnisoGg {
            bu,
            bv,
            ln_norm: shape.ln_norm - (bu * bv).ln(),
            shape,
        }
    }
    /// (μ, μΛ) as the isotropic form, with β sinθ → √(β_u² ω_x² + β_v² ω_y²).
    #[inline(always)]
    fn mu_lambda<R: Real>(&self, w: V3<R>, row: Option<&LambdaRow>) -> (R, R) {
        let bs = projected2(self.bu, self.bv, w).sqrt();
        self.shape.mu_lambda_at(w.z.abs(), bs, row)
    }
    /// [`Distribution::d`] over any [`Real`].
    #[inline(always)]
    pub fn d_in<R: Real>(&self, m: V3<R>) -> R {
        let c2 = m.z * m.z;
        let d = self
            .shape
            .d_at(self.ln_norm, stretched2(self.bu, self.bv, m) / c2, c2);
        R::select(m.z.le(R::zero()) | c2.lt(R::splat(C2_MIN)), R::zero(), d)
    }
    /// [`Masking::g1_over_mu`] over any [`Real`].
    #[inline(always)]
    pub fn g1_over_mu_in<R: Real>(&self, w: V3<R>) -> R {
        self.g1_over_mu_with(w, None)
    }
    /// [`Self::g1_over_mu_in`] with T̂ from the Λ table's `row` at this p where given
    /// ([`Self::row`]).
    #[inline(always)]
    pub fn g1_over_mu_with<R: Real>(&self, w: V3<R>, row: Option<&LambdaRow>) -> R {
        let (mu, mu_lambda) = self.mu_lambda(w, row);
        R::splat(1.0) / (mu + mu_lambda)
    }
    /// The Λ table at this shape p, for [`Self::g1_over_mu_with`] in f32 lanes.
    pub fn row(&self) -> LambdaRow {
        gg_lambda_table().row(self.shape.p)
    }
}

impl Distribution for AnisoGg {
    fn d(&self, m: DVec3) -> f64 {
        self.d_in(m.into())
    }
}

impl Masking for AnisoGg {
    fn lambda(&self, w: DVec3) -> f64 {
        let (mu, mu_lambda) = self.mu_lambda(V3::from(w), None);
        mu_lambda / mu
    }
    fn g1_over_mu(&self, w: DVec3) -> f64 {
        self.g1_over_mu_in(w.into())
    }
}
