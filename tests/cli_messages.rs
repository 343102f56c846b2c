//! The CLI's messages as a user reads them (issue: what a new user meets): each error said
//! once, flags rather than internal names, bare `hbn` as a usage error.

use std::path::Path;

mod common;
use common::hbn;

#[test]
fn bare_hbn_is_a_usage_error() {
    let mut out = Vec::new();
    let mut err = Vec::new();
    let r = hbn_cli::run_with(["hbn"], &mut out, &mut err);
    let e = r.expect_err("bare hbn does nothing: a usage error");
    // It shows the help: the usage and the commands.
    let text = hbn_cli::error_message(&e);
    assert!(
        text.contains("Usage:") && text.contains("demo") && text.contains("estimate"),
        "{text}"
    );
    assert_eq!(hbn_cli::main_exit_code(Err(e)), 2);
}

/// Writes a log of `n` samples at 100 Hz with `/input`, `/state` and `/sensor` (each `.data`).
fn write_log(file: &Path, u: &[f64], x: &[f64], y: &[f64]) {
    let t = hbn_pipeline::log_times(u.len(), 100.0);
    let topics = [
        hbn_io::ScalarTopic {
            topic: "/input",
            values: u,
        },
        hbn_io::ScalarTopic {
            topic: "/state",
            values: x,
        },
        hbn_io::ScalarTopic {
            topic: "/sensor",
            values: y,
        },
    ];
    hbn_io::write_scalar_log(file, &t, &topics, hbn_io::Encoding::Json).expect("write");
}

/// `hbn train` of a small model from `log` into `out`, with `extra` flags.
fn train_small(log: &str, out: &str, extra: &[&str]) -> (Option<String>, String) {
    let mut a = vec![
        "train",
        "--log",
        log,
        "--max-points",
        "50",
        "--starts",
        "1",
        "--out",
        out,
    ];
    a.extend_from_slice(extra);
    hbn(&a)
}

/// A small model trained on a simulated log; returns (dir, log, model).
/// `hbn inspect MODEL --json`, parsed (the command must succeed).
fn inspect(model: &str) -> serde_json::Value {
    let (e, out) = hbn(&["inspect", model, "--json"]);
    assert!(e.is_none(), "{e:?}");
    serde_json::from_str(&out).unwrap()
}

fn small_model() -> (tempfile::TempDir, String, String) {
    let d = tempfile::tempdir().expect("tempdir");
    let p = |n: &str| d.path().join(n).to_string_lossy().into_owned();
    let (log, model) = (p("a.mcap"), p("m.hbn"));
    let (e, _) = hbn(&["simulate", "--steps", "300", "--out", &log]);
    assert!(e.is_none(), "{e:?}");
    let (e, _) = train_small(&log, &model, &[]);
    assert!(e.is_none(), "{e:?}");
    (d, log, model)
}

#[test]
fn a_constant_target_is_said_once() {
    let d = tempfile::tempdir().expect("tempdir");
    let log = d.path().join("flat.mcap");
    let u: Vec<f64> = (0..200).map(|k| (k as f64 * 0.05).sin()).collect();
    let x = vec![0.5; u.len()];
    write_log(&log, &u, &x, &u);
    let model = d.path().join("m.hbn");
    let (e, _) = hbn(&[
        "train",
        "--log",
        &log.to_string_lossy(),
        "--max-points",
        "50",
        "--starts",
        "1",
        "--out",
        &model.to_string_lossy(),
    ]);
    let e = e.expect("a constant state cannot be learned");
    assert_eq!(e.matches("constant").count(), 1, "{e}");
    assert!(!model.exists());
}

#[test]
fn every_mode_is_spelled_as_its_flag() {
    use hbn_cli::cli::{Cli, Command, ModeChoice};
    use hbn_core::Mode;
    let parse = |cmd: &str, mode: &str| -> Option<ModeChoice> {
        let c = <Cli as clap::Parser>::try_parse_from([
            "hbn", cmd, "--model", "m", "--log", "l", "--mode", mode,
        ])
        .ok()?;
        match c.command {
            Command::Estimate(a) => a.mode,
            Command::Eval(a) => Some(a.mode),
            _ => None,
        }
    };
    for m in Mode::ALL {
        assert_eq!(parse("estimate", m.name()), Some(ModeChoice::One(m)));
        assert_eq!(parse("eval", m.name()), Some(ModeChoice::One(m)));
    }
    // `all` is accepted by estimate as by eval.
    assert_eq!(parse("estimate", "all"), Some(ModeChoice::All));
    assert_eq!(parse("eval", "all"), Some(ModeChoice::All));
    assert_eq!(ModeChoice::All.modes(), Mode::ALL.to_vec());
    // The help lists every mode by the same name.
    let (e, _) = hbn(&["estimate", "--mode", "nope", "--model", "m", "--log", "l"]);
    let e = e.expect("unknown mode");
    for m in Mode::ALL {
        assert!(e.contains(m.name()), "{e}");
    }
    // Tables and summaries use the same names (`ekf-blr`, not `ekf_blr` or `EKF+BLR`).
    let (_d, log, model) = small_model();
    let (_, out) = hbn(&["inspect", &model]);
    let (_, eval) = hbn(&["eval", "--model", &model, "--log", &log]);
    for text in [&out, &eval] {
        for m in Mode::ALL {
            assert!(text.contains(m.name()), "{m}: {text}");
        }
        assert!(
            !text.contains("ekf_blr") && !text.contains("EKF+BLR"),
            "{text}"
        );
    }
    let table = hbn_pipeline::experiment::markdown_table(&[]);
    assert!(
        table.contains("nRMSE ekf-blr") && !table.contains("EKF"),
        "{table}"
    );
}

#[test]
fn estimate_mode_all_writes_one_file_per_mode() {
    let (d, log, model) = small_model();
    let p = |n: &str| d.path().join(n).to_string_lossy().into_owned();
    let (e, out) = hbn(&[
        "estimate",
        "--model",
        &model,
        "--log",
        &log,
        "--mode",
        "all",
        "--csv",
        &p("est.csv"),
        "--out",
        &p("est.mcap"),
    ]);
    assert!(e.is_none(), "{e:?}");
    assert!(!d.path().join("est.csv").exists() && !d.path().join("est.mcap").exists());
    let mut csvs = Vec::new();
    for m in hbn_core::Mode::ALL {
        let csv = d.path().join(format!("est-{}.csv", m.name()));
        let mcap = d.path().join(format!("est-{}.mcap", m.name()));
        let text = std::fs::read_to_string(&csv).expect("a CSV per mode");
        assert!(text.starts_with(hbn_pipeline::CSV_HEADER), "{text}");
        assert!(mcap.is_file(), "{}", mcap.display());
        assert!(
            out.contains(&format!("`{}`", csv.display())),
            "{m} not in the summary: {out}"
        );
        csvs.push(text);
    }
    // Each file holds its own mode's estimate, the same as a run of that mode alone.
    let single = p("single.csv");
    let mode = hbn_core::Mode::ALL[1];
    let (e, _) = hbn(&[
        "estimate",
        "--model",
        &model,
        "--log",
        &log,
        "--mode",
        mode.name(),
        "--csv",
        &single,
    ]);
    assert!(e.is_none(), "{e:?}");
    assert_eq!(std::fs::read_to_string(&single).expect("csv"), csvs[1]);
    assert_ne!(csvs[0], csvs[1]);
}

#[test]
fn signal_mismatches_name_the_flags_in_estimate_and_eval() {
    let (_d, log, model) = small_model();
    for (cmd, flag) in [
        ("estimate", "--output"),
        ("eval", "--output"),
        ("eval", "--state"),
        ("eval", "--input"),
    ] {
        let (e, _) = hbn(&[cmd, "--model", &model, "--log", &log, flag, "/nope.data"]);
        let e = e.unwrap_or_else(|| panic!("{cmd} {flag}: a missing topic"));
        assert_eq!(e.matches("/nope").count(), 1, "{e}");
        assert!(
            e.contains("--input") && e.contains("--output") && e.contains("--state"),
            "{cmd} {flag}: {e}"
        );
    }
}

/// The same log gives fewer samples to `eval` than to `estimate` when the state covers a
/// shorter span; both say which signals the span is common to.
#[test]
fn sample_counts_explain_their_span() {
    let fixture = concat!(env!("CARGO_MANIFEST_DIR"), "/fixtures/json_zstd.mcap");
    let d = tempfile::tempdir().expect("tempdir");
    let model = d.path().join("m.hbn").to_string_lossy().into_owned();
    let (e, _) = hbn(&[
        "train",
        "--log",
        fixture,
        "--max-points",
        "60",
        "--starts",
        "1",
        "--max-iters",
        "30",
        "--out",
        &model,
    ]);
    assert!(e.is_none(), "{e:?}");
    let count = |text: &str, after: &str| -> usize {
        let head = text.split(" samples at ").next().unwrap_or("");
        head.rsplit(after)
            .next()
            .unwrap_or("")
            .trim()
            .parse()
            .expect("count")
    };
    let (_, est) = hbn(&["estimate", "--model", &model, "--log", fixture]);
    assert!(
        est.contains("where /input.data and /sensor.data both have data"),
        "{est}"
    );
    let (_, ev) = hbn(&["eval", "--model", &model, "--log", fixture]);
    assert!(
        ev.contains("where /input.data, /state.data and /sensor.data all have data"),
        "{ev}"
    );
    let (n_est, n_eval) = (count(&est, ":"), count(&ev, ":"));
    assert!(n_eval < n_est, "estimate {n_est}, eval {n_eval}");
}

#[test]
fn details_are_behind_verbose_and_json() {
    let (_d, log, model) = small_model();
    let (_, out) = hbn(&["estimate", "--model", &model, "--log", &log]);
    assert!(
        !out.contains("NIS") && out.contains("--verbose"),
        "short by default: {out}"
    );
    let (_, out) = hbn(&["estimate", "--model", &model, "--log", &log, "--verbose"]);
    assert!(
        out.contains("mean NIS")
            && out.contains("guard flags")
            && out.contains("docs/glossary.md#nis"),
        "{out}"
    );
    let (e, out) = hbn(&["estimate", "--model", &model, "--log", &log, "--json"]);
    assert!(e.is_none(), "{e:?}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("estimate JSON");
    assert_eq!(v["samples"], 300);
    assert_eq!(
        v["estimates"][0]["default_mode"], true,
        "without --mode: the model's default: {v}"
    );
    assert!(v["estimates"][0]["mean_nis"].as_f64().is_some(), "{v}");
    let d = tempfile::tempdir().expect("tempdir");
    let m2 = d.path().join("m2.hbn").to_string_lossy().into_owned();
    let train = |extra: &str| {
        let extra: &[&str] = if extra.is_empty() { &[] } else { &[extra] };
        train_small(&log, &m2, extra)
    };
    let (_, short) = train("");
    assert!(
        short.contains("default mode") && !short.contains("LML") && short.contains("--verbose"),
        "{short}"
    );
    let (_, long) = train("--verbose");
    // Each GP's fit (its LML, or its bound when held-out data chose the sparse GPs).
    assert!(
        (long.contains("LML") || long.contains("bound"))
            && long.contains("Q scale")
            && long.contains("docs/glossary.md#"),
        "{long}"
    );
    let (_, json) = train("--json");
    let v: serde_json::Value = serde_json::from_str(&json).expect("train JSON");
    assert_eq!(v["samples"], 300);
    assert!(v["transition"]["length_scales"].is_array(), "{v}");
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
fn reading_errors_name_the_flag_and_the_python_keyword() {
    let gap = hbn_io::IoError::Gap {
        path: "/input.data".into(),
        at_s: -0.25,
        gap_s: 1.5,
        max_gap_s: 0.5,
    }
    .to_string();
    assert!(
        gap.contains("`--max-gap`") && gap.contains("`max_gap_s=`"),
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
        "--verbose",
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
    // A log's length is its samples over the rate, as `simulate` says (not the last sample's
    // time), and never confused with computing time.
    let (_, out) = hbn(&["estimate", "--model", &p("m.hbn"), "--log", &p("a.mcap")]);
    assert!(
        out.contains("300 samples at 100.0 Hz (3.00 s, where"),
        "{out}"
    );
    assert!(!out.contains("2.99 s") && !out.contains("took"), "{out}");
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

/// `--inducing` and `--kernel` take lists: model selection on held-out data, its table in the
/// train summary and in `hbn inspect`; without held-out data the first is trained, with a warning.
#[test]
fn model_selection_lists_print_their_table() {
    let (d, log, _) = small_model();
    let m2 = d.path().join("sel.hbn").to_string_lossy().into_owned();
    let train = |extra: &[&str]| train_small(&log, &m2, extra);
    let mut out = Vec::new();
    let mut err = Vec::new();
    let args = [
        "hbn",
        "train",
        "--log",
        &log,
        "--max-points",
        "50",
        "--starts",
        "1",
        "--out",
        &m2,
        "--inducing",
        "exact,4",
        "--verbose",
    ];
    hbn_cli::run_with(args, &mut out, &mut err).expect("train with four candidates");
    let (out, err) = (String::from_utf8_lossy(&out), String::from_utf8_lossy(&err));
    // The kernels are chosen by evidence before the candidates train, so the notice names
    // the candidates without them (it once named Matern 5/2 for candidates that became SE-ARD).
    assert!(
        err.contains(
            "model selection: training 4 candidates side by side (exact, m=4, m=4 lags=1, \
             exact sensor=memory, each GP's kernel chosen by evidence first)"
        ),
        "announced on stderr: {err}"
    );
    // The sparse GPs also with the default lag set, the exact ones with a sensor with memory.
    assert!(
        out.contains("model selection, 4 candidates")
            && out.contains(" exact")
            && out.contains(" m=4 ")
            && out.contains(" m=4 lags=1")
            && out.contains(" exact sensor=memory"),
        "{out}"
    );
    assert_eq!(out.matches("* chosen").count(), 1, "{out}");
    let (e, out) = hbn(&["inspect", &m2]);
    assert!(e.is_none(), "{e:?}");
    assert!(out.contains("model selection, 4 candidates"), "{out}");
    // `--lags` given once trains that set alone; given again, the others are tried.
    let (e, out) = train(&[
        "--inducing",
        "exact,4",
        "--lags",
        "none",
        "--sensor-inputs",
        "thesis",
        "--verbose",
    ]);
    assert!(e.is_none(), "{e:?}");
    assert!(out.contains("model selection, 2 candidates"), "{out}");
    let (e, out) = train(&[
        "--inducing",
        "4",
        "--lags",
        "none",
        "--lags",
        "0.5",
        "--sensor-inputs",
        "thesis",
        "--verbose",
    ]);
    assert!(e.is_none(), "{e:?}");
    assert!(
        out.contains("model selection, 2 candidates") && out.contains(" m=4 lags=0.5"),
        "{out}"
    );
    // Without held-out data nothing is chosen: the first candidate is trained, and the
    // summary says why.
    let (e, out) = train(&["--inducing", "exact,4", "--validation", "0"]);
    assert!(e.is_none(), "{e:?}");
    assert!(
        out.contains("no model selection: validation is 0") && out.contains(" exact) trained"),
        "{out}"
    );
    let (e, _) = train(&["--kernel", "matern52,rbf"]);
    let text = e.expect("unknown kernel");
    assert!(text.contains("--kernel") && text.contains("rbf"), "{text}");
}

#[test]
fn memory_flag_sets_the_play_operators_and_names_itself_when_wrong() {
    let (_dir, log, m) = small_model();
    let dir = tempfile::tempdir().unwrap();
    let m2 = dir.path().join("m2.hbn").to_string_lossy().into_owned();
    let inspect_memory = |model: &str| {
        let (e, out) = hbn(&["inspect", model, "--json"]);
        assert!(e.is_none(), "{e:?}");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        assert_eq!(
            v["memory"]["radii"].as_array().map(|a| a.len()),
            v["memory"]["fractions"].as_array().map(|a| a.len())
        );
        v["memory"]["fractions"].clone()
    };
    // The default model reads the default play operators.
    assert_eq!(inspect_memory(&m), serde_json::json!([0.05, 0.2]));
    let (e, _) = train_small(&log, &m2, &["--memory", "none"]);
    assert!(e.is_none(), "{e:?}");
    assert_eq!(inspect_memory(&m2), serde_json::json!([]));
    let (e, _) = train_small(&log, &m2, &["--memory", "0.1,0.3,0.5"]);
    assert!(e.is_none(), "{e:?}");
    assert_eq!(inspect_memory(&m2), serde_json::json!([0.1, 0.3, 0.5]));
    for bad in ["0", "1.5", "0.1,x", "0.1,0.2,0.3,0.4,0.5"] {
        let (e, _) = train_small(&log, &m2, &["--memory", bad]);
        let text = e.unwrap_or_else(|| panic!("--memory {bad} accepted"));
        assert!(text.contains("--memory"), "{bad}: {text}");
    }
}

#[test]
fn lags_flag_sets_the_low_pass_inputs_and_names_itself_when_wrong() {
    let (_dir, log, m) = small_model();
    let dir = tempfile::tempdir().unwrap();
    let m2 = dir.path().join("m2.hbn").to_string_lossy().into_owned();
    // The default model has none.
    assert_eq!(inspect(&m)["memory"]["lag_seconds"], serde_json::json!([]));
    let (e, _) = train_small(&log, &m2, &["--lags", "0.5,2"]);
    assert!(e.is_none(), "{e:?}");
    let v = inspect(&m2);
    assert_eq!(v["memory"]["lag_seconds"], serde_json::json!([0.5, 2.0]));
    let a = v["memory"]["lag_coefficients"].as_array().unwrap();
    assert_eq!(a.len(), 2);
    // 100 Hz: a = 1 - exp(-1 / 50) for 0.5 s.
    let a0 = a[0].as_f64().unwrap();
    assert!((a0 - (1.0 - (-0.02f64).exp())).abs() < 1e-12, "{a0}");
    // The transition's inputs name the lags after the plays.
    let names: Vec<String> = v["transition"]["inputs"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|n| n.as_str().map(String::from))
                .collect()
        })
        .unwrap_or_default();
    assert!(names.iter().any(|n| n.starts_with("lag(")), "{names:?}");
    // Bad values, and too many plays and lags together, name the flag.
    for bad in [
        &["--lags", "0"][..],
        &["--lags", "1,x"],
        &["--lags", "1,2,3"],
    ] {
        let (e, _) = train_small(&log, &m2, bad);
        let text = e.unwrap_or_else(|| panic!("{bad:?} accepted"));
        assert!(text.contains("--lags"), "{bad:?}: {text}");
    }
}

#[test]
fn sensor_inputs_flag_sets_what_the_sensor_reads_and_names_itself_when_wrong() {
    let (_dir, log, m) = small_model();
    let dir = tempfile::tempdir().unwrap();
    let m2 = dir.path().join("m2.hbn").to_string_lossy().into_owned();
    let sensor_inputs = |v: &serde_json::Value| -> Vec<String> {
        v["sensor"]["inputs"]
            .as_array()
            .map(|a| {
                a.iter()
                    .filter_map(|n| n.as_str().map(String::from))
                    .collect()
            })
            .unwrap_or_default()
    };
    // The default model's sensor is one of the two: with memory of the state, or the thesis'.
    let default = sensor_inputs(&inspect(&m));
    assert!(
        default[0] == "x[k]" && default[1].starts_with("play(x, ") || default[1] == "y[k-1]",
        "{default:?}"
    );
    let (e, _) = train_small(&log, &m2, &["--sensor-inputs", "memory"]);
    assert!(e.is_none(), "{e:?}");
    assert_eq!(
        sensor_inputs(&inspect(&m2)),
        ["x[k]", "play(x, 0.05)[k]", "play(x, 0.2)[k]"]
    );
    let (e, _) = train_small(&log, &m2, &["--sensor-inputs", "thesis"]);
    assert!(e.is_none(), "{e:?}");
    assert_eq!(sensor_inputs(&inspect(&m2)), ["x[k-1]", "y[k-1]", "x[k]"]);
    let (e, _) = train_small(&log, &m2, &["--sensor-inputs", "state"]);
    assert!(e.is_none(), "{e:?}");
    let v = inspect(&m2);
    let names = sensor_inputs(&v);
    assert_eq!(names.len(), 2, "{names:?}");
    assert!(
        names[0].ends_with("[k-1]") && names[1].ends_with("[k]"),
        "{names:?}"
    );
    assert_eq!(
        v["sensor"]["length_scales"].as_array().map(|a| a.len()),
        Some(2)
    );
    // The estimate runs on it.
    let est = dir.path().join("e.csv").to_string_lossy().into_owned();
    let (e, _) = hbn(&["estimate", "--model", &m2, "--log", &log, "--csv", &est]);
    assert!(e.is_none(), "{e:?}");
    // Listed by the user without held-out data: the first one trains, and the summary says so.
    let (e, out) = train_small(
        &log,
        &m2,
        &["--sensor-inputs", "state,thesis", "--validation", "0"],
    );
    assert!(e.is_none(), "{e:?}");
    assert!(
        out.contains("no model selection: validation is 0")
            && out.contains("sensor=state) trained"),
        "{out}"
    );
    assert_eq!(sensor_inputs(&inspect(&m2)).len(), 2);
    for bad in ["level", "thesis,x"] {
        let (e, _) = train_small(&log, &m2, &["--sensor-inputs", bad]);
        let text = e.unwrap_or_else(|| panic!("--sensor-inputs {bad} accepted"));
        assert!(
            text.contains("--sensor-inputs")
                && text.contains("thesis, state")
                && text.contains("memory"),
            "{bad}: {text}"
        );
    }
}

#[test]
fn linear_mean_flag_sets_the_gps_prior_means_and_inspect_shows_them() {
    let (_dir, log, m) = small_model();
    let dir = tempfile::tempdir().unwrap();
    let m2 = dir.path().join("m2.hbn").to_string_lossy().into_owned();
    let v = inspect(&m);
    for gp in ["transition", "sensor"] {
        assert_eq!(v[gp]["mean"], "constant", "{gp}");
        assert_eq!(v[gp]["linear_slopes"], serde_json::json!([]), "{gp}");
    }
    for (choice, linear) in [("transition", [true, false]), ("both", [true, true])] {
        let (e, _) = train_small(&log, &m2, &["--linear-mean", choice]);
        assert!(e.is_none(), "{e:?}");
        let v = inspect(&m2);
        for (gp, want) in ["transition", "sensor"].into_iter().zip(linear) {
            let slopes = v[gp]["linear_slopes"].as_array().unwrap();
            if want {
                assert_eq!(v[gp]["mean"], "linear", "{choice} {gp}");
                assert_eq!(slopes.len(), v[gp]["inputs"].as_array().unwrap().len());
            } else {
                assert_eq!(v[gp]["mean"], "constant", "{choice} {gp}");
                assert!(slopes.is_empty());
            }
        }
    }
    let (e, text) = hbn(&["inspect", &m2]);
    assert!(e.is_none(), "{e:?}");
    assert!(text.contains("linear mean       slopes"), "{text}");
}
