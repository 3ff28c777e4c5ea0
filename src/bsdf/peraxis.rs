//! `M+peraxis`: the roughness parameters of M (`alpha`, `beta`) get one value per
//! measured φ plane, the others stay shared — the paper fits its anisotropic diffusers
//! A and D axis by axis (§2.3.2); this fits both planes at once with the index and scale
//! shared. The node itself computes nothing: the layout (src/bsdf/mod.rs) gives the
//! parameters below it one scalar view per (plane, channel) group.
//! Twin: `shaders/bsdf/peraxis.wgsl`.

use super::{Bsdf, Entry, InCatalogue, Node, ParamDecl, WgslFn};
use crate::data::Kind;

/// Registry entry: a suffix of either kind; in the catalogue, appended to the scaled
/// models for data measured on several planes.
pub const ENTRY: Entry = Entry::suffix(
    "peraxis",
    None,
    InCatalogue::MultiPlaneAfter("scale"),
    "parameters declared per-plane (roughness) get one value per measured phi plane",
    build,
);
// It adds no effect for diagnose: it describes the planes, not the surface, so diagnose
// names anisotropy through `+aniso`, whose lobes also predict directions between planes.

#[derive(Debug, Clone, Copy)]
pub struct PerAxis {
    kind: Kind,
}

impl super::kernel::PassThrough for PerAxis {}

impl Bsdf for PerAxis {
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
        false // samples on different planes see different parameters
    }
    fn wgsl(&self) -> WgslFn {
        WgslFn::single("peraxis", include_str!("../../shaders/bsdf/peraxis.wgsl"))
    }
}

pub fn build(inner: Node) -> Result<Node, String> {
    let mut has_roughness = false;
    fn visit(n: &Node, f: &mut impl FnMut(&Node)) {
        f(n);
        for c in &n.children {
            visit(c, f);
        }
    }
    let mut twice = false;
    visit(&inner, &mut |n| {
        has_roughness |= n.bsdf.params().iter().any(|p| p.per_axis);
        twice |= n.bsdf.name() == "peraxis";
    });
    if twice {
        return Err("+peraxis given twice".into());
    }
    if !has_roughness {
        return Err("+peraxis needs a model with a per-plane (roughness) parameter".into());
    }
    let kind = inner.bsdf.kind();
    Ok(Node::with(PerAxis { kind }, vec![inner]))
}
