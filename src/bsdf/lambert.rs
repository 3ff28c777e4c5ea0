//! Lambertian reflection: f = ρ/π. Twin: `shaders/lambert.wgsl`.

use super::{no_arg, Ast, Bsdf, Node, ParamDecl, WgslFn};
use crate::data::Kind;
use glam::DVec3;
use std::f64::consts::FRAC_1_PI;

#[derive(Debug, Clone, Copy)]
pub struct Lambert;

impl Bsdf for Lambert {
    fn name(&self) -> &'static str {
        "lambert"
    }
    fn kind(&self) -> Kind {
        Kind::Brdf
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![ParamDecl::rgb("rho", 0.0, 1.0, 0.5, "albedo")]
    }
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, _children: &[f64]) -> f64 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        p[0] * FRAC_1_PI
    }
    fn wgsl(&self) -> WgslFn {
        WgslFn {
            sources: vec![("lambert", include_str!("../../shaders/bsdf/lambert.wgsl"))],
            function: "lambert_eval".into(),
        }
    }
}

pub fn build(arg: Option<&Ast>) -> Result<Node, String> {
    no_arg("lambert", arg)?;
    Ok(Node::leaf(Lambert))
}
