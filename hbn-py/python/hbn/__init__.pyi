"""Type stubs of the hbn package (see __init__.py for the documentation)."""

import os
from typing import Any, Dict, Iterator, List, Literal, Mapping, Optional, Sequence, Tuple, Union, overload

import numpy as np
import numpy.typing as npt

from . import _hbn

__all__ = [
    "HysteresisModel",
    "Estimate",
    "Filter",
    "FilterOutput",
    "VectorFilterOutput",
    "GaussianProcess",
    "Explorer",
    "Simulator",
    "simulate",
    "oracle_estimate",
    "pooled_score",
    "read_mcap",
    "list_topics",
    "default_params",
    "default_log_options",
    "default_gp_params",
    "default_explore_params",
    "default_sim_params",
    "HbnError",
    "HbnIOError",
    "HbnFileNotFoundError",
    "DataError",
    "ModelFileError",
    "ConfigError",
    "TrainingError",
    "SYSTEMS",
    "MULTI_SYSTEMS",
    "KERNELS",
    "DEFAULT_INDUCING",
    "MODES",
    "__version__",
]

__version__: str
SYSTEMS: Tuple[str, ...]
MULTI_SYSTEMS: Tuple[str, ...]
KERNELS: str
DEFAULT_INDUCING: int
MODES: Tuple[str, ...]

HbnError = _hbn.HbnError
HbnIOError = _hbn.HbnIOError
HbnFileNotFoundError = _hbn.HbnFileNotFoundError
DataError = _hbn.DataError
ModelFileError = _hbn.ModelFileError
ConfigError = _hbn.ConfigError
TrainingError = _hbn.TrainingError
FilterOutput = _hbn.FilterOutput
VectorFilterOutput = _hbn.VectorFilterOutput

def default_params() -> Dict[str, Any]: ...
def default_log_options() -> Dict[str, Any]: ...
def default_gp_params() -> Dict[str, Any]: ...
def default_explore_params() -> Dict[str, Any]: ...
def default_sim_params() -> Dict[str, Any]: ...

PathLike = Union[str, os.PathLike[str]]
ArrayLike = npt.ArrayLike
FloatArray = npt.NDArray[np.float64]

class GaussianProcess:
    kernel: str
    lengthscales: Optional[Union[float, Sequence[float], np.ndarray]]
    signal_variance: Optional[float]
    noise_variance: Optional[float]
    optimize: bool
    normalize: bool
    n_starts: int
    max_iters: int
    max_points: int
    seed: int
    n_inducing: Optional[int]
    inducing_points: Optional[ArrayLike]
    optimize_inducing: bool
    mean: str
    def __init__(
        self,
        kernel: str = ...,
        lengthscales: Optional[Union[float, Sequence[float], np.ndarray]] = None,
        signal_variance: Optional[float] = None,
        noise_variance: Optional[float] = None,
        optimize: bool = ...,
        normalize: bool = ...,
        n_starts: int = ...,
        max_iters: int = ...,
        max_points: int = ...,
        seed: int = ...,
        n_inducing: Optional[int] = None,
        inducing_points: Optional[ArrayLike] = None,
        optimize_inducing: bool = ...,
        mean: str = ...,
    ) -> None: ...
    def fit(self, X: ArrayLike, y: ArrayLike) -> GaussianProcess: ...
    @overload
    def predict(
        self, X: ArrayLike, return_std: Literal[False] = False, return_grad: Literal[False] = False
    ) -> FloatArray: ...
    @overload
    def predict(
        self, X: ArrayLike, return_std: Literal[True], return_grad: Literal[False] = False
    ) -> Tuple[FloatArray, FloatArray]: ...
    @overload
    def predict(
        self, X: ArrayLike, return_std: Literal[False] = False, *, return_grad: Literal[True]
    ) -> Tuple[FloatArray, FloatArray]: ...
    @overload
    def predict(
        self, X: ArrayLike, return_std: Literal[True], return_grad: Literal[True]
    ) -> Tuple[FloatArray, FloatArray, FloatArray]: ...
    @overload
    def predict(
        self, X: ArrayLike, return_std: bool = False, return_grad: bool = False
    ) -> Union[FloatArray, Tuple[FloatArray, ...]]: ...
    def log_marginal_likelihood(self) -> float: ...
    @property
    def hyperparameters(self) -> Dict[str, Any]: ...
    @property
    def n_support(self) -> int: ...
    @property
    def is_sparse(self) -> bool: ...
    @property
    def inducing_points_(self) -> npt.NDArray[np.float64]: ...
    @property
    def n_features_in_(self) -> int: ...
    @property
    def warnings_(self) -> List[str]: ...
    @property
    def report_(self) -> Dict[str, Any]: ...
    def save(self, path: PathLike) -> None: ...
    @classmethod
    def load(cls, path: PathLike) -> GaussianProcess: ...

class Estimate:
    FLAG_NAMES: Tuple[str, ...]
    x: FloatArray
    x_std: FloatArray
    y_pred: FloatArray
    innovation: FloatArray
    nis: FloatArray
    q_x: Optional[FloatArray]
    r: Optional[FloatArray]
    flags: npt.NDArray[np.uint32]
    obs_min: Optional[FloatArray]
    obs_max: Optional[FloatArray]
    obs_x: Optional[FloatArray]
    x_cov: Optional[FloatArray]
    unobservable: Optional[FloatArray]
    mode: str
    t: Optional[FloatArray]
    def __init__(
        self, fields: Mapping[str, np.ndarray], mode: str, t: Optional[np.ndarray] = None
    ) -> None: ...
    def __iter__(self) -> Iterator[FloatArray]: ...
    def __len__(self) -> int: ...
    def flag_names(self, k: int) -> List[str]: ...
    def flag_counts(self) -> Dict[str, int]: ...
    def to_dict(self) -> Dict[str, np.ndarray]: ...
    def score(self, x_ref: ArrayLike) -> Dict[str, Any]: ...

class HysteresisModel:
    def __init__(self, core: Union[_hbn.HysteresisModelCore, _hbn.VectorModelCore]) -> None: ...
    @classmethod
    def fit(
        cls,
        u: Union[ArrayLike, Sequence[ArrayLike]],
        x: Union[ArrayLike, Sequence[ArrayLike]],
        y: Union[ArrayLike, Sequence[ArrayLike]],
        rate_hz: float = ...,
        signals: Optional[Mapping[str, Any]] = None,
        *,
        kernel: Union[str, Sequence[str], None] = ...,
        transition_kernel: Optional[str] = ...,
        sensor_kernel: Optional[str] = ...,
        n_inducing: Union[int, None, Sequence[Optional[int]]] = ...,
        max_points: int = ...,
        subset_policy: str = ...,
        n_starts: int = ...,
        max_iters: int = ...,
        seed: int = ...,
        normalize: bool = ...,
        noise_floor: float = ...,
        blr_window: float = ...,
        validation: float = ...,
        memory: Sequence[float] = ...,
        lags: Union[Sequence[float], Sequence[Sequence[float]]] = ...,
        linear_mean: str = ...,
        sensor_inputs: Union[str, Sequence[str]] = ...,
        max_signal_variance: Optional[float] = ...,
        firmware_budget: Union[int, str, None] = ...,
    ) -> HysteresisModel: ...
    @classmethod
    def from_logs(
        cls,
        logs: Union[PathLike, Sequence[PathLike]],
        input: Union[str, Sequence[str]] = ...,
        state: Union[str, Sequence[str]] = ...,
        output: Union[str, Sequence[str]] = ...,
        rate_hz: Optional[float] = ...,
        time_source: str = ...,
        max_gap_s: float = ...,
        min_coverage: float = ...,
        min_state_samples: int = ...,
        *,
        kernel: Union[str, Sequence[str], None] = ...,
        transition_kernel: Optional[str] = ...,
        sensor_kernel: Optional[str] = ...,
        n_inducing: Union[int, None, Sequence[Optional[int]]] = ...,
        max_points: int = ...,
        subset_policy: str = ...,
        n_starts: int = ...,
        max_iters: int = ...,
        seed: int = ...,
        normalize: bool = ...,
        noise_floor: float = ...,
        blr_window: float = ...,
        validation: float = ...,
        memory: Sequence[float] = ...,
        lags: Union[Sequence[float], Sequence[Sequence[float]]] = ...,
        linear_mean: str = ...,
        sensor_inputs: Union[str, Sequence[str]] = ...,
        max_signal_variance: Optional[float] = ...,
        firmware_budget: Union[int, str, None] = ...,
    ) -> HysteresisModel: ...
    def estimate(self, u: ArrayLike, y: ArrayLike, mode: Optional[str] = None) -> Estimate: ...
    def smooth(self, u: ArrayLike, y: ArrayLike, mode: Optional[str] = None) -> Estimate: ...
    def estimate_log(
        self,
        path: PathLike,
        mode: Optional[str] = None,
        input: Union[str, Sequence[str], None] = None,
        output: Union[str, Sequence[str], None] = None,
        csv: Optional[PathLike] = None,
        mcap: Optional[PathLike] = None,
        time_source: Optional[str] = ...,
        max_gap_s: Optional[float] = ...,
    ) -> Estimate: ...
    def filter(self, mode: Optional[str] = None) -> Filter: ...
    @property
    def is_vector(self) -> bool: ...
    @property
    def dims(self) -> Tuple[int, int, int]: ...
    def simulate_open_loop(self, u: ArrayLike) -> FloatArray: ...
    def save(self, path: PathLike) -> None: ...
    @classmethod
    def load(cls, path: PathLike) -> HysteresisModel: ...
    def to_bytes(self) -> bytes: ...
    @classmethod
    def from_bytes(cls, data: bytes) -> HysteresisModel: ...
    @property
    def rate_hz(self) -> float: ...
    @property
    def rate(self) -> float: ...
    @property
    def default_mode(self) -> str: ...
    @property
    def tuning(self) -> Dict[str, Any]: ...
    @property
    def signals(self) -> Dict[str, Any]: ...
    @property
    def params(self) -> Dict[str, Any]: ...
    @property
    def summary(self) -> Dict[str, Any]: ...
    @property
    def transition(self) -> GaussianProcess: ...
    @property
    def sensor(self) -> GaussianProcess: ...
    @property
    def transition_gps(self) -> List[GaussianProcess]: ...
    @property
    def sensor_gps(self) -> List[GaussianProcess]: ...
    def ekf_config(self, mode: Optional[str] = None) -> Dict[str, Any]: ...
    def initial_state(self, y0: float) -> Optional[Tuple[float, float]]: ...

class Filter:
    def __init__(self, core: Union[_hbn.FilterCore, _hbn.VectorFilterCore]) -> None: ...
    @overload
    def step(self, u: float, y: float) -> FilterOutput: ...
    @overload
    def step(self, u: Sequence[float], y: Sequence[float]) -> VectorFilterOutput: ...
    def reset(self) -> None: ...
    @property
    def mode(self) -> str: ...
    @property
    def steps(self) -> int: ...

class Explorer:
    def __init__(
        self,
        u_min: float,
        u_max: float,
        max_step: float,
        rate_hz: float = ...,
        seed: int = ...,
        u_start: Optional[float] = ...,
        random_samples: int = ...,
        alpha_start: float = ...,
        alpha_end: float = ...,
        alpha_ramp: int = ...,
        refit_every: int = ...,
        optimize_every: int = ...,
        candidates: int = ...,
        horizon: int = ...,
        strategy: str = ...,
        pool: int = ...,
        lag: int = ...,
        criterion: str = ...,
        *,
        kernel: Union[str, Sequence[str], None] = ...,
        transition_kernel: Optional[str] = ...,
        sensor_kernel: Optional[str] = ...,
        n_inducing: Union[int, None, Sequence[Optional[int]]] = ...,
        max_points: int = ...,
        subset_policy: str = ...,
        n_starts: int = ...,
        max_iters: int = ...,
        normalize: bool = ...,
        noise_floor: float = ...,
        blr_window: float = ...,
        validation: float = ...,
        memory: Sequence[float] = ...,
        lags: Union[Sequence[float], Sequence[Sequence[float]]] = ...,
        linear_mean: str = ...,
        sensor_inputs: Union[str, Sequence[str]] = ...,
        max_signal_variance: Optional[float] = ...,
        firmware_budget: Union[int, str, None] = ...,
    ) -> None: ...
    def propose(self) -> float: ...
    def observe(self, u: float, x: float, y: float) -> None: ...
    def model(self) -> HysteresisModel: ...
    def plan(self, steps: int) -> Tuple[FloatArray, FloatArray]: ...
    def start_run(self) -> None: ...
    @property
    def phase(self) -> str: ...
    @property
    def alpha(self) -> float: ...
    @property
    def n_observed(self) -> int: ...
    @property
    def warnings(self) -> List[str]: ...
    @property
    def runs(self) -> List[Dict[str, FloatArray]]: ...
    @property
    def settings(self) -> Dict[str, Any]: ...

class Simulator:
    def __init__(
        self,
        system: str,
        seed: int = ...,
        noise_gain: float = ...,
        rate_hz: float = ...,
    ) -> None: ...
    def step(self, u: float) -> Tuple[float, float]: ...
    @property
    def steps(self) -> int: ...

def pooled_score(estimates: Sequence[Estimate], x_refs: Sequence[ArrayLike]) -> Dict[str, Any]: ...
def simulate(
    system: str,
    steps: int,
    seed: int = ...,
    noise_gain: float = ...,
    rate_hz: float = ...,
) -> Dict[str, FloatArray]: ...
def oracle_estimate(
    system: str,
    u: ArrayLike,
    x: ArrayLike,
    y: ArrayLike,
    noise_gain: float = ...,
    rate_hz: float = ...,
    lookahead: Optional[int] = ...,
    particles: int = ...,
) -> Dict[str, FloatArray]: ...
def list_topics(path: PathLike) -> List[Dict[str, Any]]: ...
def read_mcap(
    path: PathLike,
    signals: Mapping[str, str],
    rate_hz: Optional[float] = ...,
    time_source: str = ...,
    max_gap_s: float = ...,
) -> Dict[str, FloatArray]: ...

# Deprecated alias of HysteresisModel (a DeprecationWarning at runtime).
HbnModel = HysteresisModel
