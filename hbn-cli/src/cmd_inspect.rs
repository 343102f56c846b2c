//! `hbn inspect`: what a model file contains.

use hbn_gp::GaussianProcess;
use hbn_model::{GpRole, HysteresisModel, KernelChoice, LocalData};
use serde_json::{Value, json};

use crate::Ui;
use crate::cli::InspectArgs;
use crate::cmd_estimate::load_model;
use crate::glossary::{self, Term};

/// The inputs of one GP by the model's signal names: `x[k-1], x[k-2], u[k-1], u[k-2]` for the
/// transition (which predicts `x[k]`), `x[k-1], y[k-1], x[k]` for the sensor (which predicts
/// `y[k]`; `x[k-1], x[k]` for a sensor of the state only; `x[k], play(x, 0.05)[k],
/// play(x, 0.2)[k]` for a sensor with memory).
pub fn input_names(model: &HysteresisModel, role: GpRole) -> Vec<String> {
    let s = model.signals();
    let (u, x, y) = (&s.input.name, &s.state.name, &s.output.name);
    match role {
        GpRole::Transition => {
            let mut names = vec![
                format!("{x}[k-1]"),
                format!("{x}[k-2]"),
                format!("{u}[k-1]"),
                format!("{u}[k-2]"),
            ];
            // One play operator per `--memory` radius, after u[k-1].
            names.extend(
                model
                    .params()
                    .memory
                    .iter()
                    .map(|f| format!("play({u}, {f})[k-1]")),
            );
            // Then one lag per `--lags` time constant.
            names.extend(
                model
                    .params()
                    .lags
                    .iter()
                    .map(|tau| format!("lag({u}, {tau} s)[k-1]")),
            );
            names
        }
        GpRole::Sensor => {
            // The sensor rows' columns: the thesis' three, then the plays of the state.
            let mut row = vec![format!("{x}[k-1]"), format!("{y}[k-1]"), format!("{x}[k]")];
            row.extend(
                hbn_model::SENSOR_MEMORY
                    .iter()
                    .map(|f| format!("play({x}, {f})[k]")),
            );
            let columns = model.params().sensor_inputs.columns();
            columns
                .iter()
                .filter_map(|&j| row.get(j).cloned())
                .collect()
        }
    }
}

/// What one GP predicts: `x[k]` or `y[k]`.
pub fn target_name(model: &HysteresisModel, role: GpRole) -> String {
    let s = model.signals();
    match role {
        GpRole::Transition => format!("{}[k]", s.state.name),
        GpRole::Sensor => format!("{}[k]", s.output.name),
    }
}

/// A subset policy as `--subset` spells it.
fn subset_name(p: hbn_gp::SubsetPolicy) -> String {
    use clap::ValueEnum;
    crate::cli::SubsetArg::from(p)
        .to_possible_value()
        .map_or_else(|| format!("{p:?}"), |v| v.get_name().to_owned())
}

fn gp_json(gp: &GaussianProcess, kernel: KernelChoice, inputs: &[String], target: &str) -> Value {
    let r = gp.report();
    let ls = gp.length_scales();
    let named: serde_json::Map<String, Value> = if ls.len() == inputs.len() {
        inputs
            .iter()
            .zip(&ls)
            .map(|(n, l)| (n.clone(), json!(l)))
            .collect()
    } else {
        serde_json::Map::new()
    };
    // Starts are numbered from 1, as the text and the progress bar count them.
    let starts: Vec<Value> = r
        .starts
        .iter()
        .enumerate()
        .map(|(i, st)| {
            let mut v = json!(st);
            if let Some(o) = v.as_object_mut() {
                o.insert("start".into(), json!(i + 1));
            }
            v
        })
        .collect();
    json!({
        "predicts": target,
        "inputs": inputs,
        "kernel": kernel.to_string(),
        "mean": if gp.linear_mean().is_empty() { "constant" } else { "linear" },
        "linear_slopes": gp.linear_mean(),
        "signal_variance": gp.signal_variance(),
        "length_scales": ls,
        "length_scales_by_input": named,
        "noise_variance": gp.noise_variance(),
        "kind": if gp.is_sparse() { "sparse" } else { "exact" },
        "support_points": gp.n_support(),
        "log_marginal_likelihood": gp.log_marginal_likelihood(),
        "training": {
            "search_samples": r.search_samples,
            "refinement": r.refinement,
            "samples": r.n_samples,
            "support_points": r.n_support,
            "subset_policy": r.subset_policy.map(subset_name),
            "starts": starts,
            "best_start": r.best_start.map(|b| b + 1),
            "evaluations": r.evaluations,
            "jitter_evaluations": r.jitter_evaluations,
            "max_jitter": r.max_jitter,
            "final_jitter": r.final_jitter,
            "signal_variance_at_bound": r.signal_variance_at_bound,
        }
    })
}

fn blr_json(l: &LocalData) -> Value {
    json!({
        "samples": l.len(),
        "cells": l.cells(),
        "max_cell": l.max_cell(),
        "window": l.window_fraction(),
    })
}

/// The model description as JSON.
pub fn model_json(model: &HysteresisModel) -> Value {
    let p = model.params();
    let s = model.summary();
    let (us, xs, ys) = model.stats();
    json!({
        "signals": model.signals(),
        "rate_hz": model.rate_hz(),
        "memory": {
            "fractions": p.memory,
            "radii": model.plays().map(|pl| pl.radii().to_vec()).unwrap_or_default(),
            "lag_seconds": p.lags,
            "lag_coefficients": model.plays().map(|pl| pl.lags().to_vec()).unwrap_or_default(),
        },
        "training_ranges": {"u": us, "x": xs, "y": ys},
        "transition": gp_json(
            model.transition(),
            p.transition_kernel,
            &input_names(model, GpRole::Transition),
            &target_name(model, GpRole::Transition),
        ),
        "sensor": gp_json(
            model.sensor(),
            p.sensor_kernel,
            &input_names(model, GpRole::Sensor),
            &target_name(model, GpRole::Sensor),
        ),
        "blr": {
            "transition": blr_json(model.transition_local()),
            "sensor": blr_json(model.sensor_local()),
        },
        "summary": {
            "trajectories": s.trajectories,
            "rows": s.rows,
            "starts": s.starts,
        },
        "observability": s.observability,
        "filter": {"tuning": model.tuning(), "validation": s.validation},
        "warnings": s.warnings,
    })
}

fn fmt_list(v: &[f64]) -> String {
    v.iter()
        .map(|x| format!("{x:.4e}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// Length scales labelled by their input (`x[k-1] 2.0878e2, ...`) when there is one per input.
pub fn named_length_scales(ls: &[f64], inputs: &[String]) -> String {
    if ls.len() == inputs.len() {
        ls.iter()
            .zip(inputs)
            .map(|(l, n)| format!("{n} {l:.4e}"))
            .collect::<Vec<_>>()
            .join(", ")
    } else {
        format!("[{}]", fmt_list(ls))
    }
}

fn gp_text(model: &HysteresisModel, role: GpRole, kernel: KernelChoice) -> String {
    let gp = model.gp(role);
    let r = gp.report();
    let failed = r.starts.iter().filter(|s| s.error.is_some()).count();
    let inputs = input_names(model, role);
    let mut s = format!(
        "{} GP: predicts {} from {}\n  kernel            {kernel}\n  signal variance   {:.4e}\n  \
         length scales     {}\n  noise variance    {:.4e}\n  {}    {} of {} samples",
        role.name(),
        target_name(model, role),
        inputs.join(", "),
        gp.signal_variance(),
        named_length_scales(&gp.length_scales(), &inputs),
        gp.noise_variance(),
        if gp.is_sparse() {
            "inducing points"
        } else {
            "support points "
        },
        gp.n_support(),
        r.n_samples,
    );
    if !gp.linear_mean().is_empty() {
        s.push_str(&format!(
            "\n  linear mean       slopes {}",
            named_length_scales(gp.linear_mean(), &inputs)
        ));
    }
    if let Some(p) = r.subset_policy {
        s.push_str(&format!(" (subset: {})", subset_name(p)));
    }
    s.push_str(&format!(
        "\n  training {}      {:.3}\n  starts            {} ({} failed; best: start {} of {}), {} \
         evaluations\n  jitter            {} evaluations needed it (at most {:.0e} of the mean diagonal), final {:.1e}\n",
        if gp.is_sparse() { "bound" } else { "LML  " },
        gp.log_marginal_likelihood(),
        r.starts.len(),
        failed,
        r.best_start
            .map_or_else(|| "-".to_owned(), |b| (b + 1).to_string()),
        r.starts.len(),
        r.evaluations,
        r.jitter_evaluations,
        r.max_jitter,
        r.final_jitter,
    ));
    s
}

/// The model description as text.
pub fn model_text(model: &HysteresisModel, file: &std::path::Path) -> String {
    let p = model.params();
    let s = model.summary();
    let sig = model.signals();
    let path =
        |i: &hbn_model::SignalInfo| i.path.clone().unwrap_or_else(|| "(not from a log)".into());
    let mut t = format!(
        "model `{}`\nsignals\n  input  {} = {}\n  state  {} = {}\n  output {} = {}\nrate {:.1} Hz\n\
         trained on {} trajector{}, {} rows per GP\n\n",
        file.display(),
        sig.input.name,
        path(&sig.input),
        sig.state.name,
        path(&sig.state),
        sig.output.name,
        path(&sig.output),
        model.rate_hz(),
        s.trajectories,
        if s.trajectories == 1 { "y" } else { "ies" },
        s.rows,
    );
    for role in GpRole::ALL {
        if role == GpRole::Sensor {
            t.push('\n');
        }
        t.push_str(&gp_text(model, role, p.kernel(role)));
        let ends = crate::report::terminations(s, role);
        if !ends.is_empty() {
            t.push_str(&format!("  start endings      {ends}\n"));
        }
    }
    t.push_str("\nBLR index (ekf-blr)\n");
    for (n, l) in [
        ("transition", model.transition_local()),
        ("sensor", model.sensor_local()),
    ] {
        t.push_str(&format!(
            "  {n:<10} {} samples in {} cells (max {} per cell), window +-{} of range\n",
            l.len(),
            l.cells(),
            l.max_cell(),
            l.window_fraction()
        ));
    }
    t.push_str("\nfilter\n");
    t.push_str(&crate::report::evidence_line(model, true));
    t.push_str(&crate::report::validation_table(model));
    match &s.observability {
        Some(o) => t.push_str(&format!(
            "\nobservability (first training trajectory)\n  lambda_min: min {:.3e}, median {:.3e}; \
             lambda_max {:.3e}\n  near-unobservable (the sensor says almost nothing about the \
             state) on {:.1}% of samples\n",
            o.min,
            o.median,
            o.max,
            100.0 * o.near_unobservable
        )),
        None => t.push_str("\nobservability: not computed\n"),
    }
    let points = if p.n_inducing.is_some() {
        Term::InducingPoints
    } else {
        Term::SupportPoints
    };
    t.push_str(&format!(
        "\n{}\n",
        glossary::links(&[
            Term::Signals,
            Term::Rows,
            Term::LengthScales,
            points,
            Term::Lml,
            Term::OptimiserStarts,
            Term::Jitter,
            Term::BlrIndex,
            Term::ValidationTable,
            Term::Observability,
        ])
    ));
    if s.warnings.is_empty() {
        t.push_str("\nno warnings\n");
    } else {
        t.push_str("\nwarnings\n");
        for w in &s.warnings {
            t.push_str(&format!("  {w}\n"));
        }
    }
    t
}

/// Runs `hbn inspect`.
pub fn run(ui: &mut Ui<'_>, args: &InspectArgs) -> anyhow::Result<()> {
    if crate::cmd_estimate::is_vector_model(&args.model) {
        let model = hbn_model::VectorModel::load(&args.model).map_err(|e| {
            anyhow::anyhow!(e).context(format!("cannot load the model `{}`", args.model.display()))
        })?;
        return if args.json {
            ui.line(serde_json::to_string_pretty(&vector_json(&model))?)
        } else {
            ui.print(vector_text(&model, &args.model))
        };
    }
    let model = load_model(&args.model)?;
    if args.json {
        let text = serde_json::to_string_pretty(&model_json(&model))?;
        ui.line(text)
    } else {
        ui.print(model_text(&model, &args.model))?;
        ui.line("\nfirmware (`hbn export`, docs/firmware.md):")?;
        ui.print(crate::cmd_export::size_text(&model, None)?)
    }
}

/// One line per GP of a vector model.
fn vector_gps(model: &hbn_model::VectorModel) -> Vec<(String, &GaussianProcess)> {
    let d = model.dims();
    let names = model.signal_names();
    let name = |v: &[String], i: usize| v.get(i).cloned().unwrap_or_default();
    let mut out = Vec::new();
    for i in 0..d.states {
        if let Some(gp) = model.transition(i) {
            out.push((format!("transition {i} ({})", name(&names.states, i)), gp));
        }
    }
    for j in 0..d.sensors {
        if let Some(gp) = model.sensor(j) {
            let inputs = if model.sensor_reads_output(j).unwrap_or(true) {
                "thesis inputs"
            } else {
                "state only"
            };
            out.push((
                format!("sensor {j} ({}, {inputs})", name(&names.outputs, j)),
                gp,
            ));
        }
    }
    out
}

/// `hbn inspect` of a vector model: sizes, signals, choices, every GP, the held-out scores.
pub fn vector_text(model: &hbn_model::VectorModel, file: &std::path::Path) -> String {
    let d = model.dims();
    let names = model.signal_names();
    let s = model.summary();
    let mut t = format!(
        "vector model `{}`: {} inputs, {} state components, {} sensors at {} Hz; default mode {}\n",
        file.display(),
        d.inputs,
        d.states,
        d.sensors,
        model.rate_hz(),
        model.default_mode()
    );
    t.push_str(&format!(
        "  signals: inputs {}; states {}; outputs {}\n",
        names.inputs.join(", "),
        names.states.join(", "),
        names.outputs.join(", ")
    ));
    t.push_str(&format!(
        "  trained on {} samples from {} trajectories in {:.1} s\n",
        s.samples, s.trajectories, s.seconds
    ));
    t.push_str("GPs:\n");
    for (label, gp) in vector_gps(model) {
        t.push_str(&format!(
            "  {label}: {}, {} inputs, {} support points{}, noise variance {:.3e}\n",
            kernel_name(gp),
            gp.kernel().dim,
            gp.n_support(),
            if gp.is_sparse() { " (inducing)" } else { "" },
            gp.noise_variance()
        ));
    }
    if !s.kernel_evidence.is_empty() {
        t.push_str("kernels chosen by evidence (log marginal likelihood; the highest is kept):\n");
        let mut rows = s.kernel_evidence.iter().peekable();
        while let Some(first) = rows.next() {
            let mut line = vec![first];
            while let Some(r) = rows.next_if(|r| r.gp == first.gp) {
                line.push(r);
            }
            let each: Vec<String> = line
                .iter()
                .map(|r| {
                    let lml = r.lml.map_or("failed".to_owned(), |l| format!("{l:.2}"));
                    format!(
                        "{} {lml}{}",
                        r.kernel,
                        if r.chosen { " (kept)" } else { "" }
                    )
                })
                .collect();
            t.push_str(&format!("  {:<24} {}\n", first.gp, each.join(", ")));
        }
    }
    if !s.validation.is_empty() {
        t.push_str(
            "held-out choices (NLPD of the state summed over components; lower is better):\n",
        );
        for r in &s.validation {
            let nrmse: Vec<String> = r.nrmse.iter().map(|v| format!("{v:.4}")).collect();
            t.push_str(&format!(
                "  {:<40} NLPD {:>9.3}  nRMSE {}{}\n",
                r.what,
                r.nlpd,
                nrmse.join(", "),
                if r.chosen { "  (kept)" } else { "" }
            ));
        }
    }
    if !s.candidates.is_empty() {
        t.push_str(
            "candidates, trained side by side (the lowest held-out NLPD among those at least as \
             accurate held out as the first):\n",
        );
        for r in &s.candidates {
            let nrmse: Vec<String> = r.nrmse.iter().map(|v| format!("{v:.4}")).collect();
            let score = match (r.nlpd, &r.error) {
                (Some(nlpd), _) => format!("NLPD {nlpd:>9.3}  nRMSE {}", nrmse.join(", ")),
                (None, Some(e)) => format!("failed: {e}"),
                (None, None) => "no held-out score".to_owned(),
            };
            t.push_str(&format!(
                "  {:<6} lags {:<12} {score}  {:.1} s{}\n",
                inducing_setting(r.n_inducing),
                lag_set(&r.lags),
                r.seconds,
                if r.chosen { "  (chosen)" } else { "" }
            ));
        }
    }
    for w in &s.warnings {
        t.push_str(&format!("warning: {w}\n"));
    }
    t
}

/// The kernel a fitted GP uses, by name (`custom` for a structure no choice gives).
fn kernel_name(gp: &GaussianProcess) -> String {
    KernelChoice::of_spec(gp.kernel()).map_or_else(|| "custom".to_owned(), |k| k.to_string())
}

/// An inducing setting as the CLI prints it: `exact`, `m=64`.
pub fn inducing_setting(n_inducing: Option<usize>) -> String {
    n_inducing.map_or_else(|| "exact".to_owned(), |m| format!("m={m}"))
}

/// A lag set as the CLI prints it: `none`, `1 s`, `0.1 s, 1 s`.
pub fn lag_set(lags: &[f64]) -> String {
    if lags.is_empty() {
        return "none".to_owned();
    }
    let each: Vec<String> = lags.iter().map(|t| format!("{t} s")).collect();
    each.join(", ")
}

/// `hbn inspect --json` of a vector model.
pub fn vector_json(model: &hbn_model::VectorModel) -> Value {
    let d = model.dims();
    let gps: Vec<Value> = vector_gps(model)
        .into_iter()
        .map(|(label, gp)| {
            json!({
                "gp": label,
                "kernel": kernel_name(gp),
                "inputs": gp.kernel().dim,
                "support_points": gp.n_support(),
                "sparse": gp.is_sparse(),
                "noise_variance": gp.noise_variance(),
            })
        })
        .collect();
    json!({
        "kind": "vector",
        "inputs": d.inputs,
        "states": d.states,
        "sensors": d.sensors,
        "rate_hz": model.rate_hz(),
        "default_mode": model.default_mode().name(),
        "signals": model.signal_names(),
        "gps": gps,
        "summary": model.summary(),
    })
}
