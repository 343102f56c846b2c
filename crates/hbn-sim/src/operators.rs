//! Rate-independent hysteresis building blocks (HBN.md section 9).
//!
//! Every operator implements [`Hysteresis`]: `step` consumes the next input sample and returns
//! the output, `reset` returns to the virgin state (all internal memories at the value they have
//! for an input that has always been 0). None of them depends on the sampling period: the output
//! is a function of the input *sequence* only.

use crate::SimError;

/// A discrete-time hysteresis operator driven one sample at a time.
pub trait Hysteresis {
    /// Consumes the next input sample and returns the corresponding output.
    fn step(&mut self, input: f64) -> f64;
    /// Returns to the virgin state (as if the input had always been 0).
    fn reset(&mut self);
}

fn check(name: &'static str, value: f64, ok: bool, reason: &'static str) -> Result<(), SimError> {
    if ok && value.is_finite() {
        Ok(())
    } else {
        Err(SimError::InvalidParameter {
            name,
            value,
            reason,
        })
    }
}

fn check_len(name: &'static str, a: usize, b: usize) -> Result<(), SimError> {
    if a == b {
        Ok(())
    } else {
        Err(SimError::InvalidParameter {
            name,
            value: b as f64,
            reason: "length must match the other parameter list",
        })
    }
}

// ---------------------------------------------------------------------------------------------
// Play operator
// ---------------------------------------------------------------------------------------------

/// The play (backlash) operator of radius `r`:
/// `w[k] = max(u[k] - r, min(u[k] + r, w[k-1]))`.
#[derive(Clone, Debug, PartialEq)]
pub struct PlayOperator {
    radius: f64,
    initial: f64,
    w: f64,
}

impl PlayOperator {
    /// Play of half-width `radius >= 0` whose memory starts (and resets) at `initial`.
    pub fn new(radius: f64, initial: f64) -> Result<Self, SimError> {
        check("radius", radius, radius >= 0.0, "must be finite and >= 0")?;
        check("initial", initial, true, "must be finite")?;
        Ok(Self {
            radius,
            initial,
            w: initial,
        })
    }

    /// The radius (half-width of the dead band).
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// The current output (memory) `w`.
    pub fn output(&self) -> f64 {
        self.w
    }
}

impl Default for PlayOperator {
    /// Radius 0.1, memory starting at 0.
    fn default() -> Self {
        Self {
            radius: 0.1,
            initial: 0.0,
            w: 0.0,
        }
    }
}

impl Hysteresis for PlayOperator {
    fn step(&mut self, input: f64) -> f64 {
        self.w = (input - self.radius).max((input + self.radius).min(self.w));
        self.w
    }

    fn reset(&mut self) {
        self.w = self.initial;
    }
}

// ---------------------------------------------------------------------------------------------
// Generalised Prandtl-Ishlinskii
// ---------------------------------------------------------------------------------------------

/// Envelope function of the generalised PI model: `gamma(u) = c0 tanh(c1 u + c2) + c3`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Envelope {
    /// Amplitude.
    pub c0: f64,
    /// Input gain.
    pub c1: f64,
    /// Input offset.
    pub c2: f64,
    /// Output offset.
    pub c3: f64,
}

impl Envelope {
    /// Evaluates `c0 tanh(c1 u + c2) + c3`.
    pub fn eval(&self, u: f64) -> f64 {
        self.c0 * (self.c1 * u + self.c2).tanh() + self.c3
    }
}

impl Default for Envelope {
    /// A sigmoid through `gamma(0) = 0` and `gamma(1) = 1`, steepest at `u = 0.5`:
    /// `c0 = 0.5 / tanh(1.5)`, `c1 = 3`, `c2 = -1.5`, `c3 = 0.5`.
    fn default() -> Self {
        Self {
            c0: 0.5 / 1.5f64.tanh(),
            c1: 3.0,
            c2: -1.5,
            c3: 0.5,
        }
    }
}

/// Generalised Prandtl-Ishlinskii model: plays acting on the envelope `g = gamma(u)`,
/// `y = p0 g + sum_j p_j play_{r_j}(g)`. The plays' memories start at `gamma(0)`.
#[derive(Clone, Debug, PartialEq)]
pub struct PrandtlIshlinskii {
    envelope: Envelope,
    p0: f64,
    weights: Vec<f64>,
    plays: Vec<PlayOperator>,
}

impl PrandtlIshlinskii {
    /// Model with envelope `envelope`, direct gain `p0`, play radii `radii` (each >= 0) and
    /// play weights `weights` (same length, finite).
    pub fn new(
        envelope: Envelope,
        p0: f64,
        radii: &[f64],
        weights: &[f64],
    ) -> Result<Self, SimError> {
        check("c0", envelope.c0, true, "must be finite")?;
        check("c1", envelope.c1, true, "must be finite")?;
        check("c2", envelope.c2, true, "must be finite")?;
        check("c3", envelope.c3, true, "must be finite")?;
        check("p0", p0, true, "must be finite")?;
        check_len("weights", radii.len(), weights.len())?;
        let g0 = envelope.eval(0.0);
        let mut plays = Vec::with_capacity(radii.len());
        for (&r, &p) in radii.iter().zip(weights) {
            check("weight", p, true, "must be finite")?;
            plays.push(PlayOperator::new(r, g0)?);
        }
        Ok(Self {
            envelope,
            p0,
            weights: weights.to_vec(),
            plays,
        })
    }

    /// The envelope function.
    pub fn envelope(&self) -> Envelope {
        self.envelope
    }
}

impl Default for PrandtlIshlinskii {
    /// Default envelope, `p0 = 0.3`, six plays with radii `0.035 j` (j = 1..6) and weights 0.14.
    fn default() -> Self {
        let envelope = Envelope::default();
        let g0 = envelope.eval(0.0);
        let plays = (1..=6)
            .map(|j| PlayOperator {
                radius: 0.035 * j as f64,
                initial: g0,
                w: g0,
            })
            .collect();
        Self {
            envelope,
            p0: 0.3,
            weights: vec![0.14; 6],
            plays,
        }
    }
}

impl Hysteresis for PrandtlIshlinskii {
    fn step(&mut self, input: f64) -> f64 {
        let g = self.envelope.eval(input);
        let mut y = self.p0 * g;
        for (play, p) in self.plays.iter_mut().zip(&self.weights) {
            y += p * play.step(g);
        }
        y
    }

    fn reset(&mut self) {
        for play in &mut self.plays {
            play.reset();
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Maxwell-slip
// ---------------------------------------------------------------------------------------------

/// Maxwell-slip model: a linear spring `k0` in parallel with elasto-slide elements of stiffness
/// `k_i` that slip at force `F_i`. With `s_i = x[k] - x[k-1] + d_i[k-1]`:
/// `d_i[k] = sgn(s_i) min(|s_i|, F_i / k_i)` and `F[k] = k0 x[k] + sum_i k_i d_i[k]`.
/// Starts relaxed: `x[-1] = 0`, all `d_i = 0`.
#[derive(Clone, Debug, PartialEq)]
pub struct MaxwellSlip {
    k0: f64,
    stiffness: Vec<f64>,
    limits: Vec<f64>,
    d: Vec<f64>,
    x_prev: f64,
}

impl MaxwellSlip {
    /// Model with parallel stiffness `k0`, element stiffnesses `stiffness` (each > 0) and slip
    /// forces `slip_forces` (each >= 0, same length).
    pub fn new(k0: f64, stiffness: &[f64], slip_forces: &[f64]) -> Result<Self, SimError> {
        check("k0", k0, true, "must be finite")?;
        check_len("slip_forces", stiffness.len(), slip_forces.len())?;
        let mut limits = Vec::with_capacity(stiffness.len());
        for (&k, &f) in stiffness.iter().zip(slip_forces) {
            check("stiffness", k, k > 0.0, "must be finite and > 0")?;
            check("slip_force", f, f >= 0.0, "must be finite and >= 0")?;
            limits.push(f / k);
        }
        Ok(Self {
            k0,
            stiffness: stiffness.to_vec(),
            d: vec![0.0; limits.len()],
            limits,
            x_prev: 0.0,
        })
    }
}

impl Default for MaxwellSlip {
    /// `k0 = 0.6`, eight elements with `k_i = 0.25` and slip deflections `F_i / k_i = 0.025 i`.
    fn default() -> Self {
        let stiffness = vec![0.25; 8];
        let limits: Vec<f64> = (1..=8).map(|i| 0.025 * i as f64).collect();
        Self {
            k0: 0.6,
            stiffness,
            d: vec![0.0; limits.len()],
            limits,
            x_prev: 0.0,
        }
    }
}

impl Hysteresis for MaxwellSlip {
    fn step(&mut self, input: f64) -> f64 {
        let dx = input - self.x_prev;
        self.x_prev = input;
        let mut f = self.k0 * input;
        for ((d, &lim), &k) in self.d.iter_mut().zip(&self.limits).zip(&self.stiffness) {
            let s = dx + *d;
            *d = s.signum() * s.abs().min(lim);
            f += k * *d;
        }
        f
    }

    fn reset(&mut self) {
        self.x_prev = 0.0;
        self.d.iter_mut().for_each(|d| *d = 0.0);
    }
}

// ---------------------------------------------------------------------------------------------
// Bouc-Wen
// ---------------------------------------------------------------------------------------------

/// Parameters of [`BoucWen`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoucWenParams {
    /// `A`: initial slope of `z(u)`.
    pub a: f64,
    /// `beta > 0`: loop shape (together with `gamma`).
    pub beta: f64,
    /// `gamma`, `|gamma| <= beta`: loop shape.
    pub gamma: f64,
    /// Exponent `n >= 1`: sharpness of the transition to saturation.
    pub n: f64,
    /// Gain of the linear (elastic) part of the output.
    pub k_lin: f64,
    /// Gain of the hysteretic part of the output.
    pub k_z: f64,
    /// Largest input increment integrated in one explicit Euler sub-step (> 0).
    pub max_substep: f64,
}

impl Default for BoucWenParams {
    /// `A = 1, beta = 2.5, gamma = 0.5, n = 1, k_lin = 0.4, k_z = 1.8, max_substep = 1e-3`
    /// (`|z| < A / (beta + gamma) = 1/3`).
    fn default() -> Self {
        Self {
            a: 1.0,
            beta: 2.5,
            gamma: 0.5,
            n: 1.0,
            k_lin: 0.4,
            k_z: 1.8,
            max_substep: 1e-3,
        }
    }
}

/// Bouc-Wen model `dz = A du - beta |du| |z|^(n-1) z - gamma du |z|^n`, output
/// `y = k_lin u + k_z z`. Discretised in the input (rate-independent): the increment of each
/// sample is split into `ceil(|du| / max_substep)` explicit Euler sub-steps (at most 100 000).
/// Starts at `u = 0`, `z = 0`.
#[derive(Clone, Debug, PartialEq)]
pub struct BoucWen {
    p: BoucWenParams,
    z: f64,
    u_prev: f64,
}

impl BoucWen {
    /// Model with the given parameters (checked).
    pub fn new(p: BoucWenParams) -> Result<Self, SimError> {
        check("a", p.a, true, "must be finite")?;
        check("beta", p.beta, p.beta > 0.0, "must be finite and > 0")?;
        check(
            "gamma",
            p.gamma,
            p.gamma.abs() <= p.beta,
            "must satisfy |gamma| <= beta for bounded z",
        )?;
        check("n", p.n, p.n >= 1.0, "must be finite and >= 1")?;
        check("k_lin", p.k_lin, true, "must be finite")?;
        check("k_z", p.k_z, true, "must be finite")?;
        check(
            "max_substep",
            p.max_substep,
            p.max_substep > 0.0,
            "must be finite and > 0",
        )?;
        Ok(Self {
            p,
            z: 0.0,
            u_prev: 0.0,
        })
    }

    /// The parameters.
    pub fn params(&self) -> BoucWenParams {
        self.p
    }

    /// The hysteretic state `z`.
    pub fn z(&self) -> f64 {
        self.z
    }
}

impl Default for BoucWen {
    fn default() -> Self {
        Self {
            p: BoucWenParams::default(),
            z: 0.0,
            u_prev: 0.0,
        }
    }
}

impl Hysteresis for BoucWen {
    fn step(&mut self, input: f64) -> f64 {
        let p = &self.p;
        let du = input - self.u_prev;
        self.u_prev = input;
        let m = (du.abs() / p.max_substep).ceil().clamp(1.0, 100_000.0);
        let h = du / m;
        let unit_n = p.n == 1.0;
        for _ in 0..m as usize {
            let az = self.z.abs();
            let (zn1, zn) = if unit_n {
                (1.0, az)
            } else {
                (az.powf(p.n - 1.0), az.powf(p.n))
            };
            self.z += p.a * h - p.beta * h.abs() * zn1 * self.z - p.gamma * h * zn;
        }
        p.k_lin * input + p.k_z * self.z
    }

    fn reset(&mut self) {
        self.z = 0.0;
        self.u_prev = 0.0;
    }
}

// ---------------------------------------------------------------------------------------------
// Preisach
// ---------------------------------------------------------------------------------------------

/// Weight density of the Preisach plane, a product of Gaussians in the relay width
/// `alpha - beta` and centre `(alpha + beta) / 2`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreisachDensity {
    /// Mean relay width `alpha - beta`.
    pub width_mean: f64,
    /// Spread of the relay width (> 0).
    pub width_std: f64,
    /// Mean relay centre.
    pub center_mean: f64,
    /// Spread of the relay centre (> 0).
    pub center_std: f64,
}

impl PreisachDensity {
    /// Unnormalised density at thresholds `(alpha, beta)`.
    pub fn eval(&self, alpha: f64, beta: f64) -> f64 {
        let w = (alpha - beta - self.width_mean) / self.width_std;
        let c = (0.5 * (alpha + beta) - self.center_mean) / self.center_std;
        (-0.5 * (w * w + c * c)).exp()
    }
}

impl Default for PreisachDensity {
    /// Width `0.25 +- 0.15`, centre `0.5 +- 0.25`.
    fn default() -> Self {
        Self {
            width_mean: 0.25,
            width_std: 0.15,
            center_mean: 0.5,
            center_std: 0.25,
        }
    }
}

/// Discrete Preisach model: relays on a `levels x levels` triangular grid over `[lo, hi]`
/// (thresholds at cell centres `lo + (i + 1/2) (hi - lo) / levels`, `beta <= alpha`). A relay
/// switches up when `u >= alpha`, down when `u <= beta`. The output is the weighted fraction
/// of relays that are up, `sum w (s + 1) / 2` with weights from the density normalised to sum
/// to 1, so it lies in `[0, 1]`. Starts (and resets) with all relays down (negative
/// saturation, the state of an input that has always been `<= lo`).
#[derive(Clone, Debug, PartialEq)]
pub struct Preisach {
    alphas: Vec<f64>,
    betas: Vec<f64>,
    weights: Vec<f64>,
    up: Vec<bool>,
}

impl Preisach {
    /// Grid of `levels` (1..=1000) thresholds over `[lo, hi]` weighted by `density`.
    pub fn new(
        levels: usize,
        lo: f64,
        hi: f64,
        density: PreisachDensity,
    ) -> Result<Self, SimError> {
        check(
            "levels",
            levels as f64,
            (1..=1000).contains(&levels),
            "must be in 1..=1000",
        )?;
        check("lo", lo, true, "must be finite")?;
        check("hi", hi, hi > lo, "must be finite and > lo")?;
        check("width_mean", density.width_mean, true, "must be finite")?;
        check(
            "width_std",
            density.width_std,
            density.width_std > 0.0,
            "must be finite and > 0",
        )?;
        check("center_mean", density.center_mean, true, "must be finite")?;
        check(
            "center_std",
            density.center_std,
            density.center_std > 0.0,
            "must be finite and > 0",
        )?;
        let cell = (hi - lo) / levels as f64;
        let n = levels * (levels + 1) / 2;
        let (mut alphas, mut betas, mut weights) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for i in 0..levels {
            let alpha = lo + (i as f64 + 0.5) * cell;
            for j in 0..=i {
                let beta = lo + (j as f64 + 0.5) * cell;
                alphas.push(alpha);
                betas.push(beta);
                weights.push(density.eval(alpha, beta));
            }
        }
        let total: f64 = weights.iter().sum();
        if !(total.is_finite() && total > 0.0) {
            return Err(SimError::InvalidParameter {
                name: "density",
                value: total,
                reason: "total relay weight must be finite and > 0",
            });
        }
        weights.iter_mut().for_each(|w| *w /= total);
        Ok(Self {
            alphas,
            betas,
            weights,
            up: vec![false; n],
        })
    }

    /// Number of relays.
    pub fn relays(&self) -> usize {
        self.weights.len()
    }
}

impl Default for Preisach {
    /// 50 levels over `[0, 1]` with the default density.
    fn default() -> Self {
        let mut p = Self {
            alphas: Vec::new(),
            betas: Vec::new(),
            weights: Vec::new(),
            up: Vec::new(),
        };
        if let Ok(built) = Self::new(50, 0.0, 1.0, PreisachDensity::default()) {
            p = built;
        }
        p
    }
}

impl Hysteresis for Preisach {
    fn step(&mut self, input: f64) -> f64 {
        let mut y = 0.0;
        for (((up, &a), &b), &w) in self
            .up
            .iter_mut()
            .zip(&self.alphas)
            .zip(&self.betas)
            .zip(&self.weights)
        {
            if input >= a {
                *up = true;
            } else if input <= b {
                *up = false;
            }
            if *up {
                y += w;
            }
        }
        y
    }

    fn reset(&mut self) {
        self.up.iter_mut().for_each(|s| *s = false);
    }
}

// ---------------------------------------------------------------------------------------------
// Duhem / Coleman-Hodgdon
// ---------------------------------------------------------------------------------------------

/// Coleman-Hodgdon (Duhem) model: `y_h[k] = y_h[k-1] + b du - a |du| y_h[k-1]` with
/// `du = u[k] - u[k-1]`, output `y = k_lin u + y_h` (linear anhysteretic part plus hysteretic
/// part, `|y_h| -> b / a`). The formula is applied once per sample when `a |du| <= 0.5`;
/// larger increments are split into `ceil(a |du| / 0.5)` equal sub-steps for stability.
/// Starts at `u = 0`, `y_h = 0`.
#[derive(Clone, Debug, PartialEq)]
pub struct Duhem {
    a: f64,
    b: f64,
    k_lin: f64,
    yh: f64,
    u_prev: f64,
}

impl Duhem {
    /// Model with decay rate `a >= 0`, hysteretic gain `b` and linear gain `k_lin`.
    pub fn new(a: f64, b: f64, k_lin: f64) -> Result<Self, SimError> {
        check("a", a, a >= 0.0, "must be finite and >= 0")?;
        check("b", b, true, "must be finite")?;
        check("k_lin", k_lin, true, "must be finite")?;
        Ok(Self {
            a,
            b,
            k_lin,
            yh: 0.0,
            u_prev: 0.0,
        })
    }

    /// The hysteretic state `y_h`.
    pub fn hysteretic_part(&self) -> f64 {
        self.yh
    }
}

impl Default for Duhem {
    /// `a = 5, b = 1, k_lin = 0.6` (`|y_h| < 0.2`).
    fn default() -> Self {
        Self {
            a: 5.0,
            b: 1.0,
            k_lin: 0.6,
            yh: 0.0,
            u_prev: 0.0,
        }
    }
}

impl Hysteresis for Duhem {
    fn step(&mut self, input: f64) -> f64 {
        let du = input - self.u_prev;
        self.u_prev = input;
        let m = (self.a * du.abs() / 0.5).ceil().clamp(1.0, 100_000.0);
        let h = du / m;
        for _ in 0..m as usize {
            self.yh += self.b * h - self.a * h.abs() * self.yh;
        }
        self.k_lin * input + self.yh
    }

    fn reset(&mut self) {
        self.yh = 0.0;
        self.u_prev = 0.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64, tol: f64) {
        assert!((a - b).abs() <= tol, "{a} vs {b} (tol {tol})");
    }

    #[test]
    fn play_operator_ramp_up_down() {
        let mut p = PlayOperator::new(0.1, 0.0).unwrap();
        let u = [0.0, 0.2, 0.4, 0.3, 0.2, 0.1, 0.0];
        let want = [0.0, 0.1, 0.3, 0.3, 0.3, 0.2, 0.1];
        for (&ui, &wi) in u.iter().zip(&want) {
            close(p.step(ui), wi, 1e-15);
        }
        p.reset();
        assert_eq!(p.output(), 0.0);
        assert!(PlayOperator::new(-0.1, 0.0).is_err());
        assert!(PlayOperator::new(0.1, f64::NAN).is_err());
    }

    #[test]
    fn generalized_pi_matches_hand_composition() {
        let env = Envelope {
            c0: 1.0,
            c1: 2.0,
            c2: 0.0,
            c3: 0.0,
        };
        let mut pi = PrandtlIshlinskii::new(env, 0.5, &[0.1, 0.2], &[0.3, 0.7]).unwrap();
        let mut p1 = PlayOperator::new(0.1, 0.0).unwrap();
        let mut p2 = PlayOperator::new(0.2, 0.0).unwrap();
        for &u in &[0.0f64, 0.1, 0.3, 0.6, 0.4, 0.2, 0.35, 0.0] {
            let g = (2.0 * u).tanh();
            let want = 0.5 * g + 0.3 * p1.step(g) + 0.7 * p2.step(g);
            close(pi.step(u), want, 1e-15);
        }
        // Hand value: u = 0.5 from rest, g = tanh(1) = 0.761594..., plays at g - r.
        pi.reset();
        let g = 1f64.tanh();
        close(
            pi.step(0.5),
            0.5 * g + 0.3 * (g - 0.1) + 0.7 * (g - 0.2),
            1e-15,
        );
        assert!(PrandtlIshlinskii::new(env, 0.5, &[0.1], &[0.3, 0.7]).is_err());
        // Default envelope passes through (0, 0) and (1, 1).
        close(Envelope::default().eval(0.0), 0.0, 1e-15);
        close(Envelope::default().eval(1.0), 1.0, 1e-15);
    }

    #[test]
    fn maxwell_slip_element_saturates_at_f_over_k() {
        // One element k = 2, F = 0.2 -> slip deflection 0.1, force limit 0.2; no parallel spring.
        let mut m = MaxwellSlip::new(0.0, &[2.0], &[0.2]).unwrap();
        close(m.step(0.05), 0.1, 1e-15); // sticking: d = 0.05
        close(m.step(0.3), 0.2, 1e-15); // slipped: d = F/k = 0.1, force = F
        close(m.step(0.5), 0.2, 1e-15); // stays saturated
        close(m.step(0.45), 0.1, 1e-15); // reversal: d = 0.05
        close(m.step(0.0), -0.2, 1e-15); // saturated the other way
        // With a parallel spring k0 = 1 the force adds k0 x.
        let mut m = MaxwellSlip::new(1.0, &[2.0], &[0.2]).unwrap();
        close(m.step(0.3), 0.3 + 0.2, 1e-15);
        assert!(MaxwellSlip::new(1.0, &[0.0], &[0.2]).is_err());
        assert!(MaxwellSlip::new(1.0, &[1.0], &[-0.2]).is_err());
    }

    #[test]
    fn bouc_wen_virgin_curve_matches_closed_form() {
        // n = 1, loading from z = 0 with du > 0: dz/du = A - (beta + gamma) z, so
        // z(u) = A / (beta + gamma) (1 - exp(-(beta + gamma) u)).
        let mut bw = BoucWen::new(BoucWenParams {
            k_lin: 0.0,
            k_z: 1.0,
            max_substep: 1e-4,
            ..BoucWenParams::default()
        })
        .unwrap();
        for k in 1..=50 {
            let u = 0.02 * k as f64;
            let z = bw.step(u);
            close(z, (1.0 - (-3.0 * u).exp()) / 3.0, 1e-4);
        }
        // Unloading (z > 0, du < 0): dz/du = A + (beta - gamma) z, a steeper descent.
        let z1 = bw.z();
        let z2 = bw.step(0.98);
        close((z2 - z1) / -0.02, 1.0 + 2.0 * z1, 0.05);
        assert!(
            BoucWen::new(BoucWenParams {
                gamma: 3.0,
                ..BoucWenParams::default()
            })
            .is_err()
        );
        assert!(
            BoucWen::new(BoucWenParams {
                n: 0.5,
                ..BoucWenParams::default()
            })
            .is_err()
        );
    }

    #[test]
    fn bouc_wen_substeps_make_it_step_size_independent() {
        let mut coarse = BoucWen::default();
        let mut fine = BoucWen::default();
        let a = coarse.step(0.8);
        let mut b = 0.0;
        for k in 1..=80 {
            b = fine.step(0.01 * k as f64);
        }
        close(a, b, 1e-4);
        // z stays within A / (beta + gamma) even for huge jumps.
        coarse.reset();
        for &u in &[1.5, -0.5, 1.5, -0.5] {
            coarse.step(u);
            assert!(coarse.z().abs() <= 1.0 / 3.0 + 1e-9);
        }
    }

    #[test]
    fn preisach_two_level_hand_case() {
        let d = PreisachDensity::default();
        let mut p = Preisach::new(2, 0.0, 1.0, d).unwrap();
        assert_eq!(p.relays(), 3);
        // relays: (0.25, 0.25), (0.75, 0.25), (0.75, 0.75)
        let w = [d.eval(0.25, 0.25), d.eval(0.75, 0.25), d.eval(0.75, 0.75)];
        let t: f64 = w.iter().sum();
        close(p.step(0.0), 0.0, 1e-15);
        close(p.step(0.5), w[0] / t, 1e-15);
        close(p.step(1.0), 1.0, 1e-12);
        close(p.step(0.5), (w[0] + w[1]) / t, 1e-15);
        close(p.step(0.0), 0.0, 1e-15);
        p.step(1.0);
        p.reset();
        close(p.step(0.5), w[0] / t, 1e-15);
        assert!(Preisach::new(0, 0.0, 1.0, d).is_err());
        assert!(Preisach::new(3, 1.0, 1.0, d).is_err());
        assert_eq!(Preisach::default().relays(), 50 * 51 / 2);
    }

    #[test]
    fn duhem_increment_formula() {
        let mut d = Duhem::new(2.0, 1.0, 0.5).unwrap();
        // yh = 0 + 1 * 0.1 - 2 * 0.1 * 0 = 0.1
        close(d.step(0.1), 0.05 + 0.1, 1e-15);
        // yh = 0.1 + 0.1 - 2 * 0.1 * 0.1 = 0.18
        close(d.step(0.2), 0.1 + 0.18, 1e-15);
        // yh = 0.18 - 0.1 - 2 * 0.1 * 0.18 = 0.044
        close(d.step(0.1), 0.05 + 0.044, 1e-15);
        close(d.hysteretic_part(), 0.044, 1e-15);
        // Saturation towards b / a under sustained loading.
        d.reset();
        let mut y = 0.0;
        for k in 1..=200 {
            y = d.step(0.05 * k as f64) - 0.5 * 0.05 * k as f64;
        }
        close(y, 0.5, 1e-6);
        assert!(Duhem::new(-1.0, 1.0, 0.0).is_err());
    }
}
