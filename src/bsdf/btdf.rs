//! Microfacet transmission (the benchmark paper §2.3.2, Eq. 1; Walter, Marschner, Li,
//! Torrance 2007) with four normal distributions from [`super::microfacet`], and the BTDF
//! suffix combinators. Twin: `shaders/bsdf/btdf.wgsl` (with `microfacet.wgsl`).
//!
//! f_t(ωi, ωo) = |i·m| |o·m| (1 − F(i·m)) G(i, o) D(m) / (|μi| |μo| (η_i (i·m) + η_t (o·m))²),
//! m = −(η_i i + η_t o)/‖η_i i + η_t o‖, η_i = 1, ωi above (z > 0), ωo below (z < 0).
//! There is no η_t² radiance factor (it cancels for a slab measured in air): this f_t is
//! Walter's BTDF f_W(i → o) divided by η_t², which by Walter's reciprocity
//! f_W(i → o)/η_t² = f_W(o → i)/η_i² is also f_W(o → i), the BTDF of the reverse path
//! (light inside the η_t medium arriving along ωo, leaving into air along ωi); the tests
//! check both relations against a literal transcription of Walter's equations.
//!
//! Walter's validity conditions: m is taken in the upper hemisphere (D(m) = 0 below);
//! the light must reach the front of the microfacet and leave through its back,
//! i·m > 0 and o·m < 0 (the χ⁺ factors of G1(i, m) and G1(o, m)). η_t = 1 is an
//! index-matched interface whose BTDF is a delta along ωo = −ωi: returned as 0.
//!
//! G = G1(i) G1(o), separable Smith. `tr`, `beckmann` and `gtr` use the Trowbridge–Reitz
//! Λ (as the paper), `gg` its own Λ from a table computed once in f64 ([`gg_lambda_table`],
//! bound as the GPU's `LUT`).
//!
//! Numerics (shared by both twins): the half vector is built as (i + o) + (η−1) o so that it
//! keeps its relative accuracy near η → 1 and o → −i; NDFs take cos²θm and sin²θm from the
//! components of m (no 1 − cos² cancellation at sharp peaks); G1/|μ| is evaluated in forms
//! without a division by μ, so grazing θt gives no 0·∞.

use super::kernel::{lanes, Kernel, LaneChildren, LaneDir, SlotMemo};
use super::microfacet::{
    gg_lambda_table, ggx_d, ggx_g1_over_mu, Beckmann, Distribution, Gg, Gtr, Masking,
    MICROFACET_WGSL,
};
use super::effect::{Adds, Effect};
use super::{Ast, Bsdf, Channels, Entry, InCatalogue, Node, ParamDecl, Role, WgslFn};
use crate::data::Kind;
use crate::math::fresnel_transmittance_in;
use crate::math::lanes::{Real, V3};
use glam::DVec3;
use std::f64::consts::PI;
use std::sync::Arc;
use super::stretched::{AnisoBeckmann, AnisoGg, AnisoGgx, Frame, ALPHA_U, ALPHA_V, ANISO_WGSL, BETA_U, BETA_V, PHI0};

pub(crate) const BTDF_WGSL: (&str, &str) = ("btdf", include_str!("../../shaders/bsdf/btdf.wgsl"));

/// Below this ‖i + η o‖² the configuration is the degenerate straight-through ray of an
/// index-matched interface: returned as 0 (also keeps f32 far from overflow).
pub const L2_MIN: f64 = 1e-20;

pub const ALPHA: ParamDecl = ParamDecl::shared("alpha", 1e-3, 1.0, 0.2, "microfacet roughness")
    .log()
    .per_axis();
pub const ETA: ParamDecl = ParamDecl::shared(
    "eta",
    1.0,
    3.0,
    1.5,
    "transmission refractive index eta_t (eta_i = 1)",
);
pub const GAMMA: ParamDecl = ParamDecl::shared(
    "gamma",
    0.5,
    4.0,
    2.0,
    "GTR tail exponent (2 = Trowbridge-Reitz)",
)
.neutral_at(2.0);
pub const BETA: ParamDecl = ParamDecl::shared("beta", 3e-3, 1.0, 0.2, "generalized Gaussian width")
    .log()
    .per_axis();
pub const P_SHAPE: ParamDecl = ParamDecl::shared(
    "p",
    0.2,
    5.0,
    1.0,
    "generalized Gaussian shape (1 = Beckmann)",
);
pub const SCALE: ParamDecl =
    ParamDecl::shared("scale", 0.0, 10.0, 1.0, "BTDF scale factor S").neutral_at(1.0);
pub const TAU: ParamDecl = ParamDecl::shared(
    "tau",
    0.0,
    5.0,
    0.1,
    "optical depth tau*d of the absorbing layer",
)
.neutral_at(0.0);
pub const KD: ParamDecl = ParamDecl::shared(
    "kd",
    0.0,
    1.0,
    0.05,
    "Lambertian transmission kd (adds kd/pi)",
)
.neutral_at(0.0);

/// The normal distribution of a `btdf(…)` term.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ndf {
    /// Trowbridge–Reitz (GGX): α, η.
    Tr,
    /// Beckmann: α, η (TR Smith G, as the paper).
    Beckmann,
    /// Burley's generalized TR: α, γ, η (TR Smith G).
    Gtr,
    /// Holzschuch–Pacanowski generalized Gaussian: β, p, η (its own Smith G).
    Gg,
}

impl Ndf {
    pub const ALL: [Ndf; 4] = [Ndf::Tr, Ndf::Beckmann, Ndf::Gtr, Ndf::Gg];

    pub fn name(self) -> &'static str {
        match self {
            Ndf::Tr => "tr",
            Ndf::Beckmann => "beckmann",
            Ndf::Gtr => "gtr",
            Ndf::Gg => "gg",
        }
    }

    pub fn from_name(name: &str) -> Option<Ndf> {
        Ndf::ALL.into_iter().find(|n| n.name() == name)
    }

    /// Parameters in the order `eval` (and the WGSL twin) reads them.
    pub fn params(self) -> Vec<ParamDecl> {
        match self {
            Ndf::Tr | Ndf::Beckmann => vec![ALPHA, ETA],
            Ndf::Gtr => vec![ALPHA, GAMMA, ETA],
            Ndf::Gg => vec![BETA, P_SHAPE, ETA],
        }
    }

}

// ---------------------------------------------------------------------------------------
// Walter transmission core

/// The refraction microfacet of a valid transmission configuration.
#[derive(Clone, Copy, Debug)]
pub struct Refraction<R: Real = f64> {
    /// Microfacet normal, upper hemisphere (m.z > 0), unit.
    pub m: V3<R>,
    /// i·m > 0.
    pub im: R,
    /// o·m < 0.
    pub om: R,
    /// (η_i (i·m) + η_t (o·m))² = ‖i + η_t o‖².
    pub l2: R,
}

/// Walter's refraction half vector and validity conditions; `None` when f_t = 0
/// (ωi not above, ωo not below, η ≤ 1, degenerate or back-facing microfacet).
pub fn refraction(wi: DVec3, wo: DVec3, eta: f64) -> Option<Refraction> {
    let (r, valid) = refraction_in(V3::from(wi), V3::from(wo), eta);
    valid.then_some(r)
}

/// [`refraction`] over any [`Real`]: the microfacet, and where it is valid.
#[inline(always)]
pub fn refraction_in<R: Real>(wi: V3<R>, wo: V3<R>, eta: f64) -> (Refraction<R>, R::Mask) {
    let zero = R::zero();
    let valid = zero.lt(wi.z) & wo.z.lt(zero) & R::splat(1.0).lt(R::splat(eta));
    // v = i + η o, written so that it keeps its relative accuracy when it is small.
    let v = (wi + wo) + wo.scale(R::splat(eta - 1.0));
    let l2 = v.dot(v);
    // Not NaN and above L2_MIN.
    let valid = valid & R::splat(L2_MIN).lt(l2);
    let len = l2.sqrt();
    let m = V3::new(-v.x / len, -v.y / len, -v.z / len);
    // D lives on the upper hemisphere; the χ⁺ tests below reject this side for η > 1.
    let m = V3::select(m.z.lt(zero), V3::new(-m.x, -m.y, -m.z), m);
    let im = wi.dot(m);
    let om = wo.dot(m);
    let valid = valid & zero.lt(m.z) & zero.lt(im) & om.lt(zero);
    (Refraction { m, im, om, l2 }, valid)
}

/// Eq. 1 with the distribution `ndf` and the Smith masking `masking`.
pub fn walter_transmission(
    wi: DVec3,
    wo: DVec3,
    eta: f64,
    ndf: &impl Distribution,
    masking: &impl Masking,
) -> f64 {
    let Some(r) = refraction(wi, wo, eta) else {
        return 0.0;
    };
    transmit(
        &r,
        eta,
        ndf.d(r.m.into()),
        masking.g1_over_mu(wi),
        masking.g1_over_mu(wo),
    )
}

/// |i·m| |o·m| (1 − F(i·m)) D · (G1(i)/|μi|) (G1(o)/|μo|) / ‖i + η o‖².
#[inline(always)]
pub fn transmit<R: Real>(r: &Refraction<R>, eta: f64, d: R, g1i_over_mu: R, g1o_over_mu: R) -> R {
    r.im * (-r.om) * fresnel_transmittance_in(r.im, R::splat(eta)) * d * g1i_over_mu * g1o_over_mu
        / r.l2
}

impl Ndf {
    /// f_t for this NDF with parameters `p` (in [`Ndf::params`] order) over any [`Real`]:
    /// the kernel of `btdf(…)`, Eq. 1 ([`walter_in`]) with the NDF's D and G1.
    #[inline(always)]
    pub fn eval_in<R: Real>(self, p: [f64; 3], wi: V3<R>, wo: V3<R>) -> R {
        // (Closures marked inline: out of line they would be compiled without the
        // vector extensions of the kernel that calls them.)
        match self {
            Ndf::Gg => {
                let gg = Gg::new(p[0], p[1]);
                walter_in(
                    wi,
                    wo,
                    p[2],
                    #[inline(always)]
                    |m| gg.d_in(m),
                    #[inline(always)]
                    |w| gg.g1_over_mu_in(w),
                )
            }
            Ndf::Tr => walter_in(
                wi,
                wo,
                p[1],
                #[inline(always)]
                |m| ggx_d(p[0], m),
                #[inline(always)]
                |w| ggx_g1_over_mu(p[0], w),
            ),
            Ndf::Beckmann => walter_in(
                wi,
                wo,
                p[1],
                #[inline(always)]
                |m| Beckmann { alpha: p[0] }.d_in(m),
                #[inline(always)]
                |w| ggx_g1_over_mu(p[0], w),
            ),
            Ndf::Gtr => walter_in(
                wi,
                wo,
                p[2],
                #[inline(always)]
                |m| {
                    Gtr {
                        alpha: p[0],
                        gamma: p[1],
                    }
                    .d_in(m)
                },
                #[inline(always)]
                |w| ggx_g1_over_mu(p[0], w),
            ),
        }
    }
}

// ---------------------------------------------------------------------------------------
// Nodes

/// A `btdf(ndf)` term.
#[derive(Clone, Copy, Debug)]
pub struct Btdf {
    pub ndf: Ndf,
}

impl Kernel for Btdf {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        let third = if p.count() > 2 { p.get(0, 2) } else { 0.0 };
        let p3 = [p.get(0, 0), p.get(0, 1), third];
        if self.ndf == Ndf::Gg && !R::F64 {
            return gg_tabled(p3, dirs, p.len(), out);
        }
        for (_, (wi, wo), out) in lanes(dirs, p.len(), out) {
            out.fill(self.ndf.eval_in(p3, wi, wo));
        }
    }
}

/// `btdf(gg)` in f32 lanes with G1/|μ| from per-block tables keyed by the engine's μ
/// slots ([`SlotMemo`], as the GPU's `btdf_gg_prepare` tabulates it per candidate): each
/// G1 reads sixteen entries of the Λ table lane by lane, otherwise most of the kernel's
/// cost. f32 lanes only: G1 takes sinθ from the direction's x and y, which a slot (keyed
/// by μ) does not see, so directions sharing a μ get the first one's value, equal to
/// rounding but not bit for bit as f64 lanes must be.
#[inline(always)]
fn gg_tabled<R: Real>(p: [f64; 3], dirs: &[LaneDir<R>], n: usize, out: &mut [R]) {
    let (gg, row) = (Gg::new(p[0], p[1]), gg_lambda_table().row(p[1]));
    let row = Some(&row);
    let (mut g_i, mut g_o) = (SlotMemo::default(), SlotMemo::default());
    for (dir, out) in dirs.iter().zip(out.chunks_exact_mut(n.max(1))) {
        let ([slot_i, slot_o], wi, wo) = (dir.mu_slots, dir.wi, dir.wo);
        let value = walter_with_g1(
            wi,
            wo,
            p[2],
            #[inline(always)]
            |m| gg.d_in(m),
            #[inline(always)]
            || {
                let g1i = g_i.get(
                    slot_i,
                    wi.z,
                    #[inline(always)]
                    |_| gg.g1_over_mu_with(wi, row),
                );
                let g1o = g_o.get(
                    slot_o,
                    wo.z,
                    #[inline(always)]
                    |_| gg.g1_over_mu_with(wo, row),
                );
                (g1i, g1o)
            },
        );
        out.fill(value);
    }
}

impl Bsdf for Btdf {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    /// TR's lobe is GGX's, which `+ndf` makes data-driven (the other distributions are not
    /// at the table's zero deviation, so they would not embed).
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        (self.ndf == Ndf::Tr).then(|| (super::GgxPlace::Transmission, super::Tabulated::default()))
    }
    fn params(&self) -> Vec<ParamDecl> {
        self.ndf.params()
    }
    super::kernel::kernel_methods!();
    /// f(i, o) needs ωi above and ωo below, so f(o, i) = 0: not reciprocal by swapping.
    fn reciprocal(&self) -> bool {
        false
    }
    fn wgsl(&self) -> WgslFn {
        WgslFn {
            sources: vec![MICROFACET_WGSL, ANISO_WGSL, BTDF_WGSL],
            function: format!("btdf_{}_eval", self.ndf.name()),
        }
    }
    fn anisotropic(&self) -> Option<std::sync::Arc<dyn Bsdf>> {
        BtdfAniso::of(self.ndf).map(|b| Arc::new(b) as Arc<dyn Bsdf>)
    }
    fn lut(&self) -> Option<Vec<f32>> {
        match self.ndf {
            Ndf::Gg => Some(gg_lambda_table().to_f32()),
            _ => None,
        }
    }
    fn wgsl_prepare(&self) -> Option<&'static str> {
        match self.ndf {
            // GG's shape constants and its G1(μ)/μ at every polar cosine of the problem:
            // its Λ table costs 16 texel fetches per G1.
            Ndf::Gg => Some("btdf_gg_prepare"),
            _ => None,
        }
    }
}

/// A BTDF suffix combinator.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Suffix {
    /// f · S.
    Scale,
    /// f · exp(−τ/μt), μt = |ωo.z|.
    Absorb,
    /// f + k_d/π for ωi above and ωo below.
    Diffuse,
}

impl Suffix {
    pub fn name(self) -> &'static str {
        self.entry().name
    }
    pub fn apply(self, k: f64, wi: DVec3, wo: DVec3, inner: f64) -> f64 {
        self.apply_in(k, V3::from(wi), V3::from(wo), inner)
    }

    /// [`Self::apply`] over any [`Real`].
    #[inline(always)]
    pub fn apply_in<R: Real>(self, k: f64, wi: V3<R>, wo: V3<R>, inner: R) -> R {
        match self {
            Suffix::Scale => inner * R::splat(k),
            Suffix::Absorb => inner * (R::splat(-k) / wo.z.abs().max(R::splat(1e-20))).exp(),
            Suffix::Diffuse => {
                let zero = R::zero();
                let through = zero.lt(wi.z) & wo.z.lt(zero);
                R::select(through, inner + R::splat(k / PI), inner)
            }
        }
    }
}

impl Kernel for Suffix {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], inner: LaneChildren<R>, out: &mut [R]) {
        for (d, (wi, wo), out) in lanes(dirs, p.len(), out) {
            for (i, (o, &f)) in out.iter_mut().zip(inner.at(0, d)).enumerate() {
                *o = self.apply_in(p.get(i, 0), wi, wo, f);
            }
        }
    }
}

impl Bsdf for Suffix {
    fn entry(&self) -> &'static Entry {
        match self {
            Suffix::Scale => &SCALE_ENTRY,
            Suffix::Absorb => &ABSORB_ENTRY,
            Suffix::Diffuse => &DIFFUSE_ENTRY,
        }
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![match self {
            Suffix::Scale => SCALE,
            Suffix::Absorb => TAU,
            Suffix::Diffuse => KD,
        }]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &[""]
    }
    super::kernel::kernel_methods!();
    fn reciprocal(&self) -> bool {
        false
    }
    fn wgsl(&self) -> WgslFn {
        WgslFn {
            sources: vec![MICROFACET_WGSL, ANISO_WGSL, BTDF_WGSL],
            function: format!("btdf_{}_eval", self.name()),
        }
    }
}

// ---------------------------------------------------------------------------------------
// Builders (registry)

/// Registry entries: the transmission family and its three suffixes.
pub const ENTRY: Entry = Entry::term(
    "btdf",
    Kind::Btdf,
    Role::Transmission,
    "Walter 2007 microfacet transmission: btdf(tr|beckmann|gtr|gg)",
    build,
)
.with_variants(&["tr", "beckmann", "gtr", "gg"])
.adding(&[
    // TR's tails are longer than Beckmann's and the Generalized Gaussian's: a swap.
    Adds::variant(Effect::LongTail, &["beckmann", "gg"], "tr").not_nested(),
    // γ = 2 is TR.
    Adds::variant(Effect::LongTail, &["tr"], "gtr"),
]);
const BTDF: Option<Kind> = Some(Kind::Btdf);
pub const SCALE_ENTRY: Entry = Entry::suffix(
    "scale",
    BTDF,
    InCatalogue::Yes,
    "multiplies a BTDF by S",
    build_scale,
)
// S = 1 is M alone.
.adding(&[Adds::appended(Effect::Scale)]);
pub const ABSORB_ENTRY: Entry = Entry::suffix(
    "absorb",
    BTDF,
    InCatalogue::Yes,
    "Beer-Lambert attenuation exp(-tau/mu_t) (BTDF)",
    build_absorb,
)
// τ = 0 is M alone.
.adding(&[Adds::appended(Effect::Absorption)]);
pub const DIFFUSE_ENTRY: Entry = Entry::suffix(
    "diffuse",
    BTDF,
    InCatalogue::No,
    "adds a Lambertian transmission kd/pi (BTDF)",
    build_diffuse,
)
// k_d = 0 is M alone.
.adding(&[Adds::appended(Effect::DiffuseFloor)]);

const NDF_LIST: &str = "tr, beckmann, gtr, gg";

pub fn build(arg: Option<&Ast>) -> Result<Node, String> {
    let Some(arg) = arg else {
        return Err(format!(
            "'btdf' needs a normal distribution: btdf(x) with x one of {NDF_LIST}"
        ));
    };
    match arg {
        Ast::Term { name, arg: None } => match Ndf::from_name(name) {
            Some(ndf) => Ok(Node::leaf(Btdf { ndf })),
            None => Err(format!("unknown BTDF distribution 'btdf({name})' (known: {NDF_LIST})")),
        },
        _ => Err(format!(
            "'btdf' takes a distribution name (one of {NDF_LIST}); suffixes go outside: btdf(tr)+scale"
        )),
    }
}

fn wrap(suffix: Suffix, inner: Node) -> Result<Node, String> {
    let s = suffix.name();
    if inner.bsdf.kind() != Kind::Btdf {
        return Err(format!(
            "+{s} applies to BTDF models (btdf({NDF_LIST})), not to the BRDF model '{}'",
            inner.bsdf.name()
        ));
    }
    let mut n = &inner;
    loop {
        if n.bsdf.name() == s {
            return Err(format!("+{s} given twice"));
        }
        match n.children.first() {
            Some(c) => n = c,
            None => break,
        }
    }
    Ok(Node::with(suffix, vec![inner]))
}

pub fn build_scale(inner: Node) -> Result<Node, String> {
    wrap(Suffix::Scale, inner)
}

pub fn build_absorb(inner: Node) -> Result<Node, String> {
    wrap(Suffix::Absorb, inner)
}

pub fn build_diffuse(inner: Node) -> Result<Node, String> {
    wrap(Suffix::Diffuse, inner)
}

// ---------------------------------------------------------------------------------------
// The anisotropic form (`+aniso`): its entry is not registered (the spec names it as
// `M+aniso`); it carries the isotropic model's name, kind and role.

/// `btdf(ndf)` with an anisotropic distribution: α_u, α_v, φ0, η (tr, beckmann) or
/// β_u, β_v, φ0, p, η (gg).
#[derive(Debug, Clone, Copy)]
pub struct BtdfAniso {
    pub ndf: Ndf,
}

const BTDF_ENTRY: Entry = Entry::term(
    "btdf",
    Kind::Btdf,
    Role::Transmission,
    "Walter 2007 microfacet transmission, anisotropic",
    |_| Err("the anisotropic forms are made by +aniso".into()),
);

impl BtdfAniso {
    /// The NDFs with an anisotropic form (GTR is not shape-invariant: stretching its
    /// slopes does not give a GTR).
    pub fn of(ndf: Ndf) -> Option<BtdfAniso> {
        matches!(ndf, Ndf::Tr | Ndf::Beckmann | Ndf::Gg).then_some(BtdfAniso { ndf })
    }
}

impl Kernel for BtdfAniso {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        let (bu, bv, frame) = (p.get(0, 0), p.get(0, 1), Frame::new(p.get(0, 2)));
        let (p3, p4) = (p.get(0, 3), if p.count() > 4 { p.get(0, 4) } else { 0.0 });
        let tr = AnisoGgx { au: bu, av: bv };
        let beckmann = AnisoBeckmann { au: bu, av: bv };
        let gg = (self.ndf == Ndf::Gg).then(|| AnisoGg::new(bu, bv, p3));
        // In f32 lanes the Λ table at this p, read four values a lane instead of sixteen.
        let row = gg.as_ref().filter(|_| !R::F64).map(AnisoGg::row);
        // (Closures marked inline: out of line they would be compiled without the
        // vector extensions of the kernel that calls them.)
        for (_, (wi, wo), out) in lanes(dirs, p.len(), out) {
            let (li, lo) = (frame.local_in(wi), frame.local_in(wo));
            let value = match (self.ndf, &gg) {
                (_, Some(gg)) => walter_in(
                    li,
                    lo,
                    p4,
                    #[inline(always)]
                    |m| gg.d_in(m),
                    #[inline(always)]
                    |w| gg.g1_over_mu_with(w, row.as_ref()),
                ),
                (Ndf::Beckmann, None) => walter_in(
                    li,
                    lo,
                    p3,
                    #[inline(always)]
                    |m| beckmann.d_in(m),
                    #[inline(always)]
                    |w| tr.g1_over_mu_in(w),
                ),
                _ => walter_in(
                    li,
                    lo,
                    p3,
                    #[inline(always)]
                    |m| tr.d_in(m),
                    #[inline(always)]
                    |w| tr.g1_over_mu_in(w),
                ),
            };
            out.fill(value);
        }
    }
}

/// Eq. 1 over any [`Real`] with the distribution `d` and the Smith G1/|μ| `g1_over_mu`
/// (every `btdf` lobe, isotropic and anisotropic).
#[inline(always)]
pub(super) fn walter_in<R: Real>(
    wi: V3<R>,
    wo: V3<R>,
    eta: f64,
    d: impl Fn(V3<R>) -> R,
    g1_over_mu: impl Fn(V3<R>) -> R,
) -> R {
    walter_with_g1(
        wi,
        wo,
        eta,
        d,
        #[inline(always)]
        || (g1_over_mu(wi), g1_over_mu(wo)),
    )
}

/// [`walter_in`] with the pair G1(ωi)/|μi|, G1(ωo)/|μo| from `g1`, called only where a
/// lane refracts.
#[inline(always)]
fn walter_with_g1<R: Real>(
    wi: V3<R>,
    wo: V3<R>,
    eta: f64,
    d: impl Fn(V3<R>) -> R,
    g1: impl FnOnce() -> (R, R),
) -> R {
    let (r, valid) = refraction_in(wi, wo, eta);
    if !R::any(valid) {
        return R::zero();
    }
    let (g1i_over_mu, g1o_over_mu) = g1();
    let value = transmit(&r, eta, d(r.m), g1i_over_mu, g1o_over_mu);
    R::select(valid, value, R::zero())
}

impl Bsdf for BtdfAniso {
    fn entry(&self) -> &'static Entry {
        &BTDF_ENTRY
    }
    fn frame_params(&self) -> Option<[usize; 3]> {
        Some([0, 1, 2])
    }
    fn params(&self) -> Vec<ParamDecl> {
        match self.ndf {
            Ndf::Gg => vec![BETA_U, BETA_V, PHI0, P_SHAPE, ETA],
            _ => vec![ALPHA_U, ALPHA_V, PHI0, ETA],
        }
    }
    super::kernel::kernel_methods!();
    fn reciprocal(&self) -> bool {
        false
    }
    fn wgsl(&self) -> WgslFn {
        WgslFn {
            sources: vec![MICROFACET_WGSL, ANISO_WGSL, BTDF_WGSL],
            function: match self.ndf {
                Ndf::Tr => "btdf_aniso_tr_eval",
                Ndf::Beckmann => "btdf_aniso_beckmann_eval",
                _ => "btdf_aniso_gg_eval",
            }
            .into(),
        }
    }
    fn lut(&self) -> Option<Vec<f32>> {
        (self.ndf == Ndf::Gg).then(|| gg_lambda_table().to_f32())
    }
}


#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn declared_variants_are_the_ndfs() {
        let names: Vec<&str> = Ndf::ALL.iter().map(|n| n.name()).collect();
        assert_eq!(names, ENTRY.variants);
        assert_eq!(NDF_LIST, ENTRY.variants.join(", "));
    }
}
