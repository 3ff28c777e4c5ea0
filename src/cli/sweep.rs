//! `bsdfit sweep` and `bsdfit merge`: their options, turned into a
//! [`SweepConfig`]/[`MergeConfig`] for the runner in [`crate::workflows::sweep`].

use super::progress::ConsoleObserver;
use super::{BackendArgs, ConstraintArgs, DataArgs};
use crate::output::results::DEFAULT_OUT;
use crate::workflows::sweep::{
    self, slurm, MergeConfig, Selection, Shard, SweepConfig, SweepStats,
};
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

/// `bsdfit sweep` arguments.
#[derive(Args, Debug, Clone)]
pub struct SweepArgs {
    /// Data set files, in any format read (bsdfit v1 CSV, ALTA text, MERL binary, RGL
    /// .bsdf, Zemax BSDF, ASTM E1392, Mueller-matrix BRDF CSV; recognised by content), or directories of *.csv
    /// files (default: the bundled data/ directory).
    pub data: Vec<PathBuf>,
    /// Model specs, comma-separated (default: the whole catalogue for each kind of data;
    /// a spec is used on the data sets of its kind).
    #[arg(long, value_delimiter = ',')]
    pub models: Option<Vec<String>>,
    /// Losses, comma-separated (default: rmse,chi2 for BRDF, f,chi2 for BTDF — the
    /// benchmark's RMSE / g₁ comparison plus the χ² fit; each loss is used on the data sets
    /// it is defined for).
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
    #[arg(long, default_value_t = sweep::run::DEFAULT_SEED, value_parser = super::parse_seed, allow_hyphen_values = true)]
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
    /// Run the sweep saved in FILE (the JSON that `--emit-slurm` writes as
    /// DIR/slurm/sweep.json for its array tasks); with it only --shard and --dry-run may
    /// be given.
    #[arg(long, value_name = "FILE", conflicts_with_all = CHOOSES_THE_SWEEP)]
    pub config: Option<PathBuf>,
}

/// The options that choose a sweep, which a saved one (`--config`) already holds.
const CHOOSES_THE_SWEEP: [&str; 20] = [
    "data",
    "models",
    "losses",
    "weights",
    "optimizer",
    "restarts",
    "seed",
    "backend",
    "fix",
    "bounds",
    "prior",
    "wavelengths",
    "allow_zero_uncertainty",
    "assume_uncertainty",
    "band",
    "max_samples",
    "alta_values",
    "sample_geometry",
    "out",
    "no_pictures",
];

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

impl SweepArgs {
    /// The runner's configuration these options ask for.
    pub fn config(&self) -> Result<SweepConfig> {
        let shard = self.shard.as_deref().map(Shard::parse).transpose()?;
        if let Some(path) = &self.config {
            return Ok(SweepConfig {
                shard,
                dry_run: self.dry_run,
                ..SweepConfig::load(path)?
            });
        }
        Ok(SweepConfig {
            data: self.data.clone(),
            read: self.data_args.read_options()?,
            selection: Selection {
                models: self.models.clone(),
                losses: self.losses.clone(),
                weights: self.weights.clone(),
                optimizer: self.optimizer.clone(),
            },
            restarts: self.restarts,
            seed: self.seed,
            backend: self.backend.backend,
            constraints: self.constraints.spec(true)?,
            out: self.out.clone(),
            shard,
            pictures: !self.no_pictures,
            dry_run: self.dry_run,
        })
    }
}

/// The `sweep` command: run it (or write its Slurm job scripts, or list its cells).
pub fn run_sweep(args: &SweepArgs) -> Result<SweepStats> {
    let cfg = args.config()?;
    let mut console = ConsoleObserver::new("sweep");
    if let Some(tasks) = args.emit_slurm {
        slurm::emit(&cfg, tasks, args.slurm_cpus, None, &mut console)?;
        return Ok(SweepStats::default());
    }
    let stats = sweep::run(&cfg, &mut console)?;
    for c in &stats.listing {
        let t = &c.task;
        let state = if c.done { "done" } else { "todo" };
        println!(
            "{}\t{state}\t{}\t{}\t{}/{}\t{}",
            c.index, c.data, t.model, t.loss, t.weights, t.optimizer
        );
    }
    Ok(stats)
}

/// The `merge` command: union the rows of shard directories into `--out`.
pub fn run_merge(args: &MergeArgs) -> Result<()> {
    use crate::workflows::collection;
    if (args.shards && collection::merge::is_collection(&args.out))
        || args
            .inputs
            .iter()
            .any(|i| collection::merge::is_collection(i))
    {
        return collection::merge(
            &args.out,
            &args.inputs,
            args.shards,
            !args.no_pictures,
            &mut ConsoleObserver::new("merge"),
        );
    }
    let cfg = MergeConfig {
        inputs: args.inputs.clone(),
        shards: args.shards,
        out: args.out.clone(),
        pictures: !args.no_pictures,
    };
    sweep::merge(&cfg, &mut ConsoleObserver::new("merge"))
}
