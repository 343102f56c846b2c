//! `hbn eval`: score the model's estimates against the logged state
//! ([`hbn_pipeline::evaluate_log`]), as a table, JSON or a plot.

use std::path::Path;

use anyhow::Context;
use hbn_model::HysteresisModel;
use hbn_pipeline::{Evaluation, Method, SignalChoice, evaluate_log};

use crate::Ui;
use crate::cli::EvalArgs;
use crate::cmd_estimate::load_model;
use crate::glossary::{self, Term};
use crate::plot::{self, EvalPlot, ModeSeries};
use crate::report::{self, Renderer};

/// An aligned text table of the scores, one row per method, the model's default mode marked
/// `*`. Always RMSE, nRMSE and the share of samples within 2 standard deviations (about 95%
/// when the uncertainty is honest); with `verbose` also within 1 (about 68%), the mean NEES
/// (about 1) and the NLPD.
pub fn table(ev: &Evaluation, default_mode: hbn_core::Mode, verbose: bool) -> String {
    let mut s = format!(
        "{:<11} {:>10} {:>8} {:>8}",
        "method", "RMSE", "nRMSE", "in 2 sd"
    );
    if verbose {
        s.push_str(&format!(
            " {:>8} {:>10} {:>8}",
            "in 1 sd", "mean NEES", "NLPD"
        ));
    }
    s.push('\n');
    for sc in &ev.scores {
        let star = if sc.method == Method::Filter(default_mode) {
            "*"
        } else {
            ""
        };
        s.push_str(&format!(
            "{:<11} {:>10.6} {:>8.4}",
            format!("{}{star}", sc.method.name()),
            sc.rmse,
            sc.nrmse
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
    if ev
        .scores
        .iter()
        .any(|sc| sc.method == Method::Filter(default_mode))
    {
        s.push_str("* the model's default mode\n");
    }
    s
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

/// Runs `hbn eval`.
pub fn run(ui: &mut Ui<'_>, args: &EvalArgs) -> anyhow::Result<Evaluation> {
    if let Some(p) = &args.plot {
        crate::check_output(p, "plot")?;
    }
    let model = load_model(&args.model)?;
    let signals = SignalChoice {
        input: args.input.clone(),
        state: args.state.clone(),
        output: args.output.clone(),
    };
    let modes = args.mode.modes();
    let opts = args.read.options(&model);
    let mut render = Renderer::default();
    let result = evaluate_log(&model, &args.log, &signals, &modes, opts, &mut |e| {
        render.event(ui, e)
    });
    render.finish();
    let state_topic = signals
        .resolve(&model, hbn_pipeline::LogOption::State)
        .ok()
        .map(|p| p.topic);
    let ev = result
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
                    args.log.display()
                ))
            } else {
                e
            }
        })
        .with_context(|| format!("evaluation on `{}` failed", args.log.display()))?;
    if let Some(p) = &args.plot {
        plot::eval_plot(p, &plot_data(&ev, &model, &args.model, &args.log))?;
    }
    if args.json {
        ui.line(serde_json::to_string_pretty(&ev.to_json()).context("cannot format JSON")?)?;
    } else {
        ui.print(format!(
            "scored `{}` on `{}`: {}\n",
            args.model.display(),
            args.log.display(),
            report::grid_text(&ev.log)
        ))?;
        ui.print(table(&ev, model.default_mode(), ui.verbose))?;
        ui.print(legend(ui.verbose))?;
        if let Some(p) = &args.plot {
            ui.line(format!("wrote plot `{}`", p.display()))?;
        }
    }
    Ok(ev)
}
