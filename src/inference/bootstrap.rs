//! Extension tests calibrated by a parametric bootstrap.
//!
//! The F test of a nested extension assumes the regular case: the null model is the
//! extension at an interior point of its parameter space, where every parameter is
//! identified. Many extensions of the catalogue break it. Their null sits on a bound
//! (σ = 0 in `on`, k_s = 0 in `fa(B)`, k_r = 0 in `+retro`, β at its floor in `dmg`),
//! where the statistic follows a mixture that puts mass at 0 (Self & Liang 1987: the
//! nominal p-value is too large), or some of the extension's parameters vanish from the
//! model at the null (the lobe's α and η when k_s = 0), where the fit maximises over them
//! and the nominal p-value is too small (Davies 1987).
//!
//! The bootstrap draws B replicate data sets from the fitted null model with the stated
//! uncertainties (y*_k = y′_k + u_k z_k), refits the null and the extension to each (all
//! replicates in lockstep, [`fit_many`]), and compares the observed statistic
//! T = ΔP·F = Δχ² / (χ²₁/ν₁) with the replicates' T*_b (Davison & Hinkley 1997, §4.2):
//!
//! - where any replicate reaches T, the p-value is the empirical
//!   (1 + #{T*_b ≥ T}) / (B + 1), valid for any B (the observed data and the replicates are
//!   exchangeable under the null);
//! - where none does, the count only says p ≤ 1/(B + 1), and the p-value comes from a tail
//!   fitted to the replicates, capped at that bound: π · P(χ²_ν ≥ T/a), π the share of
//!   replicates with T*_b > 0 (the mass at 0 of a null on a bound), a·χ²_ν matched to the
//!   mean and variance of the positive T*_b (Satterthwaite's approximation, which the
//!   Self–Liang mixtures and the Davies sup statistics both follow in their tails to good
//!   accuracy). A test at a level below 1/(B + 1) thus rejects only when T exceeds every
//!   replicate, which happens with probability 1/(B + 1) under the null, and the tail
//!   decides within that: the fitted tail cannot make the test reject more often than
//!   the count allows. (A tail fitted to ~50 positive replicates is a noisy estimate;
//!   used wherever fewer than ten replicates reach T it rejected 2.8 % of null data sets
//!   at α = 0.01 in `tests/bootstrap.rs`.)
//!
//! The observed T is computed by the same procedure as the replicates' (the measured data
//! is refitted alongside them, as replicate 0): a statistic computed by one optimizer
//! setting and referred to a distribution computed by another is not calibrated — e.g.
//! at `on`'s null σ = 0 the gradient in σ vanishes, so a fit started there stays there
//! unless a random start finds the σ > 0 optimum, and more restarts on one side than the
//! other shift the whole distribution. Every extension refit starts from the data set's
//! own null optimum carried into the extension (so Δχ² ≥ 0), from the extension's optimum
//! on the measured data (found by the thorough fit: without it, a few restarts may miss a
//! many-parameter extension's optimum on the measured data and lose the test's power),
//! and from screened random starts.

use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::{Loss, Metric, Weights};
use crate::engine::Backend;
use crate::inference::fit::{fit_many, FitOptions, Optimizer};
use crate::inference::mc::ReplicaSource;
use crate::math::chi2_sf;
use serde::Serialize;
use std::time::Instant;

/// Replicate statistics at or below this count as 0 (a nested extension that did not move
/// off its null, up to the optimizer's tolerance).
const ZERO: f64 = 1e-3;
/// Positive replicates needed to fit the tail.
const MIN_POSITIVE: usize = 10;

/// How the bootstrap runs.
#[derive(Clone, Debug)]
pub struct BootstrapOptions {
    /// Replicates B (0: no bootstrap).
    pub replicates: usize,
    /// Random restarts per replicate fit, besides the carried-over optima.
    pub restarts: usize,
    pub seed: u64,
}

impl Default for BootstrapOptions {
    fn default() -> Self {
        BootstrapOptions {
            replicates: 99,
            restarts: 2,
            seed: 1,
        }
    }
}

/// Where a calibrated p-value came from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PSource {
    /// (1 + #{T*_b ≥ T}) / (B + 1).
    Empirical,
    /// π · P(χ²_ν ≥ T/a) fitted to the replicates.
    Tail,
    /// Too few positive replicates to fit a tail: the empirical bound 1/(B + 1) (or more).
    EmpiricalBound,
}

/// A bootstrap-calibrated p-value and what it rests on.
#[derive(Clone, Debug, Serialize)]
pub struct Calibrated {
    pub p: f64,
    pub source: PSource,
    /// The observed statistic T = Δχ² / (χ²₁/ν₁), from the measured data refitted by the
    /// replicates' procedure.
    pub statistic: f64,
    /// Replicates drawn and those whose two fits both ended finite (the counts use these).
    pub replicates: usize,
    pub fitted: usize,
    /// Replicates with T*_b ≥ T.
    pub exceeding: usize,
    /// Share π of replicates with T*_b > 0, and the fitted tail a·χ²_ν (None when not
    /// fitted).
    pub positive_share: f64,
    pub tail: Option<(f64, f64)>,
    pub seconds: f64,
    /// Model-sample evaluations of the refits (null and extension).
    pub evaluations: u64,
}

impl Calibrated {
    /// "bootstrap, 99 replicates, 3 reach T" / "bootstrap tail (π = 0.52, 1.3·χ²_2.1)".
    pub fn describe(&self) -> String {
        match (self.source, self.tail) {
            (PSource::Tail, Some((a, nu))) => format!(
                "bootstrap: {} of {} replicates reach T = {:.4}; tail {:.2}·{:.3}·χ²_{:.2} fitted to them",
                self.exceeding, self.fitted, self.statistic, self.positive_share, a, nu
            ),
            (PSource::EmpiricalBound, _) => format!(
                "bootstrap: {} of {} replicates reach T = {:.4}, too few positive to fit a tail (p is a bound)",
                self.exceeding, self.fitted, self.statistic
            ),
            _ => format!(
                "bootstrap: {} of {} replicates reach T = {:.4}",
                self.exceeding, self.fitted, self.statistic
            ),
        }
    }
}

/// T = Δχ² / (χ²₁/ν₁), Δχ² = χ²₀ − χ²₁ clipped at 0 (ΔP times the F statistic).
/// Values at or below [`ZERO`] are 0: the rounding of an extension fit that stayed at its
/// null must not count as an improvement, on the measured data or on a replicate.
pub fn statistic(chi2_null: f64, chi2_ext: f64, dof_ext: usize) -> f64 {
    let t = (chi2_null - chi2_ext).max(0.0) / (chi2_ext / dof_ext.max(1) as f64);
    if t > ZERO {
        t
    } else {
        0.0
    }
}

/// The p-value of `t` against the replicate statistics `reps` (module doc): the p-value,
/// its source, the share π of positive replicates and the fitted tail (a, ν).
pub fn p_value(t: f64, reps: &[f64]) -> (f64, PSource, f64, Option<(f64, f64)>) {
    let b = reps.len();
    let exceeding = reps.iter().filter(|&&r| r >= t).count();
    let empirical = (1 + exceeding) as f64 / (b + 1) as f64;
    let positive: Vec<f64> = reps.iter().copied().filter(|&r| r > ZERO).collect();
    let share = positive.len() as f64 / b.max(1) as f64;
    if exceeding > 0 {
        return (empirical, PSource::Empirical, share, None);
    }
    if positive.len() < MIN_POSITIVE {
        return (empirical, PSource::EmpiricalBound, share, None);
    }
    let n = positive.len() as f64;
    let mean = positive.iter().sum::<f64>() / n;
    let var = positive.iter().map(|r| (r - mean).powi(2)).sum::<f64>() / (n - 1.0);
    if var <= 0.0 || mean <= 0.0 {
        return (empirical, PSource::EmpiricalBound, share, None);
    }
    // a·χ²_ν has mean aν and variance 2a²ν.
    let a = var / (2.0 * mean);
    let nu = 2.0 * mean * mean / var;
    let tail = (share * chi2_sf(t / a, nu)).min(empirical);
    (tail, PSource::Tail, share, Some((a, nu)))
}

/// Replicate data sets drawn from a fitted model's values with the stated uncertainties.
pub fn null_replicates(data: &Dataset, values: &[f64], count: usize, seed: u64) -> Vec<Dataset> {
    let mut fitted = data.clone();
    for (s, &v) in fitted.samples.iter_mut().zip(values) {
        s.value = v;
    }
    ReplicaSource::new(&fitted, chi2(), 0.0, seed).draw(count)
}

fn chi2() -> Loss {
    Loss::new(Metric::Chi2, Weights::Uniform)
}

/// The null model refitted to the measured data (index 0) and to each replicate: the
/// optima (physical) and χ² (non-finite where a fit failed).
pub struct NullRefits {
    pub replicates: Vec<Dataset>,
    pub flat: Vec<Vec<f64>>,
    pub chi2: Vec<f64>,
    pub seconds: f64,
    pub evaluations: u64,
}

/// Refits of replicates: Levenberg–Marquardt on χ², stopped once a step gains less than
/// 1e-7 of χ² (T needs χ² to ~1e-3 absolute, and replicate fits start next to their
/// optimum; the 1e-10 of a reported fit would only make the unidentified parameters of
/// an irregular null crawl along their flat valley).
fn replicate_options(base: &FitOptions, boot: &BootstrapOptions) -> FitOptions {
    FitOptions {
        optimizer: Optimizer::Lm,
        restarts: boot.restarts.max(1),
        seed: boot.seed ^ 0x5eed_b007,
        lm: crate::optim::lm::LmOptions {
            ftol: 1e-7,
            max_iterations: 100,
            ..base.lm.clone()
        },
        ..base.clone()
    }
}

/// χ² fits of `model` to every data set, in lockstep.
fn refit(
    model: &Model,
    datas: &[Dataset],
    backend: &dyn Backend,
    opts: &FitOptions,
) -> anyhow::Result<(
    Vec<crate::inference::fit::Optimum>,
    crate::inference::fit::ManyStats,
)> {
    let refs: Vec<&Dataset> = datas.iter().collect();
    let losses = vec![chi2(); refs.len()];
    let (optima, _, stats) = fit_many(model, &refs, &losses, backend, opts, &mut |_| {})?;
    Ok((optima, stats))
}

/// Draw the replicates from the null fit (`null_flat`, its model values `null_values`) and
/// refit the null to each, all in lockstep.
pub fn refit_null(
    null: &Model,
    null_flat: &[f64],
    null_values: &[f64],
    data: &Dataset,
    backend: &dyn Backend,
    base: &FitOptions,
    boot: &BootstrapOptions,
) -> anyhow::Result<NullRefits> {
    anyhow::ensure!(
        boot.replicates >= 1,
        "the bootstrap needs at least 1 replicate"
    );
    let t0 = Instant::now();
    let mut replicates = vec![data.clone()];
    replicates.extend(null_replicates(
        data,
        null_values,
        boot.replicates,
        boot.seed,
    ));
    let opts = FitOptions {
        initial_points: vec![null_flat.to_vec()],
        problem_points: vec![],
        ..replicate_options(base, boot)
    };
    let (optima, stats) = refit(null, &replicates, backend, &opts)?;
    Ok(NullRefits {
        replicates,
        flat: optima.iter().map(|o| o.flat.clone()).collect(),
        chi2: optima.iter().map(|o| o.loss).collect(),
        seconds: t0.elapsed().as_secs_f64(),
        evaluations: stats.evaluations,
    })
}

/// The calibrated p-value of extending the null of `nulls` to `ext` (`dof_ext` = K − P of
/// the extension): `ext` refitted to the measured data and to each replicate, T of the
/// measured data against the replicates' (module doc). `embed` carries a null optimum
/// into the extension's parameters; `ext_flat`, the extension's optimum on the measured
/// data, is one more start of every refit.
#[allow(clippy::too_many_arguments)]
pub fn calibrate(
    ext: &Model,
    ext_flat: &[f64],
    embed: &dyn Fn(&[f64]) -> Vec<f64>,
    nulls: &NullRefits,
    dof_ext: usize,
    backend: &dyn Backend,
    base: &FitOptions,
    boot: &BootstrapOptions,
) -> anyhow::Result<Calibrated> {
    let t0 = Instant::now();
    let opts = FitOptions {
        initial_points: vec![ext_flat.to_vec()],
        problem_points: nulls.flat.iter().map(|f| embed(f)).collect(),
        ..replicate_options(base, boot)
    };
    let (optima, stats) = refit(ext, &nulls.replicates, backend, &opts)?;
    anyhow::ensure!(
        optima[0].loss.is_finite() && nulls.chi2[0].is_finite(),
        "refitting {} or its null to the measured data ended non-finite",
        ext.spec
    );
    let observed = statistic(nulls.chi2[0], optima[0].loss, dof_ext);
    let reps: Vec<f64> = optima[1..]
        .iter()
        .zip(&nulls.chi2[1..])
        .filter(|(o, c0)| o.loss.is_finite() && c0.is_finite())
        .map(|(o, &c0)| statistic(c0, o.loss, dof_ext))
        .collect();
    anyhow::ensure!(
        !reps.is_empty(),
        "no bootstrap replicate of {} could be fitted",
        ext.spec
    );
    let (p, source, positive_share, tail) = p_value(observed, &reps);
    Ok(Calibrated {
        p,
        source,
        statistic: observed,
        replicates: nulls.replicates.len() - 1,
        fitted: reps.len(),
        exceeding: reps.iter().filter(|&&r| r >= observed).count(),
        positive_share,
        tail,
        seconds: t0.elapsed().as_secs_f64() + nulls.seconds,
        evaluations: stats.evaluations + nulls.evaluations,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;
    use rand_distr::{Distribution, Normal};

    /// Draws of ½χ²₀ + ½χ²₁ (the statistic of one parameter on a bound): beyond every
    /// replicate the fitted tail must give the exact ½·P(χ²₁ ≥ t), within the sampling
    /// error of 2,000 replicates' moments; inside their range the count gives it.
    #[test]
    fn tail_of_a_boundary_mixture() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let n = Normal::new(0.0, 1.0).unwrap();
        let reps: Vec<f64> = (0..2000)
            .map(|_| {
                let z: f64 = n.sample(&mut rng);
                z.max(0.0).powi(2)
            })
            .collect();
        let max = reps.iter().copied().fold(0.0, f64::max);
        for t in [max + 0.5, max + 5.0] {
            let (p, source, share, tail) = p_value(t, &reps);
            let exact = 0.5 * chi2_sf(t, 1.0);
            assert_eq!(source, PSource::Tail, "t = {t}");
            assert!((share - 0.5).abs() < 0.04, "π = {share}");
            let (a, nu) = tail.unwrap();
            assert!(
                (a - 1.0).abs() < 0.2 && (nu - 1.0).abs() < 0.2,
                "{a}·χ²_{nu}"
            );
            assert!(
                (p / exact).ln().abs() < 0.7,
                "t = {t}: p = {p:.3e}, exact {exact:.3e}"
            );
        }
        // Inside the replicates' range the empirical count is used.
        let (p, source, ..) = p_value(1.0, &reps);
        assert!(p_value(max, &reps).1 == PSource::Empirical);
        let exact = 0.5 * chi2_sf(1.0, 1.0);
        assert_eq!(source, PSource::Empirical);
        assert!((p - exact).abs() < 0.03, "{p} vs {exact}");
    }

    /// T = Δχ²/(χ²₁/ν₁), a worse extension counting as 0, and so does anything up to
    /// [`ZERO`]; ν₁ = 0 counts as 1.
    #[test]
    fn the_statistic_is_delta_chi2_over_the_extensions_reduced_chi2() {
        assert_eq!(statistic(120.0, 100.0, 50), 10.0);
        assert_eq!(statistic(100.0, 120.0, 50), 0.0);
        assert_eq!(statistic(100.0 + 5e-4, 100.0, 100), 0.0);
        // Exactly 1e-3 (1/1000, correctly rounded) is "at or below".
        assert_eq!(statistic(1001.0, 1000.0, 1), 0.0);
        assert!((statistic(100.0 + 2e-3, 100.0, 100) - 2e-3).abs() < 1e-12);
        assert_eq!(statistic(10.0, 5.0, 0), 1.0);
    }

    /// Each branch of the p-value against counts and tails worked out by hand.
    #[test]
    fn p_values_by_hand() {
        // B = 10, three replicates at or above T = 3 (3.0 itself counts): (1 + 3)/11;
        // six of ten positive.
        let reps = [0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 0.0, 0.0, 0.0];
        let (p, source, share, tail) = p_value(3.0, &reps);
        assert_eq!(
            (p, source, share, tail),
            (4.0 / 11.0, PSource::Empirical, 0.6, None)
        );
        // None reaches T and only 9 are positive: the bound 1/(B + 1).
        let mut reps = vec![0.5; 9];
        reps.push(0.0);
        let (p, source, share, tail) = p_value(1.0, &reps);
        assert_eq!(
            (p, source, share, tail),
            (1.0 / 11.0, PSource::EmpiricalBound, 0.9, None)
        );
        // Positive replicates all equal: no variance to fit a tail to.
        let (p, source, ..) = p_value(5.0, &[1.0; 12]);
        assert_eq!((p, source), (1.0 / 13.0, PSource::EmpiricalBound));
        // Ten positive replicates 2 ± d (mean 2, variance 10d²/9 = 2) and ten at 0:
        // a = var/(2·mean) = 1/2, ν = 2·mean²/var = 4, π = 1/2, and
        // P(χ²₄ ≥ x) = e^(−x/2)(1 + x/2): p = π·P(χ²₄ ≥ 2T) = ½e^(−T)(1 + T).
        let d = 1.8f64.sqrt();
        let mut reps: Vec<f64> = (0..10)
            .map(|i| if i % 2 == 0 { 2.0 + d } else { 2.0 - d })
            .collect();
        reps.extend([0.0; 10]);
        let (p, source, share, tail) = p_value(20.0, &reps);
        let (a, nu) = tail.unwrap();
        assert_eq!((source, share), (PSource::Tail, 0.5));
        assert!(
            (a - 0.5).abs() < 1e-12 && (nu - 4.0).abs() < 1e-12,
            "{a} {nu}"
        );
        let want = 0.5 * (-20.0f64).exp() * 21.0;
        assert!((p / want - 1.0).abs() < 1e-9, "{p} vs {want}");
        // Just above every replicate the tail (½e^(−3.4)·4.4 = 0.073) is capped at 1/21.
        let (p, source, ..) = p_value(3.4, &reps);
        assert_eq!((p, source), (1.0 / 21.0, PSource::Tail));
    }

    /// A replicate statistic of exactly [`ZERO`] is not positive.
    #[test]
    fn a_replicate_at_zero_is_not_positive() {
        let (_, _, share, _) = p_value(1.0, &[1e-3, 0.5, 2.0e-3, 0.0]);
        assert_eq!(share, 0.5);
    }

    /// The replicate fits: LM stopped at 1e-7 of χ² within 100 iterations, at least one
    /// restart, a seed of their own; everything else as the base options.
    #[test]
    fn replicate_fits_use_lm_with_a_looser_tolerance() {
        let base = FitOptions {
            optimizer: Optimizer::Compass,
            restarts: 9,
            screen: 5,
            seed: 1,
            ..FitOptions::default()
        };
        for restarts in [0, 3] {
            let boot = BootstrapOptions {
                replicates: 9,
                restarts,
                seed: 1,
            };
            let o = replicate_options(&base, &boot);
            assert_eq!(o.optimizer, Optimizer::Lm);
            assert_eq!(o.restarts, restarts.max(1));
            assert_eq!((o.lm.ftol, o.lm.max_iterations), (1e-7, 100));
            assert_eq!((o.screen, o.lm.xtol), (5, base.lm.xtol));
            assert_ne!(o.seed, boot.seed);
        }
    }

    #[test]
    fn descriptions_name_the_source_of_the_p_value() {
        let mut c = Calibrated {
            p: 0.05,
            source: PSource::Empirical,
            statistic: 3.25,
            replicates: 99,
            fitted: 98,
            exceeding: 4,
            positive_share: 0.5,
            tail: None,
            seconds: 1.0,
            evaluations: 10,
        };
        assert_eq!(
            c.describe(),
            "bootstrap: 4 of 98 replicates reach T = 3.2500"
        );
        c.source = PSource::EmpiricalBound;
        c.exceeding = 0;
        assert!(c
            .describe()
            .ends_with("too few positive to fit a tail (p is a bound)"));
        c.source = PSource::Tail;
        c.tail = Some((1.25, 2.5));
        assert!(
            c.describe()
                .ends_with("tail 0.50·1.250·χ²_2.50 fitted to them"),
            "{}",
            c.describe()
        );
    }

    /// Lambert data (ρ = 0.46, 2 % noise) and its Oren–Nayar extension, whose null σ = 0
    /// is irregular: the null refits start with the measured data, the replicates scatter
    /// about the null's fitted values by their uncertainties, and the calibrated p-value
    /// agrees with its own counts.
    #[test]
    fn a_calibration_counts_its_replicates_and_agrees_with_its_p_value() {
        use crate::data::{Kind, RawRow, ReadOptions};
        use crate::engine::cpu::CpuBackend;
        use crate::workflows::diagnose::{embed, fit_model, DiagnoseOptions};
        let f = 0.46 / std::f64::consts::PI;
        let mut rows = Vec::new();
        for ti in [10.0, 35.0, 60.0] {
            for k in 0..=22 {
                let to = -77.0 + 7.0 * k as f64;
                if (to - ti).abs() > 0.5 {
                    let i = rows.len();
                    let wiggle = ((i * 7919) % 13) as f64 / 6.0 - 1.0;
                    let row = RawRow {
                        theta_i: ti,
                        phi_i: 20.0,
                        theta_o: to,
                        phi_o: 20.0,
                        wavelength_nm: 550.0,
                        value: f * (1.0 + 0.02 * wiggle),
                        uncertainty: 0.02 * f,
                    };
                    rows.push((i + 1, row));
                }
            }
        }
        let data =
            Dataset::from_rows(Kind::Brdf, "b", &rows, "b.csv", &ReadOptions::default()).unwrap();
        let backend = CpuBackend::new();
        let opts = DiagnoseOptions {
            restarts: 4,
            seed: 1,
            ..Default::default()
        };
        let null = Model::for_data("lambert", &data).unwrap();
        let ext = Model::for_data("on", &data).unwrap();
        let current = fit_model(&null, &data, &backend, &opts, &[]).unwrap();
        let start = embed(&null, &current.flat, &ext);
        let fit = fit_model(&ext, &data, &backend, &opts, &[start]).unwrap();
        let base = FitOptions {
            optimizer: Optimizer::Lm,
            restarts: 2,
            screen: 1,
            ..FitOptions::default()
        };
        let boot = BootstrapOptions {
            replicates: 19,
            restarts: 1,
            seed: 3,
        };
        let nulls = refit_null(
            &null,
            &current.flat,
            &current.values,
            &data,
            &backend,
            &base,
            &boot,
        )
        .unwrap();
        assert_eq!(
            (nulls.replicates.len(), nulls.flat.len(), nulls.chi2.len()),
            (20, 20, 20)
        );
        for (a, b) in nulls.replicates[0].samples.iter().zip(&data.samples) {
            assert_eq!(a.value, b.value);
        }
        let z: Vec<f64> = nulls.replicates[1..]
            .iter()
            .flat_map(|r| {
                r.samples
                    .iter()
                    .zip(&current.values)
                    .map(|(s, v)| (s.value - v) / s.uncertainty)
            })
            .collect();
        let n = z.len() as f64;
        let mean = z.iter().sum::<f64>() / n;
        let sd = (z.iter().map(|z| (z - mean).powi(2)).sum::<f64>() / n).sqrt();
        assert!(
            z.len() == 19 * data.len() && mean.abs() < 0.15 && (sd - 1.0).abs() < 0.1,
            "{mean} {sd}"
        );
        assert!(
            (nulls.chi2[0] / current.chi2 - 1.0).abs() < 1e-6,
            "{} {}",
            nulls.chi2[0],
            current.chi2
        );

        let c = calibrate(
            &ext,
            &fit.flat,
            &|g| embed(&null, g, &ext),
            &nulls,
            fit.dof,
            &backend,
            &base,
            &boot,
        )
        .unwrap();
        assert_eq!(c.replicates, 19);
        assert!(
            c.fitted >= 17 && c.fitted <= 19 && c.exceeding <= c.fitted,
            "{c:?}"
        );
        let t = statistic(current.chi2, fit.chi2, fit.dof);
        assert!(
            (c.statistic - t).abs() < 0.01 + 1e-3 * t,
            "T {} vs {t}",
            c.statistic
        );
        let bound = 1.0 / (c.fitted + 1) as f64;
        match c.source {
            PSource::Empirical => {
                assert_eq!(
                    c.p,
                    (1 + c.exceeding) as f64 / (c.fitted + 1) as f64,
                    "{c:?}"
                )
            }
            PSource::EmpiricalBound => assert!(c.exceeding == 0 && c.p == bound, "{c:?}"),
            PSource::Tail => assert!(c.exceeding == 0 && c.p <= bound, "{c:?}"),
        }
        assert!(
            c.evaluations > nulls.evaluations && c.evaluations < 100 * nulls.evaluations,
            "{c:?}"
        );
        assert!(c.seconds >= nulls.seconds);
        // The refits are deterministic: the same calibration against null refits that
        // report 1000 more evaluations reports 1000 more; against a non-finite null χ²
        // of the measured data it is an error.
        let again = |chi2_0: f64, extra: u64| NullRefits {
            replicates: nulls.replicates.clone(),
            flat: nulls.flat.clone(),
            chi2: [&[chi2_0][..], &nulls.chi2[1..]].concat(),
            seconds: nulls.seconds,
            evaluations: nulls.evaluations + extra,
        };
        let embed_null = |g: &[f64]| embed(&null, g, &ext);
        let more = again(nulls.chi2[0], 1000);
        let c2 = calibrate(
            &ext,
            &fit.flat,
            &embed_null,
            &more,
            fit.dof,
            &backend,
            &base,
            &boot,
        )
        .unwrap();
        assert_eq!(c2.evaluations, c.evaluations + 1000);
        assert_eq!(
            (c2.p, c2.statistic, c2.exceeding),
            (c.p, c.statistic, c.exceeding)
        );
        // A replicate whose null refit is not finite is left out of the counts.
        let mut one_failed = again(nulls.chi2[0], 0);
        one_failed.chi2[5] = f64::NAN;
        let c3 = calibrate(
            &ext,
            &fit.flat,
            &embed_null,
            &one_failed,
            fit.dof,
            &backend,
            &base,
            &boot,
        )
        .unwrap();
        assert_eq!(c3.fitted, c.fitted - 1);
        let nan = again(f64::NAN, 0);
        assert!(calibrate(
            &ext,
            &fit.flat,
            &embed_null,
            &nan,
            fit.dof,
            &backend,
            &base,
            &boot
        )
        .is_err());
    }

    /// Replicates drawn from a model's values, not the data's: y* = y′ + u z.
    #[test]
    fn null_replicates_scatter_about_the_models_values() {
        use crate::data::{Kind, RawRow, ReadOptions};
        let rows: Vec<(usize, RawRow)> = (0..3)
            .map(|i| {
                let row = RawRow {
                    theta_i: 10.0 * i as f64,
                    phi_i: 0.0,
                    theta_o: 30.0,
                    phi_o: 180.0,
                    wavelength_nm: 550.0,
                    value: 1.0,
                    uncertainty: 1e-6,
                };
                (i + 1, row)
            })
            .collect();
        let data =
            Dataset::from_rows(Kind::Brdf, "n", &rows, "n.csv", &ReadOptions::default()).unwrap();
        let reps = null_replicates(&data, &[2.0, 3.0, 4.0], 5, 1);
        assert_eq!(reps.len(), 5);
        for r in &reps {
            for (s, v) in r.samples.iter().zip([2.0, 3.0, 4.0]) {
                assert!((s.value - v).abs() < 1e-4, "{} vs {v}", s.value);
            }
        }
    }

    /// Without positive replicates no tail can be fitted: the p-value is the empirical
    /// bound 1/(B + 1), never 0.
    #[test]
    fn all_zero_replicates_give_the_empirical_bound() {
        let reps = vec![0.0; 99];
        let (p, source, share, tail) = p_value(5.0, &reps);
        assert_eq!(source, PSource::EmpiricalBound);
        assert_eq!(p, 0.01);
        assert_eq!(share, 0.0);
        assert!(tail.is_none());
        assert_eq!(p_value(0.0, &reps).0, 1.0);
    }
}
