//! `M+retro`: adds a retroreflective lobe to any BRDF M (docs/models.md), the "back-vector"
//! lobe of Belcour et al. 2014: k_r · D(h̄) · G1(ωi) G1(ωo) / (4 μi μo) with GGX D and Smith
//! G on h̄ = normalize(ωi + ω̄o), ω̄o = (−o_x, −o_y, o_z) ([`super::microfacet::Ggx`]). It
//! peaks at ωo = ωi. Like every retro lobe it multiplies its value by its efficiency slot
//! (`+falloff`, [`super::falloff`]): f = f_M + E · lobe, E = 1 without `+falloff`.
//! Twin: `shaders/bsdf/retro.wgsl`.

use super::effect::{Adds, Effect};
use super::falloff;
use super::kernel::{lanes, Kernel, LaneChildren, LaneDir};
use super::microfacet::{ggx_reflection, single_wgsl};
use super::{Bsdf, Channels, Entry, InCatalogue, Node, ParamDecl, WgslFn};
use crate::data::Kind;
use crate::math::lanes::{Real, V3};

#[derive(Debug, Clone, Copy)]
pub struct Retro;

impl Kernel for Retro {
    /// The lobe without its scale k_r once per direction: GGX on the back-vector half
    /// vector ωi + ω̄o, ω̄o = (−o_x, −o_y, o_z) (unnormalised; 0 below the surface); per
    /// channel k_r, M's value and the efficiency slot's.
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], children: LaneChildren<R>, out: &mut [R]) {
        let alpha = R::splat(p.get(0, 1));
        let zero = R::zero();
        for (d, (wi, wo), out) in lanes(dirs, p.len(), out) {
            let above = zero.lt(wi.z) & zero.lt(wo.z);
            let back = V3::new(-wo.x, -wo.y, wo.z);
            let kernel = R::select(above, ggx_reflection(alpha, wi, back, wi + back), zero);
            let (inner, efficiency) = (children.at(0, d), children.at(1, d));
            for (i, o) in out.iter_mut().enumerate() {
                let lobe = R::splat(p.get(i, 0)) * kernel;
                *o = inner[i] + efficiency[i] * lobe;
            }
        }
    }
}

impl Bsdf for Retro {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![
            ParamDecl::rgb("kr", 0.0, 10.0, 0.1, "retroreflective lobe scale")
                .neutral_at(0.0)
                .lobe_amplitude(),
            ParamDecl::shared("alpha_r", 1e-3, 1.0, 0.1, "retro lobe GGX roughness")
                .log()
                .lobe_width(),
        ]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        // The wrapped model M and the efficiency slot, both unprefixed.
        &["", ""]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        single_wgsl("retro", include_str!("../../shaders/bsdf/retro.wgsl"))
    }
}

/// Registry entry (one line in [`super::registry::REGISTRY`]).
pub const ENTRY: Entry = Entry::suffix(
    "retro",
    Some(Kind::Brdf),
    InCatalogue::No,
    "adds a back-vector retroreflective GGX lobe (BRDF)",
    build,
)
// k_r = 0 is M alone: a lobe around the retro direction.
.adding(&[Adds::appended(Effect::RetroLobe)]);

pub fn build(inner: Node) -> Result<Node, String> {
    if inner.bsdf.kind() != Kind::Brdf {
        return Err("+retro applies to BRDF models".into());
    }
    if inner.bsdf.name() == "retro" {
        return Err("+retro given twice".into());
    }
    if falloff::is_retro_lobe(&inner) {
        return Err(format!(
            "+retro after +{}: a model takes one retro lobe",
            inner.bsdf.name()
        ));
    }
    Ok(Node::with(Retro, falloff::lobe_children(inner)))
}
