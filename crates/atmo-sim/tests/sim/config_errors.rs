//! Bad plant and scenario files are refused with errors naming the file and key.

use atmo_core::{ConfigFile, CoreError};
use atmo_plant::config::PlantConfig;
use atmo_sim::{Scenario, SimError};

const PLANT: &str = include_str!("../../../../config/plant.toml");
const PLANT_FILE: &str = "plants/bad.toml";
const SCENARIO: &str = include_str!("../../../../config/scenarios/wheel_landing.toml");

fn scenario_path() -> String {
    // Next to the real file, so that its relative plant path resolves.
    format!(
        "{}/../../config/scenarios/bad_scenario.toml",
        env!("CARGO_MANIFEST_DIR")
    )
}

fn plant_error(from: &str, to: &str) -> String {
    assert!(
        PLANT.contains(from),
        "test setup: `{from}` not in plant.toml"
    );
    let err = PlantConfig::from_toml_str(&PLANT.replacen(from, to, 1), PLANT_FILE)
        .expect_err("must be refused");
    let msg = err.to_string();
    assert!(
        msg.contains(PLANT_FILE),
        "error does not name the file: {msg}"
    );
    msg
}

fn scenario_error(from: &str, to: &str) -> (SimError, String) {
    assert!(
        SCENARIO.contains(from),
        "test setup: `{from}` not in the scenario"
    );
    let err = Scenario::from_toml_str(&SCENARIO.replacen(from, to, 1), scenario_path())
        .expect_err("must be refused");
    let msg = err.to_string();
    assert!(
        msg.contains("bad_scenario.toml"),
        "error does not name the file: {msg}"
    );
    (err, msg)
}

#[test]
fn the_shipped_plant_file_switches_every_effect_on() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/plant.toml");
    let cfg = PlantConfig::load(path).unwrap();
    assert_eq!(cfg.effects.enabled_names().len(), 10);
    assert_eq!(cfg.dt, 0.001);
}

#[test]
fn unknown_effect_is_an_error_naming_it_and_its_line() {
    let msg = plant_error(
        "[effects.drag]",
        "[effects.gyro_magic]\ngain = 1.0\n\n[effects.drag]",
    );
    assert!(msg.contains("gyro_magic"), "{msg}");
    assert!(msg.contains("effects"), "{msg}");
    let line = PLANT
        .lines()
        .position(|l| l.starts_with("[effects.drag]"))
        .unwrap()
        + 1;
    assert!(
        msg.contains(&format!(":{line}:")) || msg.contains(&format!(":{}:", line + 1)),
        "line {line}: {msg}"
    );
}

#[test]
fn unknown_key_in_an_effect_is_an_error() {
    let msg = plant_error("curve = 0.0", "curve = 0.0\nsmoothness = 2");
    assert!(
        msg.contains("smoothness") && msg.contains("motor_lag"),
        "{msg}"
    );
}

#[test]
fn negative_time_constant_is_an_error_naming_the_key() {
    let msg = plant_error("time_constant = 0.03", "time_constant = -0.03");
    assert!(msg.contains("effects.motor_lag.time_constant"), "{msg}");
    assert!(msg.contains("-0.03"), "{msg}");
}

#[test]
fn a_gust_out_of_range_is_an_error_naming_its_index() {
    let msg = plant_error(
        "# gusts = [",
        "gusts = [{ t = 5.0, duration = 1.0, velocity = [2.0, 0.0, 0.0] }, \
         { t = 6.0, duration = 0.0, velocity = [1.0, 0.0, 0.0] }]\n# gusts = [",
    );
    assert!(msg.contains("effects.wind.gusts[1].duration"), "{msg}");
}

#[test]
fn a_motor_lag_curve_beside_a_thrust_curve_is_an_error() {
    let msg = plant_error(
        "curve = 0.0",
        "curve = 0.2\n\n[effects.thrust_curve]\ncurve = 0.1",
    );
    assert!(msg.contains("effects.motor_lag.curve"), "{msg}");
    assert!(msg.contains("effects.thrust_curve"), "{msg}");
}

#[test]
fn a_step_above_one_millisecond_is_an_error() {
    let msg = plant_error("dt = 0.001", "dt = 0.002");
    assert!(msg.contains("`dt`"), "{msg}");
}

#[test]
fn a_ragged_ground_effect_table_is_an_error() {
    let msg = plant_error(
        "[0.190, 0.120, 0.070, 0.035, 0.010, 0.0]",
        "[0.190, 0.120, 0.070]",
    );
    assert!(msg.contains("effects.ground_effect.gain[1]"), "{msg}");
}

#[test]
fn unphysical_mass_errors_are_refused_by_the_plant() {
    use atmo_plant::config::{EffectsConfig, MassErrorConfig, TerrainConfig};
    use atmo_plant::plant::{InitialState, Plant};
    let mut cfg = PlantConfig::ideal();
    cfg.effects = EffectsConfig {
        mass_error: Some(MassErrorConfig {
            enabled: true,
            mass_scale: 2.0,
            inertia_scale: 0.5,
        }),
        ..EffectsConfig::none()
    };
    let x = atmo_core::model::State::zeros();
    let err = Plant::new(
        &atmo_core::RobotConfig::atmo(),
        &cfg,
        &TerrainConfig::flat(-10.0),
        &InitialState::at(x, 0.0),
        1,
    )
    .expect_err("must be refused");
    assert!(
        err.to_string().contains("effects.mass_error.inertia_scale"),
        "{err}"
    );
}

#[test]
fn slope_out_of_range_is_an_error_naming_the_key() {
    let (err, msg) = scenario_error(
        "[terrain]\nheight = 0.0",
        "[terrain]\nheight = 0.0\nslope_deg = 30.0",
    );
    assert!(
        matches!(err, SimError::Core(CoreError::ConfigValue { .. })),
        "{msg}"
    );
    assert!(
        msg.contains("terrain.slope_deg") && msg.contains("30"),
        "{msg}"
    );
}

#[test]
fn a_scenario_effect_override_is_checked_too() {
    let (_, msg) = scenario_error(
        "[initial]",
        "[effects.motor_lag]\ntime_constant = -1.0\n\n[initial]",
    );
    assert!(msg.contains("effects.motor_lag.time_constant"), "{msg}");
    let (_, msg) = scenario_error(
        "[initial]",
        "[effects.rotor_icing]\nrate = 1.0\n\n[initial]",
    );
    assert!(msg.contains("rotor_icing"), "{msg}");
}

#[test]
fn a_pilot_velocity_above_one_metre_per_second_is_an_error() {
    let (_, msg) = scenario_error("velocity = [0.5, 0.0, 0.0]", "velocity = [1.2, 0.0, 0.0]");
    assert!(msg.contains("pilot[1].velocity"), "{msg}");
    // A huge component is reported as given (its squared norm overflowed:
    // "got inf").
    let (_, msg) = scenario_error("velocity = [0.5, 0.0, 0.0]", "velocity = [0.5, 0.0, 1e300]");
    assert!(msg.ends_with("got 1e300"), "{msg}");
}

#[test]
fn an_open_loop_entry_needs_exactly_one_rotor_source() {
    let (_, msg) = scenario_error(
        "trim_scale = 0.99",
        "trim_scale = 0.99\nrotors = [0.5, 0.5, 0.5, 0.5]",
    );
    assert!(msg.contains("open_loop[2].rotors"), "{msg}");
}

#[test]
fn unknown_scenario_key_names_its_path() {
    let (err, msg) = scenario_error("throttle = 0.35", "throttle = 0.35\nflaps = true");
    assert!(
        matches!(err, SimError::Core(CoreError::ConfigParse { .. })),
        "{msg}"
    );
    assert!(msg.contains("pilot") && msg.contains("flaps"), "{msg}");
}

#[test]
fn times_out_of_order_are_an_error() {
    let (_, msg) = scenario_error("t = 3.0\ntrim_scale = 0.99", "t = 0.2\ntrim_scale = 0.99");
    assert!(msg.contains("open_loop[2].t"), "{msg}");
}

#[test]
fn a_missing_plant_file_is_named() {
    let text = SCENARIO.replacen(
        "plant = \"../plant.toml\"",
        "plant = \"../no_such_plant.toml\"",
        1,
    );
    let err = Scenario::from_toml_str(&text, scenario_path()).expect_err("must be refused");
    assert!(
        matches!(err, SimError::Core(CoreError::ConfigRead { .. })),
        "{err}"
    );
    assert!(err.to_string().contains("no_such_plant.toml"), "{err}");
}

/// A device named as a configuration (`atmo-sim fly /dev/zero`) was read
/// until memory ran out: every configuration file is read through the one
/// input rule (`atmo_core::input_file`), refused before reading, naming
/// the file.
#[test]
fn a_device_or_a_folder_named_as_a_configuration_is_refused_before_reading() {
    let folder = std::env::temp_dir();
    let mut paths = vec![folder.clone()];
    paths.extend(
        ["/dev/zero", "/dev/null"]
            .map(std::path::PathBuf::from)
            .into_iter()
            .filter(|p| p.exists()),
    );
    for path in paths {
        let scenario = Scenario::load(&path).unwrap_err().to_string();
        let robot = atmo_core::RobotConfig::load(&path).unwrap_err().to_string();
        for msg in [scenario, robot] {
            assert!(
                msg.contains(&path.display().to_string()) && msg.contains("not a regular file"),
                "{msg}"
            );
        }
    }
    let latin1 = folder.join(format!("atmo-latin1-{}.toml", std::process::id()));
    std::fs::write(&latin1, b"name = \"caf\xe9\"\n").unwrap();
    let msg = PlantConfig::load(&latin1).unwrap_err().to_string();
    std::fs::remove_file(&latin1).unwrap();
    assert!(
        msg.contains("atmo-latin1") && msg.contains("not UTF-8 text"),
        "{msg}"
    );
}
