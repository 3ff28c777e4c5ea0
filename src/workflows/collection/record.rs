//! One data set's outcome in a collection ([`CellRecord`]) and the collection's tables,
//! `diagnoses.csv` and `diagnoses.json` (docs/output.md).

use super::Listed;
use crate::data::Dataset;
use crate::output::files::write_if_changed;
use crate::workflows::diagnose::Diagnosis;
use anyhow::Result;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// The collection's table as CSV, one row per data set.
pub const DIAGNOSES_CSV: &str = "diagnoses.csv";
/// The collection's table as JSON: every cell's record.
pub const DIAGNOSES_JSON: &str = "diagnoses.json";

/// Whether a cell's diagnosis ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CellStatus {
    Done,
    /// Unreadable, refused by the checks, or stopped by an error: `error` says which.
    Failed,
}

/// One step of a data set's path: the model adopted, the effect it adds, its fit, and
/// the test that adopted it in the round before.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RoundRecord {
    pub model: String,
    /// None for the start model.
    pub effect: Option<String>,
    pub chi2_red: Option<f64>,
    /// The test behind the p-value: `F`, `bootstrap`, `F_nominal` (None at the start or
    /// where the step was not a nested extension).
    pub test: Option<String>,
    #[serde(rename = "F")]
    pub f: Option<f64>,
    pub p: Option<f64>,
    /// Seconds of the round that adopted it (the start fit's for the start model).
    pub seconds: Option<f64>,
}

/// A fitted parameter of the final model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParamRecord {
    pub name: String,
    pub value: Option<f64>,
    /// Standard uncertainty (None where the data leave it undetermined).
    pub std: Option<f64>,
}

/// One cell of a collection: a data set's diagnosis, or the error that stopped it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CellRecord {
    /// The cell's name (its file's, made unique in the collection).
    pub data: String,
    pub path: String,
    /// The key of the bytes read (None: the file could not be read).
    pub hash: Option<String>,
    pub status: CellStatus,
    pub error: Option<String>,
    pub material: Option<String>,
    pub samples: usize,
    pub channels: usize,
    pub start_model: String,
    pub start_chi2_red: Option<f64>,
    pub final_model: Option<String>,
    pub final_chi2_red: Option<f64>,
    /// P(χ² ≥ observed) of the final fit: consistent with the uncertainties above the level.
    pub final_p_consistent: Option<f64>,
    pub effects: Vec<String>,
    pub rounds: Vec<RoundRecord>,
    pub params: Vec<ParamRecord>,
    /// Why the path ended, in words.
    pub stop: Option<String>,
    pub backend: Option<String>,
    /// Wall-clock seconds of the cell.
    pub seconds: f64,
}

/// A finite number, or None (JSON has no NaN).
fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

impl CellRecord {
    /// The record of a data set that could not be diagnosed.
    pub fn failed(
        l: &Listed,
        hash: Option<String>,
        start_model: &str,
        error: String,
        seconds: f64,
    ) -> CellRecord {
        CellRecord {
            data: l.name.clone(),
            path: l.path.display().to_string(),
            hash,
            status: CellStatus::Failed,
            error: Some(error),
            material: None,
            samples: 0,
            channels: 0,
            start_model: start_model.to_string(),
            start_chi2_red: None,
            final_model: None,
            final_chi2_red: None,
            final_p_consistent: None,
            effects: Vec::new(),
            rounds: Vec::new(),
            params: Vec::new(),
            stop: None,
            backend: None,
            seconds,
        }
    }

    /// The record of a finished diagnosis of `data`, the bytes keyed `hash` (its seconds
    /// are the caller's).
    pub fn of_diagnosis(
        l: &Listed,
        hash: Option<String>,
        data: &Dataset,
        d: &Diagnosis,
        max_steps: usize,
    ) -> CellRecord {
        let rounds = d
            .steps
            .iter()
            .enumerate()
            .map(|(k, s)| {
                // The candidate of the round before that became this step.
                let before = k.checked_sub(1).map(|j| &d.steps[j]);
                let adopted = before.and_then(|b| {
                    b.candidates
                        .iter()
                        .find(|c| c.candidate.spec == s.model && c.fit.is_some())
                });
                RoundRecord {
                    model: s.model.clone(),
                    effect: s.effect.map(|e| e.name().to_string()),
                    chi2_red: finite(s.chi2_red),
                    test: adopted
                        .and_then(|c| c.p_test.to_json().get("test").cloned())
                        .and_then(|t| t.as_str().map(str::to_string)),
                    f: adopted.and_then(|c| c.f).and_then(finite),
                    p: adopted.and_then(|c| c.p).and_then(finite),
                    seconds: match before {
                        None => finite(s.fit.seconds),
                        Some(b) => b
                            .round_seconds
                            .map(|r| r.fits + r.scoring + r.bootstraps)
                            .and_then(finite),
                    },
                }
            })
            .collect();
        let last = d.steps.last().expect("a diagnosis has its start step");
        let params = last
            .fit
            .model
            .flat_names()
            .into_iter()
            .enumerate()
            .map(|(i, name)| ParamRecord {
                name,
                value: last.fit.flat.get(i).copied().and_then(finite),
                std: last.fit.cov.std.get(i).copied().flatten().and_then(finite),
            })
            .collect();
        let p = last.fit.p_consistent();
        // Effects the path adopted (a backward elimination's last step adds none).
        let adopted = d.steps.iter().filter(|s| s.effect.is_some()).count();
        // The headline first: consistent, else the path's own words for its end.
        let stop = match last.evidence.rsplit_once("Stopped: ") {
            _ if p >= d.alpha => format!("consistent with the uncertainties (p = {p:.3})"),
            Some((_, why)) => why.trim().to_string(),
            None if adopted > max_steps => {
                format!("reached the most effects ({max_steps}) and the factors past them")
            }
            None if adopted == max_steps => format!("reached the most effects ({max_steps})"),
            None => "no significant extension left".to_string(),
        };
        CellRecord {
            data: l.name.clone(),
            path: l.path.display().to_string(),
            hash,
            status: CellStatus::Done,
            error: None,
            material: Some(data.material.clone()),
            samples: data.len(),
            channels: data.channel_count(),
            start_model: d.start_model.clone(),
            start_chi2_red: d.steps.first().and_then(|s| finite(s.chi2_red)),
            final_model: Some(d.final_model.clone()),
            final_chi2_red: finite(last.chi2_red),
            final_p_consistent: finite(p),
            effects: d.effects.iter().map(|e| e.name().to_string()).collect(),
            rounds,
            params,
            stop: Some(stop),
            backend: Some(d.backend.clone()),
            seconds: 0.0,
        }
    }
}

/// The cells in the table's order: by final χ²_red, worst first (failed cells last, by
/// name), so the data sets the collection's models fit least well lead.
pub fn sorted(cells: &[CellRecord]) -> Vec<&CellRecord> {
    let mut v: Vec<&CellRecord> = cells.iter().collect();
    v.sort_by(|a, b| {
        let key = |r: &CellRecord| r.final_chi2_red.unwrap_or(f64::NEG_INFINITY);
        key(b).total_cmp(&key(a)).then_with(|| a.data.cmp(&b.data))
    });
    v
}

/// A number for the CSV (empty where there is none).
fn num(x: Option<f64>) -> String {
    x.map(|v| format!("{v}")).unwrap_or_default()
}

/// A round in one CSV cell: `model [effect] χ²_red=… test p=… s`.
fn round_text(r: &RoundRecord) -> String {
    let mut t = r.model.clone();
    if let Some(e) = &r.effect {
        t.push_str(&format!(" [{e}]"));
    }
    if let Some(c) = r.chi2_red {
        t.push_str(&format!(" chi2_red={c:.4}"));
    }
    if let (Some(test), Some(p)) = (&r.test, r.p) {
        t.push_str(&format!(" {test} p={p:.3e}"));
    }
    if let Some(s) = r.seconds {
        t.push_str(&format!(" {s:.1}s"));
    }
    t
}

/// The CSV table's text.
pub fn csv_text(cells: &[CellRecord]) -> Result<String> {
    let mut w = csv::Writer::from_writer(Vec::new());
    w.write_record([
        "data",
        "status",
        "material",
        "samples",
        "channels",
        "start_model",
        "start_chi2_red",
        "final_model",
        "final_chi2_red",
        "final_p_consistent",
        "effects",
        "rounds",
        "params",
        "stop",
        "seconds",
        "path",
        "error",
    ])?;
    for r in sorted(cells) {
        let params = r
            .params
            .iter()
            .map(|p| match (p.value, p.std) {
                (Some(v), Some(s)) => format!("{}={v}±{s}", p.name),
                (Some(v), None) => format!("{}={v}±?", p.name),
                _ => format!("{}=?", p.name),
            })
            .collect::<Vec<_>>()
            .join("; ");
        w.write_record([
            r.data.clone(),
            serde_json::to_value(r.status)?
                .as_str()
                .unwrap_or("")
                .to_string(),
            r.material.clone().unwrap_or_default(),
            r.samples.to_string(),
            r.channels.to_string(),
            r.start_model.clone(),
            num(r.start_chi2_red),
            r.final_model.clone().unwrap_or_default(),
            num(r.final_chi2_red),
            num(r.final_p_consistent),
            r.effects.join(";"),
            r.rounds
                .iter()
                .map(round_text)
                .collect::<Vec<_>>()
                .join(" | "),
            params,
            r.stop.clone().unwrap_or_default(),
            format!("{:.2}", r.seconds),
            r.path.clone(),
            r.error.clone().unwrap_or_default(),
        ])?;
    }
    Ok(String::from_utf8(w.into_inner()?)?)
}

/// Write `diagnoses.csv` and `diagnoses.json` into `out` (only where a byte changes).
pub fn write_tables(out: &Path, cells: &[CellRecord]) -> Result<()> {
    write_if_changed(&out.join(DIAGNOSES_CSV), &csv_text(cells)?)?;
    let json: Vec<&CellRecord> = sorted(cells);
    write_if_changed(
        &out.join(DIAGNOSES_JSON),
        &(serde_json::to_string_pretty(&json)? + "\n"),
    )?;
    Ok(())
}
