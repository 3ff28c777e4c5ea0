//! What a user imposes on a fit: fixed parameters (`--fix NAME=VALUE`), narrowed bounds
//! (`--bounds NAME=LO:HI`) and Gaussian priors (`--prior NAME=MEAN:SD`).
//!
//! The optimizers see only the *free* parameters, in a unit box spanned by the (possibly
//! narrowed) bounds; [`Constraints::from_unit`] puts the fixed values back, so backends
//! always evaluate the model's full flat vector. A prior is one more residual
//! (θ − mean)/sd beside the data's: χ² becomes the negative log posterior (up to a
//! constant), the covariance gains the prior's information, and χ²_red counts each prior
//! as one observation (ν = N + priors − free parameters). A prior has the units of χ², so
//! it is refused with the paper's other losses, whose costs are not in those units.
//!
//! Names are a parameter's full name (`lobe.alpha`, every channel and plane), a flat name
//! (`rho[1]`, `alpha@phi90`: one entry), or an unambiguous last component (`alpha` when
//! the model has one `*.alpha`), so one option can follow a parameter through nested
//! models (`rho` is `rho` in `lambert` and `base.rho` in `fa(lambert)`).

use crate::bsdf::{Model, ParamDecl, Scale};
use crate::choice::field_error;

/// What a constraint does with its numbers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ConstraintKind {
    /// Hold the parameter at one value, or one per entry (`NAME=VALUE[:VALUE…]`).
    Fix,
    /// Narrow its search range to [LO, HI] (`NAME=LO:HI`).
    Bounds,
    /// A Gaussian prior N(MEAN, SD²) (`NAME=MEAN:SD`).
    Prior,
}

impl ConstraintKind {
    /// The option as a field of a message (`{fix}`).
    fn option(self) -> &'static str {
        match self {
            ConstraintKind::Fix => "{fix}",
            ConstraintKind::Bounds => "{bounds}",
            ConstraintKind::Prior => "{prior}",
        }
    }

    /// The form of the option's text.
    fn form(self) -> &'static str {
        match self {
            ConstraintKind::Fix => "NAME=VALUE",
            ConstraintKind::Bounds => "NAME=LO:HI",
            ConstraintKind::Prior => "NAME=MEAN:SD",
        }
    }

    /// What each number is, in messages (a fix takes as many values as it is given).
    fn number_names(self) -> [&'static str; 2] {
        match self {
            ConstraintKind::Fix => ["VALUE", "VALUE"],
            ConstraintKind::Bounds => ["LO", "HI"],
            ConstraintKind::Prior => ["MEAN", "SD"],
        }
    }
}

/// One constraint as a value: the parameter it names (full, flat or last component: see
/// the module doc) and its numbers, with its text `NAME=…` (as given, or written from
/// the numbers), which messages, saved sweeps and the sweep's `constraints` column show.
#[derive(Clone, Debug, PartialEq)]
pub struct Constraint {
    pub kind: ConstraintKind,
    pub name: String,
    /// Fix: one value, or one per entry of the parameter; bounds: LO, HI; prior: MEAN, SD.
    pub values: Vec<f64>,
    text: String,
}

impl Constraint {
    /// A constraint from its text (`sigma=0.3`, `rho=0.4:0.5:0.6`, `alpha=0.01:0.5`,
    /// `eta=1.5:0.1`); an error names the option as a field.
    pub fn parse(kind: ConstraintKind, text: &str) -> anyhow::Result<Constraint> {
        let (option, form) = (kind.option(), kind.form());
        let (name, rest) = text
            .split_once('=')
            .map(|(n, r)| (n.trim(), r.trim()))
            .filter(|(n, _)| !n.is_empty())
            .ok_or_else(|| field_error(format!("{option} '{text}': expected {form}")))?;
        let words: Vec<&str> = match kind {
            ConstraintKind::Fix => rest.split(':').collect(),
            ConstraintKind::Bounds | ConstraintKind::Prior => {
                let (a, b) = rest
                    .split_once(':')
                    .ok_or_else(|| field_error(format!("{option} '{text}': expected {form}")))?;
                vec![a, b]
            }
        };
        let what = kind.number_names();
        let values = words
            .iter()
            .enumerate()
            .map(|(k, w)| number(w, what[k.min(1)], option, text))
            .collect::<anyhow::Result<Vec<f64>>>()?;
        Ok(Constraint {
            kind,
            name: name.to_string(),
            values,
            text: text.to_string(),
        })
    }

    /// A constraint from its numbers (see [`Constraint::values`]), its text written from
    /// them (`NAME=A:B`, each number as Rust's `{:?}` writes it); an error names the
    /// option as a field, as [`Constraint::parse`] would.
    pub fn new(kind: ConstraintKind, name: &str, values: &[f64]) -> anyhow::Result<Constraint> {
        let numbers: Vec<String> = values.iter().map(|v| format!("{v:?}")).collect();
        let text = format!("{}={}", name.trim(), numbers.join(":"));
        let (option, form) = (kind.option(), kind.form());
        let count_fits = match kind {
            ConstraintKind::Fix => !values.is_empty(),
            ConstraintKind::Bounds | ConstraintKind::Prior => values.len() == 2,
        };
        if name.trim().is_empty() || !count_fits {
            return Err(field_error(format!("{option} '{text}': expected {form}")));
        }
        let what = kind.number_names();
        for (k, v) in values.iter().enumerate() {
            if !v.is_finite() {
                return Err(field_error(format!(
                    "{option} {text}: {} '{v:?}' is not a number",
                    what[k.min(1)]
                )));
            }
        }
        Ok(Constraint {
            kind,
            name: name.trim().to_string(),
            values: values.to_vec(),
            text,
        })
    }

    /// Its text, `NAME=…`.
    pub fn text(&self) -> &str {
        &self.text
    }
}

/// What a user imposes on a fit, before it meets a model: fixed values, bounds and
/// priors, each kind in the order given. Saved (in a sweep's configuration) as the
/// options' texts: `{"fix": ["sigma=0.3"], "bounds": [], "priors": [], "lenient": false}`.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(try_from = "SpecText", into = "SpecText")]
pub struct ConstraintSpec {
    pub items: Vec<Constraint>,
    /// Skip a name the model lacks instead of failing (runs over several models, which
    /// check the names once with [`ConstraintSpec::check_names_against`]).
    pub lenient: bool,
}

/// A [`ConstraintSpec`] as it is saved: the options' texts.
#[derive(Clone, Default, serde::Serialize, serde::Deserialize)]
#[serde(default)]
struct SpecText {
    fix: Vec<String>,
    bounds: Vec<String>,
    priors: Vec<String>,
    lenient: bool,
}

impl TryFrom<SpecText> for ConstraintSpec {
    type Error = String;
    fn try_from(t: SpecText) -> Result<Self, String> {
        ConstraintSpec::parse(&t.fix, &t.bounds, &t.priors, t.lenient).map_err(|e| format!("{e:#}"))
    }
}

impl From<ConstraintSpec> for SpecText {
    fn from(spec: ConstraintSpec) -> SpecText {
        let texts = |kind| spec.of(kind).map(|c| c.text.clone()).collect();
        SpecText {
            fix: texts(ConstraintKind::Fix),
            bounds: texts(ConstraintKind::Bounds),
            priors: texts(ConstraintKind::Prior),
            lenient: spec.lenient,
        }
    }
}

impl ConstraintSpec {
    /// The constraints of the options' texts (`--fix`, `--bounds`, `--prior` as given);
    /// the first that does not parse is the error (bounds checked first, then fixed
    /// values, then priors, the order they are applied in).
    pub fn parse<S: AsRef<str>>(
        fix: &[S],
        bounds: &[S],
        priors: &[S],
        lenient: bool,
    ) -> anyhow::Result<ConstraintSpec> {
        let parse = |kind, texts: &[S]| -> anyhow::Result<Vec<Constraint>> {
            texts
                .iter()
                .map(|t| Constraint::parse(kind, t.as_ref()))
                .collect()
        };
        let bounds = parse(ConstraintKind::Bounds, bounds)?;
        let fix = parse(ConstraintKind::Fix, fix)?;
        let priors = parse(ConstraintKind::Prior, priors)?;
        Ok(ConstraintSpec {
            items: fix.into_iter().chain(bounds).chain(priors).collect(),
            lenient,
        })
    }

    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }

    /// The constraints of one kind, in the order given.
    pub fn of(&self, kind: ConstraintKind) -> impl Iterator<Item = &Constraint> + '_ {
        self.items.iter().filter(move |c| c.kind == kind)
    }

    /// Check, before a run over several models (sweep, diagnose), that every name given
    /// is a parameter of at least one of them; a model that lacks a name ignores it.
    pub fn check_names_against(&self, models: &[&Model]) -> anyhow::Result<()> {
        let kinds = [
            ConstraintKind::Fix,
            ConstraintKind::Bounds,
            ConstraintKind::Prior,
        ];
        for c in kinds.into_iter().flat_map(|k| self.of(k)) {
            let name = &c.name;
            if !models.iter().any(|m| resolve(m, name).is_ok()) {
                let mut specs: Vec<&str> = models.iter().map(|m| m.spec.as_str()).collect();
                specs.sort_unstable();
                specs.dedup();
                return Err(field_error(format!(
                    "{} {name}: no model of this run has a parameter '{name}' (models: {})",
                    c.kind.option(),
                    specs.join(", ")
                )));
            }
        }
        Ok(())
    }
}

/// An error of the checks of [`Constraints::resolve`], whose messages name the options
/// as `{fix}`, `{bounds}`, `{prior}`, as a [`crate::choice::FieldError`].
fn as_field_error(e: anyhow::Error) -> anyhow::Error {
    field_error(format!("{e:#}"))
}

/// A Gaussian prior on one flat parameter.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Prior {
    pub name: String,
    pub index: usize,
    pub mean: f64,
    pub sd: f64,
}

/// The resolved constraints of one model.
#[derive(Clone, Debug)]
pub struct Constraints {
    /// Flat declarations with the narrowed bounds.
    pub decls: Vec<ParamDecl>,
    /// Fixed value per flat entry (None: fitted).
    pub fixed: Vec<Option<f64>>,
    /// Flat indices of the fitted parameters, ascending.
    pub free: Vec<usize>,
    pub priors: Vec<Prior>,
    /// The smoothness prior's rows: the second differences of each chain of knots the
    /// model declares ([`crate::bsdf::ParamDecl::knot`]), as (flat index, coefficient).
    /// Each is one more residual (Σ c_j θ_j)/`smooth_sd` where `smooth_sd` is set.
    pub smooth: Vec<Vec<(usize, f64)>>,
    /// The smoothness prior's standard deviation of a second difference (in the knots'
    /// units), chosen by the fit ([`crate::inference::fit::Smoothness`]); None: no prior.
    pub smooth_sd: Option<f64>,
    /// Flat indices whose bounds were narrowed.
    pub narrowed: Vec<usize>,
    names: Vec<String>,
}

/// The second differences s_{k−1} − 2 s_k + s_{k+1} along each run of consecutive knot
/// parameters (a chain anchored at s_0 = 0 before its first knot, which has no parameter).
/// A per-channel knot (`+fresnel`) takes one flat entry per channel, side by side: its run
/// holds one chain per channel, every `width`-th entry.
fn smoothness_rows(decls: &[ParamDecl]) -> Vec<Vec<(usize, f64)>> {
    let mut rows = Vec::new();
    let mut j = 0;
    while j < decls.len() {
        if !decls[j].knot {
            j += 1;
            continue;
        }
        // One run per tabulated function ([`ParamDecl::knot_stem`]).
        let start = j;
        while j < decls.len() && decls[j].knot && decls[j].knot_stem() == decls[start].knot_stem() {
            j += 1;
        }
        let width = decls[start..j]
            .iter()
            .take_while(|d| d.name == decls[start].name)
            .count();
        // Knots s_1 … s_n of channel c are at start + (k − 1)·width + c.
        let n = (j - start) / width;
        for c in 0..width {
            let at = |k: usize| start + k * width + c;
            for k in 0..n - 1 {
                let mut row = vec![(at(k), -2.0), (at(k + 1), 1.0)];
                if k > 0 {
                    row.insert(0, (at(k - 1), 1.0));
                }
                rows.push(row);
            }
        }
    }
    rows
}

/// Flat indices a name stands for (see the module doc), or a message listing the names.
pub fn resolve(model: &Model, name: &str) -> Result<Vec<usize>, String> {
    let name = name.trim();
    if let Some(p) = model.params.iter().find(|p| p.name == name) {
        return Ok((p.index..p.index + p.width(model.channels)).collect());
    }
    let flat = model.flat_names();
    if let Some(i) = flat.iter().position(|n| n == name) {
        return Ok(vec![i]);
    }
    let tail: Vec<_> = model
        .params
        .iter()
        .filter(|p| p.name.rsplit('.').next() == Some(name))
        .collect();
    match tail.as_slice() {
        [p] => Ok((p.index..p.index + p.width(model.channels)).collect()),
        [] => Err(format!(
            "model {} has no parameter '{name}' (it has: {})",
            model.spec,
            model
                .params
                .iter()
                .map(|p| p.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )),
        many => Err(format!(
            "'{name}' is ambiguous in model {}: say which of {}",
            model.spec,
            many.iter()
                .map(|p| p.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )),
    }
}

fn number(s: &str, what: &str, option: &str, item: &str) -> anyhow::Result<f64> {
    s.trim()
        .parse::<f64>()
        .ok()
        .filter(|x| x.is_finite())
        .ok_or_else(|| {
            field_error(format!(
                "{option} {item}: {what} '{}' is not a number",
                s.trim()
            ))
        })
}

impl Constraints {
    /// No constraint: every parameter free within its declared bounds.
    pub fn none(model: &Model) -> Constraints {
        Constraints {
            decls: model.flat_decls(),
            fixed: vec![None; model.dim],
            free: (0..model.dim).collect(),
            priors: vec![],
            smooth: smoothness_rows(&model.flat_decls()),
            smooth_sd: None,
            narrowed: vec![],
            names: model.flat_names(),
        }
    }

    /// Resolve `spec` against `model`. With `lenient`, a name the model lacks is skipped
    /// (runs over several models check the names once, [`ConstraintSpec::check_names_against`]);
    /// an ambiguous name is always an error.
    pub fn resolve(
        model: &Model,
        spec: &ConstraintSpec,
        lenient: bool,
    ) -> anyhow::Result<Constraints> {
        Constraints::resolve_options(model, spec, lenient).map_err(as_field_error)
    }

    /// [`Constraints::resolve`], its messages naming the options as `{fix}`, `{bounds}`,
    /// `{prior}`.
    fn resolve_options(
        model: &Model,
        spec: &ConstraintSpec,
        lenient: bool,
    ) -> anyhow::Result<Constraints> {
        let mut c = Constraints::none(model);
        let lookup = |option: &str, item: &str, name: &str| -> anyhow::Result<Option<Vec<usize>>> {
            match resolve(model, name) {
                Ok(ix) => Ok(Some(ix)),
                Err(msg) if lenient && !msg.contains("ambiguous") => Ok(None),
                Err(msg) => anyhow::bail!("{option} {item}: {msg}"),
            }
        };
        for con in spec.of(ConstraintKind::Bounds) {
            let item = con.text();
            let (lo, hi) = (con.values[0], con.values[1]);
            let Some(ix) = lookup("{bounds}", item, &con.name)? else {
                continue;
            };
            for j in ix {
                let d = &mut c.decls[j];
                anyhow::ensure!(lo < hi, "{{bounds}} {item}: LO must be below HI");
                anyhow::ensure!(
                    lo >= d.lo && hi <= d.hi,
                    "{{bounds}} {item}: [{lo}, {hi}] is not inside {}'s declared range [{}, {}] (the model is not defined beyond it)",
                    c.names[j],
                    d.lo,
                    d.hi
                );
                d.lo = lo;
                d.hi = hi;
                if d.scale == Scale::Log {
                    // Declared lo > 0 already guarantees lo > 0 here.
                    debug_assert!(lo > 0.0);
                }
                d.default = d.default.clamp(lo, hi);
                c.narrowed.push(j);
            }
        }
        for con in spec.of(ConstraintKind::Fix) {
            let (item, name, values) = (con.text(), con.name.as_str(), &con.values);
            let Some(ix) = lookup("{fix}", item, name)? else {
                continue;
            };
            anyhow::ensure!(
                values.len() == 1 || values.len() == ix.len(),
                "{{fix}} {item}: {name} has {} entries; give 1 value or {} separated by ':'",
                ix.len(),
                ix.len()
            );
            for (k, &j) in ix.iter().enumerate() {
                let v = if values.len() == 1 {
                    values[0]
                } else {
                    values[k]
                };
                let d = &c.decls[j];
                anyhow::ensure!(
                    v >= d.lo && v <= d.hi,
                    "{{fix}} {item}: {} = {v} is outside its range [{}, {}]",
                    c.names[j],
                    d.lo,
                    d.hi
                );
                c.fixed[j] = Some(v);
            }
        }
        for con in spec.of(ConstraintKind::Prior) {
            let item = con.text();
            let (mean, sd) = (con.values[0], con.values[1]);
            anyhow::ensure!(sd > 0.0, "{{prior}} {item}: SD must be positive");
            let Some(ix) = lookup("{prior}", item, &con.name)? else {
                continue;
            };
            for j in ix {
                anyhow::ensure!(
                    c.fixed[j].is_none(),
                    "{{prior}} {item}: {} is fixed by {{fix}}; a prior on it would change nothing",
                    c.names[j]
                );
                c.priors.push(Prior {
                    name: c.names[j].clone(),
                    index: j,
                    mean,
                    sd,
                });
            }
        }
        c.free = (0..model.dim).filter(|&j| c.fixed[j].is_none()).collect();
        anyhow::ensure!(
            !c.free.is_empty(),
            "{{fix}} leaves no parameter of {} to fit",
            model.spec
        );
        Ok(c)
    }

    /// Number of fitted parameters.
    pub fn dim(&self) -> usize {
        self.free.len()
    }

    /// Whether anything is constrained (else the fit is the plain one).
    pub fn is_trivial(&self) -> bool {
        self.free.len() == self.fixed.len() && self.prior_rows() == 0 && self.narrowed.is_empty()
    }

    /// The residual rows the priors add beside the data's: one per `--prior`, and the
    /// smoothness prior's where it is on.
    pub fn prior_rows(&self) -> usize {
        self.priors.len() + self.smooth_sd.map_or(0, |_| self.smooth.len())
    }

    /// Free unit-box coordinates → full physical vector.
    pub fn from_unit(&self, unit: &[f64]) -> Vec<f64> {
        let mut flat: Vec<f64> = self
            .fixed
            .iter()
            .zip(&self.decls)
            .map(|(f, d)| f.unwrap_or(d.default))
            .collect();
        for (&j, &u) in self.free.iter().zip(unit) {
            flat[j] = self.decls[j].from_unit(u);
        }
        flat
    }

    /// Full physical vector → free unit-box coordinates (clamped to the narrowed box).
    pub fn to_unit(&self, flat: &[f64]) -> Vec<f64> {
        self.free
            .iter()
            .map(|&j| self.decls[j].to_unit(flat[j]))
            .collect()
    }

    /// The prior residuals at a full physical vector: (θ − mean)/sd per `--prior`, then
    /// the smoothness rows (Σ c_j θ_j)/sd.
    pub fn prior_residuals<'a>(&'a self, flat: &'a [f64]) -> impl Iterator<Item = f64> + 'a {
        let smooth = self.smooth_sd.into_iter().flat_map(move |sd| {
            self.smooth
                .iter()
                .map(move |row| row.iter().map(|&(j, c)| c * flat[j]).sum::<f64>() / sd)
        });
        self.priors
            .iter()
            .map(|p| (flat[p.index] - p.mean) / p.sd)
            .chain(smooth)
    }

    /// The prior rows' gradients over the free parameters, each scaled by 1/sd: a `--prior`
    /// row has 1/sd at its parameter, a smoothness row c_j/sd at its knots (the rows of
    /// JᵀJ that the priors add; their residuals have unit variance).
    pub fn prior_gradients(&self) -> Vec<Vec<(usize, f64)>> {
        let at = |j: usize| self.free.iter().position(|&f| f == j);
        let mut out: Vec<Vec<(usize, f64)>> = self
            .priors
            .iter()
            .map(|p| at(p.index).map(|c| (c, 1.0 / p.sd)).into_iter().collect())
            .collect();
        if let Some(sd) = self.smooth_sd {
            out.extend(self.smooth.iter().map(|row| {
                row.iter()
                    .filter_map(|&(j, c)| at(j).map(|k| (k, c / sd)))
                    .collect()
            }));
        }
        out
    }

    /// Σ of the squared prior residuals.
    pub fn prior_chi2(&self, flat: &[f64]) -> f64 {
        self.prior_residuals(flat).map(|r| r * r).sum()
    }

    /// Warnings for fitted parameters that ended on a bound (within 1e-6 of the unit
    /// box's edge): their uncertainty is then not a symmetric interval, and a narrowed
    /// bound may be what holds them.
    pub fn on_bound_warnings(&self, flat: &[f64]) -> Vec<String> {
        let mut w = Vec::new();
        for &j in &self.free {
            let d = &self.decls[j];
            let u = d.to_unit(flat[j]);
            let edge = if u <= 1e-6 {
                Some(("lower", d.lo))
            } else if u >= 1.0 - 1e-6 {
                Some(("upper", d.hi))
            } else {
                None
            };
            if let Some((which, at)) = edge {
                let how = if self.narrowed.contains(&j) {
                    "the bounds given"
                } else {
                    "its declared range"
                };
                w.push(format!(
                    "{} = {} ended on its {which} bound {at} ({how}): the optimum may lie beyond it, and its uncertainty is not a symmetric interval",
                    self.names[j], flat[j]
                ));
            }
        }
        w
    }

    /// What was imposed, for reports: `{fixed: {name: v}, bounds: {name: [lo, hi]}, priors: [...]}`.
    pub fn to_json(&self) -> serde_json::Value {
        let mut fixed = serde_json::Map::new();
        for (j, f) in self.fixed.iter().enumerate() {
            if let Some(v) = f {
                fixed.insert(self.names[j].clone(), serde_json::json!(v));
            }
        }
        let mut bounds = serde_json::Map::new();
        for &j in &self.narrowed {
            bounds.insert(
                self.names[j].clone(),
                serde_json::json!([self.decls[j].lo, self.decls[j].hi]),
            );
        }
        let mut out =
            serde_json::json!({ "fixed": fixed, "bounds": bounds, "priors": self.priors });
        if let Some(sd) = self.smooth_sd {
            out["smoothness_sd"] = serde_json::json!(sd);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(fix: &[&str], bounds: &[&str], priors: &[&str]) -> ConstraintSpec {
        ConstraintSpec::parse(fix, bounds, priors, false).unwrap()
    }

    #[test]
    fn names_resolve_by_full_flat_and_last_component() {
        let m = Model::parse("fa(lambert)", 3).unwrap();
        assert_eq!(resolve(&m, "base.rho").unwrap().len(), 3);
        assert_eq!(
            resolve(&m, "rho").unwrap(),
            resolve(&m, "base.rho").unwrap()
        );
        let one = resolve(&m, "base.rho[1]").unwrap();
        assert_eq!(one.len(), 1);
        assert_eq!(m.flat_names()[one[0]], "base.rho[1]");
        let err = resolve(&m, "sigma").unwrap_err();
        assert!(
            err.contains("no parameter 'sigma'") && err.contains("lobe.alpha"),
            "{err}"
        );
    }

    /// One chain of second differences per tabulated function and, for per-channel knots,
    /// per channel: each row's entries are knots of one chain, every knot in some row.
    #[test]
    fn smoothness_rows_follow_each_chain_and_channel() {
        let ndf = crate::bsdf::ndf::KNOTS - 1;
        for (spec, channels, chains, knots) in [
            ("ggx+ndf", 3, 1, ndf),
            ("ggx+fresnel", 3, 3, 8),
            ("fa(lambert)+coat+ndf", 2, 2, ndf),
            // The highlight's per-channel curve beside the base's shared profile.
            ("fa(lambert)+fresnel+body", 2, 3, 8),
        ] {
            let m = Model::parse(spec, channels).unwrap();
            let rows = smoothness_rows(&m.flat_decls());
            assert_eq!(rows.len(), chains * (knots - 1), "{spec}");
            let names = m.flat_names();
            let channel = |j: usize| names[j].split('[').nth(1).map(str::to_string);
            let stem = |j: usize| {
                names[j]
                    .split(|c: char| c.is_ascii_digit())
                    .next()
                    .map(str::to_string)
            };
            for row in &rows {
                let (first, function) = (channel(row[0].0), stem(row[0].0));
                assert!(
                    row.iter().all(|&(j, _)| m.flat_decls()[j].knot
                        && channel(j) == first
                        && stem(j) == function),
                    "{spec}: {row:?}"
                );
                assert_eq!(
                    row.iter().map(|&(_, c)| c).sum::<f64>(),
                    if row.len() == 3 { 0.0 } else { -1.0 }
                );
            }
        }
    }

    #[test]
    fn fixed_parameters_leave_the_free_set_and_come_back_in_from_unit() {
        let m = Model::parse("fa(lambert)", 1).unwrap();
        let c = Constraints::resolve(&m, &spec(&["eta=1.6"], &[], &[]), false).unwrap();
        assert_eq!(c.dim(), m.dim - 1);
        let flat = c.from_unit(&vec![0.5; c.dim()]);
        let eta = resolve(&m, "eta").unwrap()[0];
        assert_eq!(flat[eta], 1.6);
        // Round trip of the free coordinates.
        let u = c.to_unit(&flat);
        assert!(u.iter().all(|&x| (x - 0.5).abs() < 1e-12), "{u:?}");
    }

    #[test]
    fn bounds_narrow_the_unit_box_and_are_checked() {
        let m = Model::parse("ggx", 1).unwrap();
        let c = Constraints::resolve(&m, &spec(&[], &["alpha=0.1:0.2"], &[]), false).unwrap();
        let a = resolve(&m, "alpha").unwrap()[0];
        let lo = c.from_unit(&[0.0, 0.0, 0.0])[a];
        let hi = c.from_unit(&[1.0, 1.0, 1.0])[a];
        assert!(
            (lo - 0.1).abs() < 1e-12 && (hi - 0.2).abs() < 1e-12,
            "{lo} {hi}"
        );
        let err = Constraints::resolve(&m, &spec(&[], &["alpha=0.1:7"], &[]), false)
            .unwrap_err()
            .to_string();
        assert!(err.contains("declared range"), "{err}");
        let err = Constraints::resolve(&m, &spec(&[], &["alpha=0.3:0.2"], &[]), false)
            .unwrap_err()
            .to_string();
        assert!(err.contains("LO must be below HI"), "{err}");
        // An end on a narrowed bound is reported as such.
        let w = c.on_bound_warnings(&c.from_unit(&[0.5, 1.0, 0.5]));
        assert!(
            w.len() == 1 && w[0].contains("(the bounds given)") && !w[0].contains("--"),
            "{w:?}"
        );
    }

    #[test]
    fn malformed_options_are_errors_naming_the_option() {
        for ((fix, priors), want) in [
            ((&["rho"][..], &[][..]), "fix 'rho': expected NAME=VALUE"),
            ((&["rho=x"], &[]), "VALUE 'x' is not a number"),
            ((&[], &["rho=0.5"]), "expected NAME=MEAN:SD"),
        ] {
            let err = ConstraintSpec::parse(fix, &[], priors, false)
                .unwrap_err()
                .to_string();
            assert!(err.contains(want), "{fix:?} {priors:?}: {err}");
        }
        let m = Model::parse("lambert", 1).unwrap();
        for (s, want) in [
            (spec(&[], &[], &["rho=0.5:0"]), "SD must be positive"),
            (
                spec(&["rho=0.5"], &[], &["rho=0.5:0.1"]),
                "is fixed by fix;",
            ),
            (spec(&["rho=2"], &[], &[]), "outside its range"),
            (spec(&["rho=0.5"], &[], &[]), "leaves no parameter"),
        ] {
            let err = Constraints::resolve(&m, &s, false).unwrap_err().to_string();
            assert!(err.contains(want), "{s:?}: {err}");
        }
        // Lenient resolution skips a name the model lacks, strict names it.
        assert!(Constraints::resolve(&m, &spec(&["alpha=0.2"], &[], &[]), true).is_ok());
        assert!(Constraints::resolve(&m, &spec(&["alpha=0.2"], &[], &[]), false).is_err());
    }

    /// A constraint given as numbers is the one its text gives, and is written as that
    /// text; numbers a text could not hold are refused with the text's messages.
    #[test]
    fn constraints_from_numbers_are_those_of_their_text() {
        use ConstraintKind::{Bounds, Fix, Prior};
        for (kind, name, values, text) in [
            (Fix, "sigma", &[0.3][..], "sigma=0.3"),
            (Fix, "rho", &[0.4, 0.5, 0.6], "rho=0.4:0.5:0.6"),
            (Bounds, "alpha", &[0.01, 0.5], "alpha=0.01:0.5"),
            (Prior, "eta", &[1.5, 0.0], "eta=1.5:0.0"),
        ] {
            let given = Constraint::new(kind, name, values).unwrap();
            assert_eq!(given.text(), text);
            assert_eq!(given, Constraint::parse(kind, text).unwrap());
        }
        for (kind, values, want) in [
            (Bounds, &[0.1][..], "bounds 'a=0.1': expected NAME=LO:HI"),
            (
                Prior,
                &[0.1, 0.2, 0.3],
                "prior 'a=0.1:0.2:0.3': expected NAME=MEAN:SD",
            ),
            (Fix, &[], "fix 'a=': expected NAME=VALUE"),
            (
                Bounds,
                &[0.1, f64::NAN],
                "bounds a=0.1:NaN: HI 'NaN' is not a number",
            ),
        ] {
            let err = Constraint::new(kind, "a", values).unwrap_err().to_string();
            assert_eq!(err, want);
        }
    }

    /// A spec is saved as the options' texts, as given, and read back the same.
    #[test]
    fn specs_are_saved_as_their_texts() {
        let s = ConstraintSpec::parse(&["sigma = 0.30"], &["alpha=0.1:0.2"], &[], true).unwrap();
        let json = serde_json::to_string(&s).unwrap();
        assert_eq!(
            json,
            r#"{"fix":["sigma = 0.30"],"bounds":["alpha=0.1:0.2"],"priors":[],"lenient":true}"#
        );
        assert_eq!(serde_json::from_str::<ConstraintSpec>(&json).unwrap(), s);
        let err = serde_json::from_str::<ConstraintSpec>(r#"{"fix":["sigma"]}"#).unwrap_err();
        assert!(
            err.to_string().contains("fix 'sigma': expected NAME=VALUE"),
            "{err}"
        );
        assert_eq!(
            serde_json::from_str::<ConstraintSpec>("{}").unwrap(),
            ConstraintSpec::default()
        );
    }
}
