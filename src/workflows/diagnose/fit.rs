//! Fitting a model for the diagnosis: a multi-start χ² fit and its statistics, and the
//! fits of a round's candidates.

use super::regions::RegionStat;
use super::score::{PTest, SETTLED};
use super::{embed, Candidate, DiagnoseOptions, Scored};
use crate::bsdf::{LobePart, Model};
use crate::data::Dataset;
use crate::engine::loss::normalised_residuals;
use crate::engine::Backend;
use crate::inference::bootstrap::{self, BootstrapOptions};
use crate::inference::covariance::Covariance;
use crate::inference::fit::{fit_outcome, FitOptions, Optimizer, Smoothness, SmoothnessChoice};
use crate::inference::stats::consistency_p;
use anyhow::{Context, Result};

/// One fitted model (χ² statistics, parameters, residuals).
#[derive(Clone, Debug)]
pub struct FitResult {
    pub model: Model,
    pub flat: Vec<f64>,
    /// Model values at the samples.
    pub values: Vec<f64>,
    /// Normalized residuals z = (y′ − y)/u.
    pub z: Vec<f64>,
    /// χ² of the data plus the priors' (`--prior`).
    pub chi2: f64,
    /// Samples + priors − fitted parameters.
    pub dof: usize,
    /// Fitted parameters (the model's, less those fixed by `--fix`).
    pub params: usize,
    pub chi2_red: f64,
    /// Best value of the driving loss.
    pub loss: f64,
    pub cov: Covariance,
    pub seconds: f64,
    /// What the fit had to do to get here, where it was refitted ([`fit_all`]).
    pub note: Option<String>,
    /// How the smoothness prior of tabulated knots was weighed (models with `+ndf`,
    /// `+fresnel` or `+body` fitted by χ²; None otherwise).
    pub smoothness: Option<crate::inference::fit::SmoothnessChoice>,
}

impl FitResult {
    pub fn spec(&self) -> &str {
        &self.model.spec
    }
    /// P(χ²_{K−P} ≥ χ²).
    pub fn p_consistent(&self) -> f64 {
        consistency_p(self.chi2, self.dof)
    }
}

/// The fit options of every fit of a diagnosis.
fn fit_options(opts: &DiagnoseOptions) -> FitOptions {
    // SMAPE is not a sum of squares: LM cannot fit it, compass can.
    let optimizer = if opts.optimizer == Optimizer::Lm && !opts.loss.is_sum_of_squares() {
        Optimizer::Compass
    } else {
        opts.optimizer
    };
    FitOptions {
        optimizer,
        restarts: opts.restarts.max(1),
        seed: opts.seed,
        screen: opts.screen,
        constraints: opts.constraints.clone(),
        ..Default::default()
    }
}

/// Multi-start fit of `model` with extra starting points `seeds` (physical parameters).
pub fn fit_model(
    model: &Model,
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    seeds: &[Vec<f64>],
) -> Result<FitResult> {
    fit_model_holding(model, data, backend, opts, seeds, None)
}

/// [`fit_model`], the smoothness prior of the knots held at the σ_s that `held`'s fit
/// chose for them (an analytic effect added to a model with a data-driven factor: the
/// same knots, so no new choice; it would cost seven fits of every candidate).
fn fit_model_holding(
    model: &Model,
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    seeds: &[Vec<f64>],
    held: Option<&FitResult>,
) -> Result<FitResult> {
    let choice = held.and_then(|h| h.smoothness.as_ref().map(|c| (h, c)));
    let fit_opts = FitOptions {
        initial_points: seeds.to_vec(),
        smoothness: Smoothness::held_from(choice.map(|(_, c)| c), Smoothness::Auto),
        ..fit_options(opts)
    };
    let mut o = fit_outcome(model, data, opts.loss, backend, &fit_opts, &mut |_| {})?;
    if let Some((h, c)) = choice {
        o.smoothness = Some(SmoothnessChoice::held(c, h.spec(), &o));
    }
    let chi2 = o.chi2 + o.chi2_prior;
    Ok(FitResult {
        model: model.clone(),
        z: normalised_residuals(data, &o.values),
        flat: o.flat,
        values: o.values,
        chi2,
        dof: o.dof,
        params: o.constraints.dim(),
        chi2_red: chi2 / o.dof as f64,
        loss: o.loss,
        cov: o.cov,
        seconds: o.seconds,
        note: None,
        smoothness: o.smoothness,
    })
}

/// Fit every candidate from the current optimum embedded in its parameters, from starts
/// the residuals suggest ([`evidence_starts`]) and from random starts: one after the
/// other, or one thread each with `parallel`. A new lobe whose fit does not improve on
/// the current model at all, though the current model is one of its points, is fitted
/// again with twice the restarts and another seed before its verdict is given: a lobe
/// whose every start missed a narrow peak is a fitting failure to retry, not evidence
/// that the peak is not there.
pub(super) fn fit_all(
    cands: &[Candidate],
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    current: &FitResult,
    flagged: &[RegionStat],
) -> Vec<Result<FitResult>> {
    let one = |c: &Candidate| -> Result<FitResult> {
        let model = Model::for_data(&c.spec, data)?;
        let embedded = embed(&current.model, &current.flat, &model);
        let evidence = evidence_starts(c, &current.model, &model, &embedded, flagged);
        let lobe = !evidence.is_empty();
        let mut seeds = vec![embedded.clone()];
        seeds.extend(evidence);
        // An analytic effect keeps the current model's knots and their prior's weight.
        let held = (!c.effect.is_data_driven()).then_some(current);
        let fit = fit_model_holding(&model, data, backend, opts, &seeds, held)
            .with_context(|| format!("fitting {}", c.spec))?;
        // Only a new lobe is retried: a parameter whose null value is its optimum (σ = 0
        // of a Lambertian sample) rightly stays at the current model.
        if fit.chi2 < current.chi2 * (1.0 - 1e-9) || !lobe {
            return Ok(fit);
        }
        let again = DiagnoseOptions {
            restarts: 2 * opts.restarts.max(1),
            seed: opts.seed ^ 0x9e37_79b9_7f4a_7c15,
            ..opts.clone()
        };
        let mut retry = fit_model_holding(&model, data, backend, &again, &seeds, held)
            .with_context(|| format!("fitting {} again", c.spec))?;
        retry.note = Some(if retry.chi2 < fit.chi2 {
            format!(
                "the first fit never left the current model; refitted with {} restarts",
                again.restarts
            )
        } else {
            format!(
                "stayed at the current model from every start ({} random, {} from the current fit and the residuals), twice",
                again.restarts,
                seeds.len()
            )
        });
        Ok(if retry.chi2 <= fit.chi2 { retry } else { fit })
    };
    if opts.parallel && cands.len() > 1 {
        std::thread::scope(|scope| {
            let handles: Vec<_> = cands.iter().map(|c| scope.spawn(move || one(c))).collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or_else(|_| Err(anyhow::anyhow!("a candidate fit panicked")))
                })
                .collect()
        })
    } else {
        cands.iter().map(one).collect()
    }
}

/// The current model refitted from the optima of the round's candidates that beat it by
/// more than one in χ² (the best three), each projected onto its parameters ([`embed`]
/// the other way: a parameter takes the candidate's of its name, or its neutral value;
/// what the candidate adds is dropped), and from its own optimum. Some where that lowers
/// its χ² by more than one: its fit had missed its optimum (a narrow peak none of its
/// starts found, which a candidate's fit did find), and the candidate would otherwise be
/// credited with a gain that is the current model's own, on a null case a false effect.
pub(super) fn refit_from_candidates(
    current: &FitResult,
    candidates: &[&FitResult],
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
) -> Result<Option<(FitResult, Vec<String>)>> {
    let mut better: Vec<&&FitResult> = candidates
        .iter()
        .filter(|c| c.chi2 < current.chi2 - MISSED_CHI2)
        .collect();
    better.sort_by(|a, b| a.chi2.total_cmp(&b.chi2));
    better.truncate(3);
    if better.is_empty() {
        return Ok(None);
    }
    let mut seeds = vec![current.flat.clone()];
    seeds.extend(
        better
            .iter()
            .map(|c| embed(&c.model, &c.flat, &current.model)),
    );
    // One random restart besides the seeds: this fit looks where the candidates found a
    // basin; the first fit already searched at random.
    let once = DiagnoseOptions {
        restarts: 1,
        ..opts.clone()
    };
    let refit = fit_model_holding(&current.model, data, backend, &once, &seeds, Some(current))
        .with_context(|| format!("refitting {} from its candidates' optima", current.spec()))?;
    let from = better.iter().map(|c| c.spec().to_string()).collect();
    Ok((refit.chi2 < current.chi2 - MISSED_CHI2).then_some((refit, from)))
}

/// The fall in χ² that shows a fit missed its model's optimum ([`refit_from_candidates`]):
/// more than one, the size of a single parameter's share; a smaller one is the optimizer's
/// tolerance.
const MISSED_CHI2: f64 = 1.0;

/// Starting points for a candidate that adds a lobe, from where the residuals say the
/// current model misses (the effect's `lobe_around`): its new width parameters at the
/// widths of the flagged regions around that direction (half, once and twice: a misfit
/// within 5° of the retro direction seeds a lobe about that wide; without a flagged
/// region, 5° and 15°), its new amplitudes at 5 % and 50 % of their ranges, every other
/// parameter at the current optimum (`embedded`). A GGX lobe of roughness α has a
/// half-width at half maximum of about 1.3 α radians about its axis.
pub(super) fn evidence_starts(
    c: &Candidate,
    old: &Model,
    new: &Model,
    embedded: &[f64],
    flagged: &[RegionStat],
) -> Vec<Vec<f64>> {
    let Some(around) = c.effect.entry().lobe_around else {
        return vec![];
    };
    let decls = new.flat_decls();
    let fresh = super::score::new_param_indices(old, new);
    let widths: Vec<usize> = fresh
        .iter()
        .copied()
        .filter(|&j| decls[j].lobe == LobePart::Width)
        .collect();
    let amplitudes: Vec<usize> = fresh
        .iter()
        .copied()
        .filter(|&j| decls[j].lobe == LobePart::Amplitude)
        .collect();
    if widths.is_empty() && amplitudes.is_empty() {
        return vec![];
    }
    let mut radii: Vec<f64> = flagged
        .iter()
        .filter_map(|r| r.cone.filter(|k| k.around == around).map(|k| k.radius_deg))
        .collect();
    if radii.is_empty() {
        radii = vec![5.0, 15.0];
    }
    radii.sort_by(f64::total_cmp);
    radii.dedup();
    let mut alphas: Vec<f64> = radii
        .iter()
        .flat_map(|r| [0.5, 1.0, 2.0].map(|k| k * r.to_radians() / 1.3))
        .collect();
    alphas.sort_by(f64::total_cmp);
    alphas.dedup_by(|a, b| (*a / *b - 1.0).abs() < 0.05);
    let mut starts = Vec::new();
    for &alpha in &alphas {
        for share in [0.05, 0.5] {
            let mut x = embedded.to_vec();
            for &j in &widths {
                x[j] = alpha.clamp(decls[j].lo, decls[j].hi);
            }
            for &j in &amplitudes {
                x[j] = decls[j].lo + share * (decls[j].hi - decls[j].lo);
            }
            starts.push(x);
        }
    }
    starts
}

/// The bootstrap-calibrated p-value of extending the fit `current` to the fit `ext` on
/// `data` (both fitted by [`fit_model`] with `opts`), at the level `opts.alpha`, whether or
/// not its null is irregular: what [`calibrate_round`] does for one candidate.
pub fn bootstrap_p(
    current: &FitResult,
    ext: &FitResult,
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
) -> Result<bootstrap::Calibrated> {
    let boot = round_bootstrap(opts);
    anyhow::ensure!(
        boot.replicates >= 1,
        "the bootstrap needs at least 1 replicate"
    );
    let mut nulls = null_refits(current, data, &boot);
    calibrate_one(current, ext, &mut nulls, opts.alpha, backend, opts, &boot)
}

/// The current model's refits to the measured data and to replicates drawn from its fit
/// (none made yet: the calibrations grow them as they need).
fn null_refits(
    current: &FitResult,
    data: &Dataset,
    boot: &BootstrapOptions,
) -> bootstrap::NullRefits {
    bootstrap::NullRefits::new(
        &current.model,
        &current.flat,
        &current.values,
        data,
        boot.seed,
    )
    .with_smoothness(chosen_smoothness(current))
}

/// The smoothness prior a fit's knots were concluded under, held fixed in the bootstrap's
/// refits: the test is then of the model adopted, and each refit is one well-posed LM
/// run instead of knots without data drifting unpenalised (what made a data-driven
/// round's bootstrap take minutes). A model without knots keeps the options' setting.
fn chosen_smoothness(fit: &FitResult) -> Smoothness {
    Smoothness::held_from(fit.smoothness.as_ref(), Smoothness::Auto)
}

/// One candidate's calibrated p-value at `level` against the current model's refits.
fn calibrate_one(
    current: &FitResult,
    ext: &FitResult,
    nulls: &mut bootstrap::NullRefits,
    level: f64,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    boot: &BootstrapOptions,
) -> Result<bootstrap::Calibrated> {
    bootstrap::calibrate(
        &ext.model,
        &ext.flat,
        &|null_flat| embed(&current.model, null_flat, &ext.model),
        nulls,
        ext.dof,
        level,
        backend,
        &FitOptions {
            smoothness: chosen_smoothness(ext),
            ..fit_options(opts)
        },
        boot,
    )
}

/// The bootstrap's options in a diagnosis (its seed tied to the diagnosis's).
fn round_bootstrap(opts: &DiagnoseOptions) -> BootstrapOptions {
    BootstrapOptions {
        seed: opts.bootstrap.seed ^ opts.seed.rotate_left(17),
        ..opts.bootstrap.clone()
    }
}

/// What decides, between two calibrations of a round, which waiting candidate is
/// calibrated next (None: none need be, the others may have been deferred): called with
/// the indices of those that still need the bootstrap, neither run nor deferred.
pub(super) type NextCalibration<'a> =
    &'a mut dyn FnMut(&mut [Scored], &[usize], &mut dyn FnMut(String)) -> Option<usize>;

/// Calibrate by the parametric bootstrap the p-value of every candidate whose null is
/// irregular and whose verdict depends on it ([`Scored::needs_calibration`]), one at a
/// time in the order `next` gives, until it names none; the others keep the nominal F test
/// and say why. The null's refits to the replicates are shared by the round's candidates,
/// grown as far as the most demanding one needs.
pub(super) fn calibrate_round(
    scored: &mut [Scored],
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    current: &FitResult,
    log: &mut dyn FnMut(String),
    next: NextCalibration,
) {
    let boot = round_bootstrap(opts);
    for s in scored
        .iter_mut()
        .filter(|s| s.irregular.is_some() && !s.is_deferred())
    {
        if !s.needs_calibration() {
            let why = if s.delta_bic_scaled >= 0.0 {
                "the BIC does not fall, so the candidate fails whatever its p-value".to_string()
            } else {
                format!(
                    "the nominal p is below {SETTLED:.0e} of the level: the calibrated one would have to be a million times larger to change the verdict"
                )
            };
            s.p_test = PTest::FNominal(why);
        } else if boot.replicates == 0 {
            s.p_test = PTest::FNominal("--bootstrap 0".into());
        }
    }
    if boot.replicates == 0 {
        return;
    }
    let mut run = vec![false; scored.len()];
    let mut nulls = None;
    loop {
        let waiting: Vec<usize> = (0..scored.len())
            .filter(|&i| !run[i] && scored[i].needs_calibration() && !scored[i].is_deferred())
            .collect();
        let Some(i) = next(scored, &waiting, log).filter(|i| waiting.contains(i)) else {
            return;
        };
        run[i] = true;
        let s = &mut scored[i];
        let fit = s.fit.as_ref().expect("needs_calibration implies a fit");
        if nulls.is_none() {
            log(format!(
                "    bootstrap: refitting {} to replicates drawn from its fit (planned {}, at most {})",
                current.model.spec,
                boot.replicates,
                boot.max_replicates.max(boot.replicates)
            ));
        }
        let n = nulls.get_or_insert_with(|| null_refits(current, data, &boot));
        match calibrate_one(current, fit, n, s.level, backend, opts, &boot) {
            Ok(c) => {
                log(format!(
                    "    bootstrap of {}: p = {:.2e} ({}; {} replicates in batches {:?}; {:.1} s)",
                    s.candidate.spec,
                    c.p,
                    c.describe(),
                    c.replicates,
                    c.batches,
                    c.seconds
                ));
                trace_phases(&s.candidate.spec, &c);
                s.calibrated(c);
            }
            Err(e) => {
                log(format!(
                    "    bootstrap of {} failed ({e:#}): keeping the nominal F test",
                    s.candidate.spec
                ));
                s.p_test = PTest::FNominal(format!("the bootstrap failed: {e:#}"));
            }
        }
    }
}

/// With `BSDFIT_TRACE` set: where a calibration's time went, on stderr.
fn trace_phases(spec: &str, c: &bootstrap::Calibrated) {
    if std::env::var_os("BSDFIT_TRACE").is_some() {
        eprintln!(
            "trace: bootstrap of {spec}: {:.1} s, {} evaluations, {:?}",
            c.seconds, c.evaluations, c.phases
        );
    }
}

/// The covariance of `fit`'s parameters with those of `hold` held at their fitted values
/// (besides any the options fix): what the data say of the others once a trade-off along a
/// ridge is settled by holding one side of it. At the optimum, holding a parameter does not
/// move the others, so no refit is needed.
pub(super) fn conditional_covariance(
    fit: &FitResult,
    data: &Dataset,
    opts: &DiagnoseOptions,
    hold: &[usize],
) -> Result<Covariance> {
    let model = &fit.model;
    let mut space =
        crate::inference::constraints::Constraints::resolve(model, &opts.constraints, true)?;
    for &j in hold {
        space.fixed[j] = Some(fit.flat[j]);
    }
    space.free = (0..model.dim)
        .filter(|&j| space.fixed[j].is_none())
        .collect();
    anyhow::ensure!(!space.free.is_empty(), "every parameter held");
    let cpu = crate::engine::cpu::CpuBackend::new();
    let mut eval = cpu.prepare(crate::engine::Problem {
        model,
        data,
        loss: opts.loss,
    })?;
    crate::inference::covariance::covariance(
        model,
        data,
        opts.loss,
        eval.as_mut(),
        &fit.flat,
        &space,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::cpu::CpuBackend;
    use crate::workflows::diagnose::testdata;

    /// A coat lobe of roughness 0.005 over a Lambertian base, in-plane at 2° steps that
    /// pass 1° beside the mirror directions (its peak seen only in its flanks); `current`
    /// is `lambert+coat` at the Lambertian optimum with the coat off (a fit whose starts all
    /// missed the peak), `on+coat` a candidate that found it (started at the truth, as is
    /// the full fit of `lambert+coat` it is compared with). (This model's refit finds the
    /// peak from the current point too; the battery's null case `btdf(beckmann)+aniso`
    /// is where only the candidates' optima lead to it: `tests/battery.rs`.)
    #[test]
    fn a_candidate_that_found_the_missed_peak_refits_the_current_model() {
        let mut rows = Vec::new();
        for ti in [20.0, 45.0] {
            for k in 0..80 {
                rows.push([ti, 0.0, -79.0 + 2.0 * k as f64, 0.0]);
            }
        }
        let truth = "kc=0.3,alpha_c=0.005,rho=0.4";
        let data = testdata::synthesized("lambert+coat", truth, &rows, (0.02, 1e-3), 3);
        let backend = CpuBackend::new();
        let opts = DiagnoseOptions {
            restarts: 8,
            ..Default::default()
        };
        let coat = Model::for_data("lambert+coat", &data).unwrap();
        let at_truth = coat.params_from_assignments(truth).unwrap();
        let fit = |spec: &str, seeds: &[Vec<f64>]| {
            let model = Model::for_data(spec, &data).unwrap();
            super::fit_model(&model, &data, &backend, &opts, seeds).unwrap()
        };
        let lambert = fit("lambert", &[]);
        let full = fit("lambert+coat", std::slice::from_ref(&at_truth));
        let on_coat = Model::for_data("on+coat", &data).unwrap();
        let on = fit("on+coat", &[embed(&coat, &at_truth, &on_coat)]);
        assert!(full.chi2_red < 1.5, "the coat fits: {}", full.chi2_red);
        let missed = FitResult {
            flat: embed(&lambert.model, &lambert.flat, &coat),
            chi2: lambert.chi2,
            ..full.clone()
        };
        assert!(
            missed.chi2 > full.chi2 + 100.0,
            "{} vs {}",
            missed.chi2,
            full.chi2
        );
        let (refit, from) = refit_from_candidates(&missed, &[&on], &data, &backend, &opts)
            .unwrap()
            .expect("the refit finds the coat");
        assert_eq!(from, ["on+coat"]);
        assert!(
            refit.chi2 <= full.chi2 + 1e-6 * full.chi2,
            "refit χ² {} against the full fit's {}",
            refit.chi2,
            full.chi2
        );
        // A current fit at its optimum is kept, and no candidate that beats it: nothing to do.
        assert!(refit_from_candidates(&full, &[&on], &data, &backend, &opts)
            .unwrap()
            .is_none());
        assert!(refit_from_candidates(&missed, &[], &data, &backend, &opts)
            .unwrap()
            .is_none());
    }
}
