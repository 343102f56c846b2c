//! `hbn demo`: simulate -> train -> estimate -> eval, through the subcommands' own functions.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;

use crate::Ui;
use crate::cli::{
    DemoArgs, EncodingArg, EstimateArgs, EvalArgs, EvalModeArg, ModeArg, ReadArgs, SimulateArgs,
};
use clap::Parser;

/// Training logs of the demo.
pub const TRAIN_LOGS: usize = 3;
/// Samples per log.
pub const STEPS: usize = 1000;

/// Runs `hbn demo`.
pub fn run(ui: &mut Ui<'_>, args: &DemoArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let dir = &args.out;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the directory `{}`", dir.display()))?;
    let p = |name: &str| -> PathBuf { dir.join(name) };
    let read = ReadArgs::default();
    let sim = |seed: u64, input_seed: u64, out: PathBuf| SimulateArgs {
        system: args.system,
        steps: STEPS,
        seed,
        noise_gain: args.noise_gain,
        input_seed: Some(input_seed),
        rate: hbn_sim::SimConfig::new(args.system).rate_hz,
        encoding: EncodingArg::Json,
        max_increment: hbn_sim::DEFAULT_MAX_INCREMENT,
        out,
    };

    ui.line(format!(
        "== 1. simulate {} (noise gain {}): {TRAIN_LOGS} training logs with the same input and \
         independent noise, 1 test log with a new input",
        args.system, args.noise_gain
    ))?;
    let mut logs = Vec::new();
    for r in 0..TRAIN_LOGS as u64 {
        let a = sim(
            args.seed.wrapping_mul(1000).wrapping_add(r),
            args.seed,
            p(&format!("train-{}.mcap", r + 1)),
        );
        crate::cmd_simulate::run(ui, &a)?;
        logs.push(a.out);
    }
    let test = sim(
        args.seed.wrapping_add(0xBEEF),
        args.seed.wrapping_add(0x7E57),
        p("test.mcap"),
    );
    crate::cmd_simulate::run(ui, &test)?;

    ui.line("\n== 2. train")?;
    let model = p("model.hbn");
    // The library defaults, with fewer support points so the demo takes seconds.
    let mut train = crate::cli::Cli::try_parse_from([
        "hbn",
        "train",
        "--max-points",
        "300",
        "--seed",
        &args.seed.to_string(),
        "--out",
        &model.to_string_lossy(),
        "--log",
        "-",
    ])
    .map_err(anyhow::Error::new)
    .and_then(|c| match c.command {
        crate::Command::Train(t) => Ok(t),
        _ => Err(anyhow::anyhow!("internal: not a train command")),
    })?;
    train.logs = logs;
    train.read = read.clone();
    crate::cmd_train::run(ui, &train)?;

    ui.line("\n== 3. estimate")?;
    for (mode, stem) in [
        (ModeArg::Ekf, "estimate"),
        (ModeArg::EkfBlr, "estimate-ekf-blr"),
    ] {
        let est = EstimateArgs {
            model: model.clone(),
            log: test.out.clone(),
            mode: Some(mode),
            input: None,
            output: None,
            out: Some(p(&format!("{stem}.mcap"))),
            csv: Some(p(&format!("{stem}.csv"))),
            read: read.clone(),
        };
        crate::cmd_estimate::run(ui, &est)?;
    }

    ui.line("\n== 4. evaluate")?;
    let eval = EvalArgs {
        model: model.clone(),
        log: test.out.clone(),
        mode: EvalModeArg::All,
        input: None,
        state: None,
        output: None,
        plot: Some(p("eval.png")),
        json: false,
        read,
    };
    crate::cmd_eval::run(ui, &eval)?;
    ui.line(format!(
        "\ndemo finished in {:.1} s; files in `{}`. Next: open estimate.mcap beside test.mcap in \
         Foxglove, or run `hbn inspect {}`",
        t0.elapsed().as_secs_f64(),
        dir.display(),
        model.display()
    ))
}
