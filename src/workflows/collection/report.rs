//! The collection's `report.html` (offline: relative links only): the table of data sets
//! sorted by final χ²_red, how often each effect was named, each data set's residual map
//! before and after its diagnosis, and the cells that failed with their errors.

use super::record::{sorted, CellRecord, CellStatus};
use super::REPORTS_DIR;
use crate::output::files::write_if_changed;
use crate::output::report::{esc, page_head};
use anyhow::Result;
use std::collections::BTreeMap;
use std::path::Path;

/// The collection's page inside its folder.
pub const REPORT_HTML: &str = "report.html";

/// A χ²_red for the page.
fn chi(x: Option<f64>) -> String {
    x.map(|v| format!("{v:.3}")).unwrap_or_else(|| "–".into())
}

/// How many data sets named each effect, most often first.
pub fn effect_counts(cells: &[CellRecord]) -> Vec<(String, usize)> {
    let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
    for r in cells.iter().filter(|r| r.status == CellStatus::Done) {
        for e in &r.effects {
            *counts.entry(e.as_str()).or_default() += 1;
        }
    }
    let mut v: Vec<(String, usize)> = counts
        .into_iter()
        .map(|(e, n)| (e.to_string(), n))
        .collect();
    v.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    v
}

/// The page's diagnosis section (without the page around it).
pub fn section(out: &Path, cells: &[CellRecord], pictures: bool) -> String {
    let done = cells
        .iter()
        .filter(|r| r.status == CellStatus::Done)
        .count();
    let mut h = format!(
        "<h2 id=\"diagnoses\">Diagnoses</h2>\n<p class=\"meta\">{} data sets, {} diagnosed, {} failed; sorted by final χ²_red, worst first (χ²_red near 1: the final model fits within the uncertainties). Tables: <a href=\"diagnoses.csv\">diagnoses.csv</a>, <a href=\"diagnoses.json\">diagnoses.json</a>.</p>\n",
        cells.len(),
        done,
        cells.len() - done
    );
    h += "<table><tr><th>data set</th><th>samples × channels</th><th>start</th><th>χ²_red start</th><th>final model</th><th>χ²_red final</th><th>effects</th><th>stopped</th><th>s</th></tr>\n";
    for r in sorted(cells) {
        let name = if pictures && r.status == CellStatus::Done {
            format!(
                "<a href=\"{REPORTS_DIR}/{0}/index.html\">{0}</a>",
                esc(&r.data)
            )
        } else {
            esc(&r.data)
        };
        if r.status == CellStatus::Failed {
            h += &format!(
                "<tr><td>{name}</td><td colspan=\"7\" class=\"note\" style=\"text-align:left\">failed: {}</td><td>{:.1}</td></tr>\n",
                esc(r.error.as_deref().unwrap_or("")),
                r.seconds
            );
            continue;
        }
        h += &format!(
            "<tr><td>{name}</td><td>{} × {}</td><td><code>{}</code></td><td>{}</td><td style=\"text-align:left\"><code>{}</code></td><td>{}</td><td style=\"text-align:left\">{}</td><td style=\"text-align:left\">{}</td><td>{:.1}</td></tr>\n",
            r.samples,
            r.channels,
            esc(&r.start_model),
            chi(r.start_chi2_red),
            esc(r.final_model.as_deref().unwrap_or("")),
            chi(r.final_chi2_red),
            if r.effects.is_empty() { "none".to_string() } else { esc(&r.effects.join(", ")) },
            esc(r.stop.as_deref().unwrap_or("")),
            r.seconds
        );
    }
    h += "</table>\n<h3>Effects named across the collection</h3>\n";
    let counts = effect_counts(cells);
    if counts.is_empty() {
        h += "<p>No effect was named: every start model fitted within the uncertainties, or none was diagnosed.</p>\n";
    } else {
        h += "<table><tr><th>effect</th><th>data sets</th></tr>\n";
        for (e, n) in counts {
            h += &format!("<tr><td>{}</td><td>{n} of {done}</td></tr>\n", esc(&e));
        }
        h += "</table>\n";
    }
    if pictures {
        h += "<h3>Residuals before and after</h3>\n<p class=\"meta\">Normalised residuals (model − measured)/u of the start model and of the final model, per data set.</p>\n";
        for r in sorted(cells)
            .into_iter()
            .filter(|r| r.status == CellStatus::Done)
        {
            let last = r.rounds.len().saturating_sub(1);
            let dir = format!("{REPORTS_DIR}/{}", r.data);
            let pics: Vec<(String, &str)> = [(0, "start"), (last, "final")]
                .into_iter()
                .filter(|(i, w)| *i > 0 || *w == "start")
                .map(|(i, w)| (format!("{dir}/residuals_{i}.svg"), w))
                .filter(|(p, _)| out.join(p).exists())
                .collect();
            if pics.is_empty() {
                continue;
            }
            h += &format!(
                "<h4>{} <span class=\"meta\">χ²_red {} → {}</span></h4>\n<div class=\"row\">",
                esc(&r.data),
                chi(r.start_chi2_red),
                chi(r.final_chi2_red)
            );
            for (p, w) in pics {
                let model = if w == "start" {
                    r.start_model.as_str()
                } else {
                    r.final_model.as_deref().unwrap_or("")
                };
                h += &format!(
                    "<figure><img src=\"{}\" alt=\"{w} residuals\" style=\"width:600px\"><figcaption>{w}: <code>{}</code></figcaption></figure>",
                    esc(&p),
                    esc(model)
                );
            }
            h += "</div>\n";
        }
    }
    h
}

/// Write `report.html` into `out` (only where a byte changes).
pub fn write(out: &Path, cells: &[CellRecord], pictures: bool) -> Result<()> {
    let html = page_head("bsdfit diagnoses")
        + "<h1>bsdfit diagnoses</h1>\n"
        + &section(out, cells, pictures)
        + "</body></html>\n";
    write_if_changed(&out.join(REPORT_HTML), &html)?;
    Ok(())
}
