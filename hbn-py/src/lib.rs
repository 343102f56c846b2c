//! Python bindings of hbn (`hbn._hbn`).
//!
//! This crate only converts types and releases the GIL: every algorithm lives in the workspace
//! crates (`hbn-gp`, `hbn-model`, `hbn-sim`, `hbn-io`). The scikit-learn style classes are in the
//! pure-Python package `hbn` (`python/hbn/__init__.py`), which validates array shapes and calls
//! the `*Core` classes and functions here.
//!
//! Errors: bad data or settings and files that are not models become `ValueError`; file-system
//! errors become `OSError` (`FileNotFoundError`, `PermissionError`, ... where the OS error says
//! so). Heavy calls run with the GIL released, inside `catch_unwind`, so a bug surfaces as a
//! `RuntimeError` rather than a panic.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::str::FromStr;

use hbn_core::{Mode, Want};
use hbn_gp::{GaussianProcess, GpError, GpParams, RawHyperparameters, SparseParams};
use hbn_io::{IoError, ReadOptions, ResampleOptions, SignalPath};
use hbn_model::{HbnModel, HbnParams, KernelChoice, ModelError, Sequence, Signals};
use hbn_sim::{SimConfig, SystemKind};
use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::exceptions::{
    PyFileExistsError, PyFileNotFoundError, PyIsADirectoryError, PyOSError, PyPermissionError,
    PyRuntimeError, PyValueError,
};
use pyo3::prelude::*;

// ---------------------------------------------------------------------------------------------
// Error conversion
// ---------------------------------------------------------------------------------------------

fn os_error(kind: std::io::ErrorKind, msg: String) -> PyErr {
    use std::io::ErrorKind as K;
    match kind {
        K::NotFound => PyFileNotFoundError::new_err(msg),
        K::PermissionDenied => PyPermissionError::new_err(msg),
        K::IsADirectory => PyIsADirectoryError::new_err(msg),
        K::AlreadyExists => PyFileExistsError::new_err(msg),
        _ => PyOSError::new_err(msg),
    }
}

fn gp_err(e: GpError) -> PyErr {
    match &e {
        GpError::Io { source, .. } => os_error(source.kind(), e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

fn model_err(e: ModelError) -> PyErr {
    match &e {
        ModelError::Io { source, .. } => os_error(source.kind(), e.to_string()),
        ModelError::Gp {
            source: GpError::Io { source, .. },
            ..
        } => os_error(source.kind(), e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

fn io_err(e: IoError) -> PyErr {
    match &e {
        IoError::Open { source, .. } => os_error(source.kind(), e.to_string()),
        _ => PyValueError::new_err(e.to_string()),
    }
}

fn value_err(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// Runs `f` with the GIL released; a panic becomes `RuntimeError` instead of crossing into Python.
fn detached<T, F>(py: Python<'_>, f: F) -> PyResult<T>
where
    F: FnOnce() -> PyResult<T> + Send,
    T: Send,
{
    py.detach(|| match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".to_owned());
            Err(PyRuntimeError::new_err(format!(
                "internal error in hbn (please report it): {what}"
            )))
        }
    })
}

fn slice<'a>(a: &'a PyReadonlyArray1<'_, f64>, name: &str) -> PyResult<&'a [f64]> {
    a.as_slice()
        .map_err(|e| PyValueError::new_err(format!("{name}: {e}")))
}

fn kernel_choice(kernel: &str) -> PyResult<KernelChoice> {
    KernelChoice::from_str(kernel).map_err(model_err)
}

fn parse_mode(mode: &str) -> PyResult<Mode> {
    Mode::from_str(mode).map_err(|e| PyValueError::new_err(format!("{mode:?}: {e}")))
}

fn mode_name(mode: Mode) -> &'static str {
    mode.name()
}

fn json<T: serde::Serialize>(v: &T) -> PyResult<String> {
    serde_json::to_string(v).map_err(value_err)
}

// ---------------------------------------------------------------------------------------------
// Gaussian process
// ---------------------------------------------------------------------------------------------

/// Native GP, exact or sparse (`hbn_gp::GaussianProcess`). Use `hbn.GaussianProcess` instead.
#[pyclass(name = "GaussianProcessCore", module = "hbn._hbn", frozen)]
pub struct GaussianProcessCore {
    inner: GaussianProcess,
    kernel: String,
}

#[pymethods]
impl GaussianProcessCore {
    /// Fits a GP to row-major inputs `x` (`len(y) x dim`) and targets `y`.
    #[staticmethod]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (x, dim, y, kernel, lengthscales, signal_variance, noise_variance,
                        optimize, normalize, n_starts, max_iters, max_points, seed,
                        n_inducing=None, inducing_points=None, optimize_inducing=false))]
    fn fit(
        py: Python<'_>,
        x: PyReadonlyArray1<'_, f64>,
        dim: usize,
        y: PyReadonlyArray1<'_, f64>,
        kernel: &str,
        lengthscales: Option<Vec<f64>>,
        signal_variance: Option<f64>,
        noise_variance: Option<f64>,
        optimize: bool,
        normalize: bool,
        n_starts: usize,
        max_iters: u64,
        max_points: usize,
        seed: u64,
        n_inducing: Option<usize>,
        inducing_points: Option<PyReadonlyArray1<'_, f64>>,
        optimize_inducing: bool,
    ) -> PyResult<Self> {
        let choice = kernel_choice(kernel)?;
        let mut params = GpParams::new(choice.spec(dim, [0, 1]));
        params.optimize = optimize;
        params.normalize = normalize;
        params.n_starts = n_starts;
        params.max_iters = max_iters;
        params.max_points = max_points;
        params.seed = seed;
        if let Some(m) = n_inducing {
            params.sparse = Some(SparseParams {
                inducing_inputs: match &inducing_points {
                    Some(z) => Some(slice(z, "inducing_points")?.to_vec()),
                    None => None,
                },
                optimize_inducing,
                ..SparseParams::new(m)
            });
        }
        if lengthscales.is_some() || signal_variance.is_some() || noise_variance.is_some() {
            params.raw_init = Some(RawHyperparameters {
                length_scales: lengthscales,
                signal_variance,
                noise_variance,
            });
        }
        let (x, y) = (slice(&x, "X")?.to_vec(), slice(&y, "y")?.to_vec());
        let inner = detached(py, move || hbn_gp::fit(&params, &x, &y).map_err(gp_err))?;
        Ok(Self {
            inner,
            kernel: choice.to_string(),
        })
    }

    /// Predicts at row-major inputs; returns `(mean, variance or None, grad or None)`, the
    /// gradient row-major `n x dim`.
    #[allow(clippy::type_complexity)]
    fn predict<'py>(
        &self,
        py: Python<'py>,
        x: PyReadonlyArray1<'_, f64>,
        variance: bool,
        grad: bool,
    ) -> PyResult<(
        Bound<'py, PyArray1<f64>>,
        Option<Bound<'py, PyArray1<f64>>>,
        Option<Bound<'py, PyArray1<f64>>>,
    )> {
        let x = slice(&x, "X")?.to_vec();
        let want = Want {
            variance,
            grad_mean: grad,
            grad_variance: false,
        };
        let d = self.inner.kernel().dim;
        let (mean, var, g) = detached(py, || {
            let preds = self.inner.predict_many(&x, want).map_err(gp_err)?;
            let mean: Vec<f64> = preds.iter().map(|p| p.mean).collect();
            let var: Vec<f64> = preds.iter().map(|p| p.variance).collect();
            let g: Vec<f64> = preds
                .iter()
                .flat_map(|p| p.grad_mean[..d].iter().copied())
                .collect();
            Ok((mean, var, g))
        })?;
        Ok((
            PyArray1::from_vec(py, mean),
            variance.then(|| PyArray1::from_vec(py, var)),
            grad.then(|| PyArray1::from_vec(py, g)),
        ))
    }

    /// Log marginal likelihood at the fitted hyperparameters (standardised targets when the
    /// model normalises).
    fn log_marginal_likelihood(&self) -> f64 {
        self.inner.log_marginal_likelihood()
    }
    /// Length scales in raw input units.
    #[getter]
    fn length_scales(&self) -> Vec<f64> {
        self.inner.length_scales()
    }
    /// Signal variance in raw output units.
    #[getter]
    fn signal_variance(&self) -> f64 {
        self.inner.signal_variance()
    }
    /// Noise variance in raw output units.
    #[getter]
    fn noise_variance(&self) -> f64 {
        self.inner.noise_variance()
    }
    /// Kernel hyperparameters (log-parameterised, standardised units).
    #[getter]
    fn theta(&self) -> Vec<f64> {
        self.inner.theta().to_vec()
    }
    /// Number of support points (exact) or inducing points (sparse).
    #[getter]
    fn n_support(&self) -> usize {
        self.inner.n_support()
    }
    /// True for a sparse (inducing-point) GP.
    #[getter]
    fn is_sparse(&self) -> bool {
        self.inner.is_sparse()
    }
    /// Support inputs (exact) or inducing inputs (sparse), raw units, row-major.
    #[getter]
    fn support_inputs<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, self.inner.support_inputs())
    }
    /// Number of inputs.
    #[getter]
    fn dim(&self) -> usize {
        self.inner.kernel().dim
    }
    /// Kernel name as given at fit time (canonical form), or the structure of a loaded model.
    #[getter]
    fn kernel(&self) -> String {
        self.kernel.clone()
    }
    /// Training report as JSON.
    fn report_json(&self) -> PyResult<String> {
        json(self.inner.report())
    }
    /// Training warnings.
    fn warnings(&self) -> Vec<String> {
        self.inner.report().warnings()
    }
    /// The model as JSON (the format of `save`).
    fn to_json(&self) -> PyResult<String> {
        self.inner.to_json().map_err(gp_err)
    }
    /// Parses `to_json` output.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Self> {
        let inner = GaussianProcess::from_json(text, "<string>").map_err(gp_err)?;
        Ok(Self::wrap(inner))
    }
    /// Writes the model atomically.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        detached(py, || self.inner.save(&path).map_err(gp_err))
    }
    /// Loads a model written by `save`.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let inner = detached(py, move || GaussianProcess::load(&path).map_err(gp_err))?;
        Ok(Self::wrap(inner))
    }
}

impl GaussianProcessCore {
    fn wrap(inner: GaussianProcess) -> Self {
        let kernel = serde_json::to_string(inner.kernel()).unwrap_or_default();
        Self { inner, kernel }
    }
}

// ---------------------------------------------------------------------------------------------
// HBN model
// ---------------------------------------------------------------------------------------------

/// Native HBN model (`hbn_model::HbnModel`). Use `hbn.HysteresisModel` instead.
#[pyclass(name = "HysteresisModelCore", module = "hbn._hbn", frozen)]
pub struct HysteresisModelCore {
    inner: HbnModel,
}

type Arr<'py> = Bound<'py, PyArray1<f64>>;

#[pymethods]
impl HysteresisModelCore {
    /// Fits both GPs to trajectories (lists of equal-length `u`, `x`, `y` arrays).
    #[staticmethod]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (u, x, y, rate, kernel, max_points, n_starts, max_iters, seed, blr_window, signals_json, n_inducing=None))]
    fn fit(
        py: Python<'_>,
        u: Vec<PyReadonlyArray1<'_, f64>>,
        x: Vec<PyReadonlyArray1<'_, f64>>,
        y: Vec<PyReadonlyArray1<'_, f64>>,
        rate: f64,
        kernel: &str,
        max_points: usize,
        n_starts: usize,
        max_iters: u64,
        seed: u64,
        blr_window: f64,
        signals_json: Option<&str>,
        n_inducing: Option<usize>,
    ) -> PyResult<Self> {
        let choice = kernel_choice(kernel)?;
        let signals: Signals = match signals_json {
            Some(text) => serde_json::from_str(text)
                .map_err(|e| PyValueError::new_err(format!("signals: {e}")))?,
            None => Signals::default(),
        };
        if u.len() != x.len() || u.len() != y.len() {
            return Err(PyValueError::new_err(format!(
                "u, x and y must hold the same number of trajectories (got {}, {}, {})",
                u.len(),
                x.len(),
                y.len()
            )));
        }
        let own = |v: &[PyReadonlyArray1<'_, f64>], n: &str| -> PyResult<Vec<Vec<f64>>> {
            v.iter().map(|a| Ok(slice(a, n)?.to_vec())).collect()
        };
        let (u, x, y) = (own(&u, "u")?, own(&x, "x")?, own(&y, "y")?);
        let params = HbnParams {
            rate_hz: rate,
            transition_kernel: choice,
            sensor_kernel: choice,
            n_inducing,
            max_points,
            n_starts,
            max_iters,
            seed,
            blr_window,
            signals,
            ..HbnParams::default()
        };
        let inner = detached(py, move || {
            let seqs: Vec<Sequence<'_>> = (0..u.len())
                .map(|i| Sequence {
                    u: &u[i],
                    x: &x[i],
                    y: &y[i],
                })
                .collect();
            HbnModel::fit(&seqs, &params).map_err(model_err)
        })?;
        Ok(Self { inner })
    }

    /// Runs the filter; returns a dict of per-sample arrays.
    fn estimate<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray1<'_, f64>,
        y: PyReadonlyArray1<'_, f64>,
        mode: &str,
    ) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
        let mode = parse_mode(mode)?;
        let (u, y) = (slice(&u, "u")?.to_vec(), slice(&y, "y")?.to_vec());
        let est = detached(py, || self.inner.estimate(&u, &y, mode).map_err(model_err))?;
        let d = pyo3::types::PyDict::new(py);
        d.set_item("x", PyArray1::from_vec(py, est.x))?;
        d.set_item("x_std", PyArray1::from_vec(py, est.x_std))?;
        d.set_item("y_pred", PyArray1::from_vec(py, est.y_pred))?;
        d.set_item("innovation", PyArray1::from_vec(py, est.innovation))?;
        d.set_item("nis", PyArray1::from_vec(py, est.nis))?;
        d.set_item("q_x", PyArray1::from_vec(py, est.q_x))?;
        d.set_item("r", PyArray1::from_vec(py, est.r))?;
        d.set_item("flags", PyArray1::from_vec(py, est.flags))?;
        d.set_item("obs_min", PyArray1::from_vec(py, est.obs_min))?;
        d.set_item("obs_max", PyArray1::from_vec(py, est.obs_max))?;
        Ok(d)
    }

    /// Open-loop GP simulation from `u` alone.
    fn simulate_open_loop<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<Arr<'py>> {
        let u = slice(&u, "u")?.to_vec();
        let x = detached(py, || self.inner.simulate_open_loop(&u).map_err(model_err))?;
        Ok(PyArray1::from_vec(py, x))
    }

    /// Default filter settings of a mode as JSON.
    fn ekf_config_json(&self, mode: &str) -> PyResult<String> {
        json(&self.inner.ekf_config(parse_mode(mode)?))
    }
    /// Sample rate (Hz).
    #[getter]
    fn rate(&self) -> f64 {
        self.inner.rate_hz()
    }
    /// Signals (names, log paths, units) as JSON.
    fn signals_json(&self) -> PyResult<String> {
        json(self.inner.signals())
    }
    /// Training parameters as JSON.
    fn params_json(&self) -> PyResult<String> {
        json(self.inner.params())
    }
    /// Training summary as JSON.
    fn summary_json(&self) -> PyResult<String> {
        json(self.inner.summary())
    }
    /// The transition GP.
    fn transition(&self) -> GaussianProcessCore {
        GaussianProcessCore::wrap(self.inner.transition().clone())
    }
    /// The sensor GP.
    fn sensor(&self) -> GaussianProcessCore {
        GaussianProcessCore::wrap(self.inner.sensor().clone())
    }
    /// The model as JSON (the format of `save`, shared with the CLI).
    fn to_json(&self) -> PyResult<String> {
        self.inner.to_json().map_err(model_err)
    }
    /// Parses `to_json` output.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Self> {
        Ok(Self {
            inner: HbnModel::from_json(text, "<string>").map_err(model_err)?,
        })
    }
    /// Writes the model atomically (the CLI's `hbn train --out` format).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        detached(py, || self.inner.save(&path).map_err(model_err))
    }
    /// Loads a model written by `save` or by `hbn train`.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let inner = detached(py, move || HbnModel::load(&path).map_err(model_err))?;
        Ok(Self { inner })
    }
}

// ---------------------------------------------------------------------------------------------
// Functions
// ---------------------------------------------------------------------------------------------

/// Simulates a hysteretic system under a random bounded-increment input: `(u, x, y)`.
#[pyfunction]
#[pyo3(signature = (system, steps, seed, noise_gain, rate))]
fn simulate<'py>(
    py: Python<'py>,
    system: &str,
    steps: usize,
    seed: u64,
    noise_gain: f64,
    rate: f64,
) -> PyResult<(Arr<'py>, Arr<'py>, Arr<'py>)> {
    let kind = SystemKind::from_str(system).map_err(value_err)?;
    let cfg = SimConfig {
        system: kind,
        noise_gain,
        rate_hz: rate,
        seed,
    };
    let t = detached(py, move || {
        hbn_sim::simulate_random(&cfg, steps).map_err(value_err)
    })?;
    Ok((
        PyArray1::from_vec(py, t.u),
        PyArray1::from_vec(py, t.x),
        PyArray1::from_vec(py, t.y),
    ))
}

/// Scores of an estimate against a reference: RMSE, nRMSE and the calibration of its standard
/// deviation (`hbn_model::metrics`), as a dict.
#[pyfunction]
fn score<'py>(
    py: Python<'py>,
    x: PyReadonlyArray1<'_, f64>,
    x_std: PyReadonlyArray1<'_, f64>,
    x_ref: PyReadonlyArray1<'_, f64>,
) -> PyResult<Bound<'py, pyo3::types::PyDict>> {
    let (x, s, r) = (
        slice(&x, "x")?,
        slice(&x_std, "x_std")?,
        slice(&x_ref, "x_ref")?,
    );
    if x.len() != r.len() || s.len() != r.len() {
        return Err(PyValueError::new_err(format!(
            "x, x_std and x_ref must have the same length (got {}, {}, {})",
            x.len(),
            s.len(),
            r.len()
        )));
    }
    let c = hbn_model::metrics::calibration(x, s, r);
    let d = pyo3::types::PyDict::new(py);
    d.set_item("rmse", hbn_model::metrics::rmse(x, r))?;
    d.set_item("nrmse", hbn_model::metrics::nrmse(x, r))?;
    d.set_item("coverage_1sigma", c.coverage_1sigma)?;
    d.set_item("coverage_2sigma", c.coverage_2sigma)?;
    d.set_item("mean_nees", c.mean_nees)?;
    d.set_item("nlpd", c.nlpd)?;
    d.set_item("samples", c.samples)?;
    Ok(d)
}

/// Names of the simulated systems.
#[pyfunction]
fn systems() -> Vec<&'static str> {
    SystemKind::ALL.iter().map(|k| k.name()).collect()
}

/// Reads signals from an MCAP log and resamples them on one grid: `(t, columns, rate)`.
#[pyfunction]
#[pyo3(signature = (path, signals, rate))]
#[allow(clippy::type_complexity)]
fn read_mcap<'py>(
    py: Python<'py>,
    path: PathBuf,
    signals: Vec<String>,
    rate: Option<f64>,
) -> PyResult<(Arr<'py>, Vec<Arr<'py>>, f64)> {
    let paths = signals
        .iter()
        .map(|s| SignalPath::from_str(s).map_err(io_err))
        .collect::<PyResult<Vec<_>>>()?;
    if paths.is_empty() {
        return Err(PyValueError::new_err("signals: give at least one signal"));
    }
    let aligned = detached(py, move || {
        let raw = hbn_io::read_signals(&path, &paths, &ReadOptions::default()).map_err(io_err)?;
        let rate = match rate {
            Some(r) => r,
            None => hbn_io::native_rate_hz(&raw[0]).ok_or_else(|| {
                PyValueError::new_err(format!(
                    "`{}` has fewer than 2 samples or no time step; pass rate=",
                    signals[0]
                ))
            })?,
        };
        hbn_io::resample(&raw, &ResampleOptions::new(rate)).map_err(io_err)
    })?;
    let rate = aligned.rate_hz;
    let cols = aligned
        .columns
        .into_iter()
        .map(|c| PyArray1::from_vec(py, c))
        .collect();
    Ok((PyArray1::from_vec(py, aligned.t_s), cols, rate))
}

/// Topics of an MCAP log: `[(topic, message_count, message_encoding, schema_name)]`.
#[pyfunction]
fn list_topics(
    py: Python<'_>,
    path: PathBuf,
) -> PyResult<Vec<(String, u64, String, Option<String>)>> {
    let topics = detached(py, move || hbn_io::list_topics(&path).map_err(io_err))?;
    Ok(topics
        .into_iter()
        .map(|t| (t.topic, t.message_count, t.message_encoding, t.schema_name))
        .collect())
}

/// Kernel names accepted by `kernel=`.
#[pyfunction]
fn kernel_names() -> &'static str {
    KernelChoice::NAMES
}

/// Estimation mode names.
#[pyfunction]
fn mode_names() -> Vec<&'static str> {
    vec![mode_name(Mode::Ekf), mode_name(Mode::EkfBlr)]
}

/// Names of the estimator's guard flags, in bit order (bit `i` is element `i`).
#[pyfunction]
fn flag_names() -> Vec<&'static str> {
    hbn_core::Flags::NAMES.to_vec()
}

/// The native extension of the `hbn` package.
#[pymodule]
fn _hbn(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<GaussianProcessCore>()?;
    m.add_class::<HysteresisModelCore>()?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(systems, m)?)?;
    m.add_function(wrap_pyfunction!(score, m)?)?;
    m.add_function(wrap_pyfunction!(read_mcap, m)?)?;
    m.add_function(wrap_pyfunction!(list_topics, m)?)?;
    m.add_function(wrap_pyfunction!(kernel_names, m)?)?;
    m.add_function(wrap_pyfunction!(mode_names, m)?)?;
    m.add_function(wrap_pyfunction!(flag_names, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("MODEL_FORMAT_VERSION", hbn_model::MODEL_FORMAT_VERSION)?;
    m.add("DEFAULT_INDUCING", hbn_model::DEFAULT_INDUCING)?;
    Ok(())
}
