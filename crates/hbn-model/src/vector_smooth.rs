//! Smoothing a vector model: the filter forward, recording each step's prediction
//! ([`hbn_core::vector::VectorEkf::predict`]), then the same Rauch-Tung-Striebel pass as the
//! scalar model's ([`crate::smooth::rts`]) over the augmented state `[x_k, x_{k-1}, s_k]` of
//! dimension `2 dx + dy`: extended for the EKF (`C_k = P_{k-1} F_k^T`), unscented for the UKF
//! (the sigma points' cross-covariance). The pass runs on the covariances scaled by each
//! component's box span (`P_ij / (span_i span_j)`), where the filter's eigenvalue bounds
//! `[p_min, p_max]` apply, and the result is scaled back.

use hbn_core::Mode;
use hbn_core::vector::{MAX_AUGMENTED, VectorPrediction};
use nalgebra::{SMatrix, SVector};

use crate::ModelError;
use crate::smooth::{CovarianceBounds, FilterRecord, Link, Smoothed, rts};
use crate::vector::{Frames, Recorded, RecordedStep, VectorEstimate, VectorModel};
use hbn_core::CoreError;

/// A smoothed run of a [`VectorModel`]: the estimate with the smoothed values, the filter's own,
/// and the smoothed augmented states with their covariances.
#[derive(Clone, Debug, PartialEq)]
pub struct VectorSmoothing {
    /// The filter's per-sample results with `x`, `x_std` and `x_cov` smoothed (calibrated by
    /// the model's per-component `std_scale`, as the filter's are); the other fields (the
    /// predicted measurements, innovations, NIS, flags and observability) are the forward
    /// filter's.
    pub estimate: VectorEstimate,
    /// The forward filter's estimate ([`VectorModel::estimate`] in the same mode).
    pub filtered: VectorEstimate,
    /// Dimension `n = 2 dx + dy` of the augmented state `z_k = [x_k, x_{k-1}, s_k]`.
    pub augmented: usize,
    /// Smoothed mean of each `z_k`, `T x n` (raw units).
    pub mean: Vec<f64>,
    /// Smoothed covariance of each `z_k`, `T x n x n` row-major (raw units, uncalibrated).
    pub cov: Vec<f64>,
    /// Lag-one cross-covariance `cov(z_k, z_{k+1})`, `(T - 1) x n x n` (zero across a step
    /// the filter re-started at).
    pub lag_one: Vec<f64>,
    /// Jitter retries the factorisations of the predicted covariances needed.
    pub jitter_retries: usize,
    /// Steps that kept their filtered state (no link to the next, or a prediction that could
    /// not be factorised).
    pub unlinked: usize,
    /// Smoothed covariances whose eigenvalues were clamped into the filter's bounds.
    pub clamped: usize,
    /// Steps that kept their filtered state because the smoothed one departed from it
    /// implausibly far ([`crate::smooth::departure_gate`]).
    pub gated: usize,
}

impl VectorModel {
    /// Smooths a sequence in `mode` (the EKF or the UKF): each `x_k` estimated from the whole
    /// sequence. Returns what [`VectorModel::estimate`] returns, with the smoothed `x`, `x_std`
    /// and `x_cov`; [`VectorModel::smooth_with`] also gives the augmented states. Offline: it
    /// needs the whole sequence, and costs about two filter runs.
    pub fn smooth(&self, u: &[f64], y: &[f64], mode: Mode) -> Result<VectorEstimate, ModelError> {
        Ok(self.smooth_with(u, y, mode)?.estimate)
    }

    /// Smooths ([`VectorModel::smooth`]) and returns the smoothed and filtered estimates and
    /// the smoothed augmented states with their covariances.
    pub fn smooth_with(
        &self,
        u: &[f64],
        y: &[f64],
        mode: Mode,
    ) -> Result<VectorSmoothing, ModelError> {
        Ok(self.smooth_frames(u, y, mode, &Frames::NONE, None)?.0)
    }

    /// [`VectorModel::smooth_with`] given measurements of the state as well (each component's
    /// frames, sorted by grid sample, with their noise variance): the smoothed states of a
    /// training log whose state was recorded at its own rate, with gaps (the E-step of
    /// [`VectorModel::fit_latent`]). [`VectorSmoothing::filtered`] is the filter's output at
    /// each sample before that sample's frames (the frames of earlier samples included).
    /// With `normal` (standard normal draws), also a path of the state drawn from the
    /// smoothed distribution ([`crate::smooth::Smoothed::sample_path`]), `T x dx`.
    pub(crate) fn smooth_frames(
        &self,
        u: &[f64],
        y: &[f64],
        mode: Mode,
        frames: &Frames<'_>,
        normal: Option<&mut dyn FnMut() -> f64>,
    ) -> Result<(VectorSmoothing, Option<Vec<f64>>), ModelError> {
        let (filtered, recorded) = self.run(u, y, mode, true, frames)?;
        let Some(recorded) = recorded else {
            return Err(CoreError::InvalidSpec("the filter run recorded nothing").into());
        };
        let config = self.config(mode);
        let n = self.dims().augmented();
        let bounds = CovarianceBounds {
            min: config.p_min,
            max: config.p_max,
        };
        let scaled = smooth_scaled(n, &recorded, bounds, normal)?;
        let dx = self.dims().states;
        let mut estimate = filtered.clone();
        let scale = |i: usize| config.std_scale.get(i).copied().unwrap_or(1.0);
        let rows = scaled
            .mean
            .chunks_exact(n)
            .zip(scaled.cov.chunks_exact(n * n));
        let x = estimate.x.chunks_exact_mut(dx);
        let x_std = estimate.x_std.chunks_exact_mut(dx);
        let x_cov = estimate.x_cov.chunks_exact_mut(dx * dx);
        for ((((m, p), x), x_std), x_cov) in rows.zip(x).zip(x_std).zip(x_cov) {
            for i in 0..dx {
                x[i] = m[i];
                x_std[i] = scale(i) * p[i * n + i].max(0.0).sqrt();
                for j in 0..dx {
                    x_cov[i * dx + j] = scale(i) * scale(j) * p[i * n + j];
                }
            }
        }
        let path = scaled.path.map(|p| {
            p.chunks_exact(n)
                .flat_map(|z| z.iter().take(dx).copied())
                .collect()
        });
        let smoothing = VectorSmoothing {
            estimate,
            filtered,
            augmented: n,
            mean: scaled.mean,
            cov: scaled.cov,
            lag_one: scaled.lag_one,
            jitter_retries: scaled.jitter_retries,
            unlinked: scaled.unlinked,
            clamped: scaled.clamped,
            gated: scaled.gated,
        };
        Ok((smoothing, path))
    }
}

/// The backward pass's results in raw units, as flat arrays.
struct Flat {
    mean: Vec<f64>,
    cov: Vec<f64>,
    lag_one: Vec<f64>,
    jitter_retries: usize,
    unlinked: usize,
    clamped: usize,
    gated: usize,
    /// A path drawn from the smoothed distribution, `T x n`, when asked for.
    path: Option<Vec<f64>>,
}

/// [`rts`] at the augmented dimension `n` (3 to [`MAX_AUGMENTED`]).
fn smooth_scaled(
    n: usize,
    recorded: &Recorded,
    bounds: CovarianceBounds,
    normal: Option<&mut dyn FnMut() -> f64>,
) -> Result<Flat, ModelError> {
    macro_rules! at_size {
        ($($size:literal),*) => {
            match n {
                $($size => Ok(smooth_n::<$size>(recorded, bounds, normal)),)*
                _ => Err(CoreError::InvalidSpec(
                    "the augmented state of a vector model has 3 to 10 components",
                )
                .into()),
            }
        };
    }
    at_size!(3, 4, 5, 6, 7, 8, 9, 10)
}

fn smooth_n<const N: usize>(
    recorded: &Recorded,
    bounds: CovarianceBounds,
    normal: Option<&mut dyn FnMut() -> f64>,
) -> Flat {
    let span = &recorded.spans;
    let sp = |i: usize| span.get(i).copied().unwrap_or(1.0);
    let vector = |z: &[f64; MAX_AUGMENTED]| SVector::<f64, N>::from_fn(|i, _| z[i] / sp(i));
    let matrix = |p: &[[f64; MAX_AUGMENTED]; MAX_AUGMENTED]| {
        SMatrix::<f64, N, N>::from_fn(|i, j| p[i][j] / (sp(i) * sp(j)))
    };
    let records: Vec<FilterRecord<N>> = recorded
        .steps
        .iter()
        .map(|s: &RecordedStep| FilterRecord {
            m_filt: vector(&s.z),
            p_filt: matrix(&s.p),
            link: s.link.map(|l: VectorPrediction| Link {
                m_pred: vector(&l.z),
                p_pred: matrix(&l.p),
                cross: matrix(&l.cross),
            }),
        })
        .collect();
    let smoothed = rts(&records, bounds);
    // Drawn where the covariances are scaled, as the backward pass ran.
    let path = normal.map(|normal| {
        smoothed
            .sample_path(normal)
            .iter()
            .flat_map(|z| (0..N).map(move |i| z[i] * sp(i)))
            .collect()
    });
    let Smoothed {
        mean,
        cov,
        lag_one,
        jitter_retries,
        unlinked,
        clamped,
        gated,
    } = smoothed;
    let raw_matrices = |ps: &[SMatrix<f64, N, N>]| -> Vec<f64> {
        let mut out = Vec::with_capacity(ps.len() * N * N);
        for p in ps {
            for i in 0..N {
                out.extend((0..N).map(|j| p[(i, j)] * sp(i) * sp(j)));
            }
        }
        out
    };
    Flat {
        mean: mean
            .iter()
            .flat_map(|m| (0..N).map(move |i| m[i] * sp(i)))
            .collect(),
        cov: raw_matrices(&cov),
        lag_one: raw_matrices(&lag_one),
        jitter_retries,
        unlinked,
        clamped,
        gated,
        path,
    }
}
