//! Reads the fixtures written by the official Python writers (fixtures/make_fixtures.py) and
//! checks values and times against the formulas there; bad inputs never panic.
use std::f64::consts::PI;
use std::path::PathBuf;

use hbn_io::{
    IoError, ReadOptions, ResampleOptions, SignalPath, TimeSource, list_topics, read_signals,
    resample,
};

const T0: u64 = 1_700_000_000 * 1_000_000_000;
const LAG: u64 = 2_000_000;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fixtures")
        .join(name)
}

fn paths(s: &[&str]) -> Vec<SignalPath> {
    s.iter().map(|p| p.parse().unwrap()).collect()
}

fn tr(t: u64) -> f64 {
    (t - T0) as f64 / 1e9
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * (1.0 + b.abs())
}

#[test]
fn json_fixture_values_and_times() {
    let f = fixture("json_zstd.mcap");
    let sigs = read_signals(
        &f,
        &paths(&[
            "/state.data",
            "/input.data",
            "/sensor.data",
            "/status.ok",
            "/status.count",
            "/vec.v[-1]",
        ]),
        &ReadOptions::default(),
    )
    .unwrap();
    assert_eq!(sigs[0].t_ns.len(), 120);
    for (k, (&t, &v)) in sigs[0].t_ns.iter().zip(&sigs[0].value).enumerate() {
        assert_eq!(t, T0 + k as u64 * 33_333_333);
        assert!(close(v, (2.0 * PI * 0.5 * tr(t)).sin()), "{k}: {v}");
    }
    assert_eq!(sigs[1].t_ns.len(), 400);
    for (k, (&t, &v)) in sigs[1].t_ns.iter().zip(&sigs[1].value).enumerate() {
        assert_eq!(t, T0 + k as u64 * 10_000_000);
        assert!(close(v, (2.0 * PI * 0.3 * tr(t)).cos()));
    }
    for (k, (&t, &v)) in sigs[2].t_ns.iter().zip(&sigs[2].value).enumerate() {
        assert_eq!(t, T0 + 5_000_000 + k as u64 * 10_000_000);
        assert!(close(v, 0.5 * tr(t) + 0.1));
    }
    assert_eq!(sigs[3].value.len(), 40);
    for k in 0..40 {
        assert_eq!(sigs[3].value[k], if k % 2 == 0 { 1.0 } else { 0.0 });
        assert_eq!(sigs[4].value[k], k as f64);
        assert_eq!(sigs[5].value[k], 3.0 * k as f64); // schemaless channel
    }
    // header stamps
    let st = read_signals(
        &f,
        &paths(&["/sensor.data"]),
        &ReadOptions {
            time_source: TimeSource::HeaderStamp,
        },
    )
    .unwrap();
    assert_eq!(st[0].t_ns[3], T0 + 5_000_000 + 30_000_000 - LAG);

    // resample the simulate-style trio
    let a = resample(&sigs[..3], &ResampleOptions::new(100.0)).unwrap();
    assert_eq!(a.t0_ns, T0 + 5_000_000);
    for (k, &t) in a.t_s.iter().enumerate() {
        let abs = t + 0.005;
        assert!((a.columns[2][k] - (0.5 * abs + 0.1)).abs() < 1e-12);
    }
}

#[test]
fn topics_are_listed() {
    let t = list_topics(&fixture("json_zstd.mcap")).unwrap();
    let names: Vec<&str> = t.iter().map(|t| t.topic.as_str()).collect();
    assert_eq!(names, ["/input", "/sensor", "/state", "/status", "/vec"]);
    assert_eq!(t[2].message_count, 120);
    assert_eq!(t[4].schema_name, None);
    assert_eq!(t[0].schema_encoding.as_deref(), Some("jsonschema"));
    let t = list_topics(&fixture("ros2_lz4.mcap")).unwrap();
    assert_eq!(t[0].topic, "/actuator");
    assert_eq!(t[0].message_encoding, "cdr");
    assert_eq!(
        t[1].schema_name.as_deref(),
        Some("sensor_msgs/msg/JointState")
    );
    assert_eq!(t[1].message_count, 300);
}

fn check_actuator(file: &str, n: usize) {
    let f = fixture(file);
    let s = read_signals(
        &f,
        &paths(&[
            "/actuator.pressure",
            "/actuator.mode",
            "/actuator.segments[1].angle",
            "/actuator.segments[0].counts[0]",
            "/actuator.segments[-1].counts[2]",
            "/actuator.accel[1]",
            "/actuator.gain",
            "/actuator.header.stamp.nanosec",
        ]),
        &ReadOptions::default(),
    )
    .unwrap();
    assert_eq!(s[0].t_ns.len(), n);
    for k in 0..n {
        let t = T0 + k as u64 * 20_000_000;
        assert_eq!(s[0].t_ns[k], t);
        assert!(close(
            s[0].value[k],
            100.0 + 10.0 * (2.0 * PI * tr(t)).sin()
        ));
        assert_eq!(s[1].value[k], (k % 3) as f64);
        assert!(close(s[2].value[k], -0.2 * k as f64));
        assert_eq!(s[3].value[k], (k % 5) as f64);
        assert_eq!(s[4].value[k], 3.0);
        assert_eq!(s[5].value[k], -0.5 * k as f64);
        assert_eq!(s[6].value[k], 0.5);
        assert_eq!(s[7].value[k], ((t - LAG) % 1_000_000_000) as f64);
    }
    let h = read_signals(
        &f,
        &paths(&["/actuator.pressure"]),
        &ReadOptions {
            time_source: TimeSource::HeaderStamp,
        },
    )
    .unwrap();
    assert_eq!(h[0].t_ns[7], T0 + 7 * 20_000_000 - LAG);
}

#[test]
fn ros2_fixture_values_and_times() {
    check_actuator("ros2_lz4.mcap", 150);
    let f = fixture("ros2_lz4.mcap");
    let s = read_signals(
        &f,
        &paths(&[
            "/joint_states.position[0]",
            "/joint_states.position[2]",
            "/joint_states.effort[2]",
        ]),
        &ReadOptions::default(),
    )
    .unwrap();
    assert_eq!(s[0].t_ns.len(), 300);
    for k in 0..300 {
        let t = T0 + k as u64 * 10_000_000;
        assert!(close(s[0].value[k], tr(t).sin()));
        assert!(close(s[1].value[k], (tr(t) + 2.0).sin()));
        assert_eq!(s[2].value[k], 2.0 * k as f64);
    }
    match read_signals(
        &f,
        &paths(&["/joint_states.velocity[0]"]),
        &ReadOptions::default(),
    ) {
        Err(e @ IoError::MissingField { .. }) => assert!(e.to_string().contains("empty"), "{e}"),
        other => panic!("{other:?}"),
    }
    match read_signals(&f, &paths(&["/actuator.label"]), &ReadOptions::default()) {
        Err(e @ IoError::NonNumeric { .. }) => assert!(e.to_string().contains("\"L0\""), "{e}"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn unchunked_unindexed_fixture() {
    check_actuator("ros2_unchunked.mcap", 50);
}

#[test]
fn missing_topic_lists_available() {
    let f = fixture("json_zstd.mcap");
    match read_signals(
        &f,
        &paths(&["/state.data", "/nope.data"]),
        &ReadOptions::default(),
    ) {
        Err(e @ IoError::MissingTopic { .. }) => {
            let m = e.to_string();
            assert!(
                m.contains("/nope") && m.contains("/input, /sensor, /state, /status, /vec"),
                "{m}"
            );
            assert!(m.contains("json_zstd.mcap"), "{m}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn missing_field_lists_fields() {
    let f = fixture("json_zstd.mcap");
    match read_signals(&f, &paths(&["/state.dta"]), &ReadOptions::default()) {
        Err(e @ IoError::MissingField { .. }) => {
            let m = e.to_string();
            assert!(
                m.contains("/state.dta") && m.contains("data") && m.contains("header"),
                "{m}"
            );
        }
        other => panic!("{other:?}"),
    }
    match read_signals(
        &fixture("ros2_lz4.mcap"),
        &paths(&["/actuator.segments[0].angel"]),
        &ReadOptions::default(),
    ) {
        Err(IoError::MissingField {
            available, topic, ..
        }) => {
            assert_eq!(topic, "/actuator");
            assert_eq!(available, ["name", "angle", "counts"]);
        }
        other => panic!("{other:?}"),
    }
    // header stamp on a topic without header
    match read_signals(
        &f,
        &paths(&["/status.count"]),
        &ReadOptions {
            time_source: TimeSource::HeaderStamp,
        },
    ) {
        Err(e @ IoError::MissingField { .. }) => {
            assert!(e.to_string().contains("header.stamp"), "{e}")
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn non_numeric_field() {
    let f = fixture("json_zstd.mcap");
    match read_signals(&f, &paths(&["/status.mode"]), &ReadOptions::default()) {
        Err(IoError::NonNumeric { path, found }) => {
            assert_eq!(path, "/status.mode");
            assert!(found.contains("\"run\""));
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn empty_random_and_missing_files() {
    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty.mcap");
    std::fs::write(&empty, b"").unwrap();
    let p = paths(&["/state.data"]);
    match read_signals(&empty, &p, &ReadOptions::default()) {
        Err(e @ IoError::Corrupt { .. }) => assert!(e.to_string().contains("empty"), "{e}"),
        other => panic!("{other:?}"),
    }
    assert!(matches!(list_topics(&empty), Err(IoError::Corrupt { .. })));
    let rnd = dir.path().join("random.mcap");
    let mut x: u32 = 12345;
    let bytes: Vec<u8> = (0..5000)
        .map(|_| {
            x = x.wrapping_mul(1664525).wrapping_add(1013904223);
            (x >> 24) as u8
        })
        .collect();
    std::fs::write(&rnd, &bytes).unwrap();
    assert!(matches!(
        read_signals(&rnd, &p, &ReadOptions::default()),
        Err(IoError::Corrupt { .. })
    ));
    // random bytes after a valid magic
    let mut m = hbn_io_magic();
    m.extend(&bytes);
    std::fs::write(&rnd, &m).unwrap();
    assert!(matches!(
        read_signals(&rnd, &p, &ReadOptions::default()),
        Err(IoError::Corrupt { .. })
    ));
    match read_signals(&dir.path().join("nope.mcap"), &p, &ReadOptions::default()) {
        Err(e @ IoError::Open { .. }) => assert!(e.to_string().contains("nope.mcap"), "{e}"),
        other => panic!("{other:?}"),
    }
}

fn hbn_io_magic() -> Vec<u8> {
    vec![0x89, b'M', b'C', b'A', b'P', 0x30, b'\r', b'\n']
}

#[test]
fn truncated_files_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["json_zstd.mcap", "ros2_lz4.mcap", "ros2_unchunked.mcap"] {
        let full = std::fs::read(fixture(name)).unwrap();
        let p = if name.starts_with("json") {
            paths(&["/input.data"])
        } else {
            paths(&["/actuator.pressure"])
        };
        let cut = dir.path().join(name);
        for frac in [0.0001, 0.1, 0.33, 0.5, 0.77, 0.95, 0.999] {
            let n = ((full.len() as f64) * frac) as usize;
            std::fs::write(&cut, &full[..n]).unwrap();
            match read_signals(&cut, &p, &ReadOptions::default()) {
                Err(IoError::Corrupt { .. }) => {}
                other => panic!("{name} cut at {n}: {other:?}"),
            }
        }
        // one byte short
        std::fs::write(&cut, &full[..full.len() - 1]).unwrap();
        assert!(read_signals(&cut, &p, &ReadOptions::default()).is_err());
    }
}

/// 2000 random truncations and bit flips: errors are fine, panics are not.
#[test]
fn fuzz_truncations_and_bit_flips() {
    let dir = tempfile::tempdir().unwrap();
    let mut x: u64 = 0x2545F4914F6CDD1D;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let files = ["json_zstd.mcap", "ros2_lz4.mcap", "ros2_unchunked.mcap"];
    let datas: Vec<Vec<u8>> = files
        .iter()
        .map(|f| std::fs::read(fixture(f)).unwrap())
        .collect();
    let pj = paths(&["/input.data", "/state.data", "/vec.v[1]"]);
    let pr = paths(&[
        "/actuator.segments[-1].counts[2]",
        "/actuator.pressure",
        "/joint_states.position[1]",
    ]);
    let target = dir.path().join("fuzz.mcap");
    let mut ok = 0;
    for i in 0..2000 {
        let which = (rnd() % 3) as usize;
        let mut d = datas[which].clone();
        match rnd() % 3 {
            0 => {
                let n = (rnd() as usize) % d.len();
                d.truncate(n);
            }
            1 => {
                for _ in 0..1 + rnd() % 4 {
                    let k = (rnd() as usize) % d.len();
                    d[k] ^= 1 << (rnd() % 8);
                }
            }
            _ => {
                let k = (rnd() as usize) % d.len();
                d[k] = rnd() as u8;
                let n = d.len() - (rnd() as usize) % 64;
                d.truncate(n);
            }
        }
        std::fs::write(&target, &d).unwrap();
        let p = if which == 0 { &pj } else { &pr };
        let opts = ReadOptions {
            time_source: if i % 2 == 0 {
                TimeSource::LogTime
            } else {
                TimeSource::HeaderStamp
            },
        };
        if read_signals(&target, p, &opts).is_ok() {
            ok += 1;
        }
        let _ = list_topics(&target);
    }
    // Some bit flips land in padding/CRCs that are not checked: those files still read.
    assert!(ok < 2000);
}

#[test]
fn a_chunk_whose_records_overrun_it_is_an_error_in_every_build() {
    // A case of the mcap_ingest fuzz target: an uncompressed chunk whose record claims more
    // bytes than the chunk has left. The mcap crate (0.26, sans_io/linear_reader.rs) subtracts
    // the record's length from the chunk's remainder without a check: with overflow checks
    // (debug and test builds) that panics; without (release) it wraps and the read fails.
    // The workspace turns overflow checks off for the mcap crate alone (Cargo.toml), so every
    // build reports a corrupt file.
    let file = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/regressions/mcap_ingest/crash-f3b9df91929d193fc63135284ed1e1b6e7c04951");
    let topics = list_topics(&file).unwrap_or_default();
    let mut p: Vec<SignalPath> = topics
        .iter()
        .filter_map(|t| format!("{}.data", t.topic).parse().ok())
        .collect();
    p.extend(paths(&["/input.data", "/state.data", "/sensor.data"]));
    for time_source in [TimeSource::LogTime, TimeSource::HeaderStamp] {
        let err = read_signals(&file, &p, &ReadOptions { time_source });
        assert!(err.is_err(), "{err:?}");
    }
}

#[test]
fn a_record_that_makes_the_mcap_crate_panic_is_a_corrupt_file() {
    // A case of the mcap_ingest fuzz target: a record whose lengths make the mcap crate (0.26,
    // read.rs) index a slice backwards and panic, in every build. hbn-io catches it and
    // reports a corrupt file.
    let file = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/regressions/mcap_ingest/crash-3461355f5aa2b41f20fc106bbd2bdeafda731cb0");
    assert!(matches!(list_topics(&file), Err(IoError::Corrupt { .. })));
    let p = paths(&["/input.data", "/state.data", "/sensor.data"]);
    assert!(read_signals(&file, &p, &ReadOptions::default()).is_err());
}
