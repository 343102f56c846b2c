//! The simulated systems: an actuator chain `u -> x` and a sensor chain `x -> y` per
//! [`SystemKind`], calibrated so that the quasi-static major loop spans `[0, 1]` in both.

use crate::operators::{
    BoucWen, BoucWenParams, Duhem, Envelope, Hysteresis, MaxwellSlip, PrandtlIshlinskii, Preisach,
    PreisachDensity,
};
use crate::{SimError, SystemKind};

/// Static sensor nonlinearity `y = tanh(kappa h) / tanh(kappa)` (maps 0 -> 0, 1 -> 1).
pub(crate) const SENSOR_KAPPA: f64 = 1.5;
/// Step of the quasi-static calibration sweep `0 -> 1 -> 0`.
pub(crate) const SWEEP_STEP: f64 = 0.005;
/// Number of samples to the peak of the sweep.
pub(crate) const SWEEP_PEAK: usize = 200;

/// The quasi-static calibration / preconditioning cycle `0 -> 1 -> 0` in steps of 0.005.
pub(crate) fn sweep() -> Vec<f64> {
    (0..=SWEEP_PEAK)
        .chain((0..SWEEP_PEAK).rev())
        .map(|i| i as f64 * SWEEP_STEP)
        .collect()
}

#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Op {
    Pi(PrandtlIshlinskii),
    Ms(MaxwellSlip),
    Bw(BoucWen),
    Pr(Preisach),
    Du(Duhem),
}

impl Hysteresis for Op {
    fn step(&mut self, input: f64) -> f64 {
        match self {
            Op::Pi(o) => o.step(input),
            Op::Ms(o) => o.step(input),
            Op::Bw(o) => o.step(input),
            Op::Pr(o) => o.step(input),
            Op::Du(o) => o.step(input),
        }
    }

    fn reset(&mut self) {
        match self {
            Op::Pi(o) => o.reset(),
            Op::Ms(o) => o.reset(),
            Op::Bw(o) => o.reset(),
            Op::Pr(o) => o.reset(),
            Op::Du(o) => o.reset(),
        }
    }
}

/// First-order lag `s' = (target - s) / tau`, discretised exactly for a target held over the
/// sample: `s[k] = s[k-1] + (1 - exp(-dt / tau)) (target[k] - s[k-1])`. In quasi-static mode
/// (used for calibration) it follows the target exactly.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Lag {
    alpha: f64,
    pub(crate) quasi_static: bool,
    pub(crate) s: f64,
}

impl Lag {
    pub(crate) fn new(tau: f64, dt: f64) -> Self {
        Self {
            alpha: 1.0 - (-dt / tau).exp(),
            quasi_static: false,
            s: 0.0,
        }
    }

    pub(crate) fn step(&mut self, target: f64) -> f64 {
        if self.quasi_static {
            self.s = target;
        } else {
            self.s += self.alpha * (target - self.s);
        }
        self.s
    }
}

/// Actuator chain: optional pneumatic lag -> hysteresis -> optional creep, then the affine
/// calibration `x = (raw - offset) * gain`.
#[derive(Clone, Debug)]
pub(crate) struct Actuator {
    pub(crate) lag: Option<Lag>,
    op: Op,
    /// Creep: `x_raw = (1 - kappa) b + c` with `c` lagging `kappa b`.
    creep: Option<(Lag, f64)>,
    pub(crate) offset: f64,
    pub(crate) gain: f64,
}

impl Actuator {
    pub(crate) fn plain(op: Op) -> Self {
        Self {
            lag: None,
            op,
            creep: None,
            offset: 0.0,
            gain: 1.0,
        }
    }

    pub(crate) fn raw(&mut self, u: f64) -> f64 {
        let p = match &mut self.lag {
            Some(lag) => lag.step(u),
            None => u,
        };
        let b = self.op.step(p);
        match &mut self.creep {
            Some((c, kappa)) => (1.0 - *kappa) * b + c.step(*kappa * b),
            None => b,
        }
    }

    pub(crate) fn step(&mut self, u: f64) -> f64 {
        (self.raw(u) - self.offset) * self.gain
    }

    pub(crate) fn reset(&mut self) {
        self.op.reset();
        if let Some(lag) = &mut self.lag {
            lag.s = 0.0;
        }
        if let Some((c, _)) = &mut self.creep {
            c.s = 0.0;
        }
    }

    pub(crate) fn set_quasi_static(&mut self, on: bool) {
        if let Some(lag) = &mut self.lag {
            lag.quasi_static = on;
        }
        if let Some((c, _)) = &mut self.creep {
            c.quasi_static = on;
        }
    }
}

/// Sensor chain: optional standard-linear-solid strain response -> `lin v + k_op H(v)` ->
/// affine calibration -> `tanh(kappa h) / tanh(kappa)`. Two sensors that compare equal give
/// the same outputs for the same states from then on.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Sensor {
    /// SLS: `v = x + rho (x - q)`, `q` lagging `x` (the dashpot of the Maxwell arm).
    sls: Option<(Lag, f64)>,
    pub(crate) lin: f64,
    pub(crate) k_op: f64,
    op: Op,
    pub(crate) offset: f64,
    pub(crate) gain: f64,
}

impl Sensor {
    pub(crate) fn plain(op: Op) -> Self {
        Self {
            sls: None,
            lin: 0.0,
            k_op: 1.0,
            op,
            offset: 0.0,
            gain: 1.0,
        }
    }

    pub(crate) fn raw(&mut self, x: f64) -> f64 {
        let v = match &mut self.sls {
            Some((q, rho)) => {
                let qv = q.step(x);
                x + *rho * (x - qv)
            }
            None => x,
        };
        self.lin * v + self.k_op * self.op.step(v)
    }

    pub(crate) fn step(&mut self, x: f64) -> f64 {
        let h = (self.raw(x) - self.offset) * self.gain;
        (SENSOR_KAPPA * h).tanh() / SENSOR_KAPPA.tanh()
    }

    pub(crate) fn reset(&mut self) {
        self.op.reset();
        if let Some((q, _)) = &mut self.sls {
            q.s = 0.0;
        }
    }

    pub(crate) fn set_quasi_static(&mut self, on: bool) {
        if let Some((q, _)) = &mut self.sls {
            q.quasi_static = on;
        }
    }
}

/// Builds the uncalibrated chains of one system (parameters documented in the crate docs).
fn build(kind: SystemKind, dt: f64) -> Result<(Actuator, Sensor), SimError> {
    let duhem_sensor = || Duhem::new(10.0, 0.5, 1.0).map(Op::Du);
    Ok(match kind {
        SystemKind::MaxwellSlip => (
            Actuator::plain(Op::Ms(MaxwellSlip::default())),
            Sensor::plain(duhem_sensor()?),
        ),
        SystemKind::GeneralizedPi => (
            Actuator::plain(Op::Pi(PrandtlIshlinskii::default())),
            Sensor::plain(Op::Bw(BoucWen::new(BoucWenParams {
                a: 1.0,
                beta: 6.0,
                gamma: 2.0,
                n: 1.0,
                k_lin: 1.0,
                k_z: 0.4,
                max_substep: 1e-3,
            })?)),
        ),
        SystemKind::BoucWen => (
            Actuator::plain(Op::Bw(BoucWen::default())),
            Sensor::plain(Op::Pi(PrandtlIshlinskii::new(
                Envelope {
                    c0: 2.0,
                    c1: 0.5,
                    c2: 0.0,
                    c3: 0.0,
                },
                0.3,
                &[0.03, 0.06, 0.09],
                &[0.3, 0.3, 0.3],
            )?)),
        ),
        SystemKind::Preisach => (
            Actuator::plain(Op::Pr(Preisach::default())),
            Sensor::plain(Op::Ms(MaxwellSlip::new(
                0.8,
                &[0.2; 4],
                &[0.004, 0.008, 0.012, 0.016],
            )?)),
        ),
        SystemKind::Duhem => (
            Actuator::plain(Op::Du(Duhem::default())),
            Sensor {
                lin: 0.85,
                k_op: 0.15,
                ..Sensor::plain(Op::Pr(Preisach::new(
                    40,
                    -0.05,
                    1.05,
                    PreisachDensity {
                        width_mean: 0.3,
                        width_std: 0.1,
                        center_mean: 0.5,
                        center_std: 0.35,
                    },
                )?))
            },
        ),
        SystemKind::SoftActuator | SystemKind::SoftActuatorLoad => (
            Actuator {
                lag: Some(Lag::new(0.08, dt)),
                creep: Some((Lag::new(1.5, dt), 0.15)),
                ..Actuator::plain(Op::Bw(BoucWen::new(BoucWenParams {
                    a: 1.0,
                    beta: 3.0,
                    gamma: 1.0,
                    n: 1.0,
                    k_lin: 1.0,
                    k_z: -0.5,
                    max_substep: 1e-3,
                })?))
            },
            Sensor {
                sls: Some((Lag::new(0.25, dt), 0.4)),
                ..Sensor::plain(duhem_sensor()?)
            },
        ),
    })
}

/// Correlation time of the supply-pressure disturbance of `soft-actuator-load`, in seconds.
pub(crate) const LOAD_TAU: f64 = 0.3;

/// The upstream disturbance of `soft-actuator-load`: an AR(1) process
/// `d[k] = a d[k-1] + sqrt(1 - a^2) w eta[k]`, `a = exp(-dt / LOAD_TAU)`, `eta[k]` uniform on
/// `[-0.5, 0.5]`, from `d = 0`. Its stationary variance is `w^2 / 12` at every rate (that of the
/// other systems' state disturbance) and its correlation time `LOAD_TAU`.
#[derive(Clone, Debug)]
pub(crate) struct LoadDisturbance {
    a: f64,
    scale: f64,
    d: f64,
}

impl LoadDisturbance {
    /// The process for disturbance width `width` (`noise_width_x`) and sampling period `dt`.
    pub(crate) fn new(width: f64, dt: f64) -> Self {
        let a = (-dt / LOAD_TAU).exp();
        Self {
            a,
            scale: (1.0 - a * a).sqrt() * width,
            d: 0.0,
        }
    }

    /// The next disturbance for the uniform draw `eta` in `[-0.5, 0.5]`.
    pub(crate) fn step(&mut self, eta: f64) -> f64 {
        self.d = self.a * self.d + self.scale * eta;
        self.d
    }
}

fn span(name: &'static str, lo: f64, hi: f64) -> Result<f64, SimError> {
    let s = hi - lo;
    if s.is_finite() && s > 1e-9 {
        Ok(s)
    } else {
        Err(SimError::InvalidParameter {
            name,
            value: s,
            reason: "calibration sweep gave a degenerate range",
        })
    }
}

/// A calibrated, preconditioned system ready to run from its relaxed state at `u = 0`.
#[derive(Clone, Debug)]
pub(crate) struct System {
    act: Actuator,
    sen: Sensor,
}

impl System {
    /// Builds, calibrates and preconditions the system for sampling period `dt`.
    ///
    /// Calibration (quasi-static: lags follow their targets exactly): from the virgin state run
    /// the cycle `0 -> 1 -> 0` once (`lo` = output at its end) and once more (`hi` = output at
    /// `u = 1`), map `[lo, hi]` to `[0, 1]`; same for the sensor fed with the calibrated `x` of
    /// the cycle. Preconditioning: reset and run one quasi-static cycle, leaving every element
    /// on the descending branch at `u = 0` with all dynamic states at equilibrium.
    pub(crate) fn new(kind: SystemKind, dt: f64) -> Result<Self, SimError> {
        let (mut act, mut sen) = build(kind, dt)?;
        let cycle = sweep();

        act.set_quasi_static(true);
        act.reset();
        let mut lo = 0.0;
        for &u in &cycle {
            lo = act.raw(u);
        }
        let mut hi = lo;
        for (i, &u) in cycle.iter().enumerate() {
            let v = act.raw(u);
            if i == SWEEP_PEAK {
                hi = v;
            }
        }
        act.gain = 1.0 / span("actuator range", lo, hi)?;
        act.offset = lo;
        act.reset();
        let xs: Vec<f64> = cycle.iter().map(|&u| act.step(u)).collect();
        act.set_quasi_static(false);

        sen.set_quasi_static(true);
        sen.reset();
        let mut lo = 0.0;
        for &x in &xs {
            lo = sen.raw(x);
        }
        let mut hi = lo;
        for (i, &x) in xs.iter().enumerate() {
            let v = sen.raw(x);
            if i == SWEEP_PEAK {
                hi = v;
            }
        }
        sen.gain = 1.0 / span("sensor range", lo, hi)?;
        sen.offset = lo;
        sen.reset();
        for &x in &xs {
            sen.raw(x);
        }
        sen.set_quasi_static(false);

        Ok(Self { act, sen })
    }

    /// Actuator: next clean state `x` for input `u`.
    pub(crate) fn actuate(&mut self, u: f64) -> f64 {
        self.act.step(u)
    }

    /// Sensor: next clean output `y` for the (possibly disturbed) state `x`.
    pub(crate) fn sense(&mut self, x: f64) -> f64 {
        self.sen.step(x)
    }

    /// A copy of the sensor in its current state (for trials run over several samples).
    pub(crate) fn sensor(&self) -> Sensor {
        self.sen.clone()
    }
}
