"""Measured data sets: read from files or built from arrays."""

from __future__ import annotations

from typing import List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _bsdfit
from ._args import ArrayLike, PathLike, _columns, _int, _real, _text, _path, _wavelengths, _assume


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
        material, a Zemax tabular BSDF, ASTM E1392 text or a NIST Mueller-matrix BRDF table
        (by content; docs/data-formats.md).

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
