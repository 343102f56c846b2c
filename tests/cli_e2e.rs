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
        "--inducing",
        "exact",
        // The thesis' sensor, whose inputs the inspect checks below name.
        "--sensor-inputs",
        "thesis",
        "--seed",
        "3",
        "--out",
        &model,
        "--verbose",
    ]);
    assert!(err.contains("using 100.0 Hz"), "rate notice: {err}");
    // Each GP's kernel chosen by evidence, said in the summary.
    assert!(
        out.contains("kernels chosen by evidence (the exact GP's LML): transition ")
            && (out.contains("against matern52") || out.contains("against se-ard")),
        "{out}"
    );
    assert!(out.contains("1600 samples at 100.0 Hz"), "{out}");
    assert!(
        out.contains("transition GP") && out.contains("LML"),
        "{out}"
    );
    // Filter-aware training: the held-out table, both modes, the default marked.
    assert!(
        out.contains("filter tuned on held-out data")
            && out.contains("4 folds: 1600 of 1600 samples held out in turn")
            && out.contains("default mode"),
        "{out}"
    );

    // inspect, text and JSON.
    let (out, _) = ok(&["inspect", &model]);
    // Length scales named by their inputs; the best start counted from 1, as in the JSON.
    assert!(
        out.contains("transition GP: predicts x[k] from x[k-1], x[k-2], u[k-1], u[k-2]")
            && out.contains("sensor GP: predicts y[k] from x[k-1], y[k-1], x[k]"),
        "{out}"
    );
    let ls_line = out
        .lines()
        .find(|l| l.trim_start().starts_with("length scales"))
        .expect("length scales line");
    for name in [
        "x[k-1] ",
        "x[k-2] ",
        "u[k-1] ",
        "u[k-2] ",
        "play(u, 0.05)[k-1] ",
        "play(u, 0.2)[k-1] ",
    ] {
        assert!(ls_line.contains(name), "{ls_line}");
    }
    assert!(out.contains("(subset: farthest-point)"), "{out}");
    assert!(out.contains("docs/glossary.md#"), "{out}");
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
    // The thesis' four inputs and the two default play operators.
    assert_eq!(
        v["transition"]["length_scales"].as_array().map(Vec::len),
        Some(6)
    );
    assert_eq!(
        v["sensor"]["length_scales"].as_array().map(Vec::len),
        Some(3)
    );
    assert_eq!(
        v["transition"]["inputs"],
        serde_json::json!([
            "x[k-1]",
            "x[k-2]",
            "u[k-1]",
            "u[k-2]",
            "play(u, 0.05)[k-1]",
            "play(u, 0.2)[k-1]"
        ])
    );
    assert_eq!(
        v["sensor"]["length_scales_by_input"]["y[k-1]"],
        v["sensor"]["length_scales"][1]
    );
    assert_eq!(
        v["transition"]["training"]["subset_policy"],
        "farthest-point"
    );
    // The text and the JSON number starts alike (from 1).
    for role in ["transition", "sensor"] {
        let best = v[role]["training"]["best_start"]
            .as_u64()
            .expect("best start");
        let n = v[role]["training"]["starts"].as_array().map_or(0, Vec::len);
        assert!((1..=n as u64).contains(&best), "{best} of {n}");
        assert_eq!(v[role]["training"]["starts"][0]["start"], 1);
        let text = ok(&["inspect", &model]).0;
        let section = text.split(&format!("{role} GP:")).nth(1).expect("section");
        assert!(
            section.contains(&format!("best: start {best} of {n}")),
            "{role}: JSON best_start {best}, text: {section}"
        );
    }
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
        // The search starts from scale 1, and scale 1 replaces the learned scales where it
        // scores better on the samples the table shows, so the held-out score can only improve.
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
    assert!(
        out.contains("600 samples at 100.0 Hz (6.00 s, where /input.data and /sensor.data")
            && out.contains("  ekf-blr"),
        "{out}"
    );
    assert!(!err.contains("resampling"), "same rate: no notice: {err}");
    let text = std::fs::read_to_string(&csv).expect("csv");
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some("t,u,y,x,x_std,y_pred,innovation,nis,flags,flag_names")
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 600);
    assert!(rows.iter().all(|r| r.len() == 10));
    // The flag names spell out the bit mask.
    for r in &rows {
        let bits: u32 = r[8].parse().expect("flags");
        let names: Vec<&str> = hbn_core::Flags(bits).names().collect();
        assert_eq!(r[9], names.join("|"), "{r:?}");
    }
    assert!(rows[0][9].contains("initialised"), "{:?}", rows[0]);
    assert_eq!(rows[0][0], "0");
    let t_last: f64 = rows[599][0].parse().expect("t");
    assert!((t_last - 5.99).abs() < 1e-9, "{t_last}");
    assert!(
        rows.iter().all(|r| r[8].parse::<u32>().is_ok()),
        "flags are integers"
    );
    assert!(
        rows.iter().all(|r| r[1..4]
            .iter()
            .all(|c| c.parse::<f64>().is_ok_and(f64::is_finite))),
        "u, y and x are finite"
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
    let csv_x0: f64 = rows[0][3].parse().expect("x");
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
        out.contains(&format!(
            "{default_mode} (the model's default mode): wrote CSV"
        )),
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
    for m in hbn_core::Mode::ALL {
        assert!(
            all.lines().any(|l| l.starts_with(m.name())),
            "{m} missing: {all}"
        );
    }
    assert!(!all.contains("ekf_blr"), "{all}");
    // A short table by default (with the glossary), every column with --verbose.
    assert!(
        out.contains("in 2 sd") && !out.contains("mean NEES") && out.contains("--verbose"),
        "{out}"
    );
    assert!(
        out.contains("terms: docs/glossary.md#rmse-and-nrmse, #2-sigma-coverage"),
        "{out}"
    );
    let (verbose, _) = ok(&[
        "eval",
        "--model",
        &model,
        "--log",
        &test,
        "--mode",
        "ekf",
        "--verbose",
    ]);
    assert!(
        verbose.contains("in 1 sd") && verbose.contains("mean NEES") && verbose.contains("NLPD"),
        "{verbose}"
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
    assert!(out.contains("150 samples at 50.0 Hz (3.00 s"), "{out}");
    // --quiet suppresses notices, not the summary, and not the warning that the log's rate
    // is not the model's.
    let (out, err) = ok(&["--quiet", "estimate", "--model", &model, "--log", &test]);
    assert!(!err.contains("note:"), "{err}");
    assert!(
        err.contains(
            "warning: /input.data is recorded at 100.0 Hz here but at 50.0 Hz in the training logs"
        ),
        "{err}"
    );
    assert!(out.contains("150 samples"), "{out}");
}

/// The sections of the README between a heading and the next heading of the same level.
fn readme_section(readme: &str, heading: &str) -> String {
    let start = readme
        .find(heading)
        .unwrap_or_else(|| panic!("README has no {heading:?}"));
    let rest = &readme[start + heading.len()..];
    let end = rest.find("\n## ").unwrap_or(rest.len());
    rest[..end].to_owned()
}

/// The fenced blocks of `lang` in a Markdown text.
fn fenced(text: &str, lang: &str) -> Vec<String> {
    let open = format!("```{lang}\n");
    let mut out = Vec::new();
    let mut rest = text;
    while let Some(i) = rest.find(&open) {
        let body = &rest[i + open.len()..];
        let j = body.find("```").expect("closed block");
        out.push(body[..j].to_owned());
        rest = &body[j..];
        rest = &rest[3..];
    }
    out
}

/// The README's worked example is what `hbn demo` runs (the same commands, seeds and
/// defaults), and the figures it quotes are what the demo prints, to the printed precision.
/// The plot shows a band per mode.
#[test]
fn demo_is_the_worked_example() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).expect("README");
    let section = readme_section(&readme, "## Worked example");
    let blocks = fenced(&section, "sh");
    let script = blocks.first().expect("the worked example's commands");
    // Shell lines: continuations joined, comments and blank lines dropped, spaces collapsed.
    let joined = script.replace("\\\n", " ");
    let readme_cmds: Vec<String> = joined
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|l| l.split_whitespace().collect::<Vec<_>>().join(" "))
        .collect();
    let demo_cmds: Vec<String> =
        hbn_cli::cmd_demo::commands(&hbn_cli::cli::DemoArgs::default(), Path::new(""))
            .iter()
            .map(|c| hbn_cli::cmd_demo::shell_line(c))
            .collect();
    assert_eq!(
        readme_cmds, demo_cmds,
        "README's worked example vs `hbn demo`"
    );

    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path().join("demo");
    let dir_s = dir.to_string_lossy().into_owned();
    let (out, _) = ok(&["-q", "demo", "--out", &dir_s]);
    for f in [
        "train1.mcap",
        "train2.mcap",
        "train3.mcap",
        "test.mcap",
        "model.hbn",
        "est.csv",
        "est.mcap",
        "eval.png",
    ] {
        assert!(dir.join(f).is_file(), "demo did not write {f}: {out}");
    }
    // Each command is printed before it runs, as the README spells it (in the demo's directory).
    for c in hbn_cli::cmd_demo::commands(&hbn_cli::cli::DemoArgs::default(), &dir) {
        let line = format!("$ {}", hbn_cli::cmd_demo::shell_line(&c));
        assert!(out.contains(&line), "{line} not printed: {out}");
    }
    // The README quotes the eval table exactly as the demo prints it.
    let quoted = fenced(&section, "text");
    let table = quoted.first().expect("the quoted eval output");
    let printed: Vec<&str> = out
        .lines()
        .skip_while(|l| !l.starts_with("method "))
        .take(table.lines().count())
        .collect();
    assert_eq!(
        table.lines().collect::<Vec<_>>(),
        printed,
        "README's quoted figures differ from what `hbn demo` prints:\n{out}"
    );
    // The prose quotes the default mode's held-out coverage: check it against the demo.
    assert!(
        out.contains("default mode ukf: on held-out data nRMSE")
            && out.contains("deviations 96.9% of the time"),
        "README says the default mode holds 96.9% on held-out data: {out}"
    );
    // The plotted band is not collapsed on the test log: the default mode's 2-sd band holds
    // most of the logged state (calibration over many runs is the accuracy report's,
    // docs/accuracy.md).
    let default_row = printed
        .iter()
        .find(|l| {
            l.split_whitespace()
                .next()
                .is_some_and(|m| m.ends_with('*'))
        })
        .expect("the default mode's row");
    let in_2sd: f64 = default_row
        .split_whitespace()
        .last()
        .and_then(|c| c.trim_end_matches('%').parse().ok())
        .expect("in 2 sd column");
    assert!(
        (85.0..=99.0).contains(&in_2sd),
        "default mode's band holds {in_2sd}% of the demo's test log"
    );

    // The plot: a band per mode, in the mode's colour.
    let img = image::open(dir.join("eval.png")).expect("png").to_rgb8();
    for i in 0..hbn_core::Mode::ALL.len() {
        let band = hbn_cli::plot::band_pixel(i);
        // Within 2 levels per channel: the backend's blending rounds its own way.
        let near = |p: &image::Rgb<u8>| p.0.iter().zip(band).all(|(a, b)| a.abs_diff(b) <= 2);
        let n = img.pixels().filter(|p| near(p)).count();
        assert!(n > 500, "mode {i}: {n} pixels of its band colour {band:?}");
    }
}
