//! Training from a slow, dropping camera: for every system x noise gain x seed, the protocol's
//! training set (`hbn_pipeline::experiment`: one random-ramp input repeated with fresh noise,
//! u and y at 100 Hz) with the state seen by a camera at `RATE` Hz that drops a fraction `DROP`
//! of its frames (each frame the true state at its own time, linearly interpolated between the
//! simulator's samples). Three default models, each scored in its default mode on a fresh
//! 100 Hz test log against the true state at every sample:
//! - `full`: the state at every sample (the camera at the grid's rate);
//! - `interpolated`: the state interpolated between the frames, as if measured
//!   ([`HysteresisModel::fit_checked`], held-out scores at the frames only);
//! - `em`: expectation-maximisation over the latent samples ([`HysteresisModel::fit_latent`]).
//!
//! One JSON object per line, then per camera the geometric mean over cells of each model's
//! nRMSE over `full`'s and the training time ratio.
//!
//! ```text
//! camera_eval --systems bouc-wen,duhem,preisach --gains 0,1,10 --seeds 1,2,3 --cameras 30:0.1,10
//! ```
use hbn_harness::parse;
use std::time::Instant;

use clap::Parser;
use hbn_core::rng::Rng;
use hbn_model::metrics::{calibration, nrmse};
use hbn_model::{HbnParams, HysteresisModel, LatentRun, Sequence, StateFrame, observed_mask};
use hbn_pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn_sim::SystemKind;

/// Slow-camera training against full-rate training, one JSON line per case.
#[derive(Parser)]
struct Args {
    /// Simulators (comma-separated).
    #[arg(long, value_delimiter = ',', required = true, value_parser = parse::<SystemKind>)]
    systems: Vec<SystemKind>,
    /// Noise gains (comma-separated).
    #[arg(long, value_delimiter = ',', required = true)]
    gains: Vec<f64>,
    /// Seeds (comma-separated).
    #[arg(long, value_delimiter = ',', required = true)]
    seeds: Vec<u64>,
    /// Cameras, `RATE[:DROP]` (Hz, fraction of frames dropped), comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "30:0.1,10")]
    cameras: Vec<String>,
    /// Samples of each training log (100 Hz).
    #[arg(long, default_value_t = 1000)]
    train_steps: usize,
    /// Training logs (the same input, fresh noise).
    #[arg(long, default_value_t = 3)]
    repeats: usize,
    /// Samples of the test log.
    #[arg(long, default_value_t = 1000)]
    test_steps: usize,
    /// Leave out the `interpolated` model (EM's first fit is the same model).
    #[arg(long)]
    no_interpolated: bool,
}

/// `RATE[:DROP]`.
fn camera(text: &str) -> Result<(f64, f64), String> {
    let (rate, drop) = text.split_once(':').unwrap_or((text, "0"));
    let rate: f64 = rate.parse().map_err(|e| format!("{text}: {e}"))?;
    let drop: f64 = drop.parse().map_err(|e| format!("{text}: {e}"))?;
    if !(rate > 0.0 && (0.0..1.0).contains(&drop)) {
        return Err(format!("{text}: a positive rate and a drop in [0, 1)"));
    }
    Ok((rate, drop))
}

/// The frames a camera at `rate` Hz records of `x` (sampled at `grid_hz`), each dropped with
/// probability `drop` (the first and last kept), on the grid, and the interpolation of the
/// frames at every grid sample (held at the ends).
fn film(
    x: &[f64],
    grid_hz: f64,
    rate: f64,
    drop: f64,
    rng: &mut Rng,
) -> (Vec<StateFrame>, Vec<f64>) {
    let n = x.len();
    let span_s = (n - 1) as f64 / grid_hz;
    let count = (span_s * rate).floor() as usize + 1;
    let mut frames = Vec::new();
    for j in 0..count {
        let pos = j as f64 / rate * grid_hz;
        let keep = j == 0 || j + 1 == count || rng.uniform() >= drop;
        if !keep {
            continue;
        }
        let k = pos.ceil() as usize;
        let (k, weight) = if k == 0 {
            (0, 1.0)
        } else {
            (k.min(n - 1), (pos - (k - 1) as f64).clamp(0.0, 1.0))
        };
        let value = if k == 0 {
            x[0]
        } else {
            weight * x[k] + (1.0 - weight) * x[k - 1]
        };
        frames.push(StateFrame { k, weight, value });
    }
    let times: Vec<f64> = frames.iter().map(|f| f.k as f64 - 1.0 + f.weight).collect();
    let interpolated = (0..n)
        .map(|k| {
            let t = k as f64;
            let i = times.partition_point(|&s| s <= t);
            match (i.checked_sub(1), frames.get(i)) {
                (Some(a), Some(b)) => {
                    let (ta, tb) = (times[a], times[i]);
                    let w = if tb > ta { (t - ta) / (tb - ta) } else { 1.0 };
                    (1.0 - w) * frames[a].value + w * b.value
                }
                (Some(a), None) => frames[a].value,
                (None, _) => frames.first().map_or(0.0, |f| f.value),
            }
        })
        .collect();
    (frames, interpolated)
}

struct Row {
    camera: usize,
    full: f64,
    interpolated: f64,
    em: f64,
    full_s: f64,
    em_s: f64,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let cameras: Vec<(f64, f64)> = args
        .cameras
        .iter()
        .map(|c| camera(c))
        .collect::<Result<_, _>>()?;
    let mut rows = Vec::new();
    for &system in &args.systems {
        for &gain in &args.gains {
            for &seed in &args.seeds {
                let cfg = ExperimentConfig {
                    train_steps: args.train_steps,
                    repeats: args.repeats,
                    test_steps: args.test_steps,
                    ..ExperimentConfig::default()
                };
                let train = training_set(system, gain, seed, &cfg)?;
                let test = test_trajectory(system, gain, seed, &cfg)?;
                let params = HbnParams {
                    seed,
                    ..HbnParams::default()
                };
                let checked = params.clone().check()?;
                let grid_hz = params.rate_hz;
                let score =
                    |m: &HysteresisModel| -> Result<(f64, f64), Box<dyn std::error::Error>> {
                        let e = m.estimate(&test.u, &test.y, m.default_mode())?;
                        Ok((
                            nrmse(&e.x, &test.x),
                            calibration(&e.x, &e.x_std, &test.x).coverage_2sigma,
                        ))
                    };
                let t = Instant::now();
                let seqs: Vec<Sequence<'_>> = train
                    .iter()
                    .map(|r| Sequence::new(&r.u, &r.x, &r.y))
                    .collect();
                let full = HysteresisModel::fit_checked(&seqs, &checked, &mut |_, _| {})?;
                let full_s = t.elapsed().as_secs_f64();
                let (full_nrmse, full_cover) = score(&full)?;
                for (ci, &(rate, drop)) in cameras.iter().enumerate() {
                    let mut rng = Rng::new(seed ^ 0xCA3E_0000 ^ (ci as u64) << 8);
                    let filmed: Vec<(Vec<StateFrame>, Vec<f64>)> = train
                        .iter()
                        .map(|r| film(&r.x, grid_hz, rate, drop, &mut rng))
                        .collect();
                    let masks: Vec<Vec<bool>> = filmed
                        .iter()
                        .zip(&train)
                        .map(|((f, _), r)| observed_mask(f, r.x.len()))
                        .collect();
                    let runs: Vec<LatentRun<'_>> = train
                        .iter()
                        .zip(&filmed)
                        .zip(&masks)
                        .map(|((r, (frames, xi)), m)| LatentRun {
                            seq: Sequence::new(&r.u, xi, &r.y).with_observed(m),
                            frames,
                        })
                        .collect();
                    let (interp_nrmse, interp_cover) = if args.no_interpolated {
                        (f64::NAN, f64::NAN)
                    } else {
                        let seqs: Vec<Sequence<'_>> = runs.iter().map(|r| r.seq).collect();
                        let m = HysteresisModel::fit_checked(&seqs, &checked, &mut |_, _| {})?;
                        score(&m)?
                    };
                    let t = Instant::now();
                    let em = HysteresisModel::fit_latent(&runs, &checked, &mut |_, _| {})?;
                    let em_s = t.elapsed().as_secs_f64();
                    let (em_nrmse, em_cover) = score(&em)?;
                    let rounds = em
                        .summary()
                        .latent
                        .as_ref()
                        .map(|l| l.rounds.clone())
                        .unwrap_or_default();
                    println!(
                        "{}",
                        serde_json::json!({
                            "system": system.name(),
                            "gain": gain,
                            "seed": seed,
                            "camera_hz": rate,
                            "drop": drop,
                            "nrmse_full": full_nrmse,
                            "nrmse_interpolated": interp_nrmse,
                            "nrmse_em": em_nrmse,
                            "coverage_full": full_cover,
                            "coverage_interpolated": interp_cover,
                            "coverage_em": em_cover,
                            "seconds_full": full_s,
                            "seconds_em": em_s,
                            "rounds": rounds.iter().map(|r| serde_json::json!({
                                "round": r.round, "nlpd": r.nlpd, "nrmse": r.nrmse, "improved": r.improved
                            })).collect::<Vec<_>>(),
                        })
                    );
                    rows.push(Row {
                        camera: ci,
                        full: full_nrmse,
                        interpolated: interp_nrmse,
                        em: em_nrmse,
                        full_s,
                        em_s,
                    });
                }
            }
        }
    }
    println!();
    println!(
        "| camera | interpolated / full (geo. mean) | EM / full (geo. mean) | EM / full (worst) | EM time / full time |"
    );
    println!("|---|---|---|---|---|");
    for (ci, (rate, drop)) in cameras.iter().enumerate() {
        let group: Vec<&Row> = rows.iter().filter(|r| r.camera == ci).collect();
        let geo = |f: &dyn Fn(&Row) -> f64| {
            let logs: Vec<f64> = group
                .iter()
                .map(|r| f(r).ln())
                .filter(|v| v.is_finite())
                .collect();
            (logs.iter().sum::<f64>() / logs.len().max(1) as f64).exp()
        };
        let worst = group.iter().map(|r| r.em / r.full).fold(f64::NAN, f64::max);
        println!(
            "| {rate} Hz, {:.0}% dropped | {:.3} | {:.3} | {:.3} | {:.2} |",
            100.0 * drop,
            geo(&|r| r.interpolated / r.full),
            geo(&|r| r.em / r.full),
            worst,
            geo(&|r| r.em_s / r.full_s),
        );
    }
    Ok(())
}
