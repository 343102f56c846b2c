//! The grid rate of training without `--rate`: the sensor's native rate (the slowest sensor's
//! for a vector model), whatever the rates of the input (a valve logged faster) and of the
//! state (a camera, latent between its frames); `--rate` overrides it. Logs are written as a
//! rig records them, each topic at its own rate.

use std::path::{Path, PathBuf};

use hbn_io::{Encoding, TimedTopic};
use hbn_model::HbnParams;
use hbn_pipeline::{Event, LogOptions, StateCamera, TrainSignals, log_times, train_from_logs};
use hbn_sim::{InputKind, SimConfig, SystemKind};

/// The simulator's rate: every topic's rate divides it.
const SIM_HZ: f64 = 200.0;

/// Every `step`-th of `v`.
fn every<T: Copy>(v: &[T], step: usize) -> Vec<T> {
    v.iter().step_by(step).copied().collect()
}

/// A bouc-wen run of `seconds` simulated at [`SIM_HZ`], written to `dir/name` with `/input`
/// at `input_hz`, `/state` as a camera at `camera_hz` sees it, `/sensor` at `sensor_hz` and,
/// with `sensor2_hz`, a second sensor `/sensor2` (the first's reading, squared) at that rate.
fn rig_log(
    dir: &Path,
    name: &str,
    seed: u64,
    seconds: f64,
    [input_hz, camera_hz, sensor_hz]: [f64; 3],
    sensor2_hz: Option<f64>,
) -> PathBuf {
    let steps = (seconds * SIM_HZ).round() as usize;
    let u = hbn_sim::generate_input(InputKind::RandomRamps, steps, 0.01, seed).unwrap();
    let cfg = SimConfig {
        system: SystemKind::BoucWen,
        noise_gain: 1.0,
        rate_hz: SIM_HZ,
        seed,
    };
    let run = hbn_sim::simulate(&cfg, &u).unwrap();
    let t = log_times(steps, SIM_HZ);
    let step = |hz: f64| (SIM_HZ / hz).round() as usize;
    let frames = StateCamera {
        rate_hz: camera_hz,
        drop: 0.0,
        seed,
    }
    .observe(SIM_HZ, &[&run.x])
    .unwrap();
    let (u_t, u) = (every(&t, step(input_hz)), every(&run.u, step(input_hz)));
    let (y_t, y) = (every(&t, step(sensor_hz)), every(&run.y, step(sensor_hz)));
    let s2 = sensor2_hz.unwrap_or(sensor_hz);
    let squared: Vec<f64> = run.y.iter().map(|v| v * v).collect();
    let (y2_t, y2) = (every(&t, step(s2)), every(&squared, step(s2)));
    let u_fields = [("data", u.as_slice())];
    let x_fields = [("data", frames.x[0].as_slice())];
    let y_fields = [("data", y.as_slice())];
    let y2_fields = [("data", y2.as_slice())];
    let mut topics = vec![
        TimedTopic {
            topic: "/input",
            t_ns: &u_t,
            fields: &u_fields,
        },
        TimedTopic {
            topic: "/state",
            t_ns: &frames.t_ns,
            fields: &x_fields,
        },
        TimedTopic {
            topic: "/sensor",
            t_ns: &y_t,
            fields: &y_fields,
        },
    ];
    if sensor2_hz.is_some() {
        topics.push(TimedTopic {
            topic: "/sensor2",
            t_ns: &y2_t,
            fields: &y2_fields,
        });
    }
    let file = dir.join(name);
    hbn_io::write_timed_log(&file, &topics, Encoding::Json).unwrap();
    file
}

/// Runs `hbn ARGS`, which must succeed; returns stdout and stderr.
fn ok(args: &[&str]) -> (String, String) {
    let mut out = Vec::new();
    let mut err = Vec::new();
    let full: Vec<&str> = std::iter::once("hbn").chain(args.iter().copied()).collect();
    let r = hbn_cli::run_with(full, &mut out, &mut err);
    let (out, err) = (
        String::from_utf8_lossy(&out).into_owned(),
        String::from_utf8_lossy(&err).into_owned(),
    );
    if let Err(e) = r {
        panic!("hbn {args:?} failed: {e:#}\nstdout: {out}\nstderr: {err}");
    }
    (out, err)
}

/// Quick training: one start, few iterations, small exact GPs, no model selection.
const QUICK: [&str; 10] = [
    "--max-points",
    "60",
    "--starts",
    "1",
    "--max-iters",
    "30",
    "--inducing",
    "exact",
    "--kernel",
    "se-ard",
];

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn a_valve_at_200_hz_a_sensor_at_100_hz_and_a_camera_at_30_hz_train_on_a_100_hz_grid() {
    let d = tempfile::tempdir().unwrap();
    let rates = [200.0, 30.0, 100.0];
    let first = rig_log(d.path(), "a.mcap", 1, 5.0, rates, None);
    // A second log whose sensor runs at 50 Hz: resampled to the first log's grid.
    let second = rig_log(d.path(), "b.mcap", 2, 5.0, [200.0, 30.0, 50.0], None);
    let mut chosen = Vec::new();
    let mut resampled = Vec::new();
    let trained = train_from_logs(
        &[first.clone(), second],
        &TrainSignals::default(),
        LogOptions::default(),
        HbnParams {
            max_points: 60,
            n_starts: 1,
            max_iters: 30,
            ..HbnParams::default()
        },
        &mut |e| match e {
            Event::NativeRate {
                file,
                path,
                rate_hz,
            } => chosen.push((file.to_owned(), path.to_string(), rate_hz)),
            Event::Resampling {
                path, native_hz, ..
            } => resampled.push((path.to_string(), native_hz.round())),
            _ => {}
        },
    )
    .unwrap();
    assert_eq!(chosen, [(first, "/sensor.data".to_owned(), 100.0)]);
    assert_eq!(trained.model.rate_hz(), 100.0);
    assert!(trained.logs.iter().all(|l| l.rate_hz() == 100.0));
    // The input and the camera are resampled in both logs, the sensor in the second only.
    let sensor: Vec<f64> = resampled
        .iter()
        .filter(|(p, _)| p == "/sensor.data")
        .map(|(_, hz)| *hz)
        .collect();
    assert_eq!(sensor, [50.0]);
    assert_eq!(
        resampled.iter().filter(|(p, _)| p == "/input.data").count(),
        2
    );
}

#[test]
fn hbn_train_says_which_rate_and_why_and_rate_overrides() {
    let d = tempfile::tempdir().unwrap();
    let rates = [200.0, 30.0, 100.0];
    let a = rig_log(d.path(), "a.mcap", 1, 5.0, rates, None);
    let b = rig_log(d.path(), "b.mcap", 2, 5.0, rates, None);
    let model = d.path().join("m.hbn");
    let mut args = vec!["train", "--log", s(&a), "--log", s(&b), "--out", s(&model)];
    args.extend(QUICK);
    let (out, err) = ok(&args);
    assert!(
        err.contains("using 100.0 Hz, the native rate of /sensor.data in"),
        "{err}"
    );
    assert!(
        out.contains("samples at 100.0 Hz (the sensor's rate); training took"),
        "{out}"
    );
    args.extend(["--rate", "50"]);
    let (out, err) = ok(&args);
    assert!(!err.contains("using "), "{err}");
    assert!(
        out.contains("samples at 50.0 Hz (set by --rate); training took"),
        "{out}"
    );
}

#[test]
fn a_vector_model_trains_at_its_slowest_sensors_rate() {
    let d = tempfile::tempdir().unwrap();
    let logs: Vec<PathBuf> = (1..=2)
        .map(|seed| {
            rig_log(
                d.path(),
                &format!("v{seed}.mcap"),
                seed,
                5.0,
                [200.0, 100.0, 100.0],
                Some(50.0),
            )
        })
        .collect();
    let model = d.path().join("v.hbn");
    let mut args = vec!["train"];
    for l in &logs {
        args.extend(["--log", s(l)]);
    }
    args.extend([
        "--output",
        "/sensor.data",
        "--output",
        "/sensor2.data",
        "--out",
        s(&model),
    ]);
    args.extend(QUICK);
    let (out, err) = ok(&args);
    assert!(
        err.contains("using 50.0 Hz, the native rate of /sensor2.data in"),
        "{err}"
    );
    assert!(
        out.contains("at 50 Hz (the rate of /sensor2.data, the slowest sensor)"),
        "{out}"
    );
}
