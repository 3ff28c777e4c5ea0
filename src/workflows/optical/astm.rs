//! `bsdfit export --format astm`: a fit as ASTM E1392 text. One row per geometry, the
//! model's BSDF (sr⁻¹) at every channel of the fit (a column per wavelength, `550nm`), then
//! the propagated standard uncertainty of each (k = 1, `u_550nm`) as extra columns after
//! all the values, which readers that do not know them can ignore. Angles in radians (the
//! unit of the format's public data sets) declared by `ANGLE_UNITS RAD`; a BTDF's
//! scattered directions have θs = 180° − θt (polar angles from the normal on the
//! illuminated side).

use super::provenance;
use super::Planes;
use crate::data::{geometry_key, Kind, ReadOptions};
use crate::inference::saved::FitFile;
use crate::workflows::export;
use anyhow::Result;
use std::collections::HashMap;
use std::path::Path;

/// The usual geometry: θi 0…75° by 15° at φi = 0; θo (θt) 0…85° by 5° and φo 0…345° by
/// 15° (on the fit's planes only, φ and φ + 180°, for a per-plane fit; the normal row once
/// per plane at its azimuth).
pub fn usual_rows(planes: Option<&[f64]>) -> Vec<[f64; 4]> {
    let phis: Vec<f64> = match planes {
        Some(p) => p.iter().flat_map(|&a| [a, a + 180.0]).collect(),
        None => (0..24).map(|k| 15.0 * k as f64).collect(),
    };
    let mut rows = Vec::new();
    for ti in (0..6).map(|k| 15.0 * k as f64) {
        match planes {
            Some(p) => rows.extend(p.iter().map(|&a| [ti, 0.0, 0.0, a])),
            None => rows.push([ti, 0.0, 0.0, 0.0]),
        }
        for to in (1..18).map(|k| 5.0 * k as f64) {
            rows.extend(phis.iter().map(|&po| [ti, 0.0, to, po]));
        }
    }
    rows
}

/// The distinct geometries (θi, φi, θo, φo in degrees) of a data file, in file order.
pub fn file_rows(path: &Path) -> Result<(Kind, Vec<[f64; 4]>)> {
    let opts = ReadOptions {
        assume_uncertainty: Some((0.0, 1.0)),
        allow_zero_uncertainty: true,
        ..Default::default()
    };
    let ds = crate::data::readers::load(path, &opts)?;
    let mut seen = std::collections::HashSet::new();
    let mut rows = Vec::new();
    for s in &ds.samples {
        let r = [s.theta_i, s.phi_i, s.theta_o, s.phi_o].map(f64::to_degrees);
        if seen.insert(geometry_key(r[0], r[1], r[2], r[3], 0.0)) {
            rows.push(r);
        }
    }
    Ok((ds.kind, rows))
}

/// The ASTM E1392 text of `file` at `rows` (degrees, bsdfit's convention); `what` says
/// where the rows came from.
pub fn astm_file(
    file: &FitFile,
    fit_path: &str,
    rows: &[[f64; 4]],
    what: &str,
) -> Result<(String, Vec<String>)> {
    let planes = Planes::new(file);
    let channels = planes.channels.clone();
    let rows: Vec<[f64; 4]> = rows
        .iter()
        .map(|r| {
            let (ti, pi) = crate::data::normalise_angles(r[0], r[1]);
            let (to, po) = crate::data::normalise_angles(r[2], r[3]);
            [ti, pi, to, po]
        })
        .collect();
    let ds = export::geometry_dataset(planes.kind, &rows, &channels, what)?;
    let p = export::predict(file, fit_path, &ds, what)?;
    let mut at: HashMap<[i64; 5], (f64, f64)> = HashMap::new();
    for s in &p.data.samples {
        let g = [s.theta_i, s.phi_i, s.theta_o, s.phi_o].map(f64::to_degrees);
        at.insert(
            geometry_key(g[0], g[1], g[2], g[3], s.wavelength_nm),
            (s.value, s.uncertainty),
        );
    }
    let f = planes.first();
    let mut t = String::new();
    t += &format!("SOURCE bsdfit {}\n", env!("CARGO_PKG_VERSION"));
    t += &format!(
        "SAMPLE_NAME \"{}\"\n",
        if f.material.is_empty() {
            "unnamed".into()
        } else {
            f.material.replace(['"', '\n', '\r'], "'")
        }
    );
    t += &format!(
        "MEAS_NAME model values of a bsdfit fit at {}\n",
        what.replace(['\n', '\r'], " ")
    );
    for (k, l) in provenance(&planes, fit_path).iter().enumerate() {
        t += &format!("NOTE_{} {l}\n", k + 1);
    }
    t += "UNCERTAINTY columns u_<wavelength>nm: the model's standard uncertainty (k = 1, sr^-1) propagated from the fit's covariance\n";
    t += &format!(
        "DATA_KIND {}\n",
        if planes.kind == Kind::Btdf {
            "BTDF"
        } else {
            "BRDF"
        }
    );
    t += "ANGLE_UNITS RAD\n";
    t += &format!("NUM_POINTS {}\n", rows.len());
    let names: Vec<String> = channels.iter().map(|w| format!("{w}nm")).collect();
    t += &format!(
        "VARS theta_i,phi_i,theta_s,phi_s,{},{}\n",
        names.join(","),
        names
            .iter()
            .map(|n| format!("u_{n}"))
            .collect::<Vec<_>>()
            .join(",")
    );
    for r in &rows {
        let theta_s = if planes.kind == Kind::Btdf {
            180.0 - r[2]
        } else {
            r[2]
        };
        let mut cells: Vec<String> = [r[0], r[1], theta_s, r[3]]
            .iter()
            .map(|a| a.to_radians().to_string())
            .collect();
        let vu: Vec<(f64, f64)> = channels
            .iter()
            .map(|&w| {
                at.get(&geometry_key(r[0], r[1], r[2], r[3], w))
                    .copied()
                    .ok_or_else(|| {
                        anyhow::anyhow!(
                            "{what}: no model value at θi = {}°, θo = {}°, φo = {}° ({w} nm)",
                            r[0],
                            r[2],
                            r[3]
                        )
                    })
            })
            .collect::<Result<_>>()?;
        cells.extend(vu.iter().map(|(v, _)| format!("{v:.9e}")));
        cells.extend(vu.iter().map(|(_, u)| format!("{u:.6e}")));
        t += &cells.join(",");
        t += "\n";
    }
    Ok((t, p.warnings))
}
