//! Throughput of the backends: model-sample evaluations per second (one eval = one model
//! at one sample and channel, the loss term and the reduction included), CPU and GPU in
//! the same run, at the batch sizes a sweep uses (restarts × (2P + 1) candidates).

use crate::bsdf::Model;
use crate::data::{Dataset, Kind};
use crate::engine::loss::{Loss, Metric, Weights};
use crate::engine::{Backend, Problem};
use crate::workflows::synth::{geometry, synthesize, Noise};
use serde::Serialize;
use std::time::Instant;

#[derive(Clone, Debug, Serialize)]
pub struct BenchRow {
    pub model: String,
    pub backend: String,
    pub samples: usize,
    pub candidates: usize,
    pub evals_per_s: f64,
}

/// A dataset of the model's kind for benchmarking: the paper's BRDF geometry with three
/// channels, or the oblique BTDF geometry with one.
pub fn bench_dataset(model_spec: &str, kind: Kind) -> anyhow::Result<Dataset> {
    let (geo, wl): (&str, Vec<f64>) = match kind {
        Kind::Brdf => ("inplane5", vec![450.0, 550.0, 650.0]),
        Kind::Btdf => ("oblique", vec![633.0]),
    };
    let model = Model::parse(model_spec, wl.len())?;
    let (_, rows) = geometry(geo).map_err(anyhow::Error::msg)?;
    synthesize(
        &model,
        &model.defaults(),
        &rows,
        &wl,
        Noise {
            rel: 0.01,
            abs: 1e-4,
        },
        1,
        "bench",
    )
    .map_err(anyhow::Error::msg)
}

/// Measure one model on one backend: repeat the batch until `min_seconds` have passed.
pub fn measure(
    model_spec: &str,
    kind: Kind,
    backend: &dyn Backend,
    restarts: usize,
    min_seconds: f64,
) -> anyhow::Result<BenchRow> {
    let data = bench_dataset(model_spec, kind)?;
    let model = Model::parse(model_spec, data.channel_count())?;
    let candidates = restarts * (2 * model.dim + 1);
    let metric = if kind == Kind::Brdf {
        Metric::Rmse
    } else {
        Metric::F
    };
    let problem = Problem {
        model: &model,
        data: &data,
        loss: Loss::new(metric, Weights::Uniform),
    };
    let mut eval = backend.prepare(problem)?;
    let starts = crate::optim::random_starts(model.dim, candidates, 7);
    let params: Vec<f64> = starts.iter().flat_map(|u| model.from_unit(u)).collect();
    eval.costs(&params)?; // warm-up: pipeline creation, first allocation
    let t0 = Instant::now();
    let mut reps = 0u64;
    while reps == 0 || t0.elapsed().as_secs_f64() < min_seconds {
        let c = eval.costs(&params)?;
        anyhow::ensure!(
            c.len() == candidates,
            "backend returned {} costs for {candidates} candidates",
            c.len()
        );
        reps += 1;
    }
    let secs = t0.elapsed().as_secs_f64();
    Ok(BenchRow {
        model: model_spec.to_string(),
        backend: backend.id().to_string(),
        samples: data.len(),
        candidates,
        evals_per_s: (reps as f64 * candidates as f64 * data.len() as f64) / secs,
    })
}

/// Median over models of GPU evals/s ÷ CPU evals/s, from rows of both backends.
pub fn median_speedup(rows: &[BenchRow]) -> Option<f64> {
    let mut ratios: Vec<f64> = rows
        .iter()
        .filter(|r| r.backend == "gpu")
        .filter_map(|g| {
            rows.iter()
                .find(|c| c.backend == "cpu" && c.model == g.model)
                .map(|c| g.evals_per_s / c.evals_per_s)
        })
        .collect();
    if ratios.is_empty() {
        return None;
    }
    ratios.sort_by(|a, b| a.total_cmp(b));
    let n = ratios.len();
    Some(if n % 2 == 1 {
        ratios[n / 2]
    } else {
        0.5 * (ratios[n / 2 - 1] + ratios[n / 2])
    })
}
