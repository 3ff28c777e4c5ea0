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
use super::{each_direction, Bsdf, Channels, Children, Dir, Entry, Node, ParamDecl, Role, WgslFn};
use crate::data::Kind;
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
    let mu = mu.clamp(1e-7, 1.0);
    let af = 1.0 / (1.0 + C1_FON * r);
    let bf = r * af;
    let si = (1.0 - mu * mu).max(0.0).sqrt();
    let g = si * (mu.acos() - si * mu) + (2.0 / 3.0) * ((si / mu) * (1.0 - si * si * si) - si);
    af + bf * FRAC_1_PI * g
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
struct EonAt {
    af: f64,
    fon: f64,
    e_avg: f64,
    one_minus_eo: f64,
    one_minus_ei: f64,
    one_minus_eavg: f64,
}

impl EonAt {
    /// None below the surface (f = 0).
    fn new(r: f64, wi: DVec3, wo: DVec3) -> Option<EonAt> {
        let (mu_i, mu_o) = (wi.z, wo.z);
        if mu_i <= 0.0 || mu_o <= 0.0 {
            return None;
        }
        let s = wi.dot(wo) - mu_i * mu_o;
        let s_over_t = if s > 0.0 { s / mu_i.max(mu_o) } else { s };
        let af = 1.0 / (1.0 + C1_FON * r);
        let e_avg = af * (1.0 + C2_FON * r);
        Some(EonAt {
            af,
            fon: 1.0 + r * s_over_t,
            e_avg,
            one_minus_eo: (1.0 - e_fon_exact(mu_o, r)).max(EPS),
            one_minus_ei: (1.0 - e_fon_exact(mu_i, r)).max(EPS),
            one_minus_eavg: (1.0 - e_avg).max(EPS),
        })
    }

    /// f_ss + f_ms for albedo ρ: the operations of [`f_fon`] and of paper Eq. 11–13, in
    /// their order.
    fn value(&self, rho: f64) -> f64 {
        let f_ss = rho * FRAC_1_PI * self.af * self.fon;
        let rho_ms = rho * rho * self.e_avg / (1.0 - rho * (1.0 - self.e_avg));
        let f_ms =
            rho_ms * FRAC_1_PI * self.one_minus_eo * self.one_minus_ei / self.one_minus_eavg;
        f_ss + f_ms
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
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, _children: &[f64]) -> f64 {
        match EonAt::new(p[1], wi, wo) {
            Some(at) => at.value(p[0]),
            None => 0.0,
        }
    }
    fn eval_channels(&self, p: Channels, dirs: &[Dir], _: Children, out: &mut [f64]) {
        let r = p.get(0, 1);
        each_direction(dirs, p.len(), out, |_, wi, wo, out| match EonAt::new(r, wi, wo) {
            Some(at) => {
                for (i, o) in out.iter_mut().enumerate() {
                    *o = at.value(p.get(i, 0));
                }
            }
            None => out.fill(0.0),
        });
    }
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
