//! Reading every supported file format into one [`Dataset`], chosen by content.
//!
//! | format | recognised by | reader |
//! |---|---|---|
//! | bsdfit v1 CSV (docs/conventions.md) | a `# bsdfit dataset v1` line or a header naming `theta_i` | [`Dataset::parse_reader`] |
//! | ALTA text | a leading `#DIM`, `#PARAM_IN`, `#PARAM_OUT`, `#VS` or `#ALTA` line | [`alta`] |
//! | MERL binary | three little-endian int32 dimensions (90, 90, 180), or dimensions whose table of doubles has exactly the file's size | [`merl`] |
//! | RGL `.bsdf` measured material | the tensor file header `tensor_file\0` | [`rgl`] (sampled at `--sample-geometry`) |
//! | Zemax tabular BSDF | a first line (after `#` comments) starting with a keyword of its header (`Source`, `Symmetry`, …) | [`zemax`] |
//! | ASTM E1392 text | a first line starting with an upper-case keyword, and a `VARS` line | [`astm`] |
//! | Mueller-matrix BRDF CSV (NIST, SCATMECH's column names) | a first line naming `lambda`, `thetai`, `phi`, `thetar`, `phir` and `f_r11` | [`mueller`] |
//!
//! Content decides, not the extension; only when nothing matches does the extension
//! (`.binary` → MERL, `.bsdf` → RGL, or Zemax for a text file) pick the reader whose
//! error will explain the problem, v1 otherwise.
//!
//! **Missing uncertainties.** ALTA files without `#VS` intervals, MERL tables, RGL files
//! and Mueller-matrix tables carry none. They are refused unless the user assumes some with `--assume-uncertainty REL,ABS`
//! ([`ReadOptions::assume_uncertainty`]):
//!
//! u = sqrt((REL·|value|)² + ABS²)   (sr⁻¹)
//!
//! — the quadrature sum of a relative and an absolute term, the same noise model as
//! `bsdfit synth`, so a relative term never gives a zero uncertainty to a zero value when
//! ABS > 0. The dataset then records the assumption ([`Dataset::assumed_uncertainty`],
//! a notice, and the metadata line `# uncertainty: assumed …` when written as v1), and
//! fits report it among their warnings.

pub mod alta;
pub mod astm;
pub mod merl;
pub mod mueller;
pub mod rgl;
pub mod tensor;
pub(crate) mod text;
pub mod v1;
pub mod zemax;

use crate::data::{DataError, Dataset, ReadOptions};
use crate::data::{Notice, NoticeKind};
use std::io::{BufRead, BufReader, IsTerminal, Read, Write};
use std::path::Path;
use std::time::{Duration, Instant};

/// The progress of a streaming read, reported every few ten thousand lines and at the end.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReadProgress {
    /// Bytes consumed so far.
    pub bytes: u64,
    /// Rows accepted so far.
    pub rows: usize,
}

/// The file formats the readers understand.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    V1Csv,
    AltaText,
    MerlBinary,
    RglBsdf,
    ZemaxBsdf,
    AstmE1392,
    MuellerCsv,
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Format::V1Csv => "bsdfit v1 CSV",
            Format::AltaText => "ALTA text",
            Format::MerlBinary => "MERL binary",
            Format::RglBsdf => "RGL .bsdf",
            Format::ZemaxBsdf => "Zemax BSDF",
            Format::AstmE1392 => "ASTM E1392",
            Format::MuellerCsv => "Mueller-matrix BRDF CSV",
        })
    }
}

/// Recognise a format from the first bytes of a file (`head`, a few KiB suffice) and its
/// total length. `None` when nothing matches.
pub fn sniff(head: &[u8], len: u64) -> Option<Format> {
    if rgl::looks_like(head) {
        return Some(Format::RglBsdf);
    }
    if merl::looks_like(head, len) {
        return Some(Format::MerlBinary);
    }
    let head = head.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(head);
    let text_lines = || {
        head.split(|&b| b == b'\n')
            .take(200)
            .map(|l| std::str::from_utf8(l).unwrap_or(""))
    };
    for raw in head.split(|&b| b == b'\n').take(200) {
        let line = String::from_utf8_lossy(raw);
        let t = line.trim();
        if t.is_empty() {
            continue;
        }
        if let Some(rest) = t.strip_prefix('#') {
            if rest.contains("bsdfit dataset") {
                return Some(Format::V1Csv);
            }
            let key = rest
                .split_ascii_whitespace()
                .next()
                .unwrap_or("")
                .to_ascii_uppercase();
            if !rest.starts_with(char::is_whitespace)
                && ["DIM", "PARAM_IN", "PARAM_OUT", "VS", "ALTA"].contains(&key.as_str())
            {
                return Some(Format::AltaText);
            }
            continue;
        }
        // The first line that is not a comment: an ASTM keyword line with a VARS line to
        // come (ASTM's SOURCE is also a Zemax keyword), a Zemax keyword, or a v1 header naming its columns.
        if astm::looks_like(text_lines()) {
            return Some(Format::AstmE1392);
        }
        if zemax::looks_like(t) {
            return Some(Format::ZemaxBsdf);
        }
        if mueller::looks_like(t) {
            return Some(Format::MuellerCsv);
        }
        return t.contains("theta_i").then_some(Format::V1Csv);
    }
    None
}

/// The reader whose error explains an unrecognised file: by extension (`.bsdf` is both
/// RGL's binary tensor file and Zemax's text; valid UTF-8 text there goes to Zemax).
fn by_extension(path: &Path, head: &[u8]) -> Format {
    match path.extension().and_then(|e| e.to_str()) {
        Some(e) if e.eq_ignore_ascii_case("binary") => Format::MerlBinary,
        Some(e) if e.eq_ignore_ascii_case("bsdf") => {
            let text = std::str::from_utf8(head).is_ok_and(|t| !t.contains('\0'));
            if text {
                Format::ZemaxBsdf
            } else {
                Format::RglBsdf
            }
        }
        _ => Format::V1Csv,
    }
}

/// The format of a file, by content ([`sniff`]), else by extension.
pub fn detect(path: &Path) -> Result<Format, DataError> {
    let (head, len) = file_head(path)?;
    Ok(sniff(&head, len).unwrap_or_else(|| by_extension(path, &head)))
}

/// The format of a file recognised by its content alone ([`sniff`]; None: no format's),
/// how a folder's files are told from the other files it holds.
pub fn recognise(path: &Path) -> Result<Option<Format>, DataError> {
    let (head, len) = file_head(path)?;
    Ok(sniff(&head, len))
}

/// The first 64 KiB of a file and its length.
fn file_head(path: &Path) -> Result<(Vec<u8>, u64), DataError> {
    let file = path.display().to_string();
    let f = std::fs::File::open(path).map_err(|e| cannot_read(&file, e))?;
    let len = f.metadata().map(|m| m.len()).unwrap_or(0);
    let mut head = Vec::new();
    f.take(1 << 16)
        .read_to_end(&mut head)
        .map_err(|e| cannot_read(&file, e))?;
    Ok((head, len))
}

fn cannot_read(file: &str, e: std::io::Error) -> DataError {
    DataError::File {
        file: file.into(),
        msg: format!("cannot read: {e}"),
    }
}

/// Read a dataset file of any supported format, recognised by its content.
pub fn load(path: &Path, opts: &ReadOptions) -> Result<Dataset, DataError> {
    load_with_progress(path, opts, &mut |_| {})
}

/// [`load`], reporting progress to stderr on long reads ([`StderrProgress`]).
pub fn load_reporting(path: &Path, opts: &ReadOptions) -> Result<Dataset, DataError> {
    let total = std::fs::metadata(path).map(|m| m.len()).ok();
    let mut bar = StderrProgress::new(&path.display().to_string(), total);
    let ds = load_with_progress(path, opts, &mut |p| bar.update(p));
    bar.finish();
    ds
}

/// [`load`] with a progress callback (called every few ten thousand lines of text).
pub fn load_with_progress(
    path: &Path,
    opts: &ReadOptions,
    progress: &mut dyn FnMut(ReadProgress),
) -> Result<Dataset, DataError> {
    let file = path.display().to_string();
    let f = std::fs::File::open(path).map_err(|e| cannot_read(&file, e))?;
    let len = f.metadata().map(|m| m.len()).unwrap_or(0);
    let mut reader = BufReader::with_capacity(1 << 16, f);
    let head = reader.fill_buf().map_err(|e| cannot_read(&file, e))?;
    let Some(format) = sniff(head, len) else {
        // Nothing recognisable: the extension's reader explains what it expected.
        let fallback = by_extension(path, &head[..head.len().min(4096)]);
        return match fallback {
            Format::ZemaxBsdf => zemax::parse_reader(reader, &file, opts, progress),
            Format::RglBsdf => {
                let mut bytes = Vec::new();
                reader
                    .read_to_end(&mut bytes)
                    .map_err(|e| cannot_read(&file, e))?;
                rgl::parse(&bytes, &file, opts)
            }
            Format::MerlBinary => {
                let mut bytes = Vec::new();
                reader
                    .read_to_end(&mut bytes)
                    .map_err(|e| cannot_read(&file, e))?;
                merl::parse(&bytes, &file, opts)
            }
            _ => Dataset::parse_reader(reader, &file, opts, progress).map_err(unrecognised),
        };
    };
    match format {
        Format::MerlBinary => {
            let mut bytes = Vec::with_capacity(len.min(1 << 27) as usize);
            reader
                .read_to_end(&mut bytes)
                .map_err(|e| cannot_read(&file, e))?;
            progress(ReadProgress {
                bytes: bytes.len() as u64,
                rows: 0,
            });
            merl::parse(&bytes, &file, opts)
        }
        Format::RglBsdf => {
            let mut bytes = Vec::with_capacity(len.min(1 << 27) as usize);
            reader
                .read_to_end(&mut bytes)
                .map_err(|e| cannot_read(&file, e))?;
            rgl::parse(&bytes, &file, opts)
        }
        Format::AltaText => alta::parse_reader(reader, &file, opts, progress),
        Format::ZemaxBsdf => zemax::parse_reader(reader, &file, opts, progress),
        Format::AstmE1392 => astm::parse_reader(reader, &file, opts, progress),
        Format::MuellerCsv => mueller::parse_reader(reader, &file, opts, progress),
        Format::V1Csv => Dataset::parse_reader(reader, &file, opts, progress),
    }
}

/// Parse a whole file held in memory (any format, recognised by content); `file` names
/// it in messages and, when nothing matches, its extension picks the reader.
pub fn parse_bytes(bytes: &[u8], file: &str, opts: &ReadOptions) -> Result<Dataset, DataError> {
    match sniff(bytes, bytes.len() as u64) {
        Some(Format::MerlBinary) => merl::parse(bytes, file, opts),
        Some(Format::RglBsdf) => rgl::parse(bytes, file, opts),
        Some(Format::AltaText) => alta::parse_reader(bytes, file, opts, &mut |_| {}),
        Some(Format::ZemaxBsdf) => zemax::parse_reader(bytes, file, opts, &mut |_| {}),
        Some(Format::AstmE1392) => astm::parse_reader(bytes, file, opts, &mut |_| {}),
        Some(Format::MuellerCsv) => mueller::parse_reader(bytes, file, opts, &mut |_| {}),
        Some(Format::V1Csv) => Dataset::parse_reader(bytes, file, opts, &mut |_| {}),
        None => match by_extension(Path::new(file), &bytes[..bytes.len().min(4096)]) {
            Format::MerlBinary => merl::parse(bytes, file, opts),
            Format::ZemaxBsdf => zemax::parse_reader(bytes, file, opts, &mut |_| {}),
            Format::RglBsdf => rgl::parse(bytes, file, opts),
            _ => Dataset::parse_reader(bytes, file, opts, &mut |_| {}).map_err(unrecognised),
        },
    }
}

/// A v1 error for a file that matched no format: say the other formats were tried too.
fn unrecognised(e: DataError) -> DataError {
    const HINT: &str = " (nor is the file recognisable as ALTA text, a MERL table, an RGL .bsdf, a Zemax BSDF, an ASTM E1392 file or a Mueller-matrix BRDF CSV)";
    match e {
        DataError::File { file, msg } => DataError::File {
            file,
            msg: msg + HINT,
        },
        DataError::Line { file, line, msg } => DataError::Line {
            file,
            line,
            msg: msg + HINT,
        },
        DataError::At {
            file,
            line,
            column,
            msg,
        } => DataError::At {
            file,
            line,
            column,
            msg: msg + HINT,
        },
        other => other,
    }
}

/// The assumed standard uncertainty of `value` (sr⁻¹): sqrt((REL·|value|)² + ABS²).
pub fn assumed_uncertainty(value: f64, rel: f64, abs: f64) -> f64 {
    (rel * value).hypot(abs)
}

/// The metadata note recording an assumption (`# uncertainty: …` in v1 files).
pub fn assumed_note(rel: f64, abs: f64) -> String {
    format!(
        "assumed, not measured: u = sqrt((REL·|value|)² + ABS²) with REL = {rel}, ABS = {abs} sr⁻¹"
    )
}

/// (REL, ABS) back from an [`assumed_note`]; `None` for any other text.
pub fn parse_assumed_note(note: &str) -> Option<(f64, f64)> {
    if !note.trim_start().starts_with("assumed") {
        return None;
    }
    let after = |key: &str| -> Option<f64> {
        let key = format!("{key} =");
        let rest = note[note.find(&key)? + key.len()..].trim_start();
        let end = rest
            .find(|c: char| !(c.is_ascii_digit() || "+-.eE".contains(c)))
            .unwrap_or(rest.len());
        rest[..end].parse().ok()
    };
    Some((after("REL")?, after("ABS")?))
}

/// Parse `REL,ABS`, an uncertainty to assume: both finite, ≥ 0, not both zero. The
/// message names what is wrong, not the option: the caller names it.
pub fn parse_assume_arg(s: &str) -> Result<(f64, f64), String> {
    let bad = || {
        format!(
            "expected REL,ABS such as 0.05,0.001 (u = sqrt((REL·|value|)² + ABS²) sr⁻¹), got '{s}'"
        )
    };
    let (r, a) = s.split_once(',').ok_or_else(bad)?;
    let rel: f64 = r.trim().parse().map_err(|_| bad())?;
    let abs: f64 = a.trim().parse().map_err(|_| bad())?;
    check_assumed(rel, abs).map_err(|e| format!("{}: {e}", bad()))
}

/// An uncertainty to assume, (REL, ABS): both finite, ≥ 0, not both zero.
pub fn check_assumed(rel: f64, abs: f64) -> Result<(f64, f64), String> {
    if !(rel.is_finite() && abs.is_finite() && rel >= 0.0 && abs >= 0.0) || rel + abs == 0.0 {
        return Err("REL and ABS must be finite, ≥ 0 and not both zero".into());
    }
    Ok((rel, abs))
}

/// The uncertainty a reader gives a value from a file without uncertainties, or the
/// error refusing such a file.
pub(crate) fn require_assumption(
    file: &str,
    opts: &ReadOptions,
    what: &str,
) -> Result<(f64, f64), DataError> {
    opts.assume_uncertainty.ok_or_else(|| DataError::File {
        file: file.into(),
        msg: format!(
            "{what} carries no uncertainties, so it cannot be fitted as measured data; pass --assume-uncertainty REL,ABS to assume u = sqrt((REL·|value|)² + ABS²) sr⁻¹ (every output will then say the uncertainties were assumed)"
        ),
    })
}

/// Record an assumption in a dataset: the field, a notice and the metadata line.
pub(crate) fn mark_assumed(ds: &mut Dataset, rel: f64, abs: f64) {
    ds.assumed_uncertainty = Some((rel, abs));
    ds.meta.insert("uncertainty".into(), assumed_note(rel, abs));
    ds.notices.push(Notice::new(
        NoticeKind::AssumedUncertainty,
        format!(
            "{}: uncertainties {}",
            ds.source.display(),
            assumed_note(rel, abs)
        ),
    ));
}

/// Progress on stderr for long reads: nothing during the first second, then an
/// indicatif bar when stderr is a terminal, else one line every 5 s.
pub struct StderrProgress {
    label: String,
    total: Option<u64>,
    start: Instant,
    last_line: Option<Instant>,
    terminal: bool,
    bar: Option<indicatif::ProgressBar>,
    /// Where the periodic lines go (stderr, or a buffer in tests).
    sink: Box<dyn std::io::Write>,
}

impl StderrProgress {
    pub fn new(label: &str, total: Option<u64>) -> StderrProgress {
        StderrProgress {
            label: label.to_string(),
            total,
            start: Instant::now(),
            last_line: None,
            terminal: std::io::stderr().is_terminal(),
            bar: None,
            sink: Box::new(std::io::stderr()),
        }
    }

    pub fn update(&mut self, p: ReadProgress) {
        self.update_at(p, Instant::now());
    }

    fn update_at(&mut self, p: ReadProgress, now: Instant) {
        if now.duration_since(self.start) < Duration::from_secs(1) {
            return;
        }
        if self.terminal {
            let bar = self.bar.get_or_insert_with(|| {
                let b = indicatif::ProgressBar::new(self.total.unwrap_or(0));
                b.set_style(
                    indicatif::ProgressStyle::with_template(
                        "reading {msg} [{elapsed_precise}] {bar:30} {bytes}/{total_bytes} ({eta})",
                    )
                    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
                );
                b
            });
            bar.set_message(format!("{} ({} rows)", self.label, p.rows));
            bar.set_position(p.bytes);
        } else if self
            .last_line
            .is_none_or(|t| now.duration_since(t) >= Duration::from_secs(5))
        {
            self.last_line = Some(now);
            let pct = match self.total {
                Some(t) if t > 0 => format!("{:.0}%, ", 100.0 * p.bytes as f64 / t as f64),
                _ => String::new(),
            };
            let _ = writeln!(
                self.sink,
                "reading {}: {pct}{} MB, {} rows, {:.0} s",
                self.label,
                p.bytes / 1_000_000,
                p.rows,
                now.duration_since(self.start).as_secs_f64()
            );
        }
    }

    pub fn finish(self) {
        if let Some(bar) = self.bar {
            bar.finish_and_clear();
        }
    }
}

/// `bsdfit convert`: read `input` (any format, with the selection options) and write it
/// as v1 CSV to `output`, saying in the header where it came from.
pub fn convert(input: &Path, output: &Path, opts: &ReadOptions) -> anyhow::Result<Dataset> {
    let format = detect(input)?;
    let mut ds = load_reporting(input, opts)?;
    ds.meta.insert(
        "converted_from".into(),
        format!("{} ({format})", input.display()),
    );
    ds.write(output)?;
    Ok(ds)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::{Arc, Mutex};

    /// A sink the test can read back.
    #[derive(Clone, Default)]
    struct Shared(Arc<Mutex<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(b);
            Ok(b.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn progress_lines_off_a_terminal_every_five_seconds_after_the_first() {
        let out = Shared::default();
        let t0 = Instant::now();
        let mut p = StderrProgress::new("big.csv", Some(200_000_000));
        p.start = t0;
        p.terminal = false;
        p.sink = Box::new(out.clone());
        let at = |s: f64| t0 + Duration::from_secs_f64(s);
        let step = |bytes: u64| ReadProgress {
            bytes,
            rows: (bytes / 50) as usize,
        };
        p.update_at(step(10_000_000), at(0.5)); // the first second: silent
        p.update_at(step(50_000_000), at(1.5)); // printed
        p.update_at(step(60_000_000), at(4.0)); // within 5 s of the last: silent
        p.update_at(step(150_000_000), at(6.6)); // printed
        p.finish();
        let text = String::from_utf8(out.0.lock().unwrap().clone()).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(
            lines,
            vec![
                "reading big.csv: 25%, 50 MB, 1000000 rows, 2 s",
                "reading big.csv: 75%, 150 MB, 3000000 rows, 7 s",
            ],
            "{text}"
        );
    }
}
