//! Time of one evaluation of the sparse GP's collapsed bound with its gradient (no
//! optimisation, so the figure does not depend on the optimiser's path):
//! `cargo run --release -p hbn-gp --example bound_eval -- [N] [M] [D] [REPEATS]`
//! (defaults 100000, 128, 6, 5). Random standardised inputs, a smooth target, SE-ARD.
use hbn_core::KernelSpec;
use hbn_gp::likelihood::LikelihoodData;
use hbn_gp::sparse::SparseBound;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let n = args.first().copied().unwrap_or(100_000);
    let m = args.get(1).copied().unwrap_or(128);
    let d = args.get(2).copied().unwrap_or(6);
    let repeats = args.get(3).copied().unwrap_or(5);
    // A fixed pseudo-random design (an LCG, so the run is reproducible without a dependency).
    let mut state = 12345u64;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    };
    let x: Vec<f64> = (0..n * d).map(|_| 1.7 * next()).collect();
    let y: Vec<f64> = x
        .chunks_exact(d)
        .map(|r| {
            r.iter()
                .enumerate()
                .map(|(j, v)| (v * (j + 1) as f64).sin())
                .sum::<f64>()
                / d as f64
        })
        .collect();
    let directions = vec![0.0; n];
    let z: Vec<f64> = x[..m * d].to_vec();
    let spec = KernelSpec::se_ard(d);
    let data = LikelihoodData {
        spec,
        whiten: &[],
        x: &x,
        directions: &directions,
        y: &y,
    };
    let bound = SparseBound::new(data, z, vec![0.0; m], false, 1e-6, 6);
    let mut p = vec![0.0; spec.n_params() + 1];
    p[spec.n_params()] = -4.0;
    let mut times = Vec::new();
    for r in 0..repeats {
        p[0] = 0.01 * r as f64; // a new point each time (the bound memoises the last)
        let t = Instant::now();
        let e = bound.evaluate(&p)?;
        times.push(t.elapsed().as_secs_f64());
        if r == 0 {
            println!("lml {:.6e}", e.lml);
        }
    }
    times.sort_by(f64::total_cmp);
    println!(
        "n = {n}, m = {m}, d = {d}: bound + gradient median {:.3} s (min {:.3}, max {:.3})",
        times[times.len() / 2],
        times[0],
        times[times.len() - 1]
    );
    Ok(())
}
