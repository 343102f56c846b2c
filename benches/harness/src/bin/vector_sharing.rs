//! Independent against shared hyperparameters for the GPs of a vector model that read the
//! same inputs: the transition GPs (one per state component) and, with `--gps sensors`, the
//! sensors' state-only GPs (one per sensor, all on `[x_{k-1}, x_k]`).
//!
//! ```text
//! vector_sharing [--systems finger,arm] [--gains 0,1,10] [--seeds 1,2,3] \
//!     [--train-steps 3000] [--test-steps 2000] [--gps transitions,sensors] \
//!     [--ties length-scales,all] [--quick] [--out FILE]
//! ```
//!
//! For each system, noise gain and seed:
//! - training run: `simulate_multi_random` with that seed and gain; test run: a fresh input and
//!   noise draw (seed `1000 + seed`). Rows by `hbn_model::vector::transition_rows` (and
//!   `sensor_rows`), with the default memory operators.
//! - independent: each component's GP fitted by `hbn_gp::fit` with the `GpParams` the vector
//!   model builds from `HbnParams::default()` (kernel, subset size, starts, iterations, seed,
//!   noise floor), its hyperparameters optimised alone.
//! - shared: one set of hyperparameters maximising the sum of the components' log marginal
//!   likelihoods, each component on its own standardised targets and the support subset its
//!   independent fit chose (the same for every component: the subset depends on the inputs
//!   only). Two ties: `length-scales` (one length scale per input for all components; each
//!   keeps its own signal variance and noise) and `all` (length scales, signal variance and
//!   noise, in standardised units: every component gets the same signal-to-noise ratio and
//!   the same variance relative to its targets). L-BFGS (argmin, More-Thuente line search) from
//!   the default start, from the mean of the independent optima and from each component's
//!   own optimum, tied; the best is kept. Each component's GP is then fitted with those
//!   hyperparameters fixed (`optimize = false`, `init`).
//! - scores on the test run's rows, per component: one-step predictive NLPD (the GP's latent
//!   variance plus its noise) and RMSE; fitting seconds (the shared side's: the whole search
//!   and the fixed fits, and the default start alone with the fixed fits).
//!
//! Prints a Markdown report (machine, command line, one row per component, then per system,
//! gain, GP family and tie the difference shared - independent over seeds) on stdout,
//! progress on stderr, and every number as JSON to `--out FILE`.
use argmin::core::{CostFunction, Executor, Gradient, State};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::quasinewton::LBFGS;
use clap::{Parser, ValueEnum};
use hbn_core::vector::Dims;
use hbn_core::{KernelSpec, Plays, Want};
use hbn_gp::likelihood::{Likelihood, LikelihoodData, noise_of, param_of_noise};
use hbn_gp::{GaussianProcess, GpError, GpParams, Hyperparameters, SparseParams};
use hbn_harness::{parse, rows};
use hbn_model::vector::{sensor_rows, transition_rows};
use hbn_model::{GpRole, HbnParams, VectorSequence};
use hbn_sim::{MultiConfig, MultiKind, MultiTrajectory, simulate_multi_random};
use serde_json::{Value, json};
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

/// Offset of the test run's seed from the training run's.
const TEST_SEED_OFFSET: u64 = 1000;
/// Cost the optimiser sees where the summed likelihood cannot be evaluated (as in hbn-gp).
const FAILED_COST: f64 = 1e150;
/// The cost tolerance of the exact GP's optimiser in hbn-gp (nats per iteration).
const COST_TOLERANCE: f64 = 1e-5;
/// L-BFGS memory and gradient tolerance of hbn-gp's optimiser.
const LBFGS_MEMORY: usize = 10;
const GRAD_TOLERANCE: f64 = 1e-5;
/// Largest difference (nats) allowed between a fitted GP's log marginal likelihood and the
/// one rebuilt here from its support points: the rebuilt problem must be the one `fit` solved.
const REBUILD_TOLERANCE: f64 = 1e-6;

/// Which hyperparameters the components share.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Tie {
    /// The length scales; each component keeps its own signal variance and noise.
    LengthScales,
    /// Length scales, signal variance and noise (standardised units).
    All,
}

impl Tie {
    fn name(self) -> &'static str {
        match self {
            Tie::LengthScales => "length-scales",
            Tie::All => "all",
        }
    }
}

/// A family of GPs on the same inputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum Family {
    /// The transition GPs, one per state component.
    Transitions,
    /// The sensors' state-only GPs (`[x_{k-1}, x_k]`), one per sensor.
    Sensors,
}

impl Family {
    fn name(self) -> &'static str {
        match self {
            Family::Transitions => "transitions",
            Family::Sensors => "sensors",
        }
    }

    fn prefix(self) -> &'static str {
        match self {
            Family::Transitions => "x",
            Family::Sensors => "y",
        }
    }
}

/// Independent against shared GP hyperparameters of a vector model (Markdown on stdout).
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
    /// GP families (comma-separated).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "transitions")]
    gps: Vec<Family>,
    /// Ties (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "length-scales,all"
    )]
    ties: Vec<Tie>,
    /// L-BFGS iterations per start of the shared search (default: the GPs' `max_iters`, the
    /// budget of each independent start).
    #[arg(long)]
    shared_iters: Option<u64>,
    /// One seed (the first of `--seeds`) and the gains 0 and 1.
    #[arg(long)]
    quick: bool,
    /// Also write the report as JSON to this file.
    #[arg(long)]
    out: Option<PathBuf>,
}

/// Component `i` of row-major targets with `width` per row.
fn column(targets: &[f64], width: usize, i: usize) -> Vec<f64> {
    targets.iter().skip(i).step_by(width).copied().collect()
}

/// The `GpParams` the vector model gives a GP of `role` with kernel `spec` (hbn-model's
/// `CheckedHbnParams::gp_params`, which is crate-private).
fn gp_params(p: &HbnParams, spec: KernelSpec, role: GpRole) -> GpParams {
    let mut g = GpParams::new(spec);
    g.max_points = p.max_points;
    g.sparse = p.n_inducing.map(SparseParams::new);
    g.subset_policy = p.subset_policy;
    g.n_starts = p.n_starts;
    g.max_iters = p.max_iters;
    g.seed = p.seed;
    g.normalize = p.normalize;
    g.noise_floor = p.noise_floor;
    g.mean = p.linear_mean.mean(role);
    g.max_signal_variance = p.max_signal_variance;
    g
}

/// The standardised support data of a fitted exact GP: the problem its fit solved.
struct Support {
    x: Vec<f64>,
    y: Vec<f64>,
    directions: Vec<f64>,
}

impl Support {
    /// Rebuilds the standardised support inputs and targets from `gp` (a constant prior mean
    /// and an unwarped, unwhitened kernel only).
    fn of(gp: &GaussianProcess) -> Result<Self, String> {
        let spec = gp.kernel();
        if gp.is_sparse() || !gp.linear_mean().is_empty() {
            return Err("only exact GPs with a constant mean are compared".into());
        }
        if spec.metric == hbn_core::Metric::Mahalanobis || spec.warp_units > 0 {
            return Err("only unwarped kernels without whitening are compared".into());
        }
        let d = spec.dim;
        let (im, is) = gp.input_standardisation();
        let (om, os) = gp.output_standardisation();
        let x: Vec<f64> = gp
            .support_inputs()
            .chunks_exact(d)
            .flat_map(|row| (0..d).map(|j| (row[j] - im[j]) / is[j]))
            .collect();
        let y: Vec<f64> = gp.support_targets().iter().map(|t| (t - om) / os).collect();
        let directions = gp
            .support_inputs()
            .chunks_exact(d)
            .map(|r| spec.direction_of(r))
            .collect();
        Ok(Self { x, y, directions })
    }

    fn likelihood(&self, spec: KernelSpec, params: &GpParams) -> Likelihood<'_> {
        Likelihood::new(
            LikelihoodData {
                spec,
                whiten: &[],
                x: &self.x,
                directions: &self.directions,
                y: &self.y,
            },
            params.noise_floor,
            params.max_jitter_retries,
        )
        .with_max_signal_variance(params.max_signal_variance.unwrap_or(f64::INFINITY))
    }
}

/// The summed log marginal likelihood of `C` components under a tie. Each component's
/// optimised vector is `[ln s_f^2, metric parameters, noise parameter]` (hbn-gp's layout);
/// the tied vector is `[ln s_f^2 (C), metric, noise (C)]` for [`Tie::LengthScales`] and one
/// component's layout for [`Tie::All`].
struct Shared<'a> {
    liks: Vec<Likelihood<'a>>,
    tie: Tie,
    /// Metric parameters (length scales) per component.
    n_metric: usize,
}

impl Shared<'_> {
    fn components(&self) -> usize {
        self.liks.len()
    }

    /// Length of the tied vector.
    fn n_vars(&self) -> usize {
        match self.tie {
            Tie::LengthScales => 2 * self.components() + self.n_metric,
            Tie::All => self.n_metric + 2,
        }
    }

    /// Component `i`'s optimised vector from the tied `z`.
    fn component(&self, z: &[f64], i: usize) -> Vec<f64> {
        match self.tie {
            Tie::All => z.to_vec(),
            Tie::LengthScales => {
                let c = self.components();
                let mut p = Vec::with_capacity(self.n_metric + 2);
                p.push(z[i]);
                p.extend_from_slice(&z[c..c + self.n_metric]);
                p.push(z[c + self.n_metric + i]);
                p
            }
        }
    }

    /// The tied vector nearest the components' vectors `ps`: the mean of what is tied, each
    /// component's own value of the rest.
    fn tie_from(&self, ps: &[Vec<f64>]) -> Vec<f64> {
        let c = ps.len() as f64;
        let mean = |k: usize| ps.iter().map(|p| p[k]).sum::<f64>() / c;
        let nm = self.n_metric;
        match self.tie {
            Tie::All => (0..nm + 2).map(mean).collect(),
            Tie::LengthScales => ps
                .iter()
                .map(|p| p[0])
                .chain((1..=nm).map(mean))
                .chain(ps.iter().map(|p| p[nm + 1]))
                .collect(),
        }
    }

    /// Summed objective (each component's log marginal likelihood minus its bound penalty)
    /// and its gradient in `z`.
    fn evaluate(&self, z: &[f64]) -> Result<(f64, Vec<f64>), GpError> {
        let c = self.components();
        let nm = self.n_metric;
        let mut total = 0.0;
        let mut grad = vec![0.0; self.n_vars()];
        for (i, lik) in self.liks.iter().enumerate() {
            let ev = lik.evaluate(&self.component(z, i))?;
            total += ev.lml;
            match self.tie {
                Tie::All => {
                    for (g, e) in grad.iter_mut().zip(&ev.grad) {
                        *g += e;
                    }
                }
                Tie::LengthScales => {
                    grad[i] += ev.grad[0];
                    for m in 0..nm {
                        grad[c + m] += ev.grad[1 + m];
                    }
                    grad[c + nm + i] += ev.grad[nm + 1];
                }
            }
        }
        Ok((total, grad))
    }
}

/// argmin adapter: minimise the negated summed objective.
struct NegShared<'s, 'a>(&'s Shared<'a>);

impl CostFunction for NegShared<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, z: &Self::Param) -> Result<f64, argmin::core::Error> {
        Ok(self
            .0
            .evaluate(z)
            .ok()
            .filter(|(v, _)| v.is_finite())
            .map_or(FAILED_COST, |(v, _)| -v))
    }
}

impl Gradient for NegShared<'_, '_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, z: &Self::Param) -> Result<Vec<f64>, argmin::core::Error> {
        Ok(match self.0.evaluate(z) {
            Ok((_, g)) => g.iter().map(|v| -v).collect(),
            Err(_) => vec![0.0; z.len()],
        })
    }
}

/// One L-BFGS run from `z0`: the best tied vector, its objective, the iterations.
fn run_lbfgs(
    shared: &Shared<'_>,
    z0: Vec<f64>,
    max_iters: u64,
) -> Result<(Vec<f64>, f64, u64), argmin::core::Error> {
    let line = MoreThuenteLineSearch::new().with_width_tolerance(0.1)?;
    let solver = LBFGS::new(line, LBFGS_MEMORY)
        .with_tolerance_grad(GRAD_TOLERANCE)?
        .with_tolerance_cost(COST_TOLERANCE)?;
    let res = Executor::new(NegShared(shared), solver)
        .configure(|s| s.param(z0).max_iters(max_iters))
        .run()?;
    let state = res.state();
    let value = -state.get_best_cost();
    let z = state
        .get_best_param()
        .cloned()
        .ok_or_else(|| argmin::core::Error::msg("no best parameter"))?;
    Ok((z, value, state.get_iter()))
}

/// Test-row scores of one GP.
#[derive(Clone, Copy, Debug)]
struct Score {
    nlpd: f64,
    rmse: f64,
}

/// Mean NLPD (latent variance plus noise) and RMSE of `gp` on `rows` against `targets`.
fn score(gp: &GaussianProcess, rows: &[f64], targets: &[f64]) -> Result<Score, GpError> {
    let preds = gp.predict_many(rows, Want::VARIANCE)?;
    let noise = gp.noise_variance();
    let n = targets.len() as f64;
    let (mut nlpd, mut sq) = (0.0, 0.0);
    for (p, t) in preds.iter().zip(targets) {
        let v = (p.variance + noise).max(f64::MIN_POSITIVE);
        let r = t - p.mean;
        nlpd += 0.5 * (2.0 * std::f64::consts::PI * v).ln() + r * r / (2.0 * v);
        sq += r * r;
    }
    Ok(Score {
        nlpd: nlpd / n,
        rmse: (sq / n).sqrt(),
    })
}

/// The shared side of one tie.
struct TieResult {
    tie: Tie,
    scores: Vec<Score>,
    /// Summed log marginal likelihood at the shared optimum.
    lml: f64,
    /// The whole search and the fixed fits; the default start and the fixed fits.
    seconds: f64,
    default_seconds: f64,
    /// Which start won (`default`, `mean`, or `own x{i}`), and the objective of each.
    best_start: String,
    starts: Vec<(String, f64, u64)>,
    /// The shared length scales, in the first component's standardised units (`ln l`).
    log_length_scales: Vec<f64>,
}

/// One GP family of one case.
struct FamilyResult {
    family: Family,
    independent: Vec<Score>,
    independent_lml: f64,
    independent_seconds: f64,
    /// Each component's own `ln l`.
    independent_log_length_scales: Vec<Vec<f64>>,
    /// Each component's optimiser starts: final log marginal likelihood and iterations.
    independent_starts: Vec<Vec<(f64, u64)>>,
    ties: Vec<TieResult>,
}

/// One system, gain and seed.
struct CaseResult {
    system: MultiKind,
    gain: f64,
    seed: u64,
    families: Vec<FamilyResult>,
}

/// GPs of one family: shared training rows, per-component targets and parameters.
struct Problem {
    family: Family,
    train_rows: Vec<f64>,
    train_targets: Vec<Vec<f64>>,
    test_rows: Vec<f64>,
    test_targets: Vec<Vec<f64>>,
    params: Vec<GpParams>,
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

/// The problem of `family` on the runs.
fn problem(
    family: Family,
    train: &VectorSequence<'_>,
    test: &VectorSequence<'_>,
    params: &HbnParams,
) -> Result<Problem, Box<dyn std::error::Error>> {
    let dims = train.dims;
    match family {
        Family::Transitions => {
            let plays = Plays::with_lags(&params.memory, &[])?;
            let (train_rows, tt) = transition_rows(std::slice::from_ref(train), &plays);
            let (test_rows, st) = transition_rows(std::slice::from_ref(test), &plays);
            let mut spec = params
                .transition_kernel
                .spec(dims.transition_dim(plays.len()), [0, 0]);
            spec.direction = None;
            spec.validate()?;
            let params = (0..dims.states)
                .map(|i| {
                    let mut g = gp_params(params, spec, GpRole::Transition);
                    g.seed = params.seed.wrapping_add(i as u64);
                    g
                })
                .collect();
            Ok(Problem {
                family,
                train_rows,
                train_targets: (0..dims.states)
                    .map(|i| column(&tt, dims.states, i))
                    .collect(),
                test_rows,
                test_targets: (0..dims.states)
                    .map(|i| column(&st, dims.states, i))
                    .collect(),
                params,
            })
        }
        Family::Sensors => {
            let mut spec = params.sensor_kernel.spec(dims.sensor_dim(false), [0, 0]);
            spec.direction = None;
            spec.validate()?;
            let mut p = Problem {
                family,
                train_rows: Vec::new(),
                train_targets: Vec::new(),
                test_rows: Vec::new(),
                test_targets: Vec::new(),
                params: Vec::new(),
            };
            for j in 0..dims.sensors {
                let (r, t) = sensor_rows(std::slice::from_ref(train), j, false);
                let (rt, tt) = sensor_rows(std::slice::from_ref(test), j, false);
                // The state-only rows do not depend on the sensor.
                p.train_rows = r;
                p.test_rows = rt;
                p.train_targets.push(t);
                p.test_targets.push(tt);
                let mut g = gp_params(params, spec, GpRole::Sensor);
                g.seed = params.seed.wrapping_add(100 + j as u64);
                p.params.push(g);
            }
            Ok(p)
        }
    }
}

/// Independent and shared fits of one family, scored.
fn run_family(
    p: &Problem,
    ties: &[Tie],
    shared_iters: Option<u64>,
) -> Result<FamilyResult, Box<dyn std::error::Error>> {
    let c = p.params.len();
    let family = p.family;
    let pre = family.prefix();
    // Independent.
    let t0 = Instant::now();
    let gps: Vec<GaussianProcess> = p
        .params
        .iter()
        .zip(&p.train_targets)
        .map(|(g, t)| hbn_gp::fit(g, &p.train_rows, t))
        .collect::<Result<_, _>>()?;
    let independent_seconds = t0.elapsed().as_secs_f64();
    let independent: Vec<Score> = gps
        .iter()
        .zip(&p.test_targets)
        .map(|(gp, t)| score(gp, &p.test_rows, t))
        .collect::<Result<_, _>>()?;
    let supports: Vec<Support> = gps.iter().map(Support::of).collect::<Result<_, _>>()?;
    let spec = *gps[0].kernel();
    let n_metric = spec.n_metric();
    // Each component's optimum in the optimised layout, and a check that the rebuilt problem
    // is the one its fit solved.
    let mut own = Vec::with_capacity(c);
    let mut independent_lml = 0.0;
    for (i, ((gp, s), g)) in gps.iter().zip(&supports).zip(&p.params).enumerate() {
        let lik = s.likelihood(spec, g);
        let h = gp.hyperparameters();
        let rebuilt = lik.solve(&h.theta, h.noise_variance)?.lml;
        let diff = (rebuilt - gp.log_marginal_likelihood()).abs();
        if diff > REBUILD_TOLERANCE * (1.0 + rebuilt.abs()) {
            return Err(format!(
                "{pre}{i}: rebuilt log marginal likelihood {rebuilt} against the fit's {}",
                gp.log_marginal_likelihood()
            )
            .into());
        }
        independent_lml += gp.log_marginal_likelihood();
        let mut v = h.theta.clone();
        v.push(param_of_noise(g.noise_floor, h.noise_variance));
        own.push(v);
    }
    let mut default = vec![0.0; spec.n_params()];
    spec.default_theta(&mut default)?;
    let floor = p.params[0].noise_floor;
    default.push(param_of_noise(floor, 0.1_f64.max(2.0 * floor)));
    eprintln!(
        "  {}: independent {independent_seconds:.1} s, sum LML {independent_lml:.1}, NLPD {:?}",
        family.name(),
        independent
            .iter()
            .map(|s| (s.nlpd * 1e3).round() / 1e3)
            .collect::<Vec<_>>()
    );

    let mut results = Vec::new();
    for &tie in ties {
        let shared = Shared {
            liks: supports
                .iter()
                .zip(&p.params)
                .map(|(s, g)| s.likelihood(spec, g))
                .collect(),
            tie,
            n_metric,
        };
        let mut starts: Vec<(String, Vec<f64>)> = vec![
            ("default".into(), shared.tie_from(&vec![default.clone(); c])),
            ("mean".into(), shared.tie_from(&own)),
        ];
        for (i, o) in own.iter().enumerate() {
            // Component i's own vector for every tied parameter.
            let mut ps = own.clone();
            for q in &mut ps {
                match tie {
                    Tie::All => q.clone_from(o),
                    Tie::LengthScales => q[1..=n_metric].copy_from_slice(&o[1..=n_metric]),
                }
            }
            starts.push((format!("own {pre}{i}"), shared.tie_from(&ps)));
        }
        let max_iters = shared_iters.unwrap_or(p.params[0].max_iters);
        let t0 = Instant::now();
        let mut best: Option<(String, Vec<f64>, f64)> = None;
        let mut report = Vec::new();
        let mut default_seconds = 0.0;
        for (name, z0) in starts {
            let ts = Instant::now();
            match run_lbfgs(&shared, z0, max_iters) {
                Ok((z, v, iters)) => {
                    report.push((name.clone(), v, iters));
                    if v.is_finite() && best.as_ref().is_none_or(|b| v > b.2) {
                        best = Some((name.clone(), z, v));
                    }
                }
                Err(e) => {
                    eprintln!("    {} start {name} failed: {e}", tie.name());
                    report.push((name.clone(), f64::NAN, 0));
                }
            }
            if name == "default" {
                default_seconds = ts.elapsed().as_secs_f64();
            }
        }
        let search_seconds = t0.elapsed().as_secs_f64();
        let Some((best_start, z, _)) = best else {
            return Err(format!("{}: every shared start failed", tie.name()).into());
        };
        // Fixed-hyperparameter fits.
        let t1 = Instant::now();
        let mut lml = 0.0;
        let mut fixed = Vec::with_capacity(c);
        for (i, (g, t)) in p.params.iter().zip(&p.train_targets).enumerate() {
            let v = shared.component(&z, i);
            let n_k = spec.n_params();
            let fixed_params = GpParams {
                optimize: false,
                init: Some(Hyperparameters {
                    theta: v[..n_k].to_vec(),
                    noise_variance: noise_of(g.noise_floor, v[n_k]),
                }),
                ..g.clone()
            };
            let gp = hbn_gp::fit(&fixed_params, &p.train_rows, t)?;
            lml += gp.log_marginal_likelihood();
            fixed.push(gp);
        }
        let fixed_seconds = t1.elapsed().as_secs_f64();
        let scores: Vec<Score> = fixed
            .iter()
            .zip(&p.test_targets)
            .map(|(gp, t)| score(gp, &p.test_rows, t))
            .collect::<Result<_, _>>()?;
        eprintln!(
            "    {}: {:.1} s (default start {:.1} s), best start {best_start}, sum LML {lml:.1} \
             ({:+.1}), NLPD {:?}",
            tie.name(),
            search_seconds + fixed_seconds,
            default_seconds + fixed_seconds,
            lml - independent_lml,
            scores
                .iter()
                .map(|s| (s.nlpd * 1e3).round() / 1e3)
                .collect::<Vec<_>>()
        );
        results.push(TieResult {
            tie,
            scores,
            lml,
            seconds: search_seconds + fixed_seconds,
            default_seconds: default_seconds + fixed_seconds,
            best_start,
            starts: report,
            log_length_scales: shared.component(&z, 0)[1..=n_metric].to_vec(),
        });
    }
    Ok(FamilyResult {
        family,
        independent,
        independent_lml,
        independent_seconds,
        independent_log_length_scales: own.iter().map(|o| o[1..=n_metric].to_vec()).collect(),
        independent_starts: gps
            .iter()
            .map(|gp| {
                gp.report()
                    .starts
                    .iter()
                    .map(|s| (s.final_lml.unwrap_or(f64::NAN), s.iterations))
                    .collect()
            })
            .collect(),
        ties: results,
    })
}

/// Runs one case.
fn run_case(
    system: MultiKind,
    gain: f64,
    seed: u64,
    args: &Args,
) -> Result<CaseResult, Box<dyn std::error::Error>> {
    let (train, test) = runs(system, gain, seed, args)?;
    let dims = Dims::new(system.inputs(), system.states(), system.sensors())?;
    let params = HbnParams::default();
    let (u, x, y) = (rows(&train.u), rows(&train.x), rows(&train.y));
    let (tu, tx, ty) = (rows(&test.u), rows(&test.x), rows(&test.y));
    let train_seq = VectorSequence::new(&u, &x, &y, dims);
    let test_seq = VectorSequence::new(&tu, &tx, &ty, dims);
    let mut families = Vec::new();
    for &family in &args.gps {
        let p = problem(family, &train_seq, &test_seq, &params)?;
        families.push(run_family(&p, &args.ties, args.shared_iters)?);
    }
    Ok(CaseResult {
        system,
        gain,
        seed,
        families,
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

/// Mean, sample standard deviation, minimum and maximum of `v` (`NaN`s when empty).
fn spread(v: &[f64]) -> (f64, f64, f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN, f64::NAN, f64::NAN);
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let sd = if v.len() > 1 {
        (v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / (n - 1.0)).sqrt()
    } else {
        0.0
    };
    let min = v.iter().copied().fold(f64::INFINITY, f64::min);
    let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    (mean, sd, min, max)
}

/// `v` with `d` decimals and a sign, or `-`.
fn signed(v: f64, d: usize) -> String {
    if v.is_finite() {
        format!("{v:+.d$}")
    } else {
        "-".into()
    }
}

/// `v` with `d` decimals, or `-`.
fn fixed(v: f64, d: usize) -> String {
    if v.is_finite() {
        format!("{v:.d$}")
    } else {
        "-".into()
    }
}

/// A float for JSON (`null` when not finite).
fn finite(v: f64) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

/// The Markdown report of `cases`.
fn markdown(header: &[(String, String)], cases: &[CaseResult], args: &Args) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Independent against shared GP hyperparameters of the vector model\n"
    );
    for (k, v) in header {
        let _ = writeln!(s, "- {k}: {v}");
    }
    let _ = writeln!(
        s,
        "\nOne-step scores on the test run's rows. NLPD in nats per row (latent variance plus \
         noise); dNLPD = shared - independent (negative: sharing is better); RMSE ratio = \
         shared / independent. dLML: summed training log marginal likelihood, shared - \
         independent.\n"
    );
    let _ = writeln!(
        s,
        "| system | gain | seed | GP | NLPD indep | RMSE indep | {} |",
        args.ties
            .iter()
            .map(|t| format!("dNLPD {0} | RMSE ratio {0}", t.name()))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    let _ = writeln!(
        s,
        "|---|---|---|---|---|---|{}",
        "---|---|".repeat(args.ties.len())
    );
    for case in cases {
        for f in &case.families {
            for (i, ind) in f.independent.iter().enumerate() {
                let cols: Vec<String> = f
                    .ties
                    .iter()
                    .map(|t| {
                        format!(
                            "{} | {}",
                            signed(t.scores[i].nlpd - ind.nlpd, 3),
                            fixed(t.scores[i].rmse / ind.rmse, 3)
                        )
                    })
                    .collect();
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {}{i} | {} | {:.3e} | {} |",
                    case.system,
                    case.gain,
                    case.seed,
                    f.family.prefix(),
                    fixed(ind.nlpd, 3),
                    ind.rmse,
                    cols.join(" | ")
                );
            }
        }
    }
    let _ = writeln!(
        s,
        "\n## Shared - independent over seeds\n\nPer seed, the mean over components; then the \
         mean, standard deviation and range over seeds. Time ratio: shared (whole search and \
         fixed fits; in brackets the default start alone) / independent fits.\n"
    );
    let _ = writeln!(
        s,
        "| system | gain | GPs | tie | dNLPD mean +- sd [min, max] | RMSE ratio mean [min, max] | worst component dNLPD | dLML mean | time ratio | best starts |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|---|---|");
    let mut groups: Vec<(MultiKind, f64)> = Vec::new();
    for c in cases {
        if !groups.contains(&(c.system, c.gain)) {
            groups.push((c.system, c.gain));
        }
    }
    for (system, gain) in groups {
        let these: Vec<&CaseResult> = cases
            .iter()
            .filter(|c| c.system == system && c.gain == gain)
            .collect();
        for &family in &args.gps {
            for (k, &tie) in args.ties.iter().enumerate() {
                let mut dn = Vec::new();
                let mut ratio = Vec::new();
                let mut worst = f64::NEG_INFINITY;
                let mut dlml = Vec::new();
                let mut time = Vec::new();
                let mut time_default = Vec::new();
                let mut best = Vec::new();
                for c in &these {
                    for f in c.families.iter().filter(|f| f.family == family) {
                        let Some(t) = f.ties.get(k) else { continue };
                        let n = f.independent.len() as f64;
                        let d: Vec<f64> = t
                            .scores
                            .iter()
                            .zip(&f.independent)
                            .map(|(a, b)| a.nlpd - b.nlpd)
                            .collect();
                        worst = d.iter().copied().fold(worst, f64::max);
                        dn.push(d.iter().sum::<f64>() / n);
                        ratio.push(
                            t.scores
                                .iter()
                                .zip(&f.independent)
                                .map(|(a, b)| a.rmse / b.rmse)
                                .sum::<f64>()
                                / n,
                        );
                        dlml.push(t.lml - f.independent_lml);
                        time.push(t.seconds / f.independent_seconds);
                        time_default.push(t.default_seconds / f.independent_seconds);
                        best.push(t.best_start.clone());
                    }
                }
                let (m, sd, lo, hi) = spread(&dn);
                let (rm, _, rlo, rhi) = spread(&ratio);
                let _ = writeln!(
                    s,
                    "| {system} | {gain} | {} | {} | {} +- {} [{}, {}] | {} [{}, {}] | {} | {} | {} ({}) | {} |",
                    family.name(),
                    tie.name(),
                    signed(m, 3),
                    fixed(sd, 3),
                    signed(lo, 3),
                    signed(hi, 3),
                    fixed(rm, 3),
                    fixed(rlo, 3),
                    fixed(rhi, 3),
                    signed(worst, 3),
                    signed(spread(&dlml).0, 1),
                    fixed(spread(&time).0, 2),
                    fixed(spread(&time_default).0, 2),
                    best.join(", ")
                );
            }
        }
    }
    s
}

/// Every number of `cases` as JSON.
fn to_json(header: &[(String, String)], cases: &[CaseResult]) -> Value {
    let scores = |v: &[Score]| {
        v.iter()
            .map(|s| json!({"nlpd": finite(s.nlpd), "rmse": finite(s.rmse)}))
            .collect::<Vec<_>>()
    };
    json!({
        "header": header.iter().map(|(k, v)| (k.clone(), json!(v))).collect::<serde_json::Map<_, _>>(),
        "cases": cases.iter().map(|c| json!({
            "system": c.system.to_string(),
            "gain": c.gain,
            "seed": c.seed,
            "families": c.families.iter().map(|f| json!({
                "family": f.family.name(),
                "independent": scores(&f.independent),
                "independent_lml": finite(f.independent_lml),
                "independent_seconds": f.independent_seconds,
                "independent_log_length_scales": f.independent_log_length_scales,
                "independent_starts": f.independent_starts.iter().map(|c| c.iter().map(|(v, it)| json!({
                    "objective": finite(*v), "iterations": it
                })).collect::<Vec<_>>()).collect::<Vec<_>>(),
                "shared": f.ties.iter().map(|t| json!({
                    "tie": t.tie.name(),
                    "scores": scores(&t.scores),
                    "lml": finite(t.lml),
                    "seconds": t.seconds,
                    "default_start_seconds": t.default_seconds,
                    "best_start": t.best_start,
                    "starts": t.starts.iter().map(|(n, v, it)| json!({
                        "start": n, "objective": finite(*v), "iterations": it
                    })).collect::<Vec<_>>(),
                    "log_length_scales": t.log_length_scales,
                })).collect::<Vec<_>>(),
            })).collect::<Vec<_>>(),
        })).collect::<Vec<_>>(),
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = Args::parse();
    if args.quick {
        args.seeds.truncate(1);
        args.gains = vec![0.0, 1.0];
    }
    let header = vec![
        ("machine".to_string(), cpu()),
        (
            "date".to_string(),
            command_output("date", &["-u", "+%Y-%m-%d %H:%M UTC"]),
        ),
        (
            "commit".to_string(),
            command_output("git", &["rev-parse", "--short", "HEAD"]),
        ),
        (
            "command".to_string(),
            format!(
                "`{}`",
                std::env::args()
                    .map(|a| a.rsplit('/').next().unwrap_or_default().to_string())
                    .collect::<Vec<_>>()
                    .join(" ")
            ),
        ),
        (
            "threads".to_string(),
            std::env::var("RAYON_NUM_THREADS").unwrap_or_else(|_| "all".into()),
        ),
        (
            "runs".to_string(),
            format!(
                "{} training samples, {} test samples",
                args.train_steps, args.test_steps
            ),
        ),
    ];
    let mut cases = Vec::new();
    for &system in &args.systems {
        for &gain in &args.gains {
            for &seed in &args.seeds {
                eprintln!("{system} gain {gain} seed {seed}");
                cases.push(run_case(system, gain, seed, &args)?);
            }
        }
    }
    print!("{}", markdown(&header, &cases, &args));
    if let Some(out) = &args.out {
        std::fs::write(
            out,
            serde_json::to_string_pretty(&to_json(&header, &cases))?,
        )?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two components on the same 30 inputs in two dimensions, different targets.
    fn data() -> (Vec<f64>, Vec<Vec<f64>>) {
        let x: Vec<f64> = (0..30)
            .flat_map(|i| {
                let t = i as f64 / 29.0;
                [2.0 * t - 1.0, (5.0 * t).sin()]
            })
            .collect();
        let y = vec![
            x.chunks_exact(2)
                .map(|r| (2.0 * r[0]).sin() + 0.1 * r[1])
                .collect(),
            x.chunks_exact(2)
                .map(|r| 3.0 * r[0] * r[0] - r[1])
                .collect(),
        ];
        (x, y)
    }

    fn fitted() -> (Vec<GaussianProcess>, GpParams) {
        let (x, ys) = data();
        let g = GpParams::new(KernelSpec::se_ard(2));
        let gps = ys.iter().map(|y| hbn_gp::fit(&g, &x, y).unwrap()).collect();
        (gps, g)
    }

    #[test]
    fn the_rebuilt_problem_is_the_one_the_fit_solved() {
        let (gps, g) = fitted();
        for gp in &gps {
            let s = Support::of(gp).unwrap();
            let h = gp.hyperparameters();
            let lml = s
                .likelihood(*gp.kernel(), &g)
                .solve(&h.theta, h.noise_variance)
                .unwrap()
                .lml;
            assert!((lml - gp.log_marginal_likelihood()).abs() < 1e-9, "{lml}");
        }
    }

    #[test]
    fn the_tied_gradient_matches_finite_differences() {
        let (gps, g) = fitted();
        let supports: Vec<Support> = gps.iter().map(|gp| Support::of(gp).unwrap()).collect();
        let spec = *gps[0].kernel();
        for tie in [Tie::LengthScales, Tie::All] {
            let shared = Shared {
                liks: supports.iter().map(|s| s.likelihood(spec, &g)).collect(),
                tie,
                n_metric: 2,
            };
            let z: Vec<f64> = (0..shared.n_vars())
                .map(|k| -0.3 + 0.2 * k as f64)
                .collect();
            let (_, grad) = shared.evaluate(&z).unwrap();
            for k in 0..z.len() {
                let h = 1e-5;
                let (mut a, mut b) = (z.clone(), z.clone());
                a[k] += h;
                b[k] -= h;
                let fd =
                    (shared.evaluate(&a).unwrap().0 - shared.evaluate(&b).unwrap().0) / (2.0 * h);
                assert!(
                    (fd - grad[k]).abs() < 1e-4 * (1.0 + fd.abs()),
                    "{tie:?} {k}: {fd} against {}",
                    grad[k]
                );
            }
        }
    }

    #[test]
    fn tying_the_components_own_tied_vectors_gives_them_back() {
        let (gps, g) = fitted();
        let supports: Vec<Support> = gps.iter().map(|gp| Support::of(gp).unwrap()).collect();
        let spec = *gps[0].kernel();
        let shared = Shared {
            liks: supports.iter().map(|s| s.likelihood(spec, &g)).collect(),
            tie: Tie::LengthScales,
            n_metric: 2,
        };
        let z = vec![0.1, 0.2, 0.3, 0.4, 0.5, 0.6];
        let ps: Vec<Vec<f64>> = (0..2).map(|i| shared.component(&z, i)).collect();
        assert_eq!(ps[1], vec![0.2, 0.3, 0.4, 0.6]);
        assert_eq!(shared.tie_from(&ps), z);
    }

    #[test]
    fn shared_fit_with_one_component_finds_its_own_optimum() {
        // With one component both ties are the component's own problem: the search must
        // reach the independent fit's likelihood.
        let (gps, g) = fitted();
        let s = Support::of(&gps[0]).unwrap();
        let spec = *gps[0].kernel();
        let shared = Shared {
            liks: vec![s.likelihood(spec, &g)],
            tie: Tie::All,
            n_metric: 2,
        };
        let mut z0 = vec![0.0; 3];
        z0.push(param_of_noise(g.noise_floor, 0.1));
        let (_, v, _) = run_lbfgs(&shared, z0, 200).unwrap();
        assert!(
            (v - gps[0].log_marginal_likelihood()).abs() < 0.05,
            "{v} against {}",
            gps[0].log_marginal_likelihood()
        );
    }
}
