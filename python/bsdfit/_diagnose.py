"""The diagnosis: one data set (``diagnose``) or a collection (``diagnose_many``)."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _bsdfit
from ._args import PathLike, ProgressEvent, ProgressArg, _Progress, _int, _real, _text, _path, _wavelengths, _assume, _slurm_binary
from ._dataset import Dataset
from ._fit import Fit, _constraint_list, _old_weighting
from ._fit import fit as _fit


@dataclass(frozen=True)
class Step:
    """One step of a diagnosis: the model, its χ²_red, and the effect it added."""

    model: str
    chi2_red: float
    effect: Optional[str]
    record: Dict[str, Any]


class Diagnosis:
    """What ``bsdfit diagnose`` found: the steps from the start model, the effects named,
    and the final model. ``report`` is the whole JSON of ``diagnose --json`` (empty for a
    collection's data set whose diagnosis failed); ``record`` the diagnosis as a
    collection's table holds it (each round's test, p-value and seconds, the final
    parameters with their uncertainties, why it stopped); ``warnings`` what the command
    line prints on stderr besides (a very large batch)."""

    def __init__(
        self,
        report: Dict[str, Any],
        warnings: Sequence[str] = (),
        record: Optional[Dict[str, Any]] = None,
        refit: Optional[Callable[[str], Fit]] = None,
    ) -> None:
        self.report = report
        self.warnings: List[str] = list(warnings)
        self.record: Dict[str, Any] = dict(record or {})
        self._refit = refit
        self._fit: Optional[Fit] = None

    @classmethod
    def _of_record(cls, record: Dict[str, Any], refit: Optional[Callable[[str], Fit]]) -> "Diagnosis":
        """A collection's data set: the steps are its rounds."""
        steps = [
            {"model": r.get("model", ""), "effect": r.get("effect"), "chi2_red": r.get("chi2_red")}
            for r in record.get("rounds", [])
        ]
        report = {
            "start_model": record.get("start_model", ""),
            "final_model": record.get("final_model") or "",
            "effects": list(record.get("effects", [])),
            "steps": steps,
        }
        return cls(report, (), record, refit)

    @property
    def data(self) -> str:
        """The data set's name (a collection's cell; the material for ``diagnose``)."""
        return str(self.record.get("data", ""))

    @property
    def ok(self) -> bool:
        """Whether the diagnosis ended (a collection's data set may have failed)."""
        return bool(self.record.get("status", "done") == "done")

    @property
    def error(self) -> Optional[str]:
        """Why a collection's data set failed (None where it did not)."""
        e = self.record.get("error")
        return None if e is None else str(e)

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

    def _rounds(self, key: str) -> np.ndarray:
        return np.array(
            [np.nan if r.get(key) is None else float(r[key]) for r in self.record.get("rounds", [])],
            dtype=float,
        )

    @property
    def chi2_red_steps(self) -> np.ndarray:
        """χ²_red after each step, as an array."""
        return np.array(self.chi2_red, dtype=float)

    @property
    def p_values(self) -> np.ndarray:
        """The p-value of the test that adopted each step (F or bootstrap; NaN for the
        start model)."""
        return self._rounds("p")

    @property
    def seconds(self) -> np.ndarray:
        """Seconds of the round that adopted each step (the start fit's first)."""
        return self._rounds("seconds")

    @property
    def stop(self) -> str:
        """Why the path ended, in words."""
        return str(self.record.get("stop") or "")

    @property
    def params(self) -> Dict[str, float]:
        """The final model's fitted parameters (flat names, e.g. ``rho[0]``)."""
        return {p["name"]: float("nan") if p.get("value") is None else float(p["value"])
                for p in self.record.get("params", [])}

    @property
    def std(self) -> Dict[str, float]:
        """Their standard uncertainties (NaN where the data leave one undetermined)."""
        return {p["name"]: float("nan") if p.get("std") is None else float(p["std"])
                for p in self.record.get("params", [])}

    @property
    def fit(self) -> Fit:
        """The final model as a :class:`Fit` (with its covariance, ``eval``, ``summary``):
        refitted once, when first asked for, with the diagnosis's loss, restarts, seed,
        constraints and backend on the data set diagnosed."""
        if self._fit is None:
            if self._refit is None or not self.ok:
                raise ValueError(f"{self.data or 'this diagnosis'}: no final model to fit"
                                 + (f" ({self.error})" if self.error else ""))
            self._fit = self._refit(self.final_model)
        return self._fit

    def summary(self) -> str:
        """A text report of the diagnosis: each step with its χ²_red, test and p-value, why
        it stopped, and the final parameters with their standard uncertainties."""
        name = self.data or self.report.get("start_model", "")
        if not self.ok:
            return f"[[Diagnosis {name}]]\n    failed: {self.error}\n"
        lines = [f"[[Diagnosis {name}]]",
                 f"    start model       = {self.report.get('start_model', '')}",
                 f"    final model       = {self.final_model}",
                 f"    effects           = {', '.join(self.effects) or 'none'}",
                 f"    stopped           = {self.stop}",
                 "[[Steps]]"]
        rounds = self.record.get("rounds") or self.report.get("steps", [])
        for k, r in enumerate(rounds):
            chi = r.get("chi2_red")
            test = "" if r.get("p") is None else f"  {r.get('test')} p = {float(r['p']):.3g}"
            effect = f" [{r['effect']}]" if r.get("effect") else ""
            chi_text = "nan" if chi is None else f"{float(chi):.4f}"
            lines.append(f"    {k}: {r.get('model', '')}{effect}  chi2_red = {chi_text}{test}")
        if self.record.get("params"):
            lines.append("[[Final parameters]]")
            for p in self.record["params"]:
                v = "nan" if p.get("value") is None else f"{float(p['value']):.6g}"
                u = "undetermined" if p.get("std") is None else f"{float(p['std']):.3g}"
                lines.append(f"    {p['name']:<16} = {v} +/- {u}")
        return "\n".join(lines) + "\n"

    def __repr__(self) -> str:
        if not self.ok:
            return f"<bsdfit.Diagnosis {self.data}: failed: {self.error}>"
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
    factors_past_max_steps: int = _DIAGNOSE_DEFAULTS["factors_past_max_steps"],
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
    options = _diagnose_options(
        loss, weights, optimizer, restarts, seed, alpha, max_steps, factors_past_max_steps,
        bootstrap, bootstrap_max, bootstrap_restarts, calibrate_all, backend, fix, bounds, prior,
        backtrack, explore,
    )
    with _Progress(progress) as reports:
        text, notes, record = _bsdfit.diagnose_json(
            dataset._native, _text("model", model), options, reports.native
        )
    refit = _refitter(dataset, dict(options, fix=fix, bounds=bounds, prior=prior))
    return Diagnosis(json.loads(text), notes, json.loads(record), refit)


def _diagnose_options(
    loss: str, weights: str, optimizer: str, restarts: int, seed: int, alpha: float,
    max_steps: int, factors_past_max_steps: int, bootstrap: int, bootstrap_max: int,
    bootstrap_restarts: int, calibrate_all: bool, backend: str, fix: Any, bounds: Any,
    prior: Any, backtrack: bool, explore: int,
) -> Dict[str, Any]:
    """The keywords of ``diagnose`` checked, as the native call takes them."""
    return {
        "loss": _text("loss", loss),
        "weights": _text("weights", weights),
        "optimizer": _text("optimizer", optimizer),
        "restarts": _int("restarts", restarts, 1),
        "seed": _int("seed", seed, 0),
        "alpha": _real("alpha", alpha),
        "max_steps": _int("max_steps", max_steps, 0),
        "factors_past_max_steps": _int("factors_past_max_steps", factors_past_max_steps, 0),
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


def _refitter(dataset: Dataset, options: Dict[str, Any]) -> Callable[[str], Fit]:
    """Fit a model to ``dataset`` with a diagnosis's options (its final model)."""
    def refit(model: str) -> Fit:
        return _fit(dataset, model, loss=options["loss"], weights=options["weights"],
                    restarts=options["restarts"], seed=options["seed"], backend=options["backend"],
                    optimizer=options["optimizer"], fix=options["fix"],
                    bounds=options["bounds"], prior=options["prior"])
    return refit



def diagnose_many(
    paths: Union[PathLike, Sequence[PathLike]],
    model: str,
    *,
    out: PathLike,
    shard: Optional[str] = None,
    pictures: bool = True,
    wavelengths: Optional[Sequence[float]] = None,
    assume_uncertainty: Optional[Union[str, Tuple[float, float]]] = None,
    max_samples: Optional[int] = None,
    loss: str = _DIAGNOSE_DEFAULTS["loss"],
    weights: str = _DIAGNOSE_DEFAULTS["weights"],
    optimizer: str = _DIAGNOSE_DEFAULTS["optimizer"],
    restarts: int = _DIAGNOSE_DEFAULTS["restarts"],
    seed: int = _DIAGNOSE_DEFAULTS["seed"],
    alpha: float = _DIAGNOSE_DEFAULTS["alpha"],
    max_steps: int = _DIAGNOSE_DEFAULTS["max_steps"],
    factors_past_max_steps: int = _DIAGNOSE_DEFAULTS["factors_past_max_steps"],
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
    progress: ProgressArg = True,
    emit_slurm: Optional[int] = None,
    slurm_cpus: int = 1,
    slurm_binary: Optional[PathLike] = None,
) -> List[Diagnosis]:
    """Diagnose a collection of data files or folders from the start ``model`` into
    ``out`` (``bsdfit diagnose FILE|DIR… --out DIR``): one resumable cell per data set
    (a rerun skips those done for the same bytes), ``diagnoses.csv``/``.json`` and
    ``report.html``. Returns the folder's table as :class:`Diagnosis` objects, worst final
    χ²_red first; a data set that failed is one too, with ``ok`` False and its ``error``
    (the others go on). ``shard``: ``"I/N"`` or ``"auto"`` (a Slurm array task), as the
    command line's ``--shard``. ``wavelengths``, ``assume_uncertainty``, ``max_samples``:
    how every file is read (a file with no more channels than ``wavelengths`` names keeps
    its own). The other keywords are :func:`diagnose`'s. ``emit_slurm=N``: run nothing;
    write the job scripts into ``out/slurm/`` (they run ``slurm_binary``, by default the
    ``bsdfit`` on the PATH) and return an empty list."""
    if isinstance(paths, (str, bytes, os.PathLike)):
        paths = [paths]
    options = _diagnose_options(
        loss, weights, optimizer, restarts, seed, alpha, max_steps, factors_past_max_steps,
        bootstrap, bootstrap_max, bootstrap_restarts, calibrate_all, backend, fix, bounds, prior,
        backtrack, explore,
    )
    tasks = None if emit_slurm is None else _int("emit_slurm", emit_slurm, 1)
    binary = None if tasks is None else _slurm_binary(slurm_binary)
    read_wavelengths = _wavelengths(wavelengths)
    read_assume = _assume(assume_uncertainty)
    read_max = None if max_samples is None else _int("max_samples", max_samples, 0)
    with _Progress(progress) as reports:
        table, _failed = _bsdfit.diagnose_many(
            [_path("paths", p) for p in paths],
            _path("out", out),
            _text("model", model),
            options,
            read_wavelengths,
            read_assume,
            read_max,
            None if shard is None else _text("shard", shard),
            bool(pictures),
            reports.native,
            tasks,
            _int("slurm_cpus", slurm_cpus, 1),
            binary,
        )
    refit_options = dict(options, fix=fix, bounds=bounds, prior=prior)

    def refitter(record: Dict[str, Any]) -> Callable[[str], Fit]:
        def refit(final_model: str) -> Fit:
            # A file with fewer channels than `wavelengths` names kept its own.
            few = wavelengths is not None and int(record.get("channels", 0)) < len(wavelengths)
            data = Dataset.read(record["path"], wavelengths=None if few else wavelengths,
                                assume_uncertainty=assume_uncertainty, max_samples=max_samples)
            return _refitter(data, refit_options)(final_model)
        return refit

    return [Diagnosis._of_record(r, refitter(r)) for r in json.loads(table)]
