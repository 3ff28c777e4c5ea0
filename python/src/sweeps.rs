//! The sweep's and the battery's native calls (`bsdfit.sweep`, `bsdfit.battery`).

use super::*;

/// Run a sweep over data files or folders into `out` (what `bsdfit sweep` does); the
/// number of fits it added. `progress` (a callable or None) hears of each fit as it ends,
/// and of the lines the command line prints. With `emit_slurm`, write the sweep's Slurm
/// job scripts instead (`sweep --emit-slurm`), which run `slurm_binary`.
#[pyfunction]
#[pyo3(signature = (paths, out, models, losses, weights, restarts, seed, backend, pictures, shard, assume_uncertainty, progress, emit_slurm, slurm_cpus, slurm_binary))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn sweep(
    py: Python<'_>,
    paths: Vec<PathBuf>,
    out: PathBuf,
    models: Option<Vec<String>>,
    losses: Option<Vec<String>>,
    weights: Option<Vec<String>>,
    restarts: usize,
    seed: u64,
    backend: String,
    pictures: bool,
    shard: Option<String>,
    assume_uncertainty: Option<AssumeUncertainty>,
    progress: Option<Py<PyAny>>,
    emit_slurm: Option<usize>,
    slurm_cpus: usize,
    slurm_binary: Option<PathBuf>,
) -> PyResult<usize> {
    use bsdfit::workflows::sweep::{self, Selection, Shard, SweepConfig};
    let (added, observer) = compute(py, move || {
        let defaults = SweepConfig::default();
        let cfg = SweepConfig {
            data: paths,
            read: read_options(None, None, None, assume_uncertainty, false, None, None)?,
            selection: Selection {
                models,
                losses,
                weights,
                ..defaults.selection.clone()
            },
            restarts,
            seed,
            backend: backend_choice(&backend)?,
            out,
            shard: shard.as_deref().map(Shard::parse).transpose()?,
            pictures,
            ..defaults
        };
        let mut observer = SweepReporter {
            reporter: Reporter::new(progress),
            stage: "sweep",
            done: 0,
            total: 0,
        };
        let added = match emit_slurm {
            Some(tasks) => {
                let binary = slurm_binary.as_deref();
                sweep::slurm::emit(&cfg, tasks, slurm_cpus, binary, &mut observer)?;
                0
            }
            None => sweep::run(&cfg, &mut observer)?.new_fits,
        };
        Ok((added, observer))
    })?;
    observer.reporter.finish(added)
}

/// The keywords of `bsdfit.battery` and their defaults, the library's
/// (`BatteryOptions::default()`), for its signature.
#[pyfunction]
pub(crate) fn battery_defaults(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = bsdfit::workflows::diagnose::battery::BatteryOptions::default();
    let dict = PyDict::new(py);
    dict.set_item("cases", d.cases)?;
    dict.set_item("nulls", d.nulls)?;
    dict.set_item("misspecified", d.misspecified)?;
    dict.set_item("misspecified_btdf", d.misspecified_btdf)?;
    dict.set_item("seed", d.seed)?;
    dict.set_item("signal", d.signal)?;
    dict.set_item("samples", d.samples)?;
    dict.set_item("restarts", d.diagnose.restarts)?;
    dict.set_item("data_driven", d.diagnose.data_driven)?;
    Ok(dict)
}

/// Run the diagnosis's randomized battery (what `bsdfit battery` does): every case and
/// its outcome as the JSON text `battery --json` writes, and the rates table (markdown)
/// the command line prints. `progress` (a callable or None) hears of each case as it
/// ends (stage `battery`).
#[pyfunction]
#[pyo3(signature = (cases, nulls, misspecified, misspecified_btdf, seed, effects, signal, samples, restarts, backend, case, data_driven, progress))]
pub(crate) fn battery(
    py: Python<'_>,
    cases: usize,
    nulls: usize,
    misspecified: usize,
    misspecified_btdf: usize,
    seed: u64,
    effects: Option<Vec<String>>,
    signal: (f64, f64),
    samples: (usize, usize),
    restarts: usize,
    backend: String,
    case: Option<usize>,
    data_driven: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<(String, String)> {
    use bsdfit::workflows::diagnose::battery::{
        effects_named, rates_table, run_battery, BatteryOptions,
    };
    let mut reporter = Reporter::new(progress);
    let (text, table, reporter) = compute(py, move || {
        let defaults = BatteryOptions::default();
        let opts = BatteryOptions {
            cases,
            nulls,
            misspecified,
            misspecified_btdf,
            seed,
            effects: match effects {
                None => defaults.effects.clone(),
                Some(names) => effects_named(&names)?,
            },
            signal,
            samples,
            diagnose: diagnose::DiagnoseOptions {
                restarts,
                seed,
                data_driven,
                ..defaults.diagnose.clone()
            },
            only: case,
        };
        opts.check()?;
        let backend = engine::select(backend_choice(&backend)?, &mut |_| {})?;
        let total = opts.total() as u64;
        let mut done = 0;
        reporter.send("battery", 0, Some(total), "");
        let outcomes = run_battery(&opts, backend.as_ref(), &mut |o| {
            done += 1;
            let what = format!(
                "case {} {} → {}",
                o.case.id,
                o.case.hidden.as_deref().unwrap_or("none"),
                o.final_model
            );
            reporter.send("battery", done, Some(total), &what);
        });
        Ok((
            serde_json::to_string(&outcomes)?,
            rates_table(&outcomes),
            reporter,
        ))
    })?;
    reporter.finish((text, table))
}
