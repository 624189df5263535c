//! SITL over ROS 2: a `SitlNode` (the plant server's side) and a `Ros2Node`
//! (the daemon's side) in one process, both from the same `Ros2Config`, on
//! loopback and their own domain id: estimates and pilot inputs from the
//! plant arrive at the daemon unchanged (on the autopilot's estimate topic
//! too when it is enabled), the daemon's status arrives at the
//! plant unchanged, bad pilot inputs are rejected and counted, and the
//! pilot topic's type is checked in the config.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

mod support;

use std::time::{Duration, Instant};

use atmo_core::ConfigFile;
use atmo_core::model::State;
use atmo_io::msg::{MpcStatus, PilotInput, RosMessage, VehicleOdometry};
use atmo_io::ros2::{
    PilotCommand, Ros2Config, Ros2Inputs, Ros2Node, Ros2Publisher, Ros2StartOptions, Ros2Thread,
    SitlInputs, SitlNode, SitlPublisher, TopicConfig,
};
use support::status;

fn domain(offset: u16) -> u16 {
    // Away from 0 and from the other ROS 2 test binaries (100..=232).
    10 + (std::process::id() % 80) as u16 + offset
}

fn options(domain: u16) -> Ros2StartOptions {
    Ros2StartOptions {
        domain_id: Some(domain),
    }
}

fn wait_for(what: &str, timeout: Duration, mut f: impl FnMut() -> bool) {
    let start = Instant::now();
    while !f() {
        assert!(start.elapsed() < timeout, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// A 12-state that varies with `k` in every component (NED/FRD); periodic,
/// so the Euler angles stay away from wrapping however long discovery takes.
fn plant_state(k: u64) -> State {
    let t = (k % 100) as f64 * 0.01;
    State::from_row_slice(&[
        1.0 + t,
        -2.0 + 0.5 * t,
        -1.5 - t,
        0.4 + t,
        0.05 - 0.1 * t,
        -0.03 + 0.2 * t,
        1.0,
        0.5 - t,
        -0.2,
        0.1 * t,
        -0.05,
        0.2 + t,
    ])
}

fn pilot(k: u64) -> PilotInput {
    let t = k as f64;
    PilotInput {
        velocity: [0.1 * t, -0.2, 0.3 - 0.01 * t],
        yaw_rate: -0.1 + 0.001 * t,
        throttle: (0.5 + 0.01 * t).min(1.0),
        arm: k.is_multiple_of(2),
        offboard: k.is_multiple_of(3),
        mpc_enabled: !k.is_multiple_of(5),
    }
}

/// Both sides of SITL from one config, on one domain.
struct Sitl {
    daemon_out: Ros2Publisher,
    daemon_in: Ros2Inputs,
    plant_out: SitlPublisher,
    plant_in: SitlInputs,
    threads: [Ros2Thread; 2],
}

impl Sitl {
    fn start(config: &Ros2Config, domain: u16) -> Self {
        let (daemon_out, daemon_in, daemon) = Ros2Node::start(config, options(domain)).unwrap();
        let (plant_out, plant_in, plant) = SitlNode::start(config, options(domain)).unwrap();
        Self {
            daemon_out,
            daemon_in,
            plant_out,
            plant_in,
            threads: [daemon, plant],
        }
    }

    fn stop(self) {
        for thread in self.threads {
            thread.stop().unwrap();
        }
    }
}

/// Estimates and pilot inputs plant -> daemon, status daemon -> plant.
#[test]
fn sitl_node_and_daemon_node_exchange_estimate_pilot_and_status() {
    let mut sitl = Sitl::start(&Ros2Config::default(), domain(0));
    let (daemon_out, daemon_in) = (&sitl.daemon_out, &mut sitl.daemon_in);
    let (plant_out, plant_in) = (&sitl.plant_out, &mut sitl.plant_in);

    // Discovery, then streams both ways.
    let stamp0 = 1_000_000_123u64; // not a whole microsecond: Odometry keeps ns
    let mut k = 0u64;
    let mut estimates = Vec::new();
    let mut pilots: Vec<PilotCommand> = Vec::new();
    let mut statuses: Vec<MpcStatus> = Vec::new();
    let start = Instant::now();
    while estimates.len() < 20 || pilots.len() < 20 || statuses.len() < 20 {
        assert!(
            start.elapsed() < Duration::from_secs(20),
            "no traffic: daemon {:?}, plant {:?}",
            daemon_in.counters(),
            plant_in.counters()
        );
        assert!(plant_out.try_publish_estimate(&plant_state(k), stamp0 + k * 6_666_667));
        assert!(plant_out.try_publish_pilot(&pilot(k)));
        assert!(daemon_out.try_publish_status(&status(k)));
        k += 1;
        std::thread::sleep(Duration::from_millis(10));
        estimates.extend(daemon_in.latest_estimate());
        pilots.extend(daemon_in.latest_pilot());
        statuses.extend(plant_in.latest_status());
    }
    for e in &estimates {
        let j = (e.stamp_ns - stamp0) / 6_666_667;
        assert_eq!(e.stamp_ns, stamp0 + j * 6_666_667, "stamp arrived changed");
        let err = (e.state - plant_state(j)).abs().max();
        assert!(err < 1e-9, "estimate {j}: NED state off by {err}");
    }
    // Each pilot input is one that was sent (the k is in its velocity).
    for p in &pilots {
        let j = (p.input.velocity[0] * 10.0).round() as u64;
        assert_eq!(p.input, pilot(j), "pilot input {j} arrived changed");
    }
    for s in &statuses {
        assert_eq!(*s, status(s.tick), "status {} arrived changed", s.tick);
    }
    let d = daemon_in.counters();
    assert_eq!(
        d.malformed + d.invalid + d.stamp_backwards + d.pilot_rejected,
        0,
        "{d:?}"
    );
    assert!(
        d.pilot_received >= 20 && d.estimates_accepted >= 20,
        "{d:?}"
    );
    let p = plant_in.counters();
    assert_eq!(p.malformed, 0, "{p:?}");
    assert!(p.status_received >= 20 && p.published >= 40, "{p:?}");
    eprintln!("daemon {d:?}\nplant {p:?}");
    sitl.stop();
}

/// NaN velocity and throttle 1.5 are rejected and counted; the last good
/// input is still the last one `latest_pilot` gave.
#[test]
fn bad_pilot_inputs_are_rejected_and_counted() {
    let mut sitl = Sitl::start(&Ros2Config::default(), domain(1));
    let (plant_out, daemon_in) = (&sitl.plant_out, &mut sitl.daemon_in);

    let good = PilotInput {
        velocity: [0.25, -0.5, 0.125],
        yaw_rate: 0.3,
        throttle: 1.0,
        arm: true,
        offboard: true,
        mpc_enabled: true,
    };
    let mut last = None;
    wait_for("a good pilot input", Duration::from_secs(15), || {
        plant_out.try_publish_pilot(&good);
        last = daemon_in.latest_pilot().or(last);
        last.is_some()
    });
    // Let the remaining copies of the good one arrive, then start counting.
    std::thread::sleep(Duration::from_millis(500));
    while let Some(p) = daemon_in.latest_pilot() {
        last = Some(p);
    }
    let last = last.unwrap();
    assert_eq!(last.input, good);

    let mut nan_velocity = good;
    nan_velocity.velocity[1] = f64::NAN;
    let mut throttle_high = good;
    throttle_high.throttle = 1.5;
    for (what, bad) in [
        ("NaN velocity", nan_velocity),
        ("throttle 1.5", throttle_high),
    ] {
        let before = daemon_in.counters();
        let mut sent = 0;
        wait_for(what, Duration::from_secs(10), || {
            plant_out.try_publish_pilot(&bad);
            sent += 1;
            daemon_in.counters().pilot_rejected > before.pilot_rejected
        });
        std::thread::sleep(Duration::from_millis(100));
        let after = daemon_in.counters();
        let rejected = after.pilot_rejected - before.pilot_rejected;
        assert!((1..=sent).contains(&rejected), "{what}: {after:?}");
        assert_eq!(
            after.pilot_received - before.pilot_received,
            rejected,
            "{what}: every pilot input since the good one was rejected: {after:?}"
        );
        assert_eq!(after.malformed, 0, "{what}: {after:?}");
        assert_eq!(
            daemon_in.latest_pilot(),
            None,
            "{what} reached the control thread"
        );
        eprintln!("{what}: sent {sent}, rejected {rejected}");
    }
    // The control thread still holds the last good one it was given.
    assert_eq!(last.input, good);
    assert!(daemon_in.counters().pilot_rejected >= 2);
    sitl.stop();
}

/// With the estimate configured as PX4 `VehicleOdometry`, the SITL node
/// publishes that (NED, float32, stamp in microseconds).
#[test]
fn sitl_publishes_px4_odometry_when_the_estimate_is_px4() {
    let mut config = Ros2Config::default();
    config.topics.estimate = TopicConfig {
        name: "/fmu/out/vehicle_odometry".into(),
        type_name: VehicleOdometry::TYPE_NAME.into(),
        enabled: true,
    };
    let mut sitl = Sitl::start(&config, domain(2));
    let (plant_out, daemon_in) = (&sitl.plant_out, &mut sitl.daemon_in);
    let mut k = 1u64;
    let mut got = None;
    wait_for("a PX4 estimate", Duration::from_secs(15), || {
        plant_out.try_publish_estimate(&plant_state(k), k * 1_000_000 + 999);
        k += 1;
        got = daemon_in.latest_estimate();
        got.is_some()
    });
    let e = got.unwrap();
    // Microseconds on the wire: the 999 ns below the microsecond are gone.
    assert_eq!(e.stamp_ns % 1_000_000, 0, "{}", e.stamp_ns);
    let j = e.stamp_ns / 1_000_000;
    let err = (e.state - plant_state(j)).abs().max();
    assert!(err < 1e-5, "float32 odometry off by {err}");
    sitl.stop();
}

/// With the autopilot's estimate topic enabled (PX4 `VehicleOdometry`,
/// the shipped name), each plant state goes out on both estimate topics:
/// the daemon's node has it as the estimate (`nav_msgs/Odometry`) and as
/// the autopilot's.
#[test]
fn sitl_publishes_the_autopilots_estimate_too_when_it_is_enabled() {
    let mut config = Ros2Config::default();
    config.topics.autopilot_estimate.enabled = true;
    assert_eq!(
        config.topics.autopilot_estimate.type_name,
        VehicleOdometry::TYPE_NAME
    );
    let mut sitl = Sitl::start(&config, domain(3));
    let (plant_out, daemon_in) = (&sitl.plant_out, &mut sitl.daemon_in);
    let mut k = 1u64;
    let (mut estimate, mut autopilot) = (None, None);
    wait_for("both estimates", Duration::from_secs(15), || {
        plant_out.try_publish_estimate(&plant_state(k), k * 1_000_000);
        k += 1;
        estimate = daemon_in.latest_estimate().or(estimate);
        autopilot = daemon_in.latest_autopilot_estimate().or(autopilot);
        estimate.is_some() && autopilot.is_some()
    });
    for (what, e, tolerance) in [
        ("estimate", estimate.unwrap(), 1e-12),
        ("autopilot's estimate (float32)", autopilot.unwrap(), 1e-5),
    ] {
        let j = e.stamp_ns / 1_000_000;
        let err = (e.state - plant_state(j)).abs().max();
        assert!(err < tolerance, "{what} off by {err}");
    }
    sitl.stop();
}

#[test]
fn config_names_topics_pilot_when_its_type_is_wrong() {
    let text = "[topics.pilot]\nname = \"/atmo/pilot\"\ntype = \"geometry_msgs/msg/Twist\"\n";
    let err = Ros2Config::from_toml_str(text, "ros2.toml")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("ros2.toml") && err.contains("topics.pilot.type"),
        "{err}"
    );
    let text = "[topics.pilot]\nname = \"pilot\"\ntype = \"atmo_msgs/msg/PilotInput\"\n";
    let err = Ros2Config::from_toml_str(text, "ros2.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("topics.pilot.name"), "{err}");
    let text = "[topics.pilot]\nname = \"/atmo/cmd_drive\"\ntype = \"atmo_msgs/msg/PilotInput\"\n";
    let err = Ros2Config::from_toml_str(text, "ros2.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("topics.pilot.name"), "duplicate name: {err}");
    let config = Ros2Config::default();
    assert_eq!(config.topics.pilot.name, "/atmo/pilot");
    assert_eq!(config.topics.pilot.type_name, PilotInput::TYPE_NAME);
    assert_eq!(SitlNode::node_name(&config), "atmo_daemon_sitl");
}
