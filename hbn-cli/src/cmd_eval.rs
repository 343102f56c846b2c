//! `hbn eval`: score the model's estimates against the logged state
//! ([`hbn_pipeline::evaluate_log`]) of one log or several (then also pooled,
//! [`hbn_pipeline::pool_evaluations`]), as a table, JSON or a plot.

use std::path::Path;

use anyhow::Context;
use hbn_model::{HysteresisModel, VectorModel};
use hbn_pipeline::{
    Compared, Evaluation, LogOption, Method, Score, SignalChoice, evaluate_log, pool_evaluations,
    scores_json,
};

use crate::Ui;
use crate::cli::EvalArgs;
use crate::cmd_estimate::load_model;
use crate::glossary::{self, Term};
use crate::plot::{self, EvalPlot, ModeSeries};
use crate::report::{self, Renderer};

/// An aligned text table of the scores, one row per method, the model's default mode marked
/// `*`; each mode's smoothed score (`smoothed`, from `--smooth`) in a row `<mode> smoothed`
/// after the mode's. Always RMSE, nRMSE and the share of samples within 2 standard deviations
/// (about 95% when the uncertainty is honest); with `verbose` also within 1 (about 68%), the
/// mean NEES (about 1) and the NLPD.
pub fn table(
    scores: &[Score],
    smoothed: &[Score],
    default_mode: hbn_core::Mode,
    verbose: bool,
) -> String {
    let mut rows: Vec<(String, &Score)> = Vec::new();
    for sc in scores {
        let star = if sc.method == Method::Filter(default_mode) {
            "*"
        } else {
            ""
        };
        rows.push((format!("{}{star}", sc.method.name()), sc));
        for sm in smoothed.iter().filter(|sm| sm.method == sc.method) {
            rows.push((format!("{} smoothed{star}", sm.method.name()), sm));
        }
    }
    let width = rows.iter().map(|(l, _)| l.len()).max().unwrap_or(0).max(11);
    let mut s = format!(
        "{:<width$} {:>10} {:>8} {:>8}",
        "method", "RMSE", "nRMSE", "in 2 sd"
    );
    if verbose {
        s.push_str(&format!(
            " {:>8} {:>10} {:>8}",
            "in 1 sd", "mean NEES", "NLPD"
        ));
    }
    s.push('\n');
    for (label, sc) in rows {
        s.push_str(&format!(
            "{label:<width$} {:>10.6} {:>8.4}",
            sc.rmse, sc.nrmse
        ));
        match &sc.calibration {
            Some(c) => {
                s.push_str(&format!(" {:>7.1}%", 100.0 * c.coverage_2sigma));
                if verbose {
                    s.push_str(&format!(
                        " {:>7.1}% {:>10.2} {:>8.3}",
                        100.0 * c.coverage_1sigma,
                        c.mean_nees,
                        c.nlpd
                    ));
                }
            }
            None => {
                s.push_str(&format!(" {:>8}", "-"));
                if verbose {
                    s.push_str(&format!(" {:>8} {:>10} {:>8}", "-", "-", "-"));
                }
            }
        }
        s.push('\n');
    }
    if scores
        .iter()
        .any(|sc| sc.method == Method::Filter(default_mode))
    {
        s.push_str("* the model's default mode\n");
    }
    if !smoothed.is_empty() {
        s.push_str("smoothed: each sample estimated from the whole log (docs/smoothing.md)\n");
    }
    s
}

/// The line saying that the state of `log` is scored at its frames only (it is measured
/// sparsely), or `None` when it is measured at about every sample.
fn frames_note(log: &hbn_pipeline::LogData, frames: Option<usize>) -> Option<String> {
    frames.map(|frames| {
        format!(
            "scored at the state's {frames} frames (it is measured at {:.0}% of the {} samples; \
             between frames the log holds no state to compare with)\n",
            100.0 * frames as f64 / log.len().max(1) as f64,
            log.len()
        )
    })
}

/// The smoothed estimate of each mode of `ev` ([`HysteresisModel::smooth`] over the pieces of
/// `log`, the log the evaluation read) against the logged state.
fn smoothed_compared(
    model: &HysteresisModel,
    log: &Path,
    signals: &SignalChoice,
    opts: hbn_pipeline::LogOptions,
    ev: &Evaluation,
) -> anyhow::Result<Vec<(hbn_core::Mode, Compared)>> {
    let which = [LogOption::Input, LogOption::State, LogOption::Output];
    let split =
        hbn_pipeline::read_pieces_at_model_rate(model, log, signals, &which, opts, &mut |_| {})
            .map_err(|e| report::error(e, opts.time_source))?;
    ev.estimates
        .iter()
        .map(|(mode, _)| {
            let est = hbn_pipeline::smooth_pieces(model, &split.pieces, 0, 2, *mode)
                .with_context(|| format!("smoothing `{}` with {mode} failed", log.display()))?;
            Ok((
                *mode,
                Compared::against(&est.x, Some(&est.x_std), &ev.log, 1),
            ))
        })
        .collect()
}

/// The scores of smoothed estimates, one per mode.
fn smoothed_scores(smoothed: &[(hbn_core::Mode, Compared)]) -> Vec<Score> {
    smoothed
        .iter()
        .map(|(mode, c)| c.score(Method::Filter(*mode)))
        .collect()
}

/// The lines after the table: what the columns mean, with glossary links.
fn legend(verbose: bool) -> String {
    let mut s = String::from(
        "nRMSE = RMSE / range of the logged state; in 2 sd = share of samples where the logged \
         state lies within 2 standard deviations of the estimate (about 95% when the \
         uncertainty is honest)",
    );
    let mut terms = vec![Term::Nrmse, Term::Coverage, Term::OpenLoop];
    if verbose {
        s.push_str(
            "; in 1 sd: about 68%; mean NEES = mean ((x - x_hat) / x_std)^2, about 1; NLPD = \
             negative log predictive density, lower is better",
        );
        terms.extend([Term::Nees, Term::Nlpd]);
    } else {
        s.push_str("; more columns with --verbose");
    }
    s.push('\n');
    s.push_str(&glossary::links(&terms));
    s.push('\n');
    s
}

/// Axis label of a signal: `state x = /state.data [deg]` (path and unit when the model has
/// them).
pub fn axis_label(role: &str, info: &hbn_model::SignalInfo) -> String {
    let mut s = format!("{role} {}", info.name);
    if let Some(p) = &info.path {
        s.push_str(&format!(" = {p}"));
    }
    if let Some(u) = &info.unit {
        s.push_str(&format!(" [{u}]"));
    }
    s
}

/// The plot of an evaluation: per mode its estimate, 2-sigma band, nRMSE and coverage.
pub fn plot_data<'a>(
    ev: &'a Evaluation,
    model: &HysteresisModel,
    model_file: &Path,
    log_file: &Path,
) -> EvalPlot<'a> {
    let sig = model.signals();
    let score = |m: Method| ev.scores.iter().find(|s| s.method == m);
    let modes = ev
        .estimates
        .iter()
        .map(|(m, e)| {
            let sc = score(Method::Filter(*m));
            ModeSeries {
                label: if *m == model.default_mode() {
                    format!("{m} (default mode)")
                } else {
                    m.name().to_owned()
                },
                x: &e.x,
                x_std: &e.x_std,
                nrmse: sc.map_or(f64::NAN, |s| s.nrmse),
                coverage_2sigma: sc
                    .and_then(|s| s.calibration)
                    .map_or(f64::NAN, |c| c.coverage_2sigma),
            }
        })
        .collect();
    EvalPlot {
        title: format!(
            "Estimated {x} vs the logged {x}: model {} on {} ({} samples)",
            model_file.display(),
            log_file.display(),
            ev.log.len(),
            x = sig.state.name,
        ),
        t: &ev.log.aligned.t_s,
        u: ev.log.column(0),
        x_ref: ev.log.column(1),
        y: ev.log.column(2),
        input_label: axis_label("input", &sig.input),
        state_label: axis_label("state", &sig.state),
        output_label: axis_label("sensor", &sig.output),
        loops_mode: ev
            .estimates
            .iter()
            .position(|(m, _)| *m == model.default_mode())
            .unwrap_or(0),
        modes,
        open_loop: &ev.open_loop,
        open_loop_nrmse: score(Method::OpenLoop).map_or(f64::NAN, |s| s.nrmse),
    }
}

/// Runs `hbn eval` with a scalar or a vector model.
pub fn run(ui: &mut Ui<'_>, args: &EvalArgs) -> anyhow::Result<()> {
    if let Some(p) = &args.plot {
        if args.log.len() > 1 {
            anyhow::bail!(
                "--plot draws one log, and --log is given {} times: plot each log with its own \
                 `hbn eval --log ... --plot ...`, or drop --plot",
                args.log.len()
            );
        }
        crate::check_output(p, "plot")?;
    }
    if crate::cmd_estimate::is_vector_model(&args.model) {
        return run_vector(ui, args);
    }
    run_scalar(ui, args)
}

/// The evaluation of a scalar model on `log`, the reading's progress rendered to `ui`.
fn evaluate_scalar(
    ui: &mut Ui<'_>,
    model: &HysteresisModel,
    log: &Path,
    signals: &SignalChoice,
    modes: &[hbn_core::Mode],
    opts: hbn_pipeline::LogOptions,
) -> anyhow::Result<Evaluation> {
    let mut render = Renderer::default();
    let result = evaluate_log(model, log, signals, modes, opts, &mut |e| {
        render.event(ui, e)
    });
    render.finish();
    let state_topic = signals
        .resolve(model, hbn_pipeline::LogOption::State)
        .ok()
        .map(|p| p.topic);
    result
        .map_err(|e| {
            let no_state = matches!(
                &e,
                hbn_pipeline::PipelineError::Read {
                    source: hbn_io::IoError::MissingTopic { topic, .. },
                    ..
                } if Some(topic) == state_topic.as_ref()
            );
            let e = report::error(e, opts.time_source);
            if no_state {
                e.context(format!(
                    "`{}` does not record the state, so there is nothing to score against; \
                     to estimate the state of this log use `hbn estimate`",
                    log.display()
                ))
            } else {
                e
            }
        })
        .with_context(|| format!("evaluation on `{}` failed", log.display()))
}

/// `hbn eval` with a scalar model.
fn run_scalar(ui: &mut Ui<'_>, args: &EvalArgs) -> anyhow::Result<()> {
    let model = load_model(&args.model)?;
    let one =
        |v: &[hbn_io::SignalPath], flag: &str| crate::cmd_estimate::one_path(v, flag, &args.model);
    let signals = SignalChoice {
        input: one(&args.input, "--input")?,
        state: one(&args.state, "--state")?,
        output: one(&args.output, "--output")?,
    };
    let modes = args.mode.modes();
    let opts = args.read.options(&model);
    let mut evaluations = Vec::with_capacity(args.log.len());
    let mut smoothed = Vec::with_capacity(args.log.len());
    for log in &args.log {
        let ev = evaluate_scalar(ui, &model, log, &signals, &modes, opts)?;
        smoothed.push(if args.smooth {
            smoothed_compared(&model, log, &signals, opts, &ev)?
        } else {
            Vec::new()
        });
        evaluations.push(ev);
    }
    if let (Some(p), [ev], [log]) = (&args.plot, evaluations.as_slice(), args.log.as_slice()) {
        plot::eval_plot(p, &plot_data(ev, &model, &args.model, log))?;
    }
    // Pooled over every log, when there are several.
    let pooled = (evaluations.len() > 1).then(|| {
        let by_mode = |i: usize| {
            Compared::join(
                smoothed
                    .iter()
                    .filter_map(|s| s.get(i))
                    .map(|(_, c)| c.clone()),
            )
        };
        let smoothed_pooled: Vec<Score> = smoothed
            .first()
            .into_iter()
            .flatten()
            .enumerate()
            .map(|(i, (mode, _))| by_mode(i).score(Method::Filter(*mode)))
            .collect();
        (pool_evaluations(&evaluations), smoothed_pooled)
    });
    if args.json {
        let each: Vec<serde_json::Value> = evaluations
            .iter()
            .zip(&smoothed)
            .zip(&args.log)
            .map(|((ev, sm), log)| {
                let mut v = ev.to_json();
                if args.smooth {
                    v["smoothed"] = scores_json(&smoothed_scores(sm));
                }
                v["log"] = serde_json::json!(log);
                v
            })
            .collect();
        let v = match (each.as_slice(), &pooled) {
            ([one], _) => one.clone(),
            (_, Some((scores, sm))) => {
                let mut p = scores_json(scores);
                p["samples"] =
                    serde_json::json!(evaluations.iter().map(|e| e.log.len()).sum::<usize>());
                if args.smooth {
                    p["smoothed"] = scores_json(sm);
                }
                serde_json::json!({"logs": each, "pooled": p})
            }
            _ => serde_json::json!({"logs": each}),
        };
        ui.line(serde_json::to_string_pretty(&v).context("cannot format JSON")?)?;
        return Ok(());
    }
    for (i, ((ev, sm), log)) in evaluations.iter().zip(&smoothed).zip(&args.log).enumerate() {
        ui.print(format!(
            "{}scored `{}` on `{}`: {}\n",
            if i > 0 { "\n" } else { "" },
            args.model.display(),
            log.display(),
            report::grid_text(&ev.log)
        ))?;
        let sm = smoothed_scores(sm);
        ui.print(table(&ev.scores, &sm, model.default_mode(), ui.verbose))?;
        let frames = ev.log.state_frames().map(<[_]>::len);
        if let Some(note) = frames_note(&ev.log, frames) {
            ui.print(note)?;
        }
    }
    if let Some((scores, sm)) = &pooled {
        ui.print(format!(
            "\npooled over the {} logs ({} samples; every sample of every log counts once, the \
             nRMSE is over the range of the state in all of them):\n",
            evaluations.len(),
            evaluations.iter().map(|e| e.log.len()).sum::<usize>()
        ))?;
        ui.print(table(scores, sm, model.default_mode(), ui.verbose))?;
    }
    ui.print(legend(ui.verbose))?;
    if let Some(p) = &args.plot {
        ui.line(format!("wrote plot `{}`", p.display()))?;
    }
    Ok(())
}

/// One row of a vector model's tables: the run's label (`ekf`, `ukf smoothed`), its mode and
/// one score per state component.
type VectorRow<'a> = (String, hbn_core::Mode, &'a [hbn_pipeline::ComponentScore]);

/// The scores of a vector model, one table per state component: a row per run with RMSE,
/// nRMSE and the share within 2 standard deviations (with `verbose` also within 1, the mean
/// NEES and the NLPD); the model's default mode marked `*`.
pub fn vector_tables(rows: &[VectorRow<'_>], model: &VectorModel, verbose: bool) -> String {
    let labels: Vec<String> = rows
        .iter()
        .map(|(label, mode, _)| {
            let star = if *mode == model.default_mode() {
                "*"
            } else {
                ""
            };
            format!("{label}{star}")
        })
        .collect();
    let names = model.signal_names();
    let width = labels.iter().map(String::len).max().unwrap_or(0).max(11);
    let mut s = String::new();
    for i in 0..model.dims().states {
        let name = names.states.get(i).map_or("", String::as_str);
        s.push_str(&format!("state component {i} ({name}):\n"));
        s.push_str(&format!(
            "  {:<width$} {:>10} {:>8} {:>8}",
            "method", "RMSE", "nRMSE", "in 2 sd"
        ));
        if verbose {
            s.push_str(&format!(
                " {:>8} {:>10} {:>8}",
                "in 1 sd", "mean NEES", "NLPD"
            ));
        }
        s.push('\n');
        for ((_, _, scores), label) in rows.iter().zip(&labels) {
            let Some(sc) = scores.get(i) else {
                continue;
            };
            let c = &sc.calibration;
            s.push_str(&format!(
                "  {label:<width$} {:>10.6} {:>8.4} {:>7.1}%",
                sc.rmse,
                sc.nrmse,
                100.0 * c.coverage_2sigma
            ));
            if verbose {
                s.push_str(&format!(
                    " {:>7.1}% {:>10.2} {:>8.3}",
                    100.0 * c.coverage_1sigma,
                    c.mean_nees,
                    c.nlpd
                ));
            }
            s.push('\n');
        }
    }
    if rows.iter().any(|(_, m, _)| *m == model.default_mode()) {
        s.push_str("* the model's default mode\n");
    }
    if rows
        .iter()
        .any(|(label, _, _)| label.ends_with(" smoothed"))
    {
        s.push_str("smoothed: each sample estimated from the whole log (docs/smoothing.md)\n");
    }
    s
}

/// The frames of a vector state measured sparsely (a camera; its first component's count), or
/// `None` when it is measured at about every sample.
fn vector_state_frames(ev: &hbn_pipeline::VectorEvaluation, model: &VectorModel) -> Option<usize> {
    ev.log.frames_of(model.dims().inputs).map(<[_]>::len)
}

/// The JSON of a vector model's scores: per run its mode, whether smoothed, and per state
/// component the RMSE, nRMSE and calibration.
fn vector_runs_json(
    rows: &[(hbn_core::Mode, bool, &[hbn_pipeline::ComponentScore])],
) -> Vec<serde_json::Value> {
    rows.iter()
        .map(|(mode, smoothed, scores)| {
            let comps: Vec<serde_json::Value> = scores
                .iter()
                .map(|sc| {
                    serde_json::json!({
                        "rmse": sc.rmse,
                        "nrmse": sc.nrmse,
                        "coverage_1sigma": sc.calibration.coverage_1sigma,
                        "coverage_2sigma": sc.calibration.coverage_2sigma,
                        "mean_nees": sc.calibration.mean_nees,
                        "nlpd": sc.calibration.nlpd,
                    })
                })
                .collect();
            serde_json::json!({"mode": mode.name(), "smoothed": smoothed, "components": comps})
        })
        .collect()
}

/// `hbn eval` with a vector model.
fn run_vector(ui: &mut Ui<'_>, args: &EvalArgs) -> anyhow::Result<()> {
    let model = VectorModel::load(&args.model)
        .with_context(|| format!("cannot load the model `{}`", args.model.display()))?;
    let mut signals = hbn_pipeline::model_signals(&model, &args.input, &args.output)?;
    if !args.state.is_empty() {
        if args.state.len() != signals.states.len() {
            anyhow::bail!(
                "--state is given {} times; the model has {} state components: give one path \
                 per component, in the model's order, or none",
                args.state.len(),
                signals.states.len()
            );
        }
        signals.states = args.state.clone();
    }
    let modes: Vec<hbn_core::Mode> = args
        .mode
        .modes()
        .into_iter()
        .filter(|m| *m != hbn_core::Mode::EkfBlr)
        .collect();
    let opts = crate::cmd_estimate::vector_log_options(&model, &args.read);
    let mut evaluations = Vec::with_capacity(args.log.len());
    for log in &args.log {
        let mut render = Renderer::default();
        let result = hbn_pipeline::evaluate_vector_log(
            &model,
            log,
            &signals,
            &modes,
            args.smooth,
            opts,
            &mut |e| render.event(ui, e),
        );
        render.finish();
        evaluations.push(
            result
                .map_err(|e| report::error(e, opts.time_source))
                .with_context(|| format!("evaluation on `{}` failed", log.display()))?,
        );
    }
    if let (Some(p), [ev], [log]) = (&args.plot, evaluations.as_slice(), args.log.as_slice()) {
        vector_plot(p, ev, &model, log)?;
    }
    let pooled = (evaluations.len() > 1)
        .then(|| hbn_pipeline::pool_vector_evaluations(&evaluations, model.dims()));
    let samples: usize = evaluations.iter().map(|e| e.log.len()).sum();
    if args.json {
        let each: Vec<serde_json::Value> = evaluations
            .iter()
            .zip(&args.log)
            .map(|(ev, log)| {
                let rows: Vec<_> = ev
                    .runs
                    .iter()
                    .map(|r| (r.mode, r.smoothed, r.scores.as_slice()))
                    .collect();
                serde_json::json!({
                    "model": args.model,
                    "log": log,
                    "states": model.signal_names().states,
                    "default_mode": model.default_mode().name(),
                    "runs": vector_runs_json(&rows),
                    "state_frames": vector_state_frames(ev, &model),
                })
            })
            .collect();
        let v = match (each.as_slice(), &pooled) {
            ([one], _) => one.clone(),
            (_, Some(pooled)) => {
                let rows: Vec<_> = pooled
                    .iter()
                    .map(|r| (r.mode, r.smoothed, r.scores.as_slice()))
                    .collect();
                serde_json::json!({
                    "logs": each,
                    "pooled": {"samples": samples, "runs": vector_runs_json(&rows)},
                })
            }
            _ => serde_json::json!({"logs": each}),
        };
        ui.line(serde_json::to_string_pretty(&v).context("cannot format JSON")?)?;
        return Ok(());
    }
    for (i, (ev, log)) in evaluations.iter().zip(&args.log).enumerate() {
        ui.print(format!(
            "{}scored `{}` on `{}`: {}\n",
            if i > 0 { "\n" } else { "" },
            args.model.display(),
            log.display(),
            report::grid_text(&ev.log)
        ))?;
        let rows: Vec<VectorRow<'_>> = ev
            .runs
            .iter()
            .map(|r| (r.label(), r.mode, r.scores.as_slice()))
            .collect();
        ui.print(vector_tables(&rows, &model, ui.verbose))?;
        if let Some(note) = frames_note(&ev.log, vector_state_frames(ev, &model)) {
            ui.print(note)?;
        }
    }
    if let Some(pooled) = &pooled {
        ui.print(format!(
            "\npooled over the {} logs ({samples} samples; every sample of every log counts \
             once, the nRMSE is over the range of each component in all of them):\n",
            evaluations.len(),
        ))?;
        let rows: Vec<VectorRow<'_>> = pooled
            .iter()
            .map(|r| (r.label(), r.mode, r.scores.as_slice()))
            .collect();
        ui.print(vector_tables(&rows, &model, ui.verbose))?;
    }
    ui.print(legend(ui.verbose))?;
    if let Some(p) = &args.plot {
        ui.line(format!("wrote plot `{}`", p.display()))?;
    }
    Ok(())
}

/// One panel per state component and mode: the logged component, the estimate and its
/// 2-sigma band against time.
fn vector_plot(
    file: &Path,
    ev: &hbn_pipeline::VectorEvaluation,
    model: &VectorModel,
    log: &Path,
) -> anyhow::Result<()> {
    let d = model.dims();
    let names = model.signal_names();
    let t = &ev.log.aligned.t_s;
    // Per component: each mode's estimate and standard deviation.
    type Series = Vec<Vec<f64>>;
    let comps: Vec<(Series, Series)> = (0..d.states)
        .map(|i| {
            (
                ev.runs.iter().map(|r| r.estimate.component(i)).collect(),
                ev.runs
                    .iter()
                    .map(|r| r.estimate.component_std(i))
                    .collect(),
            )
        })
        .collect();
    let panels: Vec<EvalPlot<'_>> = (0..d.states)
        .map(|i| {
            let (xs, ss) = &comps[i];
            EvalPlot {
                title: format!(
                    "{} on {}: state component {i} ({})",
                    "vector model",
                    log.display(),
                    names.states.get(i).map_or("", String::as_str)
                ),
                t,
                u: ev.log.column(0),
                x_ref: ev.state(d, i),
                y: ev.log.column(d.inputs + d.states),
                input_label: names.inputs.first().cloned().unwrap_or_default(),
                state_label: names.states.get(i).cloned().unwrap_or_default(),
                output_label: names.outputs.first().cloned().unwrap_or_default(),
                modes: ev
                    .runs
                    .iter()
                    .enumerate()
                    .map(|(m, r)| ModeSeries {
                        label: r.label(),
                        x: &xs[m],
                        x_std: &ss[m],
                        nrmse: r.scores[i].nrmse,
                        coverage_2sigma: r.scores[i].calibration.coverage_2sigma,
                    })
                    .collect(),
                loops_mode: 0,
                open_loop: &[],
                open_loop_nrmse: f64::NAN,
            }
        })
        .collect();
    plot::components_plot(file, &panels)
}

#[cfg(test)]
mod tests {
    /// Runs `hbn args...` in-process; returns the result and what it printed to stdout.
    fn hbn(args: &[&str]) -> (anyhow::Result<()>, String) {
        let (mut out, mut err) = (Vec::new(), Vec::new());
        let all = std::iter::once("hbn").chain(args.iter().copied());
        let r = crate::run_with(all, &mut out, &mut err);
        (r, String::from_utf8_lossy(&out).into_owned())
    }

    /// The `x` column of an estimate CSV.
    fn xs(csv: &std::path::Path) -> Vec<f64> {
        let text = std::fs::read_to_string(csv).unwrap();
        text.lines()
            .skip(1)
            .map(|l| l.split(',').nth(3).unwrap().parse().unwrap())
            .collect()
    }

    /// Simulated Duhem logs (`(input and noise seed, steps, file name)`, noise gain 1) in `dir`,
    /// and a small exact model trained on the first, `model.hbn`; returns the model's path.
    fn duhem_model(dir: &std::path::Path, logs: &[(&str, &str, &str)]) -> String {
        let p = |n: &str| dir.join(n).to_str().unwrap().to_owned();
        for (seed, steps, name) in logs {
            let (r, _) = hbn(&[
                "-q",
                "simulate",
                "--system",
                "duhem",
                "--steps",
                steps,
                "--input-seed",
                seed,
                "--seed",
                seed,
                "--noise-gain",
                "1",
                "--out",
                &p(name),
            ]);
            r.unwrap();
        }
        let (r, _) = hbn(&[
            "-q",
            "train",
            "--log",
            &p(logs[0].2),
            "--inducing",
            "exact",
            "--max-points",
            "120",
            "--starts",
            "1",
            "--validation",
            "0",
            "--out",
            &p("model.hbn"),
        ]);
        r.unwrap();
        p("model.hbn")
    }

    #[test]
    fn several_logs_are_scored_each_and_pooled_sample_by_sample() {
        let dir = tempfile::tempdir().unwrap();
        let p = |n: &str| dir.path().join(n).to_str().unwrap().to_owned();
        let logs = [
            ("1", "500", "train.mcap"),
            ("2", "300", "a.mcap"),
            ("3", "500", "b.mcap"),
        ];
        let (model, a, b) = (duhem_model(dir.path(), &logs), p("a.mcap"), p("b.mcap"));
        let json = |logs: &[&str]| -> serde_json::Value {
            let mut args = vec!["-q", "eval", "--model", &model, "--smooth", "--json"];
            for l in logs {
                args.extend(["--log", l]);
            }
            let (r, out) = hbn(&args);
            r.unwrap();
            serde_json::from_str(&out).unwrap()
        };
        let (one_a, one_b, both) = (json(&[&a]), json(&[&b]), json(&[&a, &b]));
        // Each log's scores are those it gets alone.
        assert_eq!(both["logs"][0]["nrmse"], one_a["nrmse"]);
        assert_eq!(both["logs"][1]["calibration"], one_b["calibration"]);
        assert_eq!(both["logs"][1]["log"], serde_json::json!(b));
        let pooled = &both["pooled"];
        let (na, nb) = (
            one_a["samples"].as_f64().unwrap(),
            one_b["samples"].as_f64().unwrap(),
        );
        assert_eq!(na, 300.0);
        assert_eq!(pooled["samples"].as_f64().unwrap(), na + nb);
        // The pooled RMSE is the root of the sample-weighted mean square error; coverage and
        // NEES are sample-weighted means.
        let f = |v: &serde_json::Value| v.as_f64().unwrap();
        let weighted = |x: f64, y: f64| (na * x + nb * y) / (na + nb);
        for scores in [pooled, &pooled["smoothed"]] {
            let (ea, eb) = match scores == pooled {
                true => (&one_a, &one_b),
                false => (&one_a["smoothed"], &one_b["smoothed"]),
            };
            let methods = scores["rmse"].as_object().unwrap();
            assert!(methods.len() >= 3, "{scores}");
            for m in methods.keys() {
                let want = weighted(f(&ea["rmse"][m]).powi(2), f(&eb["rmse"][m]).powi(2)).sqrt();
                assert!(
                    (f(&scores["rmse"][m]) - want).abs() < 1e-12 * want,
                    "{m}: {scores}"
                );
                // One range for every method: the state's over both logs.
                let range = f(&scores["rmse"][m]) / f(&scores["nrmse"][m]);
                let range_a = f(&ea["rmse"][m]) / f(&ea["nrmse"][m]);
                assert!(range >= range_a * (1.0 - 1e-12), "{m}: {range} {range_a}");
            }
            for (m, c) in scores["calibration"].as_object().unwrap() {
                let (ca, cb) = (&ea["calibration"][m], &eb["calibration"][m]);
                assert_eq!(f(&c["samples"]), f(&ca["samples"]) + f(&cb["samples"]));
                for k in ["coverage_2sigma", "mean_nees"] {
                    let want = weighted(f(&ca[k]), f(&cb[k]));
                    assert!((f(&c[k]) - want).abs() < 1e-12, "{m} {k}: {c}");
                }
            }
        }
        // The text: a table per log, then the pooled one.
        let (r, out) = hbn(&["-q", "eval", "--model", &model, "--log", &a, "--log", &b]);
        r.unwrap();
        assert_eq!(out.matches("\nmethod            RMSE").count(), 3, "{out}");
        assert!(
            out.contains("pooled over the 2 logs (800 samples;"),
            "{out}"
        );
        // A plot draws one log.
        let (r, _) = hbn(&[
            "-q",
            "eval",
            "--model",
            &model,
            "--log",
            &a,
            "--log",
            &b,
            "--plot",
            &p("e.png"),
        ]);
        let e = format!("{:#}", r.unwrap_err());
        assert!(e.contains("--plot draws one log"), "{e}");
        assert!(!dir.path().join("e.png").exists());
    }

    #[test]
    fn smooth_adds_a_row_per_mode_and_writes_the_smoothed_estimate() {
        let dir = tempfile::tempdir().unwrap();
        let p = |n: &str| dir.path().join(n).to_str().unwrap().to_owned();
        let logs = [("1", "500", "train.mcap"), ("2", "300", "test.mcap")];
        let (model, log) = (duhem_model(dir.path(), &logs), p("test.mcap"));
        let eval = |extra: &[&str]| {
            let mut args = vec!["-q", "eval", "--model", &model, "--log", &log];
            args.extend(extra);
            let (r, out) = hbn(&args);
            r.unwrap();
            out
        };
        let plain = eval(&[]);
        assert!(!plain.contains("smoothed"), "{plain}");
        assert!(plain.contains("\nmethod            RMSE"), "{plain}");
        let smoothed = eval(&["--smooth"]);
        for mode in hbn_core::Mode::ALL {
            assert!(
                smoothed.contains(&format!("\n{mode} smoothed")),
                "{smoothed}"
            );
        }
        // The filter's rows are the same with and without the flag.
        let rows = |t: &str| -> Vec<String> {
            t.lines()
                .filter(|l| l.starts_with("ekf") || l.starts_with("ukf"))
                .filter(|l| !l.contains("smoothed"))
                .map(|l| l.split_whitespace().skip(1).collect::<Vec<_>>().join(" "))
                .collect()
        };
        assert_eq!(rows(&plain), rows(&smoothed));
        let (r, _) = hbn(&[
            "-q",
            "estimate",
            "--model",
            &p("model.hbn"),
            "--log",
            &p("test.mcap"),
            "--csv",
            &p("filtered.csv"),
        ]);
        r.unwrap();
        let (r, out) = hbn(&[
            "-q",
            "estimate",
            "--model",
            &p("model.hbn"),
            "--log",
            &p("test.mcap"),
            "--smooth",
            "--csv",
            &p("smoothed.csv"),
            "--out",
            &p("smoothed.mcap"),
        ]);
        r.unwrap();
        assert!(out.contains("smoothed"), "{out}");
        assert!(std::fs::metadata(p("smoothed.mcap")).unwrap().len() > 0);
        let (f, s) = (
            xs(&dir.path().join("filtered.csv")),
            xs(&dir.path().join("smoothed.csv")),
        );
        assert_eq!(f.len(), s.len());
        assert_eq!(f.last(), s.last());
        assert!(f.iter().zip(&s).filter(|(a, b)| a != b).count() > f.len() / 2);
    }
}
