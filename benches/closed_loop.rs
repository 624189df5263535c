//! The whole product in simulation, timed: the Fig. 5 wheel landing (14 s
//! simulated: flight, morphing, transition past the critical angle,
//! touchdown, drive) flown by FlightStack + atmo-mpc against the built-in
//! plant with its default effects, on one thread. Issue target: a 10 s
//! flight at least 10x faster than real time, i.e. under 1 s here for 14 s.
//!
//! `cargo bench -p atmo --bench closed_loop`

use std::path::PathBuf;

use atmo_sim::closed_loop::{ControllerConfig, fly};
use atmo_sim::scenario::Scenario;
use criterion::{Criterion, criterion_group, criterion_main};

fn wheel_landing(c: &mut Criterion) {
    let path: PathBuf = [
        env!("CARGO_MANIFEST_DIR"),
        "config",
        "scenarios",
        "wheel_landing.toml",
    ]
    .iter()
    .collect();
    let scenario = Scenario::load(&path).expect("wheel landing scenario");
    let controller = ControllerConfig::atmo()
        .expect("shipped controller config")
        .deterministic();
    let mut group = c.benchmark_group("closed_loop");
    group.sample_size(10);
    group.bench_function("wheel_landing_14s", |b| {
        b.iter(|| {
            let summary = fly(&scenario, &controller, |_| {}).expect("flight");
            assert!(!summary.crashed);
            summary
        });
    });
    group.finish();
}

criterion_group!(benches, wheel_landing);
criterion_main!(benches);
