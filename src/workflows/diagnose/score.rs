//! Comparing a fitted candidate with the current model: the F test (nested) or its
//! bootstrap calibration where the null is irregular, the BIC, the identifiability of the
//! new parameters, and the consistency test of a fit.

use super::regions::RegionStat;
use super::symmetry::FrameTest;
use super::{Candidate, DiagnoseOptions, FitResult};
use crate::bsdf::{Model, ParamDecl};
use crate::data::Dataset;
use crate::inference::bootstrap::Calibrated;
use crate::inference::covariance::Covariance;
use crate::inference::stats::{self, f_test, format_p};
use anyhow::Result;
use serde_json::{json, Value};

/// Which test gave a candidate's p-value.
#[derive(Clone, Debug)]
pub enum PTest {
    /// Not nested: no p-value (the BIC decides).
    None,
    /// The F test, its reference distribution valid (the null is an interior point where
    /// every new parameter is identified).
    F,
    /// The parametric bootstrap (the null is irregular: [`Scored::irregular`]).
    Bootstrap(Calibrated),
    /// The nominal F test although the null is irregular, and why the bootstrap was not run
    /// (the verdict did not depend on it, or `--bootstrap 0`).
    FNominal(String),
    /// Not tested: the round adopts the same candidate whether or not this one is
    /// significant (why); calibrated later if a backtrack needs its verdict.
    Deferred(String),
}

impl PTest {
    /// A short name for tables: `F`, `bootstrap`, `bootstrap tail`, `F nominal`.
    pub fn label(&self) -> &'static str {
        match self {
            PTest::None => "-",
            PTest::F => "F",
            PTest::Bootstrap(c) => match c.source {
                crate::inference::bootstrap::PSource::Tail => "boot tail",
                _ => "bootstrap",
            },
            PTest::FNominal(_) => "F nominal",
            PTest::Deferred(_) => "deferred",
        }
    }
    /// The sentence the report gives.
    pub fn describe(&self) -> String {
        match self {
            PTest::None => "no p-value (not nested)".into(),
            PTest::F => {
                "F test (regular null: every new parameter identified, inside its range)".into()
            }
            PTest::Bootstrap(c) => c.describe(),
            PTest::FNominal(why) => format!("nominal F test, not calibrated: {why}"),
            PTest::Deferred(why) => format!("not tested: {why}"),
        }
    }
    pub fn to_json(&self) -> Value {
        match self {
            PTest::None => Value::Null,
            PTest::F => json!({"test": "F"}),
            PTest::Bootstrap(c) => json!({"test": "bootstrap", "bootstrap": c}),
            PTest::FNominal(why) => json!({"test": "F_nominal", "why": why}),
            PTest::Deferred(why) => json!({"test": "deferred", "why": why}),
        }
    }
}

/// A fitted candidate and its comparison with the current model.
#[derive(Clone, Debug)]
pub struct Scored {
    pub candidate: Candidate,
    pub fit: Option<FitResult>,
    /// Extra parameters over the current model.
    pub dp: i64,
    pub delta_chi2: f64,
    /// F statistic and the p-value (nested candidates): the F test's, or the bootstrap's
    /// where the null is irregular ([`PTest`]).
    pub f: Option<f64>,
    pub p: Option<f64>,
    /// The F test's nominal p-value.
    pub p_nominal: Option<f64>,
    pub p_test: PTest,
    /// Why the F test's reference distribution does not hold at this null (a new
    /// parameter's null value on a bound of its range, or new parameters the null does not
    /// identify); None for a regular null.
    pub irregular: Option<String>,
    /// The Bonferroni-corrected level α/m the p-value is held against.
    pub level: f64,
    /// BIC(candidate) − BIC(current), χ² taken as is.
    pub delta_bic: f64,
    /// The same with both χ² divided by max(1, χ²_red of the candidate).
    pub delta_bic_scaled: f64,
    pub significant: bool,
    pub identifiable: bool,
    /// Why not, when not identifiable.
    pub identifiable_why: String,
    /// What the identifiability rests on when the new parameters are not all determined
    /// on their own: the ridges the data leave, and what was held to settle them.
    pub identifiable_note: String,
    /// New parameters that ended on a bound of their range, each with what the bound means
    /// (the data push against what the model can express there). Information, not a veto:
    /// such a step is adopted when it is the best explanation on offer.
    pub on_bound: Vec<String>,
    /// Share of the current model's χ² removed inside each flagged region (region words,
    /// fraction; negative where the candidate fits that region worse).
    pub removal: Vec<(String, f64)>,
    /// Share removed inside the flagged regions together, and outside them; None when no
    /// region is flagged or the fit failed.
    pub removal_flagged: Option<f64>,
    pub removal_outside: Option<f64>,
    /// For an anisotropic candidate: whether its surface-fixed frame does better than an
    /// isotropic lobe of the same shape ([`FrameTest`]).
    pub frame_test: Option<FrameTest>,
    /// Why a lobe the candidate adds is too wide to be its effect (the effect's
    /// [`super::effects::EffectEntry::max_half_width_deg`]); None when it is not.
    pub too_wide: Option<String>,
    pub verdict: String,
}

impl Scored {
    /// Significant, its new parameters determined by the data, and (an anisotropic lobe)
    /// shown anisotropic by its frame test. A new parameter on a bound of its range does
    /// not stop it: the evidence says what the bound means.
    pub fn adoptable(&self) -> bool {
        self.significant && self.identifiable && !self.confounded() && self.too_wide.is_none()
    }

    /// An anisotropic candidate whose gain the data cannot tell from an isotropic lobe
    /// of another shape ([`FrameTest`]).
    pub fn confounded(&self) -> bool {
        self.frame_test
            .as_ref()
            .is_some_and(|t| !t.shows_anisotropy())
    }

    /// Not identifiable after all, for `why`; judge again.
    pub(super) fn refuse(&mut self, why: String) {
        self.identifiable = false;
        self.identifiable_why = why;
        self.judge();
    }

    /// Record the frame test and judge again.
    pub(super) fn set_frame_test(&mut self, test: FrameTest) {
        self.frame_test = Some(test);
        self.judge();
    }
}

/// The flat names of a candidate's parameters that the current model lacks.
pub(super) fn new_param_indices(old: &Model, new: &Model) -> Vec<usize> {
    let old_names: Vec<String> = old.flat_names();
    let names = new.flat_names();
    let is_old = |n: &str| {
        old_names.iter().any(|o| {
            o == n || n.strip_prefix("base.") == Some(o) || n.strip_prefix("lobe.") == Some(o)
        })
    };
    (0..names.len()).filter(|&j| !is_old(&names[j])).collect()
}

/// Why the F test does not hold for extending `old` to `new` (module doc of
/// [`crate::inference::bootstrap`]): new parameters whose null value lies on a bound of
/// their range, and new parameters without a null value (they vanish from the model at the
/// null, so it does not identify them). None when every new parameter's null value is
/// inside its range.
pub fn irregular_null(old: &Model, new: &Model) -> Option<String> {
    let names = new.flat_names();
    let decls = new.flat_decls();
    let (mut bound, mut unidentified) = (Vec::new(), Vec::new());
    for j in new_param_indices(old, new) {
        let d = &decls[j];
        match d.neutral {
            Some(v) if v <= d.lo || v >= d.hi => bound.push(format!("{} = {v}", names[j])),
            Some(_) => {}
            None => unidentified.push(names[j].clone()),
        }
    }
    let mut why = Vec::new();
    if !bound.is_empty() {
        why.push(format!("null on a bound ({})", bound.join(", ")));
    }
    if !unidentified.is_empty() {
        why.push(format!(
            "{} not identified at the null",
            unidentified.join(", ")
        ));
    }
    (!why.is_empty()).then(|| why.join("; "))
}

/// New parameters within 1e-6 of an edge of their unit box, each with what the bound
/// means: "kr[0] = 1 (retro lobe scale (albedo-like)) at the top of its range [0, 1]: the
/// data ask for more than the model can give there".
fn new_params_on_bound(old: &Model, fit: &FitResult) -> Vec<String> {
    let names = fit.model.flat_names();
    let decls = fit.model.flat_decls();
    new_param_indices(old, &fit.model)
        .into_iter()
        .filter_map(|j| {
            let d = &decls[j];
            let u = d.to_unit(fit.flat[j]);
            // Sitting at the neutral value on a bound is the current model, not a new
            // effect held back by the range; that is judged by significance instead.
            let neutral = d
                .neutral
                .is_some_and(|v| (v - fit.flat[j]).abs() <= 1e-9 * v.abs().max(1.0));
            if (1e-6..=1.0 - 1e-6).contains(&u) || neutral {
                return None;
            }
            let (end, want) = if u > 0.5 {
                ("top", "more")
            } else {
                ("bottom", "less")
            };
            Some(format!(
                "{} = {:.4} ({}) at the {end} of its range [{}, {}]: the data ask for {want} than the model can give there",
                names[j], fit.flat[j], d.doc, d.lo, d.hi
            ))
        })
        .collect()
}

/// Why a new lobe of `fit` is too wide to be `effect` (whose signature is a sharp lobe):
/// its half width at half maximum, about 1.3 α rad for a GGX lobe of roughness α, beyond
/// the effect's [`super::effects::EffectEntry::max_half_width_deg`].
fn too_wide(old: &Model, fit: &FitResult, effect: super::Effect) -> Option<String> {
    let max = effect.entry().max_half_width_deg?;
    let names = fit.model.flat_names();
    let decls = fit.model.flat_decls();
    new_param_indices(old, &fit.model)
        .into_iter()
        .filter(|&j| decls[j].lobe == crate::bsdf::LobePart::Width)
        .map(|j| (j, (1.3 * fit.flat[j]).to_degrees()))
        .find(|&(_, hwhm)| hwhm > max)
        .map(|(j, hwhm)| {
            format!(
                "its lobe is {hwhm:.0}° wide ({} = {:.3}; half width at half maximum, the effect's signature allows {max:.0}°): no longer a sharp excess ({}) but a broad glow that reshapes the whole hemisphere, an angular profile of the body that the catalogue lacks",
                names[j],
                fit.flat[j],
                effect.signature()
            )
        })
}

/// How much of the current misfit a candidate removes inside each flagged region, in them
/// together, and outside them.
#[allow(clippy::type_complexity)]
fn removal(
    flagged: &[RegionStat],
    current: &FitResult,
    fit: &FitResult,
) -> (Vec<(String, f64)>, Option<f64>, Option<f64>) {
    if flagged.is_empty() {
        return (vec![], None, None);
    }
    let share = |before: f64, after: f64| {
        if before > 0.0 {
            1.0 - after / before
        } else {
            0.0
        }
    };
    let per: Vec<(String, f64)> = flagged
        .iter()
        .map(|r| (r.words.clone(), share(r.chi2(&current.z), r.chi2(&fit.z))))
        .collect();
    let inside = |k: usize| flagged.iter().any(|r| r.contains(k));
    let (mut b_in, mut a_in, mut b_out, mut a_out) = (0.0, 0.0, 0.0, 0.0);
    for (k, (zb, za)) in current.z.iter().zip(&fit.z).enumerate() {
        if inside(k) {
            b_in += zb * zb;
            a_in += za * za;
        } else {
            b_out += zb * zb;
            a_out += za * za;
        }
    }
    (per, Some(share(b_in, a_in)), Some(share(b_out, a_out)))
}

/// A new parameter counts as determined when its standard uncertainty, measured in its
/// unit box (the share of its declared range the optimizers see), is at most this.
pub const IDENT_UNIT_STD: f64 = crate::inference::covariance::RIDGE_UNIT_STD;

/// Whether the data determine the effect an extension adds: at least one of its new
/// parameters has a standard uncertainty of at most [`IDENT_UNIT_STD`] of its range.
/// Correlation is reported, never a veto on its own: a parameter known to 4 % is
/// determined whatever it correlates with. Where none is determined on its own — a ridge
/// of the loss, or a singular normal matrix — the parameters along the weak directions
/// are held at their fitted values, one new parameter left free at a time, and the
/// effect counts as determined if that parameter then is; the note says which were held
/// and the ridge. Returns (determined, why not, note).
fn new_params_determined(
    old: &Model,
    fit: &FitResult,
    data: &Dataset,
    opts: &DiagnoseOptions,
) -> (bool, String, String) {
    let new = NewParams::of(old, fit);
    if new.idx.is_empty() {
        return (true, String::new(), String::new());
    }
    if let Some(judged) = new.factor_determined(data) {
        return judged;
    }
    if new.idx.iter().any(|&j| new.determined(&fit.cov, j)) {
        return (true, String::new(), new.loose_note());
    }
    if let Some(note) = new.determined_when_held(data, opts) {
        return (true, String::new(), note);
    }
    (false, new.why_undetermined(), String::new())
}

/// The new parameters of an extension's fit, as [`new_params_determined`] judges them.
struct NewParams<'a> {
    fit: &'a FitResult,
    /// The fit's flat parameter names and declarations.
    names: Vec<String>,
    decls: Vec<ParamDecl>,
    /// Which of the fit's parameters are new.
    idx: Vec<usize>,
}

impl<'a> NewParams<'a> {
    fn of(old: &Model, fit: &'a FitResult) -> NewParams<'a> {
        NewParams {
            fit,
            names: fit.model.flat_names(),
            decls: fit.model.flat_decls(),
            idx: new_param_indices(old, &fit.model),
        }
    }

    /// Where every new parameter is a knot of a tabulated factor (`+ndf`, `+fresnel`,
    /// `+body`): (determined, why not, note), judged knot by knot under the covariance
    /// with the smoothness prior's information, not by [`Covariance::std`]. The prior
    /// keeps every knot finite, so a factor counts as determined only where the data see
    /// it: at least one of its measured knots (not set by the prior) known to
    /// σ(ln) ≤ [`crate::inference::knots::DETERMINED_LN_SD`]. Judged by `std`, a factor
    /// on a lobe whose other parameters the data leave free (a broad coat's k_c and α_c
    /// trade with its curve) had every knot "undetermined" however well the data fix the
    /// curve itself. None for other extensions, or without the prior's covariance.
    fn factor_determined(&self, data: &Dataset) -> Option<(bool, String, String)> {
        use crate::inference::knots::{
            determined_knots, is_knot_of, DeterminedKnots, DETERMINED_LN_SD,
        };
        if !self.idx.iter().all(|&j| self.decls[j].knot) {
            return None;
        }
        let fit = self.fit;
        let factors = determined_knots(&fit.model, data, &fit.flat, &fit.cov)?;
        let new: Vec<&DeterminedKnots> = factors
            .iter()
            .filter(|f| {
                self.idx
                    .iter()
                    .any(|&j| is_knot_of(&self.names[j], &f.stem))
            })
            .collect();
        let label = |f: &DeterminedKnots| match f.channel {
            Some(c) => format!("{} (channel {c})", f.stem),
            None => f.stem.clone(),
        };
        let seen: Vec<String> = new
            .iter()
            .filter(|f| !f.degrees.is_empty())
            .map(|f| {
                let deg: Vec<String> = f.degrees.iter().map(|d| format!("{d:.1}°")).collect();
                format!("{} at {}", label(f), deg.join(", "))
            })
            .collect();
        if seen.is_empty() {
            let stems: Vec<String> = new.iter().map(|f| label(f)).collect();
            return Some((
                false,
                format!(
                    "no knot of {} is both measured (the data see the factor there) and known to σ(ln) ≤ {DETERMINED_LN_SD}: the smoothness prior sets its shape",
                    stems.join(", ")
                ),
                String::new(),
            ));
        }
        Some((
            true,
            String::new(),
            format!("knots determined by the data: {}", seen.join("; ")),
        ))
    }

    /// Parameter `j`'s standard uncertainty under `cov`, as a share of its unit box.
    fn unit(&self, cov: &Covariance, j: usize) -> Option<f64> {
        cov.std[j]
            .map(|s| crate::inference::covariance::unit_std(&self.decls[j], self.fit.flat[j], s))
    }

    /// Whether `cov` determines parameter `j` ([`IDENT_UNIT_STD`]).
    fn determined(&self, cov: &Covariance, j: usize) -> bool {
        self.unit(cov, j).is_some_and(|u| u <= IDENT_UNIT_STD)
    }

    /// The weak directions of `cov` that a new parameter takes part in, in words with how
    /// well each is constrained ("" for none).
    fn ridges(&self, cov: &Covariance) -> String {
        cov.ridges
            .iter()
            .filter(|r| r.components.iter().any(|(j, _)| self.idx.contains(j)))
            .map(|r| {
                let std = if r.unit_std.is_finite() {
                    format!("which the data locate to ± {:.2} of the range", r.unit_std)
                } else {
                    "which the data do not locate at all".into()
                };
                format!("{}, {std}", r.words(&self.names))
            })
            .collect::<Vec<_>>()
            .join("; ")
    }

    /// Where one new parameter is determined on its own: the note on those that are not
    /// ("" when every one is), with the ridges that hold them.
    fn loose_note(&self) -> String {
        let cov = &self.fit.cov;
        let loose: Vec<String> = self
            .idx
            .iter()
            .filter(|&&j| !self.determined(cov, j))
            .map(|&j| self.names[j].clone())
            .collect();
        if loose.is_empty() {
            return String::new();
        }
        let r = self.ridges(cov);
        format!(
            "{} not determined on {} own{}",
            loose.join(", "),
            if loose.len() == 1 { "its" } else { "their" },
            if r.is_empty() {
                String::new()
            } else {
                format!(": they move together along {r}")
            }
        )
    }

    /// No new parameter determined on its own: hold what it trades off against — the
    /// other parameters along the weak directions it takes part in, and any parameter the
    /// data do not constrain at all — at their fitted values, and look again, one new
    /// parameter free at a time. The note for the first then determined, if any.
    fn determined_when_held(&self, data: &Dataset, opts: &DiagnoseOptions) -> Option<String> {
        let cov = &self.fit.cov;
        for &free in &self.idx {
            let mut hold: Vec<usize> = cov
                .ridges
                .iter()
                .filter(|r| r.components.iter().any(|&(j, _)| j == free))
                .flat_map(|r| r.components.iter().map(|&(j, _)| j))
                .chain((0..self.names.len()).filter(|&j| cov.std[j].is_none()))
                .filter(|&j| j != free && cov.std[j] != Some(0.0))
                .collect();
            hold.sort_unstable();
            hold.dedup();
            if hold.is_empty() {
                continue;
            }
            if let Ok(c) = super::fit::conditional_covariance(self.fit, data, opts, &hold) {
                if self.determined(&c, free) {
                    let held: Vec<&str> = hold.iter().map(|&j| self.names[j].as_str()).collect();
                    let r = self.ridges(cov);
                    return Some(format!(
                        "{} is determined (± {} of its range) with {} held at the fitted values{}",
                        self.names[free],
                        share(self.unit(&c, free).unwrap_or(f64::NAN)),
                        held.join(", "),
                        if r.is_empty() {
                            String::new()
                        } else {
                            format!("; the fit moves along {r}")
                        }
                    ));
                }
            }
        }
        None
    }

    /// Why the effect counts as undetermined: each new parameter's uncertainty, and the
    /// ridges.
    fn why_undetermined(&self) -> String {
        let cov = &self.fit.cov;
        let why: Vec<String> = self
            .idx
            .iter()
            .map(|&j| match self.unit(cov, j) {
                Some(u) => format!("{} ± {u:.2} of its range", self.names[j]),
                None => format!("{} undetermined", self.names[j]),
            })
            .collect();
        let r = self.ridges(cov);
        format!(
            "{}{}",
            why.join(", "),
            if r.is_empty() {
                String::new()
            } else {
                format!(" (they move together along {r})")
            }
        )
    }
}

pub(super) fn score(
    data: &Dataset,
    current: &FitResult,
    flagged: &[RegionStat],
    candidate: Candidate,
    fit: Result<FitResult>,
    m: usize,
    opts: &DiagnoseOptions,
) -> Scored {
    let k = data.len();
    let level = opts.alpha / m.max(1) as f64;
    let fit = match fit {
        Ok(f) => f,
        Err(e) => {
            return Scored {
                candidate,
                fit: None,
                dp: 0,
                delta_chi2: 0.0,
                f: None,
                p: None,
                p_nominal: None,
                p_test: PTest::None,
                irregular: None,
                level,
                delta_bic: f64::INFINITY,
                delta_bic_scaled: f64::INFINITY,
                significant: false,
                identifiable: false,
                identifiable_why: String::new(),
                identifiable_note: String::new(),
                on_bound: vec![],
                removal: vec![],
                removal_flagged: None,
                removal_outside: None,
                frame_test: None,
                too_wide: None,
                verdict: format!("fit failed: {e:#}"),
            }
        }
    };
    let dp = fit.params as i64 - current.params as i64;
    let delta_chi2 = current.chi2 - fit.chi2;
    let s = fit.chi2_red.max(1.0);
    let delta_bic = stats::delta_bic(current.chi2, fit.chi2, dp, k, 1.0);
    let delta_bic_scaled = stats::delta_bic(current.chi2, fit.chi2, dp, k, s);
    let nested = candidate.nested && dp > 0;
    let (f, p) = if nested {
        let (fstat, p) = f_test(delta_chi2, dp as usize, fit.chi2, fit.dof);
        (Some(fstat), Some(p))
    } else {
        (None, None)
    };
    let irregular = nested
        .then(|| irregular_null(&current.model, &fit.model))
        .flatten();
    let p_test = match (nested, &irregular) {
        (false, _) => PTest::None,
        (true, None) => PTest::F,
        // Replaced by the bootstrap where the verdict depends on it (path.rs).
        (true, Some(_)) => PTest::FNominal("the bootstrap was not run".into()),
    };
    let (identifiable, why, note) = new_params_determined(&current.model, &fit, data, opts);
    let on_bound = new_params_on_bound(&current.model, &fit);
    let (removal, removal_flagged, removal_outside) = removal(flagged, current, &fit);
    let too_wide = too_wide(&current.model, &fit, candidate.effect);
    let mut scored = Scored {
        candidate,
        fit: Some(fit),
        dp,
        delta_chi2,
        f,
        p,
        p_nominal: p,
        p_test,
        irregular,
        level,
        delta_bic,
        delta_bic_scaled,
        significant: false,
        identifiable,
        identifiable_why: why,
        identifiable_note: note,
        on_bound,
        removal,
        removal_flagged,
        removal_outside,
        frame_test: None,
        too_wide,
        verdict: String::new(),
    };
    scored.judge();
    scored
}

impl Scored {
    /// Whether the nested test's verdict can depend on calibrating its p-value: the BIC
    /// gate must pass (otherwise the candidate fails whatever p is), and the nominal p must
    /// not be so far below the level that the calibrated one would have to be
    /// [`SETTLED`]⁻¹ times larger to change the verdict.
    pub fn needs_calibration(&self) -> bool {
        self.irregular.is_some()
            && self.fit.is_some()
            && self.delta_bic_scaled < 0.0
            && self.p_nominal.is_some_and(|p| p >= SETTLED * self.level)
    }

    /// Leave the test undone (the round's choice does not depend on it): not significant
    /// until a calibration says otherwise ([`Scored::undefer`]).
    pub fn defer(&mut self, why: String) {
        self.p_test = PTest::Deferred(why.clone());
        self.significant = false;
        self.verdict = format!("not tested: {why}");
    }

    /// Back to the nominal verdict, for the bootstrap to calibrate.
    pub fn undefer(&mut self) {
        self.p_test = PTest::FNominal("the bootstrap was not run".into());
        self.p = self.p_nominal;
        self.judge();
    }

    pub fn is_deferred(&self) -> bool {
        matches!(self.p_test, PTest::Deferred(_))
    }

    /// Replace the p-value by a calibrated one and judge again.
    pub fn calibrated(&mut self, c: Calibrated) {
        self.p = Some(c.p);
        self.p_test = PTest::Bootstrap(c);
        self.judge();
    }

    /// Significance and the verdict from the current p-value.
    fn judge(&mut self) {
        let level = self.level;
        self.significant = match self.p {
            Some(p) => p < level && self.delta_bic_scaled < 0.0,
            None => self.delta_bic_scaled < -SWAP_BIC,
        };
        let test = match &self.p_test {
            PTest::None | PTest::F => String::new(),
            t => format!(" [{}]", t.label()),
        };
        let retried = self
            .fit
            .as_ref()
            .and_then(|f| f.note.as_ref())
            .map(|n| format!("; {n}"))
            .unwrap_or_default();
        self.verdict = if !self.significant {
            match self.p {
                Some(p) => format!(
                    "not significant ({}{test}, need < {level:.1e}; scaled ΔBIC {:+.1}){retried}",
                    format_p(p),
                    self.delta_bic_scaled
                ),
                None => format!(
                    "not significant (swap: scaled ΔBIC {:+.1}, need < −10)",
                    self.delta_bic_scaled
                ),
            }
        } else if !self.identifiable {
            format!(
                "significant but not identifiable: {}",
                self.identifiable_why
            )
        } else if let Some(w) = &self.too_wide {
            format!("significant, but {w}")
        } else if let Some(m) = self.frame_test.as_ref().filter(|_| self.confounded()) {
            format!("significant, but {}", m.confounded_words())
        } else if !self.on_bound.is_empty() {
            format!(
                "significant; a new parameter ends on a bound: {}",
                self.on_bound
                    .iter()
                    .map(|b| b.split(" (").next().unwrap_or(b))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        } else {
            "significant".into()
        };
    }
}

/// A swap that is not nested must lower the scaled BIC by more than this: Kass &
/// Raftery's "very strong" evidence.
pub const SWAP_BIC: f64 = 10.0;

/// A nominal p-value this far below the level (times the level) settles the verdict
/// without the bootstrap ([`Scored::needs_calibration`]).
pub const SETTLED: f64 = 1e-6;

/// The consistency test of a fit: P(χ²_{K−P} ≥ χ²) ≥ α, and its verdict in words.
pub(super) fn consistency(fit: &FitResult, alpha: f64) -> (bool, String) {
    let p = fit.p_consistent();
    let ok = p >= alpha;
    let verdict = if ok {
        "consistent with the uncertainties"
    } else {
        "the misfit exceeds the uncertainties"
    };
    (
        ok,
        format!(
            "χ²_red = {:.3} on {} dof: {verdict} ({}, α = {alpha})",
            fit.chi2_red,
            fit.dof,
            format_p(p)
        ),
    )
}

/// A share of a range in words with two significant digits ("0.12", "2.1e-3").
fn share(u: f64) -> String {
    if u < 0.01 {
        format!("{u:.1e}")
    } else {
        format!("{u:.2}")
    }
}
