//! The sparse-vs-exact measurement of docs/results.md: on each simulator, noise gain and seed,
//! the thesis protocol (one training input repeated 10 times with fresh noise, a fresh test
//! input), trained once with exact GPs on 500 support points and once with sparse GPs on
//! every sample, scored by nRMSE of the EKF and EKF+BLR on the test run.
//!
//! `cargo run --release -p hbn-pipeline --example sparse_vs_exact -- OUT.json [systems] [gains]
//! [seeds] [m,...]`; with `SPARSE_ONLY=1` in the environment the exact model is skipped (its
//! figures do not change when only the sparse GP does), and `INCREMENTS=none|transition|both`
//! sets what both models learn ([`hbn_model::Increments`]), `LINEAR_MEAN=none|transition|both`
//! which GPs have a linear prior mean ([`hbn_model::LinearMean`]), `MAX_SIGNAL_VARIANCE=v` their bound
//! ([`HbnParams::max_signal_variance`]). `TRAIN_STEPS=n` and `REPEATS=r` change the training
//! set (default 500 and 10, the thesis protocol); `TRAIN_STEPS=5000 REPEATS=1` is one
//! non-repeating log of the same size, like a robot's. `MAX_POINTS=n` sets the exact GP's
//! support points (default 500; the row's names say it), `SUBSET_POLICY=farthest-point|random`
//! how it picks them. `SELECT_INDUCING=m` adds a run `select{m}`: exact GPs with `m` inducing
//! points as the alternative that held-out selection ([`hbn_model::Selection`]) chooses
//! between. `DEFAULT_RUN=1` adds a run `default`: `HbnParams::default()` as shipped (model
//! selection among exact and sparse GPs and the lag, kernels by evidence), with only the
//! protocol's training set changed. An empty `m,...` list runs no plain sparse model.
use hbn_model::HbnParams;
use hbn_pipeline::experiment::{ExperimentConfig, run_case};
use hbn_sim::SystemKind;

fn list<T: std::str::FromStr>(arg: Option<&String>, default: Vec<T>) -> Vec<T> {
    arg.map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect())
        .unwrap_or(default)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let out = args
        .get(1)
        .ok_or("usage: sparse_vs_exact OUT.json [systems] [gains] [seeds] [m,...]")?;
    let systems = list(args.get(2), SystemKind::ALL.to_vec());
    let gains = list(args.get(3), vec![0.0, 1.0, 10.0]);
    let seeds = list(args.get(4), vec![1, 2, 3]);
    let ms = list(args.get(5), vec![hbn_model::DEFAULT_INDUCING]);
    let increments: hbn_model::Increments = match std::env::var("INCREMENTS") {
        Ok(v) => v.parse()?,
        Err(_) => hbn_model::Increments::default(),
    };
    let linear_mean: hbn_model::LinearMean = match std::env::var("LINEAR_MEAN") {
        Ok(v) => v.parse()?,
        Err(_) => hbn_model::LinearMean::default(),
    };
    let max_signal_variance: Option<f64> = match std::env::var("MAX_SIGNAL_VARIANCE") {
        Ok(v) => Some(v.parse()?),
        Err(_) => None,
    };
    let defaults = ExperimentConfig::default();
    let train_steps: usize = match std::env::var("TRAIN_STEPS") {
        Ok(v) => v.parse()?,
        Err(_) => defaults.train_steps,
    };
    let repeats: usize = match std::env::var("REPEATS") {
        Ok(v) => v.parse()?,
        Err(_) => defaults.repeats,
    };
    let max_points: usize = match std::env::var("MAX_POINTS") {
        Ok(v) => v.parse()?,
        Err(_) => HbnParams::default().max_points,
    };
    let subset_policy: hbn_gp::SubsetPolicy = match std::env::var("SUBSET_POLICY") {
        Ok(v) => serde_json::from_value(serde_json::Value::String(v))?,
        Err(_) => HbnParams::default().subset_policy,
    };
    let select: Option<usize> = match std::env::var("SELECT_INDUCING") {
        Ok(v) => Some(v.parse()?),
        Err(_) => None,
    };
    let mut rows = Vec::new();
    for &system in &systems {
        for &gain in &gains {
            for &seed in &seeds {
                let mut row = serde_json::Map::new();
                row.insert("system".into(), system.name().into());
                row.insert("gain".into(), gain.into());
                row.insert("seed".into(), seed.into());
                let exact = std::env::var_os("SPARSE_ONLY").is_none();
                let runs = exact
                    .then(|| (format!("exact{max_points}"), None, None, false))
                    .into_iter()
                    .chain(
                        ms.iter()
                            .map(|&m| (format!("sparse{m}"), Some(m), None, false)),
                    )
                    .chain(select.map(|m| (format!("select{m}"), None, Some(m), false)))
                    .chain(
                        std::env::var_os("DEFAULT_RUN")
                            .map(|_| ("default".to_string(), None, None, true)),
                    );
                for (name, n_inducing, alternative, shipped) in runs {
                    let params = if shipped {
                        HbnParams::default()
                    } else {
                        HbnParams {
                            n_inducing,
                            increments,
                            linear_mean,
                            max_signal_variance,
                            max_points,
                            subset_policy,
                            sparse_from_exact: std::env::var_os("SPARSE_FROM_EXACT").is_some(),
                            select: hbn_model::Selection {
                                inducing: alternative.map(Some).into_iter().collect(),
                                ..Default::default()
                            },
                            ..HbnParams::default()
                        }
                    };
                    let cfg = ExperimentConfig {
                        params,
                        train_steps,
                        repeats,
                        ..ExperimentConfig::default()
                    };
                    let r = run_case(system, seed, gain, &cfg)?;
                    row.insert(format!("{name}_ekf"), r.nrmse_ekf.into());
                    row.insert(format!("{name}_ekf_blr"), r.nrmse_ekf_blr.into());
                    row.insert(format!("{name}_ukf"), r.nrmse_ukf.into());
                    row.insert(format!("{name}_default"), r.nrmse_default.into());
                    row.insert(
                        format!("{name}_default_mode"),
                        r.default_mode.to_string().into(),
                    );
                    row.insert(
                        format!("{name}_calibration"),
                        serde_json::to_value(r.calibration_default)?,
                    );
                    row.insert(format!("{name}_seconds"), r.train_seconds.into());
                }
                eprintln!("{}", serde_json::Value::Object(row.clone()));
                rows.push(serde_json::Value::Object(row));
            }
        }
    }
    std::fs::write(out, serde_json::to_string_pretty(&rows)?)?;
    Ok(())
}
