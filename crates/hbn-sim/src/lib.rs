//! # hbn-sim: simulators of hysteretic actuator/sensor systems
//!
//! Generates `(u, x, y)` logs like those of HBN.md section 9: an input `u` (e.g. valve pressure)
//! drives a hysteretic actuator `H_a: u -> x` (e.g. finger bend); a soft sensor `H_s: x -> y`
//! (e.g. strain-sensor voltage), itself mildly hysteretic, of another family, and followed by a
//! smooth static nonlinearity, reads the state. Everything is deterministic given
//! `(SimConfig, u)`. The multi-signal systems ([`MultiKind`], [`simulate_multi`]) have several
//! inputs, a vector state and several sensors, cross-coupled.
//!
//! ## Systems ([`SystemKind`])
//!
//! | name | actuator `u -> x` | sensor `x -> y` (before `tanh`) |
//! |---|---|---|
//! | `maxwell-slip` | [`MaxwellSlip::default`] | [`Duhem`] `a = 10, b = 0.5, k_lin = 1` |
//! | `generalized-pi` | [`PrandtlIshlinskii::default`] | [`BoucWen`] `A = 1, beta = 6, gamma = 2, n = 1, k_lin = 1, k_z = 0.4` |
//! | `bouc-wen` | [`BoucWen::default`] | [`PrandtlIshlinskii`] envelope `2 tanh(x / 2)`, `p0 = 0.3`, radii `0.03, 0.06, 0.09`, weights `0.3` |
//! | `preisach` | [`Preisach::default`] | [`MaxwellSlip`] `k0 = 0.8`, 4 elements `k = 0.2`, `F = 0.004 i` |
//! | `duhem` | [`Duhem::default`] | `0.85 x + 0.15 P(x)`, `P` = [`Preisach`] 40 levels on `[-0.05, 1.05]`, width `0.3 +- 0.1`, centre `0.5 +- 0.35` |
//! | `soft-actuator` | lag (`tau = 0.08 s`) -> [`BoucWen`] `A = 1, beta = 3, gamma = 1, n = 1, k_lin = 1, k_z = -0.5` (lagging, counter-clockwise loop) -> creep | SLS (`tau = 0.25 s`, `rho = 0.4`) -> [`Duhem`] `a = 10, b = 0.5, k_lin = 1` |
//! | `soft-actuator-load` | `soft-actuator`'s, driven by `u + d`: a supply-pressure disturbance `d` (AR(1), correlation time 0.3 s) enters before the lag | `soft-actuator`'s |
//!
//! Every sensor ends with the saturating nonlinearity `y = tanh(1.5 h) / tanh(1.5)`, so `y` is
//! never an affine function of `x`.
//!
//! `soft-actuator` is the realistic, rate-dependent scenario (all lags use `dt = 1 / rate_hz`
//! and the exact zero-order-hold discretisation `s[k] = s[k-1] + (1 - exp(-dt/tau)) (t[k] - s[k-1])`):
//! - pneumatic lag: pressure `p` follows `u` with `tau = 0.08 s`;
//! - Bouc-Wen bend `b = H(p)`;
//! - creep (viscoelastic relaxation): `x_raw = 0.85 b + c`, `c` follows `0.15 b` with
//!   `tau = 1.5 s`;
//! - sensor: standard-linear-solid strain response `v = x + 0.4 (x - q)`, `q` follows `x` with
//!   `tau = 0.25 s` (overshoots under fast motion, relaxes to `x` at rest), then Duhem, then
//!   the `tanh` saturation.
//!
//! `soft-actuator-load` is the same actuator and sensor (the same calibration; noise-free, the
//! same signals bit for bit) whose state disturbance is a slowly varying supply pressure added
//! to `u` before the lag, so it propagates through the lag, the hysteresis and the creep, as a
//! real actuator's does (see the noise model).
//!
//! The other five systems are rate-independent: their outputs depend on the input sequence
//! only, not on `rate_hz`.
//!
//! ## Calibration and initial state
//!
//! Each system is calibrated once, deterministically, by a quasi-static sweep
//! `u: 0 -> 1 -> 0` (steps of 0.005, lags following their targets exactly): raw outputs are
//! mapped affinely so that the major loop spans exactly `[0, 1]`, i.e. `x = 0` and `y = 0` at
//! `u = 0` on the descending branch, `x = 1` and `y = 1` at `u = 1`. A simulation starts from
//! the *relaxed* state: the virgin (demagnetised) state preconditioned by that one quasi-static
//! cycle, with every dynamic state (lag, creep, SLS) at rest at `u = 0`. Minor loops stay
//! inside the major loop, so for inputs in `[0, 1]` both signals stay close to `[0, 1]`
//! (rate-dependent overshoot aside). Hence the nominal ranges are
//! [`SystemKind::nominal_range_x`] `= 1` and [`SystemKind::nominal_range_y`] `= 1` for every
//! system.
//!
//! ## Noise model
//!
//! The thesis' additive `gain * U[-0.5, 0.5]` noise, scaled to the signal. With
//! `g = noise_gain` and, at every sample `k`, first `eta_x[k]` then `eta_y[k]` drawn as
//! `uniform() - 0.5` from one `hbn_core::rng::Rng` seeded with `seed` xor a fixed salt:
//! - physical disturbance of the state: `x[k] = x_clean[k] + g * 0.02 * range_x * eta_x[k]`,
//!   where `x_clean` is the actuator output (the disturbance is not fed back into the
//!   actuator) and `range_x` the fixed nominal range above (the same for every input);
//! - the sensor reads the disturbed state (the disturbance is real motion) plus measurement
//!   noise: `y[k] = H_s(x[0..=k])[k] + g * 0.02 * range_y * eta_y[k]`.
//!
//! So `g = 0` gives exactly the clean signals, and with `g = 1` the state disturbance stays
//! within `+-0.01 * range_x` with variance `(0.02 range_x)^2 / 12`.
//!
//! **`soft-actuator-load`: a disturbance that propagates.** There `eta_x[k]` drives a
//! supply-pressure disturbance instead, which enters the actuator **upstream** of its dynamics:
//! - `d[k] = a d[k-1] + sqrt(1 - a^2) g * 0.02 * range_x * eta_x[k]`, `d[-1] = 0`,
//!   `a = exp(-dt / 0.3 s)`: an AR(1) process with a correlation time of 0.3 s and the
//!   stationary variance of the others' state disturbance, `(g 0.02 range_x)^2 / 12`, at any
//!   rate;
//! - `x[k]` is the actuator's output for the input `u[k] + d[k]` (the pneumatic lag, the
//!   Bouc-Wen bend and the creep all run on the disturbed pressure), so `x[k]` carries the
//!   disturbances of every sample before it;
//! - the sensor reads `x` with the same measurement noise as above.
//!
//! With `g = 1` the state strays from the noise-free run by a standard deviation of about
//! 0.005 (the others': 0.0058), and that deviation 0.1 s later is still correlated at about
//! 0.9 with it; `g = 0` gives exactly the clean `soft-actuator`. The future of the log tells
//! about the present here, which is what a smoother (`docs/smoothing.md`) needs.
//!
//! ## Multi-signal systems ([`MultiKind`])
//!
//! [`simulate_multi`] runs systems with several inputs `u_c` (chamber valves), a vector state
//! `x_i` (tip coordinates) and several sensors `y_j`. Every input drives its chamber: a
//! pneumatic lag (pressure `p_c` follows `u_c`, discretised like `soft-actuator`'s), then the
//! chamber's own hysteretic bend `b_c = H_c(p_c)`, calibrated to `[0, 1]`. The tip's target is
//! a mixing of all bends, `m_i = sum_c M[i][c] b_c`, and the tip follows it through a lag
//! (`tau_tip`); `x_i` is the tip calibrated to `[0, 1]`. Each sensor reads a mixture of the
//! whole tip, `v_j = sum_i S[j][i] x_i / sum_i S[j][i]`, through its own mildly hysteretic
//! operator `lin v + k_op H_j(v)` of a family no chamber uses, the affine calibration and the
//! saturation `tanh(1.5 h) / tanh(1.5)`.
//!
//! | name | inputs / states / sensors | chambers: lag `tau`, bend `H_c` | `tau_tip` | sensors `H_j` (before `tanh`) |
//! |---|---|---|---|---|
//! | `finger` | 2 / 2 (planar tip: reach, drop) / 3 | 0.08 s, [`BoucWen`] `A = 1, beta = 2.5, gamma = 0.5, k_lin = 1, k_z = -0.5`; 0.12 s, [`PrandtlIshlinskii::default`] | 0.04 s | [`Duhem`] `a = 10, b = 0.5, k_lin = 1`; [`MaxwellSlip`] `k0 = 0.8`, 4 elements `k = 0.2`, `F = 0.004 i`; `0.85 v + 0.15 P(v)`, `P` = [`Preisach`] 40 levels on `[-0.05, 1.05]`, width `0.3 +- 0.1`, centre `0.5 +- 0.35` |
//! | `arm` | 3 / 3 (spatial tip) / 4 | 0.06 s, [`BoucWen`] `A = 1, beta = 3, gamma = 1, k_lin = 1, k_z = -0.5`; 0.09 s, [`Preisach`] 30 levels on `[0, 1]`, width `0.3 +- 0.15`, centre `0.5 +- 0.3`; 0.12 s, [`Duhem`] `a = 4, b = -0.4, k_lin = 1` | 0.06 s | [`MaxwellSlip`] `k0 = 0.8`, 4 elements `k = 0.2`, `F = 0.004 i`; [`PrandtlIshlinskii`] envelope `2 tanh(v / 2)`, `p0 = 0.3`, radii `0.03, 0.06, 0.09`, weights `0.3`; [`MaxwellSlip`] `k0 = 0.9`, 3 elements `k = 0.3`, `F = 0.003, 0.009, 0.015`; [`PrandtlIshlinskii`] envelope `1.5 tanh(0.7 v)`, `p0 = 0.5`, radii `0.02, 0.05`, weights `0.25` |
//!
//! Every chamber's loop lags its pressure (counter-clockwise), so the chambers' loops add up
//! in the tip instead of cancelling.
//!
//! The mixing matrices are [`FINGER_STATE_MIX`], [`FINGER_SENSOR_MIX`], [`ARM_STATE_MIX`] and
//! [`ARM_SENSOR_MIX`] (their docs give the geometry behind each weight and sign). Every state
//! component depends on every input and every sensor on every state component: tip component
//! `i` takes chamber `i` with weight 1 and every other chamber with a weight of magnitude
//! between 1/3 and 1/2; each sensor's smallest weight is at least a third of its largest.
//!
//! **Calibration** is quasi-static (every lag follows its target exactly), one stage at a
//! time: from the virgin state, all inputs together run the cycle `0 -> 1 -> 0` (steps of
//! 0.005) twice, and the `[min, max]` of the stage's raw output over the second cycle is
//! mapped to `[0, 1]`: first each chamber's bend, then each tip component, then each sensor.
//! That sweep therefore spans exactly `[0, 1]` in every state component and every sensor, and
//! the nominal ranges ([`MultiKind::nominal_range_x`], [`MultiKind::nominal_range_y`]) are 1. A
//! simulation starts from the relaxed state: virgin, then one quasi-static cycle, every lag at
//! rest at `u = 0`. With independent inputs in `[0, 1]` the state stays in about `[0, 1]`; a
//! sensor with a negative weight can leave it a little (its mixture moves against the sweep).
//!
//! **Noise** follows the scalar model with one generator (`seed` xor a salt of its own): at
//! every sample `k`, first every state component's disturbance in component order, then every
//! sensor's measurement noise, each `g * 0.02 * range * (uniform() - 0.5)`. The state
//! disturbance is real motion of the tip and **enters the tip's lag state**: the tip is pushed
//! by it and relaxes back with `tau_tip`, so a disturbance persists into the following samples
//! (the recorded `x_i[k]` is the tip after this sample's push; the sensors read it). So with
//! `g = 1`, `x_i[k]` is within `+-0.01` of what the system would have given at `k` without
//! this sample's push, but strays further from a noise-free run. `g = 0` gives exactly the
//! clean signals. Inputs: [`generate_multi_input`] gives independent random ramps, one per
//! input.
//!
//! ## The floors under estimation
//!
//! [`oracle_estimate`] gives, for a simulated trajectory, the exact posterior mean of each state
//! given the input and sensor output so far, the true past states and the simulator itself: no
//! causal estimator has a lower expected squared error on that trajectory, so it measures how
//! much any estimator could still gain (`docs/accuracy.md` reports it beside the estimators).
//! [`oracle_smooth_estimate`] is its two-sided counterpart: the posterior given also the
//! outputs up to `lookahead` samples later and the true states at every other sample, the
//! floor under any smoother; the ratio of the two is the most smoothing could gain there.
//! Both need a disturbance that does not propagate, and refuse `soft-actuator-load`
//! ([`SimError::NoExactOracle`]).
//!
//! On the multi-signal systems, [`multi_posterior_estimate`] gives the posterior of the state
//! given the inputs and outputs so far and the simulator's own model (not the true past
//! states), found by a particle filter: the least expected squared error of any causal
//! estimator, up to the particles' sampling error, which only raises it. `docs/vector.md`
//! reports it beside the vector and scalar models.
//!
//! ## Building blocks
//!
//! The operators ([`PlayOperator`], [`PrandtlIshlinskii`], [`MaxwellSlip`], [`BoucWen`],
//! [`Preisach`], [`Duhem`]) are public and implement [`Hysteresis`].

#![forbid(unsafe_code)]
#![deny(missing_docs)]

mod input;
mod multi;
mod operators;
mod oracle;
mod systems;

use hbn_core::rng::Rng;

pub use input::{DEFAULT_MAX_INCREMENT, InputKind, generate_input};
pub use multi::{
    ARM_ELONGATION_SQ, ARM_SENSOR_MIX, ARM_STATE_MIX, FINGER_SENSOR_MIX, FINGER_STATE_MIX,
    MultiConfig, MultiKind, MultiPosterior, MultiSimulator, MultiTrajectory, generate_multi_input,
    multi_posterior_estimate, simulate_multi, simulate_multi_random,
};
pub use operators::{
    BoucWen, BoucWenParams, Duhem, Envelope, Hysteresis, MaxwellSlip, PlayOperator,
    PrandtlIshlinskii, Preisach, PreisachDensity,
};
pub use oracle::{ORACLE_GRID, OracleEstimate, oracle_estimate, oracle_smooth_estimate};

/// Admissible input interval of [`simulate`] (inputs are nominally in `[0, 1]`).
pub const INPUT_RANGE: (f64, f64) = (-0.5, 1.5);

/// Salt mixed into the seed of the noise generator (see the crate docs).
const NOISE_SALT: u64 = 0x00C0_FFEE_D15E_A5E5;

/// Errors of the simulators.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A system name that does not exist.
    #[error("unknown system `{name}`; valid systems: {valid}")]
    UnknownSystem {
        /// The name given.
        name: String,
        /// Comma-separated list of the valid names.
        valid: String,
    },
    /// A parameter outside its domain.
    #[error("invalid parameter `{name}` = {value}: {reason}")]
    InvalidParameter {
        /// Parameter name.
        name: &'static str,
        /// Offending value.
        value: f64,
        /// What is required.
        reason: &'static str,
    },
    /// An input sample is NaN or infinite.
    #[error("input sample {index} is not finite ({value})")]
    NonFiniteInput {
        /// Sample index.
        index: usize,
        /// Offending value.
        value: f64,
    },
    /// An input sample outside [`INPUT_RANGE`].
    #[error("input sample {index} = {value} is outside [{lo}, {hi}]")]
    InputOutOfRange {
        /// Sample index.
        index: usize,
        /// Offending value.
        value: f64,
        /// Lower admissible bound.
        lo: f64,
        /// Upper admissible bound.
        hi: f64,
    },
    /// A multi-signal simulation given a number of input signals other than its system's.
    #[error("`{system}` takes {expected} input signals, got {got}")]
    InputCount {
        /// The system's name.
        system: &'static str,
        /// Inputs the system takes.
        expected: usize,
        /// Input signals given.
        got: usize,
    },
    /// Input signals of a multi-signal simulation that differ in length.
    #[error("input signal {input} has {len} samples, input signal 0 has {expected}")]
    InputLengthMismatch {
        /// The input signal whose length differs.
        input: usize,
        /// Its samples.
        len: usize,
        /// Samples of input signal 0.
        expected: usize,
    },
    /// Sensor outputs of a multi-signal system given in a number other than its sensors', or
    /// of a length other than the inputs'.
    #[error(
        "`{system}` has {expected} sensors of {samples} samples each; got {got} output signals, output signal {signal} with {len} samples"
    )]
    OutputShape {
        /// The system's name.
        system: &'static str,
        /// Sensors the system has.
        expected: usize,
        /// Samples of the inputs.
        samples: usize,
        /// Output signals given.
        got: usize,
        /// The first output signal whose length differs (or `got` when the count differs).
        signal: usize,
        /// Its samples (0 when the count differs).
        len: usize,
    },
    /// A sample of one input signal of a multi-signal simulation is NaN or infinite.
    #[error("input signal {input}: sample {index} is not finite ({value})")]
    NonFiniteMultiInput {
        /// Input signal.
        input: usize,
        /// Sample index.
        index: usize,
        /// Offending value.
        value: f64,
    },
    /// A sample of one input signal of a multi-signal simulation outside [`INPUT_RANGE`].
    #[error("input signal {input}: sample {index} = {value} is outside [{lo}, {hi}]")]
    MultiInputOutOfRange {
        /// Input signal.
        input: usize,
        /// Sample index.
        index: usize,
        /// Offending value.
        value: f64,
        /// Lower admissible bound.
        lo: f64,
        /// Upper admissible bound.
        hi: f64,
    },
    /// An oracle asked for a system whose disturbance propagates
    /// ([`SystemKind::disturbance_propagates`]): its state carries the disturbances of the
    /// samples before it, so the true past states do not pin the current one and the oracle's
    /// exact posterior does not apply.
    #[error(
        "no exact oracle for `{system}`: its disturbance enters upstream of the actuator's dynamics and propagates, so the true past states do not pin the current state"
    )]
    NoExactOracle {
        /// The system's name.
        system: &'static str,
    },
    /// A trajectory whose signals differ in length.
    #[error("trajectory signals differ in length: u {u}, x {x}, y {y} samples")]
    LengthMismatch {
        /// Samples of `u`.
        u: usize,
        /// Samples of `x`.
        x: usize,
        /// Samples of `y`.
        y: usize,
    },
}

/// Which simulated system.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum SystemKind {
    /// Maxwell-slip actuator, Duhem sensor.
    MaxwellSlip,
    /// Generalised Prandtl-Ishlinskii actuator, Bouc-Wen sensor.
    GeneralizedPi,
    /// Bouc-Wen actuator, Prandtl-Ishlinskii sensor.
    BoucWen,
    /// Preisach actuator, Maxwell-slip sensor.
    Preisach,
    /// Duhem (Coleman-Hodgdon) actuator, Preisach sensor.
    Duhem,
    /// Rate-dependent pneumatic soft actuator with a viscoelastic hysteretic strain sensor.
    SoftActuator,
    /// The soft actuator under a slowly correlated supply-pressure disturbance that enters
    /// upstream of its lag, hysteresis and creep, so it propagates into the later states.
    SoftActuatorLoad,
}

impl SystemKind {
    /// All systems, in declaration order.
    pub const ALL: [SystemKind; 7] = [
        SystemKind::MaxwellSlip,
        SystemKind::GeneralizedPi,
        SystemKind::BoucWen,
        SystemKind::Preisach,
        SystemKind::Duhem,
        SystemKind::SoftActuator,
        SystemKind::SoftActuatorLoad,
    ];

    /// Command-line name (kebab case).
    pub fn name(self) -> &'static str {
        match self {
            SystemKind::MaxwellSlip => "maxwell-slip",
            SystemKind::GeneralizedPi => "generalized-pi",
            SystemKind::BoucWen => "bouc-wen",
            SystemKind::Preisach => "preisach",
            SystemKind::Duhem => "duhem",
            SystemKind::SoftActuator => "soft-actuator",
            SystemKind::SoftActuatorLoad => "soft-actuator-load",
        }
    }

    /// One-line description (for `--help`).
    pub fn description(self) -> &'static str {
        match self {
            SystemKind::MaxwellSlip => {
                "Maxwell-slip actuator (8 elasto-slide elements), Duhem sensor; rate-independent"
            }
            SystemKind::GeneralizedPi => {
                "generalised Prandtl-Ishlinskii actuator (tanh envelope), Bouc-Wen sensor; rate-independent"
            }
            SystemKind::BoucWen => "Bouc-Wen actuator, Prandtl-Ishlinskii sensor; rate-independent",
            SystemKind::Preisach => {
                "Preisach relay actuator, Maxwell-slip sensor; rate-independent"
            }
            SystemKind::Duhem => {
                "Duhem/Coleman-Hodgdon actuator, Preisach sensor; rate-independent"
            }
            SystemKind::SoftActuator => {
                "pneumatic soft finger: lag + Bouc-Wen + creep, viscoelastic Duhem strain sensor; rate-dependent"
            }
            SystemKind::SoftActuatorLoad => {
                "soft-actuator under a supply-pressure disturbance (AR(1), 0.3 s) that enters before its dynamics and propagates; rate-dependent"
            }
        }
    }

    /// Fixed nominal range of `x` used to scale the noise (the calibrated quasi-static major
    /// loop spans `[0, 1]`, so this is 1 for every system).
    pub fn nominal_range_x(self) -> f64 {
        1.0
    }

    /// Fixed nominal range of `y` used to scale the noise (1 for every system, see
    /// [`SystemKind::nominal_range_x`]).
    pub fn nominal_range_y(self) -> f64 {
        1.0
    }

    /// Whether the system's response depends on the sampling rate.
    pub fn is_rate_dependent(self) -> bool {
        matches!(
            self,
            SystemKind::SoftActuator | SystemKind::SoftActuatorLoad
        )
    }

    /// Whether the state disturbance enters upstream of the actuator's dynamics and so
    /// propagates into the later states (`soft-actuator-load`), rather than being a white
    /// jitter added to the actuator's output (every other system). [`oracle_estimate`] and
    /// [`oracle_smooth_estimate`] give an exact floor only where it does not.
    pub fn disturbance_propagates(self) -> bool {
        matches!(self, SystemKind::SoftActuatorLoad)
    }
}

impl core::str::FromStr for SystemKind {
    type Err = SimError;

    /// Parses a name of [`SystemKind::name`], case-insensitively, `_` accepted for `-`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let norm = s.trim().to_ascii_lowercase().replace('_', "-");
        SystemKind::ALL
            .into_iter()
            .find(|k| k.name() == norm)
            .ok_or_else(|| SimError::UnknownSystem {
                name: s.to_string(),
                valid: SystemKind::ALL.map(|k| k.name()).join(", "),
            })
    }
}

impl core::fmt::Display for SystemKind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// One simulated trajectory, aligned samples at the rate `rate_hz`.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    /// Input.
    pub u: Vec<f64>,
    /// State (actuator output plus physical disturbance).
    pub x: Vec<f64>,
    /// Sensor output (plus measurement noise).
    pub y: Vec<f64>,
    /// Sampling rate in Hz.
    pub rate_hz: f64,
}

/// Simulator configuration (checked once by `validate`).
#[derive(Clone, Debug, PartialEq)]
pub struct SimConfig {
    /// Which system.
    pub system: SystemKind,
    /// Noise gain `g >= 0` (see the crate docs; 0 = clean).
    pub noise_gain: f64,
    /// Sampling rate in Hz (> 0).
    pub rate_hz: f64,
    /// Seed of the noise generator.
    pub seed: u64,
}

impl SimConfig {
    /// Noise-free configuration at 100 Hz with seed 0.
    pub fn new(system: SystemKind) -> Self {
        Self {
            system,
            noise_gain: 0.0,
            rate_hz: 100.0,
            seed: 0,
        }
    }

    /// Width of the state disturbance, `noise_gain * 0.02 * range_x`: `x` is the clean state
    /// plus this times a uniform draw from `[-0.5, 0.5]` (see the crate docs). For a system
    /// whose disturbance propagates ([`SystemKind::disturbance_propagates`]) it scales the
    /// upstream disturbance instead: its stationary standard deviation is this over
    /// `sqrt(12)`, as the others' state disturbance.
    pub fn noise_width_x(&self) -> f64 {
        self.noise_gain * 0.02 * self.system.nominal_range_x()
    }

    /// Width of the measurement noise, `noise_gain * 0.02 * range_y`: `y` is the sensor's clean
    /// output plus this times a uniform draw from `[-0.5, 0.5]`.
    pub fn noise_width_y(&self) -> f64 {
        self.noise_gain * 0.02 * self.system.nominal_range_y()
    }

    /// Checks `noise_gain` (finite, >= 0) and `rate_hz` (finite, > 0).
    pub fn validate(&self) -> Result<(), SimError> {
        check_gain_and_rate(self.noise_gain, self.rate_hz)
    }
}

/// Checks a noise gain (finite, >= 0) and a rate (finite, > 0).
fn check_gain_and_rate(noise_gain: f64, rate_hz: f64) -> Result<(), SimError> {
    if !(noise_gain.is_finite() && noise_gain >= 0.0) {
        return Err(SimError::InvalidParameter {
            name: "noise_gain",
            value: noise_gain,
            reason: "must be finite and >= 0",
        });
    }
    if !(rate_hz.is_finite() && rate_hz > 0.0) {
        return Err(SimError::InvalidParameter {
            name: "rate_hz",
            value: rate_hz,
            reason: "must be finite and > 0",
        });
    }
    Ok(())
}

/// A simulated robot driven one sample at a time (for an explorer or controller in the loop):
/// [`Simulator::step`] applies an input and returns the sample's state and sensor output.
/// Stepping through an input gives exactly what [`simulate`] gives for it.
#[derive(Clone, Debug)]
pub struct Simulator {
    system: systems::System,
    rng: Rng,
    noise_x: f64,
    noise_y: f64,
    /// The upstream disturbance of a system whose disturbance propagates (else `None`: the
    /// disturbance is added to the actuator's output).
    load: Option<systems::LoadDisturbance>,
    steps: usize,
}

impl Simulator {
    /// The system of `config` in its initial (demagnetised/relaxed) state; checks `config`.
    pub fn new(config: &SimConfig) -> Result<Self, SimError> {
        config.validate()?;
        let dt = 1.0 / config.rate_hz;
        Ok(Self {
            system: systems::System::new(config.system, dt)?,
            rng: Rng::new(config.seed ^ NOISE_SALT),
            noise_x: config.noise_width_x(),
            noise_y: config.noise_width_y(),
            load: config
                .system
                .disturbance_propagates()
                .then(|| systems::LoadDisturbance::new(config.noise_width_x(), dt)),
            steps: 0,
        })
    }

    /// Applies `u` for one sample; returns `(x, y)`. Rejects (and leaves the state unchanged
    /// for) a non-finite input or one outside [`INPUT_RANGE`].
    pub fn step(&mut self, u: f64) -> Result<(f64, f64), SimError> {
        let index = self.steps;
        if !u.is_finite() {
            return Err(SimError::NonFiniteInput { index, value: u });
        }
        let (lo, hi) = INPUT_RANGE;
        if !(lo..=hi).contains(&u) {
            return Err(SimError::InputOutOfRange {
                index,
                value: u,
                lo,
                hi,
            });
        }
        let eta_x = self.rng.uniform() - 0.5;
        let eta_y = self.rng.uniform() - 0.5;
        let x = match &mut self.load {
            Some(load) => {
                let d = load.step(eta_x);
                self.system.actuate(u + d)
            }
            None => self.system.actuate(u) + self.noise_x * eta_x,
        };
        let y = self.system.sense(x) + self.noise_y * eta_y;
        self.steps += 1;
        Ok((x, y))
    }

    /// Samples simulated so far.
    pub fn steps(&self) -> usize {
        self.steps
    }
}

/// Runs the system on a given input from its initial (demagnetised/relaxed) state.
///
/// Rejects an invalid configuration and any input sample that is not finite or lies outside
/// [`INPUT_RANGE`]. An empty input gives an empty trajectory.
pub fn simulate(config: &SimConfig, u: &[f64]) -> Result<Trajectory, SimError> {
    config.validate()?;
    check_input(u)?;
    let mut sim = Simulator::new(config)?;
    let mut x = Vec::with_capacity(u.len());
    let mut y = Vec::with_capacity(u.len());
    for &uk in u {
        let (xk, yk) = sim.step(uk)?;
        x.push(xk);
        y.push(yk);
    }
    Ok(Trajectory {
        u: u.to_vec(),
        x,
        y,
        rate_hz: config.rate_hz,
    })
}

/// Rejects the first input sample that is not finite or lies outside [`INPUT_RANGE`].
fn check_input(u: &[f64]) -> Result<(), SimError> {
    let (lo, hi) = INPUT_RANGE;
    for (index, &value) in u.iter().enumerate() {
        if !value.is_finite() {
            return Err(SimError::NonFiniteInput { index, value });
        }
        if !(lo..=hi).contains(&value) {
            return Err(SimError::InputOutOfRange {
                index,
                value,
                lo,
                hi,
            });
        }
    }
    Ok(())
}

/// Convenience: generate_input(RandomRamps, steps, default increment 0.02, seed) then simulate.
pub fn simulate_random(config: &SimConfig, steps: usize) -> Result<Trajectory, SimError> {
    config.validate()?;
    let u = generate_input(
        InputKind::RandomRamps,
        steps,
        DEFAULT_MAX_INCREMENT,
        config.seed,
    )?;
    simulate(config, &u)
}

#[cfg(test)]
mod tests;
