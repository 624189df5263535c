//! The paper's numbers from the physics: critical angle, in-flight limit,
//! and the control helpers.

use atmo_core::control::{
    DiffDrive, WheelRates, blending_alpha, height_factor, tilt_velocity_reference,
};
use atmo_core::limits::{
    critical_angle, max_tilt_for_reserve, thrust_to_weight, trim_saturation_angle,
};
use atmo_core::model::Input;
use atmo_core::{Model, RobotConfig};
use nalgebra::Vector3;

fn model() -> Model {
    Model::new(&RobotConfig::atmo())
}

#[test]
fn thrust_to_weight_is_about_2_1() {
    let tw = thrust_to_weight(&model());
    assert!((tw - 2.09).abs() < 0.01, "{tw}");
}

#[test]
fn critical_angle_is_61_4_deg() {
    // Reference README: with all four u equal the model cannot hold altitude above ~61.4 deg.
    let deg = critical_angle(&model()).unwrap().to_degrees();
    assert!((deg - 61.4).abs() < 0.05, "{deg}");
    // Check it against the dynamics: all rotors at full command just hold the weight.
    let body = model().at_tilt(critical_angle(&model()).unwrap());
    let vertical: f64 = (0..4).map(|i| body.thrust_force[(2, i)]).sum();
    assert!((vertical + body.mass * body.gravity).abs() < 1e-9);
}

#[test]
fn reserve_1_35_gives_the_50_deg_flight_limit() {
    let deg = max_tilt_for_reserve(&model(), 1.35).unwrap().to_degrees();
    assert!((deg - 50.0).abs() < 0.5, "{deg}");
    assert!(max_tilt_for_reserve(&model(), 3.0).is_err());
    assert!(max_tilt_for_reserve(&model(), f64::NAN).is_err());
}

#[test]
fn hover_trim_saturates_just_below_the_critical_angle() {
    let m = model();
    let sat = trim_saturation_angle(&m, 80f64.to_radians()).unwrap();
    let crit = critical_angle(&m).unwrap();
    assert!(
        sat < crit && sat > crit - 3f64.to_radians(),
        "{} vs {}",
        sat.to_degrees(),
        crit.to_degrees()
    );
    assert!((m.at_tilt(sat).hover_trim().max() - 1.0).abs() < 1e-9);
}

#[test]
fn alpha_blends_with_height_and_tilt() {
    let z_star = 0.45;
    assert_eq!(height_factor(2.0, z_star), 1.0);
    assert_eq!(height_factor(-0.1, z_star), 0.0);
    assert!((height_factor(0.225, z_star) - 0.5).abs() < 1e-15);
    assert_eq!(blending_alpha(2.0, 0.0, z_star), 1.0);
    assert!((blending_alpha(2.0, 60f64.to_radians(), z_star) - 0.5).abs() < 1e-12);
    assert_eq!(blending_alpha(0.0, 0.3, z_star), 0.0);
    // Monotone: lower and more tilted means less tracking.
    assert!(blending_alpha(0.3, 0.5, z_star) > blending_alpha(0.2, 0.5, z_star));
    assert!(blending_alpha(0.3, 0.5, z_star) > blending_alpha(0.3, 0.8, z_star));
}

#[test]
fn tilt_law_follows_the_paper() {
    let (z_phi, v) = (1.2, 0.39);
    assert_eq!(tilt_velocity_reference(1.5, false, 0.0, z_phi, v), 0.0);
    assert_eq!(tilt_velocity_reference(1.0, false, 0.0, z_phi, v), v);
    assert_eq!(tilt_velocity_reference(0.0, true, 0.6, z_phi, v), -v);
    assert_eq!(tilt_velocity_reference(0.0, true, 0.5, z_phi, v), -v);
    assert_eq!(tilt_velocity_reference(0.0, true, 0.49, z_phi, v), 0.0);
}

#[test]
fn diff_drive_round_trips_and_saturation_keeps_the_turn() {
    let drive = DiffDrive::new(&RobotConfig::atmo().wheels);
    let rates = drive.wheel_rates(0.5, 0.4);
    let (v, w) = drive.body_velocity(rates);
    assert!((v - 0.5).abs() < 1e-12 && (w - 0.4).abs() < 1e-12);
    // Turning right (FRD, positive yaw rate) runs the left wheel faster.
    assert!(rates.left > rates.right);
    // Saturated: the faster wheel at its limit, the turn radius kept.
    let fast = drive.wheel_rates(2.0, 2.0);
    assert!((fast.left.abs().max(fast.right.abs()) - 10.0).abs() < 1e-12);
    let (v2, w2) = drive.body_velocity(fast);
    assert!((v2 / w2 - 1.0).abs() < 1e-12);
    assert_eq!(
        drive.body_velocity(WheelRates {
            left: 0.0,
            right: 0.0
        }),
        (0.0, 0.0)
    );
}

/// With a rotor stopped the three left give the lift asked and, with the
/// partner pushing, the roll and pitch torque asked; with the torque only
/// the partner's negative thrust could give, the partner is off and the
/// pair on the other diagonal still gives the lift, the torque's component
/// about the one axis it turns, and nothing about its own diagonal.
#[test]
fn a_stopped_rotor_is_flown_around_by_the_three_left_the_partner_only_pushing() {
    let robot = RobotConfig::atmo();
    let body = Model::new(&robot).at_tilt(0.3);
    let wrench = |u: &Input| {
        let g = body
            .first_moment
            .cross(&Vector3::new(0.0, 0.0, body.gravity));
        (body.thrust_force * u, body.thrust_torque * u + g)
    };
    let lift = -body.mass * body.gravity;
    for stopped in 0..4 {
        let partner = (0..4)
            .find(|&r| r != stopped && robot.rotor.yaw_sign[r] == robot.rotor.yaw_sign[stopped])
            .unwrap();
        let lever = body.thrust_torque.column(partner).xy();
        // A torque the partner gives: met exactly, the partner on.
        let asked = Vector3::new(lever.x, lever.y, 0.0) * 0.1;
        let u = body.commands_without(stopped, 0.0, lift, &asked);
        let (force, torque) = wrench(&u);
        assert_eq!(u[stopped], 0.0);
        assert!(u[partner] > 0.0, "{u}");
        assert!((force.z - lift).abs() < 1e-9);
        assert!((torque.xy() - asked.xy()).norm() < 1e-9, "{torque} {asked}");
        // The opposite torque: the partner off, the lift still exact, and
        // of the torque what the pair's differential thrust (at that lift)
        // turns: the miss is square to it.
        let u = body.commands_without(stopped, 0.0, lift, &-asked);
        let (force, torque) = wrench(&u);
        assert_eq!((u[stopped], u[partner]), (0.0, 0.0), "{u}");
        assert!((force.z - lift).abs() < 1e-9);
        let mut pair = (0..4).filter(|&r| r != stopped && r != partner);
        let (a, b) = (pair.next().unwrap(), pair.next().unwrap());
        let f = |r: usize| body.thrust_force[(2, r)];
        let turn =
            body.thrust_torque.column(a).xy() * f(b) - body.thrust_torque.column(b).xy() * f(a);
        let miss = torque.xy() + asked.xy();
        assert!(miss.dot(&turn).abs() < 1e-9, "{miss} {turn}");
        assert!(miss.norm() > 1e-3, "a torque the pair cannot give: {miss}");
        // A stopped rotor that still delivers: its thrust is counted.
        let turning = body.commands_without(stopped, 0.2, lift, &asked);
        let mut delivered = turning;
        delivered[stopped] = 0.2;
        assert!((wrench(&delivered).0.z - lift).abs() < 1e-9);
    }
}
