//! `bsdfit diagnose FILE|DIR… --out DIR`: a collection of data sets diagnosed from one
//! start model, one resumable cell per data set, on one machine or a Slurm cluster.
//!
//! Layout of `--out OUT`:
//! - `collection.json`: the diagnosis asked for (start model, options, how the files are
//!   read); a later run into OUT must ask for the same one;
//! - `cells/NAME.json`: one data set's outcome ([`CellRecord`]: its diagnosis, or the
//!   error that stopped it), written atomically when it ends, so a killed run loses only
//!   the cell in flight; a rerun skips every cell recorded as done for the same bytes;
//! - `diagnoses/NAME/`: its residual maps before and after, staircase and candidate
//!   tables (what `diagnose --report` writes);
//! - `diagnoses.csv`, `diagnoses.json`, `report.html`: the table of the collection,
//!   rewritten from every cell present when a run or a merge ends.
//!
//! As for a sweep, `--shard I/N` runs the cells whose index is I − 1 modulo N, and
//! `--shard auto` (a task of a Slurm job array) writes OUT/shards/I-of-N/ in the same
//! layout, gathered by `bsdfit merge --shards --out OUT`.

pub mod merge;
pub mod record;
pub mod report;

pub use merge::merge;
pub use record::{CellRecord, CellStatus};

use super::diagnose::{diagnose, write_report, DiagnoseRequest};
use super::sweep::lock::DirLock;
use super::sweep::{slurm, Shard, SweepObserver};
use crate::data::ReadOptions;
use crate::engine::{self, Backend, BackendChoice};
use crate::output::files::{check_writable_dir, write_atomic};
use crate::output::report::safe_name as safe;
use crate::output::results::DataFile;
use crate::text::{panic_text, plural};
use anyhow::{Context, Result};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The collection's options inside its `--out` (and in OUT/slurm/ for a job array).
pub const COLLECTION_JSON: &str = "collection.json";
/// The folder of the cells' records.
pub const CELLS_DIR: &str = "cells";
/// The folder of the cells' reports.
pub const REPORTS_DIR: &str = "diagnoses";

/// A collection's diagnosis: what `bsdfit diagnose FILE|DIR… --out DIR` runs. Saved as
/// JSON (without the shard) for the tasks of a Slurm array to read.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct CollectionConfig {
    /// Data files (any format read) or folders (their files of a format read,
    /// recognised by content).
    pub data: Vec<PathBuf>,
    pub read: ReadOptions,
    /// The diagnosis of each data set.
    pub request: DiagnoseRequest,
    pub backend: BackendChoice,
    pub out: PathBuf,
    /// Write each data set's residual maps and the report's pictures.
    pub pictures: bool,
    #[serde(skip)]
    pub shard: Option<Shard>,
}

impl Default for CollectionConfig {
    fn default() -> Self {
        CollectionConfig {
            data: Vec::new(),
            read: ReadOptions::default(),
            request: DiagnoseRequest::default(),
            backend: BackendChoice::Auto,
            out: PathBuf::from("diagnoses"),
            pictures: true,
            shard: None,
        }
    }
}

impl CollectionConfig {
    /// Write the configuration to `path` (atomically).
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self)? + "\n";
        crate::output::files::write_result(path, &text, false)
    }

    /// The configuration saved in `path`.
    pub fn load(path: &Path) -> Result<CollectionConfig> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        serde_json::from_str(&text).with_context(|| {
            format!(
                "{}: not a saved collection diagnosis (what `diagnose --out DIR` writes as DIR/{COLLECTION_JSON})",
                path.display()
            )
        })
    }

    /// How every file of the collection is read: the options asked for, with one
    /// selection of wavelengths serving files with different channels
    /// ([`ReadOptions::wavelengths_at_most`]). Derived here, not stored, so the saved
    /// options are the ones asked for, whichever run (a task, a merge) saved them.
    pub fn reading(&self) -> ReadOptions {
        ReadOptions {
            wavelengths_at_most: true,
            ..self.read.clone()
        }
    }

    /// What makes two runs the same diagnosis (the files may differ: a collection grows).
    fn identity(&self) -> serde_json::Value {
        serde_json::json!({ "read": self.read, "request": self.request })
    }
}

/// One data set of a collection: its cell's name (unique in the collection, safe as a
/// file name) and its file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Listed {
    pub name: String,
    pub path: PathBuf,
}

/// The collection's data sets: files as given, and in each folder its files whose
/// content is of a format read (sorted; the others are named in `notes`). Each gets a
/// cell name: its file name, prefixed with its folder's where two share one.
pub fn list_data(paths: &[PathBuf], notes: &mut dyn FnMut(String)) -> Result<Vec<Listed>> {
    anyhow::ensure!(!paths.is_empty(), "no data file or folder given");
    let mut files = Vec::new();
    for p in paths {
        if !p.is_dir() {
            files.push(p.clone());
            continue;
        }
        let mut v: Vec<PathBuf> = std::fs::read_dir(p)
            .with_context(|| format!("cannot list {}", p.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|f| f.is_file())
            .filter(|f| {
                !f.file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with('.'))
            })
            .collect();
        v.sort();
        let (data, other): (Vec<PathBuf>, Vec<PathBuf>) = v
            .into_iter()
            .partition(|f| crate::data::readers::recognise(f).is_ok_and(|k| k.is_some()));
        if !other.is_empty() {
            notes(format!(
                "note: {} in {} not of a format read: {}",
                plural(other.len(), "file"),
                p.display(),
                other
                    .iter()
                    .filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned()))
                    .collect::<Vec<_>>()
                    .join(", ")
            ));
        }
        anyhow::ensure!(
            !data.is_empty(),
            "{} holds no data file of a format read (bsdfit v1 CSV, ALTA text, MERL binary, RGL .bsdf, Zemax BSDF, ASTM E1392)",
            p.display()
        );
        files.extend(data);
    }
    Ok(cell_names(&files))
}

/// Unique cell names: the file name; where several files share it, their folder's name
/// first; a number after where that is not enough.
fn cell_names(files: &[PathBuf]) -> Vec<Listed> {
    let base = |p: &Path| safe(&p.file_name().unwrap_or_default().to_string_lossy());
    let with_dir = |p: &Path| {
        let dir = p
            .parent()
            .and_then(|d| d.file_name())
            .map(|d| safe(&d.to_string_lossy()))
            .unwrap_or_default();
        format!("{dir}_{}", base(p))
    };
    let mut names: Vec<String> = files.iter().map(|p| base(p)).collect();
    let shared: BTreeSet<String> = names
        .iter()
        .filter(|n| names.iter().filter(|m| m == n).count() > 1)
        .cloned()
        .collect();
    for (n, p) in names.iter_mut().zip(files) {
        if shared.contains(n) {
            *n = with_dir(p);
        }
    }
    let mut seen = BTreeSet::new();
    let mut out = Vec::new();
    for (n, p) in names.into_iter().zip(files) {
        let mut name = n.clone();
        let mut k = 2;
        while !seen.insert(name.clone()) {
            name = format!("{n}-{k}");
            k += 1;
        }
        out.push(Listed {
            name,
            path: p.clone(),
        });
    }
    out
}

/// What a collection run did.
#[derive(Clone, Debug, Default)]
pub struct CollectionStats {
    /// Every cell of the folder's table, after this run.
    pub cells: Vec<CellRecord>,
    /// Cells this run diagnosed.
    pub ran: usize,
    /// The names of this run's cells that failed.
    pub failed: Vec<String>,
    /// The folder written (OUT, or a Slurm task's shard folder).
    pub out: PathBuf,
}

/// The folder a run writes and the cells it runs.
fn place(cfg: &CollectionConfig) -> Result<(PathBuf, Option<(usize, usize)>)> {
    Ok(match cfg.shard {
        None => (cfg.out.clone(), None),
        Some(Shard::Fixed(i, n)) => (cfg.out.clone(), Some((i, n))),
        Some(Shard::SlurmArray) => {
            let s = slurm::shard_from_env(&|k| std::env::var(k).ok())?;
            (slurm::shard_dir(&cfg.out, s), Some(s))
        }
    })
}

/// Refuse a folder that holds a sweep, whose report.html the collection's would replace.
pub fn refuse_sweep_folder(out: &Path) -> Result<()> {
    let sweep = out.join(crate::output::results::RESULTS_CSV);
    anyhow::ensure!(
        !sweep.exists(),
        "{} holds a sweep ({}): give the collection's diagnosis its own --out folder",
        out.display(),
        sweep.display()
    );
    Ok(())
}

/// Refuse a folder that holds another diagnosis, or a sweep; record this one in a new
/// folder.
fn check_identity(cfg: &CollectionConfig, out: &Path) -> Result<()> {
    refuse_sweep_folder(out)?;
    let path = out.join(COLLECTION_JSON);
    if path.exists() {
        let saved = CollectionConfig::load(&path)?;
        if saved.identity() != cfg.identity() {
            anyhow::bail!(
                "{} holds a diagnosis asked for with other options ({}: start model {}); give another --out folder, or the same options",
                out.display(),
                path.display(),
                saved.request.model
            );
        }
        return Ok(());
    }
    cfg.save(&path)
}

/// The record of cell `name` in `out`, if any (a record that does not parse is none).
pub fn read_cell(out: &Path, name: &str) -> Option<CellRecord> {
    let text = std::fs::read_to_string(out.join(CELLS_DIR).join(format!("{name}.json"))).ok()?;
    serde_json::from_str(&text).ok()
}

/// Every record in `out/cells/`, sorted by name.
pub fn read_cells(out: &Path) -> Result<Vec<CellRecord>> {
    let dir = out.join(CELLS_DIR);
    if !dir.exists() {
        return Ok(Vec::new());
    }
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .collect();
    paths.sort();
    let mut out = Vec::new();
    for p in paths {
        let text =
            std::fs::read_to_string(&p).with_context(|| format!("cannot read {}", p.display()))?;
        out.push(
            serde_json::from_str(&text)
                .with_context(|| format!("{}: not a cell record of a diagnosis", p.display()))?,
        );
    }
    Ok(out)
}

/// Write cell `r` into `out/cells/` (atomically).
pub fn write_cell(out: &Path, r: &CellRecord) -> Result<()> {
    let dir = out.join(CELLS_DIR);
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let text = serde_json::to_string_pretty(r)? + "\n";
    write_atomic(&dir.join(format!("{}.json", r.data)), text.as_bytes())
}

/// The bytes' key of a listed file under the collection's read options (None: unreadable).
fn hash_of(l: &Listed, read: &ReadOptions) -> Option<String> {
    std::fs::read(&l.path)
        .ok()
        .map(|b| DataFile::hash_of(&b, read))
}

/// Diagnose every cell of this run (its shard) that `out` does not hold as done for the
/// same bytes, each written as it ends, then write the collection's table and report.
/// A cell that fails is recorded with its error and the others go on.
pub fn run(cfg: &CollectionConfig, obs: &mut dyn SweepObserver) -> Result<CollectionStats> {
    crate::bsdf::spec_kind(&cfg.request.model).map_err(|e| {
        crate::choice::field_error(format!(
            "{{model}} '{}': {}",
            cfg.request.model.replace(['{', '}'], ""),
            e.to_string().replace(['{', '}'], "")
        ))
    })?;
    let (out, shard) = place(cfg)?;
    let reading = cfg.reading();
    let listed = list_data(&cfg.data, &mut |m| obs.note(&m))?;
    std::fs::create_dir_all(&out)
        .with_context(|| format!("--out: cannot create {}", out.display()))?;
    check_writable_dir(&out, "--out")?;
    let _lock = DirLock::acquire(&out, "diagnose", &mut |m| obs.note(&format!("note: {m}")))?;
    check_identity(cfg, &out)?;
    let mine: Vec<&Listed> = listed
        .iter()
        .enumerate()
        .filter(|(i, _)| shard.is_none_or(|(k, n)| i % n == k - 1))
        .map(|(_, l)| l)
        .collect();
    // Done where this folder, or the collection's own (a merge), holds it for these bytes
    // (the file is read for its key only where such a record exists).
    let done = |l: &Listed| {
        let records: Vec<CellRecord> = [out.as_path(), cfg.out.as_path()]
            .iter()
            .filter_map(|dir| read_cell(dir, &l.name))
            .filter(|r| r.status == CellStatus::Done && r.hash.is_some())
            .collect();
        !records.is_empty() && {
            let hash = hash_of(l, &reading);
            records.iter().any(|r| r.hash == hash)
        }
    };
    let todo: Vec<&Listed> = mine.iter().copied().filter(|l| !done(l)).collect();
    let shard_note = shard
        .map(|(i, n)| format!(" (shard {i}/{n})"))
        .unwrap_or_default();
    obs.note(&format!(
        "diagnose{shard_note}: {}, {} of them in this run; {} already done in {}, {} to run",
        plural(listed.len(), "data set"),
        mine.len(),
        mine.len() - todo.len(),
        out.display(),
        todo.len()
    ));
    let mut stats = CollectionStats {
        out: out.clone(),
        ..Default::default()
    };
    if !todo.is_empty() {
        let backend = engine::select(cfg.backend, &mut |m| obs.note(&m))?;
        obs.begin(mine.len() as u64, (mine.len() - todo.len()) as u64);
        for l in todo {
            let r = run_cell(cfg, l, &out, backend.as_ref(), obs);
            write_cell(&out, &r)?;
            if r.status == CellStatus::Failed {
                obs.alert(&format!(
                    "{}: failed: {}",
                    l.name,
                    r.error.as_deref().unwrap_or("")
                ));
                stats.failed.push(r.data.clone());
            }
            stats.ran += 1;
            obs.fit_ended(&l.name);
        }
        obs.end();
    }
    stats.cells = read_cells(&out)?;
    record::write_tables(&out, &stats.cells)?;
    report::write(&out, &stats.cells, cfg.pictures)?;
    obs.note(&format!(
        "wrote {}, {} and {} ({})",
        out.join(record::DIAGNOSES_CSV).display(),
        record::DIAGNOSES_JSON,
        report::REPORT_HTML,
        plural(stats.cells.len(), "data set")
    ));
    Ok(stats)
}

/// Diagnose one data set: its record, done or failed (a panic is a failure too).
fn run_cell(
    cfg: &CollectionConfig,
    l: &Listed,
    out: &Path,
    backend: &dyn Backend,
    obs: &mut dyn SweepObserver,
) -> CellRecord {
    let t0 = Instant::now();
    // The path's lines are shown as they come (a diagnosis can take minutes).
    let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        diagnose_cell(cfg, l, out, backend, &mut |line| obs.alert(&line))
    }));
    let seconds = t0.elapsed().as_secs_f64();
    let hash = hash_of(l, &cfg.reading());
    match outcome {
        Ok(Ok(mut r)) => {
            r.seconds = seconds;
            r
        }
        Ok(Err(e)) => CellRecord::failed(l, hash, &cfg.request.model, format!("{e:#}"), seconds),
        Err(p) => CellRecord::failed(
            l,
            hash,
            &cfg.request.model,
            format!(
                "internal error: {}",
                panic_text(p.as_ref()).unwrap_or("a panic")
            ),
            seconds,
        ),
    }
}

/// Read, check and diagnose one data set; write its report.
fn diagnose_cell(
    cfg: &CollectionConfig,
    l: &Listed,
    out: &Path,
    backend: &dyn Backend,
    alert: &mut dyn FnMut(String),
) -> Result<CellRecord> {
    let file = DataFile::read(&l.path, &cfg.reading())?;
    for n in &file.data.notices {
        alert(format!("{}: note: {n}", l.name));
    }
    let opts = cfg
        .request
        .prepare(&file.data, &mut |w| alert(format!("{}: {w}", l.name)))?;
    let d = diagnose(
        &file.data,
        &cfg.request.model,
        backend,
        &opts,
        &mut |line| {
            // The steps and the verdicts, not every candidate: a collection's log stays
            // readable.
            if line.starts_with("step ") || line.trim_start().starts_with('→') {
                alert(format!("{}: {}", l.name, line.trim()))
            }
        },
    )?;
    if cfg.pictures {
        write_report(&out.join(REPORTS_DIR).join(&l.name), &file.data, &d)?;
    }
    Ok(CellRecord::of_diagnosis(
        l,
        Some(file.hash.clone()),
        &file.data,
        &d,
        opts.max_steps,
    ))
}

/// `diagnose --emit-slurm TASKS`: the job scripts of the collection `cfg` in OUT/slurm/,
/// with the collection saved there as [`COLLECTION_JSON`]: an array of `tasks` tasks of
/// `cpus_per_task` CPUs each running `BINARY diagnose --config OUT/slurm/collection.json
/// --shard auto`, and the merge. The data are listed now, so a mistake fails here and not
/// on the cluster.
pub fn emit_slurm(
    cfg: &CollectionConfig,
    tasks: usize,
    cpus_per_task: usize,
    binary: Option<&Path>,
    obs: &mut dyn SweepObserver,
) -> Result<()> {
    slurm::check_array(tasks, cpus_per_task, cfg.shard.is_some())?;
    let listed = list_data(&cfg.data, &mut |m| obs.note(&m))?;
    let job = slurm::ArrayJob {
        command: "diagnose",
        config_name: COLLECTION_JSON,
        runs: "the collection they diagnose",
        cells: plural(listed.len(), "data set"),
        cell_count: listed.len(),
        gpu: cfg.backend == BackendChoice::Gpu,
        pictures: cfg.pictures,
    };
    job.emit(
        &cfg.out,
        tasks,
        cpus_per_task,
        binary,
        obs,
        &mut |out, config| {
            CollectionConfig {
                out: out.to_path_buf(),
                ..cfg.clone()
            }
            .save(config)
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Names are file names; files that share one take their folder's name first, and a
    /// number where even that is shared.
    #[test]
    fn cell_names_are_unique_and_readable() {
        let files: Vec<PathBuf> = [
            "lab/a.csv",
            "lab/b c.astm",
            "other/a.csv",
            "x/lab/a.csv",
            "y/lab/a.csv",
        ]
        .iter()
        .map(PathBuf::from)
        .collect();
        let names: Vec<String> = cell_names(&files).into_iter().map(|l| l.name).collect();
        assert_eq!(
            names,
            [
                "lab_a.csv",
                "b_c.astm",
                "other_a.csv",
                "lab_a.csv-2",
                "lab_a.csv-3"
            ]
        );
    }

    /// A folder gives its files of a format read, sorted, and names the others; a folder
    /// with none is an error naming it.
    #[test]
    fn folders_give_their_data_files() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        std::fs::write(d.join("b.csv"), "# bsdfit dataset v1\n").unwrap();
        std::fs::write(
            d.join("a.csv"),
            "theta_i,phi_i,theta_o,phi_o,wavelength_nm,value,u\n",
        )
        .unwrap();
        std::fs::write(d.join("notes.txt"), "hello\n").unwrap();
        std::fs::write(d.join(".hidden.csv"), "# bsdfit dataset v1\n").unwrap();
        let mut notes = Vec::new();
        let listed = list_data(&[d.to_path_buf()], &mut |n| notes.push(n)).unwrap();
        let names: Vec<&str> = listed.iter().map(|l| l.name.as_str()).collect();
        assert_eq!(names, ["a.csv", "b.csv"]);
        assert!(notes.iter().any(|n| n.contains("notes.txt")), "{notes:?}");
        let empty = tempfile::tempdir().unwrap();
        std::fs::write(empty.path().join("notes.txt"), "hello\n").unwrap();
        let e = list_data(&[empty.path().to_path_buf()], &mut |_| {}).unwrap_err();
        assert!(e.to_string().contains("holds no data file"), "{e}");
    }
}
