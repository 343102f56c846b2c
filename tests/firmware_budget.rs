//! `hbn train --firmware-budget`: a model trained for a flash budget exports, as f32 C, tables
//! that fit it (counted from the generated header, independently of the exporter's own size
//! report), and says so; `hbn export` warns about a model whose flash exceeds 1 MB and says how
//! to train a small one; a budget nothing fits is an error that says what the smallest needs.

use std::path::Path;

/// Runs `hbn ARGS` in-process: `(stdout, stderr)`, or `Err(message)` as `main` prints it.
fn run(args: &[&str]) -> Result<(String, String), String> {
    let mut out = Vec::new();
    let mut err = Vec::new();
    let full: Vec<&str> = std::iter::once("hbn").chain(args.iter().copied()).collect();
    match hbn_cli::run_with(full, &mut out, &mut err) {
        Ok(()) => Ok((
            String::from_utf8_lossy(&out).into_owned(),
            String::from_utf8_lossy(&err).into_owned(),
        )),
        Err(e) => Err(hbn_cli::error_message(&e)),
    }
}

fn ok(args: &[&str]) -> (String, String) {
    run(args).unwrap_or_else(|e| panic!("hbn {args:?} failed: {e}"))
}

fn path(dir: &Path, name: &str) -> String {
    dir.join(name).display().to_string()
}

/// Three simulated logs of 1000 steps (seeds 1 to 3).
fn logs(dir: &Path) -> Vec<String> {
    (1..=3)
        .map(|seed| {
            let log = path(dir, &format!("run{seed}.mcap"));
            ok(&[
                "simulate",
                "-q",
                "--steps",
                "1000",
                "--seed",
                &seed.to_string(),
                "--out",
                &log,
            ]);
            log
        })
        .collect()
}

fn train(logs: &[String], extra: &[&str], out: &str) -> Result<(String, String), String> {
    let mut args = vec!["train", "-q"];
    for l in logs {
        args.extend(["--log", l.as_str()]);
    }
    args.extend_from_slice(extra);
    args.extend(["--out", out]);
    run(&args)
}

/// A `#define NAME value` of a generated header, as a number.
fn define(header: &str, name: &str) -> usize {
    header
        .lines()
        .find_map(|l| l.strip_prefix(&format!("#define {name} ")))
        .map(|v| v.trim().trim_end_matches('u').parse().unwrap())
        .unwrap_or_else(|| panic!("no {name} in\n{header}"))
}

#[test]
fn a_16kb_budget_exports_f32_tables_within_16kb() {
    let dir = tempfile::tempdir().unwrap();
    let logs = logs(dir.path());
    let model = path(dir.path(), "small.hbn");
    let (summary, _) = train(&logs, &["--firmware-budget", "16KB"], &model)
        .unwrap_or_else(|e| panic!("training failed: {e}"));
    println!("{summary}");
    assert!(
        summary.contains("firmware budget 16384 bytes (16.0 KB)"),
        "{summary}"
    );
    assert!(
        summary.contains("flash") && summary.contains("RAM"),
        "{summary}"
    );
    let saved = std::fs::read_to_string(&model).unwrap();
    assert!(
        saved.contains("\"firmware_budget\":16384"),
        "the model keeps its budget"
    );

    let out = dir.path().join("c");
    let (text, _) = ok(&[
        "export",
        "--model",
        &model,
        "--format",
        "c",
        "--precision",
        "f32",
        "--out",
        &out.display().to_string(),
    ]);
    println!("{text}");
    let header = std::fs::read_to_string(out.join("hbn_model.h")).unwrap();
    assert_eq!(define(&header, "HBN_MODEL_REAL_BITS"), 32);
    // The constant tables as the C file declares them: u32 layout, u64 keys, f32 reals.
    let flash = 4 * define(&header, "HBN_MODEL_LAYOUT_LEN")
        + 8 * define(&header, "HBN_MODEL_KEYS_LEN")
        + 4 * define(&header, "HBN_MODEL_REALS_LEN");
    assert!(flash <= 16 * 1024, "flash {flash} bytes over 16 KB");
    assert!(
        text.contains(&format!("model data {flash} bytes")),
        "{text}"
    );
    assert!(
        text.contains("firmware budget is 16384 bytes (16.0 KB): within it"),
        "{text}"
    );
}

#[test]
fn an_export_over_1mb_warns_and_says_how_to_train_a_small_one() {
    let dir = tempfile::tempdir().unwrap();
    let logs = logs(dir.path());
    let model = path(dir.path(), "exact.hbn");
    // Exact GPs on 500 support points each: a packed Cholesky factor of 125,250 reals per GP.
    train(
        &logs,
        &["--inducing", "exact", "--validation", "0", "--starts", "1"],
        &model,
    )
    .unwrap_or_else(|e| panic!("training failed: {e}"));
    let out = path(dir.path(), "c");
    let (text, warnings) = ok(&[
        "export", "--model", &model, "--format", "c", "--mode", "ekf", "--out", &out,
    ]);
    assert!(!text.contains("firmware budget"), "{text}");
    assert!(warnings.contains("MB of flash"), "{warnings}");
    assert!(warnings.contains("--firmware-budget 64KB"), "{warnings}");
    assert!(warnings.contains("--inducing 32"), "{warnings}");
}

#[test]
fn budgets_that_cannot_be_read_or_met_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = path(dir.path(), "m.hbn");
    let e = train(&["x.mcap".into()], &["--firmware-budget", "16GB"], &out).unwrap_err();
    assert!(e.contains("16KB") && e.contains("--firmware-budget"), "{e}");
    let logs = logs(dir.path());
    let e = train(&logs, &["--firmware-budget", "1KB"], &out).unwrap_err();
    assert!(
        e.contains("no model fits a firmware budget of 1024 bytes"),
        "{e}"
    );
    assert!(
        !Path::new(&out).exists(),
        "no model file after a failed training"
    );
}
