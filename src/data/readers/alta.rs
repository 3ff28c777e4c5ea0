//! ALTA text data files (the BRDF library ALTA, <https://github.com/belcour/alta>,
//! MPL-2.0), read into the project's convention.
//!
//! # The format (ALTA `documents/data-formats.dox`, `sources/core/args.h`
//! `parse_header`, `sources/core/data_storage.cpp` `load_data_from_text`)
//!
//! ```text
//! #DIM N P
//! #PARAM_IN  ISOTROPIC_TL_TV_PROJ_DPHI
//! #PARAM_OUT INV_STERADIAN
//! #VS 0|1|2                (optional)
//! x_1 … x_N  y_1 … y_P  [interval columns]
//! ```
//! A line starting with `#` and a non-blank character is a header line `#KEY value`;
//! `# ` followed by a blank is a comment. The header ends at the first data line or at
//! `#ALTA END HEADER` (ALTA writes `#ALTA HEADER END` in function files; both are
//! accepted). Other keys (`#SAMPLE`, `#ORIGIN`, `#URL`, …) are kept as metadata
//! (`alta_sample`, …); `#SAMPLE` names the material. Columns are separated by blanks.
//!
//! **`#VS` (vertical segments).** ALTA's "confidence intervals" on the outputs, used as
//! hard bounds that its rational fitters must pass through (Pacanowski et al. 2012):
//! `#VS 0` none; `#VS 1` one column a per output, the interval [y − a, y + a];
//! `#VS 2` two columns a₋ a₊ per output, the interval [y − a₋, y + a₊] (ALTA reads the
//! first column as a distance below the value and negates it: `min_dt = -min_dt`). A
//! single `#VS k` applies to every output, `#VS k₁ … k_P` gives one per output, and the
//! interval columns follow the P outputs, output by output. (ALTA's own text reader reads
//! intervals for the first output only; the documented format repeats them per output,
//! which is what this reader expects.) ALTA states no coverage probability, so the
//! intervals are bounds only; following the GUM (JCGM 100:2008, §4.3.7–4.3.9: only bounds
//! known → rectangular distribution) the standard uncertainty is
//!
//! u = (a₋ + a₊) / (2√3)   (= a/√3 for `#VS 1`).
//!
//! Files without intervals need `--assume-uncertainty` (see [`crate::data::readers`]).
//!
//! # Input parametrizations (ALTA `sources/core/params.h`, `params.cpp`
//! `params::to_cartesian`)
//!
//! ALTA converts every parametrization to CARTESIAN = [V, L] ("we always pack the view
//! vector first"), V the view (outgoing) and L the light (incident) direction, unit
//! vectors pointing away from the surface, normal +z — the project's frame, so
//! **ωi = L and ωo = V**. The conversions re-implemented here:
//!
//! - `ISOTROPIC_TL_TV_PROJ_DPHI` [θl, x, y] with x = θv cos Δφ, y = θv sin Δφ:
//!   L = (sin θl, 0, cos θl); θv = √(x² + y²); V = (x/θv · sin θv, y/θv · sin θv, cos θv)
//!   (V = +z when θv = 0). So V has azimuth Δφ = atan2(y, x) with L at azimuth 0: the
//!   mirror direction is at x = −θl, y = 0, the retro direction at x = +θl.
//!   (ALTA's `from_cartesian` writes Δφ = φl − φv, the opposite sign of what
//!   `to_cartesian` reads back; for the isotropic BRDFs this parametrization assumes,
//!   f(Δφ) = f(−Δφ), so the two agree. This reader follows `to_cartesian`.)
//! - `ISOTROPIC_TV_TL_DPHI` [θv, θl, Δφ]: V = ω(θv, 0), L = ω(θl, Δφ).
//! - `RUSIN_TH_TD_PD` [θh, θd, φd] and `RUSIN_TH_PH_TD_PD` [θh, φh, θd, φd]
//!   (Rusinkiewicz 1998, ALTA's `half_to_cartesian`): H = ω(θh, φh), D = ω(θd, φd),
//!   V = Rz(φh)·Ry(θh)·D, L = 2(V·H)H − V, with Ry, Rz right-handed rotations about +y
//!   and +z (φh = 0 in the isotropic form). Note ALTA rotates the *view* vector into D,
//!   where MERL rotates the incident one ([`super::merl`]); for a reciprocal BRDF the two
//!   describe the same value.
//! - `SPHERICAL_TL_PL_TV_PV` [θl, φl, θv, φv]: L = ω(θl, φl), V = ω(θv, φv).
//! - `CARTESIAN` [Vx, Vy, Vz, Lx, Ly, Lz] (normalised; a vector off unit length by more
//!   than 1e-3 is an error).
//!
//! Angles are in radians. Directions below the surface (z < −1e-9) are errors naming the
//! line; z within rounding of 0 is clamped to grazing. The isotropic parametrizations
//! (`ISOTROPIC_*`, `RUSIN_TH_TD_PD`) are then rotated about the normal so that φi = 0,
//! exact for the isotropic BRDFs they describe. (θ, φ) follow ω(θ, φ) = (sin θ cos φ,
//! sin θ sin φ, cos θ), φ in [0°, 360°).
//!
//! # Outputs
//!
//! - `INV_STERADIAN` (P = 1): the BRDF in sr⁻¹.
//! - `INV_STERADIAN_COSINE_FACTOR` (P = 1): "values in inverse steradian weighted by the
//!   cosine factor of the output direction" (ALTA `params.h`), y = f·cos θo with θo the
//!   view direction's angle: f = y / cos θo, and the interval likewise. At grazing
//!   θo (cos θo < [`GRAZING_COS`]) the factor cannot be removed; those rows are dropped
//!   with a notice. (ALTA's diffuse-term initialisation divides such data by cos θl·cos θv
//!   instead; the documented definition is followed here.)
//! - `RGB_COLOR` (P = 3): BRDF values in sr⁻¹ for R, G, B, read as three channels at the
//!   nominal wavelengths R 650 nm, G 550 nm, B 450 nm ([`NOMINAL_RGB_NM`]; the project's
//!   usual 450/550/650 channel set).
//!
//! A file with one output gives no wavelength; its channel is labelled
//! [`NOMINAL_MONO_NM`] = 550 nm, and a notice says so.
//!
//! **Files without `#PARAM_OUT`** (or with `#PARAM_OUT UNKNOWN_OUTPUT`, ALTA's name for
//! it) could hold BRDF or BRDF × cos θo values, and real files often lack the line. The
//! user says which with [`ReadOptions::alta_values`] (`--alta-values brdf|brdf-cos`,
//! [`AltaValues`]): `brdf` reads them as `INV_STERADIAN`, `brdf-cos` as
//! `INV_STERADIAN_COSINE_FACTOR` (divided by cos θo), and a notice says the value kind
//! came from the option. Without it such a file is refused with an error naming the
//! option. A file whose `#PARAM_OUT` disagrees with the option is refused, naming both;
//! one that agrees is read as usual.

use super::v1::decode_line;
use super::{mark_assumed, require_assumption, Progress};
use crate::data::{
    count, Builder, DataError, Dataset, Kind, RawRow, ReadOptions, PROGRESS_EVERY_LINES,
};
use glam::DVec3;
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::Path;

/// Nominal wavelengths (nm) given to `RGB_COLOR` outputs: R, G, B.
pub const NOMINAL_RGB_NM: [f64; 3] = [650.0, 550.0, 450.0];
/// Nominal wavelength (nm) given to a single output.
pub const NOMINAL_MONO_NM: f64 = 550.0;
/// Rows of cosine-weighted data with cos θo below this are dropped.
pub const GRAZING_COS: f64 = 1e-6;

/// The input parametrizations this reader converts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamIn {
    IsotropicTlTvProjDphi,
    IsotropicTvTlDphi,
    RusinThTdPd,
    RusinThPhTdPd,
    SphericalTlPlTvPv,
    Cartesian,
}

impl ParamIn {
    pub const ALL: [ParamIn; 6] = [
        ParamIn::IsotropicTlTvProjDphi,
        ParamIn::IsotropicTvTlDphi,
        ParamIn::RusinThTdPd,
        ParamIn::RusinThPhTdPd,
        ParamIn::SphericalTlPlTvPv,
        ParamIn::Cartesian,
    ];

    /// ALTA's name of the parametrization.
    pub fn name(self) -> &'static str {
        match self {
            ParamIn::IsotropicTlTvProjDphi => "ISOTROPIC_TL_TV_PROJ_DPHI",
            ParamIn::IsotropicTvTlDphi => "ISOTROPIC_TV_TL_DPHI",
            ParamIn::RusinThTdPd => "RUSIN_TH_TD_PD",
            ParamIn::RusinThPhTdPd => "RUSIN_TH_PH_TD_PD",
            ParamIn::SphericalTlPlTvPv => "SPHERICAL_TL_PL_TV_PV",
            ParamIn::Cartesian => "CARTESIAN",
        }
    }

    pub fn parse(s: &str) -> Option<ParamIn> {
        ParamIn::ALL.into_iter().find(|p| p.name() == s)
    }

    /// Number of input columns.
    pub fn dim(self) -> usize {
        match self {
            ParamIn::IsotropicTlTvProjDphi | ParamIn::IsotropicTvTlDphi | ParamIn::RusinThTdPd => 3,
            ParamIn::RusinThPhTdPd | ParamIn::SphericalTlPlTvPv => 4,
            ParamIn::Cartesian => 6,
        }
    }

    /// Whether the parametrization assumes an isotropic BRDF (no absolute azimuth).
    pub fn isotropic(self) -> bool {
        matches!(
            self,
            ParamIn::IsotropicTlTvProjDphi | ParamIn::IsotropicTvTlDphi | ParamIn::RusinThTdPd
        )
    }

    /// ALTA's `to_cartesian`: the (V, L) = (ωo, ωi) of the coordinates `x` (radians),
    /// as written (not normalised or checked).
    pub fn to_cartesian(self, x: &[f64]) -> (DVec3, DVec3) {
        let dir = |t: f64, p: f64| DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos());
        match self {
            ParamIn::IsotropicTlTvProjDphi => {
                let theta = x[1].hypot(x[2]);
                let v = if theta > 0.0 {
                    DVec3::new(
                        x[1] / theta * theta.sin(),
                        x[2] / theta * theta.sin(),
                        theta.cos(),
                    )
                } else {
                    DVec3::Z
                };
                (v, dir(x[0], 0.0))
            }
            ParamIn::IsotropicTvTlDphi => (dir(x[0], 0.0), dir(x[1], x[2])),
            ParamIn::RusinThTdPd => half_to_cartesian(x[0], 0.0, x[1], x[2]),
            ParamIn::RusinThPhTdPd => half_to_cartesian(x[0], x[1], x[2], x[3]),
            ParamIn::SphericalTlPlTvPv => (dir(x[2], x[3]), dir(x[0], x[1])),
            ParamIn::Cartesian => (DVec3::new(x[0], x[1], x[2]), DVec3::new(x[3], x[4], x[5])),
        }
    }
}

/// Rusinkiewicz half/difference angles to (V, L) as ALTA defines it: V = Rz(φh)·Ry(θh)·D,
/// L = 2(V·H)H − V.
pub fn half_to_cartesian(theta_h: f64, phi_h: f64, theta_d: f64, phi_d: f64) -> (DVec3, DVec3) {
    let h = DVec3::new(
        theta_h.sin() * phi_h.cos(),
        theta_h.sin() * phi_h.sin(),
        theta_h.cos(),
    );
    let d = DVec3::new(
        theta_d.sin() * phi_d.cos(),
        theta_d.sin() * phi_d.sin(),
        theta_d.cos(),
    );
    let v = rot_z(rot_y(d, theta_h), phi_h);
    let l = 2.0 * v.dot(h) * h - v;
    (v, l)
}

/// Right-handed rotation by `a` about +y.
pub(crate) fn rot_y(v: DVec3, a: f64) -> DVec3 {
    let (s, c) = a.sin_cos();
    DVec3::new(c * v.x + s * v.z, v.y, -s * v.x + c * v.z)
}

/// Right-handed rotation by `a` about +z.
pub(crate) fn rot_z(v: DVec3, a: f64) -> DVec3 {
    let (s, c) = a.sin_cos();
    DVec3::new(c * v.x - s * v.y, s * v.x + c * v.y, v.z)
}

/// Rotate (ωi, ωo) about the normal so that φi = 0 (exact for an isotropic BRDF). At
/// normal incidence (sin θi ≤ 1e-12, rounding) ωi is set to +z and nothing is rotated.
pub(crate) fn to_phi_i_zero(wi: DVec3, wo: DVec3) -> (DVec3, DVec3) {
    let s = wi.x.hypot(wi.y);
    if s <= 1e-12 {
        return (DVec3::Z, wo);
    }
    let a = -wi.y.atan2(wi.x);
    let (mut i, o) = (rot_z(wi, a), rot_z(wo, a));
    i.y = 0.0; // exactly in the plane φ = 0
    (i, o)
}

/// (θ, φ) in degrees of a unit upper-hemisphere vector, φ in [0, 360) (0 at the pole).
pub(crate) fn angles_deg(w: DVec3) -> (f64, f64) {
    // atan2 keeps full precision near the pole, where acos(z) loses half the digits.
    let theta = w.x.hypot(w.y).atan2(w.z).to_degrees();
    let phi = if w.x == 0.0 && w.y == 0.0 {
        0.0
    } else {
        w.y.atan2(w.x).to_degrees().rem_euclid(360.0)
    };
    (theta, if phi >= 360.0 { 0.0 } else { phi })
}

/// Normalise a direction read from a file; `None` (with the reason) when it is not one.
fn checked_unit(w: DVec3, what: &str, strict_length: bool) -> Result<DVec3, String> {
    let n = w.length();
    if !n.is_finite() || n == 0.0 {
        return Err(format!("the {what} direction has length {n}"));
    }
    if strict_length && (n - 1.0).abs() > 1e-3 {
        return Err(format!(
            "the {what} vector ({}, {}, {}) is not of unit length ({n})",
            w.x, w.y, w.z
        ));
    }
    let mut u = w / n;
    if u.z < -1e-9 {
        return Err(format!(
            "the {what} direction is below the surface (z = {:.6}; θ = {:.4}°)",
            u.z,
            u.z.clamp(-1.0, 1.0).acos().to_degrees()
        ));
    }
    if u.z < 0.0 {
        u.z = 0.0;
        u = u.normalize();
    }
    Ok(u)
}

/// The output parametrizations this reader converts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParamOut {
    InvSteradian,
    InvSteradianCosineFactor,
    RgbColor,
}

impl ParamOut {
    pub fn name(self) -> &'static str {
        match self {
            ParamOut::InvSteradian => "INV_STERADIAN",
            ParamOut::InvSteradianCosineFactor => "INV_STERADIAN_COSINE_FACTOR",
            ParamOut::RgbColor => "RGB_COLOR",
        }
    }

    pub fn parse(s: &str) -> Option<ParamOut> {
        [
            ParamOut::InvSteradian,
            ParamOut::InvSteradianCosineFactor,
            ParamOut::RgbColor,
        ]
        .into_iter()
        .find(|p| p.name() == s)
    }

    fn dim(self) -> usize {
        match self {
            ParamOut::RgbColor => 3,
            _ => 1,
        }
    }

    /// What the values are, in words (for messages).
    pub fn meaning(self) -> &'static str {
        match self {
            ParamOut::InvSteradian => "the BRDF, sr⁻¹",
            ParamOut::InvSteradianCosineFactor => "BRDF × cos θo",
            ParamOut::RgbColor => "R, G, B BRDF values",
        }
    }
}

/// What the values of an ALTA file without `#PARAM_OUT` are (`--alta-values`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum AltaValues {
    /// The values are the BRDF in sr⁻¹ (what `#PARAM_OUT INV_STERADIAN` says).
    Brdf,
    /// The values are BRDF × cos θo, θo the outgoing (view) direction's polar angle; they
    /// are divided by cos θo, rows at grazing θo dropped (what `#PARAM_OUT
    /// INV_STERADIAN_COSINE_FACTOR` says).
    BrdfCos,
}

impl AltaValues {
    /// The option's spelling of the value.
    pub fn name(self) -> &'static str {
        match self {
            AltaValues::Brdf => "brdf",
            AltaValues::BrdfCos => "brdf-cos",
        }
    }

    /// What the values are, in words.
    pub fn meaning(self) -> &'static str {
        ParamOut::from(self).meaning()
    }
}

impl From<AltaValues> for ParamOut {
    fn from(v: AltaValues) -> ParamOut {
        match v {
            AltaValues::Brdf => ParamOut::InvSteradian,
            AltaValues::BrdfCos => ParamOut::InvSteradianCosineFactor,
        }
    }
}

impl std::fmt::Display for AltaValues {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The validated header.
struct Header {
    param_in: ParamIn,
    param_out: ParamOut,
    /// `Some` when the file has no `#PARAM_OUT` and the output kind came from the option.
    from_option: Option<AltaValues>,
    /// Interval columns per output (0, 1 or 2).
    vs: Vec<usize>,
    /// (key, value) of the other header lines.
    other: Vec<(String, String)>,
}

/// Parse ALTA text; `file` names the source in messages.
pub fn parse(text: &str, file: &str, opts: &ReadOptions) -> Result<Dataset, DataError> {
    parse_reader(text.as_bytes(), file, opts, &mut |_| {})
}

/// Once the header is read: it, the builder, and the assumed (REL, ABS) if any.
type Reading<'a> = (Header, Builder<'a>, Option<(f64, f64)>);

/// Parse ALTA text from a reader, one line at a time (see the module documentation).
pub fn parse_reader<R: BufRead>(
    mut reader: R,
    file: &str,
    opts: &ReadOptions,
    progress: &mut dyn FnMut(Progress),
) -> Result<Dataset, DataError> {
    let ferr = |msg: String| DataError::File {
        file: file.into(),
        msg,
    };
    let lerr = |line: usize, msg: String| DataError::Line {
        file: file.into(),
        line,
        msg,
    };
    let mut header = HeaderLines::default();
    let mut state: Option<Reading> = None;
    let mut buf = Vec::with_capacity(256);
    let (mut line, mut bytes) = (0usize, 0u64);
    let mut grazing = 0usize;
    loop {
        buf.clear();
        let n = reader
            .read_until(b'\n', &mut buf)
            .map_err(|e| ferr(format!("cannot read after line {line}: {e}")))?;
        if n == 0 {
            break;
        }
        line += 1;
        bytes += n as u64;
        if line % PROGRESS_EVERY_LINES == 0 {
            progress(Progress {
                bytes,
                rows: state.as_ref().map_or(0, |s| s.1.len()),
            });
        }
        let text = match decode_line(&buf, line) {
            Ok(t) => t,
            Err(msg) => match &mut state {
                Some((_, b, _)) => {
                    b.error(line, msg);
                    continue;
                }
                None => return Err(lerr(line, msg)),
            },
        };
        let t = text.trim();
        if t.is_empty() {
            continue;
        }
        if let Some(rest) = t.strip_prefix('#') {
            if state.is_none() {
                header.take(rest, line, file)?;
            }
            continue;
        }
        if state.is_none() {
            state = Some(start_reading(&header, file, opts)?);
        }
        let Some((h, b, assumed)) = &mut state else {
            unreachable!("state was just set")
        };
        match convert_row(t, h, *assumed) {
            Err(msg) => b.error(line, msg),
            Ok(None) => grazing += 1,
            Ok(Some(rows)) => {
                for r in rows.into_iter().flatten() {
                    b.push(line, r, Some(&text));
                }
            }
        }
    }
    let Some((h, mut b, assumed)) = state else {
        // No data line: say what is wrong with the header first, if anything.
        header.parse(file, opts)?;
        return Err(ferr("no data rows".into()));
    };
    progress(Progress {
        bytes,
        rows: b.len(),
    });
    let (material, meta) = material_and_meta(&h, file);
    let mut notes = reading_notes(&h, file, opts, assumed, grazing);
    notes.append(&mut b.notices);
    b.notices = notes;
    let mut ds = b.finish(&material, meta)?;
    if let Some((rel, abs)) = assumed {
        mark_assumed(&mut ds, rel, abs);
    }
    Ok(ds)
}

/// The header lines read so far: each `#KEY value` with its line, and the keys in file
/// order.
#[derive(Default)]
struct HeaderLines {
    keys: BTreeMap<String, (usize, String)>,
    order: Vec<String>,
    /// `#ALTA END HEADER` (or `#ALTA HEADER END`) was seen: later `#` lines are comments.
    closed: bool,
}

impl HeaderLines {
    /// Take the `#` line `#rest` of the header; comments (`# …`, `##…`, a bare `#`, or any
    /// line after the header's end) are skipped. A key given twice is an error.
    fn take(&mut self, rest: &str, line: usize, file: &str) -> Result<(), DataError> {
        if self.closed
            || rest.is_empty()
            || rest.starts_with(char::is_whitespace)
            || rest.starts_with('#')
        {
            return Ok(()); // a comment
        }
        let (key, value) = match rest.split_once(char::is_whitespace) {
            Some((k, v)) => (k, v.trim()),
            None => (rest, ""),
        };
        if key == "ALTA" {
            if value.split_ascii_whitespace().any(|w| w == "END") {
                self.closed = true;
            }
            return Ok(());
        }
        if self.keys.contains_key(key) {
            return Err(DataError::Line {
                file: file.into(),
                line,
                msg: format!("#{key} is given twice"),
            });
        }
        self.order.push(key.to_string());
        self.keys.insert(key.to_string(), (line, value.to_string()));
        Ok(())
    }

    /// The validated header.
    fn parse(&self, file: &str, opts: &ReadOptions) -> Result<Header, DataError> {
        parse_header(&self.keys, &self.order, file, opts)
    }
}

/// At the first data line: validate the header, check that the uncertainties are given
/// or assumed, and start the builder.
fn start_reading<'a>(
    header: &HeaderLines,
    file: &'a str,
    opts: &'a ReadOptions,
) -> Result<Reading<'a>, DataError> {
    let header = header.parse(file, opts)?;
    let assumed = if header.vs.contains(&0) {
        Some(require_assumption(
            file,
            opts,
            "this ALTA file (no #VS intervals)",
        )?)
    } else {
        None
    };
    Ok((header, Builder::new(Kind::Brdf, file, opts), assumed))
}

/// The material (`#SAMPLE`, else the file stem) and the metadata: the source format and
/// the other header lines as `alta_<key>`.
fn material_and_meta(h: &Header, file: &str) -> (String, BTreeMap<String, String>) {
    let mut meta = BTreeMap::new();
    meta.insert(
        "source_format".to_string(),
        format!(
            "ALTA text, #PARAM_IN {} #PARAM_OUT {}{}",
            h.param_in.name(),
            h.param_out.name(),
            match h.from_option {
                Some(v) => format!(" (not in the file: from --alta-values {v})"),
                None => String::new(),
            }
        ),
    );
    let mut material = Path::new(file)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    for (k, v) in &h.other {
        let v = v.trim_matches('"').to_string();
        if k.eq_ignore_ascii_case("SAMPLE") && !v.is_empty() {
            material = v.clone();
        }
        meta.insert(format!("alta_{}", k.to_ascii_lowercase()), v);
    }
    (material, meta)
}

/// The notices saying how the file was read: the conversion of its parametrization, its
/// value kind and channels, its intervals, and the grazing rows dropped.
fn reading_notes(
    h: &Header,
    file: &str,
    opts: &ReadOptions,
    assumed: Option<(f64, f64)>,
    grazing: usize,
) -> Vec<String> {
    let mut notes = vec![format!(
        "{file}: ALTA {} converted to (θi, φi, θo, φo) with ωi = L, ωo = V{}",
        h.param_in.name(),
        if h.param_in.isotropic() {
            ", rotated about the normal to φi = 0 (isotropic parametrization)"
        } else {
            ""
        }
    )];
    if let Some(v) = h.from_option {
        notes.push(format!(
            "{file}: #PARAM_OUT not given: value kind taken from --alta-values {v} ({}; read as #PARAM_OUT {})",
            v.meaning(),
            h.param_out.name()
        ));
    }
    match h.param_out {
        ParamOut::InvSteradianCosineFactor => notes.push(format!(
            "{file}: INV_STERADIAN_COSINE_FACTOR values divided by cos θo (the view direction's) to give the BRDF"
        )),
        ParamOut::RgbColor => notes.push(format!(
            "{file}: RGB_COLOR outputs read as channels at nominal wavelengths R {} nm, G {} nm, B {} nm",
            NOMINAL_RGB_NM[0], NOMINAL_RGB_NM[1], NOMINAL_RGB_NM[2]
        )),
        ParamOut::InvSteradian => {}
    }
    if h.param_out != ParamOut::RgbColor {
        notes.push(format!(
            "{file}: ALTA gives no wavelength; the single channel is labelled {NOMINAL_MONO_NM} nm (nominal)"
        ));
    }
    if h.vs.iter().any(|&k| k > 0) {
        notes.push(format!(
            "{file}: #VS intervals [y − a₋, y + a₊] taken as bounds of a rectangular distribution: u = (a₋ + a₊)/(2√3) (GUM 4.3.7)"
        ));
        if opts.assume_uncertainty.is_some() && assumed.is_none() {
            notes.push(format!(
                "{file}: --assume-uncertainty ignored: the file gives its own intervals"
            ));
        }
    }
    if grazing > 0 {
        notes.push(format!(
            "{file}: {} at grazing θo (cos θo < {GRAZING_COS:e}) dropped: the cosine factor cannot be removed there",
            count(grazing, "row", "rows")
        ));
    }
    notes
}

/// Validate the header lines into a [`Header`]: `#FORMAT`, `#DIM` against the
/// parametrizations' dimensions, `#PARAM_IN`, `#PARAM_OUT` (or `--alta-values`) and `#VS`.
fn parse_header(
    keys: &BTreeMap<String, (usize, String)>,
    order: &[String],
    file: &str,
    opts: &ReadOptions,
) -> Result<Header, DataError> {
    let ferr = |msg: String| DataError::File {
        file: file.into(),
        msg,
    };
    let lerr = |line: usize, msg: String| DataError::Line {
        file: file.into(),
        line,
        msg,
    };
    if let Some((line, v)) = keys.get("FORMAT") {
        if !v.eq_ignore_ascii_case("text") {
            return Err(lerr(
                *line,
                format!("#FORMAT {v}: only ALTA's text format is read (convert binary files with ALTA's data2data)"),
            ));
        }
    }
    let Some((dim_line, dim)) = keys.get("DIM") else {
        return Err(ferr(
            "missing #DIM line (ALTA header: #DIM N P, the input and output dimensions)".into(),
        ));
    };
    let dims: Vec<usize> = dim
        .split_ascii_whitespace()
        .map(|s| s.parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| {
            lerr(
                *dim_line,
                format!("#DIM {dim}: expected two positive integers N P"),
            )
        })?;
    let [n_in, n_out] = dims[..] else {
        return Err(lerr(
            *dim_line,
            format!("#DIM {dim}: expected two positive integers N P"),
        ));
    };
    let param_in = param_in(keys, file)?;
    if n_in != param_in.dim() {
        return Err(lerr(
            *dim_line,
            format!(
                "#DIM {dim}: {} has {} input dimensions, not {n_in}",
                param_in.name(),
                param_in.dim()
            ),
        ));
    }
    let (param_out, from_option) = param_out(keys, file, n_out, opts.alta_values)?;
    if n_out != param_out.dim() {
        return Err(lerr(
            *dim_line,
            format!(
                "#DIM {dim}: {} has {} output(s), not {n_out}",
                param_out.name(),
                param_out.dim()
            ),
        ));
    }
    let vs = interval_columns(keys, file, n_out)?;
    let known = ["DIM", "PARAM_IN", "PARAM_OUT", "VS", "FORMAT"];
    let other = order
        .iter()
        .filter(|k| !known.contains(&k.as_str()))
        .filter_map(|k| keys.get(k).map(|(_, v)| (k.clone(), v.clone())))
        .collect();
    Ok(Header {
        param_in,
        param_out,
        from_option,
        vs,
        other,
    })
}

/// The input parametrization from `#PARAM_IN`.
fn param_in(keys: &BTreeMap<String, (usize, String)>, file: &str) -> Result<ParamIn, DataError> {
    let names = |v: &[&str]| v.join(", ");
    let Some((in_line, pin)) = keys.get("PARAM_IN") else {
        return Err(DataError::File {
            file: file.into(),
            msg: format!(
                "missing #PARAM_IN line (the input parametrization; read here: {})",
                names(&ParamIn::ALL.map(|p| p.name()))
            ),
        });
    };
    ParamIn::parse(pin.trim()).ok_or_else(|| DataError::Line {
        file: file.into(),
        line: *in_line,
        msg: format!(
            "#PARAM_IN {pin} is not read here (supported: {})",
            names(&ParamIn::ALL.map(|p| p.name()))
        ),
    })
}

/// The interval columns of each of the `n_out` outputs from `#VS` (0, 1 or 2; none
/// without the line).
fn interval_columns(
    keys: &BTreeMap<String, (usize, String)>,
    file: &str,
    n_out: usize,
) -> Result<Vec<usize>, DataError> {
    let Some((line, v)) = keys.get("VS") else {
        return Ok(vec![0; n_out]);
    };
    let lerr = |msg: String| DataError::Line {
        file: file.into(),
        line: *line,
        msg,
    };
    let ks: Vec<usize> = v
        .split_ascii_whitespace()
        .map(|s| s.parse::<usize>().ok().filter(|k| *k <= 2))
        .collect::<Option<_>>()
        .ok_or_else(|| {
            lerr(format!(
                "#VS {v}: expected 0, 1 or 2 (once, or once per output)"
            ))
        })?;
    match ks.len() {
        1 => Ok(vec![ks[0]; n_out]),
        k if k == n_out => Ok(ks),
        _ => Err(lerr(format!(
            "#VS {v}: expected one value or {n_out} (one per output)"
        ))),
    }
}

/// The output kind from `#PARAM_OUT` and `--alta-values` ([`ReadOptions::alta_values`]):
/// `(kind, Some(option))` when the file does not say and the option does.
fn param_out(
    keys: &BTreeMap<String, (usize, String)>,
    file: &str,
    n_out: usize,
    option: Option<AltaValues>,
) -> Result<(ParamOut, Option<AltaValues>), DataError> {
    let ferr = |msg: String| DataError::File {
        file: file.into(),
        msg,
    };
    let lerr = |line: usize, msg: String| DataError::Line {
        file: file.into(),
        line,
        msg,
    };
    // ALTA writes UNKNOWN_OUTPUT for a file that does not say: the same as no line.
    let given = keys
        .get("PARAM_OUT")
        .filter(|(_, v)| v.trim() != "UNKNOWN_OUTPUT");
    let Some((out_line, pout)) = given else {
        let unknown = keys.get("PARAM_OUT").map(|(line, _)| *line);
        let err = |msg: String| match unknown {
            Some(line) => lerr(line, format!("#PARAM_OUT UNKNOWN_OUTPUT: {msg}")),
            None => ferr(format!("missing #PARAM_OUT line: {msg}")),
        };
        return match option {
            _ if n_out != 1 => Err(err(format!(
                "#DIM gives {n_out} outputs, and --alta-values describes one (brdf or brdf-cos); R, G, B BRDF values need the header line #PARAM_OUT RGB_COLOR"
            ))),
            None => Err(err(format!(
                "say what the values are with --alta-values brdf ({}) or --alta-values brdf-cos ({})",
                AltaValues::Brdf.meaning(),
                AltaValues::BrdfCos.meaning()
            ))),
            Some(v) => Ok((v.into(), Some(v))),
        };
    };
    let param_out = ParamOut::parse(pout.trim()).ok_or_else(|| {
        lerr(
            *out_line,
            format!(
                "#PARAM_OUT {pout} is not read here (supported: INV_STERADIAN, INV_STERADIAN_COSINE_FACTOR, RGB_COLOR)"
            ),
        )
    })?;
    if let Some(v) = option {
        if ParamOut::from(v) != param_out {
            return Err(lerr(
                *out_line,
                format!(
                    "#PARAM_OUT {} ({}) disagrees with --alta-values {v} ({})",
                    param_out.name(),
                    param_out.meaning(),
                    v.meaning()
                ),
            ));
        }
    }
    Ok((param_out, None))
}

/// One data line to its rows (one per output), `None` for a grazing cosine-weighted row.
fn convert_row(
    t: &str,
    h: &Header,
    assumed: Option<(f64, f64)>,
) -> Result<Option<[Option<RawRow>; 3]>, String> {
    let n_in = h.param_in.dim();
    let n_out = h.param_out.dim();
    let n_ci: usize = h.vs.iter().sum();
    let expected = n_in + n_out + n_ci;
    let mut x = [0f64; 16];
    let mut found = 0usize;
    for tok in t.split_ascii_whitespace() {
        if found < x.len() {
            x[found] = tok.parse::<f64>().map_err(|_| {
                let hint = if tok.contains(',') || tok.contains(';') {
                    " (ALTA columns are separated by blanks)"
                } else {
                    ""
                };
                format!("column {} = '{tok}' is not a number{hint}", found + 1)
            })?;
        }
        found += 1;
    }
    if found != expected {
        return Err(format!(
            "expected {expected} columns ({n_in} input{} + {n_out} output{}{}), found {found}",
            if n_in == 1 { "" } else { "s" },
            if n_out == 1 { "" } else { "s" },
            if n_ci > 0 {
                format!(
                    " + {n_ci} #VS interval column{}",
                    if n_ci == 1 { "" } else { "s" }
                )
            } else {
                String::new()
            }
        ));
    }
    if let Some(k) = x[..expected].iter().position(|v| !v.is_finite()) {
        return Err(format!(
            "column {} = {} is not a finite number",
            k + 1,
            x[k]
        ));
    }
    let (v, l) = h.param_in.to_cartesian(&x[..n_in]);
    let strict = h.param_in == ParamIn::Cartesian;
    let mut wo = checked_unit(v, "view (outgoing)", strict)?;
    let mut wi = checked_unit(l, "light (incident)", strict)?;
    if h.param_in.isotropic() {
        (wi, wo) = to_phi_i_zero(wi, wo);
    }
    let cos_o = wo.z;
    let cosine = h.param_out == ParamOut::InvSteradianCosineFactor;
    if cosine && cos_o < GRAZING_COS {
        return Ok(None);
    }
    let (ti, pi) = angles_deg(wi);
    let (to, po) = angles_deg(wo);
    let mut rows = [None, None, None];
    let mut ci = n_in + n_out;
    for (j, row) in rows.iter_mut().enumerate().take(n_out) {
        let y = x[n_in + j];
        let u = match h.vs[j] {
            0 => {
                let (rel, abs) = assumed.expect("checked when the header was read");
                super::assumed_uncertainty(y, rel, abs)
            }
            k => {
                let (lo, hi) = if k == 1 {
                    (x[ci], x[ci])
                } else {
                    (x[ci], x[ci + 1])
                };
                if lo < 0.0 || hi < 0.0 {
                    return Err(format!(
                        "#VS interval of output {}: distances {lo}, {hi} must be ≥ 0",
                        j + 1
                    ));
                }
                ci += k;
                (lo + hi) / (2.0 * 3f64.sqrt())
            }
        };
        let (value, u) = if cosine {
            (y / cos_o, u / cos_o)
        } else {
            (y, u)
        };
        *row = Some(RawRow {
            theta_i: ti,
            phi_i: pi,
            theta_o: to,
            phi_o: po,
            wavelength_nm: if h.param_out == ParamOut::RgbColor {
                NOMINAL_RGB_NM[j]
            } else {
                NOMINAL_MONO_NM
            },
            value,
            uncertainty: u,
        });
    }
    Ok(Some(rows))
}
