//! `hbn demo`: the README's worked example (simulate -> train -> estimate -> eval), run as the
//! same command lines through the same parser, each printed before it runs.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::Parser;

use crate::Ui;
use crate::cli::{Cli, DemoArgs};

/// Training logs of the demo.
pub const TRAIN_LOGS: u64 = 3;
/// Samples per log.
pub const STEPS: usize = 1000;

/// The noise seeds of the training logs for `seed`: `10 seed + 1`, `+ 2`, `+ 3` (11, 12, 13 for
/// seed 1); the test log has input seed `seed + 1` and noise seed `10 (seed + 1) + 1` (2 and
/// 21).
fn noise_seed(seed: u64, r: u64) -> u64 {
    seed.wrapping_mul(10).wrapping_add(r)
}

/// The commands of the worked example for `args`, with files in `dir` (each without the
/// leading `hbn`). `hbn demo` runs them in order; the README lists them for `dir` = `.` and
/// the default arguments (a test checks that they agree).
pub fn commands(args: &DemoArgs, dir: &Path) -> Vec<Vec<String>> {
    let p = |name: &str| -> String { dir.join(name).to_string_lossy().into_owned() };
    let rate = hbn_sim::SimConfig::new(args.system).rate_hz;
    let default_rate = hbn_sim::SimConfig::new(hbn_sim::SystemKind::BoucWen).rate_hz;
    let sim = |input_seed: u64, seed: u64, out: String| -> Vec<String> {
        let mut c: Vec<String> = [
            "simulate",
            "--system",
            args.system.name(),
            "--steps",
            &STEPS.to_string(),
            "--input-seed",
            &input_seed.to_string(),
            "--seed",
            &seed.to_string(),
            "--noise-gain",
            &args.noise_gain.to_string(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        if rate != default_rate {
            c.extend(["--rate".to_owned(), rate.to_string()]);
        }
        c.extend(["--out".to_owned(), out]);
        c
    };
    let mut cmds = Vec::new();
    for r in 1..=TRAIN_LOGS {
        cmds.push(sim(
            args.seed,
            noise_seed(args.seed, r),
            p(&format!("train{r}.mcap")),
        ));
    }
    let test_input = args.seed.wrapping_add(1);
    cmds.push(sim(test_input, noise_seed(test_input, 1), p("test.mcap")));
    let mut train = vec!["train".to_owned()];
    for r in 1..=TRAIN_LOGS {
        train.extend(["--log".to_owned(), p(&format!("train{r}.mcap"))]);
    }
    let owned = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
    train.extend(owned(&[
        "--input",
        hbn_pipeline::DEFAULT_INPUT,
        "--state",
        hbn_pipeline::DEFAULT_STATE,
        "--output",
        hbn_pipeline::DEFAULT_OUTPUT,
    ]));
    train.extend(["--out".to_owned(), p("model.hbn")]);
    cmds.push(train);
    cmds.push(vec![
        "estimate".to_owned(),
        "--model".to_owned(),
        p("model.hbn"),
        "--log".to_owned(),
        p("test.mcap"),
        "--csv".to_owned(),
        p("est.csv"),
        "--out".to_owned(),
        p("est.mcap"),
    ]);
    cmds.push(vec![
        "eval".to_owned(),
        "--model".to_owned(),
        p("model.hbn"),
        "--log".to_owned(),
        p("test.mcap"),
        "--plot".to_owned(),
        p("eval.png"),
    ]);
    cmds
}

/// A command line as a shell shows it: `hbn simulate --system bouc-wen ...` (arguments with
/// spaces quoted).
pub fn shell_line(args: &[String]) -> String {
    std::iter::once("hbn".to_owned())
        .chain(args.iter().map(|a| {
            if a.is_empty() || a.contains(|c: char| c.is_whitespace() || c == '\'' || c == '"') {
                format!("'{}'", a.replace('\'', "'\\''"))
            } else {
                a.clone()
            }
        }))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Runs `hbn demo`.
pub fn run(ui: &mut Ui<'_>, args: &DemoArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let dir: &PathBuf = &args.out;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the directory `{}`", dir.display()))?;
    ui.line(format!(
        "The README's worked example for {} (noise gain {}), in `{}`: three training logs with \
         one input and independent noise, a test log with a new input, then train, estimate \
         and evaluate.",
        args.system,
        args.noise_gain,
        dir.display()
    ))?;
    for cmd in commands(args, dir) {
        ui.line(format!("\n$ {}", shell_line(&cmd)))?;
        let cli = Cli::try_parse_from(std::iter::once("hbn".to_owned()).chain(cmd.iter().cloned()))
            .map_err(|e| anyhow::anyhow!("internal: the demo's command does not parse: {e}"))?;
        crate::execute(ui, cli.command)?;
    }
    ui.line(format!(
        "\ndemo finished: took {:.1} s; files in `{}`. Next: look at eval.png, run `hbn inspect \
         {}`, or open est.mcap beside test.mcap in Foxglove",
        t0.elapsed().as_secs_f64(),
        dir.display(),
        dir.join("model.hbn").display()
    ))
}
