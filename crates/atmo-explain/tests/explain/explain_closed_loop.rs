//! Closing the loop once: the ground effect fitted from one flight, written
//! as a plant file and loaded into the plant, makes a replayed landing
//! approach (another flight) match its recording better.
// Helpers outside #[test] functions unwrap too (clippy.toml allows it in tests only).
#![allow(clippy::unwrap_used)]

use atmo_core::ground_effect::table::GroundEffectConfig;
use atmo_core::{ConfigFile, RobotConfig};
use atmo_explain::data::Prepared;
use atmo_explain::output::write_all;
use atmo_explain::replay::{replay, start_rows};
use atmo_explain::synth::{Flight, Profile, record};
use atmo_explain::{Options, explain};
use atmo_plant::PlantTemplate;
use atmo_plant::config::{EffectsConfig, PlantConfig, SensorsConfig};

#[test]
fn fitted_ground_effect_makes_a_replayed_landing_match_better() {
    let robot = RobotConfig::atmo();
    let mut truth = PlantConfig::ideal();
    truth.arm_inertia_convention = robot.arm.inertia_convention;
    truth.effects = EffectsConfig {
        ground_effect: Some(GroundEffectConfig::default()),
        sensors: Some(SensorsConfig::default()),
        ..EffectsConfig::none()
    };
    // Calibration flight -> fitted_effects.toml.
    let calibration = record(&robot, &truth, &Flight::new(Profile::Mixed, 48.0, 11)).unwrap();
    let ex = explain(&calibration, &robot, &Options::default()).unwrap();
    assert!(
        ex.selected()
            .contains(&atmo_explain::effects::Effect::GroundEffect),
        "{}",
        ex.verdict
    );
    let dir = std::env::temp_dir().join(format!("atmo_explain_loop_{}", std::process::id()));
    write_all(&ex, &dir).unwrap();
    let fitted = PlantConfig::load(dir.join("fitted_effects.toml")).unwrap();
    assert!(fitted.effects.ground_effect.is_some());

    // Another flight: a landing approach down to 0.22 m hub height at 50-55 deg.
    let landing = record(&robot, &truth, &Flight::new(Profile::Landing, 14.0, 12)).unwrap();
    let prep = Prepared::new(&landing, &robot).unwrap();
    let starts = start_rows(&prep, 1.0, 0.25);
    assert!(starts.len() > 20);
    let mut nominal = PlantConfig::ideal();
    nominal.arm_inertia_convention = robot.arm.inertia_convention;
    let nominal = PlantTemplate::new(&robot, &nominal).unwrap();
    let fitted = PlantTemplate::new(&robot, &fitted).unwrap();
    let before = replay(&landing, &prep, &starts, &|_| Some(&nominal), &|_| 0.0);
    let after = replay(&landing, &prep, &starts, &|_| Some(&fitted), &|_| 0.0);
    println!(
        "replayed landing, {} starts, 1 s each: height error {:.4} -> {:.4} m, vertical speed error {:.4} -> {:.4} m/s",
        before.starts, before.position[2], after.position[2], before.velocity[2], after.velocity[2]
    );
    assert_eq!(before.starts, after.starts);
    assert!(
        after.position[2] < 0.5 * before.position[2],
        "height error {} -> {}",
        before.position[2],
        after.position[2]
    );
    assert!(after.velocity[2] < 0.5 * before.velocity[2]);
    assert!(after.position_norm() < before.position_norm());
}
