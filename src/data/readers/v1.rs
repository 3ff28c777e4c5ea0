//! The bsdfit v1 CSV reader (docs/conventions.md): `# key: value` metadata lines, a
//! header naming the seven columns (in any order), then one row per sample, read as a
//! stream straight into the dataset's [`Builder`].

use crate::data::readers::ReadProgress;
use crate::data::{
    Builder, DataError, Dataset, Kind, RawRow, ReadOptions, COLUMNS, PROGRESS_EVERY_LINES,
};
use crate::data::{Notice, NoticeKind};
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::Path;

fn strip_line_end(mut raw: &[u8]) -> &[u8] {
    if let Some(r) = raw.strip_suffix(b"\n") {
        raw = r;
    }
    if let Some(r) = raw.strip_suffix(b"\r") {
        raw = r;
    }
    raw
}

/// The text of one line read as bytes: UTF-8 as is (a BOM on line 1 skipped); a comment
/// line (`#…`) with other bytes is decoded lossily; any other line with them is an error
/// message naming the byte.
pub(crate) fn decode_line(raw: &[u8], line: usize) -> Result<std::borrow::Cow<'_, str>, String> {
    let mut raw = strip_line_end(raw);
    if line == 1 {
        raw = raw.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(raw);
    }
    match std::str::from_utf8(raw) {
        Ok(s) => Ok(std::borrow::Cow::Borrowed(s)),
        Err(e) => {
            if raw.trim_ascii_start().starts_with(b"#") {
                return Ok(String::from_utf8_lossy(raw));
            }
            let at = e.valid_up_to();
            Err(format!(
                "not valid UTF-8 (byte 0x{:02X} at column {}); save the file as UTF-8",
                raw.get(at).copied().unwrap_or(0),
                at + 1
            ))
        }
    }
}

/// A cell as written: trimmed, one pair of surrounding double quotes removed.
fn cell(s: &str) -> &str {
    let s = s.trim();
    s.strip_prefix('"')
        .and_then(|t| t.strip_suffix('"'))
        .map(str::trim)
        .unwrap_or(s)
}

fn delimiter_hint(t: &str) -> &'static str {
    if t.contains('\t') {
        " (it contains tabs: v1 files are comma-separated)"
    } else if t.contains(';') {
        " (it contains ';': v1 files are comma-separated, with '.' as the decimal mark)"
    } else {
        ""
    }
}

/// The header line: which column holds each of [`COLUMNS`], and how many cells a row has.
fn parse_header(t: &str) -> Result<([usize; 7], usize), String> {
    let names: Vec<&str> = t.split(',').map(cell).collect();
    if names.len() == 1 && !delimiter_hint(t).is_empty() {
        return Err(format!(
            "the header has no ','{}: expected {}",
            delimiter_hint(t),
            COLUMNS.join(",")
        ));
    }
    if let Some(k) = names.iter().position(|n| n.is_empty()) {
        let hint = if k + 1 == names.len() {
            "a trailing comma?"
        } else {
            "two commas in a row?"
        };
        return Err(format!(
            "empty column name (column {} of {}; {hint}); expected {}",
            k + 1,
            names.len(),
            COLUMNS.join(",")
        ));
    }
    let mut index = [0usize; 7];
    for (k, col) in COLUMNS.iter().enumerate() {
        // Spreadsheets capitalise headers: the names match whatever their case.
        match names.iter().position(|n| n.eq_ignore_ascii_case(col)) {
            Some(p) => index[k] = p,
            None => {
                return Err(format!(
                    "missing column '{col}' (header: {})",
                    names.join(",")
                ))
            }
        }
    }
    if let Some(extra) = names
        .iter()
        .find(|n| !COLUMNS.iter().any(|c| n.eq_ignore_ascii_case(c)))
    {
        return Err(format!("unexpected column '{extra}'"));
    }
    if names.len() != COLUMNS.len() {
        return Err(format!(
            "a column is named twice (header: {})",
            names.join(",")
        ));
    }
    Ok((index, names.len()))
}

fn parse_row(t: &str, index: &[usize; 7], ncols: usize) -> Result<RawRow, String> {
    let cells: Vec<&str> = t.split(',').map(cell).collect();
    if cells.len() != ncols {
        let hint = if cells.len() == ncols + 1 && cells.last().is_some_and(|c| c.is_empty()) {
            " (a trailing comma?)"
        } else {
            delimiter_hint(t)
        };
        return Err(format!(
            "expected {ncols} cells, found {}{hint}",
            cells.len()
        ));
    }
    let mut v = [0f64; 7];
    for k in 0..7 {
        let c = cells[index[k]];
        v[k] = c.parse::<f64>().map_err(|_| {
            let hint = if c.contains(';') {
                " (';' is not a separator in v1 files)"
            } else {
                ""
            };
            format!("column {} = '{c}' is not a number{hint}", COLUMNS[k])
        })?;
    }
    Ok(RawRow {
        theta_i: v[0],
        phi_i: v[1],
        theta_o: v[2],
        phi_o: v[3],
        wavelength_nm: v[4],
        value: v[5],
        uncertainty: v[6],
    })
}

impl Dataset {
    /// Parse v1 CSV text; `file` names the source in messages.
    pub fn parse(text: &str, file: &str, opts: &ReadOptions) -> Result<Dataset, DataError> {
        Self::parse_reader(text.as_bytes(), file, opts, &mut |_| {})
    }

    /// Parse v1 CSV from a reader, one line at a time: each row goes straight into its
    /// sample, so memory is that of the dataset (128 bytes a sample) plus 12 bytes a row
    /// for the repeated-geometry pass. `progress` is called every [`PROGRESS_EVERY_LINES`] lines
    /// and at the end. A UTF-8 byte-order mark is skipped; bytes that are not UTF-8 are
    /// accepted in comments and reported elsewhere; every bad row is reported (up to
    /// [`crate::data::MAX_REPORTED_ERRORS`]).
    pub fn parse_reader<R: BufRead>(
        mut reader: R,
        file: &str,
        opts: &ReadOptions,
        progress: &mut dyn FnMut(ReadProgress),
    ) -> Result<Dataset, DataError> {
        let mut meta = BTreeMap::new();
        let mut buf = Vec::with_capacity(256);
        let (mut line, mut bytes) = (0usize, 0u64);
        let mut header: Option<([usize; 7], usize)> = None;
        let mut builder: Option<Builder> = None;
        let line_err = |line: usize, msg: String| DataError::Line {
            file: file.to_string(),
            line,
            msg,
        };
        loop {
            buf.clear();
            let n = reader
                .read_until(b'\n', &mut buf)
                .map_err(|e| DataError::File {
                    file: file.into(),
                    msg: format!("cannot read after line {line}: {e}"),
                })?;
            if n == 0 {
                break;
            }
            line += 1;
            bytes += n as u64;
            if line % PROGRESS_EVERY_LINES == 0 {
                progress(ReadProgress {
                    bytes,
                    rows: builder.as_ref().map_or(0, |b| b.len()),
                });
            }
            let text = match decode_line(&buf, line) {
                Ok(t) => t,
                Err(msg) => match &mut builder {
                    Some(b) => {
                        b.error(line, msg);
                        continue;
                    }
                    None => return Err(line_err(line, msg)),
                },
            };
            let t = text.trim();
            if t.is_empty() {
                continue;
            }
            match (&mut builder, &header) {
                (Some(b), Some((index, ncols))) => {
                    if t.starts_with('#') {
                        continue;
                    }
                    match parse_row(t, index, *ncols) {
                        Ok(r) => b.push(line, r, Some(&text)),
                        Err(msg) => b.error(line, msg),
                    }
                }
                _ => {
                    if let Some(rest) = t.strip_prefix('#') {
                        if let Some((k, v)) = rest.split_once(':') {
                            // "# bsdfit dataset v1" has no colon; a remark after the value is kept.
                            meta.insert(k.trim().to_string(), v.trim().to_string());
                        }
                        continue;
                    }
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
                    header = Some(parse_header(t).map_err(|m| line_err(line, m))?);
                    builder = Some(Builder::new(kind, file, opts));
                }
            }
        }
        let Some(mut b) = builder else {
            return Err(DataError::File {
                file: file.into(),
                msg: format!("no header line (expected: {})", COLUMNS.join(",")),
            });
        };
        progress(ReadProgress {
            bytes,
            rows: b.len(),
        });
        let material = meta.get("material").cloned().unwrap_or_else(|| {
            Path::new(file)
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        });
        // A v1 file written from data whose uncertainties were assumed says so.
        let assumed = meta
            .get("uncertainty")
            .and_then(|u| crate::data::readers::parse_assumed_note(u));
        if let (Some(_), Some(note)) = (assumed, meta.get("uncertainty")) {
            b.notices.push(Notice::new(
                NoticeKind::AssumedUncertainty,
                format!("{file}: uncertainties {note}"),
            ));
        }
        if opts.assume_uncertainty.is_some() {
            b.notices.push(Notice::new(
                NoticeKind::AssumptionIgnored,
                format!(
                    "{file}: --assume-uncertainty ignored: the file gives its own uncertainties"
                ),
            ));
        }
        let mut ds = b.finish(&material, meta)?;
        ds.assumed_uncertainty = assumed;
        Ok(ds)
    }
}
