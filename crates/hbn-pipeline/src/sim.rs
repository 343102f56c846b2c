//! Simulated runs as training data and as logs: the one conversion from simulator output to
//! training sequences, and `hbn simulate`'s log writers (scalar and multi-signal systems),
//! with the state at every sample or as a slower camera sees it ([`StateCamera`]).

use std::path::Path;

use hbn_core::rng::Rng;
use hbn_io::{Encoding, TimedTopic};
use hbn_model::Sequence;
use hbn_sim::{InputKind, MultiConfig, MultiTrajectory, SimConfig, SimError, Trajectory};

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
    let traj = simulate_scalar(spec)?;
    let t = log_times(traj.u.len(), spec.config.rate_hz);
    write_scalar_run(file, &traj, &t, &t, &traj.x, spec.encoding)?;
    Ok(traj)
}

/// [`simulate_log`] with the state topic written by `camera` ([`StateCamera::observe`]): the
/// input and sensor topics hold every sample, `/state` the frames the camera kept. Returns
/// the run (the state at every sample) and the frames.
pub fn simulate_camera_log(
    spec: &SimLog,
    camera: &StateCamera,
    file: &Path,
) -> Result<(Trajectory, CameraFrames), PipelineError> {
    let traj = simulate_scalar(spec)?;
    let frames = camera.observe(spec.config.rate_hz, &[&traj.x])?;
    let t = log_times(traj.u.len(), spec.config.rate_hz);
    write_scalar_run(file, &traj, &t, &frames.t_ns, &frames.x[0], spec.encoding)?;
    Ok((traj, frames))
}

/// The run of `spec`.
fn simulate_scalar(spec: &SimLog) -> Result<Trajectory, PipelineError> {
    let u = hbn_sim::generate_input(
        InputKind::RandomRamps,
        spec.steps,
        spec.max_increment,
        spec.input_seed,
    )?;
    Ok(hbn_sim::simulate(&spec.config, &u)?)
}

/// Writes a scalar run: `u` and `y` at the sample times `t`, the state `x` at `state_t`.
fn write_scalar_run(
    file: &Path,
    traj: &Trajectory,
    t: &[u64],
    state_t: &[u64],
    x: &[f64],
    encoding: Encoding,
) -> Result<(), PipelineError> {
    let topics = [
        TimedTopic {
            topic: "/input",
            t_ns: t,
            fields: &[("data", &traj.u)],
        },
        TimedTopic {
            topic: "/state",
            t_ns: state_t,
            fields: &[("data", x)],
        },
        TimedTopic {
            topic: "/sensor",
            t_ns: t,
            fields: &[("data", &traj.y)],
        },
    ];
    write_topics(file, &topics, encoding)
}

/// [`hbn_io::write_timed_log`], its error naming `file`.
fn write_topics(
    file: &Path,
    topics: &[TimedTopic<'_>],
    encoding: Encoding,
) -> Result<(), PipelineError> {
    hbn_io::write_timed_log(file, topics, encoding).map_err(|source| PipelineError::Write {
        file: file.to_owned(),
        source,
    })
}

/// Seed salt of a camera's drops: the drops of seed `s` are independent of the noise and the
/// input drawn from `s`.
const CAMERA_SALT: u64 = 0xCA3E_7A5D_40F5_EED5;

/// A camera that records the state of a simulated run on its own clock, slower than the
/// simulator samples, and drops frames: the state of a real rig, where a camera tracks what
/// the sensor does not see.
///
/// Frame `j` is taken at log time `START_NS + j / rate_hz` (rounded to the nanosecond, as
/// [`log_times`] rounds the samples' times), for every such time up to the run's last sample;
/// it carries the true state at that time, the linear interpolation between the two
/// simulator samples around it (the frames are not snapped to the samples). Each frame is
/// then dropped with probability [`StateCamera::drop`], independently, from a stream seeded
/// by [`StateCamera::seed`]; the first and the last frame are always kept, so the state spans
/// the run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StateCamera {
    /// Frame rate (Hz): positive, finite and at most the simulator's rate.
    pub rate_hz: f64,
    /// Probability that a frame is dropped, in `[0, 1)`.
    pub drop: f64,
    /// Seed of the drops (`hbn simulate` uses its `--seed`).
    pub seed: u64,
}

/// The state as a [`StateCamera`] recorded it.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraFrames {
    /// Log time of each frame kept (ns), increasing.
    pub t_ns: Vec<u64>,
    /// The state at each frame kept: one `Vec` per state component, each as long as `t_ns`.
    pub x: Vec<Vec<f64>>,
    /// Frames the camera took over the run, kept and dropped.
    pub taken: usize,
}

impl StateCamera {
    /// Checks the camera against the simulator's rate `sim_rate_hz`: the rate positive, finite
    /// and at most `sim_rate_hz`, the drop probability in `[0, 1)`.
    pub fn check(&self, sim_rate_hz: f64) -> Result<(), SimError> {
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= sim_rate_hz) {
            return Err(SimError::InvalidParameter {
                name: "camera rate_hz",
                value: self.rate_hz,
                reason: "must be finite, > 0 and at most the simulator's rate",
            });
        }
        if !(0.0..1.0).contains(&self.drop) {
            return Err(SimError::InvalidParameter {
                name: "camera drop",
                value: self.drop,
                reason: "must be a probability in [0, 1)",
            });
        }
        Ok(())
    }

    /// The frames the camera keeps of a run sampled at `sim_rate_hz` from [`START_NS`] (times
    /// [`log_times`]) whose state components are `x` (one slice per component, all as long as
    /// the run). An error when [`StateCamera::check`] fails, when the components' lengths
    /// differ, or when the run is too short for two frames.
    pub fn observe(&self, sim_rate_hz: f64, x: &[&[f64]]) -> Result<CameraFrames, SimError> {
        self.check(sim_rate_hz)?;
        let n = x.first().map_or(0, |c| c.len());
        if x.iter().any(|c| c.len() != n) {
            return Err(SimError::InvalidParameter {
                name: "camera state components",
                value: x.len() as f64,
                reason: "must all be as long as the run",
            });
        }
        let t = log_times(n, sim_rate_hz);
        // Offset of the last sample from the first (ns), exact in an f64 for any run that
        // fits a ROS 2 stamp.
        let span = t.last().map_or(0, |&last| last - START_NS) as f64;
        // The rounding of `log_times`: at the simulator's rate, the frames are the samples.
        let times: Vec<u64> = (0usize..)
            .map(|j| (j as f64 * 1e9 / self.rate_hz).round())
            .take_while(|&offset| offset <= span)
            .map(|offset| START_NS + offset as u64)
            .collect();
        let taken = times.len();
        if taken < 2 {
            return Err(SimError::InvalidParameter {
                name: "camera rate_hz",
                value: self.rate_hz,
                reason: "takes fewer than two frames over the run; raise it or simulate more \
                         samples",
            });
        }
        let mut rng = Rng::new(self.seed ^ CAMERA_SALT);
        let mut out = CameraFrames {
            t_ns: Vec::with_capacity(taken),
            x: vec![Vec::with_capacity(taken); x.len()],
            taken,
        };
        let mut k = 0;
        for (j, &tau) in times.iter().enumerate() {
            // One draw per frame, the first and last included, so that a frame's fate does
            // not depend on the run's length.
            let dropped = rng.uniform() < self.drop && j != 0 && j + 1 != taken;
            if dropped {
                continue;
            }
            while k + 1 < n && t[k + 1] <= tau {
                k += 1;
            }
            // tau in [t[k], t[k + 1]), or tau = t[k] at the last sample.
            let w = match t.get(k + 1) {
                Some(&next) if next > t[k] => (tau - t[k]) as f64 / (next - t[k]) as f64,
                _ => 0.0,
            };
            out.t_ns.push(tau);
            for (c, comp) in out.x.iter_mut().zip(x) {
                let v = if w == 0.0 {
                    comp[k]
                } else {
                    comp[k] + w * (comp[k + 1] - comp[k])
                };
                c.push(v);
            }
        }
        Ok(out)
    }
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
    let traj = simulate_multi_run(spec)?;
    let t = log_times(traj.len(), spec.config.rate_hz);
    write_multi_run(file, &traj, &t, &t, &traj.x, spec.encoding)?;
    Ok(traj)
}

/// [`simulate_multi_log`] with the state topic written by `camera` ([`StateCamera::observe`]):
/// the input and sensor topics hold every sample, `/state` the frames the camera kept, every
/// component at the frames' times. Returns the run (the state at every sample) and the
/// frames.
pub fn simulate_multi_camera_log(
    spec: &MultiSimLog,
    camera: &StateCamera,
    file: &Path,
) -> Result<(MultiTrajectory, CameraFrames), PipelineError> {
    let traj = simulate_multi_run(spec)?;
    let x: Vec<&[f64]> = traj.x.iter().map(Vec::as_slice).collect();
    let frames = camera.observe(spec.config.rate_hz, &x)?;
    let t = log_times(traj.len(), spec.config.rate_hz);
    write_multi_run(file, &traj, &t, &frames.t_ns, &frames.x, spec.encoding)?;
    Ok((traj, frames))
}

/// The run of `spec`.
fn simulate_multi_run(spec: &MultiSimLog) -> Result<MultiTrajectory, PipelineError> {
    let kind = spec.config.system;
    let u = hbn_sim::generate_multi_input(
        kind.inputs(),
        spec.steps,
        spec.max_increment,
        spec.input_seed,
    )?;
    Ok(hbn_sim::simulate_multi(&spec.config, &u)?)
}

/// Writes a multi-signal run: the inputs and sensors at the sample times `t`, the state
/// components `x` at `state_t`.
fn write_multi_run(
    file: &Path,
    traj: &MultiTrajectory,
    t: &[u64],
    state_t: &[u64],
    x: &[Vec<f64>],
    encoding: Encoding,
) -> Result<(), PipelineError> {
    let input_topics: Vec<String> = (0..traj.u.len()).map(multi_input_topic).collect();
    let output_topics: Vec<String> = (0..traj.y.len()).map(multi_output_topic).collect();
    let state_fields: Vec<String> = (0..x.len()).map(multi_state_field).collect();
    let inputs: Vec<[(&str, &[f64]); 1]> =
        traj.u.iter().map(|v| [("data", v.as_slice())]).collect();
    let outputs: Vec<[(&str, &[f64]); 1]> =
        traj.y.iter().map(|v| [("data", v.as_slice())]).collect();
    let state: Vec<(&str, &[f64])> = state_fields
        .iter()
        .zip(x)
        .map(|(f, v)| (f.as_str(), v.as_slice()))
        .collect();
    let mut topics: Vec<TimedTopic<'_>> = input_topics
        .iter()
        .zip(&inputs)
        .map(|(topic, fields)| TimedTopic {
            topic,
            t_ns: t,
            fields,
        })
        .collect();
    topics.push(TimedTopic {
        topic: MULTI_STATE_TOPIC,
        t_ns: state_t,
        fields: &state,
    });
    topics.extend(
        output_topics
            .iter()
            .zip(&outputs)
            .map(|(topic, fields)| TimedTopic {
                topic,
                t_ns: t,
                fields,
            }),
    );
    write_topics(file, &topics, encoding)
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

    fn camera(rate_hz: f64, drop: f64, seed: u64) -> StateCamera {
        StateCamera {
            rate_hz,
            drop,
            seed,
        }
    }

    #[test]
    fn a_camera_takes_frames_on_its_own_clock_and_interpolates_the_state() {
        // 3 s at 100 Hz: samples at START + k * 10 ms, the state the time in seconds (linear,
        // so the interpolation is the time itself) and its square (not linear).
        let n = 301;
        let lin: Vec<f64> = (0..n).map(|k| k as f64 / 100.0).collect();
        let sq: Vec<f64> = lin.iter().map(|v| v * v).collect();
        let f = camera(30.0, 0.0, 1).observe(100.0, &[&lin, &sq]).unwrap();
        // Frames at j / 30 s for j = 0..=90 (the last at 3 s, the last sample).
        assert_eq!(f.taken, 91);
        assert_eq!(f.t_ns.len(), 91);
        for (j, &t) in f.t_ns.iter().enumerate() {
            assert_eq!(t, START_NS + (j as f64 * 1e9 / 30.0).round() as u64, "{j}");
        }
        assert_eq!(f.t_ns[1] - START_NS, 33_333_333);
        assert_eq!(*f.t_ns.last().unwrap(), log_times(n, 100.0)[n - 1]);
        for (j, &t) in f.t_ns.iter().enumerate() {
            let secs = (t - START_NS) as f64 / 1e9;
            assert!(
                (f.x[0][j] - secs).abs() < 1e-12,
                "{j}: {} vs {secs}",
                f.x[0][j]
            );
            // Between samples the square's interpolation lies above the curve by at most
            // h^2 / 4 (h = 10 ms), and on a sample it is the sample.
            let k = (secs * 100.0).floor() as usize;
            let (a, b) = (sq[k], sq[(k + 1).min(n - 1)]);
            assert!(f.x[1][j] >= secs * secs - 1e-12 && f.x[1][j] <= secs * secs + 2.5e-5);
            assert!(f.x[1][j] >= a.min(b) && f.x[1][j] <= a.max(b), "{j}");
        }
        // Every third frame falls on a sample and carries it bit for bit.
        for j in (0..91).step_by(3) {
            assert_eq!(f.x[1][j], sq[j / 3 * 10], "{j}");
        }
    }

    #[test]
    fn a_camera_at_the_simulators_rate_sees_every_sample() {
        let x: Vec<f64> = (0..500).map(|k| (k as f64 * 0.37).sin()).collect();
        for rate in [100.0, 37.5, 1000.0] {
            let f = camera(rate, 0.0, 4).observe(rate, &[&x]).unwrap();
            assert_eq!(f.t_ns, log_times(500, rate), "{rate}");
            assert_eq!(f.x[0], x, "{rate}");
            assert_eq!(f.taken, 500);
        }
    }

    #[test]
    fn a_camera_drops_frames_at_its_rate_and_keeps_the_ends() {
        let n = 100_001; // 1000 s at 100 Hz: 30_001 frames at 30 Hz.
        let x: Vec<f64> = (0..n).map(|k| k as f64).collect();
        let full = camera(30.0, 0.0, 7).observe(100.0, &[&x]).unwrap();
        assert_eq!(full.taken, 30_001);
        for (drop, seed) in [(0.1, 7), (0.5, 8), (0.9, 9)] {
            let f = camera(30.0, drop, seed).observe(100.0, &[&x]).unwrap();
            assert_eq!(f.taken, full.taken);
            assert_eq!(f.t_ns[0], full.t_ns[0]);
            assert_eq!(f.t_ns.last(), full.t_ns.last());
            // The frames kept are frames of the full camera, with their values.
            let mut at = 0;
            for (t, v) in f.t_ns.iter().zip(&f.x[0]) {
                while full.t_ns[at] != *t {
                    at += 1;
                }
                assert_eq!(*v, full.x[0][at]);
            }
            // The dropped share within 5 binomial standard deviations.
            let dropped = (f.taken - f.t_ns.len()) as f64;
            let m = (f.taken - 2) as f64;
            let sd = (m * drop * (1.0 - drop)).sqrt();
            assert!(
                (dropped - m * drop).abs() < 5.0 * sd,
                "drop {drop}: {dropped} of {m}"
            );
            // Deterministic per seed, and another seed drops other frames.
            assert_eq!(camera(30.0, drop, seed).observe(100.0, &[&x]).unwrap(), f);
            let other = camera(30.0, drop, seed + 100)
                .observe(100.0, &[&x])
                .unwrap();
            assert_ne!(other.t_ns, f.t_ns);
        }
    }

    #[test]
    fn bad_cameras_are_errors() {
        let x = vec![0.0; 100];
        for (rate, drop) in [
            (0.0, 0.0),
            (-30.0, 0.0),
            (f64::NAN, 0.0),
            (f64::INFINITY, 0.0),
            (100.5, 0.0),
            (30.0, 1.0),
            (30.0, -0.1),
            (30.0, f64::NAN),
        ] {
            let e = camera(rate, drop, 1).observe(100.0, &[&x]).unwrap_err();
            assert!(
                matches!(e, SimError::InvalidParameter { .. }),
                "{rate} {drop}: {e}"
            );
        }
        // 100 samples at 100 Hz span 0.99 s: one frame at 1 Hz, two at 1.02 Hz.
        let e = camera(1.0, 0.0, 1).observe(100.0, &[&x]).unwrap_err();
        assert!(e.to_string().contains("fewer than two frames"), "{e}");
        assert_eq!(camera(1.02, 0.0, 1).observe(100.0, &[&x]).unwrap().taken, 2);
        // A tiny rate takes one frame and stops.
        assert!(camera(1e-300, 0.0, 1).observe(100.0, &[&x]).is_err());
        let short = vec![0.0; 99];
        assert!(camera(30.0, 0.0, 1).observe(100.0, &[&x, &short]).is_err());
    }

    #[test]
    fn a_camera_log_holds_every_sample_of_u_and_y_and_the_frames_of_x() {
        let dir = tempfile::tempdir().unwrap();
        for encoding in [Encoding::Json, Encoding::Ros2] {
            let spec = SimLog {
                config: SimConfig {
                    noise_gain: 1.0,
                    seed: 5,
                    ..SimConfig::new(hbn_sim::SystemKind::Duhem)
                },
                steps: 600,
                input_seed: 6,
                max_increment: hbn_sim::DEFAULT_MAX_INCREMENT,
                encoding,
            };
            let plain = dir.path().join("plain.mcap");
            let want = simulate_log(&spec, &plain).unwrap();
            let file = dir.path().join("camera.mcap");
            let (traj, frames) = simulate_camera_log(&spec, &camera(30.0, 0.2, 5), &file).unwrap();
            assert_eq!(traj, want);
            let paths: Vec<SignalPath> = ["/input.data", "/state.data", "/sensor.data"]
                .iter()
                .map(|p| p.parse().unwrap())
                .collect();
            let read = hbn_io::read_signals(&file, &paths, &ReadOptions::default()).unwrap();
            let t = log_times(600, 100.0);
            assert_eq!((&read[0].t_ns, &read[0].value), (&t, &want.u));
            assert_eq!((&read[2].t_ns, &read[2].value), (&t, &want.y));
            assert_eq!(
                (&read[1].t_ns, &read[1].value),
                (&frames.t_ns, &frames.x[0])
            );
            assert_eq!(frames.taken, 180); // 5.99 s at 30 Hz: frames 0..=179.
            assert!(frames.t_ns.len() < frames.taken);
            // A camera at the simulator's rate without drops writes the log of simulate_log.
            let same = dir.path().join("same.mcap");
            simulate_camera_log(&spec, &camera(100.0, 0.0, 5), &same).unwrap();
            assert_eq!(
                std::fs::read(&same).unwrap(),
                std::fs::read(&plain).unwrap()
            );
        }
    }

    #[test]
    fn a_multi_signal_camera_log_has_every_component_at_the_frames() {
        let dir = tempfile::tempdir().unwrap();
        for kind in [MultiKind::Finger, MultiKind::Arm] {
            let spec = MultiSimLog {
                config: MultiConfig {
                    noise_gain: 1.0,
                    seed: 2,
                    ..MultiConfig::new(kind)
                },
                steps: 500,
                input_seed: 3,
                max_increment: 0.03,
                encoding: Encoding::Ros2,
            };
            let file = dir.path().join(format!("{kind}.mcap"));
            let (traj, frames) =
                simulate_multi_camera_log(&spec, &camera(30.0, 0.1, 2), &file).unwrap();
            let plain = dir.path().join(format!("{kind}_plain.mcap"));
            assert_eq!(traj, simulate_multi_log(&spec, &plain).unwrap());
            let x: Vec<&[f64]> = traj.x.iter().map(Vec::as_slice).collect();
            assert_eq!(frames, camera(30.0, 0.1, 2).observe(100.0, &x).unwrap());
            let paths: Vec<SignalPath> = (0..kind.states())
                .map(|i| multi_state_path(i).parse().unwrap())
                .chain((0..kind.inputs()).map(|i| multi_input_path(i).parse().unwrap()))
                .collect();
            let read = hbn_io::read_signals(&file, &paths, &ReadOptions::default()).unwrap();
            for (i, sig) in read[..kind.states()].iter().enumerate() {
                assert_eq!(sig.t_ns, frames.t_ns, "{kind} x{i}");
                assert_eq!(sig.value, frames.x[i], "{kind} x{i}");
            }
            for sig in &read[kind.states()..] {
                assert_eq!(sig.t_ns, log_times(500, 100.0), "{kind}");
            }
            let same = dir.path().join(format!("{kind}_same.mcap"));
            simulate_multi_camera_log(&spec, &camera(100.0, 0.0, 2), &same).unwrap();
            assert_eq!(
                std::fs::read(&same).unwrap(),
                std::fs::read(&plain).unwrap()
            );
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
