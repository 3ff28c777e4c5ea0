//! Microfacet distributions in vector form: the normal distribution D(m) and the Smith
//! masking Λ(ω) / G1(ω, m) of GGX (Trowbridge–Reitz), Beckmann, Burley's GTR and the
//! generalized Gaussian, shared by the reflection lobes (`ggx`, the lobe of `fa`, `+retro`),
//! the transmission terms (`btdf`) and the micrograin NDF. Twin: `shaders/bsdf/microfacet.wgsl`.
//!
//! Conventions (DESIGN §1): local frame with the macro-normal on +z; m and ω are unit
//! vectors. Every form takes cos²θ = z² and sin²θ = x² + y² from the components, never
//! sin²θ = 1 − cos²θ: near a sharp peak (α ≲ 1e-2) 1 − cos²θ keeps only the rounding of
//! cos θ (f32: 6e-8, while sin²θ is ~α² = 4e-6 at α = 2e-3), and the textbook GGX
//! denominator cos²θ (α² − 1) + 1 cancels the same way. GGX is written
//! D = α² / (π (α² cos²θ + sin²θ)²), which has no cancellation at all.
//!
//! D is normalised so that ∫ D(m) m.z dω_m = 1 and is 0 for m.z ≤ 0. Λ does not depend on
//! the side of ω (the sign of ω.z).

use super::WgslFn;
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
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        let (c2, s2) = cos2_sin2(m);
        let t = a2 * c2 + s2;
        a2 / (PI * t * t)
    }
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
        let mu = w.z.abs();
        let s2 = w.x * w.x + w.y * w.y;
        2.0 / (mu + (mu * mu + self.alpha * self.alpha * s2).sqrt())
    }
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
        let (c2, s2) = cos2_sin2(m);
        if m.z <= 0.0 || c2 < C2_MIN {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        (-(s2 / c2) / a2 - 2.0 * c2.ln()).exp() / (PI * a2)
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
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = (self.alpha * self.alpha).max(1e-12);
        let (c2, s2) = cos2_sin2(m);
        gtr_norm(a2, self.gamma) * (-self.gamma * (a2 * c2 + s2).ln()).exp()
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

    /// μ (1 + Λ) = μ + T̂ · J0 · (β sinθ + μ / r_c), T̂ from the table at x = b/(1+b),
    /// b = r_c β tanθ; finite at μ = 0.
    fn mu_one_plus_lambda(&self, w: DVec3) -> (f64, f64) {
        let mu = w.z.abs();
        let bs = self.beta * (w.x * w.x + w.y * w.y).sqrt();
        let b = bs * self.rc;
        let x = b / (mu + b);
        let t = gg_lambda_table().interpolate(self.p, x);
        (mu, mu + t * self.j0 * (bs + mu / self.rc))
    }
}

impl Distribution for Gg {
    /// p / (π β² Γ(1/p)) · exp(−(tan²θm/β²)^p) / cos⁴θm.
    fn d(&self, m: DVec3) -> f64 {
        let (c2, s2) = cos2_sin2(m);
        if m.z <= 0.0 || c2 < C2_MIN {
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
}

impl Masking for Gg {
    fn lambda(&self, w: DVec3) -> f64 {
        let (mu, s) = self.mu_one_plus_lambda(w);
        (s - mu) / mu
    }

    fn g1_over_mu(&self, w: DVec3) -> f64 {
        1.0 / self.mu_one_plus_lambda(w).1
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
/// arithmetic as `gg_table` in `shaders/bsdf/microfacet.wgsl`, which reads an f32 copy bound
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
    use crate::bsdf::btdf::Ndf;
    use crate::math::half_vector;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Transcriptions of the (c², s²) forms `btdf` used before this module (temporary).
    mod old {
        use super::super::*;
        use crate::bsdf::btdf::{refraction, transmit};

        pub fn walter(
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

        pub fn tr_d(c2: f64, s2: f64, alpha: f64) -> f64 {
            let a2 = alpha * alpha;
            let t = a2 * c2 + s2;
            a2 / (PI * t * t)
        }

        pub fn beckmann_d(c2: f64, s2: f64, alpha: f64) -> f64 {
            if c2 < C2_MIN {
                return 0.0;
            }
            let a2 = alpha * alpha;
            (-(s2 / c2) / a2 - 2.0 * c2.ln()).exp() / (PI * a2)
        }

        pub fn gtr_d(c2: f64, s2: f64, alpha: f64, gamma: f64) -> f64 {
            let a2 = (alpha * alpha).max(1e-12);
            crate::math::gtr_norm(a2, gamma) * (-gamma * (a2 * c2 + s2).ln()).exp()
        }

        pub fn tr_g1_over_mu(v: DVec3, alpha: f64) -> f64 {
            let mu = v.z.abs();
            let s2 = v.x * v.x + v.y * v.y;
            2.0 / (mu + (mu * mu + alpha * alpha * s2).sqrt())
        }

        pub fn gg_d(g: &Gg, c2: f64, s2: f64) -> f64 {
            if c2 < C2_MIN {
                return 0.0;
            }
            let z = s2 / c2 / (g.beta * g.beta);
            let e = if z > 0.0 {
                (g.p * z.ln()).clamp(-80.0, 80.0).exp()
            } else {
                0.0
            };
            (g.ln_norm - e - 2.0 * c2.ln()).exp()
        }

        pub fn gg_g1_over_mu(g: &Gg, v: DVec3) -> f64 {
            let mu = v.z.abs();
            let bs = g.beta * (v.x * v.x + v.y * v.y).sqrt();
            let w = bs * g.rc;
            let x = w / (mu + w);
            let t = gg_lambda_table().interpolate(g.p, x);
            1.0 / (mu + t * g.j0 * (bs + mu / g.rc))
        }
    }

    fn random_dir(rng: &mut ChaCha8Rng) -> DVec3 {
        let mu: f64 = rng.random_range(1e-4..1.0);
        let phi: f64 = rng.random_range(0.0..2.0 * PI);
        let s = (1.0 - mu * mu).sqrt();
        DVec3::new(s * phi.cos(), s * phi.sin(), mu)
    }

    /// Refactoring check: the vector forms against the cosine forms they replace, on
    /// random inputs (α log-uniform in [1e-3, 1]). Where the old GGX denominator
    /// t = c²(α²−1)+1 is itself small its f64 rounding (~ε/t) dominates the difference.
    #[test]
    fn vector_forms_match_the_forms_they_replace() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let eps = f64::EPSILON;
        let (mut worst_d, mut worst_near_peak, mut worst_g) = (0.0f64, 0.0f64, 0.0f64);
        let mut worst_model = 0.0f64;
        let mut btdf_valid = 0;
        let mut worst_mg = 0.0f64;
        for _ in 0..200_000 {
            let alpha = (1e-3f64.ln() * rng.random::<f64>()).exp();
            let gamma = rng.random_range(0.5..4.0);
            let (wi, wo) = (random_dir(&mut rng), random_dir(&mut rng));
            let h = half_vector(wi, wo);
            let ggx = Ggx { alpha };
            let old = crate::math::ggx_d(h.z, alpha);
            let new = ggx.d(h);
            let t = h.z * h.z * (alpha * alpha - 1.0) + 1.0;
            let rel = (new - old).abs() / old;
            assert!(rel <= 1e-12 + 8.0 * eps / t, "D {alpha} {h}: {old} {new}");
            if t >= 1e-3 {
                worst_d = worst_d.max(rel);
            } else {
                worst_near_peak = worst_near_peak.max(rel);
            }
            for w in [wi, wo] {
                let old = crate::math::ggx_g1(w.z, w.dot(h), alpha);
                let new = ggx.g1(w, h);
                let err = (new - old).abs() / old;
                assert!(err <= 1e-12, "G1 {alpha} {w}: {old} {new}");
                worst_g = worst_g.max(err);
                assert!(ggx.g1_over_mu(w) == old::tr_g1_over_mu(w, alpha));
            }
            // The models: ggx (and fa's lobe) and the retro lobe, old transcriptions.
            let old_lobe = |wi: DVec3, wo: DVec3| {
                let h = half_vector(wi, wo);
                crate::math::ggx_d(h.z, alpha)
                    * crate::math::ggx_g1(wi.z, wi.dot(h), alpha)
                    * crate::math::ggx_g1(wo.z, wo.dot(h), alpha)
                    / (4.0 * wi.z * wo.z)
            };
            let old = crate::math::fresnel_dielectric(wi.dot(h), 1.5) * old_lobe(wi, wo);
            let new = crate::bsdf::ggx::ggx_reflect(1.0, alpha, 1.5, wi, wo);
            let rel = (new - old).abs() / old;
            assert!(
                rel <= 1e-12 + 8.0 * eps / t,
                "ggx {alpha} {wi} {wo}: {old} {new}"
            );
            if t >= 1e-3 {
                worst_model = worst_model.max(rel);
            }
            let back = DVec3::new(-wo.x, -wo.y, wo.z);
            let old = old_lobe(wi, back);
            let new = crate::bsdf::retro::retro_lobe(1.0, alpha, wi, wo);
            let tb = {
                let hb = half_vector(wi, back);
                hb.z * hb.z * (alpha * alpha - 1.0) + 1.0
            };
            let rel = (new - old).abs() / old;
            assert!(
                rel <= 1e-12 + 8.0 * eps / tb,
                "retro {alpha} {wi} {wo}: {old} {new}"
            );
            if tb >= 1e-3 {
                worst_model = worst_model.max(rel);
            }
            // The micrograin NDF (its old explicit form), τ0 in its box.
            let tau0 = (1e-3f64.ln() * rng.random::<f64>()).exp().min(0.999);
            let beta = alpha.max(1e-2);
            let old = {
                let l0 = crate::bsdf::micrograin::lambda0(tau0);
                let b2 = beta * beta;
                let s2 = h.x * h.x + h.y * h.y;
                let d = b2 * h.z * h.z + s2;
                (l0 / tau0) * (-l0 * s2 / d).exp() * b2 / PI / (d * d)
            };
            let new = crate::bsdf::micrograin::ndf(tau0, beta, h);
            let rel = (new - old).abs() / old;
            assert!(rel <= 1e-13, "mg ndf {tau0} {beta} {h}: {old} {new}");
            worst_mg = worst_mg.max(rel);
            // The btdf terms, whole: Eq. 1 with the old (c², s²) closures.
            let eta = rng.random_range(1.01..3.0);
            let (bi, bo) = (wi, DVec3::new(wo.x, wo.y, -wo.z));
            let beta = alpha.max(3e-3);
            let p = rng.random_range(0.2..5.0);
            let gg = Gg::new(beta, p);
            for (ndf, params, old) in [
                (
                    Ndf::Tr,
                    vec![alpha, eta],
                    old::walter(
                        bi,
                        bo,
                        eta,
                        |c2, s2| old::tr_d(c2, s2, alpha),
                        |v| old::tr_g1_over_mu(v, alpha),
                    ),
                ),
                (
                    Ndf::Beckmann,
                    vec![alpha, eta],
                    old::walter(
                        bi,
                        bo,
                        eta,
                        |c2, s2| old::beckmann_d(c2, s2, alpha),
                        |v| old::tr_g1_over_mu(v, alpha),
                    ),
                ),
                (
                    Ndf::Gtr,
                    vec![alpha, gamma, eta],
                    old::walter(
                        bi,
                        bo,
                        eta,
                        |c2, s2| old::gtr_d(c2, s2, alpha, gamma),
                        |v| old::tr_g1_over_mu(v, alpha),
                    ),
                ),
                (
                    Ndf::Gg,
                    vec![beta, p, eta],
                    old::walter(
                        bi,
                        bo,
                        eta,
                        |c2, s2| old::gg_d(&gg, c2, s2),
                        |v| old::gg_g1_over_mu(&gg, v),
                    ),
                ),
            ] {
                let new = ndf.eval(&params, bi, bo);
                assert!(old == new, "{ndf:?} {params:?} {bi} {bo}: {old} {new}");
                btdf_valid += (new > 0.0) as usize;
            }
        }
        assert!(btdf_valid > 10_000, "{btdf_valid}");
        eprintln!(
            "worst relative change: GGX D {worst_d:.1e} (old t ≥ 1e-3), {worst_near_peak:.1e} (old t < 1e-3); G1 {worst_g:.1e}; ggx and retro lobes {worst_model:.1e} (old t ≥ 1e-3); btdf terms bit-identical ({btdf_valid} non-zero); micrograin D {worst_mg:.1e}"
        );
    }
}
