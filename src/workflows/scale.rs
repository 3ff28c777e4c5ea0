//! `bench --scale`: how the cost of a fit's work grows with the data. For data sets of
//! 1e3 … 1e7 samples (random isotropic directions, every direction in every channel), one
//! cheap model and expensive ones, on each backend in the same run: the throughput of
//! the two kinds of batch a fit sends (Levenberg–Marquardt's normal equations of 16
//! restarts, and the costs of the 128 screened starting points), and the process's peak
//! resident memory while the batch ran, data included.

use crate::bsdf::Model;
use crate::data::{Dataset, Kind};
use crate::engine::{Backend, Problem};
use crate::workflows::synth::{synthesize, Noise};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;
use std::time::Instant;

/// The models `bench --scale` measures by default: a cheap one and two expensive ones.
pub const DEFAULT_MODELS: [&str; 3] = ["lambert", "fa(eon)", "btdf(gg)"];
/// The data sizes (samples) it measures by default.
pub const DEFAULT_SIZES: [usize; 5] = [1_000, 10_000, 100_000, 1_000_000, 10_000_000];
/// Restarts of the LM batch (the fit's default), and random points screened per restart.
const RESTARTS: usize = 16;
const SCREEN: usize = 8;

#[derive(Clone, Debug, Serialize)]
pub struct ScaleRow {
    pub model: String,
    pub backend: String,
    pub samples: usize,
    /// Candidates of the normal-equation batch: 16 restarts × (P + 1).
    pub normal_candidates: usize,
    /// Model-sample evaluations per second of that batch (its reduction included).
    pub normal_evals_per_s: f64,
    /// Candidates of the costs batch: 16 restarts × 8 screened points.
    pub cost_candidates: usize,
    pub cost_evals_per_s: f64,
    /// Seconds to prepare the evaluator (uploads, tables).
    pub setup_s: f64,
    /// The process's peak resident memory (MiB) while the evaluator was prepared and
    /// both batches ran, the data included (Linux; null elsewhere).
    pub peak_mib: Option<f64>,
}

/// Random isotropic data for `kind`: about `samples` samples, every direction in every
/// channel (3 for a BRDF, 1 for a BTDF), θi and θo up to 85°, values of `spec` at its
/// default parameters with 2 % noise.
pub fn scale_dataset(spec: &str, kind: Kind, samples: usize, seed: u64) -> anyhow::Result<Dataset> {
    let wavelengths: Vec<f64> = match kind {
        Kind::Brdf => vec![450.0, 550.0, 650.0],
        Kind::Btdf => vec![633.0],
    };
    let model = Model::parse(spec, wavelengths.len())?;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let directions = samples.div_ceil(wavelengths.len()).max(1);
    let rows: Vec<[f64; 4]> = (0..directions)
        .map(|_| {
            let ti = rng.random_range(0.0..85.0);
            let to = rng.random_range(0.0..85.0);
            [ti, 0.0, to, rng.random_range(0.0..360.0)]
        })
        .collect();
    synthesize(
        &model,
        &model.defaults(),
        &rows,
        &wavelengths,
        Noise {
            rel: 0.02,
            abs: 1e-4,
        },
        seed,
        &format!("random isotropic, {samples} samples"),
    )
    .map_err(anyhow::Error::msg)
}

/// Reset the process's peak resident memory to its current resident memory (Linux's
/// `/proc/self/clear_refs`, value 5); false where that is not possible.
pub fn reset_peak_memory() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

/// The process's peak resident memory in MiB (`VmHWM` of `/proc/self/status`).
pub fn peak_memory_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// Measure one model on one backend over `data`: each batch repeated until
/// `min_seconds` have passed (at least once).
pub fn measure_scale(
    spec: &str,
    data: &Dataset,
    backend: &dyn Backend,
    min_seconds: f64,
) -> anyhow::Result<ScaleRow> {
    let model = Model::for_data(spec, data)?;
    let problem = Problem {
        model: &model,
        data,
        loss: crate::workflows::bench::bench_loss(data.kind),
    };
    let reset = reset_peak_memory();
    let t0 = Instant::now();
    let mut eval = backend.prepare(problem)?;
    let setup_s = t0.elapsed().as_secs_f64();
    let p = model.dim;
    let k = data.len() as f64;
    // LM's batch: 16 restarts, each with its P forward-difference neighbours.
    let points: Vec<f64> = crate::optim::random_starts(p, RESTARTS, 3)
        .into_iter()
        .flatten()
        .collect();
    let h = 1e-3;
    let steps: Vec<f64> = points
        .iter()
        .map(|&x| if x + h <= 1.0 { h } else { -h })
        .collect();
    let normal: Vec<f64> = crate::optim::difference_points(&points, &steps, p)
        .chunks(p)
        .flat_map(|u| model.from_unit(u))
        .collect();
    let normal_candidates = RESTARTS * (p + 1);
    let normal_evals_per_s = repeat(min_seconds, normal_candidates as f64 * k, || {
        eval.normal_equations(&normal, &steps).map(|_| ())
    })?;
    let costs: Vec<f64> = crate::optim::random_starts(p, RESTARTS * SCREEN, 4)
        .iter()
        .flat_map(|u| model.from_unit(u))
        .collect();
    let cost_candidates = RESTARTS * SCREEN;
    let cost_evals_per_s = repeat(min_seconds, cost_candidates as f64 * k, || {
        eval.costs(&costs).map(|_| ())
    })?;
    drop(eval);
    Ok(ScaleRow {
        model: spec.to_string(),
        backend: backend.id().to_string(),
        samples: data.len(),
        normal_candidates,
        normal_evals_per_s,
        cost_candidates,
        cost_evals_per_s,
        setup_s,
        peak_mib: if reset { peak_memory_mib() } else { None },
    })
}

/// Evaluations per second of `batch` (`evals` each), repeated until `min_seconds`.
fn repeat(
    min_seconds: f64,
    evals: f64,
    mut batch: impl FnMut() -> anyhow::Result<()>,
) -> anyhow::Result<f64> {
    let t0 = Instant::now();
    let mut reps = 0u64;
    while reps == 0 || t0.elapsed().as_secs_f64() < min_seconds {
        batch()?;
        reps += 1;
    }
    Ok(reps as f64 * evals / t0.elapsed().as_secs_f64())
}

/// The rows as a table, with the GPU/CPU ratio of each measurement where both backends
/// measured it.
pub fn table(rows: &[ScaleRow]) -> String {
    let mut s = format!(
        "{:<12} {:>8} {:>10} {:>14} {:>14} {:>9} {:>10} {:>12}\n",
        "model",
        "backend",
        "samples",
        "LM evals/s",
        "cost evals/s",
        "setup s",
        "peak MiB",
        "LM vs cpu"
    );
    for r in rows {
        // Each engine's LM rate over the CPU reference's at the same model and size.
        let ratio = rows
            .iter()
            .find(|o| o.backend == "cpu" && o.model == r.model && o.samples == r.samples)
            .filter(|_| r.backend != "cpu")
            .map_or("".to_string(), |c| {
                format!("{:.2}×", r.normal_evals_per_s / c.normal_evals_per_s)
            });
        s += &format!(
            "{:<12} {:>8} {:>10} {:>14.3e} {:>14.3e} {:>9.2} {:>10} {:>12}\n",
            r.model,
            r.backend,
            r.samples,
            r.normal_evals_per_s,
            r.cost_evals_per_s,
            r.setup_s,
            r.peak_mib.map_or("-".to_string(), |m| format!("{m:.0}")),
            ratio
        );
    }
    s
}
