//! Python bindings of hbn (`hbn._hbn`).
//!
//! This crate only converts types and releases the GIL: every algorithm, default and check lives
//! in the workspace crates (`hbn-pipeline` for logs, `hbn-model` for the model, its parameters
//! and the streaming filter, `hbn-gp`, `hbn-sim`). The scikit-learn style classes are in the
//! pure-Python package `hbn` (`python/hbn/__init__.py`), which calls the `*Core` classes and
//! functions here.
//!
//! Errors are classes under `hbn.HbnError` (created at import, each also deriving from the
//! builtin it refines, so `except ValueError` / `except FileNotFoundError` keep working):
//! `HbnIOError` (OSError; `HbnFileNotFoundError` also FileNotFoundError), `DataError`,
//! `ModelFileError`, `ConfigError` (ValueError; `.keyword` names the argument to change) and
//! `TrainingError` (RuntimeError). Heavy calls run with the GIL released, inside
//! `catch_unwind`, so a bug surfaces as a `RuntimeError` rather than a panic.
//!
//! A keyword argument is the Rust name of what it sets ([`Param::name`], the field of
//! `HbnParams`; [`LogOption::name`]): `n_starts`, `max_points`, `rate_hz`, `max_gap_s`.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::PathBuf;
use std::str::FromStr;
use std::sync::Arc;

use hbn_core::vector::{Dims, MAX_INPUTS, MAX_SENSORS, MAX_STATES, VectorStepOutput};
use hbn_core::{Flags, Mode, Want};
use hbn_gp::{GaussianProcess, GpError, GpParams, RawHyperparameters, SparseParams};
use hbn_io::{IoError, SignalPath};
use hbn_model::explore::{Criterion, ExploreError, ExploreParams, Explorer, Phase, Strategy};
use hbn_model::vector::VECTOR_MODEL_FORMAT;
use hbn_model::{
    Estimate, Filter, FilterOutput, HbnParams, HysteresisModel, KernelChoice, ModelError,
    ModelFileProblem, Param, ParamValue, Problem, SensorInputs, Sequence, SignalInfo, SignalNames,
    Signals, VectorEstimate, VectorFilter, VectorModel, VectorSequence,
};
use hbn_pipeline::{
    LogOption, LogOptions, OptionError, Outputs, PipelineError, SignalChoice, TrainSignals,
    VectorSignals,
};
use hbn_sim::{MultiConfig, MultiKind, SimConfig, SimError, Simulator, SystemKind};
use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray1};
use pyo3::exceptions::{
    PyException, PyFileNotFoundError, PyOSError, PyRuntimeError, PyTypeError, PyValueError,
};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyBool, PyBytes, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple, PyType};

// ---------------------------------------------------------------------------------------------
// Names: the Python keyword of every setting is its Rust name
// ---------------------------------------------------------------------------------------------

/// The keyword argument of a GP parameter (`hbn.GaussianProcess`): the field of
/// [`GpParams`], but `lengthscales` (scikit-learn's spelling of a kernel hyperparameter).
fn gp_keyword(name: &str) -> &str {
    match name {
        "length_scales" => "lengthscales",
        other => other,
    }
}

/// Training parameters settable by keyword: every [`Param`] but the BLR prior, in the order
/// they are applied (the shorthand `kernel` before the kernel of each GP, which overrides it).
fn keyword_params() -> impl Iterator<Item = Param> {
    Param::ALL.into_iter().filter(|&p| p != Param::Blr)
}

// ---------------------------------------------------------------------------------------------
// Exceptions
// ---------------------------------------------------------------------------------------------

struct Classes {
    base: Py<PyType>,
    io: Py<PyType>,
    not_found: Py<PyType>,
    data: Py<PyType>,
    model_file: Py<PyType>,
    config: Py<PyType>,
    training: Py<PyType>,
}

static CLASSES: PyOnceLock<Classes> = PyOnceLock::new();

fn make_class(
    py: Python<'_>,
    name: &str,
    bases: Vec<Bound<'_, PyAny>>,
    doc: &str,
) -> PyResult<Py<PyType>> {
    let dict = PyDict::new(py);
    dict.set_item("__doc__", doc)?;
    dict.set_item("__module__", "hbn")?;
    let typ = py.get_type::<PyType>();
    let cls = typ.call1((name, PyTuple::new(py, bases)?, dict))?;
    Ok(cls.cast_into::<PyType>()?.unbind())
}

fn classes(py: Python<'_>) -> PyResult<&Classes> {
    CLASSES.get_or_try_init(py, || {
        let exc = py.get_type::<PyException>().into_any();
        let base = make_class(py, "HbnError", vec![exc], "Base class of every hbn error.")?;
        let b = || base.bind(py).clone().into_any();
        let io = make_class(
            py,
            "HbnIOError",
            vec![b(), py.get_type::<PyOSError>().into_any()],
            "A file could not be read or written (also an OSError).",
        )?;
        let not_found = make_class(
            py,
            "HbnFileNotFoundError",
            vec![
                io.bind(py).clone().into_any(),
                py.get_type::<PyFileNotFoundError>().into_any(),
            ],
            "A file does not exist (also a FileNotFoundError).",
        )?;
        let value = || py.get_type::<PyValueError>().into_any();
        let data = make_class(
            py,
            "DataError",
            vec![b(), value()],
            "Bad training or estimation data, or a log that cannot be used (also a ValueError).",
        )?;
        let model_file = make_class(
            py,
            "ModelFileError",
            vec![b(), value()],
            "A file that is not an hbn model or GP of a supported version (also a ValueError).",
        )?;
        let config = make_class(
            py,
            "ConfigError",
            vec![b(), value()],
            "An invalid argument; `keyword` names it (also a ValueError).",
        )?;
        let training = make_class(
            py,
            "TrainingError",
            vec![b(), py.get_type::<PyRuntimeError>().into_any()],
            "Training failed numerically (also a RuntimeError).",
        )?;
        Ok(Classes {
            base,
            io,
            not_found,
            data,
            model_file,
            config,
            training,
        })
    })
}

/// What kind of Python exception a library error becomes.
enum Kind {
    Io(std::io::ErrorKind),
    Data,
    ModelFile,
    Config(String),
    Training,
    Internal,
}

/// A library error on its way to Python: its kind and message.
struct Fail {
    kind: Kind,
    message: String,
}

impl Fail {
    fn new(kind: Kind, message: impl Into<String>) -> Self {
        Self {
            kind,
            message: message.into(),
        }
    }

    /// An invalid argument: `invalid keyword: problem`.
    fn config(keyword: &str, problem: impl std::fmt::Display) -> Self {
        Self::new(
            Kind::Config(keyword.to_owned()),
            format!("invalid {keyword}: {problem}"),
        )
    }

    /// An invalid argument whose value is known: `invalid keyword=value: rule`.
    fn config_value(keyword: &str, value: &str, rule: impl std::fmt::Display) -> Self {
        Self::new(
            Kind::Config(keyword.to_owned()),
            format!("invalid {keyword}={value}: {rule}"),
        )
    }

    /// A parameter's [`Problem`], with the value as given in Python (`given`, its `repr`) when
    /// it is known: `invalid max_points=1: must be at least 2`. A list given names the element
    /// at fault too (`invalid memory=[0.1, 1.5]: must be in (0, 1], got 1.5`).
    fn problem(keyword: &str, problem: &Problem, given: Option<&Bound<'_, PyAny>>) -> Self {
        let (value, rule) = problem_parts(problem);
        let list =
            given.is_some_and(|g| g.is_instance_of::<PyList>() || g.is_instance_of::<PyTuple>());
        let repr = given.and_then(|g| g.repr().ok()).map(|r| r.to_string());
        match (repr, value) {
            (Some(r), Some(_)) if list => Self::config_value(keyword, &r, problem),
            (Some(r), _) => Self::config_value(keyword, &r, rule),
            (None, Some(v)) => Self::config_value(keyword, &v, rule),
            (None, None) => Self::config(keyword, rule),
        }
    }

    fn into_py(self, py: Python<'_>) -> PyErr {
        let c = match classes(py) {
            Ok(c) => c,
            Err(e) => return e,
        };
        let (cls, keyword) = match &self.kind {
            Kind::Io(std::io::ErrorKind::NotFound) => (&c.not_found, None),
            Kind::Io(_) => (&c.io, None),
            Kind::Data => (&c.data, None),
            Kind::ModelFile => (&c.model_file, None),
            Kind::Config(k) => (&c.config, Some(k.clone())),
            Kind::Training => (&c.training, None),
            Kind::Internal => return PyRuntimeError::new_err(self.message),
        };
        let err = PyErr::from_type(cls.bind(py).clone(), (self.message,));
        if let Some(k) = keyword {
            let _ = err.value(py).setattr("keyword", k);
        }
        err
    }
}

/// The value a [`Problem`] names (if any) and the rule it breaks, without the value.
fn problem_parts(p: &Problem) -> (Option<String>, String) {
    match p {
        Problem::NotPositive { value } => (
            Some(value.to_string()),
            "must be a finite number > 0".into(),
        ),
        Problem::OutOfRange { value, min, max } => (
            Some(value.to_string()),
            format!("must be in ({min}, {max}]"),
        ),
        Problem::Between { value, min, max } => (
            Some(value.to_string()),
            format!("must be in [{min}, {max}]"),
        ),
        Problem::TooSmall { value, min } => {
            (Some(value.to_string()), format!("must be at least {min}"))
        }
        Problem::Unknown { given, choices } => {
            // Quoted as Python's repr quotes a string.
            (
                Some(format!("'{given}'")),
                format!("choose one of {choices}"),
            )
        }
        Problem::WrongType { expected } => (None, format!("expected {expected}")),
        Problem::Invalid { reason } => (None, (*reason).to_owned()),
    }
}

impl From<IoError> for Fail {
    fn from(e: IoError) -> Self {
        let kind = match &e {
            IoError::Open { source, .. } => Kind::Io(source.kind()),
            IoError::BadOption { name, .. } => Kind::Config(
                if *name == "max_gap_s" {
                    "max_gap_s"
                } else {
                    "rate_hz"
                }
                .into(),
            ),
            IoError::GridTooLarge { .. } => Kind::Config("rate_hz".into()),
            IoError::BadPath { .. } => Kind::Config("signals".into()),
            _ => Kind::Data,
        };
        Fail::new(kind, e.to_string())
    }
}

impl From<GpError> for Fail {
    fn from(e: GpError) -> Self {
        match &e {
            GpError::Io { source, .. } => Fail::new(Kind::Io(source.kind()), e.to_string()),
            GpError::Format { .. } => Fail::new(Kind::ModelFile, e.to_string()),
            GpError::InvalidParameter { name, reason } => Fail::config(gp_keyword(name), reason),
            GpError::Core(c) => Fail::config("kernel", c),
            GpError::NotPositiveDefinite { .. } | GpError::OptimizationFailed { .. } => {
                Fail::new(Kind::Training, e.to_string())
            }
            _ => Fail::new(Kind::Data, e.to_string()),
        }
    }
}

impl From<ModelError> for Fail {
    fn from(e: ModelError) -> Self {
        match e {
            ModelError::Config(c) => Fail::problem(c.param.name(), &c.problem, None),
            ModelError::Gp { which, source } => {
                let inner = Fail::from(source);
                Fail::new(inner.kind, format!("{which} GP: {}", inner.message))
            }
            ModelError::Io { ref source, .. } => Fail::new(Kind::Io(source.kind()), e.to_string()),
            ModelError::ModelFile { .. } | ModelError::Core(_) => {
                Fail::new(Kind::ModelFile, e.to_string())
            }
            ModelError::Data(_) => Fail::new(Kind::Data, e.to_string()),
            ModelError::FirmwareBudget { .. } => Fail::new(Kind::Training, e.to_string()),
        }
    }
}

impl From<OptionError> for Fail {
    fn from(e: OptionError) -> Self {
        Fail::problem(e.option.name(), &e.problem, None)
    }
}

impl From<PipelineError> for Fail {
    fn from(e: PipelineError) -> Self {
        let hint = |f: Fail, h: &str| Fail::new(f.kind, format!("{}{h}", f.message));
        match e {
            PipelineError::Option(o) => o.into(),
            PipelineError::Config(c) => Fail::problem(c.param.name(), &c.problem, None),
            PipelineError::Model(m) => m.into(),
            PipelineError::Read { ref source, .. } => {
                let h = match source {
                    IoError::TimeBackwards { .. } => " (or read with time_source=\"log\")",
                    IoError::Gap { .. } | IoError::TooFewSamples { .. } => {
                        " (arguments max_gap_s=, rate_hz=)"
                    }
                    _ => "",
                };
                let kind = match source {
                    IoError::Open { source, .. } => Kind::Io(source.kind()),
                    _ => Kind::Data,
                };
                hint(Fail::new(kind, e.to_string()), h)
            }
            PipelineError::UnknownRate { .. } => {
                hint(Fail::new(Kind::Data, e.to_string()), " (rate_hz=)")
            }
            PipelineError::SignalPath { option, .. } => Fail::config(option.name(), &e),
            PipelineError::Write { ref source, .. } => {
                let kind = match source {
                    IoError::Open { source, .. } => Kind::Io(source.kind()),
                    _ => Kind::Data,
                };
                Fail::new(kind, e.to_string())
            }
            PipelineError::Sim(s) => s.into(),
            other => Fail::new(Kind::Data, other.to_string()),
        }
    }
}

impl From<ExploreError> for Fail {
    fn from(e: ExploreError) -> Self {
        match e {
            ExploreError::InvalidParameter { name, reason } => Fail::config(name, reason),
            ExploreError::Model(m) => m.into(),
            other => Fail::new(Kind::Data, other.to_string()),
        }
    }
}

impl From<SimError> for Fail {
    fn from(e: SimError) -> Self {
        match &e {
            SimError::UnknownSystem { .. } => Fail::config("system", &e),
            SimError::InvalidParameter {
                name,
                value,
                reason,
            } => Fail::config_value(name, &value.to_string(), reason),
            _ => Fail::new(Kind::Data, e.to_string()),
        }
    }
}

/// Runs `f` with the GIL released; a panic becomes `RuntimeError` instead of crossing into
/// Python; a library error becomes its hbn exception class.
fn detached<T, F>(py: Python<'_>, f: F) -> PyResult<T>
where
    F: FnOnce() -> Result<T, Fail> + Send,
    T: Send,
{
    let r = py.detach(|| match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(payload) => {
            let what = payload
                .downcast_ref::<&str>()
                .map(|s| (*s).to_owned())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown panic".to_owned());
            Err(Fail::new(
                Kind::Internal,
                format!("internal error in hbn (please report it): {what}"),
            ))
        }
    });
    r.map_err(|f| f.into_py(py))
}

/// Converts a library error with the GIL held.
fn raise<E: Into<Fail>>(py: Python<'_>, e: E) -> PyErr {
    e.into().into_py(py)
}

// ---------------------------------------------------------------------------------------------
// Conversions
// ---------------------------------------------------------------------------------------------

fn slice<'a>(a: &'a PyReadonlyArray1<'_, f64>, name: &str) -> PyResult<&'a [f64]> {
    a.as_slice()
        .map_err(|e| PyValueError::new_err(format!("{name}: {e}")))
}

/// `mode=` as a [`Mode`]; `None` is the model's default mode (chosen on held-out data).
fn parse_mode(py: Python<'_>, mode: Option<&str>, default: Mode) -> PyResult<Mode> {
    match mode {
        None => Ok(default),
        Some(m) => {
            Mode::from_str(m).map_err(|e| raise(py, Fail::config("mode", format!("{m:?}: {e}"))))
        }
    }
}

fn parse_path(py: Python<'_>, option: LogOption, text: &str) -> PyResult<SignalPath> {
    hbn_pipeline::parse_signal(option, text).map_err(|e| raise(py, e))
}

/// Log options: the library defaults with the given arguments applied.
fn log_options(
    py: Python<'_>,
    rate_hz: Option<f64>,
    time_source: Option<&str>,
    max_gap_s: Option<f64>,
) -> PyResult<LogOptions> {
    log_options_with(py, rate_hz, time_source, max_gap_s, None, None)
}

/// [`log_options`] with the coverage thresholds (training from logs).
fn log_options_with(
    py: Python<'_>,
    rate_hz: Option<f64>,
    time_source: Option<&str>,
    max_gap_s: Option<f64>,
    min_coverage: Option<f64>,
    min_state_samples: Option<usize>,
) -> PyResult<LogOptions> {
    let mut o = LogOptions::default();
    if let Some(c) = min_coverage {
        o.min_coverage = c;
    }
    if let Some(n) = min_state_samples {
        o.min_state_samples = n;
    }
    if let Some(t) = time_source {
        o.time_source = hbn_pipeline::parse_time_source(t).map_err(|e| raise(py, e))?;
    }
    if let Some(g) = max_gap_s {
        o.max_gap_s = g;
    }
    o.rate_hz = rate_hz;
    Ok(o)
}

/// A Python value as a parameter value (integers stay integers, bools stay bools; numpy
/// scalars are read like Python's), or why it cannot be one. A list or tuple is several values
/// to choose among on held-out data (`kernel=`, `n_inducing=`, where `None` is the exact GP).
fn param_value(v: &Bound<'_, PyAny>) -> Result<ParamValue, String> {
    if v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>() {
        let mut out = Vec::new();
        for item in v.try_iter().map_err(|e| e.to_string())? {
            let item = item.map_err(|e| e.to_string())?;
            out.push(if item.is_none() {
                ParamValue::Text("exact".to_owned())
            } else {
                param_value(&item)?
            });
        }
        return Ok(ParamValue::List(out));
    }
    if v.is_instance_of::<PyBool>() {
        return Ok(ParamValue::Bool(v.is_truthy().map_err(|e| e.to_string())?));
    }
    if v.is_instance_of::<PyString>() {
        return v.extract().map(ParamValue::Text).map_err(|e| e.to_string());
    }
    if v.is_instance_of::<PyFloat>() {
        return v.extract().map(ParamValue::Real).map_err(|e| e.to_string());
    }
    if v.is_instance_of::<PyInt>() || v.hasattr("__index__").unwrap_or(false) {
        return v
            .extract()
            .map(ParamValue::Int)
            .map_err(|_| "expected a non-negative integer".to_owned());
    }
    if let Ok(b) = v.extract::<bool>() {
        return Ok(ParamValue::Bool(b));
    }
    if let Ok(r) = v.extract::<f64>() {
        return Ok(ParamValue::Real(r));
    }
    let kind = v
        .get_type()
        .name()
        .map(|n| n.to_string())
        .unwrap_or_default();
    Err(format!("cannot use a value of type {kind} here"))
}

/// Training parameters: [`HbnParams::default`] with the keyword arguments applied by
/// [`HbnParams::set`] in [`Param::ALL`]'s order, then checked ([`HbnParams::check_ref`]), so
/// that an error shows the value as given. `None` keeps a parameter's default, except
/// `n_inducing=None`, which asks for exact GPs (and no model selection among inducing
/// settings), as documented. Unknown keywords are a `TypeError`, like Python's own.
fn hbn_params(py: Python<'_>, kwargs: Option<&Bound<'_, PyDict>>) -> PyResult<HbnParams> {
    let mut p = HbnParams::default();
    let Some(kwargs) = kwargs else {
        return Ok(p);
    };
    for k in kwargs.keys() {
        let key: String = k.extract()?;
        if !keyword_params().any(|p| p.name() == key) {
            let known: Vec<&str> = keyword_params().map(Param::name).collect();
            return Err(PyTypeError::new_err(format!(
                "unexpected keyword argument {key:?}; training parameters: {}",
                known.join(", ")
            )));
        }
    }
    for param in keyword_params() {
        let Some(v) = kwargs.get_item(param.name())? else {
            continue;
        };
        let value = if v.is_none() {
            if param != Param::Inducing {
                continue;
            }
            ParamValue::Text("exact".to_owned())
        } else {
            let repr = || v.repr().map(|r| r.to_string()).unwrap_or_default();
            param_value(&v)
                .map_err(|why| raise(py, Fail::config_value(param.name(), &repr(), why)))?
        };
        p.set(param, value)
            .map_err(|e| raise(py, Fail::problem(e.param.name(), &e.problem, Some(&v))))?;
    }
    if let Err(e) = p.check_ref() {
        let given = kwargs.get_item(e.param.name())?.filter(|g| !g.is_none());
        return Err(raise(
            py,
            Fail::problem(e.param.name(), &e.problem, given.as_ref()),
        ));
    }
    Ok(p)
}

fn value_to_py<'py>(py: Python<'py>, v: &ParamValue) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        ParamValue::Int(i) => i.into_pyobject(py)?.into_any(),
        ParamValue::Real(r) => r.into_pyobject(py)?.into_any(),
        ParamValue::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
        ParamValue::Text(t) => t.into_pyobject(py)?.into_any(),
        ParamValue::List(items) => {
            let l = PyList::empty(py);
            for item in items {
                l.append(value_to_py(py, item)?)?;
            }
            l.into_any()
        }
    })
}

/// A JSON value as Python objects (dicts, lists, numbers, strings, None).
fn json_to_py<'py>(py: Python<'py>, v: &serde_json::Value) -> PyResult<Bound<'py, PyAny>> {
    use serde_json::Value;
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
        Value::Number(n) => match (n.as_u64(), n.as_i64()) {
            (Some(u), _) => u.into_pyobject(py)?.into_any(),
            (None, Some(i)) => i.into_pyobject(py)?.into_any(),
            _ => n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any(),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any(),
        Value::Array(a) => {
            let l = PyList::empty(py);
            for x in a {
                l.append(json_to_py(py, x)?)?;
            }
            l.into_any()
        }
        Value::Object(m) => {
            let d = PyDict::new(py);
            for (k, x) in m {
                d.set_item(k, json_to_py(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// A serialisable value as Python objects.
fn to_py<'py, T: serde::Serialize>(py: Python<'py>, v: &T) -> PyResult<Bound<'py, PyAny>> {
    let value = serde_json::to_value(v)
        .map_err(|e| PyRuntimeError::new_err(format!("internal error in hbn: {e}")))?;
    json_to_py(py, &value)
}

/// A parameter's value in Python: the exact GP (`n_inducing`) and no cap
/// (`max_signal_variance`) are `None`, like a kernel chosen by evidence (no value).
fn param_to_py<'py>(
    py: Python<'py>,
    param: Param,
    v: Option<ParamValue>,
) -> PyResult<Bound<'py, PyAny>> {
    let is_none = |v: &ParamValue| match (param, v) {
        (Param::Inducing, ParamValue::Text(t)) => t == "exact",
        (Param::MaxSignalVariance, ParamValue::Text(t)) => t == "none",
        _ => false,
    };
    let none = || py.None().into_bound(py);
    match v {
        None => Ok(none()),
        Some(v) if is_none(&v) => Ok(none()),
        Some(ParamValue::List(items)) if param == Param::Inducing => {
            let l = PyList::empty(py);
            for item in &items {
                l.append(if is_none(item) {
                    none()
                } else {
                    value_to_py(py, item)?
                })?;
            }
            Ok(l.into_any())
        }
        Some(v) => value_to_py(py, &v),
    }
}

/// Training parameters as a dict by keyword, plus `blr` and `signals`. `with_kernel` adds the
/// shorthand `kernel` (for the defaults: `None`, each GP chooses by evidence); a trained model
/// has the kernel of each GP.
fn params_dict<'py>(
    py: Python<'py>,
    p: &HbnParams,
    with_kernel: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    for param in keyword_params().filter(|&q| with_kernel || q != Param::Kernel) {
        d.set_item(param.name(), param_to_py(py, param, p.get(param))?)?;
    }
    d.set_item("blr", to_py(py, &p.blr)?)?;
    d.set_item("signals", to_py(py, &p.signals)?)?;
    Ok(d)
}

fn signal_info(
    v: Option<Bound<'_, PyAny>>,
    default: SignalInfo,
    key: &str,
) -> PyResult<SignalInfo> {
    let Some(v) = v.filter(|v| !v.is_none()) else {
        return Ok(default);
    };
    if let Ok(path) = v.extract::<String>() {
        return Ok(SignalInfo {
            path: Some(path),
            ..default
        });
    }
    let d = v.cast_into::<PyDict>().map_err(|_| {
        PyValueError::new_err(format!(
            "signals[{key:?}] must be a message path string or a dict"
        ))
    })?;
    let get = |k: &str| -> PyResult<Option<String>> {
        match d.get_item(k)? {
            Some(x) if !x.is_none() => Ok(Some(x.extract()?)),
            _ => Ok(None),
        }
    };
    Ok(SignalInfo {
        name: get("name")?.unwrap_or(default.name),
        path: get("path")?,
        unit: get("unit")?,
        native_rate_hz: None,
    })
}

/// `{"u": path-or-dict, "x": ..., "y": ...}` as signal descriptions.
fn signals_from(d: Option<&Bound<'_, PyDict>>) -> PyResult<Signals> {
    let def = Signals::default();
    let Some(d) = d else { return Ok(def) };
    for k in d.keys() {
        let k: String = k.extract()?;
        if !["u", "x", "y"].contains(&k.as_str()) {
            return Err(PyValueError::new_err(format!(
                "signals: unknown key {k:?}; use u, x and y"
            )));
        }
    }
    Ok(Signals {
        input: signal_info(d.get_item("u")?, def.input, "u")?,
        state: signal_info(d.get_item("x")?, def.state, "x")?,
        output: signal_info(d.get_item("y")?, def.output, "y")?,
        ..Signals::default()
    })
}

type Arr<'py> = Bound<'py, PyArray1<f64>>;

fn estimate_dict(py: Python<'_>, est: Estimate) -> PyResult<Bound<'_, PyDict>> {
    let d = PyDict::new(py);
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
    d.set_item("obs_x", PyArray1::from_vec(py, est.obs_x))?;
    Ok(d)
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
    /// Fits a GP to row-major inputs `x` (`len(y) x dim`) and targets `y`; `None` settings take
    /// the library defaults (`default_gp_params()`).
    #[staticmethod]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (x, dim, y, kernel, lengthscales, signal_variance, noise_variance,
                        optimize, normalize, n_starts, max_iters, max_points, seed,
                        n_inducing=None, inducing_points=None, optimize_inducing=false,
                        mean=None))]
    fn fit(
        py: Python<'_>,
        x: PyReadonlyArray1<'_, f64>,
        dim: usize,
        y: PyReadonlyArray1<'_, f64>,
        kernel: &str,
        lengthscales: Option<Vec<f64>>,
        signal_variance: Option<f64>,
        noise_variance: Option<f64>,
        optimize: Option<bool>,
        normalize: Option<bool>,
        n_starts: Option<usize>,
        max_iters: Option<u64>,
        max_points: Option<usize>,
        seed: Option<u64>,
        n_inducing: Option<usize>,
        inducing_points: Option<PyReadonlyArray1<'_, f64>>,
        optimize_inducing: bool,
        mean: Option<&str>,
    ) -> PyResult<Self> {
        let choice = KernelChoice::from_str(kernel).map_err(|e| {
            let rule = format!("choose one of {}", KernelChoice::NAMES);
            raise(
                py,
                Fail::config_value("kernel", &format!("'{}'", e.given), rule),
            )
        })?;
        let mut params = GpParams::new(choice.spec(dim, [0, 1]));
        if let Some(mean) = mean {
            params.mean = mean
                .parse()
                .map_err(|e: String| raise(py, Fail::config("mean", e)))?;
        }
        params.optimize = optimize.unwrap_or(params.optimize);
        params.normalize = normalize.unwrap_or(params.normalize);
        params.n_starts = n_starts.unwrap_or(params.n_starts);
        params.max_iters = max_iters.unwrap_or(params.max_iters);
        params.max_points = max_points.unwrap_or(params.max_points);
        params.seed = seed.unwrap_or(params.seed);
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
        let inner = detached(py, move || Ok(hbn_gp::fit(&params, &x, &y)?))?;
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
    ) -> PyResult<(Arr<'py>, Option<Arr<'py>>, Option<Arr<'py>>)> {
        let x = slice(&x, "X")?.to_vec();
        let want = Want {
            variance,
            grad_mean: grad,
            grad_variance: false,
        };
        let d = self.inner.kernel().dim;
        let (mean, var, g) = detached(py, || {
            let preds = self.inner.predict_many(&x, want)?;
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
    /// Training report as a dict.
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, self.inner.report())
    }
    /// Training warnings.
    fn warnings(&self) -> Vec<String> {
        self.inner.report().warnings()
    }
    /// The model as JSON (the format of `save`; GIL released).
    fn to_json(&self, py: Python<'_>) -> PyResult<String> {
        detached(py, || Ok(self.inner.to_json()?))
    }
    /// Parses `to_json` output (GIL released).
    #[staticmethod]
    fn from_json(py: Python<'_>, text: &str) -> PyResult<Self> {
        let inner = detached(py, || Ok(GaussianProcess::from_json(text, "<string>")?))?;
        Ok(Self::wrap(inner))
    }
    /// Writes the model atomically.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        detached(py, || Ok(self.inner.save(&path)?))
    }
    /// Loads a model written by `save`.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let inner = detached(py, move || Ok(GaussianProcess::load(&path)?))?;
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
// HBN model and the streaming filter
// ---------------------------------------------------------------------------------------------

/// Native HBN model (`hbn_model::HysteresisModel`). Use `hbn.HysteresisModel` instead.
#[pyclass(name = "HysteresisModelCore", module = "hbn._hbn", frozen)]
pub struct HysteresisModelCore {
    inner: Arc<HysteresisModel>,
}

impl HysteresisModelCore {
    fn wrap(model: HysteresisModel) -> Self {
        Self {
            inner: Arc::new(model),
        }
    }
}

#[pymethods]
impl HysteresisModelCore {
    /// Fits both GPs to trajectories (lists of equal-length `u`, `x`, `y` arrays; `x` NaN where
    /// the state was not measured, `HysteresisModel::fit_partial`); `params` are the training
    /// keywords (`rate_hz` among them) applied over the library defaults.
    #[staticmethod]
    #[pyo3(signature = (u, x, y, signals, params))]
    fn fit(
        py: Python<'_>,
        u: Vec<PyReadonlyArray1<'_, f64>>,
        x: Vec<PyReadonlyArray1<'_, f64>>,
        y: Vec<PyReadonlyArray1<'_, f64>>,
        signals: Option<&Bound<'_, PyDict>>,
        params: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let mut p = hbn_params(py, params)?;
        p.signals = signals_from(signals)?;
        if u.len() != x.len() || u.len() != y.len() {
            return Err(raise(
                py,
                Fail::new(
                    Kind::Data,
                    format!(
                        "u, x and y must hold the same number of trajectories (got {}, {}, {})",
                        u.len(),
                        x.len(),
                        y.len()
                    ),
                ),
            ));
        }
        let own = |v: &[PyReadonlyArray1<'_, f64>], n: &str| -> PyResult<Vec<Vec<f64>>> {
            v.iter().map(|a| Ok(slice(a, n)?.to_vec())).collect()
        };
        let (u, x, y) = (own(&u, "u")?, own(&x, "x")?, own(&y, "y")?);
        let inner = detached(py, move || {
            let seqs: Vec<Sequence<'_>> = (0..u.len())
                .map(|i| Sequence::new(&u[i], &x[i], &y[i]))
                .collect();
            Ok(HysteresisModel::fit_partial(&seqs, &p)?)
        })?;
        Ok(Self::wrap(inner))
    }

    /// Trains from MCAP logs exactly like `hbn train` (`hbn_pipeline::train_from_logs`): the
    /// same logs, paths and parameters give the same model file.
    #[staticmethod]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (logs, input, state, output, rate_hz, time_source, max_gap_s, params, min_coverage=None, min_state_samples=None))]
    fn from_logs(
        py: Python<'_>,
        logs: Vec<PathBuf>,
        input: Option<&str>,
        state: Option<&str>,
        output: Option<&str>,
        rate_hz: Option<f64>,
        time_source: Option<&str>,
        max_gap_s: Option<f64>,
        params: Option<&Bound<'_, PyDict>>,
        min_coverage: Option<f64>,
        min_state_samples: Option<usize>,
    ) -> PyResult<Self> {
        if logs.is_empty() {
            return Err(raise(
                py,
                Fail::config_value("logs", "[]", "give at least one MCAP log"),
            ));
        }
        let p = hbn_params(py, params)?;
        let opts = log_options_with(
            py,
            rate_hz,
            time_source,
            max_gap_s,
            min_coverage,
            min_state_samples,
        )?;
        let d = TrainSignals::default();
        let signals = TrainSignals {
            input: match input {
                Some(t) => parse_path(py, LogOption::Input, t)?,
                None => d.input,
            },
            state: match state {
                Some(t) => parse_path(py, LogOption::State, t)?,
                None => d.state,
            },
            output: match output {
                Some(t) => parse_path(py, LogOption::Output, t)?,
                None => d.output,
            },
        };
        let trained = detached(py, move || {
            Ok(hbn_pipeline::train_from_logs(
                &logs,
                &signals,
                opts,
                p,
                &mut |_| {},
            )?)
        })?;
        Ok(Self::wrap(trained.model))
    }

    /// Runs the filter over a sequence; returns a dict of per-sample arrays.
    #[pyo3(signature = (u, y, mode))]
    fn estimate<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray1<'_, f64>,
        y: PyReadonlyArray1<'_, f64>,
        mode: Option<&str>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mode = parse_mode(py, mode, self.inner.default_mode())?;
        let (u, y) = (slice(&u, "u")?.to_vec(), slice(&y, "y")?.to_vec());
        let est = detached(py, || Ok(self.inner.estimate(&u, &y, mode)?))?;
        estimate_dict(py, est)
    }

    /// Smooths a sequence (the filter forward, the Rauch-Tung-Striebel pass backward,
    /// `HysteresisModel::smooth`); returns the dict of `estimate` with the smoothed `x` and
    /// `x_std`.
    #[pyo3(signature = (u, y, mode))]
    fn smooth<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray1<'_, f64>,
        y: PyReadonlyArray1<'_, f64>,
        mode: Option<&str>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mode = parse_mode(py, mode, self.inner.default_mode())?;
        let (u, y) = (slice(&u, "u")?.to_vec(), slice(&y, "y")?.to_vec());
        let est = detached(py, || Ok(self.inner.smooth(&u, &y, mode)?))?;
        estimate_dict(py, est)
    }

    /// Reads `u` and `y` from a log at the model's rate, runs the filter, optionally writes
    /// CSV and MCAP (like `hbn estimate`); returns `(t, dict of per-sample arrays)`.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (path, mode, input, output, csv, mcap, time_source, max_gap_s))]
    fn estimate_log<'py>(
        &self,
        py: Python<'py>,
        path: PathBuf,
        mode: Option<&str>,
        input: Option<&str>,
        output: Option<&str>,
        csv: Option<PathBuf>,
        mcap: Option<PathBuf>,
        time_source: Option<&str>,
        max_gap_s: Option<f64>,
    ) -> PyResult<(Arr<'py>, Bound<'py, PyDict>)> {
        let mode = parse_mode(py, mode, self.inner.default_mode())?;
        let time_source = time_source
            .map(|t| hbn_pipeline::parse_time_source(t).map_err(|e| raise(py, e)))
            .transpose()?;
        let opts = hbn_pipeline::model_log_options(&self.inner, time_source, max_gap_s);
        opts.check().map_err(|e| raise(py, e))?;
        let signals = SignalChoice {
            input: input
                .map(|t| parse_path(py, LogOption::Input, t))
                .transpose()?,
            state: None,
            output: output
                .map(|t| parse_path(py, LogOption::Output, t))
                .transpose()?,
        };
        let outputs = Outputs { csv, mcap };
        let est = detached(py, || {
            Ok(hbn_pipeline::estimate_log(
                &self.inner,
                &path,
                &signals,
                mode,
                opts,
                &outputs,
                &mut |_| {},
            )?)
        })?;
        let t = PyArray1::from_vec(py, est.log.aligned.t_s);
        Ok((t, estimate_dict(py, est.estimate)?))
    }

    /// A streaming filter over this model (sharing it, not copying it).
    #[pyo3(signature = (mode))]
    fn filter(&self, py: Python<'_>, mode: Option<&str>) -> PyResult<FilterCore> {
        let mode = parse_mode(py, mode, self.inner.default_mode())?;
        let inner = Filter::new(self.inner.clone(), mode).map_err(|e| raise(py, e))?;
        Ok(FilterCore { inner })
    }

    /// Open-loop GP simulation from `u` alone.
    fn simulate_open_loop<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<Arr<'py>> {
        let u = slice(&u, "u")?.to_vec();
        let x = detached(py, || Ok(self.inner.simulate_open_loop(&u)?))?;
        Ok(PyArray1::from_vec(py, x))
    }

    /// Default filter settings of a mode, as a dict.
    #[pyo3(signature = (mode))]
    fn ekf_config<'py>(&self, py: Python<'py>, mode: Option<&str>) -> PyResult<Bound<'py, PyAny>> {
        let mode = parse_mode(py, mode, self.inner.default_mode())?;
        to_py(py, &self.inner.ekf_config(mode))
    }
    /// Prior `(mean, variance)` of `x_0` given the first measurement, or `None`.
    fn initial_state(&self, y0: f64) -> Option<(f64, f64)> {
        self.inner.initial_state(y0)
    }
    /// Sample rate (Hz).
    #[getter]
    fn rate_hz(&self) -> f64 {
        self.inner.rate_hz()
    }
    /// Signals (names, log paths, units) as a dict.
    fn signals<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, self.inner.signals())
    }
    /// Training parameters as a dict by keyword argument.
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        params_dict(py, self.inner.params(), false)
    }
    /// Training summary as a dict.
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let s = self.inner.summary();
        let d = to_py(py, s)?;
        // Wall-clock time is not saved in model files; report it while it is known.
        d.set_item("seconds", s.seconds)?;
        Ok(d)
    }
    /// The mode estimation uses without `mode=` (chosen on held-out data at training).
    fn default_mode(&self) -> &'static str {
        self.inner.default_mode().name()
    }
    /// Noise scales per mode and the default mode, as a dict.
    fn tuning<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, self.inner.tuning())
    }
    /// The transition GP.
    fn transition(&self) -> GaussianProcessCore {
        GaussianProcessCore::wrap(self.inner.transition().clone())
    }
    /// The sensor GP.
    fn sensor(&self) -> GaussianProcessCore {
        GaussianProcessCore::wrap(self.inner.sensor().clone())
    }
    /// The model as JSON (the format of `save`, shared with the CLI; GIL released).
    fn to_json(&self, py: Python<'_>) -> PyResult<String> {
        detached(py, || Ok(self.inner.to_json()?))
    }
    /// Parses `to_json` output (GIL released).
    #[staticmethod]
    fn from_json(py: Python<'_>, text: &str) -> PyResult<Self> {
        let inner = detached(py, || Ok(HysteresisModel::from_json(text, "<string>")?))?;
        Ok(Self::wrap(inner))
    }
    /// The bytes of the model file `save` writes (GIL released): what a pickled model holds.
    fn to_bytes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let inner = &self.inner;
        let text = detached(py, move || Ok(inner.to_json()?))?;
        Ok(PyBytes::new(py, text.as_bytes()))
    }
    /// A model from the bytes of a model file (GIL released); `origin` names them in errors.
    #[staticmethod]
    fn from_bytes(py: Python<'_>, data: Vec<u8>, origin: &str) -> PyResult<Self> {
        let origin = origin.to_owned();
        let inner = detached(py, move || {
            let text = String::from_utf8(data).map_err(|_| {
                Fail::new(
                    Kind::ModelFile,
                    format!("{origin}: not an hbn model file (not UTF-8 text)"),
                )
            })?;
            Ok(HysteresisModel::from_json(&text, &origin)?)
        })?;
        Ok(Self::wrap(inner))
    }
    /// Writes the model atomically (the CLI's `hbn train --out` format).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        detached(py, || Ok(self.inner.save(&path)?))
    }
    /// Loads a model written by `save` or by `hbn train`.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let inner = detached(py, move || Ok(HysteresisModel::load(&path)?))?;
        Ok(Self::wrap(inner))
    }
}

/// Native streaming filter (`hbn_model::Filter`). Use `hbn.Filter` instead.
#[pyclass(name = "FilterCore", module = "hbn._hbn")]
pub struct FilterCore {
    inner: Filter,
}

#[pymethods]
impl FilterCore {
    /// One sample: input `u` and measurement `y` (NaN allowed: held or skipped, flagged).
    fn step(&mut self, u: f64, y: f64) -> FilterStep {
        FilterStep::from(self.inner.step(u, y))
    }
    /// Forgets the state; the next step initialises again.
    fn reset(&mut self) {
        self.inner.reset();
    }
    /// The estimation mode.
    #[getter]
    fn mode(&self) -> &'static str {
        self.inner.mode().name()
    }
    /// Samples since the last (re)initialisation.
    #[getter]
    fn steps(&self) -> u64 {
        self.inner.state().map_or(0, |s| s.steps)
    }
}

/// The output of one filter step.
#[pyclass(name = "FilterOutput", module = "hbn", frozen, get_all)]
pub struct FilterStep {
    /// Estimate of the state.
    x: f64,
    /// Standard deviation of the estimate of the state.
    x_std: f64,
    /// Predicted measurement before the update.
    y_pred: f64,
    /// Innovation `y - y_pred` (0 when the update was skipped).
    innovation: f64,
    /// Innovation variance.
    innovation_var: f64,
    /// Normalised innovation squared.
    nis: f64,
    /// Process noise variance used for x.
    q_x: f64,
    /// Measurement noise variance used.
    r: f64,
    /// Guard flags (bits; see `flag_names()`).
    flags: u32,
    /// Smallest eigenvalue of the observability Gramian (NaN for the first samples).
    obs_min: f64,
    /// Largest eigenvalue of the observability Gramian.
    obs_max: f64,
    /// Information on x alone in the observability Gramian (NaN for the first samples).
    obs_x: f64,
}

impl From<FilterOutput> for FilterStep {
    fn from(o: FilterOutput) -> Self {
        Self {
            x: o.x,
            x_std: o.x_std,
            y_pred: o.y_pred,
            innovation: o.innovation,
            innovation_var: o.innovation_var,
            nis: o.nis,
            q_x: o.q_x,
            r: o.r,
            flags: o.flags.0,
            obs_min: o.obs_min,
            obs_max: o.obs_max,
            obs_x: o.obs_x,
        }
    }
}

#[pymethods]
impl FilterStep {
    /// Names of the guard flags that fired.
    fn flag_names(&self) -> Vec<&'static str> {
        Flags(self.flags).names().collect()
    }
    fn __repr__(&self) -> String {
        format!(
            "FilterOutput(x={}, x_std={}, flags={:?})",
            self.x,
            self.x_std,
            self.flag_names()
        )
    }
}

// ---------------------------------------------------------------------------------------------
// Vector model (several inputs, a vector state, several sensors) and its streaming filter
// ---------------------------------------------------------------------------------------------

/// The sizes `(inputs, states, sensors)` of a vector model, checked against its limits.
fn vector_dims(py: Python<'_>, (du, dx, dy): (usize, usize, usize)) -> PyResult<Dims> {
    Dims::new(du, dx, dy).map_err(|e| {
        raise(
            py,
            Fail::new(
                Kind::Data,
                format!(
                    "a model takes 1 to {MAX_INPUTS} inputs, 1 to {MAX_STATES} state components \
                     and 1 to {MAX_SENSORS} sensors, got {du}, {dx} and {dy} ({e})"
                ),
            ),
        )
    })
}

/// Each sensor's inputs for a vector model, as `hbn train --sensor-inputs` gives them: none
/// (chosen on held-out data, one sensor at a time) for the default, else the primary value
/// and the alternatives given (one for every sensor, or one per sensor).
fn vector_sensor_inputs(p: &HbnParams) -> Vec<SensorInputs> {
    let d = HbnParams::default();
    if p.sensor_inputs == d.sensor_inputs && p.select.sensor_inputs == d.select.sensor_inputs {
        return Vec::new();
    }
    std::iter::once(p.sensor_inputs)
        .chain(p.select.sensor_inputs.iter().copied())
        .collect()
}

/// Message paths of one kind of signal.
fn parse_paths(py: Python<'_>, option: LogOption, texts: &[String]) -> PyResult<Vec<SignalPath>> {
    texts.iter().map(|t| parse_path(py, option, t)).collect()
}

/// A row-major `T x d` array (`T x d x d` for `cov`) of a vector estimate as numpy.
fn shaped<'py>(py: Python<'py>, values: Vec<f64>, shape: &[usize]) -> PyResult<Bound<'py, PyAny>> {
    Ok(PyArray1::from_vec(py, values).reshape(shape)?.into_any())
}

fn vector_estimate_dict(py: Python<'_>, est: VectorEstimate) -> PyResult<Bound<'_, PyDict>> {
    let (t, dx, dy) = (est.len(), est.dims.states, est.dims.sensors);
    let d = PyDict::new(py);
    d.set_item("x", shaped(py, est.x, &[t, dx])?)?;
    d.set_item("x_std", shaped(py, est.x_std, &[t, dx])?)?;
    d.set_item("x_cov", shaped(py, est.x_cov, &[t, dx, dx])?)?;
    d.set_item("y_pred", shaped(py, est.y_pred, &[t, dy])?)?;
    d.set_item("innovation", shaped(py, est.innovation, &[t, dy])?)?;
    d.set_item("nis", PyArray1::from_vec(py, est.nis))?;
    d.set_item("flags", PyArray1::from_vec(py, est.flags))?;
    d.set_item("unobservable", PyArray1::from_vec(py, est.unobservable))?;
    Ok(d)
}

/// Native vector HBN model (`hbn_model::VectorModel`). Use `hbn.HysteresisModel` instead.
#[pyclass(name = "VectorModelCore", module = "hbn._hbn", frozen)]
pub struct VectorModelCore {
    inner: Arc<VectorModel>,
}

impl VectorModelCore {
    fn wrap(model: VectorModel) -> Self {
        Self {
            inner: Arc::new(model),
        }
    }
}

#[pymethods]
impl VectorModelCore {
    /// Fits one transition GP per state component and one sensor GP per sensor to
    /// trajectories: lists of row-major `u` (`T x du`), `x` (`T x dx`) and `y` (`T x dy`)
    /// arrays, flattened; `dims` is `(du, dx, dy)`; `names` the signals' names
    /// `(inputs, states, outputs)`; `params` the training keywords.
    #[staticmethod]
    #[pyo3(signature = (u, x, y, dims, names, params))]
    #[allow(clippy::type_complexity)]
    fn fit(
        py: Python<'_>,
        u: Vec<PyReadonlyArray1<'_, f64>>,
        x: Vec<PyReadonlyArray1<'_, f64>>,
        y: Vec<PyReadonlyArray1<'_, f64>>,
        dims: (usize, usize, usize),
        names: Option<(Vec<String>, Vec<String>, Vec<String>)>,
        params: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let p = hbn_params(py, params)?;
        let dims = vector_dims(py, dims)?;
        if u.len() != x.len() || u.len() != y.len() {
            return Err(raise(
                py,
                Fail::new(
                    Kind::Data,
                    format!(
                        "u, x and y must hold the same number of trajectories (got {}, {}, {})",
                        u.len(),
                        x.len(),
                        y.len()
                    ),
                ),
            ));
        }
        let own = |v: &[PyReadonlyArray1<'_, f64>], n: &str| -> PyResult<Vec<Vec<f64>>> {
            v.iter().map(|a| Ok(slice(a, n)?.to_vec())).collect()
        };
        let (u, x, y) = (own(&u, "u")?, own(&x, "x")?, own(&y, "y")?);
        let names = names
            .map(|(inputs, states, outputs)| SignalNames {
                inputs,
                states,
                outputs,
            })
            .unwrap_or_default();
        let inner = detached(py, move || {
            let sensors = vector_sensor_inputs(&p);
            let checked = p.check().map_err(ModelError::Config)?;
            let seqs: Vec<VectorSequence<'_>> = (0..u.len())
                .map(|i| VectorSequence::new(&u[i], &x[i], &y[i], dims))
                .collect();
            Ok(VectorModel::fit_partial(&seqs, &checked, names, &sensors)?)
        })?;
        Ok(Self::wrap(inner))
    }

    /// Trains from MCAP logs exactly like `hbn train` with repeated `--input`, `--state` and
    /// `--output` flags (`hbn_pipeline::train_vector_from_logs`).
    #[staticmethod]
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (logs, inputs, states, outputs, rate_hz, time_source, max_gap_s, params, min_coverage=None, min_state_samples=None))]
    fn from_logs(
        py: Python<'_>,
        logs: Vec<PathBuf>,
        inputs: Vec<String>,
        states: Vec<String>,
        outputs: Vec<String>,
        rate_hz: Option<f64>,
        time_source: Option<&str>,
        max_gap_s: Option<f64>,
        params: Option<&Bound<'_, PyDict>>,
        min_coverage: Option<f64>,
        min_state_samples: Option<usize>,
    ) -> PyResult<Self> {
        if logs.is_empty() {
            return Err(raise(
                py,
                Fail::config_value("logs", "[]", "give at least one MCAP log"),
            ));
        }
        let p = hbn_params(py, params)?;
        let opts = log_options_with(
            py,
            rate_hz,
            time_source,
            max_gap_s,
            min_coverage,
            min_state_samples,
        )?;
        let signals = VectorSignals {
            inputs: parse_paths(py, LogOption::Input, &inputs)?,
            states: parse_paths(py, LogOption::State, &states)?,
            outputs: parse_paths(py, LogOption::Output, &outputs)?,
        };
        let sensors = vector_sensor_inputs(&p);
        let trained = detached(py, move || {
            Ok(hbn_pipeline::train_vector_from_logs(
                &logs,
                &signals,
                opts,
                p,
                &sensors,
                &mut |_| {},
            )?)
        })?;
        Ok(Self::wrap(trained.model))
    }

    /// Runs the filter over row-major `u` (`T x du`) and `y` (`T x dy`, flattened); returns a
    /// dict of per-sample arrays shaped `(T, d)`.
    #[pyo3(signature = (u, y, mode))]
    fn estimate<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray1<'_, f64>,
        y: PyReadonlyArray1<'_, f64>,
        mode: Option<&str>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mode = parse_mode(py, mode, self.inner.default_mode())?;
        let (u, y) = (slice(&u, "u")?.to_vec(), slice(&y, "y")?.to_vec());
        let est = detached(py, || Ok(self.inner.estimate(&u, &y, mode)?))?;
        vector_estimate_dict(py, est)
    }

    /// Smooths row-major `u` and `y` as `estimate` takes them (`VectorModel::smooth`); returns
    /// the dict of `estimate` with the smoothed `x`, `x_std` and `x_cov`.
    #[pyo3(signature = (u, y, mode))]
    fn smooth<'py>(
        &self,
        py: Python<'py>,
        u: PyReadonlyArray1<'_, f64>,
        y: PyReadonlyArray1<'_, f64>,
        mode: Option<&str>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mode = parse_mode(py, mode, self.inner.default_mode())?;
        let (u, y) = (slice(&u, "u")?.to_vec(), slice(&y, "y")?.to_vec());
        let est = detached(py, || Ok(self.inner.smooth(&u, &y, mode)?))?;
        vector_estimate_dict(py, est)
    }

    /// Reads the inputs and outputs from a log at the model's rate (the model's message paths
    /// unless given, one per signal in order), runs the filter and optionally writes the CSV
    /// and MCAP of `hbn estimate --csv --out`; returns `(t, dict of per-sample arrays)`.
    #[allow(clippy::too_many_arguments)]
    #[pyo3(signature = (path, mode, inputs, outputs, csv, mcap, time_source, max_gap_s))]
    fn estimate_log<'py>(
        &self,
        py: Python<'py>,
        path: PathBuf,
        mode: Option<&str>,
        inputs: Vec<String>,
        outputs: Vec<String>,
        csv: Option<PathBuf>,
        mcap: Option<PathBuf>,
        time_source: Option<&str>,
        max_gap_s: Option<f64>,
    ) -> PyResult<(Arr<'py>, Bound<'py, PyDict>)> {
        let mode = parse_mode(py, mode, self.inner.default_mode())?;
        let mut opts = LogOptions::default();
        if let Some((t, gap)) = self.inner.read_options() {
            if let Ok(ts) = hbn_pipeline::parse_time_source(t) {
                opts.time_source = ts;
            }
            opts.max_gap_s = gap;
        }
        if let Some(t) = time_source {
            opts.time_source = hbn_pipeline::parse_time_source(t).map_err(|e| raise(py, e))?;
        }
        if let Some(g) = max_gap_s {
            opts.max_gap_s = g;
        }
        let inputs = parse_paths(py, LogOption::Input, &inputs)?;
        let outputs = parse_paths(py, LogOption::Output, &outputs)?;
        let model = &self.inner;
        let run = detached(py, move || {
            let signals = hbn_pipeline::model_signals(model, &inputs, &outputs)?;
            let run =
                hbn_pipeline::estimate_vector_log(model, &path, &signals, mode, opts, &mut |_| {})?;
            // Both outputs are rendered before either is written, as `hbn estimate` does.
            let csv_text = csv.as_ref().map(|_| hbn_pipeline::vector_csv(&run, false));
            if let Some(mcap) = &mcap {
                run.write_mcap(mcap, model.signal_names())?;
            }
            if let (Some(csv), Some(text)) = (&csv, csv_text) {
                hbn_fs::write_atomic(csv, text.as_bytes())
                    .map_err(|e| Fail::new(Kind::Io(e.source.kind()), e.to_string()))?;
            }
            Ok(run)
        })?;
        let t = PyArray1::from_vec(py, run.log.aligned.t_s);
        Ok((t, vector_estimate_dict(py, run.estimate)?))
    }

    /// A streaming filter over this model (sharing it, not copying it).
    #[pyo3(signature = (mode))]
    fn filter(&self, py: Python<'_>, mode: Option<&str>) -> PyResult<VectorFilterCore> {
        let mode = parse_mode(py, mode, self.inner.default_mode())?;
        let inner = VectorFilter::new(self.inner.clone(), mode).map_err(|e| raise(py, e))?;
        Ok(VectorFilterCore { inner })
    }

    /// The filter's settings of a mode, as a dict (per-component arrays padded to the limits).
    #[pyo3(signature = (mode))]
    fn ekf_config<'py>(&self, py: Python<'py>, mode: Option<&str>) -> PyResult<Bound<'py, PyAny>> {
        let mode = parse_mode(py, mode, self.inner.default_mode())?;
        to_py(py, &self.inner.config(mode))
    }
    /// `(inputs, states, sensors)`.
    #[getter]
    fn dims(&self) -> (usize, usize, usize) {
        let d = self.inner.dims();
        (d.inputs, d.states, d.sensors)
    }
    /// Sample rate (Hz).
    #[getter]
    fn rate_hz(&self) -> f64 {
        self.inner.rate_hz()
    }
    /// The signals' names (message paths) as a dict: `inputs`, `states`, `outputs`.
    fn signals<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, self.inner.signal_names())
    }
    /// Training parameters as a dict by keyword argument.
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        params_dict(py, self.inner.params(), false)
    }
    /// Training summary as a dict (held-out scores, warnings, observability).
    fn summary<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_py(py, self.inner.summary())
    }
    /// The mode estimation uses without `mode=` (chosen on held-out data at training).
    fn default_mode(&self) -> &'static str {
        self.inner.default_mode().name()
    }
    /// The transition GP of state component `i`.
    fn transition(&self, py: Python<'_>, i: usize) -> PyResult<GaussianProcessCore> {
        let gp = self.inner.transition(i).ok_or_else(|| {
            let n = self.inner.dims().states;
            raise(
                py,
                Fail::config_value(
                    "i",
                    &i.to_string(),
                    format!("the model has {n} state components"),
                ),
            )
        })?;
        Ok(GaussianProcessCore::wrap(gp.clone()))
    }
    /// The GP of sensor `j`.
    fn sensor(&self, py: Python<'_>, j: usize) -> PyResult<GaussianProcessCore> {
        let gp = self.inner.sensor(j).ok_or_else(|| {
            let n = self.inner.dims().sensors;
            raise(
                py,
                Fail::config_value("j", &j.to_string(), format!("the model has {n} sensors")),
            )
        })?;
        Ok(GaussianProcessCore::wrap(gp.clone()))
    }
    /// The model as JSON (the format of `save`, shared with the CLI; GIL released).
    fn to_json(&self, py: Python<'_>) -> PyResult<String> {
        detached(py, || Ok(self.inner.to_json()?))
    }
    /// The bytes of the model file `save` writes (GIL released): what a pickled model holds.
    fn to_bytes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyBytes>> {
        let inner = &self.inner;
        let text = detached(py, move || Ok(inner.to_json()?))?;
        Ok(PyBytes::new(py, text.as_bytes()))
    }
    /// Writes the model atomically (the CLI's `hbn train --out` format).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        detached(py, || Ok(self.inner.save(&path)?))
    }
}

/// A scalar or a vector model, whichever the file's format tag names.
enum AnyModel {
    Scalar(Box<HysteresisModel>),
    Vector(Box<VectorModel>),
}

impl AnyModel {
    /// `scalar` is the scalar loader's result; a file tagged as a vector model is read by
    /// `vector` instead.
    fn pick(
        scalar: Result<HysteresisModel, ModelError>,
        vector: impl FnOnce() -> Result<VectorModel, ModelError>,
    ) -> Result<Self, ModelError> {
        match scalar {
            Ok(m) => Ok(Self::Scalar(Box::new(m))),
            Err(ModelError::ModelFile {
                problem: ModelFileProblem::WrongFormat { tag },
                ..
            }) if tag == VECTOR_MODEL_FORMAT => Ok(Self::Vector(Box::new(vector()?))),
            Err(e) => Err(e),
        }
    }

    fn into_py(self, py: Python<'_>) -> PyResult<Py<PyAny>> {
        Ok(match self {
            Self::Scalar(m) => Py::new(py, HysteresisModelCore::wrap(*m))?.into_any(),
            Self::Vector(m) => Py::new(py, VectorModelCore::wrap(*m))?.into_any(),
        })
    }
}

/// Loads a model file written by `save` or `hbn train`: a `HysteresisModelCore`, or a
/// `VectorModelCore` for a file of the format `hbn-vector-model`.
#[pyfunction]
fn load_model(py: Python<'_>, path: PathBuf) -> PyResult<Py<PyAny>> {
    let m = detached(py, move || {
        Ok(AnyModel::pick(HysteresisModel::load(&path), || {
            VectorModel::load(&path)
        })?)
    })?;
    m.into_py(py)
}

/// A model from the bytes of a model file (GIL released), scalar or vector by its format tag;
/// `origin` names them in errors.
#[pyfunction]
fn model_from_bytes(py: Python<'_>, data: Vec<u8>, origin: &str) -> PyResult<Py<PyAny>> {
    let origin = origin.to_owned();
    let m = detached(py, move || {
        let text = String::from_utf8(data).map_err(|_| {
            Fail::new(
                Kind::ModelFile,
                format!("{origin}: not an hbn model file (not UTF-8 text)"),
            )
        })?;
        Ok(AnyModel::pick(
            HysteresisModel::from_json(&text, &origin),
            || VectorModel::from_json(&text, &origin),
        )?)
    })?;
    m.into_py(py)
}

/// Native streaming filter of a vector model (`hbn_model::VectorFilter`). Use `hbn.Filter`
/// instead.
#[pyclass(name = "VectorFilterCore", module = "hbn._hbn")]
pub struct VectorFilterCore {
    inner: VectorFilter,
}

#[pymethods]
impl VectorFilterCore {
    /// One sample: the inputs `u` (`du` values) and measurements `y` (`dy` values; a NaN
    /// one is left out of the update, and flagged).
    fn step(
        &mut self,
        u: PyReadonlyArray1<'_, f64>,
        y: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<VectorFilterStep> {
        let out = self.inner.step(slice(&u, "u")?, slice(&y, "y")?);
        Ok(VectorFilterStep {
            dims: self.inner.dims(),
            out,
        })
    }
    /// Forgets the state; the next step initialises again.
    fn reset(&mut self) {
        self.inner.reset();
    }
    /// The estimation mode.
    #[getter]
    fn mode(&self) -> &'static str {
        self.inner.mode().name()
    }
    /// Samples since the last (re)initialisation.
    #[getter]
    fn steps(&self) -> u64 {
        self.inner.state().map_or(0, |s| s.steps)
    }
    /// `(inputs, states, sensors)`.
    #[getter]
    fn dims(&self) -> (usize, usize, usize) {
        let d = self.inner.dims();
        (d.inputs, d.states, d.sensors)
    }
}

/// The output of one step of a vector model's filter: per state component and per sensor,
/// tuples.
#[pyclass(name = "VectorFilterOutput", module = "hbn", frozen)]
pub struct VectorFilterStep {
    dims: Dims,
    out: VectorStepOutput,
}

#[pymethods]
impl VectorFilterStep {
    /// Estimate of each state component.
    #[getter]
    fn x<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        PyTuple::new(py, &self.out.x[..self.dims.states])
    }
    /// Standard deviation of each state component.
    #[getter]
    fn x_std<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        PyTuple::new(py, &self.out.x_std[..self.dims.states])
    }
    /// Covariance of the state, a tuple of `dx` rows.
    #[getter]
    fn x_cov<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let dx = self.dims.states;
        let rows = self.out.x_cov[..dx]
            .iter()
            .map(|r| PyTuple::new(py, &r[..dx]))
            .collect::<PyResult<Vec<_>>>()?;
        PyTuple::new(py, rows)
    }
    /// Predicted measurement of each sensor before the update.
    #[getter]
    fn y_pred<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        PyTuple::new(py, &self.out.y_pred[..self.dims.sensors])
    }
    /// Innovation of each sensor (0 where it was not updated).
    #[getter]
    fn innovation<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        PyTuple::new(py, &self.out.innovation[..self.dims.sensors])
    }
    /// Innovation variance of each sensor.
    #[getter]
    fn innovation_var<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        PyTuple::new(py, &self.out.innovation_var[..self.dims.sensors])
    }
    /// Normalised innovation squared of the whole update.
    #[getter]
    fn nis(&self) -> f64 {
        self.out.nis
    }
    /// Process noise variance of each transition.
    #[getter]
    fn q_x<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        PyTuple::new(py, &self.out.q_x[..self.dims.states])
    }
    /// Measurement noise variance of each sensor.
    #[getter]
    fn r<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        PyTuple::new(py, &self.out.r[..self.dims.sensors])
    }
    /// Guard flags (bits; see `flag_names()`).
    #[getter]
    fn flags(&self) -> u32 {
        self.out.flags.0
    }
    /// Names of the guard flags that fired.
    fn flag_names(&self) -> Vec<&'static str> {
        self.out.flags.names().collect()
    }
    fn __repr__(&self) -> String {
        let dx = self.dims.states;
        format!(
            "VectorFilterOutput(x={:?}, x_std={:?}, flags={:?})",
            &self.out.x[..dx],
            &self.out.x_std[..dx],
            self.flag_names()
        )
    }
}

// ---------------------------------------------------------------------------------------------
// Functions
// ---------------------------------------------------------------------------------------------

/// Native explorer (`hbn_model::explore::Explorer`). Use `hbn.Explorer` instead.
#[pyclass(name = "ExplorerCore", module = "hbn._hbn")]
pub struct ExplorerCore {
    inner: Explorer,
}

#[pymethods]
impl ExplorerCore {
    /// Checks the parameters; `params` are the training keywords of `HysteresisModel.fit`
    /// (`rate_hz` among them); `seed` seeds the explorer and the training.
    #[new]
    #[pyo3(signature = (u_min, u_max, max_step, seed, u_start, random_samples, alpha_start,
        alpha_end, alpha_ramp, refit_every, optimize_every, candidates, horizon, strategy, pool,
        lag, criterion, params))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        u_min: f64,
        u_max: f64,
        max_step: f64,
        seed: Option<u64>,
        u_start: Option<f64>,
        random_samples: Option<usize>,
        alpha_start: Option<f64>,
        alpha_end: Option<f64>,
        alpha_ramp: Option<usize>,
        refit_every: Option<usize>,
        optimize_every: Option<usize>,
        candidates: Option<usize>,
        horizon: Option<usize>,
        strategy: Option<&str>,
        pool: Option<usize>,
        lag: Option<usize>,
        criterion: Option<&str>,
        params: Option<&Bound<'_, PyDict>>,
    ) -> PyResult<Self> {
        let mut p = ExploreParams::new(u_min, u_max, max_step);
        p.model = hbn_params(py, params)?;
        if let Some(s) = seed {
            p.seed = s;
            p.model.seed = s;
        }
        p.u_start = u_start;
        p.random_samples = random_samples.unwrap_or(p.random_samples);
        p.alpha_start = alpha_start.unwrap_or(p.alpha_start);
        p.alpha_end = alpha_end.unwrap_or(p.alpha_end);
        p.alpha_ramp = alpha_ramp.unwrap_or(p.alpha_ramp);
        p.refit_every = refit_every.unwrap_or(p.refit_every);
        p.optimize_every = optimize_every.unwrap_or(p.optimize_every);
        p.candidates = candidates.unwrap_or(p.candidates);
        p.horizon = horizon.unwrap_or(p.horizon);
        p.pool = pool.unwrap_or(p.pool);
        p.lag = lag.unwrap_or(p.lag);
        if let Some(s) = strategy {
            p.strategy =
                Strategy::from_str(s).map_err(|e| raise(py, Fail::config("strategy", e)))?;
        }
        if let Some(c) = criterion {
            p.criterion =
                Criterion::from_str(c).map_err(|e| raise(py, Fail::config("criterion", e)))?;
        }
        let inner = Explorer::new(p).map_err(|e| raise(py, e))?;
        Ok(Self { inner })
    }
    /// The next input to apply.
    fn propose(&mut self, py: Python<'_>) -> PyResult<f64> {
        let inner = &mut self.inner;
        detached(py, move || Ok(inner.propose()))
    }
    /// Records one observed sample; refits when due (GIL released).
    fn observe(&mut self, py: Python<'_>, u: f64, x: f64, y: f64) -> PyResult<()> {
        let inner = &mut self.inner;
        detached(py, move || Ok(inner.observe(u, x, y)?))
    }
    /// Trains the HBN on every sample observed (GIL released).
    fn model(&self, py: Python<'_>) -> PyResult<HysteresisModelCore> {
        let inner = &self.inner;
        let model = detached(py, move || Ok(inner.model()?))?;
        Ok(HysteresisModelCore::wrap(model))
    }
    /// A schedule of `steps` inputs and the predicted states (GIL released).
    fn plan<'py>(&self, py: Python<'py>, steps: usize) -> PyResult<(Arr<'py>, Arr<'py>)> {
        let inner = &self.inner;
        let (u, x) = detached(py, move || Ok(inner.plan(steps)))?;
        Ok((PyArray1::from_vec(py, u), PyArray1::from_vec(py, x)))
    }
    /// Starts a new run (the robot was reset).
    fn start_run(&mut self) {
        self.inner.start_run();
    }
    /// `random` or `seeking`.
    #[getter]
    fn phase(&self) -> &'static str {
        match self.inner.phase() {
            Phase::Random => "random",
            Phase::Seeking { .. } => "seeking",
        }
    }
    /// The weight of uncertainty seeking now.
    #[getter]
    fn alpha(&self) -> f64 {
        self.inner.alpha()
    }
    /// Samples observed so far.
    #[getter]
    fn n_observed(&self) -> usize {
        self.inner.n_observed()
    }
    /// What went wrong and was recovered from.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.inner.warnings().to_vec()
    }
    /// The observed runs as `(u, x, y)` arrays.
    #[getter]
    fn runs<'py>(&self, py: Python<'py>) -> Vec<(Arr<'py>, Arr<'py>, Arr<'py>)> {
        self.inner
            .runs()
            .map(|(u, x, y)| {
                (
                    PyArray1::from_slice(py, u),
                    PyArray1::from_slice(py, x),
                    PyArray1::from_slice(py, y),
                )
            })
            .collect()
    }
    /// The explorer's parameters (bounds, schedule; not the training parameters).
    #[getter]
    fn settings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        explore_dict(py, self.inner.params())
    }
}

/// The explorer's settings by keyword (bounds included).
fn explore_dict<'py>(py: Python<'py>, p: &ExploreParams) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("u_min", p.u_min)?;
    d.set_item("u_max", p.u_max)?;
    d.set_item("max_step", p.max_step)?;
    d.set_item("u_start", p.u_start)?;
    d.set_item("random_samples", p.random_samples)?;
    d.set_item("alpha_start", p.alpha_start)?;
    d.set_item("alpha_end", p.alpha_end)?;
    d.set_item("alpha_ramp", p.alpha_ramp)?;
    d.set_item("refit_every", p.refit_every)?;
    d.set_item("optimize_every", p.optimize_every)?;
    d.set_item("candidates", p.candidates)?;
    d.set_item("pool", p.pool)?;
    d.set_item("horizon", p.horizon)?;
    d.set_item("lag", p.lag)?;
    d.set_item("strategy", p.strategy.name())?;
    d.set_item("criterion", p.criterion.name())?;
    d.set_item("seed", p.seed)?;
    Ok(d)
}

/// The explorer's defaults (`ExploreParams::new`), by keyword; the bounds have none.
#[pyfunction]
fn default_explore_params(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let d = explore_dict(py, &ExploreParams::new(0.0, 1.0, 1.0))?;
    for k in ["u_min", "u_max", "max_step"] {
        d.del_item(k)?;
    }
    Ok(d)
}

/// A simulator configuration; `None` settings take the simulator's defaults.
fn sim_config(
    py: Python<'_>,
    system: &str,
    seed: Option<u64>,
    noise_gain: Option<f64>,
    rate_hz: Option<f64>,
) -> PyResult<SimConfig> {
    let kind = SystemKind::from_str(system).map_err(|e| raise(py, e))?;
    let d = SimConfig::new(kind);
    Ok(SimConfig {
        system: kind,
        noise_gain: noise_gain.unwrap_or(d.noise_gain),
        rate_hz: rate_hz.unwrap_or(d.rate_hz),
        seed: seed.unwrap_or(d.seed),
    })
}

/// Native stepping simulator (`hbn_sim::Simulator`). Use `hbn.Simulator` instead.
#[pyclass(name = "SimulatorCore", module = "hbn._hbn")]
pub struct SimulatorCore {
    inner: Simulator,
}

#[pymethods]
impl SimulatorCore {
    /// The system in its relaxed state; `None` settings take the simulator's defaults.
    #[new]
    #[pyo3(signature = (system, seed, noise_gain, rate_hz))]
    fn new(
        py: Python<'_>,
        system: &str,
        seed: Option<u64>,
        noise_gain: Option<f64>,
        rate_hz: Option<f64>,
    ) -> PyResult<Self> {
        let cfg = sim_config(py, system, seed, noise_gain, rate_hz)?;
        let inner = Simulator::new(&cfg).map_err(|e| raise(py, e))?;
        Ok(Self { inner })
    }
    /// Applies `u` for one sample: `(x, y)`.
    fn step(&mut self, py: Python<'_>, u: f64) -> PyResult<(f64, f64)> {
        self.inner.step(u).map_err(|e| raise(py, e))
    }
    /// Samples simulated so far.
    #[getter]
    fn steps(&self) -> usize {
        self.inner.steps()
    }
}

/// Simulates a hysteretic system under a random bounded-increment input: `(u, x, y)`.
/// `None` settings take the simulator's defaults.
#[pyfunction]
#[pyo3(signature = (system, steps, seed, noise_gain, rate_hz))]
fn simulate<'py>(
    py: Python<'py>,
    system: &str,
    steps: usize,
    seed: Option<u64>,
    noise_gain: Option<f64>,
    rate_hz: Option<f64>,
) -> PyResult<(Arr<'py>, Arr<'py>, Arr<'py>)> {
    let cfg = sim_config(py, system, seed, noise_gain, rate_hz)?;
    let t = detached(py, move || Ok(hbn_sim::simulate_random(&cfg, steps)?))?;
    Ok((
        PyArray1::from_vec(py, t.u),
        PyArray1::from_vec(py, t.x),
        PyArray1::from_vec(py, t.y),
    ))
}

/// Simulates a multi-signal system (`hbn_sim::MultiKind`: several inputs, a vector state,
/// several sensors) under random inputs: `(u, x, y, (du, dx, dy))`, each signal row-major
/// `(T, d)` flattened. `None` settings take the simulator's defaults.
#[pyfunction]
#[pyo3(signature = (system, steps, seed, noise_gain, rate_hz))]
#[allow(clippy::type_complexity)]
fn simulate_multi<'py>(
    py: Python<'py>,
    system: &str,
    steps: usize,
    seed: Option<u64>,
    noise_gain: Option<f64>,
    rate_hz: Option<f64>,
) -> PyResult<(Arr<'py>, Arr<'py>, Arr<'py>, (usize, usize, usize))> {
    let kind = MultiKind::from_str(system).map_err(|e| raise(py, e))?;
    let cfg = multi_config(kind, seed, noise_gain, rate_hz);
    let t = detached(py, move || Ok(hbn_sim::simulate_multi_random(&cfg, steps)?))?;
    let dims = (kind.inputs(), kind.states(), kind.sensors());
    Ok((
        PyArray1::from_vec(py, row_major(&t.u)),
        PyArray1::from_vec(py, row_major(&t.x)),
        PyArray1::from_vec(py, row_major(&t.y)),
        dims,
    ))
}

/// The configuration of `kind` with the given settings (`None`: the simulator's defaults).
fn multi_config(
    kind: MultiKind,
    seed: Option<u64>,
    noise_gain: Option<f64>,
    rate_hz: Option<f64>,
) -> MultiConfig {
    let d = MultiConfig::new(kind);
    MultiConfig {
        noise_gain: noise_gain.unwrap_or(d.noise_gain),
        rate_hz: rate_hz.unwrap_or(d.rate_hz),
        seed: seed.unwrap_or(d.seed),
        ..d
    }
}

/// Row-major `(T, d)` flattened from component-major signals (a shorter one reads as NaN).
fn row_major(signals: &[Vec<f64>]) -> Vec<f64> {
    let n = signals.first().map_or(0, Vec::len);
    (0..n)
        .flat_map(|k| {
            signals
                .iter()
                .map(move |s| s.get(k).copied().unwrap_or(f64::NAN))
        })
        .collect()
}

/// Names of the multi-signal simulators.
#[pyfunction]
fn multi_systems() -> Vec<&'static str> {
    MultiKind::ALL.iter().map(|k| k.name()).collect()
}

/// `(inputs, state components, sensors)` of a multi-signal simulator.
#[pyfunction]
fn multi_dims(py: Python<'_>, system: &str) -> PyResult<(usize, usize, usize)> {
    let kind = MultiKind::from_str(system).map_err(|e| raise(py, e))?;
    Ok((kind.inputs(), kind.states(), kind.sensors()))
}

/// The floor under estimation on a simulated trajectory: the posterior `(mean, std)` of each
/// `x[k]` given `u` and `y` up to `k + lookahead`, the true states around it and the simulator
/// itself ([`hbn_sim::oracle_estimate`] for lookahead 0, the causal floor;
/// [`hbn_sim::oracle_smooth_estimate`] otherwise, `None` for the whole log: the floor under
/// smoothing). A system whose disturbance propagates has none (`ConfigError` on `system`).
#[pyfunction]
#[pyo3(signature = (system, u, x, y, noise_gain, rate_hz, lookahead))]
#[allow(clippy::too_many_arguments)]
fn oracle_estimate<'py>(
    py: Python<'py>,
    system: &str,
    u: PyReadonlyArray1<'_, f64>,
    x: PyReadonlyArray1<'_, f64>,
    y: PyReadonlyArray1<'_, f64>,
    noise_gain: Option<f64>,
    rate_hz: Option<f64>,
    lookahead: Option<usize>,
) -> PyResult<(Arr<'py>, Arr<'py>)> {
    let cfg = sim_config(py, system, None, noise_gain, rate_hz)?;
    let traj = hbn_sim::Trajectory {
        u: slice(&u, "u")?.to_vec(),
        x: slice(&x, "x")?.to_vec(),
        y: slice(&y, "y")?.to_vec(),
        rate_hz: cfg.rate_hz,
    };
    let lookahead = lookahead.unwrap_or(usize::MAX);
    let est = detached(py, move || {
        match hbn_sim::oracle_smooth_estimate(&cfg, &traj, lookahead) {
            Ok(est) => Ok(est),
            // A system with no exact floor: the `system` argument is what to change.
            Err(e @ hbn_sim::SimError::NoExactOracle { .. }) => Err(Fail::config("system", &e)),
            Err(e) => Err(e.into()),
        }
    })?;
    Ok((
        PyArray1::from_vec(py, est.mean),
        PyArray1::from_vec(py, est.std),
    ))
}

/// The floor under causal estimation on a multi-signal simulator: the posterior `(mean, std)`
/// of the state given `u` and `y` (row-major `(T, du)` and `(T, dy)`, flattened) and the
/// simulator's own model, by a particle filter of `particles` particles
/// ([`hbn_sim::multi_posterior_estimate`]); both row-major `(T, dx)` flattened, and `dx`.
#[pyfunction]
#[pyo3(signature = (system, u, y, noise_gain, rate_hz, particles, seed))]
#[allow(clippy::too_many_arguments)]
fn multi_oracle_estimate<'py>(
    py: Python<'py>,
    system: &str,
    u: PyReadonlyArray1<'_, f64>,
    y: PyReadonlyArray1<'_, f64>,
    noise_gain: Option<f64>,
    rate_hz: Option<f64>,
    particles: usize,
    seed: u64,
) -> PyResult<(Arr<'py>, Arr<'py>, usize)> {
    let kind = MultiKind::from_str(system).map_err(|e| raise(py, e))?;
    let cfg = multi_config(kind, None, noise_gain, rate_hz);
    // Component-major signals from the row-major arrays (the wrapper checked their shapes).
    let columns = |flat: &[f64], width: usize| -> Vec<Vec<f64>> {
        (0..width)
            .map(|c| flat.iter().skip(c).step_by(width).copied().collect())
            .collect()
    };
    let (u, y) = (
        columns(slice(&u, "u")?, kind.inputs()),
        columns(slice(&y, "y")?, kind.sensors()),
    );
    let post = detached(py, move || {
        Ok(hbn_sim::multi_posterior_estimate(
            &cfg, &u, &y, particles, seed,
        )?)
    })?;
    Ok((
        PyArray1::from_vec(py, row_major(&post.mean)),
        PyArray1::from_vec(py, row_major(&post.std)),
        kind.states(),
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

/// Reads signals from an MCAP log and resamples them on one grid (`hbn_pipeline::load_log`,
/// the pipeline of the CLI): `(t, columns, rate)`.
#[pyfunction]
#[pyo3(signature = (path, signals, rate_hz, time_source, max_gap_s))]
#[allow(clippy::type_complexity)]
fn read_mcap<'py>(
    py: Python<'py>,
    path: PathBuf,
    signals: Vec<String>,
    rate_hz: Option<f64>,
    time_source: Option<&str>,
    max_gap_s: Option<f64>,
) -> PyResult<(Arr<'py>, Vec<Arr<'py>>, f64)> {
    let paths = signals
        .iter()
        .map(|s| parse_path(py, LogOption::Input, s))
        .collect::<PyResult<Vec<_>>>()?;
    if paths.is_empty() {
        return Err(raise(
            py,
            Fail::config("signals", "give at least one signal"),
        ));
    }
    let opts = log_options(py, rate_hz, time_source, max_gap_s)?;
    let log = detached(py, move || {
        let opts = opts.check()?;
        Ok(hbn_pipeline::load_log(
            &path,
            &paths,
            opts.rate_hz,
            &opts,
            &mut |_| {},
        )?)
    })?;
    let rate = log.rate_hz();
    let cols = log
        .aligned
        .columns
        .into_iter()
        .map(|c| PyArray1::from_vec(py, c))
        .collect();
    Ok((PyArray1::from_vec(py, log.aligned.t_s), cols, rate))
}

/// One channel: `(topic, message_count, message_encoding, schema_name)`.
type TopicRow = (String, u64, String, Option<String>);

/// Topics of an MCAP log: `[(topic, message_count, message_encoding, schema_name)]`.
#[pyfunction]
fn list_topics(py: Python<'_>, path: PathBuf) -> PyResult<Vec<TopicRow>> {
    let topics = detached(py, move || Ok(hbn_io::list_topics(&path)?))?;
    Ok(topics
        .into_iter()
        .map(|t| (t.topic, t.message_count, t.message_encoding, t.schema_name))
        .collect())
}

/// The training parameters' defaults, by keyword argument (`hbn_model::HbnParams::default`,
/// read back by `HbnParams::get`, the inverse of the `HbnParams::set` that applies keywords),
/// plus `blr` and `signals`.
#[pyfunction]
fn default_params(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    params_dict(py, &HbnParams::default(), true)
}

/// The keywords of the training parameters, in the order they are applied.
#[pyfunction]
fn training_keywords() -> Vec<&'static str> {
    keyword_params().map(Param::name).collect()
}

/// `HbnParams::default()` serialised by serde (the model file's `params`): a second,
/// independent reading of the defaults, which the tests compare with `default_params()`.
#[pyfunction]
fn default_params_json(py: Python<'_>) -> PyResult<String> {
    serde_json::to_string(&HbnParams::default())
        .map_err(|e| raise(py, Fail::new(Kind::Internal, e.to_string())))
}

/// The log reading defaults (`hbn_pipeline::LogOptions::default`) by keyword: `time_source`,
/// `max_gap_s`, `rate_hz` (None: the log's native rate), the default signal paths `input`,
/// `state`, `output`, and the default estimation `mode`.
#[pyfunction]
fn default_log_options(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let o = LogOptions::default();
    let d = PyDict::new(py);
    d.set_item(LogOption::TimeSource.name(), o.time_source.name())?;
    d.set_item(LogOption::MaxGap.name(), o.max_gap_s)?;
    d.set_item(LogOption::Rate.name(), o.rate_hz)?;
    d.set_item(LogOption::MinCoverage.name(), o.min_coverage)?;
    d.set_item(LogOption::MinStateSamples.name(), o.min_state_samples)?;
    d.set_item(LogOption::Input.name(), hbn_pipeline::DEFAULT_INPUT)?;
    d.set_item(LogOption::State.name(), hbn_pipeline::DEFAULT_STATE)?;
    d.set_item(LogOption::Output.name(), hbn_pipeline::DEFAULT_OUTPUT)?;
    d.set_item(LogOption::Mode.name(), Mode::default().name())?;
    Ok(d)
}

/// The kernel of `hbn.GaussianProcess` when none is named.
const GP_DEFAULT_KERNEL: &str = "se-ard";

/// The GP fitting defaults (`hbn_gp::GpParams::new`), by keyword argument.
#[pyfunction]
fn default_gp_params(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let p = GpParams::new(hbn_core::KernelSpec::se_ard(1));
    let d = PyDict::new(py);
    d.set_item("kernel", GP_DEFAULT_KERNEL)?;
    d.set_item("optimize", p.optimize)?;
    d.set_item("normalize", p.normalize)?;
    d.set_item("n_starts", p.n_starts)?;
    d.set_item("max_iters", p.max_iters)?;
    d.set_item("max_points", p.max_points)?;
    d.set_item("seed", p.seed)?;
    d.set_item("mean", p.mean.name())?;
    d.set_item("optimize_inducing", SparseParams::new(1).optimize_inducing)?;
    Ok(d)
}

/// The simulators' defaults (`hbn_sim::SimConfig::new`), by keyword argument: `seed`,
/// `noise_gain`, `rate_hz`.
#[pyfunction]
fn default_sim_params(py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
    let c = SimConfig::new(SystemKind::ALL[0]);
    let d = PyDict::new(py);
    d.set_item("seed", c.seed)?;
    d.set_item("noise_gain", c.noise_gain)?;
    d.set_item("rate_hz", c.rate_hz)?;
    Ok(d)
}

/// Kernel names accepted by `kernel=`.
#[pyfunction]
fn kernel_names() -> &'static str {
    KernelChoice::NAMES
}

/// Estimation mode names.
#[pyfunction]
fn mode_names() -> Vec<&'static str> {
    Mode::ALL.iter().map(|m| m.name()).collect()
}

/// Names of the estimator's guard flags, in bit order (bit `i` is element `i`).
#[pyfunction]
fn flag_names() -> Vec<&'static str> {
    Flags::NAMES.to_vec()
}

/// The native extension of the `hbn` package.
#[pymodule]
fn _hbn(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<GaussianProcessCore>()?;
    m.add_class::<HysteresisModelCore>()?;
    m.add_class::<FilterCore>()?;
    m.add_class::<FilterStep>()?;
    m.add_class::<VectorModelCore>()?;
    m.add_class::<VectorFilterCore>()?;
    m.add_class::<VectorFilterStep>()?;
    m.add_class::<ExplorerCore>()?;
    m.add_class::<SimulatorCore>()?;
    m.add_function(wrap_pyfunction!(default_explore_params, m)?)?;
    m.add_function(wrap_pyfunction!(load_model, m)?)?;
    m.add_function(wrap_pyfunction!(model_from_bytes, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(simulate_multi, m)?)?;
    m.add_function(wrap_pyfunction!(multi_systems, m)?)?;
    m.add_function(wrap_pyfunction!(oracle_estimate, m)?)?;
    m.add_function(wrap_pyfunction!(multi_oracle_estimate, m)?)?;
    m.add_function(wrap_pyfunction!(multi_dims, m)?)?;
    m.add_function(wrap_pyfunction!(systems, m)?)?;
    m.add_function(wrap_pyfunction!(score, m)?)?;
    m.add_function(wrap_pyfunction!(read_mcap, m)?)?;
    m.add_function(wrap_pyfunction!(list_topics, m)?)?;
    m.add_function(wrap_pyfunction!(default_params, m)?)?;
    m.add_function(wrap_pyfunction!(default_log_options, m)?)?;
    m.add_function(wrap_pyfunction!(default_gp_params, m)?)?;
    m.add_function(wrap_pyfunction!(default_sim_params, m)?)?;
    m.add_function(wrap_pyfunction!(training_keywords, m)?)?;
    m.add_function(wrap_pyfunction!(default_params_json, m)?)?;
    m.add_function(wrap_pyfunction!(kernel_names, m)?)?;
    m.add_function(wrap_pyfunction!(mode_names, m)?)?;
    m.add_function(wrap_pyfunction!(flag_names, m)?)?;
    let c = classes(py)?;
    m.add("HbnError", c.base.bind(py))?;
    m.add("HbnIOError", c.io.bind(py))?;
    m.add("HbnFileNotFoundError", c.not_found.bind(py))?;
    m.add("DataError", c.data.bind(py))?;
    m.add("ModelFileError", c.model_file.bind(py))?;
    m.add("ConfigError", c.config.bind(py))?;
    m.add("TrainingError", c.training.bind(py))?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("MODEL_FORMAT_VERSION", hbn_model::MODEL_FORMAT_VERSION)?;
    m.add("DEFAULT_INDUCING", hbn_model::DEFAULT_INDUCING)?;
    Ok(())
}
