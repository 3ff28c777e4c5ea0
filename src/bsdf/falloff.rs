//! `M+<retro lobe>+falloff`: an entrance-angle efficiency for the retroreflective lobe
//! written just before it (`+retro`, `+mrm`, `+mrm82`; docs/models.md):
//! f = f_M + E(μi, μo) · f_lobe with E = (μi μo)^q, q ≥ 0.
//!
//! Why: a retroreflective sheet returns light through elements (glass beads, cube-corner
//! prisms) whose working aperture shrinks as the light enters obliquely; retroreflective
//! sheeting is specified by a coefficient of retroreflection that falls with the entrance
//! angle (the "entrance angularity" of the sheeting). A back-vector microfacet lobe does
//! the opposite: its peak D(n)·G2/(4μi²) grows as 1/μi² towards grazing incidence. E is the
//! simplest factor that (i) is reciprocal (symmetric in μi and μo), (ii) is 1 at normal
//! incidence and never above 1, so the lobe only loses energy, (iii) is monotone in the
//! entrance angle, and (iv) is exactly 1 at q = 0 (the neutral value), so `M+mrm` is
//! `M+mrm+falloff` at q = 0 (nested). At the retro peak (μo = μi) it is μi^(2q): q = 1
//! cancels the 1/μi² growth of the lobe's peak, larger q makes the peak fall.
//!
//! How it applies to the lobe only: every retro lobe node has two children, the model M it
//! is added to and an efficiency slot that it multiplies its own value by
//! (f = f_M + slot · f_lobe). Without `+falloff` the slot is [`NoFalloff`] (E = 1, no
//! parameter); `+falloff` puts [`Falloff`] there. The diffuse base and the specular lobe
//! of M never see E. Twin: `shaders/bsdf/falloff.wgsl`.

use super::effect::{Adds, Effect};
use super::kernel::{lanes, Kernel, LaneChildren, LaneDir};
use super::{Bsdf, Channels, Entry, InCatalogue, Node, ParamDecl, WgslFn};
use crate::data::Kind;
use crate::math::lanes::Real;

const WGSL: (&str, &str) = ("falloff", include_str!("../../shaders/bsdf/falloff.wgsl"));

/// The exponent q of [`efficiency`].
pub const Q: ParamDecl = ParamDecl::shared(
    "q",
    0.0,
    10.0,
    1.0,
    "retro lobe entrance-angle exponent: E = (mu_i mu_o)^q",
)
// q = 0: E = 1, the lobe as without +falloff.
.neutral_at(0.0);

/// The efficiency slot of a retro lobe without `+falloff`: E = 1, no parameter.
#[derive(Debug, Clone, Copy)]
pub struct NoFalloff;

/// The slot's declaration: not in the registry (no spec names it), only the node's identity.
const NO_FALLOFF: Entry = Entry::suffix(
    "no_falloff",
    Some(Kind::Brdf),
    InCatalogue::No,
    "a retro lobe's efficiency slot without +falloff (E = 1)",
    |_| Err("the efficiency slot is not a spec suffix".into()),
);

impl Kernel for NoFalloff {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        for (_, _, out) in lanes(dirs, p.len(), out) {
            out.fill(R::splat(1.0));
        }
    }
}

impl Bsdf for NoFalloff {
    fn entry(&self) -> &'static Entry {
        &NO_FALLOFF
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        WgslFn {
            sources: vec![WGSL],
            function: "falloff_none_eval".into(),
        }
    }
}

/// E = (μi μo)^q in a retro lobe's efficiency slot.
#[derive(Debug, Clone, Copy)]
pub struct Falloff;

impl Kernel for Falloff {
    /// The efficiency E = (μi μo)^q, the same in every channel (0 below the surface,
    /// where every retro lobe is 0).
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        let q = p.get(0, 0);
        let zero = R::zero();
        for (_, (wi, wo), out) in lanes(dirs, p.len(), out) {
            let above = zero.lt(wi.z) & zero.lt(wo.z);
            let e = R::select(above, (wi.z * wo.z).powf(q), zero);
            out.fill(e);
        }
    }
}

impl Bsdf for Falloff {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![Q]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        WgslFn::single("falloff", WGSL.1)
    }
}

/// The children of a retro lobe added to `inner`: the model itself and an empty
/// efficiency slot (E = 1) that `+falloff` may fill.
pub fn lobe_children(inner: Node) -> Vec<Node> {
    vec![inner, Node::leaf(NoFalloff)]
}

/// Whether `node` is a retro lobe (it has an efficiency slot), e.g. the root of `M+mrm`.
pub fn is_retro_lobe(node: &Node) -> bool {
    node.children.len() == 2 && {
        let slot = node.children[1].bsdf.name();
        slot == NO_FALLOFF.name || slot == ENTRY.name
    }
}

/// Registry entry (one line in [`super::registry::REGISTRY`]).
pub const ENTRY: Entry = Entry::suffix(
    "falloff",
    Some(Kind::Brdf),
    InCatalogue::No,
    "entrance-angle efficiency (mu_i mu_o)^q of the retro lobe before it (+retro, +mrm, +mrm82)",
    build,
)
// q = 0 is M alone. Only a spec with a retro lobe accepts it; on others the extension does
// not build and is not tried.
.adding(&[Adds::appended(Effect::RetroFalloff)]);

pub fn build(inner: Node) -> Result<Node, String> {
    if !is_retro_lobe(&inner) {
        return Err(format!(
            "+falloff scales a retro lobe and must follow one (+retro, +mrm, +mrm82), e.g. lambert+mrm+falloff; '{}' is not a retro lobe",
            inner.bsdf.name()
        ));
    }
    if inner.children[1].bsdf.name() == ENTRY.name {
        return Err("+falloff given twice".into());
    }
    let mut node = inner;
    node.children[1] = Node::leaf(Falloff);
    Ok(node)
}
