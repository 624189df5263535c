//! The whole product in simulation, timed: the Fig. 5 wheel landing (14 s
//! simulated: flight, morphing, transition past the critical angle,
//! touchdown, drive) flown by FlightStack + atmo-mpc against the built-in
//! plant with its default effects, on one thread. Target: a 10 s
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

/// The flare's touchdown prediction (`atmo_flight::flare::predict_touchdown`),
/// run in each preparation of a flare's approach until its decision: from
/// 57 deg rolled 3 deg, on the default ground-effect surface,
/// the rotors spinning up from 0.88 with the motors' lag, 5 ms steps (as
/// the flight stack calls it).
fn flare_prediction(c: &mut Criterion) {
    use atmo_core::model::{Input, State, idx};
    use atmo_core::{Model, RobotConfig};
    use atmo_flight::flare::{TouchdownModel, predict_touchdown};
    use atmo_flight::ground_model::ground_surface;
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
        // 3 N of missing lift, as the observer learns on a robot 3 %
        // heavier than its file.
        disturbance: nalgebra::Vector6::new(0.0, 0.0, 3.0, 0.0, 0.0, 0.0),
        wheel_radius: robot.wheels.radius,
        tilt_rate: robot.limits.tilt_rate_max,
        tilt_max: robot.limits.tilt_transition_max(),
        thrust: 0.96,
        thrust_now: Input::from_element(0.88),
        motor_time_constant: robot.rotor.time_constant,
    };
    // The wheels 10 cm above the ground at 57 deg (about where the flare
    // decides), sinking at 0.05 m/s.
    let tilt = 57f64.to_radians();
    let mut state = State::zeros();
    state[idx::ROLL] = 3f64.to_radians();
    state[idx::VZ] = 0.05;
    state[idx::Z] = atmo_mpc::wheel_clearance_at_attitude(
        &model.at_tilt(tilt),
        &touchdown.ground,
        &state,
        touchdown.wheel_radius,
    ) - 0.10;
    let landed = predict_touchdown(&touchdown, &state, tilt, 0.005, 0.6);
    assert!(landed.is_some(), "the benchmark's tilt-up touches down");
    c.bench_function("flare/predict_touchdown", |b| {
        b.iter(|| predict_touchdown(&touchdown, &state, tilt, 0.005, 0.6));
    });
}

criterion_group!(benches, wheel_landing, flare_prediction);
criterion_main!(benches);
