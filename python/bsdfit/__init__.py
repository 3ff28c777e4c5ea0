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
import numbers
import operator
import os
import shutil
import sys
import time
import warnings as _warnings
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _bsdfit

__all__ = [
    "Dataset",
    "Fit",
    "Diagnosis",
    "Step",
    "ProgressEvent",
    "ModelInfo",
    "Parameter",
    "fit",
    "diagnose",
    "sweep",
    "Battery",
    "battery",
    "models",
    "gpu_available",
    "evaluate",
    "__version__",
]

__version__: str = _bsdfit.__version__

ArrayLike = Union[float, Sequence[float], np.ndarray]
PathLike = Union[str, "os.PathLike[str]"]


@dataclass(frozen=True)
class ProgressEvent:
    """What a long call reports as it runs, to a ``progress=`` callable.

    ``stage``: ``"fit"`` (restarts converged of ``total``), ``"mc"`` (Monte Carlo replica
    restarts), ``"diagnose"`` (``message`` is the line the command line prints; ``total``
    is None), ``"sweep"`` (fits ended of ``total``; ``message`` names the last),
    ``"battery"`` (cases ended of ``total``; ``message`` names the last) or ``"note"`` (a
    line the command line prints: a warning, a skipped file).
    """

    stage: str
    done: int
    total: Optional[int]
    message: str


ProgressArg = Union[None, bool, Callable[[ProgressEvent], Any]]


class _Bar:
    """A progress bar on stderr, one line redrawn in place (at most ten times a second),
    with the lines of ``note`` events printed above it."""

    def __init__(self) -> None:
        self._shown = ""
        self._last = 0.0

    def __call__(self, event: ProgressEvent) -> None:
        if event.stage == "note" or event.total is None:
            self._clear()
            print(f"{event.stage}: {event.message}" if event.stage != "note" else event.message,
                  file=sys.stderr, flush=True)
            return
        now = time.monotonic()
        if event.done < event.total and now - self._last < 0.1:
            return
        self._last = now
        width = 30
        filled = width * event.done // max(event.total, 1)
        line = (f"{event.stage}: [{'#' * filled}{'.' * (width - filled)}] "
                f"{event.done}/{event.total} {event.message}")[:100]
        sys.stderr.write("\r" + line.ljust(len(self._shown)))
        sys.stderr.flush()
        self._shown = line

    def _clear(self) -> None:
        if self._shown:
            sys.stderr.write("\r" + " " * len(self._shown) + "\r")
            self._shown = ""

    def close(self) -> None:
        if self._shown:
            sys.stderr.write("\n")
            sys.stderr.flush()
            self._shown = ""


class _Progress:
    """A ``progress=`` argument as the native module's callable: None (no reports), a bar
    on stderr (``True``), or the user's callable given a :class:`ProgressEvent`."""

    def __init__(self, progress: ProgressArg) -> None:
        self._bar: Optional[_Bar] = None
        self._user: Optional[Callable[[ProgressEvent], Any]] = None
        if progress is True:
            self._bar = _Bar()
        elif progress is None or progress is False:
            pass
        elif callable(progress):
            self._user = progress
        else:
            raise TypeError(
                f"progress: expected True, False, None or a callable, got {_short(progress)}"
            )

    @property
    def native(self) -> Optional[Callable[[str, int, Optional[int], str], None]]:
        if self._bar is None and self._user is None:
            return None
        return self._send

    def _send(self, stage: str, done: int, total: Optional[int], message: str) -> None:
        event = ProgressEvent(stage, done, total, message)
        if self._bar is not None:
            self._bar(event)
        if self._user is not None:
            self._user(event)

    def __enter__(self) -> "_Progress":
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._bar is not None:
            self._bar.close()


# The checks of the arguments' Python types and ranges, one function per kind of argument:
# each names the argument in its message. What the values mean (a row's angles, a model's
# name, a constraint's range) is checked by the library, with the command line's messages.

_U64_MAX = 2**64 - 1

# What numpy's dtype kinds hold, in words, for the arrays that are not real numbers.
_DTYPE_WORDS = {
    "b": "booleans",
    "c": "complex numbers",
    "O": "Python objects",
    "U": "strings",
    "S": "bytes",
    "M": "dates",
    "m": "time spans",
    "V": "records",
}


def _short(x: Any) -> str:
    """``x`` in a message: its type and a short repr."""
    text = repr(x)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{type(x).__name__} {text}"


def _numbers(name: str, x: Any, *, max_ndim: Optional[int], allow_empty: bool) -> np.ndarray:
    """``x`` as a float64 array: real numbers (integers or floats) only; at most
    ``max_ndim`` dimensions (None: any); empty only with ``allow_empty``. Anything else
    raises TypeError (not numbers) or ValueError (the wrong shape) naming ``name``."""
    expected = "a number or a 1-D array of numbers" if max_ndim == 1 else "numbers"
    if x is None or isinstance(x, (str, bytes)):
        raise TypeError(f"{name}: expected {expected}, got {_short(x)}")
    try:
        a = np.asarray(x)
    except (TypeError, ValueError):
        # numpy ≥ 1.24 refuses a ragged sequence outright.
        raise ValueError(
            f"{name}: expected {expected}, got a ragged sequence (its items differ in length or nesting)"
        ) from None
    kind = a.dtype.kind
    if kind == "O" and any(isinstance(e, (list, tuple, np.ndarray)) for e in a.flat):
        # Older numpy makes an object array of a ragged sequence.
        raise ValueError(
            f"{name}: expected {expected}, got a ragged sequence (its items differ in length or nesting)"
        )
    if kind not in "iuf":
        words = _DTYPE_WORDS.get(kind, f"dtype {a.dtype}")
        got = f"an array of {words} (dtype {a.dtype})" if a.ndim else _short(x)
        raise TypeError(f"{name}: expected real numbers, got {got}")
    if max_ndim is not None and a.ndim > max_ndim:
        raise ValueError(
            f"{name}: expected {expected}, got a {a.ndim}-D array of shape {a.shape}"
        )
    if not allow_empty and a.size == 0:
        raise ValueError(f"{name}: an empty array (no samples)")
    return a.astype(np.float64, copy=False)


def _columns(**cols: Any) -> List[np.ndarray]:
    """The columns of :meth:`Dataset.from_arrays`: numbers or 1-D arrays of numbers, none
    empty, the numbers broadcast to the arrays' length; contiguous float64."""
    arrays = [_numbers(k, v, max_ndim=1, allow_empty=False) for k, v in cols.items()]
    try:
        shaped = np.broadcast_arrays(*arrays)
    except ValueError:
        shapes = ", ".join(f"{k} {np.shape(a)}" for k, a in zip(cols, arrays))
        raise ValueError(f"the columns do not broadcast to one shape: {shapes}") from None
    return [np.ascontiguousarray(a, dtype=np.float64).ravel() for a in shaped]


def _broadcast(names: Sequence[str], values: Sequence[Any]) -> Tuple[Tuple[int, ...], List[np.ndarray]]:
    """Geometry arguments (numbers or arrays of any shape, checked as ``_numbers`` checks
    them) broadcast together: their common shape, and each as a flat float64 array."""
    arrays = [_numbers(k, v, max_ndim=None, allow_empty=True) for k, v in zip(names, values)]
    try:
        shape = np.broadcast_shapes(*(a.shape for a in arrays))
    except ValueError:
        raise ValueError("the geometry arrays do not broadcast to one shape") from None
    cols = [np.ascontiguousarray(np.broadcast_to(a, shape), dtype=np.float64).ravel()
            for a in arrays]
    return shape, cols


def _int(name: str, n: Any, lo: int, hi: int = _U64_MAX) -> int:
    """An integer in [lo, hi] (an int or a numpy integer; not a bool, not a float)."""
    if isinstance(n, (bool, np.bool_)):
        raise TypeError(f"{name}: expected an integer, got {_short(n)}")
    try:
        k = operator.index(n)
    except TypeError:
        raise TypeError(f"{name}: expected an integer, got {_short(n)}") from None
    if k < lo:
        raise ValueError(f"{name} must be ≥ {lo}, got {k}")
    if k > hi:
        raise ValueError(f"{name} must be ≤ {hi}, got {k}")
    return k


def _real(name: str, x: Any) -> float:
    """A real number (an int, a float or a numpy number; not a bool, not a string)."""
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, numbers.Real):
        raise TypeError(f"{name}: expected a number, got {_short(x)}")
    return float(x)


def _text(name: str, x: Any) -> str:
    if not isinstance(x, str):
        raise TypeError(f"{name}: expected a string, got {_short(x)}")
    return x


def _path(name: str, p: Any) -> str:
    try:
        return os.fsdecode(os.fspath(p))
    except TypeError:
        raise TypeError(f"{name}: expected a file path (str or os.PathLike), got {_short(p)}") from None


def _wavelengths(given: Optional[Any]) -> Optional[List[float]]:
    if given is None:
        return None
    return [float(w) for w in _numbers("wavelengths", given, max_ndim=1, allow_empty=True).ravel()]


def _assume(
    assume_uncertainty: Optional[Union[str, Tuple[float, float]]],
) -> Optional[Union[str, Tuple[float, float]]]:
    """``assume_uncertainty`` for the library: ``(rel, abs)`` as numbers, or the command
    line's ``"REL,ABS"`` text as it is."""
    if assume_uncertainty is None or isinstance(assume_uncertainty, str):
        return assume_uncertainty
    pair = _numbers("assume_uncertainty", assume_uncertainty, max_ndim=1, allow_empty=True)
    if pair.shape != (2,):
        raise ValueError(
            f"assume_uncertainty: expected (rel, abs) or 'REL,ABS', got {_short(assume_uncertainty)}"
        )
    rel, abs_ = (float(v) for v in pair)
    return (rel, abs_)


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

        Raises OSError (FileNotFoundError, IsADirectoryError, …) when the file cannot be
        read, ValueError when its content is bad, TypeError for an argument of the wrong type.
        """
        native = _bsdfit.read_dataset(
            _path("path", path),
            _wavelengths(wavelengths),
            None if band is None else _real("band", band),
            None if max_samples is None else _int("max_samples", max_samples, 0),
            _assume(assume_uncertainty),
            bool(allow_zero_uncertainty),
            None if alta_values is None else _text("alta_values", alta_values),
            None if sample_geometry is None else _text("sample_geometry", sample_geometry),
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
        """Measurements from arrays: one sample per row of the 1-D arrays, a number
        standing for all rows (and an array of one item likewise).

        ``kind`` is ``"brdf"`` or ``"btdf"``; angles in degrees (signed polar angles
        allowed, as in the v1 CSV), wavelength in nm, value and its standard uncertainty
        (k = 1) in sr⁻¹. Each row is checked as a file row would be; a bad row (NaN or
        infinite values included) raises ValueError naming it as ``arrays:ROW`` (1-based).
        An argument that is not real numbers (strings, complex numbers, booleans, Python
        objects) raises TypeError naming it; one with two or more dimensions, a ragged
        sequence, an empty array, or arrays of different lengths raise ValueError.
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
            _text("kind", kind),
            ti,
            pi,
            to,
            po,
            wl,
            v,
            u,
            _text("material", material),
            _wavelengths(wavelengths),
            None if band is None else _real("band", band),
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
        self._native.write_csv(_path("path", path))


def _check_report(report: Any, name: str) -> "_bsdfit.NativeFit":
    """``report`` (JSON data) read as the fit report :class:`Fit` evaluates, after the
    checks of ``bsdfit eval``'s reader and of the best fit's χ²_red and loss; ValueError
    naming ``name`` if it is not one."""
    if isinstance(report, dict) and "per_axis" in report:
        raise ValueError(
            f"{name}: a per-plane fit file (fit --per-axis) holds one fit per plane: "
            "load each with Fit(report['per_axis'][k]['fit'])"
        )
    try:
        text = json.dumps(report, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} is not a bsdfit fit report: not JSON data ({e})") from None
    native = _bsdfit.NativeFit(text, name)
    best = report.get("best")
    if not (
        isinstance(best, dict)
        and all(type(best.get(k)) in (int, float) for k in ("chi2_red", "loss"))
    ):
        raise ValueError(
            f"{name} is not a bsdfit fit report: no 'best' with the numbers 'chi2_red' and "
            "'loss' (docs/output.md)"
        )
    return native


class Fit:
    """A fitted model: what ``bsdfit fit --json`` writes, with numpy views of it.

    As scipy's ``least_squares`` result and lmfit's ``ModelResult``: ``x`` (the flat
    parameter vector, in ``param_names`` order, the order of ``covariance``),
    ``success``, ``status`` and ``message`` (why the optimizer stopped), ``nfev``,
    ``nfree``, ``residual`` (normalised residuals), ``bic``, ``aic`` and ``summary()``.
    ``params`` maps each parameter to its value (an array for per-channel parameters),
    ``std`` likewise (NaN where the data did not determine it, 0 where fixed).
    """

    def __init__(self, report: Dict[str, Any], warnings: Sequence[str] = ()) -> None:
        """``report``: the dict of a fit report (the JSON of ``bsdfit fit --json``),
        checked as ``bsdfit eval`` checks the file (ValueError if it is not one)."""
        if not isinstance(report, dict):
            raise TypeError(f"report: expected the dict of a fit report, got {_short(report)}")
        self._native = _check_report(report, "Fit(report)")
        self.report: Dict[str, Any] = report
        self.warnings: List[str] = list(report.get("warnings", [])) + list(warnings)
        self._residual: Optional[np.ndarray] = None
        self._summary: Optional[str] = None

    @classmethod
    def load(cls, path: PathLike) -> "Fit":
        """Read a fit report written by :meth:`to_json` or ``bsdfit fit --json``.

        Raises OSError when the file cannot be read, ValueError naming it when it is not
        a fit report (not UTF-8 JSON, or fields missing or inconsistent, as ``bsdfit
        eval`` checks them)."""
        name = _path("path", path)
        with open(name, "rb") as f:
            raw = f.read()
        try:
            report = json.loads(raw.decode("utf-8"))
        except UnicodeDecodeError as e:
            raise ValueError(f"{name} is not a bsdfit fit report: not UTF-8 text ({e})") from None
        except json.JSONDecodeError as e:
            raise ValueError(f"{name} is not a bsdfit fit report: not JSON ({e})") from None
        _check_report(report, name)
        return cls(report)

    def to_json(self, path: PathLike) -> None:
        """Write the report in the command line's format (``bsdfit eval``/``export`` read it)."""
        with open(_path("path", path), "w", encoding="utf-8") as f:
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
    def x(self) -> np.ndarray:
        """The best parameters as one flat array, in :attr:`param_names` order (the order
        of :attr:`covariance` and :attr:`correlation`)."""
        return self._flat("flat_params")

    def _stop(self, key: str) -> Any:
        stop = self.report.get("stop")
        return stop.get(key) if isinstance(stop, dict) else None

    @property
    def success(self) -> bool:
        """Whether the optimizer stopped because it converged (not out of iterations or
        evaluations, nor at a non-finite cost). False for a report that does not say."""
        return bool(self._stop("success"))

    @property
    def status(self) -> str:
        """Why the optimizer stopped, as an identifier: ``small_gain``,
        ``predicted_gain``, ``small_step``, ``damping``, ``stalled`` (Levenberg–Marquardt
        converged), ``max_iterations``, ``not_finite``, ``step_below_minimum`` (compass
        search converged), ``evaluation_budget``; ``unknown`` for a report that does not
        say (docs/output.md)."""
        return str(self._stop("status") or "unknown")

    @property
    def message(self) -> str:
        """Why the optimizer stopped, in words."""
        return str(self._stop("message") or "the report does not say why the optimizer stopped")

    @property
    def nfev(self) -> int:
        """Model-sample evaluations the fit made (all restarts, the polish and the
        covariance)."""
        return int(self.report["evaluations"])

    @property
    def nfree(self) -> int:
        """Degrees of freedom: samples + priors − fitted parameters (χ²_red's denominator)."""
        return int(self.report["dof"])

    @property
    def nvarys(self) -> int:
        """Fitted parameters (the flat vector's, less those fixed)."""
        return int(self.report["n_params"])

    @property
    def residual(self) -> Optional[np.ndarray]:
        """The normalised residuals (model − value)/uncertainty at the best fit, one per
        sample of the data it was fitted to, in the data's order; None for a fit loaded
        from a file (which does not hold the data)."""
        return None if self._residual is None else self._residual.copy()

    def _criterion(self, key: str) -> float:
        v = self.report.get(key)
        return float(v) if isinstance(v, (int, float)) else float("nan")

    @property
    def bic(self) -> float:
        """Bayesian information criterion χ² + k·ln K (χ² with the priors' share, k fitted
        parameters, K samples); lower is better between fits of the same data."""
        return self._criterion("bic")

    @property
    def aic(self) -> float:
        """Akaike information criterion χ² + 2k."""
        return self._criterion("aic")

    def summary(self) -> str:
        """The text report ``bsdfit fit`` prints: the parameters with their standard
        uncertainties, restarts, evaluations, why the optimizer stopped, warnings."""
        if self._summary is None:
            self._summary = _bsdfit.fit_summary(json.dumps(self.report), "the fit report")
        return self._summary

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
        Returns ``(values, uncertainties)`` shaped like the broadcast inputs (of any number
        of dimensions; empty inputs give empty results). Arguments that are not real
        numbers raise TypeError, NaN or infinite ones ValueError, each naming itself.
        """
        if wavelength_nm is None:
            if len(self.channels) != 1:
                raise ValueError(
                    f"the fit has {len(self.channels)} channels ({self.channels} nm): "
                    "say which with wavelength_nm"
                )
            wavelength_nm = self.channels[0]
        shape, cols = _broadcast(("theta_i", "phi_i", "theta_o", "phi_o", "wavelength_nm"),
                                 (theta_i, phi_i, theta_o, phi_o, wavelength_nm))
        if cols[0].size == 0:
            return np.zeros(shape), np.zeros(shape)
        values, uncertainties, warnings = self._native.eval(*cols)
        for w in warnings:
            if w not in self.warnings:
                self.warnings.append(w)
        return values.reshape(shape), uncertainties.reshape(shape)


# Per constraint argument: the command line's form, and the pair a mapping's value must be
# (None: one value, or one per channel).
_CONSTRAINTS: Dict[str, Tuple[str, Optional[Tuple[str, str]], str]] = {
    "fix": ("NAME=VALUE", None, "{'sigma': 0.3}"),
    "bounds": ("NAME=LO:HI", ("lo", "hi"), "{'alpha': (0.01, 0.5)}"),
    "prior": ("NAME=MEAN:SD", ("mean", "sd"), "{'eta': (1.5, 0.1)}"),
}


# One item of a constraint argument as the native module takes it: a parameter's name and
# its numbers, or the command line's NAME=… text.
_ConstraintItem = Union[str, Tuple[str, List[float]]]


def _constraint_list(name: str, given: Any) -> List[_ConstraintItem]:
    """``fix``/``bounds``/``prior`` as values for the library: (name, numbers) from a
    mapping (``{"sigma": 0.3}``, ``{"alpha": (0.01, 0.5)}``, ``{"rho": [0.4, 0.5, 0.6]}``),
    the command line's NAME=… strings as they are (a mapping's string value too)."""
    form, pair, example = _CONSTRAINTS[name]
    if given is None:
        return []
    if isinstance(given, str):
        return [given]
    if isinstance(given, Mapping):
        out: List[_ConstraintItem] = []
        for k, v in given.items():
            if not isinstance(k, str):
                raise TypeError(f"{name}: parameter names are strings, got {_short(k)}")
            if isinstance(v, str):
                out.append(f"{k}={v}")
                continue
            values = _numbers(f"{name}[{k!r}]", v, max_ndim=1, allow_empty=False).ravel()
            if pair is not None and values.size != 2:
                raise ValueError(
                    f"{name}[{k!r}]: expected ({pair[0]}, {pair[1]}), got {_short(v)}"
                )
            out.append((k, [float(x) for x in values]))
        return out
    if isinstance(given, (list, tuple)) and all(isinstance(item, str) for item in given):
        return [str(item) for item in given]
    raise TypeError(
        f"{name}: expected a mapping such as {example} or {form} strings, got {_short(given)}"
    )


# The library's defaults of fit (FitRequest::default()), shown in its signature.
_FIT_DEFAULTS: Dict[str, Any] = _bsdfit.fit_defaults()


def _smoothness(value: Any) -> str:
    """``smoothness`` as the word the library reads: "auto", "off" or a number (a σ)."""
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        raise TypeError(f'smoothness: "auto", "off" or a positive number, got {_short(value)}')
    return value if isinstance(value, str) else repr(float(value))


def _old_weighting(call: str, weights: Any, weighting: Any, default: Any) -> Any:
    """The weights of a call that may use the deprecated keyword ``weighting``: it warns,
    and giving both (weights other than its default) is an error."""
    if weighting is None:
        return weights
    _warnings.warn(
        f"{call}(weighting=...) is deprecated: use weights=... (the command line's --weights)",
        DeprecationWarning,
        stacklevel=3,
    )
    if weights != default:
        raise TypeError(f"{call}: give weights or its deprecated spelling weighting, not both")
    return weighting


def fit(
    dataset: Dataset,
    model: str,
    *,
    loss: str = _FIT_DEFAULTS["loss"],
    weights: str = _FIT_DEFAULTS["weights"],
    restarts: int = _FIT_DEFAULTS["restarts"],
    seed: int = _FIT_DEFAULTS["seed"],
    backend: str = "auto",
    optimizer: Optional[str] = _FIT_DEFAULTS["optimizer"],
    fix: Any = None,
    bounds: Any = None,
    prior: Any = None,
    mc: int = _FIT_DEFAULTS["mc"],
    mc_scale: float = _FIT_DEFAULTS["mc_scale"],
    mc_restarts: int = _FIT_DEFAULTS["mc_restarts"],
    smoothness: Union[str, float] = _FIT_DEFAULTS["smoothness"],
    progress: ProgressArg = None,
    weighting: Optional[str] = None,
) -> Fit:
    """Fit ``model`` (a spec such as ``"on"``, ``"fa(eon)"``, ``"btdf(gg)+scale"``) to the data.

    The keywords are ``bsdfit fit``'s options with its defaults: ``loss`` (chi2, or the
    benchmark losses smape rmse ngan low / f cosf logf logcosf), ``weights`` (uniform,
    relunc, invunc; ``weighting`` is its deprecated spelling and warns), ``restarts``,
    ``seed``, ``backend`` ("cpu", "gpu" or "auto"), ``optimizer``
    ("lm" or "compass"; default by loss), ``fix`` ({name: value}), ``bounds``
    ({name: (lo, hi)}), ``prior`` ({name: (mean, sd)}), and Monte Carlo replicas ``mc``
    with ``mc_scale`` and ``mc_restarts``; ``smoothness``, the prior on a data-driven
    factor's knots (``+ndf``, ``+fresnel``, ``+body``): "auto" (σ chosen from the data,
    reported in ``Fit.report["smoothness"]``), "off", or a σ. The same data and seed give
    the same parameters as the command line. ``progress``: True for a bar on stderr, or a callable given a
    :class:`ProgressEvent` as restarts converge.

    Arguments of the wrong type raise TypeError, bad values ValueError, each naming the
    argument (``restarts`` ≥ 1, ``seed`` in [0, 2**64 − 1], ``backend`` one of "auto",
    "cpu", "gpu", …); warnings the command line prints (a very large batch) are in
    :attr:`Fit.warnings`.
    """
    if not isinstance(dataset, Dataset):
        raise TypeError("dataset: a bsdfit.Dataset (Dataset.read or Dataset.from_arrays)")
    weights = _old_weighting("fit", weights, weighting, _FIT_DEFAULTS["weights"])
    with _Progress(progress) as reports:
        text, mc_error, notes, residual, summary = _bsdfit.fit_json(
            dataset._native,
            _text("model", model),
            _text("loss", loss),
            _text("weights", weights),
            None if optimizer is None else _text("optimizer", optimizer),
            _int("restarts", restarts, 1),
            _int("seed", seed, 0),
            _text("backend", backend),
            _constraint_list("fix", fix),
            _constraint_list("bounds", bounds),
            _constraint_list("prior", prior),
            _int("mc", mc, 0),
            _real("mc_scale", mc_scale),
            _int("mc_restarts", mc_restarts, 0),
            _smoothness(smoothness),
            reports.native,
        )
    result = Fit(json.loads(text), notes)
    result._residual = residual
    result._summary = summary
    if mc_error is not None:
        raise ValueError(f"mc: {mc_error} (the fit itself: {result!r})")
    return result


@dataclass(frozen=True)
class Step:
    """One step of a diagnosis: the model, its χ²_red, and the effect it added."""

    model: str
    chi2_red: float
    effect: Optional[str]
    record: Dict[str, Any]


class Diagnosis:
    """What ``bsdfit diagnose`` found: the steps from the start model, the effects named,
    and the final model. ``report`` is the whole JSON of ``diagnose --json``; ``warnings``
    what the command line prints on stderr besides (a very large batch)."""

    def __init__(self, report: Dict[str, Any], warnings: Sequence[str] = ()) -> None:
        self.report = report
        self.warnings: List[str] = list(warnings)

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


# The library's defaults of diagnose (DiagnoseOptions::default()), shown in its signature.
_DIAGNOSE_DEFAULTS: Dict[str, Any] = _bsdfit.diagnose_defaults()


def diagnose(
    dataset: Dataset,
    model: str,
    *,
    loss: str = _DIAGNOSE_DEFAULTS["loss"],
    weights: str = _DIAGNOSE_DEFAULTS["weights"],
    optimizer: str = _DIAGNOSE_DEFAULTS["optimizer"],
    restarts: int = _DIAGNOSE_DEFAULTS["restarts"],
    seed: int = _DIAGNOSE_DEFAULTS["seed"],
    alpha: float = _DIAGNOSE_DEFAULTS["alpha"],
    max_steps: int = _DIAGNOSE_DEFAULTS["max_steps"],
    bootstrap: int = _DIAGNOSE_DEFAULTS["bootstrap"],
    bootstrap_max: int = _DIAGNOSE_DEFAULTS["bootstrap_max"],
    bootstrap_restarts: int = _DIAGNOSE_DEFAULTS["bootstrap_restarts"],
    calibrate_all: bool = _DIAGNOSE_DEFAULTS["calibrate_all"],
    backend: str = "auto",
    fix: Any = None,
    bounds: Any = None,
    prior: Any = None,
    backtrack: bool = _DIAGNOSE_DEFAULTS["backtrack"],
    explore: int = _DIAGNOSE_DEFAULTS["explore"],
    progress: ProgressArg = None,
    weighting: Optional[str] = None,
) -> Diagnosis:
    """Find where ``model`` and the data disagree beyond the uncertainties, name the missing
    effect, add it and repeat while the improvement is significant (``bsdfit diagnose``).
    ``progress``: True to print the steps on stderr as they are found, or a callable given
    a :class:`ProgressEvent` per line. ``bootstrap`` replicates are planned for each
    calibrated test: it stops earlier once its verdict is settled and draws more, up to
    ``bootstrap_max``, where they cannot decide; ``calibrate_all`` runs the tests that
    cannot change a round's choice too (they are deferred by default). ``weights``: as
    ``fit``'s (``weighting`` is its deprecated spelling)."""
    if not isinstance(dataset, Dataset):
        raise TypeError("dataset: a bsdfit.Dataset (Dataset.read or Dataset.from_arrays)")
    weights = _old_weighting("diagnose", weights, weighting, _DIAGNOSE_DEFAULTS["weights"])
    with _Progress(progress) as reports:
        options = {
            "loss": _text("loss", loss),
            "weights": _text("weights", weights),
            "optimizer": _text("optimizer", optimizer),
            "restarts": _int("restarts", restarts, 1),
            "seed": _int("seed", seed, 0),
            "alpha": _real("alpha", alpha),
            "max_steps": _int("max_steps", max_steps, 0),
            "bootstrap": _int("bootstrap", bootstrap, 0),
            "bootstrap_max": _int("bootstrap_max", bootstrap_max, 0),
            "bootstrap_restarts": _int("bootstrap_restarts", bootstrap_restarts, 0),
            "calibrate_all": bool(calibrate_all),
            "backend": _text("backend", backend),
            "fix": _constraint_list("fix", fix),
            "bounds": _constraint_list("bounds", bounds),
            "prior": _constraint_list("prior", prior),
            "backtrack": bool(backtrack),
            "explore": _int("explore", explore, 0),
        }
        text, notes = _bsdfit.diagnose_json(
            dataset._native, _text("model", model), options, reports.native
        )
    return Diagnosis(json.loads(text), notes)


# The library's defaults of sweep (SweepConfig::default()), shown in its signature.
_SWEEP_DEFAULTS: Dict[str, Any] = _bsdfit.sweep_defaults()


def sweep(
    paths: Union[PathLike, Sequence[PathLike]],
    out: PathLike,
    *,
    models: Optional[Sequence[str]] = None,
    losses: Optional[Sequence[str]] = None,
    weights: Optional[Union[str, Sequence[str]]] = None,
    restarts: int = _SWEEP_DEFAULTS["restarts"],
    seed: int = _SWEEP_DEFAULTS["seed"],
    backend: str = _SWEEP_DEFAULTS["backend"],
    pictures: bool = _SWEEP_DEFAULTS["pictures"],
    shard: Optional[str] = None,
    assume_uncertainty: Optional[Union[str, Tuple[float, float]]] = None,
    progress: ProgressArg = True,
    emit_slurm: Optional[int] = None,
    slurm_cpus: int = 1,
    slurm_binary: Optional[PathLike] = None,
    weighting: Optional[Union[str, Sequence[str]]] = None,
) -> str:
    """Run ``bsdfit sweep`` over data files or folders into ``out`` (the same folder the
    command line writes: results.csv, results.json, pictures, report.html; resumable).
    Returns the path of ``out``.

    ``weights``: the weightings to sweep (as ``fit``'s keyword and ``--weights``;
    ``weighting`` is its deprecated spelling and warns). ``progress``: True (the default)
    for a bar on stderr with the command line's notes above it, False or None for
    silence, or a callable given a :class:`ProgressEvent` as each fit ends.

    ``emit_slurm=N``: run nothing; write the job scripts ``bsdfit sweep --emit-slurm N``
    writes into ``out/slurm/`` (an array of N tasks with ``slurm_cpus`` CPUs each, a merge
    job, submit.sh, and the sweep they run saved as sweep.json; docs/cluster.md). The
    tasks run the ``bsdfit`` command line: ``slurm_binary``, by default the one on the
    PATH."""
    weights = _old_weighting("sweep", weights, weighting, None)
    if isinstance(paths, (str, bytes, os.PathLike)):
        paths = [paths]

    def listed(name: str, given: Optional[Sequence[str]]) -> Optional[List[str]]:
        if given is None:
            return None
        if isinstance(given, str):
            return [given]
        return [_text(name, g) for g in given]

    out_path = _path("out", out)
    tasks = None if emit_slurm is None else _int("emit_slurm", emit_slurm, 1)
    binary: Optional[str] = None
    if tasks is not None:
        found = shutil.which("bsdfit") if slurm_binary is None else _path("slurm_binary", slurm_binary)
        if found is None:
            raise ValueError(
                "emit_slurm: the job scripts run the bsdfit command line, and there is none "
                "on the PATH: give slurm_binary=PATH (cargo build --release builds it)"
            )
        binary = os.path.realpath(found)
    with _Progress(progress) as reports:
        _bsdfit.sweep(
            [_path("paths", p) for p in paths],
            out_path,
            listed("models", models),
            listed("losses", losses),
            listed("weights", weights),
            _int("restarts", restarts, 1),
            _int("seed", seed, 0),
            _text("backend", backend),
            bool(pictures),
            None if shard is None else _text("shard", shard),
            _assume(assume_uncertainty),
            reports.native,
            tasks,
            _int("slurm_cpus", slurm_cpus, 1),
            binary,
        )
    return out_path


class Battery:
    """What ``bsdfit battery`` measured: ``outcomes``, every case and its diagnosis as
    ``battery --json`` writes them (one dict each: ``case``, ``named``, ``final_model``,
    ``snr``, ``detected``, ``false_effect``, ``error``, …), and ``table``, the rates the
    command line prints (markdown)."""

    def __init__(self, outcomes: List[Dict[str, Any]], table: str) -> None:
        self.outcomes = outcomes
        self.table = table

    def __len__(self) -> int:
        return len(self.outcomes)

    def __repr__(self) -> str:
        detected = sum(1 for o in self.outcomes if o.get("detected"))
        false = sum(1 for o in self.outcomes if o.get("false_effect"))
        return (f"<bsdfit.Battery {len(self.outcomes)} cases: {detected} detected, "
                f"{false} false effects>")


# The library's defaults of the battery (BatteryOptions::default()), shown in its signature.
_BATTERY_DEFAULTS: Dict[str, Any] = _bsdfit.battery_defaults()


def _range(name: str, given: Any, integer: bool) -> Tuple[Any, Any]:
    """A ``(lo, hi)`` pair of numbers (integers with ``integer``), naming ``name``."""
    if not isinstance(given, (list, tuple)) or len(given) != 2:
        raise TypeError(f"{name}: expected (lo, hi), got {_short(given)}")
    if integer:
        return (_int(f"{name}[0]", given[0], 0), _int(f"{name}[1]", given[1], 0))
    return (_real(f"{name}[0]", given[0]), _real(f"{name}[1]", given[1]))


def battery(
    *,
    cases: int = _BATTERY_DEFAULTS["cases"],
    nulls: int = _BATTERY_DEFAULTS["nulls"],
    misspecified: int = _BATTERY_DEFAULTS["misspecified"],
    seed: int = _BATTERY_DEFAULTS["seed"],
    effects: Optional[Sequence[str]] = None,
    signal: Tuple[float, float] = _BATTERY_DEFAULTS["signal"],
    samples: Tuple[int, int] = _BATTERY_DEFAULTS["samples"],
    restarts: int = _BATTERY_DEFAULTS["restarts"],
    backend: str = "auto",
    case: Optional[int] = None,
    data_driven: bool = False,
    progress: ProgressArg = True,
) -> Battery:
    """Run the diagnosis's randomized battery (``bsdfit battery``): ``cases`` cases per
    hidden effect (``effects``: names as ``diagnose`` gives them; default every effect)
    and ``nulls`` cases with nothing hidden, then ``misspecified`` null cases whose
    isotropic truths lie outside the catalogue (diagnosed from ``fa(lambert)``), the effect's pre-fit ``signal`` and the
    sample counts drawn log-uniformly from their ``(lo, hi)`` ranges, each diagnosed with
    ``restarts`` restarts per fit. The same ``seed`` draws the same battery; ``case=ID``
    runs that case only. ``data_driven=True`` offers the data-driven factors in each
    diagnosis's last round (off by default: it can cost minutes a case). ``progress``: True (the default) for a bar on stderr, False or
    None for silence, or a callable given a :class:`ProgressEvent` as each case ends."""
    listed = None
    if effects is not None:
        listed = [effects] if isinstance(effects, str) else [_text("effects", e) for e in effects]
    with _Progress(progress) as reports:
        text, table = _bsdfit.battery(
            _int("cases", cases, 0),
            _int("nulls", nulls, 0),
            _int("misspecified", misspecified, 0),
            _int("seed", seed, 0),
            listed,
            _range("signal", signal, integer=False),
            _range("samples", samples, integer=True),
            _int("restarts", restarts, 1),
            _text("backend", backend),
            None if case is None else _int("case", case, 0),
            bool(data_driven),
            reports.native,
        )
    return Battery(json.loads(text), table)


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


def evaluate(
    model: str,
    params: Union[str, Mapping[str, Union[float, Sequence[float]]]],
    theta_i: ArrayLike,
    phi_i: ArrayLike,
    theta_o: ArrayLike,
    phi_o: ArrayLike,
    *,
    backend: str = "cpu",
) -> np.ndarray:
    """The model ``model`` at the parameters ``params`` and the geometries (degrees,
    broadcast together; θo is the transmission angle of a BTDF, measured from −n), at
    one wavelength: an array shaped like the broadcast inputs.

    ``params`` maps names (``bsdfit.models()`` lists them) to values, or is the command
    line's ``"name=value,…"``; parameters not named keep their defaults. ``backend`` is
    ``"cpu"`` (the f64 reference), ``"gpu"`` (the f32 engine) or ``"auto"``. Any azimuth
    is allowed, so an anisotropic fit's planes between the measured ones can be drawn.
    """
    if isinstance(params, str):
        text = params
    elif isinstance(params, Mapping):
        parts = []
        for name, value in params.items():
            values = np.atleast_1d(_numbers(f"params[{name!r}]", value, max_ndim=1, allow_empty=False))
            parts.append(f"{_text('params', name)}=" + ":".join(repr(float(v)) for v in values))
        text = ",".join(parts)
    else:
        raise TypeError(f"params: expected a mapping of names to values or a string, got {_short(params)}")
    shape, cols = _broadcast(("theta_i", "phi_i", "theta_o", "phi_o"),
                             (theta_i, phi_i, theta_o, phi_o))
    theta_i_, phi_i_, theta_o_, phi_o_ = cols
    values = _bsdfit.evaluate(_text("model", model), text, theta_i_, phi_i_, theta_o_, phi_o_,
                              _text("backend", backend))
    return np.asarray(values).reshape(shape)
