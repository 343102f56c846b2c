//! `hbn simulate`: a simulated system's u, x, y as an MCAP log.

use anyhow::{Context, bail};
use hbn_io::{Encoding, ScalarTopic};
use hbn_sim::{InputKind, SimConfig, Trajectory};

use crate::Ui;
use crate::cli::{EncodingArg, SimulateArgs};

/// Log time of the first sample (ns): 1 s, so that no message is stamped at 0.
pub const START_NS: u64 = 1_000_000_000;

/// Log times of `n` samples at `rate_hz`, starting at [`START_NS`].
pub fn log_times(n: usize, rate_hz: f64) -> Vec<u64> {
    (0..n)
        .map(|k| START_NS + (k as f64 * 1e9 / rate_hz).round() as u64)
        .collect()
}

/// Simulates and writes the log; returns the trajectory.
pub fn simulate_to_log(args: &SimulateArgs) -> anyhow::Result<Trajectory> {
    crate::check_output(&args.out, "output log")?;
    if args.steps < 3 {
        bail!("--steps must be at least 3, got {}", args.steps);
    }
    let u = hbn_sim::generate_input(
        InputKind::RandomRamps,
        args.steps,
        args.max_increment,
        args.input_seed.unwrap_or(args.seed),
    )
    .context("cannot generate the input")?;
    let cfg = SimConfig {
        system: args.system,
        noise_gain: args.noise_gain,
        rate_hz: args.rate,
        seed: args.seed,
    };
    let traj = hbn_sim::simulate(&cfg, &u).context("simulation failed")?;
    let t = log_times(traj.u.len(), args.rate);
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
    let enc = match args.encoding {
        EncodingArg::Json => Encoding::Json,
        EncodingArg::Ros2 => Encoding::Ros2,
    };
    hbn_io::write_scalar_log(&args.out, &t, &topics, enc)
        .with_context(|| format!("cannot write `{}`", args.out.display()))?;
    Ok(traj)
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
