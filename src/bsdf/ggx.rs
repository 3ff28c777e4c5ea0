//! GGX microfacet reflection (Walter, Marschner, Li, Torrance 2007, Eq. 20 with the GGX
//! D of Eq. 33 and the separable Smith G of Eq. 23/34):
//! f = k_s · F(ωi·h; η) · D(h) · G1(ωi) G1(ωo) / (4 μi μo), F the exact dielectric
//! Fresnel; D and G1 are [`super::microfacet::Ggx`] (no cancellation at small α).
//! Twin: `shaders/bsdf/ggx.wgsl`.

use super::microfacet::{self, reflection};
use super::{Bsdf, Entry, Node, ParamDecl, Role, WgslFn};
use crate::data::Kind;
use crate::math::{fresnel_dielectric, half_vector};
use glam::DVec3;

/// The GGX reflection lobe, shared by `ggx` and the lobe of `fa(B)`.
pub fn ggx_reflect(ks: f64, alpha: f64, eta: f64, wi: DVec3, wo: DVec3) -> f64 {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return 0.0;
    }
    let h = half_vector(wi, wo);
    ks * fresnel_dielectric(wi.dot(h), eta) * reflection(&microfacet::Ggx { alpha }, wi, wo, h)
}

/// Parameters of a GGX lobe (also the `lobe.*` parameters of `fa`).
pub const KS: ParamDecl = ParamDecl::rgb("ks", 0.0, 1.0, 0.5, "specular scale").neutral_at(0.0);
pub const ALPHA: ParamDecl = ParamDecl::shared("alpha", 1e-3, 1.0, 0.2, "GGX roughness").log();
pub const ETA: ParamDecl = ParamDecl::shared("eta", 1.0, 5.0, 1.5, "refractive index")
    // η = 1: no Fresnel reflection, so the lobe vanishes (and fa's base is unattenuated).
    .neutral_at(1.0);

#[derive(Debug, Clone, Copy)]
pub struct Ggx;

impl Bsdf for Ggx {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![KS, ALPHA, ETA]
    }
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, _children: &[f64]) -> f64 {
        ggx_reflect(p[0], p[1], p[2], wi, wo)
    }
    fn wgsl(&self) -> WgslFn {
        microfacet::single_wgsl("ggx", include_str!("../../shaders/bsdf/ggx.wgsl"))
    }
}

/// Registry entry (one line in [`super::registry::REGISTRY`]).
pub const ENTRY: Entry = Entry::leaf(
    "ggx",
    Kind::Brdf,
    Role::SpecularLobe,
    "GGX microfacet reflection (Walter et al. 2007)",
    || Node::leaf(Ggx),
);
