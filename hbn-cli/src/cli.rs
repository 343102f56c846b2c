//! Command-line definitions (clap derive).

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use hbn_core::Mode;
use hbn_gp::SubsetPolicy;
use hbn_io::{SignalPath, TimeSource};
use hbn_model::{HbnParams, KernelChoice, LinearMean, SensorInputs};
use hbn_pipeline::LogOptions;
use hbn_sim::{MultiKind, SimConfig, SystemKind};

// Every default below is read from the library's parameter types (`HbnParams::default`,
// `LogOptions::default`, `Mode::default`, `SimConfig::new`); none is written here.
fn params() -> HbnParams {
    HbnParams::default()
}

fn log_options() -> LogOptions {
    LogOptions::default()
}

fn experiment() -> hbn_pipeline::experiment::ExperimentConfig {
    hbn_pipeline::experiment::ExperimentConfig::default()
}

/// Gaussian-process models of hysteretic soft-robot systems and a real-time EKF.
///
/// Train a model of actuator input u -> state x -> soft-sensor output y from MCAP logs
/// (ROS 2 or Foxglove SDK), then estimate x from u and y alone, and evaluate the estimate.
/// Signals are Foxglove message paths: `/topic.field.sub`, `[i]` indices, and quoted topics
/// with dots (`"/a.b".data`).
#[derive(Debug, Parser)]
#[command(
    name = "hbn",
    version,
    propagate_version = true,
    after_help = "Start here:\n  hbn demo --out hbn-demo\n\nTypical workflow:\n  hbn train --log run1.mcap --log run2.mcap --out model.hbn\n  hbn estimate --model model.hbn --log test.mcap --out est.mcap\n  hbn eval --model model.hbn --log test.mcap --plot eval.png"
)]
pub struct Cli {
    /// Suppress progress bars and notices (summaries still go to stdout).
    #[arg(short, long, global = true)]
    pub quiet: bool,

    /// Print details after the summary: GP hyperparameters and the held-out table of
    /// `train`, filter diagnostics of `estimate`, all calibration columns of `eval` (terms
    /// explained in docs/glossary.md).
    #[arg(short, long, global = true)]
    pub verbose: bool,

    /// The subcommand.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Simulate a hysteretic system and write its u, x, y as an MCAP log.
    Simulate(SimulateArgs),
    /// Train a model from one or more MCAP logs (each log is one trajectory).
    Train(TrainArgs),
    /// Estimate the state x from the input u and sensor y of a log.
    Estimate(EstimateArgs),
    /// Evaluate a model on a log that also records the true state.
    Eval(EvalArgs),
    /// Show what a model file contains (signals, rate, kernels, hyperparameters, diagnostics).
    Inspect(InspectArgs),
    /// Export a model as firmware source: Rust tables for a no_std crate, or C for libhbn_ffi.
    Export(ExportArgs),
    /// Plan an input schedule that explores where the model is uncertain (thesis Sec. 3.4),
    /// for a robot that cannot run the Python explorer in its loop.
    Explore(ExploreArgs),
    /// Simulate, train, estimate and evaluate end to end in one directory (under a minute).
    Demo(DemoArgs),
    /// Run the thesis' simulation experiment (systems x noise gains x seeds).
    Experiment(ExperimentArgs),
}

/// Message encoding of simulated logs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum EncodingArg {
    /// Foxglove-style JSON messages with a JSON schema.
    Json,
    /// ROS 2 CDR messages with a ros2msg schema.
    Ros2,
}

/// Which clock samples are placed at.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TimeSourceArg {
    /// The MCAP log time (when the recorder received the message).
    Log,
    /// The message's `header.stamp`.
    Header,
}

impl From<TimeSource> for TimeSourceArg {
    fn from(t: TimeSource) -> Self {
        match t {
            TimeSource::LogTime => TimeSourceArg::Log,
            TimeSource::HeaderStamp => TimeSourceArg::Header,
        }
    }
}

impl From<TimeSourceArg> for TimeSource {
    fn from(t: TimeSourceArg) -> Self {
        match t {
            TimeSourceArg::Log => TimeSource::LogTime,
            TimeSourceArg::Header => TimeSource::HeaderStamp,
        }
    }
}

/// `--mode` of `hbn estimate` and `hbn eval`: one mode by its name ([`Mode::name`]) or `all`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ModeChoice {
    /// One mode.
    One(Mode),
    /// Every mode ([`Mode::ALL`]).
    All,
}

impl ModeChoice {
    /// The modes chosen, in the order of [`Mode::ALL`].
    pub fn modes(self) -> Vec<Mode> {
        match self {
            ModeChoice::One(m) => vec![m],
            ModeChoice::All => Mode::ALL.to_vec(),
        }
    }
}

impl std::fmt::Display for ModeChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ModeChoice::One(m) => f.write_str(m.name()),
            ModeChoice::All => f.write_str("all"),
        }
    }
}

impl std::str::FromStr for ModeChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s.trim().eq_ignore_ascii_case("all") {
            return Ok(ModeChoice::All);
        }
        s.parse::<Mode>()
            .map(ModeChoice::One)
            .map_err(|e| e.to_string())
    }
}

/// The values `--mode` accepts: every mode's name, then `all` (listed by `--help`).
fn mode_choice() -> impl clap::builder::TypedValueParser<Value = ModeChoice> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    let values = Mode::ALL
        .iter()
        .map(|m| PossibleValue::new(m.name()))
        .chain(std::iter::once(
            PossibleValue::new("all").help("every mode, one after the other"),
        ));
    PossibleValuesParser::new(values).try_map(|s: String| s.parse::<ModeChoice>())
}

/// How training reduces large data sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SubsetArg {
    /// Greedy farthest-point sampling (deterministic, covers the input space evenly).
    FarthestPoint,
    /// A random subset drawn with --seed.
    Random,
}

impl From<SubsetPolicy> for SubsetArg {
    fn from(p: SubsetPolicy) -> Self {
        match p {
            SubsetPolicy::FarthestPoint => SubsetArg::FarthestPoint,
            SubsetPolicy::Random => SubsetArg::Random,
        }
    }
}

impl From<SubsetArg> for SubsetPolicy {
    fn from(p: SubsetArg) -> Self {
        match p {
            SubsetArg::FarthestPoint => SubsetPolicy::FarthestPoint,
            SubsetArg::Random => SubsetPolicy::Random,
        }
    }
}

fn parse_system(s: &str) -> Result<SystemKind, String> {
    s.parse::<SystemKind>().map_err(|e| e.to_string())
}

fn parse_kernel(s: &str) -> Result<KernelChoice, String> {
    s.parse::<KernelChoice>().map_err(|e| e.to_string())
}

fn parse_path(s: &str) -> Result<SignalPath, String> {
    s.parse::<SignalPath>().map_err(|e| e.to_string())
}

fn parse_positive(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("expected a finite number > 0, got {s:?}")),
    }
}

/// `--memory`: radii of the transition's play operators as fractions of the input's range,
/// or none.
#[derive(Clone, Debug, PartialEq)]
pub struct Memory(pub Vec<f64>);

fn parse_memory(s: &str) -> Result<Memory, String> {
    number_list(
        s,
        |v| v > 0.0 && v <= 1.0,
        "fractions of the input's range in (0, 1]",
    )
    .map(Memory)
}

/// A comma-separated list of finite numbers that pass `ok`, or `none` (empty); `what` says
/// what they must be.
fn number_list(s: &str, ok: fn(f64) -> bool, what: &str) -> Result<Vec<f64>, String> {
    let t = s.trim();
    if t.eq_ignore_ascii_case("none") {
        return Ok(Vec::new());
    }
    t.split(',')
        .map(|r| match r.trim().parse::<f64>() {
            Ok(v) if v.is_finite() && ok(v) => Ok(v),
            _ => Err(format!(
                "expected {what}, comma-separated, or `none`; got {r:?}"
            )),
        })
        .collect()
}

impl std::fmt::Display for Memory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&memory_text(&self.0))
    }
}

/// `--lags`: time constants (seconds) of the transition's lags, or none.
#[derive(Clone, Debug, PartialEq)]
pub struct Lags(pub Vec<f64>);

/// The primary lag set and the alternatives model selection tries: the first given and the
/// rest, else the library's defaults (no lags, with [`hbn_model::DEFAULT_LAGS`] tried).
pub fn lags_choice(given: &[Lags]) -> (Vec<f64>, Vec<Vec<f64>>) {
    match given.split_first() {
        Some((first, rest)) => (first.0.clone(), rest.iter().map(|l| l.0.clone()).collect()),
        None => {
            let d = params();
            (d.lags, d.select.lags)
        }
    }
}

fn parse_lags(s: &str) -> Result<Lags, String> {
    number_list(s, |v| v > 0.0, "time constants in seconds (> 0)").map(Lags)
}

/// `--max-signal-variance`: a bound, or `none`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cap(pub Option<f64>);

impl std::fmt::Display for Cap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0 {
            Some(v) => write!(f, "{v}"),
            None => f.write_str("none"),
        }
    }
}

fn parse_cap(s: &str) -> Result<Cap, String> {
    if s.trim().eq_ignore_ascii_case("none") {
        return Ok(Cap(None));
    }
    s.trim()
        .parse::<f64>()
        .map(|v| Cap(Some(v)))
        .map_err(|_| format!("expected a number or `none`, got `{s}`"))
}

/// `--linear-mean`: which GPs have a linear prior mean.
fn parse_linear_mean(s: &str) -> Result<LinearMean, String> {
    s.parse()
}

fn memory_text(m: &[f64]) -> String {
    if m.is_empty() {
        "none".to_owned()
    } else {
        m.iter()
            .map(|r| r.to_string())
            .collect::<Vec<_>>()
            .join(",")
    }
}

/// `--inducing`: a count of inducing points (sparse GPs) or `exact`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Inducing(pub Option<usize>);

/// The primary inducing setting and the alternatives model selection tries: the first given
/// and the rest, else the library's defaults (exact GPs, with sparse GPs of
/// [`hbn_model::DEFAULT_INDUCING`] points as the alternative).
pub fn inducing_choice(given: &[Inducing]) -> (Option<usize>, Vec<Option<usize>>) {
    match given.split_first() {
        Some((first, rest)) => (first.0, rest.iter().map(|i| i.0).collect()),
        None => {
            let d = params();
            (d.n_inducing, d.select.inducing)
        }
    }
}

fn parse_inducing(s: &str) -> Result<Inducing, String> {
    let t = s.trim();
    if t.eq_ignore_ascii_case("exact") {
        return Ok(Inducing(None));
    }
    match t.parse::<usize>() {
        Ok(m) if m >= 1 => Ok(Inducing(Some(m))),
        _ => Err(format!(
            "expected a number of inducing points >= 1 or `exact`, got {s:?}"
        )),
    }
}

/// The primary sensor inputs and the alternatives model selection tries: the first given and
/// the rest, else the library's defaults (the thesis' sensor, with a sensor of the state only
/// tried).
pub fn sensor_inputs_choice(given: &[SensorInputs]) -> (SensorInputs, Vec<SensorInputs>) {
    match given.split_first() {
        Some((first, rest)) => (*first, rest.to_vec()),
        None => {
            let d = params();
            (d.sensor_inputs, d.select.sensor_inputs)
        }
    }
}

fn parse_sensor_inputs(s: &str) -> Result<SensorInputs, String> {
    s.parse()
}

fn parse_non_negative(s: &str) -> Result<f64, String> {
    match s.trim().parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("expected a finite number >= 0, got {s:?}")),
    }
}

/// The width of the name column in the lists of systems: the longest name of either list.
fn system_name_width() -> usize {
    SystemKind::ALL
        .iter()
        .map(|k| k.name().len())
        .chain(MultiKind::ALL.iter().map(|k| k.name().len()))
        .max()
        .unwrap_or(0)
}

fn systems_help() -> String {
    let width = system_name_width();
    SystemKind::ALL
        .iter()
        .map(|k| format!("  {:<width$} {}", k.name(), k.description()))
        .collect::<Vec<_>>()
        .join("\n")
}

/// A system `hbn simulate` runs: a scalar one (one input, state and sensor) or a
/// multi-signal one (several inputs, a vector state, several sensors).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimSystem {
    /// One input, one state, one sensor.
    Scalar(SystemKind),
    /// Several inputs, a vector state, several sensors.
    Multi(MultiKind),
}

impl SimSystem {
    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            SimSystem::Scalar(k) => k.name(),
            SimSystem::Multi(k) => k.name(),
        }
    }
}

impl std::fmt::Display for SimSystem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

fn parse_sim_system(s: &str) -> Result<SimSystem, String> {
    if let Ok(k) = s.parse::<SystemKind>() {
        return Ok(SimSystem::Scalar(k));
    }
    if let Ok(k) = s.parse::<MultiKind>() {
        return Ok(SimSystem::Multi(k));
    }
    let valid: Vec<&str> = SystemKind::ALL
        .iter()
        .map(|k| k.name())
        .chain(MultiKind::ALL.iter().map(|k| k.name()))
        .collect();
    Err(format!(
        "unknown system `{s}`; valid systems: {}",
        valid.join(", ")
    ))
}

fn multi_systems_help() -> String {
    let width = system_name_width();
    MultiKind::ALL
        .iter()
        .map(|k| format!("  {:<width$} {}", k.name(), k.description()))
        .collect::<Vec<_>>()
        .join("\n")
}

/// `hbn simulate`.
#[derive(Clone, Debug, Args)]
#[command(after_help = format!(
    "Systems:\n{}\n\nMulti-signal systems:\n{}\n\nExample:\n  \
     hbn simulate --system bouc-wen --steps 1000 --seed 1 --noise-gain 1 --out train1.mcap\n  \
     hbn simulate --system bouc-wen --steps 1000 --seed 2 --input-seed 1 --noise-gain 1 --out train2.mcap\n  \
     hbn simulate --system finger --steps 1000 --seed 1 --out finger.mcap\n\n\
     Topics /input, /state and /sensor carry {{header: {{stamp}}, data}}, so the signal paths are\n\
     /input.data, /state.data and /sensor.data (the defaults of `hbn train`).\n\n\
     A multi-signal system writes one topic per input, /input0, /input1, ..., and per sensor,\n\
     /sensor0, /sensor1, ... (field data), and one topic /state with a field per state\n\
     component: the paths are /input0.data, ..., /state.x0, /state.x1, ..., /sensor0.data, ...\n\
     Every input is its own random ramp (from --input-seed).\n\n\
     A slow camera: --state-rate 30 --state-drop 0.1 writes the state as a 30 Hz camera that\n\
     drops a tenth of its frames records it (the input and sensor stay at --rate):\n  \
     hbn simulate --system bouc-wen --steps 3000 --state-rate 30 --state-drop 0.1 --out cam.mcap",
    systems_help(),
    multi_systems_help()
))]
pub struct SimulateArgs {
    /// System to simulate: a scalar or a multi-signal system (see the lists below).
    #[arg(long, value_parser = parse_sim_system, default_value = "bouc-wen")]
    pub system: SimSystem,
    /// Number of samples.
    #[arg(long, default_value_t = 1000)]
    pub steps: usize,
    /// Seed of the measurement / process noise (and of the input unless --input-seed is given).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Noise gain (0 = noise-free, 1 = the thesis' nominal noise).
    #[arg(long, default_value_t = 1.0, value_parser = parse_non_negative)]
    pub noise_gain: f64,
    /// Seed of the random-ramp input (default: --seed). Reuse one input seed with different
    /// --seed values to record repeated-input training logs.
    #[arg(long)]
    pub input_seed: Option<u64>,
    /// Sample rate (Hz).
    #[arg(long, default_value_t = SimConfig::new(SystemKind::BoucWen).rate_hz, value_parser = parse_positive)]
    pub rate: f64,
    /// Message encoding.
    #[arg(long, value_enum, default_value_t = EncodingArg::Json)]
    pub encoding: EncodingArg,
    /// Largest input increment per sample.
    #[arg(long, default_value_t = hbn_sim::DEFAULT_MAX_INCREMENT, value_parser = parse_positive)]
    pub max_increment: f64,
    /// Rate of the state topic (Hz): a camera slower than the sensor, its frames at 1 s + j /
    /// HZ on its own clock, each the true state interpolated between the samples around it;
    /// at most --rate [default: --rate, the state at every sample]
    #[arg(long, value_name = "HZ", allow_negative_numbers = true, value_parser = parse_positive)]
    pub state_rate: Option<f64>,
    /// Share of the camera's frames dropped, each independently (seeded by --seed), in [0, 1);
    /// the first and last frames are kept, so the state spans the log.
    #[arg(long, value_name = "FRACTION", default_value_t = 0.0, allow_negative_numbers = true,
          value_parser = |s: &str| match s.trim().parse::<f64>() {
              Ok(v) if (0.0..1.0).contains(&v) => Ok(v),
              _ => Err(format!("expected a fraction in [0, 1), got {s:?}")),
          })]
    pub state_drop: f64,
    /// Output MCAP file.
    #[arg(long)]
    pub out: PathBuf,
}

/// Options shared by the commands that read logs.
#[derive(Clone, Debug, Args)]
pub struct ReadArgs {
    /// Clock to place samples at.
    #[arg(help_heading = "Data", long, value_enum, default_value_t = log_options().time_source.into())]
    pub time_source: TimeSourceArg,
    /// Largest allowed gap between two samples of a signal (seconds).
    #[arg(help_heading = "Data", long, allow_negative_numbers = true, default_value_t = log_options().max_gap_s)]
    pub max_gap: f64,
    /// Warn when a signal spans less than this fraction of its log (the grid covers only the
    /// span all signals share).
    #[arg(help_heading = "Data", long, allow_negative_numbers = true, default_value_t = log_options().min_coverage)]
    pub min_coverage: f64,
}

impl Default for ReadArgs {
    fn default() -> Self {
        let o = log_options();
        Self {
            time_source: o.time_source.into(),
            max_gap: o.max_gap_s,
            min_coverage: o.min_coverage,
        }
    }
}

impl ReadArgs {
    /// The library's log options with these values (and the grid rate, if given).
    pub fn options(&self, rate_hz: Option<f64>) -> LogOptions {
        LogOptions {
            time_source: self.time_source.into(),
            max_gap_s: self.max_gap,
            rate_hz,
            min_coverage: self.min_coverage,
            ..log_options()
        }
    }
}

/// Log reading options of the commands that read logs for a model (`estimate`, `eval`): each
/// defaults to what the model was trained with.
#[derive(Clone, Debug, Default, Args)]
pub struct ModelReadArgs {
    /// Clock to place samples at [default: the model's]
    #[arg(help_heading = "Data", long, value_enum)]
    pub time_source: Option<TimeSourceArg>,
    /// Largest allowed gap between two samples of a signal (seconds); the filter restarts after
    /// a longer one [default: the model's]
    #[arg(help_heading = "Data", long, allow_negative_numbers = true)]
    pub max_gap: Option<f64>,
    /// Warn when a signal spans less than this fraction of its log.
    #[arg(help_heading = "Data", long, allow_negative_numbers = true, default_value_t = log_options().min_coverage)]
    pub min_coverage: f64,
}

impl ModelReadArgs {
    /// The library's log options for `model`: these values where given, else the model's.
    pub fn options(&self, model: &hbn_model::HysteresisModel) -> LogOptions {
        LogOptions {
            min_coverage: self.min_coverage,
            ..hbn_pipeline::model_log_options(model, self.time_source.map(Into::into), self.max_gap)
        }
    }
}

/// `hbn train`.
#[derive(Clone, Debug, Args)]
#[command(
    after_help = "Example:\n  hbn train --log run1.mcap --log run2.mcap --input /valve.pressure \
     --state /mocap.angle --output /strain.data --out model.hbn\n\n\
     Each log is one trajectory; its signals are resampled to one rate (default: the native rate\n\
     of the input signal in the first log). Kernels: matern52, se-ard, se, thesis; default: each\n\
     GP chooses between matern52 and se-ard by its evidence (the exact GP's log marginal\n\
     likelihood). Every option: docs/options.md."
)]
pub struct TrainArgs {
    /// Training log (repeat for several trajectories).
    #[arg(help_heading = "Data", long = "log", required = true)]
    pub logs: Vec<PathBuf>,
    /// Input signal u; repeat for several inputs, in order (a vector model). Default
    /// `/input.data`, or in a log of `hbn simulate --system finger|arm` its `/input0.data`,
    /// `/input1.data`, ...
    #[arg(help_heading = "Data", long, action = clap::ArgAction::Append, value_parser = parse_path)]
    pub input: Vec<SignalPath>,
    /// State signal x (the reference the model learns); repeat for a state of several
    /// components, in order. Default `/state.data`, or `/state.x0`, `/state.x1`, ... in a
    /// simulated multi-signal log.
    #[arg(help_heading = "Data", long, action = clap::ArgAction::Append, value_parser = parse_path)]
    pub state: Vec<SignalPath>,
    /// Sensor output signal y; repeat for several sensors, in order. Default `/sensor.data`,
    /// or `/sensor0.data`, `/sensor1.data`, ... in a simulated multi-signal log.
    #[arg(help_heading = "Data", long, action = clap::ArgAction::Append, value_parser = parse_path)]
    pub output: Vec<SignalPath>,
    /// Resampling rate (Hz); default: the input's native rate in the first log.
    #[arg(help_heading = "Data", long, allow_negative_numbers = true)]
    pub rate: Option<f64>,
    /// Fewest samples of the state, over all logs, where all signals overlap: fewer is an
    /// error (the state is what the model learns from).
    #[arg(help_heading = "Data", long, default_value_t = log_options().min_state_samples)]
    pub min_state_samples: usize,
    /// Kernel of both GPs. Default: each GP chooses between matern52 and se-ard by its
    /// evidence (the exact GP's log marginal likelihood); naming a kernel turns that off.
    /// Several, comma-separated, are chosen among on held-out data (model selection; each
    /// costs one training).
    #[arg(help_heading = "Model", long, value_parser = parse_kernel, value_delimiter = ',', value_name = "KERNEL[,..]")]
    pub kernel: Vec<KernelChoice>,
    /// Kernel of the transition GP (overrides --kernel; turns the choice by evidence off).
    #[arg(help_heading = "Model", long, value_parser = parse_kernel)]
    pub transition_kernel: Option<KernelChoice>,
    /// Kernel of the sensor GP (overrides --kernel; turns the choice by evidence off).
    #[arg(help_heading = "Model", long, value_parser = parse_kernel)]
    pub sensor_kernel: Option<KernelChoice>,
    /// Inducing points per GP for sparse GPs trained on every sample, or `exact`: exact GPs on
    /// at most --max-points samples each. Several, comma-separated (`exact,64,128`), are
    /// chosen among on held-out data, with every --kernel. Default `exact,64`: the held-out
    /// data choose (docs/sparse.md); with --validation 0, exact.
    #[arg(help_heading = "Model", long, value_parser = parse_inducing, value_delimiter = ',', value_name = "M|exact[,..]")]
    pub inducing: Vec<Inducing>,
    /// Most support points per exact GP (with --inducing exact).
    #[arg(help_heading = "Model", long, default_value_t = params().max_points)]
    pub max_points: usize,
    /// How to choose the support points when a log has more samples.
    #[arg(help_heading = "Training", long = "subset-policy", alias = "subset", value_enum, default_value_t = params().subset_policy.into())]
    pub subset: SubsetArg,
    /// Optimiser starts per GP.
    #[arg(help_heading = "Training", long, default_value_t = params().n_starts)]
    pub starts: usize,
    /// L-BFGS iterations per start.
    #[arg(help_heading = "Training", long, default_value_t = params().max_iters)]
    pub max_iters: u64,
    /// Seed of random starts and subsets.
    #[arg(help_heading = "Training", long, default_value_t = params().seed)]
    pub seed: u64,
    /// Lower bound of each GP's noise variance (standardised units).
    #[arg(help_heading = "Training", long, allow_negative_numbers = true, default_value_t = params().noise_floor)]
    pub noise_floor: f64,
    /// Do not standardise GP inputs and outputs.
    #[arg(help_heading = "Training", long, default_value_t = !params().normalize)]
    pub no_normalize: bool,
    /// BLR window as a fraction of each coordinate's range.
    #[arg(help_heading = "Model", long, allow_negative_numbers = true, default_value_t = params().blr_window)]
    pub blr_window: f64,
    /// Fraction of every log held out at a time to learn the filter's noise scales and default
    /// mode (blocked cross-validation: 0.25 holds out each quarter of every log in turn);
    /// 0 turns filter tuning off.
    #[arg(help_heading = "Training", long, allow_negative_numbers = true, default_value_t = params().validation)]
    pub validation: f64,
    /// The input's long memory: radii of play operators (backlashes) whose outputs the
    /// transition GP reads besides u_{k-1} and u_{k-2}, as fractions of the input's range,
    /// comma-separated (at most 4), or `none` for the thesis' four inputs. docs/memory.md.
    #[arg(help_heading = "Model", long, value_parser = parse_memory, default_value_t = Memory(params().memory), value_name = "R[,..]|none")]
    pub memory: Memory,
    /// The input's recent past: time constants in seconds of first-order low-pass filters
    /// (lags) of u whose outputs the transition GP reads after the plays, comma-separated
    /// (plays and lags at most 4 in all), or `none`. For creep and viscoelastic relaxation
    /// (soft actuators). Given more than once, the first is the primary set and the others
    /// are tried on held-out data with the sparse candidates (default: `none`, with `1` tried;
    /// a vector model tries `0.1` and `1`; `--lags none` alone trains without lags and tries
    /// none). docs/memory.md.
    #[arg(help_heading = "Model", long, value_parser = parse_lags, value_name = "TAU[,..]|none")]
    pub lags: Vec<Lags>,
    /// Which GPs have a linear prior mean (the targets' least-squares plane on the GP's inputs,
    /// the kernel modelling the rest): `none`, `transition` or `both`. On the sensor GP it can
    /// cost observability. docs/sparse.md.
    #[arg(help_heading = "Model", long, value_parser = parse_linear_mean, default_value_t = params().linear_mean, value_name = "none|transition|both")]
    pub linear_mean: LinearMean,
    /// What the sensor GP reads: `thesis` ([x_{k-1}, y_{k-1}, x_k]), `memory` (x_k and two play
    /// operators of the state, the history a hysteretic sensor depends on) or `state`
    /// ([x_{k-1}, x_k]); several, comma-separated, are chosen among on held-out data, the
    /// first being the primary one (default `thesis,memory`; `--sensor-inputs thesis` alone
    /// tries no other). Vector models take `thesis` or `state`. docs/memory.md.
    #[arg(help_heading = "Model", long, value_parser = parse_sensor_inputs, value_delimiter = ',', value_name = "thesis|memory|state[,..]")]
    pub sensor_inputs: Vec<SensorInputs>,
    /// Largest signal variance of both GPs, as a multiple of the variance of what each kernel
    /// models, or `none` for only the 1e5 box: keeps a near-linear fit from extrapolating like
    /// a polynomial. docs/sparse.md.
    #[arg(help_heading = "Model", long, value_parser = parse_cap, default_value_t = Cap(params().max_signal_variance), value_name = "V|none")]
    pub max_signal_variance: Cap,
    /// Train what fits this much firmware flash (the f32 export's tables), e.g. `16KB`, `64KB`,
    /// `1MB` or bytes: sparse GPs with the most inducing points (64 down to 8) that fit, a
    /// thinned initial-state table, and a default mode that fits. Scalar models only.
    /// docs/firmware.md.
    #[arg(help_heading = "Model", long, value_parser = hbn_model::parse_bytes, value_name = "SIZE")]
    pub firmware_budget: Option<u64>,
    /// Log reading options.
    #[command(flatten)]
    pub read: ReadArgs,
    /// Output model file.
    #[arg(help_heading = "Output", long)]
    pub out: PathBuf,
    /// Print the summary as JSON (what `hbn inspect --json` prints, with the training run's
    /// samples and time).
    #[arg(help_heading = "Output", long)]
    pub json: bool,
}

/// `hbn estimate`.
#[derive(Clone, Debug, Args)]
#[command(
    after_help = "Example:\n  hbn estimate --model model.hbn --log test.mcap --out est.mcap --csv est.csv\n  \
     hbn estimate --model model.hbn --log test.mcap --mode all --csv est.csv\n\n\
     The MCAP output has one JSON channel /hbn/estimate (x, x_std, y_pred, innovation, nis,\n\
     flags, flag_names) on the input log's clock: open it in Foxglove beside the input log.\n\
     CSV columns: t,u,y,x,x_std,y_pred,innovation,nis,flags,flag_names (t in seconds from the\n\
     first sample; u and y the input and sensor samples the filter ran on, on the model's grid:\n\
     fed to an f64 firmware export they give the same x bit for bit, docs/firmware.md; flags\n\
     as a bit mask and as names joined by |). With --mode all, each mode is written to its own\n\
     files, the mode's name added to the file name: est-ekf.csv, est-ekf-blr.csv, ...\n\
     Terms: docs/glossary.md."
)]
pub struct EstimateArgs {
    /// Model file from `hbn train`.
    #[arg(long)]
    pub model: PathBuf,
    /// Log with the input and sensor signals.
    #[arg(long)]
    pub log: PathBuf,
    /// Estimation mode, or `all` for every mode (default: the model's, the mode with the best
    /// held-out score at training; see `hbn inspect`).
    #[arg(long, value_parser = mode_choice())]
    pub mode: Option<ModeChoice>,
    /// Input signal (default: the path the model was trained with); repeat for each input of
    /// a vector model, in the model's order.
    #[arg(long, action = clap::ArgAction::Append, value_parser = parse_path)]
    pub input: Vec<SignalPath>,
    /// Sensor signal (default: the path the model was trained with); repeat for each sensor
    /// of a vector model, in the model's order.
    #[arg(long, action = clap::ArgAction::Append, value_parser = parse_path)]
    pub output: Vec<SignalPath>,
    /// With a vector model, add the state covariance's off-diagonals to the CSV
    /// (`cov_x0_x1`, ...).
    #[arg(long)]
    pub covariance: bool,
    /// Write the estimate as an MCAP log.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write the estimate as CSV.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Smooth: estimate each sample from the whole log (the filter forward, then a
    /// Rauch-Tung-Striebel pass backward) instead of from the samples up to it. x and x_std
    /// (and a vector model's covariances) in the outputs are the smoothed ones, the other
    /// columns the filter's. Offline; docs/smoothing.md.
    #[arg(long)]
    pub smooth: bool,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
    /// Log reading options.
    #[command(flatten)]
    pub read: ModelReadArgs,
}

/// `hbn eval`.
#[derive(Clone, Debug, Args)]
#[command(
    after_help = "Example:\n  hbn eval --model model.hbn --log test.mcap --plot eval.png\n  \
     hbn eval --model model.hbn --log test.mcap --mode ekf --json\n  \
     hbn eval --model model.hbn --log test1.mcap --log test2.mcap --log test3.mcap\n\n\
     Scores RMSE and nRMSE (RMSE / range of the reference) of each filter mode and of the\n\
     open-loop GP simulation against the logged state, and how often the state lies within 2\n\
     standard deviations of the estimate (about 95% when the uncertainty is honest); --verbose\n\
     adds the 1-sd coverage, mean NEES and NLPD. Terms: docs/glossary.md."
)]
pub struct EvalArgs {
    /// Model file from `hbn train`.
    #[arg(long)]
    pub model: PathBuf,
    /// Log with input, state (reference) and sensor signals; repeat to score several logs,
    /// each on its own and then all pooled sample by sample (a band is judged better on
    /// several logs with different inputs than on one).
    #[arg(long, action = clap::ArgAction::Append, required = true)]
    pub log: Vec<PathBuf>,
    /// Mode to evaluate, or `all`.
    #[arg(long, value_parser = mode_choice(), default_value_t = ModeChoice::All)]
    pub mode: ModeChoice,
    /// Input signal (default: the model's); repeat for each input of a vector model, in order.
    #[arg(long, action = clap::ArgAction::Append, value_parser = parse_path)]
    pub input: Vec<SignalPath>,
    /// Reference state signal (default: the model's); repeat for each component of a vector
    /// model, in order.
    #[arg(long, action = clap::ArgAction::Append, value_parser = parse_path)]
    pub state: Vec<SignalPath>,
    /// Sensor signal (default: the model's); repeat for each sensor of a vector model.
    #[arg(long, action = clap::ArgAction::Append, value_parser = parse_path)]
    pub output: Vec<SignalPath>,
    /// Write a PNG plot: per mode the estimate with its 2-sigma band against the logged state
    /// (nRMSE and 2-sigma coverage in the legend), and the hysteresis loops (one `--log`
    /// only).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Also score each mode's smoothed estimate (each sample estimated from the whole log): a
    /// row `<mode> smoothed` after the mode's; docs/smoothing.md.
    #[arg(long)]
    pub smooth: bool,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Log reading options.
    #[command(flatten)]
    pub read: ModelReadArgs,
}

/// `hbn inspect`.
#[derive(Clone, Debug, Args)]
#[command(after_help = "Example:\n  hbn inspect model.hbn\n  hbn inspect model.hbn --json")]
pub struct InspectArgs {
    /// Model file.
    pub model: PathBuf,
    /// Print JSON.
    #[arg(long)]
    pub json: bool,
}

/// Source language of `hbn export`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    /// hbn_model.rs: static arrays and `hbn_model()`, to `include!` in a no_std crate.
    Rust,
    /// hbn_model.h and hbn_model.c: const arrays and `hbn_model` for the C ABI (hbn.h).
    C,
}

/// Precision of the exported real numbers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PrecisionArg {
    /// double: the estimates equal `hbn estimate` bit for bit.
    F64,
    /// float: half the model data, estimates within a few tenths of a percent (docs/firmware.md).
    F32,
}

/// `hbn export`.
#[derive(Clone, Debug, Args)]
#[command(
    after_help = "Examples:\n  hbn export --model model.hbn --out fw --format c --precision f32\n  \
     make -C examples/firmware-c MODEL=$PWD/fw\n  hbn export --model model.hbn --out fw-rs --format rust\n\n\
     Writes hbn_model.h and hbn_model.c (--format c) or hbn_model.rs (--format rust) into --out\n\
     (created if missing; nothing is written if the export fails) and prints the size report:\n\
     bytes of model data (flash) and work memory (RAM) per mode. See docs/firmware.md."
)]
pub struct ExportArgs {
    /// Model file from `hbn train`.
    #[arg(long)]
    pub model: PathBuf,
    /// Output directory (created if missing).
    #[arg(long)]
    pub out: PathBuf,
    /// Source language.
    #[arg(long, value_enum)]
    pub format: FormatArg,
    /// Precision of the exported real numbers.
    #[arg(long, value_enum, default_value = "f64")]
    pub precision: PrecisionArg,
    /// Estimation mode built into the export (default: the model's). EKF+BLR also exports the
    /// training samples its local regression reads.
    #[arg(long, value_parser = mode_value())]
    pub mode: Option<Mode>,
    /// Keep at most N of the training (y, x) pairs the prior of x_0 reads (default: all, and
    /// the export reproduces `hbn estimate` exactly). Fewer pairs shrink the model data (8
    /// bytes a pair in f32) and change only the first estimates; 0 drops the prior (the filter
    /// starts from the training mean).
    #[arg(long, value_name = "N")]
    pub init_pairs: Option<usize>,
}

fn explore() -> hbn_model::explore::ExploreParams {
    // The bounds have no default (they come from the logs); only the schedule's defaults are read.
    hbn_model::explore::ExploreParams::new(0.0, 1.0, 0.02)
}

/// `hbn explore`.
#[derive(Clone, Debug, Args)]
#[command(
    after_help = "Example:\n  hbn train --log batch1.mcap --out model.hbn\n  \
     hbn explore --model model.hbn --log batch1.mcap --samples 3000 --out plan.csv --out plan.mcap\n\n\
     Plans --samples inputs at the model's rate that continue the last --log, as ramps: each\n\
     goes to a target level at a constant slope (at most --max-step per sample); with\n\
     probability a the next ramp is the one along which the model's transition GP is most\n\
     uncertain (over its first --horizon samples), else a random one, a growing from\n\
     --alpha-start to --alpha-end over --alpha-ramp samples (--strategy steps: the thesis'\n\
     per-sample rule u += a*eps + (1-a)*w). The states along the\n\
     plan are the model's predictions, so the plan spreads out as if they had been measured.\n\
     Every input lies in [--u-min, --u-max] and differs from the previous one by at most\n\
     --max-step (defaults: the range and the largest step of u in the logs).\n\
     Output: CSV (t,u,x_pred; t in seconds from the first planned sample) for a file ending in\n\
     .csv, else MCAP with topics /explore/u and /explore/x_pred (field data). Apply the plan,\n\
     record u, x and y, and train on all logs. With Python in the loop, hbn.Explorer refits as\n\
     data arrive (docs/exploration.md)."
)]
pub struct ExploreArgs {
    /// Model file from `hbn train` on the first batch.
    #[arg(long)]
    pub model: PathBuf,
    /// Logs of the first batch (repeat the flag); the plan continues the last one.
    #[arg(long = "log", required = true)]
    pub logs: Vec<PathBuf>,
    /// Samples to plan (at the model's rate).
    #[arg(long)]
    pub samples: usize,
    /// Output file: `.csv` for CSV, anything else for MCAP (repeat for both).
    #[arg(long = "out", required = true)]
    pub outs: Vec<PathBuf>,
    /// Lowest input (default: the lowest u in the logs).
    #[arg(long, allow_negative_numbers = true)]
    pub u_min: Option<f64>,
    /// Highest input (default: the highest u in the logs).
    #[arg(long, allow_negative_numbers = true)]
    pub u_max: Option<f64>,
    /// Largest change of the input per sample (default: the largest in the logs).
    #[arg(long)]
    pub max_step: Option<f64>,
    /// Weight of the uncertainty-seeking step at the start of the plan.
    #[arg(help_heading = "Advanced", long, default_value_t = explore().alpha_start)]
    pub alpha_start: f64,
    /// Weight of the uncertainty-seeking step at the end of the ramp.
    #[arg(help_heading = "Advanced", long, default_value_t = explore().alpha_end)]
    pub alpha_end: f64,
    /// Samples over which the weight grows from --alpha-start to --alpha-end.
    #[arg(help_heading = "Advanced", long, default_value_t = explore().alpha_ramp)]
    pub alpha_ramp: usize,
    /// Refit the transition GP on the planned samples every N samples.
    #[arg(help_heading = "Advanced", long, default_value_t = explore().refit_every, value_name = "N")]
    pub refit_every: usize,
    /// Candidate steps evaluated per sample (--strategy steps).
    #[arg(help_heading = "Advanced", long, default_value_t = explore().candidates)]
    pub candidates: usize,
    /// Random ramps drawn per uncertainty-seeking choice; the best by --criterion is
    /// followed (--strategy ramps). More seeks harder (docs/exploration.md).
    #[arg(help_heading = "Advanced", long, default_value_t = explore().pool, value_name = "N")]
    pub pool: usize,
    /// Look-ahead (samples) of the uncertainty search: a candidate ramp is scored over its
    /// first N samples.
    #[arg(help_heading = "Advanced", long, default_value_t = explore().horizon, value_name = "N")]
    pub horizon: usize,
    /// How the input moves: `ramps` (to a target level at a constant slope; the next ramp
    /// seeks uncertainty with probability a) or `steps` (the thesis' per-sample rule).
    #[arg(help_heading = "Advanced", long, default_value_t = explore().strategy.name().to_owned(),
          value_parser = ["ramps", "steps"])]
    pub strategy: String,
    /// How a seeking choice of --strategy ramps scores the pool: `reduction` (the ramp whose
    /// samples would lower the transition GP's variance most, summed over where all the pool's
    /// ramps go) or `variance` (the ramp along which it is most uncertain).
    #[arg(help_heading = "Advanced", long, default_value_t = explore().criterion.name().to_owned(),
          value_parser = ["reduction", "variance"])]
    pub criterion: String,
    /// Seed of the random steps.
    #[arg(long, default_value_t = explore().seed)]
    pub seed: u64,
    /// Input signal (default: the path the model was trained with).
    #[arg(long, value_parser = parse_path)]
    pub input: Option<SignalPath>,
    /// State signal (default: the path the model was trained with).
    #[arg(long, value_parser = parse_path)]
    pub state: Option<SignalPath>,
    /// Sensor signal (default: the path the model was trained with).
    #[arg(long, value_parser = parse_path)]
    pub output: Option<SignalPath>,
    /// Log reading options.
    #[command(flatten)]
    pub read: ReadArgs,
}

fn mode_value() -> impl clap::builder::TypedValueParser<Value = Mode> {
    use clap::builder::{PossibleValuesParser, TypedValueParser};
    PossibleValuesParser::new(Mode::ALL.map(|m| m.name())).try_map(|s: String| s.parse::<Mode>())
}

/// `hbn demo`.
#[derive(Clone, Debug, Args)]
#[command(after_help = format!(
    "Example:\n  hbn demo --out hbn-demo --system bouc-wen\n\n\
     Runs the README's worked example in the --out directory, printing each command before it\n\
     runs: three training logs with the same input (--input-seed SEED) and independent noise\n\
     (--seed 10*SEED+1, +2, +3), a test log with a new input (--input-seed SEED+1,\n\
     --seed 10*(SEED+1)+1), hbn train with the default options, hbn estimate in the model's\n\
     default mode and hbn eval of every mode. Writes train1..3.mcap, test.mcap, model.hbn,\n\
     est.csv, est.mcap and eval.png.\n\nSystems:\n{}",
    systems_help()
))]
pub struct DemoArgs {
    /// Output directory (created if missing).
    #[arg(long, default_value = "hbn-demo")]
    pub out: PathBuf,
    /// System to simulate.
    #[arg(long, value_parser = parse_system, default_value = "bouc-wen")]
    pub system: SystemKind,
    /// Noise gain.
    #[arg(long, default_value_t = 1.0, value_parser = parse_non_negative)]
    pub noise_gain: f64,
    /// Seed (the input seed of the training logs; see below).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

impl Default for DemoArgs {
    fn default() -> Self {
        Self {
            out: PathBuf::from("hbn-demo"),
            system: SystemKind::BoucWen,
            noise_gain: 1.0,
            seed: 1,
        }
    }
}

/// `hbn experiment`.
#[derive(Clone, Debug, Args)]
#[command(
    after_help = "Example:\n  hbn experiment --systems maxwell-slip,generalized-pi --gains 0,0.5,1 --seeds 1,2,3 \
     --json results.json --plot results.png\n\n\
     Per case: train on --repeats noisy copies of one --train-steps input, test on a fresh\n\
     --test-steps input; prints mean nRMSE per (system, gain) as a Markdown table."
)]
pub struct ExperimentArgs {
    /// Systems (comma-separated).
    #[arg(long, value_delimiter = ',', value_parser = parse_system,
          default_values_t = experiment().systems)]
    pub systems: Vec<SystemKind>,
    /// Noise gains (comma-separated).
    #[arg(long, value_delimiter = ',', value_parser = parse_non_negative,
          default_values_t = experiment().noise_gains)]
    pub gains: Vec<f64>,
    /// Seeds (comma-separated), one run each.
    #[arg(long, value_delimiter = ',', default_values_t = experiment().seeds)]
    pub seeds: Vec<u64>,
    /// Samples of the training input.
    #[arg(long, default_value_t = experiment().train_steps)]
    pub train_steps: usize,
    /// Repetitions of the training input (fresh noise each).
    #[arg(long, default_value_t = experiment().repeats)]
    pub repeats: usize,
    /// Samples of the test input.
    #[arg(long, default_value_t = experiment().test_steps)]
    pub test_steps: usize,
    /// Inducing points per GP (sparse GPs on every sample), or `exact`; several,
    /// comma-separated, are chosen among on held-out data (default `exact,64`, as hbn train).
    #[arg(long, value_parser = parse_inducing, value_delimiter = ',', value_name = "M|exact[,..]")]
    pub inducing: Vec<Inducing>,
    /// Most support points per GP.
    #[arg(long, default_value_t = params().max_points)]
    pub max_points: usize,
    /// Play operators' radii as fractions of the input's range, or `none` (as `hbn train`).
    #[arg(long, value_parser = parse_memory, default_value_t = Memory(params().memory), value_name = "R[,..]|none")]
    pub memory: Memory,
    /// Lags' time constants in seconds, or `none`; repeat to choose on held-out data (as `hbn
    /// train`).
    #[arg(long, value_parser = parse_lags, value_name = "TAU[,..]|none")]
    pub lags: Vec<Lags>,
    /// Which GPs have a linear prior mean: `none`, `transition` or `both` (as `hbn train`).
    #[arg(long, value_parser = parse_linear_mean, default_value_t = params().linear_mean, value_name = "none|transition|both")]
    pub linear_mean: LinearMean,
    /// What the sensor GP reads, `thesis`, `memory` or `state`; several are chosen among on
    /// held-out data (as `hbn train`).
    #[arg(long, value_parser = parse_sensor_inputs, value_delimiter = ',', value_name = "thesis|memory|state[,..]")]
    pub sensor_inputs: Vec<SensorInputs>,
    /// Write all rows as JSON.
    #[arg(long)]
    pub json: Option<PathBuf>,
    /// Write a PNG plot of nRMSE vs noise gain.
    #[arg(long)]
    pub plot: Option<PathBuf>,
}
