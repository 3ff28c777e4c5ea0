//! `bsdfit sweep` and `bsdfit merge`: the benchmark as users run it.
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
//! `report.html` ([`crate::output::report`]).

pub mod lock;
pub mod merge;
pub mod pool;
pub mod run;
pub mod slurm;

pub use merge::{merge, MergeConfig};
pub use run::{run, Shard, SweepConfig, SweepObserver, SweepStats};

use crate::bsdf;
use crate::choice::field_error;
use crate::data::Kind;
use crate::engine::loss::{Loss, Metric, Weights};
use crate::inference::fit::Optimizer;
use crate::output::results::{write_if_changed, DataFile, FitKey, Row, Skipped, SKIPPED_JSON};
use anyhow::{Context, Result};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// Expand files and directories (their *.csv, sorted) into a list of data files.
pub fn expand_data(paths: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let paths: Vec<PathBuf> = if paths.is_empty() {
        vec![crate::data::bundled_data_dir()]
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
    let word = s.replace(['{', '}'], "");
    let bad = |why: &str| field_error(format!("{{shard}} '{word}': {why}"));
    let (i, n) = s
        .split_once('/')
        .ok_or_else(|| bad("expected I/N, e.g. 1/2"))?;
    let (i, n): (usize, usize) = (
        i.trim()
            .parse()
            .map_err(|_| bad("I is not a whole number"))?,
        n.trim()
            .parse()
            .map_err(|_| bad("N is not a whole number"))?,
    );
    if !(n >= 1 && (1..=n).contains(&i)) {
        return Err(bad("need 1 ≤ I ≤ N"));
    }
    Ok((i, n))
}

fn parse_weights(w: &str, kind: Kind) -> Result<Weights> {
    if w.trim().eq_ignore_ascii_case("unc") {
        return Ok(Weights::uncertainty_for(kind));
    }
    w.parse()
        .map_err(|e: String| field_error(format!("{{weights}}: {}", e.replace(['{', '}'], ""))))
}

/// What a sweep runs on each data set; `None` means the default for the data's kind.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct Selection {
    pub models: Option<Vec<String>>,
    pub losses: Option<Vec<String>>,
    pub weights: Option<Vec<String>>,
    /// `auto`, `lm` or `compass`, each at most once.
    pub optimizer: Vec<String>,
}

/// Every task of a sweep, in a deterministic order: data files as given, then models,
/// losses, weightings, optimizers as listed.
pub fn tasks(files: &[DataFile], args: &Selection) -> Result<Vec<Task>> {
    let mut out = Vec::new();
    for (di, f) in files.iter().enumerate() {
        let kind = f.data.kind;
        let models: Vec<String> = match &args.models {
            Some(list) => list
                .iter()
                .map(|s| s.trim().to_string())
                // A spec that does not parse is kept for every kind: its fit is then
                // skipped with the parser's reason.
                .filter(|s| {
                    !s.is_empty() && bsdf::spec_kind(s).is_ok_and(|k| k == kind)
                        || bsdf::spec_kind(s).is_err()
                })
                .collect(),
            // Data measured on several φ planes (anisotropic diffusers) also gets the
            // catalogue's per-plane variants.
            None => bsdf::catalogue_for(kind, f.data.axes.len()),
        };
        let losses: Vec<Metric> = match &args.losses {
            Some(list) => {
                let mut v = Vec::new();
                for l in list {
                    let m: Metric = l.parse().map_err(|e: String| {
                        field_error(format!("{{losses}}: {}", e.replace(['{', '}'], "")))
                    })?;
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
                            other => {
                                return Err(field_error(format!(
                                    "{{optimizer}}: unknown '{}' (auto, lm, compass)",
                                    other.replace(['{', '}'], "")
                                )))
                            }
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

/// skipped.json: this run's skipped/failed tasks, plus earlier ones that still have no row.
pub fn write_skipped(out: &Path, now: &[Skipped], rows: &[Row], files: &[DataFile]) -> Result<()> {
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

/// The skipped.json entry of a task.
pub fn skipped_entry(f: &DataFile, t: &Task, status: &str, reason: String) -> Skipped {
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
