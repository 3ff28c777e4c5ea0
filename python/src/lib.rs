//! `bsdfit._bsdfit`: the native half of the Python module. It calls the library the way the
//! command line does (the same request types, defaults and checks), so the same data and
//! seed give the same numbers. The Pythonic surface (keyword arguments, numpy broadcasting,
//! the `Fit` object) lives in `bsdfit/__init__.py`; this file only moves data across.
//!
//! Every call that computes releases the GIL, and every error comes back as a Python
//! exception carrying the command line's message: `OSError` (or its subclass for the
//! cause: `FileNotFoundError`, `PermissionError`, `IsADirectoryError`) when a file cannot
//! be read, `ValueError` for bad input, `RuntimeError` for a bug (a panic is caught here
//! and never crosses into Python). The arguments' Python types and ranges are checked in
//! `bsdfit/__init__.py`, before they get here.

// Each function takes the keyword arguments of its Python call, one Rust argument each.
#![allow(clippy::too_many_arguments)]

mod console;
mod diagnosis;
mod sweeps;

use bsdfit::choice::{Choice, ChoiceError};
use bsdfit::data::readers::{self, alta::AltaValues};
use bsdfit::data::{AssumeArg, Dataset, Kind, RawRow, ReadOptions, ReadRequest};
use bsdfit::engine::loss::{Metric, Weights};
use bsdfit::engine::{self, BackendChoice};
use bsdfit::inference::constraints::{Constraint, ConstraintKind, ConstraintSpec};
use bsdfit::inference::fit::{FitReport, Optimizer};
use bsdfit::inference::saved::FitFile;
use bsdfit::workflows::{diagnose, export, fit};
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::exceptions::{
    PyFileNotFoundError, PyIsADirectoryError, PyOSError, PyPermissionError, PyRuntimeError,
    PyValueError,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::sync::Arc;

/// The value a keyword argument's word names (`lm`, `brdf-cos`, …), from the library's
/// table of words; the message names the argument and lists the words.
fn parse_choice<T: Choice>(what: &str, s: &str) -> anyhow::Result<T> {
    T::parse_choice(s).map_err(|e| {
        let e = ChoiceError { what: "", ..e };
        anyhow::anyhow!("{what}{e}")
    })
}

/// An error as Python sees it: `OSError` when a file could not be read or written (the
/// subclass Python's own `open` would raise for the cause), `ValueError` otherwise, with
/// the whole chain of causes as the command line prints it.
fn to_py(e: anyhow::Error) -> PyErr {
    use std::io::ErrorKind;
    let msg = format!("{e:#}");
    let io = e.chain().find_map(|c| c.downcast_ref::<std::io::Error>());
    match io.map(|io| io.kind()) {
        None => PyValueError::new_err(msg),
        Some(ErrorKind::NotFound) => PyFileNotFoundError::new_err(msg),
        Some(ErrorKind::PermissionDenied) => PyPermissionError::new_err(msg),
        Some(ErrorKind::IsADirectory) => PyIsADirectoryError::new_err(msg),
        Some(_) => PyOSError::new_err(msg),
    }
}

/// Run `work` without the GIL; a panic becomes a `RuntimeError` naming it as a bug.
fn compute<T: Send>(
    py: Python<'_>,
    work: impl FnOnce() -> anyhow::Result<T> + Send,
) -> PyResult<T> {
    let outcome = py.detach(|| catch_unwind(AssertUnwindSafe(work)));
    caught(outcome)
}

/// The outcome of `work` run under `catch_unwind` as a Python result.
fn caught<T>(outcome: std::thread::Result<anyhow::Result<T>>) -> PyResult<T> {
    match outcome {
        Ok(result) => result.map_err(to_py),
        Err(panic) => {
            let what = bsdfit::text::panic_text(panic.as_ref()).unwrap_or("unknown panic");
            Err(PyRuntimeError::new_err(format!(
                "bsdfit internal error (a bug, please report it): {what}"
            )))
        }
    }
}

/// A Python progress callable, called (with the GIL) from work that runs without it, as
/// `callback(stage, done, total, message)`. The first exception it raises is kept and
/// raised when the work ends; the callable is not called again meanwhile.
struct Reporter {
    callback: Option<Py<PyAny>>,
    error: Option<PyErr>,
}

impl Reporter {
    fn new(callback: Option<Py<PyAny>>) -> Reporter {
        Reporter {
            callback,
            error: None,
        }
    }

    fn send(&mut self, stage: &str, done: u64, total: Option<u64>, message: &str) {
        let Some(callback) = &self.callback else {
            return;
        };
        if self.error.is_some() {
            return;
        }
        let sent = Python::attach(|py| {
            callback
                .call1(py, (stage, done, total, message))
                .map(|_| ())
        });
        if let Err(e) = sent {
            self.error = Some(e);
        }
    }

    /// `value`, or the exception the callable raised.
    fn finish<T>(self, value: T) -> PyResult<T> {
        match self.error {
            Some(e) => Err(e),
            None => Ok(value),
        }
    }
}

/// A sweep's or a collection's progress as calls of a Python callable (stage `sweep`, or
/// `diagnose_many`: cells ended of the total).
struct SweepReporter {
    reporter: Reporter,
    stage: &'static str,
    done: u64,
    total: u64,
}

impl bsdfit::workflows::sweep::SweepObserver for SweepReporter {
    fn note(&mut self, line: &str) {
        self.reporter
            .send("note", self.done, Some(self.total), line);
    }
    fn begin(&mut self, total: u64, done: u64) {
        (self.total, self.done) = (total, done);
        self.reporter.send(self.stage, done, Some(total), "");
    }
    fn alert(&mut self, line: &str) {
        self.note(line);
    }
    fn fit_ended(&mut self, what: &str) {
        self.done += 1;
        self.reporter
            .send(self.stage, self.done, Some(self.total), what);
    }
    fn end(&mut self) {}
}

/// A dataset as the library holds it (angles in radians inside, degrees across).
#[pyclass(frozen, module = "bsdfit._bsdfit")]
struct NativeDataset {
    data: Arc<Dataset>,
}

#[pymethods]
impl NativeDataset {
    fn __len__(&self) -> usize {
        self.data.len()
    }

    #[getter]
    fn kind(&self) -> String {
        self.data.kind.to_string()
    }

    #[getter]
    fn material(&self) -> String {
        self.data.material.clone()
    }

    #[getter]
    fn source(&self) -> String {
        self.data.source.display().to_string()
    }

    #[getter]
    fn channels(&self) -> Vec<f64> {
        self.data.channels.clone()
    }

    #[getter]
    fn planes(&self) -> Vec<f64> {
        self.data.axes.clone()
    }

    #[getter]
    fn notices(&self) -> Vec<String> {
        self.data.notices.iter().map(|n| n.text.clone()).collect()
    }

    #[getter]
    fn assumed_uncertainty(&self) -> Option<(f64, f64)> {
        self.data.assumed_uncertainty
    }

    /// One column as a new float64 array: angles in degrees (as normalised on reading:
    /// θ ≥ 0), wavelength in nm, value and uncertainty in sr⁻¹, channel as an index.
    fn column<'py>(&self, py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let s = &self.data.samples;
        let v: Vec<f64> = match name {
            "theta_i" => s.iter().map(|s| s.theta_i.to_degrees()).collect(),
            "phi_i" => s.iter().map(|s| s.phi_i.to_degrees()).collect(),
            "theta_o" => s.iter().map(|s| s.theta_o.to_degrees()).collect(),
            "phi_o" => s.iter().map(|s| s.phi_o.to_degrees()).collect(),
            "wavelength_nm" => s.iter().map(|s| s.wavelength_nm).collect(),
            "value" => s.iter().map(|s| s.value).collect(),
            "uncertainty" => s.iter().map(|s| s.uncertainty).collect(),
            "channel" => s.iter().map(|s| s.channel as f64).collect(),
            other => {
                return Err(PyValueError::new_err(format!(
                    "no column '{other}' (theta_i, phi_i, theta_o, phi_o, wavelength_nm, value, uncertainty, channel)"
                )))
            }
        };
        Ok(PyArray1::from_vec(py, v))
    }

    /// Write the dataset as bsdfit v1 CSV.
    fn write_csv(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let data = self.data.clone();
        compute(py, move || {
            // An OSError of the cause's kind, naming the file, before the writer's message.
            std::fs::File::create(&path).map_err(|e| {
                anyhow::Error::new(std::io::Error::new(
                    e.kind(),
                    format!("cannot write {}: {e}", path.display()),
                ))
            })?;
            data.write(&path)
        })
    }
}

/// An `assume_uncertainty` argument: `(rel, abs)` or the command line's `"REL,ABS"`.
#[derive(FromPyObject)]
enum AssumeUncertainty {
    Values(f64, f64),
    Text(String),
}

/// Reader options from the keyword arguments shared by `read_dataset`, `from_arrays` and
/// `sweep`, checked by the library as the command line's are.
fn read_options(
    wavelengths: Option<Vec<f64>>,
    band: Option<f64>,
    max_samples: Option<usize>,
    assume_uncertainty: Option<AssumeUncertainty>,
    allow_zero_uncertainty: bool,
    alta_values: Option<String>,
    sample_geometry: Option<String>,
) -> anyhow::Result<ReadOptions> {
    ReadOptions::from_request(ReadRequest {
        allow_zero_uncertainty,
        wavelengths,
        band_nm: band,
        assume_uncertainty: assume_uncertainty.map(|a| match a {
            AssumeUncertainty::Values(rel, abs) => AssumeArg::Values(rel, abs),
            AssumeUncertainty::Text(text) => AssumeArg::Text(text),
        }),
        max_samples,
        alta_values: alta_values
            .map(|s| parse_choice::<AltaValues>("alta_values", &s))
            .transpose()?,
        sample_geometry,
    })
}

#[pyfunction]
#[pyo3(signature = (path, wavelengths, band, max_samples, assume_uncertainty, allow_zero_uncertainty, alta_values, sample_geometry))]
fn read_dataset(
    py: Python<'_>,
    path: PathBuf,
    wavelengths: Option<Vec<f64>>,
    band: Option<f64>,
    max_samples: Option<usize>,
    assume_uncertainty: Option<AssumeUncertainty>,
    allow_zero_uncertainty: bool,
    alta_values: Option<String>,
    sample_geometry: Option<String>,
) -> PyResult<NativeDataset> {
    let data = compute(py, move || {
        // Name the file in an OSError before any reader sees it.
        let named = |kind: std::io::ErrorKind, why: String| {
            anyhow::Error::new(std::io::Error::new(
                kind,
                format!("{}: {why}", path.display()),
            ))
        };
        std::fs::File::open(&path).map_err(|e| named(e.kind(), e.to_string()))?;
        if path.is_dir() {
            return Err(named(
                std::io::ErrorKind::IsADirectory,
                "a folder, not a data file".into(),
            ));
        }
        let opts = read_options(
            wavelengths,
            band,
            max_samples,
            assume_uncertainty,
            allow_zero_uncertainty,
            alta_values,
            sample_geometry,
        )?;
        Ok(readers::load(&path, &opts)?)
    })?;
    Ok(NativeDataset {
        data: Arc::new(data),
    })
}

/// The slice of a float64 array (the Python side makes them contiguous).
fn slice<'a>(name: &str, a: &'a PyReadonlyArray1<'_, f64>) -> PyResult<&'a [f64]> {
    a.as_slice()
        .map_err(|_| PyValueError::new_err(format!("{name}: not a contiguous float64 array")))
}

/// Rows of the seven columns (degrees), each tagged with its 1-based row number.
fn rows(
    theta_i: &[f64],
    phi_i: &[f64],
    theta_o: &[f64],
    phi_o: &[f64],
    wavelength_nm: &[f64],
    value: &[f64],
    uncertainty: &[f64],
) -> PyResult<Vec<(usize, RawRow)>> {
    let n = theta_i.len();
    let cols = [phi_i, theta_o, phi_o, wavelength_nm, value, uncertainty];
    if cols.iter().any(|c| c.len() != n) {
        return Err(PyValueError::new_err(format!(
            "the columns have different lengths ({n}, {})",
            cols.iter()
                .map(|c| c.len().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    Ok((0..n)
        .map(|k| {
            (
                k + 1,
                RawRow {
                    theta_i: theta_i[k],
                    phi_i: phi_i[k],
                    theta_o: theta_o[k],
                    phi_o: phi_o[k],
                    wavelength_nm: wavelength_nm[k],
                    value: value[k],
                    uncertainty: uncertainty[k],
                },
            )
        })
        .collect())
}

#[pyfunction]
#[pyo3(signature = (kind, theta_i, phi_i, theta_o, phi_o, wavelength_nm, value, uncertainty, material, wavelengths, band, allow_zero_uncertainty))]
fn dataset_from_arrays(
    py: Python<'_>,
    kind: &str,
    theta_i: PyReadonlyArray1<'_, f64>,
    phi_i: PyReadonlyArray1<'_, f64>,
    theta_o: PyReadonlyArray1<'_, f64>,
    phi_o: PyReadonlyArray1<'_, f64>,
    wavelength_nm: PyReadonlyArray1<'_, f64>,
    value: PyReadonlyArray1<'_, f64>,
    uncertainty: PyReadonlyArray1<'_, f64>,
    material: String,
    wavelengths: Option<Vec<f64>>,
    band: Option<f64>,
    allow_zero_uncertainty: bool,
) -> PyResult<NativeDataset> {
    let kind: Kind = kind
        .parse()
        .map_err(|e: String| PyValueError::new_err(format!("kind: {e}")))?;
    let raw = rows(
        slice("theta_i", &theta_i)?,
        slice("phi_i", &phi_i)?,
        slice("theta_o", &theta_o)?,
        slice("phi_o", &phi_o)?,
        slice("wavelength_nm", &wavelength_nm)?,
        slice("value", &value)?,
        slice("uncertainty", &uncertainty)?,
    )?;
    let data = compute(py, move || {
        let opts = read_options(
            wavelengths,
            band,
            None,
            None,
            allow_zero_uncertainty,
            None,
            None,
        )?;
        // Messages name a bad row as `arrays:ROW` (1-based).
        Ok(Dataset::from_rows(kind, &material, &raw, "arrays", &opts)?)
    })?;
    Ok(NativeDataset {
        data: Arc::new(data),
    })
}

/// One item of a `fix`, `bounds` or `prior` argument: a parameter's name and its numbers
/// (what a mapping gives), or the command line's `NAME=…` text.
#[derive(FromPyObject)]
enum ConstraintArg {
    Values(String, Vec<f64>),
    Text(String),
}

/// The constraints of `fix`, `bounds` and `prior` as values; an error names the argument.
fn constraint_spec(
    fix: Vec<ConstraintArg>,
    bounds: Vec<ConstraintArg>,
    prior: Vec<ConstraintArg>,
    lenient: bool,
) -> anyhow::Result<ConstraintSpec> {
    let mut items = Vec::new();
    // Bounds first, then fixed values, then priors: the order the library applies them in
    // (and the command line checks them in).
    for (kind, args) in [
        (ConstraintKind::Bounds, bounds),
        (ConstraintKind::Fix, fix),
        (ConstraintKind::Prior, prior),
    ] {
        for arg in args {
            items.push(match arg {
                ConstraintArg::Values(name, values) => Constraint::new(kind, &name, &values)?,
                ConstraintArg::Text(text) => Constraint::parse(kind, &text)?,
            });
        }
    }
    Ok(ConstraintSpec { items, lenient })
}

fn backend_choice(s: &str) -> anyhow::Result<BackendChoice> {
    parse_choice("backend", s)
}

/// The loss and weights words of a call as values; an error names the keyword.
fn loss_words(loss: &str, weights: &str) -> anyhow::Result<(Metric, Weights)> {
    let metric = loss
        .parse()
        .map_err(|e: String| anyhow::anyhow!("loss: {e}"))?;
    let weights = weights
        .parse()
        .map_err(|e: String| anyhow::anyhow!("weights: {e}"))?;
    Ok((metric, weights))
}

/// Fit one model: the report as the JSON text `bsdfit fit --json` writes, the Monte Carlo
/// error if its replicas failed, the warnings the command line prints on stderr, the
/// normalised residuals of the best fit (one per sample) and the text summary the command
/// line prints. `progress` (a callable or None) hears of the restarts as they converge.
#[pyfunction]
#[pyo3(signature = (dataset, model, loss, weights, optimizer, restarts, seed, backend, fix, bounds, prior, mc, mc_scale, mc_restarts, smoothness, progress))]
#[allow(clippy::type_complexity)]
fn fit_json<'py>(
    py: Python<'py>,
    dataset: &NativeDataset,
    model: String,
    loss: String,
    weights: String,
    optimizer: Option<String>,
    restarts: usize,
    seed: u64,
    backend: String,
    fix: Vec<ConstraintArg>,
    bounds: Vec<ConstraintArg>,
    prior: Vec<ConstraintArg>,
    mc: usize,
    mc_scale: f64,
    mc_restarts: usize,
    smoothness: String,
    progress: Option<Py<PyAny>>,
) -> PyResult<(
    String,
    Option<String>,
    Vec<String>,
    Bound<'py, PyArray1<f64>>,
    String,
)> {
    let data = dataset.data.clone();
    let mut reporter = Reporter::new(progress);
    let (text, mc_error, notes, residuals, summary, reporter) = compute(py, move || {
        let optimizer = optimizer
            .map(|s| parse_choice::<Optimizer>("optimizer", &s))
            .transpose()?;
        let (loss, weights) = loss_words(&loss, &weights)?;
        let request = fit::FitRequest {
            model,
            loss,
            weights,
            optimizer,
            restarts,
            seed,
            constraints: constraint_spec(fix, bounds, prior, false)?,
            mc,
            mc_scale,
            mc_restarts,
            smoothness: smoothness
                .parse()
                .map_err(|e: String| anyhow::anyhow!("smoothness: {e}"))?,
        };
        // Every check runs before the backend starts, as on the command line.
        let mut notes = Vec::new();
        request.preflight(&data, &mut |w| notes.push(w))?;
        let backend = engine::select(backend_choice(&backend)?, &mut |_| {})?;
        let mc_total = request.mc_total() as u64;
        let outcome = request.run(&data, backend.as_ref(), &mut |stage, active| {
            let (name, total) = match stage {
                fit::Stage::Fit => ("fit", restarts as u64),
                fit::Stage::MonteCarlo => ("mc", mc_total),
            };
            reporter.send(name, total.saturating_sub(active as u64), Some(total), "");
        })?;
        // The last restarts stop without a report of their own: the stages end complete.
        reporter.send("fit", restarts as u64, Some(restarts as u64), "");
        if mc > 0 {
            reporter.send("mc", mc_total, Some(mc_total), "");
        }
        outcome.check_finite(&data, backend.as_ref())?;
        let residuals = outcome.residuals(&data)?;
        let summary = outcome.report.summary();
        let mc_error = outcome.mc_error.map(|e| format!("{e:#}"));
        let text = serde_json::to_string(&outcome.report)?;
        Ok((text, mc_error, notes, residuals, summary, reporter))
    })?;
    reporter.finish((
        text,
        mc_error,
        notes,
        PyArray1::from_vec(py, residuals),
        summary,
    ))
}

/// A model at given parameters (`name=value,…`) and geometries (degrees), evaluated by
/// the chosen backend: one value per geometry.
#[pyfunction]
#[pyo3(signature = (model, params, theta_i, phi_i, theta_o, phi_o, backend))]
#[allow(clippy::too_many_arguments)]
fn evaluate<'py>(
    py: Python<'py>,
    model: String,
    params: String,
    theta_i: PyReadonlyArray1<'_, f64>,
    phi_i: PyReadonlyArray1<'_, f64>,
    theta_o: PyReadonlyArray1<'_, f64>,
    phi_o: PyReadonlyArray1<'_, f64>,
    backend: String,
) -> PyResult<Bound<'py, PyArray1<f64>>> {
    let cols = [
        slice("theta_i", &theta_i)?,
        slice("phi_i", &phi_i)?,
        slice("theta_o", &theta_o)?,
        slice("phi_o", &phi_o)?,
    ];
    let n = cols[0].len();
    if cols.iter().any(|c| c.len() != n) {
        return Err(PyValueError::new_err(
            "theta_i, phi_i, theta_o and phi_o have different lengths",
        ));
    }
    let geometry: Vec<[f64; 4]> = (0..n)
        .map(|k| [cols[0][k], cols[1][k], cols[2][k], cols[3][k]])
        .collect();
    let values = compute(py, move || {
        let backend = engine::select(backend_choice(&backend)?, &mut |_| {})?;
        bsdfit::workflows::synth::evaluate(&model, &params, &geometry, backend.as_ref())
    })?;
    Ok(PyArray1::from_vec(py, values))
}

/// The text summary of a fit report (its JSON text), as `bsdfit fit` prints it.
#[pyfunction]
fn fit_summary(text: &str, name: &str) -> PyResult<String> {
    caught(catch_unwind(|| {
        let report: FitReport = serde_json::from_str(text)
            .map_err(|e| anyhow::anyhow!("{name}: not a complete fit report ({e})"))?;
        Ok(report.summary())
    }))
}

/// A fit report read once, checked as `bsdfit eval` checks its file, and evaluated at
/// geometries without reading it again.
#[pyclass(frozen, module = "bsdfit._bsdfit")]
struct NativeFit {
    file: FitFile,
}

#[pymethods]
impl NativeFit {
    /// The fit report in `text` (JSON); `name` names it in messages. Quick: it keeps the
    /// GIL.
    #[new]
    fn new(text: &str, name: &str) -> PyResult<NativeFit> {
        let file = caught(catch_unwind(|| FitFile::parse(text, name)))?;
        Ok(NativeFit { file })
    }

    /// The fit at the given geometries: values and their propagated standard
    /// uncertainties, in the order given, and the warnings `bsdfit eval` prints.
    #[allow(clippy::type_complexity)]
    fn eval<'py>(
        &self,
        py: Python<'py>,
        theta_i: PyReadonlyArray1<'py, f64>,
        phi_i: PyReadonlyArray1<'py, f64>,
        theta_o: PyReadonlyArray1<'py, f64>,
        phi_o: PyReadonlyArray1<'py, f64>,
        wavelength_nm: PyReadonlyArray1<'py, f64>,
    ) -> PyResult<(
        Bound<'py, PyArray1<f64>>,
        Bound<'py, PyArray1<f64>>,
        Vec<String>,
    )> {
        let n = theta_i.len()?;
        let zeros = vec![0.0; n];
        let ones = vec![1.0; n];
        let raw = rows(
            slice("theta_i", &theta_i)?,
            slice("phi_i", &phi_i)?,
            slice("theta_o", &theta_o)?,
            slice("phi_o", &phi_o)?,
            slice("wavelength_nm", &wavelength_nm)?,
            &zeros,
            &ones,
        )?;
        let file = &self.file;
        let (values, uncertainties, warnings) = compute(py, move || {
            let kind = match file {
                FitFile::Single(f) => f.model.kind,
                FitFile::PerAxis(v) => v[0].1.model.kind,
            };
            let opts = ReadOptions {
                allow_zero_uncertainty: true,
                ..Default::default()
            };
            let at = Dataset::from_rows(kind, "eval", &raw, "eval", &opts)?;
            let p = export::predict(file, "the fit", &at, "eval")?;
            // Back to the caller's order: each sample keeps its row number.
            let mut values = vec![f64::NAN; n];
            let mut uncertainties = vec![f64::NAN; n];
            for s in &p.data.samples {
                values[s.line as usize - 1] = s.value;
                uncertainties[s.line as usize - 1] = s.uncertainty;
            }
            Ok((values, uncertainties, p.warnings))
        })?;
        Ok((
            PyArray1::from_vec(py, values),
            PyArray1::from_vec(py, uncertainties),
            warnings,
        ))
    }
}

/// The keywords of `bsdfit.fit` that have a library default, and those defaults
/// (`FitRequest::default()`): the Python signature shows these, so that no default is
/// written twice.
#[pyfunction]
fn fit_defaults(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = fit::FitRequest::default();
    let dict = PyDict::new(py);
    dict.set_item("loss", d.loss.to_string())?;
    dict.set_item("weights", d.weights.to_string())?;
    dict.set_item("optimizer", d.optimizer.map(|o| o.to_string()))?;
    dict.set_item("restarts", d.restarts)?;
    dict.set_item("seed", d.seed)?;
    dict.set_item("mc", d.mc)?;
    dict.set_item("mc_scale", d.mc_scale)?;
    dict.set_item("mc_restarts", d.mc_restarts)?;
    dict.set_item("smoothness", d.smoothness.to_string())?;
    Ok(dict)
}

/// The keywords of `bsdfit.sweep` that have a library default, and those defaults
/// (`SweepConfig::default()`), for its signature as [`fit_defaults`] for `fit`.
#[pyfunction]
fn sweep_defaults(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = bsdfit::workflows::sweep::SweepConfig::default();
    let dict = PyDict::new(py);
    dict.set_item("restarts", d.restarts)?;
    dict.set_item("seed", d.seed)?;
    dict.set_item("backend", d.backend.to_string())?;
    dict.set_item("pictures", d.pictures)?;
    Ok(dict)
}

/// The keywords of `bsdfit.diagnose` and their defaults, the library's
/// (`DiagnoseOptions::default()`): the Python signature shows these, so that no default is
/// written twice.
/// The catalogue: `[(spec, kind, [(parameter, rgb, lo, hi), …]), …]`.
#[pyfunction]
#[allow(clippy::type_complexity)]
fn catalogue() -> PyResult<Vec<(String, String, Vec<(String, bool, f64, f64)>)>> {
    let mut out = Vec::new();
    for spec in bsdfit::bsdf::registry::listed_specs() {
        let model = bsdfit::bsdf::Model::parse(&spec, 1).map_err(|e| to_py(e.into()))?;
        let params = model
            .params
            .iter()
            .map(|p| (p.name.clone(), p.decl.rgb, p.decl.lo, p.decl.hi))
            .collect();
        out.push((spec, model.kind.to_string(), params));
    }
    Ok(out)
}

/// Whether a Vulkan adapter (a GPU, or lavapipe) can be opened, and its name or why not.
#[pyfunction]
fn gpu_adapter(py: Python<'_>) -> (bool, String) {
    py.detach(|| match engine::gpu::GpuBackend::new() {
        Ok(g) => (true, engine::Backend::name(&g)),
        Err(e) => (false, e.to_string()),
    })
}

#[pymodule]
fn _bsdfit(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<NativeDataset>()?;
    m.add_class::<NativeFit>()?;
    m.add_function(wrap_pyfunction!(read_dataset, m)?)?;
    m.add_function(wrap_pyfunction!(dataset_from_arrays, m)?)?;
    m.add_function(wrap_pyfunction!(fit_json, m)?)?;
    m.add_function(wrap_pyfunction!(fit_summary, m)?)?;
    m.add_function(wrap_pyfunction!(fit_defaults, m)?)?;
    m.add_function(wrap_pyfunction!(sweep_defaults, m)?)?;
    m.add_function(wrap_pyfunction!(console::run_cli, m)?)?;
    m.add_function(wrap_pyfunction!(diagnosis::diagnose_defaults, m)?)?;
    m.add_function(wrap_pyfunction!(diagnosis::diagnose_json, m)?)?;
    m.add_function(wrap_pyfunction!(diagnosis::diagnose_many, m)?)?;
    m.add_function(wrap_pyfunction!(sweeps::sweep, m)?)?;
    m.add_function(wrap_pyfunction!(sweeps::battery_defaults, m)?)?;
    m.add_function(wrap_pyfunction!(sweeps::battery, m)?)?;
    m.add_function(wrap_pyfunction!(catalogue, m)?)?;
    m.add_function(wrap_pyfunction!(gpu_adapter, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
