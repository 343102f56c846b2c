//! Fits a GP (SE-ARD plus noise, standardised targets) to a JSON data file and prints the
//! timing and the log marginal likelihood as one JSON object, for `benches/compare_sklearn.py`:
//!
//! ```text
//! fit_timing DATA.json [--starts N] [--repeats R]
//! ```
//!
//! DATA.json is `{"x": [...row-major...], "y": [...], "d": D}`; every sample is a support
//! point (`max_points` = n).
use clap::Parser;
use hbn_core::KernelSpec;
use hbn_gp::{GpParams, fit};
use std::path::PathBuf;
use std::time::Instant;

/// One GP fit timed, as JSON on stdout.
#[derive(Parser)]
struct Args {
    /// Data file: JSON with `x` (the inputs, row-major), `y` (the targets) and `d` (inputs per row).
    data: PathBuf,
    /// Optimiser starts.
    #[arg(long, default_value_t = 1)]
    starts: usize,
    /// Fits timed (the median is reported).
    #[arg(long, default_value_t = 1)]
    repeats: usize,
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&args.data)?)?;
    let vec = |k: &str| -> Vec<f64> {
        doc[k]
            .as_array()
            .map(|a| a.iter().filter_map(|v| v.as_f64()).collect())
            .unwrap_or_default()
    };
    let (x, y) = (vec("x"), vec("y"));
    let d = doc["d"].as_u64().ok_or("d missing")? as usize;
    let mut p = GpParams::new(KernelSpec::se_ard(d));
    p.n_starts = args.starts.max(1);
    p.max_points = y.len();
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..args.repeats.max(1) {
        let t = Instant::now();
        last = Some(fit(&p, &x, &y)?);
        times.push(t.elapsed().as_secs_f64());
    }
    let gp = last.ok_or("no fit")?;
    times.sort_by(f64::total_cmp);
    println!(
        "{}",
        serde_json::json!({
            "seconds_median": times[times.len() / 2],
            "seconds": times,
            "lml": gp.log_marginal_likelihood(),
            "evaluations": gp.report().evaluations,
            "length_scales": gp.length_scales(),
            "noise_variance": gp.noise_variance(),
        })
    );
    Ok(())
}
