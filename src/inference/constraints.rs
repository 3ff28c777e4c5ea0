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

/// The constraint options as given (`NAME=…` strings), before they meet a model.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ConstraintSpec {
    pub fix: Vec<String>,
    pub bounds: Vec<String>,
    pub priors: Vec<String>,
    /// Skip a name the model lacks instead of failing (runs over several models, which
    /// check the names once with [`ConstraintSpec::check_names_against`]).
    pub lenient: bool,
}

impl ConstraintSpec {
    pub fn is_empty(&self) -> bool {
        self.fix.is_empty() && self.bounds.is_empty() && self.priors.is_empty()
    }

    /// Every (option, name) pair, for checks that each name means something.
    fn names(&self) -> Vec<(&'static str, String)> {
        fn name(s: &str) -> &str {
            s.split_once('=').map_or(s, |(n, _)| n).trim()
        }
        let mut v = Vec::new();
        v.extend(self.fix.iter().map(|s| ("{fix}", name(s).to_string())));
        v.extend(
            self.bounds
                .iter()
                .map(|s| ("{bounds}", name(s).to_string())),
        );
        v.extend(self.priors.iter().map(|s| ("{prior}", name(s).to_string())));
        v
    }

    /// Check, before a run over several models (sweep, diagnose), that every name given
    /// is a parameter of at least one of them; a model that lacks a name ignores it.
    pub fn check_names_against(&self, models: &[&Model]) -> anyhow::Result<()> {
        for (option, name) in self.names() {
            if !models.iter().any(|m| resolve(m, &name).is_ok()) {
                let specs: Vec<&str> = models.iter().map(|m| m.spec.as_str()).collect();
                return Err(crate::choice::field_error(format!(
                    "{option} {name}: no model of this run has a parameter '{name}' (models: {})",
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
    crate::choice::field_error(format!("{e:#}"))
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
    /// Flat indices whose bounds were narrowed.
    pub narrowed: Vec<usize>,
    names: Vec<String>,
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
        .ok_or_else(|| anyhow::anyhow!("{option} {item}: {what} '{}' is not a number", s.trim()))
}

/// `NAME=REST` → (name, rest).
fn split_item<'a>(item: &'a str, option: &str, form: &str) -> anyhow::Result<(&'a str, &'a str)> {
    item.split_once('=')
        .map(|(n, r)| (n.trim(), r.trim()))
        .filter(|(n, _)| !n.is_empty())
        .ok_or_else(|| anyhow::anyhow!("{option} '{item}': expected {form}"))
}

/// `A:B` → (A, B).
fn pair(
    rest: &str,
    option: &str,
    item: &str,
    form: &str,
    names: [&str; 2],
) -> anyhow::Result<(f64, f64)> {
    let (a, b) = rest
        .split_once(':')
        .ok_or_else(|| anyhow::anyhow!("{option} '{item}': expected {form}"))?;
    Ok((
        number(a, names[0], option, item)?,
        number(b, names[1], option, item)?,
    ))
}

impl Constraints {
    /// No constraint: every parameter free within its declared bounds.
    pub fn none(model: &Model) -> Constraints {
        Constraints {
            decls: model.flat_decls(),
            fixed: vec![None; model.dim],
            free: (0..model.dim).collect(),
            priors: vec![],
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
        for item in &spec.bounds {
            let (name, rest) = split_item(item, "{bounds}", "NAME=LO:HI")?;
            let (lo, hi) = pair(rest, "{bounds}", item, "NAME=LO:HI", ["LO", "HI"])?;
            let Some(ix) = lookup("{bounds}", item, name)? else {
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
        for item in &spec.fix {
            let (name, rest) = split_item(item, "{fix}", "NAME=VALUE")?;
            let values: Vec<f64> = rest
                .split(':')
                .map(|v| number(v, "VALUE", "{fix}", item))
                .collect::<anyhow::Result<_>>()?;
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
        for item in &spec.priors {
            let (name, rest) = split_item(item, "{prior}", "NAME=MEAN:SD")?;
            let (mean, sd) = pair(rest, "{prior}", item, "NAME=MEAN:SD", ["MEAN", "SD"])?;
            anyhow::ensure!(sd > 0.0, "{{prior}} {item}: SD must be positive");
            let Some(ix) = lookup("{prior}", item, name)? else {
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
        self.free.len() == self.fixed.len() && self.priors.is_empty() && self.narrowed.is_empty()
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

    /// The prior residuals (θ − mean)/sd at a full physical vector.
    pub fn prior_residuals<'a>(&'a self, flat: &'a [f64]) -> impl Iterator<Item = f64> + 'a {
        self.priors.iter().map(|p| (flat[p.index] - p.mean) / p.sd)
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
        serde_json::json!({ "fixed": fixed, "bounds": bounds, "priors": self.priors })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(fix: &[&str], bounds: &[&str], priors: &[&str]) -> ConstraintSpec {
        let v = |a: &[&str]| a.iter().map(|s| s.to_string()).collect();
        ConstraintSpec {
            fix: v(fix),
            bounds: v(bounds),
            priors: v(priors),
            lenient: false,
        }
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
        let m = Model::parse("lambert", 1).unwrap();
        for (s, want) in [
            (spec(&["rho"], &[], &[]), "fix 'rho': expected NAME=VALUE"),
            (spec(&["rho=x"], &[], &[]), "VALUE 'x' is not a number"),
            (spec(&[], &[], &["rho=0.5"]), "expected NAME=MEAN:SD"),
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
}
