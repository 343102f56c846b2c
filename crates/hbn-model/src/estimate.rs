//! Estimation over whole sequences: the [`Filter`](crate::Filter)'s per-sample step in a loop,
//! the open-loop GP simulation baseline, and the observability diagnostic.

use crate::ModelError;
use crate::filter::{FilterOutput, Tracker};
use crate::model::HysteresisModel;
use hbn_core::{Ekf, EkfConfig, Flags, Mode, Want};

/// Observability window `h` of thesis Sec. 4.2.
pub const OBSERVABILITY_WINDOW: usize = 3;

/// Per-sample results of an estimation run.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Estimate {
    /// Estimate of `x_k`.
    pub x: Vec<f64>,
    /// Its standard deviation.
    pub x_std: Vec<f64>,
    /// Predicted measurement before the update.
    pub y_pred: Vec<f64>,
    /// Innovation.
    pub innovation: Vec<f64>,
    /// Normalised innovation squared.
    pub nis: Vec<f64>,
    /// Process noise variance used for `x`.
    pub q_x: Vec<f64>,
    /// Measurement noise variance used.
    pub r: Vec<f64>,
    /// Guard flags (bits of [`Flags`]).
    pub flags: Vec<u32>,
    /// Smallest eigenvalue of the `h = 3` observability Gramian (NaN for the first samples).
    pub obs_min: Vec<f64>,
    /// Largest eigenvalue of the Gramian.
    pub obs_max: Vec<f64>,
    /// Information on `x` alone in the Gramian ([`hbn_core::state_information`]).
    pub obs_x: Vec<f64>,
}

/// Summary of the observability diagnostic.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ObservabilitySummary {
    /// Smallest `lambda_min` along the trajectory.
    pub min: f64,
    /// Median `lambda_min`.
    pub median: f64,
    /// Largest `lambda_max`.
    pub max: f64,
    /// Fraction of samples where the information on `x` alone
    /// ([`hbn_core::state_information`]) fell below [`NEAR_UNOBSERVABLE`] of `lambda_max`: the
    /// measurements do not pin down the state there. (A small `lambda_min` alone can be a
    /// component that does not matter: `x_{k-1}` when the transition ignores `x_{k-2}`, as
    /// it may with play operators.)
    pub near_unobservable: f64,
}

/// Ratio of the information on `x` to `lambda_max` below which a sample counts as
/// near-unobservable.
pub const NEAR_UNOBSERVABLE: f64 = 1e-8;

impl Estimate {
    /// An empty estimate with room for `n` samples.
    pub fn with_capacity(n: usize) -> Self {
        Self {
            x: Vec::with_capacity(n),
            x_std: Vec::with_capacity(n),
            y_pred: Vec::with_capacity(n),
            innovation: Vec::with_capacity(n),
            nis: Vec::with_capacity(n),
            q_x: Vec::with_capacity(n),
            r: Vec::with_capacity(n),
            flags: Vec::with_capacity(n),
            obs_min: Vec::with_capacity(n),
            obs_max: Vec::with_capacity(n),
            obs_x: Vec::with_capacity(n),
        }
    }

    /// Appends one sample's output.
    pub fn push(&mut self, o: &FilterOutput) {
        self.x.push(o.x);
        self.x_std.push(o.x_std);
        self.y_pred.push(o.y_pred);
        self.innovation.push(o.innovation);
        self.nis.push(o.nis);
        self.q_x.push(o.q_x);
        self.r.push(o.r);
        self.flags.push(o.flags.0);
        self.obs_min.push(o.obs_min);
        self.obs_max.push(o.obs_max);
        self.obs_x.push(o.obs_x);
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Counts of each guard flag over the run, by name.
    pub fn flag_counts(&self) -> Vec<(&'static str, usize)> {
        count_flags(&self.flags)
    }

    /// Observability summary (`None` if the run was too short).
    pub fn observability(&self) -> Option<ObservabilitySummary> {
        let mut mins: Vec<f64> = self
            .obs_min
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .collect();
        if mins.is_empty() {
            return None;
        }
        mins.sort_by(f64::total_cmp);
        let max = self
            .obs_max
            .iter()
            .copied()
            .filter(|v| v.is_finite())
            .fold(0.0, f64::max);
        let near = self
            .obs_x
            .iter()
            .zip(&self.obs_max)
            .filter(|(a, b)| a.is_finite() && b.is_finite())
            .filter(|(a, b)| **a <= NEAR_UNOBSERVABLE * **b)
            .count();
        Some(ObservabilitySummary {
            min: mins[0],
            median: mins[mins.len() / 2],
            max,
            near_unobservable: near as f64 / mins.len() as f64,
        })
    }
}

impl HysteresisModel {
    /// Runs the filter over a sequence with the default settings of `mode`: the loop of
    /// [`Filter::step`](crate::Filter::step) over the samples, without taking ownership of the
    /// model (equal to [`Filter::run`](crate::Filter::run) bit for bit).
    pub fn estimate(&self, u: &[f64], y: &[f64], mode: Mode) -> Result<Estimate, ModelError> {
        self.estimate_with(u, y, &self.ekf_config(mode))
    }

    /// Runs the filter with explicit settings.
    pub fn estimate_with(
        &self,
        u: &[f64],
        y: &[f64],
        config: &EkfConfig,
    ) -> Result<Estimate, ModelError> {
        let ekf = Ekf::new(self.view()?, *config)?;
        crate::filter::run(&mut Tracker::new(&ekf), &ekf, u, y)
    }

    /// Open-loop GP simulation: `x_k = mean H_D(x_{k-1}, x_{k-2}, u_{k-1}, u_{k-2}, plays)`
    /// from the training mean, without measurements (the baseline the EKF must beat).
    pub fn simulate_open_loop(&self, u: &[f64]) -> Result<Vec<f64>, ModelError> {
        let view = self.gp_view(crate::GpRole::Transition)?;
        let plays = self.plays()?;
        let mut play_states = vec![[0.0; hbn_core::MAX_PLAYS]; u.len()];
        plays.run(u, &mut play_states);
        let mut scratch = vec![0.0; view.predict_scratch(Want::default())];
        let cfg = self.ekf_config(Mode::Ekf);
        let mut x = Vec::with_capacity(u.len());
        for k in 0..u.len() {
            if k < 2 {
                x.push(cfg.x0_mean);
                continue;
            }
            let input = hbn_core::transition_input(
                x[k - 1],
                x[k - 2],
                u[k - 1],
                u[k - 2],
                &play_states[k - 1],
            );
            let input = input.get(..view.dim()).unwrap_or(&input);
            let next = match view.predict(input, Want::default(), &mut scratch) {
                Ok(p) => p.mean.clamp(cfg.x_bounds.0, cfg.x_bounds.1),
                Err(_) => x[k - 1],
            };
            x.push(next);
        }
        Ok(x)
    }
}

/// Counts of each guard flag over per-sample flag words, by name, in order of first appearance.
pub(crate) fn count_flags(flags: &[u32]) -> Vec<(&'static str, usize)> {
    let mut counts: Vec<(&'static str, usize)> = Vec::new();
    for &f in flags {
        for name in Flags(f).names() {
            match counts.iter_mut().find(|(n, _)| *n == name) {
                Some((_, c)) => *c += 1,
                None => counts.push((name, 1)),
            }
        }
    }
    counts
}
