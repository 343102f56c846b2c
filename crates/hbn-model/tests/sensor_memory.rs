//! The sensor with memory of the state ([`SensorInputs::Memory`]) on a system whose sensor
//! is hysteretic: the Duhem actuator read through a Preisach sensor, whose output depends on
//! the state's past extrema. The thesis' sensor reads `y_{k-1}` for that memory and learns the
//! output's increments; the sensor with memory reads plays of the state and pins its level.

use hbn_core::Mode;
use hbn_model::{HbnParams, HysteresisModel, SENSOR_MEMORY, Selection, SensorInputs, Sequence};
use hbn_sim::{SimConfig, SystemKind, simulate_random};

fn params(sensor_inputs: SensorInputs) -> HbnParams {
    HbnParams {
        max_points: 300,
        n_starts: 1,
        max_iters: 60,
        sensor_inputs,
        select: Selection::default(),
        kernel_evidence: Vec::new(),
        ..HbnParams::default()
    }
}

#[test]
fn a_sensor_with_memory_pins_a_hysteretic_sensors_state() {
    let cfg = SimConfig {
        noise_gain: 1.0,
        ..SimConfig::new(SystemKind::Duhem)
    };
    let train = simulate_random(&cfg, 1500).unwrap();
    let test = simulate_random(&SimConfig { seed: 7, ..cfg }, 1000).unwrap();
    let seqs = [Sequence::new(&train.u, &train.x, &train.y)];
    let thesis = HysteresisModel::fit(&seqs, &params(SensorInputs::Thesis)).unwrap();
    let memory = HysteresisModel::fit(&seqs, &params(SensorInputs::Memory)).unwrap();
    assert!(thesis.sensor_memory().unwrap().is_empty());
    // Two plays of the state, at the fractions of its training range.
    let (lo, hi) = train
        .x
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let radii = memory.sensor_memory().unwrap().radii().to_vec();
    assert_eq!(radii.len(), SENSOR_MEMORY.len());
    for (r, f) in radii.iter().zip(SENSOR_MEMORY) {
        assert!((r - f * (hi - lo)).abs() < 1e-12, "{radii:?}");
    }
    assert_eq!(memory.sensor().kernel().dim, 3);
    let score = |m: &HysteresisModel| {
        let run = m.estimate(&test.u, &test.y, Mode::Ekf).unwrap();
        hbn_model::metrics::nrmse(&run.x, &test.x)
    };
    let (e_thesis, e_memory) = (score(&thesis), score(&memory));
    assert!(
        e_memory < 0.75 * e_thesis,
        "memory {e_memory:.4} against thesis {e_thesis:.4}"
    );
    // The model file keeps the plays: read back, it estimates the same, bit for bit.
    let back = HysteresisModel::from_json(&memory.to_json().unwrap(), "test").unwrap();
    assert_eq!(
        back.sensor_memory().unwrap(),
        memory.sensor_memory().unwrap()
    );
    let (a, b) = (
        memory.estimate(&test.u, &test.y, Mode::Ukf).unwrap(),
        back.estimate(&test.u, &test.y, Mode::Ukf).unwrap(),
    );
    assert_eq!(a.x, b.x);
    // A file whose plays do not match its sensor's inputs is refused, naming both.
    let text = memory.to_json().unwrap();
    let radii = memory.sensor_memory().unwrap().radii().to_vec();
    let written = format!(
        "\"sensor_memory_radii\":{}",
        serde_json::to_string(&radii).unwrap()
    );
    assert!(text.contains(&written), "{written}");
    let edited = text.replace(&written, "\"sensor_memory_radii\":[]");
    let e = HysteresisModel::from_json(&edited, "edited.hbn").unwrap_err();
    assert!(
        e.to_string().contains("sensor_memory_radii") && e.to_string().contains("edited.hbn"),
        "{e}"
    );
}
