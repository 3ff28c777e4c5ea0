//! Fresnel aggregate of a diffuse base and a GGX highlight (the benchmark paper §2.1.2):
//! f = ggx(α, η, k_s) + (1 − F(μi; η)) (1 − F(μo; η)) · f_B,
//! the base seen through the interface that makes the highlight. B is one of
//! `lambert on eon vmf`. The lobe's parameters are named `lobe.*`, the base's `base.*`.
//! Twin: `shaders/bsdf/fa.wgsl`.

use super::ggx::{GgxLobe, ALPHA, ETA, KS};
use super::kernel::{lanes, Kernel, LaneChildren, LaneDir, Memo};
use super::effect::{Adds, Effect};
use super::{Bsdf, Channels, Entry, Node, ParamDecl, Role, WgslFn};
use super::microfacet::MICROFACET_WGSL;
use crate::data::Kind;
use crate::math::fresnel_transmittance_in;
use crate::math::lanes::{Real, V3};
use std::sync::Arc;
use super::ggx::aniso_lobe;
use super::stretched::{Frame, ALPHA_U, ALPHA_V, PHI0};

#[derive(Debug, Clone, Copy)]
pub struct FresnelAggregate;

impl Kernel for FresnelAggregate {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], base: LaneChildren<R>, out: &mut [R]) {
        let (alpha, eta) = (p.get(0, 0), p.get(0, 1));
        aggregate_block(
            p,
            dirs,
            base,
            out,
            #[inline(always)]
            |wi, wo| GgxLobe::at_in(alpha, eta, wi, wo),
        );
    }
}

/// The aggregate's values when its parameters begin `lobe.alpha, lobe.eta, lobe.ks`:
/// the lobe's F and kernel and the two Fresnel transmittances once per direction (the
/// transmittances once per run of directions with the same μi, μo: a memo); per channel
/// only k_s and the base's value differ (`fa(B)` and its `+ndf` form).
#[inline(always)]
pub fn aggregate_block<R: Real>(
    p: Channels,
    dirs: &[LaneDir<R>],
    base: LaneChildren<R>,
    out: &mut [R],
    lobe: impl Fn(V3<R>, V3<R>) -> GgxLobe<R>,
) {
    aggregate_block_with(
        p,
        p.get(0, 1),
        dirs,
        base,
        out,
        lobe,
        #[inline(always)]
        |lobe, i| lobe.scaled(R::splat(p.get(i, 2))),
    );
}

/// [`aggregate_block`] with the interface's index η given (the anisotropic lobe's
/// parameters put it fourth) and channel i's highlight taken by `channel` from the
/// direction's lobe (`+fresnel` reshapes F per channel).
#[inline(always)]
pub fn aggregate_block_with<R: Real>(
    p: Channels,
    eta: f64,
    dirs: &[LaneDir<R>],
    base: LaneChildren<R>,
    out: &mut [R],
    lobe: impl Fn(V3<R>, V3<R>) -> GgxLobe<R>,
    channel: impl Fn(&GgxLobe<R>, usize) -> R,
) {
    let n = p.len();
    let zero = R::zero();
    let (mut ti, mut to) = (Memo::default(), Memo::default());
    for (d, (wi, wo), out) in lanes(dirs, n, out) {
        let below = wi.z.le(zero) | wo.z.le(zero);
        let lobe = lobe(wi, wo);
        let transmit = ti.get(
            wi.z,
            #[inline(always)]
            |mu| fresnel_transmittance_in(mu, R::splat(eta)),
        ) * to.get(
            wo.z,
            #[inline(always)]
            |mu| fresnel_transmittance_in(mu, R::splat(eta)),
        );
        for (i, (o, &b)) in out.iter_mut().zip(base.at(0, d)).enumerate() {
            let v = channel(&lobe, i) + transmit * b;
            *o = R::select(below, zero, v);
        }
    }
}

impl Bsdf for FresnelAggregate {
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((super::GgxPlace::Aggregate, super::Tabulated { ndf: false, fresnel: false }))
    }
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
    super::kernel::kernel_methods!();
    fn anisotropic(&self) -> Option<std::sync::Arc<dyn Bsdf>> {
        Some(Arc::new(FaAniso))
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

// ---------------------------------------------------------------------------------------
// The anisotropic form (`+aniso`): its entry is not registered (the spec names it as
// `M+aniso`); it carries the isotropic model's name, kind and role.

/// `fa(B)` with an anisotropic highlight: lobe.α_u, lobe.α_v, lobe.φ0, lobe.η, lobe.k_s.
#[derive(Debug, Clone, Copy)]
pub struct FaAniso;

const FA_ENTRY: Entry = Entry::layer(
    "fa",
    Kind::Brdf,
    &[Role::DiffuseBase],
    "Fresnel aggregate with an anisotropic GGX lobe",
    |base| Node::with(FaAniso, vec![base]),
);

impl Kernel for FaAniso {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], base: LaneChildren<R>, out: &mut [R]) {
        let (au, av, frame, eta) = (p.get(0, 0), p.get(0, 1), Frame::new(p.get(0, 2)), p.get(0, 3));
        aggregate_block_with(
            p,
            eta,
            dirs,
            base,
            out,
            #[inline(always)]
            |wi, wo| aniso_lobe(au, av, frame, eta, wi, wo),
            #[inline(always)]
            |lobe, i| lobe.scaled_outer(R::splat(p.get(i, 4))),
        );
    }
}

impl Bsdf for FaAniso {
    fn entry(&self) -> &'static Entry {
        &FA_ENTRY
    }
    fn frame_params(&self) -> Option<[usize; 3]> {
        Some([0, 1, 2])
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![
            ALPHA_U.renamed("lobe.alpha_u"),
            ALPHA_V.renamed("lobe.alpha_v"),
            PHI0.renamed("lobe.phi0"),
            ETA.renamed("lobe.eta"),
            KS.renamed("lobe.ks"),
        ]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &["base"]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        super::stretched::wgsl("fa_aniso_eval")
    }
}

