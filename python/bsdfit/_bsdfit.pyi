"""Type stub of ``bsdfit._bsdfit``, the native half of the module (Rust, PyO3).

Use the ``bsdfit`` package instead: it wraps these with keyword arguments, numpy
broadcasting and the :class:`bsdfit.Fit` object, and checks the arguments' types and
ranges first. Every function that computes releases the GIL; errors are ``OSError`` or
its subclass for the cause (a file), ``ValueError`` (bad input, with the command line's
message) or ``RuntimeError`` (a bug).
"""

from typing import Any, Callable, Dict, List, Optional, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

# One item of fix, bounds or prior: (parameter name, its numbers), or a NAME=… text.
ConstraintItem = Union[str, Tuple[str, List[float]]]

# A progress callable: (stage, done, total or None, message).
ProgressCallback = Callable[[str, int, Optional[int], str], None]

class NativeDataset:
    """A dataset as the library holds it."""

    def __len__(self) -> int: ...
    @property
    def kind(self) -> str:
        """``"brdf"`` or ``"btdf"``."""
    @property
    def material(self) -> str: ...
    @property
    def source(self) -> str: ...
    @property
    def channels(self) -> List[float]:
        """Channel wavelengths (nm), in channel order."""
    @property
    def planes(self) -> List[float]:
        """Measurement planes (φ, degrees)."""
    @property
    def notices(self) -> List[str]: ...
    @property
    def assumed_uncertainty(self) -> Optional[Tuple[float, float]]: ...
    def column(self, name: str) -> npt.NDArray[np.float64]:
        """One column as a new float64 array (angles in degrees)."""
    def write_csv(self, path: str) -> None:
        """Write as bsdfit v1 CSV."""

def read_dataset(
    path: str,
    wavelengths: Optional[List[float]],
    band: Optional[float],
    max_samples: Optional[int],
    assume_uncertainty: Optional[Union[str, Tuple[float, float]]],
    allow_zero_uncertainty: bool,
    alta_values: Optional[str],
    sample_geometry: Optional[str],
) -> NativeDataset:
    """Read any data file the command line reads, with its selection options."""

def dataset_from_arrays(
    kind: str,
    theta_i: npt.NDArray[np.float64],
    phi_i: npt.NDArray[np.float64],
    theta_o: npt.NDArray[np.float64],
    phi_o: npt.NDArray[np.float64],
    wavelength_nm: npt.NDArray[np.float64],
    value: npt.NDArray[np.float64],
    uncertainty: npt.NDArray[np.float64],
    material: str,
    wavelengths: Optional[List[float]],
    band: Optional[float],
    allow_zero_uncertainty: bool,
) -> NativeDataset:
    """A dataset from contiguous float64 columns of one length (degrees, nm, sr⁻¹)."""

def fit_json(
    dataset: NativeDataset,
    model: str,
    loss: str,
    weights: str,
    optimizer: Optional[str],
    restarts: int,
    seed: int,
    backend: str,
    fix: List[ConstraintItem],
    bounds: List[ConstraintItem],
    prior: List[ConstraintItem],
    mc: int,
    mc_scale: float,
    mc_restarts: int,
    smoothness: str,
    progress: Optional[ProgressCallback],
) -> Tuple[str, Optional[str], List[str], npt.NDArray[np.float64], str]:
    """Fit one model: the report as ``bsdfit fit --json`` writes it, the Monte Carlo
    error if the replicas failed (the fit itself stands), the warnings the command line
    prints on stderr, the normalised residuals of the best fit and its text summary."""

def fit_summary(text: str, name: str) -> str:
    """The text summary ``bsdfit fit`` prints, of a fit report's JSON text."""

class NativeFit:
    """A fit report read once (checked as ``bsdfit eval`` checks its file)."""

    def __init__(self, text: str, name: str) -> None: ...
    def eval(
        self,
        theta_i: npt.NDArray[np.float64],
        phi_i: npt.NDArray[np.float64],
        theta_o: npt.NDArray[np.float64],
        phi_o: npt.NDArray[np.float64],
        wavelength_nm: npt.NDArray[np.float64],
    ) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], List[str]]:
        """The fit's values and propagated standard uncertainties at these geometries, in
        order, with the warnings ``bsdfit eval`` prints."""

def fit_defaults() -> Dict[str, Any]:
    """The keywords of ``bsdfit.fit`` that have a library default, and those defaults."""

def sweep_defaults() -> Dict[str, Any]:
    """The keywords of ``bsdfit.sweep`` that have a library default, and those defaults."""

def run_cli(args: List[str]) -> int:
    """Run the command line ``args`` (the program's name first); its exit status."""

def diagnose_defaults() -> Dict[str, Any]:
    """The keywords of ``bsdfit.diagnose`` and the library's defaults of them."""

def diagnose_json(
    dataset: NativeDataset,
    model: str,
    options: Dict[str, Any],
    progress: Optional[ProgressCallback],
) -> Tuple[str, List[str], str]:
    """The diagnosis as ``bsdfit diagnose --json`` writes it, the warnings the command
    line prints on stderr, and the diagnosis as a collection's cell records it (JSON)."""

def diagnose_many(
    paths: List[str],
    out: str,
    model: str,
    options: Dict[str, Any],
    wavelengths: Optional[List[float]],
    assume_uncertainty: Optional[Union[str, Tuple[float, float]]],
    max_samples: Optional[int],
    shard: Optional[str],
    pictures: bool,
    progress: Optional[ProgressCallback],
    emit_slurm: Optional[int],
    slurm_cpus: int,
    slurm_binary: Optional[str],
) -> Tuple[str, List[str]]:
    """A collection diagnosed into ``out`` (``bsdfit diagnose FILE|DIR… --out DIR``): its
    table (every cell's record, worst final χ²_red first, JSON) and this run's failed
    cells."""

def sweep(
    paths: List[str],
    out: str,
    models: Optional[List[str]],
    losses: Optional[List[str]],
    weights: Optional[List[str]],
    restarts: int,
    seed: int,
    backend: str,
    pictures: bool,
    shard: Optional[str],
    assume_uncertainty: Optional[Union[str, Tuple[float, float]]],
    progress: Optional[ProgressCallback],
    emit_slurm: Optional[int],
    slurm_cpus: int,
    slurm_binary: Optional[str],
) -> int:
    """Run a sweep into ``out`` (the command line's ``bsdfit sweep``); the fits it added.
    With ``emit_slurm``, write its Slurm job scripts instead (0 fits)."""

def battery_defaults() -> Dict[str, Any]:
    """The keywords of ``bsdfit.battery`` and the library's defaults of them."""

def battery(
    cases: int,
    nulls: int,
    misspecified: int,
    misspecified_btdf: int,
    seed: int,
    effects: Optional[List[str]],
    signal: Tuple[float, float],
    samples: Tuple[int, int],
    restarts: int,
    backend: str,
    case: Optional[int],
    data_driven: bool,
    progress: Optional[ProgressCallback],
) -> Tuple[str, str]:
    """Run the diagnosis's randomized battery (``bsdfit battery``): every case and its
    outcome as the JSON text ``battery --json`` writes, and the rates table (markdown)."""

def catalogue() -> List[Tuple[str, str, List[Tuple[str, bool, float, float]]]]:
    """``[(spec, kind, [(parameter, per_channel, lo, hi), …]), …]``."""

def evaluate(
    model: str,
    params: str,
    theta_i: np.ndarray,
    phi_i: np.ndarray,
    theta_o: np.ndarray,
    phi_o: np.ndarray,
    backend: str,
) -> np.ndarray:
    """The model at ``name=value,…`` parameters and the geometries (degrees)."""

def gpu_adapter() -> Tuple[bool, str]:
    """Whether a Vulkan adapter can be opened: (True, its name) or (False, why not)."""
