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

/// The panels of each tabulated factor of `fit`'s model (`+ndf`, `+fresnel`, `+body`):
/// the fitted value at the knots — measured ones filled with a ±2σ band (the linearised
/// σ of the logarithm), those the smoothness prior sets apart — against the same factor of
/// the analytic model `analytic` (the diagnosis's last step without tabulated factors,
/// embedded: its knots at 0 are it), or, where that model has no such lobe, the fit's own
/// analytic reference (GGX's D at its α, F(θd; η) at its η, ρ ≡ 1).
pub fn factor_panels(
    data: &Dataset,
    fit: &FitResult,
    analytic: Option<&FitResult>,
) -> Vec<crate::output::plot::Panel> {
    use crate::inference::knots::{Factor, FactorKind};
    use crate::output::plot::{lighten, Dash, Panel, Series, PALETTE};
    let (model, flat, cov) = (&fit.model, &fit.flat, &fit.cov);
    // The analytic step's parameters in this model's layout, and the fit's own with its
    // knots at 0 (its analytic reference).
    let reference: Option<Vec<f64>> = analytic.map(|a| super::embed(&a.model, &a.flat, model));
    let own_reference = {
        let mut r = flat.clone();
        for p in model.params.iter().filter(|p| p.decl.knot) {
            r[p.index..p.index + p.width(model.channels)].fill(0.0);
        }
        r
    };
    // Every factor's knots as (θ, value, σ of its log, measured), the bands computed once.
    type Knots = Vec<(f64, f64, Option<f64>, bool)>;
    let mut knots: Vec<(FactorKind, String, Option<usize>, Knots)> = Vec::new();
    use crate::inference::knots::{bands, body_bands, fresnel_bands};
    for (name, k) in bands(model, data, flat, cov) {
        let rows = k
            .iter()
            .map(|k| (k.theta_deg, k.d, k.sigma_ln_d, k.measured));
        knots.push((FactorKind::Ndf, name, None, rows.collect()));
    }
    for (name, c, k) in fresnel_bands(model, data, flat, cov) {
        let rows = k
            .iter()
            .map(|k| (k.theta_deg, k.f, k.sigma_ln_f, k.measured));
        knots.push((FactorKind::Fresnel, name, Some(c), rows.collect()));
    }
    for (name, k) in body_bands(model, data, flat, cov) {
        let rows = k
            .iter()
            .map(|k| (k.theta_deg, k.rho, k.sigma_ln_rho, k.measured));
        knots.push((FactorKind::Body, name, None, rows.collect()));
    }
    let knots_of = |f: &Factor| -> Knots {
        knots
            .iter()
            .find(|(kind, name, c, _)| *kind == f.kind && *name == f.name && *c == f.channel)
            .map(|k| k.3.clone())
            .unwrap_or_default()
    };
    let mut panels: Vec<Panel> = Vec::new();
    for f in Factor::all(model) {
        let (title, x_label, y_label) = match f.kind {
            FactorKind::Ndf => (format!("{}: the NDF", f.name), "θm (°)", "D (sr⁻¹)"),
            FactorKind::Fresnel => (
                format!("{}: the highlight's Fresnel factor", f.name),
                "θd (°)",
                "k_s F(θd) e^s(θd)",
            ),
            FactorKind::Body => (format!("{}: the body's profile", f.name), "θ (°)", "ρ(θ)"),
        };
        // A Fresnel curve's channels share one panel.
        let channel = f.channel.unwrap_or(0);
        let color = PALETTE[channel % PALETTE.len()];
        let suffix = f
            .channel
            .map_or(String::new(), |c| format!(" ({})", channel_name(data, c)));
        let rows = knots_of(&f);
        let measured: Vec<&(f64, f64, Option<f64>, bool)> = rows.iter().filter(|r| r.3).collect();
        let band = |sign: f64| -> Vec<(f64, f64)> {
            measured
                .iter()
                .filter_map(|&&(x, y, s, _)| Some((x, y * (sign * 2.0 * s?).exp())))
                .collect()
        };
        // The analytic step serves where it has the lobe (the factor's analytic inputs).
        let name_of = |j: usize| {
            model
                .params
                .iter()
                .find(|p| (p.index..p.index + p.width(model.channels)).contains(&j))
                .map(|p| p.name.as_str())
        };
        let from_analytic = analytic.is_some_and(|a| {
            f.analytic_inputs()
                .iter()
                .all(|&j| name_of(j).is_some_and(|n| a.model.params.iter().any(|q| q.name == n)))
        });
        let analytic_values = match (&reference, from_analytic) {
            (Some(r), true) => f.ln_values(r),
            _ => f.ln_values(&own_reference),
        };
        let mut series = vec![
            Series {
                label: format!("fitted, measured{suffix}"),
                color,
                points: measured.iter().map(|&&(x, y, _, _)| (x, y, 0.0)).collect(),
                ..Default::default()
            },
            Series {
                label: format!("set by the prior{suffix}"),
                color: lighten(color, 0.6),
                points: rows
                    .iter()
                    .filter(|r| !r.3)
                    .map(|&(x, y, _, _)| (x, y, 0.0))
                    .collect(),
                ..Default::default()
            },
            Series {
                label: format!("±2σ{suffix}"),
                color: lighten(color, 0.4),
                curve: band(1.0),
                dash: Dash::Dotted,
                ..Default::default()
            },
            Series {
                label: String::new(),
                color: lighten(color, 0.4),
                curve: band(-1.0),
                dash: Dash::Dotted,
                ..Default::default()
            },
            Series {
                label: if from_analytic {
                    format!("{}{suffix}", analytic.map_or("", |a| a.spec()))
                } else {
                    format!("analytic at the fit's parameters{suffix}")
                },
                color,
                curve: f
                    .degrees()
                    .into_iter()
                    .zip(analytic_values)
                    .map(|(x, l)| (x, l.exp()))
                    .filter(|p| p.1.is_finite() && p.1 > 0.0)
                    .collect(),
                dash: Dash::Dashed,
                ..Default::default()
            },
        ];
        match panels.last_mut() {
            Some(p) if f.channel.is_some_and(|c| c > 0) && p.title == title => {
                p.series.append(&mut series)
            }
            _ => panels.push(Panel {
                title,
                x_label: x_label.into(),
                y_label: y_label.into(),
                series,
                log_y: Some(f.kind == FactorKind::Ndf),
            }),
        }
    }
    panels
}

/// What a factor picture shows, and how the smoothness prior's weight was chosen.
fn factors_caption(
    smoothness: Option<&crate::inference::fit::SmoothnessChoice>,
    analytic: Option<&FitResult>,
) -> String {
    let mut s = String::from(
        "Filled: the fitted value at knots where the data see the factor (signal ≥ 3σ), with ±2σ (linearised, in the logarithm) dotted; pale: knots the smoothness prior sets, not measured. ",
    );
    s += &match analytic {
        Some(a) => format!("Dashed: the same factor of {} (the last analytic step) where it has the lobe, else the analytic factor at this fit's own parameters (knots at 0). ", a.spec()),
        None => "Dashed: the analytic factor at this fit's own parameters (knots at 0). ".into(),
    };
    if let Some(c) = smoothness {
        s += &format!(
            "The smoothness prior's σ_s = {} ({:.1} effective parameters) was chosen among {} by the {}.",
            c.chosen.sd,
            c.chosen.effective_params,
            c.tried.len(),
            c.criterion
        );
    }
    s
}

/// A channel's name for a legend: its wavelength.
fn channel_name(data: &Dataset, c: usize) -> String {
    data.channels
        .get(c)
        .map_or(format!("channel {c}"), |nm| format!("{nm} nm"))
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
    let mut analytic: Option<&FitResult> = None;
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
        // A step with tabulated factors: each one against the last analytic step's.
        let panels = factor_panels(data, &s.fit, analytic);
        if panels.is_empty() {
            analytic = Some(&s.fit);
        } else {
            let name = format!("factors_{i}.svg");
            crate::output::plot::write_svg(&dir.join(&name), &panels, (560, 420))?;
            html += &format!(
                "<h3>the tabulated factors of {}</h3><p>{}</p><img src=\"{name}\">\n",
                esc(s.fit.spec()),
                esc(&factors_caption(s.fit.smoothness.as_ref(), analytic))
            );
        }
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

use crate::output::report::esc;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Model;

    /// A fit of `spec` at the middle of every range, its knots at 0.
    fn fit_at_middle(spec: &str, data: &Dataset) -> FitResult {
        let model = Model::for_data(spec, data).unwrap();
        let mut flat = vec![0.0; model.dim];
        for p in model.params.iter().filter(|p| !p.decl.knot) {
            let w = p.width(model.channels);
            flat[p.index..p.index + w].fill(0.5 * (p.decl.lo + p.decl.hi));
        }
        FitResult {
            model,
            flat,
            values: vec![],
            z: vec![],
            chi2: 0.0,
            dof: 1,
            params: 0,
            chi2_red: 0.0,
            loss: 0.0,
            cov: Default::default(),
            seconds: 0.0,
            note: None,
            smoothness: None,
        }
    }

    /// A Fresnel curve's channels share one panel, each labelled with its wavelength; the
    /// dashed reference is the analytic step's k_s F(θd; η) where it has the lobe, read
    /// through the embedding, and the fit's own where it has none; a model without
    /// tabulated factors has no panel.
    #[test]
    fn factor_panels_compare_with_the_analytic_step() {
        let data = super::super::testdata::dataset(
            Kind::Brdf,
            &[[10.0, 0.0, 30.0, 180.0], [40.0, 0.0, 50.0, 90.0]],
            2,
        );
        let driven = fit_at_middle("fa(lambert)+fresnel", &data);
        let mut analytic = fit_at_middle("fa(lambert)", &data);
        assert!(factor_panels(&data, &analytic, None).is_empty());
        let ks = analytic
            .model
            .params
            .iter()
            .find(|p| p.name == "lobe.ks")
            .unwrap();
        analytic.flat[ks.index] = 0.25; // channel 0's amplitude differs from the fit's
        let panels = factor_panels(&data, &driven, Some(&analytic));
        assert_eq!(panels.len(), 1, "the channels share a panel");
        let labels: Vec<&str> = panels[0].series.iter().map(|s| s.label.as_str()).collect();
        assert!(labels.iter().any(|l| l.contains("450 nm")), "{labels:?}");
        assert!(labels.iter().any(|l| l.contains("550 nm")), "{labels:?}");
        // The references: the analytic step's, channel by channel (its k_s at 0°, where
        // F(0; η) multiplies both the same).
        let references: Vec<&Vec<(f64, f64)>> = panels[0]
            .series
            .iter()
            .filter(|s| s.label.starts_with(&format!("{} (", analytic.spec())))
            .map(|s| &s.curve)
            .collect();
        assert_eq!(references.len(), 2);
        let ratio = references[0][0].1 / references[1][0].1;
        let want = 0.25 / analytic.flat[ks.index + 1];
        assert!((ratio - want).abs() < 1e-12, "{ratio} against {want}");
        let ks_fit = &driven.flat[ks.index..ks.index + 2];
        assert!(
            (references[1][0].1 - ks_fit[1]).abs() > 1e-3,
            "not the fit's own amplitude"
        );
        // Without the analytic step: the fit's own reference.
        let own = factor_panels(&data, &driven, None);
        assert!(own[0]
            .series
            .iter()
            .any(|s| s.label.starts_with("analytic at the fit's")));
    }
}
