//! What a robot builder's first logs do to `hbn train`: a state topic (a camera) that stops
//! early, or covers only part of the log. Each topic has its own rate and span, as on a rig.

use std::collections::BTreeMap;
use std::path::Path;

/// One topic of a hand-written log: name, message times (s) and `data` values.
struct Topic<'a> {
    name: &'a str,
    t_s: Vec<f64>,
    values: Vec<f64>,
}

/// Samples of `f` at `rate_hz` from `start_s` for `duration_s`.
fn topic<'a>(
    name: &'a str,
    rate_hz: f64,
    start_s: f64,
    duration_s: f64,
    f: impl Fn(f64) -> f64,
) -> Topic<'a> {
    let n = (duration_s * rate_hz).round() as usize;
    let t_s: Vec<f64> = (0..n).map(|k| start_s + k as f64 / rate_hz).collect();
    let values = t_s.iter().map(|&t| f(t)).collect();
    Topic { name, t_s, values }
}

/// Writes `topics` as JSON messages `{"data": v}` at their log times, time-ordered.
fn write_log(file: &Path, topics: &[Topic<'_>]) {
    let w = std::io::BufWriter::new(std::fs::File::create(file).unwrap());
    let mut out = mcap::WriteOptions::new().create(w).unwrap();
    let schema = br#"{"type":"object","properties":{"data":{"type":"number"}}}"#;
    let schema_id = out.add_schema("Scalar", "jsonschema", schema).unwrap();
    let mut messages = Vec::new();
    for tp in topics {
        let id = out
            .add_channel(schema_id, tp.name, "json", &BTreeMap::new())
            .unwrap();
        for (&t, &v) in tp.t_s.iter().zip(&tp.values) {
            messages.push(((1e9 + t * 1e9).round() as u64, id, v));
        }
    }
    messages.sort_by_key(|m| m.0);
    for (k, (t, id, v)) in messages.into_iter().enumerate() {
        let body = format!("{{\"data\":{v}}}");
        out.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: id,
                sequence: k as u32,
                log_time: t,
                publish_time: t,
            },
            body.as_bytes(),
        )
        .unwrap();
    }
    out.finish().unwrap();
}

/// A hysteretic rig: the valve ramps, the bend lags it, the strain sensor follows the bend.
fn rig(state_start_s: f64, state_duration_s: f64, state_hz: f64) -> Vec<Topic<'static>> {
    rig_with_strain(state_start_s, state_duration_s, state_hz, 100.0)
}

/// [`rig`] with the strain sensor at `strain_hz`.
fn rig_with_strain(
    state_start_s: f64,
    state_duration_s: f64,
    state_hz: f64,
    strain_hz: f64,
) -> Vec<Topic<'static>> {
    let u = |t: f64| 0.5 + 0.4 * (0.7 * t).sin() * (0.13 * t).cos();
    let x = move |t: f64| 0.8 * u(t - 0.15) + 0.1 * (0.7 * t).cos();
    vec![
        topic("/valve", 100.0, 0.0, 20.0, u),
        topic("/camera", state_hz, state_start_s, state_duration_s, x),
        topic("/strain", strain_hz, 0.005, 20.0, move |t| {
            2.0 * x(t) + 0.05
        }),
    ]
}

/// `hbn train` on `log`: (error, stderr).
fn train(log: &Path, out: &Path, extra: &[&str]) -> (Option<String>, String) {
    let mut args = vec![
        "hbn",
        "train",
        "--log",
        log.to_str().unwrap(),
        "--input",
        "/valve.data",
        "--state",
        "/camera.data",
        "--output",
        "/strain.data",
        "--max-points",
        "60",
        "--starts",
        "1",
        "--max-iters",
        "30",
        "--inducing",
        "exact",
        "--lags",
        "none",
        "--sensor-inputs",
        "thesis",
        "--out",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let (mut stdout, mut stderr) = (Vec::new(), Vec::new());
    let r = hbn_cli::run_with(args, &mut stdout, &mut stderr);
    (
        r.err().map(|e| hbn_cli::error_message(&e)),
        String::from_utf8_lossy(&stderr).into_owned(),
    )
}

/// `hbn estimate --model model --log log --csv csv`, which must succeed: its stderr.
fn estimate(model: &Path, log: &Path, csv: &Path) -> String {
    let args = [
        "hbn",
        "estimate",
        "--model",
        model.to_str().unwrap(),
        "--log",
        log.to_str().unwrap(),
        "--csv",
        csv.to_str().unwrap(),
    ];
    let (mut stdout, mut stderr) = (Vec::new(), Vec::new());
    let r = hbn_cli::run_with(args, &mut stdout, &mut stderr);
    assert!(
        r.is_ok(),
        "{:?}",
        r.err().map(|e| hbn_cli::error_message(&e))
    );
    String::from_utf8_lossy(&stderr).into_owned()
}

#[test]
fn a_camera_that_stops_after_three_frames_is_refused_and_writes_no_model() {
    let d = tempfile::tempdir().unwrap();
    let (log, model) = (d.path().join("rig.mcap"), d.path().join("m.hbn"));
    write_log(&log, &rig(0.0, 0.1, 30.0));
    let (e, stderr) = train(&log, &model, &[]);
    let e = e.expect("three state samples must not train a model");
    assert!(
        e.contains("/camera.data")
            && e.contains("of its 3 samples")
            && e.contains("--min-state-samples"),
        "{e}"
    );
    assert!(!model.exists(), "a refused training leaves no model file");
    // The coverage warning names the topic and how much of the log it spans.
    assert!(stderr.contains("/camera.data spans only"), "{stderr}");
    // The model-selection notice comes only once the data passed their checks.
    assert!(!stderr.contains("model selection"), "{stderr}");
}

#[test]
fn a_camera_that_covers_part_of_the_log_trains_with_a_warning() {
    let d = tempfile::tempdir().unwrap();
    let (log, model) = (d.path().join("rig.mcap"), d.path().join("m.hbn"));
    // The camera records the first 8 s of 20 (240 frames at 30 Hz).
    write_log(&log, &rig(0.0, 8.0, 30.0));
    let (e, stderr) = train(&log, &model, &[]);
    assert!(e.is_none(), "{e:?}");
    assert!(model.exists());
    assert!(
        stderr.contains("/camera.data spans only") && stderr.contains("--min-coverage"),
        "{stderr}"
    );
    // Raising the threshold for state samples above what the log holds refuses it; lowering
    // the coverage threshold silences the warning.
    let (e, _) = train(&log, &model, &["--min-state-samples", "1000"]);
    assert!(e.expect("too few").contains("at least 1000 needed"));
    let (e, stderr) = train(&log, &d.path().join("m2.hbn"), &["--min-coverage", "0.3"]);
    assert!(e.is_none(), "{e:?}");
    assert!(!stderr.contains("spans only"), "{stderr}");
}

/// The valve at 100 Hz sets the grid; the strain sensor runs at 50 Hz, in training as at run
/// time: estimating on such a log says nothing about rates. A log whose sensor runs at another
/// rate than in training is warned about.
#[test]
fn rates_like_the_training_logs_are_not_warned_about() {
    let d = tempfile::tempdir().unwrap();
    let p = |n: &str| d.path().join(n);
    write_log(&p("train.mcap"), &rig_with_strain(0.0, 20.0, 30.0, 50.0));
    let (e, _) = train(&p("train.mcap"), &p("m.hbn"), &[]);
    assert!(e.is_none(), "{e:?}");
    write_log(&p("run.mcap"), &rig_with_strain(0.0, 20.0, 30.0, 50.0));
    let stderr = estimate(&p("m.hbn"), &p("run.mcap"), &p("est.csv"));
    assert!(!stderr.contains("recorded at"), "{stderr}");
    write_log(&p("other.mcap"), &rig_with_strain(0.0, 20.0, 30.0, 25.0));
    let stderr = estimate(&p("m.hbn"), &p("other.mcap"), &p("est.csv"));
    assert!(
        stderr.contains(
            "/strain.data is recorded at 25.0 Hz here but at 50.0 Hz in the training logs"
        ),
        "{stderr}"
    );
}

/// The rig of the issue: a camera at 30 Hz with one 0.56 s dropout. Training splits the log at
/// the dropout (a warning says where) instead of failing; estimation on a log whose sensor
/// drops out for a second restarts the filter after the gap and says so.
#[test]
fn a_camera_dropout_splits_the_log_and_a_sensor_dropout_restarts_the_filter() {
    let d = tempfile::tempdir().unwrap();
    let p = |n: &str| d.path().join(n);
    let mut topics = rig(0.0, 20.0, 30.0);
    // Drop the frames between 9.00 s and 9.56 s.
    let camera = &mut topics[1];
    let keep: Vec<bool> = camera.t_s.iter().map(|&t| !(9.0 < t && t < 9.56)).collect();
    let mut k = keep.iter();
    camera.t_s.retain(|_| *k.next().unwrap());
    let mut k = keep.iter();
    camera.values.retain(|_| *k.next().unwrap());
    write_log(&p("train.mcap"), &topics);
    let (e, stderr) = train(&p("train.mcap"), &p("m.hbn"), &[]);
    assert!(e.is_none(), "{e:?}");
    assert!(
        stderr.contains("/camera.data for 0.5") && stderr.contains("split there into 2 pieces"),
        "{stderr}"
    );

    // A run-time log whose strain sensor is silent from 12 s to 13 s.
    let mut topics = rig(0.0, 20.0, 30.0);
    let strain = &mut topics[2];
    let keep: Vec<bool> = strain
        .t_s
        .iter()
        .map(|&t| !(12.0 < t && t < 13.0))
        .collect();
    let mut k = keep.iter();
    strain.t_s.retain(|_| *k.next().unwrap());
    let mut k = keep.iter();
    strain.values.retain(|_| *k.next().unwrap());
    write_log(&p("run.mcap"), &topics);
    let stderr = estimate(&p("m.hbn"), &p("run.mcap"), &p("est.csv"));
    assert!(
        stderr.contains("the filter restarted after each"),
        "{stderr}"
    );
    // The CSV has no rows inside the gap, and the first row after it carries `initialised`.
    let csv = std::fs::read_to_string(p("est.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    let t: Vec<f64> = rows.iter().map(|r| r[0].parse().unwrap()).collect();
    let after = t.iter().position(|&t| t > 12.5).unwrap();
    assert!(t[after] > 12.9, "no estimate inside the gap: {}", t[after]);
    assert!(t[after - 1] < 12.1);
    assert!(rows[after][9].contains("initialised"), "{:?}", rows[after]);
    assert!(
        rows.iter()
            .all(|r| r[3].parse::<f64>().unwrap().is_finite())
    );

    // A model trained with --max-gap 2 reads run-time logs with it: the 1 s silence is a
    // dropout, not a gap. The filter predicts through it: rows inside it, `y` NaN there (what
    // the filter read), flagged `measurement_invalid`, and no restart.
    let (e, _) = train(&p("train.mcap"), &p("m2.hbn"), &["--max-gap", "2"]);
    assert!(e.is_none(), "{e:?}");
    let stderr = estimate(&p("m2.hbn"), &p("run.mcap"), &p("est2.csv"));
    assert!(!stderr.contains("restarted"), "{stderr}");
    let csv = std::fs::read_to_string(p("est2.csv")).unwrap();
    let inside: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|r| {
            let t: f64 = r[0].parse().unwrap();
            12.1 < t && t < 12.9
        })
        .collect();
    assert!(
        inside.len() > 70,
        "{} rows inside the dropout",
        inside.len()
    );
    for r in &inside {
        assert_eq!(r[2], "NaN", "{r:?}");
        assert!(r[9].contains("measurement_invalid"), "{r:?}");
        assert!(r[3].parse::<f64>().unwrap().is_finite(), "{r:?}");
    }
}
