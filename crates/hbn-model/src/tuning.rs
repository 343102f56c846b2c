//! Filter-aware training: after the GPs are fitted, the filter's free noise scales are learned
//! on held-out runs by maximising the likelihood of the recorded state under the filter's
//! Gaussian estimate (the idea of Abbeel et al., "Discriminative Training of Kalman Filters",
//! RSS 2005), and the mode with the best held-out score becomes the model's default.
//!
//! Three scales per mode ([`NoiseScales`]): `q` multiplies the process noise (the GP variances
//! and their model-error floors), `r` the measurement noise, and `std` the reported standard
//! deviation. For given `q` and `r` the best `std` has a closed form (the square root of the
//! mean normalised squared error), so the search runs over `(log q, log r)` only, on the
//! *profile* negative log predictive density
//!
//! ```text
//! J(q, r) = 1/2 ln(2 pi) + 1/2 mean(ln sigma_k^2) + 1/2 ln(mean(e_k^2 / sigma_k^2)) + 1/2
//! ```
//!
//! (`e_k` the error, `sigma_k` the filter's standard deviation at scale 1): a coarse grid over
//! five decades, then a pattern search. `docs/tuning.md` gives the reasoning and measurements.

use crate::dataset::Sequence;
use crate::metrics::{Calibration, calibration, nrmse};
use crate::{HbnModel, ModelError};
use hbn_core::{EkfConfig, Mode};
use serde::{Deserialize, Serialize};

/// Noise scales of one filter mode (`1, 1, 1` = the GP variances as they are).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct NoiseScales {
    /// Scale of the process noise `Q`.
    pub q: f64,
    /// Scale of the measurement noise `R`.
    pub r: f64,
    /// Scale of the reported standard deviation of `x`.
    pub std: f64,
}

impl Default for NoiseScales {
    fn default() -> Self {
        Self {
            q: 1.0,
            r: 1.0,
            std: 1.0,
        }
    }
}

impl NoiseScales {
    /// Writes the scales into filter settings.
    pub fn apply(&self, config: &mut EkfConfig) {
        config.q_scale = self.q;
        config.r_scale = self.r;
        config.std_scale = self.std;
    }
}

/// The filter settings a model carries beside its GPs: noise scales per mode and the mode
/// that estimation uses when none is asked for.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FilterTuning {
    /// Scales of the plain EKF.
    pub ekf: NoiseScales,
    /// Scales of the EKF with local regression.
    pub ekf_blr: NoiseScales,
    /// Scales of the unscented filter (model files from before it existed: scale 1).
    #[serde(default)]
    pub ukf: NoiseScales,
    /// The mode with the best held-out score (the EKF for untuned models).
    pub default_mode: Mode,
}

impl Default for FilterTuning {
    fn default() -> Self {
        Self {
            ekf: NoiseScales::default(),
            ekf_blr: NoiseScales::default(),
            ukf: NoiseScales::default(),
            default_mode: Mode::Ekf,
        }
    }
}

impl FilterTuning {
    /// The scales of one mode.
    pub fn scales(&self, mode: Mode) -> NoiseScales {
        match mode {
            Mode::Ekf => self.ekf,
            Mode::EkfBlr => self.ekf_blr,
            Mode::Ukf => self.ukf,
        }
    }

    fn set(&mut self, mode: Mode, scales: NoiseScales) {
        match mode {
            Mode::Ekf => self.ekf = scales,
            Mode::EkfBlr => self.ekf_blr = scales,
            Mode::Ukf => self.ukf = scales,
        }
    }
}

/// Which data were held out for tuning: the end of every run (a block of consecutive
/// samples), so that the held-out inputs are unseen even when every run repeats the same input
/// schedule (holding out whole runs would then validate on inputs the GPs were trained on).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Holdout {
    /// First held-out sample of each run.
    pub from: Vec<usize>,
    /// Samples held out in all.
    pub held_out: usize,
    /// Samples in all.
    pub samples: usize,
}

impl std::fmt::Display for Holdout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the last {} of {} samples held out, the end of each of {} run{}",
            self.held_out,
            self.samples,
            self.from.len(),
            if self.from.len() == 1 { "" } else { "s" }
        )
    }
}

/// Scores of one filter on the held-out data.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeldOutScores {
    /// RMSE over the range of the held-out state.
    pub nrmse: f64,
    /// Coverage, NEES and NLPD of the filter's standard deviation.
    pub calibration: Calibration,
}

/// One mode of the validation table.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ValidationRow {
    /// The mode.
    pub mode: Mode,
    /// The scales learned.
    pub scales: NoiseScales,
    /// Held-out scores at scale 1 (before tuning).
    pub untuned: HeldOutScores,
    /// Held-out scores with the learned scales.
    pub tuned: HeldOutScores,
    /// Filter runs over the held-out data the search took.
    pub evaluations: usize,
}

/// What filter-aware training did: the split, and per mode the scales and held-out scores.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ValidationReport {
    /// Which data were held out.
    pub holdout: Holdout,
    /// Held-out samples scored (after the cap, [`MAX_VALIDATION_SAMPLES`]).
    pub samples: usize,
    /// One row per mode.
    pub rows: Vec<ValidationRow>,
    /// The mode chosen as the default (lowest tuned NLPD).
    pub default_mode: Mode,
}

/// Held-out samples the search runs the filter over at most (a prefix of each held-out run,
/// in proportion): bounds the cost of tuning on long logs.
pub const MAX_VALIDATION_SAMPLES: usize = 1500;
/// Fewest samples a held-out block (one run) or the training part may have for tuning.
pub const MIN_TUNING_SAMPLES: usize = 50;

/// Training and held-out runs.
pub(crate) struct Split<'a> {
    pub train: Vec<Sequence<'a>>,
    pub validation: Vec<Sequence<'a>>,
    pub holdout: Holdout,
}

/// Splits the runs for tuning: the last `fraction` of every run is held out (runs whose
/// parts would be shorter than 3 samples contribute only to one side). `None` when `fraction`
/// is 0 or either side would have fewer than [`MIN_TUNING_SAMPLES`] samples.
pub(crate) fn split<'a>(runs: &[Sequence<'a>], fraction: f64) -> Option<Split<'a>> {
    if !(fraction > 0.0 && fraction < 1.0) {
        return None;
    }
    let (mut train, mut validation, mut from_all) = (Vec::new(), Vec::new(), Vec::new());
    for r in runs {
        let len = r.u.len().min(r.x.len()).min(r.y.len());
        let from = ((1.0 - fraction) * len as f64).floor() as usize;
        let cut = |s: &'a [f64]| s[..len].split_at(from);
        let ((u0, u1), (x0, x1), (y0, y1)) = (cut(r.u), cut(r.x), cut(r.y));
        if from >= 3 {
            train.push(Sequence::new(u0, x0, y0));
        }
        if len - from >= 3 {
            validation.push(Sequence::new(u1, x1, y1));
        }
        from_all.push(from);
    }
    let samples: usize = runs.iter().map(|s| s.u.len()).sum();
    let held_out: usize = validation.iter().map(|s| s.u.len()).sum();
    let trained: usize = train.iter().map(|s| s.u.len()).sum();
    if held_out < MIN_TUNING_SAMPLES || trained < MIN_TUNING_SAMPLES {
        return None;
    }
    Some(Split {
        train,
        validation,
        holdout: Holdout {
            from: from_all,
            held_out,
            samples,
        },
    })
}

/// The held-out runs, each cut to a prefix so that they hold at most `cap` samples together.
fn capped<'a>(runs: &[Sequence<'a>], cap: usize) -> Vec<Sequence<'a>> {
    let total: usize = runs.iter().map(|s| s.u.len()).sum();
    if total <= cap {
        return runs.to_vec();
    }
    runs.iter()
        .map(|s| {
            let keep = (s.u.len() * cap).div_ceil(total).min(s.u.len());
            Sequence::new(&s.u[..keep], &s.x[..keep], &s.y[..keep])
        })
        .collect()
}

/// Sums over the held-out samples of one filter run.
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    n: usize,
    log_var: f64,
    nees: f64,
}

impl Sums {
    /// The profile NLPD (the best `std` scale plugged in) and that scale.
    fn profile(&self) -> Option<(f64, f64)> {
        if self.n == 0 {
            return None;
        }
        let n = self.n as f64;
        let mean_nees = (self.nees / n).max(1e-300);
        let j = 0.5 * (2.0 * std::f64::consts::PI).ln()
            + 0.5 * self.log_var / n
            + 0.5 * mean_nees.ln()
            + 0.5;
        j.is_finite().then_some((j, mean_nees.sqrt()))
    }
}

/// Runs the filter with `config` over every held-out run; `None` if it fails.
fn run_all(
    model: &HbnModel,
    runs: &[Sequence<'_>],
    config: &EkfConfig,
) -> Option<Vec<crate::Estimate>> {
    runs.iter()
        .map(|s| model.estimate_with(s.u, s.y, config).ok())
        .collect()
}

fn sums(model: &HbnModel, runs: &[Sequence<'_>], config: &EkfConfig) -> Sums {
    let mut out = Sums::default();
    let Some(ests) = run_all(model, runs, config) else {
        return out;
    };
    for (s, est) in runs.iter().zip(&ests) {
        for ((&xh, &sd), &xr) in est.x.iter().zip(&est.x_std).zip(s.x) {
            if !(xh.is_finite() && sd.is_finite() && sd > 0.0 && xr.is_finite()) {
                continue;
            }
            let var = sd * sd;
            out.n += 1;
            out.log_var += var.ln();
            out.nees += (xr - xh) * (xr - xh) / var;
        }
    }
    out
}

fn scores(
    model: &HbnModel,
    runs: &[Sequence<'_>],
    config: &EkfConfig,
) -> Result<HeldOutScores, ModelError> {
    let (mut x, mut sd, mut xr) = (Vec::new(), Vec::new(), Vec::new());
    for s in runs {
        let est = model.estimate_with(s.u, s.y, config)?;
        x.extend_from_slice(&est.x);
        sd.extend_from_slice(&est.x_std);
        xr.extend_from_slice(s.x);
    }
    Ok(HeldOutScores {
        nrmse: nrmse(&x, &xr),
        calibration: calibration(&x, &sd, &xr),
    })
}

/// Evaluates `points` (`(log10 q, log10 r)`) on up to `threads` threads; results in order.
fn evaluate_many(
    model: &HbnModel,
    runs: &[Sequence<'_>],
    base: &EkfConfig,
    points: &[(f64, f64)],
) -> Vec<Option<(f64, f64)>> {
    let eval = |&(lq, lr): &(f64, f64)| {
        let mut c = *base;
        c.q_scale = 10f64.powf(lq);
        c.r_scale = 10f64.powf(lr);
        c.std_scale = 1.0;
        sums(model, runs, &c)
            .profile()
            .map(|(j, s)| (j + SCALE_PENALTY * (lq * lq + lr * lr), s))
    };
    let threads = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(points.len())
        .max(1);
    if threads == 1 {
        return points.iter().map(eval).collect();
    }
    let chunk = points.len().div_ceil(threads);
    std::thread::scope(|scope| {
        let handles: Vec<_> = points
            .chunks(chunk)
            .map(|part| {
                (
                    part.len(),
                    scope.spawn(move || part.iter().map(eval).collect::<Vec<_>>()),
                )
            })
            .collect();
        // A thread that panicked counts as failed evaluations (keeps the order).
        handles
            .into_iter()
            .flat_map(|(len, h)| h.join().unwrap_or_else(|_| vec![None; len]))
            .collect()
    })
}

/// Penalty on the scales' distance from 1, in nats of held-out NLPD per squared decade of
/// `q` and of `r`. The held-out block is short and correlated in time, so its NLPD alone can
/// prefer extreme scales that do not carry over (measured: `r = 10^4`, a filter that ignores
/// the sensor, doubled the nRMSE on fresh data); this shrinks the scales towards 1.
const SCALE_PENALTY: f64 = 0.1;
/// Filter runs per mode at most (the grid's 17, then the pattern search).
const MAX_EVALUATIONS: usize = 45;
/// Bounds of the search in decades.
const LOG_MIN: f64 = -3.0;
const LOG_MAX: f64 = 4.0;

/// Learns the scales of one mode: a grid (or, with `start`, only the untuned point and
/// `start`), then pattern search. Returns the scales, the profile objective at them and the
/// number of filter runs.
///
/// The first mode searches the whole grid; the others start from its optimum (`start`, in
/// decades), because the modes share both GPs and their optima lie close (measured: within
/// 0.4 decades of each other on the demo's data). This halves the cost of tuning, most of
/// which was the unscented mode's 17-point grid at 3.6 times the EKF's step cost.
fn search(
    model: &HbnModel,
    runs: &[Sequence<'_>],
    base: &EkfConfig,
    start: Option<(f64, f64)>,
) -> Option<(NoiseScales, usize)> {
    let mut points: Vec<(f64, f64)> = vec![(0.0, 0.0)];
    match start {
        Some(p) if p != (0.0, 0.0) => points.push(p),
        Some(_) => {}
        None => {
            let grid = [-2.0, -1.0 / 3.0, 4.0 / 3.0, 3.0];
            for &lq in &grid {
                for &lr in &grid {
                    points.push((lq, lr));
                }
            }
        }
    }
    let mut evaluations = points.len();
    let mut best: Option<((f64, f64), f64, f64)> = None;
    let consider =
        |best: &mut Option<((f64, f64), f64, f64)>, p: (f64, f64), r: Option<(f64, f64)>| {
            if let Some((j, s)) = r
                && best.is_none_or(|b| j < b.1)
            {
                *best = Some((p, j, s));
            }
        };
    for (p, r) in points.iter().zip(evaluate_many(model, runs, base, &points)) {
        consider(&mut best, *p, r);
    }
    let mut step = 0.8;
    while step > 0.09 && evaluations < MAX_EVALUATIONS {
        let ((lq, lr), j0, _) = best?;
        let around: Vec<(f64, f64)> = [(step, 0.0), (-step, 0.0), (0.0, step), (0.0, -step)]
            .iter()
            .map(|(dq, dr)| {
                (
                    (lq + dq).clamp(LOG_MIN, LOG_MAX),
                    (lr + dr).clamp(LOG_MIN, LOG_MAX),
                )
            })
            .filter(|&p| p != (lq, lr))
            .collect();
        evaluations += around.len();
        for (p, r) in around.iter().zip(evaluate_many(model, runs, base, &around)) {
            consider(&mut best, *p, r);
        }
        if best.is_some_and(|b| b.1 >= j0) {
            step /= 2.0;
        }
    }
    let ((lq, lr), _, s) = best?;
    Some((
        NoiseScales {
            q: 10f64.powf(lq),
            r: 10f64.powf(lr),
            std: s,
        },
        evaluations,
    ))
}

/// Tunes every mode of `model` (trained on `split.train`) on `split.validation`.
pub(crate) fn tune(
    model: &HbnModel,
    split: &Split<'_>,
) -> Result<Option<(FilterTuning, ValidationReport)>, ModelError> {
    let runs = capped(&split.validation, MAX_VALIDATION_SAMPLES);
    let samples: usize = runs.iter().map(|s| s.u.len()).sum();
    let mut tuning = FilterTuning::default();
    let mut rows = Vec::new();
    let mut first_optimum: Option<(f64, f64)> = None;
    for mode in Mode::ALL {
        let base = model.untuned_config(mode);
        let Some((scales, evaluations)) = search(model, &runs, &base, first_optimum) else {
            return Ok(None);
        };
        first_optimum.get_or_insert((scales.q.log10(), scales.r.log10()));
        let mut tuned_cfg = base;
        scales.apply(&mut tuned_cfg);
        let untuned = scores(model, &runs, &base)?;
        let tuned = scores(model, &runs, &tuned_cfg)?;
        let finite = |s: &HeldOutScores| s.nrmse.is_finite() && s.calibration.nlpd.is_finite();
        if !(finite(&tuned) && finite(&untuned)) {
            return Ok(None);
        }
        tuning.set(mode, scales);
        rows.push(ValidationRow {
            mode,
            scales,
            untuned,
            tuned,
            evaluations,
        });
    }
    let default_mode = rows
        .iter()
        .min_by(|a, b| {
            a.tuned
                .calibration
                .nlpd
                .total_cmp(&b.tuned.calibration.nlpd)
        })
        .map_or(Mode::Ekf, |r| r.mode);
    tuning.default_mode = default_mode;
    Ok(Some((
        tuning,
        ValidationReport {
            holdout: split.holdout.clone(),
            samples,
            rows,
            default_mode,
        },
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seq(n: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let u: Vec<f64> = (0..n).map(|i| i as f64).collect();
        (u.clone(), u.clone(), u)
    }

    #[test]
    fn the_end_of_every_run_is_held_out() {
        let (u, x, y) = seq(400);
        let (u2, x2, y2) = seq(100);
        let runs = [Sequence::new(&u, &x, &y), Sequence::new(&u2, &x2, &y2)];
        let s = split(&runs, 0.25).unwrap();
        assert_eq!(
            s.holdout,
            Holdout {
                from: vec![300, 75],
                held_out: 125,
                samples: 500
            }
        );
        assert_eq!((s.train[0].u.len(), s.train[1].u.len()), (300, 75));
        assert_eq!(s.validation[0].x.first(), Some(&300.0));
        assert_eq!(s.validation[1].y.first(), Some(&75.0));
        // One run works the same way; too little data or no fraction: no split.
        assert_eq!(split(&runs[..1], 0.25).unwrap().holdout.held_out, 100);
        let (u, x, y) = seq(150);
        assert!(split(&[Sequence::new(&u, &x, &y)], 0.25).is_none());
        assert!(split(&runs, 0.0).is_none());
    }

    #[test]
    fn cap_keeps_a_proportional_prefix() {
        let (u, x, y) = seq(3000);
        let (u2, x2, y2) = seq(1000);
        let runs = [Sequence::new(&u, &x, &y), Sequence::new(&u2, &x2, &y2)];
        let c = capped(&runs, 2000);
        assert_eq!((c[0].u.len(), c[1].u.len()), (1500, 500));
    }

    #[test]
    fn profile_scale_is_the_root_mean_nees() {
        let s = Sums {
            n: 4,
            log_var: 0.0,
            nees: 16.0,
        };
        let (j, scale) = s.profile().unwrap();
        assert!((scale - 2.0).abs() < 1e-12);
        // Equal to the NLPD at that scale: 1/2 ln(2 pi 4) + 1/2 (mean NEES / 4).
        let direct = 0.5 * (2.0 * std::f64::consts::PI * 4.0).ln() + 0.5;
        assert!((j - direct).abs() < 1e-12);
        assert!(Sums::default().profile().is_none());
    }
}
