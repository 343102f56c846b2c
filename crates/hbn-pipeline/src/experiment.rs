//! The thesis' simulation protocol (Sec. 5.1, Tables 1 and 2), reproducible from seeds.
//!
//! For each system, seed and noise gain: one random training input (bounded increments) is
//! applied `repeats` times with independent noise (the thesis used 10); both GPs are fitted;
//! a fresh random test input is simulated once with noise; `x` is estimated from `u` and `y`
//! by the EKF, the EKF+BLR and open-loop GP simulation, and scored by nRMSE against the true
//! (disturbed) state.

use crate::error::PipelineError;
use crate::log::{Event, Observer};
use crate::sim::sequences;
use hbn_core::Mode;
use hbn_model::metrics::{Calibration, calibration, correlation, nrmse, rmse};
use hbn_model::{HbnParams, HysteresisModel};
use hbn_sim::{InputKind, SimConfig, SystemKind, Trajectory, generate_input, simulate};
use serde::Serialize;

/// Settings of one experiment.
#[derive(Clone, Debug, PartialEq)]
pub struct ExperimentConfig {
    /// Systems to run.
    pub systems: Vec<SystemKind>,
    /// Seeds (one run each).
    pub seeds: Vec<u64>,
    /// Noise gains.
    pub noise_gains: Vec<f64>,
    /// Samples of the training input.
    pub train_steps: usize,
    /// How often the training input is repeated (with fresh noise).
    pub repeats: usize,
    /// Samples of the test input.
    pub test_steps: usize,
    /// Largest input increment per sample.
    pub max_increment: f64,
    /// Training parameters.
    pub params: HbnParams,
}

impl Default for ExperimentConfig {
    fn default() -> Self {
        Self {
            systems: vec![SystemKind::MaxwellSlip, SystemKind::GeneralizedPi],
            seeds: vec![1, 2, 3],
            noise_gains: vec![0.0, 0.5, 1.0],
            train_steps: 500,
            repeats: 10,
            test_steps: 1000,
            max_increment: hbn_sim::DEFAULT_MAX_INCREMENT,
            params: HbnParams::default(),
        }
    }
}

/// One run's scores.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ExperimentRow {
    /// System name.
    pub system: String,
    /// Seed.
    pub seed: u64,
    /// Noise gain.
    pub noise_gain: f64,
    /// nRMSE of the plain EKF.
    pub nrmse_ekf: f64,
    /// nRMSE of the EKF+BLR.
    pub nrmse_ekf_blr: f64,
    /// nRMSE of the unscented filter.
    pub nrmse_ukf: f64,
    /// nRMSE of open-loop GP simulation.
    pub nrmse_open_loop: f64,
    /// RMSE of the plain EKF.
    pub rmse_ekf: f64,
    /// RMSE of the EKF+BLR.
    pub rmse_ekf_blr: f64,
    /// RMSE of the unscented filter.
    pub rmse_ukf: f64,
    /// RMSE of open-loop GP simulation.
    pub rmse_open_loop: f64,
    /// Correlation of the EKF's process-noise estimate with the state.
    pub noise_state_corr_ekf: f64,
    /// Correlation of the EKF+BLR's process-noise estimate with the state.
    pub noise_state_corr_ekf_blr: f64,
    /// The model's default mode (chosen on held-out data at training).
    pub default_mode: Mode,
    /// nRMSE of the default mode.
    pub nrmse_default: f64,
    /// Calibration of the default mode's standard deviation on the test run.
    pub calibration_default: Calibration,
    /// Whether any estimate was non-finite (never expected).
    pub non_finite: bool,
    /// Training seconds.
    pub train_seconds: f64,
}

/// Training trajectories of the protocol: the same input `repeats` times, independent noise.
pub fn training_set(
    system: SystemKind,
    noise_gain: f64,
    seed: u64,
    cfg: &ExperimentConfig,
) -> Result<Vec<Trajectory>, PipelineError> {
    let u = generate_input(
        InputKind::RandomRamps,
        cfg.train_steps,
        cfg.max_increment,
        seed,
    )?;
    (0..cfg.repeats.max(1))
        .map(|r| {
            let sim = SimConfig {
                system,
                noise_gain,
                rate_hz: cfg.params.rate_hz,
                seed: seed.wrapping_mul(1000).wrapping_add(r as u64),
            };
            Ok(simulate(&sim, &u)?)
        })
        .collect()
}

/// A fresh test trajectory for `seed`.
pub fn test_trajectory(
    system: SystemKind,
    noise_gain: f64,
    seed: u64,
    cfg: &ExperimentConfig,
) -> Result<Trajectory, PipelineError> {
    let u = generate_input(
        InputKind::RandomRamps,
        cfg.test_steps,
        cfg.max_increment,
        seed.wrapping_add(0x7E57),
    )?;
    let sim = SimConfig {
        system,
        noise_gain,
        rate_hz: cfg.params.rate_hz,
        seed: seed.wrapping_add(0xBEEF),
    };
    Ok(simulate(&sim, &u)?)
}

/// Runs one (system, seed, gain) case.
pub fn run_case(
    system: SystemKind,
    seed: u64,
    noise_gain: f64,
    cfg: &ExperimentConfig,
) -> Result<ExperimentRow, PipelineError> {
    let train = training_set(system, noise_gain, seed, cfg)?;
    let params = HbnParams {
        seed,
        ..cfg.params.clone()
    };
    let model = HysteresisModel::fit(&sequences(&train), &params)?;
    let test = test_trajectory(system, noise_gain, seed, cfg)?;
    let ekf = model.estimate(&test.u, &test.y, Mode::Ekf)?;
    let blr = model.estimate(&test.u, &test.y, Mode::EkfBlr)?;
    let ukf = model.estimate(&test.u, &test.y, Mode::Ukf)?;
    let open = model.simulate_open_loop(&test.u)?;
    let default_mode = model.default_mode();
    let default = match default_mode {
        Mode::Ekf => &ekf,
        Mode::EkfBlr => &blr,
        Mode::Ukf => &ukf,
    };
    let non_finite = [&ekf, &blr, &ukf]
        .iter()
        .flat_map(|e| e.x.iter().chain(&e.x_std))
        .any(|v| !v.is_finite());
    Ok(ExperimentRow {
        system: system.name().into(),
        seed,
        noise_gain,
        nrmse_ekf: nrmse(&ekf.x, &test.x),
        nrmse_ekf_blr: nrmse(&blr.x, &test.x),
        nrmse_ukf: nrmse(&ukf.x, &test.x),
        nrmse_open_loop: nrmse(&open, &test.x),
        rmse_ekf: rmse(&ekf.x, &test.x),
        rmse_ekf_blr: rmse(&blr.x, &test.x),
        rmse_ukf: rmse(&ukf.x, &test.x),
        rmse_open_loop: rmse(&open, &test.x),
        noise_state_corr_ekf: correlation(&ekf.q_x, &test.x),
        noise_state_corr_ekf_blr: correlation(&blr.q_x, &test.x),
        default_mode,
        nrmse_default: nrmse(&default.x, &test.x),
        calibration_default: calibration(&default.x, &default.x_std, &test.x),
        non_finite,
        train_seconds: model.summary().seconds,
    })
}

/// Runs every case of `cfg` (parameters checked first), reporting each as
/// [`Event::ExperimentCase`].
pub fn run(
    cfg: &ExperimentConfig,
    observe: &mut Observer<'_>,
) -> Result<Vec<ExperimentRow>, PipelineError> {
    cfg.params.check_ref()?;
    let total = cfg.systems.len() * cfg.noise_gains.len() * cfg.seeds.len();
    let mut rows = Vec::with_capacity(total);
    for &system in &cfg.systems {
        for &gain in &cfg.noise_gains {
            for &seed in &cfg.seeds {
                let row = run_case(system, seed, gain, cfg)?;
                rows.push(row);
                if let Some(row) = rows.last() {
                    observe(Event::ExperimentCase {
                        row,
                        done: rows.len(),
                        total,
                    });
                }
            }
        }
    }
    Ok(rows)
}

/// Mean of each method's nRMSE per (system, gain), as a Markdown table.
pub fn markdown_table(rows: &[ExperimentRow]) -> String {
    let mut keys: Vec<(String, f64)> = Vec::new();
    for r in rows {
        if !keys
            .iter()
            .any(|(s, g)| *s == r.system && *g == r.noise_gain)
        {
            keys.push((r.system.clone(), r.noise_gain));
        }
    }
    let mut out = String::from(
        "| system | noise gain | runs | nRMSE ekf | nRMSE ekf-blr | nRMSE ukf | nRMSE open-loop | nRMSE default mode | 2-sigma coverage | mean NEES | corr(q, x) ekf | corr(q, x) ekf-blr |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for (s, g) in keys {
        let sel: Vec<&ExperimentRow> = rows
            .iter()
            .filter(|r| r.system == s && r.noise_gain == g)
            .collect();
        let mean =
            |f: fn(&ExperimentRow) -> f64| sel.iter().map(|r| f(r)).sum::<f64>() / sel.len() as f64;
        out.push_str(&format!(
            "| {s} | {g} | {} | {:.4} | {:.4} | {:.4} | {:.4} | {:.4} | {:.1}% | {:.2} | {:.2} | {:.2} |\n",
            sel.len(),
            mean(|r| r.nrmse_ekf),
            mean(|r| r.nrmse_ekf_blr),
            mean(|r| r.nrmse_ukf),
            mean(|r| r.nrmse_open_loop),
            mean(|r| r.nrmse_default),
            100.0 * mean(|r| r.calibration_default.coverage_2sigma),
            mean(|r| r.calibration_default.mean_nees),
            mean(|r| r.noise_state_corr_ekf),
            mean(|r| r.noise_state_corr_ekf_blr),
        ));
    }
    out
}
