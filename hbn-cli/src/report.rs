//! What the CLI adds to the library: its own names for settings (`--max-points`), hints in
//! error messages, and the rendering of workflow events as notices and progress bars.

use hbn_io::{IoError, TimeSource};
use hbn_model::{ModelError, Param};
use hbn_pipeline::{Event, LogOption, PipelineError, Setting};
use indicatif::ProgressBar;

use crate::Ui;

/// The command-line flag of a setting.
pub fn flag(setting: Setting) -> &'static str {
    match setting {
        Setting::Param(p) => match p {
            Param::Rate => "--rate",
            Param::Kernel => "--kernel",
            Param::TransitionKernel => "--transition-kernel",
            Param::SensorKernel => "--sensor-kernel",
            Param::Inducing => "--inducing",
            Param::MaxPoints => "--max-points",
            Param::SubsetPolicy => "--subset",
            Param::Starts => "--starts",
            Param::MaxIters => "--max-iters",
            Param::Seed => "--seed",
            Param::Normalize => "--no-normalize",
            Param::NoiseFloor => "--noise-floor",
            Param::BlrWindow => "--blr-window",
            Param::Blr => "the BLR prior (set in the Rust API)",
            Param::Validation => "--validation",
            Param::Memory => "--memory",
            Param::Lags => "--lags",
            Param::LinearMean => "--linear-mean",
            Param::MaxSignalVariance => "--max-signal-variance",
            Param::SensorInputs => "--sensor-inputs",
            Param::FirmwareBudget => "--firmware-budget",
        },
        Setting::Log(o) => match o {
            LogOption::Rate => "--rate",
            LogOption::MaxGap => "--max-gap",
            LogOption::TimeSource => "--time-source",
            LogOption::Logs => "--log",
            LogOption::Input => "--input",
            LogOption::State => "--state",
            LogOption::Output => "--output",
            LogOption::Mode => "--mode",
            LogOption::MinCoverage => "--min-coverage",
            LogOption::MinStateSamples => "--min-state-samples",
        },
    }
}

/// A library error as the CLI reports it: settings by their flag, reading errors with the
/// flags that would fix them.
pub fn error(e: PipelineError, time_source: TimeSource) -> anyhow::Error {
    let problem = match &e {
        PipelineError::Option(o) => Some(o.problem.to_string()),
        PipelineError::Config(c) | PipelineError::Model(ModelError::Config(c)) => {
            Some(c.problem.to_string())
        }
        _ => None,
    };
    if let (Some(setting), Some(problem)) = (e.setting(), problem) {
        return anyhow::anyhow!("invalid {}: {problem}", flag(setting));
    }
    let hint = match &e {
        PipelineError::Read {
            source: IoError::TimeBackwards { .. },
            ..
        } if time_source == TimeSource::HeaderStamp => " (on the command line: --time-source log)",
        PipelineError::Read {
            source: IoError::Gap { .. } | IoError::TooFewSamples { .. },
            ..
        } => " (options --max-gap, --rate)",
        PipelineError::UnknownRate { .. } => " (--rate)",
        PipelineError::SignalPath { .. } => " (--input, --state, --output)",
        PipelineError::Read {
            source: IoError::MissingTopic { .. } | IoError::MissingField { .. },
            ..
        } => {
            " (the signals are the model's training paths unless --input, --output or --state \
             say otherwise)"
        }
        _ => "",
    };
    if hint.is_empty() {
        anyhow::Error::new(e)
    } else {
        anyhow::anyhow!("{e}{hint}")
    }
}

/// `1000 samples at 100.0 Hz (10.00 s, where /input.data and /sensor.data both have data)`:
/// the grid of a log, with the signals whose common span it covers (so that `estimate`, which
/// reads two signals, and `eval`, which reads three, explain why their counts may differ).
pub fn grid_text(log: &hbn_pipeline::LogData) -> String {
    let paths: Vec<String> = log.paths.iter().map(|p| p.to_string()).collect();
    let signals = match paths.as_slice() {
        [] => String::new(),
        [one] => format!(", where {one} has data"),
        [a, b] => format!(", where {a} and {b} both have data"),
        [rest @ .., last] => format!(", where {} and {last} all have data", rest.join(", ")),
    };
    format!(
        "{} sample{} at {:.1} Hz ({:.2} s{signals})",
        log.len(),
        if log.len() == 1 { "" } else { "s" },
        log.rate_hz(),
        log.duration_s()
    )
}

/// Why each optimiser start of one GP stopped, comma-separated.
pub fn terminations(summary: &hbn_model::TrainingSummary, role: hbn_model::GpRole) -> String {
    summary
        .terminations(role)
        .map(|t| t.to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// Renders workflow events: notices on stderr and progress bars (both off with `--quiet`).
#[derive(Default)]
pub struct Renderer {
    reading: Option<ProgressBar>,
    training: Option<ProgressBar>,
    experiment: Option<ProgressBar>,
    /// A notice to show once the logs are read and checked (what training is about to do).
    pub when_logs_read: Option<String>,
}

impl Renderer {
    /// Shows one event.
    pub fn event(&mut self, ui: &mut Ui<'_>, e: Event<'_>) {
        match e {
            Event::Reading { file, progress } => {
                if progress.done {
                    if let Some(b) = self.reading.take() {
                        b.finish_and_clear();
                    }
                } else {
                    let bar = self.reading.get_or_insert_with(|| {
                        crate::progress::bytes(ui.quiet, progress.total_bytes, file)
                    });
                    bar.set_position(progress.bytes_read);
                }
            }
            Event::NativeRate {
                file,
                path,
                rate_hz,
            } => ui.notice(format!(
                "using {rate_hz:.1} Hz, the native rate of {path} in `{}` (set --rate to override)",
                file.display()
            )),
            Event::Resampling {
                file,
                path,
                native_hz,
                rate_hz,
            } => ui.notice(format!(
                "resampling {path} from {native_hz:.1} Hz to {rate_hz:.1} Hz (`{}`)",
                file.display()
            )),
            Event::PartialCoverage {
                file,
                path,
                covered_s,
                log_s,
            } => ui.warn(format!(
                "{path} spans only {covered_s:.2} s of the {log_s:.2} s of `{}` ({:.0}%); hbn uses \
                 only the span all signals share, so the rest of the log is left out: record \
                 every signal for the whole log, or cut the log to where they overlap \
                 (--min-coverage sets this warning's threshold)",
                file.display(),
                100.0 * covered_s / log_s
            )),
            Event::Split {
                file,
                gaps,
                overlap_start_ns,
                pieces,
                dropped,
                max_gap_s,
            } => {
                let at: Vec<String> = gaps
                    .iter()
                    .map(|g| {
                        let t = (g.start_ns as f64 - overlap_start_ns as f64) * 1e-9;
                        format!("{} for {:.3} s at t = {t:.3} s", g.path, g.gap_s)
                    })
                    .collect();
                ui.warn(format!(
                    "`{}` has {} gap{} longer than --max-gap ({max_gap_s} s): {}; it is split \
                     there into {pieces} piece{}, each a trajectory of its own{}",
                    file.display(),
                    gaps.len(),
                    if gaps.len() == 1 { "" } else { "s" },
                    at.join(", "),
                    if pieces == 1 { "" } else { "s" },
                    if dropped > 0 {
                        format!(" ({dropped} too short to use left out)")
                    } else {
                        String::new()
                    }
                ))
            }
            Event::NoState { file, path } => ui.warn(format!(
                "`{}` has no topic `{}` for the state ({path}): it trains with its state \
                 latent, from u and y alone, beside the logs that have it \
                 (expectation-maximisation; docs/slow-camera.md)",
                file.display(),
                path.topic
            )),
            Event::LogsRead { .. } => {
                if let Some(msg) = self.when_logs_read.take() {
                    ui.notice(msg);
                }
            }
            Event::Training { gp, progress } => {
                let bar = self.training.get_or_insert_with(|| {
                    crate::progress::bar(ui.quiet, 2 * progress.n_starts as u64, "training")
                });
                bar.inc(1);
                let best = progress
                    .best_lml
                    .map_or_else(|| "-".to_owned(), |l| format!("{l:.1}"));
                bar.set_message(format!(
                    "{gp} GP start {}/{} {} (best LML {best})",
                    progress.start + 1,
                    progress.n_starts,
                    progress.termination
                ));
            }
            Event::ExperimentCase { row, total, .. } => {
                let bar = self.experiment.get_or_insert_with(|| {
                    crate::progress::bar(ui.quiet, total as u64, "experiment")
                });
                bar.inc(1);
                bar.set_message(format!(
                    "{} gain {} seed {}: nRMSE {:.4} ({}), 2-sigma coverage {:.0}%",
                    row.system,
                    row.noise_gain,
                    row.seed,
                    row.nrmse_default,
                    row.default_mode.name(),
                    100.0 * row.calibration_default.coverage_2sigma
                ));
            }
        }
    }

    /// Clears every bar.
    pub fn finish(&mut self) {
        for b in [
            self.reading.take(),
            self.training.take(),
            self.experiment.take(),
        ]
        .into_iter()
        .flatten()
        {
            b.finish_and_clear();
        }
    }
}

impl Drop for Renderer {
    fn drop(&mut self) {
        self.finish();
    }
}

/// Each GP's kernel chosen by evidence (`hbn train`, `hbn inspect`): the chosen kernels, and
/// with `details` every kernel's LML; empty when the kernels were set.
pub fn evidence_line(model: &hbn_model::HysteresisModel, details: bool) -> String {
    let rows = &model.summary().kernel_evidence;
    if rows.is_empty() {
        return String::new();
    }
    let lml = |l: Option<f64>| l.map_or("failed".to_owned(), |l| format!("{l:.1}"));
    let per_gp: Vec<String> = hbn_model::GpRole::ALL
        .iter()
        .map(|&role| {
            let of: Vec<_> = rows.iter().filter(|r| r.gp == role).collect();
            let chosen = of.iter().find(|r| r.chosen);
            let name = chosen.map_or("none".to_owned(), |r| r.kernel.to_string());
            if !details {
                return format!("{} {name}", role.name());
            }
            let others: Vec<String> = of
                .iter()
                .filter(|r| !r.chosen)
                .map(|r| format!("{} {}", r.kernel, lml(r.lml)))
                .collect();
            format!(
                "{} {name} (LML {}), against {}",
                role.name(),
                lml(chosen.and_then(|r| r.lml)),
                others.join(", ")
            )
        })
        .collect();
    if details {
        format!(
            "  kernels chosen by evidence (the exact GP's LML): {}\n",
            per_gp.join("; ")
        )
    } else {
        format!("  kernels chosen by evidence: {}\n", per_gp.join(", "))
    }
}

/// The validation table of filter-aware training (`hbn train`, `hbn inspect`): per mode the
/// learned noise scales and the held-out scores before and after; empty without tuning.
pub fn validation_table(model: &hbn_model::HysteresisModel) -> String {
    let Some(v) = &model.summary().validation else {
        return "  filter not tuned (trained with --validation 0, or too little data): noise \
                scales 1, default mode ekf\n"
            .to_owned();
    };
    let scored = if v.searched > 0 && v.searched < v.samples {
        format!(
            "{} samples scored; the Q and R scales searched on {} of them",
            v.samples, v.searched
        )
    } else {
        format!("{} samples scored", v.samples)
    };
    let mut s = format!(
        "  filter tuned on held-out data ({}; {scored}):\n    {:<8} {:>8} {:>8} {:>9} \
         {:>17} {:>17} {:>17}\n",
        v.holdout,
        "mode",
        "Q scale",
        "R scale",
        "std scale",
        "nRMSE before/now",
        "in 2 sd before/now",
        "NLPD before/now"
    );
    for r in &v.rows {
        let star = if r.mode == v.default_mode { "*" } else { " " };
        s.push_str(&format!(
            "    {:<7}{star} {:>8.3} {:>8.3} {:>9.3} {:>8.4}/{:<8.4} {:>7.1}%/{:<8} {:>8.3}/{:<8.3}\n",
            r.mode.name(),
            r.scales.q,
            r.scales.r,
            r.scales.std,
            r.untuned.nrmse,
            r.tuned.nrmse,
            100.0 * r.untuned.calibration.coverage_2sigma,
            format!("{:.1}%", 100.0 * r.tuned.calibration.coverage_2sigma),
            r.untuned.calibration.nlpd,
            r.tuned.calibration.nlpd,
        ));
    }
    s.push_str(&format!(
        "    * default mode: {} (lowest held-out NLPD; `hbn estimate` uses it without --mode)\n",
        v.default_mode.name()
    ));
    s.push_str(&candidate_table(&v.candidates));
    s
}

/// The model-selection table (`--kernel a,b`, `--inducing exact,64`): per candidate its
/// default mode's tuned held-out scores; empty with one candidate.
fn candidate_table(rows: &[hbn_model::CandidateRow]) -> String {
    if rows.is_empty() {
        return String::new();
    }
    // The first column as wide as the longest name (with its `*`), at least 24.
    let w = rows
        .iter()
        .map(|r| r.candidate.to_string().chars().count() + 1)
        .max()
        .unwrap_or(0)
        .max(24);
    let mut s = format!(
        "  model selection, {} candidates on the same held-out data:\n    {:<w$} {:<8} {:>8} {:>8} \
         {:>8} {:>8} {:>5}\n",
        rows.len(),
        "candidate",
        "mode",
        "nRMSE",
        "in 2 sd",
        "NLPD",
        "seconds",
        "lost"
    );
    for r in rows {
        let star = if r.chosen { "*" } else { " " };
        let name = format!("{}{star}", r.candidate);
        match (&r.scored, &r.note) {
            (Some((mode, sc)), _) => s.push_str(&format!(
                "    {name:<w$} {:<8} {:>8.4} {:>7.1}% {:>8.3} {:>8} {:>5}\n",
                mode.name(),
                sc.nrmse,
                100.0 * sc.calibration.coverage_2sigma,
                sc.calibration.nlpd,
                // Not saved in model files: a loaded model has none.
                if r.seconds > 0.0 {
                    format!("{:.1}", r.seconds)
                } else {
                    "-".to_owned()
                },
                r.lost
            )),
            (None, note) => s.push_str(&format!(
                "    {name:<w$} not scored: {}\n",
                note.as_deref().unwrap_or("no held-out score")
            )),
        }
    }
    s.push_str(
        "    * chosen: the lowest held-out NLPD of its default mode among those with a held-out \
         nRMSE no higher than the first's, leaving out those whose filter lost the state on their \
         own training runs (lost: samples it re-started at) while another did not; the model is \
         that candidate's\n",
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every setting has a flag, and the flags of distinct settings are distinct (except the
    /// rate, which is one flag for the log grid and the model).
    #[test]
    fn every_setting_has_its_own_flag() {
        let mut seen = std::collections::BTreeMap::new();
        let settings = Param::ALL
            .iter()
            .map(|&p| Setting::Param(p))
            .chain(LogOption::ALL.iter().map(|&o| Setting::Log(o)));
        for s in settings {
            let f = flag(s);
            assert!(
                f.starts_with("--") || s == Setting::Param(Param::Blr),
                "{s:?}"
            );
            if let Some(prev) = seen.insert(f, s) {
                assert_eq!(f, "--rate", "{prev:?} and {s:?} share {f}");
            }
        }
    }
}
