//! # hbn-cli — the `hbn` command
//!
//! Train, estimate and evaluate Hysteresis Bayesian Network models from MCAP logs without
//! writing code. The binary is a thin wrapper over [`run`]; tests call [`run_with`] to capture
//! stdout and notices.
//!
//! The commands are thin shells over `hbn-pipeline` (reading logs, training, estimating,
//! writing outputs): this crate parses flags into the library's parameter types (whose
//! defaults it shows), renders the library's events and errors with flag names, and plots.
//! Every output file is written with hbn-fs's atomic writer, so a failing command leaves no
//! partial output behind.
#![forbid(unsafe_code)]
#![cfg_attr(
    not(test),
    deny(clippy::unwrap_used, clippy::expect_used, clippy::panic)
)]

pub mod cli;
pub mod cmd_demo;
pub mod cmd_estimate;
pub mod cmd_eval;
pub mod cmd_experiment;
pub mod cmd_explore;
pub mod cmd_export;
pub mod cmd_inspect;
pub mod cmd_simulate;
pub mod cmd_train;
pub mod glossary;
pub mod plot;
pub mod progress;
pub mod report;

use std::ffi::OsString;
use std::io::Write;
use std::path::Path;

use anyhow::{Context, bail};
use clap::Parser;

pub use anyhow;
pub use cli::{Cli, Command};

/// Where a command prints: summaries to `out`, notices to `err` (suppressed by `--quiet`).
pub struct Ui<'a> {
    /// `--quiet`: no progress bars, no notices.
    pub quiet: bool,
    /// `--verbose`: details after the summary.
    pub verbose: bool,
    out: &'a mut dyn Write,
    err: &'a mut dyn Write,
}

impl<'a> Ui<'a> {
    /// A console printing to the given writers (neither quiet nor verbose).
    pub fn new(quiet: bool, out: &'a mut dyn Write, err: &'a mut dyn Write) -> Self {
        Ui {
            quiet,
            verbose: false,
            out,
            err,
        }
    }

    /// The same console, verbose or not.
    pub fn with_verbose(mut self, verbose: bool) -> Self {
        self.verbose = verbose;
        self
    }

    /// Prints a notice (`note: ...`) to stderr unless quiet.
    pub fn notice(&mut self, msg: impl std::fmt::Display) {
        if !self.quiet {
            // A closed stderr must not turn into an error of the command.
            let _ = writeln!(self.err, "note: {msg}");
        }
    }

    /// Prints a warning (`warning: ...`) to stderr, even when quiet: something the user should
    /// act on.
    pub fn warn(&mut self, msg: impl std::fmt::Display) {
        // A closed stderr must not turn into an error of the command.
        let _ = writeln!(self.err, "warning: {msg}");
    }

    /// Prints summary text to stdout.
    pub fn print(&mut self, text: impl std::fmt::Display) -> anyhow::Result<()> {
        write!(self.out, "{text}").context("cannot write to stdout")?;
        self.out.flush().context("cannot write to stdout")
    }

    /// Prints one summary line to stdout.
    pub fn line(&mut self, text: impl std::fmt::Display) -> anyhow::Result<()> {
        self.print(format_args!("{text}\n"))
    }
}

/// Parses `args` (the first is the program name) and runs the command, printing to the
/// process's stdout and stderr. `--help` and `--version` print and return `Ok`.
pub fn run<I, T>(args: I) -> anyhow::Result<()>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let mut out = std::io::stdout().lock();
    let mut err = std::io::stderr();
    run_with(args, &mut out, &mut err)
}

/// [`run`], printing summaries to `out` and notices to `err`.
pub fn run_with<I, T>(args: I, out: &mut dyn Write, err: &mut dyn Write) -> anyhow::Result<()>
where
    I: IntoIterator<Item = T>,
    T: Into<OsString> + Clone,
{
    let cli = match Cli::try_parse_from(args) {
        Ok(c) => c,
        Err(e) => {
            use clap::error::ErrorKind;
            return match e.kind() {
                // Bare `hbn` (no subcommand) prints the help too, but as a usage error
                // (exit 2), like any other command line that does nothing.
                ErrorKind::DisplayHelp | ErrorKind::DisplayVersion => {
                    write!(out, "{}", e.render()).context("cannot write to stdout")?;
                    Ok(())
                }
                _ => Err(anyhow::Error::new(e)),
            };
        }
    };
    let mut ui = Ui::new(cli.quiet, out, err).with_verbose(cli.verbose);
    execute(&mut ui, cli.command)
}

/// Runs one parsed command.
pub fn execute(ui: &mut Ui<'_>, command: Command) -> anyhow::Result<()> {
    let ui = &mut *ui;
    match command {
        Command::Simulate(a) => cmd_simulate::run(ui, &a),
        Command::Train(a) => cmd_train::run(ui, &a).map(|_| ()),
        Command::Estimate(a) => cmd_estimate::run(ui, &a).map(|_| ()),
        Command::Eval(a) => cmd_eval::run(ui, &a).map(|_| ()),
        Command::Inspect(a) => cmd_inspect::run(ui, &a),
        Command::Export(a) => cmd_export::run(ui, &a),
        Command::Explore(a) => cmd_explore::run(ui, &a).map(|_| ()),
        Command::Demo(a) => cmd_demo::run(ui, &a),
        Command::Experiment(a) => cmd_experiment::run(ui, &a).map(|_| ()),
    }
}

/// Prints an error of [`run`] to stderr and returns the process exit code: 0 for `Ok`, 2 for
/// usage errors (clap's message), 1 for everything else (`error: ` and the context chain).
pub fn main_exit_code(result: anyhow::Result<()>) -> i32 {
    match result {
        Ok(()) => 0,
        Err(e) => {
            if let Some(c) = e.downcast_ref::<clap::Error>() {
                eprint!("{}", c.render());
                2
            } else {
                eprintln!("error: {}", error_message(&e));
                1
            }
        }
    }
}

/// The error and its causes on one line, each said once: a cause whose text its parent's
/// message already contains (library errors often name their source in their own message) is
/// skipped.
pub fn error_message(e: &anyhow::Error) -> String {
    let mut parts: Vec<String> = Vec::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if text.is_empty() || parts.iter().any(|p| p.contains(&text)) {
            continue;
        }
        parts.push(text);
    }
    parts.join(": ")
}

/// Fails early (before any long computation) when `file` cannot be created: its directory
/// does not exist or `file` is a directory.
pub fn check_output(file: &Path, what: &str) -> anyhow::Result<()> {
    if file.as_os_str().is_empty() {
        bail!("the {what} path is empty");
    }
    if file.is_dir() {
        bail!(
            "the {what} path `{}` is a directory; give a file name",
            file.display()
        );
    }
    let dir = match file.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !dir.is_dir() {
        bail!(
            "cannot write the {what} `{}`: directory `{}` does not exist; create it first",
            file.display(),
            dir.display()
        );
    }
    Ok(())
}
