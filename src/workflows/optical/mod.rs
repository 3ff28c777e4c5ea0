//! A fit out to optical design software (docs/export.md, docs/data-formats.md): the
//! Zemax tabular BSDF ([`zemax`], read by OpticStudio and other optical design programs)
//! and ASTM E1392 text ([`astm`]), for BRDF and BTDF fits alike, with the TIS of every
//! table integrated from the model ([`tis`]).

pub mod astm;
pub mod tis;
pub mod zemax;

use crate::data::Kind;
use crate::inference::saved::{FitFile, SavedFit};
use glam::DVec3;

/// The model(s) of a fit file as functions of (channel, ωi, ωo, φo): one isotropic fit, or
/// one per measurement plane (`+peraxis`, or `fit --per-axis`).
pub struct Planes<'a> {
    /// (plane φ in [0°, 180°), the fit, the scalar view of each channel), by plane.
    entries: Vec<(f64, &'a SavedFit, Vec<Vec<f64>>)>,
    pub kind: Kind,
    pub channels: Vec<f64>,
}

impl<'a> Planes<'a> {
    pub fn new(file: &'a FitFile) -> Planes<'a> {
        let mut entries = Vec::new();
        match file {
            FitFile::Single(f) => {
                let m = &f.model;
                let axes = if m.axes.len() > 1 {
                    m.axes.clone()
                } else {
                    vec![0.0]
                };
                for (k, &phi) in axes.iter().enumerate() {
                    let views = (0..m.channels)
                        .map(|c| m.scalars(&f.flat, k * m.channels + c))
                        .collect();
                    entries.push((phi.rem_euclid(180.0), f.as_ref(), views));
                }
            }
            FitFile::PerAxis(v) => {
                for (phi, f) in v {
                    let views = (0..f.model.channels)
                        .map(|c| f.model.scalars(&f.flat, c))
                        .collect();
                    entries.push((phi.rem_euclid(180.0), f, views));
                }
            }
        }
        entries.sort_by(|a, b| a.0.total_cmp(&b.0));
        let first = entries[0].1;
        Planes {
            kind: first.model.kind,
            channels: first.channels.clone(),
            entries,
        }
    }

    /// Whether the fit has parameters of its own per plane.
    pub fn per_plane(&self) -> bool {
        self.entries.len() > 1
    }

    /// The planes (degrees in [0, 180)).
    pub fn planes(&self) -> Vec<f64> {
        self.entries.iter().map(|e| e.0).collect()
    }

    /// The first fit (for its model, material and warnings).
    pub fn first(&self) -> &SavedFit {
        self.entries[0].1
    }

    /// The model at channel `ch` for (ωi, ωo), ωo at azimuth `phi_o` (degrees). A per-plane
    /// fit is its plane's model on a plane (φo ≡ plane mod 180°); between two planes p₁ <
    /// p₂ (cyclically, mod 180°) it is the blend (1 − w) f₁ + w f₂ with w = sin²(π/2 · t),
    /// t = (φo − p₁)/(p₂ − p₁): for two perpendicular planes f = cos²Δφ f₁ + sin²Δφ f₂.
    pub fn value(&self, ch: usize, wi: DVec3, wo: DVec3, phi_o: f64) -> f64 {
        let eval = |k: usize| {
            let (_, f, views) = &self.entries[k];
            f.model.root.eval(&views[ch], wi, wo)
        };
        if !self.per_plane() {
            return eval(0);
        }
        let (k1, k2, w) = self.blend(phi_o);
        if w == 0.0 {
            eval(k1)
        } else {
            (1.0 - w) * eval(k1) + w * eval(k2)
        }
    }

    /// The neighbouring planes of azimuth `phi` and the weight of the second.
    fn blend(&self, phi: f64) -> (usize, usize, f64) {
        let n = self.entries.len();
        let p = phi.rem_euclid(180.0);
        let k1 = self
            .entries
            .iter()
            .rposition(|e| e.0 <= p + 1e-9)
            .unwrap_or(n - 1);
        let k2 = (k1 + 1) % n;
        let (p1, p2) = (self.entries[k1].0, self.entries[k2].0);
        let span = (p2 - p1).rem_euclid(180.0);
        let span = if span == 0.0 { 180.0 } else { span };
        let t = ((p - p1).rem_euclid(180.0) / span).clamp(0.0, 1.0);
        let t = if t < 1e-9 { 0.0 } else { t };
        (k1, k2, (std::f64::consts::FRAC_PI_2 * t).sin().powi(2))
    }
}

/// The channel of `channels` nearest `nm` (within the usual gap), or why not.
pub fn nearest_channel(channels: &[f64], nm: f64, option: &str) -> anyhow::Result<usize> {
    let (i, d) = channels
        .iter()
        .enumerate()
        .map(|(i, c)| (i, (c - nm).abs()))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .expect("a fit has channels");
    anyhow::ensure!(
        d <= crate::data::MAX_WAVELENGTH_GAP_NM,
        "{option} {nm}: no channel of the fit within {} nm (channels: {:?} nm)",
        crate::data::MAX_WAVELENGTH_GAP_NM,
        channels
    );
    Ok(i)
}

/// Header comment lines common to both formats: where the numbers come from.
pub fn provenance(planes: &Planes, fit_path: &str) -> Vec<String> {
    let f = planes.first();
    let mut l = vec![format!(
        "bsdfit {}: model values of the fit {fit_path} ({} to {})",
        env!("CARGO_PKG_VERSION"),
        f.model.spec,
        if f.material.is_empty() {
            "unnamed data"
        } else {
            &f.material
        }
    )];
    for (phi, fit, _) in &planes.entries {
        let which = if planes.per_plane() {
            format!(" (plane {phi}°)")
        } else {
            String::new()
        };
        l.push(format!("parameters{which}: {}", fit.params_text()));
    }
    if planes.per_plane() {
        l.push(format!(
            "a per-plane fit (planes {:?}°): on a plane its own model; between planes p1 < p2 the blend (1 - w) f1 + w f2, w = sin²(90° (phi - p1)/(p2 - p1))",
            planes.planes()
        ));
    }
    for w in &f.warnings {
        l.push(format!("the fit says: {w}"));
    }
    l.into_iter()
        .map(|s| s.replace(['\n', '\r'], " "))
        .collect()
}
