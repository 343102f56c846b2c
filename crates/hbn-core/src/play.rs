//! Play operators: the input's long memory, as extra inputs of the transition GP.
//!
//! The HBN's transition `x_k = H_D(x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2})` sees two samples of
//! the input. A hysteretic system with a long memory (a Preisach material, where the state
//! depends on which past extrema of `u` have not yet been wiped out) needs more than that,
//! and the filter's state `x_{k-1}` carries it only as far as the model of it is exact. A
//! *play operator* of radius `r` (a backlash: Krasnosel'skii and Pokrovskii, "Systems with
//! Hysteresis", 1989; the building block of the Prandtl-Ishlinskii model) is a one-number
//! summary of the input's whole past:
//!
//! ```text
//! p_k = max(u_k - r, min(u_k + r, p_{k-1})),   p_0 = u_0
//! ```
//!
//! It follows `u` at distance `r` while `u` moves one way and stays put for a reversal smaller
//! than `2 r`. With plays, the transition GP reads
//! `[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}, p^1_{k-1}, .., p^m_{k-1}]`. The plays depend on the
//! input alone, so the filter's Jacobians and noise are those of the HBN without them.
//! `docs/memory.md` explains how the radii are chosen.
//!
//! Beside the plays, a model may have **lags**: first-order low-pass filters of the input,
//! `l_k = l_{k-1} + a (u_k - l_{k-1})`, `l_0 = u_0`, with `a = 1 - exp(-dt / tau)` for a time
//! constant `tau`. They summarise the recent past of `u` on the scale `tau`, which is what
//! creep and viscoelastic relaxation (soft materials) depend on and two samples of `u` cannot
//! show. They follow the plays among the transition's inputs, and count towards
//! [`MAX_PLAYS`].

use crate::CoreError;

/// Most memory operators (plays and lags together) a model can have (the transition's
/// dimension, `4 + plays + lags`, stays within [`crate::MAX_DIM`]).
pub const MAX_PLAYS: usize = 4;

/// A model's memory operators of the input: play operators (their radii, in the input's
/// units) and lags (their coefficients `a` in `(0, 1]`), checked, at most [`MAX_PLAYS`] in
/// all. The default has none: the thesis' HBN.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Plays {
    radii: [f64; MAX_PLAYS],
    len: usize,
    lags: [f64; MAX_PLAYS],
    n_lags: usize,
}

/// The plays' values after some input: what the filter carries between steps.
pub type PlayState = [f64; MAX_PLAYS];

impl Plays {
    /// No play operators.
    pub const NONE: Plays = Plays {
        radii: [0.0; MAX_PLAYS],
        len: 0,
        lags: [0.0; MAX_PLAYS],
        n_lags: 0,
    };

    /// Play operators and lags: [`Plays::new`]`(radii)` plus lags with coefficients `lags`
    /// (each in `(0, 1]`: [`lag_coefficient`]); at most [`MAX_PLAYS`] in all.
    pub fn with_lags(radii: &[f64], lags: &[f64]) -> Result<Self, CoreError> {
        let mut out = Self::new(radii)?;
        if radii.len() + lags.len() > MAX_PLAYS {
            return Err(CoreError::InvalidSpec(
                "a model has at most 4 play operators and lags in all",
            ));
        }
        for (slot, &a) in out.lags.iter_mut().zip(lags) {
            if !(a.is_finite() && a > 0.0 && a <= 1.0) {
                return Err(CoreError::InvalidSpec(
                    "a lag's coefficient must lie in (0, 1]",
                ));
            }
            *slot = a;
        }
        out.n_lags = lags.len();
        Ok(out)
    }

    /// Checks the radii: at most [`MAX_PLAYS`], each finite and positive.
    pub fn new(radii: &[f64]) -> Result<Self, CoreError> {
        if radii.len() > MAX_PLAYS {
            return Err(CoreError::InvalidSpec(
                "a model has at most 4 play operators",
            ));
        }
        let mut out = Self::NONE;
        for (slot, &r) in out.radii.iter_mut().zip(radii) {
            if !(r.is_finite() && r > 0.0) {
                return Err(CoreError::InvalidSpec(
                    "a play operator's radius must be finite and positive",
                ));
            }
            *slot = r;
        }
        out.len = radii.len();
        Ok(out)
    }

    /// The play operators' radii.
    pub fn radii(&self) -> &[f64] {
        self.radii.get(..self.len).unwrap_or(&[])
    }

    /// The lags' coefficients `a`.
    pub fn lags(&self) -> &[f64] {
        self.lags.get(..self.n_lags).unwrap_or(&[])
    }

    /// Number of memory operators (plays and lags): the transition's extra inputs.
    pub fn len(&self) -> usize {
        self.len + self.n_lags
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The plays at the first input `u_0`: all equal to it (unused slots too).
    pub fn start(&self, u0: f64) -> PlayState {
        [u0; MAX_PLAYS]
    }

    /// Advances the plays, then the lags, by one input `u` (unused slots follow `u`). A
    /// non-finite `u` leaves them as they are.
    pub fn advance(&self, state: &mut PlayState, u: f64) {
        if !u.is_finite() {
            return;
        }
        let (radii, lags) = (self.radii(), self.lags());
        for (i, p) in state.iter_mut().enumerate() {
            *p = match (
                radii.get(i),
                i.checked_sub(radii.len()).and_then(|j| lags.get(j)),
            ) {
                (Some(&r), _) => clamp_play(*p, u - r, u + r),
                (None, Some(&a)) => *p + a * (u - *p),
                (None, None) => u,
            };
        }
    }

    /// The plays of a whole input sequence: `out[k]` is the state after `u_0..=u_k`
    /// (`out[0]` = `start(u_0)`). Writes `min(u.len(), out.len())` states.
    pub fn run(&self, u: &[f64], out: &mut [PlayState]) {
        let Some(&u0) = u.first() else { return };
        let mut st = self.start(u0);
        for (o, &uk) in out.iter_mut().zip(u) {
            self.advance(&mut st, uk);
            *o = st;
        }
    }
}

/// The coefficient `a = 1 - exp(-1 / (rate_hz tau))` of a lag with time constant `tau`
/// seconds at `rate_hz` samples per second (`None` unless both are finite and positive).
pub fn lag_coefficient(tau: f64, rate_hz: f64) -> Option<f64> {
    let samples = tau * rate_hz;
    (tau.is_finite() && rate_hz.is_finite() && tau > 0.0 && rate_hz > 0.0 && samples.is_finite())
        .then(|| -libm::expm1(-1.0 / samples))
}

/// The transition's input `[x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}, plays and lags after u_{k-1}]`, with
/// every play slot filled: a GP with `4 + plays.len()` inputs reads the first that many (the
/// filter, the open-loop simulation, the training rows and the explorer all build it here).
pub fn transition_input(
    x1: f64,
    x2: f64,
    u1: f64,
    u2: f64,
    plays: &PlayState,
) -> [f64; crate::MAX_DIM] {
    let mut input = [0.0; crate::MAX_DIM];
    for (slot, v) in input.iter_mut().zip([x1, x2, u1, u2].iter().chain(plays)) {
        *slot = *v;
    }
    input
}

/// `p` clamped to `[lo, hi]` (`max(lo, min(hi, p))`, without `f64::clamp`'s panic).
pub(crate) fn clamp_play(p: f64, lo: f64, hi: f64) -> f64 {
    let p = if p > hi { hi } else { p };
    if p < lo { lo } else { p }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_play_follows_at_its_radius_and_holds_on_small_reversals() {
        let plays = Plays::new(&[1.0]).unwrap();
        let u = [0.0, 0.5, 2.0, 3.0, 2.5, 1.5, 0.5, 0.8];
        let mut out = [[0.0; MAX_PLAYS]; 8];
        plays.run(&u, &mut out);
        let p: Vec<f64> = out.iter().map(|s| s[0]).collect();
        // Starts at u_0, holds while |u - p| <= r, then trails u by r.
        assert_eq!(p, vec![0.0, 0.0, 1.0, 2.0, 2.0, 2.0, 1.5, 1.5]);
        // Unused slots follow the input.
        assert_eq!(out[5][1], 1.5);
    }

    #[test]
    fn the_play_remembers_which_way_the_input_came() {
        // Same input value, reached from above and from below: different plays.
        let plays = Plays::new(&[0.5]).unwrap();
        let mut up = plays.start(0.0);
        for u in [0.0, 1.0, 2.0] {
            plays.advance(&mut up, u);
        }
        let mut down = plays.start(4.0);
        for u in [4.0, 3.0, 2.0] {
            plays.advance(&mut down, u);
        }
        assert_eq!(up[0], 1.5);
        assert_eq!(down[0], 2.5);
    }

    #[test]
    fn bad_radii_are_rejected() {
        assert!(Plays::new(&[]).unwrap().is_empty());
        assert!(Plays::new(&[0.0]).is_err());
        assert!(Plays::new(&[-1.0]).is_err());
        assert!(Plays::new(&[f64::NAN]).is_err());
        assert!(Plays::new(&[1.0; 5]).is_err());
        assert_eq!(Plays::new(&[1.0, 2.0]).unwrap().radii(), &[1.0, 2.0]);
    }

    #[test]
    fn a_lag_is_a_first_order_low_pass_after_the_plays() {
        let a = lag_coefficient(1.0, 10.0).unwrap();
        assert!((a - (1.0 - (-0.1f64).exp())).abs() < 1e-15);
        let m = Plays::with_lags(&[1.0], &[0.5]).unwrap();
        assert_eq!(m.len(), 2);
        assert_eq!(m.lags(), &[0.5]);
        let u = [0.0, 2.0, 2.0, 2.0, 0.0];
        let mut out = [[0.0; MAX_PLAYS]; 5];
        m.run(&u, &mut out);
        // Slot 0: the play of radius 1; slot 1: the lag, halfway towards u at every step.
        assert_eq!(out.map(|s| s[0]), [0.0, 1.0, 1.0, 1.0, 1.0]);
        assert_eq!(out.map(|s| s[1]), [0.0, 1.0, 1.5, 1.75, 0.875]);
        // Unused slots follow the input.
        assert_eq!(out[4][2], 0.0);
        // A lag of coefficient 1 is the input itself.
        let id = Plays::with_lags(&[], &[1.0]).unwrap();
        let mut s = id.start(3.0);
        id.advance(&mut s, 7.0);
        assert_eq!(s[0], 7.0);
    }

    #[test]
    fn bad_lags_are_rejected() {
        assert!(Plays::with_lags(&[], &[0.0]).is_err());
        assert!(Plays::with_lags(&[], &[1.5]).is_err());
        assert!(Plays::with_lags(&[], &[f64::NAN]).is_err());
        assert!(Plays::with_lags(&[1.0; 3], &[0.5; 2]).is_err());
        assert!(Plays::with_lags(&[0.0], &[0.5]).is_err());
        assert_eq!(lag_coefficient(0.0, 100.0), None);
        assert_eq!(lag_coefficient(1.0, f64::INFINITY), None);
        assert_eq!(lag_coefficient(f64::NAN, 100.0), None);
    }

    #[test]
    fn a_non_finite_input_leaves_the_plays_alone() {
        let plays = Plays::new(&[1.0]).unwrap();
        let mut s = plays.start(3.0);
        plays.advance(&mut s, f64::NAN);
        assert_eq!(s, [3.0; MAX_PLAYS]);
    }
}
