//! The row validator every reader goes through: rows in, one at a time, checked and
//! normalised into samples; then the whole checked (repeated geometries, uncertainty
//! floors), its channels selected and its measurement planes found, into a [`Dataset`].

use super::channels::select_channels;
use super::dataset::{plane_index, sample_key};
use super::{
    geometry_key, measurement_planes, normalise_angles, DataError, Dataset, Kind, RawRow,
    ReadOptions, Sample, MAX_ABS_VALUE, MAX_PLANES, MAX_REPORTED_ERRORS, MIN_ABS_UNCERTAINTY,
    MIN_REL_UNCERTAINTY, UNCERTAINTY_FLOOR_ABS, UNCERTAINTY_FLOOR_REL,
};
use super::{Notice, NoticeKind};
use crate::text::plural_with as count;
use std::collections::BTreeMap;
use std::path::PathBuf;

/// FNV-1a, 64 bits (stable across runs; for grouping rows, not for security).
fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

fn fold32(h: u64) -> u32 {
    (h ^ (h >> 32)) as u32
}

fn key_hash(k: &[i64; 5]) -> u64 {
    let mut bytes = [0u8; 40];
    for (i, x) in k.iter().enumerate() {
        bytes[i * 8..i * 8 + 8].copy_from_slice(&x.to_le_bytes());
    }
    fnv1a(&bytes)
}

/// Per-row side data kept while reading, for the repeated-geometry pass: 12 bytes a row.
/// Rows with equal geometry hashes are compared on their exact keys, so a collision of
/// these 32-bit hashes costs time, never a wrong count; a text-hash collision between two
/// rows of the same geometry would only add a spurious warning.
struct RowKey {
    geometry: u32,
    /// Hash of the row's text (0 for rows not read from text).
    text: u32,
    index: u32,
}

/// The field of a row a check is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Field {
    ThetaI,
    PhiI,
    ThetaO,
    PhiO,
    Wavelength,
    Value,
    Uncertainty,
}

/// Where a reader found each field of a row: 1-based character columns of one line
/// (`None`: not written as such, e.g. a direction computed from several cells).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Cells {
    pub(crate) theta_i: Option<usize>,
    pub(crate) phi_i: Option<usize>,
    pub(crate) theta_o: Option<usize>,
    pub(crate) phi_o: Option<usize>,
    pub(crate) wavelength: Option<usize>,
    pub(crate) value: Option<usize>,
    pub(crate) uncertainty: Option<usize>,
}

impl Cells {
    /// Every field at one column (a table cell that stands for a whole row).
    pub(crate) fn all(column: usize) -> Cells {
        let c = Some(column);
        Cells {
            theta_i: c,
            phi_i: c,
            theta_o: c,
            phi_o: c,
            wavelength: c,
            value: c,
            uncertainty: c,
        }
    }

    fn of(&self, f: Field) -> Option<usize> {
        match f {
            Field::ThetaI => self.theta_i,
            Field::PhiI => self.phi_i,
            Field::ThetaO => self.theta_o,
            Field::PhiO => self.phi_o,
            Field::Wavelength => self.wavelength,
            Field::Value => self.value,
            Field::Uncertainty => self.uncertainty,
        }
    }
}

/// Validates rows one at a time into samples and finishes them into a [`Dataset`]
/// (repeated geometries, channels, planes). Every reader goes through it, so every format
/// gets the same checks and messages. Bad rows are collected, not returned at the first.
pub(crate) struct Builder<'a> {
    file: &'a str,
    kind: Kind,
    opts: &'a ReadOptions,
    samples: Vec<Sample>,
    keys: Vec<RowKey>,
    errors: Vec<(usize, Option<usize>, String)>,
    more_errors: usize,
    floored: usize,
    /// Notices of the reader (printed before the builder's own).
    pub(crate) notices: Vec<Notice>,
}

impl<'a> Builder<'a> {
    pub(crate) fn new(kind: Kind, file: &'a str, opts: &'a ReadOptions) -> Builder<'a> {
        Builder {
            file,
            kind,
            opts,
            samples: Vec::new(),
            keys: Vec::new(),
            errors: Vec::new(),
            more_errors: 0,
            floored: 0,
            notices: Vec::new(),
        }
    }

    /// Record a bad row (the first [`MAX_REPORTED_ERRORS`] are kept, the rest counted).
    pub(crate) fn error(&mut self, line: usize, msg: String) {
        self.error_at(line, None, msg);
    }

    /// Record a problem at a column (1-based, in characters) of a line, when known.
    pub(crate) fn error_at(&mut self, line: usize, column: Option<usize>, msg: String) {
        if self.errors.len() < MAX_REPORTED_ERRORS {
            self.errors.push((line, column, msg));
        } else {
            self.more_errors += 1;
        }
    }

    /// The kind of the samples.
    pub(crate) fn kind(&self) -> Kind {
        self.kind
    }

    /// Rows accepted so far.
    pub(crate) fn len(&self) -> usize {
        self.samples.len()
    }

    /// Validate one row (degrees, signed angles allowed) and keep it as a sample.
    /// `text` is the row as written, for the byte-identical-repeat warning.
    pub(crate) fn push(&mut self, line: usize, r: RawRow, text: Option<&str>) {
        self.push_at(line, r, text, &Cells::default());
    }

    /// [`Builder::push`] for a reader that knows where each field of the row is written:
    /// a rejected field's error names its column.
    pub(crate) fn push_at(&mut self, line: usize, r: RawRow, text: Option<&str>, cells: &Cells) {
        let u = match self.check(&r) {
            Ok(u) => u,
            Err((field, msg)) => return self.error_at(line, cells.of(field), msg),
        };
        let key = geometry_key(r.theta_i, r.phi_i, r.theta_o, r.phi_o, r.wavelength_nm);
        let (ti, pi) = normalise_angles(r.theta_i, r.phi_i);
        let (to, po) = normalise_angles(r.theta_o, r.phi_o);
        let (ti, pi, to, po) = (
            ti.to_radians(),
            pi.to_radians(),
            to.to_radians(),
            po.to_radians(),
        );
        let Ok(index) = u32::try_from(self.samples.len()) else {
            return self.error(line, "more than 4294967295 rows".into());
        };
        self.keys.push(RowKey {
            geometry: fold32(key_hash(&key)),
            text: text.map(|t| fold32(fnv1a(t.as_bytes())) | 1).unwrap_or(0),
            index,
        });
        self.samples.push(Sample {
            theta_i: ti,
            phi_i: pi,
            theta_o: to,
            phi_o: po,
            wavelength_nm: r.wavelength_nm,
            value: r.value,
            uncertainty: u,
            channel: 0,
            axis: 0,
            transmitted: self.kind == Kind::Btdf,
            line: u32::try_from(line).unwrap_or(u32::MAX),
        });
    }

    /// The row's checks (docs/conventions.md): its uncertainty (floored if allowed and
    /// needed), or the field at fault and why.
    fn check(&mut self, r: &RawRow) -> Result<f64, (Field, String)> {
        for (field, name, v) in [
            (Field::ThetaI, "theta_i", r.theta_i),
            (Field::PhiI, "phi_i", r.phi_i),
            (Field::ThetaO, "theta_o", r.theta_o),
            (Field::PhiO, "phi_o", r.phi_o),
            (Field::Wavelength, "wavelength_nm", r.wavelength_nm),
            (Field::Value, "value", r.value),
            (Field::Uncertainty, "uncertainty", r.uncertainty),
        ] {
            if !v.is_finite() {
                return Err((field, format!("column {name} is not a finite number ({v})")));
            }
        }
        for (field, name, v) in [
            (Field::ThetaI, "theta_i", r.theta_i),
            (Field::ThetaO, "theta_o", r.theta_o),
        ] {
            if !(-90.0..=90.0).contains(&v) {
                return Err((field, format!("{name} = {v}° is outside [-90, 90]")));
            }
        }
        if r.wavelength_nm <= 0.0 {
            return Err((
                Field::Wavelength,
                format!("wavelength_nm = {} must be positive", r.wavelength_nm),
            ));
        }
        if r.value.abs() > MAX_ABS_VALUE {
            return Err((
                Field::Value,
                format!(
                    "value = {} sr⁻¹ is outside the range of a BSDF (|value| ≤ {MAX_ABS_VALUE:e} sr⁻¹; a unit or exponent mistake?)",
                    r.value
                ),
            ));
        }
        let mut u = r.uncertainty;
        if u < 0.0 {
            return Err((Field::Uncertainty, format!("uncertainty = {u} is negative")));
        }
        let tiny = u < MIN_ABS_UNCERTAINTY || u < MIN_REL_UNCERTAINTY * r.value.abs();
        if tiny {
            if !self.opts.allow_zero_uncertainty {
                let msg = if u == 0.0 {
                    "uncertainty is zero (pass --allow-zero-uncertainty to use a floor)".into()
                } else {
                    format!(
                        "uncertainty = {u:e} is below max({MIN_REL_UNCERTAINTY:e}·|value|, {MIN_ABS_UNCERTAINTY:e} sr⁻¹): its χ² weight 1/u² would overflow or swamp every other sample (pass --allow-zero-uncertainty to use a floor)"
                    )
                };
                return Err((Field::Uncertainty, msg));
            }
            u = (UNCERTAINTY_FLOOR_REL * r.value.abs()).max(UNCERTAINTY_FLOOR_ABS);
            self.floored += 1;
        }
        if r.value < -3.0 * u {
            return Err((
                Field::Value,
                format!(
                    "value = {} is negative beyond 3 uncertainties ({u})",
                    r.value
                ),
            ));
        }
        Ok(u)
    }

    /// The errors so far as one [`DataError`], if any.
    pub(crate) fn take_errors(&mut self) -> Option<DataError> {
        if self.errors.is_empty() {
            return None;
        }
        let file = self.file.to_string();
        let mut errors = std::mem::take(&mut self.errors);
        let more = std::mem::take(&mut self.more_errors);
        Some(if errors.len() == 1 && more == 0 {
            match errors.pop().expect("one error") {
                (line, Some(column), msg) => DataError::At {
                    file,
                    line,
                    column,
                    msg,
                },
                (line, None, msg) => DataError::Line { file, line, msg },
            }
        } else {
            DataError::Lines { file, errors, more }
        })
    }

    /// Check the rows as a whole and build the dataset.
    pub(crate) fn finish(
        mut self,
        material: &str,
        meta: BTreeMap<String, String>,
    ) -> Result<Dataset, DataError> {
        if let Some(e) = self.take_errors() {
            return Err(e);
        }
        let file = self.file;
        if self.samples.is_empty() {
            return Err(DataError::File {
                file: file.to_string(),
                msg: "no data rows".into(),
            });
        }
        let mut notices = std::mem::take(&mut self.notices);
        self.repeated_geometries(&mut notices);
        if self.floored > 0 {
            notices.push(Notice::new(
                NoticeKind::UncertaintyFloor,
                format!(
                    "{file}: {} replaced by max({}·|value|, {} sr⁻¹)",
                    count(
                        self.floored,
                        "zero uncertainty (or vanishingly small)",
                        "zero uncertainties (or vanishingly small ones)"
                    ),
                    UNCERTAINTY_FLOOR_REL,
                    UNCERTAINTY_FLOOR_ABS
                ),
            ));
        }
        let mut samples = std::mem::take(&mut self.samples);
        let channels = select_channels(&mut samples, file, self.opts, &mut notices)?;
        if samples.is_empty() {
            return Err(DataError::File {
                file: file.into(),
                msg: "the selection leaves no sample".into(),
            });
        }
        let mut axes = measurement_planes(
            samples
                .iter()
                .map(|s| (s.theta_o.to_degrees(), s.phi_o.to_degrees())),
        );
        if axes.len() > MAX_PLANES {
            // Out-of-plane data (MERL tables, dense ALTA scans): one "plane" per azimuth
            // is no measurement plane; per-plane fits and checks would multiply by them.
            notices.push(Notice::from(format!(
                "{file}: {} distinct outgoing azimuths (mod 180°): the data are not scans on a few planes, so they are treated as one (no per-plane analysis)",
                axes.len()
            )));
            axes = vec![0.0];
            for s in &mut samples {
                s.axis = 0;
            }
        } else {
            for s in &mut samples {
                s.axis = plane_index(&axes, s.theta_o.to_degrees(), s.phi_o.to_degrees());
            }
        }
        samples.shrink_to_fit();
        Ok(Dataset {
            kind: self.kind,
            material: material.to_string(),
            meta,
            channels,
            samples,
            axes,
            source: PathBuf::from(file),
            notices,
            assumed_uncertainty: None,
        })
    }

    /// A geometry measured more than once is a set of independent samples (docs/conventions.md);
    /// say how many there are, and warn about rows repeated byte for byte.
    fn repeated_geometries(&mut self, notices: &mut Vec<Notice>) {
        let mut keys = std::mem::take(&mut self.keys);
        keys.sort_unstable_by_key(|k| (k.geometry, k.index));
        let (mut geometries, mut members) = (0usize, 0usize);
        let mut identical: Vec<(usize, usize)> = Vec::new();
        let mut identical_count = 0usize;
        let mut i = 0;
        while i < keys.len() {
            let mut j = i + 1;
            while j < keys.len() && keys[j].geometry == keys[i].geometry {
                j += 1;
            }
            if j - i > 1 {
                // Same hash: group by the exact key (a hash collision splits the group).
                let mut group: Vec<([i64; 5], usize, u32)> = keys[i..j]
                    .iter()
                    .map(|k| {
                        let idx = k.index as usize;
                        (sample_key(&self.samples[idx]), idx, k.text)
                    })
                    .collect();
                group.sort_unstable();
                let mut a = 0;
                while a < group.len() {
                    let mut b = a + 1;
                    while b < group.len() && group[b].0 == group[a].0 {
                        b += 1;
                    }
                    if b - a > 1 {
                        geometries += 1;
                        members += b - a;
                        for m in a + 1..b {
                            let (_, idx, text) = group[m];
                            if text == 0 {
                                continue;
                            }
                            if let Some(first) = group[a..m].iter().find(|g| g.2 == text) {
                                identical_count += 1;
                                if identical.len() < 5 {
                                    identical.push((
                                        self.samples[first.1].line as usize,
                                        self.samples[idx].line as usize,
                                    ));
                                }
                            }
                        }
                    }
                    a = b;
                }
            }
            i = j;
        }
        let file = self.file;
        if geometries > 0 {
            notices.push(Notice::from(format!(
                "{file}: {} measured more than once ({} in all), kept as independent samples",
                count(
                    geometries,
                    "geometry (and wavelength)",
                    "geometries (and wavelengths)"
                ),
                count(members, "sample", "samples")
            )));
        }
        if identical_count > 0 {
            let mut s = format!(
                "{file}: warning: {} repeated byte for byte (a row pasted twice?):",
                count(identical_count, "row", "rows")
            );
            for (a, b) in &identical {
                s += &format!(" line {b} repeats line {a};");
            }
            if identical_count > identical.len() {
                s += &format!(" … and {} more", identical_count - identical.len());
            }
            notices.push(Notice::from(s.trim_end_matches(';').to_string()));
        }
    }
}
