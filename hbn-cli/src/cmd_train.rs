//! `hbn train`: fit the HBN to logs ([`hbn_pipeline::train_from_logs`]).

use anyhow::Context;
use hbn_model::{GpRole, HbnParams, HysteresisModel, Selection};
use hbn_pipeline::{Event, TrainSignals, VectorSignals, train_from_logs, train_vector_from_logs};
use serde_json::json;

use crate::Ui;
use crate::cli::TrainArgs;
use crate::glossary::{self, Term};
use crate::report::{self, Renderer};

impl TrainArgs {
    /// The training parameters: the library defaults with the flags applied.
    pub fn params(&self) -> HbnParams {
        let d = HbnParams::default();
        let kernel = self.kernel.first().copied();
        let (n_inducing, inducing) = crate::cli::inducing_choice(&self.inducing);
        let (lags, select_lags) = crate::cli::lags_choice(&self.lags);
        let (sensor_inputs, select_sensors) = crate::cli::sensor_inputs_choice(&self.sensor_inputs);
        HbnParams {
            transition_kernel: self
                .transition_kernel
                .or(kernel)
                .unwrap_or(d.transition_kernel),
            sensor_kernel: self.sensor_kernel.or(kernel).unwrap_or(d.sensor_kernel),
            n_inducing,
            select: Selection {
                kernels: self.kernel.iter().skip(1).copied().collect(),
                inducing,
                lags: select_lags,
                sensor_inputs: select_sensors,
            },
            max_points: self.max_points,
            subset_policy: self.subset.into(),
            n_starts: self.starts,
            max_iters: self.max_iters,
            seed: self.seed,
            normalize: !self.no_normalize,
            noise_floor: self.noise_floor,
            blr_window: self.blr_window,
            validation: self.validation,
            memory: self.memory.0.clone(),
            lags,
            linear_mean: self.linear_mean,
            sensor_inputs,
            max_signal_variance: self.max_signal_variance.0,
            firmware_budget: self.firmware_budget,
            // A kernel named on the command line is used as named.
            kernel_evidence: if self.kernel.is_empty()
                && self.transition_kernel.is_none()
                && self.sensor_kernel.is_none()
            {
                d.kernel_evidence
            } else {
                Vec::new()
            },
            ..d
        }
    }
}

/// The signals to train on: the flags given (a missing kind takes its default), or, with
/// none, the defaults found in the first log ([`hbn_pipeline::default_signals`]).
fn signals(args: &TrainArgs) -> anyhow::Result<VectorSignals> {
    if args.input.is_empty() && args.state.is_empty() && args.output.is_empty() {
        let first = args
            .logs
            .first()
            .context("give a training log with --log")?;
        let opts = args.read.options(args.rate);
        return hbn_pipeline::default_signals(first, opts, &mut |_| {})
            .map_err(|e| report::error(e, opts.time_source));
    }
    let d = TrainSignals::default();
    let or = |given: &[hbn_io::SignalPath], default: &hbn_io::SignalPath| {
        if given.is_empty() {
            vec![default.clone()]
        } else {
            given.to_vec()
        }
    };
    Ok(VectorSignals {
        inputs: or(&args.input, &d.input),
        states: or(&args.state, &d.state),
        outputs: or(&args.output, &d.output),
    })
}

/// Trains, saves and summarises a scalar model or, with several inputs, state components or
/// sensors, a vector model.
pub fn run(ui: &mut Ui<'_>, args: &TrainArgs) -> anyhow::Result<()> {
    crate::check_output(&args.out, "model file")?;
    // Every option is checked before a log is opened (finding the default signals opens one).
    let opts = hbn_pipeline::LogOptions {
        min_state_samples: args.min_state_samples,
        ..args.read.options(args.rate)
    };
    if let Err(e) = opts.check() {
        return Err(report::error(e.into(), opts.time_source));
    }
    if let Err(e) = args.params().check() {
        return Err(report::error(e.into(), opts.time_source));
    }
    let all = signals(args)?;
    if !all.is_scalar() {
        return run_vector(ui, args, &all);
    }
    run_scalar(ui, args, &all).map(|_| ())
}

/// `hbn train` for a vector model.
fn run_vector(ui: &mut Ui<'_>, args: &TrainArgs, signals: &VectorSignals) -> anyhow::Result<()> {
    let opts = hbn_pipeline::LogOptions {
        min_state_samples: args.min_state_samples,
        ..args.read.options(args.rate)
    };
    let mut render = Renderer::default();
    let params = args.params();
    let candidates = hbn_model::VectorModel::candidates(&params);
    if candidates.len() > 1 {
        let names: Vec<String> = candidates
            .iter()
            .map(|(lags, m)| {
                format!(
                    "{} lags {}",
                    crate::cmd_inspect::inducing_setting(*m),
                    crate::cmd_inspect::lag_set(lags)
                )
            })
            .collect();
        // Shown once the logs are read and checked, not before an error about them.
        render.when_logs_read = Some(format!(
            "model selection: training {} vector candidates side by side ({}); the one with \
             the lowest held-out NLPD, if at least as accurate held out as the first, becomes \
             the model",
            candidates.len(),
            names.join(", ")
        ));
    }
    let mut native = None;
    let trained = train_vector_from_logs(
        &args.logs,
        signals,
        opts,
        params,
        &args.sensor_inputs,
        &mut |e| {
            note_native_rate(&mut native, &e);
            render.event(ui, e)
        },
    );
    render.finish();
    let trained = trained.map_err(|e| report::error(e, opts.time_source))?;
    let model = trained.model;
    model
        .save(&args.out)
        .with_context(|| format!("cannot save the model to `{}`", args.out.display()))?;
    let d = model.dims();
    let s = model.summary();
    let mut text = format!(
        "trained a vector model ({} inputs, {} state components, {} sensors) on {} samples from {} trajectories in {:.1} s at {} Hz{}; saved to `{}`\n",
        d.inputs,
        d.states,
        d.sensors,
        s.samples,
        s.trajectories,
        s.seconds,
        model.rate_hz(),
        rate_reason(args.rate, native.as_deref(), &signals.outputs)
            .map_or(String::new(), |r| format!(" ({r})")),
        args.out.display()
    );
    let names = model.signal_names();
    text.push_str(&format!(
        "  signals: inputs {}; states {}; outputs {}\n",
        names.inputs.join(", "),
        names.states.join(", "),
        names.outputs.join(", ")
    ));
    let sensors: Vec<String> = (0..d.sensors)
        .map(|j| {
            let reads = model.sensor_reads_output(j).unwrap_or(true);
            format!(
                "{j}: {}",
                if reads { "thesis inputs" } else { "state only" }
            )
        })
        .collect();
    let lags = if s.candidates.is_empty() && model.lags().is_empty() {
        String::new()
    } else {
        format!(", lags {}", crate::cmd_inspect::lag_set(model.lags()))
    };
    text.push_str(&format!(
        "  chosen on held-out data: mode {}, sensors {}{lags}, GPs {}\n",
        model.default_mode(),
        sensors.join(", "),
        crate::cmd_inspect::inducing_setting(model.params().n_inducing)
    ));
    if let Some(best) = s.validation.iter().rev().find(|r| r.chosen) {
        let nrmse: Vec<String> = best.nrmse.iter().map(|v| format!("{v:.4}")).collect();
        text.push_str(&format!(
            "  held-out nRMSE per state component: {}\n",
            nrmse.join(", ")
        ));
    }
    for w in &s.warnings {
        text.push_str(&format!("  warning: {w}\n"));
    }
    ui.print(text)?;
    Ok(())
}

/// `hbn train` for a scalar model; returns the model.
fn run_scalar(
    ui: &mut Ui<'_>,
    args: &TrainArgs,
    all: &VectorSignals,
) -> anyhow::Result<HysteresisModel> {
    let first = |v: &[hbn_io::SignalPath]| v.first().cloned().context("a signal path is missing");
    let signals = TrainSignals {
        input: first(&all.inputs)?,
        state: first(&all.states)?,
        output: first(&all.outputs)?,
    };
    let opts = hbn_pipeline::LogOptions {
        min_state_samples: args.min_state_samples,
        ..args.read.options(args.rate)
    };
    let params = args.params();
    // With a flash budget every candidate is sparse, at the largest inducing setting that fits
    // (shown as the ladder's first).
    let budget = params.firmware_budget.map(|_| HbnParams {
        n_inducing: Some(hbn_model::FIRMWARE_INDUCING_LADDER[0]),
        select: Selection {
            inducing: Vec::new(),
            ..params.select.clone()
        },
        ..params.clone()
    });
    let candidates = budget.as_ref().unwrap_or(&params).candidates();
    let mut render = Renderer::default();
    if candidates.len() > 1 {
        // With the kernels chosen by evidence first, the candidates' kernels are not known yet.
        let evidence = params.chooses_kernels_by_evidence();
        let names: Vec<String> = candidates
            .iter()
            .map(|c| if evidence { c.shape() } else { c.to_string() })
            .collect();
        // Shown once the logs are read and checked, not before an error about them.
        render.when_logs_read = Some(format!(
            "model selection: training {} candidates side by side ({}{}); the one with the \
             lowest held-out NLPD, if at least as accurate held out as the first, becomes the model",
            candidates.len(),
            names.join(", "),
            if evidence {
                ", each GP's kernel chosen by evidence first"
            } else {
                ""
            }
        ));
        if budget.is_some()
            && let Some(note) = render.when_logs_read.as_mut()
        {
            note.push_str(
                "; for the firmware budget, m is the most inducing points (64 down to 8) whose \
                 f32 export fits",
            );
        }
    }
    let mut native = None;
    let trained = train_from_logs(&args.logs, &signals, opts, params, &mut |e| {
        note_native_rate(&mut native, &e);
        render.event(ui, e)
    });
    render.finish();
    let trained = trained.map_err(|e| report::error(e, opts.time_source))?;
    let model = trained.model;
    model
        .save(&args.out)
        .with_context(|| format!("cannot save the model to `{}`", args.out.display()))?;
    let samples = trained.logs.iter().map(|l| l.len()).sum();
    if args.json {
        let mut v = crate::cmd_inspect::model_json(&model);
        if let Some(o) = v.as_object_mut() {
            o.insert("file".into(), json!(args.out));
            o.insert("samples".into(), json!(samples));
            o.insert("seconds".into(), json!(model.summary().seconds));
        }
        ui.line(serde_json::to_string_pretty(&v).context("cannot format JSON")?)?;
    } else {
        let reason = rate_reason(
            args.rate,
            native.as_deref(),
            std::slice::from_ref(&signals.output),
        );
        ui.print(summary_text(
            &model,
            samples,
            &args.out,
            reason.as_deref(),
            ui.verbose,
        ))?;
    }
    Ok(model)
}

/// Keeps the path of the first [`Event::NativeRate`]: the signal whose native rate the grid
/// runs at.
fn note_native_rate(native: &mut Option<String>, e: &Event<'_>) {
    if let Event::NativeRate { path, .. } = e {
        native.get_or_insert_with(|| path.to_string());
    }
}

/// Why the grid runs at its rate, for the summary: `--rate` given, or the native rate of a
/// signal (`native`), named as the sensor (`outputs`, the slowest of several) where it is one.
/// `None` without either.
pub fn rate_reason(
    given: Option<f64>,
    native: Option<&str>,
    outputs: &[hbn_io::SignalPath],
) -> Option<String> {
    if given.is_some() {
        return Some("set by --rate".to_owned());
    }
    let path = native?;
    let sensor = outputs.iter().any(|o| o.to_string() == path);
    Some(match (sensor, outputs.len()) {
        (true, 1) => "the sensor's rate".to_owned(),
        (true, _) => format!("the rate of {path}, the slowest sensor"),
        (false, _) => format!("the native rate of {path}"),
    })
}

/// The one-line result of filter-aware training: the default mode and its held-out scores.
pub fn default_mode_line(model: &HysteresisModel) -> String {
    let Some(v) = &model.summary().validation else {
        return format!(
            "filter not tuned (--validation 0, or too little data to hold some out): default \
             mode {}",
            model.default_mode()
        );
    };
    match v.rows.iter().find(|r| r.mode == v.default_mode) {
        Some(r) => format!(
            "default mode {}: on held-out data nRMSE {:.4}, the held-out state within 2 standard \
             deviations {:.1}% of the time (about 95% when the uncertainty is honest)",
            v.default_mode,
            r.tuned.nrmse,
            100.0 * r.tuned.calibration.coverage_2sigma
        ),
        None => format!("default mode {}", v.default_mode),
    }
}

/// The size of a model trained for a flash budget ([`HbnParams::firmware_budget`]): the
/// inducing points per GP, and the f32 export's flash and RAM in the default mode against the
/// budget, with the modes that fit (`None` without a budget).
pub fn budget_line(model: &HysteresisModel) -> Option<String> {
    let budget = model.params().firmware_budget?;
    let kb = |b: u64| b as f64 / 1024.0;
    let sizes = hbn_export::size_report(model, hbn_export::Precision::F32, None).ok()?;
    let fit: Vec<String> = sizes
        .iter()
        .filter(|s| s.model_bytes as u64 <= budget)
        .map(|s| s.mode.to_string())
        .collect();
    let this = sizes.iter().find(|s| s.mode == model.default_mode())?;
    Some(format!(
        "  firmware budget {budget} bytes ({:.1} KB): {} and {} inducing points (transition, \
         sensor); f32 export in mode {}: flash {} bytes ({:.1} KB), RAM {} bytes ({:.1} KB); \
         modes that fit: {}\n",
        kb(budget),
        model.gp(GpRole::Transition).n_support(),
        model.gp(GpRole::Sensor).n_support(),
        this.mode,
        this.model_bytes,
        kb(this.model_bytes as u64),
        this.work_bytes(),
        kb(this.work_bytes() as u64),
        fit.join(", ")
    ))
}

/// The training summary: what was trained, at which rate and why (`rate_reason`, see
/// [`rate_reason`]), how long it took, the default mode and its held-out scores, and the
/// warnings; with `verbose`, each GP and the held-out table.
pub fn summary_text(
    model: &HysteresisModel,
    samples: usize,
    out: &std::path::Path,
    rate_reason: Option<&str>,
    verbose: bool,
) -> String {
    let s = model.summary();
    let p = model.params();
    let mut text = format!(
        "trained `{}` from {} log{}: {} samples at {:.1} Hz{}; training took {:.1} s\n  {}\n",
        out.display(),
        s.trajectories,
        if s.trajectories == 1 { "" } else { "s" },
        samples,
        model.rate_hz(),
        rate_reason.map_or(String::new(), |r| format!(" ({r})")),
        s.seconds,
        default_mode_line(model),
    );
    text.push_str(&report::evidence_line(model, verbose));
    if let Some(line) = budget_line(model) {
        text.push_str(&line);
    }
    if verbose {
        text.push_str(&format!("  {} rows per GP\n", s.rows));
        for role in GpRole::ALL {
            let gp = model.gp(role);
            let (points, score) = if gp.is_sparse() {
                ("inducing points", "bound")
            } else {
                ("support points", "LML")
            };
            let chosen = gp
                .report()
                .subset_note()
                .map_or(String::new(), |n| format!(" ({n})"));
            text.push_str(&format!(
                "  {:<10} GP: {:>4} {points}{chosen}, {score} {:>10.2}, kernel {}; optimiser \
                 starts: {}\n",
                role.name(),
                gp.n_support(),
                gp.log_marginal_likelihood(),
                p.kernel(role),
                report::terminations(s, role)
            ));
        }
        text.push_str(&report::validation_table(model));
        let points = if p.n_inducing.is_some() {
            Term::InducingPoints
        } else {
            Term::SupportPoints
        };
        text.push_str(&format!(
            "  {}\n",
            glossary::links(&[
                Term::Rows,
                points,
                Term::Lml,
                Term::OptimiserStarts,
                Term::ValidationTable
            ])
        ));
    }
    if s.warnings.is_empty() {
        text.push_str("  no warnings\n");
    } else {
        for w in &s.warnings {
            text.push_str(&format!("  warning: {w}\n"));
        }
    }
    if !verbose {
        text.push_str(&format!(
            "  (details: --verbose, or `hbn inspect {}`; {})\n",
            out.display(),
            glossary::links(&[Term::DefaultMode, Term::Nrmse, Term::Coverage])
        ));
    }
    text
}
