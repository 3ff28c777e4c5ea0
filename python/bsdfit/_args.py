"""The checks of the arguments and the progress reports every call shares."""

from __future__ import annotations

import numbers
import operator
import os
import shutil
import sys
import time
from dataclasses import dataclass
from typing import Any, Callable, List, Optional, Sequence, Tuple, Union

import numpy as np



ArrayLike = Union[float, Sequence[float], np.ndarray]
PathLike = Union[str, "os.PathLike[str]"]


@dataclass(frozen=True)
class ProgressEvent:
    """What a long call reports as it runs, to a ``progress=`` callable.

    ``stage``: ``"fit"`` (restarts converged of ``total``), ``"mc"`` (Monte Carlo replica
    restarts), ``"diagnose"`` (``message`` is the line the command line prints; ``total``
    is None), ``"sweep"`` (fits ended of ``total``; ``message`` names the last),
    ``"diagnose_many"`` (a collection's data sets ended of ``total``; ``message`` names
    the last; the steps come as ``"note"``),
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


def _slurm_binary(given: Optional[PathLike]) -> str:
    """The ``bsdfit`` command the Slurm job scripts run: ``given``, else the one this
    package installed beside this Python (``pip install`` puts it there), else the one on
    the PATH."""
    if given is not None:
        return os.path.realpath(_path("slurm_binary", given))
    beside = os.path.join(os.path.dirname(sys.executable), "bsdfit")
    found = beside if os.path.isfile(beside) and os.access(beside, os.X_OK) else shutil.which("bsdfit")
    if found is None:
        raise ValueError(
            "emit_slurm: the job scripts run the bsdfit command, and there is none beside this "
            "Python or on the PATH: reinstall the package (pip install ./python installs it) "
            "or give slurm_binary=PATH"
        )
    return os.path.realpath(found)
