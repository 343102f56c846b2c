//! The floors under state estimation on a simulated trajectory: the exact posterior of `x_k`
//! under the simulator's own model, given more than any estimator has.
//!
//! With the noise model of the crate docs, the clean state `x_clean[k]` is a deterministic
//! function of `u[0..=k]`, and the recorded state is `x[k] = x_clean[k] + w_x eta_x[k]` with
//! `eta_x[k]` uniform on `[-0.5, 0.5]`, independent of everything else (the disturbance is not
//! fed back into the actuator). The sensor reads it: `y[j] = S_j(x[0..=j]) + w_y eta_y[j]`,
//! where the sensor's state depends on the states before `j`, so `x[k]` moves every later
//! output through the sensor's memory.
//!
//! - **Causal** ([`oracle_estimate`]): given the simulator, `u`, `y[0..=k]` and the **true**
//!   past states `x[0..k]`, the only unknown at sample `k` is `eta_x[k]`, and its posterior is
//!   uniform on the set of `eta` in `[-0.5, 0.5]` with `|y[k] - S_k(x_clean[k] + w_x eta)| <=
//!   w_y / 2`.
//! - **Two-sided** ([`oracle_smooth_estimate`]): given also `y[k+1..=k+L]` and the true
//!   states at every other sample, past and future, the unknown is still `eta_x[k]` alone (the
//!   other disturbances are given, and independent of it), and its posterior is uniform on the
//!   `eta` for which `y[k]` **and** every `y[k+j]`, `j = 1..=L`, lie within `w_y / 2` of the
//!   sensor run forward from `x[k] = x_clean[k] + w_x eta` through the true later states.
//!
//! Each estimate is that posterior's mean, found on a grid of [`ORACLE_GRID`] + 1 points.
//!
//! Why they are floors: the posterior mean minimises the mean squared error given what it
//! conditions on, and conditioning on more (the true states around `x[k]`, the true model) can
//! only lower the least achievable error. A causal estimator (a filter, an LSTM) sees
//! `u[0..=k]` and `y[0..=k]` only, so none has a lower expected squared error than
//! [`oracle_estimate`] on the same trajectory; a smoother sees `u` and `y` over the whole log,
//! so none has a lower expected squared error than [`oracle_smooth_estimate`] with a lookahead
//! reaching the end of the log. What is left between an estimator and its floor is what
//! better learning, filtering or smoothing could still win, and the ratio of the two floors is
//! the most any smoother could gain over the best filter there.
//!
//! Neither applies to a system whose disturbance propagates
//! ([`crate::SystemKind::disturbance_propagates`]): its state carries the disturbances of the
//! samples before it, so the true past states do not pin the current one, and both refuse it
//! ([`SimError::NoExactOracle`]).

use std::collections::VecDeque;

use crate::{SimConfig, SimError, Trajectory, check_input, systems::Sensor, systems::System};

/// Intervals of the grid over `eta_x[k]` on which [`oracle_estimate`] and
/// [`oracle_smooth_estimate`] find the posterior. The posterior mean is then within a few
/// thousandths of the disturbance's width `w_x` of the exact one (the grid's spacing is
/// `w_x / 400`).
pub const ORACLE_GRID: usize = 400;

/// The posterior of every `x[k]` found by [`oracle_estimate`] or [`oracle_smooth_estimate`].
#[derive(Clone, Debug, PartialEq)]
pub struct OracleEstimate {
    /// Posterior mean of `x[k]`, the least-squares estimate.
    pub mean: Vec<f64>,
    /// Posterior standard deviation of `x[k]` (the grid's own spacing included, so never 0
    /// unless the data are noise-free).
    pub std: Vec<f64>,
    /// Lowest `x[k]` the data allow (the posterior's support is `[lo, hi]`, to the grid's
    /// spacing).
    pub lo: Vec<f64>,
    /// Highest `x[k]` the data allow.
    pub hi: Vec<f64>,
    /// Samples where no grid point explained every output it was checked against within the
    /// noise's bound (an allowed set narrower than the grid's spacing). There the estimate
    /// keeps the grid points that explain the longest run `y[k], y[k+1], ...`; where none
    /// explains `y[k]`, the grid point with the smallest residual at `k`.
    pub unresolved: usize,
}

/// The exact posterior of each recorded state `x[k]` of `traj`, a trajectory of `config`'s
/// system, given `u[0..=k]`, `y[0..=k]`, the simulator's model and the true past states
/// `x[0..k]`: the floor under causal estimation.
///
/// Why its error is a floor: `x[k]` is the clean state, a deterministic function of `u[0..=k]`,
/// plus a uniform disturbance drawn afresh at every sample; `y[k]` is the sensor's reading of
/// `x[k]`, whose state depends on the past states, plus uniform noise. Given the true past, the
/// only unknown is the current disturbance, and its posterior is uniform on the values that
/// explain `y[k]` within the noise's bound; the estimate is its mean, found on a grid of
/// [`ORACLE_GRID`] + 1 points. A causal estimator (a filter, an LSTM) sees `u[0..=k]` and
/// `y[0..=k]` only, a subset of what this posterior conditions on, so none has a lower expected
/// squared error on the trajectory.
///
/// `traj` must come from [`crate::simulate`] with `config` (the same system, rate and noise
/// gain; the noise seed is not used). With `noise_gain = 0` the estimate is the clean state,
/// exactly `traj.x`. It is [`oracle_smooth_estimate`] with lookahead 0.
///
/// # Errors
/// An invalid `config`, a system whose disturbance propagates ([`SimError::NoExactOracle`]),
/// signals of different lengths, or an input outside [`crate::INPUT_RANGE`].
pub fn oracle_estimate(config: &SimConfig, traj: &Trajectory) -> Result<OracleEstimate, SimError> {
    posterior(config, traj, 0)
}

/// The exact posterior of each recorded state `x[k]` of `traj`, a trajectory of `config`'s
/// system, given `u`, `y[0..=k + lookahead]`, the simulator's model and the true states at
/// every other sample, past and future: the floor under two-sided estimation (smoothing).
///
/// Why its error is a floor: the disturbance `eta_x[k]` is independent of every other sample's
/// disturbance and noise, so given the true states around it, it is the only unknown, and the
/// later outputs inform it only through the sensor's memory. Its posterior is uniform on the
/// values for which `y[k]` and every `y[k+j]`, `j = 1..=lookahead`, lie within the noise's
/// bound of the sensor run forward from `x[k] = x_clean[k] + w_x eta` through the true states
/// `x[k+1..]`; the estimate is its mean, found on a grid of [`ORACLE_GRID`] + 1 points. An
/// estimator that sees `u` and `y[0..=k + lookahead]` only conditions on less, so none has a
/// lower expected squared error on the trajectory; with `lookahead >= traj.u.len()` (say
/// `usize::MAX`) it is the floor under any smoother of the whole log. Lookahead 0 gives
/// exactly [`oracle_estimate`], and a longer one is never worse on average.
///
/// Cost: each grid point that explains `y[k]` runs a copy of the sensor forward until an
/// output falls outside the bound, the lookahead ends, or the copy's state equals the true
/// sensor's (then every later output is the truth's, which the bound allows: the run stops,
/// exactly). Rate-independent sensors forget a sample after a large enough excursion, so the
/// run is short on them whatever the lookahead; a sensor with a continuous state (a lag, a
/// Duhem or Bouc-Wen operator) never quite forgets, and there the lookahead bounds the cost.
/// The true sensor's states over the lookahead are kept (memory: one sensor per sample of
/// the lookahead, at most the log).
///
/// `traj` must come from [`crate::simulate`] with `config` (the same system, rate and noise
/// gain; the noise seed is not used). With `noise_gain = 0` the estimate is exactly `traj.x`.
///
/// # Errors
/// As [`oracle_estimate`].
pub fn oracle_smooth_estimate(
    config: &SimConfig,
    traj: &Trajectory,
    lookahead: usize,
) -> Result<OracleEstimate, SimError> {
    posterior(config, traj, lookahead)
}

/// The posterior of each `x[k]` given `y[0..=k + lookahead]` and the true states at every other
/// sample (see [`oracle_smooth_estimate`]).
fn posterior(
    config: &SimConfig,
    traj: &Trajectory,
    lookahead: usize,
) -> Result<OracleEstimate, SimError> {
    config.validate()?;
    if config.system.disturbance_propagates() {
        return Err(SimError::NoExactOracle {
            system: config.system.name(),
        });
    }
    let n = traj.u.len();
    if traj.x.len() != n || traj.y.len() != n {
        return Err(SimError::LengthMismatch {
            u: n,
            x: traj.x.len(),
            y: traj.y.len(),
        });
    }
    check_input(&traj.u)?;
    let mut system = System::new(config.system, 1.0 / config.rate_hz)?;
    let width_x = config.noise_width_x();
    let width_y = config.noise_width_y();
    let spacing = width_x / ORACLE_GRID as f64;
    // Rounding slack on the bound `|residual| <= w_y / 2`: the truth sits inside it exactly in
    // real arithmetic, and the simulator's own sum may round it just outside.
    let bound = 0.5 * width_y * (1.0 + 1e-9) + 1e-15;
    let grid_var = spacing * spacing / 12.0;

    let mut out = OracleEstimate {
        mean: Vec::with_capacity(n),
        std: Vec::with_capacity(n),
        lo: Vec::with_capacity(n),
        hi: Vec::with_capacity(n),
        unresolved: 0,
    };
    // The true sensor's states after samples `k..=last` (front: after `k`), run ahead of the
    // estimate; only kept with a lookahead.
    let mut truth_ahead = system.sensor();
    let mut truth: VecDeque<Sensor> = VecDeque::new();
    let mut ahead_done = 0usize;
    // Per grid point: the trial state and how many outputs in a row from `y[k]` it explains.
    let mut trials = vec![(0.0, 0usize); ORACLE_GRID + 1];
    for k in 0..n {
        let x_clean = system.actuate(traj.u[k]);
        let last = k.saturating_add(lookahead).min(n - 1);
        let full = last - k + 1;
        if lookahead > 0 && width_x > 0.0 {
            truth.pop_front();
            while ahead_done <= last {
                truth_ahead.step(traj.x[ahead_done]);
                truth.push_back(truth_ahead.clone());
                ahead_done += 1;
            }
        }
        if width_x > 0.0 {
            let (mut best_residual, mut best_x) = (f64::INFINITY, x_clean);
            let mut deepest = 0usize;
            for (i, trial) in trials.iter_mut().enumerate() {
                let eta = i as f64 / ORACLE_GRID as f64 - 0.5;
                let x_trial = x_clean + width_x * eta;
                let mut sensor = system.sensor();
                let residual = (traj.y[k] - sensor.step(x_trial)).abs();
                if residual < best_residual {
                    best_residual = residual;
                    best_x = x_trial;
                }
                let mut depth = 0;
                if residual <= bound {
                    depth = 1;
                    if full > 1 {
                        depth = explained_ahead(&mut sensor, traj, &truth, k, last, bound);
                    }
                }
                *trial = (x_trial, depth);
                deepest = deepest.max(depth);
            }
            if deepest == 0 {
                out.unresolved += 1;
                out.mean.push(best_x);
                out.std.push(grid_var.sqrt());
                out.lo.push(best_x);
                out.hi.push(best_x);
            } else {
                if deepest < full {
                    out.unresolved += 1;
                }
                let (mut count, mut sum, mut sum_sq) = (0usize, 0.0, 0.0);
                let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
                for &(x_trial, depth) in &trials {
                    if depth == deepest {
                        count += 1;
                        sum += x_trial;
                        sum_sq += x_trial * x_trial;
                        lo = lo.min(x_trial);
                        hi = hi.max(x_trial);
                    }
                }
                let mean = sum / count as f64;
                let var = (sum_sq / count as f64 - mean * mean).max(0.0);
                out.mean.push(mean);
                out.std.push((var + grid_var).sqrt());
                out.lo.push(lo);
                out.hi.push(hi);
            }
        } else {
            out.mean.push(x_clean);
            out.std.push(0.0);
            out.lo.push(x_clean);
            out.hi.push(x_clean);
        }
        // The sensor moves on with the true state, which the oracle is given.
        system.sense(traj.x[k]);
    }
    Ok(out)
}

/// How many outputs in a row from `y[k]` (which it explains) a trial sensor explains, up to
/// `y[last]`: `sensor` has read the trial state `x[k]`, and runs on through the true states.
/// `truth[j - k]` is the true sensor's state after sample `j`; once the trial's equals it,
/// every later output is the truth's, which the bound allows.
fn explained_ahead(
    sensor: &mut Sensor,
    traj: &Trajectory,
    truth: &VecDeque<Sensor>,
    k: usize,
    last: usize,
    bound: f64,
) -> usize {
    let full = last - k + 1;
    if truth.front() == Some(&*sensor) {
        return full;
    }
    for j in k + 1..=last {
        if (traj.y[j] - sensor.step(traj.x[j])).abs() > bound {
            return j - k;
        }
        if truth.get(j - k) == Some(&*sensor) {
            return full;
        }
    }
    full
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{SystemKind, simulate_random};

    fn config(system: SystemKind, gain: f64, seed: u64) -> SimConfig {
        SimConfig {
            noise_gain: gain,
            seed,
            ..SimConfig::new(system)
        }
    }

    #[test]
    fn noise_free_data_are_recovered_exactly() {
        let c = config(SystemKind::Duhem, 0.0, 3);
        let traj = simulate_random(&c, 300).unwrap();
        let est = oracle_estimate(&c, &traj).unwrap();
        assert_eq!(est.mean, traj.x);
        assert!(est.std.iter().all(|&s| s == 0.0));
    }

    /// The true state lies in the posterior's support at every sample, on every system: this
    /// fails if the oracle's model of the sensor drifts from the simulator's (say, the sensor
    /// moved on with the estimate instead of the true state), because then the truth no longer
    /// explains `y` within the noise's bound somewhere.
    /// The systems with an exact oracle (every one whose disturbance does not propagate).
    fn exact() -> impl Iterator<Item = SystemKind> {
        SystemKind::ALL
            .into_iter()
            .filter(|k| !k.disturbance_propagates())
    }

    #[test]
    fn the_truth_is_always_allowed() {
        for system in exact() {
            let c = config(system, 3.0, 7);
            let traj = simulate_random(&c, 400).unwrap();
            let est = oracle_estimate(&c, &traj).unwrap();
            let spacing = c.noise_width_x() / ORACLE_GRID as f64;
            assert_eq!(est.unresolved, 0, "{system}");
            for k in 0..traj.x.len() {
                assert!(
                    est.lo[k] - spacing <= traj.x[k] && traj.x[k] <= est.hi[k] + spacing,
                    "{system} sample {k}: {} outside [{}, {}]",
                    traj.x[k],
                    est.lo[k],
                    est.hi[k]
                );
            }
        }
    }

    /// The posterior is exact, so its band is calibrated: mean NEES near 1, and it uses `y`:
    /// its error is well under the prior's (the clean state alone, error `w_x / sqrt(12)`).
    #[test]
    fn the_posterior_is_calibrated_and_sharper_than_the_prior() {
        let (mut nees, mut sq_post, mut sq_prior, mut n) = (0.0, 0.0, 0.0, 0usize);
        for (i, system) in exact().enumerate() {
            let c = config(system, 5.0, 11 + i as u64);
            let traj = simulate_random(&c, 600).unwrap();
            let est = oracle_estimate(&c, &traj).unwrap();
            let w = c.noise_width_x();
            for k in 0..traj.x.len() {
                let e = traj.x[k] - est.mean[k];
                nees += (e / est.std[k]).powi(2);
                sq_post += e * e;
                sq_prior += w * w / 12.0;
                n += 1;
            }
        }
        let nees = nees / n as f64;
        assert!((0.85..1.15).contains(&nees), "mean NEES {nees}");
        assert!(
            sq_post < 0.7 * sq_prior,
            "posterior {sq_post} prior {sq_prior}"
        );
    }

    #[test]
    fn mismatched_signals_are_rejected() {
        let c = config(SystemKind::BoucWen, 1.0, 1);
        let mut traj = simulate_random(&c, 50).unwrap();
        traj.y.pop();
        assert!(matches!(
            oracle_estimate(&c, &traj),
            Err(SimError::LengthMismatch {
                u: 50,
                x: 50,
                y: 49
            })
        ));
    }

    #[test]
    fn a_propagating_disturbance_is_refused() {
        let c = config(SystemKind::SoftActuatorLoad, 1.0, 2);
        let traj = simulate_random(&c, 50).unwrap();
        for est in [
            oracle_estimate(&c, &traj),
            oracle_smooth_estimate(&c, &traj, 10),
        ] {
            let err = est.unwrap_err();
            assert!(
                matches!(
                    err,
                    SimError::NoExactOracle {
                        system: "soft-actuator-load"
                    }
                ),
                "{err}"
            );
            assert!(err.to_string().contains("propagates"), "{err}");
        }
    }

    fn mse(est: &OracleEstimate, x: &[f64]) -> f64 {
        est.mean
            .iter()
            .zip(x)
            .map(|(m, t)| (m - t) * (m - t))
            .sum::<f64>()
            / x.len() as f64
    }

    /// Lookahead 0 is the causal oracle, bit for bit; noise-free data give the state exactly.
    #[test]
    fn without_lookahead_the_two_sided_oracle_is_the_causal_one() {
        for system in exact() {
            let c = config(system, 4.0, 5);
            let traj = simulate_random(&c, 300).unwrap();
            assert_eq!(
                oracle_smooth_estimate(&c, &traj, 0).unwrap(),
                oracle_estimate(&c, &traj).unwrap(),
                "{system}"
            );
            let clean = config(system, 0.0, 5);
            let traj = simulate_random(&clean, 300).unwrap();
            let est = oracle_smooth_estimate(&clean, &traj, 50).unwrap();
            assert_eq!(est.mean, traj.x, "{system}");
            assert!(est.std.iter().all(|&s| s == 0.0), "{system}");
        }
    }

    /// On every system at gains 1 and 10, the two-sided posterior contains the truth, is
    /// calibrated and its mean squared error is never above the causal one's (it conditions
    /// on more); its support is inside the causal one's at every sample. This fails if the
    /// future is checked against the wrong sensor run (the truth would be excluded somewhere)
    /// or ignored on a system whose sensor remembers (the gain would be nil).
    #[test]
    fn the_future_narrows_the_posterior_and_keeps_the_truth() {
        let mut gained = 0;
        for system in exact() {
            for gain in [1.0, 10.0] {
                let c = config(system, gain, 31);
                let traj = simulate_random(&c, 500).unwrap();
                let one = oracle_estimate(&c, &traj).unwrap();
                let two = oracle_smooth_estimate(&c, &traj, 40).unwrap();
                let spacing = c.noise_width_x() / ORACLE_GRID as f64;
                assert_eq!(two.unresolved, 0, "{system} gain {gain}");
                let mut nees = 0.0;
                for k in 0..traj.x.len() {
                    assert!(
                        two.lo[k] - spacing <= traj.x[k] && traj.x[k] <= two.hi[k] + spacing,
                        "{system} gain {gain} sample {k}"
                    );
                    assert!(
                        one.lo[k] <= two.lo[k] && two.hi[k] <= one.hi[k],
                        "{system} gain {gain} sample {k}"
                    );
                    nees += ((traj.x[k] - two.mean[k]) / two.std[k]).powi(2);
                }
                let nees = nees / traj.x.len() as f64;
                assert!(
                    (0.75..1.3).contains(&nees),
                    "{system} gain {gain}: NEES {nees}"
                );
                let (m1, m2) = (mse(&one, &traj.x), mse(&two, &traj.x));
                assert!(m2 <= m1 * 1.02, "{system} gain {gain}: {m2} > {m1}");
                if m2 < 0.95 * m1 {
                    gained += 1;
                }
                eprintln!(
                    "{system} gain {gain}: two-sided / one-sided RMSE {:.3}",
                    (m2 / m1).sqrt()
                );
            }
        }
        assert!(
            gained >= 2,
            "the future narrowed the posterior on {gained} cases"
        );
    }

    #[test]
    fn a_longer_lookahead_is_never_worse_on_average() {
        let c = config(SystemKind::Duhem, 3.0, 8);
        let traj = simulate_random(&c, 400).unwrap();
        let mut last = f64::INFINITY;
        for lookahead in [0, 1, 5, 20, usize::MAX] {
            let m = mse(
                &oracle_smooth_estimate(&c, &traj, lookahead).unwrap(),
                &traj.x,
            );
            assert!(m <= last * 1.02, "lookahead {lookahead}: {m} after {last}");
            last = m;
        }
    }
}
