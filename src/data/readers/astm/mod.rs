//! ASTM E1392 angle-resolved scatter text files, read into bsdfit's convention.
//! docs/data-formats.md gives the layout, what the standard leaves open and what this
//! reader chose, and a worked example.
//!
//! ```text
//! SOURCE  …                     keyword lines: KEY value (any keywords; kept as metadata)
//! SAMPLE_NAME "white paint"     the material
//! NUM_POINTS 1439               checked against the number of data rows
//! ANGLE_UNITS DEG | RAD         bsdfit's declaration of the angle unit (or a unit in VARS)
//! VARS theta_i,phi_i,theta_s,phi_s,400nm,410nm,…   the last header line
//! 0.0,0.0,0.1745,3.1416,0.0421,0.0425,…            one row per geometry
//! ```
//!
//! - **Angles**: (θi, φi) is the direction towards the source, (θs, φs) the scattered
//!   direction, both polar angles measured from the sample normal on the illuminated
//!   side, so a transmitted direction has θs > 90°: bsdfit's θt = 180° − θs, φt = φs. A
//!   file holds reflected or transmitted rows (BRDF or BTDF), not both. A negative θ is
//!   the same polar angle on the other side (φ + 180°). `phi_i` may be left out (0).
//! - **Unit**: the standard's public data files (Cornell's spectral BRDFs, which ALTA's
//!   and libbsdf's ASTM readers read) give radians and say nothing; bsdfit reads radians
//!   unless a line `ANGLE_UNITS DEG` or a unit in the angle names (`theta_i[deg]`,
//!   `theta_i(deg)`, `theta_i_deg`) says degrees. An undeclared angle outside the
//!   radian ranges is an error that says how to declare degrees.
//! - **Values**: BSDF values in sr⁻¹. Value columns named by a wavelength (`550`,
//!   `550nm`) are channels at those wavelengths; `R, G, B` and `X, Y, Z` get nominal
//!   wavelengths (650, 550, 450 and 600, 555, 445 nm); a single value column of another
//!   name (`BRDF`, `Integrated …`) is one channel at the `WAVELENGTH` keyword's value, or
//!   550 nm (nominal). A NaN cell is a masked value and is skipped.
//! - **Uncertainties**: a column `u_NAME` (or `u(NAME)`) holds the standard uncertainty
//!   (k = 1, sr⁻¹) of the value column NAME — bsdfit's extension, written last so that
//!   readers that do not know it can ignore it. Value columns without one need
//!   `--assume-uncertainty`.
//!
//! Every error names `file:line:column`.

mod vars;

use super::text::{blank_tokens, column_of, end_column, locate, number, LineReader};
use super::{mark_assumed, require_assumption, ReadProgress};
use crate::data::Notice;
use crate::data::{
    Builder, Cells, DataError, Dataset, Kind, RawRow, ReadOptions, PROGRESS_EVERY_LINES,
};
use crate::text::plural_with as count;
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::Path;
pub use vars::{AngleUnit, ValueName, Vars, ANGLES};

/// A place in the file: (line, column), both 1-based.
pub(crate) type Pos = (usize, usize);

/// Nominal wavelength (nm) of a single value column without a `WAVELENGTH` keyword.
pub const NOMINAL_MONO_NM: f64 = 550.0;
/// Nominal wavelengths (nm) of R, G, B columns.
pub const NOMINAL_RGB_NM: [f64; 3] = [650.0, 550.0, 450.0];
/// Nominal wavelengths (nm) of X, Y, Z columns (the peaks of x̄, ȳ, z̄).
pub const NOMINAL_XYZ_NM: [f64; 3] = [600.0, 555.0, 445.0];

/// Does this text look like an ASTM E1392 file? Its first line that is neither blank nor
/// `#` starts with an upper-case keyword, and a line starting with `VARS` follows within
/// `lines`.
pub fn looks_like<'a>(mut lines: impl Iterator<Item = &'a str>) -> bool {
    let is_key = |w: &str| {
        w.chars().next().is_some_and(|c| c.is_ascii_uppercase())
            && w.chars()
                .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
    };
    let mut content = lines
        .by_ref()
        .map(str::trim)
        .filter(|t| !t.is_empty() && !t.starts_with('#'));
    let Some(first) = content.next() else {
        return false;
    };
    let word = |t: &str| t.split_whitespace().next().unwrap_or("").to_string();
    if !is_key(&word(first)) {
        return false;
    }
    word(first) == "VARS" || content.any(|t| word(t) == "VARS")
}

/// Parse ASTM E1392 text; `file` names the source in messages.
pub fn parse(text: &str, file: &str, opts: &ReadOptions) -> Result<Dataset, DataError> {
    parse_reader(text.as_bytes(), file, opts, &mut |_| {})
}

/// The header lines before VARS.
#[derive(Default)]
struct Header {
    keys: Vec<(String, String)>,
    num_points: Option<(usize, Pos)>,
    unit: Option<(AngleUnit, Pos)>,
    wavelength: Option<f64>,
    sample_name: Option<String>,
}

/// The data part: the columns, and the rows so far.
struct Data<'a> {
    file: &'a str,
    opts: &'a ReadOptions,
    header: Header,
    vars: Vars,
    vars_line: usize,
    unit: AngleUnit,
    declared: bool,
    /// The wavelength of each value column.
    wavelengths: Vec<f64>,
    assumed: Option<(f64, f64)>,
    /// The kind, from the first row that is not grazing, and where.
    kind: Option<(Kind, Pos)>,
    /// Rows read before the kind was known.
    pending: Vec<(usize, RawRow, Cells)>,
    b: Option<Builder<'a>>,
    rows: usize,
    masked: usize,
}

/// Parse ASTM E1392 text from a reader, one line at a time.
pub fn parse_reader<R: BufRead>(
    reader: R,
    file: &str,
    opts: &ReadOptions,
    progress: &mut dyn FnMut(ReadProgress),
) -> Result<Dataset, DataError> {
    let mut lines = LineReader::new(reader, file);
    let mut header = Header::default();
    let mut data: Option<Data> = None;
    while let Some(text) = lines.next_line()? {
        let line = lines.line;
        if line.is_multiple_of(PROGRESS_EVERY_LINES) {
            let rows = data.as_ref().map_or(0, |d| d.rows);
            progress(ReadProgress {
                bytes: lines.bytes,
                rows,
            });
        }
        let t = text.trim();
        if t.is_empty() || t.starts_with('#') {
            continue;
        }
        match &mut data {
            Some(d) => d.row(&text, line)?,
            None => {
                if let Some(vars_text) = header_line(&mut header, &text, line, file)? {
                    let h = std::mem::take(&mut header);
                    data = Some(Data::new(h, vars_text, &text, line, file, opts)?);
                }
            }
        }
    }
    progress(ReadProgress {
        bytes: lines.bytes,
        rows: data.as_ref().map_or(0, |d| d.rows),
    });
    let Some(d) = data else {
        let at = lines.line.max(1);
        return Err(DataError::at(file, at, 1, "no VARS line: an ASTM E1392 header ends with VARS theta_i,phi_i,theta_s,phi_s,<value columns>".into()));
    };
    d.finish()
}

/// One header line. `Some(rest)` when it is the VARS line (its text after the keyword).
fn header_line<'t>(
    h: &mut Header,
    text: &'t str,
    line: usize,
    file: &str,
) -> Result<Option<&'t str>, DataError> {
    let tokens = blank_tokens(text);
    let key = tokens[0];
    let err = |col: usize, msg: String| DataError::at(file, line, col, msg);
    let is_key = key
        .text
        .chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic())
        && key
            .text
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_');
    if !is_key {
        return Err(err(key.column, format!(
            "'{}' is not a header keyword: an ASTM E1392 header is KEY value lines ending with VARS, before any data",
            key.text
        )));
    }
    let start = text.find(key.text).unwrap_or(0) + key.text.len();
    let rest = &text[start..];
    let value = rest.trim().trim_matches('"').trim().to_string();
    let value_col = column_of(text, start + (rest.len() - rest.trim_start().len()));
    let upper = key.text.to_ascii_uppercase();
    let once = |slot_full: bool| {
        if slot_full {
            Err(err(key.column, format!("{upper} is given twice")))
        } else {
            Ok(())
        }
    };
    match upper.as_str() {
        "VARS" => return Ok(Some(rest)),
        "NUM_POINTS" => {
            once(h.num_points.is_some())?;
            let n = value
                .parse::<usize>()
                .map_err(|_| err(value_col, format!("NUM_POINTS '{value}' is not a count")))?;
            h.num_points = Some((n, (line, value_col)));
        }
        "ANGLE_UNITS" | "ANGLE_UNIT" => {
            once(h.unit.is_some())?;
            let u = AngleUnit::parse(&value)
                .ok_or_else(|| err(value_col, format!("{upper} '{value}': expected DEG or RAD")))?;
            h.unit = Some((u, (line, value_col)));
        }
        "WAVELENGTH" => {
            once(h.wavelength.is_some())?;
            h.wavelength = Some(wavelength_value(&value).ok_or_else(|| {
                err(value_col, format!("WAVELENGTH '{value}': expected a wavelength such as 633, 633 nm or 0.633 um"))
            })?);
        }
        _ => {
            if upper == "SAMPLE_NAME" && !value.is_empty() {
                h.sample_name = Some(value.clone());
            }
            match h.keys.iter_mut().find(|(k, _)| *k == upper) {
                Some((_, v)) => *v = format!("{v}; {value}"),
                None => h.keys.push((upper, value)),
            }
        }
    }
    Ok(None)
}

/// `633`, `633 nm`, `0.633 um` (or µm): nm.
fn wavelength_value(s: &str) -> Option<f64> {
    let s = s.trim();
    let (num, scale) = if let Some(n) = s.strip_suffix("nm") {
        (n, 1.0)
    } else if let Some(n) = s.strip_suffix("um").or_else(|| s.strip_suffix("µm")) {
        (n, 1000.0)
    } else {
        (s, 1.0)
    };
    num.trim()
        .parse::<f64>()
        .ok()
        .map(|w| w * scale)
        .filter(|w| w.is_finite() && *w > 0.0)
}

impl<'a> Data<'a> {
    fn new(
        header: Header,
        vars_text: &str,
        text: &str,
        line: usize,
        file: &'a str,
        opts: &'a ReadOptions,
    ) -> Result<Data<'a>, DataError> {
        let offset = text.len() - vars_text.len();
        let mut names = vars::cells_of(vars_text);
        for t in &mut names {
            t.column += column_of(text, offset) - 1;
        }
        let vars = vars::parse(&names, line).map_err(|(p, m)| DataError::at(file, p.0, p.1, m))?;
        let (unit, declared) = match (header.unit, vars.unit) {
            (Some((a, pa)), Some((b, pb))) if a != b => {
                return Err(DataError::at(
                    file,
                    pb.0,
                    pb.1,
                    format!(
                        "this angle name says {} but line {} (column {}) says {}",
                        b.name(),
                        pa.0,
                        pa.1,
                        a.name()
                    ),
                ))
            }
            (Some((u, _)), _) | (None, Some((u, _))) => (u, true),
            (None, None) => (AngleUnit::Radians, false),
        };
        let wavelengths = channel_wavelengths(&vars, header.wavelength);
        let assumed = if vars.values.iter().any(|v| v.uncertainty.is_none()) {
            let missing = vars
                .values
                .iter()
                .find(|v| v.uncertainty.is_none())
                .expect("checked");
            Some(
                require_assumption(
                    file,
                    opts,
                    &format!("this ASTM E1392 file (no u_{} column)", missing.name),
                )
                .map_err(|e| locate(e, line, missing.at.1))?,
            )
        } else {
            None
        };
        Ok(Data {
            file,
            opts,
            header,
            vars,
            vars_line: line,
            unit,
            declared,
            wavelengths,
            assumed,
            kind: None,
            pending: Vec::new(),
            b: None,
            rows: 0,
            masked: 0,
        })
    }

    /// A data row: its geometry, then one sample per value column.
    fn row(&mut self, text: &str, line: usize) -> Result<(), DataError> {
        let file = self.file;
        let cells = vars::cells_of(text);
        if cells.len() != self.vars.cells {
            let col = cells
                .get(self.vars.cells)
                .map_or(end_column(text), |t| t.column);
            return Err(DataError::at(
                file,
                line,
                col,
                format!(
                    "expected {} cells (one per VARS name, line {}), found {}",
                    self.vars.cells,
                    self.vars_line,
                    cells.len()
                ),
            ));
        }
        self.rows += 1;
        let mut ang = [0.0f64; 4];
        let mut cols = [None; 4];
        for k in 0..4 {
            let Some(i) = self.vars.angles[k] else {
                continue;
            };
            let c = cells[i];
            let v = number(c.text)
                .map_err(|m| DataError::at(file, line, c.column, format!("{}: {m}", ANGLES[k])))?;
            ang[k] = v.ok_or_else(|| {
                DataError::at(file, line, c.column, format!("{} is NaN", ANGLES[k]))
            })? * self.unit.to_deg();
            cols[k] = Some(c.column);
        }
        let (ti, pi, ts, ps) = (ang[0], ang[1], ang[2], ang[3]);
        if ti.abs() > 90.0 + 1e-9 {
            return Err(DataError::at(
                file,
                line,
                cols[0].unwrap_or(1),
                self.range_msg("theta_i", ti, 90.0),
            ));
        }
        let (ts, ps) = if ts < 0.0 {
            (-ts, ps + 180.0)
        } else {
            (ts, ps)
        };
        if ts > 180.0 + 1e-9 {
            return Err(DataError::at(
                file,
                line,
                cols[2].unwrap_or(1),
                self.range_msg("theta_s", ts, 180.0),
            ));
        }
        let transmitted = ts > 90.0;
        let theta_o = if transmitted {
            180.0 - ts
        } else {
            ts.min(90.0)
        };
        if ts != 90.0 {
            self.set_kind(
                if transmitted { Kind::Btdf } else { Kind::Brdf },
                (line, cols[2].unwrap_or(1)),
            )?;
        }
        for (j, v) in self.vars.values.iter().enumerate() {
            let c = cells[v.index];
            let Some(value) = number(c.text)
                .map_err(|m| DataError::at(file, line, c.column, format!("{}: {m}", v.name)))?
            else {
                self.masked += 1;
                continue;
            };
            let (u, ucol) = match v.uncertainty {
                Some(k) => {
                    let uc = cells[k];
                    let u = number(uc.text).map_err(|m| {
                        DataError::at(file, line, uc.column, format!("u_{}: {m}", v.name))
                    })?;
                    (u.unwrap_or(f64::NAN), uc.column)
                }
                None => {
                    let (rel, abs) = self
                        .assumed
                        .expect("required when a column has no uncertainty");
                    (super::assumed_uncertainty(value, rel, abs), c.column)
                }
            };
            let r = RawRow {
                theta_i: ti,
                phi_i: pi,
                theta_o,
                phi_o: ps,
                wavelength_nm: self.wavelengths[j],
                value,
                uncertainty: u,
            };
            let where_ = Cells {
                theta_i: cols[0],
                phi_i: cols[1],
                theta_o: cols[2],
                phi_o: cols[3],
                wavelength: Some(c.column),
                value: Some(c.column),
                uncertainty: Some(ucol),
            };
            match &mut self.b {
                Some(b) => b.push_at(line, r, None, &where_),
                None => self.pending.push((line, r, where_)),
            }
        }
        Ok(())
    }

    fn range_msg(&self, name: &str, deg: f64, max: f64) -> String {
        if self.declared {
            format!("{name} = {deg}° is outside [-{max}, {max}] degrees")
        } else {
            format!(
                "{name} = {} rad is outside [-{}, {}] (radians, the unit when none is declared): if the angles are in degrees, say so with a header line ANGLE_UNITS DEG",
                deg.to_radians(), max.to_radians(), max.to_radians()
            )
        }
    }

    /// The kind from a row that is not grazing: the first sets it (and starts the
    /// builder), a later one of the other kind is an error.
    fn set_kind(&mut self, kind: Kind, at: Pos) -> Result<(), DataError> {
        match self.kind {
            Some((k, first)) if k != kind => Err(DataError::at(self.file, at.0, at.1, format!(
                "a {} direction (theta_s {} 90° from the normal on the illuminated side) after {} rows (line {}): a file holds reflected or transmitted data, not both",
                if kind == Kind::Btdf { "transmitted" } else { "reflected" },
                if kind == Kind::Btdf { ">" } else { "<" },
                if k == Kind::Btdf { "transmitted" } else { "reflected" },
                first.0
            ))),
            Some(_) => Ok(()),
            None => {
                self.kind = Some((kind, at));
                self.start_builder(kind);
                Ok(())
            }
        }
    }

    fn start_builder(&mut self, kind: Kind) {
        let mut b = Builder::new(kind, self.file, self.opts);
        for (line, r, c) in self.pending.drain(..) {
            b.push_at(line, r, None, &c);
        }
        self.b = Some(b);
    }

    /// After the last line: NUM_POINTS, the value names against the kind, the dataset.
    fn finish(mut self) -> Result<Dataset, DataError> {
        let file = self.file;
        if let Some((n, at)) = self.header.num_points {
            if n != self.rows {
                return Err(DataError::at(
                    file,
                    at.0,
                    at.1,
                    format!(
                        "NUM_POINTS {n} but the file has {} data rows (truncated, or rows added?)",
                        self.rows
                    ),
                ));
            }
        }
        if self.b.is_none() {
            let named_btdf = self
                .vars
                .values
                .iter()
                .any(|v| v.name.eq_ignore_ascii_case("btdf"));
            self.start_builder(if named_btdf { Kind::Btdf } else { Kind::Brdf });
        }
        let kind = self.b.as_ref().map_or(Kind::Brdf, |b| b.kind());
        let clash = if kind == Kind::Brdf { "btdf" } else { "brdf" };
        if let Some(v) = self
            .vars
            .values
            .iter()
            .find(|v| v.name.eq_ignore_ascii_case(clash))
        {
            if self.kind.is_some() {
                return Err(DataError::at(file, v.at.0, v.at.1, format!(
                    "VARS names the values {} but the rows' scatter directions are {} (theta_s {} 90°): ASTM E1392 measures every polar angle from the sample normal on the illuminated side, so a transmitted direction has theta_s > 90°",
                    v.name,
                    if kind == Kind::Brdf { "reflected" } else { "transmitted" },
                    if kind == Kind::Brdf { "≤" } else { ">" }
                )));
            }
        }
        let notes = self.notes();
        let (material, meta) = self.material_and_meta();
        let mut b = self.b.take().expect("started above");
        let mut all: Vec<Notice> = notes.into_iter().map(Notice::from).collect();
        all.append(&mut b.notices);
        b.notices = all;
        let mut ds = b
            .finish(&material, meta)
            .map_err(|e| locate(e, self.vars_line, 1))?;
        if let Some((rel, abs)) = self.assumed {
            mark_assumed(&mut ds, rel, abs);
        }
        Ok(ds)
    }

    fn notes(&self) -> Vec<String> {
        let file = self.file;
        let mut notes = vec![format!(
            "{file}: ASTM E1392 angles read as {}{}; polar angles from the normal on the illuminated side (theta_s > 90°: transmitted)",
            self.unit.name(),
            if self.declared { "" } else { " (none declared: the unit of the format's public data sets; a line ANGLE_UNITS DEG says degrees)" }
        )];
        let named: Vec<&str> = self
            .vars
            .values
            .iter()
            .filter_map(|v| match &v.what {
                ValueName::Named(n) => Some(n.as_str()),
                ValueName::Wavelength(_) => None,
            })
            .collect();
        if !named.is_empty() {
            let nominal = self.vars.values.len() > 1 || self.header.wavelength.is_none();
            notes.push(format!(
                "{file}: value column(s) {} read at {:?} nm{}",
                named.join(", "),
                self.wavelengths,
                if nominal {
                    " (nominal)"
                } else {
                    " (WAVELENGTH)"
                }
            ));
        }
        if self.vars.values.iter().any(|v| v.uncertainty.is_some()) {
            notes.push(format!(
                "{file}: standard uncertainties (k = 1) from the u_ columns"
            ));
        }
        if self.masked > 0 {
            notes.push(format!(
                "{file}: {} skipped (NaN)",
                count(self.masked, "masked value", "masked values")
            ));
        }
        notes
    }

    fn material_and_meta(&self) -> (String, BTreeMap<String, String>) {
        let mut meta = BTreeMap::new();
        meta.insert(
            "source_format".into(),
            format!("ASTM E1392 text, angles in {}", self.unit.name()),
        );
        for (k, v) in &self.header.keys {
            meta.insert(format!("astm_{}", k.to_ascii_lowercase()), v.clone());
        }
        let material = self.header.sample_name.clone().unwrap_or_else(|| {
            Path::new(self.file)
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        });
        (material, meta)
    }
}

/// The wavelength of each value column.
fn channel_wavelengths(vars: &Vars, keyword: Option<f64>) -> Vec<f64> {
    let upper: Vec<String> = vars
        .values
        .iter()
        .map(|v| v.name.to_ascii_uppercase())
        .collect();
    vars.values
        .iter()
        .zip(&upper)
        .map(|(v, u)| match &v.what {
            ValueName::Wavelength(w) => *w,
            ValueName::Named(_) if vars.values.len() == 3 => {
                let rgb = ["R", "G", "B"].iter().position(|c| c == u);
                let xyz = ["X", "Y", "Z"].iter().position(|c| c == u);
                match (rgb, xyz) {
                    (Some(k), _) => NOMINAL_RGB_NM[k],
                    (_, Some(k)) => NOMINAL_XYZ_NM[k],
                    _ => keyword.unwrap_or(NOMINAL_MONO_NM),
                }
            }
            ValueName::Named(_) => keyword.unwrap_or(NOMINAL_MONO_NM),
        })
        .collect()
}
