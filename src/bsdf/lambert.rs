//! Lambertian reflection: f = ρ/π. Twin: `shaders/bsdf/lambert.wgsl`.

use super::kernel::{lanes, Kernel, LaneChildren, LaneDir};
use super::{Bsdf, Channels, Entry, MitsubaBsdf, MitsubaField, Node, ParamDecl, Role, WgslFn};
use crate::data::Kind;
use crate::math::lanes::Real;
use std::f64::consts::FRAC_1_PI;

#[derive(Debug, Clone, Copy)]
pub struct Lambert;

impl Kernel for Lambert {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        let zero = R::zero();
        for (_, (wi, wo), out) in lanes(dirs, p.len(), out) {
            let below = wi.z.le(zero) | wo.z.le(zero);
            for (i, o) in out.iter_mut().enumerate() {
                *o = R::select(below, zero, R::splat(p.get(i, 0)) * R::splat(FRAC_1_PI));
            }
        }
    }
}

impl Bsdf for Lambert {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![ParamDecl::rgb("rho", 0.0, 1.0, 0.5, "albedo").neutral_at(0.0)]
    }
    super::kernel::kernel_methods!();
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
