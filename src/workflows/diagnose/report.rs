//! `--report`: residual maps and the χ²_red staircase (SVG via crate::output::plot) and an
//! HTML page tying them to the evidence of each step.

use super::{Diagnosis, FitResult};
use crate::data::{Dataset, Kind, Sample};
use anyhow::{Context, Result};
use std::path::Path;

/// Signed outgoing angle (degrees): negative on the far side of the plane of incidence
/// (BRDF: the mirror side, as in files) or of the sample's measurement plane (BTDF).
fn signed_out(data: &Dataset, s: &Sample) -> f64 {
    let t = s.theta_o.to_degrees();
    let reference = match data.kind {
        Kind::Brdf => s.phi_i,
        Kind::Btdf => data.axes.get(s.axis).copied().unwrap_or(0.0).to_radians(),
    };
    if (s.phi_o - reference).cos() >= -1e-9 {
        t
    } else {
        -t
    }
}

/// The residual map of one fit: z against signed θo per θi (BRDF) or against signed θt
/// per (θi, plane) (BTDF), all channels, with ±3 guides.
pub fn residual_panel(data: &Dataset, fit: &FitResult, title: &str) -> crate::output::plot::Panel {
    use crate::output::plot::{Panel, Series, PALETTE};
    let mut keys: Vec<(i64, usize)> = data
        .samples
        .iter()
        .map(|s| {
            (
                (s.theta_i.to_degrees() * 10.0).round() as i64,
                if data.kind == Kind::Btdf { s.axis } else { 0 },
            )
        })
        .collect();
    keys.sort();
    keys.dedup();
    let mut series: Vec<Series> = keys
        .iter()
        .enumerate()
        .map(|(i, &(ti, ax))| {
            let mut label = format!("θi = {}°", ti as f64 / 10.0);
            if data.kind == Kind::Btdf && data.axes.len() > 1 {
                label += &format!(", φ = {}°", data.axes[ax]);
            }
            let points = data
                .samples
                .iter()
                .zip(&fit.z)
                .filter(|(s, _)| {
                    (s.theta_i.to_degrees() * 10.0).round() as i64 == ti
                        && (data.kind == Kind::Brdf || s.axis == ax)
                })
                .map(|(s, &z)| (signed_out(data, s), z, 0.0))
                .collect();
            Series {
                label,
                color: PALETTE[i % PALETTE.len()],
                points,
                ..Default::default()
            }
        })
        .collect();
    let xs: Vec<f64> = data.samples.iter().map(|s| signed_out(data, s)).collect();
    let (x0, x1) = xs
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (a.min(x), b.max(x))
        });
    for g in [-3.0, 3.0] {
        series.push(Series {
            label: String::new(),
            color: (150, 150, 150),
            curve: vec![(x0, g), (x1, g)],
            dashed: true,
            ..Default::default()
        });
    }
    let x_label = match data.kind {
        Kind::Brdf => "θo (°, negative on the mirror side)",
        Kind::Btdf => "θt (°, signed in its φ plane)",
    };
    Panel {
        title: title.into(),
        x_label: x_label.into(),
        y_label: "z = (y′ − y)/u".into(),
        series,
        log_y: Some(false),
    }
}

/// The χ²_red staircase over the steps (log axis), one labelled point per step.
pub fn staircase_panel(d: &Diagnosis) -> crate::output::plot::Panel {
    use crate::output::plot::{Panel, Series, PALETTE};
    let mut stair = Vec::new();
    for (i, s) in d.steps.iter().enumerate() {
        stair.push((i as f64 - 0.45, s.chi2_red));
        stair.push((i as f64 + 0.45, s.chi2_red));
    }
    let mut series = vec![Series {
        label: String::new(),
        color: (60, 60, 60),
        curve: stair,
        ..Default::default()
    }];
    for (i, s) in d.steps.iter().enumerate() {
        let what = match s.effect {
            Some(e) => format!("+{e} → {}", s.model),
            None => s.model.clone(),
        };
        series.push(Series {
            label: format!("{i}: {what} ({:.3})", s.chi2_red),
            color: PALETTE[i % PALETTE.len()],
            points: vec![(i as f64, s.chi2_red, 0.0)],
            ..Default::default()
        });
    }
    // At least 6 steps wide, so that the axis ticks fall on whole steps.
    let n = (d.steps.len() as f64).max(6.0);
    series.push(Series {
        label: "χ²_red = 1".into(),
        color: (150, 150, 150),
        curve: vec![(-0.5, 1.0), (n - 0.5, 1.0)],
        dashed: true,
        ..Default::default()
    });
    Panel {
        title: "χ²_red per step".into(),
        x_label: "step".into(),
        y_label: "χ²_red".into(),
        series,
        log_y: Some(true),
    }
}

/// Write `--report DIR`: `residuals_<k>.svg` per step (step k's map is the "after" of
/// step k and the "before" of step k + 1), `staircase.svg`, `diagnosis.json`,
/// `candidates.json` and an `index.html` tying them together.
pub fn write_report(dir: &Path, data: &Dataset, d: &Diagnosis) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut html = String::from("<!doctype html><meta charset=\"utf-8\"><title>bsdfit diagnose</title><body style=\"font-family:sans-serif;max-width:1100px\">\n");
    html += &format!(
        "<h1>diagnose {}</h1><p>start <code>{}</code> → final <code>{}</code>; effects: {}</p>\n<img src=\"staircase.svg\">\n",
        esc(&data.material),
        esc(&d.start_model),
        esc(&d.final_model),
        if d.effects.is_empty() { "none".to_string() } else { d.effects.iter().map(|e| e.name()).collect::<Vec<_>>().join(", ") }
    );
    for (i, s) in d.steps.iter().enumerate() {
        let title = format!("step {i}: {} (χ²_red = {:.3})", s.model, s.chi2_red);
        let name = format!("residuals_{i}.svg");
        crate::output::plot::write_svg(
            &dir.join(&name),
            &[residual_panel(data, &s.fit, &title)],
            (900, 480),
        )?;
        html += &format!(
            "<h2>{}</h2><p>{}</p><img src=\"{name}\">\n",
            esc(&title),
            esc(&s.evidence)
        );
    }
    crate::output::plot::write_svg(
        &dir.join("staircase.svg"),
        &[staircase_panel(d)],
        (700, 420),
    )?;
    std::fs::write(
        dir.join("diagnosis.json"),
        serde_json::to_string_pretty(&d.to_json())?,
    )?;
    std::fs::write(
        dir.join("candidates.json"),
        serde_json::to_string_pretty(&d.candidates_json())?,
    )?;
    std::fs::write(dir.join("index.html"), html + "</body>\n")?;
    Ok(())
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}
