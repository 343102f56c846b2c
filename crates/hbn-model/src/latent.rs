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
//!    again) on a path of every run drawn from the smoothed distribution
//!    ([`crate::smooth::Smoothed::sample_path`]), so that the GPs see the latent states'
//!    uncertainty, not only their means;
//! 4. repeat while the held-out NLPD of the default mode improves without the held-out nRMSE
//!    growing beyond the first fit's (the rule of model selection), within a training time of
//!    [`TIME_BUDGET`] times the first fit's.
//!
//! docs/slow-camera.md gives the reasoning and the measurements.

use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::dataset::Sequence;
use crate::model::GpRole;
use crate::params::{CheckedHbnParams, HbnParams};
use crate::smooth::StateFrame;
use crate::{HysteresisModel, ModelError};
use hbn_core::rng::Rng;
use hbn_gp::FitProgress;

/// Training time of the whole of [`HysteresisModel::fit_latent`] at most, as a multiple of its
/// first fit's: a round of EM starts only when the rounds so far suggest it ends within it.
pub const TIME_BUDGET: f64 = 3.0;

/// Mixed into the training seed per round for the draws of the latent paths.
const SEED_STRIDE: u64 = 0x9E37_79B9_7F4A_7C15;

/// Rounds of EM at most (each a smoothing pass and a refit).
pub const MAX_ROUNDS: usize = 4;

/// Standard deviation of a frame's measurement noise, as a fraction of the state's range in the
/// training data: the state's measurement is what the model learns and is scored against,
/// as it is when the state is measured at every sample, so the smoother follows the frames
/// closely.
pub const FRAME_STD: f64 = 1e-3;

/// One training run whose state was measured at its own times, or not at all.
#[derive(Clone, Copy, Debug)]
pub struct LatentRun<'a> {
    /// The run on the grid: `x` interpolated between the frames, and
    /// [`Sequence::observed`] the grid samples next to a frame (scored held out). For a run
    /// without frames `x` is not read (any finite values of the right length).
    pub seq: Sequence<'a>,
    /// The frames, sorted by grid sample ([`StateFrame`]). Empty for a run whose state was
    /// never measured: it joins from the first refit, on paths drawn from its smoothed states
    /// given `u` and `y` alone.
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
    /// Whether the round is kept over the best before it: a lower held-out NLPD, and a held-out
    /// nRMSE no higher than round 0's (round 0 always is).
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
    /// Runs whose state was never measured (only `u` and `y`): they are in the model only
    /// when a refit is kept (a round after 0).
    #[serde(default)]
    pub unmeasured_runs: usize,
}

/// The grid samples next to a frame (of the two grid samples around it, the nearer): where
/// the state interpolated between the frames is, within half a grid step, a measurement
/// ([`Sequence::observed`]). `len` is the run's length; frames beyond it are ignored.
pub fn observed_mask(frames: &[StateFrame], len: usize) -> Vec<bool> {
    let mut mask = vec![false; len];
    for f in frames {
        let k = if f.weight >= 0.5 {
            f.k
        } else {
            f.k.saturating_sub(1)
        };
        if let Some(m) = mask.get_mut(k) {
            *m = true;
        }
    }
    mask
}

/// A state measured at some samples of a run and not at the others, in the parts of a
/// [`LatentRun`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PartialState {
    /// The measured samples, each a frame on its grid sample (weight 1).
    pub frames: Vec<StateFrame>,
    /// The state interpolated linearly between the measured samples (held before the first
    /// and after the last).
    pub interpolated: Vec<f64>,
    /// Which samples were measured.
    pub observed: Vec<bool>,
}

impl PartialState {
    /// A run of `len` samples whose state was never measured (only `u` and `y` were logged):
    /// no frames, nothing observed, and a placeholder state of zeros that
    /// [`HysteresisModel::fit_latent`] never trains on (it replaces it with paths drawn from
    /// the smoothed states).
    pub fn unmeasured(len: usize) -> Self {
        Self {
            frames: Vec::new(),
            interpolated: vec![0.0; len],
            observed: vec![false; len],
        }
    }

    /// The measured samples of `x`: the finite ones (NaN marks a sample without a
    /// measurement). `None` when no sample is finite.
    pub fn from_gaps(x: &[f64]) -> Option<Self> {
        let frames: Vec<StateFrame> = x
            .iter()
            .enumerate()
            .filter(|(_, v)| v.is_finite())
            .map(|(k, &value)| StateFrame {
                k,
                weight: 1.0,
                value,
            })
            .collect();
        let first = frames.first()?;
        let mut interpolated = vec![first.value; x.len()];
        for pair in frames.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let span = (b.k - a.k) as f64;
            for (i, v) in interpolated.iter_mut().enumerate().take(b.k + 1).skip(a.k) {
                let w = (i - a.k) as f64 / span;
                *v = (1.0 - w) * a.value + w * b.value;
            }
        }
        if let Some(last) = frames.last() {
            interpolated
                .iter_mut()
                .skip(last.k)
                .for_each(|v| *v = last.value);
        }
        let observed = x.iter().map(|v| v.is_finite()).collect();
        Some(Self {
            frames,
            interpolated,
            observed,
        })
    }
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
    let unmeasured = match report.unmeasured_runs {
        0 => String::new(),
        1 => " (one run has no state at all: only u and y)".to_owned(),
        n => format!(" ({n} runs have no state at all: only u and y)"),
    };
    format!(
        "the state was measured at {:.0}% of the grid's samples ({} frames){unmeasured}, so \
         the samples between them are latent",
        100.0 * report.observed,
        report.frames
    )
}

/// The warning training gives about a state measured sparsely: how much was measured and what
/// expectation-maximisation did ([`em_rounds`]; no rounds: there was no held-out data to judge
/// a refit by).
pub(crate) fn latent_warning(report: &LatentReport) -> String {
    if report.rounds.is_empty() {
        return format!(
            "{}; without held-out data to judge a refit by, the model trained on the state \
             interpolated between them{}",
            sparse_note(report),
            if report.unmeasured_runs > 0 {
                " (the runs without a measured state are left out)"
            } else {
                ""
            }
        );
    }
    em_note(report)
}

/// What expectation-maximisation did ([`sparse_note`] first).
fn em_note(report: &LatentReport) -> String {
    let first = report.rounds.first();
    let best = report.rounds.iter().rfind(|r| r.improved).or(first);
    let refits = report.rounds.len().saturating_sub(1);
    match (first, best) {
        (Some(first), Some(best)) if best.round > 0 => format!(
            "{}: expectation-maximisation refitted the model on paths drawn from the smoothed \
             states {refits} time{}, and round {} is kept (held-out NLPD at the measured samples {:.3} -> \
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
            "{}: expectation-maximisation refitted the model on paths drawn from the smoothed \
             states {refits} time{} without improving the held-out score, so the model trained on the state \
             interpolated between the frames is kept{}",
            sparse_note(report),
            if refits == 1 { "" } else { "s" },
            if report.unmeasured_runs > 0 {
                " (without the runs that have no state)"
            } else {
                ""
            }
        ),
    }
}

/// The rounds of expectation-maximisation after a first fit (`first`, which took `first_s`
/// seconds of the training that started at `t0`): each round refits (`refit(best, round)`:
/// the E-step and the M-step) and is kept while `held_out` (NLPD, nRMSE at the measured
/// samples) improves by the rule of model selection, within [`MAX_ROUNDS`] and [`TIME_BUDGET`].
/// The rounds go into `report`; none when the first fit has no held-out score.
pub(crate) fn em_rounds<M>(
    first: M,
    t0: Instant,
    first_s: f64,
    held_out: impl Fn(&M) -> Option<(f64, f64)>,
    mut refit: impl FnMut(&M, usize) -> Result<M, ModelError>,
    report: &mut LatentReport,
) -> Result<M, ModelError> {
    let Some((mut best_nlpd, first_nrmse)) = held_out(&first) else {
        return Ok(first);
    };
    report.rounds.push(EmRound {
        round: 0,
        nlpd: best_nlpd,
        nrmse: first_nrmse,
        improved: true,
    });
    let mut best = first;
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
        let candidate = refit(&best, round)?;
        round_s = t_round.elapsed().as_secs_f64();
        let Some((nlpd, nrmse)) = held_out(&candidate) else {
            break;
        };
        // The rule of model selection: a lower held-out NLPD, and no less accurate than the
        // first fit held out (NLPD alone can prefer a wide band around a worse mean).
        let improved = nlpd < best_nlpd && nrmse <= first_nrmse;
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
    Ok(best)
}

/// The variance of a frame's measurement noise for a state of training range `range`
/// ([`FRAME_STD`]).
pub(crate) fn frame_variance(range: f64) -> f64 {
    (FRAME_STD * range).powi(2).max(f64::MIN_POSITIVE)
}

/// Refuses a state with an infinite value ([`crate::DataError::NonFinite`]): NaN marks a
/// sample without a measurement, an infinity is a broken one. `states`: each trajectory's.
pub(crate) fn refuse_infinite_states<'a>(
    states: impl Iterator<Item = &'a [f64]>,
) -> Result<(), ModelError> {
    for (trajectory, x) in states.enumerate() {
        if let Some((index, &value)) = x.iter().enumerate().find(|(_, v)| v.is_infinite()) {
            return Err(crate::DataError::NonFinite {
                trajectory,
                signal: crate::Signal::State,
                index,
                value,
            }
            .into());
        }
    }
    Ok(())
}

/// The random draws of round `round`'s latent paths, from the training seed.
pub(crate) fn round_rng(seed: u64, round: usize) -> Rng {
    Rng::new(seed ^ (round as u64).wrapping_mul(SEED_STRIDE))
}

impl HysteresisModel {
    /// [`HysteresisModel::fit`] for trajectories whose state is NaN where it was not measured
    /// (a slow or dropping camera): [`HysteresisModel::fit_latent`] over the measured samples
    /// ([`PartialState::from_gaps`]) when some are missing, the plain fit otherwise. A
    /// trajectory whose state is NaN throughout (only `u` and `y` were logged) joins from
    /// EM's first refit ([`PartialState::unmeasured`]); when no trajectory has a measured
    /// state, the error is [`crate::DataError::NoStateMeasured`].
    pub fn fit_partial(
        trajectories: &[Sequence<'_>],
        params: &HbnParams,
    ) -> Result<Self, ModelError> {
        let checked = params.clone().check()?;
        refuse_infinite_states(trajectories.iter().map(|t| t.x))?;
        if trajectories
            .iter()
            .all(|t| t.x.iter().all(|v| v.is_finite()))
        {
            return Self::fit_checked(trajectories, &checked, &mut |_, _| {});
        }
        let partial: Vec<PartialState> = trajectories
            .iter()
            .map(|t| {
                PartialState::from_gaps(t.x).unwrap_or_else(|| PartialState::unmeasured(t.x.len()))
            })
            .collect();
        let runs: Vec<LatentRun<'_>> = trajectories
            .iter()
            .zip(&partial)
            .map(|(t, p)| LatentRun {
                seq: Sequence::new(t.u, &p.interpolated, t.y).with_observed(&p.observed),
                frames: &p.frames,
            })
            .collect();
        Self::fit_latent(&runs, &checked, &mut |_, _| {})
    }

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
        // The first fit learns from the runs with a measured state; the others join the refits.
        let measured: Vec<Sequence<'_>> = runs
            .iter()
            .filter(|r| !r.frames.is_empty())
            .map(|r| r.seq)
            .collect();
        if measured.is_empty() {
            return Err(crate::DataError::NoStateMeasured.into());
        }
        // A run without frames has nothing measured to score, whatever its mask says.
        let longest = runs.iter().map(|r| r.seq.u.len()).max().unwrap_or(0);
        let nothing = vec![false; longest];
        let runs: Vec<LatentRun<'_>> = runs
            .iter()
            .map(|r| match r.frames {
                [] => LatentRun {
                    seq: r
                        .seq
                        .with_observed(nothing.get(..r.seq.u.len()).unwrap_or(&[])),
                    ..*r
                },
                _ => *r,
            })
            .collect();
        let seqs: Vec<Sequence<'_>> = runs.iter().map(|r| r.seq).collect();
        let best = Self::fit_checked(&measured, params, observe)?;
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
            unmeasured_runs: runs.len() - measured.len(),
        };
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
        let frame_var = frame_variance(x_stats.max - x_stats.min);
        let mut best = em_rounds(
            best,
            t0,
            first_s,
            held_out,
            |best, round| {
                let config = best.ekf_config(best.default_mode());
                // One path per run drawn from the smoothed distribution: the refit sees the
                // latent states' spread, where the smoothed means would show it a trajectory
                // smoother than the state and a noise too small.
                let mut rng = round_rng(refit.seed, round);
                // The measured samples keep the values the first fit had, so that every round's
                // held-out score compares the filter with the same references (a path drawn
                // around a frame between two grid samples pins only their mix, not the sample
                // the mask marks).
                let smoothed: Vec<Vec<f64>> = runs
                    .iter()
                    .map(|r| {
                        best.smooth_frames(r.seq.u, r.seq.y, r.frames, frame_var, &config)
                            .map(|s| {
                                s.states
                                    .sample_path(|| rng.normal())
                                    .iter()
                                    .zip(r.seq.x)
                                    .enumerate()
                                    .map(|(k, (z, x))| if r.seq.is_observed(k) { *x } else { z.x })
                                    .collect()
                            })
                    })
                    .collect::<Result<_, _>>()?;
                let seqs: Vec<Sequence<'_>> = runs
                    .iter()
                    .zip(&smoothed)
                    .map(|(r, x)| Sequence { x, ..r.seq })
                    .collect();
                Self::fit_checked(&seqs, &refit, observe)
            },
            &mut report,
        )?;
        let warning = latent_warning(&report);
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::HbnParams;
    use crate::metrics::nrmse;
    use hbn_sim::{InputKind, SimConfig, SystemKind, generate_input, simulate};

    /// Frames of `x` at every `every`-th sample (offset by `phase` grid steps, between two grid
    /// samples), and the state interpolated between them, held at the ends.
    fn film(x: &[f64], every: usize, phase: f64) -> (Vec<StateFrame>, Vec<f64>, Vec<bool>) {
        let n = x.len();
        let frames: Vec<StateFrame> = (1..n)
            .step_by(every)
            .map(|k| StateFrame {
                k,
                weight: phase,
                value: phase * x[k] + (1.0 - phase) * x[k - 1],
            })
            .collect();
        let at: Vec<f64> = frames.iter().map(|f| f.k as f64 - 1.0 + f.weight).collect();
        let interpolated = (0..n)
            .map(|k| {
                let t = k as f64;
                let i = at.partition_point(|&s| s <= t);
                match (i.checked_sub(1), frames.get(i)) {
                    (Some(a), Some(b)) => {
                        let w = (t - at[a]) / (at[i] - at[a]);
                        (1.0 - w) * frames[a].value + w * b.value
                    }
                    (Some(a), None) => frames[a].value,
                    (None, _) => frames[0].value,
                }
            })
            .collect();
        let mask = observed_mask(&frames, n);
        (frames, interpolated, mask)
    }

    #[test]
    fn a_state_with_gaps_becomes_frames_an_interpolation_and_a_mask() {
        let nan = f64::NAN;
        let p = PartialState::from_gaps(&[nan, 1.0, nan, nan, 4.0, nan]).unwrap();
        assert_eq!(p.interpolated, vec![1.0, 1.0, 2.0, 3.0, 4.0, 4.0]);
        assert_eq!(p.observed, vec![false, true, false, false, true, false]);
        assert_eq!(p.frames.len(), 2);
        assert_eq!(
            (p.frames[1].k, p.frames[1].weight, p.frames[1].value),
            (4, 1.0, 4.0)
        );
        assert_eq!(observed_mask(&p.frames, 6), p.observed);
        assert!(PartialState::from_gaps(&[nan, nan]).is_none());
        // A frame between two samples marks the nearer one; frames past the end are ignored.
        let f = |k, weight| StateFrame {
            k,
            weight,
            value: 0.0,
        };
        assert_eq!(
            observed_mask(&[f(0, 1.0), f(2, 0.3), f(3, 0.7), f(9, 1.0)], 4),
            vec![true, true, false, true]
        );
    }

    /// Runs with `u` and `y` only join EM's refits: the first fit is the measured runs'
    /// alone (the unmeasured runs' placeholder state is never read), and a refit that takes
    /// them in is kept where held-out data say it is better (a case where they do: Bouc-Wen at
    /// noise gain 1, held-out nRMSE 0.0225 -> 0.0166; a fresh run's nRMSE falls too).
    #[test]
    fn runs_without_a_state_join_from_the_first_refit() {
        let cfg = SimConfig {
            noise_gain: 1.0,
            ..SimConfig::new(SystemKind::BoucWen)
        };
        let runs: Vec<_> = (0..3)
            .map(|i| {
                let u = generate_input(InputKind::RandomRamps, 700, 0.05, 60 + i).unwrap();
                simulate(
                    &SimConfig {
                        seed: 70 + i,
                        ..cfg
                    },
                    &u,
                )
                .unwrap()
            })
            .collect();
        // The thesis' sensor alone: the test is of EM's joining, on a model whose one measured
        // run leaves room for the other two. (With the default's sensor with memory, the
        // measured run alone reaches 0.0131 here and the joined model 0.0132.)
        let mut params = HbnParams {
            max_points: 250,
            n_starts: 1,
            ..HbnParams::default()
        };
        params.select.sensor_inputs.clear();
        let measured = [Sequence::new(&runs[0].u, &runs[0].x, &runs[0].y)];
        let alone = HysteresisModel::fit_partial(&measured, &params).unwrap();
        // NaN for the state: never measured. A finite placeholder of nonsense must not matter.
        let nan = vec![f64::NAN; 700];
        let nonsense = vec![1e6; 700];
        let with_nan = [
            measured[0],
            Sequence::new(&runs[1].u, &nan, &runs[1].y),
            Sequence::new(&runs[2].u, &nan, &runs[2].y),
        ];
        let joined = HysteresisModel::fit_partial(&with_nan, &params).unwrap();
        let frames = PartialState::from_gaps(&runs[0].x).unwrap();
        let latent = [
            LatentRun {
                seq: measured[0].with_observed(&frames.observed),
                frames: &frames.frames,
            },
            LatentRun {
                seq: Sequence::new(&runs[1].u, &nonsense, &runs[1].y),
                frames: &[],
            },
            LatentRun {
                seq: Sequence::new(&runs[2].u, &nonsense, &runs[2].y),
                frames: &[],
            },
        ];
        let checked = params.clone().check().unwrap();
        let direct = HysteresisModel::fit_latent(&latent, &checked, &mut |_, _| {}).unwrap();
        let report = joined.summary().latent.clone().unwrap();
        assert_eq!(report.unmeasured_runs, 2);
        assert_eq!(report, direct.summary().latent.clone().unwrap());
        assert!((report.observed - 1.0 / 3.0).abs() < 1e-9, "{report:?}");
        // Round 0 is the measured run's model.
        assert_eq!(report.rounds[0].nlpd, held_out(&alone).unwrap().0);
        let kept = report.rounds.iter().rfind(|r| r.improved).unwrap();
        assert!(kept.round >= 1, "{report:?}");
        assert!(
            joined
                .summary()
                .warnings
                .iter()
                .any(|w| w.contains("only u and y"))
        );
        let test_u = generate_input(InputKind::RandomRamps, 800, 0.05, 99).unwrap();
        let test = simulate(&SimConfig { seed: 99, ..cfg }, &test_u).unwrap();
        let score = |m: &HysteresisModel| {
            let e = m.estimate(&test.u, &test.y, m.default_mode()).unwrap();
            nrmse(&e.x, &test.x)
        };
        let (a, b) = (score(&alone), score(&joined));
        eprintln!("measured run alone {a}, with two runs of u and y {b}: {report:?}");
        assert!(b < a, "with the unmeasured runs {b} against {a}");
    }

    #[test]
    fn fit_partial_refuses_an_infinite_state() {
        let u: Vec<f64> = (0..100).map(|k| (k as f64 * 0.1).sin()).collect();
        let mut x = u.clone();
        x[3] = f64::NAN;
        x[7] = f64::NEG_INFINITY;
        let e = HysteresisModel::fit_partial(&[Sequence::new(&u, &x, &u)], &HbnParams::default())
            .unwrap_err();
        assert!(
            matches!(
                e,
                ModelError::Data(crate::DataError::NonFinite {
                    trajectory: 0,
                    signal: crate::Signal::State,
                    index: 7,
                    ..
                })
            ),
            "{e}"
        );
    }

    #[test]
    fn fit_partial_refuses_when_no_run_has_a_measured_state() {
        let u: Vec<f64> = (0..100).map(|k| (k as f64 * 0.1).sin()).collect();
        let x = vec![f64::NAN; 100];
        let e = HysteresisModel::fit_partial(&[Sequence::new(&u, &x, &u)], &HbnParams::default())
            .unwrap_err();
        assert!(
            matches!(e, ModelError::Data(crate::DataError::NoStateMeasured)),
            "{e}"
        );
    }

    /// A case built for EM: Bouc-Wen at noise gain 1, the state filmed at every fourth sample
    /// (halfway between two grid samples). The model trained on the interpolated state learns
    /// the interpolation's straight lines; EM's refits on paths drawn from the smoothed states
    /// score better held out (measured: nRMSE 0.0200 -> 0.0179 at the measured samples, NLPD
    /// -2.64 -> -2.85 nats, round 2 of 3 kept) and estimate a fresh run more accurately (0.0166
    /// against 0.0205; 0.0200 when the refits trained on the drawn path at the measured samples
    /// too, whose held-out references then moved from round to round), and the model kept has
    /// the best held-out score of its rounds.
    #[test]
    fn em_improves_on_the_interpolated_state() {
        let cfg = SimConfig {
            noise_gain: 1.0,
            ..SimConfig::new(SystemKind::BoucWen)
        };
        let u = generate_input(InputKind::RandomRamps, 600, 0.05, 3).unwrap();
        let runs: Vec<_> = (0..3)
            .map(|i| {
                simulate(
                    &SimConfig {
                        seed: 10 + i,
                        ..cfg
                    },
                    &u,
                )
                .unwrap()
            })
            .collect();
        let filmed: Vec<_> = runs.iter().map(|r| film(&r.x, 4, 0.5)).collect();
        let latent: Vec<LatentRun<'_>> = runs
            .iter()
            .zip(&filmed)
            .map(|(r, (frames, xi, mask))| LatentRun {
                seq: Sequence::new(&r.u, xi, &r.y).with_observed(mask),
                frames,
            })
            .collect();
        let params = HbnParams {
            max_points: 250,
            n_starts: 1,
            ..HbnParams::default()
        }
        .check()
        .unwrap();
        let seqs: Vec<Sequence<'_>> = latent.iter().map(|r| r.seq).collect();
        let interpolated = HysteresisModel::fit_checked(&seqs, &params, &mut |_, _| {}).unwrap();
        let em = HysteresisModel::fit_latent(&latent, &params, &mut |_, _| {}).unwrap();
        let report = em.summary().latent.clone().unwrap();
        assert_eq!(
            report.frames,
            filmed.iter().map(|f| f.0.len()).sum::<usize>()
        );
        assert!((report.observed - 0.25).abs() < 0.01, "{report:?}");
        let kept = report.rounds.iter().rfind(|r| r.improved).unwrap();
        let best = report
            .rounds
            .iter()
            .map(|r| r.nlpd)
            .fold(f64::INFINITY, f64::min);
        assert_eq!(kept.nlpd, best);
        assert_eq!(held_out(&em).unwrap().0, best);
        // EM kept a refit, more accurate held out than the first fit.
        assert!(kept.round >= 1, "{report:?}");
        assert!(kept.nrmse < report.rounds[0].nrmse, "{report:?}");
        assert!(em.summary().warnings.iter().any(|w| w.contains("latent")));
        let test_u = generate_input(InputKind::RandomRamps, 800, 0.05, 99).unwrap();
        let test = simulate(&SimConfig { seed: 99, ..cfg }, &test_u).unwrap();
        let score = |m: &HysteresisModel| {
            let e = m.estimate(&test.u, &test.y, m.default_mode()).unwrap();
            nrmse(&e.x, &test.x)
        };
        let (a, b) = (score(&interpolated), score(&em));
        eprintln!("interpolated {a}, EM {b}, rounds {:?}", report.rounds);
        assert!(b < 0.9 * a, "EM {b} against the interpolated state's {a}");
    }
}
