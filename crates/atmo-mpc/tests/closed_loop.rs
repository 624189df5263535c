//! Closed-loop tests against the atmo-core model (no plant effects).
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

mod common;

use atmo_core::model::{State, idx};
use atmo_mpc::Formulation;
use common::{controller, hover_at, run};

const TICKS_PER_SECOND: usize = 150;

fn perturbed_hover() -> State {
    // 0.5 m off in x, 20 deg roll, 1 m/s sideways, 1 m above the reference origin.
    let mut x = hover_at(0.5, 0.0, 1.0);
    x[idx::ROLL] = 20f64.to_radians();
    x[idx::VY] = 1.0;
    x
}

fn recovery(formulation: Formulation) {
    let mut mpc = controller(formulation);
    let reference = hover_at(0.0, 0.0, 1.0);
    let trace = run(
        &mut mpc,
        perturbed_hover(),
        4 * TICKS_PER_SECOND,
        |m, _, _| {
            m.set_reference_constant(&reference).unwrap();
            m.set_alpha(1.0).unwrap();
            m.set_tilt_ramp(0.0, 0.0, 0.0, 0.0).unwrap();
            0.0
        },
    );
    let x = trace.last();
    assert!(trace.inputs_within_bounds());
    assert_eq!(trace.fresh_fraction(), 1.0);
    let pos_err = (x.fixed_rows::<3>(idx::X) - reference.fixed_rows::<3>(idx::X)).norm();
    eprintln!("{formulation:?} recovery: error {pos_err:.4} m after 4 s");
    assert!(pos_err < 0.02, "position error after 4 s: {pos_err} m");
    assert!(x.fixed_rows::<3>(idx::YAW).amax() < 1f64.to_radians());
    assert!(x.fixed_rows::<3>(idx::VX).norm() < 0.02);
}

#[test]
fn recovers_to_hover_from_offset_roll_and_velocity_condensed() {
    recovery(Formulation::Condensed);
}

#[test]
fn recovers_to_hover_from_offset_roll_and_velocity_sparse() {
    recovery(Formulation::Sparse);
}

#[test]
fn position_step_settles() {
    let mut mpc = controller(Formulation::Condensed);
    let start = hover_at(0.0, 0.0, 1.0);
    let target = hover_at(1.0, -0.5, 1.5);
    let trace = run(&mut mpc, start, 4 * TICKS_PER_SECOND, |m, _, _| {
        m.set_reference_constant(&target).unwrap();
        m.set_alpha(1.0).unwrap();
        m.set_tilt_ramp(0.0, 0.0, 0.0, 0.0).unwrap();
        0.0
    });
    assert!(trace.inputs_within_bounds());
    assert_eq!(trace.fresh_fraction(), 1.0);
    let x = trace.last();
    let pos_err = (x.fixed_rows::<3>(idx::X) - target.fixed_rows::<3>(idx::X)).norm();
    assert!(pos_err < 0.02, "position error after 4 s: {pos_err} m");
    // No wild excursion on the way: never more than 10 cm beyond the target in x.
    let overshoot = trace
        .states
        .iter()
        .map(|s| s[idx::X] - 1.0)
        .fold(f64::MIN, f64::max);
    eprintln!("position step: error {pos_err:.4} m, overshoot {overshoot:.4} m");
    assert!(overshoot < 0.10, "overshoot {overshoot} m");
    // The step saturates the rotors at first: the box constraint is active.
    assert!(
        trace
            .inputs
            .iter()
            .any(|u| u.max() > 0.99 || u.min() < 0.01)
    );
}

/// The paper's in-flight morph: tilt 0 -> 50 deg at the mechanism's speed
/// while hovering, alpha refreshed every 10 ticks as the flight stack does.
#[test]
fn tilt_ramp_to_50_deg_holds_altitude() {
    let mut mpc = controller(Formulation::Condensed);
    let cfg = atmo_core::RobotConfig::atmo();
    let rate = cfg.limits.tilt_rate_max;
    let max = cfg.limits.tilt_flight_max();
    assert!((rate - std::f64::consts::FRAC_PI_2 / 4.0).abs() < 1e-12);
    let height = 2.0;
    let reference = hover_at(0.0, 0.0, height);
    let tick = mpc.settings().horizon.tick_period;
    let mut schedule = atmo_mpc::AlphaSchedule::new(mpc.settings().cost.alpha_refresh_ticks);
    let trace = run(&mut mpc, reference, 4 * TICKS_PER_SECOND, |m, k, x| {
        let varphi = (rate * tick * k as f64).min(max);
        let commanded = if varphi < max { rate } else { 0.0 };
        let alpha = schedule.update(-x[idx::Z], varphi, cfg.limits.transition_height);
        m.set_reference_constant(&reference).unwrap();
        m.set_alpha(alpha).unwrap();
        m.set_tilt_ramp(varphi, commanded, 0.0, max).unwrap();
        varphi
    });
    assert!(trace.inputs_within_bounds());
    assert_eq!(trace.fresh_fraction(), 1.0);
    assert!(
        (trace.tilts.last().unwrap() - max).abs() < 1e-12,
        "the ramp reached 50 deg"
    );
    let worst = trace
        .states
        .iter()
        .map(|s| (-s[idx::Z] - height).abs())
        .fold(0.0, f64::max);
    eprintln!("tilt ramp: worst altitude error {worst:.4} m");
    assert!(worst < 0.05, "altitude error {worst} m during the ramp");
    // At 50 deg the rotors work harder: the hover trim is about 0.73-0.76.
    let u = trace.inputs.last().unwrap();
    assert!(u.min() > 0.70 && u.max() < 0.80, "{u:?}");
}

/// Offset-free control: a constant wrench on the plant (here 5 N of extra
/// weight and torques about all axes, all of which the rotors can balance at
/// level attitude) leaves a steady-state offset unless the MPC predicts with
/// it (`set_disturbance`, which the flight stack feeds from its observer).
/// A sideways force is left out on purpose: holding position against it
/// needs a tilted attitude, which the level attitude reference penalizes, so
/// some offset is the optimum of the cost, not a modelling error.
#[test]
fn known_disturbance_removes_the_steady_state_offset() {
    let wrench = nalgebra::Vector6::new(0.0, 0.0, 5.0, 0.05, -0.03, 0.01);
    let reference = hover_at(0.0, 0.0, 1.0);
    let offset = |compensate: bool| {
        let mut mpc = controller(Formulation::Condensed);
        mpc.set_reference_constant(&reference).unwrap();
        if compensate {
            mpc.set_disturbance(&wrench).unwrap();
        }
        mpc.reset(&reference).unwrap();
        let plant = mpc.model().at_tilt(0.0).with_disturbance(wrench);
        let h = mpc.settings().horizon.tick_period / common::SUBSTEPS as f64;
        let mut x = reference;
        for _ in 0..5 * TICKS_PER_SECOND {
            let out = mpc.tick(&x).unwrap();
            assert!(out.outcome.is_fresh());
            for _ in 0..common::SUBSTEPS {
                x = plant.rk4_step(&x, &out.u, h);
            }
        }
        (x.fixed_rows::<3>(idx::X) - reference.fixed_rows::<3>(idx::X)).norm()
    };
    let uncompensated = offset(false);
    let compensated = offset(true);
    eprintln!(
        "steady-state offset: {uncompensated:.4} m without, {compensated:.5} m with the disturbance"
    );
    assert!(uncompensated > 0.05, "{uncompensated}");
    assert!(compensated < 1e-3, "{compensated}");
}

/// The yaw cost. From a hover 20 deg off the reference heading: held, it
/// turns back; rate-only or free, it keeps the heading it has (no torque
/// spent on the angle). From a hover spinning at 1 rad/s: rate-only, the
/// spin is stopped; free, it is left to run. The position is held in
/// every case.
#[test]
fn a_heading_held_turns_back_and_a_rate_only_one_stops_spinning_where_it_is() {
    use atmo_mpc::YawCost;
    let reference = hover_at(0.0, 0.0, 1.0);
    let fly = |yaw: YawCost, start: State| {
        let mut mpc = controller(Formulation::Condensed);
        mpc.set_yaw_cost(yaw);
        let trace = run(&mut mpc, start, 2 * TICKS_PER_SECOND, |m, _, _| {
            m.set_reference_constant(&reference).unwrap();
            m.set_alpha(1.0).unwrap();
            m.set_tilt_ramp(0.0, 0.0, 0.0, 0.0).unwrap();
            0.0
        });
        let x = *trace.last();
        let pos_err = (x.fixed_rows::<3>(idx::X) - reference.fixed_rows::<3>(idx::X)).norm();
        eprintln!(
            "{yaw:?}: heading {:.2} deg, yaw rate {:.3} rad/s after 2 s, position error {pos_err:.4} m",
            x[idx::YAW].to_degrees(),
            x[idx::WZ]
        );
        assert!(pos_err < 0.02, "{yaw:?}: {pos_err} m");
        (x[idx::YAW].to_degrees(), x[idx::WZ])
    };
    let mut turned = reference;
    turned[idx::YAW] = 20f64.to_radians();
    let held = fly(YawCost::Held, turned);
    assert!(held.0.abs() < 5.0, "held: {held:?}");
    for yaw in [YawCost::RateOnly, YawCost::Free] {
        let (heading, rate) = fly(yaw, turned);
        assert!((heading - 20.0).abs() < 0.5 && rate.abs() < 0.01, "{yaw:?}");
    }
    let mut spinning = reference;
    spinning[idx::WZ] = 1.0;
    let rate_only = fly(YawCost::RateOnly, spinning);
    assert!(rate_only.1.abs() < 0.05, "rate only: {rate_only:?}");
    let free = fly(YawCost::Free, spinning);
    assert!(free.1 > 0.5, "free: {free:?}");
}
