"""One fit: ``bsdfit.fit`` and its ``Fit``."""

from __future__ import annotations

import json
import warnings as _warnings
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from . import _bsdfit
from ._args import ArrayLike, PathLike, ProgressEvent, ProgressArg, _Progress, _short, _numbers, _broadcast, _int, _real, _text, _path
from ._dataset import Dataset


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
