//! The JSON report of a fit (docs/output.md) and its human-readable summary.

use super::{Conclusions, FitOptions};
use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::Loss;
use crate::engine::Backend;
use crate::inference::mc_summary::{nan_if_null, nans_if_null};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

/// The best parameters of a fit (docs/output.md `best`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Best {
    #[serde(deserialize_with = "nan_if_null")]
    pub loss: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub chi2_red: f64,
    /// Parameter name → value (an array per channel for rgb parameters).
    pub params: Map<String, Value>,
    /// Standard uncertainties, same shape; null where the data does not determine it.
    pub param_std: Map<String, Value>,
}

/// The JSON report of one fit (docs/output.md), with extras after the contract's fields.
/// It reads back from the JSON it writes (for [`FitReport::summary`] of a saved report).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FitReport {
    pub model: String,
    pub loss: String,
    pub weights: String,
    pub optimizer: String,
    pub backend: String,
    pub restarts: usize,
    pub evaluations: u64,
    #[serde(deserialize_with = "nan_if_null")]
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
    #[serde(deserialize_with = "nans_if_null")]
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
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub constraints: Option<Value>,
    /// `--mc N`: the parameters' distribution over N refitted replicas of the data
    /// (absent without it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub monte_carlo: Option<crate::inference::mc_summary::McSummary>,
    /// Why the optimizer stopped on the best restart (the f64 polish's reason where it
    /// ran).
    #[serde(default = "StopReport::unknown")]
    pub stop: StopReport,
    /// The Bayesian and Akaike information criteria of the fit, χ² + k·ln K and χ² + 2k
    /// (χ² with the priors' share, k fitted parameters, K samples): lower is better
    /// between fits of the same data.
    #[serde(default = "not_a_number", deserialize_with = "nan_if_null")]
    pub bic: f64,
    #[serde(default = "not_a_number", deserialize_with = "nan_if_null")]
    pub aic: f64,
    /// How the smoothness prior's σ_s was chosen, where the model has tabulated knots
    /// (`+ndf`) and the loss is χ² (absent otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub smoothness: Option<super::SmoothnessChoice>,
    /// Each data-driven NDF (`+ndf`) at its knots: D with σ(ln D), and whether the data
    /// see the lobe there (absent without one).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ndf: Vec<NdfReport>,
    /// Each data-driven Fresnel curve (`+fresnel`) per channel at its knots: k_s F e^s
    /// with σ(ln), and whether the data see the lobe there (absent without one).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub fresnel: Vec<FresnelReport>,
    /// Each data-driven body profile (`+body`) at its knots: ρ(θ) with σ(ln ρ), and
    /// whether the data see the body there (absent without one).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub body: Vec<BodyReport>,
}

/// One data-driven body profile ([`crate::inference::knots::body_bands`]).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct BodyReport {
    /// Its knots' stem (`body` on a bare base, `base.body` under a layer).
    pub base: String,
    pub knots: Vec<crate::inference::knots::BodyBand>,
}

/// One channel of a data-driven Fresnel curve ([`crate::inference::knots::fresnel_bands`]).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FresnelReport {
    /// Its knots' stem (`fresnel` in `ggx+fresnel`, `lobe.fresnel` in `fa(B)+fresnel`,
    /// `fresnel_c` for a coat).
    pub lobe: String,
    /// The channel (0-based, in the data's channel order).
    pub channel: usize,
    pub knots: Vec<crate::inference::knots::FresnelBand>,
}

/// One data-driven NDF of a fit ([`crate::inference::knots::bands`]).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct NdfReport {
    /// Its knots' stem (`ndf` in `ggx+ndf`, `lobe.ndf` in `fa(B)+ndf`, `ndf_c` for a coat).
    pub lobe: String,
    pub knots: Vec<crate::inference::knots::KnotBand>,
}

/// Why the optimizer stopped (docs/output.md `stop`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq, Eq)]
pub struct StopReport {
    /// A short identifier: `small_gain`, `max_iterations`, `step_below_minimum`, …
    pub status: String,
    /// Whether it converged (not out of iterations or evaluations, nor at a non-finite cost).
    pub success: bool,
    /// The reason in words.
    pub message: String,
}

impl StopReport {
    /// What a report that does not say why its optimizer stopped reads back as.
    fn unknown() -> StopReport {
        StopReport {
            status: "unknown".into(),
            success: false,
            message: "the report does not say why the optimizer stopped".into(),
        }
    }
}

fn not_a_number() -> f64 {
    f64::NAN
}

impl From<crate::optim::Stop> for StopReport {
    fn from(s: crate::optim::Stop) -> StopReport {
        StopReport {
            status: s.status().to_string(),
            success: s.converged(),
            message: s.message().to_string(),
        }
    }
}

pub(super) fn make_report(
    model: &Model,
    data: &Dataset,
    loss: Loss,
    opts: &FitOptions,
    backend: &dyn Backend,
    o: Conclusions,
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
    let ndf: Vec<NdfReport> = crate::inference::knots::bands(model, data, flat, &cov)
        .into_iter()
        .map(|(lobe, knots)| NdfReport { lobe, knots })
        .collect();
    let fresnel: Vec<FresnelReport> =
        crate::inference::knots::fresnel_bands(model, data, flat, &cov)
            .into_iter()
            .map(|(lobe, channel, knots)| FresnelReport {
                lobe,
                channel,
                knots,
            })
            .collect();
    let body: Vec<BodyReport> = crate::inference::knots::body_bands(model, data, flat, &cov)
        .into_iter()
        .map(|(base, knots)| BodyReport { base, knots })
        .collect();
    let mut knot_warnings = Vec::new();
    for n in &ndf {
        let unseen: Vec<String> = n
            .knots
            .iter()
            .filter(|k| !k.measured)
            .map(|k| format!("{:.1}°", k.theta_deg))
            .collect();
        if !unseen.is_empty() {
            knot_warnings.push(format!(
                "{}: D at θm = {} is set by the smoothness prior, not measured (no half vectors there, the lobe below {}σ of the data, or the data's share of the knot below {}); its band there is the prior's",
                n.lobe,
                unseen.join(", "),
                crate::inference::knots::MEASURED_SIGNAL,
                crate::inference::knots::MEASURED_SHARE
            ));
        }
    }
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
            .chain(knot_warnings)
            .collect(),
        dof: o.dof,
        n_params: o.constraints.dim(),
        constraints,
        monte_carlo: None,
        stop: o.stop.into(),
        bic: crate::inference::stats::bic(o.chi2 + o.chi2_prior, o.constraints.dim(), data.len()),
        aic: crate::inference::stats::aic(o.chi2 + o.chi2_prior, o.constraints.dim()),
        smoothness: o.smoothness,
        ndf,
        fresnel,
        body,
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
    /// Give each tabulated factor's knots their spread over the Monte Carlo replicas
    /// `replicas` (the refitted flat vectors of `model`).
    pub fn attach_knot_mc(&mut self, model: &Model, replicas: &[Vec<f64>]) {
        use crate::inference::knots::{mc_bands, FactorKind, KnotMc};
        // Each knot of a report takes its replicas' spread, in order.
        fn set<K>(knots: &mut [K], spread: &[KnotMc], mc: fn(&mut K) -> &mut Option<KnotMc>) {
            for (k, s) in knots.iter_mut().zip(spread) {
                *mc(k) = Some(s.clone());
            }
        }
        for (factor, spread) in mc_bands(model, replicas) {
            let name = factor.name.as_str();
            match factor.kind {
                FactorKind::Ndf => self
                    .ndf
                    .iter_mut()
                    .filter(|r| r.lobe == name)
                    .for_each(|r| set(&mut r.knots, &spread, |k| &mut k.mc)),
                FactorKind::Fresnel => self
                    .fresnel
                    .iter_mut()
                    .filter(|r| r.lobe == name && Some(r.channel) == factor.channel)
                    .for_each(|r| set(&mut r.knots, &spread, |k| &mut k.mc)),
                FactorKind::Body => self
                    .body
                    .iter_mut()
                    .filter(|r| r.base == name)
                    .for_each(|r| set(&mut r.knots, &spread, |k| &mut k.mc)),
            }
        }
    }

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
                // A data-driven NDF's knot: judged as D with a band, in its table below.
                None if self.ndf.iter().any(|n| is_knot_of(name, &n.lobe)) => {
                    "(a knot: see its D table)".into()
                }
                None if self.fresnel.iter().any(|n| is_knot_of(name, &n.lobe)) => {
                    "(a knot: see its Fresnel table)".into()
                }
                None if self.body.iter().any(|n| is_knot_of(name, &n.base)) => {
                    "(a knot: see its body table)".into()
                }
                None => "(not determined)".into(),
            };
            s += &format!("  {name:<14} = {:<12.6} {std}\n", self.flat_params[i]);
        }
        s += &format!(
            "  {} restarts ({} within 1% of best), {} evaluations, {:.2} s on {}\n",
            self.restarts, self.restarts_within_1pct, self.evaluations, self.seconds, self.backend
        );
        s += &format!("  {} stopped: {}\n", self.optimizer, self.stop.message);
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
                crate::text::plural_with(priors.len(), "prior", "priors"),
                chi2_prior.unwrap_or(f64::NAN),
                self.dof
            );
        }
        if let Some(c) = &self.smoothness {
            s += &format!(
                "  smoothness prior of the knots: σ_s = {} ({:.1} effective parameters), chosen among {} by the {}\n",
                c.chosen.sd,
                c.chosen.effective_params,
                c.tried
                    .iter()
                    .map(|t| format!("{} (χ² {:.1}, edf {:.1})", t.sd, t.chi2, t.effective_params))
                    .collect::<Vec<_>>()
                    .join(", "),
                c.criterion
            );
        }
        for n in &self.ndf {
            s += &format!(
                "  {}: D(θm) at the knots (± in ln D; * set by the prior)\n",
                n.lobe
            );
            for k in &n.knots {
                let band = knot_band(k.sigma_ln_d, k.mc.as_ref());
                let mark = if k.measured { "" } else { " *" };
                s += &format!("    {:>5.2}°  {:<11.4e} {band}{mark}\n", k.theta_deg, k.d);
            }
        }
        for n in &self.fresnel {
            s += &format!(
                "  {} channel {}: k_s F e^s at the knots' θd (± in ln; * set by the prior)\n",
                n.lobe, n.channel
            );
            for k in &n.knots {
                let band = knot_band(k.sigma_ln_f, k.mc.as_ref());
                let mark = if k.measured { "" } else { " *" };
                s += &format!("    {:>5.1}°  {:<11.4e} {band}{mark}\n", k.theta_deg, k.f);
            }
        }
        for n in &self.body {
            s += &format!(
                "  {}: the body's profile ρ(θ) at the knots, f = f_B ρ(θi) ρ(θo) (± in ln ρ; * set by the prior)\n",
                n.base
            );
            for k in &n.knots {
                let band = knot_band(k.sigma_ln_rho, k.mc.as_ref());
                let mark = if k.measured { "" } else { " *" };
                s += &format!("    {:>5.1}°  {:<11.4} {band}{mark}\n", k.theta_deg, k.rho);
            }
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

/// A knot's band for the summary: ± σ of the logarithm (linearised), and the Monte Carlo
/// one beside it where there is one.
fn knot_band(linear: Option<f64>, mc: Option<&crate::inference::knots::KnotMc>) -> String {
    let mut s = linear.map_or(String::new(), |v| format!("± {v:.3}"));
    if let Some(mc) = mc {
        s += &format!(" (MC ± {:.3})", mc.sd_ln);
    }
    s
}

/// Whether the flat name `name` is a knot of the tabulated function with stem `stem`: the
/// stem, the knot's number, and a channel index for a per-channel knot (`lobe.fresnel3[1]`).
fn is_knot_of(name: &str, stem: &str) -> bool {
    name.strip_prefix(stem)
        .and_then(|k| k.split('[').next())
        .is_some_and(|k| k.parse::<usize>().is_ok())
}
