//! The firmware path end to end, as docs/firmware.md shows it: simulate an MCAP log, train
//! sparse (m = 32) and exact models, `hbn estimate --csv`, `hbn export` as C and Rust in f64
//! and f32, build the C example (`make -C examples/firmware-c`, cc and the hbn-ffi static
//! library) and the no_std Rust example, feed them the `u` and `y` columns of `hbn estimate`'s
//! CSV (the C program reads that CSV itself; the Rust runner gets the two columns, as
//! `cut -d, -f2,3 est.csv` writes them), and compare with the CSV's estimate:
//!
//! - f64: equal bit for bit (x, x_std and flags);
//! - f32: max |dx| at most [`F32_BOUND`] (2%) of the range of `hbn estimate`'s x, every
//!   model. The sparse models' estimates are ill-conditioned in the model's reals
//!   (multiplying every real by `1 +- 1e-8` moves x by a few percent of its range,
//!   docs/firmware.md); the f32 tables keep the reals they are sensitive to in two f32 parts
//!   (the split ranges of `hbn_core::tables`), which keeps them within the bound.
//!
//! Also the export's error messages, and that a failed export leaves nothing behind.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use hbn::pipeline::{LogOption, SignalChoice, read_at_model_rate};

/// Bound on max |x_f32 - x_f64| as a fraction of the range of x. The test prints what it
/// measures for each model; the export keeps the reals f32 would move by over 1% in two parts,
/// which keeps every model far inside the bound (docs/firmware.md).
const F32_BOUND: f64 = 0.02;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

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

/// [`run`]'s stdout.
fn hbn(args: &[&str]) -> Result<String, String> {
    run(args).map(|(out, _)| out)
}

/// [`run`], which must succeed.
fn ok_with_stderr(args: &[&str]) -> (String, String) {
    run(args).unwrap_or_else(|e| panic!("hbn {args:?} failed: {e}"))
}

fn ok(args: &[&str]) -> String {
    ok_with_stderr(args).0
}

/// The named columns of a CSV, as text: a header line naming them, then each row's fields.
fn columns(text: &str, names: &[&str]) -> String {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let cols: Vec<usize> = names
        .iter()
        .map(|n| header.iter().position(|h| h == n).expect(n))
        .collect();
    let mut out = names.join(",") + "\n";
    for l in lines.filter(|l| !l.trim().is_empty()) {
        let v: Vec<&str> = l.split(',').collect();
        out.push_str(&cols.iter().map(|&c| v[c]).collect::<Vec<_>>().join(","));
        out.push('\n');
    }
    out
}

/// `(x, x_std, flags)` rows of a CSV whose header names those columns.
fn read_estimates(text: &str) -> Vec<(f64, f64, u32)> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).expect(name);
    let (cx, cs, cf) = (col("x"), col("x_std"), col("flags"));
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<&str> = l.split(',').collect();
            (
                v[cx].parse().expect("x"),
                v[cs].parse().expect("x_std"),
                v[cf].parse().expect("flags"),
            )
        })
        .collect()
}

/// Runs `program` with `input` on stdin; returns stdout.
fn run_with_stdin(program: &mut Command, input: &str) -> String {
    use std::io::Write;
    let mut child = program
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let mut stdin = child.stdin.take().expect("stdin");
    let text = input.to_owned();
    let writer = std::thread::spawn(move || stdin.write_all(text.as_bytes()));
    let out = child.wait_with_output().expect("wait");
    writer.join().expect("join").expect("write stdin");
    assert!(
        out.status.success(),
        "{program:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).expect("utf-8")
}

fn cargo() -> Command {
    Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()))
}

/// The workspace's target directory (this test runs from `target/<profile>/deps`).
fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable");
    exe.ancestors().nth(3).expect("target dir").to_path_buf()
}

fn build_c(model_dir: &Path, build_dir: &Path) -> PathBuf {
    let status = Command::new("make")
        .arg("-s")
        .arg("-C")
        .arg(root().join("examples/firmware-c"))
        .arg(format!("MODEL={}", model_dir.display()))
        .arg(format!("BUILD={}", build_dir.display()))
        .arg(format!("CARGO_TARGET_DIR={}", target_dir().display()))
        .status()
        .expect("run make (is make installed?)");
    assert!(status.success(), "make -C examples/firmware-c failed");
    build_dir.join("hbn-firmware")
}

fn build_rust(model_rs: &Path, no_std_lib: bool) -> PathBuf {
    let manifest = root().join("examples/firmware-rust/Cargo.toml");
    let target = target_dir().join("firmware-rust");
    let mut cmd = cargo();
    cmd.args(["build", "--release", "--quiet", "--manifest-path"])
        .arg(&manifest)
        .arg("--target-dir")
        .arg(&target)
        .env("HBN_MODEL_RS", model_rs);
    if no_std_lib {
        cmd.args(["--no-default-features", "--lib"]);
    }
    let status = cmd.status().expect("cargo build examples/firmware-rust");
    assert!(status.success(), "building examples/firmware-rust failed");
    target.join("release/hbn-firmware-rust")
}

fn range(v: &[(f64, f64, u32)]) -> f64 {
    let (lo, hi) = v
        .iter()
        .fold((f64::MAX, f64::MIN), |(l, h), r| (l.min(r.0), h.max(r.0)));
    hi - lo
}

/// MCAP -> `hbn estimate --csv` -> the `u`, `y` columns -> the C and Rust exports: the f64
/// exports' x, x_std and flags equal the CSV's bit for bit.
#[test]
fn mcap_to_csv_to_firmware_equals_hbn_estimate() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    ok(&[
        "simulate",
        "--system",
        "bouc-wen",
        "--steps",
        "1200",
        "--input-seed",
        "1",
        "--seed",
        "11",
        "--noise-gain",
        "1",
        "--out",
        &p("train.mcap"),
    ]);
    ok(&[
        "simulate",
        "--system",
        "bouc-wen",
        "--steps",
        "400",
        "--input-seed",
        "2",
        "--seed",
        "21",
        "--noise-gain",
        "1",
        "--out",
        &p("test.mcap"),
    ]);
    // (name, training flags)
    let kinds: [(&str, &[&str]); 4] = [
        ("sparse", &["--inducing", "32", "--memory", "none"]),
        (
            "sparse-linear",
            &["--inducing", "32", "--linear-mean", "both"],
        ),
        ("sparse-memory", &["--inducing", "32", "--lags", "1"]),
        ("exact", &["--inducing", "exact", "--max-points", "150"]),
    ];
    let mut f32_report = Vec::new();
    let train = p("train.mcap");
    for (kind, flags) in kinds {
        let model = p(&format!("{kind}.hbn"));
        let mut args = vec![
            "-q",
            "train",
            "--log",
            &train,
            "--starts",
            "1",
            "--max-iters",
            "60",
            "--out",
            &model,
        ];
        args.extend_from_slice(flags);
        ok(&args);
        let est_csv = p(&format!("{kind}-est.csv"));
        ok(&[
            "-q",
            "estimate",
            "--model",
            &model,
            "--log",
            &p("test.mcap"),
            "--csv",
            &est_csv,
        ]);
        let est_text = std::fs::read_to_string(&est_csv).expect("est.csv");
        let reference = read_estimates(&est_text);
        // The firmware's input: the CSV's u and y, as `cut -d, -f2,3 est.csv` writes them.
        let samples = columns(&est_text, &["u", "y"]);
        assert!(
            est_text.starts_with("t,u,y,") && samples.starts_with("u,y\n"),
            "{samples:.40}"
        );
        // They are the u, y hbn estimate ran on (the log on the model's grid), bit for bit.
        let loaded = hbn::model::HysteresisModel::load(Path::new(&model)).expect("load");
        let log = read_at_model_rate(
            &loaded,
            Path::new(&p("test.mcap")),
            &SignalChoice::default(),
            &[LogOption::Input, LogOption::Output],
            hbn::pipeline::LogOptions::default(),
            &mut |_| {},
        )
        .expect("read the test log");
        let csv_uy: Vec<(f64, f64)> = samples
            .lines()
            .skip(1)
            .map(|l| {
                let (u, y) = l.split_once(',').expect("u,y");
                (u.parse().expect("u"), y.parse().expect("y"))
            })
            .collect();
        assert_eq!(csv_uy.len(), log.column(0).len());
        for (k, (u, y)) in csv_uy.iter().enumerate() {
            assert_eq!(u.to_bits(), log.column(0)[k].to_bits(), "{kind}: u at {k}");
            assert_eq!(y.to_bits(), log.column(1)[k].to_bits(), "{kind}: y at {k}");
        }
        assert_eq!(reference.len(), log.column(0).len());
        let span = range(&reference);

        for precision in ["f64", "f32"] {
            // C
            let c_dir = dir.path().join(format!("{kind}-c-{precision}"));
            let (out, err) = ok_with_stderr(&[
                "export",
                "--model",
                &model,
                "--out",
                &c_dir.to_string_lossy(),
                "--format",
                "c",
                "--precision",
                precision,
            ]);
            assert!(out.contains("model data"), "{out}");
            if precision == "f32" && kind.starts_with("sparse") {
                // A sparse sensor GP's latent variance does not survive one f32 part: the
                // export keeps its factor in two and says so.
                assert!(
                    err.contains("the sensor GP's variance factor is kept in two f32 parts"),
                    "{kind}: {err}"
                );
            }
            let bin = build_c(
                &c_dir,
                &dir.path().join(format!("{kind}-c-{precision}-build")),
            );
            // The documented path feeds the estimate CSV itself (the program takes the columns
            // its header names `u` and `y`); the f32 run gets the two-column file.
            let c_input = if precision == "f64" {
                &est_text
            } else {
                &samples
            };
            let c_out = read_estimates(&run_with_stdin(&mut Command::new(&bin), c_input));
            // Rust
            let rs_dir = dir.path().join(format!("{kind}-rust-{precision}"));
            ok(&[
                "export",
                "--model",
                &model,
                "--out",
                &rs_dir.to_string_lossy(),
                "--format",
                "rust",
                "--precision",
                precision,
            ]);
            let model_rs = rs_dir.join("hbn_model.rs");
            if precision == "f32" && kind == "sparse" {
                build_rust(&model_rs, true); // the library alone, no_std
            }
            let rs_bin = build_rust(&model_rs, false);
            let rs_out = read_estimates(&run_with_stdin(&mut Command::new(&rs_bin), &samples));
            for (lang, got) in [("C", &c_out), ("Rust", &rs_out)] {
                assert_eq!(got.len(), reference.len(), "{kind} {lang} {precision}");
                if precision == "f64" {
                    for (k, (g, r)) in got.iter().zip(&reference).enumerate() {
                        assert_eq!(g.0.to_bits(), r.0.to_bits(), "{kind} {lang} x at {k}");
                        assert_eq!(g.1.to_bits(), r.1.to_bits(), "{kind} {lang} x_std at {k}");
                        assert_eq!(g.2, r.2, "{kind} {lang} flags at {k}");
                    }
                } else {
                    let worst = got
                        .iter()
                        .zip(&reference)
                        .map(|(g, r)| (g.0 - r.0).abs())
                        .fold(0.0, f64::max);
                    f32_report.push(format!(
                        "{kind} {lang} f32: max |dx| = {worst:.3e} = {:.4}% of the x range",
                        100.0 * worst / span
                    ));
                    assert!(
                        worst <= F32_BOUND * span,
                        "{kind} {lang} f32: max |dx| {worst} > {F32_BOUND} of {span}"
                    );
                }
            }
        }
    }
    for line in &f32_report {
        eprintln!("{line}");
    }
}

#[test]
fn export_errors_name_the_flag_and_leave_nothing_behind() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    // A missing model names the file.
    let out = p("out");
    let e = hbn(&[
        "export",
        "--model",
        &p("missing.hbn"),
        "--out",
        &out,
        "--format",
        "c",
    ])
    .expect_err("missing model");
    assert!(e.contains("missing.hbn"), "{e}");
    assert!(!Path::new(&out).exists(), "a failed export created {out}");
    // Bad --format / --precision / --mode values name the flag and the choices.
    for (flag, bad, choices) in [
        ("--format", "python", "rust"),
        ("--precision", "f16", "f32"),
        ("--mode", "kalman", "ekf-blr"),
    ] {
        let mut args = vec!["export", "--model", "m.hbn", "--out", "o", "--format", "c"];
        if flag == "--format" {
            args[6] = bad;
        } else {
            args.extend([flag, bad]);
        }
        let e = hbn(&args).expect_err(bad);
        assert!(
            e.contains(flag) && e.contains(bad) && e.contains(choices),
            "{e}"
        );
    }
    // A model file that is not a model: named, and nothing written.
    std::fs::write(p("junk.hbn"), "{ not json").expect("write");
    let e = hbn(&[
        "export",
        "--model",
        &p("junk.hbn"),
        "--out",
        &out,
        "--format",
        "rust",
    ])
    .expect_err("junk model");
    assert!(e.contains("junk.hbn"), "{e}");
    assert!(!Path::new(&out).exists());
    // --out naming a file: an error naming --out, and the file is untouched.
    ok(&["simulate", "--steps", "300", "--out", &p("a.mcap")]);
    ok(&[
        "-q",
        "train",
        "--log",
        &p("a.mcap"),
        "--inducing",
        "8",
        "--starts",
        "1",
        "--max-iters",
        "20",
        "--validation",
        "0",
        "--out",
        &p("m.hbn"),
    ]);
    std::fs::write(p("file"), "keep").expect("write");
    let e = hbn(&[
        "export",
        "--model",
        &p("m.hbn"),
        "--out",
        &p("file"),
        "--format",
        "c",
    ])
    .expect_err("--out is a file");
    assert!(e.contains("--out") && e.contains("not a directory"), "{e}");
    assert_eq!(std::fs::read_to_string(p("file")).expect("read"), "keep");
    // The success case writes exactly the format's files; inspect shows the size table.
    let ok_dir = p("fw");
    let text = ok(&[
        "export",
        "--model",
        &p("m.hbn"),
        "--out",
        &ok_dir,
        "--format",
        "c",
    ]);
    assert!(text.contains("firmware size per mode"), "{text}");
    let mut names: Vec<String> = std::fs::read_dir(&ok_dir)
        .expect("read_dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["hbn_model.c", "hbn_model.h"]);
    let text = ok(&["inspect", &p("m.hbn")]);
    assert!(
        text.contains("firmware") && text.contains("ekf-blr"),
        "{text}"
    );
}

/// Prints a table of the accuracy of f32 exports and of small m: the README's training
/// protocol (three bouc-wen logs of 1000 samples, one input, fresh noise) and a held-out test
/// log with another input; sparse models with m = 16, 32, 64 and the default exact model, each
/// in its default mode, in f64 and from its f32 tables. Run with
/// `cargo test --release --test firmware -- --ignored --nocapture`.
#[test]
#[ignore = "a measurement (about 2 minutes)"]
fn measure_f32_and_small_m() {
    use hbn::core::Estimator;
    use hbn::core::tables::{Tables, widen};
    use hbn::model::metrics::nrmse;
    use hbn_export::{Precision, model_tables, size_report};

    let dir = tempfile::tempdir().expect("tempdir");
    let p = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    for (log, input_seed, seed) in [
        ("train1.mcap", "1", "11"),
        ("train2.mcap", "1", "12"),
        ("train3.mcap", "1", "13"),
        ("test.mcap", "2", "21"),
    ] {
        ok(&[
            "simulate",
            "--system",
            "bouc-wen",
            "--steps",
            "1000",
            "--input-seed",
            input_seed,
            "--seed",
            seed,
            "--noise-gain",
            "1",
            "--out",
            &p(log),
        ]);
    }
    let logs = [p("train1.mcap"), p("train2.mcap"), p("train3.mcap")];
    eprintln!(
        "| model | mode | nRMSE f64 | nRMSE f32 | max abs(x_f32 - x_f64) / range of x | f32 model data | f32, --init-pairs 100 |"
    );
    eprintln!("|---|---|---|---|---|---|---|");
    for (name, inducing, kernel) in [
        ("m = 16", "16", "matern52"),
        ("m = 32", "32", "matern52"),
        ("m = 64", "64", "matern52"),
        ("exact (500 points)", "exact", "matern52"),
        ("m = 32, se-ard", "32", "se-ard"),
        ("exact, se-ard", "exact", "se-ard"),
    ] {
        let model_file = p(&format!("model-{inducing}-{kernel}.hbn"));
        ok(&[
            "-q",
            "train",
            "--log",
            &logs[0],
            "--log",
            &logs[1],
            "--log",
            &logs[2],
            "--inducing",
            inducing,
            "--kernel",
            kernel,
            "--out",
            &model_file,
        ]);
        let model = hbn::model::HysteresisModel::load(Path::new(&model_file)).expect("load");
        let log = read_at_model_rate(
            &model,
            Path::new(&p("test.mcap")),
            &SignalChoice::default(),
            &[LogOption::Input, LogOption::State, LogOption::Output],
            hbn::pipeline::LogOptions::default(),
            &mut |_| {},
        )
        .expect("read the test log");
        let (u, x, y) = (log.column(0), log.column(1), log.column(2));
        let span =
            x.iter().cloned().fold(f64::MIN, f64::max) - x.iter().cloned().fold(f64::MAX, f64::min);
        let all = size_report(&model, Precision::F32, None).expect("sizes");
        let thin = size_report(&model, Precision::F32, Some(100)).expect("sizes");
        let bytes = |s: &[hbn_export::ModeSize], m: hbn::core::Mode| {
            s.iter().find(|r| r.mode == m).map_or(0, |r| r.model_bytes)
        };
        let default = model.default_mode();
        let mut modes = vec![default];
        if default != hbn::core::Mode::Ekf {
            modes.push(hbn::core::Mode::Ekf);
        }
        for mode in modes {
            let f64_est = model.estimate(u, y, mode).expect("estimate");
            let t = model_tables(&model, mode).expect("tables");
            let r32 = t.reals_f32().expect("f32");
            let mut wide = vec![0.0; r32.len()];
            let reals = widen(&t.layout, &r32, &mut wide).expect("widen");
            let tm = Tables {
                layout: &t.layout,
                keys: &t.keys,
                reals,
            }
            .model()
            .expect("f32 tables");
            let mut scratch = vec![0.0; Estimator::scratch_len(&tm.view)];
            let mut e = Estimator::new(tm.view, tm.config, &mut scratch).expect("estimator");
            let x32: Vec<f64> = u.iter().zip(y).map(|(&u, &y)| e.step(u, y).x).collect();
            let worst = x32
                .iter()
                .zip(&f64_est.x)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
            let star = if mode == default { "*" } else { "" };
            eprintln!(
                "| {name} | {mode}{star} | {:.4} | {:.4} | {:.2}% | {:.1} KB | {:.1} KB |",
                nrmse(&f64_est.x, x),
                nrmse(&x32, x),
                100.0 * worst / span,
                bytes(&all, mode) as f64 / 1024.0,
                bytes(&thin, mode) as f64 / 1024.0,
            );
        }
    }
}
