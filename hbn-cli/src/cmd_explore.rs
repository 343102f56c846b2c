//! `hbn explore`: an input schedule that seeks where the model is uncertain, planned from a
//! model and its first batch of logs ([`hbn_pipeline::explore::plan_from_logs`]).

use anyhow::Context;
use hbn_model::explore::{ExploreError, ExploreParams};
use hbn_pipeline::explore::{Bounds, PlanRequest, Schedule, plan_from_logs};
use hbn_pipeline::{PipelineError, SignalChoice};

use crate::Ui;
use crate::cli::ExploreArgs;
use crate::cmd_estimate::load_model;
use crate::report::{self, Renderer};

/// The flag of an [`ExploreParams`] field (`max_step` -> `--max-step`).
pub fn flag(field: &str) -> String {
    format!("--{}", field.replace('_', "-"))
}

/// Runs `hbn explore`; returns the schedule written.
pub fn run(ui: &mut Ui<'_>, args: &ExploreArgs) -> anyhow::Result<Schedule> {
    for f in &args.outs {
        crate::check_output(f, "schedule output")?;
    }
    if args.samples == 0 {
        anyhow::bail!("invalid --samples: must be at least 1");
    }
    let model = load_model(&args.model)?;
    let mut params = ExploreParams::new(0.0, 1.0, 1.0);
    params.alpha_start = args.alpha_start;
    params.alpha_end = args.alpha_end;
    params.alpha_ramp = args.alpha_ramp;
    params.refit_every = args.refit_every;
    params.candidates = args.candidates;
    params.pool = args.pool;
    params.horizon = args.horizon;
    params.strategy = args
        .strategy
        .parse()
        .map_err(|e: String| anyhow::anyhow!("invalid --strategy: {e}"))?;
    params.criterion = args
        .criterion
        .parse()
        .map_err(|e: String| anyhow::anyhow!("invalid --criterion: {e}"))?;
    params.seed = args.seed;
    let request = PlanRequest {
        logs: args.logs.clone(),
        signals: SignalChoice {
            input: args.input.clone(),
            state: args.state.clone(),
            output: args.output.clone(),
        },
        log_options: args.read.options(None),
        bounds: Bounds {
            u_min: args.u_min,
            u_max: args.u_max,
            max_step: args.max_step,
        },
        params,
        steps: args.samples,
    };
    let mut render = Renderer::default();
    let result = plan_from_logs(&model, &request, &mut |e| render.event(ui, e));
    render.finish();
    let schedule = result
        .map_err(|e| match e {
            PipelineError::Explore(ExploreError::InvalidParameter { name, reason }) => {
                let bound = matches!(name, "u_min" | "u_max" | "max_step");
                let from_logs = if bound {
                    " (without the flag it is taken from the logs)"
                } else {
                    ""
                };
                anyhow::anyhow!("invalid {}: {reason}{from_logs}", flag(name))
            }
            other => report::error(other, request.log_options.time_source),
        })
        .with_context(|| format!("cannot plan from `{}`", args.model.display()))?;
    for f in &args.outs {
        schedule
            .write(f)
            .map_err(anyhow::Error::new)
            .with_context(|| format!("cannot write the schedule `{}`", f.display()))?;
    }
    let p = &schedule.params;
    let u_name = &model.signals().input.name;
    ui.line(format!(
        "planned {} samples ({:.1} s at {} Hz) of {u_name} in [{:.4}, {:.4}], steps <= {:.4}, \
         continuing `{}` (last input {:.4}); stands on {} logged samples",
        schedule.u.len(),
        schedule.u.len() as f64 / schedule.rate_hz,
        schedule.rate_hz,
        p.u_min,
        p.u_max,
        p.max_step,
        args.logs
            .last()
            .map_or_else(String::new, |l| l.display().to_string()),
        schedule.last_input,
        schedule.history_samples
    ))?;
    let lo = schedule.u.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = schedule.u.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    ui.line(format!("  the plan visits {u_name} in [{lo:.4}, {hi:.4}]"))?;
    for f in &args.outs {
        ui.line(format!("  wrote `{}`", f.display()))?;
    }
    Ok(schedule)
}
