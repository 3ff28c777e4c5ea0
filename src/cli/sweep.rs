//! `bsdfit sweep` and `bsdfit merge`.

use super::checks::{batch_bytes, batch_candidates, check_batch_memory, nonfinite_message};
use super::progress::{plural, plural_with, Progress};
use super::{BackendArgs, ConstraintArgs, DataArgs};
use crate::bsdf::Model;
use crate::engine::{self, loss::Loss};
use crate::inference::constraints::{ConstraintSpec, Constraints};
use crate::inference::fit::{fit, fit_stage, FitOptions, PhaseSeconds};
use crate::output::files::check_writable_dir;
use crate::output::report::RunInfo;
use crate::output::results::{
    read_results, results_csv_text, write_if_changed, write_summaries, Appender, DataFile, FitKey,
    Key, Row, Skipped, DEFAULT_OUT, RESULTS_CSV, SKIPPED_JSON,
};
use crate::workflows::sweep::lock::DirLock;
use crate::workflows::sweep::slurm;
use crate::workflows::sweep::{
    expand_data, parse_shard, skipped_entry, tasks, write_skipped, Selection, Task,
};
use anyhow::{Context, Result};
use clap::Args;
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// `bsdfit sweep` arguments.
#[derive(Args, Debug, Clone)]
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
    /// Random restarts per fit, as in `fit` and `diagnose`. With 8, the default sweep's
    /// model rankings changed with the seed in 4 of its 36 groups (data set × loss ×
    /// weighting) and its fits ended 5–20 times further above the best loss known; 16
    /// costs about twice the time. The `restarts_within_1pct` column shows where more
    /// restarts would matter.
    #[arg(long, default_value_t = super::DEFAULT_RESTARTS, value_parser = super::parse_restarts, allow_hyphen_values = true)]
    pub restarts: usize,
    /// Seed of the random restarts (a non-negative integer).
    #[arg(long, default_value_t = 1, value_parser = super::parse_seed, allow_hyphen_values = true)]
    pub seed: u64,
    #[command(flatten)]
    pub backend: BackendArgs,
    #[command(flatten)]
    pub constraints: ConstraintArgs,
    #[command(flatten)]
    pub data_args: DataArgs,
    /// Output directory (results, pictures, report.html). One process at a time: a sweep
    /// or merge holds DIR/.bsdfit.lock while it runs, and another one started on the same
    /// folder stops with an error naming the holder (a lock left by a killed process on
    /// this host is taken over).
    #[arg(long, default_value = DEFAULT_OUT)]
    pub out: PathBuf,
    /// Run only shard I of N (1-based), e.g. 2/4. Shards that run at the same time must
    /// each write to their own --out folder (e.g. --out run-1, --out run-2); combine them
    /// afterwards with `bsdfit merge run-1 run-2 --out DIR`. `auto`: the shard of this
    /// Slurm job-array task (SLURM_ARRAY_TASK_ID, _MIN, _MAX, _STEP, _COUNT), written into
    /// DIR/shards/I-of-N/ with the sweep's plan in DIR/plan.json; combine them with
    /// `bsdfit merge --shards --out DIR` (docs/cluster.md).
    #[arg(long, value_name = "I/N|auto")]
    pub shard: Option<String>,
    /// Write Slurm job scripts for this sweep into DIR/slurm/ instead of running it: an
    /// array of TASKS tasks (`--shard auto` each; `--gres=gpu:1` with --backend gpu), a
    /// merge job that runs when every task has ended, and submit.sh that submits both.
    #[arg(long, value_name = "TASKS")]
    pub emit_slurm: Option<usize>,
    /// With --emit-slurm: CPUs per array task (`--cpus-per-task`; the CPU reference uses
    /// SLURM_CPUS_PER_TASK threads).
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub slurm_cpus: usize,
    /// Skip the plots, renders and report.html (results files only).
    #[arg(long)]
    pub no_pictures: bool,
    /// List the tasks (and which are done) without fitting.
    #[arg(long)]
    pub dry_run: bool,
}

/// `bsdfit merge` arguments.
#[derive(Args, Debug, Clone)]
pub struct MergeArgs {
    /// Shard output directories (or their results.csv files).
    #[arg(required_unless_present = "shards")]
    pub inputs: Vec<PathBuf>,
    /// Merge the shard folders a `sweep --shard auto` wrote into OUT/shards/, and check
    /// them against OUT/plan.json: the cells no shard wrote are listed, and merge then
    /// fails (after writing what it has), so a lost task is never silent.
    #[arg(long)]
    pub shards: bool,
    /// Output directory; rows already in its results.csv are kept. Locked while merge runs
    /// (DIR/.bsdfit.lock), like a sweep's.
    #[arg(long, default_value = DEFAULT_OUT)]
    pub out: PathBuf,
    /// Skip the plots, renders and report.html (results files only).
    #[arg(long)]
    pub no_pictures: bool,
}

/// The run's constraint options as one canonical text (the `constraints` column).
fn constraints_text(c: &ConstraintSpec) -> String {
    let mut items: Vec<String> = Vec::new();
    items.extend(c.fix.iter().map(|s| format!("fix {}", s.trim())));
    items.extend(c.bounds.iter().map(|s| format!("bounds {}", s.trim())));
    items.extend(c.priors.iter().map(|s| format!("prior {}", s.trim())));
    items.join("; ")
}

fn describe_constraints(text: &str) -> &str {
    if text.is_empty() {
        "none"
    } else {
        text
    }
}

/// The `sweep` command.
/// What a sweep measured about itself (`bench --sweep` prints it).
#[derive(Clone, Debug, Default)]
pub struct SweepStats {
    /// The device submissions, when a GPU backend ran fits.
    pub submissions: Option<crate::engine::SubmissionStats>,
    /// Thread-seconds per phase, summed over the stages fitted together (a stage that
    /// failed and was fitted one task at a time is not counted).
    pub phases: PhaseSeconds,
}

/// Run a sweep.
pub fn run_sweep(args: &SweepArgs) -> Result<SweepStats> {
    let t0 = Instant::now();
    if let Some(tasks) = args.emit_slurm {
        emit_slurm(args, tasks)?;
        return Ok(SweepStats::default());
    }
    let auto = args.shard.as_deref().map(str::trim) == Some("auto");
    let shard = if auto {
        Some(slurm::shard_from_env(&|k| std::env::var(k).ok())?)
    } else {
        args.shard.as_deref().map(parse_shard).transpose()?
    };
    // `--shard auto`: this shard's own folder inside --out (no two tasks write one file).
    let out = match shard {
        Some(s) if auto => slurm::shard_dir(&args.out, s),
        _ => args.out.clone(),
    };
    let (files, all) = read_cells(args)?;
    let mine: Vec<(usize, &Task)> = all
        .iter()
        .enumerate()
        .filter(|(i, _)| shard.is_none_or(|(k, n)| i % n == k - 1))
        .collect();
    // The folder is checked and locked before anything is read from it or fitted.
    let _lock = if args.dry_run {
        None
    } else {
        if auto {
            std::fs::create_dir_all(&out)
                .with_context(|| format!("--out: cannot create {}", out.display()))?;
        }
        check_writable_dir(&out, "--out")?;
        Some(DirLock::acquire(&out, "sweep", &mut |m| {
            eprintln!("note: {m}")
        })?)
    };
    let csv_path = out.join(RESULTS_CSV);
    let mut rows = read_results(&csv_path, !args.dry_run, &mut |m| eprintln!("note: {m}"))?;
    let constraints = args.constraints.spec(true);
    let constraints_text = constraints_text(&constraints);
    if let Some(r) = rows.iter().find(|r| r.constraints != constraints_text) {
        anyhow::bail!(
            "{} holds fits made under other constraints ({}) than this run's ({}); use another --out directory",
            csv_path.display(),
            describe_constraints(&r.constraints),
            describe_constraints(&constraints_text)
        );
    }
    let mut done: BTreeSet<Key> = rows.iter().map(Row::key).collect();
    let key_of = |t: &Task| Key {
        data_hash: files[t.data].hash.clone(),
        model: t.model.clone(),
        loss: t.loss.to_string(),
        weights: t.weights.to_string(),
        optimizer: t.optimizer.to_string(),
        restarts: args.restarts,
        seed: args.seed,
    };
    if let (true, Some((_, n)), false) = (auto, shard, args.dry_run) {
        let plan = slurm::Plan {
            shards: n,
            constraints: constraints_text.clone(),
            cells: all
                .iter()
                .enumerate()
                .map(|(i, t)| slurm::PlanCell {
                    data: files[t.data].name.clone(),
                    key: key_of(t),
                    shard: i % n + 1,
                })
                .collect(),
        };
        plan.record(&args.out)?;
        // Cells another shard (of this or an earlier submission) already wrote are done.
        for dir in slurm::shard_dirs(&args.out)?
            .into_iter()
            .chain(std::iter::once(args.out.clone()))
            .filter(|d| *d != out)
        {
            let other = read_results(&dir.join(RESULTS_CSV), false, &mut |_| {})?;
            done.extend(other.iter().map(Row::key));
        }
    }
    let todo: Vec<&Task> = mine
        .iter()
        .map(|(_, t)| *t)
        .filter(|t| !done.contains(&key_of(t)))
        .collect();
    let shard_note = shard
        .map(|(i, n)| format!(" (shard {i}/{n})"))
        .unwrap_or_default();
    eprintln!(
        "sweep{shard_note}: {}, {} of {}; {} already in {}, {} to run",
        plural_with(files.len(), "data set", "data sets"),
        plural(mine.len(), "task"),
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
        return Ok(SweepStats::default());
    }

    let mut skipped: Vec<Skipped> = Vec::new();
    let mut unavailable: HashMap<String, String> = HashMap::new();
    let mut new_rows = 0usize;
    let mut workers = 0usize;
    let t_fits = Instant::now();
    let mut submissions = None;
    let phases = std::sync::Mutex::new(PhaseSeconds::default());
    if !todo.is_empty() {
        // Models that cannot be built are skipped up front (cheap, sequential).
        let mut runnable: Vec<(&Task, Model)> = Vec::new();
        let mut unbuilt = 0u64;
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
                        eprintln!("skipping {}: {reason}", t.model);
                    }
                    skipped.push(skipped_entry(f, t, "skipped", reason));
                    unbuilt += 1;
                }
            }
        }
        // The largest batch of the sweep must fit in memory (checked before any fit).
        if let Some((t, m)) = runnable.iter().max_by_key(|(t, m)| {
            batch_bytes(
                batch_candidates(args.restarts, m.dim),
                m.dim,
                files[t.data].data.len(),
            )
        }) {
            let f = &files[t.data];
            check_batch_memory(
                args.restarts,
                m.dim,
                f.data.len(),
                &format!("{} on {} (the sweep's largest fit)", m.spec, f.name),
                &mut |w| eprintln!("{w}"),
            )?;
        }
        if !constraints.is_empty() {
            let models: Vec<&Model> = runnable.iter().map(|(_, m)| m).collect();
            constraints.check_names_against(&models)?;
            for (_, m) in &runnable {
                Constraints::resolve(m, &constraints, true)
                    .with_context(|| format!("model {}", m.spec))?;
            }
        }
        let backend = engine::select(args.backend.backend, &mut |m| eprintln!("{m}"))?;
        let mut app = Appender::open(&csv_path)?;
        let mut progress = Progress::new("sweep", todo.len() as u64, "fits");
        progress.inc(unbuilt);
        // A stage is one model (same spec, channels and planes) under one optimizer and
        // one loss term shape over every data set, loss and weighting it applies to (the
        // default χ² and RMSE, or χ² and f, are both squares): its fits step in lockstep,
        // so each optimizer step is one submission of all their candidates (many fits
        // per dispatch). On lavapipe, one stage per loss instead took 4,311 submissions
        // against 2,821, and the default sweep 3.7 s against 3.3 s. Stages run on one
        // worker per core; this thread appends every finished fit to results.csv at
        // once, so an interrupted run loses at most the stages in flight. Each fit is
        // deterministic on its own (its starts do not depend on the stage), and
        // results.csv is rewritten in canonical order at the end, so the outcome does not
        // depend on the staging or on which worker finished first.
        let stages = stages_of(&runnable);
        workers = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
            .clamp(1, stages.len().max(1));
        let next = std::sync::atomic::AtomicUsize::new(0);
        let stop = std::sync::atomic::AtomicBool::new(false);
        let backend = backend.as_ref();
        std::thread::scope(|scope| -> Result<()> {
            // The kernels of every stage, compiled ahead in stage order on a thread of
            // their own: a driver compiles when a pipeline is created (lavapipe: NIR,
            // then LLVM, 0.01–0.1 s a model), and this thread does it while the workers
            // wait on the device, instead of on a worker's path. A worker that needs a
            // kernel still being compiled waits for that one alone; an error (or a panic
            // in the driver) is left for the worker to meet and report against its fits.
            {
                let (stages, runnable, stop) = (&stages, &runnable, &stop);
                scope.spawn(move || {
                    for stage in stages {
                        if stop.load(std::sync::atomic::Ordering::SeqCst) {
                            break;
                        }
                        let model = &runnable[stage[0]].1;
                        let _ = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                            backend.prepare_kernels(model)
                        }));
                    }
                });
            }
            let (tx, rx) = std::sync::mpsc::channel();
            for _ in 0..workers {
                let tx = tx.clone();
                let (runnable, next, stop, files) = (&runnable, &next, &stop, &files);
                let (stages, constraints, phases) = (&stages, &constraints, &phases);
                scope.spawn(move || loop {
                    let si = next.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
                    if si >= stages.len() || stop.load(std::sync::atomic::Ordering::SeqCst) {
                        break;
                    }
                    let stage = &stages[si];
                    let (t0, model) = &runnable[stage[0]];
                    let opts = FitOptions {
                        optimizer: t0.optimizer,
                        restarts: args.restarts,
                        seed: args.seed,
                        constraints: constraints.clone(),
                        ..Default::default()
                    };
                    let datas: Vec<&crate::data::Dataset> = stage
                        .iter()
                        .map(|&i| &files[runnable[i].0.data].data)
                        .collect();
                    let losses: Vec<Loss> = stage
                        .iter()
                        .map(|&i| Loss::new(runnable[i].0.loss, runnable[i].0.weights))
                        .collect();
                    let together = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                        fit_stage(model, &datas, &losses, backend, &opts, &mut |_| {})
                    }));
                    let results: Vec<_> = match together {
                        Ok(Ok((reports, spent))) => {
                            if let Ok(mut p) = phases.lock() {
                                *p += spent;
                            }
                            reports.into_iter().map(|r| Ok(Ok(r))).collect()
                        }
                        // One bad fit fails the stage: fit each alone, so the failure is
                        // attributed to its own task and the others still land.
                        _ => stage
                            .iter()
                            .zip(datas.iter().zip(&losses))
                            .map(|(&i, (data, &loss))| {
                                std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                                    fit(&runnable[i].1, data, loss, backend, &opts, &mut |_| {})
                                }))
                            })
                            .collect(),
                    };
                    for (&i, result) in stage.iter().zip(results) {
                        if tx.send((i, result)).is_err() {
                            return;
                        }
                    }
                });
            }
            drop(tx);
            for (i, result) in rx {
                let (t, model) = &runnable[i];
                let f = &files[t.data];
                let loss = Loss::new(t.loss, t.weights);
                progress.set_message(format!(
                    "{} · {} · {}/{} · {}",
                    f.name, t.model, t.loss, t.weights, t.optimizer
                ));
                match result {
                    Ok(Ok(report)) => {
                        let mut row = Row::from_report(&report, f);
                        row.constraints = constraints_text.clone();
                        if !(report.best.chi2_red.is_finite() && report.best.loss.is_finite()) {
                            // Kept (the fit ran), but flagged with the samples that cause it.
                            let msg = nonfinite_message(
                                model,
                                &f.data,
                                loss,
                                &report.flat_params,
                                report.best.chi2_red,
                                report.best.loss,
                                backend,
                            );
                            progress.println(format!("warning: {msg}"));
                            let mut w = row.warnings_json();
                            w.push(msg);
                            row.warnings = serde_json::to_string(&w)?;
                        }
                        if let Err(e) = app.push(&row) {
                            stop.store(true, std::sync::atomic::Ordering::SeqCst);
                            return Err(e);
                        }
                        rows.push(row);
                        new_rows += 1;
                    }
                    Ok(Err(e)) => {
                        progress.println(format!(
                            "fit failed: {} · {} · {loss}: {e:#}",
                            f.name, t.model
                        ));
                        skipped.push(skipped_entry(f, t, "failed", format!("{e:#}")));
                    }
                    Err(p) => {
                        let msg = p
                            .downcast_ref::<String>()
                            .cloned()
                            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                            .unwrap_or_else(|| "panic".into());
                        progress.println(format!(
                            "fit panicked: {} · {} · {loss}: {msg}",
                            f.name, t.model
                        ));
                        skipped.push(skipped_entry(f, t, "failed", format!("panic: {msg}")));
                    }
                }
                progress.inc(1);
            }
            Ok(())
        })?;
        progress.finish();
        submissions = backend.submissions();
    }
    let fit_wall = t_fits.elapsed().as_secs_f64();
    // Canonical results.csv (unchanged bytes when nothing new ran), then summaries.
    write_if_changed(&csv_path, &results_csv_text(&rows)?).with_context(|| {
        format!(
            "{} still holds every row, as appended during the run (not in canonical order)",
            csv_path.display()
        )
    })?;
    write_summaries(&out, &rows)?;
    write_skipped(&out, &skipped, &rows, &files)?;
    eprintln!(
        "{}, {} in {}, {} skipped/failed, {:.1} s",
        plural_with(new_rows, "new fit", "new fits"),
        plural(rows.len(), "row"),
        csv_path.display(),
        skipped.len(),
        t0.elapsed().as_secs_f64()
    );
    if auto {
        eprintln!(
            "shard done; when every shard has, combine them with `bsdfit merge --shards --out {}`",
            args.out.display()
        );
    } else if shard.is_some() {
        eprintln!("shard done; combine the shards with `bsdfit merge DIR... --out DIR` (it writes the pictures and report)");
    } else if !args.no_pictures {
        let run = RunInfo {
            new_fits: new_rows,
            wall_seconds: fit_wall,
            workers,
        };
        crate::output::report::publish(&out, &rows, Some(&run), &mut |m| eprintln!("{m}"))?;
    }
    Ok(SweepStats {
        submissions,
        phases: phases.into_inner().unwrap_or_default(),
    })
}

/// Group tasks into stages (indices into `runnable`, in task order): same model spec,
/// channels and measurement planes, same loss term shape and optimizer.
fn stages_of(runnable: &[(&Task, Model)]) -> Vec<Vec<usize>> {
    let mut index: HashMap<String, usize> = HashMap::new();
    let mut stages: Vec<Vec<usize>> = Vec::new();
    for (i, (t, m)) in runnable.iter().enumerate() {
        let key = format!(
            "{}|{}|{:?}|{:?}|{}",
            m.spec,
            m.channels,
            m.axes,
            t.loss.term(),
            t.optimizer
        );
        let s = *index.entry(key).or_insert_with(|| {
            stages.push(Vec::new());
            stages.len() - 1
        });
        stages[s].push(i);
    }
    stages
}

/// The `merge` command: union the rows of shard directories into `--out`.
pub fn run_merge(args: &MergeArgs) -> Result<()> {
    check_writable_dir(&args.out, "--out")?;
    let _lock = DirLock::acquire(&args.out, "merge", &mut |m| eprintln!("note: {m}"))?;
    let out_csv = args.out.join(RESULTS_CSV);
    let mut rows = read_results(&out_csv, true, &mut |m| eprintln!("note: {m}"))?;
    let mut by_key: BTreeMap<Key, usize> =
        rows.iter().enumerate().map(|(i, r)| (r.key(), i)).collect();
    let mut skipped: Vec<Skipped> = Vec::new();
    let mut inputs = args.inputs.clone();
    let plan = if args.shards {
        let plan = slurm::Plan::read(&args.out)?.with_context(|| {
            format!(
                "--shards: {} has no {} (no `sweep --shard auto --out {}` has started there)",
                args.out.display(),
                slurm::PLAN_JSON,
                args.out.display()
            )
        })?;
        inputs.extend(slurm::shard_dirs(&args.out)?);
        Some(plan)
    } else {
        None
    };
    for input in &inputs {
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
        if let Some((h, alive)) = DirLock::holder(&dir) {
            if alive != Some(false) {
                eprintln!(
                    "warning: {} is still in use by {}; merging the rows it holds so far (merge again when it has finished)",
                    dir.display(),
                    h.describe()
                );
            }
        }
        let part = read_results(&csv, false, &mut |m| eprintln!("note: {m}"))?;
        if let (Some(a), Some(b)) = (rows.first(), part.first()) {
            anyhow::ensure!(
                a.constraints == b.constraints,
                "{} holds fits made under other constraints ({}) than the rows merged so far ({}); merge them into another --out directory",
                csv.display(),
                describe_constraints(&b.constraints),
                describe_constraints(&a.constraints)
            );
        }
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
            "{}: {} added, {same} already present",
            csv.display(),
            plural(added, "row")
        );
        let sk = dir.join(SKIPPED_JSON);
        if let Ok(text) = std::fs::read_to_string(&sk) {
            match serde_json::from_str::<Vec<Skipped>>(&text) {
                Ok(v) => skipped.extend(v),
                Err(e) => eprintln!(
                    "note: {} is not a list of skipped fits ({e}); ignored",
                    sk.display()
                ),
            }
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
    eprintln!("{} in {}", plural(rows.len(), "row"), out_csv.display());
    if !args.no_pictures {
        crate::output::report::publish(&args.out, &rows, None, &mut |m| eprintln!("{m}"))?;
    }
    if let Some(plan) = plan {
        let have: BTreeSet<Key> = rows.iter().map(Row::key).collect();
        let missing = plan.missing(&have);
        // A fit that ran and failed is in skipped.json, as in a single-process sweep.
        let failed: BTreeSet<FitKey> = skipped.iter().map(Skipped::fit_key).collect();
        let (failed_cells, lost): (Vec<_>, Vec<_>) = missing
            .into_iter()
            .partition(|c| failed.contains(&c.fit_key()));
        if !failed_cells.is_empty() {
            eprintln!(
                "{} of the plan ran and failed (listed in {})",
                plural(failed_cells.len(), "fit"),
                args.out.join(SKIPPED_JSON).display()
            );
        }
        if !lost.is_empty() {
            for c in &lost {
                eprintln!("missing: {}", c.describe());
            }
            let shards: BTreeSet<usize> = lost.iter().map(|c| c.shard).collect();
            anyhow::bail!(
                "{} of the plan's {} cells are in no shard's results (shards {} of {}: a task failed, was cancelled or has not run yet). Re-submit the array (only missing cells run), then merge again",
                lost.len(),
                plan.cells.len(),
                shards.iter().map(|s| s.to_string()).collect::<Vec<_>>().join(", "),
                plan.shards,
            );
        }
        eprintln!("all {} cells of the plan are merged", plan.cells.len());
    }
    Ok(())
}

/// The sweep's data files and its task list (every cell, in order).
fn read_cells(args: &SweepArgs) -> Result<(Vec<DataFile>, Vec<Task>)> {
    let paths = expand_data(&args.data)?;
    let mut files = Vec::new();
    for p in &paths {
        files.push(DataFile::read(p, &args.data_args.read_options()?)?);
    }
    let all = tasks(
        &files,
        &Selection {
            models: args.models.clone(),
            losses: args.losses.clone(),
            weights: args.weights.clone(),
            optimizer: args.optimizer.clone(),
        },
    )?;
    Ok((files, all))
}

/// `sweep --emit-slurm TASKS`: the job scripts of this sweep, in OUT/slurm/.
fn emit_slurm(args: &SweepArgs, array_tasks: usize) -> Result<()> {
    anyhow::ensure!(
        array_tasks >= 1,
        "--emit-slurm {array_tasks}: the array needs at least one task"
    );
    anyhow::ensure!(
        args.slurm_cpus >= 1,
        "--slurm-cpus {}: at least one CPU per task",
        args.slurm_cpus
    );
    anyhow::ensure!(
        args.shard.is_none(),
        "--emit-slurm writes an array whose tasks use --shard auto; leave --shard out"
    );
    // Fail now, not on the cluster: the data must read and the selection be valid.
    let (_, all) = read_cells(args)?;
    let workdir = std::env::current_dir().context("cannot read the current folder")?;
    let out = workdir.join(&args.out);
    let dir = out.join("slurm");
    std::fs::create_dir_all(dir.join("logs"))
        .with_context(|| format!("cannot create {}", dir.join("logs").display()))?;
    let binary = std::env::current_exe()
        .context("cannot find the bsdfit binary")?
        .canonicalize()
        .context("cannot find the bsdfit binary")?;
    // Running from the Python module, the "binary" is Python: name bsdfit's instead.
    let binary = if binary
        .file_name()
        .is_some_and(|n| n.to_string_lossy().starts_with("bsdfit"))
    {
        binary
    } else {
        PathBuf::from("bsdfit")
    };
    let scripts = slurm::JobScripts {
        binary: &binary,
        workdir: &workdir,
        out: &out,
        sweep_args: &sweep_argv(args),
        tasks: array_tasks,
        cpus_per_task: args.slurm_cpus,
        gpu: args.backend.backend == engine::BackendChoice::Gpu,
        pictures: !args.no_pictures,
    };
    for (name, text, executable) in scripts.files() {
        let path = dir.join(name);
        crate::output::files::write_result(&path, &text, false)?;
        #[cfg(unix)]
        if executable {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755))
                .with_context(|| format!("cannot make {} executable", path.display()))?;
        }
        #[cfg(not(unix))]
        let _ = executable;
    }
    eprintln!(
        "wrote {0}/array.sbatch ({array_tasks} tasks for {1}), {0}/merge.sbatch and {0}/submit.sh; submit with: sh {0}/submit.sh",
        dir.display(),
        plural(all.len(), "cell"),
    );
    if array_tasks > all.len() {
        eprintln!(
            "note: {array_tasks} tasks for {}: {} of them will have nothing to do",
            plural(all.len(), "cell"),
            array_tasks - all.len()
        );
    }
    Ok(())
}

/// The arguments that make a sweep's task list, as `bsdfit sweep` takes them (without
/// --out, --shard, --emit-slurm, --dry-run and --no-pictures, which the job scripts set).
pub fn sweep_argv(a: &SweepArgs) -> Vec<String> {
    let mut v: Vec<String> = a.data.iter().map(|p| p.display().to_string()).collect();
    let mut opt = |name: &str, value: String| {
        v.push(format!("--{name}"));
        v.push(value);
    };
    for (name, list) in [
        ("models", &a.models),
        ("losses", &a.losses),
        ("weights", &a.weights),
    ] {
        if let Some(list) = list {
            opt(name, list.join(","));
        }
    }
    opt("optimizer", a.optimizer.join(","));
    opt("restarts", a.restarts.to_string());
    opt("seed", a.seed.to_string());
    opt(
        "backend",
        clap::ValueEnum::to_possible_value(&a.backend.backend)
            .map(|p| p.get_name().to_string())
            .unwrap_or_else(|| "auto".into()),
    );
    for f in &a.constraints.fix {
        opt("fix", f.clone());
    }
    for b in &a.constraints.bounds {
        opt("bounds", b.clone());
    }
    for p in &a.constraints.prior {
        opt("prior", p.clone());
    }
    let d = &a.data_args;
    if let Some(w) = &d.wavelengths {
        opt(
            "wavelengths",
            w.iter()
                .map(|x| x.to_string())
                .collect::<Vec<_>>()
                .join(","),
        );
    }
    if let Some(u) = &d.assume_uncertainty {
        opt("assume-uncertainty", u.clone());
    }
    if let Some(b) = d.band {
        opt("band", b.to_string());
    }
    opt("max-samples", d.max_samples.to_string());
    if let Some(k) = d.alta_values {
        opt("alta-values", k.name().to_string());
    }
    if let Some(g) = &d.sample_geometry {
        opt("sample-geometry", g.clone());
    }
    if d.allow_zero_uncertainty {
        v.push("--allow-zero-uncertainty".into());
    }
    v
}
