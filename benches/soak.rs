//! Long run of the estimator step (docs/reliability.md): `STEPS` samples (default 10^7) of a
//! noisy test run, cycled, with outliers in `y` (every 997 samples, +-50 ranges), NaN bursts
//! (20 samples every 50,000), invalid inputs, and sensor dropouts (`y` missing for 3 s = 300
//! samples every 100,000, at a point of the test run that moves). Checks that no output is ever non-finite and that `x_std` stays in
//! `[sqrt(p_min), sqrt(p_max)]` (times the model's std scale), and measures the recovery after
//! each dropout in two ways: the samples from the dropout's end until the error is back within
//! 3 times the RMS error of the 1000 samples before the dropout, and until it is within 3
//! `x_std` (the filter's own bound), each for 50 samples in a row.
//!
//! `cargo bench --bench soak -- [STEPS] [MODE]` (MODE `ekf`, `ekf-blr` or `ukf`; default every
//! mode).

use hbn::core::rng::Rng;
use hbn::core::{Estimator, Mode};
use hbn::model::{HbnParams, HysteresisModel};
use hbn::pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn::pipeline::sequences;
use hbn::sim::SystemKind;
use std::time::Instant;

const DROPOUT_EVERY: usize = 100_000;
/// Sample of period `n` (of `DROPOUT_EVERY`) where its dropout starts: 40,000 (a multiple of the
/// 20,000-sample test run that is cycled) plus a point of the run that moves from dropout to
/// dropout, in [1000, 18700], away from the wrap-around where the true state jumps.
fn dropout_start(n: usize) -> usize {
    n * DROPOUT_EVERY + 40_000 + 1_000 + (n * 7_919) % 17_700
}
const DROPOUT_LEN: usize = 300;
const SETTLED: usize = 50;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a != "--bench")
        .collect();
    let steps: usize = args
        .first()
        .and_then(|a| a.parse().ok())
        .unwrap_or(10_000_000);
    let modes: Vec<Mode> = match args.get(1) {
        Some(m) => vec![m.parse()?],
        None => Mode::ALL.to_vec(),
    };
    let system = SystemKind::GeneralizedPi;
    let cfg = ExperimentConfig {
        train_steps: 600,
        repeats: 3,
        test_steps: 20_000,
        params: HbnParams {
            max_points: 150,
            ..HbnParams::default()
        },
        ..ExperimentConfig::default()
    };
    let runs = training_set(system, 1.0, 5, &cfg)?;
    let model = HysteresisModel::fit(&sequences(&runs), &cfg.params)?;
    let test = test_trajectory(system, 1.0, 5, &cfg)?;
    if test.u.len() != 20_000 {
        return Err(format!("the test run has {} samples, not 20,000", test.u.len()).into());
    }
    let (_, x_stats, y_stats) = model.stats();
    let view = model.view()?;
    println!(
        "soak: {system}, {} support points per GP, {steps} steps per mode",
        model.transition().n_support()
    );
    for mode in modes {
        let config = model.ekf_config(mode);
        let (lo, hi) = (
            config.std_scale * config.p_min.sqrt(),
            config.std_scale * config.p_max.sqrt(),
        );
        let mut scratch = vec![0.0; Estimator::scratch_len(&view)];
        let mut est = Estimator::new(view, config, &mut scratch)?;
        let mut rng = Rng::new(11);
        let (mut non_finite, mut out_of_bounds, mut rejected) = (0usize, 0usize, 0usize);
        let mut recoveries: Vec<usize> = Vec::new();
        let mut pending: Option<(usize, usize, f64)> = None; // (dropout end, settled run, bound)
        let mut recoveries_std: Vec<usize> = Vec::new();
        let mut pending_std: Option<(usize, usize)> = None; // (dropout end, settled run)
        let (mut lost, mut lost_std) = (0usize, 0usize);
        // The largest error during each dropout, over the RMS error before it.
        let (mut peak, mut peaks) = (0.0f64, Vec::new());
        let mut recent = std::collections::VecDeque::with_capacity(1000);
        let (mut se, mut inside, mut scored) = (0.0, 0usize, 0usize);
        let t0 = Instant::now();
        for k in 0..steps {
            let i = k % test.u.len();
            let mut u = test.u[i];
            let mut y = test.y[i];
            let outlier = k % 997 == 0;
            if outlier {
                y += 50.0 * y_stats.span() * (rng.uniform() - 0.5);
            }
            if k % 50_000 < 20 && k >= 50_000 {
                y = f64::NAN;
            }
            if k % 250_007 == 0 {
                u = f64::INFINITY;
            }
            let drop_at = dropout_start(k / DROPOUT_EVERY);
            let dropped = (drop_at..drop_at + DROPOUT_LEN).contains(&k);
            if dropped {
                y = f64::NAN;
            }
            let out = est.step(u, y);
            if !(out.x.is_finite() && out.x_std.is_finite() && out.nis.is_finite()) {
                non_finite += 1;
                continue;
            }
            if out.x_std < lo * (1.0 - 1e-9) || out.x_std > hi * (1.0 + 1e-9) {
                out_of_bounds += 1;
            }
            rejected += usize::from(out.flags.has(hbn::core::Flags::OUTLIER_REJECTED));
            let err = (out.x - test.x[i]).abs();
            if !dropped && k % 997 != 0 {
                se += err * err;
                inside += usize::from(err <= 2.0 * out.x_std);
                scored += 1;
            }
            if dropped {
                peak = peak.max(err);
            }
            if !dropped && !outlier {
                if recent.len() == 1000 {
                    recent.pop_front();
                }
                recent.push_back(err * err);
            }
            if k == drop_at + DROPOUT_LEN {
                let rms = (recent.iter().sum::<f64>() / recent.len().max(1) as f64).sqrt();
                // A dropout not recovered from before the next one ends counts as such.
                lost += usize::from(pending.is_some());
                lost_std += usize::from(pending_std.is_some());
                peaks.push(peak / rms);
                peak = 0.0;
                pending = Some((k, 0, 3.0 * rms));
                pending_std = Some((k, 0));
            }
            if let Some((end, run)) = pending_std {
                let run = if err <= 3.0 * out.x_std { run + 1 } else { 0 };
                if run >= SETTLED {
                    recoveries_std.push(k + 1 - SETTLED - end);
                    pending_std = None;
                } else {
                    pending_std = Some((end, run));
                }
            }
            if let Some((end, run, bound)) = pending {
                let run = if err <= bound { run + 1 } else { 0 };
                if run >= SETTLED {
                    recoveries.push(k + 1 - SETTLED - end);
                    pending = None;
                } else {
                    pending = Some((end, run, bound));
                }
            }
        }
        let secs = t0.elapsed().as_secs_f64();
        recoveries.sort_unstable();
        recoveries_std.sort_unstable();
        peaks.sort_by(f64::total_cmp);
        let pct = |r: &[usize], p: f64| {
            r.get(((r.len() as f64 - 1.0) * p).round() as usize)
                .copied()
                .unwrap_or(0)
        };
        println!(
            "{:<8} {steps} steps in {secs:.1} s ({:.2} us/step): non-finite {non_finite}, \
             x_std out of [{lo:.3e}, {hi:.3e}] {out_of_bounds}, outliers rejected {rejected}; \
             nRMSE outside dropouts {:.4}, in 2 sd {:.1}%",
            mode.name(),
            1e6 * secs / steps as f64,
            (se / scored.max(1) as f64).sqrt() / x_stats.span(),
            100.0 * inside as f64 / scored.max(1) as f64,
        );
        println!(
            "{:<8} {} dropouts of {DROPOUT_LEN} samples; recovered ({SETTLED} samples in a row) \
             to 3x the RMS error before: median {} / 95% {} / max {} samples, {} not; \
             to 3 x_std: median {} / 95% {} / max {} samples, {} not; largest error during a \
             dropout: median {:.1} / max {:.1} times the RMS error before",
            "",
            recoveries.len() + lost + usize::from(pending.is_some()),
            pct(&recoveries, 0.5),
            pct(&recoveries, 0.95),
            recoveries.last().copied().unwrap_or(0),
            lost + usize::from(pending.is_some()),
            pct(&recoveries_std, 0.5),
            pct(&recoveries_std, 0.95),
            recoveries_std.last().copied().unwrap_or(0),
            lost_std + usize::from(pending_std.is_some()),
            peaks.get(peaks.len() / 2).copied().unwrap_or(0.0),
            peaks.last().copied().unwrap_or(0.0),
        );
        if non_finite > 0 || out_of_bounds > 0 {
            return Err(
                format!("{mode}: {non_finite} non-finite, {out_of_bounds} out of bounds").into(),
            );
        }
    }
    Ok(())
}
