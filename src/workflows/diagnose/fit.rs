//! Fitting a model for the diagnosis: a multi-start χ² fit and its statistics, and the
//! fits of a round's candidates.

use super::score::{PTest, SETTLED};
use super::{embed, Candidate, DiagnoseOptions, Scored};
use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::normalised_residuals;
use crate::engine::Backend;
use crate::inference::bootstrap::{self, BootstrapOptions};
use crate::inference::covariance::Covariance;
use crate::inference::fit::{fit_outcome, FitOptions, Optimizer};
use crate::inference::stats::consistency_p;
use anyhow::{Context, Result};

/// One fitted model (χ² statistics, parameters, residuals).
#[derive(Clone, Debug)]
pub struct FitResult {
    pub model: Model,
    pub flat: Vec<f64>,
    /// Model values at the samples.
    pub values: Vec<f64>,
    /// Normalized residuals z = (y′ − y)/u.
    pub z: Vec<f64>,
    /// χ² of the data plus the priors' (`--prior`).
    pub chi2: f64,
    /// Samples + priors − fitted parameters.
    pub dof: usize,
    /// Fitted parameters (the model's, less those fixed by `--fix`).
    pub params: usize,
    pub chi2_red: f64,
    /// Best value of the driving loss.
    pub loss: f64,
    pub cov: Covariance,
    pub seconds: f64,
}

impl FitResult {
    pub fn spec(&self) -> &str {
        &self.model.spec
    }
    /// P(χ²_{K−P} ≥ χ²).
    pub fn p_consistent(&self) -> f64 {
        consistency_p(self.chi2, self.dof)
    }
}

/// The fit options of every fit of a diagnosis.
fn fit_options(opts: &DiagnoseOptions) -> FitOptions {
    // SMAPE is not a sum of squares: LM cannot fit it, compass can.
    let optimizer = if opts.optimizer == Optimizer::Lm && !opts.loss.is_sum_of_squares() {
        Optimizer::Compass
    } else {
        opts.optimizer
    };
    FitOptions {
        optimizer,
        restarts: opts.restarts.max(1),
        seed: opts.seed,
        screen: opts.screen,
        constraints: opts.constraints.clone(),
        ..Default::default()
    }
}

/// Multi-start fit of `model` with extra starting points `seeds` (physical parameters).
pub fn fit_model(
    model: &Model,
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    seeds: &[Vec<f64>],
) -> Result<FitResult> {
    let fit_opts = FitOptions {
        initial_points: seeds.to_vec(),
        ..fit_options(opts)
    };
    let o = fit_outcome(model, data, opts.loss, backend, &fit_opts, &mut |_| {})?;
    let chi2 = o.chi2 + o.chi2_prior;
    Ok(FitResult {
        model: model.clone(),
        z: normalised_residuals(data, &o.values),
        flat: o.flat,
        values: o.values,
        chi2,
        dof: o.dof,
        params: o.constraints.dim(),
        chi2_red: chi2 / o.dof as f64,
        loss: o.loss,
        cov: o.cov,
        seconds: o.seconds,
    })
}

/// Fit every candidate from the current optimum embedded in its parameters (plus random
/// starts): one after the other, or one thread each with `parallel`.
pub(super) fn fit_all(
    cands: &[Candidate],
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    current: &FitResult,
) -> Vec<Result<FitResult>> {
    let one = |c: &Candidate| -> Result<FitResult> {
        let model = Model::for_data(&c.spec, data)?;
        let seed = embed(&current.model, &current.flat, &model);
        fit_model(&model, data, backend, opts, &[seed])
            .with_context(|| format!("fitting {}", c.spec))
    };
    if opts.parallel && cands.len() > 1 {
        std::thread::scope(|scope| {
            let handles: Vec<_> = cands.iter().map(|c| scope.spawn(move || one(c))).collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or_else(|_| Err(anyhow::anyhow!("a candidate fit panicked")))
                })
                .collect()
        })
    } else {
        cands.iter().map(one).collect()
    }
}

/// The bootstrap-calibrated p-value of extending the fit `current` to the fit `ext` on
/// `data` (both fitted by [`fit_model`] with `opts`), whether or not its null is irregular:
/// what [`calibrate_round`] does for one candidate.
pub fn bootstrap_p(
    current: &FitResult,
    ext: &FitResult,
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
) -> Result<bootstrap::Calibrated> {
    let boot = round_bootstrap(opts);
    let nulls = refit_current(current, data, backend, opts, &boot)?;
    calibrate_one(current, ext, &nulls, backend, opts, &boot)
}

/// The current model refitted to the measured data and the replicates drawn from its fit.
fn refit_current(
    current: &FitResult,
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    boot: &BootstrapOptions,
) -> Result<bootstrap::NullRefits> {
    bootstrap::refit_null(
        &current.model,
        &current.flat,
        &current.values,
        data,
        backend,
        &fit_options(opts),
        boot,
    )
}

/// One candidate's calibrated p-value against the current model's refits.
fn calibrate_one(
    current: &FitResult,
    ext: &FitResult,
    nulls: &bootstrap::NullRefits,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    boot: &BootstrapOptions,
) -> Result<bootstrap::Calibrated> {
    bootstrap::calibrate(
        &ext.model,
        &ext.flat,
        &|null_flat| embed(&current.model, null_flat, &ext.model),
        nulls,
        ext.dof,
        backend,
        &fit_options(opts),
        boot,
    )
}

/// The bootstrap's options in a diagnosis (its seed tied to the diagnosis's).
fn round_bootstrap(opts: &DiagnoseOptions) -> BootstrapOptions {
    BootstrapOptions {
        seed: opts.bootstrap.seed ^ opts.seed.rotate_left(17),
        ..opts.bootstrap.clone()
    }
}

/// Calibrate by the parametric bootstrap the p-value of every candidate whose null is
/// irregular and whose verdict depends on it ([`Scored::needs_calibration`]); the others
/// keep the nominal F test and say why. The null is refitted to the replicates once per
/// round, shared by the candidates.
pub(super) fn calibrate_round(
    scored: &mut [Scored],
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    current: &FitResult,
    log: &mut dyn FnMut(String),
) {
    let boot = round_bootstrap(opts);
    let mut nulls = None;
    for s in scored.iter_mut().filter(|s| s.irregular.is_some()) {
        if !s.needs_calibration() {
            let why = if s.delta_bic_scaled >= 0.0 {
                "the BIC does not fall, so the candidate fails whatever its p-value".to_string()
            } else {
                format!(
                    "the nominal p is below {SETTLED:.0e} of the level: the calibrated one would have to be a million times larger to change the verdict"
                )
            };
            s.p_test = PTest::FNominal(why);
            continue;
        }
        if boot.replicates == 0 {
            s.p_test = PTest::FNominal("--bootstrap 0".into());
            continue;
        }
        let fit = s.fit.as_ref().expect("needs_calibration implies a fit");
        if nulls.is_none() {
            log(format!(
                "    bootstrap: refitting {} to {} replicates drawn from its fit",
                current.model.spec, boot.replicates
            ));
            nulls = Some(refit_current(current, data, backend, opts, &boot));
        }
        let result = match nulls.as_ref().expect("set above") {
            Ok(n) => calibrate_one(current, fit, n, backend, opts, &boot),
            Err(e) => Err(anyhow::anyhow!("{e:#}")),
        };
        match result {
            Ok(c) => {
                log(format!(
                    "    bootstrap of {}: p = {:.2e} ({}; {:.1} s)",
                    s.candidate.spec,
                    c.p,
                    c.describe(),
                    c.seconds
                ));
                s.calibrated(c);
            }
            Err(e) => {
                log(format!(
                    "    bootstrap of {} failed ({e:#}): keeping the nominal F test",
                    s.candidate.spec
                ));
                s.p_test = PTest::FNominal(format!("the bootstrap failed: {e:#}"));
            }
        }
    }
}
