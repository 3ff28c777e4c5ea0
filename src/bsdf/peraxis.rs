//! `M+peraxis`: the roughness parameters of M (`alpha`, `beta`) get one value per
//! measured φ plane, the others stay shared — the paper fits its anisotropic diffusers
//! A and D axis by axis (§2.3.2); this fits both planes at once with the index and scale
//! shared. The node itself computes nothing: the layout (src/model/mod.rs) gives the
//! parameters below it one scalar view per (plane, channel) group.
//! Twin: `shaders/peraxis.wgsl`.

use super::{Bsdf, Node, ParamDecl, WgslFn};
use crate::data::Kind;
use glam::DVec3;

/// Parameter names that become per-plane under `+peraxis`.
pub const PER_AXIS: &[&str] = &["alpha", "beta"];

#[derive(Debug, Clone, Copy)]
pub struct PerAxis {
    kind: Kind,
}

impl Bsdf for PerAxis {
    fn name(&self) -> &'static str {
        "peraxis"
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
    fn eval(&self, _p: &[f64], _wi: DVec3, _wo: DVec3, children: &[f64]) -> f64 {
        children[0]
    }
    fn reciprocal(&self) -> bool {
        false // samples on different planes see different parameters
    }
    fn wgsl(&self) -> WgslFn {
        WgslFn {
            sources: vec![("peraxis", include_str!("../../shaders/bsdf/peraxis.wgsl"))],
            function: "peraxis_eval".into(),
        }
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
        has_roughness |= n.bsdf.params().iter().any(|p| PER_AXIS.contains(&p.name));
        twice |= n.bsdf.name() == "peraxis";
    });
    if twice {
        return Err("+peraxis given twice".into());
    }
    if !has_roughness {
        return Err("+peraxis needs a model with a roughness parameter (alpha or beta)".into());
    }
    let kind = inner.bsdf.kind();
    Ok(Node::with(PerAxis { kind }, vec![inner]))
}
