//! Zemax tabular BSDF files (the "BSDF Data Interchange" format of Radiant Imaging, read
//! by Zemax OpticStudio and other optical design programs), read into bsdfit's
//! convention. docs/data-formats.md gives the format, the definitions this reader rests
//! on, and a worked example.
//!
//! ```text
//! # comments
//! Source  Measured
//! Symmetry  PlaneSymmetrical | Asymmetrical | Asymmetrical4D
//! SpectralContent  Monochrome | XYZ
//! ScatterType  BRDF | BTDF
//! SampleRotation  N        then N angles (degrees)
//! AngleOfIncidence  N      then N angles
//! ScatterAzimuth  N        then N angles
//! ScatterRadial  N         then N angles
//!
//! Monochrome               (or TristimulusX, TristimulusY, TristimulusZ: one section each)
//! DataBegin
//! TIS 0.134506             then one row per azimuth, one value per radial angle
//! …                        one TIS and table per incidence, for every sample rotation
//! DataEnd
//! ```
//!
//! - **Geometry**: [`geometry`] (each cell's (θi, φi, θo, φo), from the format's
//!   definitions; tested and documented there).
//! - **Values** are BSDF values in sr⁻¹ (the format tabulates "BSDF data"; a Lambertian
//!   surface of reflectance ρ is the constant ρ/π). They are read as they are: **TIS is
//!   not used to scale them**. TIS ("total integrated scatter") is the fraction of the
//!   incident power scattered, ∫ f cos θs dω; real tables need not integrate to it (their
//!   grid stops short of the horizon, cells beyond it are zero, the TIS line may come from
//!   another measurement), so the reader reports how far the table's own integral
//!   ([`geometry::table_integral`]) is from each TIS line and keeps the TIS values as
//!   metadata (`zemax_tis`).
//! - **Masked cells**: a value of exactly 0 or NaN is no measurement (writers fill the
//!   cells they did not measure, beyond the horizon or the instrument's reach, with zeros)
//!   and is skipped; cells beyond the horizon (θo ≥ 90°) have no BSDF and are skipped;
//!   both are counted in a notice.
//! - **Repeated directions**: the radial-0 column (the specular direction) is written once
//!   per azimuth, and an azimuth list with both 0° and 360° writes one direction twice;
//!   such cells are one geometry, read once with their mean (a notice says how much they
//!   differed). The half of a PlaneSymmetrical table that is not written is not mirrored
//!   in: mirrored cells are not measurements.
//! - **Channels**: Monochrome has no wavelength: the channel is labelled 550 nm
//!   (nominal) unless a `# wavelength_nm: W` comment (written by bsdfit) gives it;
//!   TristimulusX, Y, Z become three channels at the nominal 600, 555, 445 nm (the peaks
//!   of x̄, ȳ, z̄), with a notice.
//! - **Uncertainties**: none in the format: `--assume-uncertainty` is required.
//!
//! Every error names `file:line:column`.

pub mod geometry;
mod header;

use super::text::{blank_tokens, end_column, locate, number, LineReader};
use super::{mark_assumed, require_assumption, ReadProgress};
use crate::data::Notice;
use crate::data::{
    geometry_key, Builder, Cells, DataError, Dataset, RawRow, ReadOptions, PROGRESS_EVERY_LINES,
};
use crate::text::plural_with as count;
use geometry::{cell_geometry, incident_azimuth, table_integral, HORIZON_COS};
pub use header::{Header, Spectral, Symmetry, MAX_ANGLES, SYMMETRIES};
use header::{HeaderLines, Pos};
use std::collections::{BTreeMap, HashMap};
use std::io::BufRead;
use std::path::Path;

/// Nominal wavelength (nm) of a Monochrome table without a `# wavelength_nm:` comment.
pub const NOMINAL_MONO_NM: f64 = 550.0;
/// Nominal wavelengths (nm) of the TristimulusX, Y, Z tables: the peaks of the CIE 1931
/// colour-matching functions x̄ (main lobe), ȳ, z̄.
pub const NOMINAL_XYZ_NM: [f64; 3] = [600.0, 555.0, 445.0];
/// The spectral indicators of the data sections, in channel order.
pub const INDICATORS: [&str; 4] = ["Monochrome", "TristimulusX", "TristimulusY", "TristimulusZ"];

/// Does this text look like a Zemax BSDF file? Its first line that is neither blank nor a
/// `#` comment starts with a keyword of the header.
pub fn looks_like(first_line: &str) -> bool {
    let word = first_line.split_whitespace().next().unwrap_or("");
    ["Source", "Symmetry", "SpectralContent", "ScatterType"]
        .iter()
        .chain(header::LISTS.iter())
        .any(|k| k.eq_ignore_ascii_case(word))
}

/// The header of a Zemax BSDF file (its layout: symmetry, spectral content, kind and the
/// four angle lists), read up to the start of the data; the tables are not read.
pub fn read_header<R: BufRead>(reader: R, file: &str) -> Result<Header, DataError> {
    let mut lines = LineReader::new(reader, file);
    let mut header = HeaderLines::default();
    while let Some(text) = lines.next_line()? {
        let line = lines.line;
        let t = text.trim();
        if t.is_empty() {
            continue;
        }
        if t.starts_with('#') {
            header.comment(&text, line, file)?;
        } else if header.take(&text, line, file)? {
            return header.finish(file, (line, 1));
        }
    }
    let at = lines.line.max(1);
    header.finish(file, (at, 1))?;
    Err(DataError::at(
        file,
        at,
        1,
        "no data after the header".into(),
    ))
}

/// Parse Zemax BSDF text; `file` names the source in messages.
pub fn parse(text: &str, file: &str, opts: &ReadOptions) -> Result<Dataset, DataError> {
    parse_reader(text.as_bytes(), file, opts, &mut |_| {})
}

/// The table being read: its block (rotation × incidence), TIS and values so far.
struct Table {
    block: usize,
    /// The line of its TIS.
    tis_line: usize,
    tis: f64,
    rows: usize,
    /// Values at (azimuth j, radial k), NaN where masked; with their (line, column).
    values: Vec<(f64, Pos)>,
}

/// The state of the data part.
struct Reading<'a> {
    h: Header,
    b: Builder<'a>,
    assumed: (f64, f64),
    /// The current section's channel (index into [`INDICATORS`]) and whether DataBegin
    /// opened it.
    channel: Option<usize>,
    open: bool,
    /// Tables completed per channel.
    done: [usize; 4],
    table: Option<Table>,
    counts: Counts,
    /// (block, channel, TIS, the table's own integral).
    tis: Vec<(usize, usize, f64, Option<f64>)>,
    data_begin: Pos,
}

/// What was skipped or merged, for the notices.
#[derive(Default)]
struct Counts {
    masked: usize,
    beyond: usize,
    beyond_nonzero: usize,
    merged: usize,
    merged_spread: f64,
}

/// Parse Zemax BSDF text from a reader, one line at a time.
pub fn parse_reader<R: BufRead>(
    reader: R,
    file: &str,
    opts: &ReadOptions,
    progress: &mut dyn FnMut(ReadProgress),
) -> Result<Dataset, DataError> {
    let mut lines = LineReader::new(reader, file);
    let mut header = HeaderLines::default();
    let mut state: Option<Reading> = None;
    let mut comments: Vec<String> = Vec::new();
    while let Some(text) = lines.next_line()? {
        let line = lines.line;
        if line.is_multiple_of(PROGRESS_EVERY_LINES) {
            let rows = state.as_ref().map_or(0, |s| s.b.len());
            progress(ReadProgress {
                bytes: lines.bytes,
                rows,
            });
        }
        let t = text.trim();
        if t.is_empty() {
            continue;
        }
        if t.starts_with('#') {
            if state.is_none() {
                header.comment(&text, line, file)?;
                if comments.len() < 20 {
                    comments.push(t.trim_start_matches('#').trim().to_string());
                }
            }
            continue;
        }
        if state.is_none() {
            if !header.take(&text, line, file)? {
                continue;
            }
            let h = std::mem::take(&mut header).finish(file, (line, 1))?;
            state = Some(start(h, file, opts, (line, 1))?);
        }
        let s = state.as_mut().expect("set above");
        s.take(&text, line, file)?;
    }
    let Some(mut s) = state else {
        let at = (lines.line.max(1), 1);
        header.finish(file, at)?;
        return Err(DataError::at(file, at.0, at.1, "no data: the header is not followed by a spectral indicator (Monochrome, TristimulusX…), DataBegin and the tables".into()));
    };
    progress(ReadProgress {
        bytes: lines.bytes,
        rows: s.b.len(),
    });
    s.end(file, (lines.line, end_column("")))?;
    s.finish(file, opts, comments)
}

/// At the first data line: the uncertainty assumption and the builder.
fn start<'a>(
    h: Header,
    file: &'a str,
    opts: &'a ReadOptions,
    at: Pos,
) -> Result<Reading<'a>, DataError> {
    let assumed = require_assumption(file, opts, "this Zemax BSDF file")
        .map_err(|e| locate(e, at.0, at.1))?;
    let b = Builder::new(h.kind, file, opts);
    Ok(Reading {
        h,
        b,
        assumed,
        channel: None,
        open: false,
        done: [0; 4],
        table: None,
        counts: Counts::default(),
        tis: Vec::new(),
        data_begin: at,
    })
}

impl Reading<'_> {
    fn blocks(&self) -> usize {
        self.h.rotations.len() * self.h.incidences.len()
    }

    /// The channels a file of this spectral content has (indices into [`INDICATORS`]).
    fn channels(&self) -> &'static [usize] {
        match self.h.spectral {
            Spectral::Monochrome => &[0],
            Spectral::Xyz => &[1, 2, 3],
        }
    }

    /// One non-blank, non-comment line of the data part.
    fn take(&mut self, text: &str, line: usize, file: &str) -> Result<(), DataError> {
        let tokens = blank_tokens(text);
        let first = tokens[0];
        let at = (line, first.column);
        let e = |at: Pos, msg: String| DataError::at(file, at.0, at.1, msg);
        if number(first.text).is_ok() {
            return self.row(text, line, file);
        }
        if let Some(t) = &self.table {
            return Err(e(at, format!(
                "'{}' where the table of TIS line {} expects its row {} of {} (one per ScatterAzimuth angle)",
                first.text, t.tis_line, t.rows + 1, self.h.azimuths.len()
            )));
        }
        let word = first.text.to_ascii_lowercase();
        if let Some(extra) = tokens.get(if word == "tis" { 2 } else { 1 }) {
            return Err(e(
                (line, extra.column),
                format!("unexpected '{}' after {}", extra.text, first.text),
            ));
        }
        if let Some(c) = INDICATORS
            .iter()
            .position(|i| i.eq_ignore_ascii_case(&word))
        {
            return self.indicator(c, at, file);
        }
        match word.as_str() {
            "databegin" => {
                if self.open {
                    return Err(e(at, "DataBegin inside a data section (no DataEnd before it)".into()));
                }
                if self.channel.is_none() && self.h.spectral == Spectral::Monochrome {
                    self.channel = Some(0);
                }
                if self.channel.is_none() {
                    return Err(e(at, "DataBegin without a spectral indicator before it (TristimulusX, TristimulusY or TristimulusZ for SpectralContent XYZ)".into()));
                }
                self.open = true;
                Ok(())
            }
            "dataend" => self.end(file, at),
            "tis" => self.start_table(&tokens, text, line, file),
            _ => Err(e(at, format!(
                "'{}' is not part of the data (a spectral indicator, DataBegin, TIS, a row of values, or DataEnd)",
                first.text
            ))),
        }
    }

    /// A spectral indicator: the next section's channel.
    fn indicator(&mut self, c: usize, at: Pos, file: &str) -> Result<(), DataError> {
        let e = |msg: String| DataError::at(file, at.0, at.1, msg);
        if !self.channels().contains(&c) {
            return Err(e(format!(
                "{} data in a file whose SpectralContent (line {}) is {}",
                INDICATORS[c],
                self.h.spectral_at.0,
                match self.h.spectral {
                    Spectral::Monochrome => "Monochrome",
                    Spectral::Xyz => "XYZ (TristimulusX, TristimulusY, TristimulusZ)",
                }
            )));
        }
        if let Some(cur) = self.channel {
            if self.done[cur] != 0 && self.done[cur] != self.blocks() {
                return Err(e(format!(
                    "{} begins while the {} section has {} of its {} tables",
                    INDICATORS[c],
                    INDICATORS[cur],
                    self.done[cur],
                    self.blocks()
                )));
            }
        }
        if self.done[c] != 0 {
            return Err(e(format!("a second {} section", INDICATORS[c])));
        }
        self.channel = Some(c);
        Ok(())
    }

    /// `TIS v`: a table begins.
    fn start_table(
        &mut self,
        tokens: &[super::text::Token],
        text: &str,
        line: usize,
        file: &str,
    ) -> Result<(), DataError> {
        let e = |at: Pos, msg: String| DataError::at(file, at.0, at.1, msg);
        let (Some(c), true) = (self.channel, self.open) else {
            return Err(e(
                (line, tokens[0].column),
                "TIS outside a data section (after DataBegin)".into(),
            ));
        };
        let Some(v) = tokens.get(1) else {
            return Err(e((line, end_column(text)), "TIS needs a value".into()));
        };
        let tis = match number(v.text) {
            Ok(Some(x)) if x >= 0.0 => x,
            Ok(Some(x)) => return Err(e((line, v.column), format!("TIS {x} is negative"))),
            Ok(None) => f64::NAN,
            Err(m) => return Err(e((line, v.column), format!("TIS {m}"))),
        };
        if self.done[c] == self.blocks() {
            return Err(e(
                (line, tokens[0].column),
                format!(
                    "a table beyond the {} of the header ({} sample rotation(s) × {} incidence(s))",
                    self.blocks(),
                    self.h.rotations.len(),
                    self.h.incidences.len()
                ),
            ));
        }
        self.table = Some(Table {
            block: self.done[c],
            tis_line: line,
            tis,
            rows: 0,
            values: Vec::with_capacity(self.h.azimuths.len() * self.h.radials.len()),
        });
        Ok(())
    }

    /// A row of values: one per radial angle, at the table's next azimuth.
    fn row(&mut self, text: &str, line: usize, file: &str) -> Result<(), DataError> {
        let nr = self.h.radials.len();
        let tokens = blank_tokens(text);
        let Some(t) = self.table.as_mut() else {
            return Err(DataError::at(
                file,
                line,
                tokens[0].column,
                "a row of values outside a table (each table starts with a TIS line)".into(),
            ));
        };
        if tokens.len() != nr {
            let col = tokens.get(nr).map_or(end_column(text), |t| t.column);
            return Err(DataError::at(
                file,
                line,
                col,
                format!(
                    "expected {nr} values (one per ScatterRadial angle), found {}",
                    tokens.len()
                ),
            ));
        }
        for tok in &tokens {
            let v = number(tok.text).map_err(|m| DataError::at(file, line, tok.column, m))?;
            t.values.push((v.unwrap_or(f64::NAN), (line, tok.column)));
        }
        t.rows += 1;
        if t.rows == self.h.azimuths.len() {
            let t = self.table.take().expect("checked");
            self.finish_table(t);
        }
        Ok(())
    }

    /// A complete table: its cells into the builder, its TIS compared with its integral.
    fn finish_table(&mut self, t: Table) {
        let c = self.channel.expect("a table is in a section");
        let h = &self.h;
        let nr = h.radials.len();
        let rotation = h.rotations[t.block / h.incidences.len()];
        let aoi = h.incidences[t.block % h.incidences.len()];
        let wl = match h.spectral {
            Spectral::Monochrome => h.wavelength.unwrap_or(NOMINAL_MONO_NM),
            Spectral::Xyz => NOMINAL_XYZ_NM[c - 1],
        };
        // One geometry per direction: (key) → (row, sum, n, min, max, place).
        let mut cells: Vec<(RawRow, f64, usize, f64, f64, Pos)> = Vec::new();
        let mut index: HashMap<[i64; 5], usize> = HashMap::new();
        let mut for_integral = vec![0.0; t.values.len()];
        for (n, &(v, at)) in t.values.iter().enumerate() {
            let g = cell_geometry(rotation, aoi, h.azimuths[n / nr], h.radials[n % nr]);
            if g.cos_o <= HORIZON_COS {
                self.counts.beyond += 1;
                self.counts.beyond_nonzero += usize::from(v != 0.0 && !v.is_nan());
                continue;
            }
            if v == 0.0 || v.is_nan() {
                self.counts.masked += 1;
                continue;
            }
            for_integral[n] = v;
            let r = RawRow {
                theta_i: g.theta_i,
                phi_i: g.phi_i,
                theta_o: g.theta_o,
                phi_o: g.phi_o,
                wavelength_nm: wl,
                value: v,
                uncertainty: 0.0,
            };
            let key = geometry_key(r.theta_i, r.phi_i, r.theta_o, r.phi_o, wl);
            match index.get(&key) {
                Some(&i) => {
                    let m = &mut cells[i];
                    (m.1, m.2, m.3, m.4) = (m.1 + v, m.2 + 1, m.3.min(v), m.4.max(v));
                    self.counts.merged += 1;
                }
                None => {
                    index.insert(key, cells.len());
                    cells.push((r, v, 1, v, v, at));
                }
            }
        }
        let (rel, abs) = self.assumed;
        for (mut r, sum, n, lo, hi, at) in cells {
            // Repeated directions (the radial-0 column) usually repeat one value: keep
            // it exactly rather than a mean that rounds it by an ulp.
            r.value = if lo == hi { lo } else { sum / n as f64 };
            r.uncertainty = super::assumed_uncertainty(r.value, rel, abs);
            if n > 1 {
                let spread = (hi - lo) / r.value.abs().max(f64::MIN_POSITIVE);
                self.counts.merged_spread = self.counts.merged_spread.max(spread);
            }
            self.b.push_at(at.0, r, None, &Cells::all(at.1));
        }
        let integral = table_integral(
            aoi,
            incident_azimuth(rotation),
            &h.azimuths,
            &h.radials,
            &for_integral,
            h.symmetry == Symmetry::PlaneSymmetrical,
        );
        self.tis.push((t.block, c, t.tis, integral));
        self.done[c] += 1;
    }

    /// `DataEnd` (or the end of the file at `at`): the section must be complete.
    fn end(&mut self, file: &str, at: Pos) -> Result<(), DataError> {
        let e = |msg: String| DataError::at(file, at.0, at.1, msg);
        if let Some(t) = &self.table {
            return Err(e(format!(
                "the table of the TIS line at line {} has {} of its {} rows (one per ScatterAzimuth angle)",
                t.tis_line, t.rows, self.h.azimuths.len()
            )));
        }
        if let Some(c) = self.channel {
            if self.done[c] != self.blocks() {
                return Err(e(format!(
                    "the {} section has {} of its {} tables ({} sample rotation(s) × {} incidence(s), each a TIS line and its rows)",
                    INDICATORS[c], self.done[c], self.blocks(), self.h.rotations.len(), self.h.incidences.len()
                )));
            }
        }
        self.open = false;
        Ok(())
    }

    /// All sections read: check that every channel is there, then build the dataset.
    fn finish(
        mut self,
        file: &str,
        opts: &ReadOptions,
        comments: Vec<String>,
    ) -> Result<Dataset, DataError> {
        let at = self.data_begin;
        if let Some(&c) = self.channels().iter().find(|&&c| self.done[c] == 0) {
            return Err(DataError::at(
                file,
                self.h.spectral_at.0,
                self.h.spectral_at.1,
                format!(
                    "no {} section: SpectralContent {} needs one",
                    INDICATORS[c],
                    if self.h.spectral == Spectral::Xyz {
                        "XYZ"
                    } else {
                        "Monochrome"
                    }
                ),
            ));
        }
        let mut notes: Vec<Notice> = self
            .notes(file, opts)
            .into_iter()
            .map(Notice::from)
            .collect();
        notes.append(&mut self.b.notices);
        self.b.notices = notes;
        let (material, meta) = self.material_and_meta(file, comments);
        let mut ds = self
            .b
            .finish(&material, meta)
            .map_err(|e| locate(e, at.0, at.1))?;
        mark_assumed(&mut ds, self.assumed.0, self.assumed.1);
        Ok(ds)
    }

    fn notes(&self, file: &str, _opts: &ReadOptions) -> Vec<String> {
        let h = &self.h;
        let mut notes = vec![format!(
            "{file}: Zemax BSDF ({}, {}): cells read as BSDF values in sr⁻¹ at (θi, φi = sample rotation + 90°, θ{o}, φ{o}) about the {} direction (docs/data-formats.md)",
            h.symmetry.name(),
            h.kind.to_string().to_uppercase(),
            if h.kind == crate::data::Kind::Btdf { "direct transmission" } else { "specular" },
            o = if h.kind == crate::data::Kind::Btdf { "t" } else { "o" },
        )];
        match (h.spectral, h.wavelength) {
            (Spectral::Monochrome, None) => notes.push(format!(
                "{file}: Monochrome data give no wavelength; the channel is labelled {NOMINAL_MONO_NM} nm (nominal)"
            )),
            (Spectral::Xyz, _) => notes.push(format!(
                "{file}: TristimulusX, Y, Z read as channels at the nominal {} nm (peaks of x̄, ȳ, z̄)",
                NOMINAL_XYZ_NM.map(|w| w.to_string()).join(", ")
            )),
            _ => {}
        }
        let c = &self.counts;
        if c.masked + c.beyond > 0 {
            notes.push(format!(
                "{file}: {} skipped: {} masked (0 or NaN: no measurement) and {} beyond the horizon ({} of them non-zero)",
                count(c.masked + c.beyond, "cell", "cells"), c.masked, c.beyond, c.beyond_nonzero
            ));
        }
        if c.merged > 0 {
            notes.push(format!(
                "{file}: {} repeat a direction of their table (the radial-0 column at every azimuth, or azimuths 0° and 360°): each direction read once, the mean of its cells (they differ by up to {:.3}%)",
                count(c.merged, "cell", "cells"), 100.0 * c.merged_spread
            ));
        }
        let ratios: Vec<f64> = self
            .tis
            .iter()
            .filter_map(|&(_, _, t, i)| i.filter(|_| t > 0.0).map(|i| i / t))
            .collect();
        if let (Some(lo), Some(hi)) = (
            ratios.iter().copied().reduce(f64::min),
            ratios.iter().copied().reduce(f64::max),
        ) {
            notes.push(format!(
                "{file}: the tables integrate to {lo:.3}–{hi:.3} of their TIS lines (∫ f cos θ dω, trapezoidal rule on the table's own grid, zero beyond it); TIS is kept as metadata, not used to scale the values"
            ));
        }
        notes
    }

    fn material_and_meta(
        &self,
        file: &str,
        comments: Vec<String>,
    ) -> (String, BTreeMap<String, String>) {
        let h = &self.h;
        let mut meta = BTreeMap::new();
        meta.insert(
            "source_format".into(),
            format!(
                "Zemax BSDF, Symmetry {}, SpectralContent {}, ScatterType {}",
                h.symmetry.name(),
                if h.spectral == Spectral::Xyz {
                    "XYZ"
                } else {
                    "Monochrome"
                },
                h.kind.to_string().to_uppercase()
            ),
        );
        if let Some(s) = &h.source {
            meta.insert("zemax_source".into(), s.clone());
        }
        let comments: Vec<String> = comments.into_iter().filter(|c| !c.is_empty()).collect();
        if !comments.is_empty() {
            meta.insert("zemax_comments".into(), comments.join(" | "));
        }
        let tis: Vec<String> = self
            .tis
            .iter()
            .map(|&(block, c, t, _)| {
                let rot = h.rotations[block / h.incidences.len()];
                let aoi = h.incidences[block % h.incidences.len()];
                let ch = if h.spectral == Spectral::Xyz {
                    format!("{} ", INDICATORS[c])
                } else {
                    String::new()
                };
                format!("{ch}rotation {rot} AOI {aoi}: {t}")
            })
            .collect();
        meta.insert("zemax_tis".into(), tis.join("; "));
        let material = Path::new(file)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        (material, meta)
    }
}
