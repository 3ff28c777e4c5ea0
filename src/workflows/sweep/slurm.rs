//! Sweeps on a Slurm cluster (docs/cluster.md): the shard of a job-array task read from
//! Slurm's environment, one folder per shard inside the sweep's folder, the plan that lets
//! a merge name the cells no shard wrote, and the job scripts `sweep --emit-slurm` writes.
//!
//! Layout of `--out OUT` for `--shard auto`:
//! - `OUT/shards/I-of-N/`: shard I's own results folder (its own lock, resumable);
//! - `OUT/plan.json`: every cell of the sweep, written by the first shard to start;
//! - `OUT/results.csv`, report…: written by `bsdfit merge --shards --out OUT`.
//!
//! No two processes write one file: shards write their own folders, the plan is written
//! to a temporary and renamed into place (the same content from every shard), and the
//! merge holds `OUT`'s lock.

use super::run::{read_cells, SweepConfig, SweepObserver};
use crate::choice::field_error;
use crate::engine::BackendChoice;
use crate::output::results::{fit_key, FitKey, Key};
use crate::text::plural;
use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The folder of the shard folders inside a sweep's `--out`.
pub const SHARDS_DIR: &str = "shards";
/// The sweep's plan inside its `--out`.
pub const PLAN_JSON: &str = "plan.json";

/// The variables `--shard auto` reads, in the order the error message lists them.
const ARRAY_VARS: [&str; 5] = [
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_MIN",
    "SLURM_ARRAY_TASK_MAX",
    "SLURM_ARRAY_TASK_STEP",
    "SLURM_ARRAY_TASK_COUNT",
];

/// The shard (I of N, 1-based) of this Slurm job-array task, from its environment
/// (`get` reads a variable). Any index base and step Slurm allows (`--array=0-9`,
/// `--array=1-99:2`, `--array=5-5`): task ID maps to I = (ID − MIN)/STEP + 1 of
/// N = COUNT (or (MAX − MIN)/STEP + 1). A list of indices that is not such a range
/// (`--array=1,4,5`) cannot be numbered from the variables and is refused.
pub fn shard_from_env(get: &dyn Fn(&str) -> Option<String>) -> Result<(usize, usize)> {
    // The messages name the option as a field (`{shard=auto}`): `--shard auto` on the
    // command line, `shard='auto'` in Python.
    let num = |name: &str| -> Result<Option<u64>> {
        match get(name) {
            None => Ok(None),
            Some(v) if v.trim().is_empty() => Ok(None),
            Some(v) => v.trim().parse::<u64>().map(Some).map_err(|e| {
                let v = v.replace('{', "(").replace('}', ")");
                field_error(format!("{{shard=auto}}: {name}={v} is not an index: {e}"))
            }),
        }
    };
    let Some(id) = num("SLURM_ARRAY_TASK_ID")? else {
        return Err(field_error(format!(
            "{{shard=auto}}: SLURM_ARRAY_TASK_ID is not set, so this is not a task of a Slurm job array ({{shard=auto}} reads {}). Submit with `sbatch --array=1-N`, or give {{shard=I/N}}",
            ARRAY_VARS.join(", ")
        )));
    };
    let min = num("SLURM_ARRAY_TASK_MIN")?.ok_or_else(|| {
        field_error("{shard=auto}: SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_MIN is not")
    })?;
    let max = num("SLURM_ARRAY_TASK_MAX")?.ok_or_else(|| {
        field_error("{shard=auto}: SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_MAX is not")
    })?;
    let step = num("SLURM_ARRAY_TASK_STEP")?.unwrap_or(1).max(1);
    if !(min <= id && id <= max) {
        return Err(field_error(format!(
            "{{shard=auto}}: SLURM_ARRAY_TASK_ID={id} is outside SLURM_ARRAY_TASK_MIN..MAX = {min}..{max}"
        )));
    }
    let span = (max - min) / step + 1;
    let count = num("SLURM_ARRAY_TASK_COUNT")?.unwrap_or(span);
    if !((max - min) % step == 0 && count == span && (id - min) % step == 0) {
        return Err(field_error(format!(
            "{{shard=auto}}: the array's indices ({min}..{max}, step {step}, {count} tasks) are not one range MIN-MAX[:STEP], so task {id} cannot be numbered; submit with --array=1-{count} (or give {{shard=I/N}})"
        )));
    }
    Ok((((id - min) / step + 1) as usize, count as usize))
}

/// Shard I of N's own folder inside the sweep's `out`.
pub fn shard_dir(out: &Path, (i, n): (usize, usize)) -> PathBuf {
    out.join(SHARDS_DIR).join(format!("{i}-of-{n}"))
}

/// The shard folders present in `out` (sorted).
pub fn shard_dirs(out: &Path) -> Result<Vec<PathBuf>> {
    let dir = out.join(SHARDS_DIR);
    if !dir.exists() {
        return Ok(Vec::new());
    }
    let mut dirs: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_dir())
        .collect();
    dirs.sort();
    Ok(dirs)
}

/// One cell of a sweep: its key, its data set's label for messages, and its shard. In
/// plan.json the key's fields sit beside `data` and `shard`.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct PlanCell {
    pub data: String,
    #[serde(flatten)]
    pub key: Key,
    /// The shard (1-based) that runs it.
    pub shard: usize,
}

impl PlanCell {
    /// The key a failed fit of this cell has in skipped.json.
    pub fn fit_key(&self) -> FitKey {
        let k = &self.key;
        fit_key(&self.data, &k.model, &k.loss, &k.weights, &k.optimizer)
    }

    /// `data · model · loss/weights (optimizer), shard I`.
    pub fn describe(&self) -> String {
        let k = &self.key;
        format!(
            "{} · {} · {}/{} ({}), shard {}",
            self.data, k.model, k.loss, k.weights, k.optimizer, self.shard
        )
    }
}

/// Every cell of a sharded sweep, and its number of shards.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Plan {
    pub shards: usize,
    pub constraints: String,
    pub cells: Vec<PlanCell>,
}

impl Plan {
    fn same_work(&self, other: &Plan) -> bool {
        fn keys(p: &Plan) -> BTreeSet<&Key> {
            p.cells.iter().map(|c| &c.key).collect()
        }
        self.constraints == other.constraints && keys(self) == keys(other)
    }

    /// Write the plan into `out`, or check that the plan already there asks for the same
    /// cells (a re-submitted array may use another number of shards: the plan is then
    /// rewritten with the new numbering).
    pub fn record(&self, out: &Path) -> Result<()> {
        let path = out.join(PLAN_JSON);
        if let Some(old) = Plan::read(out)? {
            anyhow::ensure!(
                old.same_work(self),
                "{} holds the plan of another sweep ({} cells{}) than this one ({} cells{}): other data, models, losses, restarts, seed or constraints; use another --out folder",
                path.display(),
                old.cells.len(),
                describe_constraints(&old.constraints),
                self.cells.len(),
                describe_constraints(&self.constraints),
            );
            if old == *self {
                return Ok(());
            }
        }
        // Several shards start at once: each writes its own temporary and renames it
        // into place; the contents are the same, so whichever lands last is right.
        let tmp = out.join(format!(".{PLAN_JSON}.{}.tmp", std::process::id()));
        std::fs::write(&tmp, serde_json::to_string_pretty(self)? + "\n")
            .with_context(|| format!("cannot write {}", tmp.display()))?;
        std::fs::rename(&tmp, &path)
            .with_context(|| format!("cannot rename {} to {}", tmp.display(), path.display()))?;
        Ok(())
    }

    /// The plan in `out`, if a sharded sweep wrote one.
    pub fn read(out: &Path) -> Result<Option<Plan>> {
        let path = out.join(PLAN_JSON);
        match std::fs::read_to_string(&path) {
            Ok(text) => {
                Ok(Some(serde_json::from_str(&text).with_context(|| {
                    format!("{} is not a sweep plan", path.display())
                })?))
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(e).with_context(|| format!("cannot read {}", path.display())),
        }
    }

    /// The cells whose key is not in `have`.
    pub fn missing(&self, have: &BTreeSet<Key>) -> Vec<&PlanCell> {
        self.cells
            .iter()
            .filter(|c| !have.contains(&c.key))
            .collect()
    }
}

fn describe_constraints(c: &str) -> String {
    if c.is_empty() {
        String::new()
    } else {
        format!(", constraints {c}")
    }
}

/// A word as one shell word (single quotes, `'` written as `'\''`).
pub fn shell_quote(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c))
    {
        return s.to_string();
    }
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// What `sweep --emit-slurm` (and `diagnose --emit-slurm`) needs to write the job scripts.
pub struct JobScripts<'a> {
    /// The command each array task runs with `--config CONFIG --shard auto`: `sweep` or
    /// `diagnose`.
    pub command: &'static str,
    /// The bsdfit binary (absolute).
    pub binary: &'a Path,
    /// The folder the jobs run in (relative paths in the arguments are relative to it).
    pub workdir: &'a Path,
    /// The sweep's folder (absolute).
    pub out: &'a Path,
    /// The saved configuration the tasks run ([`SWEEP_JSON`] in OUT/slurm/ for a sweep).
    pub config: &'a Path,
    pub tasks: usize,
    pub cpus_per_task: usize,
    /// Ask each task for one GPU (`--gres=gpu:1`).
    pub gpu: bool,
    pub pictures: bool,
}

impl JobScripts<'_> {
    /// (file name, content, executable) of `array.sbatch`, `merge.sbatch`, `submit.sh`.
    pub fn files(&self) -> Vec<(&'static str, String, bool)> {
        let q = |p: &Path| shell_quote(&p.display().to_string());
        let logs = self.out.join("slurm").join("logs");
        let gres = if self.gpu {
            "#SBATCH --gres=gpu:1\n"
        } else {
            ""
        };
        let array = format!(
            "#!/bin/bash
# bsdfit {cmd} as a Slurm job array: task I of {n} runs shard I/{n} into
# {out}/shards/I-of-{n}/ (written by `bsdfit {cmd} --emit-slurm`; edit the #SBATCH lines
# freely, keep the array a range). Re-submitting resumes: only missing cells run.
#SBATCH --job-name=bsdfit-{cmd}
#SBATCH --array=1-{n}
#SBATCH --cpus-per-task={cpus}
{gres}#SBATCH --chdir={wd}
#SBATCH --output={logs}/{cmd}-%A_%a.out
set -euo pipefail
# The CPU reference uses the CPUs Slurm gave the task.
export RAYON_NUM_THREADS=\"${{SLURM_CPUS_PER_TASK:-1}}\"
exec {bin} {cmd} --config {config} --shard auto
",
            cmd = self.command,
            n = self.tasks,
            out = self.out.display(),
            cpus = self.cpus_per_task,
            wd = q(self.workdir),
            logs = q(&logs),
            bin = q(self.binary),
            config = q(self.config),
        );
        let merge = format!(
            "#!/bin/bash
# Merges the shards of {out} once every task of the array has ended (successfully or
# not): it lists the cells no shard wrote and then fails, so a lost task is never silent.
#SBATCH --job-name=bsdfit-merge
#SBATCH --cpus-per-task=1
#SBATCH --chdir={wd}
#SBATCH --output={logs}/merge-%j.out
set -euo pipefail
exec {bin} merge --shards --out {outq}{pictures}
",
            out = self.out.display(),
            wd = q(self.workdir),
            logs = q(&logs),
            bin = q(self.binary),
            outq = q(self.out),
            pictures = if self.pictures { "" } else { " --no-pictures" },
        );
        let submit = format!(
            "#!/bin/sh
# Submit the {cmd}'s job array, then the merge, which waits for every task to end
# (afterany: a failed task leaves cells missing, and the merge says which).
set -eu
dir=$(dirname \"$0\")
array=$(sbatch --parsable \"$dir/array.sbatch\")
array=${{array%%;*}}
merge=$(sbatch --parsable --dependency=afterany:\"$array\" \"$dir/merge.sbatch\")
merge=${{merge%%;*}}
echo \"submitted array job $array ({n} tasks) and merge job $merge; results in {out}\"
",
            cmd = self.command,
            n = self.tasks,
            out = self.out.display(),
        );
        vec![
            ("array.sbatch", array, false),
            ("merge.sbatch", merge, false),
            ("submit.sh", submit, true),
        ]
    }
}

/// The saved sweep configuration the job scripts' tasks read, in OUT/slurm/.
pub const SWEEP_JSON: &str = "sweep.json";

/// `sweep --emit-slurm TASKS`: the job scripts of the sweep `cfg` in OUT/slurm/, with the
/// sweep saved there as [`SWEEP_JSON`]: an array of `tasks` tasks of `cpus_per_task` CPUs
/// each running `BINARY sweep --config OUT/slurm/sweep.json --shard auto`, BINARY the
/// given one or this process's ([`bsdfit_binary`]). The data and the selection are read
/// now, so a mistake fails here and not on the cluster.
pub fn emit(
    cfg: &SweepConfig,
    tasks: usize,
    cpus_per_task: usize,
    binary: Option<&Path>,
    obs: &mut dyn SweepObserver,
) -> Result<()> {
    check_array(tasks, cpus_per_task, cfg.shard.is_some())?;
    let (_, all) = read_cells(cfg)?;
    let job = ArrayJob {
        command: "sweep",
        config_name: SWEEP_JSON,
        runs: "the sweep they run",
        cells: plural(all.len(), "cell"),
        cell_count: all.len(),
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
            SweepConfig {
                out: out.to_path_buf(),
                ..cfg.clone()
            }
            .save(config)
        },
    )
}

/// A job array of `bsdfit COMMAND --config OUT/slurm/CONFIG --shard auto` tasks and its
/// merge, as `sweep --emit-slurm` and `diagnose --emit-slurm` write them.
pub struct ArrayJob {
    /// `sweep` or `diagnose`.
    pub command: &'static str,
    /// The file name of the saved configuration in OUT/slurm/.
    pub config_name: &'static str,
    /// What the tasks run, in words (`the sweep they run`).
    pub runs: &'static str,
    /// The cells in words (`24 cells`), and their number.
    pub cells: String,
    pub cell_count: usize,
    /// Ask each task for one GPU.
    pub gpu: bool,
    pub pictures: bool,
}

impl ArrayJob {
    /// Write OUT/slurm/ (`out` relative to the current folder, where the jobs run): the
    /// configuration (`save` writes it, given the absolute OUT, to the path given), the
    /// array, the merge and submit.sh; tell `obs` how to submit them.
    pub fn emit(
        &self,
        out: &Path,
        tasks: usize,
        cpus_per_task: usize,
        binary: Option<&Path>,
        obs: &mut dyn SweepObserver,
        save: &mut dyn FnMut(&Path, &Path) -> Result<()>,
    ) -> Result<()> {
        let workdir = std::env::current_dir().context("cannot read the current folder")?;
        let out = workdir.join(out);
        let dir = out.join("slurm");
        std::fs::create_dir_all(dir.join("logs"))
            .with_context(|| format!("cannot create {}", dir.join("logs").display()))?;
        let config = dir.join(self.config_name);
        save(&out, &config)?;
        let binary = match binary {
            Some(b) => b.to_path_buf(),
            None => bsdfit_binary()?,
        };
        JobScripts {
            command: self.command,
            binary: &binary,
            workdir: &workdir,
            out: &out,
            config: &config,
            tasks,
            cpus_per_task,
            gpu: self.gpu,
            pictures: self.pictures,
        }
        .write(&dir)?;
        obs.note(&format!(
            "wrote {0}/array.sbatch ({tasks} tasks for {1}), {0}/merge.sbatch, {0}/submit.sh and {2}, {0}/{3}; submit with: sh {0}/submit.sh",
            dir.display(),
            self.cells,
            self.runs,
            self.config_name,
        ));
        if tasks > self.cell_count {
            obs.note(&format!(
                "note: {tasks} tasks for {}: {} of them will have nothing to do",
                self.cells,
                tasks - self.cell_count
            ));
        }
        Ok(())
    }
}

/// The checks of `--emit-slurm TASKS --slurm-cpus N` (`sharded`: a `--shard` was given).
pub fn check_array(tasks: usize, cpus_per_task: usize, sharded: bool) -> Result<()> {
    if tasks < 1 {
        return Err(field_error(format!(
            "{{emit_slurm={tasks}}}: the array needs at least one task"
        )));
    }
    if cpus_per_task < 1 {
        return Err(field_error(format!(
            "{{slurm_cpus={cpus_per_task}}}: at least one CPU per task"
        )));
    }
    if sharded {
        return Err(field_error(
            "{emit_slurm} writes an array whose tasks use {shard=auto}; leave {shard} out",
        ));
    }
    Ok(())
}

impl JobScripts<'_> {
    /// Write the scripts into `dir` (submit.sh executable).
    pub fn write(&self, dir: &Path) -> Result<()> {
        for (name, text, executable) in self.files() {
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
        Ok(())
    }
}

/// The bsdfit binary the job scripts run: this process's, or `bsdfit` on the PATH when
/// this process is not bsdfit (the Python module runs inside Python).
pub fn bsdfit_binary() -> Result<PathBuf> {
    let binary = std::env::current_exe()
        .context("cannot find the bsdfit binary")?
        .canonicalize()
        .context("cannot find the bsdfit binary")?;
    Ok(
        if binary
            .file_name()
            .is_some_and(|n| n.to_string_lossy().starts_with("bsdfit"))
        {
            binary
        } else {
            PathBuf::from("bsdfit")
        },
    )
}
