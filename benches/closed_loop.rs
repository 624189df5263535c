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

/// The flare's touchdown prediction (`atmo_daemon::flare::predict_touchdown`),
/// run in each preparation of a flare's approach: from a hover 2 cm above
/// the hold at 57 deg, level, on the default ground-effect surface.
fn flare_prediction(c: &mut Criterion) {
    use atmo_core::model::{State, idx};
    use atmo_core::{Model, RobotConfig};
    use atmo_daemon::flare::{TouchdownModel, predict_touchdown};
    use atmo_daemon::ground_model::ground_surface;
    use atmo_mpc::settings::GroundEffectSource;

    let robot = RobotConfig::atmo();
    let model = Model::new(&robot);
    let surface = ground_surface(&GroundEffectSource::PlantDefault)
        .expect("default surface")
        .expect("a surface");
    let touchdown = TouchdownModel {
        model: &model,
        surface: Some(&*surface),
        ground: atmo_core::GroundPlane::level(0.0),
        disturbance: nalgebra::Vector6::zeros(),
        wheel_radius: robot.wheels.radius,
        tilt_rate: robot.limits.tilt_rate_max,
        tilt_max: robot.limits.tilt_transition_max(),
        thrust: 0.9,
        hold_attitude: false,
    };
    let mut state = State::zeros();
    state[idx::Z] = -0.25;
    let tilt = 57f64.to_radians();
    let landed = predict_touchdown(&touchdown, &state, tilt, 0.01, 0.5);
    assert!(landed.is_some(), "the benchmark's tilt-up touches down");
    c.bench_function("flare/predict_touchdown", |b| {
        b.iter(|| predict_touchdown(&touchdown, &state, tilt, 0.01, 0.5));
    });
    // The late prediction after the commit: from 65 deg with the wheels
    // 3 cm up (the window's edge), rolled 3 deg, falling at 0.3 m/s, the
    // attitude held, 5 ms steps.
    let late = TouchdownModel {
        hold_attitude: true,
        thrust: 0.95,
        ..touchdown
    };
    let tilt = 65f64.to_radians();
    let mut state = State::zeros();
    state[idx::ROLL] = 3f64.to_radians();
    state[idx::VZ] = 0.3;
    let body = model.at_tilt(tilt);
    state[idx::Z] = atmo_mpc::wheel_clearance_at_attitude(
        &body,
        &touchdown.ground,
        &state,
        touchdown.wheel_radius,
    ) - 0.03;
    let landed = predict_touchdown(&late, &state, tilt, 0.005, 0.5);
    assert!(landed.is_some(), "the late prediction touches down");
    c.bench_function("flare/predict_touchdown_late", |b| {
        b.iter(|| predict_touchdown(&late, &state, tilt, 0.005, 0.5));
    });
}

criterion_group!(benches, wheel_landing, flare_prediction);
criterion_main!(benches);
