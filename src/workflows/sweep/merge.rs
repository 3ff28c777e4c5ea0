//! `bsdfit merge`: the union of the rows of several sweep folders (shards run apart, or
//! the shard folders of a Slurm array checked against its plan) in one output folder.

use super::lock::DirLock;
use super::run::{describe_constraints, SweepObserver};
use super::slurm;
use crate::output::files::check_writable_dir;
use crate::output::results::{
    read_results, results_csv_text, write_if_changed, write_summaries, FitKey, Key, Row, Skipped,
    RESULTS_CSV, SKIPPED_JSON,
};
use crate::text::plural;
use anyhow::{Context, Result};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// What to merge, and where.
#[derive(Clone, Debug)]
pub struct MergeConfig {
    /// Sweep folders (or their results.csv files).
    pub inputs: Vec<PathBuf>,
    /// Also merge OUT/shards/*, and check them against OUT/plan.json.
    pub shards: bool,
    /// Output folder; rows already in its results.csv are kept.
    pub out: PathBuf,
    pub pictures: bool,
}

/// The inputs, each folder a `sweep --shard auto` wrote (its plan.json and shards/) with
/// its shard folders after it, said in a note; other inputs as they are.
fn with_shard_folders(inputs: &[PathBuf], obs: &mut dyn SweepObserver) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for input in inputs {
        if !(input.is_dir() && input.join(slurm::PLAN_JSON).exists()) {
            out.push(input.clone());
            continue;
        }
        let shards = slurm::shard_dirs(input)?;
        anyhow::ensure!(
            !shards.is_empty() || input.join(RESULTS_CSV).exists(),
            "{}: the folder of a `sweep --shard auto` whose tasks have written no rows yet; merge when they have (`bsdfit merge --shards --out {}` then checks them against its plan)",
            input.display(),
            input.display()
        );
        obs.note(&format!(
            "note: {} is the folder of a `sweep --shard auto`: merging its {} (`bsdfit merge --shards --out {}` merges them there and checks them against its plan)",
            input.display(),
            plural(shards.len(), "shard folder"),
            input.display()
        ));
        if input.join(RESULTS_CSV).exists() {
            out.push(input.clone());
        }
        out.extend(shards);
    }
    Ok(out)
}

/// The rows merged so far and the skipped entries met on the way.
struct Merged {
    rows: Vec<Row>,
    by_key: BTreeMap<Key, usize>,
    skipped: Vec<Skipped>,
}

/// Merge the inputs' rows into `cfg.out`; with `shards`, list each cell of the plan that
/// no shard wrote and fail (after writing what there is), so a lost task is never silent.
pub fn merge(cfg: &MergeConfig, obs: &mut dyn SweepObserver) -> Result<()> {
    check_writable_dir(&cfg.out, "--out")?;
    let _lock = DirLock::acquire(&cfg.out, "merge", &mut |m| obs.note(&format!("note: {m}")))?;
    let out_csv = cfg.out.join(RESULTS_CSV);
    let rows = read_results(&out_csv, true, &mut |m| obs.note(&format!("note: {m}")))?;
    let mut merged = Merged {
        by_key: rows.iter().enumerate().map(|(i, r)| (r.key(), i)).collect(),
        rows,
        skipped: Vec::new(),
    };
    let mut inputs = with_shard_folders(&cfg.inputs, obs)?;
    let plan = if cfg.shards {
        let plan = slurm::Plan::read(&cfg.out)?.with_context(|| {
            format!(
                "--shards: {} has no {} (no `sweep --shard auto --out {}` has started there)",
                cfg.out.display(),
                slurm::PLAN_JSON,
                cfg.out.display()
            )
        })?;
        inputs.extend(slurm::shard_dirs(&cfg.out)?);
        Some(plan)
    } else {
        None
    };
    for input in &inputs {
        merged.add_input(input, &out_csv, obs)?;
    }
    let Merged {
        rows, mut skipped, ..
    } = merged;
    write_if_changed(&out_csv, &results_csv_text(&rows)?)?;
    write_summaries(&cfg.out, &rows)?;
    let have: BTreeSet<FitKey> = rows.iter().map(Row::fit_key).collect();
    skipped.retain(|s| !have.contains(&s.fit_key()));
    skipped.sort_by_key(Skipped::fit_key);
    skipped.dedup_by_key(|s| s.fit_key());
    write_if_changed(
        &cfg.out.join(SKIPPED_JSON),
        &(serde_json::to_string_pretty(&skipped)? + "\n"),
    )?;
    obs.note(&format!(
        "{} in {}",
        plural(rows.len(), "row"),
        out_csv.display()
    ));
    if cfg.pictures {
        crate::output::report::publish(&cfg.out, &rows, None, &mut |m| obs.note(&m))?;
    }
    match plan {
        Some(plan) => check_plan(&plan, &rows, &skipped, &cfg.out, obs),
        None => Ok(()),
    }
}

impl Merged {
    /// Add the rows of one input folder (or results.csv) and its skipped.json entries.
    fn add_input(
        &mut self,
        input: &Path,
        out_csv: &Path,
        obs: &mut dyn SweepObserver,
    ) -> Result<()> {
        let (csv, dir) = if input.is_dir() {
            (input.join(RESULTS_CSV), input.to_path_buf())
        } else {
            (
                input.to_path_buf(),
                input.parent().map(Path::to_path_buf).unwrap_or_default(),
            )
        };
        anyhow::ensure!(
            csv.exists(),
            "{} not found: give a folder a sweep wrote (`bsdfit sweep --out`), or its {RESULTS_CSV}",
            csv.display()
        );
        if csv.canonicalize().ok() == out_csv.canonicalize().ok() {
            return Ok(());
        }
        if let Some((h, alive)) = DirLock::holder(&dir) {
            if alive != Some(false) {
                obs.note(&format!(
                    "warning: {} is still in use by {}; merging the rows it holds so far (merge again when it has finished)",
                    dir.display(),
                    h.describe()
                ));
            }
        }
        let part = read_results(&csv, false, &mut |m| obs.note(&format!("note: {m}")))?;
        if let (Some(a), Some(b)) = (self.rows.first(), part.first()) {
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
            match self.by_key.get(&r.key()) {
                Some(&i) => {
                    if self.rows[i].deterministic() != r.deterministic() {
                        obs.note(&format!(
                            "warning: {} has a different result for {} · {} · {}/{} ({}); keeping the first",
                            csv.display(),
                            r.data,
                            r.model,
                            r.loss,
                            r.weights,
                            r.optimizer
                        ));
                    }
                    same += 1;
                }
                None => {
                    self.by_key.insert(r.key(), self.rows.len());
                    self.rows.push(r);
                    added += 1;
                }
            }
        }
        obs.note(&format!(
            "{}: {} added, {same} already present",
            csv.display(),
            plural(added, "row")
        ));
        let sk = dir.join(SKIPPED_JSON);
        if let Ok(text) = std::fs::read_to_string(&sk) {
            match serde_json::from_str::<Vec<Skipped>>(&text) {
                Ok(v) => self.skipped.extend(v),
                Err(e) => obs.note(&format!(
                    "note: {} is not a list of skipped fits ({e}); ignored",
                    sk.display()
                )),
            }
        }
        Ok(())
    }
}

/// `merge --shards`: every cell of the plan has a row, or ran and failed (skipped.json);
/// the others are listed and the merge fails.
fn check_plan(
    plan: &slurm::Plan,
    rows: &[Row],
    skipped: &[Skipped],
    out: &Path,
    obs: &mut dyn SweepObserver,
) -> Result<()> {
    let have: BTreeSet<Key> = rows.iter().map(Row::key).collect();
    let missing = plan.missing(&have);
    // A fit that ran and failed is in skipped.json, as in a single-process sweep.
    let failed: BTreeSet<FitKey> = skipped.iter().map(Skipped::fit_key).collect();
    let (failed_cells, lost): (Vec<_>, Vec<_>) = missing
        .into_iter()
        .partition(|c| failed.contains(&c.fit_key()));
    if !failed_cells.is_empty() {
        obs.note(&format!(
            "{} of the plan ran and failed (listed in {})",
            plural(failed_cells.len(), "fit"),
            out.join(SKIPPED_JSON).display()
        ));
    }
    if !lost.is_empty() {
        for c in &lost {
            obs.note(&format!("missing: {}", c.describe()));
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
    obs.note(&format!(
        "all {} cells of the plan are merged",
        plan.cells.len()
    ));
    Ok(())
}
