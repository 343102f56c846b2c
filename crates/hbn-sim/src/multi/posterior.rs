//! The floor under causal state estimation on a multi-signal system: the posterior of the state
//! given the inputs and outputs so far **and the simulator's own model**, found by a particle
//! filter.
//!
//! The chambers are deterministic functions of the inputs; each tip component is a first-order
//! lag of the mixed bends whose state takes a uniform disturbance at every sample (so the
//! disturbance propagates), and each sensor reads a mix of the tip through its own hysteretic
//! chain, plus uniform noise. Every particle carries the tips' lag states and the sensors'
//! operator states, is moved by the true dynamics with a fresh draw of the disturbance, and is
//! weighted by how well it explains every output: within the noise's half-width the likelihood
//! is flat, as the noise's is; outside it falls off over a short soft edge
//! ([`SOFT_EDGE`] of the noise's width) instead of dropping to zero, so that a cloud that
//! missed the allowed set still has weights.
//!
//! Why it is a floor: the posterior mean minimises the expected squared error given `u[0..=k]`
//! and `y[0..=k]`, which is all a causal estimator sees; it also knows the model, which a
//! learned estimator has to learn. With enough particles its error approaches the least
//! achievable; with too few it is higher, never lower in expectation, so a floor computed with
//! few particles is conservative (run it with more to see it settle).

use hbn_core::rng::Rng;

use super::{MultiConfig, MultiSystem, Tip, check_inputs, dot};
use crate::{SimError, systems::Sensor};

/// Salt mixed into the seed of the particle filter's generator.
const POSTERIOR_SALT: u64 = 0x0B5E_55ED_F100_2A11;

/// Width of the likelihood's soft edge outside the noise's half-width, as a share of the
/// sensor noise's width `w_y`.
pub const SOFT_EDGE: f64 = 0.05;

/// The posterior of a multi-signal trajectory's state found by [`multi_posterior_estimate`].
#[derive(Clone, Debug, PartialEq)]
pub struct MultiPosterior {
    /// Posterior mean of each state component at each sample (`mean[i][k]`), the
    /// least-squares causal estimate.
    pub mean: Vec<Vec<f64>>,
    /// Posterior standard deviation of each state component at each sample.
    pub std: Vec<Vec<f64>>,
    /// The smallest effective number of particles over the run (before resampling); a value
    /// near 1 means the cloud collapsed somewhere and more particles are needed there.
    pub min_effective_particles: f64,
    /// Samples after which the cloud was resampled (effective number below half the
    /// particles).
    pub resamples: usize,
}

/// One hypothesis of the hidden state: the tips' lags and the sensors' chains, and the state
/// they give at the current sample.
#[derive(Clone, Debug)]
struct Particle {
    tips: Vec<Tip>,
    gauges: Vec<Sensor>,
    x: Vec<f64>,
}

/// The posterior of the state of `config`'s multi-signal system at every sample, given its
/// inputs `u` (one signal per input) and sensor outputs `y` (one signal per sensor, each as
/// long as the inputs; a non-finite output is treated as missing) and the system's own model,
/// by a particle filter with `particles` particles whose random draws derive from `seed`.
///
/// The trajectory must start from the system's relaxed state, as [`super::simulate_multi`]'s
/// do. With noise gain 0 the state is a deterministic function of the inputs and the posterior
/// is exact (one particle runs, whatever `particles` says).
///
/// # Errors
/// An invalid `config`; inputs of the wrong count, of different lengths or out of range; outputs
/// of the wrong count or length ([`SimError::OutputShape`]); no particles.
pub fn multi_posterior_estimate(
    config: &MultiConfig,
    u: &[Vec<f64>],
    y: &[Vec<f64>],
    particles: usize,
    seed: u64,
) -> Result<MultiPosterior, SimError> {
    config.validate()?;
    let kind = config.system;
    let n = check_inputs(kind, u)?;
    let bad = if y.len() != kind.sensors() {
        Some((y.len(), 0))
    } else {
        y.iter()
            .enumerate()
            .find(|(_, s)| s.len() != n)
            .map(|(j, s)| (j, s.len()))
    };
    if let Some((signal, len)) = bad {
        return Err(SimError::OutputShape {
            system: kind.name(),
            expected: kind.sensors(),
            samples: n,
            got: y.len(),
            signal,
            len,
        });
    }
    if particles == 0 {
        return Err(SimError::InvalidParameter {
            name: "particles",
            value: 0.0,
            reason: "the particle filter needs at least one particle",
        });
    }
    let mut system = MultiSystem::new(kind, 1.0 / config.rate_hz)?;
    let (width_x, width_y) = (config.noise_width_x(), config.noise_width_y());
    let (half_y, edge) = (0.5 * width_y, (SOFT_EDGE * width_y).max(f64::MIN_POSITIVE));
    let (dx, du) = (kind.states(), kind.inputs());
    // Without a disturbance every particle follows the same path: one is the exact posterior.
    let particles = if width_x == 0.0 { 1 } else { particles };

    let start = Particle {
        tips: system.tips.clone(),
        gauges: system.gauges.clone(),
        x: vec![0.0; dx],
    };
    let mut cloud = vec![start; particles];
    let mut weight = vec![1.0 / particles as f64; particles];
    let mut log_weight = vec![0.0; particles];
    let mut rng = Rng::new(seed ^ POSTERIOR_SALT);
    let mut out = MultiPosterior {
        mean: vec![Vec::with_capacity(n); dx],
        std: vec![Vec::with_capacity(n); dx],
        min_effective_particles: particles as f64,
        resamples: 0,
    };
    let mut uk = vec![0.0; du];
    let mut targets = vec![0.0; dx];
    for k in 0..n {
        for (v, ui) in uk.iter_mut().zip(u) {
            *v = ui[k];
        }
        system.bend(&uk);
        for (t, row) in targets.iter_mut().zip(&system.state_mix) {
            *t = dot(row, &system.bends);
        }
        for ((p, lw), w) in cloud.iter_mut().zip(&mut log_weight).zip(&weight) {
            for ((xi, tip), &t) in p.x.iter_mut().zip(&mut p.tips).zip(&targets) {
                let d = width_x * (rng.uniform() - 0.5);
                *xi = tip.step(t) + d;
                tip.disturb(d);
            }
            let mut log_likelihood = 0.0;
            for ((g, row), yj) in p.gauges.iter_mut().zip(&system.sensor_mix).zip(y) {
                let predicted = g.step(dot(row, &p.x));
                let measured = yj[k];
                if measured.is_finite() {
                    let excess = ((measured - predicted).abs() - half_y).max(0.0) / edge;
                    log_likelihood -= 0.5 * excess * excess;
                }
            }
            *lw = w.ln() + log_likelihood;
        }
        normalise(&log_weight, &mut weight);
        for i in 0..dx {
            let mean: f64 = cloud.iter().zip(&weight).map(|(p, w)| w * p.x[i]).sum();
            let var: f64 = cloud
                .iter()
                .zip(&weight)
                .map(|(p, w)| w * (p.x[i] - mean) * (p.x[i] - mean))
                .sum();
            out.mean[i].push(mean);
            out.std[i].push(var.max(0.0).sqrt());
        }
        let effective = 1.0 / weight.iter().map(|w| w * w).sum::<f64>();
        out.min_effective_particles = out.min_effective_particles.min(effective);
        if effective < 0.5 * particles as f64 {
            cloud = resample(&cloud, &weight, rng.uniform());
            weight.fill(1.0 / particles as f64);
            out.resamples += 1;
        }
    }
    Ok(out)
}

/// Normalised weights from log weights (uniform when none is finite).
fn normalise(log_weight: &[f64], weight: &mut [f64]) {
    let top = log_weight
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(f64::NEG_INFINITY, f64::max);
    let mut sum = 0.0;
    for (w, &lw) in weight.iter_mut().zip(log_weight) {
        *w = if lw.is_finite() {
            (lw - top).exp()
        } else {
            0.0
        };
        sum += *w;
    }
    if sum > 0.0 && sum.is_finite() {
        weight.iter_mut().for_each(|w| *w /= sum);
    } else {
        let uniform = 1.0 / weight.len() as f64;
        weight.fill(uniform);
    }
}

/// Systematic resampling of `cloud` by `weight` (normalised), with the offset `u0` in `[0, 1)`.
fn resample(cloud: &[Particle], weight: &[f64], u0: f64) -> Vec<Particle> {
    let n = cloud.len();
    let mut out = Vec::with_capacity(n);
    let mut cumulative = weight.first().copied().unwrap_or(0.0);
    let mut i = 0;
    for m in 0..n {
        let point = (m as f64 + u0) / n as f64;
        while point > cumulative && i + 1 < n {
            i += 1;
            cumulative += weight[i];
        }
        out.push(cloud[i].clone());
    }
    out
}
