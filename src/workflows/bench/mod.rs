//! Throughput of the backends: model-sample evaluations per second (one eval = one model
//! at one sample and channel, the loss term and the reduction included), CPU and GPU in
//! the same run, at the batch sizes a sweep uses (restarts × (2P + 1) candidates); and for
//! `bench --sweep`, the timing of whole sweeps and the comparison of their results
//! ([`sweeps`]).

use crate::bsdf::Model;
use crate::data::{Dataset, Kind};
use crate::engine::loss::{Loss, Metric, Weights};
use crate::engine::{Backend, Problem};
use crate::workflows::synth::{geometry, synthesize, Noise};
use serde::Serialize;
use std::time::Instant;

pub mod sweeps;
pub use sweeps::*;

#[derive(Clone, Debug, Serialize)]
pub struct BenchRow {
    pub model: String,
    pub backend: String,
    /// The data measured on: `synthetic GEOMETRY` or the file given with `--data`.
    pub data: String,
    pub samples: usize,
    pub candidates: usize,
    pub evals_per_s: f64,
    /// Worker threads of the CPU backend (null for the GPU): `evals_per_s / threads` is
    /// the per-thread rate on an otherwise idle machine.
    pub threads: Option<usize>,
    /// Evaluations per second of the process's CPU time (all threads, from
    /// `/proc/self/stat`; null elsewhere and for the GPU): the rate of one busy thread,
    /// which other jobs sharing the cores do not lower as they lower `evals_per_s`.
    pub evals_per_cpu_s: Option<f64>,
}

/// CPU time (user + system, all threads) this process has used, in seconds, where
/// `/proc/self/stat` exists (Linux): fields 14 and 15, in clock ticks of 1/100 s (the
/// USER_HZ Linux exposes on every architecture).
pub fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The command name (field 2) is in parentheses and may hold spaces: count from after it.
    let rest = &stat[stat.rfind(')')? + 1..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i)?.parse::<u64>().ok();
    // `rest` starts at field 3, so fields 14 and 15 are its 11th and 12th.
    Some((ticks(11)? + ticks(12)?) as f64 / 100.0)
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
        &format!("synthetic {geo}"),
    )
    .map_err(anyhow::Error::msg)
}

/// The loss the benchmarks evaluate: RMSE for a BRDF, the plain L2 of f for a BTDF
/// (uniform weights; every sum-of-squares loss costs the same).
pub fn bench_loss(kind: Kind) -> Loss {
    let metric = if kind == Kind::Brdf {
        Metric::Rmse
    } else {
        Metric::F
    };
    Loss::new(metric, Weights::Uniform)
}

/// Measure one model on one backend over `data` (a [`bench_dataset`] or a user's file):
/// repeat the batch until `min_seconds` have passed.
pub fn measure(
    model_spec: &str,
    data: &Dataset,
    backend: &dyn Backend,
    restarts: usize,
    min_seconds: f64,
) -> anyhow::Result<BenchRow> {
    let model = Model::for_data(model_spec, data)?;
    anyhow::ensure!(
        model.kind == data.kind,
        "{} is a {} model but the data are {}",
        model.spec,
        model.kind,
        data.kind
    );
    let candidates = restarts * (2 * model.dim + 1);
    let problem = Problem {
        model: &model,
        data,
        loss: bench_loss(data.kind),
    };
    let mut eval = backend.prepare(problem)?;
    let starts = crate::optim::random_starts(model.dim, candidates, 7);
    let params: Vec<f64> = starts.iter().flat_map(|u| model.from_unit(u)).collect();
    eval.costs(&params)?; // warm-up: pipeline creation, first allocation
    let t0 = Instant::now();
    let cpu0 = process_cpu_seconds();
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
    let evals = reps as f64 * candidates as f64 * data.len() as f64;
    // Host backends: their rate per thread and per CPU-second mean something.
    let is_cpu = backend.submissions().is_none();
    let cpu_secs = match (cpu0, process_cpu_seconds()) {
        // At least 10 ticks, so that the tick's rounding stays below 10 %.
        (Some(a), Some(b)) if is_cpu && b - a >= 0.1 => Some(b - a),
        _ => None,
    };
    Ok(BenchRow {
        model: model_spec.to_string(),
        backend: backend.id().to_string(),
        data: data.source.display().to_string(),
        samples: data.len(),
        candidates,
        evals_per_s: evals / secs,
        threads: is_cpu.then(rayon::current_num_threads),
        evals_per_cpu_s: cpu_secs.map(|c| evals / c),
    })
}

/// Median over models of GPU evals/s ÷ CPU evals/s, from rows of both backends.
pub fn median_speedup(rows: &[BenchRow]) -> Option<f64> {
    median_ratio(rows, "gpu", "cpu")
}

/// Median over models of evals/s on backend `over` ÷ evals/s on backend `under`.
pub fn median_ratio(rows: &[BenchRow], over: &str, under: &str) -> Option<f64> {
    let mut ratios: Vec<f64> = rows
        .iter()
        .filter(|r| r.backend == over)
        .filter_map(|g| {
            rows.iter()
                .find(|c| c.backend == under && c.model == g.model)
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

// ---------------------------------------------------------------------------------------
// `bench --sweep`: the sweep timed once per backend, and the two backends' results compared
