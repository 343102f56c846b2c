//! `hbn experiment`: the thesis' simulation study.

use anyhow::{Context, bail};
use hbn_model::HbnParams;
use hbn_pipeline::experiment::{self, ExperimentConfig, ExperimentRow};

use crate::Ui;
use crate::cli::ExperimentArgs;
use crate::glossary::Term;
use crate::plot::{self, GainLine};
use crate::report::{self, Renderer};

/// A method's label and its nRMSE in a row.
type Method = (&'static str, fn(&ExperimentRow) -> f64);

/// Mean nRMSE per (system, gain) and method, as plot panels.
pub fn panels(rows: &[ExperimentRow]) -> Vec<(String, Vec<GainLine>)> {
    let mut systems: Vec<String> = Vec::new();
    for r in rows {
        if !systems.contains(&r.system) {
            systems.push(r.system.clone());
        }
    }
    let methods: [Method; 4] = [
        ("ekf", |r| r.nrmse_ekf),
        ("ekf-blr", |r| r.nrmse_ekf_blr),
        ("ukf", |r| r.nrmse_ukf),
        ("open-loop", |r| r.nrmse_open_loop),
    ];
    systems
        .into_iter()
        .map(|s| {
            let sel: Vec<&ExperimentRow> = rows.iter().filter(|r| r.system == s).collect();
            let mut gains: Vec<f64> = Vec::new();
            for r in &sel {
                if !gains.contains(&r.noise_gain) {
                    gains.push(r.noise_gain);
                }
            }
            gains.sort_by(f64::total_cmp);
            let lines = methods
                .iter()
                .map(|(label, f)| GainLine {
                    label,
                    points: gains
                        .iter()
                        .map(|&g| {
                            let v: Vec<f64> = sel
                                .iter()
                                .filter(|r| r.noise_gain == g)
                                .map(|r| f(r))
                                .collect();
                            (g, v.iter().sum::<f64>() / v.len().max(1) as f64)
                        })
                        .collect(),
                })
                .collect();
            (s, lines)
        })
        .collect()
}

/// Runs `hbn experiment`; returns the rows.
pub fn run(ui: &mut Ui<'_>, args: &ExperimentArgs) -> anyhow::Result<Vec<ExperimentRow>> {
    for (f, what) in [(&args.json, "JSON output"), (&args.plot, "plot")] {
        if let Some(f) = f {
            crate::check_output(f, what)?;
        }
    }
    if args.systems.is_empty() || args.gains.is_empty() || args.seeds.is_empty() {
        bail!("give at least one system, noise gain and seed");
    }
    let cfg = ExperimentConfig {
        systems: args.systems.clone(),
        seeds: args.seeds.clone(),
        noise_gains: args.gains.clone(),
        train_steps: args.train_steps,
        repeats: args.repeats,
        test_steps: args.test_steps,
        max_increment: hbn_sim::DEFAULT_MAX_INCREMENT,
        params: {
            let (n_inducing, inducing) = crate::cli::inducing_choice(&args.inducing);
            let (lags, select_lags) = crate::cli::lags_choice(&args.lags);
            let (sensor_inputs, select_sensors) =
                crate::cli::sensor_inputs_choice(&args.sensor_inputs);
            HbnParams {
                n_inducing,
                select: hbn_model::Selection {
                    kernels: Vec::new(),
                    inducing,
                    lags: select_lags,
                    sensor_inputs: select_sensors,
                },
                max_points: args.max_points,
                memory: args.memory.0.clone(),
                lags,
                linear_mean: args.linear_mean,
                sensor_inputs,
                ..HbnParams::default()
            }
        },
    };
    let mut render = Renderer::default();
    let rows = experiment::run(&cfg, &mut |e| render.event(ui, e));
    render.finish();
    let rows = rows
        .map_err(|e| report::error(e, hbn_io::TimeSource::LogTime))
        .context("experiment failed")?;
    if let Some(f) = &args.json {
        let text = serde_json::to_string_pretty(&rows).context("cannot format JSON")?;
        hbn_fs::write_atomic(f, text.as_bytes())?;
    }
    if let Some(f) = &args.plot {
        plot::experiment_plot(f, &panels(&rows))?;
    }
    ui.print(experiment::markdown_table(&rows))?;
    ui.line(crate::glossary::links(&[
        Term::NoiseGain,
        Term::Nrmse,
        Term::DefaultMode,
        Term::Coverage,
        Term::Nees,
        Term::NoiseStateCorrelation,
    ]))?;
    for (f, what) in [(&args.json, "rows"), (&args.plot, "plot")] {
        if let Some(f) = f {
            ui.line(format!("wrote {what} `{}`", f.display()))?;
        }
    }
    Ok(rows)
}
