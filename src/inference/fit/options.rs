//! What a fit is asked to do: the optimizer and its settings, restarts, seeds and
//! starting points, the f64 polish and the user's constraints.

use super::smoothness::Smoothness;
use crate::inference::constraints::ConstraintSpec;
use crate::optim::{compass, lm};
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Optimizer {
    /// Compass search (Kolda, Lewis, Torczon 2003), BBM's optimizer; any loss.
    Compass,
    /// Levenberg–Marquardt; sum-of-squares losses only.
    Lm,
}

impl crate::choice::Choice for Optimizer {
    const WHAT: &'static str = "optimizer";
    const TABLE: &'static [(Self, &'static str, &'static str)] = &[
        (
            Optimizer::Compass,
            "compass",
            "Compass search (Kolda, Lewis, Torczon 2003), BBM's optimizer; any loss",
        ),
        (
            Optimizer::Lm,
            "lm",
            "Levenberg–Marquardt; sum-of-squares losses only",
        ),
    ];
}
crate::choice::named_choice!(Optimizer);

#[derive(Clone, Debug)]
pub struct FitOptions {
    pub optimizer: Optimizer,
    pub restarts: usize,
    pub seed: u64,
    /// Draw this many random points per restart, evaluate them in one batch and start
    /// from the best (1 = plain random starts). Cheap, and it keeps restarts out of the
    /// flat, hopeless corners of the box that local optimizers cannot leave.
    pub screen: usize,
    /// Extra starting points (physical parameter vectors), tried before the random ones;
    /// e.g. a smaller model's optimum carried into its extension.
    pub initial_points: Vec<Vec<f64>>,
    /// One more starting point per problem of [`fit_many`](super::fit_many) (physical),
    /// tried after `initial_points`: empty, or one per data set (e.g. each bootstrap
    /// replicate's own null optimum carried into the extension, so a nested extension can
    /// only improve).
    pub problem_points: Vec<Vec<f64>>,
    pub compass: compass::CompassOptions,
    pub lm: lm::LmOptions,
    /// Levenberg–Marquardt: the restarts only find the basins, with the same settings on
    /// every backend, and the best restart of each problem is continued in f64 on the
    /// CPU reference to f64's convergence (see
    /// [`search_options`](super::polish::search_options),
    /// [`polish_in_f64`](super::polish::polish_in_f64)).
    /// Off: every restart goes to the backend's own convergence, and nothing is polished.
    pub polish: bool,
    /// `--fix`, `--bounds`, `--prior` (resolved against each model fitted).
    pub constraints: ConstraintSpec,
    /// The smoothness prior of tabulated knots (`+ndf`), where the model has any:
    /// [`Smoothness::Auto`] is resolved by [`super::fit_outcome`]; [`super::fit_many`]
    /// (sweeps) treats it as off.
    pub smoothness: Smoothness,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            optimizer: Optimizer::Compass,
            restarts: 32,
            seed: 1,
            screen: 8,
            initial_points: vec![],
            problem_points: vec![],
            compass: Default::default(),
            lm: Default::default(),
            polish: true,
            constraints: Default::default(),
            smoothness: Smoothness::Auto,
        }
    }
}
