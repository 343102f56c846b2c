//! End-to-end tests of the `hbn` command, run in-process through `hbn_cli::run_with`:
//! simulate -> train -> inspect -> estimate -> eval, the committed fixture (state at 30 Hz,
//! input at 100 Hz), the resampling notice, and the demo.

use std::path::Path;

use hbn_io::{ReadOptions, SignalPath};

/// Runs `hbn ARGS`; returns the result, stdout and stderr.
fn hbn(args: &[&str]) -> (hbn_cli::anyhow::Result<()>, String, String) {
    let mut out = Vec::new();
    let mut err = Vec::new();
    let full: Vec<&str> = std::iter::once("hbn").chain(args.iter().copied()).collect();
    let r = hbn_cli::run_with(full, &mut out, &mut err);
    (
        r,
        String::from_utf8_lossy(&out).into_owned(),
        String::from_utf8_lossy(&err).into_owned(),
    )
}

/// Runs `hbn ARGS`, which must succeed; returns stdout and stderr.
fn ok(args: &[&str]) -> (String, String) {
    let (r, out, err) = hbn(args);
    if let Err(e) = r {
        panic!("hbn {args:?} failed: {e:#}\nstdout: {out}\nstderr: {err}");
    }
    (out, err)
}

fn p(dir: &Path, name: &str) -> String {
    dir.join(name).to_string_lossy().into_owned()
}

#[test]
fn simulate_train_inspect_estimate_eval() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path();
    let (a, b, test) = (p(dir, "a.mcap"), p(dir, "b.mcap"), p(dir, "test.mcap"));
    let sim = |seed: &str, input_seed: &str, steps: &str, enc: &str, out: &str| {
        ok(&[
            "simulate",
            "--system",
            "bouc-wen",
            "--steps",
            steps,
            "--seed",
            seed,
            "--input-seed",
            input_seed,
            "--noise-gain",
            "1",
            "--encoding",
            enc,
            "--out",
            out,
        ])
    };
    // Two training logs with the same input and independent noise, one per encoding.
    let (s, _) = sim("11", "5", "800", "json", &a);
    assert!(s.contains("800 bouc-wen samples"), "{s}");
    sim("12", "5", "800", "ros2", &b);
    sim("13", "99", "600", "ros2", &test);
    let topics = hbn_io::list_topics(Path::new(&b)).expect("topics");
    let names: Vec<&str> = topics.iter().map(|t| t.topic.as_str()).collect();
    assert_eq!(names, ["/input", "/sensor", "/state"]);
    assert!(
        topics
            .iter()
            .all(|t| t.message_encoding == "cdr" && t.message_count == 800)
    );

    let model = p(dir, "model.hbn");
    let (out, err) = ok(&[
        "train",
        "--log",
        &a,
        "--log",
        &b,
        "--max-points",
        "250",
        "--seed",
        "3",
        "--out",
        &model,
    ]);
    assert!(err.contains("using 100.0 Hz"), "rate notice: {err}");
    assert!(out.contains("1600 samples at 100.0 Hz"), "{out}");
    assert!(
        out.contains("transition GP") && out.contains("LML"),
        "{out}"
    );
    // Filter-aware training: the held-out table, both modes, the default marked.
    assert!(
        out.contains("filter tuned on held-out data")
            && out.contains("the last 400 of 1600 samples held out")
            && out.contains("default mode"),
        "{out}"
    );

    // inspect, text and JSON.
    let (out, _) = ok(&["inspect", &model]);
    for needle in [
        "/input.data",
        "/state.data",
        "/sensor.data",
        "100.0 Hz",
        "length scales",
        "BLR index",
        "observability",
    ] {
        assert!(out.contains(needle), "inspect lacks {needle:?}: {out}");
    }
    let (out, _) = ok(&["inspect", &model, "--json"]);
    let v: serde_json::Value = serde_json::from_str(&out).expect("inspect JSON");
    assert_eq!(v["rate_hz"], 100.0);
    assert_eq!(v["signals"]["input"]["path"], "/input.data");
    assert_eq!(v["transition"]["support_points"], 250);
    assert_eq!(
        v["transition"]["length_scales"].as_array().map(Vec::len),
        Some(4)
    );
    assert_eq!(
        v["sensor"]["length_scales"].as_array().map(Vec::len),
        Some(3)
    );
    assert!(v["blr"]["transition"]["cells"].as_u64().unwrap_or(0) > 0);
    let rows = v["filter"]["validation"]["rows"]
        .as_array()
        .expect("validation rows");
    assert_eq!(rows.len(), hbn_core::Mode::ALL.len());
    let default_mode = v["filter"]["tuning"]["default_mode"]
        .as_str()
        .expect("default mode")
        .to_owned();
    assert_eq!(
        v["filter"]["validation"]["default_mode"],
        default_mode.as_str()
    );
    for r in rows {
        // The search starts from scale 1, so the held-out score can only improve.
        let nlpd = |k: &str| r[k]["calibration"]["nlpd"].as_f64().expect("nlpd");
        assert!(nlpd("tuned") <= nlpd("untuned") + 1e-9, "{r}");
        assert!(r["scales"]["q"].as_f64().is_some_and(|q| q > 0.0), "{r}");
    }

    // estimate to CSV and MCAP.
    let (csv, mcap) = (p(dir, "est.csv"), p(dir, "est.mcap"));
    let (out, err) = ok(&[
        "estimate", "--model", &model, "--log", &test, "--mode", "ekf-blr", "--csv", &csv, "--out",
        &mcap,
    ]);
    assert!(out.contains("ekf-blr: 600 samples"), "{out}");
    assert!(!err.contains("resampling"), "same rate: no notice: {err}");
    let text = std::fs::read_to_string(&csv).expect("csv");
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("t,x,x_std,y_pred,innovation,nis,flags,flag_names")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 600);
    assert!(rows.iter().all(|r| r.len() == 8));
    // The flag names spell out the bit mask.
    for r in &rows {
        let bits: u32 = r[6].parse().expect("flags");
        let names: Vec<&str> = hbn_core::Flags(bits).names().collect();
        assert_eq!(r[7], names.join("|"));
    }
    assert!(rows[0][7].contains("initialised"), "{:?}", rows[0]);
    assert_eq!(rows[0][0], "0");
    let t_last: f64 = rows[599][0].parse().expect("t");
    assert!((t_last - 5.99).abs() < 1e-9, "{t_last}");
    assert!(
        rows.iter().all(|r| r[6].parse::<u32>().is_ok()),
        "flags are integers"
    );
    assert!(
        rows.iter()
            .all(|r| r[1].parse::<f64>().map(f64::is_finite).unwrap_or(false)),
        "x is finite"
    );
    let topics = hbn_io::list_topics(Path::new(&mcap)).expect("topics");
    assert_eq!(topics.len(), 1);
    assert_eq!(topics[0].topic, "/hbn/estimate");
    assert_eq!(topics[0].message_count, 600);
    assert_eq!(topics[0].schema_encoding.as_deref(), Some("jsonschema"));
    let paths: Vec<SignalPath> = ["/hbn/estimate.x", "/hbn/estimate.flags"]
        .iter()
        .map(|s| s.parse().expect("path"))
        .collect();
    let sig = hbn_io::read_signals(Path::new(&mcap), &paths, &ReadOptions::default())
        .expect("read estimate");
    assert_eq!(sig[0].value.len(), 600);
    // On the input log's clock: the simulated log starts at 1 s.
    assert_eq!(sig[0].t_ns[0], 1_000_000_000);
    assert_eq!(sig[0].t_ns[599], 1_000_000_000 + 599 * 10_000_000);
    let csv_x0: f64 = rows[0][1].parse().expect("x");
    assert_eq!(sig[0].value[0], csv_x0);

    // Without --mode, estimate runs the model's default mode (chosen on held-out data).
    let (csv_default, csv_named) = (p(dir, "default.csv"), p(dir, "named.csv"));
    let (out, _) = ok(&[
        "estimate",
        "--model",
        &model,
        "--log",
        &test,
        "--csv",
        &csv_default,
    ]);
    assert!(
        out.contains(&format!("{default_mode}: 600 samples")),
        "{out}"
    );
    ok(&[
        "estimate",
        "--model",
        &model,
        "--log",
        &test,
        "--mode",
        &default_mode,
        "--csv",
        &csv_named,
    ]);
    assert_eq!(
        std::fs::read_to_string(&csv_default).expect("csv"),
        std::fs::read_to_string(&csv_named).expect("csv")
    );

    // eval --json and a plot.
    let png = p(dir, "eval.png");
    let (out, _) = ok(&[
        "eval", "--model", &model, "--log", &test, "--json", "--plot", &png,
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).expect("eval JSON");
    let n = |k: &str| v["nrmse"][k].as_f64().expect(k);
    assert_eq!(v["samples"], 600);
    assert_eq!(v["rate_hz"], 100.0);
    assert!(n("ekf") < n("open_loop"), "{v}");
    assert!(n("ekf") < 0.15, "{v}");
    assert!(n("ekf_blr") < 0.15, "{v}");
    assert!(v["rmse"]["ekf"].as_f64().is_some());
    // Calibration of both filter modes (not of open loop, which has no uncertainty): values in
    // range and consistent with each other (the 2-sigma band holds at least the 1-sigma one).
    for mode in ["ekf", "ekf_blr"] {
        let c = &v["calibration"][mode];
        let f = |k: &str| c[k].as_f64().expect(k);
        assert_eq!(c["samples"], 600, "{c}");
        assert!((0.0..=1.0).contains(&f("coverage_1sigma")), "{c}");
        assert!(f("coverage_2sigma") >= f("coverage_1sigma"), "{c}");
        assert!(f("mean_nees") > 0.0 && f("nlpd").is_finite(), "{c}");
    }
    assert!(v["calibration"].get("open_loop").is_none());
    let bytes = std::fs::read(&png).expect("png");
    assert!(bytes.starts_with(b"\x89PNG"), "PNG written");
    // The table form.
    let (out, _) = ok(&["eval", "--model", &model, "--log", &test, "--mode", "ekf"]);
    // The table names methods as the flags do (`ekf-blr`, not the JSON key `ekf_blr`).
    assert!(out.contains("ekf") && out.contains("open-loop") && !out.contains("ekf-blr"));
    let (all, _) = ok(&["eval", "--model", &model, "--log", &test, "--mode", "all"]);
    assert!(
        all.contains("ekf-blr") && all.contains("ukf") && !all.contains("ekf_blr"),
        "{all}"
    );
    assert!(
        out.contains("in 2 sd") && out.contains("mean NEES"),
        "{out}"
    );

    // Errors leave no output behind and name the topic.
    let bad = p(dir, "bad.csv");
    let (r, _, _) = hbn(&[
        "estimate",
        "--model",
        &model,
        "--log",
        &test,
        "--output",
        "/strain.data",
        "--csv",
        &bad,
    ]);
    let msg = format!("{:#}", r.expect_err("missing topic"));
    assert!(msg.contains("/strain") && msg.contains("/sensor"), "{msg}");
    assert!(!Path::new(&bad).exists());
}

#[test]
fn fixture_with_30hz_state_trains_and_estimates() {
    let fixture = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/json_zstd.mcap");
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path();
    let model = p(dir, "fixture.hbn");
    let (out, err) = ok(&[
        "train",
        "--log",
        fixture,
        "--max-points",
        "120",
        "--starts",
        "1",
        "--max-iters",
        "40",
        "--out",
        &model,
    ]);
    assert!(
        err.contains("resampling /state.data from 30.0 Hz to 100.0 Hz"),
        "{err}"
    );
    assert!(!err.contains("resampling /input.data"), "{err}");
    assert!(out.contains("at 100.0 Hz"), "{out}");
    let csv = p(dir, "fixture.csv");
    let mcap = p(dir, "fixture-est.mcap");
    ok(&[
        "estimate", "--model", &model, "--log", fixture, "--csv", &csv, "--out", &mcap,
    ]);
    let text = std::fs::read_to_string(&csv).expect("csv");
    // /input and /sensor overlap from 5 ms to 3.99 s: 399 points at 100 Hz.
    let rows = text.lines().count() - 1;
    assert!((390..=400).contains(&rows), "{rows} rows");
    // The estimate is on the fixture's clock (T0 = 1.7e9 s, + 5 ms sensor offset).
    let sig = hbn_io::read_signals(
        Path::new(&mcap),
        &["/hbn/estimate.x".parse().expect("path")],
        &ReadOptions::default(),
    )
    .expect("read");
    assert_eq!(sig[0].t_ns[0], 1_700_000_000_000_000_000 + 5_000_000);
    // Header stamps work as the clock too.
    ok(&[
        "estimate",
        "--model",
        &model,
        "--log",
        fixture,
        "--time-source",
        "header",
    ]);
}

#[test]
fn model_rate_differs_from_log_rate_prints_a_notice() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path();
    let (train, test, model) = (p(dir, "t50.mcap"), p(dir, "t100.mcap"), p(dir, "m50.hbn"));
    ok(&[
        "simulate", "--system", "duhem", "--steps", "400", "--rate", "50", "--out", &train,
    ]);
    ok(&[
        "simulate", "--system", "duhem", "--steps", "300", "--seed", "2", "--out", &test,
    ]);
    let (_, err) = ok(&[
        "train",
        "--log",
        &train,
        "--max-points",
        "100",
        "--starts",
        "1",
        "--out",
        &model,
    ]);
    assert!(err.contains("using 50.0 Hz"), "{err}");
    let (out, err) = ok(&["estimate", "--model", &model, "--log", &test]);
    assert!(
        err.contains("resampling /input.data from 100.0 Hz to 50.0 Hz"),
        "{err}"
    );
    assert!(
        err.contains("resampling /sensor.data from 100.0 Hz to 50.0 Hz"),
        "{err}"
    );
    assert!(out.contains("150 samples"), "2.99 s at 50 Hz: {out}");
    // --quiet suppresses notices, not the summary, and not the warning that the log's rate
    // is not the model's.
    let (out, err) = ok(&["--quiet", "estimate", "--model", &model, "--log", &test]);
    assert!(!err.contains("note:"), "{err}");
    assert!(
        err.contains(
            "warning: /input.data is recorded at 100.0 Hz but the model was trained at 50.0 Hz"
        ),
        "{err}"
    );
    assert!(out.contains("150 samples"), "{out}");
}

#[test]
fn demo_writes_everything() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path().join("demo");
    let dir_s = dir.to_string_lossy().into_owned();
    // (How long the demo takes is a benchmark figure, docs/benchmarks.md, not a test: a timed
    // test fails on a loaded machine.)
    let (out, _) = ok(&["-q", "demo", "--out", &dir_s, "--system", "duhem"]);
    for f in [
        "train-1.mcap",
        "train-2.mcap",
        "train-3.mcap",
        "test.mcap",
        "model.hbn",
        "estimate.csv",
        "estimate.mcap",
        "estimate-ekf-blr.csv",
        "estimate-ekf-blr.mcap",
        "eval.png",
    ] {
        assert!(dir.join(f).is_file(), "demo did not write {f}: {out}");
    }
    assert!(out.contains("open-loop") && out.contains("nRMSE"), "{out}");
}
