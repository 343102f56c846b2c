//! `hbn explore`: simulate a first batch -> train -> plan a schedule; the schedule keeps the
//! bounds and the increment bound from the last logged input on, is written as CSV and MCAP
//! (readable by hbn's own reader), and bad flags are named with nothing written.

use std::path::Path;

mod common;
use common::hbn;

/// A first batch (400 samples of bouc-wen) and a model trained on it.
fn first_batch() -> (tempfile::TempDir, String, String) {
    let d = tempfile::tempdir().expect("tempdir");
    let p = |n: &str| d.path().join(n).to_string_lossy().into_owned();
    let (log, model) = (p("batch1.mcap"), p("m.hbn"));
    let (e, _) = hbn(&["simulate", "--steps", "400", "--out", &log]);
    assert!(e.is_none(), "{e:?}");
    let (e, _) = hbn(&[
        "train",
        "--log",
        &log,
        "--max-points",
        "80",
        "--starts",
        "1",
        "--validation",
        "0",
        "--out",
        &model,
    ]);
    assert!(e.is_none(), "{e:?}");
    (d, log, model)
}

fn last_logged_input(log: &str) -> f64 {
    let path: hbn_io::SignalPath = "/input.data".parse().expect("path");
    let raw = hbn_io::read_signals(Path::new(log), &[path], &hbn_io::ReadOptions::default())
        .expect("read the log");
    *raw[0].value.last().expect("samples")
}

/// The inputs of a schedule's CSV (column `u`).
fn planned_inputs(csv: &Path) -> Vec<f64> {
    let text = std::fs::read_to_string(csv).expect("csv");
    text.lines()
        .skip(1)
        .map(|l| l.split(',').nth(1).expect("u").parse().expect("number"))
        .collect()
}

/// The bounds of `hbn simulate`'s input ([0, 1], steps up to 0.02), from the log's last input.
fn assert_within_the_logs_bounds(u: &[f64], log: &str) {
    let mut prev = last_logged_input(log);
    for &v in u {
        assert!((0.0..=1.0).contains(&v), "{v}");
        assert!((v - prev).abs() <= 0.02, "{prev} -> {v}");
        prev = v;
    }
}

#[test]
fn a_schedule_keeps_its_bounds_and_is_written_as_csv_and_mcap() {
    let (d, log, model) = first_batch();
    let csv = d.path().join("plan.csv");
    let mcap = d.path().join("plan.mcap");
    let (e, out) = hbn(&[
        "explore",
        "--model",
        &model,
        "--log",
        &log,
        "--samples",
        "600",
        "--u-min",
        "0.1",
        "--u-max",
        "0.9",
        "--max-step",
        "0.015",
        "--out",
        csv.to_str().expect("utf8"),
        "--out",
        mcap.to_str().expect("utf8"),
    ]);
    assert!(e.is_none(), "{e:?}");
    assert!(out.contains("planned 600 samples"), "{out}");
    let text = std::fs::read_to_string(&csv).expect("csv written");
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some(hbn_pipeline::explore::SCHEDULE_CSV_HEADER)
    );
    let rows: Vec<[f64; 3]> = lines
        .map(|l| {
            let v: Vec<f64> = l.split(',').map(|c| c.parse().expect("number")).collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    assert_eq!(rows.len(), 600);
    let mut prev = last_logged_input(&log).clamp(0.1, 0.9);
    let start = last_logged_input(&log);
    assert!(
        (0.1..=0.9).contains(&start),
        "test setup: the log ends inside the bounds"
    );
    for (k, r) in rows.iter().enumerate() {
        assert!((r[0] - k as f64 / 100.0).abs() < 1e-9, "time of row {k}");
        assert!((0.1..=0.9).contains(&r[1]), "u[{k}] = {}", r[1]);
        assert!(
            (r[1] - prev).abs() <= 0.015,
            "step {k}: {} -> {}",
            prev,
            r[1]
        );
        assert!(r[2].is_finite());
        prev = r[1];
    }
    let lo = rows.iter().map(|r| r[1]).fold(f64::INFINITY, f64::min);
    let hi = rows.iter().map(|r| r[1]).fold(f64::NEG_INFINITY, f64::max);
    assert!(hi - lo > 0.5, "the plan explores: u in [{lo}, {hi}]");
    // The MCAP holds the same inputs on /explore/u.
    let path: hbn_io::SignalPath = "/explore/u.data".parse().expect("path");
    let raw = hbn_io::read_signals(&mcap, &[path], &hbn_io::ReadOptions::default())
        .expect("the schedule MCAP reads back");
    let u_mcap: Vec<f64> = raw[0].value.clone();
    let u_csv: Vec<f64> = rows.iter().map(|r| r[1]).collect();
    assert_eq!(u_mcap.len(), 600);
    for (a, b) in u_mcap.iter().zip(&u_csv) {
        assert!((a - b).abs() <= 1e-12 * a.abs().max(1.0), "{a} vs {b}");
    }
}

#[test]
fn bounds_left_out_come_from_the_logs() {
    let (d, log, model) = first_batch();
    let csv = d.path().join("plan.csv");
    let (e, out) = hbn(&[
        "explore",
        "--model",
        &model,
        "--log",
        &log,
        "--samples",
        "300",
        "--out",
        csv.to_str().expect("utf8"),
    ]);
    assert!(e.is_none(), "{e:?}");
    // hbn simulate's input lies in [0, 1] with steps below 0.02.
    assert_within_the_logs_bounds(&planned_inputs(&csv), &log);
    assert!(out.contains("steps <= 0.01"), "{out}");
}

#[test]
fn the_criterion_flag_scores_the_seeking_ramps() {
    // Same model, log and seed: the plans differ once a seeking choice is scored, and both
    // keep the bounds.
    let (d, log, model) = first_batch();
    let plan = |criterion: &str| {
        let csv = d.path().join(format!("plan-{criterion}.csv"));
        let (e, _) = hbn(&[
            "explore",
            "--model",
            &model,
            "--log",
            &log,
            "--samples",
            "400",
            "--alpha-start",
            "1",
            "--alpha-end",
            "1",
            "--criterion",
            criterion,
            "--out",
            csv.to_str().expect("utf8"),
        ]);
        assert!(e.is_none(), "{criterion}: {e:?}");
        let u = planned_inputs(&csv);
        assert_within_the_logs_bounds(&u, &log);
        u
    };
    assert_ne!(plan("variance"), plan("reduction"));
}

#[test]
fn bad_flags_are_named_and_nothing_is_written() {
    let (d, log, model) = first_batch();
    let csv = d.path().join("plan.csv");
    let csv_s = csv.to_str().expect("utf8").to_owned();
    let base = |extra: &[&str]| {
        let mut a = vec![
            "explore",
            "--model",
            &model,
            "--log",
            &log,
            "--samples",
            "50",
            "--out",
            &csv_s,
        ];
        a.extend_from_slice(extra);
        hbn(&a)
    };
    for (extra, needle) in [
        (&["--max-step", "0"][..], "invalid --max-step"),
        (&["--u-min", "0.8", "--u-max", "0.2"][..], "invalid --u-max"),
        (&["--alpha-end", "1.5"][..], "invalid --alpha-end"),
        (&["--horizon", "0"][..], "invalid --horizon"),
        (&["--candidates", "1"][..], "invalid --candidates"),
        (&["--pool", "1"][..], "invalid --pool"),
        (&["--refit-every", "0"][..], "invalid --refit-every"),
        (&["--criterion", "entropy"][..], "--criterion"),
    ] {
        let (e, _) = base(extra);
        let e = e.unwrap_or_else(|| panic!("{extra:?} must fail"));
        assert!(e.contains(needle), "{extra:?}: {e}");
        assert!(!csv.exists(), "{extra:?} left a file behind");
    }
    let (e, _) = hbn(&[
        "explore",
        "--model",
        &model,
        "--log",
        &log,
        "--samples",
        "0",
        "--out",
        &csv_s,
    ]);
    assert!(e.expect("fails").contains("--samples"));
    let missing = d.path().join("nope.mcap");
    let (e, _) = hbn(&[
        "explore",
        "--model",
        &model,
        "--log",
        missing.to_str().expect("utf8"),
        "--samples",
        "10",
        "--out",
        &csv_s,
    ]);
    assert!(e.expect("fails").contains("nope.mcap"));
    let no_dir = d.path().join("no/such/dir/plan.csv");
    let (e, _) = base(&[]);
    assert!(e.is_none(), "{e:?}");
    std::fs::remove_file(&csv).expect("written");
    let (e, _) = hbn(&[
        "explore",
        "--model",
        &model,
        "--log",
        &log,
        "--samples",
        "10",
        "--out",
        no_dir.to_str().expect("utf8"),
    ]);
    assert!(e.expect("fails").contains("does not exist"));
    let leftovers: Vec<_> = std::fs::read_dir(d.path())
        .expect("dir")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !["batch1.mcap", "m.hbn"].contains(&n.as_str()))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}
