//! Goniometric datasets: the v1 CSV format of DESIGN §2, validation, channel selection.
//!
//! Every failure is a [`DataError`] naming the file and line; nothing here panics on
//! user input.

use crate::math::direction;
use glam::DVec3;
use std::collections::{BTreeMap, HashMap};
use std::fmt;
use std::path::{Path, PathBuf};

/// Whether the dataset holds reflectance (BRDF) or transmittance (BTDF) samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    Brdf,
    Btdf,
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Kind::Brdf => "brdf",
            Kind::Btdf => "btdf",
        })
    }
}

impl std::str::FromStr for Kind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "brdf" => Ok(Kind::Brdf),
            "btdf" => Ok(Kind::Btdf),
            other => Err(format!("unknown kind '{other}' (expected brdf or btdf)")),
        }
    }
}

/// One measurement: geometry (normalised so θ ≥ 0), value and standard uncertainty.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    /// Incident polar angle θi in radians, in [0, π/2].
    pub theta_i: f64,
    pub phi_i: f64,
    /// Outgoing polar angle in radians: θo for a BRDF, θt (from −n) for a BTDF.
    pub theta_o: f64,
    pub phi_o: f64,
    pub wavelength_nm: f64,
    /// Measured BRDF/BTDF value, sr⁻¹.
    pub value: f64,
    /// Standard uncertainty (k = 1), sr⁻¹, > 0.
    pub uncertainty: f64,
    /// Index into [`Dataset::channels`].
    pub channel: usize,
    /// Index into [`Dataset::axes`]: the φ plane of the outgoing direction (a sample at
    /// θo = 0 lies on every plane and is given plane 0).
    pub axis: usize,
    /// Incident direction, pointing away from the surface (upper hemisphere).
    pub wi: DVec3,
    /// Outgoing direction: upper hemisphere for a BRDF, lower for a BTDF.
    pub wo: DVec3,
    /// 1-based line in the source file (0 for synthetic data never written).
    pub line: usize,
}

/// A dataset in memory: metadata, channels (distinct wavelengths) and samples.
#[derive(Clone, Debug)]
pub struct Dataset {
    pub kind: Kind,
    /// Free-text material name (`# material:`), or the file stem.
    pub material: String,
    /// Every `# key: value` line, unknown keys included.
    pub meta: BTreeMap<String, String>,
    /// Wavelengths in nm, one per channel, in channel order.
    pub channels: Vec<f64>,
    pub samples: Vec<Sample>,
    /// Measurement planes: distinct φo mod 180° (degrees) of the samples with θo > 0,
    /// ascending; `[0.0]` when there is none. Anisotropic diffusers are measured on two.
    pub axes: Vec<f64>,
    /// Where the data came from (for messages); empty for in-memory data.
    pub source: PathBuf,
    /// Human-readable notices produced while reading (e.g. uncertainty floors applied).
    pub notices: Vec<String>,
}

/// Problems reading or validating a dataset.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    #[error("{file}: {msg}")]
    File { file: String, msg: String },
    #[error("{file}:{line}: {msg}")]
    Line {
        file: String,
        line: usize,
        msg: String,
    },
}

/// Options that relax or shape reading.
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// Accept zero uncertainties by replacing them with a floor (and saying so).
    pub allow_zero_uncertainty: bool,
    /// Keep only the channels nearest to these wavelengths (nm), in this order.
    pub wavelengths: Option<Vec<f64>>,
}

pub const COLUMNS: [&str; 7] = [
    "theta_i",
    "phi_i",
    "theta_o",
    "phi_o",
    "wavelength_nm",
    "value",
    "uncertainty",
];

/// Relative uncertainty floor used with `--allow-zero-uncertainty`.
pub const UNCERTAINTY_FLOOR_REL: f64 = 0.01;
/// Absolute uncertainty floor (sr⁻¹) used with `--allow-zero-uncertainty`.
pub const UNCERTAINTY_FLOOR_ABS: f64 = 1e-6;

/// One raw row as written in a file: signed angles in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RawRow {
    pub theta_i: f64,
    pub phi_i: f64,
    pub theta_o: f64,
    pub phi_o: f64,
    pub wavelength_nm: f64,
    pub value: f64,
    pub uncertainty: f64,
}

/// Signed-angle convention (DESIGN §1): a negative θ is the same angle at φ + 180°.
/// Returns (θ, φ) in degrees with θ ≥ 0 and φ in [0, 360).
pub fn normalise_angles(theta: f64, phi: f64) -> (f64, f64) {
    let (t, p) = if theta < 0.0 {
        (-theta, phi + 180.0)
    } else {
        (theta, phi)
    };
    let p = p.rem_euclid(360.0);
    // Azimuth is meaningless at the pole; fold it so duplicates are detected.
    if t == 0.0 {
        (0.0, 0.0)
    } else {
        (t, p)
    }
}

impl Dataset {
    /// Build from raw rows (degrees, signed angles allowed), validating as a file would be.
    pub fn from_rows(
        kind: Kind,
        material: &str,
        rows: &[(usize, RawRow)],
        file: &str,
        opts: &ReadOptions,
    ) -> Result<Dataset, DataError> {
        let mut notices = Vec::new();
        let line_err = |line: usize, msg: String| DataError::Line {
            file: file.to_string(),
            line,
            msg,
        };
        if rows.is_empty() {
            return Err(DataError::File {
                file: file.to_string(),
                msg: "no data rows".into(),
            });
        }
        let mut seen: HashMap<[u64; 5], usize> = HashMap::new();
        let mut floored = 0usize;
        let mut tmp = Vec::with_capacity(rows.len());
        for &(line, r) in rows {
            for (name, v) in [
                ("theta_i", r.theta_i),
                ("phi_i", r.phi_i),
                ("theta_o", r.theta_o),
                ("phi_o", r.phi_o),
                ("wavelength_nm", r.wavelength_nm),
                ("value", r.value),
                ("uncertainty", r.uncertainty),
            ] {
                if !v.is_finite() {
                    return Err(line_err(
                        line,
                        format!("column {name} is not a finite number ({v})"),
                    ));
                }
            }
            for (name, v) in [("theta_i", r.theta_i), ("theta_o", r.theta_o)] {
                if !(-90.0..=90.0).contains(&v) {
                    return Err(line_err(
                        line,
                        format!("{name} = {v}° is outside [-90, 90]"),
                    ));
                }
            }
            if r.wavelength_nm <= 0.0 {
                return Err(line_err(
                    line,
                    format!("wavelength_nm = {} must be positive", r.wavelength_nm),
                ));
            }
            let mut u = r.uncertainty;
            if u < 0.0 {
                return Err(line_err(line, format!("uncertainty = {u} is negative")));
            }
            if u == 0.0 {
                if !opts.allow_zero_uncertainty {
                    return Err(line_err(
                        line,
                        "uncertainty is zero (pass --allow-zero-uncertainty to use a floor)".into(),
                    ));
                }
                u = (UNCERTAINTY_FLOOR_REL * r.value.abs()).max(UNCERTAINTY_FLOOR_ABS);
                floored += 1;
            }
            if r.value < -3.0 * u {
                return Err(line_err(
                    line,
                    format!(
                        "value = {} is negative beyond 3 uncertainties ({u})",
                        r.value
                    ),
                ));
            }
            let (ti, pi) = normalise_angles(r.theta_i, r.phi_i);
            let (to, po) = normalise_angles(r.theta_o, r.phi_o);
            let key = [ti, pi, to, po, r.wavelength_nm].map(|x| (x * 1e6).round() as i64 as u64);
            if let Some(first) = seen.insert(key, line) {
                return Err(line_err(
                    line,
                    format!("duplicate of line {first} (same geometry and wavelength)"),
                ));
            }
            tmp.push((line, ti, pi, to, po, r.wavelength_nm, r.value, u));
        }
        if floored > 0 {
            notices.push(format!(
                "{file}: {floored} zero uncertainties replaced by max({}·|value|, {} sr⁻¹)",
                UNCERTAINTY_FLOOR_REL, UNCERTAINTY_FLOOR_ABS
            ));
        }
        // Channels: distinct wavelengths, optionally narrowed to the requested ones.
        let mut present: Vec<f64> = tmp.iter().map(|t| t.5).collect();
        present.sort_by(|a, b| a.total_cmp(b));
        present.dedup();
        let channels = match &opts.wavelengths {
            None => present.clone(),
            Some(wanted) => {
                if wanted.is_empty() {
                    return Err(DataError::File {
                        file: file.into(),
                        msg: "--wavelengths selects no channel".into(),
                    });
                }
                let mut chosen = Vec::new();
                for &w in wanted {
                    let nearest = *present
                        .iter()
                        .min_by(|a, b| (*a - w).abs().total_cmp(&(*b - w).abs()))
                        .expect("present is non-empty");
                    if chosen.contains(&nearest) {
                        return Err(DataError::File {
                            file: file.into(),
                            msg: format!(
                                "--wavelengths: {w} nm maps to {nearest} nm, already selected (present: {present:?})"
                            ),
                        });
                    }
                    if nearest != w {
                        notices.push(format!(
                            "{file}: wavelength {w} nm → nearest present {nearest} nm"
                        ));
                    }
                    chosen.push(nearest);
                }
                chosen
            }
        };
        let axes = measurement_planes(tmp.iter().map(|t| (t.3, t.4)));
        let mut samples = Vec::new();
        for (line, ti, pi, to, po, wl, value, u) in tmp {
            let axis = plane_index(&axes, to, po);
            let Some(channel) = channels.iter().position(|&c| c == wl) else {
                continue;
            };
            let (ti, pi, to, po) = (
                ti.to_radians(),
                pi.to_radians(),
                to.to_radians(),
                po.to_radians(),
            );
            let wi = direction(ti, pi);
            let mut wo = direction(to, po);
            if kind == Kind::Btdf {
                wo.z = -wo.z; // θt is measured from −n (DESIGN §1)
            }
            samples.push(Sample {
                theta_i: ti,
                phi_i: pi,
                theta_o: to,
                phi_o: po,
                wavelength_nm: wl,
                value,
                uncertainty: u,
                channel,
                axis,
                wi,
                wo,
                line,
            });
        }
        if samples.is_empty() {
            return Err(DataError::File {
                file: file.into(),
                msg: "the selection leaves no sample".into(),
            });
        }
        Ok(Dataset {
            kind,
            material: material.to_string(),
            meta: BTreeMap::new(),
            channels,
            samples,
            axes,
            source: PathBuf::from(file),
            notices,
        })
    }

    /// Read a v1 CSV file.
    pub fn read(path: &Path, opts: &ReadOptions) -> Result<Dataset, DataError> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|e| DataError::File {
            file: file.clone(),
            msg: format!("cannot read: {e}"),
        })?;
        Self::parse(&text, &file, opts)
    }

    /// Parse v1 CSV text; `file` names the source in messages.
    pub fn parse(text: &str, file: &str, opts: &ReadOptions) -> Result<Dataset, DataError> {
        let mut meta = BTreeMap::new();
        let mut header_line = None;
        let mut offset = 0usize; // byte offset of the header line
                                 // split_inclusive keeps each line's terminator in its length, so the offset is
                                 // right for CRLF files too.
        for (idx, line) in text.split_inclusive('\n').enumerate() {
            let t = line.trim();
            if t.is_empty() {
                offset += line.len();
                continue;
            }
            if let Some(rest) = t.strip_prefix('#') {
                if let Some((k, v)) = rest.split_once(':') {
                    let key = k.trim().to_string();
                    // "# bsdfit dataset v1" has no colon; a free-text remark after the value is kept.
                    meta.insert(key, v.trim().to_string());
                }
                offset += line.len();
                continue;
            }
            header_line = Some(idx + 1);
            break;
        }
        let Some(header_line) = header_line else {
            return Err(DataError::File {
                file: file.into(),
                msg: "no header line (expected: theta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty)".into(),
            });
        };
        let kind: Kind = match meta.get("kind") {
            None => {
                return Err(DataError::File {
                    file: file.into(),
                    msg: "missing '# kind: brdf|btdf' metadata line".into(),
                })
            }
            Some(k) => k.parse().map_err(|e: String| DataError::File {
                file: file.into(),
                msg: e,
            })?,
        };
        let body = &text[offset.min(text.len())..];
        // File line of each record. csv's own positions point at the first comment or empty
        // line skipped before a record, and lag by one line in CRLF files, so count the lines
        // csv reads as records ourselves (v1 has no multi-line quoted cells).
        let record_lines: Vec<usize> = body
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
            .map(|(i, _)| i + header_line)
            .skip(1) // the header
            .collect();
        let record_line = |k: usize| record_lines.get(k).copied().unwrap_or(header_line);
        let mut rdr = csv::ReaderBuilder::new()
            .has_headers(true)
            .flexible(true)
            .comment(Some(b'#'))
            .trim(csv::Trim::All)
            .from_reader(body.as_bytes());
        let headers = rdr
            .headers()
            .map_err(|e| DataError::Line {
                file: file.into(),
                line: header_line,
                msg: format!("cannot read header: {e}"),
            })?
            .clone();
        let names: Vec<&str> = headers.iter().collect();
        let mut index = [0usize; 7];
        for (k, col) in COLUMNS.iter().enumerate() {
            match names.iter().position(|n| n == col) {
                Some(p) => index[k] = p,
                None => {
                    return Err(DataError::Line {
                        file: file.into(),
                        line: header_line,
                        msg: format!("missing column '{col}' (header: {})", names.join(",")),
                    })
                }
            }
        }
        if let Some(extra) = names.iter().find(|n| !COLUMNS.contains(n)) {
            return Err(DataError::Line {
                file: file.into(),
                line: header_line,
                msg: format!("unexpected column '{extra}'"),
            });
        }
        let mut rows = Vec::new();
        for rec in rdr.records() {
            let rec = rec.map_err(|e| DataError::Line {
                file: file.into(),
                line: record_line(rows.len()),
                msg: format!("malformed CSV: {e}"),
            })?;
            let line = record_line(rows.len());
            if rec.len() != 7 {
                return Err(DataError::Line {
                    file: file.into(),
                    line,
                    msg: format!("expected 7 cells, found {}", rec.len()),
                });
            }
            let mut v = [0f64; 7];
            for k in 0..7 {
                let cell = &rec[index[k]];
                v[k] = cell.parse::<f64>().map_err(|_| DataError::Line {
                    file: file.into(),
                    line,
                    msg: format!("column {} = '{cell}' is not a number", COLUMNS[k]),
                })?;
            }
            rows.push((
                line,
                RawRow {
                    theta_i: v[0],
                    phi_i: v[1],
                    theta_o: v[2],
                    phi_o: v[3],
                    wavelength_nm: v[4],
                    value: v[5],
                    uncertainty: v[6],
                },
            ));
        }
        let material = meta.get("material").cloned().unwrap_or_else(|| {
            Path::new(file)
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        });
        let mut ds = Dataset::from_rows(kind, &material, &rows, file, opts)?;
        ds.meta = meta;
        Ok(ds)
    }

    /// Write the v1 CSV format (angles in degrees, θ ≥ 0 with φ carrying the side).
    pub fn to_csv(&self) -> String {
        let mut out = String::from("# bsdfit dataset v1\n");
        out += &format!("# material: {}\n", self.material);
        out += &format!("# kind: {}\n", self.kind);
        for (k, v) in &self.meta {
            if k != "material" && k != "kind" {
                out += &format!("# {k}: {v}\n");
            }
        }
        out += &COLUMNS.join(",");
        out.push('\n');
        for s in &self.samples {
            out += &format!(
                "{},{},{},{},{},{:e},{:e}\n",
                fmt_deg(s.theta_i),
                fmt_deg(s.phi_i),
                fmt_deg(s.theta_o),
                fmt_deg(s.phi_o),
                s.wavelength_nm,
                s.value,
                s.uncertainty
            );
        }
        out
    }

    pub fn write(&self, path: &Path) -> anyhow::Result<()> {
        std::fs::write(path, self.to_csv())
            .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", path.display()))
    }

    /// Number of (sample, channel) pairs K.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    pub fn channel_count(&self) -> usize {
        self.channels.len()
    }

    /// A short label for messages and tables.
    pub fn label(&self) -> String {
        if self.material.is_empty() {
            self.source.display().to_string()
        } else {
            self.material.clone()
        }
    }
}

/// The plane of an outgoing direction (θ ≥ 0, degrees): φ mod 180, or None at θ = 0.
fn plane_of(theta_deg: f64, phi_deg: f64) -> Option<f64> {
    if theta_deg == 0.0 {
        return None;
    }
    let p = (phi_deg.rem_euclid(180.0) * 1e6).round() / 1e6;
    Some(if p >= 180.0 { 0.0 } else { p })
}

/// Distinct measurement planes of (θo, φo) pairs in degrees (θ ≥ 0), ascending.
pub fn measurement_planes(pairs: impl Iterator<Item = (f64, f64)>) -> Vec<f64> {
    let mut planes: Vec<f64> = pairs.filter_map(|(t, p)| plane_of(t, p)).collect();
    planes.sort_by(|a, b| a.total_cmp(b));
    planes.dedup();
    if planes.is_empty() {
        planes.push(0.0);
    }
    planes
}

fn plane_index(planes: &[f64], theta_deg: f64, phi_deg: f64) -> usize {
    match plane_of(theta_deg, phi_deg) {
        None => 0,
        Some(p) => planes.iter().position(|&q| q == p).unwrap_or(0),
    }
}

impl Dataset {
    /// The samples of one measurement plane (and those at θo = 0, which lie on every
    /// plane), as a dataset of its own with that single axis.
    pub fn axis_subset(&self, axis: usize) -> Dataset {
        let mut d = self.clone();
        d.samples.retain(|s| s.axis == axis || s.theta_o == 0.0);
        for s in &mut d.samples {
            s.axis = 0;
        }
        d.axes = vec![self.axes[axis]];
        d
    }
}

/// Degrees with rounding noise from the radian round trip removed.
fn fmt_deg(rad: f64) -> String {
    let d = rad.to_degrees();
    let r = (d * 1e9).round() / 1e9;
    format!("{r}")
}
