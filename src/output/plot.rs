//! Angular plots (paper Figs. 1–6, top rows): model curves against the measured samples
//! with their ±u bars, in SVG (plotters' SVG backend, no system font libraries).
//!
//! BRDF: in-plane samples (φo = φi or φi + 180°) against signed θo (negative on the mirror
//! side, the file convention), one curve per θi for a few θi, at one channel.
//! BTDF: samples against signed θt, one curve per (θi, measurement plane φ).

use crate::bsdf::Model;
use crate::data::{Dataset, Kind, Sample};
use crate::math::direction;
use anyhow::Result;
use glam::DVec3;
use plotters::prelude::*;
use std::path::Path;

/// A categorical palette (Tableau 10).
pub const PALETTE: [(u8, u8, u8); 10] = [
    (31, 119, 180),
    (214, 39, 40),
    (44, 160, 44),
    (148, 103, 189),
    (255, 127, 14),
    (23, 190, 207),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
];

/// One curve and/or set of measured points.
#[derive(Clone, Debug, Default)]
pub struct Series {
    pub label: String,
    pub color: (u8, u8, u8),
    /// Model curve (x, y).
    pub curve: Vec<(f64, f64)>,
    /// Measured points (x, y, u).
    pub points: Vec<(f64, f64, f64)>,
    /// Draw the curve dashed (kept for callers; [`Series::dash`] chooses the pattern).
    pub dashed: bool,
    /// The curve's line pattern.
    pub dash: Dash,
}

/// One chart.
#[derive(Clone, Debug, Default)]
pub struct Panel {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    /// Force a log y axis (None: automatic, when the values span more than two decades).
    pub log_y: Option<bool>,
}

/// `c` blended towards white by `t` (0: unchanged, 1: white).
pub fn lighten(c: (u8, u8, u8), t: f64) -> (u8, u8, u8) {
    let f = |v: u8| (v as f64 + (255.0 - v as f64) * t).round() as u8;
    (f(c.0), f(c.1), f(c.2))
}

fn rgb(c: (u8, u8, u8)) -> RGBColor {
    RGBColor(c.0, c.1, c.2)
}

impl Panel {
    fn ranges(&self) -> ((f64, f64), (f64, f64), bool) {
        let xs = self.series.iter().flat_map(|s| {
            s.curve
                .iter()
                .map(|p| p.0)
                .chain(s.points.iter().map(|p| p.0))
        });
        let (mut x0, mut x1) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(x), b.max(x))
        });
        if !(x0.is_finite() && x1.is_finite()) || x1 <= x0 {
            (x0, x1) = (-90.0, 90.0);
        }
        let pad = 0.03 * (x1 - x0);
        let ys: Vec<f64> = self
            .series
            .iter()
            .flat_map(|s| {
                s.curve
                    .iter()
                    .map(|p| p.1)
                    .chain(s.points.iter().map(|p| p.1 + p.2))
            })
            .filter(|y| y.is_finite())
            .collect();
        let ymax = ys.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let pos_min = self
            .series
            .iter()
            .flat_map(|s| {
                s.curve
                    .iter()
                    .map(|p| p.1)
                    .chain(s.points.iter().map(|p| p.1))
            })
            .filter(|y| y.is_finite() && *y > 0.0)
            .fold(f64::INFINITY, f64::min);
        let log = self
            .log_y
            .unwrap_or(ymax > 0.0 && pos_min.is_finite() && ymax / pos_min > 100.0);
        // Room at the top for the legend (upper right), growing with its entries, so it
        // does not cover the data.
        let entries = self.series.iter().filter(|s| !s.label.is_empty()).count();
        let room = if entries == 0 {
            0.05
        } else {
            (0.08 + 0.055 * entries as f64).min(0.45)
        };
        if log {
            let lo = (pos_min.max(ymax * 1e-5)).max(1e-12) * 0.7;
            let hi = ymax.max(lo * 10.0) * 1.5;
            let hi = hi * (hi / lo).powf(room / (1.0 - room));
            ((x0 - pad, x1 + pad), (lo, hi), true)
        } else {
            let ymin = ys.iter().cloned().fold(f64::INFINITY, f64::min).min(0.0);
            let hi = if ymax.is_finite() && ymax > ymin {
                ymax
            } else {
                ymin + 1.0
            };
            let top = hi + (hi - ymin) * room / (1.0 - room);
            ((x0 - pad, x1 + pad), (ymin, top), false)
        }
    }
}

fn fmt_tick(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if !(1e-2..1e4).contains(&a) {
        format!("{v:.0e}")
    } else if a >= 10.0 {
        format!("{v:.0}")
    } else {
        let s = format!("{v:.3}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// The line pattern of a model curve.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Dash {
    #[default]
    Solid,
    /// 6 px dashes.
    Dashed,
    /// Dots.
    Dotted,
    /// 12 px dashes.
    Long,
}

impl Dash {
    /// The n-th pattern, for telling several fits apart besides their colour.
    pub fn nth(n: usize) -> Dash {
        [Dash::Solid, Dash::Dashed, Dash::Dotted, Dash::Long][n % 4]
    }
    /// (dash, gap) in pixels; None for solid.
    fn pattern(self) -> Option<(u32, u32)> {
        match self {
            Dash::Solid => None,
            Dash::Dashed => Some((6, 4)),
            Dash::Dotted => Some((2, 3)),
            Dash::Long => Some((12, 5)),
        }
    }
}

impl Series {
    fn line_dash(&self) -> Dash {
        if self.dash == Dash::Solid && self.dashed {
            Dash::Dashed
        } else {
            self.dash
        }
    }
}

/// Width of model curves (px): thin, so that overlapping curves and the measured points
/// under them stay visible.
const CURVE_WIDTH: u32 = 1;

macro_rules! draw_chart {
    ($chart:expr, $panel:expr, $ylo:expr) => {{
        let chart = &mut $chart;
        let panel: &Panel = $panel;
        // Values at or below `ylo` (log axes: ≤ 0, or below the axis) are drawn at `ylo`.
        let ylo: f64 = $ylo;
        chart
            .configure_mesh()
            .x_desc(panel.x_label.as_str())
            .y_desc(panel.y_label.as_str())
            .x_label_formatter(&|v| fmt_tick(*v))
            .y_label_formatter(&|v| fmt_tick(*v))
            .light_line_style(RGBColor(240, 240, 240))
            .bold_line_style(RGBColor(220, 220, 220))
            .label_style(("sans-serif", 13))
            .axis_desc_style(("sans-serif", 14))
            .draw()
            .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
        let mut floored = 0usize;
        for s in &panel.series {
            let c = rgb(s.color);
            let style = ShapeStyle {
                color: c.to_rgba(),
                filled: false,
                stroke_width: CURVE_WIDTH,
            };
            let curve: Vec<(f64, f64)> = s
                .curve
                .iter()
                .filter(|p| p.1.is_finite())
                .map(|&(x, y)| (x, y.max(ylo)))
                .collect();
            let pts: Vec<(f64, f64, f64)> = s
                .points
                .iter()
                .filter(|p| p.1.is_finite())
                .cloned()
                .collect();
            let dash = s.line_dash();
            if !curve.is_empty() {
                let anno = match dash.pattern() {
                    Some((d, g)) => chart
                        .draw_series(DashedLineSeries::new(curve, d, g, style))
                        .map_err(|e| anyhow::anyhow!("plot: {e}"))?,
                    None => chart
                        .draw_series(LineSeries::new(curve, style))
                        .map_err(|e| anyhow::anyhow!("plot: {e}"))?,
                };
                if !s.label.is_empty() {
                    let with_dot = !pts.is_empty();
                    anno.label(s.label.as_str()).legend(move |(x, y)| {
                        let line: DynElement<_, _> = match dash.pattern() {
                            Some((d, g)) => plotters::element::DashedPathElement::new(
                                vec![(x, y), (x + 22, y)],
                                d,
                                g,
                                style,
                            )
                            .into_dyn(),
                            None => PathElement::new(vec![(x, y), (x + 22, y)], style).into_dyn(),
                        };
                        let dot =
                            Circle::new((x + 11, y), if with_dot { 3 } else { 0 }, c.filled());
                        EmptyElement::at((0, 0)) + line + dot
                    });
                }
            }
            if !pts.is_empty() {
                // Error bars (±u, floored on log axes) with short caps, then the markers.
                chart
                    .draw_series(pts.iter().map(|&(x, y, u)| {
                        PathElement::new(
                            vec![(x, (y - u).max(ylo)), (x, (y + u).max(ylo))],
                            c.mix(0.7).stroke_width(1),
                        )
                    }))
                    .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
                let a = chart
                    .draw_series(pts.iter().filter(|p| p.1 > ylo).map(|&(x, y, _)| {
                        EmptyElement::at((x, y))
                            + Circle::new((0, 0), 3, c.filled())
                            + Circle::new((0, 0), 3, WHITE.stroke_width(1))
                    }))
                    .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
                if s.curve.is_empty() && !s.label.is_empty() {
                    a.label(s.label.as_str())
                        .legend(move |(x, y)| Circle::new((x + 11, y), 3, c.filled()));
                }
                // Values the axis cannot show (≤ 0 on a log axis): an open triangle
                // pointing down at the bottom edge.
                let low: Vec<f64> = pts.iter().filter(|p| p.1 <= ylo).map(|p| p.0).collect();
                floored += low.len();
                chart
                    .draw_series(low.iter().map(|&x| {
                        EmptyElement::at((x, ylo))
                            + PathElement::new(
                                vec![(-4, -9), (4, -9), (0, -2), (-4, -9)],
                                c.stroke_width(1),
                            )
                    }))
                    .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
            }
        }
        if floored > 0 {
            let grey = RGBColor(90, 90, 90);
            chart
                .draw_series(std::iter::empty::<Circle<(f64, f64), i32>>())
                .map_err(|e| anyhow::anyhow!("plot: {e}"))?
                .label("measured ≤ 0 or below the axis (at its bottom edge)")
                .legend(move |(x, y)| {
                    PathElement::new(
                        vec![
                            (x + 7, y - 4),
                            (x + 15, y - 4),
                            (x + 11, y + 3),
                            (x + 7, y - 4),
                        ],
                        grey.stroke_width(1),
                    )
                });
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.9))
            .border_style(RGBColor(180, 180, 180))
            .label_font(("sans-serif", 13))
            .draw()
            .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
    }};
}

/// Draw panels side by side into an SVG file (written atomically).
pub fn write_svg(path: &Path, panels: &[Panel], panel_size: (u32, u32)) -> Result<()> {
    let svg = svg_text(panels, panel_size)?;
    crate::output::files::write_atomic(path, svg.as_bytes())
}

/// Panels side by side as SVG text.
pub fn svg_text(panels: &[Panel], panel_size: (u32, u32)) -> Result<String> {
    let n = panels.len().max(1) as u32;
    let mut svg = String::new();
    {
        let root =
            SVGBackend::with_string(&mut svg, (panel_size.0 * n, panel_size.1)).into_drawing_area();
        root.fill(&WHITE)
            .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
        let areas = root.split_evenly((1, n as usize));
        for (area, panel) in areas.iter().zip(panels) {
            let ((x0, x1), (y0, y1), log) = panel.ranges();
            let mut b = ChartBuilder::on(area);
            b.caption(panel.title.as_str(), ("sans-serif", 16))
                .margin(10)
                .x_label_area_size(40)
                .y_label_area_size(62);
            if log {
                let mut chart = b
                    .build_cartesian_2d(x0..x1, (y0..y1).log_scale())
                    .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
                draw_chart!(chart, panel, y0);
            } else {
                let mut chart = b
                    .build_cartesian_2d(x0..x1, y0..y1)
                    .map_err(|e| anyhow::anyhow!("plot: {e}"))?;
                draw_chart!(chart, panel, f64::NEG_INFINITY);
            }
        }
        root.present().map_err(|e| anyhow::anyhow!("plot: {e}"))?;
    }
    Ok(svg)
}

/// A fitted model to draw: label, compiled model, flat parameters.
pub struct Fitted<'a> {
    pub label: String,
    pub model: &'a Model,
    pub flat: &'a [f64],
    /// The fit's covariance propagated to model values, where known: an anisotropic
    /// BTDF's prediction between the measured planes is drawn with its ±1σ band.
    pub propagator: Option<&'a crate::inference::saved::Propagator<'a>>,
}

/// Signed in-plane angle of a BRDF sample's θo relative to its φi (None if out of plane).
pub fn inplane_x(s: &Sample) -> Option<f64> {
    let t = s.theta_o.to_degrees();
    if t < 1e-9 {
        return Some(0.0);
    }
    let d = (s.phi_o - s.phi_i).to_degrees().rem_euclid(360.0);
    if !(1e-6..=360.0 - 1e-6).contains(&d) {
        Some(t)
    } else if (d - 180.0).abs() < 1e-6 {
        Some(-t)
    } else {
        None
    }
}

/// The channel nearest 550 nm (the middle channel of 450/550/650).
pub fn display_channel(data: &Dataset) -> usize {
    (0..data.channels.len())
        .min_by(|&a, &b| {
            (data.channels[a] - 550.0)
                .abs()
                .total_cmp(&(data.channels[b] - 550.0).abs())
        })
        .unwrap_or(0)
}

/// Up to `n` θi values of the in-plane samples, evenly spread (degrees).
pub fn plot_thetas(data: &Dataset, n: usize) -> Vec<f64> {
    let mut t: Vec<f64> = data
        .samples
        .iter()
        .filter(|s| inplane_x(s).is_some())
        .map(|s| (s.theta_i.to_degrees() * 1e6).round() / 1e6)
        .collect();
    t.sort_by(|a, b| a.total_cmp(b));
    t.dedup();
    if t.len() <= n {
        return t;
    }
    (0..n)
        .map(|k| t[(k * (t.len() - 1) + (n - 1) / 2) / (n - 1).max(1)])
        .collect::<Vec<_>>()
}

fn brdf_dirs(theta_i: f64, x: f64) -> (DVec3, DVec3) {
    let wi = direction(theta_i.to_radians(), 0.0);
    let wo = direction(
        x.abs().to_radians(),
        if x < 0.0 { std::f64::consts::PI } else { 0.0 },
    );
    (wi, wo)
}

fn curve_xs(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let n = ((hi - lo) / step).round() as usize;
    (0..=n).map(|i| lo + i as f64 * step).collect()
}

/// Measured in-plane points of channel `ch` at incidence `ti` (degrees).
fn brdf_points(data: &Dataset, ch: usize, ti: f64) -> Vec<(f64, f64, f64)> {
    let mut pts: Vec<(f64, f64, f64)> = data
        .samples
        .iter()
        .filter(|s| s.channel == ch && (s.theta_i.to_degrees() - ti).abs() < 1e-6)
        .filter_map(|s| inplane_x(s).map(|x| (x, s.value, s.uncertainty)))
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    pts
}

/// BRDF panel: one fit, one curve per θi (colours), measured in-plane points with ±u.
pub fn brdf_panel(data: &Dataset, fit: &Fitted, title: &str) -> Panel {
    let ch = display_channel(data);
    let thetas = plot_thetas(data, 4);
    let mut series = Vec::new();
    for (k, &ti) in thetas.iter().enumerate() {
        let curve = curve_xs(-89.5, 89.5, 0.5)
            .into_iter()
            .map(|x| {
                let (wi, wo) = brdf_dirs(ti, x);
                (x, fit.model.eval(fit.flat, ch, wi, wo))
            })
            .collect();
        series.push(Series {
            label: format!("θi = {ti}°"),
            color: PALETTE[k % PALETTE.len()],
            curve,
            points: brdf_points(data, ch, ti),
            // Curves that coincide (e.g. Lambert at every θi) stay visible as patterns.
            dash: Dash::nth(k),
            ..Default::default()
        });
    }
    Panel {
        title: title.to_string(),
        x_label: format!(
            "θo (°, in plane; < 0: mirror side) — {} nm",
            data.channels.get(ch).copied().unwrap_or(0.0)
        ),
        y_label: "BRDF (sr⁻¹)".into(),
        series,
        log_y: None,
    }
}

/// Measurement planes of BTDF samples: (θi, plane index) groups with signed θt.
fn btdf_groups(data: &Dataset) -> Vec<(f64, usize)> {
    let mut g: Vec<(f64, usize)> = data
        .samples
        .iter()
        .map(|s| ((s.theta_i.to_degrees() * 1e6).round() / 1e6, s.axis))
        .collect();
    g.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    g.dedup();
    g
}

fn btdf_signed(s: &Sample, plane_deg: f64) -> f64 {
    let t = s.theta_o.to_degrees();
    let d = (s.phi_o.to_degrees() - plane_deg).rem_euclid(360.0);
    if (d - 180.0).abs() < 1e-6 {
        -t
    } else {
        t
    }
}

fn btdf_points(data: &Dataset, ti: f64, axis: usize, ch: usize) -> Vec<(f64, f64, f64)> {
    let plane = data.axes.get(axis).copied().unwrap_or(0.0);
    let mut pts: Vec<(f64, f64, f64)> = data
        .samples
        .iter()
        .filter(|s| s.channel == ch && s.axis == axis && (s.theta_i.to_degrees() - ti).abs() < 1e-6)
        .map(|s| (btdf_signed(s, plane), s.value, s.uncertainty))
        .collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    pts
}

fn btdf_curve(
    data: &Dataset,
    fit: &Fitted,
    ti: f64,
    axis: usize,
    ch: usize,
    lo: f64,
    hi: f64,
) -> Vec<(f64, f64)> {
    let plane = data.axes.get(axis).copied().unwrap_or(0.0);
    let group = if fit.model.axes.len() > 1 {
        axis.min(fit.model.axes.len() - 1) * fit.model.channels + ch
    } else {
        ch
    };
    let wi = direction(ti.to_radians(), 0.0);
    curve_xs(lo, hi, 0.25)
        .into_iter()
        .map(|x| {
            let phi = if x < 0.0 { plane + 180.0 } else { plane };
            let mut wo = direction(x.abs().to_radians(), phi.to_radians());
            wo.z = -wo.z;
            (x, fit.model.eval(fit.flat, group, wi, wo))
        })
        .collect()
}

fn btdf_range(data: &Dataset) -> (f64, f64) {
    let m = data
        .samples
        .iter()
        .map(|s| s.theta_o.to_degrees())
        .fold(0.0, f64::max);
    let lo_side = data.samples.iter().any(|s| {
        let plane = data.axes.get(s.axis).copied().unwrap_or(0.0);
        btdf_signed(s, plane) < 0.0
    });
    let hi = (m + 2.0).min(89.0);
    (if lo_side { -hi } else { 0.0 }, hi)
}

/// Do two curves on the same abscissae coincide (to 1e-9 relative)?
fn same_curve(a: &[(f64, f64)], b: &[(f64, f64)]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(p, q)| {
            p.0 == q.0 && (p.1 == q.1 || (p.1 - q.1).abs() <= 1e-9 * p.1.abs().max(q.1.abs()))
        })
}

fn plane_label(data: &Dataset, ti: f64, axis: usize, groups: &[(f64, usize)]) -> String {
    let mut parts = Vec::new();
    if groups.iter().any(|g| g.0 != groups[0].0) {
        parts.push(format!("θi = {ti}°"));
    }
    if data.axes.len() > 1 {
        parts.push(format!(
            "φ = {}°",
            data.axes.get(axis).copied().unwrap_or(0.0)
        ));
    }
    parts.join(", ")
}

/// BTDF panel: several fits overlaid (one colour and line pattern per fit; lighter on
/// the second and later planes or incidences), measured points in black/grey per plane.
pub fn btdf_panel(data: &Dataset, fits: &[Fitted], title: &str) -> Panel {
    let ch = 0;
    let groups = btdf_groups(data);
    let (lo, hi) = btdf_range(data);
    let mut series = Vec::new();
    let single = fits.len() == 1;
    for (gi, &(ti, axis)) in groups.iter().enumerate() {
        let pl = plane_label(data, ti, axis, &groups);
        let grey = [(0, 0, 0), (110, 110, 110), (170, 170, 170)][gi.min(2)];
        series.push(Series {
            label: if pl.is_empty() {
                "measured ± u".into()
            } else {
                format!("measured, {pl}")
            },
            color: if single {
                PALETTE[gi % PALETTE.len()]
            } else {
                grey
            },
            points: btdf_points(data, ti, axis, ch),
            ..Default::default()
        });
    }
    for (fi, fit) in fits.iter().enumerate() {
        let mut drawn: Vec<Vec<(f64, f64)>> = Vec::new();
        for (gi, &(ti, axis)) in groups.iter().enumerate() {
            let pl = plane_label(data, ti, axis, &groups);
            let label = match (single, pl.is_empty()) {
                (true, true) => fit.label.clone(),
                (true, false) => format!("model, {pl}"),
                (false, _) if gi == 0 => fit.label.clone(),
                _ => String::new(),
            };
            let curve = btdf_curve(data, fit, ti, axis, ch, lo, hi);
            // An isotropic fit gives the same curve on every plane: draw it once (several
            // fits), so the first plane's curve is not painted over.
            if !single && drawn.iter().any(|c| same_curve(c, &curve)) {
                continue;
            }
            drawn.push(curve.clone());
            series.push(Series {
                label,
                color: if single {
                    PALETTE[gi % PALETTE.len()]
                } else if gi == 0 {
                    PALETTE[fi % PALETTE.len()]
                } else {
                    lighten(PALETTE[fi % PALETTE.len()], 0.45)
                },
                curve,
                // Each fit (or, for one fit, each plane/incidence) its own colour and line
                // pattern, so coinciding curves stay visible.
                dash: Dash::nth(if single { gi } else { fi }),
                ..Default::default()
            });
        }
    }
    if let [fit] = fits {
        series.extend(between_planes(data, fit, &groups, lo, hi));
    }
    Panel {
        title: title.to_string(),
        x_label: format!(
            "θt (°, signed in each φ plane) — {} nm",
            data.channels.first().copied().unwrap_or(0.0)
        ),
        y_label: "BTDF (sr⁻¹)".into(),
        series,
        log_y: None,
    }
}

/// An anisotropic fit (`+aniso`) on data measured on two or more planes predicts the
/// plane halfway between the first two (45° between planes at 0° and 90°): its curve at
/// each incidence, and the ±1σ band propagated from the fit's covariance where known.
fn between_planes(
    data: &Dataset,
    fit: &Fitted,
    groups: &[(f64, usize)],
    lo: f64,
    hi: f64,
) -> Vec<Series> {
    let anisotropic = fit.model.params.iter().any(|p| p.decl.needs_planes);
    if !anisotropic || data.axes.len() < 2 || fit.model.axes.len() > 1 {
        return Vec::new();
    }
    let plane = 0.5 * (data.axes[0] + data.axes[1]);
    let mut incidences: Vec<f64> = groups.iter().map(|g| g.0).collect();
    incidences.dedup();
    let color = (90, 90, 90);
    let mut out = Vec::new();
    for (k, &ti) in incidences.iter().enumerate() {
        let at = ti_label(&incidences, ti);
        let wi = direction(ti.to_radians(), 0.0);
        let mut lower_bound = false;
        let points: Vec<(f64, f64, f64)> = curve_xs(lo, hi, 0.25)
            .into_iter()
            .map(|x| {
                let phi = if x < 0.0 { plane + 180.0 } else { plane };
                let mut wo = direction(x.abs().to_radians(), phi.to_radians());
                wo.z = -wo.z;
                match fit.propagator {
                    Some(p) => {
                        let e = p.eval(0, wi, wo);
                        lower_bound |= e.depends_on_undetermined;
                        (x, e.value, e.uncertainty)
                    }
                    None => (x, fit.model.eval(fit.flat, 0, wi, wo), f64::NAN),
                }
            })
            .collect();
        // A parameter the data do not determine (φ0 at normal incidence on the planes of
        // the axes) has no σ: the band is then a lower bound, and says so.
        let bound = if lower_bound {
            " (a lower bound: it depends on undetermined parameters)"
        } else {
            ""
        };
        out.push(Series {
            label: if k == 0 {
                format!("predicted, φ = {plane}°{at}")
            } else {
                String::new()
            },
            color,
            curve: points.iter().map(|&(x, y, _)| (x, y)).collect(),
            dash: Dash::nth(3),
            ..Default::default()
        });
        if points.iter().all(|p| p.2.is_finite()) {
            let label = format!("±1σ (propagated), φ = {plane}°{bound}");
            for (sign, label) in [(1.0, label), (-1.0, String::new())] {
                out.push(Series {
                    label: if k == 0 { label } else { String::new() },
                    color: lighten(color, 0.5),
                    curve: points.iter().map(|&(x, y, u)| (x, y + sign * u)).collect(),
                    dash: Dash::nth(1),
                    ..Default::default()
                });
            }
        }
    }
    out
}

fn ti_label(incidences: &[f64], ti: f64) -> String {
    if incidences.len() > 1 {
        format!(", θi = {ti}°")
    } else {
        String::new()
    }
}

/// The angular panel of one fit for either kind of data.
pub fn fit_panel(data: &Dataset, fit: &Fitted, title: &str) -> Panel {
    match data.kind {
        Kind::Brdf => brdf_panel(data, fit, title),
        Kind::Btdf => btdf_panel(data, std::slice::from_ref(fit), title),
    }
}

/// Panels of one fit per panel, on a common y range (so panels compare at a glance).
pub fn common_y(panels: &mut [Panel]) {
    let log = panels.iter().any(|p| p.ranges().2);
    for p in panels.iter_mut() {
        p.log_y = Some(log);
    }
}
