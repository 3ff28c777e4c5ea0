//! `M+aniso`: the microfacet lobes of M made anisotropic. Each lobe's roughness α becomes
//! two, α_u along the surface's tangent u and α_v along its bitangent v, and the tangent
//! frame is turned by φ0 (degrees) against the data's φ = 0: `ggx+aniso`,
//! `fa(B)+aniso` (the highlight), `M+coat+aniso` (the coat), `btdf(tr|beckmann|gg)+aniso`
//! (transmission with β_u, β_v for the generalized Gaussian). At α_u = α_v every form is
//! its isotropic model for any φ0, so M embeds in `M+aniso` (diagnose's F test).
//! Each lobe's anisotropic form lives with the lobe (`ggx.rs`, `fa.rs`, `coat.rs`,
//! `btdf.rs`) over the stretched distributions of [`super::stretched`]. Twin:
//! `aniso_eval` in `shaders/bsdf/aniso.wgsl`.

use super::effect::{Adds, Effect};
use super::{Bsdf, Entry, InCatalogue, Node, ParamDecl, WgslFn};
use crate::data::Kind;

/// Registry entry: a suffix of either kind.
pub const ENTRY: Entry = Entry::suffix(
    "aniso",
    None,
    // For data on several planes, beside `+peraxis`: the scaled BTDFs as one anisotropic
    // surface.
    InCatalogue::MultiPlaneAfter("scale"),
    "anisotropic microfacet lobes: alpha_u, alpha_v and the tangent azimuth phi0 (ggx, fa, +coat, btdf tr/beckmann/gg)",
    build,
)
// α_u = α_v is M for any φ0. Only data on two or more planes (or off-plane) can tell
// α_u from α_v: one plane sees one combination of them.
.adding(&[Adds::appended(Effect::Anisotropy).on_planes(2)]);

/// The `+aniso` node: passes its inner model's value through (the anisotropy lives in
/// the lobes [`build`] put in place of the isotropic ones).
#[derive(Debug, Clone, Copy)]
pub struct Aniso {
    kind: Kind,
}

impl super::kernel::PassThrough for Aniso {}

impl Bsdf for Aniso {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn kind(&self) -> Kind {
        self.kind
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &[""]
    }
    super::kernel::kernel_methods!();
    fn reciprocal(&self) -> bool {
        // ggx and fa stay reciprocal (the frame turns both directions); btdf never was.
        self.kind == Kind::Brdf
    }
    fn wgsl(&self) -> WgslFn {
        super::stretched::wgsl("aniso_eval")
    }
}

/// Replace every lobe of `inner` that has an anisotropic form ([`Bsdf::anisotropic`]) by
/// it, and wrap the result in the pass-through `+aniso` node.
pub fn build(inner: Node) -> Result<Node, String> {
    let kind = inner.bsdf.kind();
    let (swapped, count, names) = inner.with_forms(&|b| b.anisotropic());
    if names.contains(&ENTRY.name) || names.contains(&super::peraxis::ENTRY.name) {
        return Err(
            "+aniso given twice, or with +peraxis (one surface, or one roughness per plane: not both)"
                .into(),
        );
    }
    if count == 0 {
        return Err(
            "+aniso needs a microfacet lobe with an anisotropic form: ggx, fa(B), +coat, or btdf(tr|beckmann|gg)"
                .into(),
        );
    }
    Ok(Node::with(Aniso { kind }, vec![swapped]))
}
