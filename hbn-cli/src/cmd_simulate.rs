//! `hbn simulate`: a simulated system's u, x, y as an MCAP log
//! ([`hbn_pipeline::simulate_log`]).

use anyhow::{Context, bail};
use hbn_io::Encoding;
use hbn_pipeline::{SimLog, simulate_log};
use hbn_sim::{SimConfig, Trajectory};

use crate::Ui;
use crate::cli::{EncodingArg, SimulateArgs};

/// Simulates and writes the log; returns the trajectory.
pub fn simulate_to_log(args: &SimulateArgs) -> anyhow::Result<Trajectory> {
    crate::check_output(&args.out, "output log")?;
    if args.steps < hbn_model::MIN_SAMPLES {
        bail!(
            "--steps must be at least {}, got {}",
            hbn_model::MIN_SAMPLES,
            args.steps
        );
    }
    let spec = SimLog {
        config: SimConfig {
            system: args.system,
            noise_gain: args.noise_gain,
            rate_hz: args.rate,
            seed: args.seed,
        },
        steps: args.steps,
        input_seed: args.input_seed.unwrap_or(args.seed),
        max_increment: args.max_increment,
        encoding: match args.encoding {
            EncodingArg::Json => Encoding::Json,
            EncodingArg::Ros2 => Encoding::Ros2,
        },
    };
    simulate_log(&spec, &args.out).context("simulation failed")
}

/// Runs `hbn simulate`.
pub fn run(ui: &mut Ui<'_>, args: &SimulateArgs) -> anyhow::Result<()> {
    let traj = simulate_to_log(args)?;
    ui.line(format!(
        "wrote `{}`: {} {} samples at {} Hz ({:.2} s), noise gain {}, seed {}, input seed {}; \
         signals /input.data, /state.data, /sensor.data",
        args.out.display(),
        traj.u.len(),
        args.system,
        args.rate,
        traj.u.len() as f64 / args.rate,
        args.noise_gain,
        args.seed,
        args.input_seed.unwrap_or(args.seed),
    ))
}
