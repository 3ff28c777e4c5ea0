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

from dataclasses import dataclass
from typing import Any, List, Mapping, Sequence, Tuple, Union

import numpy as np

from . import _bsdfit
from ._args import ArrayLike, ProgressEvent, _short, _numbers, _broadcast, _text
from ._dataset import Dataset
from ._diagnose import Diagnosis, Step, diagnose, diagnose_many
from ._fit import Fit, fit
from ._sweep import Battery, battery, sweep


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
    "diagnose_many",
    "sweep",
    "Battery",
    "battery",
    "models",
    "gpu_available",
    "evaluate",
    "__version__",
]

__version__: str = _bsdfit.__version__


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
