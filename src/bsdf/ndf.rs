//! `M+ndf`: the highlight's microfacet distribution made data-driven. Each isotropic GGX
//! lobe of M (`ggx`, the highlight of `fa(B)`, the lobe of `+coat`) takes the distribution
//!
//!   D(m) = D_GGX(m; α) · exp(s(θm)) / N(α, s),   N = ∫ D_GGX e^s cos θm dω_m,
//!
//! where s is a Catmull–Rom spline through K = 32 knots in θm, dense near the normal, with
//! s = 0 at the normal and one free value `ndf1` … `ndf31` at each other knot: any
//! isotropic NDF is GGX times a positive factor, and the knots tabulate that factor's
//! logarithm (the tabulated NDF in the spirit of Dupuy et al. 2015's data-driven
//! microfacet distributions; Lavoué et al. 2021 found such lobes the closest fits of
//! measured materials). Normalised, D keeps ∫ D cos θm dω = 1 at every parameter value.
//! At s = 0 it is GGX: `M+ndf` embeds M (diagnose's F test), and a fit starts from M's α.
//!
//! The Smith masking comes from the same D (Heitz 2014, Eq. 17):
//! G1(ω) = μ / A(μ), A(μ) = ∫ (ω·m)⁺ D(m) dω_m the projected area of the microsurface,
//! and A(μ) = μ + C(μ) with C(μ) = ∫ (ω·m)⁻ D(m) dω_m (since ∫ m D dω_m = n), the part
//! facing away from ω, which is 0 until the lobe reaches the plane normal to ω. C is
//! computed once per parameter vector at 65 cosines μ_j = (j/64)² (dense toward grazing,
//! where C changes fastest) and read between them linearly in √μ (the [`NdfTable`]), by
//! quadrature over θm in each knot interval, cut into one piece per 4 units of change of s
//! (at most 4), with 8 Gauss–Legendre points per piece in the variable
//! t = α/√(α² + tan²θm), in which GGX's mass is uniform, so the peak is resolved at any
//! α) with the azimuth integral in closed form. At s = 0 the model is GGX within 3e-4
//! relative for θi, θo ≤ 86° at every α in bounds (tested): the table is part of the
//! model's definition, the same in both twins.
//!
//! The knots: x = 31 · (2 sin²(θm/2))^(1/3) is the knot coordinate, knot k at x = k
//! (θ_k = 0, 0.47, 1.33, 2.44, 3.76, 5.25, 6.9, 8.7, 10.6, 12.7, 14.9, 17.2, 19.6, 22.1,
//! 24.8, 27.5, 30.4, 33.4, 36.5, 39.7, 43.0, 46.4, 50.0, 53.7, 57.6, 61.6, 65.8, 70.2,
//! 74.7, 79.6, 84.6 and 90 degrees: spacing from 0.5° at the normal to 5°), s a
//! Catmull–Rom spline in x. The cube root spreads 32 knots as the fourth root spread 16
//! (whose first knot sat at 0.36°); a fourth root at 32 would put the first at 0.08°,
//! below any goniometer's angular resolution. 2 sin²(θ/2) = sin²θ / (1 + cos θ)
//! is taken from the components (never 1 − cos θ, which loses the near-normal angles).
//! K is one constant on each side ([`KNOTS`]; `NDF_KNOTS` in the twin, which reads the
//! knots in a loop; the parameter names are made from it). 16 knots were the first
//! choice: 32 cost a `+ndf` fit about 5× the time (docs/models.md, "Cost").
//!
//! Twin: `shaders/bsdf/ndf.wgsl`.

use super::coat::blend_block;
use super::effect::{Adds, Effect};
use super::fa::aggregate_block;
use super::ggx::{lobe_block, GgxLobe, ETA, KS};
use super::kernel::{Kernel, LaneChildren, LaneDir};
use super::microfacet::MICROFACET_WGSL;
use super::{Bsdf, Channels, Entry, InCatalogue, Node, ParamDecl, Role, WgslFn};
use crate::data::Kind;
use crate::math::lanes::{Real, V3};
use std::cell::RefCell;
use std::f64::consts::PI;
use std::rc::Rc;
use std::sync::LazyLock;

/// Knots of the deviation s, the first (the normal) fixed at 0.
pub const KNOTS: usize = 32;
/// Cosines of the masking table: μ_j = (j / (MU_POINTS − 1))².
pub const MU_POINTS: usize = 65;

pub(crate) const NDF_WGSL: (&str, &str) = ("ndf", include_str!("../../shaders/bsdf/ndf.wgsl"));

/// The free knots' names of each stem: `ndf1` … `ndf31` (`ggx+ndf`, `btdf(tr)+ndf`),
/// `lobe.ndf1` … (the highlight of `fa(B)+ndf`), `ndf_c1` … (a coat's lobe). Made once and
/// kept for the program's life: a declaration's name is `&'static str`.
pub(super) static NAMES: LazyLock<[&'static str; KNOTS - 1]> = LazyLock::new(|| knot_names("ndf"));
pub(super) static COAT_NAMES: LazyLock<[&'static str; KNOTS - 1]> =
    LazyLock::new(|| knot_names("ndf_c"));
pub(super) static LOBE_NAMES: LazyLock<[&'static str; KNOTS - 1]> =
    LazyLock::new(|| knot_names("lobe.ndf"));

fn knot_names(stem: &str) -> [&'static str; KNOTS - 1] {
    std::array::from_fn(|k| &*Box::leak(format!("{stem}{}", k + 1).into_boxed_str()))
}

/// One knot's log-factor: s = 0 is GGX there. ±15 spans e^30 ≈ 10^13 of shape change,
/// beyond what a measurement of a highlight over a diffuse floor can see.
const KNOT: ParamDecl = ParamDecl::shared(
    "ndf",
    -15.0,
    15.0,
    0.0,
    "ln(D / D_GGX) at this knot of the data-driven NDF (0: GGX; see the knots' angles in docs/models.md)",
)
.neutral_at(0.0)
.knot();

pub(super) fn knots(
    names: &'static LazyLock<[&'static str; KNOTS - 1]>,
) -> impl Iterator<Item = ParamDecl> {
    names.iter().map(|&n| KNOT.renamed(n))
}

/// The knot coordinate x ∈ [0, K − 1] of y = 2 sin²(θ/2) ∈ [0, 1]: knot k at x = k.
#[inline]
fn knot_coordinate(y: f64) -> f64 {
    (KNOTS - 1) as f64 * y.max(0.0).cbrt()
}

/// (cos θ, sin² θ) at knot coordinate x: y = (x/(K − 1))³, cos θ = 1 − y, sin² θ = y (2 − y)
/// (the inverse of [`knot_coordinate`]).
fn angle_at(x: f64) -> (f64, f64) {
    let r = x / (KNOTS - 1) as f64;
    let y = r * r * r;
    (1.0 - y, y * (2.0 - y))
}

/// (cos θ_k, sin² θ_k) of knot k.
pub fn knot_angle(k: usize) -> (f64, f64) {
    angle_at(k as f64)
}

/// The knots' angles in degrees (for reports and docs).
pub fn knot_degrees() -> [f64; KNOTS] {
    std::array::from_fn(|k| {
        let (c, s2) = knot_angle(k);
        s2.sqrt().atan2(c).to_degrees()
    })
}

/// s at knot coordinate x: the Catmull–Rom spline through the knots (C¹, exact for
/// quadratics, so a smooth log-factor is followed to O(h⁴) between knots where a linear
/// one would leave O(h²)), continued evenly through the normal (s_{−1} = s_1: D is
/// smooth there) and linearly past the last knot.
#[inline]
fn deviation(s: &[f64; KNOTS], x: f64) -> f64 {
    let x = x.clamp(0.0, (KNOTS - 1) as f64);
    let k = (x as usize).min(KNOTS - 2);
    let t = x - k as f64;
    let p0 = if k == 0 { s[1] } else { s[k - 1] };
    let (p1, p2) = (s[k], s[k + 1]);
    let p3 = if k + 2 < KNOTS { s[k + 2] } else { 2.0 * s[KNOTS - 1] - s[KNOTS - 2] };
    catmull_rom(p0, p1, p2, p3, t)
}

/// The Catmull–Rom segment between p1 (t = 0) and p2 (t = 1).
#[inline]
pub(super) fn catmull_rom(p0: f64, p1: f64, p2: f64, p3: f64, t: f64) -> f64 {
    let a = 2.0 * p0 - 5.0 * p1 + 4.0 * p2 - p3;
    let b = -p0 + 3.0 * (p1 - p2) + p3;
    0.5 * (2.0 * p1 + t * ((p2 - p0) + t * (a + t * b)))
}

/// The quadrature pieces of the knot interval between knots of values a and b: one per
/// 4 units of |b − a|, 1 to 4. 8 Gauss points integrate e^(r u) over a piece (u ∈ [0, 1])
/// to 2e-4 relative for r ≤ 4, the spline's overshoot aside; the cap keeps a candidate's
/// table within a GPU invocation's loop budget (at most 31 · 4 · 8 nodes).
#[inline]
fn pieces(a: f64, b: f64) -> usize {
    (((b - a).abs() / 4.0).ceil() as usize).clamp(1, 4)
}

/// The table's cosines a node at sin θm = `sm` faces away from: μ_j < sin θm, j below
/// this (the rest of the sum is 0; the count keeps the GPU's loops short for sharp lobes).
#[inline]
fn facing_count(sm: f64) -> usize {
    (((MU_POINTS - 1) as f64 * sm.sqrt()).ceil() as usize + 1).min(MU_POINTS)
}

/// 8-point Gauss–Legendre nodes (±) and weights on [−1, 1].
const GAUSS_X: [f64; 4] = [
    0.183_434_642_495_649_8,
    0.525_532_409_916_329,
    0.796_666_477_413_626_7,
    0.960_289_856_497_536_3,
];
const GAUSS_W: [f64; 4] = [
    0.362_683_783_378_362,
    0.313_706_645_877_887_3,
    0.222_381_034_453_374_5,
    0.101_228_536_290_376_3,
];

/// ∫ (−(ω·m))⁺ dφm over the azimuth of m, for ω at (cos θω = μ, sin θω = sw) and m at
/// (cos θm = cm, sin θm = sm): with a = μ cm, b = sw sm, ω·m = a + b cos φ, and where it
/// changes sign (b > a) the integral is 2 (b sin ψ − a (π − ψ)), cos ψ = −a/b.
#[inline]
fn facing_away(mu: f64, sw: f64, cm: f64, sm: f64) -> f64 {
    let (a, b) = (mu * cm, sw * sm);
    if b <= a {
        return 0.0;
    }
    let r = a / b;
    let psi = (-r).acos();
    2.0 * (b * (1.0 - r * r).max(0.0).sqrt() - a * (PI - psi))
}

/// What one parameter vector (α and the knots) fixes: the normalisation N and the
/// facing-away integral C(μ_j) at the table's cosines.
#[derive(Clone, Debug)]
pub struct NdfTable {
    pub s: [f64; KNOTS],
    pub alpha: f64,
    /// 1 / N.
    pub inv_norm: f64,
    /// C(μ_j), μ_j = (j / (MU_POINTS − 1))².
    pub c: [f64; MU_POINTS],
}

impl NdfTable {
    /// The table of (α, s) (`s[0]` = 0).
    pub fn new(alpha: f64, s: [f64; KNOTS]) -> NdfTable {
        let a2 = alpha * alpha;
        // t at knot coordinate x: t = α cos θ / √(α² cos² θ + sin² θ) (1 at the normal, 0
        // at 90°).
        let t_of = |x: f64| {
            let (c, s2) = angle_at(x);
            alpha * c / (a2 * c * c + s2).sqrt()
        };
        let mut norm = 0.0;
        let mut c = [0.0; MU_POINTS];
        let mu = |j: usize| {
            let r = j as f64 / (MU_POINTS - 1) as f64;
            r * r
        };
        let sw: [f64; MU_POINTS] = std::array::from_fn(|j| (1.0 - mu(j) * mu(j)).max(0.0).sqrt());
        for k in 0..KNOTS - 1 {
            // Pieces of the interval, equal in x, so that s changes by about 4 or less
            // within each ([`pieces`]).
            let pieces = pieces(s[k], s[k + 1]);
            for piece in 0..pieces {
                let x0 = k as f64 + piece as f64 / pieces as f64;
                let x1 = k as f64 + (piece + 1) as f64 / pieces as f64;
                let (hi, lo) = (t_of(x0), t_of(x1));
                let (mid, half) = (0.5 * (hi + lo), 0.5 * (hi - lo));
                for g in 0..8 {
                    let (xi, w) = (GAUSS_X[g / 2], GAUSS_W[g / 2]);
                    let t = if g % 2 == 0 { mid - half * xi } else { mid + half * xi };
                    let wt = half * w;
                    // The node's angle: cos θ = t/√q, sin² θ = α² (1 − t²)/q.
                    let q = t * t + a2 * (1.0 - t * t);
                    let rq = q.sqrt();
                    let (cm, sm2) = (t / rq, a2 * (1.0 - t * t) / q);
                    let sm = sm2.sqrt();
                    let x = knot_coordinate(sm2 / (1.0 + cm)).clamp(x0, x1);
                    let e = deviation(&s, x).exp();
                    // GGX's D cos θ sin θ dθ dφ integrates to dt² = 2t dt over the azimuth.
                    norm += e * 2.0 * t * wt;
                    // D_GGX sin θ dθ = √q dt / π (per radian of azimuth, times 2π / 2π).
                    let weight = e * rq / PI * wt;
                    for j in 0..facing_count(sm) {
                        c[j] += weight * facing_away(mu(j), sw[j], cm, sm);
                    }
                }
            }
        }
        let inv_norm = 1.0 / norm;
        for v in &mut c {
            *v *= inv_norm;
        }
        NdfTable {
            s,
            alpha,
            inv_norm,
            c,
        }
    }

    /// C(μ), linear in √μ between the table's cosines (μ clamped to [0, 1]).
    #[inline]
    pub fn facing_away(&self, mu: f64) -> f64 {
        let x = mu.clamp(0.0, 1.0).sqrt() * (MU_POINTS - 1) as f64;
        let j = (x as usize).min(MU_POINTS - 2);
        let f = x - j as f64;
        self.c[j] + f * (self.c[j + 1] - self.c[j])
    }

    /// D at the unit normal m.
    pub fn d(&self, m: glam::DVec3) -> f64 {
        let v = V3::<f64>::from(m);
        self.d_in(v)
    }

    /// D at any positive multiple m of a unit normal (0 for m.z ≤ 0).
    #[inline(always)]
    pub fn d_in<R: Real>(&self, m: V3<R>) -> R {
        let a2 = R::splat(self.alpha * self.alpha);
        let (c2, s2) = (m.z * m.z, m.x * m.x + m.y * m.y);
        let len2 = c2 + s2;
        let len = len2.sqrt();
        let t = a2 * c2 + s2;
        let ggx = a2 * (len2 * len2) / (R::splat(PI) * t * t);
        let e = self.factor(s2 / (len * (len + m.z)));
        R::select(m.z.le(R::zero()), R::zero(), ggx * e)
    }

    /// exp(s(θ)) / N at y = 2 sin²(θ/2), per lane.
    #[inline(always)]
    fn factor<R: Real>(&self, y: R) -> R {
        let s = R::from_fn(|l| deviation(&self.s, knot_coordinate(y.lane(l))));
        s.exp() * R::splat(self.inv_norm)
    }

    /// The reflection kernel D(h) G1(ωi) G1(ωo) / (4 μi μo) at m = any positive multiple
    /// of the half vector h, with G1 = μ/(μ + C(μ)) and the χ⁺ side tests of
    /// [`super::microfacet::Masking::g1`]; ωi and ωo above the surface.
    #[inline(always)]
    pub fn reflection<R: Real>(&self, wi: V3<R>, wo: V3<R>, m: V3<R>) -> R {
        let zero = R::zero();
        let masked = m.z.le(zero) | (wi.dot(m) * wi.z).le(zero) | (wo.dot(m) * wo.z).le(zero);
        let ci = R::from_fn(|l| self.facing_away(wi.z.lane(l)));
        let co = R::from_fn(|l| self.facing_away(wo.z.lane(l)));
        let value = self.d_in(m) / (R::splat(4.0) * (wi.z + ci) * (wo.z + co));
        R::select(masked, zero, value)
    }
}

impl NdfTable {
    /// Smith's G1(ω)/|μ| of the table's D: 1/(|μ| + C(|μ|)), μ = cos θ (a direction below
    /// the surface masked as seen from that side). The χ⁺ side tests are the caller's.
    #[inline(always)]
    pub fn g1_over_mu<R: Real>(&self, w: V3<R>) -> R {
        let mu = w.z.abs();
        let c = R::from_fn(|l| self.facing_away(mu.lane(l)));
        R::splat(1.0) / (mu + c)
    }
}

thread_local! {
    /// The last tables built on this thread: a fit evaluates one parameter vector over
    /// many blocks of directions, so each vector's table is built once per thread.
    static TABLES: RefCell<Vec<Rc<NdfTable>>> = const { RefCell::new(Vec::new()) };
}

/// The table of α and the free knots `free` (`ndf1` …), from the thread's cache when
/// the same values were asked for last.
pub fn table(alpha: f64, free: impl Fn(usize) -> f64) -> Rc<NdfTable> {
    let s: [f64; KNOTS] = std::array::from_fn(|k| if k == 0 { 0.0 } else { free(k - 1) });
    const KEEP: usize = 8;
    TABLES.with(|cache| {
        let mut cache = cache.borrow_mut();
        let same = |t: &NdfTable| {
            t.alpha.to_bits() == alpha.to_bits()
                && t.s.iter().zip(&s).all(|(a, b)| a.to_bits() == b.to_bits())
        };
        if let Some(i) = cache.iter().position(|t| same(t)) {
            let t = cache.remove(i);
            cache.push(t.clone());
            return t;
        }
        let t = Rc::new(NdfTable::new(alpha, s));
        if cache.len() == KEEP {
            cache.remove(0);
        }
        cache.push(t.clone());
        t
    })
}

// ---------------------------------------------------------------------------------------
// Nodes: the data-driven form of each GGX highlight. Their entries are not registered
// (the spec names them as `M+ndf`); each carries its GGX model's name, kind and role.

/// `ggx` with the data-driven NDF: k_s, α, η, ndf1 … ndf31.
#[derive(Debug, Clone, Copy)]
pub struct GgxNdf;

const GGX_ENTRY: Entry = Entry::leaf(
    "ggx",
    Kind::Brdf,
    Role::SpecularLobe,
    "GGX microfacet reflection with a data-driven NDF",
    || Node::leaf(GgxNdf),
);

impl Kernel for GgxNdf {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], _: LaneChildren<R>, out: &mut [R]) {
        let eta = p.get(0, 2);
        let tab = table(p.get(0, 1), |k| p.get(0, 3 + k));
        lobe_block(
            p,
            dirs,
            out,
            #[inline(always)]
            |wi, wo| GgxLobe::at_with(eta, wi, wo, |m| tab.reflection(wi, wo, m)),
        );
    }
}

impl Bsdf for GgxNdf {
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((super::GgxPlace::Ggx, super::Tabulated { ndf: true, fresnel: false }))
    }
    fn entry(&self) -> &'static Entry {
        &GGX_ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        [KS, super::ggx::ALPHA, ETA].into_iter().chain(knots(&NAMES)).collect()
    }
    super::kernel::kernel_methods!();
    fn wgsl(&self) -> WgslFn {
        ndf_wgsl("ggx_ndf_eval")
    }
    fn wgsl_prepare(&self) -> Option<&'static str> {
        Some("ggx_ndf_prepare")
    }
}

/// `fa(B)` with a data-driven highlight: lobe.α, lobe.η, lobe.k_s, lobe.ndf1 … 31.
#[derive(Debug, Clone, Copy)]
pub struct FaNdf;

const FA_ENTRY: Entry = Entry::layer(
    "fa",
    Kind::Brdf,
    &[Role::DiffuseBase],
    "Fresnel aggregate with a data-driven NDF",
    |base| Node::with(FaNdf, vec![base]),
);

impl Kernel for FaNdf {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], base: LaneChildren<R>, out: &mut [R]) {
        let eta = p.get(0, 1);
        let tab = table(p.get(0, 0), |k| p.get(0, 3 + k));
        aggregate_block(
            p,
            dirs,
            base,
            out,
            #[inline(always)]
            |wi, wo| GgxLobe::at_with(eta, wi, wo, |m| tab.reflection(wi, wo, m)),
        );
    }
}

impl Bsdf for FaNdf {
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((super::GgxPlace::Aggregate, super::Tabulated { ndf: true, fresnel: false }))
    }
    fn entry(&self) -> &'static Entry {
        &FA_ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        [
            super::ggx::ALPHA.renamed("lobe.alpha"),
            ETA.renamed("lobe.eta"),
            KS.renamed("lobe.ks"),
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
        ndf_wgsl("fa_ndf_eval")
    }
    fn wgsl_prepare(&self) -> Option<&'static str> {
        Some("fa_ndf_prepare")
    }
}

/// `M+coat` with a data-driven coat lobe: k_c, α_c, ndf_c1 … ndf_c31.
#[derive(Debug, Clone, Copy)]
pub struct CoatNdf;

const COAT_ENTRY: Entry = Entry::suffix(
    "coat",
    Some(Kind::Brdf),
    InCatalogue::No,
    "a second GGX lobe with a data-driven NDF",
    |inner| Ok(Node::with(CoatNdf, vec![inner])),
);

impl Kernel for CoatNdf {
    #[inline(always)]
    fn block<R: Real>(&self, p: Channels, dirs: &[LaneDir<R>], inner: LaneChildren<R>, out: &mut [R]) {
        let tab = table(p.get(0, 1), |k| p.get(0, 2 + k));
        blend_block(
            p,
            dirs,
            inner,
            out,
            #[inline(always)]
            |wi, wo| tab.reflection(wi, wo, wi + wo),
        );
    }
}

impl Bsdf for CoatNdf {
    fn ggx_lobe(&self) -> Option<(super::GgxPlace, super::Tabulated)> {
        Some((super::GgxPlace::Coat, super::Tabulated { ndf: true, fresnel: false }))
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
        ndf_wgsl("coat_ndf_eval")
    }
    fn wgsl_prepare(&self) -> Option<&'static str> {
        Some("coat_ndf_prepare")
    }
}

fn ndf_wgsl(function: &str) -> WgslFn {
    WgslFn {
        sources: vec![MICROFACET_WGSL, NDF_WGSL],
        function: function.into(),
    }
}

/// Registry entry: a suffix of BRDF models with a GGX highlight.
pub const ENTRY: Entry = Entry::suffix(
    "ndf",
    None,
    InCatalogue::No,
    "data-driven NDFs of the GGX lobes (ggx, fa, +coat, btdf(tr)): D = D_GGX(alpha) exp(s(theta_m)) / N, s on 32 knots, Smith masking from the same D",
    build,
)
// s = 0 is GGX: M embeds in M+ndf (diagnose's F test). Offered once no analytic effect is.
.adding(&[Adds::appended(Effect::HighlightShape)]);

/// The `+ndf` node: passes its inner model's value through (the distribution lives in
/// the highlight [`build`] put in place of the GGX one).
#[derive(Debug, Clone, Copy)]
pub struct Ndf {
    kind: Kind,
}

impl super::kernel::PassThrough for Ndf {}

impl Bsdf for Ndf {
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
    fn wgsl(&self) -> WgslFn {
        ndf_wgsl("ndf_eval")
    }
}

/// Replace every isotropic GGX lobe of `inner` (`ggx`, the highlight of `fa(B)`, the lobe
/// of `+coat`, the lobe of `btdf(tr)`, wherever they sit) by its data-driven form, each
/// with knots of its own, and wrap the result in the pass-through `+ndf` node.
pub fn build(inner: Node) -> Result<Node, String> {
    let kind = inner.bsdf.kind();
    super::registry::form_suffix(
        inner,
        ENTRY.name,
        None,
        |t| &mut t.ndf,
        Ndf { kind },
        "an isotropic GGX lobe: ggx, fa(B), +coat or btdf(tr) (before any +aniso)",
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Model;
    use glam::DVec3;
    use rand::{Rng, SeedableRng};

    fn dir(theta: f64, phi: f64) -> DVec3 {
        DVec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
    }

    /// The twin's sizes are its own constants (it has no other source of them): they must
    /// be this file's, or the twin reads other parameters as knots.
    #[test]
    fn the_twin_declares_the_same_knot_and_table_sizes() {
        let declared = |name: &str| -> usize {
            let line = NDF_WGSL
                .1
                .lines()
                .find(|l| l.starts_with(&format!("const {name}: u32 = ")))
                .unwrap_or_else(|| panic!("{name} is not declared in the twin"));
            let value = line.rsplit(' ').next().unwrap().trim_end_matches("u;");
            value.parse().unwrap()
        };
        assert_eq!(declared("NDF_KNOTS"), KNOTS);
        assert_eq!(declared("NDF_MU_POINTS"), MU_POINTS);
    }

    /// A random deviation: smooth-ish knots in [−3, 3] (a walk), s[0] = 0.
    fn random_knots(rng: &mut impl Rng) -> [f64; KNOTS] {
        let mut s = [0.0; KNOTS];
        for k in 1..KNOTS {
            s[k] = (s[k - 1] + rng.random_range(-1.0..1.0)).clamp(-3.0, 3.0);
        }
        s
    }

    /// At s = 0 the model is GGX: within 3e-4 relative at every direction pair with
    /// θi, θo ≤ 86°, for α from the lower bound to 1 (the masking table's quadrature and
    /// its interpolation in √μ are the only differences).
    #[test]
    fn at_zero_deviation_the_lobe_is_ggx() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        for spec in ["ggx", "fa(lambert)", "lambert+coat"] {
            let ggx = Model::parse(spec, 1).unwrap();
            let ndf = Model::parse(&format!("{spec}+ndf"), 1).unwrap();
            for alpha in [1e-3, 0.01, 0.1, 0.5, 1.0] {
                let mut pg = ggx.defaults();
                let a = ggx
                    .params
                    .iter()
                    .position(|p| p.name.ends_with("alpha") || p.name == "alpha_c")
                    .unwrap();
                pg[a] = alpha;
                // The same values by name; the knots at their neutral 0.
                let pn: Vec<f64> = ndf
                    .params
                    .iter()
                    .map(|p| match ggx.params.iter().find(|q| q.name == p.name) {
                        Some(q) => pg[q.index],
                        None => 0.0,
                    })
                    .collect();
                for _ in 0..5000 {
                    let wi = dir(rng.random_range(0.0..86f64.to_radians()), 0.0);
                    let wo = dir(rng.random_range(0.0..86f64.to_radians()), rng.random_range(0.0..6.3));
                    let (a, b) = (ggx.eval(&pg, 0, wi, wo), ndf.eval(&pn, 0, wi, wo));
                    assert!(a > 0.0 && b.is_finite(), "{spec} α {alpha}: {a} {b}");
                    assert!((a - b).abs() <= 3e-4 * a, "{spec} α {alpha} at {wi} {wo}: GGX {a}, +ndf {b}");
                }
            }
        }
    }

    /// ∫ D cos θm dω = 1 and G1 = μ / ∫ (ω·m)⁺ D dω_m for random deviations, both
    /// integrals by brute force here (midpoints in θm and φm, written in the test): the
    /// Smith masking is that of the tabulated D itself, not GGX's.
    #[test]
    fn the_distribution_is_normalised_and_masks_by_its_own_projected_area() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        for alpha in [0.08, 0.3, 0.9] {
            let table = NdfTable::new(alpha, random_knots(&mut rng));
            // θm: 6000 midpoints (resolves α = 0.08's peak); φm: 720.
            let (nt, np) = (6000, 720);
            let (dt, dp) = (std::f64::consts::FRAC_PI_2 / nt as f64, 2.0 * PI / np as f64);
            let mut norm = 0.0;
            let mut ring = Vec::with_capacity(nt);
            for i in 0..nt {
                let th = (i as f64 + 0.5) * dt;
                let d = table.d(dir(th, 0.0));
                norm += d * th.cos() * th.sin() * dt * 2.0 * PI;
                ring.push((th, d));
            }
            assert!((norm - 1.0).abs() < 1e-3, "α {alpha}: ∫ D cos dω = {norm}");
            let brute_g1 = |w: DVec3| {
                let mut area = 0.0;
                for &(th, d) in &ring {
                    let mut around = 0.0;
                    for j in 0..np {
                        around += dir(th, (j as f64 + 0.5) * dp).dot(w).max(0.0);
                    }
                    area += d * th.sin() * dt * around * dp;
                }
                w.z / area
            };
            for theta_deg in [30.0, 60.0, 75.0, 83.0, 88.0] {
                let w = dir(f64::to_radians(theta_deg), 0.0);
                let brute = brute_g1(w);
                let table_g1 = w.z / (w.z + table.facing_away(w.z));
                assert!(
                    (brute - table_g1).abs() < 2e-3 * brute,
                    "α {alpha} θ {theta_deg}: G1 {table_g1} (table), {brute} (brute force)"
                );
            }
            // The lobe's kernel uses that masking: D G1 G1 / (4 μi μo).
            let (wi, wo) = (dir(70f64.to_radians(), 0.0), dir(80f64.to_radians(), 2.0));
            let h = (wi + wo).normalize();
            let want = table.d(h) * brute_g1(wi) * brute_g1(wo) / (4.0 * wi.z * wo.z);
            let got = table.reflection::<f64>(wi.into(), wo.into(), (wi + wo).into());
            assert!((got - want).abs() < 4e-3 * want, "α {alpha}: kernel {got}, brute force {want}");
        }
    }

    /// The knots sit where the documentation says, and s is linear between them.
    #[test]
    fn knots_and_deviation() {
        let deg = knot_degrees();
        let doc = [0.0, 0.469, 1.33, 2.44, 3.76, 5.25, 6.9, 8.7, 10.6, 12.7, 14.9, 17.2, 19.6, 22.1, 24.8, 27.5,
            30.4, 33.4, 36.5, 39.7, 43.0, 46.4, 50.0, 53.7, 57.6, 61.6, 65.8, 70.2, 74.7, 79.6, 84.6, 90.0];
        assert_eq!(doc.len(), KNOTS);
        for (k, (&a, &b)) in deg.iter().zip(&doc).enumerate() {
            assert!((a - b).abs() < 0.06, "knot {k}: {a}° (docs say {b}°)");
            let (c, s2) = knot_angle(k);
            assert!((knot_coordinate(s2 / (1.0 + c)) - k as f64).abs() < 1e-9);
        }
        // The spline reproduces a quadratic between interior knots, passes through every
        // knot, and is even about the normal.
        let s: [f64; KNOTS] = std::array::from_fn(|k| (k * k) as f64);
        assert_eq!(deviation(&s, 3.0), 9.0);
        assert!((deviation(&s, 3.25) - 3.25 * 3.25).abs() < 1e-12);
        assert_eq!(deviation(&s, 40.0), 961.0);
        let t: [f64; KNOTS] = std::array::from_fn(|k| ((k as f64) * 0.7).sin());
        for k in 0..KNOTS {
            assert!((deviation(&t, k as f64) - t[k]).abs() < 1e-12);
        }
        let slope = (deviation(&t, 1e-6) - deviation(&t, 0.0)) / 1e-6;
        assert!(slope.abs() < 1e-5, "ds/dx at the normal: {slope}");
    }

    /// +ndf takes the highlight of ggx and fa(B) and the lobe of btdf(tr) wherever it
    /// sits, once, and refuses models without one (the other BTDF distributions are not
    /// GGX at zero deviation).
    #[test]
    fn the_suffix_swaps_the_ggx_highlight() {
        for (spec, knots) in [("ggx+ndf", "ndf1"), ("fa(eon)+ndf", "lobe.ndf1"), ("fa(lambert)+coat+ndf", "lobe.ndf15"),
            ("fa(lambert)+coat+ndf", "ndf_c1"),
            ("rmg(lambert)+coat+ndf", "ndf_c15"), ("rmg(ggx)+ndf", "base.ndf3"),
            ("btdf(tr)+ndf", "ndf15"), ("btdf(tr)+diffuse+scale+ndf", "ndf1")] {
            let m = Model::parse(spec, 3).unwrap_or_else(|e| panic!("{spec}: {e}"));
            assert!(m.params.iter().any(|p| p.name == knots), "{spec}: {:?}", m.params.iter().map(|p| &p.name).collect::<Vec<_>>());
        }
        assert_eq!(Model::parse("btdf(tr)+ndf", 1).unwrap().kind, Kind::Btdf);
        for spec in ["lambert+ndf", "ggx+ndf+ndf", "ggx+aniso+ndf", "btdf(beckmann)+ndf", "btdf(gg)+ndf",
            "btdf(tr)+aniso+ndf", "btdf(tr)+fresnel", "btdf(tr)+ndf+fresnel"] {
            assert!(Model::parse(spec, 1).is_err(), "{spec} parsed");
        }
    }

    /// At zero deviation `btdf(tr)+ndf` is `btdf(tr)` within the table's quadrature error
    /// (3e-4 relative, as the reflection lobe), so `btdf(tr)` embeds in it.
    #[test]
    fn the_transmission_lobe_at_zero_deviation_is_tr() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut compared = 0;
        for alpha in [0.02, 0.1, 0.3, 0.7] {
            let tr = Model::parse("btdf(tr)", 1).unwrap();
            let ndf = Model::parse("btdf(tr)+ndf", 1).unwrap();
            let eta = rng.random_range(1.1..2.0);
            let mut p = vec![0.0; ndf.dim];
            p[0] = alpha;
            p[1] = eta;
            for _ in 0..400 {
                let wi = dir(rng.random_range(0.0..86f64).to_radians(), 0.0);
                let o = dir(rng.random_range(0.0..86f64).to_radians(), rng.random_range(0.0..PI));
                let wo = DVec3::new(o.x, o.y, -o.z);
                let (a, b) = (tr.eval(&[alpha, eta], 0, wi, wo), ndf.eval(&p, 0, wi, wo));
                assert!(!b.is_nan());
                if a > 1e-12 {
                    assert!((b / a - 1.0).abs() < 3e-4, "α {alpha}: {b} against {a}");
                    compared += 1;
                } else {
                    assert!(b <= 1e-9, "α {alpha}: {b} against {a}");
                }
            }
        }
        assert!(compared > 400, "{compared} values compared");
    }
}
