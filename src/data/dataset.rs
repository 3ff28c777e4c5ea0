//! Goniometric datasets: the v1 CSV format of docs/conventions.md, validation, channel selection.
//!
//! Every failure is a [`DataError`] naming the file and line; nothing here panics on
//! user input. A file's bad rows are all reported at once (up to [`MAX_REPORTED_ERRORS`]).
//! The v1 reader streams: it reads one line at a time into the final samples, so a file
//! needs little more memory than its [`Dataset`] (see [`Dataset::parse_reader`]). Other
//! formats (ALTA, MERL) and the content-sniffing entry point are in [`crate::data::readers`].

use crate::math::direction;
use glam::DVec3;
use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::io::Write;
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
    /// 1-based line in the source file (0 for synthetic data never written).
    pub line: u32,
    /// Index into [`Dataset::axes`]: the φ plane of the outgoing direction. A sample at
    /// θo = 0 lies on every plane; it is given the plane of the φo written in its row when
    /// that is one of the planes (two scans through the normal give one normal sample to
    /// each plane), else plane 0.
    pub axis: usize,
    /// A transmission sample (BTDF): the outgoing direction is in the lower hemisphere.
    pub transmitted: bool,
}

// The directions are computed from the angles when needed, not stored: a sample is 80
// bytes, so reading a file takes well under twice its size (tests/reader_memory.rs).
const _: () = assert!(std::mem::size_of::<Sample>() == 80);

impl Sample {
    /// Incident direction, pointing away from the surface (upper hemisphere).
    #[inline]
    pub fn wi(&self) -> DVec3 {
        direction(self.theta_i, self.phi_i)
    }
    /// Outgoing direction: upper hemisphere for a BRDF, lower for a BTDF (θt is measured
    /// from −n, docs/conventions.md).
    #[inline]
    pub fn wo(&self) -> DVec3 {
        let w = direction(self.theta_o, self.phi_o);
        if self.transmitted {
            DVec3::new(w.x, w.y, -w.z)
        } else {
            w
        }
    }
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
    /// ascending; `[0.0]` when there is none, or when there are more than [`MAX_PLANES`]
    /// (out-of-plane data such as MERL tables). Anisotropic diffusers are measured on two.
    pub axes: Vec<f64>,
    /// Where the data came from (for messages); empty for in-memory data.
    pub source: PathBuf,
    /// Human-readable notices produced while reading (e.g. uncertainty floors applied).
    pub notices: Vec<String>,
    /// `Some((REL, ABS))` when the file carried no uncertainties and they were assumed,
    /// u = sqrt((REL·|value|)² + ABS²) ([`crate::data::readers::assumed_uncertainty`]); every
    /// output derived from such data must say so.
    pub assumed_uncertainty: Option<(f64, f64)>,
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
    /// Several bad rows: the first [`MAX_REPORTED_ERRORS`], one per line of the message,
    /// then how many more there are.
    #[error("{}", fmt_lines(.file, .errors, *.more))]
    Lines {
        file: String,
        errors: Vec<(usize, String)>,
        more: usize,
    },
}

fn fmt_lines(file: &str, errors: &[(usize, String)], more: usize) -> String {
    let mut s = format!("{} bad rows in {file}:", errors.len() + more);
    for (line, msg) in errors {
        s += &format!("\n{file}:{line}: {msg}");
    }
    if more > 0 {
        s += &format!("\n… and {more} more");
    }
    s
}

/// "1 sample", "2 samples": `n` followed by the singular or plural noun (an empty noun
/// gives the bare number).
pub fn count(n: usize, singular: &str, plural: &str) -> String {
    let noun = if n == 1 { singular } else { plural };
    if noun.is_empty() {
        n.to_string()
    } else {
        format!("{n} {noun}")
    }
}

/// At most this many bad rows are listed in one error; the rest are counted.
pub const MAX_REPORTED_ERRORS: usize = 20;
/// Largest |value| accepted, sr⁻¹. Even a mirror-like BRDF measured with a 0.1° aperture
/// stays below about 1e6 sr⁻¹; larger values are unit or exponent mistakes and would
/// dominate every loss.
pub const MAX_ABS_VALUE: f64 = 1e7;
/// Smallest accepted uncertainty relative to |value|: below it, double-precision rounding
/// of the value itself exceeds the stated uncertainty.
pub const MIN_REL_UNCERTAINTY: f64 = 1e-12;
/// Smallest accepted uncertainty, sr⁻¹: 1/u² of smaller ones overflows χ² sums (f64
/// overflows near 1e308, and a residual of 1 sr⁻¹ over u = 1e-160 already does).
pub const MIN_ABS_UNCERTAINTY: f64 = 1e-30;
/// More distinct outgoing azimuths (mod 180°) than this and the data are not scans on a
/// few measurement planes: [`Dataset::axes`] is then the single plane 0.
pub const MAX_PLANES: usize = 32;
/// `--wavelengths`: a request farther than this from every wavelength of the file is an
/// error rather than a silent substitution.
pub const MAX_WAVELENGTH_GAP_NM: f64 = 50.0;

/// Options that relax or shape reading.
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// Accept zero (or vanishingly small) uncertainties by replacing them with a floor
    /// (and saying so).
    pub allow_zero_uncertainty: bool,
    /// Keep only the channels nearest to these wavelengths (nm), in this order.
    pub wavelengths: Option<Vec<f64>>,
    /// With `wavelengths`: each selected channel averages, per geometry, every wavelength
    /// of the file within ± this many nm of it: value = mean, u = sqrt(Σu²)/n (the
    /// standard uncertainty of a mean of n independent values).
    pub band_nm: Option<f64>,
    /// For files that carry no uncertainties (ALTA text without `#VS`, MERL binary):
    /// assume u = sqrt((REL·|value|)² + ABS²) with (REL, ABS). Without it such files are
    /// refused; with it the dataset records the assumption
    /// ([`Dataset::assumed_uncertainty`]). Ignored (with a notice) for files that carry
    /// their own uncertainties.
    pub assume_uncertainty: Option<(f64, f64)>,
    /// MERL tables: keep at most this many measured cells, a deterministic subsample;
    /// `None` is [`crate::data::readers::merl::DEFAULT_MAX_SAMPLES`], `Some(0)` keeps all.
    pub max_samples: Option<usize>,
    /// ALTA text files without `#PARAM_OUT`: what their values are (the BRDF, or BRDF ×
    /// cos θo). Without it such files are refused; a file whose `#PARAM_OUT` disagrees is
    /// refused, naming both. Other formats ignore it
    /// ([`crate::data::readers::alta`]).
    pub alta_values: Option<crate::data::readers::alta::AltaValues>,
    /// Files that hold a material rather than samples (RGL `.bsdf`): the named geometry
    /// (`bsdfit models` lists them; names joined by `+`) to sample it at; `None` is
    /// [`crate::data::readers::rgl::DEFAULT_GEOMETRY`]. Other formats ignore it.
    pub sample_geometry: Option<String>,
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

/// Signed-angle convention (docs/conventions.md): a negative θ is the same angle at φ + 180°.
/// Returns (θ, φ) in degrees with θ ≥ 0 and φ in [0, 360). At the pole (θ = 0) the
/// azimuth does not change the direction but is kept as written: it says on which
/// measurement plane a normal sample was taken ([`geometry_key`] ignores it).
pub fn normalise_angles(theta: f64, phi: f64) -> (f64, f64) {
    let (t, p) = if theta < 0.0 {
        (-theta, phi + 180.0)
    } else {
        (theta, phi)
    };
    let mut p = p.rem_euclid(360.0) + 0.0; // + 0.0 turns −0 into 0
    if p >= 360.0 {
        p = 0.0; // rem_euclid of a tiny negative rounds up to 360
    }
    (t, p)
}

/// The identity of a geometry and wavelength: the normalised angles (degrees) rounded to
/// 1e-6°, the azimuth folded to 0 at a pole (where it means nothing), and the wavelength
/// to 1e-6 nm. Two rows with the same key measured the same thing.
pub fn geometry_key(theta_i: f64, phi_i: f64, theta_o: f64, phi_o: f64, wl: f64) -> [i64; 5] {
    let (ti, pi) = normalise_angles(theta_i, phi_i);
    let (to, po) = normalise_angles(theta_o, phi_o);
    let pi = if ti == 0.0 { 0.0 } else { pi };
    let po = if to == 0.0 { 0.0 } else { po };
    [ti, pi, to, po, wl].map(|x| (x * 1e6).round() as i64)
}

fn sample_key(s: &Sample) -> [i64; 5] {
    geometry_key(
        s.theta_i.to_degrees(),
        s.phi_i.to_degrees(),
        s.theta_o.to_degrees(),
        s.phi_o.to_degrees(),
        s.wavelength_nm,
    )
}

/// FNV-1a, 64 bits (stable across runs; for grouping rows, not for security).
fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

fn fold32(h: u64) -> u32 {
    (h ^ (h >> 32)) as u32
}

fn key_hash(k: &[i64; 5]) -> u64 {
    let mut bytes = [0u8; 40];
    for (i, x) in k.iter().enumerate() {
        bytes[i * 8..i * 8 + 8].copy_from_slice(&x.to_le_bytes());
    }
    fnv1a(&bytes)
}

/// Per-row side data kept while reading, for the repeated-geometry pass: 12 bytes a row.
/// Rows with equal geometry hashes are compared on their exact keys, so a collision of
/// these 32-bit hashes costs time, never a wrong count; a text-hash collision between two
/// rows of the same geometry would only add a spurious warning.
struct RowKey {
    geometry: u32,
    /// Hash of the row's text (0 for rows not read from text).
    text: u32,
    index: u32,
}

/// Validates rows one at a time into samples and finishes them into a [`Dataset`]
/// (repeated geometries, channels, planes). Every reader goes through it, so every format
/// gets the same checks and messages. Bad rows are collected, not returned at the first.
pub(crate) struct Builder<'a> {
    file: &'a str,
    kind: Kind,
    opts: &'a ReadOptions,
    samples: Vec<Sample>,
    keys: Vec<RowKey>,
    errors: Vec<(usize, String)>,
    more_errors: usize,
    floored: usize,
    /// Notices of the reader (printed before the builder's own).
    pub(crate) notices: Vec<String>,
}

impl<'a> Builder<'a> {
    pub(crate) fn new(kind: Kind, file: &'a str, opts: &'a ReadOptions) -> Builder<'a> {
        Builder {
            file,
            kind,
            opts,
            samples: Vec::new(),
            keys: Vec::new(),
            errors: Vec::new(),
            more_errors: 0,
            floored: 0,
            notices: Vec::new(),
        }
    }

    /// Record a bad row (the first [`MAX_REPORTED_ERRORS`] are kept, the rest counted).
    pub(crate) fn error(&mut self, line: usize, msg: String) {
        if self.errors.len() < MAX_REPORTED_ERRORS {
            self.errors.push((line, msg));
        } else {
            self.more_errors += 1;
        }
    }

    /// Rows accepted so far.
    pub(crate) fn len(&self) -> usize {
        self.samples.len()
    }

    /// Validate one row (degrees, signed angles allowed) and keep it as a sample.
    /// `text` is the row as written, for the byte-identical-repeat warning.
    pub(crate) fn push(&mut self, line: usize, r: RawRow, text: Option<&str>) {
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
                return self.error(line, format!("column {name} is not a finite number ({v})"));
            }
        }
        for (name, v) in [("theta_i", r.theta_i), ("theta_o", r.theta_o)] {
            if !(-90.0..=90.0).contains(&v) {
                return self.error(line, format!("{name} = {v}° is outside [-90, 90]"));
            }
        }
        if r.wavelength_nm <= 0.0 {
            return self.error(
                line,
                format!("wavelength_nm = {} must be positive", r.wavelength_nm),
            );
        }
        if r.value.abs() > MAX_ABS_VALUE {
            return self.error(
                line,
                format!(
                    "value = {} sr⁻¹ is outside the range of a BSDF (|value| ≤ {MAX_ABS_VALUE:e} sr⁻¹; a unit or exponent mistake?)",
                    r.value
                ),
            );
        }
        let mut u = r.uncertainty;
        if u < 0.0 {
            return self.error(line, format!("uncertainty = {u} is negative"));
        }
        let tiny = u < MIN_ABS_UNCERTAINTY || u < MIN_REL_UNCERTAINTY * r.value.abs();
        if tiny {
            if !self.opts.allow_zero_uncertainty {
                let msg = if u == 0.0 {
                    "uncertainty is zero (pass --allow-zero-uncertainty to use a floor)".into()
                } else {
                    format!(
                        "uncertainty = {u:e} is below max({MIN_REL_UNCERTAINTY:e}·|value|, {MIN_ABS_UNCERTAINTY:e} sr⁻¹): its χ² weight 1/u² would overflow or swamp every other sample (pass --allow-zero-uncertainty to use a floor)"
                    )
                };
                return self.error(line, msg);
            }
            u = (UNCERTAINTY_FLOOR_REL * r.value.abs()).max(UNCERTAINTY_FLOOR_ABS);
            self.floored += 1;
        }
        if r.value < -3.0 * u {
            return self.error(
                line,
                format!(
                    "value = {} is negative beyond 3 uncertainties ({u})",
                    r.value
                ),
            );
        }
        let key = geometry_key(r.theta_i, r.phi_i, r.theta_o, r.phi_o, r.wavelength_nm);
        let (ti, pi) = normalise_angles(r.theta_i, r.phi_i);
        let (to, po) = normalise_angles(r.theta_o, r.phi_o);
        let (ti, pi, to, po) = (
            ti.to_radians(),
            pi.to_radians(),
            to.to_radians(),
            po.to_radians(),
        );
        let Ok(index) = u32::try_from(self.samples.len()) else {
            return self.error(line, "more than 4294967295 rows".into());
        };
        self.keys.push(RowKey {
            geometry: fold32(key_hash(&key)),
            text: text.map(|t| fold32(fnv1a(t.as_bytes())) | 1).unwrap_or(0),
            index,
        });
        self.samples.push(Sample {
            theta_i: ti,
            phi_i: pi,
            theta_o: to,
            phi_o: po,
            wavelength_nm: r.wavelength_nm,
            value: r.value,
            uncertainty: u,
            channel: 0,
            axis: 0,
            transmitted: self.kind == Kind::Btdf,
            line: u32::try_from(line).unwrap_or(u32::MAX),
        });
    }

    /// The errors so far as one [`DataError`], if any.
    pub(crate) fn take_errors(&mut self) -> Option<DataError> {
        if self.errors.is_empty() {
            return None;
        }
        let file = self.file.to_string();
        let mut errors = std::mem::take(&mut self.errors);
        let more = std::mem::take(&mut self.more_errors);
        Some(if errors.len() == 1 && more == 0 {
            let (line, msg) = errors.pop().expect("one error");
            DataError::Line { file, line, msg }
        } else {
            DataError::Lines { file, errors, more }
        })
    }

    /// Check the rows as a whole and build the dataset.
    pub(crate) fn finish(
        mut self,
        material: &str,
        meta: BTreeMap<String, String>,
    ) -> Result<Dataset, DataError> {
        if let Some(e) = self.take_errors() {
            return Err(e);
        }
        let file = self.file;
        if self.samples.is_empty() {
            return Err(DataError::File {
                file: file.to_string(),
                msg: "no data rows".into(),
            });
        }
        let mut notices = std::mem::take(&mut self.notices);
        self.repeated_geometries(&mut notices);
        if self.floored > 0 {
            notices.push(format!(
                "{file}: {} replaced by max({}·|value|, {} sr⁻¹)",
                count(
                    self.floored,
                    "zero uncertainty (or vanishingly small)",
                    "zero uncertainties (or vanishingly small ones)"
                ),
                UNCERTAINTY_FLOOR_REL,
                UNCERTAINTY_FLOOR_ABS
            ));
        }
        let mut samples = std::mem::take(&mut self.samples);
        let channels = select_channels(&mut samples, file, self.opts, &mut notices)?;
        if samples.is_empty() {
            return Err(DataError::File {
                file: file.into(),
                msg: "the selection leaves no sample".into(),
            });
        }
        let mut axes = measurement_planes(
            samples
                .iter()
                .map(|s| (s.theta_o.to_degrees(), s.phi_o.to_degrees())),
        );
        if axes.len() > MAX_PLANES {
            // Out-of-plane data (MERL tables, dense ALTA scans): one "plane" per azimuth
            // is no measurement plane; per-plane fits and checks would multiply by them.
            notices.push(format!(
                "{file}: {} distinct outgoing azimuths (mod 180°): the data are not scans on a few planes, so they are treated as one (no per-plane analysis)",
                axes.len()
            ));
            axes = vec![0.0];
            for s in &mut samples {
                s.axis = 0;
            }
        } else {
            for s in &mut samples {
                s.axis = plane_index(&axes, s.theta_o.to_degrees(), s.phi_o.to_degrees());
            }
        }
        samples.shrink_to_fit();
        Ok(Dataset {
            kind: self.kind,
            material: material.to_string(),
            meta,
            channels,
            samples,
            axes,
            source: PathBuf::from(file),
            notices,
            assumed_uncertainty: None,
        })
    }

    /// A geometry measured more than once is a set of independent samples (docs/conventions.md);
    /// say how many there are, and warn about rows repeated byte for byte.
    fn repeated_geometries(&mut self, notices: &mut Vec<String>) {
        let mut keys = std::mem::take(&mut self.keys);
        keys.sort_unstable_by_key(|k| (k.geometry, k.index));
        let (mut geometries, mut members) = (0usize, 0usize);
        let mut identical: Vec<(usize, usize)> = Vec::new();
        let mut identical_count = 0usize;
        let mut i = 0;
        while i < keys.len() {
            let mut j = i + 1;
            while j < keys.len() && keys[j].geometry == keys[i].geometry {
                j += 1;
            }
            if j - i > 1 {
                // Same hash: group by the exact key (a hash collision splits the group).
                let mut group: Vec<([i64; 5], usize, u32)> = keys[i..j]
                    .iter()
                    .map(|k| {
                        let idx = k.index as usize;
                        (sample_key(&self.samples[idx]), idx, k.text)
                    })
                    .collect();
                group.sort_unstable();
                let mut a = 0;
                while a < group.len() {
                    let mut b = a + 1;
                    while b < group.len() && group[b].0 == group[a].0 {
                        b += 1;
                    }
                    if b - a > 1 {
                        geometries += 1;
                        members += b - a;
                        for m in a + 1..b {
                            let (_, idx, text) = group[m];
                            if text == 0 {
                                continue;
                            }
                            if let Some(first) = group[a..m].iter().find(|g| g.2 == text) {
                                identical_count += 1;
                                if identical.len() < 5 {
                                    identical.push((
                                        self.samples[first.1].line as usize,
                                        self.samples[idx].line as usize,
                                    ));
                                }
                            }
                        }
                    }
                    a = b;
                }
            }
            i = j;
        }
        let file = self.file;
        if geometries > 0 {
            notices.push(format!(
                "{file}: {} measured more than once ({} in all), kept as independent samples",
                count(
                    geometries,
                    "geometry (and wavelength)",
                    "geometries (and wavelengths)"
                ),
                count(members, "sample", "samples")
            ));
        }
        if identical_count > 0 {
            let mut s = format!(
                "{file}: warning: {} repeated byte for byte (a row pasted twice?):",
                count(identical_count, "row", "rows")
            );
            for (a, b) in &identical {
                s += &format!(" line {b} repeats line {a};");
            }
            if identical_count > identical.len() {
                s += &format!(" … and {} more", identical_count - identical.len());
            }
            notices.push(s.trim_end_matches(';').to_string());
        }
    }
}

/// Choose the channels: every wavelength, or the ones nearest to `--wavelengths` (each
/// within [`MAX_WAVELENGTH_GAP_NM`]), optionally averaged over `--band`. Drops the other
/// samples and sets [`Sample::channel`].
fn select_channels(
    samples: &mut Vec<Sample>,
    file: &str,
    opts: &ReadOptions,
    notices: &mut Vec<String>,
) -> Result<Vec<f64>, DataError> {
    let ferr = |msg: String| DataError::File {
        file: file.into(),
        msg,
    };
    // Wavelengths are positive and finite, so their bit patterns sort as they do.
    let present: Vec<f64> = samples
        .iter()
        .map(|s| s.wavelength_nm.to_bits())
        .collect::<BTreeSet<u64>>()
        .into_iter()
        .map(f64::from_bits)
        .collect();
    let list = |v: &[f64]| {
        v.iter()
            .map(|w| w.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let Some(wanted) = &opts.wavelengths else {
        if opts.band_nm.is_some() {
            return Err(ferr(
                "--band needs --wavelengths: the centres of the bands to average".into(),
            ));
        }
        for s in samples.iter_mut() {
            s.channel = present
                .binary_search_by(|p| p.total_cmp(&s.wavelength_nm))
                .unwrap_or(0);
        }
        return Ok(present);
    };
    if wanted.is_empty() {
        return Err(ferr("--wavelengths selects no channel".into()));
    }
    if wanted.len() > present.len() {
        return Err(ferr(format!(
            "--wavelengths asks for {} ({} nm) but the file has only {}: {} nm",
            count(wanted.len(), "channel", "channels"),
            list(wanted),
            count(present.len(), "wavelength", "wavelengths"),
            list(&present)
        )));
    }
    let mut chosen: Vec<f64> = Vec::new();
    for &w in wanted {
        if !w.is_finite() || w <= 0.0 {
            return Err(ferr(format!(
                "--wavelengths: {w} nm is not a positive wavelength"
            )));
        }
        let nearest = present
            .iter()
            .copied()
            .min_by(|a, b| (a - w).abs().total_cmp(&(b - w).abs()))
            .unwrap_or(w);
        if (nearest - w).abs() > MAX_WAVELENGTH_GAP_NM {
            return Err(ferr(format!(
                "--wavelengths: no wavelength within {MAX_WAVELENGTH_GAP_NM} nm of {w} nm; the file has only: {} nm",
                list(&present)
            )));
        }
        if let Some(c) = chosen.iter().position(|&c| c == nearest) {
            return Err(ferr(format!(
                "--wavelengths: {} nm and {w} nm would both use the {nearest} nm channel; the file has only these wavelengths: {} nm",
                wanted[c],
                list(&present)
            )));
        }
        if nearest != w {
            notices.push(format!(
                "{file}: wavelength {w} nm → nearest present {nearest} nm"
            ));
        }
        chosen.push(nearest);
    }
    let band = match opts.band_nm {
        None => 0.0,
        Some(b) if b.is_finite() && b >= 0.0 => b,
        Some(b) => return Err(ferr(format!("--band {b}: expected a width ≥ 0 nm"))),
    };
    if band == 0.0 {
        samples.retain(|s| chosen.contains(&s.wavelength_nm));
        for s in samples.iter_mut() {
            s.channel = chosen
                .iter()
                .position(|&c| c == s.wavelength_nm)
                .unwrap_or(0);
        }
        return Ok(chosen);
    }
    // Bands: every present wavelength within ±band of a chosen centre joins its channel.
    let mut member_of: Vec<(f64, usize)> = Vec::new();
    for (ch, &c) in chosen.iter().enumerate() {
        let members: Vec<f64> = present
            .iter()
            .copied()
            .filter(|w| (w - c).abs() <= band)
            .collect();
        for &w in &members {
            if let Some(&(_, other)) = member_of.iter().find(|m| m.0 == w) {
                return Err(ferr(format!(
                    "--band {band}: {w} nm lies in the bands of both {} nm and {c} nm; narrow the band or space the wavelengths",
                    chosen[other]
                )));
            }
            member_of.push((w, ch));
        }
    }
    // Group by (channel, geometry) and average.
    let mut groups: Vec<(usize, [i64; 4], usize)> = samples
        .iter()
        .enumerate()
        .filter_map(|(i, s)| {
            let ch = member_of.iter().find(|m| m.0 == s.wavelength_nm)?.1;
            let k = sample_key(s);
            Some((ch, [k[0], k[1], k[2], k[3]], i))
        })
        .collect();
    groups.sort_unstable();
    let mut out: Vec<(usize, Sample)> = Vec::new();
    let (mut n_min, mut n_max) = (usize::MAX, 0usize);
    let mut a = 0;
    while a < groups.len() {
        let mut b = a + 1;
        while b < groups.len() && groups[b].0 == groups[a].0 && groups[b].1 == groups[a].1 {
            b += 1;
        }
        let n = b - a;
        let first = groups[a].2; // smallest index of the group (sorted last)
        let mut s = samples[first].clone();
        let mut sum = 0.0;
        let mut var = 0.0;
        for g in &groups[a..b] {
            let m = &samples[g.2];
            sum += m.value;
            var += m.uncertainty * m.uncertainty;
        }
        s.value = sum / n as f64;
        s.uncertainty = var.sqrt() / n as f64;
        s.channel = groups[a].0;
        s.wavelength_nm = chosen[groups[a].0];
        out.push((first, s));
        n_min = n_min.min(n);
        n_max = n_max.max(n);
        a = b;
    }
    out.sort_unstable_by_key(|(i, _)| *i);
    *samples = out.into_iter().map(|(_, s)| s).collect();
    for (ch, &c) in chosen.iter().enumerate() {
        let members: Vec<f64> = member_of
            .iter()
            .filter(|m| m.1 == ch)
            .map(|m| m.0)
            .collect();
        notices.push(format!(
            "{file}: --band ±{band} nm: channel {c} nm averages {} nm",
            list(&members)
        ));
    }
    if n_max > 0 {
        notices.push(format!(
            "{file}: --band: {} per geometry averaged (value = mean, u = sqrt(Σu²)/n)",
            if n_min == n_max {
                count(n_min, "sample", "samples")
            } else {
                format!("{n_min} to {n_max} samples")
            }
        ));
    }
    Ok(chosen)
}

/// How often (in lines) the readers report progress.
pub(crate) const PROGRESS_EVERY_LINES: usize = 1 << 16;

impl Dataset {
    /// Build from raw rows (degrees, signed angles allowed), validating as a file would be.
    pub fn from_rows(
        kind: Kind,
        material: &str,
        rows: &[(usize, RawRow)],
        file: &str,
        opts: &ReadOptions,
    ) -> Result<Dataset, DataError> {
        let mut b = Builder::new(kind, file, opts);
        for &(line, r) in rows {
            b.push(line, r, None);
        }
        b.finish(material, BTreeMap::new())
    }

    /// Read a dataset file of any supported format (v1 CSV, ALTA text, MERL binary),
    /// recognised by its content: see [`crate::data::readers::load`].
    pub fn read(path: &Path, opts: &ReadOptions) -> Result<Dataset, DataError> {
        crate::data::readers::load(path, opts)
    }

    /// Write the v1 CSV format (angles in degrees, θ ≥ 0 with φ carrying the side).
    pub fn to_csv(&self) -> String {
        let mut out = Vec::new();
        self.write_csv(&mut out)
            .expect("writing to memory cannot fail");
        String::from_utf8(out).expect("the CSV is UTF-8")
    }

    /// Write the v1 CSV format to `w`, one row at a time.
    pub fn write_csv<W: Write>(&self, w: &mut W) -> std::io::Result<()> {
        writeln!(w, "# bsdfit dataset v1")?;
        writeln!(w, "# material: {}", one_line(&self.material))?;
        writeln!(w, "# kind: {}", self.kind)?;
        for (k, v) in &self.meta {
            if k != "material" && k != "kind" {
                writeln!(w, "# {}: {}", one_line(k), one_line(v))?;
            }
        }
        writeln!(w, "{}", COLUMNS.join(","))?;
        for s in &self.samples {
            writeln!(
                w,
                "{},{},{},{},{},{:e},{:e}",
                fmt_deg(s.theta_i),
                fmt_deg(s.phi_i),
                fmt_deg(s.theta_o),
                fmt_deg(s.phi_o),
                s.wavelength_nm,
                s.value,
                s.uncertainty
            )?;
        }
        Ok(())
    }

    pub fn write(&self, path: &Path) -> anyhow::Result<()> {
        let fail = |e: std::io::Error| anyhow::anyhow!("cannot write {}: {e}", path.display());
        let f = std::fs::File::create(path).map_err(fail)?;
        let mut w = std::io::BufWriter::new(f);
        self.write_csv(&mut w).map_err(fail)?;
        w.flush().map_err(fail)
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

/// The plane of an azimuth (degrees): φ mod 180, rounded to 1e-6°.
fn plane_of_phi(phi_deg: f64) -> f64 {
    let p = (phi_deg.rem_euclid(180.0) * 1e6).round() / 1e6;
    if p >= 180.0 {
        0.0
    } else {
        p + 0.0
    }
}

/// The plane of an outgoing direction (θ ≥ 0, degrees): φ mod 180, or None at θ = 0.
fn plane_of(theta_deg: f64, phi_deg: f64) -> Option<f64> {
    if theta_deg == 0.0 {
        return None;
    }
    Some(plane_of_phi(phi_deg))
}

/// Distinct measurement planes of (θo, φo) pairs in degrees (θ ≥ 0), ascending.
pub fn measurement_planes(pairs: impl Iterator<Item = (f64, f64)>) -> Vec<f64> {
    // Planes are in [0, 180): their bit patterns sort as they do.
    let set: BTreeSet<u64> = pairs
        .filter_map(|(t, p)| plane_of(t, p))
        .map(f64::to_bits)
        .collect();
    let mut planes: Vec<f64> = set.into_iter().map(f64::from_bits).collect();
    if planes.is_empty() {
        planes.push(0.0);
    }
    planes
}

/// The index of a direction's plane in `planes`. A direction at the pole lies on every
/// plane: it goes to the plane of the azimuth written with it when that is one of the
/// planes (a scan through the normal on that plane), else to plane 0.
fn plane_index(planes: &[f64], theta_deg: f64, phi_deg: f64) -> usize {
    let p = plane_of(theta_deg, phi_deg).unwrap_or_else(|| plane_of_phi(phi_deg));
    // `planes` is sorted (measurement_planes): out-of-plane data (MERL, ALTA) has one
    // plane per distinct azimuth, up to millions.
    planes.binary_search_by(|q| q.total_cmp(&p)).unwrap_or(0)
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

/// Metadata text on one line (a newline would end the comment and corrupt the file).
fn one_line(s: &str) -> String {
    s.replace(['\n', '\r'], " ")
}

/// Degrees with rounding noise from the radian round trip removed.
fn fmt_deg(rad: f64) -> String {
    let d = rad.to_degrees();
    let r = (d * 1e9).round() / 1e9;
    format!("{r}")
}
