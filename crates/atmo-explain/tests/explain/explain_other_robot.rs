//! The discrepancy finder is driven by the robot file it is given: a plain
//! quadrotor (`config/quadrotor.toml`: ATMO's format at varphi = 0 with a
//! 1.24 kg airframe's parameters), flown by the MPC on its own model, with a
//! motor lag concealed and with nothing concealed.
// Helpers outside #[test] functions unwrap too (clippy.toml allows it in tests only).
#![allow(clippy::unwrap_used)]

use atmo_core::{ConfigFile, RobotConfig};
use atmo_explain::effects::Effect;
use atmo_explain::parameter::Param;
use atmo_explain::recording::Recording;
use atmo_explain::synth::{Flight, Profile, record};
use atmo_explain::{Explanation, Options, explain};
use atmo_plant::config::{EffectsConfig, MotorLagConfig, PlantConfig, SensorsConfig};

fn quadrotor() -> RobotConfig {
    RobotConfig::load(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../config/quadrotor.toml"
    ))
    .expect("config/quadrotor.toml loads")
}

fn quadrotor_flight(effects: EffectsConfig) -> Recording {
    let robot = quadrotor();
    let mut plant = PlantConfig::ideal();
    plant.arm_inertia_convention = robot.arm.inertia_convention;
    plant.effects = effects;
    plant.effects.sensors = Some(SensorsConfig::default());
    let rec = record(&robot, &plant, &Flight::new(Profile::Cruise, 36.0, 21)).unwrap();
    assert!(rec.samples.iter().all(|s| s.varphi == 0.0));
    rec
}

fn analyse(effects: EffectsConfig) -> Explanation {
    explain(
        &quadrotor_flight(effects),
        &quadrotor(),
        &Options::default(),
    )
    .unwrap()
}

#[test]
fn the_model_is_the_robot_files_a_quadrotor_with_a_concealed_motor_lag() {
    let ex = analyse(EffectsConfig {
        motor_lag: Some(MotorLagConfig::default()),
        ..EffectsConfig::none()
    });
    assert!(ex.mismatch_found);
    assert_eq!(ex.effects[0].name, Effect::MotorLag, "{}", ex.verdict);
    assert!(ex.effects[0].selected);
    let others = ex.confidently_claimed_besides(&[Effect::MotorLag]);
    assert!(others.is_empty(), "{others:?} claimed: {}", ex.verdict);
    let tau = ex.parameter(Param::TimeConstant).unwrap();
    assert!((tau - 0.03).abs() <= 0.15 * 0.03, "time constant {tau}");
    let (b, a) = (
        ex.heldout_rms_before.located_normalized,
        ex.heldout_rms_after.located_normalized,
    );
    assert!(a <= 0.4 * b, "located-region RMS {b:.3} -> {a:.3}");
}

#[test]
fn a_quadrotor_flown_on_its_own_model_shows_no_mismatch_and_against_atmos_a_mismatch() {
    let rec = quadrotor_flight(EffectsConfig::none());
    let ex = explain(&rec, &quadrotor(), &Options::default()).unwrap();
    assert!(!ex.mismatch_found, "{}", ex.verdict);
    assert!(ex.selected().is_empty());
    assert!(ex.verdict.starts_with("no significant mismatch"));
    // The same flight against ATMO's file: the analysis really uses the
    // model it is given.
    let wrong = explain(&rec, &RobotConfig::atmo(), &Options::default()).unwrap();
    assert!(wrong.mismatch_found, "{}", wrong.verdict);
    assert!(!wrong.located.is_empty());
    println!(
        "quadrotor flight against ATMO's model: {}; located-region RMS {:.1} noise floors",
        wrong.verdict, wrong.heldout_rms_before.located_normalized
    );
}
