//! The discrepancy workflow (docs/diagnose.md, issue #6): fit a start model, decide whether the
//! misfit exceeds the uncertainties, say in words where the model and the measurement
//! disagree, fit every applicable extension of the model from the effect catalogue, adopt
//! the best significant one, name its effect, and repeat until nothing significant remains.
//!
//! Statistics (all on χ² = Σ ((y′ − y)/u)², K samples, P parameters):
//! - Consistency: χ² against the χ² distribution with K − P degrees of freedom; the misfit
//!   exceeds the uncertainties when P(χ²_{K−P} ≥ χ²) < α.
//! - A nested extension (the current model is the extension at some parameter values, e.g.
//!   σ = 0 in `on`, k_s = 0 and η = 1 in `fa(B)`, S = 1 in `+scale`) is tested with the
//!   F statistic F = ((χ²₀ − χ²₁)/ΔP) / (χ²₁/(K − P₁)) against F(ΔP, K − P₁): it uses the
//!   extension's own residual variance, so a model that still misses some other effect
//!   (χ²_red ≫ 1) does not make every extension look significant, as the plain
//!   likelihood-ratio test Δχ² ~ χ²(ΔP) would. The level is Bonferroni-corrected over the
//!   candidates of a round (α/m), and the Bayesian information criterion
//!   BIC = χ² + P ln K, with the χ² scaled by max(1, χ²_red) of the extension, must fall.
//! - A non-nested swap (`beckmann`/`gg` → `tr`) has no F test; it must lower the scaled
//!   BIC by more than 10 (Kass & Raftery's "very strong" evidence).
//! - Among the significant candidates the one with the lowest BIC is adopted. A candidate
//!   whose new parameters the data does not determine (no standard uncertainty, one larger
//!   than its range, or a multiple correlation above 0.999 with the other parameters) is
//!   never adopted: "never add an effect that the data cannot distinguish".
//! - The path is greedy; when it ends with the misfit still exceeding the uncertainties,
//!   each step is revisited once with the best significant candidate of another effect
//!   (see [`diagnose`]).
//!
//! Extension fits start from the current optimum embedded in the larger model ([`embed`]:
//! a nested extension can then only improve) plus seeded, screened random starts, with
//! Levenberg–Marquardt on χ² by default. A round's candidates are fitted on one backend
//! (the GPU when present), each fit sending all its restarts as one batch; the candidates
//! go one after the other (on lavapipe or the CPU backend concurrency only adds
//! contention: 12 s instead of 3.4 s for the 7 extensions of `lambert` on 552 samples),
//! or concurrently with `parallel` (`--parallel`).
//!
//! Files: `effects` (the effect catalogue), `extensions` (candidate extensions of a spec
//! and the embedding of the current optimum), `fit` (the fits), `regions` (residual
//! statistics over angular regions and their sentences), `score` (F test, BIC,
//! identifiability, consistency), `path` (adoption, greedy path, backtracking: the
//! [`diagnose`] driver), `json` (docs/output.md output), `report` (SVG panels and HTML),
//! `request` (a diagnosis as its callers ask for it, checked before any fit).

pub mod battery;
mod effects;
mod explore;
mod extensions;
mod fit;
mod json;
pub mod misspecified;
mod path;
mod prune;
mod regions;
mod report;
mod request;
mod score;
mod symmetry;
#[cfg(test)]
mod testdata;

pub use effects::Effect;
pub use explore::subsample;
pub use extensions::{embed, extensions, render_spec, Candidate};
pub use fit::{bootstrap_p, fit_model, FitResult};
pub use path::diagnose;
pub use regions::{describe_regions, region_stats, RegionStat};
pub use report::{factor_panels, residual_panel, staircase_panel, write_report};
pub use request::DiagnoseRequest;
pub use score::{irregular_null, PTest, Scored};
pub use symmetry::FrameTest;

use crate::engine::loss::{Loss, Metric, Weights};
use crate::inference::fit::Optimizer;

/// Options of a diagnosis (saved as JSON with a collection's diagnosis).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct DiagnoseOptions {
    /// The loss that drives each fit (χ² unless told otherwise); the tests always use χ².
    pub loss: Loss,
    pub optimizer: Optimizer,
    /// Random restarts per fit (the embedded current optimum is one more start).
    pub restarts: usize,
    pub seed: u64,
    /// Random draws per restart, screened to the best `restarts` (as `fit`).
    pub screen: usize,
    /// Significance level of the consistency test and (Bonferroni-corrected) of the F tests.
    pub alpha: f64,
    /// Most effects to add (the search of the catalogue's effects is bounded by it).
    pub max_steps: usize,
    /// Steps a path may take beyond `max_steps` when its last step took a data-driven
    /// factor: only the factors it lacks (`+ndf`, `+fresnel`, `+body`), so the budget does
    /// not cut a path between two factors. 0: the path stops at `max_steps` as any other.
    pub factors_past_max_steps: usize,
    /// Stop as soon as χ²_red is consistent with the uncertainties (docs/diagnose.md). Turning it
    /// off makes every round fit and test the candidates anyway (used to measure the false
    /// positive rate of the F/BIC gates on their own).
    pub stop_when_consistent: bool,
    /// When the greedy path ends inconsistent, revisit each step once with the best
    /// candidate of another effect and keep the path with the lowest final BIC.
    pub backtrack: bool,
    /// Fit a round's candidates concurrently (one thread each) on the shared backend;
    /// otherwise one after the other, each fit batching all its restarts.
    pub parallel: bool,
    /// The parametric bootstrap that calibrates the p-values of extensions whose null is
    /// irregular (`--bootstrap`, `--bootstrap-restarts`); 0 replicates: the nominal F test.
    pub bootstrap: crate::inference::bootstrap::BootstrapOptions,
    /// Calibrate every candidate whose own verdict depends on its bootstrap, even where the
    /// round adopts the same candidate whatever that verdict (by default such tests are
    /// deferred, and run only if a backtrack needs them).
    pub calibrate_all: bool,
    /// `--fix`, `--bounds`, `--prior`, applied to every model of the path that has the
    /// parameter named (a fixed value stays fixed in every extension).
    pub constraints: crate::inference::constraints::ConstraintSpec,
    /// Data with more samples than this (and a quarter) are explored on a stratified
    /// subsample of this many, and the path found is confirmed on all of them
    /// (`explore`); 0: always on all data.
    pub explore: usize,
    /// Whether the data-driven factors (`+ndf`, `+fresnel`, `+body`) are tried where no
    /// analytic path ends consistent (at the ends of the analytic paths, in a round where
    /// no analytic effect is significant). On for `diagnose`; the battery, which measures
    /// the catalogue's effects, turns it off.
    pub data_driven: bool,
}

impl Default for DiagnoseOptions {
    fn default() -> Self {
        DiagnoseOptions {
            loss: Loss::new(Metric::Chi2, Weights::Uniform),
            optimizer: Optimizer::Lm,
            restarts: crate::workflows::fit::DEFAULT_RESTARTS,
            seed: 1,
            screen: 8,
            alpha: 0.01,
            max_steps: 4,
            factors_past_max_steps: 2,
            stop_when_consistent: true,
            backtrack: true,
            parallel: false,
            bootstrap: Default::default(),
            calibrate_all: false,
            constraints: Default::default(),
            explore: 8000,
            data_driven: true,
        }
    }
}

/// One step of a diagnosis: the start fit (effect None) or an adopted extension.
#[derive(Clone, Debug)]
pub struct Step {
    pub model: String,
    pub effect: Option<Effect>,
    pub chi2_red: f64,
    pub loss: f64,
    pub evidence: String,
    pub fit: FitResult,
    /// The candidates fitted after this step (empty when the workflow stopped here
    /// before fitting any).
    pub candidates: Vec<Scored>,
    /// Where the time of that round of candidates went (None without a round).
    pub round_seconds: Option<RoundSeconds>,
    /// Effects of earlier steps this step dropped (the backward elimination after a
    /// data-driven factor, [`prune`]); the diagnosis does not name them.
    pub removed: Vec<Effect>,
}

/// Wall-clock seconds of a round of candidates, by stage.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct RoundSeconds {
    /// The candidates' multi-start fits (zero for those met before and cached).
    pub fits: f64,
    /// Scoring them: tests, BIC, identifiability (covariances), removal shares.
    pub scoring: f64,
    /// The bootstraps that calibrated irregular nulls.
    pub bootstraps: f64,
}

/// The outcome of [`diagnose`].
#[derive(Clone, Debug)]
pub struct Diagnosis {
    pub start_model: String,
    pub final_model: String,
    pub effects: Vec<Effect>,
    pub steps: Vec<Step>,
    pub alpha: f64,
    pub backend: String,
}

impl Diagnosis {
    /// The diagnosis of a path of steps: its last model, and each effect named once, in
    /// the order first adopted.
    fn of_steps(start_model: String, steps: Vec<Step>, alpha: f64, backend: String) -> Diagnosis {
        let mut effects: Vec<Effect> = Vec::new();
        for e in steps.iter().filter_map(|s| s.effect) {
            if !effects.contains(&e) {
                effects.push(e);
            }
        }
        // An effect stays named while one of its steps stands: a path may add one twice (a
        // specular lobe as `fa(B)`, then a second one as `+coat`) and drop one of them.
        effects.retain(|e| {
            let adopted = steps.iter().filter(|s| s.effect == Some(*e)).count();
            let dropped: usize = steps
                .iter()
                .map(|s| s.removed.iter().filter(|r| *r == e).count())
                .sum();
            adopted > dropped
        });
        Diagnosis {
            start_model,
            final_model: steps.last().expect("a step").model.clone(),
            effects,
            steps,
            alpha,
            backend,
        }
    }
}

/// The checks `diagnose` makes before any fit, for every caller (the command line, the
/// Python module): the loss for the data's kind, the significance level, the start
/// model, and every constrained name a parameter of the start model (extensions keep its
/// names). Returns the loss and the start model.
pub fn check_start(
    data: &crate::data::Dataset,
    model: &str,
    metric: Metric,
    weights: Weights,
    alpha: f64,
    constraints: &crate::inference::constraints::ConstraintSpec,
) -> anyhow::Result<(Loss, crate::bsdf::Model)> {
    let loss = crate::workflows::fit::loss_for(metric, weights, data.kind)?;
    if !(alpha > 0.0 && alpha < 1.0) {
        return Err(crate::choice::field_error(format!(
            "{{alpha}} must be in (0, 1), got {alpha}"
        )));
    }
    let start = crate::bsdf::Model::for_data(model, data)
        .map_err(|e| crate::workflows::fit::model_error(&e))?;
    let strict = crate::inference::constraints::ConstraintSpec {
        lenient: false,
        ..constraints.clone()
    };
    crate::inference::constraints::Constraints::resolve(&start, &strict, false)?;
    Ok((loss, start))
}
