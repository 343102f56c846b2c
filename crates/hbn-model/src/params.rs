//! Training parameters: one set of defaults ([`HbnParams::default`]) and one check
//! ([`HbnParams::check`], linfa's ParamGuard pattern) that every front end goes through before
//! any work starts.
//!
//! Front ends never restate a default or a rule: clap reads its defaults from
//! [`HbnParams::default`], Python applies keyword arguments over it with [`HbnParams::set`], and
//! a failed check is a [`ConfigError`] naming the [`Param`], which the CLI shows as its `--flag`
//! and Python as its `keyword=`.

use crate::dataset::{SENSOR_DIM, SENSOR_DIRECTION, TRANSITION_DIM, TRANSITION_DIRECTION};
use hbn_core::{KernelSpec, LocalRegression, Metric, Profile};
use hbn_gp::{GpParams, MeanFunction, SparseParams, SubsetPolicy};
use serde::{Deserialize, Serialize};
use std::str::FromStr;

/// The covariance families behind the kernel names (Eq. 5, 17, 18 of the thesis and ARD
/// variants). Model files store a kernel as its family and direction factor.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
enum KernelFamily {
    /// Isotropic squared exponential (Eq. 5).
    Se,
    /// ARD squared exponential.
    SeArd,
    /// ARD Matern 5/2.
    Matern52,
    /// Mahalanobis SE with the empirical input covariance (Eq. 17).
    Mahalanobis,
    /// tanh-warped inputs (Eq. 18) under the Mahalanobis SE.
    Warped,
}

/// A GP's kernel, by name: `matern52`, `se-ard`, `se` or `thesis`.
///
/// - `matern52`: ARD Matern 5/2 (the default; each GP chooses between it and `se-ard` by its
///   evidence unless a kernel is set, [`HbnParams::kernel_evidence`]);
/// - `se-ard`: ARD squared exponential;
/// - `se`: isotropic squared exponential (the thesis' Eq. 5);
/// - `thesis`: the thesis' Eq. 19 kernel, tanh-warped inputs under a Mahalanobis SE times the
///   direction-advantage factor `1/2 (1 + g g')`. It helps open-loop simulation, but the
///   filter loses track at input reversals more often than with the ARD kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct KernelChoice {
    family: KernelFamily,
    direction: bool,
}

impl KernelChoice {
    /// ARD Matern 5/2.
    pub const MATERN52: Self = Self::plain(KernelFamily::Matern52);
    /// ARD squared exponential.
    pub const SE_ARD: Self = Self::plain(KernelFamily::SeArd);
    /// Isotropic squared exponential.
    pub const SE: Self = Self::plain(KernelFamily::Se);
    /// The thesis' Eq. 19 kernel.
    pub const THESIS: Self = Self {
        family: KernelFamily::Warped,
        direction: true,
    };
    /// Every kernel, in the order of [`KernelChoice::NAMES`].
    pub const ALL: [Self; 4] = [Self::MATERN52, Self::SE_ARD, Self::SE, Self::THESIS];
    /// Names accepted by [`FromStr`].
    pub const NAMES: &'static str = "matern52, se-ard, se, thesis";

    const fn plain(family: KernelFamily) -> Self {
        Self {
            family,
            direction: false,
        }
    }

    /// The kernel's name.
    pub const fn name(self) -> &'static str {
        match (self.family, self.direction) {
            (KernelFamily::Se, false) => "se",
            (KernelFamily::SeArd, false) => "se-ard",
            (KernelFamily::Matern52, false) => "matern52",
            (KernelFamily::Warped, true) => "thesis",
            // Not constructible through this API; a hand-edited model file may hold one.
            _ => "custom",
        }
    }

    /// The kernel structure for `dim` inputs with direction pair `dir`.
    pub fn spec(&self, dim: usize, dir: [usize; 2]) -> KernelSpec {
        let base = KernelSpec::se_ard(dim);
        let mut spec = match self.family {
            KernelFamily::Se => KernelSpec {
                metric: Metric::Isotropic,
                ..base
            },
            KernelFamily::SeArd => base,
            KernelFamily::Matern52 => KernelSpec {
                profile: Profile::Matern52,
                ..base
            },
            KernelFamily::Mahalanobis => KernelSpec {
                metric: Metric::Mahalanobis,
                ..base
            },
            KernelFamily::Warped => KernelSpec {
                metric: Metric::Mahalanobis,
                warp_units: 1,
                ..base
            },
        };
        if self.direction {
            spec.direction = Some(dir);
        }
        spec
    }

    /// The kernel whose [`KernelChoice::spec`] is `spec`, its direction pair aside (a vector
    /// model's GPs have none): the kernel a fitted GP uses. `None` for a structure no choice
    /// gives.
    pub fn of_spec(spec: &KernelSpec) -> Option<Self> {
        Self::ALL.into_iter().find(|k| {
            let mut s = k.spec(spec.dim, [0, 0]);
            s.direction = spec.direction;
            s == *spec
        })
    }
}

/// The default, `matern52`: the most robust single kernel across the simulators and noise
/// levels of the accuracy report; training chooses between it and SE-ARD per GP by evidence
/// unless a kernel is set ([`HbnParams::kernel_evidence`]).
impl Default for KernelChoice {
    fn default() -> Self {
        Self::MATERN52
    }
}

/// A kernel name that is not one of [`KernelChoice::NAMES`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown kernel {given:?}; choose one of {}", KernelChoice::NAMES)]
pub struct UnknownKernel {
    /// The text given.
    pub given: String,
}

impl FromStr for KernelChoice {
    type Err = UnknownKernel;
    fn from_str(s: &str) -> Result<Self, UnknownKernel> {
        let t = s.trim();
        Self::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(t))
            .ok_or_else(|| UnknownKernel {
                given: s.to_owned(),
            })
    }
}

impl std::fmt::Display for KernelChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Name, log path and unit of one signal.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SignalInfo {
    /// Short name (`u`, `x`, `y` by default).
    pub name: String,
    /// Where it was read from (a Foxglove message path), if from a log.
    pub path: Option<String>,
    /// Unit, if known.
    pub unit: Option<String>,
    /// The rate it was recorded at in the training logs (Hz, the median interval's; the first
    /// log's), if it was read from logs. Estimation compares a log's rates with it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub native_rate_hz: Option<f64>,
}

/// The three signals of the HBN.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Signals {
    /// Input `u` (e.g. valve pressure).
    pub input: SignalInfo,
    /// State `x` (e.g. bend angle; only needed for training and evaluation).
    pub state: SignalInfo,
    /// Sensor output `y` (e.g. strain sensor voltage).
    pub output: SignalInfo,
    /// The clock the training logs were read on (`log` or `header`), if read from logs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time_source: Option<String>,
    /// The largest gap allowed in the training logs (s), if read from logs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_gap_s: Option<f64>,
}

impl Default for Signals {
    fn default() -> Self {
        let s = |n: &str| SignalInfo {
            name: n.into(),
            path: None,
            unit: None,
            native_rate_hz: None,
        };
        Self {
            input: s("u"),
            state: s("x"),
            output: s("y"),
            time_source: None,
            max_gap_s: None,
        }
    }
}

/// Inducing points per GP of the default model's sparse candidate: by default, training
/// chooses on held-out data between exact GPs (on at most `max_points` samples) and sparse GPs
/// with this many inducing points (on every sample); see [`HbnParams::select`]. Neither is
/// better everywhere: sparse GPs learn from every sample of long noisy logs, exact GPs follow
/// noise-free or repeated inputs more closely (docs/sparse.md).
pub const DEFAULT_INDUCING: usize = 64;

/// Default [`HbnParams::memory`]: two play operators, of 5% and 20% of the input's range
/// (`docs/memory.md` has the measurements).
pub const DEFAULT_MEMORY: [f64; 2] = [0.05, 0.2];

/// The lag set that model selection tries by default besides none ([`Selection::lags`]): one
/// low-pass filter of the input with a time constant of 1 s (`docs/memory.md`, "Lags").
pub const DEFAULT_LAGS: [f64; 1] = [1.0];

/// The lag sets a vector model's default selection tries besides none, in place of
/// [`DEFAULT_LAGS`]: a time constant of 0.1 s (a pneumatic chamber filling behind its valve)
/// and one of 1 s (creep). A vector model trains one candidate per lag set, side by side, and
/// keeps the one held-out data prefer (`docs/vector.md`, "Lags"); lag sets given by the caller
/// ([`Selection::lags`] other than the default, `hbn train --lags`) replace these.
pub const VECTOR_DEFAULT_LAGS: [[f64; 1]; 2] = [[0.1], [1.0]];

/// What the sensor GP reads ([`HbnParams::sensor_inputs`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SensorInputs {
    /// `[x_{k-1}, y_{k-1}, x_k]`, the thesis' sensor (Eq. 16). With `y_{k-1}` among its inputs
    /// the GP can learn the output's increments from the state's, and then `y` does not pin the
    /// state's level: a drift of the estimate is never corrected.
    #[default]
    Thesis,
    /// `[x_{k-1}, x_k]`: the output as a function of the state's last two values, so every
    /// measurement says where the state is. It cannot model a sensor's own memory beyond what
    /// `x_{k-1}` carries.
    State,
    /// `[x_k, q^1_k, q^2_k]`: the state and two play operators of it
    /// ([`SENSOR_MEMORY`] of its range), the history a hysteretic sensor's output depends on,
    /// so every measurement says where the state is without the sensor GP learning increments
    /// from `y_{k-1}`. The filter carries the plays of its own estimates
    /// ([`hbn_core::HbnView::sensor_memory`]).
    Memory,
}

/// What the default model's sensor GP reads ([`HbnParams::sensor_inputs`]): the thesis'
/// inputs; model selection tries a sensor with memory of the state beside it
/// ([`Selection::sensor_inputs`]). Candidates with this sensor are named without it
/// (`matern52 exact`), the others with it (`matern52 exact sensor=memory`).
pub const DEFAULT_SENSOR_INPUTS: SensorInputs = SensorInputs::Thesis;

/// Radii of the play operators of the state that a sensor with memory reads
/// ([`SensorInputs::Memory`]), as fractions of the training state's range: the input's
/// default memory ([`DEFAULT_MEMORY`]) on the state.
pub const SENSOR_MEMORY: [f64; hbn_core::MAX_SENSOR_MEMORY] = DEFAULT_MEMORY;

impl SensorInputs {
    /// Every choice, in the order of their names.
    pub const ALL: [SensorInputs; 3] = [
        SensorInputs::Thesis,
        SensorInputs::State,
        SensorInputs::Memory,
    ];

    /// `thesis`, `state` or `memory`.
    pub const fn name(self) -> &'static str {
        match self {
            SensorInputs::Thesis => "thesis",
            SensorInputs::State => "state",
            SensorInputs::Memory => "memory",
        }
    }

    /// Whether this is the thesis' sensor (the default, which model files do not write).
    pub fn is_thesis(&self) -> bool {
        *self == SensorInputs::Thesis
    }

    /// The input dimension ([`hbn_core::SENSOR_DIM`], [`hbn_core::SENSOR_STATE_DIM`], or one
    /// more than [`SENSOR_MEMORY`]'s length).
    pub const fn dim(self) -> usize {
        match self {
            SensorInputs::Thesis => SENSOR_DIM,
            SensorInputs::State => hbn_core::SENSOR_STATE_DIM,
            SensorInputs::Memory => 1 + SENSOR_MEMORY.len(),
        }
    }

    /// The columns of the sensor row `[x_{k-1}, y_{k-1}, x_k, q^1_k, q^2_k]`
    /// ([`crate::build_dataset`]) this sensor reads.
    pub const fn columns(self) -> &'static [usize] {
        match self {
            SensorInputs::Thesis => &[0, 1, 2],
            SensorInputs::State => &[0, 2],
            SensorInputs::Memory => &[2, 3, 4],
        }
    }

    /// The direction pair of the advantage kernel in these inputs: `sgn(x_k - x_{k-1})`, or
    /// for a sensor with memory `sgn(x_k - q^1_k)`, which is the direction the state last
    /// moved in by more than the narrow play's band.
    pub const fn direction(self) -> [usize; 2] {
        match self {
            SensorInputs::Thesis => SENSOR_DIRECTION,
            SensorInputs::State => [1, 0],
            SensorInputs::Memory => [0, 1],
        }
    }

    /// Whether the sensor reads plays of the state ([`SensorInputs::Memory`]).
    pub const fn has_memory(self) -> bool {
        matches!(self, SensorInputs::Memory)
    }
}

impl std::fmt::Display for SensorInputs {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for SensorInputs {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        SensorInputs::ALL
            .into_iter()
            .find(|i| i.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| format!("unknown sensor inputs `{s}`; choose thesis, state or memory"))
    }
}

/// Which GPs have a linear prior mean ([`MeanFunction::Linear`]): the targets' least-squares
/// plane on the GP's inputs, subtracted before the kernel and added back in prediction.
///
/// It takes the near-linear part of a relation away from the kernel, whose likelihood is
/// otherwise nearly flat along a ridge of growing signal variance and length scales (see
/// [`HbnParams::max_signal_variance`]). On the sensor GP it can cost observability: `y_k` is
/// nearly `y_{k-1}` at a high rate, the plane puts its weight there, and the filter then learns
/// little about `x_k` from `y_k` (measured in `docs/sparse.md`, where the exact model lost the
/// state in one run of three); [`LinearMean::Transition`] leaves the sensor GP's constant mean.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LinearMean {
    /// Both GPs have a constant mean (the thesis).
    #[default]
    None,
    /// The transition GP has a linear mean, the sensor GP a constant one.
    Transition,
    /// Both GPs have a linear mean.
    Both,
}

impl LinearMean {
    /// Every choice, in the order of their names.
    pub const ALL: [LinearMean; 3] = [LinearMean::None, LinearMean::Transition, LinearMean::Both];

    /// `none`, `transition` or `both`.
    pub const fn name(self) -> &'static str {
        match self {
            LinearMean::None => "none",
            LinearMean::Transition => "transition",
            LinearMean::Both => "both",
        }
    }

    /// The prior mean of `role`'s GP.
    pub const fn mean(self, role: crate::GpRole) -> MeanFunction {
        match (self, role) {
            (LinearMean::Both, _) | (LinearMean::Transition, crate::GpRole::Transition) => {
                MeanFunction::Linear
            }
            _ => MeanFunction::Constant,
        }
    }
}

impl std::fmt::Display for LinearMean {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for LinearMean {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        LinearMean::ALL
            .into_iter()
            .find(|m| m.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| format!("unknown linear mean `{s}`; choose none, transition or both"))
    }
}

/// Training parameters of the HBN. [`HbnParams::default`] is the one place hbn's defaults are
/// written; [`HbnParams::check`] is the one place they are checked.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HbnParams {
    /// Sample rate of the trajectories (Hz); estimation must use the same.
    pub rate_hz: f64,
    /// Kernel of the transition GP.
    pub transition_kernel: KernelChoice,
    /// Kernel of the sensor GP.
    pub sensor_kernel: KernelChoice,
    /// Inducing points per GP: `Some(m)` trains sparse GPs (Titsias' bound) on every sample;
    /// `None` trains exact GPs on at most `max_points` samples. The default is `None`, with
    /// `Some(DEFAULT_INDUCING)` as the alternative that [`HbnParams::select`] may choose on
    /// held-out data.
    #[serde(default)]
    pub n_inducing: Option<usize>,
    /// Most support points per exact GP (unused by the sparse GP).
    pub max_points: usize,
    /// Policy when there are more samples.
    pub subset_policy: SubsetPolicy,
    /// Optimiser starts per GP.
    pub n_starts: usize,
    /// L-BFGS iterations per start.
    pub max_iters: u64,
    /// Seed of random starts and subsets.
    pub seed: u64,
    /// Standardise GP inputs and outputs.
    pub normalize: bool,
    /// Lower bound of each GP's noise variance (standardised units). The default `1e-4` (a noise
    /// standard deviation of 1% of the target's) keeps a GP fitted to noise-free or repeated
    /// data from interpolating kinks exactly, which makes the filter's Jacobians erratic and
    /// its estimate jump at the kinks.
    pub noise_floor: f64,
    /// BLR window: `+-` this fraction of each coordinate's range.
    pub blr_window: f64,
    /// BLR prior settings.
    pub blr: LocalRegression,
    /// Fraction of every run held out at a time to learn the filter's noise scales and default
    /// mode (filter-aware training, [`crate::tuning`]): blocked cross-validation with
    /// `floor(1 / validation)` folds (at most [`crate::tuning::MAX_FOLDS`]), fold `j` holding
    /// out the `j`-th block of this length from the end of every run. `0` turns tuning off
    /// (noise scales 1, EKF by default).
    #[serde(default)]
    pub validation: f64,
    /// Which GPs have a linear prior mean ([`LinearMean`]): a least-squares plane on their
    /// inputs that the kernel models the rest of.
    #[serde(default)]
    pub linear_mean: LinearMean,
    /// What the sensor GP reads ([`SensorInputs`]): by default the thesis'
    /// `[x_{k-1}, y_{k-1}, x_k]`, with the state and two plays of it
    /// ([`SensorInputs::Memory`]) tried on held-out data ([`HbnParams::select`]); or the
    /// state's `[x_{k-1}, x_k]` alone. The thesis' sensor is not written to model files (a file
    /// without the field has it).
    #[serde(default, skip_serializing_if = "SensorInputs::is_thesis")]
    pub sensor_inputs: SensorInputs,
    /// Largest signal variance of both GPs, relative to the variance of what each kernel
    /// models (the targets', or with a linear mean the residual's), or `None` for only the
    /// `1e5` box ([`hbn_gp::GpParams::max_signal_variance`]).
    #[serde(default)]
    pub max_signal_variance: Option<f64>,
    /// Play operators that give the transition GP the input's long memory
    /// ([`hbn_core::play`]): their radii as fractions of the training input's range
    /// (`max u - min u`), each in `(0, 1]`, at most [`hbn_core::MAX_PLAYS`]. Empty: the
    /// thesis' transition on `[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}]` alone.
    #[serde(default)]
    pub memory: Vec<f64>,
    /// Lags that give the transition GP the input's recent past ([`hbn_core::play`]):
    /// first-order low-pass filters of `u` with these time constants in seconds (each
    /// finite and positive), after the plays; plays and lags at most
    /// [`hbn_core::MAX_PLAYS`] in all. Creep and viscoelastic relaxation, common in soft
    /// actuators and sensors, depend on that past. Empty (the default): none.
    #[serde(default)]
    pub lags: Vec<f64>,
    /// Alternative kernels and inducing settings that filter-aware training chooses among on
    /// the held-out data ([`Selection`]). The default has one: sparse GPs with
    /// [`DEFAULT_INDUCING`] inducing points besides the primary exact GPs. Empty: this
    /// configuration only. Without held-out data (`validation = 0`, or too little data) the
    /// primary configuration is trained; the training report warns when the alternatives are
    /// not the default's (the user asked for a choice). Model files hold the
    /// configuration that was chosen, with this list empty.
    #[serde(default)]
    pub select: Selection,
    /// Kernels each GP chooses among by its evidence, before model selection
    /// ([`crate::KernelEvidence`]): each GP's exact GP (on the `max_points` subset) is fitted
    /// with every kernel listed, and the one with the highest log marginal likelihood becomes
    /// [`HbnParams::transition_kernel`] or [`HbnParams::sensor_kernel`]. The default lists
    /// [`DEFAULT_EVIDENCE_KERNELS`] (Matern 5/2 and SE-ARD): neither kernel is best on every
    /// system, and the evidence picks the better one per GP at the cost of one more exact fit
    /// each. Fewer than two: the kernels as set.
    /// Setting a kernel ([`HbnParams::set`] with [`Param::Kernel`],
    /// [`Param::TransitionKernel`] or [`Param::SensorKernel`]) empties it. Model files hold
    /// the chosen kernels with this list empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub kernel_evidence: Vec<KernelChoice>,
    /// Flash budget of the firmware export, in bytes (`None`: no budget). With a budget,
    /// training fits what an `f32` export can hold in that many bytes of constant tables:
    /// sparse GPs with the most inducing points of [`FIRMWARE_INDUCING_LADDER`] whose tables
    /// fit, no exact candidates, a prior of `x_0` thinned to an eighth of the budget, and a
    /// default mode among those whose tables fit (docs/firmware.md, "Training for a flash
    /// budget").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub firmware_budget: Option<u64>,
    /// Signal names, paths and units.
    pub signals: Signals,
}

/// The inducing settings a training with [`HbnParams::firmware_budget`] tries, largest first.
pub const FIRMWARE_INDUCING_LADDER: [usize; 7] = [64, 48, 32, 24, 16, 12, 8];

/// The smallest [`HbnParams::firmware_budget`] accepted (bytes).
pub const MIN_FIRMWARE_BUDGET: u64 = 1024;

/// Parses a size in bytes: a number with an optional unit `B`, `KB`/`K`/`KiB` (1024 bytes)
/// or `MB`/`M`/`MiB` (1024 KB), case-insensitive, e.g. `16KB`, `1.5MB`, `65536`. Fractions of a
/// byte are dropped.
pub fn parse_bytes(text: &str) -> Result<u64, String> {
    let t = text.trim();
    let split = t
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(t.len());
    let (number, unit) = t.split_at(split);
    let scale: f64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" | "kib" => 1024.0,
        "m" | "mb" | "mib" => 1024.0 * 1024.0,
        _ => {
            return Err(format!(
                "cannot read {text:?} as a size: write bytes, or a number with KB or MB (16KB, 1MB)"
            ));
        }
    };
    let value: f64 = number.parse().map_err(|_| {
        format!(
            "cannot read {text:?} as a size: write bytes, or a number with KB or MB (16KB, 1MB)"
        )
    })?;
    let bytes = value * scale;
    if !(bytes.is_finite() && bytes < 2f64.powi(63)) {
        return Err(format!("{text:?} is too large a size"));
    }
    Ok(bytes as u64)
}

/// The kernels each GP chooses among by evidence by default ([`HbnParams::kernel_evidence`]).
pub const DEFAULT_EVIDENCE_KERNELS: [KernelChoice; 2] =
    [KernelChoice::MATERN52, KernelChoice::SE_ARD];

/// Model selection on held-out data: alternatives to the primary configuration
/// ([`HbnParams::transition_kernel`], [`HbnParams::sensor_kernel`], [`HbnParams::n_inducing`]).
///
/// Every combination of a kernel (the primary pair, or one of `kernels` for both GPs) and an
/// inducing setting (the primary one, or one of `inducing`) is a [`Candidate`]
/// ([`HbnParams::candidates`]). Each is trained, and its filter tuned, on the same folds of
/// filter-aware training; the candidate whose default mode has the lowest held-out NLPD, among
/// those whose held-out nRMSE is no higher than the primary configuration's, becomes the model.
/// Each candidate costs one training, so `k` candidates take about `k` times as long. Without
/// held-out data (`validation = 0`, too little data) the primary configuration is trained.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Selection {
    /// Kernels (each for both GPs) to try besides the primary pair.
    #[serde(default)]
    pub kernels: Vec<KernelChoice>,
    /// Inducing settings to try besides the primary one (`None` is the exact GP).
    #[serde(default)]
    pub inducing: Vec<Option<usize>>,
    /// Lag sets ([`HbnParams::lags`], time constants in seconds) to try besides the primary
    /// one, each with every sparse configuration of the kernels and inducing settings above
    /// (none when every one is exact): a sparse candidate's filter tuning runs a step about
    /// twenty times cheaper than an exact one's. The default has one, [`DEFAULT_LAGS`]: creep
    /// and relaxation over about a second. An empty list is not written.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lags: Vec<Vec<f64>>,
    /// Sensor inputs ([`SensorInputs`]) to try besides the primary one, each with the primary
    /// configuration only (kernels, inducing setting, lags): one more candidate each. An empty
    /// list is not written.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sensor_inputs: Vec<SensorInputs>,
}

impl Selection {
    /// No alternatives.
    pub fn is_empty(&self) -> bool {
        self.kernels.is_empty()
            && self.inducing.is_empty()
            && self.lags.is_empty()
            && self.sensor_inputs.is_empty()
    }
}

/// One configuration model selection trains: both kernels, the inducing setting and the lags.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// Kernel of the transition GP.
    pub transition_kernel: KernelChoice,
    /// Kernel of the sensor GP.
    pub sensor_kernel: KernelChoice,
    /// Inducing points per GP, `None` for exact GPs.
    pub n_inducing: Option<usize>,
    /// Time constants of the transition's lags ([`HbnParams::lags`]); empty lags are not
    /// written.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lags: Vec<f64>,
    /// What the sensor GP reads ([`SensorInputs::Thesis`] is not written).
    #[serde(default, skip_serializing_if = "SensorInputs::is_thesis")]
    pub sensor_inputs: SensorInputs,
}

/// `matern52 exact`, `se-ard m=64`; both kernels when they differ (`se,matern52 exact`); lags
/// and then a sensor other than [`DEFAULT_SENSOR_INPUTS`] last (`matern52 m=64 lags=1`,
/// `se exact sensor=memory`).
impl std::fmt::Display for Candidate {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.transition_kernel == self.sensor_kernel {
            write!(f, "{} ", self.transition_kernel)?;
        } else {
            write!(f, "{},{} ", self.transition_kernel, self.sensor_kernel)?;
        }
        f.write_str(&self.shape())
    }
}

impl Candidate {
    /// The candidate without its kernels (`exact`, `m=64 lags=1`): what names it before the
    /// kernels are chosen by evidence.
    pub fn shape(&self) -> String {
        let mut out = match self.n_inducing {
            Some(m) => format!("m={m}"),
            None => "exact".to_owned(),
        };
        if !self.lags.is_empty() {
            let taus: Vec<String> = self.lags.iter().map(|t| t.to_string()).collect();
            out.push_str(&format!(" lags={}", taus.join(",")));
        }
        if self.sensor_inputs != DEFAULT_SENSOR_INPUTS {
            out.push_str(&format!(" sensor={}", self.sensor_inputs));
        }
        out
    }
}

impl Default for HbnParams {
    fn default() -> Self {
        Self {
            rate_hz: 100.0,
            transition_kernel: KernelChoice::default(),
            sensor_kernel: KernelChoice::default(),
            n_inducing: None,
            max_points: 500,
            subset_policy: SubsetPolicy::FarthestPoint,
            n_starts: 2,
            max_iters: 100,
            seed: 0,
            normalize: true,
            noise_floor: 1e-4,
            blr_window: 0.025,
            blr: LocalRegression::default(),
            validation: 0.25,
            linear_mean: LinearMean::None,
            sensor_inputs: DEFAULT_SENSOR_INPUTS,
            max_signal_variance: None,
            memory: DEFAULT_MEMORY.to_vec(),
            lags: Vec::new(),
            select: Selection {
                kernels: Vec::new(),
                inducing: vec![Some(DEFAULT_INDUCING)],
                lags: vec![DEFAULT_LAGS.to_vec()],
                sensor_inputs: vec![SensorInputs::Memory],
            },
            kernel_evidence: DEFAULT_EVIDENCE_KERNELS.to_vec(),
            firmware_budget: None,
            signals: Signals::default(),
        }
    }
}

/// A user-settable training parameter. Its Rust name is [`Param::name`] (the field of
/// [`HbnParams`]); the CLI and Python map it to their own spelling (`--max-points`,
/// `max_points=`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Param {
    /// [`HbnParams::rate_hz`].
    Rate,
    /// Both kernels at once (a shorthand front ends offer).
    Kernel,
    /// [`HbnParams::transition_kernel`].
    TransitionKernel,
    /// [`HbnParams::sensor_kernel`].
    SensorKernel,
    /// [`HbnParams::n_inducing`] (a count, or `exact`).
    Inducing,
    /// [`HbnParams::max_points`].
    MaxPoints,
    /// [`HbnParams::subset_policy`].
    SubsetPolicy,
    /// [`HbnParams::n_starts`].
    Starts,
    /// [`HbnParams::max_iters`].
    MaxIters,
    /// [`HbnParams::seed`].
    Seed,
    /// [`HbnParams::normalize`].
    Normalize,
    /// [`HbnParams::noise_floor`].
    NoiseFloor,
    /// [`HbnParams::blr_window`].
    BlrWindow,
    /// [`HbnParams::blr`] (the local regression's prior; set in Rust only).
    Blr,
    /// [`HbnParams::validation`].
    Validation,
    /// [`HbnParams::memory`] (a list of radii, possibly empty).
    Memory,
    /// [`HbnParams::lags`] (a list of time constants in seconds, possibly empty).
    Lags,
    /// [`HbnParams::linear_mean`] (`none`, `transition` or `both`).
    LinearMean,
    /// [`HbnParams::max_signal_variance`] (a number, or `none`).
    MaxSignalVariance,
    /// [`HbnParams::sensor_inputs`] (`thesis` or `state`, or a list of them: the first is the
    /// primary one, the rest [`Selection::sensor_inputs`]).
    SensorInputs,
    /// [`HbnParams::firmware_budget`] (bytes, or a size such as `16KB`, [`parse_bytes`]; `none`
    /// for no budget).
    FirmwareBudget,
}

impl Param {
    /// Every parameter, in the order front ends list them.
    pub const ALL: [Param; 21] = [
        Param::Rate,
        Param::Kernel,
        Param::TransitionKernel,
        Param::SensorKernel,
        Param::Inducing,
        Param::MaxPoints,
        Param::SubsetPolicy,
        Param::Starts,
        Param::MaxIters,
        Param::Seed,
        Param::Normalize,
        Param::NoiseFloor,
        Param::BlrWindow,
        Param::Blr,
        Param::Validation,
        Param::Memory,
        Param::Lags,
        Param::LinearMean,
        Param::MaxSignalVariance,
        Param::SensorInputs,
        Param::FirmwareBudget,
    ];

    /// The Rust name (the field of [`HbnParams`]; `kernel` for the shorthand).
    pub const fn name(self) -> &'static str {
        match self {
            Param::Rate => "rate_hz",
            Param::Kernel => "kernel",
            Param::TransitionKernel => "transition_kernel",
            Param::SensorKernel => "sensor_kernel",
            Param::Inducing => "n_inducing",
            Param::MaxPoints => "max_points",
            Param::SubsetPolicy => "subset_policy",
            Param::Starts => "n_starts",
            Param::MaxIters => "max_iters",
            Param::Seed => "seed",
            Param::Normalize => "normalize",
            Param::NoiseFloor => "noise_floor",
            Param::BlrWindow => "blr_window",
            Param::Blr => "blr",
            Param::Validation => "validation",
            Param::Memory => "memory",
            Param::Lags => "lags",
            Param::LinearMean => "linear_mean",
            Param::MaxSignalVariance => "max_signal_variance",
            Param::SensorInputs => "sensor_inputs",
            Param::FirmwareBudget => "firmware_budget",
        }
    }
}

impl std::fmt::Display for Param {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// What is wrong with a parameter's value.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum Problem {
    /// Must be a finite number greater than zero.
    #[error("must be a finite number > 0, got {value}")]
    NotPositive {
        /// The value given.
        value: f64,
    },
    /// Must lie in `(min, max]`.
    #[error("must be in ({min}, {max}], got {value}")]
    OutOfRange {
        /// The value given.
        value: f64,
        /// Exclusive lower bound.
        min: f64,
        /// Inclusive upper bound.
        max: f64,
    },
    /// Must lie in `[min, max]`.
    #[error("must be in [{min}, {max}], got {value}")]
    Between {
        /// The value given.
        value: f64,
        /// Inclusive lower bound.
        min: f64,
        /// Inclusive upper bound.
        max: f64,
    },
    /// Must be at least `min`.
    #[error("must be at least {min}, got {value}")]
    TooSmall {
        /// The value given.
        value: u64,
        /// The smallest allowed.
        min: u64,
    },
    /// Not one of the accepted names.
    #[error("unknown value {given:?}; choose one of {choices}")]
    Unknown {
        /// The text given.
        given: String,
        /// The accepted names.
        choices: &'static str,
    },
    /// A value of the wrong kind (e.g. text for a count).
    #[error("expected {expected}")]
    WrongType {
        /// What the parameter takes.
        expected: &'static str,
    },
    /// A structural rule (the reason names it).
    #[error("{reason}")]
    Invalid {
        /// Why.
        reason: &'static str,
    },
}

/// A parameter that failed its check: which one and why. Front ends show `param` as their own
/// spelling of it.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("invalid parameter `{param}`: {problem}")]
pub struct ConfigError {
    /// The parameter to change.
    pub param: Param,
    /// What is wrong with its value.
    pub problem: Problem,
}

impl ConfigError {
    fn new(param: Param, problem: Problem) -> Self {
        Self { param, problem }
    }
}

/// A parameter's value, for front ends that set parameters by name ([`HbnParams::set`],
/// [`HbnParams::get`]).
#[derive(Clone, Debug, PartialEq)]
pub enum ParamValue {
    /// A count, seed or iteration limit.
    Int(u64),
    /// A real number.
    Real(f64),
    /// A switch.
    Bool(bool),
    /// A name (kernel, subset policy).
    Text(String),
    /// Several values to choose among on held-out data ([`Param::Kernel`],
    /// [`Param::Inducing`]; [`Selection`]): the first is the primary one.
    List(Vec<ParamValue>),
}

/// [`HbnParams`] that passed [`HbnParams::check`]: training takes only these.
///
/// The second field is internal to model selection: a sparse candidate whose kernels are the
/// primary exact configuration's starts its hyperparameter search from those exact GPs' optimum
/// (one optimiser start), which takes about a third of the likelihood evaluations of its own
/// starts.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckedHbnParams(HbnParams, bool);

impl std::ops::Deref for CheckedHbnParams {
    type Target = HbnParams;
    fn deref(&self) -> &HbnParams {
        &self.0
    }
}

impl CheckedHbnParams {
    /// These parameters with sparse GPs of `m` inducing points and no other inducing setting
    /// to choose among (a rung of a flash budget's ladder, [`HbnParams::firmware_budget`]).
    pub(crate) fn with_sparse_only(&self, m: usize) -> Self {
        let mut p = self.0.clone();
        p.n_inducing = Some(m);
        p.select.inducing.clear();
        Self(p, false)
    }

    /// The parameters.
    pub fn into_inner(self) -> HbnParams {
        self.0
    }

    /// Replaces the signal descriptions (metadata, nothing to check).
    pub fn with_signals(mut self, signals: Signals) -> Self {
        self.0.signals = signals;
        self
    }

    /// Replaces the rate (e.g. by the rate a log was resampled to), checking it.
    pub fn with_rate(mut self, rate_hz: f64) -> Result<Self, ConfigError> {
        let mut p = self.0.clone();
        p.rate_hz = rate_hz;
        p.check_ref()?;
        self.0 = p;
        Ok(self)
    }

    /// The parameters of one of [`HbnParams::candidates`] (checked with the rest: every
    /// alternative was).
    pub(crate) fn for_candidate(&self, c: &Candidate) -> CheckedHbnParams {
        CheckedHbnParams(self.0.with_candidate(c), false)
    }

    /// [`Self::for_candidate`] for a sparse candidate whose searches start from the primary
    /// exact GPs ([`Self::starts_from_exact`]).
    pub(crate) fn starting_from_exact(&self, c: &Candidate) -> CheckedHbnParams {
        CheckedHbnParams(self.0.with_candidate(c), true)
    }

    /// Whether a sparse GP's hyperparameter search starts from the optimum of the exact GP with
    /// the same settings (one start) instead of its own starts.
    pub(crate) fn starts_from_exact(&self) -> bool {
        self.1
    }

    /// These parameters with `kernel` for the GP `role` (checked: every kernel of
    /// [`HbnParams::kernel_evidence`] was).
    pub(crate) fn with_kernel(&self, role: crate::GpRole, kernel: KernelChoice) -> Self {
        let mut p = self.0.clone();
        match role {
            crate::GpRole::Transition => p.transition_kernel = kernel,
            crate::GpRole::Sensor => p.sensor_kernel = kernel,
        }
        CheckedHbnParams(p, self.1)
    }

    /// These parameters without the kernel choice by evidence (the kernels as they are).
    pub(crate) fn without_kernel_evidence(mut self) -> Self {
        self.0.kernel_evidence.clear();
        self
    }

    /// GP parameters for one kernel structure (valid by construction).
    pub(crate) fn gp_params(&self, spec: KernelSpec, role: crate::GpRole) -> GpParams {
        let p = &self.0;
        let mut g = GpParams::new(spec);
        g.max_points = p.max_points;
        g.sparse = p.n_inducing.map(SparseParams::new);
        g.subset_policy = p.subset_policy;
        g.n_starts = p.n_starts;
        g.max_iters = p.max_iters;
        g.seed = p.seed;
        g.normalize = p.normalize;
        g.noise_floor = p.noise_floor;
        g.mean = p.linear_mean.mean(role);
        g.max_signal_variance = p.max_signal_variance;
        g
    }
}

/// The numbers of a list parameter (integers read as reals); `expected` names the type in
/// the error for anything else.
fn numbers(
    param: Param,
    values: Vec<ParamValue>,
    expected: &'static str,
) -> Result<Vec<f64>, ConfigError> {
    values
        .into_iter()
        .map(|r| match r {
            ParamValue::Real(r) => Ok(r),
            ParamValue::Int(r) => Ok(r as f64),
            _ => Err(ConfigError::new(param, Problem::WrongType { expected })),
        })
        .collect()
}

const SUBSET_NAMES: &str = "farthest-point, random";

const LAG_SETS: &str =
    "lag sets: lists of numbers (time constants in seconds), the first the primary one";

fn subset_name(p: SubsetPolicy) -> &'static str {
    match p {
        SubsetPolicy::FarthestPoint => "farthest-point",
        SubsetPolicy::Random => "random",
    }
}

impl HbnParams {
    /// The kernel of one GP.
    pub fn kernel(&self, role: crate::GpRole) -> KernelChoice {
        match role {
            crate::GpRole::Transition => self.transition_kernel,
            crate::GpRole::Sensor => self.sensor_kernel,
        }
    }

    /// The primary configuration.
    pub fn candidate(&self) -> Candidate {
        Candidate {
            transition_kernel: self.transition_kernel,
            sensor_kernel: self.sensor_kernel,
            n_inducing: self.n_inducing,
            lags: self.lags.clone(),
            sensor_inputs: self.sensor_inputs,
        }
    }

    /// Every configuration model selection trains ([`Selection`]), the primary one first, then
    /// kernel by kernel, each with every inducing setting (with the primary lags), then the
    /// alternative lag sets with every sparse one of those, then the primary configuration
    /// with each alternative sensor ([`Selection::sensor_inputs`]); no configuration twice.
    pub fn candidates(&self) -> Vec<Candidate> {
        let kernels = std::iter::once((self.transition_kernel, self.sensor_kernel))
            .chain(self.select.kernels.iter().map(|&k| (k, k)));
        let mut out: Vec<Candidate> = Vec::new();
        for (transition_kernel, sensor_kernel) in kernels {
            let inducing =
                std::iter::once(self.n_inducing).chain(self.select.inducing.iter().copied());
            for n_inducing in inducing {
                let c = Candidate {
                    transition_kernel,
                    sensor_kernel,
                    n_inducing,
                    lags: self.lags.clone(),
                    sensor_inputs: self.sensor_inputs,
                };
                if !out.contains(&c) {
                    out.push(c);
                }
            }
        }
        // Lag sets go with the sparse configurations only.
        let sparse: Vec<Candidate> = out
            .iter()
            .filter(|c| c.n_inducing.is_some())
            .cloned()
            .collect();
        for lags in &self.select.lags {
            for c in &sparse {
                let c = Candidate {
                    lags: lags.clone(),
                    ..c.clone()
                };
                if !out.contains(&c) {
                    out.push(c);
                }
            }
        }
        // Other sensors go with the primary configuration only.
        for &sensor_inputs in &self.select.sensor_inputs {
            let c = Candidate {
                sensor_inputs,
                ..self.candidate()
            };
            if !out.contains(&c) {
                out.push(c);
            }
        }
        out
    }

    /// These parameters with `c` as the configuration and no alternatives: what a model trained
    /// as candidate `c` records (training with them again trains the same model).
    pub fn with_candidate(&self, c: &Candidate) -> HbnParams {
        HbnParams {
            transition_kernel: c.transition_kernel,
            sensor_kernel: c.sensor_kernel,
            n_inducing: c.n_inducing,
            lags: c.lags.clone(),
            sensor_inputs: c.sensor_inputs,
            select: Selection::default(),
            kernel_evidence: Vec::new(),
            ..self.clone()
        }
    }

    /// Whether training chooses each GP's kernel by evidence ([`HbnParams::kernel_evidence`]
    /// lists two or more).
    pub fn chooses_kernels_by_evidence(&self) -> bool {
        self.kernel_evidence.len() > 1
    }

    /// The coefficients `a` of [`HbnParams::lags`] at [`HbnParams::rate_hz`]
    /// ([`hbn_core::lag_coefficient`]); an error when a time constant or the rate is not finite
    /// and positive (checked parameters never are).
    pub fn lag_coefficients(&self) -> Result<Vec<f64>, hbn_core::CoreError> {
        self.lags
            .iter()
            .map(|&tau| {
                hbn_core::lag_coefficient(tau, self.rate_hz).ok_or(
                    hbn_core::CoreError::InvalidSpec(
                        "a lag's time constant and the rate must be finite and positive",
                    ),
                )
            })
            .collect()
    }

    /// Inputs of the transition GP: the thesis' four plus one per play operator
    /// ([`HbnParams::memory`]) and lag ([`HbnParams::lags`]).
    pub fn transition_dim(&self) -> usize {
        TRANSITION_DIM + self.memory.len() + self.lags.len()
    }

    /// Checks every field once; training then trusts them. Each error names the [`Param`].
    pub fn check(self) -> Result<CheckedHbnParams, ConfigError> {
        self.check_ref()?;
        Ok(CheckedHbnParams(self, false))
    }

    /// [`HbnParams::check`] without consuming the parameters.
    pub fn check_ref(&self) -> Result<(), ConfigError> {
        let positive = |param, value: f64| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(ConfigError::new(param, Problem::NotPositive { value }))
            }
        };
        let at_least = |param, value: u64, min: u64| {
            if value >= min {
                Ok(())
            } else {
                Err(ConfigError::new(param, Problem::TooSmall { value, min }))
            }
        };
        positive(Param::Rate, self.rate_hz)?;
        at_least(
            Param::MaxPoints,
            self.max_points as u64,
            hbn_gp::MIN_POINTS as u64,
        )?;
        for m in std::iter::once(self.n_inducing)
            .chain(self.select.inducing.iter().copied())
            .flatten()
        {
            at_least(Param::Inducing, m as u64, 1)?;
        }
        if self.memory.len() > hbn_core::MAX_PLAYS {
            return Err(ConfigError::new(
                Param::Memory,
                Problem::Invalid {
                    reason: "at most 4 play operators",
                },
            ));
        }
        if self.memory.len() + self.lags.len() > hbn_core::MAX_PLAYS {
            return Err(ConfigError::new(
                Param::Lags,
                Problem::Invalid {
                    reason: "at most 4 play operators and lags in all",
                },
            ));
        }
        for lags in std::iter::once(&self.lags).chain(&self.select.lags) {
            if self.memory.len() + lags.len() > hbn_core::MAX_PLAYS {
                return Err(ConfigError::new(
                    Param::Lags,
                    Problem::Invalid {
                        reason: "at most 4 play operators and lags in all",
                    },
                ));
            }
            for &tau in lags {
                positive(Param::Lags, tau)?;
            }
        }
        for &r in &self.memory {
            if !(r.is_finite() && r > 0.0 && r <= 1.0) {
                return Err(ConfigError::new(
                    Param::Memory,
                    Problem::OutOfRange {
                        value: r,
                        min: 0.0,
                        max: 1.0,
                    },
                ));
            }
        }
        at_least(Param::Starts, self.n_starts as u64, 1)?;
        at_least(Param::MaxIters, self.max_iters, 1)?;
        positive(Param::NoiseFloor, self.noise_floor)?;
        if let Some(v) = self.max_signal_variance {
            positive(Param::MaxSignalVariance, v)?;
        }
        if let Some(b) = self.firmware_budget {
            at_least(Param::FirmwareBudget, b, MIN_FIRMWARE_BUDGET)?;
        }
        if !(self.blr_window.is_finite() && self.blr_window > 0.0 && self.blr_window <= 0.5) {
            return Err(ConfigError::new(
                Param::BlrWindow,
                Problem::OutOfRange {
                    value: self.blr_window,
                    min: 0.0,
                    max: 0.5,
                },
            ));
        }
        if !(self.validation.is_finite() && (0.0..=0.5).contains(&self.validation)) {
            return Err(ConfigError::new(
                Param::Validation,
                Problem::Between {
                    value: self.validation,
                    min: 0.0,
                    max: 0.5,
                },
            ));
        }
        self.blr.validate().map_err(|e| {
            ConfigError::new(
                Param::Blr,
                Problem::Invalid {
                    reason: core_reason(e),
                },
            )
        })?;
        for (param, kernel, dim, dir) in [
            (
                Param::TransitionKernel,
                self.transition_kernel,
                self.transition_dim(),
                TRANSITION_DIRECTION,
            ),
            (
                Param::SensorKernel,
                self.sensor_kernel,
                self.sensor_inputs.dim(),
                self.sensor_inputs.direction(),
            ),
        ]
        .into_iter()
        .chain(self.select.sensor_inputs.iter().map(|s| {
            (
                Param::SensorInputs,
                self.sensor_kernel,
                s.dim(),
                s.direction(),
            )
        }))
        .chain(
            self.select
                .kernels
                .iter()
                .chain(&self.kernel_evidence)
                .flat_map(|&k| {
                    [
                        (
                            Param::Kernel,
                            k,
                            self.transition_dim(),
                            TRANSITION_DIRECTION,
                        ),
                        (
                            Param::Kernel,
                            k,
                            SensorInputs::Thesis.dim(),
                            SensorInputs::Thesis.direction(),
                        ),
                        (
                            Param::Kernel,
                            k,
                            SensorInputs::State.dim(),
                            SensorInputs::State.direction(),
                        ),
                        (
                            Param::Kernel,
                            k,
                            SensorInputs::Memory.dim(),
                            SensorInputs::Memory.direction(),
                        ),
                    ]
                }),
        ) {
            kernel.spec(dim, dir).validate().map_err(|e| {
                ConfigError::new(
                    param,
                    Problem::Invalid {
                        reason: core_reason(e),
                    },
                )
            })?;
        }
        Ok(())
    }

    /// Sets one parameter by name (front ends that take parameters as keywords). The value's
    /// kind must fit; the range is checked later, by [`HbnParams::check`].
    pub fn set(&mut self, param: Param, value: ParamValue) -> Result<(), ConfigError> {
        let wrong = |expected| Err(ConfigError::new(param, Problem::WrongType { expected }));
        let kernel = |v: &str| {
            v.parse::<KernelChoice>().map_err(|e| {
                ConfigError::new(
                    param,
                    Problem::Unknown {
                        given: e.given,
                        choices: KernelChoice::NAMES,
                    },
                )
            })
        };
        let count = |v: u64| {
            usize::try_from(v).map_err(|_| {
                ConfigError::new(
                    param,
                    Problem::WrongType {
                        expected: "a count that fits this machine",
                    },
                )
            })
        };
        let inducing = |v: ParamValue| match v {
            ParamValue::Int(m) => Ok(Some(count(m)?)),
            ParamValue::Text(t) if t.trim().eq_ignore_ascii_case("exact") => Ok(None),
            ParamValue::Text(t) => Err(ConfigError::new(
                param,
                Problem::Unknown {
                    given: t,
                    choices: "a count of inducing points, or exact",
                },
            )),
            _ => Err(ConfigError::new(
                param,
                Problem::WrongType {
                    expected: "a count of inducing points, or \"exact\"",
                },
            )),
        };
        let kernel_value = |v: ParamValue| match v {
            ParamValue::Text(t) => kernel(&t),
            _ => Err(ConfigError::new(
                param,
                Problem::WrongType {
                    expected: "a kernel name",
                },
            )),
        };
        let sensor_inputs = |v: ParamValue| match v {
            ParamValue::Text(t) => t.parse::<SensorInputs>().map_err(|_| {
                ConfigError::new(
                    param,
                    Problem::Unknown {
                        given: t,
                        choices: "thesis, state, memory",
                    },
                )
            }),
            _ => Err(ConfigError::new(
                param,
                Problem::WrongType {
                    expected: "thesis or state, or a list of them",
                },
            )),
        };
        // A list: the first value is the primary one, the rest are alternatives.
        fn primary_and_rest<T>(
            param: Param,
            v: Vec<ParamValue>,
            one: impl Fn(ParamValue) -> Result<T, ConfigError>,
        ) -> Result<(T, Vec<T>), ConfigError> {
            let mut it = v.into_iter();
            let first = it.next().ok_or(ConfigError::new(
                param,
                Problem::WrongType {
                    expected: "a non-empty list",
                },
            ))?;
            Ok((one(first)?, it.map(one).collect::<Result<Vec<_>, _>>()?))
        }
        match (param, value) {
            (Param::Rate, ParamValue::Real(v)) => self.rate_hz = v,
            (Param::Rate, ParamValue::Int(v)) => self.rate_hz = v as f64,
            (Param::Kernel, ParamValue::List(v)) => {
                let (k, alternatives) = primary_and_rest(param, v, kernel_value)?;
                self.transition_kernel = k;
                self.sensor_kernel = k;
                self.select.kernels = alternatives;
                self.kernel_evidence.clear();
            }
            (Param::Kernel, ParamValue::Text(t)) => {
                let k = kernel(&t)?;
                self.transition_kernel = k;
                self.sensor_kernel = k;
                self.select.kernels.clear();
                self.kernel_evidence.clear();
            }
            (Param::TransitionKernel, ParamValue::Text(t)) => {
                self.transition_kernel = kernel(&t)?;
                self.kernel_evidence.clear();
            }
            (Param::SensorKernel, ParamValue::Text(t)) => {
                self.sensor_kernel = kernel(&t)?;
                self.kernel_evidence.clear();
            }
            (Param::Inducing, ParamValue::List(v)) => {
                let (m, alternatives) = primary_and_rest(param, v, inducing)?;
                self.n_inducing = m;
                self.select.inducing = alternatives;
            }
            (Param::Inducing, v) => {
                self.n_inducing = inducing(v)?;
                self.select.inducing.clear();
            }
            (Param::MaxPoints, ParamValue::Int(v)) => self.max_points = count(v)?,
            (Param::SubsetPolicy, ParamValue::Text(t)) => {
                self.subset_policy = match t.trim().to_ascii_lowercase().as_str() {
                    "farthest-point" => SubsetPolicy::FarthestPoint,
                    "random" => SubsetPolicy::Random,
                    _ => {
                        return Err(ConfigError::new(
                            param,
                            Problem::Unknown {
                                given: t,
                                choices: SUBSET_NAMES,
                            },
                        ));
                    }
                }
            }
            (Param::Starts, ParamValue::Int(v)) => self.n_starts = count(v)?,
            (Param::MaxIters, ParamValue::Int(v)) => self.max_iters = v,
            (Param::Seed, ParamValue::Int(v)) => self.seed = v,
            (Param::Normalize, ParamValue::Bool(v)) => self.normalize = v,
            (Param::NoiseFloor, ParamValue::Real(v)) => self.noise_floor = v,
            (Param::BlrWindow, ParamValue::Real(v)) => self.blr_window = v,
            (Param::Validation, ParamValue::Real(v)) => self.validation = v,
            (Param::Validation, ParamValue::Int(v)) => self.validation = v as f64,
            (Param::Memory, ParamValue::List(v)) => {
                self.memory = numbers(
                    param,
                    v,
                    "a list of numbers (fractions of the input's range)",
                )?;
            }
            (Param::Memory, ParamValue::Real(r)) => self.memory = vec![r],
            (Param::Memory, ParamValue::Text(t)) if t.trim().eq_ignore_ascii_case("none") => {
                self.memory.clear();
            }
            (Param::Memory, _) => {
                return wrong("a list of numbers (fractions of the input's range), or none");
            }
            // A list of lag sets: the primary one, then those model selection tries.
            (Param::Lags, ParamValue::List(v))
                if v.iter().any(|x| matches!(x, ParamValue::List(_))) =>
            {
                let mut sets = v.into_iter().map(|set| match set {
                    ParamValue::List(taus) => numbers(param, taus, LAG_SETS),
                    ParamValue::Text(t) if t.trim().eq_ignore_ascii_case("none") => Ok(Vec::new()),
                    ParamValue::Real(r) => Ok(vec![r]),
                    ParamValue::Int(r) => Ok(vec![r as f64]),
                    _ => Err(ConfigError::new(
                        param,
                        Problem::WrongType { expected: LAG_SETS },
                    )),
                });
                self.lags = sets.next().transpose()?.unwrap_or_default();
                self.select.lags = sets.collect::<Result<_, _>>()?;
            }
            (Param::Lags, ParamValue::List(v)) => {
                self.lags = numbers(param, v, "a list of numbers (time constants in seconds)")?;
                self.select.lags.clear();
            }
            (Param::Lags, ParamValue::Real(r)) => {
                self.lags = vec![r];
                self.select.lags.clear();
            }
            (Param::Lags, ParamValue::Int(r)) => {
                self.lags = vec![r as f64];
                self.select.lags.clear();
            }
            (Param::Lags, ParamValue::Text(t)) if t.trim().eq_ignore_ascii_case("none") => {
                self.lags.clear();
                self.select.lags.clear();
            }
            (Param::Lags, _) => {
                return wrong("a list of numbers (time constants in seconds), or none");
            }
            (Param::LinearMean, ParamValue::Text(t)) => {
                self.linear_mean = t.parse().map_err(|_| {
                    ConfigError::new(
                        param,
                        Problem::Unknown {
                            given: t,
                            choices: "none, transition, both",
                        },
                    )
                })?;
            }
            (Param::LinearMean, _) => return wrong("none, transition or both"),
            (Param::SensorInputs, ParamValue::List(v)) => {
                let (primary, alternatives) = primary_and_rest(param, v, sensor_inputs)?;
                self.sensor_inputs = primary;
                self.select.sensor_inputs = alternatives;
            }
            (Param::SensorInputs, v) => {
                self.sensor_inputs = sensor_inputs(v)?;
                self.select.sensor_inputs.clear();
            }
            (Param::MaxSignalVariance, ParamValue::Real(v)) => self.max_signal_variance = Some(v),
            (Param::MaxSignalVariance, ParamValue::Int(v)) => {
                self.max_signal_variance = Some(v as f64);
            }
            (Param::MaxSignalVariance, ParamValue::Text(t))
                if t.trim().eq_ignore_ascii_case("none") =>
            {
                self.max_signal_variance = None;
            }
            (Param::MaxSignalVariance, _) => return wrong("a number, or none"),
            (Param::FirmwareBudget, ParamValue::Int(v)) => self.firmware_budget = Some(v),
            (Param::FirmwareBudget, ParamValue::Text(t))
                if t.trim().eq_ignore_ascii_case("none") =>
            {
                self.firmware_budget = None;
            }
            (Param::FirmwareBudget, ParamValue::Text(t)) => {
                self.firmware_budget = Some(parse_bytes(&t).map_err(|_| {
                    ConfigError::new(
                        param,
                        Problem::WrongType {
                            expected: "bytes, or a size such as 16KB or 1MB",
                        },
                    )
                })?);
            }
            (Param::FirmwareBudget, _) => return wrong("bytes, or a size such as 16KB or 1MB"),
            (Param::Rate | Param::NoiseFloor | Param::BlrWindow | Param::Validation, _) => {
                return wrong("a number");
            }
            (Param::Kernel, _) => return wrong("a kernel name, or a list of them"),
            (Param::TransitionKernel | Param::SensorKernel, _) => {
                return wrong("a kernel name");
            }
            (Param::SubsetPolicy, _) => return wrong("a subset policy name"),
            (Param::MaxPoints | Param::Starts | Param::MaxIters | Param::Seed, _) => {
                return wrong("a non-negative integer");
            }
            (Param::Normalize, _) => return wrong("a bool"),
            (Param::Blr, _) => return wrong("LocalRegression settings (set them in Rust)"),
        }
        Ok(())
    }

    /// The value of one parameter (`None` for [`Param::Blr`], which is not a single value, and
    /// for the kernels while each GP chooses its own by evidence,
    /// [`HbnParams::kernel_evidence`]; [`Param::Kernel`] reads the transition kernel).
    pub fn get(&self, param: Param) -> Option<ParamValue> {
        Some(match param {
            Param::Rate => ParamValue::Real(self.rate_hz),
            // Chosen by evidence at training: no value to give (setting one turns the choice
            // off).
            Param::Kernel | Param::TransitionKernel | Param::SensorKernel
                if self.chooses_kernels_by_evidence() && self.select.kernels.is_empty() =>
            {
                return None;
            }
            Param::Kernel if !self.select.kernels.is_empty() => ParamValue::List(
                std::iter::once(self.transition_kernel)
                    .chain(self.select.kernels.iter().copied())
                    .map(|k| ParamValue::Text(k.to_string()))
                    .collect(),
            ),
            Param::Kernel | Param::TransitionKernel => {
                ParamValue::Text(self.transition_kernel.to_string())
            }
            Param::SensorKernel => ParamValue::Text(self.sensor_kernel.to_string()),
            Param::Inducing if !self.select.inducing.is_empty() => ParamValue::List(
                std::iter::once(self.n_inducing)
                    .chain(self.select.inducing.iter().copied())
                    .map(inducing_value)
                    .collect(),
            ),
            Param::Inducing => inducing_value(self.n_inducing),
            Param::MaxPoints => ParamValue::Int(self.max_points as u64),
            Param::SubsetPolicy => ParamValue::Text(subset_name(self.subset_policy).to_owned()),
            Param::Starts => ParamValue::Int(self.n_starts as u64),
            Param::MaxIters => ParamValue::Int(self.max_iters),
            Param::Seed => ParamValue::Int(self.seed),
            Param::Normalize => ParamValue::Bool(self.normalize),
            Param::NoiseFloor => ParamValue::Real(self.noise_floor),
            Param::BlrWindow => ParamValue::Real(self.blr_window),
            Param::Validation => ParamValue::Real(self.validation),
            Param::Memory => {
                ParamValue::List(self.memory.iter().map(|&r| ParamValue::Real(r)).collect())
            }
            Param::Lags if !self.select.lags.is_empty() => ParamValue::List(
                std::iter::once(&self.lags)
                    .chain(&self.select.lags)
                    .map(|set| ParamValue::List(set.iter().map(|&r| ParamValue::Real(r)).collect()))
                    .collect(),
            ),
            Param::Lags => {
                ParamValue::List(self.lags.iter().map(|&r| ParamValue::Real(r)).collect())
            }
            Param::LinearMean => ParamValue::Text(self.linear_mean.name().to_owned()),
            Param::SensorInputs if !self.select.sensor_inputs.is_empty() => ParamValue::List(
                std::iter::once(self.sensor_inputs)
                    .chain(self.select.sensor_inputs.iter().copied())
                    .map(|s| ParamValue::Text(s.name().to_owned()))
                    .collect(),
            ),
            Param::SensorInputs => ParamValue::Text(self.sensor_inputs.name().to_owned()),
            Param::MaxSignalVariance => match self.max_signal_variance {
                Some(v) => ParamValue::Real(v),
                None => ParamValue::Text("none".to_owned()),
            },
            Param::FirmwareBudget => ParamValue::Int(self.firmware_budget?),
            Param::Blr => return None,
        })
    }
}

fn inducing_value(m: Option<usize>) -> ParamValue {
    match m {
        Some(m) => ParamValue::Int(m as u64),
        None => ParamValue::Text("exact".to_owned()),
    }
}

fn core_reason(e: hbn_core::CoreError) -> &'static str {
    match e {
        hbn_core::CoreError::InvalidSpec(why) => why,
        hbn_core::CoreError::DimensionMismatch { .. } => "a dimension does not match",
        hbn_core::CoreError::NonFinite => "a value is NaN or infinite",
        hbn_core::CoreError::ScratchTooSmall { .. } => "scratch too small",
        hbn_core::CoreError::Empty => "empty",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every kernel is recognised from its structure, with or without a direction pair.
    #[test]
    fn a_kernel_is_recognised_from_its_structure() {
        for k in KernelChoice::ALL {
            let mut spec = k.spec(6, [0, 3]);
            assert_eq!(KernelChoice::of_spec(&spec), Some(k), "{k}");
            spec.direction = None;
            assert_eq!(KernelChoice::of_spec(&spec), Some(k), "{k}");
        }
        let mut odd = KernelChoice::SE.spec(6, [0, 0]);
        odd.warp_units = 2;
        assert_eq!(KernelChoice::of_spec(&odd), None);
    }

    /// Sizes in bytes, KB (1024) and MB (1024 KB), any case, with or without a space.
    #[test]
    fn firmware_budget_sizes_parse() {
        for (text, bytes) in [
            ("16KB", 16 * 1024),
            ("16kb", 16 * 1024),
            ("64 KiB", 64 * 1024),
            ("1MB", 1024 * 1024),
            ("1.5M", 1536 * 1024),
            ("4096", 4096),
            ("4096B", 4096),
            (" 8k ", 8192),
        ] {
            assert_eq!(parse_bytes(text), Ok(bytes), "{text}");
        }
        for bad in ["", "KB", "16 GB", "-1KB", "1e3", "sixteen", "16KB extra"] {
            assert!(parse_bytes(bad).is_err(), "{bad}");
        }
        let mut p = HbnParams::default();
        assert_eq!(p.get(Param::FirmwareBudget), None);
        p.set(Param::FirmwareBudget, ParamValue::Text("16KB".into()))
            .unwrap();
        assert_eq!(p.firmware_budget, Some(16384));
        assert_eq!(p.get(Param::FirmwareBudget), Some(ParamValue::Int(16384)));
        p.set(Param::FirmwareBudget, ParamValue::Int(65536))
            .unwrap();
        assert_eq!(p.firmware_budget, Some(65536));
        p.set(Param::FirmwareBudget, ParamValue::Text("none".into()))
            .unwrap();
        assert_eq!(p.firmware_budget, None);
        let e = p
            .set(Param::FirmwareBudget, ParamValue::Text("lots".into()))
            .unwrap_err();
        assert_eq!(e.param, Param::FirmwareBudget);
        p.firmware_budget = Some(512);
        assert_eq!(p.check_ref().unwrap_err().param, Param::FirmwareBudget);
        // Older parameter files (no field) read as no budget; no budget is not written.
        let json = serde_json::to_string(&HbnParams::default()).unwrap();
        assert!(!json.contains("firmware_budget"));
    }

    /// One bad value per checked parameter: the check names that parameter.
    #[test]
    fn every_check_names_its_parameter() {
        type Spoil = fn(&mut HbnParams);
        let bad: [(Param, Spoil); 21] = [
            (Param::FirmwareBudget, |p| p.firmware_budget = Some(100)),
            (Param::Lags, |p| p.lags = vec![0.0]),
            (Param::Lags, |p| p.lags = vec![f64::INFINITY]),
            (Param::Lags, |p| p.lags = vec![1.0; 3]),
            (Param::Memory, |p| p.memory = vec![0.0]),
            (Param::Memory, |p| p.memory = vec![1.5]),
            (Param::Memory, |p| p.memory = vec![0.1; 5]),
            (Param::Rate, |p| p.rate_hz = 0.0),
            (Param::Rate, |p| p.rate_hz = f64::NAN),
            (Param::MaxPoints, |p| p.max_points = 1),
            (Param::Inducing, |p| p.n_inducing = Some(0)),
            (Param::Validation, |p| p.validation = 0.6),
            (Param::Validation, |p| p.validation = f64::NAN),
            (Param::Starts, |p| p.n_starts = 0),
            (Param::MaxIters, |p| p.max_iters = 0),
            (Param::NoiseFloor, |p| p.noise_floor = 0.0),
            (Param::MaxSignalVariance, |p| {
                p.max_signal_variance = Some(0.0)
            }),
            (Param::MaxSignalVariance, |p| {
                p.max_signal_variance = Some(f64::INFINITY)
            }),
            (Param::BlrWindow, |p| p.blr_window = 0.6),
            (Param::BlrWindow, |p| p.blr_window = 0.0),
            (Param::Blr, |p| p.blr.nu0 = 1.0),
        ];
        for (param, spoil) in bad {
            let mut p = HbnParams::default();
            spoil(&mut p);
            let e = p.check().unwrap_err();
            assert_eq!(e.param, param, "{e}");
            assert!(e.to_string().contains(param.name()), "{e}");
        }
        assert!(HbnParams::default().check().is_ok());
        // The smallest accepted values pass.
        let edge = HbnParams {
            max_points: hbn_gp::MIN_POINTS,
            n_starts: 1,
            max_iters: 1,
            blr_window: 0.5,
            ..HbnParams::default()
        };
        assert!(edge.check().is_ok());
    }

    #[test]
    fn set_and_get_by_name() {
        let mut p = HbnParams::default();
        p.set(Param::MaxPoints, ParamValue::Int(7)).unwrap();
        p.set(Param::Kernel, ParamValue::Text("thesis".into()))
            .unwrap();
        p.set(Param::SubsetPolicy, ParamValue::Text("random".into()))
            .unwrap();
        assert_eq!(p.max_points, 7);
        assert_eq!(p.sensor_kernel, KernelChoice::THESIS);
        assert_eq!(p.sensor_kernel.to_string(), "thesis");
        // The removed names are refused, with the accepted ones in the message.
        for old in ["se-ard+dir", "ard", "matern", "mahalanobis", "warped"] {
            let e = p
                .set(Param::Kernel, ParamValue::Text(old.into()))
                .unwrap_err();
            assert!(
                e.to_string().contains("matern52, se-ard, se, thesis"),
                "{e}"
            );
        }
        for k in KernelChoice::ALL {
            assert_eq!(k.name().parse::<KernelChoice>().unwrap(), k);
        }
        assert_eq!(p.subset_policy, SubsetPolicy::Random);
        assert_eq!(p.get(Param::MaxPoints), Some(ParamValue::Int(7)));
        let e = p
            .set(Param::TransitionKernel, ParamValue::Text("rbf".into()))
            .unwrap_err();
        assert_eq!(e.param, Param::TransitionKernel);
        assert!(matches!(e.problem, Problem::Unknown { .. }));
        let e = p.set(Param::Seed, ParamValue::Real(1.5)).unwrap_err();
        assert_eq!(e.param, Param::Seed);
        // Every parameter but the BLR settings, the kernels (chosen by evidence at training)
        // and the firmware budget (none by default) reads back what the defaults hold.
        let d = HbnParams::default();
        for param in Param::ALL {
            let Some(v) = d.get(param) else {
                assert!(
                    matches!(
                        param,
                        Param::Blr
                            | Param::Kernel
                            | Param::TransitionKernel
                            | Param::SensorKernel
                            | Param::FirmwareBudget
                    ),
                    "{param}"
                );
                continue;
            };
            let mut q = HbnParams::default();
            q.set(param, v).unwrap();
            assert_eq!(q, d, "{param}");
        }
    }

    /// The default model is chosen on held-out data between exact GPs (the primary, trained
    /// alone when nothing is held out) and sparse GPs of `DEFAULT_INDUCING` points, without
    /// and with the `DEFAULT_LAGS`, and the exact GPs with a sensor with memory of the state.
    #[test]
    fn the_default_chooses_between_exact_and_sparse_gps() {
        let p = HbnParams::default();
        let names: Vec<String> = p.candidates().iter().map(|c| c.to_string()).collect();
        assert_eq!(
            names,
            [
                "matern52 exact",
                "matern52 m=64",
                "matern52 m=64 lags=1",
                "matern52 exact sensor=memory"
            ]
        );
        assert_eq!(
            p.get(Param::SensorInputs),
            Some(ParamValue::List(vec![
                ParamValue::Text("thesis".into()),
                ParamValue::Text("memory".into())
            ]))
        );
        assert_eq!(p.candidate().n_inducing, None);
        assert!(p.validation > 0.0);
        // Read back as the list the CLI and Python show.
        assert_eq!(
            p.get(Param::Inducing),
            Some(ParamValue::List(vec![
                ParamValue::Text("exact".into()),
                ParamValue::Int(DEFAULT_INDUCING as u64)
            ]))
        );
        // Without held-out data it still checks (the primary is then trained).
        let q = HbnParams {
            validation: 0.0,
            ..HbnParams::default()
        };
        assert!(q.check_ref().is_ok());
    }

    /// Lists set alternatives (the first value is the primary one), read back as lists, and
    /// give the candidates in order; a single value drops the alternatives.
    #[test]
    fn lists_set_the_candidates() {
        let text = |t: &str| ParamValue::Text(t.to_owned());
        let mut p = HbnParams::default();
        let kernels = ParamValue::List(vec![text("se-ard"), text("matern52")]);
        p.set(Param::Kernel, kernels.clone()).unwrap();
        let inducing = ParamValue::List(vec![ParamValue::Int(32), text("exact")]);
        p.set(Param::Inducing, inducing.clone()).unwrap();
        assert_eq!(p.get(Param::Kernel), Some(kernels));
        assert_eq!(p.get(Param::Inducing), Some(inducing));
        let names: Vec<String> = p.candidates().iter().map(|c| c.to_string()).collect();
        assert_eq!(
            names,
            [
                "se-ard m=32",
                "se-ard exact",
                "matern52 m=32",
                "matern52 exact",
                "se-ard m=32 lags=1",
                "matern52 m=32 lags=1",
                "se-ard m=32 sensor=memory"
            ]
        );
        assert!(p.check_ref().is_ok());
        // A candidate's parameters have no alternatives left.
        let c = p.candidates()[3].clone();
        let q = p.with_candidate(&c);
        assert_eq!(q.candidates(), vec![c]);
        // A repeated value is one candidate; a bad one names the parameter.
        p.set(
            Param::Inducing,
            ParamValue::List(vec![text("exact"), text("exact")]),
        )
        .unwrap();
        // Kernels se-ard and matern52, exact, and the primary with the state-only sensor.
        assert_eq!(p.candidates().len(), 3);
        let e = p
            .set(
                Param::Kernel,
                ParamValue::List(vec![text("se"), text("rbf")]),
            )
            .unwrap_err();
        assert_eq!(e.param, Param::Kernel);
        let e = p
            .set(Param::Inducing, ParamValue::List(vec![]))
            .unwrap_err();
        assert_eq!(e.param, Param::Inducing);
        p.set(Param::Kernel, text("se")).unwrap();
        p.set(Param::Inducing, ParamValue::Int(8)).unwrap();
        p.set(Param::Lags, text("none")).unwrap();
        assert!(!p.select.is_empty());
        p.set(Param::SensorInputs, text("thesis")).unwrap();
        assert!(p.select.is_empty());
        assert_eq!(p.candidates().len(), 1);
    }

    #[test]
    fn lag_sets_are_tried_with_the_sparse_configurations_and_set_as_lists_of_lists() {
        let d = HbnParams::default();
        let names: Vec<String> = d.candidates().iter().map(|c| c.to_string()).collect();
        assert_eq!(
            names,
            [
                "matern52 exact",
                "matern52 m=64",
                "matern52 m=64 lags=1",
                "matern52 exact sensor=memory"
            ]
        );
        // Every configuration exact: no lag set is tried (`n_inducing=None` in Python trains
        // exact GPs, choosing only the sensor's inputs).
        let exact = HbnParams {
            select: Selection {
                inducing: Vec::new(),
                ..d.select.clone()
            },
            ..d.clone()
        };
        let memory = Candidate {
            sensor_inputs: SensorInputs::Memory,
            ..exact.candidate()
        };
        assert_eq!(exact.candidates(), vec![exact.candidate(), memory]);
        // A list of lists: the primary set, then the alternatives; read back the same way.
        let mut p = HbnParams::default();
        let set =
            |taus: &[f64]| ParamValue::List(taus.iter().map(|&t| ParamValue::Real(t)).collect());
        p.set(
            Param::Lags,
            ParamValue::List(vec![set(&[0.5]), set(&[]), set(&[2.0, 3.0])]),
        )
        .unwrap();
        assert_eq!(
            (p.lags.clone(), p.select.lags.clone()),
            (vec![0.5], vec![vec![], vec![2.0, 3.0]])
        );
        assert_eq!(
            p.get(Param::Lags),
            Some(ParamValue::List(vec![
                set(&[0.5]),
                set(&[]),
                set(&[2.0, 3.0])
            ]))
        );
        // One set: no alternatives.
        p.set(Param::Lags, set(&[1.0])).unwrap();
        assert_eq!(
            (p.lags.clone(), p.select.lags.is_empty()),
            (vec![1.0], true)
        );
        p.set(Param::Lags, ParamValue::Text("none".into())).unwrap();
        assert_eq!((p.lags.is_empty(), p.select.lags.is_empty()), (true, true));
        // Alternatives are checked like the primary set.
        let bad = HbnParams {
            select: Selection {
                lags: vec![vec![0.0]],
                ..Selection::default()
            },
            ..HbnParams::default()
        };
        assert_eq!(bad.check().unwrap_err().param, Param::Lags);
        let too_many = HbnParams {
            select: Selection {
                lags: vec![vec![1.0; 3]],
                ..Selection::default()
            },
            ..HbnParams::default()
        };
        assert_eq!(too_many.check().unwrap_err().param, Param::Lags);
    }

    /// Sensor inputs set by name (a list: the primary, then the alternatives), read back the
    /// same way, and a model file without the field reads as the thesis'.
    #[test]
    fn sensor_inputs_are_set_checked_and_chosen() {
        let text = |t: &str| ParamValue::Text(t.to_owned());
        let mut p = HbnParams::default();
        p.set(Param::SensorInputs, text("state")).unwrap();
        assert_eq!(p.sensor_inputs, SensorInputs::State);
        assert!(p.select.sensor_inputs.is_empty());
        assert_eq!(p.get(Param::SensorInputs), Some(text("state")));
        let both = ParamValue::List(vec![text("state"), text("thesis")]);
        p.set(Param::SensorInputs, both.clone()).unwrap();
        assert_eq!(p.get(Param::SensorInputs), Some(both));
        assert_eq!(p.candidate().sensor_inputs, SensorInputs::State);
        assert!(p.check_ref().is_ok());
        let e = p.set(Param::SensorInputs, text("level")).unwrap_err();
        assert_eq!(e.param, Param::SensorInputs);
        assert!(e.to_string().contains("thesis, state, memory"), "{e}");
        let e = p.set(Param::SensorInputs, ParamValue::Int(2)).unwrap_err();
        assert_eq!(e.param, Param::SensorInputs);
        // Not written when it is the thesis' sensor, so older readers and files agree.
        let json = serde_json::to_string(&HbnParams {
            select: Selection::default(),
            ..HbnParams::default()
        })
        .unwrap();
        assert!(!json.contains("sensor_inputs"), "{json}");
        let back: HbnParams = serde_json::from_str(&json).unwrap();
        assert_eq!(back.sensor_inputs, SensorInputs::Thesis);
        let state = serde_json::to_string(&HbnParams {
            sensor_inputs: SensorInputs::State,
            ..HbnParams::default()
        })
        .unwrap();
        assert!(state.contains("\"sensor_inputs\":\"state\""), "{state}");
    }
}
