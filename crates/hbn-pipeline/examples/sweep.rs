//! The noise sweep of docs/results.md (thesis Table 2 protocol; Table 1 is its gain-1 rows):
//! `cargo run --release -p hbn-pipeline --example sweep -- OUT.json [systems] [gains] [seeds]`.
use hbn_pipeline::experiment::{ExperimentConfig, markdown_table, run};
use hbn_sim::SystemKind;

fn list<T: std::str::FromStr>(arg: Option<&String>, default: Vec<T>) -> Vec<T> {
    arg.map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect())
        .unwrap_or(default)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let out = args
        .get(1)
        .ok_or("usage: sweep OUT.json [systems] [gains] [seeds]")?;
    let cfg = ExperimentConfig {
        systems: list(
            args.get(2),
            vec![SystemKind::MaxwellSlip, SystemKind::GeneralizedPi],
        ),
        noise_gains: list(args.get(3), vec![0.0, 0.5, 1.0, 2.0, 5.0, 10.0]),
        seeds: list(args.get(4), vec![1, 2, 3]),
        ..ExperimentConfig::default()
    };
    let rows = run(&cfg, &mut |e| {
        let hbn_pipeline::Event::ExperimentCase { row: r, .. } = e else {
            return;
        };
        eprintln!(
            "{} gain {} seed {}: ekf {:.4} ekf+blr {:.4} open {:.4}",
            r.system, r.noise_gain, r.seed, r.nrmse_ekf, r.nrmse_ekf_blr, r.nrmse_open_loop
        )
    })?;
    hbn_fs::write_atomic(
        out.as_ref(),
        serde_json::to_string_pretty(&rows)?.as_bytes(),
    )?;
    println!("{}", markdown_table(&rows));
    Ok(())
}
