//! `hbn simulate`: a simulated system's u, x, y as an MCAP log
//! ([`hbn_pipeline::simulate_log`], [`hbn_pipeline::simulate_multi_log`]), the state at
//! every sample or as a slower camera records it ([`hbn_pipeline::StateCamera`]).

use anyhow::{Context, bail};
use hbn_io::Encoding;
use hbn_pipeline::{
    CameraFrames, MultiSimLog, SimLog, StateCamera, multi_input_path, multi_output_path,
    multi_state_path, simulate_camera_log, simulate_log, simulate_multi_camera_log,
    simulate_multi_log,
};
use hbn_sim::{MultiConfig, MultiTrajectory, SimConfig, Trajectory};

use crate::Ui;
use crate::cli::{EncodingArg, SimSystem, SimulateArgs};

/// A simulated run as written to the log.
#[derive(Clone, Debug, PartialEq)]
pub enum SimRun {
    /// A scalar system's run.
    Scalar(Trajectory),
    /// A multi-signal system's run.
    Multi(MultiTrajectory),
}

impl SimRun {
    /// Number of samples.
    pub fn samples(&self) -> usize {
        match self {
            SimRun::Scalar(t) => t.u.len(),
            SimRun::Multi(t) => t.len(),
        }
    }

    /// The message paths of the signals written, inputs first, then the state, then the
    /// sensors.
    pub fn signals(&self) -> Vec<String> {
        match self {
            SimRun::Scalar(_) => [
                hbn_pipeline::DEFAULT_INPUT,
                hbn_pipeline::DEFAULT_STATE,
                hbn_pipeline::DEFAULT_OUTPUT,
            ]
            .map(str::to_owned)
            .to_vec(),
            SimRun::Multi(t) => (0..t.u.len())
                .map(multi_input_path)
                .chain((0..t.x.len()).map(multi_state_path))
                .chain((0..t.y.len()).map(multi_output_path))
                .collect(),
        }
    }
}

/// What `hbn simulate` wrote: the run, and the camera's frames when the state topic is a
/// camera's (`--state-rate`, `--state-drop`).
#[derive(Clone, Debug, PartialEq)]
pub struct Simulated {
    /// The run, the state at every sample.
    pub run: SimRun,
    /// The frames of the state topic, or `None` when it holds every sample.
    pub camera: Option<CameraFrames>,
}

/// The camera of `--state-rate` and `--state-drop`, or `None` for the state at every sample.
/// A rate above `--rate` is a usage error that names both flags.
pub fn camera(args: &SimulateArgs) -> anyhow::Result<Option<StateCamera>> {
    if args.state_rate.is_none() && args.state_drop == 0.0 {
        return Ok(None);
    }
    let rate_hz = args.state_rate.unwrap_or(args.rate);
    let bad_rate = |why: String| {
        anyhow::Error::new(clap::Error::raw(
            clap::error::ErrorKind::ValueValidation,
            format!("invalid value '{rate_hz}' for '--state-rate <HZ>': {why}\n"),
        ))
    };
    if rate_hz > args.rate {
        return Err(bad_rate(format!(
            "the camera cannot be faster than the simulator (--rate {}); give --state-rate at \
             most {}, or raise --rate",
            args.rate, args.rate
        )));
    }
    // The second frame must fall within the run (the library's rounding to nanoseconds).
    let span_ns = (args.steps.saturating_sub(1) as f64 * 1e9 / args.rate).round();
    if (1e9 / rate_hz).round() > span_ns {
        let span_s = span_ns / 1e9;
        return Err(bad_rate(format!(
            "the camera takes fewer than two frames over the run's {span_s:.2} s (--steps {} at \
             --rate {}); give --state-rate at least {:.2}, or more --steps",
            args.steps,
            args.rate,
            ((1.0 / span_s) * 100.0).ceil() / 100.0
        )));
    }
    Ok(Some(StateCamera {
        rate_hz,
        drop: args.state_drop,
        seed: args.seed,
    }))
}

/// Simulates and writes the log; returns the run and the camera's frames.
pub fn simulate_to_log(args: &SimulateArgs) -> anyhow::Result<Simulated> {
    let camera = camera(args)?;
    crate::check_output(&args.out, "output log")?;
    if args.steps < hbn_model::MIN_SAMPLES {
        bail!(
            "--steps must be at least {}, got {}",
            hbn_model::MIN_SAMPLES,
            args.steps
        );
    }
    let input_seed = args.input_seed.unwrap_or(args.seed);
    let encoding = match args.encoding {
        EncodingArg::Json => Encoding::Json,
        EncodingArg::Ros2 => Encoding::Ros2,
    };
    let written = match args.system {
        SimSystem::Scalar(system) => {
            let spec = SimLog {
                config: SimConfig {
                    system,
                    noise_gain: args.noise_gain,
                    rate_hz: args.rate,
                    seed: args.seed,
                },
                steps: args.steps,
                input_seed,
                max_increment: args.max_increment,
                encoding,
            };
            match &camera {
                None => simulate_log(&spec, &args.out).map(|t| (SimRun::Scalar(t), None)),
                Some(c) => simulate_camera_log(&spec, c, &args.out)
                    .map(|(t, f)| (SimRun::Scalar(t), Some(f))),
            }
        }
        SimSystem::Multi(system) => {
            let spec = MultiSimLog {
                config: MultiConfig {
                    system,
                    noise_gain: args.noise_gain,
                    rate_hz: args.rate,
                    seed: args.seed,
                },
                steps: args.steps,
                input_seed,
                max_increment: args.max_increment,
                encoding,
            };
            match &camera {
                None => simulate_multi_log(&spec, &args.out).map(|t| (SimRun::Multi(t), None)),
                Some(c) => simulate_multi_camera_log(&spec, c, &args.out)
                    .map(|(t, f)| (SimRun::Multi(t), Some(f))),
            }
        }
    };
    let (run, camera) = written.context("simulation failed")?;
    Ok(Simulated { run, camera })
}

/// Runs `hbn simulate`.
pub fn run(ui: &mut Ui<'_>, args: &SimulateArgs) -> anyhow::Result<()> {
    let Simulated { run: sim, camera } = simulate_to_log(args)?;
    let state = match &camera {
        None => String::new(),
        Some(f) => format!(
            "; state from a {} Hz camera: {} of {} frames kept (drop {})",
            args.state_rate.unwrap_or(args.rate),
            f.t_ns.len(),
            f.taken,
            args.state_drop
        ),
    };
    ui.line(format!(
        "wrote `{}`: {} {} samples at {} Hz ({:.2} s), noise gain {}, seed {}, input seed {}{}; \
         signals {}",
        args.out.display(),
        sim.samples(),
        args.system,
        args.rate,
        sim.samples() as f64 / args.rate,
        args.noise_gain,
        args.seed,
        args.input_seed.unwrap_or(args.seed),
        state,
        sim.signals().join(", "),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cli::{Cli, Command};
    use clap::Parser;

    fn args(flags: &[&str]) -> SimulateArgs {
        let line = ["hbn", "simulate", "--out", "x.mcap"].iter().chain(flags);
        match Cli::try_parse_from(line).unwrap().command {
            Command::Simulate(a) => a,
            other => panic!("{other:?}"),
        }
    }

    fn usage_error(flags: &[&str]) -> String {
        let e = camera(&args(flags)).unwrap_err();
        e.downcast_ref::<clap::Error>().unwrap().to_string()
    }

    #[test]
    fn the_camera_flags_make_a_camera() {
        assert_eq!(camera(&args(&[])).unwrap(), None);
        let c = camera(&args(&["--state-rate", "30", "--seed", "4"])).unwrap();
        assert_eq!(
            c,
            Some(StateCamera {
                rate_hz: 30.0,
                drop: 0.0,
                seed: 4
            })
        );
        // Drops alone: a camera at the simulator's rate.
        let c = camera(&args(&["--state-drop", "0.2", "--rate", "50"])).unwrap();
        assert_eq!(
            c,
            Some(StateCamera {
                rate_hz: 50.0,
                drop: 0.2,
                seed: 1
            })
        );
        assert!(camera(&args(&["--state-rate", "100"])).unwrap().is_some());
    }

    #[test]
    fn a_camera_faster_than_the_simulator_or_with_one_frame_is_a_usage_error() {
        let e = usage_error(&["--state-rate", "100.5"]);
        assert!(
            e.contains("'--state-rate <HZ>'") && e.contains("at most 100"),
            "{e}"
        );
        let e = usage_error(&["--rate", "20", "--state-rate", "30"]);
        assert!(e.contains("at most 20, or raise --rate"), "{e}");
        // 1000 samples at 100 Hz span 9.99 s: the second frame at 0.1 Hz is at 10 s.
        let e = usage_error(&["--steps", "1000", "--state-rate", "0.1"]);
        assert!(
            e.contains("fewer than two frames") && e.contains("at least 0.11"),
            "{e}"
        );
        assert!(camera(&args(&["--steps", "1000", "--state-rate", "0.11"])).is_ok());
        for bad in [["--state-drop", "1"], ["--state-rate", "0"]] {
            let line = ["hbn", "simulate", "--out", "x.mcap"].iter().chain(&bad);
            let e = Cli::try_parse_from(line).unwrap_err().to_string();
            assert!(e.contains(bad[0]), "{e}");
        }
    }
}
