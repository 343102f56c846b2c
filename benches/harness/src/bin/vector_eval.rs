//! The vector HBN against the best scalar HBN of each state component, on the multi-signal
//! simulators (`hbn_sim::MultiKind`): the benchmark behind the vector model's acceptance bar
//! (per component, nRMSE at most 0.8x the best scalar model's, 2-sigma coverage in
//! 0.90-0.98).
//!
//! ```text
//! vector_eval [--systems finger,arm] [--gains 0,1,10] [--seeds 1,2,3] \
//!     [--train-steps 3000] [--test-steps 2000] [--pick nrmse|nlpd] [--quick] [--out FILE] \
//!     [--floor-particles 2000] [--coverage-runs 0] [--scalar-cache DIR]
//! ```
//!
//! For each system, noise gain and seed:
//! - training run: `simulate_multi_random` with that seed and gain; test run: a fresh input and
//!   noise draw (seed `1000 + seed`). Nothing is scored on the training run.
//! - the vector model: `VectorModel::fit` with `HbnParams::default()`, estimating the test run
//!   in its default mode; per component the nRMSE (RMSE over the span of the true test
//!   component), the 2-sigma coverage and the mean NEES; the JSON names the candidate it
//!   kept (`vector_lags`, `vector_inducing`).
//! - the scalar models: `HysteresisModel::fit` with `HbnParams::default()` on every triple
//!   (input `a`, component `i`, sensor `j`) of the training run. The pair `(a, j)` of component
//!   `i` is chosen by the model's own held-out score on the training run (the tuned row of its
//!   default mode in `summary().validation`: nRMSE by default, NLPD with `--pick nlpd`), then
//!   scored on the test run. The oracle column is the pair with the lowest nRMSE on the test
//!   run itself: optimistic for the scalar side, since it picks on the data it is scored on.
//! - the floor: `hbn_sim::multi_posterior_estimate` on the test run (`--floor-particles`
//!   particles), the posterior mean given the inputs, the outputs and the simulator's own model.
//!   No causal estimator has a lower expected error, so where the floor's nRMSE is more than
//!   0.8x the scalar model's the bar lies below what any estimator can reach.
//! - with `--coverage-runs N`, the vector model's 2-sigma coverage on `N` more fresh test runs
//!   (seeds `COVERAGE_SEED_OFFSET + 100 s + r`): how much one test run's coverage varies for
//!   one trained model.
//!
//! Prints a Markdown report (machine, date, command line, one row per component, then the
//! geometric mean of the ratios per system and gain) on stdout, progress on stderr, and the
//! same with every pair's scores as JSON to `--out FILE`.
use clap::{Parser, ValueEnum};
use hbn_core::Mode;
use hbn_core::vector::Dims;
use hbn_harness::{parse, rows};
use hbn_model::metrics::{calibration, nrmse};
use hbn_model::{HbnParams, HysteresisModel, Sequence, VectorModel, VectorSequence};
use hbn_sim::{
    MultiConfig, MultiKind, MultiTrajectory, multi_posterior_estimate, simulate_multi_random,
};
use serde_json::{Value, json};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// The acceptance bar: vector nRMSE at most this times the best scalar model's.
const RATIO_BAR: f64 = 0.8;
/// The acceptance band of the 2-sigma coverage.
const COVERAGE_BAND: (f64, f64) = (0.90, 0.98);
/// Offset of the test run's seed from the training run's.
const TEST_SEED_OFFSET: u64 = 1000;
/// Offset of the seeds of the extra coverage runs (`--coverage-runs`).
const COVERAGE_SEED_OFFSET: u64 = 20_000;

/// The held-out score that chooses each component's scalar pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Pick {
    /// Held-out nRMSE of the pair's model (its default mode, tuned).
    Nrmse,
    /// Held-out NLPD of the pair's model (its default mode, tuned).
    Nlpd,
}

/// Vector HBN against the best scalar HBN per component (Markdown on stdout).
#[derive(Parser)]
struct Args {
    /// Systems (comma-separated: finger, arm).
    #[arg(long, value_delimiter = ',', default_value = "finger,arm", value_parser = parse::<MultiKind>)]
    systems: Vec<MultiKind>,
    /// Noise gains (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "0,1,10")]
    gains: Vec<f64>,
    /// Seeds of the training runs (comma-separated); the test run of seed `s` has seed `1000 + s`.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3")]
    seeds: Vec<u64>,
    /// Samples of each training run.
    #[arg(long, default_value_t = 3000)]
    train_steps: usize,
    /// Samples of each test run.
    #[arg(long, default_value_t = 2000)]
    test_steps: usize,
    /// Held-out score that chooses each component's scalar pair.
    #[arg(long, value_enum, default_value_t = Pick::Nrmse)]
    pick: Pick,
    /// One seed (the first of `--seeds`) and the gains 0 and 1.
    #[arg(long)]
    quick: bool,
    /// Also write the report as JSON to this file.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Keep each scalar pair's scores in this folder and reuse them when present (one file per
    /// system, gain, seed, run lengths and pair): the scalar side does not depend on the vector
    /// model, so a re-run after a change to the vector model refits only the vector model.
    /// Clear the folder when the scalar model or its defaults change.
    #[arg(long)]
    scalar_cache: Option<PathBuf>,
    /// Particles of the floor's particle filter on each test run (0: no floor). 2000 give the
    /// floor's nRMSE to about 1e-4 of 32000's on the arm at noise gain 10.
    #[arg(long, default_value_t = 2000)]
    floor_particles: usize,
    /// Also score the vector model's 2-sigma coverage on this many more fresh test runs.
    #[arg(long, default_value_t = 0)]
    coverage_runs: usize,
}

/// Geometric mean of the finite positive values (`NaN` when there are none).
fn geometric_mean(values: &[f64]) -> f64 {
    let logs: Vec<f64> = values
        .iter()
        .filter(|v| v.is_finite() && **v > 0.0)
        .map(|v| v.ln())
        .collect();
    if logs.is_empty() {
        f64::NAN
    } else {
        (logs.iter().sum::<f64>() / logs.len() as f64).exp()
    }
}

/// One scalar model: input `a`, component `i`, sensor `j`.
#[derive(Clone, Debug)]
struct PairResult {
    component: usize,
    input: usize,
    sensor: usize,
    seconds: f64,
    mode: Option<Mode>,
    /// Held-out nRMSE and NLPD of its default mode on the training run (`NaN` without).
    heldout_nrmse: f64,
    heldout_nlpd: f64,
    /// On the test run.
    test_nrmse: f64,
    test_coverage: f64,
    test_nees: f64,
    error: Option<String>,
}

impl PairResult {
    /// Reads a pair saved by [`PairResult::to_json`] (`None` when a field is missing).
    fn from_json(v: &Value) -> Option<Self> {
        let num = |k: &str| v[k].as_f64().unwrap_or(f64::NAN);
        let index = |k: &str| v[k].as_u64().and_then(|n| usize::try_from(n).ok());
        Some(Self {
            component: index("component")?,
            input: index("input")?,
            sensor: index("sensor")?,
            seconds: v["seconds"].as_f64()?,
            mode: v["mode"].as_str().and_then(|m| m.parse().ok()),
            heldout_nrmse: num("heldout_nrmse"),
            heldout_nlpd: num("heldout_nlpd"),
            test_nrmse: num("test_nrmse"),
            test_coverage: num("test_coverage_2sigma"),
            test_nees: num("test_mean_nees"),
            error: v["error"].as_str().map(str::to_string),
        })
    }

    fn score(&self, pick: Pick) -> f64 {
        match pick {
            Pick::Nrmse => self.heldout_nrmse,
            Pick::Nlpd => self.heldout_nlpd,
        }
    }

    fn label(&self) -> String {
        format!("u{},y{}", self.input, self.sensor)
    }

    fn to_json(&self) -> Value {
        json!({
            "component": self.component,
            "input": self.input,
            "sensor": self.sensor,
            "seconds": self.seconds,
            "mode": self.mode.map(|m| m.to_string()),
            "heldout_nrmse": finite(self.heldout_nrmse),
            "heldout_nlpd": finite(self.heldout_nlpd),
            "test_nrmse": finite(self.test_nrmse),
            "test_coverage_2sigma": finite(self.test_coverage),
            "test_mean_nees": finite(self.test_nees),
            "error": self.error,
        })
    }
}

/// A float for JSON (`null` when not finite).
fn finite(v: f64) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

/// One component of one case.
#[derive(Clone, Debug)]
struct ComponentResult {
    component: usize,
    vector_nrmse: f64,
    vector_coverage: f64,
    vector_nees: f64,
    vector_unobservable: f64,
    /// nRMSE of the posterior mean under the simulator's own model (`NaN` without a floor).
    floor_nrmse: f64,
    /// The vector model's 2-sigma coverage on each extra fresh test run (`--coverage-runs`).
    extra_coverage: Vec<f64>,
    /// Index into the case's pairs: the held-out choice and the oracle.
    chosen: Option<usize>,
    oracle: Option<usize>,
}

/// One system, gain and seed.
struct CaseResult {
    system: MultiKind,
    gain: f64,
    seed: u64,
    vector_seconds: f64,
    vector_mode: Mode,
    /// The candidate the vector model kept: its lag set and inducing setting.
    vector_lags: Vec<f64>,
    vector_inducing: Option<usize>,
    vector_warnings: Vec<String>,
    /// The vector model's held-out table (`VectorSummary::validation`) as JSON rows.
    vector_validation: Vec<Value>,
    scalar_seconds: f64,
    /// Scalar pairs read from `--scalar-cache` (their seconds are those of the original fit).
    scalar_cached: usize,
    components: Vec<ComponentResult>,
    pairs: Vec<PairResult>,
}

impl CaseResult {
    fn ratio(&self, c: &ComponentResult, pair: Option<usize>) -> f64 {
        pair.and_then(|p| self.pairs.get(p))
            .map_or(f64::NAN, |p| c.vector_nrmse / p.test_nrmse)
    }

    fn pair_nrmse(&self, pair: Option<usize>) -> f64 {
        pair.and_then(|p| self.pairs.get(p))
            .map_or(f64::NAN, |p| p.test_nrmse)
    }

    /// The floor's nRMSE over the held-out scalar choice's: the lowest ratio any causal
    /// estimator can reach in expectation.
    fn floor_ratio(&self, c: &ComponentResult) -> f64 {
        c.floor_nrmse / self.pair_nrmse(c.chosen)
    }
}

/// The training and test runs of one case.
fn runs(
    system: MultiKind,
    gain: f64,
    seed: u64,
    args: &Args,
) -> Result<(MultiTrajectory, MultiTrajectory), hbn_sim::SimError> {
    let cfg = MultiConfig {
        noise_gain: gain,
        seed,
        ..MultiConfig::new(system)
    };
    let train = simulate_multi_random(&cfg, args.train_steps)?;
    let test = simulate_multi_random(
        &MultiConfig {
            seed: TEST_SEED_OFFSET + seed,
            ..cfg
        },
        args.test_steps,
    )?;
    Ok((train, test))
}

/// Fits, estimates and scores one scalar pair.
fn scalar_pair(
    train: &MultiTrajectory,
    test: &MultiTrajectory,
    (a, i, j): (usize, usize, usize),
    params: &HbnParams,
) -> PairResult {
    let mut r = PairResult {
        component: i,
        input: a,
        sensor: j,
        seconds: 0.0,
        mode: None,
        heldout_nrmse: f64::NAN,
        heldout_nlpd: f64::NAN,
        test_nrmse: f64::NAN,
        test_coverage: f64::NAN,
        test_nees: f64::NAN,
        error: None,
    };
    let t0 = Instant::now();
    let fitted = HysteresisModel::fit(
        &[Sequence::new(&train.u[a], &train.x[i], &train.y[j])],
        params,
    );
    r.seconds = t0.elapsed().as_secs_f64();
    let model = match fitted {
        Ok(m) => m,
        Err(e) => {
            r.error = Some(format!("fit: {e}"));
            return r;
        }
    };
    let mode = model.default_mode();
    r.mode = Some(mode);
    if let Some(row) = model
        .summary()
        .validation
        .as_ref()
        .and_then(|v| v.rows.iter().find(|row| row.mode == mode))
    {
        r.heldout_nrmse = row.tuned.nrmse;
        r.heldout_nlpd = row.tuned.calibration.nlpd;
    }
    match model.estimate(&test.u[a], &test.y[j], mode) {
        Ok(e) => {
            r.test_nrmse = nrmse(&e.x, &test.x[i]);
            let c = calibration(&e.x, &e.x_std, &test.x[i]);
            r.test_coverage = c.coverage_2sigma;
            r.test_nees = c.mean_nees;
        }
        Err(e) => r.error = Some(format!("estimate: {e}")),
    }
    r
}

/// Index of the pair of component `i` with the lowest `key` (finite values only).
fn argmin(pairs: &[PairResult], i: usize, key: impl Fn(&PairResult) -> f64) -> Option<usize> {
    pairs
        .iter()
        .enumerate()
        .filter(|(_, p)| p.component == i && key(p).is_finite())
        .min_by(|(_, p), (_, q)| key(p).total_cmp(&key(q)))
        .map(|(k, _)| k)
}

/// Runs one case: the vector model, every scalar pair, the choices.
fn run_case(
    system: MultiKind,
    gain: f64,
    seed: u64,
    args: &Args,
) -> Result<CaseResult, Box<dyn std::error::Error>> {
    let (train, test) = runs(system, gain, seed, args)?;
    let floor = if args.floor_particles > 0 {
        let t0 = Instant::now();
        let config = MultiConfig {
            noise_gain: gain,
            seed: TEST_SEED_OFFSET + seed,
            ..MultiConfig::new(system)
        };
        let post = multi_posterior_estimate(&config, &test.u, &test.y, args.floor_particles, seed)?;
        eprintln!(
            "  floor: {:.1} s, {} particles, fewest effective {:.0}",
            t0.elapsed().as_secs_f64(),
            args.floor_particles,
            post.min_effective_particles
        );
        Some(post.mean)
    } else {
        None
    };
    let dims = Dims::new(system.inputs(), system.states(), system.sensors())?;
    let params = HbnParams::default();

    let (u, x, y) = (rows(&train.u), rows(&train.x), rows(&train.y));
    let t0 = Instant::now();
    let model = VectorModel::fit(&[VectorSequence::new(&u, &x, &y, dims)], &params)?;
    let vector_seconds = t0.elapsed().as_secs_f64();
    let mode = model.default_mode();
    let est = model.estimate(&rows(&test.u), &rows(&test.y), mode)?;
    eprintln!(
        "  vector: {vector_seconds:.1} s, mode {mode}, lags {:?}, inducing {:?}, warnings {:?}",
        model.lags(),
        model.params().n_inducing,
        model.summary().warnings
    );
    let validation: Vec<Value> = model
        .summary()
        .validation
        .iter()
        .map(|row| {
            eprintln!(
                "    held out{} {}: NLPD {:.3}, nRMSE {:?}",
                if row.chosen { " (kept)" } else { "" },
                row.what,
                row.nlpd,
                row.nrmse
                    .iter()
                    .map(|v| (v * 1e4).round() / 1e4)
                    .collect::<Vec<_>>()
            );
            json!({
                "what": row.what,
                "nlpd": finite(row.nlpd),
                "nrmse": row.nrmse.iter().map(|v| finite(*v)).collect::<Vec<_>>(),
                "chosen": row.chosen,
            })
        })
        .collect();
    let mut components: Vec<ComponentResult> = (0..dims.states)
        .map(|i| {
            let (xi, si) = (est.component(i), est.component_std(i));
            let c = calibration(&xi, &si, &test.x[i]);
            ComponentResult {
                component: i,
                vector_nrmse: nrmse(&xi, &test.x[i]),
                vector_coverage: c.coverage_2sigma,
                vector_nees: c.mean_nees,
                vector_unobservable: est.unobservable.get(i).copied().unwrap_or(f64::NAN),
                floor_nrmse: floor
                    .as_ref()
                    .and_then(|f| f.get(i))
                    .map_or(f64::NAN, |m| nrmse(m, &test.x[i])),
                extra_coverage: Vec::new(),
                chosen: None,
                oracle: None,
            }
        })
        .collect();

    for r in 0..args.coverage_runs as u64 {
        let run = simulate_multi_random(
            &MultiConfig {
                noise_gain: gain,
                seed: COVERAGE_SEED_OFFSET + 100 * seed + r,
                ..MultiConfig::new(system)
            },
            args.test_steps,
        )?;
        let e = model.estimate(&rows(&run.u), &rows(&run.y), mode)?;
        for c in &mut components {
            let i = c.component;
            let cal = calibration(&e.component(i), &e.component_std(i), &run.x[i]);
            c.extra_coverage.push(cal.coverage_2sigma);
        }
    }

    let mut pairs = Vec::new();
    let mut cached = 0;
    for i in 0..dims.states {
        for a in 0..dims.inputs {
            for j in 0..dims.sensors {
                let file = args.scalar_cache.as_ref().map(|dir| {
                    dir.join(format!(
                        "{system}-gain{gain}-seed{seed}-train{}-test{}-u{a}-x{i}-y{j}.json",
                        args.train_steps, args.test_steps
                    ))
                });
                let saved = file
                    .as_ref()
                    .and_then(|f| std::fs::read_to_string(f).ok())
                    .and_then(|t| serde_json::from_str::<Value>(&t).ok())
                    .and_then(|v| PairResult::from_json(&v));
                let p = match saved {
                    Some(p) => {
                        cached += 1;
                        p
                    }
                    None => {
                        let p = scalar_pair(&train, &test, (a, i, j), &params);
                        if let Some(f) = &file {
                            std::fs::create_dir_all(f.parent().unwrap_or(f))?;
                            std::fs::write(f, serde_json::to_string_pretty(&p.to_json())?)?;
                        }
                        p
                    }
                };
                eprintln!(
                    "  scalar x{i} <- (u{a}, y{j}): {:.1} s, held-out nRMSE {:.4} NLPD {:.3}, test nRMSE {:.4}{}",
                    p.seconds,
                    p.heldout_nrmse,
                    p.heldout_nlpd,
                    p.test_nrmse,
                    p.error
                        .as_deref()
                        .map(|e| format!(" ({e})"))
                        .unwrap_or_default()
                );
                pairs.push(p);
            }
        }
    }
    for c in &mut components {
        // The held-out choice must have a test score to be compared; a pair that fails on
        // the test run after winning held out is reported as NaN rather than replaced.
        c.chosen = argmin(&pairs, c.component, |p| p.score(args.pick));
        c.oracle = argmin(&pairs, c.component, |p| p.test_nrmse);
    }
    Ok(CaseResult {
        system,
        gain,
        seed,
        vector_seconds,
        vector_mode: mode,
        vector_lags: model.lags().to_vec(),
        vector_inducing: model.params().n_inducing,
        vector_warnings: model.summary().warnings.clone(),
        vector_validation: validation,
        scalar_seconds: pairs.iter().map(|p| p.seconds).sum(),
        scalar_cached: cached,
        components,
        pairs,
    })
}

/// The output of a shell command, trimmed (empty when it cannot run).
fn command_output(program: &str, args: &[&str]) -> String {
    std::process::Command::new(program)
        .args(args)
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
        .unwrap_or_default()
}

/// The CPU's model name and the number of logical CPUs, from /proc/cpuinfo.
fn cpu() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let name = info
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split(':').nth(1))
        .map_or("unknown", str::trim)
        .to_string();
    let count = info.lines().filter(|l| l.starts_with("processor")).count();
    format!("{name} ({count} logical CPUs)")
}

/// `v` with 4 decimals, or `-`.
fn f4(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.4}")
    } else {
        "-".into()
    }
}

/// `v` with 2 decimals, or `-`.
fn f2(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.2}")
    } else {
        "-".into()
    }
}

/// `v` with 3 decimals, or `-`.
fn f3(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3}")
    } else {
        "-".into()
    }
}

/// Whether the vector model meets the bar in one component (ratio against the held-out
/// choice, and coverage).
fn passes(ratio: f64, coverage: f64) -> (bool, bool) {
    (
        ratio.is_finite() && ratio <= RATIO_BAR,
        (COVERAGE_BAND.0..=COVERAGE_BAND.1).contains(&coverage),
    )
}

/// The Markdown rows of one case (one per component).
fn case_rows(case: &CaseResult) -> String {
    let mut s = String::new();
    for c in &case.components {
        let label = |p: Option<usize>| {
            p.and_then(|p| case.pairs.get(p))
                .map_or("-".to_string(), PairResult::label)
        };
        let ratio = case.ratio(c, c.chosen);
        let (ok_ratio, ok_cov) = passes(ratio, c.vector_coverage);
        let _ = writeln!(
            s,
            "| {} | {} | {} | x{} | {} | {} ({}) | {}{} | {} ({}) | {} | {} | {}{} | {}{} | {} | {:.1} / {:.1} |",
            case.system,
            case.gain,
            case.seed,
            c.component,
            f4(c.vector_nrmse),
            f4(case.pair_nrmse(c.chosen)),
            label(c.chosen),
            f2(ratio),
            if ok_ratio { "" } else { " !" },
            f4(case.pair_nrmse(c.oracle)),
            label(c.oracle),
            f2(case.ratio(c, c.oracle)),
            f4(c.floor_nrmse),
            f2(case.floor_ratio(c)),
            if case.floor_ratio(c) > RATIO_BAR {
                " !"
            } else {
                ""
            },
            f3(c.vector_coverage),
            if ok_cov { "" } else { " !" },
            f2(c.vector_nees),
            case.vector_seconds,
            case.scalar_seconds,
        );
    }
    s
}

/// The Markdown report of `cases`.
fn markdown(header: &[(String, String)], cases: &[CaseResult], pick: Pick) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Vector HBN against the best scalar HBN per component\n"
    );
    for (k, v) in header {
        let _ = writeln!(s, "- {k}: {v}");
    }
    let pick_name = match pick {
        Pick::Nrmse => "held-out nRMSE",
        Pick::Nlpd => "held-out NLPD",
    };
    let _ = writeln!(
        s,
        "\nScalar pair (input, sensor) of each component chosen by the scalar model's own {pick_name} \
         on the training run (`held-out`); `oracle` is the pair with the lowest nRMSE on the test \
         run itself (optimistic for the scalar side). Ratio = vector nRMSE / scalar nRMSE; the \
         bar is ratio <= {RATIO_BAR} against the held-out choice and 2-sigma coverage in \
         [{}, {}] (`!` marks a miss). Floor: the posterior mean under the simulator's own model \
         (a particle filter on the test run), which no causal estimator beats in expectation; \
         floor ratio = floor nRMSE / held-out scalar nRMSE, the lowest ratio reachable (`!` where \
         it exceeds the bar). Time: training seconds, vector / all scalar pairs of the case.\n",
        COVERAGE_BAND.0, COVERAGE_BAND.1
    );
    let _ = writeln!(
        s,
        "| system | gain | seed | comp. | vector nRMSE | held-out scalar nRMSE (pair) | ratio | oracle scalar nRMSE (pair) | ratio | floor nRMSE | floor ratio | vector cov. 2σ | vector NEES | time vector / scalar (s) |"
    );
    let _ = writeln!(
        s,
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    );
    for case in cases {
        s.push_str(&case_rows(case));
    }
    if cases
        .iter()
        .any(|c| c.components.iter().any(|k| !k.extra_coverage.is_empty()))
    {
        let _ = writeln!(
            s,
            "\nThe vector model's 2-sigma coverage on more fresh test runs (one trained model per \
             row; runs outside [{}, {}] counted):\n\n| system | gain | seed | comp. | runs | mean | sd | min | max | outside |\n|---|---|---|---|---|---|---|---|---|---|",
            COVERAGE_BAND.0, COVERAGE_BAND.1
        );
        for case in cases {
            for c in &case.components {
                let v = &c.extra_coverage;
                if v.is_empty() {
                    continue;
                }
                let n = v.len() as f64;
                let mean = v.iter().sum::<f64>() / n;
                let sd = (v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / n).sqrt();
                let (lo, hi) = v
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                        (l.min(x), h.max(x))
                    });
                let outside = v.iter().filter(|x| !passes(0.0, **x).1).count();
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | x{} | {} | {} | {} | {} | {} | {} |",
                    case.system,
                    case.gain,
                    case.seed,
                    c.component,
                    v.len(),
                    f3(mean),
                    f3(sd),
                    f3(lo),
                    f3(hi),
                    outside
                );
            }
        }
    }
    let _ = writeln!(
        s,
        "\n| system | gain | components x seeds | geo. mean ratio (held-out) | geo. mean ratio (oracle) | cells over the ratio bar | cells whose floor is over the bar | cells outside the coverage band |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|");
    for g in groups(cases) {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            g.system,
            g.gain,
            g.cells,
            f3(g.geo_heldout),
            f3(g.geo_oracle),
            g.ratio_misses,
            g.floor_over_bar,
            g.coverage_misses
        );
    }
    s
}

/// The summary of one system and gain over seeds and components.
struct Group {
    system: MultiKind,
    gain: f64,
    cells: usize,
    geo_heldout: f64,
    geo_oracle: f64,
    ratio_misses: usize,
    /// Cells where even the floor is over the ratio bar.
    floor_over_bar: usize,
    coverage_misses: usize,
}

/// The summary of each system and gain, in the order first run.
fn groups(cases: &[CaseResult]) -> Vec<Group> {
    let mut keys: Vec<(MultiKind, f64)> = Vec::new();
    for c in cases {
        if !keys.contains(&(c.system, c.gain)) {
            keys.push((c.system, c.gain));
        }
    }
    keys.into_iter()
        .map(|(system, gain)| {
            let mut held = Vec::new();
            let mut oracle = Vec::new();
            let (mut ratio_misses, mut coverage_misses, mut floor_over_bar) = (0, 0, 0);
            for case in cases
                .iter()
                .filter(|c| c.system == system && c.gain == gain)
            {
                for c in &case.components {
                    let r = case.ratio(c, c.chosen);
                    held.push(r);
                    oracle.push(case.ratio(c, c.oracle));
                    let (ok_ratio, ok_cov) = passes(r, c.vector_coverage);
                    ratio_misses += usize::from(!ok_ratio);
                    coverage_misses += usize::from(!ok_cov);
                    floor_over_bar += usize::from(case.floor_ratio(c) > RATIO_BAR);
                }
            }
            Group {
                system,
                gain,
                cells: held.len(),
                geo_heldout: geometric_mean(&held),
                geo_oracle: geometric_mean(&oracle),
                ratio_misses,
                floor_over_bar,
                coverage_misses,
            }
        })
        .collect()
}

/// The JSON report of `cases`.
fn to_json(header: &[(String, String)], cases: &[CaseResult], pick: Pick) -> Value {
    let header: serde_json::Map<String, Value> =
        header.iter().map(|(k, v)| (k.clone(), json!(v))).collect();
    let case_values: Vec<Value> = cases
        .iter()
        .map(|case| {
            let components: Vec<Value> = case
                .components
                .iter()
                .map(|c| {
                    let pair = |p: Option<usize>| p.and_then(|p| case.pairs.get(p));
                    json!({
                        "component": c.component,
                        "vector_nrmse": finite(c.vector_nrmse),
                        "vector_coverage_2sigma": finite(c.vector_coverage),
                        "vector_mean_nees": finite(c.vector_nees),
                        "vector_unobservable": finite(c.vector_unobservable),
                        "heldout_pair": pair(c.chosen).map(|p| [p.input, p.sensor]),
                        "heldout_scalar_nrmse": finite(case.pair_nrmse(c.chosen)),
                        "heldout_ratio": finite(case.ratio(c, c.chosen)),
                        "oracle_pair": pair(c.oracle).map(|p| [p.input, p.sensor]),
                        "oracle_scalar_nrmse": finite(case.pair_nrmse(c.oracle)),
                        "oracle_ratio": finite(case.ratio(c, c.oracle)),
                        "floor_nrmse": finite(c.floor_nrmse),
                        "floor_ratio": finite(case.floor_ratio(c)),
                        "extra_coverage_2sigma": c.extra_coverage.iter().map(|v| finite(*v)).collect::<Vec<_>>(),
                    })
                })
                .collect();
            json!({
                "system": case.system.name(),
                "gain": case.gain,
                "seed": case.seed,
                "vector_seconds": case.vector_seconds,
                "vector_mode": case.vector_mode.to_string(),
                "vector_lags": case.vector_lags,
                "vector_inducing": case.vector_inducing,
                "vector_warnings": case.vector_warnings,
                "vector_validation": case.vector_validation,
                "scalar_seconds_total": case.scalar_seconds,
                "scalar_pairs_cached": case.scalar_cached,
                "components": components,
                "pairs": case.pairs.iter().map(PairResult::to_json).collect::<Vec<_>>(),
            })
        })
        .collect();
    let summary: Vec<Value> = groups(cases)
        .iter()
        .map(|g| {
            json!({
                "system": g.system.name(),
                "gain": g.gain,
                "cells": g.cells,
                "geo_mean_ratio_heldout": finite(g.geo_heldout),
                "geo_mean_ratio_oracle": finite(g.geo_oracle),
                "ratio_misses": g.ratio_misses,
                "floor_over_bar": g.floor_over_bar,
                "coverage_misses": g.coverage_misses,
            })
        })
        .collect();
    json!({
        "header": header,
        "pick": format!("{pick:?}").to_lowercase(),
        "ratio_bar": RATIO_BAR,
        "coverage_band": [COVERAGE_BAND.0, COVERAGE_BAND.1],
        "cases": case_values,
        "summary": summary,
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = Args::parse();
    if args.quick {
        args.seeds.truncate(1);
        args.gains = vec![0.0, 1.0];
    }
    let started = Instant::now();
    let header = vec![
        ("machine".to_string(), command_output("uname", &["-a"])),
        ("cpu".to_string(), cpu()),
        (
            "date".to_string(),
            command_output("date", &["-u", "+%Y-%m-%dT%H:%M:%SZ"]),
        ),
        (
            "command".to_string(),
            std::env::args().collect::<Vec<_>>().join(" "),
        ),
        (
            "runs".to_string(),
            format!(
                "training {} samples (seed s), test {} samples (seed {TEST_SEED_OFFSET} + s), HbnParams::default()",
                args.train_steps, args.test_steps
            ),
        ),
    ];
    let mut cases = Vec::new();
    let mut failures = Vec::new();
    for &system in &args.systems {
        for &gain in &args.gains {
            for &seed in &args.seeds {
                eprintln!("{system}, gain {gain}, seed {seed}:");
                let t0 = Instant::now();
                match run_case(system, gain, seed, &args) {
                    Ok(c) => {
                        eprint!("{}", case_rows(&c));
                        cases.push(c);
                        // The JSON so far, so that a run stopped early leaves its finished cases.
                        if let Some(path) = &args.out {
                            let mut partial = header.clone();
                            partial.push(("finished".to_string(), "no: cases so far".to_string()));
                            std::fs::write(
                                path,
                                serde_json::to_string_pretty(&to_json(
                                    &partial, &cases, args.pick,
                                ))?,
                            )?;
                        }
                    }
                    Err(e) => {
                        eprintln!("  failed: {e}");
                        failures.push(format!("{system}, gain {gain}, seed {seed}: {e}"));
                    }
                }
                eprintln!("  case: {:.1} s", t0.elapsed().as_secs_f64());
            }
        }
    }
    let mut header = header;
    header.push((
        "wall time".to_string(),
        format!("{:.0} s", started.elapsed().as_secs_f64()),
    ));
    let cached: usize = cases.iter().map(|c| c.scalar_cached).sum();
    if cached > 0 {
        header.push((
            "scalar pairs read from --scalar-cache".to_string(),
            format!(
                "{cached} of {} (their seconds are those of the run that fitted them)",
                cases.iter().map(|c| c.pairs.len()).sum::<usize>()
            ),
        ));
    }
    if !failures.is_empty() {
        header.push(("failed cases".to_string(), failures.join("; ")));
    }
    print!("{}", markdown(&header, &cases, args.pick));
    if let Some(path) = &args.out {
        std::fs::write(
            path,
            serde_json::to_string_pretty(&to_json(&header, &cases, args.pick))?,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_interleave_component_major_signals() {
        assert_eq!(
            rows(&[vec![1.0, 2.0, 3.0], vec![10.0, 20.0, 30.0]]),
            vec![1.0, 10.0, 2.0, 20.0, 3.0, 30.0]
        );
        assert!(rows(&[]).is_empty());
    }

    #[test]
    fn geometric_mean_skips_values_that_are_not_positive_and_finite() {
        assert!((geometric_mean(&[0.5, 2.0]) - 1.0).abs() < 1e-12);
        assert!((geometric_mean(&[4.0, f64::NAN, 1.0, 0.0]) - 2.0).abs() < 1e-12);
        assert!(geometric_mean(&[f64::NAN]).is_nan());
    }

    fn pair(component: usize, input: usize, heldout: f64, test: f64) -> PairResult {
        PairResult {
            component,
            input,
            sensor: 0,
            seconds: 0.0,
            mode: None,
            heldout_nrmse: heldout,
            heldout_nlpd: -heldout,
            test_nrmse: test,
            test_coverage: f64::NAN,
            test_nees: f64::NAN,
            error: None,
        }
    }

    #[test]
    fn the_held_out_choice_ignores_the_test_run_and_the_oracle_uses_it() {
        let pairs = vec![
            pair(0, 0, 0.10, 0.30),
            pair(0, 1, 0.20, 0.05),
            pair(1, 0, 0.01, 0.01),
            pair(0, 2, f64::NAN, 0.01),
        ];
        assert_eq!(argmin(&pairs, 0, |p| p.score(Pick::Nrmse)), Some(0));
        assert_eq!(argmin(&pairs, 0, |p| p.score(Pick::Nlpd)), Some(1));
        assert_eq!(argmin(&pairs, 0, |p| p.test_nrmse), Some(3));
        assert_eq!(argmin(&pairs, 2, |p| p.test_nrmse), None);
    }

    #[test]
    fn a_pair_round_trips_through_its_json() {
        let mut p = pair(1, 2, 0.1, 0.2);
        p.mode = Some(Mode::Ukf);
        p.error = Some("estimate: diverged".into());
        let back = PairResult::from_json(&p.to_json()).map(|b| b.to_json());
        assert_eq!(back, Some(p.to_json()));
        assert!(PairResult::from_json(&json!({"component": 0})).is_none());
    }

    #[test]
    fn the_bar_needs_both_the_ratio_and_the_coverage() {
        assert_eq!(passes(0.8, 0.95), (true, true));
        assert_eq!(passes(0.81, 0.95), (false, true));
        assert_eq!(passes(0.5, 0.89), (true, false));
        assert_eq!(passes(f64::NAN, 0.99), (false, false));
    }
}
