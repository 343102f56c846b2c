//! `hbn eval`: score the model's estimates against the logged state
//! ([`hbn_pipeline::evaluate_log`]), as a table, JSON or a plot.

use anyhow::Context;
use hbn_core::Mode;
use hbn_pipeline::{Evaluation, SignalChoice, evaluate_log};

use crate::Ui;
use crate::cli::{EvalArgs, EvalModeArg};
use crate::cmd_estimate::load_model;
use crate::plot::{self, EvalPlot, Series};
use crate::report::{self, Renderer};

/// An aligned text table of the scores; the calibration columns say how often the truth lies
/// within 1 and 2 standard deviations (about 68% and 95% when the uncertainty is honest) and
/// the mean squared error in standard deviations (about 1 when honest).
pub fn table(ev: &Evaluation) -> String {
    let mut s = format!(
        "{:<10} {:>12} {:>10} {:>9} {:>9} {:>10} {:>9}\n",
        "method", "RMSE", "nRMSE", "in 1 sd", "in 2 sd", "mean NEES", "NLPD"
    );
    for sc in &ev.scores {
        s.push_str(&format!(
            "{:<10} {:>12.6} {:>10.4}",
            sc.method.name(),
            sc.rmse,
            sc.nrmse
        ));
        match &sc.calibration {
            Some(c) => s.push_str(&format!(
                " {:>8.1}% {:>8.1}% {:>10.2} {:>9.3}\n",
                100.0 * c.coverage_1sigma,
                100.0 * c.coverage_2sigma,
                c.mean_nees,
                c.nlpd
            )),
            None => s.push_str(&format!(" {:>9} {:>9} {:>10} {:>9}\n", "-", "-", "-", "-")),
        }
    }
    s.push_str(&format!(
        "{} samples at {:.1} Hz; NEES = ((x - x_hat) / x_std)^2, NLPD = negative log \
         predictive density (lower is better)\n",
        ev.log.len(),
        ev.log.rate_hz()
    ));
    s
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
    let modes: &[Mode] = match args.mode {
        EvalModeArg::Ekf => &[Mode::Ekf],
        EvalModeArg::EkfBlr => &[Mode::EkfBlr],
        EvalModeArg::Ukf => &[Mode::Ukf],
        EvalModeArg::All => &Mode::ALL,
    };
    let opts = args.read.options(None);
    let mut render = Renderer::default();
    let result = evaluate_log(&model, &args.log, &signals, modes, opts, &mut |e| {
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
        let series: Vec<Series<'_>> = ev
            .estimates
            .iter()
            .map(|(m, e)| Series {
                label: m.name(),
                x: &e.x,
                x_std: Some(&e.x_std),
            })
            .chain(std::iter::once(Series {
                label: "open loop",
                x: &ev.open_loop,
                x_std: None,
            }))
            .collect();
        plot::eval_plot(
            p,
            &EvalPlot {
                title: &format!("{} on {}", args.model.display(), args.log.display()),
                t: &ev.log.aligned.t_s,
                u: ev.log.column(0),
                x_ref: ev.log.column(1),
                y: ev.log.column(2),
                estimates: &series,
            },
        )?;
    }
    if args.json {
        ui.line(serde_json::to_string_pretty(&ev.to_json()).context("cannot format JSON")?)?;
    } else {
        ui.print(table(&ev))?;
        if let Some(p) = &args.plot {
            ui.line(format!("wrote plot `{}`", p.display()))?;
        }
    }
    Ok(ev)
}
