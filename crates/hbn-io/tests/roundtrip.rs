//! Writing then reading, resampling, and signal-level errors.
use std::collections::BTreeMap;
use std::path::Path;

use hbn_io::{
    Encoding, IoError, RawSignal, ReadOptions, ResampleOptions, ScalarTopic, SignalPath,
    TimeSource, native_rate_hz, read_signals, resample, stamped_scalar_cdr, stamped_scalar_ros2msg,
    write_atomic, write_json_log, write_scalar_log,
};
use serde_json::json;

const T0: u64 = 1_650_000_000_123_456_789;

fn paths(s: &[&str]) -> Vec<SignalPath> {
    s.iter().map(|p| p.parse().unwrap()).collect()
}

#[test]
fn scalar_log_round_trip_json_and_ros2() {
    let dir = tempfile::tempdir().unwrap();
    let n = 500;
    let t: Vec<u64> = (0..n)
        .map(|k| T0 + k * 10_000_000 + (k * 7919) % 1000)
        .collect();
    let u: Vec<f64> = (0..n)
        .map(|k| (k as f64 * 0.1).sin() * 1e-3 + 1.0 / 3.0)
        .collect();
    let x: Vec<f64> = (0..n)
        .map(|k| -(k as f64).sqrt() * std::f64::consts::E)
        .collect();
    let y: Vec<f64> = (0..n)
        .map(|k| f64::from_bits(0x3FF0_0000_0000_0001 + k))
        .collect();
    for enc in [Encoding::Json, Encoding::Ros2] {
        let f = dir.path().join(format!("sim_{enc:?}.mcap"));
        write_scalar_log(
            &f,
            &t,
            &[
                ScalarTopic {
                    topic: "/input",
                    values: &u,
                },
                ScalarTopic {
                    topic: "/state",
                    values: &x,
                },
                ScalarTopic {
                    topic: "/sensor",
                    values: &y,
                },
            ],
            enc,
        )
        .unwrap();
        let s = read_signals(
            &f,
            &paths(&["/input.data", "/state.data", "/sensor.data"]),
            &ReadOptions::default(),
        )
        .unwrap();
        assert_eq!(s[0].t_ns, t, "{enc:?}");
        assert_eq!(s[0].value, u, "{enc:?}");
        assert_eq!(s[1].value, x, "{enc:?}");
        assert_eq!(s[2].value, y, "{enc:?}");
        let mut reports = Vec::new();
        let h = hbn_io::read_signals_observed(
            &f,
            &paths(&["/sensor.data"]),
            &ReadOptions {
                time_source: TimeSource::HeaderStamp,
            },
            &mut |p| reports.push(p),
        )
        .unwrap();
        assert_eq!(h[0].t_ns, t);
        // The observer hears the end of the pass, with the whole file read.
        let last = reports.last().copied().unwrap();
        assert!(last.done && last.total_bytes > 0, "{last:?}");
        assert_eq!(last.bytes_read, last.total_bytes);
        assert_eq!(reports.iter().filter(|p| p.done).count(), 1);
        let topics = hbn_io::list_topics(&f).unwrap();
        assert_eq!(topics.len(), 3);
        assert_eq!(
            topics[0].schema_name.as_deref(),
            Some("hbn_msgs/msg/StampedScalar")
        );
        assert_eq!(
            topics[0].schema_encoding.as_deref(),
            Some(if enc == Encoding::Json {
                "jsonschema"
            } else {
                "ros2msg"
            })
        );
        // no temp files left behind
        let left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| e.file_name().to_string_lossy().starts_with(".hbn-tmp"))
            .collect();
        assert!(left.is_empty());
    }
}

#[test]
fn writer_rejects_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("bad.mcap");
    let t = [1, 2, 3];
    assert!(matches!(
        write_scalar_log(
            &f,
            &t,
            &[ScalarTopic {
                topic: "/a",
                values: &[1.0, 2.0]
            }],
            Encoding::Json
        ),
        Err(IoError::InvalidInput { .. })
    ));
    assert!(matches!(
        write_scalar_log(
            &f,
            &t,
            &[ScalarTopic {
                topic: "/a",
                values: &[1.0, f64::NAN, 2.0]
            }],
            Encoding::Ros2
        ),
        Err(IoError::NonFinite { t: 2, .. })
    ));
    assert!(matches!(
        write_scalar_log(
            &f,
            &[3, 2, 1],
            &[ScalarTopic {
                topic: "/a",
                values: &[1.0; 3]
            }],
            Encoding::Json
        ),
        Err(IoError::InvalidInput { .. })
    ));
    assert!(!f.exists());
    // Into a directory that does not exist: Open error naming the file.
    let g = dir.path().join("no/such/dir/x.mcap");
    match write_atomic(&g, b"abc") {
        Err(e @ IoError::Open { .. }) => assert!(e.to_string().contains("x.mcap"), "{e}"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn write_atomic_replaces() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("m.csv");
    write_atomic(&f, b"one").unwrap();
    write_atomic(&f, b"two,2\n").unwrap();
    assert_eq!(std::fs::read(&f).unwrap(), b"two,2\n");
    // relative path in the current dir style
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

fn json_log(dir: &Path, name: &str, t: &[u64], recs: Vec<serde_json::Value>) -> std::path::PathBuf {
    let f = dir.join(name);
    write_json_log(
        &f,
        "/est",
        "hbn/Estimate",
        &json!({"type": "object"}),
        t,
        &recs,
    )
    .unwrap();
    f
}

fn stamp_rec(sec: u64, nsec: u64, v: f64) -> serde_json::Value {
    json!({"header": {"stamp": {"sec": sec, "nsec": nsec}, "frame_id": ""}, "x": v, "arr": [v, 2.0 * v]})
}

#[test]
fn json_log_and_foxglove_nsec_stamps() {
    let dir = tempfile::tempdir().unwrap();
    let t = [10, 20, 30];
    let f = json_log(
        dir.path(),
        "a.mcap",
        &t,
        vec![
            stamp_rec(1, 5, 1.0),
            stamp_rec(1, 6, 2.0),
            stamp_rec(2, 0, 3.0),
        ],
    );
    let s = read_signals(
        &f,
        &paths(&["/est.x", "/est.arr[1]"]),
        &ReadOptions::default(),
    )
    .unwrap();
    assert_eq!(s[0].t_ns, t);
    assert_eq!(s[1].value, [2.0, 4.0, 6.0]);
    let h = read_signals(
        &f,
        &paths(&["/est.x"]),
        &ReadOptions {
            time_source: TimeSource::HeaderStamp,
        },
    )
    .unwrap();
    assert_eq!(h[0].t_ns, [1_000_000_005, 1_000_000_006, 2_000_000_000]);
}

#[test]
fn time_backwards_and_equal_times() {
    let dir = tempfile::tempdir().unwrap();
    let f = json_log(
        dir.path(),
        "b.mcap",
        &[10, 20, 30],
        vec![
            stamp_rec(5, 0, 1.0),
            stamp_rec(4, 0, 2.0),
            stamp_rec(6, 0, 3.0),
        ],
    );
    match read_signals(
        &f,
        &paths(&["/est.x"]),
        &ReadOptions {
            time_source: TimeSource::HeaderStamp,
        },
    ) {
        Err(
            e @ IoError::TimeBackwards {
                t_prev: 5_000_000_000,
                t: 4_000_000_000,
                ..
            },
        ) => {
            assert!(e.to_string().contains("/est.x"), "{e}")
        }
        other => panic!("{other:?}"),
    }
    // equal times: the later value is kept
    let f = json_log(
        dir.path(),
        "c.mcap",
        &[10, 10, 30],
        vec![
            stamp_rec(5, 0, 1.0),
            stamp_rec(5, 0, 2.0),
            stamp_rec(6, 0, 3.0),
        ],
    );
    let s = read_signals(&f, &paths(&["/est.x"]), &ReadOptions::default()).unwrap();
    assert_eq!(s[0].t_ns, [10, 30]);
    assert_eq!(s[0].value, [2.0, 3.0]);
}

#[test]
fn nan_and_bad_json_and_unsupported_encoding() {
    let dir = tempfile::tempdir().unwrap();
    let f = dir.path().join("nan.mcap");
    {
        let file = std::fs::File::create(&f).unwrap();
        let mut w = mcap::Writer::new(std::io::BufWriter::new(file)).unwrap();
        let sid = w
            .add_schema(
                "hbn_msgs/msg/StampedScalar",
                "ros2msg",
                stamped_scalar_ros2msg().as_bytes(),
            )
            .unwrap();
        let c = w.add_channel(sid, "/x", "cdr", &BTreeMap::new()).unwrap();
        let j = w.add_channel(0, "/j", "json", &BTreeMap::new()).unwrap();
        let pb = w
            .add_channel(0, "/pb", "protobuf", &BTreeMap::new())
            .unwrap();
        for (k, v) in [1.0, 2.0, f64::NAN].iter().enumerate() {
            let hdr = |ch| mcap::records::MessageHeader {
                channel_id: ch,
                sequence: 0,
                log_time: 1_000_000_000 * (k as u64 + 1),
                publish_time: 0,
            };
            w.write_to_known_channel(&hdr(c), &stamped_scalar_cdr(k as i32, 0, "", *v))
                .unwrap();
            w.write_to_known_channel(
                &hdr(j),
                if k < 2 {
                    b"{\"a\": 1}"
                } else {
                    b"{\"a\": NaN}"
                },
            )
            .unwrap();
            w.write_to_known_channel(&hdr(pb), b"\x08\x01").unwrap();
        }
        w.finish().unwrap();
    }
    match read_signals(&f, &paths(&["/x.data"]), &ReadOptions::default()) {
        Err(
            e @ IoError::NonFinite {
                t: 3_000_000_000, ..
            },
        ) => assert!(e.to_string().contains("/x.data"), "{e}"),
        other => panic!("{other:?}"),
    }
    match read_signals(&f, &paths(&["/j.a"]), &ReadOptions::default()) {
        Err(e @ IoError::BadMessage { .. }) => assert!(e.to_string().contains("/j"), "{e}"),
        other => panic!("{other:?}"),
    }
    match read_signals(&f, &paths(&["/pb.a"]), &ReadOptions::default()) {
        Err(e @ IoError::UnsupportedEncoding { .. }) => {
            let m = e.to_string();
            assert!(m.contains("/pb") && m.contains("protobuf"), "{m}");
        }
        other => panic!("{other:?}"),
    }
}

fn sig(path: &str, t: Vec<u64>, f: impl Fn(f64) -> f64) -> RawSignal {
    let value = t.iter().map(|&t| f(t as f64 * 1e-9)).collect();
    RawSignal {
        path: path.parse().unwrap(),
        t_ns: t,
        value,
    }
}

fn jittered(rate: f64, n: u64, start_ns: u64, seed: u64) -> Vec<u64> {
    let step = (1e9 / rate) as u64;
    let mut x = seed;
    (0..n)
        .map(|k| {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            start_ns + k * step + (x >> 33) % (step / 5)
        })
        .collect()
}

#[test]
fn resample_30_and_100_hz_with_jitter() {
    let a = sig("/state.data", jittered(30.0, 90, 2_000_000_000, 1), |t| {
        3.0 * t - 1.0
    });
    let b = sig("/input.data", jittered(100.0, 300, 2_010_000_000, 2), |t| {
        -0.5 * t + 4.0
    });
    let out = resample(&[a.clone(), b.clone()], &ResampleOptions::new(100.0)).unwrap();
    let start = a.t_ns[0].max(b.t_ns[0]);
    let end = (*a.t_ns.last().unwrap()).min(*b.t_ns.last().unwrap());
    assert_eq!(out.t0_ns, start);
    assert_eq!(out.rate_hz, 100.0);
    let expect_n = ((end - start) as f64 * 1e-9 * 100.0).floor() as usize + 1;
    assert_eq!(out.t_s.len(), expect_n);
    assert_eq!(out.columns.len(), 2);
    for (k, &t) in out.t_s.iter().enumerate() {
        assert!((t - k as f64 / 100.0).abs() < 1e-12);
        let abs = start as f64 * 1e-9 + t;
        assert!((out.columns[0][k] - (3.0 * abs - 1.0)).abs() < 1e-6, "{k}");
        assert!((out.columns[1][k] - (-0.5 * abs + 4.0)).abs() < 1e-6, "{k}");
    }
    let r30 = native_rate_hz(&a).unwrap();
    let r100 = native_rate_hz(&b).unwrap();
    assert!((r30 - 30.0).abs() < 2.0, "{r30}");
    assert!((r100 - 100.0).abs() < 5.0, "{r100}");
    let exact = sig("/x", (0..11).map(|k| k * 20_000_000).collect(), |t| t);
    assert_eq!(native_rate_hz(&exact), Some(50.0));
    assert_eq!(native_rate_hz(&sig("/x", vec![5], |t| t)), None);
}

#[test]
fn resample_errors() {
    let a = sig("/a.v", (0..100).map(|k| k * 10_000_000).collect(), |t| t);
    // gap of 0.7 s in b at 0.3 s
    let mut tb: Vec<u64> = (0..30).map(|k| k * 10_000_000).collect();
    tb.extend((100..110).map(|k| k * 10_000_000));
    let b = sig("/b.v", tb, |t| t);
    match resample(&[a.clone(), b.clone()], &ResampleOptions::new(50.0)) {
        Err(e @ IoError::Gap { .. }) => {
            let IoError::Gap {
                ref path,
                at_s,
                gap_s,
                max_gap_s,
            } = e
            else {
                unreachable!()
            };
            assert_eq!(path, "/b.v");
            assert!((at_s - 0.29).abs() < 1e-9, "{at_s}");
            assert!((gap_s - 0.71).abs() < 1e-9);
            assert_eq!(max_gap_s, 0.5);
            assert!(
                e.to_string().contains("/b.v") && e.to_string().contains("0.290"),
                "{e}"
            );
        }
        other => panic!("{other:?}"),
    }
    // a larger max_gap accepts it
    let ok = resample(
        &[a.clone(), b],
        &ResampleOptions {
            rate_hz: 50.0,
            max_gap_s: 1.0,
        },
    )
    .unwrap();
    assert_eq!(ok.t_s.len(), 50);
    let late = sig("/c.v", (200..300).map(|k| k * 10_000_000).collect(), |t| t);
    assert!(matches!(
        resample(&[a.clone(), late], &ResampleOptions::new(10.0)),
        Err(IoError::NoOverlap { .. })
    ));
    let one = sig("/d.v", vec![5], |t| t);
    assert!(matches!(
        resample(&[a.clone(), one], &ResampleOptions::new(10.0)),
        Err(IoError::TooFewSamples { n: 1, need: 2, .. })
    ));
    for rate in [0.0, -1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            resample(std::slice::from_ref(&a), &ResampleOptions::new(rate)),
            Err(IoError::BadOption { .. })
        ));
    }
    assert!(matches!(
        resample(
            std::slice::from_ref(&a),
            &ResampleOptions {
                rate_hz: 10.0,
                max_gap_s: f64::NAN
            }
        ),
        Err(IoError::BadOption { .. })
    ));
    // a grid with a single point
    let short = sig("/e.v", vec![0, 1000], |t| t);
    assert!(matches!(
        resample(&[short], &ResampleOptions::new(10.0)),
        Err(IoError::TooFewSamples { .. })
    ));
}
