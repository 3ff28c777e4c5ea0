//! Running a sweep: the cells of this run (its shard), the output folder's lock and its
//! rows so far, the fits on the [`Pool`], and the files written at the end. `bsdfit
//! sweep`, `bench --sweep` and the Python module's `sweep()` all call [`run`].

use super::lock::DirLock;
use super::pool::{CellOutcome, Pool, PoolEvent, Runnable};
use super::{expand_data, skipped_entry, slurm, tasks, write_skipped, Selection, Task};
use crate::bsdf::Model;
use crate::data::ReadOptions;
use crate::engine::{self, loss::Loss, Backend as _, BackendChoice};
use crate::inference::constraints::{ConstraintSpec, Constraints};
use crate::inference::fit::{FitOptions, PhaseSeconds};
use crate::output::files::check_writable_dir;
use crate::output::report::RunInfo;
use crate::output::results::{
    read_results, results_csv_text, write_if_changed, write_summaries, Appender, DataFile, Key,
    Row, Skipped, DEFAULT_OUT, RESULTS_CSV,
};
use crate::text::{panic_text, plural, plural_with};
use crate::workflows::checks::nonfinite_message;
use crate::workflows::checks::{batch_bytes, batch_candidates, check_batch_memory};
use anyhow::{Context, Result};
use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The default seed of a sweep's random restarts.
pub const DEFAULT_SEED: u64 = 1;

/// Which part of the cell list this process runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shard {
    /// Shard I of N (1-based): the cells whose index is I − 1 modulo N, written to the
    /// output folder itself.
    Fixed(usize, usize),
    /// The shard of this Slurm job-array task, written to OUT/shards/I-of-N/ with the
    /// sweep's plan in OUT/plan.json.
    SlurmArray,
}

impl Shard {
    /// `I/N` or `auto` (the command line's `--shard`).
    pub fn parse(text: &str) -> Result<Shard> {
        Ok(match text.trim() {
            "auto" => Shard::SlurmArray,
            s => {
                let (i, n) = super::parse_shard(s)?;
                Shard::Fixed(i, n)
            }
        })
    }
}

/// What a sweep runs and where it writes. [`SweepConfig::default`] is what `bsdfit sweep`
/// does with no options. It is saved as JSON (without the shard and the dry-run flag,
/// which each run gives) for the tasks of a Slurm array to read ([`SweepConfig::save`],
/// [`SweepConfig::load`]).
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct SweepConfig {
    /// Data files or folders of *.csv (empty: the bundled data/ folder).
    pub data: Vec<PathBuf>,
    /// How the files are read.
    pub read: ReadOptions,
    /// Models, losses, weightings and optimizers per data set.
    pub selection: Selection,
    pub restarts: usize,
    pub seed: u64,
    pub backend: BackendChoice,
    /// `--fix`, `--bounds`, `--prior`, lenient (a model without a parameter ignores it).
    pub constraints: ConstraintSpec,
    pub out: PathBuf,
    #[serde(skip)]
    pub shard: Option<Shard>,
    /// Write the plots, renders and report.html (a sharded run leaves them to merge).
    pub pictures: bool,
    /// List the cells (and which are done) without locking, fitting or writing.
    #[serde(skip)]
    pub dry_run: bool,
}

impl SweepConfig {
    /// The configuration as the JSON a saved sweep file holds.
    pub fn to_json(&self) -> Result<String> {
        Ok(serde_json::to_string_pretty(self)? + "\n")
    }

    /// Write the configuration to `path` (atomically).
    pub fn save(&self, path: &Path) -> Result<()> {
        crate::output::files::write_result(path, &self.to_json()?, false)
    }

    /// The configuration saved in `path`; every field missing from it takes its default.
    pub fn load(path: &Path) -> Result<SweepConfig> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read {}", path.display()))?;
        serde_json::from_str(&text).with_context(|| {
            format!(
                "{}: not a saved sweep configuration (what `sweep --emit-slurm` writes)",
                path.display()
            )
        })
    }
}

impl Default for SweepConfig {
    fn default() -> Self {
        SweepConfig {
            data: Vec::new(),
            read: ReadOptions::default(),
            selection: Selection {
                optimizer: vec!["auto".into()],
                ..Selection::default()
            },
            restarts: crate::workflows::fit::DEFAULT_RESTARTS,
            seed: DEFAULT_SEED,
            backend: BackendChoice::Auto,
            constraints: ConstraintSpec {
                lenient: true,
                ..ConstraintSpec::default()
            },
            out: PathBuf::from(DEFAULT_OUT),
            shard: None,
            pictures: true,
            dry_run: false,
        }
    }
}

/// What a sweep tells its caller while it runs. The command line prints the lines on
/// stderr and draws a progress bar over the fits.
pub trait SweepObserver {
    /// A line for the user.
    fn note(&mut self, line: &str);
    /// The fits begin: `total` cells, of which `done` are already accounted for (models
    /// that do not build for their data).
    fn begin(&mut self, total: u64, done: u64);
    /// A line about one fit (a warning or a failure), shown while the fits run.
    fn alert(&mut self, line: &str);
    /// One fit has ended; `what` names its cell.
    fn fit_ended(&mut self, what: &str);
    /// Every fit has ended.
    fn end(&mut self);
}

/// One cell of a dry run's listing.
#[derive(Clone, Debug)]
pub struct ListedCell {
    /// Its index in the sweep's cell list (the one shards split).
    pub index: usize,
    /// Whether the output folder already holds its row.
    pub done: bool,
    pub data: String,
    pub task: Task,
}

/// What a sweep measured about itself (`bench --sweep` prints it), and a dry run's list.
#[derive(Clone, Debug, Default)]
pub struct SweepStats {
    /// The device submissions, when a GPU backend ran fits.
    pub submissions: Option<crate::engine::SubmissionStats>,
    /// Thread-seconds per phase, summed over the stages fitted together (a stage that
    /// failed and was fitted one cell at a time is not counted).
    pub phases: PhaseSeconds,
    /// Fits this run added.
    pub new_fits: usize,
    /// A dry run's cells (empty otherwise).
    pub listing: Vec<ListedCell>,
}

/// The sweep's data files and its cell list (every cell, in order).
pub fn read_cells(cfg: &SweepConfig) -> Result<(Vec<DataFile>, Vec<Task>)> {
    let paths = expand_data(&cfg.data)?;
    let mut files = Vec::new();
    for p in &paths {
        files.push(DataFile::read(p, &cfg.read)?);
    }
    let all = tasks(&files, &cfg.selection)?;
    Ok((files, all))
}

/// The run's constraint options as one canonical text (the `constraints` column).
pub fn constraints_text(c: &ConstraintSpec) -> String {
    use crate::inference::constraints::ConstraintKind;
    let mut items: Vec<String> = Vec::new();
    for (kind, word) in [
        (ConstraintKind::Fix, "fix"),
        (ConstraintKind::Bounds, "bounds"),
        (ConstraintKind::Prior, "prior"),
    ] {
        items.extend(c.of(kind).map(|s| format!("{word} {}", s.text().trim())));
    }
    items.join("; ")
}

/// A `constraints` cell as words.
pub fn describe_constraints(text: &str) -> &str {
    if text.is_empty() {
        "none"
    } else {
        text
    }
}

/// Where this process stands in the sweep: its shard and the folder it writes.
struct Place {
    shard: Option<(usize, usize)>,
    /// `--shard auto`: a Slurm array task writing its own folder inside `cfg.out`.
    slurm: bool,
    out: PathBuf,
}

impl Place {
    fn of(cfg: &SweepConfig) -> Result<Place> {
        Ok(match cfg.shard {
            None => Place {
                shard: None,
                slurm: false,
                out: cfg.out.clone(),
            },
            Some(Shard::Fixed(i, n)) => Place {
                shard: Some((i, n)),
                slurm: false,
                out: cfg.out.clone(),
            },
            Some(Shard::SlurmArray) => {
                let s = slurm::shard_from_env(&|k| std::env::var(k).ok())?;
                Place {
                    shard: Some(s),
                    slurm: true,
                    // No two tasks write one file.
                    out: slurm::shard_dir(&cfg.out, s),
                }
            }
        })
    }

    fn mine(&self, index: usize) -> bool {
        self.shard.is_none_or(|(k, n)| index % n == k - 1)
    }
}

/// Run a sweep: fit every cell of this run that the output folder does not hold yet,
/// appending each row as it ends, then write the summaries (and, unsharded, the
/// pictures and report).
pub fn run(cfg: &SweepConfig, obs: &mut dyn SweepObserver) -> Result<SweepStats> {
    let t0 = Instant::now();
    if cfg.restarts < 1 {
        return Err(crate::choice::field_error("{restarts}: at least 1"));
    }
    let place = Place::of(cfg)?;
    let out = &place.out;
    let (files, all) = read_cells(cfg)?;
    let mine: Vec<(usize, &Task)> = all
        .iter()
        .enumerate()
        .filter(|(i, _)| place.mine(*i))
        .collect();
    // A constraint that names no parameter of any model is refused before the folder is
    // created or locked (each model built once per data set).
    if !cfg.constraints.is_empty() {
        let pairs: BTreeSet<(&str, usize)> =
            all.iter().map(|t| (t.model.as_str(), t.data)).collect();
        let models: Vec<Model> = pairs
            .into_iter()
            .filter_map(|(spec, d)| Model::for_data(spec, &files[d].data).ok())
            .collect();
        cfg.constraints
            .check_names_against(&models.iter().collect::<Vec<_>>())?;
    }
    // The folder is checked and locked before anything is read from it or fitted.
    let _lock = if cfg.dry_run {
        None
    } else {
        if place.slurm {
            std::fs::create_dir_all(out)
                .with_context(|| format!("--out: cannot create {}", out.display()))?;
        }
        check_writable_dir(out, "--out")?;
        Some(DirLock::acquire(out, "sweep", &mut |m| {
            obs.note(&format!("note: {m}"))
        })?)
    };
    let csv_path = out.join(RESULTS_CSV);
    let mut rows = read_results(&csv_path, !cfg.dry_run, &mut |m| {
        obs.note(&format!("note: {m}"))
    })?;
    let constraints_text = constraints_text(&cfg.constraints);
    if let Some(r) = rows.iter().find(|r| r.constraints != constraints_text) {
        anyhow::bail!(
            "{} holds fits made under other constraints ({}) than this run's ({}); use another --out directory",
            csv_path.display(),
            describe_constraints(&r.constraints),
            describe_constraints(&constraints_text)
        );
    }
    let key_of = |t: &Task| Key {
        data_hash: files[t.data].hash.clone(),
        model: t.model.clone(),
        loss: t.loss.to_string(),
        weights: t.weights.to_string(),
        optimizer: t.optimizer.to_string(),
        restarts: cfg.restarts,
        seed: cfg.seed,
    };
    let mut done: BTreeSet<Key> = rows.iter().map(Row::key).collect();
    if let (true, Some((_, n)), false) = (place.slurm, place.shard, cfg.dry_run) {
        record_plan(cfg, &files, &all, n, &constraints_text, &key_of)?;
        done.extend(done_by_other_shards(&cfg.out, out)?);
    }
    let todo: Vec<&Task> = mine
        .iter()
        .map(|(_, t)| *t)
        .filter(|t| !done.contains(&key_of(t)))
        .collect();
    let shard_note = place
        .shard
        .map(|(i, n)| format!(" (shard {i}/{n})"))
        .unwrap_or_default();
    obs.note(&format!(
        "sweep{shard_note}: {}, {} of {}; {} already in {}, {} to run",
        plural_with(files.len(), "data set", "data sets"),
        plural(mine.len(), "task"),
        all.len(),
        mine.len() - todo.len(),
        csv_path.display(),
        todo.len()
    ));
    if cfg.dry_run {
        let listing = mine
            .iter()
            .map(|&(index, t)| ListedCell {
                index,
                done: done.contains(&key_of(t)),
                data: files[t.data].name.clone(),
                task: t.clone(),
            })
            .collect();
        return Ok(SweepStats {
            listing,
            ..SweepStats::default()
        });
    }

    let t_fits = Instant::now();
    let mut run = FitRun {
        cfg,
        files: &files,
        csv_path: &csv_path,
        constraints_text: &constraints_text,
        skipped: Vec::new(),
        new_rows: 0,
    };
    let (stats, workers) = if todo.is_empty() {
        (SweepStats::default(), 0)
    } else {
        run.fit(&todo, &mut rows, obs)?
    };
    let fit_wall = t_fits.elapsed().as_secs_f64();
    let info = RunInfo {
        new_fits: run.new_rows,
        wall_seconds: fit_wall,
        workers,
    };
    run.write_outputs(&place, &rows, &info, t0, obs)?;
    Ok(SweepStats {
        new_fits: run.new_rows,
        ..stats
    })
}

/// `--shard auto`: record every cell in OUT/plan.json (the first shard writes it; the
/// others check that it is this sweep's).
fn record_plan(
    cfg: &SweepConfig,
    files: &[DataFile],
    all: &[Task],
    shards: usize,
    constraints_text: &str,
    key_of: &dyn Fn(&Task) -> Key,
) -> Result<()> {
    let plan = slurm::Plan {
        shards,
        constraints: constraints_text.to_string(),
        cells: all
            .iter()
            .enumerate()
            .map(|(i, t)| slurm::PlanCell {
                data: files[t.data].name.clone(),
                key: key_of(t),
                shard: i % shards + 1,
            })
            .collect(),
    };
    plan.record(&cfg.out)
}

/// The cells another shard (of this or an earlier submission) already wrote: every shard
/// folder of `out` and `out` itself, except this shard's own folder `mine`.
fn done_by_other_shards(out: &Path, mine: &Path) -> Result<BTreeSet<Key>> {
    let mut done = BTreeSet::new();
    for dir in slurm::shard_dirs(out)?
        .into_iter()
        .chain(std::iter::once(out.to_path_buf()))
        .filter(|d| d != mine)
    {
        let other = read_results(&dir.join(RESULTS_CSV), false, &mut |_| {})?;
        done.extend(other.iter().map(Row::key));
    }
    Ok(done)
}

/// The fitting part of a run, and what it has written so far.
struct FitRun<'a> {
    cfg: &'a SweepConfig,
    files: &'a [DataFile],
    csv_path: &'a Path,
    constraints_text: &'a str,
    skipped: Vec<Skipped>,
    new_rows: usize,
}

impl FitRun<'_> {
    /// The files written at the end: results.csv in canonical order (unchanged bytes when
    /// nothing new ran), the summaries and skipped.json; then, unsharded, the pictures and
    /// report (a shard leaves them to merge).
    fn write_outputs(
        &self,
        place: &Place,
        rows: &[Row],
        info: &RunInfo,
        t0: Instant,
        obs: &mut dyn SweepObserver,
    ) -> Result<()> {
        let out = &place.out;
        write_if_changed(self.csv_path, &results_csv_text(rows)?).with_context(|| {
            format!(
                "{} still holds every row, as appended during the run (not in canonical order)",
                self.csv_path.display()
            )
        })?;
        write_summaries(out, rows)?;
        write_skipped(out, &self.skipped, rows, self.files)?;
        obs.note(&format!(
            "{}, {} in {}, {} skipped/failed, {:.1} s",
            plural_with(self.new_rows, "new fit", "new fits"),
            plural(rows.len(), "row"),
            self.csv_path.display(),
            self.skipped.len(),
            t0.elapsed().as_secs_f64()
        ));
        if place.slurm {
            obs.note(&format!(
                "shard done; when every shard has, combine them with `bsdfit merge --shards --out {}`",
                self.cfg.out.display()
            ));
        } else if place.shard.is_some() {
            obs.note("shard done; combine the shards with `bsdfit merge DIR... --out DIR` (it writes the pictures and report)");
        } else if self.cfg.pictures {
            crate::output::report::publish(out, rows, Some(info), &mut |m| obs.note(&m))?;
        }
        Ok(())
    }

    /// Fit `todo` on the pool, appending each row to results.csv (and `rows`) as it
    /// ends, so an interrupted run loses at most the stages in flight. Returns what the
    /// backend and pool measured, and the number of workers.
    fn fit(
        &mut self,
        todo: &[&Task],
        rows: &mut Vec<Row>,
        obs: &mut dyn SweepObserver,
    ) -> Result<(SweepStats, usize)> {
        let (runnable, unbuilt) = self.build_models(todo, obs);
        self.check_before_fitting(&runnable, obs)?;
        let backend = engine::select(self.cfg.backend, &mut |m| obs.note(&m))?;
        let cpu = engine::cpu::CpuBackend::new();
        let mut app = Appender::open(self.csv_path)?;
        obs.begin(todo.len() as u64, unbuilt);
        let pool = Pool {
            files: self.files,
            backend: backend.as_ref(),
            fallback: (backend.id() != cpu.id()).then_some(&cpu as &dyn engine::Backend),
            options: FitOptions {
                restarts: self.cfg.restarts,
                seed: self.cfg.seed,
                constraints: self.cfg.constraints.clone(),
                ..Default::default()
            },
        };
        let files = self.files;
        let what = |t: &Task| {
            format!(
                "{} · {} · {}/{} · {}",
                files[t.data].name, t.model, t.loss, t.weights, t.optimizer
            )
        };
        let mut faulted = false;
        let stats = pool.run(&runnable, &mut |event| {
            let (i, outcome) = match event {
                PoolEvent::Landed(i, outcome) => (i, *outcome),
                PoolEvent::Rerun { cells, fault } => {
                    if !std::mem::replace(&mut faulted, true) {
                        obs.alert(&format!(
                            "GPU fault: {fault}; the sweep continues on the CPU reference, \
                             and the fits the GPU failed are re-run there"
                        ));
                    }
                    for &i in &cells {
                        obs.alert(&format!(
                            "re-running on the CPU reference ({}): {}",
                            fault.brief(),
                            what(runnable[i].0)
                        ));
                    }
                    return Ok(());
                }
            };
            let (t, model) = &runnable[i];
            let what = what(t);
            if let Some(row) = self.land(t, model, outcome, backend.as_ref(), obs)? {
                app.push(&row)?;
                rows.push(row);
                self.new_rows += 1;
            }
            obs.fit_ended(&what);
            Ok(())
        })?;
        obs.end();
        Ok((
            SweepStats {
                submissions: backend.submissions(),
                phases: stats.phases,
                ..SweepStats::default()
            },
            stats.workers,
        ))
    }

    /// The models of the cells; a model that cannot be built is skipped up front (cheap,
    /// sequential), its reason said once. Returns the buildable cells and the number
    /// skipped.
    fn build_models<'t>(
        &mut self,
        todo: &[&'t Task],
        obs: &mut dyn SweepObserver,
    ) -> (Vec<Runnable<'t>>, u64) {
        let mut runnable = Vec::new();
        let mut unavailable: HashMap<String, String> = HashMap::new();
        let mut unbuilt = 0u64;
        for &t in todo {
            let f = &self.files[t.data];
            match Model::for_data(&t.model, &f.data) {
                Ok(m) => runnable.push((t, m)),
                Err(e) => {
                    let reason = e.to_string();
                    if unavailable
                        .insert(t.model.clone(), reason.clone())
                        .is_none()
                    {
                        obs.note(&format!("skipping {}: {reason}", t.model));
                    }
                    self.skipped.push(skipped_entry(f, t, "skipped", reason));
                    unbuilt += 1;
                }
            }
        }
        (runnable, unbuilt)
    }

    /// Before any fit: the largest batch of the sweep must fit in memory, and every
    /// constraint must name a parameter of some model and resolve on each.
    fn check_before_fitting(
        &self,
        runnable: &[Runnable],
        obs: &mut dyn SweepObserver,
    ) -> Result<()> {
        let restarts = self.cfg.restarts;
        if let Some((t, m)) = runnable.iter().max_by_key(|(t, m)| {
            batch_bytes(
                batch_candidates(restarts, m.dim),
                m.dim,
                self.files[t.data].data.len(),
            )
        }) {
            let f = &self.files[t.data];
            check_batch_memory(
                restarts,
                m.dim,
                f.data.len(),
                &format!("{} on {} (the sweep's largest fit)", m.spec, f.name),
                &mut |w| obs.note(&w),
            )?;
        }
        // The names were checked against the whole plan's models before the shards split
        // it (`run`); a shard's own models may lack a parameter another shard's have.
        let constraints = &self.cfg.constraints;
        if !constraints.is_empty() {
            for (_, m) in runnable {
                Constraints::resolve(m, constraints, true)
                    .with_context(|| format!("model {}", m.spec))?;
            }
        }
        Ok(())
    }

    /// One fit's outcome as a row to append (a non-finite fit is kept, flagged with the
    /// samples that cause it), or, for a failure, an entry of skipped.json.
    fn land(
        &mut self,
        t: &Task,
        model: &Model,
        outcome: CellOutcome,
        backend: &dyn engine::Backend,
        obs: &mut dyn SweepObserver,
    ) -> Result<Option<Row>> {
        let f = &self.files[t.data];
        let loss = Loss::new(t.loss, t.weights);
        let report = match outcome {
            Ok(Ok(report)) => report,
            Ok(Err(e)) => {
                obs.alert(&format!(
                    "fit failed: {} · {} · {loss}: {e:#}",
                    f.name, t.model
                ));
                self.skipped
                    .push(skipped_entry(f, t, "failed", format!("{e:#}")));
                return Ok(None);
            }
            Err(p) => {
                let msg = panic_text(p.as_ref()).unwrap_or("panic");
                obs.alert(&format!(
                    "fit panicked: {} · {} · {loss}: {msg}",
                    f.name, t.model
                ));
                self.skipped
                    .push(skipped_entry(f, t, "failed", format!("panic: {msg}")));
                return Ok(None);
            }
        };
        let mut row = Row::from_report(&report, f);
        row.constraints = self.constraints_text.to_string();
        if !(report.best.chi2_red.is_finite() && report.best.loss.is_finite()) {
            let msg = nonfinite_message(
                model,
                &f.data,
                loss,
                &report.flat_params,
                report.best.chi2_red,
                report.best.loss,
                backend,
            );
            obs.alert(&format!("warning: {msg}"));
            let mut w = row.warnings_json();
            w.push(msg);
            row.warnings = serde_json::to_string(&w)?;
        }
        Ok(Some(row))
    }
}
