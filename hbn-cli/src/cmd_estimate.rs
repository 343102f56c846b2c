//! `hbn estimate`: run the filter over a log and write the estimate
//! ([`hbn_pipeline::estimate_log_modes`]).

use std::path::Path;

use anyhow::Context;
use hbn_core::Mode;
use hbn_model::{Estimate, HysteresisModel, VectorModel};
use hbn_pipeline::{LogEstimate, LogOption, Outputs, SignalChoice, estimate_log_modes};
use serde_json::{Value, json};

use crate::Ui;
use crate::cli::EstimateArgs;
use crate::glossary::{self, Term};
use crate::report::{self, Renderer};

/// Whether `file` is a vector model's file (its format tag; any other content is left to the
/// scalar loader, which names the problem).
pub fn is_vector_model(file: &Path) -> bool {
    std::fs::read(file)
        .ok()
        .and_then(|b| serde_json::from_slice::<Value>(&b).ok())
        .and_then(|v| v.get("format").and_then(|f| f.as_str().map(str::to_owned)))
        .is_some_and(|f| f == hbn_model::vector::VECTOR_MODEL_FORMAT)
}

/// The one path a scalar model takes from a repeatable flag (`None`: the model's).
pub fn one_path(
    v: &[hbn_io::SignalPath],
    flag: &str,
    model: &Path,
) -> anyhow::Result<Option<hbn_io::SignalPath>> {
    if v.len() > 1 {
        anyhow::bail!(
            "{flag} is given {} times, but `{}` is a scalar model (one input, one state, one \
             sensor); give it once",
            v.len(),
            model.display()
        );
    }
    Ok(v.first().cloned())
}

/// How to read a log for a vector model: as its training logs were read, with these flags'
/// values where given.
pub fn vector_log_options(
    model: &VectorModel,
    read: &crate::cli::ModelReadArgs,
) -> hbn_pipeline::LogOptions {
    let mut opts = hbn_pipeline::LogOptions {
        min_coverage: read.min_coverage,
        ..hbn_pipeline::LogOptions::default()
    };
    if let Some((t, gap)) = model.read_options() {
        if let Ok(ts) = hbn_pipeline::parse_time_source(t) {
            opts.time_source = ts;
        }
        opts.max_gap_s = gap;
    }
    if let Some(ts) = read.time_source {
        opts.time_source = ts.into();
    }
    if let Some(gap) = read.max_gap {
        opts.max_gap_s = gap;
    }
    opts
}

/// `hbn estimate` with a vector model: the CSV of [`hbn_pipeline::vector_csv`] and the MCAP
/// log of [`hbn_pipeline::VectorLogEstimate::write_mcap`].
fn run_vector(ui: &mut Ui<'_>, args: &EstimateArgs) -> anyhow::Result<()> {
    let model = VectorModel::load(&args.model)
        .with_context(|| format!("cannot load the model `{}`", args.model.display()))?;
    let mode = match args.mode {
        None => model.default_mode(),
        Some(m) => match m.modes().as_slice() {
            [one] if *one != Mode::EkfBlr => *one,
            [_] => anyhow::bail!(
                "--mode ekf-blr takes scalar models; a vector model filters with ekf or ukf"
            ),
            _ => anyhow::bail!("--mode all takes scalar models here; choose ekf or ukf"),
        },
    };
    let signals = hbn_pipeline::model_signals(&model, &args.input, &args.output)?;
    let opts = vector_log_options(&model, &args.read);
    let mut render = Renderer::default();
    let pass = if args.smooth {
        hbn_pipeline::smooth_vector_log
    } else {
        hbn_pipeline::estimate_vector_log
    };
    let result = pass(&model, &args.log, &signals, mode, opts, &mut |e| {
        render.event(ui, e)
    });
    render.finish();
    let run = result
        .map_err(|e| report::error(e, opts.time_source))
        .with_context(|| format!("estimation on `{}` failed", args.log.display()))?;
    // Both outputs are rendered before either is written.
    let csv_text = args
        .csv
        .as_ref()
        .map(|_| hbn_pipeline::vector_csv(&run, args.covariance));
    if let Some(mcap) = &args.out {
        run.write_mcap(mcap, model.signal_names())
            .map_err(|e| report::error(e, opts.time_source))?;
    }
    if let (Some(csv), Some(text)) = (&args.csv, csv_text) {
        hbn_fs::write_atomic(csv, text.as_bytes())
            .with_context(|| format!("cannot write `{}`", csv.display()))?;
    }
    let e = &run.estimate;
    let d = e.dims;
    let wrote: String = [&args.csv, &args.out]
        .iter()
        .filter_map(|f| f.as_ref())
        .map(|f| format!("; wrote `{}`", f.display()))
        .collect();
    let smoothed = if args.smooth { " (smoothed)" } else { "" };
    let mut text = format!(
        "estimated {} state components over {} samples of `{}` with {}{smoothed}{wrote}\n",
        d.states,
        e.len(),
        args.log.display(),
        mode,
    );
    for (i, f) in e.unobservable.iter().enumerate() {
        if *f > 0.05 {
            text.push_str(&format!(
                "  warning: state component {i} is unobservable in {:.0}% of the windows\n",
                100.0 * f
            ));
        }
    }
    if args.json {
        let v = vector_summary_json(args, &model, &run);
        ui.line(serde_json::to_string_pretty(&v).context("cannot format JSON")?)?;
    } else {
        ui.print(text)?;
    }
    Ok(())
}

/// The summary of a vector model's run as JSON (`--json`): the log, the sizes, the mode, the
/// mean NIS, how often each guard flag was raised, each component's unobservable share of
/// windows and the files written.
fn vector_summary_json(
    args: &EstimateArgs,
    model: &VectorModel,
    run: &hbn_pipeline::VectorLogEstimate,
) -> Value {
    let e = &run.estimate;
    let flags: serde_json::Map<String, Value> = e
        .flag_counts()
        .into_iter()
        .map(|(n, c)| (n.to_owned(), json!(c)))
        .collect();
    let finite: Vec<f64> = e.nis.iter().copied().filter(|v| v.is_finite()).collect();
    let mean_nis = (!finite.is_empty()).then(|| finite.iter().sum::<f64>() / finite.len() as f64);
    json!({
        "log": args.log,
        "model": args.model,
        "samples": run.log.len(),
        "rate_hz": model.rate_hz(),
        "duration_s": run.log.duration_s(),
        "signals": run.log.paths.iter().map(|p| p.to_string()).collect::<Vec<_>>(),
        "inputs": e.dims.inputs,
        "states": e.dims.states,
        "sensors": e.dims.sensors,
        "estimates": [{
            "mode": e.mode.name(),
            "default_mode": e.mode == model.default_mode(),
            "smoothed": args.smooth,
            "mean_nis": mean_nis,
            "flags": flags,
            "unobservable": e.unobservable,
            "csv": args.csv,
            "mcap": args.out,
        }],
    })
}

/// Writes each run to `outputs` (one run) or to its mode's files ([`Outputs::for_mode`]),
/// removing the files already written if one fails.
fn write_runs(
    runs: &[LogEstimate],
    outputs: &Outputs,
    time_source: hbn_io::TimeSource,
) -> anyhow::Result<()> {
    let mut written: Vec<std::path::PathBuf> = Vec::new();
    for r in runs {
        let files = if runs.len() == 1 {
            outputs.clone()
        } else {
            outputs.for_mode(r.mode)
        };
        if let Err(err) = r.write(&files) {
            for f in &written {
                let _ = std::fs::remove_file(f);
            }
            return Err(report::error(err, time_source));
        }
        written.extend(files.files().map(Path::to_path_buf));
    }
    Ok(())
}

/// Loads a model, naming the file in errors.
pub fn load_model(file: &Path) -> anyhow::Result<HysteresisModel> {
    if is_vector_model(file) {
        anyhow::bail!(
            "`{}` is a vector model (several inputs, states or sensors); this command takes \
             scalar models. A vector model runs with `hbn estimate`, `hbn eval` and `hbn inspect`",
            file.display()
        );
    }
    HysteresisModel::load(file)
        .with_context(|| format!("cannot load the model `{}`", file.display()))
}

/// Mean normalised innovation squared over the samples that have one.
pub fn mean_nis(est: &Estimate) -> f64 {
    let finite: Vec<f64> = est.nis.iter().copied().filter(|v| v.is_finite()).collect();
    if finite.is_empty() {
        f64::NAN
    } else {
        finite.iter().sum::<f64>() / finite.len() as f64
    }
}

/// The filter diagnostics of one run (`--verbose`): mean NIS, guard flags, observability.
pub fn diagnostics(est: &Estimate, mode: Mode) -> String {
    let mut s = format!(
        "  {mode} diagnostics: mean NIS {:.3} (about 1 when the filter's noise fits the log)",
        mean_nis(est)
    );
    if let Some(o) = est.observability() {
        s.push_str(&format!(
            ", near-unobservable on {:.1}% of samples",
            100.0 * o.near_unobservable
        ));
    }
    let counts = est.flag_counts();
    if counts.is_empty() {
        s.push_str("; no guard flags\n");
    } else {
        let c: Vec<String> = counts.iter().map(|(n, c)| format!("{n} x{c}")).collect();
        s.push_str(&format!("; guard flags (samples): {}\n", c.join(", ")));
    }
    s
}

fn outputs_of(args: &EstimateArgs, modes: usize, mode: Mode) -> Outputs {
    let o = Outputs {
        csv: args.csv.clone(),
        mcap: args.out.clone(),
    };
    if modes > 1 { o.for_mode(mode) } else { o }
}

/// The summary as JSON (`--json`).
pub fn summary_json(args: &EstimateArgs, model: &HysteresisModel, runs: &[LogEstimate]) -> Value {
    let log = runs.first().map(|r| &r.log);
    let estimates: Vec<Value> = runs
        .iter()
        .map(|r| {
            let files = outputs_of(args, runs.len(), r.mode);
            let flags: serde_json::Map<String, Value> = r
                .estimate
                .flag_counts()
                .into_iter()
                .map(|(n, c)| (n.to_owned(), json!(c)))
                .collect();
            let mut v = json!({
                "mode": r.mode.name(),
                "default_mode": r.mode == model.default_mode(),
                "mean_nis": mean_nis(&r.estimate),
                "flags": flags,
                "near_unobservable": r.estimate.observability().map(|o| o.near_unobservable),
                "csv": files.csv,
                "mcap": files.mcap,
                "warnings": r.warnings().iter().map(ToString::to_string).collect::<Vec<_>>(),
            });
            if args.smooth {
                v["smoothed"] = json!(true);
            }
            v
        })
        .collect();
    json!({
        "log": args.log,
        "model": args.model,
        "samples": log.map(|l| l.len()),
        "rate_hz": model.rate_hz(),
        "duration_s": log.map(|l| l.duration_s()),
        "signals": log.map(|l| l.paths.iter().map(|p| p.to_string()).collect::<Vec<_>>()),
        "estimates": estimates,
    })
}

/// Runs `hbn estimate`; returns one estimate per mode run.
pub fn run(ui: &mut Ui<'_>, args: &EstimateArgs) -> anyhow::Result<Vec<LogEstimate>> {
    for (f, what) in [(&args.out, "MCAP output"), (&args.csv, "CSV output")] {
        if let Some(f) = f {
            crate::check_output(f, what)?;
        }
    }
    if is_vector_model(&args.model) {
        run_vector(ui, args)?;
        return Ok(Vec::new());
    }
    let model = load_model(&args.model)?;
    let one = |v: &[hbn_io::SignalPath], flag: &str| one_path(v, flag, &args.model);
    let signals = SignalChoice {
        input: one(&args.input, "--input")?,
        state: None,
        output: one(&args.output, "--output")?,
    };
    let outputs = Outputs {
        csv: args.csv.clone(),
        mcap: args.out.clone(),
    };
    let modes = args
        .mode
        .map_or_else(|| vec![model.default_mode()], |m| m.modes());
    let opts = args.read.options(&model);
    let mut render = Renderer::default();
    // Smoothing writes the files itself, after replacing the filter's estimates.
    let filter_outputs = if args.smooth {
        Outputs::default()
    } else {
        outputs.clone()
    };
    let result = estimate_log_modes(
        &model,
        &args.log,
        &signals,
        &modes,
        opts,
        &filter_outputs,
        &mut |e| render.event(ui, e),
    );
    render.finish();
    let mut runs = result
        .map_err(|e| report::error(e, opts.time_source))
        .with_context(|| format!("estimation on `{}` failed", args.log.display()))?;
    if args.smooth {
        let which = [LogOption::Input, LogOption::Output];
        let pieces = hbn_pipeline::read_pieces_at_model_rate(
            &model,
            &args.log,
            &signals,
            &which,
            opts,
            &mut |_| {},
        )
        .map_err(|e| report::error(e, opts.time_source))?;
        for r in &mut runs {
            r.estimate = hbn_pipeline::smooth_pieces(&model, &pieces.pieces, 0, 1, r.mode)
                .with_context(|| {
                    format!("smoothing `{}` with {} failed", args.log.display(), r.mode)
                })?;
        }
        write_runs(&runs, &outputs, opts.time_source)?;
    }
    if args.json {
        let v = summary_json(args, &model, &runs);
        ui.line(serde_json::to_string_pretty(&v).context("cannot format JSON")?)?;
    } else {
        ui.print(summary_text(ui.verbose, args, &model, &runs))?;
    }
    for r in &runs {
        for w in r.warnings() {
            if runs.len() > 1 {
                ui.warn(format_args!("{}: {w}", r.mode));
            } else {
                ui.warn(w);
            }
        }
    }
    Ok(runs)
}

/// The text summary: what was estimated and where it was written; with `verbose`, the filter
/// diagnostics of each mode.
pub fn summary_text(
    verbose: bool,
    args: &EstimateArgs,
    model: &HysteresisModel,
    runs: &[LogEstimate],
) -> String {
    let Some(first) = runs.first() else {
        return String::new();
    };
    let mut text = format!(
        "estimated {} in `{}` with `{}`: {}\n",
        model.signals().state.name,
        args.log.display(),
        args.model.display(),
        report::grid_text(&first.log)
    );
    for r in runs {
        let default = if r.mode == model.default_mode() {
            " (the model's default mode)"
        } else {
            ""
        };
        let files = outputs_of(args, runs.len(), r.mode);
        let mut wrote: Vec<String> = Vec::new();
        if let Some(f) = &files.csv {
            wrote.push(format!("CSV `{}`", f.display()));
        }
        if let Some(f) = &files.mcap {
            wrote.push(format!(
                "MCAP `{}` (topic {})",
                f.display(),
                hbn_pipeline::ESTIMATE_TOPIC
            ));
        }
        let wrote = if wrote.is_empty() {
            "nothing written (give --csv or --out)".to_owned()
        } else {
            format!("wrote {}", wrote.join(" and "))
        };
        let smoothed = if args.smooth { " smoothed" } else { "" };
        text.push_str(&format!("  {}{smoothed}{default}: {wrote}\n", r.mode));
        if verbose {
            text.push_str(&diagnostics(&r.estimate, r.mode));
        }
    }
    if verbose {
        text.push_str(&format!(
            "  {}\n",
            glossary::links(&[Term::Nis, Term::GuardFlags, Term::Observability])
        ));
    } else {
        text.push_str("  (filter diagnostics: --verbose)\n");
    }
    text
}
