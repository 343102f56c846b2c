//! The `hbn` binary: help texts, exit codes and error messages on bad inputs, and that a
//! failing command leaves no output file behind.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const HBN: &str = env!("CARGO_BIN_EXE_hbn");

fn hbn(dir: &Path, args: &[&str]) -> Output {
    Command::new(HBN)
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run hbn")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// Asserts a clean failure: non-zero exit, no panic, stderr mentions every `needles`, and no
/// file other than `before` in `dir` (no output, no temporary file).
fn assert_fails(dir: &Path, args: &[&str], needles: &[&str]) {
    let before = files(dir);
    let out = hbn(dir, args);
    let err = text(&out.stderr);
    assert!(
        !out.status.success(),
        "{args:?} should fail; stdout: {}",
        text(&out.stdout)
    );
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    assert!(
        err.lines().any(|l| l.starts_with("error")),
        "{args:?}: stderr {err:?}"
    );
    for n in needles {
        assert!(err.contains(n), "{args:?}: stderr lacks {n:?}: {err}");
    }
    assert_eq!(files(dir), before, "{args:?} left files behind");
}

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .expect("read dir")
        .map(|e| e.expect("entry").path())
        .collect();
    v.sort();
    v
}

/// A small valid log written by `hbn simulate`.
fn valid_log(dir: &Path) -> PathBuf {
    let out = hbn(
        dir,
        &[
            "simulate",
            "--system",
            "duhem",
            "--steps",
            "200",
            "--out",
            "valid.mcap",
        ],
    );
    assert!(out.status.success(), "{}", text(&out.stderr));
    dir.join("valid.mcap")
}

/// A JSON log with topics /input, /state, /sensor from explicit samples (one tuple per
/// message: topic, log time, data value as JSON text).
fn custom_log(file: &Path, msgs: &[(&str, u64, &str)]) {
    let mut w = mcap::Writer::new(std::io::BufWriter::new(
        std::fs::File::create(file).expect("create"),
    ))
    .expect("writer");
    let mut ids = BTreeMap::new();
    for t in ["/input", "/state", "/sensor"] {
        let id = w
            .add_channel(0, t, "json", &BTreeMap::new())
            .expect("channel");
        ids.insert(t, id);
    }
    for (k, (topic, t, v)) in msgs.iter().enumerate() {
        let data = format!("{{\"data\": {v}}}");
        w.write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: ids[topic],
                sequence: k as u32,
                log_time: *t,
                publish_time: *t,
            },
            data.as_bytes(),
        )
        .expect("write");
    }
    w.finish().expect("finish");
}

fn regular(n: u64, topic_values: impl Fn(&str, u64) -> String) -> Vec<(String, u64, String)> {
    let mut v = Vec::new();
    for k in 0..n {
        for t in ["/input", "/state", "/sensor"] {
            v.push((
                t.to_owned(),
                1_000_000_000 + k * 10_000_000,
                topic_values(t, k),
            ));
        }
    }
    v
}

fn write_custom(file: &Path, msgs: &[(String, u64, String)]) {
    let m: Vec<(&str, u64, &str)> = msgs
        .iter()
        .map(|(a, b, c)| (a.as_str(), *b, c.as_str()))
        .collect();
    custom_log(file, &m);
}

#[test]
fn help_of_every_subcommand_shows_its_example() {
    let dir = tempfile::tempdir().expect("tempdir");
    let cases = [
        ("simulate", "hbn simulate --system bouc-wen"),
        ("train", "hbn train --log run1.mcap"),
        ("estimate", "hbn estimate --model model.hbn --log test.mcap"),
        ("eval", "hbn eval --model model.hbn --log test.mcap"),
        ("inspect", "hbn inspect model.hbn"),
        ("demo", "hbn demo --out hbn-demo"),
        ("experiment", "hbn experiment --systems"),
    ];
    for (sub, example) in cases {
        let out = hbn(dir.path(), &[sub, "--help"]);
        assert!(out.status.success(), "{sub} --help failed");
        let s = text(&out.stdout);
        assert!(s.contains("Example"), "{sub} --help lacks an example: {s}");
        assert!(s.contains(example), "{sub} --help lacks {example:?}: {s}");
    }
    let out = hbn(dir.path(), &["--help"]);
    assert!(out.status.success());
    assert!(text(&out.stdout).contains("hbn demo"));
    let out = hbn(dir.path(), &["--version"]);
    assert!(out.status.success());
    assert!(text(&out.stdout).contains(env!("CARGO_PKG_VERSION")));
}

#[test]
fn usage_errors_exit_2() {
    let dir = tempfile::tempdir().expect("tempdir");
    for args in [
        &[
            "train", "--kernel", "foo", "--log", "a.mcap", "--out", "m.hbn",
        ][..],
        &["simulate", "--system", "nope", "--out", "x.mcap"],
        &["frobnicate"],
        &["train", "--out", "m.hbn"],
        &[
            "estimate", "--model", "m.hbn", "--log", "x.mcap", "--input", "/a[x",
        ],
    ] {
        let out = hbn(dir.path(), args);
        assert_eq!(
            out.status.code(),
            Some(2),
            "{args:?}: {}",
            text(&out.stderr)
        );
        assert!(!text(&out.stderr).contains("panicked"));
    }
    let out = hbn(
        dir.path(),
        &["train", "--kernel", "foo", "--log", "a", "--out", "b"],
    );
    assert!(text(&out.stderr).contains("se-ard"), "lists the kernels");
    let out = hbn(
        dir.path(),
        &["simulate", "--system", "nope", "--out", "x.mcap"],
    );
    assert!(text(&out.stderr).contains("bouc-wen"), "lists the systems");
}

#[test]
fn bad_logs_fail_cleanly_naming_the_file() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path();
    let valid = valid_log(dir);
    std::fs::write(dir.join("empty.mcap"), b"").expect("write");
    let noise: Vec<u8> = (0..4096u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    std::fs::write(dir.join("random.mcap"), &noise).expect("write");
    let bytes = std::fs::read(&valid).expect("read");
    std::fs::write(dir.join("truncated.mcap"), &bytes[..bytes.len() / 2]).expect("write");

    for log in ["empty.mcap", "random.mcap", "truncated.mcap"] {
        assert_fails(
            dir,
            &["train", "--log", log, "--out", "model.hbn"],
            &[log, "MCAP"],
        );
    }
    assert_fails(
        dir,
        &["train", "--log", "missing.mcap", "--out", "model.hbn"],
        &["missing.mcap"],
    );
    // Missing topic: the message lists the log's topics.
    assert_fails(
        dir,
        &[
            "train",
            "--log",
            "valid.mcap",
            "--state",
            "/angle.data",
            "--out",
            "model.hbn",
        ],
        &["/angle", "valid.mcap", "/input, /sensor, /state"],
    );
    // Missing field: names the path and the fields there.
    assert_fails(
        dir,
        &[
            "train",
            "--log",
            "valid.mcap",
            "--state",
            "/state.value",
            "--out",
            "model.hbn",
        ],
        &["/state.value", "data"],
    );
    // Non-numeric field.
    assert_fails(
        dir,
        &[
            "train",
            "--log",
            "valid.mcap",
            "--state",
            "/state.header",
            "--out",
            "model.hbn",
        ],
        &["/state.header"],
    );
    // Output into a directory that does not exist.
    assert_fails(
        dir,
        &["train", "--log", "valid.mcap", "--out", "nodir/model.hbn"],
        &["nodir"],
    );
    assert_fails(
        dir,
        &["simulate", "--steps", "100", "--out", "nodir/sim.mcap"],
        &["nodir"],
    );
}

#[test]
fn bad_samples_fail_cleanly() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path();
    // A string where a number should be.
    let msgs = regular(100, |t, k| {
        if t == "/state" && k == 50 {
            "\"high\"".into()
        } else {
            format!("{}", k as f64 / 100.0)
        }
    });
    write_custom(&dir.join("string.mcap"), &msgs);
    assert_fails(
        dir,
        &["train", "--log", "string.mcap", "--out", "model.hbn"],
        &["/state.data", "not numeric"],
    );
    // Header stamps going back in time (read with --time-source header).
    let mut msgs = regular(100, |_, k| format!("{}", k as f64 / 100.0));
    for (i, m) in msgs.iter_mut().enumerate() {
        let k = (i / 3) as u64;
        let stamp = if k == 60 {
            100_000_000
        } else {
            1_000_000_000 + k * 10_000_000
        };
        m.2 = format!(
            "{}, \"header\": {{\"stamp\": {{\"sec\": {}, \"nanosec\": {}}}}}",
            k as f64 / 100.0,
            stamp / 1_000_000_000,
            stamp % 1_000_000_000
        );
    }
    write_custom(&dir.join("backwards.mcap"), &msgs);
    assert_fails(
        dir,
        &[
            "train",
            "--log",
            "backwards.mcap",
            "--time-source",
            "header",
            "--out",
            "model.hbn",
        ],
        &["back in time", "--time-source log"],
    );
    // A 3.4 s gap in the state of a 4 s log: a gap splits a log, but neither piece (0.3 s on
    // each side) is long enough to train on, so the gap is the error.
    let msgs: Vec<_> = regular(400, |_, k| format!("{}", k as f64 / 400.0))
        .into_iter()
        .filter(|(t, time, _)| !(t == "/state" && *time > 1_300_000_000 && *time < 4_700_000_000))
        .collect();
    write_custom(&dir.join("gap.mcap"), &msgs);
    assert_fails(
        dir,
        &["train", "--log", "gap.mcap", "--out", "model.hbn"],
        &["/state.data", "gap.mcap", "gap of 3.4", "--max-gap"],
    );
}

/// A ROS 2 (CDR) log whose /state has a NaN sample (JSON cannot encode one).
fn nan_log(file: &Path) {
    let mut w = mcap::Writer::new(std::io::BufWriter::new(
        std::fs::File::create(file).expect("create"),
    ))
    .expect("writer");
    let schema = w
        .add_schema(
            hbn_io::STAMPED_SCALAR_NAME,
            "ros2msg",
            hbn_io::stamped_scalar_ros2msg().as_bytes(),
        )
        .expect("schema");
    let ids: Vec<u16> = ["/input", "/state", "/sensor"]
        .iter()
        .map(|t| {
            w.add_channel(schema, t, "cdr", &BTreeMap::new())
                .expect("channel")
        })
        .collect();
    for k in 0..100u32 {
        for (c, &id) in ids.iter().enumerate() {
            let v = if c == 1 && k == 42 {
                f64::NAN
            } else {
                f64::from(k) / 100.0
            };
            let t = 1_000_000_000 + u64::from(k) * 10_000_000;
            w.write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: id,
                    sequence: k,
                    log_time: t,
                    publish_time: t,
                },
                &hbn_io::stamped_scalar_cdr(1, k * 10_000_000, "", v),
            )
            .expect("write");
        }
    }
    w.finish().expect("finish");
}

#[test]
fn nan_sample_fails_cleanly() {
    let d = tempfile::tempdir().expect("tempdir");
    nan_log(&d.path().join("nan.mcap"));
    assert_fails(
        d.path(),
        &["train", "--log", "nan.mcap", "--out", "model.hbn"],
        &["/state.data", "non-finite", "nan.mcap"],
    );
}

#[test]
fn bad_models_fail_cleanly() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path();
    valid_log(dir);
    std::fs::write(dir.join("notes.hbn"), "just some notes\n").expect("write");
    std::fs::write(
        dir.join("v99.hbn"),
        r#"{"format":"hbn-model","version":99,"model":{}}"#,
    )
    .expect("write");
    std::fs::write(dir.join("other.hbn"), r#"{"format":"something-else"}"#).expect("write");
    for (model, needle) in [
        ("notes.hbn", "not an hbn model"),
        ("valid.mcap", "not an hbn model"),
        ("other.hbn", "not an hbn model"),
        ("v99.hbn", "version 99"),
        ("absent.hbn", "absent.hbn"),
    ] {
        assert_fails(
            dir,
            &[
                "estimate",
                "--model",
                model,
                "--log",
                "valid.mcap",
                "--csv",
                "est.csv",
                "--out",
                "est.mcap",
            ],
            &[model, needle],
        );
        assert_fails(
            dir,
            &[
                "eval",
                "--model",
                model,
                "--log",
                "valid.mcap",
                "--plot",
                "eval.png",
            ],
            &[model, needle],
        );
        assert_fails(dir, &["inspect", model], &[model, needle]);
    }
}

/// Every training parameter and log option is checked once, by the library, before any file
/// is opened: a bad value fails with exit code 1 and a message naming the flag to change (the
/// log does not even exist).
#[test]
fn every_parameter_check_names_its_flag() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path();
    let train = |extra: &[&'static str]| -> Vec<&'static str> {
        let mut a = vec!["train", "--log", "absent.mcap", "--out", "model.hbn"];
        a.extend_from_slice(extra);
        a
    };
    // Names the CLI parses itself (kernels, subset policies, clocks) are usage errors (exit
    // code 2); values the library checks exit with 1. Both name the flag.
    for (args, flag, code) in [
        (train(&["--max-points", "1"]), "--max-points", 1),
        (train(&["--starts", "0"]), "--starts", 1),
        (train(&["--max-iters", "0"]), "--max-iters", 1),
        (train(&["--noise-floor", "0"]), "--noise-floor", 1),
        (train(&["--noise-floor", "nan"]), "--noise-floor", 1),
        (train(&["--blr-window", "0.7"]), "--blr-window", 1),
        (train(&["--blr-window", "0"]), "--blr-window", 1),
        (train(&["--rate", "0"]), "--rate", 1),
        (train(&["--rate", "-5"]), "--rate", 1),
        (train(&["--max-gap", "0"]), "--max-gap", 1),
        (train(&["--max-gap", "inf"]), "--max-gap", 1),
        (train(&["--kernel", "rbf"]), "--kernel", 2),
        (train(&["--subset", "all"]), "--subset", 2),
        (train(&["--linear-mean", "sensor"]), "--linear-mean", 2),
        (
            train(&["--max-signal-variance", "0"]),
            "--max-signal-variance",
            1,
        ),
        (
            train(&["--max-signal-variance", "lots"]),
            "--max-signal-variance",
            2,
        ),
        (train(&["--time-source", "gps"]), "--time-source", 2),
    ] {
        let out = hbn(dir, &args);
        let err = text(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{args:?}: {err}");
        assert!(err.contains(flag), "{args:?}: stderr lacks {flag}: {err}");
        assert!(
            !err.contains("absent.mcap"),
            "{args:?} read the log first: {err}"
        );
    }
}
