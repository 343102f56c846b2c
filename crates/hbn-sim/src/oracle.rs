//! The floor under causal state estimation on a simulated trajectory: the exact posterior of
//! `x_k` under the simulator's own model, given more than any estimator has.
//!
//! With the noise model of the crate docs, the clean state `x_clean[k]` is a deterministic
//! function of `u[0..=k]`, and the recorded state is `x[k] = x_clean[k] + w_x eta_x[k]` with
//! `eta_x[k]` uniform on `[-0.5, 0.5]`, independent of everything before it. The sensor reads it:
//! `y[k] = S_k(x[k]) + w_y eta_y[k]`, where the sensor's state `S_k` depends on the states
//! `x[0..k]`. [`oracle_estimate`] knows the simulator, `u[0..=k]`, `y[0..=k]` and the **true**
//! past states `x[0..k]`, so the only unknown at sample `k` is `eta_x[k]`, and its posterior is
//! uniform on the set of `eta` in `[-0.5, 0.5]` with `|y[k] - S_k(x_clean[k] + w_x eta)| <=
//! w_y / 2`. The estimate is that posterior's mean, found on a grid of [`ORACLE_GRID`] + 1 points.
//!
//! Why it is a floor: a causal estimator (a filter, an LSTM) sees `u[0..=k]` and `y[0..=k]` only.
//! The posterior mean minimises the mean squared error given what it conditions on, and
//! conditioning on more (the true past states, the true model) can only lower the least
//! achievable error. So no causal estimator, learned or not, has a lower expected squared error
//! than this one on the same trajectory; what is left between an estimator and this floor is
//! what better learning or filtering could still win.

use crate::{SimConfig, SimError, Trajectory, check_input, systems::System};

/// Intervals of the grid over `eta_x[k]` on which [`oracle_estimate`] finds the posterior.
/// The posterior mean is then within a few thousandths of the disturbance's width `w_x` of
/// the exact one (the grid's spacing is `w_x / 400`).
pub const ORACLE_GRID: usize = 400;

/// The posterior of every `x[k]` found by [`oracle_estimate`].
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
    /// Samples where no grid point explained `y[k]` within the noise's bound (an allowed set
    /// narrower than the grid's spacing); there the estimate is the grid point with the
    /// smallest residual.
    pub unresolved: usize,
}

/// The exact posterior of each recorded state `x[k]` of `traj`, a trajectory of `config`'s
/// system, given `u[0..=k]`, `y[0..=k]`, the simulator's model and the true past states
/// `x[0..k]`.
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
/// exactly `traj.x`.
///
/// # Errors
/// An invalid `config`, signals of different lengths, or an input outside
/// [`crate::INPUT_RANGE`].
pub fn oracle_estimate(config: &SimConfig, traj: &Trajectory) -> Result<OracleEstimate, SimError> {
    config.validate()?;
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
    for k in 0..n {
        let x_clean = system.actuate(traj.u[k]);
        if width_x > 0.0 {
            let (mut count, mut sum, mut sum_sq) = (0usize, 0.0, 0.0);
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            let (mut best_residual, mut best_x) = (f64::INFINITY, x_clean);
            for i in 0..=ORACLE_GRID {
                let eta = i as f64 / ORACLE_GRID as f64 - 0.5;
                let x_trial = x_clean + width_x * eta;
                let residual = (traj.y[k] - system.sense_trial(x_trial)).abs();
                if residual < best_residual {
                    best_residual = residual;
                    best_x = x_trial;
                }
                if residual <= bound {
                    count += 1;
                    sum += x_trial;
                    sum_sq += x_trial * x_trial;
                    lo = lo.min(x_trial);
                    hi = hi.max(x_trial);
                }
            }
            if count == 0 {
                out.unresolved += 1;
                out.mean.push(best_x);
                out.std.push(grid_var.sqrt());
                out.lo.push(best_x);
                out.hi.push(best_x);
            } else {
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
    #[test]
    fn the_truth_is_always_allowed() {
        for system in SystemKind::ALL {
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
        for (i, system) in SystemKind::ALL.into_iter().enumerate() {
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
}
