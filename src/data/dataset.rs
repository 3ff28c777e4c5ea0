//! Goniometric datasets: the v1 CSV format of docs/conventions.md and the limits rows are
//! validated against (the validation itself is in `builder.rs`, channel selection in
//! `channels.rs`).
//!
//! Every failure is a [`DataError`] naming the file and line; nothing here panics on
//! user input. A file's bad rows are all reported at once (up to [`MAX_REPORTED_ERRORS`]).
//! The v1 reader streams: it reads one line at a time into the final samples, so a file
//! needs little more memory than its [`Dataset`] (see [`Dataset::parse_reader`]). Other
//! formats (ALTA, MERL) and the content-sniffing entry point are in [`crate::data::readers`].

use super::Builder;
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
    /// What the reader wants the user to know (e.g. uncertainty floors applied), each
    /// with its kind.
    pub notices: Vec<Notice>,
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
    /// A problem at a place in a line: `file:line:column: msg`, the column 1-based in
    /// characters.
    #[error("{file}:{line}:{column}: {msg}")]
    At {
        file: String,
        line: usize,
        column: usize,
        msg: String,
    },
    /// Several bad rows: the first [`MAX_REPORTED_ERRORS`] as (line, column if known,
    /// message), one per line of the message, then how many more there are.
    #[error("{}", fmt_lines(.file, .errors, *.more))]
    Lines {
        file: String,
        errors: Vec<(usize, Option<usize>, String)>,
        more: usize,
    },
}

impl DataError {
    /// An error about the whole of `file`.
    pub fn in_file(file: &str, msg: String) -> DataError {
        DataError::File {
            file: file.into(),
            msg,
        }
    }
    /// An error at line `line` (1-based) of `file`.
    pub fn at_line(file: &str, line: usize, msg: String) -> DataError {
        DataError::Line {
            file: file.into(),
            line,
            msg,
        }
    }
    /// An error at line `line`, character column `column` (both 1-based) of `file`.
    pub fn at(file: &str, line: usize, column: usize, msg: String) -> DataError {
        DataError::At {
            file: file.into(),
            line,
            column,
            msg,
        }
    }
}

fn fmt_lines(file: &str, errors: &[(usize, Option<usize>, String)], more: usize) -> String {
    let mut s = format!("{} bad rows in {file}:", errors.len() + more);
    for (line, column, msg) in errors {
        match column {
            Some(c) => s += &format!("\n{file}:{line}:{c}: {msg}"),
            None => s += &format!("\n{file}:{line}: {msg}"),
        }
    }
    if more > 0 {
        s += &format!("\n… and {more} more");
    }
    s
}

/// What a notice is about, for a caller that shows some and not others.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoticeKind {
    /// The uncertainties were assumed (`assume_uncertainty`, or a v1 file saying so).
    AssumedUncertainty,
    /// `assume_uncertainty` was given for a file with uncertainties of its own.
    AssumptionIgnored,
    /// Zero uncertainties were replaced by a floor (`allow_zero_uncertainty`).
    UncertaintyFloor,
    /// Anything else about how the file was read (conversions, channels, repeats).
    Reading,
}

/// One line the reader wants the user to know, with what it is about.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Notice {
    pub kind: NoticeKind,
    pub text: String,
}

impl Notice {
    pub fn new(kind: NoticeKind, text: impl Into<String>) -> Notice {
        Notice {
            kind,
            text: text.into(),
        }
    }
}

/// A notice about how the file was read ([`NoticeKind::Reading`]).
impl From<String> for Notice {
    fn from(text: String) -> Notice {
        Notice::new(NoticeKind::Reading, text)
    }
}

/// A notice reads as its text (`notice.contains(…)`, `notices.join("\n")`).
impl std::ops::Deref for Notice {
    type Target = str;
    fn deref(&self) -> &str {
        &self.text
    }
}

impl std::borrow::Borrow<str> for Notice {
    fn borrow(&self) -> &str {
        &self.text
    }
}

impl std::fmt::Display for Notice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
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
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct ReadOptions {
    /// Accept zero (or vanishingly small) uncertainties by replacing them with a floor
    /// (and saying so).
    pub allow_zero_uncertainty: bool,
    /// Keep only the channels nearest to these wavelengths (nm), in this order.
    pub wavelengths: Option<Vec<f64>>,
    /// With `wavelengths` (and no `band_nm`): a file with no more channels than it names
    /// keeps all of its own, with a notice, instead of being refused. A collection's files
    /// differ (a spectral scan beside a one-wavelength Zemax file), and one selection must
    /// serve them all.
    pub wavelengths_at_most: bool,
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

/// An uncertainty to assume, as a caller gives it: the text `REL,ABS` (the command
/// line's), or the two numbers.
#[derive(Clone, Debug, PartialEq)]
pub enum AssumeArg {
    Text(String),
    Values(f64, f64),
}

/// The reader options a caller asks for, as its options give them: what
/// [`ReadOptions::from_request`] checks and completes, for the command line and the
/// Python module alike.
#[derive(Clone, Debug, Default)]
pub struct ReadRequest {
    pub allow_zero_uncertainty: bool,
    pub wavelengths: Option<Vec<f64>>,
    pub band_nm: Option<f64>,
    pub assume_uncertainty: Option<AssumeArg>,
    /// None: [`crate::data::readers::merl::DEFAULT_MAX_SAMPLES`].
    pub max_samples: Option<usize>,
    pub alta_values: Option<crate::data::readers::alta::AltaValues>,
    pub sample_geometry: Option<String>,
}

impl ReadOptions {
    /// The options `request` asks for, with the checks that need no file made once,
    /// here: the uncertainty to assume, and a band (a width ≥ 0 nm, around the
    /// wavelengths chosen). Errors name the options as fields
    /// ([`crate::choice::FieldError`]).
    pub fn from_request(request: ReadRequest) -> anyhow::Result<ReadOptions> {
        use crate::choice::field_error;
        use crate::data::readers::{check_assumed, parse_assume_arg};
        let assume_uncertainty = match &request.assume_uncertainty {
            None => None,
            Some(AssumeArg::Text(text)) => Some(parse_assume_arg(text)),
            Some(AssumeArg::Values(rel, abs)) => {
                Some(check_assumed(*rel, *abs).map_err(|e| format!("({rel:?}, {abs:?}): {e}")))
            }
        }
        .transpose()
        .map_err(|e| field_error(format!("{{assume_uncertainty}}: {e}")))?;
        match request.band_nm {
            Some(_) if request.wavelengths.is_none() => {
                return Err(field_error(
                    "{band} needs {wavelengths}: the centres of the bands to average",
                ))
            }
            Some(b) if !(b.is_finite() && b >= 0.0) => {
                return Err(field_error(format!(
                    "{{band={b}}}: expected a width ≥ 0 nm"
                )))
            }
            _ => {}
        }
        Ok(ReadOptions {
            allow_zero_uncertainty: request.allow_zero_uncertainty,
            wavelengths: request.wavelengths,
            wavelengths_at_most: false,
            band_nm: request.band_nm,
            assume_uncertainty,
            max_samples: Some(
                request
                    .max_samples
                    .unwrap_or(crate::data::readers::merl::DEFAULT_MAX_SAMPLES),
            ),
            alta_values: request.alta_values,
            sample_geometry: request.sample_geometry,
        })
    }
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

impl RawRow {
    /// A geometry (θi, φi, θo, φo in degrees) at a wavelength, with a placeholder value
    /// (0 ± 1) for the model to fill in.
    pub fn placeholder(geometry: [f64; 4], wavelength_nm: f64) -> RawRow {
        RawRow {
            theta_i: geometry[0],
            phi_i: geometry[1],
            theta_o: geometry[2],
            phi_o: geometry[3],
            wavelength_nm,
            value: 0.0,
            uncertainty: 1.0,
        }
    }
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

pub(super) fn sample_key(s: &Sample) -> [i64; 5] {
    geometry_key(
        s.theta_i.to_degrees(),
        s.phi_i.to_degrees(),
        s.theta_o.to_degrees(),
        s.phi_o.to_degrees(),
        s.wavelength_nm,
    )
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
pub(super) fn plane_index(planes: &[f64], theta_deg: f64, phi_deg: f64) -> usize {
    let p = plane_of(theta_deg, phi_deg).unwrap_or_else(|| plane_of_phi(phi_deg));
    // `planes` is sorted (measurement_planes): out-of-plane data (MERL, ALTA) has one
    // plane per distinct azimuth, up to millions.
    planes.binary_search_by(|q| q.total_cmp(&p)).unwrap_or(0)
}

impl Dataset {
    /// How many planes through the normal hold the data's directions: the distinct
    /// azimuths of ωi and ωo (θ > 0) modulo 180°, to 0.01°; [`MAX_PLANES`] + 1 when
    /// there are more (out-of-plane data). A surface's anisotropy shows only across planes:
    /// in one plane the data see one combination of its two roughnesses.
    pub fn direction_planes(&self) -> usize {
        let mut planes = BTreeSet::new();
        for s in &self.samples {
            for (theta, phi) in [(s.theta_i, s.phi_i), (s.theta_o, s.phi_o)] {
                if theta > 1e-9 {
                    planes.insert(
                        (phi.to_degrees().rem_euclid(180.0) * 100.0).round() as i64 % 18000,
                    );
                    if planes.len() > MAX_PLANES {
                        return MAX_PLANES + 1;
                    }
                }
            }
        }
        planes.len().max(1)
    }

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
