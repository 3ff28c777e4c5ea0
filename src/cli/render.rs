//! `bsdfit render`.

use super::DataArgs;
use crate::bsdf::Model;
use crate::data::Dataset;
use crate::output::render::{render_fit, ErrorMetric, Lookup, RenderOptions};
use crate::output::results;
use anyhow::Result;
use clap::Args;

/// `bsdfit render` arguments.
#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    /// BRDF data set whose samples make the tabulated baseline (and to which the fit
    /// belongs), in any format read (bsdfit v1 CSV, ALTA text, MERL binary, RGL .bsdf,
    /// Zemax BSDF, ASTM E1392, Mueller-matrix BRDF CSV; recognised by content).
    pub data: std::path::PathBuf,
    /// A fit: the JSON of `bsdfit fit --json`, or results.json of a sweep (then pick the row
    /// with --model and, if several match, --loss/--weights/--optimizer).
    #[arg(long)]
    pub fit: Option<std::path::PathBuf>,
    /// Model spec (with --params instead of --fit, or to pick a row of results.json).
    #[arg(long)]
    pub model: Option<String>,
    /// Parameters as name=value,... (with --model, instead of --fit).
    #[arg(long)]
    pub params: Option<String>,
    /// With a sweep's results.json as --fit: the loss of the row to render.
    #[arg(long)]
    pub loss: Option<String>,
    /// With a sweep's results.json as --fit: the weighting of the row to render.
    #[arg(long)]
    pub weights: Option<String>,
    /// With a sweep's results.json as --fit: the optimizer of the row to render.
    #[arg(long)]
    pub optimizer: Option<String>,
    /// Another data set of the same material for the baseline (e.g. one with off-plane and
    /// near-specular samples, so that the baseline covers the whole hemisphere).
    #[arg(long)]
    pub baseline: Option<std::path::PathBuf>,
    /// Image width and height in pixels (8–4096).
    #[arg(long, default_value_t = 256)]
    pub size: u32,
    /// Light direction THETA,PHI in degrees (polar angle from the view axis, azimuth in the
    /// image plane; 135 = upper left).
    #[arg(long, default_value = "45,135")]
    pub light: String,
    /// How the tabulated baseline finds a pixel's value among the samples: nearest (the
    /// nearest sample's) or idw (an inverse-distance blend of the 4 nearest).
    #[arg(long, value_parser = super::choice::<Lookup>(), default_value = "idw")]
    pub lookup: Lookup,
    /// The per-pixel error the error image shows between the model's render and the
    /// tabulated baseline's.
    #[arg(long, value_parser = super::choice::<ErrorMetric>(), default_value = "smape")]
    pub error: ErrorMetric,
    /// Error at the top of the colour scale (default 0.5 for SMAPE, 0.1 for RMSE).
    #[arg(long)]
    pub error_scale: Option<f64>,
    #[command(flatten)]
    pub data_args: DataArgs,
    /// Output directory: baseline.png, model.png, error.png, render.json (created if
    /// needed; checked before rendering).
    #[arg(long)]
    pub out: std::path::PathBuf,
}

/// The `render` command.
pub fn run(a: &RenderArgs) -> Result<()> {
    use anyhow::Context;
    let data = a.data_args.read(&a.data)?;
    let baseline = match &a.baseline {
        Some(p) => a.data_args.read(p)?,
        None => data.clone(),
    };
    let (spec, params): (String, serde_json::Map<String, serde_json::Value>) =
        match (&a.fit, &a.model, &a.params) {
            (Some(path), _, _) => {
                let text = std::fs::read_to_string(path)
                    .with_context(|| format!("cannot read {}", path.display()))?;
                let v: serde_json::Value = serde_json::from_str(&text)
                    .with_context(|| format!("{} is not JSON", path.display()))?;
                pick_fit(&v, a, &data)?
            }
            (None, Some(spec), Some(p)) => {
                let m = Model::for_data(spec, &data)?;
                let flat = m.params_from_assignments(p).context("--params")?;
                let mut map = serde_json::Map::new();
                for fp in &m.params {
                    let w = fp.width(m.channels);
                    let vals = &flat[fp.index..fp.index + w];
                    map.insert(
                        fp.name.clone(),
                        if w > 1 {
                            serde_json::json!(vals)
                        } else {
                            serde_json::json!(vals[0])
                        },
                    );
                }
                (spec.clone(), map)
            }
            _ => anyhow::bail!("give --fit FIT.json, or --model SPEC with --params name=value,..."),
        };
    let model = Model::for_data(&spec, &data)?;
    let flat = results::flat_from_params(&model, &params)?;
    let (lt, lp) = a
        .light
        .split_once(',')
        .and_then(|(t, p)| Some((t.trim().parse::<f64>().ok()?, p.trim().parse::<f64>().ok()?)))
        .context("--light: expected THETA,PHI in degrees")?;
    anyhow::ensure!((0.0..90.0).contains(&lt), "--light: θ must be in [0, 90)");
    anyhow::ensure!((8..=4096).contains(&a.size), "--size must be in 8..=4096");
    if let Some(scale) = a.error_scale {
        anyhow::ensure!(
            scale.is_finite() && scale > 0.0,
            "--error-scale: the error that maps to full colour must be a positive number, got {scale}"
        );
    }
    // Every option is checked before the output folder is made and the render starts.
    crate::output::check_writable_dir(&a.out, "--out")?;
    let o = RenderOptions {
        size: a.size,
        light_theta: lt,
        light_phi: lp,
        lookup: a.lookup,
        error: a.error,
        error_scale: a.error_scale.unwrap_or(match a.error {
            ErrorMetric::Smape => 0.5,
            ErrorMetric::Rmse => 0.1,
        }),
    };
    let stats = render_fit(
        &model,
        &flat,
        &baseline,
        &o,
        Some(&a.out.join("baseline.png")),
        &a.out.join("model.png"),
        &a.out.join("error.png"),
        &data.label(),
    )?;
    crate::output::write_atomic(
        &a.out.join("render.json"),
        (serde_json::to_string_pretty(&stats)? + "\n").as_bytes(),
    )?;
    println!(
        "{} on {} (baseline {}): mean per-pixel {} = {:.4}, max {:.4} over {} pixels; wrote {}/{{baseline,model,error}}.png",
        stats.model,
        stats.data,
        stats.baseline,
        stats.metric,
        stats.mean_error,
        stats.max_error,
        stats.pixels,
        a.out.display()
    );
    Ok(())
}

/// Why no row of results.json matches, with what the rows hold: the data names when none
/// is for `stem`, else that data's models.
fn no_row(rows: &[serde_json::Value], stem: &str) -> anyhow::Error {
    let field =
        |o: &serde_json::Value, k: &str| o.get(k).and_then(|v| v.as_str()).map(String::from);
    let listed = |mut names: Vec<String>| {
        names.sort();
        names.dedup();
        names.join(", ")
    };
    let models: Vec<String> = rows
        .iter()
        .filter(|o| field(o, "data").as_deref() == Some(stem))
        .filter_map(|o| field(o, "model"))
        .collect();
    if models.is_empty() {
        let data = rows.iter().filter_map(|o| field(o, "data")).collect();
        anyhow::anyhow!(
            "no row of the results is for data '{stem}' (the rows are for: {}); give the data file the sweep fitted",
            listed(data)
        )
    } else {
        anyhow::anyhow!(
            "no row of the results for data '{stem}' matches (--model/--loss/--weights/--optimizer); its rows' models: {}",
            listed(models)
        )
    }
}

/// The (model, params) of a fit JSON: a `fit --json` report, or a row of results.json.
fn pick_fit(
    v: &serde_json::Value,
    a: &RenderArgs,
    data: &Dataset,
) -> Result<(String, serde_json::Map<String, serde_json::Value>)> {
    use anyhow::Context;
    let get =
        |o: &serde_json::Value| -> Option<(String, serde_json::Map<String, serde_json::Value>)> {
            let model = o.get("model")?.as_str()?.to_string();
            let params = o
                .get("best")
                .and_then(|b| b.get("params"))
                .or_else(|| o.get("params"))?
                .as_object()?
                .clone();
            Some((model, params))
        };
    match v {
        serde_json::Value::Array(rows) => {
            let stem = a
                .data
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default();
            let want = |o: &serde_json::Value, k: &str, x: &Option<String>| {
                x.as_ref()
                    .is_none_or(|x| o.get(k).and_then(|v| v.as_str()) == Some(x.as_str()))
            };
            let hits: Vec<&serde_json::Value> = rows
                .iter()
                .filter(|o| o.get("data").and_then(|d| d.as_str()) == Some(stem.as_str()))
                .filter(|o| {
                    want(o, "model", &a.model)
                        && want(o, "loss", &a.loss)
                        && want(o, "weights", &a.weights)
                        && want(o, "optimizer", &a.optimizer)
                })
                .collect();
            match hits.len() {
                0 => Err(no_row(rows, &stem)),
                1 => get(hits[0]).context("malformed row"),
                n => anyhow::bail!("{n} rows match for data '{stem}' ({}); narrow with --model/--loss/--weights/--optimizer", data.label()),
            }
        }
        o => get(o).context(
            "the JSON has no model and best.params: give a fit report of `bsdfit fit --json` (one fit, not --per-axis) or a sweep's results.json",
        ),
    }
}
