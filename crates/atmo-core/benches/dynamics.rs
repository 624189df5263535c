//! Cost of the physics the MPC calls N times per tick.

use std::hint::black_box;

use atmo_core::RobotConfig;
use atmo_core::model::{Input, Model, State};
use criterion::{Criterion, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let model = Model::new(&RobotConfig::atmo());
    let x = State::from_fn(|i, _| 0.05 * i as f64 - 0.2);
    let u = Input::new(0.5, 0.6, 0.55, 0.45);
    let varphi = 0.8;
    let body = model.at_tilt(varphi);
    let mut group = c.benchmark_group("atmo_core");
    group.bench_function("at_tilt", |b| b.iter(|| model.at_tilt(black_box(varphi))));
    group.bench_function("f", |b| {
        b.iter(|| body.dynamics(black_box(&x), black_box(&u)));
    });
    group.bench_function("f_at_new_tilt", |b| {
        b.iter(|| model.dynamics(black_box(&x), black_box(&u), black_box(varphi)));
    });
    group.bench_function("f_and_jacobians", |b| {
        b.iter(|| body.linearize(black_box(&x), black_box(&u)));
    });
    group.bench_function("rk4_step", |b| {
        b.iter(|| body.rk4_step(black_box(&x), black_box(&u), 0.1));
    });
    group.bench_function("rk4_step_with_sensitivities", |b| {
        b.iter(|| body.rk4_step_sensitivity(black_box(&x), black_box(&u), 0.1));
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
