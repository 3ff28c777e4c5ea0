//! GGX microfacet reflection (Walter, Marschner, Li, Torrance 2007, Eq. 20 with the GGX
//! D of Eq. 33 and the separable Smith G of Eq. 23/34):
//! f = k_s · F(ωi·h; η) · D(h) · G1(ωi) G1(ωo) / (4 μi μo), F the exact dielectric
//! Fresnel; D and G1 are [`super::microfacet::Ggx`] (no cancellation at small α).
//! Twin: `shaders/bsdf/ggx.wgsl`.

use super::microfacet;
use super::{
    each_direction, Bsdf, Channels, Children, Dir, Entry, MitsubaBsdf, MitsubaField, Node,
    ParamDecl, Role, WgslFn,
};
use crate::data::Kind;
use crate::math::fresnel_dielectric;
use glam::DVec3;

/// The GGX reflection lobe, shared by `ggx` and the lobe of `fa(B)`.
pub fn ggx_reflect(ks: f64, alpha: f64, eta: f64, wi: DVec3, wo: DVec3) -> f64 {
    GgxLobe::at(alpha, eta, wi, wo).scaled(ks)
}

/// The parts of [`ggx_reflect`] that do not depend on k_s: evaluated once per direction
/// for every channel (k_s is the lobe's only rgb parameter).
#[derive(Clone, Copy, Debug)]
pub struct GgxLobe {
    /// F(ωi·h; η), and the microfacet kernel D G1 G1 / (4 μi μo); both 0 below the surface.
    fresnel: f64,
    kernel: f64,
    above: bool,
}

impl GgxLobe {
    /// The lobe below the surface (0).
    pub const ZERO: GgxLobe = GgxLobe {
        fresnel: 0.0,
        kernel: 0.0,
        above: false,
    };

    /// The lobe at (ωi, ωo) without normalising the half vector: for unit ωi and ωo,
    /// ωi·h = |ωi + ωo| / 2 (since |ωi + ωo|² = 2 + 2 ωi·ωo), and the kernel takes
    /// ωi + ωo itself ([`microfacet::Ggx::reflection`]), so F needs no division and the
    /// kernel one. (ωi = −ωo cannot occur above the surface; there h is the normal, as
    /// [`crate::math::half_vector`] takes it.)
    #[inline]
    pub fn at(alpha: f64, eta: f64, wi: DVec3, wo: DVec3) -> GgxLobe {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return GgxLobe::ZERO;
        }
        let sum = wi + wo;
        let len = sum.length();
        let (m, cos_h) = if len < 1e-12 {
            (DVec3::Z, wi.z)
        } else {
            (sum, 0.5 * len)
        };
        GgxLobe {
            fresnel: fresnel_dielectric(cos_h, eta),
            kernel: microfacet::Ggx { alpha }.reflection(wi, wo, m),
            above: true,
        }
    }
    /// k_s · F · kernel, in that order (what a per-channel evaluation computes).
    #[inline]
    pub fn scaled(&self, ks: f64) -> f64 {
        if self.above {
            ks * self.fresnel * self.kernel
        } else {
            0.0
        }
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
    fn eval_channels(&self, p: Channels, dirs: &[Dir], _: Children, out: &mut [f64]) {
        let (alpha, eta) = (p.get(0, 1), p.get(0, 2));
        each_direction(dirs, p.len(), out, |_, wi, wo, out| {
            let lobe = GgxLobe::at(alpha, eta, wi, wo);
            for (i, o) in out.iter_mut().enumerate() {
                *o = lobe.scaled(p.get(i, 0));
            }
        });
    }
    fn anisotropic(&self) -> Option<std::sync::Arc<dyn Bsdf>> {
        Some(super::aniso::ggx())
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
