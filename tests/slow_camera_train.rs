//! Training from a log whose state is a slow camera with dropped frames, end to end through the
//! `hbn` binary: `hbn simulate --state-rate --state-drop`, `hbn train` (expectation-maximisation
//! over the latent samples, said in a warning and recorded in the model file), `hbn estimate
//! --smooth --csv` on a full-rate test log, `hbn eval` on a camera log (scored at its frames).

mod run_hbn;

use run_hbn::{ok, s};

/// `hbn eval` of `model` on a camera log: the table says it scored at the state's `frames`
/// frames, and `--json` gives `state_frames`. Returns the JSON.
fn scored_at_frames(
    model: &std::path::Path,
    log: &std::path::Path,
    frames: usize,
) -> serde_json::Value {
    let scored = ok(&["eval", "--model", &s(model), "--log", &s(log)]);
    let said = format!("scored at the state's {frames} frames");
    assert!(scored.stdout.contains(&said), "{}", scored.stdout);
    let json = ok(&["eval", "--model", &s(model), "--log", &s(log), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&json.stdout).expect("json");
    assert_eq!(v["state_frames"], frames, "{v}");
    v
}

#[test]
fn a_slow_camera_log_trains_by_em_and_estimates() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (train, test, model, csv) = (
        dir.path().join("train.mcap"),
        dir.path().join("test.mcap"),
        dir.path().join("model.hbn"),
        dir.path().join("est.csv"),
    );
    ok(&[
        "simulate",
        "--system",
        "duhem",
        "--steps",
        "1200",
        "--seed",
        "1",
        "--state-rate",
        "30",
        "--state-drop",
        "0.1",
        "--out",
        &s(&train),
    ]);
    ok(&[
        "simulate",
        "--system",
        "duhem",
        "--steps",
        "600",
        "--seed",
        "2",
        "--out",
        &s(&test),
    ]);
    let trained = ok(&[
        "train",
        "--log",
        &s(&train),
        "--out",
        &s(&model),
        "--max-points",
        "200",
        "--starts",
        "1",
    ]);
    let said = format!("{}{}", trained.stdout, trained.stderr);
    assert!(
        said.contains("the samples between them are latent")
            && said.contains("expectation-maximisation"),
        "{said}"
    );
    // The model records how much of the state was measured and each round's held-out score.
    let text = std::fs::read_to_string(&model).expect("model file");
    let file: serde_json::Value = serde_json::from_str(&text).expect("json");
    let latent = &file["model"]["summary"]["latent"];
    let observed = latent["observed"].as_f64().expect("observed");
    assert!((0.2..0.35).contains(&observed), "{latent}");
    let frames = latent["frames"].as_u64().expect("frames");
    assert!((300..=360).contains(&frames), "{latent}");
    assert_eq!(latent["rounds"][0]["round"], 0);
    ok(&[
        "estimate",
        "--model",
        &s(&model),
        "--log",
        &s(&test),
        "--smooth",
        "--csv",
        &s(&csv),
    ]);
    let out = std::fs::read_to_string(&csv).expect("csv");
    let header = out.lines().next().expect("header");
    let columns: Vec<&str> = header.split(',').collect();
    assert!(
        columns.contains(&"x") && columns.contains(&"x_std"),
        "{header}"
    );
    assert_eq!(out.lines().count(), 601);
    // `hbn eval` on a camera log scores at the camera's frames only, and says so.
    let camera_test = dir.path().join("camera_test.mcap");
    ok(&[
        "simulate",
        "--system",
        "duhem",
        "--steps",
        "600",
        "--seed",
        "2",
        "--state-rate",
        "20",
        "--out",
        &s(&camera_test),
    ]);
    let v = scored_at_frames(&model, &camera_test, 120);
    assert_eq!(v["calibration"]["ekf"]["samples"], 120, "{v}");
    // A log with the state at every sample trains as before: no EM, nothing recorded.
    let full = dir.path().join("full.mcap");
    ok(&[
        "simulate",
        "--system",
        "duhem",
        "--steps",
        "600",
        "--seed",
        "3",
        "--out",
        &s(&full),
    ]);
    let plain = dir.path().join("plain.hbn");
    let r = ok(&[
        "train",
        "--log",
        &s(&full),
        "--out",
        &s(&plain),
        "--max-points",
        "150",
        "--starts",
        "1",
    ]);
    assert!(!format!("{}{}", r.stdout, r.stderr).contains("latent"));
    let text = std::fs::read_to_string(&plain).expect("model file");
    assert!(!text.contains("\"latent\""));
}

/// A vector model (the finger) trained from a 10 Hz camera treats the samples between the
/// frames as latent (expectation-maximisation, said in a warning and recorded in the model
/// file), smooths a full-rate log, and `hbn eval` on a camera log scores at its frames.
#[test]
fn a_vector_model_trains_from_a_camera_by_em() {
    let dir = tempfile::tempdir().expect("temp dir");
    let (log, model, test, csv) = (
        dir.path().join("finger.mcap"),
        dir.path().join("finger.hbn"),
        dir.path().join("finger_test.mcap"),
        dir.path().join("finger.csv"),
    );
    let finger = |seed: &str, extra: &[&str], out: &std::path::Path| {
        let mut args = vec![
            "simulate", "--system", "finger", "--steps", "1200", "--seed", seed,
        ];
        args.extend_from_slice(extra);
        let out = s(out);
        args.extend_from_slice(&["--out", &out]);
        ok(&args);
    };
    finger("2", &["--state-rate", "10"], &log);
    let run = ok(&[
        "train",
        "--log",
        &s(&log),
        "--max-points",
        "120",
        "--starts",
        "1",
        "--out",
        &s(&model),
    ]);
    assert!(
        run.stdout
            .contains("the state was measured at 10% of the grid's samples (120 frames)")
            && run.stdout.contains("latent")
            && run.stdout.contains("expectation-maximisation"),
        "{}",
        run.stdout
    );
    let text = std::fs::read_to_string(&model).expect("model file");
    let file: serde_json::Value = serde_json::from_str(&text).expect("json");
    let latent = &file["model"]["summary"]["latent"];
    let observed = latent["observed"].as_f64().expect("observed");
    assert!((0.09..0.11).contains(&observed), "{latent}");
    assert_eq!(latent["frames"], 120, "{latent}");
    assert_eq!(latent["rounds"][0]["round"], 0, "{latent}");
    // A full-rate log smooths into the vector CSV columns.
    finger("3", &[], &test);
    ok(&[
        "estimate",
        "--model",
        &s(&model),
        "--log",
        &s(&test),
        "--smooth",
        "--csv",
        &s(&csv),
    ]);
    let out = std::fs::read_to_string(&csv).expect("csv");
    let header = out.lines().next().expect("header");
    assert!(header.starts_with("t,x0,x0_std,x1,x1_std"), "{header}");
    assert_eq!(out.lines().count(), 1201);
    // A camera log is scored at its frames, each component.
    let camera_test = dir.path().join("camera_test.mcap");
    finger("4", &["--state-rate", "20"], &camera_test);
    scored_at_frames(&model, &camera_test, 240);
    // A camera at the sensor's rate: no EM.
    finger("2", &[], &log);
    let run = ok(&[
        "train",
        "--log",
        &s(&log),
        "--max-points",
        "120",
        "--starts",
        "1",
        "--out",
        &s(&model),
    ]);
    assert!(
        !run.stdout.contains("the state was measured at"),
        "{}",
        run.stdout
    );
    let text = std::fs::read_to_string(&model).expect("model file");
    let file: serde_json::Value = serde_json::from_str(&text).expect("json");
    assert!(file["model"]["summary"]["latent"].is_null());
}
