//! The header of a Zemax tabular BSDF file: its keyword lines collected one at a time,
//! then checked into a [`Header`].

use super::super::text::{blank_tokens, end_column, number, Token};
use crate::data::{DataError, Kind};

/// A place in the file: (line, column), both 1-based.
pub(super) type Pos = (usize, usize);

/// Most angles one list of the header may hold.
pub const MAX_ANGLES: usize = 100_000;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Symmetry {
    PlaneSymmetrical,
    Asymmetrical,
    Asymmetrical4D,
}

impl Symmetry {
    pub fn name(self) -> &'static str {
        match self {
            Symmetry::PlaneSymmetrical => "PlaneSymmetrical",
            Symmetry::Asymmetrical => "Asymmetrical",
            Symmetry::Asymmetrical4D => "Asymmetrical4D",
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Spectral {
    Monochrome,
    Xyz,
}

/// The four angle lists, in the order of the format.
pub(super) const LISTS: [&str; 4] = [
    "SampleRotation",
    "AngleOfIncidence",
    "ScatterAzimuth",
    "ScatterRadial",
];

/// The checked header: the table's layout (angles in degrees).
#[derive(Clone, Debug)]
pub struct Header {
    pub symmetry: Symmetry,
    pub spectral: Spectral,
    pub kind: Kind,
    pub rotations: Vec<f64>,
    pub incidences: Vec<f64>,
    pub azimuths: Vec<f64>,
    pub radials: Vec<f64>,
    pub source: Option<String>,
    /// bsdfit's `# wavelength_nm: W` comment, if any.
    pub wavelength: Option<f64>,
    /// Where the spectral content is declared (channel errors point there).
    pub(super) spectral_at: Pos,
}

/// One angle list as read so far.
#[derive(Clone, Debug)]
struct List {
    want: usize,
    at: Pos,
    values: Vec<(f64, Pos)>,
}

/// The header lines taken so far.
#[derive(Default)]
pub(super) struct HeaderLines {
    symmetry: Option<(Symmetry, Pos)>,
    spectral: Option<(Spectral, Pos)>,
    kind: Option<(Kind, Pos)>,
    source: Option<(String, Pos)>,
    lists: [Option<List>; 4],
    /// The list whose angles continue on the next line.
    filling: Option<usize>,
    wavelength: Option<(f64, Pos)>,
    last_line: usize,
}

fn err(file: &str, (line, column): Pos, msg: String) -> DataError {
    DataError::at(file, line, column, msg)
}

impl HeaderLines {
    /// A `#` comment of the header: bsdfit's `# wavelength_nm: W` is read, others skipped.
    pub(super) fn comment(&mut self, text: &str, line: usize, file: &str) -> Result<(), DataError> {
        let body = text.trim_start().trim_start_matches('#');
        let Some((key, value)) = body.split_once(':') else {
            return Ok(());
        };
        if !key.trim().eq_ignore_ascii_case("wavelength_nm") {
            return Ok(());
        }
        let at = (
            line,
            super::super::text::column_of(text, text.len() - value.len()),
        );
        let v = number(value.trim())
            .ok()
            .flatten()
            .filter(|w| *w > 0.0)
            .ok_or_else(|| {
                err(
                    file,
                    at,
                    format!(
                        "wavelength_nm: '{}' is not a wavelength in nm",
                        value.trim()
                    ),
                )
            })?;
        if let Some((_, first)) = self.wavelength {
            return Err(err(
                file,
                at,
                format!("wavelength_nm is given twice (first at line {})", first.0),
            ));
        }
        self.wavelength = Some((v, at));
        Ok(())
    }

    /// Take a non-blank, non-comment line. `Ok(true)` when the line is no header line but
    /// the start of the data (a spectral indicator or `DataBegin`).
    pub(super) fn take(&mut self, text: &str, line: usize, file: &str) -> Result<bool, DataError> {
        self.last_line = line;
        let tokens = blank_tokens(text);
        if let Some(k) = self.filling {
            return self.fill(k, &tokens, line, file).map(|_| false);
        }
        let Some(first) = tokens.first() else {
            return Ok(false);
        };
        let at = (line, first.column);
        let word = first.text.to_ascii_lowercase();
        if let Some(k) = LISTS.iter().position(|l| l.eq_ignore_ascii_case(&word)) {
            self.start_list(k, &tokens, line, file)?;
            return Ok(false);
        }
        match word.as_str() {
            "monochrome" | "tristimulusx" | "tristimulusy" | "tristimulusz" | "databegin" => {
                return Ok(true)
            }
            "source" => {
                let rest = text.trim_start()[first.text.len()..].trim().to_string();
                once(&mut self.source, (rest, at), "Source", file)?;
            }
            "symmetry" => {
                let s = one_of(&tokens, text, line, file, "Symmetry", SYMMETRIES)?;
                once(&mut self.symmetry, (s, at), "Symmetry", file)?;
            }
            "spectralcontent" => {
                let s = one_of(&tokens, text, line, file, "SpectralContent", SPECTRA)?;
                once(&mut self.spectral, (s, at), "SpectralContent", file)?;
            }
            "scattertype" => {
                let k = one_of(&tokens, text, line, file, "ScatterType", SCATTER_TYPES)?;
                once(&mut self.kind, (k, at), "ScatterType", file)?;
            }
            "tis" | "dataend" => {
                return Err(err(file, at, format!(
                    "'{}' before DataBegin: the data start with a spectral indicator (Monochrome, TristimulusX…) and DataBegin",
                    first.text
                )))
            }
            _ => {
                return Err(err(file, at, format!(
                    "'{}' is not a keyword of a Zemax BSDF header (Source, Symmetry, SpectralContent, ScatterType, SampleRotation, AngleOfIncidence, ScatterAzimuth, ScatterRadial)",
                    first.text
                )))
            }
        }
        Ok(false)
    }

    /// `SampleRotation N` (and maybe the first angles on the same line).
    fn start_list(
        &mut self,
        k: usize,
        tokens: &[Token],
        line: usize,
        file: &str,
    ) -> Result<(), DataError> {
        let at = (line, tokens[0].column);
        if let Some(l) = &self.lists[k] {
            return Err(err(
                file,
                at,
                format!("{} is given twice (first at line {})", LISTS[k], l.at.0),
            ));
        }
        let Some(n) = tokens.get(1) else {
            return Err(err(
                file,
                (line, tokens[0].column + tokens[0].text.chars().count() + 1),
                format!(
                    "{} needs the number of angles, then the angles on the next line",
                    LISTS[k]
                ),
            ));
        };
        let want = n
            .text
            .parse::<usize>()
            .ok()
            .filter(|&w| (1..=MAX_ANGLES).contains(&w))
            .ok_or_else(|| {
                err(
                    file,
                    (line, n.column),
                    format!(
                        "{} {}: expected the number of angles, an integer from 1 to {MAX_ANGLES}",
                        LISTS[k], n.text
                    ),
                )
            })?;
        self.lists[k] = Some(List {
            want,
            at: (line, n.column),
            values: Vec::with_capacity(want.min(1024)),
        });
        self.filling = Some(k);
        self.fill(k, &tokens[2..], line, file)
    }

    /// Angles of list `k` from `tokens`.
    fn fill(
        &mut self,
        k: usize,
        tokens: &[Token],
        line: usize,
        file: &str,
    ) -> Result<(), DataError> {
        let list = self.lists[k].as_mut().expect("filling a started list");
        for t in tokens {
            let at = (line, t.column);
            if list.values.len() == list.want {
                return Err(err(
                    file,
                    at,
                    format!(
                        "{} {} lists more than {} angles",
                        LISTS[k], list.want, list.want
                    ),
                ));
            }
            let v = match number(t.text) {
                Ok(Some(v)) => v,
                Ok(None) => return Err(err(file, at, format!("{}: an angle is NaN", LISTS[k]))),
                Err(m) => {
                    return Err(err(
                        file,
                        at,
                        format!(
                            "{} {}: {} angles read, then {m}",
                            LISTS[k],
                            list.want,
                            list.values.len()
                        ),
                    ))
                }
            };
            check_angle(k, v).map_err(|m| err(file, at, format!("{}: {m}", LISTS[k])))?;
            if let Some((_, p)) = list.values.iter().find(|(x, _)| *x == v) {
                return Err(err(
                    file,
                    at,
                    format!(
                        "{}: {v}° is listed twice (first at {}:{})",
                        LISTS[k], p.0, p.1
                    ),
                ));
            }
            list.values.push((v, at));
        }
        if list.values.len() == list.want {
            self.filling = None;
        }
        Ok(())
    }

    /// The checked header, once the data begin at `at`.
    pub(super) fn finish(self, file: &str, at: Pos) -> Result<Header, DataError> {
        if let Some(k) = self.filling {
            let l = self.lists[k].as_ref().expect("filling a started list");
            return Err(err(
                file,
                at,
                format!(
                    "{} {} lists only {} angles before the data begin",
                    LISTS[k],
                    l.want,
                    l.values.len()
                ),
            ));
        }
        let missing = |what: &str| {
            err(
                file,
                at,
                format!("the header has no {what} line before the data"),
            )
        };
        let (symmetry, sym_at) = self.symmetry.ok_or_else(|| missing("Symmetry"))?;
        let (spectral, spectral_at) = self.spectral.ok_or_else(|| missing("SpectralContent"))?;
        let (kind, _) = self.kind.ok_or_else(|| missing("ScatterType"))?;
        let mut lists: Vec<List> = Vec::with_capacity(4);
        for (k, l) in self.lists.into_iter().enumerate() {
            lists.push(l.ok_or_else(|| missing(LISTS[k]))?);
        }
        let rot = &lists[0];
        if rot.want > 1 && symmetry != Symmetry::Asymmetrical4D {
            return Err(err(file, rot.at, format!(
                "{} sample rotations with Symmetry {} (line {}): several rotations need Asymmetrical4D",
                rot.want, symmetry.name(), sym_at.0
            )));
        }
        if symmetry == Symmetry::PlaneSymmetrical {
            if let Some((v, p)) = lists[2]
                .values
                .iter()
                .find(|(v, _)| !(0.0..=180.0).contains(v))
            {
                return Err(err(file, *p, format!(
                    "ScatterAzimuth {v}°: a PlaneSymmetrical table covers azimuths 0–180° (line {} says PlaneSymmetrical; the whole circle needs Asymmetrical)",
                    sym_at.0
                )));
            }
        }
        let take = |l: &List| l.values.iter().map(|(v, _)| *v).collect::<Vec<f64>>();
        Ok(Header {
            symmetry,
            spectral,
            kind,
            rotations: take(&lists[0]),
            incidences: take(&lists[1]),
            azimuths: take(&lists[2]),
            radials: take(&lists[3]),
            source: self.source.map(|s| s.0),
            wavelength: self.wavelength.map(|w| w.0),
            spectral_at,
        })
    }
}

/// The ranges of the four angles: incidence in [0, 90], radial in [0, 180].
fn check_angle(k: usize, v: f64) -> Result<(), String> {
    match k {
        1 if !(0.0..=90.0).contains(&v) => Err(format!("{v}° is outside [0, 90]")),
        3 if !(0.0..=180.0).contains(&v) => Err(format!("{v}° is outside [0, 180]")),
        _ => Ok(()),
    }
}

/// A keyword given once.
fn once<T>(
    slot: &mut Option<(T, Pos)>,
    v: (T, Pos),
    name: &str,
    file: &str,
) -> Result<(), DataError> {
    if let Some((_, first)) = slot {
        return Err(err(
            file,
            v.1,
            format!("{name} is given twice (first at line {})", first.0),
        ));
    }
    *slot = Some(v);
    Ok(())
}

/// The words of the enumerated keywords, as the format spells them (matched without case;
/// the symmetries also name `export --geometry`'s).
pub const SYMMETRIES: &[(&str, Symmetry)] = &[
    ("PlaneSymmetrical", Symmetry::PlaneSymmetrical),
    ("Asymmetrical", Symmetry::Asymmetrical),
    ("Asymmetrical4D", Symmetry::Asymmetrical4D),
];
const SPECTRA: &[(&str, Spectral)] =
    &[("Monochrome", Spectral::Monochrome), ("XYZ", Spectral::Xyz)];
const SCATTER_TYPES: &[(&str, Kind)] = &[("BRDF", Kind::Brdf), ("BTDF", Kind::Btdf)];

/// The single word after a keyword, one of `words`: "Symmetry 'X' is not A, B or C"
/// otherwise.
fn one_of<T: Copy>(
    tokens: &[Token<'_>],
    text: &str,
    line: usize,
    file: &str,
    name: &str,
    words: &[(&str, T)],
) -> Result<T, DataError> {
    let v = one_word(tokens, text, line, file, name)?;
    if let Some((_, value)) = words.iter().find(|(w, _)| w.eq_ignore_ascii_case(v.text)) {
        return Ok(*value);
    }
    let names: Vec<&str> = words.iter().map(|(w, _)| *w).collect();
    let (last, rest) = names.split_last().expect("a keyword has words");
    let list = if rest.is_empty() {
        last.to_string()
    } else {
        format!("{} or {last}", rest.join(", "))
    };
    Err(err(
        file,
        (line, v.column),
        format!("{name} '{}' is not {list}", v.text),
    ))
}

/// The single word after a keyword.
fn one_word<'a>(
    tokens: &[Token<'a>],
    text: &str,
    line: usize,
    file: &str,
    name: &str,
) -> Result<Token<'a>, DataError> {
    match tokens {
        [_, v] => Ok(*v),
        [_] => Err(err(
            file,
            (line, end_column(text)),
            format!("{name} needs a value"),
        )),
        [_, _, extra, ..] => Err(err(
            file,
            (line, extra.column),
            format!("{name} takes one value, found '{}' after it", extra.text),
        )),
        [] => unreachable!("a keyword line has a token"),
    }
}
