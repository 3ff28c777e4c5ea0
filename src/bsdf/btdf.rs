//! Microfacet transmission (the benchmark paper §2.3.2, Eq. 1; Walter, Marschner, Li,
//! Torrance 2007) with four normal distributions, and the BTDF suffix combinators.
//! Twins: `shaders/btdf.wgsl` (tr, beckmann, gtr, suffixes) and `shaders/btdf_gg.wgsl` (gg).
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
//! Λ (as the paper), `gg` its own Λ from a table computed once in f64 ([`gg_lambda_table`]).
//!
//! Numerics (shared by both twins): the half vector is built as (i + o) + (η−1) o so that it
//! keeps its relative accuracy near η → 1 and o → −i; NDFs take cos²θm and sin²θm from the
//! components of m (no 1 − cos² cancellation at sharp peaks); G1/|μ| is evaluated in forms
//! without a division by μ, so grazing θt gives no 0·∞.

use super::{Ast, Bsdf, Entry, InCatalogue, Node, ParamDecl, Role, WgslFn};
use crate::data::Kind;
use crate::math::{fresnel_dielectric, gtr_norm, ln_gamma};
use glam::DVec3;
use std::f64::consts::PI;
use std::sync::OnceLock;

const BTDF_WGSL: (&str, &str) = ("btdf", include_str!("../../shaders/bsdf/btdf.wgsl"));
const BTDF_GG_WGSL: (&str, &str) = ("btdf_gg", include_str!("../../shaders/bsdf/btdf_gg.wgsl"));

/// Below this ‖i + η o‖² the configuration is the degenerate straight-through ray of an
/// index-matched interface: returned as 0 (also keeps f32 far from overflow).
pub const L2_MIN: f64 = 1e-20;
/// Below this cos²θm the exponential NDFs (Beckmann, GG) are returned as 0; they are
/// below e^-(10^6) there for every parameter in bounds.
pub const C2_MIN: f64 = 1e-30;

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

    /// f_t for this NDF with parameters `p` (in [`Ndf::params`] order).
    pub fn eval(self, p: &[f64], wi: DVec3, wo: DVec3) -> f64 {
        match self {
            Ndf::Tr => {
                let (alpha, eta) = (p[0], p[1]);
                walter_transmission(
                    wi,
                    wo,
                    eta,
                    |c2, s2| tr_d(c2, s2, alpha),
                    |v| tr_g1_over_mu(v, alpha),
                )
            }
            Ndf::Beckmann => {
                let (alpha, eta) = (p[0], p[1]);
                walter_transmission(
                    wi,
                    wo,
                    eta,
                    |c2, s2| beckmann_d(c2, s2, alpha),
                    |v| tr_g1_over_mu(v, alpha),
                )
            }
            Ndf::Gtr => {
                let (alpha, gamma, eta) = (p[0], p[1], p[2]);
                walter_transmission(
                    wi,
                    wo,
                    eta,
                    |c2, s2| gtr_d(c2, s2, alpha, gamma),
                    |v| tr_g1_over_mu(v, alpha),
                )
            }
            Ndf::Gg => {
                let (beta, shape, eta) = (p[0], p[1], p[2]);
                let g = GgShape::new(beta, shape);
                walter_transmission(wi, wo, eta, |c2, s2| g.d(c2, s2), |v| g.g1_over_mu(v))
            }
        }
    }
}

// ---------------------------------------------------------------------------------------
// Walter transmission core

/// The refraction microfacet of a valid transmission configuration.
#[derive(Clone, Copy, Debug)]
pub struct Refraction {
    /// Microfacet normal, upper hemisphere (m.z > 0), unit.
    pub m: DVec3,
    /// i·m > 0.
    pub im: f64,
    /// o·m < 0.
    pub om: f64,
    /// (η_i (i·m) + η_t (o·m))² = ‖i + η_t o‖².
    pub l2: f64,
}

/// Walter's refraction half vector and validity conditions; `None` when f_t = 0
/// (ωi not above, ωo not below, η ≤ 1, degenerate or back-facing microfacet).
pub fn refraction(wi: DVec3, wo: DVec3, eta: f64) -> Option<Refraction> {
    if !(wi.z > 0.0 && wo.z < 0.0 && eta > 1.0) {
        return None;
    }
    // v = i + η o, written so that it keeps its relative accuracy when it is small.
    let v = (wi + wo) + (eta - 1.0) * wo;
    let l2 = v.dot(v);
    if l2.is_nan() || l2 <= L2_MIN {
        return None;
    }
    let mut m = -v / l2.sqrt();
    if m.z < 0.0 {
        m = -m; // D lives on the upper hemisphere; the χ⁺ tests below reject this side for η > 1
    }
    let im = wi.dot(m);
    let om = wo.dot(m);
    if !(m.z > 0.0 && im > 0.0 && om < 0.0) {
        return None;
    }
    Some(Refraction { m, im, om, l2 })
}

/// Eq. 1 with a given NDF `d(cos²θm, sin²θm)` and Smith `g1_over_mu(v)` = G1(v)/|v.z|.
pub fn walter_transmission(
    wi: DVec3,
    wo: DVec3,
    eta: f64,
    d: impl Fn(f64, f64) -> f64,
    g1_over_mu: impl Fn(DVec3) -> f64,
) -> f64 {
    let Some(r) = refraction(wi, wo, eta) else {
        return 0.0;
    };
    let c2 = r.m.z * r.m.z;
    let s2 = r.m.x * r.m.x + r.m.y * r.m.y;
    transmit(&r, eta, d(c2, s2), g1_over_mu(wi), g1_over_mu(wo))
}

/// |i·m| |o·m| (1 − F(i·m)) D · (G1(i)/|μi|) (G1(o)/|μo|) / ‖i + η o‖².
pub fn transmit(r: &Refraction, eta: f64, d: f64, g1i_over_mu: f64, g1o_over_mu: f64) -> f64 {
    r.im * (-r.om) * (1.0 - fresnel_dielectric(r.im, eta)) * d * g1i_over_mu * g1o_over_mu / r.l2
}

// ---------------------------------------------------------------------------------------
// NDFs in terms of c2 = cos²θm and s2 = sin²θm (taken from the components of m)

/// Trowbridge–Reitz: α² / (π (α² cos² + sin²)²).
pub fn tr_d(c2: f64, s2: f64, alpha: f64) -> f64 {
    let a2 = alpha * alpha;
    let t = a2 * c2 + s2;
    a2 / (PI * t * t)
}

/// Beckmann: exp(−tan²/α²) / (π α² cos⁴).
pub fn beckmann_d(c2: f64, s2: f64, alpha: f64) -> f64 {
    if c2 < C2_MIN {
        return 0.0;
    }
    let a2 = alpha * alpha;
    (-(s2 / c2) / a2 - 2.0 * c2.ln()).exp() / (PI * a2)
}

/// Burley's GTR: c(α, γ) / (α² cos² + sin²)^γ, normalised by [`gtr_norm`].
pub fn gtr_d(c2: f64, s2: f64, alpha: f64, gamma: f64) -> f64 {
    let a2 = (alpha * alpha).max(1e-12);
    gtr_norm(a2, gamma) * (-gamma * (a2 * c2 + s2).ln()).exp()
}

/// Smith G1(v)/|v.z| for Trowbridge–Reitz: 2 / (μ + √(μ² + α² sin²θv)).
pub fn tr_g1_over_mu(v: DVec3, alpha: f64) -> f64 {
    let mu = v.z.abs();
    let s2 = v.x * v.x + v.y * v.y;
    2.0 / (mu + (mu * mu + alpha * alpha * s2).sqrt())
}

// ---------------------------------------------------------------------------------------
// Generalized Gaussian (Holzschuch & Pacanowski 2017)

/// Per-evaluation constants of a GG distribution.
#[derive(Clone, Copy, Debug)]
pub struct GgShape {
    pub beta: f64,
    pub p: f64,
    /// Characteristic slope of the β = 1 distribution, r_c = (1/p)^(1/(2p)); the table's
    /// abscissa is b = r_c · β tanθ.
    pub rc: f64,
    /// J0 = lim Λ/(β tanθ) = Γ(3/(2p)) / (π Γ(1/p)), the mean positive 1-D slope at β = 1.
    pub j0: f64,
    /// ln of the normalisation p / (π β² Γ(1/p)).
    pub ln_norm: f64,
}

impl GgShape {
    pub fn new(beta: f64, p: f64) -> GgShape {
        let lg = ln_gamma(1.0 / p);
        GgShape {
            beta,
            p,
            rc: (-p.ln() / (2.0 * p)).exp(),
            j0: (ln_gamma(1.5 / p) - lg).exp() / PI,
            ln_norm: p.ln() - lg - (PI * beta * beta).ln(),
        }
    }

    /// D = p / (π β² Γ(1/p)) · exp(−(tan²θ/β²)^p) / cos⁴θ.
    pub fn d(&self, c2: f64, s2: f64) -> f64 {
        if c2 < C2_MIN {
            return 0.0;
        }
        let z = s2 / c2 / (self.beta * self.beta);
        let e = if z > 0.0 {
            (self.p * z.ln()).clamp(-80.0, 80.0).exp()
        } else {
            0.0
        };
        (self.ln_norm - e - 2.0 * c2.ln()).exp()
    }

    /// Smith G1(v)/|v.z| = 1 / (μ (1 + Λ)) with Λ from the table:
    /// μ (1 + Λ) = μ + T̂ · J0 · (β sinθ + μ / r_c), T̂ at x = b/(1+b), b = r_c β tanθ.
    pub fn g1_over_mu(&self, v: DVec3) -> f64 {
        let mu = v.z.abs();
        let bs = self.beta * (v.x * v.x + v.y * v.y).sqrt();
        let w = bs * self.rc;
        let x = w / (mu + w);
        let t = gg_lambda_table().interpolate(self.p, x);
        1.0 / (mu + t * self.j0 * (bs + mu / self.rc))
    }

    /// Λ(θ) from the table (a = β tanθ).
    pub fn lambda(&self, a: f64) -> f64 {
        gg_lambda_table().lambda(self.p, a)
    }
}

/// Points in ln p of the GG Λ table (p from [`GG_P_LO`] to [`GG_P_HI`], uniform in ln p).
pub const GG_NP: usize = 33;
/// Points in x = b/(1+b) of the GG Λ table (x from 0 to 1 inclusive, uniform).
pub const GG_NA: usize = 129;
pub const GG_P_LO: f64 = 0.2;
pub const GG_P_HI: f64 = 5.0;

/// Tabulated Smith Λ of the generalized Gaussian NDF, computed once in f64.
///
/// Layout: `data[ip * na + ia]`, ip ∈ [0, np), ia ∈ [0, na).
/// - ip ↔ ln p = ln_p_lo + ip · (ln_p_hi − ln_p_lo)/(np − 1);
/// - ia ↔ x = ia/(na − 1), with x = b/(1 + b), b = r_c(p) · a, a = β tanθ,
///   r_c(p) = (1/p)^(1/(2p)) (the characteristic slope of the β = 1 distribution);
/// - value T̂ = Λ / (J0(p) · (a + 1/r_c(p))), J0(p) = Γ(3/(2p)) / (π Γ(1/p)); T̂ → 1 as
///   x → 1 (Λ ≈ J0 a − ½ for large a) and T̂ → 0 as x → 0.
///
/// Λ = T̂ · J0 · (a + 1/r_c), bilinear in (ln p, x) ([`LambdaTable::interpolate`], the same
/// arithmetic as `btdf_gg_table` in `shaders/btdf_gg.wgsl`, which reads an f32 copy bound
/// as `LUT`). Factoring out J0 and scaling a by r_c remove the p-dependence that bilinear
/// interpolation handles badly (J0 spans 0.2 … 25 over the p range).
#[derive(Clone, Debug)]
pub struct LambdaTable {
    pub np: usize,
    pub na: usize,
    pub ln_p_lo: f64,
    pub ln_p_hi: f64,
    pub data: Vec<f64>,
}

impl LambdaTable {
    fn compute() -> LambdaTable {
        let (ln_p_lo, ln_p_hi) = (GG_P_LO.ln(), GG_P_HI.ln());
        let mut data = Vec::with_capacity(GG_NP * GG_NA);
        for ip in 0..GG_NP {
            let p = (ln_p_lo + ip as f64 * (ln_p_hi - ln_p_lo) / (GG_NP - 1) as f64).exp();
            for ia in 0..GG_NA {
                data.push(gg_table_value(p, ia as f64 / (GG_NA - 1) as f64));
            }
        }
        LambdaTable {
            np: GG_NP,
            na: GG_NA,
            ln_p_lo,
            ln_p_hi,
            data,
        }
    }

    /// Bilinear T̂ at (p, x), clamped to the table's range.
    pub fn interpolate(&self, p: f64, x: f64) -> f64 {
        let fp = ((p.ln() - self.ln_p_lo) / (self.ln_p_hi - self.ln_p_lo)).clamp(0.0, 1.0)
            * (self.np - 1) as f64;
        let ip = (fp as usize).min(self.np - 2);
        let u = fp - ip as f64;
        let fa = x.clamp(0.0, 1.0) * (self.na - 1) as f64;
        let ia = (fa as usize).min(self.na - 2);
        let v = fa - ia as f64;
        let k = ip * self.na + ia;
        let d = &self.data;
        let t0 = d[k] + (d[k + 1] - d[k]) * v;
        let t1 = d[k + self.na] + (d[k + self.na + 1] - d[k + self.na]) * v;
        t0 + (t1 - t0) * u
    }

    /// Λ at shape p and a = β tanθ, from the table.
    pub fn lambda(&self, p: f64, a: f64) -> f64 {
        let g = GgShape::new(1.0, p);
        let b = g.rc * a;
        if !b.is_finite() {
            return f64::INFINITY;
        }
        self.interpolate(p, b / (1.0 + b)) * g.j0 * (a + 1.0 / g.rc)
    }

    /// The f32 copy the GPU reads (same layout).
    pub fn to_f32(&self) -> Vec<f32> {
        self.data.iter().map(|&v| v as f32).collect()
    }
}

/// The GG Λ table, computed on first use (~4k one-dimensional integrals).
pub fn gg_lambda_table() -> &'static LambdaTable {
    static TABLE: OnceLock<LambdaTable> = OnceLock::new();
    TABLE.get_or_init(LambdaTable::compute)
}

/// The exact table value T̂(p, x) by numerical integration.
pub fn gg_table_value(p: f64, x: f64) -> f64 {
    if x >= 1.0 {
        return 1.0;
    }
    let g = GgShape::new(1.0, p);
    let a = x / (1.0 - x) / g.rc;
    gg_lambda_exact(p, a) / (g.j0 * (a + 1.0 / g.rc))
}

/// Smith Λ of the generalized Gaussian at a = β tanθ by direct f64 integration.
///
/// With ν = 1/a and the β = 1 slope density P22(r) = p/(πΓ(1/p)) exp(−r^(2p)),
/// Λ = a ∫∫_{s > ν} (s − ν) P22 ds dt = a ∫_ν^∞ 2 (√(r² − ν²) − ν acos(ν/r)) P22(r) r dr
/// (Heitz 2014, Eq. 72 with the azimuth integrated analytically). Substituting
/// r = ν cosh u makes the integrand smooth at r = ν; 8-point Gauss–Legendre panels of
/// width min(¼, ½/p) in u up to r^(2p) = 60 give ~1e-13 relative accuracy.
pub fn gg_lambda_exact(p: f64, a: f64) -> f64 {
    if a.is_nan() || a <= 0.0 {
        return 0.0;
    }
    if !a.is_finite() {
        return f64::INFINITY;
    }
    a * gg_j(p, 1.0 / a)
}

/// J(ν) = ∫_ν^∞ (s − ν) P2(s) ds for the β = 1 GG slope distribution.
fn gg_j(p: f64, nu: f64) -> f64 {
    const X: [f64; 4] = [
        0.183_434_642_495_649_8,
        0.525_532_409_916_329,
        0.796_666_477_413_626_7,
        0.960_289_856_497_536_3,
    ];
    const W: [f64; 4] = [
        0.362_683_783_378_362,
        0.313_706_645_877_887_3,
        0.222_381_034_453_374_5,
        0.101_228_536_290_376_3,
    ];
    let c = (p.ln() - ln_gamma(1.0 / p)).exp() / PI;
    if nu <= 0.0 {
        return (ln_gamma(1.5 / p) - ln_gamma(1.0 / p)).exp() / PI;
    }
    let rmax = 60f64.powf(1.0 / (2.0 * p));
    if nu >= rmax {
        return 0.0;
    }
    let umax = (rmax / nu).acosh();
    let h = (0.5 / p).min(0.25);
    let n = ((umax / h).ceil() as usize).max(4);
    let h = umax / n as f64;
    let f = |u: f64| {
        let (sh, ch) = (u.sinh(), u.cosh());
        // sinh u − atan(sinh u) = √(r²−ν²)/ν − acos(ν/r), by its series where it cancels
        let diff = if sh < 0.1 {
            let s2 = sh * sh;
            sh * s2
                * (1.0 / 3.0 - s2 * (1.0 / 5.0 - s2 * (1.0 / 7.0 - s2 * (1.0 / 9.0 - s2 / 11.0))))
        } else {
            sh - sh.atan()
        };
        let r = nu * ch;
        2.0 * nu * diff * c * (-(2.0 * p * r.ln()).exp()).exp() * r * nu * sh
    };
    let mut sum = 0.0;
    for k in 0..n {
        let mid = (k as f64 + 0.5) * h;
        for j in 0..4 {
            let dx = 0.5 * h * X[j];
            sum += W[j] * (f(mid - dx) + f(mid + dx));
        }
    }
    sum * 0.5 * h
}

// ---------------------------------------------------------------------------------------
// Nodes

/// A `btdf(ndf)` term.
#[derive(Clone, Copy, Debug)]
pub struct Btdf {
    pub ndf: Ndf,
}

impl Bsdf for Btdf {
    fn entry(&self) -> &'static Entry {
        &ENTRY
    }
    fn params(&self) -> Vec<ParamDecl> {
        self.ndf.params()
    }
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, _children: &[f64]) -> f64 {
        self.ndf.eval(p, wi, wo)
    }
    /// f(i, o) needs ωi above and ωo below, so f(o, i) = 0: not reciprocal by swapping.
    fn reciprocal(&self) -> bool {
        false
    }
    fn wgsl(&self) -> WgslFn {
        let sources = match self.ndf {
            Ndf::Gg => vec![BTDF_WGSL, BTDF_GG_WGSL],
            _ => vec![BTDF_WGSL],
        };
        WgslFn {
            sources,
            function: format!("btdf_{}_eval", self.ndf.name()),
        }
    }
    fn lut(&self) -> Option<Vec<f32>> {
        match self.ndf {
            Ndf::Gg => Some(gg_lambda_table().to_f32()),
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
        match self {
            Suffix::Scale => inner * k,
            Suffix::Absorb => inner * (-k / wo.z.abs().max(1e-20)).exp(),
            Suffix::Diffuse => {
                if wi.z > 0.0 && wo.z < 0.0 {
                    inner + k / PI
                } else {
                    inner
                }
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
    fn eval(&self, p: &[f64], wi: DVec3, wo: DVec3, children: &[f64]) -> f64 {
        self.apply(p[0], wi, wo, children[0])
    }
    fn reciprocal(&self) -> bool {
        false
    }
    fn wgsl(&self) -> WgslFn {
        WgslFn {
            sources: vec![BTDF_WGSL],
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
.with_variants(&["tr", "beckmann", "gtr", "gg"]);
const BTDF: Option<Kind> = Some(Kind::Btdf);
pub const SCALE_ENTRY: Entry = Entry::suffix(
    "scale",
    BTDF,
    InCatalogue::Yes,
    "multiplies a BTDF by S",
    build_scale,
);
pub const ABSORB_ENTRY: Entry = Entry::suffix(
    "absorb",
    BTDF,
    InCatalogue::Yes,
    "Beer-Lambert attenuation exp(-tau/mu_t) (BTDF)",
    build_absorb,
);
pub const DIFFUSE_ENTRY: Entry = Entry::suffix(
    "diffuse",
    BTDF,
    InCatalogue::No,
    "adds a Lambertian transmission kd/pi (BTDF)",
    build_diffuse,
);

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
