//! Proof that the estimator step allocates nothing: a counting global allocator, armed only on
//! this thread and only around the step loop, must see zero allocations over 20,000 steps in
//! each mode (EKF and EKF+BLR), with exact and with sparse GPs, for the borrowing core
//! `Estimator` and for the owned `hbn::Filter` (after construction; its first step, the prior
//! from the first measurement, included); and for a sensor of the state only (two inputs),
//! exact and sparse, in every mode.

mod common;

use hbn::Filter;
use hbn::core::{Estimator, Mode};
use hbn::sim::SystemKind;
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    static ARMED: Cell<bool> = const { Cell::new(false) };
}

fn note() {
    if ARMED.with(|a| a.get()) {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
    }
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        note();
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        note();
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        note();
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn the_step_never_allocates() {
    let test = common::test_run(SystemKind::BoucWen, 1.0, 20_000, 3);
    let exact = common::train_model_kind(SystemKind::BoucWen, 1.0, 120, None, 3).0;
    let sparse = common::train_model_kind(SystemKind::BoucWen, 1.0, 120, Some(32), 3).0;
    assert!(!exact.transition().is_sparse() && sparse.transition().is_sparse());
    assert!(!exact.sensor().is_sparse() && sparse.sensor().is_sparse());
    let state_sensor = |n_inducing| {
        common::train_model_with(SystemKind::BoucWen, 1.0, 120, 3, |p| {
            p.n_inducing = n_inducing;
            p.select = hbn::model::Selection::default();
            p.sensor_inputs = hbn::model::SensorInputs::State;
        })
        .0
    };
    let (state_exact, state_sparse) = (state_sensor(None), state_sensor(Some(32)));
    assert_eq!(state_exact.sensor().kernel().dim, 2);
    assert!(state_sparse.sensor().is_sparse());
    let (exact, sparse) = (std::sync::Arc::new(exact), std::sync::Arc::new(sparse));
    let (state_exact, state_sparse) = (
        std::sync::Arc::new(state_exact),
        std::sync::Arc::new(state_sparse),
    );
    // Include the guard paths: NaN inputs and measurements now and then.
    let u = |k: usize| if k % 5001 == 17 { f64::NAN } else { test.u[k] };
    let y = |k: usize| if k % 7001 == 23 { f64::NAN } else { test.y[k] };
    for (model, mode) in [
        (&exact, Mode::Ekf),
        (&exact, Mode::EkfBlr),
        (&sparse, Mode::Ekf),
        (&sparse, Mode::EkfBlr),
        (&exact, Mode::Ukf),
        (&sparse, Mode::Ukf),
        (&state_exact, Mode::Ekf),
        (&state_exact, Mode::EkfBlr),
        (&state_exact, Mode::Ukf),
        (&state_sparse, Mode::EkfBlr),
        (&state_sparse, Mode::Ukf),
    ] {
        let view = model.view().unwrap();
        let kind = match (model.transition().is_sparse(), model.sensor().kernel().dim) {
            (true, 2) => "sparse, state-only sensor",
            (false, 2) => "exact, state-only sensor",
            (true, _) => "sparse",
            (false, _) => "exact",
        };
        let mut scratch = vec![0.0; Estimator::scratch_len(&view)];
        let mut est = Estimator::new(view, model.ekf_config(mode), &mut scratch).unwrap();
        let mut filter = Filter::new(model.clone(), mode).unwrap();
        let mut checksum = 0.0;
        ALLOCATIONS.store(0, Ordering::SeqCst);
        ARMED.with(|a| a.set(true));
        for k in 0..test.u.len() {
            let out = est.step(u(k), y(k));
            checksum += out.x + out.x_std + out.nis;
        }
        ARMED.with(|a| a.set(false));
        let n = ALLOCATIONS.load(Ordering::SeqCst);
        assert_eq!(
            n,
            0,
            "{kind} {mode:?}: {n} allocations in {} steps",
            test.u.len()
        );
        ARMED.with(|a| a.set(true));
        for k in 0..test.u.len() {
            let out = filter.step(u(k), y(k));
            checksum += out.x + out.x_std + out.obs_min.max(0.0);
            if k == 10_000 {
                filter.reset();
            }
        }
        ARMED.with(|a| a.set(false));
        let n = ALLOCATIONS.load(Ordering::SeqCst);
        assert_eq!(
            n,
            0,
            "Filter {kind} {mode:?}: {n} allocations in {} steps",
            test.u.len()
        );
        assert!(checksum.is_finite());
    }
    // The counter works: an allocation while armed is seen.
    ARMED.with(|a| a.set(true));
    let v = std::hint::black_box(vec![1u8; 64]);
    ARMED.with(|a| a.set(false));
    drop(v);
    assert!(ALLOCATIONS.load(Ordering::SeqCst) > 0);
}
