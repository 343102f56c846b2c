//! The CLI's messages as a user reads them (issue: what a new user meets): each error said
//! once, flags rather than internal names, bare `hbn` as a usage error.

use std::path::Path;

/// Runs `hbn ARGS` in-process; returns the error line `main` would print (if any) and stdout.
fn hbn(args: &[&str]) -> (Option<String>, String) {
    let mut out = Vec::new();
    let mut err = Vec::new();
    let full: Vec<&str> = std::iter::once("hbn").chain(args.iter().copied()).collect();
    let r = hbn_cli::run_with(full, &mut out, &mut err);
    (
        r.err().map(|e| hbn_cli::error_message(&e)),
        String::from_utf8_lossy(&out).into_owned(),
    )
}

#[test]
fn bare_hbn_is_a_usage_error() {
    let mut out = Vec::new();
    let mut err = Vec::new();
    let r = hbn_cli::run_with(["hbn"], &mut out, &mut err);
    let e = r.expect_err("bare hbn does nothing: a usage error");
    assert_eq!(hbn_cli::main_exit_code(Err(e)), 2);
}

#[test]
fn an_os_error_is_said_once() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path().to_string_lossy().into_owned();
    let log = d.path().join("log.mcap");
    let model = d.path().join("model.hbn");
    let (e, _) = hbn(&[
        "simulate",
        "--steps",
        "300",
        "--out",
        &log.to_string_lossy(),
    ]);
    assert!(e.is_none(), "{e:?}");
    let (e, _) = hbn(&[
        "train",
        "--log",
        &log.to_string_lossy(),
        "--max-points",
        "50",
        "--starts",
        "1",
        "--validation",
        "0",
        "--out",
        &model.to_string_lossy(),
    ]);
    assert!(e.is_none(), "{e:?}");
    for args in [
        vec![
            "estimate",
            "--model",
            &*model.to_string_lossy(),
            "--log",
            &dir,
        ],
        vec![
            "estimate",
            "--model",
            &dir,
            "--log",
            &*log.to_string_lossy(),
        ],
        vec!["inspect", &dir],
    ] {
        let (e, _) = hbn(&args);
        let e = e.expect("a directory is not a file");
        assert_eq!(e.matches("os error 21").count(), 1, "{e}");
        assert!(e.contains(&dir), "{e}");
    }
    // A topic the log does not have: said once, with the flags that choose signals.
    let (e, _) = hbn(&[
        "estimate",
        "--model",
        &model.to_string_lossy(),
        "--log",
        &log.to_string_lossy(),
        "--input",
        "/nope.data",
    ]);
    let e = e.expect("missing topic");
    assert_eq!(e.matches("is not in").count(), 1, "{e}");
    assert!(e.contains("--input") && e.contains("--output"), "{e}");
}

#[test]
fn reading_errors_name_flags_not_rust_names() {
    let gap = hbn_io::IoError::Gap {
        path: "/input.data".into(),
        at_s: -0.25,
        gap_s: 1.5,
        max_gap_s: 0.5,
    }
    .to_string();
    assert!(
        gap.contains("--max-gap") && !gap.contains("max_gap_s"),
        "{gap}"
    );
    assert!(
        gap.contains("0.250 s before") && !gap.contains("-0.25"),
        "{gap}"
    );
    let back = hbn_io::IoError::TimeBackwards {
        path: "/input.data".into(),
        t_prev: 2,
        t: 1,
    }
    .to_string();
    assert!(
        back.contains("--time-source log") && !back.contains("TimeSource::"),
        "{back}"
    );
}

#[test]
fn summaries_count_in_words() {
    let d = tempfile::tempdir().expect("tempdir");
    let p = |n: &str| d.path().join(n).to_string_lossy().into_owned();
    hbn(&["simulate", "--steps", "300", "--out", &p("a.mcap")]);
    let (e, out) = hbn(&[
        "train",
        "--log",
        &p("a.mcap"),
        "--max-points",
        "50",
        "--starts",
        "1",
        "--validation",
        "0",
        "--out",
        &p("m.hbn"),
    ]);
    assert!(e.is_none(), "{e:?}");
    assert!(
        out.contains("from 1 log:") && out.contains("training took"),
        "{out}"
    );
    // Keeping a subset of support points is normal, not a warning; optimiser stops are said
    // in words, not argmin's.
    assert!(
        out.contains("support points (chosen from 298 samples by farthest-point selection)"),
        "{out}"
    );
    assert!(
        !out.contains("warning:") && !out.contains("solver exit"),
        "{out}"
    );
    let (_, out) = hbn(&["inspect", &p("m.hbn")]);
    assert!(out.contains("trained on 1 trajectory,"), "{out}");
    // Length scales named by the input they belong to.
    assert!(out.contains("length scales     x[k-1] "), "{out}");
    assert!(
        out.contains("u[k-2] ") && out.contains("y[k-1] ") && out.contains("x[k] "),
        "{out}"
    );
    let (_, out) = hbn(&["estimate", "--model", &p("m.hbn"), "--log", &p("a.mcap")]);
    assert!(out.contains("s log)"), "{out}");
    assert!(Path::new(&p("m.hbn")).exists());
}

#[test]
fn eval_on_a_log_without_the_state_points_to_estimate() {
    let d = tempfile::tempdir().expect("tempdir");
    let p = |n: &str| d.path().join(n).to_string_lossy().into_owned();
    hbn(&["simulate", "--steps", "300", "--out", &p("a.mcap")]);
    hbn(&[
        "train",
        "--log",
        &p("a.mcap"),
        "--max-points",
        "50",
        "--starts",
        "1",
        "--validation",
        "0",
        "--out",
        &p("m.hbn"),
    ]);
    // A run-time log: input and sensor, no state.
    let u: Vec<f64> = (0..200)
        .map(|k| 0.5 + 0.3 * (k as f64 * 0.05).sin())
        .collect();
    let t = hbn_pipeline::log_times(u.len(), 100.0);
    let topics = [
        hbn_io::ScalarTopic {
            topic: "/input",
            values: &u,
        },
        hbn_io::ScalarTopic {
            topic: "/sensor",
            values: &u,
        },
    ];
    hbn_io::write_scalar_log(
        Path::new(&p("run.mcap")),
        &t,
        &topics,
        hbn_io::Encoding::Json,
    )
    .expect("write");
    let (e, _) = hbn(&["eval", "--model", &p("m.hbn"), "--log", &p("run.mcap")]);
    let e = e.expect("no state to score against");
    assert!(
        e.contains("does not record the state") && e.contains("hbn estimate"),
        "{e}"
    );
    let (e, _) = hbn(&["estimate", "--model", &p("m.hbn"), "--log", &p("run.mcap")]);
    assert!(e.is_none(), "{e:?}");
}
