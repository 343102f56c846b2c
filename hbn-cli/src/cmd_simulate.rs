//! `hbn simulate`: a simulated system's u, x, y as an MCAP log
//! ([`hbn_pipeline::simulate_log`], [`hbn_pipeline::simulate_multi_log`]).

use anyhow::{Context, bail};
use hbn_io::Encoding;
use hbn_pipeline::{
    MultiSimLog, SimLog, multi_input_path, multi_output_path, multi_state_path, simulate_log,
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

/// Simulates and writes the log; returns the run.
pub fn simulate_to_log(args: &SimulateArgs) -> anyhow::Result<SimRun> {
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
    match args.system {
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
            simulate_log(&spec, &args.out)
                .map(SimRun::Scalar)
                .context("simulation failed")
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
            simulate_multi_log(&spec, &args.out)
                .map(SimRun::Multi)
                .context("simulation failed")
        }
    }
}

/// Runs `hbn simulate`.
pub fn run(ui: &mut Ui<'_>, args: &SimulateArgs) -> anyhow::Result<()> {
    let sim = simulate_to_log(args)?;
    ui.line(format!(
        "wrote `{}`: {} {} samples at {} Hz ({:.2} s), noise gain {}, seed {}, input seed {}; \
         signals {}",
        args.out.display(),
        sim.samples(),
        args.system,
        args.rate,
        sim.samples() as f64 / args.rate,
        args.noise_gain,
        args.seed,
        args.input_seed.unwrap_or(args.seed),
        sim.signals().join(", "),
    ))
}
