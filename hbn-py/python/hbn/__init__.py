"""hbn: Gaussian-process models of hysteretic soft-robot systems and a real-time EKF.

The same Rust engine as the ``hbn`` command-line tool, with a scikit-learn feel:

* :class:`HysteresisModel` -- the Hysteresis Bayesian Network (actuator ``u -> x``, soft sensor
  ``x -> y``) learned from logged ``(u, x, y)`` trajectories, whose filter estimates ``x`` from
  ``u`` and ``y`` alone; its files are the CLI's ``hbn train --out model.hbn`` files;
* :class:`Filter` -- the streaming estimator (``model.filter()``): one ``step(u, y)`` per sample,
  equal to :meth:`HysteresisModel.estimate` sample for sample;
* :class:`GaussianProcess` -- an exact or sparse GP regressor (``fit`` / ``predict``) with the
  kernels of the HBN, input gradients of the mean, and JSON persistence;
* :class:`Explorer` -- which input to apply next while collecting training data (thesis
  Sec. 3.4), with a robot or a :class:`Simulator` in the loop;
* :func:`simulate` -- the hysteretic test systems of ``hbn simulate``; :class:`Simulator` steps
  one of them a sample at a time; :func:`oracle_estimate` -- the floor under causal estimation
  on their logs;
* :func:`read_mcap` -- numeric signals from MCAP robot logs (ROS 2 or Foxglove), resampled on one
  grid by the CLI's own pipeline; :meth:`HysteresisModel.from_logs` trains from logs exactly like
  ``hbn train``.

Every default in a signature is the library's own, read from the Rust engine when the module
loads (:func:`default_params`, :func:`default_log_options`, :func:`default_gp_params`,
:func:`default_explore_params`, :func:`default_sim_params`). A keyword is the name of the Rust
field it sets (``n_starts``, ``max_points``, ``rate_hz``); ``docs/options.md`` lists every option
with its CLI flag. A model is scalar (one input, one state, one sensor) when trained on 1-D
arrays, or a vector model (up to 4 inputs, 3 state components and 4 sensors) when trained on
``(T, d)`` arrays; ``docs/vector.md`` describes the vector model.

Example
-------
>>> import hbn
>>> train = hbn.simulate("duhem", 600, seed=1, noise_gain=1.0)
>>> model = hbn.HysteresisModel.fit(train["u"], train["x"], train["y"], max_points=200)
>>> test = hbn.simulate("duhem", 400, seed=2, noise_gain=1.0)
>>> x_hat, x_std = model.estimate(test["u"], test["y"])
>>> x_hat.shape
(400,)

Errors are subclasses of :class:`HbnError`: :class:`ConfigError` (an invalid argument; its
``keyword`` names it), :class:`DataError` (bad data or an unusable log), :class:`ModelFileError`
(not an hbn model or GP of the supported version), :class:`HbnIOError` (a file could not be read
or written; :class:`HbnFileNotFoundError` when it does not exist) and :class:`TrainingError`
(numerical failure). They also derive from ``ValueError``, ``OSError`` /
``FileNotFoundError`` and ``RuntimeError`` respectively, so generic handlers keep working.
"""

from __future__ import annotations

import functools
import inspect
import os
import textwrap
import warnings
from typing import (
    Any,
    Callable,
    Dict,
    Iterator,
    List,
    Mapping,
    Optional,
    Sequence,
    Tuple,
    TypeVar,
    Union,
)

import numpy as np

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

__version__: str = _hbn.__version__

HbnError = _hbn.HbnError
HbnIOError = _hbn.HbnIOError
HbnFileNotFoundError = _hbn.HbnFileNotFoundError
DataError = _hbn.DataError
ModelFileError = _hbn.ModelFileError
ConfigError = _hbn.ConfigError
TrainingError = _hbn.TrainingError
FilterOutput = _hbn.FilterOutput
VectorFilterOutput = _hbn.VectorFilterOutput

#: Names accepted by ``simulate(system=...)``: one input, one state, one sensor.
SYSTEMS: Tuple[str, ...] = tuple(_hbn.systems())
#: Multi-signal systems ``simulate(system=...)`` also takes: several inputs, a vector state and
#: several sensors (``"finger"``: 2 chambers, a planar tip, 3 strain sensors; ``"arm"``: 3
#: chambers, a spatial tip, 4 sensors).
MULTI_SYSTEMS: Tuple[str, ...] = tuple(_hbn.multi_systems())
#: Kernel names accepted by ``kernel=``.
KERNELS: str = _hbn.kernel_names()
#: Inducing points per GP of the default model's sparse candidate (``HysteresisModel.fit``
#: chooses between exact GPs and sparse GPs with this many points on held-out data).
DEFAULT_INDUCING: int = _hbn.DEFAULT_INDUCING
#: Estimation modes accepted by ``mode=``.
MODES: Tuple[str, ...] = tuple(_hbn.mode_names())


def default_params() -> Dict[str, Any]:
    """The training parameters' defaults by keyword (``HbnParams::default`` in Rust; the
    defaults of ``hbn train``), plus the BLR prior (``blr``) and ``signals``.

    ``kernel``, ``transition_kernel`` and ``sensor_kernel`` are ``None``: each GP chooses between
    ``"matern52"`` and ``"se-ard"`` by its evidence. ``None`` in ``n_inducing`` is the exact GP.

    >>> import hbn
    >>> p = hbn.default_params()
    >>> p["max_points"] >= 2 and p["kernel"] is None
    True
    """
    return _hbn.default_params()


def default_log_options() -> Dict[str, Any]:
    """How logs are read by default (``LogOptions::default`` in Rust; ``hbn train`` / ``hbn
    estimate``): ``time_source``, ``max_gap_s`` (seconds), ``rate_hz`` (``None``: the log's native
    rate), the default signal paths ``input``, ``state``, ``output`` and the default ``mode``.

    >>> import hbn
    >>> hbn.default_log_options()["time_source"]
    'log'
    """
    return _hbn.default_log_options()


def default_explore_params() -> Dict[str, Any]:
    """The :class:`Explorer`'s defaults (the library's ``ExploreParams``), by keyword; the
    bounds ``u_min``, ``u_max`` and ``max_step`` have none.

    >>> import hbn
    >>> hbn.default_explore_params()["strategy"]
    'ramps'
    """
    return _hbn.default_explore_params()


def default_gp_params() -> Dict[str, Any]:
    """The defaults of :class:`GaussianProcess` (``GpParams::new`` in Rust), by keyword.

    >>> import hbn
    >>> hbn.default_gp_params()["kernel"]
    'se-ard'
    """
    return _hbn.default_gp_params()


def default_sim_params() -> Dict[str, Any]:
    """The defaults of :func:`simulate`, :class:`Simulator` and :func:`oracle_estimate`
    (``SimConfig::new`` in Rust): ``seed``, ``noise_gain`` (0: noise-free) and ``rate_hz``.

    >>> import hbn
    >>> hbn.default_sim_params()["rate_hz"]
    100.0
    """
    return _hbn.default_sim_params()


def _frozen(v: Any) -> Any:
    """A default value as it appears in a signature: lists become tuples (immutable)."""
    if isinstance(v, list):
        return tuple(_frozen(i) for i in v)
    return v


# The library's defaults, read once: every signature below takes its defaults from these.
_TRAINING: Tuple[str, ...] = tuple(_hbn.training_keywords())
_P: Dict[str, Any] = {k: _frozen(v) for k, v in _hbn.default_params().items()}
_L: Dict[str, Any] = _hbn.default_log_options()
_G: Dict[str, Any] = _hbn.default_gp_params()
_E: Dict[str, Any] = _hbn.default_explore_params()
_S: Dict[str, Any] = _hbn.default_sim_params()

PathLike = Union[str, "os.PathLike[str]"]

_F = TypeVar("_F", bound=Callable[..., Any])


def _renamed(**old_to_new: str) -> Callable[[_F], _F]:
    """Accepts renamed keywords under their deprecated names for one release, with a
    ``DeprecationWarning`` naming the current one. The signature (``help()``,
    ``inspect.signature``) shows only the current names."""

    def wrap(f: _F) -> _F:
        @functools.wraps(f)
        def call(*args: Any, **kwargs: Any) -> Any:
            for old, new in old_to_new.items():
                if old in kwargs:
                    if new in kwargs:
                        raise TypeError(f"{f.__qualname__}() got both {old}= and {new}=")
                    warnings.warn(
                        f"{f.__qualname__}({old}=) is deprecated; use {new}=",
                        DeprecationWarning,
                        stacklevel=2,
                    )
                    kwargs[new] = kwargs.pop(old)
            return f(*args, **kwargs)

        call.__signature__ = inspect.signature(f)  # type: ignore[attr-defined]
        return call  # type: ignore[return-value]

    return wrap


#: The renamed training keywords (``HysteresisModel.fit``, ``from_logs``, ``Explorer``).
_RENAMED = dict(n_restarts="n_starts", max_iter="max_iters", subset="subset_policy")


def _training_args(args: Mapping[str, Any]) -> Dict[str, Any]:
    """The training keywords among a call's arguments (``locals()``), by name."""
    return {k: args[k] for k in _TRAINING if k in args}


def _native(a: Any) -> np.ndarray:
    """``a`` as a contiguous, aligned float64 array, copied only if it is not one already
    (arrays that arrive through pickle protocol 5, e.g. on a Dask worker, can be misaligned)."""
    return np.require(np.asarray(a, dtype=np.float64), requirements=["C", "A"])


def _vector(a: Any, name: str) -> np.ndarray:
    """A contiguous, aligned float64 1-D copy-if-needed of ``a``; ValueError otherwise."""
    try:
        v = _native(a)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must be numeric: {e}") from None
    if v.ndim == 0:
        v = v.reshape(1)
    if v.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {v.shape}")
    return v


def _matrix(a: Any, name: str, dim: Optional[int] = None) -> np.ndarray:
    """A contiguous float64 2-D array (a 1-D input is one feature per row)."""
    try:
        m = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must be numeric: {e}") from None
    if m.ndim == 0:
        m = m.reshape(1, 1)
    elif m.ndim == 1:
        m = m.reshape(-1, 1) if dim in (None, 1) else m.reshape(1, -1)
    if m.ndim != 2:
        raise ValueError(f"{name} must be 1-D or 2-D, got shape {m.shape}")
    if dim is not None and m.shape[1] != dim:
        raise ValueError(f"{name} has {m.shape[1]} features, but the model was fitted with {dim}")
    return _native(m)


def _fspath(path: PathLike) -> str:
    return os.fspath(path)


_NO_VALUE = object()


def _config_error(keyword: str, problem: str, value: Any = _NO_VALUE) -> ConfigError:
    """``invalid keyword=value: problem`` (``invalid keyword: problem`` without a value)."""
    shown = keyword if value is _NO_VALUE else f"{keyword}={value!r}"
    e = ConfigError(f"invalid {shown}: {problem}")
    e.keyword = keyword
    return e


def _float(v: Any, keyword: str) -> float:
    if isinstance(v, (bool, np.bool_)):
        raise _config_error(keyword, "must be a number", v)
    try:
        return float(v)
    except (TypeError, ValueError):
        raise _config_error(keyword, "must be a number", v) from None


def _opt_float(v: Any, keyword: str) -> Optional[float]:
    return None if v is None else _float(v, keyword)


def _opt_str(v: Any) -> Optional[str]:
    return None if v is None else str(v)


def _count(value: Any, keyword: str) -> Optional[int]:
    """A non-negative integer argument (``None`` passes through)."""
    if value is None:
        return None
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise _config_error(keyword, "must be an integer", value)
    if value < 0:
        raise _config_error(keyword, "must be >= 0", value)
    return int(value)


# ------------------------------------------------------------------------------------------------
# GaussianProcess
# ------------------------------------------------------------------------------------------------


class GaussianProcess:
    """Gaussian-process regression, exact or sparse (the engine of the HBN's two GPs).

    It follows scikit-learn: settings in the constructor, then :meth:`fit` on data, because its
    users come from scikit-learn's ``GaussianProcessRegressor``. (:class:`HysteresisModel` is
    built by class methods instead: a trained HBN is immutable.)

    Parameters
    ----------
    kernel : str
        ``"se"`` (isotropic squared exponential), ``"se-ard"`` (one length scale per input),
        ``"matern52"`` (ARD Matern 5/2) or ``"thesis"`` (the thesis' Eq. 19: tanh-warped inputs
        under a Mahalanobis squared exponential, times the direction-advantage factor
        ``(1 + g g') / 2`` with ``g = sign(X[:, 0] - X[:, 1])``, so it needs two features).
    lengthscales, signal_variance, noise_variance : optional
        Hyperparameters in the raw units of the data (``lengthscales``: one per feature for the
        ARD kernels, one value otherwise). With ``optimize=False`` they are used exactly as given
        (missing ones take unit variance and length scales in standardised units); with
        ``optimize=True`` they are the first optimiser start.
    optimize : bool
        Maximise the log marginal likelihood (multi-start L-BFGS on log-parameters).
    normalize : bool
        Standardise inputs (per feature) and targets before the kernel.
    n_starts : int
        Optimiser starts in all (the first from the given or default hyperparameters, the rest
        random); the CLI's ``--starts``. Must be >= 1.
    max_iters : int
        L-BFGS iterations per start.
    max_points : int
        Most support points of the exact GP; larger data sets are reduced by farthest-point
        sampling (the fit reports it in :attr:`warnings_`).
    seed : int
        Seed of the random starts.
    n_inducing : int or None
        ``None`` fits the exact GP (on at most ``max_points`` samples). An integer ``m`` fits
        the sparse GP of Titsias (2009) on every sample with ``m`` inducing points: ``O(n m^2)``
        to train, ``O(m^2)`` per prediction; :meth:`log_marginal_likelihood` is then its
        variational lower bound. The inducing inputs start from greedy conditional-variance
        selection (``docs/sparse.md``); fewer are used if the data have fewer distinct inputs.
    inducing_points : array-like (m x d), optional
        Fixed starting inducing inputs (raw units) for the sparse GP, instead of the selection.
    optimize_inducing : bool
        Learn the inducing inputs together with the hyperparameters (sparse GP only).
    mean : {"constant", "linear"}
        The prior mean. ``"linear"`` subtracts the targets' least-squares plane on the inputs
        before the kernel sees them and adds it back in prediction (its slopes join the mean
        gradient), so a nearly linear relation does not push the kernel to huge length scales
        and signal variances, and predictions far from the data follow the plane. ``"constant"``
        is the targets' mean.

    The defaults are the library's (:func:`default_gp_params`). A fitted GP pickles (its JSON
    inside).

    Examples
    --------
    >>> import numpy as np, hbn
    >>> X = np.linspace(0, 5, 40)
    >>> gp = hbn.GaussianProcess().fit(X, np.sin(X))
    >>> mean, std = gp.predict([[1.0], [2.0]], return_std=True)
    >>> bool(abs(mean[0] - np.sin(1.0)) < 1e-2)
    True

    A sparse GP on every sample of a larger data set (the greedy choice of inducing points
    stops early when the rest of the data add no variance: a sine needs fewer than 32):

    >>> X = np.linspace(0, 5, 5000)
    >>> gp = hbn.GaussianProcess(n_inducing=32).fit(X, np.sin(X))
    >>> gp.is_sparse, 1 <= gp.n_support <= 32
    (True, True)
    >>> bool(abs(gp.predict([[1.0]])[0] - np.sin(1.0)) < 1e-2)
    True
    """

    @_renamed(n_restarts="n_starts", max_iter="max_iters")
    def __init__(
        self,
        kernel: str = _G["kernel"],
        lengthscales: Optional[Union[float, Sequence[float], np.ndarray]] = None,
        signal_variance: Optional[float] = None,
        noise_variance: Optional[float] = None,
        optimize: bool = _G["optimize"],
        normalize: bool = _G["normalize"],
        n_starts: int = _G["n_starts"],
        max_iters: int = _G["max_iters"],
        max_points: int = _G["max_points"],
        seed: int = _G["seed"],
        n_inducing: Optional[int] = None,
        inducing_points: Optional[Any] = None,
        optimize_inducing: bool = _G["optimize_inducing"],
        mean: str = _G["mean"],
    ) -> None:
        self.kernel = kernel
        self.lengthscales = lengthscales
        self.signal_variance = signal_variance
        self.noise_variance = noise_variance
        self.optimize = optimize
        self.normalize = normalize
        self.n_starts = n_starts
        self.max_iters = max_iters
        self.max_points = max_points
        self.seed = seed
        self.n_inducing = n_inducing
        self.inducing_points = inducing_points
        self.optimize_inducing = optimize_inducing
        self.mean = mean
        self._core: Optional[_hbn.GaussianProcessCore] = None

    def __repr__(self) -> str:
        state = f"fitted, n_support={self._core.n_support}" if self._core else "not fitted"
        return f"GaussianProcess(kernel={self.kernel!r}, {state})"

    def __getstate__(self) -> Dict[str, Any]:
        state = self.__dict__.copy()
        core = state.pop("_core")
        state["_json"] = None if core is None else core.to_json()
        return state

    def __setstate__(self, state: Dict[str, Any]) -> None:
        state = dict(state)
        text = state.pop("_json")
        self.__dict__.update(state)
        self._core = None if text is None else _hbn.GaussianProcessCore.from_json(text)

    def _fitted(self) -> _hbn.GaussianProcessCore:
        if self._core is None:
            raise ValueError("this GaussianProcess is not fitted yet; call fit(X, y) first")
        return self._core

    def fit(self, X: Any, y: Any) -> GaussianProcess:
        """Fits the GP to inputs ``X`` (``n x d``, or 1-D for one feature) and targets ``y`` (``n``).

        Returns ``self``. Raises ``ValueError`` for NaN/Inf values, mismatched lengths, constant
        targets, an unknown kernel or invalid hyperparameters.

        >>> import hbn
        >>> gp = hbn.GaussianProcess(optimize=False).fit([0.0, 1.0, 2.0], [0.0, 1.0, 0.5])
        >>> gp.n_support
        3
        """
        Xm = _matrix(X, "X")
        yv = _vector(y, "y")
        if Xm.shape[0] != yv.shape[0]:
            raise ValueError(
                f"X and y must have the same number of samples (got {Xm.shape[0]} and {yv.shape[0]})"
            )
        ls = self.lengthscales
        if ls is not None:
            ls = [float(v) for v in np.atleast_1d(np.asarray(ls, dtype=np.float64))]
        m = _count(self.n_inducing, "n_inducing")
        Z = None
        if self.inducing_points is not None:
            if m is None:
                raise ValueError("inducing_points needs n_inducing (the sparse GP)")
            Z = _matrix(self.inducing_points, "inducing_points", Xm.shape[1])
            if Z.shape[0] != m:
                raise ValueError(f"inducing_points has {Z.shape[0]} rows but n_inducing is {m}")
            Z = Z.ravel()
        self._core = _hbn.GaussianProcessCore.fit(
            Xm.ravel(),
            Xm.shape[1],
            yv,
            str(self.kernel),
            ls,
            _opt_float(self.signal_variance, "signal_variance"),
            _opt_float(self.noise_variance, "noise_variance"),
            None if self.optimize is None else bool(self.optimize),
            None if self.normalize is None else bool(self.normalize),
            _count(self.n_starts, "n_starts"),
            _count(self.max_iters, "max_iters"),
            _count(self.max_points, "max_points"),
            _count(self.seed, "seed"),
            m,
            Z,
            bool(self.optimize_inducing),
            _opt_str(self.mean),
        )
        return self

    def predict(
        self, X: Any, return_std: bool = False, return_grad: bool = False
    ) -> Union[np.ndarray, Tuple[np.ndarray, ...]]:
        """Predictive mean at ``X``; optionally its standard deviation and input gradient.

        Returns ``mean`` (``n``), or a tuple ``(mean, std)``, ``(mean, grad)`` or
        ``(mean, std, grad)``. ``std`` is the latent function's (noise excluded, as in
        scikit-learn); ``grad`` has shape ``(n, d)``: ``d mean / d X``.

        >>> import numpy as np, hbn
        >>> gp = hbn.GaussianProcess().fit(np.linspace(0, 3, 30), np.linspace(0, 3, 30) ** 2)
        >>> mean, grad = gp.predict([1.5], return_grad=True)
        >>> grad.shape
        (1, 1)
        """
        core = self._fitted()
        Xm = _matrix(X, "X", core.dim)
        mean, var, grad = core.predict(Xm.ravel(), bool(return_std), bool(return_grad))
        out: List[np.ndarray] = [mean]
        if return_std:
            out.append(np.sqrt(np.maximum(var, 0.0)))
        if return_grad:
            out.append(grad.reshape(Xm.shape[0], core.dim))
        return out[0] if len(out) == 1 else tuple(out)

    def log_marginal_likelihood(self) -> float:
        """Log marginal likelihood at the fitted hyperparameters (for a sparse GP, its
        variational lower bound).

        Of the standardised targets when ``normalize=True`` (of the raw targets otherwise, equal to
        scikit-learn's ``log_marginal_likelihood_value_``).

        >>> import hbn
        >>> gp = hbn.GaussianProcess(optimize=False, normalize=False).fit([0.0, 1.0], [0.0, 1.0])
        >>> isinstance(gp.log_marginal_likelihood(), float)
        True
        """
        return self._fitted().log_marginal_likelihood()

    @property
    def hyperparameters(self) -> Dict[str, Any]:
        """Fitted hyperparameters: ``signal_variance``, ``lengthscales`` (array), ``noise_variance``
        (raw units) and ``theta`` (the log-parameterised vector in standardised units).

        >>> import hbn
        >>> gp = hbn.GaussianProcess(signal_variance=2.0, optimize=False, normalize=False)
        >>> round(gp.fit([0.0, 1.0], [0.0, 1.0]).hyperparameters["signal_variance"], 12)
        2.0
        """
        core = self._fitted()
        return {
            "signal_variance": core.signal_variance,
            "lengthscales": np.asarray(core.length_scales, dtype=np.float64),
            "noise_variance": core.noise_variance,
            "theta": np.asarray(core.theta, dtype=np.float64),
        }

    @property
    def n_support(self) -> int:
        """Number of support points kept (exact) or inducing points used (sparse).

        >>> import hbn
        >>> hbn.GaussianProcess(optimize=False).fit([0.0, 1.0, 2.0], [1.0, 0.0, 1.0]).n_support
        3
        """
        return self._fitted().n_support

    @property
    def is_sparse(self) -> bool:
        """True for a sparse (inducing-point) GP."""
        return self._fitted().is_sparse

    @property
    def inducing_points_(self) -> np.ndarray:
        """The sparse GP's inducing inputs (``m x d``, raw units) after fitting.

        >>> import numpy as np, hbn
        >>> X = np.linspace(0, 5, 500)
        >>> hbn.GaussianProcess(n_inducing=8).fit(X, np.sin(X)).inducing_points_.shape
        (8, 1)
        """
        core = self._fitted()
        if not core.is_sparse:
            raise ValueError("an exact GP has no inducing points (fit with n_inducing=m)")
        return np.asarray(core.support_inputs, dtype=np.float64).reshape(-1, core.dim)

    @property
    def n_features_in_(self) -> int:
        """Number of input features seen in ``fit``."""
        return self._fitted().dim

    @property
    def warnings_(self) -> List[str]:
        """Training warnings (subset, Cholesky jitter, failed optimiser starts); empty if clean."""
        return list(self._fitted().warnings())

    @property
    def report_(self) -> Dict[str, Any]:
        """The training report (starts, evaluations, jitter, seconds) as a dict."""
        return self._fitted().report()

    def save(self, path: PathLike) -> None:
        """Writes the fitted GP to a JSON file (atomically).

        >>> import hbn, tempfile, os
        >>> gp = hbn.GaussianProcess(optimize=False).fit([0.0, 1.0, 2.0], [1.0, 0.0, 1.0])
        >>> p = os.path.join(tempfile.mkdtemp(), "gp.json"); gp.save(p)
        >>> hbn.GaussianProcess.load(p).n_support
        3
        """
        self._fitted().save(_fspath(path))

    @classmethod
    def load(cls, path: PathLike) -> GaussianProcess:
        """Loads a GP written by :meth:`save` (:class:`HbnFileNotFoundError` if missing,
        :class:`ModelFileError` if the file is not an hbn GP of the supported version)."""
        return cls._from_core(_hbn.GaussianProcessCore.load(_fspath(path)))

    @classmethod
    def _from_core(cls, core: _hbn.GaussianProcessCore) -> GaussianProcess:
        gp = cls(kernel=core.kernel)
        gp._core = core
        return gp


# ------------------------------------------------------------------------------------------------
# HysteresisModel
# ------------------------------------------------------------------------------------------------


class Estimate:
    """Per-sample results of :meth:`HysteresisModel.estimate`.

    Attributes: ``x`` (estimate of the state), ``x_std`` (its standard deviation), ``y_pred``
    (predicted measurement before the update), ``innovation``, ``nis`` (normalised innovation
    squared), ``q_x`` (process noise variance used), ``r`` (measurement noise variance used),
    ``flags`` (guard bits, ``uint32``; see :meth:`flag_names`), ``obs_min`` / ``obs_max``
    (eigenvalues of the observability Gramian, NaN for the first samples), ``obs_x`` (the
    Gramian's information on ``x`` alone, the other state components left free), ``mode``, and ``t``
    (seconds from the first grid sample; only for :meth:`HysteresisModel.estimate_log`).

    A scalar model's arrays have shape ``(T,)``, or ``(T, 1)`` for ``x``, ``x_std``, ``y_pred``
    and ``innovation`` when it was given ``(T, 1)`` arrays. A vector model's have shape
    ``(T, dx)`` (``x``, ``x_std``), ``(T, dx, dx)`` (``x_cov``, the covariance of the state) and
    ``(T, dy)`` (``y_pred``, ``innovation``); ``nis`` and ``flags`` are ``(T,)``, and
    ``unobservable`` gives per state component the fraction of windows of 20 samples in which no
    sensor saw it. ``x_cov`` and ``unobservable`` are ``None`` for a scalar model; ``q_x``,
    ``r``, ``obs_min``, ``obs_max`` and ``obs_x`` are ``None`` for a vector model.

    Unpacks as ``x, x_std = model.estimate(u, y)``.

    >>> import hbn
    >>> tr = hbn.simulate("duhem", 300, seed=1)
    >>> m = hbn.HysteresisModel.fit(tr["u"], tr["x"], tr["y"], max_points=100, n_starts=1)
    >>> est = m.estimate(tr["u"], tr["y"])
    >>> x_hat, x_std = est
    >>> est.flags.dtype.name
    'uint32'
    """

    FLAG_NAMES: Tuple[str, ...] = tuple(_hbn.flag_names())

    __slots__ = (
        "x",
        "x_std",
        "y_pred",
        "innovation",
        "nis",
        "q_x",
        "r",
        "flags",
        "obs_min",
        "obs_max",
        "obs_x",
        "x_cov",
        "unobservable",
        "mode",
        "t",
    )

    def __init__(
        self, fields: Mapping[str, np.ndarray], mode: str, t: Optional[np.ndarray] = None
    ) -> None:
        self.x: np.ndarray = fields["x"]
        self.x_std: np.ndarray = fields["x_std"]
        self.y_pred: np.ndarray = fields["y_pred"]
        self.innovation: np.ndarray = fields["innovation"]
        self.nis: np.ndarray = fields["nis"]
        self.q_x: Optional[np.ndarray] = fields.get("q_x")
        self.r: Optional[np.ndarray] = fields.get("r")
        self.flags: np.ndarray = fields["flags"]
        self.obs_min: Optional[np.ndarray] = fields.get("obs_min")
        self.obs_max: Optional[np.ndarray] = fields.get("obs_max")
        self.obs_x: Optional[np.ndarray] = fields.get("obs_x")
        self.x_cov: Optional[np.ndarray] = fields.get("x_cov")
        self.unobservable: Optional[np.ndarray] = fields.get("unobservable")
        self.mode: str = mode
        self.t: Optional[np.ndarray] = t

    def __iter__(self) -> Iterator[np.ndarray]:
        yield self.x
        yield self.x_std

    def __len__(self) -> int:
        return len(self.x)

    def __repr__(self) -> str:
        return f"Estimate(mode={self.mode!r}, n={len(self.x)})"

    def flag_names(self, k: int) -> List[str]:
        """Names of the guard flags set at sample ``k``."""
        f = int(self.flags[k])
        return [n for i, n in enumerate(self.FLAG_NAMES) if f & (1 << i)]

    def flag_counts(self) -> Dict[str, int]:
        """How many samples had each guard flag set."""
        out: Dict[str, int] = {}
        for i, n in enumerate(self.FLAG_NAMES):
            c = int(np.count_nonzero(self.flags & np.uint32(1 << i)))
            if c:
                out[n] = c
        return out

    def to_dict(self) -> Dict[str, np.ndarray]:
        """All arrays by name (those the model's kind has)."""
        return {
            k: v
            for k in self.__slots__
            if k not in ("mode", "t") and (v := getattr(self, k)) is not None
        }

    def score(self, x_ref: Any) -> Dict[str, Any]:
        """Scores against the true state ``x_ref`` (same shape as ``x``), as ``hbn eval`` reports
        them: ``rmse``, ``nrmse`` (RMSE over the reference's range), ``coverage_1sigma`` and
        ``coverage_2sigma`` (fraction of samples with ``|x_ref - x| <= k * x_std``; about 0.683
        and 0.954 when the uncertainty is honest), ``mean_nees`` (mean of
        ``((x_ref - x) / x_std)^2``, about 1 when honest), ``nlpd`` (mean negative log predictive
        density, lower is better) and ``samples`` (those scored: finite, ``x_std > 0``). For a
        ``(T, d)`` estimate each score is an array of ``d``, one per state component.

        >>> import hbn
        >>> tr = hbn.simulate("duhem", 300, seed=1)
        >>> m = hbn.HysteresisModel.fit(tr["u"], tr["x"], tr["y"], max_points=100, n_starts=1)
        >>> te = hbn.simulate("duhem", 200, seed=2)
        >>> s = m.estimate(te["u"], te["y"]).score(te["x"])
        >>> sorted(s)[:3], s["samples"]
        (['coverage_1sigma', 'coverage_2sigma', 'mean_nees'], 200)
        """
        return _score(np.asarray(self.x), np.asarray(self.x_std), _reference(self.x, x_ref))


def _reference(x: Any, x_ref: Any) -> np.ndarray:
    """``x_ref`` as a float64 array of the shape of the estimate ``x`` (a ``(T,)`` reference
    of a ``(T, 1)`` estimate is reshaped); ``DataError`` otherwise."""
    x = np.asarray(x)
    ref = np.asarray(x_ref, dtype=np.float64)
    if x.ndim == 1 and ref.shape != x.shape:
        raise DataError(f"x and x_ref must have the same length (got {x.shape}, {ref.shape})")
    if ref.ndim == 1 and x.ndim == 2 and x.shape[1] == 1:
        ref = ref.reshape(-1, 1)
    if ref.shape != x.shape:
        raise DataError(f"x_ref must have the shape of x, {x.shape}; got {ref.shape}")
    return ref


def _score(x: np.ndarray, x_std: np.ndarray, ref: np.ndarray) -> Dict[str, Any]:
    """:meth:`Estimate.score` of arrays of one shape, ``(T,)`` or ``(T, d)``."""
    if x.ndim == 1:
        return dict(_hbn.score(_vector(x, "x"), _vector(x_std, "x_std"), _vector(ref, "x_ref")))
    cols = [
        _hbn.score(_native(x[:, i]), _native(x_std[:, i]), _native(ref[:, i]))
        for i in range(x.shape[1])
    ]
    return {k: np.array([c[k] for c in cols]) for k in cols[0]} if cols else {}


def pooled_score(estimates: Sequence[Estimate], x_refs: Sequence[Any]) -> Dict[str, Any]:
    """Scores of several estimates (one per log) against their true states, pooled sample by
    sample, as ``hbn eval`` with several ``--log`` reports them: the keys of
    :meth:`Estimate.score`, computed over every sample of every estimate at once (the ``nrmse``
    over the reference's range in all of them). A band is judged far better on several logs
    with different inputs than on one.

    >>> import hbn
    >>> tr = hbn.simulate("duhem", 300, seed=1)
    >>> m = hbn.HysteresisModel.fit(tr["u"], tr["x"], tr["y"], max_points=100, n_starts=1)
    >>> tests = [hbn.simulate("duhem", n, seed=s) for n, s in ((200, 2), (100, 3))]
    >>> ests = [m.estimate(t["u"], t["y"]) for t in tests]
    >>> hbn.pooled_score(ests, [t["x"] for t in tests])["samples"]
    300
    """
    estimates, x_refs = list(estimates), list(x_refs)
    if len(estimates) != len(x_refs) or not estimates:
        raise DataError(
            f"pooled_score needs one reference per estimate and at least one of each "
            f"(got {len(estimates)} estimates and {len(x_refs)} references)"
        )
    refs = [_reference(e.x, r) for e, r in zip(estimates, x_refs)]
    shapes = {np.asarray(e.x).shape[1:] for e in estimates}
    if len(shapes) != 1:
        raise DataError(f"the estimates must have one state dimension; got shapes {sorted(shapes)}")
    return _score(
        np.concatenate([np.asarray(e.x) for e in estimates]),
        np.concatenate([np.asarray(e.x_std) for e in estimates]),
        np.concatenate(refs),
    )


def _signal(a: Any, name: str) -> np.ndarray:
    """One trajectory of a signal: a contiguous float64 array of shape ``(T,)`` or ``(T, d)``."""
    try:
        v = _native(a)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{name} must be numeric: {e}") from None
    if v.ndim == 0:
        v = v.reshape(1)
    if v.ndim > 2:
        raise ValueError(f"{name} must be 1-D (T,) or 2-D (T, d), got shape {v.shape}")
    return v


def _trajectories(a: Any, name: str) -> List[np.ndarray]:
    """A list of arrays is a list of trajectories; anything else is one trajectory."""
    if isinstance(a, (list, tuple)) and len(a) > 0 and np.ndim(a[0]) >= 1:
        return [_signal(t, f"{name}[{i}]") for i, t in enumerate(a)]
    return [_signal(a, name)]


def _widths(us: List[np.ndarray], xs: List[np.ndarray], ys: List[np.ndarray]) -> Optional[Tuple[int, int, int]]:
    """``None`` for 1-D trajectories, else the widths ``(du, dx, dy)`` of ``(T, d)`` ones
    (:class:`DataError` unless every array is 1-D or every array is 2-D, with one width per
    signal)."""
    arrays = [("u", a) for a in us] + [("x", a) for a in xs] + [("y", a) for a in ys]
    dims = {a.ndim for _, a in arrays}
    if dims == {1}:
        return None
    if dims != {2}:
        shapes = ", ".join(f"{n} {a.shape}" for n, a in arrays[:6])
        raise DataError(
            "u, x and y must all be 1-D (T,) arrays (a scalar model) or all 2-D (T, d) arrays "
            f"(a vector model; reshape a single signal with a.reshape(-1, 1)), got {shapes}"
        )
    out = []
    for n, group in (("u", us), ("x", xs), ("y", ys)):
        widths = {a.shape[1] for a in group}
        if len(widths) != 1:
            raise DataError(f"every trajectory of {n} must have the same columns, got {sorted(widths)}")
        out.append(widths.pop())
    return (out[0], out[1], out[2])


def _names(signals: Optional[Mapping[str, Any]], dims: Tuple[int, int, int]) -> Optional[Tuple[List[str], List[str], List[str]]]:
    """A vector model's signal names from ``signals={"u": [...], "x": [...], "y": [...]}``."""
    if signals is None:
        return None
    unknown = set(signals) - {"u", "x", "y"}
    if unknown:
        raise _config_error("signals", f"unknown keys {sorted(unknown)}; use u, x and y", dict(signals))
    out = []
    for key, d in zip(("u", "x", "y"), dims):
        given = signals.get(key)
        if given is None:
            out.append([])
            continue
        names = [given] if isinstance(given, str) else list(given)
        if len(names) != d or not all(isinstance(n, str) for n in names):
            raise _config_error(
                "signals", f"{key} takes a list of {d} names or message paths, one per column", dict(signals)
            )
        out.append(names)
    return (out[0], out[1], out[2])


def _paths(v: Any, keyword: str) -> List[str]:
    """``input=`` / ``state=`` / ``output=`` as a list of message paths."""
    if isinstance(v, (str, os.PathLike)):
        return [str(v)]
    try:
        paths = [str(p) for p in v]
    except TypeError:
        raise _config_error(keyword, "must be a message path or a list of them", v) from None
    if not paths:
        raise _config_error(keyword, "give at least one message path", v)
    return paths


def _scalar_only(what: str, dims: Tuple[int, int, int]) -> ValueError:
    du, dx, dy = dims
    return ValueError(
        f"{what} takes scalar models (one input, one state, one sensor); this is a vector model "
        f"of {du} inputs, {dx} state components and {dy} sensors"
    )




_TRAINING_PARAMETERS_DOC = """
    Training parameters (keyword-only; the defaults are :func:`default_params`, the defaults
    of ``hbn train``; ``docs/options.md`` says when to change each):

    kernel : str, list of str or None
        Kernel of both GPs (one of :data:`KERNELS`). ``None``: each GP chooses between
        ``"matern52"`` and ``"se-ard"`` by its evidence, the exact GP's log marginal likelihood
        (the table is ``summary["kernel_evidence"]``); naming a kernel turns that off. A list
        is chosen among on held-out data (model selection, below).
    transition_kernel, sensor_kernel : str or None
        The kernel of one GP (overrides ``kernel``).
    n_inducing : int, None or list
        ``None``: exact GPs on at most ``max_points`` samples each; an integer: sparse GPs with
        that many inducing points, trained on every sample; a list (``None`` being the exact
        GP) is chosen among on held-out data. The default lets the held-out data choose
        between exact GPs and sparse GPs of :data:`DEFAULT_INDUCING` points.
    max_points : int
        Most support points of each exact GP.
    subset_policy : {"farthest-point", "random"}
        How the support points are chosen when there are more samples.
    n_starts : int
        Optimiser starts per GP.
    max_iters : int
        L-BFGS iterations per start.
    seed : int
        Seed of the random starts and subsets.
    normalize : bool
        Standardise GP inputs and outputs.
    noise_floor : float
        Lower bound of each GP's noise variance (standardised units).
    blr_window : float
        Half-width of the EKF+BLR window, as a fraction of each coordinate's range.
    validation : float
        Fraction of every run held out at a time (blocked cross-validation: 0.25 holds out
        each quarter of every run in turn) to learn the filter's noise scales and default mode
        (:attr:`HysteresisModel.tuning`) and to choose among candidates; 0 turns this off.
    memory : list of float
        The input's long memory: radii of play operators whose outputs the transition GP reads
        besides ``u_{k-1}`` and ``u_{k-2}``, as fractions of the training input's range (at most
        4); ``[]`` for the thesis' four inputs (``docs/memory.md``).
    lags : list of float, or list of lists
        Time constants (seconds) of first-order low-pass filters of the input that the
        transition GP reads after the plays, for creep and relaxation (plays and lags at most 4
        in all). A list of lists: the first set is the primary one, the others are tried on
        held-out data with the sparse candidates; ``[]`` trains without lags and tries none.
        Left out, a vector model tries none, 0.1 s and 1 s, side by side (``docs/vector.md``).
    linear_mean : {"none", "transition", "both"}
        Which GPs have a linear prior mean (see :class:`GaussianProcess`).
    sensor_inputs : str or list of str
        What the sensor GP reads: ``"thesis"``, ``[x_{k-1}, y_{k-1}, x_k]``; ``"memory"``,
        ``x_k`` and two play operators of the state (the history a hysteretic sensor's output
        depends on); or ``"state"``, ``[x_{k-1}, x_k]``. A list is chosen among on held-out
        data, the first being the primary one; the default is ``["thesis", "memory"]``
        (``docs/memory.md``). Vector models take ``"thesis"`` or ``"state"``.
    max_signal_variance : float or None
        Largest GP signal variance, as a multiple of the variance each kernel models; ``None``
        for only the ``1e5`` box.
    firmware_budget : int, str or None
        Train what fits this much firmware flash (the ``f32`` export's tables): bytes, or a
        size such as ``"16KB"``, ``"64KB"`` or ``"1MB"``. Sparse GPs with the most inducing
        points (64 down to 8) that fit, a thinned initial-state table and a default mode that
        fits (``docs/firmware.md``); ``None``: no budget. Scalar models only: a vector model
        given a budget raises :class:`ConfigError`.

    ``None`` keeps a parameter's default, except ``n_inducing=None`` (exact GPs). A bad value
    raises :class:`ConfigError` whose ``keyword`` names it.

    Model selection: every combination of a kernel and an inducing setting is a candidate,
    each sparse one also with every further lag set, and the first one also with every further
    sensor. Each is trained and its filter tuned on the same held-out data; the one whose
    default mode has the lowest held-out NLPD among those at least as accurate held out (nRMSE)
    as the first becomes the model, leaving out candidates whose filter loses the state on
    their own training runs while another does not. Each candidate costs one training. The
    table is ``summary["validation"]["candidates"]``, and :attr:`HysteresisModel.params` holds
    the configuration chosen. A vector model's candidates are each inducing setting with each
    lag set, by the same rule (``summary["candidates"]``, ``docs/vector.md``).

"""


class HysteresisModel:
    """The Hysteresis Bayesian Network: a transition GP ``x_k = H_D(x_{k-1}, x_{k-2}, u_{k-1},
    u_{k-2}, ...)`` and a sensor GP ``y_k = H_S(x_{k-1}, y_{k-1}, x_k)``, with a filter (EKF,
    EKF with local Bayesian linear regression, or UKF) that estimates ``x`` from ``u`` and ``y``
    alone.

    Build one with :meth:`fit` (arrays), :meth:`from_logs` (MCAP logs, like ``hbn train``),
    :meth:`load` (files of ``hbn train --out``) or :meth:`from_bytes`. These are class methods,
    not scikit-learn's constructor-then-``fit``: a trained model is immutable, and the
    constructors are siblings. A model pickles with its model file inside, so
    ``concurrent.futures``, ``multiprocessing`` and Dask carry it to other processes.

    The same class holds a vector model (:attr:`is_vector`): several inputs, a vector state and
    several sensors (:attr:`dims`), one transition GP per state component and one sensor GP
    per sensor (``docs/vector.md``). :meth:`fit` makes one from ``(T, d)`` arrays and
    :meth:`from_logs` from lists of message paths; :meth:`estimate`, :meth:`estimate_log`,
    :meth:`filter`, the files and pickling work alike. :meth:`simulate_open_loop`,
    :meth:`initial_state`, :attr:`tuning`, :attr:`transition`, :attr:`sensor` and the
    :class:`Explorer` take scalar models only (:attr:`transition_gps` and :attr:`sensor_gps`
    list a vector model's GPs).

    >>> import hbn
    >>> tr = hbn.simulate("maxwell-slip", 500, seed=1, noise_gain=1.0)
    >>> model = hbn.HysteresisModel.fit(tr["u"], tr["x"], tr["y"], max_points=150)
    >>> te = hbn.simulate("maxwell-slip", 300, seed=2, noise_gain=1.0)
    >>> x_hat, x_std = model.estimate(te["u"], te["y"])
    >>> model.rate_hz
    100.0
    """

    def __init__(self, core: Union[_hbn.HysteresisModelCore, _hbn.VectorModelCore]) -> None:
        if not isinstance(core, (_hbn.HysteresisModelCore, _hbn.VectorModelCore)):
            raise TypeError(
                "use HysteresisModel.fit(...), HysteresisModel.from_logs(...) or "
                "HysteresisModel.load(path)"
            )
        self._core = core

    def __repr__(self) -> str:
        if self.is_vector:
            du, dx, dy = self.dims
            return (
                f"HysteresisModel(vector: {du} inputs, {dx} states, {dy} sensors, "
                f"rate_hz={self.rate_hz}, default_mode={self.default_mode!r})"
            )
        p = self.params
        return (
            f"HysteresisModel(rate_hz={self.rate_hz}, transition_kernel="
            f"{p['transition_kernel']!r}, sensor_kernel={p['sensor_kernel']!r}, "
            f"n_inducing={p['n_inducing']!r})"
        )

    def __reduce__(self) -> Tuple[Any, Tuple[bytes]]:
        return (_model_from_bytes, (self.to_bytes(),))

    @classmethod
    @_renamed(rate="rate_hz", **_RENAMED)
    def fit(
        cls,
        u: Any,
        x: Any,
        y: Any,
        rate_hz: float = _P["rate_hz"],
        signals: Optional[Mapping[str, Any]] = None,
        *,
        kernel: Union[str, Sequence[str], None] = _P["kernel"],
        transition_kernel: Optional[str] = _P["transition_kernel"],
        sensor_kernel: Optional[str] = _P["sensor_kernel"],
        n_inducing: Union[int, None, Sequence[Optional[int]]] = _P["n_inducing"],
        max_points: int = _P["max_points"],
        subset_policy: str = _P["subset_policy"],
        n_starts: int = _P["n_starts"],
        max_iters: int = _P["max_iters"],
        seed: int = _P["seed"],
        normalize: bool = _P["normalize"],
        noise_floor: float = _P["noise_floor"],
        blr_window: float = _P["blr_window"],
        validation: float = _P["validation"],
        memory: Sequence[float] = _P["memory"],
        lags: Union[Sequence[float], Sequence[Sequence[float]]] = _P["lags"],
        linear_mean: str = _P["linear_mean"],
        sensor_inputs: Union[str, Sequence[str]] = _P["sensor_inputs"],
        max_signal_variance: Optional[float] = _P["max_signal_variance"],
        firmware_budget: Union[int, str, None] = _P["firmware_budget"],
    ) -> HysteresisModel:
        """Learns the GPs from logged trajectories sampled at ``rate_hz`` Hz.

        ``u``, ``x``, ``y``: one trajectory (arrays of equal length, at least 3 samples) or
        lists of trajectories (rows never straddle two trajectories). 1-D arrays ``(T,)`` train
        a scalar model. 2-D arrays ``(T, du)``, ``(T, dx)``, ``(T, dy)`` (all three 2-D) train a
        vector model when any width is above 1 (at most 4 inputs, 3 state components and 4
        sensors; ``docs/vector.md``), and a scalar model when all are 1, whose :meth:`estimate`
        then returns ``(T, 1)`` arrays for ``(T, 1)`` inputs. ``signals`` (optional) records
        where the signals come from, ``{"u": "/valve.pressure", "x": ..., "y": ...}`` (or
        ``{"name", "path", "unit"}`` dicts as values; for a vector model a list of names or
        message paths per key, one per column): ``hbn estimate --model`` then reads ``u`` and
        ``y`` from those message paths. To train from MCAP logs use :meth:`from_logs`, which
        keeps the logs' rate. ``x`` may be NaN where the state was not measured (a camera slower
        than ``u`` and ``y``, or dropped frames; for a vector model, per component): those
        samples are latent, and training runs expectation-maximisation over them
        (``docs/slow-camera.md``);
        a trajectory whose ``x`` is NaN throughout (only ``u`` and ``y`` logged) joins its
        refits, beside at least one trajectory with a measured state;
        ``summary["latent"]`` records how much was measured and what each round scored. A
        vector model takes the same training keywords. It chooses its
        mode, its process-noise scale, each component's standard-deviation scale and, with the
        default ``sensor_inputs``, each sensor's inputs on the held-out last quarter of every
        trajectory; ``sensor_inputs`` given as one value applies to every sensor, as a list to
        each sensor in turn (as ``hbn train --sensor-inputs``).
        {training}
        >>> import hbn
        >>> runs = [hbn.simulate("duhem", 200, seed=s, noise_gain=1.0) for s in (1, 2)]
        >>> m = hbn.HysteresisModel.fit([r["u"] for r in runs], [r["x"] for r in runs],
        ...                             [r["y"] for r in runs], max_points=100, n_starts=1)
        >>> m.summary["trajectories"]
        2
        """
        us, xs, ys = _trajectories(u, "u"), _trajectories(x, "x"), _trajectories(y, "y")
        if signals is not None and not isinstance(signals, Mapping):
            raise _config_error(
                "signals", 'must be a dict like {"u": "/topic.field", "x": ..., "y": ...}', signals
            )
        params = _training_args(locals())
        dims = _widths(us, xs, ys)
        if dims is not None and dims != (1, 1, 1):
            flat = lambda arrays: [a.ravel() for a in arrays]  # noqa: E731
            return cls(
                _hbn.VectorModelCore.fit(
                    flat(us), flat(xs), flat(ys), dims, _names(signals, dims), params
                )
            )
        if dims is not None:
            us, xs, ys = [a[:, 0] for a in us], [a[:, 0] for a in xs], [a[:, 0] for a in ys]
        core = _hbn.HysteresisModelCore.fit(
            us, xs, ys, None if signals is None else dict(signals), params
        )
        return cls(core)

    @classmethod
    @_renamed(paths="logs", rate="rate_hz", max_gap="max_gap_s", **_RENAMED)
    def from_logs(
        cls,
        logs: Union[PathLike, Sequence[PathLike]],
        input: Union[str, Sequence[str]] = _L["input"],
        state: Union[str, Sequence[str]] = _L["state"],
        output: Union[str, Sequence[str]] = _L["output"],
        rate_hz: Optional[float] = _L["rate_hz"],
        time_source: str = _L["time_source"],
        max_gap_s: float = _L["max_gap_s"],
        min_coverage: float = _L["min_coverage"],
        min_state_samples: int = _L["min_state_samples"],
        *,
        kernel: Union[str, Sequence[str], None] = _P["kernel"],
        transition_kernel: Optional[str] = _P["transition_kernel"],
        sensor_kernel: Optional[str] = _P["sensor_kernel"],
        n_inducing: Union[int, None, Sequence[Optional[int]]] = _P["n_inducing"],
        max_points: int = _P["max_points"],
        subset_policy: str = _P["subset_policy"],
        n_starts: int = _P["n_starts"],
        max_iters: int = _P["max_iters"],
        seed: int = _P["seed"],
        normalize: bool = _P["normalize"],
        noise_floor: float = _P["noise_floor"],
        blr_window: float = _P["blr_window"],
        validation: float = _P["validation"],
        memory: Sequence[float] = _P["memory"],
        lags: Union[Sequence[float], Sequence[Sequence[float]]] = _P["lags"],
        linear_mean: str = _P["linear_mean"],
        sensor_inputs: Union[str, Sequence[str]] = _P["sensor_inputs"],
        max_signal_variance: Optional[float] = _P["max_signal_variance"],
        firmware_budget: Union[int, str, None] = _P["firmware_budget"],
    ) -> HysteresisModel:
        """Trains from MCAP logs exactly like ``hbn train`` (the same Rust function): each log is
        one trajectory; the same logs and parameters give a byte-identical model file.

        ``logs``: one path or several (the CLI's ``--log``). ``input``, ``state``, ``output``:
        message paths of ``u``, ``x``, ``y`` (``/topic.field``; the defaults are the topics
        ``hbn simulate`` writes). Lists of paths, one per signal in order (the CLI's repeated
        ``--input``, ``--state``, ``--output``), train a vector model when any list has more
        than one (a single string stays scalar). ``rate_hz``: grid rate in Hz (``None``: the native rate of
        ``input`` in the first log, rounded to 0.1 Hz); the model keeps it. ``time_source``
        (``"log"`` or ``"header"``) and ``max_gap_s`` (the largest gap between two samples of a
        signal, seconds) say how the logs are read (``docs/your-robot.md``). ``min_coverage``:
        warn when a signal spans less than this fraction of its log; ``min_state_samples``: the
        fewest state samples, over all logs, where all signals overlap (fewer is an error).
        {training}
        >>> import hbn
        >>> m = hbn.HysteresisModel.from_logs("fixtures/json_zstd.mcap", input="/input.data",
        ...     state="/state.data", output="/sensor.data", max_points=80)  # doctest: +SKIP
        """
        paths = [logs] if isinstance(logs, (str, os.PathLike)) else list(logs)
        args = locals()
        params = {k: v for k, v in _training_args(args).items() if k != "rate_hz"}
        signals = [_paths(input, "input"), _paths(state, "state"), _paths(output, "output")]
        if any(len(p) > 1 for p in signals):
            return cls(
                _hbn.VectorModelCore.from_logs(
                    [_fspath(p) for p in paths],
                    *signals,
                    _opt_float(rate_hz, "rate_hz"),
                    str(time_source),
                    _float(max_gap_s, "max_gap_s"),
                    params,
                    _float(min_coverage, "min_coverage"),
                    _count(min_state_samples, "min_state_samples"),
                )
            )
        core = _hbn.HysteresisModelCore.from_logs(
            [_fspath(p) for p in paths],
            signals[0][0],
            signals[1][0],
            signals[2][0],
            _opt_float(rate_hz, "rate_hz"),
            str(time_source),
            _float(max_gap_s, "max_gap_s"),
            params,
            _float(min_coverage, "min_coverage"),
            _count(min_state_samples, "min_state_samples"),
        )
        return cls(core)

    def estimate(self, u: Any, y: Any, mode: Optional[str] = None) -> Estimate:
        """Estimates the state from the input ``u`` and the sensor output ``y`` (same length, at
        the model's rate). ``mode``: one of :data:`MODES` (``"ekf"``, ``"ekf-blr"``, ``"ukf"``;
        ``None``: the model's :attr:`default_mode`, as ``hbn estimate`` without ``--mode``; a
        vector model runs ``"ekf"`` or ``"ukf"``).

        A scalar model takes 1-D arrays and returns ``(T,)`` arrays, or ``(T, 1)`` arrays given
        ``(T, 1)`` ones. A vector model takes ``u`` of shape ``(T, du)`` and ``y`` of shape
        ``(T, dy)`` (a 1-D array for a single input or sensor) and returns ``(T, dx)`` arrays
        (:class:`Estimate` lists them all).

        NaN/Inf samples are allowed (sensor drop-outs): the filter holds the last input or skips
        the update (a vector model leaves out the sensors whose value is not finite) and says so
        in ``flags``. Equal, sample for sample, to stepping :meth:`filter` over the data.
        Returns an :class:`Estimate` that unpacks as ``(x, x_std)``.

        >>> import hbn
        >>> tr = hbn.simulate("duhem", 300, seed=1)
        >>> m = hbn.HysteresisModel.fit(tr["u"], tr["x"], tr["y"], max_points=100, n_starts=1)
        >>> est = m.estimate(tr["u"], tr["y"], mode="ekf-blr")
        >>> est.x.shape == est.x_std.shape == (300,)
        True
        """
        if isinstance(self._core, _hbn.VectorModelCore):
            um, ym = self._vector_rows(u, y)
            fields = self._core.estimate(um, ym, _opt_str(mode))
            return Estimate(fields, self._mode_name(mode))
        ua, ya = _signal(u, "u"), _signal(y, "y")
        columns = ua.ndim == 2 or ya.ndim == 2
        if columns:
            ua, ya = self._columns(ua, "u", 1)[:, 0], self._columns(ya, "y", 1)[:, 0]
        fields = self._core.estimate(_native(ua), _native(ya), _opt_str(mode))
        if columns:
            for k in ("x", "x_std", "y_pred", "innovation"):
                fields[k] = fields[k].reshape(-1, 1)
        return Estimate(fields, self._mode_name(mode))

    def smooth(self, u: Any, y: Any, mode: Optional[str] = None) -> Estimate:
        """Smooths: estimates each sample's state from the whole sequence, where
        :meth:`estimate` uses the samples up to it. The filter runs forward, then a
        Rauch-Tung-Striebel pass runs backward (extended for ``"ekf"`` and ``"ekf-blr"``,
        unscented for ``"ukf"``); offline, about twice the cost of :meth:`estimate`. Arguments
        as for :meth:`estimate`.

        Returns what :meth:`estimate` returns, with the smoothed ``x`` and ``x_std`` (and, for
        a vector model, ``x_cov``); the other fields (``y_pred``, ``innovation``, ``nis``,
        ``flags``, ...) are the forward filter's.
        The smoothed ``x_std`` is at most the filter's. docs/smoothing.md says when smoothing
        gains much and when little.

        >>> import hbn
        >>> tr = hbn.simulate("duhem", 300, seed=1)
        >>> m = hbn.HysteresisModel.fit(tr["u"], tr["x"], tr["y"], max_points=100, n_starts=1)
        >>> est, smo = m.estimate(tr["u"], tr["y"]), m.smooth(tr["u"], tr["y"])
        >>> bool((smo.x_std <= est.x_std + 1e-12).all() and smo.x[-1] == est.x[-1])
        True
        """
        if isinstance(self._core, _hbn.VectorModelCore):
            um, ym = self._vector_rows(u, y)
            fields = self._core.smooth(um, ym, _opt_str(mode))
            return Estimate(fields, self._mode_name(mode))
        ua, ya = _signal(u, "u"), _signal(y, "y")
        columns = ua.ndim == 2 or ya.ndim == 2
        if columns:
            ua, ya = self._columns(ua, "u", 1)[:, 0], self._columns(ya, "y", 1)[:, 0]
        fields = self._core.smooth(_native(ua), _native(ya), _opt_str(mode))
        if columns:
            for k in ("x", "x_std", "y_pred", "innovation"):
                fields[k] = fields[k].reshape(-1, 1)
        return Estimate(fields, self._mode_name(mode))

    def _vector_rows(self, u: Any, y: Any) -> Tuple[np.ndarray, np.ndarray]:
        """``u`` and ``y`` of a vector model as flat row-major arrays, checked against the
        model's sizes and each other's length (:class:`DataError` otherwise)."""
        du, _, dy = self.dims
        um, ym = self._columns(u, "u", du), self._columns(y, "y", dy)
        if um.shape[0] != ym.shape[0]:
            raise DataError(
                f"u and y must have equal lengths (got {um.shape[0]} and {ym.shape[0]})"
            )
        return um.ravel(), ym.ravel()

    def _columns(self, a: Any, name: str, width: int) -> np.ndarray:
        """``a`` as a ``(T, width)`` array (a 1-D array is one column); :class:`DataError`
        naming the model's sizes otherwise."""
        m = _signal(a, name)
        if m.ndim == 1 and width == 1:
            m = m.reshape(-1, 1)
        if m.ndim != 2 or m.shape[1] != width:
            du, dx, dy = self.dims
            raise DataError(
                f"{name} must have shape (T, {width}): the model has {du} inputs, {dx} state "
                f"components and {dy} sensors; got shape {m.shape}"
            )
        return _native(m)

    @_renamed(max_gap="max_gap_s")
    def estimate_log(
        self,
        path: PathLike,
        mode: Optional[str] = None,
        input: Union[str, Sequence[str], None] = None,
        output: Union[str, Sequence[str], None] = None,
        csv: Optional[PathLike] = None,
        mcap: Optional[PathLike] = None,
        time_source: Optional[str] = None,
        max_gap_s: Optional[float] = None,
    ) -> Estimate:
        """Estimates the state over an MCAP log exactly like ``hbn estimate``: reads ``u`` and
        ``y`` (the model's message paths unless ``input`` / ``output`` are given) at the model's
        rate, runs the filter (``mode``: as in :meth:`estimate`), and writes the estimate to
        ``csv`` and/or ``mcap`` when given (the CLI's formats, atomically). ``time_source`` and
        ``max_gap_s`` as in :meth:`from_logs` (``None``: those the model was trained with); after
        a gap longer than ``max_gap_s`` the filter restarts (flag ``initialised``). Returns an
        :class:`Estimate` with ``t`` set.

        A vector model reads its recorded message paths, or ``input`` and ``output`` given as
        lists (one path per signal, in the model's order); its ``csv`` has the columns of
        ``hbn estimate --csv`` (``x0``, ``x0_std``, ...) and its ``mcap`` the messages of
        ``hbn estimate --out`` (arrays per sample, with the signals' names).
        """
        if isinstance(self._core, _hbn.VectorModelCore):
            t, fields = self._core.estimate_log(
                _fspath(path),
                _opt_str(mode),
                [] if input is None else _paths(input, "input"),
                [] if output is None else _paths(output, "output"),
                None if csv is None else _fspath(csv),
                None if mcap is None else _fspath(mcap),
                _opt_str(time_source),
                _opt_float(max_gap_s, "max_gap_s"),
            )
            return Estimate(fields, self._mode_name(mode), t)
        t, fields = self._core.estimate_log(
            _fspath(path),
            _opt_str(mode),
            _opt_str(input),
            _opt_str(output),
            None if csv is None else _fspath(csv),
            None if mcap is None else _fspath(mcap),
            _opt_str(time_source),
            _opt_float(max_gap_s, "max_gap_s"),
        )
        return Estimate(fields, self._mode_name(mode), t)

    def filter(self, mode: Optional[str] = None) -> Filter:
        """A streaming estimator over this model (it shares the model): call ``step(u, y)`` once
        per sample. It initialises like :meth:`estimate` and its outputs equal :meth:`estimate`'s
        bit for bit. ``mode``: as in :meth:`estimate`. A vector model's filter takes sequences
        (``du`` inputs, ``dy`` measurements) and returns a :class:`VectorFilterOutput`.

        >>> import hbn
        >>> tr = hbn.simulate("duhem", 300, seed=1)
        >>> m = hbn.HysteresisModel.fit(tr["u"], tr["x"], tr["y"], max_points=100, n_starts=1)
        >>> f = m.filter(mode="ekf")
        >>> out = f.step(tr["u"][0], tr["y"][0])
        >>> bool(out.x == m.estimate(tr["u"][:1], tr["y"][:1]).x[0])
        True
        """
        return Filter(self._core.filter(_opt_str(mode)))

    @property
    def is_vector(self) -> bool:
        """Whether this is a vector model (trained on ``(T, d)`` arrays or lists of message
        paths with more than one input, state component or sensor)."""
        return isinstance(self._core, _hbn.VectorModelCore)

    @property
    def dims(self) -> Tuple[int, int, int]:
        """The numbers of inputs, state components and sensors: ``(1, 1, 1)`` for a scalar
        model."""
        if isinstance(self._core, _hbn.VectorModelCore):
            return tuple(self._core.dims)  # type: ignore[return-value]
        return (1, 1, 1)

    def _scalar(self, what: str) -> _hbn.HysteresisModelCore:
        """The scalar core, or the error that ``what`` takes scalar models."""
        if isinstance(self._core, _hbn.VectorModelCore):
            raise _scalar_only(what, self.dims)
        return self._core

    def _mode_name(self, mode: Optional[str]) -> str:
        return self.default_mode if mode is None else str(mode).lower()

    def simulate_open_loop(self, u: Any) -> np.ndarray:
        """Open-loop GP simulation of ``x`` from ``u`` alone (the baseline the filter must beat).

        >>> import hbn
        >>> tr = hbn.simulate("duhem", 300, seed=1)
        >>> m = hbn.HysteresisModel.fit(tr["u"], tr["x"], tr["y"], max_points=100, n_starts=1)
        >>> m.simulate_open_loop(tr["u"]).shape
        (300,)
        """
        return self._scalar("simulate_open_loop").simulate_open_loop(_vector(u, "u"))

    def save(self, path: PathLike) -> None:
        """Writes the model file (the CLI's format: ``hbn inspect`` / ``hbn estimate --model``
        read it), atomically.

        >>> import hbn, os, tempfile
        >>> tr = hbn.simulate("duhem", 200, seed=1)
        >>> m = hbn.HysteresisModel.fit(tr["u"], tr["x"], tr["y"], max_points=80, n_starts=1)
        >>> p = os.path.join(tempfile.mkdtemp(), "model.hbn"); m.save(p)
        >>> hbn.HysteresisModel.load(p).rate_hz
        100.0
        """
        self._core.save(_fspath(path))

    @classmethod
    def load(cls, path: PathLike) -> HysteresisModel:
        """Loads a model written by :meth:`save` or by ``hbn train --out``, scalar or vector (the
        file's ``format`` tag says which).

        :class:`HbnFileNotFoundError` if the file is missing; :class:`ModelFileError` if it is not
        an hbn model file of the supported format version (a model file of an older version of
        hbn says so: train the model again).
        """
        return cls(_hbn.load_model(_fspath(path)))

    def to_bytes(self) -> bytes:
        """The bytes of the model file :meth:`save` writes (what a pickled model holds).

        >>> import hbn
        >>> tr = hbn.simulate("duhem", 200, seed=1)
        >>> m = hbn.HysteresisModel.fit(tr["u"], tr["x"], tr["y"], max_points=80, n_starts=1)
        >>> hbn.HysteresisModel.from_bytes(m.to_bytes()).to_bytes() == m.to_bytes()
        True
        """
        return self._core.to_bytes()

    @classmethod
    def from_bytes(cls, data: bytes) -> HysteresisModel:
        """A model from the bytes of a model file (:meth:`to_bytes`, or a file's contents);
        :class:`ModelFileError` as in :meth:`load`."""
        return cls(_hbn.model_from_bytes(bytes(data), "<bytes>"))

    @property
    def rate_hz(self) -> float:
        """Sample rate in Hz (estimation data must use the same)."""
        return self._core.rate_hz

    @property
    def rate(self) -> float:
        """Deprecated name of :attr:`rate_hz`."""
        warnings.warn(
            "HysteresisModel.rate is deprecated; use rate_hz", DeprecationWarning, stacklevel=2
        )
        return self._core.rate_hz

    @property
    def signals(self) -> Dict[str, Any]:
        """Signal descriptions: ``{"input": {"name", "path", "unit"}, "state": ..., "output": ...}``;
        for a vector model the names (message paths) of each kind, ``{"inputs": [...],
        "states": [...], "outputs": [...]}``."""
        return self._core.signals()

    @property
    def params(self) -> Dict[str, Any]:
        """The training parameters of this model by keyword (as :func:`default_params`, with
        the kernel of each GP), plus ``blr`` and ``signals``. Training again with them trains
        the same model."""
        return self._core.params()

    @property
    def default_mode(self) -> str:
        """The mode :meth:`estimate` and :meth:`filter` use without ``mode=``: the one with the
        best held-out score at training (``validation``), ``"ekf"`` for a model trained with
        ``validation=0``."""
        return self._core.default_mode()

    @property
    def tuning(self) -> Dict[str, Any]:
        """The filter's noise scales learned on held-out data, per mode (``q``: process noise,
        ``r``: measurement noise, ``std``: reported standard deviation; all 1 untuned), and the
        ``default_mode``. The held-out table is ``summary["validation"]``."""
        return self._scalar("tuning").tuning()

    @property
    def summary(self) -> Dict[str, Any]:
        """Training summary: trajectories, rows, warnings, observability, every optimiser start
        (``gp``, ``start``, ``lml``, ``termination``), ``seconds`` (0 for a loaded model) and,
        when each GP chose its kernel by evidence, ``kernel_evidence`` (per GP and kernel the
        exact GP's ``lml`` and whether it was ``chosen``)."""
        return self._core.summary()

    @property
    def transition(self) -> GaussianProcess:
        """The transition GP (inputs ``[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}]``, then the plays
        and lags; target ``x_k``). A vector model has one per state component:
        :attr:`transition_gps`."""
        return GaussianProcess._from_core(self._scalar("transition").transition())

    @property
    def sensor(self) -> GaussianProcess:
        """The sensor GP (inputs ``[x_{k-1}, y_{k-1}, x_k]``, or ``[x_{k-1}, x_k]`` with
        ``sensor_inputs="state"``; target ``y_k``). A vector model has one per sensor:
        :attr:`sensor_gps`."""
        return GaussianProcess._from_core(self._scalar("sensor").sensor())

    @property
    def transition_gps(self) -> List[GaussianProcess]:
        """The transition GPs, one per state component (a vector model's read every state
        component, every input and their memory; ``[transition]`` for a scalar model)."""
        core = self._core
        if isinstance(core, _hbn.VectorModelCore):
            return [GaussianProcess._from_core(core.transition(i)) for i in range(self.dims[1])]
        return [GaussianProcess._from_core(core.transition())]

    @property
    def sensor_gps(self) -> List[GaussianProcess]:
        """The sensor GPs, one per sensor (``[sensor]`` for a scalar model)."""
        core = self._core
        if isinstance(core, _hbn.VectorModelCore):
            return [GaussianProcess._from_core(core.sensor(j)) for j in range(self.dims[2])]
        return [GaussianProcess._from_core(core.sensor())]

    def ekf_config(self, mode: Optional[str] = None) -> Dict[str, Any]:
        """The filter settings the estimator uses for ``mode`` (floors, bounds, training prior;
        a vector model's per-component arrays are padded to the largest sizes)."""
        return self._core.ekf_config(_opt_str(mode))

    def initial_state(self, y0: float) -> Optional[Tuple[float, float]]:
        """Prior ``(mean, variance)`` of ``x_0`` the filter takes from a first measurement ``y0``
        (``None`` if ``y0`` is not finite: the training prior of :meth:`ekf_config` applies)."""
        return self._scalar("initial_state").initial_state(float(y0))


for _f in (HysteresisModel.fit, HysteresisModel.from_logs):
    _f.__func__.__doc__ = _f.__func__.__doc__.replace(  # type: ignore[union-attr]
        "        {training}\n", textwrap.indent(_TRAINING_PARAMETERS_DOC, "    ")
    )


def _model_from_bytes(data: bytes) -> HysteresisModel:
    """Unpickles a :class:`HysteresisModel` (its model file's bytes, scalar or vector)."""
    return HysteresisModel(_hbn.model_from_bytes(data, "<pickle>"))


class Filter:
    """The streaming estimator: one :meth:`step` per sample, for a robot node or a live plot.

    Made by :meth:`HysteresisModel.filter`. It owns its state and shares the model; it
    initialises like :meth:`HysteresisModel.estimate` (the prior of ``x_0`` from the first
    measurement) and gives the same numbers, bit for bit. :meth:`step` returns a
    :class:`FilterOutput` (``x``, ``x_std``, ``y_pred``, ``innovation``, ``innovation_var``,
    ``nis``, ``q_x``, ``r``, ``flags``, ``obs_min``, ``obs_max``, ``obs_x``, ``flag_names()``);
    a vector model's filter takes sequences and returns a :class:`VectorFilterOutput` (``x``,
    ``x_std``, ``x_cov``, ``y_pred``, ``innovation``, ``innovation_var``, ``q_x``, ``r`` as
    tuples, ``nis``, ``flags``, ``flag_names()``).

    >>> import hbn
    >>> tr = hbn.simulate("duhem", 200, seed=1)
    >>> f = hbn.HysteresisModel.fit(tr["u"], tr["x"], tr["y"], max_points=80, n_starts=1).filter()
    >>> outs = [f.step(u, y) for u, y in zip(tr["u"], tr["y"])]
    >>> "initialised" in outs[0].flag_names()
    True
    """

    def __init__(self, core: Union[_hbn.FilterCore, _hbn.VectorFilterCore]) -> None:
        if not isinstance(core, (_hbn.FilterCore, _hbn.VectorFilterCore)):
            raise TypeError("use HysteresisModel.filter(mode=...)")
        self._core = core

    def __repr__(self) -> str:
        return f"Filter(mode={self.mode!r}, steps={self.steps})"

    def step(
        self, u: Union[float, Sequence[float]], y: Union[float, Sequence[float]]
    ) -> Union[FilterOutput, VectorFilterOutput]:
        """Processes one sample: input ``u`` and measurement ``y`` (NaN allowed: the last input is
        held or the update skipped, and the flags say so). A vector model's filter takes ``du``
        inputs and ``dy`` measurements (sequences; a NaN measurement is left out of the update)
        and returns a :class:`VectorFilterOutput`."""
        core = self._core
        if isinstance(core, _hbn.VectorFilterCore):
            du, _, dy = core.dims
            uv, yv = _vector(u, "u"), _vector(y, "y")
            if uv.shape[0] != du or yv.shape[0] != dy:
                raise DataError(
                    f"step takes {du} inputs and {dy} measurements, got {uv.shape[0]} and "
                    f"{yv.shape[0]}"
                )
            return core.step(uv, yv)
        return core.step(float(u), float(y))

    def reset(self) -> None:
        """Forgets the state; the next step initialises again."""
        self._core.reset()

    @property
    def mode(self) -> str:
        """The estimation mode."""
        return self._core.mode

    @property
    def steps(self) -> int:
        """Samples processed since the last (re)initialisation."""
        return self._core.steps




class Explorer:
    """Chooses the next input while training data are collected (thesis Sec. 3.4): random
    inputs first, then inputs that seek where the transition GP is uncertain.

    Parameters
    ----------
    u_min, u_max : float
        Bounds of the input.
    max_step : float
        The largest change of the input per sample. Every proposal lies in the bounds and,
        when the last observed input does, differs from it by at most ``max_step``.
    rate_hz : float
        The sample rate of the model (Hz).
    seed : int
        Seeds the random steps and the training.
    u_start : float or None
        The first input (``None``: ``u_min``).
    random_samples : int
        Length of the random phase.
    alpha_start, alpha_end : float
        The weight of uncertainty seeking grows linearly from ``alpha_start`` to
        ``alpha_end`` ...
    alpha_ramp : int
        ... over this many samples.
    refit_every : int
        Refit the transition GP every this many samples.
    optimize_every : int
        Re-learn its hyperparameters (warm-started) every this many samples.
    candidates : int
        Random steps drawn per seeking choice of ``strategy="steps"``.
    horizon : int
        Look-ahead of the uncertainty search, in samples.
    strategy : {"ramps", "steps"}
        ``"ramps"``: ramps to random target levels at random slopes, as :func:`simulate`
        drives its systems, the next ramp being, with probability ``alpha``, the best of
        ``pool`` such random ramps by ``criterion``; ``"steps"``: the thesis' per-sample rule
        ``u += alpha * eps + (1 - alpha) * w``, ``eps`` the best of ``candidates`` steps.
    pool : int
        Random ramps drawn per seeking choice (more seeks harder).
    lag : int
        0: every refit runs inside :meth:`observe`, which blocks for it. ``lag > 0``: refits run
        on a thread beside the loop and are used ``lag`` samples after they start, so that a
        loop faster than the refits (a robot at 100 Hz with ``lag=200``) is not held up; the
        proposals stay deterministic, and the older model costs some accuracy
        (``docs/exploration.md``).
    criterion : {"reduction", "variance"}
        How a seeking choice of ``"ramps"`` scores the pool: ``"reduction"``, the ramp whose
        samples would lower the transition GP's variance most, summed over where all the
        pool's ramps go; ``"variance"``, the ramp along which it is most uncertain.

    The training parameters (keyword-only) are those of :meth:`HysteresisModel.fit`, used by
    the explorer's transition GP and by :meth:`model`. The defaults are the library's
    (:func:`default_explore_params`, :func:`default_params`). A bad value raises
    :class:`ConfigError` whose ``keyword`` names it. The explorer is scalar: one input, one
    state and one sensor (several values raise ``ValueError``).

    >>> import hbn
    >>> explorer = hbn.Explorer(0.0, 1.0, 0.02, random_samples=40, max_points=60, n_starts=1)
    >>> robot = hbn.Simulator("duhem", noise_gain=1.0)
    >>> for _ in range(120):
    ...     u = explorer.propose()
    ...     x, y = robot.step(u)
    ...     explorer.observe(u, x, y)
    >>> explorer.phase
    'seeking'
    >>> model = explorer.model()
    """

    @_renamed(rate="rate_hz", **_RENAMED)
    def __init__(
        self,
        u_min: float,
        u_max: float,
        max_step: float,
        rate_hz: float = _P["rate_hz"],
        seed: int = _E["seed"],
        u_start: Optional[float] = _E["u_start"],
        random_samples: int = _E["random_samples"],
        alpha_start: float = _E["alpha_start"],
        alpha_end: float = _E["alpha_end"],
        alpha_ramp: int = _E["alpha_ramp"],
        refit_every: int = _E["refit_every"],
        optimize_every: int = _E["optimize_every"],
        candidates: int = _E["candidates"],
        horizon: int = _E["horizon"],
        strategy: str = _E["strategy"],
        pool: int = _E["pool"],
        lag: int = _E["lag"],
        criterion: str = _E["criterion"],
        *,
        kernel: Union[str, Sequence[str], None] = _P["kernel"],
        transition_kernel: Optional[str] = _P["transition_kernel"],
        sensor_kernel: Optional[str] = _P["sensor_kernel"],
        n_inducing: Union[int, None, Sequence[Optional[int]]] = _P["n_inducing"],
        max_points: int = _P["max_points"],
        subset_policy: str = _P["subset_policy"],
        n_starts: int = _P["n_starts"],
        max_iters: int = _P["max_iters"],
        normalize: bool = _P["normalize"],
        noise_floor: float = _P["noise_floor"],
        blr_window: float = _P["blr_window"],
        validation: float = _P["validation"],
        memory: Sequence[float] = _P["memory"],
        lags: Union[Sequence[float], Sequence[Sequence[float]]] = _P["lags"],
        linear_mean: str = _P["linear_mean"],
        sensor_inputs: Union[str, Sequence[str]] = _P["sensor_inputs"],
        max_signal_variance: Optional[float] = _P["max_signal_variance"],
        firmware_budget: Union[int, str, None] = _P["firmware_budget"],
    ) -> None:
        params = _training_args(locals())
        one = Explorer._one
        self._core = _hbn.ExplorerCore(
            _float(one(u_min, "u_min"), "u_min"),
            _float(one(u_max, "u_max"), "u_max"),
            _float(one(max_step, "max_step"), "max_step"),
            _count(seed, "seed"),
            _opt_float(one(u_start, "u_start"), "u_start"),
            _count(random_samples, "random_samples"),
            _opt_float(alpha_start, "alpha_start"),
            _opt_float(alpha_end, "alpha_end"),
            _count(alpha_ramp, "alpha_ramp"),
            _count(refit_every, "refit_every"),
            _count(optimize_every, "optimize_every"),
            _count(candidates, "candidates"),
            _count(horizon, "horizon"),
            _opt_str(strategy),
            _count(pool, "pool"),
            _count(lag, "lag"),
            _opt_str(criterion),
            params,
        )

    def __repr__(self) -> str:
        s = self.settings
        return (
            f"Explorer(u_min={s['u_min']}, u_max={s['u_max']}, max_step={s['max_step']}, "
            f"n_observed={self.n_observed}, phase={self.phase!r})"
        )

    @staticmethod
    def _one(v: Any, keyword: str) -> Any:
        """``v`` unless it holds several values: the explorer is scalar."""
        if np.ndim(v) > 0 and np.size(v) != 1:
            raise ValueError(
                f"the Explorer takes scalar models (one input, one state, one sensor), but "
                f"{keyword} has {np.size(v)} values; a vector model trains from logged (T, d) "
                f"arrays with HysteresisModel.fit"
            )
        return v.item() if isinstance(v, np.ndarray) else v

    def propose(self) -> float:
        """The next input to apply (draws one random step)."""
        return self._core.propose()

    def observe(self, u: float, x: float, y: float) -> None:
        """Records the sample the robot produced: ``u`` as applied, measured ``x`` and ``y``
        (finite; a NaN raises :class:`DataError` and is not recorded). Refits the transition GP
        when it is due. The explorer takes scalar models: several values in ``u``, ``x`` or
        ``y`` raise ``ValueError``."""
        one = Explorer._one
        self._core.observe(
            _float(one(u, "u"), "u"), _float(one(x, "x"), "x"), _float(one(y, "y"), "y")
        )

    def model(self) -> HysteresisModel:
        """Trains the HBN on every sample observed (like :meth:`HysteresisModel.fit`)."""
        return HysteresisModel(self._core.model())

    def plan(self, steps: int) -> Tuple[np.ndarray, np.ndarray]:
        """A schedule of ``steps`` inputs for a robot without the explorer in its loop, and
        the states the transition GP predicts along it (what ``hbn explore`` writes); each
        predicted state is treated as observed. The explorer itself is not changed."""
        return self._core.plan(_count(steps, "steps"))

    def start_run(self) -> None:
        """The robot was reset: the next samples start a new run (the next input is
        ``u_start``), and no training row straddles the two."""
        self._core.start_run()

    @property
    def phase(self) -> str:
        """``"random"`` or ``"seeking"``."""
        return self._core.phase

    @property
    def alpha(self) -> float:
        """The weight of uncertainty seeking now (0 in the random phase)."""
        return self._core.alpha

    @property
    def n_observed(self) -> int:
        """Samples observed so far, all runs."""
        return self._core.n_observed

    @property
    def warnings(self) -> List[str]:
        """What went wrong and was recovered from (a failed refit keeps the previous GP)."""
        return self._core.warnings

    @property
    def runs(self) -> List[Dict[str, np.ndarray]]:
        """The observed runs, each ``{"u", "x", "y"}``."""
        return [{"u": u, "x": x, "y": y} for u, x, y in self._core.runs]

    @property
    def settings(self) -> Dict[str, Any]:
        """The explorer's settings (bounds and schedule), defaults filled in."""
        return self._core.settings


class Simulator:
    """One of the systems of :func:`simulate`, stepped one sample at a time: a stand-in robot
    for :class:`Explorer` or a controller in the loop.

    ``system``: one of :data:`SYSTEMS`; ``seed``, ``noise_gain``, ``rate_hz`` as in
    :func:`simulate`. Stepping through an input gives exactly the ``x`` and ``y`` that
    :func:`simulate` gives for it with the same settings.

    >>> import hbn
    >>> robot = hbn.Simulator("bouc-wen", seed=1, noise_gain=1.0)
    >>> x, y = robot.step(0.1)
    >>> robot.steps
    1
    """

    @_renamed(rate="rate_hz")
    def __init__(
        self,
        system: str,
        seed: int = _S["seed"],
        noise_gain: float = _S["noise_gain"],
        rate_hz: float = _S["rate_hz"],
    ) -> None:
        self._core = _hbn.SimulatorCore(
            str(system),
            _count(seed, "seed"),
            _opt_float(noise_gain, "noise_gain"),
            _opt_float(rate_hz, "rate_hz"),
        )

    def __repr__(self) -> str:
        return f"Simulator(steps={self.steps})"

    def step(self, u: float) -> Tuple[float, float]:
        """Applies ``u`` for one sample; returns ``(x, y)``. An input that is not finite or
        lies outside the simulator's range raises :class:`DataError` and changes nothing."""
        return self._core.step(_float(u, "u"))

    @property
    def steps(self) -> int:
        """Samples simulated so far."""
        return self._core.steps


# ------------------------------------------------------------------------------------------------
# Functions
# ------------------------------------------------------------------------------------------------


@_renamed(rate="rate_hz")
def simulate(
    system: str,
    steps: int,
    seed: int = _S["seed"],
    noise_gain: float = _S["noise_gain"],
    rate_hz: float = _S["rate_hz"],
) -> Dict[str, np.ndarray]:
    """Simulates a hysteretic actuator/sensor system under a random bounded-increment input.

    ``system``: one of :data:`SYSTEMS` (``"maxwell-slip"``, ``"generalized-pi"``, ``"bouc-wen"``,
    ``"preisach"``, ``"duhem"``, ``"soft-actuator"``, ``"soft-actuator-load"``: the soft
    actuator under a supply-pressure disturbance that propagates through its dynamics).
    ``noise_gain``: the thesis' noise gain (0 = noise-free). Returns ``{"u", "x", "y"}`` arrays of ``steps`` samples (the data of
    ``hbn simulate`` with the same settings). A multi-signal system (one of
    :data:`MULTI_SYSTEMS`) gives ``(steps, d)`` arrays, one column per input, state component
    and sensor, ready for :meth:`HysteresisModel.fit`.

    >>> import hbn
    >>> d = hbn.simulate("bouc-wen", 100, seed=3, noise_gain=1.0)
    >>> sorted(d), d["x"].shape
    (['u', 'x', 'y'], (100,))
    >>> f = hbn.simulate("finger", 100, seed=3)
    >>> f["u"].shape, f["x"].shape, f["y"].shape
    ((100, 2), (100, 2), (100, 3))
    """
    if str(system).strip().lower() in MULTI_SYSTEMS:
        u, x, y, (du, dx, dy) = _hbn.simulate_multi(
            str(system),
            _count(steps, "steps"),
            _count(seed, "seed"),
            _opt_float(noise_gain, "noise_gain"),
            _opt_float(rate_hz, "rate_hz"),
        )
        return {"u": u.reshape(-1, du), "x": x.reshape(-1, dx), "y": y.reshape(-1, dy)}
    u, x, y = _hbn.simulate(
        str(system),
        _count(steps, "steps"),
        _count(seed, "seed"),
        _opt_float(noise_gain, "noise_gain"),
        _opt_float(rate_hz, "rate_hz"),
    )
    return {"u": u, "x": x, "y": y}


@_renamed(rate="rate_hz")
def oracle_estimate(
    system: str,
    u: Any,
    x: Any,
    y: Any,
    noise_gain: float = _S["noise_gain"],
    rate_hz: float = _S["rate_hz"],
    lookahead: Optional[int] = 0,
    particles: int = 2000,
) -> Dict[str, np.ndarray]:
    """The floor under state estimation on a simulated log: how low any estimator's error can
    go.

    ``u``, ``x``, ``y``: a trajectory of the simulator ``system`` (from :func:`simulate`,
    :class:`Simulator` or ``hbn simulate``) with the same ``noise_gain`` and ``rate_hz`` (the
    noise seed is not needed). Returns ``{"mean", "std"}``: the exact posterior of each ``x[k]``
    given ``u`` and ``y`` up to ``k``, the true past states ``x[:k]`` and the simulator itself.
    An estimator that sees only ``u`` and ``y`` up to ``k`` (hbn's filters, any causal
    baseline) conditions on less, so none has a lower expected squared error than ``mean`` on
    the same log: the ratio of an estimator's RMSE to this one's is what it could still gain.
    Noise-free logs give ``mean == x``. :class:`DataError` if the arrays differ in length or an
    input lies outside the simulator's range; :class:`ConfigError` for an unknown system, a bad
    setting, or ``"soft-actuator-load"``, whose disturbance propagates through its dynamics: the
    true past states do not pin its current state, so it has no exact floor.

    ``lookahead`` (samples after ``k``; ``None`` for the whole log) gives the floor under
    smoothing instead: the posterior given also ``y`` up to ``k + lookahead`` and the true
    later states, which no estimator that sees ``u`` and ``y`` of the whole log (hbn's
    :meth:`HysteresisModel.smooth`) beats. Its ratio to the causal floor is the most a smoother
    could gain on the log (``docs/smoothing.md``).

    A multi-signal system (one of :data:`MULTI_SYSTEMS`; ``u``, ``x``, ``y`` of shapes
    ``(T, du)``, ``(T, dx)``, ``(T, dy)``) propagates its disturbance through the tip's lag, so
    its floor conditions on less: ``mean`` and ``std`` (``(T, dx)``) are the posterior of the
    state given ``u`` and ``y`` up to each sample and the simulator's own model, found by a
    particle filter of ``particles`` particles (``x`` only sets the shape). No causal estimator
    beats it in expectation; fewer particles only raise its error (2000 are within about 1e-4
    nRMSE of 32000 on the arm). ``lookahead`` must be 0 there.

    >>> import hbn, numpy as np
    >>> d = hbn.simulate("bouc-wen", 400, seed=3, noise_gain=3.0)
    >>> o = hbn.oracle_estimate("bouc-wen", d["u"], d["x"], d["y"], noise_gain=3.0)
    >>> rmse = float(np.sqrt(np.mean((o["mean"] - d["x"]) ** 2)))
    >>> bool(rmse < 0.06 / np.sqrt(12))  # below the disturbance's own standard deviation
    True
    """
    if str(system).strip().lower() in MULTI_SYSTEMS:
        if _lookahead(lookahead) != 0:
            raise _config_error(
                "lookahead", "must be 0 for a multi-signal system (no smoothing floor)", lookahead
            )
        return _multi_oracle_estimate(str(system), u, x, y, noise_gain, rate_hz, particles)
    mean, std = _hbn.oracle_estimate(
        str(system),
        _vector(u, "u"),
        _vector(x, "x"),
        _vector(y, "y"),
        _opt_float(noise_gain, "noise_gain"),
        _opt_float(rate_hz, "rate_hz"),
        _lookahead(lookahead),
    )
    return {"mean": mean, "std": std}


def _multi_oracle_estimate(
    system: str, u: Any, x: Any, y: Any, noise_gain: Any, rate_hz: Any, particles: Any
) -> Dict[str, np.ndarray]:
    """:func:`oracle_estimate` of a multi-signal system (the shapes checked here)."""
    widths = dict(zip(("u", "x", "y"), _hbn.multi_dims(system)))
    arrays = {}
    for name, a in (("u", u), ("x", x), ("y", y)):
        try:
            m = np.asarray(a, dtype=np.float64)
        except (TypeError, ValueError) as e:
            raise DataError(f"{name} must be numeric: {e}") from None
        if m.ndim == 1 and widths[name] == 1:
            m = m.reshape(-1, 1)
        if m.ndim != 2 or m.shape[1] != widths[name]:
            raise DataError(
                f"{name} of {system!r} must have shape (T, {widths[name]}), got {m.shape}"
            )
        arrays[name] = m
    um, xm, ym = arrays["u"], arrays["x"], arrays["y"]
    if not um.shape[0] == xm.shape[0] == ym.shape[0]:
        raise DataError(
            f"u, x and y must have equal lengths (got {um.shape[0]}, {xm.shape[0]} and "
            f"{ym.shape[0]})"
        )
    n = _count(particles, "particles")
    if not n:
        raise _config_error("particles", "must be at least 1", particles)
    mean, std, width = _hbn.multi_oracle_estimate(
        system,
        np.ascontiguousarray(um).reshape(-1),
        np.ascontiguousarray(ym).reshape(-1),
        _opt_float(noise_gain, "noise_gain"),
        _opt_float(rate_hz, "rate_hz"),
        n,
        0,
    )
    return {"mean": mean.reshape(-1, width), "std": std.reshape(-1, width)}


def _lookahead(v: Any) -> Optional[int]:
    """``lookahead`` of :func:`oracle_estimate`: ``None``, or an integer ``>= 0``."""
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
        error = ConfigError(
            f"invalid lookahead={v!r}: must be an integer >= 0, or None for the whole log"
        )
        error.keyword = "lookahead"
        raise error
    return int(v)


def list_topics(path: PathLike) -> List[Dict[str, Any]]:
    """Topics of an MCAP log: ``[{"topic", "message_count", "encoding", "schema"}]``.

    >>> import hbn
    >>> [t["topic"] for t in hbn.list_topics("fixtures/json_zstd.mcap")]  # doctest: +SKIP
    ['/input', '/sensor', '/state']
    """
    return [
        {"topic": t, "message_count": n, "encoding": enc, "schema": schema}
        for (t, n, enc, schema) in _hbn.list_topics(_fspath(path))
    ]


@_renamed(rate="rate_hz", max_gap="max_gap_s")
def read_mcap(
    path: PathLike,
    signals: Mapping[str, str],
    rate_hz: Optional[float] = _L["rate_hz"],
    time_source: str = _L["time_source"],
    max_gap_s: float = _L["max_gap_s"],
) -> Dict[str, np.ndarray]:
    """Reads numeric signals from an MCAP log and resamples them on one uniform grid, with the
    pipeline of the ``hbn`` CLI.

    ``signals`` maps your names to message paths, e.g.
    ``{"u": "/valve.pressure", "y": "/joint_states.position[1]"}``. ``rate_hz``: grid rate in Hz
    (``None``: the native rate of the first signal, rounded to 0.1 Hz); ``time_source``,
    ``max_gap_s``: as in :meth:`HysteresisModel.from_logs`. Returns the same keys plus ``"t"``
    (seconds since the first grid point).

    >>> import hbn
    >>> d = hbn.read_mcap("fixtures/json_zstd.mcap", {"u": "/input.data"})  # doctest: +SKIP
    """
    if not isinstance(signals, Mapping) or len(signals) == 0:
        raise _config_error("signals", "must be a non-empty dict {name: message path}", signals)
    if "t" in signals:
        raise _config_error(
            "signals", '"t" is reserved for the time column; name the signal otherwise'
        )
    names = list(signals.keys())
    t, cols, _ = _hbn.read_mcap(
        _fspath(path),
        [str(signals[n]) for n in names],
        _opt_float(rate_hz, "rate_hz"),
        _opt_str(time_source),
        _opt_float(max_gap_s, "max_gap_s"),
    )
    out: Dict[str, np.ndarray] = {"t": t}
    out.update(zip(names, cols))
    return out


def __getattr__(name: str) -> Any:
    if name == "HbnModel":
        warnings.warn(
            "hbn.HbnModel is deprecated; use hbn.HysteresisModel", DeprecationWarning, stacklevel=2
        )
        return HysteresisModel
    raise AttributeError(f"module 'hbn' has no attribute {name!r}")
