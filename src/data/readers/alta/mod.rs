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
use super::{mark_assumed, require_assumption, ReadProgress};
use crate::data::{Builder, DataError, Dataset, Kind, RawRow, ReadOptions, PROGRESS_EVERY_LINES};
use crate::data::{Notice, NoticeKind};
use crate::text::plural_with as count;
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::Path;

mod header;
mod params;

use header::{Header, HeaderLines};
use params::checked_unit;
pub(crate) use params::{angles_deg, rot_y, rot_z, to_phi_i_zero};
pub use params::{half_to_cartesian, AltaValues, ParamIn, ParamOut};

/// Nominal wavelengths (nm) given to `RGB_COLOR` outputs: R, G, B.
pub const NOMINAL_RGB_NM: [f64; 3] = [650.0, 550.0, 450.0];
/// Nominal wavelength (nm) given to a single output.
pub const NOMINAL_MONO_NM: f64 = 550.0;
/// Rows of cosine-weighted data with cos θo below this are dropped.
pub const GRAZING_COS: f64 = 1e-6;

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
    progress: &mut dyn FnMut(ReadProgress),
) -> Result<Dataset, DataError> {
    let ferr = |msg: String| DataError::in_file(file, msg);
    let lerr = |line: usize, msg: String| DataError::at_line(file, line, msg);
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
            progress(ReadProgress {
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
    progress(ReadProgress {
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
) -> Vec<Notice> {
    let mut notes = vec![Notice::from(format!(
        "{file}: ALTA {} converted to (θi, φi, θo, φo) with ωi = L, ωo = V{}",
        h.param_in.name(),
        if h.param_in.isotropic() {
            ", rotated about the normal to φi = 0 (isotropic parametrization)"
        } else {
            ""
        }
    ))];
    if let Some(v) = h.from_option {
        notes.push(Notice::from(format!(
            "{file}: #PARAM_OUT not given: value kind taken from --alta-values {v} ({}; read as #PARAM_OUT {})",
            v.meaning(),
            h.param_out.name()
        )));
    }
    match h.param_out {
        ParamOut::InvSteradianCosineFactor => notes.push(Notice::from(format!(
            "{file}: INV_STERADIAN_COSINE_FACTOR values divided by cos θo (the view direction's) to give the BRDF"
        ))),
        ParamOut::RgbColor => notes.push(Notice::from(format!(
            "{file}: RGB_COLOR outputs read as channels at nominal wavelengths R {} nm, G {} nm, B {} nm",
            NOMINAL_RGB_NM[0], NOMINAL_RGB_NM[1], NOMINAL_RGB_NM[2]
        ))),
        ParamOut::InvSteradian => {}
    }
    if h.param_out != ParamOut::RgbColor {
        notes.push(Notice::from(format!(
            "{file}: ALTA gives no wavelength; the single channel is labelled {NOMINAL_MONO_NM} nm (nominal)"
        )));
    }
    if h.vs.iter().any(|&k| k > 0) {
        notes.push(Notice::from(format!(
            "{file}: #VS intervals [y − a₋, y + a₊] taken as bounds of a rectangular distribution: u = (a₋ + a₊)/(2√3) (GUM 4.3.7)"
        )));
        if opts.assume_uncertainty.is_some() && assumed.is_none() {
            notes.push(Notice::new(
                NoticeKind::AssumptionIgnored,
                format!("{file}: --assume-uncertainty ignored: the file gives its own intervals"),
            ));
        }
    }
    if grazing > 0 {
        notes.push(Notice::from(format!(
            "{file}: {} at grazing θo (cos θo < {GRAZING_COS:e}) dropped: the cosine factor cannot be removed there",
            count(grazing, "row", "rows")
        )));
    }
    notes
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
