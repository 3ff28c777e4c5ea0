//! Lambertian reflection: f = ρ/π. Twin: `shaders/bsdf/lambert.wgsl`.

use super::{
    each_direction, Bsdf, Channels, Children, Dir, Entry, MitsubaBsdf, MitsubaField, Node,
    ParamDecl, Role, WgslFn,
};
use crate::data::Kind;
use glam::DVec3;
use std::f64::consts::FRAC_1_PI;

#[derive(Debug, Clone, Copy)]
pub struct Lambert;

impl Bsdf for Lambert {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![ParamDecl::rgb("rho", 0.0, 1.0, 0.5, "albedo").neutral_at(0.0)]
    }
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, _children: &[f64]) -> f64 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        p[0] * FRAC_1_PI
    }
    fn eval_channels(&self, p: Channels, dirs: &[Dir], _: Children, out: &mut [f64]) {
        each_direction(dirs, p.len(), out, |_, wi, wo, out| {
            if wi.z <= 0.0 || wo.z <= 0.0 {
                out.fill(0.0);
                return;
            }
            for (i, o) in out.iter_mut().enumerate() {
                *o = p.get(i, 0) * FRAC_1_PI;
            }
        });
    }
    fn wgsl(&self) -> WgslFn {
        WgslFn::single("lambert", include_str!("../../shaders/bsdf/lambert.wgsl"))
    }
}

/// Registry entry (one line in [`super::registry::REGISTRY`]).
pub const ENTRY: Entry = Entry::leaf(
    "lambert",
    Kind::Brdf,
    Role::DiffuseBase,
    "Lambertian: f = rho/pi",
    || Node::leaf(Lambert),
)
.with_mitsuba(&MitsubaBsdf {
    plugin: "diffuse",
    summary: "diffuse",
    why: &["f = rho/pi: Mitsuba's diffuse BSDF with reflectance rho."],
    fields: &[MitsubaField::Rgb {
        name: "reflectance",
        param: "rho",
    }],
});
