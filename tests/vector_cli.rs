//! A vector model through the CLI: `hbn simulate --system finger`, `hbn train` with repeated
//! `--input`, `--state` and `--output` flags (and with none, finding the simulated log's
//! signals, and with sensor inputs given per sensor), `hbn estimate --csv [--covariance]` with
//! the per-component columns and `--out` with arrays, `--smooth` in `hbn estimate` and
//! `hbn eval`, `hbn eval`'s table per component and plot, and `hbn inspect` listing every GP.

use std::path::Path;

/// Runs `hbn ARGS` in-process; returns the result and stdout.
fn hbn(args: &[&str]) -> (hbn_cli::anyhow::Result<()>, String) {
    let (r, out, _) = hbn_with_stderr(args);
    (r, out)
}

/// [`hbn`], with stderr (notes and warnings) as well.
fn hbn_with_stderr(args: &[&str]) -> (hbn_cli::anyhow::Result<()>, String, String) {
    let mut out = Vec::new();
    let mut err = Vec::new();
    let full: Vec<&str> = std::iter::once("hbn").chain(args.iter().copied()).collect();
    let r = hbn_cli::run_with(full, &mut out, &mut err);
    let text = |b: &[u8]| String::from_utf8_lossy(b).into_owned();
    (r, text(&out), text(&err))
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

#[test]
fn a_finger_trains_and_estimates_through_the_cli() {
    let d = tempfile::tempdir().expect("tempdir");
    let (train, test) = (d.path().join("train.mcap"), d.path().join("test.mcap"));
    for (file, seed) in [(&train, "1"), (&test, "9")] {
        let (r, _) = hbn(&[
            "simulate",
            "--system",
            "finger",
            "--steps",
            "1200",
            "--noise-gain",
            "1",
            "--seed",
            seed,
            "--out",
            s(file),
        ]);
        r.expect("simulate");
    }
    let model = d.path().join("finger.json");
    let (r, out, err) = hbn_with_stderr(&[
        "train",
        "--log",
        s(&train),
        "--input",
        "/input0.data",
        "--input",
        "/input1.data",
        "--state",
        "/state.x0",
        "--state",
        "/state.x1",
        "--output",
        "/sensor0.data",
        "--output",
        "/sensor1.data",
        "--output",
        "/sensor2.data",
        "--max-points",
        "200",
        "--kernel",
        "matern52,se-ard",
        "--out",
        s(&model),
    ]);
    r.expect("train");
    assert!(
        out.contains("2 inputs, 2 state components, 3 sensors"),
        "{out}"
    );
    // The note names the candidates before they train.
    assert!(
        err.contains("model selection: training 6 vector candidates side by side (exact lags none"),
        "{err}"
    );
    // The candidates (exact and m = 64, each with the lags none, 0.1 s, 1 s) trained side by
    // side: the summary names the one kept.
    let chosen = out
        .lines()
        .find(|l| l.contains("chosen on held-out data"))
        .unwrap_or_default();
    let kept = ["lags none", "lags 0.1 s", "lags 1 s"]
        .iter()
        .flat_map(|l| ["exact", "m=64"].map(|g| format!("{l}, GPs {g}")));
    assert!(kept.clone().any(|l| chosen.ends_with(&l)), "{out}");
    let csv = d.path().join("est.csv");
    let (r, out) = hbn(&[
        "estimate",
        "--model",
        s(&model),
        "--log",
        s(&test),
        "--csv",
        s(&csv),
        "--covariance",
    ]);
    r.expect("estimate");
    assert!(
        out.contains("estimated 2 state components over 1200 samples"),
        "{out}"
    );
    // `--json`: the same run's summary as JSON, with the sizes and the mode.
    let (r, out) = hbn(&[
        "-q",
        "estimate",
        "--model",
        s(&model),
        "--log",
        s(&test),
        "--json",
    ]);
    r.expect("estimate --json");
    let v: serde_json::Value = serde_json::from_str(&out).expect("JSON summary");
    assert_eq!(v["samples"], 1200, "{out}");
    assert_eq!(
        (
            v["inputs"].clone(),
            v["states"].clone(),
            v["sensors"].clone()
        ),
        (2.into(), 2.into(), 3.into())
    );
    assert_eq!(
        v["estimates"][0]["unobservable"].as_array().map(Vec::len),
        Some(2)
    );
    assert!(v["estimates"][0]["mode"].is_string(), "{out}");
    let text = std::fs::read_to_string(&csv).expect("csv");
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some(
            "t,x0,x0_std,x1,x1_std,cov_x0_x1,y0_pred,innovation0,y1_pred,innovation1,\
             y2_pred,innovation2,nis,flags,flag_names"
        )
    );
    let rows: Vec<Vec<String>> = lines
        .map(|l| l.split(',').map(str::to_owned).collect())
        .collect();
    assert_eq!(rows.len(), 1200);
    // The estimate follows the simulated state: read it back and score component 0.
    let truth = hbn_io::read_signals(
        &test,
        &[
            "/state.x0".parse().expect("path"),
            "/state.x1".parse().expect("path"),
        ],
        &hbn_io::ReadOptions::default(),
    )
    .expect("read");
    for (i, sig) in truth.iter().enumerate() {
        let est: Vec<f64> = rows
            .iter()
            .map(|r| r[1 + 2 * i].parse().expect("x"))
            .collect();
        let n = est.len().min(sig.value.len());
        let span = sig.value.iter().cloned().fold(f64::MIN, f64::max)
            - sig.value.iter().cloned().fold(f64::MAX, f64::min);
        let rmse = (est[..n]
            .iter()
            .zip(&sig.value[..n])
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / n as f64)
            .sqrt();
        assert!(rmse / span < 0.1, "component {i}: nRMSE {}", rmse / span);
    }
    // Without flags, training finds the simulated log's signals.
    let model2 = d.path().join("finger2.json");
    let (r, out) = hbn(&[
        "train",
        "--log",
        s(&train),
        "--max-points",
        "200",
        "--out",
        s(&model2),
    ]);
    r.expect("train without flags");
    assert!(
        out.contains("/input1.data") && out.contains("/state.x1") && out.contains("/sensor2.data"),
        "{out}"
    );
    // `hbn eval` prints a table per component (with the plot), `hbn inspect` every GP.
    let png = d.path().join("eval.png");
    let (r, out) = hbn(&[
        "eval",
        "--model",
        s(&model),
        "--log",
        s(&test),
        "--plot",
        s(&png),
    ]);
    r.expect("eval");
    assert!(out.contains("state component 0 (/state.x0)"), "{out}");
    assert!(out.contains("state component 1 (/state.x1)"), "{out}");
    assert!(out.matches("ekf").count() >= 2, "{out}");
    assert!(std::fs::metadata(&png).expect("plot").len() > 10_000);
    let (r, out) = hbn(&["inspect", s(&model)]);
    r.expect("inspect");
    for gp in [
        "transition 0",
        "transition 1",
        "sensor 0",
        "sensor 1",
        "sensor 2",
    ] {
        assert!(out.contains(gp), "{gp}: {out}");
    }
    // The candidates' table: a row per inducing setting and lag set, one chosen.
    for g in ["exact ", "m=64  "] {
        for lags in ["lags none ", "lags 0.1 s ", "lags 1 s "] {
            let row = format!("  {g} {lags}");
            assert_eq!(out.matches(&row).count(), 1, "{row}: {out}");
        }
    }
    assert_eq!(out.matches("(chosen)").count(), 1, "{out}");
    // Every GP's line names the kernel it uses.
    let gp_lines: Vec<&str> = out
        .lines()
        .skip_while(|l| *l != "GPs:")
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .collect();
    assert_eq!(gp_lines.len(), 2 + 3, "{out}");
    for line in &gp_lines {
        assert!(
            line.contains(": matern52, ") || line.contains(": se-ard, "),
            "{line}"
        );
    }
    // Each GP's kernel chosen by evidence between the two given: a line per GP, one kept.
    let evidence: Vec<&str> = out
        .lines()
        .skip_while(|l| !l.starts_with("kernels chosen by evidence"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .collect();
    assert_eq!(evidence.len(), 2 + 2 * 3, "{out}");
    for line in &evidence {
        assert!(
            line.contains("matern52 ")
                && line.contains("se-ard ")
                && line.matches("(kept)").count() == 1,
            "{line}"
        );
    }
    // The MCAP output carries arrays in the model's order, with the signals' names.
    let mcap = d.path().join("est.mcap");
    let (r, _) = hbn(&[
        "estimate",
        "--model",
        s(&model),
        "--log",
        s(&test),
        "--out",
        s(&mcap),
    ]);
    r.expect("estimate to MCAP");
    let x1 = hbn_io::read_signals(
        &mcap,
        &["/hbn/estimate.x[1]".parse().expect("path")],
        &hbn_io::ReadOptions::default(),
    )
    .expect("read the estimate's second component");
    let csv_x1: Vec<f64> = rows.iter().map(|r| r[3].parse().expect("x1")).collect();
    assert_eq!(x1[0].value, csv_x1);
    // `--smooth`: the CSV's estimate from the whole log (a band never wider than the
    // filter's, the same last sample), and a smoothed row per mode in `hbn eval`.
    let smooth_csv = d.path().join("smoothed.csv");
    let (r, out) = hbn(&[
        "estimate",
        "--model",
        s(&model),
        "--log",
        s(&test),
        "--csv",
        s(&smooth_csv),
        "--covariance",
        "--smooth",
    ]);
    r.expect("estimate --smooth");
    assert!(out.contains("(smoothed)"), "{out}");
    let smoothed: Vec<Vec<f64>> = std::fs::read_to_string(&smooth_csv)
        .expect("smoothed csv")
        .lines()
        .skip(1)
        .map(|l| {
            l.split(',')
                .take(6)
                .map(|v| v.parse().expect("number"))
                .collect()
        })
        .collect();
    assert_eq!(smoothed.len(), rows.len());
    let mut moved = 0;
    for (sm, f) in smoothed.iter().zip(&rows) {
        let f: Vec<f64> = f
            .iter()
            .take(6)
            .map(|v| v.parse().expect("number"))
            .collect();
        for i in 0..2 {
            let (x, sd, fx, fsd) = (sm[1 + 2 * i], sm[2 + 2 * i], f[1 + 2 * i], f[2 + 2 * i]);
            assert!(x.is_finite() && sd <= fsd * (1.0 + 1e-9), "{sm:?} vs {f:?}");
            moved += usize::from((x - fx).abs() > 1e-9 * fx.abs().max(1.0));
        }
    }
    assert!(
        moved > 1000,
        "only {moved} smoothed values differ from the filter's"
    );
    let (last, flast) = (&smoothed[smoothed.len() - 1], &rows[rows.len() - 1]);
    let flast_x0: f64 = flast[1].parse().expect("x0");
    assert!((last[1] - flast_x0).abs() <= 1e-12 * flast_x0.abs().max(1.0));
    let (r, out) = hbn(&["eval", "--model", s(&model), "--log", s(&test), "--smooth"]);
    r.expect("eval --smooth");
    assert_eq!(out.matches("\n  ekf smoothed").count(), 2, "{out}");
    assert!(
        out.contains("each sample estimated from the whole log"),
        "{out}"
    );
    let (r, out) = hbn(&[
        "-q",
        "eval",
        "--model",
        s(&model),
        "--log",
        s(&test),
        "--smooth",
        "--json",
    ]);
    r.expect("eval --smooth --json");
    let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    let runs = v["runs"].as_array().expect("runs");
    assert!(
        runs.iter().any(|r| r["smoothed"] == true) && runs.iter().any(|r| r["smoothed"] == false),
        "{out}"
    );
    // Two logs of equal length: each scored as alone, then pooled (the mean square error and
    // the coverage are the two logs' means).
    let eval_json = |logs: &[&Path]| -> serde_json::Value {
        let mut args = vec![
            "-q",
            "eval",
            "--model",
            s(&model),
            "--mode",
            "ekf",
            "--json",
        ];
        for l in logs {
            args.extend(["--log", s(l)]);
        }
        let (r, out) = hbn(&args);
        r.expect("eval");
        serde_json::from_str(&out).expect("JSON")
    };
    let (on_test, on_train, both) = (
        eval_json(&[&test]),
        eval_json(&[&train]),
        eval_json(&[&test, &train]),
    );
    assert_eq!(both["logs"][0]["runs"], on_test["runs"]);
    assert_eq!(both["pooled"]["samples"], 2400);
    let comps = |v: &serde_json::Value| {
        v["runs"][0]["components"]
            .as_array()
            .expect("components")
            .clone()
    };
    let pooled = comps(&both["pooled"]);
    assert_eq!(pooled.len(), 2);
    for (i, c) in pooled.iter().enumerate() {
        let (a, b) = (&comps(&on_test)[i], &comps(&on_train)[i]);
        let f = |v: &serde_json::Value, k: &str| v[k].as_f64().expect(k);
        let mse = 0.5 * (f(a, "rmse").powi(2) + f(b, "rmse").powi(2));
        assert!((f(c, "rmse") - mse.sqrt()).abs() < 1e-12, "{c} {a} {b}");
        let cov = 0.5 * (f(a, "coverage_2sigma") + f(b, "coverage_2sigma"));
        assert!((f(c, "coverage_2sigma") - cov).abs() < 1e-12, "{c} {a} {b}");
    }
    // Sensor inputs given per sensor are kept.
    let model3 = d.path().join("finger3.json");
    let (r, out) = hbn(&[
        "train",
        "--log",
        s(&train),
        "--max-points",
        "150",
        "--sensor-inputs",
        "state,thesis,state",
        "--out",
        s(&model3),
    ]);
    r.expect("train with sensor inputs per sensor");
    assert!(
        out.contains("sensors 0: state only, 1: thesis inputs, 2: state only"),
        "{out}"
    );
    let (r, _) = hbn(&[
        "train",
        "--log",
        s(&train),
        "--sensor-inputs",
        "state,thesis",
        "--out",
        s(&d.path().join("bad.json")),
    ]);
    let e = format!("{:#}", r.expect_err("two values for three sensors"));
    assert!(e.contains("sensor-inputs"), "{e}");
    // A scalar path count that does not match the model's is refused.
    let (r, _) = hbn(&[
        "estimate",
        "--model",
        s(&model),
        "--log",
        s(&test),
        "--input",
        "/input0.data",
        "--csv",
        s(&d.path().join("x.csv")),
    ]);
    let e = format!("{:#}", r.expect_err("one input for two"));
    assert!(e.contains("one path per signal"), "{e}");
    assert!(!d.path().join("x.csv").exists());
}
