//! Sweep results: the rows of results.csv, their keys and content hashes, reading,
//! canonical writing and the summaries (results.json, rankings.md), and conversion between
//! a row's `params` JSON and a model's flat parameter vector. Sweep, merge, report and
//! render all read results through this module.
//!
//!
//! results.csv columns (one row per fit): `data` (file stem), `data_hash` (FNV-1a 64 of
//! the file's bytes), `data_path`, `kind`, `material`, `model`, `loss`, `weights`,
//! `optimizer`, `restarts`, `seed`, `samples` (K), `n_params` (P), `best_loss`,
//! `chi2_red`, `restarts_within_1pct`, `evaluations`, `params` and `param_std` (JSON
//! objects name → value, an array for per-channel parameters; null where undetermined),
//! `warnings` (JSON array), `seconds`, `backend`, `constraints` (the run's `--fix`,
//! `--bounds`, `--prior`, `;`-separated). Every column but `seconds` and `backend` is
//! deterministic for a given backend.

use crate::bsdf::Model;
use crate::data::{Dataset, ReadOptions};
use crate::inference::fit::FitReport;
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

pub const RESULTS_CSV: &str = "results.csv";
pub const RESULTS_JSON: &str = "results.json";
pub const SKIPPED_JSON: &str = "skipped.json";
pub const RANKINGS_MD: &str = "rankings.md";
/// Where `sweep` writes when no `--out` is given.
pub const DEFAULT_OUT: &str = "sweep-out";

/// One row of results.csv: one finished fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Row {
    pub data: String,
    pub data_hash: String,
    pub data_path: String,
    pub kind: String,
    pub material: String,
    pub model: String,
    pub loss: String,
    pub weights: String,
    pub optimizer: String,
    pub restarts: usize,
    pub seed: u64,
    pub samples: usize,
    pub n_params: usize,
    pub best_loss: f64,
    pub chi2_red: f64,
    pub restarts_within_1pct: usize,
    pub evaluations: u64,
    /// JSON object: parameter name → value (array for per-channel/per-plane parameters).
    pub params: String,
    /// JSON object: parameter name → standard uncertainty (null where undetermined).
    pub param_std: String,
    /// JSON array of warnings (e.g. parameters the data does not determine).
    pub warnings: String,
    pub seconds: f64,
    pub backend: String,
    /// The `--fix`/`--bounds`/`--prior` options of the run, `;`-separated (empty: none).
    /// One results folder holds fits made under one set of constraints.
    #[serde(default)]
    pub constraints: String,
}

/// The identity of a fit: resumption and shards depend on it being deterministic.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Key {
    pub data_hash: String,
    pub model: String,
    pub loss: String,
    pub weights: String,
    pub optimizer: String,
    pub restarts: usize,
    pub seed: u64,
}

impl Row {
    pub fn key(&self) -> Key {
        Key {
            data_hash: self.data_hash.clone(),
            model: self.model.clone(),
            loss: self.loss.clone(),
            weights: self.weights.clone(),
            optimizer: self.optimizer.clone(),
            restarts: self.restarts,
            seed: self.seed,
        }
    }

    /// Canonical order of rows in results files.
    fn order(&self) -> (String, String, String, String, String, String, usize, u64) {
        let k = self.key();
        (
            self.data.clone(),
            k.data_hash,
            k.model,
            k.loss,
            k.weights,
            k.optimizer,
            k.restarts,
            k.seed,
        )
    }

    /// The row without its run-dependent columns (seconds, backend), for comparisons.
    pub fn deterministic(&self) -> Row {
        Row {
            seconds: 0.0,
            backend: String::new(),
            ..self.clone()
        }
    }

    /// Parsed `params` (empty on malformed JSON).
    pub fn params_json(&self) -> serde_json::Map<String, serde_json::Value> {
        serde_json::from_str(&self.params).unwrap_or_default()
    }

    pub fn param_std_json(&self) -> serde_json::Map<String, serde_json::Value> {
        serde_json::from_str(&self.param_std).unwrap_or_default()
    }

    pub fn warnings_json(&self) -> Vec<String> {
        serde_json::from_str(&self.warnings).unwrap_or_default()
    }

    pub fn from_report(r: &FitReport, d: &DataFile) -> Row {
        Row {
            data: d.name.clone(),
            data_hash: d.hash.clone(),
            data_path: d.path.display().to_string(),
            kind: d.data.kind.to_string(),
            material: d.data.material.clone(),
            model: r.model.clone(),
            loss: r.loss.clone(),
            weights: r.weights.clone(),
            optimizer: r.optimizer.clone(),
            restarts: r.restarts,
            seed: r.seed,
            samples: r.samples,
            n_params: r.n_params,
            best_loss: r.best.loss,
            chi2_red: r.best.chi2_red,
            restarts_within_1pct: r.restarts_within_1pct,
            evaluations: r.evaluations,
            params: serde_json::to_string(&r.best.params).unwrap_or_else(|_| "{}".into()),
            param_std: serde_json::to_string(&r.best.param_std).unwrap_or_else(|_| "{}".into()),
            warnings: serde_json::to_string(&r.warnings).unwrap_or_else(|_| "[]".into()),
            seconds: (r.seconds * 1000.0).round() / 1000.0,
            backend: r.backend.clone(),
            constraints: String::new(),
        }
    }

    /// The row as a JSON object with `params`/`param_std`/`warnings` decoded.
    pub fn to_json(&self) -> serde_json::Value {
        let mut v = serde_json::to_value(self).unwrap_or(serde_json::Value::Null);
        if let Some(o) = v.as_object_mut() {
            o.insert(
                "params".into(),
                serde_json::Value::Object(self.params_json()),
            );
            o.insert(
                "param_std".into(),
                serde_json::Value::Object(self.param_std_json()),
            );
            o.insert("warnings".into(), serde_json::json!(self.warnings_json()));
        }
        v
    }
}

/// The flat parameter vector of `model` from a `params` JSON object (names → value or
/// array), as written by `fit --json` (`best.params`) and results.csv.
pub fn flat_from_params(
    model: &Model,
    params: &serde_json::Map<String, serde_json::Value>,
) -> Result<Vec<f64>> {
    let mut flat = vec![f64::NAN; model.dim];
    for p in &model.params {
        let w = p.width(model.channels);
        let v = params
            .get(&p.name)
            .with_context(|| format!("no value for parameter '{}' of {}", p.name, model.spec))?;
        let vals: Vec<f64> = match v {
            serde_json::Value::Array(a) => {
                a.iter().map(|x| x.as_f64().unwrap_or(f64::NAN)).collect()
            }
            x => vec![x.as_f64().unwrap_or(f64::NAN)],
        };
        anyhow::ensure!(
            vals.len() == w,
            "parameter '{}' of {} has {} values, expected {w}",
            p.name,
            model.spec,
            vals.len()
        );
        anyhow::ensure!(
            vals.iter().all(|x| x.is_finite()),
            "parameter '{}' of {} is not a number",
            p.name,
            model.spec
        );
        flat[p.index..p.index + w].copy_from_slice(&vals);
    }
    Ok(flat)
}

/// FNV-1a 64-bit hash of bytes, as 16 hex digits (stable across platforms and runs).
pub fn content_hash(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// A data set file of the sweep.
pub struct DataFile {
    /// Display name: the file stem.
    pub name: String,
    pub path: PathBuf,
    pub hash: String,
    pub data: Dataset,
}

impl DataFile {
    pub fn read(path: &Path, opts: &ReadOptions) -> Result<DataFile> {
        let bytes =
            std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        let data = crate::data::readers::parse_bytes(&bytes, &path.display().to_string(), opts)?;
        let hash = DataFile::hash_of(&bytes, opts);
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "data".into());
        Ok(DataFile {
            name,
            path: path.to_path_buf(),
            hash,
            data,
        })
    }

    /// The key of the data set `bytes` read with `opts`: a channel selection makes other
    /// data from the same bytes, so it is keyed apart.
    pub fn hash_of(bytes: &[u8], opts: &ReadOptions) -> String {
        if opts.wavelengths.is_none()
            && !opts.allow_zero_uncertainty
            && opts.assume_uncertainty.is_none()
            && opts.band_nm.is_none()
            && opts.alta_values.is_none()
        {
            content_hash(bytes)
        } else {
            content_hash(&[bytes, format!("{opts:?}").as_bytes()].concat())
        }
    }
}

/// A task that produced no row, and why.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Skipped {
    pub data: String,
    pub model: String,
    pub loss: String,
    pub weights: String,
    pub optimizer: String,
    /// `skipped` (the model is unavailable) or `failed` (the fit returned an error).
    pub status: String,
    pub reason: String,
}

/// (data, model, loss, weights, optimizer): what identifies a fit when results and
/// skipped lists are compared (restarts and seed are those of the sweep).
pub type FitKey = (String, String, String, String, String);

/// The fit key of a data set's label and a fit's key fields.
pub fn fit_key(data: &str, model: &str, loss: &str, weights: &str, optimizer: &str) -> FitKey {
    (
        data.into(),
        model.into(),
        loss.into(),
        weights.into(),
        optimizer.into(),
    )
}

impl Skipped {
    pub fn fit_key(&self) -> FitKey {
        fit_key(
            &self.data,
            &self.model,
            &self.loss,
            &self.weights,
            &self.optimizer,
        )
    }
}

impl Row {
    pub fn fit_key(&self) -> FitKey {
        fit_key(
            &self.data,
            &self.model,
            &self.loss,
            &self.weights,
            &self.optimizer,
        )
    }
}

/// Read results.csv. An incomplete last line (a write cut off by an interruption) is cut
/// from the file; rows that do not parse are reported and left out.
pub fn read_results(path: &Path, repair: bool, notice: &mut dyn FnMut(String)) -> Result<Vec<Row>> {
    if !path.exists() {
        return Ok(Vec::new());
    }
    let mut bytes =
        std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    if !bytes.is_empty() && !bytes.ends_with(b"\n") {
        let keep = bytes
            .iter()
            .rposition(|&b| b == b'\n')
            .map(|i| i + 1)
            .unwrap_or(0);
        notice(format!(
            "{}: dropped an incomplete last line (an interrupted write)",
            path.display()
        ));
        bytes.truncate(keep);
        if repair {
            std::fs::OpenOptions::new()
                .write(true)
                .open(path)
                .and_then(|f| f.set_len(keep as u64))
                .with_context(|| {
                    format!("cannot cut the incomplete line off {}", path.display())
                })?;
        }
    }
    if bytes.is_empty() {
        return Ok(Vec::new());
    }
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(bytes.as_slice());
    let header: Vec<String> = rdr
        .headers()
        .with_context(|| format!("cannot read the header of {}", path.display()))?
        .iter()
        .map(str::to_string)
        .collect();
    let expected = header_names();
    // Files written before the `constraints` column existed read as unconstrained.
    if header != expected && header[..] != expected[..expected.len() - 1] {
        bail!(
            "{} has columns {:?}, not this version's {:?}; use another --out directory",
            path.display(),
            header,
            expected
        );
    }
    let mut rows = Vec::new();
    for (i, rec) in rdr.deserialize::<Row>().enumerate() {
        match rec {
            Ok(r) => rows.push(r),
            Err(e) => notice(format!(
                "{}: row {} is malformed and is ignored ({e})",
                path.display(),
                i + 2
            )),
        }
    }
    Ok(rows)
}

fn header_names() -> Vec<String> {
    // The field names of Row, in order, from a serialized dummy row.
    let dummy = Row {
        data: String::new(),
        data_hash: String::new(),
        data_path: String::new(),
        kind: String::new(),
        material: String::new(),
        model: String::new(),
        loss: String::new(),
        weights: String::new(),
        optimizer: String::new(),
        restarts: 0,
        seed: 0,
        samples: 0,
        n_params: 0,
        best_loss: 0.0,
        chi2_red: 0.0,
        restarts_within_1pct: 0,
        evaluations: 0,
        params: String::new(),
        param_std: String::new(),
        warnings: String::new(),
        seconds: 0.0,
        backend: String::new(),
        constraints: String::new(),
    };
    let mut w = csv::WriterBuilder::new()
        .has_headers(true)
        .from_writer(Vec::new());
    w.serialize(&dummy).expect("serialize a row");
    let bytes = w.into_inner().expect("in-memory writer");
    let text = String::from_utf8(bytes).expect("utf8");
    text.lines()
        .next()
        .unwrap_or_default()
        .split(',')
        .map(str::to_string)
        .collect()
}

/// Rows in canonical order as CSV text (with header).
pub fn results_csv_text(rows: &[Row]) -> Result<String> {
    let mut rows: Vec<&Row> = rows.iter().collect();
    rows.sort_by_key(|a| a.order());
    let mut w = csv::WriterBuilder::new()
        .has_headers(true)
        .from_writer(Vec::new());
    if rows.is_empty() {
        w.write_record(header_names())?;
    }
    for r in rows {
        w.serialize(r)?;
    }
    Ok(String::from_utf8(
        w.into_inner().map_err(|e| anyhow::anyhow!("{e}"))?,
    )?)
}

pub use crate::output::files::write_if_changed;

/// Appends rows to results.csv, flushing after each.
pub struct Appender {
    w: csv::Writer<std::fs::File>,
    path: PathBuf,
}

impl Appender {
    pub fn open(path: &Path) -> Result<Appender> {
        let new = std::fs::metadata(path)
            .map(|m| m.len() == 0)
            .unwrap_or(true);
        let f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .with_context(|| format!("cannot open {}", path.display()))?;
        let mut w = csv::WriterBuilder::new().has_headers(false).from_writer(f);
        if new {
            w.write_record(header_names())
                .and_then(|_| w.flush().map_err(csv::Error::from))
                .with_context(|| format!("cannot write {}", path.display()))?;
        }
        Ok(Appender {
            w,
            path: path.to_path_buf(),
        })
    }
    pub fn push(&mut self, row: &Row) -> Result<()> {
        self.w
            .serialize(row)
            .and_then(|_| self.w.flush().map_err(csv::Error::from))
            .with_context(|| format!("cannot append a row to {}", self.path.display()))
    }
}

/// Results files beside results.csv: results.json and rankings.md.
pub fn write_summaries(out: &Path, rows: &[Row]) -> Result<()> {
    let mut sorted: Vec<&Row> = rows.iter().collect();
    sorted.sort_by_key(|a| a.order());
    let json: Vec<serde_json::Value> = sorted.iter().map(|r| r.to_json()).collect();
    write_if_changed(
        &out.join(RESULTS_JSON),
        &(serde_json::to_string_pretty(&json)? + "\n"),
    )?;
    write_if_changed(&out.join(RANKINGS_MD), &rankings_markdown(rows))?;
    Ok(())
}

/// Rows of one data set ranked: per model, its fits, sorted by the model's best χ²_red.
pub struct Ranking<'a> {
    pub data: String,
    pub data_hash: String,
    /// (loss, weights, optimizer) combinations present, in canonical order.
    pub columns: Vec<(String, String, String)>,
    /// (model, fits per column (None if absent), best χ²_red), best first.
    pub models: Vec<(String, Vec<Option<&'a Row>>, f64)>,
}

/// The version of each data set the report shows: the hash of its file as it is now
/// (if readable at `data_path`), else the hash with the most rows.
pub fn live_hashes(rows: &[Row]) -> BTreeMap<String, String> {
    let mut counts: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    let mut paths: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for r in rows {
        *counts
            .entry(r.data.clone())
            .or_default()
            .entry(r.data_hash.clone())
            .or_default() += 1;
        paths
            .entry(r.data.clone())
            .or_default()
            .insert(r.data_path.clone());
    }
    let mut out = BTreeMap::new();
    for (data, hashes) in counts {
        let on_disk = paths[&data]
            .iter()
            .filter_map(|p| std::fs::read(p).ok())
            .map(|b| content_hash(&b))
            .find(|h| hashes.contains_key(h));
        let h = on_disk.unwrap_or_else(|| {
            hashes
                .iter()
                .max_by_key(|(h, n)| (**n, std::cmp::Reverse((*h).clone())))
                .map(|(h, _)| h.clone())
                .unwrap_or_default()
        });
        out.insert(data, h);
    }
    out
}

/// The current rows: rows of the live version of each data set ([`live_hashes`]) and, for
/// each (data, model, loss, weights, optimizer), the one with the most restarts (then the
/// smallest seed); superseded rows are left out.
pub fn current_rows(rows: &[Row]) -> Vec<&Row> {
    let live = live_hashes(rows);
    let mut best: BTreeMap<(String, String, String, String, String, String), &Row> =
        BTreeMap::new();
    for r in rows
        .iter()
        .filter(|r| live.get(&r.data) == Some(&r.data_hash))
    {
        let k = (
            r.data.clone(),
            r.data_hash.clone(),
            r.model.clone(),
            r.loss.clone(),
            r.weights.clone(),
            r.optimizer.clone(),
        );
        match best.get(&k) {
            Some(o)
                if (o.restarts, std::cmp::Reverse(o.seed))
                    >= (r.restarts, std::cmp::Reverse(r.seed)) => {}
            _ => {
                best.insert(k, r);
            }
        }
    }
    best.into_values().collect()
}

/// Rankings per data set (data sets in name order).
pub fn rankings(rows: &[Row]) -> Vec<Ranking<'_>> {
    let cur = current_rows(rows);
    let mut by_data: BTreeMap<(String, String), Vec<&Row>> = BTreeMap::new();
    for r in cur {
        by_data
            .entry((r.data.clone(), r.data_hash.clone()))
            .or_default()
            .push(r);
    }
    let mut out = Vec::new();
    for ((data, hash), rs) in by_data {
        let columns: Vec<(String, String, String)> = rs
            .iter()
            .map(|r| (r.loss.clone(), r.weights.clone(), r.optimizer.clone()))
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect();
        // Uniform before weighted within a loss, as the paper's comparison reads.
        let mut columns = columns;
        columns.sort_by_key(|(l, w, o)| {
            (l == "chi2", l.clone(), w != "uniform", w.clone(), o.clone())
        });
        let mut models: BTreeMap<String, Vec<Option<&Row>>> = BTreeMap::new();
        for r in &rs {
            let c = columns
                .iter()
                .position(|c| c.0 == r.loss && c.1 == r.weights && c.2 == r.optimizer)
                .expect("column listed");
            models
                .entry(r.model.clone())
                .or_insert_with(|| vec![None; columns.len()])[c] = Some(r);
        }
        let mut ms: Vec<(String, Vec<Option<&Row>>, f64)> = models
            .into_iter()
            .map(|(m, fits)| {
                let best = fits
                    .iter()
                    .flatten()
                    .map(|r| r.chi2_red)
                    .filter(|x| x.is_finite())
                    .fold(f64::INFINITY, f64::min);
                (m, fits, best)
            })
            .collect();
        ms.sort_by(|a, b| a.2.total_cmp(&b.2).then(a.0.cmp(&b.0)));
        out.push(Ranking {
            data,
            data_hash: hash,
            columns,
            models: ms,
        });
    }
    out
}

/// Compact number formatting for tables.
pub fn fmt_num(x: f64) -> String {
    if !x.is_finite() {
        return format!("{x}");
    }
    let a = x.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{x:.3e}")
    } else {
        format!("{x:.4}")
    }
}

fn rankings_markdown(rows: &[Row]) -> String {
    let mut s = String::from("# Model rankings per data set\n\nModels sorted by their best reduced χ² over the fits run (χ²_red = Σ((y′−y)/u)²/(K−P), whatever loss drove the fit). Cells: loss value / χ²_red.\n");
    for rk in rankings(rows) {
        s += &format!("\n## {}\n\n| rank | model |", rk.data);
        for (l, w, o) in &rk.columns {
            s += &format!(" {l}/{w} ({o}) |");
        }
        s += " best χ²_red |\n|---:|---|";
        for _ in &rk.columns {
            s += "---:|";
        }
        s += "---:|\n";
        for (i, (m, fits, best)) in rk.models.iter().enumerate() {
            s += &format!("| {} | `{m}` |", i + 1);
            for f in fits {
                match f {
                    Some(r) => {
                        s += &format!(" {} / {} |", fmt_num(r.best_loss), fmt_num(r.chi2_red))
                    }
                    None => s += " – |",
                }
            }
            s += &format!(" {} |\n", fmt_num(*best));
        }
    }
    s
}
