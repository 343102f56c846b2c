//! Long run of the estimator step (docs/reliability.md): `STEPS` samples (default 10^7) of a
//! noisy test run, cycled, with outliers in `y` (every 997 samples, +-50 ranges), NaN bursts
//! (20 samples every 50,000), invalid inputs, and sensor dropouts (`y` missing for 3 s = 300
//! samples every 100,000). Checks that no output is ever non-finite and that `x_std` stays in
//! `[sqrt(p_min), sqrt(p_max)]`, and measures the recovery after each dropout: the samples
//! from the dropout's end until the error is back within 3 times the RMS error of the 1000
//! samples before the dropout, for 50 samples in a row.
//!
//! `cargo bench --bench soak -- [STEPS] [MODE]` (MODE `ekf`, `ekf-blr` or `ukf`; default every
//! mode).

use hbn::core::rng::Rng;
use hbn::core::{Estimator, Mode};
use hbn::model::{HbnModel, HbnParams};
use hbn::pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn::pipeline::sequences;
use hbn::sim::SystemKind;
use std::time::Instant;

const DROPOUT_EVERY: usize = 100_000;
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
    let model = HbnModel::fit(&sequences(&runs), &cfg.params)?;
    let test = test_trajectory(system, 1.0, 5, &cfg)?;
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
            let phase = k % DROPOUT_EVERY;
            let dropped = k >= DROPOUT_EVERY && phase < DROPOUT_LEN;
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
            if !dropped && !outlier {
                if recent.len() == 1000 {
                    recent.pop_front();
                }
                recent.push_back(err * err);
            }
            if k >= DROPOUT_EVERY && phase == DROPOUT_LEN {
                let rms = (recent.iter().sum::<f64>() / recent.len().max(1) as f64).sqrt();
                pending = Some((k, 0, 3.0 * rms));
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
        let pct = |p: f64| {
            recoveries
                .get(((recoveries.len() as f64 - 1.0) * p).round() as usize)
                .copied()
                .unwrap_or(0)
        };
        println!(
            "{:<8} {steps} steps in {secs:.1} s ({:.2} us/step): non-finite {non_finite}, \
             x_std out of bounds {out_of_bounds}, outliers rejected {rejected}; nRMSE outside \
             dropouts {:.4}, in 2 sd {:.1}%; {} dropouts of {DROPOUT_LEN} samples, recovered \
             (error within 3x the RMS error before, {SETTLED} samples in a row) after median {} / 95% {} / max {} \
             samples, {} not recovered",
            mode.name(),
            1e6 * secs / steps as f64,
            (se / scored.max(1) as f64).sqrt() / x_stats.span(),
            100.0 * inside as f64 / scored.max(1) as f64,
            recoveries.len(),
            pct(0.5),
            pct(0.95),
            recoveries.last().copied().unwrap_or(0),
            usize::from(pending.is_some()),
        );
        if non_finite > 0 || out_of_bounds > 0 {
            return Err(
                format!("{mode}: {non_finite} non-finite, {out_of_bounds} out of bounds").into(),
            );
        }
    }
    Ok(())
}
