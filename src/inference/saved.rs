//! A fit read back from the JSON of `bsdfit fit --json` (docs/output.md), to use it
//! elsewhere (`bsdfit eval`, `bsdfit export`), and the model's standard uncertainty
//! propagated from the fit's covariance.
//!
//! The model is rebuilt from `model`, `channels` and `axes` (the same compilation as the
//! fit's), and the JSON's `flat_names` must be the rebuilt model's: a JSON written by
//! another version of the catalogue, or edited by hand, is refused rather than read with
//! its values in the wrong places. The covariance of the flat parameters is
//! cov = diag(std) · corr · diag(std) from `flat_std` and `correlation`.
//!
//! # Propagation
//!
//! The standard uncertainty of the model value f(θ̂) at one geometry is the first-order
//! (GUM, JCGM 100:2008 §5.1.2, Eq. 13) u_f² = gᵀ cov g with g = ∂f/∂θ at θ̂, by central
//! differences of step ±[`DU`] in the unit box of each parameter (so a log-scaled roughness
//! gets a relative step, and a parameter on a bound a one-sided one). A parameter the data
//! did not determine (`null` std) has no variance to propagate: its variance is taken as
//! 0, so where the model depends on it u_f is a lower bound. [`Propagator::eval`] reports
//! that dependence so that callers can say where.

use crate::bsdf::Model;
use crate::choice::field_error;
use anyhow::{Context, Result};
use glam::DVec3;
use serde::Deserialize;
use std::path::Path;

/// Unit-box half step of the central differences of [`Propagator`]. Truncation error
/// O(DU²) and rounding O(ε/DU) are both ≲ 1e-10 relative in f64.
pub const DU: f64 = 1e-5;

/// One fitted model read back from a fit report.
#[derive(Clone, Debug)]
pub struct SavedFit {
    /// The model as compiled for the fit (its channels and planes).
    pub model: Model,
    /// The fitted flat parameter vector.
    pub flat: Vec<f64>,
    /// Standard uncertainty of each flat parameter; `None` where the data did not
    /// determine it.
    pub std: Vec<Option<f64>>,
    /// Correlation matrix of the flat parameters (`None` where undetermined).
    pub correlation: Vec<Vec<Option<f64>>>,
    /// Wavelengths (nm) of the fit's channels, in the fit's channel order.
    pub channels: Vec<f64>,
    /// The fitted material (the report's `material`), for the headers of derived files.
    pub material: String,
    /// The data the fit was made on (the report's `data`).
    pub data: String,
    /// The fit's warnings (assumed uncertainties, undetermined parameters, …): every file
    /// derived from the fit repeats them.
    pub warnings: Vec<String>,
}

/// What a fit JSON holds: one fit, or one fit per measurement plane (`fit --per-axis`).
#[derive(Clone, Debug)]
pub enum FitFile {
    Single(Box<SavedFit>),
    /// (φ of the plane in degrees, its fit), in the file's order.
    PerAxis(Vec<(f64, SavedFit)>),
}

/// The fields of a fit report that are needed to use it (docs/output.md).
#[derive(Deserialize)]
struct ReportJson {
    model: String,
    channels: Vec<f64>,
    #[serde(default)]
    axes: Option<Vec<f64>>,
    flat_names: Vec<String>,
    flat_params: Vec<Option<f64>>,
    flat_std: Vec<Option<f64>>,
    correlation: Vec<Vec<Option<f64>>>,
    #[serde(default)]
    material: Option<String>,
    #[serde(default)]
    data: Option<String>,
    #[serde(default)]
    warnings: Vec<String>,
}

impl FitFile {
    /// Read a fit JSON file.
    pub fn read(path: &Path) -> Result<FitFile> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        FitFile::parse(&text, &path.display().to_string())
    }

    /// Parse the text of a fit JSON; `file` names it in messages.
    pub fn parse(text: &str, file: &str) -> Result<FitFile> {
        let v: serde_json::Value =
            serde_json::from_str(text).map_err(|e| anyhow::anyhow!("{file}: not JSON ({e})"))?;
        if let Some(list) = v.get("per_axis") {
            let list = list.as_array().ok_or_else(|| {
                anyhow::anyhow!("{file}: 'per_axis' should be an array of {{phi, fit}}")
            })?;
            anyhow::ensure!(!list.is_empty(), "{file}: 'per_axis' is empty");
            let mut fits = Vec::new();
            for (k, item) in list.iter().enumerate() {
                let phi = item
                    .get("phi")
                    .and_then(|p| p.as_f64())
                    .filter(|p| p.is_finite())
                    .ok_or_else(|| anyhow::anyhow!("{file}: per_axis[{k}] has no number 'phi'"))?;
                let fit = item
                    .get("fit")
                    .ok_or_else(|| anyhow::anyhow!("{file}: per_axis[{k}] has no 'fit'"))?;
                let saved =
                    SavedFit::from_value(fit, &format!("{file}: per_axis[{k}] (φ = {phi}°)"))?;
                fits.push((phi, saved));
            }
            return Ok(FitFile::PerAxis(fits));
        }
        if v.is_array() {
            anyhow::bail!(
                "{file}: a JSON array (a sweep's results.json?): its rows carry no correlation matrix; give the JSON of `bsdfit fit --json`"
            );
        }
        if v.get("steps").is_some() && v.get("final_model").is_some() {
            anyhow::bail!(
                "{file}: a `bsdfit diagnose` report; fit its final model with `bsdfit fit --model SPEC --json FIT.json` and use that"
            );
        }
        Ok(FitFile::Single(Box::new(SavedFit::from_value(&v, file)?)))
    }

    /// The single fit, or the fit of plane `plane` (degrees) of a per-axis file. The
    /// errors name the option as a field (`{plane}`): `--plane` on the command line.
    pub fn select(self, plane: Option<f64>, file: &str) -> Result<SavedFit> {
        let file = file.replace('{', "(").replace('}', ")");
        match (self, plane) {
            (FitFile::Single(f), None) => Ok(*f),
            (FitFile::Single(_), Some(p)) => Err(field_error(format!(
                "{{plane={p}}}: {file} holds one fit, not one per plane (`fit --per-axis`); omit {{plane}}"
            ))),
            (FitFile::PerAxis(fits), Some(p)) => {
                let planes = planes_list(&fits);
                fits.into_iter()
                    .find(|(phi, _)| same_plane(*phi, p))
                    .map(|(_, f)| f)
                    .ok_or_else(|| field_error(format!("{{plane={p}}}: {file} has fits for φ = {planes}° only")))
            }
            (FitFile::PerAxis(fits), None) => Err(field_error(format!(
                "{file} holds one fit per measurement plane (`fit --per-axis`), for φ = {}°: choose one with {{plane=PHI}}",
                planes_list(&fits)
            ))),
        }
    }
}

fn planes_list(fits: &[(f64, SavedFit)]) -> String {
    fits.iter()
        .map(|(p, _)| p.to_string())
        .collect::<Vec<_>>()
        .join("°, ")
}

/// Whether two plane azimuths (degrees) name the same plane (φ mod 180°, to 1e-6°).
pub fn same_plane(a: f64, b: f64) -> bool {
    let d = (a - b).rem_euclid(180.0);
    d < 1e-6 || 180.0 - d < 1e-6
}

impl SavedFit {
    /// A fit report (the object `bsdfit fit --json` writes), checked against the model
    /// rebuilt from it.
    pub fn from_value(v: &serde_json::Value, file: &str) -> Result<SavedFit> {
        anyhow::ensure!(
            v.is_object(),
            "{file}: expected the JSON object of `bsdfit fit --json`"
        );
        let r: ReportJson = serde_json::from_value(v.clone()).map_err(|e| {
            anyhow::anyhow!("{file}: not a fit report of `bsdfit fit --json` ({e}; docs/output.md)")
        })?;
        anyhow::ensure!(
            !r.channels.is_empty() && r.channels.iter().all(|w| w.is_finite() && *w > 0.0),
            "{file}: 'channels' must list the fit's wavelengths (nm), got {:?}",
            r.channels
        );
        let axes = r.axes.unwrap_or_else(|| vec![0.0]);
        anyhow::ensure!(
            !axes.is_empty() && axes.iter().all(|a| a.is_finite()),
            "{file}: 'axes' must list the fit's planes (degrees), got {axes:?}"
        );
        let model = Model::parse_for(&r.model, r.channels.len(), &axes)
            .map_err(|e| anyhow::anyhow!("{file}: 'model': {e}"))?;
        let names = model.flat_names();
        let p = model.dim;
        anyhow::ensure!(
            r.flat_names == names,
            "{file}: 'flat_names' {:?} are not the parameters of {} compiled for {} channel(s) and planes {:?}: {:?} (a report of another bsdfit version, or edited?)",
            r.flat_names,
            model.spec,
            r.channels.len(),
            model.axes,
            names
        );
        anyhow::ensure!(
            r.flat_params.len() == p && r.flat_std.len() == p,
            "{file}: 'flat_params' and 'flat_std' need {p} entries each (got {} and {})",
            r.flat_params.len(),
            r.flat_std.len()
        );
        let decls = model.flat_decls();
        let mut flat = Vec::with_capacity(p);
        for (j, v) in r.flat_params.iter().enumerate() {
            let d = &decls[j];
            let x = v.filter(|x| x.is_finite()).ok_or_else(|| {
                anyhow::anyhow!("{file}: flat_params[{j}] ({}) is not a number", names[j])
            })?;
            anyhow::ensure!(
                x >= d.lo && x <= d.hi,
                "{file}: {} = {x} is outside its bounds [{}, {}]",
                names[j],
                d.lo,
                d.hi
            );
            flat.push(x);
        }
        for (j, s) in r.flat_std.iter().enumerate() {
            if let Some(s) = s {
                anyhow::ensure!(
                    s.is_finite() && *s >= 0.0,
                    "{file}: flat_std[{j}] ({}) = {s} is not a standard uncertainty (finite, ≥ 0)",
                    names[j]
                );
            }
        }
        anyhow::ensure!(
            r.correlation.len() == p && r.correlation.iter().all(|row| row.len() == p),
            "{file}: 'correlation' must be a {p} × {p} matrix"
        );
        for a in 0..p {
            for b in 0..p {
                let positive = |j: usize| r.flat_std[j].is_some_and(|s| s > 0.0);
                match r.correlation[a][b] {
                    Some(c) => anyhow::ensure!(
                        c.is_finite() && c.abs() <= 1.0 + 1e-9,
                        "{file}: correlation[{a}][{b}] = {c} is outside [−1, 1]"
                    ),
                    None => anyhow::ensure!(
                        !(positive(a) && positive(b)),
                        "{file}: correlation[{a}][{b}] is null although {} and {} have standard uncertainties",
                        names[a],
                        names[b]
                    ),
                }
            }
        }
        Ok(SavedFit {
            model,
            flat,
            std: r.flat_std,
            correlation: r.correlation,
            channels: r.channels,
            material: r.material.unwrap_or_default(),
            data: r.data.unwrap_or_default(),
            warnings: r.warnings,
        })
    }

    /// The covariance matrix cov = diag(std) · corr · diag(std), row-major P × P, with 0
    /// for the variance and covariances of undetermined parameters.
    pub fn covariance(&self) -> Vec<f64> {
        let p = self.model.dim;
        let mut cov = vec![0.0; p * p];
        for a in 0..p {
            for b in 0..p {
                if let (Some(sa), Some(sb)) = (self.std[a], self.std[b]) {
                    let c = if a == b {
                        1.0
                    } else {
                        self.correlation[a][b].unwrap_or(0.0)
                    };
                    cov[a * p + b] = sa * c * sb;
                }
            }
        }
        cov
    }

    /// Names of the parameters the fit could not determine (null std).
    pub fn undetermined(&self) -> Vec<String> {
        let names = self.model.flat_names();
        (0..self.model.dim)
            .filter(|&j| self.std[j].is_none())
            .map(|j| names[j].clone())
            .collect()
    }

    /// The fit's channel with wavelength `nm` (to 1e-6 nm), if any.
    pub fn channel_of(&self, nm: f64) -> Option<usize> {
        self.channels.iter().position(|&c| (c - nm).abs() <= 1e-6)
    }

    /// The index in the model's planes of the plane φ (degrees), if the model has
    /// per-plane parameters and one of its planes is φ.
    pub fn axis_of(&self, phi: f64) -> Option<usize> {
        self.model.axes.iter().position(|&a| same_plane(a, phi))
    }

    /// The fitted parameters as `name=value` pairs (flat names), for file headers.
    pub fn params_text(&self) -> String {
        self.model
            .flat_names()
            .iter()
            .zip(&self.flat)
            .zip(&self.std)
            .map(|((n, v), s)| match s {
                Some(s) => format!("{n}={v}±{s:.3e}"),
                None => format!("{n}={v}±undetermined"),
            })
            .collect::<Vec<_>>()
            .join(" ")
    }
}

/// Evaluates a fitted model with its propagated standard uncertainty (module docs).
pub struct Propagator<'a> {
    fit: &'a SavedFit,
    cov: Vec<f64>,
    /// Per group: the scalar view at θ̂, then per parameter j the views at θ̂ ± step and
    /// the physical step, for the parameters that change this group's view.
    groups: Vec<GroupViews>,
}

struct GroupViews {
    base: Vec<f64>,
    /// (flat index j, view at +, view at −, θ+ − θ−).
    diffs: Vec<(usize, Vec<f64>, Vec<f64>, f64)>,
}

/// One propagated evaluation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Propagated {
    /// The model value f(θ̂).
    pub value: f64,
    /// Its standard uncertainty sqrt(gᵀ cov g).
    pub uncertainty: f64,
    /// Whether f depends here on a parameter without a standard uncertainty (u is then a
    /// lower bound).
    pub depends_on_undetermined: bool,
}

impl<'a> Propagator<'a> {
    pub fn new(fit: &'a SavedFit) -> Propagator<'a> {
        let model = &fit.model;
        let decls = model.flat_decls();
        let unit = model.to_unit(&fit.flat);
        let groups = (0..model.groups())
            .map(|g| {
                let mut base = Vec::new();
                model.scalars_into(&fit.flat, g, &mut base);
                let mut diffs = Vec::new();
                for j in 0..model.dim {
                    let mut plus = fit.flat.clone();
                    let mut minus = fit.flat.clone();
                    plus[j] = decls[j].from_unit(unit[j] + DU);
                    minus[j] = decls[j].from_unit(unit[j] - DU);
                    let step = plus[j] - minus[j];
                    let (mut vp, mut vm) = (Vec::new(), Vec::new());
                    model.scalars_into(&plus, g, &mut vp);
                    model.scalars_into(&minus, g, &mut vm);
                    // A parameter of another channel or plane leaves this group's view as it is.
                    if step != 0.0 && (vp != base || vm != base) {
                        diffs.push((j, vp, vm, step));
                    }
                }
                GroupViews { base, diffs }
            })
            .collect();
        Propagator {
            fit,
            cov: fit.covariance(),
            groups,
        }
    }

    /// The value and propagated uncertainty at (ωi, ωo) for scalar-view group `g`
    /// ([`Model::group_of`]: the channel, and the plane under `+peraxis`).
    pub fn eval(&self, g: usize, wi: DVec3, wo: DVec3) -> Propagated {
        let root = &self.fit.model.root;
        let gv = &self.groups[g];
        let value = root.eval(&gv.base, wi, wo);
        let p = self.fit.model.dim;
        let grads: Vec<(usize, f64)> = gv
            .diffs
            .iter()
            .map(|(j, vp, vm, step)| (*j, (root.eval(vp, wi, wo) - root.eval(vm, wi, wo)) / step))
            .collect();
        let mut u2 = 0.0;
        let mut depends = false;
        for &(a, ga) in &grads {
            if self.fit.std[a].is_none() && ga != 0.0 {
                depends = true;
            }
            for &(b, gb) in &grads {
                u2 += ga * self.cov[a * p + b] * gb;
            }
        }
        Propagated {
            value,
            // gᵀ cov g ≥ 0 up to rounding of a correlation matrix written to 1e-16.
            uncertainty: u2.max(0.0).sqrt(),
            depends_on_undetermined: depends,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(spec: &str) -> serde_json::Value {
        let m = Model::parse(spec, 1).unwrap();
        let p = m.dim;
        serde_json::json!({
            "model": spec, "channels": [550.0], "axes": [0.0],
            "flat_names": m.flat_names(), "flat_params": m.defaults(),
            "flat_std": vec![0.01; p],
            "correlation": (0..p).map(|a| (0..p).map(|b| if a == b { 1.0 } else { 0.0 }).collect::<Vec<_>>()).collect::<Vec<_>>(),
        })
    }

    /// The plane errors name the option as a field: `--plane` on the command line,
    /// `plane` in Python.
    #[test]
    fn plane_errors_name_the_option_per_front_end() {
        let fit = || SavedFit::from_value(&report("on"), "x.json").unwrap();
        let flag = |name: &str, value: Option<&str>| {
            let flag = format!("--{name}");
            value.map_or(flag.clone(), |v| format!("{flag} {v}"))
        };
        let field = |e: anyhow::Error| e.downcast::<crate::choice::FieldError>().unwrap();
        let e = field(
            FitFile::Single(Box::new(fit()))
                .select(Some(30.0), "x.json")
                .unwrap_err(),
        );
        assert_eq!(
            e.render(&flag),
            "--plane 30: x.json holds one fit, not one per plane (`fit --per-axis`); omit --plane"
        );
        assert!(
            e.to_string().starts_with("plane=30: x.json") && e.to_string().ends_with("omit plane")
        );
        let per_axis = || FitFile::PerAxis(vec![(0.0, fit()), (90.0, fit())]);
        let e = field(per_axis().select(Some(45.0), "x.json").unwrap_err());
        assert_eq!(
            e.render(&flag),
            "--plane 45: x.json has fits for φ = 0°, 90° only"
        );
        let e = field(per_axis().select(None, "x.json").unwrap_err());
        assert!(
            e.render(&flag).ends_with("choose one with --plane PHI"),
            "{}",
            e.render(&flag)
        );
    }

    #[test]
    fn a_report_reads_back_and_bad_ones_are_named() {
        let v = report("on");
        let f = SavedFit::from_value(&v, "x.json").unwrap();
        assert_eq!(f.flat, Model::parse("on", 1).unwrap().defaults());
        let mut bad = v.clone();
        bad["flat_names"] = serde_json::json!(["rho[0]", "alpha"]);
        let e = SavedFit::from_value(&bad, "x.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("'flat_names'") && e.contains("sigma"), "{e}");
        let mut bad = v.clone();
        bad["flat_params"][1] = serde_json::json!(7.0);
        let e = SavedFit::from_value(&bad, "x.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("sigma = 7 is outside its bounds"), "{e}");
        let mut bad = v;
        bad.as_object_mut().unwrap().remove("correlation");
        let e = SavedFit::from_value(&bad, "x.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("correlation"), "{e}");
    }

    #[test]
    fn lambert_propagates_exactly() {
        // f = ρ/π: u_f = u_ρ/π.
        let mut v = report("lambert");
        v["flat_params"] = serde_json::json!([0.4]);
        v["flat_std"] = serde_json::json!([0.03]);
        let f = SavedFit::from_value(&v, "x.json").unwrap();
        let p = Propagator::new(&f).eval(0, DVec3::Z, DVec3::new(0.6, 0.0, 0.8));
        assert!((p.value - 0.4 / std::f64::consts::PI).abs() < 1e-15);
        let want = 0.03 / std::f64::consts::PI;
        assert!((p.uncertainty - want).abs() < 1e-9 * want, "{p:?}");
    }
}
