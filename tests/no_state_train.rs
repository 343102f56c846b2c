//! Training from logs of which some have no state topic at all (only the input and the
//! sensor were recorded): they join training with their state latent, beside the logs that
//! have it; without any log that has it, training fails on the missing topic, and a missing
//! field of a state topic that is there stays an error (a typo, not a log without a camera).
//! The same holds for a vector model's logs.

use std::path::{Path, PathBuf};

use hbn_io::{Encoding, IoError, TimedTopic};
use hbn_model::HbnParams;
use hbn_pipeline::{
    Event, LogOptions, PipelineError, TrainSignals, VectorSignals, log_times, train_from_logs,
    train_vector_from_logs,
};
use hbn_sim::{InputKind, SimConfig, SystemKind};

/// A bouc-wen run of `steps` samples at 100 Hz written to `dir/name`: `/input`, `/sensor`
/// and, `with_state`, `/state`.
fn log(dir: &Path, name: &str, seed: u64, steps: usize, with_state: bool) -> PathBuf {
    let u = hbn_sim::generate_input(InputKind::RandomRamps, steps, 0.05, seed).unwrap();
    let cfg = SimConfig {
        system: SystemKind::BoucWen,
        noise_gain: 1.0,
        rate_hz: 100.0,
        seed,
    };
    let run = hbn_sim::simulate(&cfg, &u).unwrap();
    let t = log_times(steps, 100.0);
    let u_fields = [("data", run.u.as_slice())];
    let x_fields = [("data", run.x.as_slice())];
    let y_fields = [("data", run.y.as_slice())];
    let mut topics = vec![
        TimedTopic {
            topic: "/input",
            t_ns: &t,
            fields: &u_fields,
        },
        TimedTopic {
            topic: "/sensor",
            t_ns: &t,
            fields: &y_fields,
        },
    ];
    if with_state {
        topics.push(TimedTopic {
            topic: "/state",
            t_ns: &t,
            fields: &x_fields,
        });
    }
    let file = dir.join(name);
    hbn_io::write_timed_log(&file, &topics, Encoding::Json).unwrap();
    file
}

fn quick() -> HbnParams {
    HbnParams {
        max_points: 150,
        n_starts: 1,
        max_iters: 40,
        ..HbnParams::default()
    }
}

#[test]
fn logs_without_a_state_topic_train_beside_one_with_it() {
    let d = tempfile::tempdir().unwrap();
    let logs = [
        log(d.path(), "camera.mcap", 1, 800, true),
        log(d.path(), "a.mcap", 2, 800, false),
        log(d.path(), "b.mcap", 3, 800, false),
    ];
    let mut without = Vec::new();
    let trained = train_from_logs(
        &logs,
        &TrainSignals::default(),
        LogOptions::default(),
        quick(),
        &mut |e| {
            if let Event::NoState { file, path } = e {
                without.push((file.to_owned(), path.to_string()));
            }
        },
    )
    .unwrap();
    assert_eq!(
        without,
        [
            (logs[1].clone(), "/state.data".to_owned()),
            (logs[2].clone(), "/state.data".to_owned()),
        ]
    );
    assert_eq!(trained.logs.len(), 3);
    assert!(trained.logs.iter().all(|l| l.rate_hz() == 100.0));
    let summary = trained.model.summary();
    let latent = summary.latent.as_ref().expect("trained by EM");
    assert_eq!(latent.unmeasured_runs, 2);
    assert_eq!(latent.frames, 800);
    assert!((latent.observed - 1.0 / 3.0).abs() < 0.01, "{latent:?}");
    assert!(latent.rounds.len() >= 2, "no refit ran: {latent:?}");
    assert!(
        summary.warnings.iter().any(|w| w.contains("only u and y")),
        "{:?}",
        summary.warnings
    );
    // The model estimates from u and y like any other.
    let est = trained
        .model
        .estimate(
            trained.logs[1].column(0),
            trained.logs[1].column(2),
            trained.model.default_mode(),
        )
        .unwrap();
    assert!(est.x.iter().all(|v| v.is_finite()));
}

#[test]
fn without_any_state_topic_training_names_the_missing_topic() {
    let d = tempfile::tempdir().unwrap();
    let logs = [
        log(d.path(), "a.mcap", 2, 400, false),
        log(d.path(), "b.mcap", 3, 400, false),
    ];
    let e = train_from_logs(
        &logs,
        &TrainSignals::default(),
        LogOptions::default(),
        quick(),
        &mut |_| {},
    )
    .unwrap_err();
    match &e {
        PipelineError::Read {
            file,
            source: IoError::MissingTopic { topic, .. },
        } => {
            assert_eq!(file, &logs[0]);
            assert_eq!(topic, "/state");
        }
        other => panic!("expected the missing state topic, got {other}"),
    }
}

#[test]
fn a_missing_field_of_the_state_topic_stays_an_error() {
    let d = tempfile::tempdir().unwrap();
    let logs = [
        log(d.path(), "camera.mcap", 1, 400, true),
        log(d.path(), "a.mcap", 2, 400, false),
    ];
    let signals = TrainSignals {
        state: "/state.angle".parse().unwrap(),
        ..TrainSignals::default()
    };
    let e =
        train_from_logs(&logs, &signals, LogOptions::default(), quick(), &mut |_| {}).unwrap_err();
    assert!(
        matches!(
            &e,
            PipelineError::Read {
                source: IoError::MissingField { .. },
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn hbn_train_warns_of_a_log_without_the_state_topic() {
    let d = tempfile::tempdir().unwrap();
    let a = log(d.path(), "camera.mcap", 1, 500, true);
    let b = log(d.path(), "a.mcap", 2, 500, false);
    let model = d.path().join("m.hbn");
    let (mut out, mut err) = (Vec::new(), Vec::new());
    let args = [
        "hbn",
        "train",
        "--log",
        a.to_str().unwrap(),
        "--log",
        b.to_str().unwrap(),
        "--out",
        model.to_str().unwrap(),
        "--max-points",
        "100",
        "--starts",
        "1",
    ];
    let r = hbn_cli::run_with(args, &mut out, &mut err);
    let err = String::from_utf8_lossy(&err);
    assert!(r.is_ok(), "{r:?}: {err}");
    assert!(
        err.contains(
            "has no topic `/state` for the state (/state.data): it trains with its state latent"
        ),
        "{err}"
    );
    assert!(model.exists());
}

/// A finger run (2 inputs, 2 state components, 3 sensors) of `steps` samples at 100 Hz:
/// `/input0`, `/input1`, `/sensor0..2` and, `with_state`, `/state` with fields `x0`, `x1`.
fn finger_log(dir: &Path, name: &str, seed: u64, steps: usize, with_state: bool) -> PathBuf {
    let mut cfg = hbn_sim::MultiConfig::new(hbn_sim::MultiKind::Finger);
    cfg.noise_gain = 1.0;
    cfg.seed = seed;
    let run = hbn_sim::simulate_multi_random(&cfg, steps).unwrap();
    let t = log_times(steps, 100.0);
    let field = |v: &[f64]| [("data", v.to_vec())];
    let u: Vec<_> = run.u.iter().map(|v| field(v)).collect();
    let y: Vec<_> = run.y.iter().map(|v| field(v)).collect();
    let names = ["/input0", "/input1", "/sensor0", "/sensor1", "/sensor2"];
    let fields: Vec<Vec<(&str, &[f64])>> = u
        .iter()
        .chain(&y)
        .map(|f| f.iter().map(|(n, v)| (*n, v.as_slice())).collect())
        .collect();
    let mut topics: Vec<TimedTopic<'_>> = names
        .iter()
        .zip(&fields)
        .map(|(topic, fields)| TimedTopic {
            topic,
            t_ns: &t,
            fields,
        })
        .collect();
    let x_fields = [("x0", run.x[0].as_slice()), ("x1", run.x[1].as_slice())];
    if with_state {
        topics.push(TimedTopic {
            topic: "/state",
            t_ns: &t,
            fields: &x_fields,
        });
    }
    let file = dir.join(name);
    hbn_io::write_timed_log(&file, &topics, Encoding::Json).unwrap();
    file
}

#[test]
fn a_vector_log_without_the_state_topic_trains_beside_one_with_it() {
    let d = tempfile::tempdir().unwrap();
    let logs = [
        finger_log(d.path(), "camera.mcap", 1, 700, true),
        finger_log(d.path(), "free.mcap", 2, 700, false),
    ];
    let paths = |v: &[&str]| v.iter().map(|p| p.parse().unwrap()).collect::<Vec<_>>();
    let signals = VectorSignals {
        inputs: paths(&["/input0.data", "/input1.data"]),
        states: paths(&["/state.x0", "/state.x1"]),
        outputs: paths(&["/sensor0.data", "/sensor1.data", "/sensor2.data"]),
    };
    let mut without = Vec::new();
    let trained = train_vector_from_logs(
        &logs,
        &signals,
        LogOptions::default(),
        quick(),
        &[],
        &mut |e| {
            if let Event::NoState { file, path } = e {
                without.push((file.to_owned(), path.to_string()));
            }
        },
    )
    .unwrap();
    // Said once per log (the components are fields of one topic).
    assert_eq!(without, [(logs[1].clone(), "/state.x0".to_owned())]);
    assert_eq!(trained.logs.len(), 2);
    let summary = trained.model.summary();
    let latent = summary.latent.as_ref().expect("trained by EM");
    assert_eq!(latent.unmeasured_runs, 1);
    assert_eq!(latent.frames, 700);
    assert!((latent.observed - 0.5).abs() < 0.01, "{latent:?}");
    assert!(!latent.rounds.is_empty(), "{latent:?}");
    // Without any log that has the state, the missing topic is the error.
    let e = train_vector_from_logs(
        &logs[1..],
        &signals,
        LogOptions::default(),
        quick(),
        &[],
        &mut |_| {},
    )
    .unwrap_err();
    assert!(
        matches!(
            &e,
            PipelineError::Read {
                source: IoError::MissingTopic { .. },
                ..
            }
        ),
        "{e}"
    );
}
