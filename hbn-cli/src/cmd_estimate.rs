//! `hbn estimate`: run the filter over a log and write the estimate
//! ([`hbn_pipeline::estimate_log`]).

use std::path::Path;

use anyhow::Context;
use hbn_model::{Estimate, HbnModel};
use hbn_pipeline::{LogEstimate, Outputs, SignalChoice, estimate_log};

use crate::Ui;
use crate::cli::EstimateArgs;
use crate::report::{self, Renderer};

/// Loads a model, naming the file in errors.
pub fn load_model(file: &Path) -> anyhow::Result<HbnModel> {
    HbnModel::load(file).with_context(|| format!("cannot load the model `{}`", file.display()))
}

/// Summary line of a run.
pub fn summary(est: &Estimate, mode: hbn_core::Mode) -> String {
    let finite_nis: Vec<f64> = est.nis.iter().copied().filter(|v| v.is_finite()).collect();
    let mean_nis = if finite_nis.is_empty() {
        f64::NAN
    } else {
        finite_nis.iter().sum::<f64>() / finite_nis.len() as f64
    };
    let mut s = format!("  {mode}: {} samples, mean NIS {mean_nis:.3}", est.len());
    let counts = est.flag_counts();
    if counts.is_empty() {
        s.push_str(", no guard flags");
    } else {
        let c: Vec<String> = counts.iter().map(|(n, c)| format!("{n} x{c}")).collect();
        s.push_str(&format!(", flags: {}", c.join(", ")));
    }
    if let Some(o) = est.observability() {
        s.push_str(&format!(
            ", near-unobservable {:.1}%",
            100.0 * o.near_unobservable
        ));
    }
    s.push('\n');
    s
}

/// Runs `hbn estimate`; returns the log and the estimate.
pub fn run(ui: &mut Ui<'_>, args: &EstimateArgs) -> anyhow::Result<LogEstimate> {
    for (f, what) in [(&args.out, "MCAP output"), (&args.csv, "CSV output")] {
        if let Some(f) = f {
            crate::check_output(f, what)?;
        }
    }
    let model = load_model(&args.model)?;
    let signals = SignalChoice {
        input: args.input.clone(),
        state: None,
        output: args.output.clone(),
    };
    let outputs = Outputs {
        csv: args.csv.clone(),
        mcap: args.out.clone(),
    };
    let opts = args.read.options(None);
    let mut render = Renderer::default();
    let result = estimate_log(
        &model,
        &args.log,
        &signals,
        args.mode.map_or(model.default_mode(), Into::into),
        opts,
        &outputs,
        &mut |e| render.event(ui, e),
    );
    render.finish();
    let est = result
        .map_err(|e| report::error(e, opts.time_source))
        .with_context(|| format!("estimation on `{}` failed", args.log.display()))?;
    let mut text = format!(
        "estimated `{}` with `{}` at {:.1} Hz (a {:.2} s log)\n",
        args.log.display(),
        args.model.display(),
        model.rate_hz(),
        est.log.aligned.t_s.last().copied().unwrap_or(0.0)
    );
    text.push_str(&summary(&est.estimate, est.mode));
    for (f, what) in [(&args.out, "MCAP (/hbn/estimate)"), (&args.csv, "CSV")] {
        if let Some(f) = f {
            text.push_str(&format!("  wrote {what}: `{}`\n", f.display()));
        }
    }
    if args.out.is_none() && args.csv.is_none() {
        text.push_str("  (no --out or --csv given: nothing written)\n");
    }
    ui.print(text)?;
    for w in est.warnings() {
        ui.warn(w);
    }
    Ok(est)
}
