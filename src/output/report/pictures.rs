//! The pictures: an angular plot of every fit, the featured comparison plots of each data
//! set, and the renders of fits against their material's baseline (the layout is in
//! [`super`]).

use super::featured::Featured;
use super::inputs::{compile, dataset, Compiled, DataInfo};
use super::{plot_rel, render_rel, safe_name, slug};
use crate::data::{Dataset, Kind};
use crate::inference::saved::{Propagator, SavedFit};
use crate::output::files::write_atomic;
use crate::output::plot::{self, Fitted, Panel};
use crate::output::render::{self, RenderOptions, RenderStats};
use crate::output::results::{fmt_num, Row};
use anyhow::Result;
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// A rebuilt fit as the plots take it, labelled with its model.
fn fitted<'c>(r: &Row, c: &'c Compiled) -> Fitted<'c> {
    Fitted {
        label: r.model.clone(),
        model: &c.model,
        flat: &c.flat,
        propagator: None,
    }
}

/// An anisotropic BTDF fit on data from several planes with its covariance (recomputed
/// on the CPU reference from the data, the row's loss and its fitted parameters), so that
/// the plot can draw the uncertainty of its prediction between the planes. None for other
/// fits, and for fits made under constraints (their free parameters are not in the row).
fn with_covariance(r: &Row, c: &Compiled, ds: &Dataset) -> Option<SavedFit> {
    let anisotropic = c.model.params.iter().any(|p| p.decl.needs_planes);
    if !anisotropic || ds.kind != Kind::Btdf || ds.axes.len() < 2 || !r.constraints.is_empty() {
        return None;
    }
    let cov =
        crate::inference::covariance::at_fitted_point(&c.model, ds, &r.loss, &r.weights, &c.flat)
            .ok()?;
    Some(SavedFit {
        model: c.model.clone(),
        flat: c.flat.clone(),
        std: cov.std,
        correlation: cov.correlation,
        channels: ds.channels.clone(),
        material: ds.material.clone(),
        data: r.data.clone(),
        warnings: cov.warnings,
    })
}

/// Rebuild the fits of `rows`, all or none.
fn compile_all(rows: &[&Row], ds: &Dataset) -> Result<Vec<Compiled>> {
    rows.iter().map(|r| compile(r, ds)).collect()
}

fn fit_title(r: &Row) -> String {
    format!(
        "{} — {}/{} ({}), χ²_red = {}",
        r.model,
        r.loss,
        r.weights,
        r.optimizer,
        fmt_num(r.chi2_red)
    )
}

/// Write the angular plot of every fit in `cur` whose data set could be read; a fit whose
/// model cannot be rebuilt goes to `problems`. Returns how many plots were written.
pub(super) fn fit_plots(
    out: &Path,
    cur: &[&Row],
    datas: &BTreeMap<String, DataInfo>,
    problems: &mut Vec<String>,
) -> Result<usize> {
    let mut n_plots = 0;
    for r in cur {
        let Some(ds) = dataset(datas, &r.data) else {
            continue;
        };
        match compile(r, ds) {
            Ok(c) => {
                let saved = with_covariance(r, &c, ds);
                let propagator = saved.as_ref().map(Propagator::new);
                let mut f = fitted(r, &c);
                f.propagator = propagator.as_ref();
                let panel = plot::fit_panel(ds, &f, &fit_title(r));
                plot::write_svg(&out.join(plot_rel(r)), &[panel], (640, 440))?;
                n_plots += 1;
            }
            Err(e) => problems.push(format!("{} · {}: cannot plot ({e:#})", r.data, r.model)),
        }
    }
    Ok(n_plots)
}

/// Write the featured plots of the data set `data` into `plots/<data>/`: `weights.svg`,
/// `models.svg` and (BTDF) `suffixes.svg`, each when there is something to compare.
pub(super) fn featured_plots(out: &Path, data: &str, ds: &Dataset, f: &Featured) -> Result<()> {
    let dir = out.join("plots").join(safe_name(data));
    if let Some((u, w)) = f.weights {
        weights_plot(&dir, ds, u, w)?;
    }
    if !f.models.is_empty() {
        models_plot(&dir, data, ds, &f.models)?;
    }
    if !f.suffixes.is_empty() {
        suffixes_plot(&dir, data, ds, &f.suffixes)?;
    }
    Ok(())
}

/// One model fitted with uniform weights (left) and uncertainty weights (right), on a
/// common y axis (paper Fig. 3, top).
fn weights_plot(dir: &Path, ds: &Dataset, u: &Row, w: &Row) -> Result<()> {
    let (cu, cw) = (compile(u, ds)?, compile(w, ds)?);
    let mut panels = vec![
        plot::fit_panel(
            ds,
            &fitted(u, &cu),
            &format!("{} — {} uniform", u.model, u.loss),
        ),
        plot::fit_panel(
            ds,
            &fitted(w, &cw),
            &format!("{} — {} {}", w.model, w.loss, w.weights),
        ),
    ];
    plot::common_y(&mut panels);
    plot::write_svg(&dir.join("weights.svg"), &panels, (600, 430))
}

/// The featured models: side by side on a common y axis (BRDF, Fig. 2), or overlaid in
/// one panel (BTDF: the best variant of each NDF family, Fig. 4).
fn models_plot(dir: &Path, data: &str, ds: &Dataset, models: &[&Row]) -> Result<()> {
    let cs = compile_all(models, ds)?;
    match ds.kind {
        Kind::Brdf => {
            let mut panels: Vec<Panel> = models
                .iter()
                .zip(&cs)
                .map(|(r, c)| {
                    plot::fit_panel(
                        ds,
                        &fitted(r, c),
                        &format!("{} — {}/{}", r.model, r.loss, r.weights),
                    )
                })
                .collect();
            plot::common_y(&mut panels);
            plot::write_svg(&dir.join("models.svg"), &panels, (600, 430))
        }
        Kind::Btdf => {
            let t = format!(
                "{} — best of each NDF, {}/{}",
                data, models[0].loss, models[0].weights
            );
            overlay_plot(&dir.join("models.svg"), ds, models, &cs, &t)
        }
    }
}

/// The best BTDF family plain, with `+scale` and with `+absorb`, overlaid (Fig. 5).
fn suffixes_plot(dir: &Path, data: &str, ds: &Dataset, suffixes: &[&Row]) -> Result<()> {
    let cs = compile_all(suffixes, ds)?;
    let t = format!(
        "{} — scale vs absorption, {}/{}",
        data, suffixes[0].loss, suffixes[0].weights
    );
    overlay_plot(&dir.join("suffixes.svg"), ds, suffixes, &cs, &t)
}

/// Several fits of a BTDF data set overlaid in one panel.
fn overlay_plot(
    path: &Path,
    ds: &Dataset,
    rows: &[&Row],
    cs: &[Compiled],
    title: &str,
) -> Result<()> {
    let fits: Vec<Fitted> = rows.iter().zip(cs).map(|(r, c)| fitted(r, c)).collect();
    plot::write_svg(path, &[plot::btdf_panel(ds, &fits, title)], (760, 480))
}

/// Render each fit of `rows` once (a fit listed again is skipped) against the baseline of
/// its material, into `renders/<data>/`, with its statistics in a `stats.json` beside the
/// images; a fit that cannot be rendered goes to `problems`. Returns the statistics by
/// render path ([`render_rel`]).
pub(super) fn renders(
    out: &Path,
    rows: &[&Row],
    datas: &BTreeMap<String, DataInfo>,
    baseline_of: &BTreeMap<String, String>,
    problems: &mut Vec<String>,
) -> Result<BTreeMap<String, RenderStats>> {
    let ropts = RenderOptions::default();
    let mut renders: BTreeMap<String, RenderStats> = BTreeMap::new();
    let mut done: BTreeSet<(String, String)> = BTreeSet::new(); // (data, slug)
    for r in rows {
        if !done.insert((r.data.clone(), slug(r))) {
            continue;
        }
        let Some(ds) = dataset(datas, &r.data) else {
            continue;
        };
        let base_name = baseline_of
            .get(&ds.material)
            .cloned()
            .unwrap_or(r.data.clone());
        let Some(base) = dataset(datas, &base_name) else {
            continue;
        };
        let c = compile(r, ds)?;
        let base_png = out.join(format!("renders/{}/baseline.png", safe_name(&r.data)));
        let rel = render_rel(r, "");
        let stats = render::render_fit(
            &c.model,
            &c.flat,
            base,
            &ropts,
            Some(&base_png),
            &out.join(format!("{rel}model.png")),
            &out.join(format!("{rel}error.png")),
            &r.data,
        );
        match stats {
            Ok(mut s) => {
                s.baseline = base_name.clone();
                write_atomic(
                    &out.join(format!("{rel}stats.json")),
                    (serde_json::to_string_pretty(&s)? + "\n").as_bytes(),
                )?;
                renders.insert(rel, s);
            }
            Err(e) => problems.push(format!("{} · {}: cannot render ({e:#})", r.data, r.model)),
        }
    }
    Ok(renders)
}
