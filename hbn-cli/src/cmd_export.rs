//! `hbn export`: a model as firmware source (see `hbn-export` and docs/firmware.md).

use anyhow::Context;
use hbn_core::Mode;
use hbn_export::{Format, Precision};
use hbn_model::{HysteresisModel, VectorModel};

use crate::Ui;
use crate::cli::{ExportArgs, FormatArg, PrecisionArg};
use crate::cmd_estimate::{is_vector_model, load_model};

impl From<FormatArg> for Format {
    fn from(f: FormatArg) -> Self {
        match f {
            FormatArg::Rust => Format::Rust,
            FormatArg::C => Format::C,
        }
    }
}

impl From<PrecisionArg> for Precision {
    fn from(p: PrecisionArg) -> Self {
        match p {
            PrecisionArg::F64 => Precision::F64,
            PrecisionArg::F32 => Precision::F32,
        }
    }
}

/// The firmware size table of `model` at both precisions (what `hbn export` and `hbn
/// inspect` print).
pub fn size_text(model: &HysteresisModel, init_pairs: Option<usize>) -> anyhow::Result<String> {
    let mut s = String::new();
    for p in [Precision::F32, Precision::F64] {
        let sizes = hbn_export::size_report(model, p, init_pairs)
            .context("cannot compute the firmware size report")?;
        let table = hbn_export::size_table(&sizes, model.default_mode());
        // The legend once, after the last table.
        let body: Vec<&str> = table.lines().collect();
        let keep = if p == Precision::F64 {
            body.len()
        } else {
            body.len().saturating_sub(1)
        };
        for line in body.iter().take(keep) {
            s.push_str(&format!("  {line}\n"));
        }
    }
    Ok(s)
}

/// Flash above which `hbn export` warns that the model is not firmware-sized (1 MB).
const LARGE_FLASH: usize = 1024 * 1024;

/// Runs `hbn export`.
pub fn run(ui: &mut Ui<'_>, args: &ExportArgs) -> anyhow::Result<()> {
    if is_vector_model(&args.model) {
        return run_vector(ui, args);
    }
    let model = load_model(&args.model)?;
    let mode = args.mode.unwrap_or_else(|| model.default_mode());
    let (format, precision) = (Format::from(args.format), Precision::from(args.precision));
    let origin = args.model.file_name().map_or_else(
        || args.model.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let files = hbn_export::export(&model, mode, format, precision, args.init_pairs, &origin)
        .with_context(|| {
            format!(
                "cannot export `{}` as --format {} --precision {}",
                args.model.display(),
                format.name(),
                precision.name()
            )
        })?;
    let paths = hbn_export::write(&args.out, &files).with_context(|| {
        format!(
            "cannot write the export into --out `{}`",
            args.out.display()
        )
    })?;
    let names: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    let exact_f32 = precision == Precision::F32
        && !(model.transition().is_sparse() && model.sensor().is_sparse());
    if exact_f32 {
        ui.warn(
            "the tables of an exact GP hold its packed Cholesky factor, n (n + 1) / 2 reals per \
             GP (about 1 MB in f32 at the default 500 support points, see docs/firmware.md): for \
             a microcontroller, train a sparse model (hbn train --inducing 32)",
        );
    }
    let sizes = hbn_export::size_report(&model, precision, args.init_pairs)
        .context("cannot compute the firmware size report")?;
    let this = sizes.iter().find(|s| s.mode == mode);
    if precision == Precision::F32 {
        let view = model.view().context("cannot read the model's GPs")?;
        let errors = hbn_export::f32_variance_errors(&view);
        // The rule of `factors_in_two_parts`, on the errors it would compute again.
        for (name, err) in ["transition", "sensor"]
            .iter()
            .zip(errors)
            .filter(|(_, err)| *err > hbn_export::F32_VARIANCE_TOLERANCE)
        {
            ui.notice(format!(
                "the {name} GP's variance factor is kept in two f32 parts (in one, its latent \
                 variance would move by {:.0}% of what the filter adds it to; docs/firmware.md)",
                100.0 * err
            ));
        }
    }
    ui.line(format!(
        "exported `{}` (mode {mode}, {} reals) as {}: {}",
        args.model.display(),
        precision.name(),
        format.name(),
        names.join(", ")
    ))?;
    if let Some(s) = this {
        let kb = |b: usize| b as f64 / 1024.0;
        let against = match model.params().firmware_budget {
            Some(budget) => {
                let fits = s.model_bytes as u64 <= budget;
                format!(
                    "; the model's firmware budget is {budget} bytes ({:.1} KB): {}",
                    budget as f64 / 1024.0,
                    if fits {
                        "within it".to_owned()
                    } else if precision == Precision::F64 {
                        "the budget is for f32 reals (--precision f32)".to_owned()
                    } else {
                        format!("over it by {} bytes", s.model_bytes as u64 - budget)
                    }
                )
            }
            None => String::new(),
        };
        ui.line(format!(
            "model data {} bytes ({:.1} KB) of flash, work memory {} bytes ({:.1} KB) of RAM{against}",
            s.model_bytes,
            kb(s.model_bytes),
            s.work_bytes(),
            kb(s.work_bytes())
        ))?;
        // An exact model's f32 export has had its own warning above.
        if s.model_bytes > LARGE_FLASH && !exact_f32 {
            ui.warn(format!(
                "this export's model data need {:.1} MB of flash, more than most \
                 microcontrollers have; train a model for a flash budget (hbn train \
                 --firmware-budget 64KB), or a small one by hand (hbn train --inducing 32, then \
                 hbn export --mode ekf --precision f32); docs/firmware.md",
                s.model_bytes as f64 / (1024.0 * 1024.0)
            ));
        }
    }
    ui.line("firmware size per mode:")?;
    ui.print(size_text(&model, args.init_pairs)?)
}

/// The firmware size table of a vector `model` at both precisions.
pub fn vector_size_text(model: &VectorModel, init_rows: Option<usize>) -> anyhow::Result<String> {
    let mut s = String::new();
    for p in [Precision::F32, Precision::F64] {
        let sizes = hbn_export::vector_size_report(model, p, init_rows)
            .context("cannot compute the firmware size report")?;
        let table = hbn_export::vector_size_table(&sizes, model.default_mode());
        // The legend once, after the last table.
        let body: Vec<&str> = table.lines().collect();
        let keep = if p == Precision::F64 {
            body.len()
        } else {
            body.len().saturating_sub(1)
        };
        for line in body.iter().take(keep) {
            s.push_str(&format!("  {line}\n"));
        }
    }
    Ok(s)
}

/// `hbn export` of a vector model: its tables for `hbn_vector_filter_init` (C) or
/// `hbn_core::VectorEstimator` (Rust), and its size report.
fn run_vector(ui: &mut Ui<'_>, args: &ExportArgs) -> anyhow::Result<()> {
    let model = VectorModel::load(&args.model)
        .with_context(|| format!("cannot load the model `{}`", args.model.display()))?;
    let mode = args.mode.unwrap_or_else(|| model.default_mode());
    if mode == Mode::EkfBlr {
        anyhow::bail!(
            "--mode ekf-blr is for scalar models; a vector model exports with --mode ekf or ukf"
        );
    }
    let (format, precision) = (Format::from(args.format), Precision::from(args.precision));
    let origin = args.model.file_name().map_or_else(
        || args.model.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let files =
        hbn_export::export_vector(&model, mode, format, precision, args.init_pairs, &origin)
            .with_context(|| {
                format!(
                    "cannot export `{}` as --format {} --precision {}",
                    args.model.display(),
                    format.name(),
                    precision.name()
                )
            })?;
    let paths = hbn_export::write(&args.out, &files).with_context(|| {
        format!(
            "cannot write the export into --out `{}`",
            args.out.display()
        )
    })?;
    let names: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
    let d = model.dims();
    let sparse = (0..d.states)
        .filter_map(|i| model.transition(i))
        .chain((0..d.sensors).filter_map(|j| model.sensor(j)))
        .all(|gp| gp.is_sparse());
    if precision == Precision::F32 && !sparse {
        ui.warn(
            "the tables of an exact GP hold its packed Cholesky factor, n (n + 1) / 2 reals per \
             GP, and a vector model has one GP per state component and per sensor: for a \
             microcontroller, train a sparse model (hbn train --inducing 32)",
        );
    }
    let sizes = hbn_export::vector_size_report(&model, precision, args.init_pairs)
        .context("cannot compute the firmware size report")?;
    ui.line(format!(
        "exported `{}` ({} inputs, {} state components, {} sensors; mode {mode}, {} reals) as {}: {}",
        args.model.display(),
        d.inputs,
        d.states,
        d.sensors,
        precision.name(),
        format.name(),
        names.join(", ")
    ))?;
    if let Some(s) = sizes.iter().find(|s| s.mode == mode) {
        let kb = |b: usize| b as f64 / 1024.0;
        ui.line(format!(
            "model data {} bytes ({:.1} KB) of flash, work memory {} bytes ({:.1} KB) of RAM",
            s.model_bytes,
            kb(s.model_bytes),
            s.work_bytes(),
            kb(s.work_bytes())
        ))?;
        if s.model_bytes > LARGE_FLASH {
            ui.warn(format!(
                "this export's model data need {:.1} MB of flash, more than most \
                 microcontrollers have; train a sparse model (hbn train --inducing 32) and keep \
                 fewer rows of the prior of x_0 (hbn export --init-pairs 100); docs/firmware.md",
                s.model_bytes as f64 / (1024.0 * 1024.0)
            ));
        }
    }
    ui.line("firmware size per mode:")?;
    ui.print(vector_size_text(&model, args.init_pairs)?)
}
