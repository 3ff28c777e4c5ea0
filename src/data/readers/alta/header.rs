//! The ALTA header: its `#KEY value` lines collected, then validated into a [`Header`].

use super::params::{AltaValues, ParamIn, ParamOut};
use crate::data::{DataError, ReadOptions};
use std::collections::BTreeMap;

/// The validated header.
pub(super) struct Header {
    pub(super) param_in: ParamIn,
    pub(super) param_out: ParamOut,
    /// `Some` when the file has no `#PARAM_OUT` and the output kind came from the option.
    pub(super) from_option: Option<AltaValues>,
    /// Interval columns per output (0, 1 or 2).
    pub(super) vs: Vec<usize>,
    /// (key, value) of the other header lines.
    pub(super) other: Vec<(String, String)>,
}

/// The header lines read so far: each `#KEY value` with its line, and the keys in file
/// order.
#[derive(Default)]
pub(super) struct HeaderLines {
    keys: BTreeMap<String, (usize, String)>,
    order: Vec<String>,
    /// `#ALTA END HEADER` (or `#ALTA HEADER END`) was seen: later `#` lines are comments.
    closed: bool,
}

impl HeaderLines {
    /// Take the `#` line `#rest` of the header; comments (`# …`, `##…`, a bare `#`, or any
    /// line after the header's end) are skipped. A key given twice is an error.
    pub(super) fn take(&mut self, rest: &str, line: usize, file: &str) -> Result<(), DataError> {
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
    pub(super) fn parse(&self, file: &str, opts: &ReadOptions) -> Result<Header, DataError> {
        parse_header(&self.keys, &self.order, file, opts)
    }
}

/// Validate the header lines into a [`Header`]: `#FORMAT`, `#DIM` against the
/// parametrizations' dimensions, `#PARAM_IN`, `#PARAM_OUT` (or `--alta-values`) and `#VS`.
fn parse_header(
    keys: &BTreeMap<String, (usize, String)>,
    order: &[String],
    file: &str,
    opts: &ReadOptions,
) -> Result<Header, DataError> {
    let ferr = |msg: String| DataError::in_file(file, msg);
    let lerr = |line: usize, msg: String| DataError::at_line(file, line, msg);
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
    let ferr = |msg: String| DataError::in_file(file, msg);
    let lerr = |line: usize, msg: String| DataError::at_line(file, line, msg);
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
