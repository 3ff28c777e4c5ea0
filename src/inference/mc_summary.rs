//! What Monte Carlo reports (`fit --mc N`, JSON `monte_carlo`): plain data, kept apart
//! from [`crate::inference::mc`] so that a fit report can hold it while the Monte Carlo
//! driver calls the fit (one direction of dependency: `mc` → `fit` → `mc_summary`).

use serde::{Deserialize, Deserializer, Serialize};

/// A number read back from JSON, where bsdfit writes a non-finite number as null: NaN then.
pub(crate) fn nan_if_null<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// [`nan_if_null`] for each number of a list.
pub(crate) fn nans_if_null<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
    let v = Vec::<Option<f64>>::deserialize(d)?;
    Ok(v.into_iter().map(|x| x.unwrap_or(f64::NAN)).collect())
}

/// [`nan_if_null`] for an interval.
fn interval_nan_if_null<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
    let [lo, hi] = <[Option<f64>; 2]>::deserialize(d)?;
    Ok([lo.unwrap_or(f64::NAN), hi.unwrap_or(f64::NAN)])
}

/// Coverage probability of the reported intervals.
pub const COVERAGE: f64 = 0.95;

/// Shortest interval holding `p` of the sorted values (JCGM 101 §7.7.2).
pub fn shortest_interval(sorted: &[f64], p: f64) -> [f64; 2] {
    let n = sorted.len();
    if n == 0 {
        return [f64::NAN, f64::NAN];
    }
    let q = ((p * n as f64).round() as usize).clamp(1, n);
    let mut best = [sorted[0], sorted[q - 1]];
    for i in 0..=n - q {
        if sorted[i + q - 1] - sorted[i] < best[1] - best[0] {
            best = [sorted[i], sorted[i + q - 1]];
        }
    }
    best
}

/// One flat parameter's Monte Carlo summary.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct McParam {
    pub name: String,
    /// Best fit of the measured data.
    #[serde(deserialize_with = "nan_if_null")]
    pub value: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub mean: f64,
    #[serde(deserialize_with = "nan_if_null")]
    pub sd: f64,
    /// 95 % shortest coverage interval [lo, hi].
    #[serde(deserialize_with = "interval_nan_if_null")]
    pub interval: [f64; 2],
    /// The linearized standard uncertainty of the fit (None where undetermined).
    pub linear_sd: Option<f64>,
    /// Fraction of replicas whose value lies on a declared bound (within 1e-6 of the
    /// range).
    #[serde(deserialize_with = "nan_if_null")]
    pub on_bound: f64,
}

/// What `--mc N` reports (JSON `monte_carlo`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct McSummary {
    pub replicas: usize,
    /// Replicas whose refit ended at a finite loss (the statistics use these).
    pub converged: usize,
    #[serde(deserialize_with = "nan_if_null")]
    pub scale_rel: f64,
    pub seed: u64,
    pub restarts_per_replica: usize,
    #[serde(deserialize_with = "nan_if_null")]
    pub coverage: f64,
    /// Fitted (free) parameters only; fixed ones have no distribution.
    pub params: Vec<McParam>,
    /// Correlation of the free parameters over the replicas (null where a parameter does
    /// not vary).
    pub correlation: Vec<Vec<Option<f64>>>,
    pub warnings: Vec<String>,
    #[serde(deserialize_with = "nan_if_null")]
    pub seconds: f64,
    pub evaluations: u64,
    /// Backend evaluators the replicas needed (each optimizer step is one submission per
    /// evaluator).
    pub batches: usize,
}
