//! The disturbance observer learns a constant wrench the model leaves out,
//! and the MPC with it holds attitude and altitude with no steady error.

use atmo_core::model::{Input, State, idx};
use atmo_core::{Model, RobotConfig};
use atmo_flight::observer::{DisturbanceObserver, ObserverSettings};
use nalgebra::Vector6;

fn settings() -> ObserverSettings {
    ObserverSettings {
        force_gain: 0.05,
        torque_gain: 0.1,
        max_force: 15.0,
        max_torque: 1.0,
        min_interval: 0.004,
    }
}

#[test]
fn learns_a_constant_wrench_from_the_prediction_error() {
    let model = Model::new(&RobotConfig::atmo());
    let truth = Vector6::new(0.0, 1.5, -3.0, 0.2, -0.27, 0.05);
    let body = model.at_tilt(0.3);
    let plant = body.with_disturbance(truth);
    let u = body.hover_trim();
    let mut obs = DisturbanceObserver::new(settings());
    let mut x = State::zeros();
    x[idx::Z] = -1.0;
    let dt = 1.0 / 120.0;
    for k in 0..400u64 {
        obs.update(&model, k * 8_333_333, &x, 0.3, &u);
        // Keep the state near hover: the observer needs samples, not a crash.
        x = plant.rk4_step(&x, &u, dt);
        if k % 20 == 0 {
            x = State::zeros();
            x[idx::Z] = -1.0;
            obs.pause();
        }
    }
    let err = (obs.wrench() - truth).amax();
    assert!(err < 0.05, "estimate {:?} vs truth {truth:?}", obs.wrench());
}

#[test]
fn clamps_and_ignores_repeated_or_gapped_samples() {
    let model = Model::new(&RobotConfig::atmo());
    let mut obs = DisturbanceObserver::new(ObserverSettings {
        max_torque: 0.1,
        ..settings()
    });
    let plant = model
        .at_tilt(0.0)
        .with_disturbance(Vector6::new(0.0, 0.0, 0.0, 5.0, 0.0, 0.0));
    let u = Input::from_element(0.48);
    let mut x = State::zeros();
    for k in 0..200u64 {
        obs.update(&model, k * 8_333_333, &x, 0.0, &u);
        obs.update(&model, k * 8_333_333, &x, 0.0, &u); // repeated stamp: ignored
        x = plant.rk4_step(&x, &u, 1.0 / 120.0);
    }
    assert!(
        (obs.wrench()[3] - 0.1).abs() < 1e-12,
        "clamped to the limit: {}",
        obs.wrench()[3]
    );
    let before = obs.wrench();
    obs.update(&model, 10_000_000_000, &State::from_element(9.0), 0.0, &u); // 8 s gap: restart only
    assert_eq!(obs.wrench(), before);
    obs.reset();
    assert_eq!(obs.wrench(), Vector6::zeros());
}

/// A burst from a loaded transport: two estimates measured a sample period
/// apart, accepted 39 us apart (the SITL flight that fell: the estimate
/// hit its limits in one update and the MPC cut the thrust). The close one
/// is not differenced, and the next, a period later, is against the base.
#[test]
fn a_burst_of_estimates_does_not_throw_the_estimate() {
    let model = Model::new(&RobotConfig::atmo());
    let body = model.at_tilt(0.0);
    let u = body.hover_trim();
    let period = 8_333_333u64;
    let mut x = State::zeros();
    x[idx::Z] = -0.8;
    let mut obs = DisturbanceObserver::new(settings());
    let mut stamp = 1_000_000_000u64;
    obs.update(&model, stamp, &x, 0.0, &u);
    // Measured a period later (1 cm/s of motion-capture noise on vz),
    // accepted 39 us after the base.
    let mut next = body.rk4_step(&x, &u, period as f64 * 1e-9);
    next[idx::VZ] += 0.01;
    stamp += 39_000;
    obs.update(&model, stamp, &next, 0.0, &u);
    assert_eq!(obs.wrench(), Vector6::zeros(), "differenced over 39 us");
    let later = body.rk4_step(&next, &u, period as f64 * 1e-9);
    stamp += period;
    obs.update(&model, stamp, &later, 0.0, &u);
    let s = settings();
    // Differenced: 1 cm/s over about one period, ~6.6 N of innovation, ~0.33 N
    // of estimate at this gain (the 39 us pair alone: ~1400 N, the limit).
    assert!(
        obs.wrench()[2] != 0.0 && obs.wrench()[2].abs() < 0.5 * s.max_force * s.force_gain,
        "one period against the base: {:?}",
        obs.wrench()
    );
}

/// Near the ground at 55 deg the plant's thrust gain is the MPC's surface.
/// An observer that predicts with that surface learns nothing (the MPC
/// already knows the lift); one that predicts with the nominal model
/// learns the lift as a disturbance, which an MPC with the surface would
/// then count twice (it did: docs/landing.md, "A bug found on the way").
#[test]
fn with_the_mpcs_surface_the_ground_effect_is_not_learned_twice() {
    use atmo_core::ground_effect::GroundedBody;
    use atmo_core::model::rk4_step;
    use atmo_flight::ground_model::ground_surface;
    use atmo_mpc::settings::GroundEffectSource;

    let model = Model::new(&RobotConfig::atmo());
    let surface = ground_surface(&GroundEffectSource::PlantDefault)
        .unwrap()
        .unwrap();
    let tilt = 55f64.to_radians();
    let body = model.at_tilt(tilt);
    let u = body.hover_trim();
    let start = {
        let mut x = State::zeros();
        x[idx::Z] = -0.25;
        x
    };
    let learned = |with_surface: bool| {
        let mut obs = DisturbanceObserver::new(settings());
        if with_surface {
            obs.set_ground_effect(Some(surface.clone()));
        }
        obs.set_ground_height(0.0);
        let plant = GroundedBody {
            body,
            surface: &*surface,
            ground_z: 0.0,
        };
        let mut x = start;
        for k in 0..400u64 {
            obs.update(&model, k * 8_333_333, &x, tilt, &u);
            x = rk4_step(&plant, &x, &u, 1.0 / 120.0);
            if k % 20 == 0 {
                x = start;
                obs.pause();
            }
        }
        obs.wrench()
    };
    let with = learned(true);
    let without = learned(false);
    assert!(with.amax() < 0.05, "with the surface: learned {with:?}");
    // The nominal observer learns the lift (upwards: -z in the body frame).
    assert!(
        without[2] < -3.0,
        "without the surface: learned {without:?}"
    );
}
