//! Ground contact: resting, driving, crashes.

mod common;

use atmo_core::model::{State, idx};
use atmo_plant::config::TerrainConfig;
use atmo_plant::plant::{Command, CrashKind, EventKind, InitialState, Plant};
use common::{contact_only, level_at, robot, wheel_drop};
use nalgebra::Vector3;

const DRIVE: f64 = std::f64::consts::FRAC_PI_2;

/// A robot in drive configuration resting on `terrain`, placed with its
/// wheels just touching, facing uphill.
fn parked(terrain: &TerrainConfig) -> Plant {
    parked_with(terrain, &contact_only())
}

fn parked_with(terrain: &TerrainConfig, config: &atmo_plant::config::PlantConfig) -> Plant {
    let slope = terrain.slope_deg.to_radians();
    let drop = wheel_drop(DRIVE);
    // Pitch the body with the slope (nose up = positive pitch in FRD).
    let mut x = level_at(0.0);
    x[idx::PITCH] = slope;
    // B sits `drop` above the plane along its normal.
    let plane = atmo_plant::contact::Plane::new(terrain);
    let b = plane.point + plane.normal * (drop + 1e-4);
    x[idx::X] = b.x;
    x[idx::Y] = b.y;
    x[idx::Z] = b.z;
    Plant::new(&robot(), config, terrain, &InitialState::at(x, DRIVE), 7).expect("a valid plant")
}

struct Window {
    max_speed: f64,
    max_rate: f64,
    position: Vector3<f64>,
}

fn window(plant: &mut Plant, seconds: f64) -> Window {
    let mut max_speed: f64 = 0.0;
    let mut max_rate: f64 = 0.0;
    let n = (seconds / plant.dt()).round() as usize;
    for _ in 0..n {
        plant.step(&Command::idle()).expect("the plant steps");
        let x = plant.state();
        max_speed = max_speed.max(Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ]).norm());
        max_rate = max_rate.max(Vector3::new(x[idx::WX], x[idx::WY], x[idx::WZ]).norm());
    }
    let x = plant.state();
    Window {
        max_speed,
        max_rate,
        position: Vector3::new(x[idx::X], x[idx::Y], x[idx::Z]),
    }
}

fn rests_still(terrain: TerrainConfig) {
    rests_still_with(terrain, &contact_only(), 1.0);
}

/// `growth`: how much louder the last window may be than the early one
/// (1 = not at all; noisy effects make the jitter stationary, not zero).
fn rests_still_with(terrain: TerrainConfig, config: &atmo_plant::config::PlantConfig, growth: f64) {
    let mut plant = parked_with(&terrain, config);
    let settle = window(&mut plant, 5.0);
    let early = window(&mut plant, 10.0);
    let mut late = early.position;
    let mut last = Window {
        max_speed: 0.0,
        max_rate: 0.0,
        position: late,
    };
    for _ in 0..4 {
        last = window(&mut plant, 11.25);
        late = last.position;
    }
    let drift = (late - settle.position).norm();
    eprintln!(
        "slope {}: settle speed {:.3e}, early {:.3e}/{:.3e}, last {:.3e}/{:.3e}, drift {:.3e} m, z {:.5}",
        terrain.slope_deg,
        settle.max_speed,
        early.max_speed,
        early.max_rate,
        last.max_speed,
        last.max_rate,
        drift,
        late.z
    );
    assert!(plant.crash().is_none(), "{:?}", plant.crash());
    assert!(plant.contact_signal());
    // No drift after settling: less than 0.1 mm over 55 s.
    assert!(drift < 1e-4, "drift {drift} m");
    // No jitter, and none growing: the last window is quieter than 1 mm/s and
    // not louder than the early one.
    assert!(
        last.max_speed < 1e-3 && last.max_rate < 1e-2,
        "jitter {} m/s {} rad/s",
        last.max_speed,
        last.max_rate
    );
    assert!(last.max_speed <= growth * early.max_speed + 1e-9);
    assert!(last.max_rate <= growth * early.max_rate + 1e-9);
    // Still on its wheels, body at the slope's pitch.
    let x = plant.state();
    assert!(
        (x[idx::PITCH] - terrain.slope_deg.to_radians()).abs() < 0.01,
        "pitch {}",
        x[idx::PITCH]
    );
    assert!(x[idx::ROLL].abs() < 1e-3);
}

#[test]
fn resting_on_flat_ground_is_still_for_60_s() {
    rests_still(TerrainConfig::flat(0.0));
}

#[test]
fn resting_on_a_20_deg_slope_with_every_effect_on_is_still_for_60_s() {
    // Wind turbulence, sensors, mass errors...: the parked robot must not creep.
    rests_still_with(
        TerrainConfig {
            height: 0.0,
            slope_deg: 20.0,
            slope_azimuth_deg: 0.0,
        },
        &atmo_plant::config::PlantConfig::full(),
        2.0,
    );
}

#[test]
fn resting_on_a_20_deg_slope_is_still_for_60_s() {
    rests_still(TerrainConfig {
        height: 0.0,
        slope_deg: 20.0,
        slope_azimuth_deg: 0.0,
    });
}

/// Drops the robot (level, drive tilt) with its wheels `height` m above the
/// ground and returns the plant after 2 s.
fn drop_from(height: f64, tilt: f64) -> Plant {
    let x = level_at(wheel_drop(tilt) + height);
    let mut plant = Plant::new(
        &robot(),
        &contact_only(),
        &TerrainConfig::flat(0.0),
        &InitialState::at(x, tilt),
        3,
    )
    .expect("a valid plant");
    plant
        .advance(&Command::idle(), 2.0)
        .expect("the plant steps");
    plant
}

#[test]
fn a_hard_drop_is_a_crash() {
    // 1.5 m: about 5.4 m/s at impact, far above the 2 m/s crash speed.
    let plant = drop_from(1.5, DRIVE);
    let crash = plant.crash().expect("a 1.5 m drop must be reported");
    match crash.kind {
        EventKind::Crash(CrashKind::HardImpact { speed, .. }) => {
            let expected = (2.0 * 9.81 * 1.5_f64).sqrt();
            assert!(
                (speed - expected).abs() < 0.05,
                "impact speed {speed}, expected {expected}"
            );
        }
        other => panic!("expected a hard impact, got {other:?}"),
    }
    // Touchdown was reported at the same instant as the crash.
    assert!(
        plant
            .events()
            .iter()
            .any(|e| e.kind == EventKind::Touchdown)
    );
}

#[test]
fn a_gentle_touchdown_is_not_a_crash() {
    // 5 cm: about 1 m/s at impact.
    let plant = drop_from(0.05, DRIVE);
    assert!(plant.crash().is_none(), "{:?}", plant.crash());
    assert!(plant.contact_signal());
    let x = plant.state();
    assert!(Vector3::new(x[idx::VX], x[idx::VY], x[idx::VZ]).norm() < 1e-3);
}

#[test]
fn landing_flat_as_a_quadrotor_puts_the_base_on_the_ground() {
    // At varphi = 0 the shrouds lie above the base bottom: the base touches.
    let plant = drop_from(0.3, 0.0);
    let crash = plant.crash().expect("base contact must be reported");
    assert!(
        matches!(crash.kind, EventKind::Crash(CrashKind::BodyContact { .. })),
        "{crash:?}"
    );
}

#[test]
fn a_robot_landing_on_its_side_tips_over() {
    // Rolled by 80 deg: it lands on the shrouds of one side and the base.
    let mut x: State = level_at(0.5);
    x[idx::ROLL] = 80f64.to_radians();
    let mut plant = Plant::new(
        &robot(),
        &contact_only(),
        &TerrainConfig::flat(0.0),
        &InitialState::at(x, DRIVE),
        3,
    )
    .expect("a valid plant");
    plant
        .advance(&Command::idle(), 2.0)
        .expect("the plant steps");
    assert!(
        plant
            .events()
            .iter()
            .any(|e| matches!(e.kind, EventKind::Crash(CrashKind::TipOver { angle_deg }) if angle_deg > 60.0)),
        "{:?}",
        plant.events()
    );
}

#[test]
fn driven_wheels_roll_the_robot_forward_and_turn_it() {
    let mut plant = parked(&TerrainConfig::flat(0.0));
    plant.advance(&Command::idle(), 1.0).unwrap();
    let start = plant.state();
    // 4 rad/s on both wheels: 0.5 m/s forward.
    let mut cmd = Command::idle();
    cmd.wheel_rates.left = 4.0;
    cmd.wheel_rates.right = 4.0;
    plant.advance(&cmd, 4.0).unwrap();
    let x = plant.state();
    let speed = x[idx::VX];
    assert!((speed - 0.5).abs() < 0.02, "speed {speed}");
    assert!(
        (x[idx::X] - start[idx::X]) > 1.5,
        "moved {}",
        x[idx::X] - start[idx::X]
    );
    assert!(x[idx::Y].abs() < 0.01 && x[idx::YAW].abs() < 0.01);
    assert!(plant.crash().is_none());
    // Left faster than right: FRD yaw rate positive (turns right).
    cmd.wheel_rates.left = 6.0;
    cmd.wheel_rates.right = 2.0;
    plant.advance(&cmd, 2.0).unwrap();
    let x = plant.state();
    let omega = x[idx::WZ];
    // Kinematic value R (wl - wr) / (2 l) with the actual track. Four wheels
    // on two belts turn by skidding (front and back wheels slide sideways),
    // so the yaw rate is a fraction of it (about 0.42 with the default
    // friction): right way round, and neither stuck nor above kinematic.
    let track_half = 0.138;
    let expected = 0.125 * 4.0 / (2.0 * track_half);
    assert!(
        omega > 0.3 * expected && omega < expected,
        "yaw rate {omega}, kinematic {expected}"
    );
    // Commands beyond the motor limit are held to it.
    cmd.wheel_rates.left = 50.0;
    cmd.wheel_rates.right = 50.0;
    plant.advance(&cmd, 3.0).unwrap();
    let rates = plant.wheel_rates();
    assert!(
        (rates.left - 10.0).abs() < 0.05 && (rates.right - 10.0).abs() < 0.05,
        "{rates:?}"
    );
}

#[test]
fn the_wheels_touch_first_from_about_35_deg_of_tilt() {
    // Gentle touchdowns (5 cm) at landing tilts: the shroud wheels take the load.
    for deg in [40.0_f64, 60.0, 70.0, 90.0] {
        let plant = drop_from(0.05, deg.to_radians());
        assert!(plant.crash().is_none(), "{deg} deg: {:?}", plant.crash());
        assert!(plant.contact_signal(), "{deg} deg");
    }
    // Below about 33 deg the base (bottom 0.06 m below B) reaches the ground
    // before the wheels. Dropped with its lowest point 5 cm up.
    for deg in [0.0_f64, 20.0] {
        let tilt = deg.to_radians();
        assert!(
            wheel_drop(tilt) < 0.06,
            "{deg} deg: the base is the lowest point"
        );
        let x = level_at(0.06 + 0.05);
        let mut plant = Plant::new(
            &robot(),
            &contact_only(),
            &TerrainConfig::flat(0.0),
            &InitialState::at(x, tilt),
            3,
        )
        .unwrap();
        assert!(plant.crash().is_none());
        plant.advance(&Command::idle(), 1.0).unwrap();
        assert!(
            matches!(
                plant.crash().map(|c| c.kind),
                Some(EventKind::Crash(CrashKind::BodyContact { .. }))
            ),
            "{deg} deg: {:?}",
            plant.crash()
        );
    }
}
