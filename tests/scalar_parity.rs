//! A scalar model's estimates are pinned: `hbn estimate` on the fixture model and log must
//! write exactly the reference CSVs in `fixtures/scalar_parity` (every number is the shortest
//! text that reads back to the same `f64`, so equal text is equal bits), in every mode. The
//! vector model shares the GP code and the CLI with scalar models; this is what proves that a
//! scalar model keeps its estimates.
//!
//! The fixture was made with
//! `hbn simulate --system preisach --steps 800 --seed 5 --noise-gain 1 --out train.mcap`,
//! `hbn simulate --system preisach --steps 200 --seed 6 --noise-gain 1 --out test.mcap`,
//! `hbn train --log train.mcap --firmware-budget 16384 --out model.hbn` and
//! `hbn estimate --model model.hbn --log test.mcap --mode MODE --csv expected_MODE.csv`.
//! Regenerate it only for a change meant to move scalar estimates, and say so in CHANGELOG.md.

use std::path::PathBuf;

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures/scalar_parity")
        .join(name)
}

#[test]
fn a_scalar_models_estimates_are_the_reference_bit_for_bit() {
    let d = tempfile::tempdir().expect("tempdir");
    for mode in ["ekf", "ekf-blr", "ukf"] {
        let out = d.path().join(format!("{mode}.csv"));
        let (model, log) = (fixture("model.hbn"), fixture("test.mcap"));
        let args = [
            "hbn",
            "estimate",
            "--model",
            model.to_str().expect("utf-8"),
            "--log",
            log.to_str().expect("utf-8"),
            "--mode",
            mode,
            "--csv",
            out.to_str().expect("utf-8"),
        ];
        let (mut o, mut e) = (Vec::new(), Vec::new());
        hbn_cli::run_with(args, &mut o, &mut e).expect("estimate");
        let got = std::fs::read_to_string(&out).expect("csv");
        let want =
            std::fs::read_to_string(fixture(&format!("expected_{mode}.csv"))).expect("fixture");
        assert_eq!(got.lines().count(), want.lines().count(), "{mode}");
        for (k, (g, w)) in got.lines().zip(want.lines()).enumerate() {
            assert_eq!(g, w, "{mode}, line {k}");
        }
    }
}
