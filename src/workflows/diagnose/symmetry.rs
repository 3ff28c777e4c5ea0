//! Anisotropy measured at one incidence azimuth: the mirror-symmetry test.
//!
//! At one incidence azimuth φi an anisotropic lobe whose frame lies on the plane of
//! incidence or across it is mirror-symmetric about that plane, as every isotropic BSDF
//! is, so the data cannot tell it from an isotropic lobe that is narrower across the plane
//! than along it (a shape the catalogue may lack: `crate::data::azimuths`). What only an
//! anisotropic surface can do there is break the mirror symmetry: a frame turned off the
//! plane. The test refits the candidate with every free frame azimuth φ0 held on the plane
//! of incidence (φ0 = φi; the frame across it is the same family with α_u and α_v
//! swapped) and asks whether turning the frame off the plane is significant:
//!
//!   F = (Δχ² / q) / (χ²₁ / (K − P₁)),  p = P(F(q, K − P₁) ≥ F),
//!
//! with Δχ² = χ²(frame on the plane) − χ²(frame free), q the number of frame azimuths
//! freed and χ²₁, K − P₁ the free fit's. As in the extensions' F test, the residual
//! variance of the richer fit scales the gain, so a misfit left by a lobe shape the
//! catalogue lacks does not make an asymmetric frame look significant. The frame counts
//! as determined when p is below the round's level (α over its candidates).

use super::{fit_model, DiagnoseOptions, FitResult};
use crate::data::Dataset;
use crate::engine::Backend;
use crate::inference::constraints::{Constraint, ConstraintKind, Constraints};
use crate::inference::stats::{f_test, format_p};
use anyhow::Result;

/// The outcome of the mirror-symmetry test of one anisotropic fit.
#[derive(Clone, Debug)]
pub struct MirrorTest {
    /// The plane of incidence, degrees in [0, 180).
    pub plane: f64,
    /// The frame azimuths freed, with their fitted values (degrees).
    pub frames: Vec<(String, f64)>,
    /// χ² of the fit with the frames held on the plane, less the free fit's.
    pub delta_chi2: f64,
    pub f: f64,
    pub p: f64,
    pub level: f64,
    pub dof: usize,
}

impl MirrorTest {
    /// The frame breaks the mirror symmetry significantly.
    pub fn broken(&self) -> bool {
        self.delta_chi2 > 0.0 && self.p < self.level
    }

    /// The test in words: "held on the plane of incidence (φ0 = 30°) the fit loses
    /// Δχ² = 2.1: F(1, 980) = 0.3, p = 0.58, need < 1.4e-3".
    pub fn describe(&self) -> String {
        let fitted: Vec<String> = self
            .frames
            .iter()
            .map(|(n, v)| format!("{n} = {v:.1}°"))
            .collect();
        format!(
            "fitted {}; held on the plane of incidence (φ0 = {:.0}°) the fit loses Δχ² = {:.1}: F({}, {}) = {:.2}, {}, need < {:.1e}",
            fitted.join(", "),
            fold(self.plane),
            self.delta_chi2,
            self.frames.len(),
            self.dof,
            self.f,
            format_p(self.p),
            self.level
        )
    }

    /// Why the candidate is not adopted when the symmetry is not broken.
    pub fn confounded_words(&self) -> String {
        format!(
            "at one incidence azimuth (φi = {:.0}°) its gain is a lobe shape across the plane of incidence against along it, which this geometry cannot tell from anisotropy: the frame does not break the mirror symmetry about the plane ({}). Measure at a second incidence azimuth to tell them apart",
            self.plane,
            self.describe()
        )
    }

    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "plane_of_incidence_deg": self.plane,
            "frames": self.frames.iter().map(|(n, v)| serde_json::json!({"name": n, "deg": v})).collect::<Vec<_>>(),
            "delta_chi2": self.delta_chi2,
            "F": self.f,
            "p": self.p,
            "level": self.level,
            "symmetry_broken": self.broken(),
        })
    }
}

/// An azimuth in degrees folded into φ0's range [−90°, 90°).
fn fold(deg: f64) -> f64 {
    (deg + 90.0).rem_euclid(180.0) - 90.0
}

/// `flat` with each lobe's α_u and α_v swapped: the same surface turned by 90°.
fn swapped(frames: &[[usize; 3]], flat: &[f64]) -> Vec<f64> {
    let mut out = flat.to_vec();
    for &[u, v, _] in frames {
        out.swap(u, v);
    }
    out
}

/// `flat` with each lobe's α_u and α_v at their geometric mean: the isotropic lobe.
fn isotropic(frames: &[[usize; 3]], flat: &[f64]) -> Vec<f64> {
    let mut out = flat.to_vec();
    for &[u, v, _] in frames {
        let g = (flat[u] * flat[v]).sqrt();
        out[u] = g;
        out[v] = g;
    }
    out
}

/// Refit `fit` (an anisotropic candidate) with its free frame azimuths held on the plane
/// of incidence `plane` (degrees), and compare. None when the options hold every frame
/// already (the user has named it).
pub(super) fn mirror_test(
    fit: &FitResult,
    data: &Dataset,
    backend: &dyn Backend,
    opts: &DiagnoseOptions,
    plane: f64,
    level: f64,
    cached: Option<&FitResult>,
) -> Result<Option<(MirrorTest, FitResult)>> {
    let model = &fit.model;
    let names = model.flat_names();
    let space = Constraints::resolve(model, &opts.constraints, true)?;
    let frames = model.frames();
    let free: Vec<usize> = frames
        .iter()
        .map(|&[_, _, phi]| phi)
        .filter(|&j| space.fixed[j].is_none())
        .collect();
    if free.is_empty() {
        return Ok(None);
    }
    let on_plane = fold(plane);
    let aligned = match cached {
        Some(f) => f.clone(),
        None => {
            let mut held = opts.clone();
            for &j in &free {
                held.constraints.items.push(Constraint::new(
                    ConstraintKind::Fix,
                    &names[j],
                    &[on_plane],
                )?);
            }
            let mut start = fit.flat.clone();
            for &j in &free {
                start[j] = on_plane;
            }
            let seeds = vec![
                start.clone(),
                swapped(&frames, &start),
                isotropic(&frames, &start),
            ];
            fit_model(model, data, backend, &held, &seeds)?
        }
    };
    let delta_chi2 = aligned.chi2 - fit.chi2;
    let (f, p) = f_test(delta_chi2, free.len(), fit.chi2, fit.dof);
    let test = MirrorTest {
        plane,
        frames: free
            .iter()
            .map(|&j| (names[j].clone(), fit.flat[j]))
            .collect(),
        delta_chi2,
        f,
        p,
        level,
        dof: fit.dof,
    };
    Ok(Some((test, aligned)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bsdf::Model;

    #[test]
    fn every_lobe_frame_is_found_and_turned() {
        let m = Model::parse("fa(lambert)+coat+aniso", 3).unwrap();
        let names = m.flat_names();
        let frames = m.frames();
        let named: Vec<[&str; 3]> = frames
            .iter()
            .map(|f| f.map(|j| names[j].as_str()))
            .collect();
        assert_eq!(
            named,
            [
                ["alpha_c_u", "alpha_c_v", "phi0_c"],
                ["lobe.alpha_u", "lobe.alpha_v", "lobe.phi0"]
            ]
        );
        let flat: Vec<f64> = (0..m.dim).map(|j| 0.01 * (j + 1) as f64).collect();
        let s = swapped(&frames, &flat);
        let iso = isotropic(&frames, &flat);
        for [u, v, phi] in frames {
            assert_eq!((s[u], s[v], s[phi]), (flat[v], flat[u], flat[phi]));
            let g = (flat[u] * flat[v]).sqrt();
            assert!((iso[u] - g).abs() < 1e-15 && (iso[v] - g).abs() < 1e-15);
        }
    }

    #[test]
    fn planes_fold_into_the_frame_range() {
        assert_eq!(fold(0.0), 0.0);
        assert_eq!(fold(30.0), 30.0);
        assert_eq!(fold(135.0), -45.0);
        assert_eq!(fold(90.0), -90.0);
    }
}
