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
use crate::{HysteresisModel, ModelError};
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
    /// Scales of the unscented filter (scale 1 when the file has none).
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

/// Which data were held out for tuning: blocked cross-validation over time. Each run is cut
/// into blocks of `fraction` of its length from its end; fold `j` holds out block `j` of every
/// run and refits the GPs on the rest, so that every held-out input is unseen by the GPs that
/// predict it, even when every run repeats the same input schedule (holding out whole runs would
/// then validate on inputs the GPs were trained on). Fold 0 is the end of every run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Holdout {
    /// First held-out sample of each run in fold 0 (the end of the run).
    pub from: Vec<usize>,
    /// Samples held out in all folds together.
    pub held_out: usize,
    /// Samples in all.
    pub samples: usize,
    /// Folds (1 when the file gives none: the end of every run).
    #[serde(default = "one_fold")]
    pub folds: usize,
}

fn one_fold() -> usize {
    1
}

impl std::fmt::Display for Holdout {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let runs = self.from.len();
        let s = if runs == 1 { "" } else { "s" };
        if self.folds <= 1 {
            write!(
                f,
                "the last {} of {} samples held out, the end of each of {runs} run{s}",
                self.held_out, self.samples,
            )
        } else {
            write!(
                f,
                "{} folds: {} of {} samples held out in turn, a block of each of {runs} run{s} per fold",
                self.folds, self.held_out, self.samples,
            )
        }
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
    /// Held-out samples the table's scores, the `std` scales and the default mode were
    /// computed on (after the cap, [`MAX_CALIBRATION_SAMPLES`]).
    pub samples: usize,
    /// Held-out samples the search for the `q` and `r` scales ran on (after the cap,
    /// [`MAX_VALIDATION_SAMPLES`]): all of `samples` when there are few, a subset otherwise.
    #[serde(default)]
    pub searched: usize,
    /// One row per mode.
    pub rows: Vec<ValidationRow>,
    /// The mode chosen as the default (lowest tuned NLPD).
    pub default_mode: Mode,
    /// Model selection ([`crate::Selection`]): one row per candidate trained, in the order
    /// trained; empty when there was one configuration.
    #[serde(default)]
    pub candidates: Vec<CandidateRow>,
}

/// One candidate of model selection and its held-out scores.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CandidateRow {
    /// The configuration.
    pub candidate: crate::Candidate,
    /// Its default mode and that mode's tuned held-out scores; `None` when it could not be
    /// scored (see `note`).
    pub scored: Option<(Mode, HeldOutScores)>,
    /// Seconds its training and tuning took. Not saved (like
    /// [`crate::TrainingSummary::seconds`]), so that a model file depends only on its data and
    /// parameters: 0 in a loaded model.
    #[serde(skip)]
    pub seconds: f64,
    /// Why it has no score (a training error, or the filter failing on the held-out data).
    #[serde(default)]
    pub note: Option<String>,
    /// The candidate chosen: the lowest held-out NLPD among the candidates whose held-out
    /// nRMSE is no higher than the first's, leaving out those that lost the state on their
    /// own training runs (`lost`) when another did not.
    pub chosen: bool,
    /// Times its filter, in its default mode, lost the state (flag `relocalised`) when run
    /// over the runs it was trained on, after tuning; 0 when not scored.
    #[serde(default)]
    pub lost: usize,
}

/// Held-out samples the search runs the filter over at most, all folds together (a prefix of
/// each held-out block, in proportion): bounds the cost of tuning on long logs. On the README's
/// demo (3 x 1000 samples, 4 folds) 750 give the scales about the coverage on the test log
/// that 1000 and 1500 give, at half the cost.
pub const MAX_VALIDATION_SAMPLES: usize = 750;
/// Held-out samples at most that the learned `(q, r)` of each mode are run over once more to
/// set the `std` scale, the held-out table's scores and the default mode (all folds together,
/// spread over the runs, whole blocks or pieces of them). The search of `(q, r)` makes dozens
/// of filter runs and keeps to [`MAX_VALIDATION_SAMPLES`]; these two runs per mode can afford
/// more: on long logs the filter's error varies by several times from one stretch of 500
/// samples to the next, and `std` scales set on the search's 750 samples alone miscalibrate
/// the band on fresh logs.
pub const MAX_CALIBRATION_SAMPLES: usize = 4000;
/// Shortest piece of a held-out block that [`spread`] scores, where the cap forces pieces.
const MIN_SPREAD_PIECE: usize = 200;
/// Fewest samples a held-out block (one run) or the training part may have for tuning.
pub const MIN_TUNING_SAMPLES: usize = 50;

/// Folds of blocked cross-validation at most: with the default `validation = 0.25`, every
/// quarter of every run is held out once, so the noise scales are learned on every part of the
/// input, not on the one segment at the runs' ends (measured on the README's demo, where the
/// runs repeat one input: the end alone gave a band that held 89% of a fresh run's truth).
pub const MAX_FOLDS: usize = 4;

/// Samples of a run before a held-out block that the filter runs over unscored (fewer where the
/// block starts earlier): the block is scored from the filter's running state, as most of a
/// long log is, not from a cold start; cold starts on short blocks would make the learned scales
/// fit start-up transients.
pub const BURN_IN: usize = 20;

/// A held-out block: what the filter runs over (up to [`BURN_IN`] samples of the run before
/// the block, then the block) and how many of those lead in unscored.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Block<'a> {
    pub seq: Sequence<'a>,
    pub burn_in: usize,
}

impl<'a> Block<'a> {
    /// Samples scored.
    fn scored(&self) -> usize {
        self.seq.u.len().saturating_sub(self.burn_in)
    }

    /// The block cut to its first `keep` scored samples.
    fn prefix(&self, keep: usize) -> Self {
        let end = (self.burn_in + keep).min(self.seq.u.len());
        let s = &self.seq;
        Self {
            seq: s.slice(0, end),
            burn_in: self.burn_in,
        }
    }
}

/// One fold: the runs without one block each (a run may leave two pieces), and the blocks.
pub(crate) struct Fold<'a> {
    pub train: Vec<Sequence<'a>>,
    pub validation: Vec<Block<'a>>,
}

/// The folds of filter-aware training, and what they hold out.
pub(crate) struct Split<'a> {
    pub folds: Vec<Fold<'a>>,
    pub holdout: Holdout,
}

/// Splits the runs for tuning: `floor(1 / fraction)` folds (at most [`MAX_FOLDS`]); fold `j`
/// holds out the block `[1 - (j + 1) fraction, 1 - j fraction)` of every run (pieces shorter
/// than 3 samples contribute to neither side). A fold whose held-out or training part has fewer
/// than [`MIN_TUNING_SAMPLES`] samples is dropped; `None` when `fraction` is 0 or fold 0 (the
/// end of every run) is dropped.
pub(crate) fn split<'a>(runs: &[Sequence<'a>], fraction: f64) -> Option<Split<'a>> {
    if !(fraction > 0.0 && fraction < 1.0) {
        return None;
    }
    let n_folds = ((1.0 / fraction + 1e-9).floor() as usize).clamp(1, MAX_FOLDS);
    let samples: usize = runs.iter().map(|s| s.u.len()).sum();
    let mut folds = Vec::new();
    let mut from_last = Vec::new();
    for j in 0..n_folds {
        let (mut train, mut validation) = (Vec::new(), Vec::new());
        for r in runs {
            let len = r.u.len().min(r.x.len()).min(r.y.len());
            let at = |q: f64| ((q * len as f64).floor().max(0.0) as usize).min(len);
            let from = at(1.0 - (j + 1) as f64 * fraction);
            let to = if j == 0 {
                len
            } else {
                at(1.0 - j as f64 * fraction)
            };
            let part = |a: usize, b: usize| r.slice(a, b);
            if from >= 3 {
                train.push(part(0, from));
            }
            if len - to >= 3 {
                train.push(part(to, len));
            }
            if to - from >= 3 {
                let burn_in = from.min(BURN_IN);
                validation.push(Block {
                    seq: part(from - burn_in, to),
                    burn_in,
                });
            }
            if j == 0 {
                from_last.push(from);
            }
        }
        let held_out: usize = validation.iter().map(Block::scored).sum();
        let trained: usize = train.iter().map(|s| s.u.len()).sum();
        if held_out >= MIN_TUNING_SAMPLES && trained >= MIN_TUNING_SAMPLES {
            folds.push(Fold { train, validation });
        } else if j == 0 {
            return None;
        }
    }
    let held_out = folds
        .iter()
        .flat_map(|f| &f.validation)
        .map(Block::scored)
        .sum();
    Some(Split {
        holdout: Holdout {
            from: from_last,
            held_out,
            samples,
            folds: folds.len(),
        },
        folds,
    })
}

/// A fold's model (its GPs fitted on the fold's training part) and the held-out blocks it is
/// scored on.
pub(crate) struct Trial<'a> {
    pub model: HysteresisModel,
    pub blocks: Vec<Block<'a>>,
}

/// A fold's model and the held-out blocks (or pieces of them) it is scored on.
struct Scored<'t, 'a> {
    model: &'t HysteresisModel,
    blocks: Vec<Block<'a>>,
}

/// Pairs every fold's model with its blocks in `blocks` (one list per fold, in order).
fn scored<'t, 'a>(trials: &'t [Trial<'a>], blocks: Vec<Vec<Block<'a>>>) -> Vec<Scored<'t, 'a>> {
    trials
        .iter()
        .zip(blocks)
        .map(|(t, blocks)| Scored {
            model: &t.model,
            blocks,
        })
        .collect()
}

/// Shortest piece of a block worth scoring when the cap cuts it.
const MIN_PIECE: usize = 25;

/// The held-out blocks of every fold under a cap of `cap` scored samples: each fold gets an
/// equal share, filled with whole blocks (fold `j` starting at run `j`, so that the folds score
/// different runs where the runs repeat one input) and the last one cut to fit (dropped if
/// under [`MIN_PIECE`] samples). Whole blocks, not a short prefix of every block: with many
/// runs, prefixes of 19 samples made the scales fit start-up transients.
fn capped<'a>(folds: &[Vec<Block<'a>>], cap: usize) -> Vec<Vec<Block<'a>>> {
    share_out(folds, cap, false)
}

/// The held-out blocks of every fold under a cap of `cap` scored samples, spread over the
/// runs: each fold gets an equal share, divided evenly among as many of its blocks as give
/// pieces of at least [`MIN_SPREAD_PIECE`] samples (fold `j` starting at run `j`), a prefix of
/// each; a block shorter than its piece leaves the rest to the next ones. [`capped`] fills
/// whole blocks instead, which on long runs scores one stretch per fold.
fn spread<'a>(folds: &[Vec<Block<'a>>], cap: usize) -> Vec<Vec<Block<'a>>> {
    share_out(folds, cap, true)
}

/// [`capped`] (`even` false: each block taken whole while the share lasts) and [`spread`]
/// (`even` true: the share divided among the pieces).
fn share_out<'a>(folds: &[Vec<Block<'a>>], cap: usize, even: bool) -> Vec<Vec<Block<'a>>> {
    let total: usize = folds.iter().flatten().map(Block::scored).sum();
    if total <= cap {
        return folds.to_vec();
    }
    let share = cap / folds.len().max(1);
    folds
        .iter()
        .enumerate()
        .map(|(j, blocks)| {
            let pieces = if even {
                (share / MIN_SPREAD_PIECE).clamp(1, blocks.len().max(1))
            } else {
                blocks.len()
            };
            let mut out = Vec::new();
            let mut left = share;
            for i in 0..blocks.len() {
                if out.len() == pieces || left == 0 {
                    break;
                }
                let b = blocks[(i + j) % blocks.len()];
                let piece = if even {
                    left.div_ceil(pieces - out.len())
                } else {
                    left
                };
                let keep = b.scored().min(piece);
                if keep < MIN_PIECE.min(b.scored()) {
                    continue;
                }
                out.push(b.prefix(keep));
                left -= keep;
            }
            out
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

/// What one filter run of every fold leaves to score: the scored samples of every held-out
/// block in order (estimate, its standard deviation at `std` scale 1, recorded state).
#[derive(Clone, Debug, Default)]
struct Run {
    x: Vec<f64>,
    sd: Vec<f64>,
    reference: Vec<f64>,
}

impl Run {
    /// Runs every fold's filter in `mode` over its held-out blocks with the scales `(q, r)`
    /// (`std` scale 1).
    fn of(trials: &[Scored<'_, '_>], mode: Mode, q: f64, r: f64) -> Result<Self, ModelError> {
        let mut out = Self::default();
        for t in trials {
            let mut config = t.model.untuned_config(mode);
            config.q_scale = q;
            config.r_scale = r;
            for b in &t.blocks {
                let s = &b.seq;
                let est = t.model.estimate_with(s.u, s.y, &config)?;
                let k = b
                    .burn_in
                    .min(est.x.len())
                    .min(est.x_std.len())
                    .min(s.x.len());
                out.x.extend_from_slice(&est.x[k..]);
                out.sd.extend_from_slice(&est.x_std[k..]);
                // Only measured states are scored: elsewhere the recorded state is a stand-in.
                out.reference.extend(
                    s.x.iter()
                        .enumerate()
                        .skip(k)
                        .map(|(i, &x)| if s.is_observed(i) { x } else { f64::NAN }),
                );
            }
        }
        Ok(out)
    }

    /// What the profile objective needs, over the samples with a finite estimate, a finite
    /// positive standard deviation and a finite recorded state.
    fn sums(&self) -> Sums {
        let mut out = Sums::default();
        for ((&xh, &sd), &xr) in self.x.iter().zip(&self.sd).zip(&self.reference) {
            if !(xh.is_finite() && sd.is_finite() && sd > 0.0 && xr.is_finite()) {
                continue;
            }
            let var = sd * sd;
            out.n += 1;
            out.log_var += var.ln();
            out.nees += (xr - xh) * (xr - xh) / var;
        }
        out
    }

    /// Held-out scores with the reported standard deviation scaled by `std` (exactly what a
    /// filter with `std_scale = std` reports: it multiplies the same `sqrt(P_11)`).
    fn scores(&self, std: f64) -> HeldOutScores {
        let sd: Vec<f64> = self.sd.iter().map(|s| std * s).collect();
        HeldOutScores {
            nrmse: nrmse(&self.x, &self.reference),
            calibration: calibration(&self.x, &sd, &self.reference),
        }
    }
}

/// A point of the search in lattice units of [`LATTICE`] decades of `q` and of `r`. Every
/// point the search can reach lies on the lattice, so a point met again is recognised exactly
/// and not run twice.
type Point = (i32, i32);

/// The search's lattice spacing in decades: the grid, every step and the bounds are multiples.
const LATTICE: f64 = 0.05;

/// The scales `(q, r)` at a lattice point.
fn scales_at((lq, lr): Point) -> (f64, f64) {
    let decades = |k: i32| f64::from(k) * LATTICE;
    (10f64.powf(decades(lq)), 10f64.powf(decades(lr)))
}

/// One evaluated point: the penalised profile objective and its best `std` scale (`None` when
/// a filter failed or scored nothing), and the run behind it.
type Evaluated = Option<(f64, f64, Run)>;

/// Runs the filter at `points` on up to `threads` threads; results in order.
fn evaluate_many(trials: &[Scored<'_, '_>], mode: Mode, points: &[Point]) -> Vec<Evaluated> {
    let eval = |&p: &Point| -> Evaluated {
        let (q, r) = scales_at(p);
        let run = Run::of(trials, mode, q, r).ok()?;
        let (j, s) = run.sums().profile()?;
        let (lq, lr) = (f64::from(p.0) * LATTICE, f64::from(p.1) * LATTICE);
        Some((j + SCALE_PENALTY * (lq * lq + lr * lr), s, run))
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
/// Filter runs per mode at most (the grid's 10, then the pattern search).
const MAX_EVALUATIONS: usize = 45;
/// Filter runs at most of a mode that starts from the first mode's optimum.
const MAX_EVALUATIONS_FROM_START: usize = 16;
/// Bounds of the search, in lattice units (-3 and 4 decades).
const LOG_MIN: i32 = -60;
const LOG_MAX: i32 = 80;
/// The first mode's grid, in lattice units (-1.5, 0.25 and 2 decades).
const GRID: [i32; 3] = [-30, 5, 40];
/// First steps of the pattern search in lattice units (0.8 decades; 0.4 from the first
/// mode's optimum), and the last (0.1 decades).
const FIRST_STEP: i32 = 16;
const FIRST_STEP_FROM_START: i32 = 8;
const LAST_STEP: i32 = 2;

/// What the search of one mode found.
struct Found<R> {
    /// The optimum in lattice units (where the next modes start).
    at: Point,
    /// Filter runs made (points met again are not run again).
    evaluations: usize,
    /// The run at the optimum, and at the untuned point (scales 1) when it ran.
    best: R,
    untuned: Option<R>,
}

/// Pattern search on the lattice for the lowest objective that `evaluate` returns (with the
/// best `std` scale and the run behind it; `None` for a failed run): a grid (or, with
/// `start`, only the untuned point and `start`), then a compass search from the best point,
/// its step halved when no neighbour improves, down to [`LAST_STEP`], within `budget` runs.
/// `evaluate` gets each batch of points at once (they may run in parallel) and is never asked
/// for a point twice: the search comes back to points it has left (the centre it moved
/// from), and those are looked up.
fn pattern_search<R>(
    start: Option<Point>,
    mut evaluate: impl FnMut(&[Point]) -> Vec<Option<(f64, f64, R)>>,
) -> Option<Found<R>> {
    let mut points: Vec<Point> = vec![(0, 0)];
    match start {
        Some(p) if p != (0, 0) => points.push(p),
        Some(_) => {}
        None => {
            for &lq in &GRID {
                for &lr in &GRID {
                    points.push((lq, lr));
                }
            }
        }
    }
    let mut seen: std::collections::HashMap<Point, Option<(f64, f64, R)>> =
        std::collections::HashMap::new();
    let mut best: Option<(Point, f64, f64)> = None;
    let mut take = |seen: &mut std::collections::HashMap<Point, Option<(f64, f64, R)>>,
                    batch: &[Point]| {
        for (&p, e) in batch.iter().zip(evaluate(batch)) {
            if let Some((j, s, _)) = &e
                && best.is_none_or(|b| *j < b.1)
            {
                best = Some((p, *j, *s));
            }
            seen.insert(p, e);
        }
        best
    };
    let mut evaluations = points.len();
    let mut current = take(&mut seen, &points);
    // From the first mode's optimum the search only refines: a smaller first step and budget.
    let (mut step, budget) = if start.is_some() {
        (FIRST_STEP_FROM_START, MAX_EVALUATIONS_FROM_START)
    } else {
        (FIRST_STEP, MAX_EVALUATIONS)
    };
    while step >= LAST_STEP && evaluations < budget {
        let ((lq, lr), j0, _) = current?;
        let mut new: Vec<Point> = Vec::new();
        for (dq, dr) in [(step, 0), (-step, 0), (0, step), (0, -step)] {
            let p = (
                (lq + dq).clamp(LOG_MIN, LOG_MAX),
                (lr + dr).clamp(LOG_MIN, LOG_MAX),
            );
            if p != (lq, lr) && !new.contains(&p) && !seen.contains_key(&p) {
                new.push(p);
            }
        }
        evaluations += new.len();
        current = take(&mut seen, &new);
        if current.is_some_and(|b| b.1 >= j0) {
            step /= 2;
        }
    }
    let (at, _, _) = current?;
    let mut run_at = |p: Point| seen.remove(&p).flatten().map(|(_, _, run)| run);
    let best = run_at(at)?;
    let untuned = run_at((0, 0));
    Some(Found {
        at,
        evaluations,
        best,
        untuned,
    })
}

/// Tunes every mode on the folds: `trials` pairs each fold's model (GPs refitted on the fold's
/// training part) with its held-out runs. The search of `(q, r)` runs on at most
/// [`MAX_VALIDATION_SAMPLES`] of them ([`capped`]); the `std` scale, the table's scores and
/// the default mode come from the learned `(q, r)` run over at most
/// [`MAX_CALIBRATION_SAMPLES`] ([`spread`]; the same samples when there are few). The scales
/// are common to all folds.
pub(crate) fn tune(
    trials: Vec<Trial<'_>>,
    holdout: &Holdout,
) -> Result<Option<(FilterTuning, ValidationReport)>, ModelError> {
    let blocks: Vec<Vec<Block<'_>>> = trials.iter().map(|t| t.blocks.clone()).collect();
    let count = |set: &[Scored<'_, '_>]| -> usize {
        set.iter().flat_map(|t| &t.blocks).map(Block::scored).sum()
    };
    let search = scored(&trials, capped(&blocks, MAX_VALIDATION_SAMPLES));
    let total: usize = blocks.iter().flatten().map(Block::scored).sum();
    // Under the search's cap both sets are every held-out sample: the search's runs serve.
    let wide = (total > MAX_VALIDATION_SAMPLES)
        .then(|| scored(&trials, spread(&blocks, MAX_CALIBRATION_SAMPLES)));
    let searched = count(&search);
    let samples = wide.as_deref().map_or(searched, count);
    let mut tuning = FilterTuning::default();
    let mut rows = Vec::new();
    let mut first_optimum: Option<Point> = None;
    for mode in Mode::ALL {
        let Some(found) =
            pattern_search(first_optimum, |points| evaluate_many(&search, mode, points))
        else {
            return Ok(None);
        };
        first_optimum.get_or_insert(found.at);
        let (at, best, untuned) = match &wide {
            // The learned and the untuned point on the wide set, side by side. The learned
            // point stands if it scores at least as well there (penalised, as in the search);
            // otherwise the identity does, so the table's score after tuning is never worse
            // than before on the samples it shows. Both failing is a failure to tune; the
            // untuned point alone failing runs again for its error.
            Some(wide) => {
                let points: &[Point] = if found.at == (0, 0) {
                    &[(0, 0)]
                } else {
                    &[found.at, (0, 0)]
                };
                let mut runs = evaluate_many(wide, mode, points).into_iter();
                let learned = runs.next().flatten();
                let identity = runs.next().flatten();
                match (learned, identity) {
                    (Some((j, _, best)), Some((j0, _, run))) if j <= j0 => {
                        (found.at, best, run.scores(1.0))
                    }
                    (_, Some((_, _, run))) => {
                        let untuned = run.scores(1.0);
                        ((0, 0), run, untuned)
                    }
                    (Some((_, _, best)), None) if found.at == (0, 0) => {
                        let untuned = best.scores(1.0);
                        (found.at, best, untuned)
                    }
                    (Some((_, _, best)), None) => {
                        let untuned = Run::of(wide, mode, 1.0, 1.0)?.scores(1.0);
                        (found.at, best, untuned)
                    }
                    (None, None) => return Ok(None),
                }
            }
            // The untuned point is the optimum, or failed in the search: run it again (for
            // the error it gives, if it fails).
            None => {
                let untuned = match &found.untuned {
                    Some(run) => run.scores(1.0),
                    None if found.at == (0, 0) => found.best.scores(1.0),
                    None => Run::of(&search, mode, 1.0, 1.0)?.scores(1.0),
                };
                (found.at, found.best, untuned)
            }
        };
        let (q, r) = scales_at(at);
        let Some((_, std)) = best.sums().profile() else {
            return Ok(None);
        };
        let scales = NoiseScales { q, r, std };
        let tuned = best.scores(scales.std);
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
            evaluations: found.evaluations,
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
            holdout: holdout.clone(),
            samples,
            searched,
            rows,
            default_mode,
            candidates: Vec::new(),
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
    fn every_block_of_every_run_is_held_out_once() {
        let (u, x, y) = seq(400);
        let (mut u2, x2, y2) = seq(100);
        u2.iter_mut().for_each(|v| *v += 1000.0); // tells the runs' samples apart
        let runs = [Sequence::new(&u, &x, &y), Sequence::new(&u2, &x2, &y2)];
        let s = split(&runs, 0.25).unwrap();
        assert_eq!(
            s.holdout,
            Holdout {
                from: vec![300, 75],
                held_out: 500,
                samples: 500,
                folds: 4,
            }
        );
        // Fold 0: the end of every run, led in by the samples before it; the training part is
        // what precedes it.
        let f0 = &s.folds[0];
        assert_eq!((f0.train[0].u.len(), f0.train[1].u.len()), (300, 75));
        let b = f0.validation[0];
        assert_eq!((b.burn_in, b.seq.u.len()), (BURN_IN, 100 + BURN_IN));
        assert_eq!(b.seq.x[b.burn_in], 300.0);
        assert_eq!(f0.validation[1].seq.u[BURN_IN], 1075.0);
        // Fold 1: the block before; the training part is both sides of it.
        let f1 = &s.folds[1];
        let starts: Vec<f64> = f1.train.iter().map(|t| t.u[0]).collect();
        assert_eq!(starts, vec![0.0, 300.0, 1000.0, 1075.0]);
        assert_eq!(f1.validation[0].seq.u[BURN_IN], 200.0);
        assert_eq!(f1.validation[0].scored(), 100);
        // Fold 3: the start of every run (no samples before it to lead in); training is what
        // follows it.
        let f3 = &s.folds[3];
        assert_eq!(f3.validation[0].burn_in, 0);
        assert_eq!(f3.validation[0].seq.u, &u[..100]);
        assert_eq!(f3.train[0].u, &u[100..]);
        // Every sample of every run is scored exactly once, and never trained on in its fold.
        let mut count = vec![0; 400];
        for f in &s.folds {
            for b in f.validation.iter().filter(|b| b.scored() > 30) {
                for &t in &b.seq.u[b.burn_in..] {
                    count[t as usize] += 1;
                    assert!(f.train.iter().all(|tr| !tr.u.contains(&t)));
                }
            }
        }
        assert!(count.iter().all(|&c| c == 1));
        // One run works the same way; half held out gives two folds; too little data or no
        // fraction: no split.
        assert_eq!(split(&runs[..1], 0.25).unwrap().holdout.held_out, 400);
        assert_eq!(split(&runs, 0.5).unwrap().folds.len(), 2);
        assert_eq!(split(&runs, 0.1).unwrap().folds.len(), MAX_FOLDS);
        let (u, x, y) = seq(150);
        assert!(split(&[Sequence::new(&u, &x, &y)], 0.25).is_none());
        assert!(split(&runs, 0.0).is_none());
    }

    #[test]
    fn the_cap_keeps_whole_blocks_an_equal_share_per_fold() {
        let (u, x, y) = seq(1000);
        let block = |from: usize, len: usize, burn_in: usize| Block {
            seq: Sequence::new(
                &u[from - burn_in..from + len],
                &x[from - burn_in..from + len],
                &y[from - burn_in..from + len],
            ),
            burn_in,
        };
        // Two folds of three 100-sample blocks each (one per run); a cap of 300 gives each
        // fold 150: one whole block and half of the next, fold j starting at block j.
        let folds = vec![
            vec![
                block(100, 100, 20),
                block(300, 100, 20),
                block(500, 100, 20),
            ],
            vec![block(0, 100, 0), block(200, 100, 20), block(400, 100, 20)],
        ];
        let c = capped(&folds, 300);
        let firsts = |f: &Vec<Block<'_>>| -> Vec<(f64, usize)> {
            f.iter().map(|b| (b.seq.u[b.burn_in], b.scored())).collect()
        };
        assert_eq!(firsts(&c[0]), vec![(100.0, 100), (300.0, 50)]);
        assert_eq!(firsts(&c[1]), vec![(200.0, 100), (400.0, 50)]);
        // A share that would leave a piece under MIN_PIECE drops it.
        let c = capped(&folds, 2 * (100 + MIN_PIECE - 1));
        assert_eq!(c[0].len(), 1);
        // Under the cap, everything is kept.
        assert_eq!(capped(&folds, 600)[1].len(), 3);
    }

    #[test]
    fn the_wide_cap_spreads_pieces_over_every_run() {
        let (u, x, y) = seq(20_000);
        let block = |from: usize, len: usize| Block {
            seq: Sequence::new(
                &u[from - BURN_IN..from + len],
                &x[from - BURN_IN..from + len],
                &y[from - BURN_IN..from + len],
            ),
            burn_in: BURN_IN,
        };
        // Two folds of five 1000-sample blocks (one per run), one with a short block.
        let folds = vec![
            (0..5).map(|r| block(100 + 2000 * r, 1000)).collect(),
            vec![
                block(1100, 1000),
                block(3100, 100),
                block(5100, 1000),
                block(7100, 1000),
                block(9100, 1000),
            ],
        ];
        let firsts = |f: &Vec<Block<'_>>| -> Vec<(f64, usize)> {
            f.iter().map(|b| (b.seq.u[b.burn_in], b.scored())).collect()
        };
        // A share of 1000 per fold: five pieces of 200, one per run, fold j from run j; the
        // short block gives its 100 and the pieces after it share the rest.
        let c = spread(&folds, 2000);
        assert_eq!(
            firsts(&c[0]),
            vec![
                (100.0, 200),
                (2100.0, 200),
                (4100.0, 200),
                (6100.0, 200),
                (8100.0, 200)
            ]
        );
        assert_eq!(
            firsts(&c[1]),
            vec![
                (3100.0, 100),
                (5100.0, 225),
                (7100.0, 225),
                (9100.0, 225),
                (1100.0, 225)
            ]
        );
        // A smaller share: fewer pieces, none under MIN_SPREAD_PIECE.
        let c = spread(&folds, 2 * 450);
        assert_eq!(firsts(&c[0]), vec![(100.0, 225), (2100.0, 225)]);
        // Under the cap, every block whole; `capped` at the same cap fills whole blocks.
        let all: Vec<_> = folds.iter().map(firsts).collect();
        assert_eq!(
            spread(&folds, 10_000)
                .iter()
                .map(firsts)
                .collect::<Vec<_>>(),
            all
        );
        assert_eq!(firsts(&capped(&folds, 2000)[0]), vec![(100.0, 1000)]);
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

    /// Runs the pattern search on `objective` and returns what it found and every batch it
    /// asked for.
    fn searched(
        start: Option<Point>,
        objective: impl Fn(Point) -> Option<f64>,
    ) -> (Option<Found<Point>>, Vec<Vec<Point>>) {
        let mut batches = Vec::new();
        let found = pattern_search(start, |points| {
            batches.push(points.to_vec());
            points
                .iter()
                .map(|&p| objective(p).map(|j| (j, 1.0, p)))
                .collect()
        });
        (found, batches)
    }

    #[test]
    fn the_search_finds_a_bowls_floor_and_runs_no_point_twice() {
        let floor = (13, -7);
        let bowl = |(q, r): Point| {
            Some(f64::from((q - floor.0).pow(2)) + 0.5 * f64::from((r - floor.1).pow(2)))
        };
        let (found, batches) = searched(None, bowl);
        let found = found.expect("found");
        // The compass search ends where no neighbour at the last step (2 units) is lower:
        // within one unit of the floor in each direction.
        assert!(
            (found.at.0 - floor.0).abs() <= 1 && (found.at.1 - floor.1).abs() <= 1,
            "{:?}",
            found.at
        );
        assert_eq!(found.best, found.at, "the run returned is the optimum's");
        assert_eq!(found.untuned, Some((0, 0)));
        let all: Vec<Point> = batches.concat();
        let mut distinct = all.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), all.len(), "a point ran twice: {all:?}");
        assert_eq!(found.evaluations, all.len());
        assert!(found.evaluations <= MAX_EVALUATIONS + 3);
        // The grid comes first, in one batch.
        assert_eq!(batches[0].len(), 10);
    }

    #[test]
    fn from_a_start_the_search_only_refines_and_failed_points_never_win() {
        // Every point with q above 1 fails (as a filter that diverges would); the untuned
        // point fails too.
        let objective = |(q, r): Point| {
            (q <= 20 && (q, r) != (0, 0)).then(|| f64::from((q - 30).pow(2) + (r - 8).pow(2)))
        };
        let (found, batches) = searched(Some((16, 8)), objective);
        let found = found.expect("found");
        assert_eq!(batches[0], vec![(0, 0), (16, 8)]);
        // The first ring is 8 units (0.4 decades) from the start.
        assert!(batches[1].contains(&(24, 8)) && batches[1].contains(&(16, 0)));
        // The best point that did not fail: q as high as allowed.
        assert_eq!(found.at, (20, 8));
        assert_eq!(found.untuned, None, "the untuned point failed");
        assert!(found.evaluations <= MAX_EVALUATIONS_FROM_START + 3);
        // Nothing runs at all: nothing found.
        assert!(searched(None, |_| None).0.is_none());
    }

    #[test]
    fn lattice_points_are_the_decades_they_name() {
        assert_eq!(scales_at((0, 0)), (1.0, 1.0));
        let (q, r) = scales_at((GRID[0], GRID[2]));
        assert!((q.log10() + 1.5).abs() < 1e-12 && (r.log10() - 2.0).abs() < 1e-12);
        assert!((f64::from(LAST_STEP) * LATTICE - 0.1).abs() < 1e-12);
        assert!((f64::from(LOG_MIN) * LATTICE + 3.0).abs() < 1e-12);
    }

    #[test]
    fn only_measured_states_are_scored_held_out() {
        // The mask follows every cut of the split and of the cap.
        let (u, x, y) = seq(400);
        let observed: Vec<bool> = (0..400).map(|k: usize| k.is_multiple_of(3)).collect();
        let runs = [Sequence::new(&u, &x, &y).with_observed(&observed)];
        let s = split(&runs, 0.25).unwrap();
        for f in &s.folds {
            for part in f.train.iter().chain(f.validation.iter().map(|b| &b.seq)) {
                let o = part.observed.expect("the mask is kept");
                assert_eq!(o.len(), part.u.len());
                for (k, &t) in part.u.iter().enumerate() {
                    assert_eq!(o[k], (t as usize).is_multiple_of(3));
                }
            }
            let b = f.validation[0].prefix(40);
            assert_eq!(b.seq.observed.unwrap().len(), b.seq.u.len());
        }
        // The filter's run scores the measured samples and leaves the others out.
        let cfg = hbn_sim::SimConfig {
            noise_gain: 1.0,
            ..hbn_sim::SimConfig::new(hbn_sim::SystemKind::Duhem)
        };
        let t = hbn_sim::simulate_random(&cfg, 300).unwrap();
        let params = crate::HbnParams {
            max_points: 80,
            n_starts: 1,
            validation: 0.0,
            ..crate::HbnParams::default()
        };
        let model = HysteresisModel::fit(&[Sequence::new(&t.u, &t.x, &t.y)], &params).unwrap();
        let observed: Vec<bool> = (0..300).map(|k| k % 4 == 1).collect();
        // The state between the measurements is garbage: it must not count.
        let garbage: Vec<f64> =
            t.x.iter()
                .zip(&observed)
                .map(|(&x, &o)| if o { x } else { x + 100.0 })
                .collect();
        let run = |seq: Sequence<'_>| {
            let trials = [Scored {
                model: &model,
                blocks: vec![Block { seq, burn_in: 20 }],
            }];
            Run::of(&trials, Mode::Ekf, 1.0, 1.0).unwrap()
        };
        let masked = run(Sequence::new(&t.u, &garbage, &t.y).with_observed(&observed));
        let clean = run(Sequence::new(&t.u, &t.x, &t.y));
        assert_eq!(masked.x, clean.x);
        let scored: Vec<usize> = (20..300).filter(|k| observed[*k]).collect();
        assert_eq!(masked.sums().n, scored.len());
        for (i, k) in (20..300).enumerate() {
            if observed[k] {
                assert_eq!(masked.reference[i], t.x[k]);
            } else {
                assert!(masked.reference[i].is_nan());
            }
        }
        // Over the measured samples the scores are those of the clean state there.
        let clean_measured = Run {
            reference: clean
                .reference
                .iter()
                .enumerate()
                .map(|(i, &r)| if observed[i + 20] { r } else { f64::NAN })
                .collect(),
            ..clean.clone()
        };
        assert_eq!(masked.scores(1.0), clean_measured.scores(1.0));
    }
}
