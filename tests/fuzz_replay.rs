//! Replays the committed fuzz corpora (`fuzz/corpus/<target>/`) and the inputs of every crash
//! the fuzzers found (`fuzz/regressions/<target>/`) through the same entry functions as the
//! cargo-fuzz targets, on stable, as ordinary tests. A panic here is a regression.

mod entries {
    #![allow(dead_code, clippy::needless_range_loop)]
    include!("../fuzz/src/entries.rs");
}

use std::path::Path;

fn replay(target: &str) -> usize {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz");
    let mut n = 0;
    for dir in ["corpus", "regressions"] {
        let Ok(rd) = std::fs::read_dir(root.join(dir).join(target)) else {
            continue;
        };
        let mut files: Vec<_> = rd.filter_map(|e| e.ok()).map(|e| e.path()).collect();
        files.sort();
        for f in files {
            // A fuzzer running beside the tests may remove inputs it has minimised away.
            let data = match std::fs::read(&f) {
                Ok(d) => d,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => continue,
                Err(e) => panic!("read corpus file {}: {e}", f.display()),
            };
            let r = std::panic::catch_unwind(|| entries::run_entry(target, &data));
            assert!(r.is_ok(), "{target}: {} panicked", f.display());
            n += 1;
        }
    }
    n
}

macro_rules! replay_test {
    ($($name:ident),*) => {$(
        #[test]
        fn $name() {
            let n = replay(stringify!($name));
            assert!(n > 0, "no corpus for {}", stringify!($name));
        }
    )*};
}

replay_test!(mcap_ingest, cdr, ros2msg, signal_path, model_load, step);

#[test]
fn every_target_is_replayed() {
    assert_eq!(
        entries::TARGETS,
        [
            "mcap_ingest",
            "cdr",
            "ros2msg",
            "signal_path",
            "model_load",
            "step"
        ]
    );
}
