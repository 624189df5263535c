//! `Preflight` against a ROS 2 peer (estimates and pilot at 100 Hz) and a
//! tilt driver on the driver ports that integrates the commanded tilt
//! velocity (exactly, or at half speed: a slipping belt), as
//! `atmo-daemon preflight` runs them.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use atmo_core::model::{State, idx};
use atmo_core::{ConfigFile, Linkage, RobotConfig};
use atmo_daemon::onboard::DaemonConfig;
use atmo_daemon::preflight::{Preflight, Report};
use atmo_io::drivers::{DriverEndpoint, DriverId};
use atmo_io::msg::PilotInput;
use atmo_io::ros2::{Ros2Node, Ros2StartOptions, SitlNode};

fn config(tag: &str) -> DaemonConfig {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config");
    let text = format!(
        "robot = \"atmo.toml\"\nflight = \"flight.toml\"\nmpc = \"mpc.toml\"\n\
         [ros2]\nloopback_only = true\n\
         [drivers]\niceoryx_prefix = \"atmo_preflight_{tag}_{}_\"\nliveness_timeout_ms = 200\n\
         [arming]\nestimate_window_ms = 400\ntilt_window_ms = 400\n",
        std::process::id()
    );
    DaemonConfig::from_toml_str(&text, dir.join("preflight-test.toml")).unwrap()
}

/// Runs a preflight with a tilt mechanism that moves `follows` times the
/// commanded velocity, starting at `start_deg`.
fn preflight(tag: &str, follows: f64, start_deg: f64, sweep_to_deg: f64) -> Report {
    let config = config(tag);
    let robot = RobotConfig::atmo();
    let domain = 140 + (std::process::id() % 20) as u16 + u16::from(tag.as_bytes()[0] % 10);
    let options = Ros2StartOptions {
        domain_id: Some(domain),
    };
    let (_out, ros_in, ros_thread) = Ros2Node::start(&config.ros2, options).unwrap();
    let (peer, _peer_in, peer_thread) = SitlNode::start(&config.ros2, options).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let drivers = config.drivers.clone();
    let peer_stop = Arc::clone(&stop);
    let linkage = Linkage::from_config(&robot.linkage, robot.limits.tilt_max()).unwrap();
    let robot_side = std::thread::spawn(move || {
        let mut driver = DriverEndpoint::open(&drivers, "preflight_test").unwrap();
        let mut state = State::zeros();
        state[idx::Z] = -0.1;
        let pilot = PilotInput {
            arm: true,
            offboard: true,
            mpc_enabled: true,
            ..PilotInput::default()
        };
        let mut tilt = start_deg.to_radians();
        let mut velocity = 0.0;
        let mut last = Instant::now();
        let mut stamp = 1_000_000_000u64;
        while !peer_stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(10));
            stamp += 10_000_000;
            peer.try_publish_estimate(&state, stamp);
            peer.try_publish_pilot(&pilot);
            let dt = last.elapsed().as_secs_f64();
            last = Instant::now();
            tilt = (tilt + follows * velocity * dt).clamp(0.0, std::f64::consts::FRAC_PI_2);
            if let Some(c) = driver.receive().tilt_velocity {
                velocity = c.velocity;
            }
            let counts = linkage.counts_from_tilt(tilt).unwrap();
            driver.publish_tilt_encoder(counts.round() as i64);
            driver.publish_ground_contact(false);
            for d in DriverId::ALL {
                driver.publish_heartbeat(d);
            }
        }
    });
    let mut preflight = Preflight::open(&config, &robot, ros_in, 150.0, 0.1).unwrap();
    let report = preflight.run(Some(sweep_to_deg));
    drop(preflight);
    stop.store(true, Ordering::Relaxed);
    robot_side.join().unwrap();
    ros_thread.stop().unwrap();
    peer_thread.stop().unwrap();
    println!("{report}");
    report
}

#[test]
fn a_healthy_robot_passes_every_row_and_a_slipping_belt_fails_the_sweep() {
    let healthy = preflight("ok", 1.0, 10.0, 30.0);
    assert!(healthy.passed(), "{healthy}");
    assert_eq!(healthy.rows.len(), 5 + 3, "five checks, three legs");
    assert!(healthy.to_string().ends_with("all 8 passed"));

    let slipping = preflight("slip", 0.5, 0.0, 30.0);
    let failed: Vec<&str> = slipping
        .rows
        .iter()
        .filter(|r| !r.pass)
        .map(|r| r.check.as_str())
        .collect();
    // At rest the encoder agrees; moving, it lags half the command behind.
    assert_eq!(
        failed,
        ["tilt sweep to 30 deg", "tilt sweep to 0 deg"],
        "{slipping}"
    );
    assert!(slipping.to_string().contains("FAILED"));
}
