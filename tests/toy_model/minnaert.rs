//! A toy model defined outside the library, to show that a model is three touches: this
//! file (its declaration and CPU evaluation), its WGSL twin `minnaert.wgsl`, and one
//! registry line (`bsdfit::bsdf::registry::register(&minnaert::ENTRY)`).
//!
//! Minnaert's law (Minnaert 1941, used for planetary surfaces): f = ρ/π (μi μo)^(k−1).
//! k = 1 is Lambert; k < 1 brightens the limb (grazing directions), k > 1 darkens it.

use bsdfit::bsdf::{Bsdf, Entry, Node, ParamDecl, Role, WgslFn};
use bsdfit::data::Kind;
use glam::DVec3;
use std::f64::consts::FRAC_1_PI;

#[derive(Debug, Clone, Copy)]
pub struct Minnaert;

impl Bsdf for Minnaert {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![
            ParamDecl::rgb("rho", 0.0, 1.0, 0.5, "albedo").neutral_at(0.0),
            ParamDecl::shared("k", 0.6, 1.6, 1.0, "limb-darkening exponent").neutral_at(1.0),
        ]
    }
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, _children: &[f64]) -> f64 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        p[0] * FRAC_1_PI * (wi.z * wo.z).powf(p[1] - 1.0)
    }
    fn wgsl(&self) -> WgslFn {
        WgslFn::single("minnaert", include_str!("minnaert.wgsl"))
    }
}

/// Its registry entry: a diffuse base, so every layer over diffuse bases (`fa`, `dmg`,
/// `rmg`) accepts it and `diagnose` can wrap it, with no other change.
pub const ENTRY: Entry = Entry::leaf(
    "minnaert",
    Kind::Brdf,
    Role::DiffuseBase,
    "Minnaert limb darkening: f = rho/pi (mu_i mu_o)^(k-1)",
    || Node::leaf(Minnaert),
);
