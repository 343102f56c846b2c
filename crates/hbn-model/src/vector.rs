//! The HBN with several inputs, a vector state and several sensors: training, estimation and
//! the model file. The step is [`hbn_core::vector`]'s; this module learns what it reads.
//!
//! - One transition GP per state component on `[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}, memory]`
//!   (every component, every input, the memory operators of each input), one sensor GP per
//!   sensor on `[x_{k-1}, y^j_{k-1}, x_k]` or on the state only `[x_{k-1}, x_k]`.
//! - Held out: the last quarter of every trajectory. The GPs are fitted on the first three
//!   quarters; the filter runs over the held-out quarters and is scored by the NLPD of the
//!   state summed over its components. On that score each sensor's inputs are chosen, one
//!   sensor at a time (the thesis' inputs first, then the state only where it scores lower),
//!   then the mode (EKF or UKF), the scale of the process noise, and each component's
//!   standard-deviation scale (so that its held-out NEES is one). The GPs are then refitted
//!   on every sample with the hyperparameters found.
//! - ARD length scales let each GP ignore the inputs that do not matter; a kernel whose
//!   features mix inputs (Mahalanobis, warping) takes at most 8 inputs.

use std::path::Path;
use std::sync::OnceLock;
use std::time::Instant;

use hbn_core::vector::{
    AugMatrix, Dims, MAX_AUGMENTED, MAX_SENSORS, MAX_STATES, VectorConfig, VectorEkf,
    VectorInitPrior, VectorPrediction, VectorState, VectorView, vector_state_information,
};
use hbn_core::{Flags, GpView, Mode, PlayState, Plays};
use hbn_gp::GaussianProcess;
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::error::{DataError, ModelError, ModelFileProblem, Signal};
use crate::model::{GpRole, OUTLIER_GATE, SignalStats};
use crate::params::{
    CheckedHbnParams, ConfigError, HbnParams, KernelChoice, Param, Problem, SensorInputs,
};
use crate::smooth::StateFrame;

/// The model file's tag.
pub const VECTOR_MODEL_FORMAT: &str = "hbn-vector-model";
/// The model file's version.
pub const VECTOR_MODEL_FORMAT_VERSION: u32 = 1;
/// Training samples the first-measurement prior averages over.
const INIT_NEIGHBOURS: usize = 20;
/// Window (samples) of the observability diagnostic.
const OBSERVABILITY_WINDOW: usize = 20;
/// A component's information below this fraction of the best-seen component's (both in
/// units of the components' spans) counts as unobservable in a window.
const UNOBSERVABLE_RATIO: f64 = 1e-6;
/// Process-noise scales tried on the held-out quarters.
const Q_SCALES: [f64; 3] = [0.25, 1.0, 4.0];

/// One trajectory of a vector system: row-major `(T, d)` arrays (sample `k` of input `a` is
/// `u[k * du + a]`).
#[derive(Clone, Copy, Debug)]
pub struct VectorSequence<'a> {
    /// Inputs, `T x du`.
    pub u: &'a [f64],
    /// States, `T x dx`.
    pub x: &'a [f64],
    /// Sensor outputs, `T x dy`.
    pub y: &'a [f64],
    /// Sizes.
    pub dims: Dims,
    /// Where each state component was measured, `T x dx` row-major as `x`; `None` when every
    /// component was measured at every sample. Elsewhere `x` holds a stand-in (interpolated
    /// between the measurements, or a path drawn from the smoothed states): the GPs train on
    /// it, but held-out scores compare the filter with measured values only.
    pub observed: Option<&'a [bool]>,
}

impl<'a> VectorSequence<'a> {
    /// A trajectory of `dims`; checked by [`VectorSequence::validate`] when training.
    pub fn new(u: &'a [f64], x: &'a [f64], y: &'a [f64], dims: Dims) -> Self {
        Self {
            u,
            x,
            y,
            dims,
            observed: None,
        }
    }

    /// The same trajectory with component `i` of the state measured at sample `k` only where
    /// `observed[k * dx + i]` is true ([`VectorSequence::observed`]).
    pub fn with_observed(self, observed: &'a [bool]) -> Self {
        Self {
            observed: Some(observed),
            ..self
        }
    }

    /// Whether component `i` of `x_k` was measured.
    pub fn is_observed(&self, k: usize, i: usize) -> bool {
        self.observed
            .is_none_or(|o| o.get(k * self.dims.states + i).copied().unwrap_or(false))
    }

    /// Samples.
    pub fn len(&self) -> usize {
        self.u.len() / self.dims.inputs.max(1)
    }

    /// Whether it has no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Checks shapes (whole rows, equal lengths, at least [`crate::MIN_SAMPLES`]) and values.
    pub fn validate(&self, index: usize) -> Result<(), DataError> {
        let d = self.dims;
        let t = self.len();
        if !self.u.len().is_multiple_of(d.inputs)
            || self.x.len() != t * d.states
            || self.y.len() != t * d.sensors
        {
            return Err(DataError::LengthMismatch {
                trajectory: index,
                u: self.u.len() / d.inputs.max(1),
                x: self.x.len() / d.states.max(1),
                y: self.y.len() / d.sensors.max(1),
            });
        }
        if let Some(o) = self.observed
            && o.len() != self.x.len()
        {
            return Err(DataError::ObservedLength {
                trajectory: index,
                observed: o.len(),
                samples: self.x.len(),
            });
        }
        if t < crate::MIN_SAMPLES {
            return Err(DataError::TooShort {
                trajectory: index,
                len: t,
                min: crate::MIN_SAMPLES,
            });
        }
        for (signal, values) in [
            (Signal::Input, self.u),
            (Signal::State, self.x),
            (Signal::Output, self.y),
        ] {
            if let Some((i, v)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(DataError::NonFinite {
                    trajectory: index,
                    signal,
                    index: i,
                    value: *v,
                });
            }
        }
        Ok(())
    }

    /// Samples `from..to` of every signal.
    fn slice(&self, from: usize, to: usize) -> VectorSequence<'a> {
        let d = self.dims;
        VectorSequence {
            u: &self.u[from * d.inputs..to * d.inputs],
            x: &self.x[from * d.states..to * d.states],
            y: &self.y[from * d.sensors..to * d.sensors],
            dims: d,
            observed: self
                .observed
                .map(|o| o.get(from * d.states..to * d.states).unwrap_or(&[])),
        }
    }
}

/// A vector model's estimate of one run: row-major `(T, d)` arrays.
#[derive(Clone, Debug, PartialEq)]
pub struct VectorEstimate {
    /// Sizes.
    pub dims: Dims,
    /// Mode run.
    pub mode: Mode,
    /// `x_k`, `T x dx`.
    pub x: Vec<f64>,
    /// Standard deviation of each component, `T x dx`.
    pub x_std: Vec<f64>,
    /// Covariance of `x_k`, `T x dx x dx`.
    pub x_cov: Vec<f64>,
    /// Predicted measurement before the update, `T x dy`.
    pub y_pred: Vec<f64>,
    /// Innovation of each sensor (0 where it was not updated), `T x dy`.
    pub innovation: Vec<f64>,
    /// Normalised innovation squared of each step.
    pub nis: Vec<f64>,
    /// Guard flags of each step ([`hbn_core::Flags`]).
    pub flags: Vec<u32>,
    /// Per state component, the fraction of windows of 20 steps in which
    /// the measurements said (next to) nothing about it (module docs of
    /// [`hbn_core::vector::vector_state_information`]).
    pub unobservable: Vec<f64>,
}

/// One step of a recorded filter run: the filtered augmented state after it and the
/// prediction it started from (`None` at the first sample and where the filter re-started).
#[derive(Clone, Copy, Debug)]
pub(crate) struct RecordedStep {
    pub(crate) z: [f64; MAX_AUGMENTED],
    pub(crate) p: AugMatrix,
    pub(crate) link: Option<VectorPrediction>,
}

/// A recorded filter run ([`VectorModel::run`]) and the span of each augmented component.
#[derive(Clone, Debug)]
pub(crate) struct Recorded {
    pub(crate) spans: [f64; MAX_AUGMENTED],
    pub(crate) steps: Vec<RecordedStep>,
}

impl VectorEstimate {
    /// Samples.
    pub fn len(&self) -> usize {
        self.nis.len()
    }

    /// Whether it has no samples.
    pub fn is_empty(&self) -> bool {
        self.nis.is_empty()
    }

    /// Counts of each guard flag over the run, by name.
    pub fn flag_counts(&self) -> Vec<(&'static str, usize)> {
        crate::estimate::count_flags(&self.flags)
    }

    /// Component `i` of the state over time.
    pub fn component(&self, i: usize) -> Vec<f64> {
        let dx = self.dims.states;
        self.x.iter().skip(i).step_by(dx).copied().collect()
    }

    /// Standard deviation of component `i` over time.
    pub fn component_std(&self, i: usize) -> Vec<f64> {
        let dx = self.dims.states;
        self.x_std.iter().skip(i).step_by(dx).copied().collect()
    }
}

/// Held-out scores of one configuration (lower is better).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VectorValidationRow {
    /// What was tried (e.g. `sensor 1: state only`, `mode ukf`).
    pub what: String,
    /// Held-out NLPD of the state, summed over components (per sample).
    pub nlpd: f64,
    /// Held-out nRMSE of each component (RMSE over its training range).
    pub nrmse: Vec<f64>,
    /// Whether it was kept.
    pub chosen: bool,
}

/// What training found and measured.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct VectorSummary {
    /// Trajectories trained on.
    pub trajectories: usize,
    /// Samples trained on.
    pub samples: usize,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// Every configuration scored on the held-out quarters, in order.
    pub validation: Vec<VectorValidationRow>,
    /// Warnings for the user.
    pub warnings: Vec<String>,
    /// Per component, the fraction of the first training trajectory's windows in which it
    /// was unobservable.
    pub unobservable: Vec<f64>,
    /// How much of the state was measured and what expectation-maximisation did, when the
    /// state was measured only sometimes ([`VectorModel::fit_latent`]).
    #[serde(default)]
    pub latent: Option<crate::latent::LatentReport>,
    /// The candidates trained side by side (each inducing setting with each lag set), in
    /// order (empty when only one was: [`VectorModel::fit_with_sensors`]).
    #[serde(default, alias = "lags")]
    pub candidates: Vec<VectorCandidateRow>,
    /// Each GP's kernel chosen by evidence among the kernels listed (the set kernel and
    /// [`crate::params::Selection::kernels`]): one row per GP and kernel of the fit that
    /// chose them (the first held-out fold's, or every trajectory's without folds), in order;
    /// empty when one kernel was given.
    #[serde(default)]
    pub kernel_evidence: Vec<VectorKernelRow>,
}

/// One GP's evidence under one kernel, in a vector model's kernel choice.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VectorKernelRow {
    /// Which GP: `transition i`, or `sensor j` with `own output` or `state only`.
    pub gp: String,
    /// The kernel.
    pub kernel: KernelChoice,
    /// Log marginal likelihood of the GP with this kernel (`None`: it could not be fitted).
    pub lml: Option<f64>,
    /// Whether this kernel was chosen for the GP.
    pub chosen: bool,
}

/// One candidate of a vector model's selection: its lag set, its inducing setting and its
/// held-out scores.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VectorCandidateRow {
    /// The lags' time constants (s); empty: none.
    pub lags: Vec<f64>,
    /// Inducing points per GP (sparse GPs on every sample), or `None`: exact GPs on at most
    /// [`HbnParams::max_points`] samples.
    #[serde(default)]
    pub n_inducing: Option<usize>,
    /// Held-out NLPD of the state, summed over components, of the candidate's final choice
    /// (`None` when it failed to train or has no held-out score).
    pub nlpd: Option<f64>,
    /// Held-out nRMSE of each component.
    pub nrmse: Vec<f64>,
    /// Wall-clock seconds of its training.
    pub seconds: f64,
    /// Why it failed to train.
    pub error: Option<String>,
    /// Whether it became the model.
    pub chosen: bool,
}

/// A trained vector HBN (one GP per state component and per sensor).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VectorModel {
    params: HbnParams,
    dims: Dims,
    /// One per state component.
    transitions: Vec<GaussianProcess>,
    /// One per sensor.
    sensors: Vec<GaussianProcess>,
    /// Whether sensor `j` reads its own previous output.
    sensor_reads_output: Vec<bool>,
    u_stats: Vec<SignalStats>,
    x_stats: Vec<SignalStats>,
    y_stats: Vec<SignalStats>,
    /// First-measurement prior: rows `[y (dy), x (dx)]`.
    init_rows: Vec<f64>,
    mode: Mode,
    q_scale: f64,
    std_scale: Vec<f64>,
    play_radii: Vec<f64>,
    /// Names of the signals (message paths), inputs then states then outputs.
    signal_names: SignalNames,
    /// How the training logs were read: time source and largest gap (s), so that estimation
    /// reads its logs the same way.
    #[serde(default)]
    read_options: Option<(String, f64)>,
    summary: VectorSummary,
}

/// The signals a vector model was trained on (message paths, or names given by the caller).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SignalNames {
    /// One per input.
    pub inputs: Vec<String>,
    /// One per state component.
    pub states: Vec<String>,
    /// One per sensor.
    pub outputs: Vec<String>,
}

#[derive(Serialize, Deserialize)]
struct VectorModelFile {
    format: String,
    version: u32,
    model: VectorModel,
}

/// The GPs fitted on one set of trajectories.
#[derive(Clone)]
struct Fitted {
    transitions: Vec<GaussianProcess>,
    /// Per sensor: with its own previous output, state only.
    sensors: Vec<SensorPair>,
    /// The kernel choice by evidence, where this fit made it.
    kernels: Vec<VectorKernelRow>,
}

/// A lag candidate's model (or why it failed) and the seconds its training took.
type Trained = (Result<VectorModel, ModelError>, f64);

/// The sensor GPs of one fit, and their rows of the kernel choice.
type SensorFits = (Vec<SensorPair>, Vec<VectorKernelRow>);

/// Per sensor: its GP with its own previous output among its inputs, and its GP of the state
/// only (`None`: not fitted, where the sensor's inputs were given).
type SensorPair = [Option<GaussianProcess>; 2];

/// Sensor GPs fitted once and shared by the lag candidates of
/// [`VectorModel::fit_with_sensors`]. A sensor GP's rows (`x_{k-1}`, `x_k`, `y_{k-1}`), settings
/// and seed do not depend on the transition's lags, so every candidate would fit the same ones:
/// the first candidate to need a stage's sensor GPs fits them, the others wait for them and
/// take a copy. Stages: fold `f` for `f < folds`, then the fit on every trajectory (no folds),
/// then the refit on every trajectory.
pub(crate) struct SharedSensors {
    folds: usize,
    cells: Vec<OnceLock<Option<SensorFits>>>,
}

/// Which fit of [`VectorModel::fit_one`] a set of sensor GPs belongs to.
#[derive(Clone, Copy)]
enum Stage {
    /// Fold `f`'s training part.
    Fold(usize),
    /// Every trajectory, hyperparameters optimised (no held-out folds).
    All,
    /// Every trajectory with the first fold's hyperparameters.
    Refit,
}

impl SharedSensors {
    fn new(folds: usize) -> Self {
        Self {
            folds,
            cells: (0..folds + 2).map(|_| OnceLock::new()).collect(),
        }
    }

    fn cell(&self, stage: Stage) -> Option<&OnceLock<Option<SensorFits>>> {
        self.cells.get(match stage {
            Stage::Fold(f) if f < self.folds => f,
            Stage::Fold(_) => return None,
            Stage::All => self.folds,
            Stage::Refit => self.folds + 1,
        })
    }
}

impl Fitted {
    /// Sensor `j`'s GP with its own previous output among its inputs (`reads`) or without.
    fn sensor(&self, j: usize, reads: bool) -> Result<&GaussianProcess, ModelError> {
        self.sensors
            .get(j)
            .and_then(|pair| pair[usize::from(!reads)].as_ref())
            .ok_or_else(unfitted)
    }
}

impl VectorModel {
    /// Trains on `trajectories` with `params` (their kernels, memory radii, subset sizes,
    /// optimiser settings and seed; the sizes come from the trajectories).
    pub fn fit(
        trajectories: &[VectorSequence<'_>],
        params: &HbnParams,
    ) -> Result<Self, ModelError> {
        let checked = params.clone().check()?;
        Self::fit_checked(trajectories, &checked, SignalNames::default())
    }

    /// [`VectorModel::fit`] with checked parameters and the signals' names.
    pub fn fit_checked(
        trajectories: &[VectorSequence<'_>],
        params: &CheckedHbnParams,
        names: SignalNames,
    ) -> Result<Self, ModelError> {
        Self::fit_with_sensors(trajectories, params, names, &[])
    }

    /// [`VectorModel::fit_checked`] with each sensor's inputs given: none (chosen on held-out
    /// data, one sensor at a time), one for every sensor, or one per sensor.
    ///
    /// With held-out data (`params.validation > 0`) it trains one candidate per inducing
    /// setting (the primary [`HbnParams::n_inducing`], then the selection's,
    /// [`crate::params::Selection::inducing`]) and lag set (the primary [`HbnParams::lags`],
    /// then the selection's, [`crate::VECTOR_DEFAULT_LAGS`] by default), side by side, and
    /// keeps the one with the lowest held-out NLPD among those at least as accurate held out
    /// (mean nRMSE over components) as the primary, the rule of the scalar model's selection;
    /// [`VectorSummary::candidates`] has the table. A candidate that fails to train is
    /// reported there; training fails only when the primary fails.
    pub fn fit_with_sensors(
        trajectories: &[VectorSequence<'_>],
        params: &CheckedHbnParams,
        names: SignalNames,
        sensors: &[SensorInputs],
    ) -> Result<Self, ModelError> {
        if params.firmware_budget.is_some() {
            return Err(ModelError::Config(ConfigError {
                param: Param::FirmwareBudget,
                problem: Problem::Invalid {
                    reason: "a flash budget trains scalar models only; for a vector model, \
                             train sparse GPs (--inducing 32, Python n_inducing=32) and read \
                             the sizes `hbn export` prints",
                },
            }));
        }
        let candidates = Self::candidates(params);
        // Without held-out folds (no data held out, or no trajectory long enough) nothing
        // could choose among the candidates: the primary alone.
        if candidates.len() < 2 || fold_count(trajectories) == 0 {
            return Self::fit_one(trajectories, params, names, sensors, None);
        }
        let t0 = Instant::now();
        // The sensor GPs depend on the inducing setting, not on the lags: one set of shared
        // cells per inducing setting.
        let inducing = inducing_settings(params);
        let shared: Vec<SharedSensors> = inducing
            .iter()
            .map(|_| SharedSensors::new(fold_count(trajectories)))
            .collect();
        let fit = |(lags, n_inducing): &(Vec<f64>, Option<usize>)| -> Trained {
            let t = Instant::now();
            let one = HbnParams {
                lags: lags.clone(),
                n_inducing: *n_inducing,
                select: crate::params::Selection {
                    lags: Vec::new(),
                    inducing: Vec::new(),
                    ..params.select.clone()
                },
                ..(**params).clone()
            };
            let cells = inducing
                .iter()
                .position(|m| m == n_inducing)
                .and_then(|i| shared.get(i));
            let model = one
                .check()
                .map_err(ModelError::from)
                .and_then(|p| Self::fit_one(trajectories, &p, names.clone(), sensors, cells));
            (model, t.elapsed().as_secs_f64())
        };
        // Candidates are handed out one at a time, in order: the first to fit a stage's sensor
        // GPs takes longer than those that find them fitted.
        let fitted: Vec<Trained> = crate::parallel::side_by_side(&candidates, fit);
        let mut rows: Vec<VectorCandidateRow> = candidates
            .iter()
            .zip(&fitted)
            .map(|((lags, n_inducing), (model, seconds))| {
                let scores = model.as_ref().ok().and_then(|m| m.held_out_best());
                VectorCandidateRow {
                    lags: lags.clone(),
                    n_inducing: *n_inducing,
                    nlpd: scores.as_ref().map(|s| s.0),
                    nrmse: scores.map(|s| s.1).unwrap_or_default(),
                    seconds: *seconds,
                    error: model.as_ref().err().map(ToString::to_string),
                    chosen: false,
                }
            })
            .collect();
        let choice = choose_candidate(&rows);
        // `choice` is the primary (0) unless a candidate that trained beat it; a failed
        // primary's error is the training's.
        let mut model = fitted
            .into_iter()
            .nth(choice)
            .map_or_else(|| Err(unfitted_candidate()), |(m, _)| m)?;
        if let Some(row) = rows.get_mut(choice) {
            row.chosen = true;
        }
        model.summary.candidates = rows;
        model.summary.seconds = t0.elapsed().as_secs_f64();
        Ok(model)
    }

    /// The candidates [`VectorModel::fit_with_sensors`] trains with `params` when it has
    /// held-out data, `(lags, inducing setting)`, the primary first: each inducing setting
    /// (the primary [`HbnParams::n_inducing`], then [`crate::params::Selection::inducing`])
    /// with each lag set; one alone when there is nothing to choose.
    pub fn candidates(params: &HbnParams) -> Vec<(Vec<f64>, Option<usize>)> {
        if params.validation <= 0.0 {
            return vec![(params.lags.clone(), params.n_inducing)];
        }
        candidates(params)
    }

    /// The held-out NLPD (summed over components) and nRMSE (per component) of this model's
    /// final choice on its held-out folds (`None` without held-out data).
    pub(crate) fn held_out_best(&self) -> Option<(f64, Vec<f64>)> {
        let row = self.summary.validation.iter().rfind(|r| r.chosen)?;
        (row.nlpd.is_finite() && row.nrmse.iter().all(|v| v.is_finite()))
            .then(|| (row.nlpd, row.nrmse.clone()))
    }

    /// [`VectorModel::fit_with_sensors`] for one candidate (`params.lags` and
    /// `params.n_inducing`; the selection's lag sets and inducing settings are not read). With `shared`, the sensor GPs come from there (fitted by whichever
    /// candidate needs them first).
    pub(crate) fn fit_one(
        trajectories: &[VectorSequence<'_>],
        params: &CheckedHbnParams,
        names: SignalNames,
        sensors: &[SensorInputs],
        shared: Option<&SharedSensors>,
    ) -> Result<Self, ModelError> {
        let t0 = Instant::now();
        let first = trajectories.first().ok_or(DataError::NoTrajectories)?;
        let dims = first.dims;
        dims.validate()?;
        for (i, t) in trajectories.iter().enumerate() {
            if t.dims != dims {
                return Err(ModelError::Core(hbn_core::CoreError::InvalidSpec(
                    "every trajectory must have the same numbers of inputs, states and outputs",
                )));
            }
            t.validate(i)?;
        }
        let plays = Plays::with_lags(&params.memory, &params.lag_coefficients()?)?;
        let t_dim = dims.transition_dim(plays.len());
        if t_dim > hbn_core::MAX_DIM {
            return Err(ModelError::Core(hbn_core::CoreError::InvalidSpec(
                "too many transition inputs (2 dx + du (2 + memory) > 32): use fewer memory radii",
            )));
        }
        // Folds: each quarter of every trajectory long enough, held out in turn. The GPs'
        // hyperparameters are optimised once, on the first fold's training part (all but the
        // last quarter); the other folds refit them with those hyperparameters.
        let folds = folds(trajectories);
        if sensors.contains(&SensorInputs::Memory) {
            return Err(ModelError::Config(ConfigError {
                param: Param::SensorInputs,
                problem: Problem::Invalid {
                    reason: "a vector model's sensors read `thesis` or `state` inputs; \
                             `memory` is for models of one state and one sensor",
                },
            }));
        }
        let fixed: Vec<bool> = match sensors {
            [] => Vec::new(),
            [one] => vec![*one == SensorInputs::Thesis; dims.sensors],
            many if many.len() == dims.sensors => {
                many.iter().map(|s| *s == SensorInputs::Thesis).collect()
            }
            _ => {
                return Err(ModelError::Config(ConfigError {
                    param: Param::SensorInputs,
                    problem: Problem::Invalid {
                        reason: "a vector model takes one sensor-inputs value for every sensor \
                                 or one per sensor",
                    },
                }));
            }
        };
        let stats = Stats::of(trajectories);
        let mut fold_fits: Vec<Fitted> = Vec::with_capacity(folds.len());
        let cell = |stage| shared.and_then(|s| s.cell(stage));
        for (f, (train, _)) in folds.iter().enumerate() {
            let fit = Self::fit_gps(
                train,
                params,
                &plays,
                fold_fits.first(),
                &fixed,
                cell(Stage::Fold(f)),
            )?;
            fold_fits.push(fit);
        }
        let primary = match fold_fits.first() {
            Some(f) => f.clone(),
            None => Self::fit_gps(trajectories, params, &plays, None, &fixed, cell(Stage::All))?,
        };
        let mut model = Self::assemble(
            params,
            dims,
            &plays,
            &stats,
            trajectories,
            primary.clone(),
            names,
        )?;
        model.summary.kernel_evidence = primary.kernels.clone();
        for (j, reads) in fixed.iter().enumerate() {
            model.sensors[j] = primary.sensor(j, *reads)?.clone();
            model.sensor_reads_output[j] = *reads;
        }
        let mut validation = Vec::new();
        if !folds.is_empty() {
            let held: Vec<&[VectorSequence<'_>]> =
                folds.iter().map(|(_, h)| h.as_slice()).collect();
            model.choose_on_held_out(&held, &fold_fits, !fixed.is_empty(), &mut validation)?;
        }
        // Refit on every sample with the hyperparameters found.
        let refit = Self::fit_gps(
            trajectories,
            params,
            &plays,
            Some(&primary),
            &fixed,
            cell(Stage::Refit),
        )?;
        let choice = model.sensor_reads_output.clone();
        model.transitions = refit.transitions;
        model.sensors = refit
            .sensors
            .into_iter()
            .zip(&choice)
            .map(|(pair, &reads)| {
                let [with_y, state_only] = pair;
                if reads { with_y } else { state_only }.ok_or_else(unfitted)
            })
            .collect::<Result<_, _>>()?;
        model.summary.trajectories = trajectories.len();
        model.summary.samples = trajectories.iter().map(|t| t.len()).sum();
        model.summary.validation = validation;
        let first_run = model.estimate(first.u, first.y, model.mode)?;
        model.summary.unobservable = first_run.unobservable.clone();
        for (i, f) in first_run.unobservable.iter().enumerate() {
            if *f > 0.05 {
                model.summary.warnings.push(format!(
                    "observability: state component {} ({}) is unobservable in {:.0}% of the \
                     first training log's windows; no sensor distinguishes its values there",
                    i,
                    model
                        .signal_names
                        .states
                        .get(i)
                        .map_or("unnamed", String::as_str),
                    100.0 * f
                ));
            }
        }
        model.summary.seconds = t0.elapsed().as_secs_f64();
        Ok(model)
    }

    /// Fits every GP on `trajectories`: the transitions and both variants of each sensor, or
    /// only the variant `only[j]` says (`true`: with its own previous output) where `only`
    /// is not empty (the sensor inputs were given). With `fixed`, each GP keeps the
    /// hyperparameters of its twin there (a refit on other data). With `shared`, the sensor
    /// GPs are those in the cell, fitted here first if it is empty ([`SharedSensors`]).
    fn fit_gps(
        trajectories: &[VectorSequence<'_>],
        params: &CheckedHbnParams,
        plays: &Plays,
        fixed: Option<&Fitted>,
        only: &[bool],
        shared: Option<&OnceLock<Option<SensorFits>>>,
    ) -> Result<Fitted, ModelError> {
        let dims = trajectories[0].dims;
        let (t_rows, t_targets) = transition_rows(trajectories, plays);
        let t_dim = dims.transition_dim(plays.len());
        let mut transitions = Vec::with_capacity(dims.states);
        let mut kernels = Vec::new();
        for i in 0..dims.states {
            let targets: Vec<f64> = t_targets
                .iter()
                .skip(i)
                .step_by(dims.states)
                .copied()
                .collect();
            let gp = Self::fit_gp(
                params,
                GpRole::Transition,
                t_dim,
                params.seed.wrapping_add(i as u64),
                fixed.map(|f| &f.transitions[i]),
                (&t_rows, &targets),
                &format!("transition {i}"),
                &mut kernels,
            )?;
            transitions.push(gp);
        }
        let fit_sensors = || Self::fit_sensors(trajectories, params, fixed, only);
        // A failed shared fit is fitted again here, so that its error is this fit's.
        let (sensors, sensor_kernels) =
            match shared.map(|cell| cell.get_or_init(|| fit_sensors().ok())) {
                Some(Some(fits)) => fits.clone(),
                _ => fit_sensors()?,
            };
        kernels.extend(sensor_kernels);
        Ok(Fitted {
            transitions,
            sensors,
            kernels,
        })
    }

    /// Fits one GP on `(rows, targets)`. With `fixed`, that GP's kernel and hyperparameters
    /// (a refit on other data); otherwise the role's kernel and those of the selection
    /// ([`crate::params::Selection::kernels`]), keeping the highest log marginal likelihood
    /// (the first of equals; rows for `evidence`, labelled `gp`, where there were several).
    #[allow(clippy::too_many_arguments)]
    fn fit_gp(
        params: &CheckedHbnParams,
        role: GpRole,
        dim: usize,
        seed: u64,
        fixed: Option<&GaussianProcess>,
        (rows, targets): (&[f64], &[f64]),
        gp: &str,
        evidence: &mut Vec<VectorKernelRow>,
    ) -> Result<GaussianProcess, ModelError> {
        let fit = |spec: hbn_core::KernelSpec, init: Option<&GaussianProcess>| {
            spec.validate().map_err(|e| ModelError::Gp {
                which: role,
                source: hbn_gp::GpError::from(e),
            })?;
            let mut g = params.gp_params(spec, role);
            g.seed = seed;
            if let Some(f) = init {
                g.init = Some(f.hyperparameters());
                g.optimize = false;
            }
            hbn_gp::fit(&g, rows, targets).map_err(|source| ModelError::Gp {
                which: role,
                source,
            })
        };
        if let Some(f) = fixed {
            return fit(*f.kernel(), Some(f));
        }
        let set = match role {
            GpRole::Transition => params.transition_kernel,
            GpRole::Sensor => params.sensor_kernel,
        };
        // A list of kernels (`--kernel a,b`) is chosen among by evidence, per GP. The
        // scalar default's choice by evidence ([`HbnParams::kernel_evidence`]) is not made:
        // docs/vector.md, "The model".
        let mut kernels = vec![set];
        for k in &params.select.kernels {
            if !kernels.contains(k) {
                kernels.push(*k);
            }
        }
        let fits: Vec<(KernelChoice, Result<GaussianProcess, ModelError>)> = kernels
            .iter()
            .map(|k| {
                let mut spec = k.spec(dim, [0, 0]);
                spec.direction = None;
                (*k, fit(spec, None))
            })
            .collect();
        let lml = |r: &Result<GaussianProcess, ModelError>| {
            r.as_ref()
                .ok()
                .map(GaussianProcess::log_marginal_likelihood)
                .filter(|l| l.is_finite())
        };
        let best = crate::evidence::highest(fits.iter().map(|(_, r)| lml(r)));
        if fits.len() > 1 {
            evidence.extend(fits.iter().enumerate().map(|(i, (k, r))| VectorKernelRow {
                gp: gp.to_owned(),
                kernel: *k,
                lml: lml(r),
                chosen: Some(i) == best,
            }));
        }
        // None fitted: the first kernel's error.
        fits.into_iter()
            .nth(best.unwrap_or(0))
            .map_or_else(|| Err(unfitted()), |(_, r)| r)
    }

    /// The sensor GPs of [`VectorModel::fit_gps`].
    fn fit_sensors(
        trajectories: &[VectorSequence<'_>],
        params: &CheckedHbnParams,
        fixed: Option<&Fitted>,
        only: &[bool],
    ) -> Result<SensorFits, ModelError> {
        let dims = trajectories[0].dims;
        let mut sensors = Vec::with_capacity(dims.sensors);
        let mut kernels = Vec::new();
        for j in 0..dims.sensors {
            let mut pair = [None, None];
            for (slot, reads) in pair.iter_mut().zip([true, false]) {
                if only.get(j).is_some_and(|given| *given != reads) {
                    continue;
                }
                let (rows, targets) = sensor_rows(trajectories, j, reads);
                let twin = fixed.map(|f| f.sensor(j, reads)).transpose()?;
                let inputs = if reads { "own output" } else { "state only" };
                let gp = Self::fit_gp(
                    params,
                    GpRole::Sensor,
                    dims.sensor_dim(reads),
                    params.seed.wrapping_add(100 + j as u64),
                    twin,
                    (&rows, &targets),
                    &format!("sensor {j} ({inputs})"),
                    &mut kernels,
                )?;
                *slot = Some(gp);
            }
            sensors.push(pair);
        }
        Ok((sensors, kernels))
    }

    fn assemble(
        params: &CheckedHbnParams,
        dims: Dims,
        plays: &Plays,
        stats: &Stats,
        trajectories: &[VectorSequence<'_>],
        fitted: Fitted,
        names: SignalNames,
    ) -> Result<Self, ModelError> {
        let mut init_rows = Vec::new();
        for t in trajectories {
            for k in 0..t.len() {
                init_rows.extend_from_slice(&t.y[k * dims.sensors..(k + 1) * dims.sensors]);
                init_rows.extend_from_slice(&t.x[k * dims.states..(k + 1) * dims.states]);
            }
        }
        // Keep the prior's table bounded: every n-th row.
        let width = dims.sensors + dims.states;
        let rows = init_rows.len() / width;
        let keep = 2000;
        if rows > keep {
            let step = rows.div_ceil(keep);
            init_rows = init_rows
                .chunks_exact(width)
                .step_by(step)
                .flatten()
                .copied()
                .collect();
        }
        // Each sensor's variant with its own previous output, or the one fitted.
        let sensors = fitted
            .sensors
            .into_iter()
            .map(|[with_y, state_only]| with_y.or(state_only).ok_or_else(unfitted))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            params: (**params).clone(),
            dims,
            transitions: fitted.transitions,
            sensors,
            sensor_reads_output: vec![true; dims.sensors],
            u_stats: stats.u.clone(),
            x_stats: stats.x.clone(),
            y_stats: stats.y.clone(),
            init_rows,
            mode: Mode::Ekf,
            q_scale: 1.0,
            std_scale: vec![1.0; dims.states],
            play_radii: plays.radii().to_vec(),
            signal_names: names,
            read_options: None,
            summary: VectorSummary::default(),
        })
    }

    /// Chooses, on the held-out folds: each sensor's inputs (one sensor at a time: its
    /// state-only GP replaces the thesis' where the score falls; skipped when given), the
    /// mode, the process-noise scale, then each component's std scale (its held-out NEES
    /// made one). `fits` holds each fold's GPs, `held` its held-out parts.
    fn choose_on_held_out(
        &mut self,
        held: &[&[VectorSequence<'_>]],
        fits: &[Fitted],
        sensors_given: bool,
        rows: &mut Vec<VectorValidationRow>,
    ) -> Result<(), ModelError> {
        let mut best = self.held_out_score(held, fits)?;
        let first = if sensors_given {
            "sensor inputs as given"
        } else {
            "sensors read their own previous output"
        };
        rows.push(best.row(first.into(), true));
        let mut consider = |this: &mut Self,
                            candidate: Self,
                            what: String,
                            best: &mut HeldOut|
         -> Result<(), ModelError> {
            let s = candidate.held_out_score(held, fits)?;
            let better = s.nlpd < best.nlpd;
            rows.push(s.row(what, better));
            if better {
                *this = candidate;
                *best = s;
            }
            Ok(())
        };
        if !sensors_given {
            for j in 0..self.dims.sensors {
                let mut candidate = self.clone();
                candidate.sensor_reads_output[j] = false;
                if let Some(f) = fits.first() {
                    candidate.sensors[j] = f.sensor(j, false)?.clone();
                }
                consider(
                    self,
                    candidate,
                    format!("sensor {j}: state only"),
                    &mut best,
                )?;
            }
        }
        let mut candidate = self.clone();
        candidate.mode = Mode::Ukf;
        consider(self, candidate, "mode ukf".into(), &mut best)?;
        for q in Q_SCALES.into_iter().filter(|q| *q != 1.0) {
            let mut candidate = self.clone();
            candidate.q_scale = q;
            consider(self, candidate, format!("process noise x{q}"), &mut best)?;
        }
        // The band is scaled so that 95% of the held-out states fall inside +-2 std: the 95th
        // percentile of |error| / std over 2 (robust where a few stretches, such as a filter
        // starting on a held-out quarter, have large normalised errors).
        self.std_scale = best
            .normalised
            .iter()
            .map(|z| calibration_scale(z))
            .collect();
        Ok(())
    }

    /// This model's settings (sensor choice, mode, noise scale) with fold `f`'s GPs.
    fn on_fold(&self, fit: &Fitted) -> Result<Self, ModelError> {
        let mut m = self.clone();
        m.transitions = fit.transitions.clone();
        m.sensors = self
            .sensor_reads_output
            .iter()
            .enumerate()
            .map(|(j, reads)| fit.sensor(j, *reads).cloned())
            .collect::<Result<_, _>>()?;
        m.std_scale = vec![1.0; self.dims.states];
        Ok(m)
    }

    /// The filter's held-out score over every fold with this model's settings (each fold's
    /// own GPs), pooled over the held-out samples.
    fn held_out_score(
        &self,
        held: &[&[VectorSequence<'_>]],
        fits: &[Fitted],
    ) -> Result<HeldOut, ModelError> {
        let dx = self.dims.states;
        // Per component: the measured values scored, their squared errors, `ln sd` and the
        // normalised errors `|err| / sd`.
        let mut count = vec![0usize; dx];
        let mut sq = vec![0.0; dx];
        let mut log_std = vec![0.0; dx];
        let mut normalised = vec![Vec::new(); dx];
        for (parts, fit) in held.iter().zip(fits) {
            let model = self.on_fold(fit)?;
            for t in parts.iter() {
                let e = model.estimate(t.u, t.y, model.mode)?;
                for k in 0..t.len() {
                    for i in (0..dx).filter(|&i| t.is_observed(k, i)) {
                        let err = e.x[k * dx + i] - t.x[k * dx + i];
                        let sd = e.x_std[k * dx + i].max(1e-300);
                        count[i] += 1;
                        sq[i] += err * err;
                        log_std[i] += sd.ln();
                        normalised[i].push(err.abs() / sd);
                    }
                }
            }
        }
        let nrmse = sq
            .iter()
            .zip(&count)
            .zip(&self.x_stats)
            .map(|((s, c), st)| (s / (*c).max(1) as f64).sqrt() / st.span().max(1e-12))
            .collect();
        // Scored as the model will report: each component's band scaled as training scales it
        // ([`calibration_scale`]), so that a setting is not chosen for widening an
        // overconfident band, which the scale does anyway. With the scale `c`, a value's NLPD
        // gains `ln c` and its squared term is divided by `c^2`. Each component's mean NLPD
        // over its measured values, summed over the components.
        let mut nlpd = 0.0;
        for ((z, l), c) in normalised.iter().zip(&log_std).zip(&count) {
            let scale = calibration_scale(z);
            let mut sum = l + 0.5 * (2.0 * std::f64::consts::PI).ln() * *c as f64;
            for v in z {
                sum += scale.ln() + 0.5 * (v / scale) * (v / scale);
            }
            nlpd += sum / (*c).max(1) as f64;
        }
        Ok(HeldOut {
            nlpd: if nlpd.is_finite() {
                nlpd
            } else {
                f64::INFINITY
            },
            nrmse,
            normalised,
        })
    }

    /// The sizes.
    pub fn dims(&self) -> Dims {
        self.dims
    }

    /// The mode chosen on held-out data.
    pub fn default_mode(&self) -> Mode {
        self.mode
    }

    /// Training parameters.
    pub fn params(&self) -> &HbnParams {
        &self.params
    }

    /// Sample rate (Hz).
    pub fn rate_hz(&self) -> f64 {
        self.params.rate_hz
    }

    /// The signals' names.
    pub fn signal_names(&self) -> &SignalNames {
        &self.signal_names
    }

    /// Sets the signals' names (the paths the logs were read by).
    pub fn set_signal_names(&mut self, names: SignalNames) {
        self.signal_names = names;
    }

    /// Records how the training logs were read (time source name, largest gap in seconds).
    pub fn set_read_options(&mut self, time_source: &str, max_gap_s: f64) {
        self.read_options = Some((time_source.to_owned(), max_gap_s));
    }

    /// How the training logs were read, if they were logs.
    pub fn read_options(&self) -> Option<(&str, f64)> {
        self.read_options.as_ref().map(|(t, g)| (t.as_str(), *g))
    }

    /// What training found.
    pub fn summary(&self) -> &VectorSummary {
        &self.summary
    }

    /// What training found, to add to.
    pub(crate) fn summary_mut(&mut self) -> &mut VectorSummary {
        &mut self.summary
    }

    /// Whether sensor `j` reads its own previous output (else the state only).
    pub fn sensor_reads_output(&self, j: usize) -> Option<bool> {
        self.sensor_reads_output.get(j).copied()
    }

    /// The transition GP of state component `i`.
    pub fn transition(&self, i: usize) -> Option<&GaussianProcess> {
        self.transitions.get(i)
    }

    /// The GP of sensor `j`.
    pub fn sensor(&self, j: usize) -> Option<&GaussianProcess> {
        self.sensors.get(j)
    }

    /// Training statistics of the inputs, states and outputs, per component.
    pub fn stats(&self) -> (&[SignalStats], &[SignalStats], &[SignalStats]) {
        (&self.u_stats, &self.x_stats, &self.y_stats)
    }

    /// The time constants (s) of the transition's lags ([`HbnParams::lags`]); empty: none.
    pub fn lags(&self) -> &[f64] {
        &self.params.lags
    }

    /// The memory operators.
    pub fn plays(&self) -> Result<Plays, ModelError> {
        Ok(Plays::with_lags(
            &self.play_radii,
            &self.params.lag_coefficients()?,
        )?)
    }

    /// The filter's settings in `mode`, with the noise and std scales chosen on held-out data.
    pub fn config(&self, mode: Mode) -> VectorConfig {
        let mut c = VectorConfig {
            mode,
            x_bounds: [(0.0, 1.0); MAX_STATES],
            y_bounds: [(0.0, 1.0); MAX_SENSORS],
            x0_mean: [0.0; MAX_STATES],
            x0_var: [1.0; MAX_STATES],
            qx_model_floor: [0.0; MAX_STATES],
            r_model_floor: [0.0; MAX_SENSORS],
            q_floor: 1e-10 / 1.44,
            r_floor: 1e-10 / 1.44,
            p_min: 1e-14,
            p_max: 4.0,
            jac_max: 20.0,
            innovation_min: 1e-14,
            nis_gate: OUTLIER_GATE,
            q_scale: self.q_scale,
            r_scale: 1.0,
            std_scale: [1.0; MAX_STATES],
        };
        for (i, s) in self.x_stats.iter().enumerate().take(MAX_STATES) {
            let sp = s.span();
            c.x_bounds[i] = (s.min - 0.1 * sp, s.max + 0.1 * sp);
            c.x0_mean[i] = s.mean;
            c.x0_var[i] = s.var.max(1e-12 * sp * sp);
            c.qx_model_floor[i] = self.transitions[i].loo_error_variance();
            c.std_scale[i] = self.std_scale.get(i).copied().unwrap_or(1.0);
        }
        for (j, s) in self.y_stats.iter().enumerate().take(MAX_SENSORS) {
            let sp = s.span();
            c.y_bounds[j] = (s.min - 0.1 * sp, s.max + 0.1 * sp);
            c.r_model_floor[j] = self.sensors[j].loo_error_variance();
        }
        c
    }

    /// Runs the filter over `u` (`T x du`) and `y` (`T x dy`, non-finite values missing).
    pub fn estimate(&self, u: &[f64], y: &[f64], mode: Mode) -> Result<VectorEstimate, ModelError> {
        self.run(u, y, mode, false, &Frames::NONE)
            .map(|(out, _)| out)
    }

    /// The filter over a sequence ([`VectorModel::estimate`]); with `record`, also what the
    /// smoother needs at each step (the prediction before it, through
    /// [`VectorEkf::predict`], and the filtered state after it).
    pub(crate) fn run(
        &self,
        u: &[f64],
        y: &[f64],
        mode: Mode,
        record: bool,
        frames: &Frames<'_>,
    ) -> Result<(VectorEstimate, Option<Recorded>), ModelError> {
        let d = self.dims;
        let t = u.len() / d.inputs;
        if !u.len().is_multiple_of(d.inputs) || y.len() != t * d.sensors {
            return Err(DataError::InputOutputLength {
                u: u.len() / d.inputs,
                y: y.len() / d.sensors,
            }
            .into());
        }
        let tv: Vec<GpView<'_>> = self
            .transitions
            .iter()
            .map(|g| g.view())
            .collect::<Result<_, _>>()?;
        let sv: Vec<GpView<'_>> = self
            .sensors
            .iter()
            .map(|g| g.view())
            .collect::<Result<_, _>>()?;
        let y_scale: Vec<f64> = self.y_stats.iter().map(|s| s.span().max(1e-12)).collect();
        let var_floor: Vec<f64> = self
            .x_stats
            .iter()
            .map(|s| (1e-4 * s.span() * s.span()).max(1e-18))
            .collect();
        let init =
            VectorInitPrior::new(&self.init_rows, d, &y_scale, INIT_NEIGHBOURS, &var_floor).ok();
        let view = VectorView {
            dims: d,
            transitions: &tv,
            sensors: &sv,
            plays: self.plays()?,
            init,
        };
        let ekf = VectorEkf::new(view, self.config(mode))?;
        let mut scratch = vec![0.0; ekf.scratch_len()];
        let mut state = None;
        let mut out = VectorEstimate {
            dims: d,
            mode,
            x: Vec::with_capacity(t * d.states),
            x_std: Vec::with_capacity(t * d.states),
            x_cov: Vec::with_capacity(t * d.states * d.states),
            y_pred: Vec::with_capacity(t * d.sensors),
            innovation: Vec::with_capacity(t * d.sensors),
            nis: Vec::with_capacity(t),
            flags: Vec::with_capacity(t),
            unobservable: vec![0.0; d.states],
        };
        let mut jac = Vec::with_capacity(OBSERVABILITY_WINDOW);
        let mut rs = Vec::with_capacity(OBSERVABILITY_WINDOW);
        let mut windows = 0usize;
        let spans: Vec<f64> = self.x_stats.iter().map(|s| s.span().max(1e-12)).collect();
        let mut recorded = record.then(|| Recorded {
            spans: *ekf.spans(),
            steps: Vec::with_capacity(t),
        });
        // Each component's frames not applied yet.
        let mut pending: Vec<&[StateFrame]> = (0..d.states)
            .map(|i| frames.of.get(i).map_or(&[][..], Vec::as_slice))
            .collect();
        for k in 0..t {
            let prediction = match (&recorded, &state) {
                (Some(_), Some(st)) => Some(ekf.predict(st, &mut scratch)),
                _ => None,
            };
            let o = ekf.step(
                &mut state,
                &mut scratch,
                &u[k * d.inputs..(k + 1) * d.inputs],
                &y[k * d.sensors..(k + 1) * d.sensors],
            );
            for (i, rest) in pending.iter_mut().enumerate() {
                let here = rest.partition_point(|f| f.k <= k);
                let (now, later) = rest.split_at(here);
                *rest = later;
                let var = frames.var.get(i).copied().unwrap_or(0.0);
                if let Some(st) = state.as_mut() {
                    for f in now.iter().filter(|f| f.k == k) {
                        frame_update(st, d, i, f, var);
                    }
                }
            }
            if let (Some(rec), Some(st)) = (recorded.as_mut(), &state) {
                // A re-start (or the first sample) does not follow from the prediction.
                let restarted = o.flags.has(Flags::RELOCALISED) || o.flags.has(Flags::INITIALISED);
                rec.steps.push(RecordedStep {
                    z: st.z,
                    p: st.p,
                    link: prediction.filter(|_| !restarted),
                });
            }
            out.x.extend_from_slice(&o.x[..d.states]);
            out.x_std.extend_from_slice(&o.x_std[..d.states]);
            for row in o.x_cov.iter().take(d.states) {
                out.x_cov.extend_from_slice(&row[..d.states]);
            }
            out.y_pred.extend_from_slice(&o.y_pred[..d.sensors]);
            out.innovation.extend_from_slice(&o.innovation[..d.sensors]);
            out.nis.push(o.nis);
            out.flags.push(o.flags.0);
            if k > 0 {
                jac.push(o.jacobian);
                rs.push(o.r);
            }
            if jac.len() == OBSERVABILITY_WINDOW {
                if let Some(info) = vector_state_information(d, &jac, &rs) {
                    let scaled: Vec<f64> = (0..d.states)
                        .map(|i| info[i] * spans[i] * spans[i])
                        .collect();
                    let best = scaled.iter().fold(0.0f64, |a, b| a.max(*b));
                    windows += 1;
                    for (i, v) in scaled.iter().enumerate() {
                        if *v <= UNOBSERVABLE_RATIO * best {
                            out.unobservable[i] += 1.0;
                        }
                    }
                }
                jac.clear();
                rs.clear();
            }
        }
        if windows > 0 {
            for f in &mut out.unobservable {
                *f /= windows as f64;
            }
        }
        Ok((out, recorded))
    }

    /// The model as JSON text (the model file).
    pub fn to_json(&self) -> Result<String, ModelError> {
        serde_json::to_string(&VectorModelFile {
            format: VECTOR_MODEL_FORMAT.into(),
            version: VECTOR_MODEL_FORMAT_VERSION,
            model: self.clone(),
        })
        .map_err(|e| ModelError::ModelFile {
            path: "<memory>".into(),
            problem: ModelFileProblem::Malformed {
                detail: e.to_string(),
            },
        })
    }

    /// Parses [`VectorModel::to_json`] output, checking tag, version and consistency.
    pub fn from_json(text: &str, origin: &str) -> Result<Self, ModelError> {
        let fail = |problem| ModelError::ModelFile {
            path: origin.into(),
            problem,
        };
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|_| fail(ModelFileProblem::NotJson))?;
        let tag = value.get("format").and_then(|v| v.as_str()).unwrap_or("");
        if tag != VECTOR_MODEL_FORMAT {
            return Err(fail(ModelFileProblem::WrongFormat { tag: tag.into() }));
        }
        let version = value.get("version").and_then(|v| v.as_u64()).unwrap_or(0);
        if version != u64::from(VECTOR_MODEL_FORMAT_VERSION) {
            return Err(fail(ModelFileProblem::UnsupportedVersion { version }));
        }
        let file: VectorModelFile = serde_json::from_value(value).map_err(|e| {
            fail(ModelFileProblem::Malformed {
                detail: e.to_string(),
            })
        })?;
        let mut m = file.model;
        for gp in m.transitions.iter_mut().chain(m.sensors.iter_mut()) {
            gp.restore_factor().map_err(|e| {
                fail(ModelFileProblem::Malformed {
                    detail: format!("a GP's factor cannot be recomputed: {e}"),
                })
            })?;
        }
        m.check().map_err(|e| match e {
            ModelError::Core(c) => fail(ModelFileProblem::Inconsistent(c)),
            other => other,
        })?;
        Ok(m)
    }

    /// Checks the parts agree (sizes, GP dimensions, views).
    fn check(&self) -> Result<(), ModelError> {
        let d = self.dims;
        d.validate()?;
        let bad = |why| ModelError::Core(hbn_core::CoreError::InvalidSpec(why));
        if self.transitions.len() != d.states
            || self.sensors.len() != d.sensors
            || self.sensor_reads_output.len() != d.sensors
            || self.u_stats.len() != d.inputs
            || self.x_stats.len() != d.states
            || self.y_stats.len() != d.sensors
            || self.std_scale.len() != d.states
        {
            return Err(bad("the model's parts disagree with its sizes"));
        }
        let tv: Vec<GpView<'_>> = self
            .transitions
            .iter()
            .map(|g| g.view())
            .collect::<Result<_, _>>()?;
        let sv: Vec<GpView<'_>> = self
            .sensors
            .iter()
            .map(|g| g.view())
            .collect::<Result<_, _>>()?;
        let view = VectorView {
            dims: d,
            transitions: &tv,
            sensors: &sv,
            plays: self.plays()?,
            init: None,
        };
        VectorEkf::new(view, self.config(self.mode))?;
        Ok(())
    }

    /// Writes the model file atomically.
    pub fn save(&self, path: &Path) -> Result<(), ModelError> {
        Ok(hbn_fs::write_atomic(path, self.to_json()?.as_bytes())?)
    }

    /// Loads a model written by [`VectorModel::save`].
    pub fn load(path: &Path) -> Result<Self, ModelError> {
        let bytes = std::fs::read(path).map_err(|source| ModelError::Io {
            path: path.display().to_string(),
            source,
        })?;
        let text = String::from_utf8(bytes).map_err(|_| ModelError::ModelFile {
            path: path.display().to_string(),
            problem: ModelFileProblem::NotJson,
        })?;
        Self::from_json(&text, &path.display().to_string())
    }

    /// The prior of `x_0` from the first measurements over the training rows, as
    /// [`VectorModel::estimate`] builds it (`None` where it cannot be built: the settings'
    /// training prior applies). For a streaming filter ([`crate::VectorFilter`]).
    pub fn init_prior(&self) -> Option<VectorInitPrior<'_>> {
        let y_scale: Vec<f64> = self.y_stats.iter().map(|s| s.span().max(1e-12)).collect();
        let var_floor: Vec<f64> = self
            .x_stats
            .iter()
            .map(|s| (1e-4 * s.span() * s.span()).max(1e-18))
            .collect();
        VectorInitPrior::new(
            &self.init_rows,
            self.dims,
            &y_scale,
            INIT_NEIGHBOURS,
            &var_floor,
        )
        .ok()
    }

    /// The parts [`VectorModel::init_prior`] builds the prior of `x_0` from (for exporting
    /// the model as tables): the training rows `[y (dy), x (dx)]`, each sensor's distance
    /// scale, the neighbours averaged and each component's variance floor.
    pub fn init_prior_parts(&self) -> (&[f64], Vec<f64>, usize, Vec<f64>) {
        let y_scale = self.y_stats.iter().map(|s| s.span().max(1e-12)).collect();
        let var_floor = self
            .x_stats
            .iter()
            .map(|s| (1e-4 * s.span() * s.span()).max(1e-18))
            .collect();
        (&self.init_rows, y_scale, INIT_NEIGHBOURS, var_floor)
    }
}

/// Measurements of the state for [`VectorModel::run`]: per component, its frames (sorted by
/// grid sample) and their noise variance.
pub(crate) struct Frames<'a> {
    /// Frames of each component.
    pub of: &'a [Vec<StateFrame>],
    /// Noise variance of each component's frames.
    pub var: &'a [f64],
}

impl Frames<'_> {
    /// No frames: the filter alone.
    pub const NONE: Frames<'static> = Frames { of: &[], var: &[] };
}

/// Updates the filter's state with a frame of component `i`: `value = w x_k[i] + (1 - w)
/// x_{k-1}[i] + e`, `e ~ N(0, var)` (Joseph form, symmetric). A frame with a non-finite value
/// or weight, or an update that is not finite, leaves the state as it was.
fn frame_update(st: &mut VectorState, d: Dims, i: usize, frame: &StateFrame, var: f64) {
    let w = frame.weight;
    if !(w.is_finite() && frame.value.is_finite() && var.is_finite() && var > 0.0) {
        return;
    }
    let w = w.clamp(0.0, 1.0);
    let n = d.augmented();
    let mut h = DVector::<f64>::zeros(n);
    h[i] = w;
    h[d.states + i] = 1.0 - w;
    let p = DMatrix::from_fn(n, n, |r, c| st.p[r][c]);
    let z = DVector::from_fn(n, |r, _| st.z[r]);
    let ph = &p * &h;
    let s = h.dot(&ph) + var;
    if !(s.is_finite() && s > 0.0) {
        return;
    }
    let gain = ph / s;
    let innovation = frame.value - h.dot(&z);
    let i_kh = DMatrix::<f64>::identity(n, n) - &gain * h.transpose();
    let p_new = &i_kh * p * i_kh.transpose() + &gain * gain.transpose() * var;
    let p_new = 0.5 * (&p_new + p_new.transpose());
    let z_new = z + gain * innovation;
    if z_new.iter().chain(p_new.iter()).all(|v| v.is_finite()) {
        for r in 0..n {
            st.z[r] = z_new[r];
            for c in 0..n {
                st.p[r][c] = p_new[(r, c)];
            }
        }
    }
}

/// The lag sets a vector model trains: the primary ([`HbnParams::lags`]), then the
/// selection's, where the library's default selection ([`crate::DEFAULT_LAGS`]) stands for
/// [`crate::VECTOR_DEFAULT_LAGS`]; each set once.
fn lag_sets(params: &HbnParams) -> Vec<Vec<f64>> {
    let default = [crate::DEFAULT_LAGS.to_vec()];
    let alternatives: Vec<Vec<f64>> = if params.select.lags == default {
        crate::VECTOR_DEFAULT_LAGS
            .iter()
            .map(|l| l.to_vec())
            .collect()
    } else {
        params.select.lags.clone()
    };
    let mut sets = vec![params.lags.clone()];
    for set in alternatives {
        if !sets.contains(&set) {
            sets.push(set);
        }
    }
    sets
}

/// The inducing settings a vector model trains: the primary ([`HbnParams::n_inducing`]), then
/// the selection's; each once.
fn inducing_settings(params: &HbnParams) -> Vec<Option<usize>> {
    let mut out = vec![params.n_inducing];
    for m in &params.select.inducing {
        if !out.contains(m) {
            out.push(*m);
        }
    }
    out
}

/// The candidates a vector model trains, `(lags, inducing setting)`: each inducing setting
/// ([`inducing_settings`]) with each lag set ([`lag_sets`]), the primary (both primary) first.
fn candidates(params: &HbnParams) -> Vec<(Vec<f64>, Option<usize>)> {
    let sets = lag_sets(params);
    inducing_settings(params)
        .into_iter()
        .flat_map(|m| sets.iter().map(move |lags| (lags.clone(), m)))
        .collect()
}

/// The candidate `fit_with_sensors` keeps: the lowest held-out NLPD among those scored whose
/// mean held-out nRMSE is no higher than the primary's (row 0); the primary when it alone
/// scored or nothing beats it.
fn choose_candidate(rows: &[VectorCandidateRow]) -> usize {
    let mean = |r: &VectorCandidateRow| r.nrmse.iter().sum::<f64>() / r.nrmse.len().max(1) as f64;
    let Some(primary) = rows.first().filter(|r| r.nlpd.is_some()) else {
        return 0;
    };
    let limit = mean(primary);
    let mut best = (0, primary.nlpd.unwrap_or(f64::INFINITY));
    for (i, r) in rows.iter().enumerate().skip(1) {
        if let Some(nlpd) = r.nlpd
            && nlpd < best.1
            && mean(r) <= limit
        {
            best = (i, nlpd);
        }
    }
    best.0
}

fn unfitted_candidate() -> ModelError {
    ModelError::Core(hbn_core::CoreError::InvalidSpec(
        "a lag candidate's training stopped unexpectedly",
    ))
}

fn unfitted() -> ModelError {
    ModelError::Core(hbn_core::CoreError::InvalidSpec(
        "a sensor GP could not be fitted",
    ))
}

/// How many folds [`folds`] makes of `trajectories`: 4, or 0 when no trajectory is long enough
/// (80 samples). Reads only the lengths, so it is safe before the trajectories are validated.
fn fold_count(trajectories: &[VectorSequence<'_>]) -> usize {
    if trajectories.iter().any(|t| t.len() >= 80) {
        4
    } else {
        0
    }
}

/// The held-out folds of `trajectories`: for each quarter `q` (the last first), the training
/// parts (every trajectory long enough without its quarter `q`, the pieces before and after
/// it as trajectories of their own; shorter trajectories whole) and the held-out quarters.
/// None when no trajectory is long enough (80 samples).
#[allow(clippy::type_complexity)]
fn folds<'a>(
    trajectories: &[VectorSequence<'a>],
) -> Vec<(Vec<VectorSequence<'a>>, Vec<VectorSequence<'a>>)> {
    (0..fold_count(trajectories))
        .rev()
        .map(|q| {
            let (mut train, mut held) = (Vec::new(), Vec::new());
            for t in trajectories {
                let n = t.len();
                if n < 80 {
                    train.push(*t);
                    continue;
                }
                let (a, b) = (q * n / 4, (q + 1) * n / 4);
                for (from, to) in [(0, a), (b, n)] {
                    if to - from >= 20 {
                        train.push(t.slice(from, to));
                    }
                }
                held.push(t.slice(a, b));
            }
            (train, held)
        })
        .collect()
}

/// A configuration's held-out scores.
struct HeldOut {
    nlpd: f64,
    nrmse: Vec<f64>,
    /// Per component, `|error| / std` of every held-out sample.
    normalised: Vec<Vec<f64>>,
}

/// Bounds of a component's band scale. Wide: with little noise the GPs' variances miss most
/// of the model's error and the filter's own band is 2-16 times too narrow (measured on the
/// finger and the arm at noise gains 0 and 1, 3000 training samples).
const CALIBRATION_SCALE_RANGE: (f64, f64) = (0.01, 1000.0);

/// The scale of a component's band from its held-out `|error| / std`: the 95% quantile over
/// 2 (so that 95% of the held-out states fall inside +-2 std), within
/// [`CALIBRATION_SCALE_RANGE`].
fn calibration_scale(normalised: &[f64]) -> f64 {
    let q = quantile(normalised, 0.95) / 2.0;
    if q.is_finite() && q > 0.0 {
        q.clamp(CALIBRATION_SCALE_RANGE.0, CALIBRATION_SCALE_RANGE.1)
    } else {
        1.0
    }
}

/// The `p` quantile of `values` (NaN when empty; non-finite values sort last).
fn quantile(values: &[f64], p: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let idx = ((v.len() - 1) as f64 * p).round() as usize;
    v[idx.min(v.len() - 1)]
}

impl HeldOut {
    fn row(&self, what: String, chosen: bool) -> VectorValidationRow {
        VectorValidationRow {
            what,
            nlpd: self.nlpd,
            nrmse: self.nrmse.clone(),
            chosen,
        }
    }
}

/// Per-component statistics of all trajectories.
struct Stats {
    u: Vec<SignalStats>,
    x: Vec<SignalStats>,
    y: Vec<SignalStats>,
}

impl Stats {
    fn of(trajectories: &[VectorSequence<'_>]) -> Self {
        let d = trajectories[0].dims;
        fn u_of<'s>(t: &'s VectorSequence<'_>) -> &'s [f64] {
            t.u
        }
        fn x_of<'s>(t: &'s VectorSequence<'_>) -> &'s [f64] {
            t.x
        }
        fn y_of<'s>(t: &'s VectorSequence<'_>) -> &'s [f64] {
            t.y
        }
        let col =
            |pick: for<'s> fn(&'s VectorSequence<'_>) -> &'s [f64], width: usize, c: usize| {
                let values: Vec<f64> = trajectories
                    .iter()
                    .flat_map(|t| pick(t).iter().skip(c).step_by(width).copied())
                    .collect();
                SignalStats::of(values.iter())
            };
        Self {
            u: (0..d.inputs).map(|a| col(u_of, d.inputs, a)).collect(),
            x: (0..d.states).map(|i| col(x_of, d.states, i)).collect(),
            y: (0..d.sensors).map(|j| col(y_of, d.sensors, j)).collect(),
        }
    }
}

/// Transition rows `[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}, memory after u_{k-1}]` (row-major)
/// and their targets `x_k` (`dx` per row), for `k >= 2` of every trajectory.
pub fn transition_rows(trajectories: &[VectorSequence<'_>], plays: &Plays) -> (Vec<f64>, Vec<f64>) {
    let mut rows = Vec::new();
    let mut targets = Vec::new();
    let m = plays.len();
    for t in trajectories {
        let d = t.dims;
        let n = t.len();
        // Memory of each input after every sample.
        let mut mem: Vec<Vec<PlayState>> = Vec::with_capacity(d.inputs);
        for a in 0..d.inputs {
            let ua: Vec<f64> = t.u.iter().skip(a).step_by(d.inputs).copied().collect();
            let mut out = vec![[0.0; hbn_core::MAX_PLAYS]; n];
            plays.run(&ua, &mut out);
            mem.push(out);
        }
        for k in 2..n {
            rows.extend_from_slice(&t.x[(k - 1) * d.states..k * d.states]);
            rows.extend_from_slice(&t.x[(k - 2) * d.states..(k - 1) * d.states]);
            rows.extend_from_slice(&t.u[(k - 1) * d.inputs..k * d.inputs]);
            rows.extend_from_slice(&t.u[(k - 2) * d.inputs..(k - 1) * d.inputs]);
            for memory in &mem {
                rows.extend_from_slice(&memory[k - 1][..m]);
            }
            targets.extend_from_slice(&t.x[k * d.states..(k + 1) * d.states]);
        }
    }
    (rows, targets)
}

/// Sensor `j`'s rows `[x_{k-1}, y^j_{k-1}, x_k]` (or `[x_{k-1}, x_k]`) and targets `y^j_k`,
/// for `k >= 1` of every trajectory.
pub fn sensor_rows(
    trajectories: &[VectorSequence<'_>],
    j: usize,
    reads_output: bool,
) -> (Vec<f64>, Vec<f64>) {
    let mut rows = Vec::new();
    let mut targets = Vec::new();
    for t in trajectories {
        let d = t.dims;
        for k in 1..t.len() {
            rows.extend_from_slice(&t.x[(k - 1) * d.states..k * d.states]);
            if reads_output {
                rows.push(t.y[(k - 1) * d.sensors + j]);
            }
            rows.extend_from_slice(&t.x[k * d.states..(k + 1) * d.states]);
            targets.push(t.y[k * d.sensors + j]);
        }
    }
    (rows, targets)
}

#[cfg(test)]
mod tests {
    use super::*;
    use hbn_sim::{MultiConfig, MultiKind, simulate_multi_random};

    fn rows(signals: &[Vec<f64>]) -> Vec<f64> {
        let t = signals[0].len();
        (0..t)
            .flat_map(|k| signals.iter().map(move |s| s[k]))
            .collect()
    }

    /// The band's scale is the held-out 95% quantile of `|error| / std` over 2, however far
    /// the filter's own band is off (measured: up to 16 times too narrow without noise).
    #[test]
    fn the_band_scale_is_the_held_out_quantile_over_two() {
        // 100 values 0.3, 0.6, ..., 30: the 95% quantile (index 94) is 28.5.
        let z: Vec<f64> = (1..=100).map(|i| 0.3 * f64::from(i)).collect();
        assert!((calibration_scale(&z) - 14.25).abs() < 1e-12);
        let small: Vec<f64> = z.iter().map(|v| v / 100.0).collect();
        assert!((calibration_scale(&small) - 0.1425).abs() < 1e-12);
        assert_eq!(calibration_scale(&[]), 1.0);
        assert_eq!(calibration_scale(&[0.0; 5]), 1.0);
    }

    /// The lag sets trained: the primary, then the selection's, with the library's default
    /// selection standing for the vector default; each set once.
    #[test]
    fn lag_sets_are_the_primary_then_the_selection() {
        let d = HbnParams::default();
        assert_eq!(lag_sets(&d), [vec![], vec![0.1], vec![1.0]]);
        let mut p = d.clone();
        p.select.lags = vec![vec![0.5], vec![]];
        assert_eq!(lag_sets(&p), [vec![], vec![0.5]]);
        p.lags = vec![0.1];
        p.select.lags = Vec::new();
        assert_eq!(lag_sets(&p), [vec![0.1]]);
    }

    /// The candidates: each inducing setting (the primary, then the selection's) with each lag
    /// set; the library's default trains exact and 64-point sparse GPs with three lag sets.
    #[test]
    fn candidates_are_each_inducing_setting_with_each_lag_set() {
        let d = HbnParams::default();
        let sets = [vec![], vec![0.1], vec![1.0]];
        let expected: Vec<(Vec<f64>, Option<usize>)> = [None, Some(64)]
            .into_iter()
            .flat_map(|m| sets.iter().map(move |l| (l.clone(), m)))
            .collect();
        assert_eq!(candidates(&d), expected);
        assert_eq!(VectorModel::candidates(&d), expected);
        let nothing_held_out = HbnParams {
            validation: 0.0,
            ..d.clone()
        };
        assert_eq!(VectorModel::candidates(&nothing_held_out), [(vec![], None)]);
        let mut p = d.clone();
        p.n_inducing = Some(32);
        p.select.inducing = vec![Some(32), None];
        p.select.lags = Vec::new();
        assert_eq!(candidates(&p), [(vec![], Some(32)), (vec![], None)]);
        p.select.inducing.clear();
        assert_eq!(candidates(&p), [(vec![], Some(32))]);
    }

    /// Without held-out folds (every trajectory shorter than 80 samples) nothing could choose,
    /// so only the primary candidate trains.
    #[test]
    fn without_folds_only_the_primary_trains() {
        let (dims, u, x, y) = finger_rows(60);
        let seq = VectorSequence::new(&u, &x, &y, dims);
        let params = quick_params(40, 10);
        let model = VectorModel::fit_checked(&[seq], &params, SignalNames::default()).unwrap();
        assert!(model.summary().candidates.is_empty());
        assert_eq!(model.params().n_inducing, None);
        assert!(model.lags().is_empty());
    }

    /// A flash budget is refused with a message that says what to do instead, not ignored.
    #[test]
    fn a_flash_budget_is_refused() {
        let (dims, u, x, y) = finger_rows(120);
        let seq = VectorSequence::new(&u, &x, &y, dims);
        let params = HbnParams {
            firmware_budget: Some(64 * 1024),
            ..HbnParams::default()
        };
        match VectorModel::fit(&[seq], &params) {
            Err(ModelError::Config(e)) => {
                assert_eq!(e.param, Param::FirmwareBudget);
                assert!(e.to_string().contains("--inducing"), "{e}");
            }
            other => panic!("{:?}", other.map(|_| ())),
        }
    }

    /// A model file written before the candidates had inducing settings lists them under
    /// `lags`: they read as exact candidates.
    #[test]
    fn older_files_list_the_candidates_under_lags() {
        let text = r#"{"trajectories": 1, "samples": 400, "seconds": 2.0, "validation": [],
            "warnings": [], "unobservable": [0.0, 0.0],
            "lags": [{"lags": [0.1], "nlpd": -3.5, "nrmse": [0.02, 0.03], "seconds": 1.0,
                      "error": null, "chosen": true}]}"#;
        let s: VectorSummary = serde_json::from_str(text).unwrap();
        assert_eq!(s.candidates.len(), 1);
        let row = &s.candidates[0];
        assert_eq!((row.lags.as_slice(), row.n_inducing), (&[0.1][..], None));
        assert!(row.chosen);
    }

    /// The choice: the lowest held-out NLPD among the candidates no less accurate held out
    /// (mean nRMSE) than the primary; the primary when nothing beats it or it has no score.
    #[test]
    fn the_choice_follows_the_rule_of_model_selection() {
        let row = |nlpd: Option<f64>, nrmse: [f64; 2]| VectorCandidateRow {
            lags: Vec::new(),
            n_inducing: None,
            nlpd,
            nrmse: nrmse.to_vec(),
            seconds: 1.0,
            error: None,
            chosen: false,
        };
        let primary = row(Some(-4.0), [0.02, 0.04]);
        // Lower NLPD and as accurate: chosen.
        assert_eq!(
            choose_candidate(&[primary.clone(), row(Some(-4.5), [0.02, 0.04])]),
            1
        );
        // Lower NLPD but less accurate on average: not chosen.
        assert_eq!(
            choose_candidate(&[primary.clone(), row(Some(-4.5), [0.01, 0.06])]),
            0
        );
        // The lowest NLPD among the accurate ones, not the first.
        let rows = [
            primary.clone(),
            row(Some(-4.2), [0.02, 0.03]),
            row(Some(-4.6), [0.02, 0.03]),
            row(Some(-5.0), [0.05, 0.05]),
            row(None, [0.0, 0.0]),
        ];
        assert_eq!(choose_candidate(&rows), 2);
        assert_eq!(
            choose_candidate(&[row(None, [0.0; 2]), row(Some(-9.0), [0.0; 2])]),
            0
        );
    }

    /// A simulated finger run at noise gain 1, row-major: `(dims, u, x, y)`.
    fn finger_rows(steps: usize) -> (Dims, Vec<f64>, Vec<f64>, Vec<f64>) {
        let kind = MultiKind::Finger;
        let dims = Dims::new(kind.inputs(), kind.states(), kind.sensors()).unwrap();
        let mut cfg = MultiConfig::new(kind);
        cfg.noise_gain = 1.0;
        let run = simulate_multi_random(&cfg, steps).unwrap();
        (dims, rows(&run.u), rows(&run.x), rows(&run.y))
    }

    /// Defaults with a small support set and a short optimisation, checked.
    fn quick_params(max_points: usize, max_iters: u64) -> CheckedHbnParams {
        HbnParams {
            max_points,
            n_starts: 1,
            max_iters,
            ..HbnParams::default()
        }
        .check()
        .unwrap()
    }

    /// Sensor inputs given per sensor: only those variants are fitted (an EM refit, or
    /// `--sensor-inputs`, trains neither more nor less), and the model uses them.
    #[test]
    fn given_sensor_inputs_fit_only_those_variants() {
        let (dims, u, x, y) = finger_rows(300);
        let seq = VectorSequence::new(&u, &x, &y, dims);
        let params = quick_params(60, 20);
        let plays = Plays::with_lags(&params.memory, &[]).unwrap();
        let given = [true, false, true];
        let fit = VectorModel::fit_gps(&[seq], &params, &plays, None, &given, None).unwrap();
        let fitted: Vec<[bool; 2]> = fit
            .sensors
            .iter()
            .map(|[a, b]| [a.is_some(), b.is_some()])
            .collect();
        assert_eq!(fitted, [[true, false], [false, true], [true, false]]);
        assert!(fit.sensor(1, true).is_err() && fit.sensor(1, false).is_ok());
        let both = VectorModel::fit_gps(&[seq], &params, &plays, None, &[], None).unwrap();
        assert!(both.sensors.iter().all(|[a, b]| a.is_some() && b.is_some()));
        // The variants fitted alone are those fitted beside the others.
        for (j, reads) in given.iter().enumerate() {
            assert_eq!(
                fit.sensor(j, *reads).unwrap().hyperparameters(),
                both.sensor(j, *reads).unwrap().hyperparameters()
            );
        }
        let sensors = [
            SensorInputs::Thesis,
            SensorInputs::State,
            SensorInputs::Thesis,
        ];
        let model =
            VectorModel::fit_with_sensors(&[seq], &params, SignalNames::default(), &sensors)
                .unwrap();
        let reads: Vec<_> = (0..3).map(|j| model.sensor_reads_output(j)).collect();
        assert_eq!(reads, [Some(true), Some(false), Some(true)]);
        // A sensor with memory of the state is a scalar model's: refused, naming the setting.
        let e = VectorModel::fit_with_sensors(
            &[seq],
            &params,
            SignalNames::default(),
            &[SensorInputs::Memory],
        )
        .unwrap_err();
        assert!(
            matches!(&e, ModelError::Config(c) if c.param == Param::SensorInputs),
            "{e}"
        );
    }

    /// The candidates of one inducing setting share their sensor GPs ([`SharedSensors`]): the
    /// model chosen is the one its lag set and inducing setting train alone, held-out table,
    /// GPs and estimates bit for bit.
    #[test]
    fn candidates_share_their_sensor_gps() {
        let (dims, u, x, y) = finger_rows(400);
        let seq = VectorSequence::new(&u, &x, &y, dims);
        let params = quick_params(80, 30);
        let model =
            VectorModel::fit_with_sensors(&[seq], &params, SignalNames::default(), &[]).unwrap();
        let shapes: Vec<(Vec<f64>, Option<usize>)> = model
            .summary()
            .candidates
            .iter()
            .map(|r| (r.lags.clone(), r.n_inducing))
            .collect();
        assert_eq!(shapes, candidates(&params));
        assert_eq!(shapes.len(), 6);
        let chosen = model.params().clone().check().unwrap();
        let alone =
            VectorModel::fit_one(&[seq], &chosen, SignalNames::default(), &[], None).unwrap();
        assert_eq!(model.summary().validation, alone.summary().validation);
        let hypers = |m: &VectorModel| {
            let gps = m.transitions.iter().chain(&m.sensors);
            gps.map(|g| g.hyperparameters()).collect::<Vec<_>>()
        };
        assert_eq!(hypers(&model), hypers(&alone));
        let (a, b) = (
            model.estimate(&u, &y, model.mode).unwrap(),
            alone.estimate(&u, &y, alone.mode).unwrap(),
        );
        let bits = |v: &[f64]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&a.x), bits(&b.x));
        assert_eq!(bits(&a.x_std), bits(&b.x_std));
    }

    /// Given several kernels, each GP's kernel is chosen among them by evidence (the highest
    /// log marginal likelihood of the first fold's fit, one row per GP and kernel), and the
    /// model's GPs, refitted on every sample, keep the kernel chosen. By default, Matern 5/2
    /// and no choice.
    #[test]
    fn each_gp_takes_the_listed_kernel_with_the_highest_evidence() {
        let (dims, u, x, y) = finger_rows(300);
        let seq = VectorSequence::new(&u, &x, &y, dims);
        let base = HbnParams {
            lags: Vec::new(),
            select: crate::params::Selection::default(),
            ..(*quick_params(60, 20)).clone()
        };
        let spec = |k: KernelChoice, gp: &GaussianProcess| {
            let mut s = k.spec(gp.kernel().dim, [0, 0]);
            s.direction = None;
            s
        };
        let model = VectorModel::fit_checked(
            &[seq],
            &base.clone().check().unwrap(),
            SignalNames::default(),
        )
        .unwrap();
        assert!(model.summary().kernel_evidence.is_empty());
        let gp = model.transition(0).unwrap();
        assert_eq!(*gp.kernel(), spec(KernelChoice::MATERN52, gp));
        let mut listed = base;
        listed.select.kernels = vec![KernelChoice::SE_ARD];
        let params = listed.check().unwrap();
        let model = VectorModel::fit_checked(&[seq], &params, SignalNames::default()).unwrap();
        let rows = &model.summary().kernel_evidence;
        // Two transitions and both variants of three sensors.
        assert_eq!(rows.len(), (2 + 2 * 3) * 2);
        let mut seen_both = [false, false];
        for per_gp in rows.chunks(2) {
            assert!(per_gp.iter().all(|r| r.gp == per_gp[0].gp));
            assert_eq!(
                (per_gp[0].kernel, per_gp[1].kernel),
                (KernelChoice::MATERN52, KernelChoice::SE_ARD)
            );
            let chosen: Vec<_> = per_gp.iter().filter(|r| r.chosen).collect();
            assert_eq!(chosen.len(), 1, "{per_gp:?}");
            let best = per_gp.iter().filter_map(|r| r.lml).fold(f64::MIN, f64::max);
            assert_eq!(chosen[0].lml, Some(best));
            let gp = match per_gp[0].gp.strip_prefix("transition ") {
                Some(i) => model.transition(i.parse().unwrap()),
                None => {
                    let j: usize = per_gp[0].gp["sensor ".len()..][..1].parse().unwrap();
                    let reads = per_gp[0].gp.contains("own output");
                    (model.sensor_reads_output(j) == Some(reads))
                        .then(|| model.sensor(j))
                        .flatten()
                }
            };
            if let Some(gp) = gp {
                assert_eq!(*gp.kernel(), spec(chosen[0].kernel, gp), "{}", per_gp[0].gp);
            }
            seen_both[usize::from(chosen[0].kernel == KernelChoice::SE_ARD)] = true;
        }
        assert_eq!(seen_both, [true, true], "{rows:?}");
    }

    /// Trajectories of unequal lengths are a data error before anything is fitted or sliced,
    /// with the lag candidates (the default) as with one.
    #[test]
    fn unequal_lengths_are_a_data_error() {
        let (dims, u, x, y) = finger_rows(200);
        let seq = VectorSequence::new(&u, &x[..x.len() - 4], &y, dims);
        for lags in [vec![vec![1.0]], Vec::new()] {
            let mut p = HbnParams::default();
            p.select.lags = lags;
            let e = VectorModel::fit(&[seq], &p).unwrap_err();
            assert!(
                matches!(e, ModelError::Data(DataError::LengthMismatch { .. })),
                "{e}"
            );
        }
    }

    /// The held-out score reads the state only where the mask says it was measured: nonsense
    /// elsewhere changes nothing, and the mask changes what is scored.
    #[test]
    fn the_held_out_score_reads_measured_values_only() {
        let (dims, u, x, y) = finger_rows(400);
        let seq = VectorSequence::new(&u, &x, &y, dims);
        let params = quick_params(80, 30);
        let model = VectorModel::fit(&[seq], &params).unwrap();
        // The fold's GPs with the lag set the model chose.
        let chosen = model.params().clone().check().unwrap();
        let fit = VectorModel::fit_gps(&[seq], &chosen, &model.plays().unwrap(), None, &[], None)
            .unwrap();
        // Component 0 measured at every third sample, component 1 at every fifth.
        let mask: Vec<bool> = (0..x.len())
            .map(|j| {
                let (k, i) = (j / 2, j % 2);
                if i == 0 { k % 3 == 0 } else { k % 5 == 0 }
            })
            .collect();
        let nonsense: Vec<f64> = x
            .iter()
            .zip(&mask)
            .map(|(v, m)| if *m { *v } else { 1e3 })
            .collect();
        let score = |x: &[f64], mask: Option<&[bool]>| {
            let mut held = VectorSequence::new(&u, x, &y, dims);
            if let Some(m) = mask {
                held = held.with_observed(m);
            }
            model
                .held_out_score(&[&[held][..]], std::slice::from_ref(&fit))
                .unwrap()
        };
        let (a, b, all) = (
            score(&x, Some(&mask)),
            score(&nonsense, Some(&mask)),
            score(&x, None),
        );
        assert_eq!(a.nlpd, b.nlpd);
        assert_eq!(a.nrmse, b.nrmse);
        assert_eq!(a.normalised[0].len(), 134);
        assert_eq!(a.normalised[1].len(), 80);
        assert_eq!(all.normalised[0].len(), 400);
        assert!(a.nlpd.is_finite() && a.nlpd != all.nlpd);
        // A mask of the wrong length is refused.
        let short = vec![true; 10];
        let e = VectorSequence::new(&u, &x, &y, dims)
            .with_observed(&short)
            .validate(0)
            .unwrap_err();
        assert!(matches!(e, DataError::ObservedLength { .. }), "{e}");
    }
}
