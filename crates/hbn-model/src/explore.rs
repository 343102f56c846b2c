//! Exploration for data collection (thesis Sec. 3.4): which input to apply next so that a
//! model trained on the collected data is accurate after fewer minutes of calibration.
//!
//! The [`Explorer`] proposes the next input `u_t`, the robot (or a simulator) applies it, and
//! the observed `(u, x, y)` is given back with [`Explorer::observe`]. Two phases:
//!
//! 1. **random** (the first [`ExploreParams::random_samples`] samples): random inputs within
//!    the bounds and the increment bound `eta` ([`ExploreParams::max_step`]);
//! 2. **uncertainty seeking**, with a weight `a` that grows linearly from
//!    [`ExploreParams::alpha_start`] to [`ExploreParams::alpha_end`] over
//!    [`ExploreParams::alpha_ramp`] samples.
//!
//! How the input moves is the [`Strategy`]:
//! - [`Strategy::Ramps`] (default): ramps to a target level at a constant slope, as the
//!   random-ramp inputs of `hbn simulate`; random ramps in phase 1; in phase 2 the next ramp
//!   is, with probability `a`, the best of a pool of [`ExploreParams::pool`] random ramps by
//!   the [`Criterion`]: the one whose first [`ExploreParams::horizon`] samples would lower the
//!   latent variance of the transition GP `H_D` most, summed over where all the pool's ramps
//!   go ([`Criterion::Reduction`], the default), or the one along which that variance is
//!   largest ([`Criterion::Variance`]). The pool is drawn as the random ramps are, so the
//!   explored input stays an input like those the robot will see, tilted towards where the
//!   model would learn most.
//! - [`Strategy::Steps`]: the thesis' rule, `u_t = u_{t-1} + w` in phase 1 and `u_t = u_{t-1} +
//!   a eps + (1 - a) w` in phase 2, `w` uniform in `[-eta, eta]`, `eps` in `[-eta, eta]`
//!   maximising the latent variance of `H_D` where a ramp of steps `eps` leads within
//!   `horizon` samples (1 = the thesis' one-step look-ahead).
//!
//! The input `u_t` moves the state of the *next* sample (`x_{t+1} = H_D(x_t, x_{t-1}, u_t,
//! u_{t-1})`), and `x_t` is not observed yet when `u_t` is chosen, so the variance along a
//! candidate is taken at `[x̂_t, x_{t-1}, u_t, u_{t-1}]` and beyond, the states `x̂` rolled
//! forward by the transition GP's mean.
//!
//! What the measurements say (docs/exploration.md): the explored data train models about 6
//! times more accurate than the thesis' random walk. Against random ramps, measured against
//! two independent draws of them on seeds no design used (216 runs, six simulators, session
//! 36): 0.933x their nRMSE (geometric mean), 0.89x at 500 samples and 0.98x at 1000, at most
//! 0.98x on each simulator. One draw against another differs by a factor of about 1.5 in a
//! single run, so a comparison with one draw of a few seeds says little. The most uncertain
//! ramp over the whole range (the rule before the pool) sent the input to the ends of the
//! range and scored 1.07x.
//!
//! The transition GP is refitted on every sample so far every
//! [`ExploreParams::refit_every`] samples with the hyperparameters it has (a factorisation:
//! the variance then knows where the new data are), and its hyperparameters are re-learned
//! every [`ExploreParams::optimize_every`] samples, warm-started from the previous ones (one
//! optimiser start of at most [`RELEARN_MAX_ITERS`] iterations, so that `observe()` blocks
//! for a bounded time). [`Explorer::model`] trains the whole HBN ([`HysteresisModel::fit`]) on
//! everything observed.
//!
//! Guarantees (tested): a proposal lies in `[u_min, u_max]`, and, when the last observed input
//! lies in the bounds, differs from it by at most `eta`. A last input outside the bounds (the
//! robot did not follow) is answered with the nearest bound. Equal seeds and equal
//! observations give equal proposals, bit for bit.
//!
//! ```
//! use hbn_model::explore::{ExploreParams, Explorer};
//! use hbn_sim::{SimConfig, Simulator, SystemKind};
//! let mut params = ExploreParams::new(0.0, 1.0, 0.02);
//! params.random_samples = 60;
//! params.model.max_points = 60;
//! params.model.n_starts = 1;
//! let mut explorer = Explorer::new(params).unwrap();
//! let mut robot = Simulator::new(&SimConfig::new(SystemKind::Duhem)).unwrap();
//! let mut last = None;
//! for _ in 0..100 {
//!     let u = explorer.propose();
//!     assert!((0.0..=1.0).contains(&u));
//!     if let Some(prev) = last {
//!         assert!(f64::abs(u - prev) <= 0.02);
//!     }
//!     let (x, y) = robot.step(u).unwrap();
//!     explorer.observe(u, x, y).unwrap();
//!     last = Some(u);
//! }
//! assert!(explorer.alpha() > 0.0); // past the random phase: seeking uncertainty
//! let model = explorer.model().unwrap();
//! assert_eq!(model.summary().rows, 98);
//! ```

use hbn_core::rng::Rng;
use hbn_core::{GpView, MAX_DIM, PlayState, Plays, Want, transition_input};
use hbn_gp::{GaussianProcess, Hyperparameters};

use crate::dataset::{
    Memory, Sequence, TRANSITION_DIM, TRANSITION_DIRECTION, Table, build_dataset,
};
use crate::params::{CheckedHbnParams, HbnParams};
use crate::{HysteresisModel, ModelError};

/// Steps are drawn within this fraction of `max_step`, so that floating-point rounding never
/// makes a proposal differ from the last input by more than `max_step`.
const STEP_MARGIN: f64 = 1.0 - 1e-9;

/// Fewest samples of the random phase: the first transition GP needs data to stand on.
pub const MIN_RANDOM_SAMPLES: usize = 10;

/// Parameters of the [`Explorer`]. Build with [`ExploreParams::new`] (the bounds and the
/// increment bound have no sensible default), adjust fields, [`ExploreParams::check`] once.
#[derive(Clone, Debug, PartialEq)]
pub struct ExploreParams {
    /// Lowest input the explorer may propose.
    pub u_min: f64,
    /// Highest input the explorer may propose.
    pub u_max: f64,
    /// Increment bound `eta`: `|u_t - u_{t-1}| <= max_step` (Assumption 2).
    pub max_step: f64,
    /// The first input, before anything is observed (default: `u_min`, the relaxed state of
    /// an actuator driven by pressure or current).
    pub u_start: Option<f64>,
    /// Samples of the random phase (`k` of the thesis). Default 200.
    pub random_samples: usize,
    /// Weight `a` of uncertainty seeking when that phase starts (the probability that a ramp
    /// seeks, or the weight of `eps` in a step). Default 0.5.
    pub alpha_start: f64,
    /// Weight `a` reached at the end of the ramp. Default 0.9.
    pub alpha_end: f64,
    /// Samples over which `a` grows linearly from `alpha_start` to `alpha_end`. Default 1000.
    pub alpha_ramp: usize,
    /// Refit the transition GP on all samples so far every this many samples, with the
    /// hyperparameters it has. Default 10.
    pub refit_every: usize,
    /// Re-learn the transition GP's hyperparameters every this many samples (warm-started
    /// from the previous ones). Default 200.
    pub optimize_every: usize,
    /// [`Strategy::Steps`]: the steps `eps` evenly spaced in `[-eta, eta]` evaluated per
    /// choice. Default 21. (Not used by [`Strategy::Ramps`], which draws
    /// [`ExploreParams::pool`] ramps.)
    pub candidates: usize,
    /// [`Strategy::Ramps`]: random ramps drawn per seeking choice (target uniform in the
    /// bounds, slope uniform in `[0.1, 1] max_step`, as the random ones); the best by the
    /// [`ExploreParams::criterion`] is followed. More makes the input seek harder: on the runs
    /// that chose the default (with [`Criterion::Variance`]), 4 scored 0.97x random ramps'
    /// nRMSE, 8 0.89x and 16 1.02x, and the most uncertain ramp of a grid over the whole range
    /// (the rule before the pool) 1.01x; on runs held out from that choice 8 scored 0.97x and
    /// the grid 1.12x (docs/exploration.md). At least 2, at most [`MAX_POOL`]. Default 8.
    pub pool: usize,
    /// Look-ahead in samples. [`Strategy::Ramps`]: a candidate ramp is scored over its first
    /// `horizon` samples (by the [`ExploreParams::criterion`]). [`Strategy::Steps`]: a candidate
    /// `eps` is scored by the variance at the end of the ramp `u_{t-1} + j eps`,
    /// `j = 1..=horizon`; `1` is the thesis' one-step rule, which oscillates between `+eta`
    /// and `-eta` once the variance is flat across one step (measured: 400 samples of pure
    /// seeking stayed within 0.024 of where they began). Default 50.
    pub horizon: usize,
    /// Samples a refit may take. `0` (default): every refit of the transition GP runs inside
    /// [`Explorer::observe`], which then blocks for it (a few milliseconds per sample on average, up to about a second when hyperparameters
    /// are re-learned).
    /// `lag > 0`: each refit runs on a thread beside the loop, on the data observed when it
    /// starts, and `observe()` waits only if it has not finished when its GP is due: a
    /// re-learning of the hyperparameters is used `lag` samples after it starts; the first
    /// fit, at the end of the random phase, and the refits with the current hyperparameters
    /// (which go on while a re-learning runs) `min(lag, refit_every)` samples after. The
    /// explorer stays deterministic: equal seeds and observations give equal proposals,
    /// however fast the machine. The model steered by is older, which costs some accuracy
    /// (1.02x the default's nRMSE with `lag = 200`; docs/exploration.md). For a loop that
    /// cannot wait for a refit: at 100 Hz, `lag = 200` left 4 samples of 2000 over the 10 ms
    /// period (by at most 62 ms), `lag = 0` 161 (by up to 0.7 s).
    pub lag: usize,
    /// How the input moves ([`Strategy::Ramps`] by default).
    pub strategy: Strategy,
    /// [`Strategy::Ramps`]: how a seeking choice scores the ramps of the pool
    /// ([`Criterion::Reduction`] by default).
    pub criterion: Criterion,
    /// Seed of the random steps and ramps.
    pub seed: u64,
    /// Training parameters of the HBN: the transition GP of the explorer and
    /// [`Explorer::model`] use them (rate, kernels, `max_points`, `n_inducing`, ...).
    pub model: HbnParams,
}

impl ExploreParams {
    /// Default of [`ExploreParams::random_samples`].
    pub const DEFAULT_RANDOM_SAMPLES: usize = 200;
    /// Default of [`ExploreParams::alpha_start`].
    pub const DEFAULT_ALPHA_START: f64 = 0.5;
    /// Default of [`ExploreParams::alpha_end`].
    pub const DEFAULT_ALPHA_END: f64 = 0.9;
    /// Default of [`ExploreParams::alpha_ramp`].
    pub const DEFAULT_ALPHA_RAMP: usize = 1000;
    /// Default of [`ExploreParams::refit_every`].
    pub const DEFAULT_REFIT_EVERY: usize = 10;
    /// Default of [`ExploreParams::optimize_every`].
    pub const DEFAULT_OPTIMIZE_EVERY: usize = 200;
    /// Default of [`ExploreParams::candidates`].
    pub const DEFAULT_CANDIDATES: usize = 21;
    /// Default of [`ExploreParams::horizon`].
    pub const DEFAULT_HORIZON: usize = 50;
    /// Default of [`ExploreParams::pool`].
    pub const DEFAULT_POOL: usize = 8;

    /// The defaults for inputs in `[u_min, u_max]` with increments at most `max_step`.
    pub fn new(u_min: f64, u_max: f64, max_step: f64) -> Self {
        Self {
            u_min,
            u_max,
            max_step,
            u_start: None,
            random_samples: Self::DEFAULT_RANDOM_SAMPLES,
            alpha_start: Self::DEFAULT_ALPHA_START,
            alpha_end: Self::DEFAULT_ALPHA_END,
            alpha_ramp: Self::DEFAULT_ALPHA_RAMP,
            refit_every: Self::DEFAULT_REFIT_EVERY,
            optimize_every: Self::DEFAULT_OPTIMIZE_EVERY,
            candidates: Self::DEFAULT_CANDIDATES,
            pool: Self::DEFAULT_POOL,
            horizon: Self::DEFAULT_HORIZON,
            lag: 0,
            strategy: Strategy::Ramps,
            criterion: Criterion::Reduction,
            seed: 0,
            model: HbnParams::default(),
        }
    }

    /// Checks every field once (the explorer then trusts them). Errors name the field.
    pub fn check(self) -> Result<CheckedExploreParams, ExploreError> {
        let bad = |name: &'static str, reason: String| {
            Err(ExploreError::InvalidParameter { name, reason })
        };
        for (name, v) in [("u_min", self.u_min), ("u_max", self.u_max)] {
            if !v.is_finite() {
                return bad(name, format!("must be finite, got {v}"));
            }
        }
        if self.u_min >= self.u_max {
            return bad(
                "u_max",
                format!(
                    "must be greater than u_min = {}, got {}",
                    self.u_min, self.u_max
                ),
            );
        }
        if !(self.max_step.is_finite() && self.max_step > 0.0) {
            return bad(
                "max_step",
                format!("must be finite and > 0, got {}", self.max_step),
            );
        }
        if let Some(u0) = self.u_start
            && !(self.u_min..=self.u_max).contains(&u0)
        {
            return bad(
                "u_start",
                format!(
                    "must lie in [u_min, u_max] = [{}, {}], got {u0}",
                    self.u_min, self.u_max
                ),
            );
        }
        if self.random_samples < MIN_RANDOM_SAMPLES {
            return bad(
                "random_samples",
                format!(
                    "must be at least {MIN_RANDOM_SAMPLES} (the first transition GP needs \
                     data), got {}",
                    self.random_samples
                ),
            );
        }
        for (name, v) in [
            ("alpha_start", self.alpha_start),
            ("alpha_end", self.alpha_end),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return bad(name, format!("must be in [0, 1], got {v}"));
            }
        }
        for (name, v) in [
            ("refit_every", self.refit_every),
            ("optimize_every", self.optimize_every),
            ("horizon", self.horizon),
        ] {
            if v == 0 {
                return bad(name, "must be at least 1".into());
            }
        }
        if self.candidates < 2 {
            return bad(
                "candidates",
                format!("must be at least 2, got {}", self.candidates),
            );
        }
        if !(2..=MAX_POOL).contains(&self.pool) {
            return bad(
                "pool",
                format!("must be in [2, {MAX_POOL}], got {}", self.pool),
            );
        }
        let model = self.model.clone().check().map_err(ModelError::from)?;
        Ok(CheckedExploreParams {
            params: self,
            model,
        })
    }
}

/// [`ExploreParams`] that passed [`ExploreParams::check`].
#[derive(Clone, Debug)]
pub struct CheckedExploreParams {
    params: ExploreParams,
    model: CheckedHbnParams,
}

impl std::ops::Deref for CheckedExploreParams {
    type Target = ExploreParams;
    fn deref(&self) -> &ExploreParams {
        &self.params
    }
}

/// Errors of the explorer.
#[derive(Debug, thiserror::Error)]
pub enum ExploreError {
    /// A parameter failed its check; `name` is the field of [`ExploreParams`].
    #[error("{name}: {reason}")]
    InvalidParameter {
        /// Field of [`ExploreParams`] (the Python keyword; the CLI flag with `-` for `_`).
        name: &'static str,
        /// What is wrong and what would fix it.
        reason: String,
    },
    /// An observed sample is NaN or infinite.
    #[error(
        "observation {index}: {signal} is {value}; give the explorer finite samples (skip a \
         sample the robot could not measure)"
    )]
    NonFiniteObservation {
        /// Index of the sample among the observations.
        index: usize,
        /// `u`, `x` or `y`.
        signal: crate::Signal,
        /// The value.
        value: f64,
    },
    /// Training parameters or the model fit failed.
    #[error(transparent)]
    Model(#[from] ModelError),
}

/// How the explorer moves the input.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Strategy {
    /// Ramps, like the random-ramp inputs of `hbn simulate`: each ramp goes to a target level
    /// at a constant slope; when it arrives, the next ramp is a random one (target uniform in
    /// the bounds, slope uniform in `[0.1, 1] max_step`), or, with probability `alpha`, the
    /// best of `pool` such random ramps by the [`Criterion`] (scored over their first
    /// `horizon` samples). The thesis' random phase is random ramps here.
    #[default]
    Ramps,
    /// The thesis' per-sample rule: `u_t = u_{t-1} + a eps + (1 - a) w`, `w` uniform in
    /// `[-eta, eta]`, `eps` the step whose ramp of `horizon` samples ends where the variance
    /// is largest. Measured (docs/exploration.md): its inputs move at nearly `a eta` every
    /// sample, so the data miss slow inputs, and the models it trains were less accurate
    /// than random ramps'.
    Steps,
}

impl Strategy {
    /// `ramps` or `steps`.
    pub const fn name(self) -> &'static str {
        match self {
            Strategy::Ramps => "ramps",
            Strategy::Steps => "steps",
        }
    }
}

impl std::str::FromStr for Strategy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "ramps" => Ok(Strategy::Ramps),
            "steps" => Ok(Strategy::Steps),
            _ => Err(format!("unknown strategy `{s}`; choose ramps or steps")),
        }
    }
}

/// How a seeking choice of [`Strategy::Ramps`] scores the ramps of its pool.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Criterion {
    /// The mean latent variance of the transition GP along the ramp's first `horizon`
    /// samples: the ramp where the model is least sure (uncertainty sampling).
    Variance,
    /// The reduction of the transition GP's latent variance, summed over the paths of all
    /// the pool's ramps, that observing the ramp's first `horizon` samples would bring
    /// (integrated variance reduction, Cohn's criterion). The pool is a draw of the ramps a
    /// random input takes next, so this is the ramp whose data most lower the variance where
    /// such inputs go, rather than where the variance is largest. Measured on seeds that
    /// played no part in the explorer's design (docs/exploration.md): 0.95x and 0.99x the
    /// variance's nRMSE on two sets of runs, level with random ramps overall.
    #[default]
    Reduction,
}

impl Criterion {
    /// `variance` or `reduction`.
    pub const fn name(self) -> &'static str {
        match self {
            Criterion::Variance => "variance",
            Criterion::Reduction => "reduction",
        }
    }
}

impl std::str::FromStr for Criterion {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "variance" => Ok(Criterion::Variance),
            "reduction" => Ok(Criterion::Reduction),
            _ => Err(format!(
                "unknown criterion `{s}`; choose variance or reduction"
            )),
        }
    }
}

/// Largest [`ExploreParams::pool`].
pub const MAX_POOL: usize = 256;

/// Most L-BFGS iterations of one warm-started re-learning of the transition GP's
/// hyperparameters (every [`ExploreParams::optimize_every`] samples); the next one continues
/// from where it ended. Measured (docs/exploration.md): warm starts took 16 to 22 iterations
/// up to 1200 samples, then, once the likelihood moved to a new optimum, up to 100 with 5 to 9
/// likelihood evaluations each, and `observe()` blocked for up to 5 s.
pub const RELEARN_MAX_ITERS: u64 = 25;

/// Points at which a candidate ramp's variance is sampled (evenly along its first `horizon`
/// samples).
const RAMP_POINTS: usize = 8;

/// A ramp the explorer follows: towards `target` by `slope` per sample.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Ramp {
    target: f64,
    slope: f64,
}

impl Ramp {
    /// The input `j` samples along the ramp from `u_prev`.
    fn at(self, u_prev: f64, j: usize) -> f64 {
        let dist = self.target - u_prev;
        u_prev + dist.signum() * (j as f64 * self.slope).min(dist.abs())
    }

    /// How a ramp from `u_prev` is scored: over its first `len` samples (at most `horizon`),
    /// sampled every `every` samples and at the end ([`RAMP_POINTS`] points); `None` for a
    /// target within one step, which is no ramp to score (the random one may still be it).
    fn sampling(self, u_prev: f64, horizon: usize) -> Option<(usize, usize)> {
        let dist = (self.target - u_prev).abs();
        if dist < self.slope {
            return None;
        }
        let len = ((dist / self.slope).ceil() as usize).min(horizon);
        Some((len, len.div_ceil(RAMP_POINTS)))
    }
}

/// Where the explorer is in its schedule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Phase {
    /// Random steps (the first `random_samples`, or while no transition GP could be fitted).
    Random,
    /// Uncertainty seeking with weight `alpha`.
    Seeking {
        /// The weight `a` of the variance-maximising step.
        alpha: f64,
    },
}

/// One run of observed samples (a new run starts after [`Explorer::start_run`]).
#[derive(Clone, Debug, Default)]
struct Run {
    u: Vec<f64>,
    x: Vec<f64>,
    y: Vec<f64>,
    /// The plays after the last input (`None` before the first).
    play: Option<PlayState>,
}

impl Run {
    fn push(&mut self, plays: &Plays, u: f64, x: f64, y: f64) {
        let st = self.play.get_or_insert(plays.start(u));
        plays.advance(st, u);
        self.u.push(u);
        self.x.push(x);
        self.y.push(y);
    }
}

/// The exploration loop's state: proposes inputs, takes observations, refits (see the
/// [module documentation](self)).
#[derive(Clone, Debug)]
pub struct Explorer {
    params: CheckedExploreParams,
    rng: Rng,
    runs: Vec<Run>,
    observed: usize,
    transition: Option<GaussianProcess>,
    fitted_at: usize,
    optimized_at: usize,
    /// Samples observed when the seeking phase began (the alpha ramp counts from here).
    seeking_from: Option<usize>,
    /// Re-learn hyperparameters at refits (off while planning on predicted samples).
    learn: bool,
    /// The ramp being followed ([`Strategy::Ramps`]).
    ramp: Option<Ramp>,
    warnings: Vec<String>,
    /// The transition's play operators ([`HbnParams::memory`] of the bounds' range, or those
    /// of the model an explorer resumes from): the explorer's GP reads the same inputs as the
    /// model trained from its data.
    plays: Plays,
    /// The re-learning of the hyperparameters running beside the loop
    /// ([`ExploreParams::lag`] > 0), if any.
    relearning: Option<Pending>,
    /// The refit with the current hyperparameters running beside the loop, if any.
    refitting: Option<Pending>,
}

/// A refit of the transition GP running on a thread beside the exploration loop.
#[derive(Clone, Debug)]
struct Pending {
    /// Samples observed when it started (the data it fits).
    started: usize,
    /// It is applied once this many samples are observed.
    apply_at: usize,
    /// Where the thread leaves its result (shared by clones of the explorer: the result
    /// depends only on the data and settings it started from).
    slot: std::sync::Arc<Slot>,
}

/// A refit's result, once its thread has finished.
#[derive(Default)]
struct Slot {
    result: std::sync::Mutex<Option<Result<GaussianProcess, String>>>,
    done: std::sync::Condvar,
}

impl std::fmt::Debug for Slot {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Slot")
    }
}

impl Slot {
    fn put(&self, result: Result<GaussianProcess, String>) {
        let mut guard = self
            .result
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        *guard = Some(result);
        self.done.notify_all();
    }

    /// Waits for the result.
    fn wait(&self) -> Result<GaussianProcess, String> {
        let mut guard = self
            .result
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        loop {
            if let Some(r) = guard.as_ref() {
                return r.clone();
            }
            guard = self
                .done
                .wait(guard)
                .unwrap_or_else(std::sync::PoisonError::into_inner);
        }
    }
}

/// One refit to run: the GP's settings and the table it fits.
struct RefitJob {
    gp_params: hbn_gp::GpParams,
    table: Table,
}

impl RefitJob {
    /// Fits the GP (a panic in the fit is reported as an error, so that a thread never
    /// leaves its slot empty).
    fn run(&self) -> Result<GaussianProcess, String> {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            hbn_gp::fit(&self.gp_params, &self.table.inputs, &self.table.targets)
        }))
        .map_err(|_| "the fit panicked".to_owned())
        .and_then(|r| r.map_err(|e| e.to_string()))
    }
}

impl Explorer {
    /// An explorer with nothing observed yet.
    pub fn new(params: ExploreParams) -> Result<Self, ExploreError> {
        let params = params.check()?;
        let span = params.u_max - params.u_min;
        let radii: Vec<f64> = params.model.memory.iter().map(|f| f * span).collect();
        let lags = params.model.lag_coefficients().map_err(ModelError::from)?;
        let plays = Plays::with_lags(&radii, &lags).map_err(ModelError::from)?;
        Ok(Self {
            plays,
            rng: Rng::new(params.seed ^ EXPLORE_SALT),
            params,
            runs: vec![Run::default()],
            observed: 0,
            transition: None,
            fitted_at: 0,
            optimized_at: 0,
            seeking_from: None,
            learn: true,
            ramp: None,
            warnings: Vec::new(),
            relearning: None,
            refitting: None,
        })
    }

    /// An explorer that continues from data already collected (`history`, one or more runs;
    /// the next proposal continues the last run), with the transition GP's hyperparameters
    /// taken from `model` (trained on that first batch) as the starting point. The training
    /// parameters of [`ExploreParams::model`] are replaced by the model's.
    pub fn resume(
        mut params: ExploreParams,
        model: &HysteresisModel,
        history: &[Sequence<'_>],
    ) -> Result<Self, ExploreError> {
        params.model = model.params().clone();
        let mut explorer = Self::new(params)?;
        explorer.plays = model.plays()?;
        build_dataset(history, &Memory::of_input(explorer.plays)).map_err(ModelError::from)?;
        explorer.runs = history
            .iter()
            .map(|s| {
                let mut run = Run::default();
                for ((&u, &x), &y) in s.u.iter().zip(s.x).zip(s.y) {
                    run.push(&explorer.plays, u, x, y);
                }
                run
            })
            .collect();
        explorer.observed = explorer.runs.iter().map(|r| r.u.len()).sum();
        let gp = model.transition();
        let warm = gp.hyperparameters();
        // At once, whatever the lag: the explorer starts from the model it resumes.
        explorer.refit(Some(warm), false);
        explorer.optimized_at = explorer.observed;
        if explorer.transition.is_some() {
            explorer.seeking_from = Some(explorer.observed);
        }
        Ok(explorer)
    }

    /// The checked parameters.
    pub fn params(&self) -> &ExploreParams {
        &self.params
    }

    /// Samples observed so far (all runs).
    pub fn n_observed(&self) -> usize {
        self.observed
    }

    /// The current phase.
    pub fn phase(&self) -> Phase {
        match (self.seeking_from, &self.transition) {
            (Some(from), Some(_)) => {
                let p = &*self.params;
                let done = self.observed.saturating_sub(from) as f64;
                let frac = if p.alpha_ramp == 0 {
                    1.0
                } else {
                    (done / p.alpha_ramp as f64).min(1.0)
                };
                Phase::Seeking {
                    alpha: p.alpha_start + (p.alpha_end - p.alpha_start) * frac,
                }
            }
            _ => Phase::Random,
        }
    }

    /// The weight `a` of the uncertainty-seeking step now (0 in the random phase).
    pub fn alpha(&self) -> f64 {
        match self.phase() {
            Phase::Random => 0.0,
            Phase::Seeking { alpha } => alpha,
        }
    }

    /// What went wrong along the way and was recovered from (a refit that failed keeps the
    /// previous GP; with none, steps stay random).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// The transition GP the explorer steers by (`None` during the random phase).
    pub fn transition(&self) -> Option<&GaussianProcess> {
        self.transition.as_ref()
    }

    /// Inputs, states and outputs observed, one `(u, x, y)` triple of vectors per run.
    pub fn runs(&self) -> impl Iterator<Item = (&[f64], &[f64], &[f64])> {
        self.runs
            .iter()
            .map(|r| (r.u.as_slice(), r.x.as_slice(), r.y.as_slice()))
    }

    /// Starts a new run: the robot was reset, so the next samples do not follow the last
    /// ones (no training row straddles the two). The next proposal is `u_start`.
    pub fn start_run(&mut self) {
        self.ramp = None;
        if self.runs.last().is_some_and(|r| !r.u.is_empty()) {
            self.runs.push(Run::default());
        }
    }

    /// The next input to apply: in `[u_min, u_max]`, within `max_step` of the last observed
    /// input (see the [module documentation](self)). Draws random numbers for a step
    /// ([`Strategy::Steps`]) or for a new ramp ([`Strategy::Ramps`], when the last one has
    /// arrived).
    pub fn propose(&mut self) -> f64 {
        let p = &*self.params;
        let (lo, hi) = (p.u_min, p.u_max);
        let run = self.runs.last();
        let Some(&u_prev) = run.and_then(|r| r.u.last()) else {
            return p.u_start.unwrap_or(lo);
        };
        if u_prev > hi {
            return hi;
        }
        if u_prev < lo {
            return lo;
        }
        let eta = p.max_step * STEP_MARGIN;
        if p.strategy == Strategy::Ramps {
            return self.propose_ramp(u_prev, eta);
        }
        let w = self.rng.uniform_in(-eta, eta);
        let step = match self.phase() {
            Phase::Random => w,
            Phase::Seeking { alpha } => match self.seek(u_prev, eta) {
                Some(eps) => alpha * eps + (1.0 - alpha) * w,
                None => w,
            },
        };
        // Reflect at the bounds (a reflected step is no longer than the step), then clamp
        // as a safety net against rounding.
        let mut u = u_prev + step;
        if u > hi {
            u = 2.0 * hi - u;
        }
        if u < lo {
            u = 2.0 * lo - u;
        }
        u.clamp(u_prev - eta, u_prev + eta).clamp(lo, hi)
    }

    /// [`Strategy::Ramps`]: the next input along the current ramp, after choosing a new ramp
    /// when the last one has arrived.
    fn propose_ramp(&mut self, u_prev: f64, eta: f64) -> f64 {
        let p = &*self.params;
        let (lo, hi) = (p.u_min, p.u_max);
        let ramp = match self.ramp {
            Some(r) if (r.target - u_prev).abs() > f64::EPSILON * r.target.abs().max(1.0) => r,
            _ => {
                let r = self.next_ramp(u_prev, eta);
                self.ramp = Some(r);
                r
            }
        };
        let d = ramp.target - u_prev;
        let u = u_prev + d.signum() * d.abs().min(ramp.slope);
        u.clamp(u_prev - eta, u_prev + eta).clamp(lo, hi)
    }

    /// A new ramp: a random one (target uniform in the bounds, slope uniform in
    /// `[0.1, 1] eta`), or, with probability `alpha`, the best by the criterion of a pool of
    /// `pool` random ramps (the first of which is that random one).
    fn next_ramp(&mut self, u_prev: f64, eta: f64) -> Ramp {
        let (lo, hi) = (self.params.u_min, self.params.u_max);
        // Every draw always happens, in the random phase too, so the random stream does not
        // depend on the GP or the phase.
        let coin = self.rng.uniform();
        let mut pool = [Ramp {
            target: lo,
            slope: eta,
        }; MAX_POOL];
        let pool = pool.get_mut(..self.params.pool).unwrap_or_default();
        for ramp in pool.iter_mut() {
            *ramp = Ramp {
                target: self.rng.uniform_in(lo, hi),
                slope: self.rng.uniform_in(0.1, 1.0) * eta,
            };
        }
        let random = pool.first().copied().unwrap_or(Ramp {
            target: u_prev,
            slope: eta,
        });
        if coin < self.alpha() {
            let best = match self.params.criterion {
                Criterion::Variance => self.most_uncertain(u_prev, pool),
                Criterion::Reduction => self.most_informative(u_prev, pool),
            };
            if let Some(r) = best {
                return r;
            }
        }
        random
    }

    /// Where every candidate starts: the transition GP's predictor, the states
    /// `[x̂_t, x_{t-1}]` (`x̂_t`, the state of the sample at which the proposal is applied, from
    /// the GP's mean) and the plays after the last input `u_prev`; `None` without a GP or two
    /// samples in the current run.
    fn start(&self, u_prev: f64) -> Option<(Predictor<'_>, [f64; 2], PlayState)> {
        let gp = self.transition.as_ref()?;
        let run = self.runs.last()?;
        let n = run.u.len();
        if n < 2 {
            return None;
        }
        let play = run.play?;
        let mut gp = Predictor::new(gp, self.plays.len())?;
        let (x1, x2, u2) = (run.x[n - 1], run.x[n - 2], run.u[n - 2]);
        let x_now = gp.state(transition_input(x1, x2, u_prev, u2, &play))?;
        Some((gp, [x_now, x1], play))
    }

    /// The ramp of `pool` with the largest mean latent variance of the transition GP over its
    /// first `horizon` samples (the first of equals); `None` without a GP or history, or when
    /// no ramp could be scored.
    fn most_uncertain(&self, u_prev: f64, pool: &[Ramp]) -> Option<Ramp> {
        let (mut gp, states, play) = self.start(u_prev)?;
        let horizon = self.params.horizon;
        let mut best: Option<(f64, Ramp)> = None;
        for &ramp in pool {
            let Some((len, every)) = ramp.sampling(u_prev, horizon) else {
                continue;
            };
            let path = |j: usize| ramp.at(u_prev, j);
            let Some(v) = self.path_variance(&mut gp, (states, u_prev, play), len, every, path)
            else {
                continue;
            };
            if best.is_none_or(|(b, _)| v > b) {
                best = Some((v, ramp));
            }
        }
        best.map(|(_, r)| r)
    }

    /// [`Criterion::Reduction`]: the ramp of `pool` whose first `horizon` samples, once
    /// observed, would lower the transition GP's latent variance most, summed over the
    /// sampled points of every ramp of the pool ([`Explorer::reductions`]; the first of
    /// equals); `None` without a GP or history, or when no ramp could be scored.
    fn most_informative(&self, u_prev: f64, pool: &[Ramp]) -> Option<Ramp> {
        let mut best: Option<(f64, Ramp)> = None;
        for (&ramp, reduction) in pool.iter().zip(self.reductions(u_prev, pool)?) {
            if let Some(v) = reduction
                && best.is_none_or(|(b, _)| v > b)
            {
                best = Some((v, ramp));
            }
        }
        best.map(|(_, r)| r)
    }

    /// The sampled points along the first `horizon` samples of each ramp of `pool` (as
    /// [`Explorer::most_uncertain`] samples them) and their latent posterior covariance;
    /// `None` without a GP or history.
    fn pool_paths(&self, u_prev: f64, pool: &[Ramp]) -> Option<PoolPaths> {
        let (mut gp, states, play) = self.start(u_prev)?;
        let horizon = self.params.horizon;
        let mut points: Vec<[f64; MAX_DIM]> = Vec::with_capacity(pool.len() * (RAMP_POINTS + 1));
        let mut spans = Vec::with_capacity(pool.len());
        for &ramp in pool {
            let Some((len, every)) = ramp.sampling(u_prev, horizon) else {
                spans.push(None);
                continue;
            };
            let path = |j: usize| ramp.at(u_prev, j);
            let first = points.len();
            let rolled = self.path_inputs(
                &mut gp,
                (states, u_prev, play),
                len,
                every,
                path,
                &mut points,
            );
            if rolled.is_none() {
                points.truncate(first);
                spans.push(None);
                continue;
            }
            spans.push(Some(Span {
                first,
                last: points.len(),
                every,
            }));
        }
        let cov = gp.posterior_covariances(&points)?;
        Some(PoolPaths {
            noise: gp.view.noise_variance(),
            len: points.len(),
            spans,
            cov,
        })
    }

    /// [`Criterion::Reduction`]'s score of each ramp of `pool` (`None` for a ramp that could
    /// not be scored): for its sampled points `S` (each standing for the `every` samples
    /// around it, so with noise variance `s_n^2 / every`) and all the pool's points `P`,
    /// `sum_{r in P} c_r^T (C_SS + s_n^2 / every I)^{-1} c_r`, `C` the latent posterior
    /// covariance and `c_r = C_{S r}`: how much observing the ramp lowers the variance
    /// summed over where the pool's ramps go. `None` without a GP or history.
    fn reductions(&self, u_prev: f64, pool: &[Ramp]) -> Option<Vec<Option<f64>>> {
        let paths = self.pool_paths(u_prev, pool)?;
        let (n_p, cov) = (paths.len, &paths.cov);
        let score = |span: &Span| -> Option<f64> {
            let h = span.last - span.first;
            let at = |i: usize, j: usize| cov.get(i * n_p + j).copied().unwrap_or(0.0);
            let mut a = nalgebra::DMatrix::from_fn(h, h, |i, j| at(span.first + i, span.first + j));
            let diag_mean = (0..h).map(|i| a[(i, i)]).sum::<f64>() / h.max(1) as f64;
            // The noise of `every` samples at one point, and a jitter that keeps near-equal
            // points of a noise-free GP factorable.
            let shift =
                paths.noise / span.every.max(1) as f64 + 1e-10 * diag_mean.max(f64::MIN_POSITIVE);
            for i in 0..h {
                a[(i, i)] += shift;
            }
            let chol = a.cholesky()?;
            let b = nalgebra::DMatrix::from_fn(h, n_p, |i, r| at(span.first + i, r));
            let reduction = b.component_mul(&chol.solve(&b)).sum();
            reduction.is_finite().then_some(reduction)
        };
        Some(
            paths
                .spans
                .iter()
                .map(|s| s.as_ref().and_then(score))
                .collect(),
        )
    }

    /// The step `eps` in `[-eta, eta]` (and inside the bounds) whose ramp of `horizon`
    /// samples ends at the transition input with the largest latent variance of the
    /// transition GP (states along the ramp rolled forward by the GP mean); `None` without a
    /// GP or history.
    fn seek(&self, u_prev: f64, eta: f64) -> Option<f64> {
        let (mut gp, states, play) = self.start(u_prev)?;
        let p = &*self.params;
        let e_lo = (-eta).max(p.u_min - u_prev);
        let e_hi = eta.min(p.u_max - u_prev);
        let c = p.candidates;
        let mut best: Option<(f64, f64)> = None;
        for i in 0..c {
            let eps = e_lo + (e_hi - e_lo) * i as f64 / (c - 1) as f64;
            let ramp = |j: usize| (u_prev + j as f64 * eps).clamp(p.u_min, p.u_max);
            let Some(variance) =
                self.path_variance(&mut gp, (states, u_prev, play), p.horizon, p.horizon, ramp)
            else {
                continue;
            };
            // Ties (a flat variance) go to the candidate nearest zero: no drift without cause.
            let better = match best {
                None => true,
                Some((v, e)) => variance > v || (variance == v && eps.abs() < e.abs()),
            };
            if better {
                best = Some((variance, eps));
            }
        }
        best.map(|(_, eps)| eps)
    }

    /// Mean latent variance of the transition GP along a path of inputs `path(j)`,
    /// `j = 1..=len` ([`Explorer::path_inputs`]), sampled every `every` samples and at the end.
    fn path_variance(
        &self,
        gp: &mut Predictor<'_>,
        from: ([f64; 2], f64, PlayState),
        len: usize,
        every: usize,
        path: impl Fn(usize) -> f64,
    ) -> Option<f64> {
        let mut inputs = Vec::with_capacity(len.div_ceil(every.max(1)) + 1);
        self.path_inputs(gp, from, len, every, path, &mut inputs)?;
        let (mut sum, mut count) = (0.0, 0usize);
        for &input in &inputs {
            sum += gp.variance(input)?;
            count += 1;
        }
        (count > 0).then(|| sum / count as f64)
    }

    /// The transition inputs along a path of inputs `path(j)`, `j = 1..=len`, starting
    /// (`from`) from the states `[x̂_t, x_{t-1}]`, the last input `u_prev` and the plays after
    /// it (states rolled forward by the GP mean, plays by the path), sampled every `every`
    /// samples and at the end, appended to `out`; `None` if the mean failed.
    fn path_inputs(
        &self,
        gp: &mut Predictor<'_>,
        from: ([f64; 2], f64, PlayState),
        len: usize,
        every: usize,
        path: impl Fn(usize) -> f64,
        out: &mut Vec<[f64; MAX_DIM]>,
    ) -> Option<()> {
        let ([mut x_a, mut x_b], mut u_b, mut play) = from;
        for j in 1..=len {
            let u_a = path(j);
            self.plays.advance(&mut play, u_a);
            let input = transition_input(x_a, x_b, u_a, u_b, &play);
            if j == len || j % every.max(1) == 0 {
                out.push(input);
            }
            if j == len {
                break;
            }
            let x_next = gp.state(input)?;
            (x_b, x_a, u_b) = (x_a, x_next, u_a);
        }
        Some(())
    }

    /// Records the sample the robot produced for the last input (`u` as applied, measured
    /// `x` and `y`), and refits the transition GP when it is due.
    pub fn observe(&mut self, u: f64, x: f64, y: f64) -> Result<(), ExploreError> {
        for (signal, value) in [
            (crate::Signal::Input, u),
            (crate::Signal::State, x),
            (crate::Signal::Output, y),
        ] {
            if !value.is_finite() {
                return Err(ExploreError::NonFiniteObservation {
                    index: self.observed,
                    signal,
                    value,
                });
            }
        }
        self.push(u, x, y);
        self.after_sample();
        Ok(())
    }

    fn push(&mut self, u: f64, x: f64, y: f64) {
        if self.runs.is_empty() {
            self.runs.push(Run::default());
        }
        if let Some(run) = self.runs.last_mut() {
            run.push(&self.plays, u, x, y);
        }
        self.observed += 1;
    }

    fn after_sample(&mut self) {
        if self.params.lag > 0 {
            self.after_sample_beside();
            return;
        }
        let p = &*self.params;
        let (n, every, opt_every) = (self.observed, p.refit_every, p.optimize_every);
        if self.transition.is_none() {
            if n >= p.random_samples {
                self.refit(None, true);
                self.optimized_at = n;
            }
        } else if self.learn && n >= self.optimized_at + opt_every {
            let warm = self.current_hyperparameters();
            self.refit(warm, true);
            self.optimized_at = n;
        } else if n >= self.fitted_at + every {
            let fixed = self.current_hyperparameters();
            self.refit(fixed, false);
        }
        if self.transition.is_some() && self.seeking_from.is_none() {
            self.seeking_from = Some(n);
        }
    }

    /// [`Explorer::after_sample`] with the refits beside the loop ([`ExploreParams::lag`] >
    /// 0): a re-learning is used `lag` samples after it starts; the first fit and the refits
    /// with the current hyperparameters (which go on meanwhile) `min(lag, refit_every)`
    /// samples after. Re-learned hyperparameters replace the GP when they are used, and a
    /// refit on every sample with them starts then (one still running with the old ones is
    /// dropped).
    fn after_sample_beside(&mut self) {
        let n = self.observed;
        if let Some(job) = self.relearning.take_if(|j| n >= j.apply_at) {
            let result = job.slot.wait();
            if result.is_ok() {
                self.refitting = None;
                self.fitted_at = 0;
            }
            self.apply(result, job.started);
        }
        if let Some(job) = self.refitting.take_if(|j| n >= j.apply_at) {
            let result = job.slot.wait();
            self.apply(result, job.started);
        }
        let p = &*self.params;
        let (lag, every, opt_every) = (p.lag, p.refit_every, p.optimize_every);
        let learn_due = self.learn && n >= self.optimized_at + opt_every;
        if self.transition.is_none() {
            if n >= p.random_samples && self.relearning.is_none() {
                // The first fit is on the random phase's few samples and quick (0.16 s on
                // 200): it waits only as long as a refit, so that seeking starts on time.
                self.relearning = self.start_beside(None, true, lag.min(every));
                self.optimized_at = n;
            }
        } else {
            if learn_due && self.relearning.is_none() {
                let warm = self.current_hyperparameters();
                self.relearning = self.start_beside(warm, true, lag);
                self.optimized_at = n;
            }
            if n >= self.fitted_at + every && self.refitting.is_none() {
                let fixed = self.current_hyperparameters();
                self.fitted_at = n;
                self.refitting = self.start_beside(fixed, false, lag.min(every));
            }
        }
        if self.transition.is_some() && self.seeking_from.is_none() {
            self.seeking_from = Some(n);
        }
    }

    /// The hyperparameters of the transition GP in use.
    fn current_hyperparameters(&self) -> Option<Hyperparameters> {
        self.transition
            .as_ref()
            .map(hbn_gp::GaussianProcess::hyperparameters)
    }

    /// Fits the transition GP on every sample so far, now: from `init` (or the defaults),
    /// with the optimiser when `optimize` (one start when warm-started).
    fn refit(&mut self, init: Option<Hyperparameters>, optimize: bool) {
        self.fitted_at = self.observed;
        if let Some(job) = self.job(init, optimize) {
            let result = job.run();
            self.apply(result, self.observed);
        }
    }

    /// Starts the fit of [`Explorer::refit`] on a thread beside the loop; it is to be applied
    /// `lag` samples later.
    fn start_beside(
        &mut self,
        init: Option<Hyperparameters>,
        optimize: bool,
        lag: usize,
    ) -> Option<Pending> {
        let job = self.job(init, optimize)?;
        let slot = std::sync::Arc::new(Slot::default());
        let worker = std::sync::Arc::clone(&slot);
        let spawned = std::thread::Builder::new()
            .name("hbn-explore-refit".into())
            .spawn(move || worker.put(job.run()));
        if let Err(e) = spawned {
            // No thread to be had: the refit is reported as failed, as a failed fit is.
            slot.put(Err(format!("no thread for the refit ({e})")));
        }
        Some(Pending {
            started: self.observed,
            apply_at: self.observed.saturating_add(lag),
            slot,
        })
    }

    /// The fit of the transition GP on every sample so far (`None`, with a warning, when the
    /// samples make no table).
    fn job(&mut self, init: Option<Hyperparameters>, optimize: bool) -> Option<RefitJob> {
        let table = match self.transition_table() {
            Ok(t) => t,
            Err(e) => {
                self.warnings
                    .push(format!("transition GP not refitted: {e}"));
                return None;
            }
        };
        let m = &self.params.model;
        let spec = m
            .transition_kernel
            .spec(TRANSITION_DIM + self.plays.len(), TRANSITION_DIRECTION);
        let mut gp_params = m.gp_params(spec, crate::GpRole::Transition);
        let warm = init.is_some();
        gp_params.init = init;
        gp_params.optimize = optimize;
        if warm {
            gp_params.n_starts = 1;
        }
        if warm && optimize {
            // Re-learning from where the last one ended: a bounded number of iterations, so
            // that `observe()` blocks for a bounded time; the next re-learning goes on from
            // here.
            gp_params.max_iters = gp_params.max_iters.min(RELEARN_MAX_ITERS);
        }
        Some(RefitJob { gp_params, table })
    }

    /// Uses a refit's GP from now on (a failed one keeps the previous GP, with a warning).
    fn apply(&mut self, result: Result<GaussianProcess, String>, started: usize) {
        match result {
            Ok(gp) => self.transition = Some(gp),
            Err(e) => self.warnings.push(format!(
                "transition GP refit at {started} samples failed ({e}); {}",
                if self.transition.is_some() {
                    "the previous one is kept"
                } else {
                    "steps stay random"
                }
            )),
        }
    }

    fn transition_table(&self) -> Result<Table, ModelError> {
        let seqs: Vec<Sequence<'_>> = self
            .runs
            .iter()
            .filter(|r| r.u.len() >= crate::MIN_SAMPLES)
            .map(|r| Sequence::new(&r.u, &r.x, &r.y))
            .collect();
        let data = build_dataset(&seqs, &Memory::of_input(self.plays))?;
        Ok(data.transition)
    }

    /// Trains the HBN ([`HysteresisModel::fit`] with [`ExploreParams::model`]) on every run observed.
    pub fn model(&self) -> Result<HysteresisModel, ExploreError> {
        let seqs: Vec<Sequence<'_>> = self
            .runs
            .iter()
            .filter(|r| !r.u.is_empty())
            .map(|r| Sequence::new(&r.u, &r.x, &r.y))
            .collect();
        Ok(HysteresisModel::fit_checked(
            &seqs,
            &self.params.model,
            &mut |_, _| {},
        )?)
    }

    /// An input schedule of `steps` samples for a robot that cannot run the explorer in its
    /// loop: each proposal is followed by the state the transition GP predicts for it
    /// (its mean), which the explorer then treats as observed (the GP's variance depends on
    /// where the data are, not on their values, so the plan spreads out as if measured).
    /// Hyperparameters are not re-learned on predicted samples. `self` is not changed.
    ///
    /// Returns the inputs and the predicted states. Needs a transition GP (after the random
    /// phase, or [`Explorer::resume`]); without one the plan is a random walk and the
    /// predicted states repeat the last observed one.
    pub fn plan(&self, steps: usize) -> (Vec<f64>, Vec<f64>) {
        let mut planner = self.clone();
        planner.learn = false;
        let mut u_plan = Vec::with_capacity(steps.min(PLAN_RESERVE));
        let mut x_plan = Vec::with_capacity(steps.min(PLAN_RESERVE));
        for _ in 0..steps {
            let u = planner.propose();
            let x = planner.predicted_next();
            // Predicted samples carry no sensor value: the explorer's GP never reads y.
            planner.push(u, x, 0.0);
            planner.after_sample();
            u_plan.push(u);
            x_plan.push(x);
        }
        (u_plan, x_plan)
    }

    /// The state the transition GP predicts for the sample after the last one (the input
    /// applied with it does not act on it yet: `x_t = H_D(x_{t-1}, x_{t-2}, u_{t-1},
    /// u_{t-2})`). Falls back to the last state (or 0 with none).
    fn predicted_next(&self) -> f64 {
        let last_x = self
            .runs
            .last()
            .and_then(|r| r.x.last().copied())
            .unwrap_or(0.0);
        let (Some(gp), Some(run)) = (self.transition.as_ref(), self.runs.last()) else {
            return last_x;
        };
        let n = run.u.len();
        let (true, Some(play)) = (n >= 2, run.play) else {
            return last_x;
        };
        let input = transition_input(
            run.x[n - 1],
            run.x[n - 2],
            run.u[n - 1],
            run.u[n - 2],
            &play,
        );
        Predictor::new(gp, self.plays.len())
            .and_then(|mut p| p.state(input))
            .unwrap_or(last_x)
    }
}

/// The transition GP's view (built once per proposal: building it checks every array) with
/// its scratch.
struct Predictor<'a> {
    view: GpView<'a>,
    scratch: Vec<f64>,
    /// Inputs the GP reads (4 plus the plays).
    dim: usize,
}

impl<'a> Predictor<'a> {
    fn new(gp: &'a GaussianProcess, plays: usize) -> Option<Self> {
        let view = gp.view().ok()?;
        let scratch = vec![0.0; view.predict_scratch(Want::VARIANCE)];
        Some(Self {
            view,
            scratch,
            dim: TRANSITION_DIM + plays,
        })
    }

    /// The mean state for one transition input.
    fn state(&mut self, input: [f64; MAX_DIM]) -> Option<f64> {
        let pred = self
            .view
            .predict(input.get(..self.dim)?, Want::MEAN, &mut self.scratch)
            .ok()?;
        pred.mean.is_finite().then_some(pred.mean)
    }

    /// The latent posterior covariance matrix of a set of transition inputs, row-major
    /// `len x len`; `None` if a prediction failed.
    fn posterior_covariances(&mut self, inputs: &[[f64; MAX_DIM]]) -> Option<Vec<f64>> {
        let n = self.view.len();
        let mut scratch = vec![0.0; self.view.whiten_scratch()];
        let mut whitened = vec![0.0; inputs.len() * n];
        for (input, w) in inputs.iter().zip(whitened.chunks_exact_mut(n)) {
            self.view
                .whiten(input.get(..self.dim)?, w, &mut scratch)
                .ok()?;
        }
        let p = inputs.len();
        let mut cov = vec![0.0; p * p];
        for (i, (a, w_a)) in inputs.iter().zip(whitened.chunks_exact(n)).enumerate() {
            for (j, (b, w_b)) in inputs
                .iter()
                .zip(whitened.chunks_exact(n))
                .enumerate()
                .skip(i)
            {
                let c = self
                    .view
                    .posterior_covariance(a.get(..self.dim)?, w_a, b.get(..self.dim)?, w_b)
                    .ok()?;
                cov[i * p + j] = c;
                cov[j * p + i] = c;
            }
        }
        Some(cov)
    }

    /// The latent variance at one transition input.
    fn variance(&mut self, input: [f64; MAX_DIM]) -> Option<f64> {
        let pred = self
            .view
            .predict(input.get(..self.dim)?, Want::VARIANCE, &mut self.scratch)
            .ok()?;
        pred.variance.is_finite().then_some(pred.variance)
    }
}

/// The sampled points of a pool's ramps ([`Explorer::pool_paths`]).
struct PoolPaths {
    /// The transition GP's noise variance (raw units).
    noise: f64,
    /// Points in all.
    len: usize,
    /// Each ramp's points (`None` for a ramp not scored).
    spans: Vec<Option<Span>>,
    /// Latent posterior covariance of the points, row-major `len x len`.
    cov: Vec<f64>,
}

/// One ramp's points in [`PoolPaths`]: `first..last`, each standing for `every` samples.
struct Span {
    first: usize,
    last: usize,
    every: usize,
}

/// Most samples a plan reserves memory for up front (a huge `steps` grows as it runs instead
/// of failing to reserve).
const PLAN_RESERVE: usize = 1 << 20;

/// Salt mixed into the seed, so that an explorer and a simulator seeded alike do not share
/// one random stream.
const EXPLORE_SALT: u64 = 0xE8B1_07E5_A3C4_2D19;

#[cfg(test)]
mod tests {
    use super::*;
    use hbn_sim::{SimConfig, Simulator, SystemKind};

    /// An explorer whose transition GP has seen inputs in `[0, 0.3]` only.
    fn trained_on_low_inputs() -> Explorer {
        let mut p = ExploreParams::new(0.0, 0.3, 0.02);
        p.random_samples = 80;
        p.seed = 5;
        p.model = HbnParams {
            max_points: 80,
            n_starts: 1,
            max_iters: 40,
            validation: 0.0,
            ..HbnParams::default()
        };
        let mut explorer = Explorer::new(p).unwrap();
        let mut robot = Simulator::new(&SimConfig::new(SystemKind::BoucWen)).unwrap();
        for _ in 0..120 {
            let u = explorer.propose();
            let (x, y) = robot.step(u).unwrap();
            explorer.observe(u, x, y).unwrap();
        }
        assert!(explorer.transition().is_some());
        explorer
    }

    fn last_input(explorer: &Explorer) -> f64 {
        let run = explorer.runs.last().unwrap();
        *run.u.last().unwrap()
    }

    #[test]
    fn seeking_follows_the_most_uncertain_ramp_of_the_pool_wherever_it_is_drawn() {
        // The GP knows u in [0, 0.3]. Of ramps to 0.05, 0.15, 0.25 and 0.9 (all at the same
        // slope), the one into the unseen range is the most uncertain, whichever place in
        // the pool it has; a rule that took the first ramp, or the least uncertain, fails.
        let explorer = trained_on_low_inputs();
        let u_prev = last_input(&explorer);
        let ramp = |target| Ramp {
            target,
            slope: 0.02,
        };
        let inside = [0.05, 0.15, 0.25].map(ramp);
        for place in 0..=inside.len() {
            let mut pool = inside.to_vec();
            pool.insert(place, ramp(0.9));
            let chosen = explorer.most_uncertain(u_prev, &pool).unwrap();
            assert_eq!(chosen, ramp(0.9), "pool {pool:?}");
        }
        // Without the outlier, one of the inside ramps (there is always an answer).
        let chosen = explorer.most_uncertain(u_prev, &inside).unwrap();
        assert!(inside.contains(&chosen));
    }

    #[test]
    fn a_ramps_reduction_is_the_variance_its_points_take_from_the_whole_pools_paths() {
        // Conditioning the GP on a ramp's points one at a time (rank-one updates of the
        // posterior covariance, each point with the noise of the `every` samples it stands
        // for) removes, summed over every point of every ramp of the pool, what
        // `reductions` says in one solve. A score over the ramp's own points only, or with
        // the noise of one sample, differs.
        let explorer = trained_on_low_inputs();
        let u_prev = last_input(&explorer);
        let pool = [(0.05, 0.02), (0.25, 0.01), (0.9, 0.02), (0.15, 0.005)]
            .map(|(target, slope)| Ramp { target, slope });
        let paths = explorer.pool_paths(u_prev, &pool).unwrap();
        let got = explorer.reductions(u_prev, &pool).unwrap();
        let n = paths.len;
        assert!(n > 4 * 4, "every ramp is sampled at several points");
        let spans = paths.spans.iter().flatten();
        assert!(
            spans.clone().any(|s| s.every > 1),
            "some point stands for several samples"
        );
        let mut best = (f64::NEG_INFINITY, pool[0]);
        for ((span, got), ramp) in paths.spans.iter().zip(&got).zip(pool) {
            let span = span.as_ref().unwrap();
            let mut c = paths.cov.clone();
            for s in span.first..span.last {
                let d = c[s * n + s] + paths.noise / span.every as f64;
                let col: Vec<f64> = (0..n).map(|i| c[i * n + s]).collect();
                for i in 0..n {
                    for j in 0..n {
                        c[i * n + j] -= col[i] * col[j] / d;
                    }
                }
            }
            let want: f64 = (0..n).map(|r| paths.cov[r * n + r] - c[r * n + r]).sum();
            let own: f64 = (span.first..span.last)
                .map(|r| paths.cov[r * n + r] - c[r * n + r])
                .sum();
            let got = got.unwrap();
            assert!(want > own && own > 0.0, "the other ramps' paths count");
            assert!(
                (got - want).abs() <= 1e-6 * want,
                "{ramp:?}: {got} vs {want}"
            );
            if got > best.0 {
                best = (got, ramp);
            }
        }
        assert_eq!(explorer.most_informative(u_prev, &pool), Some(best.1));
    }

    #[test]
    fn a_warm_relearning_stops_at_its_iteration_bound() {
        // Hyperparameters far from the optimum (every log-parameter 3 below the fit, the noise
        // 1000 times larger): re-learning from them cannot finish within
        // `RELEARN_MAX_ITERS` iterations (the same start without the bound takes more), so
        // the bound is what stops it, and `observe()` blocks for a bounded time.
        let mut explorer = trained_on_low_inputs();
        let gp = explorer.transition.as_ref().unwrap();
        let far = Hyperparameters {
            theta: gp.theta().iter().map(|t| t - 3.0).collect(),
            noise_variance: gp.noise_variance_std() * 1e3,
        };
        explorer.params.params.model.max_iters = 200;
        explorer.refit(Some(far.clone()), true);
        let report = explorer.transition.as_ref().unwrap().report();
        assert_eq!(report.starts.len(), 1);
        assert_eq!(report.starts[0].iterations, RELEARN_MAX_ITERS, "{report:?}");
        // The same start without the bound goes on (what `observe()` did before the bound).
        let table = explorer.transition_table().unwrap();
        let m = &explorer.params.model;
        let spec = m
            .transition_kernel
            .spec(TRANSITION_DIM + explorer.plays.len(), TRANSITION_DIRECTION);
        let mut unbounded = m.gp_params(spec, crate::GpRole::Transition);
        unbounded.init = Some(far);
        unbounded.n_starts = 1;
        let gp = hbn_gp::fit(&unbounded, &table.inputs, &table.targets).unwrap();
        assert!(gp.report().starts[0].iterations > RELEARN_MAX_ITERS);
    }
}
