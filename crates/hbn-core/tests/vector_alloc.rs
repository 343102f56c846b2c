//! Proof that the vector step allocates nothing at the largest sizes (4 inputs, each with 4
//! memory operators; 3 state components; 4 sensors): a counting global allocator, armed only
//! on this thread around the step loop, must see zero allocations in the EKF and the UKF.

mod vector_common;

use hbn_core::vector::{Dims, MAX_INPUTS, MAX_SENSORS, MAX_STATES, VectorEstimator};
use hbn_core::{MAX_PLAYS, Mode, Plays};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};
use vector_common::{config, model};

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
fn the_vector_step_allocates_nothing_at_the_largest_sizes() {
    let dims = Dims::new(MAX_INPUTS, MAX_STATES, MAX_SENSORS).unwrap();
    let plays = Plays::new(&[0.05, 0.1, 0.2, 0.3][..MAX_PLAYS]).unwrap();
    assert_eq!(dims.transition_dim(plays.len()), 30);
    let m = model(dims, plays, true, 9);
    let views = m.views();
    for mode in [Mode::Ekf, Mode::Ukf] {
        let view = views.view(dims, plays);
        let mut scratch = vec![0.0; view.scratch_len()];
        let mut est = VectorEstimator::new(view, config(dims, mode), &mut scratch).unwrap();
        let inputs: Vec<[f64; 4]> = (0..2000)
            .map(|k| {
                let t = k as f64 * 0.01;
                [t.sin(), (1.3 * t).cos(), (0.7 * t).sin(), (2.1 * t).cos()].map(|v| 0.5 + 0.4 * v)
            })
            .collect();
        let mut last = 0.0;
        ALLOCATIONS.store(0, Ordering::SeqCst);
        ARMED.with(|a| a.set(true));
        for (k, u) in inputs.iter().enumerate() {
            let y = if k % 17 == 0 {
                [0.4, f64::NAN, 0.6, 0.5]
            } else {
                [0.5, 0.45, 0.6, 0.55]
            };
            last = est.step(u, &y).x[0];
        }
        ARMED.with(|a| a.set(false));
        assert_eq!(ALLOCATIONS.load(Ordering::SeqCst), 0, "{mode:?}");
        assert!(last.is_finite());
    }
}
