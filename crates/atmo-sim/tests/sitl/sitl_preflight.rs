//! `atmo-daemon preflight` against `atmo-sim serve`: the arming checks on
//! the server's motion capture, pilot and drivers, and the props-off tilt
//! sweep moving the frozen plant's linkage through the tilt driver's port.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::process::Command;
use std::time::Duration;

use crate::sitl::{Process, daemon_config, domain, repo, run_dir, serial, sibling_binary};

#[test]
fn preflight_prints_a_passing_table_against_the_plant_server() {
    let _serial = serial();
    let dir = run_dir("preflight");
    let tag = format!("atmo_preflight_{}", std::process::id());
    let config = daemon_config(&dir, &tag);
    let domain = domain();
    let mut server = Command::new(env!("CARGO_BIN_EXE_atmo-sim"));
    server
        .arg("serve")
        .arg(repo().join("config/scenarios/wheel_landing.toml"))
        .arg("--config")
        .arg(&config)
        .arg("--out")
        .arg(dir.join("sitl"))
        .args(["--quiet", "--start-timeout", "60"])
        .env("ROS_DOMAIN_ID", &domain);
    let server = Process::spawn("atmo-sim serve", server, &dir);
    let mut preflight = Command::new(sibling_binary("atmo-daemon"));
    preflight
        .arg("preflight")
        .arg("--config")
        .arg(&config)
        .args(["--sweep-to-deg", "30"])
        .env("ROS_DOMAIN_ID", &domain);
    let mut preflight = Process::spawn("atmo-daemon preflight", preflight, &dir);
    let status = preflight.wait(Duration::from_secs(90));
    let table = std::fs::read_to_string(dir.join("atmo-daemon preflight.stdout")).unwrap();
    println!("{table}");
    drop(server);
    assert!(
        status.success(),
        "preflight exit {status}:\n{table}\nstderr:\n{}",
        preflight.stderr()
    );
    for row in [
        "arming: estimate rate  PASS",
        "arming: drivers        PASS",
        "arming: tilt encoder   PASS",
        "tilt sweep to 30 deg   PASS",
        "preflight: all 8 passed",
    ] {
        assert!(table.contains(row), "{row}:\n{table}");
    }
}
