//! The smoothness prior of a tabulated function's knots (`+ndf`: the log-factor of the
//! data-driven NDF), and how its weight is chosen from the data.
//!
//! The prior adds one residual row per second difference of a chain of knots,
//! (s_{k−1} − 2 s_k + s_{k+1})/σ_s ([`crate::inference::constraints::Constraints::smooth`]):
//! χ² becomes a penalised χ², knots where the data hold no half vectors follow their
//! neighbours instead of wandering (a fit could otherwise park NDF mass there to reshape
//! the Smith term), and the covariance gains the prior's information. σ_s is chosen by
//! fitting at each value of [`GRID`] and keeping the smallest
//! AIC with the effective number of parameters (Hastie & Tibshirani 1990, §3.5):
//! χ²_data + 2·edf, edf = tr((B_data + B_prior)⁻¹ B_data), B the Gauss–Newton normal
//! matrix at the fit's optimum. A strong prior (small σ_s) spends few effective
//! parameters, a weak one fits the data more closely with more; the data decide.

use super::{Conclusions, FitOptions};

/// How the fit sets σ_s.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Smoothness {
    /// Chosen from the data (the module's doc): the default.
    #[default]
    Auto,
    /// No smoothness prior.
    Off,
    /// This σ_s.
    Sd(f64),
}

impl Smoothness {
    /// The σ_s a fit chose, to hold in fits that conclude about the same knots (Monte
    /// Carlo replicas, a bootstrap's refits, a candidate that adds no knots); `otherwise`
    /// when the fit made no choice (a model without knots, or the prior off).
    pub fn held_from(choice: Option<&SmoothnessChoice>, otherwise: Smoothness) -> Smoothness {
        choice.map_or(otherwise, |c| Smoothness::Sd(c.chosen.sd))
    }
}

/// The words [`Smoothness::from_str`] reads: `auto`, `off`, or the σ.
impl std::fmt::Display for Smoothness {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Smoothness::Auto => f.write_str("auto"),
            Smoothness::Off => f.write_str("off"),
            Smoothness::Sd(v) => write!(f, "{v}"),
        }
    }
}

impl std::str::FromStr for Smoothness {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "auto" => Ok(Smoothness::Auto),
            "off" => Ok(Smoothness::Off),
            t => match t.parse::<f64>() {
                Ok(v) if v.is_finite() && v > 0.0 => Ok(Smoothness::Sd(v)),
                _ => Err(format!(
                    "'{t}' is not a smoothness: give auto, off, or a positive standard deviation of a knot's second difference"
                )),
            },
        }
    }
}

/// The σ_s tried by [`Smoothness::Auto`], strongest first (each fit starts from the
/// previous optimum). The weakest still holds knots without data (σ_s = 30 lets a second
/// difference reach e^30), so no fit of the choice leaves a knot undetermined; a fit
/// without the prior is `Off`. The strongest is 0.03 since the NDF has 32 knots: on a GTR
/// truth the AIC chose 0.1, then the grid's end, and 0.03 on six noise seeds of six when
/// offered (docs/models.md, the NDF's cost).
pub const GRID: [f64; 7] = [0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0];

/// One fit of the choice.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SmoothnessTrial {
    /// σ_s.
    pub sd: f64,
    /// χ² of the data alone.
    pub chi2: f64,
    /// Effective number of parameters.
    pub effective_params: f64,
    /// χ² + 2·edf.
    pub aic: f64,
}

/// What [`Smoothness::Auto`] chose, and from what.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub struct SmoothnessChoice {
    pub chosen: SmoothnessTrial,
    pub tried: Vec<SmoothnessTrial>,
    /// How it was chosen, in words (for reports).
    pub criterion: String,
}

pub const CRITERION: &str = "smallest chi2 + 2 edf (AIC with the effective number of parameters, edf = tr((B_data + B_prior)^-1 B_data))";

/// The trial of one fit's conclusions.
fn trial(sd: f64, o: &Conclusions) -> SmoothnessTrial {
    let edf = o.cov.effective_params.unwrap_or(o.constraints.dim() as f64);
    SmoothnessTrial {
        sd,
        chi2: o.chi2,
        effective_params: edf,
        aic: o.chi2 + 2.0 * edf,
    }
}

impl SmoothnessChoice {
    /// A fit concluded under the σ_s that `from` chose for the same knots on another model
    /// (`spec`), held rather than chosen again: its own χ² and effective parameters,
    /// `from`'s trials, and a criterion that says where σ_s comes from.
    pub fn held(from: &SmoothnessChoice, spec: &str, o: &Conclusions) -> SmoothnessChoice {
        SmoothnessChoice {
            chosen: trial(from.chosen.sd, o),
            tried: from.tried.clone(),
            criterion: format!(
                "{}, held from {spec}, where the data-driven factor was adopted",
                from.criterion
            ),
        }
    }
}

/// Fit at every σ_s of [`GRID`] (`fit` makes one fit under the
/// options it is given), and keep the smallest AIC. The first fit uses `opts`' restarts;
/// each later one starts from the previous optimum and the given points, with one random
/// restart.
pub fn choose(
    opts: &FitOptions,
    mut fit: impl FnMut(&FitOptions) -> anyhow::Result<Conclusions>,
) -> anyhow::Result<Conclusions> {
    let mut best: Option<(SmoothnessTrial, Conclusions)> = None;
    let mut tried = Vec::new();
    let mut previous: Option<Vec<f64>> = None;
    let mut seconds = 0.0;
    let mut evaluations = 0;
    for sd in GRID {
        let mut o = opts.clone();
        o.smoothness = Smoothness::Sd(sd);
        if let Some(p) = &previous {
            o.initial_points.insert(0, p.clone());
            o.restarts = 1;
        }
        let c = fit(&o)?;
        seconds += c.seconds;
        evaluations += c.evaluations;
        let t = trial(sd, &c);
        previous = Some(c.flat.clone());
        tried.push(t.clone());
        if best.as_ref().is_none_or(|(b, _)| t.aic < b.aic) {
            best = Some((t, c));
        }
    }
    let (chosen, mut c) = best.expect("the grid is not empty");
    c.seconds = seconds;
    c.evaluations = evaluations;
    c.smoothness = Some(SmoothnessChoice {
        chosen,
        tried,
        criterion: CRITERION.into(),
    });
    Ok(c)
}
