//! `hbn simulate --state-rate HZ --state-drop FRACTION`: the state topic as a camera slower
//! than the sensor records it, on its own clock, with frames dropped; the input and sensor
//! topics keep every sample. Runs the `hbn` binary (`run_hbn` builds it if needed) and reads
//! the logs back with hbn-io's reader.

mod run_hbn;

use std::path::Path;
use std::time::Duration;

use hbn::pipeline::{START_NS, log_times};
use hbn_io::{RawSignal, ReadOptions, SignalPath};
use run_hbn::{extra_files, ok, run, s};

fn read(file: &Path, paths: &[&str]) -> Vec<RawSignal> {
    let parsed: Vec<SignalPath> = paths.iter().map(|p| p.parse().expect("path")).collect();
    hbn_io::read_signals(file, &parsed, &ReadOptions::default()).expect("read")
}

/// `hbn simulate --system SYSTEM --steps STEPS --seed SEED` with `extra` flags into `out`;
/// returns stdout.
fn simulate(system: &str, steps: usize, seed: u64, extra: &[&str], out: &Path) -> String {
    let (steps, seed, out) = (steps.to_string(), seed.to_string(), s(out));
    let mut args = vec![
        "simulate", "--system", system, "--steps", &steps, "--seed", &seed, "--out", &out,
    ];
    args.extend_from_slice(extra);
    ok(&args).stdout
}

/// Frame `j` of a camera at `hz`: `START + j / hz`, to the nanosecond.
fn frame_time(j: usize, hz: f64) -> u64 {
    START_NS + (j as f64 * 1e9 / hz).round() as u64
}

/// The state of the full-rate run `x` (samples at `t`) at time `tau`, linearly interpolated.
fn true_state(t: &[u64], x: &[f64], tau: u64) -> f64 {
    let k = t.partition_point(|&tk| tk <= tau) - 1;
    if k + 1 == t.len() {
        return x[k];
    }
    let w = (tau - t[k]) as f64 / (t[k + 1] - t[k]) as f64;
    x[k] + w * (x[k + 1] - x[k])
}

/// Asserts that `cam`'s values are the full run's state interpolated at `cam`'s times.
fn assert_true_state(full: &RawSignal, cam: &RawSignal, what: &str) {
    let range = full.value.iter().fold(0.0f64, |m, v| m.max(v.abs())) + 1.0;
    for (&tau, &v) in cam.t_ns.iter().zip(&cam.value) {
        let want = true_state(&full.t_ns, &full.value, tau);
        assert!(
            (v - want).abs() <= 1e-12 * range,
            "{what} at {tau} ns: {v} vs {want}"
        );
    }
}

/// Asserts that `kept` is `all` with frames left out: the first and last frames kept, each
/// frame kept with its value; returns the number dropped.
fn assert_subset(all: &RawSignal, kept: &RawSignal, what: &str) -> usize {
    assert_eq!(kept.t_ns.first(), all.t_ns.first(), "{what}: first frame");
    assert_eq!(kept.t_ns.last(), all.t_ns.last(), "{what}: last frame");
    let mut at = 0;
    for (t, v) in kept.t_ns.iter().zip(&kept.value) {
        while all.t_ns[at] != *t {
            at += 1;
            assert!(
                at < all.t_ns.len(),
                "{what}: frame at {t} ns is not a camera frame"
            );
        }
        assert_eq!(*v, all.value[at], "{what} at {t} ns");
    }
    all.t_ns.len() - kept.t_ns.len()
}

#[test]
fn a_30_hz_camera_carries_the_true_state_at_its_own_times() {
    let d = tempfile::tempdir().expect("tempdir");
    let (full, cam, drop) = (
        d.path().join("full.mcap"),
        d.path().join("cam.mcap"),
        d.path().join("drop.mcap"),
    );
    simulate("duhem", 600, 3, &[], &full);
    let out = simulate("duhem", 600, 3, &["--state-rate", "30"], &cam);
    // 5.99 s at 30 Hz: frames 0..=179.
    assert!(
        out.contains("state from a 30 Hz camera: 180 of 180 frames kept"),
        "{out}"
    );
    let out = simulate(
        "duhem",
        600,
        3,
        &["--state-rate", "30", "--state-drop", "0.25"],
        &drop,
    );
    assert!(out.contains("of 180 frames kept (drop 0.25)"), "{out}");

    let paths = ["/input.data", "/state.data", "/sensor.data"];
    let f = read(&full, &paths);
    let c = read(&cam, &paths);
    let p = read(&drop, &paths);
    assert_eq!(f[1].t_ns, log_times(600, 100.0));
    // The input and sensor keep every sample, the values of the full-rate run.
    for other in [&c, &p] {
        for i in [0, 2] {
            assert_eq!(other[i].t_ns, f[i].t_ns, "{}", paths[i]);
            assert_eq!(other[i].value, f[i].value, "{}", paths[i]);
        }
    }
    // Without drops: every frame, at START + j / 30 s (not snapped to the 100 Hz samples).
    let want: Vec<u64> = (0..180).map(|j| frame_time(j, 30.0)).collect();
    assert_eq!(c[1].t_ns, want);
    assert_eq!(c[1].t_ns[1] - START_NS, 33_333_333);
    assert!(c[1].t_ns.iter().any(|t| !f[1].t_ns.contains(t)));
    assert_true_state(&f[1], &c[1], "30 Hz");
    // Every third frame falls on a sample: the sample's state, bit for bit.
    for j in (0..180).step_by(3) {
        assert_eq!(c[1].value[j], f[1].value[j / 3 * 10], "frame {j}");
    }
    // With drops: frames of the same camera, the first and last kept, fewer of them.
    let dropped = assert_subset(&c[1], &p[1], "drop 0.25");
    assert!(dropped > 0 && dropped < 100, "{dropped} of 180 dropped");
    assert!(out.contains(&format!("{} of 180 frames kept", 180 - dropped)));
    assert_true_state(&f[1], &p[1], "30 Hz, drop 0.25");
    let topics = hbn_io::list_topics(&drop).expect("topics");
    let count = |name: &str| {
        topics
            .iter()
            .find(|t| t.topic == name)
            .map(|t| t.message_count)
    };
    assert_eq!(count("/state"), Some(180 - dropped as u64));
    assert_eq!(count("/input"), Some(600));
    assert_eq!(count("/sensor"), Some(600));
}

#[test]
fn a_multi_signal_camera_has_every_component_at_its_frames() {
    let d = tempfile::tempdir().expect("tempdir");
    let (full, cam) = (d.path().join("full.mcap"), d.path().join("cam.mcap"));
    simulate("finger", 500, 4, &["--encoding", "ros2"], &full);
    let out = simulate(
        "finger",
        500,
        4,
        &[
            "--encoding",
            "ros2",
            "--state-rate",
            "30",
            "--state-drop",
            "0.2",
        ],
        &cam,
    );
    assert!(
        out.contains("signals /input0.data, /input1.data, /state.x0"),
        "{out}"
    );
    let paths = [
        "/state.x0",
        "/state.x1",
        "/input0.data",
        "/input1.data",
        "/sensor0.data",
        "/sensor1.data",
        "/sensor2.data",
    ];
    let f = read(&full, &paths);
    let c = read(&cam, &paths);
    let all: Vec<u64> = (0..150).map(|j| frame_time(j, 30.0)).collect();
    assert_eq!(c[0].t_ns, c[1].t_ns);
    assert_eq!(c[0].t_ns.first(), all.first());
    assert_eq!(c[0].t_ns.last(), all.last());
    assert!(c[0].t_ns.iter().all(|t| all.contains(t)));
    assert!(c[0].t_ns.len() < all.len());
    for i in 0..2 {
        assert_true_state(&f[i], &c[i], paths[i]);
    }
    for i in 2..paths.len() {
        assert_eq!(
            (&c[i].t_ns, &c[i].value),
            (&f[i].t_ns, &f[i].value),
            "{}",
            paths[i]
        );
    }
}

#[test]
fn the_drop_fraction_is_binomial_and_the_drops_follow_the_seed() {
    let d = tempfile::tempdir().expect("tempdir");
    // 300 s at 100 Hz: 9001 frames at 30 Hz, the 8999 between the ends each dropped with
    // probability 0.3.
    let steps = 30_001;
    let all = d.path().join("all.mcap");
    simulate("bouc-wen", steps, 5, &["--state-rate", "30"], &all);
    let all = read(&all, &["/state.data"]).remove(0);
    assert_eq!(all.t_ns.len(), 9001);
    assert_eq!(*all.t_ns.last().expect("frames"), frame_time(9000, 30.0));
    let camera = ["--state-rate", "30", "--state-drop", "0.3"];
    let mut kept = Vec::new();
    for (name, seed) in [("a", 5), ("b", 5), ("c", 6)] {
        let file = d.path().join(format!("{name}.mcap"));
        simulate("bouc-wen", steps, seed, &camera, &file);
        kept.push((file.clone(), read(&file, &["/state.data"]).remove(0)));
    }
    let dropped = assert_subset(&all, &kept[0].1, "drop 0.3") as f64;
    let (m, p) = (8999.0f64, 0.3);
    let sd = (m * p * (1.0 - p)).sqrt();
    assert!(
        (dropped - m * p).abs() < 4.5 * sd,
        "{dropped} of {m} dropped, expected {} +- {sd:.1}",
        m * p
    );
    // The same seed writes the same log; another seed drops other frames.
    assert_eq!(
        std::fs::read(&kept[0].0).expect("read"),
        std::fs::read(&kept[1].0).expect("read")
    );
    assert_ne!(kept[0].1.t_ns, kept[2].1.t_ns);
}

#[test]
fn bad_camera_values_fail_naming_the_flag() {
    let d = tempfile::tempdir().expect("tempdir");
    let out = s(&d.path().join("bad.mcap"));
    let cases: [(&[&str], &str, &str); 10] = [
        (&["--state-rate", "200"], "--state-rate", "at most 100"),
        (
            &["--rate", "50", "--state-rate", "60"],
            "--state-rate",
            "at most 50",
        ),
        (&["--state-rate", "0"], "--state-rate", "> 0"),
        (&["--state-rate", "-30"], "--state-rate", "> 0"),
        (&["--state-rate", "nan"], "--state-rate", "> 0"),
        (&["--state-rate", "inf"], "--state-rate", "> 0"),
        (&["--state-rate", "0.2"], "--state-rate", "at least 0.34"),
        (&["--state-drop", "1"], "--state-drop", "[0, 1)"),
        (&["--state-drop", "-0.1"], "--state-drop", "[0, 1)"),
        (&["--state-drop", "half"], "--state-drop", "[0, 1)"),
    ];
    for (flags, flag, fix) in cases {
        let mut args = vec!["simulate", "--steps", "300", "--out", &out];
        args.extend_from_slice(flags);
        let r = run(&args, Duration::from_secs(60));
        assert!(!r.panicked(), "{flags:?} panicked: {}", r.stderr);
        assert_eq!(r.code, Some(2), "{flags:?}: {}\n{}", r.stdout, r.stderr);
        assert!(r.stderr.contains(flag), "{flags:?}: {}", r.stderr);
        assert!(r.stderr.contains(fix), "{flags:?}: {}", r.stderr);
        assert_eq!(
            extra_files(d.path(), &[]),
            Vec::<String>::new(),
            "{flags:?}"
        );
    }
}
