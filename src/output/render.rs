//! Sphere renders (paper Figs. 1–3, bottom rows): a sphere under one directional light,
//! seen by an orthographic camera along +z, shaded with (a) a tabulated BRDF built from
//! the measured samples (the baseline), (b) a fitted model; and (c) a per-pixel error
//! image between the two (SMAPE or RMSE). PNG via the `image` crate.
//!
//! Radiance per pixel and channel: L = f(ωi, ωo)·cos θi for unit irradiance. Channels map
//! to RGB by wavelength (red: nearest 610 nm, green: 550, blue: 465; one channel: grey).
//! Both images share one exposure (the baseline's 99th-percentile radiance maps to 0.9)
//! and the sRGB transfer curve. The tabulated baseline is isotropic and reciprocal: each
//! sample (and its reciprocal) is a point (ωi, ωo) rotated to φi = 0 with |φo|; a pixel's
//! value is the nearest sample's (`nearest`) or an inverse-distance blend of the 4
//! nearest (`idw`), per channel.

use crate::bsdf::Model;
use crate::data::{Dataset, Kind};
use anyhow::Result;
use glam::DVec3;
use rayon::prelude::*;
use serde::Serialize;
use std::path::Path;

/// How the tabulated baseline finds a pixel's value among the samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Lookup {
    Nearest,
    Idw,
}

impl crate::choice::Choice for Lookup {
    const WHAT: &'static str = "lookup";
    const TABLE: &'static [(Self, &'static str, &'static str)] =
        &[(Lookup::Nearest, "nearest", ""), (Lookup::Idw, "idw", "")];
}
crate::choice::named_choice!(Lookup);

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum ErrorMetric {
    /// |m − b| / (|m| + |b| + ε) per pixel, averaged over channels, in [0, 1].
    Smape,
    /// sqrt(mean over channels of (m − b)²) in displayed units (1 = white).
    Rmse,
}

impl crate::choice::Choice for ErrorMetric {
    const WHAT: &'static str = "error";
    const TABLE: &'static [(Self, &'static str, &'static str)] = &[
        (
            ErrorMetric::Smape,
            "smape",
            "|m − b| / (|m| + |b| + ε) per pixel, averaged over channels, in [0, 1]",
        ),
        (
            ErrorMetric::Rmse,
            "rmse",
            "sqrt(mean over channels of (m − b)²) in displayed units (1 = white)",
        ),
    ];
}
crate::choice::named_choice!(ErrorMetric);

#[derive(Clone, Debug, Serialize)]
pub struct RenderOptions {
    /// Image size in pixels (square).
    pub size: u32,
    /// Light direction: polar angle from the view axis and azimuth in the image plane
    /// (degrees; 135° = from the upper left).
    pub light_theta: f64,
    pub light_phi: f64,
    pub lookup: Lookup,
    pub error: ErrorMetric,
    /// Error value shown at the top of the colour scale.
    pub error_scale: f64,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            size: 192,
            light_theta: 45.0,
            light_phi: 135.0,
            lookup: Lookup::Idw,
            error: ErrorMetric::Smape,
            error_scale: 0.5,
        }
    }
}

/// A linear-radiance image: per pixel RGB, or None outside the lit sphere.
pub struct Image {
    pub size: u32,
    pub px: Vec<Option<[f64; 3]>>,
}

/// The geometry of each lit sphere pixel in the local frame: (ωi, ωo, cos θi).
fn pixel_geometry(o: &RenderOptions) -> Vec<Option<(DVec3, DVec3, f64)>> {
    let n = o.size as usize;
    let (lt, lp) = (o.light_theta.to_radians(), o.light_phi.to_radians());
    let l = DVec3::new(lt.sin() * lp.cos(), lt.sin() * lp.sin(), lt.cos()).normalize();
    let v = DVec3::Z;
    (0..n * n)
        .map(|k| {
            let (px, py) = (k % n, k / n);
            let (x, y) = disc_coords(px as u32, py as u32, n as u32);
            let r2 = x * x + y * y;
            if r2 >= 1.0 {
                return None;
            }
            let nrm = DVec3::new(x, y, (1.0 - r2).sqrt());
            let ci = nrm.dot(l);
            if ci <= 1e-4 || nrm.dot(v) <= 1e-4 {
                return None;
            }
            // Tangent frame with the light in the t–n plane, so φi = 0 (isotropic models).
            let lt_ = l - nrm * ci;
            let t = if lt_.length() > 1e-9 {
                lt_.normalize()
            } else {
                nrm.any_orthonormal_vector()
            };
            let b = nrm.cross(t);
            let to_local = |d: DVec3| DVec3::new(d.dot(t), d.dot(b), d.dot(nrm));
            Some((to_local(l), to_local(v), ci))
        })
        .collect()
}

/// Channel of the data used for each of R, G, B.
pub fn rgb_channels(channels: &[f64]) -> [usize; 3] {
    let nearest = |w: f64| {
        (0..channels.len())
            .min_by(|&a, &b| (channels[a] - w).abs().total_cmp(&(channels[b] - w).abs()))
            .unwrap_or(0)
    };
    [nearest(610.0), nearest(550.0), nearest(465.0)]
}

/// Render a fitted model (BRDF). `flat` holds the model's parameters.
pub fn render_model(model: &Model, flat: &[f64], channels: &[f64], o: &RenderOptions) -> Image {
    let map = rgb_channels(channels);
    let px = pixel_geometry(o)
        .into_par_iter()
        .map(|g| {
            g.map(|(wi, wo, ci)| {
                let mut c = [0.0; 3];
                for (k, &ch) in map.iter().enumerate() {
                    let f = model.eval(flat, ch.min(model.channels.saturating_sub(1)), wi, wo);
                    c[k] = if f.is_finite() {
                        f.max(0.0) * ci
                    } else {
                        f64::NAN
                    };
                }
                c
            })
        })
        .collect();
    Image { size: o.size, px }
}

/// A tabulated, isotropic, reciprocal BRDF from measured samples.
pub struct Tabulated {
    /// Per channel: (feature, value).
    entries: Vec<Vec<([f64; 6], f64)>>,
    channels: Vec<f64>,
}

fn feature(wi: DVec3, wo: DVec3) -> [f64; 6] {
    // Rotate about n so that ωi has φ = 0; fold φo's sign (isotropy).
    let phi = wi.y.atan2(wi.x);
    let (s, c) = phi.sin_cos();
    let rot = |d: DVec3| DVec3::new(c * d.x + s * d.y, -s * d.x + c * d.y, d.z);
    let (a, b) = (rot(wi), rot(wo));
    [a.x, a.y.abs(), a.z, b.x, b.y.abs(), b.z]
}

impl Tabulated {
    pub fn new(data: &Dataset) -> Result<Tabulated> {
        anyhow::ensure!(
            data.kind == Kind::Brdf,
            "{}: sphere renders need BRDF data",
            data.source.display()
        );
        let mut entries = vec![Vec::new(); data.channels.len()];
        for s in &data.samples {
            entries[s.channel].push((feature(s.wi(), s.wo()), s.value));
            entries[s.channel].push((feature(s.wo(), s.wi()), s.value));
        }
        Ok(Tabulated {
            entries,
            channels: data.channels.clone(),
        })
    }

    /// The tabulated BRDF at (ωi, ωo) for channel `ch`.
    pub fn lookup(&self, ch: usize, wi: DVec3, wo: DVec3, how: Lookup) -> f64 {
        let q = feature(wi, wo);
        let e = &self.entries[ch];
        let k = if how == Lookup::Nearest { 1 } else { 4 };
        let mut best: Vec<(f64, f64)> = Vec::with_capacity(k + 1);
        for (f, v) in e {
            let d: f64 = f.iter().zip(&q).map(|(a, b)| (a - b) * (a - b)).sum();
            if best.len() < k || d < best[best.len() - 1].0 {
                let pos = best.partition_point(|x| x.0 <= d);
                best.insert(pos, (d, *v));
                best.truncate(k);
            }
        }
        if best.is_empty() {
            return f64::NAN;
        }
        if best[0].0 < 1e-12 || k == 1 {
            return best[0].1;
        }
        let (mut sw, mut sv) = (0.0, 0.0);
        for (d, v) in best {
            let w = 1.0 / d;
            sw += w;
            sv += w * v;
        }
        sv / sw
    }

    pub fn render(&self, o: &RenderOptions) -> Image {
        let map = rgb_channels(&self.channels);
        let px = pixel_geometry(o)
            .into_par_iter()
            .map(|g| {
                g.map(|(wi, wo, ci)| {
                    let mut c = [0.0; 3];
                    for (k, &ch) in map.iter().enumerate() {
                        c[k] = self.lookup(ch, wi, wo, o.lookup).max(0.0) * ci;
                    }
                    c
                })
            })
            .collect();
        Image { size: o.size, px }
    }
}

/// Exposure that maps the image's 99th-percentile channel value to 0.9.
pub fn exposure(img: &Image) -> f64 {
    let mut v: Vec<f64> = img
        .px
        .iter()
        .flatten()
        .flat_map(|c| c.iter().copied())
        .filter(|x| x.is_finite())
        .collect();
    if v.is_empty() {
        return 1.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let p = v[((v.len() - 1) as f64 * 0.99) as usize];
    if p > 0.0 {
        0.9 / p
    } else {
        1.0
    }
}

fn srgb(x: f64) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let s = if x <= 0.0031308 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0).round() as u8
}

/// Is pixel (x, y) of an n × n render on the sphere's disc (lit or not)? The same pixel
/// centres as [`pixel_geometry`]: the disc is round and fills the square image.
pub fn on_disc(x: u32, y: u32, n: u32) -> bool {
    let (u, v) = disc_coords(x, y, n);
    u * u + v * v < 1.0
}

/// The sphere's radius as a fraction of half the image width (a margin shows its limb).
const DISC: f64 = 0.94;

/// Orthographic image-plane coordinates of pixel (x, y)'s centre in units of the sphere's
/// radius: x right, y up, the same scale on both axes (square pixels, round sphere).
fn disc_coords(x: u32, y: u32, n: u32) -> (f64, f64) {
    let n = n as f64;
    (
        (2.0 * (x as f64 + 0.5) / n - 1.0) / DISC,
        (1.0 - 2.0 * (y as f64 + 0.5) / n) / DISC,
    )
}

/// Background of the renders: a light grey checkerboard (8 px squares), so that the
/// sphere's dark limb and unlit side stand out against it.
pub fn background(x: u32, y: u32) -> [u8; 3] {
    if ((x / 8) + (y / 8)).is_multiple_of(2) {
        [196, 196, 196]
    } else {
        [172, 172, 172]
    }
}

/// Write a linear image as an sRGB PNG: the sphere (unlit side black, as it is: the
/// light is directional) on a grey checkerboard; NaN pixels magenta.
pub fn write_png(path: &Path, img: &Image, exposure: f64) -> Result<()> {
    let n = img.size;
    let mut buf = image::RgbImage::new(n, n);
    for (k, p) in img.px.iter().enumerate() {
        let (x, y) = ((k as u32) % n, (k as u32) / n);
        let c = match p {
            None if on_disc(x, y, n) => [0, 0, 0],
            None => background(x, y),
            Some(c) if c.iter().any(|v| !v.is_finite()) => [255, 0, 255],
            Some(c) => [
                srgb(c[0] * exposure),
                srgb(c[1] * exposure),
                srgb(c[2] * exposure),
            ],
        };
        buf.put_pixel(x, y, image::Rgb(c));
    }
    save_png(path, &buf)
}

/// Encode a PNG in memory and write it atomically (the error names `path`).
fn save_png(path: &Path, buf: &image::RgbImage) -> Result<()> {
    let mut bytes = std::io::Cursor::new(Vec::new());
    buf.write_to(&mut bytes, image::ImageFormat::Png)
        .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))?;
    crate::output::files::write_atomic(path, bytes.get_ref())
}

/// Per-pixel error between a model image and the baseline (None outside the sphere;
/// NaN where `covered` is false: the pixel's geometry lies beyond the measured angles).
pub fn error_values(
    model: &Image,
    base: &Image,
    metric: ErrorMetric,
    exposure: f64,
    covered: &[bool],
) -> Vec<Option<f64>> {
    model
        .px
        .iter()
        .zip(&base.px)
        .zip(covered)
        .map(|((m, b), &cov)| match (m, b) {
            (Some(_), Some(_)) if !cov => Some(f64::NAN),
            (Some(m), Some(b)) => Some(match metric {
                ErrorMetric::Smape => {
                    (0..3)
                        .map(|c| (m[c] - b[c]).abs() / (m[c].abs() + b[c].abs() + 1e-6))
                        .sum::<f64>()
                        / 3.0
                }
                ErrorMetric::Rmse => ((0..3)
                    .map(|c| ((m[c] - b[c]) * exposure).powi(2))
                    .sum::<f64>()
                    / 3.0)
                    .sqrt(),
            }),
            _ => None,
        })
        .collect()
}

/// Colour map (black → purple → orange → yellow, inferno-like) for t in [0, 1].
pub fn colormap(t: f64) -> [u8; 3] {
    const STOPS: [(f64, [f64; 3]); 5] = [
        (0.0, [0.0, 0.0, 4.0]),
        (0.25, [87.0, 16.0, 110.0]),
        (0.5, [188.0, 55.0, 84.0]),
        (0.75, [249.0, 142.0, 9.0]),
        (1.0, [252.0, 255.0, 164.0]),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        1.0
    };
    for w in STOPS.windows(2) {
        if t <= w[1].0 {
            let f = (t - w[0].0) / (w[1].0 - w[0].0);
            let c: Vec<u8> = (0..3)
                .map(|k| (w[0].1[k] + f * (w[1].1[k] - w[0].1[k])).round() as u8)
                .collect();
            return [c[0], c[1], c[2]];
        }
    }
    [252, 255, 164]
}

/// Which pixels see geometries within the measured range of `data` (θi and θo at most 5°
/// beyond the largest measured ones): elsewhere the tabulated baseline only extrapolates.
pub fn coverage(data: &Dataset, o: &RenderOptions) -> Vec<bool> {
    let ti = data.samples.iter().map(|s| s.theta_i).fold(0.0, f64::max) + 5f64.to_radians();
    let to = data.samples.iter().map(|s| s.theta_o).fold(0.0, f64::max) + 5f64.to_radians();
    let ok = |a: DVec3, b: DVec3| {
        let (x, y) = (a.z.clamp(-1.0, 1.0).acos(), b.z.clamp(-1.0, 1.0).acos());
        (x <= ti && y <= to) || (y <= ti && x <= to)
    };
    pixel_geometry(o)
        .into_iter()
        .map(|g| g.is_some_and(|(wi, wo, _)| ok(wi, wo)))
        .collect()
}

/// Colour of the error image where the sphere is not lit (no error is defined there).
pub const UNLIT_RGB: [u8; 3] = [40, 40, 40];
/// Colour of the error image where the geometry lies beyond the measured angles.
pub const BEYOND_RGB: [u8; 3] = [110, 128, 150];

/// Write the error image as a PNG (value / scale through [`colormap`]; a colour bar at the
/// bottom edge, 0 on the left to `scale` on the right; NaN pixels — beyond the measured
/// angles — slate blue-grey [`BEYOND_RGB`], the unlit side dark grey [`UNLIT_RGB`], the
/// background the renders' checkerboard).
pub fn write_error_png(path: &Path, err: &[Option<f64>], size: u32, scale: f64) -> Result<()> {
    let bar = (size / 16).max(6);
    let mut buf = image::RgbImage::new(size, size + bar);
    for (k, e) in err.iter().enumerate() {
        let (x, y) = ((k as u32) % size, (k as u32) / size);
        let c = match e {
            None if on_disc(x, y, size) => UNLIT_RGB,
            None => background(x, y),
            Some(v) if v.is_nan() => BEYOND_RGB,
            Some(v) => colormap(v / scale),
        };
        buf.put_pixel(x, y, image::Rgb(c));
    }
    for x in 0..size {
        let c = colormap(x as f64 / (size - 1).max(1) as f64);
        for y in size..size + bar {
            buf.put_pixel(x, y, image::Rgb(c));
        }
    }
    save_png(path, &buf)
}

/// Summary of one render, written beside the images as JSON.
#[derive(Clone, Debug, Serialize, serde::Deserialize)]
pub struct RenderStats {
    pub model: String,
    pub data: String,
    pub baseline: String,
    pub metric: String,
    /// Mean and maximum per-pixel error over the lit sphere, within the measured angles.
    pub mean_error: f64,
    pub max_error: f64,
    pub error_scale: f64,
    pub exposure: f64,
    pub pixels: usize,
    pub lookup: String,
    pub light_theta: f64,
    pub light_phi: f64,
}

/// Render baseline (if `baseline_png` is given), model and error images; return stats.
#[allow(clippy::too_many_arguments)]
pub fn render_fit(
    model: &Model,
    flat: &[f64],
    baseline: &Dataset,
    o: &RenderOptions,
    baseline_png: Option<&Path>,
    model_png: &Path,
    error_png: &Path,
    data_label: &str,
) -> Result<RenderStats> {
    let tab = Tabulated::new(baseline)?;
    anyhow::ensure!(
        model.kind == Kind::Brdf,
        "{} is not a BRDF model; sphere renders are for BRDFs",
        model.spec
    );
    let base = tab.render(o);
    let exp = exposure(&base);
    if let Some(p) = baseline_png {
        write_png(p, &base, exp)?;
    }
    let img = render_model(model, flat, &baseline.channels, o);
    write_png(model_png, &img, exp)?;
    let err = error_values(&img, &base, o.error, exp, &coverage(baseline, o));
    write_error_png(error_png, &err, o.size, o.error_scale)?;
    let vals: Vec<f64> = err
        .iter()
        .flatten()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    let mean = if vals.is_empty() {
        f64::NAN
    } else {
        vals.iter().sum::<f64>() / vals.len() as f64
    };
    Ok(RenderStats {
        model: model.spec.clone(),
        data: data_label.to_string(),
        baseline: baseline.label(),
        metric: match o.error {
            ErrorMetric::Smape => "smape".into(),
            ErrorMetric::Rmse => "rmse".into(),
        },
        mean_error: mean,
        max_error: vals.iter().cloned().fold(0.0, f64::max),
        error_scale: o.error_scale,
        exposure: exp,
        pixels: vals.len(),
        lookup: format!("{:?}", o.lookup).to_lowercase(),
        light_theta: o.light_theta,
        light_phi: o.light_phi,
    })
}
