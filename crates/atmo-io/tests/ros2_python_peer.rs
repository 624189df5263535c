//! The ROS 2 node against a peer no one here wrote: Eclipse Cyclone DDS
//! (Python `cyclonedds`, a ROS 2 middleware) acting as a ROS 2 node
//! (tests/python/dds_peer.py). The peer must receive the status topic with
//! the values sent, and the node must accept the peer's odometry (ENU/FLU,
//! converted to NED/FRD) and count the peer's bad odometry (NaN, stamps
//! going backwards). Loopback only, no multicast, own domain id.
//!
//! Needs the Python peers: `scripts/python-peers.sh` makes the venv and
//! `.ci/run` runs this test with `ATMO_PYTHON` set (`--ignored`).
// Test, bench and example code: an unwrap that fails is the failure report.
#![allow(clippy::unwrap_used)]

mod support;

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use atmo_io::msg::frames::odometry_to_state;
use atmo_io::msg::{Header, Odometry, Point, Quaternion, Time, Twist, Vector3};
use atmo_io::ros2::{Ros2Config, Ros2Node, Ros2StartOptions};
use serde_json::Value;
use support::status;

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The peer prints each float as the integer of its bits (exact).
fn f(v: &Value) -> f64 {
    f64::from_bits(v.as_u64().unwrap())
}

/// Our JSON with every float replaced by the integer of its bits, as the
/// peer prints them (non-finite floats are null on both sides).
fn float_bits(v: Value) -> Value {
    match v {
        Value::Number(n) if n.is_f64() => Value::from(n.as_f64().unwrap().to_bits()),
        Value::Array(items) => Value::Array(items.into_iter().map(float_bits).collect()),
        Value::Object(map) => {
            Value::Object(map.into_iter().map(|(k, v)| (k, float_bits(v))).collect())
        }
        other => other,
    }
}

fn vector(v: &Value) -> Vector3 {
    Vector3 {
        x: f(&v["x"]),
        y: f(&v["y"]),
        z: f(&v["z"]),
    }
}

/// The odometry the peer printed, rebuilt field by field.
fn odometry_from_json(m: &Value) -> Odometry {
    let p = &m["pose"]["pose"];
    let mut odom = Odometry {
        header: Header {
            stamp: Time {
                sec: m["header"]["stamp"]["sec"].as_i64().unwrap() as i32,
                nanosec: m["header"]["stamp"]["nanosec"].as_u64().unwrap() as u32,
            },
            frame_id: m["header"]["frame_id"].as_str().unwrap().into(),
        },
        child_frame_id: m["child_frame_id"].as_str().unwrap().into(),
        ..Odometry::default()
    };
    let pos = vector(&p["position"]);
    odom.pose.pose.position = Point {
        x: pos.x,
        y: pos.y,
        z: pos.z,
    };
    let q = &p["orientation"];
    odom.pose.pose.orientation = Quaternion {
        x: f(&q["x"]),
        y: f(&q["y"]),
        z: f(&q["z"]),
        w: f(&q["w"]),
    };
    odom.twist.twist = Twist {
        linear: vector(&m["twist"]["twist"]["linear"]),
        angular: vector(&m["twist"]["twist"]["angular"]),
    };
    odom
}

#[test]
#[ignore = "needs the Python peers (scripts/python-peers.sh); run by .ci/run with ATMO_PYTHON"]
fn cyclone_dds_peer_receives_status_and_sends_odometry() {
    let python = std::env::var("ATMO_PYTHON")
        .expect("set ATMO_PYTHON to the venv's python (scripts/python-peers.sh prints it)");
    let domain = 150 + (std::process::id() % 80) as u16;
    let (publisher, mut inputs, node) = Ros2Node::start(
        &Ros2Config::default(),
        Ros2StartOptions {
            domain_id: Some(domain),
        },
    )
    .unwrap();

    let scripts = repo().join("tests/python");
    let mut child = Command::new(&python)
        .arg(scripts.join("dds_peer.py"))
        .arg(domain.to_string())
        .env(
            "CYCLONEDDS_URI",
            format!(
                "file://{}",
                scripts.join("cyclonedds-loopback.xml").display()
            ),
        )
        .env("PYTHONPATH", &scripts)
        .stdout(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("cannot start {python}: {e}"));
    let stdout = child.stdout.take().unwrap();
    let (line_tx, line_rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if line_tx.send(line).is_err() {
                break;
            }
        }
    });

    let mut lines: Vec<Value> = Vec::new();
    let mut estimates = Vec::new();
    let start = Instant::now();
    let mut k = 0u64;
    let mut done = None;
    while done.is_none() {
        assert!(
            start.elapsed() < Duration::from_secs(40),
            "the peer did not finish: {:?}",
            inputs.counters()
        );
        publisher.try_publish_status(&status(k));
        k += 1;
        std::thread::sleep(Duration::from_millis(10));
        while let Some(e) = inputs.latest_estimate() {
            estimates.push(e);
        }
        while let Ok(line) = line_rx.try_recv() {
            let value: Value = serde_json::from_str(&line)
                .unwrap_or_else(|e| panic!("peer printed `{line}`: {e}"));
            if value["kind"] == "done" {
                done = Some(value.clone());
            }
            lines.push(value);
        }
    }
    // A little longer for the last odometry to arrive.
    let settle = Instant::now();
    while settle.elapsed() < Duration::from_millis(300) {
        while let Some(e) = inputs.latest_estimate() {
            estimates.push(e);
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let exit = child.wait().unwrap();
    let done = done.unwrap();
    assert!(exit.success() && done["ok"] == true, "peer: {done}");

    // The peer received statuses equal to what was sent (compared as JSON in
    // the .msg layout, floats bit for bit; non-finite floats are null on both sides).
    let statuses: Vec<&Value> = lines.iter().filter(|l| l["kind"] == "status").collect();
    assert!(statuses.len() >= 30, "{} statuses", statuses.len());
    for s in &statuses {
        let tick = s["msg"]["tick"].as_u64().unwrap();
        let want = float_bits(serde_json::to_value(status(tick)).unwrap());
        assert_eq!(s["msg"], want, "status {tick}");
    }

    // The node accepted the peer's odometry, each equal to the conversion of
    // what the peer sent; latest_estimate() may skip an estimate when two
    // arrive within one 10 ms loop, never change one.
    let sent: Vec<Odometry> = lines
        .iter()
        .filter(|l| l["kind"] == "odom")
        .map(|l| odometry_from_json(&l["msg"]))
        .collect();
    assert_eq!(sent.len(), 43);
    for e in &estimates {
        let odom = sent
            .iter()
            .find(|o| o.header.stamp.to_ns() == Some(e.stamp_ns))
            .unwrap_or_else(|| panic!("estimate stamped {} was not sent", e.stamp_ns));
        assert_eq!(
            e.state,
            odometry_to_state("/atmo/mocap/odom", odom).unwrap()
        );
    }
    let c = inputs.counters();
    eprintln!(
        "counters: {c:?}, estimates seen by the control loop: {}",
        estimates.len()
    );
    // Loopback after discovery: every good odometry arrives.
    assert_eq!(c.estimates_accepted, 43, "{c:?}");
    assert!(c.invalid >= 1, "NaN odometry not counted: {c:?}");
    assert!(
        c.stamp_backwards >= 1,
        "backwards stamps not counted: {c:?}"
    );
    assert_eq!(c.malformed, 0, "{c:?}");
    // The yaw: 0.4 rad about ENU up (counter-clockwise from east) is
    // pi/2 - 0.4 clockwise from north.
    let last = estimates.last().unwrap();
    assert!((last.state[3] - (std::f64::consts::FRAC_PI_2 - 0.4)).abs() < 1e-12);
    node.stop().unwrap();
}
