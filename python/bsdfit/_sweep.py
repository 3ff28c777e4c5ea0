"""Sweeps and the randomized battery."""

from __future__ import annotations

import json
import os
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

from . import _bsdfit
from ._args import PathLike, ProgressEvent, ProgressArg, _Progress, _short, _int, _real, _text, _path, _assume, _slurm_binary
from ._fit import _old_weighting


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
    binary = None if tasks is None else _slurm_binary(slurm_binary)
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
    misspecified_btdf: int = _BATTERY_DEFAULTS["misspecified_btdf"],
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
    isotropic truths lie outside the catalogue (diagnosed from ``fa(lambert)``) and
    ``misspecified_btdf`` transmission ones (rough dielectrics whose NDF is outside the
    BTDF catalogue, diagnosed from ``btdf(tr)``), the effect's pre-fit ``signal`` and the
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
            _int("misspecified_btdf", misspecified_btdf, 0),
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
