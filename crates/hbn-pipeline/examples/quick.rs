//! Quick accuracy survey: `cargo run --release -p hbn-pipeline --example quick -- [gain] [kernel]`.
use hbn_pipeline::experiment::{ExperimentConfig, markdown_table, run};
use hbn_sim::SystemKind;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let gain: f64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(1.0);
    let mut cfg = ExperimentConfig {
        systems: SystemKind::ALL.to_vec(),
        seeds: vec![1],
        noise_gains: vec![gain],
        ..ExperimentConfig::default()
    };
    if let Some(nu) = args.get(3).and_then(|s| s.parse().ok()) {
        cfg.params.blr.nu0 = nu;
    }
    if let Some(k) = args.get(2).filter(|k| *k != "-") {
        let k = k.parse().expect("kernel");
        cfg.params.transition_kernel = k;
        cfg.params.sensor_kernel = k;
    }
    let rows = run(&cfg, &mut |e| {
        let hbn_pipeline::Event::ExperimentCase { row: r, .. } = e else {
            return;
        };
        eprintln!(
            "{} seed {} gain {}: ekf {:.4} blr {:.4} open {:.4} ({:.1}s)",
            r.system,
            r.seed,
            r.noise_gain,
            r.nrmse_ekf,
            r.nrmse_ekf_blr,
            r.nrmse_open_loop,
            r.train_seconds
        )
    })
    .expect("experiment");
    println!("{}", markdown_table(&rows));
}
