//! Running the `hbn` binary as a separate process, for the tests that need its exit code, a
//! kill, or a time limit (`tests/faults.rs`, `tests/mutated_mcap.rs`).
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// The `hbn` binary of this build (`target/<profile>/hbn`), built first if needed: `cargo test
/// --test faults` alone does not build the CLI's binary, and a stale one would test old code.
pub fn hbn_bin() -> PathBuf {
    static BIN: OnceLock<PathBuf> = OnceLock::new();
    BIN.get_or_init(|| {
        let exe = std::env::current_exe().expect("test executable");
        // target/<profile>/deps/<test> -> target/<profile>, target.
        let profile_dir = exe
            .parent()
            .and_then(Path::parent)
            .expect("target/<profile>/deps")
            .to_path_buf();
        let target_dir = profile_dir.parent().expect("target dir").to_path_buf();
        let release = profile_dir.file_name().is_some_and(|n| n == "release");
        let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
        let mut cmd = Command::new(cargo);
        cmd.args(["build", "--quiet", "-p", "hbn-cli", "--bin", "hbn"])
            .arg("--manifest-path")
            .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("Cargo.toml"))
            .arg("--target-dir")
            .arg(&target_dir);
        if release {
            cmd.arg("--release");
        }
        let status = cmd.status().expect("run cargo build for the hbn binary");
        assert!(status.success(), "building the hbn binary failed");
        let bin = profile_dir.join(format!("hbn{}", std::env::consts::EXE_SUFFIX));
        assert!(bin.exists(), "`{}` is missing", bin.display());
        bin
    })
    .clone()
}

/// What a run of `hbn` did.
pub struct Run {
    pub code: Option<i32>,
    pub stdout: String,
    pub stderr: String,
    pub timed_out: bool,
}

impl Run {
    /// A panic: exit code 101 or Rust's panic message.
    pub fn panicked(&self) -> bool {
        self.code == Some(101) || self.stderr.contains("panicked")
    }
}

/// Runs `hbn ARGS`, killing it after `limit` (then `timed_out` is set).
pub fn run(args: &[&str], limit: Duration) -> Run {
    let mut child = Command::new(hbn_bin())
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn hbn");
    // Drain the pipes on threads so a chatty child cannot block on a full pipe.
    let mut out_pipe = child.stdout.take().expect("stdout");
    let mut err_pipe = child.stderr.take().expect("stderr");
    let out_t = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = std::io::Read::read_to_end(&mut out_pipe, &mut s);
        s
    });
    let err_t = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = std::io::Read::read_to_end(&mut err_pipe, &mut s);
        s
    });
    let t0 = Instant::now();
    let mut timed_out = false;
    let status = loop {
        if let Some(st) = child.try_wait().expect("wait") {
            break st;
        }
        if t0.elapsed() > limit {
            timed_out = true;
            let _ = child.kill();
            break child.wait().expect("wait");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let stdout = out_t.join().expect("stdout thread");
    let stderr = err_t.join().expect("stderr thread");
    Run {
        code: status.code(),
        stdout: String::from_utf8_lossy(&stdout).into_owned(),
        stderr: String::from_utf8_lossy(&stderr).into_owned(),
        timed_out,
    }
}

/// A successful run.
pub fn ok(args: &[&str]) -> Run {
    let r = run(args, Duration::from_secs(300));
    assert_eq!(r.code, Some(0), "hbn {args:?}: {}\n{}", r.stdout, r.stderr);
    r
}

/// A failed run: exit code 1 (an error, not a panic), within 120 s, the message names `file`.
pub fn fails_naming(args: &[&str], file: &str) -> Run {
    let r = run(args, Duration::from_secs(120));
    assert!(!r.timed_out, "hbn {args:?} hung");
    assert!(!r.panicked(), "hbn {args:?} panicked:\n{}", r.stderr);
    assert_eq!(
        r.code,
        Some(1),
        "hbn {args:?} should fail with an error:\n{}",
        r.stderr
    );
    assert!(
        r.stderr.contains(file),
        "message should name `{file}`:\n{}",
        r.stderr
    );
    r
}

/// Names of the entries of `dir` other than those in `keep`.
pub fn extra_files(dir: &Path, keep: &[&str]) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .expect("read dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| !keep.contains(&n.as_str()))
        .collect();
    v.sort();
    v
}

pub fn s(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

/// `hbn simulate --system duhem` into `out`.
pub fn simulate(out: &Path, steps: &str, seed: &str) {
    ok(&[
        "simulate",
        "--system",
        "duhem",
        "--steps",
        steps,
        "--seed",
        seed,
        "--out",
        &s(out),
    ]);
}

/// A quick `hbn train` of `log` into `model`.
pub fn train(log: &Path, model: &Path) {
    ok(&[
        "train",
        "--log",
        &s(log),
        "--max-points",
        "80",
        "--starts",
        "1",
        "--validation",
        "0",
        "--out",
        &s(model),
    ]);
}
