//! f, the Jacobians and the RK4 step with sensitivities allocate nothing:
//! a counting global allocator around the calls (this test binary only).

use atmo_core::RobotConfig;
use atmo_core::alloc_counter::thread_allocations;
use atmo_core::model::{Input, Model, State};

#[global_allocator]
static GLOBAL: atmo_core::alloc_counter::CountingAllocator =
    atmo_core::alloc_counter::CountingAllocator;

#[test]
fn dynamics_jacobians_and_rk4_do_not_allocate() {
    let model = Model::new(&RobotConfig::atmo());
    let x = State::from_fn(|i, _| 0.1 * i as f64 - 0.3);
    let u = Input::new(0.5, 0.6, 0.55, 0.45);
    let before = thread_allocations();
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
    let after = thread_allocations();
    assert!(acc.is_finite());
    assert_eq!(
        after - before,
        0,
        "the physics allocated {} times",
        after - before
    );
}
