//! Fits a GP to a JSON data file and prints timing and likelihood as JSON, for
//! `benches/compare_sklearn.py`: `fit_timing DATA.json STARTS [REPEATS]`.
//! DATA.json = {"x": [...row-major...], "y": [...], "d": 4}.
use hbn_core::KernelSpec;
use hbn_gp::{GpParams, fit};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let path = args
        .get(1)
        .ok_or("usage: fit_timing DATA.json STARTS [REPEATS]")?;
    let starts: usize = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(1);
    let repeats: usize = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(1);
    let doc: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(path)?)?;
    let vec = |k: &str| -> Vec<f64> {
        doc[k]
            .as_array()
            .map(|a| a.iter().filter_map(|v| v.as_f64()).collect())
            .unwrap_or_default()
    };
    let (x, y) = (vec("x"), vec("y"));
    let d = doc["d"].as_u64().ok_or("d missing")? as usize;
    let mut p = GpParams::new(KernelSpec::se_ard(d));
    p.n_starts = starts;
    p.max_points = y.len();
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..repeats {
        let t = Instant::now();
        last = Some(fit(&p, &x, &y)?);
        times.push(t.elapsed().as_secs_f64());
    }
    let gp = last.ok_or("no fit")?;
    times.sort_by(f64::total_cmp);
    println!(
        "{}",
        serde_json::json!({"seconds_median": times[times.len() / 2], "seconds": times, "lml": gp.log_marginal_likelihood(),
            "evaluations": gp.report().evaluations, "length_scales": gp.length_scales(), "noise_variance": gp.noise_variance()})
    );
    Ok(())
}
