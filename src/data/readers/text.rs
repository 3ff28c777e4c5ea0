//! Reading keyword-and-table text formats (Zemax BSDF, ASTM E1392) line by line, with
//! every token's place: the errors of these readers name `file:line:column`, the column
//! 1-based in characters.

use super::v1::decode_line;
use crate::data::DataError;
use std::io::BufRead;

/// One whitespace- or comma-separated token of a line and where it starts.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Token<'a> {
    pub(crate) text: &'a str,
    /// 1-based column of its first character.
    pub(crate) column: usize,
}

/// The 1-based character column of byte offset `at` of `line`.
pub(crate) fn column_of(line: &str, at: usize) -> usize {
    line.get(..at).map_or(at, |s| s.chars().count()) + 1
}

/// The column just after the last character of `line` (where a missing token would be).
pub(crate) fn end_column(line: &str) -> usize {
    line.trim_end().chars().count() + 1
}

/// The tokens of `line` separated by runs of blanks (spaces, tabs).
pub(crate) fn blank_tokens(line: &str) -> Vec<Token<'_>> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, c) in line
        .char_indices()
        .chain(std::iter::once((line.len(), ' ')))
    {
        match (c.is_whitespace(), start) {
            (false, None) => start = Some(i),
            (true, Some(s)) => {
                out.push(Token {
                    text: &line[s..i],
                    column: column_of(line, s),
                });
                start = None;
            }
            _ => {}
        }
    }
    out
}

/// The cells of `line` separated by commas, trimmed (an empty cell is a token with empty
/// text at the place of its comma).
pub(crate) fn comma_tokens(line: &str) -> Vec<Token<'_>> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, c) in line
        .char_indices()
        .chain(std::iter::once((line.len(), ',')))
    {
        if c == ',' {
            let raw = &line[start..i];
            let lead = raw.len() - raw.trim_start().len();
            out.push(Token {
                text: raw.trim(),
                column: column_of(line, start + lead),
            });
            start = i + c.len_utf8();
        }
    }
    out
}

/// A number token: a finite f64 (exponents allowed), `Ok(None)` for a NaN written as such
/// (`nan`, `NaN`: a masked cell), or the message saying what is wrong with it.
pub(crate) fn number(t: &str) -> Result<Option<f64>, String> {
    match t.parse::<f64>() {
        Ok(v) if v.is_finite() => Ok(Some(v)),
        Ok(v) if v.is_nan() => Ok(None),
        Ok(_) => Err(format!("'{t}' is not a finite number")),
        Err(_) => {
            let hint = if t.contains(',') {
                " (the decimal mark is '.')"
            } else {
                ""
            };
            Err(format!("'{t}' is not a number{hint}"))
        }
    }
}

/// Reads a text file line by line: each line decoded (UTF-8, a BOM on line 1 skipped,
/// CR LF or LF), numbered from 1.
pub(crate) struct LineReader<'a, R> {
    reader: R,
    file: &'a str,
    buf: Vec<u8>,
    /// The number of the last line read.
    pub(crate) line: usize,
    /// Bytes read so far.
    pub(crate) bytes: u64,
}

impl<'a, R: BufRead> LineReader<'a, R> {
    pub(crate) fn new(reader: R, file: &'a str) -> Self {
        LineReader {
            reader,
            file,
            buf: Vec::with_capacity(256),
            line: 0,
            bytes: 0,
        }
    }

    /// The next line's text, `None` at the end of the file.
    pub(crate) fn next_line(&mut self) -> Result<Option<String>, DataError> {
        self.buf.clear();
        let n = self.reader.read_until(b'\n', &mut self.buf).map_err(|e| {
            DataError::at(
                self.file,
                self.line + 1,
                1,
                format!("cannot read this line: {e}"),
            )
        })?;
        if n == 0 {
            return Ok(None);
        }
        self.line += 1;
        self.bytes += n as u64;
        match decode_line(&self.buf, self.line) {
            Ok(t) => Ok(Some(t.into_owned())),
            Err(msg) => {
                let valid =
                    std::str::from_utf8(&self.buf).map_or_else(|e| e.valid_up_to(), |s| s.len());
                let column = String::from_utf8_lossy(&self.buf[..valid]).chars().count() + 1;
                Err(DataError::at(self.file, self.line, column, msg))
            }
        }
    }
}

/// Give an error of the shared row checks a place when it has none: `File` errors
/// (no rows, a channel selection that leaves nothing) go to `line`:`column`, the line
/// that declares what they are about; `Line` errors get `column`.
pub(crate) fn locate(e: DataError, line: usize, column: usize) -> DataError {
    match e {
        DataError::File { file, msg } => DataError::At {
            file,
            line,
            column,
            msg,
        },
        DataError::Line { file, line, msg } => DataError::At {
            file,
            line,
            column,
            msg,
        },
        DataError::Lines { file, errors, more } => DataError::Lines {
            file,
            errors: errors
                .into_iter()
                .map(|(l, c, m)| (l, Some(c.unwrap_or(column)), m))
                .collect(),
            more,
        },
        other => other,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tokens_know_their_columns() {
        let t = blank_tokens("  TIS\t0.5  é 7");
        let got: Vec<(&str, usize)> = t.iter().map(|t| (t.text, t.column)).collect();
        assert_eq!(got, vec![("TIS", 3), ("0.5", 7), ("é", 12), ("7", 14)]);
        let t = comma_tokens("0.1, 2 ,,x");
        let got: Vec<(&str, usize)> = t.iter().map(|t| (t.text, t.column)).collect();
        assert_eq!(got, vec![("0.1", 1), ("2", 6), ("", 9), ("x", 10)]);
        assert_eq!(end_column("ab  "), 3);
    }

    #[test]
    fn numbers_masks_and_junk() {
        assert_eq!(number("6.375E-02"), Ok(Some(0.06375)));
        assert_eq!(number("NaN"), Ok(None));
        assert!(number("inf").unwrap_err().contains("finite"));
        assert!(number("6,3").unwrap_err().contains("decimal mark"));
    }
}
