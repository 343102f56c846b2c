//! The HBN model: both GPs, their local training data, the signals and the rate.

use crate::ModelError;
use crate::dataset::{Memory, Sequence, TRANSITION_DIM, TRANSITION_DIRECTION, build_dataset};
use crate::error::ModelFileProblem;
use crate::evidence::{KernelEvidence, Prefit};
use crate::local::LocalData;
use crate::params::{CheckedHbnParams, HbnParams, Signals};
use crate::tuning::FilterTuning;
use hbn_core::{EkfConfig, GpView, HbnView, InitPrior, Mode, Plays};
use hbn_gp::{FitProgress, GaussianProcess, Hyperparameters, Termination};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// Format tag of an HBN model file.
pub const MODEL_FORMAT: &str = "hbn-model";
/// The model file format version this build writes and reads. It changes only when a file of
/// the previous version would be read wrongly; fields added since carry serde defaults.
/// A file of another version is refused with [`ModelFileProblem::UnsupportedVersion`], whose
/// message says to retrain.
pub const MODEL_FORMAT_VERSION: u32 = 4;

/// One of the two GPs of the HBN.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum GpRole {
    /// `H_D`: `x_k` from `[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}]`.
    Transition,
    /// `H_S`: `y_k` from `[x_{k-1}, y_{k-1}, x_k]`.
    Sensor,
}

impl GpRole {
    /// Both GPs, transition first.
    pub const ALL: [GpRole; 2] = [GpRole::Transition, GpRole::Sensor];

    /// `transition` or `sensor`.
    pub const fn name(self) -> &'static str {
        match self {
            GpRole::Transition => "transition",
            GpRole::Sensor => "sensor",
        }
    }
}

impl std::fmt::Display for GpRole {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Range and moments of one training signal.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SignalStats {
    /// Minimum.
    pub min: f64,
    /// Maximum.
    pub max: f64,
    /// Mean.
    pub mean: f64,
    /// Variance.
    pub var: f64,
}

impl SignalStats {
    pub(crate) fn of<'a>(values: impl Iterator<Item = &'a f64> + Clone) -> Self {
        let n = values.clone().count().max(1) as f64;
        let (min, max) = values
            .clone()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
                (l.min(v), h.max(v))
            });
        let mean = values.clone().sum::<f64>() / n;
        let var = values.map(|v| (v - mean) * (v - mean)).sum::<f64>() / n;
        Self {
            min,
            max,
            mean,
            var,
        }
    }
    /// `max - min` (at least a tiny positive number).
    pub fn span(&self) -> f64 {
        (self.max - self.min).max(1e-12 * self.max.abs().max(1.0))
    }
}

/// One optimiser start of one GP.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StartSummary {
    /// Which GP.
    pub gp: GpRole,
    /// Start index (0 = from the default hyperparameters).
    pub start: usize,
    /// Log marginal likelihood reached (`None` if the start failed).
    pub lml: Option<f64>,
    /// Why the start stopped.
    pub termination: Termination,
}

impl TrainingSummary {
    /// Why each optimiser start of one GP stopped, in order.
    pub fn terminations(&self, role: GpRole) -> impl Iterator<Item = &Termination> {
        self.starts
            .iter()
            .filter(move |s| s.gp == role)
            .map(|s| &s.termination)
    }
}

/// What training did.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainingSummary {
    /// Trajectories used.
    pub trajectories: usize,
    /// Rows of each training set.
    pub rows: usize,
    /// Wall-clock seconds of this training run. Not saved, so that a model file depends only
    /// on its data and parameters (0 in a loaded model).
    #[serde(skip)]
    pub seconds: f64,
    /// Warnings from both GPs (jitter, subsets, failed starts) and the observability check.
    pub warnings: Vec<String>,
    /// Observability of the linearised filter along the first training trajectory.
    pub observability: Option<crate::ObservabilitySummary>,
    /// Every optimiser start of both GPs, in order: what it reached and why it stopped.
    #[serde(default)]
    pub starts: Vec<StartSummary>,
    /// Filter-aware training on held-out data (`None`: not tuned, e.g. `validation = 0` or
    /// too little data).
    #[serde(default)]
    pub validation: Option<crate::tuning::ValidationReport>,
    /// Each GP's evidence under every kernel it chose among ([`HbnParams::kernel_evidence`];
    /// empty when the kernels were set).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub kernel_evidence: Vec<KernelEvidence>,
    /// How much of the state was measured, and the rounds of expectation-maximisation over
    /// the rest ([`HysteresisModel::fit_latent`]); `None` when the state was measured at every
    /// sample.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latent: Option<crate::latent::LatentReport>,
}

/// The former name of [`HysteresisModel`].
#[deprecated(since = "0.2.0", note = "renamed to `HysteresisModel`")]
pub type HbnModel = HysteresisModel;

/// The trained Hysteresis Bayesian Network.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HysteresisModel {
    params: HbnParams,
    transition: GaussianProcess,
    sensor: GaussianProcess,
    transition_local: LocalData,
    sensor_local: LocalData,
    u_stats: SignalStats,
    x_stats: SignalStats,
    y_stats: SignalStats,
    /// Training `(y, x)` pairs sorted by `y` (then `x`), for initialising the filter.
    #[serde(default)]
    init_pairs: Vec<[f64; 2]>,
    /// Training pairs [`HysteresisModel::initial_state`] averages: [`INIT_NEIGHBOURS`], or fewer
    /// in the same proportion when a flash budget thinned `init_pairs`
    /// ([`HbnParams::firmware_budget`]).
    #[serde(default = "init_neighbours_default")]
    init_neighbours: usize,
    /// Noise scales per mode and the default mode, learned on held-out data.
    #[serde(default)]
    tuning: FilterTuning,
    /// Radii of the transition's play operators in the input's units
    /// ([`HbnParams::memory`] times the training input's range; empty in model files from
    /// before play operators existed).
    #[serde(default)]
    play_radii: Vec<f64>,
    /// Radii of the sensor's play operators of the state in the state's units
    /// ([`crate::SENSOR_MEMORY`] times the training state's range) for a sensor with memory
    /// ([`crate::SensorInputs::Memory`]); empty (and not written) for the others.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    sensor_memory_radii: Vec<f64>,
    summary: TrainingSummary,
}

/// Training samples consulted by [`HysteresisModel::initial_state`].
pub const INIT_NEIGHBOURS: usize = 50;

fn init_neighbours_default() -> usize {
    INIT_NEIGHBOURS
}

/// Training pairs the prior of `x_0` keeps under a flash budget of `budget` bytes: an eighth
/// of the budget at 8 bytes a pair (`f32`), at least 32.
pub fn init_pairs_for_budget(budget: u64) -> usize {
    usize::try_from(budget / 64).unwrap_or(usize::MAX).max(32)
}

/// `pairs` thinned to at most `keep` evenly spaced pairs of the sorted table, and the number
/// of neighbours scaled by the same factor, so that the prior spans about the same range of
/// `y` (the rule of `hbn export --init-pairs`).
fn thin_init_pairs(pairs: Vec<[f64; 2]>, keep: usize) -> (Vec<[f64; 2]>, usize) {
    let n = pairs.len();
    if keep >= n || keep == 0 {
        return (pairs, INIT_NEIGHBOURS);
    }
    let picked = (0..keep)
        .filter_map(|i| pairs.get((2 * i + 1) * n / (2 * keep)))
        .copied()
        .collect();
    (picked, ((INIT_NEIGHBOURS * keep + n / 2) / n).max(1))
}

/// A lower bound of the `f32` flash of sparse GPs with `m` inducing points and inputs of
/// `dims` (transition, sensor): per GP, the packed variance factor (`m (m + 1) / 2` reals),
/// the inducing points' features and the weights, 4 bytes each. The tables hold more (kernel,
/// settings, the prior of `x_0`), so a rung whose bound exceeds the budget is not trained.
fn sparse_flash_lower_bound(m: usize, dims: [usize; 2]) -> u64 {
    dims.iter()
        .map(|&d| 4 * (m * (m + 1) / 2 + m * d + m) as u64)
        .sum()
}

/// The outlier gate every trained model's filter ships with ([`EkfConfig::nis_gate`]): a
/// measurement whose normalised innovation squared exceeds 25 (5 standard deviations; a
/// Gaussian innovation does so once in 1.7 million samples) is down-weighted to that NIS.
pub const OUTLIER_GATE: f64 = 25.0;

#[derive(Serialize, Deserialize)]
struct ModelFile {
    format: String,
    version: u32,
    model: HysteresisModel,
}

/// Where a candidate's training starts ([`HysteresisModel::fit_candidates`]).
enum Start<'a> {
    /// From nothing: its GPs are fitted first.
    Fresh,
    /// From its GPs, already fitted on every run.
    Fitted(Box<HysteresisModel>),
    /// From the hyperparameters of the exact GPs (same kernels) that its sparse searches
    /// start from, those the caller has ([`ExactStart`]).
    FromExact(&'a ExactStart<'a>),
}

/// The optimum of the exact GP with the settings of `gp_params` (its sparse setting aside) on
/// `table`: where a sparse search with [`CheckedHbnParams`]'s exact start starts. `None` when it
/// cannot be fitted (the sparse search then makes its own starts).
fn exact_optimum(
    gp_params: &hbn_gp::GpParams,
    table: &crate::dataset::Table,
) -> Option<Hyperparameters> {
    let mut p = gp_params.clone();
    p.sparse = None;
    hbn_gp::fit(&p, &table.inputs, &table.targets)
        .ok()
        .map(|gp| gp.hyperparameters())
}

/// The optimum of the exact GPs a sparse search starts from ([`CheckedHbnParams`]'s exact start),
/// per GP, when the caller has them; a GP without one is fitted exactly first, as training
/// alone would.
#[derive(Clone, Debug, Default)]
pub(crate) struct ExactStart<'a> {
    /// The exact transition GP's hyperparameters (same inputs: kernel, plays and lags).
    pub transition: Option<Hyperparameters>,
    /// The exact sensor GP's hyperparameters (same kernel).
    pub sensor: Option<Hyperparameters>,
    /// Where the sparse sensor GP that starts from `sensor` is kept for the other candidates
    /// that fit the same one ([`SharedSensor`]).
    pub sensor_fit: Option<&'a SharedSensor>,
    /// The transition GP itself with its optimiser starts, fitted on the same runs with the
    /// same settings (for a candidate that differs from the first one in its sensor only):
    /// taken as it is.
    pub transition_fit: Option<&'a (GaussianProcess, Vec<StartSummary>)>,
}

/// A sparse sensor GP fitted once for every candidate that would fit the same one, with its
/// optimiser starts: the sparse candidates that start from the same exact GPs with the same
/// inducing setting and differ only in the transition's lags (the sensor reads no plays or
/// lags, so their data and settings are the same). `None` inside: the fit failed, and each
/// candidate fits it again to report its own error.
pub(crate) type SharedSensor = std::sync::OnceLock<Option<(GaussianProcess, Vec<StartSummary>)>>;

impl HysteresisModel {
    /// Learns both relations from trajectories at `params.rate_hz`: checks the parameters
    /// ([`HbnParams::check`]), then [`HysteresisModel::fit_checked`].
    pub fn fit(trajectories: &[Sequence<'_>], params: &HbnParams) -> Result<Self, ModelError> {
        let checked = params.clone().check()?;
        Self::fit_checked(trajectories, &checked, &mut |_, _| {})
    }

    /// Learns both relations with parameters checked beforehand, reporting each optimiser
    /// start to `observe` as `(which GP, progress)`.
    ///
    /// With `params.validation > 0` (the default) this is filter-aware training: after the GPs
    /// are fitted on every run, they are refitted on the training part of the runs with the
    /// hyperparameters found (no second search), and the filter's noise scales of every mode
    /// are learned on the held-out part ([`crate::tuning`]). The GPs of the returned model are
    /// those of `validation = 0`; the held-out table is in [`TrainingSummary::validation`].
    ///
    /// With alternatives in `params.select` ([`crate::Selection`]), every candidate
    /// configuration is trained and tuned this way on the same folds, and the one whose default
    /// mode has the lowest held-out NLPD among those at least as accurate held out (nRMSE) as
    /// the primary one is returned (`choose_candidate`); the table of candidates is in the
    /// validation report ([`crate::tuning::CandidateRow`]). A candidate that fails to train is
    /// reported there and skipped; training fails only when every candidate fails (with the
    /// first candidate's error).
    pub fn fit_checked(
        trajectories: &[Sequence<'_>],
        params: &CheckedHbnParams,
        observe: &mut dyn FnMut(GpRole, &FitProgress),
    ) -> Result<Self, ModelError> {
        let t0 = Instant::now();
        let chosen = crate::evidence::choose(trajectories, params)?;
        let mut model = match params.firmware_budget {
            Some(budget) => Self::fit_budgeted(
                trajectories,
                &chosen.params,
                &chosen.prefit,
                budget,
                observe,
            )?,
            None => Self::fit_selected(trajectories, &chosen.params, &chosen.prefit, observe)?,
        };
        model.summary.kernel_evidence = chosen.rows;
        model.summary.seconds = t0.elapsed().as_secs_f64();
        Ok(model)
    }

    /// [`Self::fit_checked`] with a flash budget ([`HbnParams::firmware_budget`]): sparse GPs
    /// with the most inducing points of [`crate::FIRMWARE_INDUCING_LADDER`] whose `f32` export
    /// fits `budget` bytes of flash in some mode, trained and tuned as usual (model selection
    /// among the sparse candidates; no exact ones), largest first, skipping the settings whose
    /// lower bound already exceeds the budget. The flash of a trained candidate is that of its
    /// export's tables ([`HysteresisModel::firmware_sizes`]). The default mode becomes the
    /// held-out best of the modes that fit.
    fn fit_budgeted(
        trajectories: &[Sequence<'_>],
        params: &CheckedHbnParams,
        prefit: &[Prefit],
        budget: u64,
        observe: &mut dyn FnMut(GpRole, &FitProgress),
    ) -> Result<Self, ModelError> {
        let dims = [params.transition_dim(), params.sensor_inputs.dim()];
        let ladder = crate::FIRMWARE_INDUCING_LADDER;
        let smallest = ladder[ladder.len() - 1];
        // The smallest flash of a trained rung that did not fit, for the error.
        let mut closest: Option<(usize, usize)> = None;
        for m in ladder {
            if m != smallest && sparse_flash_lower_bound(m, dims) > budget {
                continue;
            }
            let p = params.with_sparse_only(m);
            let mut model = Self::fit_selected(trajectories, &p, prefit, observe)?;
            let sizes = model.firmware_sizes(true)?;
            let fitting: Vec<Mode> = sizes
                .iter()
                .filter(|s| s.flash as u64 <= budget)
                .map(|s| s.mode)
                .collect();
            if fitting.is_empty() {
                let least = sizes.iter().map(|s| s.flash).min().unwrap_or(usize::MAX);
                if closest.is_none_or(|(_, f)| least < f) {
                    closest = Some((m, least));
                }
                // Fewer points were used than asked: every smaller rung above them is the
                // same model.
                continue;
            }
            if !fitting.contains(&model.default_mode()) {
                let best = model.summary.validation.as_ref().and_then(|v| {
                    v.rows
                        .iter()
                        .filter(|r| fitting.contains(&r.mode))
                        .min_by(|a, b| {
                            a.tuned
                                .calibration
                                .nlpd
                                .total_cmp(&b.tuned.calibration.nlpd)
                        })
                        .map(|r| r.mode)
                });
                let mode = best.unwrap_or(fitting[0]);
                model.tuning.default_mode = mode;
                if let Some(v) = model.summary.validation.as_mut() {
                    v.default_mode = mode;
                }
            }
            return Ok(model);
        }
        Err(ModelError::FirmwareBudget {
            budget,
            inducing: closest.map_or(smallest, |c| c.0),
            flash: closest.map_or(0, |c| c.1),
        })
    }

    /// [`Self::fit_checked`] once the kernels are chosen: the primary configuration, or model
    /// selection among the candidates. `prefit` holds the GPs the kernel choice fitted.
    fn fit_selected(
        trajectories: &[Sequence<'_>],
        params: &CheckedHbnParams,
        prefit: &[Prefit],
        observe: &mut dyn FnMut(GpRole, &FitProgress),
    ) -> Result<Self, ModelError> {
        let candidates = params.candidates();
        let selecting =
            candidates.len() > 1 && crate::tuning::split(trajectories, params.validation).is_some();
        if !selecting {
            let primary = params.for_candidate(&params.candidate());
            let mut model =
                Self::fit_tuned_from(trajectories, &primary, Start::Fresh, prefit, observe)?;
            // The default's alternatives (sparse GPs, a lag, the state-only sensor) are the
            // library's offer, not the user's request: with nothing held out they are dropped
            // silently (`validation = 0` says so, and too little data has its own warning
            // below). Alternatives the user listed are warned about.
            let offered = HbnParams::default().select;
            let listed = !params.select.kernels.is_empty()
                || params
                    .select
                    .inducing
                    .iter()
                    .any(|m| !offered.inducing.contains(m))
                || params.select.lags.iter().any(|l| !offered.lags.contains(l))
                || params
                    .select
                    .sensor_inputs
                    .iter()
                    .any(|s| !offered.sensor_inputs.contains(s));
            if candidates.len() > 1 && listed {
                let why = if params.validation > 0.0 {
                    format!(
                        "too little data to hold out {:.0}% for validation",
                        100.0 * params.validation
                    )
                } else {
                    "validation is 0, so nothing is held out".to_owned()
                };
                model.summary.warnings.push(format!(
                    "no model selection: {why}; the first of {} candidates ({}) trained",
                    candidates.len(),
                    params.candidate()
                ));
            }
            return Ok(model);
        }
        let mut rows = Vec::with_capacity(candidates.len());
        // Every scored candidate: (its row, held-out NLPD, held-out nRMSE, model).
        let mut scored_models: Vec<(usize, f64, f64, HysteresisModel)> = Vec::new();
        let mut first_error = None;
        // The first candidate trained, kept in case none can be scored.
        let mut fallback: Option<(usize, HysteresisModel)> = None;
        let trained = Self::fit_candidates(trajectories, params, &candidates, prefit, observe);
        for (candidate, (fitted, seconds)) in candidates.into_iter().zip(trained) {
            let (scored, note) = match fitted {
                Ok(model) => {
                    let scored = model.summary.validation.as_ref().and_then(|v| {
                        v.rows
                            .iter()
                            .find(|r| r.mode == v.default_mode)
                            .map(|r| (r.mode, r.tuned))
                    });
                    match scored {
                        Some((_, s)) if s.calibration.nlpd.is_finite() && s.nrmse.is_finite() => {
                            scored_models.push((rows.len(), s.calibration.nlpd, s.nrmse, model));
                            (scored, None)
                        }
                        _ => {
                            if fallback.is_none() {
                                fallback = Some((rows.len(), model));
                            }
                            (
                                None,
                                Some("the filter was not tuned on the held-out data".to_owned()),
                            )
                        }
                    }
                }
                Err(e) => {
                    let note = e.to_string();
                    first_error.get_or_insert(e);
                    (None, Some(note))
                }
            };
            rows.push(crate::tuning::CandidateRow {
                candidate,
                scored,
                seconds,
                note,
                chosen: false,
                lost: 0,
            });
        }
        // Each scored candidate's filter over its own training runs: a candidate that loses
        // the state there is not chosen while another does not (docs/tuning.md, "Candidates
        // that lose their own training runs"). With one scored candidate there is no choice.
        let lost: Vec<usize> = if scored_models.len() < 2 {
            vec![0; scored_models.len()]
        } else {
            std::thread::scope(|scope| {
                let jobs: Vec<_> = scored_models
                    .iter()
                    .map(|(_, _, _, model)| scope.spawn(|| model.relocalisations(trajectories)))
                    .collect();
                // A panic is a bug: it propagates, as it would without the threads.
                jobs.into_iter()
                    .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                    .collect()
            })
        };
        for (&(row, ..), &n) in scored_models.iter().zip(&lost) {
            if let Some(r) = rows.get_mut(row) {
                r.lost = n;
            }
        }
        let scores: Vec<Score> = scored_models
            .iter()
            .zip(&lost)
            .map(|(&(row, nlpd, nrmse, _), &lost)| Score {
                row,
                nlpd,
                nrmse,
                lost: lost > 0,
            })
            .collect();
        let best = choose_candidate(&scores).map(|i| {
            let (row, _, _, model) = scored_models.swap_remove(i);
            (row, model)
        });
        let (chosen, mut model) = match (best, fallback, first_error) {
            (Some(best), _, _) => best,
            (None, Some(first), _) => first,
            (None, None, Some(e)) => return Err(e),
            // Unreachable: every candidate either trains or fails, and there are several.
            (None, None, None) => return Err(ModelError::Data(crate::DataError::NoTrajectories)),
        };
        if let Some(row) = rows.get_mut(chosen) {
            row.chosen = true;
        }
        for row in &rows {
            if let Some(note) = &row.note {
                model
                    .summary
                    .warnings
                    .push(format!("candidate {} not scored: {note}", row.candidate));
            }
        }
        if let Some(v) = model.summary.validation.as_mut() {
            v.candidates = rows;
        }
        Ok(model)
    }

    /// Trains every candidate ([`Self::fit_tuned`]) and returns each one's result and wall
    /// seconds, in the order given. Each is deterministic, so the results do not depend on
    /// the thread count or on which runs when. Progress of the candidates that run after the
    /// first one's GPs reaches `observe` on this thread.
    ///
    /// When the first candidate has exact GPs and another has sparse GPs with the same
    /// kernels, the first one's GPs are fitted before those start: their searches start from
    /// exact optima ([`Self::fit_gps`], [`CheckedHbnParams`]'s exact start), which they would
    /// otherwise fit again. One with other lags starts from the first one's sensor GP (which
    /// does not read the lags) and from an exact transition GP with its own lags, fitted on
    /// a second thread meanwhile. A third thread trains the candidates that start from
    /// nothing (other kernels), one after the other, without progress reports. Then as many
    /// workers as the machine has cores take the rest (the first one's tuning, the warm
    /// candidates) from a queue, so that a core whose candidate finished goes on to the next.
    /// A candidate that differs from the first one in its sensor's inputs only is warm too:
    /// it takes the first one's transition GP as it is and fits its own sensor GP.
    fn fit_candidates(
        trajectories: &[Sequence<'_>],
        params: &CheckedHbnParams,
        candidates: &[crate::Candidate],
        prefit: &[Prefit],
        observe: &mut dyn FnMut(GpRole, &FitProgress),
    ) -> Vec<(Result<Self, ModelError>, f64)> {
        let threads = std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
            .max(1);
        let Some(first) = candidates.first() else {
            return Vec::new();
        };
        // A sparse candidate with the first one's kernels starts from exact GPs: the first
        // one's when its lags are the same; else the first one's sensor GP (which does not
        // read the lags) and an exact transition GP with its own lags.
        let warms = |c: &crate::Candidate| {
            first.n_inducing.is_none()
                && c.n_inducing.is_some()
                && (c.transition_kernel, c.sensor_kernel, c.sensor_inputs)
                    == (
                        first.transition_kernel,
                        first.sensor_kernel,
                        first.sensor_inputs,
                    )
        };
        // A candidate that differs from the first one in its sensor's inputs only fits the
        // first one's transition GP again: it takes that GP as it is.
        let same_transition = |c: &crate::Candidate| {
            c.sensor_inputs != first.sensor_inputs
                && crate::Candidate {
                    sensor_inputs: first.sensor_inputs,
                    ..c.clone()
                } == *first
        };
        let phase_one = candidates
            .iter()
            .skip(1)
            .any(|c| warms(c) || same_transition(c));
        // Trained beside the first one's GPs: the candidates that start from nothing, and
        // the exact transition GPs of the warm ones with other lags.
        let (fresh, other_lags): (Vec<usize>, Vec<usize>) = if phase_one {
            (
                (1..candidates.len())
                    .filter(|&i| !warms(&candidates[i]) && !same_transition(&candidates[i]))
                    .collect(),
                (1..candidates.len())
                    .filter(|&i| warms(&candidates[i]) && candidates[i].lags != first.lags)
                    .collect(),
            )
        } else {
            (Vec::new(), Vec::new())
        };
        let mut results: Vec<Option<(Result<Self, ModelError>, f64)>> =
            (0..candidates.len()).map(|_| None).collect();
        let timed = |i: usize,
                     start: Start<'_>,
                     before: f64,
                     observe: &mut dyn FnMut(GpRole, &FitProgress)| {
            let p = match start {
                Start::FromExact(e) if e.transition_fit.is_none() => {
                    params.starting_from_exact(&candidates[i])
                }
                _ => params.for_candidate(&candidates[i]),
            };
            let t = Instant::now();
            let fitted = Self::fit_tuned_from(trajectories, &p, start, prefit, observe);
            (i, (fitted, before + t.elapsed().as_secs_f64()))
        };
        // Progress of the candidates on other threads, passed on to `observe` on this one.
        let (tx, rx) = std::sync::mpsc::channel::<(GpRole, FitProgress)>();
        let report = |tx: &std::sync::mpsc::Sender<(GpRole, FitProgress)>| {
            let tx = tx.clone();
            move |role: GpRole, prog: &FitProgress| {
                // The receiver lives until every sender is gone.
                let _ = tx.send((role, prog.clone()));
            }
        };
        let done = std::thread::scope(|scope| {
            let side_transitions = (!other_lags.is_empty()).then(|| {
                scope.spawn(|| {
                    other_lags
                        .iter()
                        .map(|&i| {
                            let t = Instant::now();
                            let p = params.starting_from_exact(&candidates[i]);
                            let h = Self::exact_transition_optimum(trajectories, &p);
                            (i, h, t.elapsed().as_secs_f64())
                        })
                        .collect::<Vec<_>>()
                })
            });
            let side = (!fresh.is_empty()).then(|| {
                let mut progress = report(&tx);
                let (fresh, timed) = (&fresh, &timed);
                scope.spawn(move || {
                    fresh
                        .iter()
                        .map(|&i| timed(i, Start::Fresh, 0.0, &mut progress))
                        .collect::<Vec<_>>()
                })
            });
            // Phase one: the first candidate's GPs, when warm candidates start from them.
            let mut exact: Option<(Self, f64)> = None;
            let mut first_failed = None;
            if phase_one {
                let t = Instant::now();
                let p = params.for_candidate(first);
                let fitted = Self::memory_for(trajectories, &p).and_then(|memory| {
                    Self::fit_gps(trajectories, &p, &memory, None, None, prefit, observe)
                });
                let seconds = t.elapsed().as_secs_f64();
                match fitted {
                    Ok(model) => exact = Some((model, seconds)),
                    // The first candidate failed while fitting its GPs: that is its result.
                    Err(e) => first_failed = Some((Err(e), seconds)),
                }
            }
            // One sparse sensor GP per inducing setting of the warm candidates.
            let mut settings: Vec<Option<usize>> = Vec::new();
            for c in candidates.iter().filter(|c| warms(c)) {
                if !settings.contains(&c.n_inducing) {
                    settings.push(c.n_inducing);
                }
            }
            let cells: Vec<(Option<usize>, SharedSensor)> = settings
                .into_iter()
                .map(|m| (m, SharedSensor::new()))
                .collect();
            let cell = |c: &crate::Candidate| {
                cells
                    .iter()
                    .find(|(m, _)| *m == c.n_inducing)
                    .map(|(_, cell)| cell)
            };
            let start = ExactStart {
                transition: exact.as_ref().map(|(m, _)| m.transition.hyperparameters()),
                sensor: exact.as_ref().map(|(m, _)| m.sensor.hyperparameters()),
                sensor_fit: None,
                transition_fit: None,
            };
            let first_transition = exact.as_ref().map(|(m, _)| {
                let starts = m.summary.starts.iter();
                let own = starts.filter(|s| s.gp == GpRole::Transition).cloned();
                (m.transition.clone(), own.collect::<Vec<_>>())
            });
            let shared_transition = ExactStart {
                transition_fit: first_transition.as_ref(),
                ..ExactStart::default()
            };
            // A panic is a bug: it propagates, as it would without the threads.
            fn join<T>(h: std::thread::ScopedJoinHandle<'_, T>) -> T {
                h.join().unwrap_or_else(|e| std::panic::resume_unwind(e))
            }
            let other_transitions = side_transitions.map(join).unwrap_or_default();
            // Every warm candidate's start: the first one's exact GPs, or with other lags its
            // own exact transition GP (fitted beside them).
            let warm_starts: Vec<(usize, ExactStart<'_>, f64)> = (1..candidates.len())
                .filter(|&i| warms(&candidates[i]))
                .map(|i| {
                    let (transition, seconds) =
                        match other_transitions.iter().find(|(j, _, _)| *j == i) {
                            Some((_, h, seconds)) => (h.clone(), *seconds),
                            None => (start.transition.clone(), 0.0),
                        };
                    let warm = ExactStart {
                        transition,
                        sensor_fit: cell(&candidates[i]),
                        ..start.clone()
                    };
                    (i, warm, seconds)
                })
                .collect();
            let have_exact = exact.is_some();
            let mut todo: Vec<(usize, Start<'_>, f64)> = Vec::new();
            for (i, c) in candidates.iter().enumerate() {
                if fresh.contains(&i) || (i == 0 && first_failed.is_some()) {
                    continue;
                }
                let warm = warm_starts.iter().find(|(j, _, _)| *j == i);
                todo.push(match (exact.take_if(|_| i == 0), warm) {
                    (Some((model, seconds)), _) => (i, Start::Fitted(Box::new(model)), seconds),
                    (None, Some((_, start, seconds))) if have_exact && warms(c) => {
                        (i, Start::FromExact(start), *seconds)
                    }
                    (None, _) if have_exact && same_transition(c) => {
                        (i, Start::FromExact(&shared_transition), 0.0)
                    }
                    (None, _) => (i, Start::Fresh, 0.0),
                });
            }
            let n_jobs = todo.len();
            let queue = std::sync::Mutex::new(todo.into_iter());
            let mut done: Vec<_> = std::thread::scope(|inner| {
                let workers: Vec<_> = (0..threads.min(n_jobs))
                    .map(|_| {
                        let mut progress = report(&tx);
                        let (queue, timed) = (&queue, &timed);
                        inner.spawn(move || {
                            let mut finished = Vec::new();
                            // A poisoned lock means another worker panicked: that panic
                            // propagates below, so this worker just stops.
                            while let Some((i, start, before)) =
                                queue.lock().ok().and_then(|mut q| q.next())
                            {
                                finished.push(timed(i, start, before, &mut progress));
                            }
                            finished
                        })
                    })
                    .collect();
                // Every sender is gone once the workers and the side thread are done.
                drop(tx);
                for (role, prog) in rx {
                    observe(role, &prog);
                }
                workers.into_iter().flat_map(join).collect()
            });
            done.extend(side.into_iter().flat_map(join));
            done.extend(first_failed.map(|r| (0, r)));
            done
        });
        for (i, r) in done {
            results[i] = Some(r);
        }
        // Every candidate ran above (the fallback is never used).
        results
            .into_iter()
            .map(|r| r.unwrap_or((Err(ModelError::Data(crate::DataError::NoTrajectories)), 0.0)))
            .collect()
    }

    /// One configuration: its GPs fitted on every run, then (with `params.validation > 0`)
    /// refitted per fold and the filter tuned on the held-out blocks.
    #[cfg(test)]
    fn fit_tuned(
        trajectories: &[Sequence<'_>],
        params: &CheckedHbnParams,
        observe: &mut dyn FnMut(GpRole, &FitProgress),
    ) -> Result<Self, ModelError> {
        Self::fit_tuned_from(trajectories, params, Start::Fresh, &[], observe)
    }

    /// [`Self::fit_tuned`] from GPs already fitted, or with the exact GPs a sparse search
    /// starts from ([`Start`]).
    fn fit_tuned_from(
        trajectories: &[Sequence<'_>],
        params: &CheckedHbnParams,
        start: Start<'_>,
        prefit: &[Prefit],
        observe: &mut dyn FnMut(GpRole, &FitProgress),
    ) -> Result<Self, ModelError> {
        let memory = Self::memory_for(trajectories, params)?;
        let mut model = match start {
            Start::Fitted(model) => *model,
            Start::Fresh => {
                Self::fit_gps(trajectories, params, &memory, None, None, prefit, observe)?
            }
            Start::FromExact(exact) => Self::fit_gps(
                trajectories,
                params,
                &memory,
                None,
                Some(exact),
                prefit,
                observe,
            )?,
        };
        match crate::tuning::split(trajectories, params.validation) {
            Some(split) => {
                // Per fold, the GPs of its training part with the hyperparameters learned on
                // everything (no second search): the filter is tuned on data their posterior
                // never saw.
                let trials = split
                    .folds
                    .into_iter()
                    .map(|fold| {
                        let model = Self::fit_gps(
                            &fold.train,
                            params,
                            &memory,
                            Some((&model.transition, &model.sensor)),
                            None,
                            &[],
                            &mut |_, _| {},
                        )?;
                        Ok(crate::tuning::Trial {
                            model,
                            blocks: fold.validation,
                        })
                    })
                    .collect::<Result<Vec<_>, ModelError>>()?;
                match crate::tuning::tune(trials, &split.holdout)? {
                    Some((tuning, report)) => {
                        model.tuning = tuning;
                        model.summary.validation = Some(report);
                    }
                    None => model.summary.warnings.push(
                        "filter not tuned: the filter failed on the held-out data; default \
                         noise scales kept"
                            .to_owned(),
                    ),
                }
            }
            None if params.validation > 0.0 => model.summary.warnings.push(format!(
                "filter not tuned: too little data to hold out {:.0}% for validation (the \
                 held-out and the training part each need {} samples)",
                100.0 * params.validation,
                crate::tuning::MIN_TUNING_SAMPLES
            )),
            None => {}
        }
        Ok(model)
    }

    /// The memory operators of the rows (all of `trajectories`, so that the folds of
    /// filter-aware training share the radii): the play operators of `params.memory` on the
    /// input's range and the lags of `params.lags`; for a sensor with memory
    /// ([`crate::SensorInputs::Memory`]) the plays of [`crate::SENSOR_MEMORY`] on the state's
    /// range.
    pub(crate) fn memory_for(
        trajectories: &[Sequence<'_>],
        params: &CheckedHbnParams,
    ) -> Result<Memory, ModelError> {
        let lags = params.lag_coefficients()?;
        if params.memory.is_empty() && !params.sensor_inputs.has_memory() {
            return Ok(Memory::of_input(Plays::with_lags(&[], &lags)?));
        }
        for (i, t) in trajectories.iter().enumerate() {
            t.validate(i)?;
        }
        let radii = |fractions: &[f64], span: f64| -> Vec<f64> {
            fractions.iter().map(|f| f * span).collect()
        };
        let u_span = SignalStats::of(trajectories.iter().flat_map(|t| t.u.iter())).span();
        let state = if params.sensor_inputs.has_memory() {
            let x_span = SignalStats::of(trajectories.iter().flat_map(|t| t.x.iter())).span();
            Plays::new(&radii(&crate::SENSOR_MEMORY, x_span))?
        } else {
            Plays::NONE
        };
        Ok(Memory {
            input: Plays::with_lags(&radii(&params.memory, u_span), &lags)?,
            state,
        })
    }

    /// The exact transition GP's optimum with `params` ([`exact_optimum`]): what
    /// [`Self::fit_gps`] fits first for a sparse search that starts from it.
    fn exact_transition_optimum(
        trajectories: &[Sequence<'_>],
        params: &CheckedHbnParams,
    ) -> Option<Hyperparameters> {
        let memory = Self::memory_for(trajectories, params).ok()?;
        let data = build_dataset(trajectories, &memory).ok()?;
        let (spec, table) = Self::gp_problem(params, &memory.input, &data, GpRole::Transition);
        exact_optimum(&params.gp_params(spec, GpRole::Transition), &table)
    }

    /// What one GP learns: its kernel structure and its table (inputs, targets: levels or
    /// increments), from the dataset of `plays`. [`Self::fit_gps`] and the exact optimum a
    /// sparse search starts from ([`Self::exact_transition_optimum`]) read it here, so that
    /// the two fit the same problem.
    pub(crate) fn gp_problem(
        params: &CheckedHbnParams,
        plays: &Plays,
        data: &crate::dataset::Dataset,
        which: GpRole,
    ) -> (hbn_core::KernelSpec, crate::dataset::Table) {
        match which {
            GpRole::Transition => (
                params
                    .transition_kernel
                    .spec(TRANSITION_DIM + plays.len(), TRANSITION_DIRECTION),
                data.transition.clone(),
            ),
            GpRole::Sensor => (
                params
                    .sensor_kernel
                    .spec(params.sensor_inputs.dim(), params.sensor_inputs.direction()),
                data.sensor.columns(params.sensor_inputs.columns()),
            ),
        }
    }

    /// One GP on `table` with `gp_params`, every optimiser start reported to `observe` and kept.
    pub(crate) fn fit_gp(
        which: GpRole,
        gp_params: &hbn_gp::GpParams,
        table: &crate::dataset::Table,
        observe: &mut dyn FnMut(GpRole, &FitProgress),
    ) -> Result<(GaussianProcess, Vec<StartSummary>), ModelError> {
        let mut own = Vec::new();
        let mut gp = hbn_gp::fit_observed(gp_params, &table.inputs, &table.targets, &mut |p| {
            own.push(StartSummary {
                gp: which,
                start: p.start,
                lml: p.lml,
                termination: p.termination.clone(),
            });
            observe(which, &p);
        })
        .map_err(|source| ModelError::Gp { which, source })?;
        gp.forget_timing();
        Ok((gp, own))
    }

    /// Fits both GPs and the local data on `trajectories`; with `fixed`, every GP keeps the
    /// hyperparameters of the given one (no optimisation: a refit on more data, a fold's of
    /// filter-aware training, which also skips the observability diagnostic).
    ///
    /// With [`CheckedHbnParams`]'s exact start, a sparse GP's hyperparameter search starts from
    /// the optimum of the exact GP with the same settings (one start): `exact` (transition,
    /// sensor), when the caller has those GPs already (the primary candidate of model
    /// selection), else fitted here on the same data.
    #[allow(clippy::too_many_arguments)]
    fn fit_gps(
        trajectories: &[Sequence<'_>],
        params: &CheckedHbnParams,
        memory: &Memory,
        fixed: Option<(&GaussianProcess, &GaussianProcess)>,
        exact: Option<&ExactStart<'_>>,
        prefit: &[Prefit],
        observe: &mut dyn FnMut(GpRole, &FitProgress),
    ) -> Result<Self, ModelError> {
        let t0 = Instant::now();
        let data = build_dataset(trajectories, memory)?;
        let mut starts = Vec::new();
        let mut fit_gp = |which: GpRole| {
            let (spec, table) = Self::gp_problem(params, &memory.input, &data, which);
            let table = &table;
            let mut gp_params = params.gp_params(spec, which);
            if let Some(pair) = fixed {
                gp_params.init = Some(match which {
                    GpRole::Transition => pair.0.hyperparameters(),
                    GpRole::Sensor => pair.1.hyperparameters(),
                });
                gp_params.optimize = false;
            } else if gp_params.sparse.is_some() && params.starts_from_exact() {
                // The sparse GP's search starts from the exact GP's optimum on the subset
                // (`max_points`), one start: docs/sparse.md, "Where the search starts". An
                // exact GP that cannot be fitted leaves the sparse search its own starts.
                let given = exact.and_then(|e| match which {
                    GpRole::Transition => e.transition.clone(),
                    GpRole::Sensor => e.sensor.clone(),
                });
                let start = given.or_else(|| exact_optimum(&gp_params, table));
                if let Some(h) = start {
                    gp_params.init = Some(h);
                    gp_params.n_starts = 1;
                }
            }
            // The same transition GP, fitted already for another candidate.
            let given = exact
                .and_then(|e| e.transition_fit)
                .filter(|_| which == GpRole::Transition && fixed.is_none());
            if let Some((gp, own)) = given {
                starts.extend(own.iter().cloned());
                return Ok::<_, ModelError>(gp.clone());
            }
            let mut fit_one = || Self::fit_gp(which, &gp_params, table, observe);
            // A sparse sensor GP another candidate fits the same: fitted once.
            let shared = exact.and_then(|e| e.sensor_fit).filter(|_| {
                which == GpRole::Sensor && fixed.is_none() && gp_params.sparse.is_some()
            });
            // The GP the kernel choice by evidence fitted already (the same problem).
            let chosen =
                Prefit::matching(prefit, which, &gp_params, params).filter(|_| fixed.is_none());
            let (gp, own) = match (chosen, shared.map(|c| c.get_or_init(|| fit_one().ok()))) {
                (Some(p), _) => (p.gp.clone(), p.starts.clone()),
                (None, Some(Some((gp, own)))) => (gp.clone(), own.clone()),
                _ => fit_one()?,
            };
            starts.extend(own);
            Ok::<_, ModelError>(gp)
        };
        let transition = fit_gp(GpRole::Transition)?;
        let sensor = fit_gp(GpRole::Sensor)?;
        // The local regression of the transition reads the thesis' four inputs.
        let transition_local = LocalData::build(
            &data.transition.first_columns(TRANSITION_DIM),
            params.blr_window,
        )?;
        let sensor_local = LocalData::build(
            &data.sensor.columns(params.sensor_inputs.columns()),
            params.blr_window,
        )?;
        let cat = |f: fn(&Sequence<'_>) -> Vec<f64>| {
            trajectories.iter().flat_map(f).collect::<Vec<f64>>()
        };
        let (u_all, x_all, y_all) = (
            cat(|t| t.u.to_vec()),
            cat(|t| t.x.to_vec()),
            cat(|t| t.y.to_vec()),
        );
        let mut warnings = Vec::new();
        for (role, gp) in [(GpRole::Transition, &transition), (GpRole::Sensor, &sensor)] {
            warnings.extend(
                gp.report()
                    .warnings()
                    .into_iter()
                    .map(|w| format!("{role} GP: {w}")),
            );
        }
        let mut init_pairs: Vec<[f64; 2]> =
            y_all.iter().zip(&x_all).map(|(&y, &x)| [y, x]).collect();
        init_pairs.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
        let (init_pairs, init_neighbours) = match params.firmware_budget {
            Some(b) => thin_init_pairs(init_pairs, init_pairs_for_budget(b)),
            None => (init_pairs, INIT_NEIGHBOURS),
        };
        let mut model = Self {
            params: (**params).clone(),
            transition,
            sensor,
            transition_local,
            sensor_local,
            u_stats: SignalStats::of(u_all.iter()),
            x_stats: SignalStats::of(x_all.iter()),
            y_stats: SignalStats::of(y_all.iter()),
            init_pairs,
            init_neighbours,
            tuning: FilterTuning::default(),
            play_radii: memory.input.radii().to_vec(),
            sensor_memory_radii: memory.state.radii().to_vec(),
            summary: TrainingSummary {
                trajectories: trajectories.len(),
                rows: data.transition.len(),
                seconds: 0.0,
                warnings,
                observability: None,
                starts,
                validation: None,
                kernel_evidence: Vec::new(),
                latent: None,
            },
        };
        // Observability diagnostic (Sec. 4.2) along the first training trajectory. A fold's
        // refit (`fixed`) is only scored by the filter tuning and then dropped, so it skips
        // this filter run over a whole trajectory.
        if fixed.is_none() {
            let first = &trajectories[0];
            let run = model.estimate(first.u, first.y, Mode::Ekf)?;
            let obs = run.observability();
            if let Some(o) = obs
                && o.near_unobservable > 0.05
            {
                model.summary.warnings.push(format!(
                    "observability: {:.0}% of training samples are close to unobservable \
                     (lambda_min/lambda_max < {:e}); the sensor may not distinguish states there",
                    100.0 * o.near_unobservable,
                    crate::NEAR_UNOBSERVABLE
                ));
            }
            model.summary.observability = obs;
        }
        model.summary.seconds = t0.elapsed().as_secs_f64();
        Ok(model)
    }

    /// The borrowed view the allocation-free step reads (validates every array: build it
    /// once, not per step).
    pub fn view(&self) -> Result<HbnView<'_>, ModelError> {
        Ok(HbnView {
            transition: self.gp_view(GpRole::Transition)?,
            sensor: self.gp_view(GpRole::Sensor)?,
            transition_local: Some(self.transition_local.view()?),
            sensor_local: Some(self.sensor_local.view()?),
            blr: self.params.blr,
            init: self.init_prior()?,
            plays: self.plays()?,
            sensor_memory: self.sensor_memory()?,
        })
    }

    /// The sensor's play operators of the state ([`hbn_core::HbnView::sensor_memory`]):
    /// [`Plays::NONE`] unless the sensor has memory ([`crate::SensorInputs::Memory`]). An error
    /// when the radii disagree with the sensor's inputs (an edited model file).
    pub fn sensor_memory(&self) -> Result<Plays, ModelError> {
        let expected = if self.params.sensor_inputs.has_memory() {
            crate::SENSOR_MEMORY.len()
        } else {
            0
        };
        if self.sensor_memory_radii.len() != expected {
            return Err(ModelError::Core(hbn_core::CoreError::InvalidSpec(
                "the sensor's plays of the state (sensor_memory_radii) do not match its inputs \
                 (sensor_inputs)",
            )));
        }
        Ok(Plays::new(&self.sensor_memory_radii)?)
    }

    /// The transition's play operators ([`HbnParams::memory`] in the input's units) and lags
    /// ([`HbnParams::lags`] at the model's rate).
    pub fn plays(&self) -> Result<Plays, ModelError> {
        Ok(Plays::with_lags(
            &self.play_radii,
            &self.params.lag_coefficients()?,
        )?)
    }

    /// The borrowed predictor of one relation, in the signal's own units.
    pub fn gp_view(&self, role: GpRole) -> Result<GpView<'_>, ModelError> {
        Ok(self.gp(role).view()?)
    }

    /// The prior of `x_0` from the first measurement ([`InitPrior`] over the training pairs;
    /// `None` for a model file without them).
    fn init_prior(&self) -> Result<Option<InitPrior<'_>>, ModelError> {
        if self.init_pairs.is_empty() {
            return Ok(None);
        }
        let sx = self.x_stats.span();
        Ok(Some(InitPrior::new(
            &self.init_pairs,
            self.init_neighbours,
            1e-4 * sx * sx,
        )?))
    }

    /// Samples at which the filter, in the model's default mode with its tuned settings, lost
    /// the state and re-started from the measurement (flag `relocalised`), over
    /// `trajectories` (the runs the model was trained on, for model selection); a run the
    /// filter fails on counts once.
    pub(crate) fn relocalisations(&self, trajectories: &[Sequence<'_>]) -> usize {
        let config = self.ekf_config(self.default_mode());
        trajectories
            .iter()
            .map(|t| match self.estimate_with(t.u, t.y, &config) {
                Ok(est) => est
                    .flags
                    .iter()
                    .filter(|&&f| f & hbn_core::Flags::RELOCALISED != 0)
                    .count(),
                Err(_) => 1,
            })
            .sum()
    }

    /// Filter settings of `mode`: [`HysteresisModel::untuned_config`] with the noise scales learned
    /// on held-out data ([`HysteresisModel::tuning`]).
    pub fn ekf_config(&self, mode: Mode) -> EkfConfig {
        let mut c = self.untuned_config(mode);
        self.tuning.scales(mode).apply(&mut c);
        c
    }

    /// The mode estimation uses when none is asked for: the one with the best held-out score
    /// (the EKF for a model trained without validation).
    pub fn default_mode(&self) -> Mode {
        self.tuning.default_mode
    }

    /// Noise scales per mode and the default mode.
    pub fn tuning(&self) -> &FilterTuning {
        &self.tuning
    }

    /// Filter settings from the training ranges, at noise scale 1 (see `docs/ekf.md`).
    pub fn untuned_config(&self, mode: Mode) -> EkfConfig {
        let sx = self.x_stats.span();
        let sy = self.y_stats.span();
        EkfConfig {
            mode,
            q_floor: 1e-10 * sx * sx,
            r_floor: 1e-10 * sy * sy,
            qx_model_floor: self.transition.loo_error_variance(),
            r_model_floor: self.sensor.loo_error_variance(),
            p_min: 1e-14 * sx.min(sy).powi(2),
            p_max: 4.0 * sx.max(sy).powi(2),
            jac_max: 20.0 * (sy / sx).max(sx / sy).max(1.0),
            innovation_min: 1e-14 * sy * sy,
            nis_gate: OUTLIER_GATE,
            x_bounds: (self.x_stats.min - 0.1 * sx, self.x_stats.max + 0.1 * sx),
            y_bounds: (self.y_stats.min - 0.1 * sy, self.y_stats.max + 0.1 * sy),
            x0_mean: self.x_stats.mean,
            x0_var: self.x_stats.var.max(1e-12 * sx * sx),
            q_scale: 1.0,
            r_scale: 1.0,
            std_scale: 1.0,
        }
    }

    /// Prior of `x_0` from the first measurement: mean and variance of `x` over the
    /// [`INIT_NEIGHBOURS`] training samples whose `y` is nearest `y0` (ties by index), the
    /// variance at least `1e-4` of the squared training range of `x`. Hysteresis makes `x` given
    /// `y` ambiguous; the variance says how much. `None` without training pairs or for a
    /// non-finite `y0`. The filter's first step uses exactly this ([`hbn_core::InitPrior`]).
    pub fn initial_state(&self, y0: f64) -> Option<(f64, f64)> {
        self.init_prior().ok().flatten()?.prior(y0)
    }

    /// Training parameters (kernels, rate, signals, BLR settings).
    pub fn params(&self) -> &HbnParams {
        &self.params
    }
    /// Sample rate (Hz).
    pub fn rate_hz(&self) -> f64 {
        self.params.rate_hz
    }
    /// Signal names, paths and units.
    pub fn signals(&self) -> &Signals {
        &self.params.signals
    }
    /// One of the GPs.
    pub fn gp(&self, role: GpRole) -> &GaussianProcess {
        match role {
            GpRole::Transition => &self.transition,
            GpRole::Sensor => &self.sensor,
        }
    }
    /// Transition GP.
    pub fn transition(&self) -> &GaussianProcess {
        &self.transition
    }
    /// Sensor GP.
    pub fn sensor(&self) -> &GaussianProcess {
        &self.sensor
    }
    /// Local data of the transition (EKF+BLR).
    pub fn transition_local(&self) -> &LocalData {
        &self.transition_local
    }
    /// Local data of the sensor (EKF+BLR).
    pub fn sensor_local(&self) -> &LocalData {
        &self.sensor_local
    }
    /// Statistics of `u`, `x`, `y` in training.
    pub fn stats(&self) -> (SignalStats, SignalStats, SignalStats) {
        (self.u_stats, self.x_stats, self.y_stats)
    }
    /// What training did.
    pub(crate) fn summary_mut(&mut self) -> &mut TrainingSummary {
        &mut self.summary
    }

    /// What training did.
    pub fn summary(&self) -> &TrainingSummary {
        &self.summary
    }

    /// JSON with format tag and version (exact float round trip). The same model gives the
    /// same bytes: nothing in it depends on the clock.
    pub fn to_json(&self) -> Result<String, ModelError> {
        serde_json::to_string(&ModelFile {
            format: MODEL_FORMAT.into(),
            version: MODEL_FORMAT_VERSION,
            model: self.clone(),
        })
        .map_err(|e| ModelError::ModelFile {
            path: "<memory>".into(),
            problem: ModelFileProblem::Malformed {
                detail: e.to_string(),
            },
        })
    }

    /// Parses [`HysteresisModel::to_json`] output, checking tag, version and consistency. `origin`
    /// names the source in errors.
    pub fn from_json(text: &str, origin: &str) -> Result<Self, ModelError> {
        let fail = |problem| ModelError::ModelFile {
            path: origin.into(),
            problem,
        };
        let value: serde_json::Value =
            serde_json::from_str(text).map_err(|_| fail(ModelFileProblem::NotJson))?;
        let tag = value.get("format").and_then(|v| v.as_str()).unwrap_or("");
        if tag != MODEL_FORMAT {
            return Err(fail(ModelFileProblem::WrongFormat { tag: tag.into() }));
        }
        let version = value.get("version").and_then(|v| v.as_u64()).unwrap_or(0);
        if version != u64::from(MODEL_FORMAT_VERSION) {
            return Err(fail(ModelFileProblem::UnsupportedVersion { version }));
        }
        let mut file: ModelFile = serde_json::from_value(value).map_err(|e| {
            fail(ModelFileProblem::Malformed {
                detail: e.to_string(),
            })
        })?;
        for gp in [&mut file.model.transition, &mut file.model.sensor] {
            gp.restore_factor().map_err(|e| {
                fail(ModelFileProblem::Malformed {
                    detail: format!("the GP's factor cannot be recomputed: {e}"),
                })
            })?;
        }
        file.model.view().map_err(|e| match e {
            ModelError::Core(c) => fail(ModelFileProblem::Inconsistent(c)),
            other => other,
        })?;
        Ok(file.model)
    }

    /// Writes the model atomically ([`hbn_fs::write_atomic`]).
    pub fn save(&self, path: &Path) -> Result<(), ModelError> {
        Ok(hbn_fs::write_atomic(path, self.to_json()?.as_bytes())?)
    }

    /// Loads a model written by [`HysteresisModel::save`].
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
}

/// Model selection's rule, over the scored candidates ([`Score`]) in training order (row 0 is
/// the primary configuration). First, while any candidate's filter follows its own training
/// runs without losing the state, those that lose it are left out (measured on fresh seeds: a
/// sparse candidate with the best held-out score that lost the state three times on its
/// training runs was 12x less accurate on the test log than the exact one; in another run the
/// exact one lost it, and was 3.8x less accurate). Then the lowest NLPD among the
/// candidates whose nRMSE is no higher than the primary's, so an alternative must be at least
/// as accurate as the primary to replace it, not only better calibrated. The NLPD rewards a
/// wider, honest band as well as a closer estimate, and the estimate is the product (measured:
/// a sparse candidate with held-out NLPD -2.50 against the exact one's -2.40, but nRMSE 0.0295
/// against 0.0257, was 25% less accurate on the test log). Without a scored primary: the
/// lowest NLPD. Ties go to the earlier row. Returns the chosen entry's index in `scored`;
/// `None` when nothing was scored.
pub(crate) fn choose_candidate(scored: &[Score]) -> Option<usize> {
    // Those that lost the state on their own training runs are left out while another did
    // not; a primary left out counts as unscored (no accuracy bar for the rest).
    let any_kept = scored.iter().any(|s| !s.lost);
    let kept = |s: &Score| !(any_kept && s.lost);
    let primary_nrmse = scored
        .iter()
        .find(|s| s.row == 0 && kept(s))
        .map_or(f64::INFINITY, |s| s.nrmse);
    scored
        .iter()
        .enumerate()
        .filter(|(_, s)| kept(s) && s.nrmse <= primary_nrmse)
        .min_by(|(_, a), (_, b)| a.nlpd.total_cmp(&b.nlpd).then(a.row.cmp(&b.row)))
        .map(|(i, _)| i)
}

/// A scored candidate as model selection sees it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Score {
    /// Its row in the candidate table (0: the primary).
    pub row: usize,
    /// Held-out NLPD of its default mode.
    pub nlpd: f64,
    /// Held-out nRMSE of its default mode.
    pub nrmse: f64,
    /// Whether its filter lost the state on its own training runs.
    pub lost: bool,
}

#[cfg(test)]
mod selection_tests {
    use super::{Score, choose_candidate};

    /// `choose_candidate` over `(row, NLPD, nRMSE)` entries, none of which lost the state.
    fn choose(rows: &[(usize, f64, f64)]) -> Option<usize> {
        choose_lost(
            &rows
                .iter()
                .map(|&(r, l, n)| (r, l, n, false))
                .collect::<Vec<_>>(),
        )
    }

    /// `choose_candidate` over `(row, NLPD, nRMSE, lost)` entries.
    fn choose_lost(rows: &[(usize, f64, f64, bool)]) -> Option<usize> {
        let scores: Vec<Score> = rows
            .iter()
            .map(|&(row, nlpd, nrmse, lost)| Score {
                row,
                nlpd,
                nrmse,
                lost,
            })
            .collect();
        choose_candidate(&scores)
    }

    #[test]
    fn an_alternative_must_be_as_accurate_as_the_primary() {
        // The lower NLPD wins when it is at least as accurate ...
        assert_eq!(choose(&[(0, -2.4, 0.026), (1, -2.5, 0.025)]), Some(1));
        assert_eq!(choose(&[(0, -2.4, 0.026), (1, -2.5, 0.026)]), Some(1));
        // ... not when it is only better calibrated (the measured case).
        assert_eq!(choose(&[(0, -2.399, 0.0257), (1, -2.498, 0.0295)]), Some(0));
        // The primary keeps a lower NLPD.
        assert_eq!(choose(&[(0, -2.6, 0.030), (1, -2.5, 0.020)]), Some(0));
        // Among several eligible alternatives the lowest NLPD; an ineligible one is skipped.
        let rows = [
            (0, -2.0, 0.03),
            (1, -2.9, 0.04),
            (2, -2.2, 0.02),
            (3, -2.4, 0.03),
        ];
        assert_eq!(choose(&rows), Some(3));
        // A primary that could not be scored: the lowest NLPD of the rest (the index in the
        // slice: entry 1, row 2).
        assert_eq!(choose(&[(1, -2.0, 0.03), (2, -2.2, 0.05)]), Some(1));
        assert_eq!(choose(&[]), None);
        // Ties go to the earlier candidate.
        assert_eq!(choose(&[(0, -2.5, 0.02), (1, -2.5, 0.02)]), Some(0));
    }

    #[test]
    fn a_candidate_that_loses_its_training_runs_is_left_out_while_another_does_not() {
        // The best held-out scores, but lost on its training runs: the primary is kept.
        assert_eq!(
            choose_lost(&[(0, -3.46, 0.0205, false), (1, -3.61, 0.0125, true)]),
            Some(0)
        );
        // A lost primary counts as unscored: the best of the rest, with no accuracy bar.
        assert_eq!(
            choose_lost(&[
                (0, -3.0, 0.020, true),
                (1, -2.8, 0.030, false),
                (2, -2.9, 0.025, false)
            ]),
            Some(2)
        );
        // All lost: the rule as without the check.
        assert_eq!(
            choose_lost(&[(0, -2.4, 0.026, true), (1, -2.5, 0.025, true)]),
            Some(1)
        );
        assert_eq!(
            choose_lost(&[(0, -2.4, 0.026, true), (1, -2.5, 0.030, true)]),
            Some(0)
        );
    }
}

#[cfg(test)]
mod sparse_start_tests {
    use super::*;
    use crate::params::{HbnParams, Selection};
    use hbn_sim::{SimConfig, Simulator, SystemKind};

    /// Two runs of Duhem under slow triangles of different heights.
    fn runs() -> Vec<(Vec<f64>, Vec<f64>, Vec<f64>)> {
        [0.8, 0.6]
            .iter()
            .map(|&top| {
                let mut robot = Simulator::new(&SimConfig::new(SystemKind::Duhem)).unwrap();
                let u: Vec<f64> = (0..300)
                    .map(|k| top * (1.0 - ((k % 100) as f64 / 50.0 - 1.0).abs()))
                    .collect();
                let (x, y): (Vec<f64>, Vec<f64>) =
                    u.iter().map(|&v| robot.step(v).unwrap()).unzip();
                (u, x, y)
            })
            .collect()
    }

    /// Small, quick parameters choosing between exact GPs and 16 inducing points, with the
    /// lag sets `lags` tried besides.
    fn small_selection(lags: Vec<Vec<f64>>) -> CheckedHbnParams {
        HbnParams {
            max_points: 60,
            n_starts: 2,
            max_iters: 30,
            select: Selection {
                kernels: Vec::new(),
                inducing: vec![Some(16)],
                lags,
                sensor_inputs: Vec::new(),
            },
            ..HbnParams::default()
        }
        .check()
        .unwrap()
    }

    fn sequences(data: &[(Vec<f64>, Vec<f64>, Vec<f64>)]) -> Vec<Sequence<'_>> {
        data.iter()
            .map(|(u, x, y)| Sequence::new(u, x, y))
            .collect()
    }

    #[test]
    fn a_sparse_candidate_starts_from_the_primary_exact_gps_as_it_would_alone() {
        let data = runs();
        let seqs = sequences(&data);
        let params = small_selection(Vec::new());
        let candidates = params.candidates();
        assert_eq!(candidates.len(), 2);
        let trained =
            HysteresisModel::fit_candidates(&seqs, &params, &candidates, &[], &mut |_, _| {});
        let sparse = trained[1].0.as_ref().unwrap();
        for gp in [&sparse.transition, &sparse.sensor] {
            assert_eq!(
                gp.report().starts.len(),
                1,
                "one start, from the exact optimum"
            );
        }
        // From its recorded parameters alone (the exact GPs fitted again) it is the same
        // model, bit for bit: what a model file says it was trained with reproduces it.
        let alone = HysteresisModel::fit_tuned(
            &seqs,
            &params.starting_from_exact(&candidates[1]),
            &mut |_, _| {},
        )
        .unwrap();
        assert_eq!(sparse.to_json().unwrap(), alone.to_json().unwrap());
        // Without the setting, the sparse searches make their own starts: another model.
        let own = HysteresisModel::fit_tuned(
            &seqs,
            &params.for_candidate(&candidates[1]),
            &mut |_, _| {},
        )
        .unwrap();
        assert_eq!(own.transition.report().starts.len(), 2);
        assert_ne!(own.to_json().unwrap(), alone.to_json().unwrap());
    }

    /// A candidate with a sensor of the state only takes the first candidate's transition GP
    /// (its starts too) instead of fitting it again, fits its own two-input sensor GP, and is
    /// the model its recorded parameters train alone, bit for bit.
    #[test]
    fn a_state_sensor_candidate_shares_the_transition_and_is_the_model_its_parameters_train() {
        let data = runs();
        let seqs = sequences(&data);
        let mut params = small_selection(Vec::new()).into_inner();
        params.select.sensor_inputs = vec![crate::SensorInputs::State];
        let params = params.check().unwrap();
        let candidates = params.candidates();
        assert_eq!(candidates.len(), 3);
        assert_eq!(
            (candidates[2].n_inducing, candidates[2].sensor_inputs),
            (None, crate::SensorInputs::State)
        );
        assert_eq!(candidates[2].to_string(), "matern52 exact sensor=state");
        let mut events = [0usize; 2];
        let trained =
            HysteresisModel::fit_candidates(&seqs, &params, &candidates, &[], &mut |role, _| {
                events[usize::from(role == GpRole::Sensor)] += 1;
            });
        // Transition: the first candidate's two starts and the sparse one's one; none for
        // the state sensor's candidate. Sensor: two, one, and the state sensor's two.
        assert_eq!(events, [3, 5]);
        let state = trained[2].0.as_ref().unwrap();
        let first = trained[0].0.as_ref().unwrap();
        assert_eq!(state.params().sensor_inputs, crate::SensorInputs::State);
        assert_eq!(state.sensor.kernel().dim, 2);
        assert_eq!(state.sensor_local.view().unwrap().dim(), 2);
        assert_eq!(
            serde_json::to_string(&state.transition).unwrap(),
            serde_json::to_string(&first.transition).unwrap()
        );
        assert_ne!(
            serde_json::to_string(&state.sensor).unwrap(),
            serde_json::to_string(&first.sensor).unwrap()
        );
        let alone = HysteresisModel::fit_tuned(
            &seqs,
            &params.for_candidate(&candidates[2]),
            &mut |_, _| {},
        )
        .unwrap();
        assert_eq!(state.to_json().unwrap(), alone.to_json().unwrap());
        // Every mode runs on it, and the model file reads back as the same model.
        for mode in Mode::ALL {
            let run = state.estimate(&data[0].0, &data[0].2, mode).unwrap();
            assert!(run.x.iter().all(|v| v.is_finite()), "{mode:?}");
        }
        let back = HysteresisModel::from_json(&state.to_json().unwrap(), "test").unwrap();
        assert_eq!(back.to_json().unwrap(), state.to_json().unwrap());
        assert_eq!(back.view().unwrap().sensor.dim(), 2);
    }

    /// What model selection counts: a filter that follows its training runs loses the state
    /// nowhere; driven by an input ten times its training range, it loses it and the count
    /// says so.
    #[test]
    fn relocalisations_count_where_the_filter_lost_the_state() {
        let data = runs();
        let seqs = sequences(&data);
        let params = HbnParams {
            max_points: 60,
            n_starts: 1,
            max_iters: 30,
            select: Selection::default(),
            kernel_evidence: Vec::new(),
            validation: 0.0,
            ..HbnParams::default()
        }
        .check()
        .unwrap();
        let model = HysteresisModel::fit_tuned(&seqs, &params, &mut |_, _| {}).unwrap();
        assert_eq!(model.relocalisations(&seqs), 0);
        let (u, x, y) = &data[0];
        let far: Vec<f64> = u.iter().map(|v| 10.0 * v).collect();
        let lost = model.relocalisations(&[Sequence::new(&far, x, y)]);
        assert!(lost > 0, "{lost}");
    }

    #[test]
    fn a_lag_candidate_starts_from_exact_gps_and_is_the_model_its_parameters_train() {
        let data = runs();
        let seqs = sequences(&data);
        let params = small_selection(vec![vec![0.5]]);
        let candidates = params.candidates();
        assert_eq!(candidates.len(), 3);
        assert_eq!(
            (candidates[2].n_inducing, candidates[2].lags.as_slice()),
            (Some(16), &[0.5][..])
        );
        let mut sensor_events = 0;
        let trained =
            HysteresisModel::fit_candidates(&seqs, &params, &candidates, &[], &mut |role, _| {
                sensor_events += usize::from(role == GpRole::Sensor);
            });
        // The sensor's searches: the first candidate's two starts, and one start for the
        // sparse sensor GP, which both sparse candidates fit the same and which is fitted once.
        assert_eq!(sensor_events, 3);
        let with_lag = trained[2].0.as_ref().unwrap();
        assert_eq!(with_lag.params().lags, vec![0.5]);
        assert_eq!(
            with_lag.transition.kernel().dim,
            TRANSITION_DIM + with_lag.params().memory.len() + 1,
            "the transition reads the lag"
        );
        // One start per GP: from the first candidate's exact sensor GP and from an exact
        // transition GP with the lag, fitted beside the first one's. Its recorded parameters
        // train the same model alone (both exact GPs fitted first).
        for gp in [&with_lag.transition, &with_lag.sensor] {
            assert_eq!(gp.report().starts.len(), 1);
        }
        let alone = HysteresisModel::fit_tuned(
            &seqs,
            &params.starting_from_exact(&candidates[2]),
            &mut |_, _| {},
        )
        .unwrap();
        assert_eq!(with_lag.to_json().unwrap(), alone.to_json().unwrap());
        // Its sensor GP, which does not read the lags, is the other sparse candidate's.
        let sparse = trained[1].0.as_ref().unwrap();
        assert_eq!(
            serde_json::to_string(&with_lag.sensor).unwrap(),
            serde_json::to_string(&sparse.sensor).unwrap()
        );
        // The other two are as they are without the lag candidate.
        let without = small_selection(Vec::new());
        let before = HysteresisModel::fit_candidates(
            &seqs,
            &without,
            &without.candidates(),
            &[],
            &mut |_, _| {},
        );
        for i in 0..2 {
            assert_eq!(
                trained[i].0.as_ref().unwrap().to_json().unwrap(),
                before[i].0.as_ref().unwrap().to_json().unwrap()
            );
        }
    }

    #[test]
    fn the_sparse_search_from_the_exact_optimum_ends_above_the_bounds_rounding_noise() {
        // The README demo's data: one random-ramp input (seed 1), three logs with noise seeds
        // 11, 12 and 13. The sparse bound's value carries rounding noise of about 1e-8 of
        // itself (8e-5 nats on these 3000 samples); a tolerance below that noise lets the line
        // searches near the optimum go on for dozens of evaluations that change the bound only
        // in its noise (about 150 evaluations here, against about 95).
        use hbn_sim::{
            DEFAULT_MAX_INCREMENT, InputKind, SimConfig, SystemKind, generate_input, simulate,
        };
        let u = generate_input(InputKind::RandomRamps, 1000, DEFAULT_MAX_INCREMENT, 1).unwrap();
        let logs: Vec<_> = [11, 12, 13]
            .iter()
            .map(|&seed| {
                let cfg = SimConfig {
                    seed,
                    ..SimConfig::new(SystemKind::BoucWen)
                };
                simulate(&cfg, &u).unwrap()
            })
            .collect();
        let seqs: Vec<Sequence<'_>> = logs
            .iter()
            .map(|t| Sequence::new(&t.u, &t.x, &t.y))
            .collect();
        // The model selection's sparse candidate: m = 64, its search started from the exact
        // GPs' optimum.
        let params = HbnParams {
            validation: 0.0,
            n_inducing: Some(64),
            select: crate::Selection::default(),
            ..HbnParams::default()
        }
        .check()
        .unwrap();
        let params = params.starting_from_exact(&params.candidate());
        let model = HysteresisModel::fit_tuned(&seqs, &params, &mut |_, _| {}).unwrap();
        let report = model.transition().report();
        assert_eq!(report.starts.len(), 1, "one start, from the exact optimum");
        assert!(
            report.evaluations < 120,
            "{} evaluations: the search went on in the bound's rounding noise",
            report.evaluations
        );
    }
}

#[cfg(test)]
mod budget_tests {
    use super::*;
    use crate::params::HbnParams;
    use hbn_sim::{SimConfig, Simulator, SystemKind};

    fn run(n: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let mut robot = Simulator::new(&SimConfig::new(SystemKind::Duhem)).unwrap();
        let u: Vec<f64> = (0..n)
            .map(|k| {
                0.8 * (1.0 - ((k % 150) as f64 / 75.0 - 1.0).abs())
                    * (1.0 - (k / 150 % 3) as f64 * 0.2)
            })
            .collect();
        let (x, y): (Vec<f64>, Vec<f64>) = u.iter().map(|&v| robot.step(v).unwrap()).unzip();
        (u, x, y)
    }

    /// A budget trains sparse GPs, a thinned prior of `x_0` and a default mode whose `f32`
    /// tables fit; the budget is kept in the model file.
    #[test]
    fn a_flash_budget_trains_what_fits() {
        let (u, x, y) = run(900);
        let budget = 16 * 1024;
        let params = HbnParams {
            n_starts: 1,
            max_iters: 40,
            firmware_budget: Some(budget),
            ..HbnParams::default()
        };
        let model = HysteresisModel::fit(&[Sequence::new(&u, &x, &y)], &params).unwrap();
        assert!(model.transition().is_sparse() && model.sensor().is_sparse());
        assert!(model.init_pairs.len() <= init_pairs_for_budget(budget));
        assert!(model.init_neighbours < INIT_NEIGHBOURS);
        let sizes = model.firmware_sizes(true).unwrap();
        let default = sizes
            .iter()
            .find(|s| s.mode == model.default_mode())
            .unwrap();
        assert!(default.flash as u64 <= budget, "{sizes:?}");
        assert!(default.ram > 0);
        // The lower bound that skips rungs is below the real size.
        let dims = [params.transition_dim(), 3];
        let m = model
            .transition()
            .n_support()
            .max(model.sensor().n_support());
        assert!(
            sparse_flash_lower_bound(m, dims) as usize <= default.flash,
            "{sizes:?}"
        );
        let back = HysteresisModel::from_json(&model.to_json().unwrap(), "test").unwrap();
        assert_eq!(back.params().firmware_budget, Some(budget));
        assert_eq!(back.init_neighbours, model.init_neighbours);
        assert_eq!(back.firmware_sizes(true).unwrap(), sizes);
        // A budget nothing fits: an error that says what the smallest needs.
        let tiny = HbnParams {
            firmware_budget: Some(1024),
            ..params
        };
        let e = HysteresisModel::fit(&[Sequence::new(&u, &x, &y)], &tiny).unwrap_err();
        assert!(
            matches!(e, ModelError::FirmwareBudget { budget: 1024, .. }),
            "{e}"
        );
    }

    #[test]
    fn thinning_keeps_evenly_spaced_pairs_and_scales_the_neighbours() {
        let pairs: Vec<[f64; 2]> = (0..1000).map(|i| [i as f64, 0.0]).collect();
        let (kept, k) = thin_init_pairs(pairs.clone(), 100);
        assert_eq!(kept.len(), 100);
        assert_eq!(kept[0][0], 5.0);
        assert_eq!(k, 5);
        assert_eq!(thin_init_pairs(pairs, 2000).1, INIT_NEIGHBOURS);
        assert_eq!(init_pairs_for_budget(16 * 1024), 256);
        assert_eq!(init_pairs_for_budget(1024), 32);
    }
}
