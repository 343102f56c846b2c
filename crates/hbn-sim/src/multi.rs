//! Multi-signal systems: several inputs (chamber valves), a vector state (the tip) and several
//! sensors, hysteretic and cross-coupled (see the crate docs, section "Multi-signal systems").

use hbn_core::rng::Rng;

use crate::operators::{
    BoucWen, BoucWenParams, Duhem, Envelope, MaxwellSlip, PrandtlIshlinskii, Preisach,
    PreisachDensity,
};
use crate::systems::{Actuator, Lag, Op, Sensor, sweep};
use crate::{INPUT_RANGE, InputKind, SimError, check_gain_and_rate, generate_input};

/// Salt mixed into the seed of the noise generator of the multi-signal systems.
const MULTI_NOISE_SALT: u64 = 0x3C0F_FEE5_0F7E_A5E5;

/// Salt mixed into the seed from which [`generate_multi_input`] derives one seed per input.
const MULTI_INPUT_SALT: u64 = 0x1A9E_5EED_5C0F_1A7E;

/// Finger: weight of chamber `c`'s bend in tip component `i` (`FINGER_STATE_MIX[i][c]`).
///
/// Chamber 0 is the proximal chamber, chamber 1 the distal one; the state is the tip's forward
/// reach (`x0`) and its drop towards the palm (`x1`). A curl anywhere moves the tip forward and
/// down, so every weight is positive: the proximal curl swings the whole finger, mostly forward
/// (1) and partly down (0.45); the distal curl turns the tip mostly down (1) and a little forward
/// (0.35).
pub const FINGER_STATE_MIX: [[f64; 2]; 2] = [[1.0, 0.35], [0.45, 1.0]];

/// Finger: weight of tip component `i` in the strain read by sensor `j`
/// (`FINGER_SENSOR_MIX[j][i]`).
///
/// Sensor 0 sits over the proximal chamber (mostly reach), sensor 1 over the distal one
/// (mostly drop), sensor 2 along the side: it stretches with the reach and shortens as the
/// tip drops (the negative weight).
pub const FINGER_SENSOR_MIX: [[f64; 2]; 3] = [[1.0, 0.4], [0.45, 1.0], [1.0, -0.4]];

/// Arm: squared ratio of the axial elongation to the bending displacement a chamber's
/// inflation gives (the `a^2` of [`ARM_STATE_MIX`]).
pub const ARM_ELONGATION_SQ: f64 = 1.5;

/// Arm: weight of chamber `c`'s bend in tip component `i` (`ARM_STATE_MIX[i][c]`).
///
/// The three chambers sit at 120 degrees around the segment's axis. Inflating chamber `c`
/// bends the segment towards its own side and lengthens it: the tip moves along
/// `v_c = (cos t_c, sin t_c, a)`. Tip component `i` is the tip's displacement along `v_i`, so
/// the weight is `v_i . v_c / |v_i|^2 = (cos(t_i - t_c) + a^2) / (1 + a^2)`: 1 on the diagonal
/// and `(a^2 - 1/2) / (1 + a^2) = 0.4` across with `a^2 =` [`ARM_ELONGATION_SQ`] (the shared
/// elongation outweighs the `-1/2` of the other chambers' bending directions).
pub const ARM_STATE_MIX: [[f64; 3]; 3] = [[1.0, 0.4, 0.4], [0.4, 1.0, 0.4], [0.4, 0.4, 1.0]];

/// Arm: weight of tip component `i` in the strain read by sensor `j` (`ARM_SENSOR_MIX[j][i]`).
///
/// Sensors 0 to 2 sit over chambers 0 to 2 and read mostly their own tip component; sensor 3
/// spans chambers 0 and 1 diagonally: it stretches with components 0 and 2 and shortens with
/// component 1 (the negative weight).
pub const ARM_SENSOR_MIX: [[f64; 3]; 4] = [
    [1.0, 0.4, 0.35],
    [0.35, 1.0, 0.45],
    [0.45, 0.35, 1.0],
    [1.0, -0.4, 0.5],
];

/// Finger: time constant (s) of each chamber's pneumatic lag.
const FINGER_CHAMBER_TAU: [f64; 2] = [0.08, 0.12];
/// Arm: time constant (s) of each chamber's pneumatic lag.
const ARM_CHAMBER_TAU: [f64; 3] = [0.06, 0.09, 0.12];
/// Time constant (s) of the tip's lag behind the chambers' bends (finger, arm).
const TIP_TAU: [f64; 2] = [0.04, 0.06];

/// Which multi-signal system.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub enum MultiKind {
    /// Soft finger: 2 chambers, planar tip (2 states), 3 strain sensors.
    Finger,
    /// Soft arm segment: 3 chambers, spatial tip (3 states), 4 strain sensors.
    Arm,
}

impl MultiKind {
    /// All multi-signal systems, in declaration order.
    pub const ALL: [MultiKind; 2] = [MultiKind::Finger, MultiKind::Arm];

    /// Command-line name.
    pub fn name(self) -> &'static str {
        match self {
            MultiKind::Finger => "finger",
            MultiKind::Arm => "arm",
        }
    }

    /// One-line description (for `--help`).
    pub fn description(self) -> &'static str {
        match self {
            MultiKind::Finger => {
                "soft finger: 2 chamber inputs (lag + Bouc-Wen / Prandtl-Ishlinskii), planar tip (2 states), 3 strain sensors; rate-dependent"
            }
            MultiKind::Arm => {
                "soft arm segment: 3 chamber inputs (lag + Bouc-Wen / Preisach / Duhem), spatial tip (3 states), 4 strain sensors; rate-dependent"
            }
        }
    }

    /// Number of inputs (chamber valves).
    pub fn inputs(self) -> usize {
        match self {
            MultiKind::Finger => 2,
            MultiKind::Arm => 3,
        }
    }

    /// Number of state components (tip coordinates).
    pub fn states(self) -> usize {
        match self {
            MultiKind::Finger => 2,
            MultiKind::Arm => 3,
        }
    }

    /// Number of sensors.
    pub fn sensors(self) -> usize {
        match self {
            MultiKind::Finger => 3,
            MultiKind::Arm => 4,
        }
    }

    /// The chamber-to-tip mixing, `[state][input]` ([`FINGER_STATE_MIX`], [`ARM_STATE_MIX`]).
    pub fn state_mix(self) -> Vec<Vec<f64>> {
        match self {
            MultiKind::Finger => FINGER_STATE_MIX.iter().map(|r| r.to_vec()).collect(),
            MultiKind::Arm => ARM_STATE_MIX.iter().map(|r| r.to_vec()).collect(),
        }
    }

    /// The tip-to-sensor mixing, `[sensor][state]` ([`FINGER_SENSOR_MIX`],
    /// [`ARM_SENSOR_MIX`]).
    pub fn sensor_mix(self) -> Vec<Vec<f64>> {
        match self {
            MultiKind::Finger => FINGER_SENSOR_MIX.iter().map(|r| r.to_vec()).collect(),
            MultiKind::Arm => ARM_SENSOR_MIX.iter().map(|r| r.to_vec()).collect(),
        }
    }

    /// Fixed nominal range of every state component, used to scale the noise (the calibrated
    /// quasi-static sweep spans `[0, 1]` per component, so this is 1).
    pub fn nominal_range_x(self) -> f64 {
        1.0
    }

    /// Fixed nominal range of every sensor (1, see [`MultiKind::nominal_range_x`]).
    pub fn nominal_range_y(self) -> f64 {
        1.0
    }
}

impl core::str::FromStr for MultiKind {
    type Err = SimError;

    /// Parses a name of [`MultiKind::name`], case-insensitively.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let norm = s.trim().to_ascii_lowercase();
        MultiKind::ALL
            .into_iter()
            .find(|k| k.name() == norm)
            .ok_or_else(|| SimError::UnknownSystem {
                name: s.to_string(),
                valid: MultiKind::ALL.map(|k| k.name()).join(", "),
            })
    }
}

impl core::fmt::Display for MultiKind {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// Configuration of a multi-signal simulation (checked once by [`MultiConfig::validate`]).
#[derive(Clone, Debug, PartialEq)]
pub struct MultiConfig {
    /// Which system.
    pub system: MultiKind,
    /// Noise gain `g >= 0` (0 = clean).
    pub noise_gain: f64,
    /// Sampling rate in Hz (> 0).
    pub rate_hz: f64,
    /// Seed of the noise generator.
    pub seed: u64,
}

impl MultiConfig {
    /// Noise-free configuration at 100 Hz with seed 0 (the defaults of
    /// [`crate::SimConfig::new`]).
    pub fn new(system: MultiKind) -> Self {
        Self {
            system,
            noise_gain: 0.0,
            rate_hz: 100.0,
            seed: 0,
        }
    }

    /// Width of each state component's disturbance, `noise_gain * 0.02 * range_x`.
    pub fn noise_width_x(&self) -> f64 {
        self.noise_gain * 0.02 * self.system.nominal_range_x()
    }

    /// Width of each sensor's measurement noise, `noise_gain * 0.02 * range_y`.
    pub fn noise_width_y(&self) -> f64 {
        self.noise_gain * 0.02 * self.system.nominal_range_y()
    }

    /// Checks `noise_gain` (finite, >= 0) and `rate_hz` (finite, > 0).
    pub fn validate(&self) -> Result<(), SimError> {
        check_gain_and_rate(self.noise_gain, self.rate_hz)
    }
}

/// One simulated multi-signal trajectory, aligned samples at `rate_hz`, component-major:
/// `x[i][k]` is state component `i` at sample `k`.
#[derive(Clone, Debug, PartialEq)]
pub struct MultiTrajectory {
    /// Inputs, one `Vec` per input.
    pub u: Vec<Vec<f64>>,
    /// State components (clean state plus disturbance), one `Vec` per component.
    pub x: Vec<Vec<f64>>,
    /// Sensor outputs (plus measurement noise), one `Vec` per sensor.
    pub y: Vec<Vec<f64>>,
    /// Sampling rate in Hz.
    pub rate_hz: f64,
}

impl MultiTrajectory {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.u.first().map_or(0, Vec::len)
    }

    /// Whether the trajectory has no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The tip's lag behind the chambers' mixed bends, then the affine calibration
/// `x = (s - offset) * gain`. The state disturbance enters the lag state `s`.
#[derive(Clone, Debug)]
struct Tip {
    lag: Lag,
    offset: f64,
    gain: f64,
}

impl Tip {
    fn step(&mut self, target: f64) -> f64 {
        (self.lag.step(target) - self.offset) * self.gain
    }

    /// Moves the tip by `d` (calibrated units): the lag state takes the displacement.
    fn disturb(&mut self, d: f64) {
        self.lag.s += d / self.gain;
    }
}

fn dot(w: &[f64], v: &[f64]) -> f64 {
    w.iter().zip(v).map(|(a, b)| a * b).sum()
}

/// `[lo, hi]` of `values` as calibration range (an error if degenerate).
fn range(name: &'static str, values: &[f64]) -> Result<(f64, f64), SimError> {
    let (lo, hi) = values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &v| {
            (l.min(v), h.max(v))
        });
    let span = hi - lo;
    if span.is_finite() && span > 1e-9 {
        Ok((lo, hi))
    } else {
        Err(SimError::InvalidParameter {
            name,
            value: span,
            reason: "calibration sweep gave a degenerate range",
        })
    }
}

fn bouc_wen(beta: f64, gamma: f64, k_z: f64) -> Result<Op, SimError> {
    Ok(Op::Bw(BoucWen::new(BoucWenParams {
        a: 1.0,
        beta,
        gamma,
        n: 1.0,
        k_lin: 1.0,
        k_z,
        max_substep: 1e-3,
    })?))
}

fn pi_sensor(c0: f64, c1: f64, p0: f64, radii: &[f64], w: f64) -> Result<Op, SimError> {
    Ok(Op::Pi(PrandtlIshlinskii::new(
        Envelope {
            c0,
            c1,
            c2: 0.0,
            c3: 0.0,
        },
        p0,
        radii,
        &vec![w; radii.len()],
    )?))
}

/// The uncalibrated chambers (pneumatic lag, then hysteresis) and sensors of `kind`
/// (parameters in the crate docs).
fn build(kind: MultiKind, dt: f64) -> Result<(Vec<Actuator>, Vec<Sensor>), SimError> {
    let chamber = |tau: f64, op: Op| {
        let mut a = Actuator::plain(op);
        a.lag = Some(Lag::new(tau, dt));
        a
    };
    let blend = |lin: f64, k_op: f64, op: Op| {
        let mut s = Sensor::plain(op);
        s.lin = lin;
        s.k_op = k_op;
        s
    };
    Ok(match kind {
        MultiKind::Finger => (
            vec![
                chamber(FINGER_CHAMBER_TAU[0], bouc_wen(2.5, 0.5, -0.5)?),
                chamber(FINGER_CHAMBER_TAU[1], Op::Pi(PrandtlIshlinskii::default())),
            ],
            vec![
                Sensor::plain(Op::Du(Duhem::new(10.0, 0.5, 1.0)?)),
                Sensor::plain(Op::Ms(MaxwellSlip::new(
                    0.8,
                    &[0.2; 4],
                    &[0.004, 0.008, 0.012, 0.016],
                )?)),
                blend(
                    0.85,
                    0.15,
                    Op::Pr(Preisach::new(
                        40,
                        -0.05,
                        1.05,
                        PreisachDensity {
                            width_mean: 0.3,
                            width_std: 0.1,
                            center_mean: 0.5,
                            center_std: 0.35,
                        },
                    )?),
                ),
            ],
        ),
        MultiKind::Arm => (
            vec![
                chamber(ARM_CHAMBER_TAU[0], bouc_wen(3.0, 1.0, -0.5)?),
                chamber(
                    ARM_CHAMBER_TAU[1],
                    Op::Pr(Preisach::new(
                        30,
                        0.0,
                        1.0,
                        PreisachDensity {
                            width_mean: 0.3,
                            width_std: 0.15,
                            center_mean: 0.5,
                            center_std: 0.3,
                        },
                    )?),
                ),
                chamber(ARM_CHAMBER_TAU[2], Op::Du(Duhem::new(4.0, -0.4, 1.0)?)),
            ],
            vec![
                Sensor::plain(Op::Ms(MaxwellSlip::new(
                    0.8,
                    &[0.2; 4],
                    &[0.004, 0.008, 0.012, 0.016],
                )?)),
                Sensor::plain(pi_sensor(2.0, 0.5, 0.3, &[0.03, 0.06, 0.09], 0.3)?),
                Sensor::plain(Op::Ms(MaxwellSlip::new(
                    0.9,
                    &[0.3; 3],
                    &[0.003, 0.009, 0.015],
                )?)),
                Sensor::plain(pi_sensor(1.5, 0.7, 0.5, &[0.02, 0.05], 0.25)?),
            ],
        ),
    })
}

/// A calibrated, preconditioned multi-signal system ready to run from its relaxed state at
/// `u = 0`.
#[derive(Clone, Debug)]
pub(crate) struct MultiSystem {
    chambers: Vec<Actuator>,
    /// `[state][input]`.
    state_mix: Vec<Vec<f64>>,
    tips: Vec<Tip>,
    /// `[sensor][state]`, each row divided by its sum.
    sensor_mix: Vec<Vec<f64>>,
    gauges: Vec<Sensor>,
    /// Calibrated bends of the current sample.
    bends: Vec<f64>,
}

/// Raw (uncalibrated) outputs of every stage over the second of two quasi-static cycles.
struct Raw {
    bends: Vec<Vec<f64>>,
    tips: Vec<Vec<f64>>,
    gauges: Vec<Vec<f64>>,
}

impl MultiSystem {
    /// Builds, calibrates and preconditions `kind` for the sampling period `dt`.
    ///
    /// Calibration is quasi-static (every lag follows its target exactly), one stage at a
    /// time: from the virgin state, run all inputs together through the cycle `0 -> 1 -> 0`
    /// twice and map the `[min, max]` of the stage's raw output over the second cycle to
    /// `[0, 1]`; first each chamber's bend, then each tip component (fed with the calibrated
    /// bends), then each sensor (fed with the calibrated tip). Preconditioning: reset and run
    /// one quasi-static cycle.
    pub(crate) fn new(kind: MultiKind, dt: f64) -> Result<Self, SimError> {
        let (chambers, gauges) = build(kind, dt)?;
        let tip_tau = match kind {
            MultiKind::Finger => TIP_TAU[0],
            MultiKind::Arm => TIP_TAU[1],
        };
        let tips = (0..kind.states())
            .map(|_| Tip {
                lag: Lag::new(tip_tau, dt),
                offset: 0.0,
                gain: 1.0,
            })
            .collect();
        let sensor_mix = kind
            .sensor_mix()
            .into_iter()
            .map(|row| {
                let sum: f64 = row.iter().sum();
                row.into_iter().map(|w| w / sum).collect()
            })
            .collect();
        let mut sys = Self {
            chambers,
            state_mix: kind.state_mix(),
            tips,
            sensor_mix,
            gauges,
            bends: vec![0.0; kind.inputs()],
        };
        sys.set_quasi_static(true);

        let raw = sys.quasi_static_raw();
        for (ch, r) in sys.chambers.iter_mut().zip(&raw.bends) {
            let (lo, hi) = range("chamber range", r)?;
            ch.offset = lo;
            ch.gain = 1.0 / (hi - lo);
        }
        let raw = sys.quasi_static_raw();
        for (tip, r) in sys.tips.iter_mut().zip(&raw.tips) {
            let (lo, hi) = range("tip range", r)?;
            tip.offset = lo;
            tip.gain = 1.0 / (hi - lo);
        }
        let raw = sys.quasi_static_raw();
        for (g, r) in sys.gauges.iter_mut().zip(&raw.gauges) {
            let (lo, hi) = range("sensor range", r)?;
            g.offset = lo;
            g.gain = 1.0 / (hi - lo);
        }

        sys.reset();
        let (mut x, mut y) = (vec![0.0; kind.states()], vec![0.0; kind.sensors()]);
        for u in sweep() {
            sys.actuate(&vec![u; kind.inputs()], &mut x);
            sys.sense(&x, &mut y);
        }
        sys.set_quasi_static(false);
        Ok(sys)
    }

    /// From the virgin state, runs the quasi-static cycle twice with all inputs together and
    /// returns every stage's raw output over the second cycle (stages fed with the current
    /// calibration of the stages before them).
    fn quasi_static_raw(&mut self) -> Raw {
        self.reset();
        let cycle = sweep();
        let mut raw = Raw {
            bends: vec![Vec::with_capacity(cycle.len()); self.chambers.len()],
            tips: vec![Vec::with_capacity(cycle.len()); self.tips.len()],
            gauges: vec![Vec::with_capacity(cycle.len()); self.gauges.len()],
        };
        let mut x = vec![0.0; self.tips.len()];
        for pass in 0..2 {
            for &u in &cycle {
                for (c, ch) in self.chambers.iter_mut().enumerate() {
                    let r = ch.raw(u);
                    self.bends[c] = (r - ch.offset) * ch.gain;
                    if pass == 1 {
                        raw.bends[c].push(r);
                    }
                }
                for (i, tip) in self.tips.iter_mut().enumerate() {
                    let r = tip.lag.step(dot(&self.state_mix[i], &self.bends));
                    x[i] = (r - tip.offset) * tip.gain;
                    if pass == 1 {
                        raw.tips[i].push(r);
                    }
                }
                for (j, g) in self.gauges.iter_mut().enumerate() {
                    let r = g.raw(dot(&self.sensor_mix[j], &x));
                    if pass == 1 {
                        raw.gauges[j].push(r);
                    }
                }
            }
        }
        raw
    }

    /// Back to the virgin state (every operator virgin, every lag at rest at 0).
    pub(crate) fn reset(&mut self) {
        for ch in &mut self.chambers {
            ch.reset();
        }
        for tip in &mut self.tips {
            tip.lag.s = 0.0;
        }
        for g in &mut self.gauges {
            g.reset();
        }
    }

    /// Quasi-static mode: every lag follows its target exactly (calibration).
    pub(crate) fn set_quasi_static(&mut self, on: bool) {
        for ch in &mut self.chambers {
            ch.set_quasi_static(on);
        }
        for tip in &mut self.tips {
            tip.lag.quasi_static = on;
        }
        for g in &mut self.gauges {
            g.set_quasi_static(on);
        }
    }

    /// Actuators: the next clean state `x` for the inputs `u` (one per chamber).
    pub(crate) fn actuate(&mut self, u: &[f64], x: &mut [f64]) {
        self.bend(u);
        for ((xi, tip), row) in x.iter_mut().zip(&mut self.tips).zip(&self.state_mix) {
            *xi = tip.step(dot(row, &self.bends));
        }
    }

    /// Chambers only: the calibrated bends for the inputs `u` (one per chamber), the tips'
    /// targets before mixing.
    fn bend(&mut self, u: &[f64]) {
        for ((b, ch), &uc) in self.bends.iter_mut().zip(&mut self.chambers).zip(u) {
            *b = ch.step(uc);
        }
    }

    /// Moves state component `i` by `d` (calibrated units) for good: the tip's lag state
    /// takes the displacement, which then relaxes with the lag's time constant.
    pub(crate) fn disturb(&mut self, i: usize, d: f64) {
        if let Some(tip) = self.tips.get_mut(i) {
            tip.disturb(d);
        }
    }

    /// Sensors: the next clean outputs `y` for the (possibly disturbed) state `x`.
    pub(crate) fn sense(&mut self, x: &[f64], y: &mut [f64]) {
        for ((yj, g), row) in y.iter_mut().zip(&mut self.gauges).zip(&self.sensor_mix) {
            *yj = g.step(dot(row, x));
        }
    }
}

/// A multi-signal system driven one sample at a time: [`MultiSimulator::step`] applies one
/// value per input and returns the sample's state and sensor outputs. Stepping through an
/// input gives exactly what [`simulate_multi`] gives for it.
#[derive(Clone, Debug)]
pub struct MultiSimulator {
    kind: MultiKind,
    system: MultiSystem,
    rng: Rng,
    noise_x: f64,
    noise_y: f64,
    steps: usize,
}

impl MultiSimulator {
    /// The system of `config` in its relaxed state; checks `config`.
    pub fn new(config: &MultiConfig) -> Result<Self, SimError> {
        config.validate()?;
        Ok(Self {
            kind: config.system,
            system: MultiSystem::new(config.system, 1.0 / config.rate_hz)?,
            rng: Rng::new(config.seed ^ MULTI_NOISE_SALT),
            noise_x: config.noise_width_x(),
            noise_y: config.noise_width_y(),
            steps: 0,
        })
    }

    /// Applies `u` (one value per input) for one sample; returns `(x, y)`, one value per state
    /// component and per sensor. Rejects (and leaves the state unchanged for) the wrong
    /// number of inputs, or a value that is not finite or outside [`INPUT_RANGE`].
    pub fn step(&mut self, u: &[f64]) -> Result<(Vec<f64>, Vec<f64>), SimError> {
        let mut x = vec![0.0; self.kind.states()];
        let mut y = vec![0.0; self.kind.sensors()];
        self.step_into(u, &mut x, &mut y)?;
        Ok((x, y))
    }

    /// [`MultiSimulator::step`] into caller-owned buffers of [`MultiKind::states`] and
    /// [`MultiKind::sensors`] values.
    fn step_into(&mut self, u: &[f64], x: &mut [f64], y: &mut [f64]) -> Result<(), SimError> {
        if u.len() != self.kind.inputs() {
            return Err(SimError::InputCount {
                system: self.kind.name(),
                expected: self.kind.inputs(),
                got: u.len(),
            });
        }
        for (input, &value) in u.iter().enumerate() {
            check_sample(input, self.steps, value)?;
        }
        self.system.actuate(u, x);
        for (i, xi) in x.iter_mut().enumerate() {
            let d = self.noise_x * (self.rng.uniform() - 0.5);
            *xi += d;
            self.system.disturb(i, d);
        }
        self.system.sense(x, y);
        for yj in y.iter_mut() {
            *yj += self.noise_y * (self.rng.uniform() - 0.5);
        }
        self.steps += 1;
        Ok(())
    }

    /// Samples simulated so far.
    pub fn steps(&self) -> usize {
        self.steps
    }

    /// The system.
    pub fn kind(&self) -> MultiKind {
        self.kind
    }
}

/// Checks that `u` holds one signal per input of `kind`, all of one length, every sample
/// finite and within [`INPUT_RANGE`]; returns the length.
fn check_inputs(kind: MultiKind, u: &[Vec<f64>]) -> Result<usize, SimError> {
    if u.len() != kind.inputs() {
        return Err(SimError::InputCount {
            system: kind.name(),
            expected: kind.inputs(),
            got: u.len(),
        });
    }
    let n = u.first().map_or(0, Vec::len);
    for (input, ui) in u.iter().enumerate() {
        if ui.len() != n {
            return Err(SimError::InputLengthMismatch {
                input,
                len: ui.len(),
                expected: n,
            });
        }
        for (index, &value) in ui.iter().enumerate() {
            check_sample(input, index, value)?;
        }
    }
    Ok(n)
}

fn check_sample(input: usize, index: usize, value: f64) -> Result<(), SimError> {
    if !value.is_finite() {
        return Err(SimError::NonFiniteMultiInput {
            input,
            index,
            value,
        });
    }
    let (lo, hi) = INPUT_RANGE;
    if !(lo..=hi).contains(&value) {
        return Err(SimError::MultiInputOutOfRange {
            input,
            index,
            value,
            lo,
            hi,
        });
    }
    Ok(())
}

/// Runs the system of `config` on the inputs `u` (one `Vec` per input, component-major) from
/// its relaxed state.
///
/// Rejects an invalid configuration, a count of inputs other than [`MultiKind::inputs`],
/// inputs of different lengths and any sample that is not finite or lies outside
/// [`INPUT_RANGE`]. Inputs with no samples give an empty trajectory.
pub fn simulate_multi(config: &MultiConfig, u: &[Vec<f64>]) -> Result<MultiTrajectory, SimError> {
    config.validate()?;
    let kind = config.system;
    let n = check_inputs(kind, u)?;
    let mut sim = MultiSimulator::new(config)?;
    let mut x = vec![Vec::with_capacity(n); kind.states()];
    let mut y = vec![Vec::with_capacity(n); kind.sensors()];
    let (mut uk, mut xk, mut yk) = (
        vec![0.0; kind.inputs()],
        vec![0.0; kind.states()],
        vec![0.0; kind.sensors()],
    );
    for k in 0..n {
        for (v, ui) in uk.iter_mut().zip(u) {
            *v = ui[k];
        }
        sim.step_into(&uk, &mut xk, &mut yk)?;
        for (xi, &v) in x.iter_mut().zip(&xk) {
            xi.push(v);
        }
        for (yj, &v) in y.iter_mut().zip(&yk) {
            yj.push(v);
        }
    }
    Ok(MultiTrajectory {
        u: u.to_vec(),
        x,
        y,
        rate_hz: config.rate_hz,
    })
}

/// `inputs` independent random-ramp inputs of `steps` samples each (every one starting at 0,
/// in `[0, 1]`, increments at most `max_increment`): input `i` is
/// [`generate_input`]`(RandomRamps, steps, max_increment, s_i)` where `s_i` is the `i`-th
/// draw of `hbn_core::rng::Rng` seeded with `seed` xor a fixed salt.
pub fn generate_multi_input(
    inputs: usize,
    steps: usize,
    max_increment: f64,
    seed: u64,
) -> Result<Vec<Vec<f64>>, SimError> {
    let mut seeds = Rng::new(seed ^ MULTI_INPUT_SALT);
    (0..inputs)
        .map(|_| {
            generate_input(
                InputKind::RandomRamps,
                steps,
                max_increment,
                seeds.next_u64(),
            )
        })
        .collect()
}

/// Convenience: [`generate_multi_input`] with the default increment 0.02 and `config.seed`,
/// then [`simulate_multi`].
pub fn simulate_multi_random(
    config: &MultiConfig,
    steps: usize,
) -> Result<MultiTrajectory, SimError> {
    config.validate()?;
    let u = generate_multi_input(
        config.system.inputs(),
        steps,
        crate::DEFAULT_MAX_INCREMENT,
        config.seed,
    )?;
    simulate_multi(config, &u)
}

mod posterior;
pub use posterior::{MultiPosterior, multi_posterior_estimate};

#[cfg(test)]
mod tests;
