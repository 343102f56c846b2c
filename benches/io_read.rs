//! Reading + resampling a 1,000,000-message MCAP log (3 topics), JSON and ROS 2 CDR.
use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use hbn::io::{
    Encoding, ReadOptions, ResampleOptions, ScalarTopic, SignalPath, read_signals, resample,
    write_scalar_log,
};

const N: usize = 1_000_000 / 3 + 1; // time stamps; 3 topics -> ~1,000,000 messages

fn bench_read(c: &mut Criterion) {
    let dir = match tempfile::tempdir() {
        Ok(d) => d,
        Err(e) => panic!("temp dir: {e}"),
    };
    let t0: u64 = 1_700_000_000_000_000_000;
    let t: Vec<u64> = (0..N as u64).map(|k| t0 + k * 10_000_000).collect();
    let u: Vec<f64> = (0..N).map(|k| (k as f64 * 0.01).sin()).collect();
    let x: Vec<f64> = (0..N).map(|k| (k as f64 * 0.003).cos()).collect();
    let y: Vec<f64> = (0..N).map(|k| k as f64 * 1e-4).collect();
    let topics = [
        ScalarTopic {
            topic: "/input",
            values: &u,
        },
        ScalarTopic {
            topic: "/state",
            values: &x,
        },
        ScalarTopic {
            topic: "/sensor",
            values: &y,
        },
    ];
    let paths: Vec<SignalPath> = ["/input.data", "/state.data", "/sensor.data"]
        .iter()
        .filter_map(|p| p.parse().ok())
        .collect();
    let mut g = c.benchmark_group("io_read");
    g.sample_size(10);
    for (name, enc) in [("ros2_cdr", Encoding::Ros2), ("json", Encoding::Json)] {
        let file = dir.path().join(format!("bench_{name}.mcap"));
        if let Err(e) = write_scalar_log(&file, &t, &topics, enc) {
            panic!("writing the bench log: {e}");
        }
        g.bench_function(format!("read_resample_1M_{name}"), |b| {
            b.iter(|| {
                let sigs = match read_signals(&file, &paths, &ReadOptions::default()) {
                    Ok(s) => s,
                    Err(e) => panic!("{e}"),
                };
                let a = match resample(&sigs, &ResampleOptions::new(100.0)) {
                    Ok(a) => a,
                    Err(e) => panic!("{e}"),
                };
                black_box(a.t_s.len())
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench_read);
criterion_main!(benches);
