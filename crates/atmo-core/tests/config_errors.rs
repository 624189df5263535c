//! Every kind of bad robot file is refused with an error that names the
//! file, the key and what was expected.

use atmo_core::{ConfigFile, CoreError, RobotConfig};

const GOOD: &str = include_str!("../../../config/atmo.toml");
const FILE: &str = "robots/bad.toml";

fn load_with(from: &str, to: &str) -> CoreError {
    assert!(GOOD.contains(from), "test setup: `{from}` not in atmo.toml");
    let text = GOOD.replacen(from, to, 1);
    RobotConfig::from_toml_str(&text, FILE).expect_err("must be refused")
}

fn message(err: &CoreError) -> String {
    let msg = err.to_string();
    assert!(msg.contains(FILE), "error does not name the file: {msg}");
    msg
}

#[test]
fn the_shipped_file_is_valid_and_loads_from_disk() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/atmo.toml");
    let cfg = RobotConfig::load(path).unwrap();
    assert_eq!(cfg, RobotConfig::atmo());
    assert_eq!(cfg.base.mass, 2.33);
}

#[test]
fn missing_file_names_the_path() {
    let err = RobotConfig::load("/nonexistent/atmo.toml").unwrap_err();
    assert!(matches!(err, CoreError::ConfigRead { .. }));
    assert!(err.to_string().contains("/nonexistent/atmo.toml"));
    // The message says the cause, so the error does not also return it:
    // a printed chain (`{:#}`, "Caused by") said it twice.
    assert!(std::error::Error::source(&err).is_none());
    assert_eq!(err.to_string().matches("No such file").count(), 1, "{err}");
}

#[test]
fn unknown_key_is_an_error_with_its_path_and_line() {
    let err = load_with("half_track = 0.135", "half_track = 0.135\nwheel_colour = 3");
    let msg = message(&err);
    assert!(matches!(err, CoreError::ConfigParse { .. }), "{msg}");
    assert!(msg.contains("wheel_colour"), "{msg}");
    assert!(msg.contains("wheels"), "{msg}");
    let line = GOOD
        .lines()
        .position(|l| l.starts_with("half_track"))
        .unwrap()
        + 2;
    assert!(
        msg.contains(&format!(":{line}:")),
        "expected line {line}: {msg}"
    );
}

#[test]
fn unknown_section_is_an_error() {
    let err = load_with("[limits]", "[propellers]\npitch = 4.5\n\n[limits]");
    assert!(message(&err).contains("propellers"));
}

#[test]
fn missing_key_is_an_error_naming_it() {
    let err = load_with("k_moment = 0.018", "");
    let msg = message(&err);
    assert!(msg.contains("rotor"), "{msg}");
    assert!(msg.contains("k_moment"), "{msg}");
}

#[test]
fn wrong_type_is_an_error_naming_the_key() {
    let err = load_with("radius = 0.125", "radius = \"big\"");
    let msg = message(&err);
    assert!(msg.contains("wheels.radius"), "{msg}");
    assert!(msg.contains("string"), "{msg}");
}

#[test]
fn wrong_vector_length_is_an_error() {
    let err = load_with(
        "base_to_hinge = [0.0066, 0.0685, -0.021]",
        "base_to_hinge = [0.0066, 0.0685]",
    );
    assert!(message(&err).contains("arm.base_to_hinge"));
}

#[test]
fn negative_mass_is_out_of_range() {
    let err = load_with("mass = 2.33", "mass = -2.33");
    let msg = message(&err);
    assert!(matches!(err, CoreError::ConfigValue { .. }));
    assert!(
        msg.contains("base.mass") && msg.contains("[0.001, 1000] kg") && msg.contains("-2.33"),
        "{msg}"
    );
}

#[test]
fn a_robot_too_heavy_for_its_rotors_is_refused_naming_the_thrust_and_the_reason() {
    // base.mass 20 kg: thrust-to-weight 112.6 N / (23.16 kg g) = 0.496.
    let err = load_with("mass = 2.33", "mass = 20.0");
    let msg = message(&err);
    assert!(
        msg.contains("rotor.k_thrust")
            && msg.contains("thrust-to-weight 0.496")
            && msg.contains("cannot fly")
            && msg.contains("limits.thrust_reserve = 1.35"),
        "{msg}"
    );
    // Flies, but without the flight reserve of 1.35 (thrust-to-weight 1.30).
    let err = load_with("k_thrust = 28.15", "k_thrust = 17.5");
    assert!(message(&err).contains("thrust-to-weight 1.30"), "{err}");
}

#[test]
fn an_absurd_mass_is_refused_at_its_own_key() {
    let err = load_with("mass = 2.33", "mass = 1e308");
    let msg = message(&err);
    assert!(
        msg.contains("base.mass") && msg.contains("[0.001, 1000] kg"),
        "{msg}"
    );
}

/// "Positive" let a wheel of 1e9 m and an encoder of 1e-300 counts per
/// revolution (0 counts over the whole tilt) through: every length, rate
/// and count has a physical range now.
#[test]
fn absurd_geometry_and_encoder_values_are_refused_at_their_keys() {
    for (from, to, key, range) in [
        (
            "radius = 0.125",
            "radius = 1e9",
            "wheels.radius",
            "[0.001, 10] m",
        ),
        (
            "counts_per_rev = 1632.67",
            "counts_per_rev = 1e-300",
            "linkage.counts_per_rev",
            "[1, 1000000000] counts",
        ),
        ("d1 = 0.052", "d1 = 1e300", "linkage.d1", "[0.0001, 10] m"),
        (
            "transition_height = 0.45",
            "transition_height = 1e-9",
            "limits.transition_height",
            "[0.01, 100] m",
        ),
    ] {
        let msg = message(&load_with(from, to));
        assert!(msg.contains(key) && msg.contains(range), "{to}: {msg}");
    }
}

#[test]
fn non_positive_definite_inertia_is_refused() {
    let err = load_with("xx = 0.0067, yy = 0.011", "xx = -0.0067, yy = 0.011");
    let msg = message(&err);
    assert!(
        msg.contains("base.inertia") && msg.contains("positive-definite"),
        "{msg}"
    );
}

#[test]
fn unphysical_inertia_is_refused() {
    // Positive definite but violating the triangle inequality.
    let err = load_with(
        "xx = 0.0067, yy = 0.011, zz = 0.0088",
        "xx = 0.0067, yy = 0.011, zz = 0.03",
    );
    assert!(message(&err).contains("triangle"));
}

#[test]
fn tilt_limits_out_of_order_are_refused() {
    let err = load_with(
        "tilt_transition_max_deg = 70.0",
        "tilt_transition_max_deg = 40.0",
    );
    let msg = message(&err);
    assert!(
        msg.contains("limits.tilt_transition_max_deg") && msg.contains("in order"),
        "{msg}"
    );
    let err = load_with("tilt_flight_max_deg = 50.0", "tilt_flight_max_deg = 95.0");
    assert!(message(&err).contains("limits.tilt_flight_max_deg"));
}

#[test]
fn morph_height_below_transition_height_is_refused() {
    let err = load_with("morph_height = 1.2", "morph_height = 0.3");
    assert!(message(&err).contains("limits.morph_height"));
}

#[test]
fn bad_yaw_sign_is_refused() {
    let err = load_with(
        "yaw_sign = [1.0, 1.0, -1.0, -1.0]",
        "yaw_sign = [1.0, 0.5, -1.0, -1.0]",
    );
    assert!(message(&err).contains("rotor.yaw_sign[1]"));
}

#[test]
fn a_linkage_that_cannot_reach_the_drive_configuration_is_refused() {
    let err = load_with("d1 = 0.052", "d1 = 0.030");
    assert!(message(&err).contains("linkage"));
}

#[test]
fn not_toml_at_all_is_an_error() {
    let err = RobotConfig::from_toml_str("this is = = not toml", FILE).unwrap_err();
    assert!(matches!(err, CoreError::ConfigParse { .. }));
    assert!(message(&err).contains(":1:"));
}

#[test]
fn the_physical_inertia_convention_loads_and_differs() {
    let text = GOOD.replace(
        "inertia_convention = \"authors_model\"",
        "inertia_convention = \"about_com\"",
    );
    let physical = RobotConfig::from_toml_str(&text, FILE).unwrap();
    let a = atmo_core::Model::new(&RobotConfig::atmo()).at_tilt(0.0);
    let b = atmo_core::Model::new(&physical).at_tilt(0.0);
    // Same mass and first moment, more roll and yaw inertia.
    assert_eq!(a.mass, b.mass);
    assert!((a.first_moment - b.first_moment).norm() < 1e-15);
    assert!(b.inertia[(0, 0)] - a.inertia[(0, 0)] > 0.08);
    // Physical everywhere, up to the drive configuration.
    let model = atmo_core::Model::new(&physical);
    assert!((0..=90).all(|d| model.composite_is_physical(f64::from(d).to_radians())));
    let err = RobotConfig::from_toml_str(&GOOD.replace("\"authors_model\"", "\"guess\""), FILE)
        .unwrap_err();
    assert!(message(&err).contains("arm.inertia_convention"));
}
