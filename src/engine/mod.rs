//! Backends evaluate a batch of candidate parameter vectors against a dataset and a loss.
//!
//! One trait, three implementations: [`cpu::CpuBackend`] (plain Rust, f64, rayon — the
//! reference), [`simd::SimdBackend`] (the same models in SIMD lanes, f32 or f64) and
//! [`gpu::GpuBackend`] (wgpu compute, f32). Optimizers never see a backend:
//! they see an [`Evaluator`] prepared for one problem or for a batch of independent
//! problems that share a model (many fits per dispatch).

use crate::bsdf::Model;
use crate::data::Dataset;
use crate::engine::loss::Loss;

pub mod cpu;
pub mod gpu;
pub mod loss;
pub mod reduce;
pub mod simd;
pub mod wgsl;

pub use gpu::fault::{device_fault, DeviceFault};
pub use reduce::{normal_equations_of_values, RowTerms, ValueWindow, Values, WindowPart};

/// The order in which both backends walk a problem's samples: by cos θi, then cos θo
/// (a stable sort, so file order within one pair).
///
/// Why: models keep one-entry memos of what depends on μi or μo alone (micrograin's
/// G1(μ)/μ, whose Λ series is most of `rmg`'s and `dmg`'s cost; the Fresnel
/// transmittances), and a memo serves a run of consecutive directions that repeat the
/// value. Goniometric data repeat the same few polar angles in many azimuths and planes
/// — the bundled in-plane sets hold 128 directions but 71 distinct (θi, θo) pairs and 9
/// values of θo — yet files list them by plane or azimuth, so θo changed at nearly every
/// direction. Walked in this order, μo changes only between pairs: `bsdfit bench
/// --models 'rmg(ggx)' --data data/w80-g40-full.csv` (220 directions, 127 pairs) measured
/// 1.13× the rate on lavapipe and 1.17× on the CPU reference (medians of 5 and 3 runs
/// alternated with the file order), and the default sweep took 5–7 % less time on each.
/// Both backends sum a candidate's loss terms in this order.
pub fn walk_order(data: &Dataset) -> Vec<usize> {
    let key: Vec<(f64, f64)> = data.samples.iter().map(|s| (s.wi().z, s.wo().z)).collect();
    let mut order: Vec<usize> = (0..key.len()).collect();
    order.sort_by(|&a, &b| {
        key[a]
            .0
            .total_cmp(&key[b].0)
            .then(key[a].1.total_cmp(&key[b].1))
    });
    order
}

/// One fitting problem: a model compiled for the dataset's channels, the data, the loss.
#[derive(Clone, Copy)]
pub struct Problem<'a> {
    pub model: &'a Model,
    pub data: &'a Dataset,
    pub loss: Loss,
}

/// A backend turns problems into an evaluator (compiling kernels and uploading data once).
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
    /// One evaluator for several independent problems that share one model and one loss
    /// term shape (different data sets, losses, weightings, Monte Carlo replicas): a batch may mix
    /// candidates of every problem, and is evaluated in one submission.
    fn prepare_many<'a>(
        &'a self,
        problems: &[Problem<'a>],
    ) -> anyhow::Result<Box<dyn Evaluator + 'a>>;
    /// One evaluator for one problem.
    fn prepare<'a>(&'a self, problem: Problem<'a>) -> anyhow::Result<Box<dyn Evaluator + 'a>> {
        self.prepare_many(&[problem])
    }
    /// The most samples (summed over problems) one evaluator may hold; callers with more
    /// problems split them into several evaluators.
    fn max_batch_samples(&self) -> usize {
        usize::MAX
    }
    /// Sizes and times of the device submissions made so far by every evaluator of this
    /// backend (`None` for host backends, which submit nothing).
    fn submissions(&self) -> Option<SubmissionStats> {
        None
    }
    /// Compile now what evaluating `model` will need (a hint: a device backend compiles its
    /// kernels, a host backend has nothing to do), so that a scheduler can do it ahead,
    /// on a thread of its own, while the device serves other fits.
    fn prepare_kernels(&self, _model: &Model) -> anyhow::Result<()> {
        Ok(())
    }
    /// The fault that ended a device backend's use (its device lost or hung): it then
    /// refuses all work, and callers re-run what it failed on the CPU reference. `None`
    /// for host backends, which have no device to lose.
    fn fault(&self) -> Option<DeviceFault> {
        None
    }
}

/// What a device backend's submissions looked like: how many, how large (candidates, and
/// model-sample evaluations), and how long each took from upload to read-back.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SubmissionStats {
    pub submissions: usize,
    /// Candidates (parameter vectors) per submission.
    pub candidates: Spread,
    /// Model-sample evaluations per submission (candidates × their samples and channels).
    pub evaluations: Spread,
    /// Wall seconds per submission, upload to read-back. Submissions from several
    /// threads overlap, so their sum can exceed the wall time.
    pub seconds: Spread,
    pub seconds_total: f64,
}

/// Median, 90th percentile, largest and mean of a set of figures.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Spread {
    pub median: f64,
    pub p90: f64,
    pub max: f64,
    pub mean: f64,
}

impl Spread {
    pub fn of(mut v: Vec<f64>) -> Spread {
        if v.is_empty() {
            return Spread::default();
        }
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Spread {
            median: at(0.5),
            p90: at(0.9),
            max: v[v.len() - 1],
            mean: v.iter().sum::<f64>() / v.len() as f64,
        }
    }
}

impl SubmissionStats {
    /// From (candidates, evaluations, seconds) per submission.
    pub fn of(records: &[(u32, u64, f32)]) -> SubmissionStats {
        let col = |f: &dyn Fn(&(u32, u64, f32)) -> f64| records.iter().map(f).collect();
        SubmissionStats {
            submissions: records.len(),
            candidates: Spread::of(col(&|r| r.0 as f64)),
            evaluations: Spread::of(col(&|r| r.1 as f64)),
            seconds: Spread::of(col(&|r| r.2 as f64)),
            seconds_total: records.iter().map(|r| r.2 as f64).sum(),
        }
    }
}

/// Check that problems can share one evaluator: same model, and losses of one term shape
/// (their finishes may differ: each problem's sum is finished on its own).
pub fn check_shared(problems: &[Problem]) -> anyhow::Result<()> {
    let first = problems
        .first()
        .ok_or_else(|| anyhow::anyhow!("no problem to evaluate"))?;
    for p in &problems[1..] {
        anyhow::ensure!(
            std::ptr::eq(p.model, first.model)
                || (p.model.spec == first.model.spec
                    && p.model.channels == first.model.channels
                    && p.model.axes == first.model.axes),
            "problems batched together must share one model ({} vs {})",
            first.model.spec,
            p.model.spec
        );
        anyhow::ensure!(
            p.loss.metric.term() == first.loss.metric.term(),
            "problems batched together must share one loss term shape ({} vs {})",
            first.loss.metric,
            p.loss.metric
        );
    }
    Ok(())
}

/// Evaluates batches of physical parameter vectors (N × P, row-major) for one or more
/// problems. The plain methods address problem 0; the `_of` methods take, per candidate
/// (per group for the normal equations), the index of its problem.
///
/// **Streamed.** What a batch returns is reduced over the samples inside the backend:
/// a loss per candidate ([`Self::costs_of`]), the normal equations per group
/// ([`Self::normal_equations_of`]); model values leave an evaluator only window by
/// window ([`Self::value_windows`]), for the host reductions of [`reduce`]. So memory
/// grows with candidates × parameters², never with candidates × samples.
pub trait Evaluator {
    /// P, the length of one parameter vector.
    fn dim(&self) -> usize;
    /// How many problems the evaluator holds.
    fn problems(&self) -> usize {
        1
    }
    /// K_q, the sample count of problem q.
    fn samples_of(&self, q: usize) -> usize;
    /// The loss of each of the N candidates (NaN where the model is not finite; the
    /// optimizers treat NaN as +∞).
    fn costs_of(&mut self, owners: &[usize], params: &[f64]) -> anyhow::Result<Vec<f64>>;
    /// Hands the candidates' model values to `visit`, a window of rows at a time, in the
    /// evaluator's row order ([`ValueWindow`]: each window says which rows of which
    /// problem each candidate's values are, and carries every problem's loss constants in
    /// that order). Every row of every candidate's problem is visited exactly once.
    fn value_windows(
        &mut self,
        owners: &[usize],
        params: &[f64],
        visit: &mut dyn FnMut(&ValueWindow) -> anyhow::Result<()>,
    ) -> anyhow::Result<()>;
    /// Levenberg–Marquardt normal equations for N groups of m + 1 candidates: `params`
    /// (N × (m + 1) × P, physical) holds each group's point, then the point moved along
    /// each of m parameters by the signed unit-box step in `steps` (N × m); `owners`
    /// gives each group's problem. Returns JᵀJ (m × m), Jᵀr and Σr² of the loss's
    /// weighted residuals r_k = √w_k (g(y′_k) − g(y_k)), the Jacobian J_kj =
    /// (r_k(moved_j) − r_k(point)) / step_j taken in the optimizer's coordinates. By
    /// default reduced on the host from the value windows ([`reduce::normal_equations`]).
    fn normal_equations_of(
        &mut self,
        owners: &[usize],
        params: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<crate::optim::NormalEquations>> {
        reduce::normal_equations(self, owners, params, steps)
    }
    /// Model values y′ of each candidate at each sample of its problem, in sample order,
    /// the candidates' rows (K_owner values each) one after the other. Allocates
    /// candidates × samples: for a fit's best point and for tests, not for optimizers.
    fn values_of(&mut self, owners: &[usize], params: &[f64]) -> anyhow::Result<Vec<f64>> {
        reduce::values_in_sample_order(self, owners, params)
    }
    /// Model-sample evaluations performed so far (one model at one sample and channel).
    fn evaluations(&self) -> u64 {
        (0..self.problems()).map(|q| self.evaluations_of(q)).sum()
    }
    /// Those of them made for problem q.
    fn evaluations_of(&self, q: usize) -> u64;
    /// Bytes read back from a device so far (0 for host backends): what a batch costs in
    /// transfers, e.g. LM's normal equations, whose sums alone come back from the GPU.
    fn read_back_bytes(&self) -> u64 {
        0
    }

    /// [`Self::costs_of`] for problem 0.
    fn costs(&mut self, params: &[f64]) -> anyhow::Result<Vec<f64>> {
        let n = params.len() / self.dim().max(1);
        self.costs_of(&vec![0; n], params)
    }
    /// [`Self::values_of`] for problem 0 (N × K, row-major).
    fn values(&mut self, params: &[f64]) -> anyhow::Result<Vec<f64>> {
        let n = params.len() / self.dim().max(1);
        self.values_of(&vec![0; n], params)
    }
    /// [`Self::normal_equations_of`] for problem 0, groups of P + 1.
    fn normal_equations(
        &mut self,
        params: &[f64],
        steps: &[f64],
    ) -> anyhow::Result<Vec<crate::optim::NormalEquations>> {
        let n = steps.len() / self.dim().max(1);
        self.normal_equations_of(&vec![0; n], params, steps)
    }
}

/// Which backend a command should use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BackendChoice {
    /// A hardware GPU when one exists, else the SIMD CPU engine (with a notice).
    Auto,
    /// The GPU engine on any Vulkan adapter (a software one too); an error when none exists.
    Gpu,
    /// The SIMD CPU engine (f32 or f64 lanes).
    Simd,
    /// The CPU reference (f64, one direction at a time): the checker.
    Cpu,
}

impl crate::choice::Choice for BackendChoice {
    const WHAT: &'static str = "backend";
    const TABLE: &'static [(Self, &'static str, &'static str)] = &[
        (
            BackendChoice::Auto,
            "auto",
            "A hardware GPU when one exists, else the SIMD CPU engine (with a notice)",
        ),
        (
            BackendChoice::Gpu,
            "gpu",
            "The GPU engine on any Vulkan adapter, a software one (lavapipe) too; an error when none exists",
        ),
        (
            BackendChoice::Simd,
            "simd",
            "The SIMD CPU engine: the models in f32 (or f64) vector lanes of the processor",
        ),
        (
            BackendChoice::Cpu,
            "cpu",
            "The CPU reference (f64, one direction at a time): the checker",
        ),
    ];
}
crate::choice::named_choice!(BackendChoice);

impl BackendChoice {
    /// The word that names it, which is also the id of the backend it selects
    /// ([`Backend::id`]) for `gpu`, `simd` and `cpu`.
    pub fn name(self) -> &'static str {
        crate::choice::Choice::name(self)
    }

    /// The choice named `name` (`auto`, `gpu`, `simd`, `cpu`).
    pub fn from_name(name: &str) -> Option<BackendChoice> {
        name.parse().ok()
    }
}

/// `text` as literal text inside a [`crate::choice::FieldError`] template.
fn escape_braces(text: &str) -> String {
    text.replace('{', "(").replace('}', ")")
}

/// Pick a backend. `notice` receives one-line messages for the user (which adapter, or
/// why the CPU is used).
pub fn select(
    choice: BackendChoice,
    notice: &mut dyn FnMut(String),
) -> anyhow::Result<Box<dyn Backend>> {
    match choice {
        BackendChoice::Cpu => Ok(Box::new(cpu::CpuBackend::new())),
        BackendChoice::Simd => {
            let s = simd::SimdBackend::new();
            notice(format!("using {}", s.name()));
            Ok(Box::new(s))
        }
        BackendChoice::Gpu => {
            let g = gpu::GpuBackend::new().map_err(|e| {
                crate::choice::field_error(format!(
                    "{{backend=gpu}}: {}",
                    escape_braces(&e.to_string())
                ))
            })?;
            notice(format!("using {}", g.name()));
            Ok(Box::new(g))
        }
        BackendChoice::Auto => {
            let why = match gpu::GpuBackend::new() {
                Ok(g) if !g.is_software() => {
                    notice(format!("using {}", g.name()));
                    return Ok(Box::new(g));
                }
                Ok(g) => format!(
                    "the only Vulkan device is a software one, {} (--backend gpu runs the kernels there)",
                    g.adapter_name()
                ),
                Err(e) => format!("no GPU ({e})"),
            };
            let s = simd::SimdBackend::new();
            notice(format!("{why}; using {}", s.name()));
            Ok(Box::new(s))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{cpu, simd, Backend, BackendChoice, Spread, SubmissionStats};

    #[test]
    fn spreads_take_the_nearest_rank_and_the_mean() {
        let s = Spread::of((1..=10).rev().map(f64::from).collect());
        // Ranks (n − 1)·q rounded: 4.5 → 5 (the 6th value) and 8.1 → 8 (the 9th).
        assert_eq!((s.median, s.p90, s.max, s.mean), (6.0, 9.0, 10.0, 5.5));
        let empty = Spread::of(Vec::new());
        assert_eq!((empty.median, empty.max, empty.mean), (0.0, 0.0, 0.0));
        let log = SubmissionStats::of(&[(2, 100, 0.5), (4, 300, 1.5)]);
        assert_eq!(log.submissions, 2);
        assert_eq!((log.candidates.max, log.evaluations.mean), (4.0, 200.0));
        assert_eq!(log.seconds_total, 2.0);
    }

    /// Names round-trip, and `gpu` and `cpu` name the backends they select.
    #[test]
    fn backend_choice_names_are_the_option_values() {
        for c in [
            BackendChoice::Auto,
            BackendChoice::Gpu,
            BackendChoice::Simd,
            BackendChoice::Cpu,
        ] {
            assert_eq!(BackendChoice::from_name(c.name()), Some(c));
        }
        assert_eq!(BackendChoice::from_name("tpu"), None);
        assert_eq!(cpu::CpuBackend::new().id(), BackendChoice::Cpu.name());
        assert_eq!(simd::SimdBackend::new().id(), BackendChoice::Simd.name());
    }
}
