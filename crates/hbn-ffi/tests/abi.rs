//! The C ABI, called from Rust: the estimates equal the model's own bit for bit (f64 tables),
//! and every misuse returns its status.

use hbn_core::Mode;
use hbn_export::model_tables;
use hbn_ffi::*;
use hbn_model::{HbnParams, HysteresisModel, Sequence};
use hbn_sim::{SimConfig, SystemKind, simulate_random};

fn model() -> HysteresisModel {
    let cfg = SimConfig {
        noise_gain: 1.0,
        ..SimConfig::new(SystemKind::BoucWen)
    };
    let log = simulate_random(&cfg, 400).unwrap();
    let params = HbnParams {
        n_inducing: Some(16),
        n_starts: 1,
        max_iters: 40,
        ..HbnParams::default()
    };
    HysteresisModel::fit(&[Sequence::new(&log.u, &log.x, &log.y)], &params).unwrap()
}

fn zeroed() -> HbnFilter {
    HbnFilter {
        opaque: [0; HBN_FILTER_WORDS],
    }
}

#[test]
fn c_abi_reproduces_the_model_and_reports_misuse() {
    let m = model();
    let test = simulate_random(
        &SimConfig {
            noise_gain: 1.0,
            seed: 5,
            ..SimConfig::new(SystemKind::BoucWen)
        },
        200,
    )
    .unwrap();
    for mode in Mode::ALL {
        let t = model_tables(&m, mode).unwrap();
        let r32 = t.reals_f32().unwrap();
        let est = m.estimate(&test.u, &test.y, mode).unwrap();
        for f32_tables in [false, true] {
            let data = HbnModelData {
                layout: t.layout.as_ptr(),
                layout_len: t.layout.len(),
                keys: t.keys.as_ptr(),
                keys_len: t.keys.len(),
                reals_f64: if f32_tables {
                    std::ptr::null()
                } else {
                    t.reals.as_ptr()
                },
                reals_f32: if f32_tables {
                    r32.as_ptr()
                } else {
                    std::ptr::null()
                },
                reals_len: if f32_tables { r32.len() } else { t.reals.len() },
            };
            let n = unsafe { hbn_work_len(&data) };
            assert!(n > 0);
            let mut work = vec![0.0; n];
            let mut filter = zeroed();
            let mut out = HbnOutput::default();
            // Not initialised yet.
            assert_eq!(
                unsafe { hbn_filter_step(&mut filter, 0.0, 0.0, &mut out) },
                HbnStatus::NotInitialised
            );
            // Too little work memory.
            assert_eq!(
                unsafe { hbn_filter_init(&mut filter, &data, work.as_mut_ptr(), n - 1) },
                HbnStatus::WorkTooSmall
            );
            assert_eq!(
                unsafe { hbn_filter_init(&mut filter, &data, work.as_mut_ptr(), n) },
                HbnStatus::Ok
            );
            for (k, (&u, &y)) in test.u.iter().zip(&test.y).enumerate() {
                assert_eq!(
                    unsafe { hbn_filter_step(&mut filter, u, y, &mut out) },
                    HbnStatus::Ok
                );
                if f32_tables {
                    // Accuracy of f32 tables: hbn-export's and tests/firmware.rs' tests (this
                    // small model is poorly conditioned).
                    assert!(out.x.is_finite() && out.x_std.is_finite(), "{mode} k={k}");
                } else {
                    assert_eq!(out.x.to_bits(), est.x[k].to_bits(), "{mode} k={k}");
                    assert_eq!(out.x_std.to_bits(), est.x_std[k].to_bits());
                    assert_eq!(out.flags, est.flags[k], "{mode} k={k}");
                }
            }
            assert_eq!(unsafe { hbn_filter_reset(&mut filter) }, HbnStatus::Ok);
            unsafe { hbn_filter_step(&mut filter, test.u[0], test.y[0], &mut out) };
            if !f32_tables {
                assert_eq!(out.x.to_bits(), est.x[0].to_bits());
            }
        }
    }
    // Bad tables and NULLs.
    let t = model_tables(&m, Mode::Ekf).unwrap();
    let mut layout = t.layout.clone();
    layout[0] = 7;
    let data = HbnModelData {
        layout: layout.as_ptr(),
        layout_len: layout.len(),
        keys: std::ptr::null(),
        keys_len: 0,
        reals_f64: t.reals.as_ptr(),
        reals_f32: std::ptr::null(),
        reals_len: t.reals.len(),
    };
    assert_eq!(unsafe { hbn_work_len(&data) }, 0);
    let mut work = vec![0.0; 100_000];
    let mut filter = zeroed();
    assert_eq!(
        unsafe { hbn_filter_init(&mut filter, &data, work.as_mut_ptr(), work.len()) },
        HbnStatus::BadModel
    );
    assert_eq!(
        unsafe { hbn_filter_init(&mut filter, std::ptr::null(), work.as_mut_ptr(), 1) },
        HbnStatus::NullPointer
    );
    assert_eq!(unsafe { hbn_work_len(std::ptr::null()) }, 0);
    let name = unsafe { std::ffi::CStr::from_ptr(hbn_status_name(HbnStatus::WorkTooSmall)) };
    assert!(name.to_str().unwrap().contains("work memory"));
}
