//! `M+coat`: blends a second GGX specular lobe into any BRDF M (docs/models.md):
//! f = (1 − k_c) f_M + k_c · D(h) G1(ωi) G1(ωo) / (4 μi μo), GGX D and Smith G of
//! roughness α_c on the half vector h = normalize(ωi + ωo) ([`super::microfacet::Ggx`]),
//! no Fresnel factor. Where M already has a specular lobe (`fa(B)`), it is the second
//! lobe real coated materials show: a sharp reflection off a smooth top film over a broad
//! one from the rougher layer beneath (retroreflective sheeting, lacquered wood). The
//! lobe's directional albedo is at most 1 (Smith G only loses energy), so the blend keeps
//! M's energy bound; k_c = 0 is M (nested). Twin: `shaders/bsdf/coat.wgsl`.

use super::microfacet::{single_wgsl, Ggx};
use super::effect::{Adds, Effect};
use super::{each_direction, Bsdf, Channels, Children, Dir, Entry, InCatalogue, Node, ParamDecl, WgslFn};
use crate::data::Kind;
use glam::DVec3;

#[derive(Debug, Clone, Copy)]
pub struct Coat;

/// The lobe without its scale k_c (None below the surface, where the lobe is 0): what
/// the channels of one direction share.
fn coat_kernel(alpha: f64, wi: DVec3, wo: DVec3) -> Option<f64> {
    if wi.z <= 0.0 || wo.z <= 0.0 {
        return None;
    }
    // The kernel takes the unnormalised half vector (both directions are above, so the
    // sum is not 0).
    Some(Ggx { alpha }.reflection(wi, wo, wi + wo))
}

/// The coat's weight in the blend.
pub const KC: ParamDecl = ParamDecl::rgb("kc", 0.0, 1.0, 0.1, "coat lobe weight")
    .neutral_at(0.0)
    .lobe_amplitude();
/// The coat's GGX roughness.
pub const ALPHA_C: ParamDecl = ParamDecl::shared("alpha_c", 1e-3, 1.0, 0.05, "coat lobe GGX roughness")
    .log()
    .lobe_width();

impl Bsdf for Coat {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![KC, ALPHA_C]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &[""]
    }
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, children: &[f64]) -> f64 {
        (1.0 - p[0]) * children[0] + coat_kernel(p[1], wi, wo).map_or(0.0, |k| p[0] * k)
    }
    fn eval_channels(&self, p: Channels, dirs: &[Dir], children: Children, out: &mut [f64]) {
        let alpha = p.get(0, 1);
        each_direction(dirs, p.len(), out, |d, wi, wo, out| {
            let kernel = coat_kernel(alpha, wi, wo);
            let inner = children.at(0, d);
            for (i, o) in out.iter_mut().enumerate() {
                let kc = p.get(i, 0);
                *o = (1.0 - kc) * inner[i] + kernel.map_or(0.0, |k| kc * k);
            }
        });
    }
    fn anisotropic(&self) -> Option<std::sync::Arc<dyn Bsdf>> {
        Some(super::aniso::coat())
    }
    fn wgsl(&self) -> WgslFn {
        single_wgsl("coat", include_str!("../../shaders/bsdf/coat.wgsl"))
    }
}

/// Registry entry (one line in [`super::registry::REGISTRY`]).
pub const ENTRY: Entry = Entry::suffix(
    "coat",
    Some(Kind::Brdf),
    InCatalogue::No,
    "blends in a second GGX specular lobe: (1 - kc) M + kc D G/(4 mu_i mu_o), no Fresnel (a smooth coat over M's own lobe)",
    build,
)
// k_c = 0 is M alone: a sharp coat lobe over a broad one, as on real coated materials.
.adding(&[Adds::appended(Effect::SpecularLobe)]);

pub fn build(inner: Node) -> Result<Node, String> {
    if inner.bsdf.kind() != Kind::Brdf {
        return Err("+coat applies to BRDF models".into());
    }
    if inner.bsdf.name() == "coat" {
        return Err("+coat given twice".into());
    }
    Ok(Node::with(Coat, vec![inner]))
}
