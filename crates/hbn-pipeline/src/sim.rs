//! Simulated runs as training data and as logs: the one conversion from simulator output to
//! training sequences, and `hbn simulate`'s log writers (scalar and multi-signal systems).

use std::path::Path;

use hbn_io::{Encoding, ScalarTopic, Topic};
use hbn_model::Sequence;
use hbn_sim::{InputKind, MultiConfig, MultiTrajectory, SimConfig, Trajectory};

use crate::error::PipelineError;

/// Training sequences borrowing simulated runs (one trajectory each).
pub fn sequences(runs: &[Trajectory]) -> Vec<Sequence<'_>> {
    runs.iter()
        .map(|t| Sequence::new(&t.u, &t.x, &t.y))
        .collect()
}

/// Log time of the first sample of a simulated log (ns): 1 s, so that no message is stamped
/// at 0.
pub const START_NS: u64 = 1_000_000_000;

/// Log times of `n` samples at `rate_hz`, starting at [`START_NS`].
pub fn log_times(n: usize, rate_hz: f64) -> Vec<u64> {
    (0..n)
        .map(|k| START_NS + (k as f64 * 1e9 / rate_hz).round() as u64)
        .collect()
}

/// What to simulate into a log.
#[derive(Clone, Debug, PartialEq)]
pub struct SimLog {
    /// System, noise gain, rate and noise seed.
    pub config: SimConfig,
    /// Samples.
    pub steps: usize,
    /// Seed of the random-ramp input.
    pub input_seed: u64,
    /// Largest input increment per sample.
    pub max_increment: f64,
    /// Message encoding.
    pub encoding: Encoding,
}

/// Simulates `spec` and writes `u`, `x`, `y` to `file` as topics `/input`, `/state`,
/// `/sensor` (field `data`, the default training paths), atomically. Returns the run.
pub fn simulate_log(spec: &SimLog, file: &Path) -> Result<Trajectory, PipelineError> {
    let u = hbn_sim::generate_input(
        InputKind::RandomRamps,
        spec.steps,
        spec.max_increment,
        spec.input_seed,
    )?;
    let traj = hbn_sim::simulate(&spec.config, &u)?;
    let t = log_times(traj.u.len(), spec.config.rate_hz);
    let topics = [
        ScalarTopic {
            topic: "/input",
            values: &traj.u,
        },
        ScalarTopic {
            topic: "/state",
            values: &traj.x,
        },
        ScalarTopic {
            topic: "/sensor",
            values: &traj.y,
        },
    ];
    hbn_io::write_scalar_log(file, &t, &topics, spec.encoding).map_err(|source| {
        PipelineError::Write {
            file: file.to_owned(),
            source,
        }
    })?;
    Ok(traj)
}

/// Topic of the state in a multi-signal log: one message per sample with a field per state
/// component ([`multi_state_field`]).
pub const MULTI_STATE_TOPIC: &str = "/state";

/// Topic of input `i` in a multi-signal log: `/input{i}` (field `data`).
pub fn multi_input_topic(i: usize) -> String {
    format!("/input{i}")
}

/// Message path of input `i` in a multi-signal log: `/input{i}.data`.
pub fn multi_input_path(i: usize) -> String {
    format!("{}.data", multi_input_topic(i))
}

/// Field of state component `i` in the messages of [`MULTI_STATE_TOPIC`]: `x{i}`.
pub fn multi_state_field(i: usize) -> String {
    format!("x{i}")
}

/// Message path of state component `i` in a multi-signal log: `/state.x{i}`.
pub fn multi_state_path(i: usize) -> String {
    format!("{MULTI_STATE_TOPIC}.{}", multi_state_field(i))
}

/// Topic of sensor `j` in a multi-signal log: `/sensor{j}` (field `data`).
pub fn multi_output_topic(j: usize) -> String {
    format!("/sensor{j}")
}

/// Message path of sensor `j` in a multi-signal log: `/sensor{j}.data`.
pub fn multi_output_path(j: usize) -> String {
    format!("{}.data", multi_output_topic(j))
}

/// What to simulate into a multi-signal log.
#[derive(Clone, Debug, PartialEq)]
pub struct MultiSimLog {
    /// System, noise gain, rate and noise seed.
    pub config: MultiConfig,
    /// Samples.
    pub steps: usize,
    /// Seed of the random-ramp inputs (one independent ramp per input,
    /// [`hbn_sim::generate_multi_input`]).
    pub input_seed: u64,
    /// Largest increment per sample of each input.
    pub max_increment: f64,
    /// Message encoding.
    pub encoding: Encoding,
}

/// Simulates `spec` and writes it to `file` atomically: input `i` on topic `/input{i}` and
/// sensor `j` on `/sensor{j}` (field `data`), the state on one topic `/state` with a field
/// `x{i}` per component (paths [`multi_input_path`], [`multi_state_path`],
/// [`multi_output_path`]). Returns the run.
pub fn simulate_multi_log(
    spec: &MultiSimLog,
    file: &Path,
) -> Result<MultiTrajectory, PipelineError> {
    let kind = spec.config.system;
    let u = hbn_sim::generate_multi_input(
        kind.inputs(),
        spec.steps,
        spec.max_increment,
        spec.input_seed,
    )?;
    let traj = hbn_sim::simulate_multi(&spec.config, &u)?;
    let t = log_times(traj.len(), spec.config.rate_hz);
    let input_topics: Vec<String> = (0..traj.u.len()).map(multi_input_topic).collect();
    let output_topics: Vec<String> = (0..traj.y.len()).map(multi_output_topic).collect();
    let state_fields: Vec<String> = (0..traj.x.len()).map(multi_state_field).collect();
    let inputs: Vec<[(&str, &[f64]); 1]> =
        traj.u.iter().map(|v| [("data", v.as_slice())]).collect();
    let outputs: Vec<[(&str, &[f64]); 1]> =
        traj.y.iter().map(|v| [("data", v.as_slice())]).collect();
    let state: Vec<(&str, &[f64])> = state_fields
        .iter()
        .zip(&traj.x)
        .map(|(f, v)| (f.as_str(), v.as_slice()))
        .collect();
    let mut topics: Vec<Topic<'_>> = input_topics
        .iter()
        .zip(&inputs)
        .map(|(topic, fields)| Topic { topic, fields })
        .collect();
    topics.push(Topic {
        topic: MULTI_STATE_TOPIC,
        fields: &state,
    });
    topics.extend(
        output_topics
            .iter()
            .zip(&outputs)
            .map(|(topic, fields)| Topic { topic, fields }),
    );
    hbn_io::write_log(file, &t, &topics, spec.encoding).map_err(|source| PipelineError::Write {
        file: file.to_owned(),
        source,
    })?;
    Ok(traj)
}

#[cfg(test)]
mod tests {
    use super::*;
    use hbn_io::{ReadOptions, SignalPath};
    use hbn_sim::MultiKind;

    #[test]
    fn multi_signal_paths() {
        assert_eq!(multi_input_path(0), "/input0.data");
        assert_eq!(multi_input_path(12), "/input12.data");
        assert_eq!(multi_state_path(2), "/state.x2");
        assert_eq!(multi_output_path(3), "/sensor3.data");
        for p in [
            multi_input_path(1),
            multi_state_path(0),
            multi_output_path(2),
        ] {
            let parsed: SignalPath = p.parse().unwrap();
            assert_eq!(parsed.to_string(), p);
        }
    }

    #[test]
    fn a_multi_signal_log_holds_the_run() {
        let dir = tempfile::tempdir().unwrap();
        for (kind, encoding) in [
            (MultiKind::Finger, Encoding::Json),
            (MultiKind::Arm, Encoding::Ros2),
        ] {
            let spec = MultiSimLog {
                config: MultiConfig {
                    noise_gain: 1.0,
                    seed: 3,
                    rate_hz: 50.0,
                    ..MultiConfig::new(kind)
                },
                steps: 400,
                input_seed: 9,
                max_increment: 0.03,
                encoding,
            };
            let file = dir.path().join(format!("{kind}.mcap"));
            let traj = simulate_multi_log(&spec, &file).unwrap();
            let u = hbn_sim::generate_multi_input(kind.inputs(), 400, 0.03, 9).unwrap();
            assert_eq!(traj, hbn_sim::simulate_multi(&spec.config, &u).unwrap());
            let mut paths = Vec::new();
            let mut want = Vec::new();
            for (i, v) in traj.u.iter().enumerate() {
                paths.push(multi_input_path(i));
                want.push(v);
            }
            for (i, v) in traj.x.iter().enumerate() {
                paths.push(multi_state_path(i));
                want.push(v);
            }
            for (j, v) in traj.y.iter().enumerate() {
                paths.push(multi_output_path(j));
                want.push(v);
            }
            let parsed: Vec<SignalPath> = paths.iter().map(|p| p.parse().unwrap()).collect();
            let read = hbn_io::read_signals(&file, &parsed, &ReadOptions::default()).unwrap();
            let t = log_times(400, 50.0);
            for ((sig, v), p) in read.iter().zip(want).zip(&paths) {
                assert_eq!(&sig.value, v, "{kind} {p}");
                assert_eq!(sig.t_ns, t, "{kind} {p}");
            }
            let topics = hbn_io::list_topics(&file).unwrap();
            assert_eq!(topics.len(), kind.inputs() + 1 + kind.sensors(), "{kind}");
        }
        // A bad spec is a simulation error, and no file is written.
        let bad = MultiSimLog {
            config: MultiConfig {
                rate_hz: 0.0,
                ..MultiConfig::new(MultiKind::Finger)
            },
            steps: 10,
            input_seed: 0,
            max_increment: 0.02,
            encoding: Encoding::Json,
        };
        let file = dir.path().join("bad.mcap");
        assert!(matches!(
            simulate_multi_log(&bad, &file),
            Err(PipelineError::Sim(_))
        ));
        assert!(!file.exists());
    }
}
