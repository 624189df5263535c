//! The ROS 2 node against a second RustDDS participant on loopback: status
//! out with correct values, odometry in (ENU/FLU -> NED/FRD), drive commands
//! in, and each kind of bad input counted without a panic: malformed CDR, a
//! message of another type on the topic, NaN in odometry, stamps going
//! backwards. Runs on its own domain id.
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

mod support;

use std::net::Ipv4Addr;
use std::time::{Duration, Instant};

use atmo_core::ConfigFile;
use atmo_core::model::State;
use atmo_io::msg::frames::{odometry_to_state, state_to_odometry};
use atmo_io::msg::{
    Clock, DiagnosticArray, MpcStatus, Odometry, Point, PointStamped, Time, Twist, Vector3,
    Vector3Stamped, VehicleOdometry,
};
use atmo_io::ros2::{
    Ros2Config, Ros2Counters, Ros2Node, Ros2StartOptions, TopicConfig, domain_id_from_env,
};
use ros2_client::dds::rustdds::DomainParticipantBuilder;
use ros2_client::{
    Context, MessageTypeName, Name, Node, NodeName, NodeOptions, Publisher, QosProfile,
};
use serde::{Deserialize, Serialize};
use support::status;

fn domain() -> u16 {
    // Away from 0 and from other test binaries running at the same time.
    100 + (std::process::id() % 100) as u16
}

fn peer_node(domain: u16, name: &str) -> (Context, Node) {
    let dp = DomainParticipantBuilder::new(domain)
        .with_only_networks([Ipv4Addr::LOCALHOST])
        .same_host_loopback(true)
        .build()
        .unwrap();
    let context = Context::from_domain_participant(dp).unwrap();
    let node = context
        .new_node(
            NodeName::new("/", name).unwrap(),
            NodeOptions::new().enable_rosout(false),
        )
        .unwrap();
    (context, node)
}

fn topic_name(full: &str) -> Name {
    let (ns, base) = full.rsplit_once('/').unwrap();
    Name::new(if ns.is_empty() { "/" } else { ns }, base).unwrap()
}

/// Something that is not an Odometry, sent under Odometry's type name.
#[derive(Serialize, Deserialize, Clone, Debug)]
struct Garbage {
    a: u8,
    b: u16,
}

fn odometry(k: u64, stamp_s: i32) -> Odometry {
    let mut x = State::zeros();
    x[0] = 0.1 * k as f64;
    x[1] = -0.2;
    x[2] = -1.5;
    x[3] = 0.4;
    x[4] = 0.05;
    x[5] = -0.03;
    x[6] = 1.0;
    x[7] = 0.5;
    x[11] = 0.2;
    let mut odom = state_to_odometry(&x, 0);
    odom.header.stamp = Time {
        sec: stamp_s,
        nanosec: 0,
    };
    odom
}

fn wait_for(what: &str, timeout: Duration, mut f: impl FnMut() -> bool) {
    let start = Instant::now();
    while !f() {
        assert!(start.elapsed() < timeout, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
// One live node exercised end to end: the steps share its discovery and state.
#[allow(clippy::too_many_lines)]
fn node_talks_to_a_second_participant_and_counts_bad_input() {
    let domain = domain();
    let config = Ros2Config {
        diagnostics_period_ms: 100,
        ..Ros2Config::default()
    };
    let (publisher, mut inputs, thread) = Ros2Node::start(
        &config,
        Ros2StartOptions {
            domain_id: Some(domain),
        },
    )
    .unwrap();

    let qos = QosProfile::subscription_default();
    let (_peer_context, mut peer) = peer_node(domain, "peer");
    let t = peer
        .create_topic(
            &topic_name("/atmo/status"),
            MessageTypeName::new("atmo_msgs", "MpcStatus"),
            &qos,
        )
        .unwrap();
    let status_sub = peer.create_subscription::<MpcStatus>(&t, None).unwrap();
    let t = peer
        .create_topic(
            &topic_name("/diagnostics"),
            MessageTypeName::new("diagnostic_msgs", "DiagnosticArray"),
            &qos,
        )
        .unwrap();
    let diag_sub = peer
        .create_subscription::<DiagnosticArray>(&t, None)
        .unwrap();
    let t = peer
        .create_topic(
            &topic_name("/atmo/mocap/odom"),
            MessageTypeName::new("nav_msgs", "Odometry"),
            &qos,
        )
        .unwrap();
    let odom_pub = peer.create_publisher::<Odometry>(&t, None).unwrap();
    let t = peer
        .create_topic(
            &topic_name("/atmo/cmd_drive"),
            MessageTypeName::new("geometry_msgs", "Twist"),
            &qos,
        )
        .unwrap();
    let drive_pub = peer.create_publisher::<Twist>(&t, None).unwrap();

    // Discovery, then a stream both ways.
    let mut sent_k = 0u64;
    let mut received_status = Vec::new();
    let mut estimates = Vec::new();
    let mut odom_k = 0u64;
    let start = Instant::now();
    while received_status.len() < 20 || estimates.len() < 20 {
        assert!(
            start.elapsed() < Duration::from_secs(15),
            "no traffic: {:?}",
            publisher.counters()
        );
        assert!(publisher.try_publish_status(&status(sent_k)));
        sent_k += 1;
        odom_pub
            .publish(odometry(odom_k, 100 + odom_k as i32))
            .unwrap();
        odom_k += 1;
        std::thread::sleep(Duration::from_millis(10));
        while let Ok(Some((s, _))) = status_sub.take() {
            received_status.push(s);
        }
        if let Some(e) = inputs.latest_estimate() {
            estimates.push(e);
        }
    }
    for s in &received_status {
        assert_eq!(*s, status(s.tick), "status {} arrived changed", s.tick);
    }
    for e in &estimates {
        let k = e.stamp_ns / 1_000_000_000 - 100;
        let want = odometry_to_state("/x", &odometry(k, 0)).unwrap();
        assert_eq!(e.state, want);
        assert!((e.state[3] - 0.4).abs() < 1e-12); // NED yaw survives the round trip
    }
    let good = inputs.counters();
    assert_eq!(
        good.malformed + good.invalid + good.stamp_backwards,
        0,
        "{good:?}"
    );
    let mut stamp = 100 + odom_k as i32;

    // Drive commands: FLU angular.z left-positive -> FRD yaw rate.
    wait_for("a drive command", Duration::from_secs(5), || {
        drive_pub
            .publish(Twist {
                linear: Vector3 {
                    x: 0.7,
                    y: 0.0,
                    z: 0.0,
                },
                angular: Vector3 {
                    x: 0.0,
                    y: 0.0,
                    z: 0.3,
                },
            })
            .unwrap();
        inputs
            .latest_drive()
            .is_some_and(|d| d.forward == 0.7 && d.yaw_rate == -0.3)
    });

    // NaN in odometry.
    let c0 = inputs.counters();
    wait_for("a NaN estimate counted", Duration::from_secs(5), || {
        let mut odom = odometry(1, stamp);
        stamp += 1;
        odom.pose.pose.position.z = f64::NAN;
        odom_pub.publish(odom).unwrap();
        inputs.counters().invalid > c0.invalid
    });
    // Stamps going backwards.
    wait_for("a backwards stamp counted", Duration::from_secs(5), || {
        odom_pub.publish(odometry(2, 50)).unwrap();
        inputs.counters().stamp_backwards > c0.stamp_backwards
    });
    // Malformed CDR: another layout under Odometry's type name.
    let (_bad_context, mut bad) = peer_node(domain, "bad_peer");
    let t = bad
        .create_topic(
            &topic_name("/atmo/mocap/odom"),
            MessageTypeName::new("nav_msgs", "Odometry"),
            &qos,
        )
        .unwrap();
    let garbage_pub = bad.create_publisher::<Garbage>(&t, None).unwrap();
    wait_for(
        "a malformed payload counted",
        Duration::from_secs(10),
        || {
            garbage_pub.publish(Garbage { a: 1, b: 2 }).unwrap();
            inputs.counters().malformed > c0.malformed
        },
    );
    // A message of another type (Twist) on the odometry topic.
    let (_wrong_context, mut wrong) = peer_node(domain, "wrong_peer");
    let t = wrong
        .create_topic(
            &topic_name("/atmo/mocap/odom"),
            MessageTypeName::new("geometry_msgs", "Twist"),
            &qos,
        )
        .unwrap();
    let wrong_pub = wrong.create_publisher::<Twist>(&t, None).unwrap();
    let before_wrong = inputs.counters();
    for _ in 0..50 {
        wrong_pub.publish(Twist::default()).unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    let after_wrong = inputs.counters();
    // Either DDS refuses to match the writer (type names differ) or the payload
    // is counted as malformed; it is never accepted as an estimate.
    assert_eq!(
        after_wrong.estimates_accepted,
        before_wrong.estimates_accepted
    );
    eprintln!(
        "wrong type on the topic: {} counted as malformed",
        after_wrong.malformed - before_wrong.malformed
    );

    // Good data is still accepted after all that.
    let accepted = inputs.counters().estimates_accepted;
    wait_for(
        "a good estimate after the bad ones",
        Duration::from_secs(5),
        || {
            odom_pub.publish(odometry(3, stamp)).unwrap();
            stamp += 1;
            inputs.latest_estimate();
            inputs.counters().estimates_accepted > accepted
        },
    );

    // The counters are in the node's diagnostics.
    let c: Ros2Counters = inputs.counters();
    wait_for(
        "diagnostics with the counters",
        Duration::from_secs(5),
        || {
            while let Ok(Some((d, _))) = diag_sub.take() {
                let Some(own) = d.status.iter().find(|s| s.name == "atmo/ros2") else {
                    continue;
                };
                let value = |key: &str| -> u64 {
                    own.values
                        .iter()
                        .find(|kv| kv.key == key)
                        .map(|kv| kv.value.parse().unwrap())
                        .unwrap()
                };
                if value("malformed") >= c.malformed
                    && value("invalid") >= c.invalid
                    && value("stamp_backwards") >= c.stamp_backwards
                    && value("pilot_received") >= c.pilot_received
                    && value("pilot_rejected") >= c.pilot_rejected
                {
                    assert_eq!(own.level, atmo_io::msg::DiagnosticStatus::WARN);
                    return true;
                }
            }
            false
        },
    );
    eprintln!("counters: {:?}", inputs.counters());
    thread.stop().unwrap();
}

#[test]
fn config_errors_name_file_and_key() {
    let text = "[topics.estimate]\nname = \"/a/b\"\ntype = \"geometry_msgs/msg/Twist\"\n";
    let err = Ros2Config::from_toml_str(text, "ros2.toml")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("ros2.toml") && err.contains("topics.estimate.type"),
        "{err}"
    );
    let text = "[topics.status]\nname = \"atmo/status\"\ntype = \"atmo_msgs/msg/MpcStatus\"\n";
    let err = Ros2Config::from_toml_str(text, "ros2.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("topics.status.name"), "{err}");
    let err = Ros2Config::from_toml_str("nodename = \"x\"\n", "ros2.toml")
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("ros2.toml:1") && err.contains("nodename"),
        "{err}"
    );
    let text = "[topics.diagnostics]\nname = \"/atmo/status\"\ntype = \"diagnostic_msgs/msg/DiagnosticArray\"\n";
    assert!(
        Ros2Config::from_toml_str(text, "ros2.toml").is_err(),
        "duplicate name"
    );
    let px4 = "[topics.estimate]\nname = \"/fmu/out/vehicle_odometry\"\ntype = \"px4_msgs/msg/VehicleOdometry\"\n";
    let config = Ros2Config::from_toml_str(px4, "ros2.toml").unwrap();
    assert_eq!(config.topics.status.name, "/atmo/status");
    let shipped =
        Ros2Config::load(concat!(env!("CARGO_MANIFEST_DIR"), "/ros2.example.toml")).unwrap();
    assert_eq!(shipped, Ros2Config::default());
}

/// PX4's odometry (NED already) as the estimate source, through DDS.
/// A peer publishing PX4's `/fmu/out/vehicle_odometry` on `domain` (keep
/// its context and node alive while publishing).
fn px4_odometry_publisher(domain: u16) -> (Context, Node, Publisher<VehicleOdometry>) {
    let (context, mut peer) = peer_node(domain, "px4");
    let t = peer
        .create_topic(
            &topic_name("/fmu/out/vehicle_odometry"),
            MessageTypeName::new("px4_msgs", "VehicleOdometry"),
            &QosProfile::subscription_default(),
        )
        .unwrap();
    let px4 = peer.create_publisher::<VehicleOdometry>(&t, None).unwrap();
    (context, peer, px4)
}

#[test]
fn px4_vehicle_odometry_as_the_estimate() {
    let domain = domain() + 1;
    let mut config = Ros2Config::default();
    config.topics.estimate = TopicConfig {
        name: "/fmu/out/vehicle_odometry".into(),
        type_name: "px4_msgs/msg/VehicleOdometry".into(),
        enabled: true,
    };
    let (_publisher, mut inputs, thread) = Ros2Node::start(
        &config,
        Ros2StartOptions {
            domain_id: Some(domain),
        },
    )
    .unwrap();
    let (_peer_context, _peer, px4) = px4_odometry_publisher(domain);
    let mut k = 1u64;
    let mut got = None;
    wait_for("a PX4 estimate", Duration::from_secs(10), || {
        px4.publish(VehicleOdometry {
            timestamp: k * 1000,
            timestamp_sample: k * 1000,
            pose_frame: VehicleOdometry::POSE_FRAME_NED,
            position: [1.0, 2.0, -3.0],
            q: [1.0, 0.0, 0.0, 0.0],
            velocity_frame: VehicleOdometry::VELOCITY_FRAME_NED,
            velocity: [0.5, 0.0, -0.25],
            angular_velocity: [0.0, 0.0, 0.125],
            ..VehicleOdometry::default()
        })
        .unwrap();
        k += 1;
        got = inputs.latest_estimate();
        got.is_some()
    });
    let e = got.unwrap();
    assert_eq!(e.stamp_ns % 1_000_000, 0, "us -> ns");
    let want = [
        1.0, 2.0, -3.0, 0.0, 0.0, 0.0, 0.5, 0.0, -0.25, 0.0, 0.0, 0.125,
    ];
    assert_eq!(e.state.as_slice(), &want);
    thread.stop().unwrap();
}

/// PX4's odometry beside a motion-capture estimate
/// (`topics.autopilot_estimate`): it arrives as the autopilot's estimate,
/// never as the estimate; an invalid one (a NaN quaternion) is counted in
/// `autopilot_rejected` and never reaches the control thread.
#[test]
fn px4_vehicle_odometry_as_the_autopilots_estimate() {
    let domain = domain() + 5;
    let mut config = Ros2Config::default();
    config.topics.autopilot_estimate.enabled = true;
    let (_publisher, mut inputs, thread) = Ros2Node::start(
        &config,
        Ros2StartOptions {
            domain_id: Some(domain),
        },
    )
    .unwrap();
    let (_peer_context, _peer, px4) = px4_odometry_publisher(domain);
    let odometry = |k: u64, w: f32| VehicleOdometry {
        timestamp: k * 1000,
        timestamp_sample: k * 1000,
        pose_frame: VehicleOdometry::POSE_FRAME_NED,
        position: [1.0, 2.0, -3.0],
        q: [w, 0.0, 0.0, 0.0],
        velocity_frame: VehicleOdometry::VELOCITY_FRAME_NED,
        velocity: [0.5, 0.0, -0.25],
        angular_velocity: [0.0, 0.0, 0.125],
        ..VehicleOdometry::default()
    };
    let mut k = 1u64;
    let mut got = None;
    wait_for("the autopilot's estimate", Duration::from_secs(10), || {
        px4.publish(odometry(k, 1.0)).unwrap();
        k += 1;
        got = inputs.latest_autopilot_estimate();
        got.is_some()
    });
    let want = [
        1.0, 2.0, -3.0, 0.0, 0.0, 0.0, 0.5, 0.0, -0.25, 0.0, 0.0, 0.125,
    ];
    assert_eq!(got.unwrap().state.as_slice(), &want);
    assert!(inputs.latest_estimate().is_none(), "not the estimate");
    wait_for("an invalid one counted", Duration::from_secs(5), || {
        px4.publish(odometry(k, f32::NAN)).unwrap();
        k += 1;
        inputs.counters().autopilot_rejected > 0
    });
    std::thread::sleep(Duration::from_millis(50));
    assert!(
        inputs
            .latest_autopilot_estimate()
            .is_none_or(|e| e.state.as_slice() == want),
        "an invalid one never reaches the control thread"
    );
    let c = inputs.counters();
    assert!(c.autopilot_received > c.autopilot_rejected);
    assert_eq!(c.estimates_received, 0);
    thread.stop().unwrap();
}

/// `use_sim_time`: ROS time is 0 until a `/clock` arrives, then the newest
/// one (also when it jumps back); an invalid time is rejected and counted.
/// The ground topic's heights (ENU, up) come out as NED z; a NaN height is
/// rejected and counted. So do the ground normals (ENU to NED).
#[test]
fn sim_time_follows_clock_and_ground_heights_come_out_ned() {
    let domain = domain() + 3;
    let config = Ros2Config {
        use_sim_time: true,
        ..Ros2Config::default()
    };
    let (_publisher, mut inputs, thread) = Ros2Node::start(
        &config,
        Ros2StartOptions {
            domain_id: Some(domain),
        },
    )
    .unwrap();
    assert_eq!(inputs.ros_time_ns(), 0, "no /clock yet");
    let (_peer_context, mut peer) = peer_node(domain, "sim");
    let qos = QosProfile::subscription_default();
    let t = peer
        .create_topic(
            &topic_name("/clock"),
            MessageTypeName::new("rosgraph_msgs", "Clock"),
            &qos,
        )
        .unwrap();
    let clock_pub = peer.create_publisher::<Clock>(&t, None).unwrap();
    let t = peer
        .create_topic(
            &topic_name("/atmo/ground"),
            MessageTypeName::new("geometry_msgs", "PointStamped"),
            &qos,
        )
        .unwrap();
    let ground_pub = peer.create_publisher::<PointStamped>(&t, None).unwrap();
    let t = peer
        .create_topic(
            &topic_name("/atmo/ground_normal"),
            MessageTypeName::new("geometry_msgs", "Vector3Stamped"),
            &qos,
        )
        .unwrap();
    let normal_pub = peer.create_publisher::<Vector3Stamped>(&t, None).unwrap();
    let clock = |sec, nanosec| Clock {
        clock: Time { sec, nanosec },
    };
    wait_for("ROS time from /clock", Duration::from_secs(10), || {
        clock_pub.publish(clock(42, 500)).unwrap();
        inputs.ros_time_ns() == 42_000_000_500
    });
    wait_for("the clock going back", Duration::from_secs(5), || {
        clock_pub.publish(clock(7, 0)).unwrap();
        inputs.ros_time_ns() == 7_000_000_000
    });
    wait_for("an invalid /clock counted", Duration::from_secs(5), || {
        clock_pub.publish(clock(-1, 0)).unwrap();
        inputs.counters().clock_rejected > 0
    });
    assert_eq!(
        inputs.ros_time_ns(),
        7_000_000_000,
        "invalid times are not used"
    );

    let ground = |z| PointStamped {
        point: Point { x: 3.0, y: 4.0, z },
        ..PointStamped::default()
    };
    let mut got = None;
    wait_for("a ground height", Duration::from_secs(10), || {
        ground_pub.publish(ground(0.25)).unwrap();
        got = inputs.latest_ground();
        got.is_some()
    });
    assert_eq!(got.unwrap().z, -0.25, "ENU up -> NED z");
    wait_for(
        "a NaN ground height counted",
        Duration::from_secs(5),
        || {
            ground_pub.publish(ground(f64::NAN)).unwrap();
            inputs.counters().ground_rejected > 0
        },
    );
    std::thread::sleep(Duration::from_millis(50));
    assert!(
        inputs.latest_ground().is_none_or(|g| g.z == -0.25),
        "a NaN height never reaches the control thread"
    );
    let c = inputs.counters();
    assert!(
        c.ground_received > c.ground_rejected,
        "the valid height counts too"
    );
    assert!(c.clock_received >= 3);

    // A slope rising to the north: ENU (0, -sin, cos) is NED (-sin, 0, -cos).
    let normal = |x, y, z| Vector3Stamped {
        vector: Vector3 { x, y, z },
        ..Vector3Stamped::default()
    };
    let mut got = None;
    wait_for("a ground normal", Duration::from_secs(10), || {
        normal_pub.publish(normal(0.0, -0.5, 0.75)).unwrap();
        got = inputs.latest_ground_normal();
        got.is_some()
    });
    assert_eq!(got.unwrap().normal, [-0.5, 0.0, -0.75], "ENU -> NED");
    wait_for(
        "a non-finite ground normal counted",
        Duration::from_secs(5),
        || {
            normal_pub.publish(normal(0.0, f64::INFINITY, 1.0)).unwrap();
            inputs.counters().ground_normal_rejected > 0
        },
    );
    std::thread::sleep(Duration::from_millis(50));
    assert!(
        inputs
            .latest_ground_normal()
            .is_none_or(|g| g.normal == [-0.5, 0.0, -0.75]),
        "a non-finite normal never reaches the control thread"
    );
    let c = inputs.counters();
    assert!(c.ground_normal_received > c.ground_normal_rejected);
    thread.stop().unwrap();
}

/// Child half of the domain-id test: checks `domain_id_from_env` under the
/// environment the parent gave it.
#[test]
fn child_domain_id() {
    let Ok(expect) = std::env::var("ATMO_EXPECT_DOMAIN") else {
        return;
    };
    match expect.as_str() {
        "error" => {
            let err = domain_id_from_env().unwrap_err().to_string();
            assert!(err.contains("ROS_DOMAIN_ID"), "{err}");
        }
        id => assert_eq!(domain_id_from_env().unwrap(), id.parse::<u16>().unwrap()),
    }
}

#[test]
fn domain_id_comes_from_ros_domain_id() {
    for (value, expect) in [
        (Some("42"), "42"),
        (None, "0"),
        (Some(""), "0"),
        (Some("233"), "error"),
        (Some("x"), "error"),
    ] {
        let mut command = std::process::Command::new(std::env::current_exe().unwrap());
        command
            .args(["--exact", "child_domain_id"])
            .env("ATMO_EXPECT_DOMAIN", expect)
            .env_remove("ROS_DOMAIN_ID");
        if let Some(v) = value {
            command.env("ROS_DOMAIN_ID", v);
        }
        let out = command.output().unwrap();
        assert!(
            out.status.success(),
            "ROS_DOMAIN_ID={value:?}: {}",
            String::from_utf8_lossy(&out.stdout)
        );
        assert!(String::from_utf8_lossy(&out.stdout).contains("1 passed"));
    }
}

/// A full publish queue drops and counts; the caller never waits.
#[test]
fn a_full_publish_queue_drops_and_counts() {
    let config = Ros2Config {
        publish_queue: 1,
        ..Ros2Config::default()
    };
    let (publisher, _inputs, thread) = Ros2Node::start(
        &config,
        Ros2StartOptions {
            domain_id: Some(domain() + 2),
        },
    )
    .unwrap();
    let n = 5000u64;
    let start = Instant::now();
    let mut accepted = 0;
    let mut slowest = Duration::ZERO;
    for k in 0..n {
        let t0 = Instant::now();
        accepted += u64::from(publisher.try_publish_status(&status(k)));
        slowest = slowest.max(t0.elapsed());
    }
    let elapsed = start.elapsed();
    let c = publisher.counters();
    assert_eq!(accepted + c.publish_dropped, n, "{c:?}");
    assert!(
        c.publish_dropped > 0,
        "a 1-slot queue must overflow under a burst"
    );
    wait_for(
        "the accepted ones published",
        Duration::from_secs(5),
        || publisher.counters().published >= accepted,
    );
    eprintln!(
        "{n} try_publish_status in {elapsed:?} (slowest {slowest:?}), dropped {}",
        c.publish_dropped
    );
    thread.stop().unwrap();
}
