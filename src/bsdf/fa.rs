//! Fresnel aggregate of a diffuse base and a GGX highlight (the benchmark paper §2.1.2):
//! f = ggx(α, η, k_s) + (1 − F(μi; η)) (1 − F(μo; η)) · f_B,
//! the base seen through the interface that makes the highlight. B is one of
//! `lambert on eon vmf`. The lobe's parameters are named `lobe.*`, the base's `base.*`.
//! Twin: `shaders/bsdf/fa.wgsl`.

use super::ggx::{ggx_reflect, GgxLobe, ALPHA, ETA, KS};
use super::{Bsdf, Channels, Entry, Node, ParamDecl, Role, WgslFn};
use super::microfacet::MICROFACET_WGSL;
use crate::data::Kind;
use crate::math::fresnel_transmittance;
use glam::DVec3;

#[derive(Debug, Clone, Copy)]
pub struct FresnelAggregate;

impl Bsdf for FresnelAggregate {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![
            ALPHA.renamed("lobe.alpha"),
            ETA.renamed("lobe.eta"),
            KS.renamed("lobe.ks"),
        ]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &["base"]
    }
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, children: &[f64]) -> f64 {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            return 0.0;
        }
        let (alpha, eta, ks) = (p[0], p[1], p[2]);
        let transmit =
            fresnel_transmittance(wi.z, eta) * fresnel_transmittance(wo.z, eta);
        ggx_reflect(ks, alpha, eta, wi, wo) + transmit * children[0]
    }
    /// The lobe's F and kernel and the two Fresnel transmittances once per direction;
    /// per channel only k_s and the base's value differ.
    fn eval_channels(&self, p: Channels, wi: DVec3, wo: DVec3, base: &[f64], out: &mut [f64]) {
        if wi.z <= 0.0 || wo.z <= 0.0 {
            out.fill(0.0);
            return;
        }
        let (alpha, eta) = (p.get(0, 0), p.get(0, 1));
        let transmit =
            fresnel_transmittance(wi.z, eta) * fresnel_transmittance(wo.z, eta);
        let lobe = GgxLobe::at(alpha, eta, wi, wo);
        for (i, (o, &b)) in out.iter_mut().zip(base).enumerate() {
            *o = lobe.scaled(p.get(i, 2)) + transmit * b;
        }
    }
    fn wgsl(&self) -> WgslFn {
        WgslFn {
            sources: vec![
                MICROFACET_WGSL,
                ("fa", include_str!("../../shaders/bsdf/fa.wgsl")),
            ],
            function: "fa_eval".into(),
        }
    }
}

/// Registry entry (one line in [`super::registry::REGISTRY`]).
pub const ENTRY: Entry = Entry::layer(
    "fa",
    Kind::Brdf,
    &[Role::DiffuseBase],
    "Fresnel aggregate: GGX lobe over a diffuse base B: fa(B)",
    |base| Node::with(FresnelAggregate, vec![base]),
);
