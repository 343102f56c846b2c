//! The workflows end to end on simulated logs: the model keeps the log's rate, estimates are
//! written as CSV and MCAP on the log's clock, and every option is checked before any file is
//! opened.

use std::path::{Path, PathBuf};

use hbn_core::Mode;
use hbn_io::{Encoding, SignalPath};
use hbn_model::{HbnParams, Param};
use hbn_pipeline::{
    Event, LogOption, LogOptions, Outputs, PipelineError, Setting, SignalChoice, SimLog,
    TrainSignals, estimate_log, evaluate_log, simulate_log, train_from_logs,
};
use hbn_sim::{SimConfig, SystemKind};

fn sim(dir: &Path, name: &str, rate_hz: f64, seed: u64, input_seed: u64) -> PathBuf {
    let f = dir.join(name);
    simulate_log(
        &SimLog {
            config: SimConfig {
                system: SystemKind::Duhem,
                noise_gain: 1.0,
                rate_hz,
                seed,
            },
            steps: 400,
            input_seed,
            max_increment: hbn_sim::DEFAULT_MAX_INCREMENT,
            encoding: Encoding::Json,
        },
        &f,
    )
    .unwrap();
    f
}

fn small() -> HbnParams {
    HbnParams {
        max_points: 80,
        n_starts: 1,
        max_iters: 30,
        ..HbnParams::default()
    }
}

#[test]
fn a_50_hz_log_trains_a_50_hz_model_and_estimates_are_written() {
    let d = tempfile::tempdir().unwrap();
    let train = sim(d.path(), "train.mcap", 50.0, 1, 1);
    let test = sim(d.path(), "test.mcap", 50.0, 2, 2);
    let mut events = Vec::new();
    let trained = train_from_logs(
        &[train],
        &TrainSignals::default(),
        LogOptions::default(),
        small(),
        &mut |e| {
            if let Event::NativeRate { rate_hz, .. } = e {
                events.push(rate_hz)
            }
        },
    )
    .unwrap();
    // The model keeps the log's rate (no default of 100 Hz sneaks in).
    assert_eq!(trained.model.rate_hz(), 50.0);
    assert_eq!(events, [50.0]);
    assert_eq!(trained.samples(), 400);
    assert_eq!(
        trained.model.signals().output.path.as_deref(),
        Some("/sensor.data")
    );

    let outputs = Outputs {
        csv: Some(d.path().join("est.csv")),
        mcap: Some(d.path().join("est.mcap")),
    };
    let est = estimate_log(
        &trained.model,
        &test,
        &SignalChoice::default(),
        Mode::EkfBlr,
        LogOptions::default(),
        &outputs,
        &mut |_| {},
    )
    .unwrap();
    assert_eq!(est.log.rate_hz(), 50.0);
    assert_eq!(est.estimate.len(), 400);
    // CSV: header and one row per grid sample; u and y the filter ran on and x as computed,
    // each reading back to the same bits.
    let csv = std::fs::read_to_string(d.path().join("est.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().collect();
    assert_eq!(rows[0], hbn_pipeline::CSV_HEADER);
    assert_eq!(rows.len(), 401);
    for (k, row) in rows[1..].iter().enumerate() {
        let v: Vec<f64> = row
            .split(',')
            .skip(1)
            .take(3)
            .map(|c| c.parse().unwrap())
            .collect();
        assert_eq!(v[0].to_bits(), est.log.column(0)[k].to_bits(), "u at {k}");
        assert_eq!(v[1].to_bits(), est.log.column(1)[k].to_bits(), "y at {k}");
        assert_eq!(v[2].to_bits(), est.estimate.x[k].to_bits(), "x at {k}");
    }
    // MCAP: the estimate channel on the log's clock (20 ms apart, starting at the log's start).
    let back = hbn_io::read_signals(
        &d.path().join("est.mcap"),
        &["/hbn/estimate.x".parse::<SignalPath>().unwrap()],
        &Default::default(),
    )
    .unwrap();
    assert_eq!(back[0].value, est.estimate.x);
    assert_eq!(back[0].t_ns[0], hbn_pipeline::START_NS);
    assert_eq!(back[0].t_ns[1] - back[0].t_ns[0], 20_000_000);

    // Evaluation reads the state too and scores every method.
    let ev = evaluate_log(
        &trained.model,
        &test,
        &SignalChoice::default(),
        &Mode::ALL,
        LogOptions::default(),
        &mut |_| {},
    )
    .unwrap();
    // One score per mode, then the open loop.
    assert_eq!(ev.scores.len(), Mode::ALL.len() + 1);
    let open_loop = ev.scores[Mode::ALL.len()];
    assert!(ev.scores[0].nrmse < open_loop.nrmse, "{:?}", ev.scores);
    assert_eq!(ev.estimates[1].1.x, est.estimate.x);
}

#[test]
fn options_and_parameters_are_checked_before_any_file_is_opened() {
    let missing = vec![PathBuf::from("/no/such/log.mcap")];
    let train = |opts: LogOptions, params: HbnParams, logs: &[PathBuf]| {
        train_from_logs(logs, &TrainSignals::default(), opts, params, &mut |_| {}).unwrap_err()
    };
    let e = train(
        LogOptions {
            max_gap_s: 0.0,
            ..LogOptions::default()
        },
        small(),
        &missing,
    );
    assert_eq!(e.setting(), Some(Setting::Log(LogOption::MaxGap)), "{e}");
    let e = train(
        LogOptions {
            rate_hz: Some(-5.0),
            ..LogOptions::default()
        },
        small(),
        &missing,
    );
    assert_eq!(e.setting(), Some(Setting::Log(LogOption::Rate)), "{e}");
    let e = train(LogOptions::default(), small(), &[]);
    assert_eq!(e.setting(), Some(Setting::Log(LogOption::Logs)), "{e}");
    let e = train(
        LogOptions::default(),
        HbnParams {
            max_points: 1,
            ..small()
        },
        &missing,
    );
    assert_eq!(e.setting(), Some(Setting::Param(Param::MaxPoints)), "{e}");
    // With valid settings the missing file is what fails.
    let e = train(LogOptions::default(), small(), &missing);
    assert!(matches!(e, PipelineError::Read { .. }), "{e}");
    assert!(e.to_string().contains("/no/such/log.mcap"), "{e}");
}

#[test]
fn estimation_runs_at_the_model_rate_only() {
    let d = tempfile::tempdir().unwrap();
    let train = sim(d.path(), "train.mcap", 100.0, 1, 1);
    let trained = train_from_logs(
        std::slice::from_ref(&train),
        &TrainSignals::default(),
        LogOptions::default(),
        small(),
        &mut |_| {},
    )
    .unwrap();
    let e = estimate_log(
        &trained.model,
        &train,
        &SignalChoice::default(),
        Mode::Ekf,
        LogOptions {
            rate_hz: Some(50.0),
            ..LogOptions::default()
        },
        &Outputs::default(),
        &mut |_| {},
    )
    .unwrap_err();
    assert_eq!(e.setting(), Some(Setting::Log(LogOption::Rate)), "{e}");
}
