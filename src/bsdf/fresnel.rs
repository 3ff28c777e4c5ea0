//! `M+fresnel`: the highlight's Fresnel factor made data-driven, per channel. Each
//! isotropic GGX highlight of M (`ggx`, the lobe of `fa(B)`) takes, in channel c,
//!
//!   k_s,c · F(θd; η) · exp(s_c(θd)) · D G1 G1 / (4 μi μo),
//!
//! θd the angle between ωi and the half vector, s_c a Catmull–Rom spline through
//! K = 9 knots in θd with s_c = 0 at normal incidence and one free value per channel at
//! each other knot (`fresnel1` … `fresnel8`, `lobe.fresnel1` … under `fa`). The dielectric
//! curve stays as the reference shape and k_s,c·F(0; η) keeps setting the reflectance at
//! normal incidence; the knots tabulate how the measured curve departs from the
//! dielectric one with the angle — a conductor's coloured, slowly rising F (Gold, copper),
//! a coating's interference, a rougher-than-GGX grazing roll-off that the highlight
//! shows as a Fresnel change. At s = 0 the model is M exactly (diagnose's F test, and a
//! fit starts from M's values). Only the highlight is reshaped: `fa`'s base keeps the
//! dielectric transmittance (1 − F(μi; η))(1 − F(μo; η)), which η still sets. The lobe
//! of `+coat`, which has no Fresnel factor (F ≡ 1), takes k_c,c e^{s_c(θd)} the same way
//! (knots `fresnel_c1` … `fresnel_c8`).
//!
//! In this form k_s scales the reference curve (bounded by 50, not 1: a conductor's
//! k_s F(0; η) is near 1 where F(0; 1.5) = 0.04). The factor is a log so that the curve
//! stays positive; it is not bounded by 1/F: a
//! fitted k_s,c F e^s above 1 at some θd says the lobe's other factors are wrong there,
//! and the fit report shows the curve (tabulated models of measured data, e.g. Dupuy et
//! al. 2015 and Lavoué et al. 2021, fit F per channel in the same way).
//!
//! The knots: x = 8 (1 − cos θd) is the knot coordinate, knot k at x = k (θ_k = 0, 29.0,
//! 41.4, 51.3, 60.0, 68.0, 75.5, 82.8 and 90 degrees: dense toward grazing, where
//! Fresnel curves change). The spline is continued linearly past both ends (F is smooth
//! in cos θd, so in x, with a slope at the normal).
//!
//! Twin: `shaders/bsdf/fresnel.wgsl`.

use super::coat::blend_block_with;
use super::effect::{Adds, Effect};
use super::fa::aggregate_block_with;
use super::ggx::{lobe_block_with, GgxLobe, ALPHA, ETA, KS};
use super::kernel::{Kernel, LaneChildren, LaneDir};
use super::microfacet::{ggx_reflection, MICROFACET_WGSL};
use super::{Bsdf, Channels, Entry, InCatalogue, Node, ParamDecl, Role, WgslFn};
use crate::data::Kind;
use crate::math::lanes::{Real, V3};

/// Knots of the log-factor, the first (normal incidence) fixed at 0.
pub const KNOTS: usize = 9;

const FRESNEL_WGSL: (&str, &str) = ("fresnel", include_str!("../../shaders/bsdf/fresnel.wgsl"));
/// The knots' spline in WGSL (`knot_factor`), shared with `+body`: twin of
/// [`log_factor`] and [`knot_coordinate`].
pub(super) const KNOTS_WGSL: (&str, &str) = ("knots", include_str!("../../shaders/bsdf/knots.wgsl"));

pub(super) const NAMES: [&str; KNOTS - 1] = [
    "fresnel1", "fresnel2", "fresnel3", "fresnel4", "fresnel5", "fresnel6", "fresnel7",
    "fresnel8",
];
pub(super) const COAT_NAMES: [&str; KNOTS - 1] = [
    "fresnel_c1",
    "fresnel_c2",
    "fresnel_c3",
    "fresnel_c4",
    "fresnel_c5",
    "fresnel_c6",
    "fresnel_c7",
    "fresnel_c8",
];
pub(super) const LOBE_NAMES: [&str; KNOTS - 1] = [
    "lobe.fresnel1",
    "lobe.fresnel2",
    "lobe.fresnel3",
    "lobe.fresnel4",
    "lobe.fresnel5",
    "lobe.fresnel6",
    "lobe.fresnel7",
    "lobe.fresnel8",
];

/// One knot's log-factor per channel: 0 is the dielectric curve there. ±6 spans e^12 of
/// change in F's shape: a conductor's curve against a dielectric's needs about −3.3 at
/// grazing, a clear coat's rise from F ≡ 1 about +3.2. (With ±10, one grazing value of
/// `dmg(ggx)+fresnel` whose base lobe was 2e4 times its usual size differed by 3.6e-3
/// between the f32 GPU engine and the reference: bounds no measured curve needs cost f32
/// accuracy.)
const KNOT: ParamDecl = ParamDecl::rgb(
    "fresnel",
    -6.0,
    6.0,
    0.0,
    "ln(F / F_dielectric(eta)) at this knot of the highlight's Fresnel curve (0: the dielectric curve; the knots' angles are in docs/models.md)",
)
.neutral_at(0.0)
.knot();

/// k_s of a reshaped highlight: the scale of the dielectric reference curve that e^s
/// reshapes, k_s F(0; η) the reflectance at normal incidence. A conductor's is up to 1
/// where a dielectric's F(0; η) is 0.04 (η = 1.5): k_s ≈ 24, so the bound is wider than
/// the analytic lobe's 1 (which it contains, so M still embeds).
pub(super) const KS_SCALE: ParamDecl = ParamDecl { hi: 50.0, ..KS };

pub(super) fn knots(names: &'static [&'static str]) -> impl Iterator<Item = ParamDecl> {
    names.iter().map(|n| KNOT.renamed(n))
}

/// The knot coordinate x ∈ [0, 8] of cos θd: knot k at x = k.
#[inline]
pub fn knot_coordinate(cos_d: f64) -> f64 {
    (KNOTS - 1) as f64 * (1.0 - cos_d.clamp(0.0, 1.0))
}

/// θd of knot k, in degrees (for reports and docs).
pub fn knot_degrees() -> [f64; KNOTS] {
    std::array::from_fn(|k| (1.0 - k as f64 / (KNOTS - 1) as f64).acos().to_degrees())
}

/// s at knot coordinate x: the Catmull–Rom spline through the knots, continued linearly
/// past both ends (s_{−1} = 2 s_0 − s_1, s_{K} = 2 s_{K−1} − s_{K−2}).
#[inline]
pub fn log_factor(s: &[f64; KNOTS], x: f64) -> f64 {
    let x = x.clamp(0.0, (KNOTS - 1) as f64);
    let k = (x as usize).min(KNOTS - 2);
    let t = x - k as f64;
    let p0 = if k == 0 { 2.0 * s[0] - s[1] } else { s[k - 1] };
    let (p1, p2) = (s[k], s[k + 1]);
    let p3 = if k + 2 < KNOTS { s[k + 2] } else { 2.0 * s[KNOTS - 1] - s[KNOTS - 2] };
    super::ndf::catmull_rom(p0, p1, p2, p3, t)
}

/// Channel i's knots (s_0 = 0, then the node's parameters from `first`).
#[inline(always)]
fn channel_knots(p: Channels, i: usize, first: usize) -> [f64; KNOTS] {
    std::array::from_fn(|k| if k == 0 { 0.0 } else { p.get(i, first + k - 1) })
}

/// A highlight's value in channel i with its curve: k_s,c (parameter `ks`) times the lobe
/// times e^{s_c(θd)}, the channel's knots from parameter `first` (`+fresnel`'s and
/// `+ndf+fresnel`'s `ggx` and `fa` forms).
#[inline(always)]
pub(super) fn curved<R: Real>(lobe: &GgxLobe<R>, p: Channels, i: usize, ks: usize, first: usize) -> R {
    lobe.scaled_by(R::splat(p.get(i, ks)), factor(&channel_knots(p, i, first), lobe.cos_d()))
}

/// A coat lobe's curve e^{s_c(θd)} in channel i, the knots from parameter `first`; cos θd =
/// ωi·h = |ωi + ωo| / 2 for unit directions (as the GGX lobe takes it).
#[inline(always)]
pub(super) fn coat_curve<R: Real>(p: Channels, i: usize, first: usize, wi: V3<R>, wo: V3<R>) -> R {
    factor(&channel_knots(p, i, first), R::splat(0.5) * (wi + wo).length())
}

/// exp(s) per lane at the cosines `c` (cos θd here, μ under `+body`).
#[inline(always)]
pub(super) fn factor<R: Real>(s: &[f64; KNOTS], c: R) -> R {
    R::from_fn(|l| log_factor(s, knot_coordinate(c.lane(l)))).exp()
}

/// `ggx` with a data-driven Fresnel curve: ks, alpha, eta, fresnel1 … fresnel8.
#[derive(Debug, Clone, Copy)]
pub struct GgxFresnel;

const GGX_ENTRY: Entry = Entry::leaf(
    "ggx",
    Kind::Brdf,
    Role::SpecularLobe,
    "GGX reflection with a data-driven Fresnel curve",
    || Node::leaf(GgxFresnel),
);

impl Kernel for GgxFresnel {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        let (alpha, eta) = (p.get(0, 1), p.get(0, 2));
        lobe_block_with(
            p,
            dirs,
            out,
            #[inline(always)]
            |wi, wo| GgxLobe::at_in(alpha, eta, wi, wo),
            #[inline(always)]
            |lobe, i| curved(lobe, p, i, 0, 3),
        );
    }
}

impl Bsdf for GgxFresnel {
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((super::GgxPlace::Ggx, super::Tabulated { ndf: false, fresnel: true }))
    }
    fn bounded_albedo(&self) -> bool {
        false // k_s F e^s has no bound of 1 (see the module doc)
    }
    fn entry(&self) -> &'static Entry {
        &GGX_ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        [KS_SCALE, ALPHA, ETA].into_iter().chain(knots(&NAMES)).collect()
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        fresnel_wgsl("ggx_fresnel_eval")
    }
}

/// `fa(B)` whose highlight has a data-driven Fresnel curve: lobe.alpha, lobe.eta,
/// lobe.ks, lobe.fresnel1 … 8; the base's transmittance stays dielectric (η).
#[derive(Debug, Clone, Copy)]
pub struct FaFresnel;

const FA_ENTRY: Entry = Entry::layer(
    "fa",
    Kind::Brdf,
    &[Role::DiffuseBase],
    "Fresnel aggregate whose highlight has a data-driven Fresnel curve",
    |base| Node::with(FaFresnel, vec![base]),
);

impl Kernel for FaFresnel {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], base: LaneChildren<R>, out: &mut [R]) {
        let (alpha, eta) = (p.get(0, 0), p.get(0, 1));
        aggregate_block_with(
            p,
            p.get(0, 1),
            dirs,
            base,
            out,
            #[inline(always)]
            |wi, wo| GgxLobe::at_in(alpha, eta, wi, wo),
            #[inline(always)]
            |lobe, i| curved(lobe, p, i, 2, 3),
        );
    }
}

impl Bsdf for FaFresnel {
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((super::GgxPlace::Aggregate, super::Tabulated { ndf: false, fresnel: true }))
    }
    fn bounded_albedo(&self) -> bool {
        false // k_s F e^s has no bound of 1 (see the module doc)
    }
    fn entry(&self) -> &'static Entry {
        &FA_ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        [
            ALPHA.renamed("lobe.alpha"),
            ETA.renamed("lobe.eta"),
            KS_SCALE.renamed("lobe.ks"),
        ]
        .into_iter()
        .chain(knots(&LOBE_NAMES))
        .collect()
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &["base"]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        fresnel_wgsl("fa_fresnel_eval")
    }
}

/// `M+coat` whose coat lobe has an angular reflectance per channel: kc, alpha_c,
/// fresnel_c1 … 8. The coat has no Fresnel factor of its own (F ≡ 1), so here the curve
/// is k_c e^{s(θd)}: a clear film's rise toward grazing, or a tinted one's colour shift.
#[derive(Debug, Clone, Copy)]
pub struct CoatFresnel;

const COAT_ENTRY: Entry = Entry::suffix(
    "coat",
    Some(Kind::Brdf),
    InCatalogue::No,
    "a second GGX lobe with a data-driven angular reflectance",
    |inner| Ok(Node::with(CoatFresnel, vec![inner])),
);

impl Kernel for CoatFresnel {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], inner: LaneChildren<R>, out: &mut [R]) {
        let alpha = R::splat(p.get(0, 1));
        blend_block_with(
            p,
            dirs,
            inner,
            out,
            #[inline(always)]
            |wi, wo| ggx_reflection(alpha, wi, wo, wi + wo),
            #[inline(always)]
            |i, wi, wo| coat_curve(p, i, 2, wi, wo),
        );
    }
}

impl Bsdf for CoatFresnel {
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((super::GgxPlace::Coat, super::Tabulated { ndf: false, fresnel: true }))
    }
    fn bounded_albedo(&self) -> bool {
        false // k_s F e^s has no bound of 1 (see the module doc)
    }
    fn entry(&self) -> &'static Entry {
        &COAT_ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        [super::coat::KC, super::coat::ALPHA_C]
            .into_iter()
            .chain(knots(&COAT_NAMES))
            .collect()
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &[""]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        fresnel_wgsl("coat_fresnel_eval")
    }
}

fn fresnel_wgsl(function: &str) -> WgslFn {
    WgslFn {
        sources: vec![MICROFACET_WGSL, KNOTS_WGSL, FRESNEL_WGSL],
        function: function.into(),
    }
}

/// Registry entry: a suffix of BRDF models with a GGX highlight.
pub const ENTRY: Entry = Entry::suffix(
    "fresnel",
    Some(Kind::Brdf),
    InCatalogue::No,
    "data-driven Fresnel curves of the GGX lobes (ggx, fa, +coat), per channel: F(theta_d; eta) exp(s_c(theta_d)), s_c on 9 knots in theta_d",
    build,
)
// s = 0 is the dielectric curve: M embeds in M+fresnel (diagnose's F test). Offered once
// no analytic effect is.
.adding(&[Adds::appended(Effect::HighlightFresnel)]);

/// The `+fresnel` node: passes its inner model's value through (the curve lives in the
/// highlight [`build`] put in place of the GGX one).
#[derive(Debug, Clone, Copy)]
pub struct FresnelCurve;

impl super::kernel::PassThrough for FresnelCurve {}

impl Bsdf for FresnelCurve {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        vec![]
    }
    fn child_roles(&self) -> &'static [&'static str] {
        &[""]
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        fresnel_wgsl("fresnel_eval")
    }
}

/// Replace every isotropic GGX lobe of `inner` (`ggx`, the lobe of `fa(B)`, the lobe of
/// `+coat`, wherever they sit) by its form with a data-driven Fresnel curve, each with
/// knots of its own, and wrap the result in the pass-through `+fresnel` node.
pub fn build(inner: Node) -> Result<Node, String> {
    super::registry::form_suffix(
        inner,
        ENTRY.name,
        Some(Kind::Brdf),
        |t| &mut t.fresnel,
        FresnelCurve,
        "an isotropic GGX lobe: ggx, fa(B) or +coat (before any +aniso)",
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::test_support::{assert_suffix_embeds, dir};
    use crate::bsdf::Model;

    /// At s = 0 the model is M, value for value (the factor is exp(0) = 1 exactly).
    #[test]
    fn at_zero_knots_the_model_is_the_analytic_one() {
        for spec in ["ggx", "fa(lambert)", "fa(eon)+coat", "rmg(ggx)", "lambert+coat"] {
            assert_suffix_embeds(spec, "fresnel", 1);
        }
    }

    /// The knots sit where the documentation says; the spline passes through them and
    /// is exact for quadratics (also across the linear continuation at the ends).
    #[test]
    fn knots_and_curve() {
        let doc = [0.0, 29.0, 41.4, 51.3, 60.0, 68.0, 75.5, 82.8, 90.0];
        for (k, (&a, &b)) in knot_degrees().iter().zip(&doc).enumerate() {
            assert!((a - b).abs() < 0.06, "knot {k}: {a}° (docs say {b}°)");
            let c = a.to_radians().cos();
            assert!((knot_coordinate(c) - k as f64).abs() < 1e-9);
        }
        let t: [f64; KNOTS] = std::array::from_fn(|k| ((k as f64) * 0.9).sin());
        for k in 0..KNOTS {
            assert!((log_factor(&t, k as f64) - t[k]).abs() < 1e-12);
        }
        let lin: [f64; KNOTS] = std::array::from_fn(|k| 0.3 * k as f64 - 1.0);
        for x in [0.0, 0.3, 2.5, 7.7, 8.0] {
            assert!((log_factor(&lin, x) - (0.3 * x - 1.0)).abs() < 1e-12, "x {x}");
        }
    }

    /// A conductor's curve is reached: with knots set to ln(F_c / F_η) at the knots, the
    /// lobe follows a curve that is not of the dielectric family (F rising from 0.9 at
    /// the normal), channel by channel.
    #[test]
    fn the_factor_reshapes_each_channel_of_the_highlight() {
        let m = Model::parse("ggx+fresnel", 2).unwrap();
        let mut p = m.defaults();
        let knot = |c: usize, k: usize| {
            let i = m.params.iter().find(|q| q.name == format!("fresnel{k}")).unwrap().index;
            i + c
        };
        for k in 1..KNOTS {
            p[knot(0, k)] = 0.5;
            p[knot(1, k)] = -0.5;
        }
        let g = Model::parse("ggx", 2).unwrap();
        let pg = g.defaults();
        // Away from the normal-incidence knot's influence the factor is e^±0.5.
        let (wi, wo) = (dir(1.2, 0.0), dir(1.2, std::f64::consts::PI));
        for (c, want) in [(0, 0.5f64.exp()), (1, (-0.5f64).exp())] {
            let ratio = m.eval(&p, c, wi, wo) / g.eval(&pg, c, wi, wo);
            assert!((ratio - want).abs() < 1e-9 * want, "channel {c}: {ratio} vs {want}");
        }
    }

    /// +fresnel takes the highlight of ggx and fa(B) wherever it sits, once, and refuses
    /// models without one.
    #[test]
    fn the_suffix_swaps_the_ggx_highlight() {
        for (spec, knot) in [
            ("ggx+fresnel", "fresnel1"),
            ("fa(eon)+fresnel", "lobe.fresnel8"),
            ("fa(lambert)+coat+fresnel", "lobe.fresnel3"),
            ("fa(lambert)+coat+fresnel", "fresnel_c8"),
            ("rmg(lambert)+coat+fresnel", "fresnel_c1"),
            ("rmg(ggx)+fresnel", "base.fresnel2"),
            ("fa(lambert)+ndf+fresnel", "lobe.fresnel3"),
            ("lambert+coat+ndf+fresnel", "fresnel_c8"),
        ] {
            let m = Model::parse(spec, 3).unwrap_or_else(|e| panic!("{spec}: {e}"));
            assert!(m.params.iter().any(|p| p.name == knot), "{spec}");
        }
        for spec in ["lambert+fresnel", "ggx+fresnel+fresnel", "ggx+aniso+fresnel", "ggx+ndf+fresnel+fresnel", "btdf(tr)+fresnel"] {
            assert!(Model::parse(spec, 1).is_err(), "{spec} parsed");
        }
    }
}
