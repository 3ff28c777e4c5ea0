//! Backends evaluate a batch of candidate parameter vectors against a dataset and a loss.
//!
//! One trait, two implementations: [`cpu::CpuBackend`] (plain Rust, f64, rayon — the
//! reference) and [`gpu::GpuBackend`] (wgpu compute, f32). Optimizers never see a backend:
//! they see an [`Evaluator`] prepared for one problem.

use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::Loss;

pub mod cpu;
pub mod gpu;
pub mod loss;
pub mod wgsl;

/// One fitting problem: a model compiled for the dataset's channels, the data, the loss.
#[derive(Clone, Copy)]
pub struct Problem<'a> {
    pub model: &'a Model,
    pub data: &'a Dataset,
    pub loss: Loss,
}

/// A backend turns a problem into an evaluator (compiling kernels and uploading data once).
pub trait Backend: Send + Sync {
    /// Human-readable name, e.g. `cpu (rayon, 2 threads)` or `gpu (llvmpipe, Vulkan)`.
    fn name(&self) -> String;
    /// Short machine name: `cpu` or `gpu`.
    fn id(&self) -> &'static str;
    /// Unit roundoff of the arithmetic the backend evaluates models in (f64 or f32):
    /// finite differences must step well above √ε of it to mean anything.
    fn unit_roundoff(&self) -> f64 {
        f64::EPSILON / 2.0
    }
    fn prepare<'a>(&'a self, problem: Problem<'a>) -> anyhow::Result<Box<dyn Evaluator + 'a>>;
}

/// Evaluates batches of physical parameter vectors (N × P, row-major) for one problem.
pub trait Evaluator {
    /// P, the length of one parameter vector.
    fn dim(&self) -> usize;
    /// The loss of each of the N candidates (NaN where the model is not finite; the
    /// optimizers treat NaN as +∞).
    fn costs(&mut self, params: &[f64]) -> anyhow::Result<Vec<f64>>;
    /// Model values y′ for each candidate and sample (N × K, row-major).
    fn values(&mut self, params: &[f64]) -> anyhow::Result<Vec<f64>>;
    /// Levenberg–Marquardt normal equations for N groups of P + 1 candidates: `params`
    /// (N × (P + 1) × P, physical) holds each group's point, then the point moved along
    /// each parameter by the signed unit-box step in `steps` (N × P). Returns JᵀJ, Jᵀr and
    /// Σr² of the loss's weighted residuals r_k = √w_k (g(y′_k) − g(y_k)), the Jacobian
    /// J_kj = (r_k(moved_j) − r_k(point)) / step_j taken in the optimizer's coordinates.
    fn normal_equations(
        &mut self,
        params: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<crate::optim::NormalEquations>>;
    /// Model-sample evaluations performed so far (one model at one sample and channel).
    fn evaluations(&self) -> u64;
}

/// Normal equations of groups of P + 1 candidates from their model values (N·(P + 1) × K)
/// and the unit-box steps (N × P), through the loss's weighted residuals.
pub fn normal_equations_from_values(
    values: &[f64],
    terms: &crate::engine::loss::LossTerms,
    steps: &[f64],
    p: usize,
) -> Vec<crate::optim::NormalEquations> {
    let k = terms.y.len();
    values
        .chunks(k * (p + 1))
        .zip(steps.chunks(p))
        .map(|(vals, h)| {
            let rows: Vec<f64> = vals
                .chunks(k)
                .flat_map(|row| row.iter().enumerate().map(|(j, &v)| terms.residual(j, v)))
                .collect();
            crate::optim::NormalEquations::from_residuals(&rows, h, k)
        })
        .collect()
}

/// Which backend a command should use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BackendChoice {
    /// The GPU when a Vulkan adapter exists, else the CPU (with a notice).
    Auto,
    /// The GPU engine; an error when no adapter exists.
    Gpu,
    /// The CPU reference.
    Cpu,
}

/// Pick a backend. `notice` receives one-line messages for the user (which adapter, or
/// why the CPU is used).
pub fn select(
    choice: BackendChoice,
    notice: &mut dyn FnMut(String),
) -> anyhow::Result<Box<dyn Backend>> {
    match choice {
        BackendChoice::Cpu => Ok(Box::new(cpu::CpuBackend::new())),
        BackendChoice::Gpu => {
            let g = gpu::GpuBackend::new().map_err(|e| anyhow::anyhow!("--backend gpu: {e}"))?;
            notice(format!("using {}", g.name()));
            Ok(Box::new(g))
        }
        BackendChoice::Auto => match gpu::GpuBackend::new() {
            Ok(g) => {
                notice(format!("using {}", g.name()));
                Ok(Box::new(g))
            }
            Err(e) => {
                notice(format!("no GPU ({e}); using the CPU reference"));
                Ok(Box::new(cpu::CpuBackend::new()))
            }
        },
    }
}
