//! The diagnosis's native calls: one data set (`bsdfit.diagnose`) and a collection
//! (`bsdfit.diagnose_many`), both through the library's `DiagnoseRequest`.

use super::*;
use bsdfit::workflows::collection::{CellRecord, Listed};

#[pyfunction]
pub(crate) fn diagnose_defaults(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = diagnose::DiagnoseOptions::default();
    let dict = PyDict::new(py);
    dict.set_item("loss", d.loss.metric.to_string())?;
    dict.set_item("weights", d.loss.weights.to_string())?;
    dict.set_item("optimizer", d.optimizer.to_string())?;
    dict.set_item("restarts", d.restarts)?;
    dict.set_item("seed", d.seed)?;
    dict.set_item("alpha", d.alpha)?;
    dict.set_item("max_steps", d.max_steps)?;
    dict.set_item("factors_past_max_steps", d.factors_past_max_steps)?;
    dict.set_item("bootstrap", d.bootstrap.replicates)?;
    dict.set_item("bootstrap_max", d.bootstrap.max_replicates)?;
    dict.set_item("bootstrap_restarts", d.bootstrap.restarts)?;
    dict.set_item("calibrate_all", d.calibrate_all)?;
    dict.set_item("backtrack", d.backtrack)?;
    dict.set_item("explore", d.explore)?;
    Ok(dict)
}

/// A diagnosis as `bsdfit.diagnose` asks for it: the library's request (what the command
/// line builds from its flags) and the backend, read once from the keyword arguments.
struct PyDiagnoseRequest {
    request: diagnose::DiagnoseRequest,
    backend: String,
}

impl PyDiagnoseRequest {
    /// The request of a dict keyed by `bsdfit.diagnose`'s keywords (values already of
    /// their types) for the start `model`; a keyword left out takes the library's default.
    fn of_dict(model: String, dict: &Bound<'_, PyDict>) -> PyResult<PyDiagnoseRequest> {
        let mut o = diagnose::DiagnoseOptions::default();
        let mut loss = o.loss.metric.to_string();
        let mut weights = o.loss.weights.to_string();
        let mut optimizer = o.optimizer.to_string();
        let mut backend = BackendChoice::Auto.to_string();
        let (mut fix, mut bounds, mut prior) = (Vec::new(), Vec::new(), Vec::new());
        for (key, value) in dict.iter() {
            let key: String = key.extract()?;
            match key.as_str() {
                "loss" => loss = value.extract()?,
                "weights" => weights = value.extract()?,
                "optimizer" => optimizer = value.extract()?,
                "backend" => backend = value.extract()?,
                "restarts" => o.restarts = value.extract()?,
                "seed" => o.seed = value.extract()?,
                "alpha" => o.alpha = value.extract()?,
                "max_steps" => o.max_steps = value.extract()?,
                "factors_past_max_steps" => o.factors_past_max_steps = value.extract()?,
                "bootstrap" => o.bootstrap.replicates = value.extract()?,
                "bootstrap_max" => o.bootstrap.max_replicates = value.extract()?,
                "bootstrap_restarts" => o.bootstrap.restarts = value.extract()?,
                "calibrate_all" => o.calibrate_all = value.extract()?,
                "backtrack" => o.backtrack = value.extract()?,
                "explore" => o.explore = value.extract()?,
                "fix" => fix = value.extract()?,
                "bounds" => bounds = value.extract()?,
                "prior" => prior = value.extract()?,
                _ => {
                    return Err(PyValueError::new_err(format!(
                        "diagnose: no option '{key}'"
                    )))
                }
            }
        }
        o.bootstrap.seed = o.seed;
        o.constraints = constraint_spec(fix, bounds, prior, true).map_err(to_py)?;
        o.optimizer = parse_choice("optimizer", &optimizer).map_err(to_py)?;
        let (loss, weights) = loss_words(&loss, &weights).map_err(to_py)?;
        Ok(PyDiagnoseRequest {
            request: diagnose::DiagnoseRequest {
                model,
                loss,
                weights,
                options: o,
            },
            backend,
        })
    }
}

/// Diagnose a dataset from a start model: the JSON text `bsdfit diagnose --json` writes,
/// the warnings the command line prints on stderr, and the diagnosis as a collection's
/// cell records it (JSON: rounds with their tests and seconds, the final parameters with
/// their uncertainties, why it stopped). `options`: `bsdfit.diagnose`'s
/// keyword arguments (see [`PyDiagnoseRequest::of_dict`]). `progress` (a callable or None)
/// hears each line the command line prints as the path is searched.
#[pyfunction]
#[pyo3(signature = (dataset, model, options, progress))]
pub(crate) fn diagnose_json(
    py: Python<'_>,
    dataset: &NativeDataset,
    model: String,
    options: &Bound<'_, PyDict>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(String, Vec<String>, String)> {
    let data = dataset.data.clone();
    let PyDiagnoseRequest { request, backend } = PyDiagnoseRequest::of_dict(model, options)?;
    let mut reporter = Reporter::new(progress);
    let (text, notes, record, reporter) = compute(py, move || {
        let t0 = std::time::Instant::now();
        let mut notes = Vec::new();
        let options = request.prepare(&data, &mut |w| notes.push(w))?;
        let backend = engine::select(backend_choice(&backend)?, &mut |_| {})?;
        let mut lines = 0;
        let model = &request.model;
        let d = diagnose::diagnose(&data, model, backend.as_ref(), &options, &mut |line| {
            lines += 1;
            reporter.send("diagnose", lines, None, &line);
        })?;
        let listed = Listed {
            name: data.material.clone(),
            path: data.source.clone(),
        };
        let mut record = CellRecord::of_diagnosis(&listed, None, &data, &d, options.max_steps);
        record.seconds = t0.elapsed().as_secs_f64();
        let record = serde_json::to_string(&record)?;
        Ok((
            serde_json::to_string(&d.to_json())?,
            notes,
            record,
            reporter,
        ))
    })?;
    reporter.finish((text, notes, record))
}

/// Diagnose a collection of data files or folders into `out` (what `bsdfit diagnose
/// FILE|DIR… --out DIR` does): the collection's table (`diagnoses.json`, every cell's
/// record, as JSON text) and the names of this run's cells that failed. With
/// `emit_slurm`, write the job scripts instead (`diagnose --emit-slurm`), which run
/// `slurm_binary`, and return an empty table.
#[pyfunction]
#[pyo3(signature = (paths, out, model, options, wavelengths, assume_uncertainty, max_samples, shard, pictures, progress, emit_slurm, slurm_cpus, slurm_binary))]
pub(crate) fn diagnose_many(
    py: Python<'_>,
    paths: Vec<PathBuf>,
    out: PathBuf,
    model: String,
    options: &Bound<'_, PyDict>,
    wavelengths: Option<Vec<f64>>,
    assume_uncertainty: Option<AssumeUncertainty>,
    max_samples: Option<usize>,
    shard: Option<String>,
    pictures: bool,
    progress: Option<Py<PyAny>>,
    emit_slurm: Option<usize>,
    slurm_cpus: usize,
    slurm_binary: Option<PathBuf>,
) -> PyResult<(String, Vec<String>)> {
    use bsdfit::workflows::collection::{self, CollectionConfig};
    use bsdfit::workflows::sweep::Shard;
    let PyDiagnoseRequest { request, backend } = PyDiagnoseRequest::of_dict(model, options)?;
    let (table, observer) = compute(py, move || {
        let cfg = CollectionConfig {
            data: paths,
            read: read_options(
                wavelengths,
                None,
                max_samples,
                assume_uncertainty,
                false,
                None,
                None,
            )?,
            request,
            backend: backend_choice(&backend)?,
            out,
            pictures,
            shard: shard.as_deref().map(Shard::parse).transpose()?,
        };
        let mut observer = SweepReporter {
            reporter: Reporter::new(progress),
            stage: "diagnose_many",
            done: 0,
            total: 0,
        };
        let table = match emit_slurm {
            Some(tasks) => {
                let binary = slurm_binary.as_deref();
                collection::emit_slurm(&cfg, tasks, slurm_cpus, binary, &mut observer)?;
                (String::from("[]"), Vec::new())
            }
            None => {
                let stats = collection::run(&cfg, &mut observer)?;
                let sorted = collection::record::sorted(&stats.cells);
                (serde_json::to_string(&sorted)?, stats.failed)
            }
        };
        Ok((table, observer))
    })?;
    observer.reporter.finish(table)
}
