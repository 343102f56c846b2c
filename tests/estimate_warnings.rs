//! `hbn estimate` warns when a log is recorded at another rate than the model's, and when many
//! samples lie outside the training data (the `extrapolation` flag), when the filter lost the
//! state and re-started (the `relocalised` flag), and says none of it on a log like the
//! training logs.

use std::path::Path;

use hbn_io::{Encoding, ScalarTopic};

fn hbn(args: &[&str]) -> (String, String) {
    let mut out = Vec::new();
    let mut err = Vec::new();
    let full: Vec<&str> = std::iter::once("hbn").chain(args.iter().copied()).collect();
    let r = hbn_cli::run_with(full, &mut out, &mut err);
    let (out, err) = (
        String::from_utf8_lossy(&out).into_owned(),
        String::from_utf8_lossy(&err).into_owned(),
    );
    if let Err(e) = r {
        panic!("hbn {args:?} failed: {e:#}\nstdout: {out}\nstderr: {err}");
    }
    (out, err)
}

fn simulate(out: &str, seed: &str, rate: &str) {
    hbn(&[
        "simulate", "--system", "duhem", "--steps", "600", "--seed", seed, "--rate", rate, "--out",
        out,
    ]);
}

#[test]
fn estimate_warns_about_other_rates_and_data_outside_the_training_range() {
    let d = tempfile::tempdir().expect("tempdir");
    let p = |n: &str| d.path().join(n).to_string_lossy().into_owned();
    let (train, model) = (p("train.mcap"), p("model.hbn"));
    simulate(&train, "1", "100");
    hbn(&[
        "train",
        "--log",
        &train,
        "--max-points",
        "80",
        "--starts",
        "1",
        "--validation",
        "0",
        "--out",
        &model,
    ]);

    // A log like the training log: no warning.
    let same = p("same.mcap");
    simulate(&same, "2", "100");
    let (_, err) = hbn(&["estimate", "--model", &model, "--log", &same]);
    assert!(!err.contains("warning:"), "{err}");

    // The same system recorded at 50 Hz.
    let slow = p("slow.mcap");
    simulate(&slow, "3", "50");
    let (_, err) = hbn(&["estimate", "--model", &model, "--log", &slow]);
    assert!(
        err.contains(
            "warning: /input.data is recorded at 50.0 Hz here but at 100.0 Hz in the training logs"
        ),
        "{err}"
    );

    // An input ten times its training range for most of the log.
    let run = hbn_pipeline::simulate_log(
        &hbn_pipeline::SimLog {
            config: hbn_sim::SimConfig::new(hbn_sim::SystemKind::Duhem),
            steps: 600,
            input_seed: 4,
            max_increment: hbn_sim::DEFAULT_MAX_INCREMENT,
            encoding: Encoding::Json,
        },
        Path::new(&p("scratch.mcap")),
    )
    .expect("simulate");
    let u: Vec<f64> = run
        .u
        .iter()
        .enumerate()
        .map(|(k, v)| if k > 100 { 10.0 * v + 5.0 } else { *v })
        .collect();
    let far = p("far.mcap");
    let t = hbn_pipeline::log_times(u.len(), 100.0);
    let topics = [
        ScalarTopic {
            topic: "/input",
            values: &u,
        },
        ScalarTopic {
            topic: "/sensor",
            values: &run.y,
        },
    ];
    hbn_io::write_scalar_log(Path::new(&far), &t, &topics, Encoding::Json).expect("write");
    // The warning comes without --verbose; the flag counts with it.
    let (_, err) = hbn(&["estimate", "--model", &model, "--log", &far]);
    assert!(
        err.contains("are outside the training data (flag `extrapolation`)"),
        "{err}"
    );
    let (out, _) = hbn(&["estimate", "--model", &model, "--log", &far, "--verbose"]);
    assert!(out.contains("extrapolation x"), "{out}");

    // A sensor that reads far above its training range from sample 300 on (a wrong unit, a
    // broken sensor): the gate down-weights every one of those measurements, and says so.
    let y_bad: Vec<f64> = run
        .y
        .iter()
        .enumerate()
        .map(|(k, v)| if k >= 300 { 100.0 * v + 50.0 } else { *v })
        .collect();
    let topics = [
        ScalarTopic {
            topic: "/input",
            values: &run.u,
        },
        ScalarTopic {
            topic: "/sensor",
            values: &y_bad,
        },
    ];
    let lost = p("lost.mcap");
    hbn_io::write_scalar_log(Path::new(&lost), &t, &topics, Encoding::Json).expect("write");
    let (out, err) = hbn(&["estimate", "--model", &model, "--log", &lost, "--verbose"]);
    assert!(
        err.contains(
            "warning: 300 of 600 measurements (50.0%) were more than 5 standard deviations \
             from the model's prediction (flag `outlier_rejected`)"
        ),
        "{err}"
    );
    assert!(out.contains("outlier_rejected x300"), "{out}");
}
