//! Plant steps per second with every effect on.
//!
//! Each iteration runs 1000 steps (1 s of simulated time at dt = 1 ms) from
//! a fresh copy of the plant, so the robot does what the case says instead
//! of drifting for minutes: criterion's throughput line is steps per second,
//! and 1e6 steps/s is 1000x real time. The cases are in `support/cases.rs`.

#[path = "support/cases.rs"]
mod cases;

use std::hint::black_box;

use cases::{STEPS, cases};
use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("atmo_plant");
    group.throughput(Throughput::Elements(STEPS));
    for case in cases() {
        group.bench_function(format!("{}_1000_steps", case.name), |b| {
            b.iter_batched(
                || case.plant.clone(),
                |mut p| {
                    for k in 0..STEPS {
                        p.step(black_box(&(case.command)(k)))
                            .expect("the bench case steps");
                    }
                    p
                },
                BatchSize::SmallInput,
            );
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
