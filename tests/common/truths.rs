//! Truths written from textbook formulas, not through the library's models: isotropic
//! Cook–Torrance lobes with any normal distribution D, their Smith Λ integrated
//! numerically from the same D, exact dielectric Fresnel, over a Lambertian body; and a
//! goniometer that measures them with stated noise.

use bsdfit::data::{Dataset, Kind, RawRow, ReadOptions};
use glam::DVec3;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use std::f64::consts::PI;

pub const RHO: f64 = 0.25;
pub const ETA: f64 = 1.5;

pub fn dir(theta_deg: f64, phi_deg: f64) -> DVec3 {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
}

/// Unpolarised Fresnel reflectance of a dielectric of index `ETA`.
pub fn fresnel(c: f64) -> f64 {
    let t = (1.0 - (1.0 - c * c) / (ETA * ETA)).max(0.0).sqrt();
    let rs = (c - ETA * t) / (c + ETA * t);
    let rp = (ETA * c - t) / (ETA * c + t);
    0.5 * (rs * rs + rp * rp)
}

pub fn beckmann(c: f64, a: f64) -> f64 {
    let c2 = c * c;
    (-(1.0 - c2) / (c2 * a * a)).exp() / (PI * a * a * c2 * c2)
}

/// Burley's GTR with exponent γ, normalised: ∫ D cos θm dω = 1.
/// GGX (Trowbridge–Reitz): α² / (π cos⁴θ (α² + tan²θ)²).
pub fn ggx(c: f64, a: f64) -> f64 {
    let (a2, c2) = (a * a, c * c);
    let t = a2 * c2 + (1.0 - c2);
    a2 / (PI * t * t)
}

/// Unpolarised Fresnel reflectance of a conductor of complex index n + iκ (from the
/// amplitude coefficients of s and p polarisation; e.g. Born & Wolf §14.2).
pub fn conductor_fresnel(c: f64, n: f64, kappa: f64) -> f64 {
    let (c2, s2) = (c * c, 1.0 - c * c);
    let t0 = n * n - kappa * kappa - s2;
    let a2b2 = (t0 * t0 + 4.0 * n * n * kappa * kappa).sqrt();
    let a = (0.5 * (a2b2 + t0)).max(0.0).sqrt();
    let (t1, t2) = (a2b2 + c2, 2.0 * a * c);
    let rs = (t1 - t2) / (t1 + t2);
    let (t3, t4) = (c2 * a2b2 + s2 * s2, t2 * s2);
    let rp = rs * (t3 - t4) / (t3 + t4);
    0.5 * (rs + rp)
}

pub fn gtr(c: f64, a: f64, g: f64) -> f64 {
    let a2 = a * a;
    let k = (g - 1.0) * (a2 - 1.0) / (PI * (1.0 - a2.powf(1.0 - g)));
    k / (1.0 + (a2 - 1.0) * c * c).powf(g)
}

/// An isotropic normal distribution D(cos θm).
pub type Ndf = fn(f64) -> f64;

/// An isotropic microfacet lobe D(cos θm) with its Smith Λ tabulated from D itself:
/// 1 + Λ(ω) = (1/cos θ) ∫ ⟨ω·m⟩ D(m) dm over the hemisphere of normals.
pub struct Isotropic {
    pub d: Ndf,
    lambda: Vec<f64>,
}

const TABLE: usize = 256;

impl Isotropic {
    pub fn new(d: Ndf) -> Isotropic {
        let (nt, np) = (400, 96);
        let lambda = (0..TABLE)
            .map(|k| {
                let mu = (k as f64 + 0.5) / TABLE as f64;
                let so = (1.0 - mu * mu).sqrt();
                let mut sum = 0.0;
                for i in 0..nt {
                    let th = (i as f64 + 0.5) * (PI / 2.0) / nt as f64;
                    let (st, ct) = th.sin_cos();
                    let w = d(ct) * st * (PI / 2.0) / nt as f64;
                    for j in 0..np {
                        let ph = (j as f64 + 0.5) * 2.0 * PI / np as f64;
                        let dot = st * ph.cos() * so + ct * mu;
                        if dot > 0.0 {
                            sum += dot * w * 2.0 * PI / np as f64;
                        }
                    }
                }
                sum / mu - 1.0
            })
            .collect();
        Isotropic { d, lambda }
    }

    pub fn g1(&self, mu: f64) -> f64 {
        let x = (mu * TABLE as f64 - 0.5).clamp(0.0, (TABLE - 1) as f64);
        let k = (x as usize).min(TABLE - 2);
        let t = x - k as f64;
        1.0 / (1.0 + self.lambda[k] * (1.0 - t) + self.lambda[k + 1] * t)
    }

    /// The lobe over a Lambertian body of albedo `RHO`.
    pub fn brdf(&self, wi: DVec3, wo: DVec3) -> f64 {
        RHO / PI + self.specular(wi, wo)
    }

    /// The lobe F D G1 G1 / (4 μi μo) alone.
    pub fn specular(&self, wi: DVec3, wo: DVec3) -> f64 {
        self.specular_with(fresnel, wi, wo)
    }

    /// The lobe with another Fresnel curve `f(cos θd)`.
    pub fn specular_with(&self, f: impl Fn(f64) -> f64, wi: DVec3, wo: DVec3) -> f64 {
        let h = (wi + wo).normalize();
        f(wi.dot(h)) * (self.d)(h.z) * self.g1(wi.z) * self.g1(wo.z) / (4.0 * wi.z * wo.z)
    }

    /// The lobe over the body seen through the same interface (a Fresnel aggregate):
    /// spec + (1 − F(μi)) (1 − F(μo)) RHO/π.
    pub fn aggregate(&self, wi: DVec3, wo: DVec3) -> f64 {
        self.specular(wi, wo) + (1.0 - fresnel(wi.z)) * (1.0 - fresnel(wo.z)) * RHO / PI
    }
}

impl Isotropic {
    /// The lobe as a rough dielectric interface's transmission (Walter et al. 2007, Eqs. 16
    /// and 21, air above, index `ETA` below, without the η² radiance factor):
    /// |i·m| |o·m| (1 − F(i·m)) G1(i) G1(o) D(m) / (|μi| |μo| (i·m + η o·m)²),
    /// m = −(ωi + η ωo)/‖·‖ turned above the surface; ωi above, ωo below.
    pub fn transmission(&self, wi: DVec3, wo: DVec3) -> f64 {
        if wi.z <= 0.0 || wo.z >= 0.0 {
            return 0.0;
        }
        let mut m = -(wi + ETA * wo).normalize();
        if m.z < 0.0 {
            m = -m;
        }
        let (im, om) = (wi.dot(m), wo.dot(m));
        if im <= 0.0 || om >= 0.0 {
            return 0.0;
        }
        let denom = im + ETA * om;
        im * om.abs() * (1.0 - fresnel(im)) * self.g1(wi.z) * self.g1(-wo.z) * (self.d)(m.z)
            / (wi.z * wo.z.abs() * denom * denom)
    }
}

/// A transmission goniometer: θi 0, 20, 40, 60° at φi = 0, the transmitted θo 0…85° by
/// 5° at φo every 15° (φo = 180° holds the refracted ray), values of `f` with 1 % noise
/// and a floor of 1e-3 sr⁻¹, stated as the uncertainty.
pub fn measure_btdf(f: &dyn Fn(DVec3, DVec3) -> f64, seed: u64) -> Dataset {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, 1.0).unwrap();
    let mut raw = Vec::new();
    for ti in [0.0, 20.0, 40.0, 60.0] {
        for k in 0..18 {
            let to = 5.0 * k as f64;
            for j in 0..24 {
                let po = 15.0 * j as f64;
                let o = dir(to, po);
                let v = f(dir(ti, 0.0), DVec3::new(o.x, o.y, -o.z));
                let u = ((0.01 * v).powi(2) + 1e-6).sqrt();
                // Clipped at 3σ: the reader refuses values negative beyond that.
                let n: f64 = normal.sample(&mut rng);
                let row = RawRow {
                    theta_i: ti,
                    phi_i: 0.0,
                    theta_o: to,
                    phi_o: po,
                    wavelength_nm: 550.0,
                    value: v + u * n.clamp(-3.0, 3.0),
                    uncertainty: u,
                };
                raw.push((raw.len() + 1, row));
            }
        }
    }
    Dataset::from_rows(Kind::Btdf, "truth", &raw, "<test>", &ReadOptions::default()).unwrap()
}

/// A goniometer at the incidence azimuths `phi_i`: θi 10…70°, θo 5…80° by 7.5°, φo every
/// 20° about the plane of incidence, the source direction left out; values of `f` with
/// 1 % noise and a floor of 3e-4 sr⁻¹, stated as the uncertainty.
pub fn measure(phi_i: &[f64], f: &dyn Fn(DVec3, DVec3) -> f64, seed: u64) -> Dataset {
    measure_channels(phi_i, &[550.0], &|_, wi, wo| f(wi, wo), seed)
}

/// [`measure`] at several wavelengths: `f(channel, ωi, ωo)`, channel c at `wavelengths[c]`.
pub fn measure_channels(
    phi_i: &[f64],
    wavelengths: &[f64],
    f: &dyn Fn(usize, DVec3, DVec3) -> f64,
    seed: u64,
) -> Dataset {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let normal = Normal::new(0.0, 1.0).unwrap();
    let mut raw = Vec::new();
    for &pi in phi_i {
        for ti in [10.0, 25.0, 40.0, 55.0, 70.0] {
            for k in 0..11 {
                let to = 5.0 + 7.5 * k as f64;
                for j in 0..18 {
                    if j == 0 && (to - ti).abs() < 3.0 {
                        continue;
                    }
                    let po = pi + 20.0 * j as f64;
                    for (c, &nm) in wavelengths.iter().enumerate() {
                        let v = f(c, dir(ti, pi), dir(to, po));
                        let u = ((0.01 * v).powi(2) + 1e-7).sqrt();
                        let row = RawRow {
                            theta_i: ti,
                            phi_i: pi,
                            theta_o: to,
                            phi_o: po,
                            wavelength_nm: nm,
                            value: v + u * normal.sample(&mut rng),
                            uncertainty: u,
                        };
                        raw.push((raw.len() + 1, row));
                    }
                }
            }
        }
    }
    Dataset::from_rows(Kind::Brdf, "truth", &raw, "<test>", &ReadOptions::default()).unwrap()
}

/// A χ² fit of `model` to truth data on the SIMD engine, from `start` (an embedded
/// optimum of a smaller model, as diagnose starts an extension) where given, with
/// `restarts` restarts in all; the smoothness prior of any knots weighed from the data.
/// Levenberg–Marquardt, what `bsdfit fit` and `diagnose` use for χ² (compass search, the
/// library's default, stops the joint fits of many knots short of their optimum:
/// docs/models.md).
pub fn fit_truth(
    model: &bsdfit::bsdf::Model,
    data: &Dataset,
    start: Option<Vec<f64>>,
    restarts: usize,
    seed: u64,
) -> bsdfit::inference::fit::Conclusions {
    let lm = bsdfit::inference::fit::Optimizer::Lm;
    fit_truth_with(model, data, start, restarts, seed, lm)
}

/// [`fit_truth`] with the optimizer given.
pub fn fit_truth_with(
    model: &bsdfit::bsdf::Model,
    data: &Dataset,
    start: Option<Vec<f64>>,
    restarts: usize,
    seed: u64,
    optimizer: bsdfit::inference::fit::Optimizer,
) -> bsdfit::inference::fit::Conclusions {
    use bsdfit::engine::loss::{Loss, Metric, Weights};
    let opts = bsdfit::inference::fit::FitOptions {
        restarts,
        seed,
        optimizer,
        initial_points: start.into_iter().collect(),
        ..Default::default()
    };
    let loss = Loss::new(Metric::Chi2, Weights::Uniform);
    let backend = bsdfit::engine::simd::SimdBackend::new();
    bsdfit::inference::fit::fit_outcome(model, data, loss, &backend, &opts, &mut |_| {}).unwrap()
}

/// χ²/ν of a fit.
pub fn chi2_red(c: &bsdfit::inference::fit::Conclusions) -> f64 {
    c.chi2 / c.dof as f64
}

/// One measured knot held against the truth: where, and by how many of its σ the fitted
/// ln D lies from the truth's, |ln(D / D_truth)| / σ.
pub struct KnotMiss {
    pub label: String,
    pub z: f64,
}

/// Checks a fitted NDF's knots (`bsdfit::inference::knots::bands`, one lobe) against the
/// truth's D: each row printed, finite, marked measured exactly where its signal reaches
/// `MEASURED_SIGNAL` and its data share `MEASURED_SHARE`. Returns each measured knot with
/// its z, for [`assert_bands_cover`] to judge together with the test's other knots.
pub fn check_knots(
    name: &str,
    rows: &[bsdfit::inference::knots::KnotBand],
    d: Ndf,
) -> Vec<KnotMiss> {
    let mut held = Vec::new();
    for knot in rows {
        let truth = d(knot.theta_deg.to_radians().cos());
        let sigma = knot.sigma_ln_d.expect("a band with the prior on");
        let diff = (knot.d / truth).ln();
        eprintln!(
            "  {:>5.2}°: D {:.4e} (truth {truth:.4e}) ln ratio {diff:+.4} σ {sigma:.4} signal {:.1} share {:.2?}",
            knot.theta_deg, knot.d, knot.signal, knot.data_share
        );
        assert!(knot.d.is_finite() && knot.d >= 0.0 && sigma.is_finite());
        assert_eq!(
            knot.measured,
            bsdfit::inference::knots::is_measured(knot.signal, knot.data_share)
        );
        if knot.measured {
            held.push(KnotMiss {
                label: format!(
                    "{name} at {:.2}°: ln D {diff:+.4} from the truth, σ {sigma:.4}",
                    knot.theta_deg
                ),
                z: diff.abs() / sigma,
            });
        }
    }
    held
}

/// The bound n standard normal deviates stay within together with probability 95 %
/// (Bonferroni: P(|Z| > z) = 0.05 / n), or 3 where that is larger (n ≤ 18).
pub fn family_bound(n: usize) -> f64 {
    let tail = |z: f64| bsdfit::math::special::chi2_sf(z * z, 1.0);
    let target = 0.05 / n.max(1) as f64;
    let (mut lo, mut hi) = (3.0, 10.0);
    if tail(lo) <= target {
        return lo;
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if tail(mid) > target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi
}

/// Every knot of `held` (all the measured knots a test checked, over all its truths)
/// within [`family_bound`] of the truth. Why not 3σ each: a test holds 25 knots of each
/// of three truths at 32 knots, and 75 correct bands all within 3σ happens with
/// probability 0.82; the family-wise bound keeps a test's false alarms at 5 %.
pub fn assert_bands_cover(held: &[KnotMiss]) {
    let bound = family_bound(held.len());
    let misses: Vec<&str> = held
        .iter()
        .filter(|k| k.z > bound)
        .map(|k| k.label.as_str())
        .collect();
    eprintln!("{} knots held, family-wise bound {bound:.2}σ", held.len());
    assert!(
        misses.is_empty(),
        "beyond {bound:.2}σ: {}",
        misses.join("; ")
    );
}

/// `diagnose` of truth data from `start` on the SIMD engine (seed 2, 8 restarts, the
/// library's other defaults), its log and then its time, final model and effects on
/// stderr under `name`.
pub fn diagnose_truth(
    name: &str,
    data: &Dataset,
    start: &str,
) -> bsdfit::workflows::diagnose::Diagnosis {
    use bsdfit::workflows::diagnose::{diagnose, DiagnoseOptions};
    let opts = DiagnoseOptions {
        seed: 2,
        restarts: 8,
        ..Default::default()
    };
    let t0 = std::time::Instant::now();
    let backend = bsdfit::engine::simd::SimdBackend::new();
    let d = diagnose(data, start, &backend, &opts, &mut |l| eprintln!("{l}")).unwrap();
    eprintln!(
        "{name}: diagnose {:.1} s, {} → {:?}",
        t0.elapsed().as_secs_f64(),
        d.final_model,
        d.effects
    );
    d
}
