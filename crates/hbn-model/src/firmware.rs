//! Firmware sizes of a model: the bytes of the constant tables an export holds (flash) and of
//! the work memory its step needs (RAM), computed from the tables themselves
//! ([`hbn_core::tables`]), as `hbn-export` writes them. Training with a flash budget
//! ([`crate::HbnParams::firmware_budget`]) decides with these.

use hbn_core::gp::{GpView, Variance};
use hbn_core::kernel::profile_and_slope;
use hbn_core::tables::{self, TableSink};
use hbn_core::{CoreError, EkfConfig, Estimator, HbnView, Mode};

use crate::{HysteresisModel, ModelError};

/// Largest change of a GP's latent variance, as a fraction of what the filter adds it to,
/// that rounding the GP's variance factor to `f32` may cause before the tables keep the factor
/// in two parts ([`f32_variance_error`], [`factors_in_two_parts`]).
pub const F32_VARIANCE_TOLERANCE: f64 = 0.01;

/// Most probes [`f32_variance_error`] takes at a GP's support (inducing) points.
const VARIANCE_PROBES: usize = 64;

/// How far rounding `gp`'s variance factor to `f32` moves its latent variance where the filter
/// uses it: the largest `|var_f32 - var_f64| / (var_f64 + noise)` over probes at up to 64 of
/// its support (inducing) points and midway between consecutive ones, latent variances
/// clamped at 0 as the GP clamps them, with the GP's noise variance as `noise` where the
/// filter adds it (`with_noise`), else 0. The variance `k(x,x) - |F k|^2` cancels in as many
/// digits as the signal variance exceeds the posterior's, so a GP with a large signal variance
/// (a kernel on a near-linear ridge) can lose there all that `f32` keeps (an error of 1).
pub fn f32_variance_error(gp: &GpView<'_>, with_noise: bool) -> f64 {
    let p = gp.parts();
    let (n, d) = (gp.len(), gp.dim());
    let spec = *p.kernel.spec();
    let sf2 = p.kernel.signal_variance();
    let (factor, exact) = match p.variance {
        Variance::Exact { chol_packed } => (chol_packed, true),
        Variance::Sparse { variance_factor } => (variance_factor, false),
    };
    let rounded: Vec<f64> = factor.iter().map(|&v| f64::from(v as f32)).collect();
    let feature = |i: usize| &p.features[i * d..(i + 1) * d];
    let sign = |i: usize| p.directions.get(i).copied().unwrap_or(1.0);
    // |F k|^2: `L^{-1} k` by forward substitution (exact), `R k` (sparse); rows packed.
    let quad = |f: &[f64], k: &[f64]| -> f64 {
        let mut w = vec![0.0; n];
        for i in 0..n {
            let row = &f[i * (i + 1) / 2..][..=i];
            w[i] = if exact {
                let dot: f64 = row[..i].iter().zip(&w[..i]).map(|(a, b)| a * b).sum();
                (k[i] - dot) / row[i]
            } else {
                row.iter().zip(k).map(|(a, b)| a * b).sum()
            };
        }
        w.iter().map(|v| v * v).sum()
    };
    let mut worst = 0.0f64;
    let mut k = vec![0.0; n];
    let step = n.div_ceil(VARIANCE_PROBES).max(1);
    for i in (0..n).step_by(step) {
        let next = (i + step).min(n - 1);
        for (probe, g) in [
            (feature(i).to_vec(), sign(i)),
            (
                feature(i)
                    .iter()
                    .zip(feature(next))
                    .map(|(a, b)| 0.5 * (a + b))
                    .collect(),
                sign(i),
            ),
        ] {
            for (j, kj) in k.iter_mut().enumerate() {
                let r2: f64 = probe
                    .iter()
                    .zip(feature(j))
                    .map(|(a, b)| (a - b) * (a - b))
                    .sum();
                *kj =
                    sf2 * profile_and_slope(spec.profile, r2).0 * spec.direction_factor(g, sign(j));
            }
            // The latent variance, clamped at 0 as the GP does.
            let kss = sf2 * spec.direction_factor(g, g);
            let var = (kss - quad(factor, &k)).max(0.0);
            let var32 = (kss - quad(&rounded, &k)).max(0.0);
            let noise = if with_noise { p.noise_var } else { 0.0 };
            let err = (var32 - var).abs() / (var + noise);
            // 0 / 0 (no latent variance and no noise): nothing to lose.
            if !err.is_nan() {
                worst = worst.max(err);
            }
        }
    }
    worst
}

/// Which variance factors (transition, sensor) the tables keep in two parts: those whose
/// latent variance rounding to `f32` would move by more than [`F32_VARIANCE_TOLERANCE`] of
/// what the filter adds it to ([`f32_variance_error`]). The transition's variance enters the
/// process noise with its noise variance; the sensor's enters the process noise alone.
pub fn factors_in_two_parts(view: &HbnView<'_>) -> [bool; 2] {
    f32_variance_errors(view).map(|err| err > F32_VARIANCE_TOLERANCE)
}

/// [`f32_variance_error`] of the transition GP (with its noise) and of the sensor GP (without).
pub fn f32_variance_errors(view: &HbnView<'_>) -> [f64; 2] {
    [
        f32_variance_error(&view.transition, true),
        f32_variance_error(&view.sensor, false),
    ]
}

/// The table sizes of one encoding: what the arrays hold, without the values.
#[derive(Default)]
struct Counts {
    layout: Vec<u32>,
    keys: usize,
    reals: usize,
}

impl TableSink for Counts {
    fn int(&mut self, v: u32) {
        self.layout.push(v);
    }
    fn key(&mut self, _: u64) {
        self.keys += 1;
    }
    fn real(&mut self, _: f64) {
        self.reals += 1;
    }
}

/// Bytes of one export of a model in one mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FirmwareSize {
    /// The mode.
    pub mode: Mode,
    /// Constant tables (flash): layout integers, cell keys and reals (an `f32` export also
    /// holds the low parts of the variance factors kept in two parts).
    pub flash: usize,
    /// Work memory the caller provides (RAM): the widened reals of an `f32` export (8 bytes per
    /// real of the `f64` tables) and the step's scratch.
    pub ram: usize,
}

/// The sizes of `view`'s export with `config` and the factors `split` keeps in two parts, with
/// reals of `real_bytes` (4 or 8): `(flash, number of f64 reals)`.
fn table_bytes(
    view: &HbnView<'_>,
    config: &EkfConfig,
    split: [bool; 2],
    real_bytes: usize,
) -> Result<(usize, usize), CoreError> {
    let mut c = Counts::default();
    tables::encode_with(view, config, split, &mut c)?;
    let low = if real_bytes == 4 {
        tables::split_ranges(&c.layout)?.total()
    } else {
        0
    };
    Ok((
        4 * c.layout.len() + 8 * c.keys + real_bytes * (c.reals + low),
        c.reals,
    ))
}

impl HysteresisModel {
    /// Flash and RAM of the model's export in every mode ([`Mode::ALL`]'s order), its reals
    /// `f32` (`f32 = true`) or `f64`, with the model's prior of `x_0` and tuned settings: the
    /// bytes `hbn export` reports and writes.
    pub fn firmware_sizes(&self, f32: bool) -> Result<Vec<FirmwareSize>, ModelError> {
        let view = self.view()?;
        let split = factors_in_two_parts(&view);
        let scratch = 8 * Estimator::scratch_len(&view);
        let real_bytes = if f32 { 4 } else { 8 };
        Mode::ALL
            .into_iter()
            .map(|mode| {
                let (flash, reals) = table_bytes(&view, &self.ekf_config(mode), split, real_bytes)?;
                Ok(FirmwareSize {
                    mode,
                    flash,
                    ram: scratch + if f32 { 8 * reals } else { 0 },
                })
            })
            .collect()
    }
}
