//! `hbn train`: fit the HBN to logs.

use anyhow::{Context, bail};
use hbn_model::{HbnModel, HbnParams, KernelChoice, Sequence, SignalInfo, Signals};

use crate::Ui;
use crate::cli::TrainArgs;
use crate::logdata::{self, ReadSettings};

fn info(name: &str, path: &hbn_io::SignalPath) -> SignalInfo {
    SignalInfo {
        name: name.into(),
        path: Some(path.to_string()),
        unit: None,
    }
}

/// Trains, saves and summarises; returns the model.
pub fn run(ui: &mut Ui<'_>, args: &TrainArgs) -> anyhow::Result<HbnModel> {
    crate::check_output(&args.out, "model file")?;
    if args.logs.is_empty() {
        bail!("give at least one --log");
    }
    if args.starts == 0 {
        bail!("--starts must be at least 1");
    }
    if args.max_points < 3 {
        bail!("--max-points must be at least 3, got {}", args.max_points);
    }
    let settings = ReadSettings::from(&args.read);
    let paths = [args.input.clone(), args.state.clone(), args.output.clone()];
    let mut rate = args.rate;
    let mut logs = Vec::with_capacity(args.logs.len());
    for file in &args.logs {
        let data = logdata::load(ui, file, &paths, rate, &settings)?;
        rate = Some(data.aligned.rate_hz);
        if data.len() < 10 {
            bail!(
                "`{}` has only {} aligned samples at {:.1} Hz; record a longer log",
                file.display(),
                data.len(),
                data.aligned.rate_hz
            );
        }
        logs.push(data);
    }
    let rate_hz = rate.unwrap_or(100.0);
    let default_kernel = args.kernel.unwrap_or_default();
    let params = HbnParams {
        rate_hz,
        transition_kernel: args.transition_kernel.unwrap_or(default_kernel),
        sensor_kernel: args.sensor_kernel.unwrap_or(default_kernel),
        n_inducing: args
            .inducing
            .map_or(HbnParams::default().n_inducing, |i| i.0),
        max_points: args.max_points,
        n_starts: args.starts,
        max_iters: args.max_iters,
        seed: args.seed,
        blr_window: args.blr_window,
        signals: Signals {
            input: info("u", &args.input),
            state: info("x", &args.state),
            output: info("y", &args.output),
        },
        ..HbnParams::default()
    };
    let seqs: Vec<Sequence<'_>> = logs
        .iter()
        .map(|d| Sequence {
            u: d.column(0),
            x: d.column(1),
            y: d.column(2),
        })
        .collect();
    let samples: usize = logs.iter().map(|d| d.len()).sum();
    let pb = crate::progress::bar(ui.quiet, 2 * args.starts as u64, "training");
    pb.set_message(format!("{samples} samples at {rate_hz:.1} Hz"));
    let result = HbnModel::fit_observed(&seqs, &params, &mut |which, p| {
        pb.inc(1);
        let best = p
            .best_lml
            .map_or_else(|| "-".to_owned(), |l| format!("{l:.1}"));
        pb.set_message(format!(
            "{which} GP start {}/{} (best LML {best})",
            p.start + 1,
            p.n_starts
        ));
    });
    pb.finish_and_clear();
    let mut model = result.context("training failed")?;
    model.set_signals(params.signals.clone());
    model
        .save(&args.out)
        .with_context(|| format!("cannot save the model to `{}`", args.out.display()))?;
    print_summary(ui, &model, samples, &args.out)?;
    Ok(model)
}

fn kernel_name(k: KernelChoice) -> String {
    k.to_string()
}

/// Prints the training summary.
pub fn print_summary(
    ui: &mut Ui<'_>,
    model: &HbnModel,
    samples: usize,
    out: &std::path::Path,
) -> anyhow::Result<()> {
    let s = model.summary();
    let p = model.params();
    let mut text = format!(
        "trained `{}` from {} log(s): {} samples at {:.1} Hz, {} rows per GP, {:.1} s\n",
        out.display(),
        s.trajectories,
        samples,
        model.rate_hz(),
        s.rows,
        s.seconds
    );
    for (name, gp, k) in [
        ("transition", model.transition(), p.transition_kernel),
        ("sensor", model.sensor(), p.sensor_kernel),
    ] {
        let (points, score) = if gp.is_sparse() {
            ("inducing points", "bound")
        } else {
            ("support points", "LML")
        };
        text.push_str(&format!(
            "  {name:<10} GP: {:>4} {points}, {score} {:>10.2}, kernel {}\n",
            gp.n_support(),
            gp.log_marginal_likelihood(),
            kernel_name(k)
        ));
    }
    if s.warnings.is_empty() {
        text.push_str("  no warnings\n");
    } else {
        for w in &s.warnings {
            text.push_str(&format!("  warning: {w}\n"));
        }
    }
    ui.print(text)
}
