//! A scalar model's export is pinned: the files `hbn export` writes for the fixture model
//! (`fixtures/scalar.hbn`, a sparse model with 8 inducing points trained on a simulated Bouc-Wen
//! log) hash to the reference values below, and its size report is the reference one. Vector
//! models share the tables' code and the generators; this test shows that a scalar model's
//! firmware (its source text, flash and RAM) stays what it is. A deliberate change to the
//! scalar tables or sources updates these values (and says why in its commit).

use std::path::Path;

use hbn_core::Mode;
use hbn_export::{Format, Precision, export, size_report};
use hbn_model::HysteresisModel;

/// 64-bit FNV-1a of `bytes`.
fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

fn fixture() -> HysteresisModel {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/scalar.hbn");
    HysteresisModel::load(&path).expect("the fixture model loads")
}

#[test]
fn the_scalar_export_writes_the_reference_files() {
    let model = fixture();
    // (mode, format, precision, file, length, FNV-1a)
    let reference: [(Mode, Format, Precision, &str, usize, u64); 8] = [
        (
            Mode::Ekf,
            Format::C,
            Precision::F64,
            "hbn_model.h",
            1025,
            0x526ce76e5bc0bcd4,
        ),
        (
            Mode::Ekf,
            Format::C,
            Precision::F64,
            "hbn_model.c",
            18624,
            0xc643630213f1b6c4,
        ),
        (
            Mode::Ekf,
            Format::C,
            Precision::F32,
            "hbn_model.h",
            1026,
            0x0e3dd54a15cae513,
        ),
        (
            Mode::Ekf,
            Format::C,
            Precision::F32,
            "hbn_model.c",
            14672,
            0x3c655ad8cfe3e921,
        ),
        (
            Mode::Ekf,
            Format::Rust,
            Precision::F64,
            "hbn_model.rs",
            19331,
            0xbbb7e92f29c47bfb,
        ),
        (
            Mode::Ekf,
            Format::Rust,
            Precision::F32,
            "hbn_model.rs",
            14424,
            0x495ed251cb05b9f2,
        ),
        (
            Mode::EkfBlr,
            Format::C,
            Precision::F32,
            "hbn_model.h",
            1039,
            0x54ce500819371629,
        ),
        (
            Mode::EkfBlr,
            Format::C,
            Precision::F32,
            "hbn_model.c",
            56354,
            0x16bbebaa3a4be261,
        ),
    ];
    for (mode, format, precision, name, len, hash) in reference {
        let files = export(&model, mode, format, precision, None, "scalar.hbn").expect("export");
        let file = files
            .iter()
            .find(|f| f.name == name)
            .expect("the export writes the file");
        let what = format!("{mode} {} {} {name}", format.name(), precision.name());
        assert_eq!(file.text.len(), len, "{what}: length");
        assert_eq!(fnv1a(file.text.as_bytes()), hash, "{what}: content");
    }
}

#[test]
fn the_scalar_size_report_is_the_reference() {
    let model = fixture();
    // (precision, init pairs, mode, flash bytes, RAM bytes)
    let reference = [
        (Precision::F32, None, Mode::Ekf, 4172, 6800),
        (Precision::F32, None, Mode::EkfBlr, 17892, 28424),
        (Precision::F32, None, Mode::Ukf, 4172, 6800),
        (Precision::F64, None, Mode::Ekf, 6844, 128),
        (Precision::F64, None, Mode::EkfBlr, 31292, 128),
        (Precision::F64, None, Mode::Ukf, 6844, 128),
        (Precision::F32, Some(50), Mode::Ekf, 2172, 2800),
    ];
    for (precision, pairs, mode, flash, ram) in reference {
        let sizes = size_report(&model, precision, pairs).expect("size report");
        let s = sizes.iter().find(|s| s.mode == mode).expect("every mode");
        assert_eq!(
            (s.model_bytes, s.work_bytes()),
            (flash, ram),
            "{mode} {} {pairs:?}",
            precision.name()
        );
    }
}
