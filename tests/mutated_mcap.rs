//! Damaged MCAP logs through `hbn estimate` and `hbn train`: deterministic, seeded
//! mutations of a log written by `hbn simulate` and of the committed fixture
//! `fixtures/json_zstd.mcap` (written by the official MCAP writer: chunked, zstd): bit flips,
//! truncation at random offsets, duplicated records and reordered records (the record framing
//! is parsed: 8 magic bytes, then `opcode u8, length u64 LE, body`). Every run must end within
//! 60 s, never panic (exit code 101 or a "panicked" message), exit 0 or 1, name the log when
//! it fails, and leave no output and no temporary file when it fails.

mod run_hbn;

use run_hbn::{extra_files, run, s, simulate, train};
use std::path::Path;
use std::time::Duration;

/// Cases per source log (two sources: 40 cases, each run through estimate and train).
const CASES_PER_LOG: usize = 20;
const LIMIT: Duration = Duration::from_secs(60);

/// MCAP record framing: the (start, end) of each top-level record after the 8 magic bytes.
fn records(bytes: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut at = 8;
    while let Some(head) = bytes.get(at..at + 9) {
        let mut len = [0u8; 8];
        len.copy_from_slice(&head[1..]);
        let end = usize::try_from(u64::from_le_bytes(len))
            .ok()
            .and_then(|l| (at + 9).checked_add(l));
        match end {
            Some(end) if end <= bytes.len() => {
                out.push((at, end));
                at = end;
            }
            _ => break,
        }
    }
    out
}

/// A small deterministic generator (64-bit LCG) for the mutations.
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

/// Mutation `case % 4`: bit flips, truncation, a duplicated record, two records swapped.
fn mutate(bytes: &[u8], case: usize, rng: &mut Lcg) -> (Vec<u8>, String) {
    let recs = records(bytes);
    match case % 4 {
        0 => {
            let mut b = bytes.to_vec();
            let n = 1 + rng.below(16);
            for _ in 0..n {
                let i = rng.below(b.len());
                b[i] ^= 1 << rng.below(8);
            }
            (b, format!("{n} bit flips"))
        }
        1 => {
            let at = rng.below(bytes.len());
            (bytes[..at].to_vec(), format!("truncated at {at}"))
        }
        2 => {
            let (s0, e0) = recs[rng.below(recs.len())];
            let at = recs[rng.below(recs.len())].0;
            let mut b = bytes[..at].to_vec();
            b.extend_from_slice(&bytes[s0..e0]);
            b.extend_from_slice(&bytes[at..]);
            (b, format!("record at {s0} duplicated before {at}"))
        }
        _ => {
            let i = rng.below(recs.len() - 1);
            let j = i + 1 + rng.below(recs.len() - i - 1);
            let ((s0, e0), (s1, e1)) = (recs[i], recs[j]);
            let mut b = bytes[..s0].to_vec();
            b.extend_from_slice(&bytes[s1..e1]);
            b.extend_from_slice(&bytes[e0..s1]);
            b.extend_from_slice(&bytes[s0..e0]);
            b.extend_from_slice(&bytes[e1..]);
            (b, format!("records at {s0} and {s1} swapped"))
        }
    }
}

/// Outcomes of the runs: (succeeded, failed with an error).
fn damage(clean: &[u8], model: &Path, dir: &Path, seed: u64) -> (usize, usize) {
    assert!(
        records(clean).len() > 10,
        "the framing parser finds the records"
    );
    let mut rng = Lcg(seed);
    let bad = dir.join("bad.mcap");
    let (csv, out_model) = (dir.join("est.csv"), dir.join("bad-model.hbn"));
    let (mut passed, mut failed) = (0, 0);
    for case in 0..CASES_PER_LOG {
        let (bytes, what) = mutate(clean, case, &mut rng);
        std::fs::write(&bad, &bytes).expect("write");
        let estimate = [
            "estimate",
            "--model",
            &s(model),
            "--log",
            &s(&bad),
            "--csv",
            &s(&csv),
        ];
        let train = [
            "train",
            "--log",
            &s(&bad),
            "--max-points",
            "60",
            "--starts",
            "1",
            "--max-iters",
            "30",
            "--validation",
            "0",
            "--out",
            &s(&out_model),
        ];
        for (args, out) in [(&estimate[..], &csv), (&train[..], &out_model)] {
            let r = run(args, LIMIT);
            let label = format!("seed {seed:#x} case {case} ({what}): hbn {}", args[0]);
            assert!(!r.timed_out, "{label} hung");
            assert!(!r.panicked(), "{label} panicked:\n{}", r.stderr);
            match r.code {
                Some(0) => {
                    passed += 1;
                    assert!(out.exists(), "{label}: succeeded without output");
                }
                Some(1) => {
                    failed += 1;
                    assert!(
                        r.stderr.contains("bad.mcap"),
                        "{label}: the error should name the log:\n{}",
                        r.stderr
                    );
                    assert!(!out.exists(), "{label}: failed but left output");
                }
                other => panic!("{label}: exit {other:?}\n{}", r.stderr),
            }
            let _ = std::fs::remove_file(out);
            assert_eq!(
                extra_files(dir, &["log.mcap", "model.hbn", "bad.mcap"]),
                Vec::<String>::new(),
                "{label}"
            );
        }
    }
    (passed, failed)
}

#[test]
fn damaged_logs_never_panic_hang_or_leave_output() {
    let d = tempfile::tempdir().expect("tempdir");
    let dir = d.path();
    let (log, model) = (dir.join("log.mcap"), dir.join("model.hbn"));
    // A log of hbn's own writer, and a model trained on it.
    simulate(&log, "400", "4");
    train(&log, &model);
    let sim = std::fs::read(&log).expect("read");
    let (p1, f1) = damage(&sim, &model, dir, 0x5EED);
    // The fixture of the official writer (chunked, zstd; /input, /state, /sensor), through the
    // same model.
    let fixture = Path::new(env!("CARGO_MANIFEST_DIR")).join("fixtures/json_zstd.mcap");
    let official = std::fs::read(fixture).expect("read fixture");
    let (p2, f2) = damage(&official, &model, dir, 0xF1C5);
    eprintln!("simulated log: {p1} runs succeeded, {f1} failed; fixture: {p2} / {f2}");
    // Both outcomes occur: damage the reader tolerates (a flipped bit in a value, a duplicated
    // index record) and damage it reports.
    assert!(
        f1 + f2 > 0 && p1 + p2 > 0,
        "{} failed, {} passed",
        f1 + f2,
        p1 + p2
    );
}
