//! `hbn estimate`: run the EKF over a log.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Context;
use hbn_core::{Flags, Mode};
use hbn_io::SignalPath;
use hbn_model::{Estimate, HbnModel};
use serde_json::{Value, json};

use crate::Ui;
use crate::cli::{EstimateArgs, ModeArg};
use crate::logdata::{self, LogData, ReadSettings};

/// Topic of the estimate in the output MCAP.
pub const ESTIMATE_TOPIC: &str = "/hbn/estimate";
/// Schema name of the estimate messages.
pub const ESTIMATE_SCHEMA: &str = "hbn/Estimate";
/// CSV header.
pub const CSV_HEADER: &str = "t,x,x_std,y_pred,innovation,nis,flags";

/// The core mode of a CLI mode.
pub fn mode(m: ModeArg) -> Mode {
    match m {
        ModeArg::Ekf => Mode::Ekf,
        ModeArg::EkfBlr => Mode::EkfBlr,
    }
}

/// CLI name of a mode.
pub fn mode_name(m: Mode) -> &'static str {
    m.name()
}

/// Loads a model, naming the file in errors.
pub fn load_model(file: &Path) -> anyhow::Result<HbnModel> {
    HbnModel::load(file).with_context(|| format!("cannot load the model `{}`", file.display()))
}

/// The input and output paths: explicit, else the model's, else the defaults.
pub fn model_io_paths(
    model: &HbnModel,
    model_file: &Path,
    input: Option<&SignalPath>,
    output: Option<&SignalPath>,
) -> anyhow::Result<(SignalPath, SignalPath)> {
    let s = model.signals();
    let u = match input {
        Some(p) => p.clone(),
        None => logdata::model_path(s.input.path.as_deref(), "/input.data", model_file)?,
    };
    let y = match output {
        Some(p) => p.clone(),
        None => logdata::model_path(s.output.path.as_deref(), "/sensor.data", model_file)?,
    };
    Ok((u, y))
}

/// JSON schema of the estimate messages.
pub fn estimate_schema() -> Value {
    json!({
        "title": ESTIMATE_SCHEMA,
        "description": "State estimate of the hbn EKF, one message per resampled sample",
        "type": "object",
        "properties": {
            "x": {"type": "number", "description": "estimate of the state x"},
            "x_std": {"type": "number", "description": "standard deviation of the estimate"},
            "y_pred": {"type": "number", "description": "predicted sensor output before the update"},
            "innovation": {"type": "number", "description": "y - y_pred"},
            "nis": {"type": "number", "description": "normalised innovation squared"},
            "flags": {"type": "integer", "description": "guard flags (bitset)"},
            "flag_names": {"type": "array", "items": {"type": "string"}, "description": "names of the set flags"}
        },
        "required": ["x", "x_std", "y_pred", "innovation", "nis", "flags", "flag_names"]
    })
}

/// The estimate as CSV text.
pub fn csv_text(t_s: &[f64], est: &Estimate) -> String {
    let mut s = String::with_capacity(64 * t_s.len() + 64);
    s.push_str(CSV_HEADER);
    s.push('\n');
    for (k, t) in t_s.iter().enumerate() {
        let g = |v: &Vec<f64>| v.get(k).copied().unwrap_or(f64::NAN);
        let _ = writeln!(
            s,
            "{t},{},{},{},{},{},{}",
            g(&est.x),
            g(&est.x_std),
            g(&est.y_pred),
            g(&est.innovation),
            g(&est.nis),
            est.flags.get(k).copied().unwrap_or(0)
        );
    }
    s
}

/// Writes the estimate as MCAP on the log's clock.
pub fn write_mcap(file: &Path, log: &LogData, est: &Estimate) -> anyhow::Result<()> {
    let a = &log.aligned;
    let t_ns: Vec<u64> = a
        .t_s
        .iter()
        .map(|t| a.t0_ns.saturating_add((t * 1e9).round() as u64))
        .collect();
    let records: Vec<Value> = (0..a.t_s.len())
        .map(|k| {
            let f = est.flags.get(k).copied().unwrap_or(0);
            let g = |v: &Vec<f64>| v.get(k).copied().unwrap_or(f64::NAN);
            json!({
                "x": g(&est.x),
                "x_std": g(&est.x_std),
                "y_pred": g(&est.y_pred),
                "innovation": g(&est.innovation),
                "nis": g(&est.nis),
                "flags": f,
                "flag_names": Flags(f).names().collect::<Vec<_>>(),
            })
        })
        .collect();
    hbn_io::write_json_log(
        file,
        ESTIMATE_TOPIC,
        ESTIMATE_SCHEMA,
        &estimate_schema(),
        &t_ns,
        &records,
    )
    .with_context(|| format!("cannot write `{}`", file.display()))?;
    Ok(())
}

/// Summary lines of a run.
pub fn summary(est: &Estimate, m: Mode) -> String {
    let n = est.x.len();
    let finite_nis: Vec<f64> = est.nis.iter().copied().filter(|v| v.is_finite()).collect();
    let mean_nis = if finite_nis.is_empty() {
        f64::NAN
    } else {
        finite_nis.iter().sum::<f64>() / finite_nis.len() as f64
    };
    let mut s = format!("  {}: {n} samples, mean NIS {mean_nis:.3}", mode_name(m));
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

/// Runs `hbn estimate`; returns the log data and the estimate.
pub fn run(ui: &mut Ui<'_>, args: &EstimateArgs) -> anyhow::Result<(LogData, Estimate)> {
    for (f, what) in [(&args.out, "MCAP output"), (&args.csv, "CSV output")] {
        if let Some(f) = f {
            crate::check_output(f, what)?;
        }
    }
    let model = load_model(&args.model)?;
    let (u, y) = model_io_paths(
        &model,
        &args.model,
        args.input.as_ref(),
        args.output.as_ref(),
    )?;
    let settings = ReadSettings::from(&args.read);
    let log = logdata::load(ui, &args.log, &[u, y], Some(model.rate_hz()), &settings)?;
    let m = mode(args.mode);
    let est = model
        .estimate(log.column(0), log.column(1), m)
        .with_context(|| format!("estimation on `{}` failed", args.log.display()))?;
    // Render everything first, then write: an error leaves no output behind.
    let csv = args.csv.as_ref().map(|_| csv_text(&log.aligned.t_s, &est));
    if let Some(f) = &args.out {
        write_mcap(f, &log, &est)?;
    }
    if let (Some(f), Some(text)) = (&args.csv, csv) {
        hbn_io::write_atomic(f, text.as_bytes())
            .with_context(|| format!("cannot write `{}`", f.display()))?;
    }
    let mut text = format!(
        "estimated `{}` with `{}` at {:.1} Hz ({:.2} s)\n",
        args.log.display(),
        args.model.display(),
        model.rate_hz(),
        log.aligned.t_s.last().copied().unwrap_or(0.0)
    );
    text.push_str(&summary(&est, m));
    for (f, what) in [(&args.out, "MCAP (/hbn/estimate)"), (&args.csv, "CSV")] {
        if let Some(f) = f {
            text.push_str(&format!("  wrote {what}: `{}`\n", f.display()));
        }
    }
    if args.out.is_none() && args.csv.is_none() {
        text.push_str("  (no --out or --csv given: nothing written)\n");
    }
    ui.print(text)?;
    Ok((log, est))
}
