//! The sweep's pictures and `report.html`: everything is computed from the results rows
//! (results.csv), the data files they name and the render statistics written beside the
//! images — no number in the report is typed in.
//!
//! Layout of the output directory:
//! - `plots/<data>/<fit>.svg`: angular plot of every fit (model curves, measured ±u);
//! - `plots/<data>/weights.svg`: the best model fitted with uniform vs uncertainty weights
//!   (paper Fig. 3, top); `plots/<data>/models.svg`: the top models (BRDF, Fig. 2) or the
//!   best variant of each NDF family (BTDF, Fig. 4); `plots/<data>/suffixes.svg` (BTDF):
//!   plain vs `+scale` vs `+absorb` for the best family (Fig. 5);
//! - `renders/<data>/baseline.png` and `renders/<data>/<fit>-{model,error}.png` + `.json`
//!   (BRDF; Figs. 1–3, bottom): the baseline is the tabulated data set of the same material
//!   with the most samples, so a fit to in-plane data is judged against the full data;
//! - `report.html`, tying it together (offline: relative links only).

mod featured;
mod html;
mod inputs;

use crate::data::Kind;
use crate::output::files::write_atomic;
use crate::output::plot::{self, Fitted, Panel};
use crate::output::render::{self, RenderOptions, RenderStats};
use crate::output::results::{self, current_rows, fmt_num, rankings, Row, Skipped};
use anyhow::Result;
use featured::{featured, Featured};
use inputs::{compile, load_data, Compiled};
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Bumped when the pictures or report change for the same results.
const REPORT_VERSION: &str = "report-v5";

/// File-name-safe slug of a fit.
pub fn slug(r: &Row) -> String {
    let m: String = r
        .model
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '.' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!(
        "{m}__{}-{}-{}-r{}-s{}",
        r.loss, r.weights, r.optimizer, r.restarts, r.seed
    )
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn safe_name(s: &str) -> String {
    s.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '.' || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
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

/// Render and plot paths relative to the output directory.
fn plot_rel(r: &Row) -> String {
    format!("plots/{}/{}.svg", safe_name(&r.data), slug(r))
}
fn render_rel(r: &Row, what: &str) -> String {
    format!("renders/{}/{}-{what}", safe_name(&r.data), slug(r))
}

/// Fingerprint of what the pictures depend on.
fn stamp(out: &Path) -> String {
    let csv = std::fs::read(out.join(results::RESULTS_CSV)).unwrap_or_default();
    let sk = std::fs::read(out.join(results::SKIPPED_JSON)).unwrap_or_default();
    format!(
        "{REPORT_VERSION} {} {} {}",
        env!("CARGO_PKG_VERSION"),
        results::content_hash(&csv),
        results::content_hash(&sk)
    )
}

/// What the run that calls [`publish`] did, for the report's header.
#[derive(Clone, Copy, Debug)]
pub struct RunInfo {
    /// Fits this run added to results.csv.
    pub new_fits: usize,
    /// Wall-clock seconds this run spent fitting.
    pub wall_seconds: f64,
    /// Fits that ran at the same time.
    pub workers: usize,
}

/// Write pictures and report.html for `rows` into `out`; `run` is what the calling sweep
/// did (None for `merge`: the shards' wall times are not known).
pub fn publish(
    out: &Path,
    rows: &[Row],
    run: Option<&RunInfo>,
    notice: &mut dyn FnMut(String),
) -> Result<()> {
    let t0 = std::time::Instant::now();
    let stamp_path = out.join("report.stamp");
    let st = stamp(out);
    if out.join("report.html").exists()
        && std::fs::read_to_string(&stamp_path).ok().as_deref() == Some(st.as_str())
    {
        notice(format!(
            "pictures and {} are up to date",
            out.join("report.html").display()
        ));
        return Ok(());
    }
    let cur = current_rows(rows);
    let datas = load_data(&cur);
    let ranks = rankings(rows);
    let ropts = RenderOptions::default();
    let mut problems: Vec<String> = datas.values().filter_map(|d| d.note.clone()).collect();
    // Baseline of each BRDF material: its data set with the most samples.
    let mut baseline_of: BTreeMap<String, String> = BTreeMap::new();
    for d in datas.values() {
        if let Some(ds) = &d.data {
            if ds.kind == Kind::Brdf {
                let e = baseline_of
                    .entry(ds.material.clone())
                    .or_insert(d.name.clone());
                let cur_n = datas[e.as_str()]
                    .data
                    .as_ref()
                    .map(|x| x.len())
                    .unwrap_or(0);
                if ds.len() > cur_n {
                    *e = d.name.clone();
                }
            }
        }
    }
    // Per-fit plots.
    let mut n_plots = 0;
    for r in &cur {
        let Some(ds) = datas.get(&r.data).and_then(|d| d.data.as_ref()) else {
            continue;
        };
        match compile(r, ds) {
            Ok(c) => {
                let fit = Fitted {
                    label: r.model.clone(),
                    model: &c.model,
                    flat: &c.flat,
                };
                let panel = plot::fit_panel(ds, &fit, &fit_title(r));
                plot::write_svg(&out.join(plot_rel(r)), &[panel], (640, 440))?;
                n_plots += 1;
            }
            Err(e) => problems.push(format!("{} · {}: cannot plot ({e:#})", r.data, r.model)),
        }
    }
    // Featured plots and renders.
    let mut feats: BTreeMap<String, Featured> = BTreeMap::new();
    let mut renders: BTreeMap<String, RenderStats> = BTreeMap::new(); // slug path → stats
    let mut to_render: BTreeSet<(String, String)> = BTreeSet::new(); // (data, slug)
    let mut render_rows: Vec<&Row> = Vec::new();
    for rk in &ranks {
        let Some(ds) = datas.get(&rk.data).and_then(|d| d.data.as_ref()) else {
            continue;
        };
        let f = featured(rk, ds.kind);
        let dir = out.join("plots").join(safe_name(&rk.data));
        if let Some((u, w)) = f.weights {
            let (cu, cw) = (compile(u, ds)?, compile(w, ds)?);
            let mut panels = vec![
                plot::fit_panel(
                    ds,
                    &Fitted {
                        label: u.model.clone(),
                        model: &cu.model,
                        flat: &cu.flat,
                    },
                    &format!("{} — {} uniform", u.model, u.loss),
                ),
                plot::fit_panel(
                    ds,
                    &Fitted {
                        label: w.model.clone(),
                        model: &cw.model,
                        flat: &cw.flat,
                    },
                    &format!("{} — {} {}", w.model, w.loss, w.weights),
                ),
            ];
            plot::common_y(&mut panels);
            plot::write_svg(&dir.join("weights.svg"), &panels, (600, 430))?;
            if ds.kind == Kind::Brdf {
                render_rows.extend([u, w]);
            }
        }
        if !f.models.is_empty() {
            let cs: Vec<Compiled> = f
                .models
                .iter()
                .map(|r| compile(r, ds))
                .collect::<Result<_>>()?;
            match ds.kind {
                Kind::Brdf => {
                    let mut panels: Vec<Panel> = f
                        .models
                        .iter()
                        .zip(&cs)
                        .map(|(r, c)| {
                            plot::fit_panel(
                                ds,
                                &Fitted {
                                    label: r.model.clone(),
                                    model: &c.model,
                                    flat: &c.flat,
                                },
                                &format!("{} — {}/{}", r.model, r.loss, r.weights),
                            )
                        })
                        .collect();
                    plot::common_y(&mut panels);
                    plot::write_svg(&dir.join("models.svg"), &panels, (600, 430))?;
                    render_rows.extend(f.models.iter().copied());
                }
                Kind::Btdf => {
                    let fits: Vec<Fitted> = f
                        .models
                        .iter()
                        .zip(&cs)
                        .map(|(r, c)| Fitted {
                            label: r.model.clone(),
                            model: &c.model,
                            flat: &c.flat,
                        })
                        .collect();
                    let t = format!(
                        "{} — best of each NDF, {}/{}",
                        rk.data, f.models[0].loss, f.models[0].weights
                    );
                    plot::write_svg(
                        &dir.join("models.svg"),
                        &[plot::btdf_panel(ds, &fits, &t)],
                        (760, 480),
                    )?;
                }
            }
        }
        if !f.suffixes.is_empty() {
            let cs: Vec<Compiled> = f
                .suffixes
                .iter()
                .map(|r| compile(r, ds))
                .collect::<Result<_>>()?;
            let fits: Vec<Fitted> = f
                .suffixes
                .iter()
                .zip(&cs)
                .map(|(r, c)| Fitted {
                    label: r.model.clone(),
                    model: &c.model,
                    flat: &c.flat,
                })
                .collect();
            let t = format!(
                "{} — scale vs absorption, {}/{}",
                rk.data, f.suffixes[0].loss, f.suffixes[0].weights
            );
            plot::write_svg(
                &dir.join("suffixes.svg"),
                &[plot::btdf_panel(ds, &fits, &t)],
                (760, 480),
            )?;
        }
        feats.insert(rk.data.clone(), f);
    }
    // Sampling geometry (Fig. 1): the top models of a material's richest data set, fitted
    // to each of its data sets, all rendered against the same baseline.
    let mut sampling: Vec<(String, Vec<&Row>)> = Vec::new();
    for (material, base) in &baseline_of {
        let members: Vec<&String> = datas
            .values()
            .filter(|d| d.data.as_ref().is_some_and(|x| &x.material == material))
            .map(|d| &d.name)
            .collect();
        if members.len() < 2 {
            continue;
        }
        let Some(f) = feats.get(base) else { continue };
        let mut list = Vec::new();
        for top in f.models.iter() {
            for m in &members {
                if let Some(r) = cur.iter().find(|r| {
                    &&r.data == m
                        && r.model == top.model
                        && r.loss == top.loss
                        && r.weights == top.weights
                        && r.optimizer == top.optimizer
                }) {
                    list.push(*r);
                }
            }
        }
        render_rows.extend(list.iter().copied());
        sampling.push((material.clone(), list));
    }
    // Renders.
    for r in render_rows {
        if !to_render.insert((r.data.clone(), slug(r))) {
            continue;
        }
        let Some(ds) = datas.get(&r.data).and_then(|d| d.data.as_ref()) else {
            continue;
        };
        let base_name = baseline_of
            .get(&ds.material)
            .cloned()
            .unwrap_or(r.data.clone());
        let Some(base) = datas.get(&base_name).and_then(|d| d.data.as_ref()) else {
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
    let skipped: Vec<Skipped> = std::fs::read_to_string(out.join(results::SKIPPED_JSON))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default();
    let html = html::Page {
        all: rows,
        run,
        cur: &cur,
        ranks: &ranks,
        datas: &datas,
        feats: &feats,
        renders: &renders,
        baseline_of: &baseline_of,
        sampling: &sampling,
        skipped: &skipped,
        problems: &problems,
    }
    .html();
    write_atomic(&out.join("report.html"), html.as_bytes())?;
    write_atomic(&stamp_path, st.as_bytes())?;
    notice(format!(
        "wrote {} ({} fit plots, {} renders) in {:.1} s",
        out.join("report.html").display(),
        n_plots,
        renders.len(),
        t0.elapsed().as_secs_f64()
    ));
    for p in &problems {
        notice(format!("note: {p}"));
    }
    Ok(())
}
