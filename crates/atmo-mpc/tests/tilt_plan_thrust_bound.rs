//! The tilt plan's per-tick rotor bound (`TiltPlan::thrust_max`): the flight
//! stack raises it after a weak robot's flare commits (atmo-daemon `flare`).
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use atmo_core::RobotConfig;
use atmo_core::model::{Model, idx};
use atmo_mpc::{Formulation, Mpc, TiltPlan};
use common::hover_at;

fn plan(thrust_max: Option<f64>) -> TiltPlan {
    let robot = RobotConfig::atmo();
    TiltPlan {
        tilt_min: 0.0,
        tilt_max: robot.limits.tilt_transition_max(),
        rate_min: 0.0,
        rate_max: robot.limits.tilt_rate_max,
        wheel_radius: robot.wheels.radius,
        thrust_max,
    }
}

/// The largest rotor command of a few ticks at 62 deg of tilt, 0.3 m up,
/// sinking at 0.3 m/s and asked to climb: more than the rotors have.
fn largest_command(thrust_max: Option<f64>) -> f64 {
    let mut mpc = Mpc::new(
        Model::new(&RobotConfig::atmo()),
        common::settings(Formulation::Condensed),
    )
    .unwrap();
    let tilt = 62f64.to_radians();
    let mut x = hover_at(0.0, 0.0, 0.3);
    x[idx::VZ] = 0.3;
    mpc.set_reference_constant(&hover_at(0.0, 0.0, 1.0))
        .unwrap();
    mpc.set_ground_height(0.0).unwrap();
    mpc.set_tilt_ramp(tilt, 0.0, 0.0, tilt).unwrap();
    mpc.reset(&x).unwrap();
    let mut largest = 0.0f64;
    for _ in 0..5 {
        mpc.set_alpha(0.0).unwrap();
        mpc.set_tilt_plan(&plan(thrust_max)).unwrap();
        mpc.set_measured_tilt(tilt).unwrap();
        mpc.prepare().unwrap();
        let out = mpc.feedback(&x).unwrap();
        largest = out.u.iter().copied().fold(largest, f64::max);
    }
    largest
}

#[test]
fn the_rotor_bound_of_the_tilt_plan_is_the_tick_s_own() {
    let shipped = common::settings(Formulation::Condensed)
        .tilt_plan
        .unwrap()
        .thrust_max;
    let kept = largest_command(None);
    let raised = largest_command(Some(1.0));
    eprintln!("largest command: {kept:.4} within {shipped}, {raised:.4} within 1.0");
    assert!(
        kept <= shipped + 1e-9,
        "{kept} above the settings' {shipped}"
    );
    assert!(
        (shipped - kept).abs() < 1e-6,
        "the test asks for more than the rotors have: {kept}"
    );
    assert!(raised <= 1.0 + 1e-9 && raised > shipped + 0.02, "{raised}");
}

#[test]
fn a_rotor_bound_beyond_full_thrust_or_not_finite_is_refused() {
    let mut mpc = Mpc::new(
        Model::new(&RobotConfig::atmo()),
        common::settings(Formulation::Condensed),
    )
    .unwrap();
    for bad in [1.2, -0.1, f64::NAN, f64::INFINITY] {
        let err = mpc.set_tilt_plan(&plan(Some(bad))).unwrap_err();
        assert!(err.to_string().contains("tilt plan"), "{bad}: {err}");
    }
    mpc.set_tilt_plan(&plan(Some(1.0))).unwrap();
    mpc.set_tilt_plan(&plan(None)).unwrap();
}
