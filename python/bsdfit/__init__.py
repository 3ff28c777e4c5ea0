"""bsdfit: fit BRDF and BTDF models to measured goniometric data with uncertainties.

numpy arrays in and out; angles in degrees, wavelengths in nm, values in sr⁻¹, as in the
bsdfit v1 CSV format. The work runs in the Rust library (the same code as the ``bsdfit``
command line, so the same data and seed give the same parameters), with the GIL released.

    >>> import bsdfit
    >>> data = bsdfit.Dataset.read("data/red-brick.csv")
    >>> fit = bsdfit.fit(data, "on", seed=3, backend="cpu")
    >>> fit.params["sigma"], fit.chi2_red
    >>> values, uncertainties = fit.eval(30.0, 0.0, [0.0, 20.0, 40.0], 180.0)
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _bsdfit

__all__ = [
    "Dataset",
    "Fit",
    "Diagnosis",
    "Step",
    "ModelInfo",
    "Parameter",
    "fit",
    "diagnose",
    "sweep",
    "models",
    "gpu_available",
    "__version__",
]

__version__: str = _bsdfit.__version__

ArrayLike = Union[float, Sequence[float], np.ndarray]
PathLike = Union[str, "os.PathLike[str]"]


def _floats(name: str, x: Any) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name}: not an array of numbers ({e})") from None
    return a


def _columns(**cols: Any) -> List[np.ndarray]:
    """Broadcast the columns to one shape and flatten them to contiguous float64."""
    arrays = [_floats(k, v) for k, v in cols.items()]
    try:
        shaped = np.broadcast_arrays(*arrays)
    except ValueError:
        shapes = ", ".join(f"{k} {np.shape(a)}" for k, a in zip(cols, arrays))
        raise ValueError(f"the columns do not broadcast to one shape: {shapes}") from None
    return [np.ascontiguousarray(a, dtype=np.float64).ravel() for a in shaped]


def _assume(assume_uncertainty: Optional[Union[str, Tuple[float, float]]]) -> Optional[str]:
    if assume_uncertainty is None or isinstance(assume_uncertainty, str):
        return assume_uncertainty
    rel, abs_ = assume_uncertainty
    return f"{float(rel)!r},{float(abs_)!r}"


class Dataset:
    """Measurements: one sample per row (geometry, wavelength, value, standard uncertainty).

    Build one with :meth:`read` (any file the command line reads) or :meth:`from_arrays`.
    Columns are numpy arrays; angles in degrees as normalised on reading (θ ≥ 0).
    """

    __slots__ = ("_native",)

    def __init__(self, native: "_bsdfit.NativeDataset") -> None:
        self._native = native

    @classmethod
    def read(
        cls,
        path: PathLike,
        *,
        wavelengths: Optional[Sequence[float]] = None,
        band: Optional[float] = None,
        max_samples: Optional[int] = None,
        assume_uncertainty: Optional[Union[str, Tuple[float, float]]] = None,
        allow_zero_uncertainty: bool = False,
        alta_values: Optional[str] = None,
        sample_geometry: Optional[str] = None,
    ) -> "Dataset":
        """Read a data file: bsdfit v1 CSV, ALTA text, a MERL binary table, an RGL .bsdf
        material, a Zemax tabular BSDF or ASTM E1392 text (by content; docs/data-formats.md).

        The keywords are the command line's data options: ``wavelengths`` keeps the channels
        nearest these wavelengths (nm), ``band`` averages ±band nm around each,
        ``max_samples`` caps a MERL table (0 keeps all), ``assume_uncertainty=(rel, abs)``
        gives u = sqrt((rel·|value|)² + abs²) to files without uncertainties,
        ``allow_zero_uncertainty`` floors zero uncertainties instead of refusing them, and
        ``alta_values="brdf"|"brdf-cos"`` says what an ALTA file without #PARAM_OUT holds,
        and ``sample_geometry`` names the geometry an RGL .bsdf material is sampled at
        (default ``"grid:10"``).

        Raises OSError when the file cannot be read, ValueError when its content is bad.
        """
        native = _bsdfit.read_dataset(
            os.fspath(path),
            None if wavelengths is None else [float(w) for w in wavelengths],
            None if band is None else float(band),
            None if max_samples is None else int(max_samples),
            _assume(assume_uncertainty),
            bool(allow_zero_uncertainty),
            alta_values,
            sample_geometry,
        )
        return cls(native)

    @classmethod
    def from_arrays(
        cls,
        kind: str,
        theta_i: ArrayLike,
        phi_i: ArrayLike,
        theta_o: ArrayLike,
        phi_o: ArrayLike,
        wavelength_nm: ArrayLike,
        value: ArrayLike,
        uncertainty: ArrayLike,
        *,
        material: str = "arrays",
        wavelengths: Optional[Sequence[float]] = None,
        band: Optional[float] = None,
        allow_zero_uncertainty: bool = False,
    ) -> "Dataset":
        """Measurements from arrays (broadcast together, then flattened).

        ``kind`` is ``"brdf"`` or ``"btdf"``; angles in degrees (signed polar angles
        allowed, as in the v1 CSV), wavelength in nm, value and its standard uncertainty
        (k = 1) in sr⁻¹. Each row is checked as a file row would be; a bad row raises
        ValueError naming it as ``arrays:ROW`` (1-based).
        """
        ti, pi, to, po, wl, v, u = _columns(
            theta_i=theta_i,
            phi_i=phi_i,
            theta_o=theta_o,
            phi_o=phi_o,
            wavelength_nm=wavelength_nm,
            value=value,
            uncertainty=uncertainty,
        )
        native = _bsdfit.dataset_from_arrays(
            kind,
            ti,
            pi,
            to,
            po,
            wl,
            v,
            u,
            material,
            None if wavelengths is None else [float(w) for w in wavelengths],
            None if band is None else float(band),
            bool(allow_zero_uncertainty),
        )
        return cls(native)

    def __len__(self) -> int:
        return len(self._native)

    def __repr__(self) -> str:
        return (
            f"<bsdfit.Dataset {self.material!r}: {len(self)} {self.kind.upper()} samples, "
            f"channels {self.channels} nm>"
        )

    @property
    def kind(self) -> str:
        """``"brdf"`` or ``"btdf"``."""
        return self._native.kind

    @property
    def material(self) -> str:
        return self._native.material

    @property
    def source(self) -> str:
        """The file it was read from (or ``"arrays"``)."""
        return self._native.source

    @property
    def channels(self) -> List[float]:
        """The wavelengths (nm) of the channels, in channel order."""
        return self._native.channels

    @property
    def planes(self) -> List[float]:
        """The measurement planes (φ, degrees); [0] for data not on a few planes."""
        return self._native.planes

    @property
    def notices(self) -> List[str]:
        """What the reader wants you to know (assumed uncertainties, merged repeats, …)."""
        return self._native.notices

    @property
    def theta_i(self) -> np.ndarray:
        return self._native.column("theta_i")

    @property
    def phi_i(self) -> np.ndarray:
        return self._native.column("phi_i")

    @property
    def theta_o(self) -> np.ndarray:
        return self._native.column("theta_o")

    @property
    def phi_o(self) -> np.ndarray:
        return self._native.column("phi_o")

    @property
    def wavelength_nm(self) -> np.ndarray:
        return self._native.column("wavelength_nm")

    @property
    def value(self) -> np.ndarray:
        return self._native.column("value")

    @property
    def uncertainty(self) -> np.ndarray:
        return self._native.column("uncertainty")

    @property
    def channel(self) -> np.ndarray:
        """The channel index of each sample (into :attr:`channels`)."""
        return self._native.column("channel").astype(np.int64)

    def write_csv(self, path: PathLike) -> None:
        """Write as bsdfit v1 CSV (what ``bsdfit convert`` writes)."""
        self._native.write_csv(os.fspath(path))


class Fit:
    """A fitted model: what ``bsdfit fit --json`` writes, with numpy views of it.

    ``params`` maps each parameter to its value (an array for per-channel parameters),
    ``std`` likewise (NaN where the data did not determine it, 0 where fixed);
    ``covariance`` and ``correlation`` are over the flat vector named by ``param_names``.
    """

    def __init__(self, report: Dict[str, Any], warnings: Sequence[str] = ()) -> None:
        if "per_axis" in report:
            raise ValueError(
                "a per-plane fit file (fit --per-axis) holds one fit per plane: "
                "load each with Fit(report['per_axis'][k]['fit'])"
            )
        self.report: Dict[str, Any] = report
        self.warnings: List[str] = list(report.get("warnings", [])) + list(warnings)

    @classmethod
    def load(cls, path: PathLike) -> "Fit":
        """Read a fit report written by :meth:`to_json` or ``bsdfit fit --json``."""
        with open(os.fspath(path), encoding="utf-8") as f:
            try:
                report = json.load(f)
            except json.JSONDecodeError as e:
                raise ValueError(f"{os.fspath(path)}: not a fit report ({e})") from None
        return cls(report)

    def to_json(self, path: PathLike) -> None:
        """Write the report in the command line's format (``bsdfit eval``/``export`` read it)."""
        with open(os.fspath(path), "w", encoding="utf-8") as f:
            json.dump(self.report, f, indent=2)
            f.write("\n")

    def __repr__(self) -> str:
        return (
            f"<bsdfit.Fit {self.model} on {self.report.get('material', '?')}: "
            f"χ²_red = {self.chi2_red:.4g}, loss = {self.loss:.4g}>"
        )

    @property
    def model(self) -> str:
        return str(self.report["model"])

    @property
    def param_names(self) -> List[str]:
        """Names of the flat parameter vector (per-channel parameters as ``name[c]``)."""
        return list(self.report["flat_names"])

    @property
    def chi2_red(self) -> float:
        return float(self.report["best"]["chi2_red"])

    @property
    def loss(self) -> float:
        """The loss the fit minimised, at the best fit."""
        return float(self.report["best"]["loss"])

    @property
    def channels(self) -> List[float]:
        return list(self.report["channels"])

    @property
    def monte_carlo(self) -> Optional[Dict[str, Any]]:
        """With ``mc=N``: the parameters' distribution over N refitted replicas (mean, σ,
        95 % interval and correlations per parameter, as in ``fit --mc``); else None."""
        mc = self.report.get("monte_carlo")
        return dict(mc) if isinstance(mc, dict) else None

    def _flat(self, key: str) -> np.ndarray:
        return np.array(
            [np.nan if v is None else float(v) for v in self.report[key]], dtype=np.float64
        )

    def _grouped(self, flat: np.ndarray) -> Dict[str, Union[float, np.ndarray]]:
        out: Dict[str, Any] = {}
        for name, v in zip(self.param_names, flat):
            base, bracket, _ = name.partition("[")
            if bracket:
                out.setdefault(base, []).append(float(v))
            else:
                out[name] = float(v)
        return {k: np.array(v) if isinstance(v, list) else v for k, v in out.items()}

    @property
    def params(self) -> Dict[str, Union[float, np.ndarray]]:
        return self._grouped(self._flat("flat_params"))

    @property
    def std(self) -> Dict[str, Union[float, np.ndarray]]:
        return self._grouped(self._flat("flat_std"))

    @property
    def correlation(self) -> np.ndarray:
        """The parameters' correlation matrix (NaN where undetermined)."""
        return np.asarray(
            [[np.nan if c is None else float(c) for c in row] for row in self.report["correlation"]],
            dtype=np.float64,
        ).reshape(len(self.param_names), len(self.param_names))

    @property
    def covariance(self) -> np.ndarray:
        """cov = diag(std)·corr·diag(std); 0 for undetermined parameters (as ``eval`` uses)."""
        std = np.nan_to_num(self._flat("flat_std"), nan=0.0)
        corr = np.nan_to_num(self.correlation, nan=0.0)
        np.fill_diagonal(corr, 1.0)
        cov: np.ndarray = std[:, None] * corr * std[None, :]
        return cov

    def eval(
        self,
        theta_i: ArrayLike,
        phi_i: ArrayLike,
        theta_o: ArrayLike,
        phi_o: ArrayLike,
        wavelength_nm: Optional[ArrayLike] = None,
    ) -> Tuple[np.ndarray, np.ndarray]:
        """The model at these geometries (degrees; broadcast together) and the standard
        uncertainty of each value propagated from the fit's covariance, as ``bsdfit eval``.

        ``wavelength_nm`` must be channels of the fit; by default, the fit's only channel.
        Returns ``(values, uncertainties)`` shaped like the broadcast inputs.
        """
        if wavelength_nm is None:
            if len(self.channels) != 1:
                raise ValueError(
                    f"the fit has {len(self.channels)} channels ({self.channels} nm): "
                    "say which with wavelength_nm"
                )
            wavelength_nm = self.channels[0]
        arrays = [_floats(k, v) for k, v in
                  zip(("theta_i", "phi_i", "theta_o", "phi_o", "wavelength_nm"),
                      (theta_i, phi_i, theta_o, phi_o, wavelength_nm))]
        try:
            shape = np.broadcast_shapes(*(a.shape for a in arrays))
        except ValueError:
            raise ValueError("the geometry arrays do not broadcast to one shape") from None
        cols = [np.ascontiguousarray(np.broadcast_to(a, shape), dtype=np.float64).ravel()
                for a in arrays]
        if cols[0].size == 0:
            return np.zeros(shape), np.zeros(shape)
        values, uncertainties, warnings = _bsdfit.eval_fit(json.dumps(self.report), *cols)
        for w in warnings:
            if w not in self.warnings:
                self.warnings.append(w)
        return values.reshape(shape), uncertainties.reshape(shape)


def _constraint_list(given: Any) -> List[str]:
    """``fix``/``bounds``/``prior`` as the command line's NAME=… strings.

    Accepts a mapping (``{"sigma": 0.3}``, ``{"alpha": (0.01, 0.5)}``,
    ``{"rho": [0.4, 0.5, 0.6]}``) or the strings themselves.
    """
    if given is None:
        return []
    if isinstance(given, str):
        return [given]
    if isinstance(given, Mapping):
        out = []
        for k, v in given.items():
            if isinstance(v, str):
                out.append(f"{k}={v}")
            elif np.ndim(v) == 0:
                out.append(f"{k}={float(v)!r}")
            else:
                out.append(f"{k}=" + ":".join(repr(float(x)) for x in np.ravel(v)))
        return out
    return [str(s) for s in given]


def fit(
    dataset: Dataset,
    model: str,
    *,
    loss: str = "chi2",
    weighting: str = "uniform",
    restarts: int = 16,
    seed: int = 1,
    backend: str = "auto",
    optimizer: Optional[str] = None,
    fix: Any = None,
    bounds: Any = None,
    prior: Any = None,
    mc: int = 0,
    mc_scale: float = 0.0,
    mc_restarts: int = 3,
) -> Fit:
    """Fit ``model`` (a spec such as ``"on"``, ``"fa(eon)"``, ``"btdf(gg)+scale"``) to the data.

    The keywords are ``bsdfit fit``'s options with its defaults: ``loss`` (chi2, or the
    paper's smape rmse ngan low / f cosf logf logcosf), ``weighting`` (uniform, relunc,
    invunc), ``restarts``, ``seed``, ``backend`` ("cpu", "gpu" or "auto"), ``optimizer``
    ("lm" or "compass"; default by loss), ``fix`` ({name: value}), ``bounds``
    ({name: (lo, hi)}), ``prior`` ({name: (mean, sd)}), and Monte Carlo replicas ``mc``
    with ``mc_scale`` and ``mc_restarts``. The same data and seed give the same parameters
    as the command line.
    """
    if not isinstance(dataset, Dataset):
        raise TypeError("dataset: a bsdfit.Dataset (Dataset.read or Dataset.from_arrays)")
    text, mc_error = _bsdfit.fit_json(
        dataset._native,
        str(model),
        str(loss),
        str(weighting),
        optimizer,
        _positive("restarts", restarts),
        _seed(seed),
        str(backend),
        _constraint_list(fix),
        _constraint_list(bounds),
        _constraint_list(prior),
        int(mc),
        float(mc_scale),
        int(mc_restarts),
    )
    result = Fit(json.loads(text))
    if mc_error is not None:
        raise ValueError(f"mc: {mc_error} (the fit itself: {result!r})")
    return result


def _positive(name: str, n: Any) -> int:
    if isinstance(n, bool) or int(n) != n or int(n) < 1:
        raise ValueError(f"{name}: a positive integer, got {n!r}")
    return int(n)


def _seed(seed: Any) -> int:
    if isinstance(seed, bool) or int(seed) != seed or int(seed) < 0:
        raise ValueError(f"seed: a non-negative integer, got {seed!r}")
    return int(seed)


@dataclass(frozen=True)
class Step:
    """One step of a diagnosis: the model, its χ²_red, and the effect it added."""

    model: str
    chi2_red: float
    effect: Optional[str]
    record: Dict[str, Any]


class Diagnosis:
    """What ``bsdfit diagnose`` found: the steps from the start model, the effects named,
    and the final model. ``report`` is the whole JSON of ``diagnose --json``."""

    def __init__(self, report: Dict[str, Any]) -> None:
        self.report = report

    @property
    def steps(self) -> List[Step]:
        return [
            Step(
                model=s.get("model", ""),
                chi2_red=float("nan") if s.get("chi2_red") is None else float(s["chi2_red"]),
                effect=s.get("effect"),
                record=s,
            )
            for s in self.report.get("steps", [])
        ]

    @property
    def effects(self) -> List[str]:
        return list(self.report.get("effects", []))

    @property
    def final_model(self) -> str:
        return str(self.report.get("final_model", ""))

    @property
    def chi2_red(self) -> List[float]:
        """χ²_red after each step (the first is the start model's)."""
        return [s.chi2_red for s in self.steps]

    def __repr__(self) -> str:
        path = " → ".join(f"{c:.3g}" for c in self.chi2_red)
        return f"<bsdfit.Diagnosis {self.final_model}: effects {self.effects}, χ²_red {path}>"


def diagnose(
    dataset: Dataset,
    model: str,
    *,
    loss: str = "chi2",
    weighting: str = "uniform",
    optimizer: str = "lm",
    restarts: int = 16,
    seed: int = 1,
    alpha: float = 0.01,
    max_steps: int = 4,
    bootstrap: int = 99,
    bootstrap_restarts: int = 2,
    backend: str = "auto",
    fix: Any = None,
    bounds: Any = None,
    prior: Any = None,
    backtrack: bool = True,
    explore: int = 8000,
) -> Diagnosis:
    """Find where ``model`` and the data disagree beyond the uncertainties, name the missing
    effect, add it and repeat while the improvement is significant (``bsdfit diagnose``)."""
    if not isinstance(dataset, Dataset):
        raise TypeError("dataset: a bsdfit.Dataset (Dataset.read or Dataset.from_arrays)")
    text = _bsdfit.diagnose_json(
        dataset._native,
        str(model),
        str(loss),
        str(weighting),
        str(optimizer),
        _positive("restarts", restarts),
        _seed(seed),
        float(alpha),
        int(max_steps),
        int(bootstrap),
        int(bootstrap_restarts),
        str(backend),
        _constraint_list(fix),
        _constraint_list(bounds),
        _constraint_list(prior),
        bool(backtrack),
        int(explore),
    )
    return Diagnosis(json.loads(text))


def sweep(
    paths: Union[PathLike, Sequence[PathLike]],
    out: PathLike,
    *,
    models: Optional[Sequence[str]] = None,
    losses: Optional[Sequence[str]] = None,
    weights: Optional[Sequence[str]] = None,
    restarts: int = 16,
    seed: int = 1,
    backend: str = "auto",
    pictures: bool = True,
    shard: Optional[str] = None,
    assume_uncertainty: Optional[Union[str, Tuple[float, float]]] = None,
) -> str:
    """Run ``bsdfit sweep`` over data files or folders into ``out`` (the same folder the
    command line writes: results.csv, results.json, pictures, report.html; resumable).
    Returns the path of ``out``."""
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]

    def listed(given: Optional[Sequence[str]]) -> Optional[List[str]]:
        if given is None:
            return None
        return [given] if isinstance(given, str) else list(given)

    _bsdfit.sweep(
        [os.fspath(p) for p in paths],
        os.fspath(out),
        listed(models),
        listed(losses),
        listed(weights),
        _positive("restarts", restarts),
        _seed(seed),
        str(backend),
        bool(pictures),
        None if shard is None else str(shard),
        _assume(assume_uncertainty),
    )
    return os.fspath(out)


@dataclass(frozen=True)
class Parameter:
    name: str
    per_channel: bool
    lo: float
    hi: float


@dataclass(frozen=True)
class ModelInfo:
    spec: str
    kind: str
    parameters: Tuple[Parameter, ...]


def models() -> List[ModelInfo]:
    """The catalogue (what ``bsdfit models`` lists), each parameter with its range."""
    return [
        ModelInfo(spec, kind, tuple(Parameter(*p) for p in params))
        for spec, kind, params in _bsdfit.catalogue()
    ]


def gpu_available() -> Tuple[bool, str]:
    """Whether the GPU engine can start (a Vulkan adapter, lavapipe included): (yes, its
    name) or (no, why not)."""
    return _bsdfit.gpu_adapter()
