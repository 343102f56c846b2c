"""Type stubs of the hbn package (see __init__.py for the documentation)."""

import os
from typing import Any, Dict, Iterator, List, Literal, Mapping, Optional, Sequence, Tuple, Union, overload

import numpy as np
import numpy.typing as npt

from . import _hbn

__all__ = [
    "GaussianProcess",
    "HysteresisModel",
    "Estimate",
    "simulate",
    "read_mcap",
    "list_topics",
    "SYSTEMS",
    "KERNELS",
    "DEFAULT_INDUCING",
    "__version__",
]

__version__: str
SYSTEMS: Tuple[str, ...]
KERNELS: str
DEFAULT_INDUCING: int

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
    n_restarts: int
    max_iter: int
    max_points: int
    seed: int
    def __init__(
        self,
        kernel: str = "se-ard",
        lengthscales: Optional[Union[float, Sequence[float], np.ndarray]] = None,
        signal_variance: Optional[float] = None,
        noise_variance: Optional[float] = None,
        optimize: bool = True,
        normalize: bool = True,
        n_restarts: int = 2,
        max_iter: int = 200,
        max_points: int = 1000,
        seed: int = 0,
        n_inducing: Optional[int] = None,
        inducing_points: Optional[ArrayLike] = None,
        optimize_inducing: bool = False,
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
    q_x: FloatArray
    r: FloatArray
    flags: npt.NDArray[np.uint32]
    obs_min: FloatArray
    obs_max: FloatArray
    mode: str
    def __init__(self, fields: Mapping[str, np.ndarray], mode: str) -> None: ...
    def __iter__(self) -> Iterator[FloatArray]: ...
    def __len__(self) -> int: ...
    def flag_names(self, k: int) -> List[str]: ...
    def flag_counts(self) -> Dict[str, int]: ...
    def to_dict(self) -> Dict[str, np.ndarray]: ...
    def score(self, x_ref: ArrayLike) -> Dict[str, float]: ...

class HysteresisModel:
    def __init__(self, core: _hbn.HysteresisModelCore) -> None: ...
    @classmethod
    def fit(
        cls,
        u: Union[ArrayLike, Sequence[ArrayLike]],
        x: Union[ArrayLike, Sequence[ArrayLike]],
        y: Union[ArrayLike, Sequence[ArrayLike]],
        rate: float = 100.0,
        kernel: str = "matern52",
        max_points: int = 500,
        n_restarts: int = 2,
        seed: int = 0,
        blr_window: float = 0.025,
        max_iter: int = 100,
        signals: Optional[Mapping[str, Any]] = None,
        n_inducing: Optional[int] = None,
    ) -> HysteresisModel: ...
    def estimate(self, u: ArrayLike, y: ArrayLike, mode: str = "ekf") -> Estimate: ...
    def simulate_open_loop(self, u: ArrayLike) -> FloatArray: ...
    def save(self, path: PathLike) -> None: ...
    @classmethod
    def load(cls, path: PathLike) -> HysteresisModel: ...
    @property
    def rate(self) -> float: ...
    @property
    def signals(self) -> Dict[str, Dict[str, Optional[str]]]: ...
    @property
    def params(self) -> Dict[str, Any]: ...
    @property
    def summary(self) -> Dict[str, Any]: ...
    @property
    def transition(self) -> GaussianProcess: ...
    @property
    def sensor(self) -> GaussianProcess: ...
    def ekf_config(self, mode: str = "ekf") -> Dict[str, Any]: ...

def simulate(
    system: str, steps: int, seed: int = 0, noise_gain: float = 0.0, rate: float = 100.0
) -> Dict[str, FloatArray]: ...
def list_topics(path: PathLike) -> List[Dict[str, Any]]: ...
def read_mcap(
    path: PathLike, signals: Mapping[str, str], rate: Optional[float] = None
) -> Dict[str, FloatArray]: ...
