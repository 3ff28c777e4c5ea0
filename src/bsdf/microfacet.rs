//! Microfacet distributions in vector form: the normal distribution D(m) and the Smith
//! masking Λ(ω) / G1(ω, m) of GGX (Trowbridge–Reitz), Beckmann, Burley's GTR and the
//! generalized Gaussian, shared by the reflection lobes (`ggx`, the lobe of `fa`, `+retro`),
//! the transmission terms (`btdf`) and the micrograin NDF. Twin: `shaders/bsdf/microfacet.wgsl`.
//!
//! Conventions (docs/conventions.md): local frame with the macro-normal on +z; m and ω are unit
//! vectors. Every form takes cos²θ = z² and sin²θ = x² + y² from the components, never
//! sin²θ = 1 − cos²θ: near a sharp peak (α ≲ 1e-2) 1 − cos²θ keeps only the rounding of
//! cos θ (f32: 6e-8, while sin²θ is ~α² = 4e-6 at α = 2e-3), and the textbook GGX
//! denominator cos²θ (α² − 1) + 1 cancels the same way. GGX is written
//! D = α² / (π (α² cos²θ + sin²θ)²), which has no cancellation at all.
//!
//! D is normalised so that ∫ D(m) m.z dω_m = 1 and is 0 for m.z ≤ 0. Λ does not depend on
//! the side of ω (the sign of ω.z).

use super::WgslFn;
use crate::math::lanes::{Real, V3};
use crate::math::ln_gamma;
use glam::DVec3;
use std::f64::consts::PI;
use std::sync::OnceLock;

/// The WGSL twin, for the `sources` of every model that uses it.
pub const MICROFACET_WGSL: (&str, &str) = (
    "microfacet",
    include_str!("../../shaders/bsdf/microfacet.wgsl"),
);

/// A node whose twin is one file `shaders/bsdf/<name>.wgsl` defining `<name>_eval` on top
/// of `microfacet.wgsl` ([`WgslFn::single`] with this module's twin).
pub fn single_wgsl(name: &'static str, source: &'static str) -> WgslFn {
    let mut w = WgslFn::single(name, source);
    w.sources.insert(0, MICROFACET_WGSL);
    w
}

/// A microfacet normal distribution D(m).
pub trait Distribution {
    /// D at the unit microfacet normal `m` (0 below the surface, m.z ≤ 0).
    fn d(&self, m: DVec3) -> f64;
}

/// Smith masking of a distribution (Heitz 2014): Λ(ω) and the G1 built from it.
pub trait Masking {
    /// Smith Λ at the unit direction `w` (infinite at grazing, w.z = 0).
    fn lambda(&self, w: DVec3) -> f64;

    /// G1(ω)/|ω.z| = 1 / (|ω.z| (1 + Λ(ω))) without the side test, in a form that stays
    /// finite as ω.z → 0 (what the BTDF's |μ| divisions need).
    fn g1_over_mu(&self, w: DVec3) -> f64;

    /// Smith G1(ω, m) = χ⁺((ω·m)/(ω·n)) / (1 + Λ(ω)) (Walter 2007, Eq. 34 for GGX): zero
    /// when ω and m lie on opposite sides relative to the macro-normal.
    fn g1(&self, w: DVec3, m: DVec3) -> f64 {
        if w.dot(m) * w.z <= 0.0 {
            return 0.0;
        }
        w.z.abs() * self.g1_over_mu(w)
    }
}

/// cos²θ and sin²θ of a unit vector, from its components.
pub fn cos2_sin2(v: DVec3) -> (f64, f64) {
    (v.z * v.z, v.x * v.x + v.y * v.y)
}

/// The microfacet reflection kernel D(h) G1(ωi, h) G1(ωo, h) / (4 μi μo) at the unit half
/// vector `h` of ωi and ωo (Walter 2007, Eq. 20 without its Fresnel factor); ωi and ωo
/// must be above the surface.
pub fn reflection<M: Distribution + Masking>(ndf: &M, wi: DVec3, wo: DVec3, h: DVec3) -> f64 {
    ndf.d(h) * ndf.g1(wi, h) * ndf.g1(wo, h) / (4.0 * wi.z * wo.z)
}

// ---------------------------------------------------------------------------------------
// GGX / Trowbridge–Reitz

/// GGX (Trowbridge–Reitz) of roughness α (Walter 2007, Eqs. 33–34; Heitz 2014, Eq. 72).
#[derive(Clone, Copy, Debug)]
pub struct Ggx {
    pub alpha: f64,
}

impl Distribution for Ggx {
    /// α² / (π (α² cos²θm + sin²θm)²).
    fn d(&self, m: DVec3) -> f64 {
        ggx_d(self.alpha, m.into())
    }
}

/// [`Ggx`]'s D over any [`Real`].
#[inline(always)]
pub fn ggx_d<R: Real>(alpha: f64, m: V3<R>) -> R {
    let a2 = R::splat(alpha * alpha);
    let (c2, s2) = (m.z * m.z, m.x * m.x + m.y * m.y);
    let t = a2 * c2 + s2;
    R::select(m.z.le(R::zero()), R::zero(), a2 / (R::splat(PI) * t * t))
}

impl Ggx {
    /// [`reflection`] for GGX in one division, at `m` = any positive multiple of the half
    /// vector h (ωi + ωo itself: no normalisation needed). With G1(ω) = 2μ / (μ + r),
    /// r = √(μ² + α² sin²θ) (Walter 2007, Eq. 34), the μi μo of G1(ωi) G1(ωo) cancel the
    /// 4 μi μo, and D(h) = α² / (π t²), t = α² cos²θh + sin²θh = (α² m_z² + m_x² + m_y²)/|m|²,
    /// leaving α² |m|⁴ / (π t_m² (μi + ri)(μo + ro)), t_m = α² m_z² + m_x² + m_y², which is
    /// unchanged when m is scaled. The same value as the generic kernel to rounding, in a
    /// fifth of its divisions (the lobes of `ggx`, `fa` and `+retro` evaluate it once per
    /// direction). ωi and ωo must be above the surface.
    #[inline]
    pub fn reflection(&self, wi: DVec3, wo: DVec3, m: DVec3) -> f64 {
        ggx_reflection(self.alpha, wi.into(), wo.into(), m.into())
    }
}

/// [`Ggx::reflection`] over any [`Real`] (lanes of directions; `f64` is the reference).
#[inline(always)]
pub fn ggx_reflection<R: Real>(alpha: R, wi: V3<R>, wo: V3<R>, m: V3<R>) -> R {
    // D = 0 below; χ⁺ of G1: a facet facing away from ωi or ωo masks it.
    let zero = R::zero();
    let masked = m.z.le(zero) | (wi.dot(m) * wi.z).le(zero) | (wo.dot(m) * wo.z).le(zero);
    let a2 = alpha * alpha;
    let (c2, s2) = (m.z * m.z, m.x.mul_add(m.x, m.y * m.y));
    let (t, m2) = (a2.mul_add(c2, s2), c2 + s2);
    let value = a2 * (m2 * m2) / (R::splat(PI) * t * t * ggx_r(a2, wi) * ggx_r(a2, wo));
    R::select(masked, zero, value)
}

/// μ + √(μ² + α² sin²θ), μ = |cos θ|: 2μ / G1(ω) of GGX.
#[inline(always)]
fn ggx_r<R: Real>(a2: R, w: V3<R>) -> R {
    let mu = w.z.abs();
    mu + mu.mul_add(mu, a2 * w.x.mul_add(w.x, w.y * w.y)).sqrt()
}

impl Masking for Ggx {
    /// ½ (√(1 + α² tan²θ) − 1) = α² sin²θ / (2 μ (μ + √(μ² + α² sin²θ))), μ = |cos θ|.
    fn lambda(&self, w: DVec3) -> f64 {
        let mu = w.z.abs();
        let as2 = self.alpha * self.alpha * (w.x * w.x + w.y * w.y);
        as2 / (2.0 * mu * (mu + (mu * mu + as2).sqrt()))
    }

    /// 2 / (μ + √(μ² + α² sin²θ)).
    fn g1_over_mu(&self, w: DVec3) -> f64 {
        ggx_g1_over_mu(self.alpha, w.into())
    }
}

/// [`Ggx`]'s G1(ω)/|ω.z| over any [`Real`].
#[inline(always)]
pub fn ggx_g1_over_mu<R: Real>(alpha: f64, w: V3<R>) -> R {
    let mu = w.z.abs();
    let s2 = w.x * w.x + w.y * w.y;
    R::splat(2.0) / (mu + (mu * mu + R::splat(alpha * alpha) * s2).sqrt())
}

// ---------------------------------------------------------------------------------------
// Beckmann and GTR (the `btdf` terms pair them with the GGX Λ, as the benchmark paper)

/// Below this cos²θm the exponential NDFs (Beckmann, GG) are returned as 0; they are
/// below e^-(10^6) there for every parameter in bounds.
pub const C2_MIN: f64 = 1e-30;

/// Beckmann of roughness α (Walter 2007, Eq. 25).
#[derive(Clone, Copy, Debug)]
pub struct Beckmann {
    pub alpha: f64,
}

impl Distribution for Beckmann {
    /// exp(−tan²θm/α²) / (π α² cos⁴θm).
    fn d(&self, m: DVec3) -> f64 {
        self.d_in(m.into())
    }
}

impl Beckmann {
    /// [`Distribution::d`] over any [`Real`].
    #[inline(always)]
    pub fn d_in<R: Real>(&self, m: V3<R>) -> R {
        let (c2, s2) = (m.z * m.z, m.x * m.x + m.y * m.y);
        let zero = R::zero();
        let a2 = self.alpha * self.alpha;
        let d = (-(s2 / c2) / R::splat(a2) - R::splat(2.0) * c2.ln()).exp() / R::splat(PI * a2);
        R::select(m.z.le(zero) | c2.lt(R::splat(C2_MIN)), zero, d)
    }
}

/// Burley's generalized Trowbridge–Reitz (Burley 2012, Appendix B): γ = 2 is GGX, γ = 1
/// Berry.
#[derive(Clone, Copy, Debug)]
pub struct Gtr {
    pub alpha: f64,
    pub gamma: f64,
}

impl Distribution for Gtr {
    /// c(α, γ) / (α² cos²θm + sin²θm)^γ, normalised by [`gtr_norm`].
    fn d(&self, m: DVec3) -> f64 {
        self.d_in(m.into())
    }
}

impl Gtr {
    /// [`Distribution::d`] over any [`Real`].
    #[inline(always)]
    pub fn d_in<R: Real>(&self, m: V3<R>) -> R {
        let a2 = (self.alpha * self.alpha).max(1e-12);
        let (c2, s2) = (m.z * m.z, m.x * m.x + m.y * m.y);
        let d = R::splat(gtr_norm(a2, self.gamma))
            * (R::splat(-self.gamma) * (R::splat(a2) * c2 + s2).ln()).exp();
        R::select(m.z.le(R::zero()), R::zero(), d)
    }
}

/// Normalisation constant of GTR: (γ−1)(α²−1) / (π (1 − (α²)^(1−γ))), with its limits
/// at γ = 1 and α = 1 taken analytically (the plain form is 0/0 there).
pub fn gtr_norm(a2: f64, gamma: f64) -> f64 {
    let ln_a2 = a2.ln();
    // (γ−1)(α²−1) / (1 − e^x) with x = (1−γ) ln α², i.e. (α²−1)/ln α² · x/(e^x − 1),
    // each factor → 1 at its 0/0 point.
    let x = (1.0 - gamma) * ln_a2;
    let ratio = if x.abs() < 1e-8 {
        1.0 - 0.5 * x
    } else {
        x / x.exp_m1()
    };
    let a_term = if ln_a2.abs() < 1e-8 {
        1.0 + 0.5 * ln_a2
    } else {
        (a2 - 1.0) / ln_a2
    };
    a_term * ratio / PI
}

// ---------------------------------------------------------------------------------------
// Generalized Gaussian (Holzschuch & Pacanowski 2017)

/// Holzschuch–Pacanowski generalized Gaussian of width β and shape p (Holzschuch &
/// Pacanowski 2017; p = 1 is Beckmann of α = β), with its per-evaluation constants. Its
/// Smith Λ comes from the table [`gg_lambda_table`].
#[derive(Clone, Copy, Debug)]
pub struct Gg {
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

impl Gg {
    pub fn new(beta: f64, p: f64) -> Gg {
        let lg = ln_gamma(1.0 / p);
        Gg {
            beta,
            p,
            rc: (-p.ln() / (2.0 * p)).exp(),
            j0: (ln_gamma(1.5 / p) - lg).exp() / PI,
            ln_norm: p.ln() - lg - (PI * beta * beta).ln(),
        }
    }

    /// (μ, μ Λ) with μ Λ = T̂ · J0 · (β sinθ + μ / r_c), T̂ from the table at x = b/(1+b),
    /// b = r_c β tanθ; finite at μ = 0.
    #[inline(always)]
    fn mu_lambda<R: Real>(&self, w: V3<R>, row: Option<&LambdaRow>) -> (R, R) {
        let bs = R::splat(self.beta) * (w.x * w.x + w.y * w.y).sqrt();
        self.mu_lambda_at(w.z.abs(), bs, row)
    }

    /// (μ, μ Λ) at μ = |cos θ| and the width `bs` the direction sees (β sinθ; the
    /// anisotropic form's projected width, [`super::stretched`]), T̂ from the table at
    /// this shape p, or from its `row` at p where given (f32 lanes). In lanes the
    /// table's values are read lane by lane.
    #[inline(always)]
    pub(super) fn mu_lambda_at<R: Real>(&self, mu: R, bs: R, row: Option<&LambdaRow>) -> (R, R) {
        let b = bs * R::splat(self.rc);
        let x = b / (mu + b);
        let t = match row {
            Some(row) => row.interpolate_in(x),
            None => gg_lambda_table().interpolate_in(self.p, x),
        };
        (mu, t * R::splat(self.j0) * (bs + mu / R::splat(self.rc)))
    }

    /// D from z = tan²θm/β² (the anisotropic form's stretched slope) and c2 = cos²θm,
    /// with the normalisation `ln_norm` (its own for the anisotropic form).
    #[inline(always)]
    pub(super) fn d_at<R: Real>(&self, ln_norm: f64, z: R, c2: R) -> R {
        let zero = R::zero();
        let e = R::select(
            zero.lt(z),
            (R::splat(self.p) * z.ln()).clamp(-80.0, 80.0).exp(),
            zero,
        );
        (R::splat(ln_norm) - e - R::splat(2.0) * c2.ln()).exp()
    }

    /// [`Distribution::d`] over any [`Real`].
    #[inline(always)]
    pub fn d_in<R: Real>(&self, m: V3<R>) -> R {
        let (c2, s2) = (m.z * m.z, m.x * m.x + m.y * m.y);
        let zero = R::zero();
        let d = self.d_at(self.ln_norm, s2 / c2 / R::splat(self.beta * self.beta), c2);
        R::select(m.z.le(zero) | c2.lt(R::splat(C2_MIN)), zero, d)
    }

    /// [`Masking::g1_over_mu`] over any [`Real`].
    #[inline(always)]
    pub fn g1_over_mu_in<R: Real>(&self, w: V3<R>) -> R {
        self.g1_over_mu_with(w, None)
    }

    /// [`Self::g1_over_mu_in`] with T̂ from the table's `row` at this p where given.
    #[inline(always)]
    pub fn g1_over_mu_with<R: Real>(&self, w: V3<R>, row: Option<&LambdaRow>) -> R {
        let (mu, mu_lambda) = self.mu_lambda(w, row);
        R::splat(1.0) / (mu + mu_lambda)
    }
}

impl Distribution for Gg {
    /// p / (π β² Γ(1/p)) · exp(−(tan²θm/β²)^p) / cos⁴θm.
    fn d(&self, m: DVec3) -> f64 {
        self.d_in(m.into())
    }
}

impl Masking for Gg {
    fn lambda(&self, w: DVec3) -> f64 {
        let (mu, mu_lambda) = self.mu_lambda(V3::from(w), None);
        mu_lambda / mu
    }

    fn g1_over_mu(&self, w: DVec3) -> f64 {
        self.g1_over_mu_in(w.into())
    }
}

/// Points in ln p of the GG Λ table (p from [`GG_P_LO`] to [`GG_P_HI`], uniform in ln p),
/// not counting the ghost row stored on each side.
pub const GG_NP: usize = 65;
/// Points in x = b/(1+b) of the GG Λ table (x from 0 to 1 inclusive, uniform), not
/// counting the ghost column stored on each side.
pub const GG_NA: usize = 129;
pub const GG_P_LO: f64 = 0.2;
pub const GG_P_HI: f64 = 5.0;

/// Catmull–Rom weights of the four nodes around a cell at fraction t ∈ [0, 1] (Catmull &
/// Rom 1974; Keys 1981, a = −½): the cubic through the two cell nodes whose slopes are
/// the central differences there. Local, interpolating, O(h³) accurate; the same
/// polynomial forms are written in `gg_cr_weights` of `shaders/bsdf/microfacet.wgsl`.
pub fn catmull_rom_weights(t: f64) -> [f64; 4] {
    catmull_rom_weights_in(t)
}

/// [`catmull_rom_weights`] over any [`Real`].
#[inline(always)]
fn catmull_rom_weights_in<R: Real>(t: R) -> [R; 4] {
    let c = R::splat;
    let t2 = t * t;
    let t3 = t2 * t;
    [
        c(0.5) * (-t3 + c(2.0) * t2 - t),
        c(0.5) * (c(3.0) * t3 - c(5.0) * t2 + c(2.0)),
        c(0.5) * (c(-3.0) * t3 + c(4.0) * t2 + t),
        c(0.5) * (t3 - t2),
    ]
}

/// Tabulated Smith Λ of the generalized Gaussian NDF, computed once in f64.
///
/// Grid: ln p uniform on [ln [`GG_P_LO`], ln [`GG_P_HI`]] ([`GG_NP`] points) and
/// x = b/(1 + b) uniform on [0, 1] ([`GG_NA`] points), with b = r_c(p) · a, a = β tanθ,
/// r_c(p) = (1/p)^(1/(2p)) (the characteristic slope of the β = 1 distribution); value
/// T̂ = Λ / (J0(p) · (a + 1/r_c(p))), J0(p) = Γ(3/(2p)) / (π Γ(1/p)); T̂ → 1 as x → 1
/// (Λ ≈ J0 a − ½ for large a) and T̂ → 0 as x → 0. Factoring out J0 and scaling a by r_c
/// remove the p-dependence that interpolation handles badly (J0 spans 0.2 … 25 over the
/// p range).
///
/// Interpolation is bicubic Catmull–Rom ([`LambdaTable::interpolate`], the same
/// arithmetic as `gg_table` in `shaders/bsdf/microfacet.wgsl`, which reads an f32 copy
/// bound as `LUT`). It needs one node beyond each side of a cell, so the table stores a
/// ghost row on each side of the p range (exact values at ln p one step outside: the
/// integral is defined for every p > 0) and a ghost column on each side of x (x < 0 and
/// x > 1 have no meaning; the quadratic through the three nearest columns, 3f₀ − 3f₁ + f₂,
/// keeps the edge cells third-order accurate). Measured against direct integration at
/// 20,000 random (p, x) points, the relative error of G1 = 1/(1 + Λ), |ΔΛ|/(1 + Λ), is
/// 4.6e-7 (the bilinear 33 × 129 table this replaces: 9.4e-5; bicubic on it without the
/// ghost rows: 4.8e-5, its edge cells only second order). 67 × 131 values, 35 kB in f32.
///
/// Layout: `data[r * GG_NA_STRIDE + c]`, stored row r = ip + 1 for grid row ip ∈ [−1, GG_NP],
/// stored column c = ia + 1 for grid column ia ∈ [−1, GG_NA].
#[derive(Clone, Debug)]
pub struct LambdaTable {
    pub np: usize,
    pub na: usize,
    pub ln_p_lo: f64,
    pub ln_p_hi: f64,
    pub data: Vec<f64>,
}

/// Stored values per row of the GG Λ table: the grid's [`GG_NA`] plus two ghost columns.
pub const GG_NA_STRIDE: usize = GG_NA + 2;
/// Stored rows of the GG Λ table: the grid's [`GG_NP`] plus two ghost rows.
pub const GG_NP_STORED: usize = GG_NP + 2;

impl LambdaTable {
    fn compute() -> LambdaTable {
        let (ln_p_lo, ln_p_hi) = (GG_P_LO.ln(), GG_P_HI.ln());
        let step = (ln_p_hi - ln_p_lo) / (GG_NP - 1) as f64;
        let mut data = Vec::with_capacity(GG_NP_STORED * GG_NA_STRIDE);
        for r in 0..GG_NP_STORED {
            let p = (ln_p_lo + (r as f64 - 1.0) * step).exp();
            let row: Vec<f64> = (0..GG_NA)
                .map(|ia| gg_table_value(p, ia as f64 / (GG_NA - 1) as f64))
                .collect();
            let n = GG_NA - 1;
            data.push(3.0 * row[0] - 3.0 * row[1] + row[2]);
            data.extend_from_slice(&row);
            data.push(3.0 * row[n] - 3.0 * row[n - 1] + row[n - 2]);
        }
        LambdaTable {
            np: GG_NP,
            na: GG_NA,
            ln_p_lo,
            ln_p_hi,
            data,
        }
    }

    /// Bicubic (Catmull–Rom) T̂ at (p, x), clamped to the table's range.
    pub fn interpolate(&self, p: f64, x: f64) -> f64 {
        self.interpolate_in(p, x)
    }

    /// [`Self::interpolate`] over any [`Real`]: the weights in p once, those in x and
    /// the table's values per lane.
    #[inline(always)]
    pub fn interpolate_in<R: Real>(&self, p: f64, x: R) -> R {
        let stride = self.na + 2;
        let (ip, wp) = self.p_weights(p);
        let (ia, wa) = x_weights(self.na, x);
        // Grid node (ip − 1, ia − 1) is stored at (ip, ia).
        let mut t = R::zero();
        for (i, &wpi) in wp.iter().enumerate() {
            let row = &self.data[(ip + i) * stride..];
            t = t + R::splat(wpi) * weigh_row(row, &ia, &wa);
        }
        // Cubic overshoot where T̂ leaves 0 must not make Λ negative (G1 > 1).
        t.max(R::zero())
    }

    /// The table collapsed at shape p ([`LambdaRow`]).
    pub fn row(&self, p: f64) -> LambdaRow {
        let (ip, wp) = self.p_weights(p);
        let mut data = [0.0; GG_NA_STRIDE];
        for (i, &wpi) in wp.iter().enumerate() {
            let row = &self.data[(ip + i) * GG_NA_STRIDE..(ip + i + 1) * GG_NA_STRIDE];
            for (d, &v) in data.iter_mut().zip(row) {
                *d += wpi * v;
            }
        }
        LambdaRow { data }
    }

    /// The first of the four grid rows the interpolation at p weighs, and their weights.
    #[inline(always)]
    fn p_weights(&self, p: f64) -> (usize, [f64; 4]) {
        let fp = ((p.ln() - self.ln_p_lo) / (self.ln_p_hi - self.ln_p_lo)).clamp(0.0, 1.0)
            * (self.np - 1) as f64;
        let ip = (fp as usize).min(self.np - 2);
        (ip, catmull_rom_weights(fp - ip as f64))
    }

    /// Λ at shape p and a = β tanθ, from the table.
    pub fn lambda(&self, p: f64, a: f64) -> f64 {
        let g = Gg::new(1.0, p);
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

/// The GG Λ table at one shape p: the four rows the bicubic interpolation weighs in p,
/// summed once per parameter vector, so that T̂ at x reads four values per lane instead
/// of sixteen. For f32 lanes: the sums run in another order than
/// [`LambdaTable::interpolate_in`]'s, so the values are equal to rounding, not bit for bit.
#[derive(Clone, Debug)]
pub struct LambdaRow {
    data: [f64; GG_NA_STRIDE],
}

impl LambdaRow {
    /// T̂ at x (the table's clamp and Catmull–Rom weights in x).
    #[inline(always)]
    pub fn interpolate_in<R: Real>(&self, x: R) -> R {
        let (ia, wa) = x_weights(GG_NA, x);
        weigh_row(&self.data, &ia, &wa).max(R::zero())
    }
}

/// Per lane, the first of the four grid columns (of `na`) the interpolation at x weighs,
/// and their weights.
#[inline(always)]
fn x_weights<R: Real>(na: usize, x: R) -> ([usize; 16], [R; 4]) {
    let fa = x.clamp(0.0, 1.0) * R::splat((na - 1) as f64);
    let mut ia = [0usize; 16];
    for (j, ia) in ia.iter_mut().enumerate().take(R::LANES) {
        *ia = (fa.lane(j) as usize).min(na - 2);
    }
    let wa = catmull_rom_weights_in(fa - R::from_fn(|j| ia[j] as f64));
    (ia, wa)
}

/// Σ_k wa[k] · row[ia + k] per lane: one row's cubic in x.
#[inline(always)]
fn weigh_row<R: Real>(row: &[f64], ia: &[usize; 16], wa: &[R; 4]) -> R {
    wa[0] * gather(row, ia, 0)
        + wa[1] * gather(row, ia, 1)
        + wa[2] * gather(row, ia, 2)
        + wa[3] * gather(row, ia, 3)
}

/// Lane j of the result is `row[ia[j] + k]`.
#[inline(always)]
fn gather<R: Real>(row: &[f64], ia: &[usize; 16], k: usize) -> R {
    R::from_fn(|j| row[ia[j] + k])
}

/// The GG Λ table, computed on first use (~8.7k one-dimensional integrals).
pub fn gg_lambda_table() -> &'static LambdaTable {
    static TABLE: OnceLock<LambdaTable> = OnceLock::new();
    TABLE.get_or_init(LambdaTable::compute)
}

/// The exact table value T̂(p, x) by numerical integration.
pub fn gg_table_value(p: f64, x: f64) -> f64 {
    if x >= 1.0 {
        return 1.0;
    }
    let g = Gg::new(1.0, p);
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

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// The vector forms against independent closed forms in θ (cos θ and tan θ from the
    /// angle, not from the vector's components) at moderate roughness (α, β ∈ [0.05, 1]),
    /// where the cosine forms are well conditioned in f64. Tolerance 1e-12 relative (the
    /// exponential NDFs: 1e-12 · (1 + exponent), the exponent's own rounding, where D is a
    /// normal f64).
    #[test]
    fn vector_forms_match_the_closed_forms_in_theta() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        // Below f64's normal range (far in the exponential tails) digits are lost anyway.
        const NORMAL: f64 = 1e-300;
        let close = |a: f64, b: f64, tol: f64| a.is_finite() && (a - b).abs() <= tol * b.abs();
        for _ in 0..20_000 {
            let alpha: f64 = (0.05f64.ln() * rng.random::<f64>()).exp();
            let theta: f64 = rng.random_range(0.0..1.55);
            let phi: f64 = rng.random_range(0.0..2.0 * PI);
            let v = DVec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            );
            let (c, t2) = (theta.cos(), theta.tan().powi(2));
            let a2 = alpha * alpha;

            // GGX: D = α² / (π cos⁴ (α² + tan²)²), Λ = ½ (√(1 + α² tan²) − 1).
            let ggx = Ggx { alpha };
            let d = a2 / (PI * c.powi(4) * (a2 + t2).powi(2));
            assert!(close(ggx.d(v), d, 1e-12), "GGX D α {alpha} θ {theta}");
            // (the closed form's √(1 + x) − 1 cancels at small x: compare |ΔΛ|/(1 + Λ))
            let lambda = 0.5 * ((1.0 + a2 * t2).sqrt() - 1.0);
            let gl = ggx.lambda(v);
            assert!(
                gl.is_finite() && (gl - lambda).abs() <= 1e-12 * (1.0 + lambda),
                "GGX Λ α {alpha} θ {theta}: {gl} {lambda}"
            );
            let g1 = 1.0 / (1.0 + lambda);
            assert!(close(ggx.g1(v, DVec3::Z), g1, 1e-12), "GGX G1");
            assert!(close(ggx.g1_over_mu(-v) * c, g1, 1e-12), "GGX G1/μ below");
            // χ⁺: a microfacet facing away from ω masks it completely.
            assert_eq!(ggx.g1(v, DVec3::new(-v.x, -v.y, -v.z)), 0.0);

            // Beckmann: exp(−tan²/α²) / (π α² cos⁴).
            let x = t2 / a2;
            let d = (-x).exp() / (PI * a2 * c.powi(4));
            let db = Beckmann { alpha }.d(v);
            assert!(
                close(db, d, 1e-12 * (1.0 + x)) || d < NORMAL,
                "Beckmann α {alpha} θ {theta}: {db} {d}"
            );

            // GTR: c(α, γ) / (α² cos² + 1 − cos²)^γ; γ = 2 is GGX.
            let gamma: f64 = rng.random_range(0.5..4.0);
            let d = gtr_norm(a2, gamma) * (a2 * c * c + 1.0 - c * c).powf(-gamma);
            assert!(close(Gtr { alpha, gamma }.d(v), d, 1e-12), "GTR γ {gamma}");
            let gtr2 = Gtr { alpha, gamma: 2.0 };
            assert!(close(gtr2.d(v), ggx.d(v), 1e-12), "GTR γ = 2 vs GGX");

            // GG: p / (π β² Γ(1/p)) exp(−(tan²/β²)^p) / cos⁴; Λ from the table at β tanθ.
            let p: f64 = rng.random_range(0.2..5.0);
            let gg = Gg::new(alpha, p);
            let x = (t2 / a2).powf(p);
            let d = p / (PI * a2 * ln_gamma(1.0 / p).exp()) * (-x).exp() / c.powi(4);
            assert!(
                close(gg.d(v), d, 1e-12 * (1.0 + x)) || d < NORMAL,
                "GG D p {p}"
            );
            // (|ΔΛ|/(1 + Λ): the relative error of G1; Λ is ~1e-25 at small tanθ/β.)
            let lambda = gg_lambda_table().lambda(p, alpha * theta.tan());
            let gl = gg.lambda(v);
            assert!(
                gl.is_finite() && (gl - lambda).abs() <= 1e-12 * (1.0 + lambda),
                "GG Λ p {p} θ {theta}: {gl} {lambda}"
            );
            assert!(close(gg.g1(v, DVec3::Z), 1.0 / (1.0 + lambda), 1e-12));
        }
        // Below the surface D is 0; at grazing Λ = ∞, G1 = 0 and G1/μ stays finite.
        let (below, grazing) = (DVec3::new(0.6, 0.0, -0.8), DVec3::X);
        assert_eq!(Ggx { alpha: 0.3 }.d(below), 0.0);
        assert_eq!(Beckmann { alpha: 0.3 }.d(below), 0.0);
        assert_eq!(
            Gtr {
                alpha: 0.3,
                gamma: 1.5
            }
            .d(below),
            0.0
        );
        assert_eq!(Gg::new(0.3, 2.0).d(below), 0.0);
        assert_eq!(Ggx { alpha: 0.3 }.lambda(grazing), f64::INFINITY);
        assert!((Ggx { alpha: 0.3 }.g1_over_mu(grazing) - 2.0 / 0.3).abs() < 1e-15);
        let gg = Gg::new(0.3, 2.0);
        assert!(gg.g1_over_mu(grazing).is_finite() && gg.g1_over_mu(grazing) > 0.0);
    }

    /// GGX's one-division reflection kernel is the generic D G1 G1 / (4 μi μo) to
    /// rounding, from sharp to rough, at grazing and on the wrong side of a facet.
    #[test]
    fn ggx_reflection_kernel_matches_the_generic_one() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let mut worst = 0.0f64;
        for k in 0..50_000 {
            let alpha: f64 = (1e-3f64.ln() * rng.random::<f64>()).exp();
            let mut dir = || {
                let mu: f64 = if k % 4 == 0 {
                    rng.random_range(1e-4..2e-2)
                } else {
                    rng.random_range(1e-4..1.0)
                };
                let phi: f64 = rng.random_range(0.0..2.0 * PI);
                let s = (1.0 - mu * mu).sqrt();
                DVec3::new(s * phi.cos(), s * phi.sin(), mu)
            };
            let (wi, wo) = (dir(), dir());
            let h = crate::math::half_vector(wi, wo);
            let ggx = Ggx { alpha };
            let generic = reflection(&ggx, wi, wo, h);
            // At h, and at the unnormalised ωi + ωo (the kernel is invariant under scaling).
            for fast in [ggx.reflection(wi, wo, h), ggx.reflection(wi, wo, wi + wo)] {
                assert!(
                    fast.is_finite() && fast >= 0.0,
                    "α {alpha} {wi} {wo}: {fast}"
                );
                if generic == 0.0 {
                    assert_eq!(fast, 0.0, "α {alpha} {wi} {wo}");
                    continue;
                }
                let rel = (fast - generic).abs() / generic;
                worst = worst.max(rel);
                assert!(rel <= 1e-13, "α {alpha} {wi} {wo}: {fast:e} vs {generic:e}");
            }
        }
        eprintln!("GGX one-division kernel vs generic: worst relative difference {worst:.1e}");
        // A facet facing away from ωo: zero, as G1's χ⁺.
        let (wi, wo) = (DVec3::new(0.6, 0.0, 0.8), DVec3::new(0.0, 0.6, 0.8));
        assert_eq!(
            Ggx { alpha: 0.3 }.reflection(wi, wo, DVec3::new(-0.8, 0.0, 0.6)),
            0.0
        );
    }

    /// The point of the vector form: at a sharp peak (α = 2e-3, θh up to 0.1°) evaluated in
    /// f32, α² cos² + sin² keeps f32's relative accuracy where the textbook
    /// cos² (α² − 1) + 1 loses it (the GPU twin computes the former).
    #[test]
    fn ggx_vector_form_is_accurate_in_f32_at_small_alpha() {
        let alpha = 2e-3f64;
        let (mut worst_new, mut worst_old) = (0.0f64, 0.0f64);
        for k in 0..=100 {
            let th = (0.1f64 * k as f64 / 100.0).to_radians();
            let m = DVec3::new(th.sin() * 0.6, th.sin() * 0.8, th.cos());
            let exact = Ggx { alpha }.d(m);
            let (a, mz, s2) = (
                alpha as f32,
                m.z as f32,
                (m.x as f32).powi(2) + (m.y as f32).powi(2),
            );
            let a2 = a * a;
            let t_new = a2 * (mz * mz) + s2;
            let t_old = mz * mz * (a2 - 1.0) + 1.0;
            let d = |t: f32| (a2 / (std::f32::consts::PI * t * t)) as f64;
            worst_new = worst_new.max((d(t_new) - exact).abs() / exact);
            worst_old = worst_old.max((d(t_old) - exact).abs() / exact);
        }
        eprintln!("f32 GGX D at α = 2e-3, θh ≤ 0.1°: vector form {worst_new:.1e}, cosine form {worst_old:.1e}");
        assert!(worst_new < 1e-6, "vector form in f32: {worst_new:e}");
        assert!(
            worst_old > 1e-2,
            "the cosine form was expected to fail: {worst_old:e}"
        );
    }
}
