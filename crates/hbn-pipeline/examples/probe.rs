//! Diagnostic for one experiment case: `probe SYSTEM GAIN SEED`; `INDUCING=m`, `LINEAR_MEAN=both`,
//! `MAX_SIGNAL_VARIANCE=v`,
//! `KERNEL=name` and `STRIDE=k` in the environment change the model and the printout.
use hbn_core::Mode;
use hbn_model::{HbnParams, HysteresisModel};
use hbn_pipeline::experiment::{ExperimentConfig, test_trajectory, training_set};
use hbn_pipeline::sequences;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let a: Vec<String> = std::env::args().collect();
    let system = a[1].parse()?;
    let gain: f64 = a[2].parse()?;
    let seed: u64 = a[3].parse()?;
    let cfg = ExperimentConfig::default();
    let train = training_set(system, gain, seed, &cfg)?;
    let test = test_trajectory(system, gain, seed, &cfg)?;
    let rng = |v: &[f64]| {
        v.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                (l.min(x), h.max(x))
            })
    };
    println!(
        "train u {:?} x {:?} y {:?}",
        rng(&train[0].u),
        rng(&train[0].x),
        rng(&train[0].y)
    );
    println!(
        "test  u {:?} x {:?} y {:?}",
        rng(&test.u),
        rng(&test.x),
        rng(&test.y)
    );
    let mut params = HbnParams {
        seed,
        ..cfg.params.clone()
    };
    if let Ok(m) = std::env::var("INDUCING") {
        params.n_inducing = m.parse().ok();
    }
    if let Ok(m) = std::env::var("LINEAR_MEAN") {
        params.linear_mean = m.parse()?;
    }
    if let Ok(v) = std::env::var("MAX_SIGNAL_VARIANCE") {
        params.max_signal_variance = Some(v.parse()?);
    }
    if let Ok(k) = std::env::var("KERNEL") {
        params.transition_kernel = k.parse()?;
        params.sensor_kernel = k.parse()?;
    }
    let model = HysteresisModel::fit(&sequences(&train), &params)?;
    let open = model.simulate_open_loop(&test.u)?;
    println!("warnings {:?}", model.summary().warnings);
    println!(
        "tr noise {:e} loo {:e}; se noise {:e} loo {:e}",
        model.transition().noise_variance(),
        model.transition().loo_error_variance(),
        model.sensor().noise_variance(),
        model.sensor().loo_error_variance()
    );
    for (name, gp) in [
        ("transition", model.transition()),
        ("sensor", model.sensor()),
    ] {
        let r = gp.report();
        println!(
            "{name}: theta {:?} noise {:e} final lml {:?} starts {:?} refinement {:?}",
            gp.theta(),
            gp.noise_variance(),
            r.starts.iter().map(|s| s.final_lml).collect::<Vec<_>>(),
            r.starts.iter().map(|s| s.iterations).collect::<Vec<_>>(),
            r.refinement.as_ref().map(|s| (s.final_lml, s.iterations))
        );
    }
    let est = model.estimate(&test.u, &test.y, Mode::Ekf)?;
    let stride: usize = std::env::var("STRIDE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(50);
    for k in (0..test.u.len()).step_by(stride).take(60) {
        println!(
            "{k:4} u {:.3} x {:.3} est {:.3} +- {:.3} y {:.3} ypred {:.3} flags {:?}",
            test.u[k],
            test.x[k],
            est.x[k],
            est.x_std[k],
            test.y[k],
            est.y_pred[k],
            hbn_core::Flags(est.flags[k]).names().collect::<Vec<_>>()
        );
    }
    println!("{:?}", est.flag_counts());
    let blr = model.estimate(&test.u, &test.y, Mode::EkfBlr)?;
    println!(
        "nrmse ekf {:.4} blr {:.4} open {:.4}",
        hbn_model::metrics::nrmse(&est.x, &test.x),
        hbn_model::metrics::nrmse(&blr.x, &test.x),
        hbn_model::metrics::nrmse(&open, &test.x)
    );
    Ok(())
}
