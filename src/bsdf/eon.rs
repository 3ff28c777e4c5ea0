//! Energy-preserving Oren–Nayar (EON): Portsmouth, Kutz & Hill, "EON: A practical
//! energy-preserving rough diffuse BRDF", JCGT 14(1), 2025.
//!
//! f = f_ss + f_ms. The single-scattering lobe is Fujii's improved Oren–Nayar (FON):
//! f_ss = ρ/π · A_F · (1 + r · s/t), s = ωi·ωo − μiμo, t = max(μi, μo) where s > 0 else 1,
//! A_F = 1/(1 + c1 r), c1 = 1/2 − 2/(3π)  (paper §3, Eq. 4–5).
//! The multiple-scattering compensation (paper §4, Eq. 11–13) uses the exact directional
//! albedo E_F(μ) of FON (paper Eq. 9, "E_FON_exact"), its average Ē_F = A_F (1 + c2 r),
//! c2 = 2/3 − 28/(15π), and ρ_ms = ρ² Ē_F / (1 − ρ (1 − Ē_F)):
//! f_ms = ρ_ms/π · (1 − E_F(μo)) (1 − E_F(μi)) / (1 − Ē_F).
//! Twin: `shaders/bsdf/eon.wgsl`.

use super::effect::{Adds, Effect};
use super::kernel::{lanes, Kernel, LaneChildren, LaneDir};
use super::{Bsdf, Channels, Entry, Node, ParamDecl, Role, WgslFn};
use crate::data::Kind;
use crate::math::lanes::{Real, V3};
use glam::DVec3;
use std::f64::consts::{FRAC_1_PI, PI};

/// c1 = 1/2 − 2/(3π)
pub const C1_FON: f64 = 0.5 - 2.0 / (3.0 * PI);
/// c2 = 2/3 − 28/(15π)
pub const C2_FON: f64 = 2.0 / 3.0 - 28.0 / (15.0 * PI);
/// Guards the (1 − E) factors where they vanish (r → 0), as the reference code does.
const EPS: f64 = 1e-7;

/// Exact directional albedo of the FON single-scattering lobe with ρ = 1 (EON Eq. 9).
pub fn e_fon_exact(mu: f64, r: f64) -> f64 {
    e_fon_exact_in(mu, r)
}

/// [`e_fon_exact`] over any [`Real`].
#[inline(always)]
pub fn e_fon_exact_in<R: Real>(mu: R, r: R) -> R {
    let one = R::splat(1.0);
    let mu = mu.clamp(1e-7, 1.0);
    let af = one / (one + R::splat(C1_FON) * r);
    let bf = r * af;
    let si = (one - mu * mu).max(R::zero()).sqrt();
    let g = si * (mu.acos() - si * mu)
        + R::splat(2.0 / 3.0) * ((si / mu) * (one - si * si * si) - si);
    af + bf * R::splat(FRAC_1_PI) * g
}

/// Single-scattering FON lobe (without the multiple-scattering term).
pub fn f_fon(rho: f64, r: f64, wi: DVec3, wo: DVec3) -> f64 {
    let (mu_i, mu_o) = (wi.z, wo.z);
    let s = wi.dot(wo) - mu_i * mu_o;
    let s_over_t = if s > 0.0 { s / mu_i.max(mu_o) } else { s };
    let af = 1.0 / (1.0 + C1_FON * r);
    rho * FRAC_1_PI * af * (1.0 + r * s_over_t)
}

#[derive(Debug, Clone, Copy)]
pub struct Eon;

/// What EON depends on besides ρ, at one direction pair: A_F and 1 + r s/t of the
/// single-scattering FON lobe, Ē_F and the three (1 − E) factors of f_ms (the directional
/// albedos are the costly part, so channels share them).
struct EonAt<R: Real> {
    af: R,
    fon: R,
    e_avg: R,
    one_minus_eo: R,
    one_minus_ei: R,
    one_minus_eavg: R,
    /// Below the surface (f = 0).
    below: R::Mask,
}

impl<R: Real> EonAt<R> {
    #[inline(always)]
    fn new(r: f64, wi: V3<R>, wo: V3<R>) -> EonAt<R> {
        let (mu_i, mu_o) = (wi.z, wo.z);
        let (zero, one) = (R::zero(), R::splat(1.0));
        let below = mu_i.le(zero) | mu_o.le(zero);
        let s = wi.dot(wo) - mu_i * mu_o;
        let s_over_t = R::select(zero.lt(s), s / mu_i.max(mu_o), s);
        let r = R::splat(r);
        let af = one / (one + R::splat(C1_FON) * r);
        let e_avg = af * (one + R::splat(C2_FON) * r);
        let eps = R::splat(EPS);
        EonAt {
            af,
            fon: one + r * s_over_t,
            e_avg,
            one_minus_eo: (one - e_fon_exact_in(mu_o, r)).max(eps),
            one_minus_ei: (one - e_fon_exact_in(mu_i, r)).max(eps),
            one_minus_eavg: (one - e_avg).max(eps),
            below,
        }
    }

    /// f_ss + f_ms for albedo ρ: the operations of [`f_fon`] and of paper Eq. 11–13, in
    /// their order.
    #[inline(always)]
    fn value(&self, rho: R) -> R {
        let one = R::splat(1.0);
        let f_ss = rho * R::splat(FRAC_1_PI) * self.af * self.fon;
        let rho_ms = rho * rho * self.e_avg / (one - rho * (one - self.e_avg));
        let f_ms = rho_ms * R::splat(FRAC_1_PI) * self.one_minus_eo * self.one_minus_ei
            / self.one_minus_eavg;
        R::select(self.below, R::zero(), f_ss + f_ms)
    }
}

impl Kernel for Eon {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        let r = p.get(0, 1);
        for (_, (wi, wo), out) in lanes(dirs, p.len(), out) {
            let at = EonAt::new(r, wi, wo);
            for (i, o) in out.iter_mut().enumerate() {
                *o = at.value(R::splat(p.get(i, 0)));
            }
        }
    }
}

impl Bsdf for Eon {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![
            ParamDecl::rgb("rho", 0.0, 1.0, 0.5, "albedo").neutral_at(0.0),
            ParamDecl::shared("r", 0.0, 1.0, 0.5, "roughness").neutral_at(0.0),
        ]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        WgslFn::single("eon", include_str!("../../shaders/bsdf/eon.wgsl"))
    }
}

/// Registry entry (one line in [`super::registry::REGISTRY`]).
pub const ENTRY: Entry = Entry::leaf(
    "eon",
    Kind::Brdf,
    Role::DiffuseBase,
    "energy-preserving Oren-Nayar (Portsmouth, Kutz, Hill 2025)",
    || Node::leaf(Eon),
)
// At r = 0 it is Lambert: roughness adds backscatter to a Lambertian base.
.adding(&[Adds::generalizing(Effect::Backscatter, super::lambert::ENTRY.name)]);
