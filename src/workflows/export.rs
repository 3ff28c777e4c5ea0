//! Using a fit elsewhere (docs/export.md): the fitted model evaluated, with its propagated
//! standard uncertainty, at the geometries of a data file or of a named geometry
//! (`bsdfit eval`), on a dense grid (`bsdfit export --format tabulated`), as a MERL table
//! (`--format merl`) or as a Mitsuba 3 `<bsdf>` where one is exactly the model
//! (`--format mitsuba`). Everything runs on the CPU reference ([`crate::bsdf::Model`] in
//! f64): no GPU is needed.

use crate::bsdf::MitsubaField;
use crate::data::readers::merl;
use crate::data::{Dataset, Kind, RawRow, ReadOptions, Sample};
use crate::inference::saved::{same_plane, FitFile, Propagated, Propagator, SavedFit};
use crate::text::plural_with as count;
use anyhow::Result;
use rayon::prelude::*;
use std::collections::BTreeMap;

/// A dataset of model values and their propagated uncertainties, ready to write as v1.
pub struct Predicted {
    pub data: Dataset,
    /// What the user must know about the numbers (stderr, and the file's header).
    pub warnings: Vec<String>,
}

/// Below this the reader refuses an uncertainty (max(1e-12·|value|, 1e-30 sr⁻¹), see
/// docs/conventions.md) unless `--allow-zero-uncertainty` is given.
fn reader_accepts(value: f64, u: f64) -> bool {
    u >= crate::data::MIN_ABS_UNCERTAINTY && u >= crate::data::MIN_REL_UNCERTAINTY * value.abs()
}

/// The plane (φ mod 180°, degrees) of a sample; at θo = 0, the plane of the azimuth
/// written with it (docs/conventions.md, measurement planes).
fn sample_plane(s: &Sample) -> f64 {
    s.phi_o.to_degrees().rem_euclid(180.0)
}

/// Which fit, and which of its scalar-view groups, evaluates each sample.
enum Resolver<'a> {
    Single(&'a SavedFit, Propagator<'a>),
    PerAxis(Vec<(f64, &'a SavedFit, Propagator<'a>)>),
}

impl<'a> Resolver<'a> {
    fn new(file: &'a FitFile) -> Resolver<'a> {
        match file {
            FitFile::Single(f) => Resolver::Single(f, Propagator::new(f)),
            FitFile::PerAxis(fits) => Resolver::PerAxis(
                fits.iter()
                    .map(|(phi, f)| (*phi, f, Propagator::new(f)))
                    .collect(),
            ),
        }
    }

    fn first(&self) -> &SavedFit {
        match self {
            Resolver::Single(f, _) => f,
            Resolver::PerAxis(v) => v[0].1,
        }
    }

    /// (propagator, group) of a sample, or why it cannot be evaluated.
    fn resolve(&self, s: &Sample) -> Result<(&Propagator<'a>, usize), String> {
        let plane = sample_plane(s);
        let at_normal = s.theta_o == 0.0;
        let channel = |f: &SavedFit| {
            f.channel_of(s.wavelength_nm).ok_or_else(|| {
                format!(
                    "wavelength {} nm is not a channel of the fit ({} nm)",
                    s.wavelength_nm,
                    list(&f.channels)
                )
            })
        };
        match self {
            Resolver::Single(f, prop) => {
                let ch = channel(f)?;
                if f.model.axes.len() <= 1 {
                    return Ok((prop, ch));
                }
                // +peraxis: the sample's plane picks the roughness; a normal sample whose
                // azimuth names no plane goes to the first, as when data are read.
                let axis = match f.axis_of(plane) {
                    Some(a) => a,
                    None if at_normal => 0,
                    None => {
                        return Err(format!(
                            "φo = {plane}° (mod 180°) is not one of the planes the fit has roughnesses for ({}°)",
                            list(&f.model.axes)
                        ))
                    }
                };
                Ok((prop, axis * f.model.channels + ch))
            }
            Resolver::PerAxis(fits) => {
                let hit = fits
                    .iter()
                    .find(|(phi, _, _)| same_plane(*phi, plane))
                    .or(if at_normal { fits.first() } else { None })
                    .ok_or_else(|| {
                        format!(
                            "φo = {plane}° (mod 180°) is not one of the planes of the per-plane fits ({}°)",
                            list(&fits.iter().map(|f| f.0).collect::<Vec<_>>())
                        )
                    })?;
                Ok((&hit.2, channel(hit.1)?))
            }
        }
    }
}

fn list(v: &[f64]) -> String {
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Evaluate the fit(s) of `file` at every sample of `at`: the value column becomes the
/// model value and the uncertainty column its propagated standard uncertainty (k = 1).
/// `fit_path` and `what` (where the geometries came from) go into the header.
pub fn predict(file: &FitFile, fit_path: &str, at: &Dataset, what: &str) -> Result<Predicted> {
    let resolver = Resolver::new(file);
    let first = resolver.first();
    anyhow::ensure!(
        at.kind == first.model.kind,
        "{} is a {} model but {what} holds {} geometries",
        first.model.spec,
        first.model.kind,
        at.kind
    );
    let mut out = at.clone();
    let counts = evaluate_samples(&resolver, &mut out, what)?;
    let fits: Vec<&SavedFit> = match file {
        FitFile::Single(f) => vec![f.as_ref()],
        FitFile::PerAxis(v) => v.iter().map(|(_, f)| f).collect(),
    };
    let warnings = prediction_warnings(&fits, counts, out.len());
    let material = if first.material.is_empty() {
        format!("{} fit", first.model.spec)
    } else {
        format!("{} ({} fit)", first.material, first.model.spec)
    };
    out.meta = prediction_header(file, first, fit_path, at, what, &warnings, &material);
    out.material = material;
    out.notices.clear();
    out.assumed_uncertainty = None;
    Ok(Predicted {
        data: out,
        warnings,
    })
}

/// Rows of a prediction that need a word ([`prediction_warnings`]).
#[derive(Clone, Copy, Debug, Default)]
struct RowCounts {
    /// Rows whose uncertainty the reader would refuse as zero.
    zero_u: usize,
    /// Rows whose value depends on a parameter the fit did not determine.
    undetermined: usize,
}

/// Replace every sample's value and uncertainty in `out` by the model's and its
/// propagated uncertainty; an error names the first sample (its line, or its geometry
/// in `what`) that cannot be evaluated or whose prediction is not finite.
fn evaluate_samples(resolver: &Resolver, out: &mut Dataset, what: &str) -> Result<RowCounts> {
    // One clear message per problem, before any work: the first sample that cannot be
    // evaluated names its line.
    let resolved: Vec<(usize, Result<Propagated, String>)> = out
        .samples
        .par_iter()
        .enumerate()
        .map(|(k, s)| {
            (
                k,
                resolver
                    .resolve(s)
                    .map(|(prop, g)| prop.eval(g, s.wi(), s.wo())),
            )
        })
        .collect();
    let mut counts = RowCounts::default();
    for (k, r) in resolved {
        let s = &mut out.samples[k];
        let where_ = || {
            if s.line > 0 {
                format!("{what}:{}", s.line)
            } else {
                format!(
                    "{what} (θi = {:.3}°, φi = {:.3}°, θo = {:.3}°, φo = {:.3}°, {} nm)",
                    s.theta_i.to_degrees(),
                    s.phi_i.to_degrees(),
                    s.theta_o.to_degrees(),
                    s.phi_o.to_degrees(),
                    s.wavelength_nm
                )
            }
        };
        let p = r.map_err(|m| anyhow::anyhow!("{}: {m}", where_()))?;
        anyhow::ensure!(
            p.value.is_finite() && p.uncertainty.is_finite(),
            "{}: the model gives {} ± {} there",
            where_(),
            p.value,
            p.uncertainty
        );
        if !reader_accepts(p.value, p.uncertainty) {
            counts.zero_u += 1;
        }
        if p.depends_on_undetermined {
            counts.undetermined += 1;
        }
        s.value = p.value;
        s.uncertainty = p.uncertainty;
    }
    Ok(counts)
}

/// What the user must know about a prediction of `rows` rows from `fits`: parameters
/// without an uncertainty, zero uncertainties, and the fits' own warnings (each once).
fn prediction_warnings(fits: &[&SavedFit], counts: RowCounts, rows: usize) -> Vec<String> {
    let mut warnings = Vec::new();
    let mut undetermined: Vec<String> = Vec::new();
    for n in fits.iter().flat_map(|f| f.undetermined()) {
        if !undetermined.contains(&n) {
            undetermined.push(n);
        }
    }
    if counts.undetermined > 0 {
        warnings.push(format!(
            "{} {} no standard uncertainty in the fit (the data did not determine {}): {} taken as 0, so at {} of {} the model depends on {} and the uncertainty is a lower bound",
            undetermined.join(", "),
            if undetermined.len() == 1 { "has" } else { "have" },
            if undetermined.len() == 1 { "it" } else { "them" },
            if undetermined.len() == 1 { "its variance is" } else { "their variances are" },
            count(counts.undetermined, "row", "rows"),
            rows,
            if undetermined.len() == 1 { "it" } else { "them" },
        ));
    }
    if counts.zero_u > 0 {
        warnings.push(format!(
            "{} a zero model uncertainty (the model does not depend on the fitted parameters there, e.g. where it is 0): reading the file back as data needs --allow-zero-uncertainty",
            count(counts.zero_u, "row has", "rows have")
        ));
    }
    for f in fits {
        for w in &f.warnings {
            let w = format!("the fit says: {w}");
            if !warnings.contains(&w) {
                warnings.push(w);
            }
        }
    }
    warnings
}

/// The header of a prediction: what it is, from which fit and parameters, how its
/// uncertainty was made, its warnings and `material`.
fn prediction_header(
    file: &FitFile,
    first: &SavedFit,
    fit_path: &str,
    at: &Dataset,
    what: &str,
    warnings: &[String],
    material: &str,
) -> BTreeMap<String, String> {
    let mut meta = BTreeMap::new();
    meta.insert("kind".to_string(), at.kind.to_string());
    meta.insert(
        "source".into(),
        format!("model values of the fit {fit_path} evaluated by bsdfit at {what}"),
    );
    meta.insert("fit_model".into(), first.model.spec.clone());
    match file {
        FitFile::Single(f) => {
            meta.insert("fit_params".into(), f.params_text());
        }
        FitFile::PerAxis(v) => {
            for (phi, f) in v {
                meta.insert(format!("fit_params_phi{phi}"), f.params_text());
            }
        }
    }
    if !first.data.is_empty() {
        meta.insert("fit_data".into(), first.data.clone());
    }
    meta.insert(
        "uncertainty".into(),
        "the model's standard uncertainty (k = 1) propagated from the fit's covariance, u² = gᵀ cov g with g = ∂f/∂θ (central differences); not a measurement uncertainty".into(),
    );
    for (k, w) in warnings.iter().enumerate() {
        meta.insert(format!("warning_{}", k + 1), w.clone());
    }
    meta.insert("material".into(), material.to_string());
    meta
}

/// A dataset of the rows (signed θi, φi, θo, φo in degrees) at every one of `channels`,
/// with placeholder values, for [`predict`].
pub fn geometry_dataset(
    kind: Kind,
    rows: &[[f64; 4]],
    channels: &[f64],
    label: &str,
) -> Result<Dataset> {
    let mut raw = Vec::with_capacity(rows.len() * channels.len());
    for r in rows {
        for &wl in channels {
            raw.push((0, RawRow::placeholder(*r, wl)));
        }
    }
    let ds = Dataset::from_rows(kind, label, &raw, label, &ReadOptions::default())?;
    Ok(ds)
}

/// The channels of a fit file (those of its first fit; per-plane fits share them).
pub fn fit_channels(file: &FitFile) -> Vec<f64> {
    match file {
        FitFile::Single(f) => f.channels.clone(),
        FitFile::PerAxis(v) => v[0].1.channels.clone(),
    }
}

/// The grid of `bsdfit export --format tabulated` (docs/export.md).
#[derive(Clone, Copy, Debug)]
pub struct Grid {
    /// Step of θi and θo (θt), degrees.
    pub theta_step: f64,
    /// Largest θi and θo (θt), degrees (< 90).
    pub theta_max: f64,
    /// Step of φo (φt) over [0°, 360°), degrees.
    pub phi_step: f64,
}

impl Default for Grid {
    fn default() -> Self {
        Grid {
            theta_step: 5.0,
            theta_max: 85.0,
            phi_step: 15.0,
        }
    }
}

/// Largest number of rows (geometries × channels) a tabulated export writes.
pub const MAX_GRID_ROWS: usize = 20_000_000;

impl Grid {
    /// The rows of the grid: θi = 0, step, … ≤ θmax at φi = 0; θo likewise; φo = 0, step, …
    /// < 360° (one row at θo = 0). On the planes `planes` only (φ and φ + 180°, with the
    /// normal row once per plane at its azimuth) when the fit has per-plane parameters.
    pub fn rows(&self, planes: Option<&[f64]>, channels: usize) -> Result<Vec<[f64; 4]>> {
        let Grid {
            theta_step,
            theta_max,
            phi_step,
        } = *self;
        anyhow::ensure!(
            theta_step.is_finite() && theta_step > 0.0 && theta_step <= 90.0,
            "--theta-step {theta_step}: expected a step in (0, 90] degrees"
        );
        anyhow::ensure!(
            theta_max.is_finite() && (0.0..90.0).contains(&theta_max),
            "--theta-max {theta_max}: expected an angle in [0, 90) degrees (at 90° a direction lies in the surface)"
        );
        anyhow::ensure!(
            phi_step.is_finite() && phi_step > 0.0 && phi_step <= 360.0,
            "--phi-step {phi_step}: expected a step in (0, 360] degrees"
        );
        let thetas: Vec<f64> = (0..)
            .map(|k| k as f64 * theta_step)
            .take_while(|t| *t <= theta_max + 1e-9)
            .collect();
        let phis: Vec<f64> = match planes {
            Some(p) => p.iter().flat_map(|&a| [a, a + 180.0]).collect(),
            None => (0..)
                .map(|k| k as f64 * phi_step)
                .take_while(|p| *p < 360.0 - 1e-9)
                .collect(),
        };
        let per_theta_i = 1 + (thetas.len() - 1) * phis.len();
        let total = thetas.len() as u128 * per_theta_i as u128 * channels as u128;
        anyhow::ensure!(
            total <= MAX_GRID_ROWS as u128,
            "the grid has {total} rows (θ: {} values, φ: {}, {channels} channel(s)), more than {MAX_GRID_ROWS}: use a larger --theta-step or --phi-step",
            thetas.len(),
            phis.len()
        );
        let mut rows = Vec::with_capacity(thetas.len() * per_theta_i);
        for &ti in &thetas {
            match planes {
                // A per-plane model: the normal row once per plane, at that plane's azimuth.
                Some(p) => rows.extend(p.iter().map(|&a| [ti, 0.0, 0.0, a])),
                None => rows.push([ti, 0.0, 0.0, 0.0]),
            }
            for &to in &thetas[1..] {
                rows.extend(phis.iter().map(|&po| [ti, 0.0, to, po]));
            }
        }
        Ok(rows)
    }
}

/// The planes a fit file has parameters of its own for, if any.
pub fn fit_planes(file: &FitFile) -> Option<Vec<f64>> {
    match file {
        FitFile::Single(f) if f.model.axes.len() > 1 => Some(f.model.axes.clone()),
        FitFile::Single(_) => None,
        FitFile::PerAxis(v) => Some(v.iter().map(|(p, _)| *p).collect()),
    }
}

/// The fit's channels that become R, G, B: one channel for all three; three channels by
/// wavelength, longest → R; or the channels nearest the wavelengths `rgb` gives (R, G, B).
pub fn rgb_channels(fit: &SavedFit, rgb: Option<&[f64]>) -> Result<[usize; 3]> {
    let ch = &fit.channels;
    if let Some(want) = rgb {
        anyhow::ensure!(
            want.len() == 3,
            "--rgb takes three wavelengths R,G,B in nm, got {}",
            want.len()
        );
        let mut out = [0usize; 3];
        for (k, &w) in want.iter().enumerate() {
            let (i, d) = ch
                .iter()
                .enumerate()
                .map(|(i, c)| (i, (c - w).abs()))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .expect("a fit has channels");
            anyhow::ensure!(
                d <= crate::data::MAX_WAVELENGTH_GAP_NM,
                "--rgb: no channel of the fit within {} nm of {w} nm (channels: {} nm)",
                crate::data::MAX_WAVELENGTH_GAP_NM,
                list(ch)
            );
            out[k] = i;
        }
        return Ok(out);
    }
    match ch.len() {
        1 => Ok([0, 0, 0]),
        3 => {
            let mut order = [0usize, 1, 2];
            order.sort_by(|&a, &b| ch[b].total_cmp(&ch[a]));
            Ok(order)
        }
        n => anyhow::bail!(
            "the fit has {n} channels ({} nm): RGB formats take 1 or 3; pick three with --rgb R_NM,G_NM,B_NM",
            list(ch)
        ),
    }
}

/// A MERL table of the fitted BRDF at every cell centre (R, G, B from [`rgb_channels`]).
pub fn merl_table(fit: &SavedFit, rgb: [usize; 3]) -> Result<Vec<u8>> {
    let m = &fit.model;
    anyhow::ensure!(
        m.kind == Kind::Brdf,
        "{} is a BTDF model: a MERL table holds a BRDF (use --format tabulated)",
        m.spec
    );
    let views: Vec<Vec<f64>> = rgb.iter().map(|&g| m.scalars(&fit.flat, g)).collect();
    let bytes = merl::encode_par(|th, td, pd| {
        let (wi, wo) =
            merl::cell_directions(th, td, pd).expect("encode visits cells above the horizon");
        [0, 1, 2].map(|c| m.root.eval(&views[c], wi, wo))
    });
    Ok(bytes)
}

/// The models with an exact Mitsuba 3 counterpart (their declarations say so), and what
/// they become.
pub fn mitsuba_exact() -> Vec<(&'static str, &'static str)> {
    crate::bsdf::registry::all()
        .into_iter()
        .filter_map(|e| e.mitsuba.map(|m| (e.name, m.summary)))
        .collect()
}

/// A Mitsuba 3 `<bsdf>` that evaluates exactly as the fitted model (docs/export.md): the
/// counterpart its declaration names, with the fitted values.
pub fn mitsuba_xml(fit: &SavedFit, rgb: [usize; 3], fit_path: &str) -> Result<String> {
    let m = &fit.model;
    let leaf = m.root.children.is_empty();
    let exact = mitsuba_exact()
        .iter()
        .map(|(n, to)| format!("{n} (→ {to})"))
        .collect::<Vec<_>>()
        .join(", ");
    let refuse = |why: &str| {
        anyhow::anyhow!(
            "{} has no exact Mitsuba 3 counterpart ({why}); exported exactly: {exact}. Use --format {} instead",
            m.spec,
            if m.kind == Kind::Brdf { "merl (a tabulated BRDF) or --format tabulated" } else { "tabulated" }
        )
    };
    if m.kind == Kind::Btdf {
        return Err(refuse(
            "a bsdfit BTDF is the transmission of a slab measured in air; Mitsuba's roughdielectric is one interface into a medium, with a reflection lobe and the η² radiance scaling",
        ));
    }
    let Some(target) = m.root.bsdf.entry().mitsuba.filter(|_| leaf) else {
        return Err(refuse("no Mitsuba 3 BSDF has its formula"));
    };
    let value = |pname: &str, g: usize| -> f64 {
        let j = m
            .params
            .iter()
            .position(|p| p.name == pname)
            .expect("the model declares it");
        fit.flat[m.slot(j, g)]
    };
    let rgb_of = |pname: &str| {
        rgb.iter()
            .map(|&g| value(pname, g).to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let channels = rgb
        .iter()
        .zip(["R", "G", "B"])
        .map(|(&g, c)| format!("{c} = {} nm", fit.channels[g]))
        .collect::<Vec<_>>()
        .join(", ");
    let mut x = String::from("<?xml version=\"1.0\" encoding=\"utf-8\"?>\n");
    // An XML comment may not contain two hyphens in a row: no option names here.
    let material = if fit.material.is_empty() {
        String::new()
    } else {
        format!(" to '{}'", fit.material.replace("--", "- -"))
    };
    x += &format!(
        "<!-- bsdfit: model {}{material}, from {} ({channels}).\n",
        m.spec,
        fit_path.replace("--", "- -")
    );
    let (last, first) = target.why.split_last().unwrap_or((&"", &[]));
    for line in first {
        x += &format!("     {line}\n");
    }
    x += &format!("     {last} -->\n");
    x += &format!("<bsdf type=\"{}\" version=\"3.0.0\">\n", target.plugin);
    for field in target.fields {
        x += &match *field {
            MitsubaField::Text { name, value } => {
                format!("    <string name=\"{name}\" value=\"{value}\"/>\n")
            }
            MitsubaField::Param { name, param } => {
                format!(
                    "    <float name=\"{name}\" value=\"{}\"/>\n",
                    value(param, 0)
                )
            }
            MitsubaField::Constant { name, value } => {
                format!("    <float name=\"{name}\" value=\"{value}\"/>\n")
            }
            MitsubaField::Rgb { name, param } => {
                format!("    <rgb name=\"{name}\" value=\"{}\"/>\n", rgb_of(param))
            }
        };
    }
    x += "</bsdf>\n";
    Ok(x)
}
