//! Mueller-matrix BRDF tables in comma-separated text, as NIST publishes its goniometric
//! measurements (T. A. Germer's sintered-PTFE data, Applied Optics 56, 2017,
//! written with the column names of NIST's SCATMECH library):
//!
//! ```text
//! lambda,thetai,phi,thetar,phir,f_r11,f_r12/f_r11,…,f_r44/f_r11
//! 0.532,-45,0,30.96,-10.2,2.9E-01,0.012,…
//! ```
//!
//! One header line naming the columns, then one row per geometry and wavelength:
//! `lambda` the wavelength in **micrometres**, `thetai`, `phi` (or `phii`), `thetar`,
//! `phir` in degrees, and `f_r11` (or `fr11`) the unpolarised BRDF in sr⁻¹, the Mueller
//! matrix's first element. The normalised Mueller elements that follow are not read (a
//! scalar BRDF is fitted), and a notice says so. Columns are found by name, in any order.
//!
//! Angles are signed: SCATMECH's regular grids write the incidence as θi ≤ 0 at φ = 0
//! (normal incidence as θi = −0.001°), the project's own convention (a negative θ is the
//! same direction at φ + 180°), so the rows read as written: the incident direction, the
//! direction toward the source, at (|θi|, 180°), its mirror direction at φr = 0. Every
//! direction must lie on the reflected hemisphere (|θ| ≤ 90°).
//!
//! These tables carry no uncertainties: reading one needs `--assume-uncertainty REL,ABS`
//! (see [`crate::data::readers`]).

use super::text::{comma_tokens, end_column, locate, number, LineReader};
use super::{mark_assumed, require_assumption, ReadProgress};
use crate::data::Notice;
use crate::data::{
    Builder, Cells, DataError, Dataset, Kind, RawRow, ReadOptions, PROGRESS_EVERY_LINES,
};
use crate::text::plural_with as count;
use std::collections::BTreeMap;
use std::io::BufRead;
use std::path::Path;

/// The columns read, each with the names it may have in a header (lower case).
const COLUMNS: [(&str, &[&str]); 6] = [
    ("wavelength", &["lambda"]),
    ("theta_i", &["thetai"]),
    ("phi_i", &["phi", "phii"]),
    ("theta_o", &["thetar"]),
    ("phi_o", &["phir"]),
    ("value", &["f_r11", "fr11"]),
];

/// Whether the first line that is not blank is this format's header: comma-separated
/// names including the wavelength, the angles and the Mueller matrix's first element.
pub fn looks_like(first_line: &str) -> bool {
    let names: Vec<String> = first_line
        .split(',')
        .map(|c| c.trim().to_ascii_lowercase())
        .collect();
    COLUMNS
        .iter()
        .all(|(_, aliases)| names.iter().any(|n| aliases.contains(&n.as_str())))
}

/// Parse a whole table held in memory.
pub fn parse(text: &str, file: &str, opts: &ReadOptions) -> Result<Dataset, DataError> {
    parse_reader(text.as_bytes(), file, opts, &mut |_| {})
}

/// Parse a table line by line (see the module documentation).
pub fn parse_reader<R: BufRead>(
    reader: R,
    file: &str,
    opts: &ReadOptions,
    progress: &mut dyn FnMut(ReadProgress),
) -> Result<Dataset, DataError> {
    let mut lines = LineReader::new(reader, file);
    let (header, header_line) = loop {
        match lines.next_line()? {
            None => {
                return Err(DataError::at(
                    file,
                    lines.line.max(1),
                    1,
                    "empty file: no header line".into(),
                ))
            }
            Some(t) if t.trim().is_empty() => continue,
            Some(t) => break (t, lines.line),
        }
    };
    let columns = locate_columns(&header, file, header_line)?;
    let width = comma_tokens(&header).len();
    let (rel, abs) = require_assumption(
        file,
        opts,
        "this Mueller-matrix BRDF table (no uncertainty column)",
    )
    .map_err(|e| locate(e, header_line, 1))?;
    let mut b = Builder::new(Kind::Brdf, file, opts);
    let (mut rows, mut masked) = (0usize, 0usize);
    let mut wavelengths: Vec<f64> = Vec::new();
    while let Some(text) = lines.next_line()? {
        let line = lines.line;
        if line.is_multiple_of(PROGRESS_EVERY_LINES) {
            progress(ReadProgress {
                bytes: lines.bytes,
                rows: b.len(),
            });
        }
        if text.trim().is_empty() {
            continue;
        }
        let cells = comma_tokens(&text);
        if cells.len() != width {
            let col = cells.get(width).map_or(end_column(&text), |t| t.column);
            return Err(DataError::at(
                file,
                line,
                col,
                format!(
                    "expected {width} cells (one per name of the header, line {header_line}), found {}",
                    cells.len()
                ),
            ));
        }
        rows += 1;
        let mut x = [0.0f64; 6];
        let mut at = [0usize; 6];
        let mut nan = false;
        for (k, &i) in columns.iter().enumerate() {
            let c = cells[i];
            at[k] = c.column;
            match number(c.text).map_err(|m| {
                DataError::at(file, line, c.column, format!("{}: {m}", COLUMNS[k].0))
            })? {
                Some(v) => x[k] = v,
                // A NaN value is a masked cell; a NaN angle or wavelength is an error.
                None if k == 5 => nan = true,
                None => {
                    return Err(DataError::at(
                        file,
                        line,
                        c.column,
                        format!("{} is NaN", COLUMNS[k].0),
                    ))
                }
            }
        }
        if nan {
            masked += 1;
            continue;
        }
        for (k, name) in [(1, "thetai"), (3, "thetar")] {
            if x[k].abs() > 90.0 + 1e-9 {
                return Err(DataError::at(
                    file,
                    line,
                    at[k],
                    format!(
                        "{name} = {}° is outside [-90, 90] degrees (a BRDF table: both directions above the surface)",
                        x[k]
                    ),
                ));
            }
        }
        // (Finite: `number` refused the others.)
        if x[0] <= 0.0 {
            return Err(DataError::at(
                file,
                line,
                at[0],
                format!("lambda = {} µm: a wavelength must be > 0", x[0]),
            ));
        }
        let wavelength_nm = x[0] * 1000.0;
        if !wavelengths.contains(&wavelength_nm) {
            wavelengths.push(wavelength_nm);
        }
        let r = RawRow {
            theta_i: x[1],
            phi_i: x[2],
            theta_o: x[3],
            phi_o: x[4],
            wavelength_nm,
            value: x[5],
            uncertainty: super::assumed_uncertainty(x[5], rel, abs),
        };
        let cells = Cells {
            wavelength: Some(at[0]),
            theta_i: Some(at[1]),
            phi_i: Some(at[2]),
            theta_o: Some(at[3]),
            phi_o: Some(at[4]),
            value: Some(at[5]),
            uncertainty: Some(at[5]),
        };
        b.push_at(line, r, Some(&text), &cells);
    }
    progress(ReadProgress {
        bytes: lines.bytes,
        rows: b.len(),
    });
    if rows == 0 {
        return Err(DataError::at(
            file,
            header_line,
            1,
            "no data rows after the header".into(),
        ));
    }
    wavelengths.sort_by(f64::total_cmp);
    let mut notes = vec![
        Notice::from(format!(
            "{file}: Mueller-matrix BRDF table: f_r11 read as the BRDF (sr⁻¹), lambda in µm as nm ({:?}); the {} normalised Mueller elements not read",
            wavelengths,
            width.saturating_sub(6)
        )),
        Notice::from(format!(
            "{file}: signed angles (θ < 0: the direction at φ + 180°), as SCATMECH writes its incidences"
        )),
    ];
    if masked > 0 {
        notes.push(Notice::from(format!(
            "{file}: {} skipped (NaN)",
            count(masked, "masked value", "masked values")
        )));
    }
    notes.append(&mut b.notices);
    b.notices = notes;
    let material = Path::new(file)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut meta = BTreeMap::new();
    meta.insert(
        "source_format".into(),
        "Mueller-matrix BRDF CSV (NIST SCATMECH columns; f_r11 read)".into(),
    );
    let mut ds = b
        .finish(&material, meta)
        .map_err(|e| locate(e, header_line, 1))?;
    mark_assumed(&mut ds, rel, abs);
    Ok(ds)
}

/// The index of each of [`COLUMNS`] in the header's cells, or an error naming the missing one.
fn locate_columns(header: &str, file: &str, line: usize) -> Result<[usize; 6], DataError> {
    let cells = comma_tokens(header);
    let mut found = [0usize; 6];
    for (k, (what, aliases)) in COLUMNS.iter().enumerate() {
        let hits: Vec<usize> = cells
            .iter()
            .enumerate()
            .filter(|(_, c)| aliases.contains(&c.text.to_ascii_lowercase().as_str()))
            .map(|(i, _)| i)
            .collect();
        match hits.as_slice() {
            [i] => found[k] = *i,
            [] => {
                return Err(DataError::at(
                    file,
                    line,
                    end_column(header),
                    format!("the header names no {what} column (expected one of {aliases:?})"),
                ))
            }
            [_, j, ..] => {
                return Err(DataError::at(
                    file,
                    line,
                    cells[*j].column,
                    format!("the header names the {what} column twice"),
                ))
            }
        }
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts() -> ReadOptions {
        ReadOptions {
            assume_uncertainty: Some((0.01, 0.0)),
            ..ReadOptions::default()
        }
    }

    const HEAD: &str = "lambda,thetai,phi,thetar,phir,f_r11,f_r12/f_r11\n";

    #[test]
    fn signed_incidence_reads_on_the_far_side_and_wavelength_in_nanometres() {
        let text = format!("{HEAD}0.532,-45,0,40,0,0.35,0.01\n0.532,-0.001,0,30,90,0.31,0.0\n");
        let ds = parse(&text, "t.csv", &opts()).unwrap();
        assert_eq!(ds.samples.len(), 2);
        let s = &ds.samples[0];
        assert!((s.theta_i.to_degrees() - 45.0).abs() < 1e-12);
        assert!(
            (s.phi_i.to_degrees() - 180.0).abs() < 1e-12,
            "{}",
            s.phi_i.to_degrees()
        );
        assert!((s.wavelength_nm - 532.0).abs() < 1e-9);
        assert!((s.uncertainty - 0.0035).abs() < 1e-12);
        assert!(ds.assumed_uncertainty.is_some());
    }

    #[test]
    fn refused_without_an_assumed_uncertainty() {
        let text = format!("{HEAD}0.532,-45,0,40,0,0.35,0.01\n");
        let e = parse(&text, "t.csv", &ReadOptions::default())
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("--assume-uncertainty") && e.contains("t.csv"),
            "{e}"
        );
    }

    #[test]
    fn bad_cells_name_line_and_column() {
        let text = format!("{HEAD}0.532,-45,0,40,0,0.35,0.01\n0.532,-45,0,95,0,0.3,0\n");
        let e = parse(&text, "t.csv", &opts()).unwrap_err().to_string();
        assert!(e.contains("t.csv:3:") && e.contains("thetar = 95"), "{e}");
        let text = format!("{HEAD}0.532,-45,0,40,0,abc,0.01\n");
        let e = parse(&text, "t.csv", &opts()).unwrap_err().to_string();
        assert!(e.contains("t.csv:2:18") && e.contains("value"), "{e}");
        let text = format!("{HEAD}0.532,-45,0,40,0,0.35\n");
        let e = parse(&text, "t.csv", &opts()).unwrap_err().to_string();
        assert!(e.contains("expected 7 cells"), "{e}");
        let e = parse("lambda,thetai,phi,thetar,f_r11\n", "t.csv", &opts())
            .unwrap_err()
            .to_string();
        assert!(e.contains("no phi_o column"), "{e}");
    }

    #[test]
    fn recognised_by_its_header_only() {
        assert!(looks_like(HEAD.trim()));
        assert!(looks_like("lambda, thetai, phii, thetar, phir, fr11, m12"));
        assert!(!looks_like(
            "theta_i,phi_i,theta_o,phi_o,wavelength_nm,value,uncertainty"
        ));
    }
}
