//! `bsdfit sweep` and `bsdfit merge`: the benchmark as users run it (issue #5).
//!
//! A sweep is a list of tasks — every data set × applicable model × loss × weighting ×
//! optimizer — run one fit at a time on one backend. Each finished fit is appended to
//! `results.csv` and flushed at once, so an interrupted sweep loses at most the fit in
//! flight; a re-run reads the rows back and skips every task whose [`Key`] is present.
//! `--shard I/N` keeps the tasks whose index in the (deterministic) task list is I−1
//! modulo N, so N machines can share a sweep; `bsdfit merge` unions their rows.
//!
//! When the sweep ends, `results.csv` is rewritten in a canonical order (sorted by data
//! set, model, loss, weights, optimizer, restarts, seed; only if that changes a byte),
//! `results.json`, `rankings.md`, `skipped.json` are written, and then the pictures and
//! `report.html` ([`crate::report`]).
//!
//! results.csv columns (one row per fit): `data` (file stem), `data_hash` (FNV-1a 64 of
//! the file's bytes), `data_path`, `kind`, `material`, `model`, `loss`, `weights`,
//! `optimizer`, `restarts`, `seed`, `samples` (K), `n_params` (P), `best_loss`,
//! `chi2_red`, `restarts_within_1pct`, `evaluations`, `params` and `param_std` (JSON
//! objects name → value, an array for per-channel parameters; null where undetermined),
//! `warnings` (JSON array), `seconds`, `backend`. Every column but the last two is
//! deterministic for a given backend.

use crate::backend::{self, BackendChoice};
use crate::dataset::{Dataset, Kind, ReadOptions};
use crate::fit::{fit, FitOptions, FitReport, Optimizer};
use crate::loss::{Loss, Metric, Weights};
use crate::model::{self, Model};
use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

pub const RESULTS_CSV: &str = "results.csv";
pub const RESULTS_JSON: &str = "results.json";
pub const SKIPPED_JSON: &str = "skipped.json";
pub const RANKINGS_MD: &str = "rankings.md";
/// Where `sweep` writes when no `--out` is given.
pub const DEFAULT_OUT: &str = "sweep-out";

/// `bsdfit sweep` arguments.
#[derive(clap::Args, Debug, Clone)]
pub struct SweepArgs {
    /// Data set files or directories of *.csv files (default: the bundled data/ directory).
    pub data: Vec<PathBuf>,
    /// Model specs, comma-separated (default: the whole catalogue for each kind of data;
    /// a spec is used on the data sets of its kind).
    #[arg(long, value_delimiter = ',')]
    pub models: Option<Vec<String>>,
    /// Losses, comma-separated (default: rmse,chi2 for BRDF, f,chi2 for BTDF — the paper's
    /// RMSE / g₁ comparison plus the χ² fit; each loss is used on the data sets it is
    /// defined for).
    #[arg(long, value_delimiter = ',')]
    pub losses: Option<Vec<String>>,
    /// Weightings, comma-separated: uniform, relunc, invunc, or unc (the kind's
    /// uncertainty weighting: relunc for BRDF, invunc for BTDF). Default: uniform,unc.
    /// (chi2 weights by 1/u² by definition and is fitted once, as `uniform`.)
    #[arg(long, value_delimiter = ',')]
    pub weights: Option<Vec<String>>,
    /// Optimizers, comma-separated: lm, compass, or auto (lm for sum-of-squares losses,
    /// compass otherwise). Combinations lm × smape are left out.
    #[arg(long, value_delimiter = ',', default_value = "auto")]
    pub optimizer: Vec<String>,
    /// Random restarts per fit.
    #[arg(long, default_value_t = 8)]
    pub restarts: usize,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[arg(long, value_enum, default_value = "auto")]
    pub backend: BackendChoice,
    /// Output directory (results, pictures, report.html).
    #[arg(long, default_value = DEFAULT_OUT)]
    pub out: PathBuf,
    /// Run only shard I of N (1-based), e.g. 2/4; combine the shards with `bsdfit merge`.
    #[arg(long)]
    pub shard: Option<String>,
    /// Skip the plots, renders and report.html (results files only).
    #[arg(long)]
    pub no_pictures: bool,
    /// List the tasks (and which are done) without fitting.
    #[arg(long)]
    pub dry_run: bool,
}

/// `bsdfit merge` arguments.
#[derive(clap::Args, Debug, Clone)]
pub struct MergeArgs {
    /// Shard output directories (or their results.csv files).
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Output directory; rows already in its results.csv are kept.
    #[arg(long, default_value = DEFAULT_OUT)]
    pub out: PathBuf,
    /// Skip the plots, renders and report.html (results files only).
    #[arg(long)]
    pub no_pictures: bool,
}

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
}

/// The identity of a fit: resumption and shards depend on it being deterministic.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
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

    fn from_report(r: &FitReport, d: &DataFile) -> Row {
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
            n_params: r.flat_params.len(),
            best_loss: r.best.loss,
            chi2_red: r.best.chi2_red,
            restarts_within_1pct: r.restarts_within_1pct,
            evaluations: r.evaluations,
            params: serde_json::to_string(&r.best.params).unwrap_or_else(|_| "{}".into()),
            param_std: serde_json::to_string(&r.best.param_std).unwrap_or_else(|_| "{}".into()),
            warnings: serde_json::to_string(&r.warnings).unwrap_or_else(|_| "[]".into()),
            seconds: (r.seconds * 1000.0).round() / 1000.0,
            backend: r.backend.clone(),
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
    pub fn read(path: &Path) -> Result<DataFile> {
        let bytes =
            std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
        let data = crate::readers::parse_bytes(
            &bytes,
            &path.display().to_string(),
            &ReadOptions::default(),
        )?;
        let name = path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "data".into());
        Ok(DataFile {
            name,
            path: path.to_path_buf(),
            hash: content_hash(&bytes),
            data,
        })
    }
}

/// The bundled data directory: `./data` if present, else the crate's own `data/`.
pub fn bundled_data_dir() -> PathBuf {
    let local = PathBuf::from("data");
    if local.is_dir() {
        return local;
    }
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data")
}

/// Expand files and directories (their *.csv, sorted) into a list of data files.
pub fn expand_data(paths: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let paths: Vec<PathBuf> = if paths.is_empty() {
        vec![bundled_data_dir()]
    } else {
        paths.to_vec()
    };
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut v: Vec<PathBuf> = std::fs::read_dir(&p)
                .with_context(|| format!("cannot list {}", p.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.extension().is_some_and(|x| x.eq_ignore_ascii_case("csv")))
                .collect();
            v.sort();
            anyhow::ensure!(!v.is_empty(), "{} holds no *.csv data set", p.display());
            out.extend(v);
        } else {
            out.push(p);
        }
    }
    Ok(out)
}

/// The kind of data a spec is for, from its syntax (works for models that fail to build).
pub fn spec_kind(spec: &str) -> Kind {
    if spec.trim_start().to_ascii_lowercase().starts_with("btdf") {
        Kind::Btdf
    } else {
        Kind::Brdf
    }
}

/// One fit to run.
#[derive(Clone, Debug)]
pub struct Task {
    /// Index into the sweep's data files.
    pub data: usize,
    pub model: String,
    pub loss: Metric,
    pub weights: Weights,
    pub optimizer: Optimizer,
}

/// Parse `I/N` (1 ≤ I ≤ N).
pub fn parse_shard(s: &str) -> Result<(usize, usize)> {
    let (i, n) = s
        .split_once('/')
        .context("--shard: expected I/N, e.g. 1/2")?;
    let (i, n): (usize, usize) = (
        i.trim().parse().context("--shard: I")?,
        n.trim().parse().context("--shard: N")?,
    );
    anyhow::ensure!(
        n >= 1 && (1..=n).contains(&i),
        "--shard {s}: need 1 ≤ I ≤ N"
    );
    Ok((i, n))
}

fn parse_weights(w: &str, kind: Kind) -> Result<Weights> {
    if w.trim().eq_ignore_ascii_case("unc") {
        return Ok(Weights::uncertainty_for(kind));
    }
    w.parse()
        .map_err(|e: String| anyhow::anyhow!("--weights: {e}"))
}

/// Every task of a sweep, in a deterministic order: data files as given, then models,
/// losses, weightings, optimizers as listed.
pub fn tasks(files: &[DataFile], args: &SweepArgs) -> Result<Vec<Task>> {
    let mut out = Vec::new();
    for (di, f) in files.iter().enumerate() {
        let kind = f.data.kind;
        let models: Vec<String> = match &args.models {
            Some(list) => list
                .iter()
                .map(|s| s.trim().to_string())
                .filter(|s| !s.is_empty() && spec_kind(s) == kind)
                .collect(),
            None => {
                let mut v = model::catalogue(kind);
                // Data measured on several φ planes (anisotropic diffusers, paper §2.3.2)
                // also gets the per-plane roughness variants of the scaled BTDF models.
                if kind == Kind::Btdf && f.data.axes.len() > 1 {
                    v.extend(
                        ["tr", "beckmann", "gtr", "gg"]
                            .iter()
                            .map(|n| format!("btdf({n})+scale+peraxis")),
                    );
                }
                v
            }
        };
        let losses: Vec<Metric> = match &args.losses {
            Some(list) => {
                let mut v = Vec::new();
                for l in list {
                    let m: Metric = l
                        .parse()
                        .map_err(|e: String| anyhow::anyhow!("--losses: {e}"))?;
                    if m.applies_to(kind) && !v.contains(&m) {
                        v.push(m);
                    }
                }
                v
            }
            None => vec![
                match kind {
                    Kind::Brdf => Metric::Rmse,
                    Kind::Btdf => Metric::F,
                },
                Metric::Chi2,
            ],
        };
        let weight_names: Vec<String> = args
            .weights
            .clone()
            .unwrap_or_else(|| vec!["uniform".into(), "unc".into()]);
        let mut weights = Vec::new();
        for w in &weight_names {
            let w = parse_weights(w, kind)?;
            if !weights.contains(&w) {
                weights.push(w);
            }
        }
        for m in &models {
            for &loss in &losses {
                // χ² weights by 1/u² whatever the weighting: fit it once.
                let ws: &[Weights] = if loss == Metric::Chi2 {
                    &[Weights::Uniform]
                } else {
                    &weights
                };
                for &w in ws {
                    let mut opts = Vec::new();
                    for o in &args.optimizer {
                        let o = match o.trim().to_ascii_lowercase().as_str() {
                            "auto" => {
                                if Loss::new(loss, w).is_sum_of_squares() {
                                    Optimizer::Lm
                                } else {
                                    Optimizer::Compass
                                }
                            }
                            "lm" => Optimizer::Lm,
                            "compass" => Optimizer::Compass,
                            other => bail!("--optimizer: unknown '{other}' (auto, lm, compass)"),
                        };
                        if o == Optimizer::Lm && !Loss::new(loss, w).is_sum_of_squares() {
                            continue; // LM needs a sum of squares
                        }
                        if !opts.contains(&o) {
                            opts.push(o);
                        }
                    }
                    for o in opts {
                        out.push(Task {
                            data: di,
                            model: m.clone(),
                            loss,
                            weights: w,
                            optimizer: o,
                        });
                    }
                }
            }
        }
    }
    Ok(out)
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
type FitKey = (String, String, String, String, String);

fn fit_key(data: &str, model: &str, loss: &str, weights: &str, optimizer: &str) -> FitKey {
    (
        data.into(),
        model.into(),
        loss.into(),
        weights.into(),
        optimizer.into(),
    )
}

impl Skipped {
    fn fit_key(&self) -> FitKey {
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
    fn fit_key(&self) -> FitKey {
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
            let f = std::fs::OpenOptions::new().write(true).open(path)?;
            f.set_len(keep as u64)?;
        }
    }
    if bytes.is_empty() {
        return Ok(Vec::new());
    }
    let mut rdr = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_reader(bytes.as_slice());
    let header: Vec<String> = rdr.headers()?.iter().map(str::to_string).collect();
    let expected = header_names();
    if header != expected {
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

/// Write `text` to `path` atomically, and only if it changes the file.
pub fn write_if_changed(path: &Path, text: &str) -> Result<bool> {
    if std::fs::read(path).ok().as_deref() == Some(text.as_bytes()) {
        return Ok(false);
    }
    let tmp = path.with_extension("tmp");
    std::fs::write(&tmp, text).with_context(|| format!("cannot write {}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(true)
}

/// Appends rows to results.csv, flushing after each.
struct Appender {
    w: csv::Writer<std::fs::File>,
}

impl Appender {
    fn open(path: &Path) -> Result<Appender> {
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
            w.write_record(header_names())?;
            w.flush()?;
        }
        Ok(Appender { w })
    }
    fn push(&mut self, row: &Row) -> Result<()> {
        self.w.serialize(row)?;
        self.w.flush()?;
        Ok(())
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

/// The `sweep` command.
pub fn run_sweep(args: &SweepArgs) -> Result<()> {
    let t0 = Instant::now();
    let shard = args.shard.as_deref().map(parse_shard).transpose()?;
    let paths = expand_data(&args.data)?;
    let mut files = Vec::new();
    for p in &paths {
        files.push(DataFile::read(p)?);
    }
    anyhow::ensure!(args.restarts > 0, "--restarts must be at least 1");
    let all = tasks(&files, args)?;
    let mine: Vec<(usize, &Task)> = all
        .iter()
        .enumerate()
        .filter(|(i, _)| shard.is_none_or(|(k, n)| i % n == k - 1))
        .collect();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let csv_path = args.out.join(RESULTS_CSV);
    let mut rows = read_results(&csv_path, !args.dry_run, &mut |m| eprintln!("note: {m}"))?;
    let done: BTreeSet<Key> = rows.iter().map(Row::key).collect();
    let key_of = |t: &Task| Key {
        data_hash: files[t.data].hash.clone(),
        model: t.model.clone(),
        loss: t.loss.to_string(),
        weights: t.weights.to_string(),
        optimizer: t.optimizer.to_string(),
        restarts: args.restarts,
        seed: args.seed,
    };
    let todo: Vec<&Task> = mine
        .iter()
        .map(|(_, t)| *t)
        .filter(|t| !done.contains(&key_of(t)))
        .collect();
    let shard_note = shard
        .map(|(i, n)| format!(" (shard {i}/{n})"))
        .unwrap_or_default();
    eprintln!(
        "sweep{shard_note}: {} data set(s), {} task(s) of {}; {} already in {}, {} to run",
        files.len(),
        mine.len(),
        all.len(),
        mine.len() - todo.len(),
        csv_path.display(),
        todo.len()
    );
    if args.dry_run {
        for (i, t) in &mine {
            let state = if done.contains(&key_of(t)) {
                "done"
            } else {
                "todo"
            };
            println!(
                "{i}\t{state}\t{}\t{}\t{}/{}\t{}",
                files[t.data].name, t.model, t.loss, t.weights, t.optimizer
            );
        }
        return Ok(());
    }

    let mut skipped: Vec<Skipped> = Vec::new();
    let mut unavailable: HashMap<String, String> = HashMap::new();
    let mut new_rows = 0usize;
    if !todo.is_empty() {
        let backend = backend::select(args.backend, &mut |m| eprintln!("{m}"))?;
        let mut app = Appender::open(&csv_path)?;
        let bar = indicatif::ProgressBar::new(todo.len() as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} [{elapsed_precise}] {bar:30} {pos}/{len} fits (ETA {eta}) {wide_msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        // Models that cannot be built are skipped up front (cheap, sequential).
        let mut runnable: Vec<(&Task, Model)> = Vec::new();
        for t in &todo {
            let f = &files[t.data];
            match Model::for_data(&t.model, &f.data) {
                Ok(m) => runnable.push((t, m)),
                Err(e) => {
                    let reason = e.to_string();
                    if unavailable
                        .insert(t.model.clone(), reason.clone())
                        .is_none()
                    {
                        say(&bar, format!("skipping {}: {reason}", t.model));
                    }
                    skipped.push(skipped_entry(f, t, "skipped", reason));
                    bar.inc(1);
                }
            }
        }
        // Fits run on one worker per core (a fit's batches are small, so one fit alone
        // leaves cores idle); this thread appends every finished fit to results.csv at
        // once, so an interrupted run loses at most the fits in flight. Each fit is
        // deterministic on its own, and results.csv is rewritten in canonical order at
        // the end, so the outcome does not depend on which worker finished first.
        let workers = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
            .clamp(1, runnable.len().max(1));
        let next = std::sync::atomic::AtomicUsize::new(0);
        let stop = std::sync::atomic::AtomicBool::new(false);
        let backend = backend.as_ref();
        std::thread::scope(|scope| -> Result<()> {
            let (tx, rx) = std::sync::mpsc::channel();
            for _ in 0..workers {
                let tx = tx.clone();
                let (runnable, next, stop, files) = (&runnable, &next, &stop, &files);
                scope.spawn(move || loop {
                    let i = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                    if i >= runnable.len() || stop.load(std::sync::atomic::Ordering::SeqCst) {
                        break;
                    }
                    let (t, model) = &runnable[i];
                    let opts = FitOptions {
                        optimizer: t.optimizer,
                        restarts: args.restarts,
                        seed: args.seed,
                        ..Default::default()
                    };
                    let loss = Loss::new(t.loss, t.weights);
                    let data = &files[t.data].data;
                    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        fit(model, data, loss, backend, &opts, &mut |_| {})
                    }));
                    if tx.send((i, result)).is_err() {
                        break;
                    }
                });
            }
            drop(tx);
            for (i, result) in rx {
                let (t, _) = &runnable[i];
                let f = &files[t.data];
                let loss = Loss::new(t.loss, t.weights);
                bar.set_message(format!(
                    "{} · {} · {}/{} · {}",
                    f.name, t.model, t.loss, t.weights, t.optimizer
                ));
                match result {
                    Ok(Ok(report)) => {
                        let row = Row::from_report(&report, f);
                        if let Err(e) = app.push(&row) {
                            stop.store(true, std::sync::atomic::Ordering::SeqCst);
                            return Err(e);
                        }
                        rows.push(row);
                        new_rows += 1;
                    }
                    Ok(Err(e)) => {
                        say(
                            &bar,
                            format!("fit failed: {} · {} · {loss}: {e:#}", f.name, t.model),
                        );
                        skipped.push(skipped_entry(f, t, "failed", format!("{e:#}")));
                    }
                    Err(p) => {
                        let msg = p
                            .downcast_ref::<String>()
                            .cloned()
                            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                            .unwrap_or_else(|| "panic".into());
                        say(
                            &bar,
                            format!("fit panicked: {} · {} · {loss}: {msg}", f.name, t.model),
                        );
                        skipped.push(skipped_entry(f, t, "failed", format!("panic: {msg}")));
                    }
                }
                bar.inc(1);
            }
            Ok(())
        })?;
        bar.finish_and_clear();
    }
    // Canonical results.csv (unchanged bytes when nothing new ran), then summaries.
    write_if_changed(&csv_path, &results_csv_text(&rows)?)?;
    write_summaries(&args.out, &rows)?;
    write_skipped(&args.out, &skipped, &rows, &files)?;
    eprintln!(
        "{} new fit(s), {} row(s) in {}, {} skipped/failed, {:.1} s",
        new_rows,
        rows.len(),
        csv_path.display(),
        skipped.len(),
        t0.elapsed().as_secs_f64()
    );
    if shard.is_some() {
        eprintln!("shard done; combine the shards with `bsdfit merge DIR... --out DIR` (it writes the pictures and report)");
    } else if !args.no_pictures {
        crate::report::publish(&args.out, &rows, &mut |m| eprintln!("{m}"))?;
    }
    Ok(())
}

/// skipped.json: this run's skipped/failed tasks, plus earlier ones that still have no row.
fn write_skipped(out: &Path, now: &[Skipped], rows: &[Row], files: &[DataFile]) -> Result<()> {
    let path = out.join(SKIPPED_JSON);
    let mut all: Vec<Skipped> = now.to_vec();
    let names: BTreeSet<&str> = files.iter().map(|f| f.name.as_str()).collect();
    let have: BTreeSet<FitKey> = rows.iter().map(Row::fit_key).collect();
    let id = Skipped::fit_key;
    if let Ok(text) = std::fs::read_to_string(&path) {
        let old: Vec<Skipped> = serde_json::from_str(&text).unwrap_or_default();
        let seen: BTreeSet<_> = all.iter().map(id).collect();
        // Earlier entries for data sets not in this run, still without a row, are kept.
        all.extend(old.into_iter().filter(|s| {
            !names.contains(s.data.as_str()) && !seen.contains(&id(s)) && !have.contains(&id(s))
        }));
    }
    all.sort_by_key(id);
    write_if_changed(&path, &(serde_json::to_string_pretty(&all)? + "\n"))?;
    Ok(())
}

/// The `merge` command: union the rows of shard directories into `--out`.
pub fn run_merge(args: &MergeArgs) -> Result<()> {
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let out_csv = args.out.join(RESULTS_CSV);
    let mut rows = read_results(&out_csv, true, &mut |m| eprintln!("note: {m}"))?;
    let mut by_key: BTreeMap<Key, usize> =
        rows.iter().enumerate().map(|(i, r)| (r.key(), i)).collect();
    let mut skipped: Vec<Skipped> = Vec::new();
    for input in &args.inputs {
        let (csv, dir) = if input.is_dir() {
            (input.join(RESULTS_CSV), input.clone())
        } else {
            (
                input.clone(),
                input.parent().map(Path::to_path_buf).unwrap_or_default(),
            )
        };
        anyhow::ensure!(csv.exists(), "{} not found", csv.display());
        if csv.canonicalize().ok() == out_csv.canonicalize().ok() {
            continue;
        }
        let part = read_results(&csv, false, &mut |m| eprintln!("note: {m}"))?;
        let (mut added, mut same) = (0, 0);
        for r in part {
            match by_key.get(&r.key()) {
                Some(&i) => {
                    if rows[i].deterministic() != r.deterministic() {
                        eprintln!(
                            "warning: {} has a different result for {} · {} · {}/{} ({}); keeping the first",
                            csv.display(),
                            r.data,
                            r.model,
                            r.loss,
                            r.weights,
                            r.optimizer
                        );
                    }
                    same += 1;
                }
                None => {
                    by_key.insert(r.key(), rows.len());
                    rows.push(r);
                    added += 1;
                }
            }
        }
        eprintln!(
            "{}: {added} row(s) added, {same} already present",
            csv.display()
        );
        if let Ok(text) = std::fs::read_to_string(dir.join(SKIPPED_JSON)) {
            skipped.extend(serde_json::from_str::<Vec<Skipped>>(&text).unwrap_or_default());
        }
    }
    write_if_changed(&out_csv, &results_csv_text(&rows)?)?;
    write_summaries(&args.out, &rows)?;
    let have: BTreeSet<FitKey> = rows.iter().map(Row::fit_key).collect();
    skipped.retain(|s| !have.contains(&s.fit_key()));
    skipped.sort_by_key(Skipped::fit_key);
    skipped.dedup_by_key(|s| s.fit_key());
    write_if_changed(
        &args.out.join(SKIPPED_JSON),
        &(serde_json::to_string_pretty(&skipped)? + "\n"),
    )?;
    eprintln!("{} row(s) in {}", rows.len(), out_csv.display());
    if !args.no_pictures {
        crate::report::publish(&args.out, &rows, &mut |m| eprintln!("{m}"))?;
    }
    Ok(())
}

/// A line for the user above the progress bar (printed even when the bar is hidden).
/// The skipped.json entry of a task.
fn skipped_entry(f: &DataFile, t: &Task, status: &str, reason: String) -> Skipped {
    Skipped {
        data: f.name.clone(),
        model: t.model.clone(),
        loss: t.loss.to_string(),
        weights: t.weights.to_string(),
        optimizer: t.optimizer.to_string(),
        status: status.into(),
        reason,
    }
}

fn say(bar: &indicatif::ProgressBar, msg: String) {
    bar.suspend(|| eprintln!("{msg}"));
}

/// Convenience for callers: write a file, creating its directory.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(d) = path.parent() {
        std::fs::create_dir_all(d)?;
    }
    let mut f =
        std::fs::File::create(path).with_context(|| format!("cannot write {}", path.display()))?;
    f.write_all(bytes)?;
    Ok(())
}
