//! The battery's misspecified null cases: isotropic surfaces whose highlight lies outside
//! the catalogue's analytic families, written here from their textbook formulas and not
//! through the library's models, so that what `diagnose` names on them measures how it
//! behaves when no model of the catalogue is right.
//!
//! Each truth is a Lambertian body (ρ per channel) plus one microfacet highlight
//! k_s F(ωi·h) D(h) G(ωi, ωo) / (4 cos θi cos θo) (Cook & Torrance 1982; Walter et al.
//! 2007, Eq. 20), with one ingredient the catalogue lacks:
//!
//! - `beckmann`: the Beckmann NDF D = exp(−tan²θ/α²) / (π α² cos⁴θ);
//! - `gtr`: Burley's generalized Trowbridge–Reitz with γ ≠ 2 (Burley 2012, App. B):
//!   D ∝ 1 / (1 + (α² − 1) cos²θ)^γ;
//! - `two-scale`: a mixture of two Beckmann widths, a sharp core on a wide skirt;
//! - `v-cavity`: the GGX NDF with the V-cavity shadowing of Cook & Torrance,
//!   G = min(1, 2 (n·h)(n·ωo)/(ωo·h), 2 (n·h)(n·ωi)/(ωi·h));
//! - `schlick`: the GGX NDF with Schlick's Fresnel F0 + (1 − F0)(1 − cos)⁵ in place of
//!   the exact dielectric one.
//!
//! The transmission families are rough dielectric interfaces (Walter et al. 2007, Eq. 21:
//! air above, index η below, exact (1 − F), Smith masking from D), their NDF outside the
//! BTDF catalogue's TR, Beckmann, GTR and generalized-Gaussian families:
//!
//! - `btdf-two-scale-ndf`: the two-scale Beckmann mixture above;
//! - `btdf-student-ndf`: the Student-t NDF of Ribardière et al. 2017,
//!   D = (1 + tan²θ / ((γ − 1) α²))^(−γ) / (π α² cos⁴θ), with γ ∉ {2, ∞} (γ = 2 is GGX,
//!   γ → ∞ Beckmann).
//!
//! Where masking is Smith's, Λ is integrated numerically from the truth's own D:
//! 1 + Λ(ω) = (1/cos θ) ∫ ⟨ω·m⟩ D(m) dm (Heitz 2014, Eq. 8 and 19), so no family borrows
//! a closed form of the catalogue's. The truths have no backscatter, no retroreflection,
//! no anisotropy and no grazing decay of their own: a diagnosis that names one of them on
//! these data names a false effect.

use super::battery::{case_seed, log_uniform, rate, BatteryOptions, Case, Outcome};
use super::Effect;
use crate::data::{Dataset, Kind, RawRow, ReadOptions};
use anyhow::{anyhow, Result};
use glam::DVec3;
use rand::seq::IndexedRandom;
use rand::Rng;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use std::f64::consts::PI;

/// The families, in the order the battery cycles through them.
pub const FAMILIES: [&str; 5] = [
    "beckmann-ndf",
    "gtr-ndf",
    "two-scale-ndf",
    "v-cavity-shadowing",
    "schlick-fresnel",
];

/// The transmission families, in the order the battery cycles through them (its
/// `misspecified_btdf` cases).
pub const BTDF_FAMILIES: [&str; 2] = ["btdf-two-scale-ndf", "btdf-student-ndf"];

/// The data-driven factor that represents what each family's truth lacks in the
/// catalogue: the NDF's shape for the three distributions and for V-cavity shadowing (a
/// masking term the tabulated NDF's Smith Λ can bend toward), the Fresnel curve for
/// Schlick's approximation.
pub fn right_factor(family: &str) -> Effect {
    if family == "schlick-fresnel" {
        Effect::HighlightFresnel
    } else {
        Effect::HighlightShape
    }
}

/// The isotropic normal distributions of the truths, D(cos θm), each normalised so that
/// ∫ D cos θm dω = 1.
#[derive(Clone, Debug)]
enum Ndf {
    Beckmann(f64),
    Ggx(f64),
    Gtr {
        alpha: f64,
        gamma: f64,
    },
    /// w·Beckmann(α1) + (1 − w)·Beckmann(α2).
    TwoScale {
        a1: f64,
        a2: f64,
        w: f64,
    },
    /// Ribardière et al. 2017's Student-t distribution.
    Student {
        alpha: f64,
        gamma: f64,
    },
}

fn beckmann(c: f64, a: f64) -> f64 {
    let c2 = c * c;
    if c2 <= 0.0 {
        return 0.0;
    }
    (-(1.0 - c2) / (c2 * a * a)).exp() / (PI * a * a * c2 * c2)
}

impl Ndf {
    fn d(&self, c: f64) -> f64 {
        if c <= 0.0 {
            return 0.0;
        }
        match *self {
            Ndf::Beckmann(a) => beckmann(c, a),
            Ndf::Ggx(a) => {
                let a2 = a * a;
                let t = 1.0 + (a2 - 1.0) * c * c;
                a2 / (PI * t * t)
            }
            Ndf::Gtr { alpha, gamma } => {
                let a2 = alpha * alpha;
                let k = (gamma - 1.0) * (a2 - 1.0) / (PI * (1.0 - a2.powf(1.0 - gamma)));
                k / (1.0 + (a2 - 1.0) * c * c).powf(gamma)
            }
            Ndf::TwoScale { a1, a2, w } => w * beckmann(c, a1) + (1.0 - w) * beckmann(c, a2),
            Ndf::Student { alpha, gamma } => {
                // ∫ D cos θ dω = 1 by t = tan²θ: π K (γ − 1) α² / (γ − 1) with K = 1/(π α²).
                let (a2, c2) = (alpha * alpha, c * c);
                let tan2 = (1.0 - c2) / c2;
                (1.0 + tan2 / ((gamma - 1.0) * a2)).powf(-gamma) / (PI * a2 * c2 * c2)
            }
        }
    }
}

#[derive(Clone, Debug)]
enum Fresnel {
    /// The unpolarised reflectance of a dielectric of index η.
    Exact(f64),
    /// Schlick's approximation with normal reflectance F0.
    Schlick(f64),
}

impl Fresnel {
    fn at(&self, c: f64) -> f64 {
        match *self {
            Fresnel::Exact(eta) => {
                let t = (1.0 - (1.0 - c * c) / (eta * eta)).max(0.0).sqrt();
                let rs = (c - eta * t) / (c + eta * t);
                let rp = (eta * c - t) / (eta * c + t);
                0.5 * (rs * rs + rp * rp)
            }
            Fresnel::Schlick(f0) => f0 + (1.0 - f0) * (1.0 - c).clamp(0.0, 1.0).powi(5),
        }
    }
}

/// Points of the tabulated Smith Λ in cos θ.
const LAMBDA_POINTS: usize = 256;

/// One misspecified truth.
#[derive(Clone, Debug)]
pub struct Truth {
    pub family: &'static str,
    /// A BRDF (a body and a highlight) or a BTDF (a rough dielectric's transmission).
    pub kind: Kind,
    ndf: Ndf,
    fresnel: Fresnel,
    /// Smith masking from the NDF (tabulated Λ) when Some; V-cavity when None.
    lambda: Option<Vec<f64>>,
    ks: f64,
    rho: Vec<f64>,
}

impl Truth {
    /// A truth of `family` with `channels` body albedos, its parameters drawn from `rng`.
    pub fn draw(family: &'static str, channels: usize, rng: &mut ChaCha8Rng) -> Truth {
        if BTDF_FAMILIES.contains(&family) {
            return Truth::draw_btdf(family, rng);
        }
        let eta = rng.random_range(1.3..1.8);
        let alpha = (rng.random_range(0.05f64.ln()..0.4f64.ln())).exp();
        let (ndf, fresnel, smith) = match family {
            "beckmann-ndf" => (Ndf::Beckmann(alpha), Fresnel::Exact(eta), true),
            "gtr-ndf" => {
                let gamma = *[1.3, 1.5, 1.7, 2.7, 3.5].choose(rng).expect("non-empty");
                (Ndf::Gtr { alpha, gamma }, Fresnel::Exact(eta), true)
            }
            "two-scale-ndf" => {
                let a1 = rng.random_range(0.03..0.08);
                let a2 = rng.random_range(0.2..0.45);
                let w = rng.random_range(0.3..0.7);
                (Ndf::TwoScale { a1, a2, w }, Fresnel::Exact(eta), true)
            }
            "v-cavity-shadowing" => (Ndf::Ggx(alpha), Fresnel::Exact(eta), false),
            _ => {
                let f0 = rng.random_range(0.02..0.15);
                (Ndf::Ggx(alpha), Fresnel::Schlick(f0), true)
            }
        };
        let lambda = smith.then(|| smith_lambda(&ndf));
        Truth {
            kind: Kind::Brdf,
            family: FAMILIES
                .iter()
                .copied()
                .find(|f| *f == family)
                .unwrap_or("schlick-fresnel"),
            ndf,
            fresnel,
            lambda,
            ks: rng.random_range(0.5..1.0),
            rho: (0..channels).map(|_| rng.random_range(0.05..0.7)).collect(),
        }
    }

    /// A transmission truth of `family` (one of [`BTDF_FAMILIES`]), one channel: a rough
    /// dielectric of index η ∈ [1.3, 1.8] with no body, no absorption and no scale.
    fn draw_btdf(family: &'static str, rng: &mut ChaCha8Rng) -> Truth {
        let eta = rng.random_range(1.3..1.8);
        let ndf = if family == "btdf-two-scale-ndf" {
            Ndf::TwoScale {
                a1: rng.random_range(0.04..0.1),
                a2: rng.random_range(0.2..0.45),
                w: rng.random_range(0.3..0.7),
            }
        } else {
            Ndf::Student {
                alpha: (rng.random_range(0.05f64.ln()..0.35f64.ln())).exp(),
                gamma: *[1.6, 3.0, 6.0].choose(rng).expect("non-empty"),
            }
        };
        Truth {
            family: BTDF_FAMILIES
                .iter()
                .copied()
                .find(|f| *f == family)
                .unwrap_or("btdf-student-ndf"),
            kind: Kind::Btdf,
            lambda: Some(smith_lambda(&ndf)),
            ndf,
            fresnel: Fresnel::Exact(eta),
            ks: 1.0,
            rho: vec![0.0],
        }
    }

    /// The truth in words, with its parameters.
    pub fn describe(&self) -> String {
        let ndf = match &self.ndf {
            Ndf::Beckmann(a) => format!("Beckmann α = {a:.3}"),
            Ndf::Ggx(a) => format!("GGX α = {a:.3}"),
            Ndf::Gtr { alpha, gamma } => format!("GTR α = {alpha:.3}, γ = {gamma}"),
            Ndf::TwoScale { a1, a2, w } => {
                format!(
                    "{w:.2}·Beckmann α = {a1:.3} + {:.2}·Beckmann α = {a2:.3}",
                    1.0 - w
                )
            }
            Ndf::Student { alpha, gamma } => format!("Student-t α = {alpha:.3}, γ = {gamma}"),
        };
        let masking = if self.lambda.is_some() {
            "Smith masking from D"
        } else {
            "V-cavity shadowing"
        };
        let fresnel = match self.fresnel {
            Fresnel::Exact(eta) => format!("exact Fresnel η = {eta:.2}"),
            Fresnel::Schlick(f0) => format!("Schlick Fresnel F0 = {f0:.3}"),
        };
        if self.kind == Kind::Btdf {
            return format!(
                "{}: rough dielectric transmission ({ndf}, {masking}, 1 − {fresnel})",
                self.family
            );
        }
        let rho: Vec<String> = self.rho.iter().map(|r| format!("{r:.2}")).collect();
        format!(
            "{}: Lambertian ρ = {} + {:.2} × ({ndf}, {masking}, {fresnel})",
            self.family,
            rho.join(":"),
            self.ks
        )
    }

    fn masking(&self, wi: DVec3, wo: DVec3, h: DVec3) -> f64 {
        match &self.lambda {
            Some(table) => 1.0 / ((1.0 + lookup(table, wi.z)) * (1.0 + lookup(table, wo.z))),
            None => {
                let (nh, ho) = (h.z, wo.dot(h).max(1e-12));
                (2.0 * nh * wo.z / ho).min(2.0 * nh * wi.z / ho).min(1.0)
            }
        }
    }

    /// The BRDF in channel `ch` for directions above the surface; for a transmission
    /// truth, its BTDF with `wo` below the surface.
    pub fn eval(&self, wi: DVec3, wo: DVec3, ch: usize) -> f64 {
        if self.kind == Kind::Btdf {
            return self.transmission(wi, wo);
        }
        let body = self.rho[ch] / PI;
        let h = (wi + wo).normalize();
        let spec = self.ks * self.fresnel.at(wi.dot(h)) * self.ndf.d(h.z) * self.masking(wi, wo, h)
            / (4.0 * wi.z * wo.z);
        body + spec
    }
}

impl Truth {
    /// Walter et al. 2007, Eq. 21 without the η² radiance factor (the convention of the
    /// catalogue's BTDFs): |i·m| |o·m| (1 − F(i·m)) G1(i) G1(o) D(m) / (μi |μo| (i·m + η o·m)²),
    /// m = −(ωi + η ωo)/‖·‖ turned above the surface; ωi above, ωo below.
    fn transmission(&self, wi: DVec3, wo: DVec3) -> f64 {
        let Fresnel::Exact(eta) = self.fresnel else {
            return 0.0;
        };
        if wi.z <= 0.0 || wo.z >= 0.0 {
            return 0.0;
        }
        let mut m = -(wi + eta * wo).normalize();
        if m.z < 0.0 {
            m = -m;
        }
        let (im, om) = (wi.dot(m), wo.dot(m));
        if im <= 0.0 || om >= 0.0 {
            return 0.0;
        }
        let g1 = |mu: f64| {
            self.lambda
                .as_ref()
                .map_or(1.0, |t| 1.0 / (1.0 + lookup(t, mu)))
        };
        let denom = im + eta * om;
        self.ks
            * im
            * om.abs()
            * (1.0 - self.fresnel.at(im))
            * g1(wi.z)
            * g1(-wo.z)
            * self.ndf.d(m.z)
            / (wi.z * wo.z.abs() * denom * denom)
    }

    /// Where the truth's lobe peaks for incidence at `theta_i` degrees: the mirror angle,
    /// or the refracted one (Snell).
    fn peak_theta(&self, theta_i: f64) -> f64 {
        match (self.kind, &self.fresnel) {
            (Kind::Btdf, Fresnel::Exact(eta)) => {
                (theta_i.to_radians().sin() / eta).asin().to_degrees()
            }
            _ => theta_i,
        }
    }
}

/// Λ(cos θ) at [`LAMBDA_POINTS`] cell centres, integrated from D over the hemisphere of
/// normals (midpoint rule, fine enough for α ≥ 0.03).
fn smith_lambda(ndf: &Ndf) -> Vec<f64> {
    let (nt, np) = (600usize, 96usize);
    let dt = (PI / 2.0) / nt as f64;
    let dp = 2.0 * PI / np as f64;
    let normals: Vec<(f64, f64, f64)> = (0..nt)
        .map(|i| {
            let th = (i as f64 + 0.5) * dt;
            let (st, ct) = th.sin_cos();
            (st, ct, ndf.d(ct) * st * dt * dp)
        })
        .collect();
    let cos_phi: Vec<f64> = (0..np).map(|j| ((j as f64 + 0.5) * dp).cos()).collect();
    (0..LAMBDA_POINTS)
        .map(|k| {
            let mu = (k as f64 + 0.5) / LAMBDA_POINTS as f64;
            let so = (1.0 - mu * mu).sqrt();
            let mut sum = 0.0;
            for &(st, ct, w) in &normals {
                for &cp in &cos_phi {
                    let dot = st * cp * so + ct * mu;
                    if dot > 0.0 {
                        sum += dot * w;
                    }
                }
            }
            (sum / mu - 1.0).max(0.0)
        })
        .collect()
}

/// Λ at `mu` by linear interpolation between cell centres.
fn lookup(table: &[f64], mu: f64) -> f64 {
    let n = table.len();
    let x = (mu * n as f64 - 0.5).clamp(0.0, (n - 1) as f64);
    let k = (x as usize).min(n - 2);
    let t = x - k as f64;
    table[k] * (1.0 - t) + table[k + 1] * t
}

/// A measurement of `truth`: incidence on `azimuths` planes, each at a few polar angles,
/// outgoing directions spread over the hemisphere (cosine-weighted) plus points within 6°
/// of the mirror direction, about `count` samples in all; noise u = √((rel·f)² + abs²)
/// drawn from `rng` and stated as the uncertainty.
pub fn measure(
    truth: &Truth,
    azimuths: &[f64],
    count: usize,
    noise: (f64, f64),
    rng: &mut ChaCha8Rng,
) -> Result<Dataset> {
    let channels = truth.rho.len();
    let mut incidences: Vec<f64> = (0..rng.random_range(3..=5))
        .map(|_| 5.0 * rng.random_range(1..=14) as f64)
        .collect();
    incidences.sort_by(f64::total_cmp);
    incidences.dedup();
    let per = (count / (channels * azimuths.len() * incidences.len())).max(20);
    let gauss = Normal::new(0.0, 1.0).expect("a unit normal");
    let wavelengths = [450.0, 550.0, 650.0];
    let mut raw = Vec::new();
    for &pi in azimuths {
        for &ti in &incidences {
            for k in 0..per {
                let (to, po) = if k % 4 == 0 {
                    // Near the mirror (or refracted) direction, where the lobe's shape
                    // shows.
                    let d = rng.random_range(0.0f64..6.0);
                    let a = rng.random_range(0.0..2.0 * PI);
                    let to = (truth.peak_theta(ti) + d * a.cos()).abs().clamp(0.5, 85.0);
                    (to, pi + 180.0 + d * a.sin() * 2.0)
                } else {
                    let to = rng.random::<f64>().sqrt().asin().to_degrees().min(85.0);
                    (to, pi + rng.random_range(0.0..360.0))
                };
                let wi = direction(ti, pi);
                let mut wo = direction(to, po);
                // A BTDF file's θo is measured from the far side's normal.
                if truth.kind == Kind::Btdf {
                    wo.z = -wo.z;
                }
                for (ch, &wl) in wavelengths.iter().take(channels).enumerate() {
                    let f = truth.eval(wi, wo, ch);
                    let u = ((noise.0 * f).powi(2) + noise.1.powi(2)).sqrt();
                    let mut n: f64 = gauss.sample(rng);
                    // Far from a transmitted lobe f is near 0, and the reader refuses
                    // values more than 3 σ below it.
                    if truth.kind == Kind::Btdf {
                        n = n.clamp(-3.0, 3.0);
                    }
                    let row = RawRow {
                        theta_i: ti,
                        phi_i: pi,
                        theta_o: to,
                        phi_o: po,
                        wavelength_nm: if channels == 1 { 550.0 } else { wl },
                        value: f + u * n,
                        uncertainty: u,
                    };
                    raw.push((raw.len() + 1, row));
                }
            }
        }
    }
    Ok(Dataset::from_rows(
        truth.kind,
        &truth.describe(),
        &raw,
        "<battery>",
        &ReadOptions::default(),
    )?)
}

fn direction(theta_deg: f64, phi_deg: f64) -> DVec3 {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

// ---------------------------------------------------------------------------------------
// The battery's misspecified cases

/// The `k`-th misspecified case's family, and whether it is measured at several
/// incidence azimuths: the families in turn at one azimuth, then in turn at several.
pub(super) fn family_of(k: usize) -> (&'static str, bool) {
    let n = FAMILIES.len();
    (FAMILIES[k % n], (k / n) % 2 == 1)
}

/// [`family_of`] for the `k`-th transmission case, from [`BTDF_FAMILIES`].
pub(super) fn btdf_family_of(k: usize) -> (&'static str, bool) {
    let n = BTDF_FAMILIES.len();
    (BTDF_FAMILIES[k % n], (k / n) % 2 == 1)
}

/// The start model of the misspecified cases, from the effect table: the first BRDF model
/// of the catalogue (a Lambertian body) with its first extension that adds a specular
/// lobe (`fa(lambert)`, the catalogue's GGX highlight over it), the model the truths
/// depart from; on transmission data the first BTDF model of the catalogue (`btdf(tr)`,
/// Walter's BTDF with the GGX NDF).
pub fn start_model(data: &Dataset) -> Result<String> {
    if data.kind == Kind::Btdf {
        return crate::bsdf::catalogue(Kind::Btdf)
            .into_iter()
            .next()
            .ok_or_else(|| anyhow!("no BTDF model in the catalogue"));
    }
    let body = crate::bsdf::catalogue(Kind::Brdf)
        .into_iter()
        .next()
        .ok_or_else(|| anyhow!("no BRDF model in the catalogue"))?;
    super::extensions(&body, data)?
        .into_iter()
        .find(|c| c.effect == Effect::SpecularLobe)
        .map(|c| c.spec)
        .ok_or_else(|| anyhow!("no specular lobe extends {body}"))
}

/// Draw a misspecified null case of a battery, case `id`: an isotropic truth of `family`
/// (from [`family_of`] or [`btdf_family_of`]) measured at one incidence azimuth or at
/// `several`, one or three channels (a transmission truth: one), about a log-uniform
/// number of samples in `opts.samples` (at most 4,000), noise of 1–5 % with a floor.
pub fn generate(
    (family, several): (&'static str, bool),
    id: usize,
    opts: &BatteryOptions,
) -> Result<(Case, Dataset)> {
    let seed = case_seed(opts, id);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Drawn for every family, so a reflection case draws what it did before the
    // transmission families existed; a transmission truth has one channel.
    let channels = if rng.random::<f64>() < 0.5 { 3 } else { 1 };
    let channels = if BTDF_FAMILIES.contains(&family) {
        1
    } else {
        channels
    };
    let truth = Truth::draw(family, channels, &mut rng);
    let first: f64 = rng.random_range(0.0..180.0);
    let azimuths: Vec<f64> = if several {
        let n = rng.random_range(2..=3);
        (0..n)
            .map(|j| first + 180.0 * j as f64 / n as f64)
            .collect()
    } else {
        vec![first]
    };
    let (lo, hi) = (
        opts.samples.0.max(20) as f64,
        opts.samples.1.clamp(20, 4000) as f64,
    );
    let count = log_uniform(lo, hi.max(lo), &mut rng) as usize;
    let noise = (rng.random_range(0.01..0.05), rng.random_range(1e-4..1e-3));
    let mut data = measure(&truth, &azimuths, count, noise, &mut rng)?;
    data.material = format!("battery case {id}");
    let geometry = format!(
        "hemisphere at {} incidence azimuth{} ({})",
        azimuths.len(),
        if azimuths.len() > 1 { "s" } else { "" },
        azimuths
            .iter()
            .map(|a| format!("{a:.0}°"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let case = Case {
        id,
        hidden: None,
        misspecified: Some(family.to_string()),
        start: start_model(&data)?,
        truth: truth.describe(),
        truth_params: vec![],
        geometry,
        samples: data.len(),
        channels,
        noise_rel: noise.0,
        signal: 0.0,
        seed,
    };
    Ok((case, data))
}

/// Whether a diagnosis of a misspecified case names a false effect. Its truth is
/// isotropic, without backscatter, retroreflection or decay: only a second specular lobe,
/// another NDF family for a transmitted lobe (the analytic ways to reshape a lobe:
/// `long_tail` swaps the family) or a data-driven factor (a reshaped highlight, its
/// Fresnel curve, or the body's profile: the truth's body is a plain Lambertian one, where
/// `fa`'s is Fresnel-transmitted) is a right name.
pub fn names_a_false_effect(effects: &[Effect]) -> bool {
    effects
        .iter()
        .any(|e| ![Effect::SpecularLobe, Effect::LongTail].contains(e) && !e.is_data_driven())
}

/// The misspecified null cases as a markdown table: per family and geometry (one
/// incidence azimuth or several), how many cases named each effect, and the false
/// effects (any effect but a second specular lobe, another NDF family for a transmitted
/// lobe, or a data-driven factor); empty without such cases.
pub fn table(outcomes: &[Outcome]) -> String {
    let cases: Vec<&Outcome> = outcomes
        .iter()
        .filter(|o| o.case.misspecified.is_some() && o.error.is_none())
        .collect();
    if cases.is_empty() {
        return String::new();
    }
    let mut starts: Vec<&str> = cases.iter().map(|o| o.case.start.as_str()).collect();
    starts.sort();
    starts.dedup();
    let start = starts.join("` or `");
    let mut s = format!(
        "\nMisspecified null cases (isotropic truths outside the catalogue, diagnosed from `{start}`):\n\n| truth | incidence azimuths | cases | the truth's factor named | anisotropy named | anisotropy refused (cases) | retro_lobe named | other effects named | false effects |\n|---|---|---|---|---|---|---|---|---|\n"
    );
    let several = |o: &Outcome| !o.case.geometry.starts_with("hemisphere at 1 ");
    for family in FAMILIES.into_iter().chain(BTDF_FAMILIES) {
        for multi in [false, true] {
            let group: Vec<&&Outcome> = cases
                .iter()
                .filter(|o| o.case.misspecified.as_deref() == Some(family) && several(o) == multi)
                .collect();
            if group.is_empty() {
                continue;
            }
            let named = |e: Effect| {
                group
                    .iter()
                    .filter(|o| o.named.iter().any(|n| n == e.name()))
                    .count()
            };
            let mut others: Vec<(String, usize)> = Vec::new();
            for o in &group {
                for n in &o.named {
                    if [Effect::Anisotropy, Effect::RetroLobe, right_factor(family)]
                        .iter()
                        .any(|e| e.name() == n)
                    {
                        continue;
                    }
                    match others.iter_mut().find(|(m, _)| m == n) {
                        Some((_, c)) => *c += 1,
                        None => others.push((n.clone(), 1)),
                    }
                }
            }
            let others = if others.is_empty() {
                "–".to_string()
            } else {
                others
                    .iter()
                    .map(|(n, c)| format!("`{n}` {c}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            };
            let right = right_factor(family);
            s += &format!(
                "| `{family}` | {} | {} | `{}` {} | {} | {} | {} | {others} | {} |\n",
                if multi { "several" } else { "one" },
                group.len(),
                right.name(),
                named(right),
                named(Effect::Anisotropy),
                group.iter().filter(|o| o.anisotropy_refused > 0).count(),
                named(Effect::RetroLobe),
                rate(group.iter().filter(|o| o.false_effect).count(), group.len())
            );
        }
    }
    let anis = cases
        .iter()
        .filter(|o| o.named.iter().any(|n| n == Effect::Anisotropy.name()))
        .count();
    let right = cases
        .iter()
        .filter(|o| {
            let family = o.case.misspecified.as_deref().unwrap_or_default();
            o.named.iter().any(|n| n == right_factor(family).name())
        })
        .count();
    s += &format!(
        "\nThe truth's own factor named on {right} of {}. Anisotropy named on {} of {} isotropic truths; false effects on {} (any analytic effect but a second specular lobe or, on transmission, another NDF family for the lobe (`long_tail`); the data-driven factors are not false here). Anisotropy refused: cases where a significant, identifiable `+aniso` candidate was refused because its surface-fixed frame did no better than an isotropic lobe of the same shape (at one incidence azimuth: did not break the mirror symmetry about the plane of incidence).\n",
        cases.len(),
        anis,
        cases.len(),
        rate(cases.iter().filter(|o| o.false_effect).count(), cases.len())
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// Every NDF is normalised (∫ D cos θm dω = 1), and its tabulated Λ vanishes at the
    /// normal and grows towards grazing.
    #[test]
    fn distributions_are_normalised_and_lambda_vanishes_at_the_normal() {
        let ndfs = [
            Ndf::Beckmann(0.2),
            Ndf::Ggx(0.1),
            Ndf::Gtr {
                alpha: 0.15,
                gamma: 1.5,
            },
            Ndf::Gtr {
                alpha: 0.2,
                gamma: 3.0,
            },
            Ndf::TwoScale {
                a1: 0.05,
                a2: 0.3,
                w: 0.5,
            },
            Ndf::Student {
                alpha: 0.1,
                gamma: 1.6,
            },
            Ndf::Student {
                alpha: 0.3,
                gamma: 6.0,
            },
        ];
        for ndf in ndfs {
            let n = 20_000;
            let dt = (PI / 2.0) / n as f64;
            let norm: f64 = (0..n)
                .map(|i| {
                    let th = (i as f64 + 0.5) * dt;
                    ndf.d(th.cos()) * th.cos() * th.sin() * dt * 2.0 * PI
                })
                .sum();
            assert!((norm - 1.0).abs() < 2e-3, "{ndf:?}: ∫ D cos = {norm}");
            let lambda = smith_lambda(&ndf);
            assert!(
                lookup(&lambda, 1.0) < 2e-3,
                "{ndf:?}: Λ(normal) = {}",
                lambda[255]
            );
            // Λ grows towards grazing.
            assert!(lambda.windows(2).all(|w| w[0] >= w[1] - 1e-9), "{ndf:?}");
        }
    }

    /// Beckmann's Λ has a closed form (Walter et al. 2007, Eq. 27, exact with erf):
    /// Λ(a) = (erf(a) − 1)/2 + e^(−a²)/(2a√π), a = 1/(α tan θ). The numerical table
    /// agrees with it to 1 %.
    #[test]
    fn the_tabulated_lambda_matches_beckmanns_closed_form() {
        let alpha = 0.3;
        let table = smith_lambda(&Ndf::Beckmann(alpha));
        for mu in [0.2, 0.4, 0.6, 0.8] {
            let tan = (1.0f64 - mu * mu).sqrt() / mu;
            let a = 1.0 / (alpha * tan);
            // erf by Simpson's rule on 2/√π e^(−t²).
            let n = 2000;
            let h = a / n as f64;
            let f = |t: f64| (-t * t).exp();
            let simpson: f64 = (0..=n)
                .map(|i| {
                    let w = if i == 0 || i == n {
                        1.0
                    } else if i % 2 == 1 {
                        4.0
                    } else {
                        2.0
                    };
                    w * f(i as f64 * h)
                })
                .sum::<f64>()
                * h
                / 3.0;
            let erf = 2.0 / PI.sqrt() * simpson;
            let exact = (erf - 1.0) / 2.0 + (-a * a).exp() / (2.0 * a * PI.sqrt());
            let got = lookup(&table, mu);
            assert!(
                (got - exact).abs() <= 0.01 * exact.max(1e-3),
                "μ {mu}: {got} vs {exact}"
            );
        }
    }

    #[test]
    fn every_family_draws_and_measures() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for family in FAMILIES.into_iter().chain(BTDF_FAMILIES) {
            let t = Truth::draw(family, 3, &mut rng);
            assert_eq!(t.family, family);
            let d = measure(&t, &[20.0], 600, (0.02, 1e-4), &mut rng).unwrap();
            let channels = if t.kind == Kind::Btdf { 1 } else { 3 };
            assert!(d.len() >= 150 * channels && d.samples.iter().all(|s| s.value.is_finite()));
            assert_eq!(d.kind, t.kind);
            assert_eq!(d.azimuth_coverage().one_azimuth(), Some(20.0));
            if t.kind == Kind::Btdf {
                // The transmitted lobe is there, and where Snell puts it: the brightest
                // sample lies within 8° of the refracted direction, far above the floor.
                let top = d
                    .samples
                    .iter()
                    .max_by(|a, b| a.value.total_cmp(&b.value))
                    .expect("samples");
                let peak = t.peak_theta(top.theta_i.to_degrees());
                assert!(
                    top.transmitted
                        && (top.theta_o.to_degrees() - peak).abs() < 8.0
                        && top.value > 100.0 * 1e-4,
                    "{family}: brightest {top:?}, refracted θ {peak:.1}°"
                );
            }
        }
    }

    #[test]
    fn only_a_lobe_reshaped_or_a_data_driven_factor_is_a_right_name() {
        use Effect::*;
        for right in [
            vec![],
            vec![SpecularLobe, HighlightShape],
            vec![LongTail, BodyProfile],
        ] {
            assert!(!names_a_false_effect(&right), "{right:?}");
        }
        for wrong in [
            Anisotropy,
            Absorption,
            Scale,
            DiffuseFloor,
            Backscatter,
            RetroLobe,
        ] {
            assert!(names_a_false_effect(&[LongTail, wrong]), "{wrong:?}");
        }
    }

    /// Student-t's limits are the catalogue's: γ = 2 is GGX, a large γ is Beckmann.
    #[test]
    fn student_t_is_ggx_at_two_and_beckmann_in_the_limit() {
        for c in [0.99, 0.9, 0.7, 0.5] {
            let ggx = Ndf::Ggx(0.2).d(c);
            let st = Ndf::Student {
                alpha: 0.2,
                gamma: 2.0,
            }
            .d(c);
            assert!((st / ggx - 1.0).abs() < 1e-12, "c {c}: {st} vs {ggx}");
            let b = Ndf::Beckmann(0.2).d(c);
            // (1 + x/γ)^(−γ) = e^(−x) (1 + x²/(2γ) + …): 3e-5 at x = 75 (c = 0.5); the
            // base's rounding, raised to γ, adds γ·1e-16.
            let st = Ndf::Student {
                alpha: 0.2,
                gamma: 1e8,
            }
            .d(c);
            assert!((st / b - 1.0).abs() < 1e-3, "c {c}: {st} vs {b}");
        }
    }

    /// The transmission truth conserves energy and is the BTDF a rough interface gives:
    /// its albedo Σ f |cos θo| dω at normal incidence is at most 1 − F(0) and, for a
    /// smooth-ish lobe, within a few per cent of it (little masking at α ≈ 0.05), and it
    /// peaks on the refracted direction.
    #[test]
    fn the_transmission_truth_conserves_energy_and_peaks_where_snell_says() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let truth = Truth {
            ndf: Ndf::Student {
                alpha: 0.05,
                gamma: 3.0,
            },
            lambda: Some(smith_lambda(&Ndf::Student {
                alpha: 0.05,
                gamma: 3.0,
            })),
            ..Truth::draw("btdf-student-ndf", 1, &mut rng)
        };
        let Fresnel::Exact(eta) = truth.fresnel else {
            panic!("exact Fresnel")
        };
        let wi = direction(0.0, 0.0);
        let nt = 4000;
        let dt = (PI / 2.0) / nt as f64;
        let mut albedo = 0.0;
        for i in 0..nt {
            let th = (i as f64 + 0.5) * dt;
            let mut wo = direction(th.to_degrees(), 0.0);
            wo.z = -wo.z;
            albedo += truth.transmission(wi, wo) * th.cos() * th.sin() * dt * 2.0 * PI;
        }
        let t0 = (1.0 - truth.fresnel.at(1.0)) / (eta * eta);
        assert!(
            albedo <= t0 * 1.001 && albedo > 0.95 * t0,
            "albedo {albedo}, (1 − F)/η² {t0}"
        );
        let ti = 40.0;
        let peak = truth.peak_theta(ti);
        assert!((peak - (ti.to_radians().sin() / eta).asin().to_degrees()).abs() < 1e-9);
        let at = |t: f64| {
            let mut wo = direction(t, 180.0);
            wo.z = -wo.z;
            truth.transmission(direction(ti, 0.0), wo)
        };
        assert!(at(peak) > at(peak + 3.0) && at(peak) > at(peak - 3.0));
    }
}
