//! `bsdfit export --format zemax`: a fit as a Zemax tabular BSDF file. The cells are the
//! model's BSDF (sr⁻¹) at the cell geometries of [`geometry`] (the reader's, so a written
//! file reads back to the model), 0 beyond the horizon; each table's TIS is the model's
//! ∫ f cos θ dω over the whole hemisphere ([`super::tis`]), not the table's sum.

use super::{nearest_channel, provenance, tis::tis, Planes};
use crate::choice::field_error;
use crate::data::readers::zemax::{self, geometry, Header, Symmetry, NOMINAL_XYZ_NM, SYMMETRIES};
use crate::data::Kind;
use crate::inference::saved::FitFile;
use anyhow::Result;
use rayon::prelude::*;
use std::path::Path;

/// The angles of a table (degrees) and its symmetry.
#[derive(Clone, Debug, PartialEq)]
pub struct ZemaxGrid {
    pub symmetry: Symmetry,
    pub rotations: Vec<f64>,
    pub incidences: Vec<f64>,
    pub azimuths: Vec<f64>,
    pub radials: Vec<f64>,
}

fn range(a: f64, b: f64, step: f64) -> Vec<f64> {
    let n = ((b - a) / step + 1e-9).floor() as usize;
    (0..=n).map(|k| a + k as f64 * step).collect()
}

impl ZemaxGrid {
    /// The usual grid: one sample rotation (0), incidences 0…80° by 10°, azimuths 0…180°
    /// by 10° (0…350° for an asymmetrical table), radial angles 0…10° by 1°, 12.5…30° by
    /// 2.5°, 35…90° by 5° and 100…180° by 10° (every scattered direction of the
    /// hemisphere, finer near the specular direction).
    pub fn usual(symmetry: Symmetry) -> ZemaxGrid {
        let mut radials = range(0.0, 10.0, 1.0);
        radials.extend(range(12.5, 30.0, 2.5));
        radials.extend(range(35.0, 90.0, 5.0));
        radials.extend(range(100.0, 180.0, 10.0));
        ZemaxGrid {
            symmetry,
            rotations: vec![0.0],
            incidences: range(0.0, 80.0, 10.0),
            azimuths: if symmetry == Symmetry::PlaneSymmetrical {
                range(0.0, 180.0, 10.0)
            } else {
                range(0.0, 350.0, 10.0)
            },
            radials,
        }
    }

    /// The grid of a Zemax file's header.
    pub fn of(h: &Header) -> ZemaxGrid {
        ZemaxGrid {
            symmetry: h.symmetry,
            rotations: h.rotations.clone(),
            incidences: h.incidences.clone(),
            azimuths: h.azimuths.clone(),
            radials: h.radials.clone(),
        }
    }

    /// The `geometry` option: a Zemax file (its grid), or `key=list;…` with keys `rotation`,
    /// `aoi`, `azimuth`, `radial`, `symmetry` (a list is numbers and `from:step:to`
    /// ranges joined by commas; a key left out keeps the usual grid's list).
    pub fn parse(spec: &str, default_symmetry: Symmetry) -> Result<ZemaxGrid> {
        let path = Path::new(spec);
        if path.is_file() {
            let f = std::fs::File::open(path)?;
            let h = zemax::read_header(std::io::BufReader::new(f), spec)?;
            return Ok(ZemaxGrid::of(&h));
        }
        if !spec.contains('=') {
            return Err(field_error(format!(
                "{{geometry}} '{spec}': neither a Zemax file nor a grid such as 'aoi=0:10:80;azimuth=0:10:180;radial=0:5:90'"
            )));
        }
        let mut symmetry = default_symmetry;
        let mut lists: [Option<Vec<f64>>; 4] = [None, None, None, None];
        for item in spec.split(';').map(str::trim).filter(|s| !s.is_empty()) {
            let (k, v) = item
                .split_once('=')
                .ok_or_else(|| field_error(format!("{{geometry}}: '{item}' is not key=list")))?;
            let k = k.trim().to_ascii_lowercase();
            if k == "symmetry" {
                let word = v.trim();
                symmetry = SYMMETRIES
                    .iter()
                    .find(|(w, _)| w.eq_ignore_ascii_case(word))
                    .map(|(_, s)| *s)
                    .ok_or_else(|| {
                        field_error(format!(
                            "{{geometry}}: symmetry '{}' is not PlaneSymmetrical, Asymmetrical or Asymmetrical4D",
                            word.to_ascii_lowercase()
                        ))
                    })?;
                continue;
            }
            let slot = match k.as_str() {
                "rotation" | "rotations" | "samplerotation" => 0,
                "aoi" | "incidence" | "angleofincidence" => 1,
                "azimuth" | "scatterazimuth" => 2,
                "radial" | "scatterradial" => 3,
                _ => {
                    return Err(field_error(format!(
                        "{{geometry}}: unknown key '{k}' (rotation, aoi, azimuth, radial, symmetry)"
                    )))
                }
            };
            lists[slot] =
                Some(parse_list(v).map_err(|e| field_error(format!("{{geometry}} {k}: {e}")))?);
        }
        let usual = ZemaxGrid::usual(symmetry);
        let [r, i, a, d] = lists;
        let g = ZemaxGrid {
            symmetry,
            rotations: r.unwrap_or(usual.rotations),
            incidences: i.unwrap_or(usual.incidences),
            azimuths: a.unwrap_or(usual.azimuths),
            radials: d.unwrap_or(usual.radials),
        };
        g.check()?;
        Ok(g)
    }

    /// The same grid as an asymmetrical table: a plane-symmetric half (azimuths 0–180°)
    /// mirrored to the whole circle (a and 360° − a), for a per-plane fit.
    pub fn asymmetrical(&self) -> ZemaxGrid {
        if self.symmetry != Symmetry::PlaneSymmetrical {
            return self.clone();
        }
        let mut az: Vec<f64> = self.azimuths.clone();
        az.extend(
            self.azimuths
                .iter()
                .filter(|a| **a > 0.0 && **a < 180.0)
                .map(|a| 360.0 - a),
        );
        az.sort_by(f64::total_cmp);
        az.dedup();
        ZemaxGrid {
            symmetry: Symmetry::Asymmetrical,
            azimuths: az,
            ..self.clone()
        }
    }

    /// The ranges and combinations the reader accepts.
    fn check(&self) -> Result<()> {
        let require = |ok: bool, template: String| {
            if ok {
                Ok(())
            } else {
                Err(field_error(template))
            }
        };
        require(
            self.incidences.iter().all(|a| (0.0..=90.0).contains(a)),
            "{geometry}: incidences must be in [0, 90]°".into(),
        )?;
        require(
            self.radials.iter().all(|r| (0.0..=180.0).contains(r)),
            "{geometry}: radial angles must be in [0, 180]°".into(),
        )?;
        require(
            self.rotations.len() == 1 || self.symmetry == Symmetry::Asymmetrical4D,
            "{geometry}: several sample rotations need symmetry=Asymmetrical4D".into(),
        )?;
        require(
            self.symmetry != Symmetry::PlaneSymmetrical
                || self.azimuths.iter().all(|a| (0.0..=180.0).contains(a)),
            "{geometry}: a PlaneSymmetrical table has azimuths in [0, 180]°".into(),
        )?;
        for (name, v) in [
            ("rotation", &self.rotations),
            ("aoi", &self.incidences),
            ("azimuth", &self.azimuths),
            ("radial", &self.radials),
        ] {
            require(
                !v.is_empty() && v.len() <= zemax::MAX_ANGLES,
                format!(
                    "{{geometry}}: {name} needs 1 to {} angles",
                    zemax::MAX_ANGLES
                ),
            )?;
        }
        Ok(())
    }
}

/// `1,2,5:5:30`: numbers and inclusive `from:step:to` ranges.
fn parse_list(v: &str) -> Result<Vec<f64>> {
    let mut out = Vec::new();
    for part in v.split(',').map(str::trim) {
        let nums: Vec<f64> = part
            .split(':')
            .map(|x| {
                x.trim()
                    .parse::<f64>()
                    .map_err(|_| anyhow::anyhow!("'{part}' is not a number or from:step:to"))
            })
            .collect::<Result<_>>()?;
        match nums[..] {
            [x] if x.is_finite() => out.push(x),
            [a, s, b] if a.is_finite() && b.is_finite() && s > 0.0 && (b - a) / s < 1e5 => {
                out.extend(range(a, b, s))
            }
            _ => anyhow::bail!("'{part}' is not a number or from:step:to (step > 0)"),
        }
    }
    Ok(out)
}

/// Which channels become which table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Spectrum {
    /// One channel, as `Monochrome` (its wavelength in a `# wavelength_nm:` comment).
    Mono(usize),
    /// Channels X, Y, Z (at the reader's nominal wavelengths) as `XYZ`.
    Xyz([usize; 3]),
}

/// A one-channel fit is Monochrome; a fit whose three channels are the nominal X, Y, Z
/// wavelengths (a file read as XYZ) is XYZ; otherwise `--channel NM` picks one.
pub fn spectrum(channels: &[f64], channel: Option<f64>) -> Result<Spectrum> {
    if let Some(nm) = channel {
        return Ok(Spectrum::Mono(nearest_channel(channels, nm, "--channel")?));
    }
    let xyz = NOMINAL_XYZ_NM.map(|w| channels.iter().position(|c| *c == w));
    match (channels.len(), xyz) {
        (1, _) => Ok(Spectrum::Mono(0)),
        (3, [Some(x), Some(y), Some(z)]) => Ok(Spectrum::Xyz([x, y, z])),
        (n, _) => anyhow::bail!(
            "the fit has {n} channels ({channels:?} nm): a Zemax file holds one (Monochrome) or X, Y, Z; pick one with --channel NM"
        ),
    }
}

/// What a written file holds, for the closing message.
pub struct Written {
    pub text: String,
    pub tables: usize,
    pub cells: usize,
    pub symmetry: Symmetry,
}

/// The Zemax file of `file` on `grid`.
pub fn zemax_file(
    file: &FitFile,
    fit_path: &str,
    grid: &ZemaxGrid,
    spectrum: Spectrum,
) -> Result<Written> {
    let planes = Planes::new(file);
    anyhow::ensure!(
        !planes.per_plane() || grid.symmetry != Symmetry::PlaneSymmetrical,
        "a per-plane fit (planes {:?}°) is not symmetric about the plane of incidence: it is written as an asymmetrical table; give --geometry with symmetry=Asymmetrical and azimuths over 0–360°",
        planes.planes()
    );
    grid.check()?;
    let mut t = String::new();
    for l in provenance(&planes, fit_path) {
        t += &format!("# {l}\n");
    }
    t += "# cells: the model's BSDF (sr^-1) at each cell (0 beyond the horizon); TIS: the model's integral of f cos(theta) over the hemisphere (docs/data-formats.md)\n";
    let (sections, spectral): (Vec<(&str, usize)>, &str) = match spectrum {
        Spectrum::Mono(c) => {
            t += &format!("# wavelength_nm: {}\n", planes.channels[c]);
            (vec![("Monochrome", c)], "Monochrome")
        }
        Spectrum::Xyz(c) => (
            vec![
                ("TristimulusX", c[0]),
                ("TristimulusY", c[1]),
                ("TristimulusZ", c[2]),
            ],
            "XYZ",
        ),
    };
    let list = |v: &[f64]| {
        v.iter()
            .map(|x| x.to_string())
            .collect::<Vec<_>>()
            .join("\t")
    };
    t += "Source\tMeasured\n";
    t += &format!("Symmetry\t{}\n", grid.symmetry.name());
    t += &format!("SpectralContent\t{spectral}\n");
    t += &format!(
        "ScatterType\t{}\n",
        if planes.kind == Kind::Btdf {
            "BTDF"
        } else {
            "BRDF"
        }
    );
    for (name, v) in [
        ("SampleRotation", &grid.rotations),
        ("AngleOfIncidence", &grid.incidences),
        ("ScatterAzimuth", &grid.azimuths),
        ("ScatterRadial", &grid.radials),
    ] {
        t += &format!("{name}\t{}\n{}\n", v.len(), list(v));
    }
    t += "\n";
    for (name, c) in &sections {
        t += &format!("{name}\nDataBegin\n");
        for rot in &grid.rotations {
            for aoi in &grid.incidences {
                t += &table(&planes, *c, *rot, *aoi, grid);
            }
        }
        t += "DataEnd\n";
    }
    let tables = sections.len() * grid.rotations.len() * grid.incidences.len();
    Ok(Written {
        text: t,
        tables,
        cells: tables * grid.azimuths.len() * grid.radials.len(),
        symmetry: grid.symmetry,
    })
}

/// One table: its TIS line and one row per azimuth.
fn table(planes: &Planes, ch: usize, rotation: f64, aoi: f64, grid: &ZemaxGrid) -> String {
    let transmitted = planes.kind == Kind::Btdf;
    let phi_i = geometry::incident_azimuth(rotation);
    let f = |wi, wo, phi_o| planes.value(ch, wi, wo, phi_o);
    let total = tis(aoi, phi_i, transmitted, &f);
    let rows: Vec<String> = grid
        .azimuths
        .par_iter()
        .map(|&a| {
            let cells: Vec<String> = grid
                .radials
                .iter()
                .map(|&r| {
                    let g = geometry::cell_geometry(rotation, aoi, a, r);
                    if g.cos_o <= geometry::HORIZON_COS {
                        return format!("{:.9E}", 0.0);
                    }
                    let wi = crate::math::direction(g.theta_i.to_radians(), g.phi_i.to_radians());
                    let mut wo =
                        crate::math::direction(g.theta_o.to_radians(), g.phi_o.to_radians());
                    if transmitted {
                        wo.z = -wo.z;
                    }
                    format!("{:.9E}", planes.value(ch, wi, wo, g.phi_o))
                })
                .collect();
            cells.join("\t")
        })
        .collect();
    format!("TIS\t{total:.9}\n{}\n", rows.join("\n"))
}
