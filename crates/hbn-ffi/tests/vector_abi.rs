//! The vector C ABI, called from Rust: the estimates equal `VectorModel::estimate` bit for bit
//! (f64 tables, EKF and UKF), f32 tables stay close, a copied filter carries on as the
//! original, and every misuse returns its status (scalar and vector tables each refused by the
//! other's filter).

use hbn_core::Mode;
use hbn_core::vector::Dims;
use hbn_export::{model_tables, vector_model_tables};
use hbn_ffi::*;
use hbn_model::{HbnParams, HysteresisModel, Sequence, VectorModel, VectorSequence};
use hbn_sim::{MultiConfig, MultiKind, simulate_multi_random};

/// A finger run: `(u, x, y)` row-major.
fn run(seed: u64, steps: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut cfg = MultiConfig::new(MultiKind::Finger);
    cfg.noise_gain = 1.0;
    cfg.seed = seed;
    let t = simulate_multi_random(&cfg, steps).unwrap();
    let rows = |s: &[Vec<f64>]| -> Vec<f64> {
        (0..s[0].len())
            .flat_map(|k| s.iter().map(move |c| c[k]))
            .collect()
    };
    (rows(&t.u), rows(&t.x), rows(&t.y))
}

fn dims() -> Dims {
    let k = MultiKind::Finger;
    Dims::new(k.inputs(), k.states(), k.sensors()).unwrap()
}

fn model() -> VectorModel {
    let (u, x, y) = run(1, 600);
    let params = HbnParams {
        n_inducing: Some(16),
        n_starts: 1,
        max_iters: 30,
        ..HbnParams::default()
    };
    VectorModel::fit(&[VectorSequence::new(&u, &x, &y, dims())], &params).unwrap()
}

fn data(layout: &[u32], keys: &[u64], f64s: Option<&[f64]>, f32s: Option<&[f32]>) -> HbnModelData {
    HbnModelData {
        layout: layout.as_ptr(),
        layout_len: layout.len(),
        keys: keys.as_ptr(),
        keys_len: keys.len(),
        reals_f64: f64s.map_or(std::ptr::null(), <[f64]>::as_ptr),
        reals_f32: f32s.map_or(std::ptr::null(), <[f32]>::as_ptr),
        reals_len: f64s.map_or(0, <[f64]>::len) + f32s.map_or(0, <[f32]>::len),
    }
}

fn zeroed() -> Box<HbnVectorFilter> {
    Box::new(HbnVectorFilter {
        opaque: [0; HBN_VECTOR_FILTER_WORDS],
    })
}

#[test]
fn the_vector_abi_reproduces_the_model_and_reports_misuse() {
    let m = model();
    let d = dims();
    let (ut, xt, mut yt) = run(5, 300);
    yt[40 * d.sensors + 2] = f64::NAN;
    for mode in [Mode::Ekf, Mode::Ukf] {
        let t = vector_model_tables(&m, mode).unwrap();
        let r32 = t.reals_f32().unwrap();
        let est = m.estimate(&ut, &yt, mode).unwrap();
        for f32_tables in [false, true] {
            let data = if f32_tables {
                data(&t.layout, &[], None, Some(&r32))
            } else {
                data(&t.layout, &[], Some(&t.reals), None)
            };
            let n = unsafe { hbn_vector_work_len(&data) };
            assert!(n > 0);
            // The scalar API does not take a vector model's tables.
            assert_eq!(unsafe { hbn_work_len(&data) }, 0);
            let mut work = vec![0.0; n];
            let mut filter = zeroed();
            let mut out = HbnVectorOutput::default();
            let (u0, y0) = (&ut[..d.inputs], &yt[..d.sensors]);
            assert_eq!(
                unsafe { hbn_vector_filter_step(&mut *filter, u0.as_ptr(), y0.as_ptr(), &mut out) },
                HbnStatus::NotInitialised
            );
            assert_eq!(
                unsafe { hbn_vector_filter_init(&mut *filter, &data, work.as_mut_ptr(), n - 1) },
                HbnStatus::WorkTooSmall
            );
            assert_eq!(
                unsafe { hbn_vector_filter_init(&mut *filter, &data, work.as_mut_ptr(), n) },
                HbnStatus::Ok
            );
            assert_eq!(
                unsafe {
                    hbn_vector_filter_step(&mut *filter, std::ptr::null(), y0.as_ptr(), &mut out)
                },
                HbnStatus::NullPointer
            );
            let mut outs = Vec::new();
            for (u, y) in ut.chunks_exact(d.inputs).zip(yt.chunks_exact(d.sensors)) {
                assert_eq!(
                    unsafe {
                        hbn_vector_filter_step(&mut *filter, u.as_ptr(), y.as_ptr(), &mut out)
                    },
                    HbnStatus::Ok
                );
                outs.push(out);
            }
            for (k, o) in outs.iter().enumerate() {
                // Past the model's sizes: zeros.
                assert_eq!(o.x[d.states..], [0.0; HBN_MAX_STATES][d.states..]);
                assert_eq!(o.y_pred[d.sensors..], [0.0; HBN_MAX_SENSORS][d.sensors..]);
                for i in 0..d.states {
                    let (x, s) = (est.x[k * d.states + i], est.x_std[k * d.states + i]);
                    if f32_tables {
                        let xi: Vec<f64> = xt.iter().skip(i).step_by(d.states).copied().collect();
                        let span = xi.iter().cloned().fold(f64::MIN, f64::max)
                            - xi.iter().cloned().fold(f64::MAX, f64::min);
                        assert!((o.x[i] - x).abs() < 0.02 * span, "{mode} k={k} x{i}");
                    } else {
                        assert_eq!(o.x[i].to_bits(), x.to_bits(), "{mode} k={k} x{i}");
                        assert_eq!(o.x_std[i].to_bits(), s.to_bits(), "{mode} k={k} std{i}");
                        for j in 0..d.states {
                            let c = est.x_cov[k * d.states * d.states + i * d.states + j];
                            assert_eq!(o.x_cov[i][j].to_bits(), c.to_bits(), "{mode} k={k}");
                        }
                    }
                }
                if !f32_tables {
                    assert_eq!(o.flags, est.flags[k], "{mode} k={k}");
                    assert_eq!(o.nis.to_bits(), est.nis[k].to_bits(), "{mode} k={k}");
                    for j in 0..d.sensors {
                        let p = est.y_pred[k * d.sensors + j];
                        assert_eq!(o.y_pred[j].to_bits(), p.to_bits(), "{mode} k={k}");
                    }
                }
            }
            // Reset: the next step is a first sample again.
            assert_eq!(
                unsafe { hbn_vector_filter_reset(&mut *filter) },
                HbnStatus::Ok
            );
            unsafe { hbn_vector_filter_step(&mut *filter, u0.as_ptr(), y0.as_ptr(), &mut out) };
            assert_eq!(out, outs[0]);
            // A copy of an initialised filter carries on as the original.
            let mut copy = Box::new(*filter);
            let (u1, y1) = (&ut[d.inputs..2 * d.inputs], &yt[d.sensors..2 * d.sensors]);
            let (mut a, mut b) = (HbnVectorOutput::default(), HbnVectorOutput::default());
            unsafe { hbn_vector_filter_step(&mut *filter, u1.as_ptr(), y1.as_ptr(), &mut a) };
            unsafe { hbn_vector_filter_step(&mut *copy, u1.as_ptr(), y1.as_ptr(), &mut b) };
            assert_eq!(a, b);
            assert_eq!(a, outs[1]);
        }
    }
    // A scalar model's tables are not a vector model, and the scalar filter refuses vector
    // tables.
    let (u, x, y) = run(3, 300);
    let params = HbnParams {
        n_inducing: Some(8),
        n_starts: 1,
        max_iters: 20,
        ..HbnParams::default()
    };
    let pick = |v: &[f64], w: usize| -> Vec<f64> { v.iter().step_by(w).copied().collect() };
    let (u0, x0, y0) = (pick(&u, d.inputs), pick(&x, d.states), pick(&y, d.sensors));
    let scalar = HysteresisModel::fit(&[Sequence::new(&u0, &x0, &y0)], &params).unwrap();
    let st = model_tables(&scalar, Mode::Ekf).unwrap();
    let sdata = data(&st.layout, &st.keys, Some(&st.reals), None);
    assert_eq!(unsafe { hbn_vector_work_len(&sdata) }, 0);
    let mut work = vec![0.0; 100_000];
    let mut filter = zeroed();
    assert_eq!(
        unsafe { hbn_vector_filter_init(&mut *filter, &sdata, work.as_mut_ptr(), work.len()) },
        HbnStatus::BadModel
    );
    let vt = vector_model_tables(&m, Mode::Ekf).unwrap();
    let vdata = data(&vt.layout, &[], Some(&vt.reals), None);
    let mut scalar_filter = HbnFilter {
        opaque: [0; HBN_FILTER_WORDS],
    };
    assert_eq!(
        unsafe { hbn_filter_init(&mut scalar_filter, &vdata, work.as_mut_ptr(), work.len()) },
        HbnStatus::BadModel
    );
    assert_eq!(
        unsafe { hbn_vector_filter_init(&mut *filter, std::ptr::null(), work.as_mut_ptr(), 1) },
        HbnStatus::NullPointer
    );
    assert_eq!(unsafe { hbn_vector_work_len(std::ptr::null()) }, 0);
    assert_eq!(
        unsafe { hbn_vector_filter_reset(std::ptr::null_mut()) },
        HbnStatus::NullPointer
    );
    // A failed init leaves the filter not initialised.
    let mut bad = vt.layout.clone();
    bad[0] ^= 1;
    let bdata = data(&bad, &[], Some(&vt.reals), None);
    assert_eq!(
        unsafe { hbn_vector_filter_init(&mut *filter, &bdata, work.as_mut_ptr(), work.len()) },
        HbnStatus::BadModel
    );
    let mut out = HbnVectorOutput::default();
    let (u0, y0) = (&u[..d.inputs], &y[..d.sensors]);
    assert_eq!(
        unsafe { hbn_vector_filter_step(&mut *filter, u0.as_ptr(), y0.as_ptr(), &mut out) },
        HbnStatus::NotInitialised
    );
}
