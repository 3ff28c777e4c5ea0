//! One diagnosis as `bsdfit diagnose` asks for it, for every caller (the command line, the
//! Python module): the request with the library's defaults, and the checks made before
//! any fit (the loss for the data's kind, the level, the start model and its constrained
//! names, the memory of a round's batch), written once, as [`crate::workflows::fit`]'s
//! `FitRequest` is for a fit.

use super::{check_start, diagnose, DiagnoseOptions, Diagnosis};
use crate::data::Dataset;
use crate::engine::loss::{Metric, Weights};
use crate::engine::Backend;
use crate::workflows::checks::check_batch_memory;
use anyhow::Result;

/// What one diagnosis is asked to do.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct DiagnoseRequest {
    /// The start model's spec, e.g. `lambert`.
    pub model: String,
    /// The loss that drives each fit (the tests always use χ²) and its weighting.
    pub loss: Metric,
    pub weights: Weights,
    /// Every other option; its `loss` is set from `loss` and `weights` once they are
    /// checked against the data ([`DiagnoseRequest::prepare`]).
    pub options: DiagnoseOptions,
}

impl Default for DiagnoseRequest {
    fn default() -> Self {
        let options = DiagnoseOptions::default();
        DiagnoseRequest {
            model: String::new(),
            loss: options.loss.metric,
            weights: options.loss.weights,
            options,
        }
    }
}

impl DiagnoseRequest {
    /// The checks before any fit, on `data`: errors name the option at fault; `warn` hears
    /// what the command line prints as a warning (a large batch). Returns the options to
    /// run, the loss set for the data's kind.
    pub fn prepare(&self, data: &Dataset, warn: &mut dyn FnMut(String)) -> Result<DiagnoseOptions> {
        let o = &self.options;
        let (loss, start) = check_start(
            data,
            &self.model,
            self.loss,
            self.weights,
            o.alpha,
            &o.constraints,
        )?;
        // Extensions add a few parameters to the start model: estimate with three more.
        check_batch_memory(
            o.restarts.saturating_add(1),
            start.dim + 3,
            data.len(),
            &format!(
                "{} and its extensions on {}",
                start.spec,
                data.source.display()
            ),
            warn,
        )?;
        Ok(DiagnoseOptions { loss, ..o.clone() })
    }

    /// Prepare and run the diagnosis on `backend`; `log` hears each line of the path as
    /// it is found (what `bsdfit diagnose` prints).
    pub fn run(
        &self,
        data: &Dataset,
        backend: &dyn Backend,
        warn: &mut dyn FnMut(String),
        log: &mut dyn FnMut(String),
    ) -> Result<Diagnosis> {
        let options = self.prepare(data, warn)?;
        diagnose(data, &self.model, backend, &options, log)
    }
}
