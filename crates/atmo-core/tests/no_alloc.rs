//! f, the Jacobians and the RK4 step with sensitivities allocate nothing:
//! a counting global allocator around the calls (this test binary only).

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

use atmo_core::RobotConfig;
use atmo_core::model::{Input, Model, State};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

#[allow(unsafe_code)] // a global allocator is unsafe by definition; it only counts and forwards
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Ordering::SeqCst);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn dynamics_jacobians_and_rk4_do_not_allocate() {
    let model = Model::new(&RobotConfig::atmo());
    let x = State::from_fn(|i, _| 0.1 * i as f64 - 0.3);
    let u = Input::new(0.5, 0.6, 0.55, 0.45);
    let before = ALLOCATIONS.load(Ordering::SeqCst);
    let mut acc = 0.0;
    for k in 0..100 {
        let varphi = 1.5 * f64::from(k) / 100.0;
        let body = model.at_tilt(varphi);
        acc += model.dynamics(&x, &u, varphi)[8];
        acc += body.linearize(&x, &u).dfdx[(8, 4)];
        acc += body.rk4_step(&x, &u, 0.001)[2];
        acc += body.rk4_step_sensitivity(&x, &u, 0.1).a[(2, 8)];
        acc += body.hover_trim()[0];
    }
    // Past 86 deg the authors' convention needs the inertia floor: also allocation-free.
    acc += model.at_tilt(1.55).mass_matrix_inv[(0, 0)];
    let after = ALLOCATIONS.load(Ordering::SeqCst);
    assert!(acc.is_finite());
    assert_eq!(
        after - before,
        0,
        "the physics allocated {} times",
        after - before
    );
}
