//! Training a vector model when its state is measured only sometimes (a camera tracking the
//! tip slower than the sensors run, dropping frames): the same expectation-maximisation as the
//! scalar model's ([`crate::latent`]), over the augmented state `[x_k, x_{k-1}, s_k]` of
//! dimension `2 dx + dy`. Each component's frames are linear measurements of its `x_k` and
//! `x_{k-1}`; the E-step smooths every run given `u`, `y` and the frames
//! ([`VectorModel::smooth_with`] with the frames as updates) and draws one path of the state
//! from the smoothed distribution; the M-step refits the GPs on it, with the sensor inputs the
//! first fit chose. The held-out scores compare the filter with measured values only.

use std::time::Instant;

use crate::latent::{
    LatentReport, PartialState, em_rounds, frame_variance, latent_warning, observed_mask,
    refuse_infinite_states, round_rng,
};
use crate::params::{CheckedHbnParams, SensorInputs};
use crate::smooth::StateFrame;
use crate::vector::{Frames, SignalNames, VectorModel, VectorSequence};
use crate::{DataError, ModelError};

/// One training run of a vector system whose state was measured at its own times, or not at
/// all.
#[derive(Clone, Copy, Debug)]
pub struct VectorLatentRun<'a> {
    /// The run on the grid, `x` interpolated between the frames (any finite values where a
    /// component has no frames). Its mask of measured values is set from the frames
    /// ([`observed_mask`], per component).
    pub seq: VectorSequence<'a>,
    /// Each state component's frames, sorted by grid sample ([`StateFrame`]); one list per
    /// component. A run where some component has no frame (only `u` and `y` were logged, or
    /// the camera never saw that coordinate) joins from the first refit, on paths drawn from
    /// its smoothed states given `u`, `y` and the frames it has.
    pub frames: &'a [Vec<StateFrame>],
}

impl VectorLatentRun<'_> {
    /// Whether every state component has at least one frame.
    fn measured(&self) -> bool {
        self.frames.len() == self.seq.dims.states && self.frames.iter().all(|f| !f.is_empty())
    }

    /// The mask of measured values, `T x dx` (the grid sample next to each frame).
    fn mask(&self) -> Vec<bool> {
        let t = self.seq.len();
        let dx = self.seq.dims.states;
        let mut mask = vec![false; t * dx];
        for (i, frames) in self.frames.iter().enumerate().take(dx) {
            for (k, seen) in observed_mask(frames, t).into_iter().enumerate() {
                if let Some(m) = mask.get_mut(k * dx + i) {
                    *m = seen;
                }
            }
        }
        mask
    }
}

/// The default mode's held-out score of a vector model: its NLPD and the mean of the
/// components' nRMSE (the last configuration kept); `None` untuned.
fn held_out(model: &VectorModel) -> Option<(f64, f64)> {
    let row = model.summary().validation.iter().rfind(|r| r.chosen)?;
    let nrmse = row.nrmse.iter().sum::<f64>() / row.nrmse.len().max(1) as f64;
    (row.nlpd.is_finite() && nrmse.is_finite()).then_some((row.nlpd, nrmse))
}

impl VectorModel {
    /// [`VectorModel::fit_with_sensors`] for trajectories whose state is NaN where it was not
    /// measured (a slow or dropping camera; a component may be missing alone):
    /// [`VectorModel::fit_latent`] over the measured values ([`PartialState::from_gaps`], per
    /// component) when some are missing, the plain fit otherwise. A trajectory whose state is
    /// NaN throughout (only `u` and `y` were logged) joins from EM's first refit; when no
    /// trajectory has every component measured somewhere, the error is
    /// [`DataError::NoStateMeasured`].
    pub fn fit_partial(
        trajectories: &[VectorSequence<'_>],
        params: &CheckedHbnParams,
        names: SignalNames,
        sensors: &[SensorInputs],
    ) -> Result<Self, ModelError> {
        refuse_infinite_states(trajectories.iter().map(|t| t.x))?;
        if trajectories
            .iter()
            .all(|t| t.x.iter().all(|v| v.is_finite()))
        {
            return Self::fit_with_sensors(trajectories, params, names, sensors);
        }
        // Per run: the state interpolated component by component, and each one's frames.
        let parts: Vec<(Vec<f64>, Vec<Vec<StateFrame>>)> = trajectories
            .iter()
            .map(|t| {
                let dx = t.dims.states.max(1);
                let n = t.x.len() / dx;
                let mut x = vec![0.0; t.x.len()];
                let mut frames = Vec::with_capacity(dx);
                for i in 0..dx {
                    let column: Vec<f64> = t.x.iter().skip(i).step_by(dx).copied().collect();
                    let p = PartialState::from_gaps(&column)
                        .unwrap_or_else(|| PartialState::unmeasured(n));
                    for (k, v) in p.interpolated.iter().enumerate() {
                        if let Some(slot) = x.get_mut(k * dx + i) {
                            *slot = *v;
                        }
                    }
                    frames.push(p.frames);
                }
                (x, frames)
            })
            .collect();
        let runs: Vec<VectorLatentRun<'_>> = trajectories
            .iter()
            .zip(&parts)
            .map(|(t, (x, frames))| VectorLatentRun {
                seq: VectorSequence::new(t.u, x, t.y, t.dims),
                frames,
            })
            .collect();
        Self::fit_latent(&runs, params, names, sensors)
    }

    /// Learns every GP from runs whose state was measured only at some samples
    /// ([`VectorLatentRun`]), by expectation-maximisation ([`crate::vector_latent`]): a first fit
    /// on the runs with every component measured (the state interpolated between the frames,
    /// held-out scores at the measured values), then rounds of smoothing and refitting kept
    /// while the held-out score improves, within [`crate::latent::TIME_BUDGET`] times the first
    /// fit's time. The model returned is the best round's; [`crate::VectorSummary::latent`]
    /// records the rounds. `sensors` as in [`VectorModel::fit_with_sensors`].
    pub fn fit_latent(
        runs: &[VectorLatentRun<'_>],
        params: &CheckedHbnParams,
        names: SignalNames,
        sensors: &[SensorInputs],
    ) -> Result<Self, ModelError> {
        let t0 = Instant::now();
        let masks: Vec<Vec<bool>> = runs.iter().map(VectorLatentRun::mask).collect();
        let runs: Vec<VectorLatentRun<'_>> = runs
            .iter()
            .zip(&masks)
            .map(|(r, m)| VectorLatentRun {
                seq: r.seq.with_observed(m),
                ..*r
            })
            .collect();
        // The first fit learns from the runs with every component measured; the others join
        // the refits.
        let measured: Vec<VectorSequence<'_>> = runs
            .iter()
            .filter(|r| r.measured())
            .map(|r| r.seq)
            .collect();
        if measured.is_empty() {
            return Err(DataError::NoStateMeasured.into());
        }
        let best = Self::fit_with_sensors(&measured, params, names.clone(), sensors)?;
        let first_s = t0.elapsed().as_secs_f64();
        let values: usize = masks.iter().map(Vec::len).sum();
        let seen: usize = masks.iter().flatten().filter(|m| **m).count();
        let mut report = LatentReport {
            observed: seen as f64 / values.max(1) as f64,
            // A camera's frame measures every component: the most frames of a component.
            frames: runs
                .iter()
                .map(|r| r.frames.iter().map(Vec::len).max().unwrap_or(0))
                .sum(),
            rounds: Vec::new(),
            unmeasured_runs: runs.len() - measured.len(),
        };
        // The sensor inputs the first fit chose, kept by every refit.
        let chosen: Vec<SensorInputs> = (0..best.dims().sensors)
            .map(|j| match best.sensor_reads_output(j) {
                Some(false) => SensorInputs::State,
                _ => SensorInputs::Thesis,
            })
            .collect();
        // The lag set and inducing setting the first fit chose (its parameters hold them
        // alone), kept by every refit, and the table of the candidates, kept in the summary.
        let refit = best.params().clone().check()?;
        let candidate_rows = best.summary().candidates.clone();
        let frame_var: Vec<f64> = best
            .stats()
            .1
            .iter()
            .map(|s| frame_variance(s.span()))
            .collect();
        let mut best = em_rounds(
            best,
            t0,
            first_s,
            held_out,
            |best, round| {
                let mut rng = round_rng(params.seed, round);
                let mut normal = || rng.normal();
                let paths: Vec<Vec<f64>> = runs
                    .iter()
                    .map(|r| {
                        let frames = Frames {
                            of: r.frames,
                            var: &frame_var,
                        };
                        let (_, path) = best.smooth_frames(
                            r.seq.u,
                            r.seq.y,
                            best.default_mode(),
                            &frames,
                            Some(&mut normal),
                        )?;
                        path.ok_or(ModelError::Core(hbn_core::CoreError::InvalidSpec(
                            "the smoother drew no path",
                        )))
                    })
                    .collect::<Result<_, _>>()?;
                // The measured values stay as the first fit had them: the held-out scores of
                // every round compare the filter with the same references (a path drawn between
                // two grid samples pins only their mix, not the sample the mask marks).
                let paths: Vec<Vec<f64>> = runs
                    .iter()
                    .zip(paths)
                    .map(|(r, mut path)| {
                        let measured = r.seq.observed.unwrap_or(&[]).iter().zip(r.seq.x);
                        for (p, (seen, x)) in path.iter_mut().zip(measured) {
                            if *seen {
                                *p = *x;
                            }
                        }
                        path
                    })
                    .collect();
                let seqs: Vec<VectorSequence<'_>> = runs
                    .iter()
                    .zip(&paths)
                    .map(|(r, x)| VectorSequence { x, ..r.seq })
                    .collect();
                Self::fit_one(&seqs, &refit, names.clone(), &chosen, None)
            },
            &mut report,
        )?;
        let warning = latent_warning(&report);
        let summary = best.summary_mut();
        summary.warnings.push(warning);
        if summary.candidates.is_empty() {
            summary.candidates = candidate_rows;
        }
        summary.latent = Some(report);
        summary.seconds = t0.elapsed().as_secs_f64();
        Ok(best)
    }
}
