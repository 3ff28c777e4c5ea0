//! Shared math of the micrograin layer (`dmg(B)`, `rmg(B)`): S. Lucas, M. Ribardière,
//! R. Pacanowski, P. Barla, "A Micrograin BSDF Model for the Rendering of Porous Layers",
//! ACM TOG 42(6), SIGGRAPH Asia 2023 (HAL hal-04220006).
//! Twin: `shaders/bsdf/micrograin.wgsl` (with `microfacet.wgsl`).
//!
//! Equation numbers are those of the paper as cited in the reference code we followed:
//! the authors' Shadertoy (shadertoy.com/view/cly3Dt) through its line-for-line C++ port
//! `src/bsdfs/micrograin.cpp` in shyHelios/mitsuba3 (`D_our` "Eq. 17", `tau_theta` "Eq. 21",
//! `tau_theta_plus` "Eq. 22", `visibility_weight` "Eq. 23", `G1_our` "supplemental").
//! The formulas were rewritten and checked numerically (tests below), not copied.
//!
//! Grains are half-ellipsoids (horizontal radius r, height β·r) placed as a Boolean
//! (Poisson) model on the base; τ0 is the fraction of the base covered by their footprints
//! and Λ0 = −ln(1 − τ0) the mean number of footprints over a point.
//!
//! * Visibility weight (Eqs. 21–23): γβ(θ) = √(β² sin²θ + cos²θ),
//!   τ(θ) = 1 − (1−τ0)^{γβ/μ} (Eq. 21), τ⁺(θ) = 1 − (1−τ0)^{(μ+γβ)/(2μ)} (Eq. 22),
//!   w = 1 − (1−τ⁺i)(1−τ⁺o)/(1−τ0) (Eq. 23) = 1 − (1−τ0)^E, E = ½(γβ(θi)/μi + γβ(θo)/μo).
//!   w ∈ [τ0, 1], symmetric in (ωi, ωo), w = τ0 at normal incidence and exitance, → 1 at grazing.
//! * NDF (Eq. 17): D(m) = (Λ0/τ0) (1−τ0)^u β² / (π d²), d = β² cos²θm + sin²θm,
//!   u = sin²θm / d: a GGX(α = β) lobe ([`super::microfacet::Ggx`]) reweighted by
//!   (Λ0/τ0) e^{−Λ0 u}; ∫ D cos θm dω = 1.
//! * Smith Λ of that NDF ("Eq. in supplemental"): the authors' shader evaluates a 7-term
//!   series Λ = (F0 + … + F6)/(e^{Λ0} − 1). Here we sum the same series to N = 32 terms in a
//!   recurrence form (σ = μ/γβ, c = β sinθ/γβ):
//!   Λ = Σ_k w_k K_k [c^{2k+2}/((2k+1) σ) − J_k], w_k = Λ0^{k+1}/(k! (e^{Λ0}−1)),
//!   K_k = Γ(k+3/2)/(√π Γ(k+2)), J_k = ∫_{asin σ}^{π/2} cos^{2k+1}φ dφ.
//!   Term k equals the shader's F_k/(e^{Λ0}−1) for k ≤ 6. With 7 terms the series carries
//!   only ≈61 % of the NDF's mass at τ0 = 0.999 (Λ0 = 6.9) and G1 is off by up to 0.08; with
//!   32 terms the truncation error on G1 is < 1e-13 for τ0 ≤ 0.999 (tested below). The
//!   two agree to < 1e-3 in G1 for τ0 ≲ 0.95. G2 = G1(μi)·G1(μo) (separable, as the
//!   reference code).
//!
//! The loop stops early when the remaining tail is provably negligible (< 1e-17 of the sum
//! in f64, < 1e-9 in f32).
//!
//! Numerics (the same clamps in f64 and f32): τ0 ∈ [1e-6, 0.9999], β ∈ [1e-4, 1], μ ≥ 1e-6
//! inside w; G1/μ is computed as 1/(γβ (σ + Λσ)), finite at μ → 0, so nothing divides by
//! zero at grazing.

use super::kernel::{LaneDir, Memo, SlotMemo};
use super::microfacet::{ggx_d, MICROFACET_WGSL};
use super::{ParamDecl, Role, WgslFn};
use crate::math::lanes::{Real, V3};
use crate::math::{fresnel_dielectric_in, fresnel_transmittance_in};
use glam::DVec3;
use std::f64::consts::FRAC_1_PI;

/// Terms of the Smith Λ series (the authors' shader uses 7; see the module doc).
pub const LAMBDA_TERMS: usize = 32;
/// The Λ series stops early once its tail is below this fraction of the sum (the f32 twin
/// uses 1e-9); most evaluations (τ0 ≲ 0.9) need far fewer than 32 terms.
pub const LAMBDA_TAIL_EPS: f64 = 1e-17;
/// Smallest cosine used where 1/μ appears in w.
pub const MU_MIN: f64 = 1e-6;
/// Internal parameter clamps (identical in `shaders/bsdf/micrograin.wgsl`); the declared
/// bounds lie inside them.
pub const TAU_MIN: f64 = 1e-6;
pub const TAU_MAX: f64 = 0.9999;
pub const BETA_MIN: f64 = 1e-4;

/// τ0 on a log scale: near τ0 → 0 the layer acts through w ≈ τ0·E, so relative changes of
/// τ0 are what data resolve there (1e-3, 1e-2, 1e-1 are distinct layers, each ~10× the
/// grazing effect of the previous); a linear box would give [1e-3, 0.1] only 10 % of the
/// unit box. On the log box dw/du ∝ τ0 (1−τ0)^{E}·E stays within a factor ~3 of its peak
/// over τ0 ∈ [0.05, 0.95], i.e. the sensitivity is spread evenly over the useful range.
/// The bases of a micrograin layer: any leaf BRDF (a diffuse base or a lone lobe).
pub const MICROGRAIN_BASES: &[Role] = &[Role::DiffuseBase, Role::SpecularLobe];

/// The WGSL of a micrograin layer `name`: the microfacet and shared micrograin functions,
/// then its own file.
pub fn layer_wgsl(name: &'static str, source: &'static str) -> WgslFn {
    WgslFn {
        sources: vec![
            MICROFACET_WGSL,
            (
                "micrograin",
                include_str!("../../shaders/bsdf/micrograin.wgsl"),
            ),
            (name, source),
        ],
        function: format!("{name}_eval"),
    }
}

pub const TAU0: ParamDecl = ParamDecl::shared("tau0", 1e-3, 0.999, 0.5, "filling factor")
    .logit()
    // The thinnest layer: w ≈ τ0 at every angle.
    .neutral_at_lo();
/// Grain albedo.
pub const RHO_G: ParamDecl = ParamDecl::rgb("rho_g", 0.0, 1.0, 0.5, "grain albedo").neutral_at(0.0);
/// Grain index of refraction (rmg).
pub const ETA_G: ParamDecl = ParamDecl::shared("eta_g", 1.0, 5.0, 1.5, "grain refractive index")
    // η = 1: Lambertian-like grains, no grain specular.
    .neutral_at(1.0);
/// β lower bound: grains 1/100 as high as wide are flat platelets already (the diffuse
/// layer is then w = τ0 everywhere but at μ < β); the f32 twin is accurate down to 1e-3.
pub const BETA_LO: f64 = 1e-2;

fn clamp_tau(t: f64) -> f64 {
    t.clamp(TAU_MIN, TAU_MAX)
}

fn clamp_beta(b: f64) -> f64 {
    b.clamp(BETA_MIN, 1.0)
}

/// Λ0 = −ln(1 − τ0), the mean number of grain footprints over a point of the base.
pub fn lambda0(tau0: f64) -> f64 {
    -(-tau0).ln_1p()
}

/// The grains' shared parameters clamped to their ranges, with Λ0 taken once per
/// parameter vector: in a lane kernel, libm's `log1p` once per lane group was 5 % of a
/// micrograin model's time.
#[derive(Clone, Copy, Debug)]
pub struct Grains {
    tau0: f64,
    beta: f64,
    l0: f64,
}

impl Grains {
    pub fn new(tau0: f64, beta: f64) -> Grains {
        let tau0 = clamp_tau(tau0);
        Grains {
            tau0,
            beta: clamp_beta(beta),
            l0: lambda0(tau0),
        }
    }
}

/// γβ(θ) = √(β² sin²θ + cos²θ): projected area of a (1, 1, β) ellipsoid seen from θ, over π.
pub fn gamma_beta(beta: f64, mu: f64) -> f64 {
    gamma_beta_in(beta, mu)
}

/// [`gamma_beta`] over any [`Real`].
#[inline(always)]
fn gamma_beta_in<R: Real>(beta: f64, mu: R) -> R {
    let s2 = (R::splat(1.0) - mu * mu).max(R::zero());
    (R::splat(beta * beta) * s2 + mu * mu).sqrt()
}

/// Visibility weight w of the grains (Eqs. 21–23): 1 − (1 − τ0)^{½(γβ(θi)/μi + γβ(θo)/μo)}.
pub fn weight(tau0: f64, beta: f64, mu_i: f64, mu_o: f64) -> f64 {
    weight_in(&Grains::new(tau0, beta), mu_i, mu_o)
}

/// [`weight`] over any [`Real`].
#[inline(always)]
pub fn weight_in<R: Real>(g: &Grains, mu_i: R, mu_o: R) -> R {
    let beta = g.beta;
    let mi = mu_i.abs().clamp(MU_MIN, 1.0);
    let mo = mu_o.abs().clamp(MU_MIN, 1.0);
    let e = R::splat(0.5) * (gamma_beta_in(beta, mi) / mi + gamma_beta_in(beta, mo) / mo);
    (-(R::splat(-g.l0) * e).exp_m1()).clamp(0.0, 1.0)
}

/// Micrograin NDF (Eq. 17) at the unit micro-normal `h` (local frame).
pub fn ndf(tau0: f64, beta: f64, h: DVec3) -> f64 {
    ndf_in(&Grains::new(tau0, beta), h.into())
}

/// [`ndf`] over any [`Real`].
#[inline(always)]
fn ndf_in<R: Real>(g: &Grains, h: V3<R>) -> R {
    let (tau0, beta, l0) = (g.tau0, g.beta, g.l0);
    let (c2, s2) = (h.z * h.z, h.x * h.x + h.y * h.y);
    let u = s2 / (R::splat(beta * beta) * c2 + s2);
    let d = R::splat(l0 / tau0) * (R::splat(-l0) * u).exp() * ggx_d(beta, h);
    R::select(h.z.le(R::zero()), R::zero(), d)
}

/// (σ, S) with σ = μ/γβ and S = Λ·σ, from the first `terms` terms of the Λ series. In
/// lanes, a lane whose series has converged adds no more terms while the others go on.
#[inline(always)]
fn lambda_parts_n<R: Real>(grains: &Grains, mu: R, terms: usize) -> (R, R) {
    let (tau0, beta, l0) = (grains.tau0, grains.beta, grains.l0);
    let one = R::splat(1.0);
    let mu = mu.clamp(0.0, 1.0);
    let s2 = (one - mu * mu).max(R::zero());
    let g = (R::splat(beta * beta) * s2 + mu * mu).sqrt();
    let sn = mu / g;
    let c2 = R::splat(beta * beta) * s2 / (g * g);
    let mut wk = l0 * (1.0 - tau0) / tau0; // w_0 = Λ0/(e^{Λ0} − 1)
    let mut c2k = one; // c^{2k}
    let mut j = c2 / (one + sn); // J_0 = 1 − σ, without cancellation
    let mut sum = R::splat(wk * SERIES[0].k) * (c2 - sn * j);
    let mut done = R::zero().lt(R::zero());
    for (k, t) in SERIES.iter().enumerate().take(terms).skip(1) {
        let kf = k as f64;
        wk *= l0 * t.inv_k;
        c2k = c2k * c2;
        j = (R::splat(2.0 * kf) * j - c2k * sn) * R::splat(t.inv_odd);
        let term = R::splat(wk * t.k) * (c2k * c2 * R::splat(t.inv_odd) - sn * j);
        sum = R::select(done, sum, sum + term);
        // Every term is ≥ 0 and ≤ w_k c^{2k+2}/2; once k + 1 ≥ 2Λ0 the w_k at least halve,
        // so the whole tail is ≤ w_k c^{2k+2}/2: stop when that is negligible.
        if kf + 1.0 >= 2.0 * l0 {
            done = done | (R::splat(wk) * c2k * c2).le(R::splat(LAMBDA_TAIL_EPS) * sum);
            if !R::any(!done) {
                break;
            }
        }
    }
    (sn, sum.max(R::zero()))
}

/// The Λ series' constant factors for term k: K_k, 1/k and 1/(2k + 1).
struct SeriesTerm {
    k: f64,
    inv_k: f64,
    inv_odd: f64,
}

/// [`SeriesTerm`] for k < [`LAMBDA_TERMS`], tabulated at compile time: the series then
/// takes no division per term (four before; the series was 37 % of the CPU sweep's time).
const SERIES: [SeriesTerm; LAMBDA_TERMS] = {
    let mut t = [const {
        SeriesTerm {
            k: 0.5, // K_0
            inv_k: 0.0,
            inv_odd: 1.0,
        }
    }; LAMBDA_TERMS];
    let mut k = 1;
    while k < LAMBDA_TERMS {
        let kf = k as f64;
        t[k].k = t[k - 1].k * ((kf + 0.5) / (kf + 1.0));
        t[k].inv_k = 1.0 / kf;
        t[k].inv_odd = 1.0 / (2.0 * kf + 1.0);
        k += 1;
    }
    t
};

fn lambda_parts(tau0: f64, beta: f64, mu: f64) -> (f64, f64) {
    lambda_parts_n(&Grains::new(tau0, beta), mu, LAMBDA_TERMS)
}

/// Smith Λ of the micrograin NDF at direction cosine μ (infinite at μ = 0).
pub fn lambda(tau0: f64, beta: f64, mu: f64) -> f64 {
    let (sn, s) = lambda_parts(tau0, beta, mu);
    if sn <= 0.0 {
        f64::INFINITY
    } else {
        s / sn
    }
}

/// Smith G1 = 1/(1 + Λ) = σ/(σ + S).
pub fn g1(tau0: f64, beta: f64, mu: f64) -> f64 {
    let (sn, s) = lambda_parts(tau0, beta, mu);
    sn / (sn + s)
}

/// G1(μ)/μ = 1/(γβ (σ + S)), finite as μ → 0.
pub fn g1_over_mu(tau0: f64, beta: f64, mu: f64) -> f64 {
    g1_over_mu_in(&Grains::new(tau0, beta), mu)
}

/// [`g1_over_mu`] over any [`Real`].
#[inline(always)]
fn g1_over_mu_in<R: Real>(g: &Grains, mu: R) -> R {
    let (sn, s) = lambda_parts_n(g, mu, LAMBDA_TERMS);
    R::splat(1.0) / (gamma_beta_in(g.beta, mu.clamp(0.0, 1.0)) * (sn + s))
}

/// Rough dielectric grain (rmg): F(ωi·h) D(h) G1(μi) G1(μo)/(4 μi μo) plus
/// (1 − F(μi))(1 − F(μo)) ρ_g/π, exact dielectric Fresnel of index η_g. As in the
/// reference shader, the specular term takes F at the half-vector angle and the diffuse
/// term the Fresnel transmittances at μi and μo.
pub fn rough_grain(tau0: f64, beta: f64, eta_g: f64, rho_g: f64, wi: DVec3, wo: DVec3) -> f64 {
    RoughGrain::at(tau0, beta, eta_g, wi, wo).value(rho_g)
}

/// [`rough_grain`] at one direction pair without ρ_g: the specular term and the product
/// of the two Fresnel transmittances, shared by every channel (ρ_g is the only rgb
/// parameter of the grain).
#[derive(Clone, Copy, Debug)]
pub struct RoughGrain<R: Real = f64> {
    /// The product of the Fresnel transmittances at μi and μo; 0 below the surface.
    transmit: R,
    /// The specular term, added where `has_spec` holds (not below the surface, nor
    /// where ωi = −ωo).
    spec: R,
    has_spec: R::Mask,
}

/// Caches of [`RoughGrain`]'s factors of μi or μo alone over one block of directions of
/// one parameter vector: one-entry memos of the Fresnel transmittances (cheaper to
/// recompute than to look up lane by lane: tabulated too, `rmg(lambert)` ran 0.88× as fast
/// on a 5,130-sample off-plane file), and G1/μ, whose Λ series is most of the grain's
/// cost, in per-block tables keyed by the engine's μ slots ([`SlotMemo`]; a one-entry
/// memo in the f64 reference).
#[derive(Clone, Debug)]
pub struct RoughGrainMemo<R: Real = f64> {
    t_i: Memo<R>,
    t_o: Memo<R>,
    g_i: SlotMemo<R>,
    g_o: SlotMemo<R>,
}

impl<R: Real> Default for RoughGrainMemo<R> {
    fn default() -> Self {
        RoughGrainMemo {
            t_i: Memo::default(),
            t_o: Memo::default(),
            g_i: SlotMemo::default(),
            g_o: SlotMemo::default(),
        }
    }
}

impl RoughGrain {
    pub fn at(tau0: f64, beta: f64, eta_g: f64, wi: DVec3, wo: DVec3) -> RoughGrain {
        let dir = LaneDir::new(wi.into(), wo.into());
        Self::at_memo(
            &mut RoughGrainMemo::default(),
            &Grains::new(tau0, beta),
            eta_g,
            &dir,
        )
    }
}

impl<R: Real> RoughGrain<R> {
    /// [`Self::at`] with the factors of μi or μo alone taken from `memo` where it holds
    /// them (the same parameters must be passed for every direction of a memo's run).
    #[inline(always)]
    pub fn at_memo(
        memo: &mut RoughGrainMemo<R>,
        grains: &Grains,
        eta_g: f64,
        dir: &LaneDir<R>,
    ) -> RoughGrain<R> {
        let (wi, wo) = (dir.wi, dir.wo);
        let (mu_i, mu_o) = (wi.z, wo.z);
        let [slot_i, slot_o] = dir.mu_slots;
        let zero = R::zero();
        let above = zero.lt(mu_i) & zero.lt(mu_o);
        if !R::any(above) {
            return RoughGrain {
                transmit: zero,
                spec: zero,
                has_spec: above,
            };
        }
        let eta = R::splat(eta_g.max(1.0));
        let transmit = memo.t_i.get(
            mu_i,
            #[inline(always)]
            |mu| fresnel_transmittance_in(mu, eta),
        ) * memo.t_o.get(
            mu_o,
            #[inline(always)]
            |mu| fresnel_transmittance_in(mu, eta),
        );
        let hs = wi + wo;
        let hl2 = hs.dot(hs);
        let has_spec = above & !hl2.lt(R::splat(1e-30));
        let hl = hl2.sqrt();
        let h = V3::new(hs.x / hl, hs.y / hl, hs.z / hl);
        let cd = wi.dot(h).clamp(0.0, 1.0);
        let spec = fresnel_dielectric_in(cd, eta)
            * ndf_in(grains, h)
            * memo.g_i.get(
                slot_i,
                mu_i,
                #[inline(always)]
                |mu| g1_over_mu_in(grains, mu),
            )
            * memo.g_o.get(
                slot_o,
                mu_o,
                #[inline(always)]
                |mu| g1_over_mu_in(grains, mu),
            )
            * R::splat(0.25);
        RoughGrain {
            transmit: R::select(above, transmit, zero),
            spec,
            has_spec,
        }
    }

    /// The grain's value for albedo ρ_g: spec + transmittances · ρ_g/π.
    #[inline(always)]
    pub fn value(&self, rho_g: R) -> R {
        let diffuse = self.transmit * rho_g * R::splat(FRAC_1_PI);
        R::select(self.has_spec, self.spec + diffuse, diffuse)
    }
}

/// The layer: f = w·f_grain + (1 − w)·f_B.
#[inline(always)]
pub fn layer<R: Real>(w: R, f_grain: R, f_base: R) -> R {
    w * f_grain + (R::splat(1.0) - w) * f_base
}

/// Helpers shared by the tests of `micrograin`, `dmg` and `rmg`.
#[cfg(test)]
pub(crate) mod testutil {
    use glam::DVec3;
    use std::f64::consts::PI;

    pub fn dir_mu(mu: f64, phi: f64) -> DVec3 {
        let s = (1.0 - mu * mu).max(0.0).sqrt();
        DVec3::new(s * phi.cos(), s * phi.sin(), mu)
    }

    pub use crate::math::gauss_legendre;

    /// Composite Gauss–Legendre rule: `panels` panels of `n` nodes on [a, b].
    pub fn composite(panels: usize, n: usize, a: f64, b: f64) -> Vec<(f64, f64)> {
        let h = (b - a) / panels as f64;
        (0..panels)
            .flat_map(|p| gauss_legendre(n, a + p as f64 * h, a + (p + 1) as f64 * h))
            .collect()
    }

    /// Edge-case grid of directions: μ from 1e-4 to 1, azimuths including wi == wo and mirror.
    pub fn edge_directions() -> Vec<DVec3> {
        let mut v = Vec::new();
        for &mu in &[1e-4, 1e-3, 0.02, 0.2, 0.5, 0.8, 0.99, 1.0] {
            for &phi in &[0.0, 0.3, PI / 2.0, PI] {
                v.push(dir_mu(mu, phi));
            }
        }
        v
    }
}

#[cfg(test)]
mod tests {
    use super::testutil::*;
    use super::*;
    use std::f64::consts::PI;

    const TAUS: [f64; 6] = [1e-3, 0.01, 0.1, 0.5, 0.9, 0.999];
    const BETAS: [f64; 5] = [BETA_LO, 0.05, 0.3, 0.7, 1.0];

    #[test]
    fn weight_is_in_unit_interval_symmetric_and_tau0_at_normal() {
        let mus = [1e-6, 1e-4, 1e-3, 0.01, 0.1, 0.3, 0.5, 0.7, 0.9, 0.999, 1.0];
        for &t in &TAUS {
            for &b in &BETAS {
                for &mi in &mus {
                    for &mo in &mus {
                        let w = weight(t, b, mi, mo);
                        assert!(
                            w.is_finite() && (0.0..=1.0).contains(&w),
                            "w({t},{b},{mi},{mo}) = {w}"
                        );
                        assert!(w >= t * (1.0 - 1e-12), "w < tau0: {w} {t}");
                        assert_eq!(
                            w,
                            weight(t, b, mo, mi),
                            "w not symmetric at {t} {b} {mi} {mo}"
                        );
                    }
                }
                assert!((weight(t, b, 1.0, 1.0) - t).abs() < 1e-12);
                assert!(weight(t, b, 1e-6, 1e-6) > weight(t, b, 0.5, 0.5));
            }
        }
        // The staged form of Eqs. 21–23 equals the simplified one.
        for &t in &TAUS {
            for &b in &BETAS {
                for &(mi, mo) in &[(0.2, 0.9), (0.7, 0.4), (0.05, 1.0)] {
                    let tp = |mu: f64| 1.0 - (1.0 - t).powf((mu + gamma_beta(b, mu)) / (2.0 * mu));
                    let staged = 1.0 - (1.0 - tp(mi)) * (1.0 - tp(mo)) / (1.0 - t);
                    let w = weight(t, b, mi, mo);
                    assert!(
                        (staged - w).abs() < 1e-12,
                        "{t} {b} {mi} {mo}: {staged} vs {w}"
                    );
                }
            }
        }
    }

    /// ∫ D(m) cos θm dω = 2π ∫₀¹ D(c) c dc, composite Gauss–Legendre in c graded towards
    /// c = 1 (where the lobe of small β sits). Tolerance 1e-6.
    #[test]
    fn ndf_is_normalised() {
        for &t in &TAUS {
            for &b in &[0.02, 0.05, 0.3, 0.7, 1.0] {
                let mut s = 0.0;
                // c = 1 − x, x ∈ [0, 1] split geometrically: [0, 1e-6], [1e-6, 1e-5], …, [0.1, 1]
                let mut edges = vec![0.0];
                edges.extend((0..7).map(|k| 10f64.powi(k - 6)));
                for w in edges.windows(2) {
                    for (x, wt) in composite(8, 20, w[0], w[1]) {
                        let c = 1.0 - x;
                        let h = dir_mu(c, 0.0);
                        s += wt * ndf(t, b, h) * c;
                    }
                }
                let integral = 2.0 * PI * s;
                assert!(
                    (integral - 1.0).abs() < 1e-6,
                    "tau0 {t} beta {b}: {integral}"
                );
            }
        }
    }

    /// The Λ series against its definition through the Smith identity
    /// 1 + Λ(v) = (1/μ) ∫ ⟨v·m⟩⁺ D(m) dω_m, with D written in the variable t = √(1 − u):
    /// D cos θm dω_m = (Λ0/τ0) e^{−Λ0 (1−t²)} 2t dt dφ/(2π), tan θm = β √(1−t²)/t, and the
    /// azimuthal integral of (a + b cos φ)⁺ done in closed form; then t = sin ψ (smooth at
    /// t = 1) and the ψ range split where the positive part switches on (t = β s/γβ).
    /// Tolerance 1e-9 relative.
    #[test]
    fn lambda_series_matches_the_smith_identity() {
        for &t in &TAUS {
            for &b in &[0.05, 0.3, 1.0] {
                for &mu in &[0.02f64, 0.1, 0.3, 0.6, 0.9, 0.999] {
                    let s = (1.0 - mu * mu).sqrt();
                    let l0 = lambda0(t);
                    let kink = (s * b / gamma_beta(b, mu)).asin();
                    let nodes = composite(32, 20, 0.0, kink).into_iter().chain(composite(
                        32,
                        20,
                        kink,
                        PI / 2.0,
                    ));
                    let mut acc = 0.0;
                    for (psi, wt) in nodes {
                        let (x, cx) = psi.sin_cos();
                        // (v·m)/cos θm · 2t = 2 (μ t + s β √(1−t²) cos φ), averaged over φ
                        let a = mu * x;
                        let bb = s * b * cx;
                        let phi_avg = if bb <= a {
                            a
                        } else {
                            let p0 = (-a / bb).acos();
                            (a * p0 + bb * p0.sin()) / PI
                        };
                        acc += wt * cx * (-l0 * cx * cx).exp() * 2.0 * phi_avg;
                    }
                    let direct = (l0 / t) * acc / mu - 1.0;
                    let series = lambda(t, b, mu);
                    let tol = 1e-9 * series.max(1e-3);
                    assert!(
                        (direct - series).abs() < tol,
                        "tau0 {t} beta {b} mu {mu}: direct {direct} series {series}"
                    );
                }
            }
        }
    }

    /// 32 terms are converged (vs 96) to 1e-13 in G1; the authors' 7 terms are not at
    /// τ0 = 0.999 (documents the difference from their shader).
    #[test]
    fn lambda_series_truncation() {
        let g1n = |t: f64, b: f64, mu: f64, n: usize| {
            let (sn, s) = lambda_parts_n(&Grains::new(t, b), mu, n);
            sn / (sn + s)
        };
        let mut worst7 = 0.0f64;
        for &t in &TAUS {
            for &b in &BETAS {
                for &mu in &[1e-4, 0.01, 0.1, 0.3, 0.6, 0.9, 0.999] {
                    let exact = g1n(t, b, mu, 96);
                    assert!(
                        (g1n(t, b, mu, LAMBDA_TERMS) - exact).abs() < 1e-13,
                        "{t} {b} {mu}"
                    );
                    worst7 = worst7.max((g1n(t, b, mu, 7) - exact).abs());
                    if t <= 0.5 {
                        assert!((g1n(t, b, mu, 7) - exact).abs() < 1e-6);
                    }
                }
            }
        }
        assert!(worst7 > 0.03, "7-term error at tau0 = 0.999 is {worst7}");
    }

    #[test]
    fn tau0_to_zero_gives_ggx_and_the_shared_functions_are_finite() {
        // τ0 → 0: D → GGX(α = β), Λ → Λ_GGX(β).
        use crate::bsdf::microfacet::{Distribution, Ggx, Masking};
        let t = 1e-6;
        for &b in &[0.05, 0.3, 1.0] {
            for &mu in &[0.05, 0.4, 0.9] {
                let h = dir_mu(mu, 0.0);
                let ggx = Ggx { alpha: b };
                let (d, dg) = (ndf(t, b, h), ggx.d(h));
                assert!((d - dg).abs() < 1e-5 * dg, "{b} {mu}: {d} {dg}");
                let (l, lg) = (lambda(t, b, mu), ggx.lambda(h));
                assert!((l - lg).abs() < 1e-5 * lg.max(1e-9), "{b} {mu}: {l} {lg}");
            }
        }
        for &t in &[0.0, 1e-3, 0.5, 0.999, 1.0] {
            for &b in &[0.0, 1e-4, BETA_LO, 0.5, 1.0] {
                for wi in edge_directions() {
                    let g = g1(t, b, wi.z);
                    let gm = g1_over_mu(t, b, wi.z);
                    assert!(
                        g.is_finite() && (0.0..=1.0).contains(&g),
                        "G1 {t} {b} {}: {g}",
                        wi.z
                    );
                    assert!(gm.is_finite() && gm >= 0.0);
                    for wo in edge_directions() {
                        for eta in [1.0, 1.5, 5.0] {
                            let f = rough_grain(t, b, eta, 1.0, wi, wo);
                            assert!(f.is_finite() && f >= 0.0, "{t} {b} {eta} {wi} {wo}: {f}");
                        }
                    }
                }
            }
        }
    }
}
