//! The speed budget: `explain()` on 90 000 rows (10 minutes at
//! 150 Hz) in at most 5 s on one core. The recording is the independent
//! generator's (`atmo-testgen`, ground effect and motor lag concealed,
//! seed 3), the one BENCHMARKS.md times through `atmo-sim explain`; it is
//! generated and parsed once, outside the measurement.
//!
//! `cargo bench -p atmo-explain --bench explain` (pin it to one core with
//! `taskset -c 0` for the budget's reading).
#![allow(clippy::unwrap_used)] // reason: a benchmark, errors abort it

use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

use atmo_core::{ConfigFile as _, RobotConfig};
use atmo_explain::recording::Recording;
use atmo_explain::{Options, explain};
use atmo_testgen::flight::{FlightPlan, fly, to_csv};
use atmo_testgen::robot::{RigidBody, RobotFile};
use criterion::{Criterion, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let robot_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/atmo.toml");
    let body = RigidBody::at_tilt(&RobotFile::load(&robot_path).unwrap(), 0.0);
    let concealed =
        atmo_testgen::concealed("ground_effect,motor_lag", atmo_testgen::Form::First).unwrap();
    let plan = FlightPlan {
        seed: 3,
        duration: 600.0,
        ..FlightPlan::default()
    };
    let csv = to_csv(&fly(&body, &concealed, &plan));
    let rec = Recording::from_csv_str(&csv, "testgen 600 s").unwrap();
    assert_eq!(rec.samples.len(), 90_000);
    let robot = RobotConfig::load(&robot_path).unwrap();
    let options = Options::default();

    let mut group = c.benchmark_group("explain");
    group.sample_size(10);
    group.measurement_time(Duration::from_secs(40));
    group.bench_function("90k_rows", |b| {
        b.iter(|| explain(black_box(&rec), &robot, &options).unwrap());
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
