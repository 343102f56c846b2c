//! Faults a user meets: an output location that cannot be written, a full device, `hbn train`
//! killed mid-run, a model file cut short, and MCAP logs damaged by bit flips, truncation,
//! duplicated and reordered records. Each must end in an error that names the file (exit code
//! 1, never a panic's 101), within a time bound, leaving no output and no temporary file.
//!
//! These run the `hbn` binary (built by `cargo test --workspace`, as `scripts/test.sh` does).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The `hbn` binary next to this test's own executable (`target/<profile>/hbn`).
fn hbn_bin() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable");
    let dir = exe
        .parent()
        .and_then(Path::parent)
        .expect("target/<profile>/deps");
    let bin = dir.join(format!("hbn{}", std::env::consts::EXE_SUFFIX));
    assert!(
        bin.exists(),
        "`{}` is missing: run `cargo test --release --workspace` (it builds the hbn binary)",
        bin.display()
    );
    bin
}

struct Run {
    code: Option<i32>,
    stdout: String,
    stderr: String,
    timed_out: bool,
}

/// Runs `hbn ARGS`, killing it after `limit`.
fn run(args: &[&str], limit: Duration) -> Run {
    let mut child = Command::new(hbn_bin())
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn hbn");
    let t0 = Instant::now();
    let mut timed_out = false;
    loop {
        if child.try_wait().expect("wait").is_some() {
            break;
        }
        if t0.elapsed() > limit {
            timed_out = true;
            let _ = child.kill();
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().expect("output");
    Run {
        code: out.status.code(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        timed_out,
    }
}

fn ok(args: &[&str]) -> Run {
    let r = run(args, Duration::from_secs(300));
    assert_eq!(r.code, Some(0), "hbn {args:?}: {}\n{}", r.stdout, r.stderr);
    r
}

/// A failed run: exit code 1 (an error, not a panic), the message names `file`.
fn fails_naming(args: &[&str], file: &str) -> Run {
    let r = run(args, Duration::from_secs(120));
    assert!(!r.timed_out, "hbn {args:?} hung");
    assert_eq!(
        r.code,
        Some(1),
        "hbn {args:?} should fail with an error:\n{}",
        r.stderr
    );
    assert!(!r.stderr.contains("panicked"), "{}", r.stderr);
    assert!(
        r.stderr.contains(file),
        "message should name `{file}`:\n{}",
        r.stderr
    );
    r
}

/// Files in `dir` other than the ones listed.
fn extra_files(dir: &Path, keep: &[&str]) -> Vec<String> {
    std::fs::read_dir(dir)
        .expect("read dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .filter(|n| !keep.contains(&n.as_str()))
        .collect()
}

fn s(p: &Path) -> String {
    p.to_string_lossy().into_owned()
}

fn simulate(out: &Path, steps: &str, seed: &str) {
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

fn train(log: &Path, model: &Path) {
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

#[test]
fn outputs_that_cannot_be_written_fail_cleanly() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path();
    let (log, model) = (dir.join("log.mcap"), dir.join("model.hbn"));
    simulate(&log, "500", "1");
    train(&log, &model);

    // The parent of the output is a regular file.
    let blocker = dir.join("not-a-dir");
    std::fs::write(&blocker, b"x").expect("write");
    let under = blocker.join("out.csv");
    fails_naming(
        &[
            "estimate",
            "--model",
            &s(&model),
            "--log",
            &s(&log),
            "--csv",
            &s(&under),
        ],
        &s(&under),
    );
    let under_model = blocker.join("model.hbn");
    fails_naming(
        &[
            "train",
            "--log",
            &s(&log),
            "--starts",
            "1",
            "--out",
            &s(&under_model),
        ],
        &s(&under_model),
    );
    let plot = blocker.join("eval.png");
    fails_naming(
        &[
            "eval",
            "--model",
            &s(&model),
            "--log",
            &s(&log),
            "--plot",
            &s(&plot),
        ],
        &s(&plot),
    );
    assert_eq!(
        extra_files(dir, &["log.mcap", "model.hbn", "not-a-dir"]),
        Vec::<String>::new()
    );

    // A read-only directory (root can write anyway: then there is nothing to test).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let ro = dir.join("read-only");
        std::fs::create_dir(&ro).expect("mkdir");
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).expect("chmod");
        let probe = ro.join("probe");
        if std::fs::write(&probe, b"x").is_err() {
            let csv = ro.join("est.csv");
            fails_naming(
                &[
                    "estimate",
                    "--model",
                    &s(&model),
                    "--log",
                    &s(&log),
                    "--csv",
                    &s(&csv),
                ],
                &s(&csv),
            );
            assert_eq!(extra_files(&ro, &[]), Vec::<String>::new());
        } else {
            eprintln!("running as root: the read-only directory case is not testable here");
            let _ = std::fs::remove_file(&probe);
        }
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).expect("chmod");
    }

    // A full device: an error naming it, and the device is still a device.
    #[cfg(unix)]
    if Path::new("/dev/full").exists() {
        use std::os::unix::fs::FileTypeExt;
        for flag in ["--csv", "--out"] {
            fails_naming(
                &[
                    "estimate",
                    "--model",
                    &s(&model),
                    "--log",
                    &s(&log),
                    flag,
                    "/dev/full",
                ],
                "/dev/full",
            );
        }
        let kind = std::fs::metadata("/dev/full").expect("stat").file_type();
        assert!(kind.is_char_device(), "/dev/full was replaced");
    }
}

#[test]
fn a_killed_training_leaves_nothing_behind() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path();
    let log = dir.join("log.mcap");
    simulate(&log, "4000", "2");
    let out = dir.join("out");
    std::fs::create_dir(&out).expect("mkdir");
    let model = out.join("model.hbn");
    let mut child = Command::new(hbn_bin())
        .args([
            "train",
            "--log",
            &s(&log),
            "--max-points",
            "500",
            "--out",
            &s(&model),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn");
    // Training 4000 samples takes seconds; kill it while it works.
    std::thread::sleep(Duration::from_millis(700));
    assert!(
        child.try_wait().expect("wait").is_none(),
        "training finished before it could be killed"
    );
    child.kill().expect("kill");
    child.wait().expect("wait");
    assert_eq!(extra_files(&out, &[]), Vec::<String>::new());
}

#[test]
fn a_model_file_cut_short_is_an_error_naming_it() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path();
    let (log, model) = (dir.join("log.mcap"), dir.join("model.hbn"));
    simulate(&log, "500", "3");
    train(&log, &model);
    let bytes = std::fs::read(&model).expect("read model");
    let cut = dir.join("cut.hbn");
    for len in [0, 1, 100, bytes.len() / 2, bytes.len() - 1] {
        std::fs::write(&cut, &bytes[..len]).expect("write");
        let csv = dir.join("est.csv");
        fails_naming(
            &[
                "estimate",
                "--model",
                &s(&cut),
                "--log",
                &s(&log),
                "--csv",
                &s(&csv),
            ],
            &s(&cut),
        );
        assert!(!csv.exists(), "an estimate was written from a cut model");
        fails_naming(&["inspect", &s(&cut)], &s(&cut));
    }
}

/// MCAP record framing: 8 magic bytes, then records of `opcode u8, length u64 LE, body`.
fn records(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut at = 8;
    while at + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().expect("8 bytes")) as usize;
        let end = at.saturating_add(9).saturating_add(len);
        if end > bytes.len() {
            break;
        }
        out.push((at, end));
        at = end;
    }
    out
}

/// A small deterministic generator for the mutations.
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

fn mutate(bytes: &[u8], case: usize, rng: &mut Lcg) -> Vec<u8> {
    let mut b = bytes.to_vec();
    let recs = records(bytes);
    match case % 4 {
        0 => {
            for _ in 0..1 + rng.below(16) {
                let i = rng.below(b.len());
                b[i] ^= 1 << rng.below(8);
            }
        }
        1 => b.truncate(rng.below(bytes.len())),
        2 if !recs.is_empty() => {
            let (s0, e0) = recs[rng.below(recs.len())];
            let copy = bytes[s0..e0].to_vec();
            let at = recs[rng.below(recs.len())].0;
            b.splice(at..at, copy);
        }
        _ if recs.len() >= 2 => {
            let i = rng.below(recs.len() - 1);
            let (s0, e0) = recs[i];
            let (s1, e1) = recs[i + 1 + rng.below(recs.len() - i - 1)];
            let mut v = bytes[..s0].to_vec();
            v.extend_from_slice(&bytes[s1..e1]);
            v.extend_from_slice(&bytes[e0..s1]);
            v.extend_from_slice(&bytes[s0..e0]);
            v.extend_from_slice(&bytes[e1..]);
            b = v;
        }
        _ => b.truncate(bytes.len() / 2),
    }
    b
}

#[test]
fn damaged_logs_never_panic_hang_or_leave_output() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path();
    let (log, model) = (dir.join("log.mcap"), dir.join("model.hbn"));
    simulate(&log, "400", "4");
    train(&log, &model);
    let clean = std::fs::read(&log).expect("read");
    assert!(
        records(&clean).len() > 10,
        "the framing parser found the records"
    );
    let mut rng = Lcg(0x5EED);
    let bad = dir.join("bad.mcap");
    let (mut failed, mut passed) = (0, 0);
    for case in 0..32 {
        std::fs::write(&bad, mutate(&clean, case, &mut rng)).expect("write");
        let (csv, out_model) = (dir.join("est.csv"), dir.join("bad-model.hbn"));
        for args in [
            vec![
                "estimate",
                "--model",
                &s(&model),
                "--log",
                &s(&bad),
                "--csv",
                &s(&csv),
            ],
            vec![
                "train",
                "--log",
                &s(&bad),
                "--max-points",
                "60",
                "--starts",
                "1",
                "--validation",
                "0",
                "--out",
                &s(&out_model),
            ],
        ] {
            let r = run(&args, Duration::from_secs(120));
            assert!(!r.timed_out, "case {case}: hbn {args:?} hung");
            assert!(
                !r.stderr.contains("panicked") && r.code != Some(101),
                "case {case}: hbn {args:?} panicked:\n{}",
                r.stderr
            );
            match r.code {
                Some(0) => passed += 1,
                Some(1) => {
                    failed += 1;
                    assert!(
                        r.stderr.contains("bad.mcap"),
                        "case {case}: the error should name the log:\n{}",
                        r.stderr
                    );
                    assert!(
                        !csv.exists() && !out_model.exists(),
                        "case {case}: output left"
                    );
                }
                other => panic!("case {case}: exit {other:?}\n{}", r.stderr),
            }
            let _ = std::fs::remove_file(&csv);
            let _ = std::fs::remove_file(&out_model);
        }
        assert_eq!(
            extra_files(dir, &["log.mcap", "model.hbn", "bad.mcap"]),
            Vec::<String>::new(),
            "case {case}"
        );
    }
    // Both outcomes occur: damage the reader tolerates (a flipped bit in a value) and damage
    // it reports.
    assert!(failed > 0 && passed > 0, "{failed} failed, {passed} passed");
}
