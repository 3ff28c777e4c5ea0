//! One fit as `bsdfit fit` runs it, for every caller (the command line, the Python module):
//! the same defaults, the same checks before any work, the same options handed to
//! [`crate::inference::fit::fit`], so the same data and seed give the same parameters
//! whoever asks.

use crate::bsdf::Model;
use crate::choice::field_error;
use crate::data::{Dataset, Kind};
use crate::engine::cpu::CpuBackend;
use crate::engine::loss::{Loss, Metric, Weights};
use crate::engine::{device_fault, Backend};
use crate::inference::constraints::{ConstraintSpec, Constraints};
use crate::inference::fit::Smoothness;
use crate::inference::fit::{fit, FitOptions, FitReport, Optimizer};
use crate::inference::mc::{monte_carlo, McOptions};
use anyhow::Result;

/// Random restarts per fit of `fit`, `diagnose` and `sweep` (one default for all).
pub const DEFAULT_RESTARTS: usize = 16;

/// What one fit is asked to do, with the command line's defaults.
#[derive(Clone, Debug)]
pub struct FitRequest {
    /// Model spec, e.g. `fa(eon)`.
    pub model: String,
    /// The loss: χ², or one of the paper's losses for the data's kind.
    pub loss: Metric,
    /// The weighting of the paper's losses (χ² weighs by 1/u² whatever it is).
    pub weights: Weights,
    /// None: LM for sum-of-squares losses, compass search for smape.
    pub optimizer: Option<Optimizer>,
    pub restarts: usize,
    pub seed: u64,
    pub constraints: ConstraintSpec,
    /// Monte Carlo replicas (0: off), the correlated relative scale uncertainty, and the
    /// random restarts per replica.
    pub mc: usize,
    pub mc_scale: f64,
    pub mc_restarts: usize,
    /// The smoothness prior of tabulated knots (`+ndf`): chosen from the data by default.
    pub smoothness: Smoothness,
}

impl Default for FitRequest {
    fn default() -> Self {
        FitRequest {
            model: String::new(),
            loss: Metric::Chi2,
            weights: Weights::Uniform,
            optimizer: None,
            restarts: DEFAULT_RESTARTS,
            seed: 1,
            constraints: ConstraintSpec::default(),
            mc: 0,
            mc_scale: 0.0,
            mc_restarts: 3,
            smoothness: Smoothness::Auto,
        }
    }
}

/// The loss a word names (`chi2`, `rmse`, …), as an error of the `loss` option.
pub fn parse_metric(word: &str) -> Result<Metric> {
    word.parse()
        .map_err(|e: String| field_error(format!("{{loss}}: {e}")))
}

/// The weighting a word names (`uniform`, `relunc`, `invunc`), as an error of the
/// `weights` option.
pub fn parse_weights(word: &str) -> Result<Weights> {
    word.parse()
        .map_err(|e: String| field_error(format!("{{weights}}: {e}")))
}

/// The loss of a metric and a weighting, checked against the kind of data.
pub fn loss_for(metric: Metric, weights: Weights, kind: Kind) -> Result<Loss> {
    if !metric.applies_to(kind) {
        return Err(field_error(format!(
            "{{loss={metric}}} is not defined for {kind} data (use one of {:?} or chi2)",
            Metric::for_kind(kind)
                .iter()
                .map(|m| m.to_string())
                .collect::<Vec<_>>()
        )));
    }
    Ok(Loss::new(metric, weights))
}

/// A model spec that does not parse or does not suit the data, as an error of the `model`
/// option.
pub fn model_error(e: &dyn std::fmt::Display) -> anyhow::Error {
    let text = e.to_string().replace('{', "(").replace('}', ")");
    field_error(format!("{{model}}: {text}"))
}

/// The optimizer asked for, or the default for the loss: LM where it applies.
pub fn optimizer_for(given: Option<Optimizer>, loss: Loss) -> Optimizer {
    given.unwrap_or(if loss.is_sum_of_squares() {
        Optimizer::Lm
    } else {
        Optimizer::Compass
    })
}

/// Which stage a progress count belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    /// The fit's restarts still active.
    Fit,
    /// The Monte Carlo replica restarts still active (of [`FitRequest::mc_total`]).
    MonteCarlo,
}

/// A fit and, where Monte Carlo was asked for and failed, why (the fit itself stands).
pub struct FitResponse {
    pub model: Model,
    pub loss: Loss,
    pub report: FitReport,
    pub mc_error: Option<anyhow::Error>,
    /// Where the GPU was lost or hung and the fit (or its Monte Carlo replicas) was
    /// re-run on the CPU reference: what happened, in one line (also among the report's
    /// warnings; the report's `backend` is the one that produced it).
    pub fallback: Option<String>,
}

impl FitResponse {
    /// An error saying why and what to try, where the best fit's χ²_red or loss is not
    /// finite (`data`, `backend`: what it was fitted to, and on).
    pub fn check_finite(&self, data: &Dataset, backend: &dyn Backend) -> Result<()> {
        let best = &self.report.best;
        anyhow::ensure!(
            best.chi2_red.is_finite() && best.loss.is_finite(),
            "{}",
            crate::workflows::checks::nonfinite_message(
                &self.model,
                data,
                self.loss,
                &self.report.flat_params,
                best.chi2_red,
                best.loss,
                backend,
            )
        );
        Ok(())
    }

    /// The normalised residuals z = (y′ − y)/u of the best fit, one per sample of `data`
    /// (the data it was fitted to), computed in f64 on the CPU reference.
    pub fn residuals(&self, data: &Dataset) -> Result<Vec<f64>> {
        let cpu = CpuBackend::new();
        let mut eval = cpu.prepare(crate::engine::Problem {
            model: &self.model,
            data,
            loss: self.loss,
        })?;
        let values = eval.values(&self.report.flat_params)?;
        Ok(crate::engine::loss::normalised_residuals(data, &values))
    }
}

/// `work` on `backend`; where its device fails it (lost or hung, [`device_fault`]),
/// `work` again on the CPU reference, with a line saying so (naming `what` was re-run).
fn on_device_or_cpu<T>(
    backend: &dyn Backend,
    what: &str,
    work: &mut dyn FnMut(&dyn Backend) -> Result<T>,
) -> Result<(T, Option<String>)> {
    match work(backend) {
        Ok(t) => Ok((t, None)),
        Err(e) => {
            let fault = device_fault(&e).cloned().or_else(|| backend.fault());
            match fault {
                Some(f) if backend.id() != "cpu" => {
                    let line = format!("GPU fault: {f}; {what} re-run on the CPU reference");
                    Ok((work(&CpuBackend::new())?, Some(line)))
                }
                _ => Err(e),
            }
        }
    }
}

impl FitRequest {
    /// The checks that need no data: Monte Carlo options.
    pub fn check(&self) -> Result<()> {
        if self.restarts < 1 {
            return Err(field_error(format!(
                "{{restarts}} takes a positive integer, got {}",
                self.restarts
            )));
        }
        if !(self.mc == 0 || self.mc >= 2) {
            return Err(field_error(format!(
                "{{mc={}}}: a distribution needs at least 2 replicas (0 turns Monte Carlo off)",
                self.mc
            )));
        }
        if !(self.mc_scale.is_finite() && (0.0..1.0).contains(&self.mc_scale)) {
            return Err(field_error(format!(
                "{{mc_scale={}}}: a relative uncertainty in [0, 1)",
                self.mc_scale
            )));
        }
        if !(self.mc > 0 || self.mc_scale == 0.0) {
            return Err(field_error(
                "{mc_scale} needs {mc}, the number of replicas, to be at least 2",
            ));
        }
        Ok(())
    }

    /// Replica restarts Monte Carlo steps in all (for a progress bar).
    pub fn mc_total(&self) -> usize {
        self.mc * (self.mc_restarts.max(1) + 1)
    }

    /// The model, loss and fit options for `data`; a misspelt model or parameter name, or
    /// a loss not defined for the data's kind, fails here, before any work.
    pub fn prepare(&self, data: &Dataset) -> Result<(Model, Loss, FitOptions)> {
        self.check()?;
        let loss = loss_for(self.loss, self.weights, data.kind)?;
        let model = Model::for_data(&self.model, data).map_err(|e| model_error(&e))?;
        Constraints::resolve(&model, &self.constraints, false)?;
        let opts = FitOptions {
            optimizer: optimizer_for(self.optimizer, loss),
            restarts: self.restarts,
            seed: self.seed,
            constraints: self.constraints.clone(),
            smoothness: self.smoothness,
            ..Default::default()
        };
        Ok((model, loss, opts))
    }

    /// Every check before the backend starts, for every front end: [`Self::prepare`]'s,
    /// then the memory of one batch of restarts (`warn` hears what the command line
    /// prints as a warning). Returns the model.
    pub fn preflight(&self, data: &Dataset, warn: &mut dyn FnMut(String)) -> Result<Model> {
        let (model, _, _) = self.prepare(data)?;
        crate::workflows::checks::check_batch_memory(
            self.restarts,
            model.dim,
            data.len(),
            &format!("{} on {}", model.spec, data.source.display()),
            warn,
        )?;
        Ok(model)
    }

    /// Fit `data` on `backend`, then (with `mc`) refit its replicas. `progress` gets the
    /// number of restarts still active in each stage. Where the GPU is lost or hangs,
    /// what it failed is re-run on the CPU reference ([`FitResponse::fallback`]).
    pub fn run(
        &self,
        data: &Dataset,
        backend: &dyn Backend,
        progress: &mut dyn FnMut(Stage, usize),
    ) -> Result<FitResponse> {
        let (model, loss, opts) = self.prepare(data)?;
        let (mut report, mut fallback) =
            on_device_or_cpu(backend, "the fit was", &mut |b: &dyn Backend| {
                fit(&model, data, loss, b, &opts, &mut |active| {
                    progress(Stage::Fit, active)
                })
            })?;
        // The replicas go where the fit went (the GPU only if it is still there).
        let cpu = CpuBackend::new();
        let backend: &dyn Backend = if fallback.is_some() { &cpu } else { backend };
        let finite = report.best.chi2_red.is_finite() && report.best.loss.is_finite();
        let mut mc_error = None;
        if self.mc > 0 && finite {
            // The replicas are fitted with the smoothness prior the fit chose.
            let mut opts = opts.clone();
            opts.smoothness = Smoothness::held_from(report.smoothness.as_ref(), opts.smoothness);
            let mc = McOptions {
                replicas: self.mc,
                scale_rel: self.mc_scale,
                seed: self.seed,
                restarts: self.mc_restarts,
            };
            let outcome = on_device_or_cpu(
                backend,
                "its Monte Carlo replicas were",
                &mut |b: &dyn Backend| {
                    monte_carlo(
                        &model,
                        data,
                        loss,
                        b,
                        &opts,
                        &report.flat_params,
                        &report.flat_std,
                        &mc,
                        &mut |active| progress(Stage::MonteCarlo, active),
                    )
                },
            );
            match outcome {
                Ok(((summary, replicas), line)) => {
                    report.attach_knot_mc(&model, &replicas);
                    report.monte_carlo = Some(summary);
                    fallback = fallback.or(line);
                }
                Err(e) => {
                    report.warnings.push(format!("--mc failed: {e:#}"));
                    mc_error = Some(e);
                }
            }
        }
        if let Some(line) = &fallback {
            report.warnings.push(line.clone());
        }
        Ok(FitResponse {
            model,
            loss,
            report,
            mc_error,
            fallback,
        })
    }
}
