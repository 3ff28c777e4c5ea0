//! `bsdfit diagnose`.

use super::progress::{ConsoleObserver, Progress};
use super::{BackendArgs, ConstraintArgs, DataArgs};
use crate::engine;
use crate::inference::bootstrap::BootstrapOptions;
use crate::inference::constraints::ConstraintSpec;
use crate::inference::fit::Optimizer;
use crate::text::plural;
use crate::workflows::collection::{self, CellStatus, CollectionConfig};
use crate::workflows::diagnose::{diagnose, write_report, DiagnoseOptions, DiagnoseRequest};
use crate::workflows::fit::{parse_metric, parse_weights};
use crate::workflows::sweep::Shard;
use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

/// `bsdfit diagnose DATA --model START [--json OUT] [--report DIR]`, or a collection:
/// `bsdfit diagnose FILE|DIR… --model START --out DIR`.
#[derive(Args, Clone, Debug)]
pub struct DiagnoseArgs {
    /// Data files, in any format read (recognised by content): bsdfit v1 CSV, ALTA text,
    /// MERL binary, RGL .bsdf, Zemax BSDF, ASTM E1392, Mueller-matrix BRDF CSV; or folders, whose files of those
    /// formats are taken (the others are named and left). One file without --out: its
    /// diagnosis is printed (and --json, --report written); several, a folder, or --out:
    /// a collection, one resumable cell per data set in --out.
    #[arg(required_unless_present = "config")]
    pub data: Vec<PathBuf>,
    /// Start model spec, e.g. lambert, on, btdf(beckmann).
    #[arg(long, required_unless_present = "config")]
    pub model: Option<String>,
    /// Loss that drives each fit (the statistics always use χ²).
    #[arg(long, default_value_t = DiagnoseOptions::default().loss.metric.to_string())]
    pub loss: String,
    /// Weighting of that loss: uniform, relunc, invunc, or unc (the kind's uncertainty
    /// weighting); χ² weights by 1/u² whatever is given.
    #[arg(long, default_value_t = DiagnoseOptions::default().loss.weights.to_string())]
    pub weights: String,
    /// Optimizer of every fit: lm (Levenberg–Marquardt, for sum-of-squares losses: χ² and
    /// every loss but smape) or compass (compass search; what smape is fitted with
    /// whatever is given).
    #[arg(long, value_parser = super::choice::<Optimizer>(), default_value_t = DiagnoseOptions::default().optimizer)]
    pub optimizer: Optimizer,
    /// Random restarts per fit (plus the current optimum as one more start); the same
    /// default as `fit`.
    #[arg(long, default_value_t = DiagnoseOptions::default().restarts, value_parser = super::parse_restarts, allow_hyphen_values = true)]
    pub restarts: usize,
    /// Seed of the random restarts (a non-negative integer).
    #[arg(long, default_value_t = DiagnoseOptions::default().seed, value_parser = super::parse_seed, allow_hyphen_values = true)]
    pub seed: u64,
    /// Significance level (consistency test; F tests at α / number of candidates).
    #[arg(long, default_value_t = DiagnoseOptions::default().alpha)]
    pub alpha: f64,
    /// Most effects to add.
    #[arg(long, default_value_t = DiagnoseOptions::default().max_steps)]
    pub max_steps: usize,
    /// Steps beyond --max-steps that a path whose last step took a data-driven factor
    /// (+ndf, +fresnel, +body) may take, each one of the factors it lacks and nothing else
    /// (0: stop at --max-steps whatever the last step was).
    #[arg(long, value_name = "N", default_value_t = DiagnoseOptions::default().factors_past_max_steps)]
    pub factors_past_max_steps: usize,
    /// Replicates of the parametric bootstrap that calibrates the p-value of an extension
    /// whose null is irregular (a new parameter's null value on a bound of its range, e.g.
    /// σ = 0 or k_s = 0, or new parameters the null does not identify, e.g. the lobe's α
    /// when k_s = 0), where the F test's reference distribution does not hold. Run only
    /// where the verdict depends on it; 0 keeps the nominal F test everywhere. These are
    /// the planned replicates: the test stops earlier once its verdict at the level is
    /// settled (enough replicates reach the observed statistic), and draws more, up to
    /// --bootstrap-max, where they cannot decide (none reaches it and 1/(B + 1) is above
    /// the level).
    #[arg(long, default_value_t = DiagnoseOptions::default().bootstrap.replicates)]
    pub bootstrap: usize,
    /// The most bootstrap replicates drawn where the planned ones cannot decide (a test
    /// still undecided there says so); at most --bootstrap keeps B fixed.
    #[arg(long, default_value_t = DiagnoseOptions::default().bootstrap.max_replicates)]
    pub bootstrap_max: usize,
    /// Calibrate every irregular candidate whose own verdict depends on it, even where the
    /// round adopts the same candidate whatever that verdict (by default such bootstraps are
    /// deferred, and run only if a backtrack needs the candidate).
    #[arg(long)]
    pub calibrate_all: bool,
    /// Random restarts per bootstrap refit (at least 1), besides the carried-over optima.
    #[arg(long, default_value_t = DiagnoseOptions::default().bootstrap.restarts)]
    pub bootstrap_restarts: usize,
    #[command(flatten)]
    pub backend: BackendArgs,
    /// Write the diagnosis (docs/output.md) as JSON here (checked before the fits start; if the
    /// write fails afterwards, the JSON is printed to stdout instead).
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write residual maps, the χ²_red staircase and the candidate tables here (checked
    /// before the fits start).
    #[arg(long)]
    pub report: Option<PathBuf>,
    #[command(flatten)]
    pub constraints: ConstraintArgs,
    #[command(flatten)]
    pub data_args: DataArgs,
    /// Keep the greedy path even when it ends with the misfit exceeding the uncertainties
    /// (by default each step is then revisited once with another effect's best candidate).
    #[arg(long)]
    pub no_backtrack: bool,
    /// Fit a round's candidates concurrently, one thread each (pays off on a real GPU; on a
    /// software device such as lavapipe, or the CPU backend, it only adds contention).
    #[arg(long)]
    pub parallel: bool,
    /// Dense data: with more than N samples (and a quarter), search the path on a
    /// stratified subsample of N samples, then refit its models on all the data and keep
    /// the steps the full data confirm (F test and BIC again there). 0: always search on
    /// all the data.
    #[arg(long, value_name = "N", default_value_t = DiagnoseOptions::default().explore)]
    pub explore: usize,
    /// Diagnose the data sets as a collection into DIR: DIR/cells/NAME.json per data set
    /// (written as each ends; a rerun skips the data sets done for the same bytes),
    /// DIR/diagnoses/NAME/ (residual maps, staircase, candidates), and DIR/diagnoses.csv,
    /// diagnoses.json and report.html for the whole collection. A data set that fails is
    /// listed with its error and the others go on. Locked while it runs (DIR/.bsdfit.lock).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// With a collection: run only shard I of N (1-based) of its data sets, e.g. 2/4, into
    /// --out (one process at a time per folder: give each concurrent shard its own, then
    /// `bsdfit merge A B --out DIR`). `auto`: the shard of this Slurm job-array task,
    /// written into DIR/shards/I-of-N/; gather them with `bsdfit merge --shards --out DIR`.
    #[arg(long, value_name = "I/N|auto")]
    pub shard: Option<String>,
    /// With a collection: write Slurm job scripts into DIR/slurm/ instead of running it
    /// (an array of TASKS tasks with `--shard auto`, a merge job that runs when every task
    /// has ended, and submit.sh that submits both).
    #[arg(long, value_name = "TASKS")]
    pub emit_slurm: Option<usize>,
    /// With --emit-slurm: CPUs per array task (`--cpus-per-task`).
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub slurm_cpus: usize,
    /// With a collection: skip each data set's residual maps and the report's pictures
    /// (the tables and report.html are still written).
    #[arg(long)]
    pub no_pictures: bool,
    /// Run the collection saved in FILE (DIR/slurm/collection.json, written by
    /// --emit-slurm for its array tasks); with it only --shard may be given.
    #[arg(long, value_name = "FILE", conflicts_with_all = CHOOSES_THE_DIAGNOSIS)]
    pub config: Option<PathBuf>,
}

/// The options that choose a collection's diagnosis, which a saved one (`--config`)
/// already holds.
const CHOOSES_THE_DIAGNOSIS: [&str; 34] = [
    "data",
    "model",
    "loss",
    "weights",
    "optimizer",
    "restarts",
    "seed",
    "alpha",
    "max_steps",
    "factors_past_max_steps",
    "bootstrap",
    "bootstrap_max",
    "calibrate_all",
    "bootstrap_restarts",
    "backend",
    "json",
    "report",
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
    "no_backtrack",
    "parallel",
    "explore",
    "out",
    "emit_slurm",
    "slurm_cpus",
    "no_pictures",
];

impl DiagnoseArgs {
    /// The diagnosis these arguments ask for (the loss and weighting words read, the
    /// constraints given).
    fn request(&self, constraints: ConstraintSpec) -> Result<DiagnoseRequest> {
        Ok(DiagnoseRequest {
            model: self.model.clone().unwrap_or_default(),
            loss: parse_metric(&self.loss)?,
            weights: parse_weights(&self.weights)?,
            options: self.options(constraints),
        })
    }

    /// The diagnosis options these arguments ask for but the loss, which the request's
    /// preparation sets once it is checked against the data.
    fn options(&self, constraints: ConstraintSpec) -> DiagnoseOptions {
        DiagnoseOptions {
            optimizer: self.optimizer,
            restarts: self.restarts,
            seed: self.seed,
            alpha: self.alpha,
            max_steps: self.max_steps,
            factors_past_max_steps: self.factors_past_max_steps,
            parallel: self.parallel,
            backtrack: !self.no_backtrack,
            bootstrap: BootstrapOptions {
                replicates: self.bootstrap,
                max_replicates: self.bootstrap_max,
                restarts: self.bootstrap_restarts,
                seed: self.seed,
            },
            calibrate_all: self.calibrate_all,
            constraints,
            explore: self.explore,
            ..Default::default()
        }
    }
}

impl DiagnoseArgs {
    /// Whether these arguments ask for a collection (several data sets, a folder, --out or
    /// the options only a collection has).
    fn is_collection(&self) -> bool {
        self.data.len() > 1
            || self.data.iter().any(|d| d.is_dir())
            || self.out.is_some()
            || self.config.is_some()
            || self.shard.is_some()
            || self.emit_slurm.is_some()
    }

    /// The collection these arguments ask for.
    fn collection(&self) -> Result<CollectionConfig> {
        let shard = self.shard.as_deref().map(Shard::parse).transpose()?;
        if let Some(path) = &self.config {
            return Ok(CollectionConfig {
                shard,
                ..CollectionConfig::load(path)?
            });
        }
        for (given, option) in [
            (self.json.is_some(), "--json"),
            (self.report.is_some(), "--report"),
        ] {
            anyhow::ensure!(
                !given,
                "{option} writes one data set's diagnosis; a collection writes DIR/diagnoses.json and DIR/diagnoses/NAME/ (give --out DIR)"
            );
        }
        let out = self.out.clone().ok_or_else(|| {
            anyhow::anyhow!(
                "diagnosing several data sets (or a folder) needs --out DIR, the collection's folder"
            )
        })?;
        Ok(CollectionConfig {
            data: self.data.clone(),
            read: self.data_args.read_options()?,
            request: self.request(self.constraints.spec(true)?)?,
            backend: self.backend.backend,
            out,
            pictures: !self.no_pictures,
            shard,
        })
    }
}

/// `bsdfit diagnose` over a collection: run it, or write its Slurm job scripts. Fails at
/// the end (after writing every table) when a data set failed.
fn run_collection(a: &DiagnoseArgs) -> Result<()> {
    let cfg = a.collection()?;
    let mut console = ConsoleObserver::counting("diagnose", "data sets");
    if let Some(tasks) = a.emit_slurm {
        return collection::emit_slurm(&cfg, tasks, a.slurm_cpus, None, &mut console);
    }
    let stats = collection::run(&cfg, &mut console)?;
    for r in collection::record::sorted(&stats.cells) {
        match r.status {
            CellStatus::Done => println!(
                "{}\t{}\t{} → {}\t{}",
                r.data,
                r.final_model.as_deref().unwrap_or(""),
                r.start_chi2_red.map_or("–".into(), |c| format!("{c:.3}")),
                r.final_chi2_red.map_or("–".into(), |c| format!("{c:.3}")),
                if r.effects.is_empty() {
                    "none".into()
                } else {
                    r.effects.join(", ")
                }
            ),
            CellStatus::Failed => {
                println!("{}\tfailed: {}", r.data, r.error.as_deref().unwrap_or(""))
            }
        }
    }
    anyhow::ensure!(
        stats.failed.is_empty(),
        "{} of this run failed: {} (their errors are in {})",
        plural(stats.failed.len(), "data set"),
        stats.failed.join(", "),
        stats.out.join(collection::record::DIAGNOSES_CSV).display()
    );
    Ok(())
}

pub fn run(a: &DiagnoseArgs) -> Result<()> {
    if a.is_collection() {
        return run_collection(a);
    }
    let path = &a.data[0];
    if let Some(path) = &a.json {
        crate::output::check_writable_file(path, "--json")?;
    }
    if let Some(dir) = &a.report {
        crate::output::check_writable_dir(dir, "--report")?;
    }
    let data = a.data_args.read(path)?;
    let request = a.request(a.constraints.spec(true)?)?;
    let opts = request.prepare(&data, &mut |w| eprintln!("{w}"))?;
    let backend = engine::select(a.backend.backend, &mut |m| eprintln!("{m}"))?;
    println!(
        "diagnose {} ({}, {}, {}) from {}",
        data.material,
        plural(data.len(), "sample"),
        plural(data.channel_count(), "channel"),
        plural(data.axes.len(), "plane"),
        request.model
    );
    let mut progress = Progress::new("diagnose", 0, "");
    progress.set_message(format!("fitting {}", request.model));
    let d = diagnose(
        &data,
        &request.model,
        backend.as_ref(),
        &opts,
        &mut |line| {
            // The latest step or candidate line is what the periodic progress line repeats.
            if let Some(head) = line.split(" — ").next().filter(|h| !h.trim().is_empty()) {
                progress.set_message(progress_message(head));
            }
            progress.suspend(|| println!("{line}"))
        },
    )?;
    progress.finish();
    println!(
        "effects: {}\nfinal model: {}",
        if d.effects.is_empty() {
            "none".to_string()
        } else {
            d.effects
                .iter()
                .map(|e| e.name())
                .collect::<Vec<_>>()
                .join(", ")
        },
        d.final_model
    );
    println!(
        "χ²_red: {}",
        d.steps
            .iter()
            .map(|s| format!("{:.3}", s.chi2_red))
            .collect::<Vec<_>>()
            .join(" → ")
    );
    if let Some(path) = &a.json {
        let text = serde_json::to_string_pretty(&d.to_json())? + "\n";
        crate::output::files::write_result(path, &text, true)?;
        eprintln!("wrote {}", path.display());
    }
    if let Some(dir) = &a.report {
        write_report(dir, &data, &d)?;
        eprintln!("wrote {}", dir.join("index.html").display());
    }
    Ok(())
}

/// A log line's head as the periodic progress line repeats it: without its parenthesised
/// details (a bootstrap's planned replicates) and at most 72 characters, cut at a word
/// with an ellipsis rather than mid-phrase.
fn progress_message(head: &str) -> String {
    let head = head.trim();
    let head = head.split(" (").next().unwrap_or(head);
    const MOST: usize = 72;
    if head.chars().count() <= MOST {
        return head.to_string();
    }
    let cut: String = head.chars().take(MOST).collect();
    let cut = cut.rsplit_once(' ').map_or(cut.as_str(), |(a, _)| a);
    format!("{cut}…")
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    /// `--config` runs a saved collection: every option that chooses the diagnosis
    /// conflicts with it, so none is silently ignored (only --shard may be given).
    #[test]
    fn config_conflicts_with_every_option_that_chooses_the_diagnosis() {
        use clap::CommandFactory;
        let cli = super::super::Cli::command();
        let diagnose = cli.find_subcommand("diagnose").expect("diagnose");
        let left: Vec<String> = diagnose
            .get_arguments()
            .map(|a| a.get_id().to_string())
            .filter(|id| !["config", "shard", "help"].contains(&id.as_str()))
            .filter(|id| !CHOOSES_THE_DIAGNOSIS.contains(&id.as_str()))
            .collect();
        assert!(left.is_empty(), "not in CHOOSES_THE_DIAGNOSIS: {left:?}");
    }

    /// `bsdfit diagnose` without options asks for the library's default diagnosis: the
    /// command line writes no default of its own.
    #[test]
    fn cli_defaults_are_the_library_defaults() {
        let cli =
            super::super::Cli::try_parse_from(["bsdfit", "diagnose", "d.csv", "--model", "on"])
                .expect("parses");
        let super::super::Command::Diagnose(a) = cli.command else {
            panic!("not diagnose");
        };
        let library = DiagnoseRequest {
            model: "on".into(),
            ..DiagnoseRequest::default()
        };
        let cli = a
            .request(library.options.constraints.clone())
            .expect("parses");
        assert_eq!(format!("{cli:?}"), format!("{library:?}"));
    }

    /// The progress line keeps a log line's words whole: no parenthesised details, no
    /// phrase cut in its middle (it once read "… replicates drawn from )").
    #[test]
    fn progress_messages_are_whole_words() {
        let bootstrap = "    bootstrap: refitting rmg(vmf)+coat to replicates drawn from its fit (planned 199, at most 799)";
        assert_eq!(
            progress_message(bootstrap),
            "bootstrap: refitting rmg(vmf)+coat to replicates drawn from its fit"
        );
        assert_eq!(
            progress_message("step 2: fa(lambert)+coat "),
            "step 2: fa(lambert)+coat"
        );
        let long = format!("fitting {}", "word ".repeat(30));
        let m = progress_message(&long);
        assert!(m.ends_with("word…") && m.chars().count() <= 73, "{m}");
    }
}
