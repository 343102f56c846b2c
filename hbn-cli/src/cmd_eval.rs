//! `hbn eval`: score the model's estimates against the logged state.

use anyhow::Context;
use hbn_core::Mode;
use hbn_model::metrics::{Calibration, calibration, nrmse, rmse};
use serde_json::{Map, Value, json};

use crate::Ui;
use crate::cli::{EvalArgs, EvalModeArg};
use crate::cmd_estimate::{load_model, mode_name, model_io_paths};
use crate::logdata::{self, ReadSettings};
use crate::plot::{self, EvalPlot, Series};

/// Scores of one method.
#[derive(Clone, Debug, PartialEq)]
pub struct Score {
    /// `ekf`, `ekf_blr` or `open_loop`.
    pub method: &'static str,
    /// RMSE.
    pub rmse: f64,
    /// nRMSE.
    pub nrmse: f64,
    /// Calibration of the estimate's standard deviation (`None` for open loop, which has none).
    pub calibration: Option<Calibration>,
}

/// The result of an evaluation.
#[derive(Clone, Debug, PartialEq)]
pub struct EvalResult {
    /// One score per method, EKF modes first, open loop last.
    pub scores: Vec<Score>,
    /// Samples compared.
    pub samples: usize,
    /// Grid rate (Hz).
    pub rate_hz: f64,
}

impl EvalResult {
    /// JSON: `{"rmse": {..}, "nrmse": {..}, "calibration": {method: {coverage_1sigma,
    /// coverage_2sigma, mean_nees, nlpd, samples}}, "samples": N, "rate_hz": ..}`.
    pub fn to_json(&self) -> Value {
        let mut r = Map::new();
        let mut n = Map::new();
        let mut c = Map::new();
        for s in &self.scores {
            r.insert(s.method.into(), json!(s.rmse));
            n.insert(s.method.into(), json!(s.nrmse));
            if let Some(cal) = &s.calibration {
                c.insert(s.method.into(), json!(cal));
            }
        }
        json!({"rmse": r, "nrmse": n, "calibration": c, "samples": self.samples,
               "rate_hz": self.rate_hz})
    }

    /// An aligned text table; the calibration columns say how often the truth lies within
    /// 1 and 2 standard deviations (about 68% and 95% when the uncertainty is honest) and the
    /// mean squared error in standard deviations (about 1 when honest).
    pub fn table(&self) -> String {
        let mut s = format!(
            "{:<10} {:>12} {:>10} {:>9} {:>9} {:>10} {:>9}\n",
            "method", "RMSE", "nRMSE", "in 1 sd", "in 2 sd", "mean NEES", "NLPD"
        );
        for sc in &self.scores {
            s.push_str(&format!(
                "{:<10} {:>12.6} {:>10.4}",
                sc.method, sc.rmse, sc.nrmse
            ));
            match &sc.calibration {
                Some(c) => s.push_str(&format!(
                    " {:>8.1}% {:>8.1}% {:>10.2} {:>9.3}\n",
                    100.0 * c.coverage_1sigma,
                    100.0 * c.coverage_2sigma,
                    c.mean_nees,
                    c.nlpd
                )),
                None => s.push_str(&format!(" {:>9} {:>9} {:>10} {:>9}\n", "-", "-", "-", "-")),
            }
        }
        s.push_str(&format!(
            "{} samples at {:.1} Hz; NEES = ((x - x_hat) / x_std)^2, NLPD = negative log \
             predictive density (lower is better)\n",
            self.samples, self.rate_hz
        ));
        s
    }
}

fn key(m: Mode) -> &'static str {
    match m {
        Mode::Ekf => "ekf",
        Mode::EkfBlr => "ekf_blr",
    }
}

/// Runs `hbn eval`.
pub fn run(ui: &mut Ui<'_>, args: &EvalArgs) -> anyhow::Result<EvalResult> {
    if let Some(p) = &args.plot {
        crate::check_output(p, "plot")?;
    }
    let model = load_model(&args.model)?;
    let (u, y) = model_io_paths(
        &model,
        &args.model,
        args.input.as_ref(),
        args.output.as_ref(),
    )?;
    let x = match &args.state {
        Some(p) => p.clone(),
        None => logdata::model_path(
            model.signals().state.path.as_deref(),
            "/state.data",
            &args.model,
        )?,
    };
    let settings = ReadSettings::from(&args.read);
    let log = logdata::load(ui, &args.log, &[u, x, y], Some(model.rate_hz()), &settings)?;
    let (uu, xr, yy) = (log.column(0), log.column(1), log.column(2));
    let modes: &[Mode] = match args.mode {
        EvalModeArg::Ekf => &[Mode::Ekf],
        EvalModeArg::EkfBlr => &[Mode::EkfBlr],
        EvalModeArg::All => &[Mode::Ekf, Mode::EkfBlr],
    };
    let mut scores = Vec::new();
    let mut estimates = Vec::new();
    for &m in modes {
        let est = model
            .estimate(uu, yy, m)
            .with_context(|| format!("estimation ({}) failed", mode_name(m)))?;
        scores.push(Score {
            method: key(m),
            rmse: rmse(&est.x, xr),
            nrmse: nrmse(&est.x, xr),
            calibration: Some(calibration(&est.x, &est.x_std, xr)),
        });
        estimates.push((m, est));
    }
    let open = model
        .simulate_open_loop(uu)
        .context("open-loop simulation failed")?;
    scores.push(Score {
        method: "open_loop",
        rmse: rmse(&open, xr),
        nrmse: nrmse(&open, xr),
        calibration: None,
    });
    let result = EvalResult {
        scores,
        samples: log.len(),
        rate_hz: model.rate_hz(),
    };
    if let Some(p) = &args.plot {
        let series: Vec<Series<'_>> = estimates
            .iter()
            .map(|(m, e)| Series {
                label: mode_name(*m),
                x: &e.x,
                x_std: Some(&e.x_std),
            })
            .chain(std::iter::once(Series {
                label: "open loop",
                x: &open,
                x_std: None,
            }))
            .collect();
        plot::eval_plot(
            p,
            &EvalPlot {
                title: &format!("{} on {}", args.model.display(), args.log.display()),
                t: &log.aligned.t_s,
                u: uu,
                x_ref: xr,
                y: yy,
                estimates: &series,
            },
        )?;
    }
    if args.json {
        ui.line(serde_json::to_string_pretty(&result.to_json()).context("cannot format JSON")?)?;
    } else {
        ui.print(result.table())?;
        if let Some(p) = &args.plot {
            ui.line(format!("wrote plot `{}`", p.display()))?;
        }
    }
    Ok(result)
}
