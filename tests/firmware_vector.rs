//! A vector model on firmware, end to end: `hbn simulate --system finger`, `hbn train` a
//! sparse (m = 32) model of 2 inputs, 2 state components and 3 sensors, `hbn estimate --csv`,
//! `hbn export --format c` and `--format rust` in f64 and f32, build `examples/firmware-c-vector`
//! (cc and the hbn-ffi static library; skipped when there is no C compiler) and
//! `examples/firmware-rust --features vector` (its no_std library, and its CSV runner), feed them
//! the inputs and sensor samples `hbn estimate` ran on, and compare with the CSV's estimate:
//!
//! - f64: x{i}, x{i}_std and flags equal bit for bit;
//! - f32: max |dx{i}| at most [`F32_BOUND`] (2%) of the range of component i's estimate.
//!
//! `hbn estimate --csv` of a vector model writes the estimate, not the samples; the samples
//! come from the same log read the same way (`hbn::pipeline::estimate_vector_log`, whose
//! estimate is checked equal to the CSV's first), written as `u0,u1,y0,y1,y2` with the
//! shortest text that reads back to the same `f64`.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// Bound on max |x_f32 - x_f64| of each component as a fraction of its range.
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

fn ok(args: &[&str]) -> String {
    run(args)
        .unwrap_or_else(|e| panic!("hbn {args:?} failed: {e}"))
        .0
}

/// The named columns of a CSV as numbers, one `Vec` per row.
fn numbers(text: &str, names: &[String]) -> Vec<Vec<f64>> {
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("header").split(',').collect();
    let cols: Vec<usize> = names
        .iter()
        .map(|n| {
            header
                .iter()
                .position(|h| h == n)
                .unwrap_or_else(|| panic!("no column {n} in {header:?}"))
        })
        .collect();
    lines
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: Vec<&str> = l.split(',').collect();
            cols.iter()
                .map(|&c| v[c].parse::<f64>().expect("a number"))
                .collect()
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

/// The workspace's target directory (this test runs from `target/<profile>/deps`).
fn target_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable");
    exe.ancestors().nth(3).expect("target dir").to_path_buf()
}

fn build_rust(model_rs: &Path, no_std_lib: bool) -> PathBuf {
    let manifest = root().join("examples/firmware-rust/Cargo.toml");
    let target = target_dir().join("firmware-rust");
    let mut cmd = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    cmd.args(["build", "--release", "--quiet", "--manifest-path"])
        .arg(&manifest)
        .arg("--target-dir")
        .arg(&target)
        .args(["--features", "vector"])
        .env("HBN_MODEL_RS", model_rs);
    if no_std_lib {
        cmd.args(["--no-default-features", "--lib"]);
    }
    let status = cmd.status().expect("cargo build examples/firmware-rust");
    assert!(status.success(), "building examples/firmware-rust failed");
    target.join("release/hbn-firmware-rust")
}

/// Checks `got` against `reference` (rows of `names`): bit for bit in f64, each component
/// within [`F32_BOUND`] of its range in f32.
fn compare(
    what: &str,
    precision: &str,
    got: &[Vec<f64>],
    reference: &[Vec<f64>],
    names: &[String],
) {
    assert_eq!(got.len(), reference.len(), "{what} {precision}");
    if precision == "f64" {
        for (k, (g, r)) in got.iter().zip(reference).enumerate() {
            for (c, name) in names.iter().enumerate() {
                assert_eq!(g[c].to_bits(), r[c].to_bits(), "{what}: {name} at {k}");
            }
        }
        return;
    }
    for i in 0..(names.len() - 1) / 2 {
        let col = |rows: &[Vec<f64>]| -> Vec<f64> { rows.iter().map(|r| r[2 * i]).collect() };
        let (g, r) = (col(got), col(reference));
        let span =
            r.iter().cloned().fold(f64::MIN, f64::max) - r.iter().cloned().fold(f64::MAX, f64::min);
        let worst = g
            .iter()
            .zip(&r)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "{what} f32 x{i}: max |dx| = {worst:.3e} = {:.2e} of its range",
            worst / span
        );
        assert!(
            worst <= F32_BOUND * span,
            "{what} f32 x{i}: max |dx| {worst} > {F32_BOUND} of {span}"
        );
    }
}

fn c_compiler() -> bool {
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    Command::new(cc)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

fn build_c(model_dir: &Path, build_dir: &Path) -> PathBuf {
    let status = Command::new("make")
        .arg("-s")
        .arg("-C")
        .arg(root().join("examples/firmware-c-vector"))
        .arg(format!("MODEL={}", model_dir.display()))
        .arg(format!("BUILD={}", build_dir.display()))
        .arg(format!("CARGO_TARGET_DIR={}", target_dir().display()))
        .status()
        .expect("run make (is make installed?)");
    assert!(
        status.success(),
        "make -C examples/firmware-c-vector failed"
    );
    build_dir.join("hbn-firmware-vector")
}

#[test]
fn a_finger_model_on_firmware_equals_hbn_estimate() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    for (log, seed, steps) in [("train.mcap", "1", "1200"), ("test.mcap", "9", "400")] {
        ok(&[
            "simulate",
            "--system",
            "finger",
            "--steps",
            steps,
            "--seed",
            seed,
            "--noise-gain",
            "1",
            "--out",
            &p(log),
        ]);
    }
    let model_file = p("finger.hbn");
    ok(&[
        "-q",
        "train",
        "--log",
        &p("train.mcap"),
        "--inducing",
        "32",
        "--starts",
        "1",
        "--max-iters",
        "40",
        "--out",
        &model_file,
    ]);
    let est_csv = p("est.csv");
    ok(&[
        "-q",
        "estimate",
        "--model",
        &model_file,
        "--log",
        &p("test.mcap"),
        "--csv",
        &est_csv,
    ]);
    let est_text = std::fs::read_to_string(&est_csv).expect("est.csv");
    let model = hbn::model::VectorModel::load(Path::new(&model_file)).expect("load");
    let d = model.dims();
    assert_eq!((d.inputs, d.states, d.sensors), (2, 2, 3));
    let names: Vec<String> = (0..d.states)
        .flat_map(|i| [format!("x{i}"), format!("x{i}_std")])
        .chain(["flags".to_owned()])
        .collect();
    let reference = numbers(&est_text, &names);

    // The samples hbn estimate ran on: the test log read as the CLI reads it.
    let signals = hbn::pipeline::model_signals(&model, &[], &[]).expect("signals");
    let mut opts = hbn::pipeline::LogOptions::default();
    if let Some((t, gap)) = model.read_options() {
        opts.time_source = hbn::pipeline::parse_time_source(t).expect("time source");
        opts.max_gap_s = gap;
    }
    let run = hbn::pipeline::estimate_vector_log(
        &model,
        Path::new(&p("test.mcap")),
        &signals,
        model.default_mode(),
        opts,
        &mut |_| {},
    )
    .expect("estimate the test log");
    let t = run.estimate.len();
    assert_eq!(t, reference.len());
    for (k, row) in reference.iter().enumerate() {
        for i in 0..d.states {
            assert_eq!(
                row[2 * i].to_bits(),
                run.estimate.x[k * d.states + i].to_bits()
            );
        }
    }
    let mut u = Vec::with_capacity(t * d.inputs);
    let mut y = Vec::with_capacity(t * d.sensors);
    for k in 0..t {
        for a in 0..d.inputs {
            u.push(run.log.column(a)[k]);
        }
        for j in 0..d.sensors {
            let dropped = run
                .log
                .dropouts
                .get(d.inputs + j)
                .is_some_and(|drop| drop.get(k).copied().unwrap_or(false));
            y.push(if dropped {
                f64::NAN
            } else {
                run.log.column(d.inputs + j)[k]
            });
        }
    }
    // These samples give the CSV's estimate, bit for bit.
    assert_eq!(
        model
            .estimate(&u, &y, model.default_mode())
            .expect("estimate"),
        run.estimate
    );
    let mut samples = (0..d.inputs)
        .map(|a| format!("u{a}"))
        .chain((0..d.sensors).map(|j| format!("y{j}")))
        .collect::<Vec<_>>()
        .join(",");
    samples.push('\n');
    for k in 0..t {
        let row: Vec<String> = u[k * d.inputs..(k + 1) * d.inputs]
            .iter()
            .chain(&y[k * d.sensors..(k + 1) * d.sensors])
            .map(|v| format!("{v}"))
            .collect();
        samples.push_str(&row.join(","));
        samples.push('\n');
    }

    for precision in ["f64", "f32"] {
        let c_dir = dir.path().join(format!("c-{precision}"));
        let out = ok(&[
            "export",
            "--model",
            &model_file,
            "--out",
            &c_dir.to_string_lossy(),
            "--format",
            "c",
            "--precision",
            precision,
        ]);
        assert!(
            out.contains("2 inputs, 2 state components, 3 sensors") && out.contains("model data"),
            "{out}"
        );
        let header = std::fs::read_to_string(c_dir.join("hbn_model.h")).expect("header");
        for line in [
            "#define HBN_MODEL_INPUTS 2",
            "#define HBN_MODEL_STATES 2",
            "#define HBN_MODEL_SENSORS 3",
        ] {
            assert!(header.contains(line), "{header}");
        }
        let rs_dir = dir.path().join(format!("rust-{precision}"));
        ok(&[
            "export",
            "--model",
            &model_file,
            "--out",
            &rs_dir.to_string_lossy(),
            "--format",
            "rust",
            "--precision",
            precision,
        ]);
        let model_rs = rs_dir.join("hbn_model.rs");
        if precision == "f32" {
            build_rust(&model_rs, true); // the library alone, no_std
        }
        let rs_bin = build_rust(&model_rs, false);
        let got = numbers(
            &run_with_stdin(&mut Command::new(&rs_bin), &samples),
            &names,
        );
        compare("Rust", precision, &got, &reference, &names);
        if !c_compiler() {
            eprintln!("no C compiler (cc): the C firmware example is not built");
            continue;
        }
        let bin = build_c(&c_dir, &dir.path().join(format!("c-{precision}-build")));
        let got = numbers(&run_with_stdin(&mut Command::new(&bin), &samples), &names);
        compare("C", precision, &got, &reference, &names);
    }
    // A vector model exports with the EKF or the UKF; EKF+BLR is for scalar models.
    let e = run_err(&[
        "export",
        "--model",
        &model_file,
        "--out",
        &p("blr"),
        "--format",
        "c",
        "--mode",
        "ekf-blr",
    ]);
    assert!(e.contains("--mode ekf-blr is for scalar models"), "{e}");
    assert!(!Path::new(&p("blr")).exists());
}

fn run_err(args: &[&str]) -> String {
    match run(args) {
        Ok(_) => panic!("hbn {args:?} succeeded"),
        Err(e) => e,
    }
}
