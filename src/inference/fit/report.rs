//! The JSON report of a fit (docs/output.md) and its human-readable summary.

use super::{FitOptions, FitOutcome};
use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::Loss;
use crate::engine::Backend;
use serde::Serialize;
use serde_json::{Map, Value};

/// The best parameters of a fit (docs/output.md `best`).
#[derive(Clone, Debug, Serialize)]
pub struct Best {
    pub loss: f64,
    pub chi2_red: f64,
    /// Parameter name → value (an array per channel for rgb parameters).
    pub params: Map<String, Value>,
    /// Standard uncertainties, same shape; null where the data does not determine it.
    pub param_std: Map<String, Value>,
}

/// The JSON report of one fit (docs/output.md), with extras after the contract's fields.
#[derive(Clone, Debug, Serialize)]
pub struct FitReport {
    pub model: String,
    pub loss: String,
    pub weights: String,
    pub optimizer: String,
    pub backend: String,
    pub restarts: usize,
    pub evaluations: u64,
    pub seconds: f64,
    pub best: Best,
    pub data: String,
    pub material: String,
    pub samples: usize,
    pub channels: Vec<f64>,
    /// Measurement planes (φ, degrees) with parameters of their own (`+peraxis`), else [0].
    pub axes: Vec<f64>,
    pub seed: u64,
    /// Restarts whose final loss is within 1% of the best (a multi-modality signal).
    pub restarts_within_1pct: usize,
    /// Parameter names of the flat vector (rgb parameters as `name[c]`).
    pub flat_names: Vec<String>,
    pub flat_params: Vec<f64>,
    pub flat_std: Vec<Option<f64>>,
    /// Correlation matrix of the flat parameters (null entries where undetermined).
    pub correlation: Vec<Vec<Option<f64>>>,
    pub warnings: Vec<String>,
    /// Degrees of freedom of χ²_red: samples + priors − fitted parameters.
    pub dof: usize,
    /// Fitted parameters (the flat vector's, less those fixed by `--fix`).
    pub n_params: usize,
    /// What `--fix`, `--bounds` and `--prior` imposed (absent when nothing was):
    /// `{fixed: {name: value}, bounds: {name: [lo, hi]}, priors: [{name, index, mean, sd}],
    /// chi2_prior}`. Fixed parameters have a standard uncertainty of 0.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub constraints: Option<Value>,
    /// `--mc N`: the parameters' distribution over N refitted replicas of the data
    /// (absent without it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub monte_carlo: Option<crate::inference::mc_summary::McSummary>,
}

pub(super) fn make_report(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    opts: &FitOptions,
    backend: &dyn Backend,
    o: FitOutcome,
) -> FitReport {
    // χ²_red counts each prior as one observation (module doc of `constraints`).
    let chi2_red = (o.chi2 + o.chi2_prior) / o.dof as f64;
    let flat = &o.flat;
    let mut cov = o.cov;
    for (j, f) in o.constraints.fixed.iter().enumerate() {
        if f.is_some() {
            cov.std[j] = Some(0.0); // fixed: exact by assumption
        }
    }
    let constraints = (!o.constraints.is_trivial()).then(|| {
        let mut v = o.constraints.to_json();
        v["chi2_prior"] = serde_json::json!(o.chi2_prior);
        v
    });
    let group = |vals: &[Option<f64>]| -> Map<String, Value> {
        let mut m = Map::new();
        for p in &model.params {
            let w = p.width(model.channels);
            let slice = &vals[p.index..p.index + w];
            // rgb and per-plane parameters are arrays (plane-major, then channel).
            let v = if w > 1 {
                Value::Array(slice.iter().map(|x| json_num(*x)).collect())
            } else {
                json_num(slice[0])
            };
            m.insert(p.name.clone(), v);
        }
        m
    };
    let params = group(&flat.iter().map(|&v| Some(v)).collect::<Vec<_>>());
    let param_std = group(&cov.std);
    FitReport {
        model: model.spec.clone(),
        loss: loss.metric.to_string(),
        weights: loss.weights.to_string(),
        optimizer: opts.optimizer.to_string(),
        backend: backend.id().to_string(),
        restarts: opts.restarts,
        evaluations: o.evaluations,
        seconds: o.seconds,
        best: Best {
            loss: o.loss,
            chi2_red,
            params,
            param_std,
        },
        data: data.source.display().to_string(),
        material: data.material.clone(),
        samples: data.len(),
        channels: data.channels.clone(),
        axes: model.axes.clone(),
        seed: opts.seed,
        restarts_within_1pct: o.within,
        flat_names: model.flat_names(),
        flat_params: flat.to_vec(),
        flat_std: cov.std,
        correlation: cov.correlation,
        warnings: data
            .assumed_uncertainty
            .map(|(rel, abs)| {
                format!(
                    "the data's uncertainties were assumed, not measured (u = sqrt((REL·|value|)² + ABS²), REL = {rel}, ABS = {abs} sr⁻¹): χ² and parameter uncertainties rest on that assumption"
                )
            })
            .into_iter()
            .chain(cov.warnings)
            .collect(),
        dof: o.dof,
        n_params: o.constraints.dim(),
        constraints,
        monte_carlo: None,
    }
}

fn json_num(v: Option<f64>) -> Value {
    match v {
        Some(x) if x.is_finite() => serde_json::Number::from_f64(x)
            .map(Value::Number)
            .unwrap_or(Value::Null),
        _ => Value::Null,
    }
}

impl FitReport {
    /// A compact human-readable summary.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "model {} fitted to '{}' ({} samples, {} channel(s)): loss {}/{} = {:.6e}, χ²_red = {:.3}\n",
            self.model,
            self.material,
            self.samples,
            self.channels.len(),
            self.loss,
            self.weights,
            self.best.loss,
            self.best.chi2_red
        );
        let fixed = self
            .constraints
            .as_ref()
            .and_then(|c| c.get("fixed"))
            .and_then(Value::as_object);
        for (i, name) in self.flat_names.iter().enumerate() {
            let std = match self.flat_std[i] {
                _ if fixed.is_some_and(|f| f.contains_key(name)) => "(fixed)".into(),
                Some(s) => format!("± {s:.3e}"),
                None => "(not determined)".into(),
            };
            s += &format!("  {name:<14} = {:<12.6} {std}\n", self.flat_params[i]);
        }
        s += &format!(
            "  {} restarts ({} within 1% of best), {} evaluations, {:.2} s on {}\n",
            self.restarts, self.restarts_within_1pct, self.evaluations, self.seconds, self.backend
        );
        if let Some(priors) = self
            .constraints
            .as_ref()
            .and_then(|c| c.get("priors"))
            .and_then(Value::as_array)
            .filter(|p| !p.is_empty())
        {
            let chi2_prior = self
                .constraints
                .as_ref()
                .and_then(|c| c["chi2_prior"].as_f64());
            s += &format!(
                "  {} in χ² (their share: {:.3}); χ²_red = (χ² + priors)/(samples + priors − fitted) with {} degrees of freedom\n",
                crate::data::count(priors.len(), "prior", "priors"),
                chi2_prior.unwrap_or(f64::NAN),
                self.dof
            );
        }
        for w in &self.warnings {
            s += &format!("  warning: {w}\n");
        }
        if let Some(mc) = &self.monte_carlo {
            s += &mc.summary();
        }
        s
    }
}
