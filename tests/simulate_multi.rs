//! `hbn simulate --system finger|arm`: the multi-signal log holds the simulated run, read back
//! by message path, in both encodings.

use std::path::Path;

use hbn::pipeline::{multi_input_path, multi_output_path, multi_state_path};
use hbn::sim::{
    DEFAULT_MAX_INCREMENT, MultiConfig, MultiKind, generate_multi_input, simulate_multi,
};
use hbn_io::{ReadOptions, SignalPath};

/// Runs `hbn ARGS` in-process; returns the result and stdout.
fn hbn(args: &[&str]) -> (hbn_cli::anyhow::Result<()>, String) {
    let mut out = Vec::new();
    let mut err = Vec::new();
    let full: Vec<&str> = std::iter::once("hbn").chain(args.iter().copied()).collect();
    let r = hbn_cli::run_with(full, &mut out, &mut err);
    (r, String::from_utf8_lossy(&out).into_owned())
}

fn read(file: &Path, paths: &[String]) -> Vec<hbn_io::RawSignal> {
    let parsed: Vec<SignalPath> = paths.iter().map(|p| p.parse().expect("path")).collect();
    hbn_io::read_signals(file, &parsed, &ReadOptions::default()).expect("read")
}

#[test]
fn simulate_finger_writes_every_signal_in_both_encodings() {
    let d = tempfile::tempdir().expect("tempdir");
    let u = generate_multi_input(2, 600, DEFAULT_MAX_INCREMENT, 5).expect("input");
    let cfg = MultiConfig {
        noise_gain: 1.0,
        seed: 11,
        ..MultiConfig::new(MultiKind::Finger)
    };
    let want = simulate_multi(&cfg, &u).expect("simulate");
    let paths = [
        "/input0.data",
        "/input1.data",
        "/state.x0",
        "/state.x1",
        "/sensor0.data",
        "/sensor1.data",
        "/sensor2.data",
    ]
    .map(str::to_owned);
    let values = [
        &want.u[0], &want.u[1], &want.x[0], &want.x[1], &want.y[0], &want.y[1], &want.y[2],
    ];
    for enc in ["json", "ros2"] {
        let file = d.path().join(format!("finger_{enc}.mcap"));
        let out = file.to_string_lossy().into_owned();
        let (r, stdout) = hbn(&[
            "simulate",
            "--system",
            "finger",
            "--steps",
            "600",
            "--seed",
            "11",
            "--input-seed",
            "5",
            "--noise-gain",
            "1",
            "--encoding",
            enc,
            "--out",
            &out,
        ]);
        r.expect("hbn simulate");
        assert!(stdout.contains("600 finger samples at 100 Hz"), "{stdout}");
        assert!(
            stdout.contains(&format!("signals {}", paths.join(", "))),
            "{stdout}"
        );
        let signals = read(&file, &paths);
        let t0 = signals[0].t_ns.clone();
        assert_eq!(t0.len(), 600);
        for ((sig, want), p) in signals.iter().zip(values).zip(&paths) {
            assert_eq!(&sig.value, want, "{enc} {p}");
            assert_eq!(sig.t_ns, t0, "{enc} {p}");
        }
        let topics = hbn_io::list_topics(&file).expect("topics");
        let names: Vec<&str> = topics.iter().map(|t| t.topic.as_str()).collect();
        assert_eq!(
            names,
            [
                "/input0", "/input1", "/sensor0", "/sensor1", "/sensor2", "/state"
            ]
        );
        let codec = if enc == "json" { "json" } else { "cdr" };
        assert!(topics.iter().all(|t| t.message_encoding == codec));
    }
}

#[test]
fn simulate_arm_writes_the_paths_the_library_names() {
    let d = tempfile::tempdir().expect("tempdir");
    let file = d.path().join("arm.mcap");
    let out = file.to_string_lossy().into_owned();
    let (r, stdout) = hbn(&[
        "simulate", "--system", "arm", "--steps", "300", "--seed", "2", "--rate", "50", "--out",
        &out,
    ]);
    r.expect("hbn simulate");
    assert!(stdout.contains("300 arm samples at 50 Hz"), "{stdout}");
    let kind = MultiKind::Arm;
    let paths: Vec<String> = (0..kind.inputs())
        .map(multi_input_path)
        .chain((0..kind.states()).map(multi_state_path))
        .chain((0..kind.sensors()).map(multi_output_path))
        .collect();
    let cfg = MultiConfig {
        noise_gain: 1.0,
        seed: 2,
        rate_hz: 50.0,
        ..MultiConfig::new(kind)
    };
    let u = generate_multi_input(3, 300, DEFAULT_MAX_INCREMENT, 2).expect("input");
    let want = simulate_multi(&cfg, &u).expect("simulate");
    let values: Vec<&Vec<f64>> = want.u.iter().chain(&want.x).chain(&want.y).collect();
    for ((sig, want), p) in read(&file, &paths).iter().zip(values).zip(&paths) {
        assert_eq!(&sig.value, want, "{p}");
    }
}

#[test]
fn an_unknown_system_names_every_valid_one() {
    let d = tempfile::tempdir().expect("tempdir");
    let out = d.path().join("x.mcap").to_string_lossy().into_owned();
    let (r, _) = hbn(&["simulate", "--system", "hand", "--out", &out]);
    let msg = format!("{:#}", r.expect_err("unknown system"));
    for name in ["hand", "bouc-wen", "soft-actuator", "finger", "arm"] {
        assert!(msg.contains(name), "{msg}");
    }
}
