//! Fresnel aggregate of a diffuse base and a GGX highlight (the benchmark paper §2.1.2):
//! f = ggx(α, η, k_s) + (1 − F(μi; η)) (1 − F(μo; η)) · f_B,
//! the base seen through the interface that makes the highlight. B is one of
//! `lambert on eon vmf`. The lobe's parameters are named `lobe.*`, the base's `base.*`.
//! Twin: `shaders/bsdf/fa.wgsl`.

use super::ggx::{ggx_reflect, GgxLobe, ALPHA, ETA, KS};
use super::effect::{Adds, Effect};
use super::{each_direction, Bsdf, Channels, Children, Dir, Entry, Memo, Node, ParamDecl, Role, WgslFn};
use super::microfacet::MICROFACET_WGSL;
use crate::data::Kind;
use crate::math::fresnel_transmittance;
use glam::DVec3;

#[derive(Debug, Clone, Copy)]
pub struct FresnelAggregate;

/// Directions whose shared factors are computed in one pass (a few kB on the stack).
const CHUNK: usize = 16;

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
    /// The lobe's F and kernel and the two Fresnel transmittances once per direction
    /// (the transmittances once per run of directions with the same μi, μo: [`Memo`]);
    /// per channel only k_s and the base's value differ.
    fn eval_channels(&self, p: Channels, dirs: &[Dir], base: Children, out: &mut [f64]) {
        let (alpha, eta, n) = (p.get(0, 0), p.get(0, 1), p.len());
        let (mut ti, mut to) = (Memo::default(), Memo::default());
        let ft = |mu| fresnel_transmittance(mu, eta);
        // Two passes per chunk of directions: first the shared factors of every direction
        // (independent of one another, so the processor overlaps their chains of square
        // roots and divisions), then the per-channel products.
        let mut shared = [(GgxLobe::ZERO, 0.0); CHUNK];
        for (c, dirs) in dirs.chunks(CHUNK).enumerate() {
            for (s, &(wi, wo)) in shared.iter_mut().zip(dirs) {
                *s = if wi.z <= 0.0 || wo.z <= 0.0 {
                    (GgxLobe::ZERO, 0.0)
                } else {
                    let transmit = ti.get(wi.z, ft) * to.get(wo.z, ft);
                    (GgxLobe::at(alpha, eta, wi, wo), transmit)
                };
            }
            let first = c * CHUNK;
            let out = &mut out[first * n..(first + dirs.len()) * n];
            each_direction(dirs, n, out, |d, wi, wo, out| {
                if wi.z <= 0.0 || wo.z <= 0.0 {
                    out.fill(0.0);
                    return;
                }
                let (lobe, transmit) = shared[d];
                for (i, (o, &b)) in out.iter_mut().zip(base.at(0, first + d)).enumerate() {
                    *o = lobe.scaled(p.get(i, 2)) + transmit * b;
                }
            });
        }
    }
    fn anisotropic(&self) -> Option<std::sync::Arc<dyn Bsdf>> {
        Some(super::aniso::fa())
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
)
.adding(&[
    // k_s = 0 is the base alone: the lobe adds a specular highlight.
    Adds::wrapping(Effect::SpecularLobe),
    // Over a black Lambertian base it is the GGX lobe alone: the base adds a diffuse floor.
    Adds::containing(
        Effect::DiffuseFloor,
        super::ggx::ENTRY.name,
        super::lambert::ENTRY.name,
    ),
]);
