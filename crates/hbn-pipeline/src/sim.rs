//! Simulated runs as training data and as logs: the one conversion from simulator output to
//! training sequences, and `hbn simulate`'s log writer.

use std::path::Path;

use hbn_io::{Encoding, ScalarTopic};
use hbn_model::Sequence;
use hbn_sim::{InputKind, SimConfig, Trajectory};

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
