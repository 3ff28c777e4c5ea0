//! GGX microfacet reflection (Walter, Marschner, Li, Torrance 2007, Eq. 20 with the GGX
//! D of Eq. 33 and the separable Smith G of Eq. 23/34):
//! f = k_s · F(ωi·h; η) · D(h) · G1(ωi) G1(ωo) / (4 μi μo), F the exact dielectric
//! Fresnel; D and G1 are [`super::microfacet::Ggx`] (no cancellation at small α).
//! Twin: `shaders/bsdf/ggx.wgsl`.

use super::microfacet;
use super::kernel::{lanes, Kernel, LaneChildren, LaneDir};
use super::{Bsdf, Channels, Entry, MitsubaBsdf, MitsubaField, Node, ParamDecl, Role, WgslFn};
use crate::data::Kind;
use crate::math::fresnel_dielectric_in;
use crate::math::lanes::{Real, V3};
use glam::DVec3;
use std::sync::Arc;
use super::stretched::{AnisoGgx, Frame, ALPHA_U, ALPHA_V, PHI0};

/// The GGX reflection lobe, shared by `ggx` and the lobe of `fa(B)`.
pub fn ggx_reflect(ks: f64, alpha: f64, eta: f64, wi: DVec3, wo: DVec3) -> f64 {
    GgxLobe::at(alpha, eta, wi, wo).scaled(ks)
}

/// The parts of [`ggx_reflect`] that do not depend on k_s: evaluated once per direction
/// for every channel (k_s is the lobe's only rgb parameter).
#[derive(Clone, Copy, Debug)]
pub struct GgxLobe<R: Real = f64> {
    /// F(ωi·h; η), and the microfacet kernel D G1 G1 / (4 μi μo); both 0 below the surface.
    fresnel: R,
    kernel: R,
    /// cos θd = ωi·h, the angle F is taken at (`+fresnel` tabulates a factor in it).
    cos_d: R,
    above: R::Mask,
}

impl GgxLobe {
    /// The lobe below the surface (0).
    pub const ZERO: GgxLobe = GgxLobe {
        fresnel: 0.0,
        kernel: 0.0,
        cos_d: 1.0,
        above: false,
    };

    /// [`Self::at_in`] at f64 directions.
    #[inline]
    pub fn at(alpha: f64, eta: f64, wi: DVec3, wo: DVec3) -> GgxLobe {
        GgxLobe::at_in(alpha, eta, wi.into(), wo.into())
    }
}

impl<R: Real> GgxLobe<R> {
    /// The lobe at (ωi, ωo) without normalising the half vector: for unit ωi and ωo,
    /// ωi·h = |ωi + ωo| / 2 (since |ωi + ωo|² = 2 + 2 ωi·ωo), and the kernel takes
    /// ωi + ωo itself ([`microfacet::Ggx::reflection`]), so F needs no division and the
    /// kernel one. (ωi = −ωo cannot occur above the surface; there h is the normal, as
    /// [`crate::math::half_vector`] takes it.)
    #[inline(always)]
    pub fn at_in(alpha: f64, eta: f64, wi: V3<R>, wo: V3<R>) -> GgxLobe<R> {
        GgxLobe::at_with(
            eta,
            wi,
            wo,
            #[inline(always)]
            |m| microfacet::ggx_reflection(R::splat(alpha), wi, wo, m),
        )
    }
    /// The lobe of another distribution, whose kernel D G1 G1 / (4 μi μo) `kernel` gives
    /// at any positive multiple m of the half vector (the data-driven NDF of `+ndf`):
    /// the Fresnel factor and the side tests are the GGX lobe's.
    #[inline(always)]
    pub fn at_with(eta: f64, wi: V3<R>, wo: V3<R>, kernel: impl FnOnce(V3<R>) -> R) -> GgxLobe<R> {
        let zero = R::zero();
        let above = zero.lt(wi.z) & zero.lt(wo.z);
        if !R::any(above) {
            return GgxLobe {
                fresnel: zero,
                kernel: zero,
                cos_d: R::splat(1.0),
                above,
            };
        }
        let sum = wi + wo;
        let len = sum.length();
        let at_normal = len.lt(R::splat(1e-12));
        let z = V3::new(zero, zero, R::splat(1.0));
        let m = V3::select(at_normal, z, sum);
        let cos_h = R::select(at_normal, wi.z, R::splat(0.5) * len);
        GgxLobe {
            fresnel: fresnel_dielectric_in(cos_h, R::splat(eta)),
            kernel: kernel(m),
            cos_d: cos_h,
            above,
        }
    }
    /// k_s · F · kernel, in that order (what a per-channel evaluation computes).
    #[inline(always)]
    pub fn scaled(&self, ks: R) -> R {
        R::select(self.above, ks * self.fresnel * self.kernel, R::zero())
    }
    /// k_s · F · factor · kernel: the lobe with its Fresnel factor reshaped (`+fresnel`).
    #[inline(always)]
    pub fn scaled_by(&self, ks: R, factor: R) -> R {
        R::select(self.above, ks * self.fresnel * factor * self.kernel, R::zero())
    }
    /// k_s · (F · kernel): the anisotropic lobes' order (their f64 values predate the
    /// lanes and stay bit for bit).
    #[inline(always)]
    pub fn scaled_outer(&self, ks: R) -> R {
        R::select(self.above, ks * (self.fresnel * self.kernel), R::zero())
    }
    /// cos θd = ωi·h (1 below the surface).
    #[inline(always)]
    pub fn cos_d(&self) -> R {
        self.cos_d
    }
}

/// Parameters of a GGX lobe (also the `lobe.*` parameters of `fa`).
pub const KS: ParamDecl = ParamDecl::rgb("ks", 0.0, 1.0, 0.5, "specular scale")
    .neutral_at(0.0)
    .lobe_amplitude();
pub const ALPHA: ParamDecl = ParamDecl::shared("alpha", 1e-3, 1.0, 0.2, "GGX roughness")
    .log()
    .lobe_width();
pub const ETA: ParamDecl = ParamDecl::shared("eta", 1.0, 5.0, 1.5, "refractive index")
    // η = 1: no Fresnel reflection, so the lobe vanishes (and fa's base is unattenuated).
    .neutral_at(1.0);

#[derive(Debug, Clone, Copy)]
pub struct Ggx;

impl Kernel for Ggx {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        let (alpha, eta) = (p.get(0, 1), p.get(0, 2));
        lobe_block(
            p,
            dirs,
            out,
            #[inline(always)]
            |wi, wo| GgxLobe::at_in(alpha, eta, wi, wo),
        );
    }
}

/// A lobe's values when k_s (rgb) is the node's first parameter: the lobe once per
/// direction, scaled per channel (`ggx` and its `+ndf` form).
#[inline(always)]
pub fn lobe_block<R: Real>(
    p: Channels,
    dirs: &[LaneDir<R>],
    out: &mut [R],
    lobe: impl Fn(V3<R>, V3<R>) -> GgxLobe<R>,
) {
    lobe_block_with(
        p,
        dirs,
        out,
        lobe,
        #[inline(always)]
        |lobe, i| lobe.scaled(R::splat(p.get(i, 0))),
    );
}

/// [`lobe_block`] with channel i's value taken by `channel` from the direction's lobe
/// (`+fresnel` reshapes F per channel).
#[inline(always)]
pub fn lobe_block_with<R: Real>(
    p: Channels,
    dirs: &[LaneDir<R>],
    out: &mut [R],
    lobe: impl Fn(V3<R>, V3<R>) -> GgxLobe<R>,
    channel: impl Fn(&GgxLobe<R>, usize) -> R,
) {
    for (_, (wi, wo), out) in lanes(dirs, p.len(), out) {
        let lobe = lobe(wi, wo);
        for (i, o) in out.iter_mut().enumerate() {
            *o = channel(&lobe, i);
        }
    }
}

impl Bsdf for Ggx {
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((super::GgxPlace::Ggx, super::Tabulated { ndf: false, fresnel: false }))
    }
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![KS, ALPHA, ETA]
    }
    super::kernel::kernel_methods!();
    fn anisotropic(&self) -> Option<std::sync::Arc<dyn Bsdf>> {
        Some(Arc::new(GgxAniso))
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
)
.with_mitsuba(&MitsubaBsdf {
    plugin: "roughconductor",
    summary: "roughconductor with a real index (k = 0) and the GGX distribution",
    why: &[
        "f = ks F(wi.h; eta) D(h) G1(wi) G1(wo) / (4 cos_i cos_o) with GGX D and separable",
        "Smith G1 (Walter et al. 2007): Mitsuba's roughconductor with the GGX distribution,",
        "specular_reflectance ks and a real index (k = 0), whose conductor Fresnel term is",
        "then exactly the dielectric one.",
    ],
    fields: &[
        MitsubaField::Text {
            name: "distribution",
            value: "ggx",
        },
        MitsubaField::Param {
            name: "alpha",
            param: "alpha",
        },
        MitsubaField::Param {
            name: "eta",
            param: "eta",
        },
        MitsubaField::Constant {
            name: "k",
            value: 0.0,
        },
        MitsubaField::Rgb {
            name: "specular_reflectance",
            param: "ks",
        },
    ],
});

// ---------------------------------------------------------------------------------------
// The anisotropic form (`+aniso`): its entry is not registered (the spec names it as
// `M+aniso`); it carries the isotropic model's name, kind and role.

/// `ggx` made anisotropic: k_s, α_u, α_v, φ0, η.
#[derive(Debug, Clone, Copy)]
pub struct GgxAniso;

const GGX_ENTRY: Entry = Entry::leaf(
    "ggx",
    Kind::Brdf,
    Role::SpecularLobe,
    "GGX microfacet reflection, anisotropic",
    || Node::leaf(GgxAniso),
);

impl Kernel for GgxAniso {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        let (au, av, frame, eta) = (p.get(0, 1), p.get(0, 2), Frame::new(p.get(0, 3)), p.get(0, 4));
        lobe_block_with(
            p,
            dirs,
            out,
            #[inline(always)]
            |wi, wo| aniso_lobe(au, av, frame, eta, wi, wo),
            #[inline(always)]
            |lobe, i| lobe.scaled_outer(R::splat(p.get(i, 0))),
        );
    }
}

/// The anisotropic GGX lobe's F(ωi·h; η) and kernel D G1 G1 / (4 μi μo) at directions in
/// the data's frame (`ggx+aniso`, `fa(B)+aniso`): the isotropic lobe's Fresnel factor,
/// half vector and side tests, none of which depends on the azimuth, on the directions
/// turned into the tangent frame, with the stretched GGX's kernel.
#[inline(always)]
pub fn aniso_lobe<R: Real>(au: f64, av: f64, frame: Frame, eta: f64, wi: V3<R>, wo: V3<R>) -> GgxLobe<R> {
    let (li, lo) = (frame.local_in(wi), frame.local_in(wo));
    GgxLobe::at_with(
        eta,
        li,
        lo,
        #[inline(always)]
        |m| AnisoGgx { au, av }.reflection_in(li, lo, m),
    )
}

impl Bsdf for GgxAniso {
    fn entry(&self) -> &'static Entry {
        &GGX_ENTRY
    }
    fn frame_params(&self) -> Option<[usize; 3]> {
        Some([1, 2, 3])
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![KS, ALPHA_U, ALPHA_V, PHI0, ETA]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        super::stretched::wgsl("ggx_aniso_eval")
    }
}
