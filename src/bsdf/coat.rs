//! `M+coat`: blends a second GGX specular lobe into any BRDF M (docs/models.md):
//! f = (1 − k_c) f_M + k_c · D(h) G1(ωi) G1(ωo) / (4 μi μo), GGX D and Smith G of
//! roughness α_c on the half vector h = normalize(ωi + ωo) ([`super::microfacet::Ggx`]),
//! no Fresnel factor. Where M already has a specular lobe (`fa(B)`), it is the second
//! lobe real coated materials show: a sharp reflection off a smooth top film over a broad
//! one from the rougher layer beneath (retroreflective sheeting, lacquered wood). The
//! lobe's directional albedo is at most 1 (Smith G only loses energy), so the blend keeps
//! M's energy bound; k_c = 0 is M (nested). Twin: `shaders/bsdf/coat.wgsl`.

use super::effect::{Adds, Effect};
use super::kernel::{lanes, Kernel, LaneChildren, LaneDir};
use super::microfacet::{ggx_reflection, single_wgsl};
use super::{Bsdf, Channels, Entry, InCatalogue, Node, ParamDecl, WgslFn};
use crate::data::Kind;
use crate::math::lanes::{Real, V3};
use std::sync::Arc;
use super::stretched::{AnisoGgx, Frame, ALPHA_U, ALPHA_V, PHI0};

#[derive(Debug, Clone, Copy)]
pub struct Coat;

impl Kernel for Coat {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], inner: LaneChildren<R>, out: &mut [R]) {
        let alpha = R::splat(p.get(0, 1));
        blend_block(
            p,
            dirs,
            inner,
            out,
            #[inline(always)]
            |wi, wo| ggx_reflection(alpha, wi, wo, wi + wo),
        );
    }
}

/// The coat's values when k_c (rgb) is the node's first parameter: the lobe's `kernel`
/// D G1 G1 / (4 μi μo) without its scale k_c once per direction (0 below the surface,
/// where the lobe is 0; it takes the unnormalised half vector, not 0 above); per channel
/// only k_c and M's value differ (`+coat` and its `+ndf` form).
#[inline(always)]
pub fn blend_block<R: Real>(
    p: Channels,
    dirs: &[LaneDir<R>],
    inner: LaneChildren<R>,
    out: &mut [R],
    kernel: impl Fn(V3<R>, V3<R>) -> R,
) {
    blend_block_with(
        p,
        dirs,
        inner,
        out,
        kernel,
        #[inline(always)]
        |_, _, _| R::splat(1.0),
    );
}

/// [`blend_block`] with channel i's lobe weighted by `factor(i, ωi, ωo)` as well
/// (`+fresnel` gives the coat an angular reflectance per channel; 1 leaves the values
/// bit for bit).
#[inline(always)]
pub fn blend_block_with<R: Real>(
    p: Channels,
    dirs: &[LaneDir<R>],
    inner: LaneChildren<R>,
    out: &mut [R],
    kernel: impl Fn(V3<R>, V3<R>) -> R,
    factor: impl Fn(usize, V3<R>, V3<R>) -> R,
) {
    let (zero, one) = (R::zero(), R::splat(1.0));
    for (d, (wi, wo), out) in lanes(dirs, p.len(), out) {
        let above = zero.lt(wi.z) & zero.lt(wo.z);
        let kernel = R::select(above, kernel(wi, wo), zero);
        for (i, (o, &m)) in out.iter_mut().zip(inner.at(0, d)).enumerate() {
            let kc = R::splat(p.get(i, 0));
            *o = (one - kc) * m + kc * factor(i, wi, wo) * kernel;
        }
    }
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
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((super::GgxPlace::Coat, super::Tabulated { ndf: false, fresnel: false }))
    }
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![KC, ALPHA_C]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &[""]
    }
    super::kernel::kernel_methods!();
    fn anisotropic(&self) -> Option<std::sync::Arc<dyn Bsdf>> {
        Some(Arc::new(CoatAniso))
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

// ---------------------------------------------------------------------------------------
// The anisotropic form (`+aniso`): its entry is not registered (the spec names it as
// `M+aniso`); it carries the isotropic model's name, kind and role.

/// `M+coat` with an anisotropic coat: k_c, α_c,u, α_c,v, φ0_c.
#[derive(Debug, Clone, Copy)]
pub struct CoatAniso;

const COAT_ENTRY: Entry = Entry::suffix(
    "coat",
    Some(Kind::Brdf),
    InCatalogue::No,
    "a second GGX lobe, anisotropic",
    |inner| Ok(Node::with(CoatAniso, vec![inner])),
);

impl Kernel for CoatAniso {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], inner: LaneChildren<R>, out: &mut [R]) {
        let (lobe, frame) = (AnisoGgx { au: p.get(0, 1), av: p.get(0, 2) }, Frame::new(p.get(0, 3)));
        blend_block(
            p,
            dirs,
            inner,
            out,
            #[inline(always)]
            |wi, wo| {
                let (li, lo) = (frame.local_in(wi), frame.local_in(wo));
                lobe.reflection_in(li, lo, li + lo)
            },
        );
    }
}

impl Bsdf for CoatAniso {
    fn entry(&self) -> &'static Entry {
        &COAT_ENTRY
    }
    fn frame_params(&self) -> Option<[usize; 3]> {
        Some([1, 2, 3])
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![
            KC,
            ALPHA_U.renamed("alpha_c_u"),
            ALPHA_V.renamed("alpha_c_v"),
            PHI0.renamed("phi0_c"),
        ]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &[""]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        super::stretched::wgsl("coat_aniso_eval")
    }
}

