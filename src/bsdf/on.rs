//! Oren–Nayar 1994, the "qualitative" model (Oren & Nayar, SIGGRAPH 1994, Eq. 30):
//! f = ρ/π · (A + B · max(0, cos(φi−φo)) · sin α · tan β), α = max(θi, θo), β = min(θi, θo),
//! A = 1 − 0.5 σ²/(σ² + 0.33), B = 0.45 σ²/(σ² + 0.09).
//!
//! The angular factor is written with vectors: max(0, cos Δφ) sin θi sin θo = max(0, s) with
//! s = ωi·ωo − μiμo, and sin α tan β / (sin θi sin θo) = 1/max(μi, μo), so the term is
//! max(0, s)/max(μi, μo) — no trigonometric calls and no pole at the normal.
//! Twin: `shaders/bsdf/on.wgsl`.

use super::effect::{Adds, Effect};
use super::kernel::{lanes, Kernel, LaneChildren, LaneDir};
use super::{Bsdf, Channels, Entry, Node, ParamDecl, Role, WgslFn};
use crate::data::Kind;
use crate::math::lanes::{Real, V3};
use std::f64::consts::{FRAC_1_PI, FRAC_PI_2};

#[derive(Debug, Clone, Copy)]
pub struct OrenNayar;

/// A + B · max(0, cos Δφ) sin α tan β, the factor of ρ/π that depends on σ and the
/// directions only (ωi and ωo above the surface).
#[inline(always)]
fn shape<R: Real>(sigma: f64, wi: V3<R>, wo: V3<R>) -> R {
    let (mu_i, mu_o) = (wi.z, wo.z);
    let s2 = sigma * sigma;
    let a = 1.0 - 0.5 * s2 / (s2 + 0.33);
    let b = 0.45 * s2 / (s2 + 0.09);
    let s = wi.dot(wo) - mu_i * mu_o;
    R::splat(a) + R::splat(b) * s.max(R::zero()) / mu_i.max(mu_o)
}

impl Kernel for OrenNayar {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        let sigma = p.get(0, 1);
        let zero = R::zero();
        for (_, (wi, wo), out) in lanes(dirs, p.len(), out) {
            let below = wi.z.le(zero) | wo.z.le(zero);
            let shape = shape(sigma, wi, wo);
            for (i, o) in out.iter_mut().enumerate() {
                let v = R::splat(p.get(i, 0)) * R::splat(FRAC_1_PI) * shape;
                *o = R::select(below, zero, v);
            }
        }
    }
}

impl Bsdf for OrenNayar {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![
            ParamDecl::rgb("rho", 0.0, 1.0, 0.5, "albedo").neutral_at(0.0),
            ParamDecl::shared(
                "sigma",
                0.0,
                FRAC_PI_2,
                0.3,
                "facet slope standard deviation (rad)",
            )
            .neutral_at(0.0),
        ]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        WgslFn::single("on", include_str!("../../shaders/bsdf/on.wgsl"))
    }
}

/// Registry entry (one line in [`super::registry::REGISTRY`]).
pub const ENTRY: Entry = Entry::leaf(
    "on",
    Kind::Brdf,
    Role::DiffuseBase,
    "Oren-Nayar 1994 qualitative model",
    || Node::leaf(OrenNayar),
)
// At σ = 0 it is Lambert: roughness adds backscatter to a Lambertian base.
.adding(&[Adds::generalizing(Effect::Backscatter, super::lambert::ENTRY.name)]);
