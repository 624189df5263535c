//! The daemon config's checks that need the whole `config/daemon.toml`:
//! the configuration problem the arming checks report, and one pilot
//! source.
// Test code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::Path;

use atmo_core::ConfigFile as _;
use atmo_daemon::onboard::DaemonConfig;

/// The three file keys every daemon file names; the tests add tables.
const BASE: &str = "robot = \"atmo.toml\"\nflight = \"flight.toml\"\nmpc = \"mpc.toml\"\n";

/// The error of `BASE` + `tables` read as `config/test.toml`.
fn refused(tables: &str) -> String {
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/test.toml");
    DaemonConfig::from_toml_str(&format!("{BASE}{tables}"), &file)
        .unwrap_err()
        .to_string()
}

#[test]
fn the_configuration_check_finds_a_daemon_that_cannot_fly() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config");
    for name in ["daemon.toml", "daemon-robot.toml"] {
        let config = DaemonConfig::load(dir.join(name)).unwrap();
        assert_eq!(config.flight_problem(), None, "{name}");
    }
    let file = dir.join("test.toml");
    let cases = [
        (
            "[ros2.topics]\npilot = { name = \"/p\", type = \"atmo_msgs/msg/PilotInput\", enabled = false }\n",
            "no pilot source",
        ),
        ("[drivers]\nrequired = [\"thrusters\"]\n", "lacks \"tilt\""),
        ("[drivers]\nrequired = [\"tilt\"]\n", "no thruster path"),
    ];
    for (text, problem) in cases {
        let config = DaemonConfig::from_toml_str(&format!("{BASE}{text}"), &file).unwrap();
        let found = config.flight_problem().unwrap_or_default();
        assert!(found.contains(problem), "{text}: {found}");
    }
}

#[test]
fn the_daemon_config_takes_one_pilot_source_and_names_a_bad_rc_key() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config");
    for name in ["daemon.toml", "daemon-robot.toml"] {
        let config = DaemonConfig::load(dir.join(name)).unwrap();
        let topics = &config.ros2.topics;
        assert!(topics.rc.enabled != topics.pilot.enabled, "{name}");
    }
    let err = refused(
        "[ros2.topics]\nrc = { name = \"/fmu/out/input_rc\", type = \"px4_msgs/msg/InputRc\" }\n",
    );
    assert!(
        err.contains("ros2.topics.pilot.enabled") && err.contains("test.toml"),
        "{err}"
    );
    let err = refused("[rc.sticks.yaw]\nchannel = 0\n");
    assert!(err.contains("rc.sticks.yaw.channel"), "{err}");
    let err = refused("[rc]\nkill_channel = 5\n");
    assert!(err.contains("kill_channel"), "{err}");
}

/// Found by trying hostile files on this build: a driver named twice in
/// `drivers.required` was accepted, and a number too large for TOML was
/// reported at key `(document)`; both now name their key.
#[test]
fn a_driver_required_twice_and_an_overflowing_number_name_their_key() {
    let err = refused("[drivers]\nrequired = [\"thrusters\", \"tilt\", \"thrusters\"]\n");
    assert!(
        err.contains("drivers.required[2]") && err.contains("each driver named once"),
        "{err}"
    );
    let err = refused("[log]\nqueue_capacity = 18446744073709551615\n");
    assert!(
        err.contains("test.toml:5: key `log.queue_capacity`"),
        "{err}"
    );
}
