//! Faults a user meets: an output location that cannot be written, a full device, `hbn train`
//! killed mid-run, a model file cut short. Each must end in an error that names the file (exit
//! code 1, never a panic's 101), within a time bound, leaving no output and no temporary file.
//! Damaged MCAP logs are the subject of `tests/mutated_mcap.rs`.
//!
//! These run the `hbn` binary as a separate process (`run_hbn` builds it if needed).

mod run_hbn;

use run_hbn::{extra_files, fails_naming, hbn_bin, s, simulate, train};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

/// Every command line that writes a file, with `out` as the output: `simulate --out`,
/// `train --out`, `estimate --csv`, `estimate --out` (MCAP) and `eval --plot`.
fn writers(log: &Path, model: &Path, out: &str) -> Vec<Vec<String>> {
    let (log, model) = (s(log), s(model));
    let lines: [&[&str]; 5] = [
        &[
            "simulate", "--system", "duhem", "--steps", "200", "--out", out,
        ],
        &[
            "train",
            "--log",
            &log,
            "--max-points",
            "60",
            "--starts",
            "1",
            "--validation",
            "0",
            "--out",
            out,
        ],
        &["estimate", "--model", &model, "--log", &log, "--csv", out],
        &["estimate", "--model", &model, "--log", &log, "--out", out],
        &["eval", "--model", &model, "--log", &log, "--plot", out],
    ];
    lines
        .iter()
        .map(|l| l.iter().map(|a| a.to_string()).collect())
        .collect()
}

fn fails_writing(args: &[String], out: &str) {
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    fails_naming(&args, out);
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
    let under = s(&blocker.join("out.file"));
    for args in writers(&log, &model, &under) {
        fails_writing(&args, &under);
    }
    assert_eq!(
        extra_files(dir, &["log.mcap", "model.hbn", "not-a-dir"]),
        Vec::<String>::new()
    );
    assert_eq!(std::fs::read(&blocker).expect("read"), b"x");

    // A read-only directory (root can write anyway: then there is nothing to test).
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let ro = dir.join("read-only");
        std::fs::create_dir(&ro).expect("mkdir");
        std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).expect("chmod");
        let probe = ro.join("probe");
        if std::fs::write(&probe, b"x").is_err() {
            let out = s(&ro.join("out.file"));
            for args in writers(&log, &model, &out) {
                fails_writing(&args, &out);
                assert_eq!(extra_files(&ro, &[]), Vec::<String>::new(), "{args:?}");
            }
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
        for args in writers(&log, &model, "/dev/full") {
            fails_writing(&args, "/dev/full");
        }
        let kind = std::fs::metadata("/dev/full").expect("stat").file_type();
        assert!(kind.is_char_device(), "/dev/full was replaced");
    } else {
        eprintln!("no /dev/full here: the full-device case is skipped");
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
    // Training 4000 samples with 500 support points takes seconds: SIGKILL it while it reads
    // the log (300 ms) and while it optimises (800 ms).
    for after_ms in [300, 800] {
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
        std::thread::sleep(Duration::from_millis(after_ms));
        assert!(
            child.try_wait().expect("wait").is_none(),
            "training finished before it could be killed"
        );
        child.kill().expect("kill"); // SIGKILL on Unix
        let status = child.wait().expect("wait");
        assert!(!status.success());
        assert_eq!(
            extra_files(&out, &[]),
            Vec::<String>::new(),
            "killed after {after_ms} ms"
        );
    }
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
    let n = bytes.len();
    for len in [
        0,
        1,
        7,
        8,
        9,
        100,
        n / 4,
        n / 2,
        3 * n / 4,
        n - 100,
        n - 8,
        n - 1,
    ] {
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
        fails_naming(&["eval", "--model", &s(&cut), "--log", &s(&log)], &s(&cut));
    }
    assert_eq!(
        extra_files(dir, &["log.mcap", "model.hbn", "cut.hbn"]),
        Vec::<String>::new()
    );
}
