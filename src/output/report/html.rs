//! `report.html`: the page that ties the pictures together, written from the rows and the
//! render statistics (offline: relative links only).

use super::featured::Featured;
use super::inputs::DataInfo;
use super::{esc, plot_rel, render_rel, safe_name, RunInfo};
use crate::data::{Dataset, Kind};
use crate::output::render::RenderStats;
use crate::output::results::{self, fmt_num, Row, Skipped};
use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;

/// "1 fit", "3 fits".
fn plural(n: usize, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

/// "12.3 s", "4 min 05 s".
fn fmt_secs(s: f64) -> String {
    if s < 60.0 {
        format!("{s:.1} s")
    } else {
        let m = (s / 60.0).floor();
        format!("{m:.0} min {:02.0} s", (s - 60.0 * m).floor())
    }
}

fn fmt_value(v: Option<&serde_json::Value>) -> String {
    match v {
        None | Some(serde_json::Value::Null) => "–".into(),
        Some(serde_json::Value::Array(a)) => a
            .iter()
            .map(|x| x.as_f64().map(fmt_num).unwrap_or("–".into()))
            .collect::<Vec<_>>()
            .join(", "),
        Some(x) => x.as_f64().map(fmt_num).unwrap_or("–".into()),
    }
}

fn params_table(fits: &[(&str, &Row)]) -> String {
    let mut names: Vec<String> = Vec::new();
    for (_, r) in fits {
        for k in r.params_json().keys() {
            if !names.contains(k) {
                names.push(k.clone());
            }
        }
    }
    let mut s = String::from("<table class=\"params\"><tr><th>parameter</th>");
    for (label, _) in fits {
        let _ = write!(s, "<th>{}</th>", esc(label));
    }
    s += "</tr>";
    for n in &names {
        let _ = write!(s, "<tr><td><code>{}</code></td>", esc(n));
        for (_, r) in fits {
            let (p, sd) = (r.params_json(), r.param_std_json());
            let _ = write!(
                s,
                "<td>{} <span class=\"std\">± {}</span></td>",
                fmt_value(p.get(n)),
                fmt_value(sd.get(n))
            );
        }
        s += "</tr>";
    }
    let undetermined = fits.iter().any(|(_, r)| {
        let sd = r.param_std_json();
        names.iter().any(|n| fmt_value(sd.get(n)).contains('–'))
    });
    for (label, f) in [("loss", 0), ("χ²_red", 1), ("restarts within 1 %", 2)] {
        let _ = write!(s, "<tr class=\"sum\"><td>{label}</td>");
        for (_, r) in fits {
            let v = match f {
                0 => fmt_num(r.best_loss),
                1 => fmt_num(r.chi2_red),
                _ => format!("{} / {}", r.restarts_within_1pct, r.restarts),
            };
            let _ = write!(s, "<td>{v}</td>");
        }
        s += "</tr>";
    }
    s += "</table>";
    if undetermined {
        s += "<p class=\"meta\">± –: no standard uncertainty, because the data do not determine that parameter (the fit barely changes along it, e.g. a parameter of a term the data do not need or one that trades off exactly against another; see the fit's warnings in results.json).</p>";
    }
    s
}

fn figure(src: &str, caption: &str, class: &str) -> String {
    format!("<figure class=\"{class}\"><a href=\"{0}\"><img src=\"{0}\" alt=\"{1}\"></a><figcaption>{1}</figcaption></figure>", esc(src), esc(caption))
}

fn render_strip(
    r: &Row,
    renders: &BTreeMap<String, RenderStats>,
    with_baseline: bool,
    label: &str,
) -> String {
    let rel = render_rel(r, "");
    let Some(s) = renders.get(&rel) else {
        return String::new();
    };
    let mut h = String::new();
    if with_baseline {
        h += &figure(
            &format!("renders/{}/baseline.png", safe_name(&r.data)),
            &format!("baseline: tabulated {}", s.baseline),
            "render",
        );
    }
    h += &figure(
        &format!("{rel}model.png"),
        &format!("{label}: {}", r.model),
        "render",
    );
    h += &figure(
        &format!("{rel}error.png"),
        &format!(
            "per-pixel {} (colour scale 0…{}, bar below; blue-grey: beyond the measured angles; dark grey: unlit): mean {:.4}",
            s.metric.to_uppercase(),
            s.error_scale,
            s.mean_error
        ),
        "render",
    );
    h
}

fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// (uniform, weighted) χ²_red of every model fitted both ways with this loss, weighting
/// and optimizer.
fn uniform_vs_weighted(rk: &results::Ranking, loss: &str, w: &str, o: &str) -> Vec<(f64, f64)> {
    let mut pairs = Vec::new();
    for (_, fits, _) in &rk.models {
        let u = fits
            .iter()
            .flatten()
            .find(|r| r.loss == loss && r.weights == "uniform" && r.optimizer == o);
        let x = fits
            .iter()
            .flatten()
            .find(|r| r.loss == loss && r.weights == w && r.optimizer == o);
        if let (Some(u), Some(x)) = (u, x) {
            pairs.push((u.chi2_red, x.chi2_red));
        }
    }
    pairs
}

/// The page's head: title and style sheet.
const HEAD: &str = "<!DOCTYPE html><html lang=\"en\"><head><meta charset=\"utf-8\"><title>bsdfit benchmark report</title><style>\n";
/// The style sheet, ending the head and opening the body.
const STYLE: &str = "body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:24px auto;max-width:1320px;color:#222;padding:0 16px}\
h1{margin-bottom:4px}h2{border-bottom:2px solid #ddd;padding-bottom:4px;margin-top:40px}h3{margin-top:26px}\
table{border-collapse:collapse;margin:10px 0;font-size:13px}th,td{border:1px solid #ddd;padding:3px 8px;text-align:right}\
th{background:#f3f3f3}td:first-child,td:nth-child(2){text-align:left}tr.top td{background:#eef7ee;font-weight:600}\
table.params td{text-align:left}tr.sum td{background:#fafafa}.std{color:#777}.meta{color:#555;font-size:13px}\
.badge{display:inline-block;background:#fff3cd;border:1px solid #e0c36b;border-radius:4px;padding:0 6px;font-size:12px;margin-left:6px}\
figure{display:inline-block;margin:6px;vertical-align:top;text-align:center}figure img{max-width:100%;border:1px solid #ddd}\
figure.render img{width:192px;height:auto;image-rendering:pixelated}figure.render{width:200px}figcaption{font-size:12px;color:#444;max-width:640px}\
figure.wide img{width:1180px}figure.plot img{width:760px}code{font-size:12px}nav a{margin-right:10px}.note{color:#8a4b00}\
.row{display:flex;flex-wrap:wrap;align-items:flex-start}\n</style></head><body>\n";

/// The head of a page in the report's style, titled `title` (escaped here), opening the
/// body.
pub fn page_head(title: &str) -> String {
    HEAD.replace("bsdfit benchmark report", &super::esc(title)) + STYLE
}

/// What the page is written from: everything [`super::publish`] gathered.
pub(super) struct Page<'a> {
    /// Every row of results.csv.
    pub(super) all: &'a [Row],
    pub(super) run: Option<&'a RunInfo>,
    /// The current rows (one per fit).
    pub(super) cur: &'a [&'a Row],
    pub(super) ranks: &'a [results::Ranking<'a>],
    pub(super) datas: &'a BTreeMap<String, DataInfo>,
    pub(super) feats: &'a BTreeMap<String, Featured<'a>>,
    /// Render statistics by render path.
    pub(super) renders: &'a BTreeMap<String, RenderStats>,
    pub(super) baseline_of: &'a BTreeMap<String, String>,
    /// Per material: the fits rendered against its baseline.
    pub(super) sampling: &'a [(String, Vec<&'a Row>)],
    pub(super) skipped: &'a [Skipped],
    pub(super) problems: &'a [String],
}

impl Page<'_> {
    /// The whole page, section by section.
    pub(super) fn html(&self) -> String {
        let mut h = String::new();
        h += HEAD;
        h += STYLE;
        h += &self.header();
        h += &self.nav();
        h += &self.weighting_table();
        h += &self.sampling_section();
        h += &self.skipped_table();
        for rk in self.ranks {
            h += &self.data_section(rk);
        }
        h += &self.notes();
        h += "<p class=\"meta\">Generated by <code>bsdfit sweep</code> / <code>bsdfit merge</code> from results.csv; regenerate with the same command.</p></body></html>\n";
        h
    }

    /// Title line: what was fitted, how, and how long it took; flags synthetic data.
    fn header(&self) -> String {
        let Page {
            all,
            run,
            cur,
            ranks,
            datas,
            ..
        } = *self;
        let mut h = String::new();
        let backends: BTreeSet<&str> = cur.iter().map(|r| r.backend.as_str()).collect();
        let secs: f64 = cur.iter().map(|r| r.seconds).sum();
        let restarts: BTreeSet<usize> = cur.iter().map(|r| r.restarts).collect();
        let synthetic = datas
            .values()
            .filter(|d| {
                d.data.as_ref().is_some_and(|x| {
                    x.meta
                        .get("source")
                        .is_some_and(|s| s.contains("synthetic"))
                })
            })
            .count();
        let restarts = restarts
            .iter()
            .map(|r| r.to_string())
            .collect::<Vec<_>>()
            .join(", ");
        let timing = match run {
            Some(r) if r.new_fits > 0 => format!(
                "; wall-clock time of the last sweep run: {} for {} ({} at a time)",
                fmt_secs(r.wall_seconds),
                plural(r.new_fits, "new fit"),
                r.workers.max(1)
            ),
            Some(_) => "; the last sweep run found every fit already in results.csv".into(),
            None => String::new(),
        };
        let _ = writeln!(
            h,
            "<h1>bsdfit benchmark report</h1><p class=\"meta\">bsdfit {} · {} ({} in results.csv) on {} · restarts {} · backend(s) {} · sum of per-fit times {} (fits ran in parallel){timing}. Source files: <a href=\"results.csv\">results.csv</a>, <a href=\"results.json\">results.json</a>, <a href=\"rankings.md\">rankings.md</a>, <a href=\"skipped.json\">skipped.json</a>.</p>",
            env!("CARGO_PKG_VERSION"),
            plural(cur.len(), "fit"),
            plural(all.len(), "row"),
            plural(ranks.len(), "data set"),
            restarts,
            esc(&backends.into_iter().collect::<Vec<_>>().join(", ")),
            fmt_secs(secs)
        );
        if synthetic > 0 {
            let _ = writeln!(h, "<p class=\"note\">{synthetic} of the {} data sets are <b>synthetic</b> (made by <code>bsdfit synth</code> from a known model; their true parameters are listed with each). They emulate the paper's sample types; they are not measurements.</p>", datas.len());
        }
        h
    }

    /// Links to each data set's section (and to the sampling section).
    fn nav(&self) -> String {
        let Page {
            ranks, sampling, ..
        } = *self;
        let mut h = String::new();
        h += "<nav>";
        for rk in ranks {
            let _ = write!(
                h,
                "<a href=\"#d-{0}\">{1}</a>",
                safe_name(&rk.data),
                esc(&rk.data)
            );
        }
        if !sampling.is_empty() {
            h += "<a href=\"#sampling\">sampling geometry</a>";
        }
        h += "</nav>\n";
        h
    }

    /// Effect of uncertainty weighting, over all models: per data set and loss, the
    /// median χ²_red with uniform and with uncertainty weights.
    fn weighting_table(&self) -> String {
        let mut h = String::new();
        h += "<h2>Effect of uncertainty weighting</h2><p>For each data set and loss, every model fitted with uniform weights and with the uncertainty weighting (BRDF: relative-uncertainty weights of the paper §2.2; BTDF: 1/u, §2.3.2). χ²_red = Σ((y′−y)/u)²/(K−P) judges both against the stated uncertainties.</p><table><tr><th>data set</th><th>loss (optimizer)</th><th>weighting</th><th>models</th><th>median χ²_red, uniform</th><th>median χ²_red, weighted</th><th>models with lower χ²_red when weighted</th></tr>";
        for rk in self.ranks {
            let mut combos: BTreeSet<(String, String, String)> = BTreeSet::new();
            for c in &rk.columns {
                if c.1 != "uniform" {
                    combos.insert(c.clone());
                }
            }
            for (loss, w, o) in combos {
                let pairs = uniform_vs_weighted(rk, &loss, &w, &o);
                if pairs.is_empty() {
                    continue;
                }
                let better = pairs.iter().filter(|p| p.1 < p.0).count();
                let _ = write!(
                    h,
                    "<tr><td><a href=\"#d-{}\">{}</a></td><td>{loss} ({o})</td><td>{w}</td><td>{}</td><td>{}</td><td>{}</td><td>{better} of {}</td></tr>",
                    safe_name(&rk.data),
                    esc(&rk.data),
                    pairs.len(),
                    fmt_num(median(pairs.iter().map(|p| p.0).collect())),
                    fmt_num(median(pairs.iter().map(|p| p.1).collect())),
                    pairs.len()
                );
            }
        }
        h += "</table>\n";
        h
    }

    /// The same models fitted to each data set of a material, rendered against one
    /// baseline (paper Fig. 1).
    fn sampling_section(&self) -> String {
        let Page {
            renders,
            baseline_of,
            sampling,
            ..
        } = *self;
        if sampling.is_empty() {
            return String::new();
        }
        let mut h = String::new();
        h += "<h2 id=\"sampling\">Effect of sampling geometry</h2><p>The same model fitted to each data set of a material, rendered against the tabulated baseline of the material's richest data set (paper Fig. 1).</p>";
        for (material, list) in sampling {
            let base = baseline_of.get(material).cloned().unwrap_or_default();
            let _ = write!(h, "<h3>{} (baseline: {})</h3><table><tr><th>model</th><th>fitted to</th><th>samples</th><th>loss/weights</th><th>χ²_red on its data</th><th>mean per-pixel error vs baseline</th></tr>", esc(material), esc(&base));
            for r in list {
                let e = renders
                    .get(&render_rel(r, ""))
                    .map(|s| format!("{} {:.4}", s.metric.to_uppercase(), s.mean_error))
                    .unwrap_or("–".into());
                let _ = write!(
                    h,
                    "<tr><td><code>{}</code></td><td>{}</td><td>{}</td><td>{}/{}</td><td>{}</td><td>{e}</td></tr>",
                    esc(&r.model),
                    esc(&r.data),
                    r.samples,
                    r.loss,
                    r.weights,
                    fmt_num(r.chi2_red)
                );
            }
            h += "</table><div class=\"row\">";
            for (i, r) in list.iter().enumerate() {
                h += &render_strip(r, renders, i == 0, &r.data);
            }
            h += "</div>";
        }
        h
    }

    /// The fits skipped.json lists, with why.
    fn skipped_table(&self) -> String {
        let skipped = self.skipped;
        if skipped.is_empty() {
            return String::new();
        }
        let mut h = String::new();
        h += "<h2>Skipped and failed fits</h2><table><tr><th>data set</th><th>model</th><th>loss/weights (optimizer)</th><th>status</th><th>reason</th></tr>";
        for s in skipped {
            let _ = write!(
                h,
                "<tr><td>{}</td><td><code>{}</code></td><td>{}/{} ({})</td><td>{}</td><td style=\"text-align:left\">{}</td></tr>",
                esc(&s.data),
                esc(&s.model),
                esc(&s.loss),
                esc(&s.weights),
                esc(&s.optimizer),
                esc(&s.status),
                esc(&s.reason)
            );
        }
        h += "</table>\n";
        h
    }

    /// One data set: heading, ranking table and its featured figures.
    fn data_section(&self, rk: &results::Ranking) -> String {
        let info = &self.datas[&rk.data];
        let mut h = data_heading(rk, info);
        h += &ranking_table(rk);
        let Some(ds) = &info.data else { return h };
        let Some(f) = self.feats.get(&rk.data) else {
            return h;
        };
        h += &featured_figures(rk, ds, f, self.renders);
        h
    }

    /// Notes gathered while drawing (missing data, fits that could not be plotted).
    fn notes(&self) -> String {
        let problems = self.problems;
        if problems.is_empty() {
            return String::new();
        }
        let mut h = String::new();
        h += "<h2>Notes</h2><ul>";
        for p in problems {
            let _ = write!(h, "<li class=\"note\">{}</li>", esc(p));
        }
        h += "</ul>";
        h
    }
}

/// A data set's heading: its name, material, sampling and (synthetic data) true parameters.
fn data_heading(rk: &results::Ranking, info: &DataInfo) -> String {
    let mut h = String::new();
    let _ = write!(h, "<h2 id=\"d-{}\">{}", safe_name(&rk.data), esc(&rk.data));
    if let Some(ds) = &info.data {
        let _ = write!(h, " — {}", esc(&ds.material));
        if ds
            .meta
            .get("source")
            .is_some_and(|s| s.contains("synthetic"))
        {
            h += "<span class=\"badge\">synthetic</span>";
        }
        let _ = write!(h, "</h2><p class=\"meta\">{} · {} samples ({} channel(s): {:?} nm) · measurement planes φ = {:?}° · file hash {}", ds.kind, ds.len(), ds.channel_count(), ds.channels, ds.axes, info.hash);
        for k in [
            "synth_model",
            "synth_params",
            "synth_geometry",
            "synth_noise",
            "synth_seed",
        ] {
            if let Some(v) = ds.meta.get(k) {
                let _ = write!(
                    h,
                    "<br>{}: <code>{}</code>",
                    esc(k.trim_start_matches("synth_")),
                    esc(v)
                );
            }
        }
        h += "</p>";
    } else {
        h += "</h2>";
    }
    if let Some(n) = &info.note {
        let _ = write!(h, "<p class=\"note\">{}</p>", esc(n));
    }
    h
}

/// The models sorted by their best χ²_red, one column per (loss, weights, optimizer).
fn ranking_table(rk: &results::Ranking) -> String {
    let mut h = String::new();
    h += "<h3>Ranking</h3><p class=\"meta\">Models sorted by their best χ²_red. Cells: loss value · χ²_red (links: angular plot of the fit).</p><table><tr><th>rank</th><th>model</th><th>P</th>";
    for (l, w, o) in &rk.columns {
        let _ = write!(h, "<th>{l}/{w}<br>({o})</th>");
    }
    h += "<th>best χ²_red</th></tr>";
    for (i, (m, fits, best)) in rk.models.iter().enumerate() {
        let p = fits
            .iter()
            .flatten()
            .map(|r| r.n_params)
            .next()
            .unwrap_or(0);
        let _ = write!(
            h,
            "<tr{}><td>{}</td><td><code>{}</code></td><td>{p}</td>",
            if i == 0 { " class=\"top\"" } else { "" },
            i + 1,
            esc(m)
        );
        for f in fits {
            match f {
                Some(r) => {
                    let _ = write!(
                        h,
                        "<td><a href=\"{}\">{} · {}</a></td>",
                        esc(&plot_rel(r)),
                        fmt_num(r.best_loss),
                        fmt_num(r.chi2_red)
                    );
                }
                None => h += "<td>–</td>",
            }
        }
        let _ = write!(h, "<td>{}</td></tr>", fmt_num(*best));
    }
    h += "</table>";
    h
}

/// The featured plots of a data set (weights, models, suffixes), with their parameter
/// tables and, for a BRDF, the renders.
fn featured_figures(
    rk: &results::Ranking,
    ds: &Dataset,
    f: &Featured,
    renders: &BTreeMap<String, RenderStats>,
) -> String {
    let mut h = String::new();
    let dir = format!("plots/{}", safe_name(&rk.data));
    if let Some((u, w)) = f.weights {
        let _ = write!(
            h,
            "<h3>Uniform vs uncertainty weighting: {}</h3>",
            esc(&u.model)
        );
        h += &figure(
            &format!("{dir}/weights.svg"),
            &format!("{} fitted with {} uniform (left) and {} {} (right); lines: model, dots: measured ± u.", u.model, u.loss, w.loss, w.weights),
            "wide",
        );
        h += &params_table(&[("uniform", u), (w.weights.as_str(), w)]);
        if ds.kind == Kind::Brdf {
            h += "<div class=\"row\">";
            h += &render_strip(u, renders, true, "uniform");
            h += &render_strip(w, renders, false, &w.weights);
            h += "</div>";
        }
    }
    if !f.models.is_empty() {
        match ds.kind {
            Kind::Brdf => {
                h += "<h3>Top models</h3>";
                h += &figure(
                    &format!("{dir}/models.svg"),
                    &format!(
                        "The two best models ({}/{}).",
                        f.models[0].loss, f.models[0].weights
                    ),
                    "wide",
                );
                h += "<div class=\"row\">";
                for (i, r) in f.models.iter().enumerate() {
                    h += &render_strip(r, renders, i == 0, &format!("#{}", i + 1));
                }
                h += "</div>";
            }
            Kind::Btdf => {
                h += "<h3>NDF families</h3>";
                let cap = if ds.axes.len() > 1 {
                    "Best variant of each NDF family (one colour and line pattern per model; isotropic fits: one curve serves both planes, the second plane's drawn lighter)."
                } else {
                    "Best variant of each NDF family."
                };
                h += &figure(&format!("{dir}/models.svg"), cap, "plot");
            }
        }
    }
    if !f.suffixes.is_empty() {
        h += "<h3>Scale vs absorption</h3>";
        h += &figure(
            &format!("{dir}/suffixes.svg"),
            "The best family plain, with +scale and with +absorb (paper Fig. 5).",
            "plot",
        );
        let labels: Vec<(&str, &Row)> = f.suffixes.iter().map(|r| (r.model.as_str(), *r)).collect();
        h += &params_table(&labels);
    }
    h
}
