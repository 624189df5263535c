//! `atmo-daemon check` refuses a robot the physics cannot fly, naming the
//! file, the key and the reason, and accepts the shipped files.
// Test code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn config_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config")
}

/// A copy of `config/` in a fresh folder, with `atmo.toml`'s `from` replaced.
fn configs_with(tag: &str, from: &str, to: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("atmo-check-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for name in ["daemon.toml", "flight.toml", "mpc.toml", "atmo.toml"] {
        let text = std::fs::read_to_string(config_dir().join(name)).unwrap();
        let text = if name == "atmo.toml" {
            assert!(text.contains(from), "test setup: `{from}` not in atmo.toml");
            text.replacen(from, to, 1)
        } else {
            text
        };
        std::fs::write(dir.join(name), text).unwrap();
    }
    dir
}

fn check(dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_atmo-daemon"))
        .args(["check", "--config"])
        .arg(dir.join("daemon.toml"))
        .output()
        .unwrap()
}

#[test]
fn check_accepts_the_shipped_configuration() {
    let out = check(&config_dir());
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

#[test]
fn check_prints_the_radio_and_the_arming_configuration_verdict() {
    let out = Command::new(env!("CARGO_BIN_EXE_atmo-daemon"))
        .args(["check", "--config"])
        .arg(config_dir().join("daemon-robot.toml"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("radio  /fmu/out/input_rc") && stdout.contains("kill ch 5"),
        "{stdout}"
    );
    assert!(
        stdout.contains("arming configuration check: can fly"),
        "{stdout}"
    );
}

#[test]
fn check_refuses_a_robot_with_thrust_to_weight_below_one() {
    // base.mass 20 kg: thrust-to-weight 0.50: a robot that cannot hover.
    let dir = configs_with("heavy", "mass = 2.33", "mass = 20.0");
    let out = check(&dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "accepted: {stderr}");
    assert!(
        stderr.contains("atmo.toml")
            && stderr.contains("rotor.k_thrust")
            && stderr.contains("cannot fly"),
        "{stderr}"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn check_refuses_an_absurd_mass_at_its_key() {
    let dir = configs_with("absurd", "mass = 2.33", "mass = 1e308");
    let out = check(&dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "accepted: {stderr}");
    assert!(
        stderr.contains("atmo.toml") && stderr.contains("base.mass"),
        "{stderr}"
    );
    std::fs::remove_dir_all(dir).unwrap();
}

/// `yaw_sign` with 6 items, one a string, and `ground_z = 1e300` passed
/// `check`: both refused, naming the file and the key.
#[test]
fn check_refuses_an_overlong_array_and_an_absurd_ground_height() {
    let dir = configs_with(
        "yaw6",
        "yaw_sign = [1.0, 1.0, -1.0, -1.0]",
        "yaw_sign = [1.0, 1.0, -1.0, -1.0, 1.0, \"x\"]",
    );
    let out = check(&dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "accepted: {stderr}");
    assert!(
        stderr.contains("atmo.toml") && stderr.contains("rotor.yaw_sign"),
        "{stderr}"
    );

    let dir = configs_with("ground", "yaw_sign", "yaw_sign");
    let daemon = std::fs::read_to_string(dir.join("daemon.toml")).unwrap();
    assert!(daemon.contains("ground_z = 0.0"));
    std::fs::write(
        dir.join("daemon.toml"),
        daemon.replacen("ground_z = 0.0", "ground_z = 1e300", 1),
    )
    .unwrap();
    let out = check(&dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "accepted: {stderr}");
    assert!(
        stderr.contains("daemon.toml") && stderr.contains("`ground_z`"),
        "{stderr}"
    );
}

/// `atmo-daemon check --params | head` panicked in println! once `head`
/// had gone: a command that only prints ends by SIGPIPE, as a C tool does.
#[cfg(unix)]
#[test]
fn check_ends_quietly_when_its_reader_is_gone() {
    let mut check = Command::new(env!("CARGO_BIN_EXE_atmo-daemon"));
    check.args(["check", "--params"]);
    atmo_core::closed_stdout::ends_by_sigpipe(&mut check).unwrap();
}

/// `check` says what a failsafe flies once the estimate is lost for good:
/// with the motion capture as the estimate, the open-loop trim unless the
/// autopilot's estimate is enabled; PX4's odometry cannot be both.
#[test]
fn check_says_what_flies_an_estimate_lost_for_good() {
    let stdout = |out: &Output| String::from_utf8_lossy(&out.stdout).into_owned();
    let shipped = check(&config_dir());
    assert!(
        stdout(&shipped).contains("estimate lost: open-loop trim"),
        "{}",
        stdout(&shipped)
    );
    let dir = configs_with("autopilot", "", "");
    let daemon = std::fs::read_to_string(dir.join("daemon.toml")).unwrap();
    let enabled = "type = \"px4_msgs/msg/VehicleOdometry\", enabled = true }";
    let daemon = daemon.replacen(
        "type = \"px4_msgs/msg/VehicleOdometry\", enabled = false }",
        enabled,
        1,
    );
    assert!(
        daemon.contains(enabled),
        "test setup: the topic's line moved"
    );
    std::fs::write(dir.join("daemon.toml"), &daemon).unwrap();
    let out = check(&dir);
    assert!(
        stdout(&out).contains(
            "estimate lost: level descent on the autopilot's estimate /fmu/out/vehicle_odometry"
        ),
        "{}",
        stdout(&out)
    );
    // PX4's odometry as the estimate too: one topic for two roles, refused.
    let both = daemon.replacen(
        "estimate = { name = \"/atmo/mocap/odom\", type = \"nav_msgs/msg/Odometry\" }",
        "estimate = { name = \"/fmu/out/vehicle_odometry\", type = \"px4_msgs/msg/VehicleOdometry\" }",
        1,
    );
    assert_ne!(both, daemon, "test setup: the estimate's line moved");
    std::fs::write(dir.join("daemon.toml"), both).unwrap();
    let out = check(&dir);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("key `ros2.topics.autopilot_estimate.name`"),
        "{stderr}"
    );
    std::fs::remove_dir_all(dir).unwrap();
}
