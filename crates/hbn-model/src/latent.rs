//! Training when the state is measured only sometimes: a camera slower than the sensor, frames
//! dropped. The samples between the frames are latent, and expectation-maximisation over the
//! HBN estimates them instead of trusting an interpolation ([`HysteresisModel::fit_latent`]):
//!
//! 1. fit the model as usual on the state interpolated between the frames (the held-out
//!    scores compare the filter with measured samples only, [`Sequence::observed`]);
//! 2. E-step: smooth every training run with the current model given `u`, `y` and the frames
//!    ([`HysteresisModel::smooth_frames`]: each frame is a linear measurement of `x_k` and
//!    `x_{k-1}`, the grid samples around it);
//! 3. M-step: refit the GPs (the configuration the first fit chose, hyperparameters searched
//!    again) on the smoothed states;
//! 4. repeat while the held-out NLPD of the default mode improves, within a training time of
//!    [`TIME_BUDGET`] times the first fit's.
//!
//! The M-step uses the smoothed means as data. docs/slow-camera.md gives the reasoning and
//! the measurements.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::dataset::Sequence;
use crate::model::GpRole;
use crate::params::CheckedHbnParams;
use crate::smooth::StateFrame;
use crate::{HysteresisModel, ModelError};
use hbn_gp::FitProgress;

/// Training time of the whole of [`HysteresisModel::fit_latent`] at most, as a multiple of its
/// first fit's: a round of EM starts only when the rounds so far suggest it ends within it.
pub const TIME_BUDGET: f64 = 3.0;

/// Rounds of EM at most (each a smoothing pass and a refit).
pub const MAX_ROUNDS: usize = 4;

/// Standard deviation of a frame's measurement noise, as a fraction of the state's range in the
/// training data: the state's measurement is what the model learns and is scored against,
/// as it is when the state is measured at every sample, so the smoother follows the frames
/// closely.
pub const FRAME_STD: f64 = 1e-3;

/// One training run whose state was measured at its own times.
#[derive(Clone, Copy, Debug)]
pub struct LatentRun<'a> {
    /// The run on the grid: `x` interpolated between the frames, and
    /// [`Sequence::observed`] the grid samples next to a frame (scored held out).
    pub seq: Sequence<'a>,
    /// The frames, sorted by grid sample ([`StateFrame`]).
    pub frames: &'a [StateFrame],
}

/// One round of expectation-maximisation ([`HysteresisModel::fit_latent`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct EmRound {
    /// The round (0: the fit on the interpolated state).
    pub round: usize,
    /// Held-out NLPD of the default mode at the measured samples (nats).
    pub nlpd: f64,
    /// Held-out nRMSE of the default mode at the measured samples.
    pub nrmse: f64,
    /// Whether the round improved on the best before it (round 0 always does).
    pub improved: bool,
}

/// How the state of the training runs was measured and what training did about the gaps.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LatentReport {
    /// Fraction of the grid samples next to a frame.
    pub observed: f64,
    /// Frames in all runs.
    pub frames: usize,
    /// The rounds of EM, the first fit included; the model is the best one's.
    pub rounds: Vec<EmRound>,
}

/// The default mode's held-out score of a model: `(NLPD, nRMSE)`; `None` untuned.
fn held_out(model: &HysteresisModel) -> Option<(f64, f64)> {
    let v = model.summary().validation.as_ref()?;
    let row = v.rows.iter().find(|r| r.mode == v.default_mode)?;
    let s = row.tuned;
    (s.calibration.nlpd.is_finite() && s.nrmse.is_finite()).then_some((s.calibration.nlpd, s.nrmse))
}

/// How much of the state was measured.
fn sparse_note(report: &LatentReport) -> String {
    format!(
        "the state was measured at {:.0}% of the grid's samples ({} frames), so the samples \
         between them are latent",
        100.0 * report.observed,
        report.frames
    )
}

/// What expectation-maximisation did ([`sparse_note`] first).
fn em_note(report: &LatentReport) -> String {
    let first = report.rounds.first();
    let best = report
        .rounds
        .iter()
        .filter(|r| r.improved)
        .next_back()
        .or(first);
    let refits = report.rounds.len().saturating_sub(1);
    match (first, best) {
        (Some(first), Some(best)) if best.round > 0 => format!(
            "{}: expectation-maximisation refitted the model on the smoothed states {refits} \
             time{}, and round {} is kept (held-out NLPD at the measured samples {:.3} -> \
             {:.3}, nRMSE {:.4} -> {:.4})",
            sparse_note(report),
            if refits == 1 { "" } else { "s" },
            best.round,
            first.nlpd,
            best.nlpd,
            first.nrmse,
            best.nrmse
        ),
        _ => format!(
            "{}: expectation-maximisation refitted the model on the smoothed states {refits} \
             time{} without improving the held-out score, so the model trained on the state \
             interpolated between the frames is kept",
            sparse_note(report),
            if refits == 1 { "" } else { "s" },
        ),
    }
}

impl HysteresisModel {
    /// Learns both relations from runs whose state was measured only at some samples
    /// ([`LatentRun`]), by expectation-maximisation (the module's documentation,
    /// [`crate::latent`]). The model returned is the round with the lowest held-out NLPD; its
    /// [`crate::TrainingSummary::latent`] records the rounds. Without held-out data (too
    /// little, or `validation = 0`) there is no score to decide by, and the first fit is
    /// returned.
    pub fn fit_latent(
        runs: &[LatentRun<'_>],
        params: &CheckedHbnParams,
        observe: &mut dyn FnMut(GpRole, &FitProgress),
    ) -> Result<Self, ModelError> {
        let t0 = Instant::now();
        let seqs: Vec<Sequence<'_>> = runs.iter().map(|r| r.seq).collect();
        let mut best = Self::fit_checked(&seqs, params, observe)?;
        let first_s = t0.elapsed().as_secs_f64();
        let samples: usize = seqs.iter().map(|s| s.u.len()).sum();
        let observed: usize = seqs
            .iter()
            .map(|s| (0..s.u.len()).filter(|&k| s.is_observed(k)).count())
            .sum();
        let mut report = LatentReport {
            observed: observed as f64 / samples.max(1) as f64,
            frames: runs.iter().map(|r| r.frames.len()).sum(),
            rounds: Vec::new(),
        };
        let Some((mut best_nlpd, nrmse)) = held_out(&best) else {
            let warning = format!(
                "{}; without held-out data to judge a refit by, the model trained on the state \
                 interpolated between them",
                sparse_note(&report)
            );
            let summary = best.summary_mut();
            summary.warnings.push(warning);
            summary.latent = Some(report);
            return Ok(best);
        };
        report.rounds.push(EmRound {
            round: 0,
            nlpd: best_nlpd,
            nrmse,
            improved: true,
        });
        // What the first fit chose among: a refit trains its choice only.
        let candidates = best
            .summary()
            .validation
            .as_ref()
            .map(|v| v.candidates.clone())
            .unwrap_or_default();
        let kernel_evidence = best.summary().kernel_evidence.clone();
        // The configuration the first fit chose, trained again on the smoothed states.
        let refit = best.params().clone().check()?;
        let x_stats = best.stats().1;
        let range = x_stats.max - x_stats.min;
        let frame_var = (FRAME_STD * range).powi(2).max(f64::MIN_POSITIVE);
        let mut round_s = 0.0f64;
        for round in 1..=MAX_ROUNDS {
            let elapsed = t0.elapsed().as_secs_f64();
            // A refit of one configuration costs at most the first fit; until a round has run,
            // assume it does.
            let next = if round_s > 0.0 { round_s } else { first_s };
            if elapsed + next > TIME_BUDGET * first_s {
                break;
            }
            let t_round = Instant::now();
            let config = best.ekf_config(best.default_mode());
            let smoothed: Vec<Vec<f64>> = runs
                .iter()
                .map(|r| {
                    best.smooth_frames(r.seq.u, r.seq.y, r.frames, frame_var, &config)
                        .map(|s| s.states.mean.iter().map(|m| m.x).collect())
                })
                .collect::<Result<_, _>>()?;
            let seqs: Vec<Sequence<'_>> = runs
                .iter()
                .zip(&smoothed)
                .map(|(r, x)| Sequence { x, ..r.seq })
                .collect();
            let candidate = Self::fit_checked(&seqs, &refit, observe)?;
            round_s = t_round.elapsed().as_secs_f64();
            let Some((nlpd, nrmse)) = held_out(&candidate) else {
                break;
            };
            let improved = nlpd < best_nlpd;
            report.rounds.push(EmRound {
                round,
                nlpd,
                nrmse,
                improved,
            });
            if !improved {
                break;
            }
            best_nlpd = nlpd;
            best = candidate;
        }
        let warning = em_note(&report);
        let summary = best.summary_mut();
        summary.warnings.push(warning);
        if let Some(v) = summary.validation.as_mut()
            && v.candidates.is_empty()
        {
            v.candidates = candidates;
        }
        if summary.kernel_evidence.is_empty() {
            summary.kernel_evidence = kernel_evidence;
        }
        summary.latent = Some(report);
        summary.seconds = t0.elapsed().as_secs_f64();
        Ok(best)
    }
}
