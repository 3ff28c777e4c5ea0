//! `M+retro`: adds a retroreflective lobe to any BRDF M (docs/models.md), the "back-vector"
//! lobe of Belcour et al. 2014: k_r · D(h̄) · G1(ωi) G1(ωo) / (4 μi μo) with GGX D and Smith
//! G on h̄ = normalize(ωi + ω̄o), ω̄o = (−o_x, −o_y, o_z) ([`super::microfacet::Ggx`]). It
//! peaks at ωo = ωi. Like every retro lobe it multiplies its value by its efficiency slot
//! (`+falloff`, [`super::falloff`]): f = f_M + E · lobe, E = 1 without `+falloff`.
//! Twin: `shaders/bsdf/retro.wgsl`.

use super::falloff;
use super::microfacet::{single_wgsl, Ggx};
use super::effect::{Adds, Effect};
use super::{each_direction, Bsdf, Channels, Children, Dir, Entry, InCatalogue, Node, ParamDecl, WgslFn};
use crate::data::Kind;
use glam::DVec3;

#[derive(Debug, Clone, Copy)]
pub struct Retro;

/// The back-vector retro lobe alone.
pub fn retro_lobe(kr: f64, alpha: f64, wi: DVec3, wo: DVec3) -> f64 {
    match retro_kernel(alpha, wi, wo) {
        Some(kernel) => kr * kernel,
        None => 0.0,
    }
}

/// The lobe without its scale k_r (None below the surface, where the lobe is 0): what
/// the channels of one direction share.
fn retro_kernel(alpha: f64, wi: DVec3, wo: DVec3) -> Option<f64> {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return None;
    }
    let wo_back = DVec3::new(-wo.x, -wo.y, wo.z);
    // The kernel takes the unnormalised half vector (both directions are above, so the
    // sum is not 0).
    Some(Ggx { alpha }.reflection(wi, wo_back, wi + wo_back))
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
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, children: &[f64]) -> f64 {
        children[0] + children[1] * retro_lobe(p[0], p[1], wi, wo)
    }
    fn eval_channels(&self, p: Channels, dirs: &[Dir], children: Children, out: &mut [f64]) {
        let alpha = p.get(0, 1);
        each_direction(dirs, p.len(), out, |d, wi, wo, out| {
            let kernel = retro_kernel(alpha, wi, wo);
            let (inner, efficiency) = (children.at(0, d), children.at(1, d));
            for (i, o) in out.iter_mut().enumerate() {
                let lobe = match kernel {
                    Some(k) => p.get(i, 0) * k,
                    None => 0.0,
                };
                *o = inner[i] + efficiency[i] * lobe;
            }
        });
    }
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
