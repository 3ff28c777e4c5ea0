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
mod pictures;

use crate::output::files::write_atomic;
use crate::output::results::{self, current_rows, rankings, Row, Skipped};
use anyhow::Result;
use featured::{featured, sampling_sets, Featured};
pub use html::page_head;
use inputs::{baselines, dataset, load_data};
use std::collections::BTreeMap;
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

/// Text escaped for HTML (element content and quoted attributes).
pub fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// A file-name-safe word: every character but ASCII letters, digits, `.`, `-`, `_` as `_`.
pub fn safe_name(s: &str) -> String {
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

/// The skipped and failed fits of skipped.json (none when it is missing or unreadable).
fn read_skipped(out: &Path) -> Vec<Skipped> {
    std::fs::read_to_string(out.join(results::SKIPPED_JSON))
        .ok()
        .and_then(|t| serde_json::from_str(&t).ok())
        .unwrap_or_default()
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
    let mut problems: Vec<String> = datas.values().filter_map(|d| d.note.clone()).collect();
    let baseline_of = baselines(&datas);
    let n_plots = pictures::fit_plots(out, &cur, &datas, &mut problems)?;
    // Featured plots, and the fits to render.
    let mut feats: BTreeMap<String, Featured> = BTreeMap::new();
    let mut render_rows: Vec<&Row> = Vec::new();
    for rk in &ranks {
        let Some(ds) = dataset(&datas, &rk.data) else {
            continue;
        };
        let f = featured(rk, ds.kind);
        pictures::featured_plots(out, &rk.data, ds, &f)?;
        render_rows.extend(f.to_render(ds.kind));
        feats.insert(rk.data.clone(), f);
    }
    let sampling = sampling_sets(&baseline_of, &datas, &feats, &cur);
    for (_, list) in &sampling {
        render_rows.extend(list.iter().copied());
    }
    let renders = pictures::renders(out, &render_rows, &datas, &baseline_of, &mut problems)?;
    let skipped = read_skipped(out);
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
