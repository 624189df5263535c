//! Effects the data cannot tell apart are reported as such: mass and
//! inertia both 5 % heavier act on the rigid body exactly like a thrust
//! coefficient 1 / 1.05 times the model's.

use atmo_core::{ConfigFile, RobotConfig};
use atmo_explain::synth::{Flight, Profile, record};
use atmo_explain::{Options, explain};
use atmo_plant::config::{EffectsConfig, MassErrorConfig, PlantConfig, SensorsConfig};

#[test]
fn equal_mass_and_inertia_scale_is_reported_as_indistinguishable_from_thrust_scale() {
    let robot = RobotConfig::atmo();
    let mut plant = PlantConfig::ideal();
    plant.arm_inertia_convention = robot.arm.inertia_convention;
    plant.effects = EffectsConfig {
        mass_error: Some(MassErrorConfig {
            enabled: true,
            mass_scale: 1.05,
            inertia_scale: 1.05,
        }),
        sensors: Some(SensorsConfig::default()),
        ..EffectsConfig::none()
    };
    let rec = record(&robot, &plant, &Flight::new(Profile::Mixed, 48.0, 9)).unwrap();
    let ex = explain(&rec, &robot, &Options::default()).unwrap();
    assert!(ex.mismatch_found);
    assert!(
        ex.verdict.contains("cannot tell it apart"),
        "{}",
        ex.verdict
    );
    // Whatever was selected, the pair is flagged.
    let flagged = ex.indistinguishable.iter().any(|(a, b)| {
        use atmo_explain::effects::Effect::{InertiaError, MassError, ThrustScale};
        (*a == ThrustScale && (*b == MassError || *b == InertiaError))
            || ((*a == MassError || *a == InertiaError) && *b == ThrustScale)
    });
    assert!(flagged, "{:?}", ex.indistinguishable);
    // And the fit is right whichever way it is written: the thrust seen
    // per unit mass is 1 / 1.05.
    let cfg = PlantConfig::from_toml_str(&ex.fitted_effects_toml, "fitted").unwrap();
    let m = cfg.effects.mass_error.expect("written as mass_error");
    assert!((m.mass_scale - 1.05).abs() < 0.01, "{}", m.mass_scale);
}
