//! A vector model's tables: the step on the `f64` tables equals `VectorModel::estimate` bit for
//! bit (EKF and UKF, sparse and exact GPs), the `f32` tables stay close, the scratch size reads
//! from the layout, the generated sources carry the sizes, the size report adds up, and corrupt
//! or foreign tables are refused.

use hbn_core::tables::{self, Tables, VectorTables};
use hbn_core::vector::{Dims, VectorEstimator};
use hbn_core::{CoreError, Mode};
use hbn_export::{
    ExportError, Format, ModelTables, Precision, VECTOR_MODES, export_vector,
    vector_f32_variance_errors, vector_model_tables, vector_size_report, vector_size_table,
};
use hbn_model::{HbnParams, Selection, VectorModel, VectorSequence};
use hbn_sim::{MultiConfig, MultiKind, simulate_multi_random};

/// Row-major `(T, d)` from component-major signals.
fn rows(signals: &[Vec<f64>]) -> Vec<f64> {
    let t = signals[0].len();
    (0..t)
        .flat_map(|k| signals.iter().map(move |s| s[k]))
        .collect()
}

/// A finger run: `(u, x, y)` row-major.
fn run(seed: u64, steps: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let mut cfg = MultiConfig::new(MultiKind::Finger);
    cfg.noise_gain = 1.0;
    cfg.seed = seed;
    let t = simulate_multi_random(&cfg, steps).unwrap();
    (rows(&t.u), rows(&t.x), rows(&t.y))
}

fn dims() -> Dims {
    let k = MultiKind::Finger;
    Dims::new(k.inputs(), k.states(), k.sensors()).unwrap()
}

/// A finger model: sparse with `inducing` points, or exact on at most 120 points.
fn model(inducing: Option<usize>) -> VectorModel {
    model_with(inducing, None)
}

/// [`model`] with the lag set given (`Some`: that set alone, no selection).
fn model_with(inducing: Option<usize>, lags: Option<Vec<f64>>) -> VectorModel {
    let (u, x, y) = run(1, 800);
    let d = HbnParams::default();
    let params = HbnParams {
        max_points: 120,
        n_inducing: inducing,
        n_starts: 1,
        max_iters: 30,
        lags: lags.clone().unwrap_or_default(),
        select: match lags {
            Some(_) => Selection {
                lags: Vec::new(),
                ..d.select.clone()
            },
            None => d.select.clone(),
        },
        ..d
    };
    VectorModel::fit(&[VectorSequence::new(&u, &x, &y, dims())], &params).unwrap()
}

/// The f32 tables of `t` as a firmware reads them: rounded to f32, widened back to f64.
fn widened(t: &ModelTables) -> Vec<f64> {
    let r32 = t.reals_f32().unwrap();
    let mut wide = vec![0.0; tables::widen_scratch(&t.layout, r32.len()).unwrap()];
    tables::widen(&t.layout, &r32, &mut wide).unwrap();
    wide
}

/// The step over `u`, `y` on tables with `reals`: `(x, x_std, flags)` per sample.
fn steps(t: &ModelTables, reals: &[f64], u: &[f64], y: &[f64]) -> Vec<(Vec<f64>, Vec<f64>, u32)> {
    let d = dims();
    let tm = VectorTables {
        layout: &t.layout,
        reals,
    }
    .model()
    .unwrap();
    let mut scratch = vec![0.0; tables::vector_scratch_len(&t.layout).unwrap()];
    assert_eq!(scratch.len(), tm.scratch_len());
    let mut e = VectorEstimator::new(tm.view(), tm.config, &mut scratch).unwrap();
    u.chunks_exact(d.inputs)
        .zip(y.chunks_exact(d.sensors))
        .map(|(u, y)| {
            let o = e.step(u, y);
            (
                o.x[..d.states].to_vec(),
                o.x_std[..d.states].to_vec(),
                o.flags.0,
            )
        })
        .collect()
}

#[test]
fn vector_tables_reproduce_the_model() {
    let d = dims();
    let (ut, xt, mut yt) = run(9, 400);
    // A missing sensor sample is left out of that step's update, on the tables as in the model.
    yt[50 * d.sensors + 1] = f64::NAN;
    let lagged = model_with(Some(16), Some(vec![0.1]));
    assert_eq!(lagged.lags(), [0.1]);
    for m in [model(Some(16)), model(None), lagged] {
        for mode in VECTOR_MODES {
            let est = m.estimate(&ut, &yt, mode).unwrap();
            let t = vector_model_tables(&m, mode).unwrap();
            assert!(t.keys.is_empty());
            let tm = t.vector_tables().model().unwrap();
            assert_eq!(tm.config, m.config(mode));
            assert_eq!(tm.dims, d);
            assert!(tm.init.is_some());
            // The memory operators, lags among them, travel with the tables.
            assert_eq!(tm.view().plays, m.plays().unwrap());
            let got = steps(&t, &t.reals, &ut, &yt);
            assert_eq!(got.len(), est.len());
            for (k, (x, s, flags)) in got.iter().enumerate() {
                for i in 0..d.states {
                    let j = k * d.states + i;
                    assert_eq!(x[i].to_bits(), est.x[j].to_bits(), "{mode} k={k} x{i}");
                    assert_eq!(
                        s[i].to_bits(),
                        est.x_std[j].to_bits(),
                        "{mode} k={k} std{i}"
                    );
                }
                assert_eq!(*flags, est.flags[k], "{mode} k={k}");
            }
            // f32: within 2% of each component's range of the f64 estimate.
            let wide = widened(&t);
            let got = steps(&t, &wide, &ut, &yt);
            for i in 0..d.states {
                let xi: Vec<f64> = xt.iter().skip(i).step_by(d.states).copied().collect();
                let span = xi.iter().cloned().fold(f64::MIN, f64::max)
                    - xi.iter().cloned().fold(f64::MAX, f64::min);
                let worst = got
                    .iter()
                    .enumerate()
                    .map(|(k, (x, _, _))| (x[i] - est.x[k * d.states + i]).abs())
                    .fold(0.0, f64::max);
                eprintln!("{mode} x{i}: f32 off by {:.2e} of the range", worst / span);
                assert!(
                    worst < 0.02 * span,
                    "{mode} x{i}: f32 off by {worst} of {span}"
                );
            }
        }
    }
}

#[test]
fn vector_exports_carry_the_sizes_and_sizes_add_up() {
    let m = model(Some(16));
    let d = m.dims();
    for precision in [Precision::F64, Precision::F32] {
        let files = export_vector(&m, Mode::Ekf, Format::C, precision, None, "finger.hbn").unwrap();
        let names: Vec<_> = files.iter().map(|f| f.name).collect();
        assert_eq!(names, ["hbn_model.h", "hbn_model.c"]);
        let h = &files[0].text;
        for (name, v) in [
            ("HBN_MODEL_INPUTS", d.inputs),
            ("HBN_MODEL_STATES", d.states),
            ("HBN_MODEL_SENSORS", d.sensors),
        ] {
            assert!(h.contains(&format!("#define {name} {v}\n")), "{h}");
        }
        assert!(h.contains("#define HBN_MODEL_VECTOR 1") && h.contains("hbn_vector_filter_init"));
        assert!(files[1].text.contains("const HbnModelData hbn_model = {"));
        let files =
            export_vector(&m, Mode::Ukf, Format::Rust, precision, None, "finger.hbn").unwrap();
        let rs = &files[0].text;
        assert_eq!(files[0].name, "hbn_model.rs");
        assert!(
            rs.contains("pub const HBN_SENSORS: usize = 3;")
                && rs.contains("pub const HBN_MODE: &str = \"ukf\";")
                && rs.contains("VectorTables"),
            "{rs:.2000}"
        );
        // The size report: the parts add up to the tables' bytes; the widened reals are 8
        // bytes per f64 real; the scratch is the view's.
        let sizes = vector_size_report(&m, precision, None).unwrap();
        assert_eq!(sizes.len(), 2);
        for s in &sizes {
            let t = vector_model_tables(&m, s.mode).unwrap();
            assert_eq!(s.model_bytes, t.bytes(precision));
            assert_eq!(s.model_bytes, s.gp_bytes + s.init_bytes);
            assert_eq!(s.local_bytes, 0);
            let widen = if precision == Precision::F32 {
                8 * t.reals.len()
            } else {
                0
            };
            assert_eq!(s.widen_bytes, widen);
            assert_eq!(
                s.scratch_bytes,
                8 * tables::vector_scratch_len(&t.layout).unwrap()
            );
        }
        let table = vector_size_table(&sizes, m.default_mode());
        assert!(
            table.contains("ukf") && table.contains("x0 prior"),
            "{table}"
        );
        // Thinning the prior's rows shrinks it; 0 rows drop it.
        let thin = vector_size_report(&m, precision, Some(50)).unwrap()[0];
        let none = vector_size_report(&m, precision, Some(0)).unwrap()[0];
        assert!(thin.init_bytes < sizes[0].init_bytes && none.init_bytes == 0);
        assert_eq!(thin.gp_bytes, sizes[0].gp_bytes);
        for keep in [Some(0), Some(1), Some(50), Some(1_000_000)] {
            export_vector(&m, Mode::Ekf, Format::C, precision, keep, "m.hbn").unwrap();
        }
    }
    // EKF+BLR is for scalar models.
    let e = export_vector(&m, Mode::EkfBlr, Format::C, Precision::F64, None, "m.hbn").unwrap_err();
    assert!(matches!(e, ExportError::Tables { .. }), "{e}");
    assert!(
        e.to_string().contains("EKF+BLR is for scalar models"),
        "{e}"
    );
    // The f32 variance errors: one per GP.
    let errors = {
        let t = vector_model_tables(&m, Mode::Ekf).unwrap();
        let tm = t.vector_tables().model().unwrap();
        vector_f32_variance_errors(&tm.view())
    };
    assert_eq!(errors.len(), d.states + d.sensors);
}

#[test]
fn corrupt_and_foreign_vector_tables_are_refused() {
    let m = model(Some(8));
    let t = vector_model_tables(&m, Mode::Ekf).unwrap();
    let bad = |t: &ModelTables| t.vector_tables().model().is_err();
    let mut magic = t.clone();
    magic.layout[0] ^= 1;
    assert!(bad(&magic));
    let mut version = t.clone();
    version.layout[1] += 1;
    assert!(bad(&version));
    let mut short = t.clone();
    short.reals.pop();
    assert!(bad(&short));
    let mut long = t.clone();
    long.reals.push(0.0);
    assert!(bad(&long));
    let mut truncated = t.clone();
    truncated.layout.pop();
    assert!(bad(&truncated));
    // Sizes past the maxima.
    let split = t.layout[2] as usize;
    let at = 3 + 2 * split + 1;
    let mut sizes = t.clone();
    sizes.layout[at + 1] = 4; // four state components
    assert!(matches!(
        sizes.vector_tables().model(),
        Err(CoreError::InvalidSpec(_))
    ));
    // A scalar reader does not read vector tables, nor a vector reader scalar ones.
    assert!(t.tables().model().is_err());
    assert!(tables::scratch_len(&t.layout).is_err());
    let params = HbnParams {
        n_inducing: Some(8),
        n_starts: 1,
        max_iters: 20,
        ..HbnParams::default()
    };
    let (u, _, y) = run(3, 300);
    let x: Vec<f64> = u.iter().step_by(2).map(|v| 0.5 * v).collect();
    let y0: Vec<f64> = y.iter().step_by(3).copied().collect();
    let u0: Vec<f64> = u.iter().step_by(2).copied().collect();
    let scalar =
        hbn_model::HysteresisModel::fit(&[hbn_model::Sequence::new(&u0, &x, &y0)], &params)
            .unwrap();
    let st = hbn_export::model_tables(&scalar, Mode::Ekf).unwrap();
    assert!(
        VectorTables {
            layout: &st.layout,
            reals: &st.reals
        }
        .model()
        .is_err()
    );
    assert!(tables::vector_scratch_len(&st.layout).is_err());
    assert!(
        Tables {
            layout: &st.layout,
            keys: &st.keys,
            reals: &st.reals
        }
        .model()
        .is_ok()
    );
    // f32 tables: a truncated array does not widen into tables that read.
    let r32 = t.reals_f32().unwrap();
    let mut wide = vec![0.0; t.reals.len()];
    assert!(tables::widen(&t.layout, &r32, &mut wide[1..]).is_err());
    let cut = tables::widen(&t.layout, &r32[1..], &mut wide);
    assert!(
        cut.is_err()
            || VectorTables {
                layout: &t.layout,
                reals: cut.unwrap()
            }
            .model()
            .is_err()
    );
}
